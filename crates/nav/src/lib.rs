//! realms-nav: how a rover gets somewhere, and where it should go next.
//!
//! Pure algorithms on maps: nothing here knows about nodes, topics or transports.
//!
//! - [`costmap`]: obstacles and hazards inflated by the rover's footprint, with a cost
//!   gradient that keeps paths away from them and a price on unknown space.
//! - [`planner`]: A* on the costmap (and the Dijkstra field it is checked against), with
//!   line-of-sight smoothing into drivable paths.
//! - [`follower`]: regulated pure pursuit for a skid-steer rover.
//! - [`frontier`]: the edges between known free space and the unknown.
//! - [`explore`]: which frontier a rover should take, discounted by what its peers took.

pub mod costmap;
pub mod explore;
pub mod follower;
pub mod frontier;
pub mod planner;

pub use costmap::{Costmap, CostmapConfig};
pub use planner::{PlanError, Planner};
