//! N maps into one: every pair estimated, a spanning tree of the most confident accepted
//! links grown from the first map (the reference), each map placed by chaining its tree
//! path, links outside the tree checked for consistency, and the grids drawn into one.
//!
//! The disagreement rule is safety first: a merged cell is an obstacle if any placed map
//! saw an obstacle there, else a hazard if any saw a hazard, else free if any saw it free,
//! else unknown. A rover planning on the merged map must keep out of anything any rover
//! saw; a stale free cell only costs a detour. The contribution layer records, per cell,
//! which maps observed it (bit `i` for map `i`), which the mission report colours.

use crate::estimate::{Estimate, PriorCheck, PriorWindow, estimate, estimate_with_prior};
use crate::map::{Map, MapCell};
use crate::prepare::{Params, Prepared};
use realms_core::geometry::normalize_angle_rad;
use realms_core::{Cell, Grid, GridGeometry, Point2, Pose2};

/// Most maps one merge takes (the contribution layer is a 64-bit mask per cell).
pub const MAX_MAPS: usize = 64;

/// Why maps could not be merged at all.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MergeError {
    /// Fewer than one map.
    #[error("nothing to merge")]
    NoMaps,
    /// More than [`MAX_MAPS`].
    #[error("{0} maps given; at most {MAX_MAPS} can be merged at once")]
    TooManyMaps(usize),
}

/// One pairwise estimate: the pose of map `moving`'s frame in map `fixed`'s frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    /// Index of the fixed map.
    pub fixed: usize,
    /// Index of the moving map.
    pub moving: usize,
    /// The estimate.
    pub estimate: Estimate,
}

/// Where one map ended up.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// Pose of the map's frame in the reference (first) map's frame; `None` if not placed.
    pub reference_from_map: Option<Pose2>,
    /// Confidence of the placement: the lowest confidence along its chain of links (1 for
    /// the reference).
    pub confidence: f64,
    /// The map it was placed against (its parent in the tree); `None` for the reference
    /// and for maps not placed.
    pub via: Option<usize>,
    /// Why it was not placed.
    pub refusal: Option<String>,
}

/// A link outside the spanning tree that disagrees with the placements it connects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inconsistency {
    /// Fixed map of the link.
    pub fixed: usize,
    /// Moving map of the link.
    pub moving: usize,
    /// Translation disagreement at the moving map's centre, metres.
    pub error_m: f64,
    /// Heading disagreement, radians.
    pub error_rad: f64,
}

/// The result of merging.
#[derive(Clone, Debug)]
pub struct Merged {
    /// One placement per input map, in input order.
    pub placements: Vec<Placement>,
    /// Every pairwise estimate.
    pub links: Vec<Link>,
    /// Accepted links outside the tree that disagree with the tree by more than 3 cells or
    /// 2 degrees.
    pub inconsistencies: Vec<Inconsistency>,
    /// The merged map, axis-aligned in the reference map's frame.
    pub grid: Grid<MapCell>,
    /// Per merged cell, bit `i` set when map `i` observed it.
    pub contribution: Grid<u64>,
}

/// Estimates every pair, places every map it can and draws the merged map.
pub fn merge(maps: &[Map], params: &Params) -> Result<Merged, MergeError> {
    if maps.is_empty() {
        return Err(MergeError::NoMaps);
    }
    if maps.len() > MAX_MAPS {
        return Err(MergeError::TooManyMaps(maps.len()));
    }
    let prepared: Vec<Prepared> = maps.iter().map(|m| Prepared::new(m, params)).collect();
    let mut links = Vec::new();
    for fixed in 0..maps.len() {
        for moving in fixed + 1..maps.len() {
            links.push(Link {
                fixed,
                moving,
                estimate: estimate(&prepared[fixed], &prepared[moving], params),
            });
        }
    }
    let placements = place(maps.len(), &links);
    let inconsistencies = check(&placements, &links, &prepared);
    let poses: Vec<Option<Pose2>> = placements.iter().map(|p| p.reference_from_map).collect();
    let (grid, contribution) = compose(maps, &poses);
    Ok(Merged {
        placements,
        links,
        inconsistencies,
        grid,
        contribution,
    })
}

/// A known-start merge: each map after the first checked against the first at its prior.
#[derive(Clone, Debug, PartialEq)]
pub struct KnownStartMerged {
    /// One check per map after the first, in input order.
    pub checks: Vec<PriorCheck>,
    /// The merged map, axis-aligned in the reference map's frame.
    pub grid: Grid<MapCell>,
    /// Per merged cell, bit `i` set when map `i` observed it.
    pub contribution: Grid<u64>,
}

/// Merges maps whose frames are known to coincide with the first's (rovers that started
/// from known places and map in one shared frame): each is refined against the first
/// within `window` ([`estimate_with_prior`]), placed where the check puts it, and drawn.
/// Each map is checked against the first only, not against the others.
pub fn merge_known_start(
    maps: &[Map],
    params: &Params,
    window: &PriorWindow,
) -> Result<KnownStartMerged, MergeError> {
    if maps.is_empty() {
        return Err(MergeError::NoMaps);
    }
    if maps.len() > MAX_MAPS {
        return Err(MergeError::TooManyMaps(maps.len()));
    }
    let reference = Prepared::new(&maps[0], params);
    let checks: Vec<PriorCheck> = maps[1..]
        .iter()
        .map(|m| {
            estimate_with_prior(
                &reference,
                &Prepared::new(m, params),
                Pose2::IDENTITY,
                window,
                params,
            )
        })
        .collect();
    let poses: Vec<Option<Pose2>> = std::iter::once(Some(Pose2::IDENTITY))
        .chain(checks.iter().map(|c| c.placed))
        .collect();
    let (grid, contribution) = compose(maps, &poses);
    Ok(KnownStartMerged {
        checks,
        grid,
        contribution,
    })
}

/// Grows the maximum-confidence spanning tree from map 0 over the accepted links.
pub fn place(count: usize, links: &[Link]) -> Vec<Placement> {
    let mut placements: Vec<Placement> = (0..count)
        .map(|_| Placement {
            reference_from_map: None,
            confidence: 0.0,
            via: None,
            refusal: None,
        })
        .collect();
    if count == 0 {
        return placements;
    }
    placements[0].reference_from_map = Some(Pose2::IDENTITY);
    placements[0].confidence = 1.0;
    loop {
        // The most confident accepted link from a placed map to an unplaced one (ties to
        // the lower indices, so the result never depends on iteration order).
        let mut best: Option<(f64, usize, usize, Pose2)> = None;
        for l in links {
            let Some(fixed_from_moving) = l.estimate.accepted() else {
                continue;
            };
            let c = l.estimate.confidence;
            let (from, to, to_in_from) = match (
                placements[l.fixed].reference_from_map,
                placements[l.moving].reference_from_map,
            ) {
                (Some(_), None) => (l.fixed, l.moving, fixed_from_moving),
                (None, Some(_)) => (l.moving, l.fixed, fixed_from_moving.inverse()),
                _ => continue,
            };
            if best.is_none_or(|(bc, ..)| c > bc) {
                best = Some((c, from, to, to_in_from));
            }
        }
        let Some((c, from, to, from_from_to)) = best else {
            break;
        };
        let parent = placements[from].clone();
        if let Some(reference_from_parent) = parent.reference_from_map {
            placements[to].reference_from_map = Some(reference_from_parent.compose(&from_from_to));
            placements[to].confidence = c.min(parent.confidence);
            placements[to].via = Some(from);
        }
    }
    for (i, p) in placements.iter_mut().enumerate() {
        if p.reference_from_map.is_some() {
            continue;
        }
        // Say why through the direct link to the reference, or any link of this map.
        let reason = links
            .iter()
            .filter(|l| l.fixed == i || l.moving == i)
            .min_by_key(|l| (l.fixed.min(l.moving), l.fixed.max(l.moving)))
            .and_then(|l| l.estimate.refusal.clone())
            .unwrap_or_else(|| "no confident link to any placed map".into());
        p.refusal = Some(reason);
    }
    placements
}

fn check(placements: &[Placement], links: &[Link], prepared: &[Prepared]) -> Vec<Inconsistency> {
    let mut out = Vec::new();
    for l in links {
        let Some(fixed_from_moving) = l.estimate.accepted() else {
            continue;
        };
        let (pf, pm) = (&placements[l.fixed], &placements[l.moving]);
        if pm.via == Some(l.fixed) || pf.via == Some(l.moving) {
            continue;
        }
        let (Some(rf), Some(rm)) = (pf.reference_from_map, pm.reference_from_map) else {
            continue;
        };
        let via_link = rf.compose(&fixed_from_moving);
        let m = &prepared[l.moving];
        let centre = m.frame_from_grid.transform_point(m.centroid);
        let error_m = via_link
            .transform_point(centre)
            .distance_m(rm.transform_point(centre));
        let error_rad = normalize_angle_rad(via_link.yaw_rad - rm.yaw_rad).abs();
        let cell = m.refine.cell_m;
        if error_m > 3.0 * cell || error_rad > 2f64.to_radians() {
            out.push(Inconsistency {
                fixed: l.fixed,
                moving: l.moving,
                error_m,
                error_rad,
            });
        }
    }
    out
}

/// Which of two cell readings the merged map keeps: obstacle over hazard over free over
/// unknown.
fn rank(c: MapCell) -> u8 {
    match c {
        MapCell::Unknown => 0,
        MapCell::Free => 1,
        MapCell::Hazard => 2,
        MapCell::Occupied => 3,
    }
}

/// Draws the placed maps (pose of each map's frame in the reference frame, `None` to leave
/// it out) into one grid, axis-aligned in the reference frame at the reference map's
/// resolution, with the contribution layer.
pub fn compose(maps: &[Map], reference_from_map: &[Option<Pose2>]) -> (Grid<MapCell>, Grid<u64>) {
    let resolution_m = maps.first().map_or(0.05, |m| m.geometry().resolution_m);
    // Each placed map: reference-from-grid-local transform and its inverse.
    let placed: Vec<(usize, Pose2)> = maps
        .iter()
        .zip(reference_from_map)
        .enumerate()
        .filter_map(|(i, (m, p))| p.map(|p| (i, p.compose(&m.frame_from_grid()))))
        .collect();
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for (i, reference_from_grid) in &placed {
        let g = maps[*i].geometry();
        for (cx, cy) in [
            (0.0, 0.0),
            (g.width_m(), 0.0),
            (0.0, g.height_m()),
            (g.width_m(), g.height_m()),
        ] {
            let p = reference_from_grid.transform_point(Point2::new(cx, cy));
            (x0, y0) = (x0.min(p.x_m), y0.min(p.y_m));
            (x1, y1) = (x1.max(p.x_m), y1.max(p.y_m));
        }
    }
    if placed.is_empty() {
        (x0, y0, x1, y1) = (0.0, 0.0, resolution_m, resolution_m);
    }
    let origin = Point2::new(
        (x0 / resolution_m).floor() * resolution_m,
        (y0 / resolution_m).floor() * resolution_m,
    );
    let geometry = GridGeometry {
        width: (((x1 - origin.x_m) / resolution_m).ceil() as usize).max(1),
        height: (((y1 - origin.y_m) / resolution_m).ceil() as usize).max(1),
        resolution_m,
        origin,
    };
    let mut grid = Grid::new(geometry, MapCell::Unknown);
    let mut contribution = Grid::new(geometry, 0u64);
    for (i, reference_from_grid) in &placed {
        let map = &maps[*i];
        let g = map.geometry();
        let grid_from_reference = reference_from_grid.inverse();
        let (s, c) = grid_from_reference.yaw_rad.sin_cos();
        for y in 0..geometry.height {
            for x in 0..geometry.width {
                let p = geometry.cell_center(Cell { x, y });
                let qx = grid_from_reference.x_m + c * p.x_m - s * p.y_m;
                let qy = grid_from_reference.y_m + s * p.x_m + c * p.y_m;
                if qx < 0.0 || qy < 0.0 {
                    continue;
                }
                let (mx, my) = (
                    (qx / g.resolution_m) as usize,
                    (qy / g.resolution_m) as usize,
                );
                let Some(v) = map.cells.get(mx, my).copied() else {
                    continue;
                };
                if !v.is_known() {
                    continue;
                }
                let k = geometry.index(Cell { x, y });
                contribution.cells_mut()[k] |= 1 << i;
                let cell = &mut grid.cells_mut()[k];
                if rank(v) > rank(*cell) {
                    *cell = v;
                }
            }
        }
    }
    (grid, contribution)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strip(values: &[MapCell], x_m: f64) -> Map {
        let g = GridGeometry {
            width: values.len(),
            height: 1,
            resolution_m: 1.0,
            origin: Point2::new(x_m, 0.0),
        };
        Map::new(Grid::from_cells(g, values.to_vec()).expect("sizes match"))
    }

    #[test]
    fn obstacles_win_and_contributions_are_recorded() {
        use MapCell::*;
        let a = strip(&[Free, Free, Free, Unknown], 0.0);
        let b = strip(&[Occupied, Free, Hazard], 1.0);
        let (grid, contrib) = compose(&[a, b], &[Some(Pose2::IDENTITY), Some(Pose2::IDENTITY)]);
        assert_eq!(grid.cells(), &[Free, Occupied, Free, Hazard]);
        assert_eq!(contrib.cells(), &[0b01, 0b11, 0b11, 0b10]);
        // A map left out draws nothing.
        let a = strip(&[Free], 0.0);
        let b = strip(&[Occupied], 5.0);
        let (grid, contrib) = compose(&[a, b], &[Some(Pose2::IDENTITY), None]);
        assert_eq!(grid.cells(), &[Free]);
        assert_eq!(contrib.cells(), &[1]);
    }

    fn accepted(x_m: f64, confidence: f64) -> Estimate {
        Estimate {
            a_from_b: Some(Pose2::new(x_m, 0.0, 0.0)),
            confidence,
            evidence: Default::default(),
            runner_up_score: 0.0,
            sharpness: 1.0,
            off_two_walls: 1.0,
            refusal: None,
            stats: Default::default(),
            hypotheses: Vec::new(),
            verified: Vec::new(),
            imprecise_rival: None,
        }
    }

    #[test]
    fn the_tree_takes_the_most_confident_links() {
        let mut refused = accepted(0.0, 0.0);
        refused.refusal = Some("ambiguous".into());
        let links = vec![
            Link {
                fixed: 0,
                moving: 1,
                estimate: accepted(10.0, 0.5),
            },
            Link {
                fixed: 0,
                moving: 2,
                estimate: refused,
            },
            // 1 <- 2 is more confident than 0 <- 1 and is the only way to 2.
            Link {
                fixed: 1,
                moving: 2,
                estimate: accepted(3.0, 0.9),
            },
            Link {
                fixed: 0,
                moving: 3,
                estimate: accepted(1.0, 0.2),
            },
        ];
        let p = place(5, &links);
        assert_eq!(p[1].reference_from_map, Some(Pose2::new(10.0, 0.0, 0.0)));
        assert_eq!(p[2].reference_from_map, Some(Pose2::new(13.0, 0.0, 0.0)));
        assert_eq!(p[2].via, Some(1));
        assert!((p[2].confidence - 0.5).abs() < 1e-12);
        assert_eq!(p[3].via, Some(0));
        assert_eq!(p[4].reference_from_map, None);
        assert!(p[4].refusal.is_some());
    }
}
