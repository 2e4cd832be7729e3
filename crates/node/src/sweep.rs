//! Taking the rover's motion out of a sweeping lidar's scan ("de-skewing"). A spinning 2D
//! lidar measures its beams one after another over the scan (0.1 s at 10 Hz), so a rover that
//! drives or turns meanwhile sees the world from a slightly different pose at each beam: at
//! 1 rad/s the scan's end is turned 5.7 degrees from its start, and a wall 10 m away lands a
//! metre off. Each beam is brought into the frame of the scan's last beam by the motion the
//! wheels (translation) and the gyro (heading) measured between the two instants, as
//! Cartographer and LIO-style systems do with their per-point times (Hess, Kohler, Rapp &
//! Andor, "Real-Time Loop Closure in 2D LIDAR SLAM", ICRA 2016, section IV).

use realms_core::{Duration, Point2, Pose2, Time};
use std::collections::VecDeque;

/// How much recent motion is kept: a few scans' worth.
const KEPT: Duration = Duration::from_millis(500);
/// The furthest a heading or position is carried on past its newest sample, at its latest
/// rate (a scan can arrive just before the IMU sample of its own instant).
const EXTRAPOLATION: Duration = Duration::from_millis(50);

/// The rover's recent motion, as its wheels (positions) and gyro (headings) report it.
#[derive(Clone, Debug, Default)]
pub struct RecentMotion {
    positions: VecDeque<(Time, Pose2)>,
    headings: VecDeque<(Time, f64)>,
}

impl RecentMotion {
    /// Takes the odometry pose at `t` (its translation is used).
    pub fn push_position(&mut self, t: Time, pose: Pose2) {
        push(&mut self.positions, t, pose);
    }

    /// Takes the gyro's integrated heading at `t`, radians (unwrapped).
    pub fn push_heading(&mut self, t: Time, yaw_rad: f64) {
        push(&mut self.headings, t, yaw_rad);
    }

    /// Where the rover was at `at`, in its frame at `reference`; `None` without the wheels'
    /// positions at both. Without the gyro, the heading is the wheels'.
    pub fn motion(&self, at: Time, reference: Time) -> Option<Pose2> {
        let (a, r) = (self.pose_at(at)?, self.pose_at(reference)?);
        Some(r.inverse() * a)
    }

    fn pose_at(&self, t: Time) -> Option<Pose2> {
        let p = sample_at(&self.positions, t, |a, b, s| a.interpolate(b, s))?;
        let yaw = sample_at(&self.headings, t, |a, b, s| a + s * (b - a)).unwrap_or(p.yaw_rad);
        Some(Pose2::new(p.x_m, p.y_m, yaw))
    }
}

fn push<T>(samples: &mut VecDeque<(Time, T)>, t: Time, value: T) {
    if samples.back().is_some_and(|(last, _)| t <= *last) {
        // Out of order or repeated: the history keeps time order.
        return;
    }
    samples.push_back((t, value));
    while samples.len() > 2 && samples[1].0 < t - KEPT {
        samples.pop_front();
    }
}

/// The value at `t`: between the samples around it, on the line through the newest two (for
/// at most [`EXTRAPOLATION`]) after the newest, and the oldest's before the oldest.
fn sample_at<T: Copy>(
    samples: &VecDeque<(Time, T)>,
    t: Time,
    lerp: impl Fn(&T, &T, f64) -> T,
) -> Option<T> {
    let n = samples.len();
    let &(t_first, first) = samples.front()?;
    if n == 1 || t <= t_first {
        return Some(first);
    }
    // The first sample after t, or the newest when none is (then read beyond it).
    let after = samples.partition_point(|(ts, _)| *ts <= t).min(n - 1);
    let ((t0, v0), (t1, v1)) = (samples[after - 1], samples[after]);
    let span = (t1 - t0).as_secs_f64();
    let ahead = (t - t0).min(t1 - t0 + EXTRAPOLATION).as_secs_f64();
    Some(lerp(&v0, &v1, ahead / span))
}

/// A scan's points, each measured `offsets[i]` after the scan's stamp, brought into the frame
/// of the rover at `reference` (the last beam's time); left as they are where the motion is
/// not known.
pub fn deskew(
    motion: &RecentMotion,
    stamp: Time,
    reference: Time,
    points: &mut [Point2],
    offsets: &[Duration],
) {
    // Where the rover was at the reference, once for the whole scan.
    let Some(to_reference) = motion.pose_at(reference).map(|r| r.inverse()) else {
        return;
    };
    for (p, offset) in points.iter_mut().zip(offsets) {
        if let Some(at) = motion.pose_at(stamp + *offset) {
            *p = (to_reference * at).transform_point(*p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    /// A rover turning on the spot at `rate` rad/s and driving at `speed` m/s, sampled as
    /// the wheels (20 Hz) and gyro (50 Hz) report it.
    fn driving(speed: f64, rate: f64, until_s: f64) -> RecentMotion {
        let mut m = RecentMotion::default();
        let pose = |s: f64| {
            // Along an arc: the exact pose at time s.
            let yaw = rate * s;
            let (x, y) = if rate == 0.0 {
                (speed * s, 0.0)
            } else {
                (speed / rate * yaw.sin(), speed / rate * (1.0 - yaw.cos()))
            };
            Pose2::new(x, y, yaw)
        };
        let mut k = 0;
        while k as f64 * 0.02 <= until_s {
            let s = k as f64 * 0.02;
            m.push_heading(t(s), pose(s).yaw_rad);
            if k % 5 == 0 {
                m.push_position(t(s), pose(s));
            }
            k += 1;
        }
        m
    }

    #[test]
    fn a_point_seen_while_turning_is_brought_to_where_the_last_beam_saw_it() {
        // Turning in place at 1 rad/s: a point seen straight ahead 0.1 s before the
        // reference lies 0.1 rad to the right of ahead, seen from the reference.
        let m = driving(0.0, 1.0, 1.2);
        let mut points = [Point2::new(10.0, 0.0)];
        deskew(&m, t(1.0), t(1.1), &mut points, &[Duration::ZERO]);
        let p = points[0];
        assert!((p.y_m.atan2(p.x_m) + 0.1).abs() < 1e-9, "{p:?}");
        assert!((p.x_m.hypot(p.y_m) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn a_point_seen_while_driving_is_moved_back_by_the_travel_since() {
        // 0.4 m/s straight: 0.1 s before the reference the rover was 4 cm behind.
        let m = driving(0.4, 0.0, 1.2);
        let mut points = [Point2::new(5.0, 1.0), Point2::new(5.0, 1.0)];
        deskew(
            &m,
            t(1.0),
            t(1.1),
            &mut points,
            &[Duration::ZERO, Duration::from_millis(100)],
        );
        assert!((points[0].x_m - 4.96).abs() < 1e-9, "{:?}", points[0]);
        assert!((points[0].y_m - 1.0).abs() < 1e-9);
        assert_eq!(
            points[1],
            Point2::new(5.0, 1.0),
            "the last beam is the reference"
        );
    }

    #[test]
    fn between_samples_and_just_past_the_newest_the_motion_is_read_on_their_line() {
        // Headings at 50 Hz, positions at 20 Hz, read at instants between them and 10 ms
        // past the newest sample (2.0 s), on an arc at 0.3 m/s and 0.5 rad/s.
        let m = driving(0.3, 0.5, 2.0);
        let moved = m.motion(t(1.913), t(2.01)).expect("known");
        assert!((moved.yaw_rad + 0.5 * 0.097).abs() < 1e-9, "{moved:?}");
        // The chord of the arc between the instants, to the interpolation's precision.
        assert!((moved.x_m + 0.3 * 0.097).abs() < 1e-3, "{moved:?}");
    }

    #[test]
    fn without_the_wheels_nothing_is_moved_and_stale_motion_is_forgotten() {
        let mut m = RecentMotion::default();
        m.push_heading(t(0.0), 0.0);
        m.push_heading(t(0.1), 0.1);
        let mut points = [Point2::new(1.0, 0.0)];
        deskew(&m, t(0.0), t(0.1), &mut points, &[Duration::ZERO]);
        assert_eq!(points[0], Point2::new(1.0, 0.0));
        // Samples older than what is kept are dropped, two at least always stay.
        let m = driving(0.4, 0.0, 5.0);
        assert!(m.positions.len() <= 12 && m.positions.len() >= 2);
        assert!(m.headings.front().expect("kept").0 >= t(4.45));
    }
}
