//! How much of the arena the fleet has mapped: the fraction of the simulator's explorable
//! area (free ground connected to the start) that at least one rover's published map knows
//! (free, obstacle or hazard), sampled whenever a map arrives. Rovers start at known poses
//! beside the lander, so their map frames are the arena's frame (until they drift; a drifted
//! map still counts where it claims to know, which is what an operator would see).

use crate::slam_record::map_grid;
use realms_core::msgs::OccupancyGrid;
use realms_core::{CentreLookup, Grid};
use realms_sim::GroundTruth;

/// Per truth cell, which rovers' maps know it (bit per rover), and the series so far.
#[derive(Clone, Debug)]
pub struct Coverage {
    known_by: Grid<u32>,
    /// Per truth cell, 1 + the number of the rover whose map knew it first (0: none yet).
    first_by: Vec<u8>,
    explorable: Vec<usize>,
    series: Vec<(f64, f64)>,
}

impl Coverage {
    /// Nothing mapped yet.
    pub fn new(truth: &GroundTruth) -> Coverage {
        let explorable = truth
            .explorable
            .cells()
            .iter()
            .enumerate()
            .filter(|(_, e)| **e)
            .map(|(i, _)| i)
            .collect();
        Coverage {
            known_by: Grid::new(*truth.explorable.geometry(), 0),
            first_by: vec![0; truth.explorable.cells().len()],
            explorable,
            series: Vec::new(),
        }
    }

    /// Rover number `rover` (0-based, below 32) published `map` at `t_s`.
    pub fn map(&mut self, t_s: f64, rover: usize, map: &OccupancyGrid) {
        let bit = 1u32 << (rover % 32);
        let Some(grid) = map_grid(map) else { return };
        let geo = *self.known_by.geometry();
        // The map's cell under each truth cell's centre, per column and per row: a division
        // a column and a row rather than two a cell, every map of every rover.
        let under = CentreLookup::new(grid.geometry(), &geo);
        let values = grid.cells();
        for &i in &self.explorable {
            let known = under
                .index(i % geo.width, i / geo.width)
                .is_some_and(|j| values[j] >= 0);
            let cell = &mut self.known_by.cells_mut()[i];
            if known {
                *cell |= bit;
                if self.first_by[i] == 0 {
                    self.first_by[i] = (rover % 255) as u8 + 1;
                }
            } else {
                *cell &= !bit;
            }
        }
        self.sample(t_s);
    }

    /// A rover published at `t_s` a map with the same cells as its last one: what it knows
    /// is unchanged, and only the series takes the sample (a parked rover's maps).
    pub fn same_map(&mut self, t_s: f64) {
        self.sample(t_s);
    }

    /// The fraction now into the series at `t_s`.
    fn sample(&mut self, t_s: f64) {
        let f = self.fraction();
        match self.series.last_mut() {
            // Maps published together count as one sample.
            Some(last) if (last.0 - t_s).abs() < 1e-6 => last.1 = f,
            _ => self.series.push((t_s, f)),
        }
    }

    /// The fraction of the explorable area known now.
    pub fn fraction(&self) -> f64 {
        if self.explorable.is_empty() {
            return 0.0;
        }
        let cells = self.known_by.cells();
        let known = self.explorable.iter().filter(|&&i| cells[i] != 0).count();
        known as f64 / self.explorable.len() as f64
    }

    /// `(t_s, fraction)` after every map.
    pub fn series(&self) -> &[(f64, f64)] {
        &self.series
    }

    /// The first time the fraction reached `level`, seconds.
    pub fn time_to(&self, level: f64) -> Option<f64> {
        self.series
            .iter()
            .find(|(_, f)| *f >= level)
            .map(|(t, _)| *t)
    }

    /// Which rovers know each truth cell (bit per rover).
    pub fn known_by(&self) -> &Grid<u32> {
        &self.known_by
    }

    /// Per truth cell, 1 + the number of the rover whose map knew it first (0: none yet).
    pub fn first_by(&self) -> &[u8] {
        &self.first_by
    }

    /// Explorable truth cells, row-major indices.
    pub fn explorable(&self) -> &[usize] {
        &self.explorable
    }
}
