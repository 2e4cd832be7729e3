//! Mission time: integer nanoseconds since mission start, so every clock comparison is exact
//! and runs reproduce bit for bit. Floating-point seconds exist only at the edges (config, plots).
//!
//! The arithmetic saturates at the clock's ends instead of overflowing: a stamp comes from
//! outside (a driver, the network, a file), and a corrupt one still decodes to any instant
//! the clock holds, its first and last nanosecond among them. Every time within centuries of
//! mission start computes exactly as plain arithmetic would.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::ops::{Add, AddAssign, Sub};

/// A point on the mission clock, in nanoseconds since mission start.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Time(pub i64);

/// A signed span of mission time in nanoseconds.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Duration(pub i64);

const NS_PER_S: i64 = 1_000_000_000;

impl Time {
    /// Mission start.
    pub const ZERO: Time = Time(0);

    /// Time from whole nanoseconds.
    pub const fn from_ns(ns: i64) -> Self {
        Time(ns)
    }

    /// Time from seconds, rounded to the nearest nanosecond.
    pub fn from_secs_f64(secs: f64) -> Self {
        Time((secs * NS_PER_S as f64).round() as i64)
    }

    /// Nanoseconds since mission start.
    pub const fn as_ns(self) -> i64 {
        self.0
    }

    /// Seconds since mission start (for display and physics, never for ordering).
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 / NS_PER_S as f64
    }

    /// Time elapsed since `earlier` (negative if `earlier` is later).
    pub fn since(self, earlier: Time) -> Duration {
        Duration(self.0.saturating_sub(earlier.0))
    }
}

impl Duration {
    /// No time at all.
    pub const ZERO: Duration = Duration(0);

    /// A duration of whole nanoseconds.
    pub const fn from_ns(ns: i64) -> Self {
        Duration(ns)
    }

    /// A duration of whole milliseconds.
    pub const fn from_millis(ms: i64) -> Self {
        Duration(ms.saturating_mul(1_000_000))
    }

    /// A duration of whole seconds.
    pub const fn from_secs(s: i64) -> Self {
        Duration(s.saturating_mul(NS_PER_S))
    }

    /// A duration from seconds, rounded to the nearest nanosecond.
    pub fn from_secs_f64(secs: f64) -> Self {
        Duration((secs * NS_PER_S as f64).round() as i64)
    }

    /// A period of `hz` events per second, rounded to the nearest nanosecond.
    pub fn from_rate_hz(hz: f64) -> Self {
        Duration::from_secs_f64(1.0 / hz)
    }

    /// Length in nanoseconds.
    pub const fn as_ns(self) -> i64 {
        self.0
    }

    /// Length in seconds.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 / NS_PER_S as f64
    }
}

impl Add<Duration> for Time {
    type Output = Time;
    fn add(self, rhs: Duration) -> Time {
        Time(self.0.saturating_add(rhs.0))
    }
}

impl AddAssign<Duration> for Time {
    fn add_assign(&mut self, rhs: Duration) {
        self.0 = self.0.saturating_add(rhs.0);
    }
}

impl Sub<Duration> for Time {
    type Output = Time;
    fn sub(self, rhs: Duration) -> Time {
        Time(self.0.saturating_sub(rhs.0))
    }
}

impl Sub for Time {
    type Output = Duration;
    fn sub(self, rhs: Time) -> Duration {
        self.since(rhs)
    }
}

impl Add for Duration {
    type Output = Duration;
    fn add(self, rhs: Duration) -> Duration {
        Duration(self.0.saturating_add(rhs.0))
    }
}

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.3}s", self.as_secs_f64())
    }
}

impl fmt::Display for Duration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.3}s", self.as_secs_f64())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_round_trip_to_the_nanosecond() {
        let t = Time::from_secs_f64(12.345_678_901);
        assert_eq!(t.as_ns(), 12_345_678_901);
        assert_eq!(Duration::from_rate_hz(10.0), Duration::from_millis(100));
        assert_eq!((t + Duration::from_secs(1)) - t, Duration::from_secs(1));
    }

    #[test]
    fn arithmetic_stops_at_the_clocks_ends() {
        let (first, last) = (Time(i64::MIN), Time(i64::MAX));
        assert_eq!(last - first, Duration(i64::MAX));
        assert_eq!(first - last, Duration(i64::MIN));
        assert_eq!(first.since(Time(1)), Duration(i64::MIN));
        assert_eq!(last + Duration::from_secs(1), last);
        assert_eq!(first - Duration::from_secs(1), first);
        let mut t = last;
        t += Duration(1);
        assert_eq!(t, last);
        assert_eq!(Duration(i64::MAX) + Duration(1), Duration(i64::MAX));
        assert_eq!(Duration::from_secs(i64::MAX / 2), Duration(i64::MAX));
        assert_eq!(Duration::from_millis(i64::MIN / 2), Duration(i64::MIN));
        // Within the clock's reach nothing changes.
        assert_eq!(Time(-5) - Time(7), Duration(-12));
        assert_eq!(Time(i64::MAX - 3) - Duration(4), Time(i64::MAX - 7));
    }
}
