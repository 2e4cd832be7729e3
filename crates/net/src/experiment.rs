//! Experiments on the simulated network that tests and benchmarks share: saturated
//! throughput over a direct link or through a relay (the field's relay measurement), and a
//! fleet's everyday traffic mix.

use crate::config::NetworkConfig;
use crate::packet::NodeAddr;
use crate::qos::{Priority, Qos, Reliability};
use crate::simnet::SimNetwork;
use realms_core::{Point2, Time, Topic};

/// Payload of one saturating frame, bytes (a full 1500-byte frame with our headers).
const FLOOD_PAYLOAD_BYTES: usize = 1420;

/// Payload throughput, Mb/s, from a rover `rover_at_m` from the lander (along a line) to the
/// lander while the rover sends as fast as the network takes it, optionally with a relay
/// rover at `relay_at_m`; measured over `seconds` after one second of warm-up.
pub fn flood_throughput_mbps(
    cfg: &NetworkConfig,
    rover_at_m: f64,
    relay_at_m: Option<f64>,
    seconds: u32,
) -> f64 {
    let rover = NodeAddr::Rover(1);
    let mut net = SimNetwork::new(cfg.clone(), Point2::new(0.0, 0.0));
    net.add_mesh_node(rover, Point2::new(rover_at_m, 0.0));
    if let Some(x) = relay_at_m {
        net.add_mesh_node(NodeAddr::Rover(2), Point2::new(x, 0.0));
    }
    let topic = Topic::new("rover1/camera/image");
    net.subscribe(NodeAddr::Lander, topic.clone());
    let qos = Qos {
        reliability: Reliability::BestEffort,
        priority: Priority::Image,
        ttl: None,
    };
    let tick_s = 0.1;
    let warmup_ticks = 10;
    let mut bytes = 0usize;
    for tick in 1..=(warmup_ticks + seconds * 10) {
        // Top the queue up to more than any link here carries in a tick.
        let backlog = net.queued_bytes(rover) + net.queued_bytes(NodeAddr::Rover(2));
        let wanted: usize = 2 << 20;
        for _ in 0..wanted.saturating_sub(backlog) / (FLOOD_PAYLOAD_BYTES + 80) {
            net.publish(rover, &topic, vec![0; FLOOD_PAYLOAD_BYTES], qos);
        }
        net.advance_to(Time::from_secs_f64(tick as f64 * tick_s));
        let delivered: usize = net.take_deliveries().iter().map(|d| d.payload.len()).sum();
        if tick > warmup_ticks {
            bytes += delivered;
        }
    }
    bytes as f64 * 8.0 / seconds.max(1) as f64 / 1e6
}

/// What [`fleet_traffic`] moved.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FleetTraffic {
    /// Messages published (one per receiver).
    pub published: u64,
    /// Messages delivered.
    pub delivered: u64,
    /// Bytes put on the air (every hop and the ground link).
    pub air_bytes: u64,
}

/// `rovers` rovers driving slow circles around an arena of `size_m` with the lander in the
/// middle, each sending a rover's everyday traffic to the lander and the ground for
/// `seconds`: pose at 10 Hz, localisation status at 1 Hz, a 2 kB map update every second and
/// a 20 kB camera frame every 2 s; the ground sends each rover a goal every 30 s.
pub fn fleet_traffic(cfg: &NetworkConfig, rovers: u8, size_m: f64, seconds: u32) -> FleetTraffic {
    let mut net = SimNetwork::new(cfg.clone(), Point2::new(0.0, 0.0));
    let position = |k: u8, t_s: f64| {
        let r = size_m / 2.0 * (0.3 + 0.7 * (k as f64 * 0.618).fract());
        let a = k as f64 * 2.4 + t_s * 0.4 / r;
        Point2::new(r * a.cos(), r * a.sin())
    };
    let streams: [(&str, u32, usize); 4] = [
        ("pose", 1, 120),
        ("localisation", 10, 80),
        ("map/delta", 10, 2000),
        ("camera/image", 20, 20_000),
    ];
    for k in 1..=rovers {
        net.add_mesh_node(NodeAddr::Rover(k), position(k, 0.0));
        for (leaf, _, _) in streams {
            let topic = Topic::new(format!("rover{k}/{leaf}"));
            net.subscribe(NodeAddr::Lander, topic.clone());
            net.subscribe(NodeAddr::Ground, topic);
        }
        net.subscribe(NodeAddr::Rover(k), Topic::new(format!("rover{k}/nav/goal")));
    }
    let mut delivered = 0u64;
    for tick in 0..seconds * 10 {
        let t_s = tick as f64 * 0.1;
        net.advance_to(Time::from_secs_f64(t_s));
        delivered += net.take_deliveries().len() as u64;
        for k in 1..=rovers {
            let me = NodeAddr::Rover(k);
            net.set_position(me, position(k, t_s));
            for (leaf, every, bytes) in streams {
                if tick % every == 0 {
                    let topic = Topic::new(format!("rover{k}/{leaf}"));
                    net.publish(me, &topic, vec![0; bytes], Qos::for_topic(&topic));
                }
            }
            if tick % 300 == 0 {
                let topic = Topic::new(format!("rover{k}/nav/goal"));
                net.publish(
                    NodeAddr::Ground,
                    &topic,
                    vec![0; 40],
                    Qos::for_topic(&topic),
                );
            }
        }
    }
    net.advance_to(Time::from_secs_f64(seconds as f64 + 5.0));
    delivered += net.take_deliveries().len() as u64;
    let stats = net.stats();
    FleetTraffic {
        published: stats.topics.values().map(|t| t.published.messages).sum(),
        delivered,
        air_bytes: stats.links.values().sum(),
    }
}
