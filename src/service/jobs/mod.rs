//! Jobs: a bounded queue in front of a rayon pool. A job's id is a hash of (shape id, canonical analysis,
//! algorithm version), so the same request finds the same job. Progress comes from the eigensolver's callback,
//! cancellation goes through its stop flag, a timer stops jobs that run too long, and a panic inside a job fails
//! that job only.

use super::error::{ApiError, Problem};
use super::store::{ResultStore, StoredResult, StoredShape};
use super::AppState;
use crate::analysis::{self, Analysis, Hooks};
use kac_core::spectrum::{Control, Progress};
use serde::Serialize;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::watch;

mod runner;
pub use runner::store_result;
use runner::{canceled, start};

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

/// What clients see of a job.
#[derive(Debug, Clone, Serialize, serde::Deserialize, utoipa::ToSchema)]
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
    pub error: Option<Problem>,
    /// Link to the result once succeeded.
    pub result: Option<String>,
    /// The request, canonical (defaults filled in).
    #[schema(value_type = Object)]
    pub request: serde_json::Value,
}

pub struct Job {
    pub view: watch::Sender<JobView>,
    pub stop: AtomicBool,
    pub timed_out: AtomicBool,
    /// The analysis name (`compare` for a comparison).
    pub name: &'static str,
}

/// What a job computes, handed to the worker with its inputs.
pub enum Work {
    /// One analysis of one stored shape.
    Analysis(Analysis, Arc<StoredShape>),
    /// Shape-DNA of several stored shapes and the distances between them.
    Compare(super::compare::CompareRequest, Vec<Arc<StoredShape>>),
}

impl Work {
    fn name(&self) -> &'static str {
        match self {
            Work::Analysis(a, _) => a.name(),
            Work::Compare(..) => "compare",
        }
    }
}

impl Job {
    pub fn snapshot(&self) -> JobView {
        self.view.borrow().clone()
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

/// The job id of a request: SHA-256 over the shape id, the canonical analysis JSON and the algorithm version
/// (first 32 hex digits).
pub fn job_id(shape_id: &str, canonical: &serde_json::Value) -> String {
    let mut h = Sha256::new();
    h.update(shape_id.as_bytes());
    h.update([0]);
    h.update(serde_json::to_vec(canonical).unwrap_or_default());
    h.update([0]);
    h.update(analysis::ALGORITHM_VERSION.to_le_bytes());
    h.finalize().iter().take(16).map(|b| format!("{b:02x}")).collect()
}

pub struct Jobs {
    pub pool: rayon::ThreadPool,
    pub jobs: Mutex<HashMap<String, Arc<Job>>>,
    /// Enqueued plus processing.
    pub active: AtomicUsize,
    pub capacity: usize,
}

impl Jobs {
    pub fn new(workers: usize, capacity: usize) -> Self {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .thread_name(|i| format!("kac-worker-{i}"))
            .build()
            .expect("a rayon pool with at least one thread");
        Jobs { pool, jobs: Mutex::new(HashMap::new()), active: AtomicUsize::new(0), capacity }
    }
    pub fn get(&self, id: &str) -> Option<Arc<Job>> {
        self.jobs.lock().unwrap_or_else(|e| e.into_inner()).get(id).cloned()
    }
    /// Jobs processing now.
    pub fn running(&self) -> usize {
        self.jobs
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .values()
            .filter(|j| j.snapshot().status == Status::Processing)
            .count()
    }
    pub fn list(&self) -> Vec<JobView> {
        let mut v: Vec<JobView> =
            self.jobs.lock().unwrap_or_else(|e| e.into_inner()).values().map(|j| j.snapshot()).collect();
        v.sort_by(|a, b| a.created_at.cmp(&b.created_at).then(a.id.cmp(&b.id)));
        v
    }
}

/// Submits a job, or returns the existing one for the same request (true: newly enqueued).
pub fn submit(state: &AppState, shape: Arc<StoredShape>, analysis: Analysis) -> Result<(Arc<Job>, bool), ApiError> {
    super::limits::check_limits(state, &analysis)?;
    super::limits::check_work(state, &analysis, shape.validated.shape.vertex_count())?;
    let canonical = serde_json::to_value(&analysis).map_err(|e| ApiError::Internal { detail: e.to_string() })?;
    let id = job_id(&shape.id, &canonical);
    let shape_id = shape.id.clone();
    enqueue(state, id, shape_id, canonical, Work::Analysis(analysis, shape))
}

/// Submits a comparison of stored shapes (the request's `shape_ids` resolved, in that order), or returns the
/// existing job for the same request.
pub fn submit_compare(
    state: &AppState,
    mut request: super::compare::CompareRequest,
    shapes: Vec<Arc<StoredShape>>,
) -> Result<(Arc<Job>, bool), ApiError> {
    if request.k == 0 {
        return Err(ApiError::Analysis(crate::analysis::AnalysisError::invalid_k(
            "k = 0: ask for at least one eigenpair",
        )));
    }
    if request.k > state.config.max_k {
        return Err(ApiError::KTooLarge {
            detail: format!("k = {} is above --max-k {}", request.k, state.config.max_k),
        });
    }
    // Each shape's shape-DNA within the limits a shape-dna job of it would have (the largest decides).
    let dna = Analysis::ShapeDna {
        options: request.options(),
        operator: request.operator.clone(),
        solver: crate::analysis::SolverSpec::default(),
    };
    if let Some(largest) = shapes.iter().map(|s| s.validated.shape.vertex_count()).max() {
        super::limits::check_work(state, &dna, largest)?;
    }
    request.shape_ids = Some(shapes.iter().map(|s| s.id.clone()).collect());
    let canonical = serde_json::to_value(&request).map_err(|e| ApiError::Internal { detail: e.to_string() })?;
    let id = job_id("compare", &canonical);
    enqueue(state, id, String::new(), canonical, Work::Compare(request, shapes))
}

/// Enqueues work under its id unless a job with that id is queued, running or done (true: newly enqueued).
fn enqueue(
    state: &AppState,
    id: String,
    shape_id: String,
    canonical: serde_json::Value,
    work: Work,
) -> Result<(Arc<Job>, bool), ApiError> {
    let jobs = &state.jobs;
    let job = {
        let mut map = jobs.jobs.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(j) = map.get(&id) {
            let st = j.snapshot().status;
            if !matches!(st, Status::Failed | Status::Canceled) {
                return Ok((j.clone(), false));
            }
        }
        // Reserve a place in the queue.
        let active = jobs.active.load(Ordering::SeqCst);
        if active >= jobs.capacity {
            return Err(ApiError::QueueFull { capacity: jobs.capacity, retry_after_s: 2 });
        }
        jobs.active.fetch_add(1, Ordering::SeqCst);
        let view = JobView {
            id: id.clone(),
            shape_id,
            analysis: work.name().into(),
            status: Status::Enqueued,
            progress: JobProgress { phase: "queued".into(), converged: 0, wanted: 0 },
            created_at: now(),
            started_at: None,
            finished_at: None,
            error: None,
            result: None,
            request: canonical,
        };
        let job = Arc::new(Job {
            view: watch::Sender::new(view),
            stop: AtomicBool::new(false),
            timed_out: AtomicBool::new(false),
            name: work.name(),
        });
        map.insert(id.clone(), job.clone());
        job
    };
    state.metrics.jobs_submitted.fetch_add(1, Ordering::Relaxed);
    persist(state, &job);
    start(state, job.clone(), work);
    Ok((job, true))
}

/// Writes a job's record to the job store (a failure is logged: the job itself goes on).
pub fn persist(state: &AppState, job: &Job) {
    // A job replaced under its id (canceled, then submitted again) no longer writes the record: it is the new
    // job's now.
    let view = job.snapshot();
    if !state.jobs.get(&view.id).is_some_and(|current| std::ptr::eq(&*current, job)) {
        return;
    }
    if let Err(e) = state.job_store.save(&view) {
        tracing::error!(job = %job.snapshot().id, error = %e, "cannot persist the job record");
    }
}

/// Cancels a job: an enqueued one at once, a running one at its next stop-flag check.
pub fn cancel(state: &AppState, job: &Job) {
    job.stop.store(true, Ordering::SeqCst);
    let mut changed = false;
    job.view.send_modify(|v| {
        if v.status == Status::Enqueued {
            v.status = Status::Canceled;
            v.finished_at = Some(now());
            v.error = Some(canceled());
            changed = true;
        }
    });
    if changed {
        persist(state, job);
    }
}

/// After a restart: loads every job record; jobs that were enqueued or running are queued again (their shapes
/// are read back from the store), finished ones are served as they were. Returns the number re-queued.
pub fn recover(state: &AppState) -> std::io::Result<usize> {
    let mut requeued = 0;
    for mut view in state.job_store.load_all()? {
        let resume = !view.status.terminal();
        // The analysis name from the stored request alone; shapes are read back only for jobs that resume.
        let name: &'static str = if view.analysis == "compare" {
            "compare"
        } else {
            serde_json::from_value::<Analysis>(view.request.clone()).map_or("unknown", |a| a.name())
        };
        let work: Result<Work, &str> = if !resume {
            Err("finished")
        } else if view.analysis == "compare" {
            match serde_json::from_value::<super::compare::CompareRequest>(view.request.clone()) {
                Err(_) => Err("the stored request no longer parses"),
                Ok(req) => {
                    let shapes: Option<Vec<_>> =
                        req.shape_ids.iter().flatten().map(|id| state.shapes.get(id)).collect();
                    shapes.map(|s| Work::Compare(req, s)).ok_or("a shape of the comparison is no longer stored")
                }
            }
        } else {
            match serde_json::from_value::<Analysis>(view.request.clone()) {
                Err(_) => Err("the stored request no longer parses"),
                Ok(a) => match state.shapes.get(&view.shape_id) {
                    Some(shape) => Ok(Work::Analysis(a, shape)),
                    None => Err("the job's shape is no longer stored"),
                },
            }
        };
        let failure = work.as_ref().err().copied();
        if resume {
            match failure {
                Some(why) => {
                    let (_, p) = ApiError::Internal { detail: format!("not resumed after a restart: {why}") }.problem();
                    view.status = Status::Failed;
                    view.finished_at = Some(now());
                    view.error = Some(p);
                }
                None => {
                    view.status = Status::Enqueued;
                    view.started_at = None;
                    view.progress = JobProgress { phase: "requeued after a restart".into(), converged: 0, wanted: 0 };
                }
            }
        }
        let job = Arc::new(Job {
            view: watch::Sender::new(view.clone()),
            stop: AtomicBool::new(false),
            timed_out: AtomicBool::new(false),
            name,
        });
        state.jobs.jobs.lock().unwrap_or_else(|e| e.into_inner()).insert(view.id.clone(), job.clone());
        if resume {
            persist(state, &job);
            if let Ok(work) = work {
                state.jobs.active.fetch_add(1, Ordering::SeqCst);
                start(state, job, work);
                requeued += 1;
            }
        }
    }
    Ok(requeued)
}
