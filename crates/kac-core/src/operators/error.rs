//! Why an operator cannot be built: the error every operator constructor returns, below them all (the point-cloud
//! geometry of [`crate::point_cloud`] returns it too).

use serde::Serialize;

/// Why an operator cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize)]
#[serde(tag = "error", rename_all = "snake_case")]
pub enum OperatorError {
    #[error("the '{operator}' operator does not apply to a {kind}")]
    NotApplicable { operator: &'static str, kind: &'static str },
    #[error("the '{mass}' mass does not apply to the '{operator}' operator")]
    MassNotApplicable { operator: &'static str, mass: &'static str },
    #[error("{element} {index} is degenerate: {message}")]
    DegenerateElement { element: &'static str, index: usize, message: String },
    #[error("the '{operator}' operator needs a manifold mesh: {message}; use 'robust'")]
    NonManifold { operator: &'static str, message: String },
    #[error("Dirichlet boundary: {message}")]
    Boundary { message: String },
    #[error("invalid parameter {name}: {message}")]
    InvalidParameter { name: &'static str, message: String },
}

impl OperatorError {
    /// Whether the request was at fault (it cannot succeed as given) rather than the computation: always, since
    /// every operator error is about the shape or the options asked for.
    pub fn caller_fault(&self) -> bool {
        match self {
            OperatorError::NotApplicable { .. }
            | OperatorError::MassNotApplicable { .. }
            | OperatorError::DegenerateElement { .. }
            | OperatorError::NonManifold { .. }
            | OperatorError::Boundary { .. }
            | OperatorError::InvalidParameter { .. } => true,
        }
    }
}
