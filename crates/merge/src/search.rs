//! Global correlative search: for a set of headings, every translation of one map's
//! structure points over the other map's score field, searched exactly by best-first branch
//! and bound, returning the best few *distinct* poses (not just the best one).
//!
//! The idea is Olson's correlative matching ("Real-Time Correlative Scan Matching", ICRA
//! 2009) with the precomputed block-maximum grids of Hess et al. ("Real-Time Loop Closure in
//! 2D LIDAR SLAM", ICRA 2016), as `realms-slam::bnb` uses for loop closure; here the window
//! is the whole map, the score punishes structure that lands on the other map's free space
//! (low overlap makes plain hit counting favour any pose that lays walls over walls), and
//! the search is best-first over all headings at once, so leaves come out in score order and
//! the first `k` mutually distinct ones are the `k` best hypotheses.

use crate::level::{Class, Level, Surface};
use realms_core::{Point2, Pose2};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Score of a structure point landing on structure.
const HIT: i8 = 2;
/// ... next to structure (one cell of slack for resampling and rotation steps).
const NEAR: i8 = 1;

/// Direction bins of the surface fields: a surface point scores only on surfaces whose free
/// side faces within about one bin of its own (two maps that share a wall saw it from the
/// same side; laying a wall's back onto another map's wall is not agreement).
pub const DIRECTION_BINS: usize = 8;

/// The bin of a free-side direction, radians.
pub fn direction_bin(normal_rad: f64) -> usize {
    // Nearest bin, wrapped with a mask (the bin count is a power of two): no fmod and no
    // rounding call, for the millions of points refinement scores.
    const _: () = assert!(DIRECTION_BINS.is_power_of_two());
    let t = normal_rad * (DIRECTION_BINS as f64 / std::f64::consts::TAU);
    (crate::level::floor_i64(t + 0.5) & (DIRECTION_BINS as i64 - 1)) as usize
}

/// Whether direction bins `m` and `n` face within one bin of each other (wrapped).
#[inline]
pub fn bins_face_alike(m: usize, n: usize) -> bool {
    let d = m.abs_diff(n);
    d.min(DIRECTION_BINS - d) <= 1
}

/// The score fields of one map, one per direction bin.
#[derive(Clone, Debug)]
pub struct Fields {
    /// Pyramid of bin `k`.
    pub bins: Vec<Pyramid>,
    /// Where the map's free cells were not judged for hazards
    /// ([`crate::Map::free_judged_for_hazards`]): the same fields without the free-space
    /// penalty, for the other map's hazard points.
    pub hazard_bins: Option<Vec<Pyramid>>,
}

/// A point's field code: its direction bin, plus [`DIRECTION_BINS`] for a hazard point.
pub fn field_code(bin: usize, hazard: bool) -> usize {
    bin + if hazard { DIRECTION_BINS } else { 0 }
}

impl Fields {
    /// The fields of `level` with `depth + 1` pyramid levels.
    pub fn new(level: &Level, free_penalty: i8, depth: usize) -> Fields {
        let (w, h) = (level.width, level.height);
        // Bit k: a surface facing within a bin of k is here (hit) / within a cell (near).
        let mut hit = vec![0u8; w * h];
        for (i, (c, n)) in level.class.iter().zip(&level.normal).enumerate() {
            if c.is_feature() && !n.is_nan() {
                let b = direction_bin(*n as f64);
                for k in [b + DIRECTION_BINS - 1, b, b + 1] {
                    hit[i] |= 1 << (k % DIRECTION_BINS);
                }
            }
        }
        let mut near = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut m = 0u8;
                for ny in y.saturating_sub(1)..(y + 2).min(h) {
                    for nx in x.saturating_sub(1)..(x + 2).min(w) {
                        m |= hit[ny * w + nx];
                    }
                }
                near[y * w + x] = m;
            }
        }
        let field = |k: usize, penalty: i8| {
            let bit = 1u8 << k;
            let base = (0..w * h)
                .map(|i| {
                    if hit[i] & bit != 0 {
                        HIT
                    } else if near[i] & bit != 0 {
                        NEAR
                    } else if level.class[i] == Class::Free && level.dist[i] > 15 {
                        -penalty
                    } else {
                        0
                    }
                })
                .collect();
            Pyramid::new(w, h, base, depth)
        };
        let bins = (0..DIRECTION_BINS)
            .map(|k| field(k, free_penalty))
            .collect();
        let hazard_bins = (!level.free_judged_for_hazards)
            .then(|| (0..DIRECTION_BINS).map(|k| field(k, 0)).collect());
        Fields { bins, hazard_bins }
    }

    /// The field for points of code `code` ([`field_code`]).
    #[inline]
    pub fn pyramid(&self, code: usize) -> &Pyramid {
        match (&self.hazard_bins, code.checked_sub(DIRECTION_BINS)) {
            (Some(hazard), Some(k)) => &hazard[k],
            (None, Some(k)) => &self.bins[k],
            (_, None) => &self.bins[code],
        }
    }
}

/// A score field and its stack of block maxima.
#[derive(Clone, Debug)]
pub struct Pyramid {
    width: i64,
    height: i64,
    /// Level `d`: cells `[-(2^d - 1), width)` x `[-(2^d - 1), height)`, row by row; the
    /// maximum of level 0 over the `2^d x 2^d` block starting at the cell.
    levels: Vec<Vec<i8>>,
}

impl Pyramid {
    /// The block maxima of `base` (`width x height`, row-major) up to blocks of `2^depth`.
    pub fn new(width: usize, height: usize, base: Vec<i8>, depth: usize) -> Pyramid {
        let (w0, h0) = (width as i64, height as i64);
        let mut levels = vec![base];
        for d in 1..=depth {
            let half = 1i64 << (d - 1);
            let (pad, prev_pad) = ((1i64 << d) - 1, half - 1);
            let prev = &levels[d - 1];
            let (pw, ph) = (w0 + prev_pad, h0 + prev_pad);
            // Level d - 1 at (x, y), 0 outside; the padded index only ever falls below the
            // grid on the low side by construction, so one comparison per axis suffices.
            let get = |x: i64, y: i64| -> i8 {
                let (ix, iy) = (x + prev_pad, y + prev_pad);
                if ix < 0 || iy < 0 || ix >= pw || iy >= ph {
                    0
                } else {
                    prev[(iy * pw + ix) as usize]
                }
            };
            let (w, h) = (w0 + pad, h0 + pad);
            // Horizontal then vertical maximum: two reads per cell instead of four.
            let mut horiz = vec![0i8; (w * (h0 + prev_pad)) as usize];
            for y in -prev_pad..h0 {
                let row = ((y + prev_pad) * w) as usize;
                for x in -pad..w0 {
                    horiz[row + (x + pad) as usize] = get(x, y).max(get(x + half, y));
                }
            }
            let hget = |x: i64, y: i64| -> i8 {
                let iy = y + prev_pad;
                if iy < 0 || iy >= h0 + prev_pad {
                    0
                } else {
                    horiz[(iy * w + x + pad) as usize]
                }
            };
            let mut cells = vec![0i8; (w * h) as usize];
            for y in -pad..h0 {
                let row = ((y + pad) * w) as usize;
                for x in -pad..w0 {
                    cells[row + (x + pad) as usize] = hget(x, y).max(hget(x, y + half));
                }
            }
            levels.push(cells);
        }
        Pyramid {
            width: w0,
            height: h0,
            levels,
        }
    }

    /// The deepest level.
    pub fn depth(&self) -> usize {
        self.levels.len() - 1
    }

    /// The field at `(x, y)`; 0 (unknown) outside.
    pub fn value(&self, x: i64, y: i64) -> i8 {
        self.at(0, x, y)
    }

    /// Level `d` at `(x, y)`; 0 (unknown) outside.
    #[inline]
    fn at(&self, d: usize, x: i64, y: i64) -> i8 {
        let pad = (1i64 << d) - 1;
        let (ix, iy) = (x + pad, y + pad);
        let w = self.width + pad;
        if ix < 0 || iy < 0 || ix >= w || iy >= self.height + pad {
            return 0;
        }
        self.levels[d][(iy * w + ix) as usize]
    }
}

/// A local search window: the moving map's centre must land within `half_m` (in x and in
/// y) of `centroid_at`, a point in the fixed grid's local metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    /// Where the prior puts the moving map's centre, fixed grid-local metres.
    pub centroid_at: Point2,
    /// Half-width, metres.
    pub half_m: f64,
}

/// Search settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchParams {
    /// How many distinct hypotheses to return.
    pub hypotheses: usize,
    /// Two poses are the same hypothesis if they put the moving map's centre within this
    /// many metres of each other...
    pub distinct_m: f64,
    /// ... and differ in heading by less than this.
    pub distinct_rad: f64,
    /// Leaves scoring below this are not hypotheses.
    pub min_score: i32,
    /// Nor are leaves scoring below this share of the best leaf.
    pub min_share_of_best: f64,
    /// Give up expanding after this many nodes (a safety net; the answer is then partial).
    pub max_nodes: usize,
}

/// What a search cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SearchStats {
    /// Headings searched.
    pub headings: usize,
    /// Nodes expanded by branch and bound.
    pub nodes: usize,
}

/// One hypothesis: where the moving grid lies in the fixed grid, and its search score.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hypothesis {
    /// Pose of the moving map's grid-local frame in the fixed map's grid-local frame.
    pub fixed_from_moving: Pose2,
    /// Heading index into the searched headings.
    pub angle_index: usize,
    /// Sum of field values under the moving points.
    pub score: i32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Node {
    bound: i32,
    depth: u8,
    angle: u32,
    tx: i32,
    ty: i32,
}

impl Ord for Node {
    fn cmp(&self, o: &Self) -> Ordering {
        // Highest bound first; at equal bound the finer node (closer to a leaf); then a
        // fixed order so results never depend on heap internals.
        self.bound
            .cmp(&o.bound)
            .then(o.depth.cmp(&self.depth))
            .then(o.angle.cmp(&self.angle))
            .then(o.tx.cmp(&self.tx))
            .then(o.ty.cmp(&self.ty))
    }
}

impl PartialOrd for Node {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// One heading: the moving points in field cells (floored) with their field codes
/// ([`field_code`]: direction bin, hazard or not), and the translation range.
struct Heading {
    yaw_rad: f64,
    cells: Vec<(i32, i32, u8)>,
    /// Weight of each cell's point.
    weights: Vec<i32>,
    /// Bounding box of `cells`: x0, y0, x1, y1.
    bbox: (i64, i64, i64, i64),
    /// Runs of equal field code in `cells`: (code, start, end).
    runs: Vec<(usize, usize, usize)>,
    /// Per pyramid level, each cell's row-major offset in that level's padded array.
    offsets: Vec<Vec<i64>>,
    /// Translation range, inclusive, cells.
    tx: (i64, i64),
    ty: (i64, i64),
    /// The moving centroid rotated, field cells (for telling hypotheses apart).
    centroid: (f64, f64),
}

/// Best-first branch and bound over `yaws_rad` and every translation that makes the moving
/// `points` (grid-local metres) land on the field at least partly, or only those in
/// `window`. `centroid` is the moving map's centre (grid-local metres), used to tell
/// hypotheses apart.
pub fn search(
    fields: &Fields,
    cell_m: f64,
    points: &[Surface],
    centroid: Point2,
    yaws_rad: &[f64],
    window: Option<Window>,
    params: &SearchParams,
) -> (Vec<Hypothesis>, SearchStats) {
    if points.is_empty() || yaws_rad.is_empty() {
        return (Vec::new(), SearchStats::default());
    }
    let headings: Vec<Heading> = yaws_rad
        .iter()
        .map(|yaw| {
            let (s, c) = yaw.sin_cos();
            let mut weighted: Vec<((i32, i32, u8), i32)> = points
                .iter()
                .map(|sf| {
                    let p = sf.p;
                    (
                        (
                            ((c * p.x_m - s * p.y_m) / cell_m).floor() as i32,
                            ((s * p.x_m + c * p.y_m) / cell_m).floor() as i32,
                            field_code(direction_bin(sf.normal_rad + yaw), sf.hazard) as u8,
                        ),
                        sf.weight as i32,
                    )
                })
                .collect();
            // By field code, so that scoring walks one field at a time.
            weighted.sort_by_key(|(c, _)| c.2);
            let (cells, weights): (Vec<(i32, i32, u8)>, Vec<i32>) = weighted.into_iter().unzip();
            let (mut x0, mut y0, mut x1, mut y1) = (i64::MAX, i64::MAX, i64::MIN, i64::MIN);
            for (x, y, _) in &cells {
                (x0, y0) = (x0.min(*x as i64), y0.min(*y as i64));
                (x1, y1) = (x1.max(*x as i64), y1.max(*y as i64));
            }
            let (fw, fh) = (fields.bins[0].width, fields.bins[0].height);
            let mut tx = (-x1, fw - 1 - x0);
            let mut ty = (-y1, fh - 1 - y0);
            let rotated = (
                (c * centroid.x_m - s * centroid.y_m) / cell_m,
                (s * centroid.x_m + c * centroid.y_m) / cell_m,
            );
            if let Some(w) = window {
                let cx = (w.centroid_at.x_m / cell_m - rotated.0).round() as i64;
                let cy = (w.centroid_at.y_m / cell_m - rotated.1).round() as i64;
                let half = (w.half_m / cell_m).ceil() as i64;
                tx = (tx.0.max(cx - half), tx.1.min(cx + half));
                ty = (ty.0.max(cy - half), ty.1.min(cy + half));
            }
            let mut runs: Vec<(usize, usize, usize)> = Vec::new();
            for (i, c) in cells.iter().enumerate() {
                match runs.last_mut() {
                    Some(r) if r.0 == c.2 as usize => r.2 = i + 1,
                    _ => runs.push((c.2 as usize, i, i + 1)),
                }
            }
            let offsets = (0..=fields.bins[0].depth())
                .map(|d| {
                    let w = fw + (1i64 << d) - 1;
                    cells
                        .iter()
                        .map(|(x, y, _)| *y as i64 * w + *x as i64)
                        .collect()
                })
                .collect();
            Heading {
                yaw_rad: *yaw,
                cells,
                weights,
                bbox: (x0, y0, x1, y1),
                runs,
                offsets,
                tx,
                ty,
                centroid: rotated,
            }
        })
        .collect();
    let (fw, fh) = (fields.bins[0].width, fields.bins[0].height);
    let score = |d: usize, h: &Heading, tx: i64, ty: i64| -> i32 {
        let pad = (1i64 << d) - 1;
        let (w, hh) = (fw + pad, fh + pad);
        let (x0, y0, x1, y1) = h.bbox;
        let inside =
            x0 + tx + pad >= 0 && y0 + ty + pad >= 0 && x1 + tx + pad < w && y1 + ty + pad < hh;
        if inside {
            // Every point lands in the array: plain indexed sums, one field per run.
            let shift = (ty + pad) * w + tx + pad;
            let offs = &h.offsets[d];
            h.runs
                .iter()
                .map(|&(k, a, b)| {
                    let cells = &fields.pyramid(k).levels[d];
                    offs[a..b]
                        .iter()
                        .zip(&h.weights[a..b])
                        .map(|(o, w)| cells[(o + shift) as usize] as i32 * w)
                        .sum::<i32>()
                })
                .sum()
        } else {
            h.cells
                .iter()
                .zip(&h.weights)
                .map(|((x, y, k), w)| {
                    fields
                        .pyramid(*k as usize)
                        .at(d, *x as i64 + tx, *y as i64 + ty) as i32
                        * w
                })
                .sum()
        }
    };
    let top = fields.bins[0].depth();
    let step = 1i64 << top;
    let mut heap = BinaryHeap::new();
    for (a, h) in headings.iter().enumerate() {
        let mut tx = h.tx.0;
        while tx <= h.tx.1 {
            let mut ty = h.ty.0;
            while ty <= h.ty.1 {
                let bound = score(top, h, tx, ty);
                if bound >= params.min_score {
                    heap.push(Node {
                        bound,
                        depth: top as u8,
                        angle: a as u32,
                        tx: tx as i32,
                        ty: ty as i32,
                    });
                }
                ty += step;
            }
            tx += step;
        }
    }
    let distinct_cells = params.distinct_m / cell_m;
    let mut found: Vec<(Node, (f64, f64))> = Vec::new();
    let mut expanded = 0usize;
    while let Some(n) = heap.pop() {
        if found.len() >= params.hypotheses {
            break;
        }
        // Best-first: once the best leaf is out, nothing below the share can follow it.
        if let Some((best, _)) = found.first()
            && (n.bound as f64) < params.min_share_of_best * best.bound as f64
        {
            break;
        }
        let h = &headings[n.angle as usize];
        if n.depth == 0 {
            let c = (h.centroid.0 + n.tx as f64, h.centroid.1 + n.ty as f64);
            let same = found.iter().any(|(m, mc)| {
                let dyaw = realms_core::geometry::normalize_angle_rad(
                    headings[m.angle as usize].yaw_rad - h.yaw_rad,
                );
                (c.0 - mc.0).hypot(c.1 - mc.1) < distinct_cells && dyaw.abs() < params.distinct_rad
            });
            if !same {
                found.push((n, c));
            }
            continue;
        }
        expanded += 1;
        if expanded > params.max_nodes {
            break;
        }
        let d = n.depth as usize - 1;
        let half = 1i64 << d;
        for (ox, oy) in [(0, 0), (half, 0), (0, half), (half, half)] {
            let (tx, ty) = (n.tx as i64 + ox, n.ty as i64 + oy);
            if tx > h.tx.1 || ty > h.ty.1 {
                continue;
            }
            let bound = score(d, h, tx, ty);
            if bound >= params.min_score {
                heap.push(Node {
                    bound,
                    depth: d as u8,
                    angle: n.angle,
                    tx: tx as i32,
                    ty: ty as i32,
                });
            }
        }
    }
    let stats = SearchStats {
        headings: headings.len(),
        nodes: expanded,
    };
    let found = found
        .into_iter()
        .map(|(n, _)| {
            let h = &headings[n.angle as usize];
            Hypothesis {
                fixed_from_moving: Pose2::new(
                    n.tx as f64 * cell_m,
                    n.ty as f64 * cell_m,
                    h.yaw_rad,
                ),
                angle_index: n.angle as usize,
                score: n.bound,
            }
        })
        .collect();
    (found, stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Map, MapCell};
    use realms_core::{Grid, GridGeometry};

    /// An L of walls and two posts on free ground.
    fn room() -> Map {
        let g = GridGeometry {
            width: 60,
            height: 40,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut grid = Grid::new(g, MapCell::Free);
        for x in 0..60 {
            *grid.get_mut(x, 0).expect("in") = MapCell::Occupied;
        }
        for y in 0..40 {
            *grid.get_mut(0, y).expect("in") = MapCell::Occupied;
        }
        for (x, y) in [(20, 20), (21, 20), (20, 21), (40, 10), (41, 10), (41, 11)] {
            *grid.get_mut(x, y).expect("in") = MapCell::Occupied;
        }
        Map::new(grid)
    }

    #[test]
    fn direction_bins_are_nearest_and_wrap() {
        use std::f64::consts::{FRAC_PI_4, PI};
        for (rad, bin) in [
            (0.0, 0),
            (FRAC_PI_4, 1),
            (-FRAC_PI_4, 7),
            (PI, 4),
            (-PI, 4),
            (2.0 * PI - 0.01, 0),
            (7.0 * PI, 4),
            (0.3, 0),
            (0.5, 1),
        ] {
            assert_eq!(direction_bin(rad), bin, "{rad}");
        }
        for x in [-2.5, -2.0, -0.1, 0.0, 0.1, 1.0, 3.7] {
            assert_eq!(crate::level::floor_i64(x), x.floor() as i64, "{x}");
        }
    }

    #[test]
    fn finds_a_shift_and_equals_brute_force() {
        let map = room();
        let level = Level::build(&map, 0.1);
        let fields = Fields::new(&level, 1, 4);
        let pts = level.surfaces(10_000);
        assert!(pts.len() > 50);
        // The same points moved by (-0.7, 0.3) m: the search must put them back.
        let moved: Vec<Surface> = pts
            .iter()
            .map(|s| Surface {
                p: Point2::new(s.p.x_m - 0.7, s.p.y_m + 0.3),
                ..*s
            })
            .collect();
        let params = SearchParams {
            hypotheses: 3,
            distinct_m: 0.5,
            distinct_rad: 0.05,
            min_score: 1,
            min_share_of_best: 0.0,
            max_nodes: 1_000_000,
        };
        let yaws = [-0.05, 0.0, 0.05];
        let (found, stats) = search(
            &fields,
            0.1,
            &moved,
            Point2::new(3.0, 2.0),
            &yaws,
            None,
            &params,
        );
        let best = found.first().expect("a hypothesis");
        assert_eq!(best.angle_index, 1);
        assert!((best.fixed_from_moving.x_m - 0.7).abs() < 1e-9, "{best:?}");
        assert!((best.fixed_from_moving.y_m + 0.3).abs() < 1e-9, "{best:?}");
        // Brute force over the same window agrees on the best score.
        let mut brute = i32::MIN;
        for yaw in yaws {
            let (s, c) = yaw.sin_cos();
            for tx in -70..70 {
                for ty in -50..50 {
                    let sc: i32 = moved
                        .iter()
                        .map(|sf| {
                            let p = sf.p;
                            let x = ((c * p.x_m - s * p.y_m) / 0.1).floor() as i64 + tx;
                            let y = ((s * p.x_m + c * p.y_m) / 0.1).floor() as i64 + ty;
                            let k = direction_bin(sf.normal_rad + yaw);
                            fields.bins[k].at(0, x, y) as i32 * sf.weight as i32
                        })
                        .sum();
                    brute = brute.max(sc);
                }
            }
        }
        assert_eq!(best.score, brute);
        // Hypotheses come out best first and distinct.
        assert!(found.windows(2).all(|w| w[0].score >= w[1].score));
        assert!(stats.nodes > 0 && stats.headings == 3);
    }

    #[test]
    fn a_wall_seen_from_behind_does_not_match() {
        let map = room();
        let level = Level::build(&map, 0.1);
        let fields = Fields::new(&level, 1, 4);
        // The bottom wall's points, seen from below (free side down): no hit anywhere on
        // the bottom wall, which was seen from above.
        let flipped: Vec<Surface> = level
            .surfaces(10_000)
            .iter()
            .filter(|s| s.p.y_m < 0.1 && s.p.x_m > 0.5)
            .map(|s| Surface {
                normal_rad: -s.normal_rad,
                ..*s
            })
            .collect();
        let score: i32 = flipped
            .iter()
            .map(|s| {
                let k = direction_bin(s.normal_rad);
                fields.bins[k].at(0, (s.p.x_m / 0.1) as i64, (s.p.y_m / 0.1) as i64) as i32
            })
            .sum();
        assert!(score <= 0, "{score}");
    }
}
