//! Request bodies before a handler reads them: the declared length against `--max-body-bytes` (so an `Expect:
//! 100-continue` for too large a body is answered 413 at once, never `100 Continue`; without `Expect` the body
//! limit refuses it after the limit's bytes), the memory every body in
//! flight may hold together (`--max-body-memory-bytes`: beyond it 503 `memory-busy` with Retry-After), and a floor
//! on the rate a body arrives at (`--min-body-rate-bytes-per-s` after `--body-read-timeout-s` of grace), so that
//! clients trickling a byte now and then cannot hold connections for ever. No handler sees a body otherwise.
//!
//! A handler that expands a body into more memory (a bulk upload's `.zip` archives) reserves what it allocates
//! against the same budget as it allocates it ([`Reservation`]), and holds it while it holds those bytes.

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
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

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

    /// An empty reservation of this budget, to grow as memory is allocated.
    pub fn reservation(&self) -> Reservation {
        Reservation { permits: self.permits.clone(), held: None, kib: 0, budget: self.bytes }
    }
}

/// Memory a handler holds against the body budget beyond the body itself (bytes expanded from an archive):
/// grown before each allocation, never waiting (503 `memory-busy` when the budget has no room), released when
/// dropped.
pub struct Reservation {
    permits: Arc<Semaphore>,
    held: Option<OwnedSemaphorePermit>,
    /// KiB held.
    kib: usize,
    budget: usize,
}

impl Reservation {
    /// Grows the reservation to cover `bytes` in all (it never shrinks): 503 `memory-busy` when the budget has not
    /// that much room left now.
    pub fn cover(&mut self, bytes: usize) -> Result<(), ApiError> {
        let want = bytes.div_ceil(1024);
        if want <= self.kib {
            return Ok(());
        }
        let busy = || ApiError::MemoryBusy { budget: self.budget, retry_after_s: 2 };
        let more = u32::try_from(want - self.kib).map_err(|_| busy())?;
        let permit = self.permits.clone().try_acquire_many_owned(more).map_err(|_| busy())?;
        match &mut self.held {
            Some(held) => held.merge(permit),
            None => self.held = Some(permit),
        }
        self.kib = want;
        Ok(())
    }

    /// The bytes reserved (whole KiB).
    pub fn bytes(&self) -> usize {
        self.kib * 1024
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
fn guarded(body: Body, floor: f64, grace: Duration, permit: OwnedSemaphorePermit) -> Body {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reservation_grows_within_the_budget_and_is_released_when_dropped() {
        let budget = BodyBudget::new(10 * 1024);
        let mut a = budget.reservation();
        a.cover(3000).unwrap();
        a.cover(1000).unwrap();
        assert_eq!(a.bytes(), 3 * 1024);
        a.cover(6 * 1024).unwrap();
        let mut b = budget.reservation();
        assert!(matches!(b.cover(5 * 1024), Err(ApiError::MemoryBusy { budget: 10240, .. })));
        b.cover(4 * 1024).unwrap();
        assert!(b.cover(4 * 1024 + 1).is_err(), "one byte more is a KiB more");
        drop(a);
        b.cover(10 * 1024).unwrap();
        assert_eq!(budget.permits.available_permits(), 0);
        drop(b);
        assert_eq!(budget.permits.available_permits(), 10);
    }
}
