//! `kac inspect FILE [--format NAME]`: the summary and validation report of a shape as one JSON object.

use super::{print_json, Failure, ShapeArgs};
use clap::Args;

#[derive(Args)]
pub struct InspectArgs {
    #[command(flatten)]
    pub shape: ShapeArgs,
}

pub fn run(a: InspectArgs) -> Result<(), Failure> {
    let (v, format) = a.shape.load()?;
    let mut out = serde_json::to_value(v.summary()).map_err(|e| Failure { code: 1, message: e.to_string() })?;
    out["file"] = a.shape.file.display().to_string().into();
    out["format"] = format.name().into();
    print_json(&out)
}
