//! Bandwidth accounting: bytes and messages per node, per topic, per link and per second,
//! and everything the network dropped, by reason.

use crate::packet::NodeAddr;
use crate::queue::DropReason;
use realms_core::Topic;
use serde::Serialize;
use std::collections::BTreeMap;

/// Messages and bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Count {
    /// Messages.
    pub messages: u64,
    /// Bytes on the air (payload and headers).
    pub bytes: u64,
}

impl Count {
    /// Adds one message of `bytes`.
    pub fn add(&mut self, bytes: usize) {
        self.messages += 1;
        self.bytes += bytes as u64;
    }
}

/// What one node did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct NodeStats {
    /// Messages it published (one per receiver).
    pub originated: Count,
    /// Messages delivered to it.
    pub delivered: Count,
    /// Messages it relayed for others.
    pub forwarded: Count,
    /// Bytes it put on the air, per second of mission time.
    pub tx_bytes_per_s: BTreeMap<u64, u64>,
}

/// What happened on one topic.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TopicStats {
    /// Published (one per receiver).
    pub published: Count,
    /// Delivered.
    pub delivered: Count,
    /// Dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
}

/// The network's counters.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct NetStats {
    /// Per node.
    pub nodes: BTreeMap<NodeAddr, NodeStats>,
    /// Per topic.
    pub topics: BTreeMap<Topic, TopicStats>,
    /// Bytes sent over each directed link (mesh hops and the ground link).
    pub links: BTreeMap<(NodeAddr, NodeAddr), u64>,
    /// Packets dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
    /// Bytes of routing control traffic (path requests and replies).
    pub routing_bytes: u64,
    /// Times a node's path to a destination changed next hop.
    pub route_changes: u64,
    /// Received messages that did not decode, counted and dropped by the receiving node.
    pub malformed: u64,
}

impl NetStats {
    /// Counts a drop.
    pub fn drop(&mut self, topic: &Topic, reason: DropReason) {
        let key = format!("{reason:?}");
        *self.dropped.entry(key.clone()).or_insert(0) += 1;
        *self
            .topics
            .entry(topic.clone())
            .or_default()
            .dropped
            .entry(key)
            .or_insert(0) += 1;
    }

    /// Drops of one reason, all topics.
    pub fn dropped(&self, reason: DropReason) -> u64 {
        self.dropped
            .get(&format!("{reason:?}"))
            .copied()
            .unwrap_or(0)
    }

    /// Counts `bytes` sent by `from` to `to` over the air at second `second`.
    pub fn transmit(&mut self, from: NodeAddr, to: NodeAddr, second: u64, bytes: usize) {
        *self.links.entry((from, to)).or_insert(0) += bytes as u64;
        *self
            .nodes
            .entry(from)
            .or_default()
            .tx_bytes_per_s
            .entry(second)
            .or_insert(0) += bytes as u64;
    }
}
