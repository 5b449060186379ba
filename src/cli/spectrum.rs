//! `kac spectrum FILE -k K [--operator NAME] [--mass NAME] [--boundary neumann|dirichlet]
//! [--eigenvectors OUT.npy] [--threads N]`: the k smallest eigenpairs of L φ = λ M φ as JSON.

use super::{print_json, Failure, ShapeArgs};
use crate::analysis::OperatorSpec;
use clap::Args;
use kac_core::spectrum::{self, Control, EigenOptions, Method};
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args)]
pub struct SpectrumCmd {
    #[command(flatten)]
    pub shape: ShapeArgs,
    #[command(flatten)]
    pub op: OperatorSpec,
    /// Number of eigenpairs.
    #[arg(short = 'k', long = "k", default_value_t = 10)]
    pub k: usize,
    /// Write the eigenvectors as a (vertices × k) float64 .npy, in the input file's vertex numbering
    /// (zeros on a Dirichlet boundary, NaN for vertices validation dropped).
    #[arg(long)]
    pub eigenvectors: Option<PathBuf>,
    /// Threads for the factorization and solves (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Relative residual tolerance.
    #[arg(long, default_value_t = kac_core::spectrum::DEFAULT_TOL)]
    pub tol: f64,
    /// Solver: auto, dense or sparse.
    #[arg(long, default_value = "auto", value_parser = ["auto", "dense", "sparse"])]
    pub method: String,
    /// Shift σ of the shift-invert solver: below the spectrum (σ < 0) L − σM is factored by Cholesky, inside it
    /// by LDLᵀ (default: inside, at 0.7 × Weyl's estimate of λ_k, for meshes, curves and point clouds with k ≥ 8;
    /// −mean(L_ii/M_ii)/n for graphs and small k).
    #[arg(long, allow_hyphen_values = true)]
    pub sigma: Option<f64>,
    /// Band mode: every eigenpair with λ in [A, B] (then -k is ignored), e.g. `--band 0,100`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub band: Option<Vec<f64>>,
    /// Tuning of the sparse solver: right-hand sides per block solve (default 8).
    #[arg(long)]
    pub block: Option<usize>,
    /// Tuning of the sparse solver: Krylov subspace columns kept between restarts (default: see the README).
    #[arg(long)]
    pub subspace: Option<usize>,
    /// Check by Sylvester's inertia (one LDLᵀ of L − τM) that no eigenvalue below the found ones was missed, and
    /// solve again for any that were: the default (the result's `solver.completeness`); the flag is kept for
    /// scripts written when it was not.
    #[arg(long, overrides_with = "no_verify")]
    pub verify: bool,
    /// Skip the completeness check (`solver.completeness` is then null).
    #[arg(long)]
    pub no_verify: bool,
}

pub fn run(a: SpectrumCmd) -> Result<(), Failure> {
    if a.threads > 0 {
        let _ = rayon::ThreadPoolBuilder::new().num_threads(a.threads).build_global();
    }
    let t0 = Instant::now();
    let (v, _) = a.shape.load()?;
    let read_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let op = crate::analysis::build_operator(&v, &a.op)?;
    let assembly_s = t1.elapsed().as_secs_f64();
    let method = match a.method.as_str() {
        "dense" => Method::Dense,
        "sparse" => Method::Sparse,
        _ => Method::Auto,
    };
    let opts = EigenOptions {
        k: a.k,
        tol: a.tol,
        threads: a.threads,
        method,
        sigma: a.sigma,
        block: a.block,
        subspace: a.subspace,
        verify: !a.no_verify,
        ..Default::default()
    };
    let result = match &a.band {
        Some(band) if band.len() != 2 => {
            return Err(Failure { code: 2, message: format!("--band takes two numbers A,B; {} given", band.len()) })
        }
        Some(band) => spectrum::eigs_band(&op.pair, band[0], band[1], &opts, Control::default()),
        None => spectrum::eigs(&op.pair, &opts, None, Control::default()),
    };
    let s = result.map_err(|e| Failure { code: if e.caller_fault() { 2 } else { 1 }, message: e.to_string() })?;
    if let Some(path) = &a.eigenvectors {
        let (rows, k) = (v.vertex_map.len(), s.values.len());
        let data = v.to_input_rows(s.vectors.as_ref(), |col| op.expand(col));
        std::fs::write(path, kac_core::io::npy::encode_f64(rows, k, &data))
            .map_err(|e| Failure { code: 1, message: format!("cannot write {}: {e}", path.display()) })?;
    }
    let st = &s.stats;
    print_json(&json!({
        "shape_id": v.id.hex(),
        "operator": op.kind.name(),
        "mass": op.mass.name(),
        "boundary": op.boundary,
        "size": op.pair.n(),
        "k": s.values.len(),
        "band": a.band,
        "eigenvalues": s.values,
        "residuals": s.residuals,
        "residual_norm": "‖Lφ − λMφ‖₂ / (max(|λ|, |σ|)·‖Mφ‖₂)",
        "eigenvectors": a.eigenvectors.as_ref().map(|p| p.display().to_string()),
        "parameters": op.parameters,
        "solver": {
            "method": st.method, "sigma": st.sigma, "block": st.block, "subspace": st.subspace, "restarts": st.restarts,
            "block_steps": st.block_steps, "solves": st.solves, "factor_nonzeros": st.factor_nnz,
            "factorization": st.factorization, "below_sigma": st.below_sigma, "tol": a.tol,
            "components": st.components, "zero_modes": st.zero_modes,
            "threads": if a.threads == 0 { rayon::current_num_threads() } else { a.threads },
            "completeness": st.completeness,
        },
        "timings": {
            "read_s": read_s, "assembly_s": assembly_s, "symbolic_s": st.timings.symbolic_s, "factorization_s": st.timings.numeric_s,
            "iteration_s": st.timings.iteration_s, "solve_s": st.timings.solve_s,
            "orthogonalize_s": st.timings.orthogonalize_s, "rayleigh_ritz_s": st.timings.rayleigh_ritz_s,
            "restart_s": st.timings.restart_s, "verify_s": st.timings.verify_s, "total_s": t0.elapsed().as_secs_f64(),
        },
    }))?;
    Ok(())
}
