//! Compact map updates: a rover sends the cells of its map that changed since its last
//! update, run-length encoded, instead of the whole grid; a snapshot (every cell) goes out
//! first, on request, and whenever the receiver may have missed something. The receiver
//! rebuilds exactly the sender's map, or knows it cannot and asks for a snapshot.
//!
//! Maps grow as rovers explore: an update carries the map's geometry, and the receiver
//! re-lays what it has onto the new geometry (cells outside the old map unknown) before
//! applying the changes. Origins stay on the same lattice of cells as the map grows, so
//! re-laying is a shift by whole cells.

use realms_core::map_server::{plausible_origin, plausible_resolution};
use realms_core::{Grid, GridGeometry};
use std::borrow::Cow;

/// The unknown cell value (ROS `nav_msgs/OccupancyGrid`).
pub const UNKNOWN: i8 = -1;

pub use realms_core::msgs::{MapUpdate, Run};

/// The geometry an update lays its cells on.
fn geometry_of(u: &MapUpdate) -> GridGeometry {
    GridGeometry {
        width: u.width as usize,
        height: u.height as usize,
        resolution_m: u.resolution_m,
        origin: u.origin,
    }
}

/// Why an update could not be applied.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DeltaError {
    /// An update in between was lost: a snapshot is needed.
    #[error("update {got} changes update {base}, but the last one applied is {have:?}")]
    Gap {
        /// The update's base.
        base: u64,
        /// The update.
        got: u64,
        /// The last update applied.
        have: Option<u64>,
    },
    /// The update contradicts itself or the map it changes.
    #[error("malformed map update {seq}: {why}")]
    Malformed {
        /// The update.
        seq: u64,
        /// What is wrong.
        why: String,
    },
}

/// The sending side: remembers what the receiver has.
#[derive(Clone, Debug, Default)]
pub struct Encoder {
    sent: Option<Grid<i8>>,
    seq: u64,
}

/// `old` laid onto `geometry` (unknown where it did not reach), `old` itself where the map
/// did not grow; `None` if the two grids are not on the same lattice of cells.
fn relay_onto(old: &Grid<i8>, geometry: GridGeometry) -> Option<Cow<'_, Grid<i8>>> {
    let g = old.geometry();
    if (g.resolution_m - geometry.resolution_m).abs() > 1e-9 * g.resolution_m {
        return None;
    }
    let shift = |a: f64, b: f64| {
        let cells = (a - b) / g.resolution_m;
        let whole = cells.round();
        // Beyond a billion cells the shift is nonsense (and would overflow below).
        ((cells - whole).abs() < 1e-6 && whole.abs() < 1e9).then_some(whole as i64)
    };
    let dx = shift(g.origin.x_m, geometry.origin.x_m)?;
    let dy = shift(g.origin.y_m, geometry.origin.y_m)?;
    if (dx, dy, g.width, g.height) == (0, 0, geometry.width, geometry.height) {
        // The map did not grow (most updates): nothing to re-lay.
        return Some(Cow::Borrowed(old));
    }
    let mut out = Grid::new(geometry, UNKNOWN);
    // Row by row: the old columns that land inside the new grid, copied as one slice.
    let x_from = (-dx).clamp(0, g.width as i64) as usize;
    let x_to = (geometry.width as i64 - dx).clamp(x_from as i64, g.width as i64) as usize;
    let new_width = geometry.width;
    for y in 0..g.height {
        let ny = y as i64 + dy;
        if ny < 0 || ny >= geometry.height as i64 || x_from == x_to {
            continue;
        }
        let src = &old.cells()[y * g.width + x_from..y * g.width + x_to];
        let dst0 = ny as usize * new_width + (x_from as i64 + dx) as usize;
        out.cells_mut()[dst0..dst0 + src.len()].copy_from_slice(src);
    }
    Some(Cow::Owned(out))
}

/// Run-length encodes the cells of `now` that differ from `before` (everything, without it).
fn runs(before: Option<&Grid<i8>>, cells: &[i8]) -> Vec<Run> {
    let mut out: Vec<Run> = Vec::new();
    let mut gap = 0u32;
    let mut push = |i: usize, v: i8, gap: &mut u32| {
        if before.is_some_and(|b| b.cells()[i] == v) {
            *gap += 1;
            return;
        }
        match out.last_mut() {
            Some(run) if *gap == 0 && run.value == v => run.len += 1,
            _ => {
                out.push(Run {
                    skip: *gap,
                    len: 1,
                    value: v,
                });
                *gap = 0;
            }
        }
    };
    // Most of a map is as it was: whole chunks found equal at once are skipped.
    const CHUNK: usize = 64;
    for start in (0..cells.len()).step_by(CHUNK) {
        let end = (start + CHUNK).min(cells.len());
        if before.is_some_and(|b| b.cells()[start..end] == cells[start..end]) {
            gap += (end - start) as u32;
            continue;
        }
        for (i, &v) in cells.iter().enumerate().take(end).skip(start) {
            push(i, v, &mut gap);
        }
    }
    out
}

impl Encoder {
    /// A fresh encoder: its first update is a snapshot.
    pub fn new() -> Self {
        Encoder::default()
    }

    /// The update that brings the receiver from what it was last sent to `map`; a snapshot
    /// when `snapshot` is asked for, when nothing was sent yet, or when the map moved off
    /// its lattice.
    pub fn update(&mut self, map: &Grid<i8>, snapshot: bool) -> MapUpdate {
        self.update_cells(*map.geometry(), map.cells(), snapshot)
    }

    /// [`update`](Self::update) for the map with geometry `g` and `cells` (row-major, one
    /// per cell of `g`).
    ///
    /// # Panics
    ///
    /// If `cells` does not hold one value per cell of `g`.
    pub fn update_cells(&mut self, g: GridGeometry, cells: &[i8], snapshot: bool) -> MapUpdate {
        assert_eq!(
            cells.len(),
            g.len(),
            "one cell value per cell of the geometry"
        );
        let base = if snapshot {
            None
        } else {
            self.sent
                .as_ref()
                .and_then(|s| relay_onto(s, g))
                .map(|before| (self.seq, before))
        };
        self.seq += 1;
        let (base_seq, encoded) = match &base {
            Some((seq, before)) => (Some(*seq), runs(Some(before), cells)),
            None => (None, runs(None, cells)),
        };
        // What the receiver now has, copied into the grid kept for it when the map did not
        // grow (most updates), not cloned into a fresh one.
        match &mut self.sent {
            Some(sent) if *sent.geometry() == g => sent.cells_mut().copy_from_slice(cells),
            sent => {
                *sent = Grid::from_cells(g, cells.to_vec());
            }
        }
        MapUpdate {
            seq: self.seq,
            base: base_seq,
            width: g.width as u32,
            height: g.height as u32,
            resolution_m: g.resolution_m,
            origin: g.origin,
            runs: encoded,
        }
    }
}

/// The receiving side: the rebuilt map.
#[derive(Clone, Debug, Default)]
pub struct Decoder {
    map: Option<Grid<i8>>,
    applied: Option<u64>,
}

impl Decoder {
    /// Nothing received yet.
    pub fn new() -> Self {
        Decoder::default()
    }

    /// The map as rebuilt so far.
    pub fn map(&self) -> Option<&Grid<i8>> {
        self.map.as_ref()
    }

    /// The last update applied.
    pub fn applied(&self) -> Option<u64> {
        self.applied
    }

    /// Applies `update`. On an error nothing changes: the map stays as it was (and a
    /// snapshot should be asked for).
    pub fn apply(&mut self, update: &MapUpdate) -> Result<(), DeltaError> {
        let malformed = |why: &str| DeltaError::Malformed {
            seq: update.seq,
            why: why.to_string(),
        };
        let g = geometry_of(update);
        let cells = g
            .width
            .checked_mul(g.height)
            .ok_or_else(|| malformed("size overflows"))?;
        // A corrupt field that still decodes: cells of 1e-300 or 1e300 m, or a map 1e300 m
        // out, would send the merges that read the map past their grids.
        if !(plausible_resolution(g.resolution_m) && plausible_origin(g.origin.x_m, g.origin.y_m)) {
            return Err(malformed(
                "resolution outside 1 mm to 100 m, or origin beyond 1e6 m",
            ));
        }
        // Refuse absurd sizes before allocating: 100 million cells is a 500 km^2 map at 5 cm.
        if cells > 100_000_000 {
            return Err(malformed("more than 100 million cells"));
        }
        // The runs are checked before anything is written: the map kept stays whole if the
        // update turns out malformed.
        let mut i = 0usize;
        for run in &update.runs {
            i = i
                .checked_add(run.skip as usize)
                .and_then(|start| start.checked_add(run.len as usize))
                .filter(|end| *end <= cells)
                .ok_or_else(|| malformed("run past the end of the map"))?;
        }
        // A fresh grid for a snapshot or a map that grew; most updates change the kept one
        // where it lies.
        let fresh = match update.base {
            None => Some(Grid::new(g, UNKNOWN)),
            Some(base) => {
                if self.applied != Some(base) {
                    return Err(DeltaError::Gap {
                        base,
                        got: update.seq,
                        have: self.applied,
                    });
                }
                let old = self
                    .map
                    .as_ref()
                    .ok_or_else(|| malformed("no map to change"))?;
                match relay_onto(old, g).ok_or_else(|| malformed("geometry off the old lattice"))? {
                    Cow::Borrowed(_) => None,
                    Cow::Owned(grown) => Some(grown),
                }
            }
        };
        if let Some(grid) = fresh {
            self.map = Some(grid);
        }
        let Some(map) = self.map.as_mut() else {
            return Err(malformed("no map to change"));
        };
        let out = map.cells_mut();
        let mut i = 0usize;
        for run in &update.runs {
            let start = i + run.skip as usize;
            i = start + run.len as usize;
            out[start..i].fill(run.value);
        }
        self.applied = Some(update.seq);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use realms_core::Point2;

    fn geometry(x0: i64, y0: i64, w: usize, h: usize) -> GridGeometry {
        GridGeometry {
            width: w,
            height: h,
            resolution_m: 0.1,
            origin: Point2::new(x0 as f64 * 0.1, y0 as f64 * 0.1),
        }
    }

    /// A step of the sender's life: its map grows and some cells change; an update may be
    /// lost on the way; the receiver may ask for a snapshot.
    #[derive(Clone, Debug)]
    struct Step {
        grow: (u8, u8, u8, u8),
        edits: Vec<(u16, i8)>,
        lost: bool,
        ask_snapshot: bool,
    }

    fn step() -> impl Strategy<Value = Step> {
        (
            (0u8..3, 0u8..3, 0u8..3, 0u8..3),
            proptest::collection::vec(
                (
                    0u16..2000,
                    prop_oneof![Just(-1i8), Just(0), Just(90), Just(100)],
                ),
                0..40,
            ),
            proptest::bool::weighted(0.2),
            proptest::bool::weighted(0.1),
        )
            .prop_map(|(grow, edits, lost, ask_snapshot)| Step {
                grow,
                edits,
                lost,
                ask_snapshot,
            })
    }

    proptest! {
        /// After any sequence of growth, edits, lost updates and snapshots, the receiver
        /// either holds exactly the sender's map or knows it is behind (and a snapshot
        /// brings it back).
        #[test]
        fn the_receiver_rebuilds_the_sender_s_map_exactly(steps in proptest::collection::vec(step(), 1..30)) {
            let (mut x0, mut y0, mut w, mut h) = (0i64, 0i64, 10usize, 8usize);
            let mut map = Grid::new(geometry(x0, y0, w, h), UNKNOWN);
            let mut enc = Encoder::new();
            let mut dec = Decoder::new();
            let mut behind = false;
            for s in steps {
                let (l, b, r, t) = (s.grow.0 as i64, s.grow.1 as i64, s.grow.2 as usize, s.grow.3 as usize);
                let g = geometry(x0 - l, y0 - b, w + l as usize + r, h + b as usize + t);
                map = relay_onto(&map, g).expect("same lattice").into_owned();
                (x0, y0, w, h) = (x0 - l, y0 - b, g.width, g.height);
                for (k, v) in &s.edits {
                    let n = map.cells().len();
                    map.cells_mut()[*k as usize % n] = *v;
                }
                let update = enc.update(&map, s.ask_snapshot || behind);
                if s.lost {
                    behind = true;
                    continue;
                }
                match dec.apply(&update) {
                    Ok(()) => {
                        behind = false;
                        prop_assert_eq!(dec.map(), Some(&map));
                    }
                    Err(DeltaError::Gap { .. }) => behind = true,
                    Err(e) => prop_assert!(false, "{}", e),
                }
            }
            // One snapshot always brings the receiver level.
            let update = enc.update(&map, true);
            dec.apply(&update).expect("a snapshot applies");
            prop_assert_eq!(dec.map(), Some(&map));
        }

        /// Whatever arrives, applying it never panics, and a rejected update changes nothing.
        #[test]
        fn malformed_updates_are_refused_without_harm(
            runs in proptest::collection::vec((any::<u32>(), any::<u32>(), any::<i8>()), 0..8),
            width in 0u32..5000,
            height in 0u32..5000,
            base in proptest::option::of(0u64..3),
            origin in (prop_oneof![Just(0.0), Just(-1e300), Just(1e300), -1e6f64..1e6], -1e6f64..1e6),
        ) {
            let mut enc = Encoder::new();
            let mut dec = Decoder::new();
            let map = Grid::new(geometry(0, 0, 6, 4), 0i8);
            dec.apply(&enc.update(&map, true)).expect("a snapshot applies");
            let before = dec.map().cloned();
            let update = MapUpdate {
                seq: 2,
                base,
                width,
                height,
                resolution_m: 0.1,
                origin: Point2::new(origin.0, origin.1),
                runs: runs.into_iter().map(|(skip, len, value)| Run { skip, len, value }).collect(),
            };
            if dec.apply(&update).is_err() {
                prop_assert_eq!(dec.map().cloned(), before);
            }
        }
    }

    #[test]
    fn an_update_with_cells_or_an_origin_no_rover_draws_is_refused() {
        let mut dec = Decoder::new();
        for (resolution_m, x_m) in [(1e-300, 0.0), (1e300, 0.0), (0.05, 1e300), (0.05, -2e6)] {
            let update = MapUpdate {
                seq: 1,
                base: None,
                width: 6,
                height: 4,
                resolution_m,
                origin: Point2::new(x_m, 0.0),
                runs: Vec::new(),
            };
            assert!(
                matches!(dec.apply(&update), Err(DeltaError::Malformed { .. })),
                "{resolution_m} {x_m}"
            );
            assert_eq!(dec.map(), None);
        }
    }

    #[test]
    fn an_unchanged_map_costs_no_runs_and_one_change_one_run() {
        let mut map = Grid::new(geometry(0, 0, 100, 100), 0i8);
        let mut enc = Encoder::new();
        let first = enc.update(&map, false);
        assert!(first.is_snapshot());
        assert_eq!(first.runs.len(), 1, "a uniform map is one run");
        assert!(enc.update(&map, false).runs.is_empty());
        *map.get_mut(50, 50).expect("inside") = 100;
        let d = enc.update(&map, false);
        assert_eq!(d.base, Some(2));
        assert_eq!(
            d.runs,
            vec![Run {
                skip: 5050,
                len: 1,
                value: 100
            }]
        );
    }
}
