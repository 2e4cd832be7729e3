//! A mission over the simulated network: rovers' map updates reach the lander and the
//! ground, nothing crosses a ground-link blackout and all of it crosses afterwards, the
//! ground rebuilds each rover's map, and the updates cost far less than full grids.

use realms_core::msgs::OccupancyGrid;
use realms_core::{Duration, Time};
use realms_mission::slam_record::map_grid;
use realms_mission::{Mission, MissionOptions};
use realms_net::NodeAddr;
use realms_sim::{Scenario, World};
use std::path::Path;

const BLACKOUT_S: [f64; 2] = [60.0, 180.0];

fn small_with_blackout() -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/small.toml");
    let mut s = Scenario::load(&path).expect("small scenario loads");
    s.faults.clear();
    s.network.ground.blackouts_s = vec![BLACKOUT_S];
    s
}

#[test]
fn map_updates_cross_after_a_blackout_and_the_ground_rebuilds_every_map() {
    let s = small_with_blackout();
    let mut mission = Mission::with_options(World::new(&s), MissionOptions::default());
    // Explore, then wait for the ground to catch up, as `realms mission` does.
    let mut explored_at = None;
    while mission.now() < Time::from_secs_f64(1200.0) {
        if mission.exploration_over() {
            let t = *explored_at.get_or_insert(mission.now());
            if mission.ground_current_since(t) && mission.now() > Time::from_secs_f64(BLACKOUT_S[1])
            {
                break;
            }
        }
        let next = mission.now() + Duration::from_secs(10);
        mission.run_until(next);
    }
    mission.finish();
    let explored_at = explored_at.expect("exploration finished");
    assert!(
        mission.ground_current_since(explored_at),
        "the ground caught up"
    );

    let (dark_from, dark_to) = (BLACKOUT_S[0] + s.network.ground.delay_s, BLACKOUT_S[1]);
    for (k, d) in mission.downlink().iter().enumerate() {
        assert!(
            d.arrivals
                .iter()
                .all(|(_, at)| !(at.as_secs_f64() > dark_from && at.as_secs_f64() < dark_to)),
            "rover {} map update crossed the blackout",
            k + 1
        );
        assert!(
            d.arrivals
                .iter()
                .any(|(stamp, _)| stamp.as_secs_f64() > dark_to),
            "updates after the blackout"
        );
        assert!(
            d.full_grid_bytes >= 50 * d.bytes,
            "map updates {} B against {} B of full grids",
            d.bytes,
            d.full_grid_bytes
        );
    }
    let lander = mission.station(NodeAddr::Lander).expect("a lander");
    let ground = mission.station(NodeAddr::Ground).expect("a ground station");
    for (body, record) in mission.world().rovers().zip(mission.slam_records()) {
        let at_ground = ground.rover(body.id).expect("the ground heard the rover");
        let rebuilt = at_ground.map.map().expect("a map at the ground");
        // The rover's own map at the end, a few seconds newer at most.
        let own = map_grid(record.map.as_ref().expect("a final map")).expect("well formed");
        assert_eq!(rebuilt.geometry(), own.geometry(), "{}", body.id);
        let same = rebuilt
            .cells()
            .iter()
            .zip(own.cells())
            .filter(|(a, b)| a == b)
            .count();
        let agreement = same as f64 / own.cells().len() as f64;
        assert!(
            agreement > 0.98,
            "{}: {agreement:.3} of cells agree",
            body.id
        );
        assert!(
            rebuilt.cells().contains(&OccupancyGrid::OCCUPIED),
            "a map with obstacles"
        );
        // The lander rebuilt the same map from the same updates.
        let at_lander = lander.rover(body.id).expect("the lander heard the rover");
        if at_lander.map_stamp == at_ground.map_stamp {
            assert_eq!(at_lander.map.map(), Some(rebuilt));
        }
        assert!(at_ground.updates_applied > 10);
    }
    let stats = mission.network().expect("simulated").stats();
    assert_eq!(stats.malformed, 0);
    // The ground's network monitor has the lander's traffic report, with every node in it.
    let report = ground
        .network()
        .expect("network statistics reached the ground");
    let names: Vec<&str> = report.nodes.iter().map(|n| n.node.as_str()).collect();
    assert_eq!(names, ["rover1", "rover2", "lander", "ground"]);
    assert!(report.nodes[0].sent_bytes > 0 && report.nodes[3].received_bytes > 0);
    // The lander's transforms reached the ground, which draws the merged map from them and
    // its own copies of the rovers' maps.
    let transforms = ground
        .transforms()
        .expect("the lander's transforms reached the ground");
    assert_eq!(transforms.header.frame_id, "rover1/map");
    assert_eq!(transforms.maps.len(), 1);
    let drawn = ground
        .merged_from_transforms()
        .expect("the ground draws the merge");
    assert!(drawn.cells().contains(&realms_merge::MapCell::Occupied));
    assert!(lander.merges_run() >= 1);
}

#[test]
fn malformed_packets_are_counted_and_dropped_and_the_mission_goes_on() {
    let s = small_with_blackout();
    let mut mission = Mission::with_options(World::new(&s), MissionOptions::default());
    mission.run_until(Time::from_secs_f64(20.0));
    let topic = realms_core::RoverId(1).topic("nav/goal");
    for garbage in [vec![], vec![0xff; 7], vec![1, 200, 3, 4, 5, 6, 7, 8, 9]] {
        assert!(mission.inject(NodeAddr::Ground, NodeAddr::Rover(1), &topic, garbage));
    }
    mission.run_until(Time::from_secs_f64(40.0));
    let stats = mission.network().expect("simulated").stats();
    assert_eq!(stats.malformed, 3);
    // Rover 1 kept exploring: its map reached the ground after the garbage did.
    let arrivals = &mission.downlink()[0].arrivals;
    assert!(arrivals.iter().any(|(_, at)| at.as_secs_f64() > 25.0));
}

/// The velocity an operator sends from the ground: a turn no navigator would command.
fn teleop(mission: &Mission) -> realms_core::msgs::Message {
    let mut cmd = realms_core::msgs::TwistStamped::default();
    cmd.header.stamp = mission.now();
    cmd.header.frame_id = "rover1/base_link".into();
    cmd.twist.angular.z = 0.123;
    realms_core::msgs::Message::CmdVel(cmd)
}

#[test]
fn teleoperation_from_the_ground_crosses_the_link_and_dies_in_a_blackout() {
    let s = small_with_blackout();
    let mut mission = Mission::with_options(World::new(&s), MissionOptions::default());
    let topic = realms_core::RoverId(1).topic("cmd_vel");
    let counts = |m: &Mission| {
        let stats = m.network().expect("simulated").stats();
        let t = stats.topics.get(&topic).cloned().unwrap_or_default();
        let expired = t.dropped.get("Expired").copied().unwrap_or(0);
        (t.published.messages, t.delivered.messages, expired)
    };
    let turning = |m: &Mission| {
        let rover = m.world().rovers().next().expect("rover1");
        rover
            .command
            .as_ref()
            .is_some_and(|c| c.twist.angular.z == 0.123)
    };

    mission.run_until(Time::from_secs_f64(20.0));
    let cmd = teleop(&mission);
    mission.publish(topic.clone(), cmd);
    // Nothing reaches the rover before the link has carried it.
    assert!(!turning(&mission), "the command skipped the network");
    assert_eq!(counts(&mission), (1, 0, 0));
    mission.run_until(Time::from_secs_f64(23.0));
    assert_eq!(counts(&mission), (1, 1, 0), "delivered once, in time");

    // In a blackout it waits at the ground, outlives its time to live and is dropped, not
    // executed two minutes late.
    mission.run_until(Time::from_secs_f64(90.0));
    let cmd = teleop(&mission);
    mission.publish(topic.clone(), cmd);
    mission.run_until(Time::from_secs_f64(200.0));
    assert_eq!(counts(&mission), (2, 1, 1));
}
