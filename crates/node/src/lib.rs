//! realms-node: the logic of every node as a sans-IO state machine.
//!
//! A node is handed messages and ticks with the current mission time and returns what it
//! wants to send; it never reads a clock, sleeps, spawns a thread or opens a socket. The
//! simulator and (later) the Zenoh runner are two thin drivers of the same code.
//!
//! - [`Node`]: the interface every node implements.
//! - [`rover::RoverNode`]: a rover's on-board logic.
//! - [`mapping::Mapping`]: the rover's SLAM on board, and what it publishes.
//! - [`navigation::Navigator`]: exploration, planning, path following and recovery.
//! - [`guard::Guard`]: the reactive check of the rover's own sensors.
//! - [`lander_merge`]: the lander's job of merging every rover's map into one.
//! - [`levelling::Levelling`]: the rover's tilt from its accelerometer, for levelling its sensors.
//! - [`layers`]: the rover's published and planner maps, redrawn only where they changed.
//! - [`sweep`]: a sweeping lidar's scan brought to one instant by the rover's measured motion.
//! - [`station::StationNode`]: the lander and the ground station: every rover's map rebuilt
//!   from its updates, its pose and its status.

pub mod cost;
pub mod guard;
pub mod lander_merge;
pub mod layers;
pub mod levelling;
pub mod mapping;
pub mod navigation;
pub mod plausible;
pub mod rover;
pub mod station;
pub mod sweep;

use realms_core::msgs::Message;
use realms_core::{Time, Topic};

/// A message a node wants published.
#[derive(Clone, Debug, PartialEq)]
pub struct Outgoing {
    /// Where to.
    pub topic: Topic,
    /// What.
    pub message: Message,
}

/// A sans-IO node.
pub trait Node {
    /// The node's name (its namespace for a rover: `rover1`).
    fn name(&self) -> &str;

    /// Topics the node wants delivered to [`on_message`](Node::on_message).
    fn subscriptions(&self) -> Vec<Topic>;

    /// A message arrived at `now`.
    fn on_message(&mut self, now: Time, topic: &Topic, message: &Message);

    /// The time asked for by [`next_wakeup`](Node::next_wakeup) has come.
    fn on_tick(&mut self, now: Time);

    /// Takes everything the node wants sent, in the order it was produced.
    fn drain_outbox(&mut self) -> Vec<Outgoing>;

    /// When the node next wants [`on_tick`](Node::on_tick), if ever.
    fn next_wakeup(&self) -> Option<Time>;

    /// The mission ends at `now`: the node may publish its final products (a rover its map).
    fn on_shutdown(&mut self, _now: Time) {}

    /// The node as a station (lander or ground), for a driver that reports what it holds.
    fn as_station(&self) -> Option<&station::StationNode> {
        None
    }

    /// The node as a rover, for a driver that grades what its SLAM estimated.
    fn as_rover(&self) -> Option<&rover::RoverNode> {
        None
    }
}

/// A 360-beam scan stamped `t` with `ranges_m`, beam 0 pointing backwards (as the simulated
/// lidar's), for tests.
#[cfg(test)]
pub(crate) fn test_scan(t: Time, ranges_m: Vec<f32>) -> realms_core::msgs::LaserScan {
    let mut s = realms_core::msgs::LaserScan {
        angle_min_rad: -std::f32::consts::PI,
        angle_increment_rad: std::f32::consts::TAU / ranges_m.len() as f32,
        range_min_m: 0.15,
        range_max_m: 12.0,
        ranges_m,
        ..realms_core::msgs::LaserScan::default()
    };
    s.header.stamp = t;
    s
}
