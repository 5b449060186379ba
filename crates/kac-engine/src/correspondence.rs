//! Correspondences between two stored shapes, run as jobs (`POST /v1/correspondence`): the request, and the
//! computation a worker runs (both shapes' eigenpairs through the cache, the functional map and its refinement,
//! the vertex maps both ways), inside the queue's limits, the job timeout and cancel.

use crate::analysis::{correspond, AnalysisError, Hooks, OperatorSpec, Output, SolverSpec};
use kac_core::correspondence::CorrespondenceOptions;
use serde::{Deserialize, Serialize};

/// Which vertex of one stored shape is which of another, by functional maps refined with ZoomOut.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct CorrespondenceRequest {
    /// The source shape.
    pub source_id: String,
    /// The target shape.
    pub target_id: String,
    /// How the map is fitted and refined (fit_k, refine_k, descriptors, weights, partial, landmarks as
    /// [source vertex, target vertex] pairs in the uploads' numbering), at the top level.
    #[serde(flatten)]
    pub options: CorrespondenceOptions,
    /// The operator of both shapes (Neumann, order 1).
    #[serde(default)]
    pub operator: OperatorSpec,
    /// A per-vertex array of the source to carry to the target (the result's array `transferred`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transfer: Option<correspond::Transfer>,
}

kac_core::object_only_serde!(CorrespondenceRequest);

/// The correspondence of the two shapes, as a result: the source is the result's shape.
pub fn run(
    source: &kac_core::Validated,
    target: &kac_core::Validated,
    req: &CorrespondenceRequest,
    hooks: Hooks<'_>,
) -> Result<Output, AnalysisError> {
    correspond::correspondence(
        source,
        target,
        &req.options,
        &req.operator,
        &SolverSpec::default(),
        req.transfer.as_ref(),
        hooks,
    )
}
