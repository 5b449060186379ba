//! Eigenpairs for an analysis: the operator it names, and the solve, reused through the eigenpair cache.

use super::*;

/// The cache key of a spectrum: the operator and what of the solver changes the pairs returned (the shape id is the
/// caller's). Of the solver, the tolerance bounds every pair's residual and `verify` whether completeness is
/// proven (an unverified spectrum must not serve a request that asks for the check); the method, shift, block,
/// subspace, slices and threads change how the same pairs are found, not which, so they share one entry.
pub fn spectrum_key(op: &OperatorSpec, solver: &SolverSpec) -> String {
    serde_json::to_string(&json!({
        "operator": op,
        "solver": { "tol": solver.tol, "verify": solver.verify },
        "version": ALGORITHM_VERSION
    }))
    .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two requests that differ only in how the pairs are found (block, subspace, slices, method, shift) share a
    /// cache entry; a tolerance or the completeness check apart, they do not.
    #[test]
    fn the_cache_key_holds_only_what_changes_the_pairs() {
        let op = OperatorSpec::default();
        let base = SolverSpec::default();
        let key = spectrum_key(&op, &base);
        let how: Vec<SolverSpec> = vec![
            SolverSpec { block: Some(16), ..base.clone() },
            SolverSpec { subspace: Some(300), ..base.clone() },
            SolverSpec { slices: Some(4), ..base.clone() },
            SolverSpec { method: SolverMethod::Dense, ..base.clone() },
            SolverSpec { sigma: Some(-0.5), ..base.clone() },
        ];
        for s in how {
            assert_eq!(spectrum_key(&op, &s), key, "{s:?}");
        }
        assert_ne!(spectrum_key(&op, &SolverSpec { tol: base.tol * 10.0, ..base.clone() }), key);
        assert_ne!(spectrum_key(&op, &SolverSpec { verify: !base.verify, ..base.clone() }), key);
    }
}

/// Computed eigenpairs with the operator they belong to.
pub struct Eigen {
    pub operator: Operator,
    pub spectrum: Spectrum,
    /// Seconds spent building the operator.
    pub assembly_s: f64,
}

/// Where computed eigenpairs are kept between analyses (the service's cache; the CLI has none). `get` returns
/// an entry with at least `k` pairs for the key, if one exists.
pub trait SpectrumCache: Sync {
    fn get(&self, key: &str, k: usize) -> Option<Arc<Eigen>>;
    fn put(&self, key: &str, eigen: Arc<Eigen>);
}

/// Hooks passed down to the eigensolver.
#[derive(Default, Clone, Copy)]
pub struct Hooks<'a> {
    pub control: Control<'a>,
    pub cache: Option<&'a dyn SpectrumCache>,
    /// Solver threads (0: rayon's pool).
    pub threads: usize,
    /// Told about every eigensolve (for metrics).
    pub on_solve: Option<&'a (dyn Fn(&kac_core::spectrum::Stats) + Sync)>,
    /// What a request may make the solver hold (the service's limits; none for the CLI).
    pub limits: SolverLimits,
}

/// Bounds on what a request may make the solver hold, checked once the operator's size is known.
#[derive(Clone, Copy, Debug)]
pub struct SolverLimits {
    /// Eigenpairs a band may return (the service's --max-k).
    pub max_pairs: usize,
    /// Values of any one array held: eigenvectors of a band, the dense pencil (unknowns²), the Krylov basis
    /// (the service's --max-output-values).
    pub max_values: usize,
}

impl Default for SolverLimits {
    fn default() -> Self {
        SolverLimits { max_pairs: usize::MAX, max_values: usize::MAX }
    }
}

impl SolverLimits {
    /// A forced dense solve holds the n × n pencil.
    fn check_dense(&self, solver: &SolverSpec, n: usize) -> Result<(), AnalysisError> {
        let values = n.saturating_mul(n);
        if solver.method == SolverMethod::Dense && values > self.max_values {
            return Err(AnalysisError::TooLarge(format!(
                "solver.method = dense holds the {n} × {n} pencil ({values} values), above the limit of {} \
                 (--max-output-values); use auto or sparse",
                self.max_values
            )));
        }
        Ok(())
    }
}

pub fn build_operator(v: &Validated, spec: &OperatorSpec) -> Result<Operator, AnalysisError> {
    Ok(operators::build(&v.shape, &operator_options(v, spec)?)?)
}

/// The core's options for an operator request (vertex indices mapped to the validated numbering).
pub fn operator_options(v: &Validated, spec: &OperatorSpec) -> Result<OperatorOptions, AnalysisError> {
    let boundary = match (&spec.dirichlet_vertices, spec.boundary) {
        (Some(list), _) => Boundary::DirichletVertices(
            map_vertices(v, list, "dirichlet_vertices")?.iter().map(|&i| i as u32).collect(),
        ),
        (None, BoundarySpec::Dirichlet) => Boundary::Dirichlet,
        (None, BoundarySpec::Neumann) => Boundary::Neumann,
    };
    let o = OperatorOptions {
        operator: spec.operator,
        mass: spec.mass,
        boundary,
        cloud: CloudParams {
            k: spec.neighbours,
            neighbourhood: spec.neighbourhood,
            t: spec.time,
            radius: spec.radius,
            dimension: spec.intrinsic_dimension,
            normalization: spec.normalization,
            denoise: spec.denoise,
        },
        order: spec.order,
        midpoints: spec.midpoints,
        polygons: v.polygons.clone(),
        edge_nodes: v.edge_nodes.clone(),
        ..Default::default()
    };
    Ok(o)
}

/// Zero modes to expect: connected components of the operator for a Neumann problem, none for Dirichlet.
pub(crate) fn expected_zero_modes(op: &Operator) -> usize {
    if op.dirichlet() {
        0
    } else {
        components(&op.pair).1
    }
}

/// Eigenpairs for an analysis: from the cache when it holds enough, else solved (and cached).
pub fn eigenpairs(
    v: &Validated,
    spec: &OperatorSpec,
    solver: &SolverSpec,
    k: usize,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<Arc<Eigen>, AnalysisError> {
    if k == 0 {
        // Before the cache, which holds at least as many pairs as any k and would answer k = 0 with none.
        return Err(AnalysisError::invalid_k("k = 0: ask for at least one eigenpair (1 ≤ k ≤ the number of unknowns)"));
    }
    let key = format!("{}:{}", v.id.hex(), spectrum_key(spec, solver));
    if let Some(e) = hooks.cache.and_then(|c| c.get(&key, k)) {
        reused.set(true);
        return Ok(e);
    }
    let (operator, assembly_s) = assemble(v, spec, solver, hooks)?;
    let n = operator.pair.n();
    if k > n {
        return Err(AnalysisError::invalid_k(format!("k = {k} is out of range for {n} unknowns (1 ≤ k ≤ {n})")));
    }
    let options = EigenOptions { max_values: hooks.limits.max_values, ..solver.eigen_options(k, hooks.threads) };
    let spectrum = spectrum::eigs(&operator.pair, &options, None, hooks.control)?;
    if let Some(f) = hooks.on_solve {
        f(&spectrum.stats);
    }
    let e = Arc::new(Eigen { operator, spectrum, assembly_s });
    if let Some(c) = hooks.cache {
        c.put(&key, e.clone());
    }
    Ok(e)
}

/// Shapes with more vertices than this (or any P2 operator) are assembled where a stop can leave the assembly.
const ASSEMBLY_WATCHED_FROM: usize = 50_000;

/// The operator a solve needs, with its assembly time, between stop checks and within the dense limit.
fn assemble(
    v: &Validated,
    spec: &OperatorSpec,
    solver: &SolverSpec,
    hooks: Hooks<'_>,
) -> Result<(Operator, f64), AnalysisError> {
    hooks.control.check()?;
    let t0 = std::time::Instant::now();
    // Assembly cannot stop inside (P2 tets of 30k unknowns: 0.3-0.5 s, once 1.6 s under load): beyond a small
    // shape it runs where a cancel or a timeout can leave it (the abandoned assembly finishes on its own thread).
    let large = v.shape.vertex_count() > ASSEMBLY_WATCHED_FROM || spec.order == 2;
    let operator = if large && hooks.control.stop.is_some() {
        let (owned, spec) = (v.clone(), spec.clone());
        hooks.control.abandonable("assembly", move || build_operator(&owned, &spec))??
    } else {
        build_operator(v, spec)?
    };
    let assembly_s = t0.elapsed().as_secs_f64();
    hooks.control.check()?;
    hooks.limits.check_dense(solver, operator.pair.n())?;
    Ok((operator, assembly_s))
}

/// Every eigenpair with λ in [a, b] (not cached: the cache holds the smallest pairs), at most
/// `hooks.limits.max_pairs` of them and no more eigenvectors than `hooks.limits.max_values` values.
pub fn band_pairs(
    v: &Validated,
    spec: &OperatorSpec,
    solver: &SolverSpec,
    band: [f64; 2],
    hooks: Hooks<'_>,
) -> Result<Eigen, AnalysisError> {
    let (operator, assembly_s) = assemble(v, spec, solver, hooks)?;
    let n = operator.pair.n();
    let opts = EigenOptions { max_values: hooks.limits.max_values, ..solver.eigen_options(0, hooks.threads) };
    // As many pairs as the eigenvectors and the solver's Krylov bases allow within the limit, so that a band beyond
    // them is refused as such: the band's solves ask for 16, 32, 64, … pairs (`eigs_band`), each counted for the
    // zero modes the operator can have (its components) and as one run where it has no Weyl's law to plan slices by.
    let mut max_pairs = hooks.limits.max_pairs.min(hooks.limits.max_values / n.max(1)).max(1);
    if opts.max_values < usize::MAX {
        let (most, weyl) = (operator.pair.components().1, operator.pair.dimension.is_some());
        let fits = |k: usize| {
            spectrum::slicing::predicted_basis(n, &EigenOptions { k, ..opts.clone() }, most, weyl)
                .is_none_or(|c| n.saturating_mul(c) <= opts.max_values)
        };
        let (limit, mut k, mut last) = (n.saturating_sub(1).max(1), 16usize.min(n.saturating_sub(1)).max(1), 0);
        loop {
            let k_asked = k.min(max_pairs);
            if !fits(k_asked) {
                max_pairs = last.max(1);
                break;
            }
            if k_asked >= max_pairs || k_asked >= limit {
                break;
            }
            last = k_asked;
            k = (2 * k_asked).min(limit);
        }
    }
    let spectrum = spectrum::eigs_band(&operator.pair, band[0], band[1], max_pairs, &opts, hooks.control)?;
    if let Some(f) = hooks.on_solve {
        f(&spectrum.stats);
    }
    Ok(Eigen { operator, spectrum, assembly_s })
}
