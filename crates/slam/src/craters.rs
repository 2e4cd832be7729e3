//! Craters inferred from the hazard layer. Seen from outside, a crater shows the depth camera
//! its far inner wall, a crescent of hazard cells; its near inner wall hides behind the rim,
//! and the lidar passes over the bowl and calls it free. A circle fitted to a crescent that
//! goes far enough round gives the crater's rim, and the whole disc inside it is hazard: a
//! rover that enters the bowl cannot be sure to climb out of it.
//!
//! The circle is the algebraic fit of Kåsa ([`CircleFit`]) to the crescent's cells; the disc
//! reaches the crescent's farthest cell from its centre.
//!
//! Not the rovers' default (`--variant crater-discs` of `realms bench slam`): the camera sees
//! a large crater's far wall in pieces of 60-110 degrees, each too short an arc to be sure
//! of, so the large craters go unfound; taking short thin arcs too marked many wrong discs
//! (BENCHMARKS.md, sixty-first session). With the hollows marked first ([`crate::hollows`])
//! a crater seen from round it is a filled disc; fitted to its outline
//! ([`CraterDiscs::fit_outline`]) it gives the rim, but other blobs' outlines fit wrong
//! circles (BENCHMARKS.md, sixty-second session). A disc the layer judged more than a share
//! of safe is refused ([`CraterDiscs::max_safe_share`]): it wins back part of that
//! precision, not all (BENCHMARKS.md, "Where the crater cells near the paths are missed").

use crate::occupancy::CellState;
use realms_core::geometry::CircleFit;
use realms_core::{Cell, Grid, Point2};

/// Which clusters of hazard cells count as a crater's wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CraterDiscs {
    /// Fewest cells in a cluster.
    pub min_cells: usize,
    /// Smallest rim radius taken for a crater, metres.
    pub min_radius_m: f64,
    /// Largest rim radius taken for a crater, metres, both as fitted and as marked (to the
    /// wall's farthest cell).
    pub max_radius_m: f64,
    /// How far round its centre the cluster must reach (the angle it spans), radians: a
    /// straight slope's edge or a rock's face fits a circle too, but covers little of it.
    pub min_span_rad: f64,
    /// The cells' spread about the fitted circle, as a share of its radius, at most: a
    /// crater's wall is a ring, a blob of rocks is not.
    pub max_spread: f64,
    /// The circle is fitted to the cluster's outline (its cells beside a cell not hazard)
    /// rather than to all its cells: with the hollows marked ([`crate::hollows`]) a crater
    /// seen from round it is a filled disc, not a crescent, and its outline is the rim.
    pub fit_outline: bool,
    /// Share of the disc's cells the layer judged safe, at most: a crater's bowl was seen
    /// hazardous wherever it was seen, while a circle fitted to a blob of rocks or a slope's
    /// edge takes in open floor the camera looked at and passed (`1.0` asks nothing).
    pub max_safe_share: f64,
}

impl Default for CraterDiscs {
    fn default() -> Self {
        CraterDiscs {
            min_cells: 20,
            min_radius_m: 0.5,
            max_radius_m: 4.0,
            min_span_rad: 150f64.to_radians(),
            max_spread: 0.3,
            fit_outline: false,
            max_safe_share: 1.0,
        }
    }
}

/// A crater found in a hazard layer: its centre and the radius its disc is marked to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crater {
    /// Centre, in the layer's frame.
    pub centre: Point2,
    /// Radius of the marked disc, metres.
    pub radius_m: f64,
}

/// Finds the craters among the hazard (`Occupied`) clusters of `states` and marks each one's
/// disc hazard; returns them. Cells where `wall` holds (at their centres: what the lidar sees
/// as an obstacle, and beside it) join no cluster, so a crater's wall is not taken together
/// with the hazard at the foot of the hall's walls.
pub fn fill_crater_discs(
    states: &mut Grid<CellState>,
    cfg: &CraterDiscs,
    wall: impl Fn(Point2) -> bool,
) -> Vec<Crater> {
    let geo = *states.geometry();
    // Asked of hazard cells only: the others join no cluster anyway.
    let walls: Vec<bool> = (states.cells().iter().enumerate())
        .map(|(i, s)| {
            *s == CellState::Occupied
                && wall(geo.cell_center(Cell {
                    x: i % geo.width,
                    y: i / geo.width,
                }))
        })
        .collect();
    let craters: Vec<Crater> = clusters(states, walls)
        .iter()
        .filter(|c| c.len() >= cfg.min_cells)
        .filter_map(|c| crater_of(states, c, cfg))
        .collect();
    for crater in &craters {
        // Clipped to the grid: a crater whose centre lies past the layer's edge still has
        // the part of its disc inside marked.
        for cell in geo.cells_within(crater.centre, crater.radius_m) {
            states.cells_mut()[geo.index(cell)] = CellState::Occupied;
        }
    }
    craters
}

/// The 8-connected clusters of `Occupied` cells outside `walls`, as cell indices.
fn clusters(states: &Grid<CellState>, walls: Vec<bool>) -> Vec<Vec<usize>> {
    let g = states.geometry();
    let (w, h) = (g.width, g.height);
    let cells = states.cells();
    // Cells at a wall count as seen from the start: no cluster takes them in.
    let mut seen = walls;
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for start in 0..cells.len() {
        if seen[start] || cells[start] != CellState::Occupied {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let mut cluster = Vec::new();
        while let Some(i) = stack.pop() {
            cluster.push(i);
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let j = ny as usize * w + nx as usize;
                    if !seen[j] && cells[j] == CellState::Occupied {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        out.push(cluster);
    }
    out
}

/// The crater a cluster is the wall of, if it is one.
fn crater_of(states: &Grid<CellState>, cluster: &[usize], cfg: &CraterDiscs) -> Option<Crater> {
    let g = states.geometry();
    let (w, h) = (g.width, g.height);
    let cells = states.cells();
    let on_outline = |i: usize| {
        let (x, y) = (i % w, i / w);
        x == 0
            || y == 0
            || x + 1 == w
            || y + 1 == h
            || [i - 1, i + 1, i - w, i + w]
                .iter()
                .any(|&j| cells[j] != CellState::Occupied)
    };
    let points: Vec<Point2> = cluster
        .iter()
        .filter(|&&i| !cfg.fit_outline || on_outline(i))
        .map(|&i| {
            g.cell_center(Cell {
                x: i % g.width,
                y: i / g.width,
            })
        })
        .collect();
    let fit = CircleFit::of(&points)?;
    let (centre, radius_m) = (fit.centre(), fit.radius_m);
    if !(cfg.min_radius_m..=cfg.max_radius_m).contains(&radius_m) {
        return None;
    }
    if fit.rms_off_m(&points) > cfg.max_spread * radius_m {
        return None;
    }
    let mut angles: Vec<f64> = points
        .iter()
        .map(|p| (p.y_m - centre.y_m).atan2(p.x_m - centre.x_m))
        .collect();
    angles.sort_by(f64::total_cmp);
    let largest_gap = angles.windows(2).map(|w| w[1] - w[0]).fold(
        angles[0] + std::f64::consts::TAU - angles[angles.len() - 1],
        f64::max,
    );
    if std::f64::consts::TAU - largest_gap < cfg.min_span_rad {
        return None;
    }
    let reach =
        (points.iter().map(|p| p.distance_m(centre))).fold(0.0, f64::max) + g.resolution_m / 2.0;
    if reach > cfg.max_radius_m {
        return None;
    }
    // A share of 1 asks nothing: the disc's cells are not counted.
    let bowl_not_seen_safe = cfg.max_safe_share >= 1.0 || {
        let (safe, all) = g
            .cells_within(centre, reach)
            .fold((0usize, 0usize), |(s, n), c| {
                (s + usize::from(cells[g.index(c)] == CellState::Free), n + 1)
            });
        safe as f64 <= cfg.max_safe_share * all as f64
    };
    bowl_not_seen_safe.then_some(Crater {
        centre,
        radius_m: reach,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_layers::{layer, set, state_at};

    /// Marks hazard every cell whose centre `inside` holds.
    fn mark(g: &mut Grid<CellState>, inside: impl Fn(Point2) -> bool) {
        set(g, CellState::Occupied, inside);
    }

    #[test]
    fn a_crescent_of_a_craters_far_wall_marks_its_whole_disc() {
        // A crater of 2 m radius at (5, 5): its inner wall from 1.3 to 2.0 m off the centre,
        // seen only on the far side (x > 4.5) from a rover west of it.
        let (c, r) = (Point2::new(5.0, 5.0), 2.0);
        let mut g = layer();
        mark(&mut g, |p| {
            let d = p.distance_m(c);
            d > 1.3 && d <= r && p.x_m > 4.5
        });
        let craters = fill_crater_discs(&mut g, &CraterDiscs::default(), |_| false);
        assert_eq!(craters.len(), 1, "{craters:?}");
        let found = craters[0];
        assert!(found.centre.distance_m(c) < 0.15, "{found:?}");
        assert!((found.radius_m - r).abs() < 0.15, "{found:?}");
        // The near wall behind the rim and the bowl are marked now; outside the rim is not.
        let at = |x: f64, y: f64| state_at(&g, x, y);
        assert_eq!(at(3.35, 5.05), CellState::Occupied);
        assert_eq!(at(5.05, 5.05), CellState::Occupied);
        assert_eq!(at(2.75, 5.05), CellState::Unknown);
    }

    #[test]
    fn a_crater_beside_a_wall_is_found_once_the_walls_foot_is_left_out() {
        // The crater's far wall as above, and a band of hazard along a wall at x = 7.2 m
        // that touches it (the wall's foot, seen as a step).
        let (c, r) = (Point2::new(5.0, 5.0), 2.0);
        let crescent_and_foot = |p: Point2| {
            let d = p.distance_m(c);
            (d > 1.3 && d <= r && p.x_m > 4.5) || (6.9..7.3).contains(&p.x_m)
        };
        let mut joined = layer();
        mark(&mut joined, crescent_and_foot);
        assert!(fill_crater_discs(&mut joined, &CraterDiscs::default(), |_| false).is_empty());
        let mut g = layer();
        mark(&mut g, crescent_and_foot);
        let craters = fill_crater_discs(&mut g, &CraterDiscs::default(), |p| p.x_m > 6.85);
        assert_eq!(craters.len(), 1, "{craters:?}");
        assert!(craters[0].centre.distance_m(c) < 0.2, "{craters:?}");
    }

    #[test]
    fn a_filled_disc_is_a_crater_by_its_outline_and_its_crest_ring_is_marked() {
        // A crater of 2 m radius at (5, 5) marked hazard out to 1.8 m but for a bite on the
        // east (the crest ring the camera judged safe, and part of the wall): its cells
        // fill a disc, not a ring.
        let (c, r) = (Point2::new(5.0, 5.0), 2.0);
        let blob = |p: Point2| {
            let d = p.distance_m(c);
            d <= r - 0.2 && !(p.x_m > 6.2 && (p.y_m - 5.0).abs() < 0.5) || (d <= r && p.x_m < 3.5)
        };
        let mut whole = layer();
        mark(&mut whole, blob);
        // Fitted to every cell, a filled disc lies thickly about its circle: refused.
        assert!(
            fill_crater_discs(&mut whole.clone(), &CraterDiscs::default(), |_| false).is_empty()
        );
        let cfg = CraterDiscs {
            fit_outline: true,
            max_spread: 0.15,
            ..CraterDiscs::default()
        };
        let craters = fill_crater_discs(&mut whole, &cfg, |_| false);
        assert_eq!(craters.len(), 1, "{craters:?}");
        assert!(craters[0].centre.distance_m(c) < 0.2, "{craters:?}");
        // The disc reaches the farthest outline cell, at the rim on the west: the ring
        // short of the rim elsewhere and the bite are marked now, outside the rim is not.
        let at = |x: f64, y: f64| state_at(&whole, x, y);
        assert_eq!(at(5.05, 6.85), CellState::Occupied);
        assert_eq!(at(6.75, 5.05), CellState::Occupied);
        assert_eq!(at(7.25, 5.05), CellState::Unknown);
    }

    #[test]
    fn a_circle_round_open_floor_the_camera_judged_is_no_crater_if_so_asked() {
        // The far wall's crescent of a 2 m crater at (5, 5), as in the first test, with the
        // floor inside judged safe: the crescent is the edge of a ridge around open ground.
        let (c, r) = (Point2::new(5.0, 5.0), 2.0);
        let crescent = |p: Point2| {
            let d = p.distance_m(c);
            d > 1.3 && d <= r && p.x_m > 4.5
        };
        let mut g = layer();
        set(&mut g, CellState::Free, |p| p.distance_m(c) <= 1.3);
        mark(&mut g, crescent);
        let checked = CraterDiscs {
            max_safe_share: 0.3,
            ..CraterDiscs::default()
        };
        assert!(fill_crater_discs(&mut g.clone(), &checked, |_| false).is_empty());
        assert_eq!(
            fill_crater_discs(&mut g, &CraterDiscs::default(), |_| false).len(),
            1
        );
        // The same crescent with the bowl unseen (hidden behind the near rim) is a crater
        // under the check too.
        let mut hidden = layer();
        mark(&mut hidden, crescent);
        assert_eq!(fill_crater_discs(&mut hidden, &checked, |_| false).len(), 1);
    }

    #[test]
    fn rocks_and_a_straight_slope_are_no_craters() {
        let mut g = layer();
        // A rock 0.3 m across, and the steep edge of a slope 4 m long.
        mark(&mut g, |p| {
            p.distance_m(Point2::new(2.0, 2.0)) < 0.15
                || ((7.0..7.3).contains(&p.x_m) && (3.0..7.0).contains(&p.y_m))
        });
        let before = g.cells().to_vec();
        assert!(fill_crater_discs(&mut g, &CraterDiscs::default(), |_| false).is_empty());
        assert_eq!(g.cells(), &before[..]);
    }
}
