//! Exhaustive scan-to-map search over a large window, made cheap by branch and bound (the
//! fast correlative scan matcher of Hess et al., "Real-Time Loop Closure in 2D LIDAR SLAM",
//! ICRA 2016, after Olson, "Real-Time Correlative Scan Matching", ICRA 2009).
//!
//! The map is precomputed once into a stack of grids; level `d` holds, for every cell, the
//! highest occupancy in the `2^d x 2^d` block starting there. Scoring a scan against level
//! `d` at an offset therefore bounds from above the score of every offset in the block, so
//! whole blocks of the search window are pruned when their bound cannot beat the best pose
//! found so far. The answer is the same as scoring every pose of the discretised window.
//!
//! Loop closure needs more than the best pose: a corridor or a repeated room gives several
//! poses that score almost alike, and taking one of them is the classic false closure. So the
//! search also reports the best pose *clearly away* from the winner (the rival), and callers
//! refuse closures whose winner does not stand out.

use crate::occupancy::{OccupancyGrid, floor_to_i64};
use realms_core::{Point2, Pose2};
use std::cell::OnceCell;

/// What an unobserved cell (or one outside the map) scores: its occupancy probability, 0.5.
/// (Scoring it low, as Cartographer does, prunes better but made closures on the real logs
/// fragile: Intel's error rose 25x with the search threshold moved by 0.05.)
const UNKNOWN: u8 = 128;

/// The precomputed stack of block maxima of one map.
#[derive(Clone, Debug)]
pub struct PrecomputedMap {
    resolution_m: f64,
    origin: Point2,
    width: i64,
    height: i64,
    /// Unknown cells kept around the map on every side (see [`PrecomputedMap::with_margin`]).
    margin: i64,
    /// Level `d`: cells `[-(2^d - 1) - margin, width + margin)` x
    /// `[-(2^d - 1) - margin, height + margin)`, row by row.
    levels: Vec<Vec<u8>>,
}

impl PrecomputedMap {
    /// Precomputes `depth + 1` levels (blocks up to `2^depth` cells) of `grid`.
    pub fn new(grid: &OccupancyGrid, depth: usize) -> Self {
        Self::with_margin(grid, depth, 0)
    }

    /// [`new`](Self::new), with `margin` unknown cells kept around the map. A search whose
    /// scan reaches no farther past the map than that scores each candidate without a
    /// bounds check per point. A closure's scan ends on the walls that bound the submap,
    /// so without a margin most candidates of its window poke out of the map, and the
    /// checks cost most of the search.
    pub fn with_margin(grid: &OccupancyGrid, depth: usize, margin: usize) -> Self {
        let geometry = grid.geometry();
        let prob = grid.probabilities();
        // Only the observed part: grids grow in generous steps, and everything outside is
        // unknown anyway.
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, p) in prob.iter().enumerate() {
            if *p != 0.5 {
                let (x, y) = (i % geometry.width, i / geometry.width);
                (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
            }
        }
        if x0 > x1 {
            (x0, y0, x1, y1) = (0, 0, 0, 0);
        }
        let (width, height) = ((x1 + 1 - x0) as i64, (y1 + 1 - y0) as i64);
        let m = margin as i64;
        let row0 = (width + 2 * m) as usize;
        let mut level0 = vec![UNKNOWN; row0 * (height + 2 * m) as usize];
        for y in y0..=y1 {
            let row = &prob[y * geometry.width + x0..=y * geometry.width + x1];
            let at = (y - y0 + margin) * row0 + margin;
            for (cell, p) in level0[at..at + row.len()].iter_mut().zip(row) {
                *cell = if *p == 0.5 {
                    UNKNOWN
                } else {
                    (p * 255.0).round().clamp(0.0, 255.0) as u8
                };
            }
        }
        let r = geometry.resolution_m;
        let mut map = PrecomputedMap {
            resolution_m: r,
            origin: Point2::new(
                geometry.origin.x_m + x0 as f64 * r,
                geometry.origin.y_m + y0 as f64 * r,
            ),
            width,
            height,
            margin: m,
            levels: vec![level0],
        };
        for d in 1..=depth {
            let next = map.next_level(d);
            map.levels.push(next);
        }
        map
    }

    /// Level `d` (`d >= 1`) from level `d - 1`: each cell the highest of the four cells
    /// `2^(d-1)` apart that its block covers, unknown outside the level below. Two passes
    /// of pairwise maxima over rows, then columns, on the level below set in a border of
    /// unknown cells, so no cell is looked up with a bounds check.
    fn next_level(&self, d: usize) -> Vec<u8> {
        let half = 1usize << (d - 1);
        let m = self.margin as usize;
        let (width, height) = (self.width as usize, self.height as usize);
        let below = &self.levels[d - 1];
        // The level below spans map cells `-(low - half)..width + m` in x (likewise y).
        let low = (1usize << d) - 1 + m;
        let (bw, bh) = (width + low - half + m, height + low - half + m);
        let (w, h) = (width + low + m, height + low + m);
        // The level below with `half` unknown cells before and after it: cells
        // `-low..width + m + half`.
        let ew = w + half;
        let mut ext = vec![UNKNOWN; ew * (h + half)];
        for y in 0..bh {
            let at = (y + half) * ew + half;
            ext[at..at + bw].copy_from_slice(&below[y * bw..(y + 1) * bw]);
        }
        let mut rows = vec![0u8; w * (h + half)];
        for (out, row) in rows.chunks_exact_mut(w).zip(ext.chunks_exact(ew)) {
            for (x, v) in out.iter_mut().enumerate() {
                *v = row[x].max(row[x + half]);
            }
        }
        let mut cells = vec![0u8; w * h];
        for (y, out) in cells.chunks_exact_mut(w).enumerate() {
            let (a, b) = (
                &rows[y * w..(y + 1) * w],
                &rows[(y + half) * w..(y + half + 1) * w],
            );
            for ((v, p), q) in out.iter_mut().zip(a).zip(b) {
                *v = (*p).max(*q);
            }
        }
        cells
    }

    /// The deepest level.
    pub fn depth(&self) -> usize {
        self.levels.len() - 1
    }

    /// Level `d`, for looking up many cells.
    fn level(&self, d: usize) -> Level<'_> {
        let low = (1i64 << d) - 1 + self.margin;
        Level {
            cells: &self.levels[d],
            pad: low,
            width: self.width + low + self.margin,
            height: self.height + low + self.margin,
        }
    }
}

/// One level of a [`PrecomputedMap`] with its padded bounds.
struct Level<'a> {
    cells: &'a [u8],
    pad: i64,
    width: i64,
    height: i64,
}

impl Level<'_> {
    /// The cell `(x, y)` (map cells, before padding); unknown outside.
    fn at(&self, x: i64, y: i64) -> u8 {
        let (ix, iy) = (x + self.pad, y + self.pad);
        // Negative indices wrap to huge unsigned ones, so one comparison per axis.
        if (ix as u64) < self.width as u64 && (iy as u64) < self.height as u64 {
            self.cells[(iy * self.width + ix) as usize]
        } else {
            UNKNOWN
        }
    }

    /// The sum of the cells at `offsets` (into the rows, from map cell (0, 0)) moved by
    /// (`dx`, `dy`) cells, every one of which must lie inside.
    fn sum_at(&self, offsets: &[i64], dx: i64, dy: i64) -> u32 {
        let shift = (dy + self.pad) * self.width + dx + self.pad;
        offsets
            .iter()
            .map(|k| self.cells[(k + shift) as usize] as u32)
            .sum()
    }
}

/// One heading's scan on one level, its points split by where they can fall over the whole
/// search window (offsets up to `n_cells` either way): a point outside the level for every
/// offset scores [`UNKNOWN`] whatever the offset, one inside it for every offset is a load
/// with no bounds test, and only the few near its edge are tested. A scan reaches 12 m and
/// a submap often less, so most candidates straddle the edge, and this keeps them off the
/// per-point test. The sums are of integers: the same scores as testing every point.
struct SplitScan {
    /// The points outside for every offset, times [`UNKNOWN`].
    outside: u32,
    /// The points inside for every offset, as offsets into the level's rows from the
    /// prior's cell.
    inside: Vec<i64>,
    /// The rest, in cells from the prior's.
    near_edge: Vec<(i64, i64)>,
}

impl SplitScan {
    fn new(level: &Level<'_>, cells: &[(i64, i64)], n_cells: i64) -> Self {
        let (pad, w, h) = (level.pad, level.width, level.height);
        let always = |v: i64, n: i64| v - n_cells + pad >= 0 && v + n_cells + pad < n;
        let never = |v: i64, n: i64| v + n_cells + pad < 0 || v - n_cells + pad >= n;
        let mut split = SplitScan {
            outside: 0,
            inside: Vec::with_capacity(cells.len()),
            near_edge: Vec::new(),
        };
        for &(x, y) in cells {
            if never(x, w) || never(y, h) {
                split.outside += UNKNOWN as u32;
            } else if always(x, w) && always(y, h) {
                split.inside.push(y * w + x);
            } else {
                split.near_edge.push((x, y));
            }
        }
        split
    }

    /// The scan's score on `level` moved by (`dx`, `dy`) cells, within the window it was
    /// split for.
    fn score(&self, level: &Level<'_>, dx: i64, dy: i64) -> u32 {
        let near_edge: u32 = self
            .near_edge
            .iter()
            .map(|(x, y)| level.at(x + dx, y + dy) as u32)
            .sum();
        self.outside + level.sum_at(&self.inside, dx, dy) + near_edge
    }
}

/// The search window around a prior pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchWindow {
    /// Half-width in x and in y, metres.
    pub linear_m: f64,
    /// Half-width in heading, radians.
    pub angular_rad: f64,
    /// Rotation steps are chosen so a point this far away moves about one cell.
    pub step_range_m: f64,
}

/// Poses clearly different from the winner, for the rival: farther than this in cells...
const RIVAL_CELLS: i64 = 6;
/// ... or in heading, radians.
const RIVAL_RAD: f64 = 0.05;

/// The search's answer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchResult {
    /// Best pose of the scan in the map's frame.
    pub pose: Pose2,
    /// Its score: mean occupancy probability at the scan's endpoints (nearest cell).
    pub score: f64,
    /// The best score of any pose clearly away from `pose`; `0` if none comes within the
    /// rival margin of `score` (or reaches `min_score`). Where one comes closer to `score`
    /// than the margin (the winner is ambiguous), the first such score the search met:
    /// the verdict is the same, and a search that went on for the best would pass over most
    /// of the window again to no end (ambiguous winners were four fifths of the rovers'
    /// closure searches' time).
    pub rival_score: f64,
    /// Set where the only rivals within the margin lie on a ridge of high scores running
    /// from the winner (see [`search_allowing_ridges`]): the scan pins the pose across the
    /// ridge, and along it only as the scores fall. `rival_score` is then the best score
    /// off the ridge.
    pub ridge: Option<Ridge>,
}

/// A ridge of the score through the winner: poses along it score nearly as well, with no
/// dip between them and the winner (a long wall seen with little else), unlike a rival in
/// a look-alike place, which scores well only where it matches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ridge {
    /// Its direction in the map's frame, radians.
    pub direction_rad: f64,
    /// How far along it the rival that revealed it lies, metres ...
    pub rival_m: f64,
    /// ... and how much lower it scores than the winner.
    pub drop: f64,
}

impl SearchResult {
    /// Whether a rival comes within `margin` of the winner: the winner is then no closure.
    pub fn is_ambiguous(&self, margin: f64) -> bool {
        ambiguous(self.score, self.rival_score, margin)
    }
}

/// The one test of ambiguity, shared by the search (which stops at the first rival that
/// passes it) and its callers (which judge its answer), so both decide alike to the bit.
fn ambiguous(winner_score: f64, rival_score: f64, margin: f64) -> bool {
    winner_score - rival_score < margin
}

#[derive(Clone, Copy)]
struct Candidate {
    angle: usize,
    dx: i64,
    dy: i64,
    score: u32,
}

/// How a search window is discretised: rotation steps that move a point at the window's
/// step range by about one cell, translation steps of one cell.
struct Discretised {
    angle_step: f64,
    n_angles: i64,
    n_cells: i64,
}

impl Discretised {
    fn new(map: &PrecomputedMap, window: &SearchWindow) -> Self {
        let r = map.resolution_m;
        let d = window.step_range_m.max(r);
        let angle_step = (1.0 - r * r / (2.0 * d * d)).acos();
        Discretised {
            angle_step,
            n_angles: (window.angular_rad / angle_step).ceil() as i64,
            n_cells: (window.linear_m / r).ceil() as i64,
        }
    }

    /// The cells of `points` with the prior's translation and its heading turned by `k`
    /// steps.
    fn cells(
        &self,
        map: &PrecomputedMap,
        points: &[Point2],
        prior: Pose2,
        k: i64,
    ) -> Vec<(i64, i64)> {
        let r = map.resolution_m;
        let (s, c) = (prior.yaw_rad + k as f64 * self.angle_step).sin_cos();
        points
            .iter()
            .map(|p| {
                let x = prior.x_m + c * p.x_m - s * p.y_m;
                let y = prior.y_m + s * p.x_m + c * p.y_m;
                (
                    floor_to_i64((x - map.origin.x_m) / r),
                    floor_to_i64((y - map.origin.y_m) / r),
                )
            })
            .collect()
    }
}

/// Finds the best pose of `points` (robot frame) in `map` within `window` around `prior`,
/// among poses scoring at least `min_score`; `None` if none does. The rival is looked for
/// only down to `rival_margin` below the winner and not below `min_score`, and no further
/// once one comes closer than that.
pub fn search(
    map: &PrecomputedMap,
    points: &[Point2],
    prior: Pose2,
    window: &SearchWindow,
    min_score: f64,
    rival_margin: f64,
) -> Option<SearchResult> {
    search_allowing_ridges(
        map,
        points,
        prior,
        window,
        min_score,
        rival_margin,
        None,
        None,
    )
}

/// [`search`], where a rival within `rival_margin` that lies on a ridge of high scores
/// running from the winner does not make the winner ambiguous: the scores between the two,
/// at every cell along the way, stay within `dip` of the rival's (each the best of itself
/// and its two neighbours along the way, as the scan's cells alias). The ridge is followed
/// both ways along that line as far as its scores stay within the margin and the dip of
/// the winner's, the rivals are looked for again away from it, and the answer is ambiguous
/// only if one comes within the margin there; otherwise it carries the ridge.
/// Olson ("Real-Time Correlative Scan Matching", ICRA 2009) reads the same shape of the
/// score as the match's uncertainty, not as a second answer. `dip` `None`: [`search`].
///
/// A pose counts as a rival only farther than `rival_beyond_m` from the winner (`None`: 6
/// cells, 30 cm on the rovers' 5 cm grids) or 0.05 rad from its heading: a score that falls
/// slowly round the winner, out to that distance, is one broad peak.
#[allow(clippy::too_many_arguments)]
pub fn search_allowing_ridges(
    map: &PrecomputedMap,
    points: &[Point2],
    prior: Pose2,
    window: &SearchWindow,
    min_score: f64,
    rival_margin: f64,
    dip: Option<f64>,
    rival_beyond_m: Option<f64>,
) -> Option<SearchResult> {
    let rival_cells = rival_beyond_m.map_or(RIVAL_CELLS, |m| (m / map.resolution_m).round() as i64);
    search_rivals(
        map,
        points,
        prior,
        window,
        min_score,
        rival_margin,
        true,
        dip,
        rival_cells,
    )
}

/// [`search`], stopping the rival's search at the first rival closer than `rival_margin`
/// if `stop_when_ambiguous`, else finding the best rival; with `ridge_dip`, as
/// [`search_allowing_ridges`].
#[allow(clippy::too_many_arguments)]
fn search_rivals(
    map: &PrecomputedMap,
    points: &[Point2],
    prior: Pose2,
    window: &SearchWindow,
    min_score: f64,
    rival_margin: f64,
    stop_when_ambiguous: bool,
    ridge_dip: Option<f64>,
    rival_cells: i64,
) -> Option<SearchResult> {
    if points.is_empty() {
        return None;
    }
    let r = map.resolution_m;
    let grid = Discretised::new(map, window);
    let (angle_step, n_angles, n_cells) = (grid.angle_step, grid.n_angles, grid.n_cells);
    // The discretised scan at each heading, in cells relative to the prior's translation.
    let scans: Vec<Vec<(i64, i64)>> = (-n_angles..=n_angles)
        .map(|k| grid.cells(map, points, prior, k))
        .collect();
    // Each heading's bounding box of cells, so that a candidate lying wholly inside the map
    // is scored without a bounds test per point.
    let boxes: Vec<(i64, i64, i64, i64)> = scans
        .iter()
        .map(|cells| {
            cells.iter().fold(
                (i64::MAX, i64::MAX, i64::MIN, i64::MIN),
                |(x0, y0, x1, y1), (x, y)| (x0.min(*x), y0.min(*y), x1.max(*x), y1.max(*y)),
            )
        })
        .collect();
    // Per level and heading, made when first needed (the bound prunes most headings before
    // the finer levels): the scan's cells as offsets into the level's rows from the prior's
    // cell, for candidates wholly inside, and split by where they can fall over the whole
    // window, for candidates that straddle the level's edge.
    let offsets: Vec<Vec<OnceCell<Vec<i64>>>> = lazy_table(map.depth(), scans.len());
    let split: Vec<Vec<OnceCell<SplitScan>>> = lazy_table(map.depth(), scans.len());
    let score_at = |d: usize, c: &Candidate| -> u32 {
        let (x0, y0, x1, y1) = boxes[c.angle];
        let level = map.level(d);
        let (pad, w) = (level.pad, level.width);
        let inside = x0 + c.dx + pad >= 0
            && y0 + c.dy + pad >= 0
            && x1 + c.dx + pad < w
            && y1 + c.dy + pad < level.height;
        if inside {
            let offsets = offsets[d][c.angle]
                .get_or_init(|| scans[c.angle].iter().map(|(x, y)| y * w + x).collect());
            level.sum_at(offsets, c.dx, c.dy)
        } else {
            split[d][c.angle]
                .get_or_init(|| SplitScan::new(&level, &scans[c.angle], n_cells))
                .score(&level, c.dx, c.dy)
        }
    };
    let threshold = (min_score * 255.0 * points.len() as f64).ceil() as u32;
    let top = map.depth();
    let step = 1i64 << top;
    let mut roots = Vec::new();
    for angle in 0..scans.len() {
        let mut dx = -n_cells;
        while dx <= n_cells {
            let mut dy = -n_cells;
            while dy <= n_cells {
                let mut c = Candidate {
                    angle,
                    dx,
                    dy,
                    score: 0,
                };
                c.score = score_at(top, &c);
                roots.push(c);
                dy += step;
            }
            dx += step;
        }
    }
    roots.sort_by_key(|c| std::cmp::Reverse(c.score));

    let mut best: Option<Candidate> = None;
    let n = (255 * points.len()) as f64;
    let mut tree = SearchTree::new(roots, n_cells, &score_at);
    let (anywhere, never_enough) = (|_: &Candidate| true, |_: &Candidate| false);
    tree.descend(
        tree.roots(),
        top,
        threshold,
        &mut best,
        &anywhere,
        &never_enough,
    );
    let winner = best?;
    // The rival: the same search, leaves near the winner excluded.
    let near = |c: &Candidate| {
        (c.dx - winner.dx).abs() <= rival_cells
            && (c.dy - winner.dy).abs() <= rival_cells
            && ((c.angle as f64 - winner.angle as f64) * angle_step).abs() <= RIVAL_RAD
    };
    // Only rivals that come within `rival_margin` matter, and looking for nothing lower
    // lets the bound prune almost everything when the winner stands out. Nor is a rival
    // looked for below `min_score`, so a winner within the margin of it is judged against
    // the rivals above it only. Looking below it too refused a few wrong closures and many
    // more right ones, and the rovers' maps came out worse (sixtieth session, BENCHMARKS.md).
    let rival_threshold = threshold.max(
        winner
            .score
            .saturating_sub((rival_margin * 255.0 * points.len() as f64) as u32),
    );
    // Ambiguous as the caller judges the answer; a better rival would be as ambiguous.
    let winner_score = winner.score as f64 / n;
    let close_rival = |c: &Candidate| ambiguous(winner_score, c.score as f64 / n, rival_margin);
    let mut rival: Option<Candidate> = None;
    tree.descend(
        tree.roots(),
        top,
        rival_threshold,
        &mut rival,
        &|c| !near(c),
        &|c| stop_when_ambiguous && close_rival(c),
    );
    let mut ridge = None;
    let leaf_score = |c: &Candidate| score_at(0, c);
    if let (Some(dip), Some(first)) = (ridge_dip.map(|d| (d * n) as u32), rival)
        && close_rival(&first)
        && on_ridge(&winner, &first, angle_step, dip, &leaf_score)
    {
        // The ridge runs both ways from the winner, as far as its scores stay within the
        // margin (and the dip) of the winner's; a rival off it is a look-alike place.
        let floor = rival_threshold.saturating_sub(dip);
        let ends =
            [1, -1].map(|sign| ridge_end(&winner, &first, sign, n_cells, floor, &leaf_score));
        let mut off_ridge: Option<Candidate> = None;
        tree.descend(
            tree.roots(),
            top,
            rival_threshold,
            &mut off_ridge,
            &|c| !near(c) && !near_segment(&ends[0], &ends[1], c, angle_step),
            &|c| stop_when_ambiguous && close_rival(c),
        );
        if !off_ridge.as_ref().is_some_and(close_rival) {
            let (ex, ey) = ((first.dx - winner.dx) as f64, (first.dy - winner.dy) as f64);
            ridge = Some(Ridge {
                direction_rad: ey.atan2(ex),
                rival_m: ex.hypot(ey) * r,
                drop: winner_score - first.score as f64 / n,
            });
        }
        if ridge.is_some() || off_ridge.as_ref().is_some_and(close_rival) {
            rival = off_ridge;
        }
    }
    let yaw = prior.yaw_rad + (winner.angle as i64 - n_angles) as f64 * angle_step;
    Some(SearchResult {
        pose: Pose2::new(
            prior.x_m + winner.dx as f64 * r,
            prior.y_m + winner.dy as f64 * r,
            yaw,
        ),
        score: winner.score as f64 / n,
        rival_score: rival.map_or(0.0, |c| c.score as f64 / n),
        ridge,
    })
}

/// Whether `rival` lies on a ridge of high scores from `winner`: at the same heading (to
/// within [`RIVAL_RAD`]), and every cell on the straight way between them scores (the
/// best of itself and its neighbours along the way) no more than `dip` below the rival,
/// `score` being the leaf score.
fn on_ridge(
    winner: &Candidate,
    rival: &Candidate,
    angle_step: f64,
    dip: u32,
    score: &dyn Fn(&Candidate) -> u32,
) -> bool {
    if (rival.angle as f64 - winner.angle as f64).abs() * angle_step > RIVAL_RAD {
        return false;
    }
    let steps = (rival.dx - winner.dx)
        .abs()
        .max((rival.dy - winner.dy).abs());
    if steps < 2 {
        return true;
    }
    let at = |k: i64| {
        let f = k as f64 / steps as f64;
        let angle =
            (winner.angle as f64 + f * (rival.angle as f64 - winner.angle as f64)).round() as usize;
        score(&on_line(winner, rival, f, angle))
    };
    let scores: Vec<u32> = (0..=steps).map(at).collect();
    let floor = rival.score.saturating_sub(dip);
    scores.windows(3).all(|w| w[0].max(w[1]).max(w[2]) >= floor)
}

/// The last pose, going from `winner` along the way to `rival` (`sign` 1) or away from it
/// (-1), one step of the larger of its cell offsets at a time, whose score (the best of
/// itself and the next step's, as the scan's cells alias) stays at `floor` or above, within
/// `n_cells` of the window's centre.
fn ridge_end(
    winner: &Candidate,
    rival: &Candidate,
    sign: i64,
    n_cells: i64,
    floor: u32,
    score: &dyn Fn(&Candidate) -> u32,
) -> Candidate {
    let steps = (rival.dx - winner.dx)
        .abs()
        .max((rival.dy - winner.dy).abs())
        .max(1) as f64;
    let at = |k: i64| {
        let mut c = on_line(winner, rival, (sign * k) as f64 / steps, winner.angle);
        if c.dx.abs() > n_cells || c.dy.abs() > n_cells {
            return None;
        }
        c.score = score(&c);
        Some(c)
    };
    let mut last = *winner;
    let mut k = 1;
    while let Some(c) = at(k) {
        let ahead = at(k + 1).map_or(0, |a| a.score);
        if c.score.max(ahead) < floor {
            break;
        }
        last = c;
        k += 1;
    }
    last
}

/// The cell a share `f` of the way from `winner` to `rival` (past the rival above 1, behind
/// the winner below 0), at heading step `angle`, unscored.
fn on_line(winner: &Candidate, rival: &Candidate, f: f64, angle: usize) -> Candidate {
    Candidate {
        angle,
        dx: winner.dx + (f * (rival.dx - winner.dx) as f64).round() as i64,
        dy: winner.dy + (f * (rival.dy - winner.dy) as f64).round() as i64,
        score: 0,
    }
}

/// Whether `c` lies within [`RIVAL_CELLS`] (and [`RIVAL_RAD`] of heading, `angle_step`
/// radians a step) of the straight way from `a` to `b`.
fn near_segment(a: &Candidate, b: &Candidate, c: &Candidate, angle_step: f64) -> bool {
    let turn = |x: &Candidate| x.angle as f64 * angle_step;
    let (lo, hi) = (turn(a).min(turn(b)), turn(a).max(turn(b)));
    if turn(c) < lo - RIVAL_RAD || turn(c) > hi + RIVAL_RAD {
        return false;
    }
    let (ex, ey) = ((b.dx - a.dx) as f64, (b.dy - a.dy) as f64);
    let (px, py) = ((c.dx - a.dx) as f64, (c.dy - a.dy) as f64);
    let len2 = ex * ex + ey * ey;
    let t = if len2 > 0.0 {
        ((px * ex + py * ey) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (qx, qy) = (px - t * ex, py - t * ey);
    qx.abs() <= RIVAL_CELLS as f64 && qy.abs() <= RIVAL_CELLS as f64
}

/// Empty cells for each of `depth + 1` levels and `headings` headings, filled when needed.
fn lazy_table<T>(depth: usize, headings: usize) -> Vec<Vec<OnceCell<T>>> {
    (0..=depth)
        .map(|_| (0..headings).map(|_| OnceCell::new()).collect())
        .collect()
}

/// The branch-and-bound tree of one search, as far as its descents have expanded it. Each
/// expanded node's children are kept, scored and sorted best first, so a later descent over
/// the same window reads them instead of scoring them again: the rival's descent passes
/// through most of the nodes the winner's did (in the rovers' missions four in five of its
/// scorings were of a node the winner's had scored). The scores and their order are the
/// same either way, and so is every answer.
struct SearchTree<'a> {
    /// The roots (sorted best first) and then every expanded node's children.
    nodes: Vec<Candidate>,
    /// Where each node's children lie in `nodes`, once it was expanded.
    children: Vec<Option<std::ops::Range<usize>>>,
    /// How many roots there are.
    roots: usize,
    n_cells: i64,
    score_at: &'a dyn Fn(usize, &Candidate) -> u32,
}

impl<'a> SearchTree<'a> {
    /// A tree of `roots` (sorted best first) only.
    fn new(
        roots: Vec<Candidate>,
        n_cells: i64,
        score_at: &'a dyn Fn(usize, &Candidate) -> u32,
    ) -> Self {
        SearchTree {
            children: vec![None; roots.len()],
            roots: roots.len(),
            nodes: roots,
            n_cells,
            score_at,
        }
    }

    /// The roots' places in `nodes`.
    fn roots(&self) -> std::ops::Range<usize> {
        0..self.roots
    }

    /// The children of node `id` (scored at `depth`, at least 1), scored at `depth - 1` and
    /// sorted best first: at most four, those of its block within the window.
    fn expand(&mut self, id: usize, depth: usize) -> std::ops::Range<usize> {
        if let Some(kept) = &self.children[id] {
            return kept.clone();
        }
        let c = self.nodes[id];
        let half = 1i64 << (depth - 1);
        let first = self.nodes.len();
        for (ox, oy) in [(0, 0), (half, 0), (0, half), (half, half)] {
            let (dx, dy) = (c.dx + ox, c.dy + oy);
            if dx > self.n_cells || dy > self.n_cells {
                continue;
            }
            let mut child = Candidate {
                angle: c.angle,
                dx,
                dy,
                score: 0,
            };
            child.score = (self.score_at)(depth - 1, &child);
            self.nodes.push(child);
            self.children.push(None);
        }
        let range = first..self.nodes.len();
        self.nodes[range.clone()].sort_by_key(|c| std::cmp::Reverse(c.score));
        self.children[id] = Some(range.clone());
        range
    }

    /// Branch and bound below `ids` (nodes sorted best first, scored at `depth`): keeps in
    /// `best` the highest-scoring leaf that `allowed` accepts and beats `threshold`, and
    /// stops (returning `true`) as soon as it keeps one that is `enough`.
    fn descend(
        &mut self,
        ids: std::ops::Range<usize>,
        depth: usize,
        threshold: u32,
        best: &mut Option<Candidate>,
        allowed: &dyn Fn(&Candidate) -> bool,
        enough: &dyn Fn(&Candidate) -> bool,
    ) -> bool {
        for id in ids {
            let c = self.nodes[id];
            let bar = best.as_ref().map_or(threshold, |b| b.score.max(threshold));
            if c.score < bar || (best.is_some() && c.score == bar) {
                // Sorted: nothing after this can win either.
                return false;
            }
            if depth == 0 {
                if allowed(&c) {
                    *best = Some(c);
                    if enough(&c) {
                        return true;
                    }
                }
                continue;
            }
            let children = self.expand(id, depth);
            if self.descend(children, depth - 1, threshold, best, allowed, enough) {
                return true;
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A map with a few walls and posts, and its scan endpoints from a pose.
    fn world() -> Vec<(Point2, Point2)> {
        vec![
            (Point2::new(-4.0, -3.0), Point2::new(5.0, -3.0)),
            (Point2::new(5.0, -3.0), Point2::new(5.0, 4.0)),
            (Point2::new(5.0, 4.0), Point2::new(-1.0, 4.0)),
            (Point2::new(-4.0, -3.0), Point2::new(-4.0, 1.0)),
            (Point2::new(1.0, 0.5), Point2::new(1.6, 0.5)),
            (Point2::new(1.6, 0.5), Point2::new(1.6, 1.5)),
            (Point2::new(-2.0, 2.0), Point2::new(-2.3, 2.6)),
        ]
    }

    fn scan(walls: &[(Point2, Point2)], pose: Pose2) -> Vec<Point2> {
        (0..360)
            .filter_map(|i| {
                let a = (i as f64).to_radians();
                let (dx, dy) = ((pose.yaw_rad + a).cos(), (pose.yaw_rad + a).sin());
                let mut best = f64::INFINITY;
                for (p, q) in walls {
                    let (ex, ey) = (q.x_m - p.x_m, q.y_m - p.y_m);
                    let den = dx * ey - dy * ex;
                    if den.abs() < 1e-12 {
                        continue;
                    }
                    let t = ((p.x_m - pose.x_m) * ey - (p.y_m - pose.y_m) * ex) / den;
                    let u = ((p.x_m - pose.x_m) * dy - (p.y_m - pose.y_m) * dx) / den;
                    if t > 0.0 && (0.0..=1.0).contains(&u) {
                        best = best.min(t);
                    }
                }
                (best < 12.0).then(|| Point2::new(best * a.cos(), best * a.sin()))
            })
            .collect()
    }

    fn map_of(walls: &[(Point2, Point2)], from: &[Pose2]) -> OccupancyGrid {
        let mut g = OccupancyGrid::new(0.05);
        for pose in from {
            let world: Vec<(Point2, bool)> = scan(walls, *pose)
                .iter()
                .map(|p| (pose.transform_point(*p), true))
                .collect();
            for _ in 0..3 {
                g.insert(pose.position(), &world);
            }
        }
        g
    }

    /// Scores every pose of the window by brute force: what branch and bound must equal.
    fn brute_force(
        map: &PrecomputedMap,
        points: &[Point2],
        prior: Pose2,
        window: &SearchWindow,
    ) -> f64 {
        brute_force_where(map, points, prior, window, |_, _, _| true)
    }

    /// The best score, by brute force, of the poses of the window (heading step, x and y
    /// cells from the prior) that `counted` accepts.
    fn brute_force_where(
        map: &PrecomputedMap,
        points: &[Point2],
        prior: Pose2,
        window: &SearchWindow,
        counted: impl Fn(i64, i64, i64) -> bool,
    ) -> f64 {
        let grid = Discretised::new(map, window);
        let (n_a, n_c) = (grid.n_angles, grid.n_cells);
        let mut best = 0u32;
        for k in -n_a..=n_a {
            let cells = grid.cells(map, points, prior, k);
            for dx in -n_c..=n_c {
                for dy in (-n_c..=n_c).filter(|dy| counted(k, dx, *dy)) {
                    let s: u32 = cells
                        .iter()
                        .map(|(x, y)| map.level(0).at(x + dx, y + dy) as u32)
                        .sum();
                    best = best.max(s);
                }
            }
        }
        best as f64 / (255 * points.len()) as f64
    }

    #[test]
    fn finds_the_pose_far_from_the_prior_and_equals_brute_force() {
        let walls = world();
        let grid = map_of(
            &walls,
            &[Pose2::new(0.0, 0.0, 0.0), Pose2::new(2.5, 2.0, 1.0)],
        );
        let map = PrecomputedMap::new(&grid, 5);
        let truth = Pose2::new(1.2, -1.1, 0.3);
        let points = scan(&walls, truth);
        // The prior is 0.9 m and 8 degrees off: far outside a local matcher's basin.
        let prior = Pose2::new(0.5, -0.5, 0.3 - 8f64.to_radians());
        let window = SearchWindow {
            linear_m: 1.0,
            angular_rad: 12f64.to_radians(),
            step_range_m: 6.0,
        };
        let found = search(&map, &points, prior, &window, 0.3, 1.0).expect("a match");
        let err = found.pose.relative_to(&truth);
        assert!(err.x_m.hypot(err.y_m) < 0.08, "{:?}", found.pose);
        assert!(err.yaw_rad.abs() < 1f64.to_radians(), "{:?}", found.pose);
        assert!(found.score > found.rival_score, "{found:?}");
        let exhaustive = brute_force(&map, &points, prior, &window);
        assert!(
            (found.score - exhaustive).abs() < 1e-12,
            "{} vs {exhaustive}",
            found.score
        );
    }

    /// The best score of any pose of the window clearly away (farther than `rival_cells`,
    /// or [`RIVAL_RAD`]) from `winner`, by brute force.
    fn brute_force_rival(
        map: &PrecomputedMap,
        points: &[Point2],
        prior: Pose2,
        window: &SearchWindow,
        winner: Pose2,
        rival_cells: i64,
    ) -> f64 {
        let grid = Discretised::new(map, window);
        let r = map.resolution_m;
        let (wx, wy) = (
            ((winner.x_m - prior.x_m) / r).round() as i64,
            ((winner.y_m - prior.y_m) / r).round() as i64,
        );
        let wk = ((winner.yaw_rad - prior.yaw_rad) / grid.angle_step).round() as i64;
        brute_force_where(map, points, prior, window, |k, dx, dy| {
            let near = (dx - wx).abs() <= rival_cells
                && (dy - wy).abs() <= rival_cells
                && ((k - wk) as f64 * grid.angle_step).abs() <= RIVAL_RAD;
            !near
        })
    }

    /// The rival's descent reads the children the winner's descent scored (see
    /// [`SearchTree`]): the best rival it finds must still be the best of the whole window
    /// away from the winner, in a scene with one answer and in one with many.
    #[test]
    fn the_rival_found_through_the_winners_tree_equals_brute_force() {
        let corridor = vec![
            (Point2::new(-20.0, -1.0), Point2::new(20.0, -1.0)),
            (Point2::new(-20.0, 1.0), Point2::new(20.0, 1.0)),
            (Point2::new(2.0, -1.0), Point2::new(2.0, -0.7)),
        ];
        let scenes = [
            (
                world(),
                Pose2::new(1.2, -1.1, 0.3),
                Pose2::new(0.9, -0.8, 0.25),
            ),
            (
                corridor,
                Pose2::new(1.0, 0.0, 0.0),
                Pose2::new(1.2, 0.1, 0.02),
            ),
        ];
        for (walls, truth, prior) in scenes {
            let grid = map_of(
                &walls,
                &[Pose2::new(0.0, 0.0, 0.0), Pose2::new(2.5, 0.5, 0.5)],
            );
            let map = PrecomputedMap::new(&grid, 5);
            let points = scan(&walls, truth);
            let window = SearchWindow {
                linear_m: 0.8,
                angular_rad: 6f64.to_radians(),
                step_range_m: 6.0,
            };
            // Rivals beyond the usual 30 cm, and beyond 50 cm (a closure into the submaps
            // begun at the known start): the winner is the same, the rival the best of the
            // poses farther away, which can only score as well or less.
            let mut rivals = Vec::new();
            for rival_cells in [RIVAL_CELLS, 10] {
                let found = search_rivals(
                    &map,
                    &points,
                    prior,
                    &window,
                    0.1,
                    1.0,
                    false,
                    None,
                    rival_cells,
                )
                .expect("a match");
                let exhaustive =
                    brute_force_rival(&map, &points, prior, &window, found.pose, rival_cells);
                assert!(found.rival_score > 0.1, "{found:?}");
                assert!(
                    (found.rival_score - exhaustive).abs() < 1e-12,
                    "{rival_cells} cells: {} vs {exhaustive}",
                    found.rival_score
                );
                rivals.push((found.pose, found.rival_score));
            }
            assert_eq!(rivals[0].0, rivals[1].0, "the winner is the same");
            assert!(rivals[1].1 <= rivals[0].1, "{rivals:?}");
        }
    }

    #[test]
    fn a_symmetric_corridor_has_a_rival_as_good_as_the_winner() {
        // Two long parallel walls and nothing else: sliding along them changes nothing.
        let walls = vec![
            (Point2::new(-20.0, -1.0), Point2::new(20.0, -1.0)),
            (Point2::new(-20.0, 1.0), Point2::new(20.0, 1.0)),
        ];
        let grid = map_of(
            &walls,
            &[Pose2::new(0.0, 0.0, 0.0), Pose2::new(3.0, 0.0, 0.0)],
        );
        let map = PrecomputedMap::new(&grid, 5);
        let points = scan(&walls, Pose2::new(1.0, 0.0, 0.0));
        let window = SearchWindow {
            linear_m: 1.0,
            angular_rad: 5f64.to_radians(),
            step_range_m: 6.0,
        };
        let prior = Pose2::new(1.2, 0.1, 0.0);
        let best_rival = search_rivals(
            &map,
            &points,
            prior,
            &window,
            0.3,
            0.1,
            false,
            None,
            RIVAL_CELLS,
        )
        .expect("the corridor matches");
        assert!(
            best_rival.score - best_rival.rival_score < 0.02,
            "the corridor must look ambiguous: {best_rival:?}"
        );
        // The search that stops at the first rival within the margin judges it the same.
        let found = search(&map, &points, prior, &window, 0.3, 0.1).expect("the corridor matches");
        assert_eq!(found.pose, best_rival.pose);
        assert!(found.is_ambiguous(0.1), "{found:?}");
    }

    /// A corridor's two long walls and, at `posts` along the lower one, square posts 0.3 m
    /// a side: what pins the pose along the corridor.
    fn corridor_with_posts(posts: &[f64]) -> Vec<(Point2, Point2)> {
        let mut walls = vec![
            (Point2::new(-20.0, -1.5), Point2::new(20.0, -1.5)),
            (Point2::new(-20.0, 1.5), Point2::new(20.0, 1.5)),
        ];
        for x in posts {
            let (x0, x1, y0, y1) = (x - 0.15, x + 0.15, -1.5, -1.2);
            walls.push((Point2::new(x0, y0), Point2::new(x0, y1)));
            walls.push((Point2::new(x0, y1), Point2::new(x1, y1)));
            walls.push((Point2::new(x1, y1), Point2::new(x1, y0)));
        }
        walls
    }

    /// The search with ridges allowed (dip 0.02) in `walls` mapped from two poses, for a
    /// scan from `truth` searched from 0.2 m off it, with margin 0.08.
    fn ridge_search(walls: &[(Point2, Point2)], truth: Pose2) -> (SearchResult, SearchResult) {
        let grid = map_of(
            walls,
            &[Pose2::new(0.0, 0.0, 0.0), Pose2::new(1.5, 0.0, 0.0)],
        );
        let map = PrecomputedMap::new(&grid, 5);
        let points = scan(walls, truth);
        let window = SearchWindow {
            linear_m: 1.0,
            angular_rad: 4f64.to_radians(),
            step_range_m: 6.0,
        };
        let prior = Pose2::new(truth.x_m + 0.2, truth.y_m - 0.05, truth.yaw_rad);
        let plain = search(&map, &points, prior, &window, 0.3, 0.08).expect("a match");
        let ridged =
            search_allowing_ridges(&map, &points, prior, &window, 0.3, 0.08, Some(0.02), None)
                .expect("a match");
        assert_eq!(plain.pose, ridged.pose, "the winner is the same either way");
        (plain, ridged)
    }

    #[test]
    fn a_lone_post_in_a_corridor_makes_a_ridge_not_a_rival() {
        // The corridor's walls score alike all along it; one post lifts the score where it
        // matches, and falls off smoothly on either side: one answer, loosely pinned along.
        let truth = Pose2::new(0.7, 0.1, 0.0);
        let (plain, ridged) = ridge_search(&corridor_with_posts(&[0.0]), truth);
        assert!(plain.is_ambiguous(0.08), "{plain:?}");
        assert!(!ridged.is_ambiguous(0.08), "{ridged:?}");
        let ridge = ridged.ridge.expect("a ridge");
        assert!(
            ridge.direction_rad.sin().abs() < 0.2,
            "the ridge runs along the corridor: {ridge:?}"
        );
        assert!(ridge.drop > 0.0 && ridge.drop < 0.08, "{ridge:?}");
        let err = ridged.pose.relative_to(&truth);
        assert!(err.x_m.hypot(err.y_m) < 0.1, "{:?}", ridged.pose);
    }

    #[test]
    fn posts_repeating_along_a_corridor_stay_ambiguous_with_ridges_allowed() {
        // Posts every 0.8 m: the pose one period along matches as well, and between the
        // two the posts miss, so the score dips: a look-alike place, not a ridge.
        let posts: Vec<f64> = (-10..=10).map(|k| k as f64 * 0.8).collect();
        let (plain, ridged) = ridge_search(&corridor_with_posts(&posts), Pose2::new(0.3, 0.1, 0.0));
        assert!(plain.is_ambiguous(0.08), "{plain:?}");
        assert!(ridged.is_ambiguous(0.08), "{ridged:?}");
        assert_eq!(ridged.ridge, None);
    }

    #[test]
    fn stopping_at_the_first_close_rival_changes_no_verdict() {
        // The corridor (ambiguous), the room with posts (not), and the room seen from
        // priors a little and far off, at margins from strict to lax.
        let corridor = vec![
            (Point2::new(-20.0, -1.0), Point2::new(20.0, -1.0)),
            (Point2::new(-20.0, 1.0), Point2::new(20.0, 1.0)),
        ];
        let room = world();
        let window = SearchWindow {
            linear_m: 1.0,
            angular_rad: 6f64.to_radians(),
            step_range_m: 6.0,
        };
        let (mut ambiguous, mut clear, mut stopped_early) = (0, 0, 0);
        for (walls, seen_from) in [
            (&corridor, Pose2::new(1.0, 0.0, 0.0)),
            (&room, Pose2::new(0.5, 0.2, 0.1)),
            (&room, Pose2::new(-1.0, 1.0, -0.4)),
        ] {
            let grid = map_of(
                walls,
                &[Pose2::new(0.0, 0.0, 0.0), Pose2::new(3.0, 0.0, 0.0)],
            );
            let map = PrecomputedMap::new(&grid, 5);
            let points = scan(walls, seen_from);
            for (ox, oy, oyaw) in [(0.2, 0.1, 0.0), (-0.6, 0.5, 0.05), (0.7, -0.8, -0.08)] {
                let prior = Pose2::new(
                    seen_from.x_m + ox,
                    seen_from.y_m + oy,
                    seen_from.yaw_rad + oyaw,
                );
                for margin in [0.01, 0.05, 0.1, 0.3] {
                    let early = search(&map, &points, prior, &window, 0.3, margin);
                    let full = search_rivals(
                        &map,
                        &points,
                        prior,
                        &window,
                        0.3,
                        margin,
                        false,
                        None,
                        RIVAL_CELLS,
                    );
                    let (Some(early), Some(full)) = (early, full) else {
                        assert_eq!(early.is_some(), full.is_some());
                        continue;
                    };
                    assert_eq!(early.pose, full.pose);
                    assert_eq!(early.score, full.score);
                    let verdict = |r: &SearchResult| r.is_ambiguous(margin);
                    assert_eq!(verdict(&early), verdict(&full), "{early:?} {full:?}");
                    if verdict(&full) {
                        ambiguous += 1;
                        stopped_early += usize::from(early.rival_score != full.rival_score);
                    } else {
                        clear += 1;
                        assert_eq!(early.rival_score, full.rival_score);
                    }
                }
            }
        }
        assert!(
            ambiguous > 3 && clear > 3 && stopped_early > 0,
            "{ambiguous} ambiguous ({stopped_early} stopped early), {clear} clear"
        );
    }

    #[test]
    fn every_level_holds_the_highest_cell_of_its_block() {
        let mut grid = OccupancyGrid::new(0.05);
        let sensor = Point2::new(0.0, 0.0);
        let ends: Vec<(Point2, bool)> = (0..90)
            .map(|i| {
                let a = (i as f64 * 4.0).to_radians();
                let r = 1.0 + 0.7 * ((i * 7) % 5) as f64;
                (Point2::new(r * a.cos(), r * a.sin()), i % 3 != 0)
            })
            .collect();
        grid.insert(sensor, &ends);
        for margin in [0, 7] {
            let map = PrecomputedMap::with_margin(&grid, 4, margin);
            let base = map.level(0);
            for d in 1..=4usize {
                let level = map.level(d);
                let block = 1i64 << d;
                for y in -level.pad - 2..map.height + margin as i64 + 2 {
                    for x in -level.pad - 2..map.width + margin as i64 + 2 {
                        let brute = (0..block)
                            .flat_map(|dy| (0..block).map(move |dx| (dx, dy)))
                            .map(|(dx, dy)| base.at(x + dx, y + dy))
                            .max()
                            .unwrap_or(UNKNOWN);
                        assert_eq!(
                            level.at(x, y),
                            brute,
                            "level {d}, margin {margin}, ({x}, {y})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_split_scan_scores_as_every_point_looked_up_on_every_level() {
        let walls = world();
        let grid = map_of(&walls, &[Pose2::new(0.0, 0.0, 0.0)]);
        let map = PrecomputedMap::with_margin(&grid, 4, 3);
        // Points inside, near the edges and far outside the map (its walls span 9 x 7 m).
        let cells: Vec<(i64, i64)> = (-300..300)
            .step_by(7)
            .flat_map(|x| (-250..250).step_by(11).map(move |y| (x, y)))
            .collect();
        let n_cells = 20;
        for d in 0..=map.depth() {
            let level = map.level(d);
            let split = SplitScan::new(&level, &cells, n_cells);
            assert!(split.outside > 0 && !split.inside.is_empty() && !split.near_edge.is_empty());
            for (dx, dy) in [(-20, -20), (-20, 20), (0, 0), (7, -13), (20, 20), (20, -5)] {
                let looked_up: u32 = cells
                    .iter()
                    .map(|(x, y)| level.at(x + dx, y + dy) as u32)
                    .sum();
                assert_eq!(
                    split.score(&level, dx, dy),
                    looked_up,
                    "level {d} at ({dx}, {dy})"
                );
            }
        }
    }
}
