//! The one interface node traffic goes through: publish and subscribe by topic key with the
//! topic's quality of service, and delivery of what arrived. A driver adapts nodes to it;
//! the simulated network ([`crate::SimNetwork`]) is one implementation, a real transport
//! (Zenoh) will be another. Payloads are already encoded with the project's one codec, so
//! bandwidth figures count the real bytes.

use crate::packet::NodeAddr;
use crate::qos::Qos;
use crate::simnet::{Delivery, SimNetwork};
use realms_core::{Time, Topic};

/// Publish/subscribe between nodes.
pub trait Transport {
    /// `node` wants messages published on `topic`.
    fn subscribe(&mut self, node: NodeAddr, topic: Topic);

    /// `from` publishes `payload` on `topic` at `now`, to every subscriber but itself.
    fn publish(&mut self, now: Time, from: NodeAddr, topic: &Topic, payload: Vec<u8>, qos: Qos);

    /// `from` sends `payload` on `topic` at `now` to `to` alone.
    fn send(
        &mut self,
        now: Time,
        from: NodeAddr,
        to: NodeAddr,
        topic: &Topic,
        payload: Vec<u8>,
        qos: Qos,
    );

    /// Everything delivered up to `now`, in delivery order.
    fn poll(&mut self, now: Time) -> Vec<Delivery>;
}

impl Transport for SimNetwork {
    fn subscribe(&mut self, node: NodeAddr, topic: Topic) {
        SimNetwork::subscribe(self, node, topic);
    }

    fn publish(&mut self, now: Time, from: NodeAddr, topic: &Topic, payload: Vec<u8>, qos: Qos) {
        self.advance_to(now);
        SimNetwork::publish(self, from, topic, payload, qos);
    }

    fn send(
        &mut self,
        now: Time,
        from: NodeAddr,
        to: NodeAddr,
        topic: &Topic,
        payload: Vec<u8>,
        qos: Qos,
    ) {
        self.advance_to(now);
        SimNetwork::send(self, from, to, topic, payload, qos);
    }

    fn poll(&mut self, now: Time) -> Vec<Delivery> {
        self.advance_to(now);
        self.take_deliveries()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::NetworkConfig;
    use realms_core::{Duration, Point2};

    /// What a driver does, through the interface alone.
    fn exchange(t: &mut dyn Transport) -> Vec<Delivery> {
        let topic = Topic::new("rover1/localisation");
        t.subscribe(NodeAddr::Lander, topic.clone());
        t.subscribe(NodeAddr::Ground, topic.clone());
        let qos = Qos::for_topic(&topic);
        t.publish(Time::ZERO, NodeAddr::Rover(1), &topic, vec![1, 2, 3], qos);
        t.send(
            Time::ZERO,
            NodeAddr::Ground,
            NodeAddr::Rover(1),
            &Topic::new("rover1/nav/goal"),
            vec![9],
            qos,
        );
        t.poll(Time::ZERO + Duration::from_secs(5))
    }

    #[test]
    fn the_simulated_network_behind_the_interface_delivers_to_every_subscriber() {
        let mut net = SimNetwork::new(NetworkConfig::default(), Point2::new(0.0, 0.0));
        net.add_mesh_node(NodeAddr::Rover(1), Point2::new(20.0, 0.0));
        let got = exchange(&mut net);
        let mut to: Vec<NodeAddr> = got.iter().map(|d| d.to).collect();
        to.sort();
        assert_eq!(to, [NodeAddr::Rover(1), NodeAddr::Lander, NodeAddr::Ground]);
        let ground = got
            .iter()
            .find(|d| d.to == NodeAddr::Ground)
            .expect("ground");
        assert_eq!(ground.payload, vec![1, 2, 3]);
        assert!(
            ground.at - ground.published >= Duration::from_secs(1),
            "1 s ground delay"
        );
    }
}
