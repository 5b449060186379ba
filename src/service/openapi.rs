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
        super::routes::delete_job,
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
        kac_core::io::Format,
    )),
    modifiers(&CommonResponses),
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

/// Responses every operation can give, added where an operation does not list them itself: 400 (malformed
/// parameters), 401/403/429 (API keys and rate limits, when configured), 500; and 413/415 on operations with a
/// request body.
struct CommonResponses;

impl utoipa::Modify for CommonResponses {
    fn modify(&self, api: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::{ContentBuilder, Ref, ResponseBuilder};
        let problem = |desc: &str| {
            ResponseBuilder::new()
                .description(desc)
                .content(
                    "application/problem+json",
                    ContentBuilder::new().schema(Some(Ref::from_schema_name("Problem"))).build(),
                )
                .build()
        };
        for (path, item) in api.paths.paths.iter_mut() {
            let v1 = path.starts_with("/v1/");
            let ops =
                [item.get.as_mut(), item.post.as_mut(), item.put.as_mut(), item.delete.as_mut(), item.patch.as_mut()];
            for op in ops.into_iter().flatten() {
                let has_body = op.request_body.is_some();
                let mut add = vec![("400", "malformed parameters (invalid-request)"), ("500", "internal error")];
                if v1 {
                    add.push(("401", "an API key is required (unauthorized)"));
                    add.push(("403", "the API key is not accepted (forbidden)"));
                    add.push(("429", "rate limit (rate-limited), with Retry-After"));
                }
                if has_body {
                    add.push(("413", "body or limit exceeded"));
                    add.push(("415", "unsupported media type or format"));
                }
                for (code, desc) in add {
                    op.responses.responses.entry(code.to_string()).or_insert_with(|| problem(desc).into());
                }
            }
        }
    }
}
