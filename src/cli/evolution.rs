//! `kac wave FILE` and `kac schrodinger FILE`: evolutions by modal superposition, the same requests as the
//! service's `wave` and `schrodinger` analyses. Initial data from a `.npy` (one value per vertex of the file, its
//! first column) or a Gaussian bump at a source vertex.

use super::analyses::{emit, run, OutArgs};
use super::{Failure, ShapeArgs};
use crate::analysis::{Analysis, InitialData, OperatorSpec};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct Start {
    /// Times (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    pub times: Vec<f64>,
    /// Eigenpairs of the superposition.
    #[arg(short = 'k', long = "k", default_value_t = crate::analysis::k_signature())]
    pub k: usize,
    /// Initial values (u₀, or Re ψ₀) as a .npy, one row per vertex of the file.
    #[arg(long)]
    pub initial: Option<PathBuf>,
    /// Or a Gaussian bump at this vertex (the file's numbering).
    #[arg(long)]
    pub source: Option<u32>,
    /// The bump's width (default: 5 % of the bounding box's diagonal).
    #[arg(long)]
    pub width: Option<f64>,
}

pub(super) fn npy_column(path: &std::path::Path) -> Result<Vec<f64>, Failure> {
    let bytes = std::fs::read(path).map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
    let (rows, cols, data) = kac_core::io::npy::decode_f64(&bytes)
        .map_err(|e| Failure { code: 2, message: format!("{}: {e}", path.display()) })?;
    Ok((0..rows).map(|r| data[r * cols.max(1)]).collect())
}

impl Start {
    pub(super) fn data(&self) -> Result<InitialData, Failure> {
        Ok(InitialData {
            initial: self.initial.as_deref().map(npy_column).transpose()?,
            source: self.source,
            width: self.width,
        })
    }
}

#[derive(Args)]
pub struct WaveCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub start: Start,
    /// Initial velocity as a .npy (default zero).
    #[arg(long)]
    pub velocity: Option<PathBuf>,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
}

pub fn wave(a: WaveCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let analysis = Analysis::Wave {
        k: a.start.k,
        times: a.start.times.clone(),
        start: a.start.data()?,
        velocity: a.velocity.as_deref().map(npy_column).transpose()?,
        operator: a.op.clone(),
        solver: a.out.solver.clone(),
    };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}

#[derive(Args)]
pub struct SchrodingerCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub start: Start,
    /// Im ψ₀ as a .npy (default zero).
    #[arg(long)]
    pub initial_imag: Option<PathBuf>,
    #[command(flatten)]
    pub op: OperatorSpec,
    #[command(flatten)]
    pub out: OutArgs,
}

pub fn schrodinger(a: SchrodingerCmd) -> Result<(), Failure> {
    let (v, _) = a.shape.load()?;
    let analysis = Analysis::Schrodinger {
        k: a.start.k,
        times: a.start.times.clone(),
        start: a.start.data()?,
        initial_imag: a.initial_imag.as_deref().map(npy_column).transpose()?,
        operator: a.op.clone(),
        solver: a.out.solver.clone(),
    };
    emit(run(&v, &analysis, &a.out)?, &a.out)
}
