//! A map reduced to a coarser cell for matching, and what the matcher reads from it: the
//! structure points (boundaries of obstacles and hazards), the distance from every cell to
//! the nearest structure, and the known cells.
//!
//! Reduction keeps structure: a coarse cell is an obstacle (or hazard) if any fine cell in it
//! is one, once lone obstacle cells (sensor speckle: a real obstacle covers several cells)
//! have been dropped; otherwise it is free if at least half of it is free, else unknown.

use crate::map::{Map, MapCell};
use realms_core::Point2;

/// Coarse cell classes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Class {
    /// Not observed (or too little of it).
    Unknown = 0,
    /// Free.
    Free = 1,
    /// An obstacle.
    Occupied = 2,
    /// A hazard.
    Hazard = 3,
}

impl Class {
    /// Obstacle or hazard.
    pub fn is_feature(self) -> bool {
        matches!(self, Class::Occupied | Class::Hazard)
    }
}

/// Distances are kept in tenths of a cell up to this cap (the matcher never looks further).
pub const DIST_CAP: u16 = 200;

/// One reduced map.
#[derive(Clone, Debug)]
pub struct Level {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Cell edge, metres.
    pub cell_m: f64,
    /// Classes, row-major from the bottom row.
    pub class: Vec<Class>,
    /// Distance to the nearest surface cell (a feature cell with a normal), tenths of a cell
    /// (3-4 chamfer), capped at [`DIST_CAP`].
    pub dist: Vec<u16>,
    /// For feature cells touching free space (8-neighbours): the direction from the cell to
    /// the free space within two cells (the side a sensor saw the surface from), radians;
    /// NaN otherwise.
    pub normal: Vec<f32>,
    /// `normal` as a direction bin, [`NO_BIN`] where there is none.
    pub bin: Vec<u8>,
    /// For feature cells: whether their blob (8-connected feature cells) is a landmark,
    /// compact and not a straight line (see `landmarks`).
    pub landmark: Vec<bool>,
    /// Whether the map's free cells were judged for hazards ([`Map::free_judged_for_hazards`]).
    pub free_judged_for_hazards: bool,
    /// Summed-area table of the known cells, `(width + 1) x (height + 1)`: entry
    /// `(x, y)` counts the known cells below and left of it (see [`Level::known_near`]).
    known_sum: Vec<u32>,
}

/// No normal, in [`Level::bin`].
pub const NO_BIN: u8 = u8::MAX;

/// A structure point: a feature cell's centre and the direction it was seen from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Centre, grid-local metres.
    pub p: Point2,
    /// Direction towards the free side, radians (in the grid-local frame).
    pub normal_rad: f64,
    /// How much the point says about position: [`LINE_WEIGHT`] on straight runs of wall
    /// (a wall matches itself slid along its length), [`SHAPE_WEIGHT`] on corners, rocks
    /// and crater rims.
    pub weight: u8,
    /// Whether the point lies on a landmark ([`Level::landmark`]): a rock, a boulder, a
    /// crater, a piece of furniture, rather than a wall.
    pub landmark: bool,
    /// Whether the point lies on a hazard (seen by a depth camera, not by a lidar).
    pub hazard: bool,
}

/// Weight of a point on a straight run of structure.
pub const LINE_WEIGHT: u8 = 1;
/// Weight of a point on a corner, a rock or a rim.
pub const SHAPE_WEIGHT: u8 = 8;

/// `x.floor() as i64`, without the library call that `floor` is on a baseline x86-64
/// target (no SSE4.1): the matcher floors a few million coordinates per pair.
#[inline]
pub fn floor_i64(x: f64) -> i64 {
    let i = x as i64;
    i - i64::from((i as f64) > x)
}

/// The summed-area table of the known cells of a `w x h` grid of classes (Crow 1984).
fn summed_known(class: &[Class], w: usize, h: usize) -> Vec<u32> {
    let mut sum = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0u32;
        for x in 0..w {
            row += u32::from(class[y * w + x] != Class::Unknown);
            sum[(y + 1) * (w + 1) + x + 1] = sum[y * (w + 1) + x + 1] + row;
        }
    }
    sum
}

/// The shape of the feature cells within `r` cells of `(x, y)` (their structure tensor):
/// how many there are, their coherence `(l1 - l2) / (l1 + l2)` (1 on a straight line, 0 on
/// a round blob) and the direction of their main axis, radians in `[-pi/2, pi/2]`. `None`
/// when there are none or they are all one point.
pub fn local_shape(
    feature: impl Fn(i64, i64) -> bool,
    x: i64,
    y: i64,
    r: i64,
) -> Option<(f64, f64, f64)> {
    let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for dy in -r..=r {
        for dx in -r..=r {
            if feature(x + dx, y + dy) {
                let (fx, fy) = (dx as f64, dy as f64);
                n += 1.0;
                sx += fx;
                sy += fy;
                sxx += fx * fx;
                syy += fy * fy;
                sxy += fx * fy;
            }
        }
    }
    if n == 0.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    let (cxx, cyy, cxy) = (sxx / n - mx * mx, syy / n - my * my, sxy / n - mx * my);
    let tr = cxx + cyy;
    if tr <= 1e-9 {
        return None;
    }
    let coherence = ((cxx - cyy).powi(2) + 4.0 * cxy * cxy).sqrt() / tr;
    Some((n, coherence, 0.5 * (2.0 * cxy).atan2(cxx - cyy)))
}

/// Whether the structure within four cells of `(x, y)` is a straight line: the covariance
/// of the structure cells there is nearly one-dimensional.
fn is_line(class: &[Class], w: usize, h: usize, x: usize, y: usize) -> bool {
    let feature = |fx: i64, fy: i64| {
        (0..w as i64).contains(&fx)
            && (0..h as i64).contains(&fy)
            && class[fy as usize * w + fx as usize].is_feature()
    };
    local_shape(feature, x as i64, y as i64, 4)
        .is_some_and(|(n, coherence, _)| n >= 4.0 && coherence > 0.9)
}

/// A map reduced to cells of some size: their classes and the surface normals, without the
/// distance field and landmarks a [`Level`] adds (all the sub-cell fit reads, at the map's
/// own resolution).
pub struct Outline {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Cell edge, metres.
    pub cell_m: f64,
    /// Classes, row-major from the bottom row.
    pub class: Vec<Class>,
    /// As [`Level::normal`].
    pub normal: Vec<f32>,
}

impl Outline {
    /// Reduces `despeckled` to cells of `cell_m` metres (at least the map's own cell), as
    /// the module documentation says.
    pub fn of(despeckled: &Despeckled, cell_m: f64) -> Outline {
        let (g, fine) = (&despeckled.geometry, &despeckled.cells);
        let r = g.resolution_m;
        let cell_m = cell_m.max(r);
        let width = ((g.width as f64 * r / cell_m).ceil() as usize).max(1);
        let height = ((g.height as f64 * r / cell_m).ceil() as usize).max(1);
        // Fine cell span of each coarse index: [start, end), at least one fine cell.
        let ratio = cell_m / r;
        let spans = |count: usize, n: usize| -> Vec<(usize, usize)> {
            let edge = |i: usize| ((i as f64 * ratio).round() as usize).min(n);
            (0..count)
                .map(|i| (edge(i), edge(i + 1).max(edge(i) + 1).min(n)))
                .collect()
        };
        let (x_spans, y_spans) = (spans(width, g.width), spans(height, g.height));
        let mut class = vec![Class::Unknown; width * height];
        for (cy, &(y0, y1)) in y_spans.iter().enumerate() {
            for (cx, &(x0, x1)) in x_spans.iter().enumerate() {
                let (mut occ, mut haz, mut free, mut total) = (false, false, 0usize, 0usize);
                for y in y0..y1 {
                    for x in x0..x1 {
                        total += 1;
                        match fine[y * g.width + x] {
                            MapCell::Occupied => occ = true,
                            MapCell::Hazard => haz = true,
                            MapCell::Free => free += 1,
                            MapCell::Unknown => {}
                        }
                    }
                }
                class[cy * width + cx] = if occ {
                    Class::Occupied
                } else if haz {
                    Class::Hazard
                } else if total > 0 && 2 * free >= total {
                    Class::Free
                } else {
                    Class::Unknown
                };
            }
        }
        let normal = normals(&class, width, height);
        Outline {
            width,
            height,
            cell_m,
            class,
            normal,
        }
    }
}

impl Level {
    /// Reduces `map` to cells of `cell_m` metres (at least the map's own cell).
    pub fn build(map: &Map, cell_m: f64) -> Level {
        Level::build_from(&Despeckled::of(map), cell_m)
    }

    /// [`Level::build`] from a map already despeckled (once for all of a map's levels).
    pub fn build_from(despeckled: &Despeckled, cell_m: f64) -> Level {
        let Outline {
            width,
            height,
            cell_m,
            class,
            normal,
        } = Outline::of(despeckled, cell_m);
        let dist = chamfer(&normal, width, height);
        let bin = normal
            .iter()
            .map(|n| {
                if n.is_nan() {
                    NO_BIN
                } else {
                    crate::search::direction_bin(*n as f64) as u8
                }
            })
            .collect();
        let landmark = landmarks(&class, width, height, cell_m);
        let known_sum = summed_known(&class, width, height);
        Level {
            width,
            height,
            cell_m,
            class,
            dist,
            normal,
            bin,
            landmark,
            free_judged_for_hazards: despeckled.free_judged_for_hazards,
            known_sum,
        }
    }

    /// Whether any cell within `r` cells of `(x, y)` (a square) is known.
    pub fn known_near(&self, x: i64, y: i64, r: i64) -> bool {
        let (w, h) = (self.width as i64, self.height as i64);
        let (x0, y0) = ((x - r).clamp(0, w), (y - r).clamp(0, h));
        let (x1, y1) = ((x + r + 1).clamp(0, w), (y + r + 1).clamp(0, h));
        if x0 >= x1 || y0 >= y1 {
            return false;
        }
        let at = |x: i64, y: i64| self.known_sum[(y * (w + 1) + x) as usize];
        at(x1, y1) + at(x0, y0) > at(x0, y1) + at(x1, y0)
    }

    /// The class at a cell, `Unknown` outside.
    pub fn class_at(&self, x: i64, y: i64) -> Class {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return Class::Unknown;
        }
        self.class[y as usize * self.width + x as usize]
    }

    /// Distance to the nearest feature in cells, `None` outside the grid.
    pub fn dist_at(&self, x: i64, y: i64) -> Option<f32> {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        Some(self.dist[y as usize * self.width + x as usize] as f32 / 10.0)
    }

    /// Centre of a cell in grid-local metres.
    pub fn center(&self, x: usize, y: usize) -> Point2 {
        Point2::new(
            (x as f64 + 0.5) * self.cell_m,
            (y as f64 + 0.5) * self.cell_m,
        )
    }

    /// Feature cells on the edge of their blob (a 4-neighbour of another class) that face
    /// free space, at most `max_points` of them (evenly thinned, deterministically).
    pub fn surfaces(&self, max_points: usize) -> Vec<Surface> {
        let mut pts = Vec::new();
        for y in 0..self.height {
            for x in 0..self.width {
                let i = y * self.width + x;
                let c = self.class[i];
                if !c.is_feature() || self.normal[i].is_nan() {
                    continue;
                }
                let (xi, yi) = (x as i64, y as i64);
                let edge = [(1, 0), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .any(|(dx, dy)| self.class_at(xi + dx, yi + dy) != c);
                if edge {
                    let line = is_line(&self.class, self.width, self.height, x, y);
                    pts.push(Surface {
                        p: self.center(x, y),
                        normal_rad: self.normal[i] as f64,
                        weight: if line { LINE_WEIGHT } else { SHAPE_WEIGHT },
                        landmark: self.landmark[i],
                        hazard: c == Class::Hazard,
                    });
                }
            }
        }
        thin(pts, max_points)
    }

    /// The cell (possibly outside) holding grid-local point `q`.
    pub fn cell_under(&self, q: Point2) -> (i64, i64) {
        (
            floor_i64(q.x_m / self.cell_m),
            floor_i64(q.y_m / self.cell_m),
        )
    }

    /// Direction bin ([`crate::search::direction_bin`]) of the cell's normal; `None`
    /// outside or where there is none.
    pub fn bin_at(&self, x: i64, y: i64) -> Option<usize> {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        let b = self.bin[y as usize * self.width + x as usize];
        (b != NO_BIN).then_some(b as usize)
    }

    /// Centres of known cells in grid-local metres, at most `max_points` (evenly thinned).
    pub fn known_points(&self, max_points: usize) -> Vec<Point2> {
        let mut pts = Vec::new();
        for y in 0..self.height {
            for x in 0..self.width {
                if self.class[y * self.width + x] != Class::Unknown {
                    pts.push(self.center(x, y));
                }
            }
        }
        thin(pts, max_points)
    }
}

/// Direction from each feature cell to the free cells within two cells (the mean offset),
/// NaN for other cells and for feature cells with no free cell that close.
fn normals(class: &[Class], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![f32::NAN; class.len()];
    for y in 0..h {
        for x in 0..w {
            if !class[y * w + x].is_feature() {
                continue;
            }
            // Only the surface itself: a cell touching free space. (Cells deeper inside a
            // thick wall would let a pose slid into the wall still look agreeing.)
            let touches_free = (y.saturating_sub(1)..(y + 2).min(h)).any(|ny| {
                (x.saturating_sub(1)..(x + 2).min(w)).any(|nx| class[ny * w + nx] == Class::Free)
            });
            if !touches_free {
                continue;
            }
            let (mut vx, mut vy, mut n) = (0i32, 0i32, 0);
            for ny in y.saturating_sub(2)..(y + 3).min(h) {
                for nx in x.saturating_sub(2)..(x + 3).min(w) {
                    if class[ny * w + nx] == Class::Free {
                        vx += nx as i32 - x as i32;
                        vy += ny as i32 - y as i32;
                        n += 1;
                    }
                }
            }
            // Free space all around (a lone post seen from everywhere) has no side.
            if n > 0 && (vx * vx + vy * vy) * 4 >= n * n {
                out[y * w + x] = (vy as f32).atan2(vx as f32);
            }
        }
    }
    out
}

/// Largest side of a landmark's bounding box, metres: rocks, boulders, craters and
/// furniture are smaller; a room's or an arena's walls, connected, are larger.
const LANDMARK_MAX_M: f64 = 8.0;
/// Blobs more coherent than this (structure tensor over the whole blob) are a stretch of
/// wall, whatever their size.
const LANDMARK_MAX_COHERENCE: f64 = 0.8;

/// Marks the feature cells whose blob (8-connected) is a landmark: at most
/// [`LANDMARK_MAX_M`] across and not a straight line. A map that agrees with another only
/// on walls is weak evidence of a pose: the walls of a rectangular room or arena match
/// themselves turned by a quarter turn, in another corner; landmarks do not repeat so.
fn landmarks(class: &[Class], w: usize, h: usize, cell_m: f64) -> Vec<bool> {
    let mut out = vec![false; class.len()];
    let mut seen = vec![false; class.len()];
    let max_cells = (LANDMARK_MAX_M / cell_m).ceil() as usize;
    let mut stack = Vec::new();
    let mut blob = Vec::new();
    for start in 0..class.len() {
        if seen[start] || !class[start].is_feature() {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        blob.clear();
        while let Some(i) = stack.pop() {
            blob.push(i);
            let (x, y) = (i % w, i / w);
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    let j = ny * w + nx;
                    if !seen[j] && class[j].is_feature() {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &i in &blob {
            let (x, y) = (i % w, i / w);
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            let (fx, fy) = (x as f64, y as f64);
            sx += fx;
            sy += fy;
            sxx += fx * fx;
            syy += fy * fy;
            sxy += fx * fy;
        }
        if x1 - x0 + 1 > max_cells || y1 - y0 + 1 > max_cells {
            continue;
        }
        let n = blob.len() as f64;
        let (mx, my) = (sx / n, sy / n);
        let (cxx, cyy, cxy) = (sxx / n - mx * mx, syy / n - my * my, sxy / n - mx * my);
        let tr = cxx + cyy;
        let coherence = if tr > 1e-9 {
            ((cxx - cyy).powi(2) + 4.0 * cxy * cxy).sqrt() / tr
        } else {
            0.0
        };
        if coherence <= LANDMARK_MAX_COHERENCE {
            for &i in &blob {
                out[i] = true;
            }
        }
    }
    out
}

/// Keeps every k-th point so that at most `max_points` remain.
fn thin<T: Copy>(pts: Vec<T>, max_points: usize) -> Vec<T> {
    if pts.len() <= max_points || max_points == 0 {
        return pts;
    }
    let step = pts.len() as f64 / max_points as f64;
    (0..max_points)
        .filter_map(|i| pts.get((i as f64 * step) as usize).copied())
        .collect()
}

/// A map's cells with lone feature cells (no feature among their 8 neighbours) made
/// unknown: speckle is neither evidence of an obstacle nor of free space. So are pockets
/// of free space too small to stand in (`MAX_FREE_POCKET_CELLS`) and walled in all
/// round: missed returns inside a rock, a wall or the lander, which would otherwise line
/// it with surface points facing inwards, different in each map, that drown its true
/// outline when two poses are compared.
pub struct Despeckled {
    geometry: realms_core::GridGeometry,
    cells: Vec<MapCell>,
    free_judged_for_hazards: bool,
}

impl Despeckled {
    /// Despeckles `map`, free pockets included.
    pub fn of(map: &Map) -> Despeckled {
        Despeckled::cleaned(map, true)
    }

    /// Despeckles `map`; its walled-in free pockets (`MAX_FREE_POCKET_CELLS`) are made
    /// unknown only if `free_pockets` is set.
    pub fn cleaned(map: &Map, free_pockets: bool) -> Despeckled {
        let g = map.geometry();
        let (w, h) = (g.width, g.height);
        let src = map.cells.cells();
        let mut out = src.to_vec();
        for y in 0..h {
            for x in 0..w {
                if !src[y * w + x].is_feature() {
                    continue;
                }
                let mut neighbour = false;
                'n: for ny in y.saturating_sub(1)..(y + 2).min(h) {
                    for nx in x.saturating_sub(1)..(x + 2).min(w) {
                        if (nx, ny) != (x, y) && src[ny * w + nx].is_feature() {
                            neighbour = true;
                            break 'n;
                        }
                    }
                }
                if !neighbour {
                    out[y * w + x] = MapCell::Unknown;
                }
            }
        }
        if free_pockets {
            unknown_free_pockets(&mut out, w, h);
        }
        Despeckled {
            geometry: *g,
            cells: out,
            free_judged_for_hazards: map.free_judged_for_hazards,
        }
    }
}

/// Free regions (8-connected) of at most this many cells are speckle, not ground.
const MAX_FREE_POCKET_CELLS: usize = 8;

/// Makes unknown every free region (8-connected) of at most [`MAX_FREE_POCKET_CELLS`]
/// cells in the row-major `cells` of a `w` x `h` grid that is walled in by obstacles and
/// hazards all round (not by unknown ground or the grid's edge).
fn unknown_free_pockets(cells: &mut [MapCell], w: usize, h: usize) {
    // 0: not yet reached; 1: in a region known to be larger; 2: in the region being grown.
    let mut mark = vec![0u8; cells.len()];
    let mut region = Vec::with_capacity(MAX_FREE_POCKET_CELLS + 1);
    for start in 0..cells.len() {
        if mark[start] != 0 || cells[start] != MapCell::Free {
            continue;
        }
        region.clear();
        region.push(start);
        mark[start] = 2;
        let mut large = false;
        let mut next = 0;
        'grow: while next < region.len() {
            let i = region[next];
            next += 1;
            let (x, y) = (i % w, i / w);
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                large = true;
                break;
            }
            for ny in y - 1..y + 2 {
                for nx in x - 1..x + 2 {
                    let j = ny * w + nx;
                    if cells[j] == MapCell::Unknown {
                        // Open to ground nobody saw: perhaps more free space.
                        large = true;
                        break 'grow;
                    }
                    if cells[j] != MapCell::Free || mark[j] == 2 {
                        continue;
                    }
                    // Reaching a region already found large, or growing past the limit.
                    if mark[j] == 1 || region.len() == MAX_FREE_POCKET_CELLS {
                        large = true;
                        break 'grow;
                    }
                    mark[j] = 2;
                    region.push(j);
                }
            }
        }
        for &i in &region {
            mark[i] = 1;
            if !large {
                cells[i] = MapCell::Unknown;
            }
        }
    }
}

/// 3-4 chamfer distance (in tenths of a cell, ~exact to 8 %) from every cell to the nearest
/// surface cell (a feature cell with a normal) (Borgefors 1986, "Distance transformations in
/// digital images"). Surfaces, not all structure: deep inside a crater or a thick wall is
/// far from anything a sensor saw, so a pose cannot gain by sinking points into it.
fn chamfer(normal: &[f32], w: usize, h: usize) -> Vec<u16> {
    let mut d: Vec<u16> = normal
        .iter()
        .map(|n| if n.is_nan() { DIST_CAP } else { 0 })
        .collect();
    // Steps of 10 (straight) and 14 (diagonal) tenths.
    let relax = |d: &mut Vec<u16>, i: usize, j: usize, step: u16| {
        let v = d[j].saturating_add(step);
        if v < d[i] {
            d[i] = v;
        }
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x > 0 {
                relax(&mut d, i, i - 1, 10);
            }
            if y > 0 {
                relax(&mut d, i, i - w, 10);
                if x > 0 {
                    relax(&mut d, i, i - w - 1, 14);
                }
                if x + 1 < w {
                    relax(&mut d, i, i - w + 1, 14);
                }
            }
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            if x + 1 < w {
                relax(&mut d, i, i + 1, 10);
            }
            if y + 1 < h {
                relax(&mut d, i, i + w, 10);
                if x + 1 < w {
                    relax(&mut d, i, i + w + 1, 14);
                }
                if x > 0 {
                    relax(&mut d, i, i + w - 1, 14);
                }
            }
        }
    }
    d.iter_mut().for_each(|v| *v = (*v).min(DIST_CAP));
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::{Grid, GridGeometry};

    fn map_from(rows: &[&str], r: f64) -> Map {
        let h = rows.len();
        let w = rows[0].len();
        let mut cells = Vec::new();
        for row in rows.iter().rev() {
            cells.extend(row.chars().map(|c| match c {
                '#' => MapCell::Occupied,
                'h' => MapCell::Hazard,
                '.' => MapCell::Free,
                _ => MapCell::Unknown,
            }));
        }
        let g = GridGeometry {
            width: w,
            height: h,
            resolution_m: r,
            origin: Point2::new(0.0, 0.0),
        };
        Map::new(Grid::from_cells(g, cells).expect("sizes match"))
    }

    #[test]
    fn reduction_keeps_structure_and_drops_speckle() {
        let map = map_from(
            &[
                "....????", //
                "..#.????", // a lone speck: dropped
                "........", //
                "##......", //
            ],
            0.05,
        );
        let level = Level::build(&map, 0.1);
        assert_eq!((level.width, level.height), (4, 2));
        // Bottom row: the wall pair makes the first coarse cell an obstacle.
        assert_eq!(level.class_at(0, 0), Class::Occupied);
        assert_eq!(level.class_at(1, 0), Class::Free);
        // Top row: the speck is gone, the unknown half stays unknown.
        assert_eq!(level.class_at(1, 1), Class::Free);
        assert_eq!(level.class_at(3, 1), Class::Unknown);
        assert_eq!(level.dist_at(0, 0), Some(0.0));
        assert_eq!(level.dist_at(1, 0), Some(1.0));
        assert_eq!(level.dist_at(1, 1), Some(1.4));
        let s = level.surfaces(100);
        assert_eq!(s.len(), 1);
        // The wall cell's free side is up and to the right.
        assert!(s[0].normal_rad > 0.2 && s[0].normal_rad < 1.4, "{s:?}");
    }

    #[test]
    fn missed_returns_inside_a_block_line_it_with_no_surface() {
        // A block with holes of one and two cells (missed returns, the two touching at a
        // corner) beside open ground, and a pocket of twelve free cells walled in (larger
        // than speckle).
        let map = map_from(
            &[
                "..........#####", //
                ".##########...#", //
                ".#.########...#", //
                ".###..#####...#", //
                ".######.###...#", //
                ".#######.######", //
                "......#########", //
            ],
            0.05,
        );
        let d = Despeckled::of(&map);
        let at = |x: usize, y: usize| d.cells[(6 - y) * 15 + x];
        for (x, y) in [(2, 2), (4, 3), (5, 3), (7, 4), (8, 5)] {
            assert_eq!(at(x, y), MapCell::Unknown, "hole at ({x}, {y})");
        }
        for (x, y) in [(0, 3), (11, 2), (12, 4), (5, 6)] {
            assert_eq!(at(x, y), MapCell::Free, "ground at ({x}, {y})");
        }
        // Asked to keep them (the rovers' maps), the holes stay free.
        let kept = Despeckled::cleaned(&map, false);
        assert_eq!(kept.cells[(6 - 2) * 15 + 2], MapCell::Free);
        assert_eq!(kept.cells[(6 - 3) * 15 + 4], MapCell::Free);
        // Only the block's outer faces are surface now: no cell inside has a normal.
        let o = Outline::of(&d, 0.05);
        let normal = |x: usize, y: usize| o.normal[(6 - y) * 15 + x];
        assert!(normal(3, 3).is_nan() && normal(6, 3).is_nan() && normal(7, 3).is_nan());
        assert!(!normal(1, 3).is_nan() && !normal(10, 2).is_nan());
        // The same map with its pockets kept would have them.
        let raw = Outline::of(&kept, 0.05);
        assert!(!raw.normal[(6 - 3) * 15 + 3].is_nan());
    }

    #[test]
    fn hazard_is_structure_too() {
        let map = map_from(&["hh..", "hh.."], 0.1);
        let level = Level::build(&map, 0.1);
        assert_eq!(level.class_at(0, 0), Class::Hazard);
        // Only the column touching free space is surface.
        let s = level.surfaces(100);
        assert_eq!(s.len(), 2);
        assert!(s.iter().all(|s| s.normal_rad.abs() < 0.8), "{s:?}");
        assert_eq!(level.known_points(2).len(), 2);
    }

    #[test]
    fn rocks_are_landmarks_and_walls_are_not() {
        // A wall along the bottom and up the left side (an L, 10 m and 6 m), a 0.3 m rock
        // and a 0.4 m crater (hazard) on open ground.
        let mut rows = vec![String::new(); 60];
        for (y, row) in rows.iter_mut().enumerate() {
            *row = (0..100)
                .map(|x| {
                    let rock = (30..33).contains(&x) && (20..23).contains(&y);
                    if y == 59 || x == 0 || rock {
                        '#'
                    } else if (60..64).contains(&x) && (40..44).contains(&y) {
                        'h'
                    } else {
                        '.'
                    }
                })
                .collect();
        }
        let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
        let level = Level::build(&map_from(&rows, 0.1), 0.1);
        let at = |x: usize, y: usize| level.landmark[y * level.width + x];
        // Rows are given top first: the rock's rows 20..23 from the top are 37..40 up.
        assert!(at(31, 38), "the rock");
        assert!(at(61, 17), "the crater");
        assert!(!at(50, 0), "the bottom wall");
        assert!(!at(0, 30), "the side wall");
        let s = level.surfaces(10_000);
        assert!(s.iter().any(|p| p.landmark) && s.iter().any(|p| !p.landmark));
    }
}
