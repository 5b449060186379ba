//! The dispatch: each analysis from its request to its summary and arrays, through the core's calls.

use super::run::*;
use super::*;

pub(crate) fn compute(
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
        Analysis::Fingerprint { options, operator, solver } => {
            let f = fingerprint_families(v, options, operator, solver, hooks, reused)?;
            let id = v.id.hex();
            let fingerprints = f
                .families
                .iter()
                .map(|x| Fingerprint { family: x.family.clone(), shape_id: id.clone(), values: x.values.clone() })
                .collect();
            let body = FingerprintSummary {
                options: options.clone(),
                shape_dna: f.shape_dna,
                families: f.families,
                measure: f.measure,
                operator: f.operator,
            };
            Part { body: Summary::Fingerprint(body), arrays: vec![], fingerprints, warnings: vec![] }
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
