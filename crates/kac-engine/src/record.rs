//! A job as the queue records it: its status, progress, timestamps, request, and failure or result. The stores
//! keep it; the job engine writes it; the HTTP layer shows it.

use crate::failure::Failure;
use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    Enqueued,
    Processing,
    Succeeded,
    Failed,
    Canceled,
}

impl Status {
    pub fn terminal(self) -> bool {
        matches!(self, Status::Succeeded | Status::Failed | Status::Canceled)
    }
    pub fn name(self) -> &'static str {
        match self {
            Status::Enqueued => "enqueued",
            Status::Processing => "processing",
            Status::Succeeded => "succeeded",
            Status::Failed => "failed",
            Status::Canceled => "canceled",
        }
    }
    /// The status a [`Status::name`] names.
    pub fn from_name(name: &str) -> Option<Status> {
        [Status::Enqueued, Status::Processing, Status::Succeeded, Status::Failed, Status::Canceled]
            .into_iter()
            .find(|s| s.name() == name)
    }
}

#[derive(Debug, Clone, Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct JobProgress {
    /// `queued`, then `operator` (assembly), the eigensolver's `null-space`, `symbolic`, `factorization`,
    /// `iterating`, `ritz-vectors`, `converged`, `verifying` (or `dense`), then `descriptor`, `storing`, `done`.
    /// A cancel or a timeout is checked at every phase and within the long ones.
    pub phase: String,
    /// Converged eigenpairs so far, of `wanted` (spectral analyses).
    pub converged: usize,
    pub wanted: usize,
}

/// One array of a result: its shape, what its columns are, and where to fetch it.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ArrayLinks {
    pub rows: usize,
    pub cols: usize,
    /// What the columns are (times, energies, eigenvalues, …), where they are numbers.
    pub columns: Option<Vec<f64>>,
    /// float64 `.npy`, rows in the upload's vertex numbering.
    pub npy: String,
    /// The shape as binary PLY coloured by a column (per-vertex arrays).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ply: Option<String>,
    /// A matrix as Matrix Market (`operator` results).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mtx: Option<String>,
    /// A matrix as SciPy `.npz` (`operator` results).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub npz: Option<String>,
    /// The values, rows of numbers (null for NaN), unless `values=false` (added to each response, not stored).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<Vec<Option<f64>>>>,
}

/// A job as the queue records it and clients see it (the HTTP layer shows `error` as a problem document).
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct JobView {
    pub id: String,
    pub shape_id: String,
    pub analysis: String,
    pub status: Status,
    pub progress: JobProgress,
    /// RFC 3339 timestamps.
    pub created_at: String,
    pub started_at: Option<String>,
    pub finished_at: Option<String>,
    pub error: Option<Failure>,
    /// Link to the result once succeeded.
    pub result: Option<String>,
    /// The request, canonical (defaults filled in).
    pub request: serde_json::Value,
}

/// How far a bulk upload's jobs have got: its jobs by status, read from the queue (on every replica the same).
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct BatchProgress {
    /// The batch's id (32 hex digits).
    pub batch: String,
    /// When the batch was recorded (RFC 3339).
    pub created_at: String,
    /// The batch's jobs, each once (a file sent twice in one upload names one job).
    pub total: usize,
    pub enqueued: usize,
    pub processing: usize,
    pub succeeded: usize,
    pub failed: usize,
    pub canceled: usize,
    /// Every job has ended (succeeded, failed or canceled); true for a batch without jobs.
    pub done: bool,
    /// The first failed jobs' ids, in the batch's order (at most 10).
    pub failed_jobs: Vec<String>,
}

impl BatchProgress {
    /// Failed jobs named in a progress report: enough to look at, few enough for a 10,000-job batch.
    pub const FAILED_SHOWN: usize = 10;

    /// The report of a batch whose jobs have these statuses (in the batch's order; one per job); the first failed
    /// ones named.
    pub fn tally<'a>(
        batch: &crate::ids::BatchId,
        created_at: String,
        jobs: impl IntoIterator<Item = (&'a str, Status)>,
    ) -> BatchProgress {
        let mut p = BatchProgress {
            batch: batch.hex(),
            created_at,
            total: 0,
            enqueued: 0,
            processing: 0,
            succeeded: 0,
            failed: 0,
            canceled: 0,
            done: false,
            failed_jobs: vec![],
        };
        for (id, status) in jobs {
            p.total += 1;
            *match status {
                Status::Enqueued => &mut p.enqueued,
                Status::Processing => &mut p.processing,
                Status::Succeeded => &mut p.succeeded,
                Status::Failed => &mut p.failed,
                Status::Canceled => &mut p.canceled,
            } += 1;
            if status == Status::Failed && p.failed_jobs.len() < Self::FAILED_SHOWN {
                p.failed_jobs.push(id.to_string());
            }
        }
        p.done = p.succeeded + p.failed + p.canceled == p.total;
        p
    }
}

pub fn now() -> String {
    // RFC 3339 in UTC from the system clock, without a date-time crate: days → civil date (Howard Hinnant's
    // algorithm).
    let d = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs() as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        d.subsec_millis()
    )
}
