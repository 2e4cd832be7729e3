//! Online calibration of how far the wheels over-report: the share of the wheels' travel the
//! ground really moved, learnt from scan matches that pin the travel down.
//!
//! Wheels on loose regolith slip a few to twenty per cent, and the share changes slowly with
//! the soil and the slope. Where the lidar sees little (the open middle of a large hall) the
//! scan matcher leans on the odometry's prediction, and an uncorrected 10 % over-report is
//! 10 cm per metre of drift. This keeps the ratio of scan-matched to wheel travel over the
//! last few metres driven where the matches were well constrained along the direction of
//! travel, and scales the prediction by it. It is the on-line counterpart of calibrating
//! odometry against scan matching (Censi, Franchi, Marchionni & Oriolo, "Simultaneous
//! Calibration of Odometry and Sensor Parameters for Mobile Robots", IEEE T-RO 2013), reduced
//! to the one parameter that changes along the way. A median over segments, not a running
//! mean, so a slip burst's few seconds do not drag it.

use realms_core::Pose2;
use std::collections::VecDeque;

/// How the wheel scale is learnt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlipCalibration {
    /// A segment ends at the first well-constrained match once the wheels have driven this
    /// far since the segment's start, metres.
    pub segment_m: f64,
    /// Segments longer than this (the matches in between were not trusted) are dropped:
    /// their start may lie in an older frame, metres.
    pub max_segment_m: f64,
    /// Segments that turned more than this are dropped: skid-steer wheels slip differently
    /// in turns, radians.
    pub max_segment_turn_rad: f64,
    /// The scale is the median of this many recent segments ...
    pub segments: usize,
    /// ... and applies once at least this many are in.
    pub min_segments: usize,
    /// A match is trusted along the travel only if the map's information there is at least
    /// this many times the odometry prior's (the prior then moves it at most 1 / (1 + this)
    /// of the way towards the prediction).
    pub min_information_ratio: f64,
    /// The scale is kept within these bounds: wheels never under-report much, and a scale
    /// near zero would stop dead reckoning altogether.
    pub min_scale: f64,
    /// Upper bound of the scale.
    pub max_scale: f64,
    /// The scale until enough segments are in: 1 takes the wheels at their word; a scale
    /// measured on the same ground beforehand (a calibration drive) spares the first metres
    /// the wheels' over-report, where the map is young and may pin the travel weakly.
    pub initial_scale: f64,
}

impl Default for SlipCalibration {
    fn default() -> Self {
        SlipCalibration {
            segment_m: 0.3,
            max_segment_m: 1.2,
            max_segment_turn_rad: 0.35,
            segments: 15,
            min_segments: 5,
            min_information_ratio: 10.0,
            min_scale: 0.6,
            max_scale: 1.05,
            initial_scale: 1.0,
        }
    }
}

/// The learnt share of the wheels' travel that is real motion.
#[derive(Clone, Debug)]
pub struct WheelScale {
    cfg: SlipCalibration,
    /// Where the current segment started: the wheel odometry pose and the matched pose.
    anchor: Option<(Pose2, Pose2)>,
    ratios: VecDeque<f64>,
    scale: f64,
}

impl WheelScale {
    /// No segments yet: the wheels are taken at the configured initial scale.
    pub fn new(cfg: SlipCalibration) -> Self {
        WheelScale {
            cfg,
            anchor: None,
            ratios: VecDeque::with_capacity(cfg.segments),
            scale: cfg.initial_scale,
        }
    }

    /// The factor for the wheels' translation.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// The wheels' relative motion `odom_delta` with its translation scaled.
    pub fn apply(&self, odom_delta: Pose2) -> Pose2 {
        Pose2::new(
            odom_delta.x_m * self.scale,
            odom_delta.y_m * self.scale,
            odom_delta.yaw_rad,
        )
    }

    /// The pose estimate jumped (an optimisation, a relocalisation) or is not to be trusted
    /// (lost, odometry unreliable): the current segment is abandoned.
    pub fn restart(&mut self) {
        self.anchor = None;
    }

    /// A scan was matched to `pose` with wheel odometry at `odom`; `trusted` says whether the
    /// match is well constrained along the travel (see [`Self::trusted`]).
    pub fn observe(&mut self, odom: Pose2, pose: Pose2, trusted: bool) {
        if !trusted {
            return;
        }
        let Some((odom0, pose0)) = self.anchor else {
            self.anchor = Some((odom, pose));
            return;
        };
        let wheels = odom0.inverse() * odom;
        let wheel_m = wheels.x_m.hypot(wheels.y_m);
        if wheel_m < self.cfg.segment_m {
            return;
        }
        self.anchor = Some((odom, pose));
        if wheel_m > self.cfg.max_segment_m || wheels.yaw_rad.abs() > self.cfg.max_segment_turn_rad
        {
            return;
        }
        // Both motions are in the robot's frame at the segment's start; the matched one is
        // measured along the wheels' direction, so sideways error does not count as slip.
        let matched = pose0.inverse() * pose;
        let along = (matched.x_m * wheels.x_m + matched.y_m * wheels.y_m) / wheel_m;
        if self.ratios.len() == self.cfg.segments {
            self.ratios.pop_front();
        }
        self.ratios.push_back(along / wheel_m);
        if self.ratios.len() >= self.cfg.min_segments {
            let mut sorted: Vec<f64> = self.ratios.iter().copied().collect();
            sorted.sort_by(f64::total_cmp);
            self.scale = sorted[sorted.len() / 2].clamp(self.cfg.min_scale, self.cfg.max_scale);
        }
    }

    /// Whether a match with Gauss-Newton `information` (x, y, heading; the prior's share
    /// included) and a translation prior of `prior_weight` per axis pins down the motion
    /// along `heading_rad`, the direction the rover faces in the information's frame.
    pub fn trusted(
        &self,
        information: &[[f64; 3]; 3],
        prior_weight: f64,
        heading_rad: f64,
    ) -> bool {
        pinned_along(
            information,
            prior_weight,
            heading_rad,
            self.cfg.min_information_ratio,
        )
    }
}

/// Whether a match with Gauss-Newton `information` (x, y, heading; the prior's share
/// included) and a translation prior of `prior_weight` per axis holds the position along
/// `heading_rad` (in the information's frame) with at least `min_ratio` times the prior's
/// information from the map itself.
pub fn pinned_along(
    information: &[[f64; 3]; 3],
    prior_weight: f64,
    heading_rad: f64,
    min_ratio: f64,
) -> bool {
    prior_weight > 0.0
        && map_information_along(information, prior_weight, heading_rad) >= min_ratio * prior_weight
}

/// How firmly a match's translation `information` pins the direction `heading_rad`, with the
/// matcher's own pull `prior_weight` (held in it) taken out, per square metre.
pub(crate) fn map_information_along(
    information: &[[f64; 3]; 3],
    prior_weight: f64,
    heading_rad: f64,
) -> f64 {
    let (s, c) = heading_rad.sin_cos();
    c * c * information[0][0] + 2.0 * c * s * information[0][1] + s * s * information[1][1]
        - prior_weight
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drives straight ahead in `steps` of 0.1 m of wheel travel, the ground moving `real`
    /// of it, every match trusted.
    fn drive(scale: &mut WheelScale, steps: usize, real: f64, heading_rad: f64) {
        let (s, c) = heading_rad.sin_cos();
        for k in 0..=steps {
            let d = k as f64 * 0.1;
            let odom = Pose2::new(d, 0.0, 0.0);
            // The matched pose lives in another frame: turned and shifted.
            let pose = Pose2::new(3.0 + c * d * real, -1.0 + s * d * real, heading_rad);
            scale.observe(odom, pose, true);
        }
    }

    #[test]
    fn learns_the_share_of_the_travel_the_ground_moved() {
        let mut w = WheelScale::new(SlipCalibration::default());
        assert_eq!(w.scale(), 1.0);
        drive(&mut w, 40, 0.88, 0.7);
        assert!((w.scale() - 0.88).abs() < 1e-9, "{}", w.scale());
        let scaled = w.apply(Pose2::new(0.5, 0.1, 0.2));
        assert!((scaled.x_m - 0.44).abs() < 1e-9 && (scaled.yaw_rad - 0.2).abs() < 1e-12);
    }

    #[test]
    fn a_slip_burst_of_a_few_segments_does_not_move_the_median() {
        let mut w = WheelScale::new(SlipCalibration::default());
        drive(&mut w, 40, 0.9, 0.0);
        // Two segments where the ground moved a tenth of the wheels' travel.
        let (odom0, pose0) = w.anchor.expect("a segment is open");
        for k in 1..=6 {
            let d = k as f64 * 0.1;
            w.observe(
                odom0 * Pose2::new(d, 0.0, 0.0),
                pose0 * Pose2::new(0.1 * d, 0.0, 0.0),
                true,
            );
        }
        assert!((w.scale() - 0.9).abs() < 1e-9, "{}", w.scale());
    }

    #[test]
    fn too_few_segments_or_untrusted_matches_leave_the_wheels_alone() {
        let mut w = WheelScale::new(SlipCalibration::default());
        drive(&mut w, 10, 0.5, 0.0);
        assert_eq!(w.scale(), 1.0, "three segments are not enough");
        let mut u = WheelScale::new(SlipCalibration::default());
        for k in 0..50 {
            let d = k as f64 * 0.1;
            u.observe(
                Pose2::new(d, 0.0, 0.0),
                Pose2::new(0.5 * d, 0.0, 0.0),
                false,
            );
        }
        assert_eq!(u.scale(), 1.0);
        // And the bounds hold: wheels that seem to under-report by half are capped.
        let mut v = WheelScale::new(SlipCalibration::default());
        drive(&mut v, 40, 1.5, 0.0);
        assert_eq!(v.scale(), 1.05);
    }

    #[test]
    fn an_initial_scale_holds_until_the_rover_has_learnt_its_own() {
        let cfg = SlipCalibration {
            initial_scale: 0.92,
            ..SlipCalibration::default()
        };
        let mut w = WheelScale::new(cfg);
        assert!((w.apply(Pose2::new(1.0, 0.0, 0.0)).x_m - 0.92).abs() < 1e-12);
        drive(&mut w, 10, 0.8, 0.0);
        assert_eq!(w.scale(), 0.92, "three segments are not enough");
        drive(&mut w, 40, 0.8, 0.0);
        assert!((w.scale() - 0.8).abs() < 1e-9, "{}", w.scale());
    }

    #[test]
    fn trusted_only_with_the_map_s_information_along_the_travel() {
        let w = WheelScale::new(SlipCalibration::default());
        // A wall ahead (x constrained) and a prior of 30 per axis.
        let wall_ahead = [
            [30.0 + 5000.0, 0.0, 0.0],
            [0.0, 30.0, 0.0],
            [0.0, 0.0, 100.0],
        ];
        assert!(w.trusted(&wall_ahead, 30.0, 0.0));
        // Driving along the wall instead: nothing pins the travel.
        assert!(!w.trusted(&wall_ahead, 30.0, std::f64::consts::FRAC_PI_2));
        assert!(!w.trusted(
            &[[30.0, 0.0, 0.0], [0.0, 30.0, 0.0], [0.0, 0.0, 1.0]],
            30.0,
            0.0
        ));
    }
}
