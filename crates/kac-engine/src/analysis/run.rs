//! The runner: one analysis of a validated shape, from its eigenpairs (or its operator) to the output.

use super::*;
use dispatch::compute;

/// Rows of the eigenvectors per chunk of a per-vertex signature; the stop flag is checked between chunks, so a chunk
/// is kept to a fraction of a second of work even for SI-HKS at k = 500 with 385 τ samples.
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

/// A shape's retrieval fingerprint in every family ([`Descriptor::FAMILIES`]), from one eigensolve.
pub struct Families {
    pub shape_dna: shape_dna::ShapeDna,
    pub families: Vec<FamilyValues>,
    pub measure: f64,
    pub operator: OperatorUsed,
}

/// The `fingerprint` analysis: shape-DNA with the options' normalization, then the heat distribution and GPS D2
/// from the same eigenpairs, scaled by the measure the mass matrix sums to.
pub fn fingerprint_families(
    v: &Validated,
    options: &FingerprintOptions,
    operator: &OperatorSpec,
    solver: &SolverSpec,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<Families, AnalysisError> {
    use kac_core::descriptors::global;
    let (e, dna, want) = shape_dna_of(v, &options.dna(), operator, solver, hooks, reused)?;
    hooks.control.phase("descriptor", 0, 0)?;
    let b = basis_of(&e, want);
    let pair = &e.operator.pair;
    let weights = global::lumped_weights(pair);
    let measure: f64 = weights.iter().sum();
    let dimension = pair.dimension.filter(|d| (1..=3).contains(d)).ok_or_else(|| {
        AnalysisError::from(DescriptorError::NotApplicable {
            message: "the fingerprint's families scale the shape to unit measure: its operator has no dimension from \
                      1 to 3"
                .into(),
        })
    })?;
    let heat = global::heat_distribution(&b, &weights, measure, dimension)?;
    hooks.control.check()?;
    let gps = global::gps_d2(&b, &weights, measure, dimension)?;
    let families = [
        (Descriptor::ShapeDna, dna.values.clone(), dna.k),
        (Descriptor::HeatDistribution, heat.values, heat.eigenpairs),
        (Descriptor::GpsD2, gps.values, gps.eigenpairs),
    ]
    .into_iter()
    .map(|(d, values, eigenpairs)| FamilyValues {
        descriptor: d.name(),
        family: descriptor_family(d, options, operator),
        eigenpairs,
        values,
    })
    .collect();
    Ok(Families { shape_dna: dna, families, measure, operator: OperatorUsed::of(&e.operator) })
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
    if let Some(parameters) = part.body.operator_parameters() {
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
    let left_out = part
        .body
        .operator_parameters()
        .and_then(|p| p.get("outliers")?.get("dropped")?.as_u64())
        .map_or(0, |n| n as usize);
    let typed = Typed { head, body: part.body };
    finite::checked_output(&typed, part.arrays, part.fingerprints, |a| is_per_vertex(a.name).then_some(v), left_out)
}

/// What a spectral heat trace's bound covers.
pub(crate) const HEAT_TRACE_ERROR: &str =
    "truncation only: `heat_trace_truncation_bound` bounds what the k pairs miss of the \
    discrete trace; the discretization error (the mesh's eigenvalues against the surface's, O(h²) for P1 elements: on \
    the unit sphere of 2,562 vertices the trace at t = 0.1 is 0.8 % low) is not included: `spectrum` with \
    `extrapolate` estimates each eigenvalue's";

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
        assert_eq!(r.err().map(|e| e.code().as_str()), Some("canceled"));
    }
}
