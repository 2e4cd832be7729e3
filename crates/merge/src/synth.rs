//! Synthetic merging cases with a known answer, for tests and `realms bench merge`: two
//! partial maps cut from one source map with a chosen overlap, the second turned by a random
//! heading and shifted, both with unknown patches and sensor speckle.
//!
//! The cut: known cells are ordered along a random direction; the first map keeps those
//! before one line, the second those after another, placed so that the shared band holds
//! the chosen share of each map's known cells (both maps hold the same number of them).

use crate::map::{Map, MapCell};
use rand::Rng;
use realms_core::{Grid, GridGeometry, Point2, Pose2};
use std::f64::consts::PI;

/// How a case is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairSpec {
    /// Share of each partial map's known cells the other map also holds, 0..1.
    pub overlap: f64,
    /// Largest shift of the second map's frame, metres (each axis).
    pub max_shift_m: f64,
    /// Chance a free cell reads as an obstacle.
    pub speckle: f64,
    /// Chance an obstacle cell reads as free (missed returns).
    pub dropout: f64,
    /// Share of each map's known area blanked out by unknown discs.
    pub unknown_patches: f64,
}

impl Default for PairSpec {
    fn default() -> Self {
        PairSpec {
            overlap: 0.2,
            max_shift_m: 10.0,
            speckle: 0.002,
            dropout: 0.05,
            unknown_patches: 0.03,
        }
    }
}

/// A generated case.
#[derive(Clone, Debug)]
pub struct Pair {
    /// The first partial map (in the source's frame).
    pub a: Map,
    /// The second partial map, in its own frame.
    pub b: Map,
    /// The answer: pose of `b`'s frame in `a`'s frame.
    pub a_from_b: Pose2,
}

/// Cuts a case from `source`; `None` if the source has too few known cells.
pub fn make_pair(source: &Grid<MapCell>, spec: &PairSpec, rng: &mut impl Rng) -> Option<Pair> {
    let g = *source.geometry();
    let phi = rng.random_range(-PI..PI);
    let (s, c) = phi.sin_cos();
    let mut proj: Vec<(f32, usize)> = source
        .iter()
        .filter(|(_, v)| v.is_known())
        .map(|(cell, _)| {
            (
                (cell.x as f64 * c + cell.y as f64 * s) as f32,
                g.index(cell),
            )
        })
        .collect();
    if proj.len() < 100 {
        return None;
    }
    proj.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    let k = proj.len() as f64;
    let o = spec.overlap.clamp(0.0, 1.0);
    let exclusive = (k * (1.0 - o) / (2.0 - o)) as usize;
    let shared = (k * o / (2.0 - o)) as usize;
    let mut in_a = vec![false; g.len()];
    let mut in_b = vec![false; g.len()];
    for (i, (_, idx)) in proj.iter().enumerate() {
        in_a[*idx] = i < exclusive + shared;
        in_b[*idx] = i >= exclusive;
    }

    // A: the source cropped to its cells, in the source frame.
    let a = crop(source, &in_a);
    // B: its cells seen from a frame turned and shifted in the source frame.
    let yaw = rng.random_range(-PI..PI);
    let shift = spec.max_shift_m;
    let source_from_b = Pose2::new(
        g.origin.x_m + rng.random_range(-shift..=shift),
        g.origin.y_m + rng.random_range(-shift..=shift),
        yaw,
    );
    let b = resample(source, &in_b, &source_from_b);
    let mut a = Map::new(a);
    let mut b = Map::new(b);
    add_noise(&mut a, spec, rng);
    add_noise(&mut b, spec, rng);
    Some(Pair {
        a,
        b,
        a_from_b: source_from_b,
    })
}

/// The cells of `source` marked in `keep`, cropped to their bounding box.
fn crop(source: &Grid<MapCell>, keep: &[bool]) -> Grid<MapCell> {
    let g = *source.geometry();
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (cell, _) in source.iter() {
        if keep[g.index(cell)] {
            (x0, y0) = (x0.min(cell.x), y0.min(cell.y));
            (x1, y1) = (x1.max(cell.x), y1.max(cell.y));
        }
    }
    if x0 > x1 {
        (x0, y0, x1, y1) = (0, 0, 0, 0);
    }
    let geometry = GridGeometry {
        width: x1 + 1 - x0,
        height: y1 + 1 - y0,
        resolution_m: g.resolution_m,
        origin: Point2::new(
            g.origin.x_m + x0 as f64 * g.resolution_m,
            g.origin.y_m + y0 as f64 * g.resolution_m,
        ),
    };
    let mut out = Grid::new(geometry, MapCell::Unknown);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let i = y * g.width + x;
            if keep[i]
                && let Some(c) = out.get_mut(x - x0, y - y0)
            {
                *c = source.cells()[i];
            }
        }
    }
    out
}

/// The cells of `source` marked in `keep`, drawn on an axis-aligned grid in a frame whose
/// pose in the source frame is `source_from_frame` (nearest cell).
fn resample(source: &Grid<MapCell>, keep: &[bool], source_from_frame: &Pose2) -> Grid<MapCell> {
    let g = *source.geometry();
    let frame_from_source = source_from_frame.inverse();
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for (cell, _) in source.iter() {
        if keep[g.index(cell)] {
            let p = frame_from_source.transform_point(g.cell_center(cell));
            (x0, y0) = (x0.min(p.x_m), y0.min(p.y_m));
            (x1, y1) = (x1.max(p.x_m), y1.max(p.y_m));
        }
    }
    let r = g.resolution_m;
    let origin = Point2::new((x0 / r).floor() * r - r, (y0 / r).floor() * r - r);
    let geometry = GridGeometry {
        width: ((x1 - origin.x_m) / r).ceil() as usize + 2,
        height: ((y1 - origin.y_m) / r).ceil() as usize + 2,
        resolution_m: r,
        origin,
    };
    let mut out = Grid::new(geometry, MapCell::Unknown);
    for y in 0..geometry.height {
        for x in 0..geometry.width {
            let p = geometry.cell_center(realms_core::Cell { x, y });
            if let Some(cell) = g.world_to_cell(source_from_frame.transform_point(p)) {
                let i = g.index(cell);
                if keep[i]
                    && let Some(c) = out.get_mut(x, y)
                {
                    *c = source.cells()[i];
                }
            }
        }
    }
    out
}

/// The same map drawn in another frame: `old_from_new` is the pose of the new frame in the
/// map's frame. The answer for the new map is the old map's pose composed with it.
pub fn reframe(map: &Map, old_from_new: &Pose2) -> Map {
    // Resample works in the source grid's frame: carry the map's own frame along.
    let g = *map.geometry();
    let keep = vec![true; g.len()];
    let local = Grid::from_cells(
        GridGeometry {
            origin: Point2::new(0.0, 0.0),
            ..g
        },
        map.cells.cells().to_vec(),
    )
    .unwrap_or_else(|| map.cells.clone());
    let grid_from_new = map.frame_from_grid().inverse().compose(old_from_new);
    Map {
        free_judged_for_hazards: map.free_judged_for_hazards,
        ..Map::new(resample(&local, &keep, &grid_from_new))
    }
}

/// Unknown discs, speckle and missed obstacle cells.
fn add_noise(map: &mut Map, spec: &PairSpec, rng: &mut impl Rng) {
    let g = *map.geometry();
    let r = g.resolution_m;
    let mut blank = map.known_cells() as f64 * spec.unknown_patches;
    let mut tries = 0;
    while blank > 0.0 && tries < 1000 {
        tries += 1;
        let radius_m = rng.random_range(0.3..1.5);
        let cx = rng.random_range(0.0..g.width_m());
        let cy = rng.random_range(0.0..g.height_m());
        let rc = (radius_m / r).ceil() as i64;
        let (ix, iy) = ((cx / r) as i64, (cy / r) as i64);
        for y in iy - rc..=iy + rc {
            for x in ix - rc..=ix + rc {
                if ((x - ix).pow(2) + (y - iy).pow(2)) as f64 > (radius_m / r).powi(2) {
                    continue;
                }
                if x < 0 || y < 0 {
                    continue;
                }
                if let Some(c) = map.cells.get_mut(x as usize, y as usize)
                    && c.is_known()
                {
                    *c = MapCell::Unknown;
                    blank -= 1.0;
                }
            }
        }
    }
    for c in map.cells.cells_mut() {
        match c {
            MapCell::Free if rng.random_bool(spec.speckle) => *c = MapCell::Occupied,
            MapCell::Occupied if rng.random_bool(spec.dropout) => *c = MapCell::Free,
            _ => {}
        }
    }
}

/// Error of an estimated `a_from_b` against the truth: the distance between where each puts
/// `b_point` (a point of the second map, e.g. its centre, in its frame), metres, and the
/// heading difference, radians.
pub fn pose_error(estimate: &Pose2, truth: &Pose2, b_point: Point2) -> (f64, f64) {
    let d = estimate
        .transform_point(b_point)
        .distance_m(truth.transform_point(b_point));
    let yaw = realms_core::geometry::normalize_angle_rad(estimate.yaw_rad - truth.yaw_rad);
    (d, yaw.abs())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn the_answer_maps_b_onto_the_source() {
        let g = GridGeometry {
            width: 80,
            height: 50,
            resolution_m: 0.1,
            origin: Point2::new(-2.0, 1.0),
        };
        let mut src = Grid::new(g, MapCell::Free);
        for x in 0..80 {
            *src.get_mut(x, 10).expect("in") = MapCell::Occupied;
        }
        let spec = PairSpec {
            speckle: 0.0,
            dropout: 0.0,
            unknown_patches: 0.0,
            ..PairSpec::default()
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let pair = make_pair(&src, &spec, &mut rng).expect("a pair");
        // Every obstacle of B, carried by the answer, lies on the source's wall.
        let mut n = 0;
        for (cell, v) in pair.b.cells.iter() {
            if *v == MapCell::Occupied {
                let p = pair.b.geometry().cell_center(cell);
                let q = pair.a_from_b.transform_point(p);
                assert!((q.y_m - (1.0 + 1.05)).abs() < 0.1, "{q:?}");
                n += 1;
            }
        }
        assert!(n > 10);
        // Each map holds about the same number of known cells, sharing 20 % of them.
        let (ka, kb) = (pair.a.known_cells() as f64, pair.b.known_cells() as f64);
        let total = 4000.0;
        assert!((ka - total / 1.8).abs() < 40.0, "{ka}");
        assert!((kb - ka).abs() < 0.05 * ka, "{kb} vs {ka}");
    }
}
