//! Request bodies before a handler reads them: the declared length against `--max-body-bytes` (so an `Expect:
//! 100-continue` for too large a body is answered 413 at once, never `100 Continue`; without `Expect` the body
//! limit refuses it after the limit's bytes), the memory every body in
//! flight may hold together (`--max-body-memory-bytes`: beyond it 503 `memory-busy` with Retry-After), and a floor
//! on the rate a body arrives at (`--min-body-rate-bytes-per-s` after `--body-read-timeout-s` of grace), so that
//! clients trickling a byte now and then cannot hold connections for ever. No handler sees a body otherwise.

use super::error::ApiError;
use super::AppState;
use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::Response;
use futures_util::StreamExt;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::Semaphore;

/// The bytes of request bodies in flight, counted in KiB (a semaphore's permits).
pub struct BodyBudget {
    permits: Arc<Semaphore>,
    pub bytes: usize,
}

impl BodyBudget {
    pub fn new(bytes: usize) -> Self {
        let kib = bytes.div_ceil(1024).clamp(1, Semaphore::MAX_PERMITS.min(u32::MAX as usize));
        BodyBudget { permits: Arc::new(Semaphore::new(kib)), bytes }
    }
}

/// A body arrived too slowly: below the rate floor once the grace period was over.
#[derive(Debug)]
pub struct TooSlow {
    pub received: u64,
    pub seconds: f64,
    pub floor: f64,
}

impl std::fmt::Display for TooSlow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the body arrived too slowly: {} bytes in {:.1} s, below the floor of {} bytes per second \
             (--min-body-rate-bytes-per-s)",
            self.received, self.seconds, self.floor
        )
    }
}

impl std::error::Error for TooSlow {}

/// Whether an error (or one of its sources) is a body that came too slowly.
pub fn too_slow(e: &(dyn std::error::Error + 'static)) -> Option<String> {
    let mut cur = Some(e);
    while let Some(err) = cur {
        if let Some(t) = err.downcast_ref::<TooSlow>() {
            return Some(t.to_string());
        }
        cur = err.source();
    }
    None
}

fn declared_length(req: &Request) -> Option<u64> {
    req.headers().get(header::CONTENT_LENGTH)?.to_str().ok()?.trim().parse().ok()
}

/// HTTP/1.1: a request has a body when it declares a length above 0 or a transfer coding (RFC 9112 §6.3).
fn has_body(req: &Request) -> bool {
    declared_length(req).is_some_and(|n| n > 0) || req.headers().contains_key(header::TRANSFER_ENCODING)
}

/// The guard in front of every route (see the module's documentation).
pub async fn guard(State(st): State<AppState>, req: Request, next: Next) -> Result<Response, ApiError> {
    if !has_body(&req) {
        return Ok(next.run(req).await);
    }
    let limit = st.config.max_body_bytes;
    let declared = declared_length(&req);
    let expects_continue = req
        .headers()
        .get(header::EXPECT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.trim().eq_ignore_ascii_case("100-continue"));
    // A client that waits for `100 Continue` is answered before the body is polled (hyper sends no `100 Continue`
    // for a body never read), so it never sends it. One that sends at once is refused by the body limit after the
    // limit's bytes (answering before it finished writing would break its pipe, and many clients then never read
    // the answer).
    if expects_continue && declared.is_some_and(|n| n > limit as u64) {
        return Err(ApiError::BodyTooLarge { limit });
    }
    // A body of unknown length may grow to the limit: that is what it reserves (and never more than the limit,
    // which refuses the rest).
    let reserve = declared.map_or(limit, |n| (n as usize).min(limit));
    let kib = reserve.div_ceil(1024).max(1).min(u32::MAX as usize) as u32;
    let budget = &st.bodies;
    let Ok(permit) = budget.permits.clone().try_acquire_many_owned(kib) else {
        st.metrics.bodies_refused.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        return Err(ApiError::MemoryBusy { budget: budget.bytes, retry_after_s: 2 });
    };
    let floor = st.config.min_body_rate_bytes_per_s as f64;
    let grace = Duration::from_secs_f64(st.config.body_read_timeout_s);
    let (parts, body) = req.into_parts();
    // The reservation lasts while the body is being received, and is released when it ends (complete, failed,
    // cut off, or dropped unread): a handler that then waits (a synchronous analysis' `wait`) holds none of it.
    let body = guarded(body, floor, grace, permit);
    Ok(next.run(Request::from_parts(parts, body)).await)
}

/// The body as a stream that holds the memory reservation `permit` until it ends, and (with a `floor` above 0)
/// fails with [`TooSlow`] when, `grace` after it began, fewer than `floor` bytes per second of the time since have
/// arrived.
fn guarded(body: Body, floor: f64, grace: Duration, permit: tokio::sync::OwnedSemaphorePermit) -> Body {
    let start = tokio::time::Instant::now();
    let stream = body.into_data_stream();
    let state = (stream, 0u64, Some(permit));
    let s = futures_util::stream::unfold(state, move |(mut stream, received, permit)| async move {
        // Ended: the permit is gone with the state.
        permit.as_ref()?;
        // The moment by which more than `received` bytes must have come (none without a floor).
        let next = stream.next();
        let got = if floor > 0.0 {
            let due = start + grace + Duration::from_secs_f64(received as f64 / floor);
            tokio::time::timeout_at(due, next).await
        } else {
            Ok(next.await)
        };
        match got {
            Ok(Some(Ok(chunk))) => {
                let n = received + chunk.len() as u64;
                Some((Ok(chunk), (stream, n, permit)))
            }
            Ok(Some(Err(e))) => Some((Err(axum::BoxError::from(e)), (stream, received, None))),
            Ok(None) => None,
            Err(_) => {
                let seconds = Instant::now().duration_since(start.into_std()).as_secs_f64();
                Some((Err(axum::BoxError::from(TooSlow { received, seconds, floor })), (stream, received, None)))
            }
        }
    });
    Body::from_stream(s)
}
