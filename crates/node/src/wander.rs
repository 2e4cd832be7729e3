//! PLACEHOLDER behaviour until exploration exists (issue 4): wander with reactive collision
//! and hazard avoidance from the rover's own sensors. It drives ahead while the corridor in
//! front is clear in the lidar scan and the depth camera sees neither a rock above the step
//! limit nor a drop below the floor, turns towards the more open side when it is not, backs
//! off when turning does not help, and now and then changes heading at random so it does not
//! circle forever.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use realms_core::msgs::{LaserScan, PointCloud};
use realms_core::{Duration, Time};

/// Tuning and the rover geometry the behaviour needs.
#[derive(Clone, Debug, PartialEq)]
pub struct WanderConfig {
    /// Speed when the way is clear, m/s.
    pub cruise_speed_m_s: f64,
    /// Yaw rate when turning away, rad/s.
    pub turn_rate_rad_s: f64,
    /// Free distance wanted ahead of the front bumper, metres.
    pub clearance_m: f64,
    /// Half the rover's length, metres.
    pub half_length_m: f64,
    /// Half the rover's width, metres.
    pub half_width_m: f64,
    /// Lidar position forward of the base, metres.
    pub lidar_x_m: f64,
    /// `base_from_optical` of the depth camera: rotation (row-major) and origin.
    pub depth_rot: [[f64; 3]; 3],
    /// Origin of the depth camera in the base frame, metres.
    pub depth_origin_m: [f64; 3],
    /// Tallest rock the rover drives over, metres.
    pub max_step_m: f64,
    /// A floor this far below the base is a drop to avoid, metres.
    pub max_drop_m: f64,
    /// Seed of the random heading changes.
    pub seed: u64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Cruise,
    Turn { dir: f64, until: Time },
    Reverse { until: Time },
}

/// The wandering state machine.
#[derive(Debug)]
pub struct Wander {
    cfg: WanderConfig,
    mode: Mode,
    hazard_ahead_until: Time,
    blocked_since: Option<Time>,
    next_random_turn: Time,
    rng: ChaCha8Rng,
}

impl Wander {
    /// A wanderer at rest.
    pub fn new(cfg: WanderConfig) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        let first = Time::from_secs_f64(rng.random_range(20.0..60.0));
        Wander {
            cfg,
            mode: Mode::Cruise,
            hazard_ahead_until: Time::ZERO,
            blocked_since: None,
            next_random_turn: first,
            rng,
        }
    }

    /// Notes rocks and drops the depth camera sees in the corridor ahead; they block the way
    /// for a second (until the next frame has had its say).
    pub fn on_depth(&mut self, now: Time, cloud: &PointCloud) {
        let c = &self.cfg;
        let r = &c.depth_rot;
        let o = &c.depth_origin_m;
        let reach = c.half_length_m + c.clearance_m;
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
                    && by.abs() < c.half_width_m + 0.1
                    && (bz > c.max_step_m || bz < -c.max_drop_m)
            });
        if hazardous {
            self.hazard_ahead_until = now + Duration::from_millis(1000);
        }
    }

    /// Decides a velocity `(v_m_s, w_rad_s)` from a new scan.
    pub fn on_scan(&mut self, now: Time, scan: &LaserScan) -> (f64, f64) {
        let c = self.cfg.clone();
        let mut blocked = now < self.hazard_ahead_until;
        let (mut left_open, mut right_open) = (0.0, 0.0);
        for (i, r) in scan.ranges_m.iter().enumerate() {
            let a = scan.angle_min_rad as f64 + i as f64 * scan.angle_increment_rad as f64;
            let range = if r.is_finite() {
                *r as f64
            } else {
                scan.range_max_m as f64
            };
            if a > 0.0 && a < 1.6 {
                left_open += range.min(4.0);
            } else if a < 0.0 && a > -1.6 {
                right_open += range.min(4.0);
            }
            if !r.is_finite() || (*r as f64) < scan.range_min_m as f64 {
                continue;
            }
            let (x, y) = (range * a.cos() + c.lidar_x_m, range * a.sin());
            if x > 0.0 && x < c.half_length_m + c.clearance_m && y.abs() < c.half_width_m + 0.15 {
                blocked = true;
            }
        }
        match self.mode {
            Mode::Reverse { until } if now < until => return (-0.15, 0.0),
            Mode::Turn { dir, until } if now < until || blocked => {
                // Being blocked mid-turn (a random one, say) counts towards the escape too.
                let since = blocked.then(|| *self.blocked_since.get_or_insert(now));
                if since.is_some_and(|s| now - s > Duration::from_secs(8)) {
                    self.blocked_since = None;
                    self.mode = Mode::Reverse {
                        until: now + Duration::from_millis(1500),
                    };
                    return (-0.15, 0.0);
                }
                return (0.0, dir * c.turn_rate_rad_s);
            }
            _ => {}
        }
        if blocked {
            self.blocked_since.get_or_insert(now);
            let dir = if left_open >= right_open { 1.0 } else { -1.0 };
            self.mode = Mode::Turn {
                dir,
                until: now + Duration::from_millis(800),
            };
            return (0.0, dir * c.turn_rate_rad_s);
        }
        self.blocked_since = None;
        if now >= self.next_random_turn {
            let dir = if self.rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let turn_s = self.rng.random_range(0.5..3.0);
            self.next_random_turn =
                now + Duration::from_secs_f64(self.rng.random_range(20.0..60.0));
            self.mode = Mode::Turn {
                dir,
                until: now + Duration::from_secs_f64(turn_s),
            };
            return (0.0, dir * c.turn_rate_rad_s);
        }
        self.mode = Mode::Cruise;
        (c.cruise_speed_m_s, 0.0)
    }
}
