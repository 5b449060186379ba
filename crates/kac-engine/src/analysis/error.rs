//! Why an analysis failed: one variant per kind, the core's errors kept whole.

use super::*;
use crate::code::Code;

/// Why an analysis failed: one variant per kind, the core's errors kept whole. Its code and whether the request
/// was at fault come from exhaustive matches (a new variant anywhere must say both).
#[derive(Debug, Clone, PartialEq)]
pub enum AnalysisError {
    /// A parameter of the request is out of its range (`invalid-parameter`).
    InvalidParameter(String),
    /// k = 0, or more eigenpairs than unknowns (`invalid-k`).
    InvalidK(String),
    /// The analysis does not apply to this kind of shape (`not-applicable`).
    NotApplicable(String),
    /// The truth table refuses this cell: analysis × shape class × boundary condition × order × extrapolation
    /// (`unsupported`; see [`super::registry`]).
    Unsupported(String),
    /// The request would make the solver hold more than a limit allows (`output-too-large`).
    TooLarge(String),
    /// A number of the result is NaN or infinite where the analysis documents no such marker
    /// (`non-finite-result`): `place` is its path in the result (`poisson.removed_mean[0]`,
    /// `arrays.solution[3][0]`). Checked before any result is returned or stored (see [`super::finite`]).
    NonFinite {
        place: String,
        value: f64,
    },
    Operator(operators::OperatorError),
    Eigen(spectrum::EigenError),
    Descriptor(DescriptorError),
}

impl AnalysisError {
    pub fn invalid_parameter(message: impl Into<String>) -> Self {
        AnalysisError::InvalidParameter(message.into())
    }
    pub fn invalid_k(message: impl Into<String>) -> Self {
        AnalysisError::InvalidK(message.into())
    }
    pub fn not_applicable(message: impl Into<String>) -> Self {
        AnalysisError::NotApplicable(message.into())
    }
    /// The stable problem code.
    pub fn code(&self) -> Code {
        match self {
            AnalysisError::InvalidParameter(_) => Code::InvalidParameter,
            AnalysisError::InvalidK(_) => Code::InvalidK,
            AnalysisError::NotApplicable(_) => Code::NotApplicable,
            AnalysisError::Unsupported(_) => Code::Unsupported,
            AnalysisError::TooLarge(_) => Code::OutputTooLarge,
            AnalysisError::NonFinite { .. } => Code::NonFiniteResult,
            AnalysisError::Operator(e) => e.into(),
            AnalysisError::Eigen(e) => e.into(),
            AnalysisError::Descriptor(e) => e.into(),
        }
    }
    /// The request cannot succeed as given (4xx); otherwise a computation failed (5xx / failed job).
    pub fn caller_fault(&self) -> bool {
        match self {
            AnalysisError::InvalidParameter(_)
            | AnalysisError::InvalidK(_)
            | AnalysisError::NotApplicable(_)
            | AnalysisError::Unsupported(_)
            | AnalysisError::TooLarge(_) => true,
            // The inputs are bounded at the boundary (see [`super::inputs`]): what is left is the computation's.
            AnalysisError::NonFinite { .. } => false,
            AnalysisError::Operator(e) => e.caller_fault(),
            AnalysisError::Eigen(e) => e.caller_fault(),
            AnalysisError::Descriptor(e) => e.caller_fault(),
        }
    }
    /// Stopped by its stop flag (a cancel or a timeout), not failed.
    pub fn is_stop(&self) -> bool {
        matches!(self, AnalysisError::Eigen(spectrum::EigenError::Canceled))
    }
}

impl std::fmt::Display for AnalysisError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AnalysisError::InvalidParameter(m)
            | AnalysisError::InvalidK(m)
            | AnalysisError::NotApplicable(m)
            | AnalysisError::Unsupported(m)
            | AnalysisError::TooLarge(m) => f.write_str(m),
            AnalysisError::NonFinite { place, value } => write!(
                f,
                "the result's {place} is {value}: the computation did not give a finite number, and no result is \
                 given rather than one holding it"
            ),
            AnalysisError::Operator(e) => e.fmt(f),
            AnalysisError::Eigen(e) => e.fmt(f),
            AnalysisError::Descriptor(e) => e.fmt(f),
        }
    }
}

impl From<DescriptorError> for AnalysisError {
    fn from(e: DescriptorError) -> Self {
        match e {
            // A limit the service set: the same answer as every other limit checked once the size is known.
            DescriptorError::TooLarge { .. } => {
                AnalysisError::TooLarge(format!("{e} (--max-output-values); ask for a coarser mesh or a lower order"))
            }
            e => AnalysisError::Descriptor(e),
        }
    }
}

/// The PDE tools fail as the descriptors do: the same faults, messages and codes.
impl From<kac_core::pde::PdeError> for AnalysisError {
    fn from(e: kac_core::pde::PdeError) -> Self {
        DescriptorError::from(e).into()
    }
}

impl From<operators::OperatorError> for AnalysisError {
    fn from(e: operators::OperatorError) -> Self {
        AnalysisError::Operator(e)
    }
}

impl From<spectrum::EigenError> for AnalysisError {
    fn from(e: spectrum::EigenError) -> Self {
        match e {
            // A limit the service set: the same answer as every other limit checked once the size is known.
            spectrum::EigenError::TooLarge { .. } => {
                AnalysisError::TooLarge(format!("{e} (--max-output-values); ask for a coarser mesh or a lower order"))
            }
            e => AnalysisError::Eigen(e),
        }
    }
}
