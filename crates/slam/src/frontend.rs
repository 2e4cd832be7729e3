//! Runs laser scans through the matcher and the map, one by one: predict the pose from the
//! odometry increment, match the scan against the map, insert it if the robot has moved
//! enough since the last insertion. (No loop closure yet: that is the pose graph's job.)

use crate::carmen::LaserReading;
use crate::matcher::{Match, MatcherConfig, MultiResMap, match_scan};
use crate::occupancy::{MissMargin, MissRule};
use crate::odometry::{OdomPredictor, OdomSample};
use crate::trajectory::StampedPose;
use realms_core::{Point2, Pose2};

/// Frontend tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrontendConfig {
    /// Finest map cell, metres.
    pub resolution_m: f64,
    /// Map resolutions (each twice as coarse as the last).
    pub levels: usize,
    /// Readings beyond this are not used, metres.
    pub max_range_m: f64,
    /// Readings closer than this are not used (the robot's own body), metres.
    pub min_range_m: f64,
    /// Insert a scan after moving this far since the last insertion, metres.
    pub insert_translation_m: f64,
    /// ... or turning this much, radians.
    pub insert_rotation_rad: f64,
    /// Fill the gaps between neighbouring beams' endpoints before matching and mapping
    /// (`None`: use the endpoints as they are). See [`densify`].
    pub densify: Option<Densify>,
    /// Whether a keyframe's free space is traced into the mapper's submaps to the points
    /// [`densify`] fills in as well as to its beams' own endpoints (`false`: the filled-in
    /// points are marked hit, and free space is traced along the beams only, a fraction of
    /// the walks). The scan-by-scan [`Frontend`] traces every point either way.
    pub trace_filled: bool,
    /// How each scan clears the cells its beams cross.
    pub miss_rule: MissRule,
    /// How far short of its hit each beam stops clearing cells (`None`: up to the hit's
    /// cell). See [`MissMargin`].
    pub miss_margin: Option<MissMargin>,
    /// Matcher tuning.
    pub matcher: MatcherConfig,
}

impl Default for FrontendConfig {
    fn default() -> Self {
        FrontendConfig {
            resolution_m: 0.05,
            levels: 3,
            max_range_m: 25.0,
            min_range_m: 0.1,
            insert_translation_m: 0.05,
            insert_rotation_rad: 2f64.to_radians(),
            densify: None,
            trace_filled: true,
            miss_rule: MissRule::EveryBeam,
            miss_margin: None,
            matcher: MatcherConfig::default(),
        }
    }
}

/// The endpoints of a scan's beams between `min_range_m` and `max_range_m` (and below the
/// laser's own no-return range), in the robot frame.
pub fn scan_points(scan: &LaserReading, min_range_m: f64, max_range_m: f64) -> Vec<Point2> {
    let max = max_range_m.min(scan.max_range_m - 1e-3);
    scan.ranges_m
        .iter()
        .enumerate()
        .filter(|(_, r)| (**r as f64) >= min_range_m && (**r as f64) < max)
        .map(|(i, r)| {
            let a = scan.angle_min_rad + i as f64 * scan.angle_increment_rad;
            let r = *r as f64;
            scan.robot_from_laser
                .transform_point(Point2::new(r * a.cos(), r * a.sin()))
        })
        .collect()
}

/// How [`densify`] fills the gaps between neighbouring endpoints.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Densify {
    /// Endpoints farther apart than this lie on different surfaces, metres.
    pub max_gap_m: f64,
    /// Points are added along a gap this far apart, metres.
    pub spacing_m: f64,
}

/// `points` (endpoints in beam order) with points added every `spacing_m` between
/// neighbours at most `max_gap_m` apart: the surface both beams landed on runs between them.
///
/// Far from the sensor a 1-degree lidar spreads its endpoints wider than a map cell, so a
/// map of a few scans draws each wall as a dotted line. A later scan's endpoints fall into
/// the gaps, and matching against the map slides them sideways onto the dots: a heading bias
/// of tenths of a degree per match, which grows into decimetres across a hall. Matching and
/// mapping the filled-in surface takes that bias away (the same idea as interpolating a
/// scan into line segments before matching, as PL-ICP does; Censi, ICRA 2008).
pub fn densify(points: &[Point2], d: Densify) -> Vec<Point2> {
    let mut out = Vec::with_capacity(points.len() * 2);
    for (i, p) in points.iter().enumerate() {
        out.push(*p);
        let Some(q) = points.get(i + 1) else { break };
        let gap = p.distance_m(*q);
        if gap <= d.max_gap_m {
            let n = (gap / d.spacing_m).ceil() as usize;
            for k in 1..n {
                let f = k as f64 / n as f64;
                out.push(Point2::new(
                    p.x_m + f * (q.x_m - p.x_m),
                    p.y_m + f * (q.y_m - p.y_m),
                ));
            }
        }
    }
    out
}

/// The scan-matching frontend.
#[derive(Debug)]
pub struct Frontend {
    cfg: FrontendConfig,
    map: MultiResMap,
    pose: Pose2,
    odometry: OdomPredictor,
    last_insert: Option<Pose2>,
    trajectory: Vec<StampedPose>,
}

impl Frontend {
    /// A frontend with an empty map.
    pub fn new(cfg: FrontendConfig) -> Self {
        Frontend {
            map: MultiResMap::new(cfg.resolution_m, cfg.levels)
                .with_miss_rule(cfg.miss_rule)
                .with_miss_margin(cfg.miss_margin),
            cfg,
            pose: Pose2::IDENTITY,
            odometry: OdomPredictor::default(),
            last_insert: None,
            trajectory: Vec::new(),
        }
    }

    /// The endpoints of usable beams, in the robot frame.
    pub fn points_in_robot(&self, scan: &LaserReading) -> Vec<Point2> {
        scan_points(scan, self.cfg.min_range_m, self.cfg.max_range_m)
    }

    /// Adds a scan; returns the estimated pose of the robot at the scan.
    pub fn add_scan(&mut self, scan: &LaserReading) -> Option<Match> {
        let prediction = self
            .odometry
            .predict(OdomSample::wheels(scan.odom), self.pose, |d| d);
        let predicted = prediction.pose;
        let points = self.points_in_robot(scan);
        let matched = match self.last_insert {
            Some(_) if points.len() >= 10 => {
                Some(match_scan(&self.map, &points, predicted, &self.cfg.matcher))
            }
            _ => None,
        };
        self.pose = matched.map_or(predicted, |m| m.pose);
        self.odometry
            .settle(scan.odom, self.pose, &prediction, false);
        let moved = self.last_insert.is_none_or(|last| {
            let d = self.pose.relative_to(&last);
            d.x_m.hypot(d.y_m) >= self.cfg.insert_translation_m
                || d.yaw_rad.abs() >= self.cfg.insert_rotation_rad
        });
        if moved && !points.is_empty() {
            let world: Vec<(Point2, bool)> = points
                .iter()
                .map(|p| (self.pose.transform_point(*p), true))
                .collect();
            let sensor = self.pose.transform_point(scan.robot_from_laser.position());
            self.map.insert(sensor, &world);
            self.last_insert = Some(self.pose);
        }
        self.trajectory.push(StampedPose {
            timestamp_s: scan.timestamp_s,
            pose: self.pose,
        });
        matched
    }

    /// Every pose so far, one per scan.
    pub fn trajectory(&self) -> &[StampedPose] {
        &self.trajectory
    }

    /// The finest map.
    pub fn map(&self) -> &crate::occupancy::OccupancyGrid {
        self.map.finest()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn densify_fills_gaps_on_a_surface_and_not_between_surfaces() {
        let points = [
            Point2::new(4.0, 0.0),
            Point2::new(4.0, 0.2),  // 0.2 m on: filled every 5 cm
            Point2::new(6.0, 0.3),  // 2 m farther: another surface
            Point2::new(6.0, 0.32), // closer than the spacing: nothing added
        ];
        let d = densify(
            &points,
            Densify {
                max_gap_m: 0.3,
                spacing_m: 0.05,
            },
        );
        let expected = [
            (4.0, 0.0),
            (4.0, 0.05),
            (4.0, 0.1),
            (4.0, 0.15),
            (4.0, 0.2),
            (6.0, 0.3),
            (6.0, 0.32),
        ];
        assert_eq!(d.len(), expected.len(), "{d:?}");
        for (p, (x, y)) in d.iter().zip(expected) {
            assert!(
                (p.x_m - x).abs() < 1e-9 && (p.y_m - y).abs() < 1e-9,
                "{d:?}"
            );
        }
    }
}
