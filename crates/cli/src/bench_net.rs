//! `realms bench net-relay`: the field experiment of the mesh radio, on the radio model.
//!
//! In the field a rover 220 m from the operator could still be pinged and teleoperated but
//! could not stream images, and a relay rover 130 m from the operator and 100 m from the
//! rover raised the throughput 2-10x. This prints the same setups from
//! [`realms_net::radio`]: the mean link (no shadowing) and the median over random shadowing
//! draws (each hop its own draw).

use crate::cli::{BenchNetRelayArgs, BenchNetSimArgs};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use realms_net::airtime::{airtime_of, path_airtime_us};
use realms_net::experiment::{FleetTraffic, fleet_traffic, flood_throughput_mbps};
use realms_net::radio::{LinkQuality, RadioConfig, relay_goodput_mbps};
use serde::Serialize;
use std::time::Instant;

/// What an application needs from a path, Mb/s.
const PING_MBPS: f64 = 0.001;
/// `cmd_vel` at 10 Hz with headers and acknowledgements.
const TELEOP_MBPS: f64 = 0.05;
/// A 640 x 480 grayscale camera, JPEG at 5 frames a second.
const IMAGES_MBPS: f64 = 2.0;

/// One setup's figures.
#[derive(Clone, Debug, Serialize)]
struct Setup {
    name: String,
    hops_m: Vec<f64>,
    snr_db: Vec<f64>,
    phy_rate_mbps: Vec<f64>,
    per: Vec<f64>,
    goodput_mbps: f64,
    airtime_us: f64,
    ping: bool,
    teleop: bool,
    images: bool,
}

fn setup(radio: &RadioConfig, name: &str, hops_m: &[f64]) -> Setup {
    let links: Vec<LinkQuality> = hops_m.iter().map(|d| radio.link(*d, 0.0)).collect();
    let goodput = relay_goodput_mbps(&links.iter().map(|l| l.goodput_mbps).collect::<Vec<_>>());
    Setup {
        name: name.to_string(),
        hops_m: hops_m.to_vec(),
        snr_db: links.iter().map(|l| l.snr_db).collect(),
        phy_rate_mbps: links.iter().map(|l| l.phy_rate_mbps).collect(),
        per: links.iter().map(|l| l.per).collect(),
        goodput_mbps: goodput,
        airtime_us: path_airtime_us(&links.iter().map(airtime_of).collect::<Vec<_>>()),
        ping: goodput >= PING_MBPS,
        teleop: goodput >= TELEOP_MBPS,
        images: goodput >= IMAGES_MBPS,
    }
}

/// A standard normal draw (Box-Muller).
fn normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Everything the bench reports.
#[derive(Debug, Serialize)]
struct Report {
    direct: Setup,
    relay: Setup,
    relay_gain: f64,
    shadowed_draws: usize,
    /// Median relayed goodput over median direct goodput (a ratio of medians: where the
    /// direct link is dead the ratio of a draw is infinite).
    relay_gain_median_shadowed: f64,
    direct_dead_fraction_shadowed: f64,
    direct_goodput_median_shadowed_mbps: f64,
    relay_goodput_median_shadowed_mbps: f64,
    sweep: Vec<Setup>,
    simulated_direct_mbps: f64,
    simulated_relay_mbps: f64,
    simulated_relay_gain: f64,
}

/// `realms bench net-relay`.
pub fn run(args: BenchNetRelayArgs) -> Result<()> {
    let radio = RadioConfig::default();
    let direct = setup(&radio, "direct, 220 m", &[220.0]);
    let relay = setup(&radio, "relay, 130 m + 100 m", &[130.0, 100.0]);
    let relay_gain = relay.goodput_mbps / direct.goodput_mbps;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let sigma = radio.shadowing_sigma_db;
    let (mut directs, mut relays, mut direct_dead) = (Vec::new(), Vec::new(), 0usize);
    for _ in 0..args.draws {
        let d = radio.link(220.0, sigma * normal(&mut rng)).goodput_mbps;
        let r = relay_goodput_mbps(&[
            radio.link(130.0, sigma * normal(&mut rng)).goodput_mbps,
            radio.link(100.0, sigma * normal(&mut rng)).goodput_mbps,
        ]);
        directs.push(d);
        relays.push(r);
        direct_dead += usize::from(d == 0.0);
    }
    let sweep = [25.0, 50.0, 100.0, 150.0, 200.0, 220.0, 250.0, 300.0]
        .iter()
        .map(|d| setup(&radio, &format!("direct, {d:.0} m"), &[*d]))
        .collect();
    // The same two setups on the simulated mesh: queues, retries and the shared channel.
    let net = realms_net::NetworkConfig {
        radio: RadioConfig {
            shadowing_sigma_db: 0.0,
            ..radio.clone()
        },
        ..realms_net::NetworkConfig::default()
    };
    let simulated_direct_mbps = flood_throughput_mbps(&net, 220.0, None, 10);
    // The relay 130 m from the lander and 100 m from the rover, the rover 220 m out.
    let simulated_relay_mbps = flood_throughput_mbps(&net, 220.0, Some(130.0), 10);
    let report = Report {
        simulated_direct_mbps,
        simulated_relay_mbps,
        simulated_relay_gain: simulated_relay_mbps / simulated_direct_mbps,
        direct,
        relay,
        relay_gain,
        shadowed_draws: args.draws,
        relay_gain_median_shadowed: crate::bench::median(relays.clone())
            / crate::bench::median(directs.clone()),
        direct_dead_fraction_shadowed: direct_dead as f64 / args.draws.max(1) as f64,
        direct_goodput_median_shadowed_mbps: crate::bench::median(directs),
        relay_goodput_median_shadowed_mbps: crate::bench::median(relays),
        sweep,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!("# realms bench net-relay");
    println!();
    println!(
        "radio: path loss {} dB at 1 m, exponent {}, shadowing sigma {} dB, {} dBm, {} dBi antennas, {} dB cables, noise {} dBm; goodput {} of the PHY rate",
        radio.path_loss_1m_db,
        radio.path_loss_exponent,
        radio.shadowing_sigma_db,
        radio.tx_power_dbm,
        radio.antenna_gain_dbi,
        radio.cable_loss_db,
        radio.noise_floor_dbm,
        radio.goodput_fraction
    );
    println!(
        "needs: ping {PING_MBPS} Mb/s, teleoperation {TELEOP_MBPS} Mb/s, images {IMAGES_MBPS} Mb/s"
    );
    println!();
    println!(
        "| setup | SNR per hop | PHY rate per hop | PER per hop | goodput | airtime | ping | teleop | images |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    let yes = |b: bool| if b { "yes" } else { "no" };
    let list = |v: &[f64], digits: usize| {
        v.iter()
            .map(|x| format!("{x:.digits$}"))
            .collect::<Vec<_>>()
            .join(" + ")
    };
    for s in std::iter::once(&report.direct)
        .chain(std::iter::once(&report.relay))
        .chain(report.sweep.iter())
    {
        println!(
            "| {} | {} dB | {} Mb/s | {} | {:.2} Mb/s | {:.0} us | {} | {} | {} |",
            s.name,
            list(&s.snr_db, 1),
            list(&s.phy_rate_mbps, 1),
            list(&s.per, 2),
            s.goodput_mbps,
            s.airtime_us,
            yes(s.ping),
            yes(s.teleop),
            yes(s.images)
        );
    }
    println!();
    println!(
        "relay gain: {:.1}x without shadowing; {:.1}x between the medians over {} shadowing draws (direct {:.2} Mb/s, relayed {:.2} Mb/s; the direct link dead in {:.0} % of draws)",
        report.relay_gain,
        report.relay_gain_median_shadowed,
        report.shadowed_draws,
        report.direct_goodput_median_shadowed_mbps,
        report.relay_goodput_median_shadowed_mbps,
        100.0 * report.direct_dead_fraction_shadowed
    );
    println!(
        "on the simulated mesh (queues, retries, one shared channel, no shadowing): direct {:.2} Mb/s, relayed {:.2} Mb/s, gain {:.1}x",
        report.simulated_direct_mbps, report.simulated_relay_mbps, report.simulated_relay_gain
    );
    Ok(())
}

/// `realms bench net-sim`: what the simulated network costs, in messages per wall second,
/// beside the simulated seconds per wall second.
pub fn net_sim(args: BenchNetSimArgs) -> Result<()> {
    let cfg = realms_net::NetworkConfig::default();
    println!("# realms bench net-sim");
    println!();
    println!(
        "{} simulated s per trial, {} trials, median; per rover: pose 10 Hz, status 1 Hz, 2 kB map update 1 Hz, 20 kB image 0.5 Hz, to the lander and the ground; {}",
        args.seconds,
        args.trials,
        crate::bench::machine()
    );
    println!();
    println!(
        "| rovers | messages | delivered | bytes on air | wall s | messages per wall s | simulated s per wall s |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for &n in &args.rovers {
        let mut walls = Vec::new();
        let mut last = FleetTraffic::default();
        for _ in 0..args.trials.max(1) {
            let t0 = Instant::now();
            last = fleet_traffic(&cfg, n, 50.0, args.seconds);
            walls.push(t0.elapsed().as_secs_f64());
        }
        let wall = crate::bench::median(walls);
        println!(
            "| {n} | {} | {} | {:.1} MB | {wall:.3} | {:.0} | {:.0} |",
            last.published,
            last.delivered,
            last.air_bytes as f64 / 1e6,
            last.published as f64 / wall,
            args.seconds as f64 / wall
        );
    }
    Ok(())
}
