//! Counters, gauges and a latency histogram, rendered in the Prometheus text format at `/metrics`.

use super::*;

/// Latency histogram buckets, seconds.
const BUCKETS: [f64; 12] = [0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0];

#[derive(Default, Clone)]
struct Histogram {
    counts: [u64; BUCKETS.len()],
    sum: f64,
    count: u64,
}

impl Histogram {
    fn observe(&mut self, v: f64) {
        for (i, b) in BUCKETS.iter().enumerate() {
            if v <= *b {
                self.counts[i] += 1;
            }
        }
        self.sum += v;
        self.count += 1;
    }
}

/// Counters the service keeps about itself, rendered at `/metrics`.
#[derive(Default)]
pub struct Metrics {
    /// (analysis, status) → (count, total seconds).
    jobs_finished: Mutex<BTreeMap<(String, String), (u64, f64)>>,
    /// (method, route, status) → count.
    requests: Mutex<BTreeMap<(String, String, u16), u64>>,
    latency: Mutex<BTreeMap<String, Histogram>>,
    pub eigensolves: AtomicU64,
    pub block_steps: AtomicU64,
    pub solves: AtomicU64,
    pub restarts: AtomicU64,
    pub(crate) next_request: AtomicU64,
    /// Connections open now, and refused at --max-connections.
    pub connections_open: AtomicU64,
    pub connections_refused: AtomicU64,
    /// Request bodies refused (503 `memory-busy`) because the bodies in flight held their memory budget.
    pub bodies_refused: AtomicU64,
    /// Requests refused because their address failed too many API-key checks.
    pub auth_throttled: AtomicU64,
}

impl kac_engine::Metrics for Metrics {
    fn record_job(&self, analysis: &str, status: &str, seconds: f64) {
        Metrics::record_job(self, analysis, status, seconds)
    }
    fn record_solve(&self, stats: &kac_core::spectrum::Stats) {
        Metrics::record_solve(self, stats)
    }
}

impl Metrics {
    pub fn record_job(&self, analysis: &str, status: &str, seconds: f64) {
        let mut m = self.jobs_finished.lock().unwrap_or_else(|e| e.into_inner());
        let e = m.entry((analysis.to_string(), status.to_string())).or_default();
        e.0 += 1;
        e.1 += seconds;
    }
    pub fn record_solve(&self, s: &kac_core::spectrum::Stats) {
        self.eigensolves.fetch_add(1, Ordering::Relaxed);
        self.block_steps.fetch_add(s.block_steps as u64, Ordering::Relaxed);
        self.solves.fetch_add(s.solves as u64, Ordering::Relaxed);
        self.restarts.fetch_add(s.restarts as u64, Ordering::Relaxed);
    }
    pub(crate) fn record_request(&self, method: &str, route: &str, status: u16, seconds: f64) {
        *self
            .requests
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .entry((method.to_string(), route.to_string(), status))
            .or_default() += 1;
        self.latency.lock().unwrap_or_else(|e| e.into_inner()).entry(route.to_string()).or_default().observe(seconds);
    }
}

fn label(v: &str) -> String {
    v.replace('\\', "\\\\").replace('"', "\\\"").replace('\n', "\\n")
}

/// The Prometheus text exposition of the service's metrics.
pub fn render(state: &AppState) -> String {
    let m = &state.metrics;
    let mut out = String::new();
    let _ = writeln!(out, "# HELP kac_http_requests_total HTTP requests by method, route and status.");
    let _ = writeln!(out, "# TYPE kac_http_requests_total counter");
    for ((method, route, status), n) in m.requests.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        let _ = writeln!(
            out,
            "kac_http_requests_total{{method=\"{}\",route=\"{}\",status=\"{status}\"}} {n}",
            label(method),
            label(route)
        );
    }
    let _ = writeln!(out, "# HELP kac_http_request_duration_seconds Request latency by route.");
    let _ = writeln!(out, "# TYPE kac_http_request_duration_seconds histogram");
    for (route, h) in m.latency.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        let r = label(route);
        for (i, b) in BUCKETS.iter().enumerate() {
            let _ =
                writeln!(out, "kac_http_request_duration_seconds_bucket{{route=\"{r}\",le=\"{b}\"}} {}", h.counts[i]);
        }
        let _ = writeln!(out, "kac_http_request_duration_seconds_bucket{{route=\"{r}\",le=\"+Inf\"}} {}", h.count);
        let _ = writeln!(out, "kac_http_request_duration_seconds_sum{{route=\"{r}\"}} {}", h.sum);
        let _ = writeln!(out, "kac_http_request_duration_seconds_count{{route=\"{r}\"}} {}", h.count);
    }
    let _ = writeln!(out, "# HELP kac_connections_open HTTP connections open.");
    let _ = writeln!(out, "# TYPE kac_connections_open gauge");
    let _ = writeln!(out, "kac_connections_open {}", m.connections_open.load(Ordering::Relaxed));
    let _ = writeln!(out, "# HELP kac_queue_depth Jobs enqueued or processing.");
    let _ = writeln!(out, "# TYPE kac_queue_depth gauge");
    let counts = state.jobs.queue.counts().unwrap_or_default();
    let count = |s: &str| counts.iter().find(|(n, _)| n == s).map_or(0, |c| c.1);
    let _ = writeln!(out, "kac_queue_depth {}", count("enqueued") + count("processing"));
    if let Some((size, idle, waiting)) = state.shapes.pool_status() {
        let _ = writeln!(out, "# HELP kac_store_pool_connections Connections of the store's pool, by state.");
        let _ = writeln!(out, "# TYPE kac_store_pool_connections gauge");
        let _ = writeln!(out, "kac_store_pool_connections{{state=\"idle\"}} {idle}");
        let _ = writeln!(out, "kac_store_pool_connections{{state=\"in_use\"}} {}", size.saturating_sub(idle));
        let _ = writeln!(out, "# HELP kac_store_pool_waiting Callers waiting for a connection of the store's pool.");
        let _ = writeln!(out, "# TYPE kac_store_pool_waiting gauge");
        let _ = writeln!(out, "kac_store_pool_waiting {waiting}");
    }
    let _ = writeln!(out, "# HELP kac_workers_lent Idle workers lent to running jobs' spectrum slices.");
    let _ = writeln!(out, "# TYPE kac_workers_lent gauge");
    let _ = writeln!(out, "kac_workers_lent {}", state.jobs.lent());
    let _ = writeln!(out, "# HELP kac_queue_capacity Configured queue capacity.");
    let _ = writeln!(out, "# TYPE kac_queue_capacity gauge");
    let _ = writeln!(out, "kac_queue_capacity {}", state.jobs.capacity);
    let _ = writeln!(out, "# HELP kac_queue_backlog Bulk uploads' jobs waiting in the backlog lane.");
    let _ = writeln!(out, "# TYPE kac_queue_backlog gauge");
    let _ = writeln!(out, "kac_queue_backlog {}", state.jobs.backlog().unwrap_or(0));
    let mut by_status: BTreeMap<&str, u64> = BTreeMap::new();
    for s in [Status::Enqueued, Status::Processing, Status::Succeeded, Status::Failed, Status::Canceled] {
        by_status.insert(s.name(), 0);
    }
    for (name, value) in by_status.iter_mut() {
        *value = count(name) as u64;
    }
    let _ = writeln!(out, "# HELP kac_jobs Jobs known to the service by status.");
    let _ = writeln!(out, "# TYPE kac_jobs gauge");
    for (s, n) in by_status {
        let _ = writeln!(out, "kac_jobs{{status=\"{s}\"}} {n}");
    }
    let _ = writeln!(out, "# HELP kac_jobs_submitted_total Jobs accepted into the queue.");
    let _ = writeln!(out, "# TYPE kac_jobs_submitted_total counter");
    let _ = writeln!(out, "kac_jobs_submitted_total {}", state.jobs.submitted.load(Ordering::Relaxed));
    let _ = writeln!(out, "# HELP kac_job_duration_seconds Time jobs spent on a worker, by analysis and outcome.");
    let _ = writeln!(out, "# TYPE kac_job_duration_seconds summary");
    for ((a, s), (n, sum)) in m.jobs_finished.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        let _ =
            writeln!(out, "kac_job_duration_seconds_sum{{analysis=\"{}\",status=\"{}\"}} {sum}", label(a), label(s));
        let _ =
            writeln!(out, "kac_job_duration_seconds_count{{analysis=\"{}\",status=\"{}\"}} {n}", label(a), label(s));
    }
    let counters = [
        (
            "kac_eigenpair_cache_hits_total",
            "Analyses served from cached eigenpairs.",
            state.cache.hits.load(Ordering::Relaxed),
        ),
        ("kac_eigenpair_cache_misses_total", "Analyses that had to solve.", state.cache.misses.load(Ordering::Relaxed)),
        ("kac_eigensolves_total", "Eigensolver runs.", m.eigensolves.load(Ordering::Relaxed)),
        (
            "kac_connections_refused_total",
            "Connections answered 503 at --max-connections.",
            m.connections_refused.load(Ordering::Relaxed),
        ),
        (
            "kac_bodies_refused_total",
            "Request bodies answered 503 memory-busy at --max-body-memory-bytes.",
            m.bodies_refused.load(Ordering::Relaxed),
        ),
        (
            "kac_auth_throttled_total",
            "Requests refused (429) after too many failed API-key checks from their address.",
            m.auth_throttled.load(Ordering::Relaxed),
        ),
        ("kac_eigensolver_block_steps_total", "Block Lanczos expansion steps.", m.block_steps.load(Ordering::Relaxed)),
        (
            "kac_eigensolver_solves_total",
            "Right-hand sides solved with the Cholesky factor.",
            m.solves.load(Ordering::Relaxed),
        ),
        ("kac_eigensolver_restarts_total", "Thick restarts.", m.restarts.load(Ordering::Relaxed)),
    ];
    for (name, help, v) in counters {
        let _ = writeln!(out, "# HELP {name} {help}");
        let _ = writeln!(out, "# TYPE {name} counter");
        let _ = writeln!(out, "{name} {v}");
    }
    out
}
