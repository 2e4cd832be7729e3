//! `realms bench slam`: the rovers' SLAM run again on exactly what their sensors gave in a
//! mission, graded against the truth, and timed on its own.
//!
//! A mission's SLAM steers its rover, so two missions with different SLAM drive different
//! paths, and a change's effect on the error drowns in the chaos of exploration (single runs
//! move by a factor of two either way, BENCHMARKS.md). Here each seed's mission is run once
//! with its sensor messages captured ([`Mission::capture_slam_inputs`]); then every SLAM
//! variant asked for is fed the same messages in the same order, so differences between
//! variants are SLAM's alone. The wall time of each replay is SLAM's cost alone too (the
//! mission's own figure also counts drawing the planner's map).

use crate::bench::{in_parallel, median, pooled};
use crate::bench_slam_closures;
use crate::bench_slam_drift::{BAND_EDGES_M, Band, WINDOW_SCANS, drift_by_band};
use crate::cli::BenchSlamArgs;
use crate::mission::{load_scenario, parse_duration_s};
use anyhow::{Context, Result, bail};
use realms_core::msgs::{LaserScan, LocalisationState, Message, OccupancyGrid};
use realms_core::{Duration, Point2, Pose2, RoverId, Time};
use realms_mission::slam_record::{
    CRATER_BANDS, CREST_SLACK_M, CraterCells, MapGrade, PATH_REACH_M, PoseErrors, aligned_rmse,
    crater_cells, grade_grid, map_grid, pose_errors,
};
use realms_mission::{CapturedInput, Mission, MissionOptions, replay_slam, rover_mapping_config};
use realms_node::mapping::{Mapping, MappingConfig, RELIEF_REFERENCE_TRAVEL_M, ReliefHop};
use realms_sim::{GroundTruth, World};
use realms_slam::mapper::ClosureWeighting;
use std::time::Instant;

/// A named change to the rovers' SLAM setup, compared against the setup as it is.
pub(crate) struct Variant {
    pub(crate) name: &'static str,
    pub(crate) what: &'static str,
    pub(crate) apply: fn(&mut MappingConfig),
}

/// A setup to compare against the one as it is: one variant, or several applied in turn.
pub(crate) struct Setup {
    /// The variants' names joined by `+`, as asked for.
    pub(crate) name: String,
    /// What each variant changes, in turn.
    pub(crate) what: String,
    /// The variants' changes, applied in the order they were named.
    pub(crate) changes: Vec<fn(&mut MappingConfig)>,
}

impl Setup {
    /// Applies every change of the setup to `c`.
    pub(crate) fn apply(&self, c: &mut MappingConfig) {
        for change in &self.changes {
            change(c);
        }
    }
}

/// The changes a mission's rovers run with for an optional setup (`--variant`): none
/// without one.
pub(crate) fn mapping_changes(setup: Option<&Setup>) -> Vec<fn(&mut MappingConfig)> {
    setup.map_or_else(Vec::new, |v| v.changes.clone())
}

/// A mission's scenario `source` as its report names it, with the setup its rovers ran,
/// if any.
pub(crate) fn with_setup(source: String, setup: Option<&Setup>) -> String {
    match setup {
        Some(v) => format!("{source}, SLAM variant {} ({})", v.name, v.what),
        None => source,
    }
}

/// The setup called `name`: a variant's name, or several joined by `+` (applied in that
/// order, so a later one wins where two set the same field); an error names any unknown one
/// and lists the known ones.
pub(crate) fn variant(name: &str) -> Result<Setup> {
    let mut parts = Vec::new();
    for part in name.split('+') {
        match VARIANTS.iter().find(|v| v.name == part) {
            Some(v) => parts.push(v),
            None => bail!(
                "unknown variant `{part}` in `{name}`; known (join several with `+`): {}",
                VARIANTS
                    .iter()
                    .map(|v| v.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
    Ok(Setup {
        name: name.to_owned(),
        what: parts
            .iter()
            .map(|v| v.what)
            .collect::<Vec<_>>()
            .join("; then "),
        changes: parts.iter().map(|v| v.apply).collect(),
    })
}

/// The position held to the wheels' prediction where the map pins it weakly (floor 100 per
/// point), the pull gated at `gate_m`, the slip check hearing each match from the previous
/// one (its own if `own_match`).
fn held_where_weak(c: &mut MappingConfig, gate_m: Option<f64>, own_match: bool) {
    c.mapper.weak_direction_floor = Some(100.0);
    c.mapper.weak_direction_gate_m = gate_m;
    c.mapper.slip_check_match_to_match = true;
    c.mapper.slip_check_own_match = own_match;
}

/// The wheel scale the median of the last `segments` pinned segments, if the setup learns
/// one.
fn slip_segments(c: &mut MappingConfig, segments: usize) {
    if let Some(s) = &mut c.mapper.slip_calibration {
        s.segments = segments;
    }
}

/// Changes the refinement on the hits, if the setup has one.
fn on_refinement(c: &mut MappingConfig, change: impl FnOnce(&mut realms_slam::ndt::NdtConfig)) {
    if let Some(n) = &mut c.mapper.ndt_refine {
        change(n);
    }
}

/// The refinement clamped to its bounds along the wheels' travel, `ahead_m` the one ahead.
fn clamped_along_travel(c: &mut MappingConfig, ahead_m: Option<f64>) {
    on_refinement(c, |n| {
        n.clamp_along_travel = true;
        n.max_push_ahead_m = ahead_m;
    });
}

/// The variants `--variant` may name (the setup as it is, `baseline`, always runs).
const VARIANTS: &[Variant] = &[
    Variant {
        name: "no-loop-closure",
        what: "no closure search (tracking against submaps only)",
        apply: |c| c.mapper.loop_candidates = 0,
    },
    Variant {
        name: "match-covariance",
        what: "the pose published with the covariance of the last match alone, as before the drift along the graph was counted (nothing else changes)",
        apply: |c| c.mapper.pose_uncertainty = None,
    },
    Variant {
        name: "no-densify",
        what: "scans not filled in between beams",
        apply: |c| c.mapper.frontend.densify = None,
    },
    Variant {
        name: "fill-untraced",
        what: "free space traced into the submaps along the beams only; the points filled in between them marked hit without a beam of their own",
        apply: |c| c.mapper.frontend.trace_filled = false,
    },
    Variant {
        name: "optimize-every-40",
        what: "accepted closures folded into the graph at every 40th keyframe, not every 20th",
        apply: |c| c.mapper.optimize_every_keyframes = 40,
    },
    Variant {
        name: "optimize-every-10",
        what: "accepted closures folded into the graph at every 10th keyframe, not every 20th",
        apply: |c| c.mapper.optimize_every_keyframes = 10,
    },
    Variant {
        name: "optimize-every-2",
        what: "accepted closures folded into the graph at once (closures are searched at every 2nd keyframe), not at every 20th",
        apply: |c| c.mapper.optimize_every_keyframes = 2,
    },
    Variant {
        name: "graph-steps-2",
        what: "the pose graph optimised by 2 Gauss-Newton steps, not 3",
        apply: |c| c.mapper.graph_iterations = 2,
    },
    Variant {
        name: "graph-steps-1",
        what: "the pose graph optimised by 1 Gauss-Newton step, not 3",
        apply: |c| c.mapper.graph_iterations = 1,
    },
    Variant {
        name: "graph-steps-1-track-in-submap",
        what: "graph-steps-1 and track-in-submap together (the active submaps' keyframes kept as their cells were drawn)",
        apply: |c| {
            c.mapper.graph_iterations = 1;
            c.mapper.track_in_submap_frame = true;
        },
    },
    Variant {
        name: "graph-later-100",
        what: "block-jacobi, with the Gauss-Newton steps after the first stopped after 100 iterations, not 500",
        apply: |c| {
            c.mapper.graph_solver = realms_slam::posegraph::GraphSolver::BlockJacobi;
            c.mapper.graph_later_cap = Some(100);
        },
    },
    Variant {
        name: "closures-every-4",
        what: "closures searched at every fourth keyframe, not every second",
        apply: |c| c.mapper.loop_every_keyframes = 4,
    },
    Variant {
        name: "no-gyro-edges",
        what: "graph edges between keyframes take the matched turn, weighted like closures",
        apply: |c| c.mapper.gyro_heading = None,
    },
    Variant {
        name: "blind-travel-as-matched",
        what: "wheel travel with too few returns to match counts as matched travel (edges and closure bounds)",
        apply: |c| c.mapper.blind_travel_uncertain = false,
    },
    Variant {
        name: "heading-prior-x100",
        what: "the matcher's pull towards the gyro's heading 100 times as strong",
        apply: |c| c.mapper.frontend.matcher.prior_rotation_weight *= 100.0,
    },
    Variant {
        name: "raw-ranges",
        what: "ranges as the lidar gave them, not averaged with their neighbours",
        apply: |c| c.smooth_ranges = false,
    },
    Variant {
        name: "weak-hops-30",
        what: "sequential edges along the heading loosened by 30 % of the hop's unpinned travel",
        apply: |c| c.mapper.weak_hop_share = Some(0.3),
    },
    Variant {
        name: "weak-hops-100",
        what: "sequential edges along the heading loosened by all of the hop's unpinned travel",
        apply: |c| c.mapper.weak_hop_share = Some(1.0),
    },
    Variant {
        name: "weak-hops-300",
        what: "sequential edges along the heading loosened by three times the hop's unpinned travel",
        apply: |c| c.mapper.weak_hop_share = Some(3.0),
    },
    Variant {
        name: "weak-hops-100-chain",
        what: "weak-hops-100, the pose graph solved to the optimum by the chain-preconditioned solver",
        apply: |c| {
            c.mapper.weak_hop_share = Some(1.0);
            c.mapper.graph_solver = realms_slam::posegraph::GraphSolver::Chain;
        },
    },
    Variant {
        name: "closure-ridges",
        what: "closures whose only rivals lie on a ridge of the score from the winner taken, held along the ridge as the score falls",
        apply: |c| c.mapper.closure_ridges = Some(realms_slam::mapper::ClosureRidges::default()),
    },
    Variant {
        name: "closure-ridges-across",
        what: "closure-ridges, the closures held across the ridge and in heading only, not along it",
        apply: |c| {
            c.mapper.closure_ridges = Some(realms_slam::mapper::ClosureRidges {
                reference_m: 0.0,
                ..realms_slam::mapper::ClosureRidges::default()
            })
        },
    },
    Variant {
        name: "closure-ridges-loose",
        what: "closure-ridges, held along the ridge a quarter as firmly (reference 0.15 m)",
        apply: |c| {
            c.mapper.closure_ridges = Some(realms_slam::mapper::ClosureRidges {
                reference_m: 0.15,
                ..realms_slam::mapper::ClosureRidges::default()
            })
        },
    },
    Variant {
        name: "no-deskew",
        what: "a sweeping lidar's beams all taken as seen at the scan's last beam, the rover's motion during the sweep left in",
        apply: |c| c.deskew = false,
    },
    Variant {
        name: "chain-solver",
        what: "the pose graph solved by conjugate gradients preconditioned by the chain of poses, to the optimum, not exactly by elimination",
        apply: |c| c.mapper.graph_solver = realms_slam::posegraph::GraphSolver::Chain,
    },
    Variant {
        name: "block-jacobi",
        what: "the pose graph's Gauss-Newton steps solved by conjugate gradients preconditioned by block-Jacobi, stopped after 500 iterations, not exactly by elimination (the rovers' default before the fifty-eighth session)",
        apply: |c| c.mapper.graph_solver = realms_slam::posegraph::GraphSolver::BlockJacobi,
    },
    Variant {
        name: "dcs",
        what: "closures discounted by dynamic covariance scaling (phi 5) rather than Huber's loss",
        apply: |c| {
            c.mapper.graph_loss =
                realms_slam::posegraph::RobustLoss::DynamicCovarianceScaling { phi: 5.0 };
        },
    },
    Variant {
        name: "track-in-submap",
        what: "after an optimisation, the active submaps' keyframes keep the poses their cells were drawn with, moved as one block (as on the recorded logs)",
        apply: |c| c.mapper.track_in_submap_frame = true,
    },
    Variant {
        name: "chain-and-track-in-submap",
        what: "chain-solver and track-in-submap together",
        apply: |c| {
            c.mapper.graph_solver = realms_slam::posegraph::GraphSolver::Chain;
            c.mapper.track_in_submap_frame = true;
        },
    },
    Variant {
        name: "tilt-newest",
        what: "the lidar's returns and the depth camera's points levelled by the newest accelerometer sample alone, not a 0.1 s average",
        apply: |c| c.tilt_smoothing = 1.0,
    },
    Variant {
        name: "tilt-less-wheels",
        what: "the wheels' acceleration (their speed read over 0.2 s) taken out of each accelerometer sample before it goes into the tilt",
        apply: |c| c.tilt_less_wheels = Some(Duration::from_millis(200)),
    },
    Variant {
        name: "tilt-less-wheels-400",
        what: "the wheels' acceleration (their speed read over 0.4 s) taken out of each accelerometer sample before it goes into the tilt",
        apply: |c| c.tilt_less_wheels = Some(Duration::from_millis(400)),
    },
    Variant {
        name: "tilt-less-wheels-100",
        what: "the wheels' acceleration (their speed read over 0.1 s) taken out of each accelerometer sample before it goes into the tilt",
        apply: |c| c.tilt_less_wheels = Some(Duration::from_millis(100)),
    },
    Variant {
        name: "tilt-gyro",
        what: "the tilt carried between accelerometer samples by the gyro's roll and pitch rates, each sample taken in at 0.02 of its departure (about 1 s)",
        apply: |c| {
            c.tilt_gyro = true;
            c.tilt_smoothing = 0.02;
        },
    },
    Variant {
        name: "tilt-gyro-05",
        what: "the tilt carried between accelerometer samples by the gyro's roll and pitch rates, each sample taken in at 0.05 of its departure (about 0.4 s)",
        apply: |c| {
            c.tilt_gyro = true;
            c.tilt_smoothing = 0.05;
        },
    },
    Variant {
        name: "tilt-half",
        what: "the lidar's returns and the depth camera's points levelled by an average of the accelerometer taking half of each new sample",
        apply: |c| c.tilt_smoothing = 0.5,
    },
    Variant {
        name: "push-ahead-2cm",
        what: "a refinement on the hits moving the match forward along the wheels' travel by more than 2 cm not taken (as one moving it back by more than 2 cm is not)",
        apply: |c| on_refinement(c, |n| n.max_push_ahead_m = Some(0.02)),
    },
    Variant {
        name: "push-ahead-3cm",
        what: "push-ahead-2cm with 3 cm forward",
        apply: |c| on_refinement(c, |n| n.max_push_ahead_m = Some(0.03)),
    },
    Variant {
        name: "push-ahead-weak-2cm",
        what: "push-ahead-2cm only where the occupancy match pins the travel less than 5 times as firmly as the matcher's pull towards the wheels",
        apply: |c| {
            c.mapper.push_ahead_where_weak = Some(realms_slam::mapper::PushAheadWhereWeak {
                min_ratio: 5.0,
                max_ahead_m: 0.02,
            })
        },
    },
    Variant {
        name: "clamp-hold-back",
        what: "a refinement holding the match back more than 2 cm against the wheels' travel is brought back to 2 cm along the travel, keeping its turn and its move across the travel, instead of being dropped",
        apply: |c| clamped_along_travel(c, None),
    },
    Variant {
        name: "clamp-2cm",
        what: "clamp-hold-back, and a refinement moving the match more than 2 cm ahead of the wheels' travel is brought back to 2 cm the same way",
        apply: |c| clamped_along_travel(c, Some(0.02)),
    },
    Variant {
        name: "clamp-3cm",
        what: "clamp-2cm with 3 cm ahead",
        apply: |c| clamped_along_travel(c, Some(0.03)),
    },
    Variant {
        name: "final-hits-within-6m",
        what: "the final map draws every finished submap again with hits out to 6 m only (free space out to 6 m beyond)",
        apply: |c| c.mapper.final_map_hit_range_m = Some(6.0),
    },
    Variant {
        name: "final-hits-within-8m",
        what: "final-hits-within-6m at 8 m",
        apply: |c| c.mapper.final_map_hit_range_m = Some(8.0),
    },
    Variant {
        name: "final-hits-within-12m",
        what: "final-hits-within-6m at 12 m (the lidar's reach): every finished submap drawn again, every hit",
        apply: |c| c.mapper.final_map_hit_range_m = Some(12.0),
    },
    Variant {
        name: "occupied-above-1.8",
        what: "a map cell counts as occupied only with summed log-odds above 1.8, not 0.5 (one hit of one keyframe in two submaps sums to 1.69)",
        apply: |c| c.mapper.map_occupied_above = 1.8,
    },
    Variant {
        name: "occupied-above-1.0",
        what: "a map cell counts as occupied only with summed log-odds above 1.0, not 0.5",
        apply: |c| c.mapper.map_occupied_above = 1.0,
    },
    Variant {
        name: "occupied-above-3.0",
        what: "a map cell counts as occupied only with summed log-odds above 3.0, not 0.5",
        apply: |c| c.mapper.map_occupied_above = 3.0,
    },
    Variant {
        name: "push-ahead-1cm",
        what: "push-ahead-2cm with 1 cm forward",
        apply: |c| on_refinement(c, |n| n.max_push_ahead_m = Some(0.01)),
    },
    Variant {
        name: "no-ndt-refine",
        what: "tracking matches taken from the occupancy grid as they are, not refined on the submap's hits",
        apply: |c| c.mapper.ndt_refine = None,
    },
    Variant {
        name: "depth-features",
        what: "the depth camera's points in hazard cells refined on and kept in the hits, beside the lidar's points",
        apply: |c| c.depth_features = true,
    },
    Variant {
        name: "no-still-hold",
        what: "a rover turning in place matched with the usual pull towards the wheels' position, not held to it",
        apply: |c| c.mapper.still_hold = None,
    },
    Variant {
        name: "still-hold-30",
        what: "a rover turning in place pulled towards the wheels' position with a translation prior of 30 per point per m^2, not held to it",
        apply: |c| {
            c.mapper.still_hold = Some(realms_slam::mapper::StillHold {
                below_m: 0.002,
                translation_weight: 30.0,
                hold_heading: false,
            })
        },
    },
    Variant {
        name: "refine-pinned-30",
        what: "the refinement on the hits moves the match only along directions the occupancy match pins at 30 per point per m^2 or more",
        apply: |c| c.mapper.refine_only_where_pinned = Some(30.0),
    },
    Variant {
        name: "refine-pinned-100",
        what: "the refinement on the hits moves the match only along directions the occupancy match pins at 100 per point per m^2 or more",
        apply: |c| c.mapper.refine_only_where_pinned = Some(100.0),
    },
    Variant {
        name: "line-hits-10",
        what: "the refinement's cells pull as lines only with 10 hits or more (not 4); fewer along a line pull not at all",
        apply: |c| on_refinement(c, |n| n.min_line_hits = 10),
    },
    Variant {
        name: "line-hits-20",
        what: "the refinement's cells pull as lines only with 20 hits or more (not 4); fewer along a line pull not at all",
        apply: |c| on_refinement(c, |n| n.min_line_hits = 20),
    },
    Variant {
        name: "no-weak-floor",
        what: "the position not held to the prediction where the map is weak, and the slip check hearing each match from the pose (the rovers' setup before the fifty-sixth session)",
        apply: |c| {
            c.mapper.weak_direction_floor = None;
            c.mapper.slip_check_match_to_match = false;
            c.mapper.slip_check_own_match = false;
        },
    },
    Variant {
        name: "start-rivals-0.5m",
        what: "a closure into a submap begun at the known start counts a rival only 0.5 m or more from the winner (not 0.3 m) at any time (the rovers do so only while they drive home at the end or are home)",
        apply: |c| {
            c.mapper.start_rivals_beyond_m = Some(0.5);
            c.mapper.start_rivals_homing_only = false;
        },
    },
    Variant {
        name: "start-rivals-0.75m",
        what: "a closure into a submap begun at the known start counts a rival only 0.75 m or more from the winner (not 0.3 m) at any time",
        apply: |c| {
            c.mapper.start_rivals_beyond_m = Some(0.75);
            c.mapper.start_rivals_homing_only = false;
        },
    },
    Variant {
        name: "no-home-rivals",
        what: "a closure into a submap begun at the known start counts a rival 30 cm off as any other closure does, also while the rover drives home at the end (the rovers' setup before the eighty-seventh session)",
        apply: |c| c.mapper.start_rivals_beyond_m = None,
    },
    Variant {
        name: "weak-floor-30",
        what: "where the map pins the position less than 30 per point per m^2 in some direction, the position there pulled towards the prediction as if it did",
        apply: |c| c.mapper.weak_direction_floor = Some(30.0),
    },
    Variant {
        name: "weak-floor-100",
        what: "where the map pins the position less than 100 per point per m^2 in some direction, the position there pulled towards the prediction as if it did",
        apply: |c| c.mapper.weak_direction_floor = Some(100.0),
    },
    Variant {
        name: "weak-floor-300",
        what: "where the map pins the position less than 300 per point per m^2 in some direction, the position there pulled towards the prediction as if it did",
        apply: |c| c.mapper.weak_direction_floor = Some(300.0),
    },
    Variant {
        name: "weak-floor-1000",
        what: "where the map pins the position less than 1000 per point per m^2 in some direction, the position there pulled towards the prediction as if it did",
        apply: |c| c.mapper.weak_direction_floor = Some(1000.0),
    },
    Variant {
        name: "slip-segments-7",
        what: "the wheel scale the median of the last 7 pinned segments, not 15 (a scale that follows the soil sooner)",
        apply: |c| slip_segments(c, 7),
    },
    Variant {
        name: "slip-segments-31",
        what: "the wheel scale the median of the last 31 pinned segments, not 15 (a scale that follows a segment whose matches slid less)",
        apply: |c| slip_segments(c, 31),
    },
    Variant {
        name: "weak-floor-100-chain",
        what: "weak-floor-100, the slip check hearing each match's motion from the previous match",
        apply: |c| held_where_weak(c, None, false),
    },
    Variant {
        name: "weak-floor-100-gate-2cm",
        what: "weak-floor-100-chain, the pull only where the match lies within 2 cm of the prediction along the weak direction",
        apply: |c| held_where_weak(c, Some(0.02), false),
    },
    Variant {
        name: "weak-floor-100-gate-3cm",
        what: "weak-floor-100-chain, the pull only where the match lies within 3 cm of the prediction along the weak direction",
        apply: |c| held_where_weak(c, Some(0.03), false),
    },
    Variant {
        name: "weak-floor-100-gate-3cm-own",
        what: "weak-floor-100-gate-3cm, the slip check's matches its own, each started from its last one",
        apply: |c| held_where_weak(c, Some(0.03), true),
    },
    Variant {
        name: "weak-floor-100-own",
        what: "weak-floor-100, the slip check's matches its own, each started from its last one",
        apply: |c| held_where_weak(c, None, true),
    },
    Variant {
        name: "prior-x30",
        what: "the matcher's pull towards the predicted position 30 times as strong (90 per point per m^2)",
        apply: |c| c.mapper.frontend.matcher.prior_translation_weight *= 30.0,
    },
    Variant {
        name: "prior-x100",
        what: "the matcher's pull towards the predicted position 100 times as strong (300 per point per m^2)",
        apply: |c| c.mapper.frontend.matcher.prior_translation_weight *= 100.0,
    },
    Variant {
        name: "drop-closures-16",
        what: "closures the optimised graph leaves more than 16 (squared Mahalanobis: 0.2 m at the closures' 5 cm) off are dropped and the graph optimised again",
        apply: |c| c.mapper.drop_closures_beyond = Some(16.0),
    },
    Variant {
        name: "drop-closures-9",
        what: "drop-closures-16 at 9 (0.15 m at 5 cm)",
        apply: |c| c.mapper.drop_closures_beyond = Some(9.0),
    },
    Variant {
        name: "closure-weighting-2000",
        what: "loop closures weighed by their match: along a direction the refined match's information is under 2,000, the closure's falls in proportion",
        apply: |c| {
            c.mapper.closure_weighting = Some(ClosureWeighting {
                translation_reference: 2000.0,
                heading_reference: None,
            })
        },
    },
    Variant {
        name: "closure-weighting-8000",
        what: "closure-weighting-2000 at 8,000",
        apply: |c| {
            c.mapper.closure_weighting = Some(ClosureWeighting {
                translation_reference: 8000.0,
                heading_reference: None,
            })
        },
    },
    Variant {
        name: "closure-weighting-2000-heading",
        what: "closure-weighting-2000, and the heading's information falls in proportion under 100,000",
        apply: |c| {
            c.mapper.closure_weighting = Some(ClosureWeighting {
                translation_reference: 2000.0,
                heading_reference: Some(1e5),
            })
        },
    },
    Variant {
        name: "same-submap-confirmation",
        what: "a loop closure asking to move its keyframe more than 0.5 m may be confirmed by a partner into the same submap (the rovers' setup before the sixtieth session)",
        apply: |c| c.mapper.distinct_confirmation_beyond_m = None,
    },
    Variant {
        name: "closure-min-information-500",
        what: "loop closures whose refined match's weakest translation information is under 500 not taken",
        apply: |c| c.mapper.closure_min_information = Some(500.0),
    },
    Variant {
        name: "closure-min-information-800",
        what: "loop closures whose refined match's weakest translation information is under 800 not taken",
        apply: |c| c.mapper.closure_min_information = Some(800.0),
    },
    Variant {
        name: "closure-min-information-1200",
        what: "loop closures whose refined match's weakest translation information is under 1200 not taken",
        apply: |c| c.mapper.closure_min_information = Some(1200.0),
    },
    Variant {
        name: "closure-min-information-500-weighting-2000",
        what: "closure-min-information-500 and closure-weighting-2000",
        apply: |c| {
            c.mapper.closure_min_information = Some(500.0);
            c.mapper.closure_weighting = Some(ClosureWeighting {
                translation_reference: 2000.0,
                heading_reference: None,
            })
        },
    },
    Variant {
        name: "redraw-bent-5cm",
        what: "after each optimisation, finished submaps whose keyframes moved over 5 cm or 1 deg relative to their first drawn again from them",
        apply: |c| {
            c.mapper.redraw_bent_submaps = Some(realms_slam::mapper::SubmapBend {
                translation_m: 0.05,
                rotation_rad: 1f64.to_radians(),
            })
        },
    },
    Variant {
        name: "redraw-bent-2cm",
        what: "redraw-bent-5cm at 2 cm or 0.4 deg",
        apply: |c| {
            c.mapper.redraw_bent_submaps = Some(realms_slam::mapper::SubmapBend {
                translation_m: 0.02,
                rotation_rad: 0.4f64.to_radians(),
            })
        },
    },
    Variant {
        name: "closure-from-nearest",
        what: "a loop closure measured from the submap's keyframe drawn nearest where it matched, not from the submap's first keyframe",
        apply: |c| c.mapper.closure_from_nearest_drawn = true,
    },
    Variant {
        name: "closure-share-30",
        what: "the n-th loop closure joining keyframes within 30 of an earlier closure's two ends weighs 1/n",
        apply: |c| c.mapper.closure_share_span = Some(30),
    },
    Variant {
        name: "closure-share-10",
        what: "closure-share-30 within 10 keyframes",
        apply: |c| c.mapper.closure_share_span = Some(10),
    },
    Variant {
        name: "surface-turn-10deg",
        what: "a scan point on a straight run of the scan not paired with a line cell whose line turns more than 10 deg from the run (a wall drawn at two offsets tilts its cells)",
        apply: |c| on_refinement(c, |n| n.max_surface_turn_rad = Some(10f64.to_radians())),
    },
    Variant {
        name: "min-hits-20",
        what: "the refinement's cells pull only with 20 hits or more, not 4 (a cell of a few hits along a wall can look like a line across it)",
        apply: |c| on_refinement(c, |n| n.min_hits = 20),
    },
    Variant {
        name: "tilt-spread-10mm",
        what: "the refinement counts each hit as spread 1 cm in every direction per metre of range (a rock's outline moves as the lidar's plane tilts)",
        apply: |c| on_refinement(c, |n| n.tilt_spread_per_m = 0.010),
    },
    Variant {
        name: "tilt-beam-10mm",
        what: "the refinement counts each hit as spread 1 cm along its beam (only) per metre of range (a rock's outline moves along the line of sight as the lidar's plane tilts)",
        apply: |c| {
            on_refinement(c, |n| {
                n.tilt_spread_per_m = 0.010;
                n.tilt_spread_along_beam = true;
            })
        },
    },
    Variant {
        name: "outline-shift-4",
        what: "the refinement counts each hit as spread along its beam by 4 m per metre its levelled height differs from its cell's hits' (a rock cut higher by the tilting lidar is cut narrower)",
        apply: |c| on_refinement(c, |n| n.outline_shift_per_height = 4.0),
    },
    Variant {
        name: "relief",
        what: "each depth frame fitted onto an earlier one's relief (measured only: the SLAM does not use it yet)",
        apply: |c| c.relief_odometry = Some(realms_slam::relief::ReliefConfig::default()),
    },
    Variant {
        name: "min-points-6",
        what: "scans of 6 endpoints or more matched and mapped, not 10 (far from the walls the lidar may see a rock or two and nothing else); closures and relocalisation still from 10",
        apply: |c| c.mapper.min_scan_points = 6,
    },
    Variant {
        name: "min-points-4",
        what: "min-points-6 at 4 endpoints",
        apply: |c| c.mapper.min_scan_points = 4,
    },
    Variant {
        name: "slip-fraction-40",
        what: "odometry unreliable once scan matching falls short of the wheels by 40 % of their travel over the window, not 50 %",
        apply: |c| c.mapper.health.slip_fraction = 0.4,
    },
    Variant {
        name: "slip-confirm-0.2s",
        what: "a disagreement between the wheels and scan matching confirmed after 0.2 s, not 0.3 s",
        apply: |c| c.mapper.health.confirm_s = 0.2,
    },
    Variant {
        name: "slow-window-6s",
        what: "odometry checked against scan matching over the last 6 s as well as the last 2 s (a rover creeping through a burst)",
        apply: |c| c.mapper.health.slow_window_s = Some(6.0),
    },
    Variant {
        name: "no-walls",
        what: "neither the walls' heading measurements (nor their closure check) nor the closures widened across unpinned travel: the rovers' SLAM before the forty-fourth session",
        apply: |c| {
            c.mapper.wall_headings = None;
            c.mapper.weak_travel = None;
        },
    },
    Variant {
        name: "no-weak-travel",
        what: "closures searched and allowed as far as the path can have drifted, unpinned travel counted like any other",
        apply: |c| c.mapper.weak_travel = None,
    },
    Variant {
        name: "no-wall-gate",
        what: "closures not checked against the turn the walls measured between their two keyframes",
        apply: |c| {
            if let Some(walls) = &mut c.mapper.wall_headings {
                walls.closure_gate_sigmas = None;
            }
        },
    },
    Variant {
        name: "wall-heading-optimizes-2",
        what: "a keyframe whose heading the walls measure more than 2 standard deviations off the tracked one has the graph optimised at the next batch, as a closure would",
        apply: |c| c.mapper.optimize_on_wall_heading_sigmas = Some(2.0),
    },
    Variant {
        name: "wall-heading-optimizes-3",
        what: "wall-heading-optimizes-2 at 3 standard deviations",
        apply: |c| c.mapper.optimize_on_wall_heading_sigmas = Some(3.0),
    },
    Variant {
        name: "walls-square",
        what: "the walls at right angles to those the first scan saw hold the heading too (a hall's walls meet square)",
        apply: |c| {
            if let Some(walls) = &mut c.mapper.wall_headings {
                walls.square_references = true;
            }
        },
    },
    Variant {
        name: "wall-headings-1deg",
        what: "each keyframe's heading the walls measured trusted to 1 deg at most, not 0.5",
        apply: |c| {
            if let Some(walls) = &mut c.mapper.wall_headings {
                walls.floor_sigma_rad = 1f64.to_radians();
            }
        },
    },
    Variant {
        name: "still-turn-on-gyro",
        what: "a rover turning in place takes its heading from the gyro's turn, not the match, as it takes its position from the wheels",
        apply: |c| {
            if let Some(hold) = &mut c.mapper.still_hold {
                hold.hold_heading = true;
            }
        },
    },
    Variant {
        name: "gyro-turns-2pct",
        what: "each match's heading the gyro's turn moved 2 % of the way towards the match's, the match redone with the heading held there",
        apply: |c| c.mapper.heading_map_share = Some(0.02),
    },
    Variant {
        name: "gyro-turns-2pct-without-walls",
        what: "gyro-turns-2pct only for scans in which no wall measures the heading",
        apply: |c| {
            c.mapper.heading_map_share = Some(0.02);
            c.mapper.heading_map_share_without_walls = true;
        },
    },
    Variant {
        name: "gyro-turns-10pct-without-walls",
        what: "gyro-turns-10pct only for scans in which no wall measures the heading",
        apply: |c| {
            c.mapper.heading_map_share = Some(0.1);
            c.mapper.heading_map_share_without_walls = true;
        },
    },
    Variant {
        name: "gyro-turns-10pct",
        what: "gyro-turns-2pct with 10 %",
        apply: |c| c.mapper.heading_map_share = Some(0.1),
    },
    Variant {
        name: "gyro-turns-30pct",
        what: "gyro-turns-2pct with 30 %",
        apply: |c| c.mapper.heading_map_share = Some(0.3),
    },
    Variant {
        name: "heading-anchor-2deg",
        what: "a match whose heading strays from the gyro's since the pose was last set (an optimisation, a relocalisation, the first scan) by more than 2 deg plus 3 sigma of the gyro's drift redone with the heading held to the gyro's",
        apply: |c| c.mapper.heading_anchor_rad = Some(2f64.to_radians()),
    },
    Variant {
        name: "heading-anchor-1deg",
        what: "heading-anchor-2deg with 1 deg",
        apply: |c| c.mapper.heading_anchor_rad = Some(1f64.to_radians()),
    },
    Variant {
        name: "heading-window-2s-0.5deg",
        what: "a match whose heading turns more than 0.5 deg away from the gyro's turn within 2 s redone with the heading held at that bound",
        apply: |c| {
            c.mapper.heading_window = Some(realms_slam::mapper::HeadingWindow {
                span_s: 2.0,
                max_rad: 0.5f64.to_radians(),
            })
        },
    },
    Variant {
        name: "heading-window-5s-0.5deg",
        what: "heading-window-2s-0.5deg over 5 s",
        apply: |c| {
            c.mapper.heading_window = Some(realms_slam::mapper::HeadingWindow {
                span_s: 5.0,
                max_rad: 0.5f64.to_radians(),
            })
        },
    },
    Variant {
        name: "heading-window-2s-1deg",
        what: "heading-window-2s-0.5deg with 1 deg",
        apply: |c| {
            c.mapper.heading_window = Some(realms_slam::mapper::HeadingWindow {
                span_s: 2.0,
                max_rad: 1f64.to_radians(),
            })
        },
    },
    Variant {
        name: "gap-drop-5cm",
        what: "gaps-to-6m, and hidden ground a hazard when the ground beyond resumes 5 cm lower than before it (not 8 cm)",
        apply: |c| {
            c.traversability.gap_reach_m = 6.0;
            c.traversability.gap_drop_m = 0.05;
        },
    },
    Variant {
        name: "gap-drop-6cm",
        what: "gaps-to-6m, and hidden ground a hazard when the ground beyond resumes 6 cm lower than before it (not 8 cm)",
        apply: |c| {
            c.traversability.gap_reach_m = 6.0;
            c.traversability.gap_drop_m = 0.06;
        },
    },
    Variant {
        name: "crest-marks",
        what: "the crest a stretch of hidden ground drops behind (the last ground seen before it) marked hazard too",
        apply: |c| c.traversability.gap_marks_crest = true,
    },
    Variant {
        name: "hazards-drawn-fine",
        what: "the submaps' hazard layers drawn together on the map's own cells (5 cm), not on the layers' 10 cm",
        apply: |c| c.traversability.assembled_resolution_m = Some(c.mapper.frontend.resolution_m),
    },
    Variant {
        name: "crater-outlines-checked",
        what: "crater-outlines, a disc refused when the layer judged more than 30 % of its cells safe",
        apply: |c| {
            c.traversability.crater_discs = Some(realms_slam::craters::CraterDiscs {
                fit_outline: true,
                max_spread: 0.15,
                max_safe_share: 0.3,
                ..Default::default()
            })
        },
    },
    Variant {
        name: "hazards-by-centre",
        what: "the published map's 5 cm cells each take the verdict of the hazard cell holding their centre, not rounded out to the hazard layer's half cell (the rovers' setup before the seventieth session)",
        apply: |c| c.hazards_rounded_out = false,
    },
    Variant {
        name: "hazards-follow-keyframes",
        what: "each depth frame kept with the keyframe it came after, and for the map the rover publishes last every hazard layer drawn again where the pose graph has those keyframes, not left where tracking had them (as the lidar's submaps are drawn again)",
        apply: |c| c.hazards_follow_keyframes = Some(realms_mission::HAZARD_LAYER_BEND),
    },
    Variant {
        name: "hazards-follow-keyframes-while-mapping",
        what: "as `hazards-follow-keyframes`, the layers drawn again whenever the graph moves, for the maps the rover plans on while it maps too",
        apply: |c| {
            c.hazards_follow_keyframes = Some(realms_mission::HAZARD_LAYER_BEND);
            c.hazards_redrawn_while_mapping = true;
        },
    },
    Variant {
        name: "wheel-scale-from-1",
        what: "the wheels taken at their word until the rover has learnt its own scale (five segments of well-pinned travel), as before the ninety-first session, not at 0.92 of it",
        apply: |c| c.mapper.take_wheels_at_their_word(),
    },
    Variant {
        name: "setup-89",
        what: "the rovers' setup before the ninetieth session: beams that returned nothing dropped, every beam clearing cells up to its hit in the grids scans are matched against too, and the wheels taken at their word until the rover has learnt its scale",
        apply: |c| {
            c.clear_rays_m = None;
            c.mapper.frontend.miss_margin = None;
            c.mapper.clear_rays_published_only = false;
            c.mapper.clear_rays_spacing_m = None;
            c.mapper.take_wheels_at_their_word();
        },
    },
    Variant {
        name: "no-clear-rays",
        what: "a lidar beam that returns nothing dropped, not drawn as free space out to 6 m",
        apply: |c| c.clear_rays_m = None,
    },
    Variant {
        name: "no-miss-margin",
        what: "every beam clears cells up to its hit in the grids scans are matched against too, not stopping 3 cm plus 0.6 % of its range short of it",
        apply: |c| c.mapper.frontend.miss_margin = None,
    },
    Variant {
        name: "clear-rays-matched",
        what: "the beams that returned nothing clear the grids scans are matched against too, from every keyframe (the eighty-eighth session's `clear-rays-6m`)",
        apply: |c| {
            c.mapper.clear_rays_published_only = false;
            c.mapper.clear_rays_spacing_m = None;
        },
    },
    Variant {
        name: "clear-rays-every-keyframe",
        what: "the beams that returned nothing drawn from every keyframe, not only from those a metre or more from the last whose were",
        apply: |c| c.mapper.clear_rays_spacing_m = None,
    },
    Variant {
        name: "clear-rays-every-0.25m",
        what: "the beams that returned nothing drawn from keyframes 0.25 m or more from the last whose were (none from a keyframe made for turning on the spot), not 1 m",
        apply: |c| c.mapper.clear_rays_spacing_m = Some(0.25),
    },
    Variant {
        name: "clear-rays-3m",
        what: "the beams that returned nothing drawn as free space out to 3 m, not 6",
        apply: |c| c.clear_rays_m = Some(3.0),
    },
    Variant {
        name: "clear-rays-12m",
        what: "the beams that returned nothing drawn as free space out to 12 m, the lidar's range, not 6",
        apply: |c| c.clear_rays_m = Some(12.0),
    },
    Variant {
        name: "depth-every-frame",
        what: "every depth frame judged, however long the rover has stood still (the rovers' setup before the seventy-fourth session; they judge 240 frames, two minutes, from where they stand)",
        apply: |c| c.depth_motion_filter = None,
    },
    Variant {
        name: "depth-at-own-stamp",
        what: "a depth frame's verdicts placed at the pose of the frame's own stamp (the latest scan's moved on by the odometry since), not at the latest scan's",
        apply: |c| c.depth_at_own_stamp = true,
    },
    Variant {
        name: "crater-discs",
        what: "craters inferred from the hazard layer's crescents (a circle fitted to each), their whole discs marked hazard",
        apply: |c| c.traversability.crater_discs = Some(Default::default()),
    },
    Variant {
        name: "gaps-to-4m",
        what: "hidden ground ends only at points within 4 m, where frames are judged (the rovers' setup before the fifty-sixth session; it is 6 m)",
        apply: |c| c.traversability.gap_reach_m = 4.0,
    },
    Variant {
        name: "gaps-to-6m",
        what: "hidden ground may end at points up to 6 m off, the depth camera's range (not 4 m), still marked only within 4 m",
        apply: |c| c.traversability.gap_reach_m = 6.0,
    },
    Variant {
        name: "crater-outlines",
        what: "crater-discs with each circle fitted to its cluster's outline (cells beside a cell not hazard), after the hollows are marked, and the cells lying within 0.15 of the radius about it",
        apply: |c| {
            c.traversability.crater_discs = Some(realms_slam::craters::CraterDiscs {
                fit_outline: true,
                max_spread: 0.15,
                ..Default::default()
            })
        },
    },
    Variant {
        name: "slip-takeback",
        what: "the matcher's pull towards the wheels is a tenth while they and the slip check's matches disagree (a burst reported is taken back, as for the rovers)",
        apply: |c| c.mapper.unreliable_pull_share = Some(0.1),
    },
    Variant {
        name: "faces-from-behind",
        what: "far corrections whose hits reach the submap's walls from behind are not refused (the rovers' setup before the sixty-fourth session)",
        apply: |c| c.mapper.faces_seen_from = None,
    },
    Variant {
        name: "closure-min-15",
        what: "keyframes of fewer than 15 hits search for no closure",
        apply: |c| c.mapper.closure_min_points = Some(15),
    },
    Variant {
        name: "closure-min-20",
        what: "keyframes of fewer than 20 hits search for no closure",
        apply: |c| c.mapper.closure_min_points = Some(20),
    },
    Variant {
        name: "no-turn-check",
        what: "the slip check does not compare the wheels' turns with the gyro's, nor is the wheels' travel scaled by the gyro's share of their turns",
        apply: |c| {
            c.mapper.health.turn_check = None;
            c.mapper.turn_scaled_travel = false;
        },
    },
    Variant {
        name: "no-turn-scaled-travel",
        what: "the wheels' travel is not scaled by the gyro's share of their turns while the two disagree",
        apply: |c| c.mapper.turn_scaled_travel = false,
    },
    Variant {
        name: "no-slip-rewind",
        what: "a slip burst reported is not taken back (with no-turn-check, `no-turn-check+no-slip-rewind`: the rovers' setup before the sixty-seventh session)",
        apply: |c| c.mapper.unreliable_rewind = false,
    },
    Variant {
        name: "no-hollows",
        what: "patches the lidar saw open and the camera never judged, walled in by hazard, left unjudged (the rovers' setup before the sixty-second session; they are marked hazard)",
        apply: |c| c.traversability.hazard_hollows = None,
    },
    Variant {
        name: "hollows-50",
        what: "patches the lidar saw open and the camera never judged marked hazard when hazard makes up 50 % of their border (not 60 %)",
        apply: |c| {
            c.traversability.hazard_hollows = Some(realms_slam::hollows::HazardHollows {
                min_hazard_share: 0.5,
                ..Default::default()
            })
        },
    },
    Variant {
        name: "no-tilt-gate",
        what: "returns taken for the floor by the ground clearance alone, not also within what the tilt's latest change could have moved them (the rovers' setup before the fifty-ninth session)",
        apply: |c| c.tilt_gate = false,
    },
    Variant {
        name: "smooth-points",
        what: "each lidar endpoint averaged with its neighbours' where the three lie on one surface, not each range with theirs (averaged ranges lie beyond an oblique wall)",
        apply: |c| c.smoothing = realms_node::mapping::ScanSmoothing::Points,
    },
    Variant {
        name: "smooth-inverse",
        what: "each lidar range averaged with its neighbours' in inverse range (scaled so a straight wall's average lies on it), not in range (averaged ranges lie beyond an oblique wall)",
        apply: |c| c.smoothing = realms_node::mapping::ScanSmoothing::InverseRanges,
    },
    Variant {
        name: "smooth-quadratic",
        what: "each lidar range read from a parabola fitted to it and its two neighbours either side (Savitzky-Golay), where all five lie on one surface, not averaged with one either side: an average of three lies inside a boulder's round outline",
        apply: |c| c.smoothing = realms_node::mapping::ScanSmoothing::Quadratic,
    },
    Variant {
        name: "smooth-quadratic-else-average",
        what: "smooth-quadratic, and where only three ranges lie on one surface (an outline's ends) their average, as the rovers' smoothing takes it",
        apply: |c| c.smoothing = realms_node::mapping::ScanSmoothing::QuadraticElseAverage,
    },
    Variant {
        name: "miss-margin-2cm",
        what: "in the grids scans are matched against, each beam stops clearing cells 2 cm plus 0.4 % of its range short of its hit, not 3 cm plus 0.6 %",
        apply: |c| {
            c.mapper.frontend.miss_margin = Some(realms_slam::occupancy::MissMargin {
                base_m: 0.02,
                per_m: 0.004,
            })
        },
    },
    Variant {
        name: "levelled-points",
        what: "each lidar return placed where it lies on the level by the rover's pitch and roll, not in the tilted plane of the sweep",
        apply: |c| c.levelled_points = true,
    },
    Variant {
        name: "silent-rays",
        what: "a depth pixel without a return above one with a return ends hidden ground where its ray reaches the camera's 6 m, when that lies below the floor before the gap",
        apply: |c| c.silent_pixels = true,
    },
    Variant {
        name: "cells-2.5cm",
        what: "the submaps' grids (matching and published) of 2.5 cm cells, not 5 cm: four times the memory and twice the walk per beam, to see what the cells' size does to the maps' stretch",
        apply: |c| c.mapper.frontend.resolution_m = 0.025,
    },
    Variant {
        name: "grids-traced-apart",
        what: "each keyframe traced into a submap's matching grid and its published grid by walks of their own, as before the ninety-second session, not by one walk along each beam marking both",
        apply: |c| c.mapper.grids_traced_apart = true,
    },
    Variant {
        name: "three-levels",
        what: "scans matched coarse to fine on three grids (5, 10, 20 cm)",
        apply: |c| c.mapper.frontend.levels = 3,
    },
];

/// One rover's replay under one variant.
#[derive(Clone, Debug)]
struct Replay {
    seed: u64,
    rover: RoverId,
    variant: String,
    /// The pose as tracked at each scan, against the truth ...
    tracked: PoseErrors,
    /// ... over this many scans.
    tracked_scans: usize,
    /// The final trajectory (after every closure), against the truth.
    last: PoseErrors,
    /// ... after the best rigid alignment to the truth (the ATE of Sturm et al., IROS 2012,
    /// which forgives a drift of the whole map against the start), RMS, metres.
    aligned_rms_m: f64,
    /// Times the rover declared itself lost.
    lost: usize,
    /// Loop closures accepted.
    closures: usize,
    /// ... of which this many were off the truth by more than
    /// [`bench_slam_closures::WRONG_CLOSURE_M`] or [`bench_slam_closures::WRONG_CLOSURE_DEG`].
    wrong_closures: usize,
    /// Every verified closure match graded against the truth, as CSV, when asked for.
    closures_csv: Option<String>,
    /// Simulated seconds of input and SLAM's wall seconds on them.
    sim_s: f64,
    wall_s: f64,
    /// Lidar scans in the input.
    scans: usize,
    /// The poses scan by scan as CSV, when asked for (`--trajectories`).
    csv: Option<String>,
    /// Each relief fit (variant `relief`) with the true travel over it.
    relief: Vec<(ReliefHop, Pose2)>,
    /// The final map graded against the truth, as the mission's report grades it.
    map: MapGrade,
    /// ... and the map itself, when the poses are asked for (`--trajectories`).
    final_map: Option<OccupancyGrid>,
    /// ... and what it says of the crater cells near the path, by where in their craters.
    crater_cells: CraterCells,
    /// The pose as tracked: its drift by distance to the arena's edge.
    drift: [Band; 3],
}

/// The columns of a `--trajectories` file.
const CSV_HEADER: &str = "t_s,true_x_m,true_y_m,true_yaw_rad,tracked_x_m,tracked_y_m,tracked_yaw_rad,final_x_m,final_y_m,final_yaw_rad,state,closures,wheels_x_m,wheels_y_m,wheels_yaw_rad";

/// The name of the replays on the sweeps' twins taken at once (`--lidar-twins`).
const AT_ONCE_TWIN: &str = "at-once-twin";

/// A rover's captured input with each sweeping scan replaced by its twin taken at once (the
/// twin is stamped with the sweep's last beam's time).
fn with_twins(input: &[CapturedInput], twins: &[LaserScan]) -> Vec<CapturedInput> {
    let by_time: std::collections::BTreeMap<Time, &LaserScan> =
        twins.iter().map(|s| (s.header.stamp, s)).collect();
    input
        .iter()
        .map(|c| match &c.message {
            Message::LaserScan(scan) => {
                let twin = by_time
                    .get(&scan.last_beam_time())
                    .expect("every sweep has its twin");
                CapturedInput {
                    message: Message::LaserScan((*twin).clone()),
                    ..c.clone()
                }
            }
            _ => c.clone(),
        })
        .collect()
}

/// What a mission's maps are graded against: the truth, and the craters' centres and rim
/// radii (metres).
struct GradedArena {
    truth: GroundTruth,
    craters: Vec<(Point2, f64)>,
}

/// Runs SLAM for one rover over its captured input.
fn replay(
    seed: u64,
    rover: RoverId,
    variant: &str,
    cfg: &MappingConfig,
    input: &[CapturedInput],
    graded: &GradedArena,
    with_csv: bool,
) -> Replay {
    let truth = &graded.truth;
    let mut mapping = Mapping::new(rover, cfg.clone());
    // Each scan's time, true pose and pose as tracked.
    let mut scans: Vec<(f64, Pose2, Pose2)> = Vec::new();
    // ... and whether the rover was tracking then.
    let mut tracking: Vec<bool> = Vec::new();
    // ... and its state, the closures accepted by then and the wheels' odometry as last
    // published (its own frame), for the CSV.
    let mut states: Vec<(LocalisationState, usize, Option<Pose2>)> = Vec::new();
    let mut wheels: Option<Pose2> = None;
    let mut odometry = input.iter().filter_map(|c| match &c.message {
        Message::Odometry(o) => {
            let p = &o.pose.pose;
            Some((
                c.t,
                Pose2::new(p.position.x, p.position.y, p.orientation.yaw_rad()),
            ))
        }
        _ => None,
    });
    let mut next_odometry = odometry.next();
    let (mut lost, mut was_lost) = (0, false);
    let started = Instant::now();
    replay_slam(&mut mapping, input, |c, m| {
        if !m.placed() {
            return;
        }
        // The final trajectory is stamped as the scans are (the time of what they show).
        let stamp = match &c.message {
            Message::LaserScan(scan) => scan.last_beam_time(),
            _ => c.t,
        };
        scans.push((stamp.as_secs_f64(), c.truth, m.pose()));
        tracking.push(m.state() == LocalisationState::Tracking);
        if with_csv {
            while let Some((_, pose)) = next_odometry.filter(|(t, _)| *t <= c.t) {
                wheels = Some(pose);
                next_odometry = odometry.next();
            }
            states.push((m.state(), m.mapper().closures, wheels));
        }
        let is_lost = m.state() == LocalisationState::Lost;
        lost += usize::from(is_lost && !was_lost);
        was_lost = is_lost;
    });
    let wall_s = started.elapsed().as_secs_f64();
    let arena = truth.lidar_obstacles.geometry();
    let drift = drift_by_band(
        &scans
            .iter()
            .zip(&tracking)
            .map(|((_, truth, tracked), on)| (*truth, *tracked, *on))
            .collect::<Vec<_>>(),
        (
            arena.origin,
            Point2::new(
                arena.origin.x_m + arena.width_m(),
                arena.origin.y_m + arena.height_m(),
            ),
        ),
    );
    let relief = relief_against_truth(mapping.relief_hops(), input);
    let path: Vec<_> = scans.iter().map(|(_, truth, _)| truth.position()).collect();
    let end = input.last().map_or(Time::ZERO, |c| c.t);
    // As the rover does before its last map.
    mapping.finish_map();
    mapping.finish_hazards();
    let final_map = mapping.map(end);
    let (map, crater_cells) = match map_grid(&final_map) {
        Some(grid) => (
            grade_grid(&grid, truth, &path),
            crater_cells(&grid, truth, &graded.craters, &path),
        ),
        // A map whose size does not match its data grades as empty.
        None => Default::default(),
    };
    // The final trajectory's poses are stamped with their scans' times.
    let truth_at = |t: f64| {
        let k = scans.partition_point(|s| s.0 < t);
        scans.get(k).filter(|s| s.0 == t).map(|s| s.1)
    };
    let trajectory = mapping.trajectory();
    let graded = bench_slam_closures::grade_all(mapping.mapper(), |t| {
        let k = scans.partition_point(|s| s.0 < t);
        scans.get(k).filter(|s| (s.0 - t).abs() < 1e-6).map(|s| s.1)
    });
    let wrong_closures = graded.iter().filter(|g| g.accepted_wrong()).count();
    let closures_csv = with_csv.then(|| bench_slam_closures::csv(&graded));
    let csv = with_csv.then(|| {
        let mut text = format!("{CSV_HEADER}\n");
        let mut finals = trajectory.iter().peekable();
        for ((t, truth, tracked), (state, closures, wheels)) in scans.iter().zip(&states) {
            while finals.next_if(|f| f.timestamp_s < *t).is_some() {}
            let last = finals
                .peek()
                .filter(|f| f.timestamp_s == *t)
                .map(|f| f.pose);
            let pose = |p: Option<Pose2>| {
                p.map_or(",,".to_string(), |p| {
                    format!("{:.4},{:.4},{:.5}", p.x_m, p.y_m, p.yaw_rad)
                })
            };
            text += &format!(
                "{t:.3},{},{},{},{state:?},{closures},{}\n",
                pose(Some(*truth)),
                pose(Some(*tracked)),
                pose(last),
                pose(*wheels)
            );
        }
        text
    });
    let last: Vec<(Pose2, Pose2)> = trajectory
        .iter()
        .filter_map(|s| truth_at(s.timestamp_s).map(|truth| (s.pose, truth)))
        .collect();
    let positions: Vec<_> = last
        .iter()
        .map(|(e, t)| (e.position(), t.position()))
        .collect();
    let sim_s = match (input.first(), input.last()) {
        (Some(a), Some(b)) => (b.t - a.t).as_secs_f64(),
        _ => 0.0,
    };
    Replay {
        seed,
        rover,
        variant: variant.to_owned(),
        tracked: pose_errors(scans.iter().map(|(_, truth, est)| (*est, *truth))),
        tracked_scans: scans.len(),
        last: pose_errors(last.into_iter()),
        aligned_rms_m: aligned_rmse(&positions).unwrap_or(f64::NAN),
        lost,
        closures: mapping.mapper().closures,
        wrong_closures,
        closures_csv,
        sim_s,
        wall_s,
        scans: input
            .iter()
            .filter(|c| matches!(c.message, Message::LaserScan(_)))
            .count(),
        csv,
        relief,
        map,
        final_map: with_csv.then_some(final_map),
        crater_cells,
        drift,
    }
}

/// Replaces the wheels' odometry in `input` by the truth's motion: each reading moves on
/// from the one before by what the rover truly did in between, so the wheels neither slip
/// nor drift (`--perfect-wheels`).
fn perfect_wheels(input: &mut [CapturedInput]) {
    let mut before: Option<(Pose2, Pose2)> = None;
    for c in input.iter_mut() {
        let Message::Odometry(odom) = &mut c.message else {
            continue;
        };
        let p = &odom.pose.pose;
        let reported = Pose2::new(p.position.x, p.position.y, p.orientation.yaw_rad());
        let pose = before.map_or(reported, |(truth, pose)| pose * (truth.inverse() * c.truth));
        before = Some((c.truth, pose));
        odom.pose.pose.position.x = pose.x_m;
        odom.pose.pose.position.y = pose.y_m;
        odom.pose.pose.orientation =
            realms_core::Quaternion::from_roll_pitch_yaw(0.0, 0.0, pose.yaw_rad);
    }
}

/// Shifts the gyro's rates after the start-up calibration in `input` by what the
/// calibration (the mean rate while the rover stood for `calibration`) measured beyond the
/// true `bias_rad_s`, so the bias the rover removes is the true one (`--exact-gyro-bias`).
fn exact_gyro_bias(input: &mut [CapturedInput], bias_rad_s: f64, calibration: Duration) {
    let end = Time::ZERO + calibration;
    let (sum, n) = input
        .iter()
        .filter_map(|c| match &c.message {
            Message::Imu(imu) if imu.header.stamp < end => Some(imu.angular_velocity.z),
            _ => None,
        })
        .fold((0.0, 0u64), |(s, n), z| (s + z, n + 1));
    if n == 0 {
        return;
    }
    let leftover = sum / n as f64 - bias_rad_s;
    for c in input.iter_mut() {
        if let Message::Imu(imu) = &mut c.message
            && imu.header.stamp >= end
        {
            imu.angular_velocity.z += leftover;
        }
    }
}

/// Each relief fit with the true travel between its two frames (the truth as each frame was
/// published, in the reference frame's rover frame).
fn relief_against_truth(hops: &[ReliefHop], input: &[CapturedInput]) -> Vec<(ReliefHop, Pose2)> {
    let frames: Vec<(Time, Pose2)> = input
        .iter()
        .filter_map(|c| match &c.message {
            Message::PointCloud(cloud) => Some((cloud.header.stamp, c.truth)),
            _ => None,
        })
        .collect();
    let truth_at = |t: Time| {
        let k = frames.partition_point(|f| f.0 < t);
        frames.get(k).filter(|f| f.0 == t).map(|f| f.1)
    };
    hops.iter()
        .filter_map(|h| Some((*h, truth_at(h.from)?.inverse() * truth_at(h.to)?)))
        .collect()
}

/// The relief fits against the wheels, over every rover of `of` (markdown table rows).
fn relief_table(name: &str, of: &[&Replay]) {
    // Along and across the true travel, metres.
    let split = |est: Pose2, truth: Pose2| {
        let d = truth.x_m.hypot(truth.y_m);
        let (ux, uy) = (truth.x_m / d, truth.y_m / d);
        let (ex, ey) = (est.x_m - truth.x_m, est.y_m - truth.y_m);
        (ex * ux + ey * uy, -ex * uy + ey * ux)
    };
    let hops: Vec<&(ReliefHop, Pose2)> = of
        .iter()
        .flat_map(|r| &r.relief)
        .filter(|(_, truth)| truth.x_m.hypot(truth.y_m) >= RELIEF_MIN_TRAVEL_M)
        .collect();
    if hops.is_empty() {
        return;
    }
    let abs_pct = |v: Vec<f64>, q: f64| {
        let mut v: Vec<f64> = v.into_iter().map(f64::abs).collect();
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            f64::NAN
        } else {
            v[((v.len() - 1) as f64 * q).round() as usize]
        }
    };
    let fitted: Vec<_> = hops
        .iter()
        .filter_map(|(h, t)| Some((h, h.fit?, *t)))
        .collect();
    let confident: Vec<_> = fitted
        .iter()
        .filter(|(h, fit, _)| {
            let d = h.wheels.x_m.hypot(h.wheels.y_m).max(1e-9);
            fit.sigma_along_m(h.wheels.x_m / d, h.wheels.y_m / d) < RELIEF_CONFIDENT_M
        })
        .collect();
    let along = |v: &mut dyn Iterator<Item = (Pose2, Pose2)>| -> Vec<f64> {
        v.map(|(e, t)| split(e, t).0 / t.x_m.hypot(t.y_m)).collect()
    };
    let row = |what: &str, est: Vec<f64>| {
        println!(
            "| {name} | {what} | {} | {:.1} % | {:.1} % |",
            est.len(),
            100.0 * abs_pct(est.clone(), 0.5),
            100.0 * abs_pct(est, 0.9)
        );
    };
    row(
        "wheels, every hop",
        along(&mut hops.iter().map(|(h, t)| (h.wheels, *t))),
    );
    row(
        "relief, every fit",
        along(&mut fitted.iter().map(|(_, f, t)| (f.motion, *t))),
    );
    row(
        "wheels, where the relief is confident",
        along(&mut confident.iter().map(|(h, _, t)| (h.wheels, *t))),
    );
    row(
        "relief, where it is confident",
        along(&mut confident.iter().map(|(_, f, t)| (f.motion, *t))),
    );
}

/// Relief fits over less true travel than this are left out of the table, metres.
const RELIEF_MIN_TRAVEL_M: f64 = 0.3;
/// A fit is confident along the travel below this standard deviation, metres.
const RELIEF_CONFIDENT_M: f64 = 0.02;

pub(crate) fn run(args: BenchSlamArgs) -> Result<()> {
    let (base, source) = load_scenario(args.scenario.as_deref())?;
    let limit_s = parse_duration_s(&args.duration)?;
    let variants = args
        .variant
        .iter()
        .map(|name| variant(name))
        .collect::<Result<Vec<_>>>()?;
    let seeds: Vec<u64> = (args.first_seed..args.first_seed + args.seeds).collect();
    // Every replayed setup by name, the setup as it is first.
    let names: Vec<&str> = std::iter::once("baseline")
        .chain(args.lidar_twins.then_some(AT_ONCE_TWIN))
        .chain(variants.iter().map(|v| v.name.as_str()))
        .collect();
    let workers = crate::bench::workers(args.jobs);
    let with_csv = args.trajectories.is_some();
    if let Some(dir) = &args.trajectories {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    println!("# realms bench slam");
    println!();
    println!(
        "scenario: {source}, {} rovers; seeds {}..{}; missions of {:.0} min{}, {}; each rover's SLAM replayed on the mission's captured sensor input; {workers} seeds at a time; machine: {}",
        base.rovers.count,
        args.first_seed,
        args.first_seed + args.seeds,
        limit_s / 60.0,
        if args.no_faults {
            ", no faults"
        } else {
            ", the scenario's faults"
        },
        if args.radio {
            "the simulated radio"
        } else {
            "ideal communication"
        },
        crate::bench::machine()
    );
    if args.perfect_wheels {
        println!("wheels: perfect (the odometry replaced by the truth's motion)");
    }
    if args.exact_gyro_bias {
        println!("gyro: the calibration's leftover bias removed");
    }
    if args.lidar_twins {
        println!(
            "lidar: sweeping; {AT_ONCE_TWIN}: the same SLAM on each sweep's twin taken at once from its last beam's pose"
        );
    }
    for v in &variants {
        println!("variant {}: {}", v.name, v.what);
    }
    println!();
    let results = in_parallel(&seeds, workers, |&seed| {
        let mut s = base.clone();
        s.seed = seed;
        s.duration_s = limit_s;
        if args.no_faults {
            s.faults.clear();
        }
        if args.lidar_twins {
            s.rovers.lidar.sweeps = true;
        }
        let options = MissionOptions {
            ideal_comms: !args.radio,
            ..MissionOptions::default()
        };
        let world = World::new(&s);
        let arena = GradedArena {
            truth: world.truth().clone(),
            craters: (world.terrain().craters.iter())
                .map(|c| (c.center, c.radius_m))
                .collect(),
        };
        let mut cfg = rover_mapping_config(&world, &options);
        if args.perfect_wheels {
            // Wheels that report the travel exactly: a calibration drive would find their
            // scale 1, and the analogue's 0.92 would shrink the first metres by 8 %.
            cfg.mapper.take_wheels_at_their_word();
        }
        let ids: Vec<RoverId> = world.rovers().map(|b| b.id).collect();
        let biases: Vec<f64> = world.rovers().map(|b| b.gyro_bias_rad_s).collect();
        let gyro_calibration = options.gyro_calibration;
        let mut mission = Mission::with_options(world, options);
        mission.capture_slam_inputs();
        if args.lidar_twins {
            mission.world_mut().keep_lidar_twins();
        }
        mission.run_until(Time::from_secs_f64(limit_s));
        let mut capture = mission.take_capture();
        let twins = mission.world_mut().take_lidar_twins();
        drop(mission);
        if args.perfect_wheels {
            for input in &mut capture {
                perfect_wheels(input);
            }
        }
        if args.exact_gyro_bias {
            for (input, bias) in capture.iter_mut().zip(&biases) {
                exact_gyro_bias(input, *bias, gyro_calibration);
            }
        }
        let mut replays = Vec::new();
        for (k, (id, input)) in ids.iter().zip(&capture).enumerate() {
            replays.push(replay(seed, *id, "baseline", &cfg, input, &arena, with_csv));
            if args.lidar_twins {
                let twinned = with_twins(input, &twins[k]);
                replays.push(replay(
                    seed,
                    *id,
                    AT_ONCE_TWIN,
                    &cfg,
                    &twinned,
                    &arena,
                    with_csv,
                ));
            }
            for v in &variants {
                let mut changed = cfg.clone();
                v.apply(&mut changed);
                replays.push(replay(
                    seed, *id, &v.name, &changed, input, &arena, with_csv,
                ));
            }
        }
        replays
    });
    let mut all: Vec<Replay> = results.into_iter().flatten().collect();
    all.sort_by_key(|r| (r.seed, r.rover.0));
    if let Some(dir) = &args.trajectories {
        for r in &all {
            if let Some(csv) = &r.csv {
                let path = dir.join(format!("seed{}-{}-{}.csv", r.seed, r.rover, r.variant));
                std::fs::write(&path, csv)
                    .with_context(|| format!("cannot write {}", path.display()))?;
            }
            if let Some(map) = &r.final_map {
                let name = format!("seed{}-{}-{}", r.seed, r.rover, r.variant);
                realms_mission::report::write_map(map, dir, &name)
                    .with_context(|| format!("cannot write the map {name} in {}", dir.display()))?;
            }
            if let Some(csv) = &r.closures_csv {
                let name = format!("seed{}-{}-{}-closures.csv", r.seed, r.rover, r.variant);
                let path = dir.join(name);
                std::fs::write(&path, csv)
                    .with_context(|| format!("cannot write {}", path.display()))?;
            }
        }
        println!("poses scan by scan, and the final maps: {}", dir.display());
    }
    println!(
        "| seed | rover | variant | tracked RMS | final RMS | final max | aligned RMS | final heading RMS | lost | closures (wrong) | SLAM speed | scans per wall second (with the depth frames between them) | hazards near the path marked (cells) | hazard cells truly untraversable | occupied right (cells) | obstacle faces marked | explorable area known |"
    );
    println!(
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    for r in &all {
        println!(
            "| {} | {} | {} | {:.3} m | {:.3} m | {:.3} m | {:.3} m | {:.2} deg | {} | {} ({}) | {:.0}x | {:.0} | {:.1} % ({}) | {:.1} % | {:.1} % ({}) | {:.1} % | {:.1} % |",
            r.seed,
            r.rover,
            r.variant,
            r.tracked.rmse_m,
            r.last.rmse_m,
            r.last.max_m,
            r.aligned_rms_m,
            r.last.heading_rmse_deg,
            r.lost,
            r.closures,
            r.wrong_closures,
            r.sim_s / r.wall_s.max(1e-9),
            r.scans as f64 / r.wall_s.max(1e-9),
            100.0 * r.map.path_hazards_flagged,
            r.map.path_hazards,
            100.0 * r.map.hazard_correct,
            100.0 * r.map.occupied_correct,
            r.map.occupied_cells,
            100.0 * r.map.obstacle_faces_marked,
            100.0 * r.map.explorable_known
        );
    }
    println!();
    println!(
        "| variant | final RMS, median rover | final RMS, worst rover per seed (median) | aligned RMS, median rover | tracked RMS, median rover | tracked within 0.2 m, all rovers | fleet SLAM speed, median seed (sim s / wall s of all rovers) | hazards near the paths marked, all rovers | hazard cells truly untraversable, all rovers |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for &name in &names {
        let of: Vec<&Replay> = all.iter().filter(|r| r.variant == name).collect();
        let worst: Vec<f64> = seeds
            .iter()
            .map(|s| {
                of.iter()
                    .filter(|r| r.seed == *s)
                    .map(|r| r.last.rmse_m)
                    .fold(0.0, f64::max)
            })
            .collect();
        let fleet_speed: Vec<f64> = seeds
            .iter()
            .map(|s| {
                let fleet = of.iter().filter(|r| r.seed == *s);
                let sim = fleet.clone().map(|r| r.sim_s).fold(0.0, f64::max);
                sim / fleet.map(|r| r.wall_s).sum::<f64>().max(1e-9)
            })
            .collect();
        // Pooled over the rovers: a rover whose path passed few hazards weighs little.
        let share =
            |part: fn(&MapGrade) -> (f64, usize)| 100.0 * pooled(of.iter().map(|r| part(&r.map)));
        println!(
            "| {name} | {:.3} m | {:.3} m | {:.3} m | {:.3} m | {:.1} % | {:.0}x | {:.1} % | {:.1} % |",
            median(of.iter().map(|r| r.last.rmse_m).collect()),
            median(worst),
            median(of.iter().map(|r| r.aligned_rms_m).collect()),
            median(of.iter().map(|r| r.tracked.rmse_m).collect()),
            // Pooled over every tracked scan.
            100.0
                * pooled(
                    of.iter()
                        .map(|r| (r.tracked.share_within_0_2_m, r.tracked_scans))
                ),
            median(fleet_speed),
            share(|m| (m.path_hazards_flagged, m.path_hazards)),
            share(|m| (m.hazard_correct, m.hazard_cells)),
        );
    }
    println!();
    println!(
        "Crater cells within {PATH_REACH_M} m of the paths, all rovers, by where in their crater (distance from the centre as a share of the rim's radius): marked / free with a mark within {CREST_SLACK_M} m (per axis) / free / unknown"
    );
    println!();
    let bands: Vec<String> = (0..CRATER_BANDS.len())
        .map(|b| {
            let from = if b == 0 { 0.0 } else { CRATER_BANDS[b - 1] };
            format!("{from:.2}-{:.2}", CRATER_BANDS[b])
        })
        .collect();
    println!("| variant | {} |", bands.join(" | "));
    println!("| --- |{}", " --- |".repeat(bands.len()));
    for &name in &names {
        let mut pooled = CraterCells::default();
        for r in all.iter().filter(|r| r.variant == name) {
            pooled.add(&r.crater_cells);
        }
        let cells: Vec<String> = (0..CRATER_BANDS.len())
            .map(|b| {
                format!(
                    "{} / {} / {} / {}",
                    pooled.marked[b], pooled.free_mark_near[b], pooled.free[b], pooled.unknown[b]
                )
            })
            .collect();
        println!("| {name} | {} |", cells.join(" | "));
    }
    println!();
    println!(
        "Tracking drift: the tracked motion over windows of {WINDOW_SCANS} scans against the true motion, by the rover's least distance to the arena's edge in the window (windows with an optimisation's jump or not tracking left out); position error as a share of the travel, heading error per metre, all rovers pooled"
    );
    println!();
    println!(
        "| variant | under {} m from the edge | {} to {} m | {} m and more |",
        BAND_EDGES_M[0], BAND_EDGES_M[0], BAND_EDGES_M[1], BAND_EDGES_M[1]
    );
    println!("| --- | --- | --- | --- |");
    for &name in &names {
        let mut pooled = [Band::default(); 3];
        for r in all.iter().filter(|r| r.variant == name) {
            for (p, b) in pooled.iter_mut().zip(&r.drift) {
                p.add(b);
            }
        }
        let cell = |b: &Band| {
            format!(
                "{:.2} %, {:.3} deg/m ({:.0} m)",
                100.0 * b.position_share(),
                b.heading_deg_per_m(),
                b.travel_m
            )
        };
        println!(
            "| {name} | {} | {} | {} |",
            cell(&pooled[0]),
            cell(&pooled[1]),
            cell(&pooled[2])
        );
    }
    if all.iter().any(|r| !r.relief.is_empty()) {
        println!();
        println!(
            "Relief fits of depth frames onto a reference frame up to {RELIEF_REFERENCE_TRAVEL_M} m back, hops of {RELIEF_MIN_TRAVEL_M} m or more; error along the true travel as a share of it; confident: the fit's standard deviation along the travel under {RELIEF_CONFIDENT_M} m"
        );
        println!();
        println!(
            "| variant | travel from | hops | median error along the travel | 90th percentile |"
        );
        println!("| --- | --- | --- | --- | --- |");
        for v in &variants {
            let of: Vec<&Replay> = all.iter().filter(|r| r.variant == v.name).collect();
            relief_table(&v.name, &of);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rovers' setup as it is, in the small scenario (quick to build).
    fn base() -> MappingConfig {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/small.toml");
        let scenario = realms_sim::Scenario::load(&path).expect("the small scenario loads");
        rover_mapping_config(&World::new(&scenario), &MissionOptions::default())
    }

    #[test]
    fn variants_joined_by_a_plus_apply_each_in_turn() {
        let setup = variant("no-weak-floor+gaps-to-4m").expect("both are known");
        assert_eq!(setup.name, "no-weak-floor+gaps-to-4m");
        let (before, mut after) = (base(), base());
        setup.apply(&mut after);
        assert_eq!(before.mapper.weak_direction_floor, Some(100.0));
        assert_eq!(after.mapper.weak_direction_floor, None);
        assert!(before.mapper.slip_check_own_match && !after.mapper.slip_check_own_match);
        assert_eq!(before.traversability.gap_reach_m, 6.0);
        assert_eq!(after.traversability.gap_reach_m, 4.0);
        // A later variant wins where two set the same field.
        let mut both = base();
        variant("weak-floor-30+weak-floor-100")
            .expect("both are known")
            .apply(&mut both);
        assert_eq!(both.mapper.weak_direction_floor, Some(100.0));
    }

    #[test]
    fn an_unknown_part_of_a_joined_variant_is_named_in_the_error() {
        let err = variant("weak-floor-100+no-such-thing")
            .err()
            .expect("an unknown variant is an error")
            .to_string();
        assert!(err.contains("`no-such-thing`"), "{err}");
        assert!(
            err.contains("weak-floor-100-own"),
            "lists the known ones: {err}"
        );
    }
}
