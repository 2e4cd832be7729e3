//! The costmap the planner and the follower drive on, built from a rover's map (a ROS-style
//! occupancy grid: -1 unknown, 0..=100 occupancy, where the rover's hazard cells count as
//! occupied).
//!
//! Costs follow Nav2's inflation layer: an obstacle cell is [`LETHAL`]; every cell closer to
//! one than the rover's inscribed radius is [`INSCRIBED`] (the rover's centre there means its
//! body touches the obstacle); beyond that the cost falls off exponentially to zero at the
//! inflation radius, so paths keep away from rocks and crater rims when they can. Unknown
//! space is passable at a price ([`CostmapConfig::unknown_cost`]): a rover exploring must plan
//! into the unknown and replan as it fills in, instead of refusing every goal beyond its map.
//!
//! Distances come from the exact Euclidean distance transform of Felzenszwalb and
//! Huttenlocher, "Distance Transforms of Sampled Functions" (Theory of Computing 8, 2012).

use realms_core::{Cell, Grid, GridGeometry, Point2};

/// An obstacle or hazard cell.
pub const LETHAL: u8 = 254;
/// The rover's centre here puts its body on an obstacle.
pub const INSCRIBED: u8 = 253;
/// The highest cost of a cell the rover may drive through.
pub const MAX_PASSABLE: u8 = 252;
/// Map cells at or above this occupancy (percent) are obstacles (map_server's 0.65).
pub const OCCUPIED_THRESHOLD: i8 = 65;

/// How the map becomes costs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostmapConfig {
    /// Radius of the circle the rover's footprint fits in, around its centre, metres.
    pub inscribed_radius_m: f64,
    /// Beyond this distance from every obstacle a cell costs nothing, metres.
    pub inflation_radius_m: f64,
    /// How fast the cost falls off beyond the inscribed radius, per metre (Nav2's
    /// `cost_scaling_factor`).
    pub cost_scaling_per_m: f64,
    /// Cost of an unknown cell (0..=[`MAX_PASSABLE`]).
    pub unknown_cost: u8,
}

impl Default for CostmapConfig {
    /// The Leo Rover (0.45 x 0.43 m) with 10 cm to spare.
    fn default() -> Self {
        CostmapConfig {
            inscribed_radius_m: 0.32,
            inflation_radius_m: 0.9,
            cost_scaling_per_m: 6.0,
            unknown_cost: 40,
        }
    }
}

/// Traversal costs over a grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Costmap {
    costs: Grid<u8>,
    known: Vec<bool>,
}

impl Costmap {
    /// The costmap of an occupancy map (-1 unknown, 0..=100 percent occupied).
    pub fn from_map(map: &Grid<i8>, cfg: &CostmapConfig) -> Costmap {
        let geometry = *map.geometry();
        let lethal: Vec<bool> = map.cells().iter().map(|&v| is_lethal(v)).collect();
        let known: Vec<bool> = map.cells().iter().map(|&v| v >= 0).collect();
        let inflation = Inflation::new(cfg, geometry.resolution_m);
        let dist2 = squared_distance_transform_within(
            &lethal,
            geometry.width,
            geometry.height,
            inflation.reach_d2,
        );
        let costs = map
            .cells()
            .iter()
            .zip(&dist2)
            .map(|(&v, &d2)| inflation.cost(v, d2))
            .collect();
        Costmap {
            costs: Grid::from_cells(geometry, costs).expect("one cost per map cell"),
            known,
        }
    }

    /// The costmap of `map`, where this one is the costmap of `before` (made with the same
    /// `cfg`): the same costs as [`from_map`](Self::from_map) gives, worked out again only
    /// within the inflation's reach of the cells that changed. A rover's map changes near
    /// the rover between two plans; the rest of the hall keeps its costs.
    pub fn updated(&self, before: &Grid<i8>, map: &Grid<i8>, cfg: &CostmapConfig) -> Costmap {
        let geometry = *map.geometry();
        if before.geometry() != &geometry || self.geometry() != &geometry {
            return Costmap::from_map(map, cfg);
        }
        let (w, h) = (geometry.width, geometry.height);
        // The box of changed cells.
        let mut changed: Option<[usize; 4]> = None;
        for (y, (old, new)) in before
            .cells()
            .chunks_exact(w)
            .zip(map.cells().chunks_exact(w))
            .enumerate()
        {
            if old == new {
                continue;
            }
            let first = old.iter().zip(new).position(|(a, b)| a != b).unwrap_or(0);
            let last = w
                - 1
                - old
                    .iter()
                    .rev()
                    .zip(new.iter().rev())
                    .position(|(a, b)| a != b)
                    .unwrap_or(0);
            changed = Some(match changed {
                None => [first, y, last, y],
                Some([x0, y0, x1, _]) => [x0.min(first), y0, x1.max(last), y],
            });
        }
        let Some([x0, y0, x1, y1]) = changed else {
            return self.clone();
        };
        let inflation = Inflation::new(cfg, geometry.resolution_m);
        // A cell's cost depends on the lethal cells within the inflation's reach: the costs
        // within that reach of a change are redone, from the lethal cells within the reach
        // of those.
        let reach = inflation.reach_cells();
        let grow = |[x0, y0, x1, y1]: [usize; 4], by: usize| {
            [
                x0.saturating_sub(by),
                y0.saturating_sub(by),
                (x1 + by).min(w - 1),
                (y1 + by).min(h - 1),
            ]
        };
        let inner = grow([x0, y0, x1, y1], reach);
        let outer = grow(inner, reach);
        let (ow, oh) = (outer[2] - outer[0] + 1, outer[3] - outer[1] + 1);
        // A change spread over much of the map (a loop closure moving its submaps) is as
        // cheap to redo whole.
        if 2 * ow * oh > w * h {
            return Costmap::from_map(map, cfg);
        }
        let lethal: Vec<bool> = (outer[1]..=outer[3])
            .flat_map(|y| {
                map.cells()[y * w + outer[0]..=y * w + outer[2]]
                    .iter()
                    .map(|&v| is_lethal(v))
            })
            .collect();
        let dist2 = squared_distance_transform_within(&lethal, ow, oh, inflation.reach_d2);
        let mut costmap = self.clone();
        let costs = costmap.costs.cells_mut();
        for y in inner[1]..=inner[3] {
            for x in inner[0]..=inner[2] {
                let i = y * w + x;
                let d2 = dist2[(y - outer[1]) * ow + (x - outer[0])];
                costs[i] = inflation.cost(map.cells()[i], d2);
            }
        }
        for y in y0..=y1 {
            for x in x0..=x1 {
                let i = y * w + x;
                costmap.known[i] = map.cells()[i] >= 0;
            }
        }
        costmap
    }

    /// A costmap from costs directly (tests, benchmarks); every cell counts as known.
    pub fn from_costs(costs: Grid<u8>) -> Costmap {
        let known = vec![true; costs.cells().len()];
        Costmap { costs, known }
    }

    /// Where the costmap lies.
    pub fn geometry(&self) -> &GridGeometry {
        self.costs.geometry()
    }

    /// The costs, row-major from the bottom row.
    pub fn costs(&self) -> &[u8] {
        self.costs.cells()
    }

    /// Whether the map said anything about each cell.
    pub fn known(&self) -> &[bool] {
        &self.known
    }

    /// Cost of a cell.
    pub fn cost(&self, c: Cell) -> u8 {
        self.costs.cells()[self.geometry().index(c)]
    }

    /// Cost at a world point; outside the map counts as unknown-but-passable at the
    /// highest passable price, so a path may leave the map only as a last resort.
    pub fn cost_at(&self, p: Point2) -> u8 {
        match self.geometry().world_to_cell(p) {
            Some(c) => self.cost(c),
            None => MAX_PASSABLE,
        }
    }
}

/// Whether a map cell is an obstacle.
fn is_lethal(v: i8) -> bool {
    v >= OCCUPIED_THRESHOLD
}

/// The inflation law of a configuration on cells of a resolution, by table.
struct Inflation {
    cfg: CostmapConfig,
    resolution_m: f64,
    /// The cost of each whole squared distance in cells, out to past the inflation radius
    /// (empty for an absurdly fine grid, where each cost is worked out).
    table: Vec<u8>,
    /// Past this squared distance a cell costs nothing.
    reach_d2: f32,
}

impl Inflation {
    fn new(cfg: &CostmapConfig, resolution_m: f64) -> Self {
        // Squared distances in cells are sums of two whole squares, so the cost of each is
        // looked up, not worked out with a root and an exponential a cell. Past the table
        // every cell lies beyond the inflation radius, where the cost is 0.
        let reach_cells = cfg.inflation_radius_m / resolution_m + 2.0;
        let table: Vec<u8> = if reach_cells * reach_cells < (1 << 20) as f64 {
            (0..=(reach_cells * reach_cells).ceil() as usize)
                .map(|k| inflation_cost((k as f64).sqrt() * resolution_m, cfg))
                .collect()
        } else {
            Vec::new()
        };
        // Distances past the table cost 0 whatever they are.
        let reach_d2 = table
            .len()
            .checked_sub(1)
            .map_or(f32::INFINITY, |k| k as f32);
        Inflation {
            cfg: *cfg,
            resolution_m,
            table,
            reach_d2,
        }
    }

    /// Cells beyond this many along either axis from every obstacle cost nothing (the whole
    /// map's width for a grid too fine for the table).
    fn reach_cells(&self) -> usize {
        if self.reach_d2.is_finite() {
            (self.reach_d2 as f64).sqrt().ceil() as usize + 1
        } else {
            usize::MAX / 4
        }
    }

    /// The cost of a map cell of value `v` at squared distance `d2` (cells) from the nearest
    /// obstacle.
    fn cost(&self, v: i8, d2: f32) -> u8 {
        let inflated = match self.table.get(d2 as usize) {
            Some(&c) => {
                debug_assert_eq!(d2.fract(), 0.0, "whole cells' squared distances");
                c
            }
            None if !self.table.is_empty() => 0,
            None => inflation_cost((d2 as f64).sqrt() * self.resolution_m, &self.cfg),
        };
        if v < 0 {
            inflated.max(self.cfg.unknown_cost.min(MAX_PASSABLE))
        } else {
            inflated
        }
    }
}

/// Nav2's inflation law: lethal on the obstacle, inscribed within the inscribed radius, then
/// `252 * exp(-k (d - r_inscribed))` out to the inflation radius.
fn inflation_cost(d_m: f64, cfg: &CostmapConfig) -> u8 {
    if d_m == 0.0 {
        LETHAL
    } else if d_m <= cfg.inscribed_radius_m {
        INSCRIBED
    } else if d_m > cfg.inflation_radius_m {
        0
    } else {
        let c =
            MAX_PASSABLE as f64 * (-cfg.cost_scaling_per_m * (d_m - cfg.inscribed_radius_m)).exp();
        c.round().clamp(0.0, MAX_PASSABLE as f64) as u8
    }
}

/// Squared Euclidean distance, in cells, from every cell to the nearest `true` one
/// (`f32::INFINITY` when there is none): Felzenszwalb & Huttenlocher's separable transform,
/// first down every column (for seeds, by sweeps: `column_distances`), then along every
/// row by the lower envelope of parabolas.
pub fn squared_distance_transform(seeds: &[bool], width: usize, height: usize) -> Vec<f32> {
    squared_distance_transform_within(seeds, width, height, f32::INFINITY)
}

/// [`squared_distance_transform`], exact where the distance is at most `max_d2` (squared
/// cells); every cell farther from all seeds reads more than `max_d2` (mostly `INFINITY`).
/// The costmap needs distances out to the inflation radius only: a column's seed farther
/// than that cannot be any cell's nearest within reach, so it is left out, and the row
/// pass skips the open floor's long empty runs instead of fitting parabolas to them.
pub fn squared_distance_transform_within(
    seeds: &[bool],
    width: usize,
    height: usize,
    max_d2: f32,
) -> Vec<f32> {
    let mut d = column_distances(seeds, width, height, max_d2);
    let mut f = vec![0.0f32; width];
    let mut out = vec![0.0f32; width];
    let mut v = vec![0usize; width];
    let mut z = vec![0.0f32; width + 1];
    for y in 0..height {
        let row = &mut d[y * width..(y + 1) * width];
        f.copy_from_slice(row);
        transform_1d(&f, &mut out, &mut v, &mut z);
        row.copy_from_slice(&out);
    }
    d
}

/// The first dimension of [`squared_distance_transform`]: the squared distance down each
/// column to the column's nearest seed. Over values that are 0 or infinite the lower
/// envelope is that and no more, so two sweeps over the rows give it without the
/// envelope's divisions and without reading the grid a column at a time; the squares of
/// whole cells are the envelope's own products, so the values are its to the bit.
fn column_distances(seeds: &[bool], width: usize, height: usize, max_d2: f32) -> Vec<f32> {
    let mut d = vec![f32::INFINITY; width * height];
    // Rows since each column's last seed, in the sweep's direction (None: none yet).
    let mut since: Vec<Option<u32>> = vec![None; width];
    let mut sweep = |y: usize, since: &mut [Option<u32>]| {
        let row = y * width..(y + 1) * width;
        for ((out, &seed), run) in d[row.clone()].iter_mut().zip(&seeds[row]).zip(since) {
            *run = if seed { Some(0) } else { run.map(|r| r + 1) };
            if let Some(r) = *run {
                let d2 = r as f32 * r as f32;
                if d2 <= max_d2 {
                    *out = out.min(d2);
                }
            }
        }
    };
    for y in 0..height {
        sweep(y, &mut since);
    }
    since.fill(None);
    for y in (0..height).rev() {
        sweep(y, &mut since);
    }
    d
}

/// One dimension of the squared distance transform of a sampled function `f`.
fn transform_1d(f: &[f32], out: &mut [f32], v: &mut [usize], z: &mut [f32]) {
    let n = f.len();
    // Parabolas rooted at infinite samples never form part of the envelope.
    let mut k: isize = -1;
    for q in 0..n {
        if !f[q].is_finite() {
            continue;
        }
        loop {
            if k < 0 {
                k = 0;
                v[0] = q;
                z[0] = f32::NEG_INFINITY;
                z[1] = f32::INFINITY;
                break;
            }
            let p = v[k as usize];
            let s = ((f[q] + (q * q) as f32) - (f[p] + (p * p) as f32)) / (2.0 * (q - p) as f32);
            if s <= z[k as usize] {
                k -= 1;
                continue;
            }
            k += 1;
            v[k as usize] = q;
            z[k as usize] = s;
            z[k as usize + 1] = f32::INFINITY;
            break;
        }
    }
    if k < 0 {
        out.fill(f32::INFINITY);
        return;
    }
    let mut j = 0usize;
    for (q, o) in out.iter_mut().enumerate() {
        while z[j + 1] < q as f32 {
            j += 1;
        }
        let p = v[j];
        let dq = q as f32 - p as f32;
        *o = dq * dq + f[p];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn geometry(width: usize, height: usize) -> GridGeometry {
        GridGeometry {
            width,
            height,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        }
    }

    /// A map cell's value from a draw of 0..40: obstacle or hazard now and then, some
    /// unknown, free or unjudged mostly (an open floor with rocks: most cells lie far from
    /// the nearest obstacle, so a change reaches far).
    fn map_value(k: u8) -> i8 {
        match k {
            0 => 100,
            1 => 90,
            2..=9 => -1,
            10..=14 => 1,
            _ => 0,
        }
    }

    proptest! {
        #[test]
        fn a_costmap_updated_where_its_map_changed_is_the_costmap_made_afresh(
            width in 60usize..200,
            height in 60usize..200,
            cells in proptest::collection::vec(0u8..40, 200 * 200),
            patch in (0usize..200, 0usize..200, 1usize..12, 1usize..12, 0u8..40),
            edits in proptest::collection::vec((0usize..20, 0usize..20, 0u8..4), 0..4),
            spread in proptest::bool::weighted(0.1),
        ) {
            let cfg = CostmapConfig::default();
            let before = Grid::from_cells(
                geometry(width, height),
                cells[..width * height].iter().map(|k| map_value(*k)).collect(),
            )
            .expect("one value a cell");
            let mut after = before.clone();
            // A patch of one value (ground newly seen), a few cells about it, and now and
            // then a cell far off (a map bent by a loop closure).
            let (px, py, pw, ph, pk) = patch;
            let (px, py) = (px % width, py % height);
            for y in py..(py + ph).min(height) {
                for x in px..(px + pw).min(width) {
                    after.cells_mut()[y * width + x] = map_value(pk);
                }
            }
            for (dx, dy, k) in &edits {
                let (x, y) = ((px + dx) % width, (py + dy) % height);
                after.cells_mut()[y * width + x] = map_value(*k);
            }
            if spread {
                let (x, y) = ((px + width / 2) % width, (py + height / 2) % height);
                after.cells_mut()[y * width + x] = OCCUPIED_THRESHOLD;
            }
            let fresh = Costmap::from_map(&after, &cfg);
            let updated = Costmap::from_map(&before, &cfg).updated(&before, &after, &cfg);
            prop_assert_eq!(updated.costs(), fresh.costs());
            prop_assert_eq!(updated.known(), fresh.known());
        }

        #[test]
        fn the_distance_transform_is_exact(
            width in 1usize..24,
            height in 1usize..24,
            seeds in proptest::collection::vec(proptest::bool::weighted(0.08), 24 * 24),
        ) {
            let seeds = &seeds[..width * height];
            let d = squared_distance_transform(seeds, width, height);
            for y in 0..height {
                for x in 0..width {
                    let brute = (0..height)
                        .flat_map(|sy| (0..width).map(move |sx| (sx, sy)))
                        .filter(|&(sx, sy)| seeds[sy * width + sx])
                        .map(|(sx, sy)| {
                            let (dx, dy) = (sx as f32 - x as f32, sy as f32 - y as f32);
                            dx * dx + dy * dy
                        })
                        .fold(f32::INFINITY, f32::min);
                    prop_assert_eq!(d[y * width + x], brute, "cell ({}, {})", x, y);
                }
            }
        }

        #[test]
        fn the_distance_transform_within_a_reach_is_exact_inside_it_and_beyond_it_outside(
            width in 1usize..40,
            height in 1usize..40,
            seeds in proptest::collection::vec(proptest::bool::weighted(0.02), 40 * 40),
            max_d2 in 0u32..60,
        ) {
            let seeds = &seeds[..width * height];
            let full = squared_distance_transform(seeds, width, height);
            let within =
                squared_distance_transform_within(seeds, width, height, max_d2 as f32);
            for (k, (w, f)) in within.iter().zip(&full).enumerate() {
                if *f <= max_d2 as f32 {
                    prop_assert_eq!(w, f, "cell {}", k);
                } else {
                    prop_assert!(*w > max_d2 as f32, "cell {}: {} within, {} in full", k, w, f);
                }
            }
        }

        #[test]
        fn every_cost_is_the_inflation_law_at_the_cells_distance(
            width in 1usize..40,
            height in 1usize..40,
            fine in proptest::bool::ANY,
            cells in proptest::collection::vec(
                prop_oneof![1 => Just(100i8), 2 => Just(-1i8), 20 => Just(0i8)],
                40 * 40,
            ),
        ) {
            let g = GridGeometry {
                resolution_m: if fine { 0.05 } else { 0.1 },
                ..geometry(width, height)
            };
            let cells = cells[..width * height].to_vec();
            let map = Grid::from_cells(g, cells.clone()).expect("sized");
            let cfg = CostmapConfig::default();
            let cm = Costmap::from_map(&map, &cfg);
            for y in 0..height {
                for x in 0..width {
                    let d2 = (0..height)
                        .flat_map(|sy| (0..width).map(move |sx| (sx, sy)))
                        .filter(|&(sx, sy)| cells[sy * width + sx] >= OCCUPIED_THRESHOLD)
                        .map(|(sx, sy)| (sx.abs_diff(x).pow(2) + sy.abs_diff(y).pow(2)) as f64)
                        .fold(f64::INFINITY, f64::min);
                    let law = inflation_cost(d2.sqrt() * g.resolution_m, &cfg);
                    let want = if cells[y * width + x] < 0 { law.max(cfg.unknown_cost) } else { law };
                    prop_assert_eq!(cm.cost(Cell { x, y }), want, "cell ({}, {})", x, y);
                }
            }
        }
    }

    #[test]
    fn a_rock_is_lethal_its_surroundings_inscribed_then_graded_then_free() {
        let g = geometry(41, 41);
        let mut map = Grid::new(g, 0i8);
        *map.get_mut(20, 20).expect("inside") = 100;
        let cfg = CostmapConfig::default();
        let cm = Costmap::from_map(&map, &cfg);
        let at = |x: usize| cm.cost(Cell { x, y: 20 });
        assert_eq!(at(20), LETHAL);
        // 0.3 m away: inside the 0.32 m inscribed radius.
        assert_eq!(at(23), INSCRIBED);
        // 0.4 m away: graded, 252 exp(-6 * 0.08) = 156.
        assert_eq!(at(24), 156);
        // Falling with distance, zero beyond 0.9 m.
        assert!(at(25) < at(24) && at(26) < at(25));
        assert_eq!(at(30), 0);
    }

    #[test]
    fn hazards_are_obstacles_and_unknown_space_is_passable_at_a_price() {
        let g = geometry(30, 10);
        let mut cells = vec![-1i8; 30 * 10];
        for y in 0..10 {
            for x in 0..15 {
                cells[y * 30 + x] = 0;
            }
        }
        cells[5 * 30 + 2] = 90;
        let map = Grid::from_cells(g, cells).expect("sized");
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        assert_eq!(cm.cost(Cell { x: 2, y: 5 }), LETHAL);
        assert_eq!(cm.cost(Cell { x: 25, y: 5 }), 40);
        assert!(!cm.known()[5 * 30 + 25]);
        assert_eq!(cm.cost(Cell { x: 12, y: 5 }), 0);
    }
}
