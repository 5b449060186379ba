//! Operations: request ids and structured request logs, Prometheus metrics, API keys and per-key rate limits.

use super::error::ApiError;
use super::jobs::Status;
use super::AppState;
use axum::extract::{MatchedPath, Request, State};
use axum::http::{header, HeaderValue};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;
use subtle::ConstantTimeEq;

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
    pub jobs_submitted: AtomicU64,
    /// (analysis, status) → (count, total seconds).
    jobs_finished: Mutex<BTreeMap<(String, String), (u64, f64)>>,
    /// (method, route, status) → count.
    requests: Mutex<BTreeMap<(String, String, u16), u64>>,
    latency: Mutex<BTreeMap<String, Histogram>>,
    pub eigensolves: AtomicU64,
    pub block_steps: AtomicU64,
    pub solves: AtomicU64,
    pub restarts: AtomicU64,
    next_request: AtomicU64,
    /// Connections open now, and refused at --max-connections.
    pub connections_open: AtomicU64,
    pub connections_refused: AtomicU64,
    /// Requests refused because their address failed too many API-key checks.
    pub auth_throttled: AtomicU64,
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
    fn record_request(&self, method: &str, route: &str, status: u16, seconds: f64) {
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
    let _ = writeln!(out, "kac_queue_depth {}", state.jobs.active.load(Ordering::SeqCst));
    let _ = writeln!(out, "# HELP kac_queue_capacity Configured queue capacity.");
    let _ = writeln!(out, "# TYPE kac_queue_capacity gauge");
    let _ = writeln!(out, "kac_queue_capacity {}", state.jobs.capacity);
    let mut by_status: BTreeMap<&str, u64> = BTreeMap::new();
    for s in [Status::Enqueued, Status::Processing, Status::Succeeded, Status::Failed, Status::Canceled] {
        by_status.insert(s.name(), 0);
    }
    for j in state.jobs.list() {
        *by_status.entry(j.status.name()).or_default() += 1;
    }
    let _ = writeln!(out, "# HELP kac_jobs Jobs known to the service by status.");
    let _ = writeln!(out, "# TYPE kac_jobs gauge");
    for (s, n) in by_status {
        let _ = writeln!(out, "kac_jobs{{status=\"{s}\"}} {n}");
    }
    let _ = writeln!(out, "# HELP kac_jobs_submitted_total Jobs accepted into the queue.");
    let _ = writeln!(out, "# TYPE kac_jobs_submitted_total counter");
    let _ = writeln!(out, "kac_jobs_submitted_total {}", m.jobs_submitted.load(Ordering::Relaxed));
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

/// Every request: an id (`x-request-id`, taken from the request or made here), one structured log line, and
/// its route, status and latency in the metrics. Never logs headers or bodies (so never an API key).
pub async fn observe(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    let t = Instant::now();
    let id = req
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .filter(|v| v.len() <= 128 && v.bytes().all(|b| b.is_ascii_graphic()))
        .map(str::to_string)
        .unwrap_or_else(|| {
            format!("{:016x}", state.metrics.next_request.fetch_add(1, Ordering::Relaxed) ^ startup_salt())
        });
    if let Ok(v) = HeaderValue::from_str(&id) {
        req.headers_mut().insert("x-request-id", v);
    }
    let method = req.method().to_string();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|p| p.as_str().to_string())
        .unwrap_or_else(|| "unmatched".to_string());
    let mut resp = next.run(req).await;
    let status = resp.status().as_u16();
    let secs = t.elapsed().as_secs_f64();
    state.metrics.record_request(&method, &route, status, secs);
    tracing::info!(request_id = %id, method = %method, route = %route, status, ms = secs * 1e3, "request");
    if let Ok(v) = HeaderValue::from_str(&id) {
        resp.headers_mut().insert("x-request-id", v);
    }
    resp
}

fn startup_salt() -> u64 {
    static SALT: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    *SALT.get_or_init(|| {
        let t = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        t.as_nanos() as u64 ^ (std::process::id() as u64).rotate_left(32)
    })
}

/// API keys (off unless configured), compared in constant time through their SHA-256 digests, an optional
/// per-key token bucket, and a per-address count of wrong keys (guessing is throttled).
pub struct Access {
    digests: Vec<[u8; 32]>,
    per_minute: u32,
    buckets: Mutex<HashMap<usize, (f64, Instant)>>,
    failures_per_minute: u32,
    /// Client address → (wrong keys in the current minute, when that minute began).
    failures: Mutex<HashMap<std::net::IpAddr, (u32, Instant)>>,
    /// When `failures` was last swept of expired entries.
    swept: Mutex<Instant>,
}

/// The window of the wrong-key count.
const FAILURE_WINDOW: std::time::Duration = std::time::Duration::from_secs(60);

impl Access {
    pub fn new(keys: &[String], per_minute: u32, failures_per_minute: u32) -> Self {
        Access {
            digests: keys.iter().filter(|k| !k.is_empty()).map(|k| Sha256::digest(k.as_bytes()).into()).collect(),
            per_minute,
            buckets: Mutex::new(HashMap::new()),
            failures_per_minute,
            failures: Mutex::new(HashMap::new()),
            swept: Mutex::new(Instant::now()),
        }
    }
    /// Seconds until `ip` may try a key again, when it has used up its wrong keys for this minute.
    fn throttled(&self, ip: std::net::IpAddr) -> Option<u64> {
        if self.failures_per_minute == 0 {
            return None;
        }
        let f = self.failures.lock().unwrap_or_else(|e| e.into_inner());
        let &(n, since) = f.get(&ip)?;
        let left = FAILURE_WINDOW.saturating_sub(since.elapsed());
        (n >= self.failures_per_minute && !left.is_zero()).then(|| left.as_secs().max(1))
    }
    /// Counts one wrong key from `ip` (a new minute starts the count again; old entries are dropped as they go).
    fn failed(&self, ip: std::net::IpAddr) {
        if self.failures_per_minute == 0 {
            return;
        }
        let mut f = self.failures.lock().unwrap_or_else(|e| e.into_inner());
        // Expired entries go in one sweep, at most every 10 s, once the map is large (not on every failure).
        let mut sweep = self.swept.lock().unwrap_or_else(|e| e.into_inner());
        if f.len() > 100_000 && sweep.elapsed() > std::time::Duration::from_secs(10) {
            f.retain(|_, (_, since)| since.elapsed() < FAILURE_WINDOW);
            *sweep = Instant::now();
        }
        drop(sweep);
        let e = f.entry(ip).or_insert((0, Instant::now()));
        if e.1.elapsed() >= FAILURE_WINDOW {
            *e = (0, Instant::now());
        }
        e.0 = e.0.saturating_add(1);
    }
    pub fn enabled(&self) -> bool {
        !self.digests.is_empty()
    }
    /// The index of the matching key; every key is compared, so the time does not tell which one matched.
    fn find(&self, token: &str) -> Option<usize> {
        let d: [u8; 32] = Sha256::digest(token.as_bytes()).into();
        let mut found = None;
        for (i, k) in self.digests.iter().enumerate() {
            if bool::from(k.ct_eq(&d)) {
                found = Some(i);
            }
        }
        found
    }
    /// Takes a token from the key's bucket, or says how many seconds until one is there.
    fn take(&self, key: usize) -> Result<(), u64> {
        if self.per_minute == 0 {
            return Ok(());
        }
        let cap = self.per_minute as f64;
        let rate = cap / 60.0;
        let mut b = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        let now = Instant::now();
        let (tokens, last) = b.entry(key).or_insert((cap, now));
        *tokens = (*tokens + rate * now.duration_since(*last).as_secs_f64()).min(cap);
        *last = now;
        if *tokens >= 1.0 {
            *tokens -= 1.0;
            Ok(())
        } else {
            Err(((1.0 - *tokens) / rate).ceil().max(1.0) as u64)
        }
    }
}

/// Paths anyone may read: health, metrics, the API description and the problem documentation.
fn public(path: &str) -> bool {
    matches!(path, "/livez" | "/readyz" | "/metrics" | "/openapi.json")
        || path.starts_with("/docs")
        || path.starts_with("/problems/")
}

pub async fn authorize(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let access = &state.access;
    if !access.enabled() || public(req.uri().path()) {
        return next.run(req).await;
    }
    let token = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer ").or_else(|| v.strip_prefix("bearer ")))
        .map(str::trim);
    let Some(token) = token else {
        let mut r = ApiError::Unauthorized.into_response();
        r.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer realm=\"kac\""));
        return r;
    };
    let ip = super::listener::client_addr(&req).map(|a| a.ip());
    if let Some(wait) = ip.and_then(|ip| access.throttled(ip)) {
        // Checked before the key, so a guesser learns nothing more until the minute is over.
        state.metrics.auth_throttled.fetch_add(1, Ordering::Relaxed);
        return ApiError::AuthThrottled { retry_after_s: wait, per_minute: access.failures_per_minute }.into_response();
    }
    let Some(key) = access.find(token) else {
        if let Some(ip) = ip {
            access.failed(ip);
        }
        return ApiError::Forbidden.into_response();
    };
    if let Err(wait) = access.take(key) {
        return ApiError::RateLimited { retry_after_s: wait, per_minute: access.per_minute }.into_response();
    }
    next.run(req).await
}
