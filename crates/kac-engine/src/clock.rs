//! The job engine's clock: wall time for leases (a store keeps them across restarts and replicas) and monotonic
//! time for timeouts and heartbeat intervals. The service runs on [`SystemClock`]; the engine's tests run on a
//! [`ManualClock`] they advance, so leases expire and jobs time out when a test says, not after real seconds.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

pub trait Clock: Send + Sync {
    /// Milliseconds since the Unix epoch.
    fn wall_ms(&self) -> i64;
    /// Time since the clock was made, never going back.
    fn elapsed(&self) -> Duration;
}

/// The system's clocks.
pub struct SystemClock {
    start: Instant,
}

impl Default for SystemClock {
    fn default() -> Self {
        Self { start: Instant::now() }
    }
}

impl Clock for SystemClock {
    fn wall_ms(&self) -> i64 {
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_millis() as i64)
    }
    fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}

/// A clock that moves only when told ([`ManualClock::advance`]); both its times move together.
pub struct ManualClock {
    wall_start_ms: i64,
    advanced_ms: AtomicU64,
}

impl Default for ManualClock {
    fn default() -> Self {
        Self { wall_start_ms: SystemClock::default().wall_ms(), advanced_ms: AtomicU64::new(0) }
    }
}

impl ManualClock {
    pub fn advance(&self, by: Duration) {
        self.advanced_ms.fetch_add(by.as_millis() as u64, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn wall_ms(&self) -> i64 {
        self.wall_start_ms + self.advanced_ms.load(Ordering::SeqCst) as i64
    }
    fn elapsed(&self) -> Duration {
        Duration::from_millis(self.advanced_ms.load(Ordering::SeqCst))
    }
}
