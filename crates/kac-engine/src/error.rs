//! Why a job cannot be submitted, read or canceled: the engine's own errors, which a host (the HTTP layer) maps to
//! its answers.

/// Why a job cannot be submitted, read or canceled.
#[derive(Debug)]
pub enum JobError {
    /// The analysis refuses the request (the truth table, its options, k).
    Analysis(crate::analysis::AnalysisError),
    /// A limit of the service refuses it.
    Limit(Limit),
    /// The queue holds its capacity (queued + running).
    QueueFull { capacity: usize },
    /// The store cannot be reached.
    Store(std::io::Error),
    /// The request cannot be recorded (it does not serialize).
    Internal(String),
}

/// Which limit: the eigenpairs asked for (--max-k), the samples of a list or grid (--max-samples), the values an
/// array or the solver's basis would hold (--max-output-values). Each with its sentence.
#[derive(Debug)]
pub enum Limit {
    Pairs(String),
    Samples(String),
    Values(String),
}

impl From<std::io::Error> for JobError {
    fn from(e: std::io::Error) -> Self {
        JobError::Store(e)
    }
}
