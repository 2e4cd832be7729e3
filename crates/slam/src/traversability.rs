//! Where the rover must not drive although its 2D lidar sees nothing there: rocks lower than
//! the lidar plane but taller than the rover can climb, crater slopes and bowls. Built from
//! depth-camera points, one frame at a time, as a local elevation grid in the rover's levelled
//! frame; each cell is judged by its step (the highest point above the local floor), its
//! slope (the height change to the cells around it) and its depth below the ground the rover
//! stands on. The verdicts are fused into a [`HazardMap`] in the map frame, a log-odds grid
//! like the occupancy map, so one noisy frame does not decide a cell.
//!
//! Crater bowls seen from outside are mostly hidden behind the rim; [`shadow_gaps`] marks
//! the hidden ground as hazardous when the visible ground resumes lower beyond it (if so
//! configured, even where that is farther off than frames are judged: a large crater's far
//! wall), or when a ray over the rim returns nothing though it ran below the floor before
//! the camera's depth ran out (a far wall beyond the camera's reach).
//!
//! The approach is the elevation-mapping family's (e.g. Fankhauser et al., "Robot-Centric
//! Elevation Mapping", 2014) reduced to what a slow rover on a known floor needs.

use crate::assembly::Assembly;
use crate::occupancy::{CellState, OccupancyGrid};
use realms_core::geometry::Intrinsics;
use realms_core::{Grid, Point2, Pose2};

/// Limits and sampling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraversabilityConfig {
    /// Elevation cell edge, metres.
    pub resolution_m: f64,
    /// Cell edge the submaps' layers are drawn together at, metres (`None`: `resolution_m`).
    /// Each drawing takes every cell from the layer cell its centre falls in, and so moves
    /// an edge by up to half a cell of the layer it is drawn on; drawn straight onto the
    /// map's finer cells, a crater's edge moves less. Not the rovers' default: four times
    /// the cells cost a fifth of the fleet's SLAM speed for little (BENCHMARKS.md, "Where
    /// the crater cells near the paths are missed").
    pub assembled_resolution_m: Option<f64>,
    /// Tallest step the rover drives over, metres.
    pub max_step_m: f64,
    /// Steepest slope it drives on, radians.
    pub max_slope_rad: f64,
    /// Ground this far below the ground under the rover is a drop (a crater bowl), metres.
    pub max_drop_m: f64,
    /// Points farther than this are not judged (depth noise grows with range), metres.
    pub max_range_m: f64,
    /// A cell needs at least this many points to be judged.
    pub min_points: usize,
    /// Points up to this far may end a stretch of hidden ground in [`shadow_gaps`]: beyond a
    /// large crater the ground resumes farther off than frames are judged, metres. The
    /// stretch is still marked only within `max_range_m`. The rovers reach to their depth
    /// camera's range (6 m), which marks more of the crater cells near their paths; alone it
    /// left whole missions' maps worse, with their pose held to the wheels where the map is
    /// weak it did not (BENCHMARKS.md, "Hidden ground ended as far as the camera sees", "The
    /// 6 m hidden-ground rule over sixteen whole missions", and "The pose held to the wheels
    /// where the map is weak, as the rovers' default").
    pub gap_reach_m: f64,
    /// Hidden ground is a hazard in [`shadow_gaps`] when the ground beyond it resumes this
    /// much lower than the ground before it (the rovers take their step limit), metres.
    pub gap_drop_m: f64,
    /// The cell of the last ground seen before such a hidden stretch is a hazard too: it is
    /// the crest the ground drops away behind, and the camera, seeing only its near side,
    /// judges it safe. The truth holds a crater's whole disc out to the crest hazard. Not
    /// the rovers' default: on fixed paths it marked few more of the crater cells near them
    /// (BENCHMARKS.md, "Where the crater cells near the paths are missed").
    pub gap_marks_crest: bool,
    /// Craters inferred from the layer's crescents of hazard, their whole discs marked
    /// ([`crate::craters`]); `None` marks only what the camera judged.
    pub crater_discs: Option<crate::craters::CraterDiscs>,
    /// Patches of ground the lidar saw open and the camera never judged, walled in by
    /// hazard, marked hazard ([`crate::hollows`]); `None` leaves them unjudged.
    pub hazard_hollows: Option<crate::hollows::HazardHollows>,
}

impl Default for TraversabilityConfig {
    fn default() -> Self {
        TraversabilityConfig {
            resolution_m: 0.1,
            assembled_resolution_m: None,
            max_step_m: 0.08,
            max_slope_rad: 20f64.to_radians(),
            max_drop_m: 0.15,
            max_range_m: 4.0,
            min_points: 1,
            gap_reach_m: 4.0,
            gap_drop_m: 0.08,
            gap_marks_crest: false,
            crater_discs: None,
            hazard_hollows: None,
        }
    }
}

/// A cell's step is measured from the lowest point within this distance, metres.
const FLOOR_REACH_M: f64 = 0.25;
/// Height differences up to this are depth noise, not slope, metres.
const SLOPE_NOISE_M: f64 = 0.02;
/// The ground a hidden stretch is compared with lies this far in front of it, metres: past
/// a rock's top or a crater's rim, back to the floor they stand on.
pub const GROUND_BEFORE_GAP_M: f64 = 1.0;

#[derive(Clone, Copy, Debug, Default)]
struct Column {
    n: u32,
    sum_z: f64,
    min_z: f64,
    max_z: f64,
}

/// Whether `x.hypot(y) > range`, asking `hypot` (a call into the C library, slow) only
/// when the squared distance is within a millionth of `range` squared: farther from it, the
/// square's rounding (a few parts in 10^16) cannot change the answer.
fn beyond(x: f64, y: f64, range: f64) -> bool {
    let (d2, r2) = (x * x + y * y, range * range);
    if d2 < r2 * (1.0 - 1e-6) {
        false
    } else if d2 > r2 * (1.0 + 1e-6) {
        true
    } else {
        x.hypot(y) > range
    }
}

/// Judges the cells one depth frame sees. `points` are `[x, y, z]` in the rover's levelled
/// frame: x forward, y left, z up from the ground under the rover, gravity-aligned. Returns
/// each judged cell's centre in that frame and whether it is hazardous.
pub fn judge_frame(points: &[[f64; 3]], cfg: &TraversabilityConfig) -> Vec<(Point2, bool)> {
    let r = cfg.resolution_m;
    let half = (cfg.max_range_m / r).ceil() as i64;
    let side = (2 * half + 1) as usize;
    // The column under a point, if within the square.
    let column = |x: f64, y: f64| -> Option<(i64, i64)> {
        let (ix, iy) = ((x / r).floor() as i64 + half, (y / r).floor() as i64 + half);
        (ix >= 0 && iy >= 0 && ix < side as i64 && iy < side as i64).then_some((ix, iy))
    };
    let judged = |p: &&[f64; 3]| {
        p[0].is_finite()
            && p[1].is_finite()
            && p[2].is_finite()
            && !beyond(p[0], p[1], cfg.max_range_m)
    };
    // Each judged point's column and height, found once (a division and a rounding down
    // per axis).
    let placed: Vec<(i64, i64, f64)> = points
        .iter()
        .filter(judged)
        .filter_map(|p| column(p[0], p[1]).map(|(ix, iy)| (ix, iy, p[2])))
        .collect();
    // The box of columns any point fell in: a frame covers a wedge of the square, so columns
    // are kept for that box alone (the whole square, 6,561 columns of 32 bytes at the
    // rovers' settings, was allocated and cleared every frame).
    let mut touched = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
    for &(ix, iy, _) in &placed {
        touched = [
            touched[0].min(ix),
            touched[1].min(iy),
            touched[2].max(ix),
            touched[3].max(iy),
        ];
    }
    if touched[0] > touched[2] {
        return Vec::new();
    }
    let cols_w = (touched[2] - touched[0] + 1) as usize;
    let col_at =
        |ix: i64, iy: i64| (iy - touched[1]) as usize * cols_w + (ix - touched[0]) as usize;
    let mut cols = vec![Column::default(); cols_w * (touched[3] - touched[1] + 1) as usize];
    for &(ix, iy, z) in &placed {
        let c = &mut cols[col_at(ix, iy)];
        if c.n == 0 {
            c.min_z = z;
            c.max_z = z;
        }
        c.n += 1;
        c.sum_z += z;
        c.min_z = c.min_z.min(z);
        c.max_z = c.max_z.max(z);
    }
    // The slope is measured over two cells so depth noise matters less.
    let baseline = 2i64;
    let slope = cfg.max_slope_rad.tan();
    let reach = (FLOOR_REACH_M / r).ceil() as i64;
    // The touched box's columns with `reach` columns of padding around it, reduced to what
    // the judging reads: each judged column's lowest point and mean height. Unjudged ones
    // (and the padding) hold a lowest point of +inf and a mean of NaN, which no minimum
    // takes and no comparison passes, so the neighbour loop needs no checks.
    let (bw, bh) = (
        (touched[2] - touched[0] + 1 + 2 * reach) as usize,
        (touched[3] - touched[1] + 1 + 2 * reach) as usize,
    );
    // Column (ix, iy)'s place in the box.
    let in_box = |ix: i64, iy: i64| {
        (iy - touched[1] + reach) as usize * bw + (ix - touched[0] + reach) as usize
    };
    let mut min_z = vec![f64::INFINITY; bw * bh];
    let mut mean = vec![f64::NAN; bw * bh];
    for iy in touched[1]..=touched[3] {
        for ix in touched[0]..=touched[2] {
            let c = &cols[col_at(ix, iy)];
            // Every judged column holds a point (a mean of none is meaningless).
            if c.n > 0 && c.n as usize >= cfg.min_points {
                let k = in_box(ix, iy);
                min_z[k] = c.min_z;
                mean[k] = c.sum_z / c.n as f64;
            }
        }
    }
    // The local floor of each column (the lowest point within `reach` cells), and the lowest
    // mean height within `reach` cells: any neighbour the column is steep above is at least
    // `least_rise` below it, so a column less than that above the lowest mean is judged not
    // steep without asking each neighbour. Both by a least-value filter along the rows and
    // then down the columns (a square's least is the least of its rows' least): 4 (2 reach
    // + 1) values a column where asking each neighbour read 2 (2 reach + 1)^2.
    let reach_cells = reach as usize;
    let floors = window_min(&min_z, bw, bh, reach_cells);
    let judged_means: Vec<f64> = mean
        .iter()
        .map(|m| if m.is_nan() { f64::INFINITY } else { *m })
        .collect();
    let lowest_means = window_min(&judged_means, bw, bh, reach_cells);
    let least_rise = slope * baseline as f64 * r + SLOPE_NOISE_M;
    // Every neighbour's offset in the box and distance, cells, worked out once a frame.
    let neighbours: Vec<(isize, f64)> = (-reach..=reach)
        .flat_map(|dy| {
            (-reach..=reach).map(move |dx| {
                (
                    dy as isize * bw as isize + dx as isize,
                    ((dx * dx + dy * dy) as f64).sqrt(),
                )
            })
        })
        .collect();
    let mut out = Vec::new();
    for iy in touched[1]..=touched[3] {
        for ix in touched[0]..=touched[2] {
            let k = in_box(ix, iy);
            let here = mean[k];
            if here.is_nan() {
                continue;
            }
            let c = &cols[col_at(ix, iy)];
            // The window's lowest point includes the column's own.
            let floor = floors[k];
            // Far from the camera the points thin out to a few cells per row, so the slope
            // is taken to any judged neighbour at least two cells away. Only the upper cell
            // of a steep pair is marked: the face of a rock or a crater's wall is the hazard,
            // not the flat floor at its foot (which would otherwise grow every rock and wall
            // by a band the width of the baseline). A difference falls as what is taken away
            // grows, rounded or not, so no neighbour passes where the lowest mean does not.
            let steep = here - lowest_means[k] > least_rise
                && neighbours.iter().any(|&(offset, dist)| {
                    let j = (k as isize + offset) as usize;
                    dist >= baseline as f64 && here - mean[j] > slope * dist * r + SLOPE_NOISE_M
                });
            let step = c.max_z - floor > cfg.max_step_m;
            let drop = here < -cfg.max_drop_m;
            let centre = Point2::new(
                (ix - half) as f64 * r + r / 2.0,
                (iy - half) as f64 * r + r / 2.0,
            );
            out.push((centre, step || steep || drop));
        }
    }
    out
}

/// The least of `values` (a `width` x `height` box, row-major, no NaN) over the square of
/// `reach` cells each way round each cell at least `reach` from the box's edge (the other
/// cells, which nothing asks for, hold +inf). Each pass takes the lesser of two whole rows
/// at a time, which the compiler runs several cells to an instruction.
fn window_min(values: &[f64], width: usize, height: usize, reach: usize) -> Vec<f64> {
    let lesser = |a: f64, b: f64| if b < a { b } else { a };
    let mut out = vec![f64::INFINITY; width * height];
    if width <= 2 * reach || height <= 2 * reach {
        return out;
    }
    let inner = width - 2 * reach;
    // Along each row first: cell `reach + i` of a row takes the least of cells `i ..= i + 2
    // reach` ...
    let mut rows = vec![f64::INFINITY; width * height];
    for (src, dst) in values.chunks_exact(width).zip(rows.chunks_exact_mut(width)) {
        let dst = &mut dst[reach..reach + inner];
        dst.copy_from_slice(&src[..inner]);
        for shift in 1..=2 * reach {
            for (d, v) in dst.iter_mut().zip(&src[shift..shift + inner]) {
                *d = lesser(*d, *v);
            }
        }
    }
    // ... then down the columns, likewise.
    for y in reach..height - reach {
        let dst = &mut out[y * width..(y + 1) * width];
        dst.copy_from_slice(&rows[(y - reach) * width..(y - reach + 1) * width]);
        for above in rows[(y - reach + 1) * width..(y + reach + 1) * width].chunks_exact(width) {
            for (d, v) in dst.iter_mut().zip(above) {
                *d = lesser(*d, *v);
            }
        }
    }
    out
}

/// Negative obstacles: the ground the camera cannot see behind a crater's rim. Along each
/// image column (`columns[c]`: that column's points in the levelled frame, any order), the
/// ground points are walked outwards; where they stop and resume more than `min_gap_m`
/// farther out *and lower than the ground before the gap* (the lowest point within
/// [`GROUND_BEFORE_GAP_M`] of its near end), the ground in between dropped out of sight, and
/// every cell of the gap within `cfg.max_range_m` is judged hazardous (with the crest it
/// starts at, if `cfg.gap_marks_crest`); the gap may end at a point as far as
/// `cfg.gap_reach_m`. A rock hides the ground behind it too, but
/// there the ground resumes at the height of the ground in front of it, only lower than the
/// rock's top: that shadow is left to [`judge_frame`].
///
/// `silent[c]` (empty if unknown) holds column `c`'s rays that returned nothing, each as the
/// point where it reaches the camera's greatest depth ([`PinholeDepth::silent_end`]): the
/// ground along such a ray lies below it all the way, so its end may end a gap as a seen
/// point would, however far off, but never starts one. Beside a large crater the far wall
/// lies beyond the camera's reach, and the rays over the near rim return nothing.
pub fn shadow_gaps(
    columns: &[Vec<[f64; 3]>],
    silent: &[Vec<[f64; 3]>],
    cfg: &TraversabilityConfig,
    min_gap_m: f64,
) -> Vec<(Point2, bool)> {
    let mut out = Vec::new();
    // One buffer for every column, and an unstable sort whose ties fall in the column's
    // order (as a stable sort's would) but that needs no scratch: a frame has a hundred
    // columns, and each column allocated twice before. Each point: its distance, its place
    // in the column (the silent rays' ends after the seen points), the point, and whether it
    // was seen (not a silent ray's end).
    let mut pts: Vec<(f64, usize, [f64; 3], bool)> = Vec::new();
    let no_silent = Vec::new();
    for (c, col) in columns.iter().enumerate() {
        pts.clear();
        pts.extend(
            col.iter()
                .filter(|p| p.iter().all(|v| v.is_finite()))
                .map(|p| (p[0].hypot(p[1]), *p))
                .filter(|(d, _)| *d <= cfg.gap_reach_m.max(cfg.max_range_m))
                .map(|(d, p)| (d, p, true))
                .chain(
                    silent
                        .get(c)
                        .unwrap_or(&no_silent)
                        .iter()
                        .filter(|p| p.iter().all(|v| v.is_finite()))
                        .map(|p| (p[0].hypot(p[1]), *p, false)),
                )
                .enumerate()
                .map(|(k, (d, p, seen))| (d, k, p, seen)),
        );
        pts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        for (k, w) in pts.windows(2).enumerate() {
            let ((d0, _, near, near_seen), (d1, _, far, _)) = (w[0], w[1]);
            if !near_seen || d1 - d0 < min_gap_m || d0 >= cfg.max_range_m {
                continue;
            }
            let ground_before = pts[..=k]
                .iter()
                .rev()
                .take_while(|(d, ..)| *d >= d0 - GROUND_BEFORE_GAP_M)
                .filter(|(.., seen)| *seen)
                .fold(near[2], |low, (_, _, p, _)| low.min(p[2]));
            if far[2] > ground_before - cfg.gap_drop_m {
                continue;
            }
            if cfg.gap_marks_crest {
                out.push((Point2::new(near[0], near[1]), true));
            }
            // Cells along the hidden stretch, at the resolution of the layer.
            let steps = ((d1 - d0) / cfg.resolution_m).ceil() as usize;
            for k in 1..steps {
                let t = k as f64 / steps as f64;
                if d0 + t * (d1 - d0) > cfg.max_range_m {
                    break;
                }
                out.push((
                    Point2::new(
                        near[0] + t * (far[0] - near[0]),
                        near[1] + t * (far[1] - near[1]),
                    ),
                    true,
                ));
            }
        }
    }
    out
}

/// A pixel without a return counts as silent (nothing within the camera's greatest depth)
/// only above a return at least this much deeper than the least depth, metres. On a
/// heightfield each ray of an image column meets the ground no nearer than the ray below it,
/// so over such a return the pixel cannot have been too near; over a nearer one it may: a
/// rock's face 0.4 m off, above the floor at its foot.
const SILENT_ABOVE_DEPTH_M: f64 = 0.25;

/// A depth camera's pinhole model, as its driver's CameraInfo gives it, and the depths it
/// returns: what a pixel without a return says about the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeDepth {
    /// The pixels' rays.
    pub intrinsics: Intrinsics,
    /// Nothing nearer than this is returned (optical depth, metres) ...
    pub min_depth_m: f64,
    /// ... and nothing deeper than this.
    pub max_depth_m: f64,
}

impl PinholeDepth {
    /// A centred pinhole of `width x height` pixels and the given fields of view, degrees.
    pub fn from_fov(
        width: u32,
        height: u32,
        hfov_deg: f64,
        vfov_deg: f64,
        min_depth_m: f64,
        max_depth_m: f64,
    ) -> Self {
        PinholeDepth {
            intrinsics: Intrinsics::from_fov(width, height, hfov_deg, vfov_deg),
            min_depth_m,
            max_depth_m,
        }
    }

    /// The silent rays of an organised cloud (`width x height` optical-frame points, rows
    /// top-down, NaN where nothing returned), per column, as [`silent_end`](Self::silent_end)s:
    /// for each run of at least two pixels without a return that starts right above a return
    /// (deep enough that the run cannot be ground too near to see, see
    /// `SILENT_ABOVE_DEPTH_M`), the run's lowest ray. A lone pixel without a return is a
    /// real camera's speckle; pixels below a column's lowest return saw ground too near.
    pub fn silent_ends(
        &self,
        cloud: &[[f32; 3]],
        width: usize,
        height: usize,
    ) -> Vec<Vec<[f64; 3]>> {
        let at = |row: usize, col: usize| cloud[row * width + col];
        let seen = |row: usize, col: usize| at(row, col).iter().all(|v| v.is_finite());
        (0..width)
            .map(|col| {
                (1..height)
                    .rev()
                    .filter(|&row| {
                        seen(row, col)
                            && f64::from(at(row, col)[2]) >= self.min_depth_m + SILENT_ABOVE_DEPTH_M
                            && !seen(row - 1, col)
                            && (row < 2 || !seen(row - 2, col))
                    })
                    .map(|row| self.silent_end(col as u32, row as u32 - 1))
                    .collect()
            })
            .collect()
    }

    /// Where the ray through pixel `(u, v)`'s centre reaches the greatest depth, in the
    /// optical frame (z forward, x right, y down): a pixel without a return saw nothing
    /// nearer on that ray.
    pub fn silent_end(&self, u: u32, v: u32) -> [f64; 3] {
        self.intrinsics.ray(u, v).map(|c| c * self.max_depth_m)
    }
}

/// The fused hazard layer, in the map frame.
#[derive(Clone, Debug)]
pub struct HazardMap {
    grid: OccupancyGrid,
}

impl HazardMap {
    /// An empty layer with `resolution_m` cells.
    pub fn new(resolution_m: f64) -> Self {
        HazardMap {
            grid: OccupancyGrid::new(resolution_m),
        }
    }

    /// Fuses one frame's verdicts, judged with the rover at `pose` (map frame).
    pub fn insert(&mut self, pose: Pose2, verdicts: &[(Point2, bool)]) {
        let world: Vec<(Point2, bool)> = verdicts
            .iter()
            .map(|(p, h)| (pose.transform_point(*p), *h))
            .collect();
        self.grid.observe_cells(&world);
    }

    /// Whether the layer holds the cell at `p` hazardous (`Some(true)`), safe
    /// (`Some(false)`), or has not seen it (`None`).
    pub fn hazard_at(&self, p: Point2) -> Option<bool> {
        let (prob, _) = self.grid.probability_and_gradient(p);
        if prob > 0.6 {
            Some(true)
        } else if prob < 0.4 {
            Some(false)
        } else {
            None
        }
    }

    /// Every cell: hazardous (`Occupied`), safe (`Free`) or unseen.
    pub fn states(&self) -> Grid<CellState> {
        self.grid.states()
    }
}

/// The hazard layer kept per submap, like the occupancy map, so a loop closure that moves a
/// stretch of the map moves the craters and rocks seen from it too. Frames go into the
/// newest submap's layer in that submap's frame; layers are drawn together at their
/// submaps' current poses through an [`Assembly`], where a layer that saw a hazard
/// outvotes the layers that saw the cell safe ([`hazard_vote`](crate::assembly::hazard_vote)). Layers are kept when the mapper drops a
/// covered submap's grids: hazards are seen once, from close by, and not seen again.
#[derive(Clone, Debug)]
pub struct SubmapHazards {
    layers: Vec<Option<HazardMap>>,
    current: Option<usize>,
    /// The layers' cell edge, metres.
    resolution_m: f64,
    assembly: Assembly,
    /// Each layer's frames, kept to draw it again where the graph moves the keyframes
    /// they hang from (see [`SubmapHazards::insert_from_keyframe`]).
    kept: Vec<Vec<KeptFrame>>,
    /// The kept frames' verdicts, one after another (single precision: a micrometre at
    /// the camera's range).
    verdicts: Vec<(f32, f32, bool)>,
    /// Frames fused into each layer, kept or not: a layer is drawn again only from all
    /// of them.
    inserted: Vec<usize>,
}

/// A depth frame kept with the keyframe it hangs from, so its layer can be drawn again
/// where the pose graph moves that keyframe within its submap.
#[derive(Clone, Debug)]
struct KeptFrame {
    /// The keyframe (a node of the pose graph) newest when the frame came.
    anchor: usize,
    /// The rover at the frame, in that keyframe's frame.
    from_anchor: Pose2,
    /// Where the frame was drawn last, in its submap's frame.
    drawn_at: Pose2,
    /// Its verdicts in [`SubmapHazards::verdicts`].
    verdicts: std::ops::Range<usize>,
}

impl SubmapHazards {
    /// No layers yet, `resolution_m` cells, drawn together on cells of `assembled_m`.
    pub fn new(resolution_m: f64, assembled_m: f64) -> Self {
        SubmapHazards {
            layers: Vec::new(),
            current: None,
            resolution_m,
            assembly: Assembly::hazard_votes(assembled_m),
            kept: Vec::new(),
            verdicts: Vec::new(),
            inserted: Vec::new(),
        }
    }

    /// [`insert`](Self::insert), the frame kept with the keyframe it hangs from:
    /// `anchor` is that keyframe's node and the rover's pose in the keyframe's frame, so
    /// that [`redraw_bent`](Self::redraw_bent) can draw the layer again where the graph
    /// moves the keyframe.
    pub fn insert_from_keyframe(
        &mut self,
        submap: usize,
        rover_in_submap: Pose2,
        anchor: (usize, Pose2),
        verdicts: &[(Point2, bool)],
    ) {
        self.insert(submap, rover_in_submap, verdicts);
        if self.kept.len() <= submap {
            self.kept.resize(submap + 1, Vec::new());
        }
        let start = self.verdicts.len();
        self.verdicts.extend(
            verdicts
                .iter()
                .map(|(p, h)| (p.x_m as f32, p.y_m as f32, *h)),
        );
        self.kept[submap].push(KeptFrame {
            anchor: anchor.0,
            from_anchor: anchor.1,
            drawn_at: rover_in_submap,
            verdicts: start..self.verdicts.len(),
        });
    }

    /// Draws again, from their kept frames, the layers whose frames now lie more than
    /// `bend` from where they were drawn: each frame at its keyframe's pose in the submap
    /// now (`keyframe_in_submap(submap, node)`, `None` if the graph no longer has it),
    /// moved on as far as the rover was from the keyframe then. A submap's keyframes are
    /// drawn where tracking had them, and the graph moves them later; the lidar's submaps
    /// are drawn again from them ([`Mapper::redraw_finished_submaps`](crate::mapper::Mapper::redraw_finished_submaps)), and a hazard
    /// layer left as drawn keeps the tracking's drift within its submap. Returns how many
    /// layers were drawn again.
    pub fn redraw_bent(
        &mut self,
        keyframe_in_submap: impl Fn(usize, usize) -> Option<Pose2>,
        bend: crate::mapper::SubmapBend,
    ) -> usize {
        let mut redrawn = 0;
        for s in 0..self.kept.len() {
            let Some(Some(old)) = self.layers.get(s) else {
                continue;
            };
            if self.inserted.get(s) != Some(&self.kept[s].len()) {
                continue;
            }
            let placed: Vec<Option<Pose2>> = self.kept[s]
                .iter()
                .map(|f| keyframe_in_submap(s, f.anchor).map(|k| k * f.from_anchor))
                .collect();
            let bent = self.kept[s].iter().zip(&placed).any(|(f, p)| {
                p.is_some_and(|p| {
                    let d = p.relative_to(&f.drawn_at);
                    d.x_m.hypot(d.y_m) > bend.translation_m || d.yaw_rad.abs() > bend.rotation_rad
                })
            });
            if !bent {
                continue;
            }
            // The sum holds the layer as it was placed: take that out before it changes.
            self.assembly.remove(s, &old.grid);
            let mut layer = HazardMap::new(self.resolution_m);
            let mut frame = Vec::new();
            for (f, p) in self.kept[s].iter_mut().zip(&placed) {
                let at = p.unwrap_or(f.drawn_at);
                frame.clear();
                frame.extend(
                    self.verdicts[f.verdicts.clone()]
                        .iter()
                        .map(|(x, y, h)| (Point2::new(*x as f64, *y as f64), *h)),
                );
                layer.insert(at, &frame);
                f.drawn_at = at;
            }
            if self.current != Some(s) {
                layer.grid.cut_to_content();
            }
            self.layers[s] = Some(layer);
            redrawn += 1;
        }
        redrawn
    }

    /// Fuses one frame's verdicts into submap `submap`'s layer, judged with the rover at
    /// `rover_in_submap` (the submap's frame). Earlier layers are final from then on.
    pub fn insert(&mut self, submap: usize, rover_in_submap: Pose2, verdicts: &[(Point2, bool)]) {
        if self.layers.len() <= submap {
            self.layers.resize(submap + 1, None);
        }
        if let Some(done) = self.current.filter(|c| *c != submap)
            && let Some(Some(layer)) = self.layers.get_mut(done)
        {
            // Final from now on: only its content is kept, the same answers.
            layer.grid.cut_to_content();
        }
        let resolution = self.resolution_m;
        self.layers[submap]
            .get_or_insert_with(|| HazardMap::new(resolution))
            .insert(rover_in_submap, verdicts);
        if self.inserted.len() <= submap {
            self.inserted.resize(submap + 1, 0);
        }
        self.inserted[submap] += 1;
        self.current = Some(submap);
    }

    /// Every cell of the layers drawn at the submaps' poses (`origins[i]` for submap `i`):
    /// hazardous (`Occupied`), safe (`Free`) or unseen.
    pub fn states(&mut self, origins: &[Pose2]) -> Grid<CellState> {
        let mut current = None;
        for (i, layer) in self.layers.iter().enumerate() {
            let (Some(layer), Some(pose)) = (layer, origins.get(i)) else {
                continue;
            };
            if Some(i) == self.current {
                current = Some((&layer.grid, *pose));
            } else {
                self.assembly.place(i, &layer.grid, *pose);
            }
        }
        let active: Vec<(&OccupancyGrid, Pose2)> = current.into_iter().collect();
        self.assembly.states(&active)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beyond_answers_as_hypot_does() {
        let range = 4.0;
        let mut cases = vec![
            (0.0, 0.0),
            (4.0, 0.0),
            (0.0, -4.0),
            (1e300, 1e300),
            (1e-300, 0.0),
        ];
        // Points on and around the circle, down to the last bits of its radius.
        for k in 0..2000 {
            let a = k as f64 * 0.0137;
            for r in [
                range,
                range * (1.0 + 1e-16),
                range * (1.0 - 1e-16),
                range + 1e-12,
                3.999_999_9,
            ] {
                cases.push((r * a.cos(), r * a.sin()));
            }
        }
        for (x, y) in cases {
            assert_eq!(beyond(x, y, range), x.hypot(y) > range, "({x}, {y})");
        }
    }

    /// Points every 2 cm over `[0.5, 3.5] x [-1.5, 1.5]` of a floor given by `height`.
    fn surface(height: impl Fn(f64, f64) -> f64) -> Vec<[f64; 3]> {
        let mut pts = Vec::new();
        for i in 0..150 {
            for j in 0..150 {
                let (x, y) = (0.5 + i as f64 * 0.02, -1.5 + j as f64 * 0.02);
                pts.push([x, y, height(x, y)]);
            }
        }
        pts
    }

    fn verdict_at(v: &[(Point2, bool)], x: f64, y: f64) -> Option<bool> {
        v.iter()
            .find(|(c, _)| (c.x_m - x).abs() <= 0.05 && (c.y_m - y).abs() <= 0.05)
            .map(|(_, h)| *h)
    }

    #[test]
    fn a_hazard_seen_once_close_by_outvotes_many_distant_safe_looks() {
        let mut layers = SubmapHazards::new(0.1, 0.1);
        let rock = Point2::new(1.05, 0.05);
        // Three submaps, their origins 1 m apart along x; the first two saw the cell safe
        // over and over, the newest saw it hazardous once.
        let origins = [
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(1.0, 0.0, 0.0),
            Pose2::new(2.0, 0.0, 0.0),
        ];
        for (s, origin) in origins.iter().enumerate() {
            let local = origin.inverse().transform_point(rock);
            let looks = if s < 2 { 10 } else { 1 };
            for _ in 0..looks {
                layers.insert(s, Pose2::IDENTITY, &[(local, s == 2)]);
            }
        }
        let states = layers.states(&origins);
        assert_eq!(states.at_world(rock), Some(&CellState::Occupied));
        // Where only safe looks were taken (two: one alone is undecided), the cell is safe.
        let mut safe = SubmapHazards::new(0.1, 0.1);
        safe.insert(0, Pose2::IDENTITY, &[(rock, false)]);
        safe.insert(0, Pose2::IDENTITY, &[(rock, false)]);
        let states = safe.states(&origins[..1]);
        assert_eq!(states.at_world(rock), Some(&CellState::Free));
    }

    #[test]
    fn a_layer_is_drawn_again_where_the_graph_moves_the_keyframes_its_frames_hang_from() {
        let bend = crate::mapper::SubmapBend {
            translation_m: 0.03,
            rotation_rad: 0.01,
        };
        // A rock 0.55 m ahead of the rover, safe ground 0.25 m ahead (cell centres).
        let verdicts = [
            (Point2::new(0.55, 0.05), true),
            (Point2::new(0.25, 0.05), false),
        ];
        // Submap 0 (finished) and submap 1 (being built), each from the origin; frames
        // from keyframes 0 and 1 in the first, 2 in the second. Tracking had keyframe 1 at
        // 1 m along x; the graph moves it to (1, 0.4), a frame 0.2 m past it with it.
        let drawn = [
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(1.0, 0.0, 0.0),
            Pose2::new(0.0, 2.0, 0.0),
        ];
        let past = Pose2::new(0.2, 0.0, 0.0);
        let frames = [
            (0, 0, Pose2::IDENTITY),
            (0, 1, Pose2::IDENTITY),
            (0, 1, past),
            (1, 2, Pose2::IDENTITY),
        ];
        let mut layers = SubmapHazards::new(0.1, 0.1);
        for (submap, node, from) in frames {
            layers.insert_from_keyframe(submap, drawn[node] * from, (node, from), &verdicts);
        }
        let origins = [Pose2::IDENTITY, Pose2::IDENTITY];
        let before = layers.states(&origins);
        assert_eq!(
            layers.redraw_bent(|_, n| Some(drawn[n]), bend),
            0,
            "nothing moved"
        );
        assert_eq!(layers.states(&origins), before);
        let moved = [drawn[0], Pose2::new(1.0, 0.4, 0.0), drawn[2]];
        assert_eq!(layers.redraw_bent(|_, n| Some(moved[n]), bend), 1);
        let after = layers.states(&origins);
        // As if drawn where the graph has the keyframes from the start.
        let mut fresh = SubmapHazards::new(0.1, 0.1);
        for (submap, node, from) in frames {
            fresh.insert(submap, moved[node] * from, &verdicts);
        }
        // (Compared cell by cell: the redrawn sum's grid also spans where the layer was.)
        let fresh = fresh.states(&origins);
        for (grid, other) in [(&after, &fresh), (&fresh, &after)] {
            for (c, v) in grid.iter() {
                let p = grid.geometry().cell_center(c);
                assert_eq!(
                    other.at_world(p).unwrap_or(&CellState::Unknown),
                    v,
                    "at {p:?}"
                );
            }
        }
        for x in [1.55, 1.75] {
            assert_eq!(
                after.at_world(Point2::new(x, 0.45)),
                Some(&CellState::Occupied)
            );
            assert_ne!(
                after.at_world(Point2::new(x, 0.05)),
                Some(&CellState::Occupied)
            );
        }
        // A layer holding a frame not kept is left as drawn: it cannot be drawn whole.
        layers.insert(1, drawn[2], &verdicts);
        let moved = [drawn[0], moved[1], Pose2::new(0.5, 2.0, 0.0)];
        assert_eq!(layers.redraw_bent(|_, n| Some(moved[n]), bend), 0);
    }

    /// [`judge_frame`] by its definition, column by column from the points: each judged
    /// column's floor is its lowest point within the reach, and it is steep where some
    /// judged neighbour two or more cells off lies further below it than the slope allows.
    fn judged_by_definition(
        points: &[[f64; 3]],
        cfg: &TraversabilityConfig,
    ) -> Vec<(Point2, bool)> {
        let r = cfg.resolution_m;
        let half = (cfg.max_range_m / r).ceil() as i64;
        let side = 2 * half + 1;
        // (n, sum, min, max) per column, keyed row first as the frame is judged.
        let mut columns: std::collections::BTreeMap<(i64, i64), (usize, f64, f64, f64)> =
            Default::default();
        for p in points {
            if !p.iter().all(|v| v.is_finite()) || beyond(p[0], p[1], cfg.max_range_m) {
                continue;
            }
            let (ix, iy) = (
                (p[0] / r).floor() as i64 + half,
                (p[1] / r).floor() as i64 + half,
            );
            if ix < 0 || iy < 0 || ix >= side || iy >= side {
                continue;
            }
            let c = columns.entry((iy, ix)).or_insert((0, 0.0, p[2], p[2]));
            c.0 += 1;
            c.1 += p[2];
            c.2 = c.2.min(p[2]);
            c.3 = c.3.max(p[2]);
        }
        let judged: std::collections::BTreeMap<(i64, i64), (f64, f64, f64)> = columns
            .iter()
            .filter(|(_, c)| c.0 >= cfg.min_points)
            .map(|(k, c)| (*k, (c.1 / c.0 as f64, c.2, c.3)))
            .collect();
        let reach = (FLOOR_REACH_M / r).ceil() as i64;
        let slope = cfg.max_slope_rad.tan();
        judged
            .iter()
            .map(|(&(iy, ix), &(here, low, high))| {
                let mut floor = low;
                let mut steep = false;
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        let Some(&(mean, low, _)) = judged.get(&(iy + dy, ix + dx)) else {
                            continue;
                        };
                        floor = floor.min(low);
                        let dist = ((dx * dx + dy * dy) as f64).sqrt();
                        if dist >= 2.0 && here - mean > slope * dist * r + SLOPE_NOISE_M {
                            steep = true;
                        }
                    }
                }
                let hazard = high - floor > cfg.max_step_m || steep || here < -cfg.max_drop_m;
                let centre = Point2::new(
                    (ix - half) as f64 * r + r / 2.0,
                    (iy - half) as f64 * r + r / 2.0,
                );
                (centre, hazard)
            })
            .collect()
    }

    proptest::proptest! {
        /// The least-value filters and the early answer for columns not far enough above
        /// their lowest neighbour judge every column as asking each neighbour does: on
        /// random undulating floors with a bank of any slope, rocks, pits, noise, points
        /// out of range and points that are not numbers, judged for any step and slope.
        #[test]
        fn frames_are_judged_as_the_definition_judges_them(
            points in proptest::collection::vec((0.0f64..4.5, -4.5f64..4.5, -0.005f64..0.005), 0..1500),
            rocks in proptest::collection::vec((0.3f64..4.0, -3.0f64..3.0, 0.05f64..0.4, -0.3f64..0.3), 0..6),
            waves in (0.0f64..0.08, 0.5f64..3.0),
            bank in (0.5f64..3.5, 0.0f64..0.8, 0.0f64..std::f64::consts::TAU),
            broken in proptest::collection::vec(0usize..1500, 0..5),
            min_points in 1usize..3,
            max_step_m in 0.05f64..1.0,
            max_slope_deg in 5.0f64..40.0,
        ) {
            // Steps and slopes of every size: with the rovers' own, a rock steep enough to
            // be judged so is nearly always a step as well.
            let cfg = TraversabilityConfig {
                min_points,
                max_step_m,
                max_slope_rad: max_slope_deg.to_radians(),
                ..TraversabilityConfig::default()
            };
            let mut pts: Vec<[f64; 3]> = points
                .iter()
                .map(|&(x, y, noise)| {
                    // A bank rising from a line at `bank.0` m, across the heading `bank.2`.
                    let across = x * bank.2.cos() + y * bank.2.sin() - bank.0;
                    let mut z = waves.0 * (x * waves.1).sin() + noise + bank.1 * across.max(0.0);
                    for &(rx, ry, radius, height) in &rocks {
                        if (x - rx).hypot(y - ry) < radius {
                            z += height;
                        }
                    }
                    [x, y, z]
                })
                .collect();
            for &i in &broken {
                if let Some(p) = pts.get_mut(i) {
                    p[i % 3] = if i % 2 == 0 { f64::NAN } else { f64::INFINITY };
                }
            }
            proptest::prop_assert_eq!(judge_frame(&pts, &cfg), judged_by_definition(&pts, &cfg));
        }
    }

    #[test]
    fn a_flat_gently_undulating_floor_is_safe_everywhere() {
        let floor = |x: f64, y: f64| 0.05 * (x * std::f64::consts::TAU / 6.0).sin() + 0.01 * y;
        let v = judge_frame(&surface(floor), &TraversabilityConfig::default());
        assert!(v.len() > 500, "{} cells judged", v.len());
        assert!(v.iter().all(|(_, h)| !h), "a hazard on a flat floor");
    }

    #[test]
    fn a_low_rock_a_steep_bank_and_a_bowl_are_hazards_and_their_surroundings_are_not() {
        let cfg = TraversabilityConfig::default();
        // A 12 cm rock (under the 30 cm lidar plane, over the 8 cm step limit) at (1.5, 0.8).
        let rock = |x: f64, y: f64| {
            if (x - 1.5).hypot(y - 0.8) < 0.15 {
                0.12
            } else {
                0.0
            }
        };
        let v = judge_frame(&surface(rock), &cfg);
        assert_eq!(verdict_at(&v, 1.55, 0.85), Some(true));
        assert_eq!(verdict_at(&v, 1.55, -0.75), Some(false));
        // A 35 degree bank rising from x = 2.5.
        let bank = |x: f64, _y: f64| if x > 2.5 { (x - 2.5) * 0.7 } else { 0.0 };
        let v = judge_frame(&surface(bank), &cfg);
        assert_eq!(verdict_at(&v, 2.95, 0.05), Some(true));
        assert_eq!(verdict_at(&v, 1.05, 0.05), Some(false));
        // A bowl 30 cm deep with gentle walls beyond x = 2.8: too deep to enter.
        let bowl = |x: f64, _y: f64| {
            if x > 2.8 {
                -0.3
            } else if x > 2.0 {
                -(x - 2.0) * 0.3
            } else {
                0.0
            }
        };
        let v = judge_frame(&surface(bowl), &cfg);
        assert_eq!(verdict_at(&v, 3.25, 0.05), Some(true));
        assert_eq!(verdict_at(&v, 1.05, 0.05), Some(false));
    }

    /// One image column's points along x: floor every 8 cm from 0.5 m to 2.0 m, nothing
    /// until `far_from_m`, then four points 10 cm apart at height `far_z_m`.
    fn floor_then_ground_beyond(far_from_m: f64, far_z_m: f64) -> Vec<[f64; 3]> {
        let mut col: Vec<[f64; 3]> = (0..20).map(|k| [0.5 + k as f64 * 0.08, 0.0, 0.0]).collect();
        col.extend((0..4).map(|k| [far_from_m + k as f64 * 0.1, 0.0, far_z_m]));
        col
    }

    #[test]
    fn ground_hidden_behind_a_rim_and_resuming_lower_is_a_hazard_but_a_rock_shadow_is_not() {
        let cfg = TraversabilityConfig::default();
        // One column: floor to 2.0 m, nothing seen until 3.6 m, then ground 12 cm lower.
        let mut col = floor_then_ground_beyond(3.6, -0.12);
        let v = shadow_gaps(&[col.clone()], &[], &cfg, 0.5);
        assert!(
            v.iter().any(|(p, h)| *h && (p.x_m - 3.0).abs() < 0.1),
            "{v:?}"
        );
        assert!(v.iter().all(|(p, _)| p.x_m > 2.0 && p.x_m < 3.6));
        // The same gap with the far ground at the same height (sparse points): nothing.
        for p in col.iter_mut().skip(20) {
            p[2] = 0.0;
        }
        assert!(shadow_gaps(&[col.clone()], &[], &cfg, 0.5).is_empty());
        // A rock 15 cm tall ends the near stretch: its top is higher than the ground that
        // resumes beyond its shadow, but that ground is the floor in front of it.
        col.extend((0..3).map(|k| [2.0 + k as f64 * 0.08, 0.0, 0.15]));
        assert!(shadow_gaps(&[col.clone()], &[], &cfg, 0.5).is_empty());
        // Behind a raised rim the ground resumes lower than the floor: a hazard again.
        for p in col.iter_mut().skip(20).take(4) {
            p[2] = -0.12;
        }
        assert!(shadow_gaps(&[col], &[], &cfg, 0.5).iter().any(|(_, h)| *h));
    }

    #[test]
    fn the_crest_a_hidden_stretch_drops_behind_is_marked_only_if_asked() {
        // Floor to 2.0 m (its last point at 2.02 m), hidden ground, then ground 12 cm lower.
        let col = floor_then_ground_beyond(3.6, -0.12);
        let crest = |cfg: &TraversabilityConfig| {
            shadow_gaps(std::slice::from_ref(&col), &[], cfg, 0.5)
                .iter()
                .any(|(p, h)| *h && (p.x_m - 2.02).abs() < 1e-9)
        };
        let cfg = TraversabilityConfig::default();
        assert!(!crest(&cfg));
        assert!(crest(&TraversabilityConfig {
            gap_marks_crest: true,
            ..cfg
        }));
        // Ground that resumes as high as before the hidden stretch (a rock's shadow) starts
        // no hazard, and so marks no crest.
        let mut flat = col.clone();
        for p in flat.iter_mut().skip(20) {
            p[2] = 0.0;
        }
        let marking = TraversabilityConfig {
            gap_marks_crest: true,
            ..cfg
        };
        assert!(shadow_gaps(&[flat], &[], &marking, 0.5).is_empty());
    }

    #[test]
    fn ground_hidden_up_to_a_far_wall_beyond_the_judged_range_is_marked_within_it() {
        let cfg = TraversabilityConfig {
            gap_reach_m: 6.0,
            ..TraversabilityConfig::default()
        };
        // Floor to 2.0 m, then a large crater's bowl hidden until its far wall at 5.2 m,
        // seen 0.3 m below the floor: past the 4 m frames are judged to.
        let col = floor_then_ground_beyond(5.2, -0.3);
        let v = shadow_gaps(std::slice::from_ref(&col), &[], &cfg, 0.5);
        assert!(
            v.iter().any(|(p, h)| *h && (p.x_m - 3.9).abs() < 0.1),
            "{v:?}"
        );
        assert!(
            v.iter()
                .all(|(p, _)| p.x_m > 2.0 && p.x_m <= cfg.max_range_m)
        );
        // A gap may end only where frames are judged: the far wall ends none.
        let near_only = TraversabilityConfig {
            gap_reach_m: cfg.max_range_m,
            ..cfg
        };
        assert!(shadow_gaps(&[col], &[], &near_only, 0.5).is_empty());
    }

    #[test]
    fn a_silent_run_is_read_from_its_lowest_ray_above_a_return_deep_enough() {
        // 2 columns x 9 rows, 90 x 90 degrees, depths 0.4-6 m.
        let camera = PinholeDepth::from_fov(2, 9, 90.0, 90.0, 0.4, 6.0);
        let (silent, deep, near) = ([f32::NAN; 3], [0.0, 0.5, 2.0], [0.0, 0.5, 0.5]);
        // Column 0, rows top-down: two silent pixels above a deep return; a lone silent
        // pixel between returns; a silent pair above a return too near to rule out a face
        // nearer than the least depth; two silent pixels below the lowest return.
        let col0 = [
            silent, silent, deep, silent, deep, silent, silent, near, silent,
        ];
        // Column 1: every pixel returned.
        let cloud: Vec<[f32; 3]> = col0.iter().flat_map(|p| [*p, deep]).collect();
        let ends = camera.silent_ends(&cloud, 2, 9);
        assert_eq!(ends.len(), 2);
        assert_eq!(ends[0], vec![camera.silent_end(0, 1)]);
        assert!(ends[1].is_empty());
        // The end lies on the pixel's ray at the greatest depth: row 1 of 9 looks up by
        // atan(3 / 4.5) through a 90-degree field, column 0 of 2 left by atan(0.5).
        let [x, y, z] = ends[0][0];
        assert!((z - 6.0).abs() < 1e-12);
        assert!((y / z + 3.0 / 4.5).abs() < 1e-12 && (x / z + 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_silent_ray_ends_hidden_ground_when_it_runs_below_the_floor_but_never_starts_one() {
        let cfg = TraversabilityConfig {
            gap_reach_m: 6.0,
            ..TraversabilityConfig::default()
        };
        // Floor every 8 cm to 2.0 m, and nothing seen beyond: the far wall lies past the
        // camera's reach.
        let col: Vec<[f64; 3]> = (0..20).map(|k| [0.5 + k as f64 * 0.08, 0.0, 0.0]).collect();
        assert!(shadow_gaps(std::slice::from_ref(&col), &[], &cfg, 0.5).is_empty());
        // The ray over the rim ran on to 7.5 m (past the reach of seen points) and 0.2 m
        // below the floor without meeting the ground: the hidden stretch is a drop, marked
        // to the judged range.
        let low = vec![vec![[7.5, 0.0, -0.2]]];
        let v = shadow_gaps(std::slice::from_ref(&col), &low, &cfg, 0.5);
        assert!(
            v.iter().any(|(p, h)| *h && (p.x_m - 2.5).abs() < 0.1),
            "{v:?}"
        );
        assert!(
            v.iter()
                .all(|(p, h)| *h && p.x_m > 1.9 && p.x_m <= cfg.max_range_m)
        );
        // A ray that ends 5 cm below the floor says only that the ground beyond is not
        // much lower: a dip the rover drives through.
        assert!(
            shadow_gaps(
                std::slice::from_ref(&col),
                &[vec![[6.0, 0.0, -0.05]]],
                &cfg,
                0.5
            )
            .is_empty()
        );
        // A silent ray's end is not ground: it is not the ground before a gap (at 1 m below
        // the floor, it would have hidden the drop to the ground seen at 3.0 m), and it
        // starts none (here one ending 0.7 m lower, 1 m farther).
        let mut far = col.clone();
        far.push([3.0, 0.0, -0.5]);
        let silent_first = vec![vec![[1.9, 0.0, -1.0]]];
        let v = shadow_gaps(std::slice::from_ref(&far), &silent_first, &cfg, 0.5);
        assert!(
            v.iter().any(|(p, h)| *h && (p.x_m - 2.5).abs() < 0.1),
            "{v:?}"
        );
        let ahead = vec![vec![[2.0, 0.0, 0.5]]];
        let floor_beyond = vec![[3.0, 0.0, -0.2]];
        assert!(shadow_gaps(&[floor_beyond], &ahead, &cfg, 0.5).is_empty());
    }

    #[test]
    fn the_layer_fuses_frames_in_the_map_frame() {
        let mut layer = HazardMap::new(0.1);
        let pose = Pose2::new(10.0, 5.0, std::f64::consts::FRAC_PI_2);
        // The rover faces +y in the map: a verdict 1 m ahead lands at (10, 6).
        for _ in 0..3 {
            layer.insert(
                pose,
                &[
                    (Point2::new(1.05, 0.05), true),
                    (Point2::new(2.05, 0.05), false),
                ],
            );
        }
        assert_eq!(layer.hazard_at(Point2::new(9.95, 6.05)), Some(true));
        assert_eq!(layer.hazard_at(Point2::new(9.95, 7.05)), Some(false));
        assert_eq!(layer.hazard_at(Point2::new(0.0, 0.0)), None);
    }
}
