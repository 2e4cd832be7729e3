//! The network's part of the mission report: what each rover sent and how much less that is
//! than a full occupancy grid a second, how far the ground's copy of each rover's map lagged,
//! what the network dropped and why, and `network.png` (bytes on the air per node over time).

use crate::Mission;
use crate::chart::{Series, rate_chart};
use realms_core::Grid;
use realms_net::NodeAddr;
use serde::Serialize;
use std::collections::BTreeMap;

/// `mission.json`'s `network`.
#[derive(Clone, Debug, Serialize)]
pub struct NetworkSummary {
    /// Whether messages crossed the simulated network (`false`: ideal, everything instant).
    pub simulated: bool,
    /// Per rover.
    pub rovers: Vec<RoverTraffic>,
    /// Per node (rovers, lander, ground): messages and bytes it published, received and
    /// relayed.
    pub nodes: BTreeMap<String, NodeTraffic>,
    /// Packets dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
    /// Bytes of routing control traffic.
    pub routing_bytes: u64,
    /// Path changes.
    pub route_changes: u64,
    /// Messages that did not decode.
    pub malformed: u64,
}

/// One rover's traffic.
#[derive(Clone, Debug, Serialize)]
pub struct RoverTraffic {
    /// The rover.
    pub name: String,
    /// Bytes it published to every receiver, all topics.
    pub bytes_sent: u64,
    /// Bytes of its map updates towards the ground.
    pub map_bytes: u64,
    /// Bytes a full occupancy grid once a second would have taken.
    pub full_grid_bytes: u64,
    /// `full_grid_bytes / map_bytes`.
    pub map_reduction: f64,
    /// Map updates that reached the ground.
    pub map_updates_at_ground: usize,
    /// Median age of the ground's copy of the map just before each update arrived, seconds,
    /// outside blackouts.
    pub map_lag_median_s: Option<f64>,
    /// The largest such age, seconds.
    pub map_lag_max_s: Option<f64>,
}

/// A node's traffic.
#[derive(Clone, Debug, Serialize)]
pub struct NodeTraffic {
    /// Messages it published (one per receiver).
    pub sent_messages: u64,
    /// Their bytes.
    pub sent_bytes: u64,
    /// Messages delivered to it.
    pub received_messages: u64,
    /// Their bytes.
    pub received_bytes: u64,
    /// Bytes it relayed for others.
    pub relayed_bytes: u64,
}

impl NetworkSummary {
    /// Summarises a mission's network.
    pub fn new(mission: &Mission) -> NetworkSummary {
        let scenario = mission.world().scenario();
        let ground = &scenario.network.ground;
        let Some(net) = mission.network() else {
            return NetworkSummary {
                simulated: false,
                rovers: Vec::new(),
                nodes: BTreeMap::new(),
                dropped: BTreeMap::new(),
                routing_bytes: 0,
                route_changes: 0,
                malformed: 0,
            };
        };
        let stats = net.stats();
        let rovers = mission
            .world()
            .rovers()
            .zip(mission.downlink())
            .map(|(b, d)| {
                // The ground's copy just before each arrival is as old as the previous
                // update's map; skip gaps that a blackout (or the delay after it) covers.
                let mut lags: Vec<f64> = d
                    .arrivals
                    .windows(2)
                    .filter(|w| {
                        let from = w[0].0.as_secs_f64();
                        let to = w[1].1.as_secs_f64();
                        !ground.dark_during(from - ground.delay_s, to)
                    })
                    .map(|w| (w[1].1 - w[0].0).as_secs_f64())
                    .collect();
                lags.sort_by(f64::total_cmp);
                let sent = stats
                    .nodes
                    .get(&NodeAddr::rover(b.id))
                    .map_or(0, |n| n.originated.bytes);
                RoverTraffic {
                    name: b.id.to_string(),
                    bytes_sent: sent,
                    map_bytes: d.bytes,
                    full_grid_bytes: d.full_grid_bytes,
                    map_reduction: if d.bytes > 0 {
                        d.full_grid_bytes as f64 / d.bytes as f64
                    } else {
                        0.0
                    },
                    map_updates_at_ground: d.arrivals.len(),
                    map_lag_median_s: lags.get(lags.len() / 2).copied(),
                    map_lag_max_s: lags.last().copied(),
                }
            })
            .collect();
        NetworkSummary {
            simulated: true,
            rovers,
            nodes: stats
                .nodes
                .iter()
                .map(|(a, n)| {
                    (
                        a.to_string(),
                        NodeTraffic {
                            sent_messages: n.originated.messages,
                            sent_bytes: n.originated.bytes,
                            received_messages: n.delivered.messages,
                            received_bytes: n.delivered.bytes,
                            relayed_bytes: n.forwarded.bytes,
                        },
                    )
                })
                .collect(),
            dropped: stats.dropped.clone(),
            routing_bytes: stats.routing_bytes,
            route_changes: stats.route_changes,
            malformed: stats.malformed,
        }
    }
}

/// `network.png`: bytes each node put on the air per second (a minute's mean), over the
/// mission; `None` with ideal communication.
pub fn network_chart(mission: &Mission, colors: &[[u8; 3]]) -> Option<Grid<[u8; 3]>> {
    let net = mission.network()?;
    let end_s = mission.now().as_secs_f64();
    let window = 60u64;
    let series = net
        .stats()
        .nodes
        .iter()
        .enumerate()
        .map(|(k, (addr, n))| {
            let mut points = Vec::new();
            let mut start = 0u64;
            while (start as f64) < end_s {
                let bytes: u64 = n
                    .tx_bytes_per_s
                    .range(start..start + window)
                    .map(|(_, b)| *b)
                    .sum();
                points.push(((start + window / 2) as f64, bytes as f64 / window as f64));
                start += window;
            }
            let color = match addr {
                NodeAddr::Lander => [90, 90, 90],
                NodeAddr::Ground => [20, 20, 20],
                NodeAddr::Rover(_) => colors[k % colors.len()],
            };
            Series { color, points }
        })
        .collect::<Vec<_>>();
    Some(rate_chart(&series, end_s))
}
