//! The job runner: a job on the rayon pool with its timer, from `processing` to its stored result or its
//! problem (a panic fails that job only; a stop flag set by the timer fails it with `job-timeout`, by a cancel
//! cancels it).

use super::*;

/// Starts a claimed job on the pool.
pub(super) fn start(state: &Arc<Engine>, view: JobView, owner: String) {
    let name: &'static str = if view.analysis == "compare" {
        "compare"
    } else if view.analysis == "correspondence" {
        "correspondence"
    } else if view.analysis == SLICE_JOB {
        SLICE_JOB
    } else {
        serde_json::from_value::<Analysis>(view.request.clone()).map_or("unknown", |a| a.name())
    };
    let id = view.id.clone();
    let job = Arc::new(Job {
        view: watch::Sender::new(view),
        stop: AtomicBool::new(false),
        timed_out: AtomicBool::new(false),
        lost: AtomicBool::new(false),
        finishing: AtomicBool::new(false),
        name,
        owner,
        started: state.jobs.clock.elapsed(),
    });
    state.jobs.running.lock().unwrap_or_else(|e| e.into_inner()).insert(id.clone(), job.clone());
    let st = state.clone();
    state.jobs.pool.spawn_fifo(move || {
        let started = std::time::Instant::now();
        let outcome = run_job(&st, &job);
        st.jobs.running.lock().unwrap_or_else(|e| e.into_inner()).remove(&id);
        st.jobs.notify();
        if let Some(outcome) = outcome {
            st.metrics.record_job(job.name, outcome.name(), started.elapsed().as_secs_f64());
        }
    });
}

/// The supervisor of this replica's running jobs, every 100 ms ([`Jobs::supervise_once`]), until the process
/// drains.
pub fn supervise(state: Arc<Engine>) {
    let jobs = &state.jobs;
    let mut changes = jobs.queue.changes();
    let mut beats = Beats::new();
    loop {
        std::thread::sleep(Duration::from_millis(100));
        let mut announced = std::collections::HashSet::new();
        loop {
            match changes.try_recv() {
                Ok(id) => {
                    announced.insert(id);
                }
                Err(broadcast::error::TryRecvError::Lagged(_)) => continue,
                Err(_) => break,
            }
        }
        jobs.supervise_once(&mut beats, &announced);
        if state.draining.load(Ordering::SeqCst) && jobs.running() == 0 {
            return;
        }
    }
}

/// Per running job: when the supervisor last renewed its claim (the engine's clock), and the progress it carried.
pub type Beats = HashMap<String, (Duration, JobProgress)>;

impl Jobs {
    /// One round of the supervisor: renews each running job's claim (every `lease / 3`, and within a second of a
    /// change of progress, which the beat carries to other replicas), stops a job whose cancel was asked for on
    /// any replica (at once when `announced` names it) or whose claim was lost, and stops a job that has run longer
    /// than the timeout (the clock starts when it starts running, not when it was queued).
    pub fn supervise_once(&self, beats: &mut Beats, announced: &std::collections::HashSet<String>) {
        let now = self.clock.elapsed();
        let running: Vec<Arc<Job>> = self.running.lock().unwrap_or_else(|e| e.into_inner()).values().cloned().collect();
        beats.retain(|id, _| running.iter().any(|j| j.snapshot().id == *id));
        for job in running {
            let view = job.snapshot();
            // A job whose outcome is written has no claim left to renew (it is leaving the running set).
            if view.status.terminal() {
                continue;
            }
            if now.saturating_sub(job.started) >= self.timeout && !job.stop.load(Ordering::SeqCst) {
                // A job already told to stop (canceled) stays canceled: the timer only stops a job nobody stopped.
                job.timed_out.store(true, Ordering::SeqCst);
                job.stop.store(true, Ordering::SeqCst);
            }
            // The claim itself set the lease as the job started: the first beat is due a third of a lease after
            // that, not after the supervisor first sees the job.
            let (at, progress) = beats.entry(view.id.clone()).or_insert_with(|| (job.started, view.progress.clone()));
            let since = now.saturating_sub(*at);
            let due = since >= self.lease / 3
                || (since >= Duration::from_secs(1) && progress.phase != view.progress.phase)
                || (since >= Duration::from_secs(1) && progress.converged != view.progress.converged);
            if !due && !announced.contains(&view.id) {
                continue;
            }
            match self.queue.heartbeat(&view.id, &job.owner, &view.progress, self.lease) {
                Ok(Lease::Held { cancel }) => {
                    if cancel {
                        job.stop.store(true, Ordering::SeqCst);
                    }
                    beats.insert(view.id.clone(), (now, view.progress.clone()));
                }
                // The job's outcome is being written, or was, between the snapshot and the beat: its claim ended
                // with that write (which says so itself if the claim was lost before it).
                Ok(Lease::Lost) if job.finishing.load(Ordering::SeqCst) || job.snapshot().status.terminal() => {}
                Ok(Lease::Lost) => {
                    tracing::warn!(job = %view.id, "the job's claim was lost: stopping it without a result");
                    job.lost.store(true, Ordering::SeqCst);
                    job.stop.store(true, Ordering::SeqCst);
                }
                // The store is away for a moment (a restart): the lease runs on, and the next beat tries again.
                Err(e) => tracing::error!(job = %view.id, error = %e, "cannot renew the job's claim"),
            }
        }
    }
}

/// Writes the job's final view: here at once, in the queue while this claim holds it (retried while the store
/// is away, for as long as the lease would last).
fn finish(state: &Arc<Engine>, job: &Job, status: Status, error: Option<Failure>, result: Option<String>) {
    let mut view = job.snapshot();
    view.status = status;
    view.finished_at = Some(now());
    view.error = error;
    view.result = result;
    if status == Status::Succeeded {
        view.progress.phase = "done".into();
    }
    // Shown here only once the queue holds it: a claim that was lost writes nothing, and its watchers here must
    // not see an outcome the job does not have. The supervisor's beats stop taking a missing claim for a lost one
    // from here on: the write below ends the claim.
    job.finishing.store(true, Ordering::SeqCst);
    let deadline = std::time::Instant::now() + state.jobs.lease;
    loop {
        match state.jobs.queue.finish(&view.id, &job.owner, &view) {
            Ok(true) => {
                job.view.send_replace(view);
                return;
            }
            Ok(false) => {
                tracing::warn!(job = %view.id, "the job's claim was lost before it finished: its outcome is not written");
                return;
            }
            Err(e) if std::time::Instant::now() < deadline => {
                tracing::error!(job = %view.id, error = %e, "cannot write the job's outcome; retrying");
                std::thread::sleep(Duration::from_millis(500));
            }
            Err(e) => {
                tracing::error!(job = %view.id, error = %e, "cannot write the job's outcome; its lease will expire");
                return;
            }
        }
    }
}

/// Runs a job; its outcome (None: the claim was lost, nothing written).
fn run_job(state: &Arc<Engine>, job: &Arc<Job>) -> Option<Status> {
    if job.stop.load(Ordering::SeqCst) {
        return stopped(state, job);
    }
    // Testing only (debug builds, `service::faults`): a wait before computing, in short steps that see the stop flag.
    let delay = std::time::Instant::now() + Duration::from_millis(state.faults.job_delay_ms);
    while std::time::Instant::now() < delay {
        std::thread::sleep(Duration::from_millis(20).min(delay.saturating_duration_since(std::time::Instant::now())));
        if job.stop.load(Ordering::SeqCst) {
            return stopped(state, job);
        }
    }
    let work = match work_of(state, &job.snapshot()) {
        Ok(w) => w,
        Err(NoWork::Gone(why)) => {
            let p = Failure::internal(format!("the job cannot run: {why}"));
            finish(state, job, Status::Failed, Some(p), None);
            return Some(Status::Failed);
        }
        Err(NoWork::Store(e)) => {
            tracing::error!(job = %job.snapshot().id, error = %e, "cannot read the job's shapes; leaving it to its lease");
            job.lost.store(true, Ordering::SeqCst);
            return None;
        }
    };
    let progress = |p: Progress| {
        job.view.send_modify(|v| {
            v.progress = JobProgress { phase: p.phase.into(), converged: p.converged, wanted: p.wanted };
        });
    };
    let on_solve = |s: &kac_core::spectrum::Stats| state.metrics.record_solve(s);
    // Slices of this job's spectrum that other replicas may solve (with a shared store); one operator per job, so
    // analyses of one shape only.
    let farm = match &work {
        Work::Analysis(..) => slices::SliceFarm::of(state, &job.snapshot()),
        _ => None,
    };
    let hooks = Hooks {
        on_solve: Some(&on_solve),
        control: Control {
            progress: Some(&progress),
            stop: Some(&job.stop),
            lender: Some(&*state.jobs),
            farm: farm.as_ref().map(|f| f as &dyn kac_core::spectrum::Farm),
        },
        cache: Some(&*state.cache),
        threads: state.config.solver_threads,
        limits: analysis::SolverLimits { max_pairs: state.config.max_k, max_values: state.config.max_output_values },
    };
    let panic_on = state.faults.panic_analysis.as_deref() == Some(job.name);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        if panic_on {
            panic!("test hook: the '{}' analysis panics", job.name);
        }
        match &work {
            Work::Analysis(a, shape) => analysis::run(&shape.validated, a, hooks),
            Work::Compare(req, shapes) => crate::compare::run(shapes, req, Some(&state.index), hooks, state.status_of),
            Work::Correspondence(req, s, t) => crate::correspondence::run(&s.validated, &t.validated, req, hooks),
            Work::Slice(req, shape) => slices::run(shape, req, hooks, &state.jobs.replica),
        }
    }));
    match result {
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            let p = Failure::job_panicked(&without_paths(&msg));
            finish(state, job, Status::Failed, Some(p), None);
            Some(Status::Failed)
        }
        Ok(Err(e)) if e.is_stop() => stopped(state, job),
        Ok(Err(e)) => {
            let p = Failure::of_analysis(&e);
            finish(state, job, Status::Failed, Some(p), None);
            Some(Status::Failed)
        }
        Ok(Ok(out)) => {
            job.view.send_modify(|v| v.progress.phase = "storing".into());
            for f in &out.fingerprints {
                // The search index is a by-product: a failure to keep a fingerprint does not fail the job.
                if let Err(e) = state.index.record(&*state.fingerprints, f) {
                    tracing::error!(shape = %f.shape_id, error = %e, "cannot store the fingerprint");
                }
            }
            let id = job.snapshot().id;
            // A store that is away for a moment (a restart) is waited for, as long as a lease lasts; then the claim
            // is given up and the job runs again elsewhere, never failed for it.
            let deadline = std::time::Instant::now() + state.jobs.lease;
            let (summary, arrays) = linked(out, &id);
            let result = Arc::new(if job.name == SLICE_JOB {
                // Read once, by the job that offered the slice, then removed: no body hash.
                StoredResult::unhashed(&id, summary, arrays)
            } else {
                StoredResult::new(&id, summary, arrays)
            });
            loop {
                match state.results.put(result.clone()) {
                    Ok(_) => {
                        finish(state, job, Status::Succeeded, None, Some(format!("/v1/results/{id}")));
                        return Some(Status::Succeeded);
                    }
                    Err(e) if std::time::Instant::now() < deadline && !job.lost.load(Ordering::SeqCst) => {
                        tracing::error!(job = %id, error = %e, "cannot store the result; retrying");
                        std::thread::sleep(Duration::from_millis(500));
                    }
                    Err(e) => {
                        tracing::error!(job = %id, error = %e, "cannot store the result; leaving the job to its lease");
                        job.lost.store(true, Ordering::SeqCst);
                        return None;
                    }
                }
            }
        }
    }
}

/// A job that stopped on its flag: nothing written when its claim was lost, failed with `job-timeout` when the
/// timer set it, canceled otherwise.
fn stopped(state: &Arc<Engine>, job: &Job) -> Option<Status> {
    if job.lost.load(Ordering::SeqCst) {
        None
    } else if job.timed_out.load(Ordering::SeqCst) {
        let p = Failure::job_timeout(state.jobs.timeout.as_secs());
        finish(state, job, Status::Failed, Some(p), None);
        Some(Status::Failed)
    } else {
        finish(state, job, Status::Canceled, Some(canceled()), None);
        Some(Status::Canceled)
    }
}

/// A panic message as a client may see it: source paths of the machine that built the server (`/home/…/x.rs:12`,
/// a dependency's path in the registry) cut to the file's name, so no build-host path leaves the process (the
/// whole message is logged).
pub(crate) fn without_paths(msg: &str) -> String {
    let token = |t: &str| {
        if t.contains(".rs") && (t.contains('/') || t.contains('\\')) {
            let name = t.rsplit(['/', '\\']).next().unwrap_or(t);
            name.to_string()
        } else {
            t.to_string()
        }
    };
    msg.lines().map(|l| l.split(' ').map(token).collect::<Vec<_>>().join(" ")).collect::<Vec<_>>().join("\n")
}

pub(super) fn canceled() -> Failure {
    Failure::canceled()
}

/// A result to store: the summary with each array's shape and links (its values are written into the body per
/// response), and the arrays themselves.
pub fn result_of(out: analysis::Output, id: &str) -> StoredResult {
    let (summary, arrays) = linked(out, id);
    StoredResult::new(id, summary, arrays)
}

/// An output's summary with its result id and each array's shape and links, and its arrays.
fn linked(out: analysis::Output, id: &str) -> (serde_json::Value, Vec<analysis::VertexArray>) {
    let mut summary = out.summary;
    let mut arrays = serde_json::Map::new();
    for a in &out.arrays {
        let link = |ext: &str| format!("/v1/results/{id}/arrays/{}.{ext}", a.name);
        let mut meta = super::ArrayLinks {
            rows: a.rows,
            cols: a.cols,
            columns: a.columns.clone(),
            npy: link("npy"),
            ply: None,
            mtx: None,
            npz: None,
            values: None,
        };
        if analysis::MATRIX_ARRAYS.contains(&a.name) {
            // A matrix: its triplets as .npy, the matrix itself as Matrix Market and SciPy .npz.
            meta.mtx = Some(link("mtx"));
            meta.npz = Some(link("npz"));
        } else if analysis::is_per_vertex(a.name) {
            meta.ply = Some(link("ply"));
        }
        arrays.insert(a.name.into(), serde_json::to_value(meta).unwrap_or_default());
    }
    if let Some(o) = summary.as_object_mut() {
        o.insert("result_id".into(), id.into());
        if !arrays.is_empty() {
            o.insert("arrays".into(), serde_json::Value::Object(arrays));
        }
    }
    (summary, out.arrays)
}

#[cfg(test)]
mod tests {
    #[test]
    fn panic_messages_lose_build_host_paths() {
        let m = "assertion failed at /root/.cargo/registry/src/index.crates.io-1/faer-0.24.0/src/mat/matref.rs:123:5\n\
                 left: 3 (/home/ci/kac/crates/kac-core/src/spectrum/lanczos.rs:40)";
        let s = super::without_paths(m);
        assert!(!s.contains("/root") && !s.contains("/home") && !s.contains(".cargo"), "{s}");
        assert!(s.contains("matref.rs:123:5") && s.contains("lanczos.rs:40)"), "{s}");
        assert_eq!(super::without_paths("k = 3 is above 2"), "k = 3 is above 2");
    }
}
