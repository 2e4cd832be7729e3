//! Hand-built hazard layers for the tests of the passes that read them ([`crate::craters`],
//! [`crate::hollows`]).

use crate::occupancy::CellState;
use realms_core::{Cell, Grid, GridGeometry, Point2};

/// A 10 m square of 10 cm cells, all unseen.
pub fn layer() -> Grid<CellState> {
    Grid::new(
        GridGeometry {
            width: 100,
            height: 100,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        },
        CellState::Unknown,
    )
}

/// Sets every cell whose centre `inside` holds to `state`.
pub fn set(g: &mut Grid<CellState>, state: CellState, inside: impl Fn(Point2) -> bool) {
    let geo = *g.geometry();
    for (i, c) in g.cells_mut().iter_mut().enumerate() {
        if inside(geo.cell_center(Cell {
            x: i % geo.width,
            y: i / geo.width,
        })) {
            *c = state;
        }
    }
}

/// The state of the cell under (`x_m`, `y_m`), which must lie on the layer.
pub fn state_at(g: &Grid<CellState>, x_m: f64, y_m: f64) -> CellState {
    *g.at_world(Point2::new(x_m, y_m))
        .expect("a point on the layer")
}
