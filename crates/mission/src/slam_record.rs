//! What the rovers' SLAM said during a mission, kept beside what was true, so the report can
//! grade it: pose estimates against the true pose (and wheel odometry against it, as the
//! baseline SLAM must beat), every change of localisation state, and each rover's latest map
//! graded against the simulator's ground truth, hazards included.

use realms_core::msgs::{LocalisationState, OccupancyGrid};
use realms_core::{Duration, Grid, GridGeometry, Point2, Pose2, Time};
use realms_sim::{GroundTruth, TruthCell};
use serde::Serialize;

/// How often a pose estimate is kept for grading.
pub const ESTIMATE_PERIOD: Duration = Duration::from_secs(1);

/// One graded instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseCheck {
    /// When.
    pub t: Time,
    /// SLAM's estimate.
    pub estimate: Pose2,
    /// Wheel odometry.
    pub odometry: Pose2,
    /// The truth.
    pub truth: Pose2,
    /// The standard deviations SLAM published with its estimate: position (metres, the
    /// larger of x and y) and heading (radians).
    pub sigma: Option<(f64, f64)>,
    /// SLAM's estimate of the same instant at the end of the mission, after every loop
    /// closure (what an absolute trajectory error grades), once attached.
    pub optimised: Option<Pose2>,
}

/// A change of localisation state as reported.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StateChange {
    /// Mission time, seconds.
    pub t_s: f64,
    /// The new state.
    pub state: LocalisationState,
    /// Why, as the rover put it.
    pub reason: String,
}

/// How long a rover was lost over a mission, from its changes of localisation state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LostTime {
    /// Times it became lost.
    pub episodes: usize,
    /// Seconds it spent lost, up to the mission's end.
    pub seconds: f64,
    /// Whether it was still lost at the end: it never found its place again.
    pub at_end: bool,
}

impl LostTime {
    /// Reads `changes` (in time order) over a mission that ended at `end_s`.
    pub fn of(changes: &[StateChange], end_s: f64) -> LostTime {
        let mut lost = LostTime::default();
        let mut since: Option<f64> = None;
        for c in changes {
            match (c.state == LocalisationState::Lost, since) {
                (true, None) => {
                    lost.episodes += 1;
                    since = Some(c.t_s);
                }
                (false, Some(from)) => {
                    lost.seconds += c.t_s - from;
                    since = None;
                }
                _ => {}
            }
        }
        if let Some(from) = since {
            lost.seconds += (end_s - from).max(0.0);
            lost.at_end = true;
        }
        lost
    }
}

/// Everything recorded for one rover.
#[derive(Clone, Debug, Default)]
pub struct RoverSlamRecord {
    /// Graded poses, one per [`ESTIMATE_PERIOD`].
    pub checks: Vec<PoseCheck>,
    /// Localisation state changes.
    pub changes: Vec<StateChange>,
    /// The latest map.
    pub map: Option<OccupancyGrid>,
    /// Wall time the rover's SLAM took, seconds (set when the mission finishes).
    pub wall_s: f64,
    next_check: Time,
}

impl RoverSlamRecord {
    /// Keeps a pose estimate, with the standard deviations published with it, if a check is
    /// due.
    pub fn pose(
        &mut self,
        t: Time,
        estimate: Pose2,
        sigma: Option<(f64, f64)>,
        odometry: Pose2,
        truth: Pose2,
    ) {
        if t >= self.next_check {
            self.next_check = t + ESTIMATE_PERIOD;
            self.checks.push(PoseCheck {
                t,
                estimate,
                odometry,
                truth,
                sigma,
                optimised: None,
            });
        }
    }
}

/// A scan's pose this close in time to a check stands for it (scans come at 10 Hz).
const SAME_INSTANT_S: f64 = 0.051;

impl RoverSlamRecord {
    /// The final trajectory's errors against the truth, once attached.
    pub fn trajectory_error(&self) -> Option<PoseErrors> {
        self.checks.iter().any(|c| c.optimised.is_some()).then(|| {
            pose_errors(
                self.checks
                    .iter()
                    .filter_map(|c| c.optimised.map(|o| (o, c.truth))),
            )
        })
    }

    /// The final trajectory's RMS position error after the best rigid alignment, metres.
    pub fn trajectory_error_aligned_m(&self) -> Option<f64> {
        aligned_rmse(
            &self
                .checks
                .iter()
                .filter_map(|c| c.optimised.map(|o| (o.position(), c.truth.position())))
                .collect::<Vec<_>>(),
        )
    }

    /// Attaches the rover's final trajectory (`(t_s, pose)` per scan, in time order) to the
    /// checks it covers.
    pub fn attach_trajectory(&mut self, trajectory: &[(f64, Pose2)]) {
        for c in &mut self.checks {
            let t = c.t.as_secs_f64();
            let k = trajectory.partition_point(|(s, _)| *s < t);
            c.optimised = [k.checked_sub(1), Some(k)]
                .into_iter()
                .flatten()
                .filter_map(|i| trajectory.get(i))
                .filter(|(s, _)| (s - t).abs() <= SAME_INSTANT_S)
                .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
                .map(|(_, p)| *p);
        }
    }
}

/// Errors of a pose source against the truth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PoseErrors {
    /// Root mean square position error, metres.
    pub rmse_m: f64,
    /// Largest position error, metres.
    pub max_m: f64,
    /// Position error at the end, metres.
    pub final_m: f64,
    /// Root mean square heading error, degrees.
    pub heading_rmse_deg: f64,
    /// Share of the instants at most [`POSE_BOUND_M`] off (0 without instants): how often
    /// the pose could be trusted to that bound, the figure issue 3 sets the pose after a slip
    /// burst's recovery against.
    pub share_within_0_2_m: f64,
}

/// The position error the pose after a slip burst's recovery must stay within (issue 3).
pub const POSE_BOUND_M: f64 = 0.2;

/// The errors of `(estimate, truth)` pairs in time order.
pub fn pose_errors(pairs: impl Iterator<Item = (Pose2, Pose2)>) -> PoseErrors {
    let (mut sq, mut max, mut sq_yaw, mut n) = (0.0, 0.0f64, 0.0, 0usize);
    let mut within = 0usize;
    let mut last = 0.0;
    for (estimate, truth) in pairs {
        let d = estimate.relative_to(&truth);
        let e = estimate.position().distance_m(truth.position());
        sq += e * e;
        max = max.max(e);
        within += usize::from(e <= POSE_BOUND_M);
        sq_yaw += d.yaw_rad.to_degrees().powi(2);
        n += 1;
        last = e;
    }
    if n == 0 {
        return PoseErrors::default();
    }
    let n = n as f64;
    PoseErrors {
        rmse_m: (sq / n).sqrt(),
        max_m: max,
        final_m: last,
        heading_rmse_deg: (sq_yaw / n).sqrt(),
        share_within_0_2_m: within as f64 / n,
    }
}

/// Whether the covariance a pose is published with says how far it may be off: the share of
/// the instants whose error lies inside the published 95 % region, for position (a circle of
/// the published standard deviation, the chi-square bound of two degrees of freedom) and for
/// heading (one degree of freedom). A consistent estimate reads 95 % for both; a covariance
/// that only says how well the last scan fitted the map reads far less.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct CovarianceCheck {
    /// Instants published with a covariance.
    pub instants: usize,
    /// Share of them whose position error lies inside the 95 % circle.
    pub position_inside_95: f64,
    /// Share whose heading error lies inside the 95 % interval.
    pub heading_inside_95: f64,
    /// The median published position standard deviation, metres.
    pub median_sigma_m: f64,
}

/// The 95 % quantile of the chi-square distribution with two degrees of freedom.
const CHI2_2_95: f64 = 5.991;
/// ... and with one.
const CHI2_1_95: f64 = 3.841;

/// Grades the published standard deviations of `checks` against their errors.
pub fn covariance_check(checks: &[PoseCheck]) -> CovarianceCheck {
    let mut sigmas = Vec::new();
    let (mut position, mut heading) = (0usize, 0usize);
    for c in checks {
        let Some((sigma_m, sigma_rad)) = c.sigma else {
            continue;
        };
        let e = c.estimate.position().distance_m(c.truth.position());
        let yaw = c.estimate.relative_to(&c.truth).yaw_rad;
        position += usize::from(e * e <= CHI2_2_95 * sigma_m * sigma_m);
        heading += usize::from(yaw * yaw <= CHI2_1_95 * sigma_rad * sigma_rad);
        sigmas.push(sigma_m);
    }
    if sigmas.is_empty() {
        return CovarianceCheck::default();
    }
    let n = sigmas.len();
    sigmas.sort_by(f64::total_cmp);
    CovarianceCheck {
        instants: n,
        position_inside_95: position as f64 / n as f64,
        heading_inside_95: heading as f64 / n as f64,
        median_sigma_m: sigmas[n / 2],
    }
}

/// The RMS distance of `(estimate, truth)` point pairs once the estimates are moved by the
/// rotation and translation that fit them best to the truth (the closed form of Horn 1987 /
/// Umeyama 1991 in the plane); `None` without pairs.
pub fn aligned_rmse(pairs: &[(Point2, Point2)]) -> Option<f64> {
    if pairs.is_empty() {
        return None;
    }
    let n = pairs.len() as f64;
    let mean = |f: fn(&(Point2, Point2)) -> (f64, f64)| {
        let (x, y) = pairs
            .iter()
            .map(f)
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        (x / n, y / n)
    };
    let (ax, ay) = mean(|p| (p.0.x_m, p.0.y_m));
    let (bx, by) = mean(|p| (p.1.x_m, p.1.y_m));
    let (mut dot, mut cross) = (0.0, 0.0);
    for (a, b) in pairs {
        let (px, py, qx, qy) = (a.x_m - ax, a.y_m - ay, b.x_m - bx, b.y_m - by);
        dot += px * qx + py * qy;
        cross += px * qy - py * qx;
    }
    let (s, c) = cross.atan2(dot).sin_cos();
    let sq: f64 = pairs
        .iter()
        .map(|(a, b)| {
            let (px, py) = (a.x_m - ax, a.y_m - ay);
            let (x, y) = (c * px - s * py + bx, s * px + c * py + by);
            (x - b.x_m).powi(2) + (y - b.y_m).powi(2)
        })
        .sum();
    Some((sq / n).sqrt())
}

/// How one rover's map compares with the truth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MapGrade {
    /// Cells the map calls occupied.
    pub occupied_cells: usize,
    /// Of those, the fraction within one map cell of a true lidar-visible obstacle.
    pub occupied_correct: f64,
    /// Cells the map calls free.
    pub free_cells: usize,
    /// Of those, the fraction that are truly free of obstacles (hazards count as free here:
    /// the lidar cannot see them).
    pub free_correct: f64,
    /// Fraction of the explorable area the map knows (free or occupied).
    pub explorable_known: f64,
    /// Cells the map calls hazards (from the depth camera).
    pub hazard_cells: usize,
    /// Of those, the fraction within one map cell of ground the rover truly must not enter
    /// (a hazard or an obstacle in the truth's traversability).
    pub hazard_correct: f64,
    /// True hazard cells (crater interiors, too-steep ground) the map knows.
    pub true_hazards_known: usize,
    /// Of those, the fraction the map marks as hazard or obstacle: the rest it would let the
    /// rover drive into.
    pub true_hazards_flagged: f64,
    /// True hazard cells within [`PATH_REACH_M`] of where the rover truly drove, known to
    /// the map or not: the ground the depth camera had to see.
    pub path_hazards: usize,
    /// Of those, the fraction the map marks as hazard or obstacle.
    pub path_hazards_flagged: f64,
    /// Of those, the fraction with a hazard or obstacle cell of the map within
    /// [`NEAR_FLAG_M`] (per axis, whole map cells): what the map marks there is mostly the
    /// same hazard a little off (the SLAM error, the hazard layer's coarser cells), though it
    /// may be a neighbouring one, such as a marked rim beside an unmarked interior.
    pub path_hazards_flagged_nearby: f64,
    /// Obstacle faces the map looked at: true lidar-visible obstacle cells beside a truly
    /// open cell the map knows (free, occupied or hazard).
    pub obstacle_faces_seen: usize,
    /// Of those, the fraction with an occupied map cell within one map cell: the obstacles
    /// the rover looked at that its map keeps. [`occupied_correct`](Self::occupied_correct)
    /// grades what the map marks; this grades what it leaves out.
    pub obstacle_faces_marked: f64,
}

impl MapGrade {
    /// Share of the cells the map knows (free, occupied or hazard) graded right, each as
    /// its kind is graded above: an occupied or hazard cell within a cell of a true obstacle
    /// or untraversable ground, a free cell where the truth holds no lidar-visible obstacle
    /// (a crater's floor too, since the lidar cannot see it: so a free cell turned hazard
    /// can only lower this).
    pub fn known_correct(&self) -> f64 {
        let right = self.occupied_correct * self.occupied_cells as f64
            + self.free_correct * self.free_cells as f64
            + self.hazard_correct * self.hazard_cells as f64;
        right / (self.occupied_cells + self.free_cells + self.hazard_cells).max(1) as f64
    }
}

/// How near a true hazard a marked cell must lie for
/// [`MapGrade::path_hazards_flagged_nearby`], metres.
pub const NEAR_FLAG_M: f64 = 0.25;

/// How near the rover's path a true hazard must lie to count in
/// [`MapGrade::path_hazards`], metres.
pub const PATH_REACH_M: f64 = 1.5;

/// A published map as a grid of its cell values; `None` if its size does not match its data.
pub fn map_grid(map: &OccupancyGrid) -> Option<Grid<i8>> {
    let geometry = GridGeometry {
        width: map.info.width as usize,
        height: map.info.height as usize,
        resolution_m: map.info.resolution_m as f64,
        origin: Point2::new(map.info.origin.position.x, map.info.origin.position.y),
    };
    Grid::from_cells(geometry, map.data.clone())
}

/// Whether any cell of `grid` within `reach_m` (per axis) of `p` satisfies `pred`. `p` may
/// lie outside the grid: a map's wall drawn a cell past the truth's outermost wall cells is
/// still within reach of them.
fn any_within<T>(grid: &Grid<T>, p: Point2, reach_m: f64, pred: impl Fn(&T) -> bool) -> bool {
    let g = grid.geometry();
    // Less a hair: a map's f32 resolution (0.05 m reads 0.050000001) must not make one
    // cell's reach two.
    let reach = (reach_m / g.resolution_m - 1e-6).ceil() as i64;
    let fx = ((p.x_m - g.origin.x_m) / g.resolution_m).floor();
    let fy = ((p.y_m - g.origin.y_m) / g.resolution_m).floor();
    if !(fx.is_finite() && fy.is_finite()) {
        return false;
    }
    let (cx, cy) = (fx as i64, fy as i64);
    (-reach..=reach).any(|dy| {
        (-reach..=reach).any(|dx| {
            let (x, y) = (cx + dx, cy + dy);
            x >= 0 && y >= 0 && grid.get(x as usize, y as usize).is_some_and(&pred)
        })
    })
}

/// Grades `map` (in the arena frame) against `truth`; `path` is where the rover truly was.
pub fn grade_map(map: &OccupancyGrid, truth: &GroundTruth, path: &[Point2]) -> MapGrade {
    match map_grid(map) {
        Some(grid) => grade_grid(&grid, truth, path),
        // A map whose size does not match its data grades as empty.
        None => MapGrade::default(),
    }
}

/// [`grade_map`] on a map's cells (the published values: -1 unknown, 0 free, 100
/// occupied, [`OccupancyGrid::HAZARD`]).
pub fn grade_grid(grid: &Grid<i8>, truth: &GroundTruth, path: &[Point2]) -> MapGrade {
    let res = grid.resolution_m();
    let obstacle_near = |p: Point2| any_within(&truth.lidar_obstacles, p, res, |v| *v);
    let untraversable_near =
        |p: Point2| any_within(&truth.traversability, p, res, |v| *v != TruthCell::Free);
    let mut g = MapGrade::default();
    let (mut occ_ok, mut free_ok, mut hazard_ok) = (0usize, 0usize, 0usize);
    for (cell, v) in grid.iter() {
        let p = grid.geometry().cell_center(cell);
        match *v {
            OccupancyGrid::OCCUPIED => {
                g.occupied_cells += 1;
                occ_ok += usize::from(obstacle_near(p));
            }
            OccupancyGrid::HAZARD => {
                g.hazard_cells += 1;
                hazard_ok += usize::from(untraversable_near(p));
            }
            OccupancyGrid::FREE => {
                g.free_cells += 1;
                free_ok += usize::from(truth.lidar_obstacles.at_world(p) == Some(&false));
            }
            _ => {}
        }
    }
    g.occupied_correct = occ_ok as f64 / g.occupied_cells.max(1) as f64;
    g.free_correct = free_ok as f64 / g.free_cells.max(1) as f64;
    // Explorable cells the map knows: sample the map at each explorable cell's centre.
    let (mut explorable, mut known) = (0usize, 0usize);
    for (c, e) in truth.explorable.iter() {
        if !*e {
            continue;
        }
        explorable += 1;
        let p = truth.explorable.geometry().cell_center(c);
        known += usize::from(
            grid.at_world(p)
                .is_some_and(|v| *v != OccupancyGrid::UNKNOWN),
        );
    }
    g.explorable_known = known as f64 / explorable.max(1) as f64;
    g.hazard_correct = hazard_ok as f64 / g.hazard_cells.max(1) as f64;
    let (seen, marked) = obstacle_faces(grid, truth);
    g.obstacle_faces_seen = seen;
    g.obstacle_faces_marked = marked as f64 / seen.max(1) as f64;
    // One pass over the true hazards grades both: those the map knows anywhere, and all of
    // those near the path.
    let near = near_path(truth.traversability.geometry(), path, PATH_REACH_M);
    let (mut flagged, mut path_flagged, mut path_nearby) = (0usize, 0usize, 0usize);
    for ((c, t), near) in truth.traversability.iter().zip(&near) {
        if *t != TruthCell::Hazard {
            continue;
        }
        let v = grid
            .at_world(truth.traversability.geometry().cell_center(c))
            .copied()
            .unwrap_or(OccupancyGrid::UNKNOWN);
        let marked = usize::from(v == OccupancyGrid::HAZARD || v == OccupancyGrid::OCCUPIED);
        if v != OccupancyGrid::UNKNOWN {
            g.true_hazards_known += 1;
            flagged += marked;
        }
        if *near {
            g.path_hazards += 1;
            path_flagged += marked;
            path_nearby += usize::from(
                marked == 1
                    || any_within(
                        grid,
                        truth.traversability.geometry().cell_center(c),
                        NEAR_FLAG_M,
                        |v| *v == OccupancyGrid::HAZARD || *v == OccupancyGrid::OCCUPIED,
                    ),
            );
        }
    }
    g.true_hazards_flagged = flagged as f64 / g.true_hazards_known.max(1) as f64;
    g.path_hazards_flagged = path_flagged as f64 / g.path_hazards.max(1) as f64;
    g.path_hazards_flagged_nearby = path_nearby as f64 / g.path_hazards.max(1) as f64;
    g
}

/// The true obstacle faces `grid` looked at, and how many of them it marks occupied within
/// one of its cells (see [`MapGrade::obstacle_faces_seen`]).
fn obstacle_faces(grid: &Grid<i8>, truth: &GroundTruth) -> (usize, usize) {
    let obstacles = &truth.lidar_obstacles;
    let geo = obstacles.geometry();
    let known_open = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && obstacles.get(x as usize, y as usize) == Some(&false)
            && grid
                .at_world(geo.cell_center(realms_core::Cell {
                    x: x as usize,
                    y: y as usize,
                }))
                .is_some_and(|v| *v != OccupancyGrid::UNKNOWN)
    };
    let (mut seen, mut marked) = (0usize, 0usize);
    for (cell, obstacle) in obstacles.iter() {
        if !*obstacle {
            continue;
        }
        let (x, y) = (cell.x as i64, cell.y as i64);
        let face = (-1..=1).any(|dy| (-1..=1).any(|dx| known_open(x + dx, y + dy)));
        if face {
            seen += 1;
            marked += usize::from(any_within(
                grid,
                geo.cell_center(cell),
                grid.resolution_m(),
                |v| *v == OccupancyGrid::OCCUPIED,
            ));
        }
    }
    (seen, marked)
}

/// The bands of [`CraterCells`]: their upper edges, as a share of a crater's radius from its
/// centre.
pub const CRATER_BANDS: [f64; 5] = [0.5, 0.8, 0.9, 0.95, 1.0];

/// Cells of each band of [`CRATER_BANDS`].
pub type BandCounts = [usize; CRATER_BANDS.len()];

/// The crater part of [`MapGrade::path_hazards_flagged`] (true hazard cells inside a
/// crater's rim, not steep floor outside one), sorted by where in their crater the cells
/// lie and what a map says of them, so a miss at the crest a cell off can be told from a
/// bowl never judged.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CraterCells {
    /// Marked hazard or occupied.
    pub marked: BandCounts,
    /// Free, with a mark within [`CREST_SLACK_M`] (per axis).
    pub free_mark_near: BandCounts,
    /// Free, no mark that near.
    pub free: BandCounts,
    /// Unknown.
    pub unknown: BandCounts,
}

/// How near a mark must lie for [`CraterCells::free_mark_near`], metres: a hazard cell of
/// 10 cm drawn a cell off.
pub const CREST_SLACK_M: f64 = 0.1;

impl CraterCells {
    /// Adds another map's counts.
    pub fn add(&mut self, o: &CraterCells) {
        for b in 0..CRATER_BANDS.len() {
            self.marked[b] += o.marked[b];
            self.free_mark_near[b] += o.free_mark_near[b];
            self.free[b] += o.free[b];
            self.unknown[b] += o.unknown[b];
        }
    }
}

/// Sorts the true crater cells within [`PATH_REACH_M`] of `path` by where in their crater
/// they lie (`craters`: centre and rim radius, metres) and what `grid` says of them. Cells of
/// steep floor outside every crater are left out.
pub fn crater_cells(
    grid: &Grid<i8>,
    truth: &GroundTruth,
    craters: &[(Point2, f64)],
    path: &[Point2],
) -> CraterCells {
    let geo = truth.traversability.geometry();
    let near = near_path(geo, path, PATH_REACH_M);
    let is_mark = |v: &i8| *v == OccupancyGrid::HAZARD || *v == OccupancyGrid::OCCUPIED;
    let mut out = CraterCells::default();
    for ((c, t), near) in truth.traversability.iter().zip(&near) {
        if *t != TruthCell::Hazard || !*near {
            continue;
        }
        let p = geo.cell_center(c);
        let share = craters
            .iter()
            .map(|(centre, r)| p.distance_m(*centre) / r)
            .fold(f64::INFINITY, f64::min);
        let Some(band) = CRATER_BANDS.iter().position(|edge| share < *edge) else {
            continue;
        };
        let v = grid.at_world(p).copied().unwrap_or(OccupancyGrid::UNKNOWN);
        let count = if is_mark(&v) {
            &mut out.marked
        } else if v == OccupancyGrid::UNKNOWN {
            &mut out.unknown
        } else if any_within(grid, p, CREST_SLACK_M, is_mark) {
            &mut out.free_mark_near
        } else {
            &mut out.free
        };
        count[band] += 1;
    }
    out
}

/// Per cell of `geo`, whether it lies within `reach_m` of a point of `path`. Points closer
/// than a cell to the last one stamped add nothing and are skipped.
fn near_path(geo: &GridGeometry, path: &[Point2], reach_m: f64) -> Vec<bool> {
    let mut near = vec![false; geo.len()];
    let mut last: Option<Point2> = None;
    for p in path {
        if last.is_some_and(|q| q.distance_m(*p) < geo.resolution_m) {
            continue;
        }
        last = Some(*p);
        for cell in geo.cells_within(*p, reach_m) {
            near[geo.index(cell)] = true;
        }
    }
    near
}

/// One rover's SLAM in `mission.json`.
#[derive(Clone, Debug, Serialize)]
pub struct RoverSlamSummary {
    /// SLAM's pose estimate against the truth, as published at the time.
    pub pose_error: PoseErrors,
    /// Whether the covariance published with each pose says how far it may be off.
    pub pose_covariance: CovarianceCheck,
    /// The absolute trajectory error: SLAM's final trajectory (loop closures applied to
    /// past poses) against the truth at the same instants; `None` if none was attached.
    pub trajectory_error: Option<PoseErrors>,
    /// The RMS position error of the final trajectory after the rigid motion that best lays
    /// it on the truth is taken out: the absolute trajectory error as the TUM RGB-D benchmark
    /// defines it (Sturm et al., IROS 2012), blind to a drift of the whole map against the
    /// start, metres.
    pub trajectory_error_aligned_m: Option<f64>,
    /// Wheel odometry against the truth, the baseline.
    pub odometry_error: PoseErrors,
    /// Graded instants (one per second of scans).
    pub checks: usize,
    /// Every change of localisation state.
    pub localisation: Vec<StateChange>,
    /// The final map graded against the truth, if the rover published one.
    pub map: Option<MapGrade>,
    /// The map's files in the results folder, if any.
    pub map_png: Option<String>,
}

impl RoverSlamRecord {
    /// The summary for the report.
    pub fn summary(&self, truth: &GroundTruth, map_png: Option<String>) -> RoverSlamSummary {
        RoverSlamSummary {
            pose_error: pose_errors(self.checks.iter().map(|c| (c.estimate, c.truth))),
            pose_covariance: covariance_check(&self.checks),
            trajectory_error: self.trajectory_error(),
            trajectory_error_aligned_m: self.trajectory_error_aligned_m(),
            odometry_error: pose_errors(self.checks.iter().map(|c| (c.odometry, c.truth))),
            checks: self.checks.len(),
            localisation: self.changes.clone(),
            map: self.map.as_ref().map(|m| {
                let path: Vec<Point2> = self.checks.iter().map(|c| c.truth.position()).collect();
                grade_map(m, truth, &path)
            }),
            map_png,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lost_time_adds_each_episode_and_runs_the_last_to_the_end() {
        let change = |t_s, state| StateChange {
            t_s,
            state,
            reason: String::new(),
        };
        let changes = [
            change(10.0, LocalisationState::OdometryUnreliable),
            change(20.0, LocalisationState::Lost),
            change(25.0, LocalisationState::Tracking),
            change(40.0, LocalisationState::Lost),
            change(41.0, LocalisationState::Lost),
            change(50.0, LocalisationState::OdometryUnreliable),
            change(90.0, LocalisationState::Lost),
        ];
        let lost = LostTime::of(&changes, 100.0);
        assert_eq!(lost.episodes, 3);
        assert!((lost.seconds - (5.0 + 10.0 + 10.0)).abs() < 1e-9);
        assert!(lost.at_end);
        let recovered = LostTime::of(&changes[..6], 100.0);
        assert_eq!(recovered.episodes, 2);
        assert!((recovered.seconds - 15.0).abs() < 1e-9);
        assert!(!recovered.at_end);
        assert_eq!(LostTime::of(&[], 100.0), LostTime::default());
    }

    /// A published map of `width x height` 5 cm cells at the arena's origin.
    fn map_msg(width: u32, height: u32, data: Vec<i8>) -> OccupancyGrid {
        OccupancyGrid {
            info: realms_core::msgs::MapMetaData {
                resolution_m: 0.05,
                width,
                height,
                ..Default::default()
            },
            data,
            ..Default::default()
        }
    }

    #[test]
    fn the_cells_near_a_path_are_those_within_reach_of_one_of_its_points() {
        let geo = GridGeometry {
            width: 10,
            height: 10,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        // At the centre of cell (0, 0), 0.11 m reaches its two side neighbours (0.1 m) but
        // not the diagonal one (0.14 m); a second point at the centre of (5, 5) adds its
        // cross of 5.
        let path = [
            Point2::new(0.05, 0.05),
            Point2::new(0.05, 0.05),
            Point2::new(0.55, 0.55),
        ];
        let near = near_path(&geo, &path, 0.11);
        let cells: Vec<(usize, usize)> = near
            .iter()
            .enumerate()
            .filter(|(_, n)| **n)
            .map(|(i, _)| (i % 10, i / 10))
            .collect();
        assert_eq!(
            cells,
            vec![
                (0, 0),
                (1, 0),
                (0, 1),
                (5, 4),
                (4, 5),
                (5, 5),
                (6, 5),
                (5, 6)
            ]
        );
    }

    #[test]
    fn a_hazard_marked_a_little_off_counts_as_nearby_but_not_as_flagged() {
        let geo = GridGeometry {
            width: 40,
            height: 40,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        // The truth: a crater interior of 4 x 4 cells at cells 10..14, and a second one at
        // 30..34 the map never marks.
        let mut traversability = Grid::new(geo, TruthCell::Free);
        let mut map = vec![OccupancyGrid::FREE; geo.width * geo.height];
        for y in 10..14 {
            for x in 10..14 {
                *traversability.get_mut(x, y).expect("inside") = TruthCell::Hazard;
                *traversability.get_mut(x + 20, y + 20).expect("inside") = TruthCell::Hazard;
                // The map marks the first 0.1 m east of where it is.
                map[y * geo.width + x + 2] = OccupancyGrid::HAZARD;
            }
        }
        let truth = GroundTruth {
            traversability,
            lidar_obstacles: Grid::new(geo, false),
            explorable: Grid::new(geo, true),
            explorable_area_m2: 4.0,
        };
        let msg = map_msg(40, 40, map);
        let g = grade_map(&msg, &truth, &[Point2::new(1.0, 1.0)]);
        assert_eq!(g.path_hazards, 32);
        // Half of the first block is under the shifted mark; all of it has one within
        // 0.25 m; the second block has none.
        assert!((g.path_hazards_flagged - 8.0 / 32.0).abs() < 1e-12, "{g:?}");
        assert!(
            (g.path_hazards_flagged_nearby - 16.0 / 32.0).abs() < 1e-12,
            "{g:?}"
        );
    }

    #[test]
    fn crater_cells_are_sorted_by_where_in_their_crater_and_what_the_map_says() {
        use realms_core::Cell;
        let geo = GridGeometry {
            width: 40,
            height: 40,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        // A crater of 0.5 m radius centred on the corner of cells (19, 19) and (20, 20).
        let (centre, radius) = (Point2::new(1.0, 1.0), 0.5);
        let cells_of = || (0..40).flat_map(|y| (0..40).map(move |x| Cell { x, y }));
        let mut traversability = Grid::new(geo, TruthCell::Free);
        for c in cells_of() {
            if geo.cell_center(c).distance_m(centre) < radius {
                *traversability.get_mut(c.x, c.y).expect("inside") = TruthCell::Hazard;
            }
        }
        // Steep floor outside the crater is not counted.
        *traversability.get_mut(0, 0).expect("inside") = TruthCell::Hazard;
        let truth = GroundTruth {
            traversability,
            lidar_obstacles: Grid::new(geo, false),
            explorable: Grid::new(geo, true),
            explorable_area_m2: 4.0,
        };
        // The map marks the crater out to 0.45 m of its centre, calls the rest free but for
        // the cells west of x = 0.6 m, which it never saw.
        let mut map = Grid::new(geo, OccupancyGrid::FREE);
        for c in cells_of() {
            let p = geo.cell_center(c);
            let v = map.get_mut(c.x, c.y).expect("inside");
            if p.distance_m(centre) < 0.45 {
                *v = OccupancyGrid::HAZARD;
            } else if p.x_m < 0.6 {
                *v = OccupancyGrid::UNKNOWN;
            }
        }
        let cells = crater_cells(&map, &truth, &[(centre, radius)], &[centre]);
        let share = |c: Cell| geo.cell_center(c).distance_m(centre) / radius;
        let (mut marked, mut near, mut unknown) = ([0; 5], [0; 5], [0; 5]);
        for (c, t) in truth.traversability.iter() {
            if *t != TruthCell::Hazard || c == (Cell { x: 0, y: 0 }) {
                continue;
            }
            let s = share(c);
            let band = CRATER_BANDS.iter().position(|e| s < *e).expect("inside");
            let p = geo.cell_center(c);
            if p.distance_m(centre) < 0.45 {
                marked[band] += 1;
            } else if p.x_m < 0.6 {
                unknown[band] += 1;
            } else {
                // The ring from 0.45 to 0.5 m is one cell wide: a mark is always beside it.
                near[band] += 1;
            }
        }
        assert_eq!(cells.marked, marked);
        assert_eq!(cells.free_mark_near, near);
        assert_eq!(cells.free, [0; 5]);
        assert_eq!(cells.unknown, unknown);
        // Within 0.45 m is within 0.9 of the radius; the outer bands hold the free ring.
        assert_eq!(cells.marked[3..], [0, 0]);
        assert!(cells.free_mark_near[3] > 0 && cells.free_mark_near[4] > 0);
        assert!(cells.unknown.iter().sum::<usize>() > 0);
    }

    #[test]
    fn a_wall_drawn_a_cell_past_the_truths_edge_is_right_and_two_cells_past_is_not() {
        let geo = GridGeometry {
            width: 20,
            height: 20,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        // The truth's outermost column is wall.
        let mut lidar_obstacles = Grid::new(geo, false);
        for y in 0..20 {
            *lidar_obstacles.get_mut(19, y).expect("inside") = true;
        }
        let truth = GroundTruth {
            traversability: Grid::new(geo, TruthCell::Free),
            lidar_obstacles,
            explorable: Grid::new(geo, true),
            explorable_area_m2: 1.0,
        };
        // The map is 22 columns wide over the same origin: its wall is drawn in column 20,
        // one cell past the truth's edge, for rows 0..10 and in column 21 for rows 10..20.
        let mut data = vec![OccupancyGrid::FREE; 22 * 20];
        for y in 0..20 {
            data[y * 22 + 19] = OccupancyGrid::UNKNOWN;
            data[y * 22 + if y < 10 { 20 } else { 21 }] = OccupancyGrid::OCCUPIED;
            data[y * 22 + if y < 10 { 21 } else { 20 }] = OccupancyGrid::UNKNOWN;
        }
        let msg = map_msg(22, 20, data);
        let g = grade_map(&msg, &truth, &[Point2::new(0.5, 0.5)]);
        assert_eq!(g.occupied_cells, 20);
        assert!((g.occupied_correct - 0.5).abs() < 1e-12, "{g:?}");
        // The map knows column 18 free beside all 20 wall cells. It keeps rows 0..10 of the
        // wall, and row 10 too through the marked cell diagonal to it, at (20, 9); rows
        // 11..20 are drawn two cells off and left out.
        assert_eq!(g.obstacle_faces_seen, 20);
        assert!(
            (g.obstacle_faces_marked - 11.0 / 20.0).abs() < 1e-12,
            "{g:?}"
        );
    }

    #[test]
    fn obstacle_faces_count_only_where_the_map_knows_the_open_cell_beside_them() {
        let geo = GridGeometry {
            width: 10,
            height: 10,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        // A wall along row 5, open on both sides. The map knows only the rows below it,
        // and only in columns 0..4; it marks the wall in columns 0..2, and at column 7,
        // where it knows no open cell beside it.
        let mut lidar_obstacles = Grid::new(geo, false);
        for x in 0..10 {
            *lidar_obstacles.get_mut(x, 5).expect("inside") = true;
        }
        let truth = GroundTruth {
            traversability: Grid::new(geo, TruthCell::Free),
            lidar_obstacles,
            explorable: Grid::new(geo, true),
            explorable_area_m2: 1.0,
        };
        let mut data = vec![OccupancyGrid::UNKNOWN; 100];
        for y in 0..5 {
            for x in 0..4 {
                data[y * 10 + x] = OccupancyGrid::FREE;
            }
        }
        for x in [0, 1, 7] {
            data[50 + x] = OccupancyGrid::OCCUPIED;
        }
        let g = grade_map(&map_msg(10, 10, data), &truth, &[Point2::new(0.1, 0.1)]);
        // Wall cells 0..5 touch a known open cell (cell 4 diagonally); of those, 0..3 have
        // a marked cell within one cell.
        assert_eq!(g.obstacle_faces_seen, 5);
        assert!((g.obstacle_faces_marked - 3.0 / 5.0).abs() < 1e-12, "{g:?}");
    }

    #[test]
    fn known_cells_right_weighs_each_kind_by_its_cells() {
        let g = MapGrade {
            occupied_cells: 10,
            occupied_correct: 0.5,
            free_cells: 80,
            free_correct: 1.0,
            hazard_cells: 10,
            hazard_correct: 0.2,
            ..MapGrade::default()
        };
        // 5 + 80 + 2 of 100 cells right.
        assert!((g.known_correct() - 0.87).abs() < 1e-12, "{g:?}");
        assert_eq!(MapGrade::default().known_correct(), 0.0);
    }

    #[test]
    fn pose_errors_count_the_instants_within_the_bound() {
        let truth = Pose2::new(1.0, 2.0, 0.5);
        // Off by 0.1, 0.2 (on the bound), 0.3 and 0.0 m: three of four within.
        let pairs = [0.1, 0.2, 0.3, 0.0].map(|dx| (Pose2::new(1.0 + dx, 2.0, 0.5), truth));
        let e = pose_errors(pairs.into_iter());
        assert!((e.share_within_0_2_m - 0.75).abs() < 1e-12, "{e:?}");
        assert!((e.max_m - 0.3).abs() < 1e-12 && e.final_m == 0.0);
        assert!((e.rmse_m - (0.14f64 / 4.0).sqrt()).abs() < 1e-12);
        assert_eq!(pose_errors(std::iter::empty()).share_within_0_2_m, 0.0);
    }

    #[test]
    fn a_covariance_is_graded_by_the_errors_inside_its_95_percent_region() {
        let truth = Pose2::new(1.0, 2.0, 0.5);
        let check = |dx: f64, dyaw: f64, sigma: Option<(f64, f64)>| PoseCheck {
            t: Time::ZERO,
            estimate: Pose2::new(1.0 + dx, 2.0, 0.5 + dyaw),
            odometry: truth,
            truth,
            sigma,
            optimised: None,
        };
        // 0.1 m standard deviation: the 95 % circle's radius is 0.245 m. Headings at 0.01
        // rad: the interval is 0.0196 rad.
        let checks = [
            check(0.24, 0.019, Some((0.1, 0.01))),
            check(0.25, 0.0, Some((0.1, 0.01))),
            check(-0.1, -0.02, Some((0.1, 0.01))),
            check(0.0, 0.0, Some((0.3, 0.01))),
            // Published without a covariance: not graded.
            check(5.0, 1.0, None),
        ];
        let c = covariance_check(&checks);
        assert_eq!(c.instants, 4);
        assert!((c.position_inside_95 - 0.75).abs() < 1e-12, "{c:?}");
        assert!((c.heading_inside_95 - 0.75).abs() < 1e-12, "{c:?}");
        assert_eq!(c.median_sigma_m, 0.1);
        assert_eq!(covariance_check(&[]), CovarianceCheck::default());
    }

    #[test]
    fn aligned_error_ignores_a_rigid_motion_and_keeps_a_change_of_shape() {
        let est = [(0.0, 0.0), (4.0, 0.0), (4.0, 3.0), (-1.0, 2.0)];
        let (s, c) = 0.5f64.sin_cos();
        let moved: Vec<(Point2, Point2)> = est
            .iter()
            .map(|&(x, y)| {
                let truth = Point2::new(c * x - s * y + 3.0, s * x + c * y - 2.0);
                (Point2::new(x, y), truth)
            })
            .collect();
        assert!(aligned_rmse(&moved).expect("pairs") < 1e-9);
        // A rod 2 m long estimated where the truth is 4 m long: no rigid motion helps, each
        // end stays 1 m off.
        let stretched = [
            (Point2::new(-1.0, 0.0), Point2::new(-2.0, 5.0)),
            (Point2::new(1.0, 0.0), Point2::new(2.0, 5.0)),
        ];
        let e = aligned_rmse(&stretched).expect("pairs");
        assert!((e - 1.0).abs() < 1e-9, "{e}");
        assert_eq!(aligned_rmse(&[]), None);
    }
}
