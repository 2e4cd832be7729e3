//! Sub-cell refinement of a scan match on the points themselves: the Normal Distributions
//! Transform of Biber and Straßer ("The normal distributions transform: a new approach to
//! laser scan matching", IROS 2003), with line-like cells matched point to line.
//!
//! The occupancy matcher ([`crate::matcher`]) climbs a bilinear grid whose peaks sit at cell
//! centres. A straight wall's hits all share one offset within their cells, so a match is
//! pulled by up to half a cell (2.5 cm on the 5 cm grid), and each time new walls come into
//! view they are mapped with that offset: in a noise-free simulated hall with exact odometry
//! the rovers' maps drifted 0.10 m in ten minutes (BENCHMARKS.md). Here each coarse cell keeps
//! the mean and spread of the hits that fell in it, which lose nothing to the grid. A cell
//! whose hits lie along a line pulls a point only across that line (its normal from the
//! spread), so the match slides freely along a wall where the grid decides; other cells pull
//! by their full spread. The start is the occupancy match, so the association is local.

use realms_core::{Point2, Pose2};

/// Refinement tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NdtConfig {
    /// Side of the cells whose hits are summarised, metres.
    pub cell_m: f64,
    /// A cell needs this many hits to pull.
    pub min_hits: u32,
    /// ... and this many to pull as a line (fewer along a line pull not at all: a few
    /// grazing hits on a wall can line up across it by chance).
    pub min_line_hits: u32,
    /// Variance added to every spread: the lidar's noise floor, square metres.
    pub noise_var_m2: f64,
    /// A cell whose smaller spread is below this share of its larger one is a line.
    pub line_ratio: f64,
    /// Points farther than this from every cell mean near them are left out, metres.
    pub max_distance_m: f64,
    /// Rounds of association, each followed by Gauss-Newton steps.
    pub rounds: usize,
    /// Gauss-Newton steps per round.
    pub steps: usize,
    /// How far a hit may move along its beam per metre of range while the lidar's plane
    /// tilts with the rover over rolling ground, metres per metre: a rock's outline at the
    /// scan's height shrinks or grows as the plane rises or dips there, and the farther the
    /// rock the more it does. Its square times the range squared is added to each hit's
    /// variance (0: every hit counts as the noise alone).
    pub tilt_spread_per_m: f64,
    /// The tilt's spread lies along the beam alone (a hit moves along its line of sight), not
    /// in every direction.
    pub tilt_spread_along_beam: bool,
    /// How far a hit's outline may move along its beam per metre the lidar's plane has risen
    /// or fallen there since the cell's hits were taken (the hit's height above the ground
    /// under the rover, levelled by the rover's tilt, against the cell's mean): a rock cut
    /// higher is cut narrower. Its square times the height change squared is added to the
    /// hit's variance along the beam (0: off; hits without heights are left alone).
    pub outline_shift_per_height: f64,
    /// A refinement moving the start more than this is not taken, metres ...
    pub max_shift_m: f64,
    /// ... nor one moving it back against the rover's travel by more than this, metres ...
    pub max_hold_back_m: f64,
    /// ... nor (if set) one moving it forward along the travel by more than this, metres.
    /// Along a bare wall the bound above passes the refinement's forward pulls and stops
    /// its backward ones, but on the rovers' replays this one cost more maps than it saved
    /// (BENCHMARKS.md, "A refinement that runs ahead of the wheels").
    pub max_push_ahead_m: Option<f64>,
    /// ... or turning it more than this, radians.
    pub max_turn_rad: f64,
    /// A refinement past the two bounds along the travel above is brought back to the bound it
    /// passed, along the travel only, instead of being dropped: its turn and its move
    /// across the travel are kept. Dropped whole, a refinement that the map pulls back along
    /// a bare wall loses the heading the wall gives it too.
    pub clamp_along_travel: bool,
    /// A scan point on a straight run of the scan (five neighbouring points, see
    /// `surface_directions`) whose run turns from its line cell's line by more than this is
    /// not paired with that cell, radians (`None`: every point is). A line cell drawn where
    /// a wall was seen at two offsets is turned from the wall, and pulls the wall's points
    /// along it.
    pub max_surface_turn_rad: Option<f64>,
}

/// Neighbouring scan points farther apart than this are not one surface, metres.
const NORMAL_NEIGHBOUR_M: f64 = 0.3;

impl Default for NdtConfig {
    fn default() -> Self {
        NdtConfig {
            cell_m: 0.25,
            min_hits: 4,
            min_line_hits: 4,
            noise_var_m2: 1e-4,
            tilt_spread_per_m: 0.0,
            tilt_spread_along_beam: false,
            outline_shift_per_height: 0.0,
            line_ratio: 0.1,
            max_distance_m: 0.25,
            rounds: 2,
            steps: 2,
            // The grid's pull is at most half a 5 cm cell. Refinements allowed further have
            // paired points with surfaces that move as the rover pitches (a rock's outline
            // at the scan's height): on the rovers' replays 0.1 m let a map tear by a metre.
            // And in `realms bench slip` refinements of 3-4 cm held poses back until the
            // wheels' travel was reported as slip (1.7-2.4 false alarms an hour); held back
            // by 2 cm at most, they raise none (BENCHMARKS.md, "Matches refined on the hits").
            max_shift_m: 0.04,
            max_hold_back_m: 0.02,
            max_push_ahead_m: None,
            clamp_along_travel: false,
            max_turn_rad: 0.5f64.to_radians(),
            max_surface_turn_rad: None,
        }
    }
}

/// Running sums of the hits in one cell, about the cell's corner (small numbers keep the
/// spread's cancellation harmless).
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    n: u32,
    /// Hits with a height, and the sum of their heights.
    n_h: u32,
    h: f64,
    x: f64,
    y: f64,
    xx: f64,
    xy: f64,
    yy: f64,
}

/// What one cell pulls with: its mean and the information matrix of a point's offset.
#[derive(Clone, Copy, Debug)]
struct Pull {
    mean: Point2,
    /// The mean height of the cell's hits above the ground under the rover (NaN: unknown).
    height_m: f64,
    /// Symmetric 2 x 2: [xx, xy, yy].
    information: [f64; 3],
}

impl Pull {
    fn mahalanobis2(&self, q: Point2) -> f64 {
        self.information_along(q.x_m - self.mean.x_m, q.y_m - self.mean.y_m)
    }

    /// `v' Omega v`: the cell's information along `v`, times its squared length.
    fn information_along(&self, vx: f64, vy: f64) -> f64 {
        let [a, b, c] = self.information;
        a * vx * vx + 2.0 * b * vx * vy + c * vy * vy
    }

    /// The share of its information a hit keeps once its own spread from the tilting plane
    /// is added to the cell's (exact for a line, whose information lies across it only; the
    /// trace's bound for a blob): `p` the hit in the scan's frame, `beam` the same vector in
    /// the map's frame, `height` the hit's height (NaN: unknown). 1 with both spreads off.
    fn share_kept(&self, cfg: &NdtConfig, p: Point2, beam: (f64, f64), height: f64) -> f64 {
        let tilt2 = cfg.tilt_spread_per_m * cfg.tilt_spread_per_m;
        let shift2 = cfg.outline_shift_per_height * cfg.outline_shift_per_height;
        if tilt2 == 0.0 && shift2 == 0.0 {
            return 1.0;
        }
        let [a, _, d] = self.information;
        // k^2 r^2 u' Omega u, with the beam as long as the range.
        let on_beam = self.information_along(beam.0, beam.1);
        let tilt = if cfg.tilt_spread_along_beam {
            1.0 / (1.0 + tilt2 * on_beam)
        } else {
            1.0 / (1.0 + (a + d) * (tilt2 * (p.x_m * p.x_m + p.y_m * p.y_m)))
        };
        // The outline moved along the beam by as much as the plane's height there did.
        let dh = height - self.height_m;
        if shift2 > 0.0 && dh.is_finite() {
            let r2 = beam.0 * beam.0 + beam.1 * beam.1;
            tilt / (1.0 + shift2 * dh * dh * (on_beam / r2.max(1e-12)))
        } else {
            tilt
        }
    }
}

/// One cell: its sums, and what it pulls with, worked out when hits are added (a
/// refinement looks a cell up far more often than a keyframe changes it).
#[derive(Clone, Copy, Debug, Default)]
struct Cell {
    sums: Sums,
    pull: Option<Pull>,
}

/// Cells in a rectangle that grows to take whatever is added.
#[derive(Clone, Debug, Default)]
struct Cells {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    cells: Vec<Cell>,
}

impl Cells {
    /// Room beyond what is asked for when the rectangle grows, cells.
    const MARGIN: i64 = 16;

    fn index(&self, (x, y): (i64, i64)) -> Option<usize> {
        let (dx, dy) = (x - self.x0, y - self.y0);
        (dx >= 0 && dy >= 0 && (dx as usize) < self.width && (dy as usize) < self.height)
            .then(|| dy as usize * self.width + dx as usize)
    }

    fn get(&self, key: (i64, i64)) -> Option<&Cell> {
        self.index(key).map(|i| &self.cells[i])
    }

    /// Grows the rectangle to hold the cells from `lo` to `hi` (inclusive).
    fn cover(&mut self, lo: (i64, i64), hi: (i64, i64)) {
        if self.index(lo).is_some() && self.index(hi).is_some() {
            return;
        }
        let (old_x1, old_y1) = (self.x0 + self.width as i64, self.y0 + self.height as i64);
        let (x0, y0, x1, y1) = if self.cells.is_empty() {
            (lo.0, lo.1, hi.0 + 1, hi.1 + 1)
        } else {
            (
                self.x0.min(lo.0),
                self.y0.min(lo.1),
                old_x1.max(hi.0 + 1),
                old_y1.max(hi.1 + 1),
            )
        };
        let (x0, y0) = (x0 - Self::MARGIN, y0 - Self::MARGIN);
        let (width, height) = (
            (x1 + Self::MARGIN - x0) as usize,
            (y1 + Self::MARGIN - y0) as usize,
        );
        let mut cells = vec![Cell::default(); width * height];
        for row in 0..self.height {
            let from = row * self.width;
            let to = (row as i64 + self.y0 - y0) as usize * width + (self.x0 - x0) as usize;
            cells[to..to + self.width].copy_from_slice(&self.cells[from..from + self.width]);
        }
        *self = Cells {
            x0,
            y0,
            width,
            height,
            cells,
        };
    }
}

/// The hits of a submap summarised per coarse cell.
#[derive(Clone, Debug)]
pub struct NdtMap {
    cfg: NdtConfig,
    cells: Cells,
}

impl NdtMap {
    /// An empty map.
    pub fn new(cfg: NdtConfig) -> Self {
        NdtMap {
            cfg,
            cells: Cells::default(),
        }
    }

    fn key(&self, p: Point2) -> (i64, i64) {
        (
            (p.x_m / self.cfg.cell_m).floor() as i64,
            (p.y_m / self.cfg.cell_m).floor() as i64,
        )
    }

    /// Adds hits (in the map's frame).
    pub fn insert(&mut self, hits: impl IntoIterator<Item = Point2>) {
        self.insert_with_heights(hits.into_iter().map(|p| (p, f64::NAN)));
    }

    /// Adds hits (in the map's frame), each with its height above the ground under the
    /// rover (NaN where unknown).
    pub fn insert_with_heights(&mut self, hits: impl IntoIterator<Item = (Point2, f64)>) {
        let c = self.cfg.cell_m;
        let keyed: Vec<((Point2, f64), (i64, i64))> =
            hits.into_iter().map(|p| (p, self.key(p.0))).collect();
        let Some(first) = keyed.first().map(|k| k.1) else {
            return;
        };
        let (lo, hi) = keyed.iter().fold((first, first), |(lo, hi), (_, k)| {
            (
                (lo.0.min(k.0), lo.1.min(k.1)),
                (hi.0.max(k.0), hi.1.max(k.1)),
            )
        });
        self.cells.cover(lo, hi);
        let mut touched = Vec::with_capacity(keyed.len());
        for ((p, height), key) in keyed {
            let (x, y) = (p.x_m - key.0 as f64 * c, p.y_m - key.1 as f64 * c);
            let Some(i) = self.cells.index(key) else {
                continue;
            };
            let s = &mut self.cells.cells[i].sums;
            s.n += 1;
            if height.is_finite() {
                s.n_h += 1;
                s.h += height;
            }
            s.x += x;
            s.y += y;
            s.xx += x * x;
            s.xy += x * y;
            s.yy += y * y;
            touched.push((i, key));
        }
        touched.sort_unstable();
        touched.dedup();
        for (i, key) in touched {
            let cell = &mut self.cells.cells[i];
            cell.pull = pull_of(&self.cfg, key, &cell.sums);
        }
    }

    /// Number of cells holding hits.
    pub fn cells(&self) -> usize {
        self.cells.cells.iter().filter(|c| c.sums.n > 0).count()
    }

    fn pull(&self, key: (i64, i64)) -> Option<Pull> {
        self.cells.get(key)?.pull
    }

    /// The cell near `q` that explains it best: the smallest Mahalanobis distance, plus the
    /// squared distance to the mean in cells (a line pulls only across itself, so a line cell
    /// further along the wall must not win on that alone).
    fn associate(&self, q: Point2) -> Option<Pull> {
        let (kx, ky) = self.key(q);
        let max2 = self.cfg.max_distance_m.powi(2);
        let cell2 = self.cfg.cell_m.powi(2);
        let mut best: Option<(f64, Pull)> = None;
        for dy in -1..=1 {
            for dx in -1..=1 {
                let Some(pull) = self.pull((kx + dx, ky + dy)) else {
                    continue;
                };
                let (dx, dy) = (q.x_m - pull.mean.x_m, q.y_m - pull.mean.y_m);
                let d2 = dx * dx + dy * dy;
                if d2 > max2 {
                    continue;
                }
                let cost = pull.mahalanobis2(q) + d2 / cell2;
                if best.is_none_or(|(c, _)| cost < c) {
                    best = Some((cost, pull));
                }
            }
        }
        best.map(|(_, p)| p)
    }

    /// `start` (pose of the scan in the map's frame) refined so that `points` (scan frame)
    /// lie on the cells' hits; pulled towards `start` by `prior_translation` and
    /// `prior_rotation` per point (per square metre and square radian), which decides the
    /// directions the scene leaves free. `wheels` is the travel the wheels predict for the
    /// scan, from the last pose to the prediction (map frame). `None` when too few points
    /// found a cell, or the refinement went further than a refinement should: past the
    /// bounds, or back against the wheels' travel.
    pub fn refine(
        &self,
        points: &[Point2],
        start: Pose2,
        wheels: [Point2; 2],
        prior_translation: f64,
        prior_rotation: f64,
    ) -> Option<Pose2> {
        self.refine_with_heights(
            points,
            &[],
            start,
            wheels,
            prior_translation,
            prior_rotation,
        )
    }

    /// [`refine`](Self::refine) with each point's height above the ground under the rover
    /// (`heights[i]` for `points[i]`; missing or NaN where unknown), for
    /// [`NdtConfig::outline_shift_per_height`].
    pub fn refine_with_heights(
        &self,
        points: &[Point2],
        heights: &[f64],
        start: Pose2,
        wheels: [Point2; 2],
        prior_translation: f64,
        prior_rotation: f64,
    ) -> Option<Pose2> {
        const MIN_PAIRED: usize = 20;
        let surfaces: Vec<Option<(f64, f64)>> = match self.cfg.max_surface_turn_rad {
            Some(_) => surface_directions(points),
            None => Vec::new(),
        };
        let max_sin2 = self.cfg.max_surface_turn_rad.map(|t| t.sin().powi(2));
        let mut pose = start;
        let mut pairs: Vec<(Point2, Pull, f64)> = Vec::with_capacity(points.len());
        for _ in 0..self.cfg.rounds {
            pairs.clear();
            let (sin, cos) = pose.yaw_rad.sin_cos();
            pairs.extend(points.iter().enumerate().filter_map(|(i, p)| {
                let height = heights.get(i).copied().unwrap_or(f64::NAN);
                let pull = self.associate(pose.transform_point(*p))?;
                if let (Some(max_sin2), Some(Some((dx, dy)))) = (max_sin2, surfaces.get(i)) {
                    // A line cell's information lies across its line only: its share along
                    // the point's surface is the squared sine of the turn between them.
                    let [a, b, d] = pull.information;
                    let trace = a + d;
                    let line = (a * d - b * b).abs() <= 1e-9 * trace * trace;
                    let along = pull.information_along(cos * dx - sin * dy, sin * dx + cos * dy);
                    if line && along > max_sin2 * trace {
                        return None;
                    }
                }
                Some((*p, pull, height))
            }));
            if pairs.len() < MIN_PAIRED {
                return None;
            }
            for _ in 0..self.cfg.steps {
                let step = self.gauss_newton_step(
                    &pairs,
                    &pose,
                    &start,
                    [prior_translation, prior_rotation],
                )?;
                pose = Pose2::new(
                    pose.x_m + step[0],
                    pose.y_m + step[1],
                    pose.yaw_rad + step[2],
                );
                if step[0].abs() < 1e-5 && step[1].abs() < 1e-5 && step[2].abs() < 1e-6 {
                    break;
                }
            }
        }
        let along = -self.cfg.max_push_ahead_m.unwrap_or(f64::INFINITY)..=self.cfg.max_hold_back_m;
        let held_back = held_back_m(wheels[0], wheels[1], start, pose);
        let mut within_along = along.contains(&held_back);
        if self.cfg.clamp_along_travel && !within_along {
            // Not `clamp`: bounds that cross or are NaN drop the refinement, as without it.
            let bound = held_back.max(*along.start()).min(*along.end());
            if along.contains(&bound) {
                pose = along_travel_to(wheels, pose, held_back, bound);
                within_along = true;
            }
        }
        let moved = start.relative_to(&pose);
        (pose.position().distance_m(start.position()) <= self.cfg.max_shift_m
            && moved.yaw_rad.abs() <= self.cfg.max_turn_rad
            && within_along)
            .then_some(pose)
    }

    /// One Gauss-Newton step for the paired points, with a Cauchy weight on each pair's
    /// Mahalanobis distance (a point on a rock the cell never saw is not a wall's) and the
    /// prior towards `start`.
    fn gauss_newton_step(
        &self,
        pairs: &[(Point2, Pull, f64)],
        pose: &Pose2,
        start: &Pose2,
        [prior_translation, prior_rotation]: [f64; 2],
    ) -> Option<[f64; 3]> {
        // Cauchy's scale, in squared Mahalanobis units: three noise deviations.
        const CAUCHY2: f64 = 9.0;
        let (s, c) = pose.yaw_rad.sin_cos();
        let mut h = [[0.0; 3]; 3];
        let mut g = [0.0; 3];
        for (p, pull, height) in pairs {
            let q = pose.transform_point(*p);
            let e = [q.x_m - pull.mean.x_m, q.y_m - pull.mean.y_m];
            let [a, b, d] = pull.information;
            let beam = (c * p.x_m - s * p.y_m, s * p.x_m + c * p.y_m);
            let f = pull.share_kept(&self.cfg, *p, beam, *height);
            let w = f / (1.0 + f * pull.mahalanobis2(q) / CAUCHY2);
            // d q / d theta: the beam turned a quarter.
            let (tx, ty) = (-beam.1, beam.0);
            // Columns of J (2 x 3): x, y, theta; Omega J column by column.
            let j = [[1.0, 0.0], [0.0, 1.0], [tx, ty]];
            let oj: [[f64; 2]; 3] = j.map(|col| [a * col[0] + b * col[1], b * col[0] + d * col[1]]);
            for r in 0..3 {
                g[r] += w * (oj[r][0] * e[0] + oj[r][1] * e[1]);
                for k in 0..3 {
                    h[r][k] += w * (oj[r][0] * j[k][0] + oj[r][1] * j[k][1]);
                }
            }
        }
        let n = pairs.len() as f64;
        let d = [
            pose.x_m - start.x_m,
            pose.y_m - start.y_m,
            realms_core::geometry::normalize_angle_rad(pose.yaw_rad - start.yaw_rad),
        ];
        for (k, w) in [prior_translation, prior_translation, prior_rotation]
            .into_iter()
            .enumerate()
        {
            h[k][k] += w * n;
            g[k] += w * n * d[k];
        }
        let step = crate::matcher::solve3(&h, &g)?;
        Some([-step[0], -step[1], -step[2]])
    }
}

/// Each point's surface direction (unit, scan frame), where the scan shows a straight
/// surface there: the chord between its second neighbours either side, when each point
/// of the five lies within [`NORMAL_NEIGHBOUR_M`] of the next and the three between lie
/// within [`STRAIGHT_WITHIN_M`] of the chord; else `None` (a rock's curved outline, an edge).
fn surface_directions(points: &[Point2]) -> Vec<Option<(f64, f64)>> {
    (0..points.len())
        .map(|i| {
            let five = points.get(i.checked_sub(2)?..i + 3)?;
            if five
                .windows(2)
                .any(|w| w[0].distance_m(w[1]) > NORMAL_NEIGHBOUR_M)
            {
                return None;
            }
            let (a, b) = (five[0], five[4]);
            let (dx, dy) = (b.x_m - a.x_m, b.y_m - a.y_m);
            let len = dx.hypot(dy);
            if len <= 1e-9 {
                return None;
            }
            let (ux, uy) = (dx / len, dy / len);
            let straight = five[1..4]
                .iter()
                .all(|p| ((p.x_m - a.x_m) * uy - (p.y_m - a.y_m) * ux).abs() <= STRAIGHT_WITHIN_M);
            straight.then_some((ux, uy))
        })
        .collect()
}

/// How far from the chord through five neighbouring scan points the middle three may lie
/// for the surface to count as straight, metres.
const STRAIGHT_WITHIN_M: f64 = 0.01;

/// How far `refined` moves `matched` back against the travel the wheels predict, from `from`
/// to `predicted`, metres (negative: forward along it; 0 when the wheels barely moved).
pub(crate) fn held_back_m(from: Point2, predicted: Point2, matched: Pose2, refined: Pose2) -> f64 {
    let Some((tx, ty, travel)) = wheels_travel(from, predicted) else {
        return 0.0;
    };
    -((refined.x_m - matched.x_m) * tx + (refined.y_m - matched.y_m) * ty) / travel
}

/// The wheels' travel from `from` to `to` and its length, metres; `None` when they barely
/// moved (under a millimetre), with no direction to measure along.
fn wheels_travel(from: Point2, to: Point2) -> Option<(f64, f64, f64)> {
    let (tx, ty) = (to.x_m - from.x_m, to.y_m - from.y_m);
    let length = tx.hypot(ty);
    (length > 1e-3).then_some((tx, ty, length))
}

/// `refined`, held back `held_back_m` against the wheels' travel from `wheels[0]` to
/// `wheels[1]` (as [`held_back_m`] measures it), moved along that travel so it is held back
/// `to_m` instead; its heading and its place across the travel stay.
fn along_travel_to(wheels: [Point2; 2], refined: Pose2, held_back_m: f64, to_m: f64) -> Pose2 {
    let Some((tx, ty, travel)) = wheels_travel(wheels[0], wheels[1]) else {
        return refined;
    };
    let forward = held_back_m - to_m;
    Pose2::new(
        refined.x_m + forward * tx / travel,
        refined.y_m + forward * ty / travel,
        refined.yaw_rad,
    )
}

/// The eigenvalues of the symmetric 2 x 2 matrix `[[a, b], [b, c]]`, smaller (at least 0)
/// then larger, and the smaller one's unit axis.
pub fn eigen_symmetric2(a: f64, b: f64, c: f64) -> (f64, f64, (f64, f64)) {
    let half_trace = 0.5 * (a + c);
    let root = (0.25 * (a - c).powi(2) + b * b).sqrt();
    let (small, large) = ((half_trace - root).max(0.0), half_trace + root);
    let axis = if b.abs() > 1e-15 {
        let (ex, ey) = (b, small - a);
        let norm = ex.hypot(ey);
        (ex / norm, ey / norm)
    } else if a <= c {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    (small, large, axis)
}

/// What the cell `key` holding the hits `s` pulls with; `None` below `min_hits`.
fn pull_of(cfg: &NdtConfig, key: (i64, i64), s: &Sums) -> Option<Pull> {
    if s.n < cfg.min_hits {
        return None;
    }
    let n = s.n as f64;
    let (mx, my) = (s.x / n, s.y / n);
    let (vxx, vxy, vyy) = (s.xx / n - mx * mx, s.xy / n - mx * my, s.yy / n - my * my);
    let (small, large, (nx, ny)) = eigen_symmetric2(vxx, vxy, vyy);
    let noise = cfg.noise_var_m2;
    if small < cfg.line_ratio * large && s.n < cfg.min_line_hits {
        return None;
    }
    let information = if small < cfg.line_ratio * large {
        // Across the line only: the normal is the smaller eigenvalue's axis.
        let w = 1.0 / (small + noise);
        [w * nx * nx, w * nx * ny, w * ny * ny]
    } else {
        let (a, b, c) = (vxx + noise, vxy, vyy + noise);
        let det = a * c - b * b;
        [c / det, -b / det, a / det]
    };
    let corner = (key.0 as f64 * cfg.cell_m, key.1 as f64 * cfg.cell_m);
    Some(Pull {
        mean: Point2::new(corner.0 + mx, corner.1 + my),
        height_m: if s.n_h > 0 {
            s.h / s.n_h as f64
        } else {
            f64::NAN
        },
        information,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hits along the walls of a room 8 m x 5 m with a round pillar, every `spacing_m`,
    /// placed off the cell lattice on purpose.
    fn room(spacing_m: f64) -> Vec<Point2> {
        let (x0, y0, x1, y1) = (0.013, 0.037, 8.013, 5.037);
        let mut hits = Vec::new();
        let mut t = 0.0;
        while t <= 1.0 {
            for (ax, ay, bx, by) in [
                (x0, y0, x1, y0),
                (x1, y0, x1, y1),
                (x1, y1, x0, y1),
                (x0, y1, x0, y0),
            ] {
                hits.push(Point2::new(ax + t * (bx - ax), ay + t * (by - ay)));
            }
            t += spacing_m / 8.0;
        }
        for k in 0..60 {
            let a = k as f64 * std::f64::consts::TAU / 60.0;
            hits.push(Point2::new(5.21 + 0.4 * a.cos(), 2.63 + 0.4 * a.sin()));
        }
        hits
    }

    /// The room's hits in a map, and a scan of the same walls from `truth`, sampled elsewhere
    /// along them.
    fn room_and_scan_from(truth: Pose2) -> (NdtMap, Vec<Point2>) {
        let mut map = NdtMap::new(NdtConfig::default());
        map.insert(room(0.01));
        let scan = room(0.07)
            .into_iter()
            .map(|p| truth.inverse().transform_point(p))
            .collect();
        (map, scan)
    }

    /// Wheels that did not move: nothing to hold a refinement back against.
    const STILL: [Point2; 2] = [Point2 { x_m: 0.0, y_m: 0.0 }; 2];

    #[test]
    fn a_match_a_few_centimetres_off_is_brought_onto_the_hits() {
        let truth = Pose2::new(3.1, 2.2, 0.3);
        let (map, scan) = room_and_scan_from(truth);
        for (dx, dy, dyaw) in [
            (0.025, 0.0, 0.0),
            (-0.02, 0.024, 0.004),
            (0.0, -0.03, -0.008),
        ] {
            let start = Pose2::new(truth.x_m + dx, truth.y_m + dy, truth.yaw_rad + dyaw);
            let refined = map.refine(&scan, start, STILL, 3.0, 3.0).expect("refined");
            let err = refined.relative_to(&truth);
            assert!(
                err.x_m.hypot(err.y_m) < 0.002 && err.yaw_rad.abs() < 2e-4,
                "from {start:?}: {refined:?}"
            );
        }
    }

    #[test]
    fn a_refinement_further_than_the_bound_is_not_taken() {
        let truth = Pose2::new(3.1, 2.2, 0.3);
        let (map, scan) = room_and_scan_from(truth);
        let start = Pose2::new(truth.x_m + 0.05, truth.y_m, truth.yaw_rad);
        assert!(map.refine(&scan, start, STILL, 3.0, 3.0).is_none());
        let wider = NdtMap {
            cfg: NdtConfig {
                max_shift_m: 0.06,
                ..NdtConfig::default()
            },
            ..map
        };
        let refined = wider
            .refine(&scan, start, STILL, 3.0, 3.0)
            .expect("within 6 cm");
        assert!(
            refined.position().distance_m(truth.position()) < 0.002,
            "{refined:?}"
        );
    }

    #[test]
    fn a_refinement_is_held_back_only_by_what_it_takes_from_the_wheels_travel() {
        // Wheels: 4 cm east. The match at 3.9 cm east.
        let (from, predicted) = (Point2::new(1.0, 2.0), Point2::new(1.04, 2.0));
        let matched = Pose2::new(1.039, 2.0, 0.0);
        let at = |x: f64, y: f64| Pose2::new(x, y, 0.0);
        // 2.5 cm back west: held back 2.5 cm; 1 cm north: not at all; 1 cm east: -1 cm.
        assert!((held_back_m(from, predicted, matched, at(1.014, 2.0)) - 0.025).abs() < 1e-12);
        assert!(held_back_m(from, predicted, matched, at(1.039, 2.01)).abs() < 1e-12);
        assert!((held_back_m(from, predicted, matched, at(1.049, 2.0)) + 0.01).abs() < 1e-12);
        // Diagonal travel: a move of (-3, -4) cm against a (3, 4)-direction is 5 cm back.
        let diagonal = held_back_m(
            Point2::new(0.0, 0.0),
            Point2::new(0.03, 0.04),
            at(0.03, 0.04),
            at(0.0, 0.0),
        );
        assert!((diagonal - 0.05).abs() < 1e-12, "{diagonal}");
        // A rover standing still holds nothing back.
        assert_eq!(held_back_m(from, from, matched, at(0.9, 2.0)), 0.0);
    }

    #[test]
    fn a_refinement_pushing_the_match_ahead_of_the_wheels_is_taken_only_within_its_bound() {
        let truth = Pose2::new(3.1, 2.2, 0.0);
        let (map, scan) = room_and_scan_from(truth);
        // The wheels drove 5 cm east; the match lies 3 cm short of the truth, so the
        // refinement moves it 3 cm further along the travel.
        let start = Pose2::new(truth.x_m - 0.03, truth.y_m, truth.yaw_rad);
        let wheels = [Point2::new(3.0, 2.2), Point2::new(3.05, 2.2)];
        let refined = map
            .refine(&scan, start, wheels, 3.0, 3.0)
            .expect("no bound ahead");
        assert!(
            refined.position().distance_m(truth.position()) < 0.002,
            "{refined:?}"
        );
        let bounded = |ahead_m: f64| NdtMap {
            cfg: NdtConfig {
                max_push_ahead_m: Some(ahead_m),
                ..NdtConfig::default()
            },
            ..map.clone()
        };
        assert!(
            bounded(0.02)
                .refine(&scan, start, wheels, 3.0, 3.0)
                .is_none()
        );
        assert!(
            bounded(0.035)
                .refine(&scan, start, wheels, 3.0, 3.0)
                .is_some()
        );
        // Clamped instead of dropped: 2 cm of the 3 cm along the travel are taken, and the
        // refinement's own correction across it and of the heading stay.
        let turned = Pose2::new(start.x_m, start.y_m + 0.01, 0.004);
        let clamped = NdtMap {
            cfg: NdtConfig {
                max_push_ahead_m: Some(0.02),
                clamp_along_travel: true,
                ..NdtConfig::default()
            },
            ..map.clone()
        }
        .refine(&scan, turned, wheels, 3.0, 3.0)
        .expect("clamped, not dropped");
        assert!(
            (clamped.x_m - (truth.x_m - 0.01)).abs() < 0.002,
            "{clamped:?}"
        );
        assert!((clamped.y_m - truth.y_m).abs() < 0.002, "{clamped:?}");
        assert!(clamped.yaw_rad.abs() < 0.0005, "{clamped:?}");
    }

    /// A lone wall along x (no hold on x), and five hits on a rock's face across the beam
    /// 11 m ahead whose outline the scan sees 3 cm farther than the map holds it, as when the
    /// lidar's plane dips at the rock. Counted as the noise alone, those five hits drag the
    /// rover the whole 3 cm back; spread by the tilt (11 cm at that range), they count about
    /// as much as the prediction, and move it half as far.
    #[test]
    fn a_far_rocks_outline_seen_farther_moves_a_tilt_spread_refinement_less() {
        let wall = (0..800).map(|i| Point2::new(i as f64 * 0.01, 1.513));
        let face = (0..100).map(|i| Point2::new(15.013, -0.5 + i as f64 * 0.01));
        let truth = Pose2::new(4.0, 0.0, 0.0);
        let scan: Vec<Point2> = (0..100)
            .map(|i| Point2::new(2.0 + i as f64 * 0.04, 1.513))
            .chain((0..5).map(|i| Point2::new(15.043, -0.4 + i as f64 * 0.2)))
            .map(|p| truth.inverse().transform_point(p))
            .collect();
        let shift = |cfg: NdtConfig| {
            let mut map = NdtMap::new(cfg);
            map.insert(wall.clone().chain(face.clone()));
            let refined = map.refine(&scan, truth, STILL, 3.0, 3.0).expect("refined");
            refined.x_m - truth.x_m
        };
        let plain = shift(NdtConfig::default());
        assert!(plain < -0.025, "dragged back by the face: {plain}");
        for along_beam in [false, true] {
            let spread = shift(NdtConfig {
                tilt_spread_per_m: 0.01,
                tilt_spread_along_beam: along_beam,
                ..NdtConfig::default()
            });
            assert!(
                spread < 0.0 && spread > 0.7 * plain,
                "along the beam {along_beam}: {spread} against {plain}"
            );
        }
    }

    /// A lone wall along x pins y only. A cell 2 m off it holds hits along a line turned 20
    /// degrees (a surface drawn at two offsets), and the scan sees a straight surface there 1
    /// cm off that cell's middle, longer than the cell (the points its check reads have
    /// both neighbours). Paired with the turned cell, its points drag the rover along the
    /// wall; with the surface check they are not paired with it, and the rover stays.
    #[test]
    fn a_turned_line_cell_does_not_drag_a_straight_surface_along_the_wall() {
        let wall = (0..800).map(|i| Point2::new(i as f64 * 0.01, 1.513));
        let tilt = 20f64.to_radians().tan();
        let turned = (0..25).map(|i| {
            let x = 4.0 + i as f64 * 0.01;
            Point2::new(x, 3.6 + (x - 4.125) * tilt)
        });
        let truth = Pose2::new(4.0, 0.0, 0.0);
        let scan: Vec<Point2> = (0..100)
            .map(|i| Point2::new(2.0 + i as f64 * 0.04, 1.513))
            .chain((0..43).map(|i| Point2::new(3.71 + i as f64 * 0.02, 3.61)))
            .map(|p| truth.inverse().transform_point(p))
            .collect();
        let shift = |max_surface_turn_rad: Option<f64>| {
            let mut map = NdtMap::new(NdtConfig {
                max_surface_turn_rad,
                ..NdtConfig::default()
            });
            map.insert(wall.clone().chain(turned.clone()));
            let refined = map.refine(&scan, truth, STILL, 3.0, 3.0).expect("refined");
            (refined.x_m - truth.x_m, refined.y_m - truth.y_m)
        };
        let (plain_x, _) = shift(None);
        assert!(plain_x.abs() > 0.003, "dragged along the wall: {plain_x}");
        let (checked_x, checked_y) = shift(Some(10f64.to_radians()));
        assert!(
            checked_x.abs() < 1e-4 && checked_y.abs() < 1e-4,
            "{checked_x} {checked_y}"
        );
    }

    #[test]
    fn a_points_surface_is_read_only_where_the_scan_runs_straight() {
        // A straight run along (0.8, 0.6), a corner, and a point far off.
        let mut pts: Vec<Point2> = (0..6)
            .map(|i| Point2::new(0.08 * i as f64, 0.06 * i as f64))
            .collect();
        pts.push(Point2::new(0.4, 0.4));
        pts.push(Point2::new(0.4, 1.0));
        let s = surface_directions(&pts);
        // Two neighbours either side are needed.
        assert_eq!((s[0], s[1]), (None, None));
        for k in [2, 3] {
            let (dx, dy) = s[k].expect("straight");
            assert!((dx - 0.8).abs() < 1e-12 && (dy - 0.6).abs() < 1e-12, "{k}");
        }
        // The run turns at point 6 (0.6 m along, 0.04 m off the line), and point 7 is
        // 0.6 m from it: no surface.
        assert_eq!((s[4], s[5], s[6], s[7]), (None, None, None, None));
    }

    /// The same rock face 3 cm farther, its hits taken with the plane 0.3 m above the ground
    /// and seen now 10 cm lower: with a shift of 4 m a metre of height they count as spread
    /// 40 cm along their beams and barely move the rover; seen at the height they were taken
    /// at, they pull as before.
    #[test]
    fn a_rocks_outline_cut_at_another_height_moves_an_outline_shift_refinement_less() {
        let cfg = NdtConfig {
            outline_shift_per_height: 4.0,
            ..NdtConfig::default()
        };
        let mut map = NdtMap::new(cfg);
        let wall = (0..800).map(|i| Point2::new(i as f64 * 0.01, 1.513));
        let face = (0..100).map(|i| Point2::new(15.013, -0.5 + i as f64 * 0.01));
        map.insert_with_heights(wall.chain(face).map(|p| (p, 0.3)));
        let truth = Pose2::new(4.0, 0.0, 0.0);
        let (scan, face_now): (Vec<Point2>, Vec<bool>) = (0..100)
            .map(|i| (Point2::new(2.0 + i as f64 * 0.04, 1.513), false))
            .chain((0..5).map(|i| (Point2::new(15.043, -0.4 + i as f64 * 0.2), true)))
            .map(|(p, face)| (truth.inverse().transform_point(p), face))
            .unzip();
        let shift = |face_height: f64| {
            let heights: Vec<f64> = face_now
                .iter()
                .map(|face| if *face { face_height } else { 0.3 })
                .collect();
            let refined = map
                .refine_with_heights(&scan, &heights, truth, STILL, 3.0, 3.0)
                .expect("refined");
            refined.x_m - truth.x_m
        };
        let (same, lower) = (shift(0.3), shift(0.2));
        assert!(same < -0.025, "dragged back at the same height: {same}");
        assert!(lower < 0.0 && lower > 0.5 * same, "{lower} against {same}");
    }

    #[test]
    fn along_a_lone_wall_the_start_is_kept() {
        let mut map = NdtMap::new(NdtConfig::default());
        let wall: Vec<Point2> = (0..800)
            .map(|i| Point2::new(i as f64 * 0.01, 1.013))
            .collect();
        map.insert(wall.iter().copied());
        let truth = Pose2::new(4.0, 0.0, 0.0);
        let scan: Vec<Point2> = (0..100)
            .map(|i| {
                truth
                    .inverse()
                    .transform_point(Point2::new(2.0 + i as f64 * 0.04, 1.013))
            })
            .collect();
        // 3 cm along the wall and 2 cm across it: across is corrected, along is left.
        let start = Pose2::new(4.03, 0.02, 0.0);
        let refined = map.refine(&scan, start, STILL, 3.0, 3.0).expect("refined");
        assert!((refined.y_m - 0.0).abs() < 0.001, "{refined:?}");
        assert!((refined.x_m - 4.03).abs() < 0.001, "{refined:?}");
    }

    #[test]
    fn hits_added_a_few_at_a_time_anywhere_sum_as_if_added_at_once() {
        let hits: Vec<Point2> = room(0.01)
            .into_iter()
            .map(|p| Point2::new(p.x_m * 3.0 - 11.0, p.y_m * 2.0 - 7.0))
            .collect();
        let mut at_once = NdtMap::new(NdtConfig::default());
        at_once.insert(hits.iter().copied());
        let mut in_parts = NdtMap::new(NdtConfig::default());
        // Far apart first, so the rectangle grows in every direction.
        for part in [3, 0, 2, 1] {
            in_parts.insert(hits.iter().skip(part).step_by(4).copied());
        }
        assert_eq!(at_once.cells(), in_parts.cells());
        for p in hits.iter().step_by(37) {
            let key = at_once.key(*p);
            let (a, b) = match (at_once.pull(key), in_parts.pull(key)) {
                (Some(a), Some(b)) => (a, b),
                (None, None) => continue,
                _ => panic!("{key:?} pulls in one map only"),
            };
            assert!(a.mean.distance_m(b.mean) < 1e-12, "{key:?}");
            for k in 0..3 {
                let scale = a.information[k].abs().max(1.0);
                assert!((a.information[k] - b.information[k]).abs() < 1e-6 * scale);
            }
        }
    }

    #[test]
    fn too_few_points_near_the_hits_give_no_refinement() {
        let mut map = NdtMap::new(NdtConfig::default());
        map.insert(room(0.01));
        let far: Vec<Point2> = (0..50)
            .map(|i| Point2::new(20.0 + i as f64, 20.0))
            .collect();
        assert!(
            map.refine(&far, Pose2::new(0.0, 0.0, 0.0), STILL, 3.0, 3.0)
                .is_none()
        );
    }
}
