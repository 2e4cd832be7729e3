//! The lander's merging job: every rover's rebuilt map brought into one, in the frame of the
//! first rover's map. Rovers start beside the lander at known places, so each map's frame is
//! expected to coincide with the first's; the known-start mode of `realms-merge` refines that
//! prior, notices a map that has drifted from it, and refuses rather than merge wrong.

use realms_core::{Grid, Pose2, RoverId};
use realms_merge::compose::compose;
use realms_merge::{Map, MapCell, Params, Prepared, PriorWindow, estimate_with_prior};

/// How one rover's map joined the merged map.
#[derive(Clone, Debug, PartialEq)]
pub struct MergeLink {
    /// The rover.
    pub rover: RoverId,
    /// Pose of its map's frame in the reference map's frame, if the merge was accepted.
    pub reference_from_map: Option<Pose2>,
    /// Confidence, 0..1.
    pub confidence: f64,
    /// Why it was left out, if it was.
    pub refused: Option<String>,
    /// Whether the maps agree on a pose away from the known start (drift).
    pub drifted: bool,
    /// How far the map's centre sits from where the known start puts it, metres.
    pub drift_m: f64,
}

/// The merged map and how it was made.
#[derive(Clone, Debug, PartialEq)]
pub struct MergedMap {
    /// The rover whose map frame is the merged map's.
    pub reference: RoverId,
    /// One link per other rover with a map.
    pub links: Vec<MergeLink>,
    /// The merged cells.
    pub cells: Grid<MapCell>,
    /// Per cell, a bit per rover (in `rovers` order) whose map knew it.
    pub contribution: Grid<u64>,
    /// The rovers in contribution-bit order.
    pub rovers: Vec<RoverId>,
}

/// A rover's published map as the merger's cells.
pub fn to_merge_map(grid: &Grid<i8>) -> Map {
    Map::new(grid.map(|v| MapCell::from_occupancy(*v)))
}

/// Merges `maps` (rover and rebuilt map, reference first) from the known start: every map's
/// frame assumed to be the reference's, refined and checked.
pub fn merge_from_known_start(maps: &[(RoverId, &Grid<i8>)]) -> Option<MergedMap> {
    let (reference, _) = maps.first()?;
    let params = Params::default();
    let window = PriorWindow::default();
    let converted: Vec<Map> = maps.iter().map(|(_, g)| to_merge_map(g)).collect();
    let prepared_ref = Prepared::new(&converted[0], &params);
    let mut placements = vec![Some(Pose2::IDENTITY)];
    let mut links = Vec::new();
    for ((rover, _), map) in maps.iter().zip(&converted).skip(1) {
        let check = estimate_with_prior(
            &prepared_ref,
            &Prepared::new(map, &params),
            Pose2::IDENTITY,
            &window,
            &params,
        );
        let accepted = check.estimate.accepted();
        placements.push(accepted);
        links.push(MergeLink {
            rover: *rover,
            reference_from_map: accepted,
            confidence: check.estimate.confidence,
            refused: check.estimate.refusal.clone(),
            drifted: accepted.is_some() && check.drifted,
            drift_m: check.drift_m,
        });
    }
    let (cells, contribution) = compose(&converted, &placements);
    Some(MergedMap {
        reference: *reference,
        links,
        cells,
        contribution,
        rovers: maps.iter().map(|(r, _)| *r).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::msgs::OccupancyGrid;
    use realms_core::{GridGeometry, Point2};

    /// A 20 m x 15 m walled hall at 5 cm with a few rocks, everything shifted by `dx_m`.
    fn hall(dx_m: f64) -> Grid<i8> {
        let geo = GridGeometry {
            width: 440,
            height: 340,
            resolution_m: 0.05,
            origin: Point2::new(-1.0, -1.0),
        };
        let rocks = [
            (4.0, 3.0, 0.5),
            (12.0, 9.0, 0.8),
            (15.5, 4.0, 0.4),
            (7.0, 11.5, 0.6),
        ];
        let mut g = Grid::new(geo, OccupancyGrid::UNKNOWN);
        for y in 0..geo.height {
            for x in 0..geo.width {
                let p = geo.cell_center(realms_core::Cell { x, y });
                let (px, py) = (p.x_m - dx_m, p.y_m);
                let inside = (0.0..20.0).contains(&px) && (0.0..15.0).contains(&py);
                let wall = inside && !((0.1..=19.9).contains(&px) && (0.1..=14.9).contains(&py));
                let rock = rocks
                    .iter()
                    .any(|(rx, ry, r)| (px - rx).hypot(py - ry) < *r);
                if let Some(c) = g.get_mut(x, y) {
                    *c = if wall || (inside && rock) {
                        OccupancyGrid::OCCUPIED
                    } else if inside {
                        OccupancyGrid::FREE
                    } else {
                        OccupancyGrid::UNKNOWN
                    };
                }
            }
        }
        g
    }

    #[test]
    fn maps_from_the_known_start_merge_in_place_and_a_shifted_one_is_called_drifted() {
        let (a, same, shifted) = (hall(0.0), hall(0.0), hall(0.4));
        let merged = merge_from_known_start(&[
            (RoverId(1), &a),
            (RoverId(2), &same),
            (RoverId(3), &shifted),
        ])
        .expect("three maps");
        assert_eq!(merged.links.len(), 2);
        let in_place = &merged.links[0];
        let pose = in_place.reference_from_map.expect("the same map merges");
        assert!(pose.x_m.abs() < 0.06 && pose.y_m.abs() < 0.06, "{pose:?}");
        assert!(!in_place.drifted);
        let moved = &merged.links[1];
        let pose = moved.reference_from_map.expect("the shifted map merges");
        assert!(
            (pose.x_m + 0.4).abs() < 0.06 && pose.y_m.abs() < 0.06,
            "{pose:?}"
        );
        assert!(moved.drifted, "0.4 m off the known start is drift");
        // Every rover's bit is in the contribution layer.
        let all = merged.contribution.cells().iter().fold(0, |acc, b| acc | b);
        assert_eq!(all, 0b111);
    }
}
