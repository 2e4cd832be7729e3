//! The rover node: a rover's on-board logic. It runs SLAM on its own scans and odometry
//! ([`Mapping`](crate::mapping::Mapping)), publishing its pose, its localisation state and its
//! map. For now it drives with the placeholder [`Wander`](crate::wander::Wander) behaviour;
//! navigation and exploration take its place as their issues land. It stops the rover if
//! its lidar falls silent.

use crate::mapping::{Mapping, MappingConfig};
use crate::wander::{Wander, WanderConfig};
use crate::{Node, Outgoing};
use realms_core::geometry::Vec3;
use realms_core::msgs::{Message, Twist, TwistStamped};
use realms_core::{Duration, RoverId, Time, Topic};

/// How long without a scan before the node commands a stop.
const SCAN_SILENCE: Duration = Duration::from_millis(500);

/// A rover's on-board node.
#[derive(Debug)]
pub struct RoverNode {
    id: RoverId,
    name: String,
    wander: Wander,
    mapping: Mapping,
    last_scan: Option<Time>,
    stopped_for_silence: bool,
    outbox: Vec<Outgoing>,
}

impl RoverNode {
    /// The node of rover `id`.
    pub fn new(id: RoverId, wander: WanderConfig, mapping: MappingConfig) -> Self {
        RoverNode {
            id,
            name: id.namespace(),
            wander: Wander::new(wander),
            mapping: Mapping::new(id, mapping),
            last_scan: None,
            stopped_for_silence: false,
            outbox: Vec::new(),
        }
    }

    fn send_cmd(&mut self, now: Time, v_m_s: f64, w_rad_s: f64) {
        self.outbox.push(Outgoing {
            topic: self.id.topic("cmd_vel"),
            message: Message::CmdVel(TwistStamped {
                header: realms_core::msgs::Header {
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
}

impl Node for RoverNode {
    fn name(&self) -> &str {
        &self.name
    }

    fn subscriptions(&self) -> Vec<Topic> {
        ["scan", "depth/points", "odom", "imu"]
            .iter()
            .map(|leaf| self.id.topic(leaf))
            .collect()
    }

    fn on_message(&mut self, now: Time, topic: &Topic, message: &Message) {
        if topic.rover() != Some(self.id) {
            return;
        }
        match message {
            Message::LaserScan(scan) => {
                self.last_scan = Some(now);
                self.stopped_for_silence = false;
                self.mapping.on_scan(scan, &mut self.outbox);
                let (v, w) = if self.mapping.calibrating(now) {
                    (0.0, 0.0)
                } else {
                    self.wander.on_scan(now, scan)
                };
                self.send_cmd(now, v, w);
            }
            Message::Odometry(odom) => self.mapping.on_odometry(odom),
            Message::Imu(imu) => self.mapping.on_imu(imu),
            Message::PointCloud(cloud) => {
                self.mapping.on_depth(cloud);
                self.wander.on_depth(now, cloud);
            }
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
        self.mapping.publish_map(now, &mut self.outbox);
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
