//! The engine's configuration: the store, the workers and the queue, the limits every analysis is checked against
//! and the caches. Each setting has an environment variable and a documented default (`kac serve` flattens these
//! flags into its own), and a value that does not parse stops the start.

use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct EngineConfig {
    /// Directory of the embedded store (`--store sqlite:DIR` names another).
    #[arg(long, env = "KAC_DATA_DIR", default_value = "kac-data")]
    pub data_dir: PathBuf,
    /// Where shapes, jobs and results live: `sqlite:DIR` (the default, embedded, with DIR = --data-dir: one
    /// process owns it) or `postgres://USER@HOST:PORT/DB?…` (shared by any number of replicas).
    #[arg(long, env = "KAC_STORE")]
    pub store: Option<String>,
    /// Seconds a job's claim lasts without a heartbeat (renewed every third of it while the job runs): how long a
    /// job of a replica that died waits before another replica runs it.
    #[arg(long, env = "KAC_LEASE_S", default_value_t = 30.0, value_parser = lease_seconds)]
    pub lease_s: f64,
    /// Connections to PostgreSQL per replica (the pool's size; one more listens for notifications).
    #[arg(long, env = "KAC_PG_POOL_SIZE", default_value_t = 8, value_parser = at_least_one)]
    pub pg_pool_size: usize,
    /// Worker threads running jobs (0: one per core).
    #[arg(long, env = "KAC_WORKERS", default_value_t = 0)]
    pub workers: usize,
    /// Interactive jobs (the run lane) queued or running at most; beyond it submissions get 503 with Retry-After.
    /// A bulk upload's jobs wait in the backlog lane instead, which this does not bound.
    #[arg(long, env = "KAC_QUEUE_CAPACITY", default_value_t = 64, value_parser = at_least_one)]
    pub queue_capacity: usize,
    /// Bulk uploads' jobs waiting in the backlog lane at most (on all replicas together): an upload whose files
    /// would take the backlog beyond it gets 503 with Retry-After before anything is stored.
    #[arg(long, env = "KAC_MAX_BACKLOG", default_value_t = 1_000_000, value_parser = at_least_one)]
    pub max_backlog: usize,
    /// Largest shape, in vertices.
    #[arg(long, env = "KAC_MAX_VERTICES", default_value_t = 2_000_000, value_parser = at_least_one)]
    pub max_vertices: usize,
    /// Largest number of eigenpairs an analysis may ask for.
    #[arg(long, env = "KAC_MAX_K", default_value_t = 1000, value_parser = at_least_one)]
    pub max_k: usize,
    /// The most cells of the search index one search probes before it answers without a proof that its
    /// neighbours are the exact ones (`exact: false` in the answer). More cells: higher recall, slower searches.
    #[arg(long, env = "KAC_SEARCH_CELLS", default_value_t = 32, value_parser = at_least_one)]
    pub search_cells: usize,
    /// Largest count of any list or grid a descriptor takes (times, energies, τ samples, frequencies, sources,
    /// implicit steps, interpolation values); beyond it, 413 `too-many-samples` before anything is allocated.
    #[arg(long, env = "KAC_MAX_SAMPLES", default_value_t = 10_000, value_parser = at_least_one)]
    pub max_samples: usize,
    /// Largest number of values (vertices × columns) of any per-vertex array an analysis holds or returns,
    /// eigenvectors (k × vertices) and the sparse solver's Krylov basis (each slice's, where the solve is sliced)
    /// included; beyond it, 413 `output-too-large` at submission, or as the job's error where only the run shows it.
    #[arg(long, env = "KAC_MAX_OUTPUT_VALUES", default_value_t = 200_000_000, value_parser = at_least_one)]
    pub max_output_values: usize,
    /// Seconds a job may run before it is stopped and failed.
    #[arg(long, env = "KAC_JOB_TIMEOUT_S", default_value_t = 600, value_parser = clap::value_parser!(u64).range(1..=MAX_SECONDS as u64))]
    pub job_timeout_s: u64,
    /// Bytes of eigenpairs kept in memory for reuse across analyses.
    #[arg(long, env = "KAC_CACHE_BYTES", default_value_t = 1024 * 1024 * 1024)]
    pub cache_bytes: usize,
    /// Bytes of parsed shapes, and separately of results, kept in memory in front of the store.
    #[arg(long, env = "KAC_STORE_CACHE_BYTES", default_value_t = 512 * 1024 * 1024)]
    pub store_cache_bytes: usize,
    /// Threads each eigensolve uses, its dense decompositions and sparse products included (jobs run side by side on
    /// the workers).
    #[arg(long, env = "KAC_SOLVER_THREADS", default_value_t = 1, value_parser = at_least_one)]
    pub solver_threads: usize,
}

impl EngineConfig {
    /// Whether `--store` is PostgreSQL, which any number of replicas share (the store was checked at start).
    pub fn shared_store(&self) -> bool {
        self.store.as_deref().is_some_and(|s| s.starts_with("postgres://") || s.starts_with("postgresql://"))
    }

    /// Checks what no single flag's parser can: run at start, before anything is opened.
    pub fn check(&self) -> Result<(), String> {
        if let Some(store) = &self.store {
            if !(store.starts_with("sqlite:") || store.starts_with("postgres://") || store.starts_with("postgresql://"))
            {
                return Err(format!("--store {store}: give sqlite:DIR or postgres://…"));
            }
        }
        Ok(())
    }
}

/// The longest duration any setting may name: a day (a larger one is a mistake, and `Duration` from seconds
/// panics past about 5.8·10¹¹ years).
pub const MAX_SECONDS: f64 = 86_400.0;

/// A duration in seconds: finite, positive, at most a day. `inf`, `NaN`, 0 and negatives stop the server at start.
pub fn seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("'{s}' is not a number of seconds"))?;
    if !v.is_finite() || v <= 0.0 {
        return Err(format!("{s} seconds: give a finite number above 0"));
    }
    if v < 0.001 {
        return Err(format!("{s} seconds: at least 0.001 (one millisecond)"));
    }
    if v > MAX_SECONDS {
        return Err(format!("{s} seconds: at most {MAX_SECONDS} (a day)"));
    }
    Ok(v)
}

/// A lease: as [`seconds`], and at least 0.3 s (heartbeats come every third of it).
pub fn lease_seconds(s: &str) -> Result<f64, String> {
    let v = seconds(s)?;
    if v < 0.3 {
        return Err(format!("{s} seconds: a lease lasts at least 0.3 s (it is renewed every third of it)"));
    }
    Ok(v)
}

/// A count or a size that must allow something: an integer of at least 1.
pub fn at_least_one(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(0) => Err("0 would refuse everything: give at least 1".into()),
        Ok(v) => Ok(v),
        Err(_) => Err(format!("'{s}' is not a whole number of at least 1")),
    }
}
