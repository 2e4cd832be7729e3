//! The hazard layer in a rover's published map, on hand-built ground: a crater bowl and a
//! rock below the lidar plane, neither of which the lidar sees.

use realms_core::msgs::OccupancyGrid;
use realms_core::{Point2, Pose2, Time};
use realms_mission::Mission;
use realms_sim::terrain::{Boulder, Crater};
use realms_sim::{Scenario, Terrain, World};

fn value_at(map: &OccupancyGrid, p: Point2) -> i8 {
    let r = map.info.resolution_m as f64;
    let x = ((p.x_m - map.info.origin.position.x) / r).floor() as usize;
    let y = ((p.y_m - map.info.origin.position.y) / r).floor() as usize;
    map.data[y * map.info.width as usize + x]
}

#[test]
fn a_crater_bowl_and_a_low_rock_are_hazards_and_the_floor_between_is_free() {
    let mut s = Scenario::default();
    s.rovers.count = 1;
    s.faults.clear();
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
    // The rover stands still for its first minute (measuring the gyro), looking at both.
    let mut mission = Mission::with_world(World::with_terrain(&s, t));
    mission.run_until(Time::from_secs_f64(4.5));
    mission.finish();
    let map = mission.slam_records()[0]
        .map
        .clone()
        .expect("the map was published");
    let at = |x, y| value_at(&map, Point2::new(x, y));
    assert_eq!(at(7.5, 10.0), OccupancyGrid::HAZARD, "the crater's centre");
    assert_eq!(at(7.0, 10.2), OccupancyGrid::HAZARD, "inside the crater");
    assert_eq!(at(6.0, 9.0), OccupancyGrid::HAZARD, "the rock");
    assert_eq!(at(5.7, 10.5), OccupancyGrid::FREE, "the floor between");
}
