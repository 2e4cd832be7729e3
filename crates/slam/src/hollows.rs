//! Ground hidden inside a depression. The lidar passes over a crater and calls its bowl
//! free; the depth camera, looking over the rim from outside, sees the far inner wall and
//! the bowl's hidden stretches it can prove lower than the floor, but from beside the rim
//! (the camera looking along it) and across the bowl's middle it judges nothing. What is
//! left is a patch of ground the lidar saw open and the camera never judged, walled in by
//! hazard on nearly every side: a hollow in the hazard layer. No viewpoint outside the
//! crater shows it, so a rover exploring until the ground is judged would drive round it
//! for nothing; and ground enclosed by a crater's walls is its inside.
//!
//! Each patch (4-connected cells the layer has not judged and `open` holds at) that touches
//! hazard is flooded; it is taken for a hollow, and marked hazard, when hazard makes up at
//! least [`HazardHollows::min_hazard_share`] of its border and it is no larger than a
//! crater's disc. A patch behind a rock or along a wall's foot is bordered by ground the
//! camera judged safe too, and stays as it is.

use crate::occupancy::CellState;
use realms_core::{Cell, Grid, Point2};

/// Which patches of unjudged ground count as hollows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HazardHollows {
    /// The share of a patch's border (cell sides) that must be hazard.
    pub min_hazard_share: f64,
    /// The largest patch taken, square metres: a crater's disc at most.
    pub max_area_m2: f64,
}

impl Default for HazardHollows {
    fn default() -> Self {
        HazardHollows {
            // Half marked a little more of the crater cells near the rovers' paths on the
            // same paths, and leaves more to chance where a patch's border is half floor
            // (BENCHMARKS.md, "Hollows in the hazard layer").
            min_hazard_share: 0.6,
            // A disc of 4.5 m radius: the scenario's largest crater is 3 m.
            max_area_m2: 64.0,
        }
    }
}

/// What a cell of the flood is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mark {
    /// Not asked yet.
    Unasked,
    /// Unjudged and open: may join a patch.
    Open,
    /// Anything else (judged, or not open).
    Closed,
    /// Taken into a patch already.
    Flooded,
    /// Part of a patch too large to be a hollow, found so before it was flooded whole.
    Big,
}

/// Cells of the layer (in row order) tested for hazard at once: most runs of cells hold
/// none, and a run tested without an early exit is tested many cells at a time.
const CHUNK: usize = 32;

/// Finds hollows ([`HollowFinder::fill`]), keeping its buffers from one layer to the next:
/// the layer is asked for every map the rover publishes.
#[derive(Clone, Debug, Default)]
pub struct HollowFinder {
    cfg: HazardHollows,
    marks: Vec<Mark>,
    /// Cells a flood has yet to start runs from, with where they lie (so no index is
    /// divided by the layer's width for every run a flood reaches).
    stack: Vec<(usize, Cell)>,
    /// The flood's runs of cells along rows, first and last index.
    runs: Vec<(usize, usize)>,
    hollows: Vec<usize>,
}

/// A flood's count of its patch's border: cell sides it shares with cells outside the patch
/// (the layer's edge included), and those of them that are hazard.
#[derive(Clone, Copy, Debug, Default)]
struct Border {
    sides: usize,
    hazard_sides: usize,
}

impl HollowFinder {
    /// A finder of hollows as `cfg` defines them.
    pub fn new(cfg: HazardHollows) -> Self {
        HollowFinder {
            cfg,
            ..HollowFinder::default()
        }
    }

    /// Marks hazard (`Occupied`) every hollow of `states`: see the module's doc. `open(p)`
    /// says whether the ground at `p` (a cell's centre) was seen open, by the lidar. Returns
    /// the cells marked.
    pub fn fill(&mut self, states: &mut Grid<CellState>, open: impl Fn(Point2) -> bool) -> usize {
        let g = *states.geometry();
        self.fill_cells(states, |cell| open(g.cell_center(cell)))
    }

    /// [`fill`](Self::fill), with `open(cell)` saying whether the ground of the layer's cell
    /// was seen open: a caller that holds the lidar's map on another grid can look each cell
    /// up by table ([`realms_core::CentreLookup`]) rather than by its centre's coordinates.
    ///
    /// Each patch is flooded a run of cells along a row at a time (the scanline fill of
    /// computer graphics, e.g. Heckbert, "A Seed Fill Algorithm", Graphics Gems, 1990): a
    /// row's cells are asked in order, where a flood cell by cell went back and forth
    /// between rows for every cell.
    pub fn fill_cells(
        &mut self,
        states: &mut Grid<CellState>,
        open: impl Fn(Cell) -> bool,
    ) -> usize {
        let g = *states.geometry();
        let (w, h) = (g.width, g.height);
        self.marks.clear();
        self.marks.resize(w * h, Mark::Unasked);
        self.hollows.clear();
        let layer = Layer {
            cells: states.cells(),
            open,
            width: w,
            height: h,
            max_cells: (self.cfg.max_area_m2 / (g.resolution_m * g.resolution_m)) as usize,
        };
        for (y, row) in layer.cells.chunks_exact(w.max(1)).enumerate() {
            for (chunk_x, chunk) in (0..).step_by(CHUNK).zip(row.chunks(CHUNK)) {
                let any_hazard = chunk
                    .iter()
                    .fold(false, |any, c| any | (*c == CellState::Occupied));
                if !any_hazard {
                    continue;
                }
                for (x, _) in (chunk_x..)
                    .zip(chunk)
                    .filter(|(_, c)| **c == CellState::Occupied)
                {
                    let seed = y * w + x;
                    // The four neighbours, each if inside the layer (the others' index and
                    // cell wrap, unread).
                    let starts = [
                        (x > 0, seed.wrapping_sub(1), x.wrapping_sub(1), y),
                        (x + 1 < w, seed + 1, x + 1, y),
                        (y > 0, seed.wrapping_sub(w), x, y.wrapping_sub(1)),
                        (y + 1 < h, seed + w, x, y + 1),
                    ];
                    for (inside, start, x, y) in starts {
                        // Most cells beside hazard are hazard or judged: no patch starts there.
                        if !inside
                            || layer.cells[start] != CellState::Unknown
                            || !layer.is_open(&mut self.marks, start, Cell { x, y })
                        {
                            continue;
                        }
                        let patch =
                            layer.flood(&mut self.marks, &mut self.stack, &mut self.runs, start);
                        if patch.is_some_and(|b| {
                            b.hazard_sides as f64 >= self.cfg.min_hazard_share * b.sides as f64
                        }) {
                            for &(first, last) in &self.runs {
                                self.hollows.extend(first..=last);
                            }
                        }
                    }
                }
            }
        }
        let cells = states.cells_mut();
        for &i in &self.hollows {
            cells[i] = CellState::Occupied;
        }
        self.hollows.len()
    }
}

/// The layer a [`HollowFinder`] floods, and what it asks of it.
struct Layer<'a, F> {
    cells: &'a [CellState],
    open: F,
    width: usize,
    height: usize,
    /// The most cells a hollow has.
    max_cells: usize,
}

impl<F: Fn(Cell) -> bool> Layer<'_, F> {
    /// Whether cell `i` (at `cell`) may join a patch; asks `open` once a cell, and only of
    /// the cells a flood reaches.
    #[inline]
    fn is_open(&self, marks: &mut [Mark], i: usize, cell: Cell) -> bool {
        if marks[i] == Mark::Unasked {
            marks[i] = if self.cells[i] == CellState::Unknown && (self.open)(cell) {
                Mark::Open
            } else {
                Mark::Closed
            };
        }
        marks[i] == Mark::Open
    }

    /// A side the patch shares with cell `j` outside it (asked already): counted, or the
    /// flood is part of a patch found too large (`None`).
    #[inline]
    fn border(&self, marks: &[Mark], j: usize, b: &mut Border) -> Option<()> {
        if marks[j] == Mark::Big {
            return None;
        }
        b.sides += 1;
        b.hazard_sides += usize::from(self.cells[j] == CellState::Occupied);
        Some(())
    }

    /// Floods the patch of open cell `start` into `runs` (each run's first and last index),
    /// a run of cells along a row at a time; returns its border, or `None` for a patch too
    /// large to be a hollow (its cells, and those waiting on `stack`, then marked so).
    fn flood(
        &self,
        marks: &mut [Mark],
        stack: &mut Vec<(usize, Cell)>,
        runs: &mut Vec<(usize, usize)>,
        start: usize,
    ) -> Option<Border> {
        let w = self.width;
        stack.push((
            start,
            Cell {
                x: start % w,
                y: start / w,
            },
        ));
        runs.clear();
        let mut b = Border::default();
        // The ground the lidar sees beyond what the camera has judged is one wide patch
        // along the hall's walls: once a flood is too large for a hollow it stops, and a
        // later flood that meets it is the same patch.
        let patch = self.runs_of_patch(marks, stack, runs, &mut b);
        if patch.is_none() {
            for &(first, last) in runs.iter() {
                marks[first..=last].fill(Mark::Big);
            }
            for &(i, _) in stack.iter() {
                if marks[i] == Mark::Open {
                    marks[i] = Mark::Big;
                }
            }
            stack.clear();
        }
        patch.map(|()| b)
    }

    /// [`flood`](Self::flood)'s runs, until the stack is empty (`Some`) or the patch is
    /// found too large (`None`).
    fn runs_of_patch(
        &self,
        marks: &mut [Mark],
        stack: &mut Vec<(usize, Cell)>,
        runs: &mut Vec<(usize, usize)>,
        b: &mut Border,
    ) -> Option<()> {
        let (w, h) = (self.width, self.height);
        let mut count = 0usize;
        while let Some((i, Cell { x, y })) = stack.pop() {
            if marks[i] != Mark::Open {
                // Taken into a run since it was pushed.
                continue;
            }
            let row = i - x;
            // The whole run of open cells along the row through it: its neighbours along
            // the row are open only if they join it.
            let (mut x0, mut x1) = (x, x);
            while x0 > 0 && self.is_open(marks, row + x0 - 1, Cell { x: x0 - 1, y }) {
                x0 -= 1;
            }
            while x1 + 1 < w && self.is_open(marks, row + x1 + 1, Cell { x: x1 + 1, y }) {
                x1 += 1;
            }
            marks[row + x0..=row + x1].fill(Mark::Flooded);
            runs.push((row + x0, row + x1));
            count += x1 - x0 + 1;
            if count > self.max_cells {
                return None;
            }
            for (end, beyond) in [
                (x0 > 0, (row + x0).wrapping_sub(1)),
                (x1 + 1 < w, row + x1 + 1),
            ] {
                if end {
                    self.border(marks, beyond, b)?;
                } else {
                    // The layer's edge borders on nothing judged.
                    b.sides += 1;
                }
            }
            for (ny, inside) in [(y.wrapping_sub(1), y > 0), (y + 1, y + 1 < h)] {
                if !inside {
                    b.sides += x1 - x0 + 1;
                    continue;
                }
                // A run in the next row is started once, from its first cell beside this
                // one.
                let mut in_run = false;
                for nx in x0..=x1 {
                    let j = ny * w + nx;
                    if marks[j] == Mark::Flooded {
                        in_run = false;
                        continue;
                    }
                    let cell = Cell { x: nx, y: ny };
                    if marks[j] != Mark::Big && self.is_open(marks, j, cell) {
                        if !in_run {
                            stack.push((j, cell));
                        }
                        in_run = true;
                    } else {
                        in_run = false;
                        self.border(marks, j, b)?;
                    }
                }
            }
        }
        Some(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_layers::{layer, set, state_at};
    use realms_core::GridGeometry;

    #[test]
    fn the_unjudged_middle_of_a_crater_ringed_by_hazard_is_marked_and_the_floor_round_it_is_not() {
        // A crater of 2 m radius at (5, 5): the camera judged its walls hazard (the outer
        // metre of its radius) but for a gap of a few cells on the east, where it judged
        // the rim safe; the floor round it is judged safe out to 3 m, beyond that unjudged.
        // The lidar saw everything open.
        let centre = Point2::new(5.0, 5.0);
        let mut g = layer();
        set(&mut g, CellState::Free, |p| p.distance_m(centre) <= 3.0);
        set(&mut g, CellState::Occupied, |p| {
            (1.0..=2.0).contains(&p.distance_m(centre))
        });
        set(&mut g, CellState::Unknown, |p| p.distance_m(centre) < 1.0);
        set(&mut g, CellState::Free, |p| {
            (1.0..=2.0).contains(&p.distance_m(centre)) && (p.y_m - 5.0).abs() < 0.2 && p.x_m > 5.0
        });
        let before = g.clone();
        let marked = HollowFinder::new(HazardHollows::default()).fill(&mut g, |_| true);
        let inside = before
            .cells()
            .iter()
            .zip(g.cells())
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(marked, inside);
        assert!(
            marked > 250,
            "a disc of 1 m radius is some 314 cells: {marked}"
        );
        assert_eq!(state_at(&g, 5.0, 5.0), CellState::Occupied);
        assert_eq!(state_at(&g, 5.6, 5.6), CellState::Occupied);
        // Judged ground is never changed, nor the unjudged floor far outside.
        assert_eq!(state_at(&g, 6.5, 5.0), CellState::Free);
        assert_eq!(state_at(&g, 9.0, 9.0), CellState::Unknown);
    }

    #[test]
    fn unjudged_ground_behind_a_rock_or_along_a_walls_foot_is_left_unjudged() {
        let mut g = layer();
        // The floor judged safe, but for a shadow behind a rock (hazard at x 3.0-3.3) and a
        // strip along a wall's hazard foot at y 8.0-8.2, unjudged beyond it.
        set(&mut g, CellState::Free, |_| true);
        set(&mut g, CellState::Occupied, |p| {
            (3.0..3.3).contains(&p.x_m) && (4.0..4.6).contains(&p.y_m)
        });
        set(&mut g, CellState::Unknown, |p| {
            (3.3..5.0).contains(&p.x_m) && (4.0..4.6).contains(&p.y_m)
        });
        set(&mut g, CellState::Occupied, |p| (8.0..8.2).contains(&p.y_m));
        set(&mut g, CellState::Unknown, |p| p.y_m >= 8.2);
        let before = g.clone();
        assert_eq!(
            HollowFinder::new(HazardHollows::default()).fill(&mut g, |_| true),
            0
        );
        assert!(g == before);
    }

    #[test]
    fn ground_the_lidar_never_saw_open_is_no_hollow() {
        // The same ring as a crater's, but the lidar saw nothing inside it (a tall block's
        // top, say): nothing to mark.
        let centre = Point2::new(5.0, 5.0);
        let mut g = layer();
        set(&mut g, CellState::Occupied, |p| {
            (1.0..=2.0).contains(&p.distance_m(centre))
        });
        let marked = HollowFinder::new(HazardHollows::default())
            .fill(&mut g, |p| p.distance_m(centre) >= 1.0);
        assert_eq!(marked, 0);
        assert_eq!(state_at(&g, 5.0, 5.0), CellState::Unknown);
    }

    #[test]
    fn a_patch_larger_than_a_crater_is_left_alone() {
        // A ring of hazard round a 6 m square patch (36 square metres).
        let mut g = layer();
        set(&mut g, CellState::Occupied, |p| {
            let inside =
                |m: f64| (2.0 - m..8.0 + m).contains(&p.x_m) && (2.0 - m..8.0 + m).contains(&p.y_m);
            inside(0.3) && !inside(0.0)
        });
        let within = HollowFinder::new(HazardHollows::default()).fill(&mut g.clone(), |_| true);
        assert_eq!(within, 3600);
        let cfg = HazardHollows {
            max_area_m2: 30.0,
            ..HazardHollows::default()
        };
        assert_eq!(HollowFinder::new(cfg).fill(&mut g, |_| true), 0);
    }

    /// The hollows by definition: every patch flooded whole, then judged by its size and
    /// its border.
    fn hollows_by_definition(
        states: &Grid<CellState>,
        cfg: &HazardHollows,
        open: impl Fn(usize) -> bool,
    ) -> Vec<bool> {
        let g = states.geometry();
        let (w, h) = (g.width as i64, g.height as i64);
        let cells = states.cells();
        let candidate = |i: usize| cells[i] == CellState::Unknown && open(i);
        let max_cells = (cfg.max_area_m2 / (g.resolution_m * g.resolution_m)) as usize;
        let mut patch_of = vec![usize::MAX; cells.len()];
        let mut out = vec![false; cells.len()];
        for start in 0..cells.len() {
            if !candidate(start) || patch_of[start] != usize::MAX {
                continue;
            }
            let (mut patch, mut stack) = (vec![], vec![start]);
            patch_of[start] = start;
            let (mut hazard_sides, mut sides, mut touches_hazard) = (0, 0, false);
            while let Some(i) = stack.pop() {
                patch.push(i);
                let (x, y) = ((i as i64) % w, (i as i64) / w);
                for (nx, ny) in [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)] {
                    if nx < 0 || ny < 0 || nx >= w || ny >= h {
                        sides += 1;
                        continue;
                    }
                    let j = (ny * w + nx) as usize;
                    if candidate(j) {
                        if patch_of[j] == usize::MAX {
                            patch_of[j] = start;
                            stack.push(j);
                        }
                    } else {
                        sides += 1;
                        if cells[j] == CellState::Occupied {
                            hazard_sides += 1;
                            touches_hazard = true;
                        }
                    }
                }
            }
            if touches_hazard
                && patch.len() <= max_cells
                && hazard_sides as f64 >= cfg.min_hazard_share * sides as f64
            {
                for i in patch {
                    out[i] = true;
                }
            }
        }
        out
    }

    proptest::proptest! {
        /// Floods stopped early, and started only beside hazard, find the same hollows as
        /// whole floods: on random layers of 2 m square with crater-like rings, rocks and
        /// judged ground, the largest hollow a few square metres at most.
        #[test]
        fn floods_stopped_early_find_the_hollows_the_definition_does(
            rings in proptest::collection::vec((0.0f64..2.0, 0.0f64..2.0, 0.1f64..0.8), 0..4),
            blobs in proptest::collection::vec((0.0f64..2.0, 0.0f64..2.0, 0.05f64..0.4, proptest::bool::ANY), 0..8),
            shut in proptest::collection::vec(0usize..400, 0..40),
            max_area_m2 in 0.05f64..1.5,
            min_hazard_share in 0.3f64..0.9,
        ) {
            let mut g = Grid::new(
                GridGeometry {
                    width: 20,
                    height: 20,
                    resolution_m: 0.1,
                    origin: Point2::new(0.0, 0.0),
                },
                CellState::Unknown,
            );
            for &(x, y, r) in &rings {
                let c = Point2::new(x, y);
                set(&mut g, CellState::Occupied, |p| (r..r + 0.25).contains(&p.distance_m(c)));
            }
            for &(x, y, r, hazard) in &blobs {
                let c = Point2::new(x, y);
                let state = if hazard { CellState::Occupied } else { CellState::Free };
                set(&mut g, state, |p| p.distance_m(c) < r);
            }
            let cfg = HazardHollows { min_hazard_share, max_area_m2 };
            let expected = hollows_by_definition(&g, &cfg, |i| !shut.contains(&i));
            let geo = *g.geometry();
            let open = |p: Point2| {
                let c = geo.world_to_cell(p).expect("asked of cells of the layer");
                !shut.contains(&geo.index(c))
            };
            let before = g.clone();
            let marked = HollowFinder::new(cfg).fill(&mut g, open);
            proptest::prop_assert_eq!(marked, expected.iter().filter(|h| **h).count());
            for (i, (b, a)) in before.cells().iter().zip(g.cells()).enumerate() {
                let want = if expected[i] { CellState::Occupied } else { *b };
                proptest::prop_assert_eq!(*a, want, "cell {}", i);
            }
        }
    }
}
