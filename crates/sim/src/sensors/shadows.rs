//! Where the sun's shadows fall, worked out once for the whole terrain: for every cell, the
//! height below which a point over it lies in the shadow of the columns between it and the
//! sun (or inside its own column). The sun and the ground never move, so the camera reads
//! each pixel's light from this map instead of casting a shadow ray across the hall for it
//! (a long one under a low sun).
//!
//! The map is swept from the sun's side of the grid, one column (or row, whichever the sun's
//! direction runs along most) at a time: a cell's shadow height is the highest of what the
//! columns its sun ray crosses on the way to the next column stand above the ray, and of that
//! next column's shadow height, interpolated where the ray crosses it, less the rise of the
//! ray in between. This is horizon mapping for a directional light over a heightfield (Max,
//! "Horizon mapping: shadows for bump-mapped surfaces", The Visual Computer 4, 1988; the
//! single-direction sweep of e.g. Timonen and Westerholm, "Scalable height field
//! self-shadowing", Eurographics 2010), on the terrain's columns of 5 cm cells. It is exact
//! to about a cell at a shadow's edge, where interpolation across the sweep softens it; that
//! is finer than a pixel of the rovers' 160 x 120 camera a metre or more away.

use crate::scenario::Sun;
use realms_core::{Grid, GridGeometry, Point2};

/// Per cell, the height (metres) below which a point over it is dark: in the shadow of the
/// columns between it and the sun, or inside its own column ([`SunShadows::lit`]).
#[derive(Clone, Debug)]
pub struct SunShadows {
    sun: Sun,
    /// The column's own top where nothing stands between the cell and the sun, and
    /// `f32::INFINITY` everywhere for a sun at or below the horizon.
    heights: Grid<f32>,
}

impl SunShadows {
    /// The shadows `sun` casts over the columns of `terrain` (surface heights, metres).
    pub fn new(terrain: &Grid<f32>, sun: &Sun) -> Self {
        let g = *terrain.geometry();
        let (se, ce) = sun.elevation_deg.to_radians().sin_cos();
        if se <= 0.0 {
            return SunShadows {
                sun: sun.clone(),
                heights: Grid::new(g, f32::INFINITY),
            };
        }
        let heights = if ce > 1e-9 {
            let (sa, ca) = sun.azimuth_deg.to_radians().sin_cos();
            let mut heights = Grid::new(g, f32::NEG_INFINITY);
            sweep(terrain, [ca, sa], se / ce, &mut heights);
            heights
        } else {
            // Straight overhead, a ray from a column's top meets no other column.
            terrain.clone()
        };
        SunShadows {
            sun: sun.clone(),
            heights,
        }
    }

    /// The sun these are the shadows of.
    pub fn sun(&self) -> &Sun {
        &self.sun
    }

    /// Whether the sun lights the point `p` (world metres), seen from its cell: a point on
    /// the grid above the shadow height there, or off the grid (taken as beyond everything
    /// that could shade it, as a point moved towards the sun off the grid's edge is) under a
    /// sun above the horizon.
    pub fn lit(&self, p: [f64; 3]) -> bool {
        let g = self.heights.geometry();
        match g.world_to_cell(Point2::new(p[0], p[1])) {
            Some(c) => p[2] > self.heights.cells()[g.index(c)] as f64,
            None => self.sun.elevation_deg.to_radians().sin() > 0.0,
        }
    }

    /// The shadow heights, metres (for tests and pictures).
    pub fn heights(&self) -> &Grid<f32> {
        &self.heights
    }
}

/// Fills `shadows` for a sun in the horizontal direction `to_sun` (unit), its ray rising
/// `tan_elevation` metres a metre.
fn sweep(terrain: &Grid<f32>, to_sun: [f64; 2], tan_elevation: f64, shadows: &mut Grid<f32>) {
    let g: GridGeometry = *terrain.geometry();
    let (w, h) = (g.width, g.height);
    if w == 0 || h == 0 {
        return;
    }
    // Sweep along the axis the sun's direction runs along most ("major"), one line of cells
    // across it at a time, starting with the line nearest the sun.
    let x_major = to_sun[0].abs() >= to_sun[1].abs();
    let (major_len, minor_len) = if x_major { (w, h) } else { (h, w) };
    let (u_major, u_minor) = if x_major {
        (to_sun[0], to_sun[1])
    } else {
        (to_sun[1], to_sun[0])
    };
    let index = |major: usize, minor: usize| {
        if x_major {
            minor * w + major
        } else {
            major * w + minor
        }
    };
    // From one line to the next towards the sun, the ray moves a cell along the major axis
    // and `drift` cells across it, rising by `rise_m`.
    let toward: i64 = if u_major > 0.0 { 1 } else { -1 };
    let drift = u_minor / u_major.abs();
    let rise_m = tan_elevation * g.resolution_m / u_major.abs();
    let tops = terrain.cells();
    let cells = shadows.cells_mut();
    let minor_max = minor_len as i64 - 1;
    // The cell row (across the sweep) holding a point `d` cells across from a cell centre.
    let nearest = |minor: usize, d: f64| -> Option<usize> {
        let m = minor as i64 + d.round() as i64;
        (0..=minor_max).contains(&m).then_some(m as usize)
    };
    let half_rise = rise_m / 2.0;
    // Nearest the sun first.
    let lines = (0..major_len).map(|k| if toward > 0 { major_len - 1 - k } else { k });
    // The line nearest the sun has nothing beyond it: its cells are dark only inside their
    // own columns.
    for major in lines {
        let next = major as i64 + toward;
        let has_next = (0..major_len as i64).contains(&next);
        for minor in 0..minor_len {
            let mut shadow = f64::NEG_INFINITY;
            // Within its own column the ray from the centre drifts at most half a cell across
            // (the sweep runs along the sun's main axis), so it leaves over its own cell.
            // What the next line holds is where a point at its cells' centres is dark, their
            // own columns included.
            if has_next {
                let next = next as usize;
                // Over the next line's column, from where it enters it to where it leaves
                // (half a step either side of its centre): the ray is lowest where it enters,
                // half a step on.
                for d in [drift / 2.0, drift, 1.5 * drift] {
                    if let Some(m) = nearest(minor, d) {
                        shadow = shadow.max(tops[index(next, m)] as f64 - half_rise);
                    }
                }
                // Beyond the next line's centre, what shades the ray there, interpolated
                // across at where it crosses, less the rise from here to there.
                let across = minor as f64 + drift;
                // A ray that leaves the grid's side meets nothing more.
                let on_grid = (-0.5..=minor_max as f64 + 0.5).contains(&across);
                let below = across.floor();
                let frac = across - below;
                let at = |m: f64| -> Option<f64> {
                    let m = m as i64;
                    (0..=minor_max)
                        .contains(&m)
                        .then(|| cells[index(next, m as usize)] as f64)
                };
                let beyond = match (at(below), at(below + 1.0)) {
                    (Some(a), Some(b)) => Some(a + frac * (b - a)),
                    (Some(a), None) | (None, Some(a)) => Some(a),
                    (None, None) => None,
                };
                if let Some(beyond) = beyond.filter(|_| on_grid) {
                    shadow = shadow.max(beyond - rise_m);
                }
            }
            // A point below its own column's top is inside it, where no light reaches.
            let top = tops[index(major, minor)] as f64;
            cells[index(major, minor)] = shadow.max(top) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(width: usize, height: usize) -> Grid<f32> {
        Grid::new(
            GridGeometry {
                origin: Point2::new(0.0, 0.0),
                resolution_m: 0.05,
                width,
                height,
            },
            0.0,
        )
    }

    #[test]
    fn a_wall_shades_the_floor_behind_it_as_far_as_its_height_over_the_suns_slope() {
        // A 1 m wall across the grid, 5 cm thick; the sun 20 degrees up in each of the four
        // directions along the axes and two between them.
        for azimuth_deg in [180.0f64, 0.0, 90.0, 270.0, 150.0, 200.0] {
            let mut t = flat(200, 200);
            let g = *t.geometry();
            // A wall across the grid, square to the sun's direction: x = 5 m for a sun along
            // x, y = 5 m for one along y.
            let along_x = f64::to_radians(azimuth_deg).cos().abs() >= 0.7;
            for y in 0..g.height {
                for x in 0..g.width {
                    let wall = if along_x { x == 100 } else { y == 100 };
                    if wall {
                        t.cells_mut()[g.index(realms_core::Cell { x, y })] = 1.0;
                    }
                }
            }
            let sun = Sun {
                elevation_deg: 20.0,
                azimuth_deg,
            };
            let shadows = SunShadows::new(&t, &sun);
            let (sa, ca) = sun.azimuth_deg.to_radians().sin_cos();
            // Behind the wall, away from the sun, along the middle line.
            let away = if along_x { -ca.signum() } else { -sa.signum() };
            // The shadow runs 1 m / tan 20 deg = 2.75 m from the wall, measured along the
            // sun's direction; across an axis the sun crosses slanted it is that times the
            // cosine of the slant.
            let slant = if along_x { ca.abs() } else { sa.abs() };
            let length_m = 1.0 / 20f64.to_radians().tan() * slant;
            let wall_m = 5.025 + away * 0.025;
            // Just over the floor, as the camera asks of a point it sees.
            let floor_at = |d: f64| {
                let c = wall_m + away * d;
                if along_x {
                    [c, 5.0, 1e-3]
                } else {
                    [5.0, c, 1e-3]
                }
            };
            for d in [0.1, 0.5, 1.0, 2.0, length_m - 0.15] {
                assert!(
                    !shadows.lit(floor_at(d)),
                    "{azimuth_deg} deg: {d} m behind lit"
                );
            }
            for d in [length_m + 0.15, length_m + 1.0, 4.5] {
                assert!(
                    shadows.lit(floor_at(d)),
                    "{azimuth_deg} deg: {d} m behind dark"
                );
            }
            // On the sun's side of the wall the floor is lit, and so is the wall's top.
            let front = floor_at(-1.0);
            assert!(
                shadows.lit(front),
                "{azimuth_deg} deg: before the wall dark"
            );
            let top = if along_x {
                [5.025, 5.0, 1.0 + 1e-3]
            } else {
                [5.0, 5.025, 1.0 + 1e-3]
            };
            assert!(shadows.lit(top), "{azimuth_deg} deg: the wall's top dark");
        }
    }

    #[test]
    fn a_sun_overhead_casts_no_shadow_and_one_below_the_horizon_lights_nothing() {
        let mut t = flat(40, 40);
        t.cells_mut()[20 * 40 + 20] = 3.0;
        let overhead = SunShadows::new(
            &t,
            &Sun {
                elevation_deg: 90.0,
                azimuth_deg: 0.0,
            },
        );
        // Each cell dark only inside its own column: the 3 m post at cell (20, 20), 1.0-1.05 m.
        assert_eq!(overhead.heights().cells(), t.cells());
        assert!(overhead.lit([0.5, 0.5, 1e-3]) && !overhead.lit([1.01, 1.01, 2.0]));
        let set = SunShadows::new(
            &t,
            &Sun {
                elevation_deg: -1.0,
                azimuth_deg: 0.0,
            },
        );
        assert!(!set.lit([1.0, 1.0, 10.0]) && !set.lit([-5.0, 1.0, 10.0]));
    }
}
