//! The in-process message bus of a simulated mission: topic subscriptions and per-topic
//! message counts. It is ideal (instant, lossless) and carries only on-board traffic for now;
//! the simulated mesh network (issue 5) replaces it for traffic between nodes.

use realms_core::Topic;
use std::collections::BTreeMap;

/// Subscriptions and counters.
#[derive(Debug, Default)]
pub struct Bus {
    subscribers: BTreeMap<Topic, Vec<usize>>,
    counts: BTreeMap<Topic, u64>,
}

impl Bus {
    /// Node `node` wants messages on `topic`.
    pub fn subscribe(&mut self, topic: Topic, node: usize) {
        let subs = self.subscribers.entry(topic).or_default();
        if !subs.contains(&node) {
            subs.push(node);
        }
    }

    /// Nodes subscribed to `topic`, in subscription order.
    pub fn subscribers(&self, topic: &Topic) -> &[usize] {
        self.subscribers.get(topic).map_or(&[], |v| v.as_slice())
    }

    /// Counts one message on `topic`.
    pub fn count(&mut self, topic: &Topic) {
        *self.counts.entry(topic.clone()).or_insert(0) += 1;
    }

    /// Messages per topic so far, sorted by topic.
    pub fn counts(&self) -> &BTreeMap<Topic, u64> {
        &self.counts
    }
}
