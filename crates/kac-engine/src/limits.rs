//! Limits checked at submission, before anything is allocated or queued: k against --max-k (and k ≥ 1), every
//! list or grid of a request against --max-samples, the widest per-vertex array (or the solver's basis, when
//! `solver.subspace` or `solver.block` ask for a wide one) against --max-output-values. What only the operator's
//! size decides (a forced dense solve, a band's pairs) is checked by the runner through `Hooks::limits`.

use crate::analysis::Analysis;
use crate::config::EngineConfig;
use crate::error::{JobError, Limit};

/// The eigenpairs an analysis asks the sparse solver for, where it asks for any (an embedding of d dimensions
/// needs d + 1, the first being the constant).
fn eigenpairs(a: &Analysis) -> Option<usize> {
    a.asked().map(|(what, k)| if what == "dimensions" { k + 1 } else { k })
}

pub fn check_limits(config: &EngineConfig, a: &Analysis) -> Result<(), JobError> {
    a.check_options().map_err(JobError::Analysis)?;
    let asked = a.asked();
    // Solver settings no solve could honour (a tolerance below double precision, a shift at 0 or ±1e308, a block
    // or subspace out of range) are refused here, naming the setting, rather than holding a worker until its
    // timeout or reaching an assertion of a dependency.
    if let Some(s) = a.solver() {
        s.eigen_options(asked.map_or(1, |(_, k)| k.max(1)), 0)
            .check()
            .map_err(|e| JobError::Analysis(crate::analysis::AnalysisError::Eigen(e)))?;
    }
    let Some((what, k)) = asked else { return Ok(()) };
    if k == 0 {
        // Refused at submission: the same answer on every path (a job, /v1/analyze, a cached spectrum).
        return Err(JobError::Analysis(crate::analysis::AnalysisError::invalid_k(format!(
            "{what} = 0: ask for at least one eigenpair (1 ≤ {what} ≤ the number of unknowns)"
        ))));
    }
    if k > config.max_k {
        return Err(JobError::Limit(Limit::Pairs(format!("k = {k} is above the limit of {} (--max-k)", config.max_k))));
    }
    Ok(())
}

/// The unknowns an analysis' operator will have, at most: the vertices, or with quadratic elements the vertices
/// and the edges (about 4× a triangle mesh's vertices, 8× a tet mesh's; counted exactly from the elements).
pub fn unknowns(a: &Analysis, shape: &kac_core::Shape) -> usize {
    let n = shape.vertex_count();
    if a.operator_spec().is_none_or(|o| o.order != 2) {
        return n;
    }
    match shape {
        kac_core::Shape::TriangleMesh(m) => n + kac_core::operators::p2::triangle_edges(&m.faces).len(),
        kac_core::Shape::TetMesh(m) => n + kac_core::operators::p2::tet_edges(&m.tets).len(),
        _ => n,
    }
}

/// Bounded work: every list or grid of the request against `--max-samples`, and the widest per-vertex array the
/// analysis of `shape` will hold (eigenvectors included) against `--max-output-values`, before anything is allocated.
pub fn check_work(config: &EngineConfig, a: &Analysis, validated: &kac_core::Validated) -> Result<(), JobError> {
    use kac_core::geometry::validate::Facts;
    // Every per-vertex input of the right length, finite and bounded, every vertex index in range.
    a.check_inputs(validated).map_err(JobError::Analysis)?;
    let shape = &validated.shape;
    let vertices = unknowns(a, shape);
    use kac_core::operators::OperatorKind;
    let kind = a.operator_spec().and_then(|o| o.operator).unwrap_or(OperatorKind::default_for(shape.kind()));
    // The most zero modes the operator can have: one per connected component of the shape's own elements. The
    // point-cloud operator's come from its heat-kernel neighbourhoods, on any shape, which are not known before it is
    // built.
    let most_zero_modes = match &validated.report.facts {
        _ if kind == OperatorKind::PointCloud => None,
        Facts::Surface(f) => Some(f.components),
        Facts::Solid(f) => Some(f.components),
        Facts::Curve(f) => Some(f.components),
        Facts::Graph(f) => Some(f.components),
        Facts::Cloud(_) => None,
    };
    // Whether the solver can plan spectrum slices by Weyl's law for this operator: not for graph Laplacians, nor for
    // points in Rⁿ beyond space, whose intrinsic dimension (estimated when the operator is built) may be above 3.
    let weyl =
        kind.has_weyl_dimension() && !matches!(&validated.report.facts, Facts::Cloud(c) if c.ambient_dimension > 3);
    // (name of the field, its count) for every list or grid; and the columns of the widest per-vertex array.
    let (counts, columns) = a.demand();
    let max = config.max_samples;
    if let Some((name, n)) = counts.into_iter().find(|&(_, n)| n > max) {
        return Err(JobError::Limit(Limit::Samples(format!(
            "{name} = {n} is above the limit of {max} (--max-samples, KAC_MAX_SAMPLES)"
        ))));
    }
    // The sparse solver's Krylov basis, as the solver will size it (its default included: about 3k columns for
    // small k, 2k for large; a sliced solve's widest slice, whose basis is sized for its share of the pairs), and the
    // block vectors beside it, for any number of zero modes up to the shape's components (the pairs beyond them
    // decide whether the solve is sliced); one run where the operator has no Weyl's law to plan slices by. The
    // solver checks each basis against the same limit before allocating it, where a spectrum that does not fit the
    // slices' plan needs one run's.
    let columns = match (a.solver(), eigenpairs(a)) {
        // Counted where the sparse path will run (the dense path's n² values are checked by the runner).
        (Some(s), Some(k)) => {
            let most = most_zero_modes.unwrap_or(k);
            let basis = kac_core::spectrum::slicing::predicted_basis(vertices, &s.eigen_options(k, 0), most, weyl);
            columns.max(basis.unwrap_or(0))
        }
        (Some(s), None) => columns.max(s.subspace.unwrap_or(0)).max(s.block.unwrap_or(0).saturating_mul(2)),
        (None, _) => columns,
    };
    let values = vertices.saturating_mul(columns);
    let max = config.max_output_values;
    if values > max {
        // With quadratic elements the rows are the unknowns: the vertices and the edges.
        let rows =
            if a.operator_spec().is_some_and(|o| o.order == 2) { "unknowns (vertices and edges)" } else { "vertices" };
        return Err(JobError::Limit(Limit::Values(format!(
            "this analysis holds an array of {vertices} {rows} × {columns} columns = {values} values, \
                 above the limit of {max} (--max-output-values, KAC_MAX_OUTPUT_VALUES)"
        ))));
    }
    Ok(())
}

/// A correspondence within the limits, checked at submission: its options, operator, shapes, landmarks and array to
/// transfer as the builder checks them (`analysis::check_correspondence`), and the eigenpairs per shape against
/// --max-k, naming the option that asks for them (`fit_k` or `refine_k`; twice as many on the source of a partial
/// match).
pub fn check_correspondence(
    config: &EngineConfig,
    request: &super::correspondence::CorrespondenceRequest,
    source: &kac_core::Validated,
    target: &kac_core::Validated,
) -> Result<(), JobError> {
    let o = &request.options;
    let (what, k) = if o.fit_k > o.refine_k { ("fit_k", o.fit_k) } else { ("refine_k", o.refine_k) };
    if k.saturating_mul(if o.partial { 2 } else { 1 }) > config.max_k {
        let partial = if o.partial { ", and twice that on the source of a partial match," } else { "" };
        return Err(JobError::Limit(Limit::Pairs(format!(
            "{what} = {k}{partial} is above the limit of {} eigenpairs per shape (--max-k)",
            config.max_k
        ))));
    }
    crate::analysis::check_correspondence(source, target, o, &request.operator, request.transfer.as_ref())
        .map_err(JobError::Analysis)
}
