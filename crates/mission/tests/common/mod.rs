//! Shared by the mission's integration tests.
#![allow(dead_code)]

use realms_core::{RoverId, Time};
use realms_mission::{CapturedInput, Mission, MissionOptions};
use realms_node::mapping::MappingConfig;
use realms_sim::{Scenario, World};
use std::path::Path;

/// `scenarios/small.toml`: 14 m x 10 m, two rovers.
pub fn small() -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/small.toml");
    Scenario::load(&path).expect("small scenario loads")
}

/// A mission of `scenario` over instant messages and a 5 s gyro calibration, run for
/// `seconds` with every rover's SLAM input captured: the rovers' SLAM setup, their ids, the
/// finished mission and each rover's capture, for replays on identical input.
pub fn captured_run(
    scenario: &Scenario,
    seconds: f64,
) -> (
    MappingConfig,
    Vec<RoverId>,
    Mission,
    Vec<Vec<CapturedInput>>,
) {
    let options = MissionOptions {
        ideal_comms: true,
        gyro_calibration: realms_core::Duration::from_secs(5),
        ..MissionOptions::default()
    };
    let world = World::new(scenario);
    let cfg = realms_mission::rover_mapping_config(&world, &options);
    let ids: Vec<_> = world.rovers().map(|b| b.id).collect();
    let mut mission = Mission::with_options(world, options);
    mission.capture_slam_inputs();
    mission.run_until(Time::from_secs_f64(seconds));
    mission.finish();
    let capture = mission.take_capture();
    (cfg, ids, mission, capture)
}
