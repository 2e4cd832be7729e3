//! Pictures of the world for people: a hill-shaded map of the terrain with obstacles, craters,
//! the lander and targets, onto which the mission draws trajectories.

use crate::terrain::{SurfaceKind, Terrain};
use crate::truth::{GroundTruth, TruthCell};
use realms_core::{Cell, Grid};

/// An RGB raster the size of the terrain grid.
pub type Rgb = Grid<[u8; 3]>;

/// The terrain hill-shaded from the north-west, craters and hazards tinted red, obstacles dark,
/// the lander blue and targets yellow.
pub fn truth_image(terrain: &Terrain, truth: &GroundTruth) -> Rgb {
    let g = *terrain.geometry();
    let mut img = Grid::new(g, [0u8; 3]);
    let (lx, ly, lz) = (-0.5f64, 0.5f64, 0.707f64);
    for y in 0..g.height {
        for x in 0..g.width {
            let n = terrain.surface_normal(x, y);
            let shade = (n[0] * lx + n[1] * ly + n[2] * lz).clamp(0.0, 1.0);
            let base = 70.0 + 150.0 * shade;
            let i = g.index(Cell { x, y });
            let rgb = match (terrain.kind.cells()[i], truth.traversability.cells()[i]) {
                (SurfaceKind::Lander, _) => [60, 90, 200],
                (SurfaceKind::Wall, _) => [40, 40, 40],
                (SurfaceKind::Target, _) => [240, 210, 40],
                (_, TruthCell::Obstacle) => {
                    [(base * 0.45) as u8, (base * 0.4) as u8, (base * 0.35) as u8]
                }
                (_, TruthCell::Hazard) => [
                    (base * 0.9 + 25.0).min(255.0) as u8,
                    (base * 0.55) as u8,
                    (base * 0.5) as u8,
                ],
                _ => [base as u8, base as u8, (base * 0.95) as u8],
            };
            img.cells_mut()[i] = rgb;
        }
    }
    img
}

/// Draws a polyline of world points in a colour, `width_px` cells thick.
pub fn draw_path(img: &mut Rgb, points: &[realms_core::Point2], color: [u8; 3], width_px: usize) {
    let g = *img.geometry();
    let step = g.resolution_m / 2.0;
    let mut plot = |p: realms_core::Point2| {
        if let Some(c) = g.world_to_cell(p) {
            let r = width_px / 2;
            for y in c.y.saturating_sub(r)..=(c.y + r).min(g.height - 1) {
                for x in c.x.saturating_sub(r)..=(c.x + r).min(g.width - 1) {
                    if let Some(v) = img.get_mut(x, y) {
                        *v = color;
                    }
                }
            }
        }
    };
    for w in points.windows(2) {
        let d = w[0].distance_m(w[1]);
        let n = (d / step).ceil().max(1.0) as usize;
        for k in 0..=n {
            let s = k as f64 / n as f64;
            plot(realms_core::Point2::new(
                w[0].x_m + s * (w[1].x_m - w[0].x_m),
                w[0].y_m + s * (w[1].y_m - w[0].y_m),
            ));
        }
    }
    if let [only] = points {
        plot(*only);
    }
}
