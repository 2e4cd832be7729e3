//! The hazard layer in a rover's published map, on hand-built ground: a crater bowl and a
//! rock below the lidar plane, neither of which the lidar sees; a large crater whose far
//! wall lies beyond the depth camera's reach.

use realms_core::msgs::OccupancyGrid;
use realms_core::{Point2, Pose2, Time};
use realms_mission::{Mission, MissionOptions};
use realms_sim::terrain::{Boulder, Crater};
use realms_sim::{Scenario, Terrain, World};

fn value_at(map: &OccupancyGrid, p: Point2) -> i8 {
    let r = map.info.resolution_m as f64;
    let x = ((p.x_m - map.info.origin.position.x) / r).floor() as usize;
    let y = ((p.y_m - map.info.origin.position.y) / r).floor() as usize;
    map.data[y * map.info.width as usize + x]
}

/// The map a lone rover publishes after standing through its gyro's calibration (4.5 s) on
/// `terrain`, its SLAM set up as `options` say.
fn map_after_standing(terrain: Terrain, options: MissionOptions) -> OccupancyGrid {
    let mut s = Scenario::default();
    s.rovers.count = 1;
    s.faults.clear();
    let mut mission = Mission::with_options(World::with_terrain(&s, terrain), options);
    mission.run_until(Time::from_secs_f64(4.5));
    mission.finish();
    mission.slam_records()[0]
        .map
        .clone()
        .expect("the map was published")
}

#[test]
fn a_crater_bowl_and_a_low_rock_are_hazards_and_the_floor_between_is_free() {
    let crater = Crater {
        center: Point2::new(7.5, 10.0),
        radius_m: 1.0,
        depth_m: 0.3,
        rim_m: 0.06,
    };
    let rock = Boulder {
        center: Point2::new(6.0, 9.0),
        radius_m: 0.2,
        height_m: 0.15,
    };
    let mut t = Terrain::flat(20.0, 20.0, 0.05);
    t.add_perimeter_walls(0.2, 1.0);
    t.add_crater(crater);
    t.add_boulder(rock);
    t.rover_starts = vec![Pose2::new(4.5, 10.0, 0.0)];
    // The rover stands still (measuring the gyro), looking at both.
    let map = map_after_standing(t, MissionOptions::default());
    let at = |x, y| value_at(&map, Point2::new(x, y));
    assert_eq!(at(7.5, 10.0), OccupancyGrid::HAZARD, "the crater's centre");
    assert_eq!(at(7.0, 10.2), OccupancyGrid::HAZARD, "inside the crater");
    assert_eq!(at(6.0, 9.0), OccupancyGrid::HAZARD, "the rock");
    assert_eq!(at(5.7, 10.5), OccupancyGrid::FREE, "the floor between");
}

/// The published map of a rover that stood 1.5 m from the rim of a large crater (3 m
/// radius, 0.8 m deep, its rim 0.16 m high), looking at its centre, through its gyro's
/// calibration; `options` sets up its SLAM.
fn map_beside_a_large_crater(options: MissionOptions) -> OccupancyGrid {
    let mut t = Terrain::flat(20.0, 20.0, 0.05);
    t.add_perimeter_walls(0.2, 1.0);
    t.add_crater(Crater {
        center: Point2::new(10.5, 10.0),
        radius_m: 3.0,
        depth_m: 0.8,
        rim_m: 0.16,
    });
    t.rover_starts = vec![Pose2::new(6.0, 10.0, 0.0)];
    map_after_standing(t, options)
}

#[test]
fn the_near_wall_of_a_crater_whose_far_wall_is_out_of_reach_is_a_hazard_with_silent_pixels_read() {
    // The camera sees the rim's crest 1.3 m ahead; the rays over it run on past its 6 m
    // reach without meeting the bowl, and the far wall lies 7.3 m off.
    let mut read = MissionOptions::default();
    read.mapping_changes.push(|c| c.silent_pixels = true);
    let map = map_beside_a_large_crater(read);
    let at = |x| value_at(&map, Point2::new(x, 10.0));
    for x in [7.7, 7.9, 8.2, 9.0] {
        assert_eq!(
            at(x),
            OccupancyGrid::HAZARD,
            "the crater's near wall at x = {x}"
        );
    }
    assert_eq!(at(6.8), OccupancyGrid::FREE, "the rim's outer slope");
    // With the pixels that returned nothing left unread (the rovers' setup), the hidden
    // wall is not marked: the lidar's beams passed over it, and it reads as free ground.
    let map = map_beside_a_large_crater(MissionOptions::default());
    let unmarked = [7.7, 7.9, 8.2, 9.0]
        .into_iter()
        .filter(|x| value_at(&map, Point2::new(*x, 10.0)) != OccupancyGrid::HAZARD)
        .count();
    assert!(unmarked >= 3, "{unmarked} of 4 unmarked");
}

#[test]
fn a_tall_rock_too_near_to_see_leaves_no_hazard_behind_it_with_silent_pixels_read() {
    // The camera 0.4 m from an 0.85 m rock's face: the face above the floor at its foot is
    // nearer than the camera's least depth, and those pixels return nothing, like rays
    // that met nothing; the floor behind the rock is no hazard.
    let rock = Point2::new(10.0, 10.0);
    let mut t = Terrain::flat(20.0, 20.0, 0.05);
    t.add_perimeter_walls(0.2, 1.0);
    t.add_boulder(Boulder {
        center: rock,
        radius_m: 0.7,
        height_m: 0.85,
    });
    t.rover_starts = vec![Pose2::new(8.7, 10.0, 0.0)];
    let mut options = MissionOptions::default();
    options.mapping_changes.push(|c| c.silent_pixels = true);
    let map = map_after_standing(t, options);
    let r = map.info.resolution_m as f64;
    let origin = Point2::new(map.info.origin.position.x, map.info.origin.position.y);
    let far_hazards = map
        .data
        .iter()
        .enumerate()
        .filter(|(i, v)| {
            let (x, y) = (i % map.info.width as usize, i / map.info.width as usize);
            let p = Point2::new(
                origin.x_m + (x as f64 + 0.5) * r,
                origin.y_m + (y as f64 + 0.5) * r,
            );
            **v == OccupancyGrid::HAZARD && p.distance_m(rock) > 0.9
        })
        .count();
    assert_eq!(far_hazards, 0, "hazard cells away from the rock");
}
