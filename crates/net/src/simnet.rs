//! The simulated network: an 802.11s-like mesh of rovers and the lander on one radio
//! channel, HWMP-style routing on the airtime metric, store-and-forward queues, and the
//! delayed ground link with its blackouts. Sans-IO: the caller sets node positions, publishes,
//! calls [`SimNetwork::advance_to`] with the mission clock and takes the deliveries.
//!
//! The mesh is one collision domain (the arena is far smaller than the radio's range), so
//! every transmission holds the channel for its airtime: a relayed packet costs the channel
//! twice, which is where the field's `1 / (1/g1 + 1/g2)` comes from. Paths are refreshed
//! every [`NetworkConfig::route_interval_s`] with the HWMP airtime metric, extended as HWMP+
//! does: the frame error rate comes from recent delivery on the link when there is any, and a
//! node's link costs grow with how busy its radio was.

use crate::airtime::{OVERHEAD_US, should_switch};
use crate::config::NetworkConfig;
use crate::packet::{HEADER_BYTES, NodeAddr, Packet};
use crate::qos::{Priority, Qos, Reliability};
use crate::queue::{DropReason, TxQueue};
use crate::radio::LinkQuality;
use crate::stats::NetStats;
use realms_core::{Duration, Point2, Time, Topic};
use std::collections::{BTreeMap, BTreeSet};

/// Size of a path request or reply frame, bytes (IEEE 802.11s PREQ with one target).
const PATH_FRAME_BYTES: usize = 37 + HEADER_BYTES;
/// Weight of the newest attempt in a link's estimated frame error rate.
const ERROR_EWMA: f64 = 0.05;
/// SplitMix64's increment.
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// A message that reached a node.
#[derive(Clone, Debug, PartialEq)]
pub struct Delivery {
    /// When it arrived.
    pub at: Time,
    /// Who it is for.
    pub to: NodeAddr,
    /// Who published it.
    pub from: NodeAddr,
    /// Its topic.
    pub topic: Topic,
    /// When it was published.
    pub published: Time,
    /// The encoded message.
    pub payload: Vec<u8>,
}

#[derive(Clone, Debug)]
struct MeshNode {
    position: Point2,
    up: bool,
    queue: TxQueue,
    /// Airtime used since the last path refresh, microseconds.
    airtime_us: f64,
    /// Share of the last refresh interval this node's radio was busy.
    load: f64,
}

#[derive(Clone, Copy, Debug)]
struct Link {
    quality: LinkQuality,
    /// Frame error rate estimated from attempts on this link, once there are some.
    measured_error: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Route {
    next_hop: NodeAddr,
    metric_us: f64,
}

/// One direction of the ground link.
#[derive(Clone, Debug)]
struct GroundDirection {
    from: NodeAddr,
    to: NodeAddr,
    queue: TxQueue,
    free_at: Time,
    in_flight: Vec<(Time, Packet)>,
    /// Lost reliable packets and when the sender learns of it (one round trip later).
    resend: Vec<(Time, Packet)>,
}

/// The receiving end of one stream (sender, receiver, topic).
#[derive(Clone, Debug, Default)]
struct StreamRx {
    next: u64,
    held: BTreeMap<u64, Packet>,
    abandoned: BTreeSet<u64>,
}

/// The simulated mesh and ground link.
#[derive(Debug)]
pub struct SimNetwork {
    cfg: NetworkConfig,
    now: Time,
    rng: u64,
    next_id: u64,
    mesh: BTreeMap<NodeAddr, MeshNode>,
    links: BTreeMap<(NodeAddr, NodeAddr), Link>,
    routes: BTreeMap<(NodeAddr, NodeAddr), Route>,
    subscriptions: BTreeMap<Topic, Vec<NodeAddr>>,
    seqs: BTreeMap<(NodeAddr, NodeAddr, Topic), u64>,
    streams: BTreeMap<(NodeAddr, NodeAddr, Topic), StreamRx>,
    channel_free_at: Time,
    in_air: Vec<(Time, NodeAddr, Packet)>,
    up: GroundDirection,
    down: GroundDirection,
    next_refresh: Time,
    deliveries: Vec<Delivery>,
    stats: NetStats,
}

impl SimNetwork {
    /// A network with the lander at `lander_at` and no rovers yet.
    pub fn new(cfg: NetworkConfig, lander_at: Point2) -> Self {
        let queue = TxQueue::new(cfg.queue_bytes);
        let direction = |from, to| GroundDirection {
            from,
            to,
            queue: queue.clone(),
            free_at: Time::ZERO,
            in_flight: Vec::new(),
            resend: Vec::new(),
        };
        let mut net = SimNetwork {
            rng: splitmix(cfg.seed),
            now: Time::ZERO,
            next_id: 0,
            mesh: BTreeMap::new(),
            links: BTreeMap::new(),
            routes: BTreeMap::new(),
            subscriptions: BTreeMap::new(),
            seqs: BTreeMap::new(),
            streams: BTreeMap::new(),
            channel_free_at: Time::ZERO,
            in_air: Vec::new(),
            up: direction(NodeAddr::Lander, NodeAddr::Ground),
            down: direction(NodeAddr::Ground, NodeAddr::Lander),
            next_refresh: Time::ZERO,
            deliveries: Vec::new(),
            stats: NetStats::default(),
            cfg,
        };
        net.add_mesh_node(NodeAddr::Lander, lander_at);
        net
    }

    /// Puts a rover (or any mesh node) on the network at `position`.
    pub fn add_mesh_node(&mut self, node: NodeAddr, position: Point2) {
        if node.on_mesh() {
            self.mesh.insert(
                node,
                MeshNode {
                    position,
                    up: true,
                    queue: TxQueue::new(self.cfg.queue_bytes),
                    airtime_us: 0.0,
                    load: 0.0,
                },
            );
            self.next_refresh = self.now;
        }
    }

    /// Moves a mesh node; links follow at the next path refresh.
    pub fn set_position(&mut self, node: NodeAddr, position: Point2) {
        if let Some(n) = self.mesh.get_mut(&node) {
            n.position = position;
        }
    }

    /// Switches a mesh node's radio on or off. A node going down loses what it had queued.
    pub fn set_up(&mut self, node: NodeAddr, up: bool) {
        let Some(n) = self.mesh.get_mut(&node) else {
            return;
        };
        let was_up = n.up;
        if was_up == up {
            return;
        }
        n.up = up;
        if was_up && !up {
            let mut lost = Vec::new();
            n.queue
                .remove_where(|_| true, DropReason::NodeDown, &mut lost);
            // Left queued, packets for it would wait for ever and be looked through at every
            // transmission (a powered-off rover's peers had 1,600 each after four hours).
            for other in self.mesh.values_mut() {
                other
                    .queue
                    .remove_where(|p| p.dst == node, DropReason::ReceiverDown, &mut lost);
            }
            self.in_air.retain(|(_, to, p)| {
                let keep = *to != node;
                if !keep {
                    lost.push((p.clone(), DropReason::NodeDown));
                }
                keep
            });
            for (p, why) in lost {
                self.dropped(p, why);
            }
        }
        self.next_refresh = self.now;
    }

    /// `node` wants messages published on `topic`.
    pub fn subscribe(&mut self, node: NodeAddr, topic: Topic) {
        let subs = self.subscriptions.entry(topic).or_default();
        if !subs.contains(&node) {
            subs.push(node);
        }
    }

    /// Publishes `payload` on `topic` from `from` at the network's current time: one packet
    /// to every subscriber but the publisher.
    pub fn publish(&mut self, from: NodeAddr, topic: &Topic, payload: Vec<u8>, qos: Qos) {
        let receivers: Vec<NodeAddr> = self
            .subscriptions
            .get(topic)
            .map(|s| s.iter().copied().filter(|n| *n != from).collect())
            .unwrap_or_default();
        for to in receivers {
            self.send(from, to, topic, payload.clone(), qos);
        }
    }

    /// Sends `payload` on `topic` from `from` to `to` alone.
    pub fn send(
        &mut self,
        from: NodeAddr,
        to: NodeAddr,
        topic: &Topic,
        payload: Vec<u8>,
        qos: Qos,
    ) {
        let seq = self.seqs.entry((from, to, topic.clone())).or_insert(0);
        let p = Packet {
            id: self.next_id,
            seq: *seq,
            src: from,
            dst: to,
            topic: topic.clone(),
            qos,
            created: self.now,
            payload,
            hops: 0,
        };
        *seq += 1;
        self.next_id += 1;
        let bytes = p.wire_bytes();
        self.stats
            .nodes
            .entry(from)
            .or_default()
            .originated
            .add(bytes);
        self.stats
            .topics
            .entry(topic.clone())
            .or_default()
            .published
            .add(bytes);
        if self.mesh.get(&from).is_some_and(|n| !n.up) {
            self.dropped(p, DropReason::NodeDown);
            return;
        }
        self.arrive(from, p);
    }

    /// Counts a message the receiving node could not decode.
    pub fn count_malformed(&mut self) {
        self.stats.malformed += 1;
    }

    /// The counters so far.
    pub fn stats(&self) -> &NetStats {
        &self.stats
    }

    /// Bytes waiting at a node (its mesh queue, and for the lander and the ground their end
    /// of the ground link too).
    pub fn queued_bytes(&self, node: NodeAddr) -> usize {
        let mesh = self.mesh.get(&node).map_or(0, |n| n.queue.bytes());
        let ground = match node {
            NodeAddr::Lander => self.up.queue.bytes(),
            NodeAddr::Ground => self.down.queue.bytes(),
            NodeAddr::Rover(_) => 0,
        };
        mesh + ground
    }

    /// The next hop `at` uses towards `to` on the mesh, if it has a path.
    pub fn next_hop(&self, at: NodeAddr, to: NodeAddr) -> Option<NodeAddr> {
        self.routes.get(&(at, to)).map(|r| r.next_hop)
    }

    /// The link between two mesh nodes as last refreshed.
    pub fn link(&self, a: NodeAddr, b: NodeAddr) -> Option<LinkQuality> {
        self.links.get(&(a, b)).map(|l| l.quality)
    }

    /// Messages delivered so far and not yet taken.
    pub fn take_deliveries(&mut self) -> Vec<Delivery> {
        std::mem::take(&mut self.deliveries)
    }

    /// Runs the network up to `until`.
    pub fn advance_to(&mut self, until: Time) {
        loop {
            let t = self.channel_free_at.max(self.now);
            if t > until {
                // The frame on the air ends after `until`: it lands on a later call.
                break;
            }
            self.land_mesh_arrivals(t);
            self.now = t;
            if t >= self.next_refresh {
                self.refresh_paths();
                continue;
            }
            self.run_ground_link(t);
            if self.transmit_next(t) {
                continue;
            }
            // The channel is idle: jump to whatever can change that.
            let next = [Some(self.next_refresh), self.next_ground_event()]
                .into_iter()
                .flatten()
                .filter(|e| *e > t)
                .min();
            match next {
                Some(e) if e <= until => self.now = e,
                _ => break,
            }
        }
        self.now = until.max(self.now);
        self.run_ground_link(self.now);
    }

    fn draw(&mut self) -> f64 {
        self.rng = self.rng.wrapping_add(GOLDEN_GAMMA);
        (splitmix(self.rng) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Log-normal shadowing of the pair `a`-`b`: fixed for the pair, whichever end asks.
    fn shadowing_db(&self, a: NodeAddr, b: NodeAddr) -> f64 {
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        let key = |n: NodeAddr| match n {
            NodeAddr::Rover(k) => k as u64 + 2,
            NodeAddr::Lander => 1,
            NodeAddr::Ground => 0,
        };
        let h1 = splitmix(self.cfg.seed ^ (key(lo) << 32 | key(hi)).wrapping_mul(GOLDEN_GAMMA));
        let h2 = splitmix(h1.wrapping_add(GOLDEN_GAMMA));
        let u1 = ((h1 >> 11) as f64 + 1.0) / ((1u64 << 53) as f64 + 1.0);
        let u2 = (h2 >> 11) as f64 / (1u64 << 53) as f64;
        // Box-Muller.
        let z = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        z * self.cfg.radio.shadowing_sigma_db
    }

    /// Re-measures every link and refreshes every node's path to every other (HWMP path
    /// request/reply round), with hysteresis; the control frames take airtime.
    fn refresh_paths(&mut self) {
        let interval_us = self.cfg.route_interval_s * 1e6;
        let nodes: Vec<NodeAddr> = self.mesh.keys().copied().collect();
        for n in self.mesh.values_mut() {
            n.load = (n.airtime_us / interval_us).min(1.0);
            n.airtime_us = 0.0;
        }
        for &a in &nodes {
            for &b in &nodes {
                if a == b {
                    continue;
                }
                let (na, nb) = (&self.mesh[&a], &self.mesh[&b]);
                let quality = if na.up && nb.up {
                    let d = na.position.distance_m(nb.position);
                    self.cfg.radio.link(d, self.shadowing_db(a, b))
                } else {
                    self.cfg.radio.link_at_snr(f64::NEG_INFINITY)
                };
                let measured_error = self.links.get(&(a, b)).and_then(|l| l.measured_error);
                self.links.insert(
                    (a, b),
                    Link {
                        quality,
                        measured_error,
                    },
                );
            }
        }
        let cost = |s: &Self, a: NodeAddr, b: NodeAddr| -> f64 {
            let Some(l) = s.links.get(&(a, b)) else {
                return f64::INFINITY;
            };
            if l.quality.mcs.is_none() {
                return f64::INFINITY;
            }
            let e = l
                .measured_error
                .unwrap_or(l.quality.per)
                .max(l.quality.per * 0.5);
            crate::airtime::link_airtime_us(l.quality.phy_rate_mbps, e.min(0.99))
                * (1.0 + s.mesh[&a].load)
        };
        for &dst in &nodes {
            // Dijkstra towards `dst` over the (directed) link costs.
            let mut best: BTreeMap<NodeAddr, f64> = BTreeMap::from([(dst, 0.0)]);
            let mut done: BTreeSet<NodeAddr> = BTreeSet::new();
            while let Some((&u, &du)) = best
                .iter()
                .filter(|(n, _)| !done.contains(*n))
                .min_by(|a, b| a.1.total_cmp(b.1))
            {
                done.insert(u);
                for &v in &nodes {
                    let c = cost(self, v, u);
                    if !done.contains(&v) && c.is_finite() {
                        let dv = du + c;
                        if best.get(&v).is_none_or(|old| dv < *old) {
                            best.insert(v, dv);
                        }
                    }
                }
            }
            for &src in &nodes {
                if src == dst {
                    continue;
                }
                // The best first hop from `src`.
                let candidate = nodes
                    .iter()
                    .filter(|h| **h != src)
                    .filter_map(|&h| {
                        let m = cost(self, src, h) + best.get(&h).copied().unwrap_or(f64::INFINITY);
                        m.is_finite().then_some(Route {
                            next_hop: h,
                            metric_us: m,
                        })
                    })
                    .min_by(|a, b| a.metric_us.total_cmp(&b.metric_us));
                // The current path is kept (hysteresis) only while its next hop is strictly
                // nearer the destination than this node: the feasibility condition of loop-free
                // distance-vector routing (Babel, RFC 8966 s. 2.4). Without it two nodes that
                // each keep an old path through the other would bounce packets between them.
                let own = best.get(&src).copied().unwrap_or(f64::INFINITY);
                let current = self.routes.get(&(src, dst)).and_then(|r| {
                    let h = r.next_hop;
                    let via = best.get(&h).copied().unwrap_or(f64::INFINITY);
                    (via < own).then(|| cost(self, src, h) + via)
                });
                match (candidate, current) {
                    (None, _) => {
                        self.routes.remove(&(src, dst));
                    }
                    (Some(c), Some(cur)) if !should_switch(cur, c.metric_us) => {
                        if let Some(r) = self.routes.get_mut(&(src, dst)) {
                            r.metric_us = cur;
                        }
                    }
                    (Some(c), _) => {
                        if self
                            .routes
                            .get(&(src, dst))
                            .is_some_and(|r| r.next_hop != c.next_hop)
                        {
                            self.stats.route_changes += 1;
                        }
                        self.routes.insert((src, dst), c);
                    }
                }
            }
        }
        // Every node that is up sends a path request and answers one per refresh, at the
        // lowest rate (broadcast frames go at the basic rate).
        let lowest_mbps = self.cfg.radio.mcs.first().map_or(6.5, |m| m.1);
        let up = self.mesh.values().filter(|n| n.up).count();
        let control_us =
            up as f64 * 2.0 * (OVERHEAD_US + PATH_FRAME_BYTES as f64 * 8.0 / lowest_mbps);
        self.stats.routing_bytes += (up * 2 * PATH_FRAME_BYTES) as u64;
        self.channel_free_at =
            self.now.max(self.channel_free_at) + Duration::from_secs_f64(control_us * 1e-6);
        self.next_refresh = self.now + Duration::from_secs_f64(self.cfg.route_interval_s);
    }

    /// Where a packet at mesh node `at` must go next on the mesh, if it can go now.
    fn mesh_next_hop(&self, at: NodeAddr, p: &Packet) -> Option<NodeAddr> {
        self.next_hop_to(at, mesh_target(p))
    }

    /// The next hop from mesh node `at` towards mesh node `target`, if it is up.
    fn next_hop_to(&self, at: NodeAddr, target: NodeAddr) -> Option<NodeAddr> {
        route_hop(&self.routes, at, target, |h| {
            self.mesh.get(&h).is_some_and(|n| n.up)
        })
    }

    /// Starts the next transmission on the channel, if any node has something it can send:
    /// the node whose most urgent sendable packet is the most urgent, oldest on ties
    /// (802.11e gives urgent traffic earlier channel access).
    fn transmit_next(&mut self, t: Time) -> bool {
        let mut pick: Option<(NodeAddr, (usize, Time, u64), HopMemo)> = None;
        for (&n, node) in &self.mesh {
            if !node.up {
                continue;
            }
            // A queue cut off from where its packets go holds many for the same few
            // targets, and is looked through again at every transmission: each target's
            // route is looked up once.
            let mut hops = HopMemo::default();
            if let Some(p) = node.queue.iter().find(|p| {
                hops.next_hop(mesh_target(p), |t| self.next_hop_to(n, t))
                    .is_some()
            }) {
                let key = (p.qos.priority.index(), p.created, p.id);
                if pick.as_ref().is_none_or(|(_, k, _)| key < *k) {
                    pick = Some((n, key, hops));
                }
            }
        }
        let Some((from, _, mut hops)) = pick else {
            return false;
        };
        // The pop meets the packets the search above looked through, in the same order, so
        // their targets' hops are all in `hops` already.
        let up: Vec<NodeAddr> = self
            .mesh
            .iter()
            .filter(|(_, n)| n.up)
            .map(|(a, _)| *a)
            .collect();
        let routes = &self.routes;
        let Some(p) = self.mesh.get_mut(&from).and_then(|n| {
            n.queue.pop_sendable(|p| {
                hops.next_hop(mesh_target(p), |t| {
                    route_hop(routes, from, t, |h| up.contains(&h))
                })
                .is_some()
            })
        }) else {
            return false;
        };
        if p.expired(t) {
            self.dropped(p, DropReason::Expired);
            return true;
        }
        let hop_and_link = self
            .mesh_next_hop(from, &p)
            .and_then(|h| self.links.get(&(from, h)).map(|l| (h, *l)));
        let Some((hop, link)) = hop_and_link else {
            if let Some(n) = self.mesh.get_mut(&from) {
                n.queue.push_front(p);
            }
            return false;
        };
        let q = link.quality;
        let bits = p.wire_bytes() as f64 * 8.0;
        let attempt_us =
            OVERHEAD_US + bits / (q.phy_rate_mbps * self.cfg.radio.goodput_fraction).max(1e-9);
        let mut airtime_us = 0.0;
        let mut delivered = false;
        let mut error = link.measured_error.unwrap_or(q.per);
        for _ in 0..=self.cfg.mac_retries {
            airtime_us += attempt_us;
            let lost = self.draw() < q.per;
            error = (1.0 - ERROR_EWMA) * error + ERROR_EWMA * if lost { 1.0 } else { 0.0 };
            if !lost {
                delivered = true;
                break;
            }
        }
        if let Some(l) = self.links.get_mut(&(from, hop)) {
            l.measured_error = Some(error);
        }
        if let Some(n) = self.mesh.get_mut(&from) {
            n.airtime_us += airtime_us;
        }
        let end = t + Duration::from_secs_f64(airtime_us * 1e-6);
        self.channel_free_at = end;
        self.stats
            .transmit(from, hop, t.as_secs_f64().max(0.0) as u64, p.wire_bytes());
        if from != p.src {
            self.stats
                .nodes
                .entry(from)
                .or_default()
                .forwarded
                .add(p.wire_bytes());
        }
        if delivered && p.hops >= crate::packet::MAX_HOPS {
            self.dropped(p, DropReason::HopLimit);
        } else if delivered {
            let mut p = p;
            p.hops += 1;
            self.in_air.push((end, hop, p));
        } else if p.qos.reliability == Reliability::Reliable {
            if let Some(n) = self.mesh.get_mut(&from) {
                n.queue.push_front(p);
            }
        } else {
            self.dropped(p, DropReason::LinkLoss);
        }
        true
    }

    fn land_mesh_arrivals(&mut self, t: Time) {
        if self.in_air.iter().all(|(at, _, _)| *at > t) {
            return;
        }
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.in_air)
            .into_iter()
            .partition(|(at, _, _)| *at <= t);
        self.in_air = later;
        for (at, node, p) in due {
            // Delivered at its own arrival time; the caller moves the clock on to `t` after.
            self.now = self.now.max(at);
            self.arrive(node, p);
        }
    }

    /// A packet is at `node`: delivered if it is for it, otherwise queued onwards.
    fn arrive(&mut self, node: NodeAddr, p: Packet) {
        if p.dst == node {
            self.deliver(node, p);
            return;
        }
        let mut dropped = Vec::new();
        match (node, p.dst) {
            (NodeAddr::Lander, NodeAddr::Ground) | (NodeAddr::Ground, _) => {
                let now = self.now;
                let dir = if node == NodeAddr::Ground {
                    &mut self.down
                } else {
                    &mut self.up
                };
                if dir.queue.is_empty() {
                    // The link was idle: it starts sending when this arrives.
                    dir.free_at = dir.free_at.max(now);
                }
                dir.queue.push(p, &mut dropped);
            }
            _ if self.mesh.get(&p.dst).is_some_and(|d| !d.up) => {
                dropped.push((p, DropReason::ReceiverDown));
            }
            _ => match self.mesh.get_mut(&node) {
                Some(n) if n.up => n.queue.push(p, &mut dropped),
                _ => dropped.push((p, DropReason::NodeDown)),
            },
        }
        for (p, why) in dropped {
            self.dropped(p, why);
        }
    }

    fn dropped(&mut self, p: Packet, why: DropReason) {
        self.stats.drop(&p.topic, why);
        if p.qos.reliability == Reliability::Reliable {
            let key = (p.src, p.dst, p.topic.clone());
            let s = self.streams.entry(key).or_default();
            s.abandoned.insert(p.seq);
            let to = p.dst;
            self.flush_stream(to, p.src, p.topic);
        }
    }

    fn deliver(&mut self, to: NodeAddr, p: Packet) {
        if p.expired(self.now) {
            self.dropped(p, DropReason::Expired);
            return;
        }
        let key = (p.src, to, p.topic.clone());
        let s = self.streams.entry(key).or_default();
        match p.qos.reliability {
            Reliability::BestEffort => {
                if p.seq >= s.next {
                    s.next = p.seq + 1;
                    self.hand_over(to, p);
                }
            }
            Reliability::Reliable => {
                if p.seq >= s.next {
                    s.held.insert(p.seq, p.clone());
                }
                self.flush_stream(to, p.src, p.topic);
            }
        }
    }

    /// Hands over, in order, every held packet of a reliable stream that is next in line.
    fn flush_stream(&mut self, to: NodeAddr, from: NodeAddr, topic: Topic) {
        let key = (from, to, topic);
        let mut ready = Vec::new();
        if let Some(s) = self.streams.get_mut(&key) {
            loop {
                if s.abandoned.remove(&s.next) {
                    s.next += 1;
                } else if let Some(p) = s.held.remove(&s.next) {
                    s.next += 1;
                    ready.push(p);
                } else {
                    break;
                }
            }
        }
        for p in ready {
            if p.expired(self.now) {
                // Its turn came too late (it waited for an earlier one).
                self.stats.drop(&p.topic, DropReason::Expired);
            } else {
                self.hand_over(to, p);
            }
        }
    }

    fn hand_over(&mut self, to: NodeAddr, p: Packet) {
        let bytes = p.wire_bytes();
        self.stats.nodes.entry(to).or_default().delivered.add(bytes);
        self.stats
            .topics
            .entry(p.topic.clone())
            .or_default()
            .delivered
            .add(bytes);
        self.deliveries.push(Delivery {
            at: self.now,
            to,
            from: p.src,
            topic: p.topic,
            published: p.created,
            payload: p.payload,
        });
    }

    /// Sends on and lands packets on both directions of the ground link up to `t`.
    fn run_ground_link(&mut self, t: Time) {
        self.run_ground_direction(true, t);
        self.run_ground_direction(false, t);
    }

    fn ground_direction(&mut self, up: bool) -> &mut GroundDirection {
        if up { &mut self.up } else { &mut self.down }
    }

    fn run_ground_direction(&mut self, up: bool, t: Time) {
        let delay = Duration::from_secs_f64(self.cfg.ground.delay_s);
        let bandwidth_bps = self.cfg.ground.bandwidth_bps.max(1.0);
        let dir = self.ground_direction(up);
        if dir.resend.iter().any(|(at, _)| *at <= t) {
            let (mut due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut dir.resend)
                .into_iter()
                .partition(|(at, _)| *at <= t);
            dir.resend = later;
            // Oldest ends up first.
            due.sort_by_key(|(_, p)| std::cmp::Reverse(p.id));
            for (_, p) in due {
                if dir.queue.is_empty() {
                    dir.free_at = dir.free_at.max(t);
                }
                dir.queue.push_front(p);
            }
        }
        loop {
            let dir = if up { &self.up } else { &self.down };
            let start = dir.free_at;
            if start > t || dir.queue.is_empty() {
                break;
            }
            if let Some(light) = self.cfg.ground.light_after(start.as_secs_f64()) {
                // At least a nanosecond on: an end finer than the clock must not stall here.
                let resume = Time::from_secs_f64(light).max(start + Duration::from_ns(1));
                self.ground_direction(up).free_at = resume;
                continue;
            }
            let (from, to) = (dir.from, dir.to);
            let Some(p) = self.ground_direction(up).queue.pop_sendable(|_| true) else {
                break;
            };
            if p.expired(start) {
                self.dropped(p, DropReason::Expired);
                continue;
            }
            let tx = Duration::from_secs_f64(p.wire_bytes() as f64 * 8.0 / bandwidth_bps);
            let copies = if p.qos.priority == Priority::Map {
                self.cfg.ground.map_copies.max(1)
            } else {
                1
            };
            // Each copy takes the link in turn; the first to get through is the one that
            // lands (the receiver drops the others as duplicates).
            let mut sent_until = start;
            let mut arrival = None;
            for _ in 0..copies {
                let landing = sent_until + tx + delay;
                let in_dark = self
                    .cfg
                    .ground
                    .dark_during(sent_until.as_secs_f64(), landing.as_secs_f64());
                let lost = in_dark || self.draw() < self.cfg.ground.loss;
                self.stats.transmit(
                    from,
                    to,
                    sent_until.as_secs_f64().max(0.0) as u64,
                    p.wire_bytes(),
                );
                sent_until += tx;
                if !lost && arrival.is_none() {
                    arrival = Some(landing);
                }
            }
            let dir = self.ground_direction(up);
            dir.free_at = sent_until;
            if let Some(arrival) = arrival {
                dir.in_flight.push((arrival, p));
            } else if p.qos.reliability == Reliability::Reliable {
                // Noticed missing after a round trip (selective repeat: the rest goes on).
                dir.resend.push((sent_until + delay + delay, p));
            } else {
                self.dropped(p, DropReason::LinkLoss);
            }
        }
        let dir = self.ground_direction(up);
        if dir.in_flight.iter().all(|(at, _)| *at > t) {
            return;
        }
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut dir.in_flight)
            .into_iter()
            .partition(|(at, _)| *at <= t);
        dir.in_flight = later;
        let to = dir.to;
        for (at, p) in due {
            let keep = self.now;
            self.now = at;
            self.arrive(to, p);
            self.now = keep;
        }
    }

    fn next_ground_event(&self) -> Option<Time> {
        [&self.up, &self.down]
            .into_iter()
            .flat_map(|d| {
                let landing = d.in_flight.iter().chain(&d.resend).map(|(at, _)| *at).min();
                let sending = (!d.queue.is_empty()).then(|| {
                    let s = d.free_at.as_secs_f64();
                    self.cfg
                        .ground
                        .light_after(s)
                        .map_or(d.free_at, Time::from_secs_f64)
                });
                [landing, sending]
            })
            .flatten()
            .min()
    }
}

/// SplitMix64 (Steele, Lea and Flood 2014): a tiny, well-mixed hash and generator, so the
/// network draws its own reproducible randomness without a dependency.
fn splitmix(x: u64) -> u64 {
    let mut z = x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The mesh node a packet travels to on the mesh: its destination, or the lander (the
/// gateway) for the ground.
fn mesh_target(p: &Packet) -> NodeAddr {
    if p.dst.on_mesh() {
        p.dst
    } else {
        NodeAddr::Lander
    }
}

/// The next hop from `at` towards mesh node `target` in `routes`, if `up` holds for it.
fn route_hop(
    routes: &BTreeMap<(NodeAddr, NodeAddr), Route>,
    at: NodeAddr,
    target: NodeAddr,
    up: impl Fn(NodeAddr) -> bool,
) -> Option<NodeAddr> {
    let hop = routes.get(&(at, target))?.next_hop;
    up(hop).then_some(hop)
}

/// Next hops from one node already looked up, by target (a handful at most).
#[derive(Default)]
struct HopMemo {
    known: Vec<(NodeAddr, Option<NodeAddr>)>,
}

impl HopMemo {
    fn next_hop(
        &mut self,
        target: NodeAddr,
        look_up: impl FnOnce(NodeAddr) -> Option<NodeAddr>,
    ) -> Option<NodeAddr> {
        if let Some((_, hop)) = self.known.iter().find(|(t, _)| *t == target) {
            return *hop;
        }
        let hop = look_up(target);
        self.known.push((target, hop));
        hop
    }
}
