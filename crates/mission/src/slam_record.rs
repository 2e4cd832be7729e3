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

/// Everything recorded for one rover.
#[derive(Clone, Debug, Default)]
pub struct RoverSlamRecord {
    /// Graded poses, one per [`ESTIMATE_PERIOD`].
    pub checks: Vec<PoseCheck>,
    /// Localisation state changes.
    pub changes: Vec<StateChange>,
    /// The latest map.
    pub map: Option<OccupancyGrid>,
    next_check: Time,
}

impl RoverSlamRecord {
    /// Keeps a pose estimate if a check is due.
    pub fn pose(&mut self, t: Time, estimate: Pose2, odometry: Pose2, truth: Pose2) {
        if t >= self.next_check {
            self.next_check = t + ESTIMATE_PERIOD;
            self.checks.push(PoseCheck {
                t,
                estimate,
                odometry,
                truth,
            });
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
}

fn errors(checks: &[PoseCheck], pick: impl Fn(&PoseCheck) -> Pose2) -> PoseErrors {
    if checks.is_empty() {
        return PoseErrors::default();
    }
    let (mut sq, mut max, mut sq_yaw) = (0.0, 0.0f64, 0.0);
    for c in checks {
        let d = pick(c).relative_to(&c.truth);
        let e = pick(c).position().distance_m(c.truth.position());
        sq += e * e;
        max = max.max(e);
        sq_yaw += d.yaw_rad.to_degrees().powi(2);
    }
    let n = checks.len() as f64;
    let last = checks.last().expect("not empty");
    PoseErrors {
        rmse_m: (sq / n).sqrt(),
        max_m: max,
        final_m: pick(last).position().distance_m(last.truth.position()),
        heading_rmse_deg: (sq_yaw / n).sqrt(),
    }
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
}

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

/// Whether any cell of `grid` within `reach_m` (per axis) of `p` satisfies `pred`.
fn any_within<T>(grid: &Grid<T>, p: Point2, reach_m: f64, pred: impl Fn(&T) -> bool) -> bool {
    let reach = (reach_m / grid.resolution_m()).ceil() as i64;
    let Some(c) = grid.geometry().world_to_cell(p) else {
        return false;
    };
    (-reach..=reach).any(|dy| {
        (-reach..=reach).any(|dx| {
            let (x, y) = (c.x as i64 + dx, c.y as i64 + dy);
            x >= 0 && y >= 0 && grid.get(x as usize, y as usize).is_some_and(&pred)
        })
    })
}

/// Grades `map` (in the arena frame) against `truth`.
pub fn grade_map(map: &OccupancyGrid, truth: &GroundTruth) -> MapGrade {
    let Some(grid) = map_grid(map) else {
        // A map whose size does not match its data grades as empty.
        return MapGrade::default();
    };
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
    let mut flagged = 0usize;
    for (c, t) in truth.traversability.iter() {
        if *t != TruthCell::Hazard {
            continue;
        }
        match grid
            .at_world(truth.traversability.geometry().cell_center(c))
            .copied()
        {
            None | Some(OccupancyGrid::UNKNOWN) => {}
            Some(v) => {
                g.true_hazards_known += 1;
                flagged += usize::from(v == OccupancyGrid::HAZARD || v == OccupancyGrid::OCCUPIED);
            }
        }
    }
    g.true_hazards_flagged = flagged as f64 / g.true_hazards_known.max(1) as f64;
    g
}

/// One rover's SLAM in `mission.json`.
#[derive(Clone, Debug, Serialize)]
pub struct RoverSlamSummary {
    /// SLAM's pose estimate against the truth.
    pub pose_error: PoseErrors,
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
            pose_error: errors(&self.checks, |c| c.estimate),
            odometry_error: errors(&self.checks, |c| c.odometry),
            checks: self.checks.len(),
            localisation: self.changes.clone(),
            map: self.map.as_ref().map(|m| grade_map(m, truth)),
            map_png,
        }
    }
}
