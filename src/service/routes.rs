//! Routes under `/v1`, operations endpoints, the OpenAPI document and the interactive docs.

use super::compare::CompareRequest;
use super::error::{problem_response, ApiError, CODES};
use super::jobs::{self, JobView, Status};
use super::search::SearchRequest;
use super::store::{ShapeRecord, StoredResult, StoredShape};
use super::AppState;
use crate::analysis::{self, Analysis};
use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, JsonRejection};
use axum::extract::{DefaultBodyLimit, FromRequest, FromRequestParts, Multipart, Path, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode, Uri};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use kac_core::io::Format;
use kac_core::{ReadOptions, ValidateOptions};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use utoipa_swagger_ui::SwaggerUi;

pub fn router(state: AppState) -> Router {
    let limit = state.config.max_body_bytes;
    let api = Router::new()
        .route("/livez", get(livez))
        .route("/readyz", get(readyz))
        .route("/v1/shapes", post(upload_shape).get(list_shapes))
        .route("/v1/shapes/{id}", get(get_shape).delete(delete_shape))
        .route("/v1/jobs", post(create_job).get(list_jobs))
        .route("/v1/jobs/{id}", get(get_job).delete(delete_job))
        .route("/v1/jobs/{id}/cancel", post(cancel_job))
        .route("/v1/jobs/{id}/events", get(job_events))
        .route("/v1/results/{id}", get(get_result))
        .route("/v1/results/{id}/arrays/{file}", get(get_array))
        .route("/v1/analyze", post(analyze))
        .route("/v1/compare", post(compare))
        .route("/v1/search", post(search))
        .route("/problems/{code}", get(problem_doc))
        .route("/openapi.json", get(openapi_json))
        .merge(SwaggerUi::new("/docs").config(utoipa_swagger_ui::Config::from("/openapi.json")))
        .route("/metrics", get(metrics))
        .fallback(not_found)
        .route_layer(axum::middleware::from_fn(strict_query))
        .route_layer(axum::middleware::from_fn(identity_encoding_only))
        .route_layer(axum::middleware::from_fn_with_state(state.clone(), super::ops::authorize))
        .route_layer(axum::middleware::from_fn_with_state(state.clone(), super::ops::observe))
        .layer(DefaultBodyLimit::max(limit))
        .layer(tower_http::timeout::RequestBodyTimeoutLayer::new(std::time::Duration::from_secs_f64(
            state.config.body_read_timeout_s.max(0.001),
        )))
        .with_state(state);
    // Outside the method routers, where 405 responses already carry their Allow header.
    Router::new().fallback_service(api).layer(axum::middleware::map_response(problem_405))
}

/// The document `kac openapi` prints (with the request schemas closed, see `openapi::document`), built once.
async fn openapi_json() -> Response {
    static DOC: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    let body = DOC.get_or_init(super::openapi::document).clone();
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

async fn not_found(uri: Uri) -> ApiError {
    ApiError::RouteNotFound { path: uri.path().to_string() }
}

/// Whether a body error comes from the body read timeout (`tower_http`'s `TimeoutError` in its source chain).
fn timed_out(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur = Some(e);
    while let Some(err) = cur {
        if err.is::<tower_http::timeout::TimeoutError>() {
            return true;
        }
        cur = err.source();
    }
    false
}

fn body_error(state: &AppState, e: BytesRejection) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        ApiError::BodyTooLarge { limit: state.config.max_body_bytes }
    } else if timed_out(&e) {
        ApiError::BodyTimeout { seconds: state.config.body_read_timeout_s }
    } else {
        ApiError::invalid_request(e.body_text())
    }
}

fn json_error(state: &AppState, e: JsonRejection) -> ApiError {
    match e {
        JsonRejection::MissingJsonContentType(_) => {
            ApiError::UnsupportedMediaType { detail: "send the request body as application/json".into() }
        }
        JsonRejection::BytesRejection(b) => body_error(state, b),
        other if other.status() == StatusCode::PAYLOAD_TOO_LARGE => {
            ApiError::BodyTooLarge { limit: state.config.max_body_bytes }
        }
        other => ApiError::invalid_json(other.body_text()),
    }
}

/// A JSON body checked against its OpenAPI schema (no field the document does not declare at its place, see
/// [`super::strict`]), then deserialized.
fn strict_body<T: serde::de::DeserializeOwned>(
    st: &AppState,
    body: Result<Json<Value>, JsonRejection>,
    schema: &str,
) -> Result<T, ApiError> {
    let Json(v) = body.map_err(|e| json_error(st, e))?;
    super::strict::check_body(&v, schema).map_err(ApiError::UnknownField)?;
    serde_json::from_value(v).map_err(|e| ApiError::invalid_json(e.to_string()))
}

/// Every query parameter must be one the document declares for the routed operation.
async fn strict_query(
    matched: Option<axum::extract::MatchedPath>,
    req: Request,
    next: axum::middleware::Next,
) -> Result<Response, ApiError> {
    if let (Some(path), Some(query)) = (matched.as_ref(), req.uri().query()) {
        super::strict::check_query(path.as_str(), req.method().as_str(), query).map_err(ApiError::UnknownField)?;
    }
    Ok(next.run(req).await)
}

/// The service reads request bodies as sent: a `Content-Encoding` other than `identity` (a gzip-compressed
/// upload, say) is 415 `unsupported-media-type`, rather than bytes sniffed as some format and refused with a
/// misleading parse error.
async fn identity_encoding_only(req: Request, next: axum::middleware::Next) -> Result<Response, ApiError> {
    if let Some(enc) = req.headers().get(header::CONTENT_ENCODING) {
        let enc = enc.to_str().unwrap_or("(not text)").trim();
        if !enc.eq_ignore_ascii_case("identity") && !enc.is_empty() {
            return Err(ApiError::UnsupportedMediaType {
                detail: format!(
                    "Content-Encoding '{enc}' is not decoded here: send the body uncompressed (identity encoding)"
                ),
            });
        }
    }
    Ok(next.run(req).await)
}

/// Query parameters whose rejection is a problem document (400 `invalid-request`), not axum's plain text.
pub struct Query<T>(pub T);

impl<T: serde::de::DeserializeOwned, S: Send + Sync> FromRequestParts<S> for Query<T> {
    type Rejection = ApiError;
    async fn from_request_parts(parts: &mut axum::http::request::Parts, state: &S) -> Result<Self, ApiError> {
        axum::extract::Query::<T>::from_request_parts(parts, state)
            .await
            .map(|q| Query(q.0))
            .map_err(|e| ApiError::invalid_request(e.body_text()))
    }
}

/// 405 responses keep axum's `Allow` header and get a problem body.
async fn problem_405(resp: Response) -> Response {
    if resp.status() != StatusCode::METHOD_NOT_ALLOWED
        || resp.headers().get(header::CONTENT_TYPE).is_some_and(|c| c == "application/problem+json")
    {
        return resp;
    }
    // HEAD is implied by GET (RFC 9110); the Allow header lists the documented methods.
    let allow = resp
        .headers()
        .get(header::ALLOW)
        .and_then(|a| a.to_str().ok())
        .map(|a| a.split(',').map(str::trim).filter(|m| *m != "HEAD").collect::<Vec<_>>().join(","));
    let allow = allow.and_then(|a| HeaderValue::from_str(&a).ok());
    let mut r = ApiError::MethodNotAllowed.into_response();
    if let Some(a) = allow {
        r.headers_mut().insert(header::ALLOW, a);
    }
    r
}

fn with_location(mut r: Response, location: &str) -> Response {
    if let Ok(v) = HeaderValue::from_str(location) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}

// ---------------------------------------------------------------------------------------------------------------
// Operations

/// Liveness: the process serves requests.
#[utoipa::path(get, path = "/livez", tag = "operations", responses((status = 200, description = "alive")))]
async fn livez() -> Json<Value> {
    Json(json!({ "status": "alive" }))
}

/// Readiness: not ready while draining (after SIGTERM).
#[utoipa::path(get, path = "/readyz", tag = "operations", responses(
    (status = 200, description = "ready"),
    (status = 503, description = "draining", body = super::error::Problem, content_type = "application/problem+json")))]
async fn readyz(State(st): State<AppState>) -> Result<Json<Value>, ApiError> {
    if st.draining.load(Ordering::SeqCst) {
        return Err(ApiError::NotReady { detail: "the service is shutting down".into() });
    }
    if !st.shapes.healthy() {
        return Err(ApiError::NotReady { detail: "the store does not answer".into() });
    }
    Ok(Json(json!({ "status": "ready", "queue": st.jobs.active.load(Ordering::SeqCst), "capacity": st.jobs.capacity })))
}

/// Prometheus metrics: requests by route and status, latency histograms, queue depth, jobs by status, job
/// durations by analysis, eigenpair cache hits and misses, eigensolver work.
#[utoipa::path(get, path = "/metrics", tag = "operations", responses((status = 200, description = "Prometheus text format", content_type = "text/plain")))]
async fn metrics(State(st): State<AppState>) -> Response {
    let mut r = super::ops::render(&st).into_response();
    r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; version=0.0.4"));
    r
}

/// What a problem `type` means.
#[utoipa::path(get, path = "/problems/{code}", tag = "operations",
    params(("code" = String, Path, description = "problem code")),
    responses((status = 200, description = "the code's description"),
              (status = 404, description = "unknown code", body = super::error::Problem, content_type = "application/problem+json")))]
async fn problem_doc(Path(code): Path<String>) -> Result<Json<Value>, ApiError> {
    CODES
        .iter()
        .find(|(c, _)| *c == code)
        .map(|(c, d)| Json(json!({ "type": format!("/problems/{c}"), "code": c, "description": d })))
        .ok_or(ApiError::NotFound { what: "problem code", id: code })
}

// ---------------------------------------------------------------------------------------------------------------
// Shapes

/// A stored shape.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ShapeResource {
    /// Content hash of the canonical geometry.
    pub id: String,
    /// The format it was read from.
    pub format: String,
    pub created_at: String,
    /// Size of the upload in bytes.
    pub bytes: usize,
    /// The validation summary (kind, counts, area, volume, topology, repairs), as `kac inspect` prints it.
    #[schema(value_type = Object)]
    pub summary: Value,
    #[schema(value_type = Object)]
    pub links: Value,
}

fn shape_resource(s: &ShapeRecord) -> ShapeResource {
    ShapeResource {
        id: s.id.clone(),
        format: s.format.clone(),
        created_at: s.created_at.clone(),
        bytes: s.bytes,
        summary: s.summary.clone(),
        links: json!({ "self": format!("/v1/shapes/{}", s.id), "jobs": format!("/v1/jobs?shape_id={}", s.id) }),
    }
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct UploadQuery {
    /// Format name; default: from the Content-Type, the multipart file name, or the content.
    #[param(value_type = Option<kac_core::io::Format>)]
    pub format: Option<String>,
}

/// An upload: bytes, and what may tell their format.
struct Upload {
    bytes: Bytes,
    format: Option<Format>,
    filename: Option<String>,
    media_type: Option<String>,
    /// Other multipart text fields (the synchronous form reads `analysis` from here).
    fields: Vec<(String, String)>,
}

fn parse_format(name: &str) -> Result<Format, ApiError> {
    Format::from_name(name).ok_or_else(|| {
        ApiError::invalid_request(format!(
            "unknown format '{name}'; one of: obj, off, ply, stl, gltf, glb, medit, gmsh, vtk, xyz, csv, json, mtx"
        ))
    })
}

async fn read_upload(st: &AppState, q_format: Option<String>, req: Request) -> Result<Upload, ApiError> {
    let ct = req.headers().get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("").to_string();
    let mut up = Upload {
        bytes: Bytes::new(),
        format: q_format.as_deref().map(parse_format).transpose()?,
        filename: None,
        media_type: None,
        fields: vec![],
    };
    if ct.to_ascii_lowercase().starts_with("multipart/form-data") {
        let mut mp = Multipart::from_request(req, st)
            .await
            .map_err(|e| ApiError::invalid_request(format!("multipart: {}", e.body_text())))?;
        let mut got = false;
        loop {
            let field = match mp.next_field().await {
                Ok(Some(f)) => f,
                Ok(None) => break,
                Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => {
                    return Err(ApiError::BodyTooLarge { limit: st.config.max_body_bytes })
                }
                Err(e) if timed_out(&e) => {
                    return Err(ApiError::BodyTimeout { seconds: st.config.body_read_timeout_s })
                }
                Err(e) => return Err(ApiError::invalid_request(format!("multipart: {}", e.body_text()))),
            };
            let name = field.name().unwrap_or("").to_string();
            let filename = field.file_name().map(str::to_string);
            let media = field.content_type().map(str::to_string);
            let data = field.bytes().await.map_err(|e| {
                if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                    ApiError::BodyTooLarge { limit: st.config.max_body_bytes }
                } else if timed_out(&e) {
                    ApiError::BodyTimeout { seconds: st.config.body_read_timeout_s }
                } else {
                    ApiError::invalid_request(format!("multipart: {}", e.body_text()))
                }
            })?;
            if !got && (filename.is_some() || name == "file" || name == "shape") {
                up.bytes = data;
                up.filename = filename;
                up.media_type = media;
                got = true;
            } else if name == "format" {
                let f = String::from_utf8_lossy(&data).trim().to_string();
                up.format = Some(parse_format(&f)?);
            } else {
                up.fields.push((name, String::from_utf8_lossy(&data).into_owned()));
            }
        }
        if !got {
            return Err(ApiError::invalid_request("the multipart body has no file part (name it 'file')"));
        }
    } else {
        up.media_type = (!ct.is_empty()).then_some(ct);
        up.bytes = Bytes::from_request(req, st).await.map_err(|e| body_error(st, e))?;
    }
    Ok(up)
}

/// Parses and validates an upload (on the blocking pool) and stores it: (created, shape).
async fn ingest(st: &AppState, up: Upload) -> Result<(bool, Arc<StoredShape>), ApiError> {
    if up.bytes.is_empty() {
        return Err(ApiError::invalid_request("the request body is empty; send the shape file"));
    }
    let format = match up.format {
        Some(f) => f,
        None => {
            let by_name = up
                .filename
                .as_deref()
                .and_then(|n| std::path::Path::new(n).extension())
                .and_then(|e| e.to_str())
                .and_then(Format::from_name);
            let by_media = up
                .media_type
                .as_deref()
                .filter(|m| !m.starts_with("application/octet-stream") && !m.starts_with("text/plain"))
                .and_then(Format::from_media_type);
            match by_name.or(by_media) {
                Some(f) => f,
                None => kac_core::io::choose_format(None, None, &up.bytes)?,
            }
        }
    };
    let max_vertices = st.config.max_vertices;
    let bytes = up.bytes.clone();
    let v = tokio::task::spawn_blocking(move || {
        let read = ReadOptions { max_vertices, ..Default::default() };
        kac_core::load_bytes(&bytes, format, &read, &ValidateOptions::default())
    })
    .await
    .map_err(|e| ApiError::Internal { detail: format!("validation panicked: {e}") })??;
    if v.shape.vertex_count() > max_vertices {
        return Err(ApiError::Shape(kac_core::ShapeError::LimitExceeded {
            what: "the vertex count".into(),
            value: v.shape.vertex_count() as u64,
            limit: max_vertices as u64,
        }));
    }
    let summary = serde_json::to_value(v.summary()).map_err(|e| ApiError::Internal { detail: e.to_string() })?;
    let record = ShapeRecord {
        id: v.id.hex(),
        format: format.name().into(),
        created_at: jobs::now(),
        bytes: up.bytes.len(),
        summary,
    };
    let stored = StoredShape { record, validated: v };
    // Storing writes and fsyncs a file and a record: on the blocking pool, off the request threads.
    let shapes = st.shapes.clone();
    tokio::task::spawn_blocking(move || shapes.insert(stored, &up.bytes))
        .await
        .map_err(|e| ApiError::Internal { detail: format!("storing panicked: {e}") })?
        .map_err(|e| ApiError::Internal { detail: format!("the shape could not be stored: {e}") })
}

/// Upload a shape: the file as the raw body (format from `?format=`, the Content-Type, or the content) or as a
/// multipart part named `file`. Idempotent by content hash: 201 the first time, 200 after.
#[utoipa::path(post, path = "/v1/shapes", tag = "shapes", params(UploadQuery),
    request_body(content = Vec<u8>, description = "the shape file (raw or multipart/form-data with a 'file' part)", content_type = "application/octet-stream"),
    responses(
        (status = 201, description = "stored", body = ShapeResource, headers(("Location" = String))),
        (status = 200, description = "already stored", body = ShapeResource, headers(("Location" = String))),
        (status = 400, description = "bad request", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "too large", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 415, description = "unknown format", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 422, description = "invalid shape", body = super::error::Problem, content_type = "application/problem+json")))]
async fn upload_shape(
    State(st): State<AppState>,
    Query(q): Query<UploadQuery>,
    req: Request,
) -> Result<Response, ApiError> {
    let up = read_upload(&st, q.format, req).await?;
    let (created, shape) = ingest(&st, up).await?;
    let status = if created { StatusCode::CREATED } else { StatusCode::OK };
    let loc = format!("/v1/shapes/{}", shape.id);
    Ok(with_location((status, Json(shape_resource(&shape))).into_response(), &loc))
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct Page {
    /// At most this many (default 100, at most 1000).
    pub limit: Option<usize>,
    pub offset: Option<usize>,
}

/// List stored shapes (id order).
#[utoipa::path(get, path = "/v1/shapes", tag = "shapes", params(Page), responses((status = 200, description = "a page of shapes")))]
async fn list_shapes(State(st): State<AppState>, Query(p): Query<Page>) -> Json<Value> {
    let limit = p.limit.unwrap_or(100).min(1000);
    let offset = p.offset.unwrap_or(0);
    let (items, total) = st.shapes.list(offset, limit);
    let items: Vec<ShapeResource> = items.iter().map(shape_resource).collect();
    Json(json!({ "total": total, "offset": offset, "limit": limit, "items": items }))
}

/// A stored shape with its validation summary.
#[utoipa::path(get, path = "/v1/shapes/{id}", tag = "shapes", params(("id" = String, Path)),
    responses((status = 200, body = ShapeResource),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn get_shape(State(st): State<AppState>, Path(id): Path<String>) -> Result<Json<ShapeResource>, ApiError> {
    st.shapes.get(&id).map(|s| Json(shape_resource(&s))).ok_or(ApiError::NotFound { what: "shape", id })
}

/// Delete a stored shape (its finished results stay available by id).
#[utoipa::path(delete, path = "/v1/shapes/{id}", tag = "shapes", params(("id" = String, Path)),
    responses((status = 204, description = "deleted"),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn delete_shape(State(st): State<AppState>, Path(id): Path<String>) -> Result<StatusCode, ApiError> {
    if st.shapes.remove(&id) {
        st.index.remove_shape(&id);
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::NotFound { what: "shape", id })
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Jobs

/// A job request: the shape and the analysis with its parameters (`{"shape_id": "…", "analysis": "hks", "k": 50}`).
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
pub struct JobRequest {
    pub shape_id: String,
    #[serde(flatten)]
    pub analysis: Analysis,
}

fn job_response(status: StatusCode, v: &JobView) -> Response {
    with_location((status, Json(job_json(v))).into_response(), &format!("/v1/jobs/{}", v.id))
}

fn job_json(v: &JobView) -> Value {
    let mut j = serde_json::to_value(v).unwrap_or(Value::Null);
    if let Some(o) = j.as_object_mut() {
        o.insert(
            "links".into(),
            json!({ "self": format!("/v1/jobs/{}", v.id), "events": format!("/v1/jobs/{}/events", v.id), "shape": format!("/v1/shapes/{}", v.shape_id) }),
        );
    }
    j
}

/// Submit an analysis of a stored shape: 202 with the job (a repeated request returns the existing job, 200).
#[utoipa::path(post, path = "/v1/jobs", tag = "jobs", request_body = JobRequest,
    responses(
        (status = 202, description = "enqueued", body = JobView, headers(("Location" = String))),
        (status = 200, description = "the same request was already submitted", body = JobView, headers(("Location" = String))),
        (status = 400, body = super::error::Problem, content_type = "application/problem+json"),
        (status = 404, description = "no such shape", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "k above --max-k", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "queue full", body = super::error::Problem, content_type = "application/problem+json", headers(("Retry-After" = u64)))))]
async fn create_job(
    State(st): State<AppState>,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Response, ApiError> {
    let req: JobRequest = strict_body(&st, body, "JobRequest")?;
    let shape = st.shapes.get(&req.shape_id).ok_or(ApiError::NotFound { what: "shape", id: req.shape_id.clone() })?;
    let (job, created) = jobs::submit(&st, shape, req.analysis)?;
    Ok(job_response(if created { StatusCode::ACCEPTED } else { StatusCode::OK }, &job.snapshot()))
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct JobFilter {
    /// enqueued, processing, succeeded, failed, canceled.
    pub status: Option<String>,
    pub shape_id: Option<String>,
    /// Analysis name (spectrum, hks, …).
    pub analysis: Option<String>,
    pub limit: Option<usize>,
    pub offset: Option<usize>,
}

/// List jobs, oldest first, with filters.
#[utoipa::path(get, path = "/v1/jobs", tag = "jobs", params(JobFilter), responses((status = 200, description = "a page of jobs")))]
async fn list_jobs(State(st): State<AppState>, Query(f): Query<JobFilter>) -> Json<Value> {
    let all: Vec<JobView> = st
        .jobs
        .list()
        .into_iter()
        .filter(|j| f.status.as_deref().is_none_or(|s| j.status.name() == s))
        .filter(|j| f.shape_id.as_deref().is_none_or(|s| j.shape_id == s))
        .filter(|j| f.analysis.as_deref().is_none_or(|a| j.analysis == a))
        .collect();
    let limit = f.limit.unwrap_or(100).min(1000);
    let offset = f.offset.unwrap_or(0);
    let items: Vec<Value> = all.iter().skip(offset).take(limit).map(job_json).collect();
    Json(json!({ "total": all.len(), "offset": offset, "limit": limit, "items": items }))
}

/// A job: status, progress, timestamps, error (problem detail) and result link.
#[utoipa::path(get, path = "/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path)),
    responses((status = 200, body = JobView), (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn get_job(State(st): State<AppState>, Path(id): Path<String>) -> Result<Json<Value>, ApiError> {
    st.jobs.get(&id).map(|j| Json(job_json(&j.snapshot()))).ok_or(ApiError::NotFound { what: "job", id })
}

/// Cancel a job (POST `/v1/jobs/{id}/cancel` or DELETE `/v1/jobs/{id}`): an enqueued job never starts, a running
/// eigensolve stops at its next block step. Finished jobs are left as they are.
#[utoipa::path(post, path = "/v1/jobs/{id}/cancel", tag = "jobs", params(("id" = String, Path)),
    responses((status = 202, description = "cancellation requested", body = JobView),
              (status = 200, description = "already finished", body = JobView),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn cancel_job(State(st): State<AppState>, Path(id): Path<String>) -> Result<Response, ApiError> {
    let job = st.jobs.get(&id).ok_or(ApiError::NotFound { what: "job", id })?;
    let view = job.snapshot();
    if view.status.terminal() {
        return Ok(job_response(StatusCode::OK, &view));
    }
    jobs::cancel(&st, &job);
    Ok(job_response(StatusCode::ACCEPTED, &job.snapshot()))
}

/// Cancel a job (the same as POST `/v1/jobs/{id}/cancel`); the job record stays.
#[utoipa::path(delete, path = "/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path)),
    responses((status = 202, description = "cancellation requested", body = JobView),
              (status = 200, description = "already finished", body = JobView),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn delete_job(state: State<AppState>, id: Path<String>) -> Result<Response, ApiError> {
    cancel_job(state, id).await
}

/// Progress as server-sent events: one `job` event with the job object on every change, until it finishes.
#[utoipa::path(get, path = "/v1/jobs/{id}/events", tag = "jobs", params(("id" = String, Path)),
    responses((status = 200, description = "text/event-stream of job objects", content_type = "text/event-stream"),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn job_events(State(st): State<AppState>, Path(id): Path<String>) -> Result<Response, ApiError> {
    let job = st.jobs.get(&id).ok_or(ApiError::NotFound { what: "job", id })?;
    let rx = job.view.subscribe();
    let stream = futures_util::stream::unfold((rx, false, true), |(mut rx, done, first)| async move {
        if done {
            return None;
        }
        if !first && rx.changed().await.is_err() {
            return None;
        }
        let v = rx.borrow_and_update().clone();
        let terminal = v.status.terminal();
        let ev = Event::default().event("job").json_data(job_json(&v)).unwrap_or_default();
        Some((Ok::<_, std::convert::Infallible>(ev), (rx, terminal, false)))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()).into_response())
}

// ---------------------------------------------------------------------------------------------------------------
// Results

#[derive(Deserialize, utoipa::IntoParams)]
pub struct ResultQuery {
    /// Include per-vertex values inline (default true; false gives the summary and the array links only).
    pub values: Option<bool>,
}

fn immutable(mut r: Response, etag: &str) -> Response {
    let h = r.headers_mut();
    if let Ok(v) = HeaderValue::from_str(etag) {
        h.insert(header::ETAG, v);
    }
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("public, max-age=31536000, immutable"));
    r
}

fn not_modified(headers: &HeaderMap, etag: &str) -> bool {
    headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"))
}

fn result_body(r: &StoredResult, values: bool) -> (Bytes, String) {
    if values {
        (r.body.clone(), r.etag.clone())
    } else {
        (r.summary_body.clone(), format!("\"{}-summary\"", r.etag.trim_matches('"')))
    }
}

fn result_response(r: &StoredResult, headers: &HeaderMap, values: bool) -> Response {
    let (body, etag) = result_body(r, values);
    if not_modified(headers, &etag) {
        return immutable(StatusCode::NOT_MODIFIED.into_response(), &etag);
    }
    let mut resp = (StatusCode::OK, body).into_response();
    resp.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("application/json"));
    immutable(resp, &etag)
}

/// A finished result (immutable; strong ETag, `If-None-Match` → 304).
#[utoipa::path(get, path = "/v1/results/{id}", tag = "results", params(("id" = String, Path), ResultQuery),
    responses((status = 200, description = "the result JSON: every parameter used, the numbers, per-vertex arrays with .npy and .ply links"),
              (status = 304, description = "not modified"),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn get_result(
    State(st): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<ResultQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let r = st.results.get(&id).ok_or(ApiError::NotFound { what: "result", id })?;
    Ok(result_response(&r, &headers, q.values.unwrap_or(true)))
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct ArrayQuery {
    /// PLY: which column colours the vertices (default 0).
    pub column: Option<usize>,
}

/// A per-vertex array of a result: `NAME.npy` (float64, rows in the upload's vertex numbering), `NAME.json`, or
/// `NAME.ply` (the shape with one column as vertex colours, for viewing).
#[utoipa::path(get, path = "/v1/results/{id}/arrays/{file}", tag = "results",
    params(("id" = String, Path), ("file" = String, Path, description = "NAME.npy, NAME.json or NAME.ply"), ArrayQuery),
    responses((status = 200, description = "the array"), (status = 304, description = "not modified"),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json")))]
async fn get_array(
    State(st): State<AppState>,
    Path((id, file)): Path<(String, String)>,
    Query(q): Query<ArrayQuery>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let r = st.results.get(&id).ok_or(ApiError::NotFound { what: "result", id: id.clone() })?;
    let (name, ext) = file.rsplit_once('.').ok_or(ApiError::NotFound { what: "array", id: file.clone() })?;
    let a = r.arrays.iter().find(|a| a.name == name).ok_or(ApiError::NotFound { what: "array", id: file.clone() })?;
    let col = q.column.unwrap_or(0);
    let etag = format!("\"{}-{name}-{ext}-{col}\"", r.etag.trim_matches('"'));
    if not_modified(&headers, &etag) {
        return Ok(immutable(StatusCode::NOT_MODIFIED.into_response(), &etag));
    }
    let (body, ct): (Vec<u8>, &'static str) = match ext {
        "npy" => (kac_core::io::npy::encode_f64(a.rows, a.cols, &a.data), "application/octet-stream"),
        "json" => (
            serde_json::to_vec(&json!({ "rows": a.rows, "cols": a.cols, "columns": a.columns, "values": a.to_json() }))
                .unwrap_or_default(),
            "application/json",
        ),
        "ply" => {
            if col >= a.cols {
                return Err(ApiError::invalid_request(format!("column {col} does not exist ({} columns)", a.cols)));
            }
            let shape_id = r.summary["shape_id"].as_str().unwrap_or("").to_string();
            let shape = st.shapes.get(&shape_id).ok_or(ApiError::NotFound { what: "shape", id: shape_id })?;
            (coloured_ply(&shape, a, col), "application/x-ply")
        }
        _ => return Err(ApiError::NotFound { what: "array format", id: file }),
    };
    let mut resp = (StatusCode::OK, body).into_response();
    resp.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(ct));
    Ok(immutable(resp, &etag))
}

/// The validated shape as binary PLY with one array column mapped to colours (dark blue → yellow, a
/// viridis-like ramp over the finite range; NaN grey).
fn coloured_ply(shape: &StoredShape, a: &analysis::VertexArray, col: usize) -> Vec<u8> {
    let v = &shape.validated;
    let n = v.shape.vertex_count();
    let mut vals = vec![f64::NAN; n];
    for (input, &m) in v.vertex_map.iter().enumerate() {
        if m != u32::MAX && vals[m as usize].is_nan() {
            vals[m as usize] = a.data[input * a.cols + col];
        }
    }
    let (lo, hi) = vals.iter().filter(|x| x.is_finite()).fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    const RAMP: [[f64; 3]; 5] =
        [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];
    let colors: Vec<[u8; 3]> = vals
        .iter()
        .map(|&x| {
            if !x.is_finite() {
                return [128, 128, 128];
            }
            let t = if hi > lo { (x - lo) / (hi - lo) } else { 0.5 } * 4.0;
            let i = (t.floor() as usize).min(3);
            let f = t - i as f64;
            let c = |k: usize| (RAMP[i][k] * (1.0 - f) + RAMP[i + 1][k] * f).round() as u8;
            [c(0), c(1), c(2)]
        })
        .collect();
    kac_core::io::write::ply(&v.shape, true, Some(&colors))
}

// ---------------------------------------------------------------------------------------------------------------
// Synchronous form and comparison

#[derive(Deserialize, utoipa::IntoParams)]
pub struct AnalyzeQuery {
    /// Seconds to wait for the result (default 10, at most --max-wait-s).
    pub wait: Option<f64>,
    /// Format of the shape (as for uploads).
    #[param(value_type = Option<kac_core::io::Format>)]
    pub format: Option<String>,
    /// The analysis as JSON (`{"analysis":"spectrum","k":10}`), when the body is the raw shape.
    pub analysis: Option<String>,
}

/// Upload and analyse in one request: multipart with a `file` part and an `analysis` part (JSON), or the raw
/// shape as the body and `?analysis=JSON`. Returns the result (200) when it is ready within `wait` seconds, the
/// job (202) otherwise, or the job's problem if it failed.
#[utoipa::path(post, path = "/v1/analyze", tag = "jobs", params(AnalyzeQuery),
    request_body(content = Vec<u8>, description = "multipart/form-data with 'file' and 'analysis' parts, or the raw shape", content_type = "multipart/form-data"),
    responses((status = 200, description = "the result"),
              (status = 202, description = "not ready within wait: the job", body = JobView, headers(("Location" = String))),
              (status = 400, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 409, description = "the job was canceled", body = super::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = super::error::Problem, content_type = "application/problem+json")))]
async fn analyze(
    State(st): State<AppState>,
    Query(q): Query<AnalyzeQuery>,
    req: Request,
) -> Result<Response, ApiError> {
    if let Some(w) = q.wait.filter(|w| !w.is_finite()) {
        // Before the upload is read or a job submitted (a NaN wait panicked the timer after the job was queued).
        return Err(ApiError::invalid_request(format!("wait = {w}: give a finite number of seconds")));
    }
    let headers = req.headers().clone();
    let mut up = read_upload(&st, q.format.clone(), req).await?;
    let text = q
        .analysis
        .clone()
        .or_else(|| up.fields.iter().find(|(n, _)| n == "analysis").map(|(_, v)| v.clone()))
        .ok_or_else(|| ApiError::invalid_request("give the analysis as a multipart part or ?analysis=JSON"))?;
    let value: Value = serde_json::from_str(&text).map_err(|e| ApiError::invalid_json(format!("analysis: {e}")))?;
    super::strict::check_body(&value, "Analysis").map_err(ApiError::UnknownField)?;
    let analysis: Analysis =
        serde_json::from_value(value).map_err(|e| ApiError::invalid_json(format!("analysis: {e}")))?;
    up.fields.clear();
    let (_, shape) = ingest(&st, up).await?;
    let (job, _) = jobs::submit(&st, shape, analysis)?;
    answer_within(&st, &job, q.wait, &headers).await
}

/// Waits until the job ends or `wait` seconds (default 10, at most --max-wait-s) pass; its view then.
async fn wait_for(st: &AppState, job: &jobs::Job, wait: Option<f64>) -> JobView {
    let wait = wait.unwrap_or(10.0).clamp(0.0, st.config.max_wait_s as f64);
    let mut rx = job.view.subscribe();
    let _ = tokio::time::timeout(std::time::Duration::from_secs_f64(wait), async {
        loop {
            if rx.borrow_and_update().status.terminal() {
                break;
            }
            if rx.changed().await.is_err() {
                break;
            }
        }
    })
    .await;
    job.snapshot()
}

/// The synchronous form of a job (`?wait=` seconds, default 10, at most --max-wait-s): its result (200) when it
/// is ready in time, its problem when it failed or was canceled, else the job (202, to poll or follow).
async fn answer_within(
    st: &AppState,
    job: &jobs::Job,
    wait: Option<f64>,
    headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let view = wait_for(st, job, wait).await;
    match view.status {
        Status::Succeeded => {
            let r = st.results.get(&view.id).ok_or(ApiError::Internal { detail: "the result went missing".into() })?;
            Ok(with_location(result_response(&r, headers, true), &format!("/v1/results/{}", view.id)))
        }
        Status::Failed | Status::Canceled => {
            let p = view.error.clone().ok_or(ApiError::Internal { detail: "a failed job without an error".into() })?;
            let status = StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
            Ok(with_location(problem_response(status, &p), &format!("/v1/jobs/{}", view.id)))
        }
        _ => Ok(job_response(StatusCode::ACCEPTED, &view)),
    }
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct CompareQuery {
    /// Seconds to wait for the result (default 10, at most --max-wait-s); 0 answers 202 with the job at once.
    pub wait: Option<f64>,
}

/// Distances between stored shapes by shape-DNA, and each shape's nearest neighbours, as a job in the queue
/// (its capacity, the job timeout, cancel; the same request again is the same job): the result (200) when it is
/// ready within `wait` seconds, the job (202) otherwise. A shape whose fingerprint fails is listed under
/// `failures`; the others are compared.
#[utoipa::path(post, path = "/v1/compare", tag = "jobs", params(CompareQuery), request_body = CompareRequest,
    responses((status = 200, description = "the distance matrix, nearest neighbours and per-shape failures"),
              (status = 202, description = "not ready within wait: the job", body = JobView, headers(("Location" = String))),
              (status = 400, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 409, description = "the job was canceled", body = super::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = super::error::Problem, content_type = "application/problem+json")))]
async fn compare(
    State(st): State<AppState>,
    Query(q): Query<CompareQuery>,
    headers: HeaderMap,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Response, ApiError> {
    if let Some(w) = q.wait.filter(|w| !w.is_finite()) {
        return Err(ApiError::invalid_request(format!("wait = {w}: give a finite number of seconds")));
    }
    let req: CompareRequest = strict_body(&st, body, "CompareRequest")?;
    let max = super::compare::MAX_SHAPES;
    let shapes: Vec<Arc<StoredShape>> = match &req.shape_ids {
        Some(ids) if ids.len() > max => {
            return Err(ApiError::invalid_request(format!("{} shapes: at most {max} per comparison", ids.len())))
        }
        Some(ids) => ids
            .iter()
            .map(|id| st.shapes.get(id).ok_or_else(|| ApiError::NotFound { what: "shape", id: id.clone() }))
            .collect::<Result<_, _>>()?,
        None => st.shapes.list(0, max).0.iter().filter_map(|r| st.shapes.get(&r.id)).collect(),
    };
    let (job, _) = jobs::submit_compare(&st, req, shapes)?;
    answer_within(&st, &job, q.wait, &headers).await
}

#[derive(Deserialize, utoipa::IntoParams)]
pub struct SearchQuery {
    /// With `shape_id` whose fingerprint is not stored yet: seconds to wait for its `shape-dna` job (default 10, at
    /// most --max-wait-s) before answering 202 with the job.
    pub wait: Option<f64>,
}

/// The stored shapes nearest to a shape or a fingerprint by shape-DNA, over every fingerprint of the same family
/// (k, normalization, reweighting, include_zero, operator) the service holds: those of finished `shape-dna`
/// jobs and comparisons. A `shape_id` without a stored fingerprint gets one first, as a `shape-dna` job (202 with
/// the job when it is not done within `wait`).
#[utoipa::path(post, path = "/v1/search", tag = "jobs", params(SearchQuery), request_body = SearchRequest,
    responses((status = 200, description = "the nearest shapes, nearest first, and how many were searched"),
              (status = 202, description = "the query shape's fingerprint is being computed: the job", body = JobView, headers(("Location" = String))),
              (status = 400, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 404, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 422, body = super::error::Problem, content_type = "application/problem+json"),
              (status = 503, body = super::error::Problem, content_type = "application/problem+json")))]
async fn search(
    State(st): State<AppState>,
    Query(q): Query<SearchQuery>,
    body: Result<Json<Value>, JsonRejection>,
) -> Result<Response, ApiError> {
    if let Some(w) = q.wait.filter(|w| !w.is_finite()) {
        return Err(ApiError::invalid_request(format!("wait = {w}: give a finite number of seconds")));
    }
    let req: SearchRequest = strict_body(&st, body, "SearchRequest")?;
    if req.k == 0 {
        return Err(ApiError::Analysis(analysis::AnalysisError::invalid_k(
            "k = 0: a fingerprint has at least one value",
        )));
    }
    if req.k > st.config.max_k {
        return Err(ApiError::KTooLarge { detail: format!("k = {} is above --max-k {}", req.k, st.config.max_k) });
    }
    if req.neighbours > 1000 {
        return Err(ApiError::invalid_request(format!("neighbours = {}: at most 1000", req.neighbours)));
    }
    let family = req.family();
    let query = match (&req.shape_id, &req.fingerprint) {
        (Some(_), Some(_)) | (None, None) => {
            return Err(ApiError::invalid_request("give either shape_id or fingerprint (one of them)"))
        }
        (None, Some(f)) => {
            if let Some(i) = f.iter().position(|x| !x.is_finite()) {
                return Err(ApiError::invalid_request(format!("fingerprint value {i} is not a finite number")));
            }
            f.clone()
        }
        (Some(id), None) => match st.index.get(&family, id) {
            Some(f) => f,
            None => {
                let shape = st.shapes.get(id).ok_or_else(|| ApiError::NotFound { what: "shape", id: id.clone() })?;
                let dna = Analysis::ShapeDna {
                    options: req.options(),
                    operator: req.operator.clone(),
                    solver: analysis::SolverSpec::default(),
                };
                let (job, _) = jobs::submit(&st, shape, dna)?;
                let view = wait_for(&st, &job, q.wait).await;
                match (st.index.get(&family, id), view.status) {
                    (Some(f), _) => f,
                    (None, Status::Succeeded) => {
                        // A shape-dna job that finished before fingerprints were kept (or whose fingerprint could
                        // not be kept): its stored result holds the values.
                        let r = st
                            .results
                            .get(&view.id)
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
                        let p = view
                            .error
                            .clone()
                            .ok_or(ApiError::Internal { detail: "a failed job without an error".into() })?;
                        let status = StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
                        return Ok(with_location(problem_response(status, &p), &format!("/v1/jobs/{}", view.id)));
                    }
                    (None, _) => return Ok(job_response(StatusCode::ACCEPTED, &view)),
                }
            }
        },
    };
    let (near, searched) = st
        .index
        .nearest(&family, &query, req.metric, req.neighbours, req.shape_id.as_deref())
        .map_err(ApiError::invalid_request)?;
    let neighbours: Vec<Value> = near.into_iter().map(|(id, d)| json!({ "shape_id": id, "distance": d })).collect();
    Ok(Json(json!({
        "descriptor": "shape-dna",
        "family": family,
        "options": req.options(),
        "metric": req.metric.name(),
        "operator": req.operator,
        "shape_id": req.shape_id,
        "fingerprint": query,
        "searched": searched,
        "neighbours": neighbours,
    }))
    .into_response())
}
