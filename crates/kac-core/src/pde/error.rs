//! Why a PDE tool cannot run: the tools' own error, with the messages the descriptors' error gives the same faults
//! ([`DescriptorError`]), so that callers reading either see the same strings. Converts both ways: a
//! descriptor the tools call fails as the same fault here, and a caller that reports descriptor errors can take
//! these unchanged.

use crate::cholesky::factor::Symbolic;
use crate::descriptors::DescriptorError;
use crate::pattern::Pattern;
use serde::Serialize;
use std::sync::Arc;

/// Why a PDE tool cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize)]
#[serde(tag = "error", rename_all = "snake_case")]
pub enum PdeError {
    #[error("invalid parameter {name}: {message}")]
    InvalidParameter { name: &'static str, message: String },
    #[error("the spectrum has too few eigenpairs: {message}")]
    TooFewEigenpairs { message: String },
    #[error("{message}")]
    NotApplicable { message: String },
    #[error("the linear system could not be solved: {message}")]
    Solve { message: String },
    #[error(
        "the factor of the linear system would hold {values} values (the symbolic analysis' fill), above the limit of \
         {limit}"
    )]
    TooLarge { values: usize, limit: usize },
}

impl PdeError {
    /// Whether the request was at fault (it cannot succeed as given) rather than the computation.
    pub fn caller_fault(&self) -> bool {
        match self {
            PdeError::InvalidParameter { .. }
            | PdeError::TooFewEigenpairs { .. }
            | PdeError::NotApplicable { .. }
            | PdeError::TooLarge { .. } => true,
            PdeError::Solve { .. } => false,
        }
    }
    pub(crate) fn param(name: &'static str, message: impl Into<String>) -> Self {
        PdeError::InvalidParameter { name, message: message.into() }
    }
    /// The symbolic analysis of a pattern, refused when its factor would exceed this thread's limit
    /// ([`crate::cholesky::factor::with_factor_limit`]).
    pub(crate) fn analyze(pattern: &Arc<Pattern>) -> Result<Symbolic, PdeError> {
        Ok(DescriptorError::analyze(pattern)?)
    }
}

impl From<DescriptorError> for PdeError {
    fn from(e: DescriptorError) -> Self {
        match e {
            DescriptorError::InvalidParameter { name, message } => PdeError::InvalidParameter { name, message },
            DescriptorError::TooFewEigenpairs { message } => PdeError::TooFewEigenpairs { message },
            DescriptorError::NotApplicable { message } => PdeError::NotApplicable { message },
            DescriptorError::Solve { message } => PdeError::Solve { message },
            DescriptorError::TooLarge { values, limit } => PdeError::TooLarge { values, limit },
        }
    }
}

impl From<PdeError> for DescriptorError {
    fn from(e: PdeError) -> Self {
        match e {
            PdeError::InvalidParameter { name, message } => DescriptorError::InvalidParameter { name, message },
            PdeError::TooFewEigenpairs { message } => DescriptorError::TooFewEigenpairs { message },
            PdeError::NotApplicable { message } => DescriptorError::NotApplicable { message },
            PdeError::Solve { message } => DescriptorError::Solve { message },
            PdeError::TooLarge { values, limit } => DescriptorError::TooLarge { values, limit },
        }
    }
}
