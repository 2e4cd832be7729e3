//! Everything the estimator reads from one map, computed once per map (a lander merging N
//! maps prepares each once for all its pairs): the coarse search level with its branch and
//! bound pyramid, the finer refinement level with its distance field, structure and known
//! points, and the line-direction histogram.

use crate::level::{Class, Despeckled, Level, Surface};
use crate::map::Map;
use crate::rotation::Directions;
use crate::search::Fields;
use realms_core::{Point2, Pose2};

/// Settings of the estimator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Cell of the global search, metres (coarse: the search is over every pose).
    pub search_cell_m: f64,
    /// Cell of refinement and verification, metres.
    pub refine_cell_m: f64,
    /// Search score of a structure point on the other map's free space (a hit scores 2).
    pub free_penalty: i8,
    /// Levels of block maxima for branch and bound (blocks up to `2^depth` cells).
    pub pyramid_depth: usize,
    /// At most this many structure points of the moving map enter the global search.
    pub max_search_points: usize,
    /// At most this many structure points per map enter verification.
    pub max_refine_points: usize,
    /// At most this many surface points per map enter refinement on the fine level.
    pub max_local_points: usize,
    /// Hypotheses scoring below this share of the best in the global search are dropped.
    pub min_share_of_best: f64,
    /// Branch and bound expands at most this many nodes per heading group, then keeps the
    /// hypotheses it has (best first, so the best ones come out first): a safety net for
    /// time. (Capping it at 8000 halves the time on Willow Garage but loses a third of its
    /// merges at 10 % overlap, so the default is far above what any map needed.)
    pub max_search_nodes: usize,
    /// Distinct hypotheses taken from the global search per heading group, screened on
    /// the coarse level.
    pub hypotheses: usize,
    /// The best screened hypotheses refined and verified on the fine level.
    pub refined_hypotheses: usize,
    /// Heading step of the global search, radians.
    pub yaw_step_rad: f64,
    /// Heading peaks taken from the direction histograms (each also turned by 180 degrees).
    pub direction_peaks: usize,
    /// Peaks of other lobes of the direction correlation (at least `lobe_separation_deg`
    /// from every other peak) searched as well.
    pub direction_lobes: usize,
    /// See `direction_lobes`, degrees.
    pub lobe_separation_deg: usize,
    /// Half-width of the heading search around each direction peak, radians.
    pub peak_halfwidth_rad: f64,
    /// Below this peak-to-mean ratio the direction histograms say nothing and every heading
    /// is searched.
    pub min_direction_ratio: f64,
    /// Poses whose moving-map centres lie closer than this (and headings closer than
    /// `distinct_rad`) are one hypothesis, metres.
    pub distinct_m: f64,
    /// See `distinct_m`, radians.
    pub distinct_rad: f64,
    /// Verification: how many conflicts one agreement is worth (score = agree - w * conflict).
    pub conflict_weight: f64,
    /// Refuse below this share of agreeing structure among agreeing and conflicting.
    pub min_agreement: f64,
    /// Refuse with fewer agreeing structure cells than this (per map, summed both ways).
    pub min_agree_cells: usize,
    /// Refuse below this verified score (agreeing less `conflict_weight` times conflicting):
    /// a few dozen cells of a wall and a corner, with some of them on open ground, are
    /// too little to merge on (Willow Garage at 5 % overlap: a pose 1.2 m off scored 169).
    pub min_score: f64,
    /// Refuse when at least this many landmark points (rocks, craters, furniture:
    /// [`crate::level::Level::landmark`]) land on the other map's open ground...
    pub min_landmark_conflicts: usize,
    /// ... and they are more than this share of the landmark points that agree. Walls
    /// agree with walls at a quarter turn in a rectangular arena; a rock on open ground
    /// does not happen at the true pose, whatever the walls say.
    pub max_landmark_conflict_share: f64,
    /// Refuse when the runner-up's verified score reaches this share of the winner's.
    pub max_runner_up_ratio: f64,
    /// Refuse when moving the pose this far (or turning it as much) keeps too much of its
    /// score, metres.
    pub sharpness_shift_m: f64,
    /// The sharpness check turns the pose at least this far, radians. Across a long, thin
    /// overlap (a band across the hall) 0.3 m at its edge is a fraction of a degree, and
    /// walls at the band's ends that slide along themselves keep most of the score at such
    /// a turn even where the rocks in the band pin the pose. In `realms bench merge` on lunar
    /// maps (seeds 1-5, 10 and 20 % overlap) every pose a turn of 0.3 m at the edge refused
    /// and 3 degrees did not was within 0.1 m and 0.8 degrees of the truth.
    pub sharpness_min_turn_rad: f64,
    /// Refuse below this sharpness ([`crate::verify::sharpness`]).
    pub min_sharpness: f64,
    /// With no prior, at most this many poses the landmarks vote for
    /// ([`crate::constellation`]) are refined and verified beside the search's; 0: none.
    pub landmark_hypotheses: usize,
    /// Walls at least this long count in [`crate::lines`], metres.
    pub wall_min_length_m: f64,
    /// A long wall of each map lying parallel within this much at the pose pins its
    /// heading: the sharpness check then leaves the turns out ([`crate::lines`]), radians.
    /// 0 turns the rule off.
    pub wall_pin_rad: f64,
    /// The precision check: a fit on the surfaces at the maps' own resolution
    /// ([`crate::fine::nearby`]), restarted around the best, that settles apart from it and
    /// fits about as closely refuses the merge as imprecise; one that fits clearly more
    /// closely takes the best's place (a few times, and only near the verified best; see
    /// [`Params::fine_reach_m`] and `FINE_MAX_HOPS` in [`crate::estimate`](mod@crate::estimate)).
    pub precision: crate::fine::RivalRule,
    /// Whether the precision check runs at all (the sub-cell fit of the verified best
    /// does either way).
    pub check_precision: bool,
    /// How far (metres, at the overlap's centre) the fit on the surfaces may move the
    /// verified best, and a restart that fits clearly more closely replace it (twice as far
    /// where it fits much more closely). At 0.3 m a pose that hopped from 0.54 to 0.21 m off
    /// was merged wrong (`realms bench merge --seed 4`, lunar sparse, 10 %, pair 17); at
    /// 0.15 m the lunar pairs of seeds 1-8 at 10 and 20 % (800) make 487 right merges and
    /// no wrong one, against 497 and that one.
    pub fine_reach_m: f64,
    /// Refuse below this overlap of known cells, square metres.
    pub min_overlap_m2: f64,
    /// Refuse below this confidence.
    pub min_confidence: f64,
    /// Refuse when less than this share of the agreeing structure lies off the two walls
    /// that carry most of it ([`crate::verify::off_two_walls`]): a corner alone fits every
    /// corner of a rectangular arena. Not applied with a prior (known-start mode). In
    /// `realms bench merge` (seeds 1 and 2, 1040 pairs) the quarter-turn wrong merges had
    /// 0.00-0.05 and the true merges 0.09 and more.
    pub min_off_two_walls: f64,
    /// Make pockets of a few free cells walled in all round by structure unknown
    /// ([`crate::level::Despeckled::cleaned`]): missed returns inside a rock or the lander.
    /// Off for the rovers' maps, which have no such holes (their lidars see rocks from
    /// outside) but whose hazard rings enclose ground the camera judged free: there it
    /// moved one pair of seed 3's maps 0.34 m off the shared frame, and the lander's merged
    /// map of that mission from 94.8 % to 85.4 % right (BENCHMARKS.md, forty-first session).
    pub unknown_free_pockets: bool,
    /// Refuse when a clearly different pose is as consistent (agreement at least
    /// `min_agreement`) and explains at least this share of the best one's agreeing
    /// structure.
    pub rival_share: f64,
    /// A rival must also agree at least as well as the best less this (share of agreeing
    /// structure among agreeing and conflicting). At 0.03 a quarter-turn with ten times the
    /// true pose's conflicts (96.8 % against 99.2 %) still counted as a rival.
    pub rival_agreement_slack: f64,
    /// A rival must also bring at least this share of the landmark points (rocks, rims) the
    /// best pose brings into agreement. Walls and corners line up at many poses; a pose
    /// that lines them up while leaving most of the best's rocks apart is not as likely,
    /// however much wall it overlaps.
    pub rival_landmark_share: f64,
    /// A clearly different pose is no alternative to the best when at least this share of
    /// what agrees at it also agrees at the best ...
    pub subset_share: f64,
    /// ... landing within this distance of where the best puts it, metres
    /// ([`crate::verify::shared_agreement`]).
    pub subset_tolerance_m: f64,
    /// A clearly different pose is no alternative either when it keeps the best's landmark
    /// pairs (as above, landmark points only) and overlaps less than this share of the
    /// best's overlap, explaining less. In `realms bench merge` (lunar, seeds 1-8, 10 and
    /// 20 %) that merged 9 more pairs, all right; at 1.0, on seeds 1-5, one wrong merge came
    /// in.
    pub rival_overlap_share: f64,
    /// Nor is a pose that, both aligned on the maps' own surfaces ([`crate::fine`]), fits
    /// worse than the best by at least this many standard errors
    /// ([`crate::fine::Comparison::z`]); the same test lets a runner-up that scores
    /// [`Params::max_runner_up_ratio`] of the best pass. On 10 cm cells a band swung a
    /// degree or two about its landmarks keeps their agreement; on 5 cm surfaces it does
    /// not. In `realms bench merge` (lunar, seeds 1-8, 10 and 20 %) that merged 14 more
    /// pairs of 800, none wrong.
    pub rival_worse_z: f64,
    /// A fixed map larger than this (metres, its larger side) is searched globally on a
    /// level twice as coarse, with heading steps twice as large: the search's cost grows
    /// with the area of translations, and refinement recovers the precision.
    pub large_map_m: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            search_cell_m: 0.2,
            refine_cell_m: 0.1,
            free_penalty: 10,
            pyramid_depth: 6,
            max_search_points: 600,
            max_refine_points: 4000,
            max_local_points: 1500,
            min_share_of_best: 0.5,
            max_search_nodes: 2_000_000,
            hypotheses: 5,
            refined_hypotheses: 8,
            yaw_step_rad: 0.5f64.to_radians(),
            direction_peaks: 3,
            direction_lobes: 1,
            lobe_separation_deg: 20,
            peak_halfwidth_rad: 3.0f64.to_radians(),
            min_direction_ratio: 1.5,
            distinct_m: 1.0,
            distinct_rad: 3.0f64.to_radians(),
            conflict_weight: 10.0,
            min_agreement: 0.95,
            min_agree_cells: 60,
            min_score: 200.0,
            min_landmark_conflicts: 5,
            max_landmark_conflict_share: 0.125,
            max_runner_up_ratio: 0.7,
            min_overlap_m2: 8.0,
            precision: crate::fine::RivalRule {
                apart_m: 0.1,
                apart_rad: 0.5f64.to_radians(),
                max_z: 1.0,
                better_z: -2.0,
            },
            check_precision: true,
            fine_reach_m: 0.15,
            sharpness_shift_m: 0.3,
            sharpness_min_turn_rad: 3f64.to_radians(),
            min_sharpness: 0.25,
            landmark_hypotheses: 4,
            wall_min_length_m: 6.0,
            wall_pin_rad: 1.5f64.to_radians(),
            min_confidence: 0.3,
            min_off_two_walls: 0.07,
            unknown_free_pockets: true,
            rival_share: 0.2,
            rival_agreement_slack: 0.02,
            rival_landmark_share: 0.5,
            subset_share: 0.9,
            subset_tolerance_m: 0.5,
            rival_overlap_share: 0.6,
            rival_worse_z: 3.0,
            large_map_m: 30.0,
        }
    }
}

impl Params {
    /// The settings for maps that different rovers built, each with its own SLAM drift:
    /// they disagree by a few decimetres here and there (a wall drawn 0.2 m off, a rock's
    /// hazard ring wider in one map), so the merge can be no more precise than that, and
    /// the fit on the surfaces may move the verified best 0.3 m. The precision check is
    /// off: it compares poses point by point with each point's cost capped at a cell, and
    /// on maps this far apart most points are capped at both poses, so fits a few
    /// decimetres apart look alike. On the rovers' maps of six default missions it refused
    /// 22 right merges of 156 pairs and stopped no wrong one (BENCHMARKS.md, "The rovers'
    /// own maps"); the sharpness check on 10 cm cells still refuses a pose the maps leave
    /// free to slide.
    pub fn for_rover_maps() -> Params {
        Params {
            check_precision: false,
            fine_reach_m: 0.3,
            unknown_free_pockets: false,
            ..Params::default()
        }
    }
}

/// Pyramid depth of the search level on large maps (blocks of 8 cells; see
/// `Prepared::search_depth`).
const WINDOW_PYRAMID_DEPTH: usize = 3;

/// One map, ready for matching.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// The search level.
    pub search: Level,
    /// Its branch and bound fields, built the first time the map is the fixed one.
    fields: std::cell::OnceCell<Fields>,
    /// A level twice as coarse, for the global search of large maps.
    pub global: Level,
    /// Its surface points.
    pub global_points: Vec<Surface>,
    /// Its branch and bound fields (built on first use).
    global_fields: std::cell::OnceCell<Fields>,
    /// The larger side of the map, metres.
    pub extent_m: f64,
    /// Whether the map, as the fixed one, is searched globally on [`Prepared::global`]
    /// rather than on the search level: larger than [`Params::large_map_m`].
    pub searched_coarse: bool,
    /// Fields of the search level without the pyramid, for refinement.
    flat_fields: std::cell::OnceCell<Fields>,
    /// Fields of the refinement level (no pyramid), for refinement.
    local_fields: std::cell::OnceCell<Fields>,
    /// Surface points for refinement on the fine level.
    pub local_points: Vec<Surface>,
    free_penalty: i8,
    pyramid_depth: usize,
    /// Pyramid depth of the search level's fields: the full depth where the global search
    /// runs on that level; on large maps, whose global search runs on the coarser level, it
    /// only serves searches in small windows (a rescan, a known start), and a shallower
    /// pyramid, half as costly to build, prunes those as well.
    search_depth: usize,
    /// Surface points for the global search.
    pub search_points: Vec<Surface>,
    /// The refinement level.
    pub refine: Level,
    /// Surface points for verification.
    pub refine_points: Vec<Surface>,
    /// The surfaces at the map's own resolution (no finer than half the refinement
    /// level's cell), for the last, sub-cell alignment ([`crate::fine`]).
    pub fine: crate::fine::Surfaces,
    /// Known cells of the search level, grid-local metres (for the overlap area).
    pub known_points: Vec<Point2>,
    /// Line directions of the structure.
    pub directions: Directions,
    /// The long straight walls of the refinement level, longest first.
    pub walls: Vec<crate::lines::Wall>,
    /// The landmarks of the refinement level ([`crate::constellation`]).
    pub landmarks: Vec<crate::constellation::Landmark>,
    /// Centre of the known cells, grid-local metres.
    pub centroid: Point2,
    /// Pose of the grid-local frame in the map frame.
    pub frame_from_grid: Pose2,
    /// Area each of `known_points` stands for, square metres (they are thinned evenly).
    pub known_area_per_point_m2: f64,
}

impl Prepared {
    /// The coarse global level's fields (built on first use).
    pub fn global_fields(&self) -> &Fields {
        self.global_fields
            .get_or_init(|| Fields::new(&self.global, self.free_penalty, self.pyramid_depth))
    }

    /// The search level's fields without the pyramid (built on first use).
    pub fn flat_fields(&self) -> &Fields {
        // The full search fields' first level is the same field: no need to build it twice.
        if let Some(fields) = self.fields.get() {
            return fields;
        }
        self.flat_fields
            .get_or_init(|| Fields::new(&self.search, self.free_penalty, 0))
    }

    /// The refinement level's fields (built on first use).
    pub fn local_fields(&self) -> &Fields {
        self.local_fields
            .get_or_init(|| Fields::new(&self.refine, self.free_penalty, 0))
    }

    /// The search fields (built on first use: only the fixed map of a pair needs them).
    pub fn fields(&self) -> &Fields {
        self.fields
            .get_or_init(|| Fields::new(&self.search, self.free_penalty, self.search_depth))
    }

    /// Prepares `map` with `params`.
    pub fn new(map: &Map, params: &Params) -> Prepared {
        let extent_m = map.geometry().width_m().max(map.geometry().height_m());
        let searched_coarse = extent_m > params.large_map_m;
        let despeckled = Despeckled::cleaned(map, params.unknown_free_pockets);
        let search = Level::build_from(&despeckled, params.search_cell_m);
        let global = Level::build_from(&despeckled, 2.0 * params.search_cell_m);
        let refine = Level::build_from(&despeckled, params.refine_cell_m);
        let fine = crate::fine::Surfaces::of(&crate::level::Outline::of(
            &despeckled,
            map.geometry().resolution_m.max(params.refine_cell_m / 2.0),
        ));
        let refine_points = refine.surfaces(params.max_refine_points);
        let step = refine_points
            .len()
            .div_ceil(params.max_local_points.max(1))
            .max(1);
        let local_points = refine_points.iter().step_by(step).copied().collect();
        let known_points = search.known_points(20_000);
        let known = search
            .class
            .iter()
            .filter(|c| **c != Class::Unknown)
            .count();
        let known_area_per_point_m2 = if known_points.is_empty() {
            0.0
        } else {
            known as f64 * search.cell_m * search.cell_m / known_points.len() as f64
        };
        Prepared {
            search_points: search.surfaces(params.max_search_points),
            global_points: global.surfaces(params.max_search_points),
            global,
            global_fields: std::cell::OnceCell::new(),
            extent_m,
            searched_coarse,
            known_points,
            known_area_per_point_m2,
            refine_points,
            fine,
            directions: Directions::of(&refine),
            walls: crate::lines::long_walls(&refine, params.wall_min_length_m),
            landmarks: crate::constellation::landmarks(&refine),
            centroid: map.known_centroid_in_grid(),
            frame_from_grid: map.frame_from_grid(),
            fields: std::cell::OnceCell::new(),
            local_fields: std::cell::OnceCell::new(),
            flat_fields: std::cell::OnceCell::new(),
            local_points,
            free_penalty: params.free_penalty,
            pyramid_depth: params.pyramid_depth,
            search_depth: if searched_coarse {
                params.pyramid_depth.min(WINDOW_PYRAMID_DEPTH)
            } else {
                params.pyramid_depth
            },
            search,
            refine,
        }
    }
}
