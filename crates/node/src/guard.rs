//! The rover's last line of defence: a reactive check of its own sensors, independent of the
//! map and the plan. The lidar says whether anything stands in a box just in front of (or
//! behind) the rover; the depth camera whether the ground just ahead holds a rock above the
//! step limit or drops away. Navigation stops forward motion while the front is blocked and
//! backs off only while the rear is clear.

use realms_core::msgs::{LaserScan, PointCloud};
use realms_core::{Duration, Time};

/// The rover's geometry and the margins the guard keeps.
#[derive(Clone, Debug, PartialEq)]
pub struct GuardConfig {
    /// Half the rover's length, metres.
    pub half_length_m: f64,
    /// Half the rover's width, metres.
    pub half_width_m: f64,
    /// Lidar position forward of the base, metres.
    pub lidar_x_m: f64,
    /// Free distance wanted ahead of the front (and behind the back) by the lidar, metres.
    pub lidar_clearance_m: f64,
    /// How far ahead of the front the depth camera's ground is checked, metres.
    pub depth_reach_m: f64,
    /// `base_from_optical` of the depth camera: rotation (row-major) ...
    pub depth_rot: [[f64; 3]; 3],
    /// ... and origin in the base frame, metres.
    pub depth_origin_m: [f64; 3],
    /// Tallest rock the rover drives over, metres.
    pub max_step_m: f64,
    /// A floor this far below the base is a drop, metres.
    pub max_drop_m: f64,
}

/// The guard's latest verdicts.
#[derive(Debug)]
pub struct Guard {
    cfg: GuardConfig,
    depth_hazard_until: Time,
}

/// How long a depth frame's verdict stands (frames come at 2 Hz).
const DEPTH_HOLD: Duration = Duration::from_millis(1000);

impl Guard {
    /// A guard that has seen nothing yet.
    pub fn new(cfg: GuardConfig) -> Self {
        Guard {
            cfg,
            depth_hazard_until: Time::ZERO,
        }
    }

    /// Notes rocks and drops in the strip of ground just ahead.
    pub fn on_depth(&mut self, now: Time, cloud: &PointCloud) {
        let c = &self.cfg;
        let r = &c.depth_rot;
        let o = &c.depth_origin_m;
        let reach = c.half_length_m + c.depth_reach_m;
        let hazardous = cloud
            .points_in_sensor
            .iter()
            .filter(|p| !p[2].is_nan())
            .any(|p| {
                let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
                let bx = r[0][0] * x + r[0][1] * y + r[0][2] * z + o[0];
                let by = r[1][0] * x + r[1][1] * y + r[1][2] * z + o[1];
                let bz = r[2][0] * x + r[2][1] * y + r[2][2] * z + o[2];
                bx > c.half_length_m
                    && bx < reach
                    && by.abs() < c.half_width_m + 0.03
                    && (bz > c.max_step_m || bz < -c.max_drop_m)
            });
        if hazardous {
            self.depth_hazard_until = now + DEPTH_HOLD;
        }
    }

    /// What the latest scan (and the depth camera's recent frames) say.
    pub fn on_scan(&self, now: Time, scan: &LaserScan) -> crate::navigation::Guarded {
        let c = &self.cfg;
        let (mut front, mut rear) = (now < self.depth_hazard_until, false);
        for (i, r) in scan.ranges_m.iter().enumerate() {
            if !r.is_finite() || *r < scan.range_min_m {
                continue;
            }
            let a = scan.angle_min_rad as f64 + i as f64 * scan.angle_increment_rad as f64;
            let r = *r as f64;
            let (x, y) = (r * a.cos() + c.lidar_x_m, r * a.sin());
            if y.abs() >= c.half_width_m + 0.05 {
                continue;
            }
            let edge = c.half_length_m + c.lidar_clearance_m;
            front |= x > 0.0 && x < edge;
            rear |= x < 0.0 && x > -edge;
        }
        crate::navigation::Guarded {
            front_blocked: front,
            rear_blocked: rear,
        }
    }
}
