//! The problem document (RFC 9457): how a request or a job failed, as the service answers it. A [`Failure`] the
//! engine recorded becomes one here, with the status its [`Code`] maps to ([`super::error::status_of`]).

use kac_engine::{Code, Failure};
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
    /// A problem with its code, title and sentence; the status is the code's.
    pub fn new(code: Code, title: &str, detail: String) -> Problem {
        Problem {
            type_: format!("/problems/{code}"),
            title: title.into(),
            status: super::error::status_of(code).as_u16(),
            detail,
            code: code.as_str().into(),
            extra: Map::new(),
        }
    }
}

impl From<&Failure> for Problem {
    fn from(f: &Failure) -> Problem {
        Problem { extra: f.extra.clone(), ..Problem::new(f.code, &f.title, f.detail.clone()) }
    }
}
