//! Operations endpoints: liveness, readiness, Prometheus metrics and the problem documentation.

use super::*;

/// Liveness: the process serves requests.
#[utoipa::path(get, path = "/livez", tag = "operations", responses((status = 200, description = "alive", body = Liveness)))]
pub(crate) async fn livez() -> Json<Liveness> {
    Json(Liveness { status: "alive" })
}

/// Readiness: not ready while draining (after SIGTERM).
#[utoipa::path(get, path = "/readyz", tag = "operations", responses(
    (status = 200, description = "ready", body = Readiness),
    (status = 503, description = "draining", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn readyz(State(st): State<AppState>) -> Result<Json<Readiness>, ApiError> {
    if st.draining.load(Ordering::SeqCst) {
        return Err(ApiError::NotReady { detail: "the service is shutting down".into() });
    }
    if !st.shapes.healthy() {
        return Err(ApiError::NotReady { detail: "the store does not answer".into() });
    }
    let (enqueued, processing) = st.jobs.queue.depth().map_err(store_error)?;
    Ok(Json(Readiness { status: "ready", queue: enqueued + processing, capacity: st.jobs.capacity }))
}

/// Prometheus metrics: requests by route and status, latency histograms, queue depth, jobs by status, job
/// durations by analysis, eigenpair cache hits and misses, eigensolver work.
#[utoipa::path(get, path = "/metrics", tag = "operations", responses((status = 200, description = "Prometheus text format", content_type = "text/plain")))]
pub(crate) async fn metrics(State(st): State<AppState>) -> Response {
    let mut r = crate::service::ops::render(&st).into_response();
    r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; version=0.0.4"));
    r
}

/// What a problem `type` means.
#[utoipa::path(get, path = "/problems/{code}", tag = "operations",
    params(("code" = String, Path, description = "problem code")),
    responses((status = 200, description = "the code's description", body = ProblemType),
              (status = 404, description = "unknown code", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn problem_doc(Path(code): Path<String>) -> Result<Json<ProblemType>, ApiError> {
    Code::parse(&code)
        .map(|c| {
            Json(ProblemType {
                type_: format!("/problems/{c}"),
                code: c.as_str().into(),
                description: c.describe().into(),
            })
        })
        .ok_or(ApiError::NotFound { what: "problem code", id: code })
}
