//! The runner: one analysis of a validated shape, from its eigenpairs (or its operator) to the output.

use super::*;

/// A truncated view of cached eigenpairs (the first k).
/// Rows of the eigenvectors per chunk of a per-vertex signature; the stop flag is checked between chunks (a chunk
/// of SI-HKS at k = 500 with 385 τ samples is about 0.3 s of work).
pub(crate) const SIGNATURE_ROWS: usize = 16_384;

/// A per-vertex signature computed chunk by chunk of vertices (each vertex's row depends on its own eigenvector
/// entries and on the eigenvalues only; the grid and every other field come out the same from every chunk), so
/// that a cancel or a timeout takes effect between chunks.
pub(crate) fn by_rows<T>(
    b: &Basis<'_>,
    control: &Control<'_>,
    f: impl Fn(&Basis<'_>) -> Result<T, DescriptorError>,
    values: impl Fn(&mut T) -> &mut faer::Mat<f64>,
) -> Result<T, AnalysisError> {
    let n = b.n();
    if n == 0 {
        return Ok(f(b)?);
    }
    let mut first: Option<T> = None;
    let mut full = faer::Mat::<f64>::zeros(0, 0);
    for r0 in (0..n).step_by(SIGNATURE_ROWS) {
        control.check()?;
        let rows = SIGNATURE_ROWS.min(n - r0);
        let mut part = f(&Basis::new(b.values, b.vectors.subrows(r0, rows), b.zero_tol))?;
        let m = values(&mut part);
        if first.is_none() {
            full = faer::Mat::zeros(n, m.ncols());
        }
        full.as_mut().subrows_mut(r0, rows).copy_from(m.as_ref());
        if first.is_none() {
            first = Some(part);
        }
    }
    let mut out = first.expect("n > 0 rows give a first chunk");
    *values(&mut out) = full;
    Ok(out)
}

pub(crate) fn basis_of(e: &Eigen, k: usize) -> Basis<'_> {
    let k = k.min(e.spectrum.values.len());
    Basis::new(
        &e.spectrum.values[..k],
        e.spectrum.vectors.as_ref().subcols(0, k),
        kac_core::descriptors::zero_threshold(&e.operator.pair),
    )
}

/// What one analysis computed, before the head every result has: its own numbers, its arrays, the fingerprints
/// it found (shape-DNA, for the search index) and its warnings.
pub(crate) struct Part {
    pub body: Summary,
    pub arrays: Vec<VertexArray>,
    pub fingerprints: Vec<Fingerprint>,
    pub warnings: Vec<Warning>,
}

impl Part {
    pub fn new(body: Summary, arrays: Vec<VertexArray>) -> Self {
        Self { body, arrays, fingerprints: vec![], warnings: vec![] }
    }
}

/// The output of a `spectrum` request, one schema for the CLI and the service: the pairs, the operator, the
/// solver's statistics and settings, and the timings (`read_s` is the caller's: null here). The first `k` pairs
/// of `e` are reported (all of them for a band). `eigenvectors` names where the eigenvectors went: the array
/// name here; the CLI puts its file path there.
pub(crate) fn spectrum_output(
    v: &Validated,
    e: &Eigen,
    k: usize,
    band: Option<[f64; 2]>,
    eigenvectors: bool,
    solver: &SolverSpec,
    threads: usize,
) -> (SpectrumSummary, Vec<VertexArray>) {
    let s = &e.spectrum;
    let k = k.min(s.values.len());
    let st = &s.stats;
    let t = &st.timings;
    let mut arrays = vec![];
    if eigenvectors {
        let mut a = to_input_rows(v, &e.operator, s.vectors.as_ref().subcols(0, k), "eigenvectors");
        a.columns = Some(s.values[..k].to_vec());
        arrays.push(a);
    }
    let summary = SpectrumSummary {
        k,
        band,
        residual_norm: "‖Lφ − λMφ‖₂ / (max(|λ|, |σ|)·‖Mφ‖₂)",
        sign_convention: signatures::SIGN_CONVENTION,
        eigenvalues: s.values[..k].to_vec(),
        residuals: s.residuals[..k.min(s.residuals.len())].to_vec(),
        eigenvectors: eigenvectors.then(|| "eigenvectors".to_string()),
        solver: SolverReport {
            method: st.method,
            sigma: st.sigma,
            block: st.block,
            subspace: st.subspace,
            restarts: st.restarts,
            block_steps: st.block_steps,
            solves: st.solves,
            factor_nonzeros: st.factor_nnz,
            factorization: st.factorization,
            below_sigma: st.below_sigma,
            components: st.components,
            zero_modes: st.zero_modes,
            completeness: st.completeness.clone(),
            tol: solver.tol,
            threads: if threads == 0 { rayon::current_num_threads() } else { threads },
            slices: st.slices.clone(),
            plan: st.plan.clone(),
        },
        timings: SpectrumTimings {
            read_s: None,
            assembly_s: e.assembly_s,
            symbolic_s: t.symbolic_s,
            numeric_s: t.numeric_s,
            factorization_s: t.numeric_s,
            iteration_s: t.iteration_s,
            solve_s: t.solve_s,
            orthogonalize_s: t.orthogonalize_s,
            rayleigh_ritz_s: t.rayleigh_ritz_s,
            restart_s: t.restart_s,
            verify_s: t.verify_s,
            total_s: e.assembly_s + t.total_s,
        },
        // Also at the top level, where results before the check was on by default carried it.
        completeness: st.completeness.clone(),
        eigenvalues_source: "mesh",
        mesh_eigenvalues: None,
        error_estimate: None,
        extrapolation: None,
        counting: None,
        operator: OperatorUsed::of(&e.operator),
    };
    (summary, arrays)
}

pub fn measures(v: &Validated, op: Option<&Operator>) -> Measures {
    let mass_total = op.map(|o| o.pair.mass.iter().sum::<f64>());
    let m = Measures::of(&v.summary(), mass_total);
    // A point cloud's measure is its operator's total mass, in the intrinsic dimension the operator used (a
    // curve's length, a surface's area, a solid's volume; none above 3).
    match (&v.shape, op) {
        (Shape::PointCloud(_), Some(o)) if o.pair.dimension != Some(2) => {
            let d = o.pair.dimension.unwrap_or(0);
            Measures {
                dimension: d,
                length: mass_total.filter(|_| d == 1),
                area: None,
                volume: mass_total.filter(|_| d == 3),
                has_boundary: None,
                condition: None,
            }
        }
        _ => m,
    }
}

/// Mesh spacings per wavelength below which the highest computed eigenvalues, on which Weyl's estimates rest, are
/// too high for the estimates to hold (P1 eigenvalues err by about (λh)²/12 relative: 5 % at 5 spacings).
pub const WEYL_MIN_SPACINGS_PER_WAVELENGTH: f64 = 10.0;

/// Warnings about Weyl's estimates: `weyl-underresolved` when the wavelength 2π/√λ_k of the highest eigenvalue
/// used spans fewer than [`WEYL_MIN_SPACINGS_PER_WAVELENGTH`] mesh spacings h = (|Ω|/n)^{1/d};
/// `weyl-estimate-omitted` when an estimate was left out because the eigenvalues do not resolve it (its 2σ
/// interval reaches zero or the wrong sign; `descriptors::weyl`).
pub(crate) fn weyl_warnings(
    w: Option<&kac_core::descriptors::weyl::WeylEstimate>,
    m: &Measures,
    n: usize,
) -> Vec<Warning> {
    let Some(w) = w else { return vec![] };
    let mut warnings = vec![];
    let mut underresolved = false;
    if let (Some(measure), Some(lk)) = (m.measure(), w.highest_eigenvalue.filter(|l| *l > 0.0)) {
        let h = (measure / n.max(1) as f64).powf(1.0 / f64::from(w.dimension.max(1)));
        let per = 2.0 * std::f64::consts::PI / (lk.sqrt() * h);
        if per < WEYL_MIN_SPACINGS_PER_WAVELENGTH {
            underresolved = true;
            warnings.push(Warning::new(
                "weyl-underresolved",
                format!(
                    "λ_k = {lk:.4e} has a wavelength of {per:.1} mesh spacings (under \
                     {WEYL_MIN_SPACINGS_PER_WAVELENGTH}): the highest eigenvalues, on which Weyl's estimates rest, \
                     are several percent too high and the measure and boundary estimates are biased low; refine the \
                     mesh or lower k"
                ),
            ));
        }
    }
    if !w.unresolved.is_empty() {
        let omitted: Vec<String> = w
            .unresolved
            .iter()
            .map(|u| match (u.estimate, u.uncertainty) {
                (Some(e), Some(s)) => format!("{} ({e:.4} ± {s:.4}: {})", u.field, u.reason),
                _ => format!("{} ({})", u.field, u.reason),
            })
            .collect();
        // What would help depends on why: a mesh too coarse for λ_k is not helped by more eigenvalues.
        let advice = if underresolved {
            "refine the mesh or use order-2 elements (more eigenvalues would not help: the highest are already \
             under-resolved)"
        } else {
            "compute more eigenvalues (a larger k), and check the boundary condition where the boundary has the \
             wrong sign"
        };
        warnings.push(Warning::new(
            "weyl-estimate-omitted",
            format!(
                "the {} non-zero eigenvalues do not resolve Weyl's {}: omitted; {advice}",
                w.eigenvalues_used,
                omitted.join(" and ")
            ),
        ));
    }
    warnings
}

/// The shape-DNA of a shape, typed (for `shape-dna` jobs and comparisons), with the eigenpairs it came from and
/// the number of pairs asked for (k plus the expected zero modes unless they are included).
pub fn shape_dna_of(
    v: &Validated,
    options: &ShapeDnaOptions,
    operator: &OperatorSpec,
    solver: &SolverSpec,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<(Arc<Eigen>, shape_dna::ShapeDna, usize), AnalysisError> {
    let op = build_operator(v, operator)?;
    let zeros = if options.include_zero { 0 } else { expected_zero_modes(&op) };
    let want = (options.k + zeros).min(op.pair.n());
    let e = eigenpairs(v, operator, solver, want, hooks, reused)?;
    let b = basis_of(&e, want);
    let m = measures(v, Some(&e.operator));
    let dna = shape_dna::shape_dna(b.values, b.zero_tol, &m, options)?;
    Ok((e, dna, want))
}

use kac_core::spectrum::factor;

/// Shapes from this many vertices (or with P2 elements) have their analyses without an eigensolve run where a
/// stop can leave them: their factorizations and assemblies are single calls that do not see the flag.
pub const WATCHED_FROM_VERTICES: usize = 50_000;

/// Runs an analysis on a validated shape.
pub fn run(v: &Validated, analysis: &Analysis, hooks: Hooks<'_>) -> Result<Output, AnalysisError> {
    analysis.supported(&v.shape)?;
    // Every per-vertex input bounded and every index in range before anything is computed.
    analysis.check_inputs(v)?;
    // The analyses that solve no eigenproblem (Poisson, implicit heat and diffusion, geodesics, smoothing,
    // interpolation, the operator, curvature, gradient, ...) factor and assemble in calls a stop flag cannot reach
    // inside: on a large shape they run on a thread the caller can leave at once (`Control::abandonable`); the
    // abandoned work finishes with its result dropped.
    let large =
        v.shape.vertex_count() >= WATCHED_FROM_VERTICES || analysis.operator_spec().is_some_and(|o| o.order == 2);
    if hooks.control.stop.is_some() && large && !analysis.solves_eigenpairs() {
        let (owned, a) = (v.clone(), analysis.clone());
        let (threads, limits) = (hooks.threads, hooks.limits);
        return hooks.control.abandonable("analysis", move || {
            factor::with_factor_limit(limits.max_values, || {
                run_here(&owned, &a, Hooks { threads, limits, ..Default::default() })
            })
        })?;
    }
    // Every factorization outside the eigensolver checks its predicted fill against the same limit.
    factor::with_factor_limit(hooks.limits.max_values, || run_here(v, analysis, hooks))
}

fn run_here(v: &Validated, analysis: &Analysis, hooks: Hooks<'_>) -> Result<Output, AnalysisError> {
    // Whether the eigenpairs came from the cache (no eigensolve for this analysis).
    let reused = std::cell::Cell::new(false);
    // Every eigensolve that took another path than the one it planned, told as a warning.
    let changed = std::sync::Mutex::new(Vec::<kac_core::spectrum::PlanChange>::new());
    let outer = hooks.on_solve;
    let watch = |s: &kac_core::spectrum::Stats| {
        if let Some(p) = &s.plan {
            changed.lock().unwrap_or_else(|e| e.into_inner()).push(p.clone());
        }
        if let Some(f) = outer {
            f(s);
        }
    };
    let part = compute(v, analysis, Hooks { on_solve: Some(&watch), ..hooks }, &reused)?;
    // Every result has `warnings` (the one place it says a number is outside its domain of validity), with what
    // the operator's parameters tell (a point cloud's dimension and noise) after the analysis' own.
    let mut warnings = part.warnings;
    for p in changed.into_inner().unwrap_or_else(|e| e.into_inner()) {
        warnings.push(Warning::new(
            "solver-fallback",
            format!("the eigensolver planned {} but solved by {}: {}", p.planned, p.taken, p.reason),
        ));
    }
    if let Some(parameters) = parameters_of(&part.body) {
        warnings.extend(operator_warnings(parameters));
    }
    let head = ResultHead {
        shape_id: v.id.hex(),
        algorithm_version: ALGORITHM_VERSION,
        eigenpairs_reused: reused.get(),
        warnings,
    };
    // Every number checked before the result is returned (and so before the service stores it); per-vertex rows
    // without a value are those validation dropped and the points the operator left out (a cloud's outliers).
    let left_out =
        parameters_of(&part.body).and_then(|p| p.get("outliers")?.get("dropped")?.as_u64()).map_or(0, |n| n as usize);
    let typed = Typed { head, body: part.body };
    finite::checked_output(&typed, part.arrays, part.fingerprints, |a| is_per_vertex(a.name).then_some(v), left_out)
}

/// What a spectral heat trace's bound covers.
const HEAT_TRACE_ERROR: &str = "truncation only: `heat_trace_truncation_bound` bounds what the k pairs miss of the \
    discrete trace; the discretization error (the mesh's eigenvalues against the surface's, O(h²) for P1 elements: on \
    the unit sphere of 2,562 vertices the trace at t = 0.1 is 0.8 % low) is not included: `spectrum` with \
    `extrapolate` estimates each eigenvalue's";

/// The parameters of the operator a result used, where it names one.
fn parameters_of(body: &Summary) -> Option<&serde_json::Map<String, Value>> {
    Some(match body {
        Summary::Spectrum(s) => &s.operator.parameters,
        Summary::Operator(s) => &s.operator.parameters,
        Summary::Hks(s) => &s.operator.parameters,
        Summary::SiHks(s) => &s.operator.parameters,
        Summary::Wks(s) => &s.operator.parameters,
        Summary::Gps(s) => &s.operator.parameters,
        Summary::ShapeDna(s) => &s.operator.parameters,
        Summary::Heat(s) => &s.operator.parameters,
        Summary::HeatCurvature(s) => &s.operator.parameters,
        Summary::Wave(s) => &s.operator.parameters,
        Summary::Schrodinger(s) => &s.operator.parameters,
        Summary::Poisson(s) => &s.parameters,
        Summary::Diffuse(s) => &s.operator.parameters,
        Summary::DirichletEnergy(s) => &s.operator.parameters,
        Summary::Embed(s) => &s.operator.parameters,
        Summary::Smooth(s) => &s.operator.parameters,
        Summary::Interpolate(s) => &s.operator.parameters,
        Summary::Geodesic(_)
        | Summary::Gradient(_)
        | Summary::Divergence(_)
        | Summary::Trees(_)
        | Summary::MeanCurvature(_)
        | Summary::Compare(_) => return None,
        Summary::Correspondence(s) => &s.operator.parameters,
    })
}

fn compute(
    v: &Validated,
    analysis: &Analysis,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<Part, AnalysisError> {
    Ok(match analysis {
        Analysis::Spectrum { k, band, eigenvectors, counting, extrapolate, refinements, grading, operator, solver } => {
            analysis.check_options()?;
            let (e, k) = match band {
                Some(band) => {
                    let e = Arc::new(band_pairs(v, operator, solver, *band, hooks)?);
                    let k = e.spectrum.values.len();
                    (e, k)
                }
                None => (eigenpairs(v, operator, solver, *k, hooks, reused)?, *k),
            };
            let (mut summary, arrays) = spectrum_output(v, &e, k, *band, *eigenvectors, solver, hooks.threads);
            if *counting {
                let values = &e.spectrum.values[..k.min(e.spectrum.values.len())];
                summary.counting = Some(operator::counting(v, &e, values, operator));
            }
            if *extrapolate {
                hooks.control.phase("extrapolating", 0, 0)?;
                let x = extrapolate::extrapolation(v, operator, solver, k, *refinements, *grading, hooks)?;
                // The answer asked for is the headline: `eigenvalues` are the extrapolated values, with their error
                // estimate beside them; the input mesh's own discrete values move to `mesh_eigenvalues` (they are
                // also the first level's).
                summary.mesh_eigenvalues = Some(std::mem::replace(&mut summary.eigenvalues, x.eigenvalues.clone()));
                summary.error_estimate = Some(x.error_estimate.clone());
                summary.eigenvalues_source = "extrapolation";
                summary.extrapolation = Some(x);
            }
            Part::new(Summary::Spectrum(Box::new(summary)), arrays)
        }
        Analysis::Operator { report, matrices, operator } => {
            operator::operator_output(v, operator, *report, *matrices, hooks)?
        }
        Analysis::Hks { k, options, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let h = by_rows(&basis_of(&e, *k), &hooks.control, |b| signatures::hks(b, options), |h| &mut h.values)?;
            let a = signature(v, &e, h.values.as_ref(), "hks", h.times.clone());
            let body = HksSummary { k: *k, hks: h, options: options.clone(), operator: OperatorUsed::of(&e.operator) };
            Part::new(Summary::Hks(body), vec![a])
        }
        Analysis::SiHks { k, options, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let h = by_rows(&basis_of(&e, *k), &hooks.control, |b| signatures::si_hks(b, options), |h| &mut h.values)?;
            let columns = h.frequencies.iter().map(|&f| f as f64).collect();
            let a = signature(v, &e, h.values.as_ref(), "si_hks", columns);
            let body =
                SiHksSummary { k: *k, si_hks: h, options: options.clone(), operator: OperatorUsed::of(&e.operator) };
            Part::new(Summary::SiHks(body), vec![a])
        }
        Analysis::Wks { k, options, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let w = by_rows(&basis_of(&e, *k), &hooks.control, |b| signatures::wks(b, options), |w| &mut w.values)?;
            let a = signature(v, &e, w.values.as_ref(), "wks", w.energies.clone());
            let body = WksSummary { k: *k, wks: w, options: options.clone(), operator: OperatorUsed::of(&e.operator) };
            Part::new(Summary::Wks(body), vec![a])
        }
        Analysis::Gps { k, dimensions, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            // Not by rows: each eigenvector's sign is fixed by its largest entry over all vertices.
            hooks.control.phase("descriptor", 0, 0)?;
            let g = signatures::gps(&basis_of(&e, *k), *dimensions)?;
            let a = signature(v, &e, g.values.as_ref(), "gps", g.eigenvalues.clone());
            Part::new(Summary::Gps(GpsSummary { k: *k, gps: g, operator: OperatorUsed::of(&e.operator) }), vec![a])
        }
        Analysis::ShapeDna { options, operator, solver } => {
            let (e, dna, want) = shape_dna_of(v, options, operator, solver, hooks, reused)?;
            let b = basis_of(&e, want);
            let mut m = measures(v, Some(&e.operator));
            // The operator's boundary condition gives the sign of Weyl's boundary term (given Dirichlet vertices:
            // mixed, no boundary estimate).
            use kac_core::descriptors::shape_dna::BoundaryCondition;
            m.condition = Some(match (e.operator.dirichlet(), operator.dirichlet_vertices.is_some()) {
                (false, _) => BoundaryCondition::Neumann,
                (true, true) => BoundaryCondition::Mixed,
                (true, false) => BoundaryCondition::Dirichlet,
            });
            let weyl = weyl_estimate(b.values, b.zero_tol, &m).ok();
            let warnings = weyl_warnings(weyl.as_ref(), &m, e.operator.pair.n());
            let family = fingerprint_family(options, operator);
            let fingerprints = vec![Fingerprint { family, shape_id: v.id.hex(), values: dna.values.clone() }];
            let body = ShapeDnaSummary {
                shape_dna: dna,
                weyl,
                measures: m,
                options: options.clone(),
                residuals: e.spectrum.residuals[..want.min(e.spectrum.residuals.len())].to_vec(),
                operator: OperatorUsed::of(&e.operator),
            };
            Part { body: Summary::ShapeDna(body), arrays: vec![], fingerprints, warnings }
        }
        Analysis::Heat { k, times, sources, method, steps, operator, solver } => {
            let src = map_vertices(v, sources, "sources")?;
            match method {
                HeatMethod::Spectral => {
                    let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
                    let b = basis_of(&e, *k);
                    let times = match times {
                        Some(t) => t.clone(),
                        None => signatures::default_hks_times(&b, 10)?,
                    };
                    kac_core::descriptors::check_times("times", &times)?;
                    let trace = heat_trace(b.values, &times);
                    let tail: Vec<f64> = times.iter().map(|&t| heat_trace_tail_bound(b.values, b.n(), t)).collect();
                    let mut arrays = vec![];
                    let src_op = to_operator_rows(&e.operator, &src)?;
                    let mut reports = vec![];
                    for (s_in, &s) in sources.iter().zip(&src_op) {
                        hooks.control.check()?;
                        // k_t(s, ·) for every t, and what truncation can miss of the flow of the hat function at s.
                        let kt = heat_kernel_row(&b, s, &times)?;
                        let mut u0 = vec![0.0; b.n()];
                        u0[s] = 1.0;
                        let d = diffuse_spectral(&b, &e.operator.pair, &u0, &times)?;
                        reports.push(HeatSource { source: *s_in, hat_function_truncation_bound: d.truncation_bound });
                        let mut a = to_input_rows(v, &e.operator, kt.as_ref(), "heat_kernel");
                        a.columns = Some(times.clone());
                        arrays.push(a);
                    }
                    // Dirichlet problems also lose heat through the boundary: Q(t) = ∫ u(t) from u₀ = 1.
                    let content = match e.operator.dirichlet() {
                        true => Some(kac_core::descriptors::heat::heat_content(&b, &e.operator.pair, &times)?),
                        false => None,
                    };
                    let body = HeatSummary {
                        method: HeatMethod::Spectral,
                        times,
                        sources: HeatSources::Spectral(reports),
                        kernel_arrays: "one per source: the heat kernel k_t(source, ·), a column per time",
                        k: Some(*k),
                        steps: None,
                        heat_trace: Some(trace),
                        heat_trace_tail_bound: Some(tail.clone()),
                        heat_trace_truncation_bound: Some(tail),
                        heat_trace_error: Some(HEAT_TRACE_ERROR),
                        heat_content: content,
                        operator: OperatorUsed::of(&e.operator),
                    };
                    Part::new(Summary::Heat(body), arrays)
                }
                HeatMethod::Implicit => {
                    let op = build_operator(v, operator)?;
                    let times = times
                        .clone()
                        .ok_or_else(|| AnalysisError::invalid_parameter("the implicit method needs times"))?;
                    let src_op = to_operator_rows(&op, &src)?;
                    let mut arrays = vec![];
                    for &s in &src_op {
                        hooks.control.check()?;
                        // The same quantity as the spectral method: the heat kernel k_t(·, s), the flow of the
                        // discrete delta at s (u₀ = M⁻¹e_s, so that ⟨u₀, φ⟩_M = φ(s) for every φ).
                        let u0 = pde::discrete_delta(&op.pair, s)?;
                        let u = pde::heat_implicit(&op.pair, &u0, &times, *steps)?;
                        let mut a = to_input_rows(v, &op, u.as_ref(), "heat_kernel");
                        a.columns = Some(times.clone());
                        arrays.push(a);
                    }
                    let body = HeatSummary {
                        method: HeatMethod::Implicit,
                        times,
                        sources: HeatSources::Implicit(sources.clone()),
                        kernel_arrays:
                            "one per source: the heat kernel k_t(source, ·) by backward Euler from the discrete \
                                 delta M⁻¹e_source, a column per time",
                        k: None,
                        steps: Some(*steps),
                        heat_trace: None,
                        heat_trace_tail_bound: None,
                        heat_trace_truncation_bound: None,
                        heat_trace_error: None,
                        heat_content: None,
                        operator: OperatorUsed::of(&op),
                    };
                    Part::new(Summary::Heat(body), arrays)
                }
            }
        }
        Analysis::Geodesic { sources, options } => {
            let Shape::TriangleMesh(mesh) = &v.shape else {
                return Err(AnalysisError::not_applicable(format!(
                    "geodesics by the heat method need a triangle mesh, not a {}",
                    v.shape.kind().as_str()
                )));
            };
            let src = map_vertices(v, sources, "sources")?;
            let g = geodesic::heat_method(mesh, &src, options)?;
            let n = mesh.vertices.len();
            let mut m = faer::Mat::<f64>::zeros(n, 1 + usize::from(g.varadhan.is_some()));
            for i in 0..n {
                m[(i, 0)] = g.distance[i];
                if let Some(va) = &g.varadhan {
                    m[(i, 1)] = va[i];
                }
            }
            let a = validated_to_input(v, m.as_ref(), "distance");
            let max = g.distance.iter().copied().filter(|d| d.is_finite()).fold(0.0, f64::max);
            let columns = if g.varadhan.is_some() { vec!["heat_method", "varadhan"] } else { vec!["heat_method"] };
            let body = GeodesicSummary {
                geodesic: g,
                options: options.clone(),
                max_distance: max,
                columns,
                operator: "cotan",
                mass: "lumped",
            };
            Part::new(Summary::Geodesic(body), vec![a])
        }
        Analysis::Gradient { function } => {
            let u = from_input_rows(v, function, "function")?;
            hooks.control.check()?;
            let g = kac_core::pde::calculus::gradient(&v.shape, &u)?;
            let data: Vec<f64> = g.iter().flatten().copied().collect();
            let a = VertexArray { name: "gradient", rows: g.len(), cols: 3, data, columns: None };
            let norms: Vec<f64> = g.iter().map(|x| (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt()).collect();
            let body = GradientSummary {
                elements: g.len(),
                gradient_norm: FiniteStats::of(&norms),
                rows: "the validated mesh's elements (triangles or tetrahedra) in order; columns x, y, z",
                definition: "∇u = Σ u_i ∇φ_i, constant on each element (P1)",
            };
            Part::new(Summary::Gradient(body), vec![a])
        }
        Analysis::Divergence { field, mass } => {
            hooks.control.check()?;
            let d = kac_core::pde::calculus::divergence(&v.shape, field)?;
            let mass = mass.unwrap_or(Mass::Lumped);
            // A consistent mass is left out: its inverse is not local, so the boundary's missing flux (the
            // integrated divergence of a field that crosses the boundary) spreads over the whole mesh (−20 to 88
            // for div ∇x² = 2 on the 32 × 32 criss-cross square).
            if !matches!(mass, Mass::Lumped | Mass::Voronoi) {
                return Err(AnalysisError::invalid_parameter(format!(
                    "mass: {}: the pointwise divergence is taken over lumped or voronoi (a consistent mass would spread \
                     the boundary's flux over the whole mesh)",
                    mass.name()
                )));
            }
            // The pointwise divergence: the integrated one over the mass asked for. The operator's vertices are
            // the validated mesh's (every vertex of a mesh is an unknown with Neumann conditions).
            let op = operators::build(&v.shape, &OperatorOptions { mass: Some(mass), ..Default::default() })
                .map_err(|e| AnalysisError::invalid_parameter(format!("mass: {e}")))?;
            let pair = &op.pair;
            if pair.n() != d.len() {
                return Err(AnalysisError::invalid_parameter(format!(
                    "mass: the operator has {} unknowns for {} vertices",
                    pair.n(),
                    d.len()
                )));
            }
            let pointwise: Vec<f64> =
                d.iter().enumerate().map(|(i, x)| x / pair.mass[pair.pattern.diag_pos(i)]).collect();
            let mat = faer::Mat::from_fn(d.len(), 2, |i, j| if j == 0 { d[i] } else { pointwise[i] });
            let a = validated_to_input(v, mat.as_ref(), "divergence");
            let body = DivergenceSummary {
                columns: vec!["integrated", "pointwise"],
                definition: "(div X)_i = −Σ_f |f| X_f·∇φ_i (so div ∇u = −L u); pointwise: the integrated divergence \
                             divided by the vertex's mass (`mass`)",
                mass: mass.name(),
                meaning: match mass {
                    Mass::Voronoi => {
                        "the mean of div X over the vertex's mixed Voronoi cell, the cell the cotan \
                                      Laplacian integrates over: div ∇x² = 2 exactly at the interior vertices of a \
                                      uniform grid, cut by one diagonal or by both"
                    }
                    _ => {
                        "the integrated divergence over a third of the incident triangles' area (a quarter of the \
                          incident tetrahedra's volume): biased where the vertices' cells differ from those shares \
                          (a criss-cross grid: 1.5 and 3.0 for div ∇x² = 2 at its valence-8 and valence-4 vertices)"
                    }
                },
            };
            Part::new(Summary::Divergence(body), vec![a])
        }
        Analysis::Trees {} => {
            let (edges, weights) = operators::edge_graph(&v.shape)
                .ok_or_else(|| AnalysisError::not_applicable("a point cloud has no edges; build a graph first"))?;
            let t = spanning_trees(v.shape.vertex_count(), &edges, &weights)?;
            Part::new(Summary::Trees(TreesSummary { trees: t }), vec![])
        }
        tool @ (Analysis::MeanCurvature { .. }
        | Analysis::HeatCurvature { .. }
        | Analysis::Wave { .. }
        | Analysis::Schrodinger { .. }
        | Analysis::Poisson { .. }
        | Analysis::Diffuse { .. }
        | Analysis::DirichletEnergy { .. }) => tools::run(v, tool, hooks, reused)?,
        Analysis::Embed { dimensions, scaling, operator, solver } => {
            let op = build_operator(v, operator)?;
            let zeros = expected_zero_modes(&op);
            let want = (dimensions + zeros).min(op.pair.n());
            let e = eigenpairs(v, operator, solver, want, hooks, reused)?;
            let b = basis_of(&e, want);
            let (coords, vals) = eigenmap(&b, *dimensions, *scaling == EmbedScaling::Gps)?;
            let f = fiedler(&b, &e.operator.pair, false).ok();
            let mut a = to_input_rows(v, &e.operator, coords.as_ref(), "embedding");
            a.columns = Some(vals.clone());
            let mut arrays = vec![a];
            if let Some(f) = &f {
                let fm = faer::Mat::from_fn(f.vector.len(), 1, |i, _| f.vector[i]);
                arrays.push(to_input_rows(v, &e.operator, fm.as_ref(), "fiedler"));
            }
            let body = EmbedSummary {
                dimensions: *dimensions,
                scaling: *scaling,
                eigenvalues: vals,
                fiedler: f,
                components: components(&e.operator.pair).1,
                sign_convention: signatures::SIGN_CONVENTION,
                operator: OperatorUsed::of(&e.operator),
            };
            Part::new(Summary::Embed(body), arrays)
        }
        Analysis::Smooth { alpha, function, fixed_boundary, operator } => {
            let op = build_operator(v, operator)?;
            let n = op.pair.n();
            if op.dirichlet() {
                return Err(AnalysisError::invalid_parameter(
                    "smoothing takes a Neumann operator; use fixed_boundary to clamp",
                ));
            }
            let (ubar, what) = match function {
                Some(f) => {
                    let mapped = op.restrict(&from_input_rows(v, f, "function")?);
                    (faer::Mat::from_fn(n, 1, |i, _| mapped[i]), "function")
                }
                None => {
                    let pos = v.shape.positions().ok_or_else(|| {
                        AnalysisError::not_applicable("the shape has no coordinates; give a function")
                    })?;
                    let c: Vec<Vec<f64>> =
                        (0..3).map(|j| op.restrict(&pos.iter().map(|p| p[j]).collect::<Vec<_>>())).collect();
                    (faer::Mat::from_fn(n, 3, |i, j| c[j][i]), "coordinates")
                }
            };
            let fixed = fixed_boundary.then(|| {
                // Over the operator's unknowns (P2: an edge unknown is held where both its endpoints are).
                let b: Vec<f64> =
                    operators::boundary::boundary_vertices(&v.shape).iter().map(|&x| f64::from(u8::from(x))).collect();
                op.restrict(&b).iter().map(|&x| x > 0.75).collect::<Vec<bool>>()
            });
            let u = pde::smooth(&op.pair, ubar.as_ref(), *alpha, fixed.as_deref())?;
            let a = to_input_rows(v, &op, u.as_ref(), "smoothed");
            let body = SmoothSummary {
                alpha: *alpha,
                smoothed: what,
                fixed_boundary: *fixed_boundary,
                equation: "(M + αL) u = M ū",
                operator: OperatorUsed::of(&op),
            };
            Part::new(Summary::Smooth(body), vec![a])
        }
        Analysis::Interpolate { values, labels, operator } => {
            let op = build_operator(v, operator)?;
            if op.dirichlet() {
                return Err(AnalysisError::invalid_parameter(
                    "interpolation fixes its own vertices; use a Neumann operator",
                ));
            }
            match (values.is_empty(), labels.is_empty()) {
                (false, true) => {
                    let idx = map_vertices(v, &values.iter().map(|x| x.0).collect::<Vec<_>>(), "values")?;
                    let given: Vec<(usize, f64)> = idx.into_iter().zip(values.iter().map(|x| x.1)).collect();
                    let known = fixed_rows(&v.shape, &op, &given)?;
                    let u = pde::harmonic(&op.pair, &known)?;
                    let um = faer::Mat::from_fn(u.len(), 1, |i, _| u[i]);
                    let a = to_input_rows(v, &op, um.as_ref(), "interpolated");
                    let body = InterpolateSummary {
                        method: "harmonic",
                        known: Some(values.len()),
                        labels: None,
                        operator: OperatorUsed::of(&op),
                    };
                    Part::new(Summary::Interpolate(body), vec![a])
                }
                (true, false) => {
                    let idx = map_vertices(v, &labels.iter().map(|x| x.0).collect::<Vec<_>>(), "labels")?;
                    let idx = to_operator_rows(&op, &idx)?;
                    let l: Vec<(usize, u32)> = idx.into_iter().zip(labels.iter().map(|x| x.1)).collect();
                    let r = pde::labels(&op.pair, &l)?;
                    let lm = faer::Mat::from_fn(r.label.len(), 1, |i, _| r.label[i] as f64);
                    let mut a = to_input_rows(v, &op, lm.as_ref(), "labels");
                    a.columns = None;
                    let mut s = to_input_rows(v, &op, r.scores.as_ref(), "scores");
                    s.columns = Some(r.classes.iter().map(|&c| c as f64).collect());
                    let body = InterpolateSummary {
                        method: "harmonic (Zhu et al. 2003)",
                        known: None,
                        labels: Some(r),
                        operator: OperatorUsed::of(&op),
                    };
                    Part::new(Summary::Interpolate(body), vec![a, s])
                }
                _ => {
                    return Err(AnalysisError::invalid_parameter(
                        "give either values or labels (not both, not neither)",
                    ))
                }
            }
        }
    })
}

/// How far a point cloud's noise level (after denoising) may reach relative to its spacing before the operator is
/// built on points still off their surface.
pub const NOISE_WARN_SPACINGS: f64 = 1.0;

/// Warnings read from an operator's parameters:
/// - `intrinsic-dimension-disagrees`: a point cloud in Rⁿ was given an intrinsic dimension that the neighbourhoods'
///   estimate (Levina–Bickel) rounds to another integer;
/// - `cloud-noisy`: after denoising, the cloud's noise level is above [`NOISE_WARN_SPACINGS`] spacings, so the
///   operator is built on points still scattered about their surface;
/// - `cloud-clumps-kept`: small separate pieces were kept (they hold more than the share that may be dropped);
/// - `cloud-normalization-chapter`: the chapter's uniform-weight normalization, whose spectra are biased.
pub(crate) fn operator_warnings(parameters: &serde_json::Map<String, Value>) -> Vec<Warning> {
    let get = |key: &str| parameters.get(key).unwrap_or(&Value::Null);
    let mut w = vec![];
    let (given, m, estimate) = (
        get("intrinsic_dimension_given").as_bool(),
        get("intrinsic_dimension").as_f64(),
        get("intrinsic_dimension_estimate").as_f64(),
    );
    if let (Some(true), Some(m), Some(e)) = (given, m, estimate) {
        if (e - m).abs() > 0.5 {
            w.push(Warning::new(
                "intrinsic-dimension-disagrees",
                format!(
                    "the intrinsic dimension given is {m}, the neighbourhoods' estimate (Levina–Bickel) {e:.2}: \
                     eigenvalues scale with the dimension used, so check it (regular grids bias the estimate)"
                ),
            ));
        }
    }
    if get("normalization") == "chapter" {
        w.push(Warning::new(
            "cloud-normalization-chapter",
            "the chapter's normalization (eq. 9.39, uniform weights vol/K) biases a cloud's spectrum: 8 % and 20 % \
             low at l = 2 and 3 on the unit sphere's 2,562 points, 15 % high on the first cluster of a 50 × 50 flat \
             torus (tests/truth_table.rs); the default `symmetric` normalization is within 6 % there"
                .into(),
        ));
    }
    let denoise = get("denoise");
    if let (Some(true), Some(noise), Some(h)) =
        (denoise["applied"].as_bool(), denoise["report"]["noise"].as_f64(), get("spacing_h").as_f64())
    {
        if h > 0.0 && noise > NOISE_WARN_SPACINGS * h {
            w.push(Warning::new(
                "cloud-noisy",
                format!(
                    "the cloud's noise level {noise:.3e} is {:.1} spacings (h = {h:.3e}) after denoising: the operator \
                     is built on points still scattered about the surface, and its eigenvalues are biased high",
                    noise / h
                ),
            ));
        }
    }
    if let Some(kept) = get("outliers")["clumps_kept"].as_u64().filter(|&k| k > 0) {
        w.push(Warning::new(
            "cloud-clumps-kept",
            format!(
                "{kept} points in small separate pieces were kept (together above the share that may be dropped): \
                 each piece adds a zero eigenvalue of its own"
            ),
        ));
    }
    w
}

/// A per-vertex signature's values as one array, a column per time, energy or frequency.
pub(crate) fn signature(
    v: &Validated,
    e: &Eigen,
    values: faer::MatRef<'_, f64>,
    name: &'static str,
    columns: Vec<f64>,
) -> VertexArray {
    let mut a = to_input_rows(v, &e.operator, values, name);
    a.columns = Some(columns);
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signatures computed by chunks of vertices equal the signature of the whole basis, and a raised stop flag
    /// ends the computation between chunks.
    #[test]
    fn signatures_by_rows_equal_the_whole_and_stop_between_chunks() {
        let shape = Shape::TriangleMesh(kac_core::geometry::generate::icosphere(6));
        let op = operators::build(&shape, &OperatorOptions::default()).unwrap();
        assert!(op.pair.n() > 2 * SIGNATURE_ROWS);
        let s =
            spectrum::eigs(&op.pair, &EigenOptions { k: 20, ..Default::default() }, None, Control::default()).unwrap();
        let b = Basis::new(&s.values, s.vectors.as_ref(), kac_core::descriptors::zero_threshold(&op.pair));
        let go = Control::default();
        // Equal to rounding (a product's kernel may differ for a chunk's remainder rows on some CPUs).
        let close = |a: &faer::Mat<f64>, b: &faer::Mat<f64>| {
            assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
            let scale = (0..b.ncols())
                .flat_map(|j| (0..b.nrows()).map(move |i| (i, j)))
                .fold(0.0f64, |m, (i, j)| m.max(b[(i, j)].abs()));
            for j in 0..a.ncols() {
                for i in 0..a.nrows() {
                    assert!(
                        (a[(i, j)] - b[(i, j)]).abs() <= 1e-12 * scale,
                        "({i}, {j}): {} vs {}",
                        a[(i, j)],
                        b[(i, j)]
                    );
                }
            }
        };
        let h = by_rows(&b, &go, |b| signatures::hks(b, &HksOptions::default()), |h| &mut h.values).unwrap();
        let whole = signatures::hks(&b, &HksOptions::default()).unwrap();
        assert_eq!((h.times.clone(), h.values.nrows()), (whole.times.clone(), whole.values.nrows()));
        close(&h.values, &whole.values);
        let si = by_rows(&b, &go, |b| signatures::si_hks(b, &SiHksOptions::default()), |h| &mut h.values).unwrap();
        close(&si.values, &signatures::si_hks(&b, &SiHksOptions::default()).unwrap().values);
        let w = by_rows(&b, &go, |b| signatures::wks(b, &WksOptions::default()), |w| &mut w.values).unwrap();
        close(&w.values, &signatures::wks(&b, &WksOptions::default()).unwrap().values);
        let stop = std::sync::atomic::AtomicBool::new(true);
        let stopped = Control { stop: Some(&stop), ..Control::default() };
        let r = by_rows(&b, &stopped, |b| signatures::hks(b, &HksOptions::default()), |h| &mut h.values);
        assert_eq!(r.err().map(|e| e.code()), Some("canceled"));
    }
}
