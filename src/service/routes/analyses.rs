//! `/v1/jobs` and `/v1/analyze`: submitting analyses as jobs, reading, cancelling and following them, and the
//! synchronous form that waits for a job's result.

use super::*;

/// A job request: the shape and the analysis with its parameters (`{"shape_id": "…", "analysis": "hks", "k": 50}`).
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
pub struct JobRequest {
    pub shape_id: String,
    #[serde(flatten)]
    pub analysis: Analysis,
}

/// A job request as `multipart/form-data`: the request as JSON in a `request` part, and per-vertex inputs of the
/// analysis as `.npy` parts named after their fields (1-D or one column, float64 or float32, rows in the
/// upload's vertex numbering), in place of JSON arrays.
#[derive(utoipa::ToSchema)]
#[allow(dead_code)]
pub struct JobForm {
    /// The job request (`JobRequest`) as JSON text.
    request: String,
    /// `wave`, `schrodinger`, `diffuse`: u₀ (or Re ψ₀).
    #[schema(value_type = Option<String>, format = Binary)]
    initial: Option<Vec<u8>>,
    /// `wave`: the initial velocity.
    #[schema(value_type = Option<String>, format = Binary)]
    velocity: Option<Vec<u8>>,
    /// `schrodinger`: Im ψ₀.
    #[schema(value_type = Option<String>, format = Binary)]
    initial_imag: Option<Vec<u8>>,
    /// `poisson`: g.
    #[schema(value_type = Option<String>, format = Binary)]
    g: Option<Vec<u8>>,
    /// `dirichlet-energy`, `smooth`: the function.
    #[schema(value_type = Option<String>, format = Binary)]
    function: Option<Vec<u8>>,
}

/// The per-vertex fields of analyses that a multipart request may send as `.npy` parts.
pub(crate) const ARRAY_FIELDS: &[&str] = &["initial", "velocity", "initial_imag", "g", "function"];

/// Puts the `.npy` parts of a multipart request into its JSON as arrays of numbers; a field given both ways,
/// an array that is not one column, or a value that is not finite is refused (400 `invalid-request`).
pub(crate) fn merge_arrays(value: &mut Value, arrays: &[(String, Bytes)]) -> Result<(), ApiError> {
    for (name, bytes) in arrays {
        let obj =
            value.as_object_mut().ok_or_else(|| ApiError::invalid_request("the request must be a JSON object"))?;
        if obj.contains_key(name) {
            return Err(ApiError::invalid_request(format!("`{name}` is given both in the JSON and as an .npy part")));
        }
        let (rows, cols, data) = kac_core::io::npy::decode_f64(bytes)
            .map_err(|e| ApiError::invalid_request(format!("the .npy part `{name}`: {e}")))?;
        if cols != 1 {
            return Err(ApiError::invalid_request(format!(
                "the .npy part `{name}` is ({rows} × {cols}); give one value per vertex (1-D, or one column)"
            )));
        }
        let numbers = data
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                serde_json::Number::from_f64(x).map(Value::Number).ok_or_else(|| {
                    ApiError::invalid_request(format!("the .npy part `{name}`: row {i} is not finite ({x})"))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        obj.insert(name.clone(), Value::Array(numbers));
    }
    Ok(())
}

/// Where a job's related resources are.
#[derive(Serialize, utoipa::ToSchema)]
pub struct JobLinks {
    /// `/v1/jobs/{id}`.
    #[serde(rename = "self")]
    pub self_: String,
    /// `/v1/jobs/{id}/events`: its progress as server-sent events.
    pub events: String,
    /// `/v1/shapes/{shape_id}`.
    pub shape: String,
}

// The engine's record of a job, with its failure as a problem document (the status its code maps to).
/// What clients see of a job.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
#[schema(as = JobView)]
pub struct JobBody {
    pub id: String,
    pub shape_id: String,
    pub analysis: String,
    pub status: Status,
    pub progress: JobProgress,
    /// RFC 3339 timestamps.
    pub created_at: String,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
    pub error: Option<Problem>,
    /// Link to the result once succeeded.
    pub result: Option<String>,
    /// The request, canonical (defaults filled in).
    #[schema(value_type = Object)]
    pub request: serde_json::Value,
}

impl From<&JobView> for JobBody {
    fn from(v: &JobView) -> JobBody {
        JobBody {
            id: v.id.clone(),
            shape_id: v.shape_id.clone(),
            analysis: v.analysis.clone(),
            status: v.status,
            progress: v.progress.clone(),
            created_at: v.created_at.clone(),
            started_at: v.started_at.clone(),
            finished_at: v.finished_at.clone(),
            error: v.error.as_ref().map(Problem::from),
            result: v.result.clone(),
            request: v.request.clone(),
        }
    }
}

/// A job as the routes answer it: its view and its links.
#[derive(Serialize, utoipa::ToSchema)]
pub struct JobResource {
    #[serde(flatten)]
    pub job: JobBody,
    pub links: JobLinks,
}

pub(crate) fn job_resource(v: &JobView) -> JobResource {
    JobResource {
        links: JobLinks {
            self_: format!("/v1/jobs/{}", v.id),
            events: format!("/v1/jobs/{}/events", v.id),
            shape: format!("/v1/shapes/{}", v.shape_id),
        },
        job: v.into(),
    }
}

pub(crate) fn job_response(status: StatusCode, v: &JobView) -> Response {
    with_location((status, Json(job_resource(v))).into_response(), &format!("/v1/jobs/{}", v.id))
}

/// Submit an analysis of a stored shape: 202 with the job (a repeated request returns the existing job, 200).
/// The request is JSON, or `multipart/form-data` with the JSON in a `request` part and per-vertex inputs
/// (`initial`, `velocity`, `initial_imag`, `g`, `function`) as `.npy` parts.
#[utoipa::path(post, path = "/v1/jobs", tag = "jobs",
    request_body(content((JobRequest = "application/json"), (JobForm = "multipart/form-data"))),
    responses(
        (status = 202, description = "enqueued", body = JobResource, headers(("Location" = String))),
        (status = 200, description = "the same request was already submitted", body = JobResource, headers(("Location" = String))),
        (status = 400, body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 404, description = "no such shape", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "k above --max-k", body = crate::service::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "queue full", body = crate::service::error::Problem, content_type = "application/problem+json", headers(("Retry-After" = u64)))))]
pub(crate) async fn create_job(State(st): State<AppState>, request: Request) -> Result<Response, ApiError> {
    let multipart = request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|ct| ct.to_ascii_lowercase().starts_with("multipart/form-data"));
    let req: JobRequest = if multipart {
        let (text, arrays) = job_form(&st, request).await?;
        let mut value = json_value(&text, "the `request` part")?;
        merge_arrays(&mut value, &arrays)?;
        strict_body(&st, Ok(Json(value)), "JobRequest")?
    } else {
        strict_body(&st, Json::<Value>::from_request(request, &st).await, "JobRequest")?
    };
    let shape = stored_shape(&st, &req.shape_id)?;
    let (job, created) = jobs::submit(&st.jobs, &st.engine.config, shape, req.analysis)?;
    Ok(job_response(if created { StatusCode::ACCEPTED } else { StatusCode::OK }, &job))
}

/// The parts of a multipart job request: the `request` JSON and the `.npy` parts (each part once).
async fn job_form(st: &AppState, request: Request) -> Result<(Bytes, Vec<(String, Bytes)>), ApiError> {
    let mut mp = Multipart::from_request(request, st)
        .await
        .map_err(|e| ApiError::invalid_request(format!("multipart: {}", e.body_text())))?;
    let (mut text, mut arrays) = (None, vec![]);
    loop {
        let field = match mp.next_field().await {
            Ok(Some(f)) => f,
            Ok(None) => break,
            Err(e) if crate::service::error::over_body_limit(e.status()) => {
                return Err(ApiError::BodyTooLarge { limit: st.config.max_body_bytes })
            }
            Err(e) => return Err(ApiError::invalid_request(format!("multipart: {}", e.body_text()))),
        };
        let name = field.name().unwrap_or("").to_string();
        let data = field.bytes().await.map_err(|e| {
            if crate::service::error::over_body_limit(e.status()) {
                ApiError::BodyTooLarge { limit: st.config.max_body_bytes }
            } else {
                ApiError::invalid_request(format!("multipart: {}", e.body_text()))
            }
        })?;
        if (name == "request" && text.is_some()) || arrays.iter().any(|(n, _)| *n == name) {
            return Err(ApiError::InvalidParameter {
                detail: format!("the multipart part `{name}` is sent more than once: send it once"),
                parameter: name,
            });
        }
        match name.as_str() {
            "request" => text = Some(data),
            n if ARRAY_FIELDS.contains(&n) => arrays.push((name, data)),
            other => {
                return Err(ApiError::invalid_request(format!(
                    "unknown multipart part `{other}`: give `request` (JSON) and .npy parts named {}",
                    ARRAY_FIELDS.join(", ")
                )))
            }
        }
    }
    let text = text.ok_or_else(|| ApiError::invalid_request("the multipart body has no `request` part (the JSON)"))?;
    Ok((text, arrays))
}

/// The filters of a job listing, each parsed into what it names: a value that names nothing (`status=bogus`, an
/// unknown analysis, text that is not a shape id) is refused (400 naming the parameter), never an empty page.
#[derive(Deserialize, utoipa::IntoParams)]
pub struct JobFilter {
    /// enqueued, processing, succeeded, failed, canceled.
    pub status: Option<Status>,
    /// A shape id (64 lowercase hex digits).
    #[serde(default, deserialize_with = "shape_id_param")]
    #[param(value_type = Option<String>)]
    pub shape_id: Option<crate::service::ids::ShapeId>,
    /// An analysis name (`GET /v1/analyses`: spectrum, hks, …), `compare` or `correspondence`.
    #[serde(default, deserialize_with = "job_analysis_param")]
    pub analysis: Option<String>,
    pub limit: Option<usize>,
    pub offset: Option<usize>,
}

fn shape_id_param<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<crate::service::ids::ShapeId>, D::Error> {
    let text = String::deserialize(d)?;
    crate::service::ids::ShapeId::parse(&text).map(Some).ok_or_else(|| {
        serde::de::Error::custom(format!("{text:?} is not a shape id (64 lowercase hexadecimal digits)"))
    })
}

/// The name a job of an analysis is listed under: an analysis of the registry, or a comparison or correspondence.
fn job_analysis_param<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    let text = String::deserialize(d)?;
    let named = analysis::registry::REGISTRY.iter().map(|e| e.name).chain(["compare", "correspondence"]);
    let mut names = named.clone();
    names.any(|n| n == text).then_some(Some(text.clone())).ok_or_else(|| {
        serde::de::Error::custom(format!("{text:?} is no analysis: one of {}", named.collect::<Vec<_>>().join(", ")))
    })
}

/// List jobs, oldest first, with filters.
#[utoipa::path(get, path = "/v1/jobs", tag = "jobs", params(JobFilter),
    responses((status = 200, description = "a page of jobs", body = JobPage),
              (status = 400, description = "malformed parameters (invalid-request, with `parameter`): a filter that names nothing (an unknown status or analysis, text that is not a shape id), or a parameter given twice", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn list_jobs(
    State(st): State<AppState>,
    Query(f): Query<JobFilter>,
) -> Result<Json<JobPage>, ApiError> {
    let all: Vec<JobView> = st
        .jobs
        .list()?
        .into_iter()
        .filter(|j| f.status.is_none_or(|s| j.status == s))
        .filter(|j| f.shape_id.as_ref().is_none_or(|s| j.shape_id == s.hex()))
        .filter(|j| f.analysis.as_deref().is_none_or(|a| j.analysis == a))
        .collect();
    let limit = f.limit.unwrap_or(100).min(1000);
    let offset = f.offset.unwrap_or(0);
    let items: Vec<JobResource> = all.iter().skip(offset).take(limit).map(job_resource).collect();
    Ok(Json(JobPage { total: all.len(), offset, limit, items }))
}

/// A job: status, progress, timestamps, error (problem detail) and result link.
#[utoipa::path(get, path = "/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path)),
    responses((status = 200, body = JobResource), (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn get_job(State(st): State<AppState>, JobPath(id): JobPath) -> Result<Json<JobResource>, ApiError> {
    st.jobs.view(&id)?.map(|j| Json(job_resource(&j))).ok_or(ApiError::NotFound { what: "job", id: id.hex() })
}

/// Cancel a job (POST `/v1/jobs/{id}/cancel` or DELETE `/v1/jobs/{id}`): an enqueued job never starts, a running
/// one stops at its next stop-flag check (every phase makes one; see docs/service.md, "Cancel and timeouts"). Finished jobs are left as they are.
#[utoipa::path(post, path = "/v1/jobs/{id}/cancel", tag = "jobs", params(("id" = String, Path)),
    responses((status = 202, description = "cancellation requested", body = JobResource),
              (status = 200, description = "already finished", body = JobResource),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn cancel_job(State(st): State<AppState>, JobPath(id): JobPath) -> Result<Response, ApiError> {
    let view = st.jobs.view(&id)?.ok_or_else(|| ApiError::NotFound { what: "job", id: id.hex() })?;
    if view.status.terminal() {
        return Ok(job_response(StatusCode::OK, &view));
    }
    let view = st.jobs.cancel(&id)?.ok_or(ApiError::NotFound { what: "job", id: id.hex() })?;
    Ok(job_response(StatusCode::ACCEPTED, &view))
}

/// Cancel a job (the same as POST `/v1/jobs/{id}/cancel`); the job record stays.
#[utoipa::path(delete, path = "/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path)),
    responses((status = 202, description = "cancellation requested", body = JobResource),
              (status = 200, description = "already finished", body = JobResource),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn delete_job(state: State<AppState>, id: JobPath) -> Result<Response, ApiError> {
    cancel_job(state, id).await
}

/// Progress as server-sent events: one `job` event with the job object on every change, until it finishes.
#[utoipa::path(get, path = "/v1/jobs/{id}/events", tag = "jobs", params(("id" = String, Path)),
    responses((status = 200, description = "text/event-stream of job objects", content_type = "text/event-stream"),
              (status = 404, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn job_events(State(st): State<AppState>, JobPath(id): JobPath) -> Result<Response, ApiError> {
    let mut watch = st.jobs.watch(&id);
    let first = watch.current()?.ok_or(ApiError::NotFound { what: "job", id: id.hex() })?;
    // One event per change of the job's view, wherever it runs, until it ends.
    let stream = futures_util::stream::unfold(
        (watch, Some(first), None::<Value>, false),
        |(mut w, next, last, done)| async move {
            if done {
                return None;
            }
            let mut next = next;
            loop {
                let view = match next.take() {
                    Some(view) => view,
                    None => {
                        w.changed().await;
                        w.current().ok().flatten()?
                    }
                };
                let json = serde_json::to_value(job_resource(&view)).unwrap_or(Value::Null);
                if last.as_ref() == Some(&json) {
                    continue;
                }
                let ev = Event::default().event("job").json_data(&json).unwrap_or_default();
                return Some((Ok::<_, std::convert::Infallible>(ev), (w, None, Some(json), view.status.terminal())));
            }
        },
    );
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct AnalyzeQuery {
    /// Seconds to wait for the result (default 10, at most --max-wait-s); a finite number, at least 0.
    #[param(minimum = 0)]
    pub wait: Option<f64>,
    /// Format of the shape (as for uploads).
    #[param(value_type = Option<kac_core::io::Format>)]
    pub format: Option<String>,
    /// The analysis as JSON (`{"analysis":"spectrum","k":10}`), when the body is the raw shape.
    pub analysis: Option<String>,
}

/// Upload and analyse in one request: multipart with a `file` part and an `analysis` part (JSON), with per-vertex
/// inputs as `.npy` parts named after their fields as for `/v1/jobs`, or the raw shape as the body and
/// `?analysis=JSON`. Returns the result (200) when it is ready within `wait` seconds, the
/// job (202) otherwise, or the job's problem if it failed.
#[utoipa::path(post, path = "/v1/analyze", tag = "jobs", params(AnalyzeQuery),
    request_body(content = Vec<u8>, description = "multipart/form-data with 'file' and 'analysis' parts, or the raw shape", content_type = "multipart/form-data"),
    responses((status = 200, description = "the result", body = AnalysisResult),
              (status = 202, description = "not ready within wait: the job", body = JobResource, headers(("Location" = String))),
              (status = 400, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 409, description = "the job was canceled", body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = crate::service::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn analyze(
    State(st): State<AppState>,
    Query(q): Query<AnalyzeQuery>,
    req: Request,
) -> Result<Response, ApiError> {
    // `wait` was checked by `Query` (finite, at least 0) before the upload is read or a job submitted (a NaN wait
    // panicked the timer after the job was queued).
    let headers = req.headers().clone();
    let mut up = read_upload(&st, q.format.clone(), req).await?;
    let text = q
        .analysis
        .clone()
        .or_else(|| up.fields.iter().find(|(n, _)| n == "analysis").map(|(_, v)| v.clone()))
        .ok_or_else(|| ApiError::invalid_request("give the analysis as a multipart part or ?analysis=JSON"))?;
    let mut value = json_value(text.as_bytes(), "analysis")?;
    merge_arrays(&mut value, &up.arrays)?;
    crate::service::strict::check_body(crate::service::openapi::served(), &value, "Analysis")
        .map_err(|u| ApiError::UnknownField(Box::new(u)))?;
    let analysis: Analysis =
        serde_json::from_value(value).map_err(|e| ApiError::invalid_json(format!("analysis: {e}")))?;
    up.fields.clear();
    let (_, shape) = ingest(&st, up).await?;
    let (job, _) = jobs::submit(&st.jobs, &st.engine.config, shape, analysis)?;
    answer_within(&st, &job, q.wait, &headers).await
}

/// Waits until the job ends or `wait` seconds (default 10, at most --max-wait-s) pass; its view then.
pub(crate) async fn wait_for(st: &AppState, job: &JobView, wait: Option<f64>) -> Result<JobView, ApiError> {
    let wait = wait.unwrap_or(10.0).clamp(0.0, st.config.max_wait_s as f64);
    let mut watch = st.jobs.watch(&id_of(job)?);
    let mut last = job.clone();
    let _ = tokio::time::timeout(std::time::Duration::from_secs_f64(wait), async {
        loop {
            if last.status.terminal() {
                break;
            }
            watch.changed().await;
            if let Ok(Some(v)) = watch.current() {
                last = v;
            }
        }
    })
    .await;
    Ok(match watch.current()? {
        Some(v) => v,
        None => last,
    })
}

/// The synchronous form of a job (`?wait=` seconds, default 10, at most --max-wait-s): its result (200) when it
/// is ready in time, its problem when it failed or was canceled, else the job (202, to poll or follow).
pub(crate) async fn answer_within(
    st: &AppState,
    job: &JobView,
    wait: Option<f64>,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let view = wait_for(st, job, wait).await?;
    match view.status {
        Status::Succeeded => {
            let r = st
                .results
                .get(&id_of(&view)?)
                .map_err(store_error)?
                .ok_or(ApiError::Internal { detail: "the result went missing".into() })?;
            Ok(with_location(result_response(&r, headers, true), &format!("/v1/results/{}", view.id)))
        }
        Status::Failed | Status::Canceled => {
            let f = view.error.as_ref().ok_or(ApiError::Internal { detail: "a failed job without an error".into() })?;
            Ok(with_location(failure_response(f), &format!("/v1/jobs/{}", view.id)))
        }
        _ => Ok(job_response(StatusCode::ACCEPTED, &view)),
    }
}
