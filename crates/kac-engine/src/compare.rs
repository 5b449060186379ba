//! Comparisons of stored shapes by shape-DNA, run as jobs (`POST /v1/compare`): the request, and the
//! computation a worker runs, shape by shape through the eigenpair cache, inside the queue's limits, the job
//! timeout and cancel. A shape whose fingerprint cannot be computed is reported with its problem, and the others
//! are compared without it.

use super::store::StoredShape;
use crate::analysis::{
    self, compare, AnalysisError, CompareFailure, Fingerprint, Hooks, OperatorSpec, Output, SolverSpec, Summary,
};
use kac_core::descriptors::shape_dna::{Metric, ShapeDnaOptions};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The most shapes one comparison takes.
pub const MAX_SHAPES: usize = 500;

/// Distances between stored shapes by shape-DNA, and each shape's nearest neighbours.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct CompareRequest {
    /// Shapes to compare (default: every stored shape, at most 500, in id order).
    pub shape_ids: Option<Vec<String>>,
    /// The shape-DNA's options (k, normalization, reweighting, include_zero) at the top level: one type and one
    /// set of defaults for every request and flag that fingerprints.
    #[serde(flatten)]
    pub dna: ShapeDnaOptions,
    #[serde(default)]
    pub metric: Metric,
    /// Nearest neighbours listed per shape (default 5).
    #[serde(default = "default_neighbours")]
    pub neighbours: usize,
    #[serde(default)]
    pub operator: OperatorSpec,
}

fn default_neighbours() -> usize {
    5
}

kac_core::object_only_serde!(CompareRequest);

impl CompareRequest {
    pub fn options(&self) -> ShapeDnaOptions {
        self.dna.clone()
    }
}

/// The comparison: each shape's shape-DNA (typed, through the cache), the distances between those that have one,
/// and each one's nearest neighbours; a shape that failed is listed under `failures` with its problem.
///
/// A failure's `status` in the result is the number the host gives its code (`status_of`: the HTTP layer's
/// mapping, so that the engine decides no status).
pub fn run(
    shapes: &[Arc<StoredShape>],
    req: &CompareRequest,
    hooks: Hooks<'_>,
    status_of: fn(crate::Code) -> u16,
) -> Result<Output, AnalysisError> {
    let options = req.options();
    let solver = SolverSpec::default();
    let (mut found, mut failures) = (vec![], vec![]);
    for (i, s) in shapes.iter().enumerate() {
        hooks.control.check()?;
        if let Some(p) = hooks.control.progress {
            p(kac_core::spectrum::Progress { phase: "shape-dna", converged: i, wanted: shapes.len() });
        }
        // Each shape's own solve reports no progress (the comparison reports shapes done), but stops on the flag.
        let own = Hooks { control: kac_core::spectrum::Control { progress: None, ..hooks.control }, ..hooks };
        match compare::fingerprint(&s.id, &s.validated, &options, &req.operator, &solver, own) {
            Ok(f) => found.push(f),
            Err(e) if e.is_stop() => return Err(e),
            Err(e) => {
                let p = crate::failure::Failure::of_analysis(&e);
                failures.push(CompareFailure {
                    shape_id: s.id.clone(),
                    code: p.code.as_str().into(),
                    status: status_of(p.code),
                    detail: p.detail,
                });
            }
        }
    }
    let summary = compare::comparison(&found, failures, &options, &req.operator, req.metric, req.neighbours)?;
    let family = analysis::fingerprint_family(&options, &req.operator);
    let fingerprints = found
        .into_iter()
        .map(|f| Fingerprint { family: family.clone(), shape_id: f.id, values: f.dna.values })
        .collect();
    let summary =
        serde_json::to_value(Summary::Compare(summary)).map_err(|e| AnalysisError::invalid_parameter(e.to_string()))?;
    Ok(Output { fingerprints, summary, arrays: vec![] })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flattened shape-DNA options refuse a field no part declares even without the request check (which
    /// refuses it first over HTTP, with its suggestion).
    #[test]
    fn unknown_fields_are_refused_by_the_type_too() {
        let ok: CompareRequest = serde_json::from_value(serde_json::json!({ "k": 7, "neighbours": 2 })).unwrap();
        assert_eq!((ok.dna.k, ok.neighbours), (7, 2));
        assert!(serde_json::from_value::<CompareRequest>(serde_json::json!({ "normalisation": "area" })).is_err());
    }
}
