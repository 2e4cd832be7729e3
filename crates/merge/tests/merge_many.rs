//! Merging three maps: each placed where it belongs whatever the input order, the merged
//! grid covering them all with a contribution layer that says who saw what; a map that
//! belongs nowhere is left out with a reason.

mod common;

use rand::{Rng, SeedableRng};
use realms_core::Pose2;
use realms_merge::compose::merge;
use realms_merge::synth::{self, PairSpec};
use realms_merge::{Map, MapCell, Params};

/// A, B (40 % shared with A) and C (B seen from another frame), with C's answer.
fn three() -> (Map, Map, Map, Pose2, Pose2) {
    let source = common::recorded("aws_bookstore").cells;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    let spec = PairSpec {
        overlap: 0.4,
        ..PairSpec::default()
    };
    let pair = synth::make_pair(&source, &spec, &mut rng).expect("pair");
    let b_from_c = Pose2::new(
        rng.random_range(-5.0..5.0),
        rng.random_range(-5.0..5.0),
        2.0,
    );
    let c = synth::reframe(&pair.b, &b_from_c);
    let a_from_c = pair.a_from_b.compose(&b_from_c);
    (pair.a, pair.b, c, pair.a_from_b, a_from_c)
}

#[test]
fn three_maps_merge_consistently_in_any_order() {
    let (a, b, c, a_from_b, a_from_c) = three();
    let params = Params::default();
    let merged = merge(&[a.clone(), b.clone(), c.clone()], &params).expect("merge");
    let pb = merged.placements[1].reference_from_map.expect("B placed");
    let pc = merged.placements[2].reference_from_map.expect("C placed");
    assert!(
        common::close(&pb, &a_from_b, &b),
        "B at {pb:?}, truth {a_from_b:?}"
    );
    assert!(
        common::close(&pc, &a_from_c, &c),
        "C at {pc:?}, truth {a_from_c:?}"
    );
    assert!(
        merged.inconsistencies.is_empty(),
        "{:?}",
        merged.inconsistencies
    );
    // Every map contributed, and the merged grid holds at least each map's known area.
    for bit in 0..3 {
        assert!(
            merged
                .contribution
                .cells()
                .iter()
                .any(|m| m & (1 << bit) != 0)
        );
    }
    let known = merged.grid.cells().iter().filter(|c| c.is_known()).count();
    assert!(known >= a.known_cells().max(b.known_cells()));

    // C first: the others are placed in C's frame, and relative poses agree.
    let again = merge(&[c.clone(), a.clone(), b.clone()], &params).expect("merge");
    let c_from_a = again.placements[1].reference_from_map.expect("A placed");
    let c_from_b = again.placements[2].reference_from_map.expect("B placed");
    assert!(
        common::close(&c_from_a.compose(&pb), &c_from_b, &b),
        "order changed B"
    );
    assert!(
        common::close(&c_from_a.inverse(), &pc, &c),
        "order changed C"
    );
}

#[test]
fn a_map_from_elsewhere_is_left_out_with_a_reason() {
    let (a, b, _, _, _) = three();
    let lunar = Map::new(common::lunar(5, 5, 120));
    let merged = merge(&[a, b, lunar], &Params::default()).expect("merge");
    assert!(merged.placements[1].reference_from_map.is_some());
    let p = &merged.placements[2];
    assert!(
        p.reference_from_map.is_none(),
        "the arena was merged into a bookstore"
    );
    assert!(p.refusal.as_deref().is_some_and(|r| !r.is_empty()));
    assert!(merged.contribution.cells().iter().all(|m| m & 0b100 == 0));
    assert!(merged.grid.cells().contains(&MapCell::Occupied));
}
