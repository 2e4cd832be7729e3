//! Path following for a skid-steer rover: regulated pure pursuit, after Macenski et al.,
//! "Regulated Pure Pursuit for Robot Path Tracking" (Autonomous Robots 47, 2023).
//!
//! Pure pursuit steers along the arc through a point one look-ahead distance down the path
//! (curvature `2 y / L²` in the rover's frame). The regulation slows the rover in tight turns
//! (below a minimum turning radius), near obstacles (by the costmap's cost under it) and on
//! the approach to the goal; a skid-steer rover turns in place first when the path lies well
//! off its heading. [`Follower::blocked_ahead`] checks the path ahead against a fresh costmap
//! so the caller can replan before the rover reaches what the map now shows.

use crate::costmap::{Costmap, MAX_PASSABLE};
use realms_core::{Point2, Pose2};

/// Follower tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FollowerConfig {
    /// Top speed, m/s.
    pub max_speed_m_s: f64,
    /// The regulations never slow the rover below this while it drives, m/s.
    pub min_speed_m_s: f64,
    /// Top yaw rate, rad/s.
    pub max_yaw_rate_rad_s: f64,
    /// Look-ahead distance per unit of speed, seconds ...
    pub lookahead_time_s: f64,
    /// ... within these bounds, metres.
    pub min_lookahead_m: f64,
    /// Upper bound of the look-ahead, metres.
    pub max_lookahead_m: f64,
    /// Turn in place when the look-ahead point lies more than this off the heading, rad.
    pub rotate_in_place_rad: f64,
    /// Slow down on arcs tighter than this radius, metres.
    pub min_turn_radius_m: f64,
    /// Speed is scaled by `1 - cost_slowdown * cost / 252` for the cost under the rover.
    pub cost_slowdown: f64,
    /// Slow down over this last stretch before the goal, metres.
    pub approach_m: f64,
    /// The goal is reached within this distance, metres.
    pub goal_tolerance_m: f64,
}

impl Default for FollowerConfig {
    fn default() -> Self {
        FollowerConfig {
            max_speed_m_s: 0.3,
            min_speed_m_s: 0.06,
            max_yaw_rate_rad_s: 0.8,
            lookahead_time_s: 2.0,
            min_lookahead_m: 0.35,
            max_lookahead_m: 0.8,
            rotate_in_place_rad: 0.8,
            min_turn_radius_m: 0.8,
            cost_slowdown: 0.6,
            approach_m: 0.6,
            goal_tolerance_m: 0.25,
        }
    }
}

/// What the follower wants the rover to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Steer {
    /// Drive at this speed (m/s) and yaw rate (rad/s).
    Drive {
        /// Forward speed, m/s.
        v_m_s: f64,
        /// Yaw rate, rad/s (counter-clockwise positive).
        w_rad_s: f64,
    },
    /// The goal is reached: stop.
    Arrived,
}

/// Follows one path at a time.
#[derive(Clone, Debug)]
pub struct Follower {
    cfg: FollowerConfig,
    path: Vec<Point2>,
    /// The path segment the rover was last nearest to (it never goes back).
    segment: usize,
}

impl Follower {
    /// A follower with no path.
    pub fn new(cfg: FollowerConfig) -> Self {
        Follower {
            cfg,
            path: Vec::new(),
            segment: 0,
        }
    }

    /// Follow `path` (waypoints, start first) from now on.
    pub fn set_path(&mut self, path: Vec<Point2>) {
        self.path = path;
        self.segment = 0;
    }

    /// The path being followed.
    pub fn path(&self) -> &[Point2] {
        &self.path
    }

    /// Nearest point on segment `k` to `p`, and its parameter along the segment.
    fn project(&self, k: usize, p: Point2) -> (Point2, f64) {
        let (a, b) = (self.path[k], self.path[k + 1]);
        let (dx, dy) = (b.x_m - a.x_m, b.y_m - a.y_m);
        let len2 = dx * dx + dy * dy;
        let s = if len2 > 0.0 {
            (((p.x_m - a.x_m) * dx + (p.y_m - a.y_m) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (Point2::new(a.x_m + s * dx, a.y_m + s * dy), s)
    }

    /// Moves the progress marker to the nearest segment among the next few; returns the
    /// nearest point and its distance from `p`.
    fn advance(&mut self, p: Point2) -> (Point2, f64) {
        if self.path.len() < 2 {
            let q = self.path.first().copied().unwrap_or(p);
            return (q, q.distance_m(p));
        }
        let mut best = (self.segment, self.project(self.segment, p).0);
        let mut best_d = best.1.distance_m(p);
        // Look a few metres ahead only: a path that doubles back must not be cut short.
        let mut travelled = 0.0;
        let mut at = best.1;
        for k in self.segment + 1..self.path.len() - 1 {
            travelled += at.distance_m(self.path[k]);
            at = self.path[k];
            if travelled > 2.0 * self.cfg.max_lookahead_m + best_d {
                break;
            }
            let (q, _) = self.project(k, p);
            let d = q.distance_m(p);
            if d < best_d {
                best = (k, q);
                best_d = d;
            }
        }
        self.segment = best.0;
        (best.1, best_d)
    }

    /// Distance from the rover to the path (after progress is updated).
    pub fn cross_track_m(&mut self, position: Point2) -> f64 {
        self.advance(position).1
    }

    /// The point `distance_m` further along the path from the projection `from` on the
    /// current segment (the path's end if it is shorter).
    fn along(&self, from: Point2, distance_m: f64) -> Point2 {
        let mut left = distance_m;
        let mut at = from;
        for k in self.segment + 1..self.path.len() {
            let next = self.path[k];
            let d = at.distance_m(next);
            if left <= 0.0 {
                return at;
            }
            if d >= left {
                let s = left / d;
                return Point2::new(
                    at.x_m + s * (next.x_m - at.x_m),
                    at.y_m + s * (next.y_m - at.y_m),
                );
            }
            left -= d;
            at = next;
        }
        at
    }

    /// Path length left from the projection `from`.
    fn remaining_m(&self, from: Point2) -> f64 {
        let mut total = 0.0;
        let mut at = from;
        for k in self.segment + 1..self.path.len() {
            total += at.distance_m(self.path[k]);
            at = self.path[k];
        }
        total
    }

    /// The command for the rover at `pose` moving at `speed_m_s`; `costmap` (if any) slows it
    /// near obstacles.
    pub fn steer(&mut self, pose: Pose2, speed_m_s: f64, costmap: Option<&Costmap>) -> Steer {
        let c = self.cfg;
        let Some(&goal) = self.path.last() else {
            return Steer::Arrived;
        };
        let p = pose.position();
        if p.distance_m(goal) <= c.goal_tolerance_m {
            return Steer::Arrived;
        }
        let (nearest, _) = self.advance(p);
        let lookahead =
            (speed_m_s.abs() * c.lookahead_time_s).clamp(c.min_lookahead_m, c.max_lookahead_m);
        let target = self.along(nearest, lookahead);
        let local = pose.inverse().transform_point(target);
        let bearing = local.y_m.atan2(local.x_m);
        if bearing.abs() > c.rotate_in_place_rad {
            // Proportional turn, fast when far off, so it does not overshoot at the end.
            let w = (1.5 * bearing).clamp(-c.max_yaw_rate_rad_s, c.max_yaw_rate_rad_s);
            return Steer::Drive {
                v_m_s: 0.0,
                w_rad_s: w,
            };
        }
        let l2 = local.x_m * local.x_m + local.y_m * local.y_m;
        let curvature = if l2 > 1e-9 { 2.0 * local.y_m / l2 } else { 0.0 };
        let mut v = c.max_speed_m_s;
        let radius = 1.0 / curvature.abs().max(1e-9);
        if radius < c.min_turn_radius_m {
            v *= radius / c.min_turn_radius_m;
        }
        if let Some(map) = costmap {
            let cost = map.cost_at(p).min(MAX_PASSABLE) as f64;
            v *= 1.0 - c.cost_slowdown * cost / MAX_PASSABLE as f64;
        }
        let remaining = self.remaining_m(nearest) + nearest.distance_m(p);
        if remaining < c.approach_m {
            v *= remaining / c.approach_m;
        }
        v = v.max(c.min_speed_m_s);
        let mut w = v * curvature;
        if w.abs() > c.max_yaw_rate_rad_s {
            w = w.signum() * c.max_yaw_rate_rad_s;
            v = w / curvature;
        }
        Steer::Drive {
            v_m_s: v,
            w_rad_s: w,
        }
    }

    /// Whether the path within `distance_m` ahead of the rover now crosses a cell the rover
    /// may not enter (what lies within `ignore_m` of the rover is its own business: it may be
    /// backing out of a tight spot).
    pub fn blocked_ahead(
        &mut self,
        position: Point2,
        map: &Costmap,
        distance_m: f64,
        ignore_m: f64,
    ) -> bool {
        if self.path.is_empty() {
            return false;
        }
        let (nearest, _) = self.advance(position);
        let step = 0.5 * map.geometry().resolution_m;
        let mut s = 0.0;
        while s <= distance_m {
            let q = self.along(nearest, s);
            if q.distance_m(position) > ignore_m && map.cost_at(q) > MAX_PASSABLE {
                return true;
            }
            if self.path.last().is_some_and(|g| q.distance_m(*g) < 1e-9) {
                break;
            }
            s += step;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::geometry::normalize_angle_rad;

    /// A skid-steer rover as the simulator moves it: unicycle kinematics with the Leo Rover's
    /// acceleration limits, integrated at 50 Hz, commanded at 10 Hz.
    fn drive(path: Vec<Point2>, start: Pose2, seconds: f64) -> (f64, bool, f64) {
        let mut f = Follower::new(FollowerConfig::default());
        f.set_path(path);
        let (mut pose, mut v, mut w) = (start, 0.0f64, 0.0f64);
        let (mut cmd_v, mut cmd_w) = (0.0, 0.0);
        let mut worst = 0.0f64;
        let dt = 0.02;
        for k in 0..(seconds / dt) as usize {
            if k % 5 == 0 {
                match f.steer(pose, v, None) {
                    Steer::Arrived => return (worst, true, k as f64 * dt),
                    Steer::Drive { v_m_s, w_rad_s } => (cmd_v, cmd_w) = (v_m_s, w_rad_s),
                }
                if k as f64 * dt > 3.0 {
                    worst = worst.max(f.cross_track_m(pose.position()));
                }
            }
            v += (cmd_v - v).clamp(-0.5 * dt, 0.5 * dt);
            w += (cmd_w - w).clamp(-2.0 * dt, 2.0 * dt);
            pose = Pose2::new(
                pose.x_m + v * pose.yaw_rad.cos() * dt,
                pose.y_m + v * pose.yaw_rad.sin() * dt,
                normalize_angle_rad(pose.yaw_rad + w * dt),
            );
        }
        (worst, false, seconds)
    }

    #[test]
    fn an_s_curve_is_followed_within_five_centimetres() {
        // A sine of 1 m amplitude and 8 m wavelength, sampled every 10 cm like a planner's
        // cells: the tightest bend has a radius of 1.6 m.
        let path: Vec<Point2> = (0..=160)
            .map(|k| {
                let x = k as f64 * 0.1;
                Point2::new(x, (x * std::f64::consts::TAU / 8.0).sin())
            })
            .collect();
        let start = Pose2::new(0.0, 0.0, (std::f64::consts::TAU / 8.0).atan());
        let (worst, arrived, t) = drive(path, start, 120.0);
        assert!(arrived, "not there after {t} s");
        assert!(worst < 0.05, "cross-track error {worst:.3} m");
    }

    #[test]
    fn a_sharp_corner_is_taken_by_turning_in_place_and_stays_close() {
        // An L: 4 m east, then 4 m north; the rover starts facing west.
        let path = vec![
            Point2::new(0.0, 0.0),
            Point2::new(4.0, 0.0),
            Point2::new(4.0, 4.0),
        ];
        let (worst, arrived, t) = drive(path, Pose2::new(0.0, 0.0, std::f64::consts::PI), 120.0);
        assert!(arrived, "not there after {t} s");
        assert!(worst < 0.20, "cross-track error {worst:.3} m");
        // 8 m at 0.3 m/s is 27 s; turning and slowing may not double it.
        assert!(t < 50.0, "{t} s");
    }

    #[test]
    fn the_path_ahead_is_checked_against_a_new_costmap() {
        use realms_core::{Grid, GridGeometry};
        let g = GridGeometry {
            width: 50,
            height: 10,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut costs = Grid::new(g, 0u8);
        let mut f = Follower::new(FollowerConfig::default());
        f.set_path(vec![Point2::new(0.25, 0.55), Point2::new(4.75, 0.55)]);
        let map = Costmap::from_costs(costs.clone());
        assert!(!f.blocked_ahead(Point2::new(0.25, 0.55), &map, 3.0, 0.3));
        // A rock appears 2 m ahead: within 3 m, beyond 1.5 m.
        *costs.get_mut(22, 5).expect("inside") = crate::costmap::LETHAL;
        let map = Costmap::from_costs(costs);
        assert!(f.blocked_ahead(Point2::new(0.25, 0.55), &map, 3.0, 0.3));
        assert!(!f.blocked_ahead(Point2::new(0.25, 0.55), &map, 1.5, 0.3));
    }
}
