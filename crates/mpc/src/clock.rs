//! The clock the MPC reads its time budget from, injected so that tests and simulations can
//! run on simulated time.

use std::time::Instant;

/// A monotonic clock in seconds.
pub trait Clock {
    /// Seconds since an arbitrary, fixed origin.
    fn now(&self) -> f64;
}

/// Wall-clock time (`std::time::Instant`).
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: Instant,
}

impl MonotonicClock {
    #[must_use]
    pub fn new() -> Self {
        Self {
            origin: Instant::now(),
        }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now(&self) -> f64 {
        self.origin.elapsed().as_secs_f64()
    }
}

/// A clock that only moves when told to: each reading advances it by a fixed tick, so a
/// time budget counts clock readings instead of seconds (deterministic tests).
#[derive(Debug)]
pub struct TickClock {
    t: std::sync::atomic::AtomicU64,
    tick_ns: u64,
}

impl TickClock {
    #[must_use]
    pub fn new(tick: f64) -> Self {
        Self {
            t: std::sync::atomic::AtomicU64::new(0),
            tick_ns: (tick * 1e9) as u64,
        }
    }
}

impl Clock for TickClock {
    fn now(&self) -> f64 {
        let t = self
            .t
            .fetch_add(self.tick_ns, std::sync::atomic::Ordering::Relaxed);
        t as f64 * 1e-9
    }
}
