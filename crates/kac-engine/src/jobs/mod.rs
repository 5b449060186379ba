//! Jobs: a bounded queue in front of a rayon pool. A job's id is a hash of (shape id, canonical analysis,
//! algorithm version), so the same request finds the same job. Progress comes from the eigensolver's callback,
//! cancellation goes through its stop flag, a timer stops jobs that run too long, and a panic inside a job fails
//! that job only.

use super::ids::{BatchId, JobId, ShapeId};
use super::store::{Enqueued, JobQueue, Lane, Lease, StoredResult, StoredShape};
use crate::analysis::{self, Analysis, Hooks};
use crate::config::EngineConfig;
use crate::failure::Failure;
use crate::Engine;
use kac_core::spectrum::{Control, Progress};
use serde::Serialize;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;
use tokio::sync::{broadcast, watch};

mod runner;
mod slices;
pub use crate::clock::{Clock, ManualClock, SystemClock};
pub use crate::error::{JobError, Limit};
pub use crate::record::{now, ArrayLinks, BatchProgress, JobProgress, JobView, Status};
use runner::canceled;
pub use runner::{result_of, supervise, Beats};
pub use slices::{SliceRequest, SLICE_JOB};

/// A job running on this replica: its live view (progress as it happens; the queue gets it at each heartbeat),
/// its stop flag, and the token of its claim.
pub struct Job {
    pub view: watch::Sender<JobView>,
    pub stop: AtomicBool,
    pub timed_out: AtomicBool,
    /// The analysis name (`compare` for a comparison).
    pub name: &'static str,
    /// The claim's token: this replica's id and a counter.
    pub owner: String,
    /// Set when the claim was lost (the job then stops and writes nothing).
    pub lost: AtomicBool,
    /// Set as the job's outcome is being written: its claim ends with that write, so a beat that then finds no
    /// claim has not lost it.
    pub finishing: AtomicBool,
    /// When it started running here (the engine's clock).
    pub started: Duration,
}

/// What a job computes, handed to the worker with its inputs.
pub enum Work {
    /// One analysis of one stored shape.
    Analysis(Analysis, Arc<StoredShape>),
    /// Shape-DNA of several stored shapes and the distances between them.
    Compare(super::compare::CompareRequest, Vec<Arc<StoredShape>>),
    /// The correspondence between two stored shapes (source, target).
    Correspondence(super::correspondence::CorrespondenceRequest, Arc<StoredShape>, Arc<StoredShape>),
    /// One slice of another job's spectrum ([`slices`]).
    Slice(SliceRequest, Arc<StoredShape>),
}

impl Job {
    pub fn snapshot(&self) -> JobView {
        self.view.borrow().clone()
    }
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
    JobId::from_digest(&h.finalize()).hex()
}

/// The jobs of this replica: the queue they share with every replica, the pool this replica runs them on, and
/// the ones running here now.
pub struct Jobs {
    pub pool: rayon::ThreadPool,
    pub workers: usize,
    pub queue: Arc<dyn JobQueue>,
    /// Jobs running here, by id.
    pub running: Mutex<HashMap<String, Arc<Job>>>,
    /// Enqueued plus processing jobs the run lane takes (on all replicas together); the backlog lane is not bounded
    /// here (see [`submit_backlog`]).
    pub capacity: usize,
    /// How long a claim lasts without a heartbeat.
    pub lease: Duration,
    /// How long a job may run (--job-timeout-s), from when it starts running.
    pub timeout: Duration,
    /// The clock of leases, timeouts and heartbeats.
    pub clock: Arc<dyn Clock>,
    /// Jobs this replica accepted into the queue.
    pub submitted: AtomicU64,
    /// This replica's id (claims are `{replica}:{n}`).
    pub replica: String,
    claims: AtomicU64,
    /// Idle workers lent to running jobs' spectrum slices ([`kac_core::spectrum::Lender`]): the dispatcher counts
    /// them busy.
    lent: std::sync::atomic::AtomicUsize,
    /// Workers the dispatcher has set aside for the job it is claiming (changed under `running`'s lock, so a loan
    /// never takes the worker a claim is about to start on).
    starting: std::sync::atomic::AtomicUsize,
    /// Threads of the pool one running job may use (`--solver-threads`): a loan counts them busy.
    pub solver_threads: usize,
    /// Wakes the dispatcher: a job was enqueued, or a worker became free.
    wake: (Mutex<bool>, Condvar),
}

impl Jobs {
    pub fn new(
        workers: usize,
        capacity: usize,
        queue: Arc<dyn JobQueue>,
        lease: Duration,
        timeout: Duration,
        clock: Arc<dyn Clock>,
    ) -> Self {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .thread_name(|i| format!("kac-worker-{i}"))
            .build()
            .expect("a rayon pool with at least one thread");
        let replica = {
            let d = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
            let mut h = Sha256::new();
            h.update(std::process::id().to_le_bytes());
            h.update(d.as_nanos().to_le_bytes());
            h.finalize().iter().take(6).map(|b| format!("{b:02x}")).collect()
        };
        Jobs {
            pool,
            workers,
            queue,
            running: Mutex::new(HashMap::new()),
            capacity,
            lease,
            timeout,
            clock,
            submitted: AtomicU64::new(0),
            replica,
            claims: AtomicU64::new(0),
            lent: std::sync::atomic::AtomicUsize::new(0),
            starting: std::sync::atomic::AtomicUsize::new(0),
            solver_threads: 1,
            wake: (Mutex::new(false), Condvar::new()),
        }
    }
    fn local(&self, id: &str) -> Option<Arc<Job>> {
        self.running.lock().unwrap_or_else(|e| e.into_inner()).get(id).cloned()
    }
    /// A job's view: live if it runs here, else as the queue has it.
    pub fn view(&self, id: &JobId) -> Result<Option<JobView>, JobError> {
        if let Some(j) = self.local(&id.hex()) {
            return Ok(Some(j.snapshot()));
        }
        Ok(self.queue.get(id)?)
    }
    /// Jobs processing on this replica now.
    pub fn running(&self) -> usize {
        self.running.lock().unwrap_or_else(|e| e.into_inner()).len()
    }
    /// Workers lent to running jobs' slices now.
    pub fn lent(&self) -> usize {
        self.lent.load(Ordering::SeqCst)
    }
    /// Whether a job waits in the queue (for any replica), slice jobs aside: a worker lent to a job's slices does the
    /// same work without building the operator again. A queue that cannot be read counts as one where a job waits, so
    /// that no worker is lent, or kept lent, on a guess.
    fn job_waits(&self) -> bool {
        self.queue.waiting(SLICE_JOB).map_or(true, |n| n > 0)
    }
    /// Workers neither running a job, nor set aside for one being claimed, nor lent.
    fn idle_in(&self, running: &HashMap<String, Arc<Job>>) -> usize {
        let starting = self.starting.load(Ordering::SeqCst);
        self.workers.saturating_sub(running.len() + starting + self.lent())
    }
    /// Sets a worker aside for a claim, if one is idle; [`Self::claimed`] ends it.
    fn reserve(&self) -> bool {
        let running = self.running.lock().unwrap_or_else(|e| e.into_inner());
        let idle = self.idle_in(&running) > 0;
        if idle {
            self.starting.fetch_add(1, Ordering::SeqCst);
        }
        idle
    }
    /// The claim a worker was set aside for is over (its job started, or there was none).
    fn claimed(&self) {
        let _ = self.starting.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |s| Some(s.saturating_sub(1)));
    }
    /// The claims of the jobs running here (their owners), which this replica's supervisor renews.
    pub fn held_claims(&self) -> Vec<String> {
        self.running.lock().unwrap_or_else(|e| e.into_inner()).values().map(|j| j.owner.clone()).collect()
    }
    /// Every job, oldest first (live views for the ones running here), slice jobs left out (each is part of a job
    /// listed).
    pub fn list(&self) -> Result<Vec<JobView>, JobError> {
        let mut all = self.queue.list()?;
        all.retain(|v| v.analysis != SLICE_JOB);
        for v in &mut all {
            if let Some(j) = self.local(&v.id) {
                *v = j.snapshot();
            }
        }
        Ok(all)
    }
    /// Follows a job's changes.
    pub fn watch(self: &Arc<Self>, id: &JobId) -> Watch {
        Watch { jobs: self.clone(), id: *id, changes: self.queue.changes(), local: None }
    }
    fn notify(&self) {
        let (flag, cv) = &self.wake;
        *flag.lock().unwrap_or_else(|e| e.into_inner()) = true;
        cv.notify_all();
    }
    /// Waits until woken or `timeout` passes.
    fn sleep(&self, timeout: Duration) {
        let (flag, cv) = &self.wake;
        let mut woken = flag.lock().unwrap_or_else(|e| e.into_inner());
        if !*woken {
            woken = cv.wait_timeout(woken, timeout).unwrap_or_else(|e| e.into_inner()).0;
        }
        *woken = false;
    }
    fn next_owner(&self) -> String {
        format!("{}:{}", self.replica, self.claims.fetch_add(1, Ordering::Relaxed))
    }
}

/// A job's changes, wherever it runs: the live view of a job running here, else the queue's announcements (a
/// heartbeat of the replica that runs it, or any transition), with a poll every second besides.
pub struct Watch {
    jobs: Arc<Jobs>,
    id: JobId,
    changes: broadcast::Receiver<String>,
    local: Option<watch::Receiver<JobView>>,
}

impl Watch {
    /// The job's view now (None: no such job).
    pub fn current(&mut self) -> Result<Option<JobView>, JobError> {
        if self.local.is_none() {
            self.local = self.jobs.local(&self.id.hex()).map(|j| j.view.subscribe());
        }
        match &mut self.local {
            Some(rx) if rx.has_changed().is_ok() => Ok(Some(rx.borrow_and_update().clone())),
            _ => {
                self.local = None;
                Ok(self.jobs.queue.get(&self.id)?)
            }
        }
    }
    /// Returns once the job may have changed.
    pub async fn changed(&mut self) {
        let poll = tokio::time::sleep(Duration::from_secs(1));
        let id = self.id.hex();
        let changes = &mut self.changes;
        let announced = async {
            loop {
                match changes.recv().await {
                    // `*`: the store may have missed changes (it reconnected).
                    Ok(changed) if changed == id || changed == "*" => return,
                    Ok(_) => {}
                    Err(broadcast::error::RecvError::Lagged(_)) => return,
                    Err(broadcast::error::RecvError::Closed) => return std::future::pending().await,
                }
            }
        };
        match &mut self.local {
            Some(rx) => {
                tokio::select! {
                    r = rx.changed() => if r.is_err() { self.local = None },
                    _ = announced => {},
                    _ = poll => {},
                }
            }
            None => {
                tokio::select! {
                    _ = announced => {},
                    _ = poll => {},
                }
            }
        }
    }
}

/// Submits a job within the configured limits, or returns the existing one for the same request (true: newly
/// enqueued).
pub fn submit(
    jobs: &Jobs,
    config: &EngineConfig,
    shape: Arc<StoredShape>,
    analysis: Analysis,
) -> Result<(JobView, bool), JobError> {
    submit_in(jobs, config, shape, analysis, Lane::Run)
}

/// Submits a job of a bulk upload as [`submit`] does, in the backlog lane: never refused for the queue's capacity,
/// it waits in the store behind the run lane and starts as workers free up. The caller bounds the backlog
/// (`--max-backlog`, with [`Jobs::backlog`]) before it stores anything.
pub fn submit_backlog(
    jobs: &Jobs,
    config: &EngineConfig,
    shape: Arc<StoredShape>,
    analysis: Analysis,
) -> Result<(JobView, bool), JobError> {
    submit_in(jobs, config, shape, analysis, Lane::Backlog)
}

fn submit_in(
    jobs: &Jobs,
    config: &EngineConfig,
    shape: Arc<StoredShape>,
    analysis: Analysis,
    lane: Lane,
) -> Result<(JobView, bool), JobError> {
    analysis.supported(&shape.validated.shape).map_err(JobError::Analysis)?;
    super::limits::check_limits(config, &analysis)?;
    super::limits::check_work(config, &analysis, &shape.validated)?;
    let canonical = serde_json::to_value(&analysis).map_err(|e| JobError::Internal(e.to_string()))?;
    let id = job_id(&shape.id, &canonical);
    let shape_id = shape.id.clone();
    jobs.enqueue_in(id, shape_id, analysis.name(), canonical, lane)
}

/// Submits a comparison of stored shapes (the request's `shape_ids` resolved, in that order), or returns the
/// existing job for the same request.
pub fn submit_compare(
    jobs: &Jobs,
    config: &EngineConfig,
    mut request: super::compare::CompareRequest,
    shapes: Vec<Arc<StoredShape>>,
) -> Result<(JobView, bool), JobError> {
    request.check().map_err(JobError::Analysis)?;
    if request.options.k == 0 {
        return Err(JobError::Analysis(crate::analysis::AnalysisError::invalid_k(
            "k = 0: ask for at least one eigenpair",
        )));
    }
    if request.options.k > config.max_k {
        return Err(JobError::Limit(Limit::Pairs(format!(
            "k = {} is above --max-k {}",
            request.options.k, config.max_k
        ))));
    }
    // Each shape's fingerprint within the limits a job of it would have (its eigenvectors too, unless shape-DNA
    // alone is asked).
    let dna = match request.descriptor {
        crate::analysis::Descriptor::ShapeDna => Analysis::ShapeDna {
            options: request.options(),
            operator: request.operator.clone(),
            solver: crate::analysis::SolverSpec::default(),
        },
        _ => Analysis::Fingerprint {
            options: request.options.clone(),
            operator: request.operator.clone(),
            solver: crate::analysis::SolverSpec::default(),
        },
    };
    for s in &shapes {
        super::limits::check_work(config, &dna, &s.validated)?;
    }
    request.shape_ids = Some(shapes.iter().map(|s| s.id.clone()).collect());
    let canonical = serde_json::to_value(&request).map_err(|e| JobError::Internal(e.to_string()))?;
    let id = job_id("compare", &canonical);
    jobs.enqueue(id, String::new(), "compare", canonical)
}

/// Submits a correspondence between two stored shapes within the configured limits, or returns the existing job
/// for the same request.
pub fn submit_correspondence(
    jobs: &Jobs,
    config: &EngineConfig,
    request: super::correspondence::CorrespondenceRequest,
    source: &StoredShape,
    target: &StoredShape,
) -> Result<(JobView, bool), JobError> {
    super::limits::check_correspondence(config, &request, &source.validated, &target.validated)?;
    let o = &request.options;
    let k = o.refine_k.max(o.fit_k) * if o.partial { 2 } else { 1 };
    // The eigenvectors of both shapes and the embeddings the nearest neighbours are searched in.
    let n = source.validated.shape.vertex_count().max(target.validated.shape.vertex_count());
    let held = n.saturating_mul(3 * k);
    if held > config.max_output_values {
        return Err(JobError::Limit(Limit::Values(format!(
            "{k} eigenpairs of {n} vertices hold about {held} values, above --max-output-values {}",
            config.max_output_values
        ))));
    }
    for s in [source, target] {
        if !matches!(
            s.validated.shape,
            kac_core::Shape::TriangleMesh(_) | kac_core::Shape::TetMesh(_) | kac_core::Shape::PointCloud(_)
        ) {
            return Err(JobError::Analysis(crate::analysis::AnalysisError::not_applicable(format!(
                "a correspondence is between surfaces, solids or point clouds, not a {}",
                s.validated.shape.kind().as_str()
            ))));
        }
    }
    let canonical = serde_json::to_value(&request).map_err(|e| JobError::Internal(e.to_string()))?;
    let id = job_id("correspondence", &canonical);
    jobs.enqueue(id, source.id.clone(), "correspondence", canonical)
}

impl Jobs {
    /// Enqueues a request under its id in the run lane unless a job with that id is queued, running or done (true:
    /// newly enqueued).
    fn enqueue(
        &self,
        id: String,
        shape_id: String,
        analysis: &str,
        canonical: serde_json::Value,
    ) -> Result<(JobView, bool), JobError> {
        self.enqueue_in(id, shape_id, analysis, canonical, Lane::Run)
    }

    /// [`Jobs::enqueue`] in a given lane.
    fn enqueue_in(
        &self,
        id: String,
        shape_id: String,
        analysis: &str,
        canonical: serde_json::Value,
        lane: Lane,
    ) -> Result<(JobView, bool), JobError> {
        let view = JobView {
            id,
            shape_id,
            analysis: analysis.into(),
            status: Status::Enqueued,
            progress: JobProgress { phase: "queued".into(), converged: 0, wanted: 0 },
            created_at: now(),
            started_at: None,
            finished_at: None,
            error: None,
            result: None,
            request: canonical,
        };
        match self.queue.enqueue(view, lane, self.capacity)? {
            Enqueued::Existing(v) => Ok((v, false)),
            Enqueued::Full => Err(JobError::QueueFull { capacity: self.capacity }),
            Enqueued::New(v) => {
                self.submitted.fetch_add(1, Ordering::Relaxed);
                self.notify();
                Ok((v, true))
            }
        }
    }

    /// Jobs waiting in the backlog lane (on all replicas together).
    pub fn backlog(&self) -> Result<usize, JobError> {
        Ok(self.queue.backlog()?)
    }

    /// Records a bulk upload's jobs as a new batch; its id.
    pub fn put_batch(&self, jobs: &[JobId]) -> Result<BatchId, JobError> {
        let seed: Vec<u8> = jobs.iter().flat_map(|j| j.0).collect();
        let batch = BatchId::draw(&seed);
        self.queue.put_batch(&batch, jobs)?;
        Ok(batch)
    }

    /// A batch's progress (None: no such batch).
    pub fn batch(&self, batch: &BatchId) -> Result<Option<BatchProgress>, JobError> {
        Ok(self.queue.batch(batch)?)
    }

    /// Cancels a job: an enqueued one at once, a running one at its next stop-flag check (here at once; on another
    /// replica when its heartbeat sees the request, at once on the announcement). None: no such job.
    pub fn cancel(&self, id: &JobId) -> Result<Option<JobView>, JobError> {
        let view = self.queue.cancel(id, &canceled())?;
        if let Some(j) = self.local(&id.hex()) {
            j.stop.store(true, Ordering::SeqCst);
            return Ok(Some(j.snapshot()));
        }
        Ok(view)
    }
}

/// After a start: the jobs a dead process held go back in the queue (see [`JobQueue::recover`]); the number
/// enqueued.
pub fn recover(jobs: &Jobs) -> std::io::Result<usize> {
    jobs.queue.recover()
}

/// Why a claimed job's work cannot be made.
enum NoWork {
    /// Its request or shapes are gone: the job fails.
    Gone(&'static str),
    /// The store cannot be read now: the job is left to its lease, and another claim tries again.
    Store(std::io::Error),
}

/// The work a claimed job names: its request parsed and its shapes read back from the store.
fn work_of(state: &Arc<Engine>, view: &JobView) -> Result<Work, NoWork> {
    // Ids the service wrote itself; one that does not parse names no stored shape.
    let shape = |id: &str, gone: &'static str| match ShapeId::parse(id).map(|id| state.shapes.get(&id)) {
        None => Err(NoWork::Gone(gone)),
        Some(got) => match got {
            Ok(Some(s)) => Ok(s),
            Ok(None) => Err(NoWork::Gone(gone)),
            Err(e) => Err(NoWork::Store(e)),
        },
    };
    if view.analysis == "correspondence" {
        let req = serde_json::from_value::<super::correspondence::CorrespondenceRequest>(view.request.clone())
            .map_err(|_| NoWork::Gone("the stored request no longer parses"))?;
        let source = shape(&req.source_id, "the correspondence's source is no longer stored")?;
        let target = shape(&req.target_id, "the correspondence's target is no longer stored")?;
        return Ok(Work::Correspondence(req, source, target));
    }
    if view.analysis == SLICE_JOB {
        let req = serde_json::from_value::<SliceRequest>(view.request.clone())
            .map_err(|_| NoWork::Gone("the stored request no longer parses"))?;
        return Ok(Work::Slice(req, shape(&view.shape_id, "the job's shape is no longer stored")?));
    }
    if view.analysis == "compare" {
        let req = serde_json::from_value::<super::compare::CompareRequest>(view.request.clone())
            .map_err(|_| NoWork::Gone("the stored request no longer parses"))?;
        let shapes = req
            .shape_ids
            .iter()
            .flatten()
            .map(|id| shape(id, "a shape of the comparison is no longer stored"))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Work::Compare(req, shapes))
    } else {
        let a = serde_json::from_value::<Analysis>(view.request.clone())
            .map_err(|_| NoWork::Gone("the stored request no longer parses"))?;
        Ok(Work::Analysis(a, shape(&view.shape_id, "the job's shape is no longer stored")?))
    }
}

/// Idle workers lent to a job cut into spectrum slices, one slice at a time: a worker given back (no slice left,
/// or a job waiting in the queue after a slice) wakes the dispatcher. Lending never runs more threads than the
/// pool has: a lent worker is one of its threads, counted busy until given back.
impl kac_core::spectrum::Lender for Jobs {
    fn borrow(&self, wanted: usize) -> usize {
        // A job waiting in the queue comes first: no worker is lent while one waits (asked before the lock below,
        // since the queue may be a database).
        if self.job_waits() {
            return 0;
        }
        // Under the running set's lock, so that two jobs asking together are not both granted the same worker.
        // A running job may use `solver_threads` threads of the pool: those are not idle.
        let running = self.running.lock().unwrap_or_else(|e| e.into_inner());
        let busy = running.len() * self.solver_threads.max(1) + self.starting.load(Ordering::SeqCst);
        let mut granted = 0;
        let _ = self.lent.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |lent| {
            granted = self.workers.saturating_sub(busy + lent).min(wanted);
            Some(lent + granted)
        });
        granted
    }
    fn wanted_back(&self) -> bool {
        // A job waiting in the queue (for any replica) takes precedence over more slices of one already running.
        self.job_waits()
    }
    fn give_back(&self) {
        let _ = self.lent.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |l| Some(l.saturating_sub(1)));
        self.notify();
    }
}

/// Wakes this replica's dispatcher whenever the queue announces a change (a job enqueued on any replica among
/// them), so that an idle worker claims it at once rather than at its next poll. Ends with the queue.
pub fn wake_on_changes(jobs: &Arc<Jobs>) -> std::io::Result<()> {
    let mut changes = jobs.queue.changes();
    let jobs = Arc::downgrade(jobs);
    std::thread::Builder::new().name("kac-wake".into()).spawn(move || loop {
        match changes.blocking_recv() {
            Ok(_) | Err(broadcast::error::RecvError::Lagged(_)) => match jobs.upgrade() {
                Some(j) => j.notify(),
                None => return,
            },
            Err(broadcast::error::RecvError::Closed) => return,
        }
    })?;
    Ok(())
}

/// The dispatcher of this replica: claims jobs from the queue while a worker is free and starts them on the pool;
/// every `lease / 3` it also requeues jobs whose lease expired (a replica that died; never one running here).
/// Runs until the process drains.
pub fn dispatch(state: Arc<Engine>) {
    let jobs = &state.jobs;
    let mut last_sweep: Option<Duration> = None;
    loop {
        if state.draining.load(Ordering::SeqCst) {
            return;
        }
        let now = jobs.clock.elapsed();
        if last_sweep.is_none_or(|at| now.saturating_sub(at) >= jobs.lease / 3) {
            last_sweep = Some(now);
            match jobs.queue.requeue_expired(&jobs.held_claims()) {
                Ok(ids) if !ids.is_empty() => tracing::warn!(jobs = ?ids, "requeued jobs whose lease expired"),
                Ok(_) => {}
                Err(e) => tracing::error!(error = %e, "cannot requeue expired jobs"),
            }
        }
        if !jobs.reserve() {
            jobs.sleep(Duration::from_millis(500));
            continue;
        }
        let owner = jobs.next_owner();
        let claim = jobs.queue.claim(&owner, jobs.lease);
        if let Ok(Some(view)) = claim {
            // In the running set before the reservation ends: the worker stays counted busy throughout.
            runner::start(&state, view, owner);
            jobs.claimed();
            continue;
        }
        jobs.claimed();
        match claim {
            Ok(_) => jobs.sleep(Duration::from_millis(500)),
            Err(e) => {
                tracing::error!(error = %e, "cannot claim a job");
                jobs.sleep(Duration::from_secs(1));
            }
        }
    }
}

#[cfg(test)]
mod tests;
