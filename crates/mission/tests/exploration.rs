//! Autonomous exploration and goal-driven navigation in simulated missions, graded against
//! the simulator's truth: coverage of the explorable area, collisions, hazard entries, where
//! the rovers end up, and whether two rovers split the work.

use realms_core::msgs::{Header, Message, NavActivity, NavGoal, NavStatus};
use realms_core::{Point2, Pose2, RoverId, Time};
use realms_mission::{Mission, MissionOptions};
use realms_sim::terrain::Boulder;
use realms_sim::{Scenario, Terrain, World};
use std::path::Path;

fn small() -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/small.toml");
    let mut s = Scenario::load(&path).expect("small scenario loads");
    s.faults.clear();
    s
}

/// Runs until every rover is home and done, or `limit_s`.
fn run_to_completion(mission: &mut Mission, limit_s: f64) {
    while mission.now().as_secs_f64() < limit_s && !mission.exploration_over() {
        let next = mission.now() + realms_core::Duration::from_secs(10);
        mission.run_until(next);
    }
    mission.finish();
}

/// The target a rover was exploring towards at `t`, from its status messages.
fn exploring_target_at(log: &[(Time, NavStatus)], t: Time) -> Option<Point2> {
    let (_, status) = log.iter().rev().find(|(at, _)| *at <= t)?;
    (status.activity == NavActivity::Exploring)
        .then_some(status.target)
        .flatten()
}

#[test]
fn two_rovers_explore_a_small_arena_fully_split_the_work_and_return_home() {
    let s = small();
    let mut mission = Mission::new(&s);
    let starts: Vec<Pose2> = mission.world().rovers().map(|b| b.pose).collect();
    run_to_completion(&mut mission, 1800.0);
    let t_end = mission.now().as_secs_f64();
    assert!(
        mission.exploration_over(),
        "still exploring after {t_end:.0} s"
    );
    let coverage = mission.coverage().fraction();
    assert!(coverage >= 0.95, "coverage {coverage:.3}");
    for (body, start) in mission.world().rovers().zip(&starts) {
        assert_eq!(body.stats.collisions, 0, "{} collided", body.id);
        assert_eq!(body.stats.hazard_entries, 0, "{} entered a hazard", body.id);
        let home = body.pose.position().distance_m(start.position());
        assert!(home < 1.0, "{} ended {home:.2} m from its start", body.id);
    }
    // Whenever both were exploring, they were heading for different places.
    let log = mission.nav_log();
    let (mut both, mut same) = (0, 0);
    for k in 0..t_end as i64 {
        let t = Time::from_secs_f64(k as f64);
        if let (Some(a), Some(b)) = (
            exploring_target_at(&log[0], t),
            exploring_target_at(&log[1], t),
        ) {
            both += 1;
            if a.distance_m(b) < 1.0 {
                same += 1;
            }
        }
    }
    assert!(both >= 5, "both explored together for only {both} s");
    assert!(
        same * 20 <= both,
        "same target for {same} of {both} s of joint exploration"
    );
}

#[test]
fn rovers_that_hear_nothing_from_each_other_still_explore_it_all() {
    let s = small();
    let options = MissionOptions {
        rovers_hear_each_other: false,
        ideal_comms: true,
        ..MissionOptions::default()
    };
    let mut mission = Mission::with_options(World::new(&s), options);
    run_to_completion(&mut mission, 1800.0);
    assert!(mission.exploration_over(), "still exploring");
    let coverage = mission.coverage().fraction();
    assert!(coverage >= 0.95, "coverage {coverage:.3}");
    // Each mapped the arena alone: each map knows nearly all of it.
    let truth = mission.world().truth().clone();
    for record in mission.slam_records() {
        let grade = record.summary(&truth, None).map.expect("a map");
        assert!(grade.explorable_known >= 0.9, "{grade:?}");
    }
    for body in mission.world().rovers() {
        assert_eq!(body.stats.collisions, 0, "{} collided", body.id);
        assert_eq!(body.stats.hazard_entries, 0, "{} entered a hazard", body.id);
    }
}

/// A 16 x 10 m walled floor with a field of rocks (too tall to drive over) between the
/// rover at its west end and the east end: three staggered columns, 1.5 m between rocks.
fn boulder_field() -> World {
    let mut s = Scenario::default();
    s.rovers.count = 1;
    s.faults.clear();
    let mut t = Terrain::flat(16.0, 10.0, 0.05);
    t.add_perimeter_walls(0.2, 1.0);
    for (i, x) in [6.0, 7.6, 9.2].into_iter().enumerate() {
        for k in 0..4 {
            // Alternate columns are offset so there is no straight way through.
            let y = 1.5 + 2.2 * k as f64 + if i % 2 == 1 { 1.1 } else { 0.0 };
            t.add_boulder(Boulder {
                center: Point2::new(x, y),
                radius_m: 0.35,
                height_m: 0.5,
            });
        }
    }
    t.rover_starts = vec![Pose2::new(2.0, 5.0, 0.0)];
    World::with_terrain(&s, t)
}

fn send_goal(mission: &mut Mission, target: Option<Point2>) {
    let now = mission.now();
    mission.publish(
        RoverId(1).topic("nav/goal"),
        Message::NavGoal(NavGoal {
            header: Header {
                stamp: now,
                frame_id: "rover1/map".into(),
            },
            target,
        }),
    );
}

#[test]
fn a_goal_behind_a_boulder_field_is_reached_without_touching_a_rock() {
    let mut mission = Mission::with_world(boulder_field());
    mission.run_until(Time::from_secs_f64(6.0));
    let goal = Point2::new(13.0, 5.0);
    send_goal(&mut mission, Some(goal));
    let mut reached_at = None;
    while mission.now() < Time::from_secs_f64(300.0) && reached_at.is_none() {
        let next = mission.now() + realms_core::Duration::from_secs(1);
        mission.run_until(next);
        let log = &mission.nav_log()[0];
        if log
            .iter()
            .any(|(_, s)| s.reason.starts_with("reached Operator"))
        {
            reached_at = Some(mission.world().rovers().next().expect("one rover").pose);
        }
    }
    let pose = reached_at.expect("the goal was reached within 300 s");
    let miss = pose.position().distance_m(goal);
    assert!(miss < 0.5, "stopped {miss:.2} m from the goal");
    let body = mission.world().rovers().next().expect("one rover");
    assert_eq!(body.stats.collisions, 0);
}

#[test]
fn a_goal_inside_a_rock_is_refused_once_and_not_retried() {
    let options = MissionOptions {
        // The test is timed from the rovers' start: a short gyro calibration.
        gyro_calibration: realms_core::Duration::from_secs(5),
        ..MissionOptions::default()
    };
    let mut mission = Mission::with_options(boulder_field(), options);
    // Let the rover see the field first, so the rock is on its map.
    mission.run_until(Time::from_secs_f64(8.0));
    send_goal(&mut mission, Some(Point2::new(6.0, 1.3)));
    mission.run_until(Time::from_secs_f64(60.0));
    let log = &mission.nav_log()[0];
    let refusals: Vec<&NavStatus> = log
        .iter()
        .map(|(_, s)| s)
        .filter(|s| s.reason.starts_with("gave up Operator"))
        .collect();
    assert_eq!(refusals.len(), 1, "{log:?}");
    assert!(
        refusals[0].reason.contains("blocked"),
        "{}",
        refusals[0].reason
    );
    // It said so within seconds and went back to exploring, not to the goal.
    let (t_refused, _) = log
        .iter()
        .find(|(_, s)| s.reason.starts_with("gave up Operator"))
        .expect("found above");
    assert!(t_refused.as_secs_f64() < 12.0, "refused at {t_refused:?}");
    let retried = log
        .iter()
        .filter(|(t, s)| t > t_refused && s.activity == NavActivity::OperatorGoal)
        .count();
    assert_eq!(retried, 0);
}
