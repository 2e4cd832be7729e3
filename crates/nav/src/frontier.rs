//! Frontiers (Yamauchi, "A Frontier-Based Approach for Autonomous Exploration", CIRA 1997):
//! known free cells beside unknown ones, where driving up and looking adds to the map. On a
//! planetary rover "known" means judged by the ground sensor too: ground the 2D lidar alone
//! saw free ([`UNJUDGED`]) may be a crater bowl, so it is explored like unknown ground.
//! Frontier cells the rover cannot stand on (inscribed in the costmap) are left out, and
//! 8-connected frontier cells are grouped so each group is one candidate target.
//! [`FrontierTracker`] finds the same frontiers map after map, examining only what changed.

use crate::costmap::{Costmap, MAX_PASSABLE, OCCUPIED_THRESHOLD};
use realms_core::{Cell, Grid, GridGeometry, Point2};

/// A map value for ground the 2D lidar saw free but no ground sensor has judged yet: its
/// beams pass over crater bowls and rocks lower than its plane, so it cannot tell. The
/// planner drives on it as on free ground; exploration counts it as still to be seen, so a
/// rover goes to look at it with its depth camera. (Occupancy 1 %: any reader that does not
/// know the value takes it for free ground.)
pub const UNJUDGED: i8 = 1;

/// Whether a map value leaves the ground still to be explored: unknown, or only seen free
/// by the lidar ([`UNJUDGED`]).
pub fn still_to_explore(v: i8) -> bool {
    v < 0 || v == UNJUDGED
}

/// One connected stretch of frontier.
#[derive(Clone, Debug, PartialEq)]
pub struct Frontier {
    /// Its cells.
    pub cells: Vec<Cell>,
    /// Their mean position.
    pub centroid: Point2,
    /// How many of them border unknown ground; the rest border only ground the lidar saw
    /// ([`UNJUDGED`]), where driving up shows the depth camera's verdict and no new map.
    pub beside_unknown: usize,
}

/// Every frontier of `map` (-1 unknown, 0..=100 occupancy, [`UNJUDGED`]) with at least
/// `min_cells` cells, largest first; `costmap` must share the map's geometry. Cells still to
/// explore that `seen_by_others` (per map cell, if given) marks are not worth driving to: a
/// peer has mapped them.
///
/// This examines every cell; [`FrontierTracker`] gives the same answer examining only what
/// changed since its last call.
pub fn detect(
    map: &Grid<i8>,
    costmap: &Costmap,
    min_cells: usize,
    seen_by_others: Option<&[bool]>,
) -> Vec<Frontier> {
    let geo = *map.geometry();
    let inputs = Inputs::new(map, costmap, seen_by_others);
    let flags: Vec<bool> = (0..geo.len()).map(|i| inputs.is_frontier(i)).collect();
    let mut visited = vec![false; geo.len()];
    group(&inputs, &flags, &mut visited, 0..geo.len(), min_cells)
}

/// What decides whether a cell is a frontier, borrowed from the caller.
struct Inputs<'a> {
    geo: GridGeometry,
    map: &'a [i8],
    costs: &'a [u8],
    seen: Option<&'a [bool]>,
}

impl<'a> Inputs<'a> {
    fn new(map: &'a Grid<i8>, costmap: &'a Costmap, seen: Option<&'a [bool]>) -> Self {
        let geo = map.geometry();
        Inputs {
            geo: *geo,
            map: map.cells(),
            costs: costmap.costs(),
            seen,
        }
    }

    /// Whether a peer has mapped cell `j`.
    fn seen_by_peer(&self, j: usize) -> bool {
        self.seen.is_some_and(|s| s[j])
    }

    /// Still to explore, and no peer has mapped it.
    fn open(&self, j: usize) -> bool {
        still_to_explore(self.map[j]) && !self.seen_by_peer(j)
    }

    /// Whether any of cell `i`'s four neighbours satisfies `pred`.
    fn any_neighbour(&self, i: usize, pred: impl Fn(usize) -> bool) -> bool {
        let (w, h) = (self.geo.width, self.geo.height);
        let (x, y) = (i % w, i / w);
        (x > 0 && pred(i - 1))
            || (x + 1 < w && pred(i + 1))
            || (y > 0 && pred(i - w))
            || (y + 1 < h && pred(i + w))
    }

    /// Beside unknown ground no peer has mapped (4-connected).
    fn beside_unknown(&self, i: usize) -> bool {
        self.any_neighbour(i, |j| self.map[j] < 0 && !self.seen_by_peer(j))
    }

    /// Known free, passable, and beside open ground (4-connected): judged ground beside
    /// unknown or unjudged ground, unjudged ground beside unknown ground.
    fn is_frontier(&self, i: usize) -> bool {
        let v = self.map[i];
        if !(0..OCCUPIED_THRESHOLD).contains(&v) || self.costs[i] > MAX_PASSABLE {
            return false;
        }
        if v == UNJUDGED {
            self.beside_unknown(i)
        } else {
            self.any_neighbour(i, |j| self.open(j))
        }
    }
}

/// Groups the cells `flags` marks into 8-connected frontiers of at least `min_cells`, largest
/// first. `seeds` must hold every marked cell in increasing order (it may hold others), so
/// each group is walked from its lowest cell whichever caller asks. `visited` (one per cell,
/// all false) is scratch, left all false again.
fn group(
    inputs: &Inputs,
    flags: &[bool],
    visited: &mut [bool],
    seeds: impl Iterator<Item = usize>,
    min_cells: usize,
) -> Vec<Frontier> {
    let (w, h) = (inputs.geo.width, inputs.geo.height);
    let mut walked = Vec::new();
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for seed in seeds {
        if visited[seed] || !flags[seed] {
            continue;
        }
        visited[seed] = true;
        stack.push(seed);
        let mut cells = Vec::new();
        while let Some(i) = stack.pop() {
            walked.push(i);
            let (x, y) = (i % w, i / w);
            cells.push(Cell { x, y });
            for dy in -1isize..=1 {
                for dx in -1isize..=1 {
                    let (nx, ny) = (x as isize + dx, y as isize + dy);
                    if (dx, dy) == (0, 0)
                        || nx < 0
                        || ny < 0
                        || nx >= w as isize
                        || ny >= h as isize
                    {
                        continue;
                    }
                    let j = ny as usize * w + nx as usize;
                    if !visited[j] && flags[j] {
                        visited[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if cells.len() >= min_cells {
            let n = cells.len() as f64;
            let (sx, sy) = cells.iter().fold((0.0, 0.0), |(sx, sy), c| {
                let p = inputs.geo.cell_center(*c);
                (sx + p.x_m, sy + p.y_m)
            });
            cells.sort();
            let beside_unknown = cells
                .iter()
                .filter(|c| inputs.beside_unknown(c.y * w + c.x))
                .count();
            out.push(Frontier {
                cells,
                centroid: Point2::new(sx / n, sy / n),
                beside_unknown,
            });
        }
    }
    for i in walked {
        visited[i] = false;
    }
    out.sort_by(|a, b| {
        b.cells
            .len()
            .cmp(&a.cells.len())
            .then(a.cells[0].cmp(&b.cells[0]))
    });
    out
}

/// Frontier detection that carries its work from one map to the next, in the manner of
/// the incremental detectors of Keidar and Kaminka ("Efficient frontier detection for robot
/// exploration", IJRR 33, 2014): a cell's frontier flag is re-examined only where the map,
/// the costmap or the peers' coverage changed under it or beside it, and grouping walks the
/// frontier cells alone, never the whole map. A new map extent (the map grew) starts afresh.
///
/// The answer is always the one [`detect`] gives for the same inputs.
#[derive(Clone, Debug, Default)]
pub struct FrontierTracker {
    geo: Option<GridGeometry>,
    map: Vec<i8>,
    costs: Vec<u8>,
    seen: Vec<bool>,
    /// All false: the peers' coverage when the caller gives none.
    nobody: Vec<bool>,
    flags: Vec<bool>,
    /// Every flagged cell, and perhaps some no longer flagged (dropped when grouping).
    listed: Vec<usize>,
    on_list: Vec<bool>,
    visited: Vec<bool>,
    examined: usize,
}

impl FrontierTracker {
    /// A tracker that has seen no map yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Frontier-flag examinations the last [`update`](Self::update) made (a cell beside
    /// several changes counts once for each).
    pub fn last_examined(&self) -> usize {
        self.examined
    }

    /// The frontiers of `map` (as [`detect`] defines them), updating only what changed
    /// since the previous call.
    pub fn update(
        &mut self,
        map: &Grid<i8>,
        costmap: &Costmap,
        min_cells: usize,
        seen_by_others: Option<&[bool]>,
    ) -> Vec<Frontier> {
        let geo = *map.geometry();
        let inputs = Inputs::new(map, costmap, seen_by_others);
        let n = geo.len();
        if self.geo != Some(geo) {
            self.geo = Some(geo);
            self.map = inputs.map.to_vec();
            self.costs = inputs.costs.to_vec();
            self.nobody = vec![false; n];
            self.seen = seen_by_others.map_or_else(|| self.nobody.clone(), <[bool]>::to_vec);
            self.flags = (0..n).map(|i| inputs.is_frontier(i)).collect();
            self.listed = (0..n).filter(|&i| self.flags[i]).collect();
            self.on_list = self.flags.clone();
            self.visited = vec![false; n];
            self.examined = n;
        } else {
            let seen = seen_by_others.unwrap_or(&self.nobody);
            let w = geo.width;
            let mut examined = 0;
            // Whole runs of unchanged cells are passed over by comparing slices, which the
            // compiler turns into block compares; only a run with a change is walked.
            const RUN: usize = 64;
            for start in (0..n).step_by(RUN) {
                let r = start..(start + RUN).min(n);
                if inputs.map[r.clone()] == self.map[r.clone()]
                    && inputs.costs[r.clone()] == self.costs[r.clone()]
                    && seen[r.clone()] == self.seen[r.clone()]
                {
                    continue;
                }
                for i in r {
                    let (m, c, s) = (inputs.map[i], inputs.costs[i], seen[i]);
                    let own = m != self.map[i] || c != self.costs[i];
                    // The neighbours' flags depend on whether this cell is unknown or
                    // unjudged, and on whether a peer has seen it.
                    let neighbours = m != self.map[i] || s != self.seen[i];
                    // Kept even where it changes nothing (peers' coverage of known ground),
                    // so the run compares equal next time.
                    self.seen[i] = s;
                    if !own && !neighbours {
                        continue;
                    }
                    self.map[i] = m;
                    self.costs[i] = c;
                    // A cell's flag depends on its own state and on its four neighbours'
                    // values and coverage; a change of those touches their flags.
                    let (x, y) = (i % w, i / w);
                    let mut touch = |j: usize| {
                        examined += 1;
                        let f = inputs.is_frontier(j);
                        self.flags[j] = f;
                        if f && !self.on_list[j] {
                            self.on_list[j] = true;
                            self.listed.push(j);
                        }
                    };
                    touch(i);
                    if neighbours {
                        if x > 0 {
                            touch(i - 1);
                        }
                        if x + 1 < w {
                            touch(i + 1);
                        }
                        if y > 0 {
                            touch(i - w);
                        }
                        if y + 1 < geo.height {
                            touch(i + w);
                        }
                    }
                }
            }
            self.examined = examined;
        }
        let flags = &self.flags;
        let on_list = &mut self.on_list;
        self.listed.retain(|&i| {
            on_list[i] = flags[i];
            flags[i]
        });
        self.listed.sort_unstable();
        group(
            &inputs,
            &self.flags,
            &mut self.visited,
            self.listed.iter().copied(),
            min_cells,
        )
    }
}

/// The map coarsened `factor` times: a coarse cell is known where at least half its cells
/// are known and not [`still_to_explore`] (what a rover tells its peers it has seen).
pub fn coarse_known(map: &Grid<i8>, factor: usize) -> Grid<bool> {
    let f = factor.max(1);
    let g = *map.geometry();
    let geo = GridGeometry {
        width: g.width.div_ceil(f),
        height: g.height.div_ceil(f),
        resolution_m: g.resolution_m * f as f64,
        origin: g.origin,
    };
    let v = map.cells();
    let mut cells = Vec::with_capacity(geo.len());
    for cy in 0..geo.height {
        for cx in 0..geo.width {
            let (mut known, mut all) = (0, 0);
            for y in cy * f..((cy + 1) * f).min(g.height) {
                for x in cx * f..((cx + 1) * f).min(g.width) {
                    all += 1;
                    known += usize::from(!still_to_explore(v[y * g.width + x]));
                }
            }
            cells.push(2 * known >= all);
        }
    }
    Grid::from_cells(geo, cells).expect("one value per coarse cell")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CostmapConfig;

    /// 60 x 40 cells of 10 cm, unknown but for the block `xs` x `ys`, which holds `value`.
    fn map_with(xs: std::ops::Range<usize>, ys: std::ops::Range<usize>, value: i8) -> Grid<i8> {
        let g = GridGeometry {
            width: 60,
            height: 40,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut map = Grid::new(g, -1i8);
        for y in ys {
            for x in xs.clone() {
                *map.get_mut(x, y).expect("inside") = value;
            }
        }
        map
    }

    #[test]
    fn the_open_edges_of_a_walled_room_are_frontiers_and_its_walls_are_not() {
        // 60 x 40 cells: the left 30 columns known; a wall closes the bottom of the known
        // part; a speck of unknown inside the known part is too small to count.
        let mut map = map_with(0..30, 0..40, 0);
        for x in 0..30 {
            *map.get_mut(x, 0).expect("inside") = 100;
        }
        *map.get_mut(15, 20).expect("inside") = -1;
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        let frontiers = detect(&map, &cm, 8, None);
        assert_eq!(frontiers.len(), 1, "{frontiers:?}");
        let f = &frontiers[0];
        // Column 29, from the first row clear of the wall's inscribed band (rows 1-3 lie
        // within 0.32 m of the wall's row 0) to the top.
        assert!(f.cells.iter().all(|c| c.x == 29), "{:?}", f.cells);
        assert_eq!(f.cells.len(), 40 - 4);
        assert!((f.centroid.x_m - 2.95).abs() < 1e-9);
    }

    #[test]
    fn ground_only_the_lidar_saw_is_explored_until_judged() {
        // Columns 0-9 judged free, 10-29 only seen free by the lidar, 30-59 unknown.
        let mut map = map_with(0..30, 0..40, UNJUDGED);
        for y in 0..40 {
            for x in 0..10 {
                *map.get_mut(x, y).expect("inside") = 0;
            }
        }
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        let mut frontiers = detect(&map, &cm, 8, None);
        frontiers.sort_by_key(|f| f.cells[0].x);
        assert_eq!(frontiers.len(), 2, "{frontiers:?}");
        // The judged edge faces unjudged ground: no new map there, only the ground's verdict.
        assert!(frontiers[0].cells.iter().all(|c| c.x == 9));
        assert_eq!(frontiers[0].beside_unknown, 0);
        // The lidar's edge faces unknown ground, judged or not.
        assert!(frontiers[1].cells.iter().all(|c| c.x == 29));
        assert_eq!(frontiers[1].beside_unknown, 40);
        // Once all of it is judged, only the edge to the unknown is left.
        let judged = map_with(0..30, 0..40, 0);
        let cm = Costmap::from_map(&judged, &CostmapConfig::default());
        let frontiers = detect(&judged, &cm, 8, None);
        assert_eq!(frontiers.len(), 1);
        assert!(frontiers[0].cells.iter().all(|c| c.x == 29));
        // A peer that judged the unjudged part takes the judged edge away too.
        let peer = coarse_known(&map_with(0..60, 0..40, 0), 5);
        let seen: Vec<bool> = map
            .iter()
            .map(|(c, _)| {
                *peer
                    .at_world(map.geometry().cell_center(c))
                    .expect("same extent")
            })
            .collect();
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        assert!(detect(&map, &cm, 8, Some(&seen)).is_empty());
    }

    #[test]
    fn ground_a_peer_has_seen_is_no_frontier() {
        let map = map_with(0..30, 0..40, 0);
        let g = *map.geometry();
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        // A peer knows the lower half of the unknown side, coarsely.
        let peer = map_with(0..60, 0..20, 0);
        let coarse = coarse_known(&peer, 5);
        let seen: Vec<bool> = map
            .iter()
            .map(|(c, _)| *coarse.at_world(g.cell_center(c)).expect("same extent"))
            .collect();
        let frontiers = detect(&map, &cm, 8, Some(&seen));
        assert_eq!(frontiers.len(), 1);
        assert!(frontiers[0].cells.iter().all(|c| c.x == 29 && c.y >= 20));
        assert_eq!(frontiers[0].cells.len(), 20);
    }
}
