//! The success bodies of the routes that have no type of their own elsewhere: each route returns one of these
//! (or a type from the analysis layer), so that the OpenAPI document types every success response and the
//! contract test (schemathesis' response conformance) holds the two together.

use super::*;
use crate::analysis::OperatorSpec;
use kac_core::descriptors::shape_dna::ShapeDnaOptions;

/// `GET /livez`.
#[derive(Serialize, utoipa::ToSchema)]
pub struct Liveness {
    /// `alive`.
    pub status: &'static str,
}

/// `GET /readyz`.
#[derive(Serialize, utoipa::ToSchema)]
pub struct Readiness {
    /// `ready`.
    pub status: &'static str,
    /// Jobs enqueued or running.
    pub queue: usize,
    /// The queue's capacity (--queue-capacity).
    pub capacity: usize,
}

/// `GET /problems/{code}`: what a problem type means.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ProblemType {
    /// `/problems/{code}`.
    #[serde(rename = "type")]
    pub type_: String,
    pub code: String,
    pub description: String,
}

/// A page of jobs (`GET /v1/jobs`), oldest first.
#[derive(Serialize, utoipa::ToSchema)]
pub struct JobPage {
    pub total: usize,
    pub offset: usize,
    pub limit: usize,
    /// Each job as `GET /v1/jobs/{id}` shows it (with its `links`).
    pub items: Vec<super::JobResource>,
}

/// A page of shapes (`GET /v1/shapes`).
#[derive(Serialize, utoipa::ToSchema)]
pub struct ShapePage {
    pub total: usize,
    pub offset: usize,
    pub limit: usize,
    pub items: Vec<ShapeResource>,
}

/// One neighbour of a search.
#[derive(Serialize, utoipa::ToSchema)]
pub struct Neighbour {
    pub shape_id: String,
    pub distance: f64,
}

/// The stored shapes nearest to the query (`POST /v1/search`).
#[derive(Serialize, utoipa::ToSchema)]
pub struct SearchResult {
    /// `shape-dna`.
    pub descriptor: &'static str,
    /// The fingerprint family searched: every parameter that changes the values.
    pub family: String,
    pub options: ShapeDnaOptions,
    pub metric: &'static str,
    #[schema(value_type = OperatorSpec)]
    pub operator: Value,
    /// The query shape, when the query was one (it is left out of the neighbours).
    pub shape_id: Option<String>,
    /// The query's fingerprint.
    pub fingerprint: Vec<f64>,
    /// Fingerprints of this family held.
    pub searched: usize,
    /// Fingerprints whose distance was computed: all of them for a scan, fewer through the index.
    pub probed: usize,
    /// Whether the neighbours are proven to be the exact nearest ones: always for a scan; through the index, when
    /// every cell not probed lies farther from the query than the last neighbour. Distances are exact either way.
    pub exact: bool,
    /// `scan` (every fingerprint of the family, or of the shapes carrying the tags) or `index`.
    pub method: crate::service::search::Method,
    /// The tags the search was limited to (sorted, repeats dropped).
    pub tags: Vec<String>,
    /// Nearest first; ties by id.
    pub neighbours: Vec<Neighbour>,
}

pub use crate::service::jobs::ArrayLinks;

/// What the service adds to every stored result: its id and its arrays' links. The OpenAPI document's
/// `AnalysisResult` is this with each analysis' own fields ([`crate::analysis::Summary`]), one flat schema per
/// analysis (`SpectrumResult`, `HksResult`, …, `CompareResult`) under a discriminator on `analysis`.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ResultEnvelope {
    /// The result's id: the hash of the shape, the analysis and its parameters.
    pub result_id: String,
    /// The result's arrays by name (absent when it has none).
    pub arrays: Option<std::collections::BTreeMap<String, ArrayLinks>>,
}

/// A finished result (`GET /v1/results/{id}`, `POST /v1/analyze`, `POST /v1/compare`): the union of the
/// analyses' results, named in the OpenAPI document by the post-processing of [`crate::service::openapi`].
#[derive(utoipa::ToSchema)]
pub struct AnalysisResult {
    pub analysis: String,
}
