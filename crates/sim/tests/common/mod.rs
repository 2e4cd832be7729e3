//! Hand-built worlds shared by the simulator's integration tests.
#![allow(dead_code)]

use realms_core::geometry::Vec3;
use realms_core::msgs::{Message, Twist, TwistStamped};
use realms_core::{Duration, Pose2, RoverId, Time, Topic};
use realms_sim::{Scenario, Terrain, World};

/// A scenario whose rover is the default one, with `count` rovers and no faults.
pub fn scenario(count: u8) -> Scenario {
    let mut s = Scenario::default();
    s.rovers.count = count;
    s.faults.clear();
    s
}

/// A flat 20 m x 20 m floor with walls round the edge and rovers at `starts`.
pub fn flat_world(s: &Scenario, starts: &[Pose2], build: impl FnOnce(&mut Terrain)) -> World {
    let mut t = Terrain::flat(20.0, 20.0, 0.05);
    t.add_perimeter_walls(0.2, 1.0);
    build(&mut t);
    t.rover_starts = starts.to_vec();
    World::with_terrain(s, t)
}

/// Drives rover `id` with a constant command, refreshed every 100 ms, for `secs`; returns
/// every message the world published.
pub fn drive(
    world: &mut World,
    id: RoverId,
    v_m_s: f64,
    w_rad_s: f64,
    secs: f64,
) -> Vec<(Topic, Message)> {
    let mut out = Vec::new();
    let end = world.now() + Duration::from_secs_f64(secs);
    let mut t = world.now();
    while t < end {
        world.command(
            id,
            TwistStamped {
                header: realms_core::msgs::Header {
                    stamp: t,
                    frame_id: format!("{id}/base_link"),
                },
                twist: Twist {
                    linear: Vec3::new(v_m_s, 0.0, 0.0),
                    angular: Vec3::new(0.0, 0.0, w_rad_s),
                },
            },
        );
        t = (t + Duration::from_millis(100)).min(end);
        world.advance_to(t, &mut out);
    }
    out
}

/// Runs the world with no commands until `t`.
pub fn idle_until(world: &mut World, t: Time) -> Vec<(Topic, Message)> {
    let mut out = Vec::new();
    world.advance_to(t, &mut out);
    out
}
