//! The maps realms-merge works on: a grid of [`MapCell`] (unknown, free, occupied, hazard)
//! and the pose of the grid in the map's own frame (a ROS map_server origin, yaw included).

use realms_core::map_server::Trinary;
use realms_core::msgs::OccupancyGrid;
use realms_core::{Grid, GridGeometry, Point2, Pose2};

/// What one cell of a map says.
///
/// `Hazard` is ground a rover must not enter that a 2D lidar does not see as an obstacle
/// (crater interiors, steep slopes, low rocks): lunar maps carry it, ROS maps never do.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MapCell {
    /// Not observed.
    #[default]
    Unknown,
    /// Observed and free.
    Free,
    /// An obstacle (what a lidar sees).
    Occupied,
    /// Not drivable, though no obstacle to a lidar.
    Hazard,
}

impl MapCell {
    /// Whether the cell was observed at all.
    pub fn is_known(self) -> bool {
        self != MapCell::Unknown
    }

    /// Whether the cell is structure the matcher can align on (an obstacle or a hazard).
    pub fn is_feature(self) -> bool {
        matches!(self, MapCell::Occupied | MapCell::Hazard)
    }
}

impl MapCell {
    /// A cell of a realms occupancy map (ROS values, and the hazard value).
    pub fn from_occupancy(v: i8) -> MapCell {
        match v {
            OccupancyGrid::FREE => MapCell::Free,
            OccupancyGrid::OCCUPIED => MapCell::Occupied,
            OccupancyGrid::HAZARD => MapCell::Hazard,
            _ => MapCell::Unknown,
        }
    }

    /// The cell as a realms occupancy map's value ([`MapCell::from_occupancy`] undone).
    pub fn to_occupancy(self) -> i8 {
        match self {
            MapCell::Unknown => OccupancyGrid::UNKNOWN,
            MapCell::Free => OccupancyGrid::FREE,
            MapCell::Occupied => OccupancyGrid::OCCUPIED,
            MapCell::Hazard => OccupancyGrid::HAZARD,
        }
    }

    /// The cell as [`realms_core::map_server::write_with_hazards`] takes it: its map_server
    /// class (a hazard is occupied) and whether it is a hazard.
    pub fn with_hazard(self) -> (Trinary, bool) {
        (Trinary::from(self), self == MapCell::Hazard)
    }
}

impl From<Trinary> for MapCell {
    fn from(t: Trinary) -> Self {
        match t {
            Trinary::Unknown => MapCell::Unknown,
            Trinary::Free => MapCell::Free,
            Trinary::Occupied => MapCell::Occupied,
        }
    }
}

impl From<MapCell> for Trinary {
    /// A hazard is written as an obstacle: map_server has no hazard class, and a planner
    /// reading the map must keep out of it.
    fn from(c: MapCell) -> Self {
        match c {
            MapCell::Unknown => Trinary::Unknown,
            MapCell::Free => Trinary::Free,
            MapCell::Occupied | MapCell::Hazard => Trinary::Occupied,
        }
    }
}

/// A map: cells, and where the grid lies in the map's frame.
///
/// The grid's `origin` point plus [`Map::origin_yaw_rad`] is the map_server `origin`: the
/// pose of the lower-left corner of cell (0, 0) in the map frame. The algorithms work in
/// *grid-local* coordinates (cell (0, 0)'s corner at (0, 0), axes along columns and rows)
/// and convert with [`Map::frame_from_grid`].
#[derive(Clone, Debug, PartialEq)]
pub struct Map {
    /// The cells.
    pub cells: Grid<MapCell>,
    /// Rotation of the grid in the map frame (map_server origin yaw), radians.
    pub origin_yaw_rad: f64,
    /// Whether every free cell was also judged for hazards, so that a hazard the other map
    /// puts on one contradicts it. True for a survey of the whole ground (the synthetic
    /// maps); false for a rover's map, whose lidar clears ground metres beyond where its
    /// depth camera judged it: there a crater one rover walked round may lie on ground the
    /// other saw free from afar, and that is no evidence against a pose.
    pub free_judged_for_hazards: bool,
}

impl Map {
    /// A map whose grid is not rotated in its frame.
    pub fn new(cells: Grid<MapCell>) -> Self {
        Map {
            cells,
            origin_yaw_rad: 0.0,
            free_judged_for_hazards: true,
        }
    }

    /// This map with its free cells marked as not judged for hazards (see
    /// [`Map::free_judged_for_hazards`]): a rover's map.
    pub fn with_free_unjudged_for_hazards(mut self) -> Self {
        self.free_judged_for_hazards = false;
        self
    }

    /// The grid's geometry.
    pub fn geometry(&self) -> &GridGeometry {
        self.cells.geometry()
    }

    /// Pose of the grid-local frame in the map frame.
    pub fn frame_from_grid(&self) -> Pose2 {
        let o = self.geometry().origin;
        Pose2::new(o.x_m, o.y_m, self.origin_yaw_rad)
    }

    /// The centre of `cell`, in grid-local metres.
    pub fn cell_centre_in_grid(&self, cell: realms_core::Cell) -> Point2 {
        let r = self.geometry().resolution_m;
        Point2::new((cell.x as f64 + 0.5) * r, (cell.y as f64 + 0.5) * r)
    }

    /// Whether the cell under `p` (grid-local metres) is known; false off the grid.
    pub fn knows_in_grid(&self, p: Point2) -> bool {
        let r = self.geometry().resolution_m;
        let (x, y) = (p.x_m / r, p.y_m / r);
        x >= 0.0
            && y >= 0.0
            && self
                .cells
                .get(x as usize, y as usize)
                .is_some_and(|c| c.is_known())
    }

    /// Number of known cells.
    pub fn known_cells(&self) -> usize {
        self.cells.cells().iter().filter(|c| c.is_known()).count()
    }

    /// Centre of the known cells in grid-local metres (the grid centre if none is known).
    pub fn known_centroid_in_grid(&self) -> Point2 {
        let g = self.geometry();
        let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
        for (c, v) in self.cells.iter() {
            if v.is_known() {
                sx += c.x as f64 + 0.5;
                sy += c.y as f64 + 0.5;
                n += 1;
            }
        }
        if n == 0 {
            return Point2::new(g.width_m() / 2.0, g.height_m() / 2.0);
        }
        Point2::new(
            sx / n as f64 * g.resolution_m,
            sy / n as f64 * g.resolution_m,
        )
    }
}
