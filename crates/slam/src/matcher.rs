//! Scan-to-map matching by Gauss-Newton on a smooth (bilinear) occupancy map at several
//! resolutions, coarse to fine, after Kohlbrecher et al., "A Flexible and Scalable SLAM System
//! with Full 3D Motion Estimation" (Hector SLAM, SSRR 2011). The coarse levels widen the basin
//! of convergence; a weak prior towards the odometry prediction keeps feature-poor corridors
//! from sliding.

use crate::occupancy::OccupancyGrid;
use realms_core::{Point2, Pose2};

/// The same map at several resolutions, finest first.
#[derive(Clone, Debug)]
pub struct MultiResMap {
    levels: Vec<OccupancyGrid>,
}

impl MultiResMap {
    /// `levels` maps, the finest at `resolution_m`, each next one twice as coarse.
    pub fn new(resolution_m: f64, levels: usize) -> Self {
        MultiResMap {
            levels: (0..levels.max(1))
                .map(|k| OccupancyGrid::new(resolution_m * (1 << k) as f64))
                .collect(),
        }
    }

    /// The maps clearing cells by `rule` from now on.
    pub fn with_miss_rule(mut self, rule: crate::occupancy::MissRule) -> Self {
        self.levels = self
            .levels
            .into_iter()
            .map(|l| l.with_miss_rule(rule))
            .collect();
        self
    }

    /// The maps' beams stopping short of their hits by `margin` from now on (see
    /// [`crate::occupancy::MissMargin`]).
    pub fn with_miss_margin(mut self, margin: Option<crate::occupancy::MissMargin>) -> Self {
        self.levels = self
            .levels
            .into_iter()
            .map(|l| l.with_miss_margin(margin))
            .collect();
        self
    }

    /// Inserts a scan into every level.
    pub fn insert(&mut self, sensor: Point2, endpoints: &[(Point2, bool)]) {
        self.insert_with_rays(sensor, endpoints, None);
    }

    /// Inserts a scan into every level, tracing free space only to `rays` when given (see
    /// [`crate::occupancy::OccupancyGrid::insert_with_rays`]).
    pub fn insert_with_rays(
        &mut self,
        sensor: Point2,
        endpoints: &[(Point2, bool)],
        rays: Option<&[Point2]>,
    ) {
        for l in &mut self.levels {
            l.insert_with_rays(sensor, endpoints, rays);
        }
    }

    /// Cuts every level to its content (see [`OccupancyGrid::cut_to_content`]).
    pub fn cut_to_content(&mut self) {
        for l in &mut self.levels {
            l.cut_to_content();
        }
    }

    /// Whether every level is whole (see [`OccupancyGrid::is_whole`]).
    pub fn is_whole(&self) -> bool {
        self.levels.iter().all(OccupancyGrid::is_whole)
    }

    /// Makes every level whole again (see [`OccupancyGrid::make_whole`]).
    pub fn make_whole(&mut self) {
        for l in &mut self.levels {
            l.make_whole();
        }
    }

    /// Gives the memory of every level back (see [`OccupancyGrid::release`]).
    pub fn release(&mut self) {
        for l in &mut self.levels {
            l.release();
        }
    }

    /// The finest map.
    pub fn finest(&self) -> &OccupancyGrid {
        &self.levels[0]
    }

    /// The map, if there is only one level.
    pub fn single_level_mut(&mut self) -> Option<&mut OccupancyGrid> {
        match &mut self.levels[..] {
            [only] => Some(only),
            _ => None,
        }
    }

    /// The coarsest map.
    pub fn coarsest(&self) -> &OccupancyGrid {
        self.levels.last().expect("at least one level")
    }
}

/// Matcher tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatcherConfig {
    /// Gauss-Newton iterations per level.
    pub iterations: usize,
    /// Pull towards the prior's translation (per point, per square metre).
    pub prior_translation_weight: f64,
    /// Pull towards the prior's heading (per point, per square radian).
    pub prior_rotation_weight: f64,
}

impl Default for MatcherConfig {
    fn default() -> Self {
        MatcherConfig {
            iterations: 6,
            prior_translation_weight: 3.0,
            prior_rotation_weight: 3.0,
        }
    }
}

/// A match and how much to trust it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    /// Best pose of the scan in the map frame.
    pub pose: Pose2,
    /// Mean occupancy probability at the scan's endpoints on the finest map (1: every
    /// endpoint on an occupied cell).
    pub score: f64,
    /// Gauss-Newton information matrix (x, y, theta) at the solution; its inverse scaled by
    /// the residual is the covariance.
    pub information: [[f64; 3]; 3],
}

/// Matches `points` (in the robot frame) against `map`, starting from `prior`.
pub fn match_scan(
    map: &MultiResMap,
    points: &[Point2],
    prior: Pose2,
    cfg: &MatcherConfig,
) -> Match {
    let mut pose = prior;
    let mut information = [[0.0; 3]; 3];
    for level in map.levels.iter().rev() {
        for _ in 0..cfg.iterations {
            let (h, g) = normal_equations(level, points, &pose, &prior, cfg);
            information = h;
            let Some(step) = solve3(&h, &g) else { break };
            pose = Pose2::new(
                pose.x_m + step[0],
                pose.y_m + step[1],
                pose.yaw_rad + step[2],
            );
            if step[0].abs() < 1e-4 && step[1].abs() < 1e-4 && step[2].abs() < 1e-4 {
                break;
            }
        }
    }
    let finest = map.finest();
    let score = if points.is_empty() {
        0.0
    } else {
        points
            .iter()
            .map(|p| finest.probability_and_gradient(pose.transform_point(*p)).0)
            .sum::<f64>()
            / points.len() as f64
    };
    Match {
        pose,
        score,
        information,
    }
}

/// The heading within `half_width_rad` of `prior`'s, in steps of `step_rad`, at which
/// `points` (robot frame, at `prior`'s translation) land on the most occupied cells of the
/// coarsest map. Gauss-Newton converges only within a few degrees of the answer, and in a
/// fast turn the wheels' heading can be off by more (the MIT CSAIL log's odometry turns 105
/// degrees over four readings at 24 s, 46 of them in one, where the robot turned 95): a
/// search over headings finds the basin first.
pub fn best_heading(
    map: &MultiResMap,
    points: &[Point2],
    prior: Pose2,
    half_width_rad: f64,
    step_rad: f64,
) -> Pose2 {
    let coarse = map.coarsest();
    let steps = (half_width_rad / step_rad.max(1e-6)).ceil() as i64;
    let mut best = (f64::NEG_INFINITY, prior);
    for k in -steps..=steps {
        let pose = Pose2::new(prior.x_m, prior.y_m, prior.yaw_rad + k as f64 * step_rad);
        let score: f64 = points
            .iter()
            .map(|p| coarse.probability_and_gradient(pose.transform_point(*p)).0)
            .sum();
        if score > best.0 {
            best = (score, pose);
        }
    }
    best.1
}

/// H and g of the Gauss-Newton step for residuals 1 - M(S_i(pose)), plus the prior.
fn normal_equations(
    map: &OccupancyGrid,
    points: &[Point2],
    pose: &Pose2,
    prior: &Pose2,
    cfg: &MatcherConfig,
) -> ([[f64; 3]; 3], [f64; 3]) {
    let (s, c) = pose.yaw_rad.sin_cos();
    let mut h = [[0.0; 3]; 3];
    let mut g = [0.0; 3];
    for p in points {
        let world = pose.transform_point(*p);
        let (m, grad) = map.probability_and_gradient(world);
        let dtheta = grad[0] * (-s * p.x_m - c * p.y_m) + grad[1] * (c * p.x_m - s * p.y_m);
        let j = [grad[0], grad[1], dtheta];
        let r = 1.0 - m;
        // H is symmetric: its upper triangle only, mirrored below.
        for a in 0..3 {
            g[a] += j[a] * r;
            for b in a..3 {
                h[a][b] += j[a] * j[b];
            }
        }
    }
    (h[1][0], h[2][0], h[2][1]) = (h[0][1], h[0][2], h[1][2]);
    let n = points.len() as f64;
    let (wt, wr) = (
        cfg.prior_translation_weight * n,
        cfg.prior_rotation_weight * n,
    );
    let d = [
        prior.x_m - pose.x_m,
        prior.y_m - pose.y_m,
        realms_core::geometry::normalize_angle_rad(prior.yaw_rad - pose.yaw_rad),
    ];
    for (k, w) in [wt, wt, wr].into_iter().enumerate() {
        h[k][k] += w;
        g[k] += w * d[k];
    }
    (h, g)
}

/// Solves a symmetric 3x3 system by Cramer's rule; `None` if (nearly) singular.
pub(crate) fn solve3(a: &[[f64; 3]; 3], b: &[f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if d.abs() < 1e-12 {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = *a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *xk = det(&m) / d;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Endpoints of a 360-beam scan inside a 6 m x 4 m room with a pillar, from `pose`. The
    /// walls run through cell centres (x, y = k * 0.05 + 0.025): walls on cell boundaries would
    /// put every hit in the cell on one side and shift the whole map by half a cell.
    fn room_scan(pose: Pose2) -> Vec<Point2> {
        let o = 0.025;
        let walls = [
            (o, o, 6.0 + o, o),
            (6.0 + o, o, 6.0 + o, 4.0 + o),
            (6.0 + o, 4.0 + o, o, 4.0 + o),
            (o, 4.0 + o, o, o),
            (4.0 + o, 1.5 + o, 4.5 + o, 1.5 + o),
            (4.5 + o, 1.5 + o, 4.5 + o, 2.5 + o),
        ];
        (0..360)
            .filter_map(|i| {
                let a = pose.yaw_rad + (i as f64).to_radians();
                let (dx, dy) = (a.cos(), a.sin());
                let mut best = f64::INFINITY;
                for (x1, y1, x2, y2) in walls {
                    let (ex, ey) = (x2 - x1, y2 - y1);
                    let den = dx * ey - dy * ex;
                    if den.abs() < 1e-12 {
                        continue;
                    }
                    let t = ((x1 - pose.x_m) * ey - (y1 - pose.y_m) * ex) / den;
                    let u = ((x1 - pose.x_m) * dy - (y1 - pose.y_m) * dx) / den;
                    if t > 0.0 && (0.0..=1.0).contains(&u) {
                        best = best.min(t);
                    }
                }
                best.is_finite().then(|| {
                    Point2::new(
                        best * (i as f64).to_radians().cos(),
                        best * (i as f64).to_radians().sin(),
                    )
                })
            })
            .collect()
    }

    /// The room's map at 5 cm on three levels, scanned from each of `poses`.
    fn room_map(poses: &[Pose2]) -> MultiResMap {
        let mut map = MultiResMap::new(0.05, 3);
        for pose in poses {
            let world: Vec<(Point2, bool)> = room_scan(*pose)
                .iter()
                .map(|p| (pose.transform_point(*p), true))
                .collect();
            map.insert(pose.position(), &world);
        }
        map
    }

    #[test]
    fn recovers_a_known_offset_in_a_room() {
        // The map a robot would have after scanning from three places in the room.
        let map = room_map(&[
            Pose2::new(2.0, 2.0, 0.0),
            Pose2::new(1.0, 1.0, 0.5),
            Pose2::new(3.0, 3.0, -0.4),
        ]);
        let truth1 = Pose2::new(2.3, 1.85, 0.08);
        let scan1 = room_scan(truth1);
        // Start 0.15 m and 4 degrees off, as odometry would.
        let prior = Pose2::new(2.42, 1.95, 0.08 - 4f64.to_radians());
        let cfg = MatcherConfig {
            prior_translation_weight: 3.0,
            prior_rotation_weight: 3.0,
            ..Default::default()
        };
        let m = match_scan(&map, &scan1, prior, &cfg);
        let err = m.pose.relative_to(&truth1);
        assert!(
            err.x_m.hypot(err.y_m) < 0.02,
            "{:?} vs {:?}",
            m.pose,
            truth1
        );
        assert!(err.yaw_rad.abs() < 0.5f64.to_radians(), "{:?}", m.pose);
        assert!(m.score > 0.6, "{}", m.score);
    }

    #[test]
    fn a_search_over_headings_finds_a_turn_the_local_match_cannot() {
        let map = room_map(&[Pose2::new(2.0, 2.0, 0.0)]);
        // Turned in place, with the wheels' heading 25 degrees past the turn. In this plain
        // room the local match alone still finds turns up to about 18 degrees, so the test
        // goes past the mapper's 20-degree search, and searches 30.
        let truth1 = Pose2::new(2.0, 2.0, 0.6);
        let scan1 = room_scan(truth1);
        let prior = Pose2::new(2.0, 2.0, 0.6 + 25f64.to_radians());
        let cfg = MatcherConfig::default();
        let heading_err = |m: &Match| m.pose.relative_to(&truth1).yaw_rad.abs();
        let local = match_scan(&map, &scan1, prior, &cfg);
        assert!(heading_err(&local) > 5f64.to_radians(), "{:?}", local.pose);
        let start = best_heading(&map, &scan1, prior, 30f64.to_radians(), 1f64.to_radians());
        let searched = match_scan(&map, &scan1, start, &cfg);
        assert!(
            heading_err(&searched) < 0.5f64.to_radians(),
            "{:?}",
            searched.pose
        );
        // By more than the mapper's margin for taking it (`FastTurn::margin`, 0.1).
        assert!(
            searched.score > local.score + 0.1,
            "{} vs {}",
            searched.score,
            local.score
        );
    }
}
