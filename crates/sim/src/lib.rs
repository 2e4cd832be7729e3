//! realms-sim: a deterministic simulation of a lunar analogue arena and the rovers in it.
//!
//! - [`scenario`]: the strict TOML scenario ([`Scenario`]) that defines a mission.
//! - [`terrain`]: the seeded heightfield (floor, walls, lander, craters, boulders, targets).
//! - [`truth`]: ground truth the rest of the project is graded against.
//! - [`raycast`]: max-mipmap ray casting against the heightfield, shared by all sensors.
//! - [`rover`]: skid-steer kinematics on 3D terrain, collisions, getting stuck, slip.
//! - [`sensors`]: lidar, depth camera, grayscale camera, wheel odometry and gyro.
//! - [`world`]: the discrete-event [`World`] tying it together on one integer-nanosecond clock.
//!
//! Every random draw comes from [`rng::Streams`], derived from the scenario seed, so the same
//! scenario and seed give the same world and the same sensor data bit for bit.

pub mod raycast;
pub mod render;
pub mod rng;
pub mod rover;
pub mod scenario;
pub mod scheduler;
pub mod sensors;
pub mod terrain;
pub mod truth;
pub mod world;

pub use scenario::{Scenario, ScenarioError};
pub use terrain::Terrain;
pub use truth::{GroundTruth, TruthCell};
pub use world::{SimEvent, SimEventKind, World};
