//! The problem document (RFC 9457): how a request or a job failed. A data type of its own, apart from the HTTP
//! layer (`service::error` maps every error to one), so that the job engine and the stores can record a job's
//! failure without depending on HTTP.

use serde::Serialize;
use serde_json::{Map, Value};

/// An RFC 9457 problem document.
#[derive(Debug, Clone, Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Problem {
    /// `/problems/{code}`: stable, documented at that path.
    #[serde(rename = "type")]
    pub type_: String,
    pub title: String,
    pub status: u16,
    pub detail: String,
    /// The stable code (the last segment of `type`).
    pub code: String,
    #[serde(flatten)]
    #[schema(value_type = Object)]
    pub extra: Map<String, Value>,
}

impl Problem {
    /// A job that was canceled (409 `canceled`): what the engine records when a cancel ends a job, wherever it is.
    pub fn canceled() -> Problem {
        Problem {
            type_: "/problems/canceled".into(),
            title: "Canceled".into(),
            status: 409,
            detail: "the job was canceled".into(),
            code: "canceled".into(),
            extra: Map::new(),
        }
    }
}
