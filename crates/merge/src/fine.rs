//! The last, sub-cell step of a merge: two maps aligned on their surfaces at the maps' own
//! resolution, near a pose the coarser levels found, and whether another pose nearby fits
//! them as closely.
//!
//! The levels the search and verification run on count a point as agreeing within a cell
//! and a half of structure (15 cm on 10 cm cells): every pose within a few centimetres of
//! the best scores alike, so they cannot tell a pose right to 3 cm from one 15 cm off, nor
//! a heading held by a short straight stretch of wall from one 2 degrees off. Here each
//! surface cell of one map is paired with the nearest surface cell of the other that faces
//! the same way, and the pose is solved by least squares on the distances along the
//! surfaces' normals (point-to-line ICP, both ways; Censi 2008, "An ICP variant using a
//! point-to-line metric"), with a robust weight, stepping only along the directions the
//! pairs pin: along a bare wall the fit stays where it started.
//!
//! [`nearby`] then asks whether the fit is the only one: fits started from poses around it
//! that settle apart from it are compared with it point by point, over the points that land
//! on the other map's known ground at both ([`compare`]); one that is not clearly worse
//! makes the merge imprecise.

use crate::level::{Class, Outline, floor_i64, local_shape};
use crate::verify::Rigid;
use realms_core::{Point2, Pose2};

/// The surface cells of a level, with a normal fitted to their neighbours, indexed by
/// cell for nearest-point queries.
#[derive(Clone, Debug)]
pub struct Surfaces {
    /// Surface points, grid-local metres, with the unit normal towards the free side.
    points: Vec<(Point2, [f64; 2])>,
    /// For each cell of the level, the index of its point, or `u32::MAX`.
    index: Vec<u32>,
    /// For each cell, whether the map knows it (free, obstacle or hazard).
    known: Vec<bool>,
    width: usize,
    height: usize,
    cell_m: f64,
}

/// Neighbours (cells) a surface point's normal is fitted over.
const NORMAL_RADIUS_CELLS: i64 = 3;
/// Pairs whose normals differ by more than this (cosine) are no pair: the two faces of a
/// thin wall, a rock seen from opposite sides.
const MIN_NORMAL_COS: f64 = 0.5;

impl Surfaces {
    /// The surface cells of `outline`: feature cells with a normal on the edge of their
    /// blob, as [`crate::level::Level::surfaces`] takes them, none thinned.
    pub fn of(outline: &Outline) -> Surfaces {
        let (width, height) = (outline.width, outline.height);
        let class_at = |x: i64, y: i64| {
            if x < 0 || y < 0 || x >= width as i64 || y >= height as i64 {
                Class::Unknown
            } else {
                outline.class[y as usize * width + x as usize]
            }
        };
        let mut raw = Vec::new();
        let mut index = vec![u32::MAX; width * height];
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                let c = outline.class[i];
                if !c.is_feature() || outline.normal[i].is_nan() {
                    continue;
                }
                let (xi, yi) = (x as i64, y as i64);
                if [(1, 0), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .any(|(dx, dy)| class_at(xi + dx, yi + dy) != c)
                {
                    index[i] = raw.len() as u32;
                    raw.push((x as i64, y as i64, f64::from(outline.normal[i])));
                }
            }
        }
        // A normal from the structure tensor of the surface cells around each: the cell
        // grid's own normal (towards the free cells within two cells) turns in steps.
        let points = raw
            .iter()
            .map(|&(cx, cy, free_rad)| {
                let surface = |x: i64, y: i64| {
                    (0..width as i64).contains(&x)
                        && (0..height as i64).contains(&y)
                        && index[y as usize * width + x as usize] != u32::MAX
                };
                let free_side = [free_rad.cos(), free_rad.sin()];
                let normal = match local_shape(surface, cx, cy, NORMAL_RADIUS_CELLS) {
                    Some((n, _, axis_rad)) if n >= 3.0 => {
                        let v = [-axis_rad.sin(), axis_rad.cos()];
                        let along_free = v[0] * free_side[0] + v[1] * free_side[1];
                        if along_free.abs() < MIN_NORMAL_COS {
                            free_side
                        } else if along_free < 0.0 {
                            [-v[0], -v[1]]
                        } else {
                            v
                        }
                    }
                    _ => free_side,
                };
                let p = Point2::new(
                    (cx as f64 + 0.5) * outline.cell_m,
                    (cy as f64 + 0.5) * outline.cell_m,
                );
                (p, normal)
            })
            .collect();
        Surfaces {
            points,
            index,
            known: outline.class.iter().map(|c| *c != Class::Unknown).collect(),
            width,
            height,
            cell_m: outline.cell_m,
        }
    }

    /// Whether the cell under `q` is known.
    fn knows(&self, q: Point2) -> bool {
        let (x, y) = (
            floor_i64(q.x_m / self.cell_m),
            floor_i64(q.y_m / self.cell_m),
        );
        x >= 0
            && y >= 0
            && (x as usize) < self.width
            && (y as usize) < self.height
            && self.known[y as usize * self.width + x as usize]
    }

    /// The nearest surface point to `q` within `radius` cells whose normal agrees with
    /// `normal` (cosine at least [`MIN_NORMAL_COS`]).
    fn nearest(&self, q: Point2, normal: [f64; 2], radius: i64) -> Option<(Point2, [f64; 2])> {
        let (cx, cy) = (
            floor_i64(q.x_m / self.cell_m),
            floor_i64(q.y_m / self.cell_m),
        );
        let (w, h) = (self.width as i64, self.height as i64);
        // Off the grid by more than the radius (or not a number): nothing within reach.
        if !(-radius..w + radius).contains(&cx) || !(-radius..h + radius).contains(&cy) {
            return None;
        }
        let mut best: Option<(f64, usize)> = None;
        let visit = |x: i64, y: i64, best: &mut Option<(f64, usize)>| {
            if x < 0 || y < 0 || x >= w || y >= h {
                return;
            }
            let i = self.index[(y * w + x) as usize];
            if i == u32::MAX {
                return;
            }
            let (p, n) = self.points[i as usize];
            if n[0] * normal[0] + n[1] * normal[1] < MIN_NORMAL_COS {
                return;
            }
            let d2 = (p.x_m - q.x_m).powi(2) + (p.y_m - q.y_m).powi(2);
            if best.is_none_or(|(b, _)| d2 < b) {
                *best = Some((d2, i as usize));
            }
        };
        // Ring by ring outwards: every cell of ring r + 1 lies at least r cells from q, so
        // a point found within that ends the search.
        for r in 0..=radius {
            if r == 0 {
                visit(cx, cy, &mut best);
            } else {
                for d in -r..=r {
                    visit(cx + d, cy - r, &mut best);
                    visit(cx + d, cy + r, &mut best);
                }
                for d in 1 - r..r {
                    visit(cx - r, cy + d, &mut best);
                    visit(cx + r, cy + d, &mut best);
                }
            }
            let reach = r as f64 * self.cell_m;
            if best.is_some_and(|(d2, _)| d2 <= reach * reach) {
                break;
            }
        }
        best.map(|(_, i)| self.points[i])
    }
}

/// The points of both maps that land on the other map's known ground at a pose, or `margin_m`
/// from it along an axis: all a fit near that pose can pair.
#[derive(Clone, Debug)]
pub struct Overlap {
    a: Vec<usize>,
    b: Vec<usize>,
}

impl Overlap {
    /// The overlap at grid-local `pose` (of the second map in the first's).
    pub fn at(a: &Surfaces, b: &Surfaces, pose: &Pose2, margin_m: f64) -> Overlap {
        let near = |target: &Surfaces, q: Point2| {
            [(0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]
                .iter()
                .any(|(dx, dy)| {
                    target.knows(Point2::new(q.x_m + dx * margin_m, q.y_m + dy * margin_m))
                })
        };
        let inv = pose.inverse();
        Overlap {
            b: (0..b.points.len())
                .filter(|&i| near(a, pose.transform_point(b.points[i].0)))
                .collect(),
            a: (0..a.points.len())
                .filter(|&i| near(b, inv.transform_point(a.points[i].0)))
                .collect(),
        }
    }

    /// The points of either overlap.
    pub fn union(&self, other: &Overlap) -> Overlap {
        let merge = |x: &[usize], y: &[usize]| {
            let mut all: Vec<usize> = x.iter().chain(y).copied().collect();
            all.sort_unstable();
            all.dedup();
            all
        };
        Overlap {
            a: merge(&self.a, &other.a),
            b: merge(&self.b, &other.b),
        }
    }

    /// At most `max_points` of the overlap's points (evenly, from each map in proportion).
    pub fn thinned(&self, max_points: usize) -> Overlap {
        let total = self.a.len() + self.b.len();
        if total <= max_points {
            return self.clone();
        }
        let step = total.div_ceil(max_points.max(1));
        Overlap {
            a: self.a.iter().step_by(step).copied().collect(),
            b: self.b.iter().step_by(step).copied().collect(),
        }
    }
}

/// A point's pair at a pose: the second map's point moved into the first map's frame,
/// the first map's point, and the pair's normal in the first map's frame.
type Pair = (Point2, Point2, [f64; 2]);

/// Visits every point of `overlap` at grid-local `pose`, seen from the first map: `f(pair,
/// on_known)` with its pair within `radius` cells if there is one, and whether the point
/// lands on the other map's known ground.
fn for_points(
    a: &Surfaces,
    b: &Surfaces,
    overlap: &Overlap,
    pose: &Pose2,
    radius: i64,
    mut f: impl FnMut(Option<Pair>, bool),
) {
    let (there, back) = (Rigid::new(pose), Rigid::new(&pose.inverse()));
    for &i in &overlap.b {
        let (p, n) = b.points[i];
        let m = there.apply(p);
        let pair = a
            .nearest(m, there.turn(n), radius)
            .map(|(q, na)| (m, q, na));
        f(pair, a.knows(m));
    }
    for &i in &overlap.a {
        let (q, n) = a.points[i];
        let q_in_b = back.apply(q);
        // The second map's point moved, its normal turned into the first map's frame.
        let pair = b
            .nearest(q_in_b, back.turn(n), radius)
            .map(|(p, nb)| (there.apply(p), q, there.turn(nb)));
        f(pair, b.knows(q_in_b));
    }
}

/// Distance along the normal of a pair.
fn residual((m, q, n): Pair) -> f64 {
    n[0] * (m.x_m - q.x_m) + n[1] * (m.y_m - q.y_m)
}

/// An alignment on the surfaces.
#[derive(Clone, Copy, Debug)]
pub struct FineFit {
    /// Grid-local pose of the second map in the first's.
    pub pose: Pose2,
    /// Pairs in the last iteration (both ways).
    pub pairs: usize,
}

/// Search radius (cells) for pairs in a fit's first iterations; then [`SETTLE_RADIUS`].
const START_RADIUS: i64 = 4;
const SETTLE_RADIUS: i64 = 2;
/// Iterations of a fit, the first few at [`START_RADIUS`].
const ITERATIONS: usize = 12;
const WIDE_ITERATIONS: usize = 4;
/// A direction of the pose is fitted only where the pairs pin it as firmly as this many
/// pairs facing along it would (the eigenvalue of their normal matrix, turns counted as the
/// arc at the overlap's spread).
const MIN_PINNING_PAIRS: f64 = 20.0;
/// A fit has settled when a step moves it less than this share of a cell ...
const SETTLED_STEP_CELLS: f64 = 0.01;
/// ... and turns it less than this, radians.
const SETTLED_TURN_RAD: f64 = 1e-4;

/// Point-to-line ICP between the surfaces of two maps over `overlap`, from grid-local
/// `start`: Gauss-Newton on the distances along the normal of the point each is paired
/// with, Huber-weighted beyond half a cell.
pub fn align(a: &Surfaces, b: &Surfaces, overlap: &Overlap, start: Pose2) -> FineFit {
    align_with(a, b, overlap, start, true)
}

/// [`align`] with the heading held at `start`'s: where the maps' walls have pinned it more
/// surely than the overlap can ([`crate::lines`]).
pub fn align_at_heading(a: &Surfaces, b: &Surfaces, overlap: &Overlap, start: Pose2) -> FineFit {
    align_with(a, b, overlap, start, false)
}

/// [`align`], turning the pose only if `fit_heading`.
fn align_with(
    a: &Surfaces,
    b: &Surfaces,
    overlap: &Overlap,
    start: Pose2,
    fit_heading: bool,
) -> FineFit {
    let cell_m = a.cell_m.max(b.cell_m);
    let huber = 0.5 * cell_m;
    // Turns are taken about the overlap's centre (both maps' points in it, in the first
    // map's frame) and measured as the arc at its spread, so that the three directions
    // weigh alike.
    let there = Rigid::new(&start);
    let (pivot, lever) = spread(
        overlap
            .a
            .iter()
            .map(|&i| a.points[i].0)
            .chain(overlap.b.iter().map(|&i| there.apply(b.points[i].0))),
    );
    let mut fit = FineFit {
        pose: start,
        pairs: 0,
    };
    for iteration in 0..ITERATIONS {
        let radius = if iteration < WIDE_ITERATIONS {
            START_RADIUS
        } else {
            SETTLE_RADIUS
        };
        let (mut h, mut g, mut pairs) = ([[0.0f64; 3]; 3], [0.0f64; 3], 0usize);
        for_points(a, b, overlap, &fit.pose, radius, |pair, _| {
            if let Some(pair @ (m, _, n)) = pair {
                let r = residual(pair);
                let (ux, uy) = ((m.x_m - pivot.x_m) / lever, (m.y_m - pivot.y_m) / lever);
                // Held, the heading has no column: its eigenvalue is 0 and it never steps.
                let turn = if fit_heading {
                    n[1] * ux - n[0] * uy
                } else {
                    0.0
                };
                let jac = [n[0], n[1], turn];
                let w = if r.abs() <= huber {
                    1.0
                } else {
                    huber / r.abs()
                };
                for u in 0..3 {
                    g[u] += w * jac[u] * r;
                    for v in 0..3 {
                        h[u][v] += w * jac[u] * jac[v];
                    }
                }
                pairs += 1;
            }
        });
        fit.pairs = pairs;
        // Only along directions the pairs pin: along one nothing pins (a bare wall's
        // length), a step would follow noise (Zhang, Kaess and Singh 2016, "On degeneracy
        // of optimization-based state estimation problems").
        let (values, vectors) = eigen_symmetric3(&h);
        let mut step = [0.0f64; 3];
        for (value, v) in values.iter().zip(&vectors) {
            if *value >= MIN_PINNING_PAIRS {
                let along = -(v[0] * g[0] + v[1] * g[1] + v[2] * g[2]) / value;
                for k in 0..3 {
                    step[k] += along * v[k];
                }
            }
        }
        // p' = R(dyaw) (p - pivot) + pivot + (dx, dy), in the first map's frame.
        let dyaw = step[2] / lever;
        let (ds, dc) = dyaw.sin_cos();
        let p = fit.pose;
        let (tx, ty) = (p.x_m - pivot.x_m, p.y_m - pivot.y_m);
        fit.pose = Pose2::new(
            dc * tx - ds * ty + pivot.x_m + step[0],
            ds * tx + dc * ty + pivot.y_m + step[1],
            p.yaw_rad + dyaw,
        );
        if iteration >= WIDE_ITERATIONS
            && step[0].hypot(step[1]) < SETTLED_STEP_CELLS * cell_m
            && dyaw.abs() < SETTLED_TURN_RAD
        {
            break;
        }
    }
    fit
}

/// The centre of `points` and their root mean square distance from it (at least a metre).
fn spread(points: impl Iterator<Item = Point2> + Clone) -> (Point2, f64) {
    let (mut n, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for p in points.clone() {
        n += 1.0;
        sx += p.x_m;
        sy += p.y_m;
    }
    if n == 0.0 {
        return (Point2::new(0.0, 0.0), 1.0);
    }
    let c = Point2::new(sx / n, sy / n);
    let ms = points.map(|p| p.distance_m(c).powi(2)).sum::<f64>() / n;
    (c, ms.sqrt().max(1.0))
}

/// Eigenvalues and unit eigenvectors of a symmetric 3 x 3 matrix, by cyclic Jacobi
/// rotations (Golub and Van Loan, "Matrix Computations", 8.5).
fn eigen_symmetric3(m: &[[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut a = *m;
    // Columns of v are the eigenvectors.
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..20 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        if off <= 1e-24 * (a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2)).max(1e-300) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // a <- J^T a J with J the rotation in the (p, q) plane.
            for row in a.iter_mut() {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * row_p[k] - s * row_q[k]);
            a[q] = std::array::from_fn(|k| s * row_p[k] + c * row_q[k]);
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let values = [a[0][0], a[1][1], a[2][2]];
    let vectors = std::array::from_fn(|k| [v[0][k], v[1][k], v[2][k]]);
    (values, vectors)
}

/// [`compare`] finds no difference between poses that share fewer points than this.
const MIN_COMMON_POINTS: usize = 30;
/// ... and two shifts at one heading fewer than this among the points the shift moves
/// across their surfaces ([`moved_across`]): each of those speaks to the shift.
const MIN_MOVED_ACROSS_POINTS: usize = 10;

/// Two poses compared point by point.
#[derive(Clone, Copy, Debug)]
pub struct Comparison {
    /// Points counted at both poses.
    pub common: usize,
    /// How much worse the second pose fits, in standard errors of the mean difference of
    /// the points' costs (negative: it fits better). 0 with too few points in common:
    /// `MIN_COMMON_POINTS`, or between two poses at one heading
    /// `MIN_MOVED_ACROSS_POINTS` of those the shift moves across their surface (the
    /// only ones counted there).
    /// Each pair of surface points is counted from both maps and neighbouring points' costs
    /// are correlated, so this overstates the evidence; the thresholds were chosen on it as
    /// it is.
    pub z: f64,
    /// Root mean square of the points' capped distances at the first pose, metres ...
    pub rms_p_m: f64,
    /// ... and at the second.
    pub rms_q_m: f64,
}

/// Compares how closely grid-local poses `p` and `q` lay the maps' surfaces on each other,
/// over the points of `overlap` counted at both: each costs its squared distance along the
/// normal to its pair, at most a cell squared; a point with no pair costs that cap where it
/// lands on the other map's known ground and is not counted where it does not. A sum over
/// the points that fit would reward a pose that widens a thin overlap; the same points at
/// both poses do not.
pub fn compare(a: &Surfaces, b: &Surfaces, overlap: &Overlap, p: &Pose2, q: &Pose2) -> Comparison {
    let cell_m = a.cell_m.max(b.cell_m);
    let cap = cell_m * cell_m;
    let costs = |pose: &Pose2| {
        let mut out = Vec::with_capacity(overlap.a.len() + overlap.b.len());
        for_points(a, b, overlap, pose, SETTLE_RADIUS, |pair, on_known| {
            out.push(match pair {
                Some(pair) => Some(residual(pair).powi(2).min(cap)),
                None => on_known.then_some(cap),
            })
        });
        out
    };
    let (cp, cq) = (costs(p), costs(q));
    // Between two poses at one heading (any shift: a restart where the walls hold the
    // heading, a rival, a neighbour) only the points the shift moves across their surface
    // are compared. A turn moves the short wall pieces at a band's ends mostly along
    // themselves too, yet their turning is what tells it: there every point counts.
    let shifted =
        realms_core::geometry::normalize_angle_rad(q.yaw_rad - p.yaw_rad).abs() < SAME_HEADING_RAD;
    let informative = if shifted {
        moved_across(a, b, overlap, p, q)
    } else {
        vec![true; cp.len()]
    };
    let min_common = if shifted {
        MIN_MOVED_ACROSS_POINTS
    } else {
        MIN_COMMON_POINTS
    };
    let (mut n, mut sum_p, mut sum, mut sum2) = (0usize, 0.0, 0.0, 0.0);
    for ((x, y), _) in cp.iter().zip(&cq).zip(&informative).filter(|(_, i)| **i) {
        if let (Some(x), Some(y)) = (x, y) {
            let d = y - x;
            n += 1;
            sum_p += x;
            sum += d;
            sum2 += d * d;
        }
    }
    let nf = n.max(1) as f64;
    let mean = sum / nf;
    // Too few points in common is no evidence either way; and differences below a
    // thousandth of a cell squared are rounding.
    let z = if n < min_common {
        0.0
    } else {
        let var = (sum2 - nf * mean * mean).max(0.0) / (nf - 1.0);
        mean / (var / nf + (1e-3 * cap).powi(2)).sqrt()
    };
    Comparison {
        common: n,
        z,
        rms_p_m: (sum_p / nf).sqrt(),
        rms_q_m: ((sum_p + sum) / nf).max(0.0).sqrt(),
    }
}

/// Poses whose headings differ by less than this are shifts of one another in [`compare`].
const SAME_HEADING_RAD: f64 = 1e-9;

/// For each point of `overlap`, in [`for_points`]' order: whether going from pose `p` to
/// `q` moves the other map across its surface there rather than along it (by at least
/// half the move, along the point's normal). A wall slid along itself says nothing about
/// which of two poses is right; its points' costs differ only by the noise along it
/// (speckle, missed cells, the staircase of a turned wall), and that noise would drown the
/// few points that do tell, a rock's or a rim's.
fn moved_across(a: &Surfaces, b: &Surfaces, overlap: &Overlap, p: &Pose2, q: &Pose2) -> Vec<bool> {
    let (at_p, at_q, back_p) = (Rigid::new(p), Rigid::new(q), Rigid::new(&p.inverse()));
    let across = |n: [f64; 2], from: Point2, to: Point2| {
        let (dx, dy) = (to.x_m - from.x_m, to.y_m - from.y_m);
        let moved = dx.hypot(dy);
        moved < 1e-9 || (n[0] * dx + n[1] * dy).abs() >= 0.5 * moved
    };
    let mut out = Vec::with_capacity(overlap.a.len() + overlap.b.len());
    for &i in &overlap.b {
        let (x, n) = b.points[i];
        out.push(across(at_p.turn(n), at_p.apply(x), at_q.apply(x)));
    }
    for &i in &overlap.a {
        let (x, n) = a.points[i];
        // The second map's ground under this point at `p`, carried to where `q` puts it.
        out.push(across(n, x, at_q.apply(back_p.apply(x))));
    }
    out
}

/// What [`nearby`] asks of another fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RivalRule {
    /// A fit settled farther than this from the best at the overlap's centre, metres ...
    pub apart_m: f64,
    /// ... or turned farther than this from it, radians ...
    pub apart_rad: f64,
    /// ... that fits worse by fewer standard errors than this ([`Comparison::z`]) is a
    /// rival: the surfaces do not tell the two apart ...
    pub max_z: f64,
    /// ... unless it fits better by at least this many (negative): then it is the better
    /// pose.
    pub better_z: f64,
}

/// Points (both maps) a restart of [`nearby`] is fitted on, at most.
const PROBE_FIT_POINTS: usize = 1500;
/// Distances (metres) of the restarts [`nearby`] fits from, in eight directions each.
const PROBE_SHIFTS_M: [f64; 3] = [0.1, 0.2, 0.35];
/// Turns (radians: half a degree, one and three) about the overlap's centre it fits from,
/// either way.
const PROBE_TURNS_RAD: [f64; 3] = [0.0087, 0.0175, 0.052];
/// Turns about either end of the overlap, by the angle that moves the other end this far
/// (metres): a band pinned at one end swings about it.
const PROBE_SWING_M: f64 = 0.3;

/// What fits restarted around a pose found ([`nearby`]).
#[derive(Clone, Copy, Debug)]
pub enum Nearby {
    /// None settled apart from it that fits about as closely.
    Alone,
    /// One settled apart and fits clearly more closely (by [`RivalRule::better_z`]): the
    /// pose was not the optimum.
    Better(Pose2, Comparison),
    /// One settled apart and fits about as closely: the surfaces do not tell the two apart.
    Rival(Pose2, Comparison),
}

/// Fits restarted from poses around `best` (shifted, turned about the overlap's `centre`,
/// swung about either of its `ends`; grid-local in the second map): the first that settles
/// apart from `best` and fits clearly more closely, else the first that fits about as
/// closely, by `rule`. With `heading_held`, the restarts are shifts only and keep `best`'s
/// heading ([`align_at_heading`]).
#[allow(clippy::too_many_arguments)]
pub fn nearby(
    a: &Surfaces,
    b: &Surfaces,
    overlap: &Overlap,
    best: &Pose2,
    centre: Point2,
    ends: [Point2; 2],
    rule: &RivalRule,
    heading_held: bool,
) -> Nearby {
    let mut probes = Vec::new();
    for shift in PROBE_SHIFTS_M {
        for k in 0..8 {
            let (s, c) = (f64::from(k) * std::f64::consts::FRAC_PI_4).sin_cos();
            probes.push(Pose2::new(
                best.x_m + shift * c,
                best.y_m + shift * s,
                best.yaw_rad,
            ));
        }
    }
    if !heading_held {
        for turn in PROBE_TURNS_RAD {
            probes.push(crate::verify::turned_about(best, centre, turn));
            probes.push(crate::verify::turned_about(best, centre, -turn));
        }
        let swing = (PROBE_SWING_M / ends[0].distance_m(ends[1]).max(1.0)).min(0.1);
        for pivot in ends {
            probes.push(crate::verify::turned_about(best, pivot, swing));
            probes.push(crate::verify::turned_about(best, pivot, -swing));
        }
    }
    let here = best.transform_point(centre);
    // Where a restart settles needs fewer points than comparing two poses does.
    let thinned = overlap.thinned(PROBE_FIT_POINTS);
    let mut rival = None;
    for probe in probes {
        let p = align_with(a, b, &thinned, probe, !heading_held).pose;
        let apart = p.transform_point(centre).distance_m(here) > rule.apart_m
            || realms_core::geometry::normalize_angle_rad(p.yaw_rad - best.yaw_rad).abs()
                > rule.apart_rad;
        if !apart {
            continue;
        }
        let comparison = compare(a, b, overlap, best, &p);
        if comparison.z <= rule.better_z {
            return Nearby::Better(p, comparison);
        }
        if comparison.z < rule.max_z && rival.is_none() {
            rival = Some((p, comparison));
        }
    }
    rival.map_or(Nearby::Alone, |(p, c)| Nearby::Rival(p, c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::Despeckled;
    use crate::map::{Map, MapCell};
    use realms_core::{Grid, GridGeometry};

    /// A 10 m x 8 m room drawn on 5 cm cells from a frame whose pose in the room is
    /// `room_from_grid`: walls 10 cm thick along `walls` (y = 0 and y = 8 m; and x = 0 if
    /// `corner`), round rocks of 20 cm radius at `rocks` (room metres), free inside.
    fn room(room_from_grid: &Pose2, corner: bool, rocks: &[(f64, f64)]) -> Surfaces {
        room_at(room_from_grid, corner, rocks, 0.05)
    }

    /// [`room`] on cells of `cell_m`.
    fn room_at(
        room_from_grid: &Pose2,
        corner: bool,
        rocks: &[(f64, f64)],
        cell_m: f64,
    ) -> Surfaces {
        let g = GridGeometry {
            width: (12.0 / cell_m).round() as usize,
            height: (10.0 / cell_m).round() as usize,
            resolution_m: cell_m,
            origin: Point2::new(-1.0, -1.0),
        };
        let mut grid = Grid::new(g, MapCell::Unknown);
        for y in 0..g.height {
            for x in 0..g.width {
                let c = g.cell_center(realms_core::Cell { x, y });
                let p = room_from_grid.transform_point(c);
                let inside = (-0.1..10.0).contains(&p.x_m) && (-0.1..8.1).contains(&p.y_m);
                let wall = p.y_m < 0.0 || p.y_m > 8.0 || (corner && p.x_m < 0.0);
                let rock = rocks
                    .iter()
                    .any(|&(rx, ry)| (p.x_m - rx).hypot(p.y_m - ry) < 0.2);
                if let Some(cell) = grid.get_mut(x, y) {
                    *cell = match (inside, wall || rock) {
                        (false, _) => MapCell::Unknown,
                        (true, true) => MapCell::Occupied,
                        (true, false) => MapCell::Free,
                    };
                }
            }
        }
        let map = Map::new(grid);
        Surfaces::of(&Outline::of(&Despeckled::of(&map), cell_m))
    }

    #[test]
    fn a_shift_along_the_walls_is_judged_on_what_it_moves_across() {
        // Two walls along x (grid-local y = 1 m and 9 m) and a rock at (6, 5).
        let room_from = Pose2::new(0.0, 0.0, 0.0);
        let s = room(&room_from, false, &[(5.0, 4.0)]);
        let p = grid_pose(&room_from, &room_from);
        let overlap = Overlap::at(&s, &s, &p, 0.5);
        let points: Vec<Point2> = overlap
            .b
            .iter()
            .chain(&overlap.a)
            .map(|&i| s.points[i].0)
            .collect();
        let share = |q: &Pose2, near: &dyn Fn(Point2) -> bool| {
            let informative = moved_across(&s, &s, &overlap, &p, q);
            let (mut n, mut k) = (0usize, 0usize);
            for (pt, inf) in points.iter().zip(&informative) {
                if near(*pt) {
                    n += 1;
                    k += usize::from(*inf);
                }
            }
            assert!(n > 10, "{n} points");
            k as f64 / n as f64
        };
        let walls = |q: Point2| {
            (2.0..9.0).contains(&q.x_m) && ((q.y_m - 1.0).abs() < 0.3 || (q.y_m - 9.0).abs() < 0.3)
        };
        let rock = |q: Point2| q.distance_m(Point2::new(6.0, 5.0)) < 0.5;
        let along = Pose2::new(p.x_m + 0.3, p.y_m, p.yaw_rad);
        let across = Pose2::new(p.x_m, p.y_m + 0.3, p.yaw_rad);
        // Slid along the walls, only the rock tells; moved across them, the walls do.
        assert_eq!(share(&along, &walls), 0.0);
        assert!(share(&along, &rock) > 0.4, "{}", share(&along, &rock));
        assert!(share(&across, &walls) > 0.95, "{}", share(&across, &walls));
    }

    /// Grid-local pose of the second room drawing in the first (both drawn with the room's
    /// frame at the grids' `origin` of (-1, -1)).
    fn grid_pose(room_from_a: &Pose2, room_from_b: &Pose2) -> Pose2 {
        let grid_from_local = Pose2::new(-1.0, -1.0, 0.0);
        grid_from_local
            .inverse()
            .compose(&room_from_a.inverse())
            .compose(room_from_b)
            .compose(&grid_from_local)
    }

    /// The fit of `b` onto `a` from `start`, its overlap, and how far it lands from `truth`
    /// at the room's middle (metres) and in heading (degrees).
    fn fit_from(
        a: &Surfaces,
        b: &Surfaces,
        truth: &Pose2,
        start: Pose2,
    ) -> (FineFit, Overlap, f64, f64) {
        let overlap = Overlap::at(a, b, &start, 0.5);
        let fit = align(a, b, &overlap, start);
        let c = Point2::new(5.0, 4.0);
        let off = fit
            .pose
            .transform_point(c)
            .distance_m(truth.transform_point(c));
        let turn = (fit.pose.yaw_rad - truth.yaw_rad).abs().to_degrees();
        (fit, overlap, off, turn)
    }

    #[test]
    fn a_fit_recovers_a_pose_to_a_fraction_of_a_cell() {
        let rocks = [(3.0, 2.5), (6.2, 5.1), (7.5, 1.7)];
        let room_from_a = Pose2::new(0.0, 0.0, 0.0);
        let room_from_b = Pose2::new(0.023, -0.017, 0.4f64.to_radians());
        let a = room(&room_from_a, true, &rocks);
        let b = room(&room_from_b, true, &rocks);
        let truth = grid_pose(&room_from_a, &room_from_b);
        let start = Pose2::new(truth.x_m + 0.08, truth.y_m - 0.06, truth.yaw_rad + 0.01);
        let (fit, overlap, off, turn) = fit_from(&a, &b, &truth, start);
        assert!(off < 0.01 && turn < 0.1, "{off} m, {turn} deg off; {fit:?}");
        assert!(fit.pairs > 500, "{fit:?}");
        // Nothing else fits as closely.
        let rule = RivalRule {
            apart_m: 0.1,
            apart_rad: 0.5f64.to_radians(),
            max_z: 1.0,
            better_z: -2.0,
        };
        let ends = [Point2::new(1.0, 4.0), Point2::new(9.0, 4.0)];
        let c = Point2::new(5.0, 4.0);
        let found = nearby(&a, &b, &overlap, &fit.pose, c, ends, &rule, false);
        assert!(matches!(found, Nearby::Alone), "{found:?}");
    }

    #[test]
    fn maps_of_different_resolutions_are_fitted_alike() {
        let rocks = [(3.0, 2.5), (6.2, 5.1), (7.5, 1.7)];
        let room_from_a = Pose2::new(0.0, 0.0, 0.0);
        let room_from_b = Pose2::new(-0.031, 0.012, -0.6f64.to_radians());
        let a = room(&room_from_a, true, &rocks);
        let b = room_at(&room_from_b, true, &rocks, 0.1);
        let truth = grid_pose(&room_from_a, &room_from_b);
        let start = Pose2::new(truth.x_m - 0.07, truth.y_m + 0.05, truth.yaw_rad - 0.008);
        let (fit, _, off, turn) = fit_from(&a, &b, &truth, start);
        assert!(off < 0.02 && turn < 0.2, "{off} m, {turn} deg off; {fit:?}");
    }

    #[test]
    fn a_corridor_with_nothing_in_it_has_a_rival_along_itself() {
        let room_from_a = Pose2::new(0.0, 0.0, 0.0);
        let room_from_b = Pose2::new(0.03, 0.01, 0.0);
        let rule = RivalRule {
            apart_m: 0.1,
            apart_rad: 0.5f64.to_radians(),
            max_z: 1.0,
            better_z: -2.0,
        };
        let c = Point2::new(5.0, 4.0);
        let ends = [Point2::new(1.0, 4.0), Point2::new(9.0, 4.0)];
        let truth = grid_pose(&room_from_a, &room_from_b);
        let bare = (
            room(&room_from_a, false, &[]),
            room(&room_from_b, false, &[]),
        );
        let overlap = Overlap::at(&bare.0, &bare.1, &truth, 0.5);
        let fit = align(&bare.0, &bare.1, &overlap, truth);
        let found = nearby(&bare.0, &bare.1, &overlap, &fit.pose, c, ends, &rule, false);
        let Nearby::Rival(p, comparison) = found else {
            panic!("a corridor's walls slide along themselves: {found:?}");
        };
        // The rival slid along the walls (x), not across them.
        let (here, there) = (fit.pose.transform_point(c), p.transform_point(c));
        assert!((there.x_m - here.x_m).abs() > 0.05, "{here:?} -> {there:?}");
        assert!((there.y_m - here.y_m).abs() < 0.02, "{here:?} -> {there:?}");
        // Nothing the slide moves across its surface: no evidence either way.
        assert!(
            comparison.common < 30 && comparison.z == 0.0,
            "{comparison:?}"
        );
        // A rock in the corridor pins it.
        let rocks = [(4.0, 3.0)];
        let pinned = (
            room(&room_from_a, false, &rocks),
            room(&room_from_b, false, &rocks),
        );
        let overlap = Overlap::at(&pinned.0, &pinned.1, &truth, 0.5);
        let fit = align(&pinned.0, &pinned.1, &overlap, truth);
        let found = nearby(
            &pinned.0, &pinned.1, &overlap, &fit.pose, c, ends, &rule, false,
        );
        assert!(matches!(found, Nearby::Alone), "{found:?}");
    }

    #[test]
    fn the_eigen_decomposition_rebuilds_its_matrix() {
        let m = [[4.0, 1.0, -2.0], [1.0, 3.0, 0.5], [-2.0, 0.5, 1e-3]];
        let (values, vectors) = eigen_symmetric3(&m);
        for r in 0..3 {
            for c in 0..3 {
                let rebuilt: f64 = (0..3)
                    .map(|k| values[k] * vectors[k][r] * vectors[k][c])
                    .sum();
                assert!(
                    (rebuilt - m[r][c]).abs() < 1e-9,
                    "({r}, {c}): {rebuilt} against {}",
                    m[r][c]
                );
            }
        }
        // A direction nothing pins has a zero eigenvalue along it.
        let wall = [[0.0, 0.0, 0.0], [0.0, 50.0, 5.0], [0.0, 5.0, 20.0]];
        let (values, vectors) = eigen_symmetric3(&wall);
        let k = (0..3)
            .min_by(|&i, &j| values[i].total_cmp(&values[j]))
            .expect("three");
        assert!(
            values[k].abs() < 1e-12 && vectors[k][0].abs() > 1.0 - 1e-12,
            "{values:?} {vectors:?}"
        );
    }

    #[test]
    fn poses_sharing_too_few_points_are_not_told_apart() {
        let room_from_a = Pose2::new(0.0, 0.0, 0.0);
        let a = room(&room_from_a, true, &[(3.0, 2.5)]);
        let b = room(&room_from_a, true, &[(3.0, 2.5)]);
        let truth = grid_pose(&room_from_a, &room_from_a);
        let overlap = Overlap::at(&a, &b, &truth, 0.5);
        let off = Pose2::new(truth.x_m + 0.04, truth.y_m, truth.yaw_rad);
        // On all the points it moves across their surfaces (the wall at x = 0, the rock),
        // 4 cm off is clearly worse ...
        let all = compare(&a, &b, &overlap, &truth, &off);
        assert!(all.common > 150 && all.z > 3.0, "{all:?}");
        // ... on a handful of them, no evidence either way.
        let few = overlap.thinned(20);
        let some = compare(&a, &b, &few, &truth, &off);
        assert!(some.common < 30 && some.z == 0.0, "{some:?}");
    }
}
