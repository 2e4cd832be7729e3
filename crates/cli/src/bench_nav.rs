//! `realms bench plan` and `realms bench explore`: what navigation costs and what exploration
//! achieves.
//!
//! - plan: cross-arena paths on the costmap of the default arena's ground truth (1000 x 720
//!   cells of 5 cm), A* against plain Dijkstra on the same graph in the same run (the
//!   machine is shared and noisy, the ratio within a run much less so); medians.
//! - explore: whole missions for several fleet sizes and seeds, ideal communication and no
//!   faults (the setting of the exploration targets); coverage over time against the
//!   simulator's explorable area, median over seeds, as a table and a PNG.

use crate::cli::{BenchExploreArgs, BenchPlanArgs};
use crate::mission::{load_scenario, parse_duration_s};
use anyhow::{Context, Result, bail};
use realms_core::{Cell, Grid, Point2};
use realms_mission::MissionOptions;
use realms_mission::chart::{Series, coverage_chart};
use realms_mission::report::ROVER_COLORS;
use realms_nav::costmap::{Costmap, CostmapConfig};
use realms_nav::planner::{Planner, PlannerConfig, smooth};
use realms_sim::{TruthCell, World};
use std::time::Instant;

/// The nearest cell to `p` that costs nothing (free and clear of every obstacle's gradient).
fn free_near(map: &Costmap, p: Point2) -> Option<Point2> {
    let geo = map.geometry();
    let c = geo.world_to_cell(p)?;
    for r in 0..200i64 {
        for dy in -r..=r {
            for dx in -r..=r {
                if dx.abs() != r && dy.abs() != r {
                    continue;
                }
                let (x, y) = (c.x as i64 + dx, c.y as i64 + dy);
                if x < 0 || y < 0 || x >= geo.width as i64 || y >= geo.height as i64 {
                    continue;
                }
                let cell = Cell {
                    x: x as usize,
                    y: y as usize,
                };
                if map.cost(cell) == 0 {
                    return Some(geo.cell_center(cell));
                }
            }
        }
    }
    None
}

/// `realms bench plan`.
pub fn plan(args: BenchPlanArgs) -> Result<()> {
    let (scenario, source) = load_scenario(args.scenario.as_deref())?;
    let world = World::new(&scenario);
    let truth = &world.truth().traversability;
    let map: Grid<i8> = truth.map(|c| match c {
        TruthCell::Free => 0,
        TruthCell::Obstacle => 100,
        TruthCell::Hazard => 90,
    });
    let t0 = Instant::now();
    let costmap = Costmap::from_map(&map, &CostmapConfig::default());
    let build_ms = t0.elapsed().as_secs_f64() * 1e3;
    let geo = *costmap.geometry();
    println!("# realms bench plan");
    println!();
    println!(
        "scenario: {source}, seed {}; costmap {} x {} cells of {} m from the ground truth (built in {build_ms:.1} ms); machine: {}",
        scenario.seed,
        geo.width,
        geo.height,
        geo.resolution_m,
        crate::bench::machine()
    );
    println!();
    let (w, h) = (geo.width_m(), geo.height_m());
    let pairs = [
        ("south-west to north-east", (1.0, 1.0), (w - 1.0, h - 1.0)),
        ("north-west to south-east", (1.0, h - 1.0), (w - 1.0, 1.0)),
        ("west to east", (1.0, h / 2.0), (w - 1.0, h / 2.0)),
        (
            "lander to the far wall",
            (w / 2.0, 6.0),
            (w / 2.0 - 3.0, h - 1.0),
        ),
    ];
    println!(
        "| path | length | A* median | expanded | Dijkstra median | expanded | Dijkstra / A* |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    let mut planner = Planner::new(PlannerConfig::default());
    let (mut all_astar, mut all_ratio) = (Vec::new(), Vec::new());
    for (name, s, g) in pairs {
        let start = free_near(&costmap, Point2::new(s.0, s.1)).context("no free start")?;
        let goal = free_near(&costmap, Point2::new(g.0, g.1)).context("no free goal")?;
        let (mut astar, mut dijkstra) = (Vec::new(), Vec::new());
        let (mut exp_a, mut exp_d, mut length) = (0, 0, 0.0);
        for _ in 0..args.trials {
            let t = Instant::now();
            let a = planner.plan(&costmap, start, goal)?;
            astar.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            let d = planner.plan_dijkstra(&costmap, start, goal)?;
            dijkstra.push(t.elapsed().as_secs_f64() * 1e3);
            if (a.cost - d.cost).abs() > 1e-3 * a.cost {
                bail!(
                    "A* and Dijkstra disagree on {name}: {} against {}",
                    a.cost,
                    d.cost
                );
            }
            exp_a = a.expanded;
            exp_d = d.expanded;
            let path = smooth(&costmap, &a.cells, 2.0);
            length = path.windows(2).map(|p| p[0].distance_m(p[1])).sum();
        }
        let (ma, md) = (crate::bench::median(astar), crate::bench::median(dijkstra));
        all_astar.push(ma);
        all_ratio.push(md / ma);
        println!(
            "| {name} | {length:.1} m | {ma:.2} ms | {exp_a} | {md:.2} ms | {exp_d} | {:.1}x |",
            md / ma
        );
    }
    println!();
    println!(
        "median over the paths: A* {:.2} ms, {:.1}x faster than Dijkstra ({} trials each)",
        crate::bench::median(all_astar),
        crate::bench::median(all_ratio),
        args.trials
    );
    frontiers(&map)
}

/// Frontier detection as a rover explores: the ground truth revealed disc by disc along a
/// serpentine across the arena, and after each disc the frontiers found by the incremental
/// tracker and by a full detection, timed in the same run (the costmap is built untimed).
fn frontiers(truth: &Grid<i8>) -> Result<()> {
    const SENSING_RADIUS_M: f64 = 5.0;
    const STEP_M: f64 = 2.5;
    let geo = *truth.geometry();
    let mut map = Grid::new(geo, -1i8);
    let (w, h) = (geo.width_m(), geo.height_m());
    let mut stops = Vec::new();
    let mut row = 0;
    let mut y = 3.0;
    while y < h {
        let xs: Vec<f64> = (0..)
            .map(|k| 3.0 + k as f64 * STEP_M)
            .take_while(|x| *x < w)
            .collect();
        let ordered: Vec<f64> = if row % 2 == 0 {
            xs
        } else {
            xs.into_iter().rev().collect()
        };
        stops.extend(ordered.into_iter().map(|x| Point2::new(x, y)));
        y += 2.0 * SENSING_RADIUS_M;
        row += 1;
    }
    let cfg = CostmapConfig::default();
    let min_cells = realms_nav::explore::ExploreConfig::default().min_frontier_cells;
    let mut tracker = realms_nav::frontier::FrontierTracker::new();
    let (mut full_ms, mut tracked_ms, mut examined) = (Vec::new(), Vec::new(), Vec::new());
    for stop in &stops {
        for cell in geo.cells_within(*stop, SENSING_RADIUS_M) {
            map.cells_mut()[geo.index(cell)] = truth.cells()[geo.index(cell)];
        }
        let costmap = Costmap::from_map(&map, &cfg);
        let t = Instant::now();
        let full = realms_nav::frontier::detect(&map, &costmap, min_cells, None);
        full_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let tracked = tracker.update(&map, &costmap, min_cells, None);
        tracked_ms.push(t.elapsed().as_secs_f64() * 1e3);
        examined.push(tracker.last_examined() as f64);
        if tracked != full {
            bail!("the tracker and full detection disagree at {stop:?}");
        }
    }
    // The first update examines every cell; the rest are the incremental case.
    let (full_ms, tracked_ms, examined) = (&full_ms[1..], &tracked_ms[1..], &examined[1..]);
    let ratios: Vec<f64> = full_ms.iter().zip(tracked_ms).map(|(f, t)| f / t).collect();
    println!();
    println!(
        "frontier detection over {} map updates ({} m discs revealed every {STEP_M} m along a serpentine, {} x {} cells):",
        full_ms.len(),
        SENSING_RADIUS_M,
        geo.width,
        geo.height
    );
    println!(
        "| full detection median | incremental median | full / incremental (median of per-update ratios) | flag examinations per update, median |"
    );
    println!("| --- | --- | --- | --- |");
    println!(
        "| {:.2} ms | {:.2} ms | {:.1}x | {:.0} of {} |",
        crate::bench::median(full_ms.to_vec()),
        crate::bench::median(tracked_ms.to_vec()),
        crate::bench::median(ratios),
        crate::bench::median(examined.to_vec()),
        geo.len()
    );
    Ok(())
}

/// One mission's outcome.
#[derive(Clone, Debug)]
struct Run {
    rovers: u8,
    seed: u64,
    series: Vec<(f64, f64)>,
    end_s: f64,
    complete: bool,
    collisions: u32,
    hazard_entries: u32,
    stuck: u32,
    wall_s: f64,
    /// Wall time of every rover's SLAM, summed.
    slam_wall_s: f64,
    /// Per rover: the final trajectory's RMS error in the arena frame, and aligned, metres.
    slam: Vec<(f64, f64)>,
    /// Over all rovers' final maps: true hazard cells the maps know and those they flag;
    /// true hazard cells near the rovers' paths and those flagged.
    hazards: HazardTally,
}

/// True hazard cells counted over a fleet's maps (a cell counts once per map).
#[derive(Clone, Copy, Debug, Default)]
struct HazardTally {
    known: usize,
    known_flagged: f64,
    near_path: usize,
    near_path_flagged: f64,
}

impl HazardTally {
    fn add(&mut self, g: &realms_mission::slam_record::MapGrade) {
        self.known += g.true_hazards_known;
        self.known_flagged += g.true_hazards_flagged * g.true_hazards_known as f64;
        self.near_path += g.path_hazards;
        self.near_path_flagged += g.path_hazards_flagged * g.path_hazards as f64;
    }

    /// The fractions flagged: of those the maps know, of those near the paths.
    fn fractions(&self) -> (f64, f64) {
        (
            self.known_flagged / self.known.max(1) as f64,
            self.near_path_flagged / self.near_path.max(1) as f64,
        )
    }
}

impl Run {
    /// Coverage at `t_s` (the latest sample at or before it).
    fn at(&self, t_s: f64) -> f64 {
        self.series
            .iter()
            .take_while(|(t, _)| *t <= t_s)
            .last()
            .map_or(0.0, |(_, f)| *f)
    }

    /// The worst rover's final trajectory error, in the arena frame and aligned.
    fn worst_slam(&self) -> (f64, f64) {
        self.slam
            .iter()
            .fold((0.0, 0.0), |(a, b), (x, y)| (a.max(*x), b.max(*y)))
    }

    fn time_to(&self, level: f64) -> Option<f64> {
        self.series
            .iter()
            .find(|(_, f)| *f >= level)
            .map(|(t, _)| *t)
    }
}

/// `realms bench explore`.
pub fn explore(args: BenchExploreArgs) -> Result<()> {
    let (base, source) = load_scenario(args.scenario.as_deref())?;
    let limit_s = parse_duration_s(&args.duration)?;
    let fleets: Vec<u8> = args
        .rovers
        .split(',')
        .map(|s| s.trim().parse::<u8>())
        .collect::<Result<_, _>>()
        .context("--rovers: a comma-separated list of fleet sizes, e.g. 1,2,3")?;
    if fleets.contains(&0) {
        bail!("--rovers: a fleet has at least one rover");
    }
    let jobs: Vec<(u8, u64)> = fleets
        .iter()
        .flat_map(|n| (0..args.seeds).map(move |k| (*n, args.first_seed + k)))
        .collect();
    let workers = crate::bench::workers(args.jobs);
    println!("# realms bench explore");
    println!();
    println!(
        "scenario: {source}; fleets {fleets:?}; seeds {}..{}; up to {:.0} min each; ideal communication{}, no faults; {workers} missions at a time; machine: {}",
        args.first_seed,
        args.first_seed + args.seeds,
        limit_s / 60.0,
        if args.no_peer_messages {
            " but rovers do not hear each other"
        } else {
            ""
        },
        crate::bench::machine()
    );
    println!();
    let mut runs = crate::bench::in_parallel(&jobs, workers, |&(n, seed)| {
        let mut s = base.clone();
        s.seed = seed;
        s.rovers.count = n;
        s.faults.clear();
        s.duration_s = limit_s;
        let t0 = Instant::now();
        let options = MissionOptions {
            rovers_hear_each_other: !args.no_peer_messages,
            // The targets are set for ideal communication.
            ideal_comms: true,
            cost_clock: realms_mission::CostClock::new(Instant::now),
            ..MissionOptions::default()
        };
        let mission = crate::bench::explore_to_end(&s, options, limit_s);
        let bodies: Vec<_> = mission.world().rovers().collect();
        let mut hazards = HazardTally::default();
        for record in mission.slam_records() {
            if let Some(grade) = record.summary(mission.world().truth(), None).map {
                hazards.add(&grade);
            }
        }
        let run = Run {
            rovers: n,
            seed,
            series: mission.coverage().series().to_vec(),
            end_s: mission.now().as_secs_f64(),
            complete: mission.exploration_over(),
            collisions: bodies.iter().map(|b| b.stats.collisions).sum(),
            hazard_entries: bodies.iter().map(|b| b.stats.hazard_entries).sum(),
            stuck: bodies.iter().filter(|b| b.stuck).count() as u32,
            wall_s: t0.elapsed().as_secs_f64(),
            slam_wall_s: mission.slam_wall_s(),
            slam: mission
                .slam_records()
                .iter()
                .filter_map(|r| {
                    Some((
                        r.trajectory_error()?.rmse_m,
                        r.trajectory_error_aligned_m()?,
                    ))
                })
                .collect(),
            hazards,
        };
        let worst = run.worst_slam();
        eprintln!(
            "{} rovers, seed {}: {:.1} % at {:.0} min{}, {} collisions, {} hazard entries, SLAM worst {:.2} m ({:.2} m aligned), {:.0} s wall ({:.0} s SLAM)",
            run.rovers,
            run.seed,
            100.0 * run.series.last().map_or(0.0, |s| s.1),
            run.end_s / 60.0,
            if run.complete { " (complete)" } else { "" },
            run.collisions,
            run.hazard_entries,
            worst.0,
            worst.1,
            run.wall_s,
            run.slam_wall_s
        );
        run
    });
    runs.sort_by_key(|r| (r.rovers, r.seed));

    println!(
        "| seed | rovers | coverage | 90 % at | 95 % at | done at | complete | collisions | hazard entries | stuck | SLAM RMS, worst rover (aligned) | true hazards flagged: known / near the paths | wall | SLAM's wall, all rovers |"
    );
    println!(
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    let minutes = |t: Option<f64>| t.map_or("-".to_string(), |t| format!("{:.1} min", t / 60.0));
    for r in &runs {
        let worst = r.worst_slam();
        println!(
            "| {} | {} | {:.1} % | {} | {} | {:.1} min | {} | {} | {} | {} | {:.2} m ({:.2} m) | {:.0} / {:.0} % | {:.0} s | {:.0} s ({:.0}x real time) |",
            r.seed,
            r.rovers,
            100.0 * r.series.last().map_or(0.0, |s| s.1),
            minutes(r.time_to(0.9)),
            minutes(r.time_to(0.95)),
            r.end_s / 60.0,
            if r.complete { "yes" } else { "no" },
            r.collisions,
            r.hazard_entries,
            r.stuck,
            worst.0,
            worst.1,
            100.0 * r.hazards.fractions().0,
            100.0 * r.hazards.fractions().1,
            r.wall_s,
            r.slam_wall_s,
            r.end_s / r.slam_wall_s.max(1e-9)
        );
    }
    println!();
    println!("Median over seeds (a run that never got there counts as the time limit):");
    println!();
    println!(
        "| rovers | 50 % at | 90 % at | 95 % at | coverage at 15 / 30 / 60 / 90 min | collisions | hazard entries | SLAM RMS per rover, median (aligned) | true hazards flagged: known / near the paths |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let median_time = |set: &[&Run], level: f64| {
        crate::bench::median(
            set.iter()
                .map(|r| r.time_to(level).unwrap_or(limit_s))
                .collect(),
        )
    };
    let mut curves = Vec::new();
    let mut t90 = Vec::new();
    for (k, n) in fleets.iter().enumerate() {
        let set: Vec<&Run> = runs.iter().filter(|r| r.rovers == *n).collect();
        let at = |t: f64| crate::bench::median(set.iter().map(|r| r.at(t)).collect());
        let m90 = median_time(&set, 0.9);
        t90.push((*n, m90));
        println!(
            "| {n} | {:.1} min | {:.1} min | {:.1} min | {:.0} / {:.0} / {:.0} / {:.0} % | {} | {} | {:.2} m ({:.2} m) | {:.0} / {:.0} % |",
            median_time(&set, 0.5) / 60.0,
            m90 / 60.0,
            median_time(&set, 0.95) / 60.0,
            100.0 * at(900.0),
            100.0 * at(1800.0),
            100.0 * at(3600.0),
            100.0 * at(5400.0),
            set.iter().map(|r| r.collisions).sum::<u32>(),
            set.iter().map(|r| r.hazard_entries).sum::<u32>(),
            crate::bench::median(
                set.iter()
                    .flat_map(|r| r.slam.iter().map(|s| s.0))
                    .collect()
            ),
            crate::bench::median(
                set.iter()
                    .flat_map(|r| r.slam.iter().map(|s| s.1))
                    .collect()
            ),
            100.0 * crate::bench::median(set.iter().map(|r| r.hazards.fractions().0).collect()),
            100.0 * crate::bench::median(set.iter().map(|r| r.hazards.fractions().1).collect()),
        );
        let points = (0..=(limit_s / 30.0) as usize)
            .map(|i| {
                let t = i as f64 * 30.0;
                (t, at(t))
            })
            .collect();
        curves.push(Series {
            color: ROVER_COLORS[k % ROVER_COLORS.len()],
            points,
        });
    }
    if let (Some(&(1, one)), Some(&(n, many))) = (t90.first(), t90.last())
        && n > 1
    {
        println!();
        println!(
            "time to 90 % with {n} rovers / with 1 rover: {:.2}",
            many / one
        );
    }
    if let Some(png) = &args.png {
        coverage_chart(&curves, limit_s).write_png(png, |c| *c)?;
        println!();
        println!(
            "curves (median per fleet size; colours in fleet order {fleets:?}: red, blue, green...) in {}",
            png.display()
        );
    }
    Ok(())
}
