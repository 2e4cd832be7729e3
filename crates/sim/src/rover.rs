//! A Leo Rover-like skid-steer body on 3D terrain: velocity commands with acceleration and
//! speed limits, pose following the ground (height, pitch, roll), wheel slip that grows on
//! slopes and loose ground, collisions that stop it, and craters that trap it.

use crate::rng::SimRng;
use crate::scenario::Rovers;
use crate::sensors::gaussian;
use crate::terrain::{Terrain, bilinear, bilinear_with};
use crate::truth::{GroundTruth, TruthCell};
use realms_core::msgs::TwistStamped;
use realms_core::{Point2, Pose2, RoverId, Time};
use serde::Serialize;

/// What happened to a rover during a physics step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepOutcome {
    /// Nothing notable.
    Moved,
    /// It ran into an obstacle (first contact of an episode).
    Collided,
    /// Its centre entered a hazard cell.
    EnteredHazard,
    /// It is now stuck for good.
    GotStuck,
}

/// Distance, collisions and trouble a rover has had, for the mission report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct RoverStats {
    /// Distance actually travelled over ground, metres.
    pub distance_m: f64,
    /// Collision episodes.
    pub collisions: u32,
    /// Times it got stuck.
    pub stuck_events: u32,
    /// Times its centre entered a hazard cell.
    pub hazard_entries: u32,
}

/// The simulated physical rover.
#[derive(Clone, Debug)]
pub struct RoverBody {
    /// Which rover.
    pub id: RoverId,
    /// True planar pose in the arena frame.
    pub pose: Pose2,
    /// Height of the base above the arena datum, metres.
    pub z_m: f64,
    /// Pitch, positive nose down (REP 103).
    pub pitch_rad: f64,
    /// Roll, positive left side up.
    pub roll_rad: f64,
    /// Speed the wheels drive at (after limits), m/s.
    pub wheel_speed_m_s: f64,
    /// Yaw rate the wheels drive at, rad/s.
    pub wheel_yaw_rate_rad_s: f64,
    /// True body yaw rate of the last step, rad/s.
    pub yaw_rate_rad_s: f64,
    /// True body speed along its heading over the last step, m/s (0 while blocked).
    pub speed_m_s: f64,
    /// Latest command and when it arrived.
    pub command: Option<TwistStamped>,
    /// Pose integrated from the wheel encoders (the `odom` frame starts at the true pose).
    pub odom_pose: Pose2,
    /// Encoder-derived speed of the last step, m/s.
    pub odom_speed_m_s: f64,
    /// Encoder-derived yaw rate of the last step, rad/s.
    pub odom_yaw_rate_rad_s: f64,
    /// Skid-steer yaw scale error of this rover's odometry (fixed).
    pub odom_yaw_scale_error: f64,
    /// Gyro bias of this rover (fixed), rad/s.
    pub gyro_bias_rad_s: f64,
    /// False once powered off.
    pub powered: bool,
    /// True once trapped.
    pub stuck: bool,
    /// Until when the wheels have almost no grip (a slip-burst fault).
    pub slip_burst_until: Option<Time>,
    /// Statistics.
    pub stats: RoverStats,
    in_contact: bool,
    in_hazard: bool,
}

impl RoverBody {
    /// A rover at rest at `pose`, its fixed odometry and gyro errors drawn from `rng`.
    pub fn new(
        id: RoverId,
        pose: Pose2,
        spec: &Rovers,
        terrain: &Terrain,
        rng: &mut SimRng,
    ) -> Self {
        let mut body = RoverBody {
            id,
            pose,
            z_m: 0.0,
            pitch_rad: 0.0,
            roll_rad: 0.0,
            wheel_speed_m_s: 0.0,
            wheel_yaw_rate_rad_s: 0.0,
            yaw_rate_rad_s: 0.0,
            speed_m_s: 0.0,
            command: None,
            odom_pose: pose,
            odom_speed_m_s: 0.0,
            odom_yaw_rate_rad_s: 0.0,
            odom_yaw_scale_error: gaussian(rng, spec.odometry.yaw_scale_error_std),
            gyro_bias_rad_s: gaussian(rng, spec.imu.gyro_bias_std_rad_s),
            powered: true,
            stuck: false,
            slip_burst_until: None,
            stats: RoverStats::default(),
            in_contact: false,
            in_hazard: false,
        };
        body.settle(spec, terrain);
        body
    }

    /// Sets height, pitch and roll from the ground under the four wheels.
    ///
    /// A wheel rides on what it can climb: a cell standing more than `max_step_m` above the
    /// floor (a wall, the lander, a blocking rock) counts at its floor height. The footprint
    /// stops half a cell short of such cells, so a wheel beside one would otherwise take part
    /// of its height by interpolation and tip the rover 30-50 degrees against a rock it
    /// never climbed.
    pub fn settle(&mut self, spec: &Rovers, terrain: &Terrain) {
        let (hl, hw) = (spec.length_m / 2.0, spec.width_m / 2.0);
        let (heights, floor) = (terrain.heights.cells(), terrain.floor.cells());
        let h = |dx: f64, dy: f64| {
            let p = self.pose.transform_point(Point2::new(dx, dy));
            bilinear_with(terrain.heights.geometry(), p, |i| {
                // The truth's test for an obstacle rock (`truth.rs`), to the bit.
                if (heights[i] - floor[i]) as f64 > spec.max_step_m {
                    floor[i]
                } else {
                    heights[i]
                }
            })
            .unwrap_or(0.0)
        };
        let (fl, fr, rl, rr) = (h(hl, hw), h(hl, -hw), h(-hl, hw), h(-hl, -hw));
        self.z_m = (fl + fr + rl + rr) / 4.0;
        self.pitch_rad = ((rl + rr) / 2.0 - (fl + fr) / 2.0).atan2(spec.length_m);
        self.roll_rad = ((fl + rl) / 2.0 - (fr + rr) / 2.0).atan2(spec.width_m);
    }

    /// Slip fraction at the current place: base + slope (the steepest slope under the rover,
    /// from pitch and roll) + looseness, or almost total during a slip burst.
    pub fn slip(&self, spec: &Rovers, terrain: &Terrain, now: Time) -> f64 {
        if self.slip_burst_until.is_some_and(|until| now < until) {
            return 0.9;
        }
        let loose = bilinear(&terrain.looseness, self.pose.position()).unwrap_or(0.0);
        let o = &spec.odometry;
        // Skid-steer wheels slip on side slopes as well as up and down them.
        let slope = self.pitch_rad.tan().hypot(self.roll_rad.tan());
        (o.slip_base + o.slip_per_slope * slope + o.slip_loose * loose).clamp(0.0, 0.95)
    }

    /// Advances the rover by `dt_s` at time `now`.
    pub fn step(
        &mut self,
        spec: &Rovers,
        terrain: &Terrain,
        truth: &GroundTruth,
        now: Time,
        dt_s: f64,
        rng: &mut SimRng,
    ) -> Vec<StepOutcome> {
        let mut outcomes = Vec::new();
        if !self.powered {
            self.wheel_speed_m_s = 0.0;
            self.wheel_yaw_rate_rad_s = 0.0;
            self.yaw_rate_rad_s = 0.0;
            self.speed_m_s = 0.0;
            self.odom_speed_m_s = 0.0;
            self.odom_yaw_rate_rad_s = 0.0;
            return outcomes;
        }
        // The driver's dead-man: a command older than the timeout means stop.
        let timeout = realms_core::Duration::from_secs_f64(spec.cmd_timeout_s);
        let (v_target, w_target) = match &self.command {
            Some(c) if now.0.saturating_sub(c.header.stamp.0) <= timeout.0 => (
                c.twist
                    .linear
                    .x
                    .clamp(-spec.max_speed_m_s, spec.max_speed_m_s),
                c.twist
                    .angular
                    .z
                    .clamp(-spec.max_yaw_rate_rad_s, spec.max_yaw_rate_rad_s),
            ),
            _ => (0.0, 0.0),
        };
        let approach = |cur: f64, target: f64, rate: f64| {
            let d = (target - cur).clamp(-rate * dt_s, rate * dt_s);
            cur + d
        };
        self.wheel_speed_m_s = approach(self.wheel_speed_m_s, v_target, spec.max_accel_m_s2);
        self.wheel_yaw_rate_rad_s = approach(
            self.wheel_yaw_rate_rad_s,
            w_target,
            spec.max_yaw_accel_rad_s2,
        );

        // Encoders see the wheels turn whether or not the ground moves with them.
        let noise = spec.odometry.speed_noise_frac;
        self.odom_speed_m_s = self.wheel_speed_m_s * (1.0 + gaussian(rng, noise));
        self.odom_yaw_rate_rad_s = self.wheel_yaw_rate_rad_s
            * (1.0 + self.odom_yaw_scale_error)
            * (1.0 + gaussian(rng, noise));
        self.odom_pose = integrate(
            &self.odom_pose,
            self.odom_speed_m_s,
            self.odom_yaw_rate_rad_s,
            dt_s,
        );

        let slip = if self.stuck {
            1.0
        } else {
            self.slip(spec, terrain, now)
        };
        let v = self.wheel_speed_m_s * (1.0 - slip);
        let w = self.wheel_yaw_rate_rad_s * (1.0 - slip);
        let next = integrate(&self.pose, v, w, dt_s);
        if v == 0.0 && w == 0.0 {
            self.yaw_rate_rad_s = 0.0;
            self.speed_m_s = 0.0;
            return outcomes;
        }
        if footprint_hits(&next, spec, truth) {
            self.yaw_rate_rad_s = 0.0;
            self.speed_m_s = 0.0;
            if !self.in_contact {
                self.in_contact = true;
                self.stats.collisions += 1;
                outcomes.push(StepOutcome::Collided);
            }
            return outcomes;
        }
        self.in_contact = false;
        self.stats.distance_m += self.pose.position().distance_m(next.position());
        self.yaw_rate_rad_s = w;
        self.speed_m_s = v;
        self.pose = next;
        self.settle(spec, terrain);

        let in_hazard =
            truth.traversability.at_world(self.pose.position()) == Some(&TruthCell::Hazard);
        if in_hazard && !self.in_hazard {
            self.stats.hazard_entries += 1;
            outcomes.push(StepOutcome::EnteredHazard);
            if !self.stuck {
                // Past the slope limit the wheels cannot climb back out.
                self.stuck = true;
                self.stats.stuck_events += 1;
                outcomes.push(StepOutcome::GotStuck);
            }
        }
        self.in_hazard = in_hazard;
        outcomes
    }
}

/// Integrates a unicycle motion over `dt_s` (midpoint heading).
fn integrate(pose: &Pose2, v_m_s: f64, w_rad_s: f64, dt_s: f64) -> Pose2 {
    let mid = pose.yaw_rad + 0.5 * w_rad_s * dt_s;
    Pose2::new(
        pose.x_m + v_m_s * dt_s * mid.cos(),
        pose.y_m + v_m_s * dt_s * mid.sin(),
        pose.yaw_rad + w_rad_s * dt_s,
    )
}

/// Whether the rover's rectangular footprint at `pose` touches any obstacle cell. Cells are
/// tested by their centres against the footprint grown by half a cell, so a rover never
/// overlaps an obstacle cell (it stops up to one cell short).
pub fn footprint_hits(pose: &Pose2, spec: &Rovers, truth: &GroundTruth) -> bool {
    let g = truth.traversability.geometry();
    let res = g.resolution_m;
    let (hl, hw) = (
        spec.length_m / 2.0 + res / 2.0,
        spec.width_m / 2.0 + res / 2.0,
    );
    let reach = hl.hypot(hw);
    let cx = (pose.x_m - g.origin.x_m) / res;
    let cy = (pose.y_m - g.origin.y_m) / res;
    let r = reach / res;
    let (x0, x1) = (
        (cx - r).floor().max(0.0) as usize,
        ((cx + r).ceil() as usize).min(g.width),
    );
    let (y0, y1) = (
        (cy - r).floor().max(0.0) as usize,
        ((cy + r).ceil() as usize).min(g.height),
    );
    if (cx - r) < 0.0
        || (cy - r) < 0.0
        || (cx + r) as usize >= g.width
        || (cy + r) as usize >= g.height
    {
        return true; // Leaving the mapped world is as good as hitting its edge.
    }
    let inv = pose.inverse();
    let cells = truth.traversability.cells();
    for y in y0..y1 {
        for x in x0..x1 {
            if cells[y * g.width + x] != TruthCell::Obstacle {
                continue;
            }
            let p = inv.transform_point(g.cell_center(realms_core::Cell { x, y }));
            if p.x_m.abs() <= hl && p.y_m.abs() <= hw {
                return true;
            }
        }
    }
    false
}
