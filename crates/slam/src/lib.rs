//! realms-slam: 2D lidar SLAM as plain types and functions, knowing nothing of nodes or
//! transports.
//!
//! - [`carmen`]: reading CARMEN laser logs (FLASER, ODOM, ROBOTLASER1).
//! - [`trajectory`]: `timestamp x y theta` trajectory files.
//! - [`numeric_lines`]: the shared reader of such number-per-field text files.
//! - [`eval`]: the relative pose error of Kümmerle et al. 2009 against `.relations` files.
//! - [`occupancy`]: a log-odds occupancy grid that grows as the robot explores.
//! - [`matcher`]: multi-resolution Gauss-Newton scan-to-map matching.
//! - [`ndt`]: a match refined on the hits themselves, per-cell means and spreads (sub-cell).
//! - [`odometry`]: the motion prediction a match starts from, with stalled odometry applied once.
//! - [`frontend`]: runs a log through the matcher and the map, scan by scan.
//! - [`bnb`]: branch-and-bound correlative search over large windows (loop closure).
//! - [`health`]: notices unreliable odometry and lost tracking, from the scans.
//! - [`posegraph`]: SE(2) pose-graph optimisation with robust loop-closure edges.
//! - `elimination`: the pose graph's normal equations solved exactly, in minimum-degree order.
//! - [`relief`]: the travel between two depth frames, from the relief of the ground they see.
//! - [`slip`]: how far the wheels over-report, learnt on line from the scan matches.
//! - [`craters`]: craters inferred from the hazard layer's crescents, their discs marked.
//! - [`hollows`]: ground the lidar saw open and the camera never judged, walled in by hazard.
//! - [`traversability`]: a hazard layer from depth-camera points (steps, slopes, drops).
//! - [`walls`]: long straight walls along directions seen from the start, as a heading reference.
//! - [`mapper`]: the full SLAM: submaps, keyframes, verified loop closures, the graph.
//! - [`assembly`]: the whole map from the submaps, kept current incrementally.

pub mod assembly;
pub mod bnb;
pub mod carmen;
pub mod craters;
pub mod drift;
mod elimination;
pub mod eval;
pub mod frontend;
pub mod health;
pub mod hollows;
pub mod mapper;
pub mod matcher;
pub mod ndt;
pub mod numeric_lines;
pub mod occupancy;
pub mod odometry;
pub mod posegraph;
pub mod relief;
pub mod slip;
#[cfg(test)]
mod test_layers;
pub mod trajectory;
pub mod traversability;
pub mod walls;
