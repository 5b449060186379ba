//! `/v1/compare` and `/v1/search`: shape-DNA comparisons as jobs, and the nearest stored shapes by fingerprint.

use super::*;
use crate::analysis::OperatorSpec;
use kac_core::descriptors::shape_dna::{Metric, ShapeDnaOptions};

/// The nearest stored shapes to a shape or a fingerprint, by shape-DNA.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct SearchRequest {
    /// A stored shape to search from (its fingerprint is computed first, as a `shape-dna` job, when the store has
    /// none of this family); the shape itself is left out of the answer.
    pub shape_id: Option<String>,
    /// Or a fingerprint of `k` values computed elsewhere (with the same parameters).
    pub fingerprint: Option<Vec<f64>>,
    /// The shape-DNA's options (k, normalization, reweighting, include_zero) at the top level: one type and one
    /// set of defaults for every request and flag that fingerprints.
    #[serde(flatten)]
    pub dna: ShapeDnaOptions,
    #[serde(default)]
    pub metric: Metric,
    /// Nearest shapes returned (default 10, at most 1000).
    #[serde(default = "default_neighbours")]
    pub neighbours: usize,
    /// Only shapes carrying every one of these tags (at most 32).
    #[serde(default)]
    pub tags: Vec<String>,
    /// Compare every fingerprint of the family instead of probing the index's nearest cells (slower on large
    /// collections; the answer is then exact by construction).
    #[serde(default)]
    pub exact: bool,
    #[serde(default)]
    pub operator: OperatorSpec,
}

fn default_neighbours() -> usize {
    10
}

kac_core::object_only_serde!(SearchRequest);

impl SearchRequest {
    pub fn options(&self) -> ShapeDnaOptions {
        self.dna.clone()
    }
    pub fn family(&self) -> String {
        crate::analysis::fingerprint_family(&self.options(), &self.operator)
    }
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct CompareQuery {
    /// Seconds to wait for the result (default 10, at most --max-wait-s); 0 answers 202 with the job at once.
    #[param(minimum = 0)]
    pub wait: Option<f64>,
}

/// Distances between stored shapes by shape-DNA, and each shape's nearest neighbours, as a job in the queue
/// (its capacity, the job timeout, cancel; the same request again is the same job): the result (200) when it is
/// ready within `wait` seconds, the job (202) otherwise. A shape whose fingerprint fails is listed under
/// `failures`; the others are compared.
#[utoipa::path(post, path = "/v1/compare", tag = "jobs", params(CompareQuery), request_body = CompareRequest,
    responses((status = 200, description = "the distance matrix, nearest neighbours and per-shape failures", body = AnalysisResult),
              (status = 202, description = "not ready within wait: the job", body = JobResource, headers(("Location" = String))),
              (status = 400, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 409, description = "the job was canceled", body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn compare(
    State(st): State<AppState>,
    Query(q): Query<CompareQuery>,
    headers: HeaderMap,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Response, ApiError> {
    let req: CompareRequest = strict_body(&st, body, "CompareRequest")?;
    let max = crate::service::compare::MAX_SHAPES;
    let shapes: Vec<Arc<StoredShape>> = match &req.shape_ids {
        Some(ids) if ids.len() > max => {
            return Err(ApiError::invalid_request(format!("{} shapes: at most {max} per comparison", ids.len())))
        }
        Some(ids) => ids.iter().map(|id| stored_shape(&st, id)).collect::<Result<_, _>>()?,
        None => {
            let (records, _) = st.shapes.list(0, max).map_err(store_error)?;
            let mut shapes = vec![];
            for r in &records {
                // A shape removed since the listing is left out.
                if let Some(id) = crate::service::ids::ShapeId::parse(&r.id) {
                    shapes.extend(st.shapes.get(&id).map_err(store_error)?);
                }
            }
            shapes
        }
    };
    let (job, _) = jobs::submit_compare(&st.jobs, &st.engine.config, req, shapes)?;
    answer_within(&st, &job, q.wait, &headers).await
}

/// Which vertex of one stored shape is which of another (functional maps refined by ZoomOut), as a job in the queue
/// (its capacity, the job timeout, cancel; the same request again is the same job): the result (200) when it is
/// ready within `wait` seconds, the job (202) otherwise. The result's arrays are the vertex maps both ways
/// (`source_to_target`: per source vertex, its match on the target, in the uploads' numbering) and each match's
/// cost, as `.npy`; its fields the functional map C and how it was fitted and refined.
#[utoipa::path(post, path = "/v1/correspondence", tag = "jobs", params(CompareQuery), request_body = CorrespondenceRequest,
    responses((status = 200, description = "the correspondence: the functional map, the vertex maps as arrays", body = AnalysisResult),
              (status = 202, description = "not ready within wait: the job", body = JobResource, headers(("Location" = String))),
              (status = 400, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 409, description = "the job was canceled", body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 413, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn correspondence(
    State(st): State<AppState>,
    Query(q): Query<CompareQuery>,
    headers: HeaderMap,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Response, ApiError> {
    let req: CorrespondenceRequest = strict_body(&st, body, "CorrespondenceRequest")?;
    let source = stored_shape(&st, &req.source_id)?;
    let target = stored_shape(&st, &req.target_id)?;
    let (job, _) = jobs::submit_correspondence(&st.jobs, &st.engine.config, req, &source, &target)?;
    answer_within(&st, &job, q.wait, &headers).await
}

/// The largest magnitude of a query fingerprint's values: a thousand squared differences of it stay finite.
pub(crate) const MAX_FINGERPRINT_VALUE: f64 = 1e100;

#[derive(Deserialize, utoipa::IntoParams)]
pub struct SearchQuery {
    /// With `shape_id` whose fingerprint is not stored yet: seconds to wait for its `shape-dna` job (default 10, at
    /// most --max-wait-s) before answering 202 with the job.
    #[param(minimum = 0)]
    pub wait: Option<f64>,
}

/// The stored shapes nearest to a shape or a fingerprint by shape-DNA, over every fingerprint of the same family
/// (k, normalization, reweighting, include_zero, operator) the service holds: those of finished `shape-dna`
/// jobs and comparisons; optionally only shapes carrying given `tags`. A `shape_id` without a stored fingerprint
/// gets one first, as a `shape-dna` job (202 with the job when it is not done within `wait`).
///
/// Large families are searched through an index (cells of nearby fingerprints, the query's nearest cells probed
/// first); the candidates are ranked by their exact stored values, and `exact` says whether the answer is proven
/// to be the exact nearest neighbours. `exact: true` in the request compares every fingerprint instead.
#[utoipa::path(post, path = "/v1/search", tag = "jobs", params(SearchQuery), request_body = SearchRequest,
    responses((status = 200, description = "the nearest shapes, nearest first, and how many were searched", body = SearchResult),
              (status = 202, description = "the query shape's fingerprint is being computed: the job", body = JobResource, headers(("Location" = String))),
              (status = 400, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn search(
    State(st): State<AppState>,
    Query(q): Query<SearchQuery>,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Response, ApiError> {
    let req: SearchRequest = strict_body(&st, body, "SearchRequest")?;
    // What other replicas computed or removed since the last search.
    st.index.sync(&*st.fingerprints).map_err(store_error)?;
    if req.dna.k == 0 {
        return Err(ApiError::Analysis(analysis::AnalysisError::invalid_k(
            "k = 0: a fingerprint has at least one value",
        )));
    }
    if req.dna.k > st.engine.config.max_k {
        return Err(ApiError::KTooLarge {
            detail: format!("k = {} is above --max-k {}", req.dna.k, st.engine.config.max_k),
        });
    }
    if req.neighbours > 1000 {
        return Err(ApiError::invalid_request(format!("neighbours = {}: at most 1000", req.neighbours)));
    }
    let tags = Tag::parse_all(&req.tags).map_err(ApiError::invalid_request)?;
    let family = req.family();
    let query = match (&req.shape_id, &req.fingerprint) {
        (Some(_), Some(_)) | (None, None) => {
            return Err(ApiError::invalid_request("give either shape_id or fingerprint (one of them)"))
        }
        (None, Some(f)) => {
            // The family's length is the request's k, whether or not the family holds rows yet.
            if f.len() != req.dna.k {
                return Err(ApiError::invalid_request(format!(
                    "fingerprint: {} values, but k = {} (a fingerprint of this family has k values)",
                    f.len(),
                    req.dna.k
                )));
            }
            if let Some(i) = f.iter().position(|x| !x.is_finite()) {
                return Err(ApiError::invalid_request(format!("fingerprint value {i} is not a finite number")));
            }
            // Distances are sums of squares of differences: values this large would overflow them to infinity.
            if let Some(i) = f.iter().position(|x| x.abs() > MAX_FINGERPRINT_VALUE) {
                return Err(ApiError::invalid_request(format!(
                    "fingerprint value {i} = {:e} is outside ±{MAX_FINGERPRINT_VALUE:e} (a shape-DNA value is a \
                     normalized eigenvalue; distances to it would overflow)",
                    f[i]
                )));
            }
            f.clone()
        }
        // The id parses before any store sees it (404 for what is not an id).
        (Some(id), None) => match stored_fingerprint(&st, &family, &crate::service::ids::shape_id(id)?.hex())? {
            Some(f) => f,
            None => {
                let shape = stored_shape(&st, id)?;
                let dna = Analysis::ShapeDna {
                    options: req.options(),
                    operator: req.operator.clone(),
                    solver: analysis::SolverSpec::default(),
                };
                let (job, _) = jobs::submit(&st.jobs, &st.engine.config, shape, dna)?;
                let view = wait_for(&st, &job, q.wait).await?;
                match (stored_fingerprint(&st, &family, id)?, view.status) {
                    (Some(f), _) => f,
                    (None, Status::Succeeded) => {
                        // A shape-dna job that finished before fingerprints were kept (or whose fingerprint could
                        // not be kept): its stored result holds the values.
                        let r = st
                            .results
                            .get(&id_of(&view)?)
                            .map_err(store_error)?
                            .ok_or(ApiError::Internal { detail: "the result went missing".into() })?;
                        let values: Vec<f64> = serde_json::from_value(r.summary["shape_dna"]["values"].clone())
                            .map_err(|e| ApiError::Internal {
                                detail: format!("the shape-dna result has no values: {e}"),
                            })?;
                        let f = analysis::Fingerprint { family: family.clone(), shape_id: id.clone(), values };
                        st.index.record(&*st.fingerprints, &f).map_err(|e| ApiError::Internal {
                            detail: format!("the fingerprint could not be stored: {e}"),
                        })?;
                        f.values
                    }
                    (None, Status::Failed | Status::Canceled) => {
                        let f = view
                            .error
                            .as_ref()
                            .ok_or(ApiError::Internal { detail: "a failed job without an error".into() })?;
                        return Ok(with_location(failure_response(f), &format!("/v1/jobs/{}", view.id)));
                    }
                    (None, _) => return Ok(job_response(StatusCode::ACCEPTED, &view)),
                }
            }
        },
    };
    let exclude = match &req.shape_id {
        Some(id) => Some(crate::service::ids::shape_id(id)?),
        None => None,
    };
    let store = st.fingerprints.clone();
    let fetch = move |family: &str, ids: &[String]| store.fingerprints_of(family, ids);
    let found = st
        .index
        .nearest(
            &crate::service::search::Query {
                family: &family,
                values: &query,
                metric: req.metric,
                count: req.neighbours,
                exclude,
                tags: &tags,
                exact: req.exact,
                max_cells: st.engine.config.search_cells,
            },
            &fetch,
        )
        .map_err(|e| match e {
            SearchError::Length(m) => ApiError::invalid_request(m),
            SearchError::Store(e) => store_error(e),
        })?;
    let neighbours: Vec<Neighbour> =
        found.neighbours.into_iter().map(|(shape_id, distance)| Neighbour { shape_id, distance }).collect();
    let operator = serde_json::to_value(&req.operator).map_err(|e| ApiError::Internal { detail: e.to_string() })?;
    Ok(Json(SearchResult {
        descriptor: "shape-dna",
        family,
        options: req.options(),
        metric: req.metric.name(),
        operator,
        shape_id: req.shape_id.clone(),
        fingerprint: query,
        searched: found.searched,
        probed: found.probed,
        exact: found.exact,
        method: found.method,
        tags: tags.into_iter().map(|t| t.as_str().to_string()).collect(),
        neighbours,
    })
    .into_response())
}

/// A stored shape's fingerprint in a family, exact, from the store (None: there is none yet).
fn stored_fingerprint(st: &AppState, family: &str, id: &str) -> Result<Option<Vec<f64>>, ApiError> {
    let mut got = st.fingerprints.fingerprints_of(family, &[id.to_string()]).map_err(store_error)?;
    Ok(got.remove(id))
}

/// This replica's search index compared with the store, row by row: every stored fingerprint must be a row of the
/// index with the same single-precision values and rounding bound (listed in its cell), the index may hold no other
/// row, and the tags must agree. A search's `exact: true` proves the neighbours exact among the index's rows; this
/// verifies those rows against the store. Differences are checked again after the log's later changes, so a change
/// made meanwhile is not reported. It reads every fingerprint of the store (seconds at 10⁶), holding the embedded
/// store's connection meanwhile; one audit runs at a time (503 while one runs).
#[utoipa::path(get, path = "/v1/search/audit", tag = "jobs",
    responses((status = 200, description = "the comparison: `consistent` and, per family, rows missing, extra or differing", body = crate::service::search::AuditReport),
              (status = 503, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn search_audit(
    State(st): State<AppState>,
) -> Result<Json<crate::service::search::AuditReport>, ApiError> {
    let state = st.clone();
    let report = tokio::task::spawn_blocking(move || state.index.audit(&*state.fingerprints))
        .await
        .map_err(|e| ApiError::Internal { detail: format!("the audit stopped: {e}") })?
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::WouldBlock => ApiError::NotReady { detail: e.to_string() },
            _ => store_error(e),
        })?;
    if !report.consistent {
        tracing::warn!(
            families = ?report.families.iter().filter(|f| f.missing + f.extra + f.differing > 0).map(|f| &f.family).collect::<Vec<_>>(),
            tags_differing = report.tags.differing,
            "the search index differs from the store: restart the replica after removing its search-index.bin"
        );
    }
    Ok(Json(report))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flattened shape-DNA options refuse a field no part declares even without the request check (which
    /// refuses it first over HTTP, with its suggestion).
    #[test]
    fn unknown_fields_are_refused_by_the_type_too() {
        let search = serde_json::json!({ "fingerprint": [1.0], "k": 1, "reweightin": "index" });
        assert!(serde_json::from_value::<SearchRequest>(search).is_err());
    }
}
