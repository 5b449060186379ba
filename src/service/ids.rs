//! Ids from requests: a path segment parsed into the engine's typed ids ([`kac_engine::ids`]) before a handler
//! sees it; what does not parse names nothing and is answered 404 `not-found` with the rule it breaks.

use super::error::ApiError;
use axum::extract::{FromRequestParts, Path};
use axum::http::request::Parts;
pub use kac_engine::ids::*;

pub fn shape_id(s: &str) -> Result<ShapeId, ApiError> {
    ShapeId::parse(s).ok_or_else(|| ApiError::NotFound {
        what: "shape",
        id: format!("{} (a shape id is 64 lowercase hexadecimal digits)", shown(s)),
    })
}

/// A job id a client sent, or 404 naming the rule it breaks.
pub fn job_id(s: &str) -> Result<JobId, ApiError> {
    JobId::parse(s).ok_or_else(|| ApiError::NotFound {
        what: "job",
        id: format!("{} (a job id is 32 lowercase hexadecimal digits)", shown(s)),
    })
}

/// A result id a client sent, or 404 naming the rule it breaks.
pub fn result_id(s: &str) -> Result<ResultId, ApiError> {
    JobId::parse(s).ok_or_else(|| ApiError::NotFound {
        what: "result",
        id: format!("{} (a result id is 32 lowercase hexadecimal digits)", shown(s)),
    })
}

/// A batch id a client sent, or 404 naming the rule it breaks.
pub fn batch_id(s: &str) -> Result<BatchId, ApiError> {
    BatchId::parse(s).ok_or_else(|| ApiError::NotFound {
        what: "batch",
        id: format!("{} (a batch id is 32 lowercase hexadecimal digits)", shown(s)),
    })
}

/// The `{id}` of a route under `/v1/shapes/`, parsed.
pub struct ShapePath(pub ShapeId);
/// The `{id}` of a route under `/v1/jobs/`, parsed.
pub struct JobPath(pub JobId);
/// The `{batch}` of `/v1/shapes/bulk/{batch}`, parsed.
pub struct BatchPath(pub BatchId);
/// The `{id}` of a route under `/v1/results/`, parsed (with the rest of the path's parameters as text).
pub struct ResultPath(pub ResultId, pub Option<String>);

/// The route's path parameters as text (a percent-decoding failure is a 404 as well: nothing has such a name).
async fn params(parts: &mut Parts) -> Result<Vec<(String, String)>, ApiError> {
    Path::<Vec<(String, String)>>::from_request_parts(parts, &())
        .await
        .map(|p| p.0)
        .map_err(|e| ApiError::NotFound { what: "resource", id: e.body_text() })
}

fn param<'a>(ps: &'a [(String, String)], name: &str) -> &'a str {
    ps.iter().find(|(k, _)| k == name).map_or("", |(_, v)| v.as_str())
}

impl<S: Send + Sync> FromRequestParts<S> for ShapePath {
    type Rejection = ApiError;
    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        Ok(ShapePath(shape_id(param(&params(parts).await?, "id"))?))
    }
}

impl<S: Send + Sync> FromRequestParts<S> for JobPath {
    type Rejection = ApiError;
    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        Ok(JobPath(job_id(param(&params(parts).await?, "id"))?))
    }
}

impl<S: Send + Sync> FromRequestParts<S> for BatchPath {
    type Rejection = ApiError;
    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        Ok(BatchPath(batch_id(param(&params(parts).await?, "batch"))?))
    }
}

impl<S: Send + Sync> FromRequestParts<S> for ResultPath {
    type Rejection = ApiError;
    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, ApiError> {
        let ps = params(parts).await?;
        let file = ps.iter().find(|(k, _)| k == "file").map(|(_, v)| v.clone());
        Ok(ResultPath(result_id(param(&ps, "id"))?, file))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_id_that_does_not_parse_is_not_found() {
        let shape = "0123456789abcdef".repeat(4);
        assert!(shape_id(&shape).is_ok() && job_id(&shape[..32]).is_ok() && result_id(&shape[..32]).is_ok());
        assert!(shape_id("..%2Fx").is_err() && job_id(&shape).is_err() && result_id(&shape).is_err());
        assert!(batch_id(&shape[..32]).is_ok() && batch_id(&shape).is_err() && batch_id("..").is_err());
    }
}
