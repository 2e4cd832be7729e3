//! ROS map_server maps: a PGM image plus a YAML file giving its resolution and origin, the
//! format every ROS user's maps are in. Pixel values follow map_server's trinary convention:
//! occupied 0, free 254, unknown 205 (`negate: 0`).
//!
//! A rover's map also has hazards (ground it must not enter that the lidar sees free).
//! [`write_with_hazards`] writes them as [`HAZARD_PIXEL`], which map_server reads as occupied,
//! and names that value in the YAML as `hazard_value`, a key ROS's map servers do not read,
//! so that realms' own reader gets the hazards back.

use crate::grid::{Grid, GridExportError};
use std::path::Path;

/// What a cell of a trinary map is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trinary {
    /// No knowledge.
    Unknown,
    /// Free space.
    Free,
    /// An obstacle.
    Occupied,
}

/// The pixel value of a hazard in [`write_with_hazards`]: occupied to map_server
/// (`p = 254 / 255`), and no other cell is written with it.
pub const HAZARD_PIXEL: u8 = 1;

/// The finest and coarsest cells a map read from outside may claim, metres (ROS maps use 1 cm
/// to 1 m, the rovers' are 5 cm): a corrupt field that still parses (1e308) would ask for
/// more cells than memory holds.
pub const MIN_RESOLUTION_M: f64 = 1e-3;
/// See [`MIN_RESOLUTION_M`].
pub const MAX_RESOLUTION_M: f64 = 100.0;
/// The farthest such a map's origin may lie from its frame's, metres.
pub const MAX_ORIGIN_M: f64 = 1e6;

/// Whether `resolution_m` lies within [`MIN_RESOLUTION_M`] ..= [`MAX_RESOLUTION_M`].
pub fn plausible_resolution(resolution_m: f64) -> bool {
    (MIN_RESOLUTION_M..=MAX_RESOLUTION_M).contains(&resolution_m)
}

/// Whether an origin at (`x_m`, `y_m`) lies within [`MAX_ORIGIN_M`] of its frame's.
pub fn plausible_origin(x_m: f64, y_m: f64) -> bool {
    x_m.abs() <= MAX_ORIGIN_M && y_m.abs() <= MAX_ORIGIN_M
}

/// Writes `stem.pgm` and `stem.yaml` into `dir`; returns the YAML path.
pub fn write(
    grid: &Grid<Trinary>,
    dir: &Path,
    stem: &str,
) -> Result<std::path::PathBuf, GridExportError> {
    write_pixels(grid, dir, stem, |c| pixel(*c), "")
}

/// [`write()`] with the cells `hazard` says are hazards (occupied to map_server) written as
/// [`HAZARD_PIXEL`], and `hazard_value: 1` in the YAML.
pub fn write_with_hazards<T>(
    grid: &Grid<T>,
    dir: &Path,
    stem: &str,
    cell: impl Fn(&T) -> (Trinary, bool),
) -> Result<std::path::PathBuf, GridExportError> {
    let value = |c: &T| match cell(c) {
        (_, true) => HAZARD_PIXEL,
        (t, false) => pixel(t),
    };
    let extra = format!("hazard_value: {HAZARD_PIXEL}\n");
    write_pixels(grid, dir, stem, value, &extra)
}

fn pixel(t: Trinary) -> u8 {
    match t {
        Trinary::Occupied => 0,
        Trinary::Free => 254,
        Trinary::Unknown => 205,
    }
}

fn write_pixels<T>(
    grid: &Grid<T>,
    dir: &Path,
    stem: &str,
    value: impl Fn(&T) -> u8,
    extra_yaml: &str,
) -> Result<std::path::PathBuf, GridExportError> {
    let pgm = dir.join(format!("{stem}.pgm"));
    grid.write_pgm(&pgm, value)?;
    let g = grid.geometry();
    let yaml = format!(
        "image: {stem}.pgm\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n{extra_yaml}",
        g.resolution_m, g.origin.x_m, g.origin.y_m
    );
    let path = dir.join(format!("{stem}.yaml"));
    std::fs::write(&path, yaml).map_err(|source| GridExportError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(path)
}
