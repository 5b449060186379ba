//! Routes under `/v1`, operations endpoints, the OpenAPI document and the interactive docs: the router and the
//! request plumbing every handler shares (strict bodies and queries, body errors, encodings, 405s) here, the
//! handlers one file per resource.

mod analyses;
mod archive;
mod collection;
mod health;
mod registry;
mod responses;
mod results;
mod retrieval;
mod shapes;
mod viewer;

pub(crate) use analyses::*;
pub(crate) use collection::*;
pub(crate) use health::*;
pub(crate) use registry::*;
pub use responses::*;
pub(crate) use results::*;
pub(crate) use retrieval::*;
pub(crate) use shapes::*;
pub(crate) use viewer::*;

use super::compare::CompareRequest;
use super::correspondence::CorrespondenceRequest;
use super::error::store_error;
use super::error::{failure_response, ApiError};
use super::ids::{JobPath, ResultPath, ShapePath};
use super::jobs::{self, JobProgress, JobView, Status};
use super::problem::Problem;
use super::search::{SearchError, Tag};
use super::store::{ShapeRecord, StoredResult, StoredShape};
use super::AppState;
use crate::analysis::{self, Analysis};
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{DefaultBodyLimit, FromRequest, FromRequestParts, Multipart, Path, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode, Uri};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use kac_core::io::Format;
use kac_core::{ReadOptions, ValidateOptions};
use kac_engine::Code;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use utoipa_swagger_ui::SwaggerUi;

pub fn router(state: AppState) -> Router {
    let limit = state.config.max_body_bytes;
    let state_cors = state.config.cors_origins.clone();
    let api = Router::new()
        .route("/livez", get(livez))
        .route("/readyz", get(readyz))
        .route("/v1/shapes", post(upload_shape).get(list_shapes))
        .route("/v1/shapes/bulk", post(bulk_upload))
        .route("/v1/shapes/bulk/{batch}", get(bulk_progress))
        .route("/v1/shapes/{id}", get(get_shape).delete(delete_shape))
        .route("/v1/shapes/{id}/tags", get(get_tags).put(put_tags))
        .route("/v1/shapes/{id}/geometry", get(get_geometry))
        .route("/v1/jobs", post(create_job).get(list_jobs))
        .route("/v1/jobs/{id}", get(get_job).delete(delete_job))
        .route("/v1/jobs/{id}/cancel", post(cancel_job))
        .route("/v1/jobs/{id}/events", get(job_events))
        .route("/v1/results/{id}", get(get_result))
        .route("/v1/results/{id}/arrays/{file}", get(get_array))
        .route("/v1/analyze", post(analyze))
        .route("/v1/analyses", get(list_analyses))
        .route("/v1/compare", post(compare))
        .route("/v1/correspondence", post(correspondence))
        .route("/v1/search", post(search))
        .route("/v1/search/audit", get(search_audit))
        .route("/problems/{code}", get(problem_doc))
        .route("/openapi.json", get(openapi_json))
        .merge(SwaggerUi::new("/docs").config(utoipa_swagger_ui::Config::from("/openapi.json")))
        .route("/metrics", get(metrics))
        .route("/", get(viewer_index))
        .route("/viewer/{file}", get(viewer_file))
        .fallback(not_found)
        .route_layer(axum::middleware::from_fn_with_state(state.clone(), super::bodies::guard))
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
    let app = Router::new().fallback_service(api).layer(axum::middleware::map_response(problem_405));
    // Outermost: a preflight is answered before authentication (it carries no key) and routing.
    match cors_layer(&state_cors) {
        Some(cors) => app.layer(cors),
        None => app,
    }
}

/// CORS for web front ends on other origins (`--cors-origins`; none by default: same origin only). Preflights
/// are answered for every route with the methods and headers a client of the API sends; `ETag`, `Location` and
/// `Retry-After` are exposed. A request from an origin not in the list gets no `Access-Control-Allow-Origin`, so
/// the browser keeps the answer from its page.
fn cors_layer(origins: &[String]) -> Option<tower_http::cors::CorsLayer> {
    use tower_http::cors::{AllowOrigin, CorsLayer};
    if origins.is_empty() {
        return None;
    }
    // Trimmed as `config::cors_origin` checked them ("https://a.org, https://b.org" lists two origins).
    let allow = if origins.iter().any(|o| o.trim() == "*") {
        AllowOrigin::any()
    } else {
        AllowOrigin::list(origins.iter().filter_map(|o| HeaderValue::from_str(o.trim().trim_end_matches('/')).ok()))
    };
    Some(
        CorsLayer::new()
            .allow_origin(allow)
            .allow_methods([axum::http::Method::GET, axum::http::Method::POST, axum::http::Method::DELETE])
            .allow_headers([
                header::AUTHORIZATION,
                header::CONTENT_TYPE,
                header::IF_NONE_MATCH,
                axum::http::HeaderName::from_static("last-event-id"),
            ])
            .expose_headers([header::ETAG, header::LOCATION, header::RETRY_AFTER])
            .max_age(std::time::Duration::from_secs(600)),
    )
}

/// The document `kac openapi` prints (with the request schemas closed, see `openapi::document`), built once.
pub(crate) async fn openapi_json() -> Response {
    static DOC: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    let body = DOC.get_or_init(super::openapi::document).clone();
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}

/// A stored shape by an id a client sent (a body field): parsed first, so text that is not an id never reaches
/// the store; 404 when it is not an id or names no stored shape.
pub(crate) fn stored_shape(st: &AppState, id: &str) -> Result<Arc<StoredShape>, ApiError> {
    let parsed = super::ids::shape_id(id)?;
    st.shapes.get(&parsed).map_err(store_error)?.ok_or_else(|| ApiError::NotFound { what: "shape", id: id.into() })
}

/// The id of a job view the service made (its ids are hashes it wrote): typed for the stores.
pub(crate) fn id_of(view: &JobView) -> Result<super::ids::JobId, ApiError> {
    super::ids::JobId::parse(&view.id)
        .ok_or_else(|| ApiError::Internal { detail: format!("a stored job has the malformed id {:?}", view.id) })
}

pub(crate) async fn not_found(uri: Uri) -> ApiError {
    ApiError::RouteNotFound { path: uri.path().to_string() }
}

/// Whether a body error comes from the body read timeout (`tower_http`'s `TimeoutError` in its source chain).
pub(crate) fn timed_out(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cur = Some(e);
    while let Some(err) = cur {
        if err.is::<tower_http::timeout::TimeoutError>() {
            return true;
        }
        cur = err.source();
    }
    false
}

pub(crate) fn body_error(state: &AppState, e: BytesRejection) -> ApiError {
    if let Some(detail) = super::bodies::too_slow(&e) {
        ApiError::BodyTooSlow { detail }
    } else if crate::service::error::over_body_limit(e.status()) {
        ApiError::BodyTooLarge { limit: state.config.max_body_bytes }
    } else if timed_out(&e) {
        ApiError::BodyTimeout { seconds: state.config.body_read_timeout_s }
    } else {
        ApiError::invalid_request(e.body_text())
    }
}

/// The problem a JSON body refused by axum's parser is answered with (the body's own errors as [`body_error`]).
fn json_error(state: &AppState, e: axum::extract::rejection::JsonRejection) -> ApiError {
    use axum::extract::rejection::JsonRejection as Axum;
    match e {
        Axum::MissingJsonContentType(_) => not_json(),
        Axum::BytesRejection(b) => body_error(state, b),
        other if crate::service::error::over_body_limit(other.status()) => {
            ApiError::BodyTooLarge { limit: state.config.max_body_bytes }
        }
        other => ApiError::invalid_json(other.body_text()),
    }
}

fn not_json() -> ApiError {
    ApiError::UnsupportedMediaType { detail: "send the request body as application/json".into() }
}

/// The project's JSON: as a request body, read by [`Json`]'s extractor, which refuses a body whose objects name a
/// key twice (400 `invalid-json` naming the key, see [`super::strict::duplicate_key`]) before it is parsed, and
/// answers every refusal as a problem; as a response, serialized as axum's `Json` does.
pub(crate) struct Json<T>(pub T);

/// What [`Json`] refuses a body with: the problem it is answered with (the body limits it names are the state's).
pub(crate) type JsonRejection = ApiError;

/// `application/json` or `application/<anything>+json`, parameters (`; charset=utf-8`) ignored, as axum's `Json`.
fn json_content_type(headers: &HeaderMap) -> bool {
    let Some(ct) = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()) else { return false };
    let essence = ct.split(';').next().unwrap_or("").trim().to_ascii_lowercase();
    match essence.split_once('/') {
        Some(("application", sub)) => sub == "json" || sub.ends_with("+json"),
        _ => false,
    }
}

impl<T: serde::de::DeserializeOwned> FromRequest<AppState> for Json<T> {
    type Rejection = ApiError;
    async fn from_request(req: Request, state: &AppState) -> Result<Self, ApiError> {
        if !json_content_type(req.headers()) {
            return Err(not_json());
        }
        let bytes = Bytes::from_request(req, state).await.map_err(|e| body_error(state, e))?;
        if let Some(key) = super::strict::duplicate_key(&bytes) {
            return Err(ApiError::DuplicateKey { within: "the request body".into(), key: Box::new(key) });
        }
        axum::Json::<T>::from_bytes(&bytes).map(|axum::Json(v)| Json(v)).map_err(|e| json_error(state, e))
    }
}

impl<T: Serialize> IntoResponse for Json<T> {
    fn into_response(self) -> Response {
        axum::Json(self.0).into_response()
    }
}

/// JSON text a client sent inside a request (a multipart part, a query parameter) as a value: a key named twice
/// in one object is refused (400 `invalid-json` with its pointer), as is text that is not JSON; `within` names
/// the part or parameter in the problem.
pub(crate) fn json_value(text: &[u8], within: &str) -> Result<Value, ApiError> {
    if let Some(key) = super::strict::duplicate_key(text) {
        return Err(ApiError::DuplicateKey { within: within.into(), key: Box::new(key) });
    }
    serde_json::from_slice(text).map_err(|e| ApiError::invalid_json(format!("{within}: {e}")))
}

/// A JSON body (no key twice in an object, see [`Json`]) checked against its OpenAPI schema (no field the document
/// does not declare at its place, see [`super::strict`]), then deserialized. (The state is the extractor's now:
/// the body's refusal already names its limits.)
pub(crate) fn strict_body<T: serde::de::DeserializeOwned>(
    _: &AppState,
    body: Result<Json<Value>, JsonRejection>,
    schema: &str,
) -> Result<T, ApiError> {
    let Json(v) = body?;
    super::strict::check_body(super::openapi::served(), &v, schema).map_err(|u| ApiError::UnknownField(Box::new(u)))?;
    serde_json::from_value(v).map_err(|e| ApiError::invalid_json(e.to_string()))
}

/// Every query parameter must be one the document declares for the routed operation.
pub(crate) async fn strict_query(
    matched: Option<axum::extract::MatchedPath>,
    req: Request,
    next: axum::middleware::Next,
) -> Result<Response, ApiError> {
    if let (Some(path), Some(query)) = (matched.as_ref(), req.uri().query()) {
        super::strict::check_query(super::openapi::served(), path.as_str(), req.method().as_str(), query)
            .map_err(|u| ApiError::UnknownField(Box::new(u)))?;
    }
    Ok(next.run(req).await)
}

/// The service reads request bodies as sent: a `Content-Encoding` other than `identity` (a gzip-compressed
/// upload, say) is 415 `unsupported-media-type`, rather than bytes sniffed as some format and refused with a
/// misleading parse error.
pub(crate) async fn identity_encoding_only(req: Request, next: axum::middleware::Next) -> Result<Response, ApiError> {
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

/// Query parameters whose rejection is a problem document (400 `invalid-request` with the `parameter`), not
/// axum's plain text. A parameter given twice is refused, as is a value its type does not take (a status, an
/// analysis or an id that names nothing); `wait`, on every route that takes it, is a finite number of seconds, at
/// least 0.
pub struct Query<T>(pub T);

impl<T: serde::de::DeserializeOwned, S: Send + Sync> FromRequestParts<S> for Query<T> {
    type Rejection = ApiError;
    async fn from_request_parts(parts: &mut axum::http::request::Parts, _: &S) -> Result<Self, ApiError> {
        let query = parts.uri.query().unwrap_or_default();
        let mut seen: Vec<std::borrow::Cow<str>> = vec![];
        for (name, value) in form_urlencoded::parse(query.as_bytes()) {
            if seen.contains(&name) {
                return Err(ApiError::InvalidParameter {
                    detail: format!("the query parameter `{name}` is given more than once: give it once"),
                    parameter: name.into_owned(),
                });
            }
            if name == "wait" {
                wait_seconds(&value)?;
            }
            seen.push(name);
        }
        let uri = parts.uri.clone();
        axum::extract::Query::<T>::try_from_uri(&uri).map(|q| Query(q.0)).map_err(|e| {
            // axum's text is "Failed to deserialize query string: {parameter}: {why}" (serde_path_to_error's path).
            let text = e.body_text();
            let why = text.strip_prefix("Failed to deserialize query string: ").unwrap_or(&text);
            match why.split_once(": ").filter(|(p, _)| seen.iter().any(|n| n == p)) {
                Some((parameter, why)) => ApiError::InvalidParameter {
                    detail: format!("the query parameter `{parameter}`: {why}"),
                    parameter: parameter.to_string(),
                },
                None => ApiError::invalid_request(format!("the query string: {why}")),
            }
        })
    }
}

/// A `wait` query parameter: seconds, a finite number of at least 0 (larger values are cut to --max-wait-s).
pub(crate) fn wait_seconds(text: &str) -> Result<f64, ApiError> {
    match text.trim().parse::<f64>() {
        Ok(w) if w.is_finite() && w >= 0.0 => Ok(w),
        _ => Err(ApiError::InvalidParameter {
            parameter: "wait".into(),
            detail: format!("wait = {text:?}: give a finite number of seconds, at least 0"),
        }),
    }
}

/// 405 responses keep axum's `Allow` header and get a problem body.
pub(crate) async fn problem_405(resp: Response) -> Response {
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

pub(crate) fn with_location(mut r: Response, location: &str) -> Response {
    if let Ok(v) = HeaderValue::from_str(location) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}
