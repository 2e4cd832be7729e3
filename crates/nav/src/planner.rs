//! Global planning on a [`Costmap`]: A* over the 8-connected cell graph (no cutting
//! corners), where entering a cell costs the step's length stretched by the cell's cost, so
//! the cheapest path trades length against clearance. The octile distance is an admissible and consistent heuristic for that
//! graph (no step is cheaper than its length), so A* returns exactly Dijkstra's optimum; the
//! Dijkstra field ([`Planner::travel_costs`]) is kept beside it for checking, for the benchmark
//! baseline, and because exploration wants the cost to every frontier at once.
//!
//! A rover whose centre sits in an inscribed or lethal cell (a hazard marked under it, a rock
//! it backed towards) may still leave: cells within [`PlannerConfig::escape_radius_m`] of the
//! start are passable at the highest price. A goal in such a cell is refused at once rather
//! than searched for.
//!
//! [`smooth`] turns the staircase of cells into a few straight legs a skid-steer rover can
//! follow, shortcutting only where the straight leg is no closer to danger than the cells it
//! replaces.

use crate::costmap::{Costmap, MAX_PASSABLE};
use realms_core::{Cell, GridGeometry, Point2};

/// Planner tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannerConfig {
    /// A cell of the highest passable cost makes a step through it `1 + cost_weight` times as
    /// dear as through free ground.
    pub cost_weight: f64,
    /// Blocked cells this close to the start may be driven out of, metres.
    pub escape_radius_m: f64,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            cost_weight: 4.0,
            escape_radius_m: 0.5,
        }
    }
}

/// Why there is no plan.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The start is off the costmap.
    #[error("start ({x_m:.2}, {y_m:.2}) is outside the map")]
    StartOutside {
        /// Where.
        x_m: f64,
        /// Where.
        y_m: f64,
    },
    /// The goal is off the costmap.
    #[error("goal ({x_m:.2}, {y_m:.2}) is outside the map")]
    GoalOutside {
        /// Where.
        x_m: f64,
        /// Where.
        y_m: f64,
    },
    /// The goal is an obstacle, a hazard, or too close to one for the rover to stand there.
    #[error("goal ({x_m:.2}, {y_m:.2}) is blocked (cost {cost})")]
    GoalBlocked {
        /// Where.
        x_m: f64,
        /// Where.
        y_m: f64,
        /// Its cost.
        cost: u8,
    },
    /// Every way to the goal is blocked.
    #[error("no path: the goal is cut off ({expanded} cells searched)")]
    NoPath {
        /// Cells expanded before giving up.
        expanded: usize,
    },
}

/// A planned path.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Cells from start to goal, each an 8-neighbour of the one before.
    pub cells: Vec<Cell>,
    /// The path's cost: metres stretched by the cells' costs.
    pub cost: f64,
    /// Cells expanded by the search.
    pub expanded: usize,
}

/// A planner with its search buffers, kept between calls so a replan allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct Planner {
    cfg: PlannerConfig,
    /// Each cell's search state, kept together: a step reads and writes all of a
    /// neighbour's, so one cache line a neighbour instead of one per array.
    cells: Vec<SearchCell>,
    generation: u32,
    /// The search generation that marked each cell a target of a flood.
    target: Vec<u32>,
    /// The cells the last search closed, in the order it closed them.
    closed_cells: Vec<u32>,
    heap: RadixHeap,
}

/// Where a flood towards targets may stop before it has reached them all (see
/// [`Planner::travel_costs_bounded`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FloodBound {
    /// Stop this much dearer than the first target reached ...
    pub beyond_first: f32,
    /// ... but not before this cell is reached (or found unreachable); it counts as one of
    /// the targets.
    pub must_reach: Option<Cell>,
}

/// One cell's state in a search.
#[derive(Clone, Copy, Debug)]
struct SearchCell {
    g: f32,
    parent: u32,
    /// The search generation that last touched the cell (its `g` is stale otherwise).
    seen: u32,
    /// The search generation that closed it.
    closed: u32,
}

impl SearchCell {
    const UNSEEN: SearchCell = SearchCell {
        g: f32::INFINITY,
        parent: u32::MAX,
        seen: 0,
        closed: 0,
    };
}

const NEIGHBOURS: [(isize, isize, f32); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, std::f32::consts::SQRT_2),
    (1, -1, std::f32::consts::SQRT_2),
    (-1, 1, std::f32::consts::SQRT_2),
    (-1, -1, std::f32::consts::SQRT_2),
];

/// A monotone priority queue (Ahuja, Mehlhorn, Orlin & Tarjan, "Faster Algorithms for the
/// Shortest Path Problem", J. ACM 37, 1990): keys go into bucket `k` by the highest bit in
/// which they differ from the last key taken out, so a push is O(1) and each item moves
/// down at most 64 times. Dijkstra and A* with a consistent heuristic never push an `f`
/// below the last one popped (float rounding aside, by an ulp); a key below the last one
/// (the same `f` with a larger `g`, or an ulp's rounding) is raised to it, which keeps the
/// order by `f` and only loses the tie-break.
#[derive(Clone, Debug, Default)]
struct RadixHeap {
    buckets: Vec<Vec<(u64, u32)>>,
    /// Bit `b` (1..=64) set while bucket `b` holds items: the next bucket to empty is found
    /// by one count of trailing zeros, not by looking into each empty bucket below it. Bit 0
    /// is never read (bucket 0 is looked at directly), so it is not kept.
    occupied: u128,
    last: u64,
    len: usize,
}

impl RadixHeap {
    fn clear(&mut self) {
        if self.buckets.len() != 65 {
            self.buckets = vec![Vec::new(); 65];
        }
        for b in &mut self.buckets {
            b.clear();
        }
        self.occupied = 0;
        self.last = 0;
        self.len = 0;
    }

    fn bucket(&self, key: u64) -> usize {
        (64 - (key ^ self.last).leading_zeros()) as usize
    }

    fn push(&mut self, key: u64, item: u32) {
        let key = key.max(self.last);
        let b = self.bucket(key);
        self.buckets[b].push((key, item));
        self.occupied |= 1 << b;
        self.len += 1;
    }

    fn pop(&mut self) -> Option<u32> {
        if self.len == 0 {
            return None;
        }
        if self.buckets[0].is_empty() {
            let higher = self.occupied & !1;
            if higher == 0 {
                return None;
            }
            let i = higher.trailing_zeros() as usize;
            let items = std::mem::take(&mut self.buckets[i]);
            self.occupied &= !(1 << i);
            self.last = items.iter().map(|(k, _)| *k).min().unwrap_or(self.last);
            for (k, item) in &items {
                let b = self.bucket(*k);
                self.buckets[b].push((*k, *item));
                self.occupied |= 1 << b;
            }
            // Give the emptied bucket its allocation back for the next round.
            let mut items = items;
            items.clear();
            if self.buckets[i].is_empty() {
                self.buckets[i] = items;
            }
        }
        self.len -= 1;
        self.buckets[0].pop().map(|(_, item)| item)
    }
}

/// The search order: lowest `f` first and, among equal `f`, highest `g` (nearest the goal,
/// which saves expanding whole plateaus of equal estimates). Non-negative floats order as
/// their bits do (IEEE 754).
fn key(f: f32, g: f32) -> u64 {
    ((f.to_bits() as u64) << 32) | (u32::MAX - g.to_bits()) as u64
}

impl Planner {
    /// A planner with `cfg`.
    pub fn new(cfg: PlannerConfig) -> Self {
        Planner {
            cfg,
            ..Planner::default()
        }
    }

    fn begin(&mut self, n: usize) {
        if self.cells.len() != n {
            self.cells = vec![SearchCell::UNSEEN; n];
            self.target = vec![0; n];
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            for c in &mut self.cells {
                c.seen = 0;
                c.closed = 0;
            }
            self.target.fill(0);
            self.generation = 1;
        }
        self.heap.clear();
        self.closed_cells.clear();
    }

    /// The search, A* when `heuristic` is set, Dijkstra otherwise; stops at `goal` if given.
    /// A flood (no `goal`) given `targets` stops once it has closed them all, or where their
    /// bound, if any, lets it stop (see [`Planner::travel_costs_bounded`]). Returns the cells
    /// it expanded and the cost the bound stopped it at, if it did.
    fn search(
        &mut self,
        map: &Costmap,
        start: Cell,
        goal: Option<Cell>,
        heuristic: bool,
        known_only: bool,
        targets: Option<(&[Cell], Option<FloodBound>)>,
    ) -> (usize, Option<f32>) {
        let geo = *map.geometry();
        let (w, h) = (geo.width, geo.height);
        self.begin(geo.len());
        let mut targets_open = usize::MAX;
        let bound = targets.and_then(|(_, b)| b);
        let must_reach = bound.and_then(|b| b.must_reach);
        if let Some((cells, _)) = targets {
            targets_open = 0;
            for c in cells.iter().chain(must_reach.as_ref()) {
                let i = geo.index(*c);
                if self.target[i] != self.generation {
                    self.target[i] = self.generation;
                    targets_open += 1;
                }
            }
        }
        let costs = map.costs();
        let known = map.known();
        let weight = self.cfg.cost_weight as f32 / MAX_PASSABLE as f32;
        let escape_cells = (self.cfg.escape_radius_m / geo.resolution_m) as f32;
        let escape2 = escape_cells * escape_cells;
        let start_cost = costs[geo.index(start)];
        let res = geo.resolution_m as f32;
        let gen_ = self.generation;
        let estimate = |x: usize, y: usize| -> f32 {
            match goal {
                Some(g) if heuristic => {
                    let dx = x.abs_diff(g.x) as f32;
                    let dy = y.abs_diff(g.y) as f32;
                    res * (dx.max(dy) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dy))
                }
                _ => 0.0,
            }
        };
        // Price per metre of entering a cell, or None where the rover may not go.
        let factor = |x: usize, y: usize| -> Option<f32> {
            let i = y * w + x;
            let c = costs[i];
            let (dx, dy) = (x as f32 - start.x as f32, y as f32 - start.y as f32);
            let near_start = dx * dx + dy * dy <= escape2;
            if known_only && !known[i] && !near_start {
                return None;
            }
            if c <= MAX_PASSABLE {
                return Some(1.0 + weight * c as f32);
            }
            // Only a rover already in a blocked cell may cross blocked cells, near where it
            // stands and none dearer than its own (Nav2's rule), to get out.
            (near_start && start_cost > MAX_PASSABLE && c <= start_cost)
                .then_some(1.0 + weight * (MAX_PASSABLE as f32) * 2.0)
        };
        let s = geo.index(start);
        self.cells[s] = SearchCell {
            g: 0.0,
            parent: u32::MAX,
            seen: gen_,
            closed: self.cells[s].closed,
        };
        self.heap
            .push(key(estimate(start.x, start.y), 0.0), s as u32);
        let goal_index = goal.map(|g| geo.index(g));
        let must_close = must_reach.map(|c| geo.index(c));
        let mut limit = f32::INFINITY;
        let mut last_closed = 0.0f32;
        let mut stopped_at = None;
        let mut expanded = 0usize;
        while let Some(i) = self.heap.pop() {
            let i = i as usize;
            if self.cells[i].closed == gen_ {
                continue;
            }
            // A flood pops cells in order of cost: past the limit, nothing nearer is left.
            if self.cells[i].g > limit && must_close.is_none_or(|m| self.cells[m].closed == gen_) {
                // Past the limit if the cell it had to reach lay farther.
                stopped_at = Some(limit.max(last_closed));
                break;
            }
            self.cells[i].closed = gen_;
            self.closed_cells.push(i as u32);
            last_closed = self.cells[i].g;
            expanded += 1;
            if Some(i) == goal_index {
                break;
            }
            if self.target[i] == gen_ {
                targets_open -= 1;
                if let Some(b) = bound
                    && limit.is_infinite()
                {
                    limit = self.cells[i].g + b.beyond_first;
                }
            }
            if targets_open == 0 {
                break;
            }
            let (x, y) = (i % w, i / w);
            let gi = self.cells[i].g;
            for &(dx, dy, len) in &NEIGHBOURS {
                let nx = x as isize + dx;
                let ny = y as isize + dy;
                if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                    continue;
                }
                let (nx, ny) = (nx as usize, ny as usize);
                let j = ny * w + nx;
                if self.cells[j].closed == gen_ {
                    continue;
                }
                let Some(f) = factor(nx, ny) else { continue };
                // No cutting corners: a diagonal step needs both cells beside it open.
                if dx != 0 && dy != 0 && (factor(nx, y).is_none() || factor(x, ny).is_none()) {
                    continue;
                }
                let g = gi + len * res * f;
                let c = &mut self.cells[j];
                if c.seen != gen_ || g < c.g {
                    c.seen = gen_;
                    c.g = g;
                    c.parent = i as u32;
                    self.heap.push(key(g + estimate(nx, ny), g), j as u32);
                }
            }
        }
        (expanded, stopped_at)
    }

    fn cells(map: &Costmap, start: Point2, goal: Point2) -> Result<(Cell, Cell), PlanError> {
        let geo = map.geometry();
        let s = geo.world_to_cell(start).ok_or(PlanError::StartOutside {
            x_m: start.x_m,
            y_m: start.y_m,
        })?;
        let g = geo.world_to_cell(goal).ok_or(PlanError::GoalOutside {
            x_m: goal.x_m,
            y_m: goal.y_m,
        })?;
        let cost = map.cost(g);
        if cost > MAX_PASSABLE && g != s {
            return Err(PlanError::GoalBlocked {
                x_m: goal.x_m,
                y_m: goal.y_m,
                cost,
            });
        }
        Ok((s, g))
    }

    fn path_to(&self, geo: &GridGeometry, goal: Cell, expanded: usize) -> Result<Plan, PlanError> {
        let gi = geo.index(goal);
        if self.cells[gi].closed != self.generation {
            return Err(PlanError::NoPath { expanded });
        }
        let mut cells = vec![goal];
        let mut i = gi;
        while self.cells[i].parent != u32::MAX {
            i = self.cells[i].parent as usize;
            cells.push(Cell {
                x: i % geo.width,
                y: i / geo.width,
            });
        }
        cells.reverse();
        Ok(Plan {
            cells,
            cost: self.cells[gi].g as f64,
            expanded,
        })
    }

    /// The cheapest path from `start` to `goal` (A*).
    pub fn plan(&mut self, map: &Costmap, start: Point2, goal: Point2) -> Result<Plan, PlanError> {
        let (s, g) = Self::cells(map, start, goal)?;
        let (expanded, _) = self.search(map, s, Some(g), true, false, None);
        self.path_to(map.geometry(), g, expanded)
    }

    /// The same path found by plain Dijkstra (the benchmark's baseline).
    pub fn plan_dijkstra(
        &mut self,
        map: &Costmap,
        start: Point2,
        goal: Point2,
    ) -> Result<Plan, PlanError> {
        let (s, g) = Self::cells(map, start, goal)?;
        let (expanded, _) = self.search(map, s, Some(g), false, false, None);
        self.path_to(map.geometry(), g, expanded)
    }

    /// The cost of the cheapest path from `start` to every cell (`INFINITY` where none),
    /// row-major like the costmap; with `known_only` the paths keep to known cells (the
    /// start's surroundings excepted), as exploration's do: every frontier lies on known
    /// ground, and the search need not flood the unknown.
    pub fn travel_costs(
        &mut self,
        map: &Costmap,
        start: Point2,
        known_only: bool,
    ) -> Result<Vec<f32>, PlanError> {
        self.travel_costs_until(map, start, known_only, None)
    }

    /// [`travel_costs`](Self::travel_costs), but given `targets` the flood stops once it
    /// has reached them all (or everything it can reach): their costs, and those of every
    /// cell nearer than the farthest of them, are exact; the cells beyond read `INFINITY`.
    /// Exploration needs the costs of the frontiers and of its goal only, and a rover with
    /// no frontier left needs none.
    pub fn travel_costs_until(
        &mut self,
        map: &Costmap,
        start: Point2,
        known_only: bool,
        targets: Option<&[Cell]>,
    ) -> Result<Vec<f32>, PlanError> {
        let s = start_cell(map, start)?;
        self.search(map, s, None, false, known_only, targets.map(|t| (t, None)));
        Ok(self.field())
    }

    /// [`travel_costs_until`](Self::travel_costs_until), but the flood also stops once it
    /// is `bound.beyond_first` dearer than the first target it reached, provided it has
    /// reached `bound.must_reach`: a frontier that much farther than another cannot be
    /// worth more, whatever it would reveal. Also returns the cost the flood stopped at,
    /// if the bound stopped it (every cell cheaper reads its exact cost, every dearer one
    /// `INFINITY`, one as dear either); `None` when it ran as `travel_costs_until` would.
    pub fn travel_costs_bounded(
        &mut self,
        map: &Costmap,
        start: Point2,
        known_only: bool,
        targets: &[Cell],
        bound: FloodBound,
    ) -> Result<(Vec<f32>, Option<f32>), PlanError> {
        let s = start_cell(map, start)?;
        let targets = Some((targets, Some(bound)));
        let (_, stopped_at) = self.search(map, s, None, false, known_only, targets);
        Ok((self.field(), stopped_at))
    }

    /// The last search's costs, `INFINITY` where it did not close a cell.
    fn field(&self) -> Vec<f32> {
        // A flood that closed few cells (a rover with no frontier left, or one right beside
        // it) writes those into a fresh field; one that closed many reads every cell in
        // order, as cheap as filling the field.
        if self.closed_cells.len() < self.cells.len() / 8 {
            let mut field = vec![f32::INFINITY; self.cells.len()];
            for &i in &self.closed_cells {
                field[i as usize] = self.cells[i as usize].g;
            }
            return field;
        }
        let gen_ = self.generation;
        self.cells
            .iter()
            .map(|c| if c.closed == gen_ { c.g } else { f32::INFINITY })
            .collect()
    }

    /// The path to `goal` from the start of the last [`travel_costs`](Self::travel_costs).
    pub fn path_from_field(&self, map: &Costmap, goal: Cell) -> Result<Plan, PlanError> {
        self.path_to(map.geometry(), goal, 0)
    }
}

/// The cell a flood starts from, or why there is none.
fn start_cell(map: &Costmap, start: Point2) -> Result<Cell, PlanError> {
    map.geometry()
        .world_to_cell(start)
        .ok_or(PlanError::StartOutside {
            x_m: start.x_m,
            y_m: start.y_m,
        })
}

/// Whether the rover may drive the straight leg from `a` to `b` without going anywhere
/// dearer than `worst`, sampled every quarter cell (a leg may clip the corner of a dearer
/// cell by less than that; the inflation's gradient is far wider).
fn leg_is_clear(map: &Costmap, a: Point2, b: Point2, worst: u8) -> bool {
    let geo = map.geometry();
    let len = a.distance_m(b);
    let steps = (len / (0.25 * geo.resolution_m)).ceil().max(1.0) as usize;
    (0..=steps).all(|k| {
        let s = k as f64 / steps as f64;
        let p = Point2::new(a.x_m + s * (b.x_m - a.x_m), a.y_m + s * (b.y_m - a.y_m));
        match geo.world_to_cell(p) {
            Some(c) => {
                let cost = map.cost(c);
                cost <= worst && cost <= MAX_PASSABLE
            }
            None => false,
        }
    })
}

/// The cells of a plan as a few straight legs (cell centres; the first and last are the
/// plan's ends). A leg replaces the cells it spans only if nowhere along it costs more than
/// the dearest of those cells, so smoothing does not bring the path closer to an obstacle;
/// legs are at most `max_leg_m` long so the follower's look-ahead stays on the plan.
pub fn smooth(map: &Costmap, cells: &[Cell], max_leg_m: f64) -> Vec<Point2> {
    let geo = map.geometry();
    let points: Vec<Point2> = cells.iter().map(|&c| geo.cell_center(c)).collect();
    let Some(&first) = points.first() else {
        return Vec::new();
    };
    let mut out = vec![first];
    let mut i = 0;
    while i + 1 < points.len() {
        // Blocked start cells (the escape zone) are kept as they are.
        let mut worst = map.cost(cells[i]).max(map.cost(cells[i + 1]));
        let mut j = i + 1;
        while j + 1 < points.len() {
            let next_worst = worst.max(map.cost(cells[j + 1]));
            if next_worst > MAX_PASSABLE
                || points[i].distance_m(points[j + 1]) > max_leg_m
                || !leg_is_clear(map, points[i], points[j + 1], next_worst)
            {
                break;
            }
            worst = next_worst;
            j += 1;
        }
        out.push(points[j]);
        i = j;
    }
    out
}

/// The cost of driving `cells` in order, as the planner prices it (for checking plans).
pub fn path_cost(map: &Costmap, cells: &[Cell], cfg: &PlannerConfig) -> f64 {
    let res = map.geometry().resolution_m as f32;
    let weight = cfg.cost_weight as f32 / MAX_PASSABLE as f32;
    cells
        .windows(2)
        .map(|w| {
            let diagonal = w[0].x != w[1].x && w[0].y != w[1].y;
            let len = if diagonal {
                std::f32::consts::SQRT_2
            } else {
                1.0
            };
            let c = map.cost(w[1]);
            let f = if c <= MAX_PASSABLE {
                1.0 + weight * c as f32
            } else {
                // Only the escape zone around the start holds such cells.
                1.0 + weight * (MAX_PASSABLE as f32) * 2.0
            };
            (len * res * f) as f64
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{INSCRIBED, LETHAL};
    use proptest::prelude::*;
    use realms_core::Grid;

    fn costmap(width: usize, height: usize, costs: Vec<u8>) -> Costmap {
        let g = GridGeometry {
            width,
            height,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        Costmap::from_costs(Grid::from_cells(g, costs).expect("sized"))
    }

    fn centre(map: &Costmap, x: usize, y: usize) -> Point2 {
        map.geometry().cell_center(Cell { x, y })
    }

    /// A random flood's scene: a costmap with a fifth of its cells blocked (the start
    /// open), a planner, the start, the full flood from it, and the target cells picked.
    fn flood_scene(
        width: usize,
        height: usize,
        raw: &[u8],
        start: (usize, usize),
        picks: &[(usize, usize)],
    ) -> (Costmap, Planner, Point2, Vec<f32>, Vec<Cell>) {
        let mut costs: Vec<u8> = raw[..width * height]
            .iter()
            .map(|&r| if r < 70 { LETHAL } else { r - 70 })
            .collect();
        let (sx, sy) = (start.0 % width, start.1 % height);
        costs[sy * width + sx] = 0;
        let map = costmap(width, height, costs);
        let mut planner = Planner::new(PlannerConfig::default());
        let s = centre(&map, sx, sy);
        let full = planner.travel_costs(&map, s, false).expect("start inside");
        let targets: Vec<Cell> = picks
            .iter()
            .map(|(x, y)| Cell {
                x: x % width,
                y: y % height,
            })
            .collect();
        (map, planner, s, full, targets)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// A* finds Dijkstra's optimum, never crosses a blocked cell, and agrees with it on
        /// whether the goal can be reached at all.
        #[test]
        fn a_star_is_optimal_and_safe_on_random_grids(
            width in 2usize..40,
            height in 2usize..30,
            raw in proptest::collection::vec(0u8..=255, 40 * 30),
            start in (0usize..40, 0usize..30),
            goal in (0usize..40, 0usize..30),
        ) {
            // A third of the cells blocked, the rest graded.
            let costs: Vec<u8> = raw[..width * height]
                .iter()
                .map(|&r| if r < 70 { LETHAL } else if r < 85 { INSCRIBED } else { r - 85 })
                .collect();
            let (sx, sy) = (start.0 % width, start.1 % height);
            let (gx, gy) = (goal.0 % width, goal.1 % height);
            let mut costs = costs;
            costs[sy * width + sx] = 0;
            let map = costmap(width, height, costs);
            let cfg = PlannerConfig { escape_radius_m: 0.0, ..PlannerConfig::default() };
            let mut planner = Planner::new(cfg);
            let (s, g) = (centre(&map, sx, sy), centre(&map, gx, gy));
            let astar = planner.plan(&map, s, g);
            let field = planner.travel_costs(&map, s, false).expect("start inside");
            let optimum = field[gy * width + gx];
            match astar {
                Ok(plan) => {
                    prop_assert!(optimum.is_finite());
                    prop_assert!((plan.cost - optimum as f64).abs() <= 1e-4 * (1.0 + plan.cost),
                        "A* {} against Dijkstra {}", plan.cost, optimum);
                    prop_assert!((path_cost(&map, &plan.cells, &cfg) - plan.cost).abs() < 1e-3);
                    prop_assert_eq!(plan.cells[0], Cell { x: sx, y: sy });
                    prop_assert_eq!(*plan.cells.last().expect("non-empty"), Cell { x: gx, y: gy });
                    for w in plan.cells.windows(2) {
                        prop_assert!(w[0].x.abs_diff(w[1].x) <= 1 && w[0].y.abs_diff(w[1].y) <= 1);
                        prop_assert!(w[0] != w[1]);
                        let crossed = map.cost(w[1]);
                        prop_assert!(crossed <= MAX_PASSABLE, "crossed {:?}", w[1]);
                    }
                    for p in smooth(&map, &plan.cells, 3.0).windows(2) {
                        prop_assert!(leg_is_clear(&map, p[0], p[1], MAX_PASSABLE));
                    }
                }
                Err(PlanError::GoalBlocked { .. }) => {
                    let goal_cost = map.cost(Cell { x: gx, y: gy });
                    prop_assert!(goal_cost > MAX_PASSABLE);
                }
                Err(e) => {
                    prop_assert!(!optimum.is_finite(), "{} but Dijkstra reached it at {}", e, optimum);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// A flood stopped at its targets gives every target, and every cell it settled on
        /// the way, exactly the full flood's cost; with no targets it settles the start only.
        #[test]
        fn a_flood_stopped_at_its_targets_costs_them_as_the_full_flood_does(
            width in 2usize..40,
            height in 2usize..30,
            raw in proptest::collection::vec(0u8..=255, 40 * 30),
            start in (0usize..40, 0usize..30),
            picks in proptest::collection::vec((0usize..40, 0usize..30), 0..6),
        ) {
            let (map, mut planner, s, full, targets) =
                flood_scene(width, height, &raw, start, &picks);
            let part = planner
                .travel_costs_until(&map, s, false, Some(&targets))
                .expect("start inside");
            for t in &targets {
                prop_assert_eq!(part[t.y * width + t.x].to_bits(), full[t.y * width + t.x].to_bits());
            }
            for (p, f) in part.iter().zip(&full) {
                prop_assert!(!p.is_finite() || p.to_bits() == f.to_bits());
            }
            if targets.is_empty() {
                prop_assert_eq!(part.iter().filter(|c| c.is_finite()).count(), 1);
            }
        }

        /// A flood bounded past its first target settles every cell up to its limit at the
        /// full flood's cost and none beyond, the limit lies the bound past the nearest
        /// target, and the cell it must reach is reached wherever the full flood reaches it.
        #[test]
        fn a_bounded_flood_settles_everything_within_its_limit_and_nothing_past_it(
            width in 2usize..40,
            height in 2usize..30,
            raw in proptest::collection::vec(0u8..=255, 40 * 30),
            start in (0usize..40, 0usize..30),
            picks in proptest::collection::vec((0usize..40, 0usize..30), 1..6),
            must in proptest::option::of((0usize..40, 0usize..30)),
            beyond_first in 0.0f32..3.0,
        ) {
            let (map, mut planner, s, full, targets) =
                flood_scene(width, height, &raw, start, &picks);
            let must_reach = must.map(|(x, y)| Cell { x: x % width, y: y % height });
            let bound = FloodBound { beyond_first, must_reach };
            let (part, limit) = planner
                .travel_costs_bounded(&map, s, false, &targets, bound)
                .expect("start inside");
            let at = |c: Cell| c.y * width + c.x;
            // The cell it must reach is a target too.
            let nearest = targets
                .iter()
                .chain(must_reach.as_ref())
                .map(|t| full[at(*t)])
                .fold(f32::INFINITY, f32::min);
            match limit {
                Some(limit) => {
                    let past = must_reach.map_or(0.0, |m| full[at(m)]);
                    prop_assert_eq!(limit.to_bits(), (nearest + beyond_first).max(past).to_bits());
                    for (p, f) in part.iter().zip(&full) {
                        if *f < limit {
                            prop_assert_eq!(p.to_bits(), f.to_bits());
                        } else if *f > limit {
                            prop_assert!(!p.is_finite());
                        } else {
                            prop_assert!(!p.is_finite() || p.to_bits() == f.to_bits());
                        }
                    }
                }
                None => {
                    for (p, f) in part.iter().zip(&full) {
                        prop_assert!(!p.is_finite() || p.to_bits() == f.to_bits());
                    }
                    for t in &targets {
                        prop_assert_eq!(part[at(*t)].to_bits(), full[at(*t)].to_bits());
                    }
                }
            }
            if let Some(m) = must_reach {
                prop_assert_eq!(part[at(m)].to_bits(), full[at(m)].to_bits());
            }
        }
    }

    proptest! {
        /// Interleaved pushes (never below the last key taken) and pops come out in key order.
        #[test]
        fn the_radix_heap_pops_in_key_order(
            steps in proptest::collection::vec((0u64..1 << 40, 0u8..3), 1..300),
        ) {
            let mut heap = RadixHeap::default();
            heap.clear();
            let mut keys: Vec<u64> = Vec::new();
            let mut waiting: Vec<u64> = Vec::new();
            let mut last = 0u64;
            for (offset, pops) in &steps {
                let key = last + offset;
                heap.push(key, keys.len() as u32);
                keys.push(key);
                waiting.push(key);
                for _ in 0..*pops {
                    let want = waiting.iter().copied().min();
                    let got = heap.pop().map(|item| keys[item as usize]);
                    prop_assert_eq!(got, want);
                    if let Some(k) = want {
                        let at = waiting.iter().position(|w| *w == k).expect("present");
                        waiting.swap_remove(at);
                        last = k;
                    }
                }
            }
        }
    }

    #[test]
    fn the_path_keeps_away_from_a_wall_when_room_allows() {
        // A lethal wall along y = 0; the gradient near it makes the cheapest path run higher.
        let (w, h) = (60, 20);
        let mut grid = Grid::new(
            GridGeometry {
                width: w,
                height: h,
                resolution_m: 0.1,
                origin: Point2::new(0.0, 0.0),
            },
            0i8,
        );
        for x in 0..w {
            *grid.get_mut(x, 0).expect("inside") = 100;
        }
        let map = Costmap::from_map(&grid, &crate::CostmapConfig::default());
        let mut planner = Planner::new(PlannerConfig::default());
        let plan = planner
            .plan(&map, centre(&map, 2, 5), centre(&map, 57, 5))
            .expect("open ground");
        let highest = plan.cells.iter().map(|c| c.y).max().expect("cells");
        assert!(
            highest >= 8,
            "the path stayed at row {highest}, 0.8 m from the wall"
        );
    }

    #[test]
    fn a_rover_can_back_out_of_an_inscribed_cell_but_not_plan_into_one() {
        let mut costs = vec![0u8; 20 * 5];
        // The rover's cell and the two beside it are too close to something.
        costs[..3].fill(INSCRIBED);
        let map = costmap(20, 5, costs);
        let mut planner = Planner::new(PlannerConfig::default());
        assert!(
            planner
                .plan(&map, centre(&map, 0, 0), centre(&map, 15, 3))
                .is_ok()
        );
        assert!(matches!(
            planner.plan(&map, centre(&map, 15, 3), centre(&map, 1, 0)),
            Err(PlanError::GoalBlocked { .. })
        ));
    }

    #[test]
    fn a_walled_in_goal_is_reported_without_a_path() {
        let mut costs = vec![0u8; 30 * 30];
        for i in 0..30 {
            costs[15 * 30 + i] = LETHAL;
        }
        let map = costmap(30, 30, costs);
        let mut planner = Planner::new(PlannerConfig::default());
        let err = planner
            .plan(&map, centre(&map, 5, 5), centre(&map, 5, 25))
            .expect_err("the wall spans the map");
        assert!(matches!(err, PlanError::NoPath { expanded } if expanded == 15 * 30));
    }
}
