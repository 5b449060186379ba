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
    #[schema(value_type = Vec<JobView>)]
    pub items: Vec<Value>,
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
    /// Nearest first; ties by id.
    pub neighbours: Vec<Neighbour>,
}

/// A warning: a number outside its domain of validity.
#[derive(Serialize, utoipa::ToSchema)]
pub struct Warning {
    pub code: String,
    pub message: String,
}

/// One array of a result: its shape, what its columns are, and where to fetch it.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ArrayLinks {
    pub rows: usize,
    pub cols: usize,
    /// What the columns are (times, energies, eigenvalues, …), where they are numbers.
    pub columns: Option<Vec<f64>>,
    /// float64 `.npy`, rows in the upload's vertex numbering.
    pub npy: String,
    /// The shape as binary PLY coloured by a column (per-vertex arrays).
    pub ply: Option<String>,
    /// A matrix as Matrix Market (`operator` results).
    pub mtx: Option<String>,
    /// A matrix as SciPy `.npz` (`operator` results).
    pub npz: Option<String>,
    /// The values, rows of numbers (null for NaN), unless `values=false`.
    pub values: Option<Vec<Vec<Option<f64>>>>,
}

/// A finished result (`GET /v1/results/{id}`, `POST /v1/analyze`, `POST /v1/compare`): the fields every result
/// has, then the analysis' own numbers and echoed parameters (see the README's table of analyses and, per
/// analysis, the CLI reference). A comparison (`compare`) has no `shape_id`.
#[derive(Serialize, utoipa::ToSchema)]
pub struct AnalysisResult {
    /// The analysis' name (`spectrum`, `hks`, …, or `compare`).
    pub analysis: String,
    pub result_id: String,
    pub shape_id: Option<String>,
    pub algorithm_version: Option<String>,
    /// Whether the eigenpairs came from the cache.
    pub eigenpairs_reused: Option<bool>,
    /// Numbers outside their domain of validity (empty when all is well).
    pub warnings: Option<Vec<Warning>>,
    /// The result's arrays by name.
    pub arrays: Option<std::collections::BTreeMap<String, ArrayLinks>>,
}
