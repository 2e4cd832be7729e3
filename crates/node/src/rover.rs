//! The rover node: a rover's on-board logic. It runs SLAM on its own scans and odometry
//! ([`Mapping`]), publishing its pose, its localisation state and its map; it explores by
//! itself ([`Navigator`]), telling its peers where it is heading (`nav/status`) and hearing
//! where they are, and takes operator goals (`nav/goal`). Its own sensors guard it
//! ([`Guard`]) against what the map does not show yet, and it stops if its lidar falls
//! silent.

use crate::cost::CostClock;
use crate::guard::{Guard, GuardConfig};
use crate::mapping::{Mapping, MappingConfig};
use crate::navigation::{Activity, GoalKind, Guarded, NavigationConfig, Navigator};
use crate::{Node, Outgoing};
use realms_core::geometry::Vec3;
use realms_core::msgs::{
    ExploredArea, Header, Message, NavActivity, NavStatus, Twist, TwistStamped,
};
use realms_core::{Duration, RoverId, Time, Topic};
use realms_slam::health::LocalisationState;

/// How long without a scan before the node commands a stop.
const SCAN_SILENCE: Duration = Duration::from_millis(500);
/// The navigation status is repeated this often even when nothing changed, so a peer that
/// missed it (or joined late) learns it.
const STATUS_REPEAT: Duration = Duration::from_secs(10);
/// How often the rover tells its peers which ground its map knows.
const EXPLORED_PERIOD: Duration = Duration::from_secs(15);
/// ... in cells this many times the navigation map's (0.5 m).
const EXPLORED_FACTOR: usize = 5;
/// Navigation plans on a map this many times coarser than SLAM's.
const NAV_MAP_FACTOR: usize = 2;
/// Yaw rate while lost: turning in place shows the relocaliser new views.
const LOST_TURN_RAD_S: f64 = 0.3;
/// A lost rover turns this long (about two turns) to show the relocaliser every view from
/// where it stands, before it drives back to where it saw more.
const LOST_TURN: Duration = Duration::from_secs(45);
/// A lost rover drives back to places whose scans kept at least this many returns: it
/// lost its place where it saw little (the open middle of a hall, one rock in range), and a
/// search of the map for a view of a few returns finds it fits many places.
const RELOCALISE_PLACE_POINTS: usize = 100;
/// ... whose returns pin a pose every way, at least this share of their surfaces' weight
/// across the direction they pin least (`realms_slam::mapper::weakest_direction_share`; a
/// straight wall's is 0, a corner's up to 0.5) ...
const RELOCALISE_PLACE_WEAKEST_SHARE: f64 = 0.1;
/// ... at least this far from where it is and from one another, metres ...
const RELOCALISE_PLACE_SPACING_M: f64 = 1.0;
/// ... and tries this many of them before it stops and waits for the operator: its wheels
/// and gyro carry its pose while it drives, and they drift.
const RELOCALISE_PLACES: usize = 3;
/// A peer not heard for this long (six of its status repeats) is taken to be gone, powered
/// off or out of reach, when a rover asks whether the fleet has finished exploring.
const PEER_GONE: Duration = Duration::from_secs(60);

/// Everything a rover node needs to know.
#[derive(Clone, Debug, PartialEq)]
pub struct RoverConfig {
    /// SLAM on board.
    pub mapping: MappingConfig,
    /// Navigation and exploration.
    pub navigation: NavigationConfig,
    /// The reactive guard.
    pub guard: GuardConfig,
    /// Every rover of the fleet (itself included): whose `nav/status` it listens to.
    pub fleet: Vec<RoverId>,
    /// Times SLAM's work, for the record.
    pub cost_clock: CostClock,
}

/// A rover's on-board node.
#[derive(Debug)]
pub struct RoverNode {
    id: RoverId,
    name: String,
    fleet: Vec<RoverId>,
    mapping: Mapping,
    navigator: Navigator,
    guard: Guard,
    last_scan: Option<Time>,
    stopped_for_silence: bool,
    last_cmd_v: f64,
    last_status: Option<(NavActivity, Option<realms_core::Point2>, Time)>,
    /// The navigator's latest event, for the status.
    reason: String,
    next_explored: Time,
    /// Since when it has been lost, if it is.
    lost_since: Option<Time>,
    /// The places it drove back to since it got lost, to find itself again.
    relocalisation_places: Vec<realms_core::Point2>,
    /// Lost, and it stopped looking: no view it turned through or drove back to matched.
    lost_gave_up: bool,
    /// Whether its map has been drawn from the final trajectory since exploring ended (see
    /// [`RoverNode::finish_when_done`]).
    finished_map: bool,
    /// Each peer's last reported activity, and when it was heard.
    peers_heard: Vec<(RoverId, NavActivity, Time)>,
    outbox: Vec<Outgoing>,
    cost_clock: CostClock,
    /// Wall time spent in SLAM, to report what it costs (see [`CostClock`]).
    slam_wall: std::time::Duration,
    /// Own sensor messages dropped for holding numbers no sensor gives
    /// ([`crate::plausible`]), and operator goals at no place on any map.
    rejected_inputs: u64,
}

impl RoverNode {
    /// The node of rover `id`.
    pub fn new(id: RoverId, cfg: RoverConfig) -> Self {
        RoverNode {
            id,
            name: id.namespace(),
            fleet: cfg.fleet,
            mapping: Mapping::new(id, cfg.mapping),
            navigator: Navigator::new(id, cfg.navigation),
            guard: Guard::new(cfg.guard),
            last_scan: None,
            stopped_for_silence: false,
            last_cmd_v: 0.0,
            last_status: None,
            reason: String::new(),
            next_explored: Time::ZERO,
            lost_since: None,
            relocalisation_places: Vec::new(),
            lost_gave_up: false,
            finished_map: false,
            peers_heard: Vec::new(),
            outbox: Vec::new(),
            cost_clock: cfg.cost_clock,
            slam_wall: std::time::Duration::ZERO,
            rejected_inputs: 0,
        }
    }

    /// Which rover this is.
    pub fn id(&self) -> RoverId {
        self.id
    }

    /// Wall time this rover's SLAM has taken so far, seconds: scan matching, the pose graph,
    /// the hazard layer and drawing the maps it publishes and plans on. It varies from run to
    /// run.
    pub fn slam_wall_s(&self) -> f64 {
        self.slam_wall.as_secs_f64()
    }

    /// How many of its own sensor messages the rover dropped for holding numbers no sensor
    /// gives (a driver's glitch; [`crate::plausible`]), and how many operator goals it
    /// refused for coordinates that are not numbers.
    pub fn rejected_inputs(&self) -> u64 {
        self.rejected_inputs
    }

    /// Hands an operator's goal to the navigator; one it refuses is counted and said at
    /// once, not at the next status due.
    fn take_operator_goal(&mut self, now: Time, target: Option<realms_core::Point2>) {
        if !self.navigator.set_operator_goal(now, target) {
            self.rejected_inputs += 1;
            self.publish_status(now);
        }
    }

    /// The rover's on-board SLAM.
    pub fn mapping(&self) -> &Mapping {
        &self.mapping
    }

    fn header(&self, now: Time) -> Header {
        Header {
            stamp: now,
            frame_id: format!("{}/map", self.name),
        }
    }

    fn send_cmd(&mut self, now: Time, v_m_s: f64, w_rad_s: f64) {
        self.last_cmd_v = v_m_s;
        self.outbox.push(Outgoing {
            topic: self.id.topic("cmd_vel"),
            message: Message::CmdVel(TwistStamped {
                header: Header {
                    stamp: now,
                    frame_id: format!("{}/base_link", self.name),
                },
                twist: Twist {
                    linear: Vec3::new(v_m_s, 0.0, 0.0),
                    angular: Vec3::new(0.0, 0.0, w_rad_s),
                },
            }),
        });
    }

    /// Publishes `nav/status` when it changed or is due again.
    fn publish_status(&mut self, now: Time) {
        let gave_up = self.lost_gave_up;
        // Lost and still turning on the spot: whatever goal it had waits, and its target
        // is no claim a peer should leave alone.
        let turning_lost = self.lost_since.is_some()
            && !gave_up
            && !self.navigator.relocalising()
            && self.mapping.state() == LocalisationState::Lost;
        let activity = match self.navigator.activity() {
            // The operator's goal is driven even by a rover that gave up finding itself.
            Activity::Driving(GoalKind::Operator) if gave_up => NavActivity::OperatorGoal,
            Activity::Recovering if gave_up && self.navigator.has_operator_goal() => {
                NavActivity::Recovering
            }
            _ if gave_up => NavActivity::Lost,
            _ if turning_lost => NavActivity::Relocalising,
            Activity::Idle => NavActivity::Idle,
            Activity::Driving(GoalKind::Frontier) => NavActivity::Exploring,
            Activity::Driving(GoalKind::Operator) => NavActivity::OperatorGoal,
            Activity::Driving(GoalKind::Home) => NavActivity::ReturningHome,
            Activity::Driving(GoalKind::Revisit) => NavActivity::Revisiting,
            Activity::Driving(GoalKind::Relocalise) => NavActivity::Relocalising,
            Activity::Recovering => NavActivity::Recovering,
            Activity::Done => NavActivity::Done,
        };
        let target = self
            .navigator
            .goal()
            .filter(|_| !turning_lost && activity != NavActivity::Lost)
            .map(|(p, _)| p);
        let events = self.navigator.take_events();
        let mut news = !events.is_empty();
        if let Some(e) = events.last() {
            self.reason = e.what.clone();
        }
        // Entering a lost state is news, with the reason said once.
        let entered = self.last_status.is_none_or(|(a, _, _)| a != activity);
        let entry_reason = match activity {
            NavActivity::Relocalising if turning_lost => {
                Some("lost its place: turning on the spot to find itself".to_string())
            }
            NavActivity::Lost => {
                let lost_s = self.lost_since.map_or(0.0, |t| (now - t).as_secs_f64());
                Some(format!(
                    "lost for {lost_s:.0} s: no view it turned through or drove back to ({} \
                     places) matched the map: stopped, waiting for the operator",
                    self.relocalisation_places.len()
                ))
            }
            _ => None,
        };
        if let Some(why) = entry_reason.filter(|_| entered) {
            self.reason = why;
            news = true;
        }
        let due = match self.last_status {
            None => true,
            Some((a, t, at)) => news || a != activity || t != target || now - at >= STATUS_REPEAT,
        };
        if due {
            self.last_status = Some((activity, target, now));
            self.outbox.push(Outgoing {
                topic: self.id.topic("nav/status"),
                message: Message::NavStatus(NavStatus {
                    header: self.header(now),
                    activity,
                    target,
                    reason: self.reason.clone(),
                }),
            });
        }
    }

    /// Tells the peers which ground the map knows, coarsely.
    fn publish_explored(&mut self, now: Time, map: &realms_core::Grid<i8>) {
        let coarse = realms_nav::frontier::coarse_known(map, EXPLORED_FACTOR);
        let g = *coarse.geometry();
        let mut known = vec![0u8; g.len().div_ceil(8)];
        for (i, k) in coarse.cells().iter().enumerate() {
            if *k {
                known[i / 8] |= 1 << (i % 8);
            }
        }
        self.outbox.push(Outgoing {
            topic: self.id.topic("nav/explored"),
            message: Message::Explored(ExploredArea {
                header: self.header(now),
                origin: g.origin,
                resolution_m: g.resolution_m as f32,
                width: g.width as u32,
                height: g.height as u32,
                known,
            }),
        });
    }

    /// Once the fleet's exploring is over and this rover is home, draws its map again from
    /// the final trajectory (as at shutdown), so the map updates the lander and the ground
    /// already receive carry the rover's best map while it is parked. Before, they only
    /// ever held the map as drawn while driving, and the lander merged that: on seed 5's
    /// default mission the lander's copy of rover3 was 90.5 % right where its final map was
    /// 97.5 % (BENCHMARKS.md, "The lander merges the rovers' final maps").
    ///
    /// It waits for its peers: a map redrawn while they still explore changes the ground
    /// it reports explored to them, and with it where they go. A peer counts as done once
    /// it reported `Done` or `Lost`, or when nothing was heard of it for [`PEER_GONE`] (a
    /// rover powered off). Done again each time the rover comes home anew.
    fn finish_when_done(&mut self, now: Time) {
        let done = matches!(self.navigator.activity(), Activity::Done) && self.peers_done(now);
        if done && !self.finished_map {
            let mapping = &mut self.mapping;
            self.cost_clock
                .time(&mut self.slam_wall, || mapping.finish_map());
        }
        self.finished_map = done;
    }

    /// Whether every peer reported `Done` or `Lost` last, or has not been heard for
    /// [`PEER_GONE`] (never heard: since the mission began).
    fn peers_done(&self, now: Time) -> bool {
        let mut peers = self.fleet.iter().filter(|peer| **peer != self.id);
        peers.all(|peer| {
            let last = self.peers_heard.iter().find(|(r, _, _)| r == peer);
            match last {
                Some((_, activity, at)) => {
                    matches!(activity, NavActivity::Done | NavActivity::Lost)
                        || now - *at >= PEER_GONE
                }
                None => now - Time::ZERO >= PEER_GONE,
            }
        })
    }

    /// Whether its map is drawn from its final trajectory: exploring is over for the
    /// fleet as far as it heard, and it is home (see `RoverNode::finish_when_done`).
    pub fn map_finished(&self) -> bool {
        self.finished_map
    }

    /// Decides the velocity after a scan.
    fn drive(&mut self, now: Time, scan: &realms_core::msgs::LaserScan) -> (f64, f64) {
        if self.mapping.calibrating(now) {
            return (0.0, 0.0);
        }
        let guarded = self.guard.on_scan(now, scan);
        self.mapping.set_homing(matches!(
            self.navigator.activity(),
            Activity::Driving(GoalKind::Home) | Activity::Done
        ));
        if self.mapping.state() == LocalisationState::Lost {
            let since = *self.lost_since.get_or_insert(now);
            if now - since < LOST_TURN {
                return (0.0, LOST_TURN_RAD_S);
            }
            return self.drive_to_relocalise(now, guarded);
        }
        if let Some(since) = self.lost_since.take() {
            self.navigator.relocalised(now, now - since);
        }
        self.relocalisation_places.clear();
        self.lost_gave_up = false;
        let pose = self.mapping.pose();
        if self.navigator.wants_map(now) {
            let mapping = &mut self.mapping;
            let map = self
                .cost_clock
                .time(&mut self.slam_wall, || mapping.nav_map(NAV_MAP_FACTOR));
            if let Some((within_m, points)) = self.navigator.anchored() {
                let sigma = self.mapping.position_uncertainty_m();
                let place = sigma.and_then(|_| {
                    let (mapper, nav) = (self.mapping.mapper(), &self.navigator);
                    let wanted = |p| nav.may_revisit(p);
                    mapper.anchored_place_near(pose.position(), within_m, points, wanted)
                });
                self.navigator.set_localisation(sigma.map(|s| (s, place)));
            }
            self.navigator.on_map(now, &map, pose);
            if now >= self.next_explored {
                self.next_explored = now + EXPLORED_PERIOD;
                self.publish_explored(now, &map);
            }
        }
        self.navigator.steer(now, pose, self.last_cmd_v, guarded)
    }

    /// Lost, and turning on the spot found nothing: drives on its wheels and gyro, over the
    /// map as it was when it got lost, to the nearest place where its lidar saw enough to
    /// find itself again (the mapper searches its map at every step of the way), trying up
    /// to [`RELOCALISE_PLACES`] before it stops and waits for the operator. This is the
    /// "backtrack" recovery of field robots whose localisation fails in sparse terrain: the
    /// way back is ground it drove, and its own guard still watches the ground ahead. A rover
    /// whose dead-reckoned pose left that map can plan no way back: each place is given up
    /// at the next map (see `Navigator::off_map`), and it gives up within a few scans.
    ///
    /// Once it gave up, it stands still until the operator sends it a goal, which it then
    /// drives to the same way (the mapper still searches its map at every step).
    fn drive_to_relocalise(&mut self, now: Time, guarded: Guarded) -> (f64, f64) {
        if self.lost_gave_up && !self.navigator.has_operator_goal() {
            return (0.0, 0.0);
        }
        let pose = self.mapping.pose();
        if !self.lost_gave_up && !self.navigator.relocalising() {
            let tried = &self.relocalisation_places;
            let wanted = |p: realms_core::Point2| {
                tried
                    .iter()
                    .all(|t| t.distance_m(p) >= RELOCALISE_PLACE_SPACING_M)
            };
            let place = (tried.len() < RELOCALISE_PLACES)
                .then(|| {
                    self.mapping.mapper().relocalisation_place(
                        pose.position(),
                        RELOCALISE_PLACE_SPACING_M,
                        RELOCALISE_PLACE_POINTS,
                        RELOCALISE_PLACE_WEAKEST_SHARE,
                        wanted,
                    )
                })
                .flatten();
            let Some(place) = place else {
                self.lost_gave_up = true;
                // A goal the operator sent before it gave up was meant for a rover that
                // knows where it is: only one sent to the rover that gave up is driven blind.
                self.navigator
                    .forget_operator_goal(now, "the rover gave up finding itself");
                return (0.0, 0.0);
            };
            self.relocalisation_places.push(place);
            self.navigator.set_localisation(None);
            self.navigator.start_relocalising(now, place);
        }
        if self.navigator.wants_map(now) {
            let mapping = &mut self.mapping;
            let map = self
                .cost_clock
                .time(&mut self.slam_wall, || mapping.nav_map(NAV_MAP_FACTOR));
            self.navigator.on_map(now, &map, pose);
        }
        self.navigator.steer(now, pose, self.last_cmd_v, guarded)
    }
}

impl Node for RoverNode {
    fn name(&self) -> &str {
        &self.name
    }

    fn subscriptions(&self) -> Vec<Topic> {
        let mut topics: Vec<Topic> = [
            "scan",
            "depth/points",
            "odom",
            "imu",
            "nav/goal",
            "map/request",
        ]
        .iter()
        .map(|leaf| self.id.topic(leaf))
        .collect();
        for peer in self.fleet.iter().filter(|peer| **peer != self.id) {
            topics.push(peer.topic("nav/status"));
            topics.push(peer.topic("nav/explored"));
        }
        topics
    }

    fn on_message(&mut self, now: Time, topic: &Topic, message: &Message) {
        let Some(from) = topic.rover() else { return };
        if from != self.id {
            match message {
                Message::NavStatus(status) => {
                    let target = match status.activity {
                        NavActivity::Exploring => status.target,
                        _ => None,
                    };
                    self.navigator.hear_peer(now, from, target);
                    match self.peers_heard.iter_mut().find(|(r, _, _)| *r == from) {
                        Some(heard) => *heard = (from, status.activity, now),
                        None => self.peers_heard.push((from, status.activity, now)),
                    }
                }
                Message::Explored(area) => self.navigator.hear_explored(now, from, area.clone()),
                _ => {}
            }
            return;
        }
        if crate::plausible::implausible(message)
            .or_else(|| crate::plausible::implausible_stamp(message, now))
            .is_some()
        {
            self.rejected_inputs += 1;
            return;
        }
        let (clock, mapping, spent) = (self.cost_clock, &mut self.mapping, &mut self.slam_wall);
        match message {
            Message::LaserScan(scan) => {
                self.last_scan = Some(now);
                self.stopped_for_silence = false;
                let outbox = &mut self.outbox;
                clock.time(spent, || mapping.on_scan(scan, outbox));
                let (v, w) = self.drive(now, scan);
                self.send_cmd(now, v, w);
                self.finish_when_done(now);
                self.publish_status(now);
            }
            Message::Odometry(odom) => clock.time(spent, || mapping.on_odometry(odom)),
            Message::Imu(imu) => clock.time(spent, || mapping.on_imu(imu)),
            Message::PointCloud(cloud) => {
                clock.time(spent, || mapping.on_depth(cloud));
                self.guard.on_depth(now, cloud);
            }
            Message::NavGoal(goal) => self.take_operator_goal(now, goal.target),
            Message::MapRequest(_) => self.mapping.request_snapshot(),
            _ => {}
        }
    }

    fn on_tick(&mut self, now: Time) {
        if let Some(last) = self.last_scan
            && now - last >= SCAN_SILENCE
            && !self.stopped_for_silence
        {
            self.stopped_for_silence = true;
            self.send_cmd(now, 0.0, 0.0);
        }
    }

    fn on_shutdown(&mut self, now: Time) {
        let (mapping, outbox) = (&mut self.mapping, &mut self.outbox);
        self.cost_clock.time(&mut self.slam_wall, || {
            mapping.finish_map();
            mapping.finish_hazards();
            mapping.publish_map(now, outbox)
        });
    }

    fn as_rover(&self) -> Option<&RoverNode> {
        Some(self)
    }

    fn drain_outbox(&mut self) -> Vec<Outgoing> {
        std::mem::take(&mut self.outbox)
    }

    fn next_wakeup(&self) -> Option<Time> {
        match self.last_scan {
            Some(last) if !self.stopped_for_silence => Some(last + SCAN_SILENCE),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mapping::rover_mapper_config;
    use realms_core::Point2;
    use realms_core::Pose2;
    use realms_core::geometry::Quaternion;
    use realms_core::msgs::{Imu, LaserScan, NavGoal, Odometry};
    use realms_slam::traversability::TraversabilityConfig;

    /// The rovers' SLAM for the tests' wheels, which report the travel exactly: a
    /// calibration drive on their ground would find a scale of 1, not the analogue's 0.92.
    fn rover_mapper_config_for_exact_wheels() -> realms_slam::mapper::MapperConfig {
        let mut mapper = rover_mapper_config();
        mapper.take_wheels_at_their_word();
        mapper
    }

    fn node() -> RoverNode {
        let id = RoverId(1);
        let depth_rot = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
        RoverNode::new(
            id,
            RoverConfig {
                mapping: crate::mapping::MappingConfig {
                    lidar_x_m: 0.0,
                    lidar_height_m: 0.3,
                    ground_clearance_m: 0.12,
                    tilt_smoothing: 0.2,
                    tilt_less_wheels: None,
                    tilt_gyro: false,
                    tilt_gate: false,
                    levelled_points: false,
                    depth_at_own_stamp: false,
                    hazards_rounded_out: false,
                    hazards_follow_keyframes: None,
                    hazards_redrawn_while_mapping: false,
                    clear_rays_m: None,
                    mapper: rover_mapper_config_for_exact_wheels(),
                    map_period: Duration::from_secs(60),
                    delta_period: Duration::from_secs(60),
                    gyro_calibration: Duration::from_secs(1),
                    depth_rot,
                    depth_origin_m: [0.2, 0.0, 0.3],
                    traversability: TraversabilityConfig::default(),
                    depth_camera: None,
                    silent_pixels: false,
                    smooth_ranges: false,
                    smoothing: crate::mapping::ScanSmoothing::Ranges,
                    deskew: true,
                    depth_features: false,
                    relief_odometry: None,
                    depth_motion_filter: None,
                },
                navigation: NavigationConfig::new(Point2::new(0.0, 0.0)),
                guard: GuardConfig {
                    half_length_m: 0.2,
                    half_width_m: 0.15,
                    lidar_x_m: 0.0,
                    lidar_clearance_m: 0.25,
                    depth_reach_m: 0.6,
                    depth_rot,
                    depth_origin_m: [0.2, 0.0, 0.3],
                    max_step_m: 0.1,
                    max_drop_m: 0.15,
                },
                fleet: vec![id],
                cost_clock: CostClock::default(),
            },
        )
    }

    /// A scan from the middle of a 6 m x 4 m room (`walls`), or of open ground.
    fn scan(t: Time, walls: bool) -> LaserScan {
        let n = 360;
        let ranges = (0..n)
            .map(|i| {
                let a = -std::f64::consts::PI + i as f64 * std::f64::consts::TAU / n as f64;
                let (s, c) = a.sin_cos();
                let r = (3.0 / c.abs()).min(2.0 / s.abs());
                if walls { r as f32 } else { f32::INFINITY }
            })
            .collect();
        crate::test_scan(t, ranges)
    }

    /// Feeds the node a level IMU sample at `t` and, if given, wheels reading the position
    /// `wheels` (x, y) heading along x.
    fn wheels_and_gyro(node: &mut RoverNode, t: Time, wheels: Option<(f64, f64)>) {
        wheels_and_gyro_stamped(node, t, t, wheels);
    }

    /// [`wheels_and_gyro`] at `t` on the node's clock, both readings stamped `stamp`.
    fn wheels_and_gyro_stamped(
        node: &mut RoverNode,
        t: Time,
        stamp: Time,
        wheels: Option<(f64, f64)>,
    ) {
        let id = node.id();
        if let Some((x, y)) = wheels {
            let mut odom = Odometry::default();
            odom.header.stamp = stamp;
            odom.pose.pose.position.x = x;
            odom.pose.pose.position.y = y;
            odom.pose.pose.orientation = Quaternion::IDENTITY;
            node.on_message(t, &id.topic("odom"), &Message::Odometry(Box::new(odom)));
        }
        let mut imu = Imu::default();
        imu.header.stamp = stamp;
        imu.linear_acceleration.z = 9.81;
        node.on_message(t, &id.topic("imu"), &Message::Imu(Box::new(imu)));
    }

    /// The `k`th tick of a rover's clock 0.1 s apart.
    fn tick(k: i64) -> Time {
        Time::ZERO + Duration::from_millis(100 * k)
    }

    /// A rover that has stood 3 s in the middle of the room (to the 30th [`tick`]).
    fn settled_in_the_room() -> RoverNode {
        let mut node = node();
        for k in 1..=30 {
            step(&mut node, tick(k), Some(true));
        }
        node
    }

    /// Stands the rover of [`settled_in_the_room`] still there from tick `from` to the 100th
    /// and checks it tracks again where it is.
    fn maps_the_room_again(node: &mut RoverNode, from: i64) {
        for k in from..=100 {
            step(node, tick(k), Some(true));
        }
        node.on_tick(tick(101));
        node.drain_outbox();
        assert_ne!(node.mapping().state(), LocalisationState::Lost);
        let pose = node.mapping().pose();
        assert!(pose.x_m.hypot(pose.y_m) < 0.1, "{pose:?}");
    }

    /// Feeds the node 0.1 s of standing still ending at `t`, with a scan if `lidar`; returns
    /// the speed and yaw rate it commanded last and the navigation statuses it sent.
    fn step(
        node: &mut RoverNode,
        t: Time,
        lidar: Option<bool>,
    ) -> (Option<(f64, f64)>, Vec<NavStatus>) {
        let id = node.id();
        wheels_and_gyro(node, t, Some((0.0, 0.0)));
        if let Some(walls) = lidar {
            let topic = id.topic("scan");
            node.on_message(t, &topic, &Message::LaserScan(scan(t, walls)));
        }
        let (mut cmd, mut statuses) = (None, Vec::new());
        for o in node.drain_outbox() {
            match o.message {
                Message::CmdVel(c) => cmd = Some((c.twist.linear.x, c.twist.angular.z)),
                Message::NavStatus(s) => statuses.push(s),
                _ => {}
            }
        }
        (cmd, statuses)
    }

    #[test]
    fn a_rover_whose_wheels_count_from_800_km_out_maps_where_it_is() {
        // Odometry whose frame starts far from zero (a driver that counts on from an
        // earlier run, or a fused source in a projected grid), and a map asked for before
        // the first scan: the map's placeholder once stretched to the first scan, 800 km
        // off, and the rover ran out of memory. It drives 1 m along its 6 m x 4 m room,
        // the wheels falling silent for its first 3 s.
        let mut node = node();
        let id = node.id();
        let at = |k: i64| Time::ZERO + Duration::from_millis(100 * k);
        let start = (8e5, 3e5);
        for k in 1..=600 {
            let t = at(k);
            node.on_tick(t);
            let _ = node.mapping.map(t);
            let dx = (k as f64 * 0.002).min(1.0);
            wheels_and_gyro(&mut node, t, (k > 30).then_some((start.0 + dx, start.1)));
            let ranges = (0..360)
                .map(|i| {
                    let a = -std::f64::consts::PI + i as f64 * std::f64::consts::TAU / 360.0;
                    let (s, c) = a.sin_cos();
                    let ahead = if c > 0.0 { 3.0 - dx } else { 3.0 + dx };
                    (ahead / c.abs()).min(2.0 / s.abs()) as f32
                })
                .collect();
            let scan = crate::test_scan(t, ranges);
            node.on_message(t, &id.topic("scan"), &Message::LaserScan(scan));
            node.drain_outbox();
        }
        let pose = node.mapping().pose();
        assert!(
            (pose.x_m - start.0 - 1.0).abs() < 0.05 && (pose.y_m - start.1).abs() < 0.05,
            "{pose:?}"
        );
        let map = node.mapping.map(at(601));
        let (w, h) = (map.info.width as f64, map.info.height as f64);
        assert!(w * h < 400.0 * 400.0, "{:?}", map.info);
        // The room's walls, 2 m from the rover's path on either side, lie on the map.
        let origin = &map.info.origin.position;
        assert!(origin.x < start.0 - 2.0 && origin.x + w * 0.05 > start.0 + 4.0);
        assert!(origin.y < start.1 - 2.0 && origin.y + h * 0.05 > start.1 + 2.0);
    }

    #[test]
    fn wheels_faster_than_any_robot_and_odd_but_possible_readings_never_exhaust_the_rover() {
        // Twelve rovers fed 20 s of readings each within what `plausible` passes, from a
        // seeded generator: wheel steps of up to 900 km every 50 ms (each a jump no robot
        // drives), stamps 2 s stale, turns of 100 rad a reading, yaw rates of 999 rad/s,
        // accelerations of 1e4 m/s^2, scans of 1 to 4096 beams with ranges at and past the
        // limits and sweeps of any length. Before the wheels' steps were bounded by what a
        // robot drives in the time (`odometry::wheel_step_bound_m`), the de-skewed beams
        // and the pose followed them and the map's grids ran out of memory.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let pick = |v: &[f64], r: u64| v[(r % v.len() as u64) as usize];
        for _ in 0..12 {
            let mut node = node();
            let id = node.id();
            let at = |k: i64| Time::ZERO + Duration::from_millis(50 * k);
            let (mut x, mut yaw) = (0.0f64, 0.0f64);
            for k in 1..400 {
                let t = at(k);
                let r = next();
                // The wheels start where a driver's odometry starts, near zero.
                if k > 10 {
                    let step = pick(&[0.0, 1e-9, 0.1, 5.0, 99.0, 500.0, 9e5, -9e5, 1e3], r >> 3);
                    x += step * if r & 1 == 0 { 0.001 } else { 1.0 };
                }
                yaw += pick(&[0.0, 0.1, 3.0, 100.0, -50.0], r >> 9);
                let mut odom = Odometry::default();
                odom.header.stamp = if r % 17 == 0 { at(k - 40) } else { t };
                odom.pose.pose.position.x = x.clamp(-9e5, 9e5);
                odom.pose.pose.position.y = (x * 0.3).clamp(-9e5, 9e5);
                odom.pose.pose.orientation = Quaternion::from_roll_pitch_yaw(0.0, 0.0, yaw);
                node.on_message(t, &id.topic("odom"), &Message::Odometry(Box::new(odom)));
                let mut imu = Imu::default();
                imu.header.stamp = t;
                imu.angular_velocity.z = pick(&[0.0, 0.5, 999.0, -999.0, 1e-300], r >> 13);
                imu.linear_acceleration.z = pick(&[9.81, 0.0, -9.81, 9999.0, 1e-300], r >> 17);
                imu.linear_acceleration.x = pick(&[0.0, 9.81, -9999.0], r >> 21);
                node.on_message(t, &id.topic("imu"), &Message::Imu(Box::new(imu)));
                if k % 2 == 0 {
                    let n = pick(&[360.0, 1.0, 2.0, 3.0, 4096.0], r >> 25) as usize;
                    let reach = [0.0, 0.2, 3.0, 11.9, 12.0, 1e4, f64::INFINITY, f64::NAN];
                    let ranges = (0..n)
                        .map(|i| pick(&reach, next() >> (i % 7)) as f32)
                        .collect();
                    let mut scan = crate::test_scan(t, ranges);
                    scan.range_max_m = pick(&[12.0, 1e4, 0.16], r >> 29) as f32;
                    scan.time_increment_s = pick(&[0.0, 1e-4, 1.0, -1.0, 1e9], r >> 33) as f32;
                    node.on_message(t, &id.topic("scan"), &Message::LaserScan(scan));
                }
                if k % 50 == 0 {
                    node.on_tick(t);
                }
                node.drain_outbox();
            }
            let pose = node.mapping().pose();
            assert!(pose.x_m.hypot(pose.y_m) < 1e4, "{pose:?}");
        }
    }

    #[test]
    fn stamps_at_the_ends_of_the_clock_never_panic_the_rover() {
        // A corrupt stamp still decodes: a message may say it was taken at any instant the
        // clock holds, its first or its last nanosecond among them. Differences from such a
        // stamp overflowed the clock's arithmetic. The rover goes on, and maps the room
        // again once they stop.
        let mut node = settled_in_the_room();
        let id = node.id();
        let ends = [
            i64::MIN,
            i64::MAX,
            i64::MIN + 1,
            i64::MAX - 1,
            -1,
            i64::MIN / 2,
        ];
        // And ten minutes ahead, which overflows nothing.
        let ahead = tick(37) + Duration::from_secs(600);
        let stamps = ends.into_iter().map(Time::from_ns).chain([ahead]);
        for (k, stamp) in stamps.enumerate() {
            let t = tick(31 + k as i64);
            wheels_and_gyro_stamped(&mut node, t, stamp, Some((0.0, 0.0)));
            node.on_message(t, &id.topic("scan"), &Message::LaserScan(scan(stamp, true)));
            let cloud = realms_core::msgs::PointCloud {
                header: Header {
                    stamp,
                    frame_id: "rover1/depth".into(),
                },
                width: 2,
                height: 1,
                points_in_sensor: vec![[0.0, 0.2, 1.0], [0.1, 0.2, 1.0]],
            };
            node.on_message(t, &id.topic("depth/points"), &Message::PointCloud(cloud));
            node.on_tick(t);
            node.drain_outbox();
        }
        // Of the seven stamps only -1 ns lies neither ahead of the rover's clock nor an hour
        // behind it: the other six instants' four messages are dropped.
        assert_eq!(node.rejected_inputs(), 24);
        maps_the_room_again(&mut node, 38);
    }

    #[test]
    fn numbers_no_sensor_or_operator_gives_never_panic_the_rover() {
        // A driver's glitch on a real rover can send any number a message holds: a pose
        // 1e20 m out (a corrupt field still decodes), NaN, infinities, a scan claiming a
        // reach of 1e20 m. The rover goes on, and maps the room again once they stop.
        let mut node = settled_in_the_room();
        let at = tick;
        let id = node.id();
        for (k, bad) in [
            1e20,
            -1e20,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e300,
        ]
        .into_iter()
        .enumerate()
        {
            let t = at(31 + k as i64);
            let mut odom = Odometry::default();
            odom.header.stamp = t;
            odom.pose.pose.position.x = bad;
            odom.pose.pose.position.y = -bad;
            odom.pose.pose.orientation = Quaternion::IDENTITY;
            odom.twist.twist.linear.x = bad;
            node.on_message(t, &id.topic("odom"), &Message::Odometry(Box::new(odom)));
            let mut imu = Imu::default();
            imu.header.stamp = t;
            imu.angular_velocity.z = bad;
            imu.linear_acceleration.x = bad;
            imu.linear_acceleration.z = bad;
            node.on_message(t, &id.topic("imu"), &Message::Imu(Box::new(imu)));
            let mut wild = scan(t, true);
            wild.range_max_m = bad as f32;
            wild.range_min_m = -(bad as f32);
            wild.angle_increment_rad = bad as f32;
            for (i, r) in wild.ranges_m.iter_mut().enumerate() {
                if i % 3 == 0 {
                    *r = bad as f32;
                }
            }
            node.on_message(t, &id.topic("scan"), &Message::LaserScan(wild));
            node.drain_outbox();
        }
        // Odometry, IMU and scan of each of the six instants.
        assert_eq!(node.rejected_inputs(), 18);
        // An operator's goal nowhere a rover can drive is no reason to panic either.
        for (k, target) in [
            Point2::new(f64::NAN, 0.0),
            Point2::new(1e20, -1e20),
            Point2::new(f64::INFINITY, 1.0),
        ]
        .into_iter()
        .enumerate()
        {
            let t = at(37 + k as i64);
            node.on_message(
                t,
                &id.topic("nav/goal"),
                &Message::NavGoal(NavGoal {
                    header: Header {
                        stamp: t,
                        frame_id: "map".into(),
                    },
                    target: Some(target),
                }),
            );
            let refused = node.drain_outbox().iter().any(
                |o| matches!(&o.message, Message::NavStatus(s) if s.reason.contains("refused")),
            );
            assert_eq!(refused, !target.x_m.is_finite(), "{target:?}");
            step(&mut node, t, Some(true));
        }
        // The two goals with a coordinate that is no number are refused; the one 1e20 m
        // off is a place, which the planner finds no way to.
        assert_eq!(node.rejected_inputs(), 20);
        maps_the_room_again(&mut node, 40);
    }

    #[test]
    fn a_rover_lost_where_nothing_matches_its_map_turns_then_stops_and_says_so_and_takes_an_operators_goal()
     {
        let mut node = node();
        let at = |k: i64| Time::ZERO + Duration::from_millis(100 * k);
        let id = node.id();
        let send_goal = |node: &mut RoverNode, k: i64, target: Option<Point2>| {
            node.on_message(
                at(k),
                &id.topic("nav/goal"),
                &Message::NavGoal(NavGoal {
                    header: Header {
                        stamp: at(k),
                        frame_id: "map".into(),
                    },
                    target,
                }),
            );
        };
        // Ten seconds mapping the room, the last on the way to an operator's goal (the
        // test's wheels stand still), then twelve without the lidar: lost.
        for k in 1..=100 {
            if k == 90 {
                send_goal(&mut node, k, Some(Point2::new(1.0, 0.5)));
            }
            step(&mut node, at(k), Some(true));
        }
        assert_ne!(node.mapping().state(), LocalisationState::Lost);
        assert!(
            node.navigator
                .goal()
                .is_some_and(|(_, kind)| kind == GoalKind::Operator),
            "it drove the operator's goal when it got lost"
        );
        for k in 101..=220 {
            step(&mut node, at(k), None);
        }
        // The lidar is back, but sees open ground: nothing to relocalise against.
        let mut turned_until = None;
        let mut lost_status = None;
        let mut turning_statuses = Vec::new();
        for k in 221..=1000 {
            let (cmd, statuses) = step(&mut node, at(k), Some(false));
            let (v, w) = cmd.expect("a command per scan");
            assert_eq!(node.mapping().state(), LocalisationState::Lost);
            assert_eq!(
                v, 0.0,
                "scan {k}: the goal it had waits; lost, it does not drive"
            );
            if w != 0.0 {
                turned_until = Some(k);
                turning_statuses.extend(statuses.iter().cloned());
            }
            if lost_status.is_none() {
                lost_status = statuses
                    .into_iter()
                    .find(|s| s.activity == NavActivity::Lost)
                    .map(|s| (k, s));
            }
        }
        // It turned from the first scan after the gap for LOST_TURN (45 s); it mapped
        // nowhere else to drive back to, so it stopped then, and said why.
        let turned_until = turned_until.expect("it turned while lost");
        assert!(
            (670..=672).contains(&turned_until),
            "turned until scan {turned_until}"
        );
        let (said_at, lost) = lost_status.expect("it reported Lost");
        assert_eq!(said_at, turned_until + 1);
        assert!(lost.reason.contains("waiting for the operator"), "{lost:?}");
        assert_eq!(lost.target, None);
        // While it turned it said it was finding itself, and claimed nothing.
        assert!(
            !turning_statuses.is_empty(),
            "it said something while turning"
        );
        for s in &turning_statuses {
            assert_eq!(
                (s.activity, s.target),
                (NavActivity::Relocalising, None),
                "{s:?}"
            );
        }
        // Now the operator sends it 1.5 m ahead, into the room it mapped: it drives there
        // on its wheels and gyro, and says so once, not at every scan.
        send_goal(&mut node, 1001, Some(Point2::new(1.5, 0.0)));
        let mut drove = false;
        let mut statuses = Vec::new();
        for k in 1002..=1030 {
            let (cmd, said) = step(&mut node, at(k), Some(false));
            assert_eq!(node.mapping().state(), LocalisationState::Lost);
            drove |= cmd.is_some_and(|(v, _)| v > 0.0);
            statuses.extend(said);
        }
        assert!(drove, "it drove towards the operator's goal");
        let [driving] = &statuses[..] else {
            panic!("one status for the new goal: {statuses:?}");
        };
        assert_eq!(
            (driving.activity, driving.target),
            (NavActivity::OperatorGoal, Some(Point2::new(1.5, 0.0)))
        );
        assert!(!driving.reason.contains("waiting"), "{driving:?}");
        // The test's wheels do not move it: after 20 s it backs off, and says so (not
        // `Lost`, which peers and the mission take for finished).
        let mut statuses = Vec::new();
        for k in 1031..=1280 {
            statuses.extend(step(&mut node, at(k), Some(false)).1);
        }
        assert!(
            statuses
                .iter()
                .any(|s| s.activity == NavActivity::Recovering),
            "{statuses:?}"
        );
        assert!(
            statuses.iter().all(|s| s.activity != NavActivity::Lost),
            "{statuses:?}"
        );
        // The operator cancels it: it stops and waits again.
        send_goal(&mut node, 1281, None);
        let (cmd, said) = step(&mut node, at(1282), Some(false));
        assert_eq!(cmd.map(|(v, _)| v), Some(0.0));
        assert!(
            said.iter().any(|s| s.activity == NavActivity::Lost
                && s.target.is_none()
                && s.reason.contains("waiting for the operator")),
            "{said:?}"
        );
    }

    /// A yard 6 m x 4 m walled on three sides (west, north, south), open to the east, and a
    /// round rock far out in the open, seen by a lidar that reaches 4 m: from inside the yard
    /// it sees walls all round, beside the rock only the rock, whose arc fits the map at
    /// any heading.
    const YARD_WALLS: [(Point2, Point2); 3] = [
        (Point2::new(-3.0, -2.0), Point2::new(-3.0, 2.0)),
        (Point2::new(-3.0, 2.0), Point2::new(3.0, 2.0)),
        (Point2::new(-3.0, -2.0), Point2::new(3.0, -2.0)),
    ];
    const YARD_ROCK: (Point2, f64) = (Point2::new(9.0, 1.5), 0.25);
    const YARD_LIDAR_REACH_M: f64 = 4.0;

    /// Where a beam from `from` along `yaw_rad` meets a yard wall or the rock within the
    /// lidar's reach.
    fn yard_range(from: Point2, yaw_rad: f64) -> f32 {
        let (s, c) = yaw_rad.sin_cos();
        let mut nearest = f64::INFINITY;
        for (a, b) in YARD_WALLS {
            // from + t (c, s) = a + u (b - a), t > 0, u in [0, 1].
            let (ex, ey) = (b.x_m - a.x_m, b.y_m - a.y_m);
            let det = c * -ey + s * ex;
            if det.abs() < 1e-12 {
                continue;
            }
            let (dx, dy) = (a.x_m - from.x_m, a.y_m - from.y_m);
            let t = (dx * -ey + dy * ex) / det;
            let u = (c * dy - s * dx) / det;
            if t > 0.0 && (0.0..=1.0).contains(&u) {
                nearest = nearest.min(t);
            }
        }
        // |from + t (c, s) - centre| = radius, the nearer root.
        let (centre, radius) = YARD_ROCK;
        let (dx, dy) = (from.x_m - centre.x_m, from.y_m - centre.y_m);
        let b = dx * c + dy * s;
        let disc = b * b - (dx * dx + dy * dy - radius * radius);
        if disc >= 0.0 && -b - disc.sqrt() > 0.0 {
            nearest = nearest.min(-b - disc.sqrt());
        }
        if nearest <= YARD_LIDAR_REACH_M {
            nearest as f32
        } else {
            f32::INFINITY
        }
    }

    /// A rover in the yard, driven by its own commands (or the test's) with perfect wheels
    /// and gyro.
    struct Yard {
        node: RoverNode,
        truth: Pose2,
        cmd: (f64, f64),
        t: Time,
        statuses: Vec<NavStatus>,
    }

    impl Yard {
        fn new() -> Yard {
            let mut node = node();
            node.navigator = Navigator::new(
                node.id(),
                NavigationConfig {
                    autonomous: false,
                    ..NavigationConfig::new(Point2::new(0.0, 0.0))
                },
            );
            Yard {
                node,
                truth: Pose2::IDENTITY,
                cmd: (0.0, 0.0),
                t: Time::ZERO,
                statuses: Vec::new(),
            }
        }

        /// 0.1 s of driving on `joystick`, or else on the node's last command, then the
        /// sensors (the lidar if `lidar`).
        fn step(&mut self, lidar: bool, joystick: Option<(f64, f64)>) {
            let dt = 0.1;
            let (v, w) = joystick.unwrap_or(self.cmd);
            let mid = self.truth.yaw_rad + w * dt / 2.0;
            self.truth = Pose2::new(
                self.truth.x_m + v * dt * mid.cos(),
                self.truth.y_m + v * dt * mid.sin(),
                self.truth.yaw_rad + w * dt,
            );
            self.t += Duration::from_millis(100);
            let (t, id) = (self.t, self.node.id());
            let mut odom = Odometry::default();
            odom.header.stamp = t;
            odom.pose.pose.position.x = self.truth.x_m;
            odom.pose.pose.position.y = self.truth.y_m;
            odom.pose.pose.orientation =
                Quaternion::from_roll_pitch_yaw(0.0, 0.0, self.truth.yaw_rad);
            odom.twist.twist.linear.x = v;
            odom.twist.twist.angular.z = w;
            self.node
                .on_message(t, &id.topic("odom"), &Message::Odometry(Box::new(odom)));
            let mut imu = Imu::default();
            imu.header.stamp = t;
            imu.angular_velocity.z = w;
            imu.linear_acceleration.z = 9.81;
            self.node
                .on_message(t, &id.topic("imu"), &Message::Imu(Box::new(imu)));
            if lidar {
                let n = 360;
                let here = self.truth.position();
                let ranges = (0..n)
                    .map(|i| {
                        let a = -std::f64::consts::PI + i as f64 * std::f64::consts::TAU / n as f64;
                        yard_range(here, self.truth.yaw_rad + a)
                    })
                    .collect();
                let scan = crate::test_scan(t, ranges);
                self.node
                    .on_message(t, &id.topic("scan"), &Message::LaserScan(scan));
            } else {
                self.node.on_tick(t);
            }
            for o in self.node.drain_outbox() {
                match o.message {
                    Message::CmdVel(c) => self.cmd = (c.twist.linear.x, c.twist.angular.z),
                    Message::NavStatus(s) => self.statuses.push(s),
                    _ => {}
                }
            }
        }
    }

    #[test]
    fn a_rover_lost_beside_a_lone_rock_drives_back_to_where_it_saw_enough_and_finds_itself() {
        let mut yard = Yard::new();
        for _ in 0..100 {
            yard.step(true, None);
        }
        // Driven out of the yard to the rock, 9 m east, at 0.3 m/s.
        for _ in 0..300 {
            yard.step(true, Some((0.3, 0.0)));
        }
        assert_ne!(yard.node.mapping().state(), LocalisationState::Lost);
        // Twelve seconds without the lidar: lost, with only the rock in sight.
        for _ in 0..120 {
            yard.step(false, Some((0.0, 0.0)));
        }
        let lost_at = yard.truth;
        let mut found = None;
        for k in 0..3000 {
            yard.step(true, None);
            if k == 0 {
                assert_eq!(yard.node.mapping().state(), LocalisationState::Lost);
            }
            if yard.node.mapping().state() != LocalisationState::Lost {
                found = Some(k);
                break;
            }
        }
        let said = |a: NavActivity| yard.statuses.iter().any(|s| s.activity == a);
        let found = found.unwrap_or_else(|| {
            panic!(
                "it found its place again; at {:?}, it said {:?}",
                yard.truth,
                yard.statuses.last()
            )
        });
        assert!(said(NavActivity::Relocalising), "it said it drove back");
        assert!(!said(NavActivity::Lost), "it never gave up");
        // It turned on the spot first (45 s), then drove back towards the yard.
        assert!(found > 450, "found after {found} scans");
        assert!(
            yard.truth.x_m < lost_at.x_m - 2.0,
            "it drove back from {lost_at:?} to {:?}",
            yard.truth
        );
        let off = yard
            .node
            .mapping()
            .pose()
            .position()
            .distance_m(yard.truth.position());
        assert!(off < 0.2, "its pose is {off:.2} m off");
        yard.step(true, None);
        assert!(!yard.node.navigator.relocalising(), "the drive ended");
    }
}
