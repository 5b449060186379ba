//! The success bodies of the routes that have no type of their own elsewhere: each route returns one of these
//! (or a type from the analysis layer), so that the OpenAPI document types every success response and the
//! contract test (schemathesis' response conformance) holds the two together.

use super::*;
use crate::analysis::OperatorSpec;

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
    /// The distance searched by: within the family, or fused (Σ weight · distance / spread over the families).
    pub distance: f64,
    /// A fused search: each family's own distance, by descriptor (before its division by the spread).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distances: Option<std::collections::BTreeMap<String, f64>>,
}

/// A family a search read.
#[derive(Serialize, utoipa::ToSchema)]
pub struct FamilyUsed {
    /// shape-dna, heat-distribution or gps-d2.
    pub descriptor: &'static str,
    pub family: String,
    /// Its weight in the fused distance (1 alone).
    pub weight: f64,
    /// Its spread over the collection: the root-mean-square distance between its fingerprints (a fused search
    /// divides the family's distances by it; absent for an empty family).
    pub spread: Option<f64>,
    /// The query's fingerprint in this family.
    pub fingerprint: Vec<f64>,
}

/// The stored shapes nearest to the query (`POST /v1/search`).
#[derive(Serialize, utoipa::ToSchema)]
pub struct SearchResult {
    /// `fused`, `shape-dna`, `heat-distribution` or `gps-d2`.
    pub descriptor: &'static str,
    /// The fingerprint family searched (every parameter that changes the values, hashed); a fused search's
    /// families joined by `+`.
    pub family: String,
    /// Each family searched, with its weight, spread and the query's fingerprint in it.
    pub families: Vec<FamilyUsed>,
    pub options: crate::analysis::FingerprintOptions,
    pub metric: &'static str,
    #[schema(value_type = OperatorSpec)]
    pub operator: Value,
    /// The query shape, when the query was one (it is left out of the neighbours).
    pub shape_id: Option<String>,
    /// The query's fingerprint (one family; empty for a fused search, whose fingerprints are in `families`).
    pub fingerprint: Vec<f64>,
    /// Fingerprints of this family held (fused: shapes holding every family).
    pub searched: usize,
    /// Fingerprints whose distance was computed: all of them for a scan, fewer through the index.
    pub probed: usize,
    /// Whether the neighbours are proven to be the exact nearest ones: always for a scan; through the index, when
    /// every cell not probed lies farther from the query than the last neighbour. Distances are exact either way.
    pub exact: bool,
    /// A fused search: shapes holding some of the families but not all (not compared: their fingerprint jobs have
    /// not finished, or they were fingerprinted by shape-DNA alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub incomplete: Option<usize>,
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
