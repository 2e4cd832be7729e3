//! The rover's tilt, which levels its lidar returns and depth points: the accelerometer's
//! specific force smoothed, with the body's own acceleration taken out first where the wheels
//! tell it.
//!
//! An accelerometer reads gravity plus whatever the body accelerates by, so starting,
//! stopping and turning read as tilt: 0.5 m/s^2 forward reads as 2.9 degrees of pitch. The
//! rovers carry a yaw gyro only, so no gyro can tell tilt from acceleration; the wheels can,
//! while they grip. The speed they travel at changes by what the body accelerates along its x
//! axis, and that speed times the gyro's yaw rate is a turn's acceleration across it (the
//! centripetal `v w`). Each encoder reading carries its own noise, so the speed is read from
//! the wheels' travel over a stretch of time around the sample, where that noise averages
//! out, and a sample waits until the wheels have been heard on both sides of it. The tilt then
//! lags by half that stretch (and one wheel reading); [`crate::mapping::MappingConfig::tilt_gate`]
//! covers what a sudden tilt does meanwhile.

use realms_core::{Duration, Pose2, Time};
use realms_slam::odometry::wheel_step_bound_m;
use std::collections::VecDeque;

/// Standard gravity, m/s^2: the levelling's start, before any sample.
const GRAVITY_M_S2: f64 = 9.81;

/// Gyro rates after a gap longer than this carry the tilt no further, seconds.
const MAX_GYRO_GAP_S: f64 = 0.1;

/// A sample waits at most this many stretches for the wheels; past that they count as silent
/// and it goes into the tilt as it came.
const WAIT_FOR_WHEELS_STRETCHES: i64 = 3;

/// The rover's tilt from its accelerometer.
#[derive(Clone, Debug)]
pub struct Levelling {
    /// The share of each sample taken into the smoothed specific force (1: the newest alone).
    smoothing: f64,
    /// The gyro's roll and pitch rates carry the tilt between samples: the stamp of the last
    /// rates taken, once any (`None` inside: not yet; the outer `None`: not carried).
    carried_by_gyro: Option<Option<Time>>,
    /// The wheels' acceleration to take out of each sample, if the rover does.
    wheels: Option<WheelAcceleration>,

    /// Smoothed specific force in the body frame (gravity, once the body's acceleration is
    /// out), m/s^2.
    gravity: [f64; 3],
    /// The newest sample as it came, m/s^2.
    newest: [f64; 3],
}

/// An accelerometer sample waiting for the wheels' speed around it.
#[derive(Clone, Copy, Debug)]
struct Waiting {
    stamp: Time,
    /// Specific force, m/s^2.
    force: [f64; 3],
    /// The gyro's yaw rate then, rad/s.
    yaw_rate_rad_s: f64,
    /// The smoothed specific force then, as the gyro carried it, m/s^2.
    gravity_then: [f64; 3],
}

/// The wheels' speed through time, and the accelerometer samples waiting for it.
#[derive(Clone, Debug)]
struct WheelAcceleration {
    /// Half the stretch of time the wheels' speed is read over.
    half_stretch: Duration,
    /// The wheels' travel along the body's x axis since they were first heard, metres, at
    /// each reading, oldest first.
    travel: VecDeque<(Time, f64)>,
    last_reading: Option<(Time, Pose2)>,
    /// Samples not yet taken in.
    waiting: VecDeque<Waiting>,
    /// The wheels' speed at the last sample taken in, and its stamp.
    last_speed: Option<(Time, f64)>,
    /// The wheels' acceleration taken out of that sample, along the body's x and y, m/s^2.
    last_correction: [f64; 2],
}

impl Levelling {
    /// A levelling that takes `smoothing` of each sample into the tilt (clamped to 0..=1),
    /// first takes out the wheels' acceleration read over `wheel_stretch` around the sample,
    /// if given, and carries the tilt between samples by the gyro's roll and pitch rates if
    /// `gyro` (a complementary filter: the gyro follows a wheel climbing a rock at once, and
    /// the accelerometer, taken in a little at a time, keeps the gyro from drifting).
    pub fn new(smoothing: f64, wheel_stretch: Option<Duration>, gyro: bool) -> Self {
        Levelling {
            smoothing: smoothing.clamp(0.0, 1.0),
            carried_by_gyro: gyro.then_some(None),
            wheels: wheel_stretch.map(|stretch| WheelAcceleration {
                half_stretch: Duration(stretch.0 / 2),
                travel: VecDeque::new(),
                last_reading: None,
                waiting: VecDeque::new(),
                last_speed: None,
                last_correction: [0.0; 2],
            }),
            gravity: [0.0, 0.0, GRAVITY_M_S2],
            newest: [0.0, 0.0, GRAVITY_M_S2],
        }
    }

    /// The smoothed specific force in the body frame, m/s^2.
    pub fn gravity(&self) -> [f64; 3] {
        self.gravity
    }

    /// The newest sample, less the wheels' acceleration as last known (the sample does not
    /// wait for the wheels here: this is what tells a sudden tilt from the smoothed one),
    /// m/s^2.
    pub fn newest(&self) -> [f64; 3] {
        let [x, y, z] = self.newest;
        let [along, across] = self.wheels.as_ref().map_or([0.0; 2], |w| w.last_correction);
        [x - along, y - across, z]
    }

    /// Takes an accelerometer sample (`force`, m/s^2 in the body frame) stamped `t`, with the
    /// gyro's rates about the body's x, y and z axes then (rad/s).
    pub fn on_accel(&mut self, t: Time, force: [f64; 3], rates_rad_s: [f64; 3]) {
        self.newest = force;
        self.carry(t, rates_rad_s);
        let gravity_then = self.gravity;
        match &mut self.wheels {
            None => self.take(force, gravity_then),
            Some(w) => {
                w.waiting.push_back(Waiting {
                    stamp: t,
                    force,
                    yaw_rate_rad_s: rates_rad_s[2],
                    gravity_then,
                });
                self.take_waiting(t);
            }
        }
    }

    /// Turns the smoothed specific force by the gyro's rates since the last ones, if the
    /// gyro carries the tilt: gravity is fixed in the world, so in the body it turns against
    /// the body's turn. Rates after a silence longer than a few samples carry nothing.
    fn carry(&mut self, t: Time, [wx, wy, wz]: [f64; 3]) {
        let Some(last) = &mut self.carried_by_gyro else {
            return;
        };
        let dt = last.replace(t).map_or(0.0, |t0| (t - t0).as_secs_f64());
        if dt <= 0.0 || dt > MAX_GYRO_GAP_S {
            return;
        }
        let [gx, gy, gz] = self.gravity;
        let spin = [wy * gz - wz * gy, wz * gx - wx * gz, wx * gy - wy * gx];
        for (g, s) in self.gravity.iter_mut().zip(spin) {
            *g -= s * dt;
        }
    }

    /// Takes the wheels' odometry pose stamped `t`.
    pub fn on_wheels(&mut self, t: Time, wheel: Pose2) {
        let Some(w) = &mut self.wheels else {
            return;
        };
        let along = match w.last_reading {
            Some((t_prev, prev)) if t > t_prev => {
                let step = prev.inverse() * wheel;
                // A step no robot drives in the time is the wheels' frame jumping (a driver
                // restarted), not travel.
                let bound = wheel_step_bound_m((t - t_prev).as_secs_f64());
                if step.x_m.hypot(step.y_m) <= bound {
                    step.x_m
                } else {
                    0.0
                }
            }
            Some(_) => return,
            None => 0.0,
        };
        let travelled = w.travel.back().map_or(0.0, |&(_, s)| s) + along;
        w.travel.push_back((t, travelled));
        w.last_reading = Some((t, wheel));
        let newest_sample = w.waiting.back().map(|s| s.stamp);
        if let Some(t) = newest_sample {
            self.take_waiting(t);
        }
    }

    /// Takes in every waiting sample the wheels' speed is known around, and those that have
    /// waited too long for it, the newest sample being stamped `newest`.
    fn take_waiting(&mut self, newest: Time) {
        let Some(w) = &mut self.wheels else {
            return;
        };
        let mut taken = Vec::new();
        while let Some(&Waiting {
            stamp: t,
            force,
            yaw_rate_rad_s: yaw_rate,
            gravity_then,
        }) = w.waiting.front()
        {
            let heard_after = w
                .travel
                .back()
                .is_some_and(|&(last, _)| last >= t + w.half_stretch);
            let waited_too_long = newest.0 - t.0 > WAIT_FOR_WHEELS_STRETCHES * 2 * w.half_stretch.0;
            if !heard_after && !waited_too_long {
                break;
            }
            w.waiting.pop_front();
            let correction = match w.speed_at(t).filter(|_| heard_after) {
                Some(speed) => {
                    let along = match w.last_speed {
                        Some((t_prev, speed_prev)) if t > t_prev => {
                            (speed - speed_prev) / (t - t_prev).as_secs_f64()
                        }
                        _ => 0.0,
                    };
                    w.last_speed = Some((t, speed));
                    [along, speed * yaw_rate]
                }
                None => {
                    w.last_speed = None;
                    [0.0; 2]
                }
            };
            w.last_correction = correction;
            let less_wheels = [force[0] - correction[0], force[1] - correction[1], force[2]];
            taken.push((less_wheels, gravity_then));
        }
        // What no waiting sample needs again: the travel from before the oldest one's stretch.
        if let Some(&Waiting { stamp: t, .. }) = w.waiting.front() {
            let keep_from = t - w.half_stretch;
            while w.travel.len() > 2 && w.travel[1].0 <= keep_from {
                w.travel.pop_front();
            }
        }
        for (force, gravity_then) in taken {
            self.take(force, gravity_then);
        }
    }

    /// Takes a sample into the smoothed specific force: `smoothing` of its departure from
    /// the smoothed force as it was at the sample's time (`gravity_then`), where the gyro
    /// carries the tilt; from the smoothed force as it is, where it does not.
    fn take(&mut self, force: [f64; 3], gravity_then: [f64; 3]) {
        let k = self.smoothing;
        let reference = if self.carried_by_gyro.is_some() {
            gravity_then
        } else {
            self.gravity
        };
        for ((g, a), r) in self.gravity.iter_mut().zip(force).zip(reference) {
            *g += k * (a - r);
        }
    }

    /// The rotation that levels body-frame vectors (undoes pitch and roll, keeps yaw), from
    /// the smoothed gravity: the body's rotation is Rz(yaw) Ry(pitch) Rx(roll) (REP 103), and
    /// gravity's reaction in the body frame is the last row of Ry(pitch) Rx(roll).
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let [gx, gy, gz] = self.gravity;
        let norm = (gx * gx + gy * gy + gz * gz).sqrt().max(1e-6);
        let pitch = (-gx / norm).clamp(-1.0, 1.0).asin();
        let roll = gy.atan2(gz);
        let (sp, cp) = pitch.sin_cos();
        let (sr, cr) = roll.sin_cos();
        [
            [cp, sp * sr, sp * cr],
            [0.0, cr, -sr],
            [-sp, cp * sr, cp * cr],
        ]
    }
}

impl WheelAcceleration {
    /// The wheels' speed at `t`, m/s: their travel across the stretch around it (cut short
    /// where the readings begin), or `None` before any two readings span part of it.
    fn speed_at(&self, t: Time) -> Option<f64> {
        let first = self.travel.front()?.0;
        let from = (t - self.half_stretch).max(first);
        let to = t + self.half_stretch;
        let span = (to - from).as_secs_f64();
        if span <= 0.0 {
            return None;
        }
        Some((self.travel_at(to)? - self.travel_at(from)?) / span)
    }

    /// The wheels' travel at `t`, metres, read on the line between the readings around it.
    fn travel_at(&self, t: Time) -> Option<f64> {
        let after = self.travel.partition_point(|&(s, _)| s < t);
        let &(t1, s1) = self.travel.get(after)?;
        if t1 == t || after == 0 {
            return (t1 == t).then_some(s1);
        }
        let (t0, s0) = self.travel[after - 1];
        let share = (t - t0).as_secs_f64() / (t1 - t0).as_secs_f64();
        Some(s0 + share * (s1 - s0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STRETCH: Duration = Duration::from_millis(200);

    /// Feeds a rover driving straight along x with speed `speed(t)` (m/s), its wheels read at
    /// 20 Hz and an accelerometer at 50 Hz that feels gravity tilted by `pitch_rad` (REP 103:
    /// positive nose down) plus the body's acceleration; returns the pitch the levelling reads
    /// at the end, degrees.
    fn pitch_read(level: &mut Levelling, pitch_rad: f64, speed: impl Fn(f64) -> f64) -> f64 {
        let dt = 0.001;
        let mut x = 0.0;
        let mut steps = 0u64;
        let mut prev_speed = speed(0.0);
        let mut felt = 0.0;
        while steps <= 4000 {
            let t_s = steps as f64 * dt;
            let v = speed(t_s);
            x += v * dt;
            felt += (v - prev_speed) / dt;
            prev_speed = v;
            let t = Time::from_secs_f64(t_s);
            if steps.is_multiple_of(50) {
                level.on_wheels(t, Pose2::new(x, 0.0, 0.0));
            }
            if steps.is_multiple_of(20) {
                let along = felt / 20.0;
                felt = 0.0;
                let force = [
                    -GRAVITY_M_S2 * pitch_rad.sin() + along,
                    0.0,
                    GRAVITY_M_S2 * pitch_rad.cos(),
                ];
                level.on_accel(t, force, [0.0; 3]);
            }
            steps += 1;
        }
        let [gx, _, gz] = level.gravity();
        (-gx).atan2(gz).to_degrees()
    }

    /// Standing till 3.2 s, then speeding up at 0.5 m/s^2: 0.4 m/s at the end (4 s), and still
    /// speeding up when the levelling is read.
    fn speeding_up(t_s: f64) -> f64 {
        0.5 * (t_s - 3.2).max(0.0)
    }

    #[test]
    fn the_accelerometer_alone_reads_speeding_up_as_pitch() {
        let mut level = Levelling::new(0.2, None, false);
        let pitch = pitch_read(&mut level, 0.0, speeding_up);
        // 0.5 m/s^2 against 9.81: 2.9 degrees nose up (a negative pitch).
        assert!((pitch + 2.92).abs() < 0.05, "{pitch}");
    }

    #[test]
    fn the_wheels_acceleration_taken_out_leaves_the_true_tilt() {
        for true_pitch_deg in [0.0, 3.0f64] {
            let mut level = Levelling::new(0.2, Some(STRETCH), false);
            let pitch = pitch_read(&mut level, true_pitch_deg.to_radians(), speeding_up);
            assert!(
                (pitch - true_pitch_deg).abs() < 0.05,
                "{true_pitch_deg}: {pitch}"
            );
        }
    }

    #[test]
    fn the_newest_sample_does_not_wait_for_the_wheels() {
        // Speeding up steadily, then a wheel climbs a rock: the newest sample shows the
        // 5 degree tilt at once, less the acceleration the wheels last told of.
        let mut level = Levelling::new(0.2, Some(STRETCH), false);
        pitch_read(&mut level, 0.0, speeding_up);
        let nose_down = 5f64.to_radians();
        level.on_accel(
            Time::from_secs_f64(4.02),
            [
                -GRAVITY_M_S2 * nose_down.sin() + 0.5,
                0.0,
                GRAVITY_M_S2 * nose_down.cos(),
            ],
            [0.0; 3],
        );
        let [x, _, z] = level.newest();
        assert!(((-x).atan2(z).to_degrees() - 5.0).abs() < 0.05, "{x} {z}");
    }

    #[test]
    fn the_gyro_carries_a_sudden_tilt_that_the_slow_average_would_miss() {
        // Level for a second, then a wheel climbs a rock: 5 degrees nose down within one 20 ms
        // sample, which the gyro reads as 4.4 rad/s about y. Taking in a fiftieth of each
        // sample, the levelling has the new tilt at once with the gyro, a tenth of it without.
        let nose_down = 5f64.to_radians();
        let pitch_after_the_rock = |gyro| {
            let mut level = Levelling::new(0.02, None, gyro);
            for i in 0..=50 {
                let t = Time::from_secs_f64(i as f64 * 0.02);
                level.on_accel(t, [0.0, 0.0, GRAVITY_M_S2], [0.0; 3]);
            }
            // Nose down is a positive pitch (REP 103), and gravity's reaction then leans
            // back along the body's x axis.
            let tilted = [
                -GRAVITY_M_S2 * nose_down.sin(),
                0.0,
                GRAVITY_M_S2 * nose_down.cos(),
            ];
            let rate = nose_down / 0.02;
            level.on_accel(Time::from_secs_f64(1.02), tilted, [0.0, rate, 0.0]);
            let [gx, _, gz] = level.gravity();
            (-gx).atan2(gz).to_degrees()
        };
        let (with_gyro, without) = (pitch_after_the_rock(true), pitch_after_the_rock(false));
        assert!((with_gyro - 5.0).abs() < 0.05, "with the gyro {with_gyro}");
        assert!((without - 0.1).abs() < 0.05, "without {without}");
    }

    #[test]
    fn a_turn_is_taken_out_across() {
        // 0.3 m/s on a 0.5 rad/s arc: 0.15 m/s^2 across, 0.87 degrees of roll if left in.
        let mut level = Levelling::new(1.0, Some(STRETCH), false);
        let mut travel = 0.0;
        for i in 0..=40 {
            let t = Time::from_secs_f64(i as f64 * 0.05);
            level.on_wheels(t, Pose2::new(travel, 0.0, 0.0));
            travel += 0.3 * 0.05;
            level.on_accel(t, [0.0, 0.15, GRAVITY_M_S2], [0.0, 0.0, 0.5]);
        }
        let [_, gy, gz] = level.gravity();
        assert!(gy.atan2(gz).to_degrees().abs() < 0.01, "{gy}");
    }

    #[test]
    fn silent_wheels_leave_the_samples_as_they_came() {
        let mut level = Levelling::new(1.0, Some(STRETCH), false);
        level.on_wheels(Time::ZERO, Pose2::IDENTITY);
        let tilted = [-0.5, 0.0, GRAVITY_M_S2];
        for i in 1..=10 {
            level.on_accel(Time::from_secs_f64(i as f64 * 0.1), tilted, [0.0; 3]);
        }
        // Samples up to 0.4 s waited for wheels that never spoke again; none is lost.
        assert_eq!(level.gravity(), tilted);
    }

    #[test]
    fn a_jump_of_the_wheels_frame_is_no_travel() {
        let mut w = Levelling::new(1.0, Some(STRETCH), false);
        w.on_wheels(Time::ZERO, Pose2::IDENTITY);
        w.on_wheels(Time::from_secs_f64(0.05), Pose2::new(40.0, 0.0, 0.0));
        let wheels = w.wheels.as_ref().expect("the wheels are read");
        assert_eq!(wheels.travel.back().expect("two readings").1, 0.0);
    }
}
