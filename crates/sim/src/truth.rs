//! Ground truth the rest of the project is graded against, derived from the terrain and the
//! rover's limits: where a rover may drive, what a perfect 2D lidar would see, and which area
//! counts as explorable.

use crate::scenario::Scenario;
use crate::terrain::{SurfaceKind, Terrain};
use realms_core::msgs::OccupancyGrid;
use realms_core::{Cell, Grid};
use serde::Serialize;
use std::collections::VecDeque;

/// Traversability of one cell for the scenario's rover.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[repr(u8)]
pub enum TruthCell {
    /// The rover can drive here.
    Free = 0,
    /// Something the rover would hit: a wall, the lander, a rock above its step limit.
    Obstacle = 1,
    /// Ground it must not enter: a crater interior or a slope beyond its limit.
    Hazard = 2,
}

/// Ground-truth maps of a generated arena.
#[derive(Clone, Debug)]
pub struct GroundTruth {
    /// Where the rover may drive.
    pub traversability: Grid<TruthCell>,
    /// Cells a perfect 2D lidar at the rover's mount height sees as obstacles.
    pub lidar_obstacles: Grid<bool>,
    /// Free cells connected to the rovers' start: the area a mission should map.
    pub explorable: Grid<bool>,
    /// Area of `explorable`, square metres.
    pub explorable_area_m2: f64,
}

impl GroundTruth {
    /// The map a perfect sensor suite would build, in ROS occupancy values with the hazard
    /// value of realms' maps: lidar obstacles occupied; craters, steep slopes and rocks the
    /// lidar passes over hazard; explorable ground free; the rest unknown.
    pub fn perfect_map(&self) -> Grid<i8> {
        let trav = self.traversability.cells();
        let lidar = self.lidar_obstacles.cells();
        let explorable = self.explorable.cells();
        let cells = (0..trav.len())
            .map(|i| {
                if lidar[i] {
                    OccupancyGrid::OCCUPIED
                } else if trav[i] != TruthCell::Free {
                    OccupancyGrid::HAZARD
                } else if explorable[i] {
                    OccupancyGrid::FREE
                } else {
                    OccupancyGrid::UNKNOWN
                }
            })
            .collect();
        Grid::from_cells(*self.traversability.geometry(), cells)
            .expect("the truth grids share one geometry")
    }

    /// Derives ground truth from a terrain and the rover limits of its scenario.
    ///
    /// - Obstacle: walls, the lander, and rocks standing more than `max_step_m` above the floor.
    /// - Hazard: the interior of every crater whose inner wall is steeper than `max_slope_deg`,
    ///   and any floor steeper than that over a two-cell baseline.
    /// - Lidar obstacle: anything standing at least the lidar's mount height above the floor
    ///   (crater bowls never are: a 2D lidar does not see negative obstacles).
    /// - Explorable: free cells 4-connected to a rover's start cell.
    pub fn derive(terrain: &Terrain, scenario: &Scenario) -> GroundTruth {
        let g = *terrain.geometry();
        let r = &scenario.rovers;
        let max_slope = r.max_slope_deg.to_radians().tan();
        let h = terrain.heights.cells();
        let f = terrain.floor.cells();
        let kind = terrain.kind.cells();
        let mut trav = Grid::new(g, TruthCell::Free);
        let lidar_h = r.lidar.mount_height_m as f32;
        let mut lidar = Grid::new(g, false);
        let step = 2usize;
        let run = 2.0 * step as f64 * g.resolution_m;
        for y in 0..g.height {
            for x in 0..g.width {
                let i = y * g.width + x;
                let above = h[i] - f[i];
                lidar.cells_mut()[i] = above >= lidar_h;
                let blocked = matches!(kind[i], SurfaceKind::Wall | SurfaceKind::Lander)
                    || above as f64 > r.max_step_m;
                let slope = {
                    let (xl, xr) = (x.saturating_sub(step), (x + step).min(g.width - 1));
                    let (yd, yu) = (y.saturating_sub(step), (y + step).min(g.height - 1));
                    let gx = (f[y * g.width + xr] - f[y * g.width + xl]) as f64 / run;
                    let gy = (f[yu * g.width + x] - f[yd * g.width + x]) as f64 / run;
                    gx.hypot(gy)
                };
                trav.cells_mut()[i] = if blocked {
                    TruthCell::Obstacle
                } else if slope > max_slope {
                    TruthCell::Hazard
                } else {
                    TruthCell::Free
                };
            }
        }
        for c in terrain
            .craters
            .iter()
            .filter(|c| c.max_inner_slope() > max_slope)
        {
            let reach = (c.radius_m / g.resolution_m).ceil() as usize + 1;
            let Some(centre) = g.world_to_cell(c.center) else {
                continue;
            };
            for y in centre.y.saturating_sub(reach)..(centre.y + reach).min(g.height) {
                for x in centre.x.saturating_sub(reach)..(centre.x + reach).min(g.width) {
                    let cell = Cell { x, y };
                    let t = &mut trav.cells_mut()[g.index(cell)];
                    if *t == TruthCell::Free
                        && g.cell_center(cell).distance_m(c.center) < c.radius_m
                    {
                        *t = TruthCell::Hazard;
                    }
                }
            }
        }

        let mut explorable = Grid::new(g, false);
        let mut queue = VecDeque::new();
        for start in &terrain.rover_starts {
            if let Some(c) = g.world_to_cell(start.position()) {
                queue.push_back(c);
            }
        }
        while let Some(c) = queue.pop_front() {
            let i = g.index(c);
            if explorable.cells()[i] || trav.cells()[i] != TruthCell::Free {
                continue;
            }
            explorable.cells_mut()[i] = true;
            let (x, y) = (c.x, c.y);
            if x > 0 {
                queue.push_back(Cell { x: x - 1, y });
            }
            if y > 0 {
                queue.push_back(Cell { x, y: y - 1 });
            }
            if x + 1 < g.width {
                queue.push_back(Cell { x: x + 1, y });
            }
            if y + 1 < g.height {
                queue.push_back(Cell { x, y: y + 1 });
            }
        }
        let count = explorable.cells().iter().filter(|e| **e).count();
        GroundTruth {
            traversability: trav,
            lidar_obstacles: lidar,
            explorable,
            explorable_area_m2: count as f64 * g.resolution_m * g.resolution_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_arena_truth_is_plausible() {
        let s = Scenario::default();
        let t = Terrain::generate(&s);
        let truth = GroundTruth::derive(&t, &s);
        // Most of a 50 x 36 m hall is explorable; craters, rocks and walls take the rest.
        let total = 50.0 * 36.0;
        assert!(
            truth.explorable_area_m2 > 0.8 * total && truth.explorable_area_m2 < 0.97 * total,
            "{} m^2",
            truth.explorable_area_m2
        );
        for c in &t.craters {
            assert_eq!(
                truth.traversability.at_world(c.center),
                Some(&TruthCell::Hazard)
            );
            assert_eq!(truth.lidar_obstacles.at_world(c.center), Some(&false));
            assert_eq!(truth.explorable.at_world(c.center), Some(&false));
        }
        for start in &t.rover_starts {
            assert_eq!(truth.explorable.at_world(start.position()), Some(&true));
        }
        for b in t.boulders.iter().filter(|b| b.height_m > 0.35) {
            assert_eq!(truth.lidar_obstacles.at_world(b.center), Some(&true));
            assert_eq!(
                truth.traversability.at_world(b.center),
                Some(&TruthCell::Obstacle)
            );
        }
    }
}
