//! The OpenAPI document, generated from the handlers and types by utoipa. Served at `/openapi.json`, committed
//! at `openapi/openapi.json` (`kac openapi > openapi/openapi.json`); a test fails when the two differ.

use utoipa::OpenApi;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "kac",
        description = "Can you hear the shape of a drum? Spectral shape analysis: upload a shape, run analyses \
(spectra, heat kernel signatures, shape-DNA, geodesics, …) as jobs, fetch immutable results. Errors are RFC 9457 \
problem+json with a stable `type` (`/problems/{code}`).",
        license(name = "MIT OR Apache-2.0")
    ),
    paths(
        super::routes::livez,
        super::routes::readyz,
        super::routes::metrics,
        super::routes::problem_doc,
        super::routes::upload_shape,
        super::routes::list_shapes,
        super::routes::get_shape,
        super::routes::delete_shape,
        super::routes::create_job,
        super::routes::list_jobs,
        super::routes::get_job,
        super::routes::cancel_job,
        super::routes::job_events,
        super::routes::get_result,
        super::routes::get_array,
        super::routes::analyze,
        super::routes::compare,
    ),
    components(schemas(
        super::error::Problem,
        super::routes::ShapeResource,
        super::routes::JobRequest,
        super::routes::CompareRequest,
        super::jobs::JobView,
        super::jobs::Status,
        super::jobs::JobProgress,
        crate::analysis::Analysis,
    )),
    tags(
        (name = "shapes", description = "Upload and inspect shapes (addressed by content hash)"),
        (name = "jobs", description = "Analyses as jobs; the synchronous form; comparisons"),
        (name = "results", description = "Immutable results and their per-vertex arrays"),
        (name = "operations", description = "Health and problem documentation"),
    )
)]
pub struct ApiDoc;

/// The document as pretty JSON (what `kac openapi` prints and `/openapi.json` serves).
pub fn document() -> String {
    ApiDoc::openapi().to_pretty_json().unwrap_or_default()
}
