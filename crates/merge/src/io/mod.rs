//! ROS map_server maps in and out: the YAML file (`image`, `resolution`, `origin`, `negate`,
//! `occupied_thresh`, `free_thresh`, `mode`) and its PGM image, read into a [`Map`].
//!
//! Cells are classified as map_server does: with `p = (max - v) / max` (or `v / max` when
//! `negate: 1`), `p > occupied_thresh` is occupied, `p < free_thresh` free, anything between
//! unknown. A map realms wrote from a rover may also name a `hazard_value`
//! ([`realms_core::map_server::write_with_hazards`]): pixels of that value are hazards, and
//! its free cells count as not judged for hazards ([`Map::free_judged_for_hazards`]). Every problem is an error naming the file, the field (or image) and what was
//! expected; external input never panics.

pub mod pgm;
pub mod yaml;

use crate::map::{Map, MapCell};
use realms_core::grid::GridExportError;
use realms_core::map_server::{
    MAX_RESOLUTION_M, MIN_RESOLUTION_M, Trinary, plausible_origin, plausible_resolution,
};
use realms_core::{Grid, GridGeometry, Point2};
use std::path::{Path, PathBuf};
use yaml::Value;

/// Why a map could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum MapFileError {
    /// A file could not be read.
    #[error("cannot read {file}")]
    Read {
        /// The file.
        file: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The YAML is not the flat `key: value` form map files use.
    #[error("{file}, line {line}: {message}")]
    Syntax {
        /// The YAML file.
        file: String,
        /// Line, 1-based.
        line: usize,
        /// What was expected.
        message: String,
    },
    /// A field is missing, unknown or has a bad value.
    #[error("{file}: `{field}` {problem}")]
    Field {
        /// The YAML file.
        file: String,
        /// The key.
        field: String,
        /// What is wrong and what was expected (with the line when the key is present).
        problem: String,
    },
    /// The image is not a PGM map_server can read.
    #[error("{file}: {message}")]
    Image {
        /// The image file.
        file: String,
        /// What was expected.
        message: String,
    },
    /// The merged map could not be written.
    #[error("cannot write the map")]
    Write(#[from] GridExportError),
}

/// The fields a map file may have: map_server's, and realms' `hazard_value`.
const KNOWN_FIELDS: [&str; 8] = [
    "image",
    "resolution",
    "origin",
    "negate",
    "occupied_thresh",
    "free_thresh",
    "mode",
    "hazard_value",
];

/// A map file's settings, as read from its YAML.
#[derive(Clone, Debug, PartialEq)]
pub struct MapMetadata {
    /// The image, resolved against the YAML's folder.
    pub image: PathBuf,
    /// Metres per cell.
    pub resolution_m: f64,
    /// Pose of the lower-left pixel's corner in the map frame: x, y metres and yaw radians.
    pub origin: [f64; 3],
    /// Whether white means occupied.
    pub negate: bool,
    /// Occupancy probability above which a pixel is occupied.
    pub occupied_thresh: f64,
    /// Occupancy probability below which a pixel is free.
    pub free_thresh: f64,
    /// The pixel value of hazards, in a map realms wrote from a rover.
    pub hazard_value: Option<u16>,
}

struct Fields<'a> {
    file: &'a str,
    doc: yaml::Document,
}

impl Fields<'_> {
    fn error(&self, field: &str, problem: String) -> MapFileError {
        MapFileError::Field {
            file: self.file.to_string(),
            field: field.to_string(),
            problem,
        }
    }

    fn scalar(&self, field: &str, expected: &str) -> Result<Option<(usize, &str)>, MapFileError> {
        match self.doc.get(field) {
            None => Ok(None),
            Some((line, Value::Scalar(s))) => Ok(Some((*line, s.as_str()))),
            Some((line, Value::List(_))) => Err(self.error(
                field,
                format!("(line {line}): expected {expected}, found a list"),
            )),
        }
    }

    fn number(&self, field: &str, expected: &str) -> Result<Option<(usize, f64)>, MapFileError> {
        let Some((line, s)) = self.scalar(field, expected)? else {
            return Ok(None);
        };
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(Some((line, v))),
            _ => Err(self.error(
                field,
                format!("(line {line}): expected {expected}, found `{s}`"),
            )),
        }
    }

    fn required_number(&self, field: &str, expected: &str) -> Result<(usize, f64), MapFileError> {
        self.number(field, expected)?
            .ok_or_else(|| self.error(field, format!("is missing: expected {expected}")))
    }

    fn threshold(&self, field: &str, default: f64) -> Result<f64, MapFileError> {
        let expected = "a probability between 0 and 1";
        match self.number(field, expected)? {
            None => Ok(default),
            Some((line, v)) if !(0.0..=1.0).contains(&v) => Err(self.error(
                field,
                format!("(line {line}): expected {expected}, found {v}"),
            )),
            Some((_, v)) => Ok(v),
        }
    }
}

/// Reads and checks a map YAML file (not the image).
pub fn read_metadata(yaml_path: &Path) -> Result<MapMetadata, MapFileError> {
    let file = yaml_path.display().to_string();
    let text = std::fs::read_to_string(yaml_path).map_err(|source| MapFileError::Read {
        file: file.clone(),
        source,
    })?;
    let doc = yaml::parse(&text).map_err(|e| MapFileError::Syntax {
        file: file.clone(),
        line: e.line,
        message: e.message,
    })?;
    let f = Fields { file: &file, doc };
    if let Some((key, (line, _))) = f
        .doc
        .iter()
        .find(|(k, _)| !KNOWN_FIELDS.contains(&k.as_str()))
    {
        return Err(f.error(
            key,
            format!(
                "(line {line}) is not a map_server field: expected one of {}",
                KNOWN_FIELDS.join(", ")
            ),
        ));
    }
    let image = match f.scalar("image", "the image file name")? {
        Some((_, s)) if !s.is_empty() => s.to_string(),
        Some((line, _)) => {
            return Err(f.error(
                "image",
                format!("(line {line}) is empty: expected a file name"),
            ));
        }
        None => return Err(f.error("image", "is missing: expected the image file name".into())),
    };
    let (line, resolution_m) = f.required_number("resolution", "metres per cell")?;
    // A corrupt digit string still parses: 1e308 m a cell would ask the merge for more
    // cells than memory holds.
    if !plausible_resolution(resolution_m) {
        return Err(f.error(
            "resolution",
            format!(
                "(line {line}): expected {MIN_RESOLUTION_M} to {MAX_RESOLUTION_M} metres per cell, found {resolution_m}"
            ),
        ));
    }
    let origin_expected =
        "[x, y, yaw]: three numbers (metres, metres, radians), x and y at most 1e6 m from zero";
    let origin = match f.doc.get("origin") {
        None => {
            return Err(f.error("origin", format!("is missing: expected {origin_expected}")));
        }
        Some((line, Value::Scalar(s))) => {
            return Err(f.error(
                "origin",
                format!("(line {line}): expected {origin_expected}, found `{s}`"),
            ));
        }
        Some((line, Value::List(items))) => {
            let nums: Vec<Option<f64>> = items
                .iter()
                .map(|s| s.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
                .collect();
            match nums.as_slice() {
                [Some(x), Some(y), Some(yaw)] if plausible_origin(*x, *y) => [*x, *y, *yaw],
                _ => {
                    return Err(f.error(
                        "origin",
                        format!(
                            "(line {line}): expected {origin_expected}, found [{}]",
                            items.join(", ")
                        ),
                    ));
                }
            }
        }
    };
    let negate = match f.scalar("negate", "0 or 1")? {
        None => false,
        Some((_, "0" | "false")) => false,
        Some((_, "1" | "true")) => true,
        Some((line, s)) => {
            return Err(f.error(
                "negate",
                format!("(line {line}): expected 0 or 1, found `{s}`"),
            ));
        }
    };
    let occupied_thresh = f.threshold("occupied_thresh", 0.65)?;
    let free_thresh = f.threshold("free_thresh", 0.196)?;
    if free_thresh >= occupied_thresh {
        return Err(f.error(
            "free_thresh",
            format!("({free_thresh}) must be below occupied_thresh ({occupied_thresh})"),
        ));
    }
    match f.scalar("mode", "trinary or scale")? {
        None | Some((_, "trinary" | "scale")) => {}
        Some((line, s)) => {
            return Err(f.error(
                "mode",
                format!("(line {line}): expected `trinary` or `scale` (raw maps carry no occupancy thresholds), found `{s}`"),
            ));
        }
    }
    let hazard_value = match f.scalar("hazard_value", "a pixel value")? {
        None => None,
        Some((line, s)) => Some(s.parse::<u16>().map_err(|_| {
            f.error(
                "hazard_value",
                format!("(line {line}): expected a pixel value (a whole number from 0 to 65535), found `{s}`"),
            )
        })?),
    };
    let dir = yaml_path.parent().unwrap_or(Path::new(""));
    Ok(MapMetadata {
        image: dir.join(image),
        resolution_m,
        origin,
        negate,
        occupied_thresh,
        free_thresh,
        hazard_value,
    })
}

/// Reads a map_server map: its YAML and the PGM image it names.
pub fn read(yaml_path: &Path) -> Result<Map, MapFileError> {
    let meta = read_metadata(yaml_path)?;
    let file = meta.image.display().to_string();
    let bytes = std::fs::read(&meta.image).map_err(|source| MapFileError::Read {
        file: file.clone(),
        source,
    })?;
    let img = pgm::decode(&bytes).map_err(|message| MapFileError::Image {
        file: file.clone(),
        message,
    })?;
    let max = img.max_value as f64;
    let classify = |v: u16| {
        if Some(v) == meta.hazard_value {
            return MapCell::Hazard;
        }
        let v = v as f64;
        let p = if meta.negate {
            v / max
        } else {
            (max - v) / max
        };
        if p > meta.occupied_thresh {
            MapCell::Occupied
        } else if p < meta.free_thresh {
            MapCell::Free
        } else {
            MapCell::Unknown
        }
    };
    // Image rows run top-down; grid rows bottom-up.
    let mut cells = Vec::with_capacity(img.samples.len());
    for row in img.samples.chunks(img.width).rev() {
        cells.extend(row.iter().map(|v| classify(*v)));
    }
    let geometry = GridGeometry {
        width: img.width,
        height: img.height,
        resolution_m: meta.resolution_m,
        origin: Point2::new(meta.origin[0], meta.origin[1]),
    };
    let grid = Grid::from_cells(geometry, cells).ok_or_else(|| MapFileError::Image {
        file,
        message: "pixel count does not match the size".into(),
    })?;
    Ok(Map {
        cells: grid,
        origin_yaw_rad: meta.origin[2],
        free_judged_for_hazards: meta.hazard_value.is_none(),
    })
}

/// Writes `grid` (axis-aligned in its frame) as `yaml_path` plus a PGM of the same stem
/// beside it; hazards, where there are any, as obstacles to map_server and hazards to
/// [`read`] ([`realms_core::map_server::write_with_hazards`]). Returns the YAML path.
pub fn write(grid: &Grid<MapCell>, yaml_path: &Path) -> Result<PathBuf, MapFileError> {
    let dir = yaml_path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let stem = yaml_path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "merged".into());
    if grid.cells().contains(&MapCell::Hazard) {
        return Ok(realms_core::map_server::write_with_hazards(
            grid,
            dir,
            &stem,
            |c| c.with_hazard(),
        )?);
    }
    let trinary = grid.map(|c| Trinary::from(*c));
    Ok(realms_core::map_server::write(&trinary, dir, &stem)?)
}
