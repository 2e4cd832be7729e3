//! Reading map_server maps: the recorded maps load with the right size and frame, and bad
//! files give errors that name the file, the field and what was expected.

mod common;

use realms_merge::MapCell;
use std::path::{Path, PathBuf};

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("realms-merge-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

const GOOD_YAML: &str = "image: m.pgm\nresolution: 0.05\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";

fn good_pgm() -> Vec<u8> {
    let mut b = b"P5\n3 2\n255\n".to_vec();
    // Top row: occupied, unknown, free; bottom row: free, free, occupied.
    b.extend([0, 205, 254, 254, 254, 0]);
    b
}

fn write(dir: &Path, yaml: &str, pgm: &[u8]) -> PathBuf {
    std::fs::write(dir.join("m.pgm"), pgm).expect("write pgm");
    let path = dir.join("m.yaml");
    std::fs::write(&path, yaml).expect("write yaml");
    path
}

fn error_of(yaml: &str, pgm: &[u8], name: &str) -> String {
    let dir = temp_dir(name);
    let path = write(&dir, yaml, pgm);
    let e = realms_merge::io::read(&path).expect_err("must be refused");
    let text = format!("{e:#}");
    std::fs::remove_dir_all(&dir).ok();
    text
}

#[test]
fn a_hand_written_map_reads_north_up_in_its_frame() {
    let dir = temp_dir("good");
    let path = write(&dir, GOOD_YAML, &good_pgm());
    let map = realms_merge::io::read(&path).expect("valid");
    assert_eq!((map.cells.width(), map.cells.height()), (3, 2));
    // Grid row 0 is the image's bottom row.
    assert_eq!(map.cells.get(2, 0), Some(&MapCell::Occupied));
    assert_eq!(map.cells.get(0, 1), Some(&MapCell::Occupied));
    assert_eq!(map.cells.get(1, 1), Some(&MapCell::Unknown));
    assert_eq!(map.cells.get(2, 1), Some(&MapCell::Free));
    assert_eq!(map.geometry().origin.x_m, -1.0);
    // Written back and read again, it is the same map.
    let out = realms_merge::io::write(&map.cells, &dir.join("copy.yaml")).expect("write");
    let again = realms_merge::io::read(&out).expect("read back");
    assert_eq!(again.cells, map.cells);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_recorded_maps_load() {
    let willow = common::recorded("willow_garage");
    assert_eq!((willow.cells.width(), willow.cells.height()), (1165, 945));
    assert_eq!(willow.geometry().resolution_m, 0.05);
    let office = common::recorded("tb3_office_real");
    assert_eq!(office.geometry().origin.x_m, -10.0);
    assert!(office.known_cells() > 10_000);
}

#[test]
fn a_rovers_map_keeps_its_hazards_through_a_file() {
    use realms_core::{Grid, GridGeometry, Point2};
    let dir = temp_dir("hazards");
    let geometry = GridGeometry {
        width: 4,
        height: 1,
        resolution_m: 0.05,
        origin: Point2::new(0.0, 0.0),
    };
    let cells = vec![
        MapCell::Free,
        MapCell::Hazard,
        MapCell::Occupied,
        MapCell::Unknown,
    ];
    let grid = Grid::from_cells(geometry, cells).expect("four cells");
    let path = realms_merge::io::write(&grid, &dir.join("rover.yaml")).expect("write");
    let yaml = std::fs::read_to_string(&path).expect("yaml");
    assert!(yaml.contains("hazard_value: 1"), "{yaml}");
    let map = realms_merge::io::read(&path).expect("read back");
    assert_eq!(map.cells, grid);
    // A rover's hazards come from a camera that looked only nearby: its free ground does
    // not rule out another rover's hazard.
    assert!(!map.free_judged_for_hazards);
    // To map_server, the hazard pixel is an obstacle: p = 254 / 255 over 0.65.
    let pgm = std::fs::read(dir.join("rover.pgm")).expect("pgm");
    assert_eq!(pgm[pgm.len() - 3], realms_core::map_server::HAZARD_PIXEL);
    // A map with no hazards is written and read as before.
    let plain = Grid::from_cells(geometry, vec![MapCell::Free; 4]).expect("four cells");
    let path = realms_merge::io::write(&plain, &dir.join("plain.yaml")).expect("write");
    let map = realms_merge::io::read(&path).expect("read back");
    assert!(map.free_judged_for_hazards);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_yaml_names_file_field_and_expectation() {
    let cases: [(&str, &str, &[&str]); 12] = [
        (
            "resolution: 0.05\norigin: [0, 0, 0]\n",
            "no-image",
            &["m.yaml", "`image`", "missing"],
        ),
        (
            "image: m.pgm\nresolution: fast\norigin: [0, 0, 0]\n",
            "bad-resolution",
            &["`resolution`", "line 2", "metres per cell", "fast"],
        ),
        (
            "image: m.pgm\nresolution: -0.05\norigin: [0, 0, 0]\n",
            "negative-resolution",
            &["`resolution`", "0.001 to 100 metres per cell", "-0.05"],
        ),
        // Corrupt digits that still parse (found by mutating a rover's map file): the
        // merge asked for more cells than memory holds.
        (
            "image: m.pgm\nresolution: 1e308\norigin: [0, 0, 0]\n",
            "huge-resolution",
            &["`resolution`", "line 2", "0.001 to 100 metres per cell"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 1e300, 0]\n",
            "far-origin",
            &["`origin`", "line 3", "at most 1e6 m"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n",
            "short-origin",
            &["`origin`", "three numbers"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: maybe\n",
            "bad-negate",
            &["`negate`", "0 or 1", "maybe"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 1.5\n",
            "bad-thresh",
            &["`free_thresh`", "between 0 and 1"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: raw\n",
            "raw-mode",
            &["`mode`", "trinary"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nresolutoin: 0.1\n",
            "typo",
            &["`resolutoin`", "line 4", "not a map_server field"],
        ),
        (
            "image: m.pgm\n  resolution: 0.05\n",
            "indented",
            &["m.yaml", "line 2", "indentation"],
        ),
        (
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nhazard_value: orange\n",
            "bad-hazard-value",
            &["`hazard_value`", "line 4", "pixel value", "orange"],
        ),
    ];
    for (yaml, name, wanted) in cases {
        let text = error_of(yaml, &good_pgm(), name);
        for w in wanted {
            assert!(text.contains(w), "{name}: `{w}` missing from: {text}");
        }
    }
}

#[test]
fn bad_images_name_the_image_and_the_problem() {
    let text = error_of(GOOD_YAML, b"P5\n3 2\n255\n\0\0", "short-pgm");
    assert!(
        text.contains("m.pgm") && text.contains("too short"),
        "{text}"
    );
    let text = error_of(GOOD_YAML, b"\x89PNG\r\n\x1a\n", "png");
    assert!(text.contains("m.pgm") && text.contains("P5"), "{text}");
    let dir = temp_dir("missing-image");
    let path = dir.join("m.yaml");
    std::fs::write(&path, GOOD_YAML).expect("yaml");
    let text = format!("{:#}", realms_merge::io::read(&path).expect_err("no image"));
    assert!(
        text.contains("m.pgm") && text.contains("cannot read"),
        "{text}"
    );
    let text = format!(
        "{:#}",
        realms_merge::io::read(&dir.join("absent.yaml")).expect_err("no yaml")
    );
    assert!(text.contains("absent.yaml"), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}
