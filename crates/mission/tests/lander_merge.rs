//! The lander merging the maps the rovers really built: five minutes into the default
//! mission (seed 2), rover 3's map shares three quarters of its ground with rover 2's.
//! Both carry their own SLAM drift, and hazards only where each rover's depth camera
//! looked; the lander must still confirm rover 3 near its known start.

use realms_core::{Pose2, RoverId, Time};
use realms_merge::{Params, Prepared, PriorWindow, estimate_with_prior};
use realms_mission::{Mission, MissionOptions};
use realms_net::NodeAddr;
use realms_node::lander_merge::{merge_from_known_start, to_merge_map};
use realms_sim::{Scenario, World};

#[test]
fn the_lander_confirms_a_rover_whose_map_overlaps_the_reference() {
    let scenario = Scenario {
        seed: 2,
        ..Scenario::default()
    };
    let mut mission = Mission::with_options(World::new(&scenario), MissionOptions::default());
    mission.run_until(Time::from_secs_f64(300.0));
    let lander = mission.station(NodeAddr::Lander).expect("a lander");
    let (two, three) = (
        lander
            .map(RoverId(2))
            .expect("rover 2's map reached the lander"),
        lander
            .map(RoverId(3))
            .expect("rover 3's map reached the lander"),
    );
    let merged =
        merge_from_known_start(&[(RoverId(2), two), (RoverId(3), three)]).expect("two maps");
    let link = &merged.links[0];
    assert!(link.confirmed, "{link:?}");
    // Both maps started in the arena's frame: the lander finds them within their drift of
    // it, and keeps the known start.
    assert!(!link.drifted, "{link:?}");
    assert_eq!(link.reference_from_map, Some(Pose2::IDENTITY), "{link:?}");
    // Asked for the precision of maps cut from one survey, the estimate itself is refused:
    // the surfaces fit as closely 0.2 m away, where the two rovers' drifts disagree. Both
    // fits lie within the drift tolerances, so they still confirm the known start.
    let check_with = |params: &Params| {
        let prepare = |g: &realms_core::Grid<i8>| Prepared::new(&to_merge_map(g), params);
        estimate_with_prior(
            &prepare(two),
            &prepare(three),
            Pose2::IDENTITY,
            &PriorWindow::default(),
            params,
        )
    };
    let check = check_with(&Params::default());
    assert!(
        check
            .estimate
            .refusal
            .as_deref()
            .is_some_and(|r| r.starts_with("imprecise")),
        "{:?}",
        check.estimate
    );
    assert!(
        check.confirmed && check.placed == Some(Pose2::IDENTITY),
        "{check:?}"
    );
    // With the settings for rovers' maps the estimate is accepted as it is.
    let check = check_with(&Params::for_rover_maps());
    assert!(check.estimate.accepted().is_some(), "{:?}", check.estimate);
}
