//! The rover's map layers for the rest of the mission, derived from the live SLAM map and
//! the hazard layer: the published map (at the SLAM map's cell) and the planner's coarser
//! one. A rover publishes its map every two seconds and replans every three; deriving a
//! whole layer each time cost more than the SLAM that feeds it, while between two calls only
//! the tiles around the rover change. So a layer is kept between calls and redrawn only in
//! the tiles where the SLAM map changed state ([`LiveView::changed_since`]) or the hazard
//! layer did.
//!
//! The planner's layer also tells ground the lidar alone saw free from ground the depth
//! camera judged ([`UNJUDGED`]), so exploration goes on until the rover has looked at the
//! ground it will report as safe; the published map keeps the ROS values.

use realms_core::msgs::OccupancyGrid;
use realms_core::{CentreLookup, Grid, GridGeometry};
use realms_nav::frontier::UNJUDGED;
use realms_slam::assembly::{LIVE_TILE_CELLS, LiveView};
use realms_slam::occupancy::CellState;

/// One layer at `factor` times the SLAM map's cell.
#[derive(Clone, Debug)]
pub struct TiledLayer {
    factor: usize,
    /// Whether ground only the lidar saw free is drawn [`UNJUDGED`] rather than free.
    mark_unjudged: bool,
    drawn: Option<Drawn>,
}

/// A layer as last drawn, and what it was drawn from.
#[derive(Clone, Debug)]
struct Drawn {
    version: u64,
    source: GridGeometry,
    hazards: Grid<CellState>,
    grid: Grid<i8>,
}

impl TiledLayer {
    /// A layer at `factor` times the SLAM map's cell; `factor` must divide
    /// [`LIVE_TILE_CELLS`] (it is rounded down to a power of two that does).
    pub fn new(factor: usize) -> Self {
        let mut f = 1;
        while f * 2 <= factor.clamp(1, LIVE_TILE_CELLS) {
            f *= 2;
        }
        TiledLayer {
            factor: f,
            mark_unjudged: false,
            drawn: None,
        }
    }

    /// The same layer, drawing ground only the lidar saw free as [`UNJUDGED`] (the
    /// planner's layer).
    pub fn marking_unjudged(self) -> Self {
        TiledLayer {
            mark_unjudged: true,
            ..self
        }
    }

    /// The cell size as a multiple of the SLAM map's.
    pub fn factor(&self) -> usize {
        self.factor
    }

    /// The layer drawn from `view` and `hazards`, redrawn only where either changed since
    /// the last call: a cell is an obstacle if any of its SLAM cells is, else hazard if the
    /// hazard layer says so at its centre, else free if any SLAM cell (or the depth camera)
    /// saw it free (unjudged, if so marked, where only the lidar did), else unknown.
    pub fn refresh(&mut self, view: &LiveView, hazards: Grid<CellState>) -> &Grid<i8> {
        let f = self.factor;
        let g = view.geometry;
        let geo = GridGeometry {
            width: g.width / f,
            height: g.height / f,
            resolution_m: g.resolution_m * f as f64,
            origin: g.origin,
        };
        let lookup = CentreLookup::new(hazards.geometry(), &geo);
        let (since, before, mut grid) = match self.drawn.take() {
            Some(d) if d.source == g && d.hazards.geometry() == hazards.geometry() => {
                (Some(d.version), Some(d.hazards), d.grid)
            }
            _ => (None, None, Grid::new(geo, OccupancyGrid::UNKNOWN)),
        };
        let t = LIVE_TILE_CELLS;
        for ty in 0..g.height.div_ceil(t) {
            for tx in 0..g.width.div_ceil(t) {
                let fine = [
                    tx * t,
                    ty * t,
                    ((tx + 1) * t).min(g.width),
                    ((ty + 1) * t).min(g.height),
                ];
                let stale = match (since, &before) {
                    (Some(v), Some(old)) => {
                        view.changed_since(tx, ty, v) || hazards_differ(old, &hazards, &g, fine)
                    }
                    _ => true,
                };
                if stale {
                    let source = Source {
                        view,
                        hazards: &hazards,
                        lookup: &lookup,
                        mark_unjudged: self.mark_unjudged,
                    };
                    draw_tile(&mut grid, &source, f, fine);
                }
            }
        }
        let drawn = self.drawn.insert(Drawn {
            version: view.version,
            source: g,
            hazards,
            grid,
        });
        &drawn.grid
    }
}

/// What a layer is drawn from.
struct Source<'a> {
    view: &'a LiveView<'a>,
    hazards: &'a Grid<CellState>,
    /// Where each layer cell's centre lies in `hazards`.
    lookup: &'a CentreLookup,
    mark_unjudged: bool,
}

/// Redraws the layer's cells inside SLAM cells `[x0, x1) x [y0, y1)` (`fine`).
fn draw_tile(grid: &mut Grid<i8>, source: &Source, f: usize, fine: [usize; 4]) {
    let Source {
        view,
        hazards,
        lookup,
        mark_unjudged,
    } = *source;
    let [x0, y0, x1, y1] = fine;
    let geo = *grid.geometry();
    let source_width = view.geometry.width;
    let (cx0, cx1) = (x0 / f, (x1 / f).min(geo.width));
    for cy in y0 / f..(y1 / f).min(geo.height) {
        for cx in cx0..cx1 {
            let (mut occupied, mut free) = (false, false);
            for dy in 0..f {
                let row = (cy * f + dy) * source_width + cx * f;
                for c in &view.states[row..row + f] {
                    occupied |= *c == CellState::Occupied;
                    free |= *c == CellState::Free;
                }
            }
            let hazard = hazard_at(hazards, lookup, cx, cy);
            grid.cells_mut()[cy * geo.width + cx] = match cell_value(occupied, hazard, free) {
                OccupancyGrid::FREE if mark_unjudged && hazard.is_none() => UNJUDGED,
                v => v,
            };
        }
    }
}

/// Whether the hazard cells under SLAM cells `[x0, x1) x [y0, y1)` (`fine`, on `source`)
/// differ between `old` and `new` (which share a geometry).
fn hazards_differ(
    old: &Grid<CellState>,
    new: &Grid<CellState>,
    source: &GridGeometry,
    fine: [usize; 4],
) -> bool {
    let h = new.geometry();
    if h.width == 0 || h.height == 0 {
        return false;
    }
    let [x0, y0, x1, y1] = fine;
    // The hazard cells holding the box's corners, one more on each side for rounding.
    let cell = |v: usize, o_src: f64, o_h: f64, n: usize| -> usize {
        let world = o_src + v as f64 * source.resolution_m;
        (((world - o_h) / h.resolution_m).floor().max(0.0) as usize).min(n - 1)
    };
    let hx0 = cell(x0, source.origin.x_m, h.origin.x_m, h.width).saturating_sub(1);
    let hx1 = (cell(x1, source.origin.x_m, h.origin.x_m, h.width) + 1).min(h.width - 1);
    let hy0 = cell(y0, source.origin.y_m, h.origin.y_m, h.height).saturating_sub(1);
    let hy1 = (cell(y1, source.origin.y_m, h.origin.y_m, h.height) + 1).min(h.height - 1);
    // Each row compared without an early exit: a slice of an enum compares cell by cell
    // with a branch each (no byte-wise comparison for it), where a fold of the differences
    // runs many cells to an instruction. Most tiles are unchanged, so all their cells are
    // read either way.
    (hy0..=hy1).any(|y| {
        let row = y * h.width;
        old.cells()[row + hx0..=row + hx1]
            .iter()
            .zip(&new.cells()[row + hx0..=row + hx1])
            .fold(false, |differ, (a, b)| differ | (*a as u8 != *b as u8))
    })
}

/// A published map cell from what the lidar map and the hazard layer say: the lidar passes
/// over crater bowls and low rocks and calls them free, so the hazard layer overrules it
/// everywhere but on what the lidar sees as obstacles; ground the depth camera judged
/// drivable is known free too.
pub fn cell_value(occupied: bool, hazard: Option<bool>, free: bool) -> i8 {
    match (occupied, hazard, free) {
        (true, _, _) => OccupancyGrid::OCCUPIED,
        (_, Some(true), _) => OccupancyGrid::HAZARD,
        (_, Some(false), _) | (_, None, true) => OccupancyGrid::FREE,
        _ => OccupancyGrid::UNKNOWN,
    }
}

/// What the hazard layer says of the cell holding the centre of layer cell (`x`, `y`) (found
/// through `lookup`): hazardous, safe, or unseen (`None`).
fn hazard_at(hazards: &Grid<CellState>, lookup: &CentreLookup, x: usize, y: usize) -> Option<bool> {
    match lookup.index(x, y).map(|i| &hazards.cells()[i]) {
        Some(CellState::Occupied) => Some(true),
        Some(CellState::Free) => Some(false),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::{Point2, Pose2};
    use realms_slam::assembly::Assembly;
    use realms_slam::occupancy::OccupancyGrid as LogOdds;

    /// 360 beams from `sensor` to the walls of a square room 2 m out.
    fn beams(sensor: Point2) -> Vec<(Point2, bool)> {
        (0..360)
            .map(|k| {
                let a = (k as f64).to_radians();
                let r = 2.0 / a.cos().abs().max(a.sin().abs());
                (
                    Point2::new(sensor.x_m + r * a.cos(), sensor.y_m + r * a.sin()),
                    true,
                )
            })
            .collect()
    }

    /// A hazard layer at 10 cm over `[-3, 6] x [-3, 3]` m with the cells in `hazardous`
    /// (x range, y range, metres) hazardous and the rest safe.
    fn hazards(hazardous: &[([f64; 2], [f64; 2])]) -> Grid<CellState> {
        let geo = GridGeometry {
            width: 90,
            height: 60,
            resolution_m: 0.1,
            origin: Point2::new(-3.0, -3.0),
        };
        let mut g = Grid::new(geo, CellState::Free);
        for y in 0..geo.height {
            for x in 0..geo.width {
                let p = geo.cell_center(realms_core::Cell { x, y });
                let inside = |([x0, x1], [y0, y1]): &([f64; 2], [f64; 2])| {
                    p.x_m >= *x0 && p.x_m <= *x1 && p.y_m >= *y0 && p.y_m <= *y1
                };
                if hazardous.iter().any(inside) {
                    g.cells_mut()[y * geo.width + x] = CellState::Occupied;
                }
            }
        }
        g
    }

    #[test]
    fn the_planners_layer_tells_ground_only_the_lidar_saw_from_judged_ground() {
        let mut asm = Assembly::new(0.05);
        let mut sub = LogOdds::new(0.05);
        let sensor = Point2::new(0.0123, 0.0271);
        let scan = beams(sensor);
        sub.insert(sensor, &scan);
        asm.trace(&[(0, Pose2::IDENTITY)], sensor, &scan);
        let view = asm.live_states(&[(0, &sub, Pose2::IDENTITY)]);
        // The depth camera judged the ground east of x = 0 safe and has not seen the west.
        let mut judged = hazards(&[]);
        let geo = *judged.geometry();
        for (i, c) in judged.cells_mut().iter_mut().enumerate() {
            if geo
                .cell_center(realms_core::Cell {
                    x: i % geo.width,
                    y: i / geo.width,
                })
                .x_m
                < 0.0
            {
                *c = CellState::Unknown;
            }
        }
        let planner = TiledLayer::new(2)
            .marking_unjudged()
            .refresh(&view, judged.clone())
            .clone();
        let published = TiledLayer::new(2).refresh(&view, judged).clone();
        let at = |g: &Grid<i8>, x: f64| *g.at_world(Point2::new(x, 0.55)).expect("inside");
        assert_eq!(at(&planner, -1.05), UNJUDGED);
        assert_eq!(at(&planner, 1.05), OccupancyGrid::FREE);
        // The published map keeps the ROS values: free either way.
        assert_eq!(at(&published, -1.05), OccupancyGrid::FREE);
        assert_eq!(at(&published, 1.05), OccupancyGrid::FREE);
    }

    #[test]
    fn a_layer_redrawn_by_tiles_equals_one_drawn_whole() {
        for factor in [1, 2] {
            let mut asm = Assembly::new(0.05);
            let mut sub = LogOdds::new(0.05);
            let mut layer = TiledLayer::new(factor);
            let mut hazardous = vec![([0.5, 0.9], [0.5, 0.7])];
            let mut sensor = Point2::new(0.0123, 0.0271);
            let mut differences_seen = 0;
            for step in 0..6 {
                let scan = beams(sensor);
                sub.insert(sensor, &scan);
                asm.trace(&[(0, Pose2::IDENTITY)], sensor, &scan);
                if step == 3 {
                    // A crater rim seen late, far from where the scans changed the map.
                    hazardous.push(([-2.5, -2.2], [-2.5, -2.3]));
                }
                let view = asm.live_states(&[(0, &sub, Pose2::IDENTITY)]);
                let before = layer.drawn.as_ref().map(|d| d.grid.clone());
                let got = layer.refresh(&view, hazards(&hazardous)).clone();
                let want = TiledLayer::new(factor)
                    .refresh(&view, hazards(&hazardous))
                    .clone();
                assert_eq!(got.geometry(), want.geometry());
                let differ = (got.cells().iter())
                    .zip(want.cells())
                    .filter(|(a, b)| a != b)
                    .count();
                assert_eq!(differ, 0, "cells differ at factor {factor}, step {step}");
                if let Some(before) = before
                    && before.geometry() == got.geometry()
                {
                    differences_seen += usize::from(before != got);
                }
                sensor = Point2::new(sensor.x_m + 0.4, sensor.y_m + 0.1);
            }
            assert!(differences_seen >= 4, "the layer changed between calls");
            let hazard_cells = layer
                .drawn
                .as_ref()
                .expect("drawn")
                .grid
                .cells()
                .iter()
                .filter(|c| **c == OccupancyGrid::HAZARD)
                .count();
            assert!(hazard_cells > 0, "both hazards were drawn");
        }
    }
}
