//! Relative pose estimation against known answers: pairs cut from the recorded maps and
//! from simulated lunar arenas, turned and shifted at random. Accepted estimates must be
//! right (a wrong merge fails the test); most must be accepted; maps that share nothing
//! must be refused; swapping the maps must give the inverse.

mod common;

use rand::SeedableRng;
use realms_merge::synth::{self, Pair, PairSpec};
use realms_merge::{Params, Prepared, estimate, estimate_maps};

fn pairs(
    source: &realms_core::Grid<realms_merge::MapCell>,
    overlap: f64,
    seed: u64,
    n: usize,
) -> Vec<Pair> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let spec = PairSpec {
        overlap,
        ..PairSpec::default()
    };
    (0..n)
        .map(|_| synth::make_pair(source, &spec, &mut rng).expect("source has known cells"))
        .collect()
}

/// Fails unless `est` was refused as imprecise (a second optimum nearby fits as well).
fn assert_refused_as_imprecise(est: &realms_merge::Estimate) {
    assert!(
        est.refusal
            .as_deref()
            .is_some_and(|r| r.starts_with("imprecise")),
        "{:?}",
        est.refusal
    );
}

/// Fails unless `est` merged `pair` right (and says why it refused, if it did).
fn assert_merged_right(est: &realms_merge::Estimate, pair: &Pair, what: &str) {
    assert!(
        common::accepted_and_right(est, pair, what),
        "{what} refused: {:?}",
        est.refusal
    );
}

fn run(pairs: &[Pair], what: &str) -> usize {
    let params = Params::default();
    let mut accepted = 0;
    for (i, pair) in pairs.iter().enumerate() {
        let est = estimate_maps(&pair.a, &pair.b, &params);
        if common::accepted_and_right(&est, pair, &format!("{what} #{i}")) {
            accepted += 1;
        } else {
            let (m, rad) = est.a_from_b.map_or((f64::NAN, f64::NAN), |p| {
                common::error(&p, &pair.a_from_b, &pair.b)
            });
            eprintln!(
                "{what} #{i} refused ({m:.2} m, {:.2} deg off): {:?}",
                rad.to_degrees(),
                est.refusal
            );
        }
    }
    accepted
}

#[test]
fn recorded_office_pairs_are_recovered() {
    let office = common::recorded("tb3_office_real").cells;
    let ok = run(&pairs(&office, 0.4, 11, 3), "office 40 %");
    assert!(ok >= 2, "only {ok} of 3 office pairs merged");
}

#[test]
fn simulated_building_pairs_are_recovered() {
    let warehouse = common::recorded("aws_small_warehouse").cells;
    let ok = run(&pairs(&warehouse, 0.4, 12, 3), "warehouse 40 %");
    assert!(ok >= 2, "only {ok} of 3 warehouse pairs merged");
}

#[test]
fn sparse_lunar_pairs_are_recovered() {
    let arena = common::lunar(3, 5, 120);
    let ok = run(&pairs(&arena, 0.3, 13, 3), "lunar 30 %");
    assert!(ok >= 2, "only {ok} of 3 lunar pairs merged");
}

#[test]
fn maps_that_share_nothing_are_refused() {
    let params = Params::default();
    for (what, source) in [
        ("office", common::recorded("tb3_office_real").cells),
        ("lunar", common::lunar(4, 5, 120)),
    ] {
        for pair in pairs(&source, 0.0, 14, 2) {
            let est = estimate_maps(&pair.a, &pair.b, &params);
            assert!(
                est.accepted().is_none(),
                "{what}: disjoint maps merged at {:?} with confidence {:.2}",
                est.a_from_b,
                est.confidence
            );
            assert!(est.refusal.as_deref().is_some_and(|r| !r.is_empty()));
        }
    }
}

#[test]
fn swapping_the_maps_gives_the_inverse() {
    let params = Params::default();
    let office = common::recorded("aws_bookstore").cells;
    let pair = &pairs(&office, 0.5, 15, 1)[0];
    let (a, b) = (
        Prepared::new(&pair.a, &params),
        Prepared::new(&pair.b, &params),
    );
    let ab = estimate(&a, &b, &params).accepted().expect("A <- B merges");
    let ba = estimate(&b, &a, &params).accepted().expect("B <- A merges");
    assert!(common::close(&ab, &pair.a_from_b, &pair.b));
    assert!(
        common::close(&ba.inverse(), &pair.a_from_b, &pair.b),
        "{ab:?} vs inverse of {ba:?}"
    );
}

#[test]
fn a_known_start_is_confirmed_or_found_drifted() {
    use realms_core::Pose2;
    use realms_merge::{PriorWindow, estimate_with_prior};
    let params = Params::default();
    let office = common::recorded("tb3_office_real").cells;
    let pair = &pairs(&office, 0.4, 16, 1)[0];
    let (a, b) = (
        Prepared::new(&pair.a, &params),
        Prepared::new(&pair.b, &params),
    );
    let window = PriorWindow::default();
    // The rover started where the lander says: confirmed, no drift.
    let same = estimate_with_prior(&a, &b, pair.a_from_b, &window, &params);
    let found = same.estimate.accepted().expect("the prior is confirmed");
    assert!(common::close(&found, &pair.a_from_b, &pair.b));
    assert!(!same.drifted, "{same:?}");
    // Confirmed within the drift tolerances, the map goes where the prior puts it.
    assert_eq!(same.placed, Some(pair.a_from_b));
    assert!(!same.moved);
    // The map has drifted 1 m and 4 degrees from the prior: found, and reported.
    let prior = pair
        .a_from_b
        .compose(&Pose2::new(0.8, -0.6, 4f64.to_radians()));
    let drifted = estimate_with_prior(&a, &b, prior, &window, &params);
    let found = drifted
        .estimate
        .accepted()
        .expect("the drifted pose is found");
    assert!(common::close(&found, &pair.a_from_b, &pair.b), "{found:?}");
    assert!(drifted.drifted && drifted.drift_m > 0.5, "{drifted:?}");
    // Drifted this far, its walls lie on the other map's open ground at the prior: the
    // maps contradict the known start, and the map goes where they put it.
    assert!(drifted.moved, "{drifted:?}");
    assert_eq!(drifted.placed, Some(found));
}

/// Two opposite corners of a 30 x 20 m arena that share no ground: the second map is a bare
/// corner of two walls (8 m and 5 m), the first a larger corner with a few rocks along its
/// walls. The second fits the first half a turn round, every wall on a wall and all free
/// ground on free ground, and the rocks rule out every placement slid along a wall. Nothing
/// in the maps tells that placement from the corner the second map really shows, so the
/// merge must be refused (as a quarter-turn wrong merge of two lunar maps with no rock in
/// their overlap was, in `realms bench merge`).
#[test]
fn a_bare_corner_is_not_merged_onto_another_corner() {
    use realms_core::{Grid, GridGeometry, Point2};
    use realms_merge::{Map, MapCell};
    let rocks_m = [
        (10.0, 2.0),
        (14.0, 3.0),
        (18.0, 1.5),
        (2.0, 8.0),
        (3.0, 11.0),
        (1.5, 13.5),
        (12.0, 10.0),
    ];
    let arena = |keep: &dyn Fn(usize, usize) -> bool, rocks_m: &[(f64, f64)]| {
        let g = GridGeometry {
            width: 600,
            height: 400,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        let mut grid = Grid::new(g, MapCell::Unknown);
        for y in 0..400 {
            for x in 0..600 {
                if keep(x, y) {
                    let wall = x < 2 || y < 2 || x >= 598 || y >= 398;
                    let (xm, ym) = (x as f64 * 0.05, y as f64 * 0.05);
                    let rock = rocks_m
                        .iter()
                        .any(|(rx, ry)| (xm - rx).abs() < 0.2 && (ym - ry).abs() < 0.2);
                    *grid.get_mut(x, y).expect("in the grid") = if wall || rock {
                        MapCell::Occupied
                    } else {
                        MapCell::Free
                    };
                }
            }
        }
        Map::new(grid)
    };
    let a = arena(&|x, y| x < 400 && y < 300, &rocks_m);
    let b = arena(&|x, y| x >= 440 && y >= 300, &[]);
    let params = Params::default();
    let (pa, pb) = (Prepared::new(&a, &params), Prepared::new(&b, &params));
    let est = estimate(&pa, &pb, &params);
    assert!(
        est.accepted().is_none(),
        "a bare corner merged at {:?} with confidence {:.2}",
        est.a_from_b,
        est.confidence
    );
    assert!(
        est.refusal
            .as_deref()
            .is_some_and(|r| r.contains("two walls")),
        "{:?}",
        est.refusal
    );
    // Without the check, every other test of the pose passes: the corner is a trap.
    let lax = Params {
        min_off_two_walls: 0.0,
        ..Params::default()
    };
    let est = estimate(&pa, &pb, &lax);
    assert!(est.accepted().is_some(), "{:?}", est.refusal);
}

/// Two maps of a 30 m x 10 m hall sharing a band 2 m wide across it, with the lander's
/// square near one end of the band. The square pins the band's position there, but the band
/// may swing about it: the walls at its ends slide along themselves. Turned about the
/// band's middle, the square moves and the score drops; turned about the square, nothing
/// does, so the pose is not pinned and must be refused. A rock at the other end pins the
/// swing, and then the merge is made. So do the hall's long walls, which lie parallel in
/// the two maps only at the true heading ([`realms_merge::lines`]): with them the swing
/// is held and the square pins the rest; without them (`wall_pin_rad` 0) it is refused.
#[test]
fn a_band_free_to_swing_about_a_square_at_one_end_is_refused() {
    use realms_core::{Grid, GridGeometry, Point2};
    use realms_merge::{Map, MapCell};
    let hall = |keep: &dyn Fn(f64) -> bool, rock: bool| {
        let g = GridGeometry {
            width: 600,
            height: 200,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        let mut grid = Grid::new(g, MapCell::Unknown);
        for y in 0..200 {
            for x in 0..600 {
                let (xm, ym) = (x as f64 * 0.05, y as f64 * 0.05);
                if !keep(xm) {
                    continue;
                }
                let wall = x < 2 || y < 2 || x >= 598 || y >= 198;
                let lander = (14.4..15.6).contains(&xm) && (1.0..2.2).contains(&ym);
                let boulder = rock && (xm - 15.0).hypot(ym - 8.5) < 0.3;
                *grid.get_mut(x, y).expect("in the grid") = if wall || lander || boulder {
                    MapCell::Occupied
                } else {
                    MapCell::Free
                };
            }
        }
        Map::new(grid)
    };
    // The swing check on its own: neither the walls' heading nor the landmarks' proposals
    // (the square, voting for the exact truth, gives a start the check passes barely, at
    // 0.26 sharpness).
    let params = Params {
        wall_pin_rad: 0.0,
        landmark_hypotheses: 0,
        ..Params::default()
    };
    let (a, b) = (hall(&|x| x < 16.0, false), hall(&|x| x >= 14.0, false));
    let held = estimate_maps(&a, &b, &Params::default());
    let p = held.accepted().expect("the walls hold the swing");
    assert!(
        p.x_m.hypot(p.y_m) < 0.05 && p.yaw_rad.abs() < 0.05f64.to_radians(),
        "{p:?}"
    );
    for rock in [false, true] {
        let a = hall(&|x| x < 16.0, rock);
        let b = hall(&|x| x >= 14.0, rock);
        let est = estimate_maps(&a, &b, &params);
        if rock {
            let p = est.accepted().expect("the rock pins the swing");
            assert!(
                p.x_m.hypot(p.y_m) < 0.05 && p.yaw_rad.abs() < 0.3f64.to_radians(),
                "{p:?}"
            );
        } else {
            // Turned only about the band's middle, this was merged 1.5 degrees and 0.4 m off.
            assert!(
                est.accepted().is_none(),
                "merged at {:?}, sharpness {:.2}",
                est.a_from_b,
                est.sharpness
            );
            assert!(
                est.refusal
                    .as_deref()
                    .is_some_and(|r| r.contains("poorly constrained")),
                "{:?}",
                est.refusal
            );
        }
    }
}

/// Lunar pairs at 20 % overlap: long bands across the hall. Turned about the band's middle by
/// 0.3 m at its edge (a fraction of a degree), the walls at the band's ends keep most of
/// the score even where its rocks pin the pose; the sharpness check turns at least 3
/// degrees. On these 10 pairs that merges 5, all right; turned by 0.3 m at the edge alone,
/// 4. (It merged 6 before the precision check also turned the pose about the band's ends:
/// pair 7, found right to the centimetre, is now refused as imprecise. Over the 500 lunar
/// pairs of `realms bench merge` at 10 and 20 %, seeds 1-5, that check refused 2 right
/// merges and 2 wrong ones.)
#[test]
fn long_lunar_bands_pinned_by_their_rocks_are_merged() {
    let arena = common::lunar(2, 5, 120);
    let ok = run(&pairs(&arena, 0.2, 22, 10), "lunar 20 %");
    assert!(ok >= 5, "only {ok} of 10 lunar pairs merged");
}

/// `realms bench merge --seed 5`, lunar sparse at 10 %, pair 4: a band with a crater rim in
/// it. The truth is found, but a pose turned about the crater until half the band has left
/// the first map's known ground is as consistent, and counted as a rival it refused the
/// merge. It keeps the best pose's own crater pairs and explains less over less than 60 %
/// of the overlap, so it is no alternative; the merge is made, and right. Since the
/// thirty-second session the maps' own surfaces also fit the swung pose clearly worse
/// (`Params::rival_worse_z`): either test alone makes the merge, neither refuses it.
#[test]
fn a_pose_swung_about_the_same_crater_out_of_view_is_no_rival() {
    let pair = common::lunar_bench_pair("lunar-sparse", 5, 10, 4);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 5 pair 4");
    let surfaces_only = estimate_maps(
        &pair.a,
        &pair.b,
        &Params {
            rival_overlap_share: 0.0,
            ..Params::default()
        },
    );
    assert_merged_right(&surfaces_only, &pair, "seed 5 pair 4, surfaces only");
    let strict = estimate_maps(
        &pair.a,
        &pair.b,
        &Params {
            rival_overlap_share: 0.0,
            rival_worse_z: f64::INFINITY,
            ..Params::default()
        },
    );
    assert!(
        strict
            .refusal
            .as_deref()
            .is_some_and(|r| r.contains("ambiguous")),
        "{:?}",
        strict.refusal
    );
}

/// `realms bench merge --seed 3`, very sparse lunar arenas at 20 % overlap, pair 24: a pose
/// 0.3 m and 1.1 degrees off was merged with confidence 1.00. A restart of refinement
/// settles 0.14 m and 0.5 degrees from it and explains the maps as well, but the precision
/// check looked only for restarts farther than 0.15 m. It now looks from 0.13 m, and
/// counts a restart only if its surfaces also lie nearly as close as the best's (since the
/// thirty-second session, fits on the maps' own surfaces: [`realms_merge::fine::nearby`]).
/// The pair must not be merged wrong (it is now refused as imprecise).
#[test]
fn a_merge_a_restart_a_cell_away_explains_as_well_is_not_made() {
    let pair = common::lunar_bench_pair("lunar-very-sparse", 3, 20, 24);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    common::accepted_and_right(&est, &pair, "seed 3 very sparse 20 % pair 24");
}

/// `realms bench merge --seed 1`, lunar sparse at 20 % overlap, pair 14: a band with some 300
/// rock and rim points in it, found right to 0.01 m and refused as imprecise, because
/// refinement restarted nearby settled 0.14 m away with as large a score and sum of
/// closeness. Slid sideways, a band widens, and every sum grows with the points that come
/// into the overlap. Refinement now ends on the points two poses share
/// ([`realms_merge::verify::paired_closeness`]), where that buys nothing, and the merge is
/// made, and right.
#[test]
fn a_band_slid_sideways_does_not_outscore_the_truth() {
    let pair = common::lunar_bench_pair("lunar-sparse", 1, 20, 14);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 1 sparse 20 % pair 14");
}

/// `realms bench merge --seed 1`, very sparse lunar arenas at 10 % overlap, pair 9: a band
/// across the hall holding the lander's edge at one end and short stretches of wall at
/// both ends. Swung about the lander by a degree, the walls slide along themselves and
/// nothing else moves much: the truth and a pose 0.3 m off at the band's middle fit alike.
/// The precision check now also turns the pose about each end of the band; the merge must
/// not be made wrong (it was refused as imprecise). Since the thirty-ninth session the
/// maps' long walls hold the heading ([`realms_merge::lines`]), the swing is gone, and the
/// merge is made, right to the centimetre. Since the forty-first, the returns the lidar
/// missed inside the lander no longer line it with surfaces facing inwards (pockets of
/// free cells walled in all round are unknown, [`realms_merge::level`]); compared on its
/// true outline, the swung pose fits clearly worse even without the walls' heading.
#[test]
fn a_band_swung_about_the_lander_at_its_end_is_not_merged_wrong() {
    let pair = common::lunar_bench_pair("lunar-very-sparse", 1, 10, 9);
    let unheld = Params {
        wall_pin_rad: 0.0,
        ..Params::default()
    };
    let est = estimate_maps(&pair.a, &pair.b, &unheld);
    assert_merged_right(
        &est,
        &pair,
        "seed 1 very sparse 10 % pair 9, walls not held",
    );
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 1 very sparse 10 % pair 9, walls held");
    let (err_m, err_rad) = common::error(&est.a_from_b.expect("merged"), &pair.a_from_b, &pair.b);
    assert!(
        err_m < 0.02 && err_rad.to_degrees() < 0.05,
        "{err_m} m, {err_rad} rad"
    );
}

/// `realms bench merge --seed 8`, lunar sparse at 10 % overlap, pair 8: the best pose is
/// 0.21 m and 0.6 degrees off across a band, and refinement also settled right to 0.01 m.
/// The slid pose overlaps 95 m² against 86 and scores 824 against 797, under the 97 % the
/// precision check asked of a second optimum, so it was merged wrong. On the points both
/// poses share, the true one fits as closely; a second optimum then needed 90 % of the score
/// and 97 % of the closeness, summed or on the shared points, and the merge was refused.
/// Since the thirty-second session a fit on the maps' own surfaces restarted near the truth
/// lays them on each other more closely by some seven standard errors, takes the slid
/// pose's place, and the merge is made right.
#[test]
fn a_band_slid_sideways_is_not_merged_when_the_truth_fits_as_closely() {
    let pair = common::lunar_bench_pair("lunar-sparse", 8, 10, 8);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 8 sparse 10 % pair 8");
}

/// `realms bench merge --seed 2`, lunar sparse at 20 % overlap, pair 0: some 200 rock and
/// rim points in the band, the verified best right to 0.01 m, refused as imprecise because
/// a restart of refinement settled 0.15 m away with 99 % of the score. On 10 cm cells,
/// agreeing within a cell and a half, the two cannot be told apart. On the maps' own 5 cm
/// surfaces the restart is clearly worse, and the sub-cell fit places the map to a fraction
/// of a cell ([`realms_merge::fine`]).
#[test]
fn a_pose_the_surfaces_pin_is_merged_to_a_fraction_of_a_cell() {
    let pair = common::lunar_bench_pair("lunar-sparse", 2, 20, 0);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 2 sparse 20 % pair 0");
    let (off_m, off_rad) = common::error(&est.accepted().expect("merged"), &pair.a_from_b, &pair.b);
    assert!(
        off_m < 0.03 && off_rad.to_degrees() < 0.1,
        "{off_m:.3} m and {:.3} deg off",
        off_rad.to_degrees()
    );
}

/// `realms bench merge --seed 4`, lunar sparse at 10 % overlap, pair 15: the best right to
/// the centimetre with 65 landmark points agreeing, refused because a pose 1.0 m and 2
/// degrees away, swung about the band's rocks, agreed as consistently on 10 cm cells.
/// Both aligned on the maps' own 5 cm surfaces, the swung pose fits clearly worse, and the
/// merge is made; with that test off (`rival_worse_z` infinite) it is refused as before.
/// In the same cases pair 13, whose best pose is a quarter turn off with the truth as its
/// rival, must not be merged.
#[test]
fn a_rival_the_surfaces_fit_clearly_worse_is_none() {
    let pair = common::lunar_bench_pair("lunar-sparse", 4, 10, 15);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 4 sparse 10 % pair 15");
    let without = estimate_maps(
        &pair.a,
        &pair.b,
        &Params {
            rival_worse_z: f64::INFINITY,
            ..Params::default()
        },
    );
    assert!(
        without
            .refusal
            .as_deref()
            .is_some_and(|r| r.contains("ambiguous")),
        "{:?}",
        without.refusal
    );
    let quarter_turn = common::lunar_bench_pair("lunar-sparse", 4, 10, 13);
    let est = estimate_maps(&quarter_turn.a, &quarter_turn.b, &Params::default());
    common::accepted_and_right(&est, &quarter_turn, "seed 4 sparse 10 % pair 13");
}

/// `realms bench merge --seed 7`, lunar sparse at 10 % overlap, pair 9: the verified best
/// 0.17 m and 1.3 degrees off across a band (merged so, wrong, before the thirty-second
/// session). On the maps' own surfaces a fit restarted 1.2 degrees away lays them on each
/// other more closely by some ten standard errors; so much closer a fit may move the pose
/// twice as far from the verified best as one merely clearly closer, and the merge is made
/// right.
#[test]
fn a_much_closer_fit_on_the_surfaces_moves_the_pose_farther() {
    let pair = common::lunar_bench_pair("lunar-sparse", 7, 10, 9);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 7 sparse 10 % pair 9");
}

/// The band of `a_band_swung_about_the_lander_at_its_end_is_not_merged_wrong`, checked from
/// its true pose as a known start: the surfaces fit a pose 0.19 m and 0.6 degrees away as
/// closely, so the estimate is refused as imprecise, but both fits lie within the drift
/// tolerances of the start, so either confirms it, and the map stays there. (Without the
/// walls' heading, which settles this band: see that test.)
#[test]
fn two_fits_the_surfaces_cannot_tell_apart_both_near_the_known_start_confirm_it() {
    use realms_merge::{PriorWindow, estimate_with_prior};
    let params = Params {
        wall_pin_rad: 0.0,
        ..Params::default()
    };
    let pair = common::lunar_bench_pair("lunar-very-sparse", 1, 10, 9);
    let (a, b) = (
        Prepared::new(&pair.a, &params),
        Prepared::new(&pair.b, &params),
    );
    let check = estimate_with_prior(&a, &b, pair.a_from_b, &PriorWindow::default(), &params);
    assert_refused_as_imprecise(&check.estimate);
    assert!(
        check.estimate.imprecise_rival.is_some(),
        "{:?}",
        check.estimate
    );
    assert!(check.confirmed && !check.drifted, "{check:?}");
    assert_eq!(check.placed, Some(pair.a_from_b));
}

/// `realms bench merge --seed 4`, lunar sparse at 20 % overlap, pair 19: a band across the
/// hall with a crater in it, found right to 0.01 m but a degree off in heading. Turned three
/// degrees about the crater, the pose kept 98 % of its score (the band's wall pieces slide
/// along themselves), and it was refused as poorly constrained. Each map holds 20 m and more
/// of the hall's walls outside the band, parallel within 0.03 degrees at the truth: they
/// now hold the heading ([`realms_merge::lines`]), and the merge is made, right in heading
/// to a tenth of a degree.
#[test]
fn a_band_turned_about_its_crater_is_held_by_the_walls() {
    let pair = common::lunar_bench_pair("lunar-sparse", 4, 20, 19);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 4 sparse 20 % pair 19");
    let found = est.a_from_b.expect("merged");
    let (_, heading_err) = common::error(&found, &pair.a_from_b, &pair.b);
    assert!(
        heading_err.to_degrees() < 0.1,
        "{}",
        heading_err.to_degrees()
    );
    // Without the walls' heading, the turns refuse it.
    let unheld = Params {
        wall_pin_rad: 0.0,
        ..Params::default()
    };
    let est = estimate_maps(&pair.a, &pair.b, &unheld);
    let why = est.refusal.expect("refused without the walls");
    assert!(why.starts_with("poorly constrained"), "{why}");
}

/// `realms bench merge --seed 7`, lunar sparse at 10 % overlap, pair 3: a band whose two
/// craters and a rock agree at the truth (123 landmark points), yet the global search
/// never proposed it: laid over walls, a dozen wrong poses outscore it on the coarse
/// level. The landmarks now propose poses of their own ([`realms_merge::constellation`]),
/// and the merge is made, right; without them the best pose lies 20 m and a quarter turn
/// off, and the merge is refused.
#[test]
fn a_band_the_search_missed_is_found_by_its_rocks() {
    let pair = common::lunar_bench_pair("lunar-sparse", 7, 10, 3);
    let est = estimate_maps(&pair.a, &pair.b, &Params::default());
    assert_merged_right(&est, &pair, "seed 7 sparse 10 % pair 3");
    let without = Params {
        landmark_hypotheses: 0,
        ..Params::default()
    };
    let est = estimate_maps(&pair.a, &pair.b, &without);
    assert!(est.accepted().is_none(), "{:?}", est.a_from_b);
    let best = est.a_from_b.expect("a best pose");
    let (err_m, _) = common::error(&best, &pair.a_from_b, &pair.b);
    assert!(err_m > 1.0, "{err_m}");
}
