//! Request ids and one structured log line per request.

use super::*;

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
