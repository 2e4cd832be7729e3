//! The rover body: commanded velocities, limits, the dead-man, collisions, craters, and the
//! odometry and gyro error models against their configured statistics.

mod common;

use common::{drive, flat_world, idle_until, scenario};
use realms_core::msgs::Message;
use realms_core::{Duration, Point2, Pose2, RoverId, Time};
use realms_sim::SimEventKind;
use realms_sim::terrain::{Boulder, Crater, Rect};

const R1: RoverId = RoverId(1);

fn firm(mut s: realms_sim::Scenario) -> realms_sim::Scenario {
    s.rovers.odometry.slip_base = 0.0;
    s.rovers.odometry.slip_per_slope = 0.0;
    s.rovers.odometry.slip_loose = 0.0;
    s
}

#[test]
fn commanded_speed_is_reached_after_the_acceleration_ramp() {
    let s = firm(scenario(1));
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    drive(&mut world, R1, 0.3, 0.0, 10.0);
    let body = world.rovers().next().expect("rover");
    // v t - v^2 / (2 a): 3.0 - 0.09 = 2.91 m.
    let travelled = body.pose.x_m - 3.0;
    assert!((travelled - 2.91).abs() < 0.01, "{travelled}");
    assert!((body.pose.y_m - 10.0).abs() < 1e-9);
    assert!((body.wheel_speed_m_s - 0.3).abs() < 1e-9);
}

#[test]
fn speed_and_yaw_rate_are_limited() {
    let s = firm(scenario(1));
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    drive(&mut world, R1, 5.0, 0.0, 5.0);
    let body = world.rovers().next().expect("rover");
    assert!((body.wheel_speed_m_s - s.rovers.max_speed_m_s).abs() < 1e-9);
    let travelled = body.pose.x_m - 3.0;
    // 0.4 * 5 - 0.4^2 / (2 * 0.5) = 1.84 m.
    assert!((travelled - 1.84).abs() < 0.01, "{travelled}");

    let mut world = flat_world(&s, &[Pose2::new(10.0, 10.0, 0.0)], |_| {});
    drive(&mut world, R1, 0.0, 9.0, 1.5);
    let body = world.rovers().next().expect("rover");
    assert!((body.wheel_yaw_rate_rad_s - s.rovers.max_yaw_rate_rad_s).abs() < 1e-9);
    // Ramp 0.5 s to 1 rad/s (0.25 rad), then 1.0 s at 1 rad/s: 1.25 rad.
    assert!(
        (body.pose.yaw_rad - 1.25).abs() < 0.03,
        "{}",
        body.pose.yaw_rad
    );
}

#[test]
fn a_stale_command_stops_the_rover() {
    let s = firm(scenario(1));
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    drive(&mut world, R1, 0.3, 0.0, 0.1);
    idle_until(&mut world, Time::from_secs_f64(5.0));
    let body = world.rovers().next().expect("rover");
    assert_eq!(body.wheel_speed_m_s, 0.0);
    // Half a second of commands at most (0.6 s incl. the first), then braking.
    assert!(body.pose.x_m - 3.0 < 0.2, "{}", body.pose.x_m);
}

#[test]
fn a_wall_stops_the_rover_and_is_recorded_once() {
    let s = firm(scenario(1));
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |t| {
        t.add_wall(
            Rect {
                min: Point2::new(5.0, 0.0),
                max: Point2::new(5.5, 20.0),
            },
            1.0,
        );
    });
    drive(&mut world, R1, 0.4, 0.0, 15.0);
    let body = world.rovers().next().expect("rover");
    let front = body.pose.x_m + s.rovers.length_m / 2.0;
    assert!(front <= 5.0 && front > 4.95, "front bumper at {front}");
    assert_eq!(body.stats.collisions, 1);
    let collisions: Vec<_> = world
        .events()
        .iter()
        .filter(|e| e.kind == SimEventKind::Collision)
        .collect();
    assert_eq!(collisions.len(), 1);
    assert_eq!(collisions[0].rover, "rover1");
}

#[test]
fn driving_into_a_steep_crater_gets_the_rover_stuck() {
    let s = firm(scenario(1));
    let crater = Crater {
        center: Point2::new(8.0, 10.0),
        radius_m: 1.5,
        depth_m: 0.6,
        rim_m: 0.1,
    };
    let mut world = flat_world(&s, &[Pose2::new(4.0, 10.0, 0.0)], |t| t.add_crater(crater));
    drive(&mut world, R1, 0.3, 0.0, 20.0);
    let body = world.rovers().next().expect("rover");
    assert!(body.stuck);
    assert_eq!(body.stats.hazard_entries, 1);
    assert_eq!(body.stats.stuck_events, 1);
    let x_stuck = body.pose.x_m;
    assert!(x_stuck > 6.5 && x_stuck < 7.0, "stuck at {x_stuck}");
    drive(&mut world, R1, -0.3, 0.0, 5.0);
    let body = world.rovers().next().expect("rover");
    assert_eq!(body.pose.x_m, x_stuck, "a stuck rover does not move");
    let kinds: Vec<_> = world.events().iter().map(|e| e.kind).collect();
    assert_eq!(kinds, vec![SimEventKind::HazardEntry, SimEventKind::Stuck]);
}

/// A rover pushed against a rock it cannot climb stays level on the floor beside it (the
/// wheel beside the rock once took part of its height and tipped the rover 50 degrees); a rock
/// low enough to drive over still lifts the wheel on it.
#[test]
fn a_rock_too_tall_to_climb_stops_the_rover_without_tipping_it_and_a_low_one_lifts_a_wheel() {
    let s = firm(scenario(1));
    let tall = Boulder {
        // Off the rover's centre line, so one front corner meets it first.
        center: Point2::new(7.0, 10.25),
        radius_m: 0.5,
        height_m: 0.45,
    };
    let mut world = flat_world(&s, &[Pose2::new(4.0, 10.0, 0.0)], |t| t.add_boulder(tall));
    drive(&mut world, R1, 0.3, 0.0, 20.0);
    let body = world.rovers().next().expect("rover");
    assert_eq!(body.stats.collisions, 1, "stopped by the rock");
    assert!(body.pose.x_m < 6.8, "{}", body.pose.x_m);
    assert!(
        body.pitch_rad.abs() < 1e-6 && body.roll_rad.abs() < 1e-6,
        "pitch {} roll {}",
        body.pitch_rad.to_degrees(),
        body.roll_rad.to_degrees()
    );

    // A 6 cm rock (under the 8 cm step) in the left wheels' track: driven over, left side up
    // (positive roll) while they are on it.
    let low = Boulder {
        center: Point2::new(7.0, 10.0 + s.rovers.width_m / 2.0),
        radius_m: 0.3,
        height_m: 0.06,
    };
    let mut world = flat_world(&s, &[Pose2::new(4.0, 10.0, 0.0)], |t| t.add_boulder(low));
    let mut most_roll: f64 = 0.0;
    for _ in 0..30 {
        drive(&mut world, R1, 0.3, 0.0, 0.5);
        most_roll = most_roll.max(world.rovers().next().expect("rover").roll_rad);
    }
    let body = world.rovers().next().expect("rover");
    assert_eq!(body.stats.collisions, 0);
    assert!(body.pose.x_m > 8.0, "drove over it: {}", body.pose.x_m);
    // Both left wheels on its crest at best: atan(0.06 / width).
    let crest = 0.06f64.atan2(s.rovers.width_m);
    assert!(
        most_roll > 0.4 * crest && most_roll <= crest + 1e-6,
        "roll {} of at most {}",
        most_roll.to_degrees(),
        crest.to_degrees()
    );
}

#[test]
fn the_rover_pitches_on_a_slope() {
    let s = firm(scenario(1));
    let mut world = flat_world(&s, &[Pose2::new(4.0, 10.0, 0.0)], |t| {
        // A 10 % ramp up towards +x from x = 6 m.
        let g = *t.geometry();
        for (cell, h) in t.floor.clone().iter() {
            let x = g.cell_center(cell).x_m;
            let i = g.index(cell);
            let rise = ((x - 6.0).max(0.0) * 0.1).min(0.8) as f32;
            if t.kind.cells()[i] == realms_sim::terrain::SurfaceKind::Floor {
                t.floor.cells_mut()[i] = h + rise;
                t.heights.cells_mut()[i] = h + rise;
            }
        }
    });
    drive(&mut world, R1, 0.3, 0.0, 12.0);
    let body = world.rovers().next().expect("rover");
    assert!(body.pose.x_m > 7.0);
    // Nose up on an upward slope: negative pitch (REP 103), atan(0.1) = 5.7 degrees.
    assert!(
        (body.pitch_rad + 0.1f64.atan()).abs() < 0.01,
        "{}",
        body.pitch_rad
    );
    assert!(body.roll_rad.abs() < 1e-6);
}

/// Odometry over-reports distance by 1 / (1 - slip) with the configured per-step noise.
#[test]
fn odometry_error_follows_the_configured_model() {
    let mut ratios = Vec::new();
    for seed in 0..30 {
        let mut s = scenario(1);
        s.seed = seed;
        s.rovers.odometry.slip_per_slope = 0.0;
        let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |t| {
            t.looseness.cells_mut().fill(0.5);
        });
        drive(&mut world, R1, 0.3, 0.0, 30.0);
        let body = world.rovers().next().expect("rover");
        let truth = body.pose.x_m - 3.0;
        let odom = body.odom_pose.x_m - 3.0;
        ratios.push(odom / truth);
    }
    let o = &scenario(1).rovers.odometry;
    let expected = 1.0 / (1.0 - (o.slip_base + 0.5 * o.slip_loose));
    let n = ratios.len() as f64;
    let mean = ratios.iter().sum::<f64>() / n;
    let std = (ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    // Per-step relative noise sigma over ~1500 moving steps.
    let steps = 30.0 / scenario(1).rovers.physics_step_s;
    let expected_std = o.speed_noise_frac / steps.sqrt();
    assert!(
        (mean - expected).abs() < 4.0 * expected_std / n.sqrt() + 1e-3,
        "mean {mean} vs {expected}"
    );
    assert!(
        std > 0.6 * expected_std && std < 1.5 * expected_std,
        "std {std} vs {expected_std}"
    );
}

#[test]
fn gyro_reads_the_yaw_rate_plus_its_bias_and_noise() {
    let s = scenario(1);
    let mut world = flat_world(&s, &[Pose2::new(10.0, 10.0, 0.0)], |_| {});
    let out = idle_until(&mut world, Time::from_secs_f64(60.0));
    let bias = world.rovers().next().expect("rover").gyro_bias_rad_s;
    let rates: Vec<f64> = out
        .iter()
        .filter_map(|(_, m)| match m {
            Message::Imu(imu) => Some(imu.angular_velocity.z),
            _ => None,
        })
        .collect();
    let n = rates.len() as f64;
    assert!(n > 2900.0, "{n} gyro messages in 60 s at 50 Hz");
    let mean = rates.iter().sum::<f64>() / n;
    let std = (rates.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
    let sigma = s.rovers.imu.gyro_noise_rad_s;
    assert!(
        (mean - bias).abs() < 4.0 * sigma / n.sqrt(),
        "mean {mean} vs bias {bias}"
    );
    assert!((std - sigma).abs() < 0.1 * sigma, "std {std}");
}

/// `s` with a slip burst on rover1 from 5 to 10 s.
fn with_slip_burst_from_5_to_10_s(mut s: realms_sim::Scenario) -> realms_sim::Scenario {
    s.faults.push(realms_sim::scenario::Fault {
        kind: realms_sim::scenario::FaultKind::SlipBurst,
        rover: "rover1".into(),
        at_s: 5.0,
        duration_s: 5.0,
        sensor: None,
    });
    s
}

#[test]
fn a_slip_burst_makes_odometry_report_motion_that_did_not_happen() {
    let s = with_slip_burst_from_5_to_10_s(firm(scenario(1)));
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    drive(&mut world, R1, 0.3, 0.0, 15.0);
    let body = world.rovers().next().expect("rover");
    let truth = body.pose.x_m - 3.0;
    let odom = body.odom_pose.x_m - 3.0;
    // 5 s at 0.3 m/s with 90 % slip: the odometry is about 1.35 m ahead of the truth.
    assert!(
        (odom - truth - 1.35).abs() < 0.1,
        "odom {odom} truth {truth}"
    );
    let kinds: Vec<_> = world.events().iter().map(|e| e.kind).collect();
    assert_eq!(
        kinds,
        vec![SimEventKind::SlipBurstStart, SimEventKind::SlipBurstEnd]
    );
}

/// The accelerometer's readings along x and y of rover1 standing for 0.5 s, then driving at
/// 0.3 m/s (turning at `w_rad_s`) on flat, firm ground with a slip burst from 5 to 10 s, the
/// body's acceleration `felt` or not: `(stamp s, x, y)` for each sample.
fn accelerometer_through_a_slip_burst(felt: bool, w_rad_s: f64) -> Vec<(f64, f64, f64)> {
    let mut s = with_slip_burst_from_5_to_10_s(firm(scenario(1)));
    s.rovers.imu.body_acceleration = felt;
    let mut world = flat_world(&s, &[Pose2::new(10.0, 10.0, 0.0)], |_| {});
    // Standing for its first samples, it has a speed to compare the next ones with.
    let mut out = idle_until(&mut world, Time::from_secs_f64(0.5));
    out.extend(drive(&mut world, R1, 0.3, w_rad_s, 15.0));
    out.iter()
        .filter_map(|(_, m)| match m {
            Message::Imu(imu) => Some((
                imu.header.stamp.as_secs_f64(),
                imu.linear_acceleration.x,
                imu.linear_acceleration.y,
            )),
            _ => None,
        })
        .collect()
}

/// The speed the accelerometer's x readings add up to between `from_s` and `to_s`.
fn speed_change(samples: &[(f64, f64, f64)], from_s: f64, to_s: f64) -> f64 {
    samples
        .windows(2)
        .filter(|w| w[1].0 > from_s && w[1].0 <= to_s)
        .map(|w| w[1].1 * (w[1].0 - w[0].0))
        .sum()
}

#[test]
fn an_accelerometer_that_feels_the_body_sees_a_slip_burst_the_wheels_do_not() {
    let felt = accelerometer_through_a_slip_burst(true, 0.0);
    // Up to 0.3 m/s, down to a tenth of it as the burst begins, and back as it ends; the
    // wheels turn at 0.3 m/s throughout.
    // Each sample's noise adds 0.02 m/s^2 x 0.02 s = 0.4 mm/s (one standard deviation), so a
    // second's readings (50) add up to within about 3 mm/s of the speed's change.
    let start = speed_change(&felt, 0.4, 1.4);
    let burst = speed_change(&felt, 4.5, 5.5);
    let end = speed_change(&felt, 9.5, 10.5);
    assert!((start - 0.3).abs() < 0.01, "start {start}");
    assert!((burst + 0.27).abs() < 0.01, "burst {burst}");
    assert!((end - 0.27).abs() < 0.01, "end {end}");
    // Driving steadily it feels nothing but its noise.
    let steady = speed_change(&felt, 1.5, 4.5);
    assert!(steady.abs() < 0.02, "steady {steady}");
    // Not felt, the burst is not in the readings either.
    let unfelt = speed_change(&accelerometer_through_a_slip_burst(false, 0.0), 4.5, 5.5);
    assert!(unfelt.abs() < 0.01, "unfelt {unfelt}");
}

#[test]
fn an_accelerometer_that_feels_the_body_feels_a_turn_across_it() {
    // 0.3 m/s on a 0.5 rad/s arc: 0.15 m/s^2 towards the turn's centre, the rover's left.
    let across = |felt| {
        let samples = accelerometer_through_a_slip_burst(felt, 0.5);
        let steady: Vec<f64> = samples
            .iter()
            .filter(|(t, _, _)| (2.0..4.5).contains(t))
            .map(|(_, _, y)| *y)
            .collect();
        steady.iter().sum::<f64>() / steady.len() as f64
    };
    let (felt, unfelt) = (across(true), across(false));
    assert!((felt - 0.15).abs() < 0.01, "felt {felt}");
    assert!(unfelt.abs() < 0.01, "unfelt {unfelt}");
}

/// Rover1 driving an arc across the foot of a 10 % ramp (rising towards +x from x = 4.5 m),
/// so its roll, pitch and heading all change: the gravity its gyro carries from the level
/// start (each sample's rates over the time since the one before, the yaw rate less the
/// gyro's bias) and the gravity its tilt at the end gives, both as unit vectors in the body.
fn gravity_carried_by_the_gyro_across_a_ramp(tilt_rates: bool) -> ([f64; 3], [f64; 3]) {
    let mut s = firm(scenario(1));
    s.rovers.imu.tilt_rates = tilt_rates;
    let mut world = flat_world(&s, &[Pose2::new(4.0, 10.0, 0.0)], |t| {
        let g = *t.geometry();
        for (cell, h) in t.floor.clone().iter() {
            let x = g.cell_center(cell).x_m;
            let i = g.index(cell);
            let rise = ((x - 4.5).max(0.0) * 0.1) as f32;
            if t.kind.cells()[i] == realms_sim::terrain::SurfaceKind::Floor {
                t.floor.cells_mut()[i] = h + rise;
                t.heights.cells_mut()[i] = h + rise;
            }
        }
    });
    let out = drive(&mut world, R1, 0.3, 0.15, 12.0);
    let body = world.rovers().next().expect("rover");
    let bias = body.gyro_bias_rad_s;
    let mut gravity = [0.0, 0.0, 1.0];
    let mut last = None;
    for (_, m) in &out {
        let Message::Imu(imu) = m else { continue };
        let t = imu.header.stamp.as_secs_f64();
        if let Some(t0) = last.replace(t) {
            let dt = t - t0;
            let w = imu.angular_velocity;
            let (wx, wy, wz) = (w.x, w.y, w.z - bias);
            // Gravity is fixed in the world, so in the body it turns against the body's turn.
            let [gx, gy, gz] = gravity;
            let spin = [wy * gz - wz * gy, wz * gx - wx * gz, wx * gy - wy * gx];
            gravity = [gx - spin[0] * dt, gy - spin[1] * dt, gz - spin[2] * dt];
            let norm = gravity.iter().map(|g| g * g).sum::<f64>().sqrt();
            gravity = gravity.map(|g| g / norm);
        }
    }
    let (sp, cp) = body.pitch_rad.sin_cos();
    let (sr, cr) = body.roll_rad.sin_cos();
    (gravity, [-sp, cp * sr, cp * cr])
}

#[test]
fn a_gyro_that_measures_roll_and_pitch_rates_carries_the_tilt() {
    let angle_deg = |a: [f64; 3], b: [f64; 3]| {
        let dot: f64 = a.iter().zip(b).map(|(a, b)| a * b).sum();
        dot.clamp(-1.0, 1.0).acos().to_degrees()
    };
    let (carried, truth) = gravity_carried_by_the_gyro_across_a_ramp(true);
    let tilt = angle_deg(truth, [0.0, 0.0, 1.0]);
    // The arc ends on the ramp, tilted by most of its 5.7 degrees.
    assert!(tilt > 3.0, "tilt {tilt}");
    // 600 samples of 0.003 rad/s noise over 0.02 s each walk the carried gravity off by about
    // 0.08 degrees per axis (one standard deviation).
    assert!(angle_deg(carried, truth) < 0.3, "{carried:?} {truth:?}");
    // A yaw gyro alone carries none of the tilt.
    let (carried, truth) = gravity_carried_by_the_gyro_across_a_ramp(false);
    assert!(
        (angle_deg(carried, truth) - tilt).abs() < 0.3,
        "{carried:?} {truth:?}"
    );
}

#[test]
fn a_powered_off_rover_stops_and_falls_silent() {
    let mut s = firm(scenario(1));
    s.faults.push(realms_sim::scenario::Fault {
        kind: realms_sim::scenario::FaultKind::PowerOff,
        rover: "rover1".into(),
        at_s: 2.0,
        duration_s: 0.0,
        sensor: None,
    });
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    drive(&mut world, R1, 0.3, 0.0, 2.5);
    let x = world.rovers().next().expect("rover").pose.x_m;
    let out = drive(&mut world, R1, 0.3, 0.0, 5.0);
    assert!(out.is_empty(), "{} messages after power-off", out.len());
    assert_eq!(world.rovers().next().expect("rover").pose.x_m, x);
}

#[test]
fn commands_a_driver_cannot_execute_are_refused() {
    let s = firm(scenario(1));
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    idle_until(&mut world, Time::from_secs_f64(1.0));
    let cmd = |stamp_s: f64, v: f64| realms_core::msgs::TwistStamped {
        header: realms_core::msgs::Header {
            stamp: Time::from_secs_f64(stamp_s),
            frame_id: "rover1/base_link".into(),
        },
        twist: realms_core::msgs::Twist {
            linear: realms_core::geometry::Vec3::new(v, 0.0, 0.0),
            angular: realms_core::geometry::Vec3::default(),
        },
    };
    assert!(!world.command(R1, cmd(1.0, f64::NAN)), "NaN speed");
    assert!(
        !world.command(R1, cmd(1.0, f64::INFINITY)),
        "infinite speed"
    );
    assert!(!world.command(R1, cmd(99.0, 0.3)), "stamped in the future");
    assert!(!world.command(RoverId(7), cmd(1.0, 0.3)), "no such rover");
    assert!(world.command(R1, cmd(1.0, 0.3)));
    idle_until(&mut world, Time::from_secs_f64(1.2));
    let body = world.rovers().next().expect("rover");
    assert!(body.pose.x_m.is_finite() && body.pose.x_m > 3.0);
}

#[test]
fn every_sensor_message_is_stamped_with_the_time_of_the_state_it_shows() {
    stamped_with_the_time_of_the_state_they_show(false);
    stamped_with_the_time_of_the_state_they_show(true);
}

fn stamped_with_the_time_of_the_state_they_show(sweeps: bool) {
    // Two rovers driven alike, side by side, with exact encoders. Their sensors fire at
    // staggered instants, but each message is stamped with the physics step whose state it
    // shows, so at any stamp both have the same odometry. Stamped when they fire, rover2's
    // readings would carry stamps 3 ms late and none would meet rover1's.
    let mut s = firm(scenario(2));
    s.rovers.lidar.sweeps = sweeps;
    s.rovers.odometry.speed_noise_frac = 0.0;
    s.rovers.odometry.yaw_scale_error_std = 0.0;
    let starts = [Pose2::new(3.0, 5.0, 0.0), Pose2::new(3.0, 12.0, 0.0)];
    let mut world = flat_world(&s, &starts, |_| {});
    let mut out = Vec::new();
    for k in 1..=30 {
        let t = Time::from_secs_f64(0.1 * k as f64);
        for id in [R1, RoverId(2)] {
            world.command(
                id,
                realms_core::msgs::TwistStamped {
                    header: realms_core::msgs::Header {
                        stamp: world.now(),
                        frame_id: format!("{id}/base_link"),
                    },
                    twist: realms_core::msgs::Twist {
                        linear: realms_core::geometry::Vec3::new(0.3, 0.0, 0.0),
                        angular: realms_core::geometry::Vec3::new(0.0, 0.0, 0.2),
                    },
                },
            );
        }
        world.advance_to(t, &mut out);
    }
    let step = Duration::from_secs_f64(s.rovers.physics_step_s);
    let mut travelled: [std::collections::BTreeMap<Time, Pose2>; 2] = Default::default();
    for (topic, message) in &out {
        // A sweeping scan is stamped with its first beam, a sweep before its last: the last
        // shows the state of the step it is published at.
        let stamp = match message {
            Message::LaserScan(scan) => {
                assert_eq!(scan.last_beam_time() - scan.header.stamp, scan.sweep());
                assert_eq!(scan.sweep() > Duration::ZERO, sweeps);
                scan.last_beam_time()
            }
            other => other.stamp(),
        };
        assert_eq!(
            stamp.0 % step.0,
            0,
            "{topic} at {stamp:?}: not a physics step"
        );
        if let Message::Odometry(o) = message {
            let rover = topic.rover().expect("a rover's topic").0 as usize - 1;
            let p = &o.pose.pose;
            let start = starts[rover];
            let moved = Pose2::new(p.position.x - start.x_m, p.position.y - start.y_m, 0.0);
            travelled[rover].insert(stamp, moved);
        }
    }
    let mut met = 0;
    for (stamp, a) in &travelled[0] {
        if let Some(b) = travelled[1].get(stamp) {
            met += 1;
            assert!(
                (a.x_m - b.x_m).abs() < 1e-9 && (a.y_m - b.y_m).abs() < 1e-9,
                "{stamp:?}: {a:?} against {b:?}"
            );
        }
    }
    assert!(met >= 20, "{met} shared stamps");
}
