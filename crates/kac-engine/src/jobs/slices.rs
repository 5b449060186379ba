//! Slices of one job on other replicas: a job whose spectrum is cut into slices ([`kac_core::spectrum::slicing`])
//! offers the slices its own and lent workers do not start at once as **slice jobs** in the shared queue, which any
//! replica's dispatcher claims like any job. The replica that claims one reads the parent's request, builds the same
//! operator, checks it against the slice's pencil digest, solves the slice and stores its pairs as a result
//! (`eigenvalues` and the array `eigenvectors`). The parent takes back, when it comes to them, the slice jobs nobody
//! has started, collects the others as they succeed, solves here any that failed or were lost (a replica that died:
//! its lease expires and the job is back in the queue, where the parent takes it back), and cancels what it offered
//! when it ends without them (canceled, timed out, or its plan given up).
//!
//! Slice jobs are offered where other replicas can claim them: with a shared store (PostgreSQL). With the embedded
//! store one process holds the queue, and its idle workers join a job as lent workers instead ([`Jobs`]'s
//! [`kac_core::spectrum::Lender`]). `GET /v1/jobs` leaves slice jobs out; each is a job of its own otherwise.

use super::*;
use kac_core::spectrum::slicing::{PartStats, SliceTask, Solved};
use kac_core::spectrum::{EigenError, Farm};

/// The analysis name of a slice job.
pub const SLICE_JOB: &str = "spectrum-slice";

/// What a slice job is asked: the parent job's request, and the slice.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct SliceRequest {
    /// The parent's id (for the logs; the slice's own id hashes the whole request).
    pub parent: String,
    /// The parent's analysis, canonical: the operator is built from it.
    pub analysis: serde_json::Value,
    pub task: SliceTask,
}

/// The offers of one running job.
pub struct SliceFarm<'a> {
    state: &'a Arc<Engine>,
    parent: JobView,
    /// (pencil digest, slice index) → (slice job id, settled: read, taken back, released, or found failed or
    /// canceled). A job may solve several pencils (an extrapolation's refinements), each sliced apart.
    offered: Mutex<HashMap<(String, usize), (String, bool)>>,
}

impl<'a> SliceFarm<'a> {
    /// A farm for the job `parent` when this replica shares its queue with others (a PostgreSQL store); None otherwise.
    pub fn of(state: &'a Arc<Engine>, parent: &JobView) -> Option<Self> {
        (state.config.shared_store() && parent.analysis != SLICE_JOB).then(|| SliceFarm {
            state,
            parent: parent.clone(),
            offered: Mutex::new(HashMap::new()),
        })
    }
    fn key(task: &SliceTask) -> (String, usize) {
        (task.pencil.clone(), task.index)
    }
    fn id_of(&self, task: &SliceTask) -> Option<String> {
        self.offered.lock().unwrap_or_else(|e| e.into_inner()).get(&Self::key(task)).map(|o| o.0.clone())
    }
    fn settle(&self, task: &SliceTask) {
        if let Some(o) = self.offered.lock().unwrap_or_else(|e| e.into_inner()).get_mut(&Self::key(task)) {
            o.1 = true;
        }
    }
    /// Slice jobs this job no longer waits for, on a thread of their own: each is canceled (an enqueued one at once,
    /// a running one at its replica's next heartbeat), and once it has ended (for at most two leases), the pairs of
    /// one that succeeded all the same (it was storing them) leave the store.
    fn discard(&self, ids: Vec<String>) {
        let ids: Vec<JobId> = ids.iter().filter_map(|id| JobId::parse(id)).collect();
        if ids.is_empty() {
            return;
        }
        let state = self.state.clone();
        let _ = std::thread::Builder::new().name("kac-slice-discard".into()).spawn(move || {
            let queue = &state.jobs.queue;
            let until = std::time::Instant::now() + 2 * state.jobs.lease;
            for job in ids {
                let _ = queue.cancel(&job, &Failure::canceled());
                loop {
                    match queue.get(&job) {
                        Ok(Some(v)) if v.status == Status::Succeeded => {
                            remove(&state, job);
                            break;
                        }
                        Ok(Some(v)) if !v.status.terminal() && std::time::Instant::now() < until => {
                            std::thread::sleep(Duration::from_millis(100));
                        }
                        Err(_) if std::time::Instant::now() < until => std::thread::sleep(Duration::from_millis(100)),
                        _ => break,
                    }
                }
            }
        });
    }
    /// The pairs a succeeded slice job stored, checked for shape; None when they cannot be read.
    fn read(&self, id: &str) -> Option<Solved> {
        let rid = JobId::parse(id)?;
        let stored = self.state.results.get(&rid).ok()??;
        // Read once, by this job, whatever it holds: the numbers leave the store (a slice of 125 pairs at 164k
        // vertices holds 160 MB), on a thread of their own while the job goes on.
        let state = self.state.clone();
        let _ = std::thread::Builder::new().name("kac-slice-remove".into()).spawn(move || remove(&state, rid));
        let vectors = stored.arrays.iter().find(|a| a.name == "eigenvectors")?;
        let values: Vec<f64> = serde_json::from_value(stored.summary.get("eigenvalues")?.clone()).ok()?;
        let m = values.len();
        if vectors.cols != m || vectors.data.len() != vectors.rows * m {
            return None;
        }
        let stats: PartStats = serde_json::from_value(stored.summary.get("slice")?.clone()).ok()?;
        let mut stats = stats.stats();
        stats.timings.iteration_s = stored.summary.get("seconds").and_then(|s| s.as_f64()).unwrap_or(0.0);
        let spectrum = kac_core::spectrum::Spectrum {
            values,
            vectors: faer::MatRef::from_row_major_slice(&vectors.data, vectors.rows, m).to_owned(),
            residuals: vec![],
            stats,
        };
        Some(Solved {
            spectrum,
            seconds: stored.summary.get("seconds").and_then(|s| s.as_f64()).unwrap_or(0.0),
            by: stored.summary.get("replica").and_then(|s| s.as_str()).unwrap_or("another replica").to_string(),
        })
    }
}

/// Removes a slice job's pairs from the store.
fn remove(state: &Arc<Engine>, id: JobId) {
    if let Err(e) = state.results.remove(&id) {
        tracing::warn!(result = %id.hex(), error = %e, "cannot remove a slice's pairs");
    }
}

impl Farm for SliceFarm<'_> {
    fn offer(&self, task: &SliceTask) -> bool {
        let request =
            SliceRequest { parent: self.parent.id.clone(), analysis: self.parent.request.clone(), task: task.clone() };
        let Ok(canonical) = serde_json::to_value(&request) else { return false };
        let id = job_id(&self.parent.shape_id, &canonical);
        match self.state.jobs.enqueue(id.clone(), self.parent.shape_id.clone(), SLICE_JOB, canonical) {
            // New, or waiting or running from an earlier run of this job (its replica died): this run's to collect.
            Ok((v, new)) if new || !v.status.terminal() => {
                self.offered.lock().unwrap_or_else(|e| e.into_inner()).insert(Self::key(task), (id, false));
                true
            }
            // Solved for an earlier run that never read it: solved here, and its pairs leave the store.
            Ok(_) => {
                self.discard(vec![id]);
                false
            }
            // A full queue, or a store away: the slice is solved here.
            Err(_) => false,
        }
    }
    fn take_back(&self, task: &SliceTask) -> bool {
        let Some(id) = self.id_of(task) else { return true };
        let jobs = &self.state.jobs;
        let owner = jobs.next_owner();
        match jobs.queue.claim_id(&id, &owner, jobs.lease) {
            Ok(Some(mut view)) => {
                // Finished at once under this claim, so that no lease of it expires and no replica runs it again.
                view.status = Status::Canceled;
                view.finished_at = Some(now());
                view.error = Some(Failure::canceled());
                view.progress.phase = "taken back by its job".into();
                // Unless the store is away: then the claim is left to expire, and the cancel at the job's end (the
                // job is not settled) keeps it from running again.
                if jobs.queue.finish(&id, &owner, &view).unwrap_or(false) {
                    self.settle(task);
                }
                true
            }
            _ => false,
        }
    }
    fn release(&self, task: &SliceTask) {
        if let Some(id) = self.id_of(task) {
            self.discard(vec![id]);
            self.settle(task);
        }
    }
    fn collect(&self, task: &SliceTask, control: &Control<'_>) -> Result<Option<Solved>, EigenError> {
        let Some(id) = self.id_of(task) else { return Ok(None) };
        let Some(job) = JobId::parse(&id) else { return Ok(None) };
        loop {
            control.check()?;
            match self.state.jobs.queue.get(&job) {
                Ok(Some(v)) => match v.status {
                    Status::Succeeded => {
                        // Unread (the store was away), it stays unsettled: discarded at the job's end.
                        let solved = self.read(&id);
                        if solved.is_some() {
                            self.settle(task);
                        }
                        return Ok(solved);
                    }
                    // Not started yet, or back in the queue after a lease expired: solved here.
                    Status::Enqueued if self.take_back(task) => return Ok(None),
                    Status::Enqueued | Status::Processing => {}
                    Status::Failed | Status::Canceled => {
                        self.settle(task);
                        return Ok(None);
                    }
                },
                Ok(None) => return Ok(None),
                // The store is away for a moment: asked again.
                Err(_) => {}
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for SliceFarm<'_> {
    /// Slice jobs this job never settled (it was canceled or timed out while they ran, or could not read one) are
    /// discarded: canceled, and their pairs removed if they were stored all the same.
    fn drop(&mut self) {
        let offered = std::mem::take(self.offered.get_mut().unwrap_or_else(|e| e.into_inner()));
        self.discard(offered.into_values().filter(|(_, settled)| !settled).map(|(id, _)| id).collect());
    }
}

/// Runs a slice job: the parent's operator built again and checked against the slice's pencil, the slice solved,
/// and its pairs: `eigenvalues` in the summary (JSON numbers read back to the bit) and the array `eigenvectors`
/// (n × m, rows in the operator's numbering).
pub fn run(
    shape: &StoredShape,
    request: &SliceRequest,
    hooks: analysis::Hooks<'_>,
    replica: &str,
) -> Result<analysis::Output, analysis::AnalysisError> {
    let parent = serde_json::from_value::<Analysis>(request.analysis.clone())
        .map_err(|e| analysis::AnalysisError::not_applicable(format!("the parent's request does not parse: {e}")))?;
    let spec = parent
        .operator_spec()
        .ok_or_else(|| analysis::AnalysisError::not_applicable("the parent analysis builds no operator"))?;
    hooks.control.check()?;
    let t0 = std::time::Instant::now();
    let operator = analysis::build_operator(&shape.validated, spec)?;
    hooks.control.check()?;
    let s = kac_core::spectrum::slicing::solve_slice(&operator.pair, &request.task, hooks.threads, hooks.control)?;
    let (n, m) = (s.vectors.nrows(), s.vectors.ncols());
    let mut rows = vec![0.0; n * m];
    faer::MatMut::from_row_major_slice_mut(&mut rows, n, m).copy_from(s.vectors.as_ref());
    let summary = serde_json::json!({
        "analysis": SLICE_JOB,
        "parent": request.parent,
        "eigenvalues": s.values,
        "slice": PartStats::of(&s.stats),
        "seconds": t0.elapsed().as_secs_f64(),
        "replica": replica,
    });
    let arrays = vec![analysis::VertexArray { name: "eigenvectors", rows: n, cols: m, data: rows, columns: None }];
    Ok(analysis::Output { summary, arrays, fingerprints: vec![] })
}
