//! realms-mission: runs a simulated mission end to end.
//!
//! [`Mission`] owns the [`World`], one node per rover, the on-board bus and
//! the simulated network between nodes ([`realms_net::SimNetwork`]; ideal delivery with
//! [`MissionOptions::ideal_comms`]), and advances all of it on the world's clock. [`report`] turns a finished
//! mission into its results folder (`mission.json`, `truth.png`, `trajectories.png`,
//! `trajectories.csv`). No clock is read here: the caller measures wall time.

pub mod bus;
pub mod chart;
pub mod coverage;
pub mod netreport;
pub mod report;
pub mod slam_record;

use bus::Bus;
use coverage::Coverage;
use realms_core::msgs::{Message, NavActivity, NavStatus, NetworkStats, NodeTrafficStats};
use realms_core::{Duration, Point2, RoverId, Time, Topic};
use realms_net::{NodeAddr, Qos, SimNetwork, Transport};
use realms_node::guard::GuardConfig;
use realms_node::mapping::{Mapping, MappingConfig, rover_mapper_config};
use realms_node::navigation::NavigationConfig;
use realms_node::rover::{RoverConfig, RoverNode};
use realms_node::station::{StationNode, StationRole};
use realms_node::{Node, Outgoing};
use realms_sim::{Scenario, World};
use realms_slam::mapper::SubmapBend;
use realms_slam::traversability::{PinholeDepth, TraversabilityConfig};
use slam_record::RoverSlamRecord;

/// Lidar returns lower than this above the ground under the rover are floor hits, metres:
/// twice the default floor undulation, so the floor ahead rising does not count as a rock.
pub const GROUND_CLEARANCE_M: f64 = 0.12;

/// How far the pose graph may move a rover's keyframes within a submap before the hazard
/// layer drawn from them is drawn again, where the rovers do so
/// ([`MappingConfig::hazards_follow_keyframes`], not their default): a third of its 10 cm
/// cells, or half a degree (a cell's turn at 6 m).
pub const HAZARD_LAYER_BEND: SubmapBend = SubmapBend {
    translation_m: 0.03,
    rotation_rad: 0.5 * std::f64::consts::PI / 180.0,
};

/// Rovers stand still this long at the start to measure their gyro's bias. A minute, as on
/// real rovers: SLAM holds a match's heading to the gyro's, and the bias left after 5 s
/// (about 0.6 deg a minute) turned whole maps; after 60 s it is a quarter of that
/// (BENCHMARKS.md, on-board SLAM).
pub const GYRO_CALIBRATION: Duration = Duration::from_secs(60);

/// How often each rover publishes its map.
pub const MAP_PERIOD: Duration = Duration::from_secs(60);

/// How often each rover sends its map's changes to the lander and the ground: often enough
/// that the ground's copy lags by at most a few seconds plus the link's delay.
pub const MAP_DELTA_PERIOD: Duration = Duration::from_secs(2);

/// How often the lander reports the network's traffic to the ground.
pub const NETWORK_STATS_PERIOD: Duration = Duration::from_secs(10);

/// How often rover poses are sampled for trajectories.
pub const TRAJECTORY_PERIOD: Duration = Duration::from_secs(1);

pub use realms_node::cost::CostClock;

/// How a mission is run, beyond its scenario.
#[derive(Clone, Debug)]
pub struct MissionOptions {
    /// Rovers hear each other's navigation messages (targets, explored ground). Off, each
    /// explores as if alone: what allocation falls back to when the radio is silent.
    pub rovers_hear_each_other: bool,
    /// Messages between nodes arrive at once and intact, as on one computer; otherwise they
    /// cross the simulated mesh and ground link of the scenario's `[network]`.
    pub ideal_comms: bool,
    /// How long the rovers stand still at the start measuring their gyro's bias
    /// ([`GYRO_CALIBRATION`] by default; short tests may take less and get a worse gyro).
    pub gyro_calibration: Duration,
    /// Lent to the rovers to time their SLAM (`mission.json`'s `slam_wall_s`); without it
    /// that time reads zero.
    pub cost_clock: CostClock,
    /// Changes to every rover's SLAM setup, applied in turn, for benches that compare setups
    /// over whole missions (none: the setup as it is).
    pub mapping_changes: Vec<fn(&mut MappingConfig)>,
    /// Changes to every rover's navigation, likewise (none: as it is).
    pub navigation_changes: Vec<fn(&mut NavigationConfig)>,
}

impl Default for MissionOptions {
    fn default() -> Self {
        MissionOptions {
            rovers_hear_each_other: true,
            ideal_comms: false,
            gyro_calibration: GYRO_CALIBRATION,
            cost_clock: CostClock::default(),
            mapping_changes: Vec::new(),
            navigation_changes: Vec::new(),
        }
    }
}

/// The on-board SLAM setup of `world`'s rovers in a mission run with `options`.
pub fn rover_mapping_config(world: &World, options: &MissionOptions) -> MappingConfig {
    let spec = &world.scenario().rovers;
    let base_from_optical = world.base_from_optical();
    let mut cfg = MappingConfig {
        lidar_x_m: spec.lidar.mount_x_m,
        lidar_height_m: spec.lidar.mount_height_m,
        ground_clearance_m: GROUND_CLEARANCE_M,
        // About 0.1 s of smoothing at 50 Hz. The newest sample alone drops the floor a sudden
        // tilt shows the lidar, but left the replays' maps no better (BENCHMARKS.md, "The
        // lidar levelled by the newest accelerometer sample").
        tilt_smoothing: 0.2,
        // The accelerometer feels the body's starts, stops and turns: taken for tilt, the
        // hazard cells on untraversable ground fell from 51 to 31 % over six replayed missions,
        // and with the wheels' acceleration taken out they read 57 % (BENCHMARKS.md, "The
        // wheels' acceleration taken out of the tilt").
        tilt_less_wheels: Some(Duration::from_millis(200)),
        tilt_gyro: false,
        // Right after a wheel climbs a rock the smoothed tilt lags, and the floor the lidar
        // then meets metres ahead was kept as arcs of obstacles across open ground: dropped,
        // the maps over sixteen missions came out 95.5 % right instead of 93.7 % (BENCHMARKS.md,
        // "Floor hits of a tilt the levelling has not caught up with").
        tilt_gate: true,
        levelled_points: false,
        depth_at_own_stamp: false,
        // The hazard layer judges 10 cm cells; drawn on the map's 5 cm cells by their centres,
        // a crater's marked edge fell a cell short of its crest. Rounded out to the half cell,
        // the sixteen missions' maps mark 96.4 % of the crater cells near the paths instead of
        // 92.4 %, with the paths unchanged; the marked hazard is truly untraversable less
        // often (59.0 % against 69.8 % on seeds 1-6) (BENCHMARKS.md, "Hazards rounded out").
        hazards_rounded_out: true,
        // Drawn again where the final trajectory has their keyframes, the layers marked no
        // more of the crater cells near the paths over 48 missions and took some 40 MB more
        // (BENCHMARKS.md, "Hazard layers drawn again where the graph moves their
        // keyframes"): variant `hazards-follow-keyframes`.
        hazards_follow_keyframes: None,
        hazards_redrawn_while_mapping: false,
        // A beam that returns nothing crossed open ground: drawn as free space out to 6 m
        // (Cartographer's missing_data_ray_length), into the published map only (see
        // `rover_mapper_config`). The open middle of the hall is then known before a rover
        // drives there to judge it (BENCHMARKS.md, "Lidar beams that return nothing").
        clear_rays_m: Some(6.0),
        mapper: rover_mapper_config(),
        map_period: MAP_PERIOD,
        delta_period: MAP_DELTA_PERIOD,
        gyro_calibration: options.gyro_calibration,
        depth_rot: base_from_optical.rot,
        depth_origin_m: base_from_optical.origin,
        traversability: TraversabilityConfig {
            max_step_m: spec.max_step_m,
            max_slope_rad: spec.max_slope_deg.to_radians(),
            // Hidden ground counts as a bowl once it resumes a step lower than the floor.
            gap_drop_m: spec.max_step_m,
            // Beside the large crater the ground beyond its hidden near wall resumes 5-7 m
            // off: ended as far as the camera sees, hidden ground marks more of the crater
            // cells near the paths. Alone it cost the maps (longer routes round marked
            // craters through open floor where tracking drifted); with the pose held to the
            // wheels where the map is weak (`rover_mapper_config`), not (BENCHMARKS.md, "The
            // pose held to the wheels where the map is weak, as the rovers' default").
            gap_reach_m: spec.depth.range_max_m,
            // What the lidar saw open and the camera never judged, walled in by hazard, is a
            // crater's inside no viewpoint outside it shows (BENCHMARKS.md, "Hollows in the
            // hazard layer").
            hazard_hollows: Some(realms_slam::hollows::HazardHollows::default()),
            ..TraversabilityConfig::default()
        },
        depth_camera: Some(PinholeDepth::from_fov(
            spec.depth.width,
            spec.depth.height,
            spec.depth.hfov_deg,
            spec.depth.vfov_deg,
            spec.depth.range_min_m,
            spec.depth.range_max_m,
        )),
        silent_pixels: false,
        // The rovers' lidar is noisy at a centimetre or more; smoothed, the median rover's
        // trajectory error fell by a sixth (BENCHMARKS.md, "Ranges smoothed along the scan").
        smooth_ranges: true,
        // Ranges read from a parabola over five beams follow the boulders' round outlines,
        // where an average of three lies inside them: on the replays the maps' stretch
        // halved, but whole missions came out 3-4 points worse (BENCHMARKS.md, "The stretch
        // without the lidar's noise").
        smoothing: realms_node::mapping::ScanSmoothing::Ranges,
        deskew: true,
        depth_features: false,
        relief_odometry: None,
        // A rover parked for hours judged every frame at 2 Hz and redrew its hazard layers
        // for nothing; two minutes from one spot settle everything it sees (it stands one
        // minute at the start), and the sixteen missions came out the same to the rover
        // (BENCHMARKS.md, "A parked rover's sensors and maps").
        depth_motion_filter: Some(realms_node::mapping::DepthStillFilter {
            min_travel_m: 0.02,
            min_turn_rad: 0.5f64.to_radians(),
            frames_while_still: 240,
        }),
    };
    for change in &options.mapping_changes {
        change(&mut cfg);
    }
    cfg
}

/// A sensor message a rover's SLAM took in, kept with the rover's true pose when the
/// simulator published it, so SLAM can be run again on exactly the same input
/// ([`Mission::capture_slam_inputs`]).
#[derive(Clone, Debug)]
pub struct CapturedInput {
    /// When it was published.
    pub t: Time,
    /// The rover's true pose then, arena frame.
    pub truth: realms_core::Pose2,
    /// A scan, odometry, IMU reading or depth frame.
    pub message: Message,
}

/// Feeds a rover's captured input to `mapping` in order, as the rover node does, calling
/// `after_scan` with each scan's capture once SLAM has taken it.
pub fn replay_slam(
    mapping: &mut Mapping,
    input: &[CapturedInput],
    mut after_scan: impl FnMut(&CapturedInput, &Mapping),
) {
    let mut out = Vec::new();
    for c in input {
        match &c.message {
            Message::LaserScan(scan) => {
                mapping.on_scan(scan, &mut out);
                out.clear();
                after_scan(c, mapping);
            }
            Message::Odometry(odom) => mapping.on_odometry(odom),
            Message::Imu(imu) => mapping.on_imu(imu),
            Message::PointCloud(cloud) => mapping.on_depth(cloud),
            _ => {}
        }
    }
}

/// The topics whose messages feed a rover's SLAM.
const SLAM_INPUTS: [&str; 4] = ["scan", "odom", "imu", "depth/points"];

/// One sampled true pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseSample {
    /// When.
    pub t: Time,
    /// Where, arena frame.
    pub x_m: f64,
    /// Where, arena frame.
    pub y_m: f64,
    /// Heading.
    pub yaw_rad: f64,
}

/// A simulated mission in progress.
pub struct Mission {
    world: World,
    nodes: Vec<Box<dyn Node>>,
    /// Where each node sits on the network.
    addrs: Vec<NodeAddr>,
    /// The network between nodes; `None` with ideal communication.
    net: Option<SimNetwork>,
    bus: Bus,
    trajectories: Vec<Vec<PoseSample>>,
    next_sample: Time,
    published: Vec<(Topic, Message)>,
    slam: Vec<RoverSlamRecord>,
    coverage: Coverage,
    /// Each rover's latest navigation activity.
    activity: Vec<NavActivity>,
    /// Every navigation status each rover published, with its arrival time.
    nav_log: Vec<Vec<(Time, NavStatus)>>,
    /// Each rover's map updates to the ground.
    downlink: Vec<MapDownlink>,
    next_net_stats: Time,
    /// Each rover's SLAM input, once asked for ([`Mission::capture_slam_inputs`]).
    capture: Option<Vec<Vec<CapturedInput>>>,
}

/// A rover's map updates on their way to the ground, for the report.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapDownlink {
    /// Bytes of map updates the rover sent towards the ground (payload and headers).
    pub bytes: u64,
    /// Bytes a full occupancy grid once a second would have taken over the same time (the
    /// plain ROS 2 `nav_msgs/OccupancyGrid` topic).
    pub full_grid_bytes: u64,
    /// Each update's map time and when it reached the ground.
    pub arrivals: Vec<(Time, Time)>,
}

impl Mission {
    /// A mission of `scenario`, with the rover nodes of the current behaviour.
    pub fn new(scenario: &Scenario) -> Mission {
        Mission::with_world(World::new(scenario))
    }

    /// A mission on a prepared world (hand-built terrain in tests).
    pub fn with_world(world: World) -> Mission {
        Mission::with_options(world, MissionOptions::default())
    }

    /// A mission on a prepared world, run as `options` say.
    pub fn with_options(world: World, options: MissionOptions) -> Mission {
        let spec = &world.scenario().rovers;
        let base_from_optical = world.base_from_optical();
        let fleet: Vec<RoverId> = world.rovers().map(|b| b.id).collect();
        let nodes: Vec<Box<dyn Node>> = world
            .rovers()
            .map(|body| {
                let guard = GuardConfig {
                    half_length_m: spec.length_m / 2.0,
                    half_width_m: spec.width_m / 2.0,
                    lidar_x_m: spec.lidar.mount_x_m,
                    lidar_clearance_m: 0.25,
                    depth_reach_m: 0.6,
                    depth_rot: base_from_optical.rot,
                    depth_origin_m: base_from_optical.origin,
                    max_step_m: spec.max_step_m,
                    // The hazard layer's drop limit, so the guard does not stop the rover on
                    // ground the map calls drivable.
                    max_drop_m: TraversabilityConfig::default().max_drop_m,
                };
                let mapping = rover_mapping_config(&world, &options);
                let mut navigation = NavigationConfig::new(body.pose.position());
                navigation.follower.max_speed_m_s = 0.3_f64.min(spec.max_speed_m_s);
                navigation.follower.max_yaw_rate_rad_s = 0.8_f64.min(spec.max_yaw_rate_rad_s);
                for change in &options.navigation_changes {
                    change(&mut navigation);
                }
                let cfg = RoverConfig {
                    mapping,
                    navigation,
                    guard,
                    fleet: if options.rovers_hear_each_other {
                        fleet.clone()
                    } else {
                        vec![body.id]
                    },
                    cost_clock: options.cost_clock,
                };
                Box::new(RoverNode::new(body.id, cfg)) as Box<dyn Node>
            })
            .collect();
        let mut nodes = nodes;
        let mut addrs: Vec<NodeAddr> = world.rovers().map(|b| NodeAddr::rover(b.id)).collect();
        let n_rovers = nodes.len();
        for (role, addr) in [
            (StationRole::Lander, NodeAddr::Lander),
            (StationRole::Ground, NodeAddr::Ground),
        ] {
            nodes.push(Box::new(StationNode::new(role, fleet.clone())));
            addrs.push(addr);
        }
        let mut net = (!options.ideal_comms).then(|| {
            let scenario = world.scenario();
            let mut cfg = scenario.network.clone();
            cfg.seed = scenario.seed ^ 0x006e_6574_776f_726b;
            let lander = Point2::new(scenario.lander.x_m, scenario.lander.y_m);
            let mut net = SimNetwork::new(cfg, lander);
            for b in world.rovers() {
                let addr = NodeAddr::rover(b.id);
                net.add_mesh_node(addr, b.pose.position());
                // The rover's drive listens for velocities from other computers.
                net.subscribe(addr, b.id.topic("cmd_vel"));
            }
            net
        });
        let mut bus = Bus::default();
        for (i, node) in nodes.iter().enumerate() {
            for topic in node.subscriptions() {
                if let Some(net) = &mut net {
                    net.subscribe(addrs[i], topic.clone());
                }
                bus.subscribe(topic, i);
            }
        }
        let trajectories = vec![Vec::new(); n_rovers];
        let coverage = Coverage::new(world.truth());
        let mut mission = Mission {
            world,
            nodes,
            addrs,
            net,
            bus,
            trajectories,
            next_sample: Time::ZERO,
            published: Vec::new(),
            slam: vec![RoverSlamRecord::default(); n_rovers],
            coverage,
            activity: vec![NavActivity::Idle; n_rovers],
            downlink: vec![MapDownlink::default(); n_rovers],
            next_net_stats: Time::ZERO,
            nav_log: vec![Vec::new(); n_rovers],
            capture: None,
        };
        mission.update_camera_wants();
        mission
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, to change what it keeps for a benchmark ([`World::keep_lidar_twins`]).
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// Sampled true trajectories, one per rover.
    pub fn trajectories(&self) -> &[Vec<PoseSample>] {
        &self.trajectories
    }

    /// The bus (for its statistics).
    pub fn bus(&self) -> &Bus {
        &self.bus
    }

    /// Mission time reached.
    pub fn now(&self) -> Time {
        self.world.now()
    }

    /// Runs every world event and node wakeup up to and including `end`.
    pub fn run_until(&mut self, end: Time) {
        loop {
            let t_world = self.world.next_due();
            let t_nodes = self.nodes.iter().filter_map(|n| n.next_wakeup()).min();
            let t = match (t_world, t_nodes) {
                (Some(a), Some(b)) => a.min(b),
                (a, b) => match a.or(b) {
                    Some(t) => t,
                    None => break,
                },
            };
            if t > end {
                break;
            }
            self.sample_trajectories(t);
            self.world.advance_to(t, &mut self.published);
            let mut pending = self.take_world_messages();
            for i in 0..self.nodes.len() {
                if self.nodes[i].next_wakeup().is_some_and(|w| w <= t) {
                    self.nodes[i].on_tick(t);
                    let from = self.addrs[i];
                    pending.extend(
                        self.nodes[i]
                            .drain_outbox()
                            .into_iter()
                            .map(|o| (from, o.topic, o.message)),
                    );
                }
            }
            self.deliver(t, pending);
            self.run_network(t);
        }
        self.world.advance_to(end, &mut self.published);
        let rest = self.take_world_messages();
        self.deliver(end, rest);
        self.run_network(end);
    }

    /// Keeps every sensor message the rovers' SLAM takes in from now on, with the true pose
    /// at the time (see [`Mission::take_capture`]). Depth frames make this about 0.5 MB per
    /// simulated second for three rovers.
    pub fn capture_slam_inputs(&mut self) {
        self.capture
            .get_or_insert_with(|| vec![Vec::new(); self.slam.len()]);
    }

    /// Each rover's captured SLAM input so far, in the order it was delivered (empty lists
    /// without [`Mission::capture_slam_inputs`]).
    pub fn take_capture(&mut self) -> Vec<Vec<CapturedInput>> {
        match &mut self.capture {
            // Each rover's list is emptied, not the list of rovers: capturing goes on.
            Some(capture) => capture.iter_mut().map(std::mem::take).collect(),
            None => vec![Vec::new(); self.slam.len()],
        }
    }

    /// What the world published, each message from the rover whose sensor made it.
    fn take_world_messages(&mut self) -> Vec<(NodeAddr, Topic, Message)> {
        if let Some(capture) = &mut self.capture {
            for (topic, message) in &self.published {
                let Some(rover) = topic.rover() else { continue };
                if !SLAM_INPUTS.contains(&topic.leaf()) {
                    continue;
                }
                if let Some((i, body)) =
                    self.world.rovers().enumerate().find(|(_, b)| b.id == rover)
                {
                    capture[i].push(CapturedInput {
                        t: self.world.now(),
                        truth: body.pose,
                        message: message.clone(),
                    });
                }
            }
        }
        std::mem::take(&mut self.published)
            .into_iter()
            .map(|(topic, message)| {
                let from = topic.rover().map_or(NodeAddr::Lander, NodeAddr::rover);
                (from, topic, message)
            })
            .collect()
    }

    /// The lander's report of the network's traffic, for the ground's network monitor.
    fn network_stats(&self, t: Time) -> Option<Message> {
        let net = self.net.as_ref()?;
        let stats = net.stats();
        let nodes = self
            .addrs
            .iter()
            .map(|a| {
                let n = stats.nodes.get(a);
                NodeTrafficStats {
                    node: a.to_string(),
                    sent_bytes: n.map_or(0, |n| n.originated.bytes),
                    received_bytes: n.map_or(0, |n| n.delivered.bytes),
                    relayed_bytes: n.map_or(0, |n| n.forwarded.bytes),
                    queued_bytes: net.queued_bytes(*a) as u64,
                }
            })
            .collect();
        Some(Message::NetworkStats(Box::new(NetworkStats {
            header: realms_core::msgs::Header {
                stamp: t,
                frame_id: "lander".into(),
            },
            nodes,
            dropped: stats.dropped.values().sum(),
            malformed: stats.malformed,
            route_changes: stats.route_changes,
        })))
    }

    /// Sends raw bytes from `from` to `to` on `topic` over the simulated network, as if a
    /// node had (what a corrupted or hostile packet looks like to the receiver); `false`
    /// with ideal communication.
    pub fn inject(
        &mut self,
        from: NodeAddr,
        to: NodeAddr,
        topic: &Topic,
        payload: Vec<u8>,
    ) -> bool {
        let Some(net) = &mut self.net else {
            return false;
        };
        let now = self.world.now();
        Transport::send(net, now, from, to, topic, payload, Qos::for_topic(topic));
        true
    }

    /// Moves the network to `t` (radios where their rovers are, dead rovers silent) and
    /// hands what it delivered to the nodes.
    fn run_network(&mut self, t: Time) {
        if self.net.is_some() && t >= self.next_net_stats {
            self.next_net_stats = t + NETWORK_STATS_PERIOD;
            if let Some(stats) = self.network_stats(t) {
                let topic = Topic::new(realms_node::station::NETWORK_STATS_TOPIC);
                self.deliver(t, vec![(NodeAddr::Lander, topic, stats)]);
            }
        }
        let Some(net) = &mut self.net else { return };
        for body in self.world.rovers() {
            let addr = NodeAddr::rover(body.id);
            net.set_position(addr, body.pose.position());
            net.set_up(addr, body.powered);
        }
        let deliveries = net.poll(t);
        if deliveries.is_empty() {
            return;
        }
        let mut pending = Vec::new();
        for d in deliveries {
            let message = match realms_core::codec::decode(&d.payload) {
                Ok(m) => m,
                Err(_) => {
                    // A node drops what it cannot read, and the network counts it.
                    if let Some(net) = &mut self.net {
                        net.count_malformed();
                    }
                    continue;
                }
            };
            if let (Some(rover), Message::CmdVel(cmd)) = (d.topic.rover(), &message)
                && d.topic.leaf() == "cmd_vel"
                && d.to == NodeAddr::rover(rover)
            {
                self.world.command(rover, cmd.clone());
            }
            if d.to == NodeAddr::Ground
                && let Message::MapDelta(delta) = &message
                && let Some(k) = self.rover_index(&d.topic)
            {
                self.downlink[k].arrivals.push((delta.header.stamp, d.at));
            }
            for i in self.bus.subscribers(&d.topic).to_vec() {
                if self.addrs[i] != d.to {
                    continue;
                }
                let node = &mut self.nodes[i];
                node.on_message(t, &d.topic, &message);
                let from = self.addrs[i];
                pending.extend(
                    node.drain_outbox()
                        .into_iter()
                        .map(|o| (from, o.topic, o.message)),
                );
            }
        }
        self.deliver(t, pending);
    }

    /// The index of the rover whose topic this is.
    fn rover_index(&self, topic: &Topic) -> Option<usize> {
        let rover = topic.rover()?;
        self.world.rovers().position(|b| b.id == rover)
    }

    /// Whether the ground holds, for every powered rover, a map update made at or after `t`
    /// (always, with ideal communication).
    pub fn ground_current_since(&self, t: Time) -> bool {
        self.net.is_none()
            || self
                .world
                .rovers()
                .zip(&self.downlink)
                .filter(|(b, _)| b.powered)
                .all(|(_, d)| d.arrivals.last().is_some_and(|(stamp, _)| *stamp >= t))
    }

    /// The lander's or the ground station's node.
    pub fn station(&self, at: NodeAddr) -> Option<&StationNode> {
        self.nodes
            .iter()
            .zip(&self.addrs)
            .find(|(_, a)| **a == at)
            .and_then(|(n, _)| n.as_station())
    }

    /// Each rover's map updates to the ground.
    pub fn downlink(&self) -> &[MapDownlink] {
        &self.downlink
    }

    /// The network's counters, unless communication is ideal.
    pub fn network(&self) -> Option<&SimNetwork> {
        self.net.as_ref()
    }

    /// Publishes `message` on `topic` at the current time, as an operator would.
    pub fn publish(&mut self, topic: Topic, message: Message) {
        let t = self.now();
        self.deliver(t, vec![(NodeAddr::Ground, topic, message)]);
    }

    /// Every navigation status each rover published, in rover order, with arrival times.
    pub fn nav_log(&self) -> &[Vec<(Time, NavStatus)>] {
        &self.nav_log
    }

    /// How much of the explorable area the rovers' maps cover, over time.
    pub fn coverage(&self) -> &Coverage {
        &self.coverage
    }

    /// Whether every rover has finished exploring (and is home, or gave up getting there
    /// and stays put), is lost past finding itself, or has no power: the mission has nothing
    /// left to do without the operator.
    pub fn exploration_over(&self) -> bool {
        self.world
            .rovers()
            .zip(&self.activity)
            .all(|(body, a)| matches!(a, NavActivity::Done | NavActivity::Lost) || !body.powered)
    }

    /// Whether every powered rover that finished exploring has drawn its map from its final
    /// trajectory (which it does once it has heard its peers finish too): from then on the
    /// map updates carry the final maps to the lander and the ground.
    pub fn maps_final(&self) -> bool {
        self.world
            .rovers()
            .zip(&self.activity)
            .filter(|(body, a)| body.powered && **a == NavActivity::Done)
            .all(|(body, _)| {
                self.nodes
                    .iter()
                    .filter_map(|n| n.as_rover())
                    .find(|r| r.id() == body.id)
                    .is_none_or(|r| r.map_finished())
            })
    }

    /// What each rover's SLAM reported, in rover order.
    pub fn slam_records(&self) -> &[RoverSlamRecord] {
        &self.slam
    }

    /// Wall time every rover's SLAM took, summed, seconds (known once the mission finished;
    /// 0 without a [`CostClock`]).
    pub fn slam_wall_s(&self) -> f64 {
        self.slam.iter().map(|r| r.wall_s).sum()
    }

    /// Ends the mission at the time reached: nodes publish their final products.
    pub fn finish(&mut self) {
        let t = self.now();
        let mut pending = Vec::new();
        for (node, from) in self.nodes.iter_mut().zip(&self.addrs) {
            node.on_shutdown(t);
            if let Some(rover) = node.as_rover() {
                let trajectory: Vec<(f64, realms_core::Pose2)> = rover
                    .mapping()
                    .trajectory()
                    .iter()
                    .map(|s| (s.timestamp_s, s.pose))
                    .collect();
                if let Some(k) = self.world.rovers().position(|b| b.id == rover.id()) {
                    self.slam[k].attach_trajectory(&trajectory);
                    self.slam[k].wall_s = rover.slam_wall_s();
                }
            }
            pending.extend(
                node.drain_outbox()
                    .into_iter()
                    .map(|o| (*from, o.topic, o.message)),
            );
        }
        self.deliver(t, pending);
    }

    /// Keeps what the rovers' SLAM says, with the truth at that moment.
    fn record_slam(&mut self, t: Time, topic: &Topic, message: &Message) {
        let Some(rover) = topic.rover() else { return };
        let Some(i) = self.world.rovers().position(|b| b.id == rover) else {
            return;
        };
        let record = &mut self.slam[i];
        match message {
            Message::Pose(p) => {
                let body = self
                    .world
                    .rovers()
                    .nth(i)
                    .expect("the index came from the same list");
                let q = &p.pose.pose;
                let estimate =
                    realms_core::Pose2::new(q.position.x, q.position.y, q.orientation.yaw_rad());
                let c = &p.pose.covariance;
                let sigma = (c[0][0].max(c[1][1]).sqrt(), c[5][5].sqrt());
                record.pose(t, estimate, Some(sigma), body.odom_pose, body.pose);
            }
            Message::Localisation(change) => {
                record.changes.push(slam_record::StateChange {
                    t_s: change.header.stamp.as_secs_f64(),
                    state: change.state,
                    reason: change.reason.clone(),
                });
            }
            Message::Map(map) => {
                let same = record
                    .map
                    .as_ref()
                    .is_some_and(|last| last.info == map.info && last.data == map.data);
                if same {
                    self.coverage.same_map(t.as_secs_f64());
                } else {
                    self.coverage.map(t.as_secs_f64(), i, map);
                }
                record.map = Some(map.clone());
            }
            Message::NavStatus(status) => {
                self.activity[i] = status.activity;
                self.nav_log[i].push((t, status.clone()));
            }
            _ => {}
        }
    }

    /// Delivers messages (and whatever they cause) at time `t`, in order: to nodes on the
    /// publisher's own computer at once, to the others through the network.
    fn deliver(&mut self, t: Time, mut pending: Vec<(NodeAddr, Topic, Message)>) {
        // Nodes answer messages with messages; bounded so a chatty loop cannot hang a run.
        for _round in 0..16 {
            if pending.is_empty() {
                return;
            }
            let mut next = Vec::new();
            for (origin, topic, message) in pending {
                self.bus.count(&topic);
                if matches!(topic.leaf(), "pose" | "localisation" | "map" | "nav/status") {
                    self.record_slam(t, &topic, &message);
                }
                let mut remote = false;
                if let (Some(rover), Message::CmdVel(cmd)) = (topic.rover(), &message)
                    && topic.leaf() == "cmd_vel"
                {
                    // The drive is on the rover's own computer: a velocity from anywhere else
                    // (the operator's teleoperation) crosses the network to reach it.
                    if self.net.is_none() || origin == NodeAddr::rover(rover) {
                        self.world.command(rover, cmd.clone());
                    } else {
                        remote = true;
                    }
                }
                for i in self.bus.subscribers(&topic).to_vec() {
                    if self.net.is_some() && self.addrs[i] != origin {
                        remote = true;
                        continue;
                    }
                    let node = &mut self.nodes[i];
                    node.on_message(t, &topic, &message);
                    let from = self.addrs[i];
                    next.extend(
                        node.drain_outbox()
                            .into_iter()
                            .map(|Outgoing { topic, message }| (from, topic, message)),
                    );
                }
                // Only map updates are counted for the report; other traffic skips the lookup.
                let rover = matches!(message, Message::MapDelta(_))
                    .then(|| self.rover_index(&topic))
                    .flatten();
                if remote && let Some(net) = &mut self.net {
                    let qos = Qos::for_topic(&topic);
                    let payload = realms_core::codec::encode(&message);
                    if let Message::MapDelta(delta) = &message
                        && let Some(k) = rover
                    {
                        let u = &delta.update;
                        let d = &mut self.downlink[k];
                        d.bytes += (payload.len() + realms_net::packet::HEADER_BYTES) as u64;
                        // One grid a second over the update period, with the message's own
                        // header (about 60 bytes) and each packet's.
                        let grid = u.width as u64 * u.height as u64 + 60;
                        d.full_grid_bytes += (grid + realms_net::packet::HEADER_BYTES as u64)
                            * MAP_DELTA_PERIOD.as_secs_f64().round() as u64;
                    }
                    Transport::publish(net, t, origin, &topic, payload, qos);
                }
            }
            pending = next;
        }
    }

    fn update_camera_wants(&mut self) {
        let ids: Vec<RoverId> = self.world.rovers().map(|b| b.id).collect();
        for id in ids {
            let wanted = !self.bus.subscribers(&id.topic("camera/image")).is_empty();
            self.world.set_camera_wanted(id, wanted);
        }
    }

    fn sample_trajectories(&mut self, t: Time) {
        while self.next_sample <= t {
            for (traj, body) in self.trajectories.iter_mut().zip(self.world.rovers()) {
                traj.push(PoseSample {
                    t: self.next_sample,
                    x_m: body.pose.x_m,
                    y_m: body.pose.y_m,
                    yaw_rad: body.pose.yaw_rad,
                });
            }
            self.next_sample += TRAJECTORY_PERIOD;
        }
    }

    /// The trajectory of each rover as points, for drawing.
    pub fn trajectory_points(&self) -> Vec<Vec<Point2>> {
        self.trajectories
            .iter()
            .map(|t| t.iter().map(|s| Point2::new(s.x_m, s.y_m)).collect())
            .collect()
    }
}
