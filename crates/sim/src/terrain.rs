//! The arena's terrain: a heightfield generated from the scenario and its seed.
//!
//! Heights are absolute (metres above the mean floor). Alongside the surface it keeps the
//! `floor` (undulation and craters, without rocks, walls or the lander: what the wheels would
//! rest on), a `kind` layer saying what each cell is, soil looseness (for slip), and the list
//! of placed features so ground truth and tests can reason about them exactly.

use crate::rng::{Purpose, SimRng, Streams};
use crate::scenario::Scenario;
use rand::Rng;
use realms_core::{Grid, GridGeometry, Point2, Pose2};
use serde::Serialize;
use std::f64::consts::PI;

/// What occupies a cell.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[repr(u8)]
pub enum SurfaceKind {
    /// Bare regolith floor (including crater bowls).
    Floor = 0,
    /// A boulder.
    Rock = 1,
    /// The arena wall.
    Wall = 2,
    /// The lander.
    Lander = 3,
    /// A resource target (a bright patch on the floor).
    Target = 4,
}

/// A crater: a parabolic bowl with a raised rim and r^-3 ejecta falloff outside it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Crater {
    /// Centre.
    pub center: Point2,
    /// Rim radius, metres.
    pub radius_m: f64,
    /// Depth of the centre below the surrounding floor, metres.
    pub depth_m: f64,
    /// Rim height above the surrounding floor, metres.
    pub rim_m: f64,
}

impl Crater {
    /// Height offset this crater adds at a distance `r_m` from its centre.
    pub fn profile_m(&self, r_m: f64) -> f64 {
        let s = r_m / self.radius_m;
        if s <= 1.0 {
            -self.depth_m + (self.depth_m + self.rim_m) * s * s
        } else if s < 4.0 {
            let taper = 1.0 - ((s - 1.0) / 3.0).powi(2);
            self.rim_m / (s * s * s) * taper
        } else {
            0.0
        }
    }

    /// Steepest slope of the bowl (at the rim, inside), as rise over run.
    pub fn max_inner_slope(&self) -> f64 {
        2.0 * (self.depth_m + self.rim_m) / self.radius_m
    }
}

/// A boulder: a half-buried ellipsoid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Boulder {
    /// Centre.
    pub center: Point2,
    /// Footprint radius, metres.
    pub radius_m: f64,
    /// Height above the floor, metres.
    pub height_m: f64,
}

impl Boulder {
    /// Height this boulder adds at a distance `r_m` from its centre.
    pub fn profile_m(&self, r_m: f64) -> f64 {
        let s = r_m / self.radius_m;
        if s < 1.0 {
            self.height_m * (1.0 - s * s).sqrt()
        } else {
            0.0
        }
    }
}

/// An axis-aligned rectangle, metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Rect {
    /// Lower-left corner.
    pub min: Point2,
    /// Upper-right corner.
    pub max: Point2,
}

impl Rect {
    /// Whether a point is inside.
    pub fn contains(&self, p: Point2) -> bool {
        p.x_m >= self.min.x_m
            && p.x_m < self.max.x_m
            && p.y_m >= self.min.y_m
            && p.y_m < self.max.y_m
    }
}

/// The generated arena.
#[derive(Clone, Debug)]
pub struct Terrain {
    /// Surface height, metres.
    pub heights: Grid<f32>,
    /// Floor height without rocks, walls or lander, metres.
    pub floor: Grid<f32>,
    /// What each cell is.
    pub kind: Grid<SurfaceKind>,
    /// Soil looseness, 0 (firm) to 1 (loosest).
    pub looseness: Grid<f32>,
    /// Placed craters.
    pub craters: Vec<Crater>,
    /// Placed boulders.
    pub boulders: Vec<Boulder>,
    /// Lander footprint.
    pub lander: Rect,
    /// Resource targets.
    pub targets: Vec<Point2>,
    /// Where each rover starts, in arena coordinates (rover 1 first).
    pub rover_starts: Vec<Pose2>,
}

/// A sum of plane waves, normalised to a peak amplitude: smooth, seeded, cheap to evaluate.
struct Waves {
    waves: Vec<(f64, f64, f64, f64)>, // (kx, ky, phase, weight)
    scale: f64,
}

impl Waves {
    fn new(rng: &mut SimRng, count: usize, min_wavelength_m: f64) -> Self {
        let waves = (0..count)
            .map(|_| {
                let wavelength = min_wavelength_m * rng.random_range(1.0..4.0);
                let dir = rng.random_range(0.0..2.0 * PI);
                let k = 2.0 * PI / wavelength;
                (
                    k * dir.cos(),
                    k * dir.sin(),
                    rng.random_range(0.0..2.0 * PI),
                    // Longer waves carry more amplitude, as in natural terrain.
                    wavelength / min_wavelength_m,
                )
            })
            .collect();
        Waves { waves, scale: 1.0 }
    }

    fn raw(&self, p: Point2) -> f64 {
        self.waves
            .iter()
            .map(|(kx, ky, ph, w)| w * (kx * p.x_m + ky * p.y_m + ph).sin())
            .sum::<f64>()
            * self.scale
    }
}

impl Terrain {
    /// Generates the arena of a scenario. Same scenario, same terrain, bit for bit.
    pub fn generate(scenario: &Scenario) -> Terrain {
        let mut rng = Streams::new(scenario.seed).rng(Purpose::Terrain);
        let a = &scenario.arena;
        let geometry = GridGeometry {
            width: (a.width_m / a.resolution_m).round() as usize,
            height: (a.length_m / a.resolution_m).round() as usize,
            resolution_m: a.resolution_m,
            origin: Point2::new(0.0, 0.0),
        };
        let center = Point2::new(a.width_m / 2.0, a.length_m / 2.0);

        let l = &scenario.lander;
        let half = l.size_m / 2.0;
        let lander = Rect {
            min: Point2::new(l.x_m - half, l.y_m - half),
            max: Point2::new(l.x_m + half, l.y_m + half),
        };
        let rover_starts = start_poses(scenario, center);

        // Keep-out discs: the lander and the start line stay clear of craters and rocks.
        let mut keep_out: Vec<(Point2, f64)> = vec![(Point2::new(l.x_m, l.y_m), half * 1.5 + 1.0)];
        keep_out.extend(rover_starts.iter().map(|p| (p.position(), 1.5)));
        let margin = a.wall_thickness_m + 0.5;
        let clear_of = |p: Point2, r: f64, keep: &[(Point2, f64)]| {
            p.x_m - r > margin
                && p.y_m - r > margin
                && p.x_m + r < a.width_m - margin
                && p.y_m + r < a.length_m - margin
                && keep.iter().all(|(c, kr)| p.distance_m(*c) > r + kr)
        };

        let c = &scenario.craters;
        let mut craters = Vec::new();
        let crater_specs = std::iter::repeat_n(
            (c.large_diameter_m, c.large_depth_m),
            c.large_count as usize,
        )
        .chain(std::iter::repeat_n(
            (c.small_diameter_m, c.small_depth_m),
            c.small_count as usize,
        ));
        until_full(crater_specs, |(diameter, depth)| {
            let radius = diameter / 2.0;
            for _ in 0..2000 {
                let p = Point2::new(
                    rng.random_range(0.0..a.width_m),
                    rng.random_range(0.0..a.length_m),
                );
                if clear_of(p, radius * 1.3, &keep_out) {
                    craters.push(Crater {
                        center: p,
                        radius_m: radius,
                        depth_m: depth,
                        rim_m: depth * c.rim_fraction,
                    });
                    keep_out.push((p, radius * 1.3));
                    return true;
                }
            }
            false
        });

        let b = &scenario.boulders;
        let mut boulders = Vec::new();
        // A boulder of `diameter` somewhere clear of `keep`, if one of 200 draws finds a spot.
        let mut place_boulder = |rng: &mut SimRng, diameter: f64, keep: &[(Point2, f64)]| {
            for _ in 0..200 {
                let p = Point2::new(
                    rng.random_range(0.0..a.width_m),
                    rng.random_range(0.0..a.length_m),
                );
                let r = diameter / 2.0;
                if clear_of(p, r, keep) {
                    let height = diameter * b.height_ratio * rng.random_range(0.8..1.2);
                    boulders.push(Boulder {
                        center: p,
                        radius_m: r,
                        height_m: height,
                    });
                    return Some((p, r));
                }
            }
            None
        };
        // A blocking boulder keeps the others (and the targets) 0.6 m off its edge.
        until_full(0..b.large_count, |_| {
            let d = rng.random_range(b.large_min_diameter_m..=b.large_max_diameter_m);
            let placed = place_boulder(&mut rng, d, &keep_out);
            if let Some((p, r)) = placed {
                keep_out.push((p, r + 0.6));
            }
            placed.is_some()
        });
        // Truncated power law by inverse CDF: N(>D) ~ D^-b between the two diameters.
        let (lo, hi) = (
            b.small_min_diameter_m.powf(-b.size_exponent),
            b.small_max_diameter_m.powf(-b.size_exponent),
        );
        until_full(0..b.small_count, |_| {
            let u: f64 = rng.random_range(0.0..1.0);
            let d = (lo - u * (lo - hi)).powf(-1.0 / b.size_exponent);
            place_boulder(&mut rng, d, &keep_out).is_some()
        });

        let mut targets = Vec::new();
        let rocks_near = RocksNear::new(&boulders, TARGET_ROCK_CLEARANCE_M, a.width_m, a.length_m);
        until_full(0..scenario.targets.count, |_| {
            for _ in 0..2000 {
                let p = Point2::new(
                    rng.random_range(0.0..a.width_m),
                    rng.random_range(0.0..a.length_m),
                );
                let clear_of_rocks = || {
                    rocks_near.at(p).iter().all(|k| {
                        let bo = &boulders[*k as usize];
                        bo.center.distance_m(p) > bo.radius_m + TARGET_ROCK_CLEARANCE_M
                    })
                };
                if clear_of(p, 0.5, &keep_out) && clear_of_rocks() {
                    targets.push(p);
                    keep_out.push((p, 1.0));
                    return true;
                }
            }
            false
        });

        let mut undulation = Waves::new(&mut rng, 8, a.undulation_wavelength_m);
        let mut loose = Waves::new(&mut rng, 5, a.undulation_wavelength_m * 2.0);
        normalise_peak(&mut undulation, &geometry, a.undulation_m);
        normalise_peak(&mut loose, &geometry, 1.0);

        let mut floor = Grid::new(geometry, 0.0f32);
        let mut looseness = Grid::new(geometry, 0.0f32);
        for y in 0..geometry.height {
            for x in 0..geometry.width {
                let p = geometry.cell_center(realms_core::Cell { x, y });
                let i = geometry.index(realms_core::Cell { x, y });
                floor.cells_mut()[i] = undulation.raw(p) as f32;
                looseness.cells_mut()[i] = (0.5 + 0.5 * loose.raw(p)) as f32;
            }
        }
        for cr in &craters {
            // Crater floors and rims collect loose, fine regolith.
            stamp(&geometry, cr.center, cr.radius_m * 1.2, |i, _| {
                let l = &mut looseness.cells_mut()[i];
                *l = (*l + 0.4).min(1.0);
            });
        }
        let mut terrain = Terrain {
            heights: floor.clone(),
            floor,
            kind: Grid::new(geometry, SurfaceKind::Floor),
            looseness,
            craters: Vec::new(),
            boulders: Vec::new(),
            lander,
            targets,
            rover_starts,
        };
        for cr in craters {
            terrain.add_crater(cr);
        }
        for bo in boulders {
            terrain.add_boulder(bo);
        }
        // Targets, walls and the lander go on top of the stamped terrain.
        let Terrain {
            heights,
            floor,
            kind,
            targets,
            ..
        } = &mut terrain;
        for t in targets {
            stamp(&geometry, *t, 0.15, |i, _| {
                kind.cells_mut()[i] = SurfaceKind::Target
            });
        }
        for y in 0..geometry.height {
            for x in 0..geometry.width {
                let cell = realms_core::Cell { x, y };
                let p = geometry.cell_center(cell);
                let i = geometry.index(cell);
                let in_wall = p.x_m < a.wall_thickness_m
                    || p.y_m < a.wall_thickness_m
                    || p.x_m > a.width_m - a.wall_thickness_m
                    || p.y_m > a.length_m - a.wall_thickness_m;
                if in_wall {
                    heights.cells_mut()[i] = floor.cells()[i] + a.wall_height_m as f32;
                    kind.cells_mut()[i] = SurfaceKind::Wall;
                } else if lander.contains(p) {
                    heights.cells_mut()[i] = floor.cells()[i] + l.height_m as f32;
                    kind.cells_mut()[i] = SurfaceKind::Lander;
                }
            }
        }

        terrain
    }

    /// A flat, firm floor at height 0 with nothing on it: the start of hand-built test worlds.
    pub fn flat(width_m: f64, length_m: f64, resolution_m: f64) -> Terrain {
        let geometry = GridGeometry {
            width: (width_m / resolution_m).round() as usize,
            height: (length_m / resolution_m).round() as usize,
            resolution_m,
            origin: Point2::new(0.0, 0.0),
        };
        Terrain {
            heights: Grid::new(geometry, 0.0),
            floor: Grid::new(geometry, 0.0),
            kind: Grid::new(geometry, SurfaceKind::Floor),
            looseness: Grid::new(geometry, 0.0),
            craters: Vec::new(),
            boulders: Vec::new(),
            lander: Rect {
                min: Point2::new(-1.0, -1.0),
                max: Point2::new(-1.0, -1.0),
            },
            targets: Vec::new(),
            rover_starts: Vec::new(),
        }
    }

    /// Adds a crater to the floor (and the surface).
    pub fn add_crater(&mut self, crater: Crater) {
        let g = *self.geometry();
        stamp(&g, crater.center, crater.radius_m * 4.0, |i, r| {
            let dz = crater.profile_m(r) as f32;
            self.floor.cells_mut()[i] += dz;
            self.heights.cells_mut()[i] += dz;
        });
        self.craters.push(crater);
    }

    /// Adds a boulder on the floor.
    pub fn add_boulder(&mut self, boulder: Boulder) {
        let g = *self.geometry();
        stamp(&g, boulder.center, boulder.radius_m, |i, r| {
            let top = self.floor.cells()[i] + boulder.profile_m(r) as f32;
            let h = &mut self.heights.cells_mut()[i];
            *h = h.max(top);
            if boulder.profile_m(r) > 0.01 {
                self.kind.cells_mut()[i] = SurfaceKind::Rock;
            }
        });
        self.boulders.push(boulder);
    }

    /// Walls `thickness_m` thick and `height_m` tall along the four edges.
    pub fn add_perimeter_walls(&mut self, thickness_m: f64, height_m: f64) {
        let g = *self.geometry();
        let (w, l) = (g.width_m(), g.height_m());
        for (min, max) in [
            ((0.0, 0.0), (w, thickness_m)),
            ((0.0, l - thickness_m), (w, l)),
            ((0.0, 0.0), (thickness_m, l)),
            ((w - thickness_m, 0.0), (w, l)),
        ] {
            let rect = Rect {
                min: Point2::new(g.origin.x_m + min.0, g.origin.y_m + min.1),
                max: Point2::new(g.origin.x_m + max.0, g.origin.y_m + max.1),
            };
            self.add_wall(rect, height_m);
        }
    }

    /// Raises every cell whose centre is inside `rect` to `height_m` above the floor, as wall.
    pub fn add_wall(&mut self, rect: Rect, height_m: f64) {
        let g = *self.geometry();
        for y in 0..g.height {
            for x in 0..g.width {
                let cell = realms_core::Cell { x, y };
                if rect.contains(g.cell_center(cell)) {
                    let i = g.index(cell);
                    self.heights.cells_mut()[i] = self.floor.cells()[i] + height_m as f32;
                    self.kind.cells_mut()[i] = SurfaceKind::Wall;
                }
            }
        }
    }

    /// Unit surface normal of cell `(x, y)`, from central differences of the surface heights
    /// (clamped at the grid's edge).
    pub fn surface_normal(&self, x: usize, y: usize) -> [f64; 3] {
        let g = self.geometry();
        let h = self.heights.cells();
        let at = |x: usize, y: usize| h[y.min(g.height - 1) * g.width + x.min(g.width - 1)] as f64;
        let gx = (at(x + 1, y) - at(x.saturating_sub(1), y)) / (2.0 * g.resolution_m);
        let gy = (at(x, y + 1) - at(x, y.saturating_sub(1))) / (2.0 * g.resolution_m);
        let n = (gx * gx + gy * gy + 1.0).sqrt();
        [-gx / n, -gy / n, 1.0 / n]
    }

    /// The heightfield's geometry.
    pub fn geometry(&self) -> &GridGeometry {
        self.heights.geometry()
    }

    /// Surface height at a world point (bilinear between cell centres), or `None` outside.
    pub fn height_at(&self, p: Point2) -> Option<f64> {
        bilinear(&self.heights, p)
    }

    /// Floor height (no rocks) at a world point, or `None` outside.
    pub fn floor_at(&self, p: Point2) -> Option<f64> {
        bilinear(&self.floor, p)
    }
}

/// Bilinear interpolation between cell centres, clamped at the border.
pub fn bilinear(grid: &Grid<f32>, p: Point2) -> Option<f64> {
    let c = grid.cells();
    bilinear_with(grid.geometry(), p, |i| c[i])
}

/// [`bilinear`] over the values `value(index)` gives the cells of a grid of geometry `g`.
pub fn bilinear_with(g: &GridGeometry, p: Point2, value: impl Fn(usize) -> f32) -> Option<f64> {
    g.world_to_cell(p)?;
    let fx = ((p.x_m - g.origin.x_m) / g.resolution_m - 0.5).clamp(0.0, (g.width - 1) as f64);
    let fy = ((p.y_m - g.origin.y_m) / g.resolution_m - 0.5).clamp(0.0, (g.height - 1) as f64);
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(g.width - 1), (y0 + 1).min(g.height - 1));
    let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
    let v = |x: usize, y: usize| value(y * g.width + x) as f64;
    Some(
        (v(x0, y0) * (1.0 - tx) + v(x1, y0) * tx) * (1.0 - ty)
            + (v(x0, y1) * (1.0 - tx) + v(x1, y1) * tx) * ty,
    )
}

/// How far a target stays from every rock's edge, metres.
const TARGET_ROCK_CLEARANCE_M: f64 = 0.5;

/// The boulders within a reach of each square cell of the arena (by index), so that asking
/// whether a spot is clear of them looks at a few rocks, not at every one: a scenario may
/// scatter a hundred thousand.
struct RocksNear {
    cell_m: f64,
    columns: usize,
    rows: usize,
    lists: Vec<Vec<u32>>,
}

impl RocksNear {
    /// Each boulder listed in every cell within `reach_m` of its edge.
    fn new(boulders: &[Boulder], reach_m: f64, width_m: f64, length_m: f64) -> Self {
        // Cells of a metre or more, at most about a million of them.
        let cell_m = (width_m * length_m / 1e6).sqrt().max(1.0);
        let columns = (width_m / cell_m).ceil() as usize + 1;
        let rows = (length_m / cell_m).ceil() as usize + 1;
        let mut near = RocksNear {
            cell_m,
            columns,
            rows,
            lists: vec![Vec::new(); columns * rows],
        };
        for (k, b) in boulders.iter().enumerate() {
            let r = b.radius_m + reach_m;
            let (x0, x1) = (near.column(b.center.x_m - r), near.column(b.center.x_m + r));
            for y in near.row(b.center.y_m - r)..=near.row(b.center.y_m + r) {
                for x in x0..=x1 {
                    near.lists[y * columns + x].push(k as u32);
                }
            }
        }
        near
    }

    /// The boulders that may lie within the reach of `p` (a spot inside the arena).
    fn at(&self, p: Point2) -> &[u32] {
        &self.lists[self.row(p.y_m) * self.columns + self.column(p.x_m)]
    }

    /// The column holding `x_m`, clamped to the grid (which rises monotonically with it,
    /// so a rock's span of cells holds every spot within its reach).
    fn column(&self, x_m: f64) -> usize {
        ((x_m / self.cell_m).floor().max(0.0) as usize).min(self.columns - 1)
    }

    /// The row holding `y_m`, clamped likewise.
    fn row(&self, y_m: f64) -> usize {
        ((y_m / self.cell_m).floor().max(0.0) as usize).min(self.rows - 1)
    }
}

/// Items of one kind (craters, boulders, targets) that found no clear spot one after
/// another. Each such item costs its thousands of draws; after [`FULL_AFTER`] in a row the
/// arena holds no more of that kind, and the rest are not tried, so a scenario asking for
/// far more than fits is generated in seconds rather than hours.
#[derive(Default)]
struct Full {
    failed_in_a_row: u32,
}

/// See [`Full`].
const FULL_AFTER: u32 = 100;

impl Full {
    fn count(&mut self, placed: bool) {
        self.failed_in_a_row = if placed { 0 } else { self.failed_in_a_row + 1 };
    }

    fn is_full(&self) -> bool {
        self.failed_in_a_row >= FULL_AFTER
    }
}

/// Calls `place` (which says whether it found a spot) for each item of one kind, in order,
/// until the arena is [`Full`] of that kind.
fn until_full<T>(items: impl IntoIterator<Item = T>, mut place: impl FnMut(T) -> bool) {
    let mut full = Full::default();
    for item in items {
        if full.is_full() {
            break;
        }
        full.count(place(item));
    }
}

/// Calls `f(index, distance)` for every cell whose centre lies within `radius_m` of `center`.
fn stamp(g: &GridGeometry, center: Point2, radius_m: f64, mut f: impl FnMut(usize, f64)) {
    let res = g.resolution_m;
    let x0 = (((center.x_m - radius_m - g.origin.x_m) / res)
        .floor()
        .max(0.0)) as usize;
    let y0 = (((center.y_m - radius_m - g.origin.y_m) / res)
        .floor()
        .max(0.0)) as usize;
    let x1 = (((center.x_m + radius_m - g.origin.x_m) / res).ceil() as usize).min(g.width);
    let y1 = (((center.y_m + radius_m - g.origin.y_m) / res).ceil() as usize).min(g.height);
    for y in y0..y1 {
        for x in x0..x1 {
            let cell = realms_core::Cell { x, y };
            let r = g.cell_center(cell).distance_m(center);
            if r <= radius_m {
                f(g.index(cell), r);
            }
        }
    }
}

fn normalise_peak(w: &mut Waves, g: &GridGeometry, peak: f64) {
    // Sampling every 8th cell finds the peak of waves several metres long closely enough.
    let mut max = 0.0f64;
    for y in (0..g.height).step_by(8) {
        for x in (0..g.width).step_by(8) {
            max = max.max(w.raw(g.cell_center(realms_core::Cell { x, y })).abs());
        }
    }
    w.scale = if max > 0.0 { peak / max } else { 0.0 };
}

/// Rovers start in a line beside the lander, facing the arena's centre.
fn start_poses(scenario: &Scenario, center: Point2) -> Vec<Pose2> {
    let l = &scenario.lander;
    let (dx, dy) = (center.x_m - l.x_m, center.y_m - l.y_m);
    // Face along the dominant axis towards the centre so the line is parallel to a lander side.
    let (fx, fy) = if dx.abs() > dy.abs() {
        (dx.signum(), 0.0)
    } else {
        (0.0, if dy == 0.0 { 1.0 } else { dy.signum() })
    };
    let yaw = fy.atan2(fx);
    let n = scenario.rovers.count as f64;
    let spacing = scenario.rovers.width_m + 0.8;
    let ahead = l.size_m / 2.0 + 1.2;
    (0..scenario.rovers.count)
        .map(|i| {
            let side = (i as f64 - (n - 1.0) / 2.0) * spacing;
            Pose2::new(
                l.x_m + fx * ahead - fy * side,
                l.y_m + fy * ahead + fx * side,
                yaw,
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_arena_has_what_the_scenario_asks_for() {
        let s = Scenario::default();
        let t = Terrain::generate(&s);
        assert_eq!((t.geometry().width, t.geometry().height), (1000, 720));
        assert_eq!(t.craters.len(), 3);
        assert_eq!(t.targets.len(), 5);
        assert_eq!(t.rover_starts.len(), 3);
        assert!(t.boulders.len() > 500, "{} boulders", t.boulders.len());
        let blocking = t
            .boulders
            .iter()
            .filter(|b| b.height_m > s.rovers.max_step_m)
            .count();
        let small = t.boulders.len() - blocking;
        assert!(
            small > 5 * blocking,
            "{small} drivable vs {blocking} blocking"
        );
        // Crater centres sit below the floor around them by about the configured depth.
        for c in &t.craters {
            let bottom = t.floor_at(c.center).expect("inside");
            let outside = t
                .floor_at(Point2::new(c.center.x_m + c.radius_m * 4.5, c.center.y_m))
                .or_else(|| t.floor_at(Point2::new(c.center.x_m - c.radius_m * 4.5, c.center.y_m)))
                .expect("inside");
            let depth = outside - bottom;
            assert!(
                (depth - c.depth_m).abs() < 0.15,
                "depth {depth} vs {}",
                c.depth_m
            );
        }
    }

    #[test]
    fn same_seed_same_terrain_other_seed_other_terrain() {
        let s = Scenario::default();
        let a = Terrain::generate(&s);
        let b = Terrain::generate(&s);
        assert_eq!(a.heights, b.heights);
        let c = Terrain::generate(&Scenario { seed: 2, ..s });
        assert_ne!(a.heights, c.heights);
    }

    #[test]
    fn the_rocks_listed_near_a_spot_hold_every_rock_within_reach_of_it() {
        use rand::{Rng, SeedableRng};
        let mut rng = SimRng::seed_from_u64(7);
        let (width_m, length_m, reach_m) = (30.0, 20.0, 0.5);
        let boulders: Vec<Boulder> = (0..2000)
            .map(|_| Boulder {
                center: Point2::new(
                    rng.random_range(0.0..width_m),
                    rng.random_range(0.0..length_m),
                ),
                radius_m: rng.random_range(0.02..1.0),
                height_m: 0.1,
            })
            .collect();
        let near = RocksNear::new(&boulders, reach_m, width_m, length_m);
        let mut listed = 0;
        for _ in 0..2000 {
            let p = Point2::new(
                rng.random_range(0.0..width_m),
                rng.random_range(0.0..length_m),
            );
            let at = near.at(p);
            listed += at.len();
            for (k, b) in boulders.iter().enumerate() {
                if b.center.distance_m(p) <= b.radius_m + reach_m {
                    assert!(at.contains(&(k as u32)), "rock {k} missing near {p:?}");
                }
            }
        }
        // A few of the 2,000 rocks a spot, not all of them.
        assert!(listed < 2000 * 100, "{listed} listed");
    }

    #[test]
    fn a_kind_is_full_after_a_hundred_misses_in_a_row_and_not_before() {
        let mut full = Full::default();
        for _ in 0..FULL_AFTER - 1 {
            full.count(false);
        }
        assert!(!full.is_full());
        // A placement starts the count again.
        full.count(true);
        for _ in 0..FULL_AFTER - 1 {
            full.count(false);
        }
        assert!(!full.is_full());
        full.count(false);
        assert!(full.is_full());
    }

    #[test]
    fn an_arena_asked_for_more_than_it_holds_gets_what_fits() {
        // A 12 m x 10 m arena holds a few dozen targets 1.5 m apart, not a thousand: the
        // generation places those and stops.
        let mut s = Scenario::default();
        s.arena.width_m = 12.0;
        s.arena.length_m = 10.0;
        s.lander.x_m = 6.0;
        s.lander.y_m = 5.0;
        s.lander.size_m = 1.0;
        s.rovers.count = 1;
        s.faults.clear();
        s.targets.count = 1000;
        s.craters.large_count = 0;
        s.craters.small_count = 0;
        s.boulders.small_count = 50;
        s.validate("t.toml").expect("a valid scenario");
        let t = Terrain::generate(&s);
        assert!(
            !t.targets.is_empty() && t.targets.len() < 100,
            "{} targets",
            t.targets.len()
        );
        for (i, a) in t.targets.iter().enumerate() {
            for b in &t.targets[i + 1..] {
                assert!(a.distance_m(*b) > 1.5, "{a:?} and {b:?}");
            }
            for rock in &t.boulders {
                assert!(rock.center.distance_m(*a) > rock.radius_m + TARGET_ROCK_CLEARANCE_M);
            }
        }
    }
}
