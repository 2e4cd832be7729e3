//! `Grid<T>`: a metric raster laid on the plane, the shape shared by heightfields, occupancy
//! maps, costmaps and ground truth. Cell (0, 0) has its lower-left corner at `origin`; x grows
//! with column, y with row (the ROS map_server convention, whose image rows run the other way,
//! which the exporters here handle).

use crate::geometry::Point2;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Where a grid lies in the world and how fine it is.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridGeometry {
    /// Number of columns (cells along x).
    pub width: usize,
    /// Number of rows (cells along y).
    pub height: usize,
    /// Edge length of a cell in metres.
    pub resolution_m: f64,
    /// World position of the lower-left corner of cell (0, 0).
    pub origin: Point2,
}

/// Integer cell coordinates, column `x` and row `y`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Cell {
    /// Column.
    pub x: usize,
    /// Row.
    pub y: usize,
}

impl GridGeometry {
    /// Cell containing a world point, or `None` outside the grid.
    pub fn world_to_cell(&self, p: Point2) -> Option<Cell> {
        // No `floor`: past the origin truncation is the floor, and before it the test fails
        // either way (`floor` is a call into libm on the baseline x86-64 target, and this
        // is asked for every cell some maps' passes touch).
        let fx = (p.x_m - self.origin.x_m) / self.resolution_m;
        let fy = (p.y_m - self.origin.y_m) / self.resolution_m;
        // Written so NaN fails the test too.
        if !(fx >= 0.0 && fy >= 0.0 && fx < self.width as f64 && fy < self.height as f64) {
            return None;
        }
        Some(Cell {
            x: fx as usize,
            y: fy as usize,
        })
    }

    /// World position of a cell's centre.
    pub fn cell_center(&self, c: Cell) -> Point2 {
        Point2::new(
            self.origin.x_m + (c.x as f64 + 0.5) * self.resolution_m,
            self.origin.y_m + (c.y as f64 + 0.5) * self.resolution_m,
        )
    }

    /// Width of the covered area in metres.
    pub fn width_m(&self) -> f64 {
        self.width as f64 * self.resolution_m
    }

    /// Height of the covered area in metres.
    pub fn height_m(&self) -> f64 {
        self.height as f64 * self.resolution_m
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// Whether the grid has no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row-major index of an in-bounds cell.
    pub fn index(&self, c: Cell) -> usize {
        c.y * self.width + c.x
    }

    /// The cells of the grid whose centres lie within `reach_m` of `p`, row by row.
    pub fn cells_within(&self, p: Point2, reach_m: f64) -> impl Iterator<Item = Cell> + '_ {
        // Index range of the square around the disc, clipped to the grid (a range that
        // misses the grid comes out empty).
        let span = |o: f64, lo_m: f64, n: usize| {
            let first = ((lo_m - reach_m - o) / self.resolution_m).floor().max(0.0);
            let last = ((lo_m + reach_m - o) / self.resolution_m)
                .floor()
                .min(n as f64 - 1.0);
            first as usize..(last + 1.0).max(first) as usize
        };
        let xs = span(self.origin.x_m, p.x_m, self.width);
        let ys = span(self.origin.y_m, p.y_m, self.height);
        ys.flat_map(move |y| xs.clone().map(move |x| Cell { x, y }))
            .filter(move |c| self.cell_center(*c).distance_m(p) <= reach_m)
    }
}

/// Which cell of one grid holds the centre of each cell of another. Axis-aligned grids map
/// column to column and row to row, so one division per column and per row gives every
/// cell what [`GridGeometry::world_to_cell`] of its centre gives, instead of two per cell:
/// the difference between drawing a 5 cm map over a 1 m one every second or not.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CentreLookup {
    columns: Vec<Option<usize>>,
    rows: Vec<Option<usize>>,
    width: usize,
}

impl CentreLookup {
    /// Where the centres of the cells of `of` lie in `into`.
    pub fn new(into: &GridGeometry, of: &GridGeometry) -> Self {
        // The centre of column x (row y) lies in the same column of `into` on every row, so
        // any in-range coordinate on the other axis finds it.
        let columns = (0..of.width)
            .map(|x| {
                let c = of.cell_center(Cell { x, y: 0 });
                let probe = Point2::new(c.x_m, into.origin.y_m + 0.5 * into.resolution_m);
                into.world_to_cell(probe).map(|cell| cell.x)
            })
            .collect();
        let rows = (0..of.height)
            .map(|y| {
                let c = of.cell_center(Cell { x: 0, y });
                let probe = Point2::new(into.origin.x_m + 0.5 * into.resolution_m, c.y_m);
                into.world_to_cell(probe).map(|cell| cell.y)
            })
            .collect();
        CentreLookup {
            columns,
            rows,
            width: into.width,
        }
    }

    /// Row-major index in the `into` grid of the cell holding the centre of cell (`x`, `y`)
    /// of the `of` grid; `None` if it lies outside.
    pub fn index(&self, x: usize, y: usize) -> Option<usize> {
        Some(self.rows.get(y).copied()?? * self.width + self.columns.get(x).copied()??)
    }

    /// The column of the `into` grid holding the centres of column `x` of the `of` grid.
    pub fn column(&self, x: usize) -> Option<usize> {
        self.columns.get(x).copied()?
    }

    /// The row of the `into` grid holding the centres of row `y` of the `of` grid.
    pub fn row(&self, y: usize) -> Option<usize> {
        self.rows.get(y).copied()?
    }
}

/// A raster of `T` over a [`GridGeometry`], stored row-major from the bottom row up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid<T> {
    geometry: GridGeometry,
    cells: Vec<T>,
}

/// Why a grid could not be written out.
#[derive(Debug, thiserror::Error)]
pub enum GridExportError {
    /// The file could not be written.
    #[error("cannot write {path}")]
    Io {
        /// The file.
        path: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The PNG encoder failed.
    #[error("cannot encode PNG {path}")]
    Png {
        /// The file.
        path: String,
        /// What the encoder said.
        source: image::ImageError,
    },
}

impl<T: Clone> Grid<T> {
    /// A grid with every cell set to `fill`.
    pub fn new(geometry: GridGeometry, fill: T) -> Self {
        Grid {
            cells: vec![fill; geometry.len()],
            geometry,
        }
    }
}

impl<T> Grid<T> {
    /// A grid from row-major cells (bottom row first); `None` if the count does not match.
    pub fn from_cells(geometry: GridGeometry, cells: Vec<T>) -> Option<Self> {
        (cells.len() == geometry.len()).then_some(Grid { geometry, cells })
    }

    /// Where the grid lies and how fine it is.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.geometry.width
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.geometry.height
    }

    /// Cell edge in metres.
    pub fn resolution_m(&self) -> f64 {
        self.geometry.resolution_m
    }

    /// The cell at column `x`, row `y`, if inside.
    pub fn get(&self, x: usize, y: usize) -> Option<&T> {
        if x < self.geometry.width && y < self.geometry.height {
            self.cells.get(y * self.geometry.width + x)
        } else {
            None
        }
    }

    /// Mutable access to the cell at column `x`, row `y`, if inside.
    pub fn get_mut(&mut self, x: usize, y: usize) -> Option<&mut T> {
        if x < self.geometry.width && y < self.geometry.height {
            self.cells.get_mut(y * self.geometry.width + x)
        } else {
            None
        }
    }

    /// The cell under a world point, if inside.
    pub fn at_world(&self, p: Point2) -> Option<&T> {
        let c = self.geometry.world_to_cell(p)?;
        self.get(c.x, c.y)
    }

    /// All cells, row-major from the bottom row.
    pub fn cells(&self) -> &[T] {
        &self.cells
    }

    /// All cells, mutable.
    pub fn cells_mut(&mut self) -> &mut [T] {
        &mut self.cells
    }

    /// Every cell with its coordinates, row-major from the bottom row.
    pub fn iter(&self) -> impl Iterator<Item = (Cell, &T)> {
        let w = self.geometry.width;
        self.cells
            .iter()
            .enumerate()
            .map(move |(i, v)| (Cell { x: i % w, y: i / w }, v))
    }

    /// A new grid of the same geometry with `f` applied to every cell.
    pub fn map<U>(&self, f: impl FnMut(&T) -> U) -> Grid<U> {
        Grid {
            geometry: self.geometry,
            cells: self.cells.iter().map(f).collect(),
        }
    }

    /// Rows top-down (image order), each as a slice.
    fn rows_top_down(&self) -> impl Iterator<Item = &[T]> {
        self.cells.chunks(self.geometry.width.max(1)).rev()
    }

    /// Writes a binary PGM (P5) image, north up, as ROS map_server reads it.
    pub fn write_pgm(&self, path: &Path, gray: impl Fn(&T) -> u8) -> Result<(), GridExportError> {
        let io_err = |source| GridExportError::Io {
            path: path.display().to_string(),
            source,
        };
        let mut bytes = format!("P5\n{} {}\n255\n", self.width(), self.height()).into_bytes();
        bytes.reserve(self.cells.len());
        for row in self.rows_top_down() {
            bytes.extend(row.iter().map(&gray));
        }
        let mut file = std::fs::File::create(path).map_err(io_err)?;
        file.write_all(&bytes).map_err(io_err)
    }

    /// Writes an RGB PNG image, north up.
    pub fn write_png(
        &self,
        path: &Path,
        color: impl Fn(&T) -> [u8; 3],
    ) -> Result<(), GridExportError> {
        let mut rgb = Vec::with_capacity(self.cells.len() * 3);
        for row in self.rows_top_down() {
            for v in row {
                rgb.extend_from_slice(&color(v));
            }
        }
        let img = image::RgbImage::from_raw(self.width() as u32, self.height() as u32, rgb)
            .expect("buffer length is width * height * 3 by construction");
        img.save_with_format(path, image::ImageFormat::Png)
            .map_err(|source| GridExportError::Png {
                path: path.display().to_string(),
                source,
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geom() -> GridGeometry {
        GridGeometry {
            width: 4,
            height: 3,
            resolution_m: 0.5,
            origin: Point2::new(-1.0, 2.0),
        }
    }

    #[test]
    fn centre_lookup_agrees_with_world_to_cell_on_every_cell() {
        // A fine grid overhanging a coarse one on every side, offsets not multiples of
        // either cell.
        let coarse = geom();
        let fine = GridGeometry {
            width: 23,
            height: 19,
            resolution_m: 0.13,
            origin: Point2::new(-1.31, 1.77),
        };
        let lookup = CentreLookup::new(&coarse, &fine);
        let (mut inside, mut outside) = (0, 0);
        for y in 0..fine.height {
            for x in 0..fine.width {
                let expected = coarse
                    .world_to_cell(fine.cell_center(Cell { x, y }))
                    .map(|c| coarse.index(c));
                assert_eq!(lookup.index(x, y), expected, "cell ({x}, {y})");
                match expected {
                    Some(_) => inside += 1,
                    None => outside += 1,
                }
            }
        }
        assert!(
            inside > 50 && outside > 50,
            "{inside} inside, {outside} outside"
        );
        assert_eq!(lookup.index(fine.width, 0), None);
    }

    #[test]
    fn cells_within_reach_are_clipped_to_the_grid() {
        let g = geom();
        // Cell (0, 0) has its centre at (-0.75, 2.25); from the grid's corner 0.4 m reaches
        // that centre (0.35 m) and no other.
        let near: Vec<Cell> = g.cells_within(Point2::new(-1.0, 2.0), 0.4).collect();
        assert_eq!(near, vec![Cell { x: 0, y: 0 }]);
        // From the centre of (1, 1), 0.55 m reaches it and its four side neighbours.
        let cross: Vec<Cell> = g.cells_within(Point2::new(-0.25, 2.75), 0.55).collect();
        assert_eq!(cross.len(), 5);
        // Far off the grid: nothing.
        assert_eq!(g.cells_within(Point2::new(50.0, -50.0), 1.0).count(), 0);
        assert_eq!(g.cells_within(Point2::new(-50.0, 50.0), 1.0).count(), 0);
    }

    #[test]
    fn world_and_cells_agree() {
        let g = geom();
        assert_eq!(
            g.world_to_cell(Point2::new(-1.0, 2.0)),
            Some(Cell { x: 0, y: 0 })
        );
        assert_eq!(
            g.world_to_cell(Point2::new(0.99, 3.49)),
            Some(Cell { x: 3, y: 2 })
        );
        assert_eq!(g.world_to_cell(Point2::new(1.0, 3.0)), None);
        assert_eq!(g.world_to_cell(Point2::new(-1.01, 3.0)), None);
        assert_eq!(g.world_to_cell(Point2::new(f64::NAN, 3.0)), None);
        let c = g.cell_center(Cell { x: 1, y: 2 });
        assert_eq!((c.x_m, c.y_m), (-0.25, 3.25));
        assert_eq!(g.world_to_cell(c), Some(Cell { x: 1, y: 2 }));
    }

    proptest::proptest! {
        /// The cell a point falls in is the floor of its offset in cells, on the grid or
        /// nowhere: points just before the origin (where truncation rounds up to 0), on
        /// the far edges, infinite or NaN.
        #[test]
        fn world_to_cell_is_the_floor_of_the_offset(
            x in proptest::prop_oneof![-3.0f64..3.0, proptest::sample::select(vec![-1.0, -1.0 - 1e-12, -0.0, 1.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY])],
            y in proptest::prop_oneof![0.0f64..6.0, proptest::sample::select(vec![2.0, 2.0 - 1e-12, 3.5, f64::NAN])],
        ) {
            let g = geom();
            let fx = ((x - g.origin.x_m) / g.resolution_m).floor();
            let fy = ((y - g.origin.y_m) / g.resolution_m).floor();
            let expected = (fx >= 0.0 && fy >= 0.0 && fx < g.width as f64 && fy < g.height as f64)
                .then_some(Cell { x: fx as usize, y: fy as usize });
            proptest::prop_assert_eq!(g.world_to_cell(Point2::new(x, y)), expected);
        }
    }

    #[test]
    fn access_is_bounds_checked() {
        let mut grid = Grid::new(geom(), 0u8);
        *grid.get_mut(3, 2).expect("inside") = 7;
        assert_eq!(grid.get(3, 2), Some(&7));
        assert_eq!(grid.get(4, 0), None);
        assert_eq!(grid.get(0, 3), None);
        assert!(grid.get_mut(9, 9).is_none());
        let (cell, _) = grid.iter().find(|(_, v)| **v == 7).expect("set above");
        assert_eq!(cell, Cell { x: 3, y: 2 });
    }

    #[test]
    fn pgm_is_written_north_up() {
        let mut grid = Grid::new(geom(), 0u8);
        *grid.get_mut(0, 2).expect("inside") = 200; // top-left in the image
        let dir = std::env::temp_dir().join(format!("realms-grid-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("g.pgm");
        grid.write_pgm(&path, |v| *v).expect("write");
        let bytes = std::fs::read(&path).expect("read back");
        let header = b"P5\n4 3\n255\n";
        assert_eq!(&bytes[..header.len()], header);
        assert_eq!(bytes[header.len()], 200);
        assert_eq!(bytes.len(), header.len() + 12);
        grid.write_png(&dir.join("g.png"), |v| [*v, 0, 0])
            .expect("png");
        std::fs::remove_dir_all(&dir).ok();
    }
}
