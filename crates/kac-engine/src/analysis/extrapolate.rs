//! Continuum spectra with error bars: the `spectrum` request's `extrapolate` solves again on uniformly refined
//! copies of the mesh (each triangle into four, each tetrahedron into eight) and extrapolates every eigenvalue
//! (`kac_core::spectrum::extrapolate`), reporting the order it observed. Uniform refinement keeps straight edges
//! straight, so the limit is the spectrum of the domain as meshed: exact for polygons and polyhedra (flat
//! triangle meshes, tet meshes); a curved surface's facets would stay flat, so it is refused there. On flat
//! triangle meshes every level is graded toward the re-entrant corners (`kac_core::geometry::grading`), which
//! restores the nominal order that their singular eigenfunctions take from uniform levels.

use super::*;
use kac_core::geometry::{grading, refine};
use kac_core::spectrum::extrapolate::richardson;

/// The `extrapolation` block: the eigenvalues on the input and on `refinements` uniform refinements, and the
/// extrapolated values with their error estimates and observed orders.
pub(crate) fn extrapolation(
    v: &Validated,
    spec: &OperatorSpec,
    solver: &SolverSpec,
    k: usize,
    refinements: usize,
    grading: bool,
    hooks: Hooks<'_>,
) -> Result<Extrapolation, AnalysisError> {
    if !(1..=3).contains(&refinements) {
        return Err(AnalysisError::invalid_parameter(format!("refinements = {refinements}: give 1, 2 or 3")));
    }
    if spec.operator == Some(OperatorKind::Polygon) {
        return Err(AnalysisError::invalid_parameter(
            "extrapolation refines the triangles; the polygon operator's polygons do not refine with them (use cotan)",
        ));
    }
    if spec.dirichlet_vertices.is_some() {
        return Err(AnalysisError::invalid_parameter(
            "extrapolation refines the mesh; give the boundary condition as `boundary`, not as vertices",
        ));
    }
    let (factor, domain) = match &v.shape {
        Shape::TriangleMesh(m) if refine::is_planar(m) => (4usize, "the plane polygon as meshed (uniform refinement keeps its straight edges)"),
        Shape::TetMesh(_) => (8, "the polyhedron as meshed (uniform refinement keeps its flat faces)"),
        Shape::TriangleMesh(_) => {
            return Err(AnalysisError::not_applicable(
                "extrapolation refines the mesh uniformly, which keeps a curved surface's facets flat: the limit \
                 would be the polyhedron's spectrum, not the surface's; it applies to flat triangle meshes and tet meshes",
            ))
        }
        other => {
            return Err(AnalysisError::not_applicable(format!(
                "extrapolation applies to flat triangle meshes and tet meshes, not a {}",
                other.kind().as_str()
            )))
        }
    };
    let mut options = operator_options(v, spec)?;
    // Refinement splits the straight edges: the input's curved edge nodes would fit its first level only.
    let curved = options.edge_nodes.take().map(|n| n.len());
    // What the finest level holds: its unknowns times its widest array, the Krylov basis as the solver will size it
    // (a sliced solve's per slice, for the zero modes its components allow) or the k eigenvectors; checked on the
    // input before any refinement (grading moves vertices, it does not change the count; refinement keeps the
    // components). The solver checks each level's basis again before it allocates it.
    let coarse = operators::build(&v.shape, &options)?;
    let finest = coarse.pair.n().saturating_mul(factor.pow(refinements as u32));
    let (most, weyl) = (coarse.pair.components().1, coarse.pair.dimension.is_some());
    let o = solver.eigen_options(k, hooks.threads);
    let basis = kac_core::spectrum::slicing::predicted_basis(finest, &o, most, weyl);
    let held = finest.saturating_mul(basis.unwrap_or(0).max(k));
    if held > hooks.limits.max_values {
        return Err(AnalysisError::TooLarge(format!(
            "{refinements} refinement(s) make about {finest} unknowns, whose eigensolve holds about {held} values, \
             above the limit of {} (--max-output-values); ask for fewer refinements or a coarser mesh",
            hooks.limits.max_values
        )));
    }
    // The corners to grade toward (flat triangle meshes), in the validated numbering; reported in the input's.
    let report = |reason: &str| GradingReport { graded: false, reason: Some(reason.into()), corners: None };
    let (corners, mut grading_report) = match (&v.shape, grading) {
        (Shape::TriangleMesh(m), true) => match grading::order_limiting_corners(m, u32::from(spec.order)) {
            Ok(c) if c.is_empty() => (c, report("no corner limits the order")),
            Ok(c) => {
                let input_vertex = |shape_vertex: u32| v.vertex_map.iter().position(|&x| x == shape_vertex);
                let listed: Vec<GradedCorner> = c.iter().map(|x| GradedCorner::of(x, input_vertex(x.vertex))).collect();
                (c, GradingReport { graded: true, reason: None, corners: Some(listed) })
            }
            Err(why) => (vec![], report(&why.to_string())),
        },
        (Shape::TriangleMesh(_), false) => (vec![], report("grading: false")),
        _ => (vec![], report("tet meshes are refined uniformly (re-entrant edges are not graded)")),
    };
    // The levels: uniform refinements of the input, each graded by the same map (so the size parameter still
    // halves), built one at a time. Should the map fold a triangle on some level, every level is solved again
    // uniform: the levels must be one family.
    type Levels = (Vec<ExtrapolationLevel>, Vec<Vec<f64>>, bool);
    let solve_levels = |graded: bool| -> Result<Levels, AnalysisError> {
        let (mut levels, mut values) = (vec![], vec![]);
        let mut plain = v.shape.clone();
        for level in 0..=refinements {
            hooks.control.check()?;
            if level > 0 {
                plain = match &plain {
                    Shape::TriangleMesh(m) => Shape::TriangleMesh(refine::refine_triangles(m)),
                    Shape::TetMesh(m) => Shape::TetMesh(refine::refine_tets(m)),
                    _ => unreachable!("checked above"),
                };
            }
            let t = std::time::Instant::now();
            let op = match (&plain, graded) {
                (Shape::TriangleMesh(m), true) => match grading::grade(m, &corners) {
                    Some(g) => operators::build(&Shape::TriangleMesh(g), &options)?,
                    None => return Ok((levels, values, true)),
                },
                _ if level == 0 => coarse.clone(),
                _ => operators::build(&plain, &options)?,
            };
            let options =
                EigenOptions { max_values: hooks.limits.max_values, ..solver.eigen_options(k, hooks.threads) };
            let s = spectrum::eigs(&op.pair, &options, None, hooks.control)?;
            levels.push(ExtrapolationLevel {
                unknowns: op.pair.n(),
                eigenvalues: s.values.clone(),
                completeness: s.stats.completeness.clone(),
                seconds: t.elapsed().as_secs_f64(),
            });
            values.push(s.values);
        }
        Ok((levels, values, false))
    };
    let (mut levels, mut values, folded) = solve_levels(!corners.is_empty())?;
    if folded {
        grading_report = report(
            "the grading map would fold a triangle near a corner (the input is too coarse there): levels left uniform",
        );
        (levels, values, _) = solve_levels(false)?;
    }
    let nominal = 2.0 * f64::from(spec.order);
    let e = richardson(&values, nominal);
    Ok(Extrapolation {
        refinements,
        domain,
        nominal_order: nominal,
        eigenvalues: e.iter().map(|x| x.value).collect(),
        error_estimate: e.iter().map(|x| x.error_estimate).collect(),
        observed_order: e.iter().map(|x| x.observed_order).collect(),
        order_used: e.iter().map(|x| x.order_used).collect(),
        levels,
        grading: grading_report,
        curved_edges_ignored: curved,
        method: "Richardson extrapolation at the order observed on the last three levels (mesh sizes h, h/2, h/4), \
                   clamped to [0.5, 2 × nominal]; the nominal order with two levels or where the differences do not \
                   shrink monotonically. error_estimate: the larger of the gap to the extrapolation at the nominal \
                   order and a tenth of the correction; where no order was observed, at least the whole correction \
                   and the last level's change",
    })
}
