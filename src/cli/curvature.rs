//! `kac mean-curvature FILE` and `kac heat-curvature FILE`: curvature heard from the Laplacian and from the heat
//! kernel, the same requests as the service's `mean-curvature` and `heat-curvature` analyses.

use super::analyses::{emit, run, OutArgs};
use super::{Failure, ShapeArgs};
use crate::analysis::{Analysis, OperatorSpec};
use clap::Args;

#[derive(Args)]
pub struct MeanCurvatureCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub out: OutArgs,
}

pub fn mean_curvature(a: MeanCurvatureCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    emit(run(&v, &Analysis::MeanCurvature {}, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct HeatCurvatureCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
    /// Eigenpairs of the heat kernel (more allow smaller times).
    #[arg(short = 'k', long = "k", default_value_t = crate::analysis::k_curvature())]
    pub k: usize,
    /// The times of the fit (default: 8 log-spaced in [4 ln 10 / λ_k, 4× that]).
    #[arg(long, value_delimiter = ',')]
    pub times: Option<Vec<f64>>,
}

pub fn heat_curvature(a: HeatCurvatureCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let analysis = Analysis::HeatCurvature {
        k: a.k,
        times: a.times.clone(),
        operator: a.op.clone(),
        solver: a.out.solver.clone(),
    };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}
