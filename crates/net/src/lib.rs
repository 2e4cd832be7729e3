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
//! The simulated mesh (routing, queues, the delayed ground link, blackouts) and the
//! transport interface build on these.

pub mod airtime;
pub mod mapdelta;
pub mod radio;
