//! Frontiers (Yamauchi, "A Frontier-Based Approach for Autonomous Exploration", CIRA 1997):
//! known free cells beside unknown ones, where driving up and looking adds to the map.
//! Frontier cells the rover cannot stand on (inscribed in the costmap) are left out, and
//! 8-connected frontier cells are grouped so each group is one candidate target.

use crate::costmap::{Costmap, MAX_PASSABLE, OCCUPIED_THRESHOLD};
use realms_core::{Cell, Grid, Point2};

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
/// largest first; `costmap` must share the map's geometry.
pub fn detect(map: &Grid<i8>, costmap: &Costmap, min_cells: usize) -> Vec<Frontier> {
    let geo = *map.geometry();
    let (w, h) = (geo.width, geo.height);
    let v = map.cells();
    let costs = costmap.costs();
    let is_frontier = |i: usize| -> bool {
        if !(0..OCCUPIED_THRESHOLD).contains(&v[i]) || costs[i] > MAX_PASSABLE {
            return false;
        }
        let (x, y) = (i % w, i / w);
        (x > 0 && v[i - 1] < 0)
            || (x + 1 < w && v[i + 1] < 0)
            || (y > 0 && v[i - w] < 0)
            || (y + 1 < h && v[i + w] < 0)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CostmapConfig;
    use realms_core::GridGeometry;

    #[test]
    fn the_open_edges_of_a_walled_room_are_frontiers_and_its_walls_are_not() {
        // 60 x 40 cells: the left 30 columns known; a wall closes the bottom of the known
        // part; a speck of unknown inside the known part is too small to count.
        let g = GridGeometry {
            width: 60,
            height: 40,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut map = Grid::new(g, -1i8);
        for y in 0..40 {
            for x in 0..30 {
                *map.get_mut(x, y).expect("inside") = if y == 0 { 100 } else { 0 };
            }
        }
        *map.get_mut(15, 20).expect("inside") = -1;
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        let frontiers = detect(&map, &cm, 8);
        assert_eq!(frontiers.len(), 1, "{frontiers:?}");
        let f = &frontiers[0];
        // Column 29, from the first row clear of the wall's inscribed band (rows 1-3 lie
        // within 0.32 m of the wall's row 0) to the top.
        assert!(f.cells.iter().all(|c| c.x == 29), "{:?}", f.cells);
        assert_eq!(f.cells.len(), 40 - 4);
        assert!((f.centroid.x_m - 2.95).abs() < 1e-9);
    }
}
