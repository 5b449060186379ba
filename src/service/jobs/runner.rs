//! The job runner: a job on the rayon pool with its timer, from `processing` to its stored result or its
//! problem (a panic fails that job only; a stop flag set by the timer fails it with `job-timeout`, by a cancel
//! cancels it).

use super::*;

/// Runs a job on the pool, with a timer that stops it when it runs too long. The clock starts when the job starts
/// running (status `processing`): time spent waiting in the queue does not count against `--job-timeout-s`.
pub(super) fn start(state: &AppState, job: Arc<Job>, work: Work) {
    let (st, j) = (state.clone(), job.clone());
    state.jobs.pool.spawn_fifo(move || execute(&st, &j, &work));
    let timeout = std::time::Duration::from_secs(state.config.job_timeout_s);
    tokio::spawn(async move {
        let mut rx = job.view.subscribe();
        loop {
            let status = rx.borrow_and_update().status;
            if status.terminal() {
                return;
            }
            if status == Status::Processing {
                break;
            }
            if rx.changed().await.is_err() {
                return;
            }
        }
        tokio::time::sleep(timeout).await;
        // A job already told to stop (canceled) stays canceled: the timer only stops a job nobody stopped.
        if !job.snapshot().status.terminal() && !job.stop.load(Ordering::SeqCst) {
            job.timed_out.store(true, Ordering::SeqCst);
            job.stop.store(true, Ordering::SeqCst);
        }
    });
}

fn finish(state: &AppState, job: &Job, status: Status, error: Option<Problem>, result: Option<String>) {
    job.view.send_modify(|v| {
        v.status = status;
        v.finished_at = Some(now());
        v.error = error;
        v.result = result;
        if status == Status::Succeeded {
            v.progress.phase = "done".into();
        }
    });
    persist(state, job);
}

fn execute(state: &AppState, job: &Arc<Job>, work: &Work) {
    let started = std::time::Instant::now();
    let outcome = run_job(state, job, work);
    state.jobs.active.fetch_sub(1, Ordering::SeqCst);
    if outcome.terminal() {
        state.metrics.record_job(job.name, outcome.name(), started.elapsed().as_secs_f64());
    }
}

fn run_job(state: &AppState, job: &Arc<Job>, work: &Work) -> Status {
    if state.draining.load(Ordering::SeqCst) {
        // Shutting down: leave it enqueued in the store; the next start runs it.
        return Status::Enqueued;
    }
    if job.stop.load(Ordering::SeqCst) {
        return stopped(state, job);
    }
    // Only an enqueued job starts: a cancel that landed after the flag was read has already ended it.
    let mut started = false;
    job.view.send_modify(|v| {
        if v.status == Status::Enqueued {
            v.status = Status::Processing;
            v.started_at = Some(now());
            v.progress.phase = "operator".into();
            started = true;
        }
    });
    if !started {
        return job.snapshot().status;
    }
    persist(state, job);
    if state.config.test_job_delay_ms > 0 {
        std::thread::sleep(std::time::Duration::from_millis(state.config.test_job_delay_ms));
        if job.stop.load(Ordering::SeqCst) {
            return stopped(state, job);
        }
    }
    let progress = |p: Progress| {
        job.view.send_modify(|v| {
            v.progress = JobProgress { phase: p.phase.into(), converged: p.converged, wanted: p.wanted };
        });
    };
    let on_solve = |s: &kac_core::spectrum::Stats| state.metrics.record_solve(s);
    let hooks = Hooks {
        on_solve: Some(&on_solve),
        control: Control { progress: Some(&progress), stop: Some(&job.stop) },
        cache: Some(&*state.cache),
        threads: state.config.solver_threads,
        limits: analysis::SolverLimits { max_pairs: state.config.max_k, max_values: state.config.max_output_values },
    };
    let panic_on = state.config.test_panic_analysis.as_deref() == Some(job.name);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        if panic_on {
            panic!("test hook: the '{}' analysis panics", job.name);
        }
        match work {
            Work::Analysis(a, shape) => analysis::run(&shape.validated, a, hooks),
            Work::Compare(req, shapes) => crate::service::compare::run(shapes, req, hooks),
        }
    }));
    match result {
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            let (_, p) = ApiError::JobPanicked { detail: msg }.problem();
            finish(state, job, Status::Failed, Some(p), None);
            Status::Failed
        }
        Ok(Err(e)) if e.is_stop() => stopped(state, job),
        Ok(Err(e)) => {
            let (_, p) = ApiError::Analysis(e).problem();
            finish(state, job, Status::Failed, Some(p), None);
            Status::Failed
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
            match store_result(&*state.results, &id, out) {
                Ok(_) => {
                    finish(state, job, Status::Succeeded, None, Some(format!("/v1/results/{id}")));
                    Status::Succeeded
                }
                Err(e) => {
                    let (_, p) =
                        ApiError::Internal { detail: format!("the result could not be stored: {e}") }.problem();
                    finish(state, job, Status::Failed, Some(p), None);
                    Status::Failed
                }
            }
        }
    }
}

/// A job that stopped on its flag: failed with `job-timeout` when the timer set it, canceled otherwise.
fn stopped(state: &AppState, job: &Job) -> Status {
    if job.timed_out.load(Ordering::SeqCst) {
        let (_, p) = ApiError::JobTimeout { seconds: state.config.job_timeout_s }.problem();
        finish(state, job, Status::Failed, Some(p), None);
        Status::Failed
    } else {
        finish(state, job, Status::Canceled, Some(canceled()), None);
        Status::Canceled
    }
}

pub(super) fn canceled() -> Problem {
    ApiError::Canceled.problem().1
}

/// Serializes a result (summary with every array inline) and stores it with its strong ETag.
pub fn store_result(results: &dyn ResultStore, id: &str, out: analysis::Output) -> std::io::Result<Arc<StoredResult>> {
    let mut summary = out.summary;
    let mut arrays = serde_json::Map::new();
    for a in &out.arrays {
        arrays.insert(
            a.name.into(),
            serde_json::json!({
                "rows": a.rows, "cols": a.cols, "columns": a.columns,
                "npy": format!("/v1/results/{id}/arrays/{}.npy", a.name),
                "ply": format!("/v1/results/{id}/arrays/{}.ply", a.name),
                "values": a.to_json(),
            }),
        );
    }
    if let Some(o) = summary.as_object_mut() {
        o.insert("result_id".into(), id.into());
        if !arrays.is_empty() {
            o.insert("arrays".into(), serde_json::Value::Object(arrays));
        }
    }
    let body = serde_json::to_vec(&summary).map_err(std::io::Error::other)?;
    results.put(StoredResult::new(id, summary, out.arrays, body))
}
