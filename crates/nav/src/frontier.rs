//! Frontiers (Yamauchi, "A Frontier-Based Approach for Autonomous Exploration", CIRA 1997):
//! known free cells beside unknown ones, where driving up and looking adds to the map.
//! Frontier cells the rover cannot stand on (inscribed in the costmap) are left out, and
//! 8-connected frontier cells are grouped so each group is one candidate target.

use crate::costmap::{Costmap, MAX_PASSABLE, OCCUPIED_THRESHOLD};
use realms_core::{Cell, Grid, GridGeometry, Point2};

/// One connected stretch of frontier.
#[derive(Clone, Debug, PartialEq)]
pub struct Frontier {
    /// Its cells.
    pub cells: Vec<Cell>,
    /// Their mean position.
    pub centroid: Point2,
}

impl Frontier {
    /// Its length, metres (cells times the cell edge, near enough for ranking).
    pub fn length_m(&self, resolution_m: f64) -> f64 {
        self.cells.len() as f64 * resolution_m
    }
}

/// Every frontier of `map` (-1 unknown, 0..=100 occupancy) with at least `min_cells` cells,
/// largest first; `costmap` must share the map's geometry. Unknown cells that `seen_by_others`
/// (per map cell, if given) marks are not worth driving to: a peer has mapped them.
pub fn detect(
    map: &Grid<i8>,
    costmap: &Costmap,
    min_cells: usize,
    seen_by_others: Option<&[bool]>,
) -> Vec<Frontier> {
    let geo = *map.geometry();
    let (w, h) = (geo.width, geo.height);
    let v = map.cells();
    let costs = costmap.costs();
    let open = |j: usize| v[j] < 0 && !seen_by_others.is_some_and(|s| s[j]);
    let is_frontier = |i: usize| -> bool {
        if !(0..OCCUPIED_THRESHOLD).contains(&v[i]) || costs[i] > MAX_PASSABLE {
            return false;
        }
        let (x, y) = (i % w, i / w);
        (x > 0 && open(i - 1))
            || (x + 1 < w && open(i + 1))
            || (y > 0 && open(i - w))
            || (y + 1 < h && open(i + w))
    };
    let mut visited = vec![false; v.len()];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for seed in 0..v.len() {
        if visited[seed] || !is_frontier(seed) {
            continue;
        }
        visited[seed] = true;
        stack.push(seed);
        let mut cells = Vec::new();
        while let Some(i) = stack.pop() {
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
                    if !visited[j] && is_frontier(j) {
                        visited[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        if cells.len() >= min_cells {
            let n = cells.len() as f64;
            let (sx, sy) = cells.iter().fold((0.0, 0.0), |(sx, sy), c| {
                let p = geo.cell_center(*c);
                (sx + p.x_m, sy + p.y_m)
            });
            cells.sort();
            out.push(Frontier {
                cells,
                centroid: Point2::new(sx / n, sy / n),
            });
        }
    }
    out.sort_by(|a, b| {
        b.cells
            .len()
            .cmp(&a.cells.len())
            .then(a.cells[0].cmp(&b.cells[0]))
    });
    out
}

/// The map coarsened `factor` times: a coarse cell is known where at least half its cells
/// are (what a rover tells its peers it has seen).
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
                    known += usize::from(v[y * g.width + x] >= 0);
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
