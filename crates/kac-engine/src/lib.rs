//! # kac-engine
//!
//! The engine of kac, without HTTP: the analyses ([`analysis`]: requests, the registry, the runner, typed
//! results), the job engine ([`jobs`]: queue, dispatcher, supervisor, runner), the stores ([`store`]: SQLite,
//! PostgreSQL, memory) and the search index ([`search`]). The `kac` binary puts HTTP and the CLI over it; anything
//! else (a Python module, a test) can drive it through an [`Engine`].
//!
//! Layers, enforced by Cargo: `kac-core` (the mathematics) ← `kac-engine` (this crate) ← `kac` (HTTP and CLI). This
//! crate depends on no HTTP crate. Every failure it reports carries a [`code::Code`]; the HTTP layer maps codes to
//! statuses.

#![deny(unsafe_op_in_unsafe_fn)]
#![deny(clippy::undocumented_unsafe_blocks)]

pub mod analysis;
pub mod clock;
pub mod code;
pub mod compare;
pub mod config;
pub mod correspondence;
pub mod error;
pub mod failure;
pub mod faults;
pub mod ids;
pub mod jobs;
pub mod limits;
pub mod record;
pub mod search;
pub mod store;

pub use code::Code;
pub use config::EngineConfig;
pub use failure::Failure;

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use store::{EigenCache, FingerprintStore, ResultStore, ShapeStore};

/// Where the engine reports what it did, for the service's metrics (or nowhere: [`NoMetrics`]).
pub trait Metrics: Send + Sync {
    /// A job of `analysis` ended with `status` after `seconds` on a worker.
    fn record_job(&self, analysis: &str, status: &str, seconds: f64);
    /// An eigensolve finished with these statistics.
    fn record_solve(&self, stats: &kac_core::spectrum::Stats);
}

/// Metrics that go nowhere.
pub struct NoMetrics;

impl Metrics for NoMetrics {
    fn record_job(&self, _: &str, _: &str, _: f64) {}
    fn record_solve(&self, _: &kac_core::spectrum::Stats) {}
}

/// The engine's handle: the stores, the search index, the eigenpair cache, the job engine, its settings and where
/// it reports. Opened once per process; the dispatcher and supervisor threads hold a reference to it.
pub struct Engine {
    pub config: EngineConfig,
    pub shapes: Arc<dyn ShapeStore>,
    pub results: Arc<dyn ResultStore>,
    pub fingerprints: Arc<dyn FingerprintStore>,
    /// Every stored fingerprint, by family, for searches.
    pub index: search::Index,
    pub cache: Arc<EigenCache>,
    pub jobs: Arc<jobs::Jobs>,
    pub metrics: Arc<dyn Metrics>,
    /// The number a result that carries one gives a failure's code (the compare result's `failures[].status`):
    /// the host's mapping, since the engine decides no status.
    pub status_of: fn(Code) -> u16,
    /// Set when the process stops: the dispatcher claims nothing more, the supervisor ends with the last job.
    pub draining: AtomicBool,
    /// Jobs enqueued when this process started (those a dead process held included).
    pub recovered: usize,
    /// Faults the tests inject (debug builds only; see [`faults`]).
    pub faults: faults::Faults,
}

impl Engine {
    /// Opens the store, puts back in the queue what a dead process held, and starts this replica's dispatcher
    /// (claims jobs while a worker is free) and supervisor (heartbeats, cancels, timeouts).
    pub fn open(
        config: EngineConfig,
        metrics: Arc<dyn Metrics>,
        status_of: fn(Code) -> u16,
    ) -> std::io::Result<Arc<Engine>> {
        let invalid = |e: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, e);
        config.check().map_err(invalid)?;
        let faults = faults::Faults::from_env().map_err(invalid)?;
        let workers = if config.workers == 0 {
            std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
        } else {
            config.workers
        };
        let backend = store::open(&config)?;
        let (index, loaded) = search::Index::load(&*backend.fingerprints, backend.index_snapshot.clone())?;
        tracing::info!(
            from = loaded.from,
            fingerprints = loaded.fingerprints,
            seconds = loaded.seconds,
            refused = loaded.snapshot_refused.as_deref().unwrap_or(""),
            "search index loaded"
        );
        let lease = std::time::Duration::from_secs_f64(config.lease_s.max(0.3));
        let timeout = std::time::Duration::from_secs(config.job_timeout_s);
        let mut jobs = jobs::Jobs::new(
            workers,
            config.queue_capacity.max(1),
            backend.queue.clone(),
            lease,
            timeout,
            Arc::new(jobs::SystemClock::default()),
        );
        jobs.solver_threads = config.solver_threads;
        let jobs = Arc::new(jobs);
        let recovered = jobs::recover(&jobs)?;
        let engine = Arc::new(Engine {
            shapes: backend.shapes,
            fingerprints: backend.fingerprints,
            index,
            results: backend.results,
            cache: Arc::new(EigenCache::new(config.cache_bytes)),
            jobs,
            metrics,
            status_of,
            draining: AtomicBool::new(false),
            recovered,
            faults,
            config,
        });
        let e = engine.clone();
        std::thread::Builder::new().name("kac-dispatch".into()).spawn(move || jobs::dispatch(e))?;
        jobs::wake_on_changes(&engine.jobs)?;
        let e = engine.clone();
        std::thread::Builder::new().name("kac-supervise".into()).spawn(move || jobs::supervise(e))?;
        Ok(engine)
    }
}
