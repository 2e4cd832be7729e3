//! The incremental frontier tracker against full detection: over random sequences of map
//! edits, peer coverage and map growth, both must find exactly the same frontiers.

use proptest::prelude::*;
use realms_core::{Grid, GridGeometry, Point2};
use realms_nav::frontier::{FrontierTracker, detect};
use realms_nav::{Costmap, CostmapConfig};

/// One step of a random exploration: blocks of the map set to a value, what peers have
/// seen, and whether the map grows first.
#[derive(Clone, Debug)]
struct Step {
    grow: bool,
    blocks: Vec<(usize, usize, usize, usize, i8)>,
    seen: Option<(usize, usize, usize, usize)>,
}

fn step() -> impl Strategy<Value = Step> {
    let block = (
        0usize..60,
        0usize..40,
        1usize..20,
        1usize..20,
        prop::sample::select(vec![-1i8, 0, 0, 0, 1, 1, 30, 90, 100]),
    );
    (
        prop::bool::weighted(0.1),
        prop::collection::vec(block, 0..4),
        prop::option::of((0usize..60, 0usize..40, 1usize..30, 1usize..30)),
    )
        .prop_map(|(grow, blocks, seen)| Step { grow, blocks, seen })
}

/// `map` grown by `by` cells on its right and top, the new part unknown (as a SLAM map grows).
fn grown(map: &Grid<i8>, by: usize) -> Grid<i8> {
    let g = *map.geometry();
    let geo = GridGeometry {
        width: g.width + by,
        height: g.height + by,
        ..g
    };
    let mut out = Grid::new(geo, -1i8);
    for (c, v) in map.iter() {
        *out.get_mut(c.x, c.y).expect("inside the larger map") = *v;
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn the_tracker_finds_what_full_detection_finds(steps in prop::collection::vec(step(), 1..12)) {
        let geo = GridGeometry {
            width: 50,
            height: 36,
            resolution_m: 0.1,
            origin: Point2::new(-2.5, -1.8),
        };
        let mut map = Grid::new(geo, -1i8);
        let cfg = CostmapConfig::default();
        let mut tracker = FrontierTracker::new();
        for s in steps {
            if s.grow {
                map = grown(&map, 7);
            }
            let g = *map.geometry();
            for (x0, y0, w, h, v) in s.blocks {
                for y in y0..(y0 + h).min(g.height) {
                    for x in x0..(x0 + w).min(g.width) {
                        *map.get_mut(x, y).expect("clipped to the map") = v;
                    }
                }
            }
            let seen: Option<Vec<bool>> = s.seen.map(|(x0, y0, w, h)| {
                map.iter()
                    .map(|(c, _)| (x0..x0 + w).contains(&c.x) && (y0..y0 + h).contains(&c.y))
                    .collect()
            });
            let cm = Costmap::from_map(&map, &cfg);
            let want = detect(&map, &cm, 3, seen.as_deref());
            let got = tracker.update(&map, &cm, 3, seen.as_deref());
            prop_assert_eq!(got, want);
        }
    }
}

/// A change in one corner of a large map is examined there, not everywhere.
#[test]
fn a_local_change_examines_a_few_cells() {
    let geo = GridGeometry {
        width: 400,
        height: 300,
        resolution_m: 0.1,
        origin: Point2::new(0.0, 0.0),
    };
    let mut map = Grid::new(geo, -1i8);
    for y in 0..150 {
        for x in 0..200 {
            *map.get_mut(x, y).expect("inside") = 0;
        }
    }
    let cfg = CostmapConfig::default();
    let mut tracker = FrontierTracker::new();
    let first = tracker.update(&map, &Costmap::from_map(&map, &cfg), 8, None);
    assert_eq!(tracker.last_examined(), geo.len());
    assert_eq!(first.len(), 1, "{first:?}");
    // Reveal a 10 x 10 block beyond the frontier's corner.
    for y in 150..160 {
        for x in 200..210 {
            *map.get_mut(x, y).expect("inside") = 0;
        }
    }
    let cm = Costmap::from_map(&map, &cfg);
    let next = tracker.update(&map, &cm, 8, None);
    assert_eq!(next, detect(&map, &cm, 8, None));
    // The block, the ring around it, and the costmap cells whose inflation it changed.
    assert!(
        tracker.last_examined() < 1000,
        "examined {} cells",
        tracker.last_examined()
    );
}
