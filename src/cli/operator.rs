//! `kac operator FILE [--operator NAME] [--mass NAME] [--boundary neumann|dirichlet] [--report] [--out-dir DIR]`:
//! the operator summary (size, non-zeros, parameters, properties) as JSON; L and M as Matrix Market files.

use super::{print_json, Failure, ShapeArgs};
use crate::analysis::OperatorSpec;
use clap::Args;
use kac_core::operators::properties;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct OperatorCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    /// Add the property report (symmetry, locality, linear precision, maximum principle, PSD, null space).
    #[arg(long)]
    pub report: bool,
    /// Write L.mtx and M.mtx (Matrix Market, symmetric) into this directory.
    #[arg(long)]
    pub out_dir: Option<PathBuf>,
}

pub fn run(a: OperatorCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let t = Instant::now();
    let op = crate::analysis::build_operator(&v, &a.op)?;
    let assembly_s = t.elapsed().as_secs_f64();
    let mut out = json!({
        "shape_id": v.id.hex(),
        "kind": v.report.kind,
        "operator": op.kind.name(),
        "mass": op.mass.name(),
        "boundary": op.boundary,
        "size": op.pair.n(),
        "vertices": op.full_size,
        "nonzeros": op.pair.nnz(),
        "mass_is_diagonal": op.pair.mass_is_diagonal,
        "parameters": op.parameters,
        "sign": "L is positive semidefinite (stiffness); the eigenproblem is L φ = λ M φ",
        "timings": { "assembly_s": assembly_s },
    });
    if a.report {
        out["properties"] = serde_json::to_value(properties::report(&v.shape, &op))
            .map_err(|e| Failure { code: 1, message: e.to_string() })?;
    }
    if let Some(dir) = &a.out_dir {
        std::fs::create_dir_all(dir)
            .map_err(|e| Failure { code: 1, message: format!("cannot create {}: {e}", dir.display()) })?;
        let (lp, mp) = (dir.join("L.mtx"), dir.join("M.mtx"));
        for (path, values) in [(&lp, &op.pair.stiffness), (&mp, &op.pair.mass)] {
            kac_core::io::mtx::write_symmetric(path, &op.pair.pattern, values)
                .map_err(|e| Failure { code: 1, message: format!("cannot write {}: {e}", path.display()) })?;
        }
        out["files"] = json!({ "L": lp.display().to_string(), "M": mp.display().to_string() });
        if let Some(keep) = &op.interior {
            out["interior_vertices"] = json!(keep);
        }
    }
    print_json(&out)
}
