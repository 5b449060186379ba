//! `kac operator FILE [operator flags] [--report] [--out-dir DIR]`: the service's `operator` analysis — the
//! operator's summary (size, non-zeros, parameters, on request the property report) as JSON; with `--out-dir`,
//! L and M as Matrix Market (`L.mtx`, `M.mtx`) and SciPy (`L.npz`, `M.npz`) files and the vertex of each unknown
//! (`unknown_vertices.npy`).

use super::{print_json, Failure, ShapeArgs};
use crate::analysis::{self, Analysis, Hooks, OperatorSpec};
use clap::Args;
use serde_json::json;
use std::path::PathBuf;

#[derive(Args)]
pub struct OperatorCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    /// Add the property report (symmetry, locality, linear precision, maximum principle, PSD, null space).
    #[arg(long)]
    pub report: bool,
    /// Write L and M (L.mtx, M.mtx: Matrix Market, symmetric; L.npz, M.npz: scipy.sparse.load_npz) and
    /// unknown_vertices.npy into this directory.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
}

fn fail(path: &std::path::Path, e: impl std::fmt::Display) -> Failure {
    Failure { code: 1, message: format!("cannot write {}: {e}", path.display()) }
}

pub fn run(a: OperatorCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let request = Analysis::Operator { report: a.report, matrices: a.out_dir.is_some(), operator: a.op.clone() };
    let mut out = analysis::run(&v, &request, Hooks::default())?;
    out.summary["shape_id"] = v.id.hex().into();
    if let Some(dir) = &a.out_dir {
        std::fs::create_dir_all(dir).map_err(|e| fail(dir, e))?;
        let n = out.summary["unknowns"].as_u64().unwrap_or(0) as usize;
        let mut files = serde_json::Map::new();
        for arr in &out.arrays {
            match arr.name {
                "stiffness" | "mass" => {
                    let letter = if arr.name == "stiffness" { "L" } else { "M" };
                    let mtx = dir.join(format!("{letter}.mtx"));
                    let npz = dir.join(format!("{letter}.npz"));
                    let comment = format!("kac {}: {} of shape {}", letter, arr.name, v.id.hex());
                    let text =
                        kac_core::io::matrix::matrix_market(n, &arr.data, &comment).map_err(|e| fail(&mtx, e))?;
                    std::fs::write(&mtx, text).map_err(|e| fail(&mtx, e))?;
                    let zip = kac_core::io::matrix::npz_csr(n, &arr.data).map_err(|e| fail(&npz, e))?;
                    std::fs::write(&npz, zip).map_err(|e| fail(&npz, e))?;
                    files.insert(letter.into(), mtx.display().to_string().into());
                    files.insert(format!("{letter}_npz"), npz.display().to_string().into());
                }
                _ => {
                    let path = dir.join(format!("{}.npy", arr.name));
                    std::fs::write(&path, kac_core::io::npy::encode_f64(arr.rows, arr.cols, &arr.data))
                        .map_err(|e| fail(&path, e))?;
                    files.insert(arr.name.into(), path.display().to_string().into());
                }
            }
        }
        out.summary["files"] = json!(files);
        // Under Dirichlet conditions, the vertex of each unknown (the interior vertices), as before in the JSON.
        if out.summary["boundary"] != "neumann" {
            if let Some(map) = out.arrays.iter().find(|a| a.name == "unknown_vertices") {
                out.summary["interior_vertices"] = json!(map.data.iter().map(|&i| i as u64).collect::<Vec<_>>());
            }
        }
    }
    print_json(&out.summary)
}
