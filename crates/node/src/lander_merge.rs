//! The lander's merging job: every rover's rebuilt map brought into one, in the frame of the
//! first rover's map. Rovers start beside the lander at known places, so each map's frame is
//! expected to coincide with the first's; the known-start mode of `realms-merge` refines that
//! prior and notices a map that has drifted from it. A map the others share too little
//! structure with to confirm any pose is placed at its known start, marked unconfirmed; one
//! that contradicts its known start is left out rather than merged wrong.

use realms_core::msgs::{Header, MapTransform, MapTransforms};
use realms_core::{Grid, Pose2, RoverId, Time};
use realms_merge::compose::merge_known_start;
use realms_merge::{Map, MapCell, Params, PriorWindow};

/// How one rover's map joined the merged map.
#[derive(Clone, Debug, PartialEq)]
pub struct MergeLink {
    /// The rover.
    pub rover: RoverId,
    /// Pose of its map's frame in the reference map's frame, if the merge was accepted.
    pub reference_from_map: Option<Pose2>,
    /// Confidence, 0..1 (0 for a map placed at its known start unconfirmed).
    pub confidence: f64,
    /// Whether the maps confirmed the pose (false: the known start, unchecked).
    pub confirmed: bool,
    /// How well the maps agree at the known start, allowing for drift
    /// ([`realms_merge::PriorCheck::loose_agreement`]); `None` with nothing to compare.
    pub agreement_at_start: Option<f64>,
    /// Why the maps could not confirm a pose, for a map placed at its known start.
    pub unconfirmed_because: Option<String>,
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

/// A rover's published map as the merger's cells. Its lidar clears ground well beyond where
/// its depth camera judged hazards, so its free cells do not rule out another rover's.
pub fn to_merge_map(grid: &Grid<i8>) -> Map {
    Map::new(grid.map(|v| MapCell::from_occupancy(*v))).with_free_unjudged_for_hazards()
}

/// Merges `maps` (rover and rebuilt map, reference first) from the known start: every map's
/// frame assumed to be the reference's, refined and checked.
pub fn merge_from_known_start(maps: &[(RoverId, &Grid<i8>)]) -> Option<MergedMap> {
    let (reference, _) = maps.first()?;
    let converted: Vec<Map> = maps.iter().map(|(_, g)| to_merge_map(g)).collect();
    let merged = merge_known_start(
        &converted,
        &Params::for_rover_maps(),
        &PriorWindow::default(),
    )
    .ok()?;
    let links = maps[1..]
        .iter()
        .zip(&merged.checks)
        .map(|((rover, _), check)| MergeLink {
            rover: *rover,
            reference_from_map: check.placed,
            confidence: check.confidence(),
            confirmed: check.confirmed,
            agreement_at_start: check.loose_agreement,
            unconfirmed_because: check.unconfirmed_because().map(str::to_string),
            refused: check.refusal.clone(),
            drifted: check.confirmed && check.drifted,
            drift_m: check.drift_m,
        })
        .collect();
    Some(MergedMap {
        reference: *reference,
        links,
        cells: merged.grid,
        contribution: merged.contribution,
        rovers: maps.iter().map(|(r, _)| *r).collect(),
    })
}

/// The merged map drawn from `maps` (rover and map, in fleet order) where `transforms` (the
/// lander's) place them: what the ground station shows without the grid crossing the
/// ground link. The reference is the map the transforms are in; maps the transforms leave
/// out, or do not name, are left out. `None` without the reference's map.
pub fn compose_with_transforms(
    maps: &[(RoverId, &Grid<i8>)],
    transforms: &MapTransforms,
) -> Option<Grid<MapCell>> {
    let (_, reference) = maps
        .iter()
        .find(|(r, _)| map_frame(*r) == transforms.header.frame_id)?;
    let (converted, poses): (Vec<Map>, Vec<Option<Pose2>>) =
        std::iter::once((to_merge_map(reference), Some(Pose2::IDENTITY)))
            .chain(maps.iter().filter_map(|(rover, g)| {
                let t = transforms
                    .maps
                    .iter()
                    .find(|t| t.child_frame_id == map_frame(*rover))?;
                let p = t.pose?;
                // A corrupt message that still decodes may place a map anywhere; drawn 1e300 m
                // off, the merged grid's loops would not end. Such a map is left out.
                let plausible = p.x_m.abs() <= MAX_TRANSFORM_M
                    && p.y_m.abs() <= MAX_TRANSFORM_M
                    && t.yaw_rad.is_finite();
                plausible.then(|| (to_merge_map(g), Some(Pose2::new(p.x_m, p.y_m, t.yaw_rad))))
            }))
            .unzip();
    Some(realms_merge::compose::compose(&converted, &poses).0)
}

/// The farthest a transform may place a rover's map from the reference's frame, metres: the
/// fleet maps one site, and a map placed farther would make the merged grid span more cells
/// than memory holds.
pub const MAX_TRANSFORM_M: f64 = 1e4;

/// A rover's map frame in [`MapTransforms`] (`rover2/map`).
fn map_frame(rover: RoverId) -> String {
    format!("{rover}/map")
}

impl MergedMap {
    /// The message saying where this merge placed each rover's map, made at `now`.
    pub fn transforms(&self, now: Time) -> MapTransforms {
        MapTransforms {
            header: Header {
                stamp: now,
                frame_id: map_frame(self.reference),
            },
            maps: self
                .links
                .iter()
                .map(|l| MapTransform {
                    child_frame_id: map_frame(l.rover),
                    pose: l
                        .reference_from_map
                        .map(|p| realms_core::Point2::new(p.x_m, p.y_m)),
                    yaw_rad: l.reference_from_map.map_or(0.0, |p| p.yaw_rad),
                    confidence: l.confidence,
                    confirmed: l.confirmed,
                })
                .collect(),
        }
    }
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

    /// `map` with a crater of `radius_m` at `centre` (hall metres) drawn as `value` over its
    /// known ground: hazard where a rover's depth camera judged it, free where its lidar
    /// only swept over it from afar.
    fn with_crater(map: &Grid<i8>, centre: Point2, radius_m: f64, value: i8) -> Grid<i8> {
        let geo = *map.geometry();
        let cells = map
            .iter()
            .map(|(cell, v)| {
                let inside = geo.cell_center(cell).distance_m(centre) < radius_m;
                if inside && *v != OccupancyGrid::UNKNOWN {
                    value
                } else {
                    *v
                }
            })
            .collect();
        Grid::from_cells(geo, cells).expect("one value per cell")
    }

    #[test]
    fn a_crater_only_one_rover_judged_does_not_stop_the_maps_confirming_each_other() {
        // Rover 1 drove round two craters and its camera marked them; rover 2 saw the same
        // ground free from across the hall, its camera never pointed there. Its map has
        // also drifted 0.15 m, within the tolerance: confirmed, it stays at its known start.
        let craters = [(Point2::new(6.0, 7.5), 1.5), (Point2::new(15.0, 11.0), 1.2)];
        let mut judged = hall(0.0);
        let mut swept = hall(0.15);
        for (centre, r) in craters {
            judged = with_crater(&judged, centre, r, OccupancyGrid::HAZARD);
            swept = with_crater(&swept, centre, r, OccupancyGrid::FREE);
        }
        let merged = merge_from_known_start(&[(RoverId(1), &judged), (RoverId(2), &swept)])
            .expect("two maps");
        let link = &merged.links[0];
        assert!(link.confirmed, "{link:?}");
        assert_eq!(link.reference_from_map, Some(Pose2::IDENTITY), "{link:?}");
        assert!(!link.drifted && link.drift_m > 0.05, "{link:?}");
        // Taken as surveys, whose free ground rules a hazard out, the craters' rims land
        // on open ground and no pose is confirmed: the map goes in at its known start only
        // because its obstacles (hazards aside) do not contradict it.
        let as_surveys = |g: &Grid<i8>| Map::new(g.map(|v| MapCell::from_occupancy(*v)));
        let check = realms_merge::estimate_with_prior(
            &realms_merge::Prepared::new(&as_surveys(&judged), &Params::for_rover_maps()),
            &realms_merge::Prepared::new(&as_surveys(&swept), &Params::for_rover_maps()),
            Pose2::IDENTITY,
            &PriorWindow::default(),
            &Params::for_rover_maps(),
        );
        assert!(!check.confirmed, "{:?}", check.estimate.refusal);
        assert_eq!(check.placed, Some(Pose2::IDENTITY), "{check:?}");
        assert!(
            check
                .estimate
                .refusal
                .as_deref()
                .is_some_and(|r| r.contains("conflict")),
            "{:?}",
            check.estimate.refusal
        );
    }

    #[test]
    fn maps_from_the_known_start_merge_in_place_and_a_shifted_one_is_called_drifted() {
        let (a, same, shifted, far) = (hall(0.0), hall(0.0), hall(0.4), hall(1.2));
        let merged = merge_from_known_start(&[
            (RoverId(1), &a),
            (RoverId(2), &same),
            (RoverId(3), &shifted),
            (RoverId(4), &far),
        ])
        .expect("four maps");
        assert_eq!(merged.links.len(), 3);
        let in_place = &merged.links[0];
        let pose = in_place.reference_from_map.expect("the same map merges");
        assert!(pose.x_m.abs() < 0.06 && pose.y_m.abs() < 0.06, "{pose:?}");
        assert!(!in_place.drifted);
        // 0.4 m off is drift, reported; but every wall still lies within the 0.5 m a drift
        // may put two maps apart, so nothing contradicts the known start: the map stays.
        let drifted = &merged.links[1];
        assert!(drifted.drifted && drifted.confirmed, "{drifted:?}");
        assert!((drifted.drift_m - 0.4).abs() < 0.06, "{drifted:?}");
        assert_eq!(
            drifted.reference_from_map,
            Some(Pose2::IDENTITY),
            "{drifted:?}"
        );
        // 1.2 m off puts the walls on the other map's open ground: the known start is
        // contradicted, and the map goes where the two agree.
        let moved = &merged.links[2];
        let pose = moved.reference_from_map.expect("the far map merges");
        assert!(
            (pose.x_m + 1.2).abs() < 0.06 && pose.y_m.abs() < 0.06,
            "{pose:?}"
        );
        assert!(moved.drifted, "{moved:?}");
        // Every rover's bit is in the contribution layer.
        let all = merged.contribution.cells().iter().fold(0, |acc, b| acc | b);
        assert_eq!(all, 0b1111);
    }

    /// `map` with every cell whose centre lies outside `keep` (an x range, metres) unknown.
    fn only(map: &Grid<i8>, keep: std::ops::Range<f64>) -> Grid<i8> {
        let geo = *map.geometry();
        let cells = map
            .iter()
            .map(|(cell, v)| {
                if keep.contains(&geo.cell_center(cell).x_m) {
                    *v
                } else {
                    OccupancyGrid::UNKNOWN
                }
            })
            .collect();
        Grid::from_cells(geo, cells).expect("one value per cell")
    }

    /// `map` turned by `yaw_rad` about the origin of its frame (nearest cell).
    fn turned(map: &Grid<i8>, yaw_rad: f64) -> Grid<i8> {
        let geo = *map.geometry();
        let back = Pose2::new(0.0, 0.0, -yaw_rad);
        let cells = map
            .iter()
            .map(|(cell, _)| {
                let p = back.transform_point(geo.cell_center(cell));
                map.at_world(p).copied().unwrap_or(OccupancyGrid::UNKNOWN)
            })
            .collect();
        Grid::from_cells(geo, cells).expect("one value per cell")
    }

    #[test]
    fn maps_too_unlike_to_confirm_sit_at_the_known_start_unless_contradicted_or_unchecked() {
        let hall = hall(0.0);
        // Rover 1 mapped the west of the hall, rover 2 the east, overlapping in a 2 m strip
        // where both see only the same two stretches of wall: no pose can be confirmed.
        let west = only(&hall, -1.0..11.0);
        let east = only(&hall, 9.0..21.0);
        // Rover 3's map is turned by 25 degrees: its walls cross rover 1's open ground.
        let wrong = turned(&hall, 25f64.to_radians());
        // Rover 4 mapped only the far east, nowhere near rover 1's ground.
        let far = only(&hall, 14.0..21.0);
        let merged = merge_from_known_start(&[
            (RoverId(1), &west),
            (RoverId(2), &east),
            (RoverId(3), &wrong),
            (RoverId(4), &far),
        ])
        .expect("four maps");
        let placed = &merged.links[0];
        assert_eq!(
            placed.reference_from_map,
            Some(Pose2::IDENTITY),
            "{placed:?}"
        );
        assert!(!placed.confirmed && placed.refused.is_none(), "{placed:?}");
        assert!(placed.unconfirmed_because.is_some(), "{placed:?}");
        assert!(
            placed.agreement_at_start.is_some_and(|a| a > 0.9),
            "{placed:?}"
        );
        assert_eq!(placed.confidence, 0.0);
        let refuse_reason = |l: &MergeLink| {
            assert_eq!(l.reference_from_map, None, "{l:?}");
            l.refused.clone().unwrap_or_default()
        };
        assert!(
            refuse_reason(&merged.links[1]).contains("contradict the known start"),
            "{:?}",
            merged.links[1]
        );
        assert!(
            refuse_reason(&merged.links[2]).contains("nothing to check the known start against"),
            "{:?}",
            merged.links[2]
        );
        // Rover 2's cells are in the merged map, rover 3's and rover 4's are not.
        let all = merged.contribution.cells().iter().fold(0, |acc, b| acc | b);
        assert_eq!(all, 0b0011);
    }
}
