//! The job queue both backends implement: a job's every transition is one call. A job is enqueued once per id
//! (the id is the request's content hash; a failed or canceled one may be enqueued again), claimed by one worker
//! with a lease that the worker renews while it runs, and finished by the worker that holds the claim: a worker
//! that lost its lease (it stalled, or another replica took the job after it expired) writes nothing. Every
//! change is announced to the job's subscribers on every replica.
//!
//! Jobs wait in one of two lanes ([`Lane`]): the run lane (interactive requests) is bounded by the capacity; the
//! backlog lane (bulk ingest) is not, and waits durably in the store behind the run lane, so that an interactive
//! request never waits behind a 10,000-file upload and no file of an upload is left without its job. A bulk
//! upload's jobs are recorded as a batch whose progress any replica can read.

use crate::failure::Failure;
use crate::ids::{BatchId, JobId};
use crate::record::{BatchProgress, JobProgress, JobView};
use std::io::Result;
use std::time::Duration;
use tokio::sync::broadcast;

/// The lane a job waits in. Claims take the run lane's oldest job first, then the backlog's oldest; requeued and
/// recovered jobs keep their lane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lane {
    /// Interactive requests: enqueued and processing jobs of this lane number at most the capacity.
    Run,
    /// Bulk ingest: never refused for capacity (bounded before anything is stored, by `--max-backlog`).
    Backlog,
}

impl Lane {
    /// The lane as the stores' `lane` column holds it: its rank in the claim order (run first).
    pub fn rank(self) -> i16 {
        match self {
            Lane::Run => 0,
            Lane::Backlog => 1,
        }
    }
    /// The lane a stored rank names (an unknown rank waits in the backlog: it is never refused nor put first).
    pub fn of_rank(rank: i64) -> Lane {
        if rank == 0 {
            Lane::Run
        } else {
            Lane::Backlog
        }
    }
}

/// The outcome of [`JobQueue::enqueue`].
#[derive(Debug)]
pub enum Enqueued {
    /// Stored as a new job (or a failed or canceled one enqueued again).
    New(JobView),
    /// A job with this id is enqueued, processing or succeeded: that one.
    Existing(JobView),
    /// A run-lane job: the run lane's enqueued plus processing jobs already number `capacity`.
    Full,
}

/// The outcome of [`JobQueue::heartbeat`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lease {
    /// Still the claim's holder, lease renewed; `cancel`: a cancel was asked for on some replica.
    Held { cancel: bool },
    /// The claim is no longer this worker's (expired and requeued, or finished): stop and write nothing.
    Lost,
}

pub trait JobQueue: Send + Sync {
    /// Stores `view` (status `enqueued`) in `lane` unless a job with its id is enqueued, processing or succeeded,
    /// or (run lane) the run lane holds `capacity` jobs that are enqueued or processing; backlog jobs are never
    /// refused and do not count. A job enqueued in the backlog and enqueued again in the run lane (a request waits
    /// for it) moves to the run lane if it has room (answered `Existing`), so the request does not wait behind the
    /// backlog.
    fn enqueue(&self, view: JobView, lane: Lane, capacity: usize) -> Result<Enqueued>;
    /// Claims for `owner` (a token unique to this claim) for `lease` the run lane's oldest enqueued job, else the
    /// backlog's oldest: status `processing`, `started_at` now. None when nothing is enqueued.
    fn claim(&self, owner: &str, lease: Duration) -> Result<Option<JobView>>;
    /// Claims the job `id` as [`JobQueue::claim`] does, if it is enqueued (a job that cut itself into slice jobs takes
    /// back one that nobody started); None when it is not.
    fn claim_id(&self, id: &str, owner: &str, lease: Duration) -> Result<Option<JobView>>;
    /// Renews the lease of a claimed job and records its progress.
    fn heartbeat(&self, id: &str, owner: &str, progress: &JobProgress, lease: Duration) -> Result<Lease>;
    /// Writes the final view (succeeded, failed or canceled) of a job this claim still holds; false (nothing
    /// written) when the claim was lost.
    fn finish(&self, id: &str, owner: &str, view: &JobView) -> Result<bool>;
    /// Cancels a job: an enqueued one at once (status `canceled`, `problem` its error), a processing one by a
    /// request that its worker sees at its next heartbeat (its view returned as it is). None: no such job.
    fn cancel(&self, id: &JobId, problem: &Failure) -> Result<Option<JobView>>;
    /// Puts processing jobs whose lease expired back in the queue; their ids. Claims named in `held` (this
    /// replica's own running jobs, which its supervisor renews) are never taken back: a replica that falls behind
    /// with a beat on a loaded machine does not lose, and then run again, the job it is running.
    fn requeue_expired(&self, held: &[String]) -> Result<Vec<String>>;
    /// At start: puts back in the queue the jobs no live worker can hold (the embedded store belongs to one
    /// process, so every processing job; a shared one waits for their leases to expire). The number of jobs
    /// enqueued afterwards.
    fn recover(&self) -> Result<usize>;
    fn get(&self, id: &JobId) -> Result<Option<JobView>>;
    /// Every job in submission order.
    fn list(&self) -> Result<Vec<JobView>>;
    /// Jobs by status name (statuses with none may be missing).
    fn counts(&self) -> Result<Vec<(String, usize)>>;
    /// Enqueued jobs of any analysis but `except` (slice jobs: see `jobs::slices`).
    fn waiting(&self, except: &str) -> Result<usize>;
    /// Jobs enqueued in the backlog lane (what `--max-backlog` bounds).
    fn backlog(&self) -> Result<usize>;
    /// Records a batch: its jobs, in order (each once: a repeated id is kept at its first place). A batch is
    /// recorded once; recording an id again changes nothing.
    fn put_batch(&self, batch: &BatchId, jobs: &[JobId]) -> Result<()>;
    /// A batch's progress, from its jobs' statuses now. None: no such batch.
    fn batch(&self, batch: &BatchId) -> Result<Option<BatchProgress>>;
    /// Jobs enqueued and processing.
    fn depth(&self) -> Result<(usize, usize)> {
        let counts = self.counts()?;
        let of = |s: &str| counts.iter().find(|(n, _)| n == s).map_or(0, |c| c.1);
        Ok((of("enqueued"), of("processing")))
    }
    /// Ids of jobs as they change (on any replica).
    fn changes(&self) -> broadcast::Receiver<String>;
}

/// A processing job whose claim ended without a finish (its worker died, stalled or gave it up): back in the queue,
/// or canceled when a cancel was asked for meanwhile (a cancel is never lost to a requeue). Its new status.
pub(crate) fn release(view: &mut JobView, cancel_requested: bool) -> crate::record::Status {
    use crate::record::{now, Status};
    if cancel_requested {
        view.status = Status::Canceled;
        view.finished_at = Some(now());
        view.error = Some(Failure::canceled());
    } else {
        view.status = Status::Enqueued;
        view.started_at = None;
        view.progress = JobProgress { phase: "requeued".into(), converged: 0, wanted: 0 };
    }
    view.status
}

/// A batch's job ids as stored: in order, each once (at its first place).
pub(crate) fn distinct(jobs: &[JobId]) -> Vec<String> {
    let mut seen = std::collections::HashSet::new();
    jobs.iter().filter(|j| seen.insert(**j)).map(JobId::hex).collect()
}
