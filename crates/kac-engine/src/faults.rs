//! Fault injection for the tests of the job engine, apart from the production configuration: read from the
//! environment by debug builds only (the tests' binary), never by a release build, which has no way to turn
//! them on. A value that does not parse stops the start, as a bad setting does.
//!
//! - `KAC_TEST_PANIC_ANALYSIS=NAME`: jobs of that analysis panic inside the worker (a panic fails one job);
//! - `KAC_TEST_JOB_DELAY_MS=N`: every job waits N ms, seeing its stop flag, before it computes (fills queues,
//!   lets cancels, timeouts and shutdowns meet running jobs).

/// The faults a test asked for (none in a release build).
#[derive(Debug, Clone, Default)]
pub struct Faults {
    pub panic_analysis: Option<String>,
    pub job_delay_ms: u64,
}

impl Faults {
    /// The faults in the environment (debug builds); none in a release build.
    pub fn from_env() -> Result<Faults, String> {
        if !cfg!(debug_assertions) {
            return Ok(Faults::default());
        }
        let delay = match std::env::var("KAC_TEST_JOB_DELAY_MS") {
            Ok(v) => v.trim().parse::<u64>().map_err(|_| format!("KAC_TEST_JOB_DELAY_MS={v:?}: give milliseconds"))?,
            Err(_) => 0,
        };
        Ok(Faults { panic_analysis: std::env::var("KAC_TEST_PANIC_ANALYSIS").ok(), job_delay_ms: delay })
    }
}
