//! Every scenario file that ships loads, and the shipped default is the built-in default.

use realms_sim::{Scenario, World};
use std::path::Path;

fn shipped() -> Vec<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("scenario folder {}: {e}", dir.display()))
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    files
}

#[test]
fn every_shipped_scenario_loads_and_builds_a_world() {
    let files = shipped();
    assert!(files.len() >= 2, "{files:?}");
    for f in files {
        let s = Scenario::load(&f).unwrap_or_else(|e| panic!("{e}"));
        let world = World::new(&s);
        assert_eq!(
            world.rovers().count(),
            s.rovers.count as usize,
            "{}",
            f.display()
        );
    }
}

#[test]
fn shipped_default_is_the_built_in_default() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/default.toml");
    assert_eq!(Scenario::load(&dir).expect("loads"), Scenario::default());
}

#[test]
fn a_missing_file_is_an_error_naming_it() {
    let e = Scenario::load(Path::new("/nonexistent/x.toml")).expect_err("missing");
    assert!(e.to_string().contains("/nonexistent/x.toml"), "{e}");
}

#[test]
fn malformed_toml_is_an_error_with_a_line() {
    let e = Scenario::parse("seed = \n[arena", "broken.toml").expect_err("malformed");
    let msg = e.to_string();
    assert!(msg.contains("broken.toml") && msg.contains("line"), "{msg}");
}
