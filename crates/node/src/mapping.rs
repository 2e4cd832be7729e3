//! A rover's SLAM on board: feeds its lidar scans, and wheel odometry with the gyro's heading,
//! to the
//! [`Mapper`], and publishes what the rest of the mission needs
//! to know: the pose with its covariance after every scan, every change of localisation state
//! with its reason, and the map now and then. Depth frames feed a hazard layer
//! ([`SubmapHazards`]) that marks what the lidar cannot see (crater bowls, low rocks) in the
//! map, kept per submap so loop closures move it with the rest.
//!
//! The map frame is the odometry frame at the first scan, so a rover that starts where its
//! odometry says (as in the simulator, where odometry starts at the true pose) maps in the
//! arena's frame until it drifts.

use crate::Outgoing;
use crate::layers::TiledLayer;
use crate::levelling::Levelling;
use crate::sweep::{self, RecentMotion};
use realms_core::geometry::{Quaternion, Vec3, normalize_angle_rad};
use realms_core::msgs::{
    Header, Imu, LaserScan, LocalisationStatus, MapDelta, MapMetaData, Message, OccupancyGrid,
    Odometry, PointCloud, Pose3, PoseWithCovariance, PoseWithCovarianceStamped,
};
use realms_core::{CentreLookup, Duration, Grid, GridGeometry, Point2, Pose2, RoverId, Time};
use realms_net::mapdelta::Encoder;
use realms_slam::health::LocalisationState;
use realms_slam::mapper::{Mapper, MapperConfig, SubmapBend};
use realms_slam::occupancy::CellState;
use realms_slam::odometry::{OdomSample, wheel_step_bound_m};
use realms_slam::relief::{self, ElevationPatch, Registration, ReliefConfig};
use realms_slam::traversability::{
    PinholeDepth, SubmapHazards, TraversabilityConfig, judge_frame, shadow_gaps,
};

/// Ground hidden for longer than this behind a rim, and resuming lower, is a drop, metres.
const SHADOW_MIN_GAP_M: f64 = 0.5;

/// The angle between two vectors, radians (0 if either is zero).
fn angle_between(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let cross = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    let sin = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    let cos = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    sin.atan2(cos)
}

/// Where a point of the base frame (`p`, metres) lies on the level, by the `level`ling
/// rotation ([`Mapping::levelling`]): its horizontal place, heading kept.
fn on_the_level(level: &[[f64; 3]; 3], p: [f64; 3]) -> Point2 {
    let [x, y] = [&level[0], &level[1]].map(|row| row[0] * p[0] + row[1] * p[1] + row[2] * p[2]);
    Point2::new(x, y)
}

/// The wheels count as silent once this many of their readings are overdue.
const WHEELS_SILENT_READINGS: f64 = 4.0;

/// How far past its latest sample the gyro's heading is carried on at its latest rate: a
/// few of its samples; a gyro silent longer than that leaves the heading where it was.
const GYRO_EXTRAPOLATION: Duration = Duration::from_millis(100);

/// Setup of the on-board SLAM.
#[derive(Clone, Debug, PartialEq)]
pub struct MappingConfig {
    /// The lidar's position forward of the base, metres (it looks straight ahead).
    pub lidar_x_m: f64,
    /// The lidar's height above the ground under the base, metres.
    pub lidar_height_m: f64,
    /// Returns whose endpoint lies less than this above the ground under the rover (with
    /// the rover's pitch and roll undone) are taken for the floor, not an obstacle, metres.
    pub ground_clearance_m: f64,
    /// The share of each accelerometer sample taken into the gravity that levels the
    /// lidar's returns and the depth camera's points (1: the newest sample alone). A wheel
    /// climbing a rock tilts the rover within one physics step; a smoothed tilt lags it.
    pub tilt_smoothing: f64,
    /// The wheels' acceleration is taken out of each accelerometer sample before it goes
    /// into the tilt, their speed read over this stretch of time around the sample
    /// ([`Levelling`]): an accelerometer that feels the body reads starting, stopping and
    /// turning as tilt (`None`: the samples as they come).
    pub tilt_less_wheels: Option<Duration>,
    /// The gyro's roll and pitch rates carry the tilt between accelerometer samples, and
    /// each sample moves it by [`tilt_smoothing`](Self::tilt_smoothing) of its departure
    /// ([`Levelling`]; `false`: the tilt is the samples' average alone). Needs a gyro that
    /// measures them: one that reads 0 about x and y leaves this the plain average.
    pub tilt_gyro: bool,
    /// A return is dropped as the floor too when its levelled height is within what the
    /// tilt's latest change, not yet in the smoothed gravity, could have moved it: the
    /// ground clearance plus the range times the angle between the smoothed gravity and
    /// the newest sample. Right after a wheel climbs a rock the lidar's plane meets the
    /// floor metres ahead, and the smoothed levelling would keep those hits as an arc of
    /// obstacles across open ground (`false`: the clearance alone).
    pub tilt_gate: bool,
    /// Each lidar return is placed where it lies on the level, by the rover's pitch and
    /// roll (the smoothed gravity), rather than in the tilted plane of the lidar's sweep. A
    /// beam tilted by an angle `e` meets a wall `1 / cos(e)` farther than the wall lies
    /// across the floor. Off for the rovers: they tilt too little for it to show in their
    /// maps' scale (BENCHMARKS.md, "Every rover's map stretched by 0.2 %") (`false`: in the
    /// sweep's plane).
    pub levelled_points: bool,
    /// A depth frame's verdicts are placed at the rover's pose at the frame's own stamp:
    /// the pose of the latest scan moved on by the odometry since (wheels' travel, gyro's
    /// heading). Frames come some 50 ms after the scans; placed at the scan's pose they
    /// land behind the rover's travel and turned back by its turn (`false`: at the
    /// latest scan's pose).
    pub depth_at_own_stamp: bool,
    /// The published map's hazards rounded out to the hazard layer's half cell
    /// ([`TiledLayer::rounding_hazards_out`]): a 5 cm cell beside a hazardous 10 cm cell is
    /// hazard too (`false`: each 5 cm cell takes the verdict of the cell holding its
    /// centre). The planner's layer is drawn as before either way.
    pub hazards_rounded_out: bool,
    /// Each depth frame is kept with the keyframe it came after, and a hazard layer is
    /// drawn again from its frames once the pose graph has moved their keyframes this far
    /// within its submap, as the lidar's submaps are for the final map
    /// ([`SubmapHazards::redraw_bent`]; `None`: each layer stays as its frames were drawn,
    /// with the tracking's drift within its submap).
    pub hazards_follow_keyframes: Option<SubmapBend>,
    /// With [`hazards_follow_keyframes`](Self::hazards_follow_keyframes), the layers are
    /// drawn again whenever the graph moves, for the maps the rover plans on and publishes
    /// while it maps (`false`: only for the map it publishes last,
    /// [`Mapping::finish_hazards`], so nothing it does while mapping changes).
    pub hazards_redrawn_while_mapping: bool,
    /// A lidar beam that returns nothing within the lidar's range (and was not dropped as
    /// a floor hit) is drawn into the maps as free space out to this range, as
    /// Cartographer's `missing_data_ray_length` does: nothing stood in the lidar's plane
    /// along it (`None`: such beams are dropped, and the ground they crossed stays unknown
    /// unless a beam that found something crossed it).
    pub clear_rays_m: Option<f64>,
    /// SLAM tuning.
    pub mapper: MapperConfig,
    /// How often the map is published.
    pub map_period: Duration,
    /// How often it sends the changes of its map (`map/delta`) to the lander and the ground.
    pub delta_period: Duration,
    /// The rover stands still this long at the start while the gyro's bias is measured.
    pub gyro_calibration: Duration,
    /// `base_from_optical` of the depth camera: rotation (row-major) ...
    pub depth_rot: [[f64; 3]; 3],
    /// ... and origin in the base frame, metres.
    pub depth_origin_m: [f64; 3],
    /// What the rover can drive over, for the hazard layer.
    pub traversability: TraversabilityConfig,
    /// The depth camera's pinhole model, for [`silent_pixels`](Self::silent_pixels).
    pub depth_camera: Option<PinholeDepth>,
    /// A pixel that returned nothing above one that did tells the hazard layer the ground
    /// along its ray lies lower than the ray ([`shadow_gaps`]; needs
    /// [`depth_camera`](Self::depth_camera)); `false` leaves such pixels unread. Off for
    /// the rovers: it marks more of the crater cells near the paths on the same paths, but
    /// whole missions' maps came out worse with it (BENCHMARKS.md, "Pixels that returned
    /// nothing").
    pub silent_pixels: bool,
    /// Each range is smoothed with its neighbours where they lie on one surface, before the
    /// scan is matched and mapped, as [`smoothing`](Self::smoothing) says (the rovers':
    /// averaged with its two neighbours, weights 1, 2, 1, which shrinks the lidar's noise to
    /// 0.6 of itself).
    pub smooth_ranges: bool,
    /// How [`smooth_ranges`](Self::smooth_ranges) smooths.
    pub smoothing: ScanSmoothing,
    /// A sweeping lidar's beams (a scan whose `time_increment_s` says when each was measured)
    /// are brought to where the rover was at the scan's last beam, by the wheels' and the
    /// gyro's motion in between ([`crate::sweep`]); `false` takes every beam as seen from there.
    pub deskew: bool,
    /// The depth camera's points in hazard cells (rocks below the lidar's plane, rims) go
    /// into the refinement of each match, beside the lidar's points, as features seen from
    /// the last depth frame, carried to the scan by odometry (`false`: the lidar alone).
    pub depth_features: bool,
    /// Each depth frame is fitted onto the relief of an earlier one
    /// ([`realms_slam::relief`]), and the travel found is kept ([`Mapping::relief_hops`])
    /// (`None`: not done). Measured only, not yet used by the SLAM.
    pub relief_odometry: Option<ReliefConfig>,
    /// Depth frames judged while the rover stands still (`None`: every frame). A rover
    /// standing still sees the same ground frame after frame: a few frames settle the
    /// cells it sees (two safe verdicts make a cell safe, ten hold it there), and judging
    /// hours more of them at a parked rover only lets its noise wander the borderline cells.
    pub depth_motion_filter: Option<DepthStillFilter>,
}

/// How many depth frames a still rover judges ([`MappingConfig::depth_motion_filter`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthStillFilter {
    /// The rover stands still while its wheels have moved less than this (metres) ...
    pub min_travel_m: f64,
    /// ... and turned less than this (radians) since it stopped, in one submap. The wheels
    /// alone say so: a gyro's heading wanders by its noise while the rover stands. Wheels
    /// fallen silent (a dropout) count as moving.
    pub min_turn_rad: f64,
    /// Frames judged from where it stands; the rest are dropped until it moves.
    pub frames_while_still: u32,
}

/// A depth frame fitted onto the relief of a reference frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReliefHop {
    /// The reference frame's stamp.
    pub from: Time,
    /// The fitted frame's stamp.
    pub to: Time,
    /// The travel between them by the wheels and the gyro, the reference's frame.
    pub wheels: Pose2,
    /// The fit, if one was found.
    pub fit: Option<Registration>,
}

/// A reference frame for the relief fits is kept until the wheels have moved this far from
/// it, metres ...
pub const RELIEF_REFERENCE_TRAVEL_M: f64 = 1.0;
/// ... or turned this far, radians.
const RELIEF_REFERENCE_TURN_RAD: f64 = 0.35;

/// SLAM tuned for the simulated rover: the lidar reaches 12 m, the arena is small, and the
/// rover is slow, so keyframes are sparser than on the office logs, and submaps covering
/// ground a newer one covers are dropped.
pub fn rover_mapper_config() -> MapperConfig {
    let mut cfg = MapperConfig::default();
    cfg.frontend.max_range_m = 12.0;
    // One degree between beams leaves gaps wider than a cell beyond 3 m; filled in, the
    // heading of a turn in place holds to a few hundredths of a degree, not a few tenths
    // (BENCHMARKS.md, "Filling in the surface between beams").
    cfg.frontend.densify = Some(realms_slam::frontend::Densify {
        max_gap_m: 0.3,
        spacing_m: 0.05,
    });
    // Each keyframe clears a cell once, however many beams cross it: the rovers' paths come
    // out better, and slip is reported more often (BENCHMARKS.md, "A narrower closure
    // search").
    cfg.frontend.miss_rule = realms_slam::occupancy::MissRule::OncePerScan;
    // A slow rover whose odometry is good to a centimetre or two between scans: matching on
    // the finest grid alone does as well as coarse to fine, and each keyframe is traced into
    // one grid instead of three (BENCHMARKS.md, "SLAM replayed on captured input").
    cfg.frontend.levels = 1;
    cfg.keyframe_translation_m = 0.3;
    cfg.keyframe_rotation_rad = 10f64.to_radians();
    // Hours of driving in one hall: keep one submap per few metres of ground, not per few
    // metres driven.
    cfg.trim_radius_m = Some(3.0);
    // The grid scans are matched against leaves the cells round each hit to the hits: a beam
    // stops clearing 3 cm plus 0.6 % of its range short of it, so the lidar's noise does not
    // push surfaces out and stretch the map (BENCHMARKS.md, "Every rover's map stretched").
    // The map the rover publishes and plans on is drawn from a grid of its own, every beam
    // clearing up to its hit, and the beams that returned nothing (`clear_rays_m`) clear
    // only that grid, from keyframes a metre apart. Over 48 whole missions the crater cells
    // near the paths went from 94.4 to 96.2 % marked, the rest even (BENCHMARKS.md, "Rays
    // drawn from keyframes spaced apart").
    cfg.frontend.miss_margin = Some(realms_slam::occupancy::MissMargin {
        base_m: 0.03,
        per_m: 0.006,
    });
    cfg.clear_rays_published_only = true;
    cfg.clear_rays_spacing_m = Some(1.0);
    // The rover parks often (calibrating, planning, waiting): matching while parked only
    // lets the pose wander.
    cfg.motion_filter = Some(realms_slam::mapper::MotionFilter {
        translation_m: 0.02,
        rotation_rad: 0.5f64.to_radians(),
    });
    // The hall's long walls, seen from the known start, measure each keyframe's heading that
    // sees them again; a closure that turns two such keyframes against their walls is a
    // wrong fit; and closures across travel the scans did not pin along the heading (the
    // wheels' over-report carried it) are searched and allowed as far as that travel can
    // have slid. Over sixteen whole missions the rovers' maps went from 88.1 to 91.9 % of
    // occupied cells right on average (30 rovers better, 18 worse), the lander's merged
    // maps from 82.6 to 89.1 %, the crater cells near the paths from 82.4 to 86.5 %
    // (BENCHMARKS.md, "Closures searched as far as a rover can have slid along a wall").
    cfg.wall_headings = Some(realms_slam::walls::WallHeadingConfig {
        closure_gate_sigmas: Some(2.0),
        ..realms_slam::walls::WallHeadingConfig::default()
    });
    cfg.weak_travel = Some(realms_slam::mapper::WeakTravel::default());
    // A closure that asks to move its keyframe more than 0.5 m needs a partner into another
    // submap: the lander's east face laid on its west face, or a slide along a wall, fits
    // every keyframe that sees it in one submap alike, and those confirmed each other. On
    // the same paths (seeds 9-16) only seed 14's rover1 (0.57 -> 0.07 m) and seed 16's
    // rover3 changed (BENCHMARKS.md, "A far correction confirmed from another submap").
    cfg.distinct_confirmation_beyond_m = Some(0.5);
    // Coming home at the end, a rover found the submaps drawn at its known start ambiguous
    // every time: near the lander the score falls slowly for decimetres round the right
    // pose, and a rival 35-40 cm off came within the margin. While it drives home at the
    // end or is home, a closure into those submaps counts a rival only 0.5 m off or more,
    // so the end of the trajectory is tied to the start and the final map with it. At any
    // time, the looser rule moved some rovers' tracking mid-mission (BENCHMARKS.md, "A
    // rover coming home finds its start ambiguous").
    cfg.start_rivals_beyond_m = Some(0.5);
    cfg.start_rivals_homing_only = true;
    // A heading the matches turn from the gyro's within seconds (a turn in the open, on a
    // few rocks) says so in the published uncertainty (BENCHMARKS.md, ninety-sixth session).
    cfg.heading_departure = Some(realms_slam::mapper::HeadingDeparture::default());
    // A far correction whose hits reach the submap's walls from behind is refused: the
    // lander's west face laid on its east face (BENCHMARKS.md, "Faces reached from behind").
    cfg.faces_seen_from = Some(realms_slam::mapper::FacesSeenFrom::default());
    // The slip check hears each match without the matcher's pull towards the wheels: where
    // the map pins the travel a few times as firmly as that pull, a burst's matches followed
    // the wheels far enough to stay under the alarm. `realms bench slip` (seeds 1-16): 94 ->
    // 96 % of bursts reported within 2 s, 7 -> 6 false alarms in 27-29 rover-hours; whole
    // missions' maps about even (BENCHMARKS.md, "The slip check without the matcher's pull
    // towards the wheels").
    cfg.slip_check_without_prior = true;
    // The gyro's heading, bias measured at the start, holds a match that would turn more.
    cfg.max_heading_step_rad = Some(1f64.to_radians());
    // Steps under that degree can add up (a rover's tracked heading strayed 12 degrees from
    // the gyro's in 20 s while it counted as tracking), but holding the heading to the
    // gyro's since the pose was set left the replays about even and one mission worse
    // (BENCHMARKS.md, "A heading held to the gyro's since the pose was set"): not yet.
    cfg.heading_anchor_rad = None;
    // Nor is the heading bounded to half a degree from the gyro's within any two seconds:
    // it stops a match walking 4 degrees off in under a second (seed 9's rover3, then 0.3 m
    // off for twenty minutes), but over 32 whole missions the maps came out about a point
    // worse (BENCHMARKS.md, "The heading bounded within a window of the gyro's").
    cfg.heading_window = None;
    // Nor does the gyro carry every turn with the map taking 2 % of each match's heading:
    // far from the walls the tracked heading drifted less than half as fast, but over
    // sixteen whole missions the median rover's map came out 4.5 points worse and the
    // missions 13 % longer (BENCHMARKS.md, "The gyro carries the turns").
    cfg.heading_map_share = None;
    // And the wheels' standstill holds the position of a rover turning in place: beside a
    // lone wall the matches slid along it 0.3 m in two seconds. On the default mission's
    // length over the radio (seeds 1-2) the final error fell from 0.089 to 0.070 m per
    // rover on average, the worst rover per seed from 0.119 to 0.089 m; on 32 ten-minute
    // missions 40 rovers did better and 38 worse, the mean 0.130 -> 0.125 m
    // (BENCHMARKS.md, "A rover turning in place holds its position").
    cfg.still_hold = Some(realms_slam::mapper::StillHold {
        below_m: 0.002,
        translation_weight: 1e7,
        hold_heading: false,
    });
    // The rover turns at most 6 degrees between scans (1 rad/s), and the gyro's heading
    // holds a match anyway: no search over headings in fast turns.
    cfg.fast_turn = None;
    cfg.stall_turn = None;
    // The rovers' closure window stays at 2.5 m, what their replays were tuned with.
    cfg.loop_window_m = 2.5;
    // And their closure candidates are the submaps that began near: searching those that
    // pass near as well closed more loops in the replays but did no better (seeds 1-8:
    // median rover 0.085 m against 0.091 m, worst per seed 0.130 m against 0.121 m;
    // BENCHMARKS.md, twenty-ninth session).
    cfg.loop_search_nearest_keyframe = false;
    // With the gyro holding the heading the map drifts about 1 % of the path (BENCHMARKS.md);
    // a closure asking for five times that is the lander's square fitted one side over.
    // The heading creeps a degree or two over a whole mission's few hundred metres; 3
    // degrees, and 0.2 degrees a metre of path between the ends, bound the closure search's
    // turns (BENCHMARKS.md, "A narrower closure search").
    cfg.closure_drift = Some(realms_slam::mapper::ClosureDrift {
        base_m: 0.3,
        per_m: 0.05,
        hop_m: 2.0,
        base_rad: 3f64.to_radians(),
        per_m_rad: 0.2f64.to_radians(),
    });
    // Loose regolith: the wheels over-report by 3-20 %, and where the lidar sees little
    // the prediction carries the pose (BENCHMARKS.md, "Wheel slip learnt on line"). Until
    // a rover has learnt its own scale its wheels are taken at 0.92 of their word, what
    // they average on the analogue's floor, not at 1: the first metres beside the lander
    // and the open middle of the hall pin the travel weakly, and there the map took the
    // wheels' 7-8 % over-report in and kept it (maps stretched 0.6 % along one axis). Over
    // 48 whole missions the final RMS fell 0.083 -> 0.068 m (BENCHMARKS.md, "The wheels'
    // scale before it is learnt").
    cfg.slip_calibration = Some(realms_slam::slip::SlipCalibration {
        initial_scale: 0.92,
        ..realms_slam::slip::SlipCalibration::default()
    });
    // The covariance published with the pose says how far it may be off, by the path that
    // ties it to the start (constants fitted on seeds 1-16 so that 95 % of the published
    // poses lie inside their 95 % circle; BENCHMARKS.md, "A pose covariance that says how
    // far off the pose may be").
    cfg.pose_uncertainty = Some(realms_slam::drift::PoseUncertainty {
        floor_m: 0.04,
        per_m: 0.002,
        weak_per_m: 0.01,
        unmatched_per_m: 0.05,
        closure_m: 2.0,
        heading_floor_rad: 0.1f64.to_radians(),
        heading_per_m_rad: 0.004f64.to_radians(),
    });
    // Each Gauss-Newton step solved exactly by block elimination, not by conjugate gradients
    // stopped after 500 block-Jacobi iterations: over sixteen whole missions the final
    // trajectory error went from 0.088 to 0.080 m per rover on average, 40 rovers of 48
    // under 0.10 m (32 before), the maps from 92.5 to 93.0 % (7 under 90 % where there were
    // 12), the crater cells near the paths marked 90.2 -> 88.6 %; rover by rover within
    // chance, but the fleet's SLAM ran 87x real time where it ran 72x the same day
    // (BENCHMARKS.md, "The pose graph solved exactly, as the rovers' default"). The map it
    // once bent on seed 3 (22nd session) now holds: the wall headings and the closure gates
    // keep the false closures out of the graph.
    cfg.graph_solver = realms_slam::posegraph::GraphSolver::Elimination;
    // Keeping the active submaps' keyframes as they were drawn helps on the recorded logs,
    // but on the rovers' replays it left the final trajectory as it was and the pose as
    // tracked 8 % worse (BENCHMARKS.md, "Solving the pose graph to its optimum").
    cfg.track_in_submap_frame = false;
    // The occupancy match's pull towards cell centres drifted the maps 0.10-0.15 m in ten
    // minutes of a noise-free hall; refined on the submap's hits, the replays' median
    // rover went from 0.136 m to 0.091 m (BENCHMARKS.md, "Matches refined on the hits").
    cfg.ndt_refine = Some(realms_slam::ndt::NdtConfig::default());
    // The rovers' gyro (BENCHMARKS.md): 0.003 rad/s of noise at 50 Hz walks 4e-4 rad in a
    // second, and a minute's calibration leaves ~6e-5 rad/s of bias; both taken a few times
    // larger, since a real gyro's bias also wanders with temperature.
    cfg.gyro_heading = Some(realms_slam::mapper::GyroHeading {
        rad_per_sqrt_s: 1e-3,
        bias_rad_s: 2e-4,
    });
    // Where the map pins the position weakly (a bare wall, the open hall), the match's
    // position there is pulled towards the wheels' prediction as if the map pinned it 100 per
    // point: the matches alone drift there by agreeing with cells drawn at poses already off.
    // The slip check hears each match from its own last match (a second match where the
    // pose was pulled off it), so slipping wheels are still heard. Over sixteen whole
    // missions, with hidden ground ended at 6 m (below), the final trajectory error went
    // from 0.117 to 0.088 m per rover on average and the worst from 0.60 to 0.21 m, the
    // crater cells near the paths marked from 85.6 to 90.2 %, the maps even (92.0 ->
    // 92.5 %); about 7 % more SLAM time (BENCHMARKS.md, "The pose held to the wheels where
    // the map is weak, as the rovers' default").
    cfg.weak_direction_floor = Some(100.0);
    cfg.slip_check_match_to_match = true;
    cfg.slip_check_own_match = true;
    // The slip check also hears the gyro: wheels that turn while the body barely does are
    // slipping, whatever the lidar sees (a bare wall, the open hall). While the two turns
    // disagree, the wheels' travel is scaled by the share of their turn the gyro saw; and a
    // reported burst is taken back by what the pose ran beyond the check's matches (the
    // matcher's pull left as it is: weakened as well, it cost the whole missions' maps).
    // `realms bench slip` (seeds 1-16): reported within 2 s 94 -> 99 % of bursts, 4 false
    // alarms in 26 rover-hours, the pose within 0.2 m of the truth after recovery 69 -> 87 %;
    // over 32 whole missions the maps 93.85 -> 94.2 % and the final RMS 0.084 -> 0.079 m
    // per rover on average (BENCHMARKS.md, "Slipping wheels told by the gyro").
    cfg.health.turn_check = Some(realms_slam::health::TurnCheck::default());
    cfg.turn_scaled_travel = true;
    cfg.unreliable_rewind = true;
    cfg
}

/// How a scan's smoothing ([`MappingConfig::smooth_ranges`]) takes each beam with its
/// neighbours.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ScanSmoothing {
    /// Their ranges. A straight wall's range is a convex function of the beam's angle
    /// (`d / cos`), so the average lies beyond an oblique wall: by 0.05 % of the range at 60
    /// degrees from the wall's normal, 0.2 % at 75 degrees (a centimetre at 5 m).
    #[default]
    Ranges,
    /// Their inverse ranges. A straight wall's inverse range is a sinusoid of the beam's
    /// angle (`cos(angle - normal) / d`), and the sum of a sinusoid's two neighbours a step
    /// `s` away is `2 cos s` times its own, so the average, scaled by that, lies on the wall.
    InverseRanges,
    /// Their endpoints (each neighbour's at its own angle), which lie on a straight wall too.
    Points,
    /// Five ranges fitted by a parabola in the beam's angle, read at the middle one
    /// (Savitzky and Golay's weights -3, 12, 17, 12, -3 over 35; Analytical Chemistry, 1964),
    /// where all five lie on one surface, and the range as it is elsewhere. A three-point
    /// average of any kind lies inside a curved outline (a boulder's: by about a quarter of
    /// the beams' spacing squared over its radius, 4 mm at 5 m from a 0.5 m rock); the
    /// parabola follows the curve, and leaves 0.70 of the noise where the average leaves 0.61.
    Quadratic,
    /// [`Quadratic`](Self::Quadratic) where five lie on one surface, and the average of
    /// [`Ranges`](Self::Ranges) where only three do (an outline's ends keep less noise,
    /// and the average's bias there).
    QuadraticElseAverage,
}

/// `ranges` with each one smoothed with its neighbours as `how` says where it and its two
/// neighbours differ by less than [`SMOOTH_MAX_STEP_M`] plus [`SMOOTH_MAX_STEP_FRACTION`] of
/// the range: one surface, not an edge (`Points` averages the ranges here, weights 1, 2, 1;
/// [`smoothed_point`] does the rest). The scan wraps round; `increment_rad` is the angle
/// between beams.
fn smoothed(ranges: &[f32], how: ScanSmoothing, increment_rad: f32) -> Vec<f32> {
    let n = ranges.len();
    // 1/a + 2/r + 1/b = (2 cos s + 2) / r on a straight wall.
    let inverse_sum_on_a_line = 2.0 * f64::from(increment_rad).cos() + 2.0;
    (0..n)
        .map(|i| {
            let r = ranges[i];
            if !on_one_surface(ranges, i) {
                return r;
            }
            let (a, b) = (ranges[(i + n - 1) % n], ranges[(i + 1) % n]);
            let five_on_one_surface = || {
                n >= 5
                    && on_one_surface(ranges, (i + n - 1) % n)
                    && on_one_surface(ranges, (i + 1) % n)
            };
            match how {
                ScanSmoothing::Quadratic | ScanSmoothing::QuadraticElseAverage
                    if five_on_one_surface() =>
                {
                    let (aa, bb) = (ranges[(i + n - 2) % n], ranges[(i + 2) % n]);
                    (-3.0 * aa + 12.0 * a + 17.0 * r + 12.0 * b - 3.0 * bb) / 35.0
                }
                ScanSmoothing::Quadratic => r,
                ScanSmoothing::InverseRanges => {
                    let sum = 1.0 / f64::from(a) + 2.0 / f64::from(r) + 1.0 / f64::from(b);
                    (inverse_sum_on_a_line / sum) as f32
                }
                ScanSmoothing::Ranges
                | ScanSmoothing::Points
                | ScanSmoothing::QuadraticElseAverage => (a + 2.0 * r + b) / 4.0,
            }
        })
        .collect()
}

/// Whether beam `i` and its two neighbours (the scan wraps round) lie on one surface, as
/// [`smoothed`] judges it.
fn on_one_surface(ranges: &[f32], i: usize) -> bool {
    let n = ranges.len();
    let r = ranges[i];
    let (a, b) = (ranges[(i + n - 1) % n], ranges[(i + 1) % n]);
    let near = |q: f32| {
        q.is_finite()
            && ((q - r).abs() as f64) < SMOOTH_MAX_STEP_M + SMOOTH_MAX_STEP_FRACTION * r as f64
    };
    n >= 3 && r.is_finite() && near(a) && near(b)
}

/// Beam `i`'s endpoint in the lidar's frame, averaged with its two neighbours' (weights 1,
/// 2, 1) where [`on_one_surface`] says the three lie on one surface; `None` without a
/// return. Three points of a straight wall average to a point on it, where their ranges'
/// average does not ([`ScanSmoothing::Ranges`]).
fn smoothed_point(
    ranges: &[f32],
    angle_min_rad: f32,
    increment_rad: f32,
    i: usize,
) -> Option<(f64, f64)> {
    let n = ranges.len();
    let at = |k: usize| {
        let r = f64::from(ranges[k]);
        let a = f64::from(angle_min_rad + k as f32 * increment_rad);
        (r * a.cos(), r * a.sin())
    };
    if !ranges[i].is_finite() {
        return None;
    }
    if !on_one_surface(ranges, i) {
        return Some(at(i));
    }
    let (p, q, s) = (at((i + n - 1) % n), at(i), at((i + 1) % n));
    Some(((p.0 + 2.0 * q.0 + s.0) / 4.0, (p.1 + 2.0 * q.1 + s.1) / 4.0))
}

/// Neighbouring ranges closer than this (plus a share of the range) lie on one surface, m.
const SMOOTH_MAX_STEP_M: f64 = 0.05;
/// ... the share: a wall seen at 80 degrees off its normal steps 10 % a degree.
const SMOOTH_MAX_STEP_FRACTION: f64 = 0.1;

/// Depth features older than this are not carried to a scan, seconds.
const DEPTH_FEATURES_MAX_AGE_S: f64 = 1.0;
/// At most this many depth features a frame.
const DEPTH_FEATURES_MAX: usize = 300;

/// The on-board SLAM of one rover.
#[derive(Debug)]
pub struct Mapping {
    id: RoverId,
    cfg: MappingConfig,
    mapper: Mapper,
    hazards: SubmapHazards,
    tracked_once: bool,
    /// The two latest odometry poses (wheel translation, gyro heading), oldest first, to
    /// interpolate at a scan's stamp.
    odometry: Vec<(Time, Pose2)>,
    /// The odometry (gyro heading) the latest scan was tracked with, for a depth frame's
    /// pose at its own stamp.
    scan_odometry: Option<Pose2>,
    /// The same readings as the wheels alone gave them (their own heading), for the slip
    /// check's comparison of the wheels' turns with the gyro's.
    wheel_readings: Vec<(Time, Pose2)>,
    last_wheel: Option<Pose2>,
    /// Time between the wheels' readings, seconds, as they come when all is well (a
    /// reading that ends a dropout does not count).
    wheel_period_s: Option<f64>,
    /// The gyro's integrated heading at its latest sample, and when that was.
    gyro_yaw_rad: f64,
    last_gyro: Option<Time>,
    /// ... and at the sample before, to read the heading between or just after them.
    prev_gyro: Option<(Time, f64)>,
    gyro_heard: bool,
    bias_sum: f64,
    bias_samples: u64,
    gyro_bias_rad_s: Option<f64>,
    /// The rover's tilt from its accelerometer.
    level: Levelling,
    /// Returns dropped as floor hits, for the record.
    floor_hits: u64,
    next_map: Time,
    next_delta: Time,
    /// What the receivers of `map/delta` were last sent.
    delta_encoder: Encoder,
    /// A receiver missed an update: the next one is a snapshot.
    snapshot_wanted: bool,
    /// The map as published, kept between publications.
    published_layer: TiledLayer,
    /// Finds the hazard layer's hollows, if the rover infers them.
    hollows: Option<realms_slam::hollows::HollowFinder>,
    /// The planner's map, kept between plans (once asked for).
    planner_layer: Option<TiledLayer>,
    /// The last depth frame's points in hazard cells (rover frame), its time and odometry
    /// pose.
    depth_features: Option<(Time, Pose2, Vec<Point2>)>,
    /// The relief fits' reference: its stamp, its patch and the wheels' pose then (the
    /// gyro's heading).
    relief_reference: Option<(Time, ElevationPatch, Pose2)>,
    relief_hops: Vec<ReliefHop>,
    /// The wheels' and gyro's last half second, to de-skew sweeping scans.
    recent: RecentMotion,
    /// The newest submap and the wheels' reading where the rover last moved, for
    /// [`MappingConfig::depth_motion_filter`].
    last_judged: Option<(usize, Pose2)>,
    /// Frames judged since the rover last moved.
    still_frames: u32,
    /// Depth frames fused into the hazard layers so far.
    hazard_frames: u64,
    /// The hazard states last worked out, and what from.
    hazard_cache: Option<HazardStatesFrom>,
    /// Hazard states worked out so far: the kept ones' version, which a layer drawn from
    /// them compares instead of their cells.
    hazard_versions: u64,
}

/// Hazard states ([`Mapping::hazard_states`]) and what they were worked out from: the hazard
/// layers after this many frames, drawn at these submap poses, the hollows and craters
/// judged against this view of the live map. While none of it changes (a rover standing
/// still, its frames not judged), neither do the states.
#[derive(Debug)]
struct HazardStatesFrom {
    frames: u64,
    origins: Vec<Pose2>,
    live: Option<(GridGeometry, u64)>,
    states: Grid<CellState>,
}

impl Mapping {
    /// SLAM for rover `id`.
    pub fn new(id: RoverId, cfg: MappingConfig) -> Self {
        let published_layer = TiledLayer::new(1).rounding_hazards_out(cfg.hazards_rounded_out);
        Mapping {
            id,
            level: Levelling::new(cfg.tilt_smoothing, cfg.tilt_less_wheels, cfg.tilt_gyro),
            mapper: Mapper::new(cfg.mapper),
            hazards: SubmapHazards::new(
                cfg.traversability.resolution_m,
                cfg.traversability
                    .assembled_resolution_m
                    .unwrap_or(cfg.traversability.resolution_m),
            ),
            tracked_once: false,
            hollows: cfg
                .traversability
                .hazard_hollows
                .map(realms_slam::hollows::HollowFinder::new),
            cfg,
            odometry: Vec::new(),
            scan_odometry: None,
            wheel_readings: Vec::new(),
            last_wheel: None,
            wheel_period_s: None,
            gyro_yaw_rad: 0.0,
            last_gyro: None,
            prev_gyro: None,
            gyro_heard: false,
            bias_sum: 0.0,
            bias_samples: 0,
            gyro_bias_rad_s: None,
            floor_hits: 0,
            next_map: Time::ZERO,
            next_delta: Time::ZERO,
            delta_encoder: Encoder::new(),
            snapshot_wanted: false,
            published_layer,
            planner_layer: None,
            depth_features: None,
            relief_reference: None,
            relief_hops: Vec::new(),
            recent: RecentMotion::default(),
            last_judged: None,
            still_frames: 0,
            hazard_frames: 0,
            hazard_cache: None,
            hazard_versions: 0,
        }
    }

    /// Every depth frame's fit onto its reference's relief so far (when
    /// [`MappingConfig::relief_odometry`] is on).
    pub fn relief_hops(&self) -> &[ReliefHop] {
        &self.relief_hops
    }

    /// The SLAM itself, for inspection (its counters, its graph).
    pub fn mapper(&self) -> &Mapper {
        &self.mapper
    }

    /// Draws the map once more from the final trajectory, for the last map the rover
    /// publishes (see [`Mapper::redraw_finished_submaps`]).
    pub fn finish_map(&mut self) {
        self.mapper.redraw_finished_submaps();
    }

    /// Lidar returns dropped so far as hits on the floor.
    pub fn floor_hits(&self) -> u64 {
        self.floor_hits
    }

    /// The localisation state now.
    pub fn state(&self) -> LocalisationState {
        self.mapper.state()
    }

    /// Tells the SLAM whether the rover is driving home at the end of its exploring, or is
    /// home ([`realms_slam::mapper::MapperConfig::start_rivals_homing_only`]).
    pub fn set_homing(&mut self, homing: bool) {
        self.mapper.set_homing(homing);
    }

    /// Whether a scan has placed the rover yet (before that, [`Mapping::pose`] is only the
    /// map frame's origin).
    pub fn placed(&self) -> bool {
        self.tracked_once
    }

    /// The pose estimate now, in the map frame.
    pub fn pose(&self) -> Pose2 {
        self.mapper.pose()
    }

    /// How far the position may be off, by the path that ties it to the start and any swing
    /// of the heading from the gyro's since the pose was last set (the standard deviation
    /// the published covariance holds at least), metres; `None` while lost or without the
    /// model (see [`Mapper::pose_uncertainty`]).
    pub fn position_uncertainty_m(&mut self) -> Option<f64> {
        if self.mapper.state() == LocalisationState::Lost {
            return None;
        }
        self.mapper
            .pose_uncertainty()
            .map(|(position_m, _)| position_m)
    }

    /// Every scan's pose as the SLAM now has it (loop closures move past poses too), for
    /// grading the trajectory afterwards.
    pub fn trajectory(&self) -> Vec<realms_slam::trajectory::StampedPose> {
        self.mapper.trajectory()
    }

    /// Takes a wheel odometry reading. Its translation is kept; its heading is replaced by
    /// the gyro's once the gyro has been heard (skid steering makes wheel headings poor: a few
    /// per cent of every turn, and more when the wheels slip).
    pub fn on_odometry(&mut self, odom: &Odometry) {
        let p = &odom.pose.pose;
        let wheel = Pose2::new(p.position.x, p.position.y, p.orientation.yaw_rad());
        let stamp = odom.header.stamp;
        let back_from_silence = self.wheels_silent_at(stamp);
        let fused = match (self.last_wheel, self.odometry.last()) {
            (Some(prev), Some((t_prev, fused_prev))) if self.gyro_heard => {
                // The wheel motion in the wheel frame, replayed along the gyro's heading. A
                // step no robot drives in the time since the last reading is a jump of the
                // wheels' own frame (a driver restarted), and no motion.
                // A stale stamp counts as no time (the bound takes none below zero).
                let dt_s = (stamp - *t_prev).as_secs_f64();
                let step = Some(prev.inverse() * wheel)
                    .filter(|s| s.x_m.hypot(s.y_m) <= wheel_step_bound_m(dt_s))
                    .unwrap_or(Pose2::IDENTITY);
                let yaw = self.gyro_yaw_at(stamp);
                let (dx, dy) = if back_from_silence {
                    // The whole travel of a dropout in one reading, along a curve: its chord
                    // in the frame where the wheels fell silent.
                    let (s, c) = fused_prev.yaw_rad.sin_cos();
                    (c * step.x_m - s * step.y_m, s * step.x_m + c * step.y_m)
                } else {
                    let turned = normalize_angle_rad(yaw - fused_prev.yaw_rad);
                    let mid_yaw = fused_prev.yaw_rad + turned / 2.0;
                    let (s, c) = mid_yaw.sin_cos();
                    (c * step.x_m, s * step.x_m)
                };
                Pose2::new(fused_prev.x_m + dx, fused_prev.y_m + dy, yaw)
            }
            _ => {
                self.gyro_yaw_rad = wheel.yaw_rad;
                self.prev_gyro = None;
                // The gyro's heading starts again from the wheels': what came before is
                // another reckoning.
                self.recent = RecentMotion::default();
                wheel
            }
        };
        self.recent.push_position(stamp, fused);
        self.level.on_wheels(stamp, wheel);
        self.last_wheel = Some(wheel);
        if !back_from_silence
            && let Some((t1, _)) = self.odometry.last()
            && stamp > *t1
        {
            self.wheel_period_s = Some((stamp - *t1).as_secs_f64());
        }
        if self.odometry.len() == 2 {
            self.odometry.remove(0);
            self.wheel_readings.remove(0);
        }
        self.odometry.push((stamp, fused));
        self.wheel_readings.push((stamp, wheel));
    }

    /// The gyro's heading at `t`: between its two latest samples, read on the line through
    /// them; after the latest, carried on at the latest rate for at most
    /// [`GYRO_EXTRAPOLATION`]. Sensors stamped alike arrive in no fixed order (in the
    /// simulator a scan comes before the IMU sample of the same instant), and a heading read
    /// one sample late is a tenth of a degree off for every 0.1 rad/s of turn; as the turn
    /// speeds up or slows down that error changes, and the matcher keeps part of each change
    /// (BENCHMARKS.md, "A scan's heading at its own stamp").
    fn gyro_yaw_at(&self, t: Time) -> f64 {
        let (Some(last_t), Some((prev_t, prev_yaw))) = (self.last_gyro, self.prev_gyro) else {
            return self.gyro_yaw_rad;
        };
        if t <= prev_t {
            return prev_yaw;
        }
        let span = (last_t - prev_t).as_secs_f64();
        if span <= 0.0 {
            return self.gyro_yaw_rad;
        }
        let rate = (self.gyro_yaw_rad - prev_yaw) / span;
        let ahead = (t - prev_t)
            .as_secs_f64()
            .min(span + GYRO_EXTRAPOLATION.as_secs_f64());
        prev_yaw + rate * ahead
    }

    /// Takes an IMU reading: integrates the gyro's yaw rate since the previous one, and
    /// smooths the accelerometer's gravity for the rover's tilt.
    pub fn on_imu(&mut self, imu: &Imu) {
        let t = imu.header.stamp;
        let rate = imu.angular_velocity.z;
        if imu.linear_acceleration_covariance[0][0] >= 0.0 {
            let a = imu.linear_acceleration;
            let w = imu.angular_velocity;
            self.level.on_accel(t, [a.x, a.y, a.z], [w.x, w.y, rate]);
        }
        if self.calibrating(t) {
            // Standing still: what the gyro reads is its bias (and noise), not a turn.
            self.bias_sum += rate;
            self.bias_samples += 1;
            self.prev_gyro = self.last_gyro.map(|prev| (prev, self.gyro_yaw_rad));
            self.last_gyro = Some(t);
            self.gyro_heard = true;
            self.recent.push_heading(t, self.gyro_yaw_rad);
            return;
        } else if self.bias_samples > 0 && self.gyro_bias_rad_s.is_none() {
            self.gyro_bias_rad_s = Some(self.bias_sum / self.bias_samples as f64);
        }
        if let Some(prev) = self.last_gyro {
            if t <= prev {
                // Out of order or repeated: the heading already covers it.
                return;
            }
            self.prev_gyro = Some((prev, self.gyro_yaw_rad));
            let bias = self.gyro_bias_rad_s.unwrap_or(0.0);
            self.gyro_yaw_rad += (rate - bias) * (t - prev).as_secs_f64();
        }
        self.last_gyro = Some(t);
        self.gyro_heard = true;
        self.recent.push_heading(t, self.gyro_yaw_rad);
    }

    /// Whether the rover must stand still at `now` so the gyro's bias can be measured: for
    /// the first [`MappingConfig::gyro_calibration`] of the mission, as on a real rover.
    pub fn calibrating(&self, now: Time) -> bool {
        now < Time::ZERO + self.cfg.gyro_calibration
    }

    /// The gyro bias measured at the start, rad/s, once known.
    pub fn gyro_bias_rad_s(&self) -> Option<f64> {
        self.gyro_bias_rad_s
    }

    /// The rotation that levels body-frame vectors (undoes pitch and roll, keeps yaw)
    /// ([`Levelling::rotation`]).
    fn levelling(&self) -> [[f64; 3]; 3] {
        self.level.rotation()
    }

    /// Takes a depth frame: judges the ground it sees and fuses the verdicts into the hazard
    /// layer at the current pose. Nothing is written while lost.
    pub fn on_depth(&mut self, cloud: &PointCloud) {
        // Nothing before the first scan has placed the rover, and nothing while lost.
        if self.mapper.state() == LocalisationState::Lost || !self.tracked_once {
            return;
        }
        if let Some(filter) = self.cfg.depth_motion_filter {
            let here = self
                .mapper
                .newest_submap()
                .map(|(i, _)| i)
                .zip(self.last_wheel);
            // Wheels that have fallen silent say nothing of whether the rover moves.
            let silent = self.wheels_silent_at(cloud.header.stamp);
            let moved = silent
                || match (here, self.last_judged) {
                    (Some((submap, odom)), Some((last_submap, last_odom))) => {
                        let step = last_odom.inverse() * odom;
                        submap != last_submap
                            || step.x_m.hypot(step.y_m) >= filter.min_travel_m
                            || step.yaw_rad.abs() >= filter.min_turn_rad
                    }
                    _ => true,
                };
            if moved {
                self.last_judged = here;
                self.still_frames = 0;
            } else if self.still_frames >= filter.frames_while_still {
                return;
            }
            self.still_frames += 1;
        }
        let level = self.levelling();
        let (r, o) = (self.cfg.depth_rot, self.cfg.depth_origin_m);
        let levelled_from_optical = |p: [f64; 3]| {
            let b = [
                r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + o[0],
                r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + o[1],
                r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + o[2],
            ];
            [
                level[0][0] * b[0] + level[0][1] * b[1] + level[0][2] * b[2],
                level[1][0] * b[0] + level[1][1] * b[1] + level[1][2] * b[2],
                level[2][0] * b[0] + level[2][1] * b[1] + level[2][2] * b[2],
            ]
        };
        let levelled: Vec<[f64; 3]> = cloud
            .points_in_sensor
            .iter()
            .map(|p| levelled_from_optical([p[0] as f64, p[1] as f64, p[2] as f64]))
            .collect();
        let points: Vec<[f64; 3]> = levelled
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .copied()
            .collect();
        if let Some(relief) = self.cfg.relief_odometry {
            self.fit_relief(cloud.header.stamp, &points, &relief);
        }
        let mut verdicts = judge_frame(&points, &self.cfg.traversability);
        // The organised cloud's columns, for the ground hidden behind rims.
        let (w, h) = (cloud.width as usize, cloud.height as usize);
        if w * h == cloud.points_in_sensor.len() && w > 0 {
            let columns: Vec<Vec<[f64; 3]>> = (0..w)
                .map(|c| (0..h).map(|r| levelled[r * w + c]).collect())
                .collect();
            let silent: Vec<Vec<[f64; 3]>> = match &self.cfg.depth_camera {
                Some(camera) if self.cfg.silent_pixels => camera
                    .silent_ends(&cloud.points_in_sensor, w, h)
                    .into_iter()
                    .map(|ends| ends.into_iter().map(levelled_from_optical).collect())
                    .collect(),
                _ => Vec::new(),
            };
            verdicts.extend(shadow_gaps(
                &columns,
                &silent,
                &self.cfg.traversability,
                SHADOW_MIN_GAP_M,
            ));
        }
        if let Some((submap, origin)) = self.mapper.newest_submap() {
            let pose = self.pose_at(cloud.header.stamp);
            let rover = origin.inverse() * pose;
            match self
                .mapper
                .newest_keyframe()
                .filter(|_| self.cfg.hazards_follow_keyframes.is_some())
            {
                Some((node, keyframe)) => self.hazards.insert_from_keyframe(
                    submap,
                    rover,
                    (node, keyframe.inverse() * pose),
                    &verdicts,
                ),
                None => self.hazards.insert(submap, rover, &verdicts),
            }
            self.hazard_frames += 1;
        }
        if self.cfg.depth_features {
            let stamp = cloud.header.stamp;
            let r = self.cfg.traversability.resolution_m;
            let key = |x: f64, y: f64| ((x / r).floor() as i64, (y / r).floor() as i64);
            let hazard: std::collections::BTreeSet<(i64, i64)> = verdicts
                .iter()
                .filter(|v| v.1)
                .map(|v| key(v.0.x_m, v.0.y_m))
                .collect();
            let on_hazards: Vec<Point2> = points
                .iter()
                .filter(|p| hazard.contains(&key(p[0], p[1])))
                .map(|p| Point2::new(p[0], p[1]))
                .collect();
            let stride = on_hazards.len().div_ceil(DEPTH_FEATURES_MAX).max(1);
            let kept = on_hazards.into_iter().step_by(stride).collect();
            self.depth_features = self
                .headed_odometry_at(stamp)
                .map(|odom| (stamp, odom, kept));
        }
    }

    /// Fits a depth frame's `points` (levelled rover frame) onto the reference frame's relief,
    /// and makes it the next reference once the rover has moved on far enough.
    fn fit_relief(&mut self, stamp: Time, points: &[[f64; 3]], cfg: &ReliefConfig) {
        let Some(odom) = self.headed_odometry_at(stamp) else {
            return;
        };
        let mut refresh = true;
        if let Some((from, patch, at)) = &self.relief_reference {
            let wheels = at.inverse() * odom;
            let fit = relief::register(patch, points, wheels, cfg);
            refresh = fit.is_none()
                || wheels.x_m.hypot(wheels.y_m) >= RELIEF_REFERENCE_TRAVEL_M
                || wheels.yaw_rad.abs() >= RELIEF_REFERENCE_TURN_RAD;
            self.relief_hops.push(ReliefHop {
                from: *from,
                to: stamp,
                wheels,
                fit,
            });
        }
        if refresh {
            self.relief_reference =
                ElevationPatch::from_points(points, cfg).map(|patch| (stamp, patch, odom));
        }
    }

    /// Whether the wheels have missed their last few readings by `t` (a dropout): the
    /// odometry's translation is then stale while the gyro's heading goes on, and the SLAM
    /// must not take the travel they report when they come back as new motion.
    fn wheels_silent_at(&self, t: Time) -> bool {
        match (self.odometry.last(), self.wheel_period_s) {
            (Some((t1, _)), Some(period)) => {
                (t - *t1).as_secs_f64() > WHEELS_SILENT_READINGS * period
            }
            _ => false,
        }
    }

    /// The rover's pose at `t` (not before the latest scan): the latest scan's pose moved
    /// on by the odometry since, if so configured ([`MappingConfig::depth_at_own_stamp`]).
    fn pose_at(&self, t: Time) -> Pose2 {
        let pose = self.mapper.pose();
        if !self.cfg.depth_at_own_stamp {
            return pose;
        }
        match (self.scan_odometry, self.headed_odometry_at(t)) {
            (Some(at_scan), Some(now)) => pose * (at_scan.inverse() * now),
            _ => pose,
        }
    }

    /// Odometry at `t` with the gyro's heading at `t` once the gyro is heard: it samples
    /// five times as often as the wheels report.
    fn headed_odometry_at(&self, t: Time) -> Option<Pose2> {
        let mut odom = self.odometry_at(t)?;
        if self.gyro_heard {
            odom.yaw_rad = self.gyro_yaw_at(t);
        }
        Some(odom)
    }

    /// Odometry at `t`, interpolated (or extrapolated a little) from the latest two readings.
    fn odometry_at(&self, t: Time) -> Option<Pose2> {
        self.reading_at(&self.odometry, t)
    }

    /// The two latest `readings` (oldest first) interpolated at `t`.
    fn reading_at(&self, readings: &[(Time, Pose2)], t: Time) -> Option<Pose2> {
        match readings {
            [] => None,
            [(_, p)] => Some(*p),
            [(t0, p0), (t1, p1)] => {
                let span = (*t1 - *t0).as_secs_f64();
                if span <= 0.0 {
                    return Some(*p1);
                }
                // Never more than one reading's period beyond the newest (after a dropout the
                // two readings are seconds apart).
                let limit = self.wheel_period_s.map_or(2.0, |p| 1.0 + p / span).min(2.0);
                let s = ((t - *t0).as_secs_f64() / span).clamp(0.0, limit);
                Some(p0.interpolate(p1, s))
            }
            _ => unreachable!("at most two readings are kept"),
        }
    }

    fn header(&self, stamp: Time) -> Header {
        Header {
            stamp,
            frame_id: format!("{}/map", self.id.namespace()),
        }
    }

    /// Takes a lidar scan; pushes the pose (and any change of state, and the map when due)
    /// to `out`.
    pub fn on_scan(&mut self, scan: &LaserScan, out: &mut Vec<Outgoing>) {
        // A sweeping scan is taken as seen at its last beam, once de-skewed; an instantaneous
        // one at its stamp.
        let stamp = scan.last_beam_time();
        let deskewing = self.cfg.deskew && scan.sweep() > Duration::ZERO;
        let Some(odom) = self.headed_odometry_at(stamp) else {
            // No odometry yet: nothing to anchor the map frame to.
            return;
        };
        if self.gyro_heard
            && let Some(wheels) = self.reading_at(&self.wheel_readings, stamp)
        {
            self.mapper.set_wheel_heading(wheels.yaw_rad);
        }
        let max = (self.cfg.mapper.frontend.max_range_m as f32).min(scan.range_max_m);
        let min = (self.cfg.mapper.frontend.min_range_m as f32).max(scan.range_min_m);
        // A point's place on the level is the levelling rotation applied to it: its last
        // row (the unit gravity reaction in the body frame) gives the height.
        let level = self.levelling();
        let up = level[2];
        let levelled = self.cfg.levelled_points;
        let (lx, lh) = (self.cfg.lidar_x_m, self.cfg.lidar_height_m);
        // How far a return's levelled height may be off per metre of range, for the tilt
        // the smoothed gravity has not caught up with.
        let unsettled_per_m = if self.cfg.tilt_gate {
            angle_between(&self.level.gravity(), &self.level.newest()).sin()
        } else {
            0.0
        };
        let mut points = Vec::with_capacity(scan.ranges_m.len());
        let mut heights = Vec::with_capacity(scan.ranges_m.len());
        let mut offsets = Vec::with_capacity(if deskewing { scan.ranges_m.len() } else { 0 });
        let by_points = self.cfg.smooth_ranges && self.cfg.smoothing == ScanSmoothing::Points;
        let ranges = if self.cfg.smooth_ranges && !by_points {
            std::borrow::Cow::Owned(smoothed(
                &scan.ranges_m,
                self.cfg.smoothing,
                scan.angle_increment_rad,
            ))
        } else {
            std::borrow::Cow::Borrowed(&scan.ranges_m)
        };
        let mut clear = Vec::new();
        for (i, r) in ranges.iter().enumerate() {
            if !(r.is_finite() && *r >= min && *r < max) {
                if let Some(reach) = self.cfg.clear_rays_m
                    && !(r.is_finite() && *r < max)
                {
                    let a = (scan.angle_min_rad + i as f32 * scan.angle_increment_rad) as f64;
                    clear.push(Point2::new(lx + reach * a.cos(), reach * a.sin()));
                }
                continue;
            }
            let a = (scan.angle_min_rad + i as f32 * scan.angle_increment_rad) as f64;
            let r = *r as f64;
            let averaged = by_points
                .then(|| smoothed_point(&ranges, scan.angle_min_rad, scan.angle_increment_rad, i))
                .flatten();
            let (x, y) = averaged.map_or((lx + r * a.cos(), r * a.sin()), |(x, y)| (lx + x, y));
            // Height of the return above the ground under the rover, levelled.
            let height = up[0] * x + up[1] * y + up[2] * lh;
            if height < self.cfg.ground_clearance_m + r * unsettled_per_m {
                self.floor_hits += 1;
                continue;
            }
            points.push(if levelled {
                on_the_level(&level, [x, y, lh])
            } else {
                Point2::new(x, y)
            });
            heights.push(height);
            if deskewing {
                offsets.push(scan.beam_offset(i));
            }
        }
        if deskewing {
            sweep::deskew(
                &self.recent,
                scan.header.stamp,
                stamp,
                &mut points,
                &offsets,
            );
        }
        let sample = OdomSample {
            pose: odom,
            wheels_silent: self.wheels_silent_at(stamp),
        };
        // The last depth frame's features, where the wheels say they are now.
        let features = match &self.depth_features {
            Some((t, at, cells))
                if (stamp.as_secs_f64() - t.as_secs_f64()).abs() < DEPTH_FEATURES_MAX_AGE_S =>
            {
                let moved = odom.inverse() * *at;
                cells.iter().map(|p| moved.transform_point(*p)).collect()
            }
            _ => Vec::new(),
        };
        self.mapper.set_features(features);
        self.mapper.set_clear_rays(clear);
        self.mapper.set_point_heights(heights);
        let tracked = self
            .mapper
            .add_points_with(stamp.as_secs_f64(), sample, points);
        // A scan taken while the wheels are silent holds their last reading, and the first
        // reading back carries the whole dropout's travel: no frame is moved on by that.
        self.scan_odometry = (!sample.wheels_silent).then_some(odom);
        self.tracked_once = true;
        for (_, change) in self.mapper.take_transitions() {
            out.push(Outgoing {
                topic: self.id.topic("localisation"),
                message: Message::Localisation(LocalisationStatus {
                    header: self.header(stamp),
                    state: change.state,
                    reason: change.reason,
                }),
            });
        }
        out.push(Outgoing {
            topic: self.id.topic("pose"),
            message: Message::Pose(Box::new(PoseWithCovarianceStamped {
                header: self.header(stamp),
                pose: PoseWithCovariance {
                    pose: Pose3 {
                        position: Vec3::new(tracked.pose.x_m, tracked.pose.y_m, 0.0),
                        orientation: Quaternion::from_roll_pitch_yaw(
                            0.0,
                            0.0,
                            tracked.pose.yaw_rad,
                        ),
                    },
                    covariance: self.covariance(tracked.state),
                },
            })),
        });
        if stamp >= self.next_delta {
            self.publish_delta(stamp, out);
        }
        if stamp >= self.next_map {
            self.publish_map(stamp, out);
        }
    }

    /// A receiver asked for a snapshot: the next update carries every cell.
    pub fn request_snapshot(&mut self) {
        self.snapshot_wanted = true;
    }

    /// Publishes the changes of the map since the last update (and restarts the period).
    pub fn publish_delta(&mut self, now: Time, out: &mut Vec<Outgoing>) {
        self.next_delta = now + self.cfg.delta_period;
        let header = self.header(now);
        let (hazards, version) = self.hazard_states();
        let view = self.mapper.live_map();
        let grid = self
            .published_layer
            .refresh_versioned(&view, hazards, Some(version));
        // Updates carry the geometry of the map message (whose resolution is a float32, as
        // in ROS), so a map rebuilt from them and the map itself agree exactly.
        let geometry = GridGeometry {
            resolution_m: grid.geometry().resolution_m as f32 as f64,
            ..*grid.geometry()
        };
        let update = self
            .delta_encoder
            .update_cells(geometry, grid.cells(), self.snapshot_wanted);
        self.snapshot_wanted = false;
        // Snapshots go on their own topic: a queue that supersedes stale map updates must
        // never replace a snapshot with an update that builds on it.
        let leaf = if update.is_snapshot() {
            "map/snapshot"
        } else {
            "map/delta"
        };
        out.push(Outgoing {
            topic: self.id.topic(leaf),
            message: Message::MapDelta(Box::new(MapDelta { header, update })),
        });
    }

    /// Publishes the map now (and restarts the period).
    pub fn publish_map(&mut self, now: Time, out: &mut Vec<Outgoing>) {
        self.next_map = now + self.cfg.map_period;
        out.push(Outgoing {
            topic: self.id.topic("map"),
            message: Message::Map(self.map(now)),
        });
    }

    /// The pose covariance: how far the pose may be from the truth by the path that ties it
    /// to the start (see [`realms_slam::drift`]) and any swing of the heading from the
    /// gyro's since the pose was last set
    /// ([`realms_slam::mapper::MapperConfig::heading_departure`]), at least what the last
    /// match's information leaves (with a floor of a centimetre and a fraction of a degree),
    /// and huge when lost, or before any match without the path's model.
    fn covariance(&mut self, state: LocalisationState) -> [[f64; 6]; 6] {
        let mut c = [[0.0; 6]; 6];
        // z, roll and pitch are not estimated.
        for i in [2, 3, 4] {
            c[i][i] = 1e6;
        }
        let (var_xy, var_yaw) = match state {
            LocalisationState::Lost => (1e4, 10.0),
            _ => {
                let h = self.mapper.last_information();
                // No match yet (standing at the known start while the gyro is calibrated):
                // the match says nothing, the path from the start all there is.
                let drift = self.mapper.pose_uncertainty();
                let none = if drift.is_some() { 0.0 } else { 1e4 };
                let per_axis = |v: f64| if v > 1e-9 { 1.0 / v } else { none };
                let (drift_m, drift_rad) = drift.unwrap_or_default();
                (
                    per_axis(h[0][0].min(h[1][1]))
                        .max(1e-4)
                        .max(drift_m * drift_m),
                    per_axis(h[2][2]).max(3e-5).max(drift_rad * drift_rad),
                )
            }
        };
        c[0][0] = var_xy;
        c[1][1] = var_xy;
        c[5][5] = var_yaw;
        c
    }

    /// Draws the hazard layers the graph bent again where it has their keyframes
    /// ([`MappingConfig::hazards_follow_keyframes`]), for the map the rover publishes last.
    /// Apart from [`finish_map`](Self::finish_map): a rover finishes its map when it is home
    /// and its peers are done, and layers drawn anew there leave slivers of ground it judged
    /// unjudged on its map, which it would drive out again to judge (sixteen missions ran
    /// 81 s longer on average).
    pub fn finish_hazards(&mut self) {
        self.redraw_bent_hazards();
    }

    /// Draws again the hazard layers the graph bent ([`MappingConfig::hazards_follow_keyframes`]).
    fn redraw_bent_hazards(&mut self) {
        let Some(bend) = self.cfg.hazards_follow_keyframes else {
            return;
        };
        let mapper = &self.mapper;
        if self
            .hazards
            .redraw_bent(|s, node| mapper.keyframe_in_submap(s, node), bend)
            > 0
        {
            self.hazard_cache = None;
        }
    }

    /// The hazard layer drawn at the submaps' poses now, with the craters or hollows it
    /// implies marked if the rover infers them.
    fn hazard_states(&mut self) -> (Grid<CellState>, u64) {
        let origins = self.mapper.submap_origins();
        // The graph moved: it may have bent some layers' keyframes too.
        if self.cfg.hazards_redrawn_while_mapping
            && self
                .hazard_cache
                .as_ref()
                .is_none_or(|kept| kept.origins != origins)
        {
            self.redraw_bent_hazards();
        }
        let discs = self.cfg.traversability.crater_discs;
        let reads_live = self.hollows.is_some() || discs.is_some();
        let view = reads_live.then(|| self.mapper.live_map());
        if let Some(kept) = &self.hazard_cache
            && kept.frames == self.hazard_frames
            && kept.origins == origins
            && match (&view, kept.live) {
                (None, None) => true,
                (Some(view), Some((geometry, version))) => {
                    view.geometry == geometry && !view.changed_anywhere_since(version)
                }
                _ => false,
            }
        {
            return (kept.states.clone(), self.hazard_versions);
        }
        let mut states = self.hazards.states(&origins);
        let live = view.as_ref().map(|v| (v.geometry, v.version));
        if let Some(view) = view {
            let g = view.geometry;
            let state_at = |p: Point2| g.world_to_cell(p).map(|c| view.states[g.index(c)]);
            if let Some(hollows) = &mut self.hollows {
                // The live map's cell under each hazard cell's centre, by table: the flood
                // asks of some 28,000 cells each time.
                let under = CentreLookup::new(&g, states.geometry());
                hollows.fill_cells(&mut states, |c| {
                    under
                        .index(c.x, c.y)
                        .is_some_and(|i| view.states[i] == CellState::Free)
                });
            }
            if let Some(discs) = discs {
                // A hazard cell with what the lidar sees as an obstacle at its centre or one
                // judged cell away (eight points round it) is a wall's or a rock's foot, not
                // a crater's wall. (The discs' own counts, such as their fewest cells, are of
                // the cells the layers are drawn on.)
                let reach_m = self.cfg.traversability.resolution_m;
                let wall = |p: Point2| {
                    (-1..=1).any(|dy| {
                        (-1..=1).any(|dx| {
                            state_at(Point2::new(
                                p.x_m + dx as f64 * reach_m,
                                p.y_m + dy as f64 * reach_m,
                            )) == Some(CellState::Occupied)
                        })
                    })
                };
                realms_slam::craters::fill_crater_discs(&mut states, &discs, wall);
            }
        }
        self.hazard_versions += 1;
        let version = self.hazard_versions;
        self.hazard_cache = Some(HazardStatesFrom {
            frames: self.hazard_frames,
            origins,
            live,
            states: states.clone(),
        });
        (states, version)
    }

    /// The map at `factor` times the SLAM resolution (a power of two up to
    /// [`LIVE_TILE_CELLS`](realms_slam::assembly::LIVE_TILE_CELLS)), for navigation: a cell
    /// is an obstacle if any of its SLAM cells is, else hazard if the hazard layer says so at
    /// its centre, else free if the depth camera judged it safe, else
    /// [`UNJUDGED`](realms_nav::frontier::UNJUDGED) if any SLAM cell saw it free, else
    /// unknown.
    pub fn nav_map(&mut self, factor: usize) -> Grid<i8> {
        let (hazards, version) = self.hazard_states();
        let layer = self
            .planner_layer
            .take()
            .filter(|l| l.factor() == TiledLayer::new(factor).factor())
            .unwrap_or_else(|| TiledLayer::new(factor).marking_unjudged());
        let view = self.mapper.live_map();
        let layer = self.planner_layer.insert(layer);
        layer
            .refresh_versioned(&view, hazards, Some(version))
            .clone()
    }

    /// The map now, at the SLAM resolution: the lidar map with the hazard layer over it.
    fn published_grid(&mut self) -> &Grid<i8> {
        let (hazards, version) = self.hazard_states();
        let view = self.mapper.live_map();
        self.published_layer
            .refresh_versioned(&view, hazards, Some(version))
    }

    /// The map now, as a ROS occupancy grid.
    pub fn map(&mut self, stamp: Time) -> OccupancyGrid {
        let header = self.header(stamp);
        map_message(header, self.published_grid())
    }
}

/// `grid` as a ROS occupancy grid.
fn map_message(header: Header, grid: &Grid<i8>) -> OccupancyGrid {
    let g = grid.geometry();
    OccupancyGrid {
        header,
        info: MapMetaData {
            resolution_m: g.resolution_m as f32,
            width: g.width as u32,
            height: g.height as u32,
            origin: Pose3 {
                position: Vec3::new(g.origin.x_m, g.origin.y_m, 0.0),
                orientation: Quaternion::IDENTITY,
            },
        },
        data: grid.cells().to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::msgs::PoseWithCovariance;

    fn mapping() -> Mapping {
        Mapping::new(
            RoverId(1),
            MappingConfig {
                lidar_x_m: 0.1,
                lidar_height_m: 0.3,
                ground_clearance_m: 0.12,
                tilt_smoothing: 0.2,
                tilt_less_wheels: None,
                tilt_gyro: false,
                tilt_gate: false,
                levelled_points: false,
                depth_at_own_stamp: false,
                hazards_rounded_out: false,
                hazards_follow_keyframes: None,
                hazards_redrawn_while_mapping: false,
                clear_rays_m: None,
                mapper: rover_mapper_config(),
                map_period: Duration::from_secs(60),
                delta_period: Duration::from_secs(2),
                gyro_calibration: Duration::from_secs(5),
                depth_rot: [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]],
                depth_origin_m: [0.2, 0.0, 0.3],
                traversability: TraversabilityConfig::default(),
                depth_camera: None,
                silent_pixels: false,
                smooth_ranges: false,
                smoothing: ScanSmoothing::Ranges,
                deskew: true,
                depth_features: false,
                relief_odometry: None,
                depth_motion_filter: None,
            },
        )
    }

    fn imu(t: Time, yaw_rate: f64, pitch_rad: f64) -> Imu {
        let g = 9.81;
        let mut m = Imu {
            linear_acceleration: Vec3::new(-g * pitch_rad.sin(), 0.0, g * pitch_rad.cos()),
            ..Imu::default()
        };
        m.header.stamp = t;
        m.angular_velocity.z = yaw_rate;
        m
    }

    fn odom(t: Time) -> Odometry {
        let mut o = Odometry {
            pose: PoseWithCovariance::default(),
            ..Odometry::default()
        };
        o.pose.pose.orientation = Quaternion::IDENTITY;
        o.header.stamp = t;
        o
    }

    /// One beam straight ahead at `range_m`, the rest without a return.
    fn scan_ahead(t: Time, range_m: f32) -> LaserScan {
        let n = 360;
        let mut ranges = vec![f32::INFINITY; n];
        ranges[n / 2] = range_m;
        crate::test_scan(t, ranges)
    }

    /// The returns `m` drops as the floor from one scan with a return `range_m` ahead, taken
    /// after 0.4 s of accelerometer samples of a level rover whose last sample is at
    /// `last_pitch_rad` (a wheel just climbed a rock).
    fn floor_hits_after_a_tilt(mut m: Mapping, last_pitch_rad: f64, range_m: f32) -> u64 {
        for k in 0..=20 {
            let pitch_rad = if k == 20 { last_pitch_rad } else { 0.0 };
            m.on_imu(&imu(Time::from_secs_f64(k as f64 * 0.02), 0.0, pitch_rad));
        }
        m.on_odometry(&odom(Time::from_secs_f64(0.4)));
        m.on_scan(
            &scan_ahead(Time::from_secs_f64(0.4), range_m),
            &mut Vec::new(),
        );
        m.floor_hits()
    }

    #[test]
    fn a_return_the_unsettled_tilt_could_have_moved_off_the_floor_is_dropped_with_the_tilt_gate() {
        // As in the test below: a wheel climbs a rock at the last sample, 5 degrees nose
        // down, and the smoothed levelling holds the rover at 1 degree. With the gate the
        // floor 3.34 m ahead is dropped; with the tilt settled, a wall 8 m ahead (a return at
        // the lidar's height) is kept.
        let gated = || {
            let mut m = mapping();
            m.cfg.tilt_gate = true;
            m
        };
        assert_eq!(floor_hits_after_a_tilt(gated(), 5f64.to_radians(), 3.34), 1);
        assert_eq!(
            floor_hits_after_a_tilt(mapping(), 5f64.to_radians(), 3.34),
            0
        );
        assert_eq!(floor_hits_after_a_tilt(gated(), 0.0, 8.0), 0);
    }

    #[test]
    fn a_return_from_a_tilted_rover_is_placed_where_it_lies_on_the_level() {
        // The rover pitched 10 degrees nose down (REP 103), a wall 10 m ahead of its base
        // across the floor. The base turns the lidar's origin and its beam with it (as the
        // simulator's `world_from_base` does): the beam ahead meets the wall 1 / cos(10 deg)
        // farther than the wall lies across the floor from the lidar, whose origin the
        // pitch has carried forward of the base by its height's sine.
        let pitch = 10f64.to_radians();
        let (lx, lh, wall) = (0.1, 0.3, 10.0);
        let range = (wall - (lx * pitch.cos() + lh * pitch.sin())) / pitch.cos();
        let mut m = mapping();
        for k in 0..200 {
            m.on_imu(&imu(Time::from_secs_f64(k as f64 * 0.02), 0.0, pitch));
        }
        let point = on_the_level(&m.levelling(), [lx + range, 0.0, lh]);
        assert!(
            (point.x_m - wall).abs() < 1e-6 && point.y_m.abs() < 1e-9,
            "{point:?}"
        );
        // In the sweep's tilted plane the wall lies 10 cm too far.
        assert!(lx + range - wall > 0.09, "{}", lx + range);
        // Level, the two agree.
        let mut level = mapping();
        for k in 0..200 {
            level.on_imu(&imu(Time::from_secs_f64(k as f64 * 0.02), 0.0, 0.0));
        }
        let point = on_the_level(&level.levelling(), [lx + 5.0, 2.0, lh]);
        assert!((point.x_m - lx - 5.0).abs() < 1e-9 && (point.y_m - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_depth_frame_is_placed_at_its_own_stamp_by_the_odometry_since_the_scan() {
        // Odometry heading 0.5 rad, a scan at 0.40 s, then the wheels 2 cm on along their
        // heading and turned 0.05 rad at 0.45 s, when a depth frame is stamped.
        let at = |t: f64, along: f64, yaw: f64| {
            let mut o = odom(Time::from_secs_f64(t));
            o.pose.pose.position.x = along * 0.5f64.cos();
            o.pose.pose.position.y = along * 0.5f64.sin();
            o.pose.pose.orientation = Quaternion::from_roll_pitch_yaw(0.0, 0.0, yaw);
            o
        };
        for own_stamp in [false, true] {
            let mut m = mapping();
            m.cfg.depth_at_own_stamp = own_stamp;
            m.on_odometry(&at(0.35, 0.14, 0.5));
            m.on_odometry(&at(0.40, 0.16, 0.5));
            m.on_scan(&scan_ahead(Time::from_secs_f64(0.4), 3.0), &mut Vec::new());
            m.on_odometry(&at(0.45, 0.18, 0.55));
            let scan_pose = m.mapper.pose();
            let expected = if own_stamp {
                scan_pose * Pose2::new(0.02, 0.0, 0.05)
            } else {
                scan_pose
            };
            let got = m.pose_at(Time::from_secs_f64(0.45));
            let off = got.relative_to(&expected);
            assert!(
                off.x_m.hypot(off.y_m) < 1e-9 && off.yaw_rad.abs() < 1e-9,
                "{own_stamp}: {got:?} against {expected:?}"
            );
        }
    }

    /// The wheels' reading at `t`: `x` metres along the x axis, heading `yaw`.
    fn wheels_at(t: f64, x: f64, yaw: f64) -> Odometry {
        let mut o = odom(Time::from_secs_f64(t));
        o.pose.pose.position.x = x;
        o.pose.pose.orientation = Quaternion::from_roll_pitch_yaw(0.0, 0.0, yaw);
        o
    }

    /// A few floor points two metres ahead of the camera (z forward, y down).
    fn floor_frame(t: f64) -> PointCloud {
        PointCloud {
            header: Header {
                stamp: Time::from_secs_f64(t),
                frame_id: "rover1/depth_optical".into(),
            },
            width: 2,
            height: 1,
            points_in_sensor: vec![[-0.1, 0.3, 2.0], [0.1, 0.3, 2.0]],
        }
    }

    /// A round room three metres about the rover, seen at `t`.
    fn round_room(t: f64) -> LaserScan {
        let mut scan = scan_ahead(Time::from_secs_f64(t), 3.0);
        scan.ranges_m.fill(3.0);
        scan
    }

    #[test]
    fn a_still_rover_judges_its_first_frames_and_then_none_until_its_wheels_move() {
        let mut m = mapping();
        m.cfg.depth_motion_filter = Some(DepthStillFilter {
            min_travel_m: 0.02,
            min_turn_rad: 0.5f64.to_radians(),
            frames_while_still: 3,
        });
        m.on_odometry(&wheels_at(0.0, 0.0, 0.0));
        m.on_scan(&round_room(0.05), &mut Vec::new());
        let mut t = 0.1;
        let mut judged = Vec::new();
        // Standing: five frames, three judged.
        for _ in 0..5 {
            m.on_depth(&floor_frame(t));
            judged.push(m.hazard_frames);
            t += 0.5;
        }
        // The wheels move a centimetre: still standing.
        m.on_odometry(&wheels_at(t, 0.01, 0.0));
        m.on_depth(&floor_frame(t));
        judged.push(m.hazard_frames);
        // Three centimetres from where it stopped: moved, judged again.
        m.on_odometry(&wheels_at(t + 0.1, 0.03, 0.0));
        m.on_depth(&floor_frame(t + 0.2));
        judged.push(m.hazard_frames);
        // Turned a degree where it stands: moved.
        m.on_odometry(&wheels_at(t + 0.3, 0.03, 1f64.to_radians()));
        m.on_depth(&floor_frame(t + 0.4));
        judged.push(m.hazard_frames);
        assert_eq!(judged, [1, 2, 3, 3, 3, 3, 4, 5]);
        // The wheels fall silent (a dropout): they say nothing of the rover standing, and
        // every frame is judged.
        let before = m.hazard_frames;
        for k in 0..5 {
            m.on_depth(&floor_frame(t + 3.0 + 0.5 * k as f64));
        }
        assert_eq!(m.hazard_frames, before + 5);
        // Without the filter every frame is judged.
        let mut every = mapping();
        every.on_odometry(&wheels_at(0.0, 0.0, 0.0));
        every.on_scan(&round_room(0.05), &mut Vec::new());
        for k in 0..5 {
            every.on_depth(&floor_frame(0.1 + 0.5 * k as f64));
        }
        assert_eq!(every.hazard_frames, 5);
    }

    #[test]
    fn a_rover_standing_at_its_start_publishes_its_pose_as_known_to_centimetres() {
        let mut m = mapping();
        m.on_odometry(&wheels_at(0.0, 0.0, 0.0));
        let mut sigmas = Vec::new();
        // Standing: after the first scan the motion filter matches none.
        for k in 0..20 {
            let mut out = Vec::new();
            m.on_scan(&round_room(0.05 + 0.1 * k as f64), &mut out);
            for o in out {
                if let Message::Pose(p) = o.message {
                    let c = p.pose.covariance;
                    sigmas.push((c[0][0].sqrt(), c[5][5].sqrt()));
                }
            }
        }
        assert_eq!(sigmas.len(), 20);
        for (m, rad) in sigmas {
            // The path model's floor, 4 cm, and the heading's of a match, 0.31 degrees;
            // before a match the last match's information used to say 100 m.
            assert!(m <= 0.05 && rad <= 0.4f64.to_radians(), "{m} m, {rad} rad");
        }
    }

    #[test]
    fn hazard_states_are_kept_while_what_they_come_from_stays_and_redone_when_it_changes() {
        // With the hollows, which read the live map.
        let mut cfg = mapping().cfg;
        cfg.traversability.hazard_hollows = Some(realms_slam::hollows::HazardHollows::default());
        let mut m = Mapping::new(RoverId(1), cfg);
        m.on_odometry(&wheels_at(0.0, 0.0, 0.0));
        m.on_scan(&round_room(0.05), &mut Vec::new());
        m.on_depth(&floor_frame(0.1));
        let (first, v1) = m.hazard_states();
        let (again, v2) = m.hazard_states();
        assert_eq!((&first, v1), (&again, v2), "nothing changed: kept");
        // A frame more: new states, the same as worked out from nothing.
        m.on_depth(&floor_frame(0.6));
        let (after_frame, v3) = m.hazard_states();
        assert_ne!(v3, v1);
        m.hazard_cache = None;
        assert_eq!(m.hazard_states().0, after_frame);
        // The live map changes (the rover moved on and saw the room from elsewhere).
        let (_, v4) = m.hazard_states();
        m.on_odometry(&wheels_at(1.0, 0.5, 0.0));
        m.on_scan(&round_room(1.05), &mut Vec::new());
        let (moved_on, v5) = m.hazard_states();
        assert_ne!(v5, v4);
        m.hazard_cache = None;
        assert_eq!(m.hazard_states().0, moved_on);
    }

    #[test]
    fn the_angle_between_two_vectors_is_read_without_losing_small_angles() {
        let a = [0.0, 0.0, 9.81];
        for deg in [1e-6, 0.5, 5.0, 90.0, 179.0] {
            let t = f64::to_radians(deg);
            let b = [2.0 * t.sin(), 0.0, 2.0 * t.cos()];
            assert!((angle_between(&a, &b) - t).abs() < 1e-12, "{deg}");
        }
        assert_eq!(angle_between(&a, &[0.0; 3]), 0.0);
    }

    #[test]
    fn a_return_from_the_floor_ahead_of_a_nose_down_rover_is_dropped() {
        // Pitched 5 degrees nose down (REP 103: positive pitch), the beam ahead meets flat
        // ground where 0.3 m - (0.1 + r) sin 5deg = 0, at r = 3.34 m; a rock face there at
        // the same range would have returned from higher up only on level ground.
        let pitch = 5f64.to_radians();
        for (pitch_rad, expect_drop) in [(pitch, true), (0.0, false)] {
            let mut m = mapping();
            for k in 0..20 {
                m.on_imu(&imu(Time::from_secs_f64(k as f64 * 0.02), 0.0, pitch_rad));
            }
            m.on_odometry(&odom(Time::from_secs_f64(0.4)));
            let mut out = Vec::new();
            m.on_scan(&scan_ahead(Time::from_secs_f64(0.4), 3.34), &mut out);
            assert_eq!(m.floor_hits() == 1, expect_drop, "pitch {pitch_rad}");
        }
    }

    #[test]
    fn a_sudden_tilt_levels_the_next_scan_only_if_the_newest_sample_counts_in_full() {
        // Level for 0.4 s, then a wheel climbs a rock: 5 degrees nose down from the last
        // accelerometer sample before the scan on. Smoothed to a fifth, the levelling still
        // holds the rover at 1 degree, and the floor ahead passes for a return 0.24 m up.
        for (tilt_smoothing, expect_drop) in [(1.0, true), (0.2, false)] {
            let mut cfg = mapping().cfg;
            cfg.tilt_smoothing = tilt_smoothing;
            let m = Mapping::new(RoverId(1), cfg);
            assert_eq!(
                floor_hits_after_a_tilt(m, 5f64.to_radians(), 3.34) == 1,
                expect_drop,
                "smoothing {tilt_smoothing}"
            );
        }
    }

    /// The heading a turn has reached at `t`: from 6 s it speeds up to 0.8 rad/s at
    /// 2 rad/s^2, holds that for 0.6 s and slows down again, as the rovers turn.
    fn turned_rad(t: f64) -> f64 {
        let s = t - 6.0;
        if s <= 0.0 {
            0.0
        } else if s < 0.4 {
            s * s
        } else if s < 1.0 {
            0.16 + 0.8 * (s - 0.4)
        } else if s < 1.4 {
            0.64 + 0.8 * (s - 1.0) - (s - 1.0).powi(2)
        } else {
            0.8
        }
    }

    /// The worst heading error of scans (without returns, so the pose is the odometry's
    /// prediction) taken through the turn, with each scan arriving before or after the
    /// gyro and wheel readings of its own instant.
    fn worst_scan_heading_error(scan_first: bool) -> f64 {
        let mut m = mapping();
        let mut out = Vec::new();
        let mut worst: f64 = 0.0;
        for k in 0..=1000 {
            let t = 0.01 * k as f64;
            let stamp = Time::from_secs_f64(t);
            let scan = |m: &mut Mapping, out: &mut Vec<Outgoing>| {
                m.on_scan(&crate::test_scan(stamp, vec![f32::INFINITY; 360]), out);
                if t > 5.5 {
                    normalize_angle_rad(m.pose().yaw_rad - turned_rad(t)).abs()
                } else {
                    0.0
                }
            };
            // Scans at 10 Hz, wheels at 20 Hz, the gyro at 50 Hz.
            let scan_due = k % 10 == 0;
            if scan_due && scan_first {
                worst = worst.max(scan(&mut m, &mut out));
            }
            if k % 5 == 0 {
                m.on_odometry(&odom(stamp));
            }
            if k % 2 == 0 {
                // Each 20 ms step's mean rate at its end, as the simulator's gyro reports.
                let rate = (turned_rad(t) - turned_rad(t - 0.02)) / 0.02;
                m.on_imu(&imu(stamp, rate, 0.0));
            }
            if scan_due && !scan_first {
                worst = worst.max(scan(&mut m, &mut out));
            }
        }
        worst
    }

    #[test]
    fn a_scans_heading_is_the_gyros_at_the_scans_own_stamp() {
        // Read one gyro sample late, the heading would lag 0.016 rad at full turn; read off
        // the wheels' 20 Hz poses, it errs by 6e-3 rad while the turn speeds up.
        let after = worst_scan_heading_error(false);
        assert!(after < 1e-9, "{after}");
        // Before the gyro's sample of its instant: carried on from the two before, off by
        // the rate's change over one sample (2 rad/s^2 * 0.02 s * 0.02 s = 8e-4 rad).
        let before = worst_scan_heading_error(true);
        assert!(before < 1e-3, "{before}");
    }

    #[test]
    fn ranges_are_averaged_with_neighbours_on_one_surface_only() {
        let inf = f32::INFINITY;
        let ranges = [1.0, 1.02, 1.0, 5.0, 5.0, 5.04, 5.0, inf];
        let s = smoothed(&ranges, ScanSmoothing::Ranges, 1f32.to_radians());
        // On one surface: (1.0 + 2 * 1.02 + 1.0) / 4 and (5.0 + 2 * 5.04 + 5.0) / 4.
        assert!((s[1] - 1.01).abs() < 1e-6, "{s:?}");
        assert!((s[5] - 5.02).abs() < 1e-6, "{s:?}");
        // Beside an edge (1 m to 5 m), a missing return or the wrap onto one: as they were.
        for i in [0, 2, 3, 6, 7] {
            assert_eq!(s[i].to_bits(), ranges[i].to_bits(), "{i}: {s:?}");
        }
        // Inside a run of one surface the middle is averaged: 5.0 between 5.0 and 5.04.
        assert!((s[4] - 5.01).abs() < 1e-6, "{s:?}");
    }

    #[test]
    fn endpoints_or_inverse_ranges_averaged_lie_on_an_oblique_wall_where_ranges_lie_beyond_it() {
        // A wall on the line x = 2 m, seen by the beams between 60 and 78 degrees.
        let (angle_min, increment) = (-std::f32::consts::PI, 1f32.to_radians());
        let angle = |i: usize| f64::from(angle_min + i as f32 * increment);
        let ranges: Vec<f32> = (0..360)
            .map(|i| {
                let a = angle(i);
                if (60f64.to_radians()..78.5f64.to_radians()).contains(&a) {
                    (2.0 / a.cos()) as f32
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        let beam = 180 + 75;
        let (x, _) = smoothed_point(&ranges, angle_min, increment, beam).expect("a return");
        assert!((x - 2.0).abs() < 1e-5, "{x}");
        // The ranges' average, 75 degrees off the wall's normal, lies 4 mm beyond it; their
        // inverses' average lies on it, and so it does at every beam the wall fills.
        let by = |how| smoothed(&ranges, how, increment);
        let (by_ranges, by_inverses) =
            (by(ScanSmoothing::Ranges), by(ScanSmoothing::InverseRanges));
        let beyond = |r: f32| f64::from(r) * angle(beam).cos() - 2.0;
        assert!(
            beyond(by_ranges[beam]) > 0.003,
            "{}",
            beyond(by_ranges[beam])
        );
        for (i, r) in by_inverses
            .iter()
            .enumerate()
            .filter(|(_, r)| r.is_finite())
        {
            let off = f64::from(*r) * angle(i).cos() - 2.0;
            assert!(off.abs() < 1e-5, "beam {i}: {off}");
        }
    }

    #[test]
    fn ranges_fitted_by_a_parabola_follow_a_boulders_round_outline_where_averages_lie_inside_it() {
        // A boulder of 0.5 m radius centred 5 m ahead: the beams within 5.7 degrees meet it.
        let (angle_min, increment) = (-std::f32::consts::PI, 1f32.to_radians());
        let angle = |i: usize| f64::from(angle_min + i as f32 * increment);
        let (centre_m, radius_m) = (5.0, 0.5);
        let on_the_rock = |a: f64| {
            let across = centre_m * a.sin();
            (across.abs() < radius_m && a.cos() > 0.0)
                .then(|| centre_m * a.cos() - (radius_m * radius_m - across * across).sqrt())
        };
        let ranges: Vec<f32> = (0..360)
            .map(|i| on_the_rock(angle(i)).map_or(f32::INFINITY, |r| r as f32))
            .collect();
        let by = |how| smoothed(&ranges, how, increment);
        let (averaged, fitted) = (by(ScanSmoothing::Ranges), by(ScanSmoothing::Quadratic));
        let fitted_else_averaged = by(ScanSmoothing::QuadraticElseAverage);
        // Straight ahead the average of three lies 3.4 mm inside the rock (4.5034 m).
        let ahead = 180;
        let inside = f64::from(averaged[ahead]) - 4.5;
        assert!(inside > 0.003, "{inside}");
        // The parabola's reading is within a millimetre of the outline wherever five beams
        // meet the rock (0.13 mm ahead, 1.2 mm 3 degrees off, where the outline turns
        // fastest), the average's 3.5-6 mm inside; at the rock's ends the range as it is, or
        // with `QuadraticElseAverage` the average.
        for i in ahead - 5..=ahead + 5 {
            let truth = on_the_rock(angle(i)).expect("on the rock");
            let off = f64::from(fitted[i]) - truth;
            if i.abs_diff(ahead) > 3 {
                assert_eq!(fitted[i].to_bits(), ranges[i].to_bits(), "beam {i}");
                let at_the_ends = fitted_else_averaged[i].to_bits();
                assert_eq!(at_the_ends, averaged[i].to_bits(), "beam {i}");
                continue;
            }
            assert_eq!(
                fitted_else_averaged[i].to_bits(),
                fitted[i].to_bits(),
                "beam {i}"
            );
            let averaged_off = f64::from(averaged[i]) - truth;
            assert!(off.abs() < 1.5e-3, "beam {i}: {off}");
            assert!(
                off.abs() * 4.0 < averaged_off,
                "beam {i}: {off} {averaged_off}"
            );
        }
    }

    #[test]
    fn the_gyro_bias_is_measured_while_standing_and_then_removed() {
        let mut m = mapping();
        let bias = 0.004;
        for k in 0..=600 {
            let t = Time::from_secs_f64(k as f64 * 0.02);
            m.on_imu(&imu(t, bias, 0.0));
            if k % 5 == 0 {
                m.on_odometry(&odom(t));
            }
        }
        assert!(!m.calibrating(Time::from_secs_f64(12.0)));
        let measured = m.gyro_bias_rad_s().expect("measured by now");
        assert!((measured - bias).abs() < 1e-9, "{measured}");
        // Standing still with the bias removed: the heading has not moved (without the
        // correction it would have turned 0.048 rad in 12 s).
        let heading = m
            .odometry_at(Time::from_secs_f64(12.0))
            .expect("odometry")
            .yaw_rad;
        assert!(heading.abs() < 1e-9, "{heading}");
    }
}
