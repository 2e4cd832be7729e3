//! Is the pose estimate still trustworthy? The fielded system this project re-builds lost its
//! odometry without noticing, and the operator found out from a smeared map. This monitor
//! watches every tracked scan and says, in a state the rover publishes, when
//!
//! - the wheel odometry disagrees with scan matching over the last couple of seconds (the
//!   wheels slip or an encoder fails; optionally also over several, for a rover creeping
//!   too slowly to slip far in two): SLAM says so and goes on matching its scans, still
//!   predicted from the wheels, but no longer learns the wheels' slip from them; the
//!   monitor also says how far the pose ran beyond the matches it heard
//!   ([`HealthMonitor::overrun`]), which the mapper may take back;
//! - the wheels turn while the gyro says the body barely does (optional, where the odometry
//!   says what the wheels' own heading did): skid-steer wheels that spin without grip turn
//!   the odometry's heading as freely as its position, but not the body's, and the gyro is
//!   blind to neither the lidar's bare walls nor an open hall. This is Borenstein and Feng's
//!   gyrodometry (ICRA 1996): where the wheels' and the gyro's rates part, the wheels are
//!   not to be trusted;
//! - scan matching itself stops fitting the map (too few points, a poor match score, or a
//!   gap in the scans long enough that odometry alone cannot bridge it): the rover is lost,
//!   the map is frozen so nothing wrong is written into it, and the mapper relocalises.
//!
//! It is plain bookkeeping over numbers the mapper already has; the decisions about the map
//! are the mapper's.

use realms_core::Pose2;

/// Matches the wheels moved less than this from the previous one (turning in place,
/// creeping) say nothing about slip along the track, metres.
const MIN_STEP_M: f64 = 0.005;

pub use realms_core::msgs::LocalisationState;

/// Thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthConfig {
    /// Odometry is compared with scan matching over this much time, seconds ...
    pub window_s: f64,
    /// ... and over this much (`None`: not): a rover creeping through a burst at a few
    /// centimetres a second slips less than the floor within the short window.
    pub slow_window_s: Option<f64>,
    /// Odometry is unreliable when scan matching falls short of the wheels' travel by more
    /// than this (metres) ...
    pub slip_min_m: f64,
    /// ... and by more than this fraction of the wheels' travel.
    pub slip_fraction: f64,
    /// ... for at least this long without a break, seconds.
    pub confirm_s: f64,
    /// Odometry counts as reliable again after agreeing for this long, seconds.
    pub recover_after_s: f64,
    /// A match scoring below this is a poor match.
    pub poor_score: f64,
    /// Lost after this many poor matches in a row.
    pub poor_matches_to_lose: usize,
    /// Lost when the scans stop for longer than this, seconds.
    pub max_scan_gap_s: f64,
    /// The wheels' turn against the gyro's over the same window (`None`: not compared).
    pub turn_check: Option<TurnCheck>,
}

/// When the wheels' turn and the gyro's disagree: over the window, the wheels turned at
/// least `min_wheels_rad` (each scan's turn counted whichever way) and the gyro turned the
/// same way by less than `max_gyro_share` of that. Skid steering loses some of every turn to
/// the ground (the rovers' wheels over-report a turn by up to a third on slopes and loose
/// ground); wheels with no grip lose nearly all of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TurnCheck {
    /// Radians.
    pub min_wheels_rad: f64,
    /// Of the wheels' turn.
    pub max_gyro_share: f64,
}

impl Default for TurnCheck {
    fn default() -> Self {
        TurnCheck {
            min_wheels_rad: 5f64.to_radians(),
            max_gyro_share: 0.5,
        }
    }
}

impl Default for HealthConfig {
    fn default() -> Self {
        HealthConfig {
            window_s: 2.0,
            // Tried at 6 s, counted from the last all-clear (before the slip check heard
            // the matches without the matcher's pull): it reported 566 of 606 slip bursts
            // where the short window alone reported 567 (BENCHMARKS.md, "The slip check
            // without the matcher's pull towards the wheels").
            slow_window_s: None,
            slip_min_m: 0.1,
            slip_fraction: 0.5,
            confirm_s: 0.3,
            recover_after_s: 3.0,
            poor_score: 0.35,
            poor_matches_to_lose: 5,
            max_scan_gap_s: 10.0,
            turn_check: None,
        }
    }
}

/// One tracked scan, as the monitor sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedScan {
    /// When, seconds.
    pub time_s: f64,
    /// Motion since the previous scan by wheel odometry.
    pub odom_delta: Pose2,
    /// Motion since the previous scan by scan matching.
    pub matched_delta: Pose2,
    /// Motion since the previous scan of the pose tracking kept (which a pull towards the
    /// wheels may have carried beyond the match).
    pub tracked_delta: Pose2,
    /// The match score (mean occupancy at the endpoints), or `None` if the scan was not
    /// matched (too few points, or no map yet).
    pub score: Option<f64>,
    /// The wheels have stopped reporting (a dropout): `odom_delta` is the gyro's turn alone.
    pub wheels_silent: bool,
    /// The turn since the previous scan by the wheels' own heading and by the gyro's,
    /// radians, where the odometry says both (`None`: the odometry's heading is the wheels'
    /// alone, or the wheels are silent).
    pub turns_rad: Option<(f64, f64)>,
}

/// A change of state, with the reason in words (for the operator).
#[derive(Clone, Debug, PartialEq)]
pub struct Transition {
    /// The new state.
    pub state: LocalisationState,
    /// Why.
    pub reason: String,
}

/// What one matched scan says about the wheels.
#[derive(Clone, Copy, Debug)]
struct MatchedStep {
    time_s: f64,
    /// The wheels' travel since the previous matched scan, metres.
    wheels_m: f64,
    /// How far the match fell short of it along the wheels' direction (capped), metres.
    shortfall_m: f64,
    /// How far the tracked pose went beyond the match along the wheels' direction, as a
    /// vector in the robot's frame, metres.
    overrun: (f64, f64),
}

/// How the wheels and the other sensors part, over a window.
#[derive(Clone, Copy, Debug)]
enum Disagreement {
    /// Scan matching saw `matched_m` of the wheels' `wheels_m` over `window_s`, the slow
    /// window's or the short one's.
    Travel {
        window_s: f64,
        is_slow: bool,
        wheels_m: f64,
        matched_m: f64,
    },
    /// The gyro turned `gyro_rad` the wheels' way while they turned `wheels_rad`, over
    /// `window_s`.
    Turn {
        window_s: f64,
        wheels_rad: f64,
        gyro_rad: f64,
    },
}

impl Disagreement {
    /// What the operator is told.
    fn reason(&self) -> String {
        match *self {
            Disagreement::Travel {
                window_s,
                wheels_m,
                matched_m,
                ..
            } => format!(
                "over the last {window_s:.0} s the wheels drove {wheels_m:.2} m but scan \
                 matching saw {matched_m:.2} m"
            ),
            Disagreement::Turn {
                window_s,
                wheels_rad,
                gyro_rad,
            } => format!(
                "over the last {window_s:.0} s the wheels turned {:.0} deg but the gyro {:.0} deg",
                wheels_rad.to_degrees(),
                gyro_rad.to_degrees()
            ),
        }
    }
}

/// The monitor.
#[derive(Clone, Debug)]
pub struct HealthMonitor {
    cfg: HealthConfig,
    state: LocalisationState,
    /// The matched scans within the window.
    recent: std::collections::VecDeque<MatchedStep>,
    /// Each scan's turn within the window: (when, the wheels' turn whichever way, the gyro's
    /// turn the same way as the wheels'), seconds and radians.
    turns: std::collections::VecDeque<(f64, f64, f64)>,
    /// Motion by odometry, as matched and as tracked since the last matched scan (scans the
    /// motion filter skipped are not matched: they follow odometry, and the next match
    /// corrects them all).
    unmatched: (Pose2, Pose2, Pose2),
    poor_in_a_row: usize,
    agreeing_since_s: Option<f64>,
    disagreeing_since_s: Option<f64>,
    /// The odometry was called unreliable on the slow window alone: its all-clear waits for
    /// that window too. Called so on the short window, the all-clear waits for the short
    /// one only, as it did before there was a slow one.
    slow_alarm: bool,
    /// The slow window counts only matches after this time, seconds: the last all-clear. A
    /// burst the short window already reported and cleared would otherwise stay in the slow
    /// window and raise the alarm again, where the rover travelled little since it.
    slow_from_s: f64,
    last_time_s: Option<f64>,
    /// Since when the wheels have been silent.
    wheels_silent_since_s: Option<f64>,
}

impl HealthMonitor {
    /// A monitor that starts out tracking.
    pub fn new(cfg: HealthConfig) -> Self {
        HealthMonitor {
            cfg,
            state: LocalisationState::Tracking,
            recent: std::collections::VecDeque::new(),
            turns: std::collections::VecDeque::new(),
            unmatched: (Pose2::IDENTITY, Pose2::IDENTITY, Pose2::IDENTITY),
            poor_in_a_row: 0,
            wheels_silent_since_s: None,
            agreeing_since_s: None,
            disagreeing_since_s: None,
            slow_alarm: false,
            slow_from_s: f64::NEG_INFINITY,
            last_time_s: None,
        }
    }

    /// The current state.
    pub fn state(&self) -> LocalisationState {
        self.state
    }

    /// The wheels and the matches disagree over the last window (a disagreement not yet
    /// confirmed, or one that raised the alarm and still lasts).
    pub fn disagrees(&self) -> bool {
        self.disagreeing_since_s.is_some()
    }

    /// How far the tracked pose went beyond the matches along the wheels' travel over the
    /// last window, in the robot's frame (each step's share in its own frame; the frames
    /// of a couple of seconds' travel differ by a few degrees at most), metres. What the
    /// mapper takes back when the alarm is raised: the matches that raised it were pulled
    /// along by the wheels first.
    pub fn overrun(&self) -> (f64, f64) {
        let from_s = self.last_time_s.unwrap_or(0.0) - self.cfg.window_s;
        self.recent
            .iter()
            .filter(|m| m.time_s >= from_s)
            .fold((0.0, 0.0), |(x, y), m| (x + m.overrun.0, y + m.overrun.1))
    }

    fn go(&mut self, state: LocalisationState, reason: String) -> Option<Transition> {
        (self.state != state).then(|| {
            self.state = state;
            if state == LocalisationState::Tracking {
                self.slow_alarm = false;
                self.slow_from_s = self.last_time_s.unwrap_or(f64::NEG_INFINITY);
            }
            if state == LocalisationState::Lost {
                // No scan is observed while lost: turns from before would linger.
                self.turns.clear();
            }
            Transition { state, reason }
        })
    }

    /// The mapper relocalised on the scan at `time_s`: tracking again, with a fresh history.
    /// The mapper shows the monitor no scans while lost, so the next scan's gap counts from
    /// here, not from the last scan before the rover was lost.
    pub fn relocalised(&mut self, time_s: f64, reason: String) -> Option<Transition> {
        self.last_time_s = Some(time_s);
        self.recent.clear();
        self.turns.clear();
        self.unmatched = (Pose2::IDENTITY, Pose2::IDENTITY, Pose2::IDENTITY);
        self.poor_in_a_row = 0;
        self.agreeing_since_s = None;
        self.wheels_silent_since_s = None;
        self.go(LocalisationState::Tracking, reason)
    }

    /// While the wheels' turns and the gyro's disagree over the window ending at `time_s`
    /// (a scan's time, not yet observed), the share of the wheels' turn the gyro saw (0 to
    /// 1): how much of their travel the wheels still carry, if they lose as much of it as
    /// of their turn. `None` while lost, and where the window holds no turns (after a gap
    /// or a dropout, the turns before it are out of the window).
    pub fn turn_share(&self, time_s: f64) -> Option<f64> {
        if self.state == LocalisationState::Lost {
            return None;
        }
        let (wheels_rad, gyro_rad) = self.disagreeing_turns(time_s - self.cfg.window_s)?;
        Some((gyro_rad / wheels_rad).clamp(0.0, 1.0))
    }

    /// The wheels' turn and the gyro's (the wheels' way) over the scans from `from_s` on,
    /// radians, if they disagree.
    fn disagreeing_turns(&self, from_s: f64) -> Option<(f64, f64)> {
        let check = self.cfg.turn_check?;
        let (wheels_rad, gyro_rad) = self
            .turns
            .iter()
            .filter(|(t, _, _)| *t >= from_s)
            .fold((0.0, 0.0), |(w, g), (_, dw, dg)| (w + dw, g + dg));
        (wheels_rad > 0.0
            && wheels_rad >= check.min_wheels_rad
            && gyro_rad < check.max_gyro_share * wheels_rad)
            .then_some((wheels_rad, gyro_rad))
    }

    /// Takes one scan; returns the change of state it causes, if any.
    pub fn observe(&mut self, scan: &TrackedScan) -> Option<Transition> {
        let gap = self.last_time_s.map(|t| scan.time_s - t);
        self.last_time_s = Some(scan.time_s);
        if self.state == LocalisationState::Lost {
            // Only relocalisation leaves this state.
            return None;
        }
        if let Some(gap) = gap
            && gap > self.cfg.max_scan_gap_s
        {
            return self.go(
                LocalisationState::Lost,
                format!("no lidar scan for {gap:.1} s"),
            );
        }
        match scan.score {
            Some(s) if s < self.cfg.poor_score => self.poor_in_a_row += 1,
            Some(_) => self.poor_in_a_row = 0,
            None => {}
        }
        if self.poor_in_a_row >= self.cfg.poor_matches_to_lose {
            return self.go(
                LocalisationState::Lost,
                format!(
                    "{} scans in a row fit the map poorly (score below {:.2})",
                    self.poor_in_a_row, self.cfg.poor_score
                ),
            );
        }
        if scan.wheels_silent {
            // Wheels that report nothing are lost odometry too: said once it has lasted a
            // moment, and never all clear while it lasts.
            self.agreeing_since_s = None;
            self.turns.clear();
            let since = *self.wheels_silent_since_s.get_or_insert(scan.time_s);
            if scan.time_s - since >= self.cfg.confirm_s {
                return self.go(
                    LocalisationState::OdometryUnreliable,
                    format!(
                        "no wheel odometry for {:.1} s: tracking on the scans and the gyro",
                        scan.time_s - since
                    ),
                );
            }
            return None;
        }
        self.wheels_silent_since_s = None;
        if let Some((wheels, gyro)) = scan.turns_rad {
            // Wheels that did not turn say nothing of which way the gyro should have (and
            // `signum` would call it a left turn).
            let gyro_their_way = if wheels == 0.0 {
                0.0
            } else {
                gyro * wheels.signum()
            };
            self.turns
                .push_back((scan.time_s, wheels.abs(), gyro_their_way));
        }
        while self
            .turns
            .front()
            .is_some_and(|(t, _, _)| *t < scan.time_s - self.cfg.window_s)
        {
            self.turns.pop_front();
        }
        // Slipping wheels report travel the scans do not see, on every match while it lasts;
        // a match that jumps (onto a new submap, or onto one a loop closure has moved) does
        // so once. Each match's shortfall along the wheels' direction is therefore capped at
        // the wheels' travel since the previous match, and at half the alarm's floor (a match
        // after a long unmatched stretch), so no single match can make the window disagree.
        self.unmatched.0 = self.unmatched.0 * scan.odom_delta;
        self.unmatched.1 = self.unmatched.1 * scan.matched_delta;
        self.unmatched.2 = self.unmatched.2 * scan.tracked_delta;
        if scan.score.is_some() {
            let (wheels, matched, tracked) = (
                self.unmatched.0.position(),
                self.unmatched.1.position(),
                self.unmatched.2.position(),
            );
            self.unmatched = (Pose2::IDENTITY, Pose2::IDENTITY, Pose2::IDENTITY);
            let step_m = wheels.x_m.hypot(wheels.y_m);
            let (shortfall_m, overrun) = if step_m > MIN_STEP_M {
                let (ux, uy) = (wheels.x_m / step_m, wheels.y_m / step_m);
                let along = matched.x_m * ux + matched.y_m * uy;
                let cap = step_m.min(self.cfg.slip_min_m / 2.0);
                let shortfall_m = (step_m - along).clamp(-cap, cap);
                // Measured against the match as the check counts it, so one match's jump
                // moves the pose back no further than it counts towards the alarm; a pose
                // behind the match was not carried by the wheels.
                let beyond_m =
                    (tracked.x_m * ux + tracked.y_m * uy - (step_m - shortfall_m)).max(0.0);
                (shortfall_m, (beyond_m * ux, beyond_m * uy))
            } else {
                (0.0, (0.0, 0.0))
            };
            self.recent.push_back(MatchedStep {
                time_s: scan.time_s,
                wheels_m: step_m,
                shortfall_m,
                overrun,
            });
        }
        let kept_s = self
            .cfg
            .slow_window_s
            .map_or(self.cfg.window_s, |w| w.max(self.cfg.window_s));
        while self
            .recent
            .front()
            .is_some_and(|m| m.time_s < scan.time_s - kept_s)
        {
            self.recent.pop_front();
        }
        let slow_counts = self.state == LocalisationState::Tracking || self.slow_alarm;
        // (window, counted from, whether it is the slow one)
        let short = (self.cfg.window_s, scan.time_s - self.cfg.window_s, false);
        let slow = self
            .cfg
            .slow_window_s
            .filter(|_| slow_counts)
            .map(|w| (w, (scan.time_s - w).max(self.slow_from_s), true));
        // The gyro first: it is heard apart from the scans, whose matches may have started
        // from a prediction the gyro's share of the turns already scaled.
        let disagreement = self
            .disagreeing_turns(short.1)
            .map(|(wheels_rad, gyro_rad)| Disagreement::Turn {
                window_s: self.cfg.window_s,
                wheels_rad,
                gyro_rad,
            })
            .or_else(|| {
                std::iter::once(short)
                    .chain(slow)
                    .find_map(|(window_s, from_s, is_slow)| {
                        let (odom_m, short_m) = self
                            .recent
                            .iter()
                            .filter(|m| m.time_s >= from_s)
                            .fold((0.0, 0.0), |(a, b), m| (a + m.wheels_m, b + m.shortfall_m));
                        (short_m > self.cfg.slip_min_m && short_m > self.cfg.slip_fraction * odom_m)
                            .then_some(Disagreement::Travel {
                                window_s,
                                is_slow,
                                wheels_m: odom_m,
                                matched_m: odom_m - short_m,
                            })
                    })
            });
        if disagreement.is_none() {
            self.disagreeing_since_s = None;
        }
        // A disagreement must last a moment: single bumps and skids in turns are not slip.
        if let Some(disagreement) = disagreement
            && scan.time_s - *self.disagreeing_since_s.get_or_insert(scan.time_s)
                >= self.cfg.confirm_s
        {
            self.agreeing_since_s = None;
            if self.state == LocalisationState::Tracking {
                self.slow_alarm =
                    matches!(disagreement, Disagreement::Travel { is_slow: true, .. });
            }
            return self.go(LocalisationState::OdometryUnreliable, disagreement.reason());
        }
        if self.state == LocalisationState::OdometryUnreliable {
            let since = *self.agreeing_since_s.get_or_insert(scan.time_s);
            if scan.time_s - since >= self.cfg.recover_after_s {
                return self.go(
                    LocalisationState::Tracking,
                    format!(
                        "wheel odometry agrees with scan matching{} again for {:.0} s",
                        if self.cfg.turn_check.is_some() {
                            " and the gyro"
                        } else {
                            ""
                        },
                        self.cfg.recover_after_s
                    ),
                );
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(t: f64, odom_m: f64, matched_m: f64, score: f64) -> TrackedScan {
        TrackedScan {
            time_s: t,
            odom_delta: Pose2::new(odom_m, 0.0, 0.0),
            matched_delta: Pose2::new(matched_m, 0.0, 0.0),
            tracked_delta: Pose2::new(matched_m, 0.0, 0.0),
            score: Some(score),
            wheels_silent: false,
            turns_rad: None,
        }
    }

    #[test]
    fn wheels_that_fall_silent_are_reported_until_they_report_again() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        let mut states = Vec::new();
        // Driving at 0.3 m/s; the wheels are silent from 10 to 16 s while the scans follow.
        for k in 0..250 {
            let t = k as f64 * 0.1;
            let silent = (10.0..16.0).contains(&t);
            let observed = TrackedScan {
                wheels_silent: silent,
                ..scan(t, if silent { 0.0 } else { 0.03 }, 0.03, 0.8)
            };
            if let Some(tr) = m.observe(&observed) {
                states.push((t, tr.state, tr.reason));
            }
        }
        assert_eq!(states.len(), 2, "{states:?}");
        let (t_silent, s, why) = &states[0];
        assert_eq!(*s, LocalisationState::OdometryUnreliable);
        assert!((10.0..11.0).contains(t_silent), "noticed at {t_silent}");
        assert!(why.contains("no wheel odometry"), "{why}");
        let (t_ok, s, _) = &states[1];
        assert_eq!(*s, LocalisationState::Tracking);
        assert!((16.0..20.0).contains(t_ok), "all clear at {t_ok}");
    }

    /// Drives at 0.3 m/s, the wheels turning 0.03 rad a scan one way for 2 s and then the
    /// other, the matches following them; from 10 s the gyro turns `gyro_share` of the
    /// wheels' turn. When the monitor checking turns by `check` first reports, why, and the
    /// share of the turn it reckons the wheels kept then.
    fn turn_slip_reported(
        gyro_share: f64,
        check: Option<TurnCheck>,
    ) -> Option<(f64, String, Option<f64>)> {
        let mut m = HealthMonitor::new(HealthConfig {
            turn_check: check,
            ..HealthConfig::default()
        });
        (0..200).find_map(|k| {
            let t = k as f64 * 0.1;
            let wheels = if (k / 20) % 2 == 0 { 0.03 } else { -0.03 };
            let gyro = if t >= 10.0 {
                gyro_share * wheels
            } else {
                wheels
            };
            let observed = TrackedScan {
                turns_rad: Some((wheels, gyro)),
                ..scan(t, 0.03, 0.03, 0.8)
            };
            m.observe(&observed)
                .map(|tr| (t, tr.reason, m.turn_share(t)))
        })
    }

    #[test]
    fn wheels_that_turn_where_the_gyro_does_not_are_reported() {
        let (t, why, share) =
            turn_slip_reported(0.1, Some(TurnCheck::default())).expect("reported");
        // Once over half the window's turns are the slipping ones (1.2 s), and the
        // disagreement has lasted its moment (0.3 s).
        assert!((10.0..12.0).contains(&t), "noticed at {t}");
        assert!(why.contains("turned"), "{why}");
        // Part of the window still holds the turns from before the slip.
        let share = share.expect("a share");
        assert!((0.1..0.5).contains(&share), "{share}");
        // Skid steering that loses a quarter of each turn is not slip.
        assert_eq!(turn_slip_reported(0.75, Some(TurnCheck::default())), None);
        // And without the check, matches that follow the wheels say nothing.
        assert_eq!(turn_slip_reported(0.1, None), None);
    }

    #[test]
    fn a_turn_share_is_not_carried_past_a_gap_nor_into_a_loss() {
        // Wheels turning 0.03 rad a scan, the gyro a tenth of it, for 1.5 s; then the scans
        // fit the map poorly until the rover is lost.
        let mut m = HealthMonitor::new(HealthConfig {
            turn_check: Some(TurnCheck::default()),
            ..HealthConfig::default()
        });
        let mut t = 0.0;
        for k in 0..15 {
            t = k as f64 * 0.1;
            m.observe(&TrackedScan {
                turns_rad: Some((0.03, 0.003)),
                ..scan(t, 0.03, 0.03, 0.8)
            });
        }
        let share = m.turn_share(t + 0.1).expect("disagreeing");
        assert!((share - 0.1).abs() < 1e-9, "{share}");
        // A scan 2.5 s later finds no turns in its window.
        assert_eq!(m.turn_share(t + 2.5), None);
        let mut state = m.state();
        while state != LocalisationState::Lost {
            t += 0.1;
            if let Some(tr) = m.observe(&TrackedScan {
                turns_rad: Some((0.03, 0.003)),
                ..scan(t, 0.03, 0.03, 0.1)
            }) {
                state = tr.state;
            }
            assert!(t < 5.0, "never lost");
        }
        assert_eq!(m.turn_share(t + 0.1), None);
    }

    #[test]
    fn slipping_wheels_are_reported_and_the_all_clear_follows() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        let mut states = Vec::new();
        // 10 s driving at 0.3 m/s, then 3 s of wheels spinning at the same rate while the
        // rover stands still, then 10 s of normal driving.
        for k in 0..230 {
            let t = k as f64 * 0.1;
            let matched = if (10.0..13.0).contains(&t) { 0.0 } else { 0.03 };
            if let Some(tr) = m.observe(&scan(t, 0.03, matched, 0.8)) {
                states.push((t, tr.state));
            }
        }
        assert_eq!(states.len(), 2, "{states:?}");
        let (t_slip, s) = states[0];
        assert_eq!(s, LocalisationState::OdometryUnreliable);
        assert!((10.0..11.5).contains(&t_slip), "noticed at {t_slip}");
        let (t_ok, s) = states[1];
        assert_eq!(s, LocalisationState::Tracking);
        assert!((15.0..19.0).contains(&t_ok), "all clear at {t_ok}");
    }

    /// A rover creeping at 5 cm/s whose wheels slip 90 % from 10 to 18 s: when the monitor
    /// `cfg` first reports it.
    fn creeping_burst_reported_at(cfg: HealthConfig) -> Option<f64> {
        let mut m = HealthMonitor::new(cfg);
        (0..250).find_map(|k| {
            let t = k as f64 * 0.1;
            // The motion filter matches every fourth scan (2 cm of wheel travel); the scans
            // between follow the wheels, and the match takes back what they over-reported.
            let truth_step = if (10.0..18.0).contains(&t) {
                0.0005
            } else {
                0.005
            };
            let (matched, score) = if k % 4 == 0 {
                (4.0 * truth_step - 3.0 * 0.005, Some(0.8))
            } else {
                (0.005, None)
            };
            m.observe(&TrackedScan {
                time_s: t,
                odom_delta: Pose2::new(0.005, 0.0, 0.0),
                matched_delta: Pose2::new(matched, 0.0, 0.0),
                tracked_delta: Pose2::new(matched, 0.0, 0.0),
                score,
                wheels_silent: false,
                turns_rad: None,
            })
            .filter(|tr| tr.state == LocalisationState::OdometryUnreliable)
            .map(|_| t)
        })
    }

    #[test]
    fn a_creeping_rover_slipping_is_reported_over_the_longer_window() {
        // The wheels are 0.1 m ahead of the truth 2.2 s into the burst: over the last 2 s
        // they have driven 0.1 m, so the short window alone never reaches the floor.
        let with_slow = HealthConfig {
            slow_window_s: Some(6.0),
            ..HealthConfig::default()
        };
        let t = creeping_burst_reported_at(with_slow).expect("reported");
        assert!((12.2..14.5).contains(&t), "reported at {t:.1} s");
        let short_only = HealthConfig {
            slow_window_s: None,
            ..HealthConfig::default()
        };
        assert_eq!(creeping_burst_reported_at(short_only), None);
    }

    #[test]
    fn a_burst_the_short_window_saw_is_cleared_as_soon_as_without_the_slow_one() {
        let changes = |cfg: HealthConfig| -> Vec<(i32, LocalisationState)> {
            let mut m = HealthMonitor::new(cfg);
            // 0.3 m/s; the wheels slip 90 % from 10 to 16 s.
            (0..300)
                .filter_map(|k| {
                    let t = k as f64 * 0.1;
                    let matched = if (10.0..16.0).contains(&t) {
                        0.003
                    } else {
                        0.03
                    };
                    m.observe(&scan(t, 0.03, matched, 0.8))
                        .map(|tr| (k, tr.state))
                })
                .collect()
        };
        let without = changes(HealthConfig {
            slow_window_s: None,
            ..HealthConfig::default()
        });
        assert_eq!(without.len(), 2, "{without:?}");
        let with_slow = HealthConfig {
            slow_window_s: Some(6.0),
            ..HealthConfig::default()
        };
        assert_eq!(changes(with_slow), without);
    }

    #[test]
    fn a_burst_already_cleared_does_not_raise_the_slow_window_again() {
        let cfg = HealthConfig {
            slow_window_s: Some(6.0),
            ..HealthConfig::default()
        };
        let mut m = HealthMonitor::new(cfg);
        // 0.3 m/s; the wheels slip 90 % from 10 to 14 s, then the rover stands still (a
        // planner's wait, say) until 30 s and drives on. The short window clears the burst
        // about 5 s after it ends; the slow window, 6 s long, still holds a second of it
        // then, on almost no other travel.
        let changes: Vec<(f64, LocalisationState)> = (0..400)
            .filter_map(|k| {
                let t = k as f64 * 0.1;
                let (odom, matched) = match t {
                    t if (10.0..14.0).contains(&t) => (0.03, 0.003),
                    t if (14.0..30.0).contains(&t) => (0.0, 0.0),
                    _ => (0.03, 0.03),
                };
                m.observe(&scan(t, odom, matched, 0.8))
                    .map(|tr| (t, tr.state))
            })
            .collect();
        assert_eq!(changes.len(), 2, "{changes:?}");
        assert_eq!(changes[0].1, LocalisationState::OdometryUnreliable);
        assert!((10.0..12.0).contains(&changes[0].0), "{changes:?}");
        assert_eq!(changes[1].1, LocalisationState::Tracking);
    }

    #[test]
    fn noise_in_normal_driving_raises_nothing() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        for k in 0..600 {
            let t = k as f64 * 0.1;
            // Odometry 10 % long, the scans a little noisy: ordinary skid-steer driving.
            let wobble = if k % 2 == 0 { 0.004 } else { -0.004 };
            assert_eq!(m.observe(&scan(t, 0.033, 0.03 + wobble, 0.7)), None, "{t}");
        }
    }

    #[test]
    fn a_match_that_jumps_once_is_not_slip() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        for k in 0..100 {
            let t = k as f64 * 0.1;
            // The rover tracks onto a submap that disagrees with the last one: one match
            // corrects the pose by half a metre, backwards along the track.
            let matched = if k == 50 { 0.03 - 0.5 } else { 0.03 };
            assert_eq!(m.observe(&scan(t, 0.03, matched, 0.7)), None, "{t}");
        }
    }

    #[test]
    fn one_match_after_a_long_unmatched_stretch_is_not_slip() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        for k in 0..40 {
            let t = k as f64 * 0.1;
            // Nothing to match against for a second (too few points), then one match that
            // puts the rover back by more than the 0.33 m the wheels drove meanwhile.
            let (matched, score) = match k {
                20..=29 => (0.03, None),
                30 => (0.03 - 0.45, Some(0.7)),
                _ => (0.03, Some(0.7)),
            };
            assert_eq!(
                m.observe(&TrackedScan {
                    time_s: t,
                    odom_delta: Pose2::new(0.03, 0.0, 0.0),
                    matched_delta: Pose2::new(matched, 0.0, 0.0),
                    tracked_delta: Pose2::new(matched, 0.0, 0.0),
                    score,
                    wheels_silent: false,
                    turns_rad: None,
                }),
                None,
                "{t}"
            );
        }
    }

    /// Drives at 0.3 m/s; from 5 s the matches see a tenth of the wheels' travel and the
    /// tracked pose `tracked_m` a step. Returns when the alarm came, how many slipping
    /// steps lie in the window then, and the overrun then.
    fn overrun_at_the_alarm(tracked_m: f64) -> (f64, usize, (f64, f64)) {
        let mut m = HealthMonitor::new(HealthConfig::default());
        for k in 0..100 {
            let t = k as f64 * 0.1;
            let slipping = t >= 5.0 - 1e-9;
            let matched = if slipping { 0.003 } else { 0.03 };
            let observed = TrackedScan {
                tracked_delta: Pose2::new(if slipping { tracked_m } else { 0.03 }, 0.0, 0.0),
                ..scan(t, 0.03, matched, 0.8)
            };
            if let Some(tr) = m.observe(&observed) {
                assert_eq!(tr.state, LocalisationState::OdometryUnreliable);
                let in_window = (50..=k).filter(|j| *j as f64 * 0.1 >= t - 2.0).count();
                return (t, in_window, m.overrun());
            }
        }
        panic!("no alarm");
    }

    #[test]
    fn the_overrun_is_what_the_pose_ran_beyond_the_matches_in_the_window() {
        // Each slipping step the pose follows the wheels 0.027 m beyond the match.
        let (t, steps, (x, y)) = overrun_at_the_alarm(0.03);
        assert!((5.0..7.0).contains(&t), "alarm at {t}");
        assert!(
            (x - 0.027 * steps as f64).abs() < 1e-9,
            "{x} over {steps} steps"
        );
        assert_eq!(y, 0.0);
        // A pose that kept to the matches ran beyond nothing, nor does one that fell behind.
        for tracked_m in [0.003, 0.0] {
            let (x, y) = overrun_at_the_alarm(tracked_m).2;
            assert!(x.abs() < 1e-9 && y == 0.0, "{tracked_m}: ({x}, {y})");
        }
    }

    #[test]
    fn slip_is_seen_when_only_every_third_scan_is_matched() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        let mut noticed = None;
        for k in 0..100 {
            let t = k as f64 * 0.1;
            // The wheels creep at 0.1 m/s and the motion filter matches every third scan:
            // the scans between follow odometry and the match takes back all of their travel.
            let slipping = t >= 5.0;
            let matched_now = k % 3 == 0;
            let (matched, score) = match (matched_now, slipping) {
                (false, _) => (0.01, None),
                (true, false) => (0.01, Some(0.8)),
                (true, true) => (0.01 - 0.03, Some(0.8)),
            };
            if let Some(tr) = m.observe(&TrackedScan {
                time_s: t,
                odom_delta: Pose2::new(0.01, 0.0, 0.0),
                matched_delta: Pose2::new(matched, 0.0, 0.0),
                tracked_delta: Pose2::new(matched, 0.0, 0.0),
                score,
                wheels_silent: false,
                turns_rad: None,
            }) {
                noticed.get_or_insert((t, tr.state));
            }
        }
        let (t, state) = noticed.expect("the slip was noticed");
        assert_eq!(state, LocalisationState::OdometryUnreliable);
        assert!((5.0..7.5).contains(&t), "noticed at {t}");
    }

    #[test]
    fn poor_matches_or_a_long_gap_mean_lost_until_relocalised() {
        let mut m = HealthMonitor::new(HealthConfig::default());
        for k in 0..10 {
            m.observe(&scan(k as f64 * 0.1, 0.03, 0.03, 0.8));
        }
        let mut lost_at = None;
        for k in 10..20 {
            if let Some(tr) = m.observe(&scan(k as f64 * 0.1, 0.03, 0.03, 0.2)) {
                lost_at.get_or_insert((k, tr.state));
            }
        }
        assert_eq!(lost_at, Some((14, LocalisationState::Lost)));
        // Good matches alone do not end it: the mapper must relocalise.
        assert_eq!(m.observe(&scan(2.1, 0.03, 0.03, 0.9)), None);
        assert_eq!(m.state(), LocalisationState::Lost);
        // Relocalised long after the last scan it saw: the scans in between went to the
        // search, so the next one, a tenth of a second on, is no gap.
        assert!(m.relocalised(60.0, "found".into()).is_some());
        assert_eq!(m.state(), LocalisationState::Tracking);
        assert_eq!(m.observe(&scan(60.1, 0.03, 0.03, 0.9)), None);
        assert_eq!(m.state(), LocalisationState::Tracking);
        let tr = m.observe(&scan(71.0, 0.03, 0.03, 0.9)).expect("a gap");
        assert_eq!(tr.state, LocalisationState::Lost);
        assert!(tr.reason.contains("no lidar scan"), "{}", tr.reason);
    }
}
