//! The full 2D SLAM (what `realms slam` runs): local tracking against submaps, keyframes in a
//! pose graph, and loop closures against finished submaps (the structure of Cartographer,
//! Hess et al., ICRA 2016, in miniature). The benchmark figures are in BENCHMARKS.md.
//!
//! - Each submap keeps its grid in the frame of its first keyframe, so when the graph moves
//!   that keyframe the submap moves with it.
//! - Scans are tracked against the older of the (at most two) active submaps, from the
//!   odometry's prediction ([`crate::odometry`]: a stalled reading's jump is applied once).
//!   Where the prediction turns fast, the headings around it are searched first
//!   ([`FastTurn`]).
//! - A keyframe is added when the robot has moved enough; it is inserted into the active
//!   submaps and linked to the previous keyframe.
//! - Loop closure: every other keyframe is searched against the nearest finished submaps by
//!   branch and bound over a window of metres ([`crate::bnb`]), and refined by Gauss-Newton.
//!   A match becomes a closure only if it passes three checks, because a few false closures
//!   ruin a map: it scores high, it clearly beats every distinct pose in the window (corridors
//!   and look-alike rooms do not), and a second closure from a nearby keyframe asks for the
//!   same correction. With a [`ClosureDrift`] bound, the search reaches only as far as the
//!   map can have drifted along the path between the two places. Accepted closures enter the
//!   graph as robust edges and the graph is re-optimised.

use crate::assembly::Assembly;
use crate::bnb::{self, PrecomputedMap, SearchWindow};
use crate::carmen::LaserReading;
use crate::drift::{PathsFromStart, PoseUncertainty, Travel};
use crate::frontend::FrontendConfig;
use crate::health::{HealthConfig, HealthMonitor, LocalisationState, TrackedScan, Transition};
use crate::matcher::{MatcherConfig, MultiResMap, best_heading, match_scan};
use crate::ndt::{NdtConfig, NdtMap};
use crate::occupancy::{CellState, OccupancyGrid};
use crate::odometry::{OdomPredictor, OdomSample};
use crate::posegraph::{Edge, GraphSolver, HeadingPrior, PoseGraph, RobustLoss};
use crate::slip::{SlipCalibration, WheelScale};
use crate::trajectory::StampedPose;
use crate::walls::{WallHeadingConfig, WallHeadings};
use realms_core::geometry::normalize_angle_rad;
use realms_core::{Cell, Point2, Pose2};

/// How far a finished submap's keyframes may move, relative to its first, before it is
/// drawn again (see [`MapperConfig::redraw_bent_submaps`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubmapBend {
    /// Metres, any keyframe.
    pub translation_m: f64,
    /// Radians, any keyframe.
    pub rotation_rad: f64,
}

/// The final map redraws the submaps whose keyframes moved this far relative to their
/// first. On the default mission's 40-minute replay a limit of 2 cm and 0.4 degrees drew
/// 25 % fewer submaps than redrawing all, and graded the maps the same to 0.1 point
/// (BENCHMARKS.md, thirty-eighth session): most submaps bend that much.
const FINAL_REDRAW_BEND: SubmapBend = SubmapBend {
    translation_m: 0.02,
    rotation_rad: 0.4 * std::f64::consts::PI / 180.0,
};
/// Bent beyond this: every submap, bent or not.
const EVERY_SUBMAP: SubmapBend = SubmapBend {
    translation_m: -1.0,
    rotation_rad: -1.0,
};

/// A loop closure's information (x, y, heading) where its match pins the pose firmly.
pub const CLOSURE_INFORMATION: [f64; 3] = [400.0, 400.0, 2500.0];

/// Loop closures weighed by their own match: a scan that sees a bare wall pins the pose
/// across it but hardly along it, and a closure that slid along such a wall holds the graph
/// as firmly as one pinned every way when all weigh the same. Measured on seeds 1-8 (40
/// minutes, BENCHMARKS.md, thirty-eighth session): the accepted closures more than 0.1 m or
/// 1 degree off the truth had a median weakest match information of 630 against 3,700 for
/// the rest, and their error lay along that weakest direction. Covariance from the scan
/// match's curvature for graph edges, as in Olson's correlative matching (ICRA 2009) and
/// Karto. Weighed so, the same replays' average error and maps stayed where they were, and
/// refusing the weak closures outright lost maps: the rovers keep every closure at
/// [`CLOSURE_INFORMATION`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosureWeighting {
    /// Along each direction where the refined match's translation information falls below
    /// this, the closure's falls in proportion from [`CLOSURE_INFORMATION`].
    pub translation_reference: f64,
    /// The same for the heading, if set.
    pub heading_reference: Option<f64>,
}

/// A closure search whose winner has rivals within the ambiguity margin all lying on a
/// ridge of high scores from it (see [`crate::bnb::search_allowing_ridges`]) is no look-alike
/// place: the scan pins the pose across the ridge and along it only as the scores fall. Near
/// the lander, where the lidar sees the lander's north face and the south wall and little
/// across them, every closure search was refused so, for a minute at a time, while the
/// tracked pose slid 0.7 m across the rover's travel (BENCHMARKS.md, "Closures along a
/// ridge of the score"). Over sixteen seeds' replays, though, the closures it let in were
/// wrong more than twice as often and the maps came out worse (91.4 -> 84.8 % of occupied
/// cells right; 89.7 % held across the ridge only): off for the rovers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosureRidges {
    /// The scores on the way from the winner to its rival may fall this far below the
    /// rival's and it still lies on the winner's ridge.
    pub dip: f64,
    /// Along the ridge, the closure's information is [`CLOSURE_INFORMATION`]'s as far as the
    /// scores fall to the rival: its full share for a fall of the ambiguity margin over
    /// this distance, less in proportion to the fall and to the square of the distance
    /// (the score's curvature), metres.
    pub reference_m: f64,
}

impl Default for ClosureRidges {
    fn default() -> Self {
        ClosureRidges {
            dip: 0.02,
            reference_m: 0.3,
        }
    }
}

impl ClosureRidges {
    /// The information of a closure measured at `measured` (in the submap's frame) whose
    /// search found `ridge`, the ambiguity margin being `margin`, and the turn of its axes
    /// (see [`Edge::information_axis_rad`]): [`CLOSURE_INFORMATION`] across the ridge and in
    /// heading, less along it.
    fn information(
        &self,
        ridge: &crate::bnb::Ridge,
        margin: f64,
        measured: Pose2,
    ) -> ([f64; 3], f64) {
        let curvature =
            (ridge.drop / margin.max(1e-9)) * (self.reference_m / ridge.rival_m.max(1e-9)).powi(2);
        let [full, across, heading] = CLOSURE_INFORMATION;
        (
            [full * curvature.clamp(0.0, 1.0), across, heading],
            normalize_angle_rad(ridge.direction_rad - measured.yaw_rad),
        )
    }
}

/// A closure's information and the turn of its x and y axes from the measured pose's (see
/// [`Edge::information_axis_rad`]), from its match `m`.
fn closure_information(
    m: &crate::matcher::Match,
    weighting: Option<ClosureWeighting>,
) -> ([f64; 3], f64) {
    let Some(w) = weighting else {
        return (CLOSURE_INFORMATION, 0.0);
    };
    let i = &m.information;
    let (weakest, strongest, (ux, uy)) = crate::ndt::eigen_symmetric2(i[0][0], i[0][1], i[1][1]);
    let share = |lambda: f64, reference: f64| (lambda / reference).clamp(0.0, 1.0);
    let [x, _, heading] = CLOSURE_INFORMATION;
    let heading = w
        .heading_reference
        .map_or(heading, |r| heading * share(i[2][2], r));
    // The weakest axis, in the submap's frame, turned into the measured pose's frame, in
    // which the graph takes the residual.
    let axis = uy.atan2(ux) - m.pose.yaw_rad;
    (
        [
            x * share(weakest, w.translation_reference),
            x * share(strongest, w.translation_reference),
            heading,
        ],
        normalize_angle_rad(axis),
    )
}

/// A closure is confirmed by another found at most this many keyframes earlier...
const CONFIRM_WITHIN_KEYFRAMES: usize = 10;
/// ... that asks for the same correction within this distance ...
const CONFIRM_TRANSLATION_M: f64 = 0.15;
/// ... and this angle.
const CONFIRM_ROTATION_RAD: f64 = 0.035;
/// At most this many of a keyframe's points take part in the closure search.
const LOOP_POINTS: usize = 200;
/// Closure search: rotation steps move a point this far away by about one cell, metres.
const LOOP_STEP_RANGE_M: f64 = 10.0;
/// Closure search: branch and bound over blocks up to 2^depth cells.
const LOOP_DEPTH: usize = 6;

/// Every `n`-th point, so that at most `max` remain.
fn subsample(points: &[Point2], max: usize) -> Vec<Point2> {
    let step = points.len().div_ceil(max.max(1)).max(1);
    points.iter().step_by(step).copied().collect()
}

/// The slip check's own match ([`MapperConfig::slip_check_own_match`]) is made only where its
/// last one lies at least this far from the pose, metres (nearer, the tracking match is as
/// good)...
const OWN_MATCH_MIN_OFFSET_M: f64 = 0.002;
/// ... and less than this (farther, it has lost the map and starts again from the pose).
const OWN_MATCH_MAX_OFFSET_M: f64 = 0.5;

/// The weakest direction of a match's translation `information` once the matcher's own pull
/// `prior_weight` towards the prediction is taken out: how firmly the map pins it (per square
/// metre) and its unit vector.
fn weakest_direction(information: &[[f64; 3]; 3], prior_weight: f64) -> (f64, (f64, f64)) {
    let (weakest, _, axis) = crate::ndt::eigen_symmetric2(
        information[0][0] - prior_weight,
        information[0][1],
        information[1][1] - prior_weight,
    );
    (weakest, axis)
}

/// `matched` moved towards `predicted` along the direction in which the match's translation
/// `information` (which holds the matcher's own pull `prior_weight` towards the prediction)
/// is weakest, as far as adding the information the map lacks below `floor` there would
/// move it; unchanged where the map pins both directions at least that firmly, or where
/// the match lies more than `gate_m` from the prediction along that direction (slipping
/// wheels run away from the map faster than its weak pull strays).
fn towards_prediction_where_weak(
    matched: Pose2,
    predicted: Pose2,
    information: &[[f64; 3]; 3],
    prior_weight: f64,
    floor: f64,
    gate_m: f64,
) -> Pose2 {
    let (weakest, (ux, uy)) = weakest_direction(information, prior_weight);
    if weakest >= floor {
        return matched;
    }
    let along = (predicted.x_m - matched.x_m) * ux + (predicted.y_m - matched.y_m) * uy;
    if along.abs() > gate_m {
        return matched;
    }
    let added = floor - weakest;
    let share = added / (weakest + prior_weight + added);
    Pose2::new(
        matched.x_m + share * along * ux,
        matched.y_m + share * along * uy,
        matched.yaw_rad,
    )
}

/// `matched` with the matcher's own pull towards the prediction `predicted` taken back along
/// the heading: the map's verdict on the travel, as the slip check needs it. A match whose
/// map pins the travel `r` times as firmly as the matcher's prior (`prior_weight`, held in
/// `information`) lands a share `1 / (r + 1)` of the way from the map's answer towards the
/// prediction; slipping wheels pull it that far towards their over-report. `r` is taken as
/// at least 1, so a weak match's noise is never amplified more than twice.
fn without_prior_along_heading(
    matched: Pose2,
    predicted: Pose2,
    information: &[[f64; 3]; 3],
    prior_weight: f64,
) -> Pose2 {
    if prior_weight <= 0.0 {
        return matched;
    }
    let (s, c) = matched.yaw_rad.sin_cos();
    let along = crate::slip::map_information_along(information, prior_weight, matched.yaw_rad);
    let ratio = (along / prior_weight).max(1.0);
    let off = ((matched.x_m - predicted.x_m) * c + (matched.y_m - predicted.y_m) * s) / ratio;
    Pose2::new(
        matched.x_m + off * c,
        matched.y_m + off * s,
        matched.yaw_rad,
    )
}

/// `refined` with no part of its move from `matched` along the direction the occupancy
/// match's `information` pins less firmly than `floor` (the matcher's prior `prior_weight`
/// taken out): the refinement removes the grid's pull towards cell centres across what the
/// scan sees, and has nothing to add along a bare wall.
fn refined_only_where_pinned(
    matched: Pose2,
    refined: Pose2,
    information: &[[f64; 3]; 3],
    prior_weight: f64,
    floor: f64,
) -> Pose2 {
    let (weakest, (ux, uy)) = weakest_direction(information, prior_weight);
    if weakest >= floor {
        return refined;
    }
    let along = (refined.x_m - matched.x_m) * ux + (refined.y_m - matched.y_m) * uy;
    Pose2::new(
        refined.x_m - along * ux,
        refined.y_m - along * uy,
        refined.yaw_rad,
    )
}

/// See [`MapperConfig::push_ahead_where_weak`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PushAheadWhereWeak {
    /// Map information along the heading, as a multiple of the matcher's prior.
    pub min_ratio: f64,
    /// How far ahead a refinement may still move the match there, metres.
    pub max_ahead_m: f64,
}

impl PushAheadWhereWeak {
    /// `refined`, or `matched` where the occupancy match's `information` (the matcher's pull
    /// `prior_weight` held in it) pins the travel weakly and the refinement moves the match
    /// too far along the wheels' travel from `wheels[0]` to `wheels[1]`.
    fn bound(
        &self,
        matched: Pose2,
        refined: Pose2,
        wheels: [Point2; 2],
        information: &[[f64; 3]; 3],
        prior_weight: f64,
    ) -> Pose2 {
        let weak = crate::slip::map_information_along(information, prior_weight, matched.yaw_rad)
            < self.min_ratio * prior_weight;
        let ahead_m = -crate::ndt::held_back_m(wheels[0], wheels[1], matched, refined);
        if weak && ahead_m > self.max_ahead_m {
            matched
        } else {
            refined
        }
    }
}

/// SLAM tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapperConfig {
    /// Tracking (matcher, map resolution, range limits).
    pub frontend: FrontendConfig,
    /// A new keyframe after this much travel, metres.
    pub keyframe_translation_m: f64,
    /// ... or this much turning, radians.
    pub keyframe_rotation_rad: f64,
    /// Keyframes per submap.
    pub submap_keyframes: usize,
    /// Loop closures are searched at every this many keyframes.
    pub loop_every_keyframes: usize,
    /// Finished submaps within this distance are searched for closures, metres ...
    pub loop_search_radius_m: f64,
    /// ... measured to the submap's nearest keyframe (`true`) or to its first (`false`). A
    /// submap spans several metres of path, and one passing a metre away may have begun
    /// farther off than the radius: ACES's last loop stayed open that way (BENCHMARKS.md,
    /// twenty-ninth session).
    pub loop_search_nearest_keyframe: bool,
    /// Half-width of the translation window of the closure search, metres.
    pub loop_window_m: f64,
    /// Half-width of the rotation window of the closure search, radians.
    pub loop_window_rad: f64,
    /// A closure is accepted only at or above this mean occupancy at the scan's endpoints.
    pub loop_min_score: f64,
    /// The search keeps poses scoring at least this (nearest-cell mean occupancy).
    pub loop_search_min_score: f64,
    /// The winner must beat any clearly different pose by this much mean occupancy.
    pub loop_ambiguity_margin: f64,
    /// Nearest finished submaps searched per attempt.
    pub loop_candidates: usize,
    /// When to call the estimate unreliable or lost.
    pub health: HealthConfig,
    /// The slip check hears each match with the matcher's pull towards the wheels'
    /// prediction taken back along the heading (`without_prior_along_heading`): where the
    /// map pins the travel only a few times as firmly as that pull, slipping wheels drag the
    /// match a quarter or more of the way towards their over-report. Off by default: it was
    /// measured on the rovers only, not on the recorded logs.
    pub slip_check_without_prior: bool,
    /// The slip check hears each match's motion from the previous match (as it was before
    /// any pull towards the prediction), not from the previous pose: where the pose is
    /// pulled off the match (see [`MapperConfig::weak_direction_floor`]), the map's steady
    /// disagreement with it would otherwise read as motion the wheels did not report, at
    /// every scan. Without that pull the two are the same.
    pub slip_check_match_to_match: bool,
    /// ... and that match is the check's own: started from its last one carried on by the
    /// wheels, not from the pose, wherever the two lie apart (a second match per scan).
    /// Only with [`MapperConfig::slip_check_match_to_match`], whose chain it is.
    pub slip_check_own_match: bool,
    /// A closure into a submap begun at the known start (among the first
    /// `submap_keyframes` keyframes) counts a pose as the winner's rival only this far from
    /// it or more (`None`: 30 cm, as any other closure). Near the lander the score falls
    /// slowly for some decimetres round the right pose, and the rover coming home at the
    /// end found its start ambiguous every time.
    pub start_rivals_beyond_m: Option<f64>,
    /// ... and only while the rover drives home at the end of its exploring, or is home
    /// ([`Mapper::set_homing`]): the closure that ties the end of the trajectory to the
    /// start, never one that steers the tracking mid-mission.
    pub start_rivals_homing_only: bool,
    /// A finished submap whose origin lies this close to a newer finished one's is dropped
    /// (`None`: keep every submap, as for a recorded log).
    pub trim_radius_m: Option<f64>,
    /// Motion filter: a scan is matched only once odometry has moved this far since the last
    /// matched scan (`None`: match every scan).
    pub motion_filter: Option<MotionFilter>,
    /// Scans with fewer endpoints than this are neither matched nor mapped (10 by default
    /// and on the rovers). Far from the walls a 12 m lidar may see one or two rocks and
    /// nothing else, which still pin the position; 6 caught more slip bursts but left whole
    /// missions' maps worse (BENCHMARKS.md, forty-fifth session), so it was not kept.
    pub min_scan_points: usize,
    /// With a gyro: a match that turns the pose more than this away from the odometry's
    /// heading is redone with the heading held to the odometry's (`None`: trust the match;
    /// right for wheel-only headings such as the recorded logs'), radians.
    pub max_heading_step_rad: Option<f64>,
    /// With a gyro ([`gyro_heading`](Self::gyro_heading)): a match whose heading has strayed
    /// from the gyro's since the pose was last set (by an optimisation, a relocalisation or
    /// the first scan) by more than this plus three standard deviations of the gyro's own
    /// drift is redone with the heading held to the gyro's. Small steps that each pass
    /// `max_heading_step_rad` can add up to degrees (`None`: no such check), radians.
    pub heading_anchor_rad: Option<f64>,
    /// With a gyro: a match whose heading has turned, within the window's span, more than
    /// its bound away from the gyro's turn is redone with the heading held at that bound
    /// (`None`: no such check). Each step under `max_heading_step_rad` passes, but steps
    /// of half a degree to a degree, four in a row, are a match walking off on a few rocks,
    /// not the gyro's error, which over a second is a few hundredths of a degree.
    pub heading_window: Option<HeadingWindow>,
    /// With a gyro: where the tracked heading swings away from the gyro's within a few
    /// seconds by more than the gyro can drift, the published position uncertainty grows by
    /// that swing times the straight-line distance from where it began, and the heading's
    /// by the swing, until the pose is next set (`None`: not watched). Only what the rover
    /// says of its pose: the pose itself is left as the match has it (the heading window,
    /// which holds it, moved every rover's path and gained nothing over whole missions).
    pub heading_departure: Option<HeadingDeparture>,
    /// With a gyro: each matched scan's heading is the gyro's turn from the last pose, moved
    /// this share of the way towards the match's own heading, and the match is redone with
    /// the heading held there (a complementary filter: the gyro carries the turns, the map
    /// takes out its slow drift; `None`: the match's heading, within `max_heading_step_rad`).
    /// Over a scan the gyro's turn is good to a few hundredths of a degree; a match on a few
    /// rocks far from the walls under-turned by a degree a second in a turn (BENCHMARKS.md,
    /// "The gyro carries the turns"). The gyro's leftover bias is not estimated: the share
    /// treats each scan's gyro error as independent, so the heading follows that bias, and
    /// in whole missions the maps came out worse. Applied after `max_heading_step_rad` and
    /// `heading_anchor_rad`, whose held headings it then starts from.
    pub heading_map_share: Option<f64>,
    /// `heading_map_share` only for scans in which no wall measures the heading (see
    /// [`crate::walls`]): beside the walls the match's heading is firmer than the share
    /// lets it be, far from them the gyro's is (BENCHMARKS.md, "The gyro carries the turns
    /// where no wall holds the heading").
    pub heading_map_share_without_walls: bool,
    /// Where the wheels report no travel over a scan (a rover turning in place), the match
    /// is held to the position the wheels predict (see [`StillHold`]; `None`: the usual
    /// pull, right for odometry that stalls, as the recorded logs' does).
    pub still_hold: Option<StillHold>,
    /// Where the map pins the match's position less firmly than this in some direction (per
    /// point, per square metre, the matcher's own prior left out), the position along that
    /// direction is pulled towards the prediction as if the map's information there were
    /// this much (`None`: the matcher's prior alone). Beside a bare wall the map's pull along
    /// it comes from how its hits were sampled, not from the wall (BENCHMARKS.md, "A rover's
    /// drift along a bare wall").
    pub weak_direction_floor: Option<f64>,
    /// ... but only where the match lies within this distance of the prediction along that
    /// direction, metres (`None`: at any distance).
    pub weak_direction_gate_m: Option<f64>,
    /// When the odometry is reported unreliable, the pose is moved back by what the wheels
    /// carried it beyond the slip check's matches over the check's window: the scans that
    /// raised the alarm already followed the slipping wheels for a second or so.
    pub unreliable_rewind: bool,
    /// While the odometry is reported unreliable, the matcher pulls towards the wheels'
    /// prediction with this share of its usual weight (`None`: the usual weight).
    pub unreliable_pull_share: Option<f64>,
    /// While the wheels' turns and the gyro's disagree ([`HealthConfig::turn_check`]), the
    /// wheels' travel is scaled by the share of their turn the gyro saw before it predicts
    /// the next match: wheels that spin without grip lose as much of their travel as of
    /// their turn, and the gyro measures the turn's loss whatever the lidar sees.
    pub turn_scaled_travel: bool,
    /// The refinement on the hits moves the match only along directions the occupancy match
    /// pins at least this firmly (per point, per square metre, its prior left out; `None`:
    /// along any). Its cells of a few hits along a wall can lie across it and pull the
    /// match back along the wall at every scan (BENCHMARKS.md, "A rover's drift along a bare
    /// wall").
    pub refine_only_where_pinned: Option<f64>,
    /// Where the occupancy match pins the travel less than `min_ratio` times as firmly as
    /// the matcher's own pull towards the wheels, a refinement moving the match more than
    /// `max_ahead_m` further along the wheels' travel is not taken (`None`: bounded only by
    /// the refinement's own limits). Along a bare wall the refinement's own bounds pass its
    /// forward pulls and stop its backward ones (BENCHMARKS.md, "A refinement that runs
    /// ahead of the wheels").
    pub push_ahead_where_weak: Option<PushAheadWhereWeak>,
    /// A cell of the live map ([`Mapper::map_states`], what a rover publishes) counts as
    /// occupied once the log-odds of the submaps holding it sum to more than this (0.5: as
    /// in a submap). A keyframe goes into each active submap (two, mostly), so a cell one
    /// hit of one keyframe sums to about 1.7. [`Mapper::render_map`] keeps the log-odds and
    /// leaves the threshold to its reader.
    pub map_occupied_above: f32,
    /// The final map (see [`Mapper::redraw_finished_submaps`]) draws every finished submap
    /// again with a keyframe's hits only out to this range, and free space out to it beyond
    /// (`None`: every hit, and only the submaps the graph bent). A heading a fraction of a
    /// degree off moves a wall 10 m away by 10 cm, where later scans' misses may never
    /// clear it (BENCHMARKS.md, "Why a trajectory can improve while its map worsens").
    pub final_map_hit_range_m: Option<f64>,
    /// A closure may correct the pose only as far as the map can have drifted between the
    /// two places it joins, and is searched only that far (`None`: any correction the
    /// search window allows).
    pub closure_drift: Option<ClosureDrift>,
    /// Closures across travel the scans did not pin are searched wider and may correct more
    /// (see [`WeakTravel`]; `None`: the path's drift alone). Needs `closure_drift`.
    pub weak_travel: Option<WeakTravel>,
    /// A keyframe hop over travel the scans did not pin along the heading ([`WeakTravel`])
    /// holds the graph along the heading only as firmly as the wheels can carry it: its
    /// sequential edge's standard deviation there grows by this share of that travel. A
    /// later closure can then bend a stretch that slid along a wall back into place, where
    /// an edge as stiff as a pinned one makes the closure the outlier (`None`: every
    /// sequential edge as stiff as a pinned one). Needs `weak_travel`.
    pub weak_hop_share: Option<f64>,
    /// Scale the wheels' translation by the share the scan matches found real (`None`: take
    /// the wheels at their word, as for a recorded log's calibrated odometry).
    pub slip_calibration: Option<SlipCalibration>,
    /// How far the pose may be from the truth, for the covariance a rover publishes, from
    /// the path through the graph that ties it to the start ([`crate::drift`]; `None`: not
    /// worked out).
    pub pose_uncertainty: Option<PoseUncertainty>,
    /// The odometry's heading is a gyro's: the graph edge between consecutive keyframes
    /// takes its turn from the odometry, weighted by this model of the gyro's error (`None`:
    /// the turn as matched, weighted like a closure; right for wheel-only headings).
    pub gyro_heading: Option<GyroHeading>,
    /// Wheel travel with nothing to match against (too few returns) counts as wholly
    /// uncertain: the graph edge across it is loosened by its length, and a closure may
    /// correct the pose by up to all of it (`false`: such travel counts as matched travel).
    pub blind_travel_uncertain: bool,
    /// How the pose graph's linear systems are solved.
    pub graph_solver: GraphSolver,
    /// The robust loss on loop closures in the pose graph.
    pub graph_loss: RobustLoss,
    /// After an optimisation, the keyframes of the submaps still being built keep their
    /// poses relative to each other (the geometry their cells were drawn with) and move as
    /// one block with the oldest of them, so tracking resumes in cells that agree with its
    /// pose (Cartographer's split of local and global SLAM); otherwise they take their
    /// optimised poses.
    pub track_in_submap_frame: bool,
    /// Where the prediction turns fast, also search the headings around it before the
    /// local match (see [`FastTurn`]); `None`: the local match alone. For wheel-only
    /// headings: with a gyro, `max_heading_step_rad` holds the heading instead, and would
    /// redo a searched match.
    pub fast_turn: Option<FastTurn>,
    /// Where the wheels stop turning while the scans were turning, also match from the
    /// heading the scans' turn carries on to (see [`StallTurn`]); `None`: the wheels'
    /// prediction alone. For wheel-only headings: a gyro does not stall with the wheels.
    pub stall_turn: Option<StallTurn>,
    /// Refine each tracking match on the tracking submap's hits themselves, per-cell means
    /// and spreads, free of the occupancy grid's pull towards cell centres (see
    /// [`crate::ndt`]; the refinement is bounded, also in how far it may move the match back
    /// against the wheels' travel); `None`: the occupancy match as it is.
    pub ndt_refine: Option<NdtConfig>,
    /// Accepted closures are folded into the graph at every this many keyframes ...
    pub optimize_every_keyframes: usize,
    /// Submaps whose closure-search precomputation is kept at once: the submaps searched
    /// last. Each holds seven levels of a byte a cell over the submap and the search
    /// window's margin, some 5 MB for a submap of a rover's reach, and kept for every
    /// submap ever searched they grew with the mission (a rover's 70 MB of the default
    /// mission's 1.65 GB). A submap searched again after it was dropped is precomputed
    /// again (under a millisecond), to the same answers. A finished submap is kept whole
    /// while its precomputation is, and cut to its content
    /// ([`crate::occupancy::OccupancyGrid::cut_to_content`]) once it is dropped or, if never
    /// searched, once the next submap finishes. Eight, not 24: a rover's searches stay
    /// among the submaps near it, and over a 30-minute mission the fleet precomputed 248
    /// times instead of 219 (BENCHMARKS.md, "A rover's memory bounded by what it maps").
    pub precomputed_kept: usize,
    /// Beams that returned nothing ([`Mapper::set_clear_rays`]) clear only the published
    /// grids (each submap then keeps one beside its matching grid, and the live map sums
    /// them), not the grids scans are matched against. In the open middle of a hall the
    /// rays clear a matching grid all round a lone rock, and a scan that lands a little off
    /// it then scores as a poor fit where unknown ground would score half: a rover 0.15 m
    /// off reported itself lost there (BENCHMARKS.md, "Lidar beams that return nothing over
    /// 48 missions").
    pub clear_rays_published_only: bool,
    /// Each keyframe is traced into a submap's matching grid and the grid its published map
    /// is drawn from by walks of their own, not by one walk along each beam
    /// marking both ([`OccupancyGrid::insert_with_rays_beside`]). The shared walk runs to
    /// where the matching beam stops and on from there, so the published beam bends by up
    /// to a cell there; the matching grid is the same either way. Kept to measure what the
    /// sharing saves.
    pub grids_traced_apart: bool,
    /// Beams that returned nothing are drawn only from keyframes at least this far (metres)
    /// from the last keyframe whose rays were (`None`: from every keyframe). Two in three
    /// keyframes are made for turning on the spot, and each would clear the same ground
    /// round the rover again; the rays cost a fifth of the fleet's SLAM drawn from every
    /// one (BENCHMARKS.md, "Lidar beams that return nothing over 48 missions").
    pub clear_rays_spacing_m: Option<f64>,
    /// ... by this many Gauss-Newton steps ...
    pub graph_iterations: usize,
    /// ... the iterative solvers' steps after the first stopped after this many
    /// iterations (`None`: as the first).
    pub graph_later_cap: Option<usize>,
    /// Loop closures weighed by what their match pins (see [`ClosureWeighting`]); `None`:
    /// every closure weighs [`CLOSURE_INFORMATION`].
    pub closure_weighting: Option<ClosureWeighting>,
    /// After each optimisation, finished submaps whose keyframes the graph moved this far
    /// relative to their first are drawn again from them (`None`: only when asked, see
    /// [`Mapper::redraw_finished_submaps`]). Closures are then searched against cells that
    /// agree with the graph.
    pub redraw_bent_submaps: Option<SubmapBend>,
    /// A loop closure joins the new keyframe to the submap's keyframe drawn nearest where it
    /// matched, measured from where that keyframe was drawn, not to the submap's first
    /// keyframe (`false`). A submap drawn while tracking drifted is bent: its far end sits
    /// off its first keyframe by the drift, and a closure measured from the first keyframe
    /// carries that bend into the graph at a closure's weight. Near the cells it matched,
    /// the submap agrees with the keyframe that drew them (Karto links a closure to the
    /// nearest scan of the chain it matched, for the same reason).
    pub closure_from_nearest_drawn: bool,
    /// Loop closures joining keyframes within this many of an accepted closure's two ends
    /// are weighed 1/2, 1/3, ... of it in turn (`None`: every closure weighs the same).
    /// Closures between the same two stretches of path match the same cells: where the map
    /// slid there, they are all wrong the same way, and counted as independent they outvote
    /// the path between.
    pub closure_share_span: Option<usize>,
    /// Long straight runs of a keyframe's scan along a direction the first keyframe's
    /// scan saw (from the start pose, known exactly) measure its heading absolutely, as a
    /// [`HeadingPrior`] in the graph ([`crate::walls`]; `None`: no such measurement). In a
    /// hall the maps' errors are mostly a slow turn of the whole map.
    pub wall_headings: Option<WallHeadingConfig>,
    /// A keyframe whose heading the walls measure more than this many of the measurement's
    /// standard deviations off the tracked heading has the graph optimised at the next
    /// batch ([`MapperConfig::optimize_every_keyframes`]) as a closure would, so the
    /// published pose turns back to the walls then rather than at the next closure
    /// (`None`: the walls' priors wait for a closure).
    pub optimize_on_wall_heading_sigmas: Option<f64>,
    /// Loop closures whose refined match pins the position less firmly than this in some
    /// direction (the smaller eigenvalue of the match's translation information) are not
    /// taken (`None`: no such floor). See [`ClosureWeighting`] for what the weak ones were.
    pub closure_min_information: Option<f64>,
    /// Loop closures whose only rivals lie on a ridge of high scores from the winner are
    /// taken, held loosely along the ridge ([`ClosureRidges`]; `None`: any rival within the
    /// ambiguity margin refuses the closure).
    pub closure_ridges: Option<ClosureRidges>,
    /// After an optimisation, loop closures the optimised graph still leaves this far off
    /// (squared Mahalanobis error) are dropped from it and the graph optimised again
    /// (`None`: every accepted closure stays).
    pub drop_closures_beyond: Option<f64>,
    /// A closure asking to move its keyframe farther than this, metres, is confirmed only by
    /// a partner into another submap (`None`: a partner into the same submap will do). A
    /// look-alike place in one submap fits every keyframe that sees it alike, so its false
    /// closures confirm each other (the lander's east face on its west face).
    pub distinct_confirmation_beyond_m: Option<f64>,
    /// A far correction whose hits reach the submap's walls from behind is refused
    /// ([`FacesSeenFrom`]; `None`: no such test).
    pub faces_seen_from: Option<FacesSeenFrom>,
    /// A keyframe of fewer hits than this searches for no closure (`None`: the search's own
    /// least, ten). On open floor a scan holds a few rocks, and its closures slide along
    /// whatever they leave loose.
    pub closure_min_points: Option<usize>,
}

/// A closure that lays one face of a block on the opposite face (the lander's west face on
/// its east face, 2.5 m along the south wall) scores and pins like a right one, and the
/// submaps begun beside the block confirm each other: each saw only the faces on its side.
/// But its beams reach the faces they land on through the block, over ground the submap
/// never saw open, where a right closure's reach them over the open ground they were seen
/// across. Over sixteen seeds' replays, a median of 2.5 % of a right closure's hits on walls
/// came from behind (99th percentile 36 %), 36-66 % of the lander's false ones
/// (BENCHMARKS.md, "Faces reached from behind"). A few right closures reach rocks seen
/// from their other side, so only corrections too far for the usual drift, with enough hits
/// on walls to hold a face (the lander's false ones had 36-198), are tested.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FacesSeenFrom {
    /// Closures asking to move their keyframe farther than this, metres, are tested ...
    pub beyond_m: f64,
    /// ... when at least this many of their hits land on walls ...
    pub min_hits: usize,
    /// ... and refused when more than this share of those come from behind.
    pub max_share: f64,
}

impl Default for FacesSeenFrom {
    fn default() -> Self {
        FacesSeenFrom {
            beyond_m: 0.5,
            min_hits: 30,
            max_share: 0.3,
        }
    }
}

/// Over a scan whose predicted turn exceeds `turn_rad`, the headings within
/// `search_rad` of the prediction are searched (every `step_rad`) for the scan's best fit
/// on the coarsest map, and the local match is run from there too. Its match is kept only
/// if it scores `margin` more than the match from the wheels' prediction: where both fit
/// poorly (a view half new after a fast turn), a slightly better fit elsewhere is as likely
/// chance as truth, and the wheels were right more often (BENCHMARKS.md, "Odometry that
/// stalls, fast turns, and closures searched as far as the path can have drifted").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastTurn {
    /// Predicted turn over one scan (from the last pose) beyond which the headings are
    /// searched, radians.
    pub turn_rad: f64,
    /// Half-width of the search, radians.
    pub search_rad: f64,
    /// Step of the search, radians.
    pub step_rad: f64,
    /// Mean occupancy by which the searched heading's match must beat the prediction's.
    pub margin: f64,
}

/// Beside a lone wall the scans pin the pose across the wall only, and a rover turning in
/// place was matched a few centimetres along it at every scan: 0.3 m in two seconds (the
/// default mission, seed 1, rover1 at 886 s). Where the wheels report less than
/// `below_m` of travel over a scan, the match's pull towards the predicted position is
/// `translation_weight` (per point, per square metre) instead of the matcher's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StillHold {
    /// Wheel travel over a scan under which the rover counts as not translating, metres.
    pub below_m: f64,
    /// The translation prior's weight then.
    pub translation_weight: f64,
    /// The heading is then held to the prediction's too, the odometry's turn (a gyro's,
    /// [`MapperConfig::gyro_heading`]): over a turn in place far from the walls a match on a
    /// few rocks under-turned by a degree a second (BENCHMARKS.md, "The gyro carries the
    /// turns"), while the gyro's turn is good to a few hundredths of a degree. Off for the
    /// rovers: their maps came out worse with it (BENCHMARKS.md, "The gyro's leftover bias
    /// measured out, and the gyro alone through turns in place").
    pub hold_heading: bool,
}

/// Odometry that stalls while the robot turns (the readings stop for most of a second, then
/// catch up), or whose turn ends a scan before the robot's, predicts no turn where the scans
/// were turning; matched from there, a scan follows only part of the turn and the heading
/// is left 10-15 degrees short (MIT CSAIL at 171 and 370 s, BENCHMARKS.md). When the
/// predicted turn is less than `stalled_share` of the last matched scan's, and that was more
/// than `min_turn_rad`, the scan is also matched from the heading the last turn carries on
/// to (a constant turn rate), and that match kept if it scores `margin` more.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StallTurn {
    /// The last matched scan's turn beyond which the robot counts as turning, radians.
    pub min_turn_rad: f64,
    /// The share of that turn the prediction must fall under.
    pub stalled_share: f64,
    /// Mean occupancy by which the carried-on turn's match must beat the prediction's.
    pub margin: f64,
}

impl FastTurn {
    /// The match of `points` from the best heading around `prior`, if it beats `local` (the
    /// match from `prior`) by the margin. `turn_rad` is the turn the prediction makes over
    /// the scan: the search reaches from the heading with no turn at all to the predicted
    /// one, each widened by the search's half-width, because odometry can also report a turn
    /// the robot never made (a glitch, a knock), and a match left 90 degrees off writes the
    /// scan into the map turned.
    fn rematch(
        &self,
        map: &MultiResMap,
        points: &[Point2],
        prior: Pose2,
        turn_rad: f64,
        local: &crate::matcher::Match,
        matcher: &MatcherConfig,
    ) -> Option<crate::matcher::Match> {
        let middle = Pose2::new(prior.x_m, prior.y_m, prior.yaw_rad - turn_rad / 2.0);
        let half_width = turn_rad.abs() / 2.0 + self.search_rad;
        let start = best_heading(map, points, middle, half_width, self.step_rad);
        // Within a step of the prediction, the local match started there.
        if normalize_angle_rad(start.yaw_rad - prior.yaw_rad).abs() <= self.step_rad {
            return None;
        }
        // The searched heading is the second match's prior: in a fast turn the wheels'
        // heading is the doubtful part.
        let other = match_scan(map, points, start, matcher);
        (other.score > local.score + self.margin).then_some(other)
    }
}

/// How far a gyro's integrated heading wanders over a span of `dt` seconds: a random walk
/// from its white noise, `rad_per_sqrt_s * sqrt(dt)`, plus what is left of its bias after
/// calibration, `bias_rad_s * dt` (standard deviations).
///
/// Over the second between two keyframes a gyro's turn is good to a few hundredths of a
/// degree, while two matches against a noisy map differ by tenths. Weighting both alike let
/// every closure turn the chain of keyframes about as far as it liked, and the matches' noise
/// walked the map's heading by a degree in minutes (BENCHMARKS.md, "A scan's heading at its
/// own stamp").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroHeading {
    /// Angle random walk, rad / sqrt(s).
    pub rad_per_sqrt_s: f64,
    /// Residual bias, rad / s.
    pub bias_rad_s: f64,
}

impl GyroHeading {
    /// Information (inverse variance) of the heading change over `dt_s` seconds, 1 / rad^2.
    pub fn information(&self, dt_s: f64) -> f64 {
        let dt = dt_s.max(1e-3);
        let var = self.rad_per_sqrt_s.powi(2) * dt + (self.bias_rad_s * dt).powi(2);
        1.0 / var.max(1e-12)
    }
}

/// The tracked heading less the odometry's (a gyro's) when the pose was last set.
#[derive(Clone, Copy, Debug)]
struct HeadingAnchor {
    time_s: f64,
    offset_rad: f64,
}

/// How far the tracked heading may turn away from the gyro's over a short span
/// ([`MapperConfig::heading_window`]). Unlike an anchor held since the pose was set, a
/// window forgets: the gyro's bias and the map's own slow corrections add up over minutes,
/// not over a few seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingWindow {
    /// The span over which the tracked heading less the gyro's is compared, seconds.
    pub span_s: f64,
    /// The most it may change within the span, radians.
    pub max_rad: f64,
}

/// When the tracked heading has swung away from the gyro's ([`MapperConfig::heading_departure`]).
/// Seed 42's rover1 turned 4.5 degrees from the gyro's heading within six seconds of a turn
/// in the open hall, drove on 17 m with it, and ended 1.04 m off while it published 0.18 m
/// (BENCHMARKS.md, ninety-sixth session). Over ten seconds the gyro's own error is a tenth of
/// a degree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingDeparture {
    /// The span over which the tracked heading less the gyro's is compared, seconds.
    pub window_s: f64,
    /// A swing within the span from this much on counts, radians.
    pub min_swing_rad: f64,
}

impl Default for HeadingDeparture {
    fn default() -> Self {
        HeadingDeparture {
            window_s: 10.0,
            min_swing_rad: 1.5f64.to_radians(),
        }
    }
}

/// A swing of the tracked heading from the gyro's since the pose was last set: the largest
/// found within one window, and where the rover was when the first swing to pass the bound
/// began (a later, larger one keeps that place: the heading has been off since then).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Departed {
    swing_rad: f64,
    from: Point2,
}

impl HeadingWindow {
    /// The heading offset (tracked less the gyro's) nearest `offset_rad` that stays within
    /// `max_rad` of every offset in `recent`; `None` if `offset_rad` already does, or if
    /// no offset can (the recent ones already spread wider than the bound: a refinement
    /// after a hold turns the heading a little past it).
    fn clamp(&self, recent: impl Iterator<Item = f64>, offset_rad: f64) -> Option<f64> {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for o in recent {
            // Relative to the new offset, so that headings across +-pi compare.
            let d = normalize_angle_rad(o - offset_rad);
            lo = lo.max(d - self.max_rad);
            hi = hi.min(d + self.max_rad);
        }
        (lo <= hi && (lo > 0.0 || hi < 0.0)).then(|| offset_rad + 0.0f64.clamp(lo, hi))
    }
}

/// How far a loop closure may move a keyframe: `base_m + per_m * d`, where `d` is the length
/// of the shortest path between the two ends through the pose graph (travel along its
/// odometry edges, [`hop_m`](Self::hop_m) for each accepted closure).
///
/// The search window must be metres wide, because after a long loop the drift can be. But a
/// symmetric object (the lander's square, a row of look-alike boulders) then offers a second
/// fit one side-length away, which scores as well as the true one and is found again from
/// every nearby keyframe, so neither the ambiguity test nor the confirmation stops it. What
/// does is that the two ends were joined a few metres ago: the map cannot have drifted metres
/// since. This is gating a closure by the relative pose uncertainty of its two ends, with the
/// path length standing in for the covariance a full estimator would carry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosureDrift {
    /// Correction always allowed, metres.
    pub base_m: f64,
    /// Allowed correction per metre of path between the ends.
    pub per_m: f64,
    /// Path length a closure already in the graph stands for, metres.
    pub hop_m: f64,
    /// Turn always allowed, radians ...
    pub base_rad: f64,
    /// ... and per metre of path between the ends.
    pub per_m_rad: f64,
}

/// Travel the scans did not pin along the rover's heading (a bare wall beside it, nothing
/// within range ahead or behind): the wheels carried the pose along it, and on loose ground
/// they over-report by up to a fifth, so the map can have slid by that share of it. A
/// closure across such a stretch is searched that much wider and may correct that much
/// more than [`ClosureDrift`] allows for the path alone; without it a rover that slid
/// metres along a wall can never be joined to the map it made before (BENCHMARKS.md,
/// "Closures searched as far as a rover can have slid along a wall").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WeakTravel {
    /// A match pins the travel if the map's information along the heading is at least this
    /// many times the matcher's prior there. Beside a lone wall it is a few hundredths; in
    /// a hall that shows a wall ahead or a few boulders, 5-20; in the simulated hall a
    /// third of the rovers' travel is below 10, a few per cent below 2.
    pub min_information_ratio: f64,
    /// The share of the unpinned travel the pose may have slid by.
    pub drift_share: f64,
    /// The closure search's translation window grows by that slide up to this, metres.
    pub max_window_m: f64,
}

impl Default for WeakTravel {
    fn default() -> Self {
        WeakTravel {
            min_information_ratio: 5.0,
            drift_share: 0.15,
            max_window_m: 6.0,
        }
    }
}

/// Scans taken while the robot stands still carry nothing new, and matching them against a
/// young, sparse submap lets the estimate wander (a degree of heading while parked in
/// feature-poor terrain, then baked into every later keyframe). Standard practice (e.g.
/// Cartographer's motion filter, slam_toolbox's minimum travel) is to skip them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionFilter {
    /// Odometry translation since the last matched scan, metres ...
    pub translation_m: f64,
    /// ... or rotation, radians, before the next scan is matched.
    pub rotation_rad: f64,
}

impl MapperConfig {
    /// Until the wheel scale is learnt, the wheels taken at their word (an initial scale
    /// of 1), if the mapper learns one: for wheels that report the travel exactly, or the
    /// setup before the rovers' initial scale.
    pub fn take_wheels_at_their_word(&mut self) {
        if let Some(s) = &mut self.slip_calibration {
            s.initial_scale = 1.0;
        }
    }
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            frontend: FrontendConfig::default(),
            keyframe_translation_m: 0.2,
            keyframe_rotation_rad: 6f64.to_radians(),
            submap_keyframes: 30,
            loop_every_keyframes: 2,
            loop_search_radius_m: 8.0,
            loop_search_nearest_keyframe: true,
            // Wide enough for a long loop's drift on wheel odometry (MIT CSAIL's is metres);
            // the drift bound below narrows it where the two ends were joined recently.
            loop_window_m: 5.0,
            loop_window_rad: 15f64.to_radians(),
            loop_min_score: 0.5,
            loop_search_min_score: 0.55,
            loop_ambiguity_margin: 0.08,
            loop_candidates: 3,
            health: HealthConfig::default(),
            slip_check_without_prior: false,
            slip_check_match_to_match: false,
            slip_check_own_match: false,
            trim_radius_m: None,
            start_rivals_beyond_m: None,
            start_rivals_homing_only: false,
            motion_filter: None,
            min_scan_points: 10,
            max_heading_step_rad: None,
            heading_anchor_rad: None,
            heading_window: None,
            heading_departure: None,
            heading_map_share: None,
            heading_map_share_without_walls: false,
            still_hold: None,
            weak_direction_floor: None,
            weak_direction_gate_m: None,
            unreliable_rewind: false,
            unreliable_pull_share: None,
            turn_scaled_travel: false,
            refine_only_where_pinned: None,
            push_ahead_where_weak: None,
            map_occupied_above: crate::assembly::OCCUPIED_ABOVE,
            final_map_hit_range_m: None,
            // Wheel odometry with the scans matched in between drifts by a few per cent of
            // the path: a closure may move a keyframe by 0.3 m plus a tenth of the path
            // between its ends, and is searched within a degree of turn a metre. On the
            // recorded logs this refused closures that slid a corridor's length (ACES), and
            // made the searches 2-3 times faster (BENCHMARKS.md, "Odometry that stalls, fast
            // turns, and closures searched as far as the path can have drifted").
            closure_drift: Some(ClosureDrift {
                base_m: 0.3,
                per_m: 0.1,
                hop_m: 2.0,
                base_rad: 5f64.to_radians(),
                per_m_rad: 1f64.to_radians(),
            }),
            weak_travel: None,
            weak_hop_share: None,
            slip_calibration: None,
            pose_uncertainty: None,
            gyro_heading: None,
            blind_travel_uncertain: true,
            graph_solver: GraphSolver::BlockJacobi,
            graph_loss: RobustLoss::Huber,
            track_in_submap_frame: true,
            fast_turn: Some(FastTurn {
                turn_rad: 10f64.to_radians(),
                search_rad: 20f64.to_radians(),
                step_rad: 1f64.to_radians(),
                margin: 0.1,
            }),
            stall_turn: Some(StallTurn {
                min_turn_rad: 3f64.to_radians(),
                stalled_share: 0.5,
                margin: 0.1,
            }),
            ndt_refine: None,
            optimize_every_keyframes: 20,
            precomputed_kept: 8,
            clear_rays_published_only: false,
            grids_traced_apart: false,
            clear_rays_spacing_m: None,
            graph_iterations: 3,
            graph_later_cap: None,
            drop_closures_beyond: None,
            distinct_confirmation_beyond_m: None,
            faces_seen_from: None,
            closure_min_points: None,
            closure_weighting: None,
            closure_min_information: None,
            closure_ridges: None,
            redraw_bent_submaps: None,
            closure_from_nearest_drawn: false,
            closure_share_span: None,
            wall_headings: None,
            optimize_on_wall_heading_sigmas: None,
        }
    }
}

#[derive(Debug)]
struct Submap {
    origin_node: usize,
    map: MultiResMap,
    /// The same keyframes drawn with every beam clearing cells up to its hit, for the
    /// published map, when the matching `map` stops its beams short of their hits
    /// ([`FrontendConfig::miss_margin`]): a margin unbiases the surfaces matched against,
    /// and leaves the few hits the noise throws in front of a surface uncleared, which
    /// thickens the surfaces a map shows.
    published: Option<OccupancyGrid>,
    keyframes: usize,
    finished: bool,
    /// The closure search's precomputation, made when searched (the map is final) and kept
    /// while it is among the submaps searched last ([`MapperConfig::precomputed_kept`]).
    precomputed: Option<PrecomputedMap>,
    /// When it was last searched, by the mapper's count of searches.
    searched_at: u64,
    /// Its grids were dropped because a newer submap covers the same ground.
    trimmed: bool,
    /// Its keyframes' hits per cell, for refining tracking matches; while it is active.
    hits: Option<NdtMap>,
    /// Where each of its keyframes was drawn, relative to its first keyframe.
    drawn: Vec<Pose2>,
}

#[derive(Clone, Copy, Debug)]
struct ScanPose {
    timestamp_s: f64,
    keyframe: usize,
    keyframe_from_scan: Pose2,
}

/// What became of one scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tracked {
    /// The pose estimate at the scan.
    pub pose: Pose2,
    /// The tracking match score, if the scan was matched.
    pub score: Option<f64>,
    /// The localisation state after it.
    pub state: LocalisationState,
    /// Whether the scan became a keyframe (and went into the map).
    pub keyframe_added: bool,
}

/// A closure's hits on the submap's walls are read for the ground this far before them along
/// their beams ([`crate::occupancy::OccupancyGrid::hits_from_behind`]), metres.
const FROM_BEHIND_BACK_M: f64 = 0.15;
/// A refinement that moves the searched pose farther than this found another basin: refused.
const MAX_REFINE_SHIFT_M: f64 = 0.2;
/// The heading prior's weight (per point, per square radian) when a match's turn is refused:
/// far above what the map's gradients give a point, so the heading stays put.
const HELD_HEADING_WEIGHT: f64 = 1e7;
/// Position standard deviation of the edge between consecutive matched keyframes, metres ...
const SEQUENTIAL_SIGMA_M: f64 = 0.05;
/// ... as information, 1 / m^2.
const SEQUENTIAL_POSITION_INFORMATION: f64 = 400.0;
/// Heading information of that edge as matched, 1 / rad^2 (a gyro's turn is firmer).
const SEQUENTIAL_HEADING_INFORMATION: f64 = 2500.0;
/// A closure or a relocalisation searches metres and degrees around a pose: a scan of fewer
/// endpoints than this fits too many places there to be taken, though from a known pose it
/// is still tracked ([`MapperConfig::min_scan_points`]).
const SEARCH_MIN_POINTS: usize = 10;
/// A finished submap is dropped for a newer one starting nearby only if the newer one knows
/// at least this share of the cells it knows. Starting nearby is not enough: driving off the
/// other way, the newer one never sees what the older saw ahead, and dropping the older would
/// make that ground unknown again (a frontier the rover then drives back to, for ever).
const TRIM_MIN_COVERED: f64 = 0.95;
/// While lost, a new relocalisation search once odometry has moved this far since the last,
/// metres ...
const RELOCALISE_AFTER_M: f64 = 0.1;
/// ... or turned this far (5 degrees), radians.
const RELOCALISE_AFTER_RAD: f64 = 0.087;
/// Relocalisation searches this far around the dead-reckoned pose, metres ...
const RELOCALISE_WINDOW_M: f64 = 3.0;
/// ... and this far in heading, radians.
const RELOCALISE_WINDOW_RAD: f64 = 0.6;
/// Every this many relocalisation searches of one loss, the first included, the search takes
/// every heading. A turn the odometry never reported (one made in a gap of the log, a knock)
/// leaves the dead-reckoned heading outside the usual window for good. A search over every
/// heading costs about five of the usual ones.
const RELOCALISE_ALL_HEADINGS_EVERY: usize = 4;

/// A closure a search found and verified, and what became of it: the figures its checks
/// saw, so that accepted closures can be graded against a known truth.
#[derive(Clone, Copy, Debug)]
pub struct ClosureRecord {
    /// The edge it would add (`from` is the submap's first keyframe).
    pub edge: Edge,
    /// The branch-and-bound search's score ...
    pub search_score: f64,
    /// ... and its best rival's (see [`bnb::SearchResult`]).
    pub rival_score: f64,
    /// The refined match's score ...
    pub score: f64,
    /// ... and information (x, y, theta).
    pub information: [[f64; 3]; 3],
    /// Whether the correction it asks for is one the map can have drifted by.
    pub within_drift: bool,
    /// How many of the keyframe's hits, at the match, land on cells the submap holds as
    /// occupied ...
    pub on_walls: usize,
    /// ... and how many of those reach them over ground the submap never saw open: faces
    /// reached from behind ([`crate::occupancy::OccupancyGrid::hits_from_behind`]).
    pub from_behind: usize,
    /// Whether it entered the graph (confirmed by another).
    pub accepted: bool,
}

/// A closure waiting for (or given) a partner's confirmation.
#[derive(Clone, Copy, Debug)]
struct ProposedClosure {
    edge: Edge,
    /// The submap it matched in.
    submap: usize,
    /// Whether it is in the graph.
    accepted: bool,
}

/// The mapper.
#[derive(Debug)]
pub struct Mapper {
    cfg: MapperConfig,
    graph: PoseGraph,
    keyframe_points: Vec<Vec<Point2>>,
    /// Each keyframe's beams that returned nothing, as the ends of the free rays drawn
    /// along them (robot frame; see [`Mapper::set_clear_rays`]).
    keyframe_clear: Vec<Vec<Point2>>,
    /// ... for the next scan.
    clear_rays: Vec<Point2>,
    /// Where the last keyframe whose clear rays were drawn stood (for
    /// [`MapperConfig::clear_rays_spacing_m`]).
    last_clear_rays_at: Option<Point2>,
    /// Each keyframe's time and odometry pose.
    keyframe_odom: Vec<(f64, Pose2)>,
    /// Wheel travel since the previous keyframe with nothing to match against (too few
    /// returns, or no map yet), per keyframe: the wheels alone carried the pose there.
    keyframe_unmatched_m: Vec<f64>,
    /// ... and since the latest keyframe.
    unmatched_m: f64,
    /// Wheel travel the matches did not pin along the heading ([`WeakTravel`]), summed over
    /// the keyframes up to each (so a stretch's is a difference of two).
    keyframe_weak_total_m: Vec<f64>,
    /// ... and since the latest keyframe.
    weak_m: f64,
    submaps: Vec<Submap>,
    scans: Vec<ScanPose>,
    pose: Pose2,
    /// Where the next scan is predicted from (odometry that stalls is applied once).
    odometry: OdomPredictor,
    /// When the last scan with a fresh wheel reading was settled on, seconds (for the
    /// wheels' plausible travel to the next).
    last_fresh_wheels_s: Option<f64>,
    /// Odometry at the last scan that was matched (for the motion filter).
    last_matched_odom: Option<Pose2>,
    /// An optimisation is due at the next batch: a closure was accepted (or the walls
    /// measured the heading far off, [`MapperConfig::optimize_on_wall_heading_sigmas`]).
    pending_closures: bool,
    /// Closures found in the last few keyframes.
    recent_closures: Vec<ProposedClosure>,
    health: HealthMonitor,
    transitions: Vec<(f64, Transition)>,
    lost_at: Option<Pose2>,
    /// The odometry pose of the last relocalisation attempt.
    last_relocalise_odom: Option<Pose2>,
    /// Points (robot frame) from another sensor that go into the next scan's refinement and
    /// its keyframe's hits, beside the scan's own.
    features: Vec<Point2>,
    /// The next scan's points' heights (see [`Mapper::set_point_heights`]).
    point_heights: Vec<f64>,
    /// The wheels' own heading at the next scan (see [`Mapper::set_wheel_heading`]).
    wheel_heading: Option<f64>,
    /// The wheels' own heading and the odometry's at the last scan, for the slip check's
    /// turns.
    last_headings: Option<(f64, f64)>,
    /// The tracked heading less the odometry's when the pose was last set, and when.
    heading_anchor: Option<HeadingAnchor>,
    /// The tracked heading less the odometry's at each scan, with the time and the position
    /// then, oldest first, since the pose was last set: over the longer span of the heading
    /// window's and the heading departure's, each of which reads its own span
    /// ([`MapperConfig::heading_window`], [`MapperConfig::heading_departure`]).
    heading_offsets: std::collections::VecDeque<(f64, f64, Point2)>,
    /// The swing found, if any, since the pose was last set.
    departed: Option<Departed>,
    /// The odometry's heading at the last scan, while not lost: where a new anchor starts
    /// from. Whatever sets the pose other than tracking (an optimisation, a relocalisation
    /// after being lost) drops the anchor.
    last_odom_yaw: Option<f64>,
    /// Relocalisation searches since the rover was declared lost.
    searches_since_lost: usize,
    last_information: [[f64; 3]; 3],
    /// The last match before any pull towards the prediction, relative to the pose tracking
    /// kept (see [`MapperConfig::slip_check_match_to_match`]).
    heard_from_pose: Option<Pose2>,
    /// Accepted loop closures.
    pub closures: usize,
    /// Every verified closure match, with what its search and refinement saw.
    closure_records: Vec<ClosureRecord>,
    /// Matches redone with the heading held to the odometry's.
    pub heading_holds: usize,
    /// Matches redone with the heading held to the gyro's because it had strayed from it
    /// since the pose was set ([`MapperConfig::heading_anchor_rad`]).
    pub heading_anchor_holds: usize,
    /// Matches redone with the heading held because it turned too far from the gyro's
    /// within the heading window ([`MapperConfig::heading_window`]).
    pub heading_window_holds: usize,
    /// Relocalisation searches made while lost.
    pub relocalise_searches: usize,
    /// Searches of a submap for a closure or a relocalisation so far (a clock for which
    /// submaps were searched last).
    searches: u64,
    /// Scans whose headings were searched for a fast turn ...
    pub fast_turn_searches: usize,
    /// ... and the matches from the searched heading that were kept.
    pub fast_turn_taken: usize,
    /// Scans matched again for a stalled turn ([`StallTurn`]) ...
    pub stall_turn_searches: usize,
    /// ... and the matches from the carried-on turn that were kept.
    pub stall_turn_taken: usize,
    /// The last matched scan's motion, for [`StallTurn`]; `None` after a scan not matched.
    last_matched_delta: Option<Pose2>,
    /// The finished submaps drawn together, for the map.
    assembly: Assembly,
    /// How far the wheels over-report, learnt from the matches.
    wheel_scale: Option<WheelScale>,
    /// Whether the rover is driving home at the end, or is home
    /// ([`MapperConfig::start_rivals_homing_only`]).
    homing: bool,
    /// The newest keyframe's uncertainty from the start, kept up to date as asked.
    paths_from_start: PathsFromStart,
    /// The wall directions the first keyframe saw, and their right angles if so set (with
    /// `wall_headings`); the headings they measured are the graph's heading priors.
    walls: Option<WallHeadings>,
}

impl Submap {
    /// The grid the published map is drawn from.
    fn published(&self) -> &OccupancyGrid {
        self.published.as_ref().unwrap_or(self.map.finest())
    }
}

/// Neighbouring returns farther apart than this lie on different surfaces: no normal is
/// taken across them, metres.
const NORMAL_MAX_CHORD_M: f64 = 0.5;

/// How well a scan's returns (in beam order) pin a pose in the direction they pin least:
/// the smaller eigenvalue of the mean of `n nᵀ` over the surface normals along the scan,
/// each normal across the chord between a return's two neighbours on the same surface.
/// 0 for a straight wall (nothing pins the pose along it), 0.5 for surfaces facing every
/// way equally (a corner of two equal walls); `0` with no normal at all. The degeneracy
/// measure of point-to-line matching (Zhang, Kaess and Singh 2016, "On degeneracy of
/// optimization-based state estimation problems"), normalised by the count.
pub fn weakest_direction_share(points: &[Point2]) -> f64 {
    let (mut xx, mut xy, mut yy, mut n) = (0.0, 0.0, 0.0, 0usize);
    for w in points.windows(3) {
        let (dx, dy) = (w[2].x_m - w[0].x_m, w[2].y_m - w[0].y_m);
        let chord = dx.hypot(dy);
        if !(1e-9..=NORMAL_MAX_CHORD_M).contains(&chord) {
            continue;
        }
        let (nx, ny) = (-dy / chord, dx / chord);
        xx += nx * nx;
        xy += nx * ny;
        yy += ny * ny;
        n += 1;
    }
    if n == 0 {
        return 0.0;
    }
    let (xx, xy, yy) = (xx / n as f64, xy / n as f64, yy / n as f64);
    let half_trace = 0.5 * (xx + yy);
    (half_trace - (0.25 * (xx - yy).powi(2) + xy * xy).sqrt()).max(0.0)
}

/// A submap's grid for the published map, when its matching grid's beams stop short of
/// their hits or leave out the beams that returned nothing (see [`Submap::published`]).
fn published_grid(cfg: &MapperConfig) -> Option<OccupancyGrid> {
    let f = &cfg.frontend;
    (f.miss_margin.is_some() || cfg.clear_rays_published_only).then(|| {
        OccupancyGrid::new(f.resolution_m)
            .with_miss_rule(f.miss_rule)
            .without_probabilities()
    })
}

impl Mapper {
    /// An empty mapper.
    pub fn new(cfg: MapperConfig) -> Self {
        Mapper {
            cfg,
            graph: PoseGraph {
                solver: cfg.graph_solver,
                loss: cfg.graph_loss,
                ..PoseGraph::default()
            },
            keyframe_points: Vec::new(),
            keyframe_clear: Vec::new(),
            clear_rays: Vec::new(),
            last_clear_rays_at: None,
            keyframe_odom: Vec::new(),
            keyframe_unmatched_m: Vec::new(),
            unmatched_m: 0.0,
            keyframe_weak_total_m: Vec::new(),
            weak_m: 0.0,
            submaps: Vec::new(),
            scans: Vec::new(),
            pose: Pose2::IDENTITY,
            odometry: OdomPredictor::default(),
            last_fresh_wheels_s: None,
            last_matched_odom: None,
            pending_closures: false,
            recent_closures: Vec::new(),
            health: HealthMonitor::new(cfg.health),
            transitions: Vec::new(),
            lost_at: None,
            last_relocalise_odom: None,
            features: Vec::new(),
            point_heights: Vec::new(),
            wheel_heading: None,
            last_headings: None,
            heading_anchor: None,
            heading_offsets: std::collections::VecDeque::new(),
            departed: None,
            last_odom_yaw: None,
            searches_since_lost: 0,
            last_information: [[0.0; 3]; 3],
            heard_from_pose: None,
            closures: 0,
            closure_records: Vec::new(),
            heading_holds: 0,
            heading_anchor_holds: 0,
            heading_window_holds: 0,
            relocalise_searches: 0,
            searches: 0,
            fast_turn_searches: 0,
            fast_turn_taken: 0,
            stall_turn_searches: 0,
            stall_turn_taken: 0,
            last_matched_delta: None,
            assembly: Assembly::new(cfg.frontend.resolution_m)
                .with_miss_rule(cfg.frontend.miss_rule)
                .with_occupied_above(cfg.map_occupied_above),
            wheel_scale: cfg.slip_calibration.map(WheelScale::new),
            homing: false,
            paths_from_start: PathsFromStart::default(),
            walls: cfg.wall_headings.map(WallHeadings::new),
        }
    }

    fn points(&self, scan: &LaserReading) -> Vec<Point2> {
        let f = &self.cfg.frontend;
        crate::frontend::scan_points(scan, f.min_range_m, f.max_range_m)
    }

    fn insert(&mut self, submap: usize, node: usize, dense: &[Point2]) {
        self.insert_within(submap, node, dense, None);
    }

    /// [`insert`](Self::insert) with hits only out to `hit_range_m` from the keyframe, if
    /// set: a point farther off clears the cells out to that range and marks none.
    fn insert_within(
        &mut self,
        submap: usize,
        node: usize,
        dense: &[Point2],
        hit_range_m: Option<f64>,
    ) {
        let origin = self.graph.nodes[self.submaps[submap].origin_node];
        let local = origin.inverse() * self.graph.nodes[node];
        let within = |p: Point2| -> (Point2, bool) {
            let range = p.x_m.hypot(p.y_m);
            match hit_range_m {
                Some(r) if range > r => (Point2::new(p.x_m * r / range, p.y_m * r / range), false),
                _ => (p, true),
            }
        };
        let clear = self.keyframe_clear.get(node).map_or(&[][..], |c| &c[..]);
        // Every beam, as the published grid takes them: the points, then the rays that
        // returned nothing.
        let world: Vec<(Point2, bool)> = dense
            .iter()
            .map(|p| {
                let (p, hit) = within(*p);
                (local.transform_point(p), hit)
            })
            .chain(
                clear
                    .iter()
                    .map(|p| (local.transform_point(within(*p).0), false)),
            )
            .collect();
        // Filled-in points are hits only: free space along the beams themselves, cut to the
        // same range.
        let world_rays: Option<Vec<Point2>> =
            (!self.cfg.frontend.trace_filled && self.cfg.frontend.densify.is_some()).then(|| {
                self.keyframe_points[node]
                    .iter()
                    .chain(clear)
                    .map(|p| local.transform_point(within(*p).0))
                    .collect()
            });
        // The matching grid's beams are the first of them: all but the rays that returned
        // nothing, if only the published grid takes those.
        let matched_clear = if self.cfg.clear_rays_published_only {
            0
        } else {
            clear.len()
        };
        let matched = (
            dense.len() + matched_clear,
            self.keyframe_points[node].len() + matched_clear,
        );
        let s = &mut self.submaps[submap];
        match (&mut s.published, s.map.single_level_mut()) {
            (Some(published), Some(grid)) if !self.cfg.grids_traced_apart => {
                published.insert_with_rays_beside(
                    grid,
                    local.position(),
                    &world,
                    world_rays.as_deref(),
                    matched,
                );
            }
            (published, _) => {
                s.map.insert_with_rays(
                    local.position(),
                    &world[..matched.0],
                    world_rays.as_deref().map(|r| &r[..matched.1]),
                );
                if let Some(published) = published {
                    published.insert_with_rays(local.position(), &world, world_rays.as_deref());
                }
            }
        }
        s.keyframes += 1;
        s.drawn.push(local);
        if let Some(hits) = &mut s.hits {
            let heights = &self.point_heights;
            hits.insert_with_heights(
                self.keyframe_points[node]
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (*p, heights.get(i).copied().unwrap_or(f64::NAN)))
                    .chain(self.features.iter().map(|p| (*p, f64::NAN)))
                    .map(|(p, h)| (local.transform_point(p), h)),
            );
        }
    }

    /// Points (robot frame) from another sensor for the next scan only: its refinement on
    /// the hits pairs them too, and its keyframe, if it makes one, adds them to the hits.
    pub fn set_features(&mut self, features: Vec<Point2>) {
        self.features = features;
    }

    /// The next scan's beams that returned nothing, each as the end of a ray (robot frame)
    /// along which the scan saw nothing: drawn into the maps as free space, never matched.
    /// For the next scan only.
    pub fn set_clear_rays(&mut self, ends: Vec<Point2>) {
        self.clear_rays = ends;
    }

    /// Each point of the next scan's height above the ground under the rover, levelled by
    /// its tilt (in the order of the points given to [`add_points_with`](Self::add_points_with);
    /// for [`NdtConfig::outline_shift_per_height`]). For the next scan only.
    pub fn set_point_heights(&mut self, heights: Vec<f64>) {
        self.point_heights = heights;
    }

    /// The wheels' own heading at the next scan, radians, where the odometry given to
    /// [`add_points_with`](Self::add_points_with) takes its heading from a gyro: the slip
    /// check then compares the two turns ([`HealthConfig::turn_check`]). For the next scan
    /// only.
    pub fn set_wheel_heading(&mut self, yaw_rad: f64) {
        self.wheel_heading = Some(yaw_rad);
    }

    /// Adds a scan from a CARMEN log.
    pub fn add_scan(&mut self, scan: &LaserReading) -> Tracked {
        let points = self.points(scan);
        self.add_points(scan.timestamp_s, scan.odom, points)
    }

    /// Adds a scan taken at `time_s`: its endpoints in the robot frame, and the wheel
    /// odometry pose at that time (any fixed odometry frame).
    pub fn add_points(&mut self, time_s: f64, odom: Pose2, points: Vec<Point2>) -> Tracked {
        self.add_points_with(time_s, OdomSample::wheels(odom), points)
    }

    /// [`Mapper::add_points`], saying whether the wheels were silent (see [`OdomSample`]).
    pub fn add_points_with(
        &mut self,
        time_s: f64,
        sample: OdomSample,
        points: Vec<Point2>,
    ) -> Tracked {
        let odom = sample.pose;
        let headings = self
            .wheel_heading
            .take()
            .filter(|_| !sample.wheels_silent)
            .map(|wheels| (wheels, odom.yaw_rad));
        let turns_rad = match (self.last_headings, headings) {
            (Some((w0, g0)), Some((w1, g1))) => {
                Some((normalize_angle_rad(w1 - w0), normalize_angle_rad(g1 - g0)))
            }
            _ => None,
        };
        self.last_headings = headings;
        let turn_share = if self.cfg.turn_scaled_travel {
            self.health.turn_share(time_s)
        } else {
            None
        };
        let max_step_m = self
            .last_fresh_wheels_s
            .map_or(crate::odometry::MAX_WHEEL_STEP_M, |t0| {
                crate::odometry::wheel_step_bound_m(time_s - t0)
            });
        let prediction = self
            .odometry
            .predict_within(sample, self.pose, max_step_m, |d| {
                let d = self.wheel_scale.as_ref().map_or(d, |w| w.apply(d));
                match turn_share {
                    Some(share) => Pose2::new(share * d.x_m, share * d.y_m, d.yaw_rad),
                    None => d,
                }
            });
        let (odom_delta, predicted) = (prediction.step, prediction.pose);
        let before = self.pose;
        if let (None, Some(odom_yaw)) = (self.heading_anchor, self.last_odom_yaw) {
            self.heading_anchor = Some(HeadingAnchor {
                time_s,
                offset_rad: normalize_angle_rad(before.yaw_rad - odom_yaw),
            });
        }
        // A relocalisation puts the pose off the wheels' track.
        let mut relocalised = false;
        let mut score = None;
        let mut trusted_along = false;
        let mut matched_alone = None;
        // The match before any pull towards the prediction, for the slip check's next scan.
        let mut match_before_pull = None;
        // Matched and mapped filled in; the live map and closures take the endpoints.
        let dense = match self.cfg.frontend.densify {
            Some(d) => std::borrow::Cow::Owned(crate::frontend::densify(&points, d)),
            None => std::borrow::Cow::Borrowed(&points),
        };
        if self.health.state() == LocalisationState::Lost {
            self.pose = predicted;
            // A view seen from (nearly) where the last attempt was made shows the search
            // nothing new: a rover turning in place is searched every few degrees, and one
            // standing still not again (a search costs as much as a loop closure's).
            let new_view = self.last_relocalise_odom.is_none_or(|at| {
                let d = at.inverse() * odom;
                d.x_m.hypot(d.y_m) >= RELOCALISE_AFTER_M || d.yaw_rad.abs() >= RELOCALISE_AFTER_RAD
            });
            if new_view {
                self.last_relocalise_odom = Some(odom);
                let dead_reckoned = self.pose;
                self.try_relocalise(time_s, &points);
                relocalised = self.pose != dead_reckoned;
            }
        } else {
            self.last_relocalise_odom = None;
            // Track against the older active submap, in its own frame.
            let tracking = self
                .submaps
                .iter()
                .position(|s| !s.finished && s.keyframes > 0);
            // Silent wheels say nothing of whether the robot moves: every scan is matched.
            let moved = match (self.cfg.motion_filter, self.last_matched_odom) {
                _ if sample.wheels_silent => true,
                (Some(f), Some(at)) => {
                    let d = at.inverse() * odom;
                    d.x_m.hypot(d.y_m) >= f.translation_m || d.yaw_rad.abs() >= f.rotation_rad
                }
                _ => true,
            };
            if self.cfg.blind_travel_uncertain
                && (tracking.is_none() || points.len() < self.cfg.min_scan_points)
            {
                self.unmatched_m += odom_delta.x_m.hypot(odom_delta.y_m);
            }
            self.pose = match tracking {
                Some(i) if points.len() >= self.cfg.min_scan_points && moved => {
                    self.last_matched_odom = Some(odom);
                    let origin = self.graph.nodes[self.submaps[i].origin_node];
                    let prior = origin.inverse() * predicted;
                    let map = &self.submaps[i].map;
                    let still = self.cfg.still_hold.filter(|hold| {
                        !sample.wheels_silent
                            && !prediction.stalled
                            && prediction.step.x_m.hypot(prediction.step.y_m) < hold.below_m
                    });
                    let matcher = match still {
                        Some(hold) => MatcherConfig {
                            prior_translation_weight: hold.translation_weight,
                            prior_rotation_weight: if hold.hold_heading {
                                HELD_HEADING_WEIGHT
                            } else {
                                self.cfg.frontend.matcher.prior_rotation_weight
                            },
                            ..self.cfg.frontend.matcher
                        },
                        None => self.cfg.frontend.matcher,
                    };
                    // The slip check's own matches keep the usual pull: they decide when
                    // the wheels agree again.
                    let check_matcher = matcher;
                    let matcher = match self.cfg.unreliable_pull_share {
                        Some(share)
                            if still.is_none()
                                && self.health.state() == LocalisationState::OdometryUnreliable
                                && self.health.disagrees() =>
                        {
                            MatcherConfig {
                                prior_translation_weight: share * matcher.prior_translation_weight,
                                ..matcher
                            }
                        }
                        _ => matcher,
                    };
                    let mut m = match_scan(map, &dense, prior, &matcher);
                    // The match's information sums over these points (floors are per point).
                    let matched_points = dense.len() as f64;
                    // The matcher's pull towards the prediction, summed over the points.
                    let prior_pull = matcher.prior_translation_weight * matched_points;
                    let turn_rad = normalize_angle_rad(predicted.yaw_rad - before.yaw_rad);
                    if let Some(fast) = self.cfg.fast_turn
                        && turn_rad.abs() > fast.turn_rad
                    {
                        self.fast_turn_searches += 1;
                        if let Some(better) =
                            fast.rematch(map, &dense, prior, turn_rad, &m, &matcher)
                        {
                            m = better;
                            self.fast_turn_taken += 1;
                        }
                    }
                    if let (Some(stall), Some(last)) =
                        (self.cfg.stall_turn, self.last_matched_delta)
                        && last.yaw_rad.abs() > stall.min_turn_rad
                        && turn_rad.abs() < stall.stalled_share * last.yaw_rad.abs()
                    {
                        self.stall_turn_searches += 1;
                        let carried_on =
                            Pose2::new(predicted.x_m, predicted.y_m, before.yaw_rad + last.yaw_rad);
                        let alt = match_scan(map, &dense, origin.inverse() * carried_on, &matcher);
                        if alt.score > m.score + stall.margin {
                            m = alt;
                            self.stall_turn_taken += 1;
                        }
                    }
                    if let Some(gate) = self.cfg.max_heading_step_rad
                        && normalize_angle_rad(m.pose.yaw_rad - prior.yaw_rad).abs() > gate
                    {
                        // Over one scan a gyro's heading is far more precise than a match
                        // on a few boulders, whose turns are how sparse scenes go wrong.
                        let held = MatcherConfig {
                            prior_rotation_weight: HELD_HEADING_WEIGHT,
                            ..matcher
                        };
                        m = match_scan(map, &dense, prior, &held);
                        self.heading_holds += 1;
                    }
                    if let (Some(tolerance), Some(gyro), Some(anchor)) = (
                        self.cfg.heading_anchor_rad,
                        self.cfg.gyro_heading,
                        self.heading_anchor,
                    ) {
                        let anchored_yaw = odom.yaw_rad + anchor.offset_rad;
                        let strayed = normalize_angle_rad((origin * m.pose).yaw_rad - anchored_yaw);
                        let gyro_sigma = gyro.information(time_s - anchor.time_s).recip().sqrt();
                        if strayed.abs() > tolerance + 3.0 * gyro_sigma {
                            let held = MatcherConfig {
                                prior_rotation_weight: HELD_HEADING_WEIGHT,
                                ..matcher
                            };
                            let anchored = origin.inverse()
                                * Pose2::new(predicted.x_m, predicted.y_m, anchored_yaw);
                            m = match_scan(map, &dense, anchored, &held);
                            self.heading_anchor_holds += 1;
                        }
                    }
                    // A refinement must not turn a heading the gyro holds.
                    let mut refine_rotation_weight = matcher.prior_rotation_weight;
                    if let Some(window) = self.cfg.heading_window {
                        let offset = normalize_angle_rad((origin * m.pose).yaw_rad - odom.yaw_rad);
                        let recent = self
                            .heading_offsets
                            .iter()
                            .filter(|(t, _, _)| *t >= time_s - window.span_s)
                            .map(|(_, o, _)| *o);
                        if let Some(bounded) = window.clamp(recent, offset) {
                            let held = MatcherConfig {
                                prior_rotation_weight: HELD_HEADING_WEIGHT,
                                ..matcher
                            };
                            let yaw = m.pose.yaw_rad + normalize_angle_rad(bounded - offset);
                            m = match_scan(
                                map,
                                &dense,
                                Pose2::new(m.pose.x_m, m.pose.y_m, yaw),
                                &held,
                            );
                            refine_rotation_weight = HELD_HEADING_WEIGHT;
                            self.heading_window_holds += 1;
                        }
                    }
                    let share = self.cfg.heading_map_share.filter(|_| {
                        !self.cfg.heading_map_share_without_walls
                            || self
                                .walls
                                .as_ref()
                                .is_none_or(|w| w.measure(predicted.yaw_rad, &points).is_none())
                    });
                    if let Some(share) = share {
                        let yaw = prior.yaw_rad
                            + share * normalize_angle_rad(m.pose.yaw_rad - prior.yaw_rad);
                        let held = MatcherConfig {
                            prior_rotation_weight: HELD_HEADING_WEIGHT,
                            ..matcher
                        };
                        m = match_scan(map, &dense, Pose2::new(m.pose.x_m, m.pose.y_m, yaw), &held);
                        refine_rotation_weight = HELD_HEADING_WEIGHT;
                    }
                    // The pose the occupancy match's information describes.
                    let occupancy_pose = m.pose;
                    if let Some(hits) = &self.submaps[i].hits {
                        let wheels = [(origin.inverse() * before).position(), prior.position()];
                        let with_features: Vec<Point2>;
                        let refined_on = if self.features.is_empty() {
                            &points
                        } else {
                            with_features = points.iter().chain(&self.features).copied().collect();
                            &with_features
                        };
                        if let Some(refined) = hits.refine_with_heights(
                            refined_on,
                            &self.point_heights,
                            m.pose,
                            wheels,
                            matcher.prior_translation_weight,
                            refine_rotation_weight,
                        ) {
                            let refined = match self.cfg.push_ahead_where_weak {
                                Some(weak) => {
                                    weak.bound(m.pose, refined, wheels, &m.information, prior_pull)
                                }
                                None => refined,
                            };
                            m.pose = match self.cfg.refine_only_where_pinned {
                                Some(floor) => refined_only_where_pinned(
                                    m.pose,
                                    refined,
                                    &m.information,
                                    prior_pull,
                                    floor * matched_points,
                                ),
                                None => refined,
                            };
                        }
                    }
                    // The scans' own verdict, for the odometry's health: it must not
                    // hear the wheels' claim back as the scans' agreement.
                    // A parked rover's match is held to the prediction: nothing to take back.
                    // The pull is taken back from the occupancy match, which `m.information`
                    // describes; the refinement on the hits (the rovers') pulls towards that
                    // match, not the wheels, so its shift is added as it is.
                    let verdict = if self.cfg.slip_check_without_prior && still.is_none() {
                        let heard = without_prior_along_heading(
                            occupancy_pose,
                            prior,
                            &m.information,
                            prior_pull,
                        );
                        Pose2::new(
                            heard.x_m + m.pose.x_m - occupancy_pose.x_m,
                            heard.y_m + m.pose.y_m - occupancy_pose.y_m,
                            m.pose.yaw_rad,
                        )
                    } else {
                        m.pose
                    };
                    matched_alone = Some(origin * verdict);
                    match_before_pull = Some(origin * m.pose);
                    // The check's own chain of matches, each started from its last one
                    // carried on by the wheels, where the pose has been pulled off it.
                    let own_check = self.cfg.slip_check_match_to_match
                        && self.cfg.slip_check_own_match
                        && still.is_none();
                    let own = self
                        .heard_from_pose
                        .filter(|o| {
                            own_check
                                && (OWN_MATCH_MIN_OFFSET_M..OWN_MATCH_MAX_OFFSET_M)
                                    .contains(&o.x_m.hypot(o.y_m))
                        })
                        .map(|o| origin.inverse() * (before * o * (before.inverse() * predicted)));
                    if let Some(own_prior) = own {
                        let own_match = match_scan(map, &dense, own_prior, &check_matcher);
                        let heard = if self.cfg.slip_check_without_prior {
                            without_prior_along_heading(
                                own_match.pose,
                                own_prior,
                                &own_match.information,
                                check_matcher.prior_translation_weight * matched_points,
                            )
                        } else {
                            own_match.pose
                        };
                        matched_alone = Some(origin * heard);
                        match_before_pull = Some(origin * own_match.pose);
                    }
                    if let Some(floor) = self.cfg.weak_direction_floor
                        && still.is_none()
                        && self.health.state() == LocalisationState::Tracking
                    {
                        m.pose = towards_prediction_where_weak(
                            m.pose,
                            prior,
                            &m.information,
                            prior_pull,
                            floor * matched_points,
                            self.cfg.weak_direction_gate_m.unwrap_or(f64::INFINITY),
                        );
                    }
                    score = Some(m.score);
                    self.last_information = m.information;
                    let prior_weight =
                        self.cfg.frontend.matcher.prior_translation_weight * dense.len() as f64;
                    trusted_along = self
                        .wheel_scale
                        .as_ref()
                        .is_some_and(|w| w.trusted(&m.information, prior_weight, m.pose.yaw_rad));
                    if let Some(weak) = self.cfg.weak_travel
                        && !crate::slip::pinned_along(
                            &m.information,
                            prior_weight,
                            m.pose.yaw_rad,
                            weak.min_information_ratio,
                        )
                    {
                        self.weak_m += odom_delta.x_m.hypot(odom_delta.y_m);
                    }
                    origin * m.pose
                }
                _ => predicted,
            };
            // The first scan fixes the pose as firmly as a match would.
            self.last_matched_odom.get_or_insert(odom);
            self.last_matched_delta = score.map(|_| before.inverse() * self.pose);
            let observed = TrackedScan {
                time_s,
                odom_delta,
                matched_delta: if self.scans.is_empty() {
                    Pose2::IDENTITY
                } else if self.cfg.slip_check_match_to_match {
                    // Without a match the last one's offset from the pose is carried on.
                    let offset = self.heard_from_pose.unwrap_or(Pose2::IDENTITY);
                    (before * offset).inverse() * matched_alone.unwrap_or(self.pose * offset)
                } else {
                    before.inverse() * matched_alone.unwrap_or(self.pose)
                },
                tracked_delta: before.inverse() * self.pose,
                score,
                wheels_silent: sample.wheels_silent,
                turns_rad,
            };
            if let Some(heard) = match_before_pull
                && self.cfg.slip_check_match_to_match
            {
                self.heard_from_pose = Some(self.pose.inverse() * heard);
            }
            let was = self.health.state();
            if let Some(mut t) = self.health.observe(&observed) {
                if self.cfg.unreliable_rewind
                    && was == LocalisationState::Tracking
                    && t.state == LocalisationState::OdometryUnreliable
                {
                    let (x, y) = self.health.overrun();
                    self.pose = self.pose * Pose2::new(-x, -y, 0.0);
                    t.reason
                        .push_str(&format!("; pose taken back {:.2} m", x.hypot(y)));
                }
                if t.state == LocalisationState::Lost {
                    self.heard_from_pose = None;
                    // The scan that tipped it is not trusted either.
                    self.pose = predicted;
                    self.lost_at = Some(before);
                    self.searches_since_lost = 0;
                }
                self.transitions.push((time_s, t));
            }
            if let Some(w) = &mut self.wheel_scale {
                // Only matches of a rover whose wheels and scans agree teach the scale: a
                // slip burst's matches would teach it the burst.
                if self.health.state() == LocalisationState::Tracking {
                    w.observe(odom, self.pose, trusted_along);
                } else {
                    w.restart();
                }
            }
        }
        let lost = self.health.state() == LocalisationState::Lost;
        let new_keyframe = match self.graph.nodes.last() {
            None => true,
            Some(last) => {
                let d = self.pose.relative_to(last);
                d.x_m.hypot(d.y_m) >= self.cfg.keyframe_translation_m
                    || d.yaw_rad.abs() >= self.cfg.keyframe_rotation_rad
            }
        };
        // While lost nothing is written into the map.
        let keyframe_added = new_keyframe && !lost && points.len() >= self.cfg.min_scan_points;
        if keyframe_added {
            let dense = dense.into_owned();
            self.add_keyframe(time_s, odom, points, &dense);
        }
        let keyframe = self.graph.nodes.len().saturating_sub(1);
        let kf_pose = self.graph.nodes.get(keyframe).copied().unwrap_or(self.pose);
        self.scans.push(ScanPose {
            timestamp_s: time_s,
            keyframe,
            keyframe_from_scan: kf_pose.inverse() * self.pose,
        });
        self.odometry
            .settle(odom, self.pose, &prediction, relocalised);
        // Silent wheels bring their whole travel in their next reading: its time counts from
        // their last fresh one.
        if !sample.wheels_silent {
            self.last_fresh_wheels_s = Some(time_s);
        }
        if lost {
            self.forget_heading_references();
            self.last_odom_yaw = None;
        } else {
            self.last_odom_yaw = Some(odom.yaw_rad);
            let spans = [
                self.cfg.heading_window.map(|w| w.span_s),
                self.cfg.heading_departure.map(|d| d.window_s),
            ];
            if let Some(span_s) = spans.into_iter().flatten().reduce(f64::max) {
                while self
                    .heading_offsets
                    .front()
                    .is_some_and(|(t, _, _)| *t < time_s - span_s)
                {
                    self.heading_offsets.pop_front();
                }
                let offset = normalize_angle_rad(self.pose.yaw_rad - odom.yaw_rad);
                if let Some(departure) = self.cfg.heading_departure {
                    self.watch_departure(departure, time_s, offset);
                }
                self.heading_offsets
                    .push_back((time_s, offset, self.pose.position()));
            }
        }
        // They were seen for this scan, and are stale at the next.
        self.features.clear();
        self.point_heights.clear();
        Tracked {
            pose: self.pose,
            score,
            state: self.health.state(),
            keyframe_added,
        }
    }

    /// While lost: search the submaps around the dead-reckoned pose for the scan, widely
    /// (odometry may have been wrong for a while), and take the pose only if it is
    /// unambiguous. Nothing is written until then.
    fn try_relocalise(&mut self, time_s: f64, points: &[Point2]) {
        if points.len() < SEARCH_MIN_POINTS {
            return;
        }
        self.relocalise_searches += 1;
        let all_headings = self
            .searches_since_lost
            .is_multiple_of(RELOCALISE_ALL_HEADINGS_EVERY);
        self.searches_since_lost += 1;
        let sample = subsample(points, LOOP_POINTS);
        let window = SearchWindow {
            linear_m: RELOCALISE_WINDOW_M,
            angular_rad: if all_headings {
                std::f64::consts::PI
            } else {
                RELOCALISE_WINDOW_RAD
            },
            step_range_m: LOOP_STEP_RANGE_M,
        };
        let pose = self.pose;
        for s in self.relocalisation_submaps(pose.position()) {
            // The map is frozen while lost, so an active submap's precomputation stays valid
            // until tracking resumes (it is dropped then).
            let Some((_, m)) = self.verified_match(s, &sample, points, pose, &window, None) else {
                continue;
            };
            let origin = self.graph.nodes[self.submaps[s].origin_node];
            self.pose = origin * m.pose;
            let moved = self
                .lost_at
                .map_or(0.0, |p| p.position().distance_m(self.pose.position()));
            let reason = format!(
                "relocalised against submap {s} (match {:.2}, {:.2} m from where it was lost)",
                m.score, moved
            );
            for sub in &mut self.submaps {
                if !sub.finished {
                    sub.precomputed = None;
                }
            }
            if let Some(t) = self.health.relocalised(time_s, reason) {
                self.transitions.push((time_s, t));
            }
            self.lost_at = None;
            return;
        }
    }

    /// The submaps a relocalisation from `at` searches, nearest first: those with keyframes,
    /// not trimmed, whose origins lie nearest `at` within reach of the search.
    fn relocalisation_submaps(&self, at: Point2) -> Vec<usize> {
        let mut order: Vec<(f64, usize)> = (0..self.submaps.len())
            .filter(|s| self.submaps[*s].keyframes > 0 && !self.submaps[*s].trimmed)
            .map(|s| {
                let origin = self.graph.nodes[self.submaps[s].origin_node];
                (origin.position().distance_m(at), s)
            })
            .filter(|(d, _)| *d <= self.cfg.loop_search_radius_m + RELOCALISE_WINDOW_M)
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        order
            .into_iter()
            .take(self.cfg.loop_candidates)
            .map(|(_, s)| s)
            .collect()
    }

    /// Searches submap `s` for `points` (robot frame; `sample` a subset for the search)
    /// around `prior` (world frame) and refines the winner; returns the pose in the submap's
    /// frame only if it passes the checks every closure and relocalisation must: a high
    /// search score, no rival within the ambiguity margin, a high refined score, and a
    /// refinement that stayed near the searched pose.
    fn verified_match(
        &mut self,
        s: usize,
        sample: &[Point2],
        points: &[Point2],
        prior: Pose2,
        window: &SearchWindow,
        ridges: Option<ClosureRidges>,
    ) -> Option<(bnb::SearchResult, crate::matcher::Match)> {
        let origin = self.graph.nodes[self.submaps[s].origin_node];
        // Unknown cells around the submap as far as a closure's window reaches: a scan that
        // reaches no farther past the submap than the window is scored without bounds checks.
        let margin = (self.cfg.loop_window_m / self.cfg.frontend.resolution_m).ceil() as usize;
        self.searches += 1;
        if self.submaps[s].precomputed.is_none() {
            self.drop_precomputed_beyond(self.cfg.precomputed_kept.saturating_sub(1));
        }
        let rivals_beyond_m = self.start_rivals_beyond(self.submaps[s].origin_node);
        let sub = &mut self.submaps[s];
        sub.searched_at = self.searches;
        // A finished submap is kept whole while its precomputation is: the refinement below
        // looks up its probabilities.
        sub.map.make_whole();
        let precomputed = sub.precomputed.get_or_insert_with(|| {
            PrecomputedMap::with_margin(sub.map.finest(), LOOP_DEPTH, margin)
        });
        let margin = self.cfg.loop_ambiguity_margin;
        let found = bnb::search_allowing_ridges(
            precomputed,
            sample,
            origin.inverse() * prior,
            window,
            self.cfg.loop_search_min_score,
            margin,
            ridges.map(|r| r.dip),
            rivals_beyond_m,
        )?;
        if found.is_ambiguous(margin) {
            return None;
        }
        let refine = MatcherConfig {
            prior_translation_weight: 0.0,
            prior_rotation_weight: 0.0,
            ..self.cfg.frontend.matcher
        };
        let m = match_scan(&sub.map, points, found.pose, &refine);
        let moved = m.pose.relative_to(&found.pose);
        (m.score >= self.cfg.loop_min_score && moved.x_m.hypot(moved.y_m) < MAX_REFINE_SHIFT_M)
            .then_some((found, m))
    }

    /// How far from a closure search's winner a rival must lie, into the submap begun at
    /// keyframe `origin_node`: [`MapperConfig::start_rivals_beyond_m`] for the submaps begun
    /// at the known start (drawn where the rover knew its pose), while it applies; `None`
    /// (the search's own 30 cm) otherwise.
    fn start_rivals_beyond(&self, origin_node: usize) -> Option<f64> {
        let at_start = origin_node < self.cfg.submap_keyframes;
        let applies = self.homing || !self.cfg.start_rivals_homing_only;
        self.cfg
            .start_rivals_beyond_m
            .filter(|_| at_start && applies)
    }

    /// Drops the closure-search precomputations of the submaps searched longest ago until
    /// at most `kept` remain.
    fn drop_precomputed_beyond(&mut self, kept: usize) {
        let mut held: Vec<&mut Submap> = self
            .submaps
            .iter_mut()
            .filter(|s| s.precomputed.is_some())
            .collect();
        let excess = held.len().saturating_sub(kept);
        held.sort_by_key(|s| s.searched_at);
        for sub in held.into_iter().take(excess) {
            sub.precomputed = None;
            if sub.finished {
                sub.map.cut_to_content();
            }
        }
    }

    /// Cuts to their content the finished submaps but `newest` that no closure search has
    /// precomputed since they finished or were last searched: they are looked up only now
    /// and then (see [`MapperConfig::precomputed_kept`]). The newest is left whole for the
    /// searches that come its way soon after it finishes.
    fn cut_unsearched(&mut self, newest: usize) {
        for (i, sub) in self.submaps.iter_mut().enumerate() {
            if i != newest
                && sub.finished
                && !sub.trimmed
                && sub.precomputed.is_none()
                && sub.map.is_whole()
            {
                sub.map.cut_to_content();
            }
        }
    }

    /// Tells the mapper whether the rover is driving home at the end of its exploring, or
    /// is home (see [`MapperConfig::start_rivals_homing_only`]).
    pub fn set_homing(&mut self, homing: bool) {
        self.homing = homing;
    }

    /// The current pose estimate.
    pub fn pose(&self) -> Pose2 {
        self.pose
    }

    /// The localisation state now.
    pub fn state(&self) -> LocalisationState {
        self.health.state()
    }

    /// Changes of localisation state since last asked, with the scan time of each.
    pub fn take_transitions(&mut self) -> Vec<(f64, Transition)> {
        std::mem::take(&mut self.transitions)
    }

    /// The last tracking match's information matrix (x, y, theta), for the covariance.
    pub fn last_information(&self) -> [[f64; 3]; 3] {
        self.last_information
    }

    /// How far the pose may be from the truth: standard deviations of its position (metres)
    /// and heading (radians), by the path through the graph from the start to the newest
    /// keyframe and the travel since ([`crate::drift`]), and by a swing of the heading from
    /// the gyro's since the pose was last set ([`MapperConfig::heading_departure`]). `None` without
    /// [`MapperConfig::pose_uncertainty`] or before the first keyframe.
    pub fn pose_uncertainty(&mut self) -> Option<(f64, f64)> {
        let model = self.cfg.pose_uncertainty?;
        let weak_total = &self.keyframe_weak_total_m;
        let unmatched = &self.keyframe_unmatched_m;
        let (position_m, heading_rad) = self.paths_from_start.newest(&model, &self.graph, |e| {
            let weak_upto = |k: usize| weak_total.get(k).copied().unwrap_or(0.0);
            Travel {
                driven_m: e.measurement.x_m.hypot(e.measurement.y_m),
                weak_m: weak_upto(e.to) - weak_upto(e.from),
                unmatched_m: unmatched.get(e.to).copied().unwrap_or(0.0),
            }
        })?;
        let newest = self.graph.nodes.last()?;
        let since = Travel {
            driven_m: newest.position().distance_m(self.pose.position()),
            weak_m: self.weak_m,
            unmatched_m: self.unmatched_m,
        };
        // A heading that swung from the gyro's carries the position off by the swing over
        // every metre since ([`MapperConfig::heading_departure`]).
        let (departed_m, departed_rad) = self.departed.map_or((0.0, 0.0), |d| {
            (
                d.swing_rad * d.from.distance_m(self.pose.position()),
                d.swing_rad,
            )
        });
        Some((
            position_m + model.position_m(since) + departed_m,
            heading_rad + model.heading_rad(since) + departed_rad,
        ))
    }

    /// Where the rover could drive to tie its pose back to ground mapped while it knew where
    /// it was: the keyframe nearest to `from` (in a straight line, in the map as the graph
    /// places it now) whose position the path from the start now holds within `within_m`
    /// (standard deviation, as [`pose_uncertainty`](Self::pose_uncertainty) last worked it
    /// out), whose scan kept at least `min_points` returns, and which `wanted` accepts (a
    /// navigator's places that closed nothing), among the keyframes of finished submaps the
    /// closure search would take for a new keyframe now. Only a closure can cut the path
    /// from the start short: a keyframe of a submap still being built is matched by
    /// tracking, which ties the pose to that submap and not to the start. A closure needs
    /// something to match, and the ground where the uncertainty began to grow is often where
    /// the scans saw little. `None` without such a keyframe, or without the uncertainty's
    /// model.
    pub fn anchored_place_near(
        &self,
        from: Point2,
        within_m: f64,
        min_points: usize,
        wanted: impl Fn(Point2) -> bool,
    ) -> Option<Point2> {
        let model = self.cfg.pose_uncertainty?;
        let sigma = self.paths_from_start.position_m();
        // The keyframe the next scan would add.
        let next = self.graph.nodes.len();
        let keyframes = self
            .submaps
            .iter()
            .filter(|s| self.searched_for_closures(s, next))
            .flat_map(|s| s.origin_node..s.origin_node + s.keyframes)
            .filter(|&k| sigma.get(k).is_some_and(|d| model.floor_m + d <= within_m));
        self.nearest_keyframe(from, keyframes, |p| p.len() >= min_points, wanted)
    }

    /// Where a lost rover could drive to find itself again: the keyframe nearest to `from`
    /// (in the map as the graph placed it when the rover lost its place) but at least
    /// `min_distance_m` from it, whose scan kept at least `min_points` returns, and which
    /// `wanted` accepts (places already tried), among the keyframes whose submap a
    /// relocalisation from the keyframe's own position searches. A scan that rich was
    /// matched to its submap when it was taken, where the rover's view when it was lost is
    /// often nearly empty (in the open middle of a hall, one rock), and turning on the spot
    /// shows nothing more. The scan must also pin a pose every way: at least
    /// `min_weakest_share` of its surfaces' weight across the direction they pin least
    /// ([`weakest_direction_share`]). A long straight wall gives hundreds of returns, and
    /// a search along it finds rivals all the way (BENCHMARKS.md, "Lidar beams that return
    /// nothing": a rover gave up by the north wall with its pose 0.24 m off). `None`
    /// without such a keyframe.
    pub fn relocalisation_place(
        &self,
        from: Point2,
        min_distance_m: f64,
        min_points: usize,
        min_weakest_share: f64,
        wanted: impl Fn(Point2) -> bool,
    ) -> Option<Point2> {
        let keyframes = (0..self.submaps.len()).flat_map(|s| {
            let sub = &self.submaps[s];
            (sub.origin_node..sub.origin_node + sub.keyframes).filter(move |&k| {
                self.graph
                    .nodes
                    .get(k)
                    .is_some_and(|pose| self.relocalisation_submaps(pose.position()).contains(&s))
            })
        });
        let usable =
            |p: &[Point2]| p.len() >= min_points && weakest_direction_share(p) >= min_weakest_share;
        let wanted = |p: Point2| p.distance_m(from) >= min_distance_m && wanted(p);
        self.nearest_keyframe(from, keyframes, usable, wanted)
    }

    /// The position nearest to `from` of `keyframes` whose scans `usable` accepts and which
    /// `wanted` accepts.
    fn nearest_keyframe(
        &self,
        from: Point2,
        keyframes: impl Iterator<Item = usize>,
        usable: impl Fn(&[Point2]) -> bool,
        wanted: impl Fn(Point2) -> bool,
    ) -> Option<Point2> {
        keyframes
            .filter(|&k| self.keyframe_points.get(k).is_some_and(|p| usable(p)))
            .filter_map(|k| self.graph.nodes.get(k).map(Pose2::position))
            .filter(|p| wanted(*p))
            .min_by(|a, b| a.distance_m(from).total_cmp(&b.distance_m(from)))
    }

    fn add_keyframe(&mut self, time_s: f64, odom: Pose2, points: Vec<Point2>, dense: &[Point2]) {
        let node = self.graph.nodes.len();
        self.graph.nodes.push(self.pose);
        if let Some(walls) = &mut self.walls {
            if node == 0 {
                walls.set_references(self.pose.yaw_rad, &points);
            } else if let Some((yaw_rad, information)) = walls.measure(self.pose.yaw_rad, &points) {
                let off_sigmas =
                    || normalize_angle_rad(self.pose.yaw_rad - yaw_rad).abs() * information.sqrt();
                if self
                    .cfg
                    .optimize_on_wall_heading_sigmas
                    .is_some_and(|k| off_sigmas() > k)
                {
                    self.pending_closures = true;
                }
                self.graph.heading_priors.push(HeadingPrior {
                    node,
                    yaw_rad,
                    information,
                });
            }
        }
        self.keyframe_points.push(points);
        let mut clear = std::mem::take(&mut self.clear_rays);
        if let Some(spacing_m) = self.cfg.clear_rays_spacing_m.filter(|_| !clear.is_empty()) {
            let at = self.pose.position();
            if self
                .last_clear_rays_at
                .is_some_and(|last| last.distance_m(at) < spacing_m)
            {
                clear.clear();
            } else {
                self.last_clear_rays_at = Some(at);
            }
        }
        self.keyframe_clear.push(clear);
        self.keyframe_odom.push((time_s, odom));
        let unmatched_m = std::mem::take(&mut self.unmatched_m);
        self.keyframe_unmatched_m.push(unmatched_m);
        let weak_hop_m = std::mem::take(&mut self.weak_m);
        let weak_total_m = self.keyframe_weak_total_m.last().copied().unwrap_or(0.0) + weak_hop_m;
        self.keyframe_weak_total_m.push(weak_total_m);
        if node > 0 {
            let mut measurement = self.graph.nodes[node - 1].inverse() * self.pose;
            // Travel the wheels alone carried may be all slip (a burst: 90 %).
            let position = if unmatched_m > 0.0 {
                1.0 / (SEQUENTIAL_SIGMA_M + unmatched_m).powi(2)
            } else {
                SEQUENTIAL_POSITION_INFORMATION
            };
            let mut information = [position, position, SEQUENTIAL_HEADING_INFORMATION];
            if let Some(share) = self.cfg.weak_hop_share.filter(|_| weak_hop_m > 0.0) {
                // The residual's x is along the later keyframe's heading, which the rover
                // drove along.
                let along = 1.0 / (SEQUENTIAL_SIGMA_M + share * weak_hop_m).powi(2);
                information[0] = information[0].min(along);
            }
            if let Some(gyro) = self.cfg.gyro_heading {
                let (t0, odom0) = self.keyframe_odom[node - 1];
                let turned = normalize_angle_rad(odom.yaw_rad - odom0.yaw_rad);
                measurement = Pose2::new(measurement.x_m, measurement.y_m, turned);
                information[2] = gyro.information(time_s - t0).max(information[2]);
            }
            self.graph.edges.push(Edge {
                from: node - 1,
                to: node,
                measurement,
                information,
                information_axis_rad: 0.0,
                robust: false,
            });
        }
        // Submaps: start one when there is none, a second halfway through the first, and
        // finish the older when it is full.
        let active: Vec<usize> = (0..self.submaps.len())
            .filter(|i| !self.submaps[*i].finished)
            .collect();
        let half = self.cfg.submap_keyframes / 2;
        if active.is_empty() || (active.len() == 1 && self.submaps[active[0]].keyframes >= half) {
            let f = &self.cfg.frontend;
            self.submaps.push(Submap {
                origin_node: node,
                map: MultiResMap::new(f.resolution_m, f.levels)
                    .with_miss_rule(f.miss_rule)
                    .with_miss_margin(f.miss_margin),
                published: published_grid(&self.cfg),
                keyframes: 0,
                finished: false,
                precomputed: None,
                searched_at: 0,
                trimmed: false,
                hits: self.cfg.ndt_refine.map(NdtMap::new),
                drawn: Vec::new(),
            });
        }
        let active: Vec<usize> = (0..self.submaps.len())
            .filter(|i| !self.submaps[*i].finished)
            .collect();
        let mut into = Vec::with_capacity(active.len());
        for s in active {
            self.insert(s, node, dense);
            into.push((s, self.graph.nodes[self.submaps[s].origin_node]));
            if self.submaps[s].keyframes >= self.cfg.submap_keyframes {
                self.submaps[s].finished = true;
                self.submaps[s].hits = None;
                // Never searched: final, only its content is kept.
                if let Some(published) = &mut self.submaps[s].published {
                    published.cut_to_content();
                }
                self.cut_unsearched(s);
                self.trim_submaps(s);
            }
        }
        // The same beams in the assembly's frame, for the live map.
        let beams: Vec<(Point2, bool)> = self.keyframe_points[node]
            .iter()
            .map(|p| (self.pose.transform_point(*p), true))
            .chain(
                self.keyframe_clear[node]
                    .iter()
                    .map(|p| (self.pose.transform_point(*p), false)),
            )
            .collect();
        self.assembly.trace(&into, self.pose.position(), &beams);
        // Closures are searched every few keyframes and the graph re-optimised in batches:
        // both cost far more than tracking.
        if node.is_multiple_of(self.cfg.loop_every_keyframes.max(1)) && self.close_loops(node) {
            self.pending_closures = true;
        }
        if self.pending_closures && node.is_multiple_of(self.cfg.optimize_every_keyframes.max(1)) {
            // The active submaps' keyframes as they were drawn into them, before the
            // optimisation bends them.
            let active = self
                .cfg
                .track_in_submap_frame
                .then(|| {
                    self.submaps
                        .iter()
                        .filter(|s| !s.finished && s.keyframes > 0)
                        .map(|s| s.origin_node)
                        .min()
                })
                .flatten()
                .map(|first| (first, self.graph.nodes[first..].to_vec()));
            let (steps, later_cap) = (
                self.cfg.graph_iterations,
                self.cfg.graph_later_cap.unwrap_or(usize::MAX),
            );
            self.graph.optimize_with_later_cap(steps, later_cap);
            if let Some(limit) = self.cfg.drop_closures_beyond
                && self.graph.drop_robust_edges_beyond(limit) > 0
            {
                self.graph.optimize_with_later_cap(steps, later_cap);
            }
            if let Some((first, drawn)) = active {
                // The active submaps' cells show those keyframes where they were: move them
                // with the oldest one as a block, so tracking goes on in cells that agree
                // with it. Once their submaps are finished, the optimisation is free to bend
                // them.
                move_as_block(&mut self.graph.nodes[first..], &drawn);
            }
            if let Some(bend) = self.cfg.redraw_bent_submaps {
                self.redraw_submaps_bent_beyond(bend, None);
            }
            // Where a stall began moves with the pose, into the optimised frame.
            self.odometry
                .shift(self.graph.nodes[node] * self.pose.inverse());
            self.pose = self.graph.nodes[node];
            // The optimisation may turn the pose: the gyro's heading is anchored anew.
            self.forget_heading_references();
            if let Some(w) = &mut self.wheel_scale {
                w.restart();
            }
            self.pending_closures = false;
        }
    }

    /// Drops what the tracked heading was compared with the gyro's against (the anchor, the
    /// windows' offsets, a swing found): the pose was set by something other than tracking.
    fn forget_heading_references(&mut self) {
        self.heading_anchor = None;
        self.heading_offsets.clear();
        self.departed = None;
    }

    /// Keeps the largest swing of the tracked heading less the gyro's, `offset_rad` at
    /// `time_s`, from the offsets within the departure window before it, from
    /// `departure.min_swing_rad` on, with where the rover was at the offset it swung from
    /// ([`MapperConfig::heading_departure`]).
    fn watch_departure(&mut self, departure: HeadingDeparture, time_s: f64, offset_rad: f64) {
        let swing = self
            .heading_offsets
            .iter()
            .filter(|(t, _, _)| *t >= time_s - departure.window_s)
            .map(|(_, o, at)| (normalize_angle_rad(offset_rad - o).abs(), *at))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((swing_rad, from)) = swing.filter(|(s, _)| *s >= departure.min_swing_rad) {
            match &mut self.departed {
                Some(d) => d.swing_rad = d.swing_rad.max(swing_rad),
                None => self.departed = Some(Departed { swing_rad, from }),
            }
        }
    }

    /// Whether keyframe `node`'s closure search takes submap `sub`: finished, not trimmed,
    /// and not so recent that it holds the keyframe's own neighbourhood.
    fn searched_for_closures(&self, sub: &Submap, node: usize) -> bool {
        sub.finished && !sub.trimmed && sub.origin_node + 2 * self.cfg.submap_keyframes <= node
    }

    /// Searches finished submaps near `node` for a closure; returns whether one was added.
    fn close_loops(&mut self, node: usize) -> bool {
        let min_points = self
            .cfg
            .closure_min_points
            .map_or(SEARCH_MIN_POINTS, |n| n.max(SEARCH_MIN_POINTS));
        if self.keyframe_points[node].len() < min_points {
            return false;
        }
        let pose = self.graph.nodes[node];
        let mut added = false;
        // The nearest finished submaps that do not contain this keyframe's neighbourhood.
        let mut candidates: Vec<(f64, usize)> = (0..self.submaps.len())
            .filter_map(|s| {
                let sub = &self.submaps[s];
                if !self.searched_for_closures(sub, node) {
                    return None;
                }
                let end = if self.cfg.loop_search_nearest_keyframe {
                    (sub.origin_node + sub.keyframes).min(self.graph.nodes.len())
                } else {
                    sub.origin_node + 1
                };
                let d = self.graph.nodes[sub.origin_node..end]
                    .iter()
                    .map(|n| n.position().distance_m(pose.position()))
                    .fold(f64::INFINITY, f64::min);
                (d <= self.cfg.loop_search_radius_m).then_some((d, s))
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        let points = subsample(&self.keyframe_points[node], LOOP_POINTS);
        for (_, s) in candidates.into_iter().take(self.cfg.loop_candidates) {
            let window = self.closure_window(self.submaps[s].origin_node, node);
            let full = std::mem::take(&mut self.keyframe_points[node]);
            let ridges = self.cfg.closure_ridges;
            let found = self.verified_match(s, &points, &full, pose, &window, ridges);
            self.keyframe_points[node] = full;
            if let Some((searched, m)) = found {
                let (information, information_axis_rad) = match (searched.ridge, ridges) {
                    (Some(ridge), Some(r)) => {
                        r.information(&ridge, self.cfg.loop_ambiguity_margin, m.pose)
                    }
                    _ => closure_information(&m, self.cfg.closure_weighting),
                };
                let (from, measurement) = self.closure_anchor(s, m.pose);
                // The information's axes are turned from the measured pose's own, which
                // stay where they are when the measurement is re-expressed.
                let closure = Edge {
                    from,
                    to: node,
                    measurement,
                    information,
                    information_axis_rad,
                    robust: true,
                };
                let i = &m.information;
                let (weakest, _, _) = crate::ndt::eigen_symmetric2(i[0][0], i[0][1], i[1][1]);
                let pinned = self
                    .cfg
                    .closure_min_information
                    .is_none_or(|f| weakest >= f);
                let within_drift = self.within_drift(&closure);
                let ends = self.keyframe_points[node]
                    .iter()
                    .map(|p| m.pose.transform_point(*p));
                let (from_behind, on_walls) = self.submaps[s].map.finest().hits_from_behind(
                    m.pose.position(),
                    ends,
                    FROM_BEHIND_BACK_M,
                );
                let walls_from_front =
                    self.walls_reached_from_front(&closure, from_behind, on_walls);
                self.closure_records.push(ClosureRecord {
                    on_walls,
                    from_behind,
                    edge: closure,
                    search_score: searched.score,
                    rival_score: searched.rival_score,
                    score: m.score,
                    information: m.information,
                    within_drift,
                    accepted: false,
                });
                if within_drift && pinned && walls_from_front {
                    added |= self.propose_closure(closure, s);
                }
            }
        }
        added
    }

    /// The keyframe a closure that matched at `matched` in submap `s`'s frame is measured
    /// from, and the measurement from it (see [`MapperConfig::closure_from_nearest_drawn`]).
    fn closure_anchor(&self, s: usize, matched: Pose2) -> (usize, Pose2) {
        let sub = &self.submaps[s];
        if !self.cfg.closure_from_nearest_drawn {
            return (sub.origin_node, matched);
        }
        let distance = |p: &Pose2| p.position().distance_m(matched.position());
        sub.drawn
            .iter()
            .enumerate()
            .min_by(|a, b| distance(a.1).total_cmp(&distance(b.1)))
            .map_or((sub.origin_node, matched), |(k, drawn)| {
                (sub.origin_node + k, drawn.inverse() * matched)
            })
    }

    /// The closure search window for joining keyframe `to` to the submap begun at keyframe
    /// `from`: the configured window, narrowed to what the map can have drifted by between
    /// them (see [`ClosureDrift`]). A pose outside that would be refused anyway, and most
    /// searches join places a few metres of path apart, so the narrow window spares most of
    /// the search (the rotations above all: each is a pass over the scan).
    fn closure_window(&self, from: usize, to: usize) -> SearchWindow {
        let mut window = SearchWindow {
            linear_m: self.cfg.loop_window_m,
            angular_rad: self.cfg.loop_window_rad,
            step_range_m: LOOP_STEP_RANGE_M,
        };
        let Some(bound) = self.cfg.closure_drift else {
            return window;
        };
        // Past this much path neither bound is narrower than the window.
        let limit_m = ((window.linear_m - bound.base_m) / bound.per_m)
            .max((window.angular_rad - bound.base_rad) / bound.per_m_rad);
        if let Some(path_m) =
            self.graph
                .path_length_within(from, to, limit_m, self.drift_length(&bound))
        {
            window.linear_m = window.linear_m.min(bound.base_m + bound.per_m * path_m);
            window.angular_rad = window
                .angular_rad
                .min(bound.base_rad + bound.per_m_rad * path_m);
        }
        if let Some(weak) = self.cfg.weak_travel {
            window.linear_m = (window.linear_m + self.weak_slide_m(from, to))
                .min(weak.max_window_m.max(window.linear_m));
        }
        window
    }

    /// How far the map can have slid between keyframes `from` and `to` over the travel the
    /// matches did not pin ([`WeakTravel`]): the least such travel on any path between them
    /// through the graph. A closure that joined the two sides of a slide since has undone it;
    /// the drift of the path's other travel is [`ClosureDrift`]'s to bound.
    fn weak_slide_m(&self, from: usize, to: usize) -> f64 {
        let Some(weak) = self.cfg.weak_travel else {
            return 0.0;
        };
        let total = |k: usize| self.keyframe_weak_total_m.get(k).copied().unwrap_or(0.0);
        let along_chain = total(from.max(to)) - total(from.min(to));
        if along_chain <= 0.0 {
            return 0.0;
        }
        let unpinned_m = |e: &Edge| {
            if !e.robust && e.to == e.from + 1 {
                total(e.to) - total(e.from)
            } else {
                0.0
            }
        };
        let least = self
            .graph
            .path_length_within(from, to, along_chain, unpinned_m)
            .unwrap_or(along_chain);
        weak.drift_share * least
    }

    /// Whether the correction `closure` asks for is one the map can have drifted by: its
    /// turn agrees with the walls' ([`Mapper::walls_agree`]), and its shift is no more than
    /// the path between its ends can have drifted ([`ClosureDrift`], widened by the slide
    /// of [`WeakTravel`]; no bound without `closure_drift`).
    fn within_drift(&self, closure: &Edge) -> bool {
        if !self.walls_agree(closure) {
            return false;
        }
        let Some(bound) = self.cfg.closure_drift else {
            return true;
        };
        let asked_m = self.asked_shift_m(closure);
        let always_m = bound.base_m + self.weak_slide_m(closure.from, closure.to);
        if asked_m <= always_m {
            return true;
        }
        let needed_m = (asked_m - always_m) / bound.per_m;
        self.graph
            .path_length_within(
                closure.from,
                closure.to,
                needed_m,
                self.drift_length(&bound),
            )
            .is_none()
    }

    /// Whether `closure`'s hits reach the submap's walls from the side the submap saw them
    /// from: false when it asks to move its keyframe farther than
    /// [`FacesSeenFrom::beyond_m`] and more than [`FacesSeenFrom::max_share`] of its hits on
    /// walls, `from_behind` of `on_walls`, come through ground the submap never saw open.
    fn walls_reached_from_front(
        &self,
        closure: &Edge,
        from_behind: usize,
        on_walls: usize,
    ) -> bool {
        let Some(rule) = self.cfg.faces_seen_from else {
            return true;
        };
        on_walls < rule.min_hits
            || from_behind as f64 <= rule.max_share * on_walls as f64
            || self.asked_shift_m(closure) <= rule.beyond_m
    }

    /// Whether the turn `closure` measures between its two keyframes agrees with the one
    /// the walls measured of them (see
    /// [`crate::walls::WallHeadingConfig::closure_gate_sigmas`]); true where either
    /// keyframe's heading was not measured.
    fn walls_agree(&self, closure: &Edge) -> bool {
        let Some(sigmas) = self.cfg.wall_headings.and_then(|w| w.closure_gate_sigmas) else {
            return true;
        };
        let priors = &self.graph.heading_priors;
        // The first keyframe's heading is the start's, known exactly.
        let measured = |node: usize| -> Option<(f64, f64)> {
            if node == 0 {
                return self.graph.nodes.first().map(|n| (n.yaw_rad, 0.0));
            }
            let i = priors.partition_point(|p| p.node < node);
            let p = priors.get(i).filter(|p| p.node == node)?;
            Some((p.yaw_rad, p.information.recip()))
        };
        let (Some((from_rad, from_var)), Some((to_rad, to_var))) =
            (measured(closure.from), measured(closure.to))
        else {
            return true;
        };
        let differs = normalize_angle_rad(closure.measurement.yaw_rad - (to_rad - from_rad));
        differs.abs() <= sigmas * (from_var + to_var).sqrt()
    }

    /// How far an edge counts towards the drift a path can have built up: its travel (a
    /// closure [`ClosureDrift::hop_m`]). Travel the wheels alone carried counts as wholly
    /// uncertain: a slip burst where the lidar sees nothing leaves the pose off by up to all
    /// of it, however short the path.
    fn drift_length(&self, bound: &ClosureDrift) -> impl Fn(&Edge) -> f64 + '_ {
        let (hop_m, per_m) = (bound.hop_m, bound.per_m);
        move |e: &Edge| {
            let unmatched_m = if e.to == e.from + 1 {
                self.keyframe_unmatched_m.get(e.to).copied().unwrap_or(0.0)
            } else {
                0.0
            };
            PoseGraph::travelled_m(e, hop_m) + unmatched_m / per_m.max(1e-6)
        }
    }

    /// How far `closure` asks to move its keyframe from where the graph has it, metres.
    fn asked_shift_m(&self, closure: &Edge) -> f64 {
        let wanted = self.graph.nodes[closure.from] * closure.measurement;
        wanted
            .position()
            .distance_m(self.graph.nodes[closure.to].position())
    }

    /// The correction a closure asks of its keyframe: where the closure puts the keyframe,
    /// relative to where the graph has it now (in the world frame).
    fn correction(&self, closure: &Edge) -> Pose2 {
        let wanted = self.graph.nodes[closure.from] * closure.measurement;
        wanted * self.graph.nodes[closure.to].inverse()
    }

    /// A closure enters the graph only when another closure found within the last few
    /// keyframes asks for the same correction: drift changes slowly, so two true closures
    /// from nearby keyframes agree, while a false match in a look-alike place rarely has a
    /// partner that is wrong in the same way. `closure` matched in submap `submap`. Returns
    /// whether edges were added.
    fn propose_closure(&mut self, closure: Edge, submap: usize) -> bool {
        let node = closure.to;
        self.recent_closures
            .retain(|c| c.edge.to + CONFIRM_WITHIN_KEYFRAMES >= node);
        let mine = self.correction(&closure);
        // Compare the corrections where they act: at this keyframe.
        let at = self.graph.nodes[node];
        let asks_far = self
            .cfg
            .distinct_confirmation_beyond_m
            .is_some_and(|far_m| self.asked_shift_m(&closure) > far_m);
        let mut confirmed = false;
        let mut to_accept = Vec::new();
        for (i, c) in self.recent_closures.iter().enumerate() {
            let other = &c.edge;
            let same_pair = other.to == node && other.from == closure.from;
            if same_pair || (asks_far && c.submap == submap) {
                continue;
            }
            let d = (mine * at).relative_to(&(self.correction(other) * at));
            if d.x_m.hypot(d.y_m) <= CONFIRM_TRANSLATION_M
                && d.yaw_rad.abs() <= CONFIRM_ROTATION_RAD
            {
                confirmed = true;
                if !c.accepted {
                    to_accept.push(i);
                }
            }
        }
        for i in to_accept {
            self.recent_closures[i].accepted = true;
            let edge = self.recent_closures[i].edge;
            self.accept_closure(edge);
        }
        if confirmed {
            self.accept_closure(closure);
        }
        self.recent_closures.push(ProposedClosure {
            edge: closure,
            submap,
            accepted: confirmed,
        });
        confirmed
    }

    /// Puts a confirmed closure into the graph and marks its record accepted.
    fn accept_closure(&mut self, mut closure: Edge) {
        if let Some(span) = self.cfg.closure_share_span {
            // The n-th closure between the same two stretches weighs 1/n: their matches
            // share the cells and the slide of the map there, so their errors are one error
            // counted many times, not many that average out.
            let near = |a: usize, b: usize| a.abs_diff(b) <= span;
            let earlier = self
                .graph
                .edges
                .iter()
                .filter(|e| e.robust && near(e.from, closure.from) && near(e.to, closure.to))
                .count();
            let share = 1.0 / (1 + earlier) as f64;
            for i in &mut closure.information {
                *i *= share;
            }
        }
        self.graph.edges.push(closure);
        self.closures += 1;
        if let Some(r) = self
            .closure_records
            .iter_mut()
            .rev()
            .find(|r| r.edge.from == closure.from && r.edge.to == closure.to)
        {
            r.accepted = true;
        }
    }

    /// Every closure a search found and verified, in the order found, accepted or not.
    pub fn closure_records(&self) -> &[ClosureRecord] {
        &self.closure_records
    }

    /// The time of keyframe `node`'s scan, seconds.
    pub fn keyframe_time_s(&self, node: usize) -> Option<f64> {
        self.keyframe_odom.get(node).map(|(t, _)| *t)
    }

    /// Every scan's pose, from the optimised keyframes.
    pub fn trajectory(&self) -> Vec<StampedPose> {
        self.scans
            .iter()
            .map(|s| StampedPose {
                timestamp_s: s.timestamp_s,
                pose: self
                    .graph
                    .nodes
                    .get(s.keyframe)
                    .map_or(s.keyframe_from_scan, |k| *k * s.keyframe_from_scan),
            })
            .collect()
    }

    /// The map now: every live submap drawn at its optimised pose (finished ones kept
    /// assembled between calls, see [`Assembly`]).
    pub fn render_map(&mut self) -> crate::occupancy::OccupancyGrid {
        let active = self.sync_assembly();
        let active: Vec<_> = active
            .into_iter()
            .map(|(s, pose)| (self.submaps[s].published(), pose))
            .collect();
        self.assembly.render(&active)
    }

    /// The state of every cell of the map, kept live between calls (see [`Assembly`]): the
    /// active submaps as traced scan by scan, so a cell may differ from
    /// [`render_map`](Self::render_map)'s where a beam crosses it at a corner.
    pub fn map_states(&mut self) -> realms_core::Grid<crate::occupancy::CellState> {
        let view = self.live_map();
        realms_core::Grid::from_cells(view.geometry, view.states.to_vec())
            .expect("one state per cell")
    }

    /// [`map_states`](Self::map_states) without copying, with where it changed since an
    /// earlier view.
    pub fn live_map(&mut self) -> crate::assembly::LiveView<'_> {
        let active = self.sync_assembly();
        let active: Vec<_> = active
            .into_iter()
            .map(|(s, pose)| (s, self.submaps[s].published(), pose))
            .collect();
        self.assembly.live_states(&active)
    }

    /// The pose of every submap's origin now, by submap index (trimmed ones included: their
    /// keyframes stay in the graph).
    pub fn submap_origins(&self) -> Vec<Pose2> {
        self.submaps
            .iter()
            .map(|s| self.graph.nodes[s.origin_node])
            .collect()
    }

    /// The newest submap (the one new observations belong to longest) and its origin.
    pub fn newest_submap(&self) -> Option<(usize, Pose2)> {
        let i = self.submaps.len().checked_sub(1)?;
        Some((i, self.graph.nodes[self.submaps[i].origin_node]))
    }

    /// The newest submap's newest keyframe: its node in the pose graph, and its pose now.
    pub fn newest_keyframe(&self) -> Option<(usize, Pose2)> {
        let sub = self.submaps.last()?;
        let node = (sub.origin_node + sub.keyframes).checked_sub(1)?;
        (sub.keyframes > 0).then(|| (node, self.graph.nodes[node]))
    }

    /// Keyframe `node`'s pose now in submap `submap`'s frame (that of the submap's first
    /// keyframe, as the submap's cells are drawn); `None` if either is unknown.
    pub fn keyframe_in_submap(&self, submap: usize, node: usize) -> Option<Pose2> {
        let origin = self
            .graph
            .nodes
            .get(self.submaps.get(submap)?.origin_node)?;
        Some(origin.inverse() * *self.graph.nodes.get(node)?)
    }

    /// Places every finished submap in the assembly at its pose now; returns the submaps
    /// still being built, with their poses.
    fn sync_assembly(&mut self) -> Vec<(usize, Pose2)> {
        let mut active = Vec::new();
        for (s, sub) in self.submaps.iter().enumerate() {
            if sub.keyframes == 0 || sub.trimmed {
                continue;
            }
            let pose = self.graph.nodes[sub.origin_node];
            if sub.finished {
                self.assembly.place(s, sub.published(), pose);
            } else {
                active.push((s, pose));
            }
        }
        active
    }

    /// Drops the grids of finished submaps that the just-finished submap `newest` makes
    /// redundant: their origins lie within the trim radius of its origin, and it knows
    /// nearly every cell they know ([`TRIM_MIN_COVERED`]). Keeps a long mission's memory
    /// bounded by the area explored, not the distance driven. Their keyframes stay in the
    /// graph.
    fn trim_submaps(&mut self, newest: usize) {
        let Some(radius) = self.cfg.trim_radius_m else {
            return;
        };
        let at = self.graph.nodes[self.submaps[newest].origin_node].position();
        for s in 0..newest {
            let origin = self.graph.nodes[self.submaps[s].origin_node].position();
            let sub = &self.submaps[s];
            if sub.finished
                && !sub.trimmed
                && origin.distance_m(at) <= radius
                && self.known_share(s, newest) >= TRIM_MIN_COVERED
            {
                let sub = &mut self.submaps[s];
                self.assembly.remove(s, sub.published());
                sub.map.release();
                if let Some(published) = &mut sub.published {
                    published.release();
                }
                sub.precomputed = None;
                sub.trimmed = true;
            }
        }
    }

    /// The share of the cells submap `old` knows (free or occupied) that submap `new` knows
    /// too, with both at their poses now; 1 when `old` knows nothing.
    fn known_share(&self, old: usize, new: usize) -> f64 {
        let old_origin = self.graph.nodes[self.submaps[old].origin_node];
        let new_origin = self.graph.nodes[self.submaps[new].origin_node];
        let new_from_old = new_origin.inverse() * old_origin;
        let grid = self.submaps[old].map.finest();
        let covering = self.submaps[new].map.finest();
        let geo = grid.geometry();
        let (mut known, mut covered) = (0usize, 0usize);
        // The cells not kept (see `OccupancyGrid::cut_to_content`) are unknown.
        let (kept, log_odds) = grid.kept_log_odds();
        for (i, l) in log_odds.iter().enumerate() {
            if CellState::from_log_odds(*l) == CellState::Unknown {
                continue;
            }
            known += 1;
            let centre = geo.cell_center(Cell {
                x: kept.x0 + i % kept.width,
                y: kept.y0 + i / kept.width,
            });
            let there = covering.log_odds_at(new_from_old.transform_point(centre));
            if CellState::from_log_odds(there) != CellState::Unknown {
                covered += 1;
            }
        }
        if known == 0 {
            1.0
        } else {
            covered as f64 / known as f64
        }
    }

    /// Draws every finished submap again from its keyframes at their poses now, relative to
    /// its first. A submap's cells show its keyframes where tracking had them when they
    /// were drawn; the graph moves them later, and the final map should show the final
    /// trajectory (as Karto and slam_toolbox draw their maps from every scan at its
    /// optimised pose). Only submaps bent more than `FINAL_REDRAW_BEND` are drawn again,
    /// unless [`MapperConfig::final_map_hit_range_m`] asks for every one with hits cut to a
    /// range (the active submaps stay as they are). Costs one keyframe's tracing per
    /// keyframe kept: for a final map, not for every optimisation.
    pub fn redraw_finished_submaps(&mut self) {
        match self.cfg.final_map_hit_range_m {
            Some(range) => self.redraw_submaps_bent_beyond(EVERY_SUBMAP, Some(range)),
            None => self.redraw_submaps_bent_beyond(FINAL_REDRAW_BEND, None),
        }
    }

    /// Draws again every finished submap whose keyframes the graph has moved, relative to
    /// its first, farther than `bend` from where they were drawn, with hits out to
    /// `hit_range_m` (if set).
    fn redraw_submaps_bent_beyond(&mut self, bend: SubmapBend, hit_range_m: Option<f64>) {
        let f = self.cfg.frontend;
        let mut redrawn = false;
        for s in 0..self.submaps.len() {
            let sub = &self.submaps[s];
            if !sub.finished || sub.trimmed || sub.keyframes == 0 {
                continue;
            }
            let (first, n) = (sub.origin_node, sub.keyframes);
            let origin = self.graph.nodes[first];
            let bent = sub.drawn.iter().enumerate().any(|(k, drawn)| {
                let d = (origin.inverse() * self.graph.nodes[first + k]).relative_to(drawn);
                d.x_m.hypot(d.y_m) > bend.translation_m || d.yaw_rad.abs() > bend.rotation_rad
            });
            if !bent {
                continue;
            }
            redrawn = true;
            let fresh = MultiResMap::new(f.resolution_m, f.levels)
                .with_miss_rule(f.miss_rule)
                .with_miss_margin(f.miss_margin);
            self.assembly.remove(s, self.submaps[s].published());
            self.submaps[s].map = fresh;
            self.submaps[s].published = published_grid(&self.cfg);
            self.submaps[s].keyframes = 0;
            self.submaps[s].precomputed = None;
            self.submaps[s].drawn.clear();
            for node in first..first + n {
                let dense = match f.densify {
                    Some(d) => crate::frontend::densify(&self.keyframe_points[node], d),
                    None => self.keyframe_points[node].clone(),
                };
                self.insert_within(s, node, &dense, hit_range_m);
            }
            // Only finished submaps are redrawn: final again, only their content is kept.
            self.submaps[s].map.cut_to_content();
            if let Some(published) = &mut self.submaps[s].published {
                published.cut_to_content();
            }
        }
        if redrawn {
            self.sync_assembly();
        }
    }

    /// Optimises the graph to the end (ten Gauss-Newton steps).
    pub fn finish(&mut self) {
        self.graph.optimize(10);
    }
}

/// Puts `nodes` back in the relative poses of `drawn` (the same nodes before they moved),
/// moved as one block so the first keeps its pose now.
fn move_as_block(nodes: &mut [Pose2], drawn: &[Pose2]) {
    let (Some(first), Some(first_drawn)) = (nodes.first(), drawn.first()) else {
        return;
    };
    let moved = *first * first_drawn.inverse();
    for (n, d) in nodes.iter_mut().zip(drawn) {
        *n = moved * *d;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frontend::Densify;
    use crate::health::TurnCheck;
    use crate::occupancy::MissMargin;

    #[test]
    fn a_closure_on_a_ridge_is_held_along_it_as_the_score_falls() {
        let ridges = ClosureRidges::default();
        // The rival 0.6 m along the ridge (at 30 degrees in the submap), scoring 0.04 below
        // the winner, margin 0.08: half the margin's fall over twice the reference distance,
        // an eighth of the full information along the ridge.
        let ridge = crate::bnb::Ridge {
            direction_rad: 30f64.to_radians(),
            rival_m: 0.6,
            drop: 0.04,
        };
        let measured = Pose2::new(1.0, 2.0, 10f64.to_radians());
        let (information, axis_rad) = ridges.information(&ridge, 0.08, measured);
        let [full, across, heading] = CLOSURE_INFORMATION;
        assert!(
            (information[0] - full / 8.0).abs() < 1e-9,
            "{information:?}"
        );
        assert_eq!([information[1], information[2]], [across, heading]);
        // The axes are turned from the measured pose's by the ridge's direction.
        assert!((axis_rad - 20f64.to_radians()).abs() < 1e-12, "{axis_rad}");
        // A rival nearer and lower than the reference pins it no more than a clear winner.
        let steep = crate::bnb::Ridge {
            rival_m: 0.2,
            drop: 0.07,
            ..ridge
        };
        assert_eq!(ridges.information(&steep, 0.08, measured).0[0], full);
    }

    #[test]
    fn a_closure_along_a_bare_wall_holds_the_graph_only_across_it() {
        // A match pinned firmly along the submap's x (a wall across x) and loosely along y.
        let m = crate::matcher::Match {
            pose: Pose2::new(3.0, 4.0, 0.3),
            score: 0.8,
            information: [[5000.0, 0.0, 0.0], [0.0, 100.0, 0.0], [0.0, 0.0, 5e4]],
        };
        let weighting = ClosureWeighting {
            translation_reference: 2000.0,
            heading_reference: Some(1e5),
        };
        let (information, axis) = closure_information(&m, Some(weighting));
        assert_eq!(information, [20.0, 400.0, 1250.0]);
        // The weak axis is the submap's y, turned into the measured pose's frame.
        let expected = std::f64::consts::FRAC_PI_2 - 0.3;
        let off = normalize_angle_rad(axis - expected);
        // An axis and its opposite are the same axis.
        assert!(off.abs() < 1e-9 || (off.abs() - std::f64::consts::PI).abs() < 1e-9);
        assert_eq!(closure_information(&m, None), (CLOSURE_INFORMATION, 0.0));
    }

    #[test]
    fn the_active_keyframes_move_as_one_block_with_the_first() {
        let drawn = [
            Pose2::new(1.0, 0.0, 0.0),
            Pose2::new(1.3, 0.1, 0.2),
            Pose2::new(1.5, 0.4, 0.5),
        ];
        // The optimisation turned the first by 0.1 rad and bent the others differently.
        let mut nodes = [
            Pose2::new(1.0, 0.2, 0.1),
            Pose2::new(1.2, 0.5, 0.1),
            Pose2::new(1.9, 0.1, 0.9),
        ];
        move_as_block(&mut nodes, &drawn);
        let first = Pose2::new(1.0, 0.2, 0.1).inverse() * nodes[0];
        assert!(first.x_m.abs() < 1e-12 && first.y_m.abs() < 1e-12 && first.yaw_rad.abs() < 1e-12);
        for k in 1..3 {
            let was = drawn[0].inverse() * drawn[k];
            let now = nodes[0].inverse() * nodes[k];
            assert!((was.x_m - now.x_m).abs() < 1e-12 && (was.y_m - now.y_m).abs() < 1e-12);
            assert!((was.yaw_rad - now.yaw_rad).abs() < 1e-12);
        }
        // The block turned with the first: the last keyframe swung round it.
        assert!((nodes[2].yaw_rad - 0.6).abs() < 1e-12, "{:?}", nodes[2]);
    }

    /// A mapper whose graph is a straight drive of `n` keyframes 0.25 m apart along x.
    fn straight_drive(n: usize) -> Mapper {
        let mut mapper = Mapper::new(MapperConfig {
            closure_drift: Some(ClosureDrift {
                base_m: 0.3,
                per_m: 0.05,
                hop_m: 2.0,
                base_rad: 3f64.to_radians(),
                per_m_rad: 0.2f64.to_radians(),
            }),
            ..MapperConfig::default()
        });
        for k in 0..n {
            mapper
                .graph
                .nodes
                .push(Pose2::new(0.25 * k as f64, 0.0, 0.0));
            if k > 0 {
                mapper.graph.edges.push(Edge {
                    from: k - 1,
                    to: k,
                    measurement: Pose2::new(0.25, 0.0, 0.0),
                    information: [400.0, 400.0, 2500.0],
                    information_axis_rad: 0.0,
                    robust: false,
                });
            }
        }
        mapper
    }

    /// A closure from `from` that puts `to` `off_m` to the side of where the graph has it.
    fn closure(mapper: &Mapper, from: usize, to: usize, off_m: f64) -> Edge {
        let wanted = mapper.graph.nodes[to] * Pose2::new(0.0, off_m, 0.0);
        Edge {
            from,
            to,
            measurement: mapper.graph.nodes[from].inverse() * wanted,
            information: [400.0, 400.0, 2500.0],
            information_axis_rad: 0.0,
            robust: true,
        }
    }

    #[test]
    fn a_far_correction_reaching_its_walls_from_behind_is_refused_and_a_near_one_not() {
        let mut mapper = straight_drive(120);
        let far = closure(&mapper, 0, 100, 2.5);
        let near = closure(&mapper, 0, 100, 0.3);
        // Without the test every closure reaches its walls from the front.
        assert!(mapper.walls_reached_from_front(&far, 60, 100));
        mapper.cfg.faces_seen_from = Some(FacesSeenFrom::default());
        // The lander's faces: 60 of 100 hits from behind, 2.5 m asked.
        assert!(!mapper.walls_reached_from_front(&far, 60, 100));
        // Right closures: few from behind; a near correction is never tested.
        assert!(mapper.walls_reached_from_front(&far, 3, 100));
        assert!(mapper.walls_reached_from_front(&far, 30, 100));
        assert!(mapper.walls_reached_from_front(&near, 60, 100));
        // Too few hits on walls to tell: a few rocks seen from their other side (seed 22's
        // rover3, 7-12 of 11-22 hits, closures 3-5 cm from the truth).
        assert!(mapper.walls_reached_from_front(&far, 12, 20));
    }

    #[test]
    fn a_far_correction_is_confirmed_only_from_another_submap_if_so_asked() {
        // Keyframes 100 and 101 both closed 1 m to the side into the submap begun at 0: they
        // confirm each other unless the far correction must come from another submap.
        // The partner's submap begins at keyframe `partner_from`: the first submap at 0, the
        // second at 40.
        let accepted = |distinct: Option<f64>, partner_from: usize| -> usize {
            let mut mapper = straight_drive(120);
            mapper.cfg.distinct_confirmation_beyond_m = distinct;
            let before = mapper.graph.edges.len();
            mapper.propose_closure(closure(&mapper, 0, 100, 1.0), 0);
            let partner_submap = usize::from(partner_from > 0);
            mapper.propose_closure(closure(&mapper, partner_from, 101, 1.0), partner_submap);
            mapper.graph.edges.len() - before
        };
        assert_eq!(accepted(None, 0), 2);
        assert_eq!(accepted(Some(0.5), 0), 0);
        assert_eq!(accepted(Some(0.5), 40), 2);
        // A near correction is confirmed within one submap as before.
        assert_eq!(accepted(Some(1.5), 0), 2);
    }

    #[test]
    fn the_closure_search_looks_only_as_far_as_the_map_can_have_drifted() {
        // 10 m of path: 0.3 + 0.05 * 10 = 0.8 m and 3 + 0.2 * 10 = 5 degrees.
        let mut mapper = straight_drive(401);
        let near = mapper.closure_window(0, 40);
        assert!((near.linear_m - 0.8).abs() < 1e-9, "{}", near.linear_m);
        assert!((near.angular_rad.to_degrees() - 5.0).abs() < 1e-9);
        // 100 m: wider than the configured window, which then stands.
        let far = mapper.closure_window(0, 400);
        assert_eq!(far.linear_m, mapper.cfg.loop_window_m);
        assert_eq!(far.angular_rad, mapper.cfg.loop_window_rad);
        // A closure joining the two ends makes them near: 0.25 + 2 + 0.25 m.
        mapper.graph.edges.push(closure(&mapper, 1, 399, 0.0));
        let joined = mapper.closure_window(0, 400);
        assert!(
            (joined.linear_m - 0.425).abs() < 1e-9,
            "{}",
            joined.linear_m
        );
        mapper.cfg.closure_drift = None;
        assert_eq!(
            mapper.closure_window(0, 40).linear_m,
            mapper.cfg.loop_window_m
        );
    }

    #[test]
    fn the_start_s_rivals_are_counted_farther_only_into_the_start_s_submaps_and_while_homing() {
        let mut mapper = Mapper::new(MapperConfig::default());
        let n = mapper.cfg.submap_keyframes;
        assert_eq!(mapper.start_rivals_beyond(0), None, "off by default");
        mapper.cfg.start_rivals_beyond_m = Some(0.5);
        mapper.cfg.start_rivals_homing_only = true;
        assert_eq!(mapper.start_rivals_beyond(0), None, "not homing yet");
        mapper.set_homing(true);
        assert_eq!(mapper.start_rivals_beyond(0), Some(0.5));
        assert_eq!(mapper.start_rivals_beyond(n - 1), Some(0.5));
        assert_eq!(mapper.start_rivals_beyond(n), None, "a submap begun later");
        mapper.set_homing(false);
        assert_eq!(mapper.start_rivals_beyond(0), None);
        mapper.cfg.start_rivals_homing_only = false;
        assert_eq!(mapper.start_rivals_beyond(0), Some(0.5), "at any time");
    }

    /// A finished submap at the origin that saw a wall 4 m east, then a newer one at the
    /// same place that saw a wall 4 m east too (`newer_looks_east`) or 4 m west; returns
    /// whether the older was dropped when the newer finished.
    fn older_dropped(newer_looks_east: bool) -> bool {
        let mut mapper = Mapper::new(MapperConfig {
            trim_radius_m: Some(3.0),
            ..MapperConfig::default()
        });
        let f = mapper.cfg.frontend;
        mapper.graph.nodes = vec![Pose2::IDENTITY; 2];
        let wall = |x_m: f64| -> Vec<(Point2, bool)> {
            (-20..=20)
                .map(|k| (Point2::new(x_m, 0.1 * k as f64), true))
                .collect()
        };
        for (node, x_m) in [(0, 4.0), (1, if newer_looks_east { 4.0 } else { -4.0 })] {
            let mut map = MultiResMap::new(f.resolution_m, f.levels);
            map.insert(Point2::new(0.0, 0.0), &wall(x_m));
            mapper.submaps.push(Submap {
                origin_node: node,
                map,
                published: None,
                keyframes: 1,
                finished: true,
                precomputed: None,
                searched_at: 0,
                trimmed: false,
                hits: None,
                drawn: vec![Pose2::IDENTITY],
            });
        }
        mapper.trim_submaps(1);
        mapper.submaps[0].trimmed
    }

    #[test]
    fn a_submap_is_dropped_only_for_a_newer_one_that_knows_its_ground() {
        assert!(older_dropped(true));
        assert!(!older_dropped(false));
    }

    #[test]
    fn closures_between_the_same_stretches_share_their_weight_if_so_asked() {
        let mut mapper = straight_drive(200);
        mapper.cfg.closure_share_span = Some(30);
        for (from, to) in [(10, 150), (20, 160), (45, 185), (100, 199)] {
            let c = closure(&mapper, from, to, 0.0);
            mapper.accept_closure(c);
        }
        let weights: Vec<f64> = mapper
            .graph
            .edges
            .iter()
            .filter(|e| e.robust)
            .map(|e| e.information[0] / CLOSURE_INFORMATION[0])
            .collect();
        // The second within 30 of the first; the third within 30 of the second only; the
        // fourth near none.
        assert_eq!(weights, vec![1.0, 0.5, 0.5, 1.0]);
    }

    #[test]
    fn a_closure_into_a_bent_submap_is_measured_from_the_keyframe_that_drew_its_cells() {
        // The truth and the graph: a straight drive along x. The submap of its first 30
        // keyframes was drawn while tracking drifted sideways, 0.2 m by its end.
        let mut mapper = straight_drive(60);
        let f = mapper.cfg.frontend;
        let bend = |k: usize| 0.2 * (k as f64 / 29.0).powi(2);
        mapper.submaps.push(Submap {
            origin_node: 0,
            map: MultiResMap::new(f.resolution_m, f.levels),
            published: None,
            keyframes: 30,
            finished: true,
            precomputed: None,
            searched_at: 0,
            trimmed: false,
            hits: None,
            drawn: (0..30)
                .map(|k| Pose2::new(0.25 * k as f64, bend(k), 0.0))
                .collect(),
        });
        // Keyframe 59 comes back 0.5 m beside keyframe 28 and matches into the cells it drew.
        let truth = Pose2::new(0.25 * 28.0, 0.5, 0.3);
        let matched = mapper.submaps[0].drawn[28] * (mapper.graph.nodes[28].inverse() * truth);
        let placed = |mapper: &Mapper| {
            let (from, measurement) = mapper.closure_anchor(0, matched);
            let at = mapper.graph.nodes[from] * measurement;
            (from, at.position().distance_m(truth.position()))
        };
        // From the submap's first keyframe the closure carries the bend.
        let (from, off_m) = placed(&mapper);
        assert_eq!(from, 0);
        assert!((off_m - bend(28)).abs() < 1e-9, "{off_m}");
        mapper.cfg.closure_from_nearest_drawn = true;
        let (from, off_m) = placed(&mapper);
        assert_eq!(from, 28);
        assert!(off_m < 1e-9, "{off_m}");
    }

    #[test]
    fn a_closure_may_correct_only_as_far_as_the_path_between_its_ends_can_drift() {
        // 10 m between the ends: 0.3 + 0.05 * 10 = 0.8 m allowed.
        let mapper = straight_drive(41);
        assert!(mapper.within_drift(&closure(&mapper, 0, 40, 0.7)));
        assert!(!mapper.within_drift(&closure(&mapper, 0, 40, 0.9)));
        // The lander's square fitted one side over, 2.4 m away, after 100 m: allowed then.
        let mut mapper = straight_drive(401);
        assert!(mapper.within_drift(&closure(&mapper, 0, 400, 2.4)));
        // ... but not once a closure has joined the two stretches: 0.25 + 2 + 0.25 m.
        let shortcut = closure(&mapper, 1, 399, 0.0);
        mapper.graph.edges.push(shortcut);
        assert!(!mapper.within_drift(&closure(&mapper, 0, 400, 2.4)));
        assert!(mapper.within_drift(&closure(&mapper, 0, 400, 0.4)));
        // Without a bound, any correction the window finds is allowed.
        mapper.cfg.closure_drift = None;
        assert!(mapper.within_drift(&closure(&mapper, 0, 400, 2.4)));
    }

    #[test]
    fn with_a_gyro_the_edges_between_keyframes_take_its_turn_at_its_weight() {
        let gyro = GyroHeading {
            rad_per_sqrt_s: 1e-3,
            bias_rad_s: 2e-4,
        };
        // Over one second: (1e-3)^2 + (2e-4)^2 = 1.04e-6 rad^2.
        assert!((gyro.information(1.0) - 1.0 / 1.04e-6).abs() < 1e-3);
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.gyro_heading = Some(gyro);
        let mut mapper = Mapper::new(cfg);
        // A curving drive; the odometry's frame is its own, so only its motion counts.
        let truth_at = |k: usize| {
            let k = k as f64;
            Pose2::new(0.05 * k, 0.01 * k, (0.8 * k).to_radians())
        };
        let odom_frame = Pose2::new(5.0, -3.0, 0.4);
        for k in 0..80 {
            let truth = truth_at(k);
            mapper.add_points(0.1 * k as f64, odom_frame * truth, sparse_hall_scan(truth));
        }
        let sequential: Vec<&Edge> = mapper
            .graph
            .edges
            .iter()
            .filter(|e| e.to == e.from + 1)
            .collect();
        assert!(
            sequential.len() >= 5,
            "{} keyframes",
            mapper.graph.nodes.len()
        );
        for e in sequential {
            let (t0, _) = mapper.keyframe_odom[e.from];
            let (t1, _) = mapper.keyframe_odom[e.to];
            let step = |t: f64| (t / 0.1).round() as usize;
            let turned = truth_at(step(t1)).yaw_rad - truth_at(step(t0)).yaw_rad;
            // Exactly the odometry's turn: a match is never this exact.
            assert!((e.measurement.yaw_rad - turned).abs() < 1e-9, "{e:?}");
            assert!((e.information[2] - gyro.information(t1 - t0)).abs() < 1e-6);
        }
    }

    #[test]
    fn travel_with_nothing_to_match_may_be_corrected_by_all_of_it() {
        // 10 m of path allow 0.3 + 0.05 * 10 = 0.8 m; 0.5 m of it carried by the wheels
        // alone (a slip burst in an empty stretch may have eaten all of it) allow 1.3 m.
        let mut mapper = straight_drive(41);
        mapper.keyframe_unmatched_m = vec![0.0; 41];
        assert!(!mapper.within_drift(&closure(&mapper, 0, 40, 1.2)));
        mapper.keyframe_unmatched_m[20] = 0.5;
        assert!(mapper.within_drift(&closure(&mapper, 0, 40, 1.2)));
        assert!(!mapper.within_drift(&closure(&mapper, 0, 40, 1.4)));
    }

    #[test]
    fn travel_the_matches_did_not_pin_widens_the_closure_search_and_its_bound() {
        // 10 m of path allow 0.3 + 0.05 * 10 = 0.8 m. Of those, 4 m slid along a bare
        // wall: 15 % of it, 0.6 m, more; the window grows by as much, to its 6 m cap.
        let mut mapper = straight_drive(401);
        mapper.cfg.weak_travel = Some(WeakTravel::default());
        mapper.keyframe_weak_total_m = vec![0.0; 401];
        assert!(!mapper.within_drift(&closure(&mapper, 0, 40, 1.2)));
        assert!((mapper.closure_window(0, 40).linear_m - 0.8).abs() < 1e-9);
        for k in 10..401 {
            mapper.keyframe_weak_total_m[k] = 4.0f64.min(0.25 * (k - 10) as f64);
        }
        assert!(mapper.within_drift(&closure(&mapper, 0, 40, 1.2)));
        assert!(!mapper.within_drift(&closure(&mapper, 0, 40, 1.5)));
        assert!((mapper.closure_window(0, 40).linear_m - 1.4).abs() < 1e-9);
        // Both ends past the stretch: nothing slid between them.
        assert!((mapper.closure_window(30, 70).linear_m - 0.8).abs() < 1e-9);
        // A closure across the stretch has undone its slide.
        let mut joined = straight_drive(401);
        joined.cfg.weak_travel = Some(WeakTravel::default());
        joined.keyframe_weak_total_m = mapper.keyframe_weak_total_m.clone();
        joined.graph.edges.push(closure(&joined, 5, 30, 0.0));
        // (Its hop shortens the path to 1.25 + 2 + 2.5 m: 0.59 m.)
        assert!((joined.closure_window(0, 40).linear_m - 0.5875).abs() < 1e-9);
        assert!(!joined.within_drift(&closure(&joined, 0, 40, 1.2)));
        // A stretch of 40 m would widen the configured 5 m window by 6 m: held to 6 m.
        for k in 10..401 {
            mapper.keyframe_weak_total_m[k] = 40.0f64.min(0.25 * (k - 10) as f64);
        }
        assert_eq!(mapper.closure_window(0, 400).linear_m, 6.0);
    }

    #[test]
    fn a_closure_that_turns_two_wall_measured_keyframes_against_their_walls_is_refused() {
        let mut mapper = straight_drive(41);
        mapper.cfg.wall_headings = Some(crate::walls::WallHeadingConfig {
            closure_gate_sigmas: Some(2.0),
            ..crate::walls::WallHeadingConfig::default()
        });
        // Keyframe 40's walls measured it 0.3 degrees left of the graph, to 0.5 degrees.
        let sigma = 0.5f64.to_radians();
        mapper.graph.heading_priors.push(HeadingPrior {
            node: 40,
            yaw_rad: 0.3f64.to_radians(),
            information: sigma.powi(2).recip(),
        });
        let turned = |deg: f64| {
            let mut c = closure(&mapper, 0, 40, 0.0);
            c.measurement.yaw_rad += deg.to_radians();
            c
        };
        // The start's heading is exact: the closure may differ from the walls by 1 degree.
        assert!(mapper.within_drift(&turned(1.2)));
        assert!(mapper.within_drift(&turned(-0.6)));
        assert!(!mapper.within_drift(&turned(1.4)));
        assert!(!mapper.within_drift(&turned(-0.8)));
        // A keyframe the walls did not measure: only the path's drift bound (3 + 0.2 * 10
        // degrees, but the closure's rotation is not checked against it).
        let mut c = closure(&mapper, 0, 39, 0.0);
        c.measurement.yaw_rad += 2f64.to_radians();
        assert!(mapper.within_drift(&c));
    }

    #[test]
    fn travel_along_a_lone_wall_is_counted_as_unpinned_and_in_a_hall_not() {
        let weak_after = |scan: &dyn Fn(Pose2) -> Vec<Point2>| {
            let mut cfg = MapperConfig::default();
            cfg.frontend.max_range_m = 12.0;
            cfg.weak_travel = Some(WeakTravel::default());
            let mut mapper = Mapper::new(cfg);
            for k in 0..=60 {
                let truth = Pose2::new(0.05 * k as f64, 0.0, 0.0);
                mapper.add_points(0.1 * k as f64, truth, scan(truth));
            }
            mapper.keyframe_weak_total_m.last().copied().unwrap_or(0.0) + mapper.weak_m
        };
        let along_wall = weak_after(&lone_wall_scan);
        let in_hall = weak_after(&sparse_hall_scan);
        // 3 m driven; the first scan is not matched.
        assert!(along_wall > 2.5, "along the wall {along_wall:.2} m");
        assert!(in_hall < 0.3, "in the hall {in_hall:.2} m");
    }

    #[test]
    fn hops_along_a_lone_wall_hold_the_graph_loosely_along_the_heading_only() {
        let edges_after = |scan: &dyn Fn(Pose2) -> Vec<Point2>| {
            let mut cfg = MapperConfig::default();
            cfg.frontend.max_range_m = 12.0;
            cfg.weak_travel = Some(WeakTravel::default());
            cfg.weak_hop_share = Some(0.5);
            let mut mapper = Mapper::new(cfg);
            for k in 0..=60 {
                let truth = Pose2::new(0.05 * k as f64, 0.0, 0.0);
                mapper.add_points(0.1 * k as f64, truth, scan(truth));
            }
            let hops: Vec<f64> = (1..mapper.graph.nodes.len())
                .map(|k| mapper.keyframe_weak_total_m[k] - mapper.keyframe_weak_total_m[k - 1])
                .collect();
            (mapper.graph.edges.clone(), hops)
        };
        let (edges, hops) = edges_after(&lone_wall_scan);
        assert!(edges.len() >= 5, "{} edges", edges.len());
        for (e, hop_m) in edges.iter().zip(&hops).skip(1) {
            // Every hop after the first matched scan slid freely along the wall.
            assert!(*hop_m > 0.15, "{hop_m:.3} m unpinned in a hop");
            let expected = 1.0 / (SEQUENTIAL_SIGMA_M + 0.5 * hop_m).powi(2);
            assert!((e.information[0] - expected).abs() < 1e-9, "{e:?}");
            assert!(
                e.information[0] < SEQUENTIAL_POSITION_INFORMATION / 2.0,
                "{e:?}"
            );
            // Across the wall, and in heading, as firm as any matched hop.
            assert_eq!(e.information[1], SEQUENTIAL_POSITION_INFORMATION);
            assert_eq!(e.information[2], SEQUENTIAL_HEADING_INFORMATION);
        }
        // In a hall the matches pin every hop once the young map holds a few scans: the
        // later edges stay firm.
        let (edges, _) = edges_after(&sparse_hall_scan);
        assert!(edges.len() >= 5);
        for e in edges.iter().skip(2) {
            assert_eq!(e.information[0], SEQUENTIAL_POSITION_INFORMATION, "{e:?}");
        }
    }

    #[test]
    fn wheel_travel_without_returns_is_counted_and_loosens_its_edge() {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        let mut mapper = Mapper::new(cfg);
        let mut k = 0;
        let mut drive = |mapper: &mut Mapper, to_x: f64, see: bool| {
            while 0.05 * k as f64 <= to_x {
                let truth = Pose2::new(0.05 * k as f64, 0.0, 0.0);
                let points = if see {
                    sparse_hall_scan(truth)
                } else {
                    Vec::new()
                };
                mapper.add_points(0.1 * k as f64, truth, points);
                k += 1;
            }
        };
        drive(&mut mapper, 1.0, true);
        let before = mapper.graph.nodes.len();
        // A metre with no returns, then the hall again.
        drive(&mut mapper, 2.0, false);
        drive(&mut mapper, 2.4, true);
        let edge = mapper
            .graph
            .edges
            .iter()
            .find(|e| e.from + 1 == e.to && e.to == before)
            .expect("an edge across the blind stretch");
        let unmatched = mapper.keyframe_unmatched_m[before];
        assert!((unmatched - 1.0).abs() < 0.06, "{unmatched}");
        let expected = 1.0 / (SEQUENTIAL_SIGMA_M + unmatched).powi(2);
        assert!((edge.information[0] - expected).abs() < 1e-9, "{edge:?}");
        // Matched keyframes keep the firm edge.
        let matched = &mapper.graph.edges[0];
        assert_eq!(mapper.keyframe_unmatched_m[1], 0.0);
        assert_eq!(matched.information[0], SEQUENTIAL_POSITION_INFORMATION);
    }

    /// A noise-free 12 m scan from `pose` of a lone wall 1.5 m to the left of the x axis,
    /// running along it, 20 m long each way from the origin (a point every 5 cm).
    fn lone_wall_scan(pose: Pose2) -> Vec<Point2> {
        (0..800)
            .map(|i| Point2::new(-20.0 + 0.05 * i as f64, 1.5))
            .map(|p| pose.inverse().transform_point(p))
            .filter(|p| p.x_m.hypot(p.y_m) < 12.0)
            .collect()
    }

    #[test]
    fn a_miss_margin_shortens_the_beams_matched_against_not_those_of_the_published_map() {
        let scan = sparse_hall_scan(Pose2::IDENTITY);
        let first_scan = |margin: Option<MissMargin>| {
            let mut cfg = MapperConfig::default();
            cfg.frontend.max_range_m = 12.0;
            cfg.frontend.miss_margin = margin;
            let mut mapper = Mapper::new(cfg);
            mapper.add_points(0.0, Pose2::IDENTITY, scan.clone());
            mapper
        };
        let mut plain = first_scan(None);
        let mut margined = first_scan(Some(MissMargin {
            base_m: 0.1,
            per_m: 0.0,
        }));
        assert_eq!(
            margined.render_map().log_odds(),
            plain.render_map().log_odds(),
            "the published map is drawn as without a margin"
        );
        // The grid matched against leaves the cells just short of each hit uncleared.
        let cleared = |m: &Mapper| {
            let grid = m.submaps[0].map.finest();
            grid.log_odds().iter().filter(|l| **l < 0.0).count()
        };
        let (kept, all) = (cleared(&margined), cleared(&plain));
        assert!(
            kept + 200 < all,
            "{kept} cleared with the margin, {all} without"
        );
    }

    /// The mapper as the sparse-hall tests drive it: the rovers' 12 m reach, one grid
    /// level, keyframes 0.3 m apart.
    fn sparse_hall_config() -> MapperConfig {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.frontend.levels = 1;
        cfg.keyframe_translation_m = 0.3;
        cfg
    }

    /// A noise-free 1-degree, 12 m scan from `pose` in a sparse hall like the simulated
    /// one: two walls 9-10 m off, a 2 m square lander near by and a few round boulders.
    fn sparse_hall_scan(pose: Pose2) -> Vec<Point2> {
        let walls = [
            (-9.0, -10.0, 30.0, -10.0),
            (-9.0, -10.0, -9.0, 20.0),
            (3.0, 1.0, 5.0, 1.0),
            (5.0, 1.0, 5.0, 3.0),
            (5.0, 3.0, 3.0, 3.0),
            (3.0, 3.0, 3.0, 1.0),
        ];
        let boulders = [
            (-3.0, 2.0, 0.4),
            (1.0, -5.0, 0.6),
            (-5.0, -4.0, 0.3),
            (6.0, -2.0, 0.5),
        ];
        ray_cast_scan(pose, &walls, &boulders)
    }

    /// A noise-free 1-degree, 12 m scan from `pose` of wall segments `(x1, y1, x2, y2)` and
    /// round boulders `(x, y, radius)`.
    fn ray_cast_scan(
        pose: Pose2,
        walls: &[(f64, f64, f64, f64)],
        boulders: &[(f64, f64, f64)],
    ) -> Vec<Point2> {
        (0..360)
            .filter_map(|i| {
                let local = (i as f64).to_radians();
                let (dy, dx) = (pose.yaw_rad + local).sin_cos();
                let (px, py) = (pose.x_m, pose.y_m);
                let to_walls = walls.iter().filter_map(|&(x1, y1, x2, y2)| {
                    let (ex, ey) = (x2 - x1, y2 - y1);
                    let den = dx * ey - dy * ex;
                    if den.abs() < 1e-12 {
                        return None;
                    }
                    let t = ((x1 - px) * ey - (y1 - py) * ex) / den;
                    let u = ((x1 - px) * dy - (y1 - py) * dx) / den;
                    (t > 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
                });
                let to_boulders = boulders.iter().filter_map(|&(cx, cy, r)| {
                    // |p + t d - c| = r, the nearer root.
                    let (ox, oy) = (px - cx, py - cy);
                    let b = ox * dx + oy * dy;
                    let disc = b * b - (ox * ox + oy * oy - r * r);
                    let t = -b - disc.max(0.0).sqrt();
                    (disc >= 0.0 && t > 0.0).then_some(t)
                });
                let range = to_walls.chain(to_boulders).fold(f64::INFINITY, f64::min);
                (range < 12.0).then(|| Point2::new(range * local.cos(), range * local.sin()))
            })
            .collect()
    }

    /// The mean heading error, degrees, of a mapper turning in place through 160 degrees in
    /// 4-degree steps in the sparse hall, with exact odometry.
    fn mean_heading_error_turning_in_place(densify: Option<Densify>) -> f64 {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.frontend.densify = densify;
        let mut mapper = Mapper::new(cfg);
        let mut sum = 0.0;
        for k in 0..40 {
            let truth = Pose2::new(0.3, 0.2, (4.0 * k as f64).to_radians());
            let tracked = mapper.add_points(0.1 * k as f64, truth, sparse_hall_scan(truth));
            let err = normalize_angle_rad(tracked.pose.yaw_rad - truth.yaw_rad);
            sum += err.abs().to_degrees();
        }
        sum / 40.0
    }

    /// A mapper (set up by `customise` after small submaps searched for closures at every
    /// keyframe) driving four laps round a 2 m circle in the sparse hall with exact odometry,
    /// 60 steps of 6 degrees a lap; `after` is called after each step with its index, the
    /// tracked pose and the mapper.
    fn drive_laps(
        customise: impl FnOnce(&mut MapperConfig),
        mut after: impl FnMut(usize, Pose2, &mut Mapper),
    ) {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.submap_keyframes = 4;
        cfg.loop_every_keyframes = 1;
        customise(&mut cfg);
        let mut mapper = Mapper::new(cfg);
        for k in 0..240 {
            let a = (6.0 * k as f64).to_radians();
            let truth = Pose2::new(
                2.0 * a.cos(),
                -1.0 + 2.0 * a.sin(),
                a + std::f64::consts::FRAC_PI_2,
            );
            let tracked = mapper.add_points(0.5 * k as f64, truth, sparse_hall_scan(truth));
            after(k, tracked.pose, &mut mapper);
        }
    }

    /// The poses of a mapper driving the laps keeping at most `kept` closure-search
    /// precomputations, and the most it held at once.
    fn laps_keeping(kept: usize) -> (Vec<Pose2>, usize) {
        let (mut poses, mut most) = (Vec::new(), 0);
        drive_laps(
            |c| c.precomputed_kept = kept,
            |_, pose, mapper| {
                poses.push(pose);
                let held = mapper
                    .submaps
                    .iter()
                    .filter(|s| s.precomputed.is_some())
                    .count();
                most = most.max(held);
            },
        );
        (poses, most)
    }

    #[test]
    fn closure_precomputations_beyond_the_kept_are_dropped_and_the_answers_stay() {
        let (bounded, most_bounded) = laps_keeping(3);
        let (unbounded, most_unbounded) = laps_keeping(usize::MAX);
        assert!(most_bounded <= 3, "{most_bounded} held");
        assert!(
            most_unbounded > 6,
            "the laps search {most_unbounded} submaps"
        );
        assert!(bounded == unbounded, "the same poses either way");
    }

    /// The uncertainty's model for [`drive_laps`]: 2 cm at the start, 1 % of the path.
    fn laps_uncertainty() -> crate::drift::PoseUncertainty {
        crate::drift::PoseUncertainty {
            floor_m: 0.02,
            per_m: 0.01,
            weak_per_m: 0.0,
            unmatched_per_m: 0.0,
            closure_m: 2.0,
            heading_floor_rad: 0.001,
            heading_per_m_rad: 0.001,
        }
    }

    #[test]
    fn the_pose_uncertainty_grows_with_the_path_and_closures_cut_it_back() {
        let model = laps_uncertainty();
        // (sigma, closures so far, arc driven) after each step.
        let mut steps = Vec::new();
        let step_m = 2.0 * 6f64.to_radians();
        drive_laps(
            |c| c.pose_uncertainty = Some(model),
            |k, _, mapper| {
                let sigma = mapper.pose_uncertainty().expect("a keyframe by now").0;
                let closures = mapper.graph.edges.iter().filter(|e| e.robust).count();
                steps.push((sigma, closures, step_m * k as f64));
            },
        );
        let path_only = |arc_m: f64| 0.02 + 0.01 * arc_m;
        // Until the first closure the uncertainty is the path driven (its chords between
        // keyframes, a little shorter than the arc).
        let first = steps.iter().position(|s| s.1 > 0).expect("the laps close");
        assert!(first > 10, "closed at step {first}");
        for &(sigma, _, arc_m) in &steps[..first] {
            // (The matches put the keyframes within millimetres of the truth.)
            assert!(sigma <= path_only(arc_m) + 0.002, "{sigma} after {arc_m} m");
            assert!(
                sigma >= path_only(0.95 * arc_m) - 0.01,
                "{sigma} after {arc_m} m"
            );
        }
        // After four laps the closures tie the pose back to the start.
        let (last, _, arc_m) = steps[239];
        assert!(last < 0.5 * path_only(arc_m), "{last} after {arc_m:.0} m");
    }

    #[test]
    fn the_place_to_revisit_is_the_nearest_keyframe_of_a_finished_submap_the_start_held_close() {
        let model = laps_uncertainty();
        // The laps' circle: 2 m about (0, -1), the start at angle 0.
        let on_lap = |deg: f64| {
            let a = deg.to_radians();
            Point2::new(2.0 * a.cos(), -1.0 + 2.0 * a.sin())
        };
        let mut asked = Vec::new();
        drive_laps(
            |c| c.pose_uncertainty = Some(model),
            |k, pose, mapper| {
                if [1, 50].contains(&k) {
                    mapper.pose_uncertainty();
                    let here = pose.position();
                    let beside_60 = on_lap(60.0);
                    let any = |_: Point2| true;
                    asked.push([
                        mapper.anchored_place_near(here, 0.05, 10, any),
                        mapper.anchored_place_near(here, 0.01, 10, any),
                        mapper.anchored_place_near(here, 0.05, 1000, any),
                        mapper.anchored_place_near(beside_60, 0.05, 10, any),
                        mapper.anchored_place_near(beside_60, 0.05, 10, |p| {
                            p.distance_m(beside_60) > 1.0
                        }),
                    ]);
                }
            },
        );
        // At the first steps only the first submap holds keyframes, and it is still built.
        assert_eq!(asked[0], [None; 5]);
        // 300 degrees round the first lap (10.5 m driven, nothing closed yet), at (1.0,
        // -2.73): the keyframes within 0.05 m are those of the first 3 m (the first 86
        // degrees of the lap), and the nearest of them the start, at (2, -1). Under the
        // model's floor none is, nor where no scan kept 1,000 returns (a scan has 360 beams).
        let [place, none, sparse, from_60, not_near_60] = asked[1];
        let place = place.expect("the start's ground is anchored");
        assert!(place.distance_m(on_lap(0.0)) < 0.02, "{place:?}");
        assert_eq!(none, None);
        assert_eq!(sparse, None);
        // Asked from the lap at 60 degrees, the nearest is a keyframe there (they lie some
        // 12 degrees, 0.4 m, apart), not the start; with the keyframes within 1 m of it
        // unwanted, another of the first 86 degrees, farther off.
        let from_60 = from_60.expect("anchored ground at 60 degrees");
        assert!(from_60.distance_m(on_lap(60.0)) < 0.25, "{from_60:?}");
        let not_near_60 = not_near_60.expect("anchored ground farther off");
        let angle = (not_near_60.y_m + 1.0).atan2(not_near_60.x_m).to_degrees();
        assert!(
            not_near_60.distance_m(on_lap(60.0)) > 1.0 && (-1.0..=90.0).contains(&angle),
            "{not_near_60:?} at {angle:.0} degrees"
        );
    }

    #[test]
    fn filling_in_the_surfaces_keeps_the_heading_of_a_turn_in_place() {
        let filled = mean_heading_error_turning_in_place(Some(Densify {
            max_gap_m: 0.3,
            spacing_m: 0.05,
        }));
        // With the endpoints as they are, 0.66 degrees: the second keyframe's map holds the
        // turn the first match took.
        assert!(filled < 0.1, "mean heading error {filled:.3} deg");
    }

    /// The final heading error, degrees, of a mapper driving east through the sparse hall
    /// whose scans turn 0.3 degrees a scan against the gyro's heading (as matches do that
    /// each stray a little the same way), with the gyro's heading anchored or not, and with
    /// the gyro carrying the turns or not.
    fn heading_error_with_matches_straying(
        anchor_rad: Option<f64>,
        heading_map_share: Option<f64>,
    ) -> f64 {
        heading_error_with_matches_straying_beside_walls(anchor_rad, heading_map_share, None)
    }

    /// [`heading_error_with_matches_straying`] with the walls measuring the keyframes'
    /// headings, and the share applied only where they measure none, if `walls` says so.
    fn heading_error_with_matches_straying_beside_walls(
        anchor_rad: Option<f64>,
        heading_map_share: Option<f64>,
        walls: Option<bool>,
    ) -> f64 {
        heading_error_with_matches_straying_under(|cfg| {
            if let Some(share_without_walls) = walls {
                cfg.wall_headings = Some(WallHeadingConfig::default());
                cfg.heading_map_share_without_walls = share_without_walls;
            }
            cfg.heading_anchor_rad = anchor_rad;
            cfg.heading_map_share = heading_map_share;
        })
    }

    /// The heading error after 40 scans whose matches each stray 0.3 degrees from the
    /// gyro's, the rovers' gyro and gate set, then `configure` applied, degrees.
    fn heading_error_with_matches_straying_under(configure: impl FnOnce(&mut MapperConfig)) -> f64 {
        let mut cfg = sparse_hall_config();
        cfg.gyro_heading = Some(GyroHeading {
            rad_per_sqrt_s: 1e-3,
            bias_rad_s: 2e-4,
        });
        cfg.max_heading_step_rad = Some(1f64.to_radians());
        configure(&mut cfg);
        let mut mapper = Mapper::new(cfg);
        let mut last = 0.0;
        for k in 0..40 {
            let truth = Pose2::new(-6.0 + 0.05 * k as f64, -7.0, 0.0);
            let seen_from = Pose2::new(truth.x_m, truth.y_m, (0.3 * k as f64).to_radians());
            let tracked = mapper.add_points(0.1 * k as f64, truth, sparse_hall_scan(seen_from));
            last = normalize_angle_rad(tracked.pose.yaw_rad - truth.yaw_rad).to_degrees();
        }
        last.abs()
    }

    #[test]
    fn a_heading_turning_from_the_gyros_faster_than_the_window_allows_is_held_at_its_bound() {
        // Matches straying 0.3 degrees a scan (3 degrees a second), 11.9 degrees off in four
        // seconds unchecked. Bounded to half a degree within any two seconds, the heading may
        // stray a quarter of a degree a second: 1.0 degree in the four seconds.
        let unchecked = heading_error_with_matches_straying(None, None);
        let windowed = heading_error_with_matches_straying_under(|cfg| {
            cfg.heading_window = Some(HeadingWindow {
                span_s: 2.0,
                max_rad: 0.5f64.to_radians(),
            });
        });
        assert!(unchecked > 8.0, "{unchecked:.2} deg");
        assert!(windowed < 1.5, "{windowed:.2} deg");
    }

    /// The published position uncertainty after 40 scans driven east 5 cm apart, with a
    /// gyro that does not turn, and the scans seen from headings turned 0.3 degrees more each
    /// (`straying`) or not, with the heading departure watched (`watched`) or not.
    fn uncertainty_with_matches_straying(straying: bool, watched: bool) -> f64 {
        let mut mapper = Mapper::new(MapperConfig {
            pose_uncertainty: Some(laps_uncertainty()),
            heading_departure: watched.then(HeadingDeparture::default),
            ..sparse_hall_config()
        });
        for k in 0..40 {
            let truth = Pose2::new(-6.0 + 0.05 * k as f64, -7.0, 0.0);
            let turned = if straying { 0.3 * k as f64 } else { 0.0 };
            let seen_from = Pose2::new(truth.x_m, truth.y_m, turned.to_radians());
            mapper.add_points(0.1 * k as f64, truth, sparse_hall_scan(seen_from));
        }
        mapper.pose_uncertainty().expect("modelled").0
    }

    #[test]
    fn a_heading_that_swings_from_the_gyros_widens_the_published_uncertainty_and_a_steady_one_does_not()
     {
        // The matches turn the heading some 12 degrees from the gyro's over the 2 m driven:
        // watched, the uncertainty grows by the swing over the metres since it began.
        let unwatched = uncertainty_with_matches_straying(true, false);
        let watched = uncertainty_with_matches_straying(true, true);
        assert!(
            watched > unwatched + 0.25,
            "{watched:.3} m watched, {unwatched:.3} m not"
        );
        // Matches that agree with the gyro leave it as the path has it.
        assert_eq!(
            uncertainty_with_matches_straying(false, true),
            uncertainty_with_matches_straying(false, false)
        );
    }

    #[test]
    fn the_heading_window_bounds_an_offset_by_every_recent_one_across_the_half_turn() {
        let window = HeadingWindow {
            span_s: 2.0,
            max_rad: 0.5f64.to_radians(),
        };
        let deg = |d: f64| d.to_radians();
        // Within half a degree of both: passes.
        assert_eq!(
            window.clamp([deg(0.1), deg(0.4)].into_iter(), deg(0.3)),
            None
        );
        // Beyond the lower one's bound: held at it.
        let held = window
            .clamp([deg(0.1), deg(0.4)].into_iter(), deg(1.0))
            .expect("held");
        assert!((held - deg(0.6)).abs() < 1e-12, "{}", held.to_degrees());
        let held = window
            .clamp([deg(0.1), deg(0.4)].into_iter(), deg(-1.0))
            .expect("held");
        assert!((held - deg(-0.1)).abs() < 1e-12, "{}", held.to_degrees());
        // Offsets either side of the half turn are 0.4 degrees apart, not 359.6.
        assert_eq!(window.clamp([deg(179.9)].into_iter(), deg(-179.7)), None);
        let held = window
            .clamp([deg(179.9)].into_iter(), deg(-179.0))
            .expect("held");
        assert!(
            (normalize_angle_rad(held - deg(-179.6))).abs() < 1e-9,
            "{}",
            held.to_degrees()
        );
        // Recent offsets spread wider than the bound: nothing can satisfy them all.
        assert_eq!(
            window.clamp([deg(0.0), deg(2.0)].into_iter(), deg(5.0)),
            None
        );
    }

    #[test]
    fn a_heading_straying_from_the_gyros_since_the_pose_was_set_is_held_to_it() {
        // Each match strays 0.3 degrees, under the scan-to-scan gate of 1 degree: unchecked,
        // the heading follows the scans 11.9 degrees off; anchored, it stays within 0.3.
        let unchecked = heading_error_with_matches_straying(None, None);
        assert!(unchecked > 8.0, "{unchecked:.2} deg");
        let anchored = heading_error_with_matches_straying(Some(2f64.to_radians()), None);
        assert!(anchored < 3.0, "{anchored:.2} deg");
    }

    #[test]
    fn with_the_gyro_carrying_the_turns_a_straying_match_moves_the_heading_by_its_share_only() {
        // Matches straying 0.3 degrees a scan, 11.9 degrees off in 40 scans unchecked. With
        // the gyro carrying the turns the keyframes go in at the held headings, so later scans
        // stray from the map less than from the truth: moved 2 % of the way towards each
        // match the heading ends 0.17 degrees off, moved 30 % it ends 3.5 degrees off.
        let unchecked = heading_error_with_matches_straying(None, None);
        let slow = heading_error_with_matches_straying(None, Some(0.02));
        let fast = heading_error_with_matches_straying(None, Some(0.3));
        assert!(slow < 0.5, "{slow:.2} deg");
        assert!(
            fast > 2.0 && fast < unchecked / 2.0,
            "{fast:.2} / {unchecked:.2} deg"
        );
    }

    #[test]
    fn the_gyro_carries_no_turn_where_walls_measure_the_heading_if_so_asked() {
        // 3 m from the hall's south and 3-5 m from its west wall every scan has walls in
        // view: with the share kept for scans without walls, the heading is the one the
        // matches give without any share, to the last bit.
        let matches = heading_error_with_matches_straying_beside_walls(None, None, Some(false));
        let everywhere =
            heading_error_with_matches_straying_beside_walls(None, Some(0.02), Some(false));
        let without_walls =
            heading_error_with_matches_straying_beside_walls(None, Some(0.02), Some(true));
        assert!(everywhere != matches, "{everywhere} {matches}");
        assert_eq!(without_walls, matches);
    }

    #[test]
    fn keyframes_that_see_the_start_walls_measure_their_heading_against_them() {
        // Driving east 3 m off the south wall, tracked from odometry that turns 0.2
        // degrees a scan the rover does not: each keyframe's walls say where it truly faces.
        let mut cfg = sparse_hall_config();
        cfg.wall_headings = Some(WallHeadingConfig::default());
        let mut mapper = Mapper::new(cfg);
        for k in 0..60 {
            let truth = Pose2::new(-6.0 + 0.1 * k as f64, -7.0, 0.0);
            let odom = Pose2::new(truth.x_m, truth.y_m, (0.2 * k as f64).to_radians());
            mapper.add_points(0.1 * k as f64, odom, sparse_hall_scan(truth));
        }
        let walls = mapper.walls.as_ref().expect("configured");
        // The south wall and the west wall.
        assert_eq!(walls.references().len(), 2, "{:?}", walls.references());
        let keyframes = mapper.graph.nodes.len();
        let measured = &mapper.graph.heading_priors;
        assert!(
            keyframes > 10 && measured.len() + 1 == keyframes,
            "{} of {keyframes}",
            measured.len()
        );
        for prior in measured {
            let off = normalize_angle_rad(prior.yaw_rad).to_degrees();
            assert!(off.abs() < 0.05, "node {}: {off:.3} deg", prior.node);
        }
    }

    /// Drives east 3 m off the sparse hall's south wall, no closures searched; after 30
    /// scans every keyframe from the third on and the pose are turned 1.5 degrees about
    /// the third, as if tracking had carried a wrong heading into the submaps, and the
    /// drive goes on. Returns the tracked heading's error at the end, degrees.
    fn heading_error_after_a_turned_stretch(optimize_on_sigmas: Option<f64>) -> f64 {
        let mut cfg = sparse_hall_config();
        cfg.loop_candidates = 0;
        // Small submaps: by the turn, those still being built start after it.
        cfg.submap_keyframes = 6;
        cfg.wall_headings = Some(WallHeadingConfig::default());
        cfg.optimize_on_wall_heading_sigmas = optimize_on_sigmas;
        let mut mapper = Mapper::new(cfg);
        let mut tracked = Pose2::default();
        for k in 0..120 {
            if k == 30 {
                let pivot = mapper.graph.nodes[2];
                let turn = pivot * Pose2::new(0.0, 0.0, 1.5f64.to_radians()) * pivot.inverse();
                for node in &mut mapper.graph.nodes[2..] {
                    *node = turn * *node;
                }
                mapper.pose = turn * mapper.pose;
            }
            let truth = Pose2::new(-6.0 + 0.1 * k as f64, -7.0, 0.0);
            tracked = mapper
                .add_points(0.1 * k as f64, truth, sparse_hall_scan(truth))
                .pose;
        }
        normalize_angle_rad(tracked.yaw_rad).to_degrees()
    }

    #[test]
    fn a_heading_the_walls_measure_far_off_turns_the_pose_back_at_the_next_batch_if_so_asked() {
        // The submaps hold the turned heading: without a closure nothing turns it back ...
        let waiting = heading_error_after_a_turned_stretch(None);
        assert!((waiting - 1.5).abs() < 0.3, "{waiting:.3} deg");
        // ... unless the walls' measurements, some 3 standard deviations off, ask for the
        // graph at 2.
        let applied = heading_error_after_a_turned_stretch(Some(2.0));
        assert!(applied.abs() < 0.3, "{applied:.3} deg");
    }

    #[test]
    fn a_wheel_odometry_that_jumps_a_hundred_kilometres_is_no_motion_and_grows_no_map() {
        // Driving east 3 m off the sparse hall's south wall, the odometry's frame jumps
        // 1e5 m at the twentieth scan (a driver restarted, or a corrupt reading) and goes
        // on from there.
        let mut mapper = Mapper::new(sparse_hall_config());
        let jump = Pose2::new(1e5, -1e5, 0.0);
        let mut tracked = Pose2::default();
        let mut truth = Pose2::default();
        for k in 0..60 {
            truth = Pose2::new(-6.0 + 0.1 * k as f64, -7.0, 0.0);
            let odom = if k >= 20 { jump * truth } else { truth };
            tracked = mapper
                .add_points(0.1 * k as f64, odom, sparse_hall_scan(truth))
                .pose;
        }
        let off = tracked.position().distance_m(truth.position());
        assert!(off < 0.1, "{off:.3} m");
        let map = mapper.render_map();
        let cells = map.geometry().len();
        assert!(cells < 2_000_000, "{cells} cells");
    }

    /// Drives east 20 m through the sparse hall with exact odometry, a path 3 m off the
    /// south wall, past the boulders and the lander (further on, with the south wall alone in
    /// view, nothing pins the pose along it); returns the largest position error of the
    /// tracked pose, metres.
    fn worst_error_driving_with_exact_odometry(refine: Option<NdtConfig>) -> f64 {
        let mut cfg = sparse_hall_config();
        cfg.ndt_refine = refine;
        let mut mapper = Mapper::new(cfg);
        let mut worst: f64 = 0.0;
        for k in 0..=500 {
            let truth = Pose2::new(
                -6.0 + 0.04 * k as f64,
                -7.0 + 0.1 * (0.01 * k as f64).sin(),
                0.0,
            );
            let tracked = mapper.add_points(0.1 * k as f64, truth, sparse_hall_scan(truth));
            worst = worst.max(tracked.pose.position().distance_m(truth.position()));
        }
        worst
    }

    /// A match's information pinning the direction `heading_rad` by `along` and the one
    /// across it by `across` (per square metre), the matcher's prior `prior_weight` added to
    /// both; its heading pinned by 50.
    fn information_along(
        heading_rad: f64,
        along: f64,
        across: f64,
        prior_weight: f64,
    ) -> [[f64; 3]; 3] {
        let (s, c) = heading_rad.sin_cos();
        [
            [
                along * c * c + across * s * s + prior_weight,
                (along - across) * c * s,
                0.0,
            ],
            [
                (along - across) * c * s,
                along * s * s + across * c * c + prior_weight,
                0.0,
            ],
            [0.0, 0.0, 50.0],
        ]
    }

    #[test]
    fn a_match_follows_the_prediction_only_where_the_map_pins_it_weakly() {
        // A wall along x: the map pins y (1000) and barely x (2); the matcher's own pull
        // towards the prediction is 30 (already in the information).
        let prior_weight = 30.0;
        let information = [
            [2.0 + prior_weight, 0.0, 0.0],
            [0.0, 1000.0 + prior_weight, 0.0],
            [0.0, 0.0, 50.0],
        ];
        let matched = Pose2::new(1.0, 2.0, 0.1);
        let predicted = Pose2::new(0.9, 2.05, 0.2);
        let moved = towards_prediction_where_weak(
            matched,
            predicted,
            &information,
            prior_weight,
            100.0,
            f64::INFINITY,
        );
        // Along x, 98 of information added to the 2 + 30 there: 98 / 130 of the way.
        assert!(
            (moved.x_m - (1.0 - 0.1 * 98.0 / 130.0)).abs() < 1e-12,
            "{moved:?}"
        );
        assert_eq!((moved.y_m, moved.yaw_rad), (2.0, 0.1));
        // The same wall running diagonally: moved along the wall only.
        let info = information_along(std::f64::consts::FRAC_PI_4, 2.0, 1000.0, prior_weight);
        let predicted = Pose2::new(1.1, 2.1, 0.1);
        let moved = towards_prediction_where_weak(
            matched,
            predicted,
            &info,
            prior_weight,
            100.0,
            f64::INFINITY,
        );
        let share = 98.0 / 130.0;
        assert!((moved.x_m - (1.0 + 0.1 * share)).abs() < 1e-9, "{moved:?}");
        assert!((moved.y_m - (2.0 + 0.1 * share)).abs() < 1e-9, "{moved:?}");
        // Pinned firmly both ways: left alone.
        let firm_both = [[500.0, 0.0, 0.0], [0.0, 800.0, 0.0], [0.0, 0.0, 50.0]];
        assert_eq!(
            towards_prediction_where_weak(
                matched,
                predicted,
                &firm_both,
                prior_weight,
                100.0,
                f64::INFINITY
            ),
            matched
        );
        // Diagonally 0.14 m apart along the weak direction: with a gate of 0.1 m the match
        // is taken as it is (slipping wheels, not the map's weak pull), within 0.2 m not.
        assert_eq!(
            towards_prediction_where_weak(matched, predicted, &info, prior_weight, 100.0, 0.1),
            matched
        );
        assert_eq!(
            towards_prediction_where_weak(matched, predicted, &info, prior_weight, 100.0, 0.2),
            moved
        );
    }

    #[test]
    fn the_slip_check_hears_the_map_without_the_matchers_pull_towards_the_wheels() {
        // Heading 30 degrees; the map pins the travel 3 times as firmly as the matcher's
        // prior (90 against 30) and across it firmly. The wheels predict 0.03 m of travel
        // where the map says 0.003: a least-squares match lands at (90 * 0.003 + 30 * 0.03)
        // / 120 = 0.00975 m along the heading.
        let prior_weight = 30.0;
        let heading = 30f64.to_radians();
        let (s, c) = heading.sin_cos();
        let information = information_along(heading, 90.0, 2000.0, prior_weight);
        let at =
            |d: f64, side: f64| Pose2::new(1.0 + d * c - side * s, 2.0 + d * s + side * c, heading);
        let predicted = at(0.03, 0.0);
        let matched = at(0.00975, 0.004);
        let heard = without_prior_along_heading(matched, predicted, &information, prior_weight);
        let expected = at(0.003, 0.004);
        assert!(
            heard.position().distance_m(expected.position()) < 1e-12,
            "{heard:?}"
        );
        assert_eq!(heard.yaw_rad, heading);
        // Beside a bare wall (the map pins the travel a tenth as firmly as the prior) the
        // match moves at most as far again: its noise is not blown up tenfold.
        let weak = information_along(0.0, 3.0, 2000.0, prior_weight);
        let heard = without_prior_along_heading(
            Pose2::new(0.02, 0.0, 0.0),
            Pose2::new(0.03, 0.0, 0.0),
            &weak,
            prior_weight,
        );
        assert!((heard.x_m - 0.01).abs() < 1e-12, "{heard:?}");
    }

    #[test]
    fn a_refinement_moves_nothing_along_a_direction_the_grid_barely_pins() {
        let prior_weight = 30.0;
        // The grid pins y firmly and x barely: a wall along x.
        let information = [
            [5.0 + prior_weight, 0.0, 0.0],
            [0.0, 2000.0 + prior_weight, 0.0],
            [0.0, 0.0, 50.0],
        ];
        let matched = Pose2::new(1.0, 2.0, 0.1);
        let refined = Pose2::new(0.97, 2.01, 0.102);
        let kept = refined_only_where_pinned(matched, refined, &information, prior_weight, 100.0);
        assert!(
            (kept.x_m - 1.0).abs() < 1e-12 && (kept.y_m - 2.01).abs() < 1e-12,
            "{kept:?}"
        );
        assert_eq!(kept.yaw_rad, 0.102);
        // Pinned both ways: the refinement as it is.
        let firm = [[400.0, 0.0, 0.0], [0.0, 400.0, 0.0], [0.0, 0.0, 50.0]];
        assert_eq!(
            refined_only_where_pinned(matched, refined, &firm, prior_weight, 100.0),
            refined
        );
    }

    #[test]
    fn matches_refined_on_the_hits_do_not_drift_with_exact_odometry() {
        let refined = worst_error_driving_with_exact_odometry(Some(NdtConfig::default()));
        let grid = worst_error_driving_with_exact_odometry(None);
        // The occupancy grid pulls every match towards cell centres and maps each newly seen
        // wall with that offset; the hits themselves carry no such pull.
        // 0.011 m against 0.086 m when written.
        assert!(
            refined < 0.02,
            "refined: {refined:.4} m (grid alone {grid:.4} m)"
        );
        assert!(
            grid > 3.0 * refined,
            "grid alone {grid:.4} m, refined {refined:.4} m"
        );
    }

    /// Drives east through the sparse hall on wheels that over-report the travel by 13.6 %
    /// (the ground moves 88 % of it), seeing for 8 m and then nothing for 3 m (scans with no
    /// endpoints, as in the middle of the simulated hall); returns how far ahead of the truth
    /// the pose is at the end of the blind stretch, metres.
    fn error_after_a_blind_stretch(slip_calibration: Option<SlipCalibration>) -> f64 {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.slip_calibration = slip_calibration;
        let mut mapper = Mapper::new(cfg);
        let truth = |k: usize| Point2::new(-6.0 + 0.04 * k as f64, 0.2);
        let mut end = Pose2::IDENTITY;
        for k in 0..=275 {
            let at = truth(k);
            let seen = if at.x_m < 2.0 {
                sparse_hall_scan(Pose2::new(at.x_m, at.y_m, 0.0))
            } else {
                Vec::new()
            };
            end = mapper
                .add_points(0.1 * k as f64, Pose2::new(at.x_m / 0.88, 0.0, 0.0), seen)
                .pose;
        }
        // The map frame is the odometry's at the first scan, which the truth has at x = -6.
        end.x_m + 6.0 / 0.88 - 6.0 - truth(275).x_m
    }

    /// A rover's wheels drive 4.5 m along x in 15 s among `walls` and `rocks`; from 5 to 10 s
    /// they slip 90 %, over-reporting 1.35 m. Returns when `cfg`'s mapper first reported the
    /// odometry unreliable, and its position error at the end, metres.
    fn slip_burst_seen(
        cfg: MapperConfig,
        walls: &[(f64, f64, f64, f64)],
        rocks: &[(f64, f64, f64)],
    ) -> (Option<f64>, f64) {
        let mut mapper = Mapper::new(cfg);
        let (mut truth_x, mut wheels_x) = (0.0, 0.0);
        let mut reported = None;
        for k in 0..150 {
            let t = 0.1 * k as f64;
            let step = if k == 0 { 0.0 } else { 0.03 };
            wheels_x += step;
            truth_x += if (5.0..10.0).contains(&t) {
                0.1 * step
            } else {
                step
            };
            let points = ray_cast_scan(Pose2::new(truth_x, 0.0, 0.0), walls, rocks);
            let tracked = mapper.add_points(t, Pose2::new(wheels_x, 0.0, 0.0), points);
            if tracked.state == LocalisationState::OdometryUnreliable {
                reported.get_or_insert(t);
            }
        }
        (reported, (mapper.pose.x_m - truth_x).abs())
    }

    /// A rover weaves along a bare wall 1.5 m to its left for 15 s (0.3 m/s, turning at up
    /// to 0.25 rad/s one way and the other); from 5 to 10 s its wheels slip 90 %, of their
    /// turns as of their travel. The odometry is the wheels' travel along a perfect gyro's
    /// heading, as a rover's is; the wheels' own heading is given beside it. Returns when
    /// `cfg`'s mapper first reported the odometry unreliable, and its position error at the
    /// end, metres.
    fn slip_while_weaving(cfg: MapperConfig) -> (Option<f64>, f64) {
        let mut mapper = Mapper::new(cfg);
        let wall = [(-20.0, 1.5, 40.0, 1.5)];
        let (mut truth, mut odom, mut wheel_yaw) = (Pose2::IDENTITY, Pose2::IDENTITY, 0.0);
        let mut reported = None;
        for k in 0..150 {
            let t = 0.1 * k as f64;
            if k > 0 {
                let (v, w) = (0.3, 0.25 * (std::f64::consts::TAU * t / 4.0).sin());
                let grip = if (5.0..10.0).contains(&t) { 0.1 } else { 1.0 };
                truth = truth * Pose2::new(grip * v * 0.1, 0.0, grip * w * 0.1);
                let (s, c) = truth.yaw_rad.sin_cos();
                odom = Pose2::new(
                    odom.x_m + c * v * 0.1,
                    odom.y_m + s * v * 0.1,
                    truth.yaw_rad,
                );
                wheel_yaw += w * 0.1;
            }
            mapper.set_wheel_heading(wheel_yaw);
            let points = ray_cast_scan(truth, &wall, &[]);
            let tracked = mapper.add_points(t, odom, points);
            if tracked.state == LocalisationState::OdometryUnreliable {
                reported.get_or_insert(t);
            }
        }
        (
            reported,
            mapper.pose.position().distance_m(truth.position()),
        )
    }

    #[test]
    fn wheels_slipping_as_they_turn_are_told_by_the_gyro_where_the_lidar_cannot_tell() {
        let cfg = |turn_check: bool, turn_scaled_travel: bool| {
            let mut cfg = MapperConfig::default();
            cfg.frontend.max_range_m = 12.0;
            cfg.health.turn_check = turn_check.then(TurnCheck::default);
            cfg.turn_scaled_travel = turn_scaled_travel;
            cfg
        };
        // The wall says nothing of the travel along it: the pose follows the wheels, 1.35 m
        // ahead at the end, and the scans never disagree with them.
        let (reported, error_m) = slip_while_weaving(cfg(false, false));
        assert_eq!(reported, None);
        assert!(error_m > 1.0, "{error_m:.2} m off");
        // The gyro sees a tenth of the wheels' turns.
        let (reported, error_m) = slip_while_weaving(cfg(true, false));
        let t = reported.expect("reported");
        assert!((5.0..7.0).contains(&t), "reported at {t:.1} s");
        assert!(error_m > 1.0, "{error_m:.2} m off");
        // And the travel scaled as the turns are keeps the pose with the truth.
        let (reported_too, error_m) = slip_while_weaving(cfg(true, true));
        assert_eq!(reported_too, reported);
        assert!(error_m < 0.2, "{error_m:.2} m off");
    }

    /// [`slip_burst_seen`] on open ground where the lidar sees one rock and nothing else
    /// (5-9 endpoints).
    fn slip_seen_on_one_rock(min_scan_points: usize) -> (Option<f64>, f64) {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.min_scan_points = min_scan_points;
        slip_burst_seen(cfg, &[], &[(6.0, 2.5, 0.3)])
    }

    /// [`slip_burst_seen`] a metre and a half from a long wall, with `rocks` in view, the
    /// mapper set up by `change`.
    fn slip_near_a_wall(
        rocks: &[(f64, f64, f64)],
        change: impl FnOnce(&mut MapperConfig),
    ) -> (Option<f64>, f64) {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.frontend.densify = Some(Densify {
            max_gap_m: 0.3,
            spacing_m: 0.05,
        });
        change(&mut cfg);
        let wall = [(-20.0, 1.5, 40.0, 1.5)];
        slip_burst_seen(cfg, &wall, rocks)
    }

    /// [`slip_near_a_wall`] with one small rock in view.
    fn slip_beside_a_wall(change: impl FnOnce(&mut MapperConfig)) -> (Option<f64>, f64) {
        slip_near_a_wall(&[(9.0, -6.0, 0.1)], change)
    }

    /// [`slip_beside_a_wall`], the slip check hearing the matches `without_prior` or not:
    /// when first reported.
    fn slip_beside_a_wall_reported_at(without_prior: bool) -> Option<f64> {
        slip_beside_a_wall(|cfg| cfg.slip_check_without_prior = without_prior).0
    }

    #[test]
    fn a_slip_burst_beside_a_wall_is_reported_once_the_matchers_pull_is_taken_back() {
        // The rock alone pins the travel along the wall, a few times as firmly as the
        // matcher's pull towards the wheels: the matches follow the wheels part of the way.
        let t = slip_beside_a_wall_reported_at(true).expect("reported");
        assert!((5.0..7.0).contains(&t), "reported at {t:.1} s");
        let heard_with_the_pull = slip_beside_a_wall_reported_at(false);
        assert!(
            heard_with_the_pull.is_none_or(|t| t >= 7.0),
            "reported at {heard_with_the_pull:?} s"
        );
    }

    /// [`slip_beside_a_wall`], the slip check hearing the matches without the matcher's
    /// pull, the match held to the wheels' prediction where the map pins it weakly at
    /// `floor` (gated at `gate_m`), and the slip check hearing each match from the previous
    /// one (`match_to_match`, its own if `own_match`) or from the pose.
    fn slip_beside_a_wall_held(
        floor: Option<f64>,
        gate_m: Option<f64>,
        match_to_match: bool,
        own_match: bool,
    ) -> (Option<f64>, f64) {
        slip_beside_a_wall(|cfg| {
            cfg.slip_check_without_prior = true;
            cfg.weak_direction_floor = floor;
            cfg.weak_direction_gate_m = gate_m;
            cfg.slip_check_match_to_match = match_to_match;
            cfg.slip_check_own_match = own_match;
        })
    }

    #[test]
    fn a_match_held_to_the_wheels_where_the_map_is_weak_lets_go_of_slipping_wheels() {
        // Nothing pulls the pose off the match: from the last match or from the pose, the
        // check hears the same.
        let usual = slip_beside_a_wall_held(None, None, false, false);
        assert_eq!(slip_beside_a_wall_held(None, None, true, false), usual);
        assert!(
            usual.0.is_some_and(|t| (5.0..7.0).contains(&t)),
            "{usual:?}"
        );
        // Held to the wheels along the wall at any distance, the pose runs off with the
        // burst's over-report, and the matches started from it follow, unheard.
        let (held, held_error_m) = slip_beside_a_wall_held(Some(100.0), None, true, false);
        assert_eq!(held, None);
        assert!(held_error_m > 1.0, "{held_error_m}");
        // Let go of once the match lies more than 1 cm from the prediction, the pose stays
        // with the map and the burst is heard.
        let (gated, gated_error_m) = slip_beside_a_wall_held(Some(100.0), Some(0.01), true, false);
        assert!(gated.is_some_and(|t| (5.0..8.0).contains(&t)), "{gated:?}");
        assert!(
            gated_error_m < 0.7 * held_error_m,
            "{gated_error_m} {held_error_m}"
        );
        // Or, held at any distance, the check's matches its own, started from its last
        // match: the burst is heard as soon as from a pose that follows the map.
        let (own, own_error_m) = slip_beside_a_wall_held(Some(100.0), None, true, true);
        assert!(
            own.is_some_and(|t| t <= usual.0.unwrap_or(f64::INFINITY)),
            "{own:?}"
        );
        assert!(own.is_some_and(|t| t >= 5.0), "{own:?}");
        assert!(
            own_error_m < 0.7 * held_error_m,
            "{own_error_m} {held_error_m}"
        );
    }

    /// [`slip_near_a_wall`] with a few rocks about, the mapper set up as on the rovers'
    /// slip check and hold along weak directions, and then by `change`.
    fn slip_among_rocks(change: impl FnOnce(&mut MapperConfig)) -> (Option<f64>, f64) {
        let rocks = [(3.0, -2.0, 0.25), (6.5, -3.5, 0.3), (9.0, -1.5, 0.2)];
        slip_near_a_wall(&rocks, |cfg| {
            cfg.slip_check_without_prior = true;
            cfg.weak_direction_floor = Some(100.0);
            cfg.slip_check_match_to_match = true;
            cfg.slip_check_own_match = true;
            change(cfg);
        })
    }

    #[test]
    fn a_slip_burst_reported_is_taken_back_and_its_wheels_pull_the_pose_no_further() {
        let (reported, followed_m) = slip_among_rocks(|_| {});
        let (reported_too, rewound_m) = slip_among_rocks(|cfg| {
            cfg.unreliable_rewind = true;
        });
        let (_, let_go_m) = slip_among_rocks(|cfg| {
            cfg.unreliable_pull_share = Some(0.1);
        });
        let (_, both_m) = slip_among_rocks(|cfg| {
            cfg.unreliable_rewind = true;
            cfg.unreliable_pull_share = Some(0.1);
        });
        // The rocks pin the travel, but the matches follow the wheels part of the way before
        // the alarm (0.3 s after the wheels are 0.1 m ahead), and the map drawn meanwhile
        // holds the pose there: 0.4 m ahead at the end.
        let t = reported.expect("reported");
        assert!((5.0..7.5).contains(&t), "reported at {t:.1} s");
        assert!(followed_m > 0.3, "{followed_m:.3} m off");
        // Taking back what the pose ran beyond the check's matches, or weakening the pull
        // while the wheels disagree, or both, leaves it within a few centimetres.
        assert_eq!(reported_too, reported);
        for (what, error_m) in [
            ("taken back", rewound_m),
            ("let go", let_go_m),
            ("both", both_m),
        ] {
            assert!(error_m < 0.06, "{what}: {error_m:.3} m off");
        }
    }

    #[test]
    fn a_slip_burst_where_the_lidar_sees_one_rock_is_reported_and_most_of_it_kept_out() {
        let (reported, error_m) = slip_seen_on_one_rock(5);
        // The wheels are 0.1 m ahead of the truth 0.37 s into the burst.
        let t = reported.expect("the burst reported");
        assert!((5.0..7.5).contains(&t), "reported at {t:.1} s");
        assert!(error_m < 0.45, "position {error_m:.2} m off");
        // Scans of a rock's few endpoints left unmatched, the pose follows the wheels.
        let (reported, error_m) = slip_seen_on_one_rock(10);
        assert_eq!(reported, None);
        assert!(error_m > 1.2, "position {error_m:.2} m off");
    }

    #[test]
    fn wheel_slip_learnt_from_the_matches_carries_the_pose_through_a_blind_stretch() {
        let learnt = error_after_a_blind_stretch(Some(SlipCalibration::default()));
        let wheels = error_after_a_blind_stretch(None);
        // Taken at their word, the wheels put it 3 m * 13.6 % = 0.41 m ahead.
        assert!(wheels > 0.3, "without calibration {wheels:.3} m");
        assert!(
            learnt.abs() < 0.03,
            "with calibration {learnt:.3} m (without {wheels:.3} m)"
        );
    }

    #[test]
    fn features_from_another_sensor_go_into_the_hits_of_their_own_scan_only() {
        // A wall 1 m to the left, seen from x = 0 and x = 0.3 (two keyframes); another
        // sensor sees a pebble 2.1 m ahead and 3.1 m to the right of the first pose. Given
        // before the first scan only, the pebble must not come back with the second.
        let wall_from = |x: f64| -> Vec<Point2> {
            (0..100)
                .map(|i| Point2::new(-1.0 + 0.05 * i as f64 - x, 1.0))
                .collect()
        };
        let pebble: Vec<Point2> = (0..10)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 10.0;
                Point2::new(2.1 + 0.05 * a.cos(), -3.1 + 0.05 * a.sin())
            })
            .collect();
        // Cells holding hits after the two keyframes, the pebble given before which scans.
        let hit_cells = |before: [bool; 2]| {
            let mut mapper = Mapper::new(MapperConfig {
                keyframe_translation_m: 0.25,
                ndt_refine: Some(NdtConfig::default()),
                ..MapperConfig::default()
            });
            for (k, x) in [0.0, 0.3].into_iter().enumerate() {
                if before[k] {
                    mapper.set_features(pebble.clone());
                }
                mapper.add_points(0.1 * k as f64, Pose2::new(x, 0.0, 0.0), wall_from(x));
            }
            assert_eq!(mapper.graph.nodes.len(), 2, "two keyframes");
            mapper.submaps[0].hits.as_ref().map_or(0, NdtMap::cells)
        };
        let (none, once, twice) = (
            hit_cells([false, false]),
            hit_cells([true, false]),
            hit_cells([true, true]),
        );
        // 0.3 m apart, the pebble's two sightings fall in different 25 cm cells.
        assert_eq!(once, none + 1, "the pebble given once");
        assert_eq!(twice, none + 2, "the pebble given twice");
    }

    #[test]
    fn a_lost_mapper_searches_again_only_for_a_new_view() {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        let mut mapper = Mapper::new(cfg);
        let here = Pose2::new(0.3, 0.2, 0.0);
        for k in 0..5 {
            mapper.add_points(0.1 * k as f64, here, sparse_hall_scan(here));
        }
        // Eleven seconds without a scan: lost. What it sees then is a ring 1 m round it,
        // which the hall has nowhere.
        let ring: Vec<Point2> = (0..360)
            .map(|i| {
                let a = (i as f64).to_radians();
                Point2::new(a.cos(), a.sin())
            })
            .collect();
        let mut t = 11.5;
        for _ in 0..20 {
            mapper.add_points(t, here, ring.clone());
            t += 0.1;
        }
        assert_eq!(mapper.state(), LocalisationState::Lost);
        assert_eq!(mapper.relocalise_searches, 1, "standing still");
        for k in 1..=10 {
            let turned = Pose2::new(here.x_m, here.y_m, (2.0 * k as f64).to_radians());
            mapper.add_points(t, turned, ring.clone());
            t += 0.1;
        }
        // 20 degrees in 2-degree steps, a search once 5 degrees from the last: at 6, 12
        // and 18 degrees.
        assert_eq!(mapper.relocalise_searches, 1 + 3, "turning");
    }

    /// A mapper of `cfg` driven 8 m east through the sparse hall on exact odometry, and its
    /// first finished submap.
    fn driven_east_through_the_sparse_hall(cfg: MapperConfig) -> (Mapper, usize) {
        let mut mapper = Mapper::new(cfg);
        for k in 0..=80 {
            let truth = Pose2::new(-6.0 + 0.1 * k as f64, -1.0, 0.0);
            mapper.add_points(0.1 * k as f64, truth, sparse_hall_scan(truth));
        }
        let s = (mapper.submaps.iter())
            .position(|s| s.finished)
            .expect("a finished submap");
        (mapper, s)
    }

    #[test]
    fn finished_submaps_are_redrawn_where_the_graph_puts_their_keyframes() {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        let (mut mapper, s) = driven_east_through_the_sparse_hall(cfg);
        let (first, n) = (mapper.submaps[s].origin_node, mapper.submaps[s].keyframes);
        assert_eq!(n, mapper.cfg.submap_keyframes);
        // The strongest evidence for an obstacle between two x (world frame) on the rover's
        // line, in the submap's grid: the west wall stands at x = -9.
        let strongest = |m: &Mapper, from_x: f64, to_x: f64| {
            let origin = m.graph.nodes[first];
            (0..=20)
                .map(|i| from_x + (to_x - from_x) * i as f64 / 20.0)
                .map(|x| {
                    let p = origin.inverse().transform_point(Point2::new(x, -1.0));
                    m.submaps[s].map.finest().log_odds_at(p)
                })
                .fold(f32::MIN, f32::max)
        };
        let (wall, beside) = ((-9.1, -8.9), (-8.85, -8.65));
        assert!(strongest(&mapper, wall.0, wall.1) > strongest(&mapper, beside.0, beside.1));
        // Moved as one with their first keyframe, the keyframes draw the same cells.
        let drawn = mapper.submaps[s].map.finest().log_odds().to_vec();
        let shift = |m: &mut Mapper, range: std::ops::Range<usize>| {
            for node in &mut m.graph.nodes[range] {
                *node = Pose2::new(node.x_m + 0.25, node.y_m, node.yaw_rad);
            }
        };
        shift(&mut mapper, first..first + n);
        mapper.redraw_finished_submaps();
        assert_eq!(mapper.submaps[s].map.finest().log_odds(), drawn.as_slice());
        // Every keyframe but the first 0.25 m farther east than it was drawn: the wall moves
        // with them in the submap.
        shift(&mut mapper, first + 1..first + n);
        mapper.redraw_finished_submaps();
        let (wall, beside) = ((-8.85, -8.65), (-9.1, -8.9));
        assert!(strongest(&mapper, wall.0, wall.1) > strongest(&mapper, beside.0, beside.1));
    }

    #[test]
    fn the_final_map_draws_hits_only_within_its_range() {
        let mut cfg = MapperConfig::default();
        cfg.frontend.max_range_m = 12.0;
        cfg.final_map_hit_range_m = Some(4.0);
        let (mut mapper, s) = driven_east_through_the_sparse_hall(cfg);
        // The farthest occupied and free cells of the submap from their nearest keyframe.
        let farthest_hit_and_free = |m: &Mapper| {
            let grid = m.submaps[s].map.finest();
            let geo = grid.geometry();
            let keyframes = &m.submaps[s].drawn;
            let (mut hit, mut free) = (0.0f64, 0.0f64);
            for (i, l) in grid.log_odds().iter().enumerate() {
                let c = geo.cell_center(Cell {
                    x: i % geo.width,
                    y: i / geo.width,
                });
                let near = || {
                    keyframes
                        .iter()
                        .map(|k| k.position().distance_m(c))
                        .fold(f64::INFINITY, f64::min)
                };
                match CellState::from_log_odds(*l) {
                    CellState::Occupied => hit = hit.max(near()),
                    CellState::Free => free = free.max(near()),
                    CellState::Unknown => {}
                }
            }
            (hit, free)
        };
        // As tracked, the west wall 3-4 m off and the south wall 9 m off are drawn.
        let (before, _) = farthest_hit_and_free(&mapper);
        assert!(before > 8.5, "{before}");
        mapper.redraw_finished_submaps();
        let (hit, free) = farthest_hit_and_free(&mapper);
        // Hits within 4 m and the half diagonal of a cell; beams to farther points clear
        // the cells out to 4 m (not dropped), and none beyond.
        assert!((3.0..=4.0 + 0.036).contains(&hit), "{hit}");
        assert!((3.9..=4.0 + 0.036).contains(&free), "{free}");
    }

    /// Returns every 5 cm of a wall along y = 1 m, from x = `from_x_m`.
    fn wall_at_y1(from_x_m: f64, points: usize) -> Vec<Point2> {
        (0..points)
            .map(|i| Point2::new(from_x_m + 0.05 * i as f64, 1.0))
            .collect()
    }

    /// Beams to the right (robot frame) that returned nothing, as rays `length_m` long every
    /// degree, as the lidar's beams are.
    fn rays_to_the_right(length_m: f64) -> Vec<Point2> {
        (1..180)
            .map(|k| {
                let a = -(k as f64).to_radians();
                Point2::new(length_m * a.cos(), length_m * a.sin())
            })
            .collect()
    }

    #[test]
    fn beams_that_returned_nothing_clear_the_ground_they_crossed_and_are_never_matched() {
        // A wall 1 m to the left; to the right nothing within the lidar's range, told as
        // rays 3 m long every degree, as the lidar's beams are.
        let (wall, clear) = (wall_at_y1(-1.0, 100), rays_to_the_right(3.0));
        let run = |with_clear: bool| {
            let mut m = Mapper::new(MapperConfig::default());
            for k in 0..=10 {
                if with_clear {
                    m.set_clear_rays(clear.clone());
                }
                m.add_points(
                    0.1 * k as f64,
                    Pose2::new(0.1 * k as f64, 0.0, 0.0),
                    wall.clone(),
                );
            }
            m
        };
        let (mut with_clear, mut without) = (run(true), run(false));
        assert_eq!(
            with_clear.pose(),
            without.pose(),
            "the rays are never matched"
        );
        let (south, farther) = (Point2::new(0.5, -2.0), Point2::new(0.5, -3.5));
        assert_eq!(
            with_clear.map_states().at_world(south),
            Some(&CellState::Free)
        );
        assert_ne!(without.map_states().at_world(south), Some(&CellState::Free));
        assert_ne!(
            with_clear.map_states().at_world(farther),
            Some(&CellState::Free),
            "only as far as the rays reach"
        );
        // Told to clear only the published grids, the grid the scans are matched against
        // keeps the ground south unknown, and the map shows it free all the same.
        let mut published_only = Mapper::new(MapperConfig {
            clear_rays_published_only: true,
            ..MapperConfig::default()
        });
        for k in 0..=10 {
            published_only.set_clear_rays(clear.clone());
            published_only.add_points(
                0.1 * k as f64,
                Pose2::new(0.1 * k as f64, 0.0, 0.0),
                wall.clone(),
            );
        }
        assert_eq!(published_only.pose(), without.pose());
        assert_eq!(
            published_only.map_states().at_world(south),
            Some(&CellState::Free)
        );
        // The first submap starts at the first keyframe, the origin.
        let matched = |m: &Mapper| m.submaps[0].map.finest().log_odds_at(south);
        assert!(matched(&with_clear) < 0.0, "cleared where matched too");
        assert_eq!(matched(&published_only), 0.0, "never cleared where matched");
        assert_eq!(matched(&published_only), matched(&without));
    }

    #[test]
    fn beams_that_returned_nothing_are_drawn_only_from_keyframes_spaced_apart() {
        // A wall 1 m to the north; to the rover's right nothing within the lidar's range,
        // told as rays 3 m long every degree. It drives 3 m east, then turns on the spot to
        // face north, its right then facing east.
        let (wall, clear) = (wall_at_y1(-2.0, 110), rays_to_the_right(3.0));
        let poses: Vec<Pose2> = (0..=30)
            .map(|k| Pose2::new(0.1 * k as f64, 0.0, 0.0))
            .chain((1..=9).map(|k| Pose2::new(3.0, 0.0, (10.0 * k as f64).to_radians())))
            .collect();
        let run = |spacing_m: Option<f64>| {
            let mut m = Mapper::new(MapperConfig {
                clear_rays_published_only: true,
                clear_rays_spacing_m: spacing_m,
                ..MapperConfig::default()
            });
            for (k, pose) in poses.iter().enumerate() {
                m.set_clear_rays(clear.clone());
                let seen = wall.iter().map(|p| pose.inverse().transform_point(*p));
                m.add_points(0.1 * k as f64, *pose, seen.collect());
            }
            m
        };
        let (mut every, mut spaced) = (run(None), run(Some(1.0)));
        let drawn = |m: &Mapper| m.keyframe_clear.iter().filter(|c| !c.is_empty()).count();
        assert_eq!(drawn(&every), every.keyframe_clear.len());
        assert!(drawn(&every) >= 15, "{}", drawn(&every));
        // Keyframes every 0.3 m: rays from those at 0, 1.2 and 2.4 m, none while turning.
        assert_eq!(drawn(&spaced), 3);
        assert_eq!(spaced.pose(), every.pose(), "the rays are never matched");
        // South of the drive: cleared either way. East of where it turned: only the turned
        // keyframes' rays reach it.
        let (south, east) = (Point2::new(0.5, -2.0), Point2::new(5.0, 0.5));
        for m in [&mut every, &mut spaced] {
            assert_eq!(m.map_states().at_world(south), Some(&CellState::Free));
        }
        assert_eq!(every.map_states().at_world(east), Some(&CellState::Free));
        assert_ne!(spaced.map_states().at_world(east), Some(&CellState::Free));
    }

    #[test]
    fn a_straight_wall_pins_nothing_along_it_and_a_corner_pins_both_ways() {
        // Returns every degree from a sensor at the origin, in beam order.
        let beams = |range: &dyn Fn(f64) -> Option<f64>| -> Vec<Point2> {
            (-90..=90)
                .filter_map(|d| {
                    let a = (d as f64).to_radians();
                    range(a).map(|r| Point2::new(r * a.cos(), r * a.sin()))
                })
                .collect()
        };
        // A wall 2 m ahead, across the whole view.
        let wall = beams(&|a| Some(2.0 / a.cos()).filter(|r| *r < 12.0));
        assert!(weakest_direction_share(&wall) < 1e-9);
        // Walls 2 m ahead and 2 m to the left, meeting in a corner.
        let corner = beams(&|a| {
            let ahead = (a.cos() > 1e-9).then(|| 2.0 / a.cos());
            let left = (a.sin() > 1e-9).then(|| 2.0 / a.sin());
            match (ahead, left) {
                (Some(f), Some(l)) => Some(f.min(l)),
                (f, l) => f.or(l),
            }
            .filter(|r| *r < 12.0)
        });
        let share = weakest_direction_share(&corner);
        assert!(share > 0.2 && share <= 0.5, "{share}");
        // No normal across a gap between surfaces: two returns far apart pin nothing.
        assert_eq!(
            weakest_direction_share(&[
                Point2::new(0.0, 2.0),
                Point2::new(3.0, 0.0),
                Point2::new(0.0, -2.0)
            ]),
            0.0
        );
    }

    #[test]
    fn the_map_shows_every_new_keyframe() {
        // A wall along the drive, 1 m to the left, seen from -1 m to +4 m of the rover.
        let wall: Vec<Point2> = (0..100)
            .map(|i| Point2::new(-1.0 + 0.05 * i as f64, 1.0))
            .collect();
        let known = |m: &mut Mapper| {
            m.map_states()
                .cells()
                .iter()
                .filter(|c| **c != CellState::Unknown)
                .count()
        };
        let mut mapper = Mapper::new(MapperConfig::default());
        mapper.add_points(0.0, Pose2::IDENTITY, wall.clone());
        let first = known(&mut mapper);
        assert!(first > 50, "{first} cells known");
        assert_eq!(known(&mut mapper), first);
        for k in 1..=10 {
            let odom = Pose2::new(0.1 * k as f64, 0.0, 0.0);
            mapper.add_points(0.1 * k as f64, odom, wall.clone());
        }
        let later = known(&mut mapper);
        // A metre more of wall, and the ground beside it.
        assert!(later > first + 20, "{later} cells known, {first} before");
    }
}
