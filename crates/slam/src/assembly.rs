//! The whole map assembled from submaps, kept current incrementally.
//!
//! Drawing every submap at its optimised pose from scratch costs seconds once a map holds a
//! few hundred submaps, far too much for a rover that wants its map every few seconds to
//! plan on. Log-odds add, so the assembly keeps the sum of the finished submaps (which no
//! longer change) and only redraws one when the pose graph has moved it, by taking it out at
//! its old pose and putting it in at the new one; submaps still being built are drawn onto a
//! copy when the map is asked for. Sums are kept unclamped so taking a submap out is exact.

use crate::occupancy::{CellState, OccupancyGrid, growth, regrow};
use realms_core::{Grid, GridGeometry, Point2, Pose2};

/// A submap is redrawn when its pose moved more than this, metres ...
const REDRAW_SHIFT_M: f64 = 0.02;
/// ... or turned more than this (2 cm at 10 m), radians.
const REDRAW_TURN_RAD: f64 = 0.002;
/// Cells added on each side when the assembly grows.
const GROW_MARGIN_CELLS: usize = 64;

/// Log-odds evidence summed over submaps on one growable grid.
#[derive(Clone, Debug)]
pub struct Assembly {
    resolution_m: f64,
    origin: Point2,
    width: usize,
    height: usize,
    sum: Vec<f32>,
    /// Where each submap (by index) was drawn into `sum`, if it was.
    placed: Vec<Option<Pose2>>,
    /// What a submap cell's log-odds contribute to the sum.
    weigh: fn(f32) -> f32,
}

impl Assembly {
    /// An empty assembly of `resolution_m` cells.
    pub fn new(resolution_m: f64) -> Self {
        Assembly::weighing(resolution_m, |l| l)
    }

    /// An empty assembly whose submaps contribute `weigh(log_odds)` per cell instead of
    /// their log-odds (a vote, say; see [`hazard_vote`]).
    pub fn weighing(resolution_m: f64, weigh: fn(f32) -> f32) -> Self {
        Assembly {
            resolution_m,
            origin: Point2::new(0.0, 0.0),
            width: 0,
            height: 0,
            sum: Vec::new(),
            placed: Vec::new(),
            weigh,
        }
    }

    /// Cell edge, metres.
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    fn geometry(&self) -> GridGeometry {
        GridGeometry {
            width: self.width,
            height: self.height,
            resolution_m: self.resolution_m,
            origin: self.origin,
        }
    }

    /// Grows the grid so the world box `[min, max]` lies inside it.
    fn ensure(&mut self, min: Point2, max: Point2) {
        let r = self.resolution_m;
        if self.width == 0 {
            self.origin = Point2::new(
                (min.x_m / r).floor() * r - GROW_MARGIN_CELLS as f64 * r,
                (min.y_m / r).floor() * r - GROW_MARGIN_CELLS as f64 * r,
            );
        }
        let (w, h) = (self.width, self.height);
        let Some(g) = growth(self.origin, r, w, h, min, max, GROW_MARGIN_CELLS) else {
            return;
        };
        self.sum = regrow(&self.sum, w, h, g, 0.0);
        self.origin = Point2::new(
            self.origin.x_m - g[0] as f64 * r,
            self.origin.y_m - g[1] as f64 * r,
        );
        self.width = w + g[0] + g[2];
        self.height = h + g[1] + g[3];
    }

    /// Adds `sign` times the log-odds of `grid` placed at `pose` to `target` (a sum over this
    /// assembly's geometry), sampling the submap at each target cell's centre.
    fn draw(&self, target: &mut [f32], grid: &OccupancyGrid, pose: Pose2, sign: f32) {
        let Some((min, max)) = placed_box(grid, pose) else {
            return;
        };
        let r = self.resolution_m;
        let cell = |v: f64, o: f64| ((v - o) / r).floor();
        let x0 = cell(min.x_m, self.origin.x_m).max(0.0) as usize;
        let y0 = cell(min.y_m, self.origin.y_m).max(0.0) as usize;
        let x1 = (cell(max.x_m, self.origin.x_m) as usize).min(self.width.saturating_sub(1));
        let y1 = (cell(max.y_m, self.origin.y_m) as usize).min(self.height.saturating_sub(1));
        let g = grid.geometry();
        let src = grid.log_odds();
        let inv = pose.inverse();
        let (c, s) = (inv.yaw_rad.cos(), inv.yaw_rad.sin());
        // Stepping one target cell along x moves the sample by (c, s) * r in the submap.
        let (dx, dy) = (c * r / g.resolution_m, s * r / g.resolution_m);
        for y in y0..=y1 {
            let row0 = Point2::new(
                self.origin.x_m + (x0 as f64 + 0.5) * r,
                self.origin.y_m + (y as f64 + 0.5) * r,
            );
            let p = inv.transform_point(row0);
            let (mut lx, mut ly) = (
                (p.x_m - g.origin.x_m) / g.resolution_m,
                (p.y_m - g.origin.y_m) / g.resolution_m,
            );
            for x in x0..=x1 {
                if lx >= 0.0 && ly >= 0.0 && lx < g.width as f64 && ly < g.height as f64 {
                    let v = src[ly as usize * g.width + lx as usize];
                    if v != 0.0 {
                        target[y * self.width + x] += sign * (self.weigh)(v);
                    }
                }
                lx += dx;
                ly += dy;
            }
        }
    }

    fn grow_for(&mut self, grid: &OccupancyGrid, pose: Pose2) {
        if let Some((min, max)) = placed_box(grid, pose) {
            self.ensure(min, max);
        }
    }

    /// Makes the sum hold finished submap `index` (`grid`, unchanging from now on) at `pose`,
    /// redrawing it only if it moved.
    pub fn place(&mut self, index: usize, grid: &OccupancyGrid, pose: Pose2) {
        if self.placed.len() <= index {
            self.placed.resize(index + 1, None);
        }
        if let Some(old) = self.placed[index] {
            let d = pose.relative_to(&old);
            if d.x_m.hypot(d.y_m) <= REDRAW_SHIFT_M && d.yaw_rad.abs() <= REDRAW_TURN_RAD {
                return;
            }
            self.remove(index, grid);
        }
        self.grow_for(grid, pose);
        let mut sum = std::mem::take(&mut self.sum);
        self.draw(&mut sum, grid, pose, 1.0);
        self.sum = sum;
        self.placed[index] = Some(pose);
    }

    /// Takes submap `index` (whose grid must be what was placed) out of the sum.
    pub fn remove(&mut self, index: usize, grid: &OccupancyGrid) {
        let Some(Some(old)) = self.placed.get(index).copied() else {
            return;
        };
        let mut sum = std::mem::take(&mut self.sum);
        self.draw(&mut sum, grid, old, -1.0);
        self.sum = sum;
        self.placed[index] = None;
    }

    /// The assembled log-odds: the finished submaps' sum with the `active` submaps (still
    /// changing) drawn on top.
    pub fn render(&mut self, active: &[(&OccupancyGrid, Pose2)]) -> OccupancyGrid {
        for (grid, pose) in active {
            self.grow_for(grid, *pose);
        }
        if self.width == 0 {
            return OccupancyGrid::new(self.resolution_m);
        }
        let mut sum = self.sum.clone();
        for (grid, pose) in active {
            self.draw(&mut sum, grid, *pose, 1.0);
        }
        OccupancyGrid::from_log_odds(self.geometry(), sum).expect("one value per cell")
    }

    /// The cell states of [`render`](Self::render) without computing probabilities.
    pub fn states(&mut self, active: &[(&OccupancyGrid, Pose2)]) -> Grid<CellState> {
        for (grid, pose) in active {
            self.grow_for(grid, *pose);
        }
        if self.width == 0 {
            // Nothing drawn yet: one unknown cell.
            self.ensure(Point2::new(0.0, 0.0), Point2::new(0.0, 0.0));
        }
        let mut sum = self.sum.clone();
        for (grid, pose) in active {
            self.draw(&mut sum, grid, *pose, 1.0);
        }
        let cells = sum.iter().map(|&l| CellState::from_log_odds(l)).collect();
        Grid::from_cells(self.geometry(), cells).expect("one state per cell")
    }
}

/// Safety first, for hazard layers: a layer that holds a cell hazardous outvotes any number
/// of layers that hold it safe (a low rock seen from afar and judged flat must not hide the
/// rock seen close by later), and a cell is safe only when some layer says so and none
/// says hazard. Undecided cells do not vote.
pub fn hazard_vote(l: f32) -> f32 {
    if l > 0.5 {
        1000.0
    } else if l < -0.5 {
        -1.0
    } else {
        0.0
    }
}

/// The world box holding what `grid` has seen, once placed at `pose`.
fn placed_box(grid: &OccupancyGrid, pose: Pose2) -> Option<(Point2, Point2)> {
    let (lo, hi) = grid.content_bounds()?;
    let corners = [
        lo,
        Point2::new(hi.x_m, lo.y_m),
        hi,
        Point2::new(lo.x_m, hi.y_m),
    ]
    .map(|c| pose.transform_point(c));
    let min = corners.iter().fold(corners[0], |m, c| {
        Point2::new(m.x_m.min(c.x_m), m.y_m.min(c.y_m))
    });
    let max = corners.iter().fold(corners[0], |m, c| {
        Point2::new(m.x_m.max(c.x_m), m.y_m.max(c.y_m))
    });
    Some((min, max))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small room seen from `sensor` (its walls 2 m out), in the submap frame.
    fn room(sensor: Point2) -> OccupancyGrid {
        let mut g = OccupancyGrid::new(0.05);
        let ends: Vec<(Point2, bool)> = (0..360)
            .map(|k| {
                let a = (k as f64).to_radians();
                let r = 2.0 / a.cos().abs().max(a.sin().abs());
                (
                    Point2::new(sensor.x_m + r * a.cos(), sensor.y_m + r * a.sin()),
                    true,
                )
            })
            .collect();
        g.insert(sensor, &ends);
        g
    }

    /// What drawing every submap from scratch gives.
    fn fresh(parts: &[(&OccupancyGrid, Pose2)]) -> Grid<CellState> {
        let mut a = Assembly::new(0.05);
        for (i, (g, p)) in parts.iter().enumerate() {
            a.place(i, g, *p);
        }
        a.states(&[])
    }

    #[test]
    fn moving_and_removing_submaps_equals_drawing_afresh() {
        let a = room(Point2::new(0.0, 0.0));
        let b = room(Point2::new(1.0, 0.5));
        let c = room(Point2::new(-0.5, 1.0));
        let mut asm = Assembly::new(0.05);
        asm.place(0, &a, Pose2::new(0.0, 0.0, 0.0));
        asm.place(1, &b, Pose2::new(3.0, 0.0, 0.3));
        asm.place(2, &c, Pose2::new(-4.0, 2.0, -1.0));
        // The graph moves submap 1 a little (below the redraw threshold) and then a lot,
        // and submap 2 is trimmed.
        asm.place(1, &b, Pose2::new(3.01, 0.0, 0.3));
        asm.place(1, &b, Pose2::new(3.5, -0.4, 0.5));
        asm.remove(2, &c);
        let got = asm.states(&[]);
        let want = fresh(&[
            (&a, Pose2::new(0.0, 0.0, 0.0)),
            (&b, Pose2::new(3.5, -0.4, 0.5)),
        ]);
        // Same content; the incremental grid may be larger (it grew for submap 2).
        let known = |g: &Grid<CellState>| -> Vec<(i64, i64, CellState)> {
            let geo = *g.geometry();
            g.iter()
                .filter(|(_, s)| **s != CellState::Unknown)
                .map(|(cell, s)| {
                    let p = geo.cell_center(cell);
                    (
                        (p.x_m / 0.05).floor() as i64,
                        (p.y_m / 0.05).floor() as i64,
                        *s,
                    )
                })
                .collect()
        };
        let (mut g, mut w) = (known(&got), known(&want));
        g.sort_by_key(|(x, y, _)| (*y, *x));
        w.sort_by_key(|(x, y, _)| (*y, *x));
        assert!(w.len() > 1000, "the rooms were drawn: {}", w.len());
        assert_eq!(g, w);
    }

    #[test]
    fn an_active_submap_is_drawn_on_top_without_entering_the_sum() {
        let a = room(Point2::new(0.0, 0.0));
        let mut asm = Assembly::new(0.05);
        let with = asm.states(&[(&a, Pose2::new(1.0, 1.0, 0.2))]);
        assert!(with.iter().any(|(_, s)| *s == CellState::Occupied));
        let without = asm.states(&[]);
        assert!(without.iter().all(|(_, s)| *s == CellState::Unknown));
    }
}
