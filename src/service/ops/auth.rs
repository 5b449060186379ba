//! API keys compared in constant time, per-key token buckets, and the per-address throttle of wrong keys.

use super::*;

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

/// Paths anyone may read: health, metrics, the API description, the problem documentation and the viewer's
/// files (the viewer asks for the key and sends it with its API calls).
fn public(path: &str) -> bool {
    matches!(path, "/" | "/livez" | "/readyz" | "/metrics" | "/openapi.json")
        || path.starts_with("/docs")
        || path.starts_with("/problems/")
        || path.starts_with("/viewer/")
}

/// The token of an `Authorization: Bearer TOKEN` header; the scheme is case-insensitive (RFC 9110 §11.1), and
/// any amount of spaces may separate it from the token.
pub(crate) fn bearer_token(header: &str) -> Option<&str> {
    let header = header.trim();
    let (scheme, token) = header.split_once([' ', '\t'])?;
    let token = token.trim();
    (scheme.eq_ignore_ascii_case("bearer") && !token.is_empty()).then_some(token)
}

pub async fn authorize(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let access = &state.access;
    if !access.enabled() || public(req.uri().path()) {
        return next.run(req).await;
    }
    let token = req.headers().get(header::AUTHORIZATION).and_then(|v| v.to_str().ok()).and_then(bearer_token);
    let Some(token) = token else {
        let mut r = ApiError::Unauthorized.into_response();
        r.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer realm=\"kac\""));
        return r;
    };
    let ip = crate::service::listener::client_addr(&req).map(|a| a.ip());
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
    let mut r = next.run(req).await;
    // An answer given for a key is the key holder's: shared caches must not keep it for others.
    let public_cache =
        r.headers().get(header::CACHE_CONTROL).and_then(|v| v.to_str().ok()).is_some_and(|v| v.contains("public"));
    if public_cache {
        r.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("private, max-age=31536000, immutable"));
    }
    r
}

#[cfg(test)]
mod tests {
    use super::bearer_token;

    #[test]
    fn the_bearer_scheme_is_case_insensitive_and_the_token_exact() {
        for h in ["Bearer k", "bearer k", "BEARER k", "bEaReR  k ", "Bearer\tk"] {
            assert_eq!(bearer_token(h), Some("k"), "{h}");
        }
        for h in ["Basic k", "Bearer", "Bearer ", "Bearerk", "k", ""] {
            assert_eq!(bearer_token(h), None, "{h}");
        }
    }
}
