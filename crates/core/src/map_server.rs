//! ROS map_server maps: a PGM image plus a YAML file giving its resolution and origin, the
//! format every ROS user's maps are in. Pixel values follow map_server's trinary convention:
//! occupied 0, free 254, unknown 205 (`negate: 0`).

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

/// Writes `stem.pgm` and `stem.yaml` into `dir`; returns the YAML path.
pub fn write(
    grid: &Grid<Trinary>,
    dir: &Path,
    stem: &str,
) -> Result<std::path::PathBuf, GridExportError> {
    let pgm = dir.join(format!("{stem}.pgm"));
    grid.write_pgm(&pgm, |c| match c {
        Trinary::Occupied => 0,
        Trinary::Free => 254,
        Trinary::Unknown => 205,
    })?;
    let g = grid.geometry();
    let yaml = format!(
        "image: {stem}.pgm\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        g.resolution_m, g.origin.x_m, g.origin.y_m
    );
    let path = dir.join(format!("{stem}.yaml"));
    std::fs::write(&path, yaml).map_err(|source| GridExportError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(path)
}
