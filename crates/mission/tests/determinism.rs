//! Same scenario and seed: byte-identical results (wall-clock fields aside). Another seed: a
//! different arena and mission.

use realms_core::Time;
use realms_mission::report::write_results;
use realms_mission::{Mission, MissionOptions};
use realms_sim::{Scenario, World};
use std::path::{Path, PathBuf};

mod common;

use common::small;

fn run(scenario: &Scenario, name: &str, wall_s: f64) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("realms-determinism-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let options = MissionOptions {
        // The test is timed from the rovers' start: a short gyro calibration.
        gyro_calibration: realms_core::Duration::from_secs(5),
        ..MissionOptions::default()
    };
    let mut mission = Mission::with_options(World::new(scenario), options);
    mission.run_until(Time::from_secs_f64(60.0));
    write_results(&mission, &dir, "small", wall_s).expect("results written");
    dir
}

fn without_wall_clock(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).expect("mission.json");
    let mut v: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let obj = v.as_object_mut().expect("an object");
    for varying in ["wall_s", "speedup", "slam_wall_s", "slam_speedup"] {
        assert!(obj.remove(varying).is_some(), "{varying}");
    }
    v
}

#[test]
fn same_seed_gives_byte_identical_outputs_and_another_seed_differs() {
    let s = small();
    let a = run(&s, "a", 1.5);
    let b = run(&s, "b", 2.5);
    for file in [
        "truth.png",
        "trajectories.png",
        "trajectories.csv",
        "slam.csv",
    ] {
        let (x, y) = (
            std::fs::read(a.join(file)).expect("a"),
            std::fs::read(b.join(file)).expect("b"),
        );
        assert!(x == y, "{file} differs between identical runs");
    }
    let (ja, jb) = (
        without_wall_clock(&a.join("mission.json")),
        without_wall_clock(&b.join("mission.json")),
    );
    assert_eq!(ja, jb);
    // The rovers actually did something worth comparing.
    let driven: f64 = ja["rovers"]
        .as_array()
        .expect("rovers")
        .iter()
        .map(|r| r["distance_m"].as_f64().expect("m"))
        .sum();
    assert!(driven > 10.0, "rovers drove only {driven} m");

    let c = run(
        &Scenario {
            seed: s.seed + 1,
            ..s.clone()
        },
        "c",
        1.5,
    );
    assert_ne!(
        std::fs::read(a.join("truth.png")).expect("a"),
        std::fs::read(c.join("truth.png")).expect("c")
    );
    assert_ne!(
        std::fs::read(a.join("trajectories.csv")).expect("a"),
        std::fs::read(c.join("trajectories.csv")).expect("c")
    );
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
}

#[test]
fn the_report_holds_the_contracted_fields_and_the_scheduled_faults() {
    let s = small();
    let dir = run(&s, "fields", 1.0);
    let v = without_wall_clock(&dir.join("mission.json"));
    for key in [
        "seed",
        "sim_duration_s",
        "rovers",
        "collisions",
        "hazard_entries",
        "events",
        "arena",
        "behaviour",
    ] {
        assert!(v.get(key).is_some(), "mission.json lacks {key}");
    }
    assert_eq!(v["seed"], 42);
    assert_eq!(v["sim_duration_s"], 60.0);
    let kinds: Vec<(&str, &str)> = v["events"]
        .as_array()
        .expect("events")
        .iter()
        .map(|e| {
            (
                e["kind"].as_str().expect("kind"),
                e["rover"].as_str().expect("rover"),
            )
        })
        .collect();
    // small.toml: rover2's lidar drops out at 30 s for 5 s; rover1 slips at 40 s for 4 s.
    for expected in [
        ("sensor_dropout_start", "rover2"),
        ("sensor_dropout_end", "rover2"),
        ("slip_burst_start", "rover1"),
        ("slip_burst_end", "rover1"),
    ] {
        assert!(
            kinds.contains(&expected),
            "{expected:?} missing from {kinds:?}"
        );
    }
    // Lidar at 10 Hz: rover1 scans at 0.0, 0.1, ... 60.0 (601); rover2 is phased 7 ms later
    // (600 in 60 s) and loses the 50 scans of its 5 s dropout.
    assert_eq!(v["messages"]["rover1/scan"], 601);
    assert_eq!(v["messages"]["rover2/scan"], 550);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn slam_replayed_on_the_captured_input_tracks_exactly_as_on_board() {
    // The replay is how `realms bench slam` compares SLAM variants on identical input: it
    // is only worth that if the setup as it is gives back exactly what the rovers had.
    let (cfg, ids, mut mission, capture) = common::captured_run(&small(), 60.0);
    assert_eq!(capture.len(), ids.len());
    let mut drove = 0;
    for (k, (id, input)) in ids.iter().zip(&capture).enumerate() {
        let mut mapping = realms_node::mapping::Mapping::new(*id, cfg.clone());
        let mut tracked = std::collections::BTreeMap::new();
        realms_mission::replay_slam(&mut mapping, input, |c, m| {
            // Scans are stamped with the time of what they show (a sweep's last beam for SLAM),
            // a few ms before they come.
            let realms_core::msgs::Message::LaserScan(scan) = &c.message else {
                unreachable!("called after scans")
            };
            tracked.insert(c.t, (m.pose(), scan.last_beam_time()));
        });
        assert!(
            input.iter().all(|c| matches!(
                c.message,
                realms_core::msgs::Message::LaserScan(_)
                    | realms_core::msgs::Message::Odometry(_)
                    | realms_core::msgs::Message::Imu(_)
                    | realms_core::msgs::Message::PointCloud(_)
            )),
            "{id}: only SLAM's input is captured"
        );
        let checks = &mission.slam_records()[k].checks;
        let last = checks.last().expect("poses were published");
        if last.truth.position().distance_m(checks[0].truth.position()) > 1.0 {
            drove += 1;
        }
        let finals: std::collections::BTreeMap<_, _> = mapping
            .trajectory()
            .iter()
            .map(|s| (Time::from_secs_f64(s.timestamp_s), s.pose))
            .collect();
        for c in checks {
            let (on_board, stamp) = tracked
                .get(&c.t)
                .expect("every published pose has its scan");
            let off = |a: realms_core::Pose2, b: realms_core::Pose2| {
                a.position().distance_m(b.position()) + (a.yaw_rad - b.yaw_rad).abs()
            };
            assert!(off(*on_board, c.estimate) < 1e-9, "{id} at {:?}", c.t);
            let optimised = c.optimised.expect("the trajectory was attached");
            let replayed = finals.get(stamp).expect("a final pose for the scan");
            assert!(off(*replayed, optimised) < 1e-9, "{id} at {:?}", c.t);
        }
    }
    // Some rover drove: the comparison is not only of poses standing at the start.
    assert!(drove > 0, "no rover drove a metre");
    // Taking what was captured does not stop the capture.
    mission.run_until(Time::from_secs_f64(61.0));
    let more = mission.take_capture();
    assert_eq!(more.len(), ids.len());
    assert!(more.iter().all(|c| !c.is_empty()), "capture goes on");
}
