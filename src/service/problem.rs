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
    /// A problem with its code, title, status and sentence (no extra members).
    pub fn new(status: u16, code: &str, title: &str, detail: String) -> Problem {
        Problem {
            type_: format!("/problems/{code}"),
            title: title.into(),
            status,
            detail,
            code: code.into(),
            extra: Map::new(),
        }
    }

    /// An analysis that failed or was refused: 409 when it was stopped, 413 when it would hold too much (as a
    /// limit checked at submission), 422 when the request is at fault, 500 otherwise. The one mapping, for jobs and
    /// for requests alike.
    pub fn of_analysis(e: &crate::analysis::AnalysisError) -> Problem {
        let status = if e.is_stop() {
            409
        } else if matches!(e, crate::analysis::AnalysisError::TooLarge(_)) {
            413
        } else if e.caller_fault() {
            422
        } else {
            500
        };
        Problem::new(status, e.code(), "The analysis cannot be computed", e.to_string())
    }

    /// A job that ran past `--job-timeout-s` (500 `job-timeout`).
    pub fn job_timeout(seconds: u64) -> Problem {
        Problem::new(
            500,
            "job-timeout",
            "Job time limit",
            format!("the job ran longer than {seconds} s (--job-timeout-s)"),
        )
    }

    /// A job whose computation panicked (500 `job-panicked`); `detail` is the panic's message.
    pub fn job_panicked(detail: &str) -> Problem {
        Problem::new(500, "job-panicked", "Internal error", format!("the computation panicked: {detail}"))
    }

    /// A fault of the service itself (500 `internal-error`).
    pub fn internal(detail: String) -> Problem {
        Problem::new(500, "internal-error", "Internal error", detail)
    }

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
