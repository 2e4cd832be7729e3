//! A node's outgoing queue: store-and-forward for when no route exists, drained by priority.
//!
//! Bounded in bytes. When full, the lowest-priority, oldest packet goes first, and every
//! drop is handed back to be counted. Map packets are never dropped: a newer map packet on
//! the same topic, from the same sender to the same receiver, replaces the queued one in
//! place (the receiver's map-delta decoder notices the gap and asks for a snapshot).

use crate::packet::Packet;
use crate::qos::Priority;
use std::collections::VecDeque;

/// Why a packet left a queue without being sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum DropReason {
    /// The queue was full and this was the lowest priority, oldest packet.
    QueueFull,
    /// Its time to live ran out.
    Expired,
    /// A newer map packet for the same cells replaced it.
    Superseded,
    /// The radio gave up on it (best effort only).
    LinkLoss,
    /// It went round a routing loop (more than [`crate::packet::MAX_HOPS`] hops).
    HopLimit,
    /// The node holding it went down.
    NodeDown,
    /// The mesh node it was addressed to is down. A node whose radio is off lets its
    /// subscriptions lapse (as a zenoh session's declarations go when its lease runs out), so
    /// nothing waits for it: what was queued for it is dropped when it goes down, and what is
    /// sent to it while it is down is dropped at once.
    ReceiverDown,
}

/// A bounded priority queue of packets.
#[derive(Clone, Debug)]
pub struct TxQueue {
    capacity_bytes: usize,
    bytes: usize,
    levels: [VecDeque<Packet>; Priority::ALL.len()],
}

impl TxQueue {
    /// An empty queue holding at most `capacity_bytes` of droppable traffic.
    pub fn new(capacity_bytes: usize) -> Self {
        TxQueue {
            capacity_bytes,
            bytes: 0,
            levels: Default::default(),
        }
    }

    /// Bytes queued.
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Packets queued.
    pub fn len(&self) -> usize {
        self.levels.iter().map(VecDeque::len).sum()
    }

    /// Whether nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.levels.iter().all(VecDeque::is_empty)
    }

    /// Queues `p`; pushes whatever had to leave (possibly `p` itself) to `dropped`.
    pub fn push(&mut self, p: Packet, dropped: &mut Vec<(Packet, DropReason)>) {
        let level = p.qos.priority.index();
        if p.qos.supersedes()
            && let Some(i) = self.levels[level]
                .iter()
                .position(|q| q.src == p.src && q.dst == p.dst && q.topic == p.topic)
            && let Some(old) = self.levels[level].remove(i)
        {
            // The newer one goes to the back: map packets keep the order they were made in,
            // so an update never overtakes the snapshot it builds on.
            self.bytes = self.bytes + p.wire_bytes() - old.wire_bytes();
            self.levels[level].push_back(p);
            dropped.push((old, DropReason::Superseded));
            return;
        }
        self.bytes += p.wire_bytes();
        self.levels[level].push_back(p);
        while self.bytes > self.capacity_bytes {
            // Lowest priority first, oldest first; map data is exempt.
            let Some(victim) = Priority::ALL
                .iter()
                .rev()
                .filter(|l| !matches!(l, Priority::Map))
                .find_map(|l| self.levels[l.index()].pop_front())
            else {
                break;
            };
            self.bytes -= victim.wire_bytes();
            dropped.push((victim, DropReason::QueueFull));
        }
    }

    /// Puts a packet back at the head of its level (a retransmission).
    pub fn push_front(&mut self, p: Packet) {
        self.bytes += p.wire_bytes();
        self.levels[p.qos.priority.index()].push_front(p);
    }

    /// Takes the most urgent packet `sendable` accepts: highest priority first, oldest first
    /// within a level. Packets `sendable` refuses (no route yet) keep their place, so one
    /// unreachable receiver does not hold up the others.
    pub fn pop_sendable(&mut self, mut sendable: impl FnMut(&Packet) -> bool) -> Option<Packet> {
        for level in &mut self.levels {
            if let Some(i) = level.iter().position(&mut sendable) {
                let p = level.remove(i)?;
                self.bytes -= p.wire_bytes();
                return Some(p);
            }
        }
        None
    }

    /// Removes every packet `doomed` selects, pushing them to `dropped` with `reason`.
    pub fn remove_where(
        &mut self,
        mut doomed: impl FnMut(&Packet) -> bool,
        reason: DropReason,
        dropped: &mut Vec<(Packet, DropReason)>,
    ) {
        for level in &mut self.levels {
            let mut kept = VecDeque::with_capacity(level.len());
            for p in level.drain(..) {
                if doomed(&p) {
                    self.bytes -= p.wire_bytes();
                    dropped.push((p, reason));
                } else {
                    kept.push_back(p);
                }
            }
            *level = kept;
        }
    }

    /// Packets queued, most urgent first.
    pub fn iter(&self) -> impl Iterator<Item = &Packet> {
        self.levels.iter().flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::packet::NodeAddr;
    use crate::qos::Qos;
    use realms_core::{Time, Topic};

    fn packet(id: u64, topic: &str, bytes: usize) -> Packet {
        Packet {
            id,
            seq: id,
            src: NodeAddr::Rover(1),
            dst: NodeAddr::Ground,
            topic: Topic::new(topic),
            qos: Qos::for_topic(&Topic::new(topic)),
            created: Time::ZERO,
            payload: vec![0; bytes],
            hops: 0,
        }
    }

    #[test]
    fn drains_by_priority_then_age() {
        let mut q = TxQueue::new(1 << 20);
        let mut dropped = Vec::new();
        q.push(packet(1, "rover1/camera/image", 10), &mut dropped);
        q.push(packet(2, "rover1/pose", 10), &mut dropped);
        q.push(packet(3, "rover1/nav/goal", 10), &mut dropped);
        q.push(packet(4, "rover1/pose", 10), &mut dropped);
        let order: Vec<u64> =
            std::iter::from_fn(|| q.pop_sendable(|_| true).map(|p| p.id)).collect();
        assert_eq!(order, vec![3, 2, 4, 1]);
        assert!(dropped.is_empty());
    }

    #[test]
    fn full_queue_drops_lowest_priority_oldest_and_never_maps() {
        let one = packet(0, "rover1/pose", 100).wire_bytes();
        let mut q = TxQueue::new(3 * one);
        let mut dropped = Vec::new();
        q.push(packet(1, "rover1/camera/image", 100), &mut dropped);
        q.push(packet(2, "rover1/map/delta", 100), &mut dropped);
        q.push(packet(3, "rover1/pose", 100), &mut dropped);
        q.push(packet(4, "rover1/pose", 100), &mut dropped);
        assert_eq!(dropped.len(), 1);
        assert_eq!((dropped[0].0.id, dropped[0].1), (1, DropReason::QueueFull));
        q.push(packet(5, "rover1/localisation", 100), &mut dropped);
        assert_eq!((dropped[1].0.id, dropped[1].1), (3, DropReason::QueueFull));
        // A newer map packet replaces the queued one.
        q.push(packet(6, "rover1/map/delta", 100), &mut dropped);
        assert_eq!((dropped[2].0.id, dropped[2].1), (2, DropReason::Superseded));
        let ids: Vec<u64> = q.iter().map(|p| p.id).collect();
        assert_eq!(ids, vec![5, 4, 6]);
        // ... behind other map packets queued since, and never a snapshot's topic (the pose
        // goes to make room: map data is never dropped).
        q.push(packet(7, "rover1/map/snapshot", 100), &mut dropped);
        q.push(packet(8, "rover1/map/delta", 100), &mut dropped);
        let ids: Vec<u64> = q.iter().map(|p| p.id).collect();
        assert_eq!(ids, vec![5, 7, 8]);
        let gone: Vec<(u64, DropReason)> = dropped.iter().map(|(p, why)| (p.id, *why)).collect();
        assert_eq!(
            gone[3..],
            [(4, DropReason::QueueFull), (6, DropReason::Superseded)]
        );
        assert_eq!(q.bytes(), 3 * one);
    }

    #[test]
    fn unreachable_packets_keep_their_place() {
        let mut q = TxQueue::new(1 << 20);
        let mut dropped = Vec::new();
        q.push(packet(1, "rover1/pose", 10), &mut dropped);
        q.push(packet(2, "rover1/pose", 10), &mut dropped);
        assert_eq!(q.pop_sendable(|p| p.id == 2).map(|p| p.id), Some(2));
        assert_eq!(q.pop_sendable(|_| true).map(|p| p.id), Some(1));
        assert!(q.is_empty());
    }
}
