//! The analyses that are the chapter's tools beyond descriptors: curvature (from the Laplacian and from the heat
//! kernel), evolutions (waves, Schrödinger), Poisson, diffusion of a function and the Dirichlet energy; and the
//! helpers that turn their inputs (per-vertex functions, initial data) into vectors over an operator's unknowns.

use super::*;

/// The truncation bound at a curvature window's first time above which the result warns.
pub const CURVATURE_TRUNCATION_WARN: f64 = 1e-3;

/// Runs one of the tools (the runner passes only these).
pub(crate) fn run(
    v: &Validated,
    analysis: &Analysis,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<Part, AnalysisError> {
    Ok(match analysis {
        Analysis::MeanCurvature {} => {
            let Shape::TriangleMesh(mesh) = &v.shape else {
                return Err(AnalysisError::not_applicable("mean curvature is computed on triangle meshes"));
            };
            hooks.control.check()?;
            let h = curvature::mean_curvature(mesh)?;
            let k = curvature::angle_defect(mesh)?;
            let column = |x: &[f64]| faer::Mat::from_fn(x.len(), 1, |i, _| x[i]);
            let normals = faer::Mat::from_fn(h.normals.len(), 3, |i, j| h.normals[i][j]);
            let arrays = vec![
                validated_to_input(v, column(&h.h).as_ref(), "mean_curvature"),
                validated_to_input(v, normals.as_ref(), "normals"),
                validated_to_input(v, column(&k).as_ref(), "gaussian_curvature"),
            ];
            let body = MeanCurvatureSummary {
                mean_curvature: FiniteStats::of(&h.h),
                gaussian_curvature: FiniteStats::of(&k),
                method: h,
                convention: "M⁻¹LX = 2Hn with Δ = −∇·∇ and n outward: H = 1/r on a sphere of radius r",
            };
            Part::new(Summary::MeanCurvature(body), arrays)
        }
        Analysis::HeatCurvature { k, times, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let pair = &e.operator.pair;
            // The measure (area) per unknown: Σ of all of M's entries over n.
            let resolved = 20.0 * pair.mass.iter().sum::<f64>() / pair.n().max(1) as f64;
            // The shape's own curvature scale bounds the window from above (the expansion is one in t κ²).
            let scale = match &v.shape {
                Shape::TriangleMesh(mesh) => Some(curvature::curvature_scale(mesh)?),
                _ => None,
            };
            let mut hc = curvature::heat_curvature(&basis_of(&e, *k), times.as_deref(), resolved, scale.as_ref())?;
            // The expansion holds away from a boundary (there it has a boundary term): boundary vertices get no
            // value, and the output says that vertices within about √t of the boundary are affected too.
            let boundary = operators::boundary::boundary_vertices(&v.shape);
            let rows: Vec<usize> = match &e.operator.interior {
                None => (0..boundary.len()).collect(),
                Some(keep) => keep.iter().map(|&i| i as usize).collect(),
            };
            let mut on_boundary = 0;
            for (row, &vertex) in rows.iter().enumerate() {
                if boundary.get(vertex).copied().unwrap_or(false) {
                    hc.k[row] = f64::NAN;
                    on_boundary += 1;
                }
            }
            let column = |x: &[f64]| faer::Mat::from_fn(x.len(), 1, |i, _| x[i]);
            let mut arrays = vec![to_input_rows(v, &e.operator, column(&hc.k).as_ref(), "heat_curvature")];
            // The window's validity: below the discretization's resolution the estimate follows the mesh, and
            // where the k pairs do not decide the kernel at its first time, truncation biases it.
            let mut warnings = vec![];
            if hc.times[0] < resolved {
                warnings.push(Warning::new(
                    "curvature-window-unresolved",
                    format!(
                        "the window starts at t = {:.3e}, below the smallest time the mesh resolves ({resolved:.3e}, \
                         20 × the mean area per vertex): the estimate follows the mesh, not the surface",
                        hc.times[0]
                    ),
                ));
            }
            if let (true, Some(scale), Some(bound)) =
                (hc.beyond_scale, &hc.curvature_scale, hc.curvature_scale.and_then(|s| s.time_bound))
            {
                let largest = hc.times.iter().copied().fold(0.0, f64::max);
                let smallest = hc.times.iter().copied().fold(f64::INFINITY, f64::min);
                // λ_k of the pairs the fit used (the basis' last).
                let lk = basis_of(&e, *k).values.last().copied().unwrap_or(0.0);
                let pairs = curvature::pairs_time(lk);
                // The default window spans a factor MIN_WINDOW_RATIO at least: it fits below the bound once its
                // start is at or below bound / MIN_WINDOW_RATIO.
                let start = bound / curvature::MIN_WINDOW_RATIO;
                let todo = if times.is_some() {
                    format!("the times were given: give times at or below {bound:.3e}")
                } else if resolved >= pairs {
                    format!(
                        "the window cannot start before the mesh resolves the kernel (t = {resolved:.3e}, 20 × \
                         the mean area per vertex): use a finer mesh, with a mean area per vertex below {:.3e} \
                         (now {:.3e})",
                        start / 20.0,
                        resolved / 20.0
                    )
                } else {
                    format!(
                        "the window cannot start before the {k} pairs decide the kernel (t = {pairs:.3e}, \
                         e^(−λ_k t) = 1e-4): ask for more eigenpairs, up to λ_k ≥ {:.3e} (now {lk:.3e}){}",
                        curvature::pairs_time(1.0) / start,
                        if resolved > start { ", and a finer mesh" } else { "" }
                    )
                };
                warnings.push(Warning::new(
                    "curvature-window-too-coarse",
                    format!(
                        "the window [{smallest:.3e}, {largest:.3e}] reaches beyond the shape's curvature scale \
                         t ≤ 1/κ_max² = {bound:.3e} (κ_max = {:.3}, the {}th percentile of the principal \
                         curvatures), where the small-time expansion is biased (above 3 %, about 30 % at six times \
                         the scale); {todo}",
                        scale.kappa_max,
                        (scale.quantile * 100.0).round()
                    ),
                ));
            }
            if hc.truncation_bound > CURVATURE_TRUNCATION_WARN {
                warnings.push(Warning::new(
                    "curvature-window-truncated",
                    format!(
                        "at the window's first time the {k} pairs may miss {:.1e} of the heat trace (above \
                         {CURVATURE_TRUNCATION_WARN:e}): ask for more pairs or later times",
                        hc.truncation_bound
                    ),
                ));
            }
            let mut summary = HeatCurvatureSummary {
                k: *k,
                heat_curvature: FiniteStats::of(&hc.k),
                fit: hc,
                boundary_vertices: on_boundary,
                resolved_time: resolved,
                boundary_note: None,
                gaussian_curvature: None,
                operator: OperatorUsed::of(&e.operator),
            };
            if on_boundary > 0 || e.operator.dirichlet() {
                summary.boundary_note = Some(
                    "the shape has a boundary: boundary vertices get no value, and within about √t of it the heat \
                     kernel's boundary term biases the estimate",
                );
            }
            if let Shape::TriangleMesh(mesh) = &v.shape {
                let ad = curvature::angle_defect(mesh)?;
                summary.gaussian_curvature = Some(FiniteStats::of(&ad));
                arrays.push(validated_to_input(v, column(&ad).as_ref(), "gaussian_curvature"));
            }
            Part { body: Summary::HeatCurvature(summary), arrays, fingerprints: vec![], warnings }
        }
        Analysis::Wave { k, times, start, velocity, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let (u0, how) = initial_function(v, &e.operator, start)?;
            let v0 = velocity.as_ref().map(|f| input_function(v, &e.operator, f, "velocity")).transpose()?;
            let basis = basis_of(&e, *k);
            let (u, dropped) = pde::wave(&basis, &e.operator.pair, &u0, v0.as_deref(), times)?;
            let energy = pde::wave_energy(&basis, &e.operator.pair, u.as_ref(), (&u0, v0.as_deref()), times)?;
            let e0 = energy.first().copied().unwrap_or(0.0);
            let drift = energy.iter().map(|x| (x - e0).abs()).fold(0.0, f64::max) / e0.abs().max(f64::MIN_POSITIVE);
            let mut a = to_input_rows(v, &e.operator, u.as_ref(), "wave");
            a.columns = Some(times.clone());
            let body = WaveSummary {
                k: *k,
                times: times.clone(),
                initial: how,
                dropped_m_norm: dropped,
                velocity: velocity.is_some(),
                energy,
                energy_relative_drift: drift,
                equation: "∂²u/∂t² = −Δu, u(t) = Σ (a cos √λt + b sin √λt/√λ) φ; energy ½(u̇ᵀMu̇ + uᵀLu), conserved",
                operator: OperatorUsed::of(&e.operator),
            };
            Part::new(Summary::Wave(body), vec![a])
        }
        Analysis::Schrodinger { k, times, start, initial_imag, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let (re0, how) = initial_function(v, &e.operator, start)?;
            let im0 = initial_imag.as_ref().map(|f| input_function(v, &e.operator, f, "initial_imag")).transpose()?;
            let pde::Evolution { re, im, norms, dropped } =
                pde::schrodinger(&basis_of(&e, *k), &e.operator.pair, &re0, im0.as_deref(), times)?;
            let mut a = to_input_rows(v, &e.operator, re.as_ref(), "schrodinger_re");
            let mut b = to_input_rows(v, &e.operator, im.as_ref(), "schrodinger_im");
            a.columns = Some(times.clone());
            b.columns = Some(times.clone());
            let body = SchrodingerSummary {
                k: *k,
                times: times.clone(),
                initial: how,
                m_norm: norms,
                dropped_m_norm: dropped,
                equation: "∂ψ/∂t = −iΔψ, ψ(t) = Σ e^{−iλt}⟨ψ₀, φ⟩_M φ",
                operator: OperatorUsed::of(&e.operator),
            };
            Part::new(Summary::Schrodinger(body), vec![a, b])
        }
        Analysis::Poisson { g, dirichlet_values, operator } => {
            let op = build_operator(v, operator)?;
            hooks.control.check()?;
            let g_op = input_function(v, &op, g, "g")?;
            let fixed = match dirichlet_values {
                Some(list) => {
                    let ids: Vec<u32> = list.iter().map(|p| p.0).collect();
                    let vertices = map_vertices(v, &ids, "dirichlet_values")?;
                    Some(fixed_rows(
                        &v.shape,
                        &op,
                        &vertices.into_iter().zip(list.iter().map(|p| p.1)).collect::<Vec<_>>(),
                    )?)
                }
                None => None,
            };
            // The condition the problem is solved with, from what was asked: values where given (on top of an
            // eliminated boundary, if the operator has one), else f = 0 on the operator's Dirichlet boundary, else
            // Neumann. One name for it: `poisson.boundary` and the top-level `boundary` agree.
            let condition = match (&fixed, op.dirichlet()) {
                (Some(list), _) => pde::PoissonBoundary::Values(list),
                (None, true) => pde::PoissonBoundary::Eliminated,
                (None, false) => pde::PoissonBoundary::Neumann,
            };
            let f = pde::poisson_with(&op.pair, &g_op, condition)?;
            let column = faer::Mat::from_fn(f.values.len(), 1, |i, _| f.values[i]);
            let arrays = vec![to_input_rows(v, &op, column.as_ref(), "solution")];
            let used = OperatorUsed::of(&op);
            let body = PoissonSummary {
                boundary: f.boundary,
                poisson: f,
                equation: "Δf = g, L f = M g (Δ = −∇·∇)",
                operator_boundary: used.boundary,
                operator: used.operator,
                mass: used.mass,
                size: used.size,
                parameters: used.parameters,
            };
            Part::new(Summary::Poisson(body), arrays)
        }
        Analysis::Diffuse { times, start, diffusivity, method, k, steps, operator, solver } => {
            if !(*diffusivity > 0.0 && diffusivity.is_finite()) {
                return Err(AnalysisError::invalid_parameter(format!(
                    "diffusivity = {diffusivity}: give a positive number"
                )));
            }
            // ∂u/∂t = −αΔu: the unit-diffusivity solution at αt.
            let scaled: Vec<f64> = times.iter().map(|t| diffusivity * t).collect();
            let (mut a, used, how, spectral, steps) = match method {
                HeatMethod::Spectral => {
                    let e = eigenpairs(v, operator, solver, *k, hooks, reused)?;
                    hooks.control.phase("descriptor", 0, 0)?;
                    let (u0, how) = initial_function(v, &e.operator, start)?;
                    let d = diffuse_spectral(&basis_of(&e, *k), &e.operator.pair, &u0, &scaled)?;
                    let a = to_input_rows(v, &e.operator, d.values.as_ref(), "diffused");
                    // `spectral.times` are the scaled times αt the unit-diffusivity solution was taken at.
                    (a, OperatorUsed::of(&e.operator), how, Some((d, scaled)), None)
                }
                HeatMethod::Implicit => {
                    let op = build_operator(v, operator)?;
                    let (u0, how) = initial_function(v, &op, start)?;
                    let u = pde::heat_implicit(&op.pair, &u0, &scaled, *steps)?;
                    let a = to_input_rows(v, &op, u.as_ref(), "diffused");
                    (a, OperatorUsed::of(&op), how, None, Some(*steps))
                }
            };
            a.columns = Some(times.clone());
            let (spectral, scaled_times) = spectral.unzip();
            let body = DiffuseSummary {
                times: times.clone(),
                diffusivity: *diffusivity,
                method: *method,
                initial: how,
                spectral,
                scaled_times,
                steps,
                operator: used,
            };
            Part::new(Summary::Diffuse(body), vec![a])
        }
        Analysis::DirichletEnergy { function, operator } => {
            let op = build_operator(v, operator)?;
            let columns: Vec<(String, Vec<f64>)> = match function {
                Some(f) => vec![("function".into(), input_function(v, &op, f, "function")?)],
                None => {
                    let pos = v.shape.positions().ok_or_else(|| {
                        AnalysisError::not_applicable("the shape has no coordinates; give a function")
                    })?;
                    ["x", "y", "z"]
                        .iter()
                        .enumerate()
                        .map(|(c, n)| (n.to_string(), op.restrict(&pos.iter().map(|p| p[c]).collect::<Vec<_>>())))
                        .collect()
                }
            };
            let n = op.pair.n();
            let mut lu = vec![0.0; n];
            let mut mu = vec![0.0; n];
            let energies: Vec<Energy> = columns
                .iter()
                .map(|(name, u)| {
                    operators::sparse::matvec(&op.pair.pattern, &op.pair.stiffness, u, &mut lu);
                    operators::sparse::matvec(&op.pair.pattern, &op.pair.mass, u, &mut mu);
                    let (ulu, umu) = (dot(u, &lu), dot(u, &mu));
                    let rayleigh_quotient = (umu > 0.0).then(|| ulu / umu);
                    Energy { of: name.clone(), energy: 0.5 * ulu, u_m_u: umu, rayleigh_quotient }
                })
                .collect();
            let body = DirichletEnergySummary {
                dirichlet_energy: energies,
                definition: "E(u) = ½ uᵀLu = ½ ∫ |∇u|²",
                operator: OperatorUsed::of(&op),
            };
            Part::new(Summary::DirichletEnergy(body), vec![])
        }
        other => unreachable!("the runner passes only the tools here, not {}", other.name()),
    })
}

/// A per-vertex function in the upload's numbering as a vector over the operator's unknowns.
pub(crate) fn input_function(v: &Validated, op: &Operator, f: &[f64], what: &str) -> Result<Vec<f64>, AnalysisError> {
    if let Some(i) = f.iter().position(|x| !x.is_finite()) {
        return Err(AnalysisError::invalid_parameter(format!("{what}: value {i} is not a finite number")));
    }
    Ok(op.restrict(&from_input_rows(v, f, what)?))
}

/// The initial data of an evolution over the operator's unknowns, and how it was given.
pub(crate) fn initial_function(
    v: &Validated,
    op: &Operator,
    start: &InitialData,
) -> Result<(Vec<f64>, InitialGiven), AnalysisError> {
    match (&start.initial, start.source) {
        (Some(f), None) => Ok((
            input_function(v, op, f, "initial")?,
            InitialGiven { given: Some("per vertex"), source: None, width: None },
        )),
        (None, Some(s)) => {
            let pos = v
                .shape
                .positions()
                .ok_or_else(|| AnalysisError::not_applicable("the shape has no coordinates; give `initial`"))?;
            let at = map_vertices(v, &[s], "source")?[0];
            let (lo, hi) = pos.iter().fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(lo, hi), p| {
                (std::array::from_fn(|c| lo[c].min(p[c])), std::array::from_fn(|c| hi[c].max(p[c])))
            });
            let diagonal = (0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>().sqrt();
            let w = start.width.unwrap_or(0.05 * diagonal);
            if !(w > 0.0 && w.is_finite()) {
                return Err(AnalysisError::invalid_parameter(format!("width = {w}: give a positive number")));
            }
            let c = pos[at];
            let bump: Vec<f64> = pos
                .iter()
                .map(|p| (-(0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>() / (2.0 * w * w)).exp())
                .collect();
            Ok((op.restrict(&bump), InitialGiven { given: None, source: Some(s), width: Some(w) }))
        }
        _ => Err(AnalysisError::invalid_parameter(
            "give either `initial` (per vertex) or `source` (with an optional `width`)",
        )),
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
