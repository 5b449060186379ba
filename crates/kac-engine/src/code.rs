//! The one table of stable problem codes. Every failure the engine reports, every refusal of the service and every
//! stored job's error carries a [`Code`]; the HTTP layer maps a code to a status in one exhaustive match. A code is
//! part of the contract: its text (the last segment of a problem's `type`, `/problems/{code}`) never changes.

use serde::{Deserialize, Serialize};

/// A stable problem code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Code {
    MalformedInput,
    TruncatedInput,
    NonFiniteValue,
    IndexOutOfRange,
    InvalidElement,
    EmptyShape,
    UnsupportedContent,
    FormatMismatch,
    UnknownFormat,
    LimitExceeded,
    IoError,
    NotFound,
    RouteNotFound,
    MethodNotAllowed,
    BodyTooLarge,
    InvalidJson,
    InvalidRequest,
    UnsupportedMediaType,
    QueueFull,
    MemoryBusy,
    KTooLarge,
    BodyTimeout,
    TooManyConnections,
    TooManySamples,
    OutputTooLarge,
    Unauthorized,
    Forbidden,
    RateLimited,
    NotReady,
    InternalError,
    JobPanicked,
    JobTimeout,
    Canceled,
    InvalidK,
    InvalidOption,
    FactorizationFailed,
    NoConvergence,
    IncompleteSpectrum,
    InvalidParameter,
    TooFewEigenpairs,
    NotApplicable,
    Unsupported,
    SolveFailed,
    NonFiniteResult,
    OperatorNotApplicable,
    MassNotApplicable,
    DegenerateElement,
    NonManifold,
    InvalidBoundary,
    /// A field or query parameter that the request does not take: the code `invalid-request`, as for a malformed
    /// parameter, but the request was understood and is refused as unprocessable.
    UnknownField,
}

impl Code {
    /// Every code, in the order of the documentation (each text once: [`Code::UnknownField`] shares
    /// `invalid-request` and is left out).
    pub const ALL: &'static [Code] = &[
        Code::MalformedInput,
        Code::TruncatedInput,
        Code::NonFiniteValue,
        Code::IndexOutOfRange,
        Code::InvalidElement,
        Code::EmptyShape,
        Code::UnsupportedContent,
        Code::FormatMismatch,
        Code::UnknownFormat,
        Code::LimitExceeded,
        Code::IoError,
        Code::NotFound,
        Code::RouteNotFound,
        Code::MethodNotAllowed,
        Code::BodyTooLarge,
        Code::InvalidJson,
        Code::InvalidRequest,
        Code::UnsupportedMediaType,
        Code::QueueFull,
        Code::MemoryBusy,
        Code::KTooLarge,
        Code::BodyTimeout,
        Code::TooManyConnections,
        Code::TooManySamples,
        Code::OutputTooLarge,
        Code::Unauthorized,
        Code::Forbidden,
        Code::RateLimited,
        Code::NotReady,
        Code::InternalError,
        Code::JobPanicked,
        Code::JobTimeout,
        Code::Canceled,
        Code::InvalidK,
        Code::InvalidOption,
        Code::FactorizationFailed,
        Code::NoConvergence,
        Code::IncompleteSpectrum,
        Code::InvalidParameter,
        Code::TooFewEigenpairs,
        Code::NotApplicable,
        Code::Unsupported,
        Code::SolveFailed,
        Code::NonFiniteResult,
        Code::OperatorNotApplicable,
        Code::MassNotApplicable,
        Code::DegenerateElement,
        Code::NonManifold,
        Code::InvalidBoundary,
    ];

    /// The code's text: the last segment of the problem's `type`.
    pub fn as_str(self) -> &'static str {
        match self {
            Code::MalformedInput => "malformed-input",
            Code::TruncatedInput => "truncated-input",
            Code::NonFiniteValue => "non-finite-value",
            Code::IndexOutOfRange => "index-out-of-range",
            Code::InvalidElement => "invalid-element",
            Code::EmptyShape => "empty-shape",
            Code::UnsupportedContent => "unsupported-content",
            Code::FormatMismatch => "format-mismatch",
            Code::UnknownFormat => "unknown-format",
            Code::LimitExceeded => "limit-exceeded",
            Code::IoError => "io-error",
            Code::NotFound => "not-found",
            Code::RouteNotFound => "route-not-found",
            Code::MethodNotAllowed => "method-not-allowed",
            Code::BodyTooLarge => "body-too-large",
            Code::InvalidJson => "invalid-json",
            Code::InvalidRequest => "invalid-request",
            Code::UnsupportedMediaType => "unsupported-media-type",
            Code::QueueFull => "queue-full",
            Code::MemoryBusy => "memory-busy",
            Code::KTooLarge => "k-too-large",
            Code::BodyTimeout => "body-timeout",
            Code::TooManyConnections => "too-many-connections",
            Code::TooManySamples => "too-many-samples",
            Code::OutputTooLarge => "output-too-large",
            Code::Unauthorized => "unauthorized",
            Code::Forbidden => "forbidden",
            Code::RateLimited => "rate-limited",
            Code::NotReady => "not-ready",
            Code::InternalError => "internal-error",
            Code::JobPanicked => "job-panicked",
            Code::JobTimeout => "job-timeout",
            Code::Canceled => "canceled",
            Code::InvalidK => "invalid-k",
            Code::InvalidOption => "invalid-option",
            Code::FactorizationFailed => "factorization-failed",
            Code::NoConvergence => "no-convergence",
            Code::IncompleteSpectrum => "incomplete-spectrum",
            Code::InvalidParameter => "invalid-parameter",
            Code::TooFewEigenpairs => "too-few-eigenpairs",
            Code::NotApplicable => "not-applicable",
            Code::Unsupported => "unsupported",
            Code::SolveFailed => "solve-failed",
            Code::NonFiniteResult => "non-finite-result",
            Code::OperatorNotApplicable => "operator-not-applicable",
            Code::MassNotApplicable => "mass-not-applicable",
            Code::DegenerateElement => "degenerate-element",
            Code::NonManifold => "non-manifold",
            Code::InvalidBoundary => "invalid-boundary",
            Code::UnknownField => "invalid-request",
        }
    }

    /// What the code means, one or two sentences (served at `/problems/{code}`).
    pub fn describe(self) -> &'static str {
        match self {
            Code::MalformedInput => {
                "The file does not follow its format's syntax; the detail names the line or byte."
            }
            Code::TruncatedInput => {
                "The file ends before the data it declares."
            }
            Code::NonFiniteValue => {
                "A coordinate or weight is NaN or infinite."
            }
            Code::IndexOutOfRange => {
                "An element refers to a vertex that does not exist."
            }
            Code::InvalidElement => {
                "An element breaks a rule (too few vertices, repeated index, …); the detail names it."
            }
            Code::EmptyShape => {
                "Nothing usable is left after validation."
            }
            Code::UnsupportedContent => {
                "The file uses a feature of its format that kac does not read."
            }
            Code::FormatMismatch => {
                "The bytes could not be read as the format given (by ?format=, the media type or the file name) and look like \
         another format; the problem names both and how the bytes begin. Send the right format name."
            }
            Code::UnknownFormat => {
                "No format was given and none could be recognized."
            }
            Code::LimitExceeded => {
                "The shape is larger than the configured limit (--max-vertices)."
            }
            Code::IoError => {
                "The server could not read or write its storage."
            }
            Code::NotFound => {
                "No resource with this id."
            }
            Code::RouteNotFound => {
                "No such route."
            }
            Code::MethodNotAllowed => {
                "The method is not allowed on this resource."
            }
            Code::BodyTooLarge => {
                "The request body exceeds --max-body-bytes."
            }
            Code::InvalidJson => {
                "The request body (or a JSON part or parameter) is not valid JSON for this endpoint, or names a key twice in \
         one object (with `pointer` and `field`)."
            }
            Code::InvalidRequest => {
                "A parameter is missing or malformed (400), or a field or query parameter is not one this request takes \
         (422, with `pointer`, `field`, `suggestion`, `belongs_in` and `accepted`)."
            }
            Code::UnsupportedMediaType => {
                "The Content-Type cannot be used here."
            }
            Code::QueueFull => {
                "The job queue is at capacity; retry after Retry-After seconds."
            }
            Code::MemoryBusy => {
                "Request bodies being received and archives being expanded hold --max-body-memory-bytes together; retry \
         after Retry-After seconds."
            }
            Code::KTooLarge => {
                "k exceeds the configured limit (--max-k)."
            }
            Code::BodyTimeout => {
                "The request body paused for longer than --body-read-timeout-s."
            }
            Code::TooManyConnections => {
                "The server holds --max-connections open connections; this one was answered and closed. Retry shortly."
            }
            Code::TooManySamples => {
                "A list or grid of the request (times, energies, τ samples, frequencies, sources, steps, values) is longer \
         than --max-samples; the detail names the field."
            }
            Code::OutputTooLarge => {
                "The analysis would hold a per-vertex array (eigenvectors included) of more than --max-output-values \
         values (vertices × columns); the detail gives both."
            }
            Code::Unauthorized => {
                "The service requires an API key (Authorization: Bearer KEY) and none was sent."
            }
            Code::Forbidden => {
                "The API key sent is not one the service accepts."
            }
            Code::RateLimited => {
                "The key exceeded its requests per minute; retry after Retry-After seconds."
            }
            Code::NotReady => {
                "The service is not ready (draining or storage unavailable)."
            }
            Code::InternalError => {
                "An unexpected failure; the job or request can be retried."
            }
            Code::JobPanicked => {
                "The computation panicked; the job failed and the service kept serving."
            }
            Code::JobTimeout => {
                "The job ran longer than --job-timeout-s and was stopped."
            }
            Code::Canceled => {
                "The job was canceled."
            }
            Code::InvalidK => {
                "k is out of range for the operator's size."
            }
            Code::InvalidOption => {
                "An eigensolver option is out of range."
            }
            Code::FactorizationFailed => {
                "L − σM could not be factored."
            }
            Code::NoConvergence => {
                "The eigensolver did not converge within its step limit."
            }
            Code::IncompleteSpectrum => {
                "Sylvester's inertia counts more eigenvalues below the check's shift than the solver found, after its \
         repair rounds; no result is given rather than an incomplete one."
            }
            Code::InvalidParameter => {
                "A descriptor or operator parameter is out of range."
            }
            Code::TooFewEigenpairs => {
                "The descriptor needs more eigenpairs than were requested."
            }
            Code::NotApplicable => {
                "The analysis does not apply to this kind of shape."
            }
            Code::Unsupported => {
                "The truth table of analyses refuses this combination of analysis, shape class, boundary condition, \
         order and extrapolation (GET /v1/analyses lists what is supported)."
            }
            Code::SolveFailed => {
                "A linear system could not be solved."
            }
            Code::NonFiniteResult => {
                "The computation gave a NaN or an infinity where the result must hold a number; the detail names the field \
         or array and its first such element. No result is stored rather than one holding it."
            }
            Code::OperatorNotApplicable => {
                "The operator does not apply to this kind of shape."
            }
            Code::MassNotApplicable => {
                "The mass matrix does not apply to this operator."
            }
            Code::DegenerateElement => {
                "An element is degenerate for this operator."
            }
            Code::NonManifold => {
                "The operator needs a manifold mesh; use 'robust'."
            }
            Code::InvalidBoundary => {
                "The boundary condition cannot be applied (no boundary, unknown vertex, …)."
            }
            Code::UnknownField => Code::InvalidRequest.describe(),
        }
    }

    /// The code whose text this is.
    pub fn parse(text: &str) -> Option<Code> {
        Code::ALL.iter().copied().find(|c| c.as_str() == text)
    }
}

impl std::fmt::Display for Code {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for Code {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for Code {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Code::parse(&text).ok_or_else(|| serde::de::Error::custom(format!("'{text}' is not a problem code of kac")))
    }
}

/// The core's errors mapped to codes, once: the core names no code of the service.
mod of_core {
    use super::Code;
    use kac_core::descriptors::DescriptorError;
    use kac_core::operators::OperatorError;
    use kac_core::pde::PdeError;
    use kac_core::spectrum::EigenError;
    use kac_core::ShapeError;

    impl From<&ShapeError> for Code {
        fn from(e: &ShapeError) -> Code {
            match e {
                ShapeError::Syntax { .. } => Code::MalformedInput,
                ShapeError::Truncated { .. } => Code::TruncatedInput,
                ShapeError::NonFinite { .. } => Code::NonFiniteValue,
                ShapeError::IndexOutOfRange { .. } => Code::IndexOutOfRange,
                ShapeError::InvalidElement { .. } => Code::InvalidElement,
                ShapeError::Empty { .. } => Code::EmptyShape,
                ShapeError::Unsupported { .. } => Code::UnsupportedContent,
                ShapeError::UnknownFormat { .. } => Code::UnknownFormat,
                ShapeError::FormatMismatch { .. } => Code::FormatMismatch,
                ShapeError::LimitExceeded { .. } => Code::LimitExceeded,
                ShapeError::Io { .. } => Code::IoError,
            }
        }
    }

    impl From<&OperatorError> for Code {
        fn from(e: &OperatorError) -> Code {
            match e {
                OperatorError::NotApplicable { .. } => Code::OperatorNotApplicable,
                OperatorError::MassNotApplicable { .. } => Code::MassNotApplicable,
                OperatorError::DegenerateElement { .. } => Code::DegenerateElement,
                OperatorError::NonManifold { .. } => Code::NonManifold,
                OperatorError::Boundary { .. } => Code::InvalidBoundary,
                OperatorError::InvalidParameter { .. } => Code::InvalidParameter,
            }
        }
    }

    impl From<&EigenError> for Code {
        fn from(e: &EigenError) -> Code {
            match e {
                EigenError::InvalidK { .. } => Code::InvalidK,
                EigenError::Factorization { .. } => Code::FactorizationFailed,
                EigenError::Canceled => Code::Canceled,
                EigenError::NoConvergence { .. } => Code::NoConvergence,
                EigenError::InvalidOption { .. } => Code::InvalidOption,
                EigenError::Incomplete { .. } => Code::IncompleteSpectrum,
                EigenError::TooLarge { .. } => Code::OutputTooLarge,
            }
        }
    }

    impl From<&PdeError> for Code {
        fn from(e: &PdeError) -> Code {
            match e {
                PdeError::InvalidParameter { .. } => Code::InvalidParameter,
                PdeError::TooFewEigenpairs { .. } => Code::TooFewEigenpairs,
                PdeError::NotApplicable { .. } => Code::NotApplicable,
                PdeError::Solve { .. } => Code::SolveFailed,
                PdeError::TooLarge { .. } => Code::OutputTooLarge,
            }
        }
    }

    impl From<&DescriptorError> for Code {
        fn from(e: &DescriptorError) -> Code {
            match e {
                DescriptorError::InvalidParameter { .. } => Code::InvalidParameter,
                DescriptorError::TooFewEigenpairs { .. } => Code::TooFewEigenpairs,
                DescriptorError::NotApplicable { .. } => Code::NotApplicable,
                DescriptorError::Solve { .. } => Code::SolveFailed,
                DescriptorError::TooLarge { .. } => Code::OutputTooLarge,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Code;

    #[test]
    fn every_code_has_one_text_and_parses_back() {
        let mut seen = std::collections::HashSet::new();
        for &c in Code::ALL {
            assert!(seen.insert(c.as_str()), "{} twice", c.as_str());
            assert_eq!(Code::parse(c.as_str()), Some(c));
            assert!(!c.describe().is_empty());
        }
        assert_eq!(Code::UnknownField.as_str(), "invalid-request");
    }
}
