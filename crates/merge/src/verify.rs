//! Local refinement and verification of one hypothesis on the finer level.
//!
//! Refinement climbs the search's direction-aware score made symmetric (each map's surface
//! points on the other's fields), first on the coarse level, then on the fine one, with
//! halving steps down to a quarter of a fine cell, and finishes on distances to surfaces.
//!
//! Verification counts, both ways, structure cells that land on structure facing the same
//! way (agree), that land on the other map's free space far from any structure (conflict),
//! and the overlap of known cells. A true alignment agrees almost everywhere the maps
//! overlap; a wrong one that lays walls over walls must also put the rest of its structure
//! on the other map's free space. Two more checks judge how well the pose is pinned down:
//! [`sharpness`] (does the score fall when the pose moves?) here, and
//! [`crate::fine::nearby`] (is there a second optimum close by that lays the surfaces on each
//! other as closely?).

use crate::level::{Class, Level, SHAPE_WEIGHT, Surface, floor_i64};
use crate::prepare::{Params, Prepared};
use crate::search::{Fields, bins_face_alike, direction_bin, field_code};
use realms_core::{Point2, Pose2};

/// Agreeing: the other map has structure within this many fine cells.
const AGREE_CELLS: f32 = 1.5;
/// Conflicting: free there, and no structure within this many fine cells.
const CONFLICT_CELLS: f32 = 2.5;

/// What verification found for one pose.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Evidence {
    /// Structure cells (both maps) landing on the other's structure facing the same way,
    /// weighted by [`Surface::weight`].
    pub agree: usize,
    /// Structure cells (both maps) landing on the other's free space, far from structure,
    /// weighted alike.
    pub conflict: usize,
    /// Overlap of the known areas, square metres.
    pub overlap_m2: f64,
    /// Centre of the overlap, in the second map's grid-local metres.
    pub overlap_centre: Point2,
    /// Root mean square distance of the overlap from its centre, metres.
    pub overlap_radius_m: f64,
    /// The ends of the overlap's long axis (its centre plus and minus the half-length of a
    /// uniform strip with the same spread along that axis), in the second map's grid-local
    /// metres.
    pub overlap_ends: [Point2; 2],
    /// `agree - conflict_weight * conflict`.
    pub score: f64,
    /// Shape points (corners, rocks, rims; not straight walls) that agree, counted once
    /// each, both maps.
    pub shape_agree: usize,
    /// Shape points that conflict, counted alike.
    pub shape_conflict: usize,
    /// Points on landmarks ([`crate::level::Level::landmark`]) that agree, counted once
    /// each, both maps.
    pub landmark_agree: usize,
    /// Points on landmarks that conflict, counted alike.
    pub landmark_conflict: usize,
}

impl Evidence {
    /// Share of agreeing structure among agreeing and conflicting (0 with neither).
    pub fn agreement(&self) -> f64 {
        let n = self.agree + self.conflict;
        if n == 0 {
            0.0
        } else {
            self.agree as f64 / n as f64
        }
    }
}

/// A pose with its sine and cosine worked out once, for transforming many points.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rigid {
    x_m: f64,
    y_m: f64,
    sin: f64,
    cos: f64,
}

impl Rigid {
    pub(crate) fn new(p: &Pose2) -> Rigid {
        let (sin, cos) = p.yaw_rad.sin_cos();
        Rigid {
            x_m: p.x_m,
            y_m: p.y_m,
            sin,
            cos,
        }
    }

    #[inline]
    pub(crate) fn apply(&self, p: Point2) -> Point2 {
        Point2::new(
            self.x_m + self.cos * p.x_m - self.sin * p.y_m,
            self.y_m + self.sin * p.x_m + self.cos * p.y_m,
        )
    }

    /// A direction turned by the pose's rotation alone.
    #[inline]
    pub(crate) fn turn(&self, v: [f64; 2]) -> [f64; 2] {
        [
            self.cos * v[0] - self.sin * v[1],
            self.sin * v[0] + self.cos * v[1],
        ]
    }
}

/// The search score of `points` carried by `target_from_source` onto `fields`.
fn field_score(
    fields: &Fields,
    cell_m: f64,
    points: &[Surface],
    target_from_source: &Pose2,
) -> i64 {
    let t = Rigid::new(target_from_source);
    points
        .iter()
        .map(|s| {
            let q = t.apply(s.p);
            let k = field_code(
                direction_bin(s.normal_rad + target_from_source.yaw_rad),
                s.hazard,
            );
            let v = fields
                .pyramid(k)
                .value(floor_i64(q.x_m / cell_m), floor_i64(q.y_m / cell_m));
            v as i64 * s.weight as i64
        })
        .sum()
}

/// A landing cell scores nothing, in [`field_score`] or [`Relevant::smooth_score`], unless the other
/// map has known ground within this many cells: one for the fields' band beside structure,
/// two for the smooth score's reach and one for its interpolation.
const REACH_CELLS: f64 = 4.0;
/// Points are picked again once the pose has moved them more than this (cells of the level
/// they land on) from where they were picked.
const MARGIN_CELLS: f64 = 4.0;

/// The surface points of both maps that can score at poses near one pose: those landing
/// within [`REACH_CELLS`] + [`MARGIN_CELLS`] of the other map's known ground. At small
/// overlaps most points land far out on unknown ground and score nothing, so refinement
/// skips them; every score stays exactly what it would be with all the points (a sum
/// without some zero terms), because the points are picked again whenever a pose moves
/// any of them farther than the margin.
struct Relevant {
    on: On,
    /// The pose the points were picked at.
    at: Pose2,
    /// The second map's points that can land near the first's known ground, and the reverse.
    b_points: Vec<Surface>,
    a_points: Vec<Surface>,
    /// Corners of the bounding boxes of all of each map's points: how far a change of pose
    /// moves any point is largest at one of them (the motion is affine in the point).
    b_corners: [Point2; 4],
    a_corners: [Point2; 4],
}

/// What a surface point earns for lying `d` fine cells from the other map's nearest
/// structure: 1 on it, nothing from two cells out.
fn earn(d: f32) -> f32 {
    (1.0 - d / 2.0).max(0.0)
}

/// [`Relevant::smooth_score`] of one map's points landing on the other's level.
fn smooth_one_way(points: &[Surface], target: &Level, target_from_source: &Pose2) -> f32 {
    let r = Rigid::new(target_from_source);
    points
        .iter()
        .filter_map(|s| dist_interp(target, r.apply(s.p)))
        .map(earn)
        .sum()
}

/// The fields refinement climbs on level `on` of `p`.
fn fields_on(p: &Prepared, on: On) -> &Fields {
    match on {
        On::Search => p.flat_fields(),
        On::Refine => p.local_fields(),
    }
}

/// The corners of the bounding box of `points`.
fn box_corners(points: &[Surface]) -> [Point2; 4] {
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for s in points {
        (x0, y0) = (x0.min(s.p.x_m), y0.min(s.p.y_m));
        (x1, y1) = (x1.max(s.p.x_m), y1.max(s.p.y_m));
    }
    if x0 > x1 {
        return [Point2::new(0.0, 0.0); 4];
    }
    [
        Point2::new(x0, y0),
        Point2::new(x1, y0),
        Point2::new(x0, y1),
        Point2::new(x1, y1),
    ]
}

/// The farthest any of `corners` moves from pose `from` to pose `to`.
fn largest_move(corners: &[Point2; 4], from: &Pose2, to: &Pose2) -> f64 {
    let (f, t) = (Rigid::new(from), Rigid::new(to));
    corners
        .iter()
        .map(|c| f.apply(*c).distance_m(t.apply(*c)))
        .fold(0.0, f64::max)
}

impl Relevant {
    /// The points and levels verification reads on `on`: each map's points, then the level
    /// of the map they land on, for both ways.
    fn parts<'p>(a: &'p Prepared, b: &'p Prepared, on: On) -> [(&'p [Surface], &'p Level); 2] {
        match on {
            On::Search => [(&b.search_points, &a.search), (&a.search_points, &b.search)],
            On::Refine => [(&b.local_points, &a.refine), (&a.local_points, &b.refine)],
        }
    }

    fn pick(a: &Prepared, b: &Prepared, on: On, at: Pose2) -> Relevant {
        let [(b_all, a_level), (a_all, b_level)] = Relevant::parts(a, b, on);
        let near = |points: &[Surface], target: &Level, t: &Pose2| -> Vec<Surface> {
            let r = Rigid::new(t);
            let reach = (REACH_CELLS + MARGIN_CELLS) as i64;
            points
                .iter()
                .filter(|s| {
                    let (x, y) = target.cell_under(r.apply(s.p));
                    target.known_near(x, y, reach)
                })
                .copied()
                .collect()
        };
        Relevant {
            on,
            at,
            b_points: near(b_all, a_level, &at),
            a_points: near(a_all, b_level, &at.inverse()),
            b_corners: box_corners(b_all),
            a_corners: box_corners(a_all),
        }
    }

    /// Picks the points again if `pose` moves any of them past the margin.
    fn keep_near(&mut self, a: &Prepared, b: &Prepared, pose: &Pose2) {
        let [(_, a_level), (_, b_level)] = Relevant::parts(a, b, self.on);
        let far = largest_move(&self.b_corners, &self.at, pose) > MARGIN_CELLS * a_level.cell_m
            || largest_move(&self.a_corners, &self.at.inverse(), &pose.inverse())
                > MARGIN_CELLS * b_level.cell_m;
        if far {
            *self = Relevant::pick(a, b, self.on, *pose);
        }
    }

    /// Both maps' points on each other's fields: a pose that looks right one way but puts
    /// the other map's structure on free space scores low.
    fn field_score(&mut self, a: &Prepared, b: &Prepared, a_from_b: &Pose2) -> i64 {
        self.keep_near(a, b, a_from_b);
        let [(_, a_level), (_, b_level)] = Relevant::parts(a, b, self.on);
        field_score(
            fields_on(a, self.on),
            a_level.cell_m,
            &self.b_points,
            a_from_b,
        ) + field_score(
            fields_on(b, self.on),
            b_level.cell_m,
            &self.a_points,
            &a_from_b.inverse(),
        )
    }

    /// Each point earns `1 - d / 2` for its distance `d` (fine cells) to the other map's
    /// nearest structure, both maps' points: smooth, for the last fraction of a cell.
    fn smooth_score(&mut self, a: &Prepared, b: &Prepared, a_from_b: &Pose2) -> f32 {
        debug_assert!(self.on == On::Refine);
        self.keep_near(a, b, a_from_b);
        smooth_one_way(&self.b_points, &a.refine, a_from_b)
            + smooth_one_way(&self.a_points, &b.refine, &a_from_b.inverse())
    }
}

/// Refines a hypothesis (grid-local `a_from_b`) by coordinate ascent on the symmetric,
/// direction-aware field score: first on the coarse level from two coarse cells and two
/// heading steps, then on the fine level from two fine cells and half a degree down to a
/// quarter of a fine cell; then on the surfaces' distances, summed and last on the points
/// the steps share ([`paired_closeness`]), which does not reward a wider overlap.
pub fn refine(a: &Prepared, b: &Prepared, start: Pose2, params: &Params) -> Pose2 {
    let coarse = a.search.cell_m;
    let yaw = params.yaw_step_rad;
    let deg = 1f64.to_radians();
    let pose = climb(
        a,
        b,
        On::Search,
        start,
        (2.0 * coarse, 2.0 * yaw),
        (coarse / 2.0, 0.25 * deg),
    );
    refine_fine(a, b, pose)
}

/// The fine level's part of [`refine`]: coordinate ascent on the field score from two fine
/// cells and half a degree down to a quarter of a fine cell, then on the surfaces'
/// distances, summed and last on the points the steps share.
fn refine_fine(a: &Prepared, b: &Prepared, start: Pose2) -> Pose2 {
    let fine = a.refine.cell_m;
    let deg = 1f64.to_radians();
    let pose = climb(
        a,
        b,
        On::Refine,
        start,
        (2.0 * fine, 0.5 * deg),
        (fine / 4.0, 0.03 * deg),
    );
    // The field score is flat within a cell of slack; finish on distances, which are not,
    // from close enough that the nearest structure is the right one.
    let pose = polish(a, b, pose, fine, deg);
    polish_on_common_points(a, b, pose, fine, deg)
}

/// Distance (fine cells) from a grid-local point to `level`'s nearest structure,
/// interpolated; `None` outside the grid.
fn dist_interp(level: &Level, p: Point2) -> Option<f32> {
    let fx = p.x_m / level.cell_m - 0.5;
    let fy = p.y_m / level.cell_m - 0.5;
    let (x0, y0) = (floor_i64(fx), floor_i64(fy));
    let (tx, ty) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
    let d00 = level.dist_at(x0, y0)?;
    let d10 = level.dist_at(x0 + 1, y0).unwrap_or(d00);
    let d01 = level.dist_at(x0, y0 + 1).unwrap_or(d00);
    let d11 = level.dist_at(x0 + 1, y0 + 1).unwrap_or(d00);
    Some((d00 * (1.0 - tx) + d10 * tx) * (1.0 - ty) + (d01 * (1.0 - tx) + d11 * tx) * ty)
}

/// How closely the two maps' surfaces lie on each other at grid-local `a_from_b`: each
/// surface point earns `1 - d / 2` for its distance `d` (fine cells, interpolated) to the
/// other map's nearest structure, both ways; what refinement's last stage climbs. Unlike
/// verification's counts, which tolerate a cell and a half, it tells poses a cell apart.
pub fn closeness(a: &Prepared, b: &Prepared, a_from_b: &Pose2) -> f64 {
    Relevant::pick(a, b, On::Refine, *a_from_b).smooth_score(a, b, a_from_b) as f64
}

/// [`closeness`] of two poses over the same points: a point counts, at both poses, only
/// where it lands on the other map's known ground at both. Closeness and the verified
/// counts are sums, so across a thin band of overlap a pose slid a few cells sideways
/// scores more by widening the band (more points land near structure) even when every
/// point it shares with the true pose lies farther from its match. On common points the
/// comparison is fair: `(closeness at p, closeness at q)`.
pub fn paired_closeness(a: &Prepared, b: &Prepared, p: &Pose2, q: &Pose2) -> (f64, f64) {
    Earnings::at(&b.local_points, &a.local_points, a, b, p).paired_with(a, b, q)
}

/// Both maps' points that land on the other's known ground at one pose, each with what it
/// earns there ([`closeness`]): the first half of [`paired_closeness`], kept to pair with
/// several poses.
struct Earnings {
    /// The second map's points, on the first.
    b: Vec<(Point2, f32)>,
    /// The first map's points, on the second.
    a: Vec<(Point2, f32)>,
}

impl Earnings {
    /// What `b_points` earn on `a` and `a_points` on `b` at grid-local `a_from_b`.
    fn at(
        b_points: &[Surface],
        a_points: &[Surface],
        a: &Prepared,
        b: &Prepared,
        a_from_b: &Pose2,
    ) -> Earnings {
        Earnings {
            b: earning(b_points, &a.refine, a_from_b),
            a: earning(a_points, &b.refine, &a_from_b.inverse()),
        }
    }

    /// [`paired_closeness`] of the pose these were taken at and `a_from_b`.
    fn paired_with(&self, a: &Prepared, b: &Prepared, a_from_b: &Pose2) -> (f64, f64) {
        let (bp, bq) = paired_sums(&self.b, &a.refine, a_from_b);
        let (ap, aq) = paired_sums(&self.a, &b.refine, &a_from_b.inverse());
        (bp + ap, bq + aq)
    }
}

/// What a point at grid-local `x` earns on `target` for [`closeness`]; `None` where it
/// lands on unknown ground.
fn earned(target: &Level, x: Point2) -> Option<f32> {
    let (cx, cy) = target.cell_under(x);
    if target.class_at(cx, cy) == Class::Unknown {
        return None;
    }
    dist_interp(target, x).map(earn)
}

/// The points that land on `target`'s known ground at `target_from_source`, each with what
/// it earns there.
fn earning(points: &[Surface], target: &Level, target_from_source: &Pose2) -> Vec<(Point2, f32)> {
    let r = Rigid::new(target_from_source);
    points
        .iter()
        .filter_map(|s| earned(target, r.apply(s.p)).map(|e| (s.p, e)))
        .collect()
}

/// Over the points of `earning` that land on known ground at `target_from_source` too:
/// what they earn at the pose `earning` was taken at, and at this one.
fn paired_sums(
    earning: &[(Point2, f32)],
    target: &Level,
    target_from_source: &Pose2,
) -> (f64, f64) {
    let r = Rigid::new(target_from_source);
    earning.iter().fold((0.0, 0.0), |(here, there), (p, e)| {
        match earned(target, r.apply(*p)) {
            Some(moved) => (here + f64::from(*e), there + f64::from(moved)),
            None => (here, there),
        }
    })
}

/// Coordinate ascent on [`paired_closeness`]: a move is taken when the points it shares
/// with the current pose lie closer at it, so a wider overlap buys nothing.
fn polish_on_common_points(a: &Prepared, b: &Prepared, start: Pose2, fine: f64, deg: f64) -> Pose2 {
    let c = b.centroid;
    let (mut step_xy, mut step_yaw) = (fine, 0.5 * deg);
    let mut pose = start;
    let mut relevant = Relevant::pick(a, b, On::Refine, start);
    let mut here = None;
    for _ in 0..80 {
        if step_xy < fine / 8.0 && step_yaw < 0.02 * deg {
            break;
        }
        relevant.keep_near(a, b, &pose);
        // What the points earn at the current pose, worked out once for its six moves.
        let earned_here = here.get_or_insert_with(|| {
            Earnings::at(&relevant.b_points, &relevant.a_points, a, b, &pose)
        });
        let mut gain = 0.0;
        let mut next = None;
        for m in moves(&pose, c, step_xy, step_yaw) {
            let (at_pose, at_move) = earned_here.paired_with(a, b, &m);
            if at_move - at_pose > gain {
                (gain, next) = (at_move - at_pose, Some(m));
            }
        }
        match next {
            Some(m) => {
                pose = m;
                here = None;
            }
            None => {
                step_xy /= 2.0;
                step_yaw /= 2.0;
            }
        }
    }
    pose
}

/// Coordinate ascent on [`Relevant::smooth_score`] from half a cell and a quarter degree down.
fn polish(a: &Prepared, b: &Prepared, start: Pose2, fine: f64, deg: f64) -> Pose2 {
    let c = b.centroid;
    let (mut step_xy, mut step_yaw) = (fine / 2.0, 0.25 * deg);
    let mut pose = start;
    let mut relevant = Relevant::pick(a, b, On::Refine, start);
    let mut best = relevant.smooth_score(a, b, &pose);
    for _ in 0..60 {
        if step_xy < fine / 8.0 && step_yaw < 0.02 * deg {
            break;
        }
        let mut improved = false;
        for m in moves(&pose, c, step_xy, step_yaw) {
            let s = relevant.smooth_score(a, b, &m);
            if s > best {
                (best, pose, improved) = (s, m, true);
            }
        }
        if !improved {
            step_xy /= 2.0;
            step_yaw /= 2.0;
        }
    }
    pose
}

/// The six moves coordinate ascent tries from `pose`: `step_xy` along each axis, and
/// `step_yaw` either way about the moving map's point `c`.
fn moves(pose: &Pose2, c: Point2, step_xy: f64, step_yaw: f64) -> [Pose2; 6] {
    [
        Pose2::new(pose.x_m + step_xy, pose.y_m, pose.yaw_rad),
        Pose2::new(pose.x_m - step_xy, pose.y_m, pose.yaw_rad),
        Pose2::new(pose.x_m, pose.y_m + step_xy, pose.yaw_rad),
        Pose2::new(pose.x_m, pose.y_m - step_xy, pose.yaw_rad),
        turned_about(pose, c, step_yaw),
        turned_about(pose, c, -step_yaw),
    ]
}

/// `p` turned by `dyaw` about the point `c` of the moving map (grid-local metres).
pub(crate) fn turned_about(p: &Pose2, c: Point2, dyaw: f64) -> Pose2 {
    let pc = p.transform_point(c);
    let q = Pose2::new(p.x_m, p.y_m, p.yaw_rad + dyaw);
    let qc = q.transform_point(c);
    Pose2::new(q.x_m + pc.x_m - qc.x_m, q.y_m + pc.y_m - qc.y_m, q.yaw_rad)
}

/// Coordinate ascent with halving steps from `steps` down to `min_steps` (metres, radians);
/// turns are about the moving map's centre, which keeps heading and translation nearly
/// independent.
fn climb(
    a: &Prepared,
    b: &Prepared,
    on: On,
    start: Pose2,
    steps: (f64, f64),
    min_steps: (f64, f64),
) -> Pose2 {
    let c = b.centroid;
    let (mut step_xy, mut step_yaw) = steps;
    let mut pose = start;
    let mut relevant = Relevant::pick(a, b, on, start);
    let mut best = relevant.field_score(a, b, &pose);
    for _ in 0..100 {
        if step_xy < min_steps.0 && step_yaw < min_steps.1 {
            break;
        }
        let mut improved = false;
        for m in moves(&pose, c, step_xy, step_yaw) {
            let s = relevant.field_score(a, b, &m);
            if s > best {
                best = s;
                pose = m;
                improved = true;
            }
        }
        if !improved {
            step_xy /= 2.0;
            step_yaw /= 2.0;
        }
    }
    pose
}

/// Tallies of one direction of verification.
#[derive(Clone, Copy, Default)]
struct Tally {
    agree: usize,
    conflict: usize,
    shape_agree: usize,
    shape_conflict: usize,
    landmark_agree: usize,
    landmark_conflict: usize,
}

/// What one structure point says about a pose.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Verdict {
    /// It lands on the other map's structure facing the same way.
    Agree,
    /// It lands on the other map's free space, far from any structure.
    Conflict,
    /// Anything else (unknown ground, structure facing another way, near structure).
    Neither,
}

/// Where `s` lands on `target` under `t` (whose heading is `yaw_rad`), and what it says.
#[inline]
fn judge(s: &Surface, target: &Level, t: &Rigid, yaw_rad: f64) -> (Point2, Verdict) {
    let q = t.apply(s.p);
    let (x, y) = target.cell_under(q);
    let Some(d) = target.dist_at(x, y) else {
        return (q, Verdict::Neither);
    };
    if d <= AGREE_CELLS {
        // A surface facing the same way (within a direction bin) within a cell.
        let n = direction_bin(s.normal_rad + yaw_rad);
        let facing = (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                target
                    .bin_at(x + dx, y + dy)
                    .is_some_and(|m| bins_face_alike(m, n))
            })
        });
        let verdict = if facing {
            Verdict::Agree
        } else {
            Verdict::Neither
        };
        (q, verdict)
    } else if d > CONFLICT_CELLS
        && target.class_at(x, y) == Class::Free
        && (target.free_judged_for_hazards || !s.hazard)
    {
        (q, Verdict::Conflict)
    } else {
        (q, Verdict::Neither)
    }
}

fn count_one_way(points: &[Surface], target: &Level, target_from_source: &Pose2) -> Tally {
    let mut tally = Tally::default();
    let t = Rigid::new(target_from_source);
    for s in points {
        match judge(s, target, &t, target_from_source.yaw_rad).1 {
            Verdict::Agree => {
                tally.agree += s.weight as usize;
                tally.shape_agree += usize::from(s.weight == SHAPE_WEIGHT);
                tally.landmark_agree += usize::from(s.landmark);
            }
            Verdict::Conflict => {
                tally.conflict += s.weight as usize;
                tally.shape_conflict += usize::from(s.weight == SHAPE_WEIGHT);
                tally.landmark_conflict += usize::from(s.landmark);
            }
            Verdict::Neither => {}
        }
    }
    tally
}

/// Share of the agreeing structure (both maps, by weight) that lies off the two straight
/// walls carrying most of it. Near 0 when all the maps agree on is a corner of two walls:
/// every corner of a rectangular arena or room fits that as well, a quarter or half turn
/// away, so such evidence cannot single out a pose however much of it there is, and in
/// sparse terrain the rest of the maps often has nothing to contradict the wrong corner.
/// Walls are found by sampling pairs of agreeing points seen from the same side (the
/// two-point line hypotheses of RANSAC, Fischler and Bolles 1981), on a fixed sequence so
/// that the answer is repeatable.
pub fn off_two_walls(a: &Prepared, b: &Prepared, a_from_b: &Pose2) -> f64 {
    // Agreeing points in the first map's grid-local frame: position, direction bin, weight.
    let mut points: Vec<(Point2, usize, f64)> = Vec::new();
    let forward = Rigid::new(a_from_b);
    for s in &b.refine_points {
        let (q, v) = judge(s, &a.refine, &forward, a_from_b.yaw_rad);
        if v == Verdict::Agree {
            let bin = direction_bin(s.normal_rad + a_from_b.yaw_rad);
            points.push((q, bin, s.weight as f64));
        }
    }
    let b_from_a = a_from_b.inverse();
    let backward = Rigid::new(&b_from_a);
    for s in &a.refine_points {
        if judge(s, &b.refine, &backward, b_from_a.yaw_rad).1 == Verdict::Agree {
            points.push((s.p, direction_bin(s.normal_rad), s.weight as f64));
        }
    }
    let total: f64 = points.iter().map(|p| p.2).sum();
    if total <= 0.0 {
        return 0.0;
    }
    let tolerance_m = AGREE_CELLS as f64 * a.refine.cell_m;
    let mut on_walls = 0.0;
    for _wall in 0..2 {
        let Some(on_wall) = strongest_wall(&points, tolerance_m) else {
            break;
        };
        let (wall, rest): (Vec<_>, Vec<_>) =
            points.into_iter().zip(on_wall).partition(|(_, on)| *on);
        on_walls += wall.iter().map(|(p, _)| p.2).sum::<f64>();
        points = rest.into_iter().map(|(p, _)| p).collect();
    }
    (1.0 - on_walls / total).max(0.0)
}

/// Which points lie on the straight wall with the most weight: points within
/// `tolerance_m` of a line through two sampled points seen from the same side at least a
/// metre apart, facing within a direction bin of them. `None` with no such pair.
fn strongest_wall(points: &[(Point2, usize, f64)], tolerance_m: f64) -> Option<Vec<bool>> {
    const SAMPLES: u64 = 256;
    let n = points.len() as u64;
    if n < 2 {
        return None;
    }
    // splitmix64: a fixed, well-spread sequence of indices.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    };
    // Whether `r` lies on the line through `p` with unit normal `(nx, ny)`, seen from the
    // same side as points in `bin`.
    let on_line = |r: &(Point2, usize, f64), p: Point2, nx: f64, ny: f64, bin: usize| {
        bins_face_alike(r.1, bin)
            && ((r.0.x_m - p.x_m) * nx + (r.0.y_m - p.y_m) * ny).abs() <= tolerance_m
    };
    let mut best: Option<(f64, Point2, f64, f64, usize)> = None;
    for _ in 0..SAMPLES {
        let (i, j) = ((next() % n) as usize, (next() % n) as usize);
        let (p, bin, _) = points[i];
        let (q, other, _) = points[j];
        let length = p.distance_m(q);
        if other != bin || length < 1.0 {
            continue;
        }
        // Unit normal of the line through p and q.
        let (nx, ny) = (-(q.y_m - p.y_m) / length, (q.x_m - p.x_m) / length);
        let weight: f64 = points
            .iter()
            .filter(|r| on_line(r, p, nx, ny, bin))
            .map(|r| r.2)
            .sum();
        if best.is_none_or(|b| weight > b.0) {
            best = Some((weight, p, nx, ny, bin));
        }
    }
    let (_, p, nx, ny, bin) = best?;
    Some(points.iter().map(|r| on_line(r, p, nx, ny, bin)).collect())
}

/// Obstacle points (hazards aside) of each map that land within `tolerance_m` of the other
/// map's structure, and those that land on its free ground farther than that from any:
/// whether two maps agree on a pose up to the drift the tolerance allows. Hazards are left
/// out because when the maps come from rovers, one rover's hazard may lie where the other's
/// lidar passed over and its depth camera never looked, which its map calls free.
pub fn loose_agreement(
    a: &Prepared,
    b: &Prepared,
    a_from_b: &Pose2,
    tolerance_m: f64,
) -> (usize, usize) {
    let one_way = |points: &[Surface], target: &Level, t: &Pose2| {
        let t = Rigid::new(t);
        let tolerance_cells = (tolerance_m / target.cell_m) as f32;
        let (mut near, mut far) = (0, 0);
        for s in points.iter().filter(|s| !s.hazard) {
            let q = t.apply(s.p);
            let (x, y) = target.cell_under(q);
            let Some(d) = target.dist_at(x, y) else {
                continue;
            };
            if d <= tolerance_cells {
                near += 1;
            } else if target.class_at(x, y) == Class::Free {
                far += 1;
            }
        }
        (near, far)
    };
    let (n1, f1) = one_way(&b.refine_points, &a.refine, a_from_b);
    let (n2, f2) = one_way(&a.refine_points, &b.refine, &a_from_b.inverse());
    (n1 + n2, f1 + f2)
}

/// Which level verification reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum On {
    /// The coarse search level: a cheap screen of many hypotheses.
    Search,
    /// The fine level: the verdict.
    Refine,
}

/// Both ways of verification's tallies for grid-local `a_from_b` on level `on`.
fn tallies(a: &Prepared, b: &Prepared, a_from_b: &Pose2, on: On) -> (Tally, Tally) {
    match on {
        On::Search => (
            count_one_way(&b.search_points, &a.search, a_from_b),
            count_one_way(&a.search_points, &b.search, &a_from_b.inverse()),
        ),
        On::Refine => (
            count_one_way(&b.refine_points, &a.refine, a_from_b),
            count_one_way(&a.refine_points, &b.refine, &a_from_b.inverse()),
        ),
    }
}

/// [`verify`]'s score alone, without the overlap it also measures (the costlier part):
/// all that screening hypotheses, or choosing between a refined pose and its start, reads.
pub fn score(a: &Prepared, b: &Prepared, a_from_b: &Pose2, conflict_weight: f64, on: On) -> f64 {
    let (t1, t2) = tallies(a, b, a_from_b, on);
    (t1.agree + t2.agree) as f64 - conflict_weight * (t1.conflict + t2.conflict) as f64
}

/// Verifies grid-local `a_from_b` on level `on`.
pub fn verify(
    a: &Prepared,
    b: &Prepared,
    a_from_b: &Pose2,
    conflict_weight: f64,
    on: On,
) -> Evidence {
    let (t1, t2) = tallies(a, b, a_from_b, on);
    let t = Rigid::new(a_from_b);
    let (mut overlap_points, mut sx, mut sy) = (0usize, 0.0, 0.0);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in &b.known_points {
        let q = t.apply(*p);
        let (x, y) = a.search.cell_under(q);
        if a.search.class_at(x, y) != Class::Unknown {
            overlap_points += 1;
            sx += p.x_m;
            sy += p.y_m;
            sxx += p.x_m * p.x_m;
            sxy += p.x_m * p.y_m;
            syy += p.y_m * p.y_m;
        }
    }
    let (overlap_centre, overlap_radius_m, overlap_ends) = if overlap_points == 0 {
        (b.centroid, 0.0, [b.centroid; 2])
    } else {
        let n = overlap_points as f64;
        let (cx, cy) = (sx / n, sy / n);
        let (vxx, vxy, vyy) = (sxx / n - cx * cx, sxy / n - cx * cy, syy / n - cy * cy);
        // The larger eigenvalue of the spread and its axis.
        let half_diff = (vxx - vyy) / 2.0;
        let major = ((vxx + vyy) / 2.0 + half_diff.hypot(vxy)).max(0.0);
        let axis = vxy.atan2(half_diff) / 2.0;
        // A uniform strip of length l spreads l^2 / 12 along it: its ends lie sqrt(3)
        // standard deviations out.
        let half_length = (3.0 * major).sqrt();
        let (s, c) = axis.sin_cos();
        (
            Point2::new(cx, cy),
            (vxx + vyy).max(0.0).sqrt(),
            [
                Point2::new(cx + half_length * c, cy + half_length * s),
                Point2::new(cx - half_length * c, cy - half_length * s),
            ],
        )
    };
    let agree = t1.agree + t2.agree;
    let conflict = t1.conflict + t2.conflict;
    Evidence {
        shape_agree: t1.shape_agree + t2.shape_agree,
        shape_conflict: t1.shape_conflict + t2.shape_conflict,
        landmark_agree: t1.landmark_agree + t2.landmark_agree,
        landmark_conflict: t1.landmark_conflict + t2.landmark_conflict,
        agree,
        conflict,
        overlap_m2: overlap_points as f64 * b.known_area_per_point_m2,
        overlap_centre,
        overlap_radius_m,
        overlap_ends,
        score: agree as f64 - conflict_weight * conflict as f64,
    }
}

/// What [`sharpness`] takes off the share lost by moves twice the shift: losing all of it
/// there counts as three quarters here.
const FAR_SHIFT_DISCOUNT: f64 = 0.25;

/// How sharply verification singles out `a_from_b`: one less the best share of its score
/// kept by the pose moved `shift_m` in any of eight directions, or turned either way, about
/// the overlap's centre and about either end of its long axis, by the angle that moves the
/// overlap `shift_m` on average about its centre, but at least `min_turn_rad`. Near 0 when
/// the maps could slide (walls and nothing else in the overlap) or turn; near 1 when any
/// move loses most of the agreement. The same idea as judging a correlative match by the
/// spread of its score (Olson 2009).
///
/// Maps that two rovers built disagree by their drift, a few decimetres, and that broadens
/// the peak: moved `shift_m`, such a pose can keep 80-100 % of its score, and lose it all
/// moved twice as far, where a slide along bare walls keeps 70 % or more (BENCHMARKS.md,
/// "The rovers' own maps"). So where the near moves keep more than half the score, the
/// moves twice as far are probed too, and the shifts' sharpness is the better of one less
/// what the near moves keep and `FAR_SHIFT_DISCOUNT` less what the far ones keep: with
/// the merge's 0.25 threshold, a pose whose far moves keep at most half its score is
/// pinned.
///
/// With `heading_held` the turns are left out: the maps' long walls have pinned the
/// heading ([`crate::lines`]), more surely than the overlap can.
#[allow(clippy::too_many_arguments)]
pub fn sharpness(
    a: &Prepared,
    b: &Prepared,
    a_from_b: &Pose2,
    evidence: &Evidence,
    conflict_weight: f64,
    shift_m: f64,
    min_turn_rad: f64,
    heading_held: bool,
) -> f64 {
    if evidence.score <= 0.0 {
        return 0.0;
    }
    let kept = |poses: &mut dyn Iterator<Item = Pose2>| {
        poses
            .map(|p| verify(a, b, &p, conflict_weight, On::Refine).score / evidence.score)
            .fold(0.0, f64::max)
    };
    let shifted = |d: f64| {
        (0..8).map(move |k| {
            let (s, co) = (k as f64 * std::f64::consts::FRAC_PI_4).sin_cos();
            Pose2::new(
                a_from_b.x_m + d * co,
                a_from_b.y_m + d * s,
                a_from_b.yaw_rad,
            )
        })
    };
    let turn_rad = (shift_m / evidence.overlap_radius_m.max(1.0))
        .min(0.1)
        .max(min_turn_rad);
    // About the ends of a long overlap too: a square or a crater at one end of a band can
    // pin the position there and leave the band free to swing about it.
    let pivots = [
        evidence.overlap_centre,
        evidence.overlap_ends[0],
        evidence.overlap_ends[1],
    ];
    let turned_kept = if heading_held {
        0.0
    } else {
        kept(
            &mut pivots
                .into_iter()
                .flat_map(|c| [turn_rad, -turn_rad].map(|t| turned_about(a_from_b, c, t))),
        )
    };
    let near = 1.0 - kept(&mut shifted(shift_m));
    // Already sharp enough for any threshold up to a half: the far moves cannot matter.
    let shift_sharpness = if near >= 0.5 {
        near
    } else {
        near.max(1.0 - FAR_SHIFT_DISCOUNT - kept(&mut shifted(2.0 * shift_m)))
    };
    shift_sharpness.min(1.0 - turned_kept).clamp(0.0, 1.0)
}

/// Share (by weight, both maps) of the structure agreeing at pose `other` that also agrees
/// at pose `base` and lands there within `tolerance_m` of where `other` puts it. Near 1 when
/// `other` explains nothing `base` does not, with the same pairs of cells: the same
/// explanation with part of it slid out of the overlap. Near 0 for an explanation of its
/// own, such as walls laid over other walls a quarter turn away.
pub fn shared_agreement(
    a: &Prepared,
    b: &Prepared,
    base: &Pose2,
    other: &Pose2,
    tolerance_m: f64,
) -> f64 {
    shared_agreement_of(a, b, base, other, tolerance_m, false)
}

/// [`shared_agreement`] over landmark points only (`landmarks`) or over all structure.
pub fn shared_agreement_of(
    a: &Prepared,
    b: &Prepared,
    base: &Pose2,
    other: &Pose2,
    tolerance_m: f64,
    landmarks: bool,
) -> f64 {
    let (mut shared, mut total) = (0.0, 0.0);
    for (points, target, base, other) in [
        (&b.refine_points, &a.refine, *base, *other),
        (&a.refine_points, &b.refine, base.inverse(), other.inverse()),
    ] {
        let (tb, to) = (Rigid::new(&base), Rigid::new(&other));
        for s in points {
            if landmarks && !s.landmark {
                continue;
            }
            let (q_other, v_other) = judge(s, target, &to, other.yaw_rad);
            if v_other != Verdict::Agree {
                continue;
            }
            total += s.weight as f64;
            let (q_base, v_base) = judge(s, target, &tb, base.yaw_rad);
            if v_base == Verdict::Agree && q_base.distance_m(q_other) <= tolerance_m {
                shared += s.weight as f64;
            }
        }
    }
    if total > 0.0 { shared / total } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Map, MapCell};
    use realms_core::{Grid, GridGeometry};

    /// A room's corner (two walls) with rocks on open ground at `rocks` (cells).
    fn corner(rocks: &[(usize, usize)]) -> Map {
        let g = GridGeometry {
            width: 120,
            height: 80,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut grid = Grid::new(g, MapCell::Free);
        for x in 0..120 {
            *grid.get_mut(x, 0).expect("in") = MapCell::Occupied;
        }
        for y in 0..80 {
            *grid.get_mut(0, y).expect("in") = MapCell::Occupied;
        }
        for &(rx, ry) in rocks {
            for y in ry..ry + 4 {
                for x in rx..rx + 4 {
                    *grid.get_mut(x, y).expect("in") = MapCell::Occupied;
                }
            }
        }
        Map::new(grid)
    }

    /// A rover's map of a 12 m x 8 m patch of ground at 5 cm between two walls along x
    /// (y = 0 and y = 8 m), open at both ends, with round hazards (rocks in their rings) of
    /// `radius_m` at `rocks` (metres), drawn `grow_m` wider (as another rover's map draws
    /// them: a camera that looked from elsewhere).
    fn corridor(rocks: &[(f64, f64)], radius_m: f64, grow_m: f64) -> Map {
        let g = GridGeometry {
            width: 240,
            height: 161,
            resolution_m: 0.05,
            origin: Point2::new(0.0, 0.0),
        };
        let cells = (0..g.len())
            .map(|i| {
                let cell = realms_core::Cell {
                    x: i % g.width,
                    y: i / g.width,
                };
                let p = g.cell_center(cell);
                let rock = rocks
                    .iter()
                    .any(|(x, y)| p.distance_m(Point2::new(*x, *y)) < radius_m + grow_m);
                if cell.y == 0 || cell.y == g.height - 1 {
                    MapCell::Occupied
                } else if rock {
                    MapCell::Hazard
                } else {
                    MapCell::Free
                }
            })
            .collect();
        Map::new(Grid::from_cells(g, cells).expect("one cell each"))
            .with_free_unjudged_for_hazards()
    }

    fn sharpness_of(a: &Map, b: &Map) -> f64 {
        let params = Params::default();
        let (a, b) = (Prepared::new(a, &params), Prepared::new(b, &params));
        let here = Pose2::new(0.0, 0.0, 0.0);
        let e = verify(&a, &b, &here, params.conflict_weight, On::Refine);
        sharpness(
            &a,
            &b,
            &here,
            &e,
            params.conflict_weight,
            params.sharpness_shift_m,
            params.sharpness_min_turn_rad,
            false,
        )
    }

    #[test]
    fn walls_alone_slide_but_hazards_drawn_wider_in_one_map_still_pin_the_pose() {
        // Bare walls: the maps slide along them, 0.3 m or 0.6 m alike.
        let bare = corridor(&[], 0.0, 0.0);
        let s = sharpness_of(&bare, &bare);
        assert!(s < 0.25, "{s}");
        // Hazards drawn 0.15 m wider in the second map: moved 0.3 m along the walls, the
        // pose keeps most of its score (0.16 sharp on those moves alone); moved 0.6 m, little
        // of it, so the pose is pinned (0.38).
        let rocks = [(2.5, 2.0), (5.0, 6.0), (7.5, 3.0), (10.0, 5.5)];
        let thin = corridor(&rocks, 0.3, 0.0);
        let fat = corridor(&rocks, 0.3, 0.15);
        let s = sharpness_of(&thin, &fat);
        assert!(s >= 0.3, "{s}");
        // The same maps, drawn alike, are sharper still.
        assert!(sharpness_of(&thin, &thin) >= s, "{s}");
    }

    #[test]
    fn a_rock_on_open_ground_is_a_landmark_conflict() {
        let params = Params::default();
        let a = Prepared::new(&corner(&[(40, 30), (80, 50)]), &params);
        let same = Prepared::new(&corner(&[(40, 30), (80, 50)]), &params);
        let moved = Prepared::new(&corner(&[(40, 30), (80, 20)]), &params);
        let here = Pose2::new(0.0, 0.0, 0.0);
        let e = verify(&a, &same, &here, params.conflict_weight, On::Refine);
        assert!(e.landmark_agree >= 16, "{e:?}");
        assert_eq!(e.landmark_conflict, 0, "{e:?}");
        // The walls agree as well as before; one rock of each map lands on open ground.
        let e = verify(&a, &moved, &here, params.conflict_weight, On::Refine);
        assert!(e.landmark_conflict >= 8, "{e:?}");
        assert!(e.landmark_agree >= 8, "{e:?}");
    }

    /// Every score with all the points, for comparison with [`Relevant`]'s.
    fn full_scores(a: &Prepared, b: &Prepared, on: On, a_from_b: &Pose2) -> (i64, f32) {
        let [(b_all, a_level), (a_all, b_level)] = Relevant::parts(a, b, on);
        let field = field_score(fields_on(a, on), a_level.cell_m, b_all, a_from_b)
            + field_score(fields_on(b, on), b_level.cell_m, a_all, &a_from_b.inverse());
        let smooth = smooth_one_way(b_all, a_level, a_from_b)
            + smooth_one_way(a_all, b_level, &a_from_b.inverse());
        (field, smooth)
    }

    #[test]
    fn refinement_skips_only_points_that_score_nothing() {
        let params = Params::default();
        // The first map known only up to column 60, with a rock right at that edge: points
        // landing just beyond it, on unknown ground, still score.
        let mut first = corner(&[(40, 30), (56, 50), (20, 60)]);
        for y in 0..80 {
            for x in 60..120 {
                *first.cells.get_mut(x, y).expect("in") = MapCell::Unknown;
            }
        }
        let a = Prepared::new(&first, &params);
        let b = Prepared::new(&corner(&[(20, 20), (60, 10), (30, 40)]), &params);
        // The second map partly off the first: many of its points land on unknown ground.
        let picked_at = Pose2::new(2.0, 1.0, 0.1);
        for on in [On::Search, On::Refine] {
            let mut relevant = Relevant::pick(&a, &b, on, picked_at);
            let all = b_points_count(&b, on) + b_points_count(&a, on);
            let kept = relevant.b_points.len() + relevant.a_points.len();
            assert!(kept < all, "{on:?}: nothing skipped ({kept} of {all})");
            // Within the margin, beyond it (picked again), and back.
            for pose in [
                picked_at,
                Pose2::new(1.7, 0.9, 0.1),
                Pose2::new(2.2, 1.1, 0.11),
                Pose2::new(0.5, 0.2, 0.0),
                Pose2::new(2.05, 0.95, 0.1),
            ] {
                let (field, smooth) = full_scores(&a, &b, on, &pose);
                assert_eq!(
                    relevant.field_score(&a, &b, &pose),
                    field,
                    "{on:?} {pose:?}"
                );
                if on == On::Refine {
                    let s = relevant.smooth_score(&a, &b, &pose);
                    assert!((s - smooth).abs() < 1e-3, "{pose:?}: {s} vs {smooth}");
                }
            }
        }
    }

    fn b_points_count(p: &Prepared, on: On) -> usize {
        match on {
            On::Search => p.search_points.len(),
            On::Refine => p.local_points.len(),
        }
    }

    #[test]
    fn a_pose_slid_a_little_shares_the_agreement_and_a_quarter_turn_does_not() {
        let params = Params::default();
        let rocky = Prepared::new(&corner(&[(40, 30), (80, 50)]), &params);
        let here = Pose2::new(0.0, 0.0, 0.0);
        assert!(shared_agreement(&rocky, &rocky, &here, &here, 0.5) > 0.99);
        // Slid a cell along the x wall: the same pairs of cells agree, 0.1 m apart.
        let slid = Pose2::new(0.1, 0.0, 0.0);
        let shared = shared_agreement(&rocky, &rocky, &here, &slid, 0.5);
        assert!(shared > 0.9, "slid: {shared}");
        // Turned a quarter and moved up so the x wall lies along the y wall, facing the
        // same way: what agrees there are other pairs of cells, metres from the first.
        let turned = Pose2::new(0.0, 8.0, -std::f64::consts::FRAC_PI_2);
        let e = verify(&rocky, &rocky, &turned, params.conflict_weight, On::Refine);
        assert!(e.agree > 50, "the walls agree at the quarter turn: {e:?}");
        let shared = shared_agreement(&rocky, &rocky, &here, &turned, 0.5);
        assert!(shared < 0.1, "turned: {shared}");
    }

    #[test]
    fn a_bare_corner_is_all_on_two_walls_and_rocks_lie_off_them() {
        let params = Params::default();
        let here = Pose2::new(0.0, 0.0, 0.0);
        let bare = Prepared::new(&corner(&[]), &params);
        let off = off_two_walls(&bare, &bare, &here);
        assert!(off < 0.05, "a bare corner: {off}");
        let rocky = Prepared::new(&corner(&[(40, 30), (80, 50)]), &params);
        let off = off_two_walls(&rocky, &rocky, &here);
        assert!(off > 0.15, "a corner with two rocks: {off}");
        // Nothing agrees at all: nothing off the walls either.
        let far = Pose2::new(100.0, 100.0, 0.0);
        assert_eq!(off_two_walls(&rocky, &rocky, &far), 0.0);
    }
}
