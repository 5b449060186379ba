//! How a job failed: its [`Code`], a title and a sentence, and the members that go with the code. The engine
//! records this with the job; the HTTP layer makes an RFC 9457 problem of it, adding the status its code maps to.

use crate::code::Code;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// A job's failure (or a refusal the engine reports): no HTTP status, only the stable code.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "Recorded")]
pub struct Failure {
    pub code: Code,
    pub title: String,
    pub detail: String,
    /// The members the code documents (for example `capacity`), beside the code, title and detail.
    #[serde(flatten)]
    pub extra: Map<String, Value>,
}

/// A failure as recorded: stores written by an earlier version hold the whole problem document, whose `type` and
/// `status` follow from the code and are dropped when it is read.
#[derive(Deserialize)]
struct Recorded {
    code: Code,
    title: String,
    detail: String,
    #[serde(flatten)]
    extra: Map<String, Value>,
}

impl From<Recorded> for Failure {
    fn from(mut r: Recorded) -> Failure {
        r.extra.remove("type");
        r.extra.remove("status");
        Failure { code: r.code, title: r.title, detail: r.detail, extra: r.extra }
    }
}

impl Failure {
    /// A failure with its code, title and sentence (no extra members).
    pub fn new(code: Code, title: &str, detail: String) -> Failure {
        Failure { code, title: title.into(), detail, extra: Map::new() }
    }

    /// An analysis that failed or was refused.
    pub fn of_analysis(e: &crate::analysis::AnalysisError) -> Failure {
        Failure::new(e.code(), "The analysis cannot be computed", e.to_string())
    }

    /// A job that ran past `--job-timeout-s` (`job-timeout`).
    pub fn job_timeout(seconds: u64) -> Failure {
        Failure::new(
            Code::JobTimeout,
            "Job time limit",
            format!("the job ran longer than {seconds} s (--job-timeout-s)"),
        )
    }

    /// A job whose computation panicked (`job-panicked`); `detail` is the panic's message.
    pub fn job_panicked(detail: &str) -> Failure {
        Failure::new(Code::JobPanicked, "Internal error", format!("the computation panicked: {detail}"))
    }

    /// A fault of the service itself (`internal-error`).
    pub fn internal(detail: String) -> Failure {
        Failure::new(Code::InternalError, "Internal error", detail)
    }

    /// A job that was canceled (`canceled`): what the engine records when a cancel ends a job, wherever it is.
    pub fn canceled() -> Failure {
        Failure::new(Code::Canceled, "Canceled", "the job was canceled".into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recorded_problem_document_reads_as_its_failure() {
        let old = r#"{"type":"/problems/job-timeout","title":"Job time limit","status":500,"detail":"d",
                      "code":"job-timeout","limit":3}"#;
        let f: Failure = serde_json::from_str(old).unwrap();
        assert_eq!(f.code, Code::JobTimeout);
        assert_eq!(f.extra.len(), 1, "{:?}", f.extra);
        let back: Failure = serde_json::from_str(&serde_json::to_string(&f).unwrap()).unwrap();
        assert_eq!(back, f);
    }
}
