//! Long straight walls as a heading reference: the directions of the walls the first scan
//! sees, from a pose known exactly, stay fixed, so a later scan that sees a long straight
//! run of points along one of those directions measures the robot's heading absolutely.
//!
//! In a hall the maps' errors are mostly a slow turn of the whole map: over 45 replays a
//! rover's final map agreed with the truth about as well as its final heading did (a
//! correlation of -0.84; BENCHMARKS.md, "The gyro's leftover bias measured out").
//! Structural regularities of built environments are a standard anchor for that drift (e.g.
//! Peasley, Birchfield, Cunningham & Fisher, "Accurate On-line 3D Occupancy Grids Using
//! Manhattan World Constraints", IROS 2012); here the directions actually seen from the
//! start are trusted, and an assumed grid of right angles only if asked
//! ([`WallHeadingConfig::square_references`]).

use realms_core::Point2;
use realms_core::geometry::{LineFit, normalize_angle_rad};

/// How runs of a scan count as walls, and how far from a reference direction one may lie.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallHeadingConfig {
    /// Shortest run that counts as a wall, metres (a boulder's face is shorter).
    pub min_length_m: f64,
    /// Fewest points in a run.
    pub min_points: usize,
    /// Largest distance of a point from the run's line, metres.
    pub max_offset_m: f64,
    /// Largest gap between neighbouring points of a run, metres.
    pub max_gap_m: f64,
    /// A run whose direction (by the tracked heading) lies within this of a reference
    /// direction measures the heading; farther off it is another structure, radians.
    pub gate_rad: f64,
    /// Standard deviation a keyframe's measured heading is never trusted beyond (walls are
    /// not perfectly straight, and the scan plane tilts with the rover), radians. It is
    /// added to what the runs' fits give, so a keyframe's heading is held gently: the
    /// gyro's edges between keyframes set the turn from one keyframe to the next, the walls
    /// over many keyframes where the map as a whole faces (0.5 degrees did better than 0.1
    /// per run and than 1 degree, BENCHMARKS.md).
    pub floor_sigma_rad: f64,
    /// A loop closure between two keyframes whose headings the walls measured is refused
    /// where the turn it asks between them differs from the walls' by more than this many
    /// standard deviations of the two measurements together (`None`: not checked). Walls
    /// hold each heading to about half a degree, so a closure that turns the map two
    /// degrees is a match that fitted the wrong way (BENCHMARKS.md, "Closures searched as
    /// far as a rover can have slid along a wall").
    pub closure_gate_sigmas: Option<f64>,
    /// The directions at right angles to those the first scan saw are references too: the
    /// walls of a hall meet square (the Manhattan world of the module's reference), so a
    /// rover that follows a wall the start could not see still has its heading held.
    pub square_references: bool,
}

impl Default for WallHeadingConfig {
    fn default() -> Self {
        WallHeadingConfig {
            min_length_m: 3.0,
            min_points: 12,
            max_offset_m: 0.05,
            max_gap_m: 0.6,
            gate_rad: 3f64.to_radians(),
            floor_sigma_rad: 0.5f64.to_radians(),
            closure_gate_sigmas: None,
            square_references: false,
        }
    }
}

/// A straight run of a scan: its direction (modulo half a turn) and how well that is known.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallRun {
    /// Direction of the run in the scan's frame, in (-pi/2, pi/2].
    pub direction_rad: f64,
    /// Standard deviation of that direction, radians (the fit's alone, no floor).
    pub sigma_rad: f64,
    /// Length between its end points, metres.
    pub length_m: f64,
    /// Points in the run.
    pub points: usize,
}

/// A line fitted through a run's points by total least squares, with what the run's
/// growth and weight need of it.
struct RunFit {
    /// Direction, in (-pi/2, pi/2].
    direction_rad: f64,
    /// Largest distance of a point from the line, metres.
    worst_offset_m: f64,
    /// Sum of the points' squared positions along the line, m^2.
    spread_along_m2: f64,
    /// Residual variance across the line, m^2.
    variance_across_m2: f64,
}

fn fit_run(points: &[Point2]) -> RunFit {
    let mut fit = RunFit {
        direction_rad: 0.0,
        worst_offset_m: 0.0,
        spread_along_m2: 0.0,
        variance_across_m2: 0.0,
    };
    let Some(line) = LineFit::through(points.iter(), 2) else {
        return fit;
    };
    fit.direction_rad = line.direction_rad;
    let mut across = 0.0;
    for p in points {
        let (a, d) = line.along_across(*p);
        fit.worst_offset_m = fit.worst_offset_m.max(d.abs());
        fit.spread_along_m2 += a * a;
        across += d * d;
    }
    if points.len() > 2 {
        fit.variance_across_m2 = across / (points.len() - 2) as f64;
    }
    fit
}

/// `a` folded into (-pi/2, pi/2]: a line's direction has no sense.
fn half_turn(a: f64) -> f64 {
    let mut d = normalize_angle_rad(a);
    if d > std::f64::consts::FRAC_PI_2 {
        d -= std::f64::consts::PI;
    } else if d <= -std::f64::consts::FRAC_PI_2 {
        d += std::f64::consts::PI;
    }
    d
}

/// The long straight runs of a scan's points, taken in beam order: a run grows point by
/// point while the points stay within `max_offset_m` of its line and `max_gap_m` of each
/// other, and is kept if it is long enough.
pub fn wall_runs(points: &[Point2], cfg: &WallHeadingConfig) -> Vec<WallRun> {
    let mut runs = Vec::new();
    let mut start = 0;
    while start + cfg.min_points <= points.len() {
        let mut end = start + 1;
        // Grow while the next point is near and the run still fits a line; the fit is
        // checked every few points, since a full refit per point is quadratic.
        while end < points.len() && points[end].distance_m(points[end - 1]) <= cfg.max_gap_m {
            let candidate = end + 1;
            if candidate - start >= 3
                && (candidate - start) % 4 == 0
                && fit_run(&points[start..candidate]).worst_offset_m > cfg.max_offset_m
            {
                break;
            }
            end = candidate;
        }
        // Trim the tail until the whole run fits (the check above skipped some points).
        while end - start >= 3 && fit_run(&points[start..end]).worst_offset_m > cfg.max_offset_m {
            end -= 1;
        }
        let run = &points[start..end];
        let length = run[0].distance_m(run[run.len() - 1]);
        if run.len() >= cfg.min_points && length >= cfg.min_length_m {
            let fit = fit_run(run);
            runs.push(WallRun {
                direction_rad: fit.direction_rad,
                sigma_rad: (fit.variance_across_m2 / fit.spread_along_m2.max(1e-12)).sqrt(),
                length_m: length,
                points: run.len(),
            });
            start = end;
        } else {
            start += 1;
        }
    }
    runs
}

/// The wall directions seen from the start, and the heading measurements later scans give.
#[derive(Clone, Debug, PartialEq)]
pub struct WallHeadings {
    cfg: WallHeadingConfig,
    /// Directions in the map frame, in (-pi/2, pi/2].
    references: Vec<f64>,
}

impl WallHeadings {
    /// No reference yet.
    pub fn new(cfg: WallHeadingConfig) -> Self {
        WallHeadings {
            cfg,
            references: Vec::new(),
        }
    }

    /// The reference directions, map frame.
    pub fn references(&self) -> &[f64] {
        &self.references
    }

    /// Takes the long runs of `points` (robot frame, beam order), seen at a heading known
    /// exactly, as the reference directions; runs within the gate of one already taken
    /// are the same direction. With [`WallHeadingConfig::square_references`], each seen
    /// direction's right angle too, where no seen direction lies within the gate of it: a
    /// corner a little off square keeps the wall it was seen to have.
    pub fn set_references(&mut self, yaw_rad: f64, points: &[Point2]) {
        let gate_rad = self.cfg.gate_rad;
        let add = |d: f64, references: &mut Vec<f64>| {
            if references.iter().all(|r| half_turn(d - r).abs() > gate_rad) {
                references.push(d);
            }
        };
        let first_new = self.references.len();
        for run in wall_runs(points, &self.cfg) {
            add(half_turn(yaw_rad + run.direction_rad), &mut self.references);
        }
        if self.cfg.square_references {
            let seen_end = self.references.len();
            for k in first_new..seen_end {
                let across = half_turn(self.references[k] + std::f64::consts::FRAC_PI_2);
                add(across, &mut self.references);
            }
        }
    }

    /// The heading `points` (robot frame, beam order) measure for a robot tracked at
    /// `yaw_rad`: the heading its wall runs along reference directions say, and its
    /// information (1 / rad^2); `None` if no run lies along a reference.
    pub fn measure(&self, yaw_rad: f64, points: &[Point2]) -> Option<(f64, f64)> {
        if self.references.is_empty() {
            return None;
        }
        let (mut weighted, mut information) = (0.0, 0.0);
        for run in wall_runs(points, &self.cfg) {
            let direction = yaw_rad + run.direction_rad;
            let Some(off) = self
                .references
                .iter()
                .map(|r| half_turn(direction - r))
                .filter(|d| d.abs() <= self.cfg.gate_rad)
                .min_by(|a, b| a.abs().total_cmp(&b.abs()))
            else {
                continue;
            };
            // A run of perfectly placed points would claim an exact direction.
            let w = 1.0 / run.sigma_rad.max(1e-5).powi(2);
            weighted += w * off;
            information += w;
        }
        (information > 0.0).then(|| {
            let variance = information.recip() + self.cfg.floor_sigma_rad.powi(2);
            (yaw_rad - weighted / information, variance.recip())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points along the segment from `a` to `b`, `n` of them, each pushed `jitter(i)`
    /// across it.
    fn along(a: Point2, b: Point2, n: usize, jitter: impl Fn(usize) -> f64) -> Vec<Point2> {
        let (dx, dy) = (b.x_m - a.x_m, b.y_m - a.y_m);
        let len = dx.hypot(dy);
        (0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64;
                let j = jitter(i);
                Point2::new(a.x_m + t * dx - j * dy / len, a.y_m + t * dy + j * dx / len)
            })
            .collect()
    }

    #[test]
    fn a_wall_and_a_boulder_give_one_run_along_the_wall() {
        let cfg = WallHeadingConfig::default();
        // A wall 6 m long at 20 degrees, then a boulder's face 0.5 m across.
        let angle = 20f64.to_radians();
        let a = Point2::new(2.0, -3.0);
        let b = Point2::new(2.0 + 6.0 * angle.cos(), -3.0 + 6.0 * angle.sin());
        let mut points = along(a, b, 40, |i| if i % 2 == 0 { 0.01 } else { -0.01 });
        points.extend(along(
            Point2::new(9.0, 3.0),
            Point2::new(9.3, 3.4),
            6,
            |_| 0.0,
        ));
        let runs = wall_runs(&points, &cfg);
        assert_eq!(runs.len(), 1, "{runs:?}");
        assert!((runs[0].direction_rad - angle).abs() < 1e-3, "{runs:?}");
        assert_eq!(runs[0].points, 40);
        assert!(
            runs[0].sigma_rad > 0.0 && runs[0].sigma_rad < 0.005,
            "{runs:?}"
        );
    }

    #[test]
    fn a_corner_splits_into_two_runs() {
        let cfg = WallHeadingConfig::default();
        let mut points = along(Point2::new(5.0, -4.0), Point2::new(5.0, 4.0), 40, |_| 0.0);
        points.extend(along(
            Point2::new(4.8, 4.0),
            Point2::new(-3.0, 4.0),
            40,
            |_| 0.0,
        ));
        let runs = wall_runs(&points, &cfg);
        assert_eq!(runs.len(), 2, "{runs:?}");
        let vertical = runs[0].direction_rad.abs();
        assert!(
            (vertical - std::f64::consts::FRAC_PI_2).abs() < 0.02,
            "{runs:?}"
        );
        assert!(runs[1].direction_rad.abs() < 0.02, "{runs:?}");
    }

    #[test]
    fn a_turned_robot_seeing_the_start_walls_measures_its_heading() {
        let cfg = WallHeadingConfig::default();
        // From the start (heading 0) a wall along x at y = 4 and one along y at x = 6.
        let mut walls = along(Point2::new(6.0, -3.0), Point2::new(6.0, 3.9), 50, |_| 0.0);
        walls.extend(along(
            Point2::new(5.9, 4.0),
            Point2::new(-2.0, 4.0),
            50,
            |_| 0.0,
        ));
        let mut headings = WallHeadings::new(cfg);
        headings.set_references(0.0, &walls);
        assert_eq!(headings.references().len(), 2);
        // Later the robot truly faces 30 degrees; the same walls in its frame.
        let truth = 30f64.to_radians();
        let (s, c) = truth.sin_cos();
        let seen: Vec<Point2> = walls
            .iter()
            .map(|p| Point2::new(c * p.x_m + s * p.y_m, -s * p.x_m + c * p.y_m))
            .collect();
        // Tracked 1.5 degrees off: the walls say where it truly faces.
        let tracked = truth + 1.5f64.to_radians();
        let (yaw, information) = headings.measure(tracked, &seen).expect("walls seen");
        assert!((yaw - truth).abs() < 1e-6, "{}", yaw.to_degrees());
        let floor = cfg.floor_sigma_rad;
        assert!(information <= 1.0 / (floor * floor) + 1e-6, "{information}");
        assert!(information > 0.5 / (floor * floor), "{information}");
        // Tracked 5 degrees off, beyond the gate: the runs may be other structures.
        assert!(headings.measure(truth + 5f64.to_radians(), &seen).is_none());
    }

    #[test]
    fn a_wall_square_to_the_start_walls_measures_the_heading_only_in_a_square_hall() {
        // The start sees one wall, along x at y = 4.
        let start = along(Point2::new(-4.0, 4.0), Point2::new(4.0, 4.0), 50, |_| 0.0);
        // Later, truly facing 100 degrees, the robot sees only a wall along y at x = -5
        // (in the map frame): at right angles to the start's.
        let truth = 100f64.to_radians();
        let (s, c) = truth.sin_cos();
        let seen: Vec<Point2> = along(Point2::new(-5.0, -3.0), Point2::new(-5.0, 5.0), 50, |_| 0.0)
            .iter()
            .map(|p| Point2::new(c * p.x_m + s * p.y_m, -s * p.x_m + c * p.y_m))
            .collect();
        let tracked = truth - 1.0f64.to_radians();
        for square in [false, true] {
            let cfg = WallHeadingConfig {
                square_references: square,
                ..WallHeadingConfig::default()
            };
            let mut headings = WallHeadings::new(cfg);
            headings.set_references(0.0, &start);
            assert_eq!(headings.references().len(), if square { 2 } else { 1 });
            let measured = headings.measure(tracked, &seen);
            if square {
                let (yaw, _) = measured.expect("the square wall measures the heading");
                assert!((yaw - truth).abs() < 1e-6, "{}", yaw.to_degrees());
            } else {
                assert!(measured.is_none(), "{measured:?}");
            }
        }
        // A start that sees both walls of a corner takes no third direction.
        let mut corner = start.clone();
        corner.extend(along(
            Point2::new(5.0, 3.9),
            Point2::new(5.0, -4.0),
            50,
            |_| 0.0,
        ));
        let mut headings = WallHeadings::new(WallHeadingConfig {
            square_references: true,
            ..WallHeadingConfig::default()
        });
        headings.set_references(0.0, &corner);
        assert_eq!(
            headings.references().len(),
            2,
            "{:?}",
            headings.references()
        );
        // One 2 degrees off square keeps the wall as seen, not the assumed right angle,
        // whichever of its walls comes first in the beams.
        let off = 92f64.to_radians();
        let end = Point2::new(4.0 + 8.0 * off.cos(), 4.0 + 8.0 * off.sin());
        let leg = along(Point2::new(4.0, 4.0), end, 50, |_| 0.0);
        for corner in [[start.clone(), leg.clone()].concat(), [leg, start].concat()] {
            let mut headings = WallHeadings::new(WallHeadingConfig {
                square_references: true,
                ..WallHeadingConfig::default()
            });
            headings.set_references(0.0, &corner);
            let refs = headings.references();
            assert_eq!(refs.len(), 2, "{refs:?}");
            for wall in [0.0, off] {
                assert!(
                    refs.iter().any(|r| half_turn(r - wall).abs() < 1e-3),
                    "{refs:?}"
                );
            }
        }
    }
}
