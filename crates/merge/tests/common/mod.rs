//! Shared by the integration tests: where the recorded maps are, a lunar source map from
//! the simulator's ground truth, and how far an estimate may be from the answer.

#![allow(dead_code)]

use realms_core::{Grid, Point2, Pose2};
use realms_merge::synth::{self, Pair};
use realms_merge::{Estimate, Map, MapCell};
use realms_sim::{GroundTruth, Scenario, Terrain};
use std::path::PathBuf;

/// `../shared/data/maps` of the checkout (never copied into the repository).
pub fn maps_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/maps")
}

/// A recorded map by name.
pub fn recorded(name: &str) -> Map {
    let path = maps_dir().join(format!("{name}.yaml"));
    realms_merge::io::read(&path).unwrap_or_else(|e| {
        panic!(
            "{} must be readable (../shared/data present?): {e:#}",
            path.display()
        )
    })
}

/// The default arena of `seed` with `large` lidar-visible boulders and `small` rocks, as the
/// map a perfect sensor suite would build (lidar obstacles occupied, craters and low rocks
/// hazards, explorable ground free).
pub fn lunar(seed: u64, large: u32, small: u32) -> Grid<MapCell> {
    let mut sc = Scenario {
        seed,
        ..Scenario::default()
    };
    sc.boulders.large_count = large;
    sc.boulders.small_count = small;
    perfect_map(&sc)
}

/// The map a perfect sensor suite would build of the arena of `sc`.
fn perfect_map(sc: &Scenario) -> Grid<MapCell> {
    let terrain = Terrain::generate(sc);
    GroundTruth::derive(&terrain, sc)
        .perfect_map()
        .map(|v| MapCell::from_occupancy(*v))
}

/// The very sparse arena of `realms bench merge` (`lunar-very-sparse`): the default arena
/// of `seed` with 2 lidar-visible boulders, 30 rocks, one small and one large crater.
pub fn lunar_very_sparse(seed: u64) -> Grid<MapCell> {
    let mut sc = Scenario {
        seed,
        ..Scenario::default()
    };
    sc.boulders.large_count = 2;
    sc.boulders.small_count = 30;
    sc.craters.small_count = 1;
    sc.craters.large_count = 1;
    perfect_map(&sc)
}

/// Pair `index` of `realms bench merge --seed SEED` for kind `kind` at `overlap_pct`, cut
/// from `sources` (the kind's three arenas, from that seed on) as the bench cuts it.
pub fn bench_pair(
    sources: &[Grid<MapCell>],
    seed: u64,
    overlap_pct: u32,
    kind: &str,
    index: usize,
) -> Pair {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
        seed ^ (u64::from(overlap_pct) << 32) ^ kind.len() as u64,
    );
    let spec = synth::PairSpec {
        overlap: f64::from(overlap_pct) / 100.0,
        ..synth::PairSpec::default()
    };
    (0..=index)
        .map(|i| synth::make_pair(&sources[i % sources.len()], &spec, &mut rng))
        .last()
        .flatten()
        .expect("the sources have known cells")
}

/// Pair `index` of `realms bench merge --seed SEED` for a lunar kind (`lunar-sparse` or
/// `lunar-very-sparse`) at `overlap_pct`, cut from the kind's three arenas as the bench
/// builds them.
pub fn lunar_bench_pair(kind: &str, seed: u64, overlap_pct: u32, index: usize) -> Pair {
    let sources: Vec<_> = (seed..seed + 3)
        .map(|s| match kind {
            "lunar-sparse" => lunar(s, 5, 120),
            "lunar-very-sparse" => lunar_very_sparse(s),
            other => panic!("not a lunar kind of the bench: {other}"),
        })
        .collect();
    bench_pair(&sources, seed, overlap_pct, kind, index)
}

/// Translation error at the second map's known centre (metres) and heading error (radians).
pub fn error(found: &Pose2, truth: &Pose2, b: &Map) -> (f64, f64) {
    let centre: Point2 = b
        .frame_from_grid()
        .transform_point(b.known_centroid_in_grid());
    synth::pose_error(found, truth, centre)
}

/// Whether an estimate is within 3 cells (at its centre) and 2 degrees of the truth.
pub fn close(found: &Pose2, truth: &Pose2, b: &Map) -> bool {
    let (m, rad) = error(found, truth, b);
    m < 3.0 * b.geometry().resolution_m && rad < 2f64.to_radians()
}

/// An accepted estimate must be right: panics on a wrong merge; returns whether accepted.
pub fn accepted_and_right(est: &Estimate, pair: &Pair, what: &str) -> bool {
    match est.accepted() {
        Some(p) => {
            let (m, rad) = error(&p, &pair.a_from_b, &pair.b);
            assert!(
                close(&p, &pair.a_from_b, &pair.b),
                "{what}: WRONG merge accepted: off by {m:.2} m, {:.2} deg (confidence {:.2})",
                rad.to_degrees(),
                est.confidence
            );
            true
        }
        None => false,
    }
}
