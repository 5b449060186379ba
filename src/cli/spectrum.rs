//! `kac spectrum FILE -k K [operator flags] [solver flags] [--band A,B] [--counting] [--eigenvectors OUT.npy] [--threads N]`:
//! the k smallest eigenpairs of L φ = λ M φ as JSON. The flags make the service's `spectrum` request, run by the
//! same analysis code, so the JSON is the service's (plus the read time, the total with it, and the file the
//! eigenvectors went to).

use super::{print_json, Failure, ShapeArgs};
use crate::analysis::{self, Analysis, Hooks, OperatorSpec, SolverSpec};
use clap::Args;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct SpectrumCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    /// Number of eigenpairs.
    #[arg(short = 'k', long = "k", default_value_t = crate::analysis::k_default())]
    pub k: usize,
    /// Write the eigenvectors as a (vertices × k) float64 .npy, in the input file's vertex numbering
    /// (zeros on a Dirichlet boundary, NaN for vertices validation dropped).
    #[arg(long)]
    pub eigenvectors: Option<PathBuf>,
    /// Threads for the factorization and solves (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    #[command(flatten)]
    pub solver: SolverSpec,
    /// The solver (auto, dense or sparse): the same as `--solver-method`, the name this command has always taken.
    #[arg(long, value_enum)]
    pub method: Option<crate::analysis::SolverMethod>,
    /// Band mode: every eigenpair with λ in [A, B] (then -k is ignored), e.g. `--band 0,100`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub band: Option<Vec<f64>>,
    /// Add the counting function N(λ) at each eigenvalue beside Weyl's law (`counting`).
    #[arg(long)]
    pub counting: bool,
    /// Continuum eigenvalues with error bars by Richardson extrapolation over refinements, graded toward the
    /// corners that limit the order (flat triangle meshes and tet meshes; `extrapolate`).
    #[arg(long)]
    pub extrapolate: bool,
    /// Refinements for --extrapolate (1 to 3; only with it).
    #[arg(long, default_value_t = crate::analysis::refinements_default())]
    pub refinements: usize,
    /// With --extrapolate: uniform levels, without grading toward the corners that limit the order (`grading:
    /// false`; only with --extrapolate).
    #[arg(long)]
    pub no_grading: bool,
    /// Check by Sylvester's inertia (one LDLᵀ of L − τM) that no eigenvalue below the found ones was missed, and
    /// solve again for any that were: the default (the result's `solver.completeness`); the flag is kept for
    /// scripts written when it was not.
    #[arg(long = "verify", id = "verify_default", overrides_with = "verify")]
    pub verify_default: bool,
}

pub fn run(a: SpectrumCmd) -> Result<(), Failure> {
    let band = match a.band.as_deref() {
        None => None,
        Some(&[lo, hi]) => Some([lo, hi]),
        Some(b) => {
            return Err(Failure { code: 2, message: format!("--band takes two numbers A,B; {} given", b.len()) })
        }
    };
    let request = Analysis::Spectrum {
        k: a.k,
        band,
        eigenvectors: a.eigenvectors.is_some(),
        counting: a.counting,
        extrapolate: a.extrapolate,
        refinements: a.refinements,
        grading: !a.no_grading,
        operator: a.op.clone(),
        solver: SolverSpec { method: a.method.unwrap_or(a.solver.method), ..a.solver.clone() },
    };
    let t0 = Instant::now();
    let (v, _) = a.shape.load()?;
    let read_s = t0.elapsed().as_secs_f64();
    let hooks = Hooks { threads: a.threads, ..Default::default() };
    let mut out = super::on_pool(a.threads, || analysis::run(&v, &request, hooks))?;
    if let Some(path) = &a.eigenvectors {
        let e = &out.arrays[0];
        std::fs::write(path, kac_core::io::npy::encode_f64(e.rows, e.cols, &e.data))
            .map_err(|e| Failure { code: 1, message: format!("cannot write {}: {e}", path.display()) })?;
        out.summary["eigenvectors"] = path.display().to_string().into();
    }
    out.summary["timings"]["read_s"] = read_s.into();
    out.summary["timings"]["total_s"] = t0.elapsed().as_secs_f64().into();
    print_json(&out.summary)
}
