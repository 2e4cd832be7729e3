//! The lander and the ground station, as far as they are built: each keeps every rover's
//! map, rebuilt from its `map/delta` updates, with the rover's latest pose, localisation
//! state and navigation status, and asks a rover for a snapshot when it missed an update.
//! The lander is where rover data is stored for the mission; every two minutes it merges
//! the maps (only when one has changed) and publishes where it placed each
//! (`lander/map/transforms`). The ground station is what the operator sees: it keeps the
//! latest transforms and draws the merged map from its own copies of the rovers' maps.

use crate::lander_merge::{MergedMap, merge_from_known_start};
use crate::{Node, Outgoing};
use realms_core::msgs::{
    Header, LocalisationState, MapDelta, MapTransforms, Message, NavStatus, NetworkStats,
};
use realms_core::{Duration, Grid, Pose2, RoverId, Time, Topic};
use realms_net::mapdelta::Decoder;
use std::collections::BTreeMap;

/// Where the lander publishes the network's traffic statistics.
pub const NETWORK_STATS_TOPIC: &str = "lander/network/stats";

/// Where the lander publishes where it placed each rover's map ([`MapTransforms`]).
pub const MAP_TRANSFORMS_TOPIC: &str = "lander/map/transforms";

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
    /// Goes up by one with every update that changed the rebuilt map (a rover sends
    /// updates on a clock, changed or not).
    pub map_version: u64,
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
    /// The version of each rover's map the last merge used: nothing changed, nothing to
    /// redo.
    merged_versions: Vec<u64>,
    /// Merges actually run (not skipped because no map had changed).
    merges_run: usize,
    /// The lander's latest transforms, as heard (the ground station).
    transforms: Option<MapTransforms>,
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
            merged_versions: Vec::new(),
            merges_run: 0,
            transforms: None,
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

    /// Merges run so far (a merge is skipped when no rover's map changed since the last).
    pub fn merges_run(&self) -> usize {
        self.merges_run
    }

    /// The lander's latest transforms, as this station heard them.
    pub fn transforms(&self) -> Option<&MapTransforms> {
        self.transforms.as_ref()
    }

    /// The merged map from this station's own copies of the rovers' maps, placed where the
    /// lander's latest transforms say (the ground station's view of the merge).
    pub fn merged_from_transforms(&self) -> Option<Grid<realms_merge::MapCell>> {
        let transforms = self.transforms.as_ref()?;
        crate::lander_merge::compose_with_transforms(&self.fleet_maps(), transforms)
    }

    /// Every rover's rebuilt map this station holds, in fleet order.
    fn fleet_maps(&self) -> Vec<(RoverId, &Grid<i8>)> {
        self.fleet
            .iter()
            .filter_map(|r| self.map(*r).map(|m| (*r, m)))
            .collect()
    }

    /// Merges every rover's rebuilt map now (the lander's job), unless none has changed
    /// since the last merge, and publishes where each went. Returns whether there were two
    /// maps to merge.
    pub fn merge_now(&mut self, now: Time) -> bool {
        let versions: Vec<u64> = self
            .fleet
            .iter()
            .map(|r| self.rovers.get(r).map_or(0, |rec| rec.map_version))
            .collect();
        if self.merged.is_some() && versions == self.merged_versions {
            return true;
        }
        let maps = self.fleet_maps();
        if maps.len() < 2 {
            return false;
        }
        self.merged = merge_from_known_start(&maps);
        if let Some(m) = &self.merged {
            self.merged_versions = versions;
            self.merges_run += 1;
            self.outbox.push(Outgoing {
                topic: Topic::new(MAP_TRANSFORMS_TOPIC),
                message: Message::MapTransforms(m.transforms(now)),
            });
        }
        true
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
        let geometry_before = record.map.map().map(|m| *m.geometry());
        match record.map.apply(&delta.update) {
            Ok(()) => {
                let u = &delta.update;
                if u.base.is_none()
                    || !u.runs.is_empty()
                    || record.map.map().map(|m| *m.geometry()) != geometry_before
                {
                    record.map_version += 1;
                }
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
            .chain((self.merge_period.is_none()).then(|| Topic::new(MAP_TRANSFORMS_TOPIC)))
            .collect()
    }

    fn on_message(&mut self, now: Time, topic: &Topic, message: &Message) {
        match message {
            Message::NetworkStats(stats) => {
                self.network = Some((**stats).clone());
                return;
            }
            Message::MapTransforms(t) => {
                self.transforms = Some(t.clone());
                return;
            }
            _ => {}
        }
        let Some(rover) = topic.rover() else { return };
        match message {
            Message::MapDelta(delta) => {
                self.on_delta(now, rover, delta);
                // The period starts once there are two maps to merge.
                if let Some(period) = self.merge_period
                    && now >= self.next_merge
                    && self.merge_now(now)
                {
                    self.next_merge = now + period;
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

    fn on_shutdown(&mut self, now: Time) {
        if self.merge_period.is_some() {
            self.merge_now(now);
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

    /// A 6 m x 4 m room at 5 cm, walls all round and a post at (2, 2), seen by `rover`.
    fn room() -> Grid<i8> {
        let geo = GridGeometry {
            width: 120,
            height: 80,
            resolution_m: 0.05,
            origin: realms_core::Point2::new(0.0, 0.0),
        };
        let cells = (0..geo.len())
            .map(|i| {
                let (x, y) = (i % geo.width, i / geo.width);
                let p = geo.cell_center(realms_core::Cell { x, y });
                let wall = x == 0 || y == 0 || x == geo.width - 1 || y == geo.height - 1;
                let post = p.distance_m(realms_core::Point2::new(2.0, 2.0)) < 0.2
                    || p.distance_m(realms_core::Point2::new(4.5, 1.0)) < 0.15;
                if wall || post { 100 } else { 0 }
            })
            .collect();
        Grid::from_cells(geo, cells).expect("one value per cell")
    }

    #[test]
    fn a_rover_map_with_a_geometry_no_rover_draws_never_panics_the_lander() {
        // A corrupt update that still decodes: the lander keeps merging what it has.
        let rovers = [RoverId(1), RoverId(2)];
        let mut lander = StationNode::new(StationRole::Lander, rovers.to_vec());
        let map = room();
        let t = Time::ZERO;
        let mut good = Encoder::new();
        lander.on_message(
            t,
            &rovers[0].topic("map/delta"),
            &delta(t, good.update(&map, true)),
        );
        for (resolution_m, origin_m) in [
            (1e-300, 0.0),
            (1e300, 0.0),
            (0.05, 1e300),
            (0.05, -1e18),
            (1e-9, 1e9),
            // Odd but possible: taken in, and the merge runs on them.
            (0.5, 1e5),
            (0.001, -9e5),
        ] {
            let mut odd = map.clone();
            let geo = GridGeometry {
                resolution_m,
                origin: realms_core::Point2::new(origin_m, -origin_m),
                ..*map.geometry()
            };
            odd = Grid::from_cells(geo, odd.cells().to_vec()).expect("same cells");
            let update = Encoder::new().update(&odd, true);
            lander.on_message(t, &rovers[1].topic("map/delta"), &delta(t, update));
            lander.on_shutdown(t);
            lander.drain_outbox();
        }
        assert!(lander.map(rovers[0]).is_some());
    }

    #[test]
    fn transforms_no_merge_gives_never_hang_the_ground() {
        // A corrupt transforms message that still decodes: the ground draws what it can (a
        // map placed 1e300 m off made its drawing loop without end).
        let rovers = [RoverId(1), RoverId(2)];
        let mut ground = StationNode::new(StationRole::Ground, rovers.to_vec());
        let map = room();
        for r in rovers {
            let update = Encoder::new().update(&map, true);
            ground.on_message(
                Time::ZERO,
                &r.topic("map/delta"),
                &delta(Time::ZERO, update),
            );
        }
        for (x_m, yaw_rad) in [
            (f64::NAN, 0.0),
            (1e300, 0.0),
            (1e6, 0.0),
            (0.0, f64::INFINITY),
            (0.0, 1e300),
            (0.5, 0.1),
        ] {
            let transforms = MapTransforms {
                header: Header {
                    stamp: Time::ZERO,
                    frame_id: "rover1/map".into(),
                },
                maps: vec![realms_core::msgs::MapTransform {
                    child_frame_id: "rover2/map".into(),
                    pose: Some(realms_core::Point2::new(x_m, -x_m)),
                    yaw_rad,
                    confidence: 1.0,
                    confirmed: true,
                }],
            };
            ground.on_message(
                Time::ZERO,
                &Topic::new(MAP_TRANSFORMS_TOPIC),
                &Message::MapTransforms(transforms),
            );
            let drawn = ground
                .merged_from_transforms()
                .expect("the reference is drawn");
            // A map placed where no merge puts one is left out: the reference alone.
            let alone = x_m.abs() > crate::lander_merge::MAX_TRANSFORM_M
                || !x_m.is_finite()
                || !yaw_rad.is_finite();
            let (cells, reference) = (drawn.geometry().len(), map.geometry().len());
            if alone {
                assert_eq!(cells, reference, "{x_m} {yaw_rad}");
            } else {
                // Placed beside the reference, shifted or turned: the merge spans more.
                assert!(cells > reference, "{x_m} {yaw_rad}: {cells} cells");
            }
        }
    }

    #[test]
    fn the_lander_merges_when_a_map_changed_and_the_ground_draws_the_merge_from_its_transforms() {
        let rovers = [RoverId(1), RoverId(2)];
        let mut lander = StationNode::new(StationRole::Lander, rovers.to_vec());
        let mut ground = StationNode::new(StationRole::Ground, rovers.to_vec());
        assert!(
            ground
                .subscriptions()
                .contains(&Topic::new(MAP_TRANSFORMS_TOPIC))
        );
        let map = room();
        let mut encoders = [Encoder::new(), Encoder::new()];
        let mut send = |station: &mut StationNode, t: f64, snapshot: bool| {
            let t = Time::from_secs_f64(t);
            for (k, r) in rovers.iter().enumerate() {
                let update = encoders[k].update(&map, snapshot);
                station.on_message(t, &r.topic("map/delta"), &delta(t, update));
            }
        };
        send(&mut lander, 0.0, true);
        let published = lander.drain_outbox();
        assert_eq!(lander.merges_run(), 1);
        assert_eq!(published.len(), 1, "{published:?}");
        assert_eq!(published[0].topic, Topic::new(MAP_TRANSFORMS_TOPIC));
        // The same maps two minutes later, sent again unchanged: nothing to redo.
        send(&mut lander, 130.0, false);
        assert_eq!(lander.merges_run(), 1);
        assert!(lander.drain_outbox().is_empty());
        // The ground has the maps and the transforms: its merged map is the lander's.
        let mut encoders2 = [Encoder::new(), Encoder::new()];
        for (k, r) in rovers.iter().enumerate() {
            let update = encoders2[k].update(&map, true);
            ground.on_message(
                Time::ZERO,
                &r.topic("map/delta"),
                &delta(Time::ZERO, update),
            );
        }
        assert_eq!(
            ground.merged_from_transforms(),
            None,
            "no transforms heard yet"
        );
        ground.on_message(Time::ZERO, &published[0].topic, &published[0].message);
        let drawn = ground.merged_from_transforms().expect("drawn");
        assert_eq!(Some(&drawn), lander.merged().map(|m| &m.cells));
    }
}
