//! Comparisons of stored shapes by shape-DNA, run as jobs (`POST /v1/compare`): the request, and the
//! computation a worker runs, shape by shape through the eigenpair cache, inside the queue's limits, the job
//! timeout and cancel. A shape whose fingerprint cannot be computed is reported with its problem, and the others
//! are compared without it.

use super::store::StoredShape;
use crate::analysis::{
    self, AnalysisError, CompareFailure, CompareNearest, CompareNeighbour, CompareSummary, Fingerprint, Hooks,
    OperatorSpec, Output, SolverSpec, Summary,
};
use kac_core::descriptors::shape_dna::{self, Metric, Normalization, Reweighting, ShapeDnaOptions};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The most shapes one comparison takes.
pub const MAX_SHAPES: usize = 500;

/// Distances between stored shapes by shape-DNA, and each shape's nearest neighbours.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
#[serde(deny_unknown_fields)]
pub struct CompareRequest {
    /// Shapes to compare (default: every stored shape, at most 500, in id order).
    pub shape_ids: Option<Vec<String>>,
    /// Fingerprint length (default 50).
    #[serde(default = "default_dna_k")]
    pub k: usize,
    #[serde(default)]
    pub normalization: Normalization,
    #[serde(default)]
    pub reweighting: Reweighting,
    #[serde(default)]
    pub include_zero: bool,
    #[serde(default)]
    pub metric: Metric,
    /// Nearest neighbours listed per shape (default 5).
    #[serde(default = "default_neighbours")]
    pub neighbours: usize,
    #[serde(default)]
    pub operator: OperatorSpec,
}

/// The shape-DNA length: the one default (`ShapeDnaOptions::default`) every request and flag uses.
fn default_dna_k() -> usize {
    ShapeDnaOptions::default().k
}
fn default_neighbours() -> usize {
    5
}

kac_core::object_only_serde!(CompareRequest);

impl CompareRequest {
    pub fn options(&self) -> ShapeDnaOptions {
        ShapeDnaOptions {
            k: self.k,
            include_zero: self.include_zero,
            normalization: self.normalization,
            reweighting: self.reweighting,
        }
    }
}

/// The comparison: each shape's shape-DNA (typed, through the cache), the distances between those that have one,
/// and each one's nearest neighbours; a shape that failed is listed under `failures` with its problem.
pub fn run(shapes: &[Arc<StoredShape>], req: &CompareRequest, hooks: Hooks<'_>) -> Result<Output, AnalysisError> {
    let options = req.options();
    let solver = SolverSpec::default();
    let (mut ids, mut fingerprints, mut failures) = (vec![], vec![], vec![]);
    for (i, s) in shapes.iter().enumerate() {
        hooks.control.check()?;
        if let Some(p) = hooks.control.progress {
            p(kac_core::spectrum::Progress { phase: "shape-dna", converged: i, wanted: shapes.len() });
        }
        // Each shape's own solve reports no progress (the comparison reports shapes done), but stops on the flag.
        let own = Hooks { control: kac_core::spectrum::Control { progress: None, ..hooks.control }, ..hooks };
        match analysis::shape_dna_of(&s.validated, &options, &req.operator, &solver, own, &Default::default()) {
            Ok((_, dna, _)) => {
                ids.push(s.id.clone());
                fingerprints.push(dna.values);
            }
            Err(e) if e.is_stop() => return Err(e),
            Err(e) => {
                let p = super::problem::Problem::of_analysis(&e);
                failures.push(CompareFailure {
                    shape_id: s.id.clone(),
                    code: p.code.to_string(),
                    status: p.status,
                    detail: p.detail,
                });
            }
        }
    }
    let distances = shape_dna::distance_matrix(&fingerprints, req.metric)?;
    let family = analysis::fingerprint_family(&options, &req.operator);
    let found: Vec<Fingerprint> = ids
        .iter()
        .zip(&fingerprints)
        .map(|(id, v)| Fingerprint { family: family.clone(), shape_id: id.clone(), values: v.clone() })
        .collect();
    let nearest: Vec<_> = (0..ids.len())
        .map(|i| {
            let near: Vec<_> = shape_dna::nearest(&distances, i, req.neighbours)
                .into_iter()
                .map(|(j, d)| CompareNeighbour { shape_id: ids[j].clone(), distance: d })
                .collect();
            CompareNearest { shape_id: ids[i].clone(), nearest: near }
        })
        .collect();
    let summary = Summary::Compare(CompareSummary {
        descriptor: "shape-dna",
        options,
        metric: req.metric.name(),
        operator: req.operator.clone(),
        shape_ids: ids,
        fingerprints,
        distances,
        nearest,
        failures,
        algorithm_version: analysis::ALGORITHM_VERSION,
        warnings: vec![],
    });
    let summary = serde_json::to_value(summary).map_err(|e| AnalysisError::invalid_parameter(e.to_string()))?;
    Ok(Output { fingerprints: found, summary, arrays: vec![] })
}
