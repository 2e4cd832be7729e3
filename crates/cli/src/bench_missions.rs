//! `realms bench missions`: whole missions, one per seed, run exactly as `realms mission`
//! runs them, and what issue 3 grades over them: each rover's map and trajectory against the
//! truth, the crater cells near its path it marked, and the lander's merged map.
//!
//! Any change to a rover's SLAM or planning sends the rovers along other paths, so one
//! mission says little of a change: these figures are read over many seeds (BENCHMARKS.md
//! compares builds on sixteen). For SLAM alone on fixed paths, see `realms bench slam`.

use crate::bench::{in_parallel, machine, mean, median, pooled, workers};
use crate::cli::BenchMissionsArgs;
use crate::mission::{load_scenario, parse_duration_s, run_to_end};
use anyhow::{Result, bail};
use realms_core::Time;
use realms_mission::report::MissionReport;
use realms_mission::slam_record::{CovarianceCheck, LostTime};
use realms_mission::{Mission, MissionOptions};
use realms_node::navigation::RevisitConfig;
use realms_sim::World;
use serde::Serialize;

/// One rover's grades in one mission.
#[derive(Clone, Debug, Serialize)]
struct RoverGrades {
    name: String,
    powered: bool,
    /// Share of the map's occupied cells the truth holds occupied (absent without a map).
    occupied_correct: Option<f64>,
    /// RMS of the final trajectory against the truth, metres.
    trajectory_rmse_m: Option<f64>,
    /// Share of the 1 Hz checks with the pose as published then within 0.2 m of the truth.
    pose_within_0_2_m: f64,
    /// Whether the covariance published with the pose said how far off it was.
    pose_covariance: CovarianceCheck,
    /// Crater cells within reach of the rover's path ...
    path_hazards: usize,
    /// ... and the share of them its map marks.
    path_hazards_flagged: f64,
    /// Cells the map marks hazard ...
    hazard_cells: usize,
    /// ... and the share of them within a cell of ground the rover truly must not enter.
    hazard_correct: f64,
    /// [`realms_mission::slam_record::MapGrade::known_correct`] (absent without a map).
    known_correct: Option<f64>,
    /// How long it was lost: a rover still lost at the end was of no more use.
    lost: LostTime,
}

/// One mission's grades.
#[derive(Clone, Debug, Serialize)]
struct MissionGrades {
    seed: u64,
    sim_duration_s: f64,
    slam_speedup: f64,
    /// Share of the explorable area some rover's map knows at the end ...
    coverage: f64,
    /// ... and when it first reached 95 %, seconds (absent if it never did).
    time_to_95_s: Option<f64>,
    /// The lander's merged map: share of its occupied cells right (absent without a merge).
    merged_occupied_correct: Option<f64>,
    /// ... and with every map the lander placed at its rover's known start instead.
    merged_at_known_starts: Option<f64>,
    /// Maps the lander found drifted from their known starts ...
    maps_drifted: usize,
    /// ... and maps it placed away from them.
    maps_moved: usize,
    rovers: Vec<RoverGrades>,
}

impl MissionGrades {
    fn of(report: &MissionReport) -> MissionGrades {
        MissionGrades {
            seed: report.seed,
            sim_duration_s: report.sim_duration_s,
            slam_speedup: report.slam_speedup,
            coverage: report.coverage,
            time_to_95_s: report.time_to_95_s,
            merged_occupied_correct: report.merge.as_ref().map(|m| m.occupied_correct),
            merged_at_known_starts: report
                .merge
                .as_ref()
                .map(|m| m.occupied_correct_at_known_starts),
            maps_drifted: report
                .merge
                .as_ref()
                .map_or(0, |m| m.maps.iter().filter(|l| l.drifted).count()),
            maps_moved: report.merge.as_ref().map_or(0, |m| {
                m.maps.iter().filter(|l| l.placed_off_known_start()).count()
            }),
            rovers: report
                .rovers
                .iter()
                .map(|r| {
                    let map = r.slam.map.as_ref();
                    RoverGrades {
                        name: r.name.clone(),
                        powered: r.powered,
                        occupied_correct: map.map(|m| m.occupied_correct),
                        trajectory_rmse_m: r.slam.trajectory_error.as_ref().map(|e| e.rmse_m),
                        pose_within_0_2_m: r.slam.pose_error.share_within_0_2_m,
                        pose_covariance: r.slam.pose_covariance,
                        path_hazards: map.map_or(0, |m| m.path_hazards),
                        path_hazards_flagged: map.map_or(0.0, |m| m.path_hazards_flagged),
                        hazard_cells: map.map_or(0, |m| m.hazard_cells),
                        hazard_correct: map.map_or(0.0, |m| m.hazard_correct),
                        known_correct: map.map(|m| m.known_correct()),
                        lost: LostTime::of(&r.slam.localisation, report.sim_duration_s),
                    }
                })
                .collect(),
        }
    }
}

/// The figures over every mission.
#[derive(Clone, Debug, Serialize)]
struct Summary {
    missions: usize,
    rovers_graded: usize,
    occupied_correct_mean: f64,
    occupied_correct_median: f64,
    rovers_under_80: usize,
    rovers_under_90: usize,
    rovers_at_least_95: usize,
    trajectory_rmse_mean_m: f64,
    trajectory_rmse_median_m: f64,
    trajectory_rmse_worst_m: f64,
    rovers_under_10cm: usize,
    /// The published pose within 0.2 m of the truth, mean over the rovers of their share of
    /// checks.
    pose_within_0_2_m_mean: f64,
    /// Published poses graded against their covariance, pooled over every rover ...
    covariance_instants: usize,
    /// ... the share inside their 95 % circle (position) ...
    position_inside_95: f64,
    /// ... and 95 % interval (heading) ...
    heading_inside_95: f64,
    /// ... and the median over the rovers of their median published position standard
    /// deviation, metres.
    median_sigma_m: f64,
    /// Crater cells near the paths marked, pooled over every rover.
    path_hazards_flagged: f64,
    /// Hazard cells marked truly untraversable, pooled over every rover.
    hazard_correct: f64,
    /// Known cells right, mean over the rovers.
    known_correct_mean: f64,
    /// Times a rover became lost, over every rover ...
    lost_episodes: usize,
    /// ... the seconds they spent lost ...
    lost_s: f64,
    /// ... and rovers still lost at their mission's end.
    lost_at_end: usize,
    /// Absent when no mission merged a map (a lone rover).
    merged_occupied_correct_mean: Option<f64>,
    /// The same with every placed map at its known start.
    merged_at_known_starts_mean: Option<f64>,
    /// Maps found drifted from their known starts, and maps placed away from them, over
    /// every mission.
    maps_drifted: usize,
    maps_moved: usize,
    sim_duration_mean_s: f64,
    /// Coverage at the end, mean over the missions.
    coverage_mean: f64,
    /// Time to 95 % coverage, mean over the missions that reached it, seconds (absent when
    /// none did) ...
    time_to_95_mean_s: Option<f64>,
    /// ... and how many did.
    reached_95: usize,
    slam_speedup_median: f64,
}

fn summarise(missions: &[MissionGrades]) -> Summary {
    let rovers = || missions.iter().flat_map(|m| &m.rovers);
    let maps: Vec<f64> = rovers().filter_map(|r| r.occupied_correct).collect();
    let errors: Vec<f64> = rovers().filter_map(|r| r.trajectory_rmse_m).collect();
    let known: Vec<f64> = rovers().filter_map(|r| r.known_correct).collect();
    let merged: Vec<f64> = missions
        .iter()
        .filter_map(|m| m.merged_occupied_correct)
        .collect();
    let merged_at_starts: Vec<f64> = missions
        .iter()
        .filter_map(|m| m.merged_at_known_starts)
        .collect();
    let lengths: Vec<f64> = missions.iter().map(|m| m.sim_duration_s).collect();
    let reached: Vec<f64> = missions.iter().filter_map(|m| m.time_to_95_s).collect();
    Summary {
        missions: missions.len(),
        rovers_graded: maps.len(),
        occupied_correct_mean: mean(&maps),
        occupied_correct_median: median(maps.clone()),
        rovers_under_80: maps.iter().filter(|v| **v < 0.80).count(),
        rovers_under_90: maps.iter().filter(|v| **v < 0.90).count(),
        rovers_at_least_95: maps.iter().filter(|v| **v >= 0.95).count(),
        trajectory_rmse_mean_m: mean(&errors),
        trajectory_rmse_median_m: median(errors.clone()),
        trajectory_rmse_worst_m: errors.iter().copied().fold(f64::NAN, f64::max),
        rovers_under_10cm: errors.iter().filter(|e| **e < 0.10).count(),
        pose_within_0_2_m_mean: mean(&rovers().map(|r| r.pose_within_0_2_m).collect::<Vec<_>>()),
        covariance_instants: rovers().map(|r| r.pose_covariance.instants).sum(),
        position_inside_95: pooled(rovers().map(|r| {
            (
                r.pose_covariance.position_inside_95,
                r.pose_covariance.instants,
            )
        })),
        heading_inside_95: pooled(rovers().map(|r| {
            (
                r.pose_covariance.heading_inside_95,
                r.pose_covariance.instants,
            )
        })),
        median_sigma_m: median(
            rovers()
                .filter(|r| r.pose_covariance.instants > 0)
                .map(|r| r.pose_covariance.median_sigma_m)
                .collect(),
        ),
        path_hazards_flagged: pooled(rovers().map(|r| (r.path_hazards_flagged, r.path_hazards))),
        hazard_correct: pooled(rovers().map(|r| (r.hazard_correct, r.hazard_cells))),
        known_correct_mean: mean(&known),
        lost_episodes: rovers().map(|r| r.lost.episodes).sum(),
        lost_s: rovers().map(|r| r.lost.seconds).sum(),
        lost_at_end: rovers().filter(|r| r.lost.at_end).count(),
        merged_occupied_correct_mean: (!merged.is_empty()).then(|| mean(&merged)),
        merged_at_known_starts_mean: (!merged_at_starts.is_empty())
            .then(|| mean(&merged_at_starts)),
        maps_drifted: missions.iter().map(|m| m.maps_drifted).sum(),
        maps_moved: missions.iter().map(|m| m.maps_moved).sum(),
        sim_duration_mean_s: mean(&lengths),
        coverage_mean: mean(&missions.iter().map(|m| m.coverage).collect::<Vec<_>>()),
        time_to_95_mean_s: (!reached.is_empty()).then(|| mean(&reached)),
        reached_95: reached.len(),
        slam_speedup_median: median(missions.iter().map(|m| m.slam_speedup).collect()),
    }
}

/// A change to the rovers' navigation by name (`--nav-variant`).
fn nav_variant(name: &str) -> Result<NavigationChange> {
    match name {
        "unjudged-must-pay" => Ok(|n| n.explore.unjudged_must_pay = true),
        "endgame-must-pay" => Ok(|n| n.endgame_unjudged_must_pay = true),
        "revisit" => Ok(|n| n.revisit = Some(RevisitConfig::default())),
        "revisit-0.4m" => Ok(|n| {
            n.revisit = Some(RevisitConfig {
                above_m: 0.4,
                ..RevisitConfig::default()
            })
        }),
        "plan-margin-10m" => Ok(|n| n.plan_margin_m = Some(10.0)),
        _ => bail!(
            "unknown navigation variant `{name}`; known: unjudged-must-pay, endgame-must-pay, \
             revisit, revisit-0.4m, plan-margin-10m (several joined with `+`)"
        ),
    }
}

/// A change to the rovers' navigation (`--nav-variant`).
type NavigationChange = fn(&mut realms_node::navigation::NavigationConfig);

/// The navigation changes `name` (`--nav-variant`) stands for, and `source` (the scenario's
/// name for the report) naming it.
pub fn with_nav_variant(
    name: Option<&str>,
    source: String,
) -> Result<(Vec<NavigationChange>, String)> {
    Ok(match name {
        None => (Vec::new(), source),
        Some(name) => (
            name.split('+').map(nav_variant).collect::<Result<_>>()?,
            format!("{source}, navigation variant {name}"),
        ),
    })
}

/// `realms bench missions`.
pub fn run(args: BenchMissionsArgs) -> Result<()> {
    let (base, source) = load_scenario(args.scenario.as_deref())?;
    let variant = args
        .variant
        .as_deref()
        .map(crate::bench_slam::variant)
        .transpose()?;

    if args.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    let limit_s = match &args.duration {
        Some(d) => parse_duration_s(d)?,
        None => base.duration_s,
    };
    let seeds: Vec<u64> = (args.first_seed..args.first_seed + args.seeds).collect();
    let mut scenarios = Vec::with_capacity(seeds.len());
    for seed in &seeds {
        let mut s = base.clone();
        s.seed = *seed;
        s.duration_s = limit_s;
        s.validate(&source)?;
        scenarios.push(s);
    }
    let source = crate::bench_slam::with_setup(source, variant.as_ref());
    let (navigation_changes, source) = with_nav_variant(args.nav_variant.as_deref(), source)?;
    let jobs = workers(args.jobs);
    let mut missions = in_parallel(&scenarios, jobs, |scenario| {
        let wall = std::time::Instant::now();
        let options = MissionOptions {
            cost_clock: realms_mission::CostClock::new(std::time::Instant::now),
            mapping_changes: crate::bench_slam::mapping_changes(variant.as_ref()),
            navigation_changes: navigation_changes.clone(),
            ..MissionOptions::default()
        };
        let mut mission = Mission::with_options(World::new(scenario), options);
        run_to_end(
            &mut mission,
            Time::from_secs_f64(scenario.duration_s),
            false,
            |_| {},
        );
        let report = MissionReport::new(&mission, &source, wall.elapsed().as_secs_f64());
        MissionGrades::of(&report)
    });
    missions.sort_by_key(|m| m.seed);
    let summary = summarise(&missions);
    if args.json {
        let out =
            serde_json::json!({ "scenario": source, "missions": missions, "summary": summary });
        println!("{out}");
        return Ok(());
    }
    print_tables(&source, &seeds, jobs, limit_s, &missions, &summary);
    Ok(())
}

fn print_tables(
    source: &str,
    seeds: &[u64],
    jobs: usize,
    limit_s: f64,
    missions: &[MissionGrades],
    s: &Summary,
) {
    let pct = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.1} %", 100.0 * v));
    println!("# realms bench missions");
    println!();
    println!(
        "scenario: {source}; seeds {}..{}; missions of at most {:.0} s, ended as `realms mission` ends them; {jobs} at a time; machine: {}",
        seeds[0],
        seeds[seeds.len() - 1],
        limit_s,
        machine()
    );
    println!();
    println!(
        "| seed | rover | occupied cells right | final trajectory RMS | published pose within 0.2 m | published pose inside its 95 % circle (median standard deviation) | crater cells near the path marked (cells) | lost: times, seconds | powered at the end |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for m in missions {
        for r in &m.rovers {
            println!(
                "| {} | {} | {} | {} | {:.1} % | {:.1} % ({:.3} m) | {:.1} % ({}) | {} | {} |",
                m.seed,
                r.name,
                pct(r.occupied_correct),
                r.trajectory_rmse_m
                    .map_or("-".to_string(), |e| format!("{e:.3} m")),
                100.0 * r.pose_within_0_2_m,
                100.0 * r.pose_covariance.position_inside_95,
                r.pose_covariance.median_sigma_m,
                100.0 * r.path_hazards_flagged,
                r.path_hazards,
                lost_cell(&r.lost),
                if r.powered { "yes" } else { "no" }
            );
        }
    }
    println!();
    println!(
        "| seed | mission length | coverage at the end | 95 % covered at | lander's merged map, occupied cells right | the same with every map at its known start | maps found drifted / placed off their known start | fleet SLAM speed |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for m in missions {
        println!(
            "| {} | {:.0} s | {:.1} % | {} | {} | {} | {} / {} | {:.0}x |",
            m.seed,
            m.sim_duration_s,
            100.0 * m.coverage,
            m.time_to_95_s
                .map_or("-".to_string(), |t| format!("{t:.0} s")),
            pct(m.merged_occupied_correct),
            pct(m.merged_at_known_starts),
            m.maps_drifted,
            m.maps_moved,
            m.slam_speedup
        );
    }
    println!();
    println!(
        "| missions (rovers graded) | occupied cells right, mean / median | rovers under 80 / under 90 / at least 95 % | final trajectory RMS, mean / median / worst | rovers under 0.10 m | published pose within 0.2 m, mean | crater cells near the paths marked | hazard cells truly untraversable | known cells right (free, occupied, hazard), mean | lander's merged map, mean (every map at its known start; maps found drifted / placed off their known start) | mission length, mean | coverage at the end, mean | 95 % covered at, mean (missions that got there) | fleet SLAM speed, median |"
    );
    println!(
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    println!(
        "| {} ({}) | {:.1} / {:.1} % | {} / {} / {} | {:.3} / {:.3} / {:.2} m | {} | {:.1} % | {:.1} % | {:.1} % | {:.1} % | {} ({}; {} / {}) | {:.0} s | {:.1} % | {} | {:.0}x |",
        s.missions,
        s.rovers_graded,
        100.0 * s.occupied_correct_mean,
        100.0 * s.occupied_correct_median,
        s.rovers_under_80,
        s.rovers_under_90,
        s.rovers_at_least_95,
        s.trajectory_rmse_mean_m,
        s.trajectory_rmse_median_m,
        s.trajectory_rmse_worst_m,
        s.rovers_under_10cm,
        100.0 * s.pose_within_0_2_m_mean,
        100.0 * s.path_hazards_flagged,
        100.0 * s.hazard_correct,
        100.0 * s.known_correct_mean,
        pct(s.merged_occupied_correct_mean),
        pct(s.merged_at_known_starts_mean),
        s.maps_drifted,
        s.maps_moved,
        s.sim_duration_mean_s,
        100.0 * s.coverage_mean,
        s.time_to_95_mean_s.map_or("-".to_string(), |t| format!(
            "{t:.0} s ({} of {})",
            s.reached_95, s.missions
        )),
        s.slam_speedup_median
    );
    println!();
    println!(
        "| times a rover became lost | seconds lost, every rover | rovers still lost at the end |"
    );
    println!("| --- | --- | --- |");
    println!(
        "| {} | {:.0} s | {} |",
        s.lost_episodes, s.lost_s, s.lost_at_end
    );
    println!();
    println!(
        "| published poses graded | position inside its 95 % circle | heading inside its 95 % interval | median published position standard deviation, median rover |"
    );
    println!("| --- | --- | --- | --- |");
    println!(
        "| {} | {:.1} % | {:.1} % | {:.3} m |",
        s.covariance_instants,
        100.0 * s.position_inside_95,
        100.0 * s.heading_inside_95,
        s.median_sigma_m
    );
}

/// A rover's time lost as the per-rover table shows it.
fn lost_cell(lost: &LostTime) -> String {
    match lost.episodes {
        0 => "-".to_string(),
        n => format!(
            "{n}, {:.0} s{}",
            lost.seconds,
            if lost.at_end {
                " (lost at the end)"
            } else {
                ""
            }
        ),
    }
}
