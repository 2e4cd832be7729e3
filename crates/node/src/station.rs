//! The lander and the ground station, as far as they are built: each keeps every rover's
//! map, rebuilt from its `map/delta` updates, with the rover's latest pose, localisation
//! state and navigation status, and asks a rover for a snapshot when it missed an update.
//! The lander is where rover data is stored for the mission (its merging comes with the
//! map-merging issue); the ground station is what the operator sees.

use crate::lander_merge::{MergedMap, merge_from_known_start};
use crate::{Node, Outgoing};
use realms_core::msgs::{Header, LocalisationState, MapDelta, Message, NavStatus, NetworkStats};
use realms_core::{Duration, Grid, Pose2, RoverId, Time, Topic};
use realms_net::mapdelta::Decoder;
use std::collections::BTreeMap;

/// Where the lander publishes the network's traffic statistics.
pub const NETWORK_STATS_TOPIC: &str = "lander/network/stats";

/// The lander merges the rovers' maps this often.
const MERGE_PERIOD: Duration = Duration::from_secs(120);

/// A snapshot request is repeated after this long if no snapshot came.
const REQUEST_RETRY: Duration = Duration::from_secs(10);

/// Which station.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StationRole {
    /// The lander: gateway and store.
    Lander,
    /// The operator's ground station.
    Ground,
}

/// What a station knows of one rover.
#[derive(Clone, Debug, Default)]
pub struct RoverRecord {
    /// The rover's map as rebuilt from its updates.
    pub map: Decoder,
    /// The time of the rover's map the rebuilt one matches.
    pub map_stamp: Option<Time>,
    /// Updates applied, and updates that could not be (a gap or a malformed update).
    pub updates_applied: u64,
    /// Updates refused.
    pub updates_refused: u64,
    /// Latest pose estimate.
    pub pose: Option<(Time, Pose2)>,
    /// Latest localisation state.
    pub localisation: Option<(Time, LocalisationState)>,
    /// Latest navigation status.
    pub nav: Option<NavStatus>,
    last_request: Option<Time>,
}

/// The lander's or the ground station's node.
#[derive(Debug)]
pub struct StationNode {
    name: String,
    fleet: Vec<RoverId>,
    rovers: BTreeMap<RoverId, RoverRecord>,
    network: Option<NetworkStats>,
    /// The lander merges the rovers' maps this often (the ground station does not merge).
    merge_period: Option<Duration>,
    next_merge: Time,
    merged: Option<MergedMap>,
    outbox: Vec<Outgoing>,
}

impl StationNode {
    /// A station listening to `fleet`.
    pub fn new(role: StationRole, fleet: Vec<RoverId>) -> Self {
        StationNode {
            name: match role {
                StationRole::Lander => "lander".into(),
                StationRole::Ground => "ground".into(),
            },
            fleet,
            rovers: BTreeMap::new(),
            network: None,
            merge_period: (role == StationRole::Lander).then_some(MERGE_PERIOD),
            next_merge: Time::ZERO,
            merged: None,
            outbox: Vec::new(),
        }
    }

    /// What the station knows of `rover`.
    pub fn rover(&self, rover: RoverId) -> Option<&RoverRecord> {
        self.rovers.get(&rover)
    }

    /// The lander's latest merge of the rovers' maps.
    pub fn merged(&self) -> Option<&MergedMap> {
        self.merged.as_ref()
    }

    /// Merges every rover's rebuilt map now (the lander's job).
    pub fn merge_now(&mut self) {
        let maps: Vec<(RoverId, &Grid<i8>)> = self
            .fleet
            .iter()
            .filter_map(|r| {
                self.rovers
                    .get(r)
                    .and_then(|rec| rec.map.map())
                    .map(|m| (*r, m))
            })
            .collect();
        if maps.len() >= 2 {
            self.merged = merge_from_known_start(&maps);
        }
    }

    /// The latest network statistics heard.
    pub fn network(&self) -> Option<&NetworkStats> {
        self.network.as_ref()
    }

    /// The rebuilt map of `rover`, if any.
    pub fn map(&self, rover: RoverId) -> Option<&Grid<i8>> {
        self.rovers.get(&rover).and_then(|r| r.map.map())
    }

    fn on_delta(&mut self, now: Time, rover: RoverId, delta: &MapDelta) {
        let record = self.rovers.entry(rover).or_default();
        match record.map.apply(&delta.update) {
            Ok(()) => {
                record.updates_applied += 1;
                record.map_stamp = Some(delta.header.stamp);
                if delta.update.is_snapshot() {
                    record.last_request = None;
                }
            }
            Err(_) => {
                record.updates_refused += 1;
                // Ask again only if no snapshot came within the retry time: one is on its way.
                if record.last_request.is_none_or(|t| now - t >= REQUEST_RETRY) {
                    record.last_request = Some(now);
                    self.outbox.push(Outgoing {
                        topic: rover.topic("map/request"),
                        message: Message::MapRequest(Header {
                            stamp: now,
                            frame_id: self.name.clone(),
                        }),
                    });
                }
            }
        }
    }
}

impl Node for StationNode {
    fn name(&self) -> &str {
        &self.name
    }

    fn subscriptions(&self) -> Vec<Topic> {
        self.fleet
            .iter()
            .flat_map(|r| {
                [
                    "map/delta",
                    "map/snapshot",
                    "pose",
                    "localisation",
                    "nav/status",
                ]
                .iter()
                .map(|leaf| r.topic(leaf))
            })
            .chain(std::iter::once(Topic::new(NETWORK_STATS_TOPIC)))
            .collect()
    }

    fn on_message(&mut self, now: Time, topic: &Topic, message: &Message) {
        if let Message::NetworkStats(stats) = message {
            self.network = Some((**stats).clone());
            return;
        }
        let Some(rover) = topic.rover() else { return };
        match message {
            Message::MapDelta(delta) => {
                self.on_delta(now, rover, delta);
                if let Some(period) = self.merge_period
                    && now >= self.next_merge
                {
                    self.next_merge = now + period;
                    self.merge_now();
                }
            }
            Message::Pose(p) => {
                let q = &p.pose.pose;
                let pose = Pose2::new(q.position.x, q.position.y, q.orientation.yaw_rad());
                self.rovers.entry(rover).or_default().pose = Some((p.header.stamp, pose));
            }
            Message::Localisation(l) => {
                self.rovers.entry(rover).or_default().localisation =
                    Some((l.header.stamp, l.state));
            }
            Message::NavStatus(s) => {
                self.rovers.entry(rover).or_default().nav = Some(s.clone());
            }
            _ => {}
        }
    }

    fn on_tick(&mut self, _now: Time) {}

    fn on_shutdown(&mut self, _now: Time) {
        if self.merge_period.is_some() {
            self.merge_now();
        }
    }

    fn drain_outbox(&mut self) -> Vec<Outgoing> {
        std::mem::take(&mut self.outbox)
    }

    fn next_wakeup(&self) -> Option<Time> {
        None
    }

    fn as_station(&self) -> Option<&StationNode> {
        Some(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::GridGeometry;
    use realms_net::mapdelta::Encoder;

    fn delta(stamp: Time, update: realms_core::msgs::MapUpdate) -> Message {
        Message::MapDelta(Box::new(MapDelta {
            header: Header {
                stamp,
                frame_id: "rover1/map".into(),
            },
            update,
        }))
    }

    #[test]
    fn rebuilds_the_map_and_asks_for_a_snapshot_after_a_gap() {
        let rover = RoverId(1);
        let topic = rover.topic("map/delta");
        let mut station = StationNode::new(StationRole::Ground, vec![rover]);
        let geo = GridGeometry {
            width: 8,
            height: 6,
            resolution_m: 0.05,
            origin: realms_core::Point2::new(0.0, 0.0),
        };
        let mut map = Grid::new(geo, -1i8);
        let mut enc = Encoder::new();
        station.on_message(
            Time::ZERO,
            &topic,
            &delta(Time::ZERO, enc.update(&map, false)),
        );
        *map.get_mut(2, 3).expect("in the map") = 100;
        // An update that never arrives.
        let _missed = enc.update(&map, false);
        *map.get_mut(5, 1).expect("in the map") = 0;
        let t = Time::from_secs_f64(4.0);
        station.on_message(t, &topic, &delta(t, enc.update(&map, false)));
        let asked = station.drain_outbox();
        assert_eq!(asked.len(), 1, "one snapshot request");
        assert_eq!(asked[0].topic, rover.topic("map/request"));
        assert_ne!(station.map(rover), Some(&map), "the gap left it behind");
        let t = Time::from_secs_f64(5.0);
        station.on_message(t, &topic, &delta(t, enc.update(&map, false)));
        assert!(
            station.drain_outbox().is_empty(),
            "a request is already out"
        );
        let t = Time::from_secs_f64(6.0);
        station.on_message(t, &topic, &delta(t, enc.update(&map, true)));
        assert_eq!(station.map(rover), Some(&map));
        assert_eq!(station.rover(rover).and_then(|r| r.map_stamp), Some(t));
    }
}
