//! `kac poisson`, `kac diffuse` and `kac dirichlet-energy`: the PDE tools as the service's analyses of the same
//! names, functions given as `.npy` (one row per vertex of the file; the first column).

use super::analyses::{emit, run, OutArgs};
use super::evolution::{npy_column, Start};
use super::{Failure, ShapeArgs};
use crate::analysis::{Analysis, HeatMethod, OperatorSpec};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct PoissonCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    /// g per vertex (.npy).
    #[arg(long)]
    pub g: PathBuf,
    /// Dirichlet values as a (count × 2) .npy of rows (vertex, value); without: Neumann.
    #[arg(long)]
    pub dirichlet_values: Option<PathBuf>,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
}

pub fn poisson(a: PoissonCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let dirichlet_values = match &a.dirichlet_values {
        None => None,
        Some(path) => {
            let bytes =
                std::fs::read(path).map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
            let (rows, cols, data) = kac_core::io::npy::decode_f64(&bytes)
                .map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
            if cols != 2 {
                return Err(Failure { code: 2, message: format!("{}: give rows of (vertex, value)", path.display()) });
            }
            Some((0..rows).map(|r| (data[2 * r] as u32, data[2 * r + 1])).collect())
        }
    };
    let analysis = Analysis::Poisson { g: npy_column(&a.g)?, dirichlet_values, operator: a.op.clone() };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct DiffuseCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub start: Start,
    /// The diffusivity α of ∂u/∂t = −αΔu.
    #[arg(long, default_value_t = crate::analysis::one())]
    pub diffusivity: f64,
    /// spectral (the k smallest eigenpairs, with the truncation bound) or implicit (backward Euler).
    #[arg(long, value_enum, default_value_t = HeatMethod::default())]
    pub method: HeatMethod,
    /// Backward-Euler steps per time.
    #[arg(long, default_value_t = crate::analysis::steps_default())]
    pub steps: usize,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
}

pub fn diffuse(a: DiffuseCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let analysis = Analysis::Diffuse {
        times: a.start.times.clone(),
        start: a.start.data()?,
        diffusivity: a.diffusivity,
        method: a.method,
        k: a.start.k,
        steps: a.steps,
        operator: a.op.clone(),
        solver: a.out.solver.clone(),
    };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct DirichletEnergyCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    /// u per vertex (.npy); without: each coordinate.
    #[arg(long)]
    pub function: Option<PathBuf>,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
}

pub fn dirichlet_energy(a: DirichletEnergyCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let analysis = Analysis::DirichletEnergy {
        function: a.function.as_deref().map(npy_column).transpose()?,
        operator: a.op.clone(),
    };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}

#[derive(clap::Args, Debug)]
pub struct GradientCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    /// u per vertex (.npy, one column, the input file's vertex numbering).
    #[arg(long)]
    pub function: PathBuf,
    #[command(flatten)]
    pub out: OutArgs,
}

/// The gradient of a per-vertex function on each triangle or tetrahedron (the `gradient` analysis).
pub fn gradient(a: GradientCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let analysis = Analysis::Gradient { function: npy_column(&a.function)? };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}

#[derive(clap::Args, Debug)]
pub struct DivergenceCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    /// The field (.npy, one row [x, y, z] per element of the validated mesh, as `gradient` writes them).
    #[arg(long)]
    pub field: PathBuf,
    /// The mass the pointwise divergence is taken over: lumped (default) or voronoi (triangle meshes).
    #[arg(long, value_parser = crate::analysis::parse_mass)]
    pub mass: Option<kac_core::operators::Mass>,
    #[command(flatten)]
    pub out: OutArgs,
}

/// The divergence of a per-element field per vertex (the `divergence` analysis).
pub fn divergence(a: DivergenceCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let path = &a.field;
    let bytes = std::fs::read(path).map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
    let (rows, cols, data) = kac_core::io::npy::decode_f64(&bytes)
        .map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
    if cols != 3 {
        return Err(Failure {
            code: 2,
            message: format!("{}: {rows} × {cols}; give one row [x, y, z] per element", path.display()),
        });
    }
    let field = (0..rows).map(|r| [data[3 * r], data[3 * r + 1], data[3 * r + 2]]).collect();
    emit(run(&v, &Analysis::Divergence { field, mass: a.mass }, &a.out)?, &a.out)
}
