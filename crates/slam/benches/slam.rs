//! Criterion benchmarks of the SLAM's per-scan and per-keyframe steps, on a real scan (the
//! Intel Research Lab log in `../shared/data/slam`, skipped with a note when it is not
//! there) and on a simulated rover's scan of a sparse lunar hall:
//!
//! - `match_scan`: the occupancy scan-to-map match (Gauss-Newton), from a prior 5 cm and a
//!   degree off;
//! - `refine_on_hits`: the rovers' refinement of that match on the submap's hits;
//! - `map_update`: one keyframe traced into a map (free space along the beams, hits at
//!   their ends), as a submap takes it;
//! - `closure_precompute`: a finished submap's stack of block maxima, made once before
//!   its first closure search;
//! - `closure_search`: the branch-and-bound search a loop closure starts with (2.5 m and
//!   3 degrees around the prior, as the rovers search);
//! - `graph_optimize`: one Gauss-Newton step of a rover's pose graph after an hour of
//!   driving (1,500 keyframes on laps of a 10 m square, 273 closures), by the rovers'
//!   capped block-Jacobi conjugate gradients, and by block elimination (the rovers' solver);
//! - `hollows`: the hollows found in a hall-sized hazard layer (50 x 36 m of 10 cm cells:
//!   three craters' walls judged hazard round unjudged middles, rocks on judged ground,
//!   unjudged strips between the judged ground and the walls' hazard feet), as the rover
//!   finds them for every map it publishes;
//! - `judge_frame`: one depth frame judged for hazards (106 x 60 pixels of a camera 0.25 m
//!   up, tilted 15 degrees down over an undulating floor with rocks, as the rovers' D455).
//!
//! `cargo bench -p realms-slam --bench slam`. Figures in BENCHMARKS.md.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use realms_core::{Grid, GridGeometry, Point2, Pose2};
use realms_slam::bnb::{PrecomputedMap, SearchWindow};
use realms_slam::carmen::CarmenLog;
use realms_slam::frontend::{Densify, densify, scan_points};
use realms_slam::hollows::{HazardHollows, HollowFinder};
use realms_slam::mapper::{Mapper, MapperConfig};
use realms_slam::matcher::{MatcherConfig, MultiResMap, match_scan};
use realms_slam::ndt::{NdtConfig, NdtMap};
use realms_slam::occupancy::{CellState, MissMargin, MissRule};
use realms_slam::posegraph::{Edge, GraphSolver, PoseGraph};
use realms_slam::traversability::{TraversabilityConfig, judge_frame};
use std::hint::black_box;

/// A scene to match in: a map of a few scans, the scan to match, where it truly is, and the
/// hits the map's scans left (for the refinement).
struct Scene {
    name: &'static str,
    map: MultiResMap,
    hits: NdtMap,
    /// The scan's points, robot frame, as matched (filled in between beams for the rover).
    points: Vec<Point2>,
    /// The beams' own endpoints, robot frame.
    beams: Vec<Point2>,
    pose: Pose2,
    matcher: MatcherConfig,
}

/// The prior a match starts from: 5 cm and a degree off the scan's pose.
fn off_prior(pose: Pose2) -> Pose2 {
    Pose2::new(
        pose.x_m + 0.05,
        pose.y_m - 0.04,
        pose.yaw_rad + 1f64.to_radians(),
    )
}

fn draw(map: &mut MultiResMap, hits: &mut NdtMap, pose: Pose2, points: &[Point2]) {
    let world: Vec<(Point2, bool)> = points
        .iter()
        .map(|p| (pose.transform_point(*p), true))
        .collect();
    map.insert(pose.position(), &world);
    hits.insert(world.iter().map(|(p, _)| *p));
}

/// The Intel log's scans 300-320 drawn at the poses our SLAM gives them, and scan 321.
fn intel_scene() -> Option<Scene> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/slam/intel.clf");
    let log = match CarmenLog::read_file(&path) {
        Ok(log) => log,
        Err(e) => {
            eprintln!("note: the Intel log is not there ({e}); its benchmarks are skipped");
            return None;
        }
    };
    let last = 321.min(log.scans.len().checked_sub(1)?);
    let mut mapper = Mapper::new(MapperConfig::default());
    for scan in &log.scans[..=last] {
        mapper.add_scan(scan);
    }
    let poses = mapper.trajectory();
    let cfg = MapperConfig::default().frontend;
    let points = |k: usize| scan_points(&log.scans[k], cfg.min_range_m, cfg.max_range_m);
    let mut map = MultiResMap::new(cfg.resolution_m, cfg.levels);
    let mut hits = NdtMap::new(NdtConfig::default());
    let first = last.saturating_sub(21);
    for (k, at) in poses.iter().enumerate().take(last).skip(first) {
        draw(&mut map, &mut hits, at.pose, &points(k));
    }
    let beams = points(last);
    Some(Scene {
        name: "intel",
        map,
        hits,
        points: beams.clone(),
        beams,
        pose: poses[last].pose,
        matcher: cfg.matcher,
    })
}

/// Where a ray from `from` along `heading` first meets the hall: its walls, a lander and
/// a few boulders (a sparse scene, like the rovers' arena); `None` past the lidar's 12 m.
fn hall_range(from: Point2, heading: f64) -> Option<f64> {
    let walls = [
        (0.0, 0.0, 40.0, 0.0),
        (40.0, 0.0, 40.0, 24.0),
        (40.0, 24.0, 0.0, 24.0),
        (0.0, 24.0, 0.0, 0.0),
        // The lander, a 3 m square.
        (18.0, 10.0, 21.0, 10.0),
        (21.0, 10.0, 21.0, 13.0),
        (21.0, 13.0, 18.0, 13.0),
        (18.0, 13.0, 18.0, 10.0),
    ];
    let boulders = [
        (12.0, 6.0, 0.4),
        (9.0, 15.0, 0.6),
        (26.0, 7.0, 0.3),
        (28.0, 17.0, 0.5),
        (15.0, 19.0, 0.35),
    ];
    let (dy, dx) = heading.sin_cos();
    let walls = walls.iter().filter_map(|&(x1, y1, x2, y2)| {
        let (ex, ey) = (x2 - x1, y2 - y1);
        let den = dx * ey - dy * ex;
        if den.abs() < 1e-12 {
            return None;
        }
        let t = ((x1 - from.x_m) * ey - (y1 - from.y_m) * ex) / den;
        let u = ((x1 - from.x_m) * dy - (y1 - from.y_m) * dx) / den;
        (t > 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
    });
    let boulders = boulders.iter().filter_map(|&(cx, cy, r)| {
        let (ox, oy) = (from.x_m - cx, from.y_m - cy);
        let b = ox * dx + oy * dy;
        let disc = b * b - (ox * ox + oy * oy - r * r);
        let t = -b - disc.max(0.0).sqrt();
        (disc >= 0.0 && t > 0.0).then_some(t)
    });
    let range = walls.chain(boulders).fold(f64::INFINITY, f64::min);
    (range < 12.0).then_some(range)
}

/// A rover's lidar scan (360 beams a degree apart, to 12 m) from `pose`, robot frame.
fn hall_scan(pose: Pose2) -> Vec<Point2> {
    (0..360)
        .filter_map(|i| {
            let local = (i as f64).to_radians();
            hall_range(pose.position(), pose.yaw_rad + local)
                .map(|r| Point2::new(r * local.cos(), r * local.sin()))
        })
        .collect()
}

/// A rover's submap of ten keyframes 0.3 m apart along the hall, set up as the rovers'
/// (one 5 cm grid, a cell cleared once a scan, scans filled in between beams), and the
/// scan from the middle of its path.
fn hall_scene() -> Scene {
    let fill = Densify {
        max_gap_m: 0.3,
        spacing_m: 0.05,
    };
    let mut map = MultiResMap::new(0.05, 1).with_miss_rule(MissRule::OncePerScan);
    let mut hits = NdtMap::new(NdtConfig::default());
    let at = |k: usize| Pose2::new(6.0 + 0.3 * k as f64, 5.0 + 0.1 * k as f64, 0.2);
    for k in 0..10 {
        let pose = at(k);
        draw(&mut map, &mut hits, pose, &densify(&hall_scan(pose), fill));
    }
    let pose = Pose2::new(7.45, 5.52, 0.21);
    let beams = hall_scan(pose);
    Scene {
        name: "sim_hall",
        map,
        hits,
        points: densify(&beams, fill),
        beams,
        pose,
        matcher: MatcherConfig::default(),
    }
}

fn benches(c: &mut Criterion) {
    let scenes: Vec<Scene> = intel_scene().into_iter().chain([hall_scene()]).collect();
    for s in &scenes {
        let prior = off_prior(s.pose);
        c.bench_function(&format!("match_scan/{}", s.name), |b| {
            b.iter(|| match_scan(black_box(&s.map), black_box(&s.points), prior, &s.matcher))
        });
        let matched = match_scan(&s.map, &s.points, prior, &s.matcher).pose;
        // What is timed must be a working match, not a diverging one.
        let off = |p: Pose2| {
            let d = s.pose.inverse() * p;
            format!(
                "{:.1} cm, {:.2} deg",
                100.0 * d.x_m.hypot(d.y_m),
                d.yaw_rad.to_degrees()
            )
        };
        eprintln!(
            "{}: the match lands {} from the scan's pose",
            s.name,
            off(matched)
        );
        let wheels = [prior.position(), prior.position()];
        c.bench_function(&format!("refine_on_hits/{}", s.name), |b| {
            b.iter(|| {
                s.hits.refine(
                    black_box(&s.beams),
                    matched,
                    wheels,
                    s.matcher.prior_translation_weight,
                    s.matcher.prior_rotation_weight,
                )
            })
        });
        let world: Vec<(Point2, bool)> = s
            .points
            .iter()
            .map(|p| (s.pose.transform_point(*p), true))
            .collect();
        c.bench_function(&format!("map_update/{}", s.name), |b| {
            b.iter_batched_ref(
                || s.map.clone(),
                |map| map.insert(s.pose.position(), black_box(&world)),
                BatchSize::LargeInput,
            )
        });
        if s.name == "sim_hall" {
            // The rovers' keyframe: its beams clear a matching grid up to a margin short of
            // their hits, and a published grid beside it up to them, filled-in points hits only.
            let margin = Some(MissMargin {
                base_m: 0.03,
                per_m: 0.006,
            });
            let matched = s.map.finest().clone().with_miss_margin(margin);
            let published = s.map.finest().clone().without_probabilities();
            let rays: Vec<Point2> = s.beams.iter().map(|p| s.pose.transform_point(*p)).collect();
            let counts = (world.len(), rays.len());
            c.bench_function(&format!("map_update_two_grids/{}", s.name), |b| {
                b.iter_batched_ref(
                    || (published.clone(), matched.clone()),
                    |(published, matched)| {
                        published.insert_with_rays_beside(
                            matched,
                            s.pose.position(),
                            black_box(&world),
                            Some(&rays),
                            counts,
                        )
                    },
                    BatchSize::LargeInput,
                )
            });
            c.bench_function(&format!("map_update_two_grids_apart/{}", s.name), |b| {
                b.iter_batched_ref(
                    || (published.clone(), matched.clone()),
                    |(published, matched)| {
                        published.insert_with_rays(
                            s.pose.position(),
                            black_box(&world),
                            Some(&rays),
                        );
                        matched.insert_with_rays(s.pose.position(), black_box(&world), Some(&rays));
                    },
                    BatchSize::LargeInput,
                )
            });
        }
        // As the rovers search: blocks up to 64 cells, and a margin as wide as the window.
        c.bench_function(&format!("closure_precompute/{}", s.name), |b| {
            b.iter(|| PrecomputedMap::with_margin(black_box(s.map.finest()), 6, 50))
        });
        let precomputed = PrecomputedMap::with_margin(s.map.finest(), 6, 50);
        let window = SearchWindow {
            linear_m: 2.5,
            angular_rad: 3f64.to_radians(),
            step_range_m: 12.0,
        };
        let far_prior = Pose2::new(s.pose.x_m + 1.2, s.pose.y_m - 0.9, s.pose.yaw_rad + 0.03);
        let found = realms_slam::bnb::search(&precomputed, &s.beams, far_prior, &window, 0.5, 0.08);
        eprintln!(
            "{}: the closure search lands {}",
            s.name,
            found.map_or("nowhere".to_string(), |f| off(f.pose))
        );
        c.bench_function(&format!("closure_search/{}", s.name), |b| {
            b.iter(|| {
                realms_slam::bnb::search(
                    &precomputed,
                    black_box(&s.beams),
                    far_prior,
                    &window,
                    0.5,
                    0.08,
                )
            })
        });
    }
}

/// A rover's graph after an hour: keyframes 0.3 m apart on laps of a 10 m square, the
/// wheels' steps 2 % long and turning a little, a closure every fifth keyframe of every lap
/// after the first to the same place one lap before (exact), and one solve already done.
fn lapped_graph() -> PoseGraph {
    const PER_SIDE: usize = 33;
    const KEYFRAMES: usize = 1500;
    let lap = 4 * PER_SIDE;
    let step = |k: usize| {
        let turn = if k % PER_SIDE == PER_SIDE - 1 {
            std::f64::consts::FRAC_PI_2
        } else {
            0.0
        };
        Pose2::new(0.3, 0.0, turn)
    };
    let mut truth = vec![Pose2::IDENTITY];
    let mut graph = PoseGraph {
        nodes: vec![Pose2::IDENTITY],
        ..PoseGraph::default()
    };
    for k in 0..KEYFRAMES - 1 {
        let exact = step(k);
        let measured = Pose2::new(exact.x_m * 1.02, 0.0, exact.yaw_rad + 0.002);
        truth.push(truth[k] * exact);
        graph.nodes.push(graph.nodes[k] * measured);
        graph.edges.push(Edge {
            from: k,
            to: k + 1,
            measurement: measured,
            information: [400.0, 400.0, 2500.0],
            information_axis_rad: 0.0,
            robust: false,
        });
        let to = k + 1;
        if to >= lap && to % 5 == 0 {
            graph.edges.push(Edge {
                from: to - lap,
                to,
                measurement: truth[to - lap].inverse() * truth[to],
                information: [400.0, 400.0, 2500.0],
                information_axis_rad: 0.0,
                robust: true,
            });
        }
    }
    graph.optimize(1);
    graph
}

fn graph_bench(c: &mut Criterion) {
    let graph = lapped_graph();
    c.bench_function("graph_optimize/lapped_square", |b| {
        b.iter_batched_ref(|| graph.clone(), |g| g.optimize(1), BatchSize::LargeInput)
    });
    // The closure checks' question: how far along the graph from the newest keyframe to one
    // a lap back (a closure's partner), asked with a limit the search gives up at.
    let newest = graph.nodes.len() - 1;
    let lap_back = newest - 4 * 33;
    c.bench_function("graph_path_length/lapped_square", |b| {
        b.iter(|| {
            graph.path_length_within(newest, lap_back, 6.0, |e| PoseGraph::travelled_m(e, 0.5))
        })
    });
    let graph = PoseGraph {
        solver: GraphSolver::Elimination,
        ..graph
    };
    c.bench_function("graph_optimize/lapped_square_elimination", |b| {
        b.iter_batched_ref(|| graph.clone(), |g| g.optimize(1), BatchSize::LargeInput)
    });
}

/// A hazard layer the size of the default hall, with what the lidar saw open: the floor the
/// camera judged safe along a few strips of the rovers' paths, unjudged beyond them up to the
/// walls' hazard feet, three craters whose walls it judged hazard round unjudged middles, and
/// rocks scattered over it all (hazard, and not seen open by the lidar where they stand).
fn hall_hazard_layer() -> (Grid<CellState>, Vec<bool>) {
    let (w, h) = (500usize, 360usize);
    let geometry = GridGeometry {
        width: w,
        height: h,
        resolution_m: 0.1,
        origin: Point2::new(0.0, 0.0),
    };
    let mut states = Grid::new(geometry, CellState::Unknown);
    let mut open = vec![true; w * h];
    let at = |x: usize, y: usize| Point2::new((x as f64 + 0.5) * 0.1, (y as f64 + 0.5) * 0.1);
    let paths = [
        (5.0, 5.0, 45.0, 5.0),
        (45.0, 5.0, 45.0, 31.0),
        (45.0, 31.0, 5.0, 31.0),
        (5.0, 31.0, 5.0, 5.0),
        (5.0, 18.0, 45.0, 18.0),
        (25.0, 5.0, 25.0, 31.0),
    ];
    let from_path = |p: Point2| {
        paths
            .iter()
            .map(|&(x0, y0, x1, y1)| {
                let (dx, dy) = (x1 - x0, y1 - y0);
                let t =
                    (((p.x_m - x0) * dx + (p.y_m - y0) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                (p.x_m - x0 - t * dx).hypot(p.y_m - y0 - t * dy)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let craters = [
        (Point2::new(15.0, 12.0), 3.0),
        (Point2::new(35.0, 25.0), 1.5),
        (Point2::new(33.0, 10.0), 1.2),
    ];
    // Rocks at fixed pseudo-random places (a linear congruential sequence).
    let mut lcg = 12345u64;
    let mut next = || {
        lcg = lcg
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (lcg >> 33) as f64 / (1u64 << 31) as f64
    };
    let rocks: Vec<(Point2, f64)> = (0..150)
        .map(|_| {
            (
                Point2::new(1.0 + 48.0 * next(), 1.0 + 34.0 * next()),
                0.1 + 0.15 * next(),
            )
        })
        .collect();
    for y in 0..h {
        for x in 0..w {
            let p = at(x, y);
            let i = y * w + x;
            let wall_foot = x < 3 || y < 3 || x >= w - 3 || y >= h - 3;
            let mut state = if wall_foot {
                CellState::Occupied
            } else if from_path(p) <= 4.0 {
                CellState::Free
            } else {
                CellState::Unknown
            };
            for &(c, r) in &craters {
                let d = p.distance_m(c);
                if d < 0.6 * r {
                    state = CellState::Unknown;
                } else if d <= r {
                    state = CellState::Occupied;
                }
            }
            for &(c, r) in &rocks {
                if p.distance_m(c) <= r {
                    state = CellState::Occupied;
                    open[i] = false;
                }
            }
            states.cells_mut()[i] = state;
        }
    }
    (states, open)
}

fn hollows_bench(c: &mut Criterion) {
    let (layer, open) = hall_hazard_layer();
    let mut finder = HollowFinder::new(HazardHollows::default());
    let width = layer.geometry().width;
    // The craters' middles are hollows; the strips along the walls are too large to be.
    let marked = finder.fill_cells(&mut layer.clone(), |cell| open[cell.y * width + cell.x]);
    assert!(
        (1300..1600).contains(&marked),
        "the three craters' middles: {marked} cells"
    );
    c.bench_function("hollows/hall", |b| {
        b.iter_batched_ref(
            || layer.clone(),
            |states| finder.fill_cells(states, |cell| open[cell.y * width + cell.x]),
            BatchSize::LargeInput,
        )
    });
}

/// The points of one depth frame in the rover's levelled frame: each of 106 x 60 pixels of
/// an 87 x 58 degree camera 0.25 m above the floor, tilted 15 degrees down, meets the
/// floor's plane, and takes the height there of an undulating floor with a few rocks;
/// pixels that meet no floor within 6 m return nothing.
fn depth_frame() -> Vec<[f64; 3]> {
    let (cols, rows, height_m, pitch) = (106, 60, 0.25, 15f64.to_radians());
    let (half_w, half_h) = (
        (87f64 / 2.0).to_radians().tan(),
        (58f64 / 2.0).to_radians().tan(),
    );
    let rocks = [
        (1.2, 0.3, 0.15, 0.12),
        (2.0, -0.8, 0.2, 0.06),
        (3.1, 0.9, 0.25, 0.2),
        (1.7, 1.4, 0.1, 0.05),
    ];
    let floor = |x: f64, y: f64| {
        let mut z = 0.04 * (x * 1.3).sin() + 0.02 * (y * 2.1).cos();
        for &(rx, ry, r, h) in &rocks {
            if (x - rx).hypot(y - ry) < r {
                z += h;
            }
        }
        z
    };
    let mut points = Vec::new();
    for v in 0..rows {
        for u in 0..cols {
            // Camera frame: forward, left, up.
            let left = half_w * (1.0 - 2.0 * (u as f64 + 0.5) / cols as f64);
            let up = half_h * (1.0 - 2.0 * (v as f64 + 0.5) / rows as f64);
            let (forward, up) = (
                pitch.cos() - up * pitch.sin(),
                pitch.sin() + up * pitch.cos(),
            );
            let down = -up;
            if down <= 0.0 {
                continue;
            }
            let t = height_m / down;
            let (x, y) = (forward * t, left * t);
            if (x * x + y * y + height_m * height_m).sqrt() > 6.0 {
                continue;
            }
            points.push([x, y, floor(x, y)]);
        }
    }
    points
}

fn traversability_bench(c: &mut Criterion) {
    let points = depth_frame();
    let cfg = TraversabilityConfig::default();
    c.bench_function("judge_frame/rocky_floor", |b| {
        b.iter(|| judge_frame(black_box(&points), &cfg))
    });
}

criterion_group! {
    name = slam;
    config = Criterion::default().sample_size(30);
    targets = benches, graph_bench, hollows_bench, traversability_bench
}
criterion_main!(slam);
