//! realms-core: the vocabulary every other realms crate speaks.
//!
//! - [`time`]: [`Time`] and [`Duration`], integer nanoseconds on the one mission clock.
//! - [`geometry`]: [`Pose2`] (SE(2)), [`Point2`], [`Vec3`], [`Quaternion`].
//! - [`ids`]: [`RoverId`] and [`Topic`] (`rover1/scan`).
//! - [`grid`]: [`Grid<T>`], a metric raster with world<->cell conversion and PGM/PNG export.
//! - [`msgs`]: hardware-facing messages shaped like their ROS 2 counterparts.
//! - [`codec`]: the one binary encoding of every [`msgs::Message`] on the wire.
//!
//! Nothing here reads a clock, a socket or a random generator.

pub mod codec;
pub mod geometry;
pub mod grid;
pub mod ids;
pub mod map_server;
pub mod msgs;
pub mod time;

pub use geometry::{Point2, Pose2, Quaternion, Vec3};
pub use grid::{Cell, CentreLookup, Grid, GridGeometry};
pub use ids::{RoverId, Topic};
pub use time::{Duration, Time};
