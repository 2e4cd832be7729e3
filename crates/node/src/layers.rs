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
use realms_core::{CentreLookup, Grid, GridGeometry, Point2};
use realms_nav::frontier::UNJUDGED;
use realms_slam::assembly::{LIVE_TILE_CELLS, LiveView};
use realms_slam::occupancy::CellState;

/// One layer at `factor` times the SLAM map's cell.
#[derive(Clone, Debug)]
pub struct TiledLayer {
    factor: usize,
    /// Whether ground only the lidar saw free is drawn [`UNJUDGED`] rather than free.
    mark_unjudged: bool,
    /// Whether a cell that would be free is drawn hazard where the hazard layer marks ground
    /// within half a hazard cell of its centre ([`rounding_hazards_out`](Self::rounding_hazards_out)).
    round_hazards_out: bool,
    drawn: Option<Drawn>,
}

/// A layer as last drawn, and what it was drawn from.
#[derive(Clone, Debug)]
struct Drawn {
    version: u64,
    source: GridGeometry,
    hazards: Grid<CellState>,
    /// The hazards' version, if the caller gave one.
    hazards_version: Option<u64>,
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
            round_hazards_out: false,
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

    /// The same layer, its hazards rounded out to the hazard layer's half cell if `round`: a cell that
    /// would be free is hazard where the hazard layer marks ground within half a hazard cell
    /// (per axis) of its centre. The hazard layer judges 10 cm cells, and a cell across a
    /// crater's crest holds mostly the gentle outer slope, so it is judged safe; drawn on
    /// 5 cm cells by their centres alone, the hazard then stops a cell short of the crest on
    /// the crater's inner wall. Rounded out, a 5 cm cell beside a hazardous 10 cm cell takes
    /// its verdict: the edge lies somewhere within that half cell, and a rover must not
    /// take it for open ground. Only for layers finer than the hazard layer: drawn on cells
    /// no finer than the hazard layer's, a layer's hazards are not rounded.
    pub fn rounding_hazards_out(self, round: bool) -> Self {
        TiledLayer {
            round_hazards_out: round,
            ..self
        }
    }

    /// The cell size as a multiple of the SLAM map's.
    pub fn factor(&self) -> usize {
        self.factor
    }

    /// The layer drawn from `view` and `hazards`, redrawn only where either changed since
    /// the last call: a cell is an obstacle if any of its SLAM cells is, else hazard if the
    /// hazard layer says so at its centre (or, rounded out, within half a hazard cell of
    /// it), else free if any SLAM cell (or the depth camera) saw it free (unjudged, if so
    /// marked, where only the lidar did), else unknown.
    pub fn refresh(&mut self, view: &LiveView, hazards: Grid<CellState>) -> &Grid<i8> {
        self.refresh_versioned(view, hazards, None)
    }

    /// [`refresh`](Self::refresh) with the hazard layer's version, if the caller keeps one:
    /// hazards of the version last drawn are taken for the same grid without comparing it
    /// cell by cell.
    pub fn refresh_versioned(
        &mut self,
        view: &LiveView,
        hazards: Grid<CellState>,
        hazards_version: Option<u64>,
    ) -> &Grid<i8> {
        let g = view.geometry;
        // Nothing changed since the last drawing (a rover standing still): it stands.
        if let Some(mut d) = self.drawn.take_if(|d| {
            d.source == g
                && !view.changed_anywhere_since(d.version)
                && match (hazards_version, d.hazards_version) {
                    (Some(now), Some(drawn)) => now == drawn,
                    _ => d.hazards == hazards,
                }
        }) {
            d.version = view.version;
            return &self.drawn.insert(d).grid;
        }
        let f = self.factor;
        let geo = GridGeometry {
            width: g.width / f,
            height: g.height / f,
            resolution_m: g.resolution_m * f as f64,
            origin: g.origin,
        };
        let lookup = CentreLookup::new(hazards.geometry(), &geo);
        // Where points half a hazard cell before and after each cell's centre (on each axis)
        // lie in the hazard layer; on cells no finer than the hazard layer's those points
        // would fall on its cells' edges, and nothing is rounded.
        let finer = hazards.geometry().resolution_m > geo.resolution_m * (1.0 + 1e-9);
        let near = (self.round_hazards_out && finer).then(|| {
            let half = 0.5 * hazards.geometry().resolution_m;
            let shifted = |d: f64| GridGeometry {
                origin: Point2::new(geo.origin.x_m + d, geo.origin.y_m + d),
                ..geo
            };
            [
                CentreLookup::new(hazards.geometry(), &shifted(-half)),
                CentreLookup::new(hazards.geometry(), &shifted(half)),
            ]
        });
        let (since, before, mut grid) = match self.drawn.take() {
            Some(d) if d.source == g && d.hazards.geometry() == hazards.geometry() => {
                // Hazards of the version last drawn are the same cells: no tile's differ.
                let same_version =
                    hazards_version.is_some() && d.hazards_version == hazards_version;
                (
                    Some(d.version),
                    (!same_version).then_some(d.hazards),
                    d.grid,
                )
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
                let stale = match since {
                    Some(v) => {
                        view.changed_since(tx, ty, v)
                            || before
                                .as_ref()
                                .is_some_and(|old| hazards_differ(old, &hazards, &g, fine))
                    }
                    None => true,
                };
                if stale {
                    let source = Source {
                        view,
                        hazards: &hazards,
                        lookup: &lookup,
                        // A tile with no hazard under it or beside it has none to round out.
                        near: near.as_ref().filter(|_| any_hazard(&hazards, &g, fine)),
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
            hazards_version,
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
    /// Where the points half a hazard cell before and after it lie, if hazards are rounded
    /// out.
    near: Option<&'a [CentreLookup; 2]>,
    mark_unjudged: bool,
}

/// Redraws the layer's cells inside SLAM cells `[x0, x1) x [y0, y1)` (`fine`).
fn draw_tile(grid: &mut Grid<i8>, source: &Source, f: usize, fine: [usize; 4]) {
    let Source {
        view,
        hazards,
        lookup,
        near,
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
                OccupancyGrid::FREE
                    if near.is_some_and(|n| hazard_near(hazards, lookup, n, cx, cy)) =>
                {
                    OccupancyGrid::HAZARD
                }
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
    let Some([hx0, hy0, hx1, hy1]) = hazard_box(h, source, fine) else {
        return false;
    };
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

/// Whether any hazard cell under SLAM cells `[x0, x1) x [y0, y1)` (`fine`, on `source`), or
/// a cell beyond, is hazardous.
fn any_hazard(hazards: &Grid<CellState>, source: &GridGeometry, fine: [usize; 4]) -> bool {
    let h = hazards.geometry();
    let Some([hx0, hy0, hx1, hy1]) = hazard_box(h, source, fine) else {
        return false;
    };
    (hy0..=hy1).any(|y| {
        let row = y * h.width;
        hazards.cells()[row + hx0..=row + hx1]
            .iter()
            .fold(false, |any, c| any | (*c == CellState::Occupied))
    })
}

/// The hazard cells `[x0, x1] x [y0, y1]` (inclusive) holding the corners of SLAM cells
/// `[x0, x1) x [y0, y1)` (`fine`, on `source`), one more on each side for rounding (and for
/// a layer's hazards rounded out, which reach half a hazard cell past the box); `None` for
/// an empty hazard layer.
fn hazard_box(h: &GridGeometry, source: &GridGeometry, fine: [usize; 4]) -> Option<[usize; 4]> {
    if h.width == 0 || h.height == 0 {
        return None;
    }
    let [x0, y0, x1, y1] = fine;
    let cell = |v: usize, o_src: f64, o_h: f64, n: usize| -> usize {
        let world = o_src + v as f64 * source.resolution_m;
        (((world - o_h) / h.resolution_m).floor().max(0.0) as usize).min(n - 1)
    };
    Some([
        cell(x0, source.origin.x_m, h.origin.x_m, h.width).saturating_sub(1),
        cell(y0, source.origin.y_m, h.origin.y_m, h.height).saturating_sub(1),
        (cell(x1, source.origin.x_m, h.origin.x_m, h.width) + 1).min(h.width - 1),
        (cell(y1, source.origin.y_m, h.origin.y_m, h.height) + 1).min(h.height - 1),
    ])
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

/// Whether the hazard layer marks a cell holding a point half a hazard cell from the centre
/// of layer cell (`x`, `y`) along either axis or both (`near`: where those points lie).
fn hazard_near(
    hazards: &Grid<CellState>,
    lookup: &CentreLookup,
    near: &[CentreLookup; 2],
    x: usize,
    y: usize,
) -> bool {
    let [before, after] = near;
    let columns = [before.column(x), lookup.column(x), after.column(x)];
    let rows = [before.row(y), lookup.row(y), after.row(y)];
    let width = hazards.geometry().width;
    rows.iter().flatten().any(|row| {
        columns
            .iter()
            .flatten()
            .any(|column| hazards.cells()[row * width + column] == CellState::Occupied)
    })
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
    use realms_core::Pose2;
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

    /// The live map and submap of one scan of the square room from near the origin.
    fn room() -> (Assembly, LogOdds) {
        let mut asm = Assembly::new(0.05);
        let mut sub = LogOdds::new(0.05);
        let sensor = Point2::new(0.0123, 0.0271);
        let scan = beams(sensor);
        sub.insert(sensor, &scan);
        asm.trace(&[(0, Pose2::IDENTITY)], sensor, &scan);
        (asm, sub)
    }

    #[test]
    fn the_planners_layer_tells_ground_only_the_lidar_saw_from_judged_ground() {
        let (mut asm, sub) = room();
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
    fn hazards_rounded_out_reach_half_a_hazard_cell_past_its_edge() {
        let (mut asm, sub) = room();
        let view = asm.live_states(&[(0, &sub, Pose2::IDENTITY)]);
        // 10 cm hazard cells covering x 0.5-0.9, y 0.5-0.7; every other judged safe.
        let hazardous = [([0.5, 0.9], [0.5, 0.7])];
        let plain = TiledLayer::new(1)
            .refresh(&view, hazards(&hazardous))
            .clone();
        let rounded = TiledLayer::new(1)
            .rounding_hazards_out(true)
            .refresh(&view, hazards(&hazardous))
            .clone();
        let at = |g: &Grid<i8>, x: f64, y: f64| {
            let p = Point2::new(x, y);
            let c = g.geometry().world_to_cell(p).expect("inside");
            // The 5 cm cells must line up with the 10 cm ones for the values below.
            let centre = g.geometry().cell_center(c);
            assert!((centre.x_m - x).abs() < 1e-9 && (centre.y_m - y).abs() < 1e-9);
            g.cells()[g.geometry().index(c)]
        };
        let (hazard, free) = (OccupancyGrid::HAZARD, OccupancyGrid::FREE);
        // (x, y) of a 5 cm cell's centre, its value drawn plainly and rounded out.
        for (x, y, plainly, rounded_out) in [
            // Inside the hazard.
            (0.525, 0.575, hazard, hazard),
            (0.875, 0.675, hazard, hazard),
            // The near halves of the 10 cm cells beside it: west, east, south, north, and
            // the corner diagonally south-west.
            (0.475, 0.625, free, hazard),
            (0.925, 0.625, free, hazard),
            (0.725, 0.475, free, hazard),
            (0.725, 0.725, free, hazard),
            (0.475, 0.475, free, hazard),
            // Their far halves, and the next cells out.
            (0.425, 0.625, free, free),
            (0.975, 0.625, free, free),
            (0.725, 0.425, free, free),
            (0.725, 0.775, free, free),
            (0.425, 0.475, free, free),
            (0.475, 0.425, free, free),
        ] {
            assert_eq!(at(&plain, x, y), plainly, "plain at ({x}, {y})");
            assert_eq!(at(&rounded, x, y), rounded_out, "rounded out at ({x}, {y})");
        }
        // Nothing else differs: the rounding adds only the ring of half cells around the
        // hazard, 8 + 8 cells along x, 4 + 4 along y, 4 corners.
        let differ = (plain.cells().iter())
            .zip(rounded.cells())
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differ, 2 * 8 + 2 * 4 + 4);
    }

    #[test]
    fn a_layer_redrawn_by_tiles_equals_one_drawn_whole() {
        for (factor, rounded) in [(1, false), (2, false), (1, true)] {
            let new_layer = || TiledLayer::new(factor).rounding_hazards_out(rounded);
            let mut asm = Assembly::new(0.05);
            let mut sub = LogOdds::new(0.05);
            let mut layer = new_layer();
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
                let want = new_layer().refresh(&view, hazards(&hazardous)).clone();
                assert_eq!(got.geometry(), want.geometry());
                let differ = (got.cells().iter())
                    .zip(want.cells())
                    .filter(|(a, b)| a != b)
                    .count();
                assert_eq!(
                    differ, 0,
                    "cells differ at factor {factor} (rounded out: {rounded}), step {step}"
                );
                if let Some(before) = before
                    && before.geometry() == got.geometry()
                {
                    differences_seen += usize::from(before != got);
                }
                sensor = Point2::new(sensor.x_m + 0.4, sensor.y_m + 0.1);
            }
            // A hazard seen with the map unchanged, ending at a tile's edge on ground the
            // room's scans saw open: only the hazards redraw tiles now, and a rounded ring
            // lies in the next tile, whose own hazard cells stay as they were.
            let view = asm.live_states(&[(0, &sub, Pose2::IDENTITY)]);
            let last = Point2::new(sensor.x_m - 0.4, sensor.y_m - 0.1);
            let tile_m = LIVE_TILE_CELLS as f64 * view.geometry.resolution_m;
            let k = ((last.x_m - view.geometry.origin.x_m) / tile_m).floor();
            let edge = view.geometry.origin.x_m + k * tile_m;
            assert!(edge > last.x_m - 1.7, "the edge lies in the room");
            hazardous.push(([edge - 0.3, edge - 0.01], [last.y_m, last.y_m + 0.3]));
            let got = layer.refresh(&view, hazards(&hazardous)).clone();
            let want = new_layer().refresh(&view, hazards(&hazardous)).clone();
            assert_eq!(
                got, want,
                "a hazard at a tile's edge, factor {factor}, rounded out: {rounded}"
            );
            // The ring's cell across the edge: hazard only when rounded out.
            let across = *want
                .at_world(Point2::new(edge + 0.025, last.y_m + 0.15))
                .expect("inside");
            let ring = if rounded {
                OccupancyGrid::HAZARD
            } else {
                OccupancyGrid::FREE
            };
            assert_eq!(across, ring, "factor {factor}, rounded out: {rounded}");
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
