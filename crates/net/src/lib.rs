//! realms-net: the network the rovers, the lander and the ground station talk over.
//!
//! So far the physics and the metric, as plain functions of distance and configuration:
//!
//! - [`radio`]: log-distance path loss with log-normal shadowing, SNR, the 802.11 rate a
//!   link picks (the one with the best goodput after packet errors), and relaying on one
//!   channel.
//! - [`airtime`]: the IEEE 802.11s HWMP airtime link metric and the path switching rule
//!   with hysteresis.
//! - [`mapdelta`]: compact map updates (changed cells, run-length encoded, snapshots on
//!   request) that rebuild the sender's map exactly.
//!
//! - [`qos`], [`packet`], [`queue`]: per-topic service (reliable or best effort, priority,
//!   time to live), packets, and the bounded store-and-forward queue with its drop policy.
//! - [`simnet`]: the simulated mesh (one channel, HWMP+ paths on the airtime metric,
//!   relaying) and the delayed ground link with blackouts; [`stats`] counts its traffic.
//! - [`transport`]: the interface nodes' traffic goes through ([`Transport`]), which the
//!   simulated network implements and a real transport will.
//! - [`config`]: the scenario's `[network]` section.

pub mod airtime;
pub mod config;
pub mod experiment;
pub mod mapdelta;
pub mod packet;
pub mod qos;
pub mod queue;
pub mod radio;
pub mod simnet;
pub mod stats;
pub mod transport;

pub use config::{GroundLinkConfig, NetworkConfig};
pub use packet::{NodeAddr, Packet};
pub use qos::{Priority, Qos, Reliability};
pub use simnet::{Delivery, SimNetwork};
pub use transport::Transport;
