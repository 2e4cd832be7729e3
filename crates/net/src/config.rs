//! The network's settings, as the scenario file's `[network]` section gives them.

use crate::radio::RadioConfig;
use serde::{Deserialize, Serialize};

/// The link between the lander and the ground station.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GroundLinkConfig {
    /// One-way delay, seconds (the 2 s round trip of the field).
    pub delay_s: f64,
    /// Bits per second each way.
    pub bandwidth_bps: f64,
    /// Fraction of packets lost (reliable ones are sent again after a round trip).
    pub loss: f64,
    /// Windows with no link at all, `[start_s, end_s]` of mission time.
    pub blackouts_s: Vec<[f64; 2]>,
    /// Copies of each map packet sent back to back. Resending a lost packet costs a round
    /// trip (2 s here), which alone would break the ground's 6 s map-age budget; a second
    /// copy of the few kilobytes a map update takes costs almost nothing on this link.
    pub map_copies: u32,
}

impl Default for GroundLinkConfig {
    fn default() -> Self {
        GroundLinkConfig {
            delay_s: 1.0,
            bandwidth_bps: 1_000_000.0,
            loss: 0.01,
            blackouts_s: Vec::new(),
            map_copies: 2,
        }
    }
}

impl GroundLinkConfig {
    /// Whether the link is down at `t_s`.
    pub fn dark_at(&self, t_s: f64) -> bool {
        self.blackouts_s
            .iter()
            .any(|[a, b]| (*a..*b).contains(&t_s))
    }

    /// Whether any blackout overlaps `[from_s, to_s]`.
    pub fn dark_during(&self, from_s: f64, to_s: f64) -> bool {
        self.blackouts_s
            .iter()
            .any(|[a, b]| *a <= to_s && from_s < *b)
    }

    /// The end of the blackout covering `t_s`, if one does.
    pub fn light_after(&self, t_s: f64) -> Option<f64> {
        self.blackouts_s
            .iter()
            .filter(|[a, b]| (*a..*b).contains(&t_s))
            .map(|[_, b]| *b)
            .reduce(f64::max)
    }
}

/// The whole network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NetworkConfig {
    /// The mesh radio.
    pub radio: RadioConfig,
    /// The ground link.
    pub ground: GroundLinkConfig,
    /// Each node's outgoing queue, bytes (map data does not count against it).
    pub queue_bytes: usize,
    /// How often paths are refreshed (HWMP's path request interval), seconds.
    pub route_interval_s: f64,
    /// Retries the radio makes for one frame before giving up on it.
    pub mac_retries: u32,
    /// Seed of the link shadowing and packet-error draws. Not in the scenario file: a
    /// mission derives it from the scenario's one seed.
    #[serde(skip)]
    pub seed: u64,
}

impl Default for NetworkConfig {
    fn default() -> Self {
        NetworkConfig {
            radio: RadioConfig::default(),
            ground: GroundLinkConfig::default(),
            queue_bytes: 4 << 20,
            route_interval_s: 1.0,
            mac_retries: 7,
            seed: 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blackout_windows() {
        let g = GroundLinkConfig {
            blackouts_s: vec![[10.0, 20.0], [15.0, 30.0]],
            ..GroundLinkConfig::default()
        };
        assert!(!g.dark_at(9.9));
        assert!(g.dark_at(10.0));
        assert!(!g.dark_at(30.0));
        assert_eq!(g.light_after(16.0), Some(30.0));
        assert!(g.dark_during(5.0, 10.5));
        assert!(!g.dark_during(30.0, 31.0));
    }
}
