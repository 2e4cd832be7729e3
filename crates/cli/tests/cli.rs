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

#[test]
fn mission_writes_its_results_folder_and_says_where() {
    let out = std::env::temp_dir().join(format!("realms-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
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
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("mission.json")).expect("json"))
            .expect("valid");
    assert_eq!(json["sim_duration_s"], 20.0);
    assert_eq!(json["rovers"].as_array().expect("rovers").len(), 2);
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
