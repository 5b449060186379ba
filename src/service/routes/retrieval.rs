//! `/v1/compare` and `/v1/search`: shape-DNA comparisons as jobs, and the nearest stored shapes by fingerprint.

use super::*;
use crate::analysis::{Descriptor, FingerprintOptions, OperatorSpec};
use kac_core::descriptors::shape_dna::Metric;

/// The nearest stored shapes to a shape or a fingerprint, by one fingerprint family or by their fusion.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct SearchRequest {
    /// A stored shape to search from (its fingerprints are computed first, as a `fingerprint` job, when the store
    /// lacks one of the families searched); the shape itself is left out of the answer.
    pub shape_id: Option<String>,
    /// Or a fingerprint computed elsewhere, of the family `descriptor` names (with the same options).
    pub fingerprint: Option<Vec<f64>>,
    /// `fused` (the default from a `shape_id`: every family, each distance divided by its spread over the
    /// collection, weighted), or one family: `shape-dna` (the default with a `fingerprint`), `heat-distribution`,
    /// `gps-d2`. See docs/retrieval.md for the families, the weights and the benchmark that chose them.
    pub descriptor: Option<Descriptor>,
    /// The fingerprint's options (k, normalization, reweighting, include_zero) at the top level, with retrieval's
    /// defaults (k 50, `geometry`, `index`: invariant to the shape's scale). Fingerprints stored under other
    /// options (the earlier default was `none`, `none`) are searched by giving those options.
    #[serde(flatten)]
    pub options: FingerprintOptions,
    /// Distances within a family (default euclidean; a fused search is euclidean only).
    #[serde(default)]
    pub metric: Metric,
    /// Nearest shapes returned (default 10, at most 1000).
    #[serde(default = "default_neighbours")]
    pub neighbours: usize,
    /// Only shapes carrying every one of these tags (at most 32).
    #[serde(default)]
    pub tags: Vec<String>,
    /// Compare every fingerprint of the family instead of probing the index's nearest cells (slower on large
    /// collections; the answer is then exact by construction). A fused search always compares every shape.
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
    /// The descriptor searched: as given, else fused from a shape and shape-DNA from a fingerprint.
    pub fn descriptor(&self) -> Descriptor {
        self.descriptor.unwrap_or(if self.fingerprint.is_some() { Descriptor::ShapeDna } else { Descriptor::Fused })
    }
    /// The families searched, in the order of [`Descriptor::FAMILIES`].
    pub fn families(&self) -> Vec<(Descriptor, String)> {
        let d = self.descriptor();
        d.members().iter().map(|&m| (m, analysis::descriptor_family(m, &self.options, &self.operator))).collect()
    }
}

/// The number of values a fingerprint of a family holds with these options.
pub(crate) fn family_length(d: Descriptor, options: &FingerprintOptions) -> usize {
    use kac_core::descriptors::global;
    match d {
        Descriptor::ShapeDna | Descriptor::Fused => options.k,
        Descriptor::HeatDistribution => global::HEAT_TIMES.2 * global::HEAT_QUANTILES,
        Descriptor::GpsD2 => global::GPS_QUANTILES,
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
    if req.options.k == 0 {
        return Err(ApiError::Analysis(analysis::AnalysisError::invalid_k(
            "k = 0: a fingerprint has at least one value",
        )));
    }
    if req.options.k > st.engine.config.max_k {
        return Err(ApiError::KTooLarge {
            detail: format!("k = {} is above --max-k {}", req.options.k, st.engine.config.max_k),
        });
    }
    if req.neighbours > 1000 {
        return Err(ApiError::invalid_request(format!("neighbours = {}: at most 1000", req.neighbours)));
    }
    let descriptor = req.descriptor();
    if descriptor == Descriptor::Fused && req.metric != Metric::Euclidean {
        return Err(ApiError::invalid_request(format!(
            "metric {}: a fused search sums Euclidean distances (give one family as `descriptor` for another metric)",
            req.metric.name()
        )));
    }
    let tags = Tag::parse_all(&req.tags).map_err(ApiError::invalid_request)?;
    let families = req.families();
    let query: Vec<Vec<f64>> =
        match (&req.shape_id, &req.fingerprint) {
            (Some(_), Some(_)) | (None, None) => {
                return Err(ApiError::invalid_request("give either shape_id or fingerprint (one of them)"))
            }
            (None, Some(_)) if descriptor == Descriptor::Fused => return Err(ApiError::invalid_request(
                "descriptor fused: a fused search starts from a stored shape (shape_id), whose fingerprint is one per \
                 family; to search by a fingerprint, name its family as `descriptor`",
            )),
            (None, Some(f)) => {
                // The family's length follows from the request, whether or not the family holds rows yet.
                let want = family_length(descriptor, &req.options);
                if f.len() != want {
                    return Err(ApiError::invalid_request(format!(
                        "fingerprint: {} values, but a {} fingerprint with these options has {want}",
                        f.len(),
                        descriptor.name()
                    )));
                }
                if let Some(i) = f.iter().position(|x| !x.is_finite()) {
                    return Err(ApiError::invalid_request(format!("fingerprint value {i} is not a finite number")));
                }
                // Distances are sums of squares of differences: values this large would overflow them to infinity.
                if let Some(i) = f.iter().position(|x| x.abs() > MAX_FINGERPRINT_VALUE) {
                    return Err(ApiError::invalid_request(format!(
                        "fingerprint value {i} = {:e} is outside ±{MAX_FINGERPRINT_VALUE:e} (distances to it would \
                     overflow)",
                        f[i]
                    )));
                }
                vec![f.clone()]
            }
            // The id parses before any store sees it (404 for what is not an id).
            (Some(id), None) => {
                let hex = crate::service::ids::shape_id(id)?.hex();
                match stored_fingerprints(&st, &families, &hex)? {
                    Some(f) => f,
                    None => match fingerprint_shape(&st, &req, id, &families, q.wait).await? {
                        Ok(f) => f,
                        Err(response) => return Ok(response),
                    },
                }
            }
        };
    let exclude = match &req.shape_id {
        Some(id) => Some(crate::service::ids::shape_id(id)?),
        None => None,
    };
    let store = st.fingerprints.clone();
    let fetch = move |family: &str, ids: &[String]| store.fingerprints_of(family, ids);
    let search_error = |e| match e {
        SearchError::Length(m) => ApiError::invalid_request(m),
        SearchError::Store(e) => store_error(e),
    };
    let operator = serde_json::to_value(&req.operator).map_err(|e| ApiError::Internal { detail: e.to_string() })?;
    let mut result = SearchResult {
        descriptor: descriptor.name(),
        family: families.iter().map(|f| f.1.as_str()).collect::<Vec<_>>().join("+"),
        families: vec![],
        options: req.options.clone(),
        metric: req.metric.name(),
        operator,
        shape_id: req.shape_id.clone(),
        fingerprint: vec![],
        searched: 0,
        probed: 0,
        incomplete: None,
        exact: true,
        method: crate::service::search::Method::Scan,
        tags: tags.iter().map(|t| t.as_str().to_string()).collect(),
        neighbours: vec![],
    };
    if descriptor == Descriptor::Fused {
        let members: Vec<crate::service::search::Member> = families
            .iter()
            .zip(&query)
            .map(|((d, family), values)| crate::service::search::Member { family, values, weight: d.weight() })
            .collect();
        let found = st
            .index
            .nearest_fused(
                &crate::service::search::FusedQuery { members: &members, count: req.neighbours, exclude, tags: &tags },
                &fetch,
            )
            .map_err(search_error)?;
        result.families = families
            .iter()
            .zip(query)
            .enumerate()
            .map(|(i, ((d, family), values))| FamilyUsed {
                descriptor: d.name(),
                family: family.clone(),
                weight: d.weight(),
                spread: found.spreads.get(i).copied(),
                fingerprint: values,
            })
            .collect();
        result.neighbours = found
            .neighbours
            .into_iter()
            .map(|(shape_id, distance, each)| Neighbour {
                shape_id,
                distance,
                distances: Some(families.iter().zip(each).map(|((d, _), x)| (d.name().to_string(), x)).collect()),
            })
            .collect();
        (result.searched, result.probed, result.exact) = (found.searched, found.probed, found.exact);
        result.incomplete = Some(found.incomplete);
        return Ok(Json(result).into_response());
    }
    let (d, family) = &families[0];
    let values = &query[0];
    let found = st
        .index
        .nearest(
            &crate::service::search::Query {
                family,
                values,
                metric: req.metric,
                count: req.neighbours,
                exclude,
                tags: &tags,
                exact: req.exact,
                max_cells: st.engine.config.search_cells,
            },
            &fetch,
        )
        .map_err(search_error)?;
    result.neighbours = found
        .neighbours
        .into_iter()
        .map(|(shape_id, distance)| Neighbour { shape_id, distance, distances: None })
        .collect();
    result.families = vec![FamilyUsed {
        descriptor: d.name(),
        family: family.clone(),
        weight: 1.0,
        spread: st.index.spread(family),
        fingerprint: values.clone(),
    }];
    result.fingerprint = values.clone();
    (result.searched, result.probed, result.exact, result.method) =
        (found.searched, found.probed, found.exact, found.method);
    Ok(Json(result).into_response())
}

/// A stored shape's fingerprints in every family asked, exact, from the store (None: one is missing).
fn stored_fingerprints(
    st: &AppState,
    families: &[(Descriptor, String)],
    id: &str,
) -> Result<Option<Vec<Vec<f64>>>, ApiError> {
    let mut out = Vec::with_capacity(families.len());
    for (_, family) in families {
        match stored_fingerprint(st, family, id)? {
            Some(f) => out.push(f),
            None => return Ok(None),
        }
    }
    Ok(Some(out))
}

/// Computes a stored shape's fingerprints as a `fingerprint` job and waits for it (`wait`): the fingerprints of the
/// families asked, or the answer to give instead (202 with the job, or the job's failure).
async fn fingerprint_shape(
    st: &AppState,
    req: &SearchRequest,
    id: &str,
    families: &[(Descriptor, String)],
    wait: Option<f64>,
) -> Result<Result<Vec<Vec<f64>>, Response>, ApiError> {
    let shape = stored_shape(st, id)?;
    // Shape-DNA alone as the shape-dna job it always was (it needs no eigenvectors, and a graph has it while it has
    // no fingerprint families); every other descriptor through the fingerprint job.
    let (options, operator, solver) = (req.options.clone(), req.operator.clone(), analysis::SolverSpec::default());
    let job = match req.descriptor() {
        Descriptor::ShapeDna => Analysis::ShapeDna { options: options.dna(), operator, solver },
        _ => Analysis::Fingerprint { options, operator, solver },
    };
    let (job, _) = jobs::submit(&st.jobs, &st.engine.config, shape, job)?;
    let view = wait_for(st, &job, wait).await?;
    if let Some(f) = stored_fingerprints(st, families, id)? {
        return Ok(Ok(f));
    }
    match view.status {
        Status::Succeeded => {
            // A job that finished before fingerprints were kept (or whose fingerprints could not be kept): its
            // stored result holds the values.
            let r = st
                .results
                .get(&id_of(&view)?)
                .map_err(store_error)?
                .ok_or(ApiError::Internal { detail: "the result went missing".into() })?;
            let mut out = vec![];
            for (d, family) in families {
                // A fingerprint result lists its families; a shape-dna result is the shape-DNA family's.
                let values: Vec<f64> = r.summary["families"]
                    .as_array()
                    .and_then(|fs| fs.iter().find(|f| f["descriptor"] == d.name()))
                    .map(|f| f["values"].clone())
                    .or_else(|| (*d == Descriptor::ShapeDna).then(|| r.summary["shape_dna"]["values"].clone()))
                    .and_then(|v| serde_json::from_value(v).ok())
                    .ok_or_else(|| ApiError::Internal {
                        detail: format!("the fingerprint result has no {} values", d.name()),
                    })?;
                let f = analysis::Fingerprint { family: family.clone(), shape_id: id.to_string(), values };
                st.index
                    .record(&*st.fingerprints, &f)
                    .map_err(|e| ApiError::Internal { detail: format!("the fingerprint could not be stored: {e}") })?;
                out.push(f.values);
            }
            Ok(Ok(out))
        }
        Status::Failed | Status::Canceled => {
            let f = view.error.as_ref().ok_or(ApiError::Internal { detail: "a failed job without an error".into() })?;
            Ok(Err(with_location(failure_response(f), &format!("/v1/jobs/{}", view.id))))
        }
        _ => Ok(Err(job_response(StatusCode::ACCEPTED, &view))),
    }
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
        assert!(serde_json::from_value::<SearchRequest>(serde_json::json!({ "fingerprint": [1.0], "k": 1 })).is_ok());
        assert!(serde_json::from_value::<SearchRequest>(search).is_err());
    }
}
