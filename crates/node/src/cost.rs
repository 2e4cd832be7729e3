//! Measuring what a node's work costs in wall time, without letting the wall clock in.
//!
//! Nodes run on simulated time alone (DESIGN.md, "One clock, one seed"), and only the binary
//! reads the wall clock. To report what, say, SLAM costs, the binary hands a node a
//! [`CostClock`]: a way to read the wall clock that the node uses to add up durations and
//! never to decide anything. Without one (tests, replays) every duration is zero.

use std::time::{Duration, Instant};

/// The binary's wall clock, lent to a node for timing its own work.
#[derive(Clone, Copy, Default)]
pub struct CostClock(Option<fn() -> Instant>);

impl CostClock {
    /// A clock that reads the wall clock through `now` (the binary passes
    /// `std::time::Instant::now`).
    pub fn new(now: fn() -> Instant) -> Self {
        CostClock(Some(now))
    }

    /// Runs `work`, adding the wall time it took to `spent`.
    pub fn time<R>(&self, spent: &mut Duration, work: impl FnOnce() -> R) -> R {
        let Some(now) = self.0 else {
            return work();
        };
        let started = now();
        let result = work();
        *spent += now().duration_since(started);
        result
    }
}

impl std::fmt::Debug for CostClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() {
            "CostClock(wall)"
        } else {
            "CostClock(none)"
        })
    }
}

/// Every clock compares equal: which one a node was lent changes nothing it does.
impl PartialEq for CostClock {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_adds_what_the_clock_says_the_work_took() {
        // A clock that advances 3 ms at every reading, so the work takes exactly 3 ms.
        fn stepping() -> Instant {
            use std::sync::atomic::{AtomicU64, Ordering};
            static BASE: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
            static READS: AtomicU64 = AtomicU64::new(0);
            let base = *BASE.get_or_init(|| {
                #[allow(clippy::disallowed_methods)] // a fixed base for the fake clock
                Instant::now()
            });
            base + Duration::from_millis(3 * READS.fetch_add(1, Ordering::SeqCst))
        }
        let mut spent = Duration::ZERO;
        let clock = CostClock::new(stepping);
        assert_eq!(clock.time(&mut spent, || 7), 7);
        assert_eq!(spent, Duration::from_millis(3));
        let mut none = Duration::ZERO;
        CostClock::default().time(&mut none, || ());
        assert_eq!(none, Duration::ZERO);
    }
}
