//! realms-merge: one map out of many, from rovers that started at unknown places.
//!
//! - [`map`]: [`Map`], a grid of [`MapCell`] (unknown, free, occupied, hazard) and its frame.
//! - [`io`]: ROS map_server maps (PGM + YAML) in and out, with errors naming file and field.
//! - [`estimate`](mod@estimate): the relative pose of two maps with no prior
//!   ([`estimate::estimate`]) or from a known start ([`estimate::estimate_with_prior`]): every
//!   hypothesis verified, a confidence in 0..1, and a refusal with the reason when the answer
//!   is not clear.
//! - [`compose`]: N maps into one: pairwise estimates, a spanning tree of the most confident
//!   links from the first map, and the merged grid with a per-map contribution layer.
//! - [`synth`]: cases with a known answer cut from a source map, for tests and benchmarks.
//!
//! Internals, public for benchmarks and curious readers: [`level`] (maps reduced for
//! matching), [`rotation`] (heading candidates), [`lines`] (long walls, and the heading they
//! hold), [`search`] (global branch and bound), [`constellation`] (poses the landmarks vote
//! for), [`verify`] (refinement and verification), [`fine`] (the sub-cell fit),
//! [`prepare`] (per-map precomputation).
//!
//! Nothing here reads a clock; randomness only in [`synth`], from the caller's generator.

pub mod compose;
pub mod constellation;
pub mod estimate;
pub mod fine;
pub mod io;
pub mod level;
pub mod lines;
pub mod map;
pub mod prepare;
pub mod rotation;
pub mod search;
pub mod synth;
pub mod verify;

pub use estimate::{
    Estimate, PriorCheck, PriorWindow, estimate, estimate_maps, estimate_with_prior,
};
pub use map::{Map, MapCell};
pub use prepare::{Params, Prepared};
