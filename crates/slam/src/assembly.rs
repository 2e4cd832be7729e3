//! The whole map assembled from submaps, kept current incrementally.
//!
//! Drawing every submap at its optimised pose from scratch costs seconds once a map holds a
//! few hundred submaps, far too much for a rover that wants its map every few seconds to
//! plan on. Log-odds add, so the assembly keeps the sum of the finished submaps (which no
//! longer change) and only redraws one when the pose graph has moved it, by taking it out at
//! its old pose and putting it in at the new one; submaps still being built are drawn onto a
//! copy when the map is asked for. Sums are kept unclamped so taking a submap out is exact.
//!
//! A rover asks for its map every few seconds, and drawing its active submaps (which span
//! ten metres of driving and the lidar's reach around it, half the map) each time cost more
//! than the rest of its SLAM. So the occupancy map is also kept *live*
//! ([`Assembly::live_states`]): each active submap has a shadow in the assembly's cells,
//! drawn from the submap once and then updated by tracing each new scan into it as the scan
//! goes into the submap, and every cell's state is kept current as its evidence changes. A
//! shadow is drawn afresh from its submap only when the pose graph moves the submap, and
//! replaced by the exact drawing when the submap is finished.

use crate::occupancy::{
    CellState, Lattice, MissRule, OccupancyGrid, beams_box, corner_before, far_off, growth, regrow,
    trace_beams, updated_log_odds,
};
use realms_core::{Grid, GridGeometry, Point2, Pose2};

/// A submap is redrawn when its pose moved more than this, metres ...
const REDRAW_SHIFT_M: f64 = 0.02;
/// ... or turned more than this (2 cm at 10 m), radians. Every optimisation after a loop
/// closure nudges most submaps by a few centimetres, and redrawing them costs an eighth of
/// a rover's SLAM; but the map is graded within one 5 cm cell of the truth, so a submap
/// drawn a cell off would cost that agreement (BENCHMARKS.md).
const REDRAW_TURN_RAD: f64 = 0.002;
/// Fractional bits of the fixed-point sample positions [`Assembly::draw`] steps.
const FIXED_BITS: u32 = 32;
/// One submap cell in those positions.
const FIXED_ONE: f64 = (1u64 << FIXED_BITS) as f64;
/// Cells added on each side when the assembly grows.
const GROW_MARGIN_CELLS: usize = 64;
/// Summed log-odds above which a cell counts as occupied by default: as in one submap
/// ([`CellState::from_log_odds`]).
pub const OCCUPIED_ABOVE: f32 = 0.5;

/// Log-odds evidence summed over submaps on one growable grid.
#[derive(Clone, Debug)]
pub struct Assembly {
    resolution_m: f64,
    origin: Point2,
    width: usize,
    height: usize,
    sum: Vec<f32>,
    /// Where each submap (by index) was drawn into `sum`, if it was.
    placed: Vec<Option<Pose2>>,
    /// What a submap cell's log-odds contribute to the sum.
    weigh: Weigh,
    /// How traced scans clear cells: as the submaps do.
    miss_rule: MissRule,
    /// Summed log-odds above which a cell counts as occupied.
    occupied_above: f32,
    /// The live map, once asked for.
    live: Option<Live>,
    /// The state of every cell of the finished submaps' sum, for [`Assembly::states`], kept
    /// until the sum changes: the hazard layers are asked for every few seconds, and their
    /// sum moves only when the pose graph moves a layer.
    summed: Option<Vec<CellState>>,
    /// [`Assembly::states`]' scratch: each cell's sum with the active submaps added, where
    /// they reach (NaN elsewhere, between calls everywhere).
    with_active: Vec<f32>,
    /// The grid is only the unknown cells put at the origin when a map was asked for before
    /// anything was drawn. It moves to where content first lands if that lies far off
    /// (`occupancy::MAX_STRETCH_M`) instead of stretching to it: a rover whose wheels count
    /// from 800 km out would otherwise grow a grid spanning the 800 km.
    placeholder: bool,
}

/// What a submap cell's log-odds contribute to an assembly's sum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Weigh {
    /// Themselves: evidence adds up.
    LogOdds,
    /// [`hazard_vote`].
    HazardVote,
}

/// Cells on a side of the square tiles the live map counts its changes in.
pub const LIVE_TILE_CELLS: usize = 32;

/// The active submaps' shadows and their sum, and every cell's state: that of the finished
/// submaps' sum with the shadows' added.
#[derive(Clone, Debug)]
struct Live {
    shadow_sum: Vec<f32>,
    states: Vec<CellState>,
    shadows: Vec<Shadow>,
    width: usize,
    /// Tiles per row.
    tiles_wide: usize,
    /// The version in which a cell of each tile (row-major) last changed state.
    tile_version: Vec<u64>,
    /// The version changes are stamped with now: one more than the last handed out.
    version: u64,
    /// Summed log-odds above which a cell counts as occupied.
    occupied_above: f32,
}

/// The live map as it is now, and where it changed ([`Assembly::live_states`]).
#[derive(Clone, Copy, Debug)]
pub struct LiveView<'a> {
    /// Where the cells lie.
    pub geometry: GridGeometry,
    /// Every cell's state, row-major from the grid's origin.
    pub states: &'a [CellState],
    /// This view's version: a later view changed only the tiles
    /// [`changed_since`](LiveView::changed_since) this one names.
    pub version: u64,
    tiles_wide: usize,
    tile_version: &'a [u64],
}

impl LiveView<'_> {
    /// Whether a cell of tile (`tx`, `ty`) (cells `tx * LIVE_TILE_CELLS ..`, likewise for
    /// `ty`) may have changed state since the view of version `since`. Views of different
    /// geometries share no versions: redraw everything when the geometry changed.
    pub fn changed_since(&self, tx: usize, ty: usize, since: u64) -> bool {
        self.tile_version
            .get(ty * self.tiles_wide + tx)
            .is_none_or(|v| *v > since)
    }

    /// Whether any cell may have changed state since the view of version `since` (of the
    /// same geometry).
    pub fn changed_anywhere_since(&self, since: u64) -> bool {
        self.tile_version.iter().any(|v| *v > since)
    }
}

/// An active submap's log-odds in the assembly's cells.
#[derive(Clone, Debug)]
struct Shadow {
    /// The submap's index.
    index: usize,
    /// The submap's pose when the shadow was drawn or started.
    pose: Pose2,
    cells: Vec<f32>,
}

impl Live {
    /// No shadows over the finished submaps' sum `finished` (`width` x `height` cells).
    fn new(finished: &[f32], width: usize, height: usize, occupied_above: f32) -> Self {
        let tiles_wide = width.div_ceil(LIVE_TILE_CELLS);
        Live {
            states: finished
                .iter()
                .map(|&l| summed_state(l, occupied_above))
                .collect(),
            shadow_sum: vec![0.0; finished.len()],
            shadows: Vec::new(),
            width,
            tiles_wide,
            tile_version: vec![1; tiles_wide * height.div_ceil(LIVE_TILE_CELLS)],
            version: 1,
            occupied_above,
        }
    }

    /// Adds `delta` to cell `i`'s shadow evidence and brings its state up to date.
    fn add(&mut self, finished: &[f32], i: usize, delta: f32) {
        self.shadow_sum[i] += delta;
        self.restate(finished, i);
    }

    /// Brings cell `i`'s state up to date with its evidence (`finished`: the finished
    /// submaps' sum), noting its tile if it changed.
    fn restate(&mut self, finished: &[f32], i: usize) {
        restate(
            [finished, &self.shadow_sum],
            &mut self.states,
            &mut self.tile_version,
            [self.width, self.tiles_wide],
            self.version,
            self.occupied_above,
            i,
        );
    }
}

/// [`Live::restate`] on borrowed parts (`sums`: the finished submaps' and the shadows';
/// `shape`: cells and tiles per row).
fn restate(
    sums: [&[f32]; 2],
    states: &mut [CellState],
    tile_version: &mut [u64],
    shape: [usize; 2],
    version: u64,
    occupied_above: f32,
    i: usize,
) {
    let state = summed_state(sums[0][i] + sums[1][i], occupied_above);
    if state != states[i] {
        states[i] = state;
        let [width, tiles_wide] = shape;
        let (x, y) = (i % width, i / width);
        tile_version[(y / LIVE_TILE_CELLS) * tiles_wide + x / LIVE_TILE_CELLS] = version;
    }
}

impl Assembly {
    /// An empty assembly of `resolution_m` cells.
    pub fn new(resolution_m: f64) -> Self {
        Assembly::weighing(resolution_m, Weigh::LogOdds)
    }

    /// An empty assembly of hazard layers, `resolution_m` cells: each submap's layer
    /// contributes its [`hazard_vote`] per cell, not its log-odds.
    pub fn hazard_votes(resolution_m: f64) -> Self {
        Assembly::weighing(resolution_m, Weigh::HazardVote)
    }

    /// The assembly tracing scans with `rule` (the submaps' own).
    pub fn with_miss_rule(mut self, rule: MissRule) -> Self {
        self.miss_rule = rule;
        self
    }

    /// The assembly counting a cell occupied only once its summed log-odds exceed
    /// `occupied_above` (by default [`OCCUPIED_ABOVE`]); cells between that and 0.5 are
    /// unknown. A stray hit drawn where no later beam passes stays otherwise. Set before
    /// the live map is first asked for: its states and versions are not redone.
    pub fn with_occupied_above(mut self, occupied_above: f32) -> Self {
        debug_assert!(self.live.is_none(), "set before the live map exists");
        self.occupied_above = occupied_above;
        self.summed = None;
        self
    }

    fn weighing(resolution_m: f64, weigh: Weigh) -> Self {
        Assembly {
            resolution_m,
            origin: Point2::new(0.0, 0.0),
            width: 0,
            height: 0,
            sum: Vec::new(),
            placed: Vec::new(),
            weigh,
            miss_rule: MissRule::default(),
            occupied_above: OCCUPIED_ABOVE,
            live: None,
            summed: None,
            with_active: Vec::new(),
            placeholder: false,
        }
    }

    /// Cell edge, metres.
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    fn geometry(&self) -> GridGeometry {
        GridGeometry {
            width: self.width,
            height: self.height,
            resolution_m: self.resolution_m,
            origin: self.origin,
        }
    }

    /// Grows the grid so the world box `[min, max]` lies inside it.
    fn ensure(&mut self, min: Point2, max: Point2) {
        let r = self.resolution_m;
        // The placeholder holds nothing (no evidence, unknown): moved, it is still that.
        // Content near it grows it as any grid.
        let moved = std::mem::take(&mut self.placeholder) && far_off(&self.geometry(), min, max);
        if self.width == 0 || moved {
            self.origin = corner_before(min, r, GROW_MARGIN_CELLS);
        }
        if moved && let Some(live) = &mut self.live {
            // A new geometry: every tile counts as changed.
            live.tile_version.fill(live.version);
        }
        let (w, h) = (self.width, self.height);
        let Some(g) = growth(self.origin, r, w, h, min, max, GROW_MARGIN_CELLS) else {
            return;
        };
        self.sum = regrow(&self.sum, w, h, g, 0.0);
        self.summed = None;
        if let Some(live) = &mut self.live {
            let (w2, h2) = (w + g[0] + g[2], h + g[1] + g[3]);
            live.shadow_sum = regrow(&live.shadow_sum, w, h, g, 0.0);
            live.states = regrow(&live.states, w, h, g, CellState::Unknown);
            for shadow in &mut live.shadows {
                shadow.cells = regrow(&shadow.cells, w, h, g, 0.0);
            }
            live.width = w2;
            live.tiles_wide = w2.div_ceil(LIVE_TILE_CELLS);
            // A new geometry: every tile counts as changed.
            live.tile_version = vec![live.version; live.tiles_wide * h2.div_ceil(LIVE_TILE_CELLS)];
        }
        self.origin = Point2::new(
            self.origin.x_m - g[0] as f64 * r,
            self.origin.y_m - g[1] as f64 * r,
        );
        self.width = w + g[0] + g[2];
        self.height = h + g[1] + g[3];
    }

    /// Samples `grid` placed at `pose` at each of this assembly's cell centres, calling
    /// `visit(cell index, weighed value)` for every cell where the sample is not zero.
    fn draw(&self, grid: &OccupancyGrid, pose: Pose2, visit: impl FnMut(usize, f32)) {
        // One loop per weighing, so the per-cell weighing is inlined, not called through a
        // pointer (drawing submaps is most of what keeping the map costs).
        match self.weigh {
            Weigh::LogOdds => self.draw_weighed(grid, pose, |l| l, visit),
            Weigh::HazardVote => self.draw_weighed(grid, pose, hazard_vote, visit),
        }
    }

    fn draw_weighed(
        &self,
        grid: &OccupancyGrid,
        pose: Pose2,
        weigh: impl Fn(f32) -> f32,
        mut visit: impl FnMut(usize, f32),
    ) {
        let Some((min, max)) = placed_box(grid, pose) else {
            return;
        };
        if self.width == 0 {
            return;
        }
        let r = self.resolution_m;
        let cell = |v: f64, o: f64| ((v - o) / r).floor();
        let x0 = cell(min.x_m, self.origin.x_m).max(0.0) as usize;
        let y0 = cell(min.y_m, self.origin.y_m).max(0.0) as usize;
        let x1 = (cell(max.x_m, self.origin.x_m) as usize).min(self.width.saturating_sub(1));
        let y1 = (cell(max.y_m, self.origin.y_m) as usize).min(self.height.saturating_sub(1));
        let g = grid.geometry();
        // A finished submap keeps only its content's cells; every other cell holds 0, which
        // is passed over anyway.
        let (kept, src) = grid.kept_log_odds();
        let inv = pose.inverse();
        let (c, s) = (inv.yaw_rad.cos(), inv.yaw_rad.sin());
        // Stepping one target cell along x moves the sample by (c, s) * r in the submap.
        // Positions are stepped in fixed point (32 fractional bits of a submap cell), so a
        // cell's index is two shifts and a sample outside the submap is an unsigned
        // comparison: about twice as fast as floats (BENCHMARKS.md), and a sample moves by
        // under a millionth of a cell across a whole row.
        let fixed = |v: f64| (v * FIXED_ONE).floor() as i64;
        let (dx, dy) = (fixed(c * r / g.resolution_m), fixed(s * r / g.resolution_m));
        // The submap's content box in its own cells, a cell wider on each side: a row's
        // samples outside it read zeros, so each row is cut to the stretch that can fall
        // inside (the placed box's corners hold half its cells for a square submap turned 45
        // degrees).
        let Some((lo, hi)) = grid.content_bounds() else {
            return;
        };
        let content_x = (
            (lo.x_m - g.origin.x_m) / g.resolution_m - 1.0,
            (hi.x_m - g.origin.x_m) / g.resolution_m + 1.0,
        );
        let content_y = (
            (lo.y_m - g.origin.y_m) / g.resolution_m - 1.0,
            (hi.y_m - g.origin.y_m) / g.resolution_m + 1.0,
        );
        let (span_lo, span_hi) = (0i64, (x1 - x0) as i64);
        for y in y0..=y1 {
            let row0 = Point2::new(
                self.origin.x_m + (x0 as f64 + 0.5) * r,
                self.origin.y_m + (y as f64 + 0.5) * r,
            );
            let p = inv.transform_point(row0);
            let lx = fixed((p.x_m - g.origin.x_m) / g.resolution_m);
            let ly = fixed((p.y_m - g.origin.y_m) / g.resolution_m);
            let (mut k_lo, mut k_hi) = (span_lo, span_hi);
            for (start, step, (c_lo, c_hi)) in [(lx, dx, content_x), (ly, dy, content_y)] {
                let (k_a, k_b) = steps_within(start, step, c_lo * FIXED_ONE, c_hi * FIXED_ONE);
                k_lo = k_lo.max(k_a);
                k_hi = k_hi.min(k_b);
            }
            if k_lo > k_hi {
                continue;
            }
            let mut lx = lx + k_lo * dx;
            let mut ly = ly + k_lo * dy;
            let row = y * self.width;
            for x in x0 + k_lo as usize..=x0 + k_hi as usize {
                // A negative position wraps to a huge cell, outside like any other.
                let (cx, cy) = ((lx as u64) >> FIXED_BITS, (ly as u64) >> FIXED_BITS);
                if let Some(i) = kept.index(cx as usize, cy as usize) {
                    let v = src[i];
                    if v != 0.0 {
                        visit(row + x, weigh(v));
                    }
                }
                lx += dx;
                ly += dy;
            }
        }
    }

    /// Adds `sign` times `grid` at `pose` to the sum (and brings the live map's states up
    /// to date, if there is one: only cells whose sum changed can change state).
    fn add(&mut self, grid: &OccupancyGrid, pose: Pose2, sign: f32) {
        self.summed = None;
        let mut sum = std::mem::take(&mut self.sum);
        let mut live = self.live.take();
        self.draw(grid, pose, |i, v| {
            sum[i] += sign * v;
            if let Some(live) = &mut live {
                live.restate(&sum, i);
            }
        });
        self.sum = sum;
        self.live = live;
    }

    fn grow_for(&mut self, grid: &OccupancyGrid, pose: Pose2) {
        if let Some((min, max)) = placed_box(grid, pose) {
            self.ensure(min, max);
        }
    }

    /// Makes the sum hold finished submap `index` (`grid`, unchanging from now on) at `pose`,
    /// redrawing it only if it moved.
    pub fn place(&mut self, index: usize, grid: &OccupancyGrid, pose: Pose2) {
        if self.placed.len() <= index {
            self.placed.resize(index + 1, None);
        }
        if let Some(old) = self.placed[index] {
            let d = pose.relative_to(&old);
            if d.x_m.hypot(d.y_m) <= REDRAW_SHIFT_M && d.yaw_rad.abs() <= REDRAW_TURN_RAD {
                return;
            }
            self.remove(index, grid);
        }
        // A submap just finished: its exact drawing replaces its shadow.
        self.drop_shadow(index);
        self.grow_for(grid, pose);
        self.add(grid, pose, 1.0);
        self.placed[index] = Some(pose);
    }

    /// Takes submap `index` (whose grid must be what was placed) out of the sum.
    pub fn remove(&mut self, index: usize, grid: &OccupancyGrid) {
        let Some(Some(old)) = self.placed.get(index).copied() else {
            return;
        };
        self.add(grid, old, -1.0);
        self.placed[index] = None;
    }

    /// Takes active submap `index`'s shadow out of the live map, if it has one.
    fn drop_shadow(&mut self, index: usize) {
        let Some(live) = &mut self.live else {
            return;
        };
        let Some(k) = live.shadows.iter().position(|s| s.index == index) else {
            return;
        };
        let shadow = live.shadows.swap_remove(k);
        for (i, v) in shadow.cells.iter().enumerate() {
            if *v != 0.0 {
                live.add(&self.sum, i, -v);
            }
        }
    }

    /// Makes the live map hold active submap `index` (`grid`) at `pose`: draws its shadow
    /// if it has none or the submap moved since it was drawn.
    fn track(&mut self, index: usize, grid: &OccupancyGrid, pose: Pose2) {
        if let Some(live) = &self.live
            && let Some(shadow) = live.shadows.iter().find(|s| s.index == index)
        {
            let d = pose.relative_to(&shadow.pose);
            if d.x_m.hypot(d.y_m) <= REDRAW_SHIFT_M && d.yaw_rad.abs() <= REDRAW_TURN_RAD {
                return;
            }
        }
        self.drop_shadow(index);
        self.grow_for(grid, pose);
        let mut cells = vec![0.0; self.sum.len()];
        let Some(mut live) = self.live.take() else {
            return;
        };
        let sum = &self.sum;
        self.draw(grid, pose, |i, v| {
            cells[i] += v;
            live.add(sum, i, v);
        });
        live.shadows.push(Shadow { index, pose, cells });
        self.live = Some(live);
    }

    /// Traces one scan, just inserted into each of the active submaps `into` (index and
    /// pose), into the live map: beams from `sensor` to each endpoint, in the assembly's
    /// frame. Does nothing until the live map is first asked for.
    pub fn trace(&mut self, into: &[(usize, Pose2)], sensor: Point2, endpoints: &[(Point2, bool)]) {
        if self.live.is_none() || endpoints.is_empty() || into.is_empty() {
            return;
        }
        let (min, max) = beams_box(sensor, endpoints);
        self.ensure(min, max);
        let lattice = Lattice {
            origin: self.origin,
            resolution_m: self.resolution_m,
            width: self.width,
        };
        let cells = self.sum.len();
        let Some(live) = &mut self.live else {
            return;
        };
        for (index, pose) in into {
            if !live.shadows.iter().any(|s| s.index == *index) {
                // A submap started since the live map was last asked for: it was empty.
                live.shadows.push(Shadow {
                    index: *index,
                    pose: *pose,
                    cells: vec![0.0; cells],
                });
            }
        }
        let shape = [live.width, live.tiles_wide];
        let finished = &self.sum;
        let Live {
            shadow_sum,
            states,
            shadows,
            tile_version,
            version,
            occupied_above,
            ..
        } = live;
        let mut targets: Vec<&mut Vec<f32>> = shadows
            .iter_mut()
            .filter(|s| into.iter().any(|(i, _)| *i == s.index))
            .map(|s| &mut s.cells)
            .collect();
        // One walk along each beam for every shadow it goes into.
        trace_beams(
            &lattice,
            sensor,
            endpoints,
            None,
            // The live map is the published one: every beam clears up to its hit, whatever
            // margin the submaps match on.
            (self.miss_rule, None),
            |i, delta| {
                let mut change = 0.0;
                for shadow in targets.iter_mut() {
                    let before = shadow[i];
                    let after = updated_log_odds(before, delta);
                    shadow[i] = after;
                    change += after - before;
                }
                if change != 0.0 {
                    shadow_sum[i] += change;
                    restate(
                        [finished, shadow_sum],
                        states,
                        tile_version,
                        shape,
                        *version,
                        *occupied_above,
                        i,
                    );
                }
            },
        );
    }

    /// The live map: the finished submaps' sum with the `active` submaps (index, grid, pose)
    /// on top, as their shadows. The first call draws the shadows; later ones redraw only the
    /// shadows of submaps that moved.
    pub fn live_states(&mut self, active: &[(usize, &OccupancyGrid, Pose2)]) -> LiveView<'_> {
        for (_, grid, pose) in active {
            self.grow_for(grid, *pose);
        }
        if self.width == 0 {
            // Nothing drawn yet: a patch of unknown cells about the frame's zero, until
            // something is.
            self.ensure(Point2::new(0.0, 0.0), Point2::new(0.0, 0.0));
            self.placeholder = true;
        }
        if self.live.is_none() {
            self.live = Some(Live::new(
                &self.sum,
                self.width,
                self.height,
                self.occupied_above,
            ));
        }
        let stale: Vec<usize> = self
            .live
            .iter()
            .flat_map(|l| &l.shadows)
            .map(|s| s.index)
            .filter(|i| !active.iter().any(|(a, _, _)| a == i))
            .collect();
        for index in stale {
            self.drop_shadow(index);
        }
        for (index, grid, pose) in active {
            self.track(*index, grid, *pose);
        }
        let geometry = self.geometry();
        let live = self.live.as_mut().expect("made above");
        let version = live.version;
        live.version += 1;
        LiveView {
            geometry,
            states: &live.states,
            version,
            tiles_wide: live.tiles_wide,
            tile_version: &live.tile_version,
        }
    }

    /// The assembled log-odds: the finished submaps' sum with the `active` submaps (still
    /// changing) drawn on top.
    pub fn render(&mut self, active: &[(&OccupancyGrid, Pose2)]) -> OccupancyGrid {
        for (grid, pose) in active {
            self.grow_for(grid, *pose);
        }
        if self.width == 0 {
            return OccupancyGrid::new(self.resolution_m);
        }
        let mut sum = self.sum.clone();
        for (grid, pose) in active {
            self.draw(grid, *pose, |i, v| sum[i] += v);
        }
        OccupancyGrid::from_log_odds(self.geometry(), sum).expect("one value per cell")
    }

    /// The cell states of [`render`](Self::render) without computing probabilities.
    pub fn states(&mut self, active: &[(&OccupancyGrid, Pose2)]) -> Grid<CellState> {
        for (grid, pose) in active {
            self.grow_for(grid, *pose);
        }
        if self.width == 0 {
            // Nothing drawn yet: a patch of unknown cells about the frame's zero, until
            // something is.
            self.ensure(Point2::new(0.0, 0.0), Point2::new(0.0, 0.0));
            self.placeholder = true;
        }
        let occupied_above = self.occupied_above;
        let sum = &self.sum;
        let mut cells = self
            .summed
            .get_or_insert_with(|| {
                sum.iter()
                    .map(|&l| summed_state(l, occupied_above))
                    .collect()
            })
            .clone();
        // The active submaps added to the sum, in order, in the cells they reach: the same
        // sums, rounded the same way, as adding them to a copy of the whole sum.
        let mut with_active = std::mem::take(&mut self.with_active);
        with_active.resize(sum.len(), f32::NAN);
        let mut reached = Vec::new();
        for (grid, pose) in active {
            self.draw(grid, *pose, |i, v| {
                if with_active[i].is_nan() {
                    with_active[i] = sum[i];
                    reached.push(i);
                }
                with_active[i] += v;
            });
        }
        for i in reached {
            cells[i] = summed_state(with_active[i], occupied_above);
            with_active[i] = f32::NAN;
        }
        self.with_active = with_active;
        Grid::from_cells(self.geometry(), cells).expect("one state per cell")
    }
}

/// The state of a cell whose submaps' log-odds sum to `l`: occupied above `occupied_above`,
/// free below -0.5 (as [`CellState::from_log_odds`]), unknown between.
fn summed_state(l: f32, occupied_above: f32) -> CellState {
    if l > occupied_above {
        CellState::Occupied
    } else if l < -0.5 {
        CellState::Free
    } else {
        CellState::Unknown
    }
}

/// Safety first, for hazard layers: a layer that holds a cell hazardous outvotes any number
/// of layers that hold it safe (a low rock seen from afar and judged flat must not hide the
/// rock seen close by later), and a cell is safe only when some layer says so and none
/// says hazard. Undecided cells do not vote.
pub fn hazard_vote(l: f32) -> f32 {
    if l > 0.5 {
        1000.0
    } else if l < -0.5 {
        -1.0
    } else {
        0.0
    }
}

/// The steps `k` (a superset, by a step or so either way) at which `start + k * step`
/// lies within `[lo, hi]`, all in the same units: all of them when `step` is zero and
/// `start` lies within, none (an empty range) when it lies outside.
fn steps_within(start: i64, step: i64, lo: f64, hi: f64) -> (i64, i64) {
    let start = start as f64;
    if step == 0 {
        return if (lo..=hi).contains(&start) {
            (i64::MIN, i64::MAX)
        } else {
            (1, 0)
        };
    }
    let (a, b) = ((lo - start) / step as f64, (hi - start) / step as f64);
    let (a, b) = if a < b { (a, b) } else { (b, a) };
    // Conversions saturate, and a step either way covers the rounding of the divisions.
    ((a as i64).saturating_sub(1), (b as i64).saturating_add(1))
}

/// The world box holding what `grid` has seen, once placed at `pose`.
fn placed_box(grid: &OccupancyGrid, pose: Pose2) -> Option<(Point2, Point2)> {
    let (lo, hi) = grid.content_bounds()?;
    let corners = [
        lo,
        Point2::new(hi.x_m, lo.y_m),
        hi,
        Point2::new(lo.x_m, hi.y_m),
    ]
    .map(|c| pose.transform_point(c));
    let min = corners.iter().fold(corners[0], |m, c| {
        Point2::new(m.x_m.min(c.x_m), m.y_m.min(c.y_m))
    });
    let max = corners.iter().fold(corners[0], |m, c| {
        Point2::new(m.x_m.max(c.x_m), m.y_m.max(c.y_m))
    });
    Some((min, max))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small room seen from `sensor` (its walls 2 m out), in the submap frame.
    fn room(sensor: Point2) -> OccupancyGrid {
        let mut g = OccupancyGrid::new(0.05);
        let ends: Vec<(Point2, bool)> = (0..360)
            .map(|k| {
                let a = (k as f64).to_radians();
                let r = 2.0 / a.cos().abs().max(a.sin().abs());
                (
                    Point2::new(sensor.x_m + r * a.cos(), sensor.y_m + r * a.sin()),
                    true,
                )
            })
            .collect();
        g.insert(sensor, &ends);
        g
    }

    /// What drawing every submap from scratch gives.
    fn fresh(parts: &[(&OccupancyGrid, Pose2)]) -> Grid<CellState> {
        let mut a = Assembly::new(0.05);
        for (i, (g, p)) in parts.iter().enumerate() {
            a.place(i, g, *p);
        }
        a.states(&[])
    }

    #[test]
    fn a_rows_cut_keeps_every_step_that_lands_inside() {
        let (lo, hi) = (-3.5e9, 7.25e9);
        for start in [
            -9e9 as i64,
            -3_500_000_000,
            0,
            1,
            7_250_000_000,
            2e10 as i64,
        ] {
            for step in [-3_000_000_000i64, -1, 0, 1, 12_345_678, 4_294_967_296] {
                let (k_lo, k_hi) = steps_within(start, step, lo, hi);
                for k in 0..2000i64 {
                    let at = (start + k * step) as f64;
                    if (lo..=hi).contains(&at) {
                        assert!((k_lo..=k_hi).contains(&k), "{start} {step} {k}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_map_asked_for_before_anything_was_drawn_moves_to_where_content_lands() {
        // A rover whose wheels count from 800 km out: its submaps lie there, and the few
        // unknown cells the live map and the states showed before them must not stretch to
        // them (a grid 800 km across). The room is drawn there too: an empty occupancy grid
        // moves to its first scan the same way.
        let far = Point2::new(8e5, 3e5);
        let sub = room(far);
        let mut live = Assembly::new(0.05);
        let placeholder = live.live_states(&[]).states;
        assert!(placeholder.iter().all(|s| *s == CellState::Unknown));
        let view = live.live_states(&[(0, &sub, Pose2::IDENTITY)]);
        let g = view.geometry;
        assert!(g.width * g.height < 300 * 300, "{g:?}");
        // The room's walls, drawn where they lie: 360 beams end in some 220 of the 320
        // cells along its 16 m of wall.
        let walls = |g: &GridGeometry, states: &[CellState]| {
            let mut n = 0;
            for (i, s) in states.iter().enumerate() {
                if *s == CellState::Occupied {
                    let p = g.cell_center(realms_core::Cell {
                        x: i % g.width,
                        y: i / g.width,
                    });
                    assert!((p.x_m - far.x_m).abs() < 2.1 && (p.y_m - far.y_m).abs() < 2.1);
                    n += 1;
                }
            }
            n
        };
        let n = walls(&g, view.states);
        assert!(n > 200, "{n}");
        let mut states = Assembly::new(0.05);
        let placeholder = states.states(&[]);
        assert!(placeholder.cells().iter().all(|s| *s == CellState::Unknown));
        states.place(0, &sub, Pose2::IDENTITY);
        let whole = states.states(&[]);
        assert!(whole.cells().len() < 300 * 300, "{:?}", whole.geometry());
        assert!(walls(whole.geometry(), whole.cells()) > 200);
        // Content 30 m off, as a rover starts in the default arena, still stretches the
        // grid to the zero: the maps keep the geometry the missions were measured with.
        let mut near = Assembly::new(0.05);
        near.live_states(&[]);
        let room = room(Point2::new(0.0, 0.0));
        let g = near
            .live_states(&[(0, &room, Pose2::new(30.0, 0.0, 0.0))])
            .geometry;
        assert!(
            g.origin.x_m <= 0.0 && g.origin.x_m + g.width_m() >= 32.0,
            "{g:?}"
        );
    }

    #[test]
    fn moving_and_removing_submaps_equals_drawing_afresh() {
        let a = room(Point2::new(0.0, 0.0));
        let b = room(Point2::new(1.0, 0.5));
        let c = room(Point2::new(-0.5, 1.0));
        let mut asm = Assembly::new(0.05);
        asm.place(0, &a, Pose2::new(0.0, 0.0, 0.0));
        asm.place(1, &b, Pose2::new(3.0, 0.0, 0.3));
        asm.place(2, &c, Pose2::new(-4.0, 2.0, -1.0));
        // The graph moves submap 1 a little (below the redraw threshold) and then a lot,
        // and submap 2 is trimmed.
        asm.place(1, &b, Pose2::new(3.01, 0.0, 0.3));
        asm.place(1, &b, Pose2::new(3.5, -0.4, 0.5));
        asm.remove(2, &c);
        let got = asm.states(&[]);
        let want = fresh(&[
            (&a, Pose2::new(0.0, 0.0, 0.0)),
            (&b, Pose2::new(3.5, -0.4, 0.5)),
        ]);
        // Same content; the incremental grid may be larger (it grew for submap 2).
        let known = |g: &Grid<CellState>| -> Vec<(i64, i64, CellState)> {
            let geo = *g.geometry();
            g.iter()
                .filter(|(_, s)| **s != CellState::Unknown)
                .map(|(cell, s)| {
                    let p = geo.cell_center(cell);
                    (
                        (p.x_m / 0.05).floor() as i64,
                        (p.y_m / 0.05).floor() as i64,
                        *s,
                    )
                })
                .collect()
        };
        let (mut g, mut w) = (known(&got), known(&want));
        g.sort_by_key(|(x, y, _)| (*y, *x));
        w.sort_by_key(|(x, y, _)| (*y, *x));
        assert!(w.len() > 1000, "the rooms were drawn: {}", w.len());
        assert_eq!(g, w);
    }

    #[test]
    fn a_cell_counts_as_occupied_only_once_its_summed_hits_pass_the_threshold() {
        // One beam ending in a hit: its end cell holds one hit's log-odds (0.847) in a
        // submap, twice that with the same scan in two submaps.
        let end = Point2::new(1.0123, 0.0271);
        let mut sub = OccupancyGrid::new(0.05);
        sub.insert(Point2::new(0.0123, 0.0271), &[(end, true)]);
        let state_at = |occupied_above: f32, submaps: usize| {
            let mut asm = Assembly::new(0.05).with_occupied_above(occupied_above);
            // The live map from the start, so each submap placed goes through its update.
            asm.live_states(&[]);
            for i in 0..submaps {
                asm.place(i, &sub, Pose2::IDENTITY);
            }
            let whole = asm.states(&[]);
            let view = asm.live_states(&[]);
            let live = Grid::from_cells(view.geometry, view.states.to_vec()).expect("cells");
            let at = |g: &Grid<CellState>| {
                let c = g.geometry().world_to_cell(end).expect("inside");
                g.cells()[c.y * g.geometry().width + c.x]
            };
            assert_eq!(at(&whole), at(&live), "{occupied_above} {submaps}");
            at(&whole)
        };
        assert_eq!(state_at(0.5, 1), CellState::Occupied);
        assert_eq!(state_at(1.0, 1), CellState::Unknown);
        assert_eq!(state_at(1.0, 2), CellState::Occupied);
        assert_eq!(state_at(1.8, 2), CellState::Unknown);
        assert_eq!(state_at(1.8, 3), CellState::Occupied);
    }

    /// 360 beams from `sensor` to the walls of a square room 2 m out.
    fn room_beams(sensor: Point2) -> Vec<(Point2, bool)> {
        (0..360)
            .map(|k| {
                let a = (k as f64).to_radians();
                let r = 2.0 / a.cos().abs().max(a.sin().abs());
                (
                    Point2::new(sensor.x_m + r * a.cos(), sensor.y_m + r * a.sin()),
                    true,
                )
            })
            .collect()
    }

    #[test]
    fn the_live_map_follows_traced_scans_and_finished_submaps_exactly() {
        // A submap at the assembly's own frame and lattice: its traced shadow must equal
        // drawing the submap itself, cell for cell (beams end off cell edges, where the two
        // grids' different corners could round a coordinate either way).
        let mut asm = Assembly::new(0.05);
        let mut sub = OccupancyGrid::new(0.05);
        let first = room_beams(Point2::new(0.0123, 0.0271));
        sub.insert(Point2::new(0.0123, 0.0271), &first);
        let view = asm.live_states(&[(0, &sub, Pose2::IDENTITY)]);
        let v0 = view.version;
        let tiles = |g: &GridGeometry| {
            (
                g.width.div_ceil(LIVE_TILE_CELLS),
                g.height.div_ceil(LIVE_TILE_CELLS),
            )
        };
        let (tw, th) = tiles(&view.geometry);
        // A scan from 3 m further east, into the submap and traced into the live map.
        let sensor = Point2::new(3.0123, 0.0271);
        let second = room_beams(sensor);
        sub.insert(sensor, &second);
        asm.trace(&[(0, Pose2::IDENTITY)], sensor, &second);
        let view = asm.live_states(&[(0, &sub, Pose2::IDENTITY)]);
        let live =
            Grid::from_cells(view.geometry, view.states.to_vec()).expect("one state per cell");
        let geometry = view.geometry;
        let grew = (tw, th) != tiles(&geometry);
        let changed: Vec<(usize, usize)> = (0..geometry.height.div_ceil(LIVE_TILE_CELLS))
            .flat_map(|ty| (0..geometry.width.div_ceil(LIVE_TILE_CELLS)).map(move |tx| (tx, ty)))
            .filter(|(tx, ty)| view.changed_since(*tx, *ty, v0))
            .collect();
        let want = fresh(&[(&sub, Pose2::IDENTITY)]);
        let on = |g: &Grid<CellState>, p: Point2| {
            g.geometry()
                .world_to_cell(p)
                .map(|c| g.cells()[c.y * g.geometry().width + c.x])
        };
        let mut compared = 0;
        for (cell, s) in want.iter() {
            let p = want.geometry().cell_center(cell);
            assert_eq!(on(&live, p).unwrap_or(CellState::Unknown), *s, "at {p:?}");
            compared += usize::from(*s != CellState::Unknown);
        }
        assert!(compared > 3000, "{compared} known cells compared");
        // Every cell that changed lies in a tile said to have changed, and the tiles west
        // of the first room, which the second scan never reached, did not.
        if !grew {
            let first_only = fresh(&[(
                &{
                    let mut g = OccupancyGrid::new(0.05);
                    g.insert(Point2::new(0.0123, 0.0271), &first);
                    g
                },
                Pose2::IDENTITY,
            )]);
            for (cell, s) in want.iter() {
                let p = want.geometry().cell_center(cell);
                if on(&first_only, p).unwrap_or(CellState::Unknown) != *s {
                    let c = geometry.world_to_cell(p).expect("inside");
                    assert!(changed.contains(&(c.x / LIVE_TILE_CELLS, c.y / LIVE_TILE_CELLS)));
                }
            }
            let west = geometry
                .world_to_cell(Point2::new(-2.5, 0.0))
                .expect("inside");
            assert!(!changed.contains(&(west.x / LIVE_TILE_CELLS, west.y / LIVE_TILE_CELLS)));
        }
        // Finished and moved: the exact drawing at the new pose replaces the shadow.
        let moved = Pose2::new(0.7, -0.3, 0.4);
        asm.place(0, &sub, moved);
        let view = asm.live_states(&[]);
        let live =
            Grid::from_cells(view.geometry, view.states.to_vec()).expect("one state per cell");
        let want = fresh(&[(&sub, moved)]);
        for (cell, s) in want.iter() {
            let p = want.geometry().cell_center(cell);
            assert_eq!(on(&live, p).unwrap_or(CellState::Unknown), *s, "at {p:?}");
        }
        assert!(
            live.iter()
                .filter(|(_, s)| **s != CellState::Unknown)
                .count()
                > 3000
        );
    }

    #[test]
    fn an_active_submap_is_drawn_on_top_without_entering_the_sum() {
        let a = room(Point2::new(0.0, 0.0));
        let mut asm = Assembly::new(0.05);
        let with = asm.states(&[(&a, Pose2::new(1.0, 1.0, 0.2))]);
        assert!(with.iter().any(|(_, s)| *s == CellState::Occupied));
        let without = asm.states(&[]);
        assert!(without.iter().all(|(_, s)| *s == CellState::Unknown));
    }

    #[test]
    fn states_agree_with_the_rendered_sum_as_submaps_move_and_overlap() {
        let (a, b, c) = (
            room(Point2::new(0.0, 0.0)),
            room(Point2::new(0.6, 0.2)),
            room(Point2::new(-0.4, 0.5)),
        );
        let mut asm = Assembly::new(0.05);
        // From the rendered log-odds, as the states' definition has it.
        let rendered = |asm: &mut Assembly, active: &[(&OccupancyGrid, Pose2)]| {
            let grid = asm.render(active);
            let states: Vec<CellState> = grid
                .log_odds()
                .iter()
                .map(|&l| summed_state(l, OCCUPIED_ABOVE))
                .collect();
            Grid::from_cells(grid.geometry(), states).expect("one state per cell")
        };
        asm.place(0, &a, Pose2::new(0.1, 0.0, 0.05));
        // Two active submaps overlapping each other and the finished one.
        let active = [
            (&b, Pose2::new(0.3, -0.2, 0.1)),
            (&c, Pose2::new(0.0, 0.4, -0.3)),
        ];
        for round in 0..3 {
            if round == 2 {
                // The finished submap moved: the states follow.
                asm.place(0, &a, Pose2::new(0.9, 0.4, 0.5));
            }
            let got = asm.states(&active);
            let want = rendered(&mut asm, &active);
            assert!(got == want, "round {round}");
            assert!(
                got.iter()
                    .filter(|(_, s)| **s == CellState::Occupied)
                    .count()
                    > 300
            );
        }
    }
}
