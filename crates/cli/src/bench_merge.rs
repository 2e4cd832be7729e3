//! `realms bench merge`: map merging on generated pairs with a known answer.
//!
//! Kinds `lunar-rovers` and `lunar-rovers-known-start` take the maps the rovers built in
//! default missions instead ([`bench_merge_rovers`]): success there is within 0.3 m and
//! 2 degrees, the maps' own drift, and they are merged with [`Params::for_rover_maps`].
//!
//! Sources: the recorded maps in `../shared/data/maps` (real: Willow Garage, the TurtleBot3
//! office; sim-building: the two AWS Gazebo worlds) and lunar arenas from the simulator's
//! ground truth (sparse and very sparse: few boulders, few craters). Each pair is cut by
//! [`realms_merge::synth`] with the chosen overlap; the second map is turned by a random
//! heading and shifted, both get unknown patches and speckle. Success: the centre of the
//! overlap placed within 3 cells and the heading within 2 degrees. A wrong merge is an
//! accepted estimate that is not a success; refusals are counted apart. Time is per pair on
//! one thread: preparing both maps and estimating.

use crate::bench::{machine, median};
use crate::bench_merge_rovers;
use crate::cli::BenchMergeArgs;
use anyhow::{Context, Result};
use rand::SeedableRng;
use realms_core::Grid;
use realms_merge::synth::{self, PairSpec};
use realms_merge::{MapCell, Params, Prepared};
use realms_sim::{GroundTruth, Scenario, Terrain};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// Success: translation error below this many cells...
const SUCCESS_CELLS: f64 = 3.0;
/// ... and heading error below this.
const SUCCESS_DEG: f64 = 2.0;
/// Success for two rovers' maps: within this distance and turn of their shared frame at the
/// overlap's centre.
/// Each map drifts from the truth by up to a few decimetres (BENCHMARKS.md), so their
/// shared frame is the answer only to about that; this is the known-start mode's own drift
/// tolerance ([`realms_merge::PriorWindow`]).
fn rover_success() -> (f64, f64) {
    let w = realms_merge::PriorWindow::default();
    (w.drift_tolerance_m, w.drift_tolerance_rad.to_degrees())
}
/// A wrong merge farther off than this (or turned more than [`GROSS_DEG`]) is gross; the
/// others are near misses (the right place, a few cells or a degree off).
const GROSS_M: f64 = 1.0;
/// See [`GROSS_M`].
const GROSS_DEG: f64 = 5.0;

/// One row of the table.
#[derive(Clone, Debug, Serialize)]
struct Row {
    kind: String,
    overlap_pct: u32,
    pairs: usize,
    success_pct: f64,
    wrong_pct: f64,
    /// Wrong merges off by more than 1 m or 5 degrees (the rest are near misses).
    gross_wrong_pct: f64,
    refused_pct: f64,
    /// Pairs whose overlap holds a landmark (rock, crater rim) agreeing at the true pose;
    /// walls alone fit every slide along them, so the others cannot be merged by anything.
    with_landmark: usize,
    /// Success among those, percent.
    success_with_landmark_pct: f64,
    /// Median error of the successful merges at the overlap's centre, metres, and of their
    /// heading, degrees (NaN, `null` in JSON, with none); from a known start, of the pose
    /// the maps agreed on (a confirmed map is placed at the prior itself).
    success_median_error_m: f64,
    success_median_error_deg: f64,
    median_ms: f64,
    max_ms: f64,
}

/// A lunar arena's ground truth as the map a perfect sensor suite would build: lidar
/// obstacles occupied; craters, steep slopes and rocks the lidar passes over as hazards;
/// explorable ground free; the rest unknown.
pub fn lunar_map(truth: &GroundTruth) -> Grid<MapCell> {
    truth.perfect_map().map(|v| MapCell::from_occupancy(*v))
}

/// The default arena with fewer rocks and craters.
fn lunar_source(very_sparse: bool, seed: u64) -> Grid<MapCell> {
    let mut sc = Scenario {
        seed,
        ..Scenario::default()
    };
    if very_sparse {
        sc.boulders.large_count = 2;
        sc.boulders.small_count = 30;
        sc.craters.small_count = 1;
        sc.craters.large_count = 1;
    } else {
        sc.boulders.large_count = 5;
        sc.boulders.small_count = 120;
    }
    let terrain = Terrain::generate(&sc);
    lunar_map(&GroundTruth::derive(&terrain, &sc))
}

fn real_sources(dir: &std::path::Path, names: &[&str]) -> Result<Vec<Grid<MapCell>>> {
    names
        .iter()
        .map(|n| {
            let path = dir.join(format!("{n}.yaml"));
            let map = realms_merge::io::read(&path)
                .with_context(|| format!("reading the source map {}", path.display()))?;
            Ok(map.cells)
        })
        .collect()
}

/// Where the error is measured: the centre of the second map's known cells that the first
/// map also knows, in the second map's frame (its whole centre if they share none). The
/// maps constrain the pose where they overlap; a heading error moves points away from
/// there, and that is judged by the heading criterion.
fn overlap_centre(pair: &synth::Pair) -> realms_core::Point2 {
    let frame_b_from_grid = pair.b.frame_from_grid();
    let a_grid_from_b_grid = pair
        .a
        .frame_from_grid()
        .inverse()
        .compose(&pair.a_from_b)
        .compose(&frame_b_from_grid);
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for (cell, v) in pair.b.cells.iter().step_by(3) {
        if !v.is_known() {
            continue;
        }
        let local = pair.b.cell_centre_in_grid(cell);
        if pair
            .a
            .knows_in_grid(a_grid_from_b_grid.transform_point(local))
        {
            sx += local.x_m;
            sy += local.y_m;
            n += 1;
        }
    }
    let local = if n == 0 {
        pair.b.known_centroid_in_grid()
    } else {
        realms_core::Point2::new(sx / n as f64, sy / n as f64)
    };
    frame_b_from_grid.transform_point(local)
}

/// The second map laid over the first at `a_from_b`, in the first map's grid: the first
/// map's structure (obstacles, hazards) red, the second's blue, both black; free ground
/// white where both know it, pale where one does.
fn write_overlay(
    pair: &synth::Pair,
    a_from_b: &realms_core::Pose2,
    path: &std::path::Path,
) -> Result<()> {
    let ga = *pair.a.geometry();
    let gb = *pair.b.geometry();
    let b_grid_from_a_grid = pair
        .b
        .frame_from_grid()
        .inverse()
        .compose(&a_from_b.inverse())
        .compose(&pair.a.frame_from_grid());
    let mut canvas = Grid::new(ga, [128u8, 128, 128]);
    for (cell, a) in pair.a.cells.iter() {
        let q = b_grid_from_a_grid.transform_point(realms_core::Point2::new(
            (cell.x as f64 + 0.5) * ga.resolution_m,
            (cell.y as f64 + 0.5) * ga.resolution_m,
        ));
        let (bx, by) = (q.x_m / gb.resolution_m, q.y_m / gb.resolution_m);
        let b = if bx >= 0.0 && by >= 0.0 {
            pair.b.cells.get(bx as usize, by as usize).copied()
        } else {
            None
        }
        .unwrap_or(MapCell::Unknown);
        let structure = |c: MapCell| matches!(c, MapCell::Occupied | MapCell::Hazard);
        let colour = match (structure(*a), structure(b), a.is_known(), b.is_known()) {
            (true, true, _, _) => [0, 0, 0],
            (true, false, _, true) => [230, 0, 0],
            (true, false, _, false) => [240, 150, 150],
            (false, true, true, _) => [0, 0, 230],
            (false, true, false, _) => [150, 150, 240],
            (false, false, true, true) => [255, 255, 255],
            (false, false, true, false) | (false, false, false, true) => [215, 215, 215],
            (false, false, false, false) => [128, 128, 128],
        };
        if let Some(c) = canvas.get_mut(cell.x, cell.y) {
            *c = colour;
        }
    }
    canvas
        .write_png(path, |c| *c)
        .with_context(|| format!("writing {}", path.display()))
}

/// Estimates one case, times it and adds its verdict to `tally`; with `verbose`, says on
/// stderr what verification found at the truth and at every hypothesis; with `dump`, writes
/// the overlays at the truth and at the estimate beside that path stem.
fn evaluate(
    pair: &synth::Pair,
    label: &str,
    judging: Judging,
    params: &Params,
    verbose: bool,
    dump: Option<&std::path::Path>,
    tally: &mut Tally,
) -> Result<()> {
    let start = Instant::now();
    let a = Prepared::new(&pair.a, params);
    let b = Prepared::new(&pair.b, params);
    let prep_ms = start.elapsed().as_secs_f64() * 1e3;
    let (est, accepted) = if judging.known_start {
        let check = realms_merge::estimate_with_prior(
            &a,
            &b,
            pair.a_from_b,
            &realms_merge::PriorWindow::default(),
            params,
        );
        let accepted = check.confirmed.then_some(check.placed).flatten();
        (check.estimate, accepted)
    } else {
        let est = realms_merge::estimate(&a, &b, params);
        let accepted = est.accepted();
        (est, accepted)
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    tally.pairs += 1;
    tally.times_ms.push(ms);
    let centre = overlap_centre(pair);
    let (err_m, err_rad) = accepted
        .or(est.a_from_b)
        .map_or((f64::INFINITY, f64::INFINITY), |p| {
            synth::pose_error(&p, &pair.a_from_b, centre)
        });
    let correct = err_m < judging.success_m && err_rad.to_degrees() < judging.success_deg;
    // From a known start, a confirmed map is placed at the prior itself: the error worth
    // reporting is that of the pose the maps agreed on.
    let (report_m, report_rad) = if judging.known_start {
        est.a_from_b.map_or((err_m, err_rad), |p| {
            synth::pose_error(&p, &pair.a_from_b, centre)
        })
    } else {
        (err_m, err_rad)
    };
    // A pose of the second map's frame in the first's, as the grids' poses.
    let to_grid = |p: &realms_core::Pose2| {
        pair.a
            .frame_from_grid()
            .inverse()
            .compose(p)
            .compose(&pair.b.frame_from_grid())
    };
    // What the maps share at the true pose (outside the timing).
    let truth_grid = to_grid(&pair.a_from_b);
    let at_truth = realms_merge::verify::verify(
        &a,
        &b,
        &truth_grid,
        params.conflict_weight,
        realms_merge::verify::On::Refine,
    );
    if let Some(stem) = dump {
        let name = |what: &str| {
            let mut s = stem.as_os_str().to_owned();
            s.push(format!("-{what}.png"));
            PathBuf::from(s)
        };
        write_overlay(pair, &pair.a_from_b, &name("at-truth"))?;
        if let Some(p) = &est.a_from_b {
            write_overlay(pair, p, &name("at-estimate"))?;
        }
    }
    let has_landmark = at_truth.landmark_agree > 0;
    tally.with_landmark += usize::from(has_landmark);
    let verdict = match (accepted.is_some(), correct) {
        (true, true) => {
            tally.ok += 1;
            tally.success_err_m.push(report_m);
            tally.success_err_deg.push(report_rad.to_degrees());
            tally.ok_with_landmark += usize::from(has_landmark);
            "ok"
        }
        (true, false) => {
            tally.wrong += 1;
            if err_m > GROSS_M || err_rad.to_degrees() > GROSS_DEG {
                tally.gross += 1;
            }
            "WRONG"
        }
        (false, _) => {
            tally.refused += 1;
            "refused"
        }
    };
    if !verbose {
        return Ok(());
    }
    // How far the true heading lies from the direction peaks the search starts from
    // (degrees, modulo half a turn).
    let (peaks, ratio) =
        realms_merge::rotation::candidates(&a.directions, &b.directions, params.direction_peaks, 5);
    let truth_deg = truth_grid.yaw_rad.to_degrees();
    let off_peak = peaks
        .iter()
        .map(|p| {
            let d = (truth_deg - p).rem_euclid(180.0);
            d.min(180.0 - d)
        })
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "  true heading {off_peak:.1} deg from the nearest direction peak (ratio {ratio:.2})"
    );
    // How far the truth and the estimate lie from laying a long wall of each map parallel.
    let wall_offset = |p: &realms_core::Pose2| {
        realms_merge::lines::parallel_offset_rad(&a.walls, &b.walls, p.yaw_rad)
            .map_or("-".to_owned(), |d| format!("{:.2}", d.to_degrees()))
    };
    eprintln!(
        "  walls: {} in the first map (longest {:.1} m), {} in the second (longest {:.1} m); parallel within {} deg at the truth, {} deg at the estimate",
        a.walls.len(),
        a.walls.first().map_or(0.0, |w| w.length_m),
        b.walls.len(),
        b.walls.first().map_or(0.0, |w| w.length_m),
        wall_offset(&truth_grid),
        est.a_from_b
            .as_ref()
            .map_or("-".to_owned(), |p| wall_offset(&to_grid(p))),
    );
    let t = at_truth;
    let close = realms_merge::verify::closeness(&a, &b, &truth_grid);
    eprintln!(
        "  truth: close {close:.0} agree {} conflict {} (shape {}/{} landmark {}/{}) overlap {:.0} m2 score {:.0}",
        t.agree,
        t.conflict,
        t.shape_agree,
        t.shape_conflict,
        t.landmark_agree,
        t.landmark_conflict,
        t.overlap_m2,
        t.score
    );
    for (p, e) in &est.verified {
        let (em, er) = synth::pose_error(p, &pair.a_from_b, centre);
        let close = realms_merge::verify::closeness(&a, &b, &to_grid(p));
        // Closeness on the points both poses share: the truth's, then this.
        let (paired_truth, paired) =
            realms_merge::verify::paired_closeness(&a, &b, &truth_grid, &to_grid(p));
        eprintln!(
            "    verified err {em:.2} m {:.2} deg: close {close:.0} (paired with truth {paired:.0} against {paired_truth:.0}) agree {} conflict {} (shape {}/{} landmark {}/{}) overlap {:.0} m2 score {:.0}",
            er.to_degrees(),
            e.agree,
            e.conflict,
            e.shape_agree,
            e.shape_conflict,
            e.landmark_agree,
            e.landmark_conflict,
            e.overlap_m2,
            e.score
        );
    }
    for (p, search_score, screen) in &est.hypotheses {
        let (em, er) = synth::pose_error(p, &pair.a_from_b, centre);
        eprintln!(
            "    hypothesis err {em:.2} m {:.2} deg: search {search_score} screen {screen:.0}",
            er.to_degrees()
        );
    }
    let e = &est.evidence;
    eprintln!(
        "{label}: {verdict} (best {}) err {:.2} m {:.2} deg; agree {} conflict {} ({:.2}; shape {}/{} landmark {}/{}) overlap {:.0} m2 score {:.0} runner-up {:.0} sharp {:.2} off-walls {:.2} conf {:.2}; {} headings {} nodes; {:.0} ms ({:.0} preparing){}",
        if correct { "right" } else { "wrong" },
        err_m,
        err_rad.to_degrees(),
        e.agree,
        e.conflict,
        e.agreement(),
        e.shape_agree,
        e.shape_conflict,
        e.landmark_agree,
        e.landmark_conflict,
        e.overlap_m2,
        e.score,
        est.runner_up_score,
        est.sharpness,
        est.off_two_walls,
        est.confidence,
        est.stats.headings,
        est.stats.nodes,
        ms,
        prep_ms,
        est.refusal
            .as_deref()
            .map(|r| format!("; {r}"))
            .unwrap_or_default()
    );
    Ok(())
}

/// What one row's cases came to.
#[derive(Default)]
struct Tally {
    pairs: usize,
    ok: usize,
    wrong: usize,
    gross: usize,
    refused: usize,
    with_landmark: usize,
    ok_with_landmark: usize,
    times_ms: Vec<f64>,
    success_err_m: Vec<f64>,
    success_err_deg: Vec<f64>,
}

/// How a case is judged: within `success_m` at the overlap's centre and `success_deg` of
/// heading is a success.
#[derive(Clone, Copy)]
struct Judging {
    success_m: f64,
    success_deg: f64,
    /// Estimate from the known start (the answer as the prior, as the lander does), not
    /// from nothing.
    known_start: bool,
}

/// The maps of two rovers' missions as cases for the overlap `[low, high)` percent: at
/// most `max` of them, the second map moved to a random frame unless `known_start`.
fn rover_cases(
    pairs: &[bench_merge_rovers::RoverPair],
    (low, high): (u32, u32),
    max: usize,
    known_start: bool,
    rng: &mut impl rand::Rng,
) -> Vec<(synth::Pair, String)> {
    pairs
        .iter()
        .filter(|p| (f64::from(low)..f64::from(high)).contains(&(100.0 * p.overlap)))
        .take(max)
        .map(|p| {
            let a_from_b = if known_start {
                bench_merge_rovers::TRUTH
            } else {
                realms_core::Pose2::new(
                    rng.random_range(-10.0..=10.0),
                    rng.random_range(-10.0..=10.0),
                    rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
                )
            };
            let b = if known_start {
                p.b.clone()
            } else {
                synth::reframe(&p.b, &a_from_b)
            };
            let label = format!("{} ({:.0} % overlap)", p.label, 100.0 * p.overlap);
            (
                synth::Pair {
                    a: p.a.clone(),
                    b,
                    a_from_b,
                },
                label,
            )
        })
        .collect()
}

/// `realms bench merge`.
pub fn run(args: BenchMergeArgs) -> Result<()> {
    let mut overlaps: Vec<u32> = args
        .overlaps
        .split(',')
        .map(|s| s.trim().parse::<u32>())
        .collect::<Result<_, _>>()
        .context("--overlaps: expected percentages like 5,10,20")?;
    anyhow::ensure!(
        overlaps.iter().all(|o| (1..=90).contains(o)),
        "--overlaps must be between 1 and 90 percent"
    );
    overlaps.sort_unstable();
    overlaps.dedup();
    // Walls a quarter turn or more apart would be laid parallel the wrong way round.
    if let Some(deg) = args.wall_pin_deg {
        anyhow::ensure!(
            (0.0..45.0).contains(&deg),
            "--wall-pin-deg: {deg} is not a turn in [0, 45) degrees"
        );
    }
    let maps_dir = args
        .maps
        .clone()
        .unwrap_or_else(|| PathBuf::from("../shared/data/maps"));
    let mut rows = Vec::new();
    let mut rover_pairs = None;
    for kind in args.kinds.split(',').map(str::trim) {
        let sources = match kind {
            "real" => real_sources(&maps_dir, &["willow_garage", "tb3_office_real"])?,
            "sim-building" => real_sources(&maps_dir, &["aws_bookstore", "aws_small_warehouse"])?,
            "lunar-sparse" => (0..3).map(|s| lunar_source(false, args.seed + s)).collect(),
            "lunar-very-sparse" => (0..3).map(|s| lunar_source(true, args.seed + s)).collect(),
            "lunar-rovers" | "lunar-rovers-known-start" => Vec::new(),
            other => anyhow::bail!(
                "--kinds: unknown kind `{other}` (real, sim-building, lunar-sparse, lunar-very-sparse, lunar-rovers, lunar-rovers-known-start)"
            ),
        };
        let rovers = kind.starts_with("lunar-rovers");
        if rovers && rover_pairs.is_none() {
            let seeds: Vec<u64> = (0..3).map(|s| args.seed + s).collect();
            rover_pairs = Some(bench_merge_rovers::rover_pairs(&seeds));
        }
        let known_start = kind == "lunar-rovers-known-start";
        let (judging, params) = if rovers {
            let (success_m, success_deg) = rover_success();
            let judging = Judging {
                success_m,
                success_deg,
                known_start,
            };
            (judging, Params::for_rover_maps())
        } else {
            let judging = Judging {
                success_m: SUCCESS_CELLS * sources[0].geometry().resolution_m,
                success_deg: SUCCESS_DEG,
                known_start,
            };
            (judging, Params::default())
        };
        let params = Params {
            wall_pin_rad: args
                .wall_pin_deg
                .map_or(params.wall_pin_rad, f64::to_radians),
            ..params
        };
        for (o, &overlap_pct) in overlaps.iter().enumerate() {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                args.seed ^ (u64::from(overlap_pct) << 32) ^ kind.len() as u64,
            );
            let spec = PairSpec {
                overlap: f64::from(overlap_pct) / 100.0,
                ..PairSpec::default()
            };
            let cases: Vec<(synth::Pair, String)> = if let Some(pairs) = &rover_pairs
                && rovers
            {
                let high = overlaps.get(o + 1).copied().unwrap_or(101);
                rover_cases(
                    pairs,
                    (overlap_pct, high),
                    args.pairs,
                    known_start,
                    &mut rng,
                )
            } else {
                let mut cases = Vec::new();
                for i in 0..args.pairs {
                    let source = &sources[i % sources.len()];
                    let Some(pair) = synth::make_pair(source, &spec, &mut rng) else {
                        anyhow::bail!("source map {i} of {kind} has too few known cells");
                    };
                    cases.push((pair, format!("{kind} {overlap_pct}% #{i}")));
                }
                cases
            };
            let mut tally = Tally::default();
            for (i, (pair, label)) in cases.iter().enumerate() {
                if let Some(dir) = &args.dump {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("creating {}", dir.display()))?;
                    for (map, side) in [(&pair.a, "a"), (&pair.b, "b")] {
                        let path = dir.join(format!("{kind}-{overlap_pct}-{i}-{side}.png"));
                        map.cells
                            .write_png(&path, |c| match c {
                                MapCell::Unknown => [128, 128, 128],
                                MapCell::Free => [255, 255, 255],
                                MapCell::Occupied => [0, 0, 0],
                                MapCell::Hazard => [220, 120, 0],
                            })
                            .with_context(|| format!("writing {}", path.display()))?;
                    }
                }
                let dump = args
                    .dump
                    .as_ref()
                    .map(|dir| dir.join(format!("{kind}-{overlap_pct}-{i}")));
                evaluate(
                    pair,
                    label,
                    judging,
                    &params,
                    args.verbose,
                    dump.as_deref(),
                    &mut tally,
                )?;
            }
            let n = tally.pairs.max(1) as f64;
            rows.push(Row {
                kind: kind.to_string(),
                overlap_pct,
                pairs: tally.pairs,
                success_pct: 100.0 * tally.ok as f64 / n,
                wrong_pct: 100.0 * tally.wrong as f64 / n,
                gross_wrong_pct: 100.0 * tally.gross as f64 / n,
                refused_pct: 100.0 * tally.refused as f64 / n,
                with_landmark: tally.with_landmark,
                success_with_landmark_pct: 100.0 * tally.ok_with_landmark as f64
                    / tally.with_landmark.max(1) as f64,
                success_median_error_m: median(tally.success_err_m),
                success_median_error_deg: median(tally.success_err_deg),
                max_ms: tally.times_ms.iter().copied().fold(0.0, f64::max),
                median_ms: median(tally.times_ms),
            });
        }
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "machine": machine(),
                "pairs": args.pairs,
                "seed": args.seed,
                "rows": rows,
            }))?
        );
        return Ok(());
    }
    println!("# realms bench merge");
    println!();
    println!(
        "at most {} pairs per cell, seed {}; success = within {SUCCESS_CELLS} cells and {SUCCESS_DEG} deg ({} m and {} deg for the rovers' maps); machine: {}",
        args.pairs,
        args.seed,
        rover_success().0,
        rover_success().1,
        machine()
    );
    println!();
    println!(
        "| source | overlap | success | wrong merge | of which gross (> {GROSS_M} m or {GROSS_DEG} deg) | refused | pairs with a landmark in the overlap | success on those | median error of a success | median ms | max ms |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for r in &rows {
        let error = if r.success_median_error_m.is_nan() {
            "-".to_string()
        } else {
            format!(
                "{:.3} m, {:.2} deg",
                r.success_median_error_m, r.success_median_error_deg
            )
        };
        println!(
            "| {} | {} % | {:.0} % | {:.1} % | {:.1} % | {:.0} % | {} of {} | {:.0} % | {error} | {:.0} | {:.0} |",
            r.kind,
            r.overlap_pct,
            r.success_pct,
            r.wrong_pct,
            r.gross_wrong_pct,
            r.refused_pct,
            r.with_landmark,
            r.pairs,
            r.success_with_landmark_pct,
            r.median_ms,
            r.max_ms
        );
    }
    Ok(())
}
