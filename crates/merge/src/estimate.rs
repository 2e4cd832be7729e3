//! The relative pose of two maps, with no prior or with a known start, verified and given a
//! confidence, or refused with the reason.
//!
//! Coarse to fine:
//! 1. headings: peaks of the correlated line-direction histograms ([`crate::rotation`]),
//!    each also turned half a turn, searched a few degrees either side; every heading when
//!    the histograms are flat;
//! 2. the global search ([`crate::search`]) over all translations at those headings on the
//!    coarse level, keeping the best few distinct hypotheses;
//! 3. on large maps (searched on a level twice as coarse) each also searched again on the
//!    search level in a small window, both kept; with no prior, the poses the landmarks vote
//!    for ([`crate::constellation`]) screened beside them;
//! 4. each refined and verified on the fine level ([`crate::verify`]);
//! 5. the best verified hypothesis is the highest scoring consistent one (no landmarks on
//!    open ground), unless another consistent one explains what it explains and more of the
//!    rocks (walls over walls a quarter turn away outscore the true pose at low overlap);
//! 6. it is accepted only if enough structure agrees, little conflicts, the maps overlap
//!    enough and the runner-up (the best clearly different pose that is neither a lesser
//!    explanation nor the same one slid along itself) scores clearly lower, no landmark
//!    lands on open ground, and more agrees than a corner of two walls (with no prior); a
//!    rival or runner-up the maps' own surfaces fit clearly worse is none;
//! 7. the pose is settled on the maps' own surfaces at their resolution ([`crate::fine`]),
//!    and refused as imprecise if a fit restarted nearby lays them on each other as
//!    closely. Refusing is always preferred to merging wrong.

use crate::fine;
use crate::map::Map;
use crate::prepare::{Params, Prepared};
use crate::rotation;
use crate::search::{self, SearchParams, SearchStats, Window};
use crate::verify::{self, Evidence, On};
use realms_core::geometry::normalize_angle_rad;
use realms_core::{Point2, Pose2};
use std::f64::consts::PI;

/// The answer for one pair of maps.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Pose of the second map's frame in the first map's frame, by the best hypothesis,
    /// settled on the maps' own surfaces where that fits them clearly more closely ([`fine`];
    /// `evidence` is the verified hypothesis's) (`None` if there was none at all). Use
    /// [`Estimate::accepted`] for a merge.
    pub a_from_b: Option<Pose2>,
    /// Confidence in the best hypothesis, 0..1.
    pub confidence: f64,
    /// What verification found for it.
    pub evidence: Evidence,
    /// Verified score of the best clearly different hypothesis (0 if none).
    pub runner_up_score: f64,
    /// How sharply verification singles out the pose, 0..1 ([`verify::sharpness`]).
    pub sharpness: f64,
    /// Share of the agreeing structure off the two walls carrying most of it
    /// ([`verify::off_two_walls`]); worked out only for a pose that passed every check
    /// before it (0 otherwise).
    pub off_two_walls: f64,
    /// Why the merge was refused; `None` if accepted.
    pub refusal: Option<String>,
    /// What the global search cost.
    pub stats: SearchStats,
    /// Every hypothesis of the global search as a pose of the second map's frame in the
    /// first's, with its search score and coarse screening score (for diagnosis); the
    /// landmarks' proposals follow, with a search score of -1.
    pub hypotheses: Vec<(Pose2, i32, f64)>,
    /// Every refined and verified hypothesis, best first, as a pose of the second map's
    /// frame in the first's with its evidence (for diagnosis).
    pub verified: Vec<(Pose2, Evidence)>,
    /// Where the merge was refused as imprecise (and passed every other check): the other
    /// pose, of the second map's frame in the first's, that lays the surfaces on each other
    /// as closely or more.
    pub imprecise_rival: Option<Pose2>,
}

impl Estimate {
    /// The pose if the merge was accepted.
    pub fn accepted(&self) -> Option<Pose2> {
        if self.refusal.is_none() {
            self.a_from_b
        } else {
            None
        }
    }

    fn refused(reason: String) -> Estimate {
        Estimate {
            a_from_b: None,
            confidence: 0.0,
            evidence: Evidence::default(),
            runner_up_score: 0.0,
            sharpness: 0.0,
            off_two_walls: 0.0,
            refusal: Some(reason),
            stats: SearchStats::default(),
            hypotheses: Vec::new(),
            verified: Vec::new(),
            imprecise_rival: None,
        }
    }
}

/// Where the second map's frame lies in the first's with no prior at all.
pub fn estimate(a: &Prepared, b: &Prepared, params: &Params) -> Estimate {
    let (mut peaks, ratio) =
        rotation::candidates(&a.directions, &b.directions, params.direction_peaks, 5);
    // The peaks a few degrees apart can all be one broad lobe of the correlation; in a
    // building the other lobe, a quarter turn away, can hold the answer (walls both ways
    // correlate almost equally). The best peak of another lobe is searched too.
    let (lobes, _) = rotation::candidates(
        &a.directions,
        &b.directions,
        params.direction_lobes + 1,
        params.lobe_separation_deg,
    );
    for lobe in lobes {
        let apart = |p: &f64| {
            let d = (lobe - p).rem_euclid(180.0);
            d.min(180.0 - d) >= params.lobe_separation_deg as f64
        };
        if peaks.iter().all(apart) {
            peaks.push(lobe);
        }
    }
    // Each heading group is searched on its own: at low overlap a wrong heading that lays
    // long walls over walls can outscore the true one, and one global list would then hold
    // nothing but its variants.
    let mut groups: Vec<Vec<f64>> = Vec::new();
    let headed = ratio >= params.min_direction_ratio && !peaks.is_empty();
    if headed {
        let n = (params.peak_halfwidth_rad / params.yaw_step_rad).round() as i64;
        for p in &peaks {
            for base in [p.to_radians(), p.to_radians() + PI] {
                groups.push(yaws_around(base, n, params.yaw_step_rad));
            }
        }
    } else {
        // No dominant directions: every heading, in quarter turns.
        let n = (2.0 * PI / params.yaw_step_rad).round() as i64;
        let all: Vec<f64> = (0..n)
            .map(|k| normalize_angle_rad(k as f64 * 2.0 * PI / n as f64))
            .collect();
        groups.extend(
            all.chunks(all.len().div_ceil(4).max(1))
                .map(<[f64]>::to_vec),
        );
    }
    // Without dominant directions the groups are quarter turns, and their middles no
    // heading the landmarks could vote at.
    run(a, b, &groups, None, headed, params)
}

/// A known-start check: the prior, what the maps say, and whether they differ.
#[derive(Clone, Debug, PartialEq)]
pub struct PriorCheck {
    /// The estimate found near the prior (refused if the maps do not confirm any pose).
    pub estimate: Estimate,
    /// Distance between the prior and the estimate at the second map's centre, metres.
    pub drift_m: f64,
    /// Heading difference, radians.
    pub drift_rad: f64,
    /// Whether the maps confirm a pose that differs from the prior by more than the
    /// tolerances.
    pub drifted: bool,
    /// Share of obstacle points within the contradiction tolerance of the other map's
    /// structure at the prior pose, among those and the ones on its open ground farther
    /// off ([`verify::loose_agreement`]); `None` when no obstacle point of either map lands
    /// on the other's known ground.
    pub loose_agreement: Option<f64>,
    /// Where the second map goes: the prior, confirmed by a pose found within the drift
    /// tolerances of it, or found beyond them where the maps still agree at the prior up to
    /// the drift `PriorWindow::contradiction_tolerance_m` allows (the map drifted where the
    /// two overlap, not as a whole), or unconfirmed when the maps share too little structure
    /// to confirm any pose but nothing in them contradicts it; the pose found when the maps
    /// contradict the prior there. `None` when they contradict it and confirm no pose.
    pub placed: Option<Pose2>,
    /// Whether `placed` was confirmed by the maps (false: it is the prior, unchecked).
    pub confirmed: bool,
    /// Whether `placed` is the pose found rather than the prior: drift the maps contradict
    /// the prior over.
    pub moved: bool,
    /// Why the map was left out, if it was.
    pub refusal: Option<String>,
}

impl PriorCheck {
    /// Confidence in the placement: the estimate's when confirmed, 0 for a map placed at
    /// its prior unchecked (or refused).
    pub fn confidence(&self) -> f64 {
        if self.confirmed {
            self.estimate.confidence
        } else {
            0.0
        }
    }

    /// Why no pose could be confirmed, for a map placed at its prior anyway.
    pub fn unconfirmed_because(&self) -> Option<&str> {
        if self.placed.is_some() && !self.confirmed {
            self.estimate.refusal.as_deref()
        } else {
            None
        }
    }
}

/// How far from a prior to look, and how far counts as drift.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PriorWindow {
    /// Half-width of the translation search, metres.
    pub linear_m: f64,
    /// Half-width of the heading search, radians.
    pub angular_rad: f64,
    /// A confirmed pose farther than this from the prior is drift, metres.
    pub drift_tolerance_m: f64,
    /// ... or turned more than this, radians.
    pub drift_tolerance_rad: f64,
    /// When no pose is confirmed, the prior is still taken unless at least this many
    /// obstacle points (surface points, thinned) of either map land on the other's open
    /// ground farther than `contradiction_tolerance_m` from its structure ...
    pub contradiction_points: usize,
    /// ... and the points within that tolerance are less than this share of those and
    /// the ones farther off.
    pub contradiction_agreement: f64,
    /// Drift a map placed unconfirmed may carry, metres.
    pub contradiction_tolerance_m: f64,
}

impl Default for PriorWindow {
    fn default() -> Self {
        PriorWindow {
            linear_m: 3.0,
            angular_rad: 10f64.to_radians(),
            drift_tolerance_m: 0.3,
            drift_tolerance_rad: 2f64.to_radians(),
            contradiction_points: 100,
            contradiction_agreement: 0.8,
            contradiction_tolerance_m: 0.5,
        }
    }
}

/// Known-start mode: refines `prior` (pose of the second map's frame in the first's) within
/// `window` and reports whether the maps have drifted from it.
///
/// Rovers that split the work share little structure, and what they share they see from
/// different sides (rover 1 the lander's east face, rover 2 its north face), so often no
/// pose can be confirmed. The known start is then evidence enough, and the map is placed at
/// the prior, marked unconfirmed (whatever the estimator's reason for not confirming, kept
/// in `estimate.refusal`), unless the maps contradict it there: many obstacles of one on
/// the other's open ground, farther from its structure than drift would put them. A map
/// none of whose obstacles land on the other's known ground (or the other way round) has
/// nothing to check the prior against and is refused.
///
/// A pose found within the drift tolerances confirms the prior, and the map is placed at
/// the prior, not at the pose found. A known start is good to centimetres; two rovers' maps
/// agree only to their drift, a few decimetres. The pose that fits them best where they
/// overlap turns the rest of the map by as much. In the default mission (seed 1), rover3's
/// map placed where it fit rover1's best (0.38 m and 0.7 degrees from its start) left 76.5 %
/// of the merged map's occupied cells on a true obstacle, against 95.4 % at the known start
/// (BENCHMARKS.md, "The rovers' own maps").
///
/// A pose found beyond the tolerances is drift, and reported. The map still stays at the
/// prior unless the maps contradict it there: a map that drifted where the two overlap has
/// not moved as a whole, and every map the lander moved off its known start this way in 32
/// whole missions left the merged map worse (seed 7: 90.4 -> 58.2 % of occupied cells
/// right; BENCHMARKS.md, "A drifted map stays at its known start").
pub fn estimate_with_prior(
    a: &Prepared,
    b: &Prepared,
    prior: Pose2,
    window: &PriorWindow,
    params: &Params,
) -> PriorCheck {
    let grid_prior = a
        .frame_from_grid
        .inverse()
        .compose(&prior)
        .compose(&b.frame_from_grid);
    let n = (window.angular_rad / params.yaw_step_rad).ceil() as i64;
    let yaws = yaws_around(grid_prior.yaw_rad, n, params.yaw_step_rad);
    let search_window = Window {
        centroid_at: grid_prior.transform_point(b.centroid),
        half_m: window.linear_m,
    };
    let estimate = run(a, b, &[yaws], Some(search_window), false, params);
    let centre = b.frame_from_grid.transform_point(b.centroid);
    let drift_of = |p: &Pose2| {
        (
            prior
                .transform_point(centre)
                .distance_m(p.transform_point(centre)),
            normalize_angle_rad(p.yaw_rad - prior.yaw_rad).abs(),
        )
    };
    let within_tolerance = |p: &Pose2| {
        let (m, rad) = drift_of(p);
        m <= window.drift_tolerance_m && rad <= window.drift_tolerance_rad
    };
    // Refused only because the surfaces fit two poses alike: when both lie within the drift
    // tolerances of the prior, the maps cannot say which, but either confirms the prior.
    let found = estimate.accepted().or_else(|| {
        let (best, rival) = (estimate.a_from_b?, estimate.imprecise_rival?);
        (within_tolerance(&best) && within_tolerance(&rival)).then_some(best)
    });
    let (drift_m, drift_rad) = found.as_ref().map_or((0.0, 0.0), drift_of);
    let (near, far) = verify::loose_agreement(a, b, &grid_prior, window.contradiction_tolerance_m);
    let loose = (near + far > 0).then(|| near as f64 / (near + far) as f64);
    let contradicted = loose.is_some_and(|share| {
        far >= window.contradiction_points && share < window.contradiction_agreement
    });
    let drifted = drift_m > window.drift_tolerance_m || drift_rad > window.drift_tolerance_rad;
    // Drift is measured on a pose found, so a drifted map always has one to go to.
    let moved = drifted && contradicted;
    let (placed, confirmed, refusal) = match found {
        Some(found) if moved => (Some(found), true, None),
        Some(_) => (Some(prior), true, None),
        None if loose.is_none() => (
            None,
            false,
            Some(format!(
                "nothing to check the known start against: no obstacle of either map lies on the other's known ground there ({})",
                estimate.refusal.as_deref().unwrap_or("no pose confirmed")
            )),
        ),
        None if contradicted => (
            None,
            false,
            Some(format!(
                "the maps contradict the known start: {:.0} % of the obstacles lie within {} m of the other map's there, {far} lie on its open ground farther off ({})",
                100.0 * loose.unwrap_or(0.0),
                window.contradiction_tolerance_m,
                estimate.refusal.as_deref().unwrap_or("no pose confirmed")
            )),
        ),
        None => (Some(prior), false, None),
    };
    PriorCheck {
        drifted,
        estimate,
        drift_m,
        drift_rad,
        loose_agreement: loose,
        placed,
        confirmed,
        moved,
        refusal,
    }
}

/// Prepares both maps and estimates with no prior.
pub fn estimate_maps(a: &Map, b: &Map, params: &Params) -> Estimate {
    estimate(&Prepared::new(a, params), &Prepared::new(b, params), params)
}

/// Whether two grid-local poses put the moving centre within `distinct_m` and turn less
/// than `distinct_rad` apart.
fn same_pose(p: &Pose2, q: &Pose2, centre: Point2, params: &Params) -> bool {
    p.transform_point(centre)
        .distance_m(q.transform_point(centre))
        < params.distinct_m
        && normalize_angle_rad(p.yaw_rad - q.yaw_rad).abs() < params.distinct_rad
}

/// Whether a clearly different pose with evidence `e` is an alternative to the best pose
/// (evidence `best`), however the totals compare: a larger overlap of walls buys a larger
/// total without being any more likely. It must be as consistent: no more than
/// `rival_agreement_slack` worse in agreement than the best, and no landmark on open ground
/// (a pose that puts a few per cent of its structure on open ground where the best puts none
/// is not an alternative on maps this clean). And it must explain a fair share of what the
/// best explains: of the structure (`rival_share`) and of the landmarks
/// (`rival_landmark_share`).
fn is_rival(e: &Evidence, best: &Evidence, params: &Params) -> bool {
    e.agreement() >= params.min_agreement
        && e.agreement() >= best.agreement() - params.rival_agreement_slack
        && !landmarks_disagree(e, params)
        && e.agree >= params.min_agree_cells
        && e.agree as f64 >= params.rival_share * best.agree as f64
        && e.landmark_agree as f64 >= params.rival_landmark_share * best.landmark_agree as f64
}

/// Whether a pose with evidence `e` is a lesser explanation than one with evidence `by`:
/// `by` explains what `e` does (`by` would be a rival to `e`), while `e` leaves out too
/// much of what `by` explains to be a rival to it. At a quarter turn in a rectangular
/// arena the walls lie over walls for metres and outscore the true pose, but the rocks the
/// true pose brings together stay apart.
fn dominated(e: &Evidence, by: &Evidence, params: &Params) -> bool {
    is_rival(by, e, params) && !is_rival(e, by, params)
}

/// Which verified pose (sorted best score first) to take: the best scoring one that is
/// consistent (agreement and landmarks), or the first pose if none is; then a consistent
/// pose that dominates it ([`dominated`]) instead, if there is one.
fn choose_best(verified: &[(Pose2, Evidence)], centre: Point2, params: &Params) -> usize {
    let consistent =
        |e: &Evidence| e.agreement() >= params.min_agreement && !landmarks_disagree(e, params);
    let Some(first) = verified.iter().position(|(_, e)| consistent(e)) else {
        return 0;
    };
    let (top, top_e) = &verified[first];
    verified
        .iter()
        .position(|(p, e)| {
            consistent(e) && !same_pose(p, top, centre, params) && dominated(top_e, e, params)
        })
        .unwrap_or(first)
}

/// Parallel walls of the two maps, within this much at a pose, say which way it could slide.
const SLIDE_WALLS_PARALLEL_RAD: f64 = 0.02;

/// The directions (grid-local in `a`) of `a`'s walls that some wall of `b` lies parallel to
/// at `pose`, one for each way they run (a band may slide along either pair of a
/// rectangular hall's walls).
fn walls_along_rad(a: &Prepared, b: &Prepared, pose: &Pose2) -> Vec<f64> {
    let mut along: Vec<f64> = Vec::new();
    for wa in &a.walls {
        let parallel =
            crate::lines::parallel_offset_rad(std::slice::from_ref(wa), &b.walls, pose.yaw_rad)
                .is_some_and(|d| d <= SLIDE_WALLS_PARALLEL_RAD);
        let new_way = along.iter().all(|&d| {
            crate::lines::directions_apart_rad(wa.direction_rad, d) > SLIDE_WALLS_DISTINCT_RAD
        });
        if parallel && new_way {
            along.push(wa.direction_rad);
        }
    }
    along
}

/// Walls whose directions differ by more than this run different ways.
const SLIDE_WALLS_DISTINCT_RAD: f64 = 0.2;

/// The search score the landmarks' proposals are listed with in [`Estimate::hypotheses`]:
/// none of the search's, which are never negative.
const LANDMARK_SEARCH_SCORE: i32 = -1;

/// The heading group of the landmarks' proposals: none of the search's.
const LANDMARK_GROUP: usize = usize::MAX;

/// The share of the chosen pose's verified score a neighbour needs to be weighed against it
/// in [`settle_among_neighbours`].
const SETTLE_SCORE_SHARE: f64 = 0.9;

/// Surface points within this of the other map's known ground at the best pose enter the
/// sub-cell fit and the precision check (whose restarts start up to 0.35 m away).
const FINE_MARGIN_M: f64 = 0.5;
/// The sub-cell fit is kept when it pairs at least this many points ...
const FINE_MIN_PAIRS: usize = 20;
/// ... and moves the overlap's centre at most [`Params::fine_reach_m`] from the verified
/// best (so may a better restart, [`Params::precision`]; one farther off makes the merge
/// imprecise: the verified best and the surfaces disagree) ...
/// ... and turns at most this far (radians) from the verified best, or as much as moves
/// the overlap's edge that far ...
const FINE_MAX_TURN_RAD: f64 = 0.035;
/// ... and fits more closely than it by at least this many standard errors (negative:
/// better; [`fine::Comparison::z`]).
const FINE_BETTER_Z: f64 = -2.0;
/// A restart that fits more closely by at least this many standard errors ...
const FINE_MUCH_BETTER_Z: f64 = -5.0;
/// ... may replace the pose this many times as far from the verified best as the reach
/// ([`within_reach`]): seed 7, lunar sparse, 10 %, pair 9, once merged 0.17 m off, is
/// merged right by a restart 1.2 degrees away that fits better by 10 standard errors.
const FINE_MUCH_BETTER_REACH: f64 = 2.0;
/// Restarts that fit clearly more closely replace the pose at most this many times.
const FINE_MAX_HOPS: usize = 3;
/// The heading the walls give ([`held_by_walls`]) is taken only where the pose keeps this
/// share of its verified score at it.
const WALL_HELD_SCORE_SHARE: f64 = 0.9;

/// Among the verified poses near the chosen one (`chosen`, an index into `verified`) that
/// are as consistent and verify nearly as well, the one whose surfaces lie closest on the
/// points they share ([`verify::paired_closeness`]). Across a thin band a pose slid a few
/// cells sideways widens the overlap and outscores the true pose on every sum; compared on
/// common points it fits worse.
fn settle_among_neighbours(
    a: &Prepared,
    b: &Prepared,
    verified: &[(Pose2, Evidence)],
    chosen: usize,
    params: &Params,
) -> usize {
    let (chosen_pose, chosen_e) = verified[chosen];
    let consistent =
        |e: &Evidence| e.agreement() >= params.min_agreement && !landmarks_disagree(e, params);
    if !consistent(&chosen_e) {
        return chosen;
    }
    let mut current = chosen;
    for (i, (p, e)) in verified.iter().enumerate() {
        if i == current
            || !same_pose(p, &chosen_pose, b.centroid, params)
            || !consistent(e)
            || e.score < SETTLE_SCORE_SHARE * chosen_e.score
        {
            continue;
        }
        let (at_current, at_p) = verify::paired_closeness(a, b, &verified[current].0, p);
        if at_p > at_current {
            current = i;
        }
    }
    current
}

/// Whether the pose `p` (evidence `e`) keeps the best pose's own landmark pairs (at least
/// `subset_share` of its agreeing landmark points agree at the best and land within
/// `subset_tolerance_m` of where it puts them) and owes its consistency to an overlap less
/// than `rival_overlap_share` of the best's, while explaining less: a band turned about the
/// crater in it until half the band has left the other map's known ground. It brings no
/// rock together that the best does not, and what it drops is evidence, not conflict.
fn swung_out_of_view(
    a: &Prepared,
    b: &Prepared,
    best_pose: &Pose2,
    best: &Evidence,
    p: &Pose2,
    e: &Evidence,
    params: &Params,
) -> bool {
    e.agree < best.agree
        && e.overlap_m2 < params.rival_overlap_share * best.overlap_m2
        && verify::shared_agreement_of(a, b, best_pose, p, params.subset_tolerance_m, true)
            >= params.subset_share
}

/// Whether landmark points land on open ground too often for `e`'s pose to be right.
fn landmarks_disagree(e: &Evidence, params: &Params) -> bool {
    e.landmark_conflict >= params.min_landmark_conflicts
        && e.landmark_conflict as f64 > params.max_landmark_conflict_share * e.landmark_agree as f64
}

/// A hypothesis of the coarse global level searched again on the search level, the
/// headings of half a heading group at half its step and a window of two coarse cells
/// either way: the middle step of coarse to fine (Olson 2009 searches a finer grid only
/// where the coarse one allows). At the coarse level's cell and step a pose a metre and two
/// degrees off can outscore the true one nearby, and refinement by coordinate ascent does
/// not always climb out of that.
fn rescan(
    a: &Prepared,
    b: &Prepared,
    start: Pose2,
    search_params: &SearchParams,
    params: &Params,
) -> Pose2 {
    let n = (params.peak_halfwidth_rad / params.yaw_step_rad).round() as i64;
    let yaws = yaws_around(start.yaw_rad, n, params.yaw_step_rad);
    let window = Window {
        centroid_at: start.transform_point(b.centroid),
        half_m: 2.0 * a.global.cell_m,
    };
    let one = SearchParams {
        hypotheses: 1,
        ..*search_params
    };
    let (found, _) = search::search(
        a.fields(),
        a.search.cell_m,
        &b.search_points,
        b.centroid,
        &yaws,
        Some(window),
        &one,
    );
    found.first().map_or(start, |h| h.fixed_from_moving)
}

fn run(
    a: &Prepared,
    b: &Prepared,
    groups: &[Vec<f64>],
    window: Option<Window>,
    landmarks_propose: bool,
    params: &Params,
) -> Estimate {
    let search_params = SearchParams {
        hypotheses: params.hypotheses,
        distinct_m: params.distinct_m,
        distinct_rad: params.distinct_rad,
        min_score: 1,
        min_share_of_best: params.min_share_of_best,
        max_nodes: params.max_search_nodes,
    };
    let mut stats = SearchStats::default();
    // Hypotheses with the heading group they came from.
    let mut hyps = Vec::new();
    let mut groups_seen = 0usize;
    let coarse = window.is_none() && a.searched_coarse;
    for yaws in groups {
        let (found, group_stats) = if coarse {
            let yaws: Vec<f64> = yaws.iter().step_by(2).copied().collect();
            search::search(
                a.global_fields(),
                a.global.cell_m,
                &b.global_points,
                b.centroid,
                &yaws,
                window,
                &search_params,
            )
        } else {
            search::search(
                a.fields(),
                a.search.cell_m,
                &b.search_points,
                b.centroid,
                yaws,
                window,
                &search_params,
            )
        };
        hyps.extend(found.into_iter().map(|h| (groups_seen, h)));
        groups_seen += 1;
        stats.headings += group_stats.headings;
        stats.nodes += group_stats.nodes;
    }
    if hyps.is_empty() {
        return Estimate::refused("no pose puts the second map's structure on the first's".into());
    }
    // Screen every hypothesis on the coarse level, then refine and verify the best few.
    let to_frames = |p: &Pose2| {
        a.frame_from_grid
            .compose(p)
            .compose(&b.frame_from_grid.inverse())
    };
    let mut screened: Vec<(usize, Pose2, f64)> = hyps
        .iter()
        .map(|(g, h)| {
            let score = verify::score(
                a,
                b,
                &h.fixed_from_moving,
                params.conflict_weight,
                On::Search,
            );
            (*g, h.fixed_from_moving, score)
        })
        .collect();
    let mut hypotheses: Vec<(Pose2, i32, f64)> = hyps
        .iter()
        .zip(&screened)
        .map(|((_, h), (_, _, score))| (to_frames(&h.fixed_from_moving), h.score, *score))
        .collect();
    // With no prior, the landmarks propose poses of their own
    // ([`crate::constellation`]): where the walls outscore a band's few rocks in the search,
    // the rocks still agree on one translation. Screened like the search's, they compete
    // for refinement with its best.
    if landmarks_propose && params.landmark_hypotheses > 0 {
        let yaws: Vec<f64> = groups
            .iter()
            .filter_map(|g| g.get(g.len() / 2))
            .map(|&yaw| {
                crate::lines::turn_to_parallel_rad(
                    &a.walls,
                    &b.walls,
                    yaw,
                    params.peak_halfwidth_rad,
                )
                .map_or(yaw, |turn| yaw + turn)
            })
            .collect();
        let proposed = crate::constellation::hypotheses(
            &a.landmarks,
            &b.landmarks,
            &yaws,
            params.landmark_hypotheses,
        );
        // And each heading group's best, where the walls lie parallel at it, slid along
        // them onto a landmark pair ([`crate::constellation::slides`]).
        let slid: Vec<Pose2> = (0..groups_seen)
            .filter_map(|g| {
                screened
                    .iter()
                    .filter(|(hg, _, _)| *hg == g)
                    .max_by(|x, y| x.2.total_cmp(&y.2))
            })
            .flat_map(|(_, p, _)| {
                walls_along_rad(a, b, p)
                    .into_iter()
                    .map(move |along| (p, along))
            })
            .flat_map(|(p, along)| {
                crate::constellation::slides(
                    &a.landmarks,
                    &b.landmarks,
                    p,
                    along,
                    params.landmark_hypotheses,
                )
            })
            .collect();
        for p in proposed.into_iter().chain(slid) {
            let score = verify::score(a, b, &p, params.conflict_weight, On::Search);
            screened.push((LANDMARK_GROUP, p, score));
            hypotheses.push((to_frames(&p), LANDMARK_SEARCH_SCORE, score));
        }
    }
    screened.sort_by(|x, y| y.2.total_cmp(&x.2));
    // The best of every heading group goes on (so that a true heading outscored by walls
    // laid over walls at another heading is still verified, and seen as a rival), and the
    // landmarks' best (with as many groups as refinements they would otherwise never be),
    // then the best of the rest.
    let mut chosen: Vec<Pose2> = Vec::new();
    for g in (0..groups_seen).chain([LANDMARK_GROUP]) {
        if let Some((_, p, score)) = screened.iter().find(|(hg, _, _)| *hg == g)
            && *score > 0.0
        {
            chosen.push(*p);
        }
    }
    for (_, p, _) in &screened {
        if chosen.len() >= params.refined_hypotheses.max(groups_seen) {
            break;
        }
        if !chosen.contains(p) {
            chosen.push(*p);
        }
    }
    if coarse {
        // Each coarse hypothesis is also searched again on the search level (see
        // [`rescan`]); the original stays too, so that a rival it leads to is still seen.
        let rescanned: Vec<Pose2> = chosen
            .iter()
            .map(|p| rescan(a, b, *p, &search_params, params))
            .collect();
        for r in rescanned {
            let settled = |p: &Pose2| {
                p.transform_point(b.centroid)
                    .distance_m(r.transform_point(b.centroid))
                    < a.search.cell_m
                    && normalize_angle_rad(p.yaw_rad - r.yaw_rad).abs() < params.yaw_step_rad
            };
            if !chosen.iter().any(settled) {
                chosen.push(r);
            }
        }
    }
    let mut verified: Vec<(Pose2, Evidence)> = chosen
        .iter()
        .map(|start| {
            // Keep the refinement unless verification finds it clearly worse (verification
            // tolerates a cell of slack, so within that it cannot tell which is more
            // precise; refinement can).
            let pose = verify::refine(a, b, *start, params);
            let refined = verify::verify(a, b, &pose, params.conflict_weight, On::Refine);
            let unrefined = verify::score(a, b, start, params.conflict_weight, On::Refine);
            if refined.score >= unrefined - 0.05 * unrefined.abs() {
                (pose, refined)
            } else {
                let unrefined = verify::verify(a, b, start, params.conflict_weight, On::Refine);
                (*start, unrefined)
            }
        })
        .collect();
    verified.sort_by(|x, y| y.1.score.total_cmp(&x.1.score));
    let best = choose_best(&verified, b.centroid, params);
    let best = settle_among_neighbours(a, b, &verified, best, params);
    let chosen_best = verified.remove(best);
    verified.insert(0, chosen_best);
    let (best_pose, evidence) = verified[0];
    // Not an alternative to the best: a clearly different pose whose landmarks land on open
    // ground, one the best explains while it leaves out what the best explains
    // ([`dominated`]), and one that agrees with nothing but what the best agrees with, paired
    // alike: the same explanation with part of it slid out of the overlap (a crater rim
    // turned about its centre, a wall slid along itself; [`verify::shared_agreement`]);
    // and one swung about the best's own landmarks until much of the overlap has left view
    // ([`swung_out_of_view`]).
    let others: Vec<&(Pose2, Evidence)> = verified
        .iter()
        .skip(1)
        .filter(|(p, e)| {
            !same_pose(p, &best_pose, b.centroid, params)
                && !landmarks_disagree(e, params)
                && !dominated(e, &evidence, params)
                && verify::shared_agreement(a, b, &best_pose, p, params.subset_tolerance_m)
                    < params.subset_share
                && !swung_out_of_view(a, b, &best_pose, &evidence, p, e, params)
        })
        .collect();
    let (overlap, settled_pose) = settle_on_surfaces(a, b, &best_pose, &evidence, params);
    // The maps' long walls may pin the heading more surely than the overlap can: then the
    // pose takes their heading, and neither the sharpness nor the precision check turns it.
    let held = held_by_walls(a, b, &settled_pose, &evidence, params);
    let heading_held = held.is_some();
    let (overlap, settled_pose, sharpness_at) = match held {
        Some((overlap, pose, e)) => (overlap, pose, (pose, e)),
        None => (overlap, settled_pose, (best_pose, evidence)),
    };
    // A rival the maps' own surfaces, aligned at both poses, fit clearly worse than the
    // best is none (`Params::rival_worse_z`).
    // (Worked out once per pose, and only for those that would otherwise refuse the merge.)
    let worse: Vec<std::cell::OnceCell<bool>> = others.iter().map(|_| Default::default()).collect();
    let fits_clearly_worse = |k: usize| {
        *worse[k].get_or_init(|| {
            let q = others[k].0;
            let q_overlap = fine::Overlap::at(&a.fine, &b.fine, &q, FINE_MARGIN_M);
            let q_fit = fine::align(&a.fine, &b.fine, &q_overlap, q);
            let both = overlap.union(&q_overlap);
            fine::compare(&a.fine, &b.fine, &both, &settled_pose, &q_fit.pose).z
                >= params.rival_worse_z
        })
    };
    // The runner-up: the best scoring other pose, leaving out those that would refuse the
    // merge on their score alone but fit the surfaces clearly worse.
    let runner_up_score = others
        .iter()
        .enumerate()
        .find(|(k, (_, e))| {
            e.score < params.max_runner_up_ratio * evidence.score || !fits_clearly_worse(*k)
        })
        .map_or(0.0, |(_, (_, e))| e.score.max(0.0));
    let rival = others
        .iter()
        .enumerate()
        .find(|(k, (_, e))| is_rival(e, &evidence, params) && !fits_clearly_worse(*k))
        .map(|(_, r)| r);
    let agreement = evidence.agreement();
    let ratio = if evidence.score > 0.0 {
        runner_up_score / evidence.score
    } else {
        1.0
    };
    let support = 1.0 - (-(evidence.agree as f64) / (2.0 * params.min_agree_cells as f64)).exp();
    let sharpness = verify::sharpness(
        a,
        b,
        &sharpness_at.0,
        &sharpness_at.1,
        params.conflict_weight,
        params.sharpness_shift_m,
        params.sharpness_min_turn_rad,
        heading_held,
    );
    let confidence =
        (agreement * (1.0 - ratio) * support * (sharpness / 0.5).min(1.0)).clamp(0.0, 1.0);
    // Only worth looking for when the merge would otherwise be accepted.
    let precise_cell = std::cell::OnceCell::new();
    let precise = || {
        *precise_cell.get_or_init(|| {
            precision_on_surfaces(
                a,
                b,
                &overlap,
                settled_pose,
                &sharpness_at.0,
                &evidence,
                params,
                heading_held,
            )
        })
    };
    // Worked out only for a pose every cheaper check has let through, and only with no
    // prior: a window around a known start already rules out the other corners.
    let off_walls_cell = std::cell::OnceCell::new();
    let off_walls = || *off_walls_cell.get_or_init(|| verify::off_two_walls(a, b, &best_pose));
    let refusal = if evidence.overlap_m2 < params.min_overlap_m2 {
        Some(format!(
            "the maps overlap by only {:.1} m^2 at the best pose (at least {:.1} needed)",
            evidence.overlap_m2, params.min_overlap_m2
        ))
    } else if evidence.agree < params.min_agree_cells {
        Some(format!(
            "too little structure agrees at the best pose ({} cells, at least {} needed)",
            evidence.agree, params.min_agree_cells
        ))
    } else if evidence.score < params.min_score {
        Some(format!(
            "too little evidence at the best pose: {} agreeing less {} x {} conflicting is {:.0} (at least {:.0} needed)",
            evidence.agree,
            params.conflict_weight,
            evidence.conflict,
            evidence.score,
            params.min_score
        ))
    } else if agreement < params.min_agreement {
        Some(format!(
            "structure disagrees at the best pose: {:.0} % agrees ({} cells), {} cells conflict",
            100.0 * agreement,
            evidence.agree,
            evidence.conflict
        ))
    } else if landmarks_disagree(&evidence, params) {
        Some(format!(
            "landmarks disagree at the best pose: {} landmark points land on open ground, {} on landmarks",
            evidence.landmark_conflict, evidence.landmark_agree
        ))
    } else if sharpness < params.min_sharpness {
        Some(format!(
            "poorly constrained: moved {:.1} m (or turned as much, at least {:.0} deg) the maps still agree {:.0} % as well, and moved twice as far more than half as well (walls with nothing else to pin them?)",
            params.sharpness_shift_m,
            params.sharpness_min_turn_rad.to_degrees(),
            100.0 * (1.0 - sharpness)
        ))
    } else if let Some((pose, e)) = rival {
        Some(format!(
            "ambiguous: a pose {:.1} m and {:.0} deg away is as consistent ({} agreeing, {} conflicting)",
            pose.transform_point(b.centroid)
                .distance_m(best_pose.transform_point(b.centroid)),
            normalize_angle_rad(pose.yaw_rad - best_pose.yaw_rad)
                .to_degrees()
                .abs(),
            e.agree,
            e.conflict
        ))
    } else if ratio >= params.max_runner_up_ratio {
        Some(format!(
            "ambiguous: a clearly different pose scores {:.0} % of the best",
            100.0 * ratio
        ))
    } else if confidence < params.min_confidence {
        Some(format!("confidence {confidence:.2} is too low"))
    } else if window.is_none() && off_walls() < params.min_off_two_walls {
        Some(format!(
            "only two walls agree: {:.0} % of the agreeing structure lies off them (at least {:.0} % needed); any corner of a rectangular room fits that as well",
            100.0 * off_walls(),
            100.0 * params.min_off_two_walls
        ))
    } else if let (current, Some(imprecision)) = precise() {
        let (pose, c, how) = match imprecision {
            Imprecision::AsClose(pose, c) => (pose, c, "about as closely"),
            Imprecision::CloserOutOfReach(pose, c) => (
                pose,
                c,
                "more closely, too far from the verified best to take",
            ),
        };
        Some(format!(
            "imprecise: a pose {:.2} m and {:.1} deg away lays the surfaces on each other {how} ({:.1} standard errors worse over {} points)",
            pose.transform_point(evidence.overlap_centre)
                .distance_m(current.transform_point(evidence.overlap_centre)),
            normalize_angle_rad(pose.yaw_rad - current.yaw_rad)
                .to_degrees()
                .abs(),
            c.z,
            c.common
        ))
    } else {
        None
    };
    let imprecise_rival = match (&refusal, precise_cell.get()) {
        (
            Some(_),
            Some((_, Some(Imprecision::AsClose(p, _) | Imprecision::CloserOutOfReach(p, _)))),
        ) => Some(to_frames(p)),
        _ => None,
    };
    Estimate {
        a_from_b: Some(to_frames(
            &precise_cell.get().map_or(settled_pose, |(pose, _)| *pose),
        )),
        confidence,
        evidence,
        runner_up_score,
        sharpness,
        off_two_walls: off_walls_cell.get().copied().unwrap_or(0.0),
        refusal,
        stats,
        hypotheses,
        verified: verified.iter().map(|(p, e)| (to_frames(p), *e)).collect(),
        imprecise_rival,
    }
}

/// How far (as a multiple of the reach, [`within_reach`]) a restart that fits more closely
/// by `c` may take the pose.
fn reach_for(c: &fine::Comparison) -> f64 {
    if c.z <= FINE_MUCH_BETTER_Z {
        FINE_MUCH_BETTER_REACH
    } else {
        1.0
    }
}

/// Whether grid-local `p` lies within `scale` times the sub-cell steps' reach of the
/// verified best: the overlap's centre moved at most `reach_m` ([`Params::fine_reach_m`]),
/// and turned at most [`FINE_MAX_TURN_RAD`] or as much as moves the overlap's edge that far.
fn within_reach(p: &Pose2, best: &Pose2, evidence: &Evidence, reach_m: f64, scale: f64) -> bool {
    let c = evidence.overlap_centre;
    let max_turn_rad =
        scale * (reach_m / evidence.overlap_radius_m.max(1.0)).min(FINE_MAX_TURN_RAD);
    p.transform_point(c).distance_m(best.transform_point(c)) <= scale * reach_m
        && normalize_angle_rad(p.yaw_rad - best.yaw_rad).abs() <= max_turn_rad
}

/// The verified best (grid-local) settled on the maps' own surfaces ([`fine::align`]), with
/// the overlap the fit used: the fit is kept only where it pairs enough points, stays within
/// reach ([`within_reach`]) and lays the surfaces on each other clearly more closely; along a
/// direction nothing pins, a fit drifts on noise.
fn settle_on_surfaces(
    a: &Prepared,
    b: &Prepared,
    best: &Pose2,
    evidence: &Evidence,
    params: &Params,
) -> (fine::Overlap, Pose2) {
    let overlap = fine::Overlap::at(&a.fine, &b.fine, best, FINE_MARGIN_M);
    let fit = fine::align(&a.fine, &b.fine, &overlap, *best);
    let settled = fit.pairs >= FINE_MIN_PAIRS
        && within_reach(&fit.pose, best, evidence, params.fine_reach_m, 1.0)
        && fine::compare(&a.fine, &b.fine, &overlap, best, &fit.pose).z <= FINE_BETTER_Z;
    (overlap, if settled { fit.pose } else { *best })
}

/// Why a pose is not precise on the surfaces.
#[derive(Clone, Copy, Debug)]
enum Imprecision {
    /// Another pose fits about as closely.
    AsClose(Pose2, fine::Comparison),
    /// Another pose fits clearly more closely, but lies beyond reach of the verified best
    /// (or the pose has already been replaced [`FINE_MAX_HOPS`] times).
    CloserOutOfReach(Pose2, fine::Comparison),
}

/// Where the maps' long walls lie parallel within [`Params::wall_pin_rad`] at `settled`
/// ([`crate::lines`]): the pose turned to lay them exactly parallel, about the overlap's
/// centre or either of its ends (whichever keeps the most verified score), and refitted on
/// the surfaces at that heading, with its overlap and verified evidence. `None` where the
/// walls say nothing, or where their heading keeps less than [`WALL_HELD_SCORE_SHARE`] of
/// the verified score: walls that are not the same or parallel ones in the hall.
fn held_by_walls(
    a: &Prepared,
    b: &Prepared,
    settled: &Pose2,
    evidence: &Evidence,
    params: &Params,
) -> Option<(fine::Overlap, Pose2, Evidence)> {
    if params.wall_pin_rad <= 0.0 {
        return None;
    }
    let turn = crate::lines::turn_to_parallel_rad(
        &a.walls,
        &b.walls,
        settled.yaw_rad,
        params.wall_pin_rad,
    )?;
    // Turned about the overlap's centre or either end, whichever keeps the most: what pins
    // the position may lie at one end of a band.
    let (overlap, pose, held) = [
        evidence.overlap_centre,
        evidence.overlap_ends[0],
        evidence.overlap_ends[1],
    ]
    .into_iter()
    .map(|pivot| {
        let turned = verify::turned_about(settled, pivot, turn);
        let overlap = fine::Overlap::at(&a.fine, &b.fine, &turned, FINE_MARGIN_M);
        let fit = fine::align_at_heading(&a.fine, &b.fine, &overlap, turned);
        let pose = if fit.pairs >= FINE_MIN_PAIRS
            && within_reach(&fit.pose, &turned, evidence, params.fine_reach_m, 1.0)
        {
            fit.pose
        } else {
            turned
        };
        let held = verify::verify(a, b, &pose, params.conflict_weight, On::Refine);
        (overlap, pose, held)
    })
    .max_by(|x, y| x.2.score.total_cmp(&y.2.score))?;
    (held.score >= WALL_HELD_SCORE_SHARE * evidence.score).then_some((overlap, pose, held))
}

/// The precision check on the surfaces ([`fine::nearby`]) from the settled pose: a restart
/// that fits clearly more closely, within reach, takes its place (at most
/// [`FINE_MAX_HOPS`] times); the pose it ends at, and why it is imprecise if it is. With
/// `heading_held` the restarts keep the heading.
#[allow(clippy::too_many_arguments)]
fn precision_on_surfaces(
    a: &Prepared,
    b: &Prepared,
    overlap: &fine::Overlap,
    settled: Pose2,
    best: &Pose2,
    evidence: &Evidence,
    params: &Params,
    heading_held: bool,
) -> (Pose2, Option<Imprecision>) {
    if !params.check_precision {
        return (settled, None);
    }
    let (mut pose, mut hops) = (settled, 0);
    loop {
        match fine::nearby(
            &a.fine,
            &b.fine,
            overlap,
            &pose,
            evidence.overlap_centre,
            evidence.overlap_ends,
            &params.precision,
            heading_held,
        ) {
            fine::Nearby::Alone => return (pose, None),
            fine::Nearby::Better(p, c)
                if hops < FINE_MAX_HOPS
                    && within_reach(&p, best, evidence, params.fine_reach_m, reach_for(&c)) =>
            {
                (pose, hops) = (p, hops + 1);
            }
            fine::Nearby::Better(p, c) => {
                return (pose, Some(Imprecision::CloserOutOfReach(p, c)));
            }
            fine::Nearby::Rival(p, c) => return (pose, Some(Imprecision::AsClose(p, c))),
        }
    }
}

/// `2n + 1` headings `step_rad` apart centred on `center_rad`.
fn yaws_around(center_rad: f64, n: i64, step_rad: f64) -> Vec<f64> {
    (-n..=n)
        .map(|k| normalize_angle_rad(center_rad + k as f64 * step_rad))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Evidence as verification reports it, with `agree` structure and `landmarks` landmark
    /// points agreeing and nothing conflicting.
    fn evidence(agree: usize, landmarks: usize) -> Evidence {
        Evidence {
            agree,
            score: agree as f64,
            landmark_agree: landmarks,
            ..Evidence::default()
        }
    }

    #[test]
    fn a_pose_lining_up_walls_but_not_the_rocks_is_no_rival() {
        // From the lunar arena at 10 % overlap (`bench merge --verbose`, seed 1, pair 16):
        // the true pose brings 58 landmark points together, a quarter-turn along the walls
        // 20, with more wall agreeing.
        let params = Params::default();
        let best = evidence(823, 58);
        assert!(!is_rival(&evidence(1493, 20), &best, &params));
        // The same pose bringing as many rocks together is one.
        assert!(is_rival(&evidence(1493, 40), &best, &params));
        // Where the best has no landmarks, structure alone decides, as before.
        assert!(is_rival(&evidence(900, 0), &evidence(823, 0), &params));
        assert!(!is_rival(&evidence(100, 0), &evidence(823, 0), &params));
        // Pair 13 (seed 1): a quarter-turn bringing 27 of the true pose's 51 rock points
        // together, but with ten times its conflicts: 96.8 % agreement against 99.2 %.
        let with_conflicts = |agree: usize, conflict: usize, landmarks: usize| Evidence {
            conflict,
            score: agree as f64 - params.conflict_weight * conflict as f64,
            ..evidence(agree, landmarks)
        };
        let truth = with_conflicts(947, 8, 51);
        assert!(!is_rival(&with_conflicts(2465, 80, 27), &truth, &params));
        // As consistent as the truth, it would be one.
        assert!(is_rival(&with_conflicts(2465, 20, 27), &truth, &params));
    }

    #[test]
    fn the_pose_that_explains_the_other_is_taken_over_a_higher_score() {
        // Pair 16's numbers again, sorted by score as verification leaves them: the
        // quarter-turn first. The true pose explains it (it would be a rival to it) while
        // it leaves most of the true pose's rocks apart: the true pose is taken.
        let params = Params::default();
        let centre = Point2::new(5.0, 5.0);
        let quarter = (Pose2::new(20.0, 3.0, 1.57), evidence(1493, 20));
        let truth = (Pose2::new(0.0, 0.0, 0.0), evidence(823, 58));
        assert!(dominated(&quarter.1, &truth.1, &params));
        assert_eq!(choose_best(&[quarter, truth], centre, &params), 1);
        // A quarter-turn with as many rocks is no lesser explanation: the top score stays
        // (and the estimate then refuses it as ambiguous).
        let rocky_quarter = (quarter.0, evidence(1493, 50));
        assert_eq!(choose_best(&[rocky_quarter, truth], centre, &params), 0);
        // The top pose landing rocks on open ground is passed over for the next consistent.
        let contradicted = (
            quarter.0,
            Evidence {
                landmark_conflict: 20,
                ..evidence(5064, 0)
            },
        );
        assert_eq!(choose_best(&[contradicted, truth], centre, &params), 1);
        // Nothing consistent: the top score stays, to be refused with its reason.
        assert_eq!(choose_best(&[contradicted], centre, &params), 0);
    }
}
