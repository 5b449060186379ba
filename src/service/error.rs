//! RFC 9457 problem details for every error the service returns. Domain errors map to HTTP in one exhaustive
//! match ([`ApiError::problem`]); `type` is `/problems/{code}` with a stable code, served as documentation.

use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use kac_core::ShapeError;
use serde_json::{Map, Value};

pub use super::problem::Problem;
use kac_engine::{Code, Failure};

/// Everything a handler can fail with.
#[derive(Debug)]
pub enum ApiError {
    Shape(ShapeError),
    Analysis(crate::analysis::AnalysisError),
    NotFound {
        what: &'static str,
        id: String,
    },
    RouteNotFound {
        path: String,
    },
    MethodNotAllowed,
    BodyTooLarge {
        limit: usize,
    },
    /// A malformed request: parameters, multipart, headers (400 `invalid-request`).
    InvalidRequest {
        detail: String,
    },
    /// A body that is not the JSON this endpoint takes (400 `invalid-json`).
    InvalidJson {
        detail: String,
    },
    /// A field or query parameter the OpenAPI document does not declare where it was sent (422).
    UnknownField(Box<super::strict::Unknown>),
    /// A query parameter or multipart part whose value is refused, or that was sent twice (400 `invalid-request`,
    /// with the `parameter`).
    InvalidParameter {
        parameter: String,
        detail: String,
    },
    /// A JSON object that names a key twice, in the request body or a JSON part (`within`), 400 `invalid-json`
    /// with its `pointer` and `field`.
    DuplicateKey {
        within: String,
        key: Box<super::strict::DuplicateKey>,
    },
    UnsupportedMediaType {
        detail: String,
    },
    QueueFull {
        capacity: usize,
        retry_after_s: u64,
    },
    /// A bulk upload whose jobs would take the backlog lane beyond --max-backlog (503 `queue-full`, Retry-After):
    /// refused before anything is stored.
    BacklogFull {
        backlog: usize,
        files: usize,
        limit: usize,
        retry_after_s: u64,
    },
    /// k above --max-k (413 `k-too-large`).
    KTooLarge {
        detail: String,
    },
    /// A list or grid longer than --max-samples (413 `too-many-samples`).
    TooManySamples {
        detail: String,
    },
    /// A per-vertex array larger than --max-output-values (413 `output-too-large`).
    OutputTooLarge {
        detail: String,
    },
    NotReady {
        detail: String,
    },
    Unauthorized,
    Forbidden,
    RateLimited {
        retry_after_s: u64,
        per_minute: u32,
    },
    /// A job canceled by its client.
    Canceled,
    /// A job stopped by --job-timeout-s.
    JobTimeout {
        seconds: u64,
    },
    /// A job whose computation panicked (caught on the worker).
    JobPanicked {
        detail: String,
    },
    /// Too many wrong API keys from one client address this minute.
    AuthThrottled {
        retry_after_s: u64,
        per_minute: u32,
    },
    /// A request body paused longer than --body-read-timeout-s.
    BodyTimeout {
        seconds: f64,
    },
    /// A request body that came slower than --min-body-rate-bytes-per-s (408 `body-timeout`).
    BodyTooSlow {
        detail: String,
    },
    /// Request bodies in flight, and the bytes expanded from archives, hold --max-body-memory-bytes (503
    /// `memory-busy`, Retry-After).
    MemoryBusy {
        budget: usize,
        retry_after_s: u64,
    },
    Internal {
        detail: String,
    },
}

impl ApiError {
    pub fn invalid_request(detail: impl Into<String>) -> Self {
        ApiError::InvalidRequest { detail: detail.into() }
    }
    pub fn invalid_json(detail: impl Into<String>) -> Self {
        ApiError::InvalidJson { detail: detail.into() }
    }

    /// The one mapping from errors to code, title and extra members; the status is the code's ([`status_of`]).
    pub fn problem(&self) -> (StatusCode, Problem) {
        let mut extra = Map::new();
        let (code, title, detail): (Code, &str, String) = match self {
            ApiError::Shape(e) => {
                if let Ok(Value::Object(m)) = serde_json::to_value(e) {
                    extra.insert("error".into(), Value::Object(m));
                }
                (Code::from(e), "The shape cannot be read", e.to_string())
            }
            // The errors a job can end with: the engine's failures, recorded with the job.
            ApiError::Analysis(e) => return with_status((&Failure::of_analysis(e)).into()),
            ApiError::Canceled => return with_status((&Failure::canceled()).into()),
            ApiError::JobTimeout { seconds } => return with_status((&Failure::job_timeout(*seconds)).into()),
            ApiError::JobPanicked { detail } => return with_status((&Failure::job_panicked(detail)).into()),
            ApiError::UnknownField(u) => {
                extra.insert("pointer".into(), u.pointer.clone().into());
                extra.insert("field".into(), u.name.clone().into());
                extra.insert("suggestion".into(), u.suggestion.as_deref().into());
                extra.insert("belongs_in".into(), u.belongs_in.as_deref().into());
                extra.insert("accepted".into(), u.allowed.clone().into());
                let title = if u.not_a_name.is_some() { "Invalid value" } else { "Unknown field" };
                (Code::UnknownField, title, u.detail())
            }
            ApiError::NotFound { what, id } => (Code::NotFound, "Not found", format!("no {what} with id '{id}'")),
            ApiError::RouteNotFound { path } => {
                (Code::RouteNotFound, "Not found", format!("no route {path}; see /openapi.json"))
            }
            ApiError::MethodNotAllowed => (
                Code::MethodNotAllowed,
                "Method not allowed",
                "this method is not allowed on this resource; see /openapi.json".into(),
            ),
            ApiError::BodyTooLarge { limit } => {
                extra.insert("limit_bytes".into(), (*limit).into());
                (
                    Code::BodyTooLarge,
                    "Request body too large",
                    format!("the request body exceeds the limit of {limit} bytes (--max-body-bytes)"),
                )
            }
            ApiError::InvalidRequest { detail } => (Code::InvalidRequest, "Bad request", detail.clone()),
            ApiError::InvalidJson { detail } => (Code::InvalidJson, "Bad request", detail.clone()),
            ApiError::InvalidParameter { parameter, detail } => {
                extra.insert("parameter".into(), parameter.clone().into());
                (Code::InvalidRequest, "Bad request", detail.clone())
            }
            ApiError::DuplicateKey { within, key } => {
                extra.insert("pointer".into(), key.pointer.clone().into());
                extra.insert("field".into(), key.key.clone().into());
                (Code::InvalidJson, "Bad request", format!("{within}: {}", key.detail()))
            }
            ApiError::UnsupportedMediaType { detail } => {
                (Code::UnsupportedMediaType, "Unsupported media type", detail.clone())
            }
            ApiError::QueueFull { capacity, retry_after_s } => {
                extra.insert("capacity".into(), (*capacity).into());
                extra.insert("retry_after_s".into(), (*retry_after_s).into());
                (
                    Code::QueueFull,
                    "The job queue is full",
                    format!("{capacity} jobs are queued or running; retry later"),
                )
            }
            ApiError::BacklogFull { backlog, files, limit, retry_after_s } => {
                extra.insert("backlog".into(), (*backlog).into());
                extra.insert("max_backlog".into(), (*limit).into());
                extra.insert("retry_after_s".into(), (*retry_after_s).into());
                (
                    Code::QueueFull,
                    "The job queue is full",
                    format!(
                        "the backlog holds {backlog} jobs of bulk uploads and this upload's {files} files would take                          it beyond {limit} (--max-backlog): nothing was stored; retry after Retry-After seconds, or                          send fewer files"
                    ),
                )
            }
            ApiError::BodyTooSlow { detail } => (Code::BodyTimeout, "The request body came too slowly", detail.clone()),
            ApiError::MemoryBusy { budget, retry_after_s } => {
                extra.insert("budget_bytes".into(), (*budget).into());
                extra.insert("retry_after_s".into(), (*retry_after_s).into());
                (
                    Code::MemoryBusy,
                    "Request bodies in flight hold their memory budget",
                    format!(
                        "request bodies being received and archives being expanded hold the budget of {budget} bytes \
                         (--max-body-memory-bytes); retry after Retry-After seconds"
                    ),
                )
            }
            ApiError::KTooLarge { detail } => (Code::KTooLarge, "A limit was exceeded", detail.clone()),
            ApiError::TooManySamples { detail } => (Code::TooManySamples, "A limit was exceeded", detail.clone()),
            ApiError::OutputTooLarge { detail } => (Code::OutputTooLarge, "A limit was exceeded", detail.clone()),
            ApiError::NotReady { detail } => (Code::NotReady, "Not ready", detail.clone()),
            ApiError::Unauthorized => (
                Code::Unauthorized,
                "Unauthorized",
                "this service needs an API key: send Authorization: Bearer KEY".into(),
            ),
            ApiError::Forbidden => (Code::Forbidden, "Forbidden", "the API key is not valid for this service".into()),
            ApiError::RateLimited { retry_after_s, per_minute } => {
                extra.insert("retry_after_s".into(), (*retry_after_s).into());
                (
                    Code::RateLimited,
                    "Too many requests",
                    format!("this key may make {per_minute} requests per minute; retry after {retry_after_s} s"),
                )
            }
            ApiError::AuthThrottled { retry_after_s, per_minute } => {
                extra.insert("retry_after_s".into(), (*retry_after_s).into());
                (
                    Code::RateLimited,
                    "Too many failed API keys",
                    format!(
                        "this address sent {per_minute} wrong API keys within a minute (--auth-failures-per-minute); \
                         retry after {retry_after_s} s"
                    ),
                )
            }
            ApiError::BodyTimeout { seconds } => (
                Code::BodyTimeout,
                "Request body too slow",
                format!("the request body paused for more than {seconds} s (--body-read-timeout-s)"),
            ),
            ApiError::Internal { detail } => return with_status((&Failure::internal(detail.clone())).into()),
        };
        with_status(Problem { extra, ..Problem::new(code, title, detail) })
    }
}

/// A problem with its status as the HTTP type.
fn with_status(p: Problem) -> (StatusCode, Problem) {
    (StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR), p)
}

/// The one mapping from a code to its HTTP status: a request at fault is 4xx (400 malformed, 404 nothing there,
/// 408/413/415 how it was sent, 422 understood but refused), a busy or unready service 503, a stopped job 409, and a
/// computation or the service itself 500.
pub fn status_of(code: Code) -> StatusCode {
    match code {
        Code::MalformedInput
        | Code::TruncatedInput
        | Code::NonFiniteValue
        | Code::IndexOutOfRange
        | Code::InvalidElement
        | Code::EmptyShape
        | Code::UnsupportedContent
        | Code::UnknownField
        | Code::InvalidK
        | Code::InvalidOption
        | Code::InvalidParameter
        | Code::TooFewEigenpairs
        | Code::NotApplicable
        | Code::Unsupported
        | Code::OperatorNotApplicable
        | Code::MassNotApplicable
        | Code::DegenerateElement
        | Code::NonManifold
        | Code::InvalidBoundary => StatusCode::UNPROCESSABLE_ENTITY,
        Code::FormatMismatch | Code::UnknownFormat | Code::UnsupportedMediaType => StatusCode::UNSUPPORTED_MEDIA_TYPE,
        Code::LimitExceeded | Code::BodyTooLarge | Code::KTooLarge | Code::TooManySamples | Code::OutputTooLarge => {
            StatusCode::PAYLOAD_TOO_LARGE
        }
        Code::IoError
        | Code::InternalError
        | Code::JobPanicked
        | Code::JobTimeout
        | Code::FactorizationFailed
        | Code::NoConvergence
        | Code::IncompleteSpectrum
        | Code::SolveFailed
        | Code::NonFiniteResult => StatusCode::INTERNAL_SERVER_ERROR,
        Code::NotFound | Code::RouteNotFound => StatusCode::NOT_FOUND,
        Code::MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
        Code::InvalidJson | Code::InvalidRequest => StatusCode::BAD_REQUEST,
        Code::QueueFull | Code::MemoryBusy | Code::TooManyConnections | Code::NotReady => {
            StatusCode::SERVICE_UNAVAILABLE
        }
        Code::BodyTimeout => StatusCode::REQUEST_TIMEOUT,
        Code::Unauthorized => StatusCode::UNAUTHORIZED,
        Code::Forbidden => StatusCode::FORBIDDEN,
        Code::RateLimited => StatusCode::TOO_MANY_REQUESTS,
        Code::Canceled => StatusCode::CONFLICT,
    }
}

/// A store that cannot be reached: 503 `not-ready` (the client may retry).
pub fn store_error(e: std::io::Error) -> ApiError {
    ApiError::NotReady { detail: format!("the store cannot be reached: {e}") }
}

/// The job engine's errors as problems: the same codes and statuses as before the engine had its own type.
impl From<super::jobs::JobError> for ApiError {
    fn from(e: super::jobs::JobError) -> Self {
        use super::jobs::{JobError, Limit};
        match e {
            JobError::Analysis(a) => ApiError::Analysis(a),
            JobError::Limit(Limit::Pairs(detail)) => ApiError::KTooLarge { detail },
            JobError::Limit(Limit::Samples(detail)) => ApiError::TooManySamples { detail },
            JobError::Limit(Limit::Values(detail)) => ApiError::OutputTooLarge { detail },
            JobError::QueueFull { capacity } => ApiError::QueueFull { capacity, retry_after_s: 2 },
            JobError::Store(e) => store_error(e),
            JobError::Internal(detail) => ApiError::Internal { detail },
        }
    }
}

pub fn problem_response(status: StatusCode, p: &Problem) -> Response {
    let mut r = (status, serde_json::to_string(p).unwrap_or_default()).into_response();
    r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("application/problem+json"));
    r
}

/// Whether a rejection of axum's (a body, a multipart field) is its body limit: the status `body-too-large` maps
/// to, which is how axum says it.
pub fn over_body_limit(status: StatusCode) -> bool {
    status == status_of(Code::BodyTooLarge)
}

/// A job's failure as its problem document, with the status of its code.
pub fn failure_response(f: &Failure) -> Response {
    let p = Problem::from(f);
    problem_response(status_of(f.code), &p)
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, p) = self.problem();
        let mut r = problem_response(status, &p);
        if let ApiError::QueueFull { retry_after_s, .. }
        | ApiError::BacklogFull { retry_after_s, .. }
        | ApiError::MemoryBusy { retry_after_s, .. }
        | ApiError::RateLimited { retry_after_s, .. }
        | ApiError::AuthThrottled { retry_after_s, .. } = self
        {
            r.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from(retry_after_s));
        }
        r
    }
}

impl From<ShapeError> for ApiError {
    fn from(e: ShapeError) -> Self {
        ApiError::Shape(e)
    }
}

impl From<crate::analysis::AnalysisError> for ApiError {
    fn from(e: crate::analysis::AnalysisError) -> Self {
        ApiError::Analysis(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::AnalysisError;
    use kac_core::descriptors::DescriptorError;
    use kac_core::operators::OperatorError;
    use kac_core::spectrum::EigenError;
    use kac_core::{Element, Location};

    /// One error of every kind the service can answer with. The `match` below has no wildcard, so a new variant
    /// of `ApiError` does not compile until it is listed here too.
    fn every_error() -> Vec<ApiError> {
        let at = || Location::line(1);
        let shape = vec![
            ShapeError::Syntax { format: "off", location: at(), message: "m".into() },
            ShapeError::Truncated { format: "off", location: at(), message: "m".into() },
            ShapeError::NonFinite { element: Element::Vertex, index: 0, value: "NaN".into(), location: at() },
            ShapeError::IndexOutOfRange { element: Element::Face, index: 0, value: 9, vertex_count: 3, location: at() },
            ShapeError::InvalidElement { element: Element::Face, index: 0, rule: "r".into(), location: at() },
            ShapeError::Empty { what: "w".into() },
            ShapeError::Unsupported { format: "off", location: at(), message: "m".into() },
            ShapeError::UnknownFormat { message: "m".into() },
            ShapeError::LimitExceeded { what: "w".into(), value: 2, limit: 1 },
            ShapeError::FormatMismatch { tried: "stl", looks_like: "off", head: "h".into(), reason: "r".into() },
            ShapeError::Io { path: "p".into(), message: "m".into() },
        ];
        let analysis = vec![
            AnalysisError::invalid_parameter("m"),
            AnalysisError::invalid_k("m"),
            AnalysisError::not_applicable("m"),
            AnalysisError::Unsupported("m".into()),
            AnalysisError::TooLarge("m".into()),
            AnalysisError::NonFinite { place: "p".into(), value: f64::NAN },
            AnalysisError::Operator(OperatorError::NotApplicable { operator: "cotan", kind: "graph" }),
            AnalysisError::Operator(OperatorError::MassNotApplicable { operator: "graph", mass: "lumped" }),
            AnalysisError::Operator(OperatorError::DegenerateElement {
                element: "face",
                index: 0,
                message: "m".into(),
            }),
            AnalysisError::Operator(OperatorError::NonManifold { operator: "cotan", message: "m".into() }),
            AnalysisError::Operator(OperatorError::Boundary { message: "m".into() }),
            AnalysisError::Operator(OperatorError::InvalidParameter { name: "n", message: "m".into() }),
            AnalysisError::Eigen(EigenError::InvalidK { k: 0, n: 1, max: 1 }),
            AnalysisError::Eigen(EigenError::Factorization { message: "m".into() }),
            AnalysisError::Eigen(EigenError::Canceled),
            AnalysisError::Eigen(EigenError::NoConvergence { converged: 0, wanted: 1, steps: 1 }),
            AnalysisError::Eigen(EigenError::InvalidOption { name: "tol", message: "m".into() }),
            AnalysisError::Eigen(EigenError::Incomplete { shift: 1.0, below: 2, found: 1, repairs: 3 }),
            AnalysisError::Descriptor(DescriptorError::InvalidParameter { name: "n", message: "m".into() }),
            AnalysisError::Descriptor(DescriptorError::TooFewEigenpairs { message: "m".into() }),
            AnalysisError::Descriptor(DescriptorError::NotApplicable { message: "m".into() }),
            AnalysisError::Descriptor(DescriptorError::Solve { message: "m".into() }),
        ];
        let unknown = crate::service::strict::Unknown {
            pointer: "/x".into(),
            name: "x".into(),
            suggestion: None,
            belongs_in: None,
            allowed: vec![],
            not_a_name: None,
        };
        let mut all: Vec<ApiError> = shape.into_iter().map(ApiError::Shape).collect();
        all.extend(analysis.into_iter().map(ApiError::Analysis));
        all.extend([
            ApiError::NotFound { what: "shape", id: "x".into() },
            ApiError::RouteNotFound { path: "/x".into() },
            ApiError::MethodNotAllowed,
            ApiError::BodyTooLarge { limit: 1 },
            ApiError::invalid_request("m"),
            ApiError::invalid_json("m"),
            ApiError::UnknownField(Box::new(unknown)),
            ApiError::InvalidParameter { parameter: "wait".into(), detail: "m".into() },
            ApiError::DuplicateKey {
                within: "the request body".into(),
                key: Box::new(crate::service::strict::DuplicateKey { pointer: "/k".into(), key: "k".into() }),
            },
            ApiError::UnsupportedMediaType { detail: "m".into() },
            ApiError::QueueFull { capacity: 1, retry_after_s: 1 },
            ApiError::BacklogFull { backlog: 1, files: 1, limit: 1, retry_after_s: 1 },
            ApiError::MemoryBusy { budget: 1, retry_after_s: 1 },
            ApiError::BodyTooSlow { detail: "m".into() },
            ApiError::KTooLarge { detail: "m".into() },
            ApiError::TooManySamples { detail: "m".into() },
            ApiError::OutputTooLarge { detail: "m".into() },
            ApiError::NotReady { detail: "m".into() },
            ApiError::Unauthorized,
            ApiError::Forbidden,
            ApiError::RateLimited { retry_after_s: 1, per_minute: 1 },
            ApiError::Canceled,
            ApiError::JobTimeout { seconds: 1 },
            ApiError::JobPanicked { detail: "m".into() },
            ApiError::AuthThrottled { retry_after_s: 1, per_minute: 1 },
            ApiError::BodyTimeout { seconds: 1.0 },
            ApiError::Internal { detail: "m".into() },
        ]);
        for e in &all {
            match e {
                ApiError::Shape(_)
                | ApiError::Analysis(_)
                | ApiError::NotFound { .. }
                | ApiError::RouteNotFound { .. }
                | ApiError::MethodNotAllowed
                | ApiError::BodyTooLarge { .. }
                | ApiError::InvalidRequest { .. }
                | ApiError::InvalidJson { .. }
                | ApiError::UnknownField(_)
                | ApiError::InvalidParameter { .. }
                | ApiError::DuplicateKey { .. }
                | ApiError::UnsupportedMediaType { .. }
                | ApiError::QueueFull { .. }
                | ApiError::BacklogFull { .. }
                | ApiError::KTooLarge { .. }
                | ApiError::TooManySamples { .. }
                | ApiError::OutputTooLarge { .. }
                | ApiError::NotReady { .. }
                | ApiError::Unauthorized
                | ApiError::Forbidden
                | ApiError::RateLimited { .. }
                | ApiError::Canceled
                | ApiError::JobTimeout { .. }
                | ApiError::JobPanicked { .. }
                | ApiError::AuthThrottled { .. }
                | ApiError::BodyTimeout { .. }
                | ApiError::BodyTooSlow { .. }
                | ApiError::MemoryBusy { .. }
                | ApiError::Internal { .. } => {}
            }
        }
        all
    }

    /// Every problem the service can build has a documented code: listed in `Code::ALL` (so served at
    /// `/problems/{code}`), in the OpenAPI document's `Problem.code` enum, and in the problem-code table of
    /// docs/service.md; and every listed code is one some error produces (plus the connection limit's, written by
    /// the listener).
    #[test]
    fn every_code_is_served_documented_and_in_the_openapi_document() {
        let listed: std::collections::BTreeSet<&str> = Code::ALL.iter().map(|c| c.as_str()).collect();
        let mut produced = std::collections::BTreeSet::new();
        for e in every_error() {
            let (status, p) = e.problem();
            assert!(listed.contains(p.code.as_str()), "{} is not in Code::ALL", p.code);
            assert_eq!((p.type_.clone(), p.status), (format!("/problems/{}", p.code), status.as_u16()));
            produced.insert(p.code);
        }
        produced.insert("too-many-connections".into());
        let unused: Vec<_> = listed.iter().filter(|c| !produced.contains(**c)).collect();
        assert!(unused.is_empty(), "codes no error produces: {unused:?}");
        let doc: serde_json::Value = serde_json::from_str(&crate::service::openapi::document()).unwrap();
        let in_doc: Vec<&str> = doc
            .pointer("/components/schemas/Problem/allOf")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
            .filter_map(|p| p.pointer("/properties/code/enum").and_then(Value::as_array))
            .flatten()
            .filter_map(Value::as_str)
            .collect();
        let reference = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/service.md")).unwrap();
        let section = reference.split("## Errors and problem codes").nth(1).expect("docs/service.md lists the codes");
        let rows: Vec<&str> = section
            .split("\n## ")
            .next()
            .unwrap()
            .lines()
            .filter_map(|l| l.strip_prefix("| `")?.split_once("` |").map(|(code, _)| code))
            .collect();
        for c in &listed {
            assert!(in_doc.contains(c), "{c} is not in the OpenAPI document's Problem.code");
            assert!(rows.contains(c), "{c} has no row in the problem-code table of docs/service.md");
        }
        let stale: Vec<_> = rows.iter().filter(|c| !listed.contains(*c)).collect();
        assert!(
            stale.is_empty(),
            "docs/service.md's problem-code table has codes that are not in Code::ALL: {stale:?}"
        );
    }
}
