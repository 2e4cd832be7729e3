//! What travels: addresses of the nodes on the network and the packets between them.

use crate::qos::Qos;
use realms_core::{RoverId, Time, Topic};
use serde::{Deserialize, Serialize};
use std::fmt;

/// A packet that has taken this many mesh hops is in a loop (the mesh is far smaller), and
/// is dropped.
pub const MAX_HOPS: u8 = 16;

/// Bytes each packet costs beyond its payload: 802.11 MAC and mesh headers (about 40), IP
/// and UDP (28) and our own header (topic id, sequence, stamp: about 12).
pub const HEADER_BYTES: usize = 80;

/// A node on the network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum NodeAddr {
    /// A rover (1-based, as its id).
    Rover(u8),
    /// The lander: mesh node and the only gateway to the ground.
    Lander,
    /// The ground station, beyond the delayed ground link.
    Ground,
}

impl NodeAddr {
    /// The rover's address.
    pub fn rover(id: RoverId) -> Self {
        NodeAddr::Rover(id.0)
    }

    /// Whether this node is on the mesh radio (everything but the ground station).
    pub fn on_mesh(self) -> bool {
        self != NodeAddr::Ground
    }
}

impl fmt::Display for NodeAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NodeAddr::Rover(k) => write!(f, "rover{k}"),
            NodeAddr::Lander => write!(f, "lander"),
            NodeAddr::Ground => write!(f, "ground"),
        }
    }
}

/// One message on its way from one node to one other.
#[derive(Clone, Debug, PartialEq)]
pub struct Packet {
    /// Unique over the network's life.
    pub id: u64,
    /// Per (sender, topic, receiver): 0, 1, 2, ... in publishing order.
    pub seq: u64,
    /// Who published it.
    pub src: NodeAddr,
    /// Who it is for.
    pub dst: NodeAddr,
    /// The topic it was published on.
    pub topic: Topic,
    /// The service asked for.
    pub qos: Qos,
    /// When it was published.
    pub created: Time,
    /// The encoded message.
    pub payload: Vec<u8>,
    /// Mesh hops taken so far.
    pub hops: u8,
}

impl Packet {
    /// Bytes on the air.
    pub fn wire_bytes(&self) -> usize {
        self.payload.len() + HEADER_BYTES
    }

    /// Whether its time to live has run out at `now`.
    pub fn expired(&self, now: Time) -> bool {
        self.qos.ttl.is_some_and(|ttl| now > self.created + ttl)
    }
}
