//! Criterion benchmark of the costmap a rover plans on, made from its map every time the map
//! changes (every 3 s in the mission): a map the size of the default hall (50 m x 36 m at
//! 5 cm) with its walls, a lander-sized block and a few hundred rocks, half of it unknown.
//!
//! `cargo bench -p realms-nav --bench costmap`. Figures in BENCHMARKS.md.

use criterion::{Criterion, criterion_group, criterion_main};
use realms_core::{Grid, GridGeometry, Point2};
use realms_nav::costmap::{Costmap, CostmapConfig};
use std::hint::black_box;

/// The hall's map as a rover has it halfway through exploring: walls all round, a 3 m
/// block, rocks of one to four cells scattered by a fixed linear congruential sequence, and
/// the eastern half not yet seen.
fn hall_map() -> Grid<i8> {
    let (width, height) = (1000, 720);
    let geometry = GridGeometry {
        width,
        height,
        resolution_m: 0.05,
        origin: Point2::new(0.0, 0.0),
    };
    let mut cells = vec![0i8; width * height];
    for y in 0..height {
        for x in 0..width {
            if x < 2 || y < 2 || x >= width - 2 || y >= height - 2 {
                cells[y * width + x] = 100;
            } else if x > width / 2 {
                cells[y * width + x] = -1;
            }
        }
    }
    for y in 300..360 {
        for x in 100..160 {
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
        let (x, y, size) = (next(width - 8) + 4, next(height - 8) + 4, next(4) + 1);
        for dy in 0..size {
            for dx in 0..size {
                cells[(y + dy) * width + x + dx] = 100;
            }
        }
    }
    Grid::from_cells(geometry, cells).expect("one value per cell")
}

fn costmap(c: &mut Criterion) {
    let map = hall_map();
    let cfg = CostmapConfig::default();
    c.bench_function("costmap_from_map/hall", |b| {
        b.iter(|| Costmap::from_map(black_box(&map), &cfg))
    });
}

criterion_group!(benches, costmap);
criterion_main!(benches);
