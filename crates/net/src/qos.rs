//! Quality of service per topic: whether a message must arrive (reliable) or may be lost
//! (best effort), how urgent it is against other traffic waiting for the same radio, and how
//! long it stays worth delivering. Nodes state it per topic; the network honours it.

use realms_core::{Duration, Topic};
use serde::{Deserialize, Serialize};

/// Urgency, highest first. Queues drain in this order (issue 5: commands, then safety and
/// localisation status, then poses, then map updates, then images).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Priority {
    /// Operator commands: goals, velocity, reset, stop.
    Command = 0,
    /// Safety and localisation status, navigation status.
    Safety = 1,
    /// Poses.
    Pose = 2,
    /// Map updates: never dropped, superseded instead.
    Map = 3,
    /// Camera images and other bulk data.
    Image = 4,
}

impl Priority {
    /// Every level, highest first.
    pub const ALL: [Priority; 5] = [
        Priority::Command,
        Priority::Safety,
        Priority::Pose,
        Priority::Map,
        Priority::Image,
    ];

    /// Position in [`Priority::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// Whether a message must arrive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Reliability {
    /// Retransmitted until it arrives (or its time to live runs out); delivered in order per
    /// topic and sender.
    Reliable,
    /// Sent once per hop (with the radio's own retries); may be lost; never delivered older
    /// than one already delivered on the same topic from the same sender.
    BestEffort,
}

/// The service a topic asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Qos {
    /// Must it arrive.
    pub reliability: Reliability,
    /// Its urgency.
    pub priority: Priority,
    /// After this long a message is dropped rather than delivered late; `None`: never.
    pub ttl: Option<Duration>,
}

impl Qos {
    /// The service for a topic by its last name segment, as the nodes of realms use them.
    /// Map data is reliable and lives for ever (it is superseded, not dropped); poses are
    /// worth little after a few seconds; commands must arrive but not minutes late.
    pub fn for_topic(topic: &Topic) -> Qos {
        let secs = |s: i64| Some(Duration::from_secs(s));
        let (reliability, priority, ttl) =
            match topic.as_str().rsplit('/').next().unwrap_or_default() {
                // Three seconds: the ground link alone takes one, and teleoperation from the ground
                // must still work; older velocities are worse than none.
                "cmd_vel" => (Reliability::BestEffort, Priority::Command, secs(3)),
                "goal" | "command" | "cancel" => {
                    (Reliability::Reliable, Priority::Command, secs(600))
                }
                "localisation" | "status" | "events" | "stats" => {
                    (Reliability::Reliable, Priority::Safety, None)
                }
                "pose" | "odom" => (Reliability::BestEffort, Priority::Pose, secs(5)),
                "map" | "delta" | "snapshot" | "explored" | "hazards" | "transforms" => {
                    (Reliability::Reliable, Priority::Map, None)
                }
                _ => (Reliability::BestEffort, Priority::Image, secs(30)),
            };
        Qos {
            reliability,
            priority,
            ttl,
        }
    }

    /// Whether messages on this topic replace older queued ones instead of being dropped.
    pub fn supersedes(&self) -> bool {
        self.priority == Priority::Map
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_get_the_service_the_issue_names() {
        let q = |s: &str| Qos::for_topic(&Topic::new(s));
        assert_eq!(q("rover1/nav/goal").priority, Priority::Command);
        assert_eq!(q("rover1/localisation").priority, Priority::Safety);
        assert_eq!(q("rover1/pose").priority, Priority::Pose);
        assert_eq!(q("rover1/map/delta").priority, Priority::Map);
        assert!(q("rover1/map/delta").supersedes());
        assert_eq!(q("rover1/map/delta").reliability, Reliability::Reliable);
        assert_eq!(q("rover1/camera/image").priority, Priority::Image);
        assert!(Priority::Command < Priority::Image);
    }
}
