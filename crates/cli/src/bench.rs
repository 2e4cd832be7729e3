//! `realms bench sim`: how fast the simulator runs and what each sensor costs.
//!
//! Speed: the default arena, its rovers driving steady arcs (no autonomy; backing away from
//! what they run into; no faults), every sensor at its default rate, cameras off (nobody
//! subscribes);
//! simulated seconds per wall second, median of several trials, every frame cast, and again
//! as a mission runs it (a still rover measured on its last cast). Sensors: frames taken
//! from random free poses across the arena (each with a cold cache) and along a drive
//! (consecutive frames, as a rover takes them), median microseconds each, with plain
//! cell-by-cell ray marching timed in the same run as the baseline the max-mipmap caster is
//! compared against.

use crate::cli::{BenchSensor, BenchSimArgs};
use crate::mission::{load_scenario, parse_duration_s};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use realms_core::geometry::Vec3;
use realms_core::msgs::{Twist, TwistStamped};
use realms_core::{Duration, Pose2, RoverId, Time};
use realms_sim::World;
use realms_sim::raycast::HeightPyramid;
use realms_sim::rover::RoverBody;
use realms_sim::sensors::shadows::SunShadows;
use realms_sim::sensors::{Frame3, camera, depth, lidar};
use std::collections::BTreeMap;
use std::time::Instant;

/// `realms bench`.
pub fn run(cmd: crate::cli::BenchCommand) -> Result<()> {
    match cmd {
        crate::cli::BenchCommand::Sim(args) => sim(args),
        crate::cli::BenchCommand::Plan(args) => crate::bench_nav::plan(args),
        crate::cli::BenchCommand::Explore(args) => crate::bench_nav::explore(args),
        crate::cli::BenchCommand::NetRelay(args) => crate::bench_net::run(args),
        crate::cli::BenchCommand::NetSim(args) => crate::bench_net::net_sim(args),
        crate::cli::BenchCommand::Merge(args) => crate::bench_merge::run(args),
        crate::cli::BenchCommand::Slip(args) => crate::bench_slip::run(args),
        crate::cli::BenchCommand::Slam(args) => crate::bench_slam::run(args),
        crate::cli::BenchCommand::Logs(args) => crate::bench_logs::run(args),
        crate::cli::BenchCommand::Missions(args) => crate::bench_missions::run(args),
        crate::cli::BenchCommand::Compare(args) => crate::bench_compare::run(args),
    }
}

/// `f` over every job on `workers` threads, results in the order of `jobs` finishing.
pub(crate) fn in_parallel<J: Sync, R: Send>(
    jobs: &[J],
    workers: usize,
    f: impl Fn(&J) -> R + Sync,
) -> Vec<R> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..workers.max(1) {
            scope.spawn(|| {
                while let Some(job) =
                    jobs.get(next.fetch_add(1, std::sync::atomic::Ordering::SeqCst))
                {
                    let r = f(job);
                    results.lock().expect("no worker panics holding it").push(r);
                }
            });
        }
    });
    results.into_inner().expect("workers are done")
}

/// How many jobs to run at once: as asked, or one per core.
pub(crate) fn workers(jobs: Option<usize>) -> usize {
    jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// Runs a mission of `scenario` until its rovers have explored the arena or `limit_s` has
/// passed, and lets the nodes publish their final products.
pub(crate) fn explore_to_end(
    scenario: &realms_sim::scenario::Scenario,
    options: realms_mission::MissionOptions,
    limit_s: f64,
) -> realms_mission::Mission {
    let mut mission = realms_mission::Mission::with_options(World::new(scenario), options);
    let end = Time::from_secs_f64(limit_s);
    while mission.now() < end && !mission.exploration_over() {
        mission.run_until((mission.now() + Duration::from_secs(30)).min(end));
    }
    mission.finish();
    mission
}

/// The share of all the parts' items that are right, from each part's `(share right,
/// items)`; 0 without items.
pub(crate) fn pooled(parts: impl Iterator<Item = (f64, usize)>) -> f64 {
    let (right, all) = parts.fold((0.0, 0usize), |(r, a), (share, n)| {
        (r + share * n as f64, a + n)
    });
    right / all.max(1) as f64
}

/// The arithmetic mean; NaN for none.
pub(crate) fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The least value at or below which at least a share `q` of `v` lies (nearest rank); NaN
/// for none.
pub(crate) fn percentile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let k = ((v.len() as f64 * q).ceil() as usize).clamp(1, v.len().max(1)) - 1;
    v.get(k).copied().unwrap_or(f64::NAN)
}

pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn sim(args: BenchSimArgs) -> Result<()> {
    let (scenario, source) = load_scenario(args.scenario.as_deref())?;
    let sim_s = parse_duration_s(&args.duration)?;
    println!("# realms bench sim");
    println!();
    println!(
        "scenario: {source}, seed {}, {} rovers; machine: {}",
        scenario.seed,
        scenario.rovers.count,
        machine()
    );
    println!();

    let t0 = Instant::now();
    let world = World::new(&scenario);
    let gen_s = t0.elapsed().as_secs_f64();
    println!(
        "world generation (terrain, truth, pyramid): {:.0} ms",
        gen_s * 1e3
    );

    // Every rover's sensors run the whole trial: the scenario's faults are left out (the
    // default one powers rover2 off at 300 s, and a longer trial then timed two rovers).
    let trial_scenario = realms_sim::Scenario {
        faults: Vec::new(),
        ..scenario.clone()
    };
    // Speed trials, each paired with a trial on plain cell-by-cell ray casting: the shared
    // machine's speed drifts between runs, the ratio within a pair much less.
    let (mut speeds, mut ratios) = (Vec::new(), Vec::new());
    let (mut msgs, mut still) = (0usize, 0u64);
    let mut reusing = Vec::new();
    for trial in 0..args.trials {
        let fast = speed_trial(
            &trial_scenario,
            sim_s,
            Casting::EveryFrame,
            &mut msgs,
            &mut still,
        );
        speeds.push(fast);
        reusing.push(speed_trial(
            &trial_scenario,
            sim_s,
            Casting::ReuseStill,
            &mut 0,
            &mut 0,
        ));
        if args.no_plain {
            eprintln!("trial {trial}: {fast:.0}x real time");
            continue;
        }
        let plain = speed_trial(&trial_scenario, sim_s, Casting::Plain, &mut 0, &mut 0);
        eprintln!("trial {trial}: {fast:.0}x real time (plain ray casting: {plain:.0}x)");
        ratios.push(fast / plain);
    }
    if args.trials > 0 {
        // Without the plain trials there is no ratio to report.
        let ratio = if ratios.is_empty() {
            String::new()
        } else {
            format!(
                "; {:.1}x the speed with plain ray casting in the same run",
                median(ratios)
            )
        };
        println!(
            "speed: {:.0}x real time (median of {} trials of {:.0} simulated s, no faults; {} messages per trial; every scan and depth frame cast){ratio}",
            median(speeds),
            args.trials,
            sim_s,
            msgs / args.trials,
        );
        println!(
            "speed as a mission runs it: {:.0}x real time ({} scans and depth frames a trial taken where the one before was, the rover stuck or still, and measured on its cast)",
            median(reusing),
            still / args.trials as u64,
        );
        println!();
    }

    let spec = &scenario.rovers;
    // Plain cell-by-cell casting, built only when compared against.
    let baseline =
        (!args.no_plain).then(|| HeightPyramid::with_max_level(&world.terrain().heights, 0));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let free: Vec<Pose2> = {
        let g = *world.truth().explorable.geometry();
        let mut poses = Vec::new();
        while poses.len() < args.frames.max(1) {
            let x = rng.random_range(0.0..g.width_m());
            let y = rng.random_range(0.0..g.height_m());
            let p = Pose2::new(
                x,
                y,
                rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
            );
            if world.truth().explorable.at_world(p.position()) == Some(&true) {
                poses.push(p);
            }
        }
        poses
    };
    // Frames along a drive: 5 cm apart on a circle about the arena's centre, heading along
    // it. Consecutive frames see nearly the same ground, as a driving rover's do, so they find
    // much of what they read still in cache, which frames from random poses do not.
    let drive_poses: Vec<Pose2> = {
        let g = *world.truth().explorable.geometry();
        let centre = (g.width_m() / 2.0, g.height_m() / 2.0);
        let radius_m = 0.3 * g.width_m().min(g.height_m());
        let step_rad = 0.05 / radius_m;
        (0..)
            .map(|i| {
                let a = i as f64 * step_rad;
                Pose2::new(
                    centre.0 + radius_m * a.cos(),
                    centre.1 + radius_m * a.sin(),
                    a + std::f64::consts::FRAC_PI_2,
                )
            })
            .take(20 * args.frames.max(1))
            .filter(|p| world.truth().explorable.at_world(p.position()) == Some(&true))
            .take(args.frames.max(1))
            .collect()
    };
    let wants = |s: BenchSensor| args.sensor == BenchSensor::All || args.sensor == s;
    // (name, random poses, along the drive, baseline on random poses): medians in microseconds.
    let mut rows: Vec<(String, f64, f64, Option<f64>)> = Vec::new();
    let mut noise = rand_chacha::ChaCha8Rng::seed_from_u64(8);
    let mut sensor_frames = |poses: &[Pose2]| -> Vec<_> {
        poses
            .iter()
            .map(|pose| {
                let body = RoverBody::new(RoverId(1), *pose, spec, world.terrain(), &mut noise);
                let base = World::world_from_base(&body);
                (
                    base.compose(&world.base_from_lidar()),
                    base.compose(&world.base_from_optical()),
                )
            })
            .collect()
    };
    let frames = sensor_frames(&free);
    let drive = sensor_frames(&drive_poses);
    let time_each = |n: usize, f: &mut dyn FnMut(usize)| {
        let us: Vec<f64> = (0..n)
            .map(|i| {
                let s = Instant::now();
                f(i);
                s.elapsed().as_secs_f64() * 1e6
            })
            .collect();
        median(us)
    };
    if wants(BenchSensor::Lidar) {
        let mut run = |p: &HeightPyramid, at: &Frame3| {
            std::hint::black_box(lidar::scan(p, at, &spec.lidar, &mut noise, Time::ZERO, "l"));
        };
        let fast = time_each(frames.len(), &mut |i| run(world.pyramid(), &frames[i].0));
        let driving = time_each(drive.len(), &mut |i| run(world.pyramid(), &drive[i].0));
        let base = baseline
            .as_ref()
            .map(|b| time_each(frames.len(), &mut |i| run(b, &frames[i].0)));
        let name = format!(
            "lidar scan ({} beams, {} m)",
            spec.lidar.beams, spec.lidar.range_max_m
        );
        rows.push((name, fast, driving, base));
    }
    if wants(BenchSensor::Depth) {
        let mut run = |p: &HeightPyramid, at: &Frame3| {
            std::hint::black_box(depth::frame(
                p,
                at,
                &spec.depth,
                &mut noise,
                Time::ZERO,
                "d",
            ));
        };
        let fast = time_each(frames.len(), &mut |i| run(world.pyramid(), &frames[i].1));
        let driving = time_each(drive.len(), &mut |i| run(world.pyramid(), &drive[i].1));
        let base = baseline
            .as_ref()
            .map(|b| time_each(frames.len(), &mut |i| run(b, &frames[i].1)));
        let d = &spec.depth;
        let name = format!(
            "depth frame ({}x{}, {} m)",
            d.width, d.height, d.range_max_m
        );
        rows.push((name, fast, driving, base));
    }
    if wants(BenchSensor::Camera) {
        let c = &spec.camera;
        // The shadows are worked out once, when a camera is first rendered.
        let started = Instant::now();
        let shadows = SunShadows::new(&world.terrain().heights, &scenario.sun);
        let shadows_ms = started.elapsed().as_secs_f64() * 1e3;
        let run = |at: &Frame3| {
            std::hint::black_box(camera::render(
                world.pyramid(),
                world.terrain(),
                &shadows,
                at,
                c,
                Time::ZERO,
                "c",
            ));
        };
        let fast = time_each(frames.len(), &mut |i| run(&frames[i].1));
        let driving = time_each(drive.len(), &mut |i| run(&drive[i].1));
        println!(
            "sun's shadows over the terrain, worked out at the first camera image: {shadows_ms:.0} ms"
        );
        rows.push((
            format!("camera image ({}x{}, shadows)", c.width, c.height),
            fast,
            driving,
            None,
        ));
    }
    if rows.is_empty() {
        return Ok(());
    }
    println!(
        "| sensor | median per frame, random poses | along a drive | baseline: plain cell march, no pyramid or clearance field (random poses) | speedup |"
    );
    println!("| --- | --- | --- | --- | --- |");
    for (name, fast, driving, base) in &rows {
        match base {
            Some(b) => println!(
                "| {name} | {fast:.1} us | {driving:.1} us | {b:.1} us | {:.1}x |",
                b / fast
            ),
            None => println!("| {name} | {fast:.1} us | {driving:.1} us | - | - |"),
        }
    }
    let row = |prefix: &str| rows.iter().find(|r| r.0.starts_with(prefix));
    if let (Some(l), Some(d)) = (row("lidar"), row("depth")) {
        let per_sim_s_us = |lidar_us: f64, depth_us: f64| {
            f64::from(spec.count) * (spec.lidar.rate_hz * lidar_us + spec.depth.rate_hz * depth_us)
        };
        println!();
        for (which, us) in [
            ("random poses", per_sim_s_us(l.1, d.1)),
            ("along a drive", per_sim_s_us(l.2, d.2)),
        ] {
            println!(
                "sensor budget ({which}): {:.2} ms of lidar + depth per simulated second for {} rovers ({:.0}x real time if sensors were all)",
                us / 1e3,
                spec.count,
                1e6 / us
            );
        }
    }
    Ok(())
}

/// How long a speed trial's rover backs away and turns after it runs into something: straight
/// back for the first half, then a turn where it stands.
const BACK_AWAY: Duration = Duration::from_millis(2000);

/// How a speed trial's sensors cast their rays.
#[derive(Clone, Copy, PartialEq)]
enum Casting {
    /// Every scan and frame cast through the pyramid and distance fields.
    EveryFrame,
    /// As the mission runs: a rover that has not moved measures on its last cast.
    ReuseStill,
    /// Every scan and frame cast cell by cell (the baseline).
    Plain,
}

/// Simulated seconds per wall second with the rovers driving steady arcs (backing away
/// from what they run into); adds the messages published to `msgs` and the scans and frames
/// taken where the one before was to `still`.
fn speed_trial(
    scenario: &realms_sim::Scenario,
    sim_s: f64,
    casting: Casting,
    msgs: &mut usize,
    still: &mut u64,
) -> f64 {
    let mut w = World::new(scenario);
    if casting == Casting::Plain {
        w.use_plain_ray_casting();
    }
    w.reuse_still_casts(casting == Casting::ReuseStill);
    let mut out = Vec::new();
    let start = Instant::now();
    let step = Duration::from_millis(250);
    let mut t = Time::ZERO;
    let end = Time::from_secs_f64(sim_s);
    // A rover that runs into something backs away and turns, then drives its arc again:
    // driven straight on it would stand against the obstacle for the rest of the trial, its
    // sensors seeing the same thing frame after frame.
    let mut events_seen = 0;
    let mut backing_until: BTreeMap<String, Time> = BTreeMap::new();
    while t < end {
        t = (t + step).min(end);
        for e in &w.events()[events_seen..] {
            if e.kind == realms_sim::SimEventKind::Collision {
                backing_until.insert(e.rover.clone(), w.now() + BACK_AWAY);
            }
        }
        events_seen = w.events().len();
        let ids: Vec<RoverId> = w.rovers().map(|b| b.id).collect();
        for id in ids {
            let phase = t.as_secs_f64() / 10.0 + f64::from(id.0);
            let left_s = backing_until
                .get(&id.to_string())
                .map_or(0.0, |until| (*until - w.now()).as_secs_f64());
            let (v, turn) = if left_s > BACK_AWAY.as_secs_f64() / 2.0 {
                (-0.2, 0.0)
            } else if left_s > 0.0 {
                (0.0, 1.0)
            } else {
                (0.3, 0.3 * phase.sin())
            };
            w.command(
                id,
                TwistStamped {
                    header: realms_core::msgs::Header {
                        stamp: w.now(),
                        frame_id: format!("{id}/base_link"),
                    },
                    twist: Twist {
                        linear: Vec3::new(v, 0.0, 0.0),
                        angular: Vec3::new(0.0, 0.0, turn),
                    },
                },
            );
        }
        w.advance_to(t, &mut out);
        *msgs += out.len();
        out.clear();
    }
    let speed = sim_s / start.elapsed().as_secs_f64();
    *still += w.still_casts();
    speed
}

pub(crate) fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    format!("{cpu}, {cores} cores, one thread used")
}
