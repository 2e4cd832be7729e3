//! A log-odds occupancy grid that grows as scans reach past its edge, updated by tracing each
//! beam from the sensor (cells passed through: free; the endpoint: occupied). It keeps the
//! occupancy probability beside the log-odds so scan matching can read it without `exp`.

use realms_core::{Grid, GridGeometry, Point2};

/// Log-odds added to a cell a beam ends in (p = 0.7).
const HIT: f32 = 0.847;
/// Log-odds added to a cell a beam passes through (p = 0.4).
const MISS: f32 = -0.405;
/// Log-odds are clamped to this magnitude so a cell can change its mind.
const CLAMP: f32 = 4.0;
/// Cells added on each side when the grid grows.
const GROW_MARGIN_CELLS: usize = 128;

/// How a scan's beams clear the cells they cross.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MissRule {
    /// Every beam adds a miss to every cell it crosses, and to its end cell after its hit
    /// (the textbook per-beam update).
    #[default]
    EveryBeam,
    /// A cell gets at most one miss per scan, and none if a beam ends in it, as in
    /// Cartographer's range data inserter: a cell near the sensor that a thousand beams cross
    /// is one observation of free space, not a thousand, and a wall cell that a grazing beam
    /// crosses on its way to the next wall cell stays a hit.
    OncePerScan,
}

/// How far short of its hit a beam stops clearing cells: `base_m + per_m * range`, metres.
///
/// A beam whose noise carries its hit past a wall crosses the wall's own cells and clears
/// them; one whose noise falls short adds its hit in front of the wall, where beams
/// carried past clear it again. So the wall's occupied cells settle behind the wall, away
/// from the sensor, by about the noise, and a lidar's noise grows with range: every
/// surface drawn the farther out the farther it was seen from, which stretches the map and
/// the path matched against it. Stopping each beam's misses short of its hit by about the
/// noise leaves the cells around the surface to the hits alone (the same reasoning as the
/// truncation band of a truncated signed distance field: Curless & Levoy, SIGGRAPH 1996).
/// Shown on a drive of exactly cast lines and circles; the rovers' replays stretch about as
/// much with a noise-free lidar (BENCHMARKS.md, "The stretch without the lidar's noise").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MissMargin {
    /// At zero range, metres.
    pub base_m: f64,
    /// Per metre of range.
    pub per_m: f64,
}

impl MissMargin {
    /// Where a beam from `sensor` to its hit `end` stops clearing cells.
    fn short_of(&self, sensor: Point2, end: Point2) -> Point2 {
        let (dx, dy) = (end.x_m - sensor.x_m, end.y_m - sensor.y_m);
        let range = dx.hypot(dy);
        if range <= 0.0 {
            return end;
        }
        let keep = (1.0 - (self.base_m + self.per_m * range) / range).max(0.0);
        Point2::new(sensor.x_m + dx * keep, sensor.y_m + dy * keep)
    }
}

/// What a map cell is, for export.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellState {
    /// Never observed, or no evidence either way.
    Unknown,
    /// Observed free.
    Free,
    /// Observed occupied.
    Occupied,
}

impl CellState {
    /// The state of a cell with log-odds `l` (beyond +-0.5 counts as known).
    pub fn from_log_odds(l: f32) -> CellState {
        if l > 0.5 {
            CellState::Occupied
        } else if l < -0.5 {
            CellState::Free
        } else {
            CellState::Unknown
        }
    }
}

/// A growable log-odds occupancy grid.
#[derive(Clone, Debug)]
pub struct OccupancyGrid {
    resolution_m: f64,
    origin: Point2,
    width: usize,
    height: usize,
    /// The log-odds of the cells kept in memory: every cell, row by row, or only those of
    /// `window` once the grid was cut ([`OccupancyGrid::cut_to_content`]); a cell outside it
    /// holds 0.
    log_odds: Vec<f32>,
    /// Each kept cell's occupancy probability, [`probability`] of its log-odds, for the
    /// matcher's lookups; empty once the grid was cut, or in a grid that keeps none, when
    /// each is worked out from its log-odds as it is read.
    prob: Vec<f32>,
    /// The cells kept in memory, if not all.
    window: Option<CellWindow>,
    /// The largest cell-centre coordinates whose bilinear lookup reads the kept
    /// probabilities, (`width - 1`, `height - 1`), or below zero once they are dropped: the
    /// one test a lookup takes on its short way ([`OccupancyGrid::probability_and_gradient`]).
    lookup_limits: (f64, f64),
    /// The world box holding every cell ever updated (none yet: `None`).
    content: Option<(Point2, Point2)>,
    miss_rule: MissRule,
    miss_margin: Option<MissMargin>,
    /// Whether `prob` is kept up to date while the grid is whole
    /// ([`OccupancyGrid::without_probabilities`]).
    keeps_probabilities: bool,
}

/// A rectangle of a grid's cells: columns `x0..x0 + width`, rows `y0..y0 + height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellWindow {
    /// First column.
    pub x0: usize,
    /// First row.
    pub y0: usize,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl CellWindow {
    /// The index of cell (`x`, `y`) (of the whole grid) among the window's, row by row, if
    /// it lies inside.
    #[inline]
    pub fn index(&self, x: usize, y: usize) -> Option<usize> {
        // Cells before the window wrap to huge offsets: one comparison per axis.
        let (dx, dy) = (x.wrapping_sub(self.x0), y.wrapping_sub(self.y0));
        (dx < self.width && dy < self.height).then(|| dy * self.width + dx)
    }
}

impl OccupancyGrid {
    /// An empty grid of `resolution_m` cells around the world origin.
    pub fn new(resolution_m: f64) -> Self {
        let side = 2 * GROW_MARGIN_CELLS;
        OccupancyGrid {
            resolution_m,
            origin: Point2::new(
                -(GROW_MARGIN_CELLS as f64) * resolution_m,
                -(GROW_MARGIN_CELLS as f64) * resolution_m,
            ),
            width: side,
            height: side,
            log_odds: vec![0.0; side * side],
            prob: vec![0.5; side * side],
            window: None,
            lookup_limits: lookup_limits(side, side, true),
            content: None,
            miss_rule: MissRule::default(),
            miss_margin: None,
            keeps_probabilities: true,
        }
    }

    /// The grid clearing cells by `rule` from now on.
    pub fn with_miss_rule(mut self, rule: MissRule) -> Self {
        self.miss_rule = rule;
        self
    }

    /// The grid's beams stopping short of their hits by `margin` from now on (`None`: each
    /// clears every cell up to its hit's).
    pub fn with_miss_margin(mut self, margin: Option<MissMargin>) -> Self {
        self.miss_margin = margin;
        self
    }

    /// The grid keeping no probabilities: one that is only rendered or read cell by cell,
    /// never matched against. Every update then writes one value instead of two, and the
    /// grid takes half the memory; a lookup works each probability out as it reads it, and
    /// every answer stays the same.
    pub fn without_probabilities(mut self) -> Self {
        self.keeps_probabilities = false;
        self.prob = Vec::new();
        self.set_lookup_limits();
        self
    }

    /// A grid holding `log_odds` (clamped) over `geometry`; `None` if the count is wrong.
    pub fn from_log_odds(geometry: GridGeometry, log_odds: Vec<f32>) -> Option<Self> {
        if log_odds.len() != geometry.len() || geometry.is_empty() {
            return None;
        }
        let log_odds: Vec<f32> = log_odds.iter().map(|l| l.clamp(-CLAMP, CLAMP)).collect();
        let prob = log_odds.iter().map(|l| probability(*l)).collect();
        let max = Point2::new(
            geometry.origin.x_m + geometry.width_m(),
            geometry.origin.y_m + geometry.height_m(),
        );
        Some(OccupancyGrid {
            resolution_m: geometry.resolution_m,
            origin: geometry.origin,
            width: geometry.width,
            height: geometry.height,
            log_odds,
            prob,
            window: None,
            lookup_limits: lookup_limits(geometry.width, geometry.height, true),
            content: Some((geometry.origin, max)),
            miss_rule: MissRule::default(),
            miss_margin: None,
            keeps_probabilities: true,
        })
    }

    /// The log-odds of every cell, row by row from the grid's origin (spread out afresh for
    /// a grid cut to its content: [`kept_log_odds`](Self::kept_log_odds) reads it as kept).
    pub fn log_odds(&self) -> std::borrow::Cow<'_, [f32]> {
        match self.window {
            None => std::borrow::Cow::Borrowed(&self.log_odds),
            Some(w) => std::borrow::Cow::Owned(self.spread_out(w)),
        }
    }

    /// The cells kept in memory and their log-odds, row by row; every cell outside holds 0
    /// (see [`cut_to_content`](Self::cut_to_content)).
    pub fn kept_log_odds(&self) -> (CellWindow, &[f32]) {
        (self.kept_window(), &self.log_odds)
    }

    /// The cells kept in memory.
    fn kept_window(&self) -> CellWindow {
        self.window.unwrap_or(CellWindow {
            x0: 0,
            y0: 0,
            width: self.width,
            height: self.height,
        })
    }

    /// The kept log-odds, those of `window`'s cells, spread over the whole grid with 0
    /// elsewhere.
    fn spread_out(&self, window: CellWindow) -> Vec<f32> {
        let mut cells = vec![0.0; self.width * self.height];
        if window.width > 0 {
            for (row, values) in self.log_odds.chunks_exact(window.width).enumerate() {
                let at = (window.y0 + row) * self.width + window.x0;
                cells[at..at + window.width].copy_from_slice(values);
            }
        }
        cells
    }

    /// Keeps in memory only the cells holding evidence (the smallest rectangle holding every
    /// cell whose log-odds are not 0) and drops the probabilities kept beside them: a
    /// finished submap's grid, which nothing updates any more and a closure search looks up
    /// only now and then, takes about a fifth of its memory. Every answer stays the same
    /// to the bit: a cell outside the rectangle holds 0 as before, and each probability is
    /// worked out from its log-odds as it is read. Updating the grid makes it whole again
    /// first, as does [`make_whole`](Self::make_whole).
    pub fn cut_to_content(&mut self) {
        let kept = self.kept_window();
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        if kept.width > 0 {
            for (row, values) in self.log_odds.chunks_exact(kept.width).enumerate() {
                // Bits, not values: a -0.0 is kept as it was.
                let filled = |l: &f32| l.to_bits() != 0;
                if let (Some(first), Some(last)) = (
                    values.iter().position(filled),
                    values.iter().rposition(filled),
                ) {
                    (x0, x1) = (x0.min(first), x1.max(last));
                    (y0, y1) = (y0.min(row), y1.max(row));
                }
            }
        }
        let window = if x0 > x1 {
            CellWindow {
                x0: 0,
                y0: 0,
                width: 0,
                height: 0,
            }
        } else {
            CellWindow {
                x0: kept.x0 + x0,
                y0: kept.y0 + y0,
                width: x1 + 1 - x0,
                height: y1 + 1 - y0,
            }
        };
        let mut cut = Vec::with_capacity(window.width * window.height);
        if window.width > 0 {
            for y in y0..=y1 {
                let at = y * kept.width + x0;
                cut.extend_from_slice(&self.log_odds[at..at + window.width]);
            }
        }
        self.log_odds = cut;
        self.prob = Vec::new();
        self.window = Some(window);
        self.set_lookup_limits();
    }

    /// Keeps every cell in memory again, and its probability if the grid keeps them (undoes
    /// [`cut_to_content`](Self::cut_to_content); nothing to do for a whole grid).
    pub fn make_whole(&mut self) {
        if let Some(w) = self.window.take() {
            self.log_odds = self.spread_out(w);
        }
        if self.prob.is_empty() && self.keeps_probabilities {
            self.prob = probabilities_of(&self.log_odds);
        }
        self.set_lookup_limits();
    }

    /// Sets [`OccupancyGrid::lookup_limits`] for the grid's size and whether it keeps its
    /// probabilities.
    fn set_lookup_limits(&mut self) {
        self.lookup_limits = lookup_limits(self.width, self.height, !self.prob.is_empty());
    }

    /// Whether every cell is kept in memory, and its probability if the grid keeps them
    /// (see [`cut_to_content`](Self::cut_to_content)).
    pub fn is_whole(&self) -> bool {
        self.window.is_none() && (!self.prob.is_empty() || !self.keeps_probabilities)
    }

    /// The log-odds of cell (`x`, `y`), inside the grid.
    #[inline]
    fn kept_at(&self, x: usize, y: usize) -> f32 {
        match self.window {
            None => self.log_odds[y * self.width + x],
            Some(w) => w.index(x, y).map_or(0.0, |i| self.log_odds[i]),
        }
    }

    /// The world box holding every cell that was ever updated, if any was.
    pub fn content_bounds(&self) -> Option<(Point2, Point2)> {
        self.content
    }

    /// Widens the content box to `[min, max]`.
    fn touch(&mut self, min: Point2, max: Point2) {
        self.content = Some(match self.content {
            None => (min, max),
            Some((a, b)) => (
                Point2::new(a.x_m.min(min.x_m), a.y_m.min(min.y_m)),
                Point2::new(b.x_m.max(max.x_m), b.y_m.max(max.y_m)),
            ),
        });
    }

    /// Cell edge, metres.
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    /// The grid's geometry now (it changes when the grid grows).
    pub fn geometry(&self) -> GridGeometry {
        GridGeometry {
            width: self.width,
            height: self.height,
            resolution_m: self.resolution_m,
            origin: self.origin,
        }
    }

    /// Grows the grid so the world box `[min, max]` lies inside it.
    fn ensure(&mut self, min: Point2, max: Point2) {
        // Updates index every cell.
        self.make_whole();
        let (w, h) = (self.width, self.height);
        if self.content.is_none() && far_off(&self.geometry(), min, max) {
            // Nothing written yet, and the first content lies far off: the empty grid moves
            // to it instead of stretching to it (content 800 km from the world's origin
            // would otherwise ask for a grid 800 km across).
            self.origin = corner_before(min, self.resolution_m, GROW_MARGIN_CELLS);
        }
        let Some(g) = growth(
            self.origin,
            self.resolution_m,
            w,
            h,
            min,
            max,
            GROW_MARGIN_CELLS,
        ) else {
            return;
        };
        self.log_odds = regrow(&self.log_odds, w, h, g, 0.0);
        if self.keeps_probabilities {
            self.prob = regrow(&self.prob, w, h, g, 0.5);
        }
        let r = self.resolution_m;
        self.origin = Point2::new(
            self.origin.x_m - g[0] as f64 * r,
            self.origin.y_m - g[1] as f64 * r,
        );
        self.width = w + g[0] + g[2];
        self.height = h + g[1] + g[3];
        self.set_lookup_limits();
    }

    /// Adds `delta` to cell `i`'s log-odds, its probability from `probabilities`.
    fn update(&mut self, i: usize, delta: f32, probabilities: &mut ProbabilityCache) {
        let old = self.log_odds[i];
        let l = updated_log_odds(old, delta);
        // A cell held at the clamp (open ground seen from many keyframes) does not change,
        // and its probability need not be worked out again.
        if l != old {
            self.log_odds[i] = l;
            if self.keeps_probabilities {
                self.prob[i] = probabilities.of(l);
            }
        }
    }

    /// Inserts one scan: beams from `sensor` to each endpoint (world frame); endpoints marked
    /// `hit` are occupied, the others (max-range readings, clipped) only clear free space.
    pub fn insert(&mut self, sensor: Point2, endpoints: &[(Point2, bool)]) {
        self.insert_with_rays(sensor, endpoints, None);
    }

    /// [`insert`](Self::insert), tracing free space only to `rays` (each the end of one of
    /// the endpoints' beams) when given: the other endpoints are surface filled in between
    /// beams ([`crate::frontend::densify`]), marked hit without a beam of their own.
    pub fn insert_with_rays(
        &mut self,
        sensor: Point2,
        endpoints: &[(Point2, bool)],
        rays: Option<&[Point2]>,
    ) {
        if endpoints.is_empty() {
            return;
        }
        let (min, max) = beams_box(sensor, endpoints);
        self.ensure(min, max);
        self.touch(min, max);
        let lattice = Lattice {
            origin: self.origin,
            resolution_m: self.resolution_m,
            width: self.width,
        };
        let mut probabilities = ProbabilityCache::new();
        trace_beams(
            &lattice,
            sensor,
            endpoints,
            rays,
            (self.miss_rule, self.miss_margin),
            |i, delta| self.update(i, delta, &mut probabilities),
        );
    }

    /// [`insert_with_rays`](Self::insert_with_rays) into this grid, and into `matched` the
    /// same scan's first `matched_endpoints` endpoints and first `matched_rays` rays, each
    /// stopped short by its own margin. Where both grids clear cells once a scan on the same
    /// cells, and this one stops no beam short, one walk along each beam marks both: it runs
    /// from the sensor to where the matching beam stops, marking both grids, and on to the
    /// hit, marking this one. `matched` comes out as traced on its own, and this grid with
    /// each of those beams bent by up to a cell where the matching beam stops. Otherwise
    /// each grid is traced on its own.
    pub fn insert_with_rays_beside(
        &mut self,
        matched: &mut OccupancyGrid,
        sensor: Point2,
        endpoints: &[(Point2, bool)],
        rays: Option<&[Point2]>,
        (matched_endpoints, matched_rays): (usize, usize),
    ) {
        let (matched_endpoints, matched_rays) = (
            matched_endpoints.min(endpoints.len()),
            rays.map_or(0, |r| matched_rays.min(r.len())),
        );
        let r = self.resolution_m;
        let shares_walks = self.miss_rule == MissRule::OncePerScan
            && matched.miss_rule == MissRule::OncePerScan
            && self.miss_margin.is_none()
            && matched.resolution_m == r
            && matched_endpoints > 0;
        if !shares_walks {
            self.insert_with_rays(sensor, endpoints, rays);
            matched.insert_with_rays(
                sensor,
                &endpoints[..matched_endpoints],
                rays.map(|r| &r[..matched_rays]),
            );
            return;
        }
        let (min, max) = beams_box(sensor, endpoints);
        self.ensure(min, max);
        self.touch(min, max);
        let (matched_min, matched_max) = beams_box(sensor, &endpoints[..matched_endpoints]);
        matched.ensure(matched_min, matched_max);
        matched.touch(matched_min, matched_max);
        let lattice = Lattice {
            origin: self.origin,
            resolution_m: r,
            width: self.width,
        };
        // Both grids started on one lattice and grow by whole cells.
        let second = SecondGrid {
            offset: (
                ((self.origin.x_m - matched.origin.x_m) / r).round() as i64,
                ((self.origin.y_m - matched.origin.y_m) / r).round() as i64,
            ),
            width: matched.width,
            height: matched.height,
            margin: matched.miss_margin,
            endpoints: matched_endpoints,
            rays: matched_rays,
        };
        let (mut own, mut theirs) = (ProbabilityCache::new(), ProbabilityCache::new());
        trace_once_per_scan(
            &lattice,
            sensor,
            endpoints,
            rays,
            None,
            Some(second),
            |layer, i, delta| match layer {
                Layer::First => self.update(i, delta, &mut own),
                Layer::Second => matched.update(i, delta, &mut theirs),
            },
        );
    }

    /// The log-odds of the cell holding `p`; 0 (no evidence) outside the grid.
    pub fn log_odds_at(&self, p: Point2) -> f32 {
        let r = self.resolution_m;
        let (fx, fy) = (
            floor_f64((p.x_m - self.origin.x_m) / r),
            floor_f64((p.y_m - self.origin.y_m) / r),
        );
        if fx >= 0.0 && fy >= 0.0 && fx < self.width as f64 && fy < self.height as f64 {
            self.kept_at(fx as usize, fy as usize)
        } else {
            0.0
        }
    }

    /// Of the beams from `sensor` that end on a cell this grid holds as occupied, how many
    /// (second) and how many of those reach it through ground the grid never saw open
    /// (first): the cell `back_m` before the end along the beam is not free. A surface seen
    /// from the side it was drawn from is reached over open ground; one reached from behind
    /// (a face laid on the opposite face of a block) is not.
    pub fn hits_from_behind(
        &self,
        sensor: Point2,
        endpoints: impl IntoIterator<Item = Point2>,
        back_m: f64,
    ) -> (usize, usize) {
        let (mut behind, mut on) = (0, 0);
        for e in endpoints {
            if CellState::from_log_odds(self.log_odds_at(e)) != CellState::Occupied {
                continue;
            }
            let (dx, dy) = (e.x_m - sensor.x_m, e.y_m - sensor.y_m);
            let d = dx.hypot(dy);
            if d <= back_m {
                continue;
            }
            on += 1;
            let f = 1.0 - back_m / d;
            let before = Point2::new(sensor.x_m + f * dx, sensor.y_m + f * dy);
            if CellState::from_log_odds(self.log_odds_at(before)) != CellState::Free {
                behind += 1;
            }
        }
        (behind, on)
    }

    /// Adds `evidence(p)` (log-odds) to every cell in the world box `[min, max]`, at the
    /// cell's centre `p`; grows the grid to hold the box.
    pub fn accumulate(&mut self, min: Point2, max: Point2, evidence: impl Fn(Point2) -> f32) {
        self.ensure(min, max);
        self.touch(min, max);
        let r = self.resolution_m;
        let x0 = ((min.x_m - self.origin.x_m) / r).floor().max(0.0) as usize;
        let y0 = ((min.y_m - self.origin.y_m) / r).floor().max(0.0) as usize;
        let x1 = (((max.x_m - self.origin.x_m) / r).floor() as usize).min(self.width - 1);
        let y1 = (((max.y_m - self.origin.y_m) / r).floor() as usize).min(self.height - 1);
        let mut probabilities = ProbabilityCache::new();
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = Point2::new(
                    self.origin.x_m + (x as f64 + 0.5) * r,
                    self.origin.y_m + (y as f64 + 0.5) * r,
                );
                let e = evidence(p);
                if e != 0.0 {
                    self.update(y * self.width + x, e, &mut probabilities);
                }
            }
        }
    }

    /// The world box the grid covers now.
    pub fn bounds(&self) -> (Point2, Point2) {
        let r = self.resolution_m;
        (
            self.origin,
            Point2::new(
                self.origin.x_m + self.width as f64 * r,
                self.origin.y_m + self.height as f64 * r,
            ),
        )
    }

    /// Gives the memory back: an empty one-cell grid remains (for a submap that another
    /// covers).
    pub fn release(&mut self) {
        self.width = 1;
        self.height = 1;
        self.log_odds = vec![0.0];
        self.prob = if self.keeps_probabilities {
            vec![0.5]
        } else {
            Vec::new()
        };
        self.window = None;
        self.set_lookup_limits();
        self.content = None;
    }

    /// Updates the cells under single observations, without tracing beams: `true` is
    /// evidence for the cell's property (occupied, or hazardous in a hazard layer), `false`
    /// against it.
    pub fn observe_cells(&mut self, observations: &[(Point2, bool)]) {
        let Some(first) = observations.first() else {
            return;
        };
        let (mut min, mut max) = (first.0, first.0);
        for (p, _) in observations {
            min = Point2::new(min.x_m.min(p.x_m), min.y_m.min(p.y_m));
            max = Point2::new(max.x_m.max(p.x_m), max.y_m.max(p.y_m));
        }
        self.ensure(min, max);
        self.touch(min, max);
        let r = self.resolution_m;
        let mut probabilities = ProbabilityCache::new();
        for (p, yes) in observations {
            let x = ((p.x_m - self.origin.x_m) / r).floor() as usize;
            let y = ((p.y_m - self.origin.y_m) / r).floor() as usize;
            self.update(
                y * self.width + x,
                if *yes { HIT } else { MISS },
                &mut probabilities,
            );
        }
    }

    /// Occupancy probability at a world point, bilinear between cell centres, with its
    /// gradient per metre; 0.5 (unknown) outside the grid.
    #[inline(always)]
    pub fn probability_and_gradient(&self, p: Point2) -> (f64, [f64; 2]) {
        let r = self.resolution_m;
        let fx = (p.x_m - self.origin.x_m) / r - 0.5;
        let fy = (p.y_m - self.origin.y_m) / r - 0.5;
        let (x_limit, y_limit) = self.lookup_limits;
        if !(fx >= 0.0 && fy >= 0.0 && fx < x_limit && fy < y_limit) {
            return self.probability_and_gradient_cut(fx, fy);
        }
        let (x0, y0) = (fx as usize, fy as usize);
        let i = y0 * self.width + x0;
        let (p00, p10) = (self.prob[i] as f64, self.prob[i + 1] as f64);
        let (p01, p11) = (
            self.prob[i + self.width] as f64,
            self.prob[i + self.width + 1] as f64,
        );
        bilinear(fx, fy, [p00, p10, p01, p11], r)
    }

    /// [`probability_and_gradient`](Self::probability_and_gradient) at cell-centre
    /// coordinates (`fx`, `fy`) outside its short way: outside the grid, or in a grid cut to
    /// its content, whose probabilities are worked out from the kept log-odds. Out of line,
    /// so the matcher's lookups into a whole grid stay as short as they were.
    #[cold]
    #[inline(never)]
    fn probability_and_gradient_cut(&self, fx: f64, fy: f64) -> (f64, [f64; 2]) {
        // A whole grid comes here only from outside it.
        let inside =
            fx >= 0.0 && fy >= 0.0 && fx < (self.width - 1) as f64 && fy < (self.height - 1) as f64;
        if !inside || !self.prob.is_empty() {
            return (0.5, [0.0, 0.0]);
        }
        let (x0, y0) = (fx as usize, fy as usize);
        let at = |x, y| probability(self.kept_at(x, y)) as f64;
        let corners = [
            at(x0, y0),
            at(x0 + 1, y0),
            at(x0, y0 + 1),
            at(x0 + 1, y0 + 1),
        ];
        bilinear(fx, fy, corners, self.resolution_m)
    }

    /// Occupancy probability of every cell, row by row from the grid's origin (see
    /// [`OccupancyGrid::geometry`]).
    pub fn probabilities(&self) -> std::borrow::Cow<'_, [f32]> {
        if self.prob.is_empty() {
            std::borrow::Cow::Owned(probabilities_of(&self.log_odds()))
        } else {
            std::borrow::Cow::Borrowed(&self.prob)
        }
    }

    /// The state of every cell (log-odds beyond +-0.5 count as known).
    pub fn states(&self) -> Grid<CellState> {
        let cells = self
            .log_odds()
            .iter()
            .map(|l| CellState::from_log_odds(*l))
            .collect();
        Grid::from_cells(self.geometry(), cells).expect("one state per cell")
    }
}

/// [`OccupancyGrid::lookup_limits`] for a grid of `width` x `height` cells that keeps its
/// probabilities or not.
fn lookup_limits(width: usize, height: usize, keeps_probabilities: bool) -> (f64, f64) {
    if keeps_probabilities {
        ((width - 1) as f64, (height - 1) as f64)
    } else {
        (-1.0, -1.0)
    }
}

/// Each cell's probability from its log-odds, as [`OccupancyGrid::update`] sets it.
fn probabilities_of(log_odds: &[f32]) -> Vec<f32> {
    let mut probabilities = ProbabilityCache::new();
    log_odds.iter().map(|l| probabilities.of(*l)).collect()
}

/// The bilinear value at cell-centre coordinates (`fx`, `fy`) (inside the grid) between the
/// probabilities of its four cells (`[p00, p10, p01, p11]`), and its gradient per metre on
/// cells of `r` metres.
#[inline(always)]
fn bilinear(fx: f64, fy: f64, [p00, p10, p01, p11]: [f64; 4], r: f64) -> (f64, [f64; 2]) {
    let (tx, ty) = (fx - (fx as usize) as f64, fy - (fy as usize) as f64);
    let v = (p00 * (1.0 - tx) + p10 * tx) * (1.0 - ty) + (p01 * (1.0 - tx) + p11 * tx) * ty;
    let gx = ((p10 - p00) * (1.0 - ty) + (p11 - p01) * ty) / r;
    let gy = ((p01 - p00) * (1.0 - tx) + (p11 - p10) * tx) / r;
    (v, [gx, gy])
}

/// `v.floor()`, without the call to the C library's `floor` that the baseline x86-64 target
/// (no SSE4.1 rounding) makes: maps look up and trace hundreds of thousands of cells a
/// second. Exact: below 2^52 in size the truncation to an integer is exact, and anything
/// larger (or infinite, or NaN) is its own floor.
pub(crate) fn floor_f64(v: f64) -> f64 {
    if v.abs() < 4_503_599_627_370_496.0 {
        let t = v as i64 as f64;
        // (The sign keeps -0.0 the floor of -0.0.)
        if t > v { t - 1.0 } else { t.copysign(v) }
    } else {
        v
    }
}

/// `v.floor() as i64`, likewise without the C library (see [`floor_f64`]).
pub(crate) fn floor_to_i64(v: f64) -> i64 {
    let t = v as i64;
    t.saturating_sub(i64::from(t as f64 > v))
}

/// The occupancy probability of log-odds `l`.
fn probability(l: f32) -> f32 {
    1.0 - 1.0 / (1.0 + l.exp())
}

/// [`probability`] remembered for the last few log-odds seen, for one update's cells. Most
/// cells a scan clears hold one of a dozen values (0 and the sums of misses down to the
/// clamp), so nearly every cell's `exp` is one already worked out. The values are those
/// [`probability`] gives: the cache only keeps them.
struct ProbabilityCache {
    /// By a hash of the log-odds' bits: the bits and their probability.
    slots: [(u32, f32); 64],
}

impl ProbabilityCache {
    fn new() -> Self {
        // Every slot starts true of the log-odds its bits are (a NaN's).
        let bits = u32::MAX;
        ProbabilityCache {
            slots: [(bits, probability(f32::from_bits(bits))); 64],
        }
    }

    fn of(&mut self, l: f32) -> f32 {
        let bits = l.to_bits();
        let slot = &mut self.slots[((bits ^ (bits >> 7) ^ (bits >> 17)) & 63) as usize];
        if slot.0 != bits {
            *slot = (bits, probability(l));
        }
        slot.1
    }
}

/// A cell's log-odds `l` after evidence `delta`, clamped.
pub(crate) fn updated_log_odds(l: f32, delta: f32) -> f32 {
    (l + delta).clamp(-CLAMP, CLAMP)
}

/// The box holding `sensor` and every endpoint.
pub(crate) fn beams_box(sensor: Point2, endpoints: &[(Point2, bool)]) -> (Point2, Point2) {
    let (mut min, mut max) = (sensor, sensor);
    for (p, _) in endpoints {
        min = Point2::new(min.x_m.min(p.x_m), min.y_m.min(p.y_m));
        max = Point2::new(max.x_m.max(p.x_m), max.y_m.max(p.y_m));
    }
    (min, max)
}

/// Where a grid's cells lie: its corner, cell edge and row length.
pub(crate) struct Lattice {
    pub origin: Point2,
    pub resolution_m: f64,
    pub width: usize,
}

impl Lattice {
    /// The cell holding `p`.
    fn cell_of(&self, p: Point2) -> Cell {
        let r = self.resolution_m;
        (
            floor_to_i64((p.x_m - self.origin.x_m) / r),
            floor_to_i64((p.y_m - self.origin.y_m) / r),
        )
    }
}

/// Where a beam from `sensor` to `p` stops clearing cells under `margin` (`hit`: `p` is a
/// hit; a beam that returned nothing clears all the way).
fn beam_stop(margin: Option<MissMargin>, sensor: Point2, p: Point2, hit: bool) -> Point2 {
    match margin {
        Some(m) if hit => m.short_of(sensor, p),
        _ => p,
    }
}

/// Traces beams from `sensor` to each endpoint over the cells of `lattice` (which must hold
/// them all), calling `update(cell index, log-odds evidence)`: a hit for each endpoint
/// marked `hit`, and misses for the cells the beams cross (and the ends of clipped
/// max-range readings) as `rule` says. With `rays`, beams run to those points only (which
/// must lie in the endpoints' box), and every endpoint is only a hit or a miss at its cell.
/// With a `margin`, a beam to a hit clears cells only up to where the margin stops it, and
/// so does each of the `rays` (taken for hits: a ray clipped at a hit range is stopped
/// short too).
pub(crate) fn trace_beams(
    lattice: &Lattice,
    sensor: Point2,
    endpoints: &[(Point2, bool)],
    rays: Option<&[Point2]>,
    (rule, margin): (MissRule, Option<MissMargin>),
    mut update: impl FnMut(usize, f32),
) {
    let to_cell = |p: Point2| lattice.cell_of(p);
    let start = to_cell(sensor);
    let w = lattice.width as i64;
    let stop = |p: Point2, hit: bool| beam_stop(margin, sensor, p, hit);
    match rule {
        MissRule::EveryBeam => {
            if let Some(rays) = rays {
                for p in rays {
                    walk(start, to_cell(stop(*p, true)), |x, y| {
                        update((y * w + x) as usize, MISS)
                    });
                }
            }
            for (p, hit) in endpoints {
                let end = to_cell(*p);
                if rays.is_none() {
                    walk(start, to_cell(stop(*p, *hit)), |x, y| {
                        update((y * w + x) as usize, MISS)
                    });
                }
                update((end.1 * w + end.0) as usize, if *hit { HIT } else { MISS });
            }
        }
        MissRule::OncePerScan => trace_once_per_scan(
            lattice,
            sensor,
            endpoints,
            rays,
            margin,
            None,
            |_, i, delta| update(i, delta),
        ),
    }
}

/// A second grid traced on the walks of another's ([`trace_once_per_scan`]): its beams are
/// the first `endpoints` endpoints and the first `rays` rays of the first grid's, each
/// stopped where its own `margin` stops it, which must be no farther than the first grid's
/// stop.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SecondGrid {
    /// The lattice's cell (x, y) is its cell (x + offset.0, y + offset.1).
    pub offset: (i64, i64),
    /// Its columns.
    pub width: usize,
    /// Its rows.
    pub height: usize,
    /// Where its beams stop short of their hits.
    pub margin: Option<MissMargin>,
    /// How many of the endpoints are its own, from the first.
    pub endpoints: usize,
    /// How many of the rays are its own, from the first.
    pub rays: usize,
}

/// A cell of a lattice: column and row.
type Cell = (i64, i64);

/// The grid an update of [`trace_once_per_scan`] is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Layer {
    First,
    Second,
}

/// [`trace_beams`] by the once-a-scan rule, into the grid of `lattice` and, if given, a
/// `second` grid whose beams are the first's cut shorter. One walk serves both: a beam of
/// both grids is walked from the sensor to where the second grid's stops, marking both,
/// and on from there to where the first grid's stops, marking the first. The second grid
/// gets the cells a walk of its own would give it; the first, a beam bent by up to a cell
/// where the second's stops.
pub(crate) fn trace_once_per_scan(
    lattice: &Lattice,
    sensor: Point2,
    endpoints: &[(Point2, bool)],
    rays: Option<&[Point2]>,
    margin: Option<MissMargin>,
    second: Option<SecondGrid>,
    mut update: impl FnMut(Layer, usize, f32),
) {
    let to_cell = |p: Point2| lattice.cell_of(p);
    let start = to_cell(sensor);
    let w = lattice.width as i64;
    let stop = |margin: Option<MissMargin>, p: Point2, hit: bool| beam_stop(margin, sensor, p, hit);
    let (second_endpoints, second_rays) = second.map_or((0, 0), |g| (g.endpoints, g.rays));
    let ((ox, oy), (second_w, second_h)) =
        second.map_or(((0, 0), (0, 0)), |g| (g.offset, (g.width, g.height)));
    // The second grid's cells are found on the first's lattice, which may put a point on a
    // cell's very edge on the other side of it: a cell its own walk would have kept within
    // its bounds might then lie outside them, and is left alone.
    let second_index = |(x, y): Cell| {
        let (x, y) = ((x + ox) as usize, (y + oy) as usize);
        (x < second_w && y < second_h).then(|| y * second_w + x)
    };
    // The scan's box of cells as one byte each: the beams only mark the cells they cross
    // (the box fits in the cache where the grid does not), and the misses are then applied
    // row by row, in the grid's own order. Each cell's update depends on that cell alone,
    // so the order changes nothing but the cost.
    let (min, max) = beams_box(sensor, endpoints);
    let ((bx, by), (tx, ty)) = (to_cell(min), to_cell(max));
    let (box_w, rows) = ((tx - bx + 1) as usize, (ty - by + 1) as usize);
    let mark_of = |(x, y): Cell| (y - by) * box_w as i64 + (x - bx);
    SCAN_MARKS.with_borrow_mut(|marks| {
        if marks.len() < box_w * rows {
            marks.resize(box_w * rows, 0);
        }
        let marks = &mut marks[..box_w * rows];
        let from = mark_of(start);
        // Each walk's end, and where the second grid's beam along it stops, if it has one.
        let walks: Vec<(Cell, Option<Cell>)> = match rays {
            None => endpoints
                .iter()
                .enumerate()
                .map(|(k, (p, hit))| {
                    let second_stop = second
                        .filter(|_| k < second_endpoints)
                        .map(|g| to_cell(stop(g.margin, *p, *hit)));
                    (to_cell(stop(margin, *p, *hit)), second_stop)
                })
                .collect(),
            Some(rays) => rays
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    let second_stop = second
                        .filter(|_| k < second_rays)
                        .map(|g| to_cell(stop(g.margin, *p, true)));
                    (to_cell(stop(margin, *p, true)), second_stop)
                })
                .collect(),
        };
        // A walk depends only on its two cells, so a second beam ending in a cell a walk
        // from the sensor already ended in would cross the same cells again: filled-in
        // scans end two or three beams in many cells.
        let walk_once = |marks: &mut [u8], end: Cell, mark: u8, walked: u8| {
            let at = mark_of(end) as usize;
            if marks[at] & walked != walked {
                walk_marking(start, end, from, box_w as i64, marks, mark);
                marks[at] |= walked;
            }
        };
        for (end, second_stop) in walks {
            match second_stop {
                None => walk_once(marks, end, CROSSED, WALKED),
                Some(stop) => {
                    walk_once(marks, stop, CROSSED | CROSSED_SECOND, WALKED_BOTH);
                    if stop != end {
                        walk_marking(stop, end, mark_of(stop), box_w as i64, marks, CROSSED);
                    }
                }
            }
        }
        // Each endpoint's own cell: a hit, or a miss unless some hit ends there too (the
        // marks are bits, so the order of the endpoints does not matter).
        for (k, (p, hit)) in endpoints.iter().enumerate() {
            let end = to_cell(*p);
            let both = k < second_endpoints;
            let mut mark = if both {
                CROSSED | CROSSED_SECOND
            } else {
                CROSSED
            };
            if *hit {
                mark |= if both {
                    ENDS_A_HIT | ENDS_A_HIT_SECOND
                } else {
                    ENDS_A_HIT
                };
                update(Layer::First, (end.1 * w + end.0) as usize, HIT);
                if both && let Some(i) = second_index(end) {
                    update(Layer::Second, i, HIT);
                }
            }
            marks[mark_of(end) as usize] |= mark;
        }
        // The sweep leaves every mark at zero again for the next scan. Most of the box is
        // outside the scan's fan: eight marks at a time are passed over.
        for (row, marks) in marks.chunks_exact_mut(box_w).enumerate() {
            let y = by + row as i64;
            let first = y * w + bx;
            for (chunk, eight) in marks.chunks_mut(8).enumerate() {
                if let Ok(word) = <[u8; 8]>::try_from(&*eight)
                    && u64::from_ne_bytes(word) == 0
                {
                    continue;
                }
                for (x, mark) in eight.iter_mut().enumerate() {
                    let column = (chunk * 8 + x) as i64;
                    if *mark & (CROSSED | ENDS_A_HIT) == CROSSED {
                        update(Layer::First, (first + column) as usize, MISS);
                    }
                    if *mark & (CROSSED_SECOND | ENDS_A_HIT_SECOND) == CROSSED_SECOND
                        && let Some(i) = second_index((bx + column, y))
                    {
                        update(Layer::Second, i, MISS);
                    }
                    *mark = 0;
                }
            }
        }
    });
}

/// A mark of the scan being traced: a beam crosses the cell, or a clipped beam ends in it.
const CROSSED: u8 = 1;
/// A mark: a hit ends in the cell (whatever beams cross it).
const ENDS_A_HIT: u8 = 2;
/// A mark: a walk ended in the cell (a walk stops before its last cell, so that alone is no
/// miss), and need not be walked to again.
const WALKED: u8 = 4;
/// [`CROSSED`] for the second grid of [`trace_once_per_scan`].
const CROSSED_SECOND: u8 = 8;
/// [`ENDS_A_HIT`] for the second grid.
const ENDS_A_HIT_SECOND: u8 = 16;
/// [`WALKED`] by a walk that marked the second grid too.
const WALKED_BOTH: u8 = WALKED | 32;

std::thread_local! {
    /// Scratch marks for [`trace_beams`]'s once-a-scan rule, all zero between scans: kept
    /// from scan to scan because a fresh box of a quarter of a megabyte is a fresh set of
    /// zeroed pages each time.
    static SCAN_MARKS: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// [`walk`], adding `mark` to each cell's mark in `marks` instead of calling a visitor,
/// where a cell's mark lies at `at` plus its column's offset from `from`'s plus `row` per
/// row. The steps are counted and taken by arithmetic rather than branches: along a
/// diagonal beam which axis a step moves on is a coin toss to a branch predictor, and a
/// keyframe's beams cross a hundred thousand cells.
fn walk_marking(
    from: (i64, i64),
    (ex, ey): (i64, i64),
    at: i64,
    row: i64,
    marks: &mut [u8],
    mark: u8,
) {
    let (sx, sy) = from;
    let (dx, dy) = ((ex - sx).abs(), -(ey - sy).abs());
    let (stx, row_step) = ((ex - sx).signum(), (ey - sy).signum() * row);
    let mut err = dx + dy;
    let mut k = at;
    // Every step moves along the longer axis, so the walk takes that many steps.
    for _ in 0..dx.max(-dy) {
        marks[k as usize] |= mark;
        let e2 = 2 * err;
        let (step_x, step_y) = (i64::from(e2 >= dy), i64::from(e2 <= dx));
        err += step_x * dy + step_y * dx;
        k += step_x * stx + step_y * row_step;
    }
}

/// Bresenham's line from cell `from` to cell `to`, calling `visit` on every cell before `to`.
fn walk(from: (i64, i64), (ex, ey): (i64, i64), mut visit: impl FnMut(i64, i64)) {
    let (sx, sy) = from;
    let (dx, dy) = ((ex - sx).abs(), -(ey - sy).abs());
    let (stx, sty) = ((ex - sx).signum(), (ey - sy).signum());
    let (mut x, mut y, mut err) = (sx, sy, dx + dy);
    while (x, y) != (ex, ey) {
        visit(x, y);
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += stx;
        }
        if e2 <= dx {
            err += dx;
            y += sty;
        }
    }
}

/// How far off an empty grid its first content may lie and the grid still stretch to it,
/// metres; farther, the grid moves to it instead. 100 m of 5 cm cells is 2,000 cells a side,
/// while a wheel frame that starts 800 km out would ask for 16 million. Within it the grids
/// keep the geometry they always had (a rover's maps stretch to the frame's zero): moving
/// them too changed every default mission and gained nothing over 48 of them (BENCHMARKS.md,
/// ninety-fourth session).
pub(crate) const MAX_STRETCH_M: f64 = 100.0;

/// Whether the world box `[min, max]` lies more than [`MAX_STRETCH_M`] off the grid `g`
/// along either axis.
pub(crate) fn far_off(g: &GridGeometry, min: Point2, max: Point2) -> bool {
    let gap_x = (g.origin.x_m - max.x_m).max(min.x_m - (g.origin.x_m + g.width_m()));
    let gap_y = (g.origin.y_m - max.y_m).max(min.y_m - (g.origin.y_m + g.height_m()));
    gap_x.max(gap_y) > MAX_STRETCH_M
}

/// The corner of a grid of `r`-metre cells (on the lattice of the world origin) that holds
/// `min` with `margin` cells to spare below and to the left.
pub(crate) fn corner_before(min: Point2, r: f64, margin: usize) -> Point2 {
    Point2::new(
        (min.x_m / r).floor() * r - margin as f64 * r,
        (min.y_m / r).floor() * r - margin as f64 * r,
    )
}

/// The cells a `width` x `height` grid of `r`-metre cells with its corner at `origin` must
/// grow by, `[left, bottom, right, top]`, to hold the world box `[min, max]`, each side that
/// grows getting `margin` cells more (so growing is rare); `None` if it holds it already.
pub(crate) fn growth(
    origin: Point2,
    r: f64,
    width: usize,
    height: usize,
    min: Point2,
    max: Point2,
    margin: usize,
) -> Option<[usize; 4]> {
    let cx0 = ((min.x_m - origin.x_m) / r).floor();
    let cy0 = ((min.y_m - origin.y_m) / r).floor();
    let cx1 = ((max.x_m - origin.x_m) / r).floor();
    let cy1 = ((max.y_m - origin.y_m) / r).floor();
    if cx0 >= 0.0 && cy0 >= 0.0 && cx1 < width as f64 && cy1 < height as f64 {
        return None;
    }
    let below = |c: f64| if c < 0.0 { (-c) as usize + margin } else { 0 };
    let beyond = |c: f64, n: usize| {
        if c >= n as f64 {
            c as usize + 1 - n + margin
        } else {
            0
        }
    };
    Some([
        below(cx0),
        below(cy0),
        beyond(cx1, width),
        beyond(cy1, height),
    ])
}

/// The row-major `cells` of a `width` x `height` grid, grown by `[left, bottom, right, top]`
/// cells filled with `fill`.
pub(crate) fn regrow<T: Copy>(
    cells: &[T],
    width: usize,
    height: usize,
    grow: [usize; 4],
    fill: T,
) -> Vec<T> {
    let [left, bottom, right, top] = grow;
    let w2 = width + left + right;
    let mut out = vec![fill; w2 * (height + bottom + top)];
    for y in 0..height {
        let dst = (y + bottom) * w2 + left;
        out[dst..dst + width].copy_from_slice(&cells[y * width..(y + 1) * width]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beams_clear_free_space_and_mark_hits_and_the_grid_grows() {
        let mut g = OccupancyGrid::new(0.1);
        // Sensor and beams on cell centres, so the traced cells are unambiguous.
        let sensor = Point2::new(0.05, 0.05);
        let beams = [
            (Point2::new(30.05, 0.05), true),
            (Point2::new(0.05, -19.95), false),
        ];
        for _ in 0..5 {
            g.insert(sensor, &beams);
        }
        let states = g.states();
        let at = |x, y| {
            *states
                .at_world(Point2::new(x, y))
                .expect("inside the grown grid")
        };
        assert_eq!(at(30.05, 0.05), CellState::Occupied);
        assert_eq!(at(15.05, 0.05), CellState::Free);
        assert_eq!(
            at(0.05, -19.95),
            CellState::Free,
            "a max-range reading only clears"
        );
        assert_eq!(at(5.05, 5.05), CellState::Unknown);
        let (p, _) = g.probability_and_gradient(Point2::new(30.05, 0.05));
        assert!(p > 0.9, "{p}");
    }

    #[test]
    fn a_face_reached_from_behind_is_told_from_one_reached_over_the_open_ground_it_was_seen_across()
    {
        // A block's east face at x = 1.25 m, seen from the east only, as a submap begun
        // beside a lander sees it; the block's inside and its west face are never seen.
        let mut g = OccupancyGrid::new(0.05);
        let face: Vec<Point2> = (0..50)
            .map(|k| Point2::new(1.25 + 0.025, -1.225 + 0.05 * k as f64))
            .collect();
        for sensor in [Point2::new(4.0, -0.5), Point2::new(4.0, 0.5)] {
            let beams: Vec<(Point2, bool)> = face.iter().map(|p| (*p, true)).collect();
            for _ in 0..3 {
                g.insert(sensor, &beams);
            }
        }
        let on_face: Vec<Point2> = face[10..40].to_vec();
        // From the east, over the open ground: every hit is on the face, none from behind.
        assert_eq!(
            g.hits_from_behind(Point2::new(3.0, 0.0), on_face.iter().copied(), 0.15),
            (0, 30)
        );
        // From the west, through the block (the west face laid on the east one): all of them.
        assert_eq!(
            g.hits_from_behind(Point2::new(-1.0, 0.0), on_face.iter().copied(), 0.15),
            (30, 30)
        );
        // Points off the face are not counted either way.
        let off: Vec<Point2> = on_face
            .iter()
            .map(|p| Point2::new(p.x_m + 1.0, p.y_m))
            .collect();
        assert_eq!(
            g.hits_from_behind(Point2::new(3.0, 0.0), off.iter().copied(), 0.15),
            (0, 0)
        );
    }

    #[test]
    fn a_scan_clears_a_cell_once_and_never_where_a_beam_ends() {
        let mut g = OccupancyGrid::new(0.1).with_miss_rule(MissRule::OncePerScan);
        let sensor = Point2::new(0.05, 0.05);
        // Two beams along the same row: the near one ends in a cell the far one crosses.
        let beams = [
            (Point2::new(1.05, 0.05), true),
            (Point2::new(2.05, 0.05), true),
            (Point2::new(2.05, 0.05), true),
        ];
        g.insert(sensor, &beams);
        let at = |x: f64| g.log_odds_at(Point2::new(x, 0.05));
        assert_eq!(at(0.55), MISS, "crossed by three beams, one observation");
        assert_eq!(at(1.05), HIT, "a hit, though two beams pass through");
        assert_eq!(at(1.55), MISS);
        assert_eq!(at(2.05), 2.0 * HIT, "two endpoints in one cell");
        assert_eq!(at(2.55), 0.0);
        // Beam by beam, each crossing is a miss, and the far beams clear the near one's hit.
        let mut g = OccupancyGrid::new(0.1);
        g.insert(sensor, &beams);
        let at = |x: f64| g.log_odds_at(Point2::new(x, 0.05));
        assert_eq!(at(0.55), 3.0 * MISS);
        assert_eq!(at(1.05), HIT + 2.0 * MISS);
    }

    /// The summed log-odds of the column of cells just in front of a wall and of the column
    /// just behind it, after 10 scans of 41 beams a degree apart from (0, 0) with noise of
    /// 2 cm: the wall is the line `x = 5` (a cell boundary), and the grid clears cells by
    /// `rule` and `margin`.
    fn wall_columns(rule: MissRule, margin: Option<MissMargin>) -> (f32, f32) {
        let mut g = OccupancyGrid::new(0.05)
            .with_miss_rule(rule)
            .with_miss_margin(margin);
        let mut state = 7u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        for _ in 0..10 {
            let beams: Vec<(Point2, bool)> = (-20..=20)
                .map(|k| {
                    let angle = (k as f64).to_radians();
                    let (u, v) = (uniform(), uniform());
                    let noise = 0.02 * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos();
                    let r = 5.0 / angle.cos() + noise;
                    (Point2::new(r * angle.cos(), r * angle.sin()), true)
                })
                .collect();
            g.insert(Point2::new(0.0, 0.0), &beams);
        }
        let column = |x: f64| -> f32 {
            (-40..40)
                .map(|row| g.log_odds_at(Point2::new(x, 0.025 + 0.05 * row as f64)))
                .sum()
        };
        (column(4.975), column(5.025))
    }

    #[test]
    fn beams_stopped_short_of_their_hits_draw_a_noisy_wall_where_it_is() {
        for rule in [MissRule::OncePerScan, MissRule::EveryBeam] {
            // A beam carried past the wall into the cell behind it crosses the cell in front
            // and clears it: the wall's evidence lies behind it.
            let (front, behind) = wall_columns(rule, None);
            assert!(front < 0.7 * behind, "{rule:?}: {front} / {behind}");
            // Stopped three standard deviations short, the cells on both sides are left to
            // the hits, which fall on either side alike.
            let margin = MissMargin {
                base_m: 0.06,
                per_m: 0.0,
            };
            let (front, behind) = wall_columns(rule, Some(margin));
            assert!(
                (front - behind).abs() < 0.05 * behind,
                "{rule:?}: {front} / {behind}"
            );
        }
    }

    #[test]
    fn points_filled_in_between_beams_are_hits_without_beams_of_their_own() {
        let sensor = Point2::new(0.05, 0.05);
        // Two beams along the axes and a filled-in point on the diagonal between their ends.
        let ends = [Point2::new(2.05, 0.05), Point2::new(0.05, 2.05)];
        let filled = (Point2::new(1.05, 1.05), true);
        let endpoints = [(ends[0], true), filled, (ends[1], true)];
        for rule in [MissRule::OncePerScan, MissRule::EveryBeam] {
            let mut g = OccupancyGrid::new(0.1).with_miss_rule(rule);
            g.insert_with_rays(sensor, &endpoints, Some(&ends));
            let at = |x: f64, y: f64| g.log_odds_at(Point2::new(x, y));
            assert_eq!(
                at(1.05, 1.05),
                HIT,
                "{rule:?}: the filled-in point is a hit"
            );
            assert_eq!(at(0.55, 0.55), 0.0, "{rule:?}: no beam runs to it");
            assert_eq!(
                at(1.05, 0.05),
                MISS,
                "{rule:?}: the beams clear their own cells"
            );
            assert_eq!(at(2.05, 0.05), HIT);
            // Traced to every endpoint, the diagonal is cleared too.
            let mut g = OccupancyGrid::new(0.1).with_miss_rule(rule);
            g.insert(sensor, &endpoints);
            assert_eq!(g.log_odds_at(Point2::new(0.55, 0.55)), MISS, "{rule:?}");
        }
    }

    #[test]
    fn the_fast_floors_are_floor() {
        for v in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1.000_000_1,
            2.999_999_9,
            -2.999_999_9,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            4_503_599_627_370_497.0,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            assert_eq!(floor_f64(v), v.floor(), "{v}");
            assert_eq!(
                floor_f64(v).is_sign_negative(),
                v.floor().is_sign_negative(),
                "{v}"
            );
            assert_eq!(floor_to_i64(v), v.floor() as i64, "{v}");
        }
        assert!(floor_f64(f64::NAN).is_nan());
        assert_eq!(floor_to_i64(f64::NAN), f64::NAN.floor() as i64);
    }

    #[test]
    fn the_marking_walk_crosses_the_cells_of_the_cell_walk() {
        // Every direction and length out to 12 cells, from a cell inside a 64-bit row.
        let (row, start) = (64i64, (30i64, 30i64));
        for ex in 18..=42 {
            for ey in 18..=42 {
                let mut expected = vec![0u8; 64 * 64];
                walk(start, (ex, ey), |x, y| {
                    expected[(y * row + x) as usize] = CROSSED
                });
                let mut marks = vec![0u8; 64 * 64];
                walk_marking(
                    start,
                    (ex, ey),
                    start.1 * row + start.0,
                    row,
                    &mut marks,
                    CROSSED,
                );
                assert_eq!(marks, expected, "to ({ex}, {ey})");
            }
        }
    }

    proptest::proptest! {
        /// The once-a-scan rule as its definition: every endpoint a hit where marked one, once
        /// per endpoint; every other cell a beam crosses or ends in a single miss.
        #[test]
        fn a_scan_updates_each_cell_as_the_rule_defines(
            sensor in (-3.0f64..3.0, -3.0f64..3.0),
            ends in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, proptest::bool::ANY), 1..60),
            // Far, or within a few cells, where beams end in the same cells and in the
            // sensor's own.
            spread_m in proptest::prop_oneof![proptest::strategy::Just(6.0f64), proptest::strategy::Just(0.2)],
            with_rays in proptest::bool::ANY,
        ) {
            let lattice = Lattice { origin: Point2::new(-10.0, -10.0), resolution_m: 0.05, width: 400 };
            let sensor = Point2::new(sensor.0, sensor.1);
            let endpoints: Vec<(Point2, bool)> = ends
                .iter()
                .map(|&(u, v, hit)| {
                    (Point2::new(sensor.x_m + u * spread_m, sensor.y_m + v * spread_m), hit)
                })
                .collect();
            // Rays to every other endpoint, as filled-in scans trace them.
            let rays: Vec<Point2> = endpoints.iter().step_by(2).map(|(p, _)| *p).collect();
            let rays = with_rays.then_some(rays.as_slice());
            let mut got = std::collections::BTreeMap::new();
            trace_beams(&lattice, sensor, &endpoints, rays, (MissRule::OncePerScan, None), |i, d| {
                *got.entry(i).or_insert(0.0f32) += d;
            });
            let cell = |p: Point2| {
                (((p.x_m + 10.0) / 0.05).floor() as i64, ((p.y_m + 10.0) / 0.05).floor() as i64)
            };
            let index = |(x, y): (i64, i64)| (y * 400 + x) as usize;
            let mut expected = std::collections::BTreeMap::new();
            for (p, hit) in &endpoints {
                if *hit {
                    *expected.entry(index(cell(*p))).or_insert(0.0f32) += HIT;
                }
            }
            let mut crossed = std::collections::BTreeSet::new();
            let traced: Vec<Point2> = match rays {
                Some(r) => r.to_vec(),
                None => endpoints.iter().map(|(p, _)| *p).collect(),
            };
            for p in traced {
                walk(cell(sensor), cell(p), |x, y| { crossed.insert(index((x, y))); });
            }
            for (p, _) in &endpoints {
                crossed.insert(index(cell(*p)));
            }
            for i in crossed {
                expected.entry(i).or_insert(MISS);
            }
            proptest::prop_assert_eq!(got, expected);
        }
    }

    /// Scan `k` of a sensor moving diagonally: 90 beams of ranges 2-3.8 m, every
    /// eleventh a miss.
    fn scan(k: usize) -> (Point2, Vec<(Point2, bool)>) {
        let sensor = Point2::new(0.3 * k as f64, 0.1 * k as f64);
        let ends = (0..90)
            .map(|b| {
                let a = b as f64 * 4f64.to_radians();
                let r = 2.0 + (b % 7) as f64 * 0.3;
                (
                    Point2::new(sensor.x_m + r * a.cos(), sensor.y_m + r * a.sin()),
                    b % 11 != 0,
                )
            })
            .collect();
        (sensor, ends)
    }

    /// A grid's answers to lookups across its content's edge and far outside it, on and
    /// off cell centres, as bits.
    fn probe(g: &OccupancyGrid) -> Vec<u64> {
        (0..6400)
            .flat_map(|i| {
                let p = Point2::new(
                    -7.0 + (i % 80) as f64 * 0.1913,
                    -7.0 + (i / 80) as f64 * 0.1717,
                );
                let (v, [gx, gy]) = g.probability_and_gradient(p);
                [
                    v.to_bits(),
                    gx.to_bits(),
                    gy.to_bits(),
                    g.log_odds_at(p).to_bits() as u64,
                ]
            })
            .collect()
    }

    /// A scan of [`scan`] with beams that returned nothing too, cut at 5 m, after its hits
    /// (returned as the count of hits and the rays: every other hit's beam, then those).
    fn scan_with_clear_rays(k: usize) -> (Point2, Vec<(Point2, bool)>, usize, Vec<Point2>) {
        let (sensor, mut ends) = scan(k);
        let hits = ends.len();
        ends.extend((0..45).map(|b| {
            let a = (2.0 + b as f64 * 8.0).to_radians();
            (
                Point2::new(sensor.x_m + 5.0 * a.cos(), sensor.y_m + 5.0 * a.sin()),
                false,
            )
        }));
        let rays = ends
            .iter()
            .enumerate()
            .filter(|(i, _)| *i >= hits || i % 2 == 0)
            .map(|(_, (p, _))| *p)
            .collect();
        (sensor, ends, hits, rays)
    }

    /// One walk along each beam marking a published grid and the matching grid beside it:
    /// the matching grid, whose beams stop short of their hits, comes out as traced alone,
    /// and the published grid as traced alone but for cells at the side of its beams, each
    /// bent by up to a cell where the matching beam stops.
    #[test]
    fn grids_traced_on_shared_walks_answer_as_each_traced_alone() {
        let margin = Some(MissMargin {
            base_m: 0.03,
            per_m: 0.006,
        });
        let (mut free, mut free_shared) = (0, 0);
        for with_rays in [false, true] {
            let published = OccupancyGrid::new(0.05)
                .with_miss_rule(MissRule::OncePerScan)
                .without_probabilities();
            let matched = OccupancyGrid::new(0.05)
                .with_miss_rule(MissRule::OncePerScan)
                .with_miss_margin(margin);
            let (mut published_shared, mut matched_shared) = (published.clone(), matched.clone());
            let mut matched_all_apart = matched.clone();
            for k in 0..6 {
                // Each scan alone into fresh grids, and all of them into grids that grow.
                let (mut published_apart, mut matched_apart) = (published.clone(), matched.clone());
                let (mut published_once, mut matched_once) = (published.clone(), matched.clone());
                let (sensor, ends, hits, rays) = scan_with_clear_rays(k);
                let rays = with_rays.then_some(&rays[..]);
                let matched_rays = hits.div_ceil(2);
                published_apart.insert_with_rays(sensor, &ends, rays);
                for matched in [&mut matched_apart, &mut matched_all_apart] {
                    matched.insert_with_rays(
                        sensor,
                        &ends[..hits],
                        rays.map(|r| &r[..matched_rays]),
                    );
                }
                for (published, matched) in [
                    (&mut published_once, &mut matched_once),
                    (&mut published_shared, &mut matched_shared),
                ] {
                    published.insert_with_rays_beside(
                        matched,
                        sensor,
                        &ends,
                        rays,
                        (hits, matched_rays),
                    );
                }
                assert_eq!(matched_once.geometry(), matched_apart.geometry());
                assert_eq!(matched_once.log_odds(), matched_apart.log_odds());
                assert_eq!(matched_once.probabilities(), matched_apart.probabilities());
                assert_eq!(published_once.geometry(), published_apart.geometry());
                let cell =
                    |x: i64, y: i64| Point2::new(x as f64 * 0.05 + 0.025, y as f64 * 0.05 + 0.025);
                let free_in = |g: &OccupancyGrid, x: i64, y: i64| g.log_odds_at(cell(x, y)) < 0.0;
                for (x, y) in (-200..200).flat_map(|y| (-200..200).map(move |x| (x, y))) {
                    let (apart, once) = (
                        published_apart.log_odds_at(cell(x, y)),
                        published_once.log_odds_at(cell(x, y)),
                    );
                    assert_eq!(
                        apart > 0.0,
                        once > 0.0,
                        "scan {k}, rays {with_rays}: cell ({x}, {y}) a hit in one grid only"
                    );
                    free += usize::from(apart < 0.0);
                    free_shared += usize::from(once < 0.0);
                    if (apart < 0.0) == (once < 0.0) {
                        continue;
                    }
                    // Free in one grid only: a cell of a beam that bends, free in the other
                    // grid next to it.
                    let (this, other) = if apart < 0.0 {
                        (&published_apart, &published_once)
                    } else {
                        (&published_once, &published_apart)
                    };
                    assert!(free_in(this, x, y));
                    assert!(
                        (-1..=1).any(|dy| (-1..=1).any(|dx| free_in(other, x + dx, y + dy))),
                        "scan {k}, rays {with_rays}: cell ({x}, {y}) free in one grid, nothing free next to it in the other"
                    );
                }
            }
            // Grown over six scans, the matching grid is still the one traced alone.
            assert_eq!(matched_shared.geometry(), matched_all_apart.geometry());
            assert_eq!(matched_shared.log_odds(), matched_all_apart.log_odds());
        }
        // A bend trades a cell for its neighbour: about as many cells are cleared.
        assert!(
            free_shared.abs_diff(free) * 100 < free,
            "{free_shared} free cells against {free}"
        );
    }

    /// A grid that keeps no probabilities answers every lookup as one that does, through
    /// growth, cuts and being made whole: only the cost differs.
    #[test]
    fn a_grid_without_probabilities_answers_as_one_with_them() {
        let mut with = OccupancyGrid::new(0.05).with_miss_rule(MissRule::OncePerScan);
        let mut without = with.clone().without_probabilities();
        for k in 0..6 {
            let (sensor, ends) = scan(k);
            with.insert(sensor, &ends);
            without.insert(sensor, &ends);
            assert!(without.is_whole());
            assert_eq!(probe(&without), probe(&with), "after scan {k}");
            if k == 3 {
                with.cut_to_content();
                without.cut_to_content();
                assert_eq!(probe(&without), probe(&with));
            }
        }
        without.observe_cells(&[(Point2::new(9.0, 9.0), true)]);
        with.observe_cells(&[(Point2::new(9.0, 9.0), true)]);
        without.make_whole();
        assert!(without.is_whole());
        assert_eq!(without.geometry(), with.geometry());
        assert_eq!(without.log_odds(), with.log_odds());
        assert_eq!(without.probabilities(), with.probabilities());
        assert_eq!(probe(&without), probe(&with));
        // It keeps one value a cell, not two.
        assert!(without.prob.is_empty());
        without.release();
        with.release();
        assert_eq!(probe(&without), probe(&with));
    }

    /// A finished submap's grid is cut to its content: every lookup must give the same bits
    /// as before, a grid updated meanwhile must end as one that stayed whole, and the grid
    /// made whole again must hold the same cells and probabilities.
    #[test]
    fn a_grid_cut_to_its_content_answers_as_the_whole_grid() {
        let mut whole = OccupancyGrid::new(0.05).with_miss_rule(MissRule::OncePerScan);
        for k in 0..3 {
            let (sensor, ends) = scan(k);
            whole.insert(sensor, &ends);
        }
        let mut cut = whole.clone();
        cut.cut_to_content();
        assert!(!cut.is_whole());
        assert_eq!(probe(&cut), probe(&whole));
        assert_eq!(cut.geometry(), whole.geometry());
        assert_eq!(cut.log_odds(), whole.log_odds());
        assert_eq!(cut.probabilities(), whole.probabilities());
        assert_eq!(cut.states().cells(), whole.states().cells());
        // The kept cells are the content's only: fewer than half the grid's.
        let (kept, kept_cells) = cut.kept_log_odds();
        assert_eq!(kept_cells.len(), kept.width * kept.height);
        assert!(kept_cells.len() * 2 < whole.log_odds().len(), "{kept:?}");
        // Updated after the cut (the grid grows too), and cut again.
        for k in 3..6 {
            let (sensor, ends) = scan(k);
            whole.insert(sensor, &ends);
            cut.insert(sensor, &ends);
            assert_eq!(probe(&cut), probe(&whole));
            cut.cut_to_content();
        }
        assert_eq!(probe(&cut), probe(&whole));
        cut.make_whole();
        assert!(cut.is_whole());
        assert_eq!(cut.kept_log_odds().1, whole.kept_log_odds().1);
        assert_eq!(cut.probabilities(), whole.probabilities());
    }

    /// A grid with nothing in it is cut to no cells and still answers as empty.
    #[test]
    fn an_empty_grid_cut_to_its_content_keeps_no_cells() {
        let mut g = OccupancyGrid::new(0.1);
        g.cut_to_content();
        assert!(g.kept_log_odds().1.is_empty());
        assert_eq!(g.log_odds_at(Point2::new(0.0, 0.0)), 0.0);
        assert_eq!(
            g.probability_and_gradient(Point2::new(0.33, -0.21)),
            (0.5, [0.0, 0.0])
        );
        g.make_whole();
        assert_eq!(g.log_odds().len(), g.geometry().len());
    }

    #[test]
    fn the_probability_cache_gives_what_probability_gives() {
        let mut cache = ProbabilityCache::new();
        // Values colliding in the cache's slots, repeated, and the NaN its slots start at.
        let mut values: Vec<f32> = (0..400)
            .map(|k| (k as f32 * 0.0173 - 3.5).sin() * 4.0)
            .collect();
        values.extend([0.0, -0.0, -4.0, 4.0, f32::from_bits(u32::MAX), f32::NAN]);
        for _ in 0..3 {
            for l in &values {
                assert_eq!(cache.of(*l).to_bits(), probability(*l).to_bits(), "{l}");
            }
        }
    }
}
