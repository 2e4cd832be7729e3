//! Criterion benchmarks of what a rover's navigation does every time its map changes (every
//! 3 s in the mission), on a map the size of the default hall (50 m x 36 m) with its walls, a
//! lander-sized block and a few hundred rocks, the eastern half not yet seen:
//!
//! - `costmap_from_map/hall`: the costmap at 5 cm (distance transform and inflation);
//! - `costmap_updated/hall`: the same costmap brought up to date after the rover has seen a
//!   4 m x 3 m patch of the unknown half (open floor with two rocks), as between two plans;
//! - `flood_to_frontiers/hall`: the flood from the rover to every frontier cell at 10 cm (the
//!   rovers' planning map), stopped once it has reached them all, as exploration runs it.
//!
//! `cargo bench -p realms-nav --bench nav`. Figures in BENCHMARKS.md.

use criterion::{Criterion, criterion_group, criterion_main};
use realms_core::{Cell, Grid, GridGeometry, Point2};
use realms_nav::Planner;
use realms_nav::costmap::{Costmap, CostmapConfig};
use realms_nav::planner::PlannerConfig;
use std::hint::black_box;

/// The hall's map as a rover has it halfway through exploring: walls all round, a 3 m
/// block, rocks of one to four cells scattered by a fixed linear congruential sequence, and
/// the eastern half not yet seen.
fn hall_map(resolution_m: f64) -> Grid<i8> {
    let (width, height) = (
        (50.0 / resolution_m).round() as usize,
        (36.0 / resolution_m).round() as usize,
    );
    let cell = |m: f64| (m / resolution_m).round() as usize;
    let geometry = GridGeometry {
        width,
        height,
        resolution_m,
        origin: Point2::new(0.0, 0.0),
    };
    let mut cells = vec![0i8; width * height];
    for y in 0..height {
        for x in 0..width {
            if x < cell(0.1) || y < cell(0.1) || x >= width - cell(0.1) || y >= height - cell(0.1) {
                cells[y * width + x] = 100;
            } else if x > width / 2 {
                cells[y * width + x] = -1;
            }
        }
    }
    for y in cell(15.0)..cell(18.0) {
        for x in cell(5.0)..cell(8.0) {
            cells[y * width + x] = 100;
        }
    }
    let mut state: u64 = 12345;
    let mut next = |n: usize| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as usize % n
    };
    for _ in 0..400 {
        let (x, y) = (next(width - 8) + 4, next(height - 8) + 4);
        let size = (cell(0.05 * (next(4) + 1) as f64)).clamp(1, 4);
        for dy in 0..size {
            for dx in 0..size {
                cells[(y + dy) * width + x + dx] = 100;
            }
        }
    }
    Grid::from_cells(geometry, cells).expect("one value per cell")
}

fn costmap(c: &mut Criterion) {
    let map = hall_map(0.05);
    let cfg = CostmapConfig::default();
    c.bench_function("costmap_from_map/hall", |b| {
        b.iter(|| Costmap::from_map(black_box(&map), &cfg))
    });
}

fn costmap_updated(c: &mut Criterion) {
    let before = hall_map(0.05);
    let cfg = CostmapConfig::default();
    let kept = Costmap::from_map(&before, &cfg);
    let mut after = before.clone();
    let width = before.geometry().width;
    let cell = |m: f64| (m / 0.05).round() as usize;
    for y in cell(20.0)..cell(23.0) {
        for x in cell(25.0)..cell(29.0) {
            let rock = (x, y) == (cell(26.0), cell(21.0)) || (x, y) == (cell(28.0), cell(22.0));
            after.cells_mut()[y * width + x] = if rock { 100 } else { 0 };
        }
    }
    c.bench_function("costmap_updated/hall", |b| {
        b.iter(|| kept.updated(black_box(&before), black_box(&after), &cfg))
    });
}

fn flood(c: &mut Criterion) {
    let map = hall_map(0.1);
    let costmap = Costmap::from_map(&map, &CostmapConfig::default());
    let geo = *costmap.geometry();
    // The frontier: every known cell beside the unknown half that a rover could stand in.
    let x = geo.width / 2;
    let targets: Vec<Cell> = (0..geo.height)
        .map(|y| Cell { x, y })
        .filter(|c| costmap.cost(*c) < realms_nav::costmap::MAX_PASSABLE)
        .collect();
    let start = Point2::new(3.0, 3.0);
    let mut planner = Planner::new(PlannerConfig::default());
    c.bench_function("flood_to_frontiers/hall", |b| {
        b.iter(|| {
            planner
                .travel_costs_until(&costmap, black_box(start), true, Some(&targets))
                .expect("the start lies on the map")
        })
    });
}

criterion_group!(benches, costmap, costmap_updated, flood);
criterion_main!(benches);
