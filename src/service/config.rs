//! `kac serve` configuration: every flag has an environment variable and a documented default, so the service
//! starts on a fresh machine with no configuration at all.

use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct Config {
    /// Address to listen on (port 0: any free port; the chosen address is printed on stdout).
    #[arg(long, env = "KAC_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: String,
    /// Directory of the embedded store (`--store sqlite:DIR` names another).
    #[arg(long, env = "KAC_DATA_DIR", default_value = "kac-data")]
    pub data_dir: PathBuf,
    /// Where shapes, jobs and results live: `sqlite:DIR` (the default, embedded, with DIR = --data-dir: one
    /// process owns it) or `postgres://USER@HOST:PORT/DB?…` (shared by any number of replicas).
    #[arg(long, env = "KAC_STORE")]
    pub store: Option<String>,
    /// Seconds a job's claim lasts without a heartbeat (renewed every third of it while the job runs): how long a
    /// job of a replica that died waits before another replica runs it.
    #[arg(long, env = "KAC_LEASE_S", default_value_t = 30.0)]
    pub lease_s: f64,
    /// Connections to PostgreSQL per replica (the pool's size; one more listens for notifications).
    #[arg(long, env = "KAC_PG_POOL_SIZE", default_value_t = 8)]
    pub pg_pool_size: usize,
    /// Worker threads running jobs (0: one per core).
    #[arg(long, env = "KAC_WORKERS", default_value_t = 0)]
    pub workers: usize,
    /// Jobs queued or running at most; beyond it submissions get 503 with Retry-After.
    #[arg(long, env = "KAC_QUEUE_CAPACITY", default_value_t = 64)]
    pub queue_capacity: usize,
    /// Largest request body in bytes (uploads).
    #[arg(long, env = "KAC_MAX_BODY_BYTES", default_value_t = 256 * 1024 * 1024)]
    pub max_body_bytes: usize,
    /// Largest shape, in vertices.
    #[arg(long, env = "KAC_MAX_VERTICES", default_value_t = 2_000_000)]
    pub max_vertices: usize,
    /// Largest number of eigenpairs an analysis may ask for.
    #[arg(long, env = "KAC_MAX_K", default_value_t = 1000)]
    pub max_k: usize,
    /// Largest count of any list or grid a descriptor takes (times, energies, τ samples, frequencies, sources,
    /// implicit steps, interpolation values); beyond it, 413 `too-many-samples` before anything is allocated.
    #[arg(long, env = "KAC_MAX_SAMPLES", default_value_t = 10_000)]
    pub max_samples: usize,
    /// Largest number of values (vertices × columns) of any per-vertex array an analysis holds or returns,
    /// eigenvectors included (k × vertices); beyond it, 413 `output-too-large` at submission.
    #[arg(long, env = "KAC_MAX_OUTPUT_VALUES", default_value_t = 200_000_000)]
    pub max_output_values: usize,
    /// Seconds a client has to send a request's whole header (also the longest idle time of a kept-alive
    /// connection between requests); then the connection is closed.
    #[arg(long, env = "KAC_HEADER_READ_TIMEOUT_S", default_value_t = 10.0)]
    pub header_read_timeout_s: f64,
    /// Longest pause, in seconds, while a request body is being sent; then 408 `body-timeout`.
    #[arg(long, env = "KAC_BODY_READ_TIMEOUT_S", default_value_t = 30.0)]
    pub body_read_timeout_s: f64,
    /// Connections served at once; one more is answered 503 `too-many-connections` and closed.
    #[arg(long, env = "KAC_MAX_CONNECTIONS", default_value_t = 1024)]
    pub max_connections: usize,
    /// Failed API-key attempts (missing or wrong key) one client address may make per minute; beyond it, 429
    /// `rate-limited` for that address until the minute is over (0: no throttling).
    #[arg(long, env = "KAC_AUTH_FAILURES_PER_MINUTE", default_value_t = 10)]
    pub auth_failures_per_minute: u32,
    /// Seconds a job may run before it is stopped and failed.
    #[arg(long, env = "KAC_JOB_TIMEOUT_S", default_value_t = 600)]
    pub job_timeout_s: u64,
    /// Longest `wait` a synchronous request may ask for, in seconds.
    #[arg(long, env = "KAC_MAX_WAIT_S", default_value_t = 60)]
    pub max_wait_s: u64,
    /// Bytes of eigenpairs kept in memory for reuse across analyses.
    #[arg(long, env = "KAC_CACHE_BYTES", default_value_t = 1024 * 1024 * 1024)]
    pub cache_bytes: usize,
    /// Bytes of parsed shapes, and separately of results, kept in memory in front of the store.
    #[arg(long, env = "KAC_STORE_CACHE_BYTES", default_value_t = 512 * 1024 * 1024)]
    pub store_cache_bytes: usize,
    /// Threads each eigensolve uses (jobs run side by side on the workers).
    #[arg(long, env = "KAC_SOLVER_THREADS", default_value_t = 1)]
    pub solver_threads: usize,
    /// On SIGTERM, seconds to let running jobs finish before exiting (the rest are re-queued at the next start).
    #[arg(long, env = "KAC_SHUTDOWN_GRACE_S", default_value_t = 10)]
    pub shutdown_grace_s: u64,
    /// API keys (comma-separated); when any is set, every /v1 request needs `Authorization: Bearer KEY`.
    /// Off by default.
    #[arg(long, env = "KAC_API_KEYS", value_delimiter = ',', hide_env_values = true)]
    pub api_keys: Vec<String>,
    /// A file with one API key per line (added to --api-keys).
    #[arg(long, env = "KAC_API_KEYS_FILE")]
    pub api_keys_file: Option<PathBuf>,
    /// Origins of web front ends allowed to call the API from a browser (comma-separated, e.g.
    /// `https://app.example.org`, or `*` for any); none by default (same origin only).
    #[arg(long, env = "KAC_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
    /// Requests per minute each API key may make (0: unlimited); beyond it, 429 with Retry-After.
    #[arg(long, env = "KAC_RATE_LIMIT_PER_MINUTE", default_value_t = 0)]
    pub rate_limit_per_minute: u32,
    /// Testing only: jobs of this analysis panic inside the worker (checks that a panic fails one job).
    #[arg(long, hide = true)]
    pub test_panic_analysis: Option<String>,
    /// Testing only: every job sleeps this many milliseconds before it starts computing (fills the queue).
    #[arg(long, hide = true, default_value_t = 0)]
    pub test_job_delay_ms: u64,
}

impl Config {
    /// Every configured key (flag, environment, file), blank lines dropped.
    pub fn api_keys(&self) -> Vec<String> {
        let mut keys: Vec<String> = self.api_keys.iter().map(|k| k.trim().to_string()).collect();
        if let Some(path) = &self.api_keys_file {
            if let Ok(text) = std::fs::read_to_string(path) {
                keys.extend(
                    text.lines().map(|l| l.trim().to_string()).filter(|l| !l.is_empty() && !l.starts_with('#')),
                );
            } else {
                tracing::error!(path = %path.display(), "cannot read the API keys file");
            }
        }
        keys.retain(|k| !k.is_empty());
        keys
    }
}
