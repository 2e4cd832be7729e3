//! The `realms` binary end to end: a short mission, scenario printing and checking, and the
//! errors a user sees for bad input.

use std::path::Path;
use std::process::Command;

fn realms() -> Command {
    Command::new(env!("CARGO_BIN_EXE_realms"))
}

fn repo(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(path)
        .display()
        .to_string()
}

/// The `mission.json` a mission wrote into `out`.
fn mission_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("mission.json")).expect("json"))
        .expect("valid")
}

#[test]
fn mission_writes_its_results_folder_and_says_where() {
    let out = fresh_dir("realms-cli");
    let o = realms()
        .args([
            "mission",
            "--scenario",
            &repo("scenarios/small.toml"),
            "--duration",
            "20s",
            "--quiet",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains(&out.display().to_string()), "{stdout}");
    for f in [
        "mission.json",
        "truth.png",
        "trajectories.png",
        "trajectories.csv",
        "slam.csv",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let json = mission_json(&out);
    assert_eq!(json["sim_duration_s"], 20.0);
    assert_eq!(json["rovers"].as_array().expect("rovers").len(), 2);
    std::fs::remove_dir_all(&out).ok();

    // With a change to the rovers' navigation, the report names it.
    let o = realms()
        .args(["mission", "--scenario", &repo("scenarios/small.toml")])
        .args([
            "--duration",
            "5s",
            "--quiet",
            "--nav-variant",
            "revisit",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = mission_json(&out);
    let scenario = json["scenario"].as_str().expect("the scenario's source");
    assert!(
        scenario.ends_with("navigation variant revisit"),
        "{scenario}"
    );
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn bench_missions_grades_each_seed_as_its_own_mission_would() {
    let small = repo("scenarios/small.toml");
    let o = realms()
        .args(["bench", "missions", "--scenario", &small])
        .args([
            "--seeds",
            "2",
            "--first-seed",
            "3",
            "--duration",
            "150s",
            "--json",
        ])
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bench: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let missions = bench["missions"].as_array().expect("missions");
    assert_eq!(missions.len(), 2);
    // The second seed, run on its own as a user runs it.
    let out = fresh_dir("realms-bench-missions");
    let o = realms()
        .args([
            "mission",
            "--scenario",
            &small,
            "--seed",
            "4",
            "--duration",
            "150s",
        ])
        .arg("--quiet")
        .arg("--out")
        .arg(&out)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = mission_json(&out);
    let graded = &missions[1];
    assert_eq!(graded["seed"], 4);
    assert_eq!(graded["sim_duration_s"], report["sim_duration_s"]);
    assert_eq!(
        graded["merged_occupied_correct"],
        report["merge"]["occupied_correct"]
    );
    let rovers = report["rovers"].as_array().expect("rovers");
    assert_eq!(
        graded["rovers"].as_array().expect("rovers").len(),
        rovers.len()
    );
    let mut maps = Vec::new();
    for (g, r) in graded["rovers"]
        .as_array()
        .expect("rovers")
        .iter()
        .zip(rovers)
    {
        assert_eq!(g["name"], r["name"]);
        assert_eq!(g["occupied_correct"], r["slam"]["map"]["occupied_correct"]);
        assert_eq!(
            g["trajectory_rmse_m"],
            r["slam"]["trajectory_error"]["rmse_m"]
        );
        assert_eq!(g["path_hazards"], r["slam"]["map"]["path_hazards"]);
        maps.push(g["occupied_correct"].as_f64().expect("a graded map"));
    }
    // The summary pools both missions' rovers.
    for g in missions[0]["rovers"].as_array().expect("rovers") {
        maps.push(g["occupied_correct"].as_f64().expect("a graded map"));
    }
    let summary = &bench["summary"];
    assert_eq!(summary["rovers_graded"], maps.len());
    let mean = maps.iter().sum::<f64>() / maps.len() as f64;
    let reported = summary["occupied_correct_mean"].as_f64().expect("a mean");
    assert!((reported - mean).abs() < 1e-12, "{reported} against {mean}");
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn print_default_round_trips_through_check() {
    let o = realms()
        .args(["scenario", "--print-default"])
        .output()
        .expect("runs");
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).expect("utf8");
    assert!(text.contains("[rovers.lidar]") && text.contains("seed = 1"));
    let file = std::env::temp_dir().join(format!("realms-default-{}.toml", std::process::id()));
    std::fs::write(&file, &text).expect("write");
    let o = realms()
        .args(["scenario", "--check"])
        .arg(&file)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_file(file).ok();
}

#[test]
fn a_bad_scenario_fails_with_file_and_key() {
    let file = std::env::temp_dir().join(format!("realms-bad-{}.toml", std::process::id()));
    std::fs::write(&file, "[rovers]\ncount = 0\n").expect("write");
    let o = realms()
        .args(["mission", "--quiet", "--scenario"])
        .arg(&file)
        .output()
        .expect("runs");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("rovers.count") && err.contains(&file.display().to_string()),
        "{err}"
    );
    std::fs::remove_file(file).ok();

    let o = realms()
        .args(["mission", "--duration", "soon"])
        .output()
        .expect("runs");
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("soon"));

    // An unknown navigation variant is refused before anything runs, naming those known.
    let o = realms()
        .args(["mission", "--quiet", "--nav-variant", "wander"])
        .output()
        .expect("runs");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("wander") && err.contains("revisit"), "{err}");
}

#[test]
fn net_relay_reproduces_the_field_experiment_as_json() {
    let o = realms()
        .args(["bench", "net-relay", "--json", "--draws", "200"])
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let gain = v["relay_gain"].as_f64().expect("relay_gain");
    assert!((2.0..=10.0).contains(&gain), "relay gain {gain}");
    // At 220 m: pings and teleoperation, no images; through the relay, images too.
    assert_eq!(v["direct"]["ping"], true);
    assert_eq!(v["direct"]["teleop"], true);
    assert_eq!(v["direct"]["images"], false);
    assert_eq!(v["relay"]["images"], true);
}

/// Writes a generated pair (A, B) from a recorded map into `dir`; returns the YAML paths
/// and the answer.
fn merge_case(
    dir: &Path,
    overlap: f64,
    seed: u64,
) -> (std::path::PathBuf, std::path::PathBuf, realms_core::Pose2) {
    use rand::SeedableRng;
    let source = realms_merge::io::read(Path::new(&repo("../shared/data/maps/aws_bookstore.yaml")))
        .expect("the recorded map (../shared/data present?)");
    let spec = realms_merge::synth::PairSpec {
        overlap,
        ..Default::default()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pair = realms_merge::synth::make_pair(&source.cells, &spec, &mut rng).expect("pair");
    std::fs::create_dir_all(dir).expect("dir");
    let a = realms_merge::io::write(&pair.a.cells, &dir.join("a.yaml")).expect("write a");
    let b = realms_merge::io::write(&pair.b.cells, &dir.join("b.yaml")).expect("write b");
    (a, b, pair.a_from_b)
}

/// `realms merge ARGS --out OUT --json`, which must succeed; its one JSON object.
fn merge_json(args: &[&std::ffi::OsStr], out: &Path) -> serde_json::Value {
    let o = realms()
        .arg("merge")
        .args(args)
        .arg("--out")
        .arg(out)
        .arg("--json")
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(&stdout).expect("one JSON object")
}

/// An empty directory of this test process's own under the system's temporary directory.
fn fresh_dir(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn merge_prints_each_pose_as_json_and_writes_the_merged_map() {
    let dir = fresh_dir("realms-cli-merge");
    let (a, b, truth) = merge_case(&dir, 0.5, 31);
    let out = dir.join("out/merged.yaml");
    let json = merge_json(&[a.as_os_str(), b.as_os_str()], &out);
    let maps = json["maps"].as_array().expect("maps");
    assert_eq!(maps.len(), 1);
    let m = &maps[0];
    assert_eq!(m["map"], b.display().to_string());
    let (x, y, yaw) = (
        m["x_m"].as_f64().expect("x_m"),
        m["y_m"].as_f64().expect("y_m"),
        m["yaw_rad"].as_f64().expect("yaw_rad"),
    );
    let c = m["confidence"].as_f64().expect("confidence");
    assert!((0.0..=1.0).contains(&c));
    let found = realms_core::Pose2::new(x, y, yaw);
    let err = found.relative_to(&truth);
    assert!(
        err.yaw_rad.abs() < 2f64.to_radians(),
        "{found:?} vs {truth:?}"
    );
    assert!(out.is_file() && dir.join("out/merged.pgm").is_file());
    let merged = realms_merge::io::read(&out).expect("the merged map reads back");
    assert!(merged.known_cells() > 0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn merge_refuses_maps_that_share_nothing_and_reports_bad_files() {
    let dir = fresh_dir("realms-cli-merge-bad");
    let (a, b, _) = merge_case(&dir, 0.0, 32);
    let o = realms()
        .arg("merge")
        .arg(&a)
        .arg(&b)
        .arg("--out")
        .arg(dir.join("m.yaml"))
        .arg("--json")
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}");
    let json: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    assert!(
        json["maps"][0]["refused"]
            .as_str()
            .is_some_and(|r| !r.is_empty()),
        "{json}"
    );

    let bad = dir.join("bad.yaml");
    std::fs::write(&bad, "image: a.pgm\nresolution: 0.05\n").expect("write");
    let o = realms()
        .arg("merge")
        .arg(&a)
        .arg(&bad)
        .arg("--out")
        .arg(dir.join("m2.yaml"))
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        stderr.contains("bad.yaml") && stderr.contains("`origin`"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `yaml` (a map_server YAML) written again as `out` with its grid moved by `moved`, a pose
/// in the frame the YAML's origin is given in.
fn moved_yaml(yaml: &Path, out: &Path, moved: realms_core::Pose2) {
    let text = std::fs::read_to_string(yaml).expect("the YAML");
    let map = realms_merge::io::read(yaml).expect("the map");
    let o = map.cells.geometry().origin;
    let p = moved.compose(&realms_core::Pose2::new(o.x_m, o.y_m, map.origin_yaw_rad));
    let lines: Vec<String> = text
        .lines()
        .map(|l| {
            if l.starts_with("origin:") {
                format!("origin: [{}, {}, {}]", p.x_m, p.y_m, p.yaw_rad)
            } else {
                l.to_string()
            }
        })
        .collect();
    std::fs::write(out, lines.join("\n") + "\n").expect("write");
}

#[test]
fn merge_from_a_known_start_confirms_a_map_in_the_shared_frame_and_refuses_a_contradicting_one() {
    let dir = fresh_dir("realms-cli-merge-ks");
    let (a, b, truth) = merge_case(&dir, 0.5, 33);
    // B's grid where it truly lies in A's frame, and the same turned 30 degrees about A's
    // origin (beyond the 10 degree window: a known start that is wrong).
    let in_frame = dir.join("b_in_frame.yaml");
    moved_yaml(&b, &in_frame, truth);
    let wrong = dir.join("b_wrong.yaml");
    moved_yaml(
        &b,
        &wrong,
        realms_core::Pose2::new(0.0, 0.0, 30f64.to_radians()).compose(&truth),
    );
    let json = merge_json(
        &[
            a.as_os_str(),
            in_frame.as_os_str(),
            wrong.as_os_str(),
            "--known-start".as_ref(),
        ],
        &dir.join("ks.yaml"),
    );
    let confirmed = &json["maps"][0];
    assert_eq!(confirmed["confirmed"], true, "{json}");
    let (x, y, yaw) = (
        confirmed["x_m"].as_f64().expect("x_m"),
        confirmed["y_m"].as_f64().expect("y_m"),
        confirmed["yaw_rad"].as_f64().expect("yaw_rad"),
    );
    assert!(x.hypot(y) < 0.15 && yaw.abs() < 1f64.to_radians(), "{json}");
    assert!(
        json["maps"][1]["refused"]
            .as_str()
            .is_some_and(|r| r.contains("contradict the known start")),
        "{json}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
