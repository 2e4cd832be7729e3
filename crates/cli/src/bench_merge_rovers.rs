//! The rovers' own maps as merging cases for `realms bench merge` (kinds `lunar-rovers` and
//! `lunar-rovers-known-start`).
//!
//! The generated pairs cut both maps from one source, so they agree wherever they overlap.
//! Maps that two rovers built agree far less: each carries its own SLAM drift (a few
//! centimetres to a few decimetres), its own artefacts (a lidar ring on the floor where the
//! rover pitched), and hazards only where its depth camera looked, while its lidar clears
//! ground metres beyond. Here default missions are run over the simulated radio, as
//! `realms mission` runs them, and every few minutes each pair of rovers' maps is taken as
//! the lander holds them. The rovers start at known places, so their maps share one frame:
//! the answer is the identity, up to the maps' own drift.

use crate::bench::in_parallel;
use realms_core::{Pose2, RoverId, Time};
use realms_merge::Map;
use realms_mission::{Mission, MissionOptions};
use realms_net::NodeAddr;
use realms_node::lander_merge::to_merge_map;
use realms_sim::{Scenario, World};

/// How often the lander's copies of the maps are taken, simulated seconds.
pub const SNAPSHOT_EVERY_S: f64 = 300.0;
/// Missions are cut off here if exploration has not ended, simulated seconds.
const MAX_MISSION_S: f64 = 3600.0;

/// Two rovers' maps at one moment of one mission, in their shared frame.
pub struct RoverPair {
    /// The first rover's map.
    pub a: Map,
    /// The second rover's map.
    pub b: Map,
    /// Share of the smaller map's known cells that the other map knows too.
    pub overlap: f64,
    /// Which mission, moment and rovers, for the verbose lines.
    pub label: String,
}

/// Every pair of rovers' maps, every [`SNAPSHOT_EVERY_S`], in default missions of `seeds`
/// (run two at a time).
pub fn rover_pairs(seeds: &[u64]) -> Vec<RoverPair> {
    let mut per_mission = in_parallel(seeds, 2, |&seed| (seed, mission_pairs(seed)));
    per_mission.sort_by_key(|(seed, _)| *seed);
    per_mission.into_iter().flat_map(|(_, p)| p).collect()
}

fn mission_pairs(seed: u64) -> Vec<RoverPair> {
    let scenario = Scenario {
        seed,
        ..Scenario::default()
    };
    let world = World::new(&scenario);
    let ids: Vec<RoverId> = world.rovers().map(|r| r.id).collect();
    let mut mission = Mission::with_options(world, MissionOptions::default());
    let end_s = scenario.duration_s.min(MAX_MISSION_S);
    let mut pairs = Vec::new();
    let mut t = 0.0;
    while t < end_s && !mission.exploration_over() {
        t += SNAPSHOT_EVERY_S;
        mission.run_until(Time::from_secs_f64(t));
        let Some(lander) = mission.station(NodeAddr::Lander) else {
            break;
        };
        let maps: Vec<(RoverId, Map)> = ids
            .iter()
            .filter_map(|id| lander.map(*id).map(|g| (*id, to_merge_map(g))))
            .collect();
        for (i, (ra, a)) in maps.iter().enumerate() {
            for (rb, b) in &maps[i + 1..] {
                pairs.push(RoverPair {
                    overlap: overlap_share(a, b),
                    a: a.clone(),
                    b: b.clone(),
                    label: format!("seed {seed} at {t:.0} s, {ra} and {rb}"),
                });
            }
        }
    }
    pairs
}

/// Share of the smaller map's known cells that the other map also knows, the two maps
/// taken in one frame.
pub fn overlap_share(a: &Map, b: &Map) -> f64 {
    let (small, large) = if a.known_cells() <= b.known_cells() {
        (a, b)
    } else {
        (b, a)
    };
    let to_large = large
        .frame_from_grid()
        .inverse()
        .compose(&small.frame_from_grid());
    let (mut known, mut shared) = (0usize, 0usize);
    for (cell, v) in small.cells.iter() {
        if v.is_known() {
            known += 1;
            let p = to_large.transform_point(small.cell_centre_in_grid(cell));
            shared += usize::from(large.knows_in_grid(p));
        }
    }
    shared as f64 / known.max(1) as f64
}

/// The answer for a pair of rovers' maps: their frames coincide.
pub const TRUTH: Pose2 = Pose2::IDENTITY;
