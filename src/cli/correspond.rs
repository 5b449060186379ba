//! `kac correspondence SOURCE TARGET`: which vertex of one shape is which of the other, by functional maps refined
//! with ZoomOut. The JSON result on stdout; `--map OUT.npy` writes, for each vertex of SOURCE, the index of its
//! match on TARGET (and `OUT.target_to_source.npy` the reverse).

use super::analyses::{read_function, OutArgs};
use super::{print_json, Failure, ShapeArgs};
use crate::analysis::{correspond, Hooks, OperatorSpec};
use clap::Args;
use kac_core::correspondence::CorrespondenceOptions;
use serde_json::json;
use std::path::PathBuf;

#[derive(Args)]
pub struct CorrespondenceCmd {
    /// The source shape.
    pub source: PathBuf,
    /// The target shape.
    pub target: PathBuf,
    #[command(flatten)]
    pub options: CorrespondenceOptions,
    /// Known pairs SOURCE:TARGET (vertex indices in the files' numbering), comma-separated: `--landmarks 0:12,40:7`.
    #[arg(long, value_delimiter = ',', value_parser = parse_landmark)]
    pub landmarks: Vec<(u32, u32)>,
    /// Write the source → target vertex map as a float64 .npy (one row per source vertex).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// A per-vertex array of SOURCE (.npy or one number per line) to carry to TARGET: the array `transferred`.
    #[arg(long)]
    pub transfer: Option<PathBuf>,
    /// The transferred array holds labels: carried by the vertex map (default: a function, by the functional map).
    #[arg(long)]
    pub transfer_labels: bool,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
}

fn parse_landmark(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = s.split_once(':').ok_or_else(|| format!("'{s}' is not SOURCE:TARGET"))?;
    Ok((
        a.trim().parse().map_err(|_| format!("'{a}' is not a vertex index"))?,
        b.trim().parse().map_err(|_| format!("'{b}' is not a vertex index"))?,
    ))
}

pub fn run(a: CorrespondenceCmd) -> Result<(), Failure> {
    let load = |file: &PathBuf| {
        ShapeArgs { file: file.clone(), format: None, weld: kac_core::Weld::Exact, keep_degenerate: false }.load()
    };
    let ((s, _), (t, _)) = (load(&a.source)?, load(&a.target)?);
    let mut options = a.options.clone();
    options.landmarks = a.landmarks.clone();
    let hooks = Hooks { threads: a.out.threads, ..Default::default() };
    let transfer = match &a.transfer {
        Some(path) => Some(correspond::Transfer { values: read_function(path)?, labels: a.transfer_labels }),
        None => None,
    };
    let result = super::on_pool(a.out.threads, || {
        correspond::correspondence(&s, &t, &options, &a.op, &a.out.solver, transfer.as_ref(), hooks)
    })?;
    let (mut out, arrays) = (result.summary, result.arrays);
    match &a.map {
        Some(path) => {
            let mut files = vec![];
            for x in arrays
                .iter()
                .filter(|x| x.name.ends_with("_to_target") || x.name.ends_with("_to_source") || x.name == "transferred")
            {
                let p = if x.name == "source_to_target" {
                    path.clone()
                } else {
                    path.with_extension(format!("{}.npy", x.name))
                };
                std::fs::write(&p, kac_core::io::npy::encode_f64(x.rows, x.cols, &x.data))
                    .map_err(|e| Failure { code: 1, message: format!("cannot write {}: {e}", p.display()) })?;
                files.push(json!({ "name": x.name, "path": p.display().to_string(), "rows": x.rows }));
            }
            out["files"] = files.into();
        }
        None => {
            let inline: serde_json::Map<String, serde_json::Value> =
                arrays.iter().map(|x| (x.name.to_string(), json!({ "rows": x.rows, "values": x.to_json() }))).collect();
            out["arrays"] = inline.into();
        }
    }
    print_json(&out)
}
