//! realms-mission: runs a simulated mission end to end.
//!
//! [`Mission`] owns the [`World`](realms_sim::World), one node per rover and the message bus
//! between them, and advances all of it on the world's clock. [`report`] turns a finished
//! mission into its results folder (`mission.json`, `truth.png`, `trajectories.png`,
//! `trajectories.csv`). No clock is read here: the caller measures wall time.

pub mod bus;
pub mod chart;
pub mod coverage;
pub mod report;
pub mod slam_record;

use bus::Bus;
use coverage::Coverage;
use realms_core::msgs::{Message, NavActivity, NavStatus};
use realms_core::{Duration, Point2, RoverId, Time, Topic};
use realms_node::guard::GuardConfig;
use realms_node::mapping::{MappingConfig, rover_mapper_config};
use realms_node::navigation::NavigationConfig;
use realms_node::rover::{RoverConfig, RoverNode};
use realms_node::{Node, Outgoing};
use realms_sim::{Scenario, World};
use realms_slam::traversability::TraversabilityConfig;
use slam_record::RoverSlamRecord;

/// Lidar returns lower than this above the ground under the rover are floor hits, metres:
/// twice the default floor undulation, so the floor ahead rising does not count as a rock.
pub const GROUND_CLEARANCE_M: f64 = 0.12;

/// Rovers stand still this long at the start to measure their gyro's bias.
pub const GYRO_CALIBRATION: Duration = Duration::from_secs(5);

/// How often each rover publishes its map.
pub const MAP_PERIOD: Duration = Duration::from_secs(60);

/// How often rover poses are sampled for trajectories.
pub const TRAJECTORY_PERIOD: Duration = Duration::from_secs(1);

/// How a mission is run, beyond its scenario.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MissionOptions {
    /// Rovers hear each other's navigation messages (targets, explored ground). Off, each
    /// explores as if alone: what allocation falls back to when the radio is silent.
    pub rovers_hear_each_other: bool,
}

impl Default for MissionOptions {
    fn default() -> Self {
        MissionOptions {
            rovers_hear_each_other: true,
        }
    }
}

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
                let mapping = MappingConfig {
                    lidar_x_m: spec.lidar.mount_x_m,
                    lidar_height_m: spec.lidar.mount_height_m,
                    ground_clearance_m: GROUND_CLEARANCE_M,
                    mapper: rover_mapper_config(),
                    map_period: MAP_PERIOD,
                    gyro_calibration: GYRO_CALIBRATION,
                    depth_rot: base_from_optical.rot,
                    depth_origin_m: base_from_optical.origin,
                    traversability: TraversabilityConfig {
                        max_step_m: spec.max_step_m,
                        max_slope_rad: spec.max_slope_deg.to_radians(),
                        ..TraversabilityConfig::default()
                    },
                };
                let mut navigation = NavigationConfig::new(body.pose.position());
                navigation.follower.max_speed_m_s = 0.3_f64.min(spec.max_speed_m_s);
                navigation.follower.max_yaw_rate_rad_s = 0.8_f64.min(spec.max_yaw_rate_rad_s);
                let cfg = RoverConfig {
                    mapping,
                    navigation,
                    guard,
                    fleet: if options.rovers_hear_each_other {
                        fleet.clone()
                    } else {
                        vec![body.id]
                    },
                };
                Box::new(RoverNode::new(body.id, cfg)) as Box<dyn Node>
            })
            .collect();
        let mut bus = Bus::default();
        for (i, node) in nodes.iter().enumerate() {
            for topic in node.subscriptions() {
                bus.subscribe(topic, i);
            }
        }
        let trajectories = vec![Vec::new(); nodes.len()];
        let coverage = Coverage::new(world.truth());
        let n_rovers = nodes.len();
        let mut mission = Mission {
            world,
            nodes,
            bus,
            trajectories,
            next_sample: Time::ZERO,
            published: Vec::new(),
            slam: vec![RoverSlamRecord::default(); n_rovers],
            coverage,
            activity: vec![NavActivity::Idle; n_rovers],
            nav_log: vec![Vec::new(); n_rovers],
        };
        mission.update_camera_wants();
        mission
    }

    /// The world.
    pub fn world(&self) -> &World {
        &self.world
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
            let mut pending: Vec<(Topic, Message)> = std::mem::take(&mut self.published);
            for i in 0..self.nodes.len() {
                if self.nodes[i].next_wakeup().is_some_and(|w| w <= t) {
                    self.nodes[i].on_tick(t);
                    pending.extend(
                        self.nodes[i]
                            .drain_outbox()
                            .into_iter()
                            .map(|o| (o.topic, o.message)),
                    );
                }
            }
            self.deliver(t, pending);
        }
        let mut rest = Vec::new();
        self.world.advance_to(end, &mut rest);
        self.deliver(end, rest);
    }

    /// Publishes `message` on `topic` at the current time, as an operator would.
    pub fn publish(&mut self, topic: Topic, message: Message) {
        let t = self.now();
        self.deliver(t, vec![(topic, message)]);
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
    /// and stays put) or has no power: the mission has nothing left to do.
    pub fn exploration_over(&self) -> bool {
        self.world
            .rovers()
            .zip(&self.activity)
            .all(|(body, a)| *a == NavActivity::Done || !body.powered)
    }

    /// What each rover's SLAM reported, in rover order.
    pub fn slam_records(&self) -> &[RoverSlamRecord] {
        &self.slam
    }

    /// Ends the mission at the time reached: nodes publish their final products.
    pub fn finish(&mut self) {
        let t = self.now();
        let mut pending = Vec::new();
        for node in &mut self.nodes {
            node.on_shutdown(t);
            pending.extend(
                node.drain_outbox()
                    .into_iter()
                    .map(|o| (o.topic, o.message)),
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
                record.pose(t, estimate, body.odom_pose, body.pose);
            }
            Message::Localisation(change) => {
                record.changes.push(slam_record::StateChange {
                    t_s: change.header.stamp.as_secs_f64(),
                    state: change.state,
                    reason: change.reason.clone(),
                });
            }
            Message::Map(map) => {
                self.coverage.map(t.as_secs_f64(), i, map);
                record.map = Some(map.clone());
            }
            Message::NavStatus(status) => {
                self.activity[i] = status.activity;
                self.nav_log[i].push((t, status.clone()));
            }
            _ => {}
        }
    }

    /// Delivers messages (and whatever they cause) at time `t`, in order.
    fn deliver(&mut self, t: Time, mut pending: Vec<(Topic, Message)>) {
        // Nodes answer messages with messages; bounded so a chatty loop cannot hang a run.
        for _round in 0..16 {
            if pending.is_empty() {
                return;
            }
            let mut next = Vec::new();
            for (topic, message) in pending {
                self.bus.count(&topic);
                if matches!(topic.leaf(), "pose" | "localisation" | "map" | "nav/status") {
                    self.record_slam(t, &topic, &message);
                }
                if let (Some(rover), Message::CmdVel(cmd)) = (topic.rover(), &message)
                    && topic.leaf() == "cmd_vel"
                {
                    self.world.command(rover, cmd.clone());
                }
                for i in self.bus.subscribers(&topic).to_vec() {
                    let node = &mut self.nodes[i];
                    node.on_message(t, &topic, &message);
                    next.extend(
                        node.drain_outbox()
                            .into_iter()
                            .map(|Outgoing { topic, message }| (topic, message)),
                    );
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
