//! Long straight walls, fitted to a fraction of a degree, and whether two maps' walls pin a
//! pose's heading.
//!
//! Two maps that overlap in a band across a hall share only short pieces of the walls the
//! band crosses, and perhaps a crater or a few rocks in between. Turned a few degrees about
//! the crater, such a pose keeps nearly all its agreement: the wall pieces at the band's
//! ends slide along themselves. Yet each map holds long stretches of the hall's walls
//! outside the overlap, and their directions are known to a tenth of a degree. Where a long
//! wall of one map lies parallel to a long wall of the other at the pose, a turn of a degree
//! or more would break that, so the walls pin the heading even where the overlap cannot.
//! This is the line-direction half of Carpin's spectral merging ("Fast and accurate map
//! merging for multi-robot systems", Autonomous Robots 25, 2008), taken from fitted walls
//! rather than a histogram so that it is precise enough to judge a turn of a degree.
//!
//! The walls are runs of surface points ([`Level::surfaces`], landmarks left out) connected
//! within two cells whose normals agree, fitted by total least squares, kept when long and
//! straight. On the lunar pairs of `realms bench merge` the walls of the two maps lie
//! parallel within 0.03 degrees at the true pose, where the estimate's heading is off by up
//! to a degree.

use crate::level::{Level, Surface};
use std::f64::consts::PI;

/// A straight run of structure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    /// Direction along the wall, radians in `[0, pi)`, in the grid-local frame.
    pub direction_rad: f64,
    /// Length between its end points, metres.
    pub length_m: f64,
    /// Spread of its points about the fitted line, metres (RMS).
    pub rms_m: f64,
    /// How many surface points it was fitted to.
    pub points: usize,
}

/// Neighbours within this many cells (Chebyshev) join a run: a missed cell or two does not
/// cut a wall.
const JOIN_CELLS: i64 = 2;
/// Neighbours join a run when their normals differ by at most this much: a corner's two
/// walls stay apart.
const JOIN_NORMAL_RAD: f64 = 30.0 * PI / 180.0;
/// A run is refitted without the points farther than this (cells) from its first fit: a
/// rock against a wall does not tilt it.
const INLIER_CELLS: f64 = 1.5;
/// A run is straight when its points spread at most this much (cells, RMS) about the line:
/// a staircased straight line spreads about 0.3 cells, a crater's rim arc far more.
const MAX_RMS_CELLS: f64 = 0.5;

/// The walls of `level` at least `min_length_m` long, longest first.
pub fn long_walls(level: &Level, min_length_m: f64) -> Vec<Wall> {
    if level.width == 0 || level.height == 0 {
        return Vec::new();
    }
    let points: Vec<Surface> = level
        .surfaces(usize::MAX)
        .into_iter()
        .filter(|s| !s.landmark)
        .collect();
    let (w, h) = (level.width as i64, level.height as i64);
    let cell_of = |s: &Surface| {
        let (x, y) = level.cell_under(s.p);
        (x.clamp(0, w - 1), y.clamp(0, h - 1))
    };
    let mut index = vec![u32::MAX; level.width * level.height];
    for (k, s) in points.iter().enumerate() {
        let (x, y) = cell_of(s);
        index[(y * w + x) as usize] = k as u32;
    }
    let mut seen = vec![false; points.len()];
    let mut walls = Vec::new();
    let mut run = Vec::new();
    let mut stack = Vec::new();
    for start in 0..points.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        run.clear();
        stack.push(start);
        while let Some(k) = stack.pop() {
            run.push(points[k].p);
            let (x, y) = cell_of(&points[k]);
            for dy in -JOIN_CELLS..=JOIN_CELLS {
                for dx in -JOIN_CELLS..=JOIN_CELLS {
                    let (nx, ny) = (x + dx, y + dy);
                    if !(0..w).contains(&nx) || !(0..h).contains(&ny) {
                        continue;
                    }
                    let j = index[(ny * w + nx) as usize];
                    if j == u32::MAX || seen[j as usize] {
                        continue;
                    }
                    let normal = points[j as usize].normal_rad;
                    if angle_between(points[k].normal_rad, normal) <= JOIN_NORMAL_RAD
                        && angle_between(points[start].normal_rad, normal) <= JOIN_NORMAL_RAD
                    {
                        seen[j as usize] = true;
                        stack.push(j as usize);
                    }
                }
            }
        }
        if let Some(wall) = fit(&run, level.cell_m)
            && wall.length_m >= min_length_m
        {
            walls.push(wall);
        }
    }
    walls.sort_by(|a, b| b.length_m.total_cmp(&a.length_m));
    walls
}

/// The straight line through `run` (total least squares, refitted on the points near the
/// first fit), or `None` if too few points or not straight.
fn fit(run: &[realms_core::Point2], cell_m: f64) -> Option<Wall> {
    let first = line_through(run.iter())?;
    let near = |p: &&realms_core::Point2| first.offset_m(**p).abs() <= INLIER_CELLS * cell_m;
    let line = line_through(run.iter().filter(near))?;
    let points = run.iter().filter(near).count();
    if line.rms_m > MAX_RMS_CELLS * cell_m {
        return None;
    }
    // `rem_euclid` of a tiny negative angle rounds to pi itself, outside `[0, pi)`.
    let direction_rad = line.direction_rad.rem_euclid(PI);
    Some(Wall {
        direction_rad: if direction_rad < PI {
            direction_rad
        } else {
            0.0
        },
        length_m: line.length_m,
        rms_m: line.rms_m,
        points,
    })
}

/// A fitted line: its centre, direction, extent along it and spread across it.
struct Line {
    cx: f64,
    cy: f64,
    direction_rad: f64,
    length_m: f64,
    rms_m: f64,
}

impl Line {
    /// Signed distance of `p` from the line.
    fn offset_m(&self, p: realms_core::Point2) -> f64 {
        let (s, c) = self.direction_rad.sin_cos();
        -(p.x_m - self.cx) * s + (p.y_m - self.cy) * c
    }
}

/// Total least squares through `points`: the main axis of their spread.
fn line_through<'a>(points: impl Iterator<Item = &'a realms_core::Point2> + Clone) -> Option<Line> {
    let fit = realms_core::geometry::LineFit::through(points.clone(), 3)?;
    let (mut lo, mut hi, mut across) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for p in points {
        let (along, off) = fit.along_across(*p);
        lo = f64::min(lo, along);
        hi = f64::max(hi, along);
        across += off * off;
    }
    Some(Line {
        cx: fit.centre.x_m,
        cy: fit.centre.y_m,
        direction_rad: fit.direction_rad,
        length_m: hi - lo,
        rms_m: (across / fit.points as f64).sqrt(),
    })
}

/// The absolute difference of two angles, in `[0, pi]`.
fn angle_between(a: f64, b: f64) -> f64 {
    ((a - b + PI).rem_euclid(2.0 * PI) - PI).abs()
}

/// The turn that lays the walls of `b` parallel to those of `a` from heading `yaw_rad` (of
/// `b`'s grid-local frame in `a`'s), if one of at most `max_rad` does: radians, signed,
/// averaged over every pair of walls it lays parallel, each weighted by the product of its
/// walls' lengths (the longer walls' directions are the surer).
pub fn turn_to_parallel_rad(a: &[Wall], b: &[Wall], yaw_rad: f64, max_rad: f64) -> Option<f64> {
    let offsets = || {
        a.iter().flat_map(move |wa| {
            b.iter().map(move |wb| {
                let d = (wa.direction_rad - wb.direction_rad - yaw_rad + PI / 2.0).rem_euclid(PI)
                    - PI / 2.0;
                (d, wa.length_m * wb.length_m)
            })
        })
    };
    let (mut sum, mut weight) = (0.0, 0.0);
    for (d, w) in offsets() {
        if d.abs() <= max_rad {
            sum += d * w;
            weight += w;
        }
    }
    (weight > 0.0).then(|| sum / weight)
}

/// How far apart two directions of lines are (each taken modulo pi), radians in `[0, pi/2]`.
pub fn directions_apart_rad(a_rad: f64, b_rad: f64) -> f64 {
    let d = (a_rad - b_rad).rem_euclid(PI);
    d.min(PI - d)
}

/// How far heading `yaw_rad` (of `b`'s grid-local frame in `a`'s) is from laying some wall
/// of `b` parallel to some wall of `a`: the least difference of direction over every pair,
/// radians in `[0, pi/2]`; `None` if either map has no wall.
pub fn parallel_offset_rad(a: &[Wall], b: &[Wall], yaw_rad: f64) -> Option<f64> {
    a.iter()
        .flat_map(|wa| {
            b.iter()
                .map(move |wb| directions_apart_rad(wb.direction_rad + yaw_rad, wa.direction_rad))
        })
        .min_by(f64::total_cmp)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Map, MapCell};
    use realms_core::{Grid, GridGeometry, Point2, Pose2};

    /// A 20 m x 12 m room with walls 10 cm thick, drawn on 5 cm cells from a frame turned
    /// `yaw_deg` from the room's, with a crater's rim (a hazard ring 3 m across) inside.
    fn turned_room(yaw_deg: f64) -> Map {
        let g = GridGeometry {
            width: 600,
            height: 600,
            resolution_m: 0.05,
            origin: Point2::new(-15.0, -15.0),
        };
        let room_from_grid = Pose2::new(0.0, 0.0, yaw_deg.to_radians());
        let mut grid = Grid::new(g, MapCell::Unknown);
        for y in 0..g.height {
            for x in 0..g.width {
                let p = room_from_grid.transform_point(g.cell_center(realms_core::Cell { x, y }));
                let (ax, ay) = (p.x_m.abs(), p.y_m.abs());
                let cell = if ax > 10.1 || ay > 6.1 {
                    continue;
                } else if ax > 10.0 || ay > 6.0 {
                    MapCell::Occupied
                } else if ((p.x_m - 4.0).hypot(p.y_m - 1.0) - 1.5).abs() < 0.1 {
                    MapCell::Hazard
                } else {
                    MapCell::Free
                };
                *grid.get_mut(x, y).expect("in the grid") = cell;
            }
        }
        Map::new(grid)
    }

    #[test]
    fn a_turned_room_s_walls_are_found_to_a_fraction_of_a_degree_and_a_rim_is_none() {
        let yaw_deg = 17.3;
        let level = Level::build(&turned_room(yaw_deg), 0.1);
        let walls = long_walls(&level, 6.0);
        // The four walls, the long ones first; the rim is no wall.
        assert_eq!(walls.len(), 4, "{walls:?}");
        assert!(
            walls[0].length_m > 19.0 && walls[1].length_m > 19.0,
            "{walls:?}"
        );
        assert!(
            walls[2].length_m > 11.0 && walls[2].length_m < 12.5,
            "{walls:?}"
        );
        // Seen from the grid, the room's x axis lies at -yaw.
        for w in &walls {
            let along = (w.direction_rad.to_degrees() + yaw_deg).rem_euclid(90.0);
            let off = along.min(90.0 - along);
            assert!(off < 0.05, "{w:?}: {off} degrees off the room's axes");
            assert!(w.rms_m < 0.05, "{w:?}");
        }
        // Two such rooms: the turn that lays one's walls on the other's is the difference
        // of their headings, from either side of it.
        let other = long_walls(&Level::build(&turned_room(-40.0), 0.1), 6.0);
        let truth = (yaw_deg + 40.0).to_radians();
        for start_deg in [-1.2, 0.7] {
            let yaw = truth + f64::to_radians(start_deg);
            let turn = turn_to_parallel_rad(&other, &walls, yaw, 1.5f64.to_radians())
                .expect("walls within 1.5 degrees of parallel");
            assert!(
                (yaw + turn - truth).abs() < 0.05f64.to_radians(),
                "from {start_deg} degrees off, turned to {} degrees off",
                (yaw + turn - truth).to_degrees()
            );
            let offset = parallel_offset_rad(&other, &walls, yaw).expect("walls");
            assert!(
                (offset.to_degrees() - start_deg.abs()).abs() < 0.05,
                "{offset}"
            );
        }
        // Three degrees off, nothing lies within 1.5 degrees of parallel.
        assert!(turn_to_parallel_rad(&other, &walls, truth + 0.05, 1.5f64.to_radians()).is_none());
    }

    #[test]
    fn directions_are_compared_across_the_half_turn() {
        let wall = |deg: f64| Wall {
            direction_rad: f64::to_radians(deg),
            length_m: 10.0,
            rms_m: 0.01,
            points: 100,
        };
        // 179.9 degrees and 0.1 degrees are 0.2 degrees apart, not 179.8.
        let turn = turn_to_parallel_rad(&[wall(179.9)], &[wall(0.1)], 0.0, 0.01)
            .expect("within 0.57 degrees");
        assert!(
            (turn.to_degrees() + 0.2).abs() < 1e-9,
            "{}",
            turn.to_degrees()
        );
        let offset = parallel_offset_rad(&[wall(179.9)], &[wall(0.1)], 0.0).expect("walls");
        assert!((offset.to_degrees() - 0.2).abs() < 1e-9);
        // No walls, no answer.
        assert!(parallel_offset_rad(&[], &[wall(0.1)], 0.0).is_none());
    }
}
