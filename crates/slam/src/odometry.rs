//! The motion prediction a scan match starts from, taken from wheel odometry that may stall.
//!
//! Odometry that stalls repeats its reading for a few scans while the robot moves on, then
//! jumps by all the motion at once (the MIT CSAIL log does, turning by up to 85 degrees in
//! one reading). The scans in between are matched on their own and follow the motion.
//! Applied from the last pose, the jump would count that motion a second time; it is applied
//! from the pose of the scan that first carried the repeated reading instead. Without a
//! stall that scan is the last one, and the prediction is the odometry's step from the last
//! pose, as usual.
//!
//! A rover's odometry is the wheels' translation with a gyro's heading: when the wheels fall
//! silent the heading goes on, so the reading never repeats exactly. The caller says so
//! ([`OdomSample::wheels_silent`]); the turn is then predicted from the heading alone, and the
//! wheels' travel, when they report again, from where they fell silent.

use realms_core::Pose2;
use realms_core::geometry::normalize_angle_rad;

/// Motion the scans followed while the odometry's reading stood still, beyond which the
/// reading that ends the stall is applied from where the stall began, metres ...
const STALL_FOLLOWED_M: f64 = 0.05;
/// ... or radians (2 degrees). Below both, the robot stood still: the scans' poses differ by
/// the matcher's noise alone, and the latest is as good a start as the anchor's.
const STALL_FOLLOWED_RAD: f64 = 0.035;

/// How far the wheels may move the pose from one scan's to the next, beyond which it is no
/// motion but a jump of the odometry's own frame (a driver restarted, or a corrupt
/// reading that still decoded), metres: no ground robot covers it between two scans. Only
/// the turn is predicted then, and the matcher finds the pose; taken as motion, a jump of
/// kilometres grew the map's grids past memory. [`OdomPredictor::predict_within`] takes a
/// bound from the time between the scans instead ([`wheel_step_bound_m`]).
pub const MAX_WHEEL_STEP_M: f64 = 100.0;

/// The fastest a ground robot drives, with a wide margin, metres a second ...
pub const MAX_WHEEL_SPEED_M_S: f64 = 20.0;
/// ... and the travel allowed however short the time, metres.
const MIN_WHEEL_STEP_M: f64 = 1.0;

/// The travel the wheels may report over `dt_s` seconds between two scans before it counts
/// as a jump of their frame: at most [`MAX_WHEEL_STEP_M`].
pub fn wheel_step_bound_m(dt_s: f64) -> f64 {
    (MIN_WHEEL_STEP_M + MAX_WHEEL_SPEED_M_S * dt_s.max(0.0)).min(MAX_WHEEL_STEP_M)
}

/// The odometry reading as it last changed, and the pose of the scan it first came with.
#[derive(Clone, Copy, Debug)]
struct Anchor {
    odom: Pose2,
    pose: Pose2,
    /// `odom` goes with `pose`: false when the pose was moved (a relocalisation) while the
    /// wheels were stalled or silent, so the reading is older than the pose.
    odom_matches_pose: bool,
}

/// The odometry at a scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdomSample {
    /// The odometry pose (any fixed odometry frame).
    pub pose: Pose2,
    /// The wheels have not reported for a while, so the pose's translation is stale (its
    /// heading, a gyro's, may still be live).
    pub wheels_silent: bool,
}

impl OdomSample {
    /// A reading from wheels that are reporting.
    pub fn wheels(pose: Pose2) -> Self {
        OdomSample {
            pose,
            wheels_silent: false,
        }
    }
}

/// Where the next scan is predicted from.
#[derive(Clone, Copy, Debug, Default)]
pub struct OdomPredictor {
    anchor: Option<Anchor>,
    /// The last scan's odometry pose.
    last_odom: Option<Pose2>,
}

/// The prediction for one scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prediction {
    /// The wheels' motion over this scan's interval alone, from the last pose (robot frame).
    pub step: Pose2,
    /// The predicted pose.
    pub pose: Pose2,
    /// The wheels said nothing new: a repeated reading, or wheels the caller called silent.
    pub stalled: bool,
}

impl OdomPredictor {
    /// The pose of a scan with odometry `sample`, the last scan's pose being `last`. `scale`
    /// corrects the wheels' motion (e.g. for slip). The first scan is predicted at the
    /// odometry's pose.
    pub fn predict(
        &self,
        sample: OdomSample,
        last: Pose2,
        scale: impl Fn(Pose2) -> Pose2,
    ) -> Prediction {
        self.predict_within(sample, last, MAX_WHEEL_STEP_M, scale)
    }

    /// [`predict`](Self::predict), taking wheels that would move the pose more than
    /// `max_step_m` from the last scan's as a jump of their frame.
    pub fn predict_within(
        &self,
        sample: OdomSample,
        last: Pose2,
        max_step_m: f64,
        scale: impl Fn(Pose2) -> Pose2,
    ) -> Prediction {
        let odom = sample.pose;
        let Some(a) = self.anchor else {
            return Prediction {
                step: Pose2::IDENTITY,
                pose: odom,
                stalled: false,
            };
        };
        if sample.wheels_silent || a.odom == odom {
            // No news from the wheels: only the heading's turn since the last scan (none
            // for a repeated reading); the matcher follows the rest.
            return self.turn_only(odom, last, true);
        }
        if !a.odom_matches_pose {
            // The pose was put where the robot is while the wheels said nothing: their
            // travel since then is unknown, and only the turn is predicted.
            return self.turn_only(odom, last, false);
        }
        let since = a.odom.inverse() * odom;
        let followed = a.pose.inverse() * last;
        let stood_still = followed.x_m.hypot(followed.y_m) < STALL_FOLLOWED_M
            && followed.yaw_rad.abs() < STALL_FOLLOWED_RAD;
        let (step, pose) = if stood_still {
            (since, last * scale(since))
        } else {
            (last.inverse() * (a.pose * since), a.pose * scale(since))
        };
        if pose.position().distance_m(last.position()) > max_step_m {
            return self.turn_only(odom, last, false);
        }
        Prediction {
            step,
            pose,
            stalled: false,
        }
    }

    /// `last` turned by the odometry's heading change since the last scan, with no travel.
    fn turn_only(&self, odom: Pose2, last: Pose2, stalled: bool) -> Prediction {
        let turned = self
            .last_odom
            .map_or(0.0, |l| normalize_angle_rad(odom.yaw_rad - l.yaw_rad));
        let step = Pose2::new(0.0, 0.0, turned);
        Prediction {
            step,
            pose: last * step,
            stalled,
        }
    }

    /// Records where the scan of `prediction` ended up. The anchor moves to it unless the
    /// odometry stalled; `moved_off_track` (a relocalisation) moves it regardless, since the
    /// pose then no longer follows the wheels.
    pub fn settle(
        &mut self,
        odom: Pose2,
        pose: Pose2,
        prediction: &Prediction,
        moved_off_track: bool,
    ) {
        if !prediction.stalled || moved_off_track {
            self.anchor = Some(Anchor {
                odom,
                pose,
                odom_matches_pose: !(prediction.stalled && moved_off_track),
            });
        }
        self.last_odom = Some(odom);
    }

    /// The map's frame moved by `correction` (an optimisation): the anchor moves with it.
    pub fn shift(&mut self, correction: Pose2) {
        if let Some(a) = &mut self.anchor {
            a.pose = correction * a.pose;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Pose2, b: Pose2) -> bool {
        let d = a.relative_to(&b);
        d.x_m.hypot(d.y_m) < 1e-9 && d.yaw_rad.abs() < 1e-9
    }

    #[test]
    fn without_a_stall_the_prediction_is_the_odometrys_step_from_the_last_pose() {
        let mut p = OdomPredictor::default();
        let odom0 = Pose2::new(5.0, 1.0, 0.3);
        let first = p.predict(OdomSample::wheels(odom0), Pose2::IDENTITY, |d| d);
        assert!(close(first.pose, odom0));
        let matched = Pose2::new(0.1, 0.0, 0.01);
        p.settle(odom0, matched, &first, false);
        let odom1 = odom0 * Pose2::new(0.2, 0.01, 0.05);
        let next = p.predict(OdomSample::wheels(odom1), matched, |d| d);
        assert!(close(next.step, Pose2::new(0.2, 0.01, 0.05)));
        assert!(close(next.pose, matched * Pose2::new(0.2, 0.01, 0.05)));
        assert!(!next.stalled);
    }

    #[test]
    fn a_jump_of_the_odometry_frame_is_no_motion() {
        let mut p = OdomPredictor::default();
        let odom0 = Pose2::new(5.0, 1.0, 0.3);
        let first = p.predict(OdomSample::wheels(odom0), Pose2::IDENTITY, |d| d);
        let matched = Pose2::new(0.1, 0.0, 0.3);
        p.settle(odom0, matched, &first, false);
        // 1e5 m in one step, turning 0.05 rad: only the turn is predicted ...
        let jumped = Pose2::new(1e5, -3.0, 0.35);
        let next = p.predict(OdomSample::wheels(jumped), matched, |d| d);
        assert!(
            close(next.pose, Pose2::new(0.1, 0.0, 0.35)),
            "{:?}",
            next.pose
        );
        // ... and the wheels' steps from the new frame on are motion again.
        p.settle(jumped, next.pose, &next, false);
        let on = jumped * Pose2::new(0.2, 0.0, 0.0);
        let after = p.predict(OdomSample::wheels(on), next.pose, |d| d);
        assert!(
            close(after.pose, next.pose * Pose2::new(0.2, 0.0, 0.0)),
            "{:?}",
            after.pose
        );
    }

    #[test]
    fn a_stall_the_scans_followed_is_counted_once() {
        // The robot drives 0.2 m and turns 0.1 rad a scan; the odometry repeats its reading
        // for three scans, then jumps by all four steps.
        let step = Pose2::new(0.2, 0.0, 0.1);
        let mut p = OdomPredictor::default();
        let odom0 = Pose2::IDENTITY;
        let mut truth = Pose2::IDENTITY;
        let first = p.predict(OdomSample::wheels(odom0), truth, |d| d);
        p.settle(odom0, truth, &first, false);
        for _ in 0..3 {
            let pred = p.predict(OdomSample::wheels(odom0), truth, |d| d);
            assert!(pred.stalled && close(pred.step, Pose2::IDENTITY));
            assert!(close(pred.pose, truth), "{:?}", pred.pose);
            truth = truth * step;
            // The matcher follows the motion.
            p.settle(odom0, truth, &pred, false);
        }
        let odom4 = step * step * step * step;
        let pred = p.predict(OdomSample::wheels(odom4), truth, |d| d);
        assert!(close(pred.pose, truth * step), "{:?}", pred.pose);
        assert!(close(pred.step, step), "{:?}", pred.step);
    }

    #[test]
    fn a_robot_that_stood_still_is_predicted_from_its_last_pose() {
        let mut p = OdomPredictor::default();
        let odom = Pose2::new(1.0, 2.0, 0.5);
        let first = p.predict(OdomSample::wheels(odom), Pose2::IDENTITY, |d| d);
        p.settle(odom, Pose2::IDENTITY, &first, false);
        // Matcher noise while parked: 1 cm.
        let parked = Pose2::new(0.01, 0.0, 0.0);
        let pred = p.predict(OdomSample::wheels(odom), parked, |d| d);
        p.settle(odom, parked, &pred, false);
        let moved = odom * Pose2::new(0.3, 0.0, 0.0);
        let pred = p.predict(OdomSample::wheels(moved), parked, |d| d);
        assert!(close(pred.pose, parked * Pose2::new(0.3, 0.0, 0.0)));
    }

    #[test]
    fn silent_wheels_under_a_live_gyro_predict_the_turn_and_apply_their_travel_once() {
        // A rover drives 0.2 m and turns 0.1 rad a scan. Its wheels fall silent for three
        // scans: the odometry's translation stands still while the gyro's heading goes on.
        let step = Pose2::new(0.2, 0.0, 0.1);
        let mut p = OdomPredictor::default();
        let mut truth = Pose2::IDENTITY;
        let first = p.predict(OdomSample::wheels(truth), truth, |d| d);
        p.settle(truth, truth, &first, false);
        let silent_at = truth;
        for k in 1..=3 {
            let heading = Pose2::new(silent_at.x_m, silent_at.y_m, 0.1 * k as f64);
            let sample = OdomSample {
                pose: heading,
                wheels_silent: true,
            };
            let pred = p.predict(sample, truth, |d| d);
            assert!(pred.stalled);
            // The gyro's turn, and no travel.
            assert!(
                close(pred.pose, truth * Pose2::new(0.0, 0.0, 0.1)),
                "{:?}",
                pred.pose
            );
            truth = truth * step;
            p.settle(heading, truth, &pred, false);
        }
        // The wheels report again, with all four steps' travel.
        let back = step * step * step * step;
        let pred = p.predict(OdomSample::wheels(back), truth, |d| d);
        assert!(close(pred.pose, truth * step), "{:?}", pred.pose);
    }

    #[test]
    fn the_anchor_moves_with_the_map_and_after_a_relocalisation() {
        let step = Pose2::new(0.2, 0.0, 0.0);
        let mut p = OdomPredictor::default();
        let odom0 = Pose2::IDENTITY;
        let first = p.predict(OdomSample::wheels(odom0), Pose2::IDENTITY, |d| d);
        p.settle(odom0, Pose2::IDENTITY, &first, false);
        let stalled = p.predict(OdomSample::wheels(odom0), Pose2::IDENTITY, |d| d);
        p.settle(odom0, step, &stalled, false);
        // An optimisation moves the map (and the last pose) by 1 m in y.
        let correction = Pose2::new(0.0, 1.0, 0.0);
        p.shift(correction);
        let last = correction * step;
        let pred = p.predict(OdomSample::wheels(step * step), last, |d| d);
        assert!(close(pred.pose, last * step), "{:?}", pred.pose);
        // A relocalisation during a stall puts the pose where the robot is, but the wheels'
        // travel since the stall began is partly before it: none of it is applied, and the
        // wheels' steps count again from the next reading.
        let mut p = OdomPredictor::default();
        let first = p.predict(OdomSample::wheels(odom0), Pose2::IDENTITY, |d| d);
        p.settle(odom0, Pose2::IDENTITY, &first, false);
        let stalled = p.predict(OdomSample::wheels(odom0), Pose2::IDENTITY, |d| d);
        let relocalised = Pose2::new(3.0, 0.0, 0.0);
        p.settle(odom0, relocalised, &stalled, true);
        let pred = p.predict(OdomSample::wheels(step), relocalised, |d| d);
        assert!(close(pred.pose, relocalised), "{:?}", pred.pose);
        assert!(!pred.stalled);
        p.settle(step, relocalised, &pred, false);
        let next = p.predict(OdomSample::wheels(step * step), relocalised, |d| d);
        assert!(close(next.pose, relocalised * step), "{:?}", next.pose);
    }
}
