//! `realms mission` and `realms scenario`: resolve flags into a scenario, run it with a
//! progress bar, write the results folder and say where it is.

use crate::cli::{MissionArgs, ScenarioArgs};
use anyhow::{Context, Result, bail};
use realms_core::Time;
use realms_mission::report::write_results;
use realms_mission::{Mission, MissionOptions};
use realms_sim::{Scenario, World};
use std::path::{Path, PathBuf};

/// Parses a duration such as `4h`, `90m`, `1h30m`, `45s` or a plain number of seconds.
pub fn parse_duration_s(text: &str) -> Result<f64> {
    if let Ok(secs) = text.trim().parse::<f64>() {
        if secs.is_finite() && secs > 0.0 {
            return Ok(secs);
        }
        bail!("duration {text:?} must be positive");
    }
    let d = humantime::parse_duration(text).with_context(|| {
        format!("duration {text:?}: expected e.g. 4h, 90m, 1h30m, 45s or seconds")
    })?;
    if d.is_zero() {
        bail!("duration {text:?} must be positive");
    }
    Ok(d.as_secs_f64())
}

/// The scenario named by `--scenario` (or the default) and where it came from.
pub fn load_scenario(path: Option<&Path>) -> Result<(Scenario, String)> {
    match path {
        Some(p) => Ok((Scenario::load(p)?, p.display().to_string())),
        None => Ok((Scenario::default(), "default".to_string())),
    }
}

/// `n` rovers, as a sentence says it ("1 rover", "3 rovers").
fn rovers(n: u8) -> String {
    format!("{n} rover{}", if n == 1 { "" } else { "s" })
}

/// `realms mission`.
pub fn run(args: MissionArgs) -> Result<()> {
    let (mut scenario, source) = load_scenario(args.scenario.as_deref())?;
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    if let Some(d) = &args.duration {
        scenario.duration_s = parse_duration_s(d)?;
    }
    if let Some(n) = args.rovers {
        for f in scenario.resize_fleet(n) {
            eprintln!(
                "note: the scenario's {} fault for {} at {} s is left out: the fleet has {}",
                f.kind.name(),
                f.rover,
                f.at_s,
                rovers(n)
            );
        }
    }
    if args.no_faults {
        scenario.faults.clear();
    }
    scenario.validate(&source)?;
    let variant = args
        .variant
        .as_deref()
        .map(crate::bench_slam::variant)
        .transpose()?;
    let source = crate::bench_slam::with_setup(source, variant.as_ref());
    let (navigation_changes, source) =
        crate::bench_missions::with_nav_variant(args.nav_variant.as_deref(), source)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| default_out_dir(scenario.seed));
    if out.exists()
        && out
            .read_dir()
            .map(|mut d| d.next().is_some())
            .unwrap_or(true)
        && args.out.is_none()
    {
        bail!("results folder {} already exists", out.display());
    }

    let wall = std::time::Instant::now();
    eprintln!(
        "realms mission: scenario {source}, seed {}, {}, {:.0} s simulated",
        scenario.seed,
        rovers(scenario.rovers.count),
        scenario.duration_s
    );
    let options = MissionOptions {
        ideal_comms: args.ideal_comms,
        cost_clock: realms_mission::CostClock::new(std::time::Instant::now),
        mapping_changes: crate::bench_slam::mapping_changes(variant.as_ref()),
        navigation_changes,
        ..MissionOptions::default()
    };
    let mut mission = Mission::with_options(World::new(&scenario), options);
    let end = Time::from_secs_f64(scenario.duration_s);
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let bar = indicatif::ProgressBar::new(scenario.duration_s.ceil() as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{elapsed_precise} [{bar:40}] {pos}/{len} sim s  {msg}",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        bar
    };
    run_to_end(&mut mission, end, args.full_duration, |sim_s| {
        bar.set_position(sim_s as u64);
        bar.set_message(format!(
            "{:.0}x real time",
            sim_s / wall.elapsed().as_secs_f64().max(1e-9)
        ));
    });
    bar.finish_and_clear();
    let wall_s = wall.elapsed().as_secs_f64();
    let report = write_results(&mission, &out, &source, wall_s)
        .with_context(|| format!("writing results to {}", out.display()))?;

    println!(
        "mission done: {:.0} s simulated in {:.1} s ({:.0}x real time)",
        report.sim_duration_s, wall_s, report.speedup
    );
    println!(
        "SLAM for {} rovers took {:.1} s of that ({:.0}x real time)",
        report.rovers.len(),
        report.slam_wall_s,
        report.slam_speedup
    );
    for r in &report.rovers {
        println!(
            "  {}: {:.0} m driven, {} collisions, {} hazard entries, {}{}",
            r.name,
            r.distance_m,
            r.collisions,
            r.hazard_entries,
            if r.powered { "powered" } else { "powered off" },
            if r.stuck { ", stuck" } else { "" }
        );
        let e = &r.slam;
        println!(
            "    SLAM pose error {:.2} m RMS ({:.2} m max, within 0.2 m {:.0} % of the time, inside its published 95 % circle {:.0} %), odometry {:.2} m RMS; {} localisation changes{}",
            e.pose_error.rmse_m,
            e.pose_error.max_m,
            100.0 * e.pose_error.share_within_0_2_m,
            100.0 * e.pose_covariance.position_inside_95,
            e.odometry_error.rmse_m,
            e.localisation.len(),
            e.map.map_or(String::new(), |m| format!(
                "; map: {:.1} % of occupied cells right, {:.1} % of the obstacles seen kept, \
                 {:.0} % of the explorable area known, {} ({:.0} % of hazard cells right)",
                100.0 * m.occupied_correct,
                100.0 * m.obstacle_faces_marked,
                100.0 * m.explorable_known,
                if m.true_hazards_known == 0 {
                    "no true hazard in the ground it knows".to_string()
                } else {
                    format!(
                        "{:.0} % of the {} true hazard cells it knows flagged",
                        100.0 * m.true_hazards_flagged,
                        m.true_hazards_known
                    )
                },
                100.0 * m.hazard_correct
            ))
        );
    }
    let powered_off: Vec<&str> = report
        .rovers
        .iter()
        .filter(|r| !r.powered)
        .map(|r| r.name.as_str())
        .collect();
    let complete = match (report.exploration_complete, powered_off.is_empty()) {
        (false, _) => String::new(),
        (true, true) => "; exploration complete, every rover home".to_string(),
        (true, false) => format!(
            "; exploration complete, every rover home but {} (powered off)",
            powered_off.join(", ")
        ),
    };
    println!(
        "coverage {:.1} % of the explorable area{}{}{}",
        100.0 * report.coverage,
        report
            .time_to_90_s
            .map_or(String::new(), |t| format!(", 90 % at {:.0} min", t / 60.0)),
        report
            .time_to_95_s
            .map_or(String::new(), |t| format!(", 95 % at {:.0} min", t / 60.0)),
        complete
    );
    let net = &report.network;
    if net.simulated {
        for r in &net.rovers {
            println!(
                "  {}: map updates {:.2} MB to the ground, {:.0}x less than a full grid a second; ground's copy {} s old at most outside blackouts (median {} s)",
                r.name,
                r.map_bytes as f64 / 1e6,
                r.map_reduction,
                r.map_lag_max_s.map_or("-".into(), |s| format!("{s:.1}")),
                r.map_lag_median_s.map_or("-".into(), |s| format!("{s:.1}")),
            );
        }
        println!(
            "network: {} dropped ({}), {} malformed, {} path changes",
            net.dropped.values().sum::<u64>(),
            net.dropped
                .iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect::<Vec<_>>()
                .join(", "),
            net.malformed,
            net.route_changes
        );
    } else {
        println!("network: ideal (every message instant and intact)");
    }
    println!("results in {}/", out.display());
    println!(
        "  mission.json  truth.png  trajectories.png  trajectories.csv  slam.csv  coverage.png  {}{}roverN_map.png/.pgm/.yaml",
        if net.simulated { "network.png  " } else { "" },
        if report.merge.is_some() {
            "merged_map.png/.pgm/.yaml  "
        } else {
            ""
        }
    );
    if let Some(m) = &report.merge {
        for l in &m.maps {
            match (&l.pose, &l.refused) {
                (Some(_), _) if !l.confirmed => println!(
                    "  merge: {} placed at its known start, unconfirmed ({}); {:.0} % of the two maps' obstacles lie within 0.5 m of the other's",
                    l.rover,
                    l.unconfirmed_because
                        .as_deref()
                        .unwrap_or("no pose confirmed"),
                    100.0 * l.agreement_at_start.unwrap_or(0.0),
                ),
                (Some(_), _) if !l.drifted => println!(
                    "  merge: {} confirmed at its known start (the maps agree {:.2} m from it), confidence {:.2}",
                    l.rover, l.drift_m, l.confidence,
                ),
                (Some(_), _) if !l.placed_off_known_start() => println!(
                    "  merge: {} drifted: the maps agree {:.2} m from its known start, confidence {:.2}; kept at the known start, which nothing in them contradicts ({:.0} % of the two maps' obstacles lie within 0.5 m of the other's there)",
                    l.rover,
                    l.drift_m,
                    l.confidence,
                    100.0 * l.agreement_at_start.unwrap_or(0.0),
                ),
                (Some(p), _) => println!(
                    "  merge: {} onto {} at ({:.2} m, {:.2} m, {:.1} deg), confidence {:.2}, drifted from the known start, which the maps contradict",
                    l.rover,
                    m.reference,
                    p[0],
                    p[1],
                    p[2].to_degrees(),
                    l.confidence,
                ),
                (None, why) => println!(
                    "  merge: {} refused: {}",
                    l.rover,
                    why.as_deref().unwrap_or("no pose")
                ),
            }
        }
        println!(
            "  merged map: {:.1} % of occupied cells right ({:.1} % with every map at its known start)",
            100.0 * m.occupied_correct,
            100.0 * m.occupied_correct_at_known_starts
        );
    }
    Ok(())
}

/// Runs `mission` as `realms mission` does: until `end`, or, unless `full_duration`, until
/// its rovers are done exploring, have drawn their maps from their final trajectories, and
/// the ground holds every rover's final map (after a blackout the queues must drain
/// first); then lets the nodes publish their final products.
/// `progress` hears the simulated seconds every 30 of them.
pub(crate) fn run_to_end(
    mission: &mut Mission,
    end: Time,
    full_duration: bool,
    mut progress: impl FnMut(f64),
) {
    let chunk = realms_core::Duration::from_secs(30);
    let mut explored_at = None;
    while mission.now() < end {
        if !full_duration && mission.exploration_over() && mission.maps_final() {
            let t = *explored_at.get_or_insert(mission.now());
            if mission.ground_current_since(t) {
                break;
            }
        }
        mission.run_until((mission.now() + chunk).min(end));
        progress(mission.now().as_secs_f64());
    }
    mission.finish();
}

/// `realms scenario`.
pub fn scenario(args: ScenarioArgs) -> Result<()> {
    if args.print_default {
        print!("{}", Scenario::default_toml());
        return Ok(());
    }
    if let Some(path) = args.check {
        let s = Scenario::load(&path)?;
        println!("{}: ok", path.display());
        print!("{}", realms_sim::scenario::to_toml(&s));
        return Ok(());
    }
    bail!("nothing to do: use --print-default or --check FILE")
}

/// `runs/<YYYYmmdd-HHMMSS>-seed<N>` in UTC.
fn default_out_dir(seed: u64) -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    let rem = secs % 86_400;
    PathBuf::from("runs").join(format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}-seed{seed}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    ))
}

/// Days since 1970-01-01 to a proleptic Gregorian date (Howard Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse_in_the_field_s_units() {
        assert_eq!(parse_duration_s("4h").expect("ok"), 14_400.0);
        assert_eq!(parse_duration_s("1h30m").expect("ok"), 5_400.0);
        assert_eq!(parse_duration_s("45").expect("ok"), 45.0);
        assert!(parse_duration_s("soon").is_err());
        assert!(parse_duration_s("0s").is_err());
        assert!(parse_duration_s("-5").is_err());
    }

    #[test]
    fn dates_are_gregorian() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_779), (2026, 11, 22));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
    }
}
