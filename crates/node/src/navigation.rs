//! The rover's navigation: where to go, how to get there, and what to do when that fails.
//!
//! Every few seconds (and at once when something goes wrong) the rover's map becomes a
//! [`Costmap`]; one Dijkstra field from the rover gives the cost to every frontier, the best
//! frontier (discounted by the targets peers have claimed) becomes the goal, and the path to
//! it comes from the same field. Between map updates the [`Follower`] steers along the path,
//! and a reactive guard (lidar and depth camera, see [`crate::guard`]) stops the rover if
//! something appears in front of it before the map shows it.
//!
//! A rover that stops making progress notices: it backs off, turns to look around and
//! replans, and after a few tries (or when a goal takes far longer than its path should)
//! gives the goal up and blacklists it. Operator goals pre-empt exploration until reached
//! or cancelled. When no reachable frontier is left the rover drives home (its start,
//! beside the lander) and stops there.
//!
//! With [`NavigationConfig::revisit`] set, a rover whose pose grew too uncertain (the
//! position's standard deviation by the path that ties it to the start, see
//! `realms_slam::drift`) breaks off exploring and drives back to the nearest ground it
//! mapped while it knew where it was, until a loop closure there ties its pose back (or it
//! gets there, or gives up, without one: that place is then not taken again): active loop
//! closing, after Stachniss, Hähnel and Burgard, "Exploration with Active Loop-Closing for
//! FastSLAM" (IROS 2004).

use realms_core::msgs::ExploredArea;
use realms_core::{Cell, CentreLookup, Duration, Grid, GridGeometry, Point2, Pose2, RoverId, Time};
use realms_nav::explore::{Candidate, ExploreConfig, PeerClaim, candidates};
use realms_nav::follower::{Follower, FollowerConfig, Steer};
use realms_nav::frontier::{Frontier, FrontierTracker, still_to_explore};
use realms_nav::planner::{FloodBound, PlannerConfig, smooth};
use realms_nav::{Costmap, CostmapConfig, Planner};
use std::collections::{BTreeMap, VecDeque};

/// Navigation tuning.
#[derive(Clone, Debug, PartialEq)]
pub struct NavigationConfig {
    /// Costs from the map.
    pub costmap: CostmapConfig,
    /// Path search.
    pub planner: PlannerConfig,
    /// Path following.
    pub follower: FollowerConfig,
    /// Frontier choice.
    pub explore: ExploreConfig,
    /// How often the map is refreshed and the plan revised.
    pub replan_period: Duration,
    /// A rover that moved less than this, metres ...
    pub stuck_distance_m: f64,
    /// ... over this long while it should be driving, is stuck.
    pub stuck_window: Duration,
    /// Recoveries tried on one goal before it is given up.
    pub max_attempts: u32,
    /// A goal must be reached at this speed along its first path's cost (metres stretched
    /// by the costmap, so at least its length), m/s ...
    pub min_progress_speed_m_s: f64,
    /// ... plus this much time.
    pub goal_slack: Duration,
    /// A peer's claim is forgotten after this long without news.
    pub claim_lifetime: Duration,
    /// Legs of a smoothed path are at most this long, metres.
    pub max_leg_m: f64,
    /// How far ahead the path is checked against each new costmap, metres.
    pub check_ahead_m: f64,
    /// Where the rover goes when exploration is over (beside the lander).
    pub home: Point2,
    /// Whether the rover explores by itself (otherwise it waits for operator goals).
    pub autonomous: bool,
    /// Exploration is over when the map has not grown by `stall_growth_m2` in this long,
    /// whatever frontiers it still shows: they are ones driving up to does not map (a map
    /// redrawn after a loop closure, ground only a sensor that cannot see it would show).
    pub stall_window: Duration,
    /// ... square metres.
    pub stall_growth_m2: f64,
    /// Driving back to re-anchor an uncertain pose (off: `None`).
    pub revisit: Option<RevisitConfig>,
    /// Once the rover has found no reachable frontier left (its map whole as far as it can
    /// tell), a frontier beside no unknown ground is worth the drive only where its gain
    /// exceeds the drive ([`ExploreConfig::unjudged_must_pay`], for the end-game alone):
    /// the scraps of unjudged ground that turn up afterwards (a wall's foot after a closure
    /// redrew the map) are left unless they are near. Off in the rovers' setup.
    pub endgame_unjudged_must_pay: bool,
    /// Unknown ground the planner may plan through beyond the map's edge, metres: the map is
    /// padded by this much unknown on every side before planning. `None` plans within the
    /// map's grid only, whose edge lies a few metres past what the rover saw (and, for a
    /// rover starting near its frame's zero, reaches back to it). Off in the rovers' setup.
    pub plan_margin_m: Option<f64>,
}

/// When a rover breaks off exploring to tie its pose back to ground it mapped while it knew
/// where it was (see the module's documentation). Uncertainties are the position's standard
/// deviation by the path that ties it to the start, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RevisitConfig {
    /// A revisit starts when the uncertainty grows past this ...
    pub above_m: f64,
    /// ... towards the nearest place the rover mapped while its own was within this, and
    /// where its scan kept at least `anchor_points` returns ...
    pub anchored_m: f64,
    /// See `anchored_m`.
    pub anchor_points: usize,
    /// ... and ends once a closure has brought it back within this.
    pub resume_m: f64,
    /// After a revisit that ended without that (the place reached, or given up), the next
    /// waits until the uncertainty has grown by this much more (and that place is not taken
    /// again): it did not close the loop, and another revisit at once would only drive there
    /// again.
    pub retry_growth_m: f64,
}

impl Default for RevisitConfig {
    fn default() -> Self {
        RevisitConfig {
            above_m: 0.25,
            anchored_m: 0.1,
            anchor_points: 100,
            resume_m: 0.15,
            retry_growth_m: 0.25,
        }
    }
}

impl NavigationConfig {
    /// Defaults for the Leo Rover, returning to `home`.
    pub fn new(home: Point2) -> Self {
        NavigationConfig {
            costmap: CostmapConfig::default(),
            planner: PlannerConfig::default(),
            follower: FollowerConfig::default(),
            explore: ExploreConfig::default(),
            replan_period: Duration::from_secs(3),
            stuck_distance_m: 0.3,
            stuck_window: Duration::from_secs(20),
            max_attempts: 3,
            min_progress_speed_m_s: 0.1,
            goal_slack: Duration::from_secs(60),
            claim_lifetime: Duration::from_secs(120),
            max_leg_m: 2.0,
            check_ahead_m: 2.5,
            home,
            autonomous: true,
            stall_window: Duration::from_secs(300),
            stall_growth_m2: 2.0,
            revisit: None,
            endgame_unjudged_must_pay: false,
            plan_margin_m: None,
        }
    }
}

/// Why the rover is going where it is going.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum GoalKind {
    /// A frontier it chose.
    Frontier,
    /// A goal the operator gave.
    Operator,
    /// Home, exploration being over.
    Home,
    /// Ground mapped while the pose was known, to tie an uncertain pose back to it.
    Revisit,
    /// While lost, a place its lidar saw enough of to find itself again.
    Relocalise,
}

/// What the navigator is doing, for status messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activity {
    /// Waiting for a map or a goal.
    Idle,
    /// Driving to a goal.
    Driving(GoalKind),
    /// Backing off after getting stuck.
    Recovering,
    /// Exploration is over and the rover is home.
    Done,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Goal {
    point: Point2,
    kind: GoalKind,
    deadline: Option<Time>,
    attempts: u32,
    /// When it was set (a revisit's drive does not count against exploring).
    started: Time,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Recovery {
    /// Back up (while the rear is clear) until then ...
    back_until: Time,
    /// ... then turn in place until then, to look around with the depth camera ...
    turn_until: Time,
    /// ... this way (+1 counter-clockwise).
    turn_dir: f64,
}

/// Something that happened, for the mission log.
#[derive(Clone, Debug, PartialEq)]
pub struct NavEvent {
    /// When.
    pub t: Time,
    /// What.
    pub what: String,
}

/// The rover's navigator.
#[derive(Debug)]
pub struct Navigator {
    id: RoverId,
    cfg: NavigationConfig,
    planner: Planner,
    follower: Follower,
    costmap: Option<Costmap>,
    /// The map (with the bumps drawn in) `costmap` was made from, and how many of its cells
    /// are explored: the same map again gives the same costmap and count, so they are kept
    /// rather than worked out anew (a rover parked at home is sent the same map every few
    /// seconds for hours).
    costmap_source: Option<(Grid<i8>, usize)>,
    /// Counts the maps that differed from the one before (`costmap_source` changed), so a
    /// result worked out on a map can tell whether it is still that map's.
    map_generation: u64,
    /// The map (its `map_generation`) and the peers' areas its cells were checked against,
    /// and which cells the peers had mapped.
    seen_cache: Option<(u64, Vec<ExploredArea>, Option<Vec<bool>>)>,
    /// Frontiers carried from one map to the next.
    frontiers: FrontierTracker,
    goal: Option<Goal>,
    operator_goal: Option<Point2>,
    blacklist: Vec<Point2>,
    peers: BTreeMap<RoverId, (Point2, Time)>,
    /// What each peer last said its map knows, and when.
    peer_areas: BTreeMap<RoverId, (ExploredArea, Time)>,
    history: VecDeque<(Time, Point2)>,
    recovery: Option<Recovery>,
    /// Where the rover got stuck driving forward (just ahead of its front), and when: drawn
    /// into each map as obstacles for [`BUMP_LIFETIME`] (see [`Navigator::with_bumps`]).
    bumps: Vec<(Point2, Time)>,
    next_map: Time,
    replan_now: bool,
    done: bool,
    /// The rover was last sent home because its map stopped growing, not for want of
    /// frontiers: it looks for none on the way.
    home_for_stall: bool,
    /// Times the way home was given up.
    home_failures: u32,
    /// When the guard last forced a replan.
    last_forced_replan: Option<Time>,
    /// Known cells of the map when it last grew by the stall threshold, and when.
    grown: Option<(usize, Time)>,
    /// The position's uncertainty (metres) and the nearest place mapped while it was
    /// small, as the rover last said ([`Navigator::set_localisation`]).
    localisation: Option<(f64, Option<Point2>)>,
    /// The uncertainty past which a revisit starts now ([`RevisitConfig::above_m`], raised
    /// after a revisit that closed no loop).
    revisit_above_m: f64,
    /// Places revisits reached, or gave up on, without a closure: not taken again.
    revisits_closed_nothing: Vec<Point2>,
    /// It once found no reachable frontier left (see
    /// [`NavigationConfig::endgame_unjudged_must_pay`]).
    ran_out_of_frontiers: bool,
    events: Vec<NavEvent>,
}

/// Tries at the way home before the rover stays where it is.
const MAX_HOME_TRIES: u32 = 3;
/// Where a rover got stuck is an obstacle in its maps for this long ...
const BUMP_LIFETIME: Duration = Duration::from_secs(600);
/// ... a disc this wide ...
const BUMP_RADIUS_M: f64 = 0.1;
/// ... centred this far ahead of the rover's centre (half the Leo Rover's length and 5 cm).
const BUMP_AHEAD_M: f64 = 0.275;
/// A rover keeps its frontier while it is worth no less than the best by more than this
/// (in the planner's cost, metres of easy ground), so it does not dither between two.
const KEEP_GOAL_MARGIN: f64 = 2.0;

/// A revisit is not started towards a place nearer than this, metres: the rover is there
/// already, and what it sees has not closed the loop.
const REVISIT_MIN_DISTANCE_M: f64 = 1.0;

/// The guard forces a replan at most this often.
const FORCED_REPLAN_PERIOD: Duration = Duration::from_secs(1);

/// The frontiers worth going to, best first, by the travel costs `field`, and those of them
/// no peer is about to map: those are left to the peer, and if they are all that is left the
/// rover waits rather than going home (the peer may yet fail).
fn rank_frontiers(
    frontiers: &[Frontier],
    geo: &GridGeometry,
    field: &[f32],
    claims: &[PeerClaim],
    blacklist: &[Point2],
    cfg: &ExploreConfig,
) -> (Vec<Candidate>, Vec<Candidate>) {
    let options = candidates(frontiers, geo, field, claims, blacklist, cfg);
    let free = options
        .iter()
        .filter(|c| !c.taken_by_peer())
        .copied()
        .collect();
    (options, free)
}

/// Whether two points are the same target.
fn same_target(a: Point2, b: Point2) -> bool {
    a.distance_m(b) < 0.5
}

impl Navigator {
    /// A navigator for rover `id`.
    pub fn new(id: RoverId, cfg: NavigationConfig) -> Self {
        let revisit_above_m = cfg.revisit.map_or(f64::INFINITY, |r| r.above_m);
        Navigator {
            id,
            planner: Planner::new(cfg.planner),
            follower: Follower::new(cfg.follower),
            cfg,
            costmap: None,
            costmap_source: None,
            map_generation: 0,
            seen_cache: None,
            frontiers: FrontierTracker::new(),
            goal: None,
            operator_goal: None,
            blacklist: Vec::new(),
            peers: BTreeMap::new(),
            peer_areas: BTreeMap::new(),
            history: VecDeque::new(),
            recovery: None,
            bumps: Vec::new(),
            next_map: Time::ZERO,
            replan_now: true,
            done: false,
            home_for_stall: false,
            home_failures: 0,
            last_forced_replan: None,
            grown: None,
            localisation: None,
            revisit_above_m,
            revisits_closed_nothing: Vec::new(),
            ran_out_of_frontiers: false,
            events: Vec::new(),
        }
    }

    /// What it is doing.
    pub fn activity(&self) -> Activity {
        if self.recovery.is_some() {
            Activity::Recovering
        } else if let Some(g) = self.goal {
            Activity::Driving(g.kind)
        } else if self.done {
            Activity::Done
        } else {
            Activity::Idle
        }
    }

    /// The goal it is driving to.
    pub fn goal(&self) -> Option<(Point2, GoalKind)> {
        self.goal.map(|g| (g.point, g.kind))
    }

    /// Targets given up on.
    pub fn blacklist(&self) -> &[Point2] {
        &self.blacklist
    }

    /// Takes what happened since the last call.
    pub fn take_events(&mut self) -> Vec<NavEvent> {
        std::mem::take(&mut self.events)
    }

    fn event(&mut self, t: Time, what: String) {
        self.events.push(NavEvent { t, what });
    }

    /// How far the position may be off (standard deviation, metres) and the nearest place
    /// mapped while it was within [`RevisitConfig::anchored_m`], for deciding on revisits at
    /// the next map. `None`: not known (lost, or no model of it).
    pub fn set_localisation(&mut self, uncertainty: Option<(f64, Option<Point2>)>) {
        self.localisation = uncertainty;
    }

    /// Uncertainty within which the places the rover mapped count as anchored, and the
    /// returns a scan must have kept there, if it revisits them
    /// ([`NavigationConfig::revisit`]).
    pub fn anchored(&self) -> Option<(f64, usize)> {
        self.cfg.revisit.map(|r| (r.anchored_m, r.anchor_points))
    }

    /// Whether `place` may be revisited: it is not within `REVISIT_MIN_DISTANCE_M` of a
    /// place a revisit reached, or gave up on, without a closure.
    pub fn may_revisit(&self, place: Point2) -> bool {
        self.revisits_closed_nothing
            .iter()
            .all(|p| p.distance_m(place) >= REVISIT_MIN_DISTANCE_M)
    }

    /// Starts or ends a revisit by the uncertainty last heard (see
    /// [`NavigationConfig::revisit`]), for the rover at `here`; none starts on a map that
    /// stopped growing (exploring is over).
    fn revise_revisit(&mut self, now: Time, here: Point2, stalled: bool) {
        let (Some(rv), Some((sigma, anchor))) = (self.cfg.revisit, self.localisation) else {
            return;
        };
        // A closure cut it back (all the way, or part of it): the bound is the first again.
        if sigma < rv.above_m {
            self.revisit_above_m = rv.above_m;
        }
        match self.goal {
            Some(g) if g.kind == GoalKind::Revisit && sigma <= rv.resume_m => {
                self.event(
                    now,
                    format!("pose tied back (within {sigma:.2} m): exploring again"),
                );
                self.goal = None;
                self.follower.set_path(Vec::new());
                self.revisit_ended(now, g.started);
            }
            // A revisit under way goes on: the guard below takes only a frontier or none.
            goal if self.cfg.autonomous
                && !self.done
                && !stalled
                && self.operator_goal.is_none()
                && goal.is_none_or(|g| g.kind == GoalKind::Frontier)
                && sigma > self.revisit_above_m =>
            {
                match anchor {
                    Some(place) if place.distance_m(here) >= REVISIT_MIN_DISTANCE_M => {
                        self.event(
                            now,
                            format!(
                                "position uncertain to {sigma:.2} m: driving back to ({:.1}, \
                                 {:.1}), mapped within {:.2} m, to close the loop",
                                place.x_m, place.y_m, rv.anchored_m
                            ),
                        );
                        self.start_goal(now, place, GoalKind::Revisit);
                    }
                    // Already there, and what it sees closes nothing.
                    Some(place) => self.revisit_closed_nothing(place),
                    // Nowhere to go back to: asked again only once it has grown further.
                    None => self.raise_revisit_bound(),
                }
            }
            _ => {}
        }
    }

    /// A revisit set at `started` ended: the drive back mapped nothing new, so the stall
    /// rule's clock is moved on by the time it took since the map last grew, rather than
    /// count it against exploring.
    /// The time spent exploring before and after still counts: a rover whose every drive
    /// towards a frontier ends in a revisit (its pose grows uncertain on the way each time, a
    /// closure ties it back each time) runs out of exploring as one that makes no headway.
    /// (Restarting the clock at each revisit, as before, kept such a rover at it for the
    /// whole mission: seed 34's rover3, ninety-fifth session.)
    fn revisit_ended(&mut self, now: Time, started: Time) {
        if let Some((known, since)) = self.grown {
            self.grown = Some((known, since + (now - started.max(since))));
        }
    }

    /// A revisit to `place` ended (or could not start) without a closure bringing the
    /// uncertainty down: the place is not taken again, and the next revisit waits until the
    /// uncertainty has grown by [`RevisitConfig::retry_growth_m`] more.
    fn revisit_closed_nothing(&mut self, place: Point2) {
        self.raise_revisit_bound();
        self.revisits_closed_nothing.push(place);
    }

    /// The next revisit waits until the uncertainty has grown by
    /// [`RevisitConfig::retry_growth_m`] more than it is now.
    fn raise_revisit_bound(&mut self) {
        if let (Some(rv), Some((sigma, _))) = (self.cfg.revisit, self.localisation) {
            self.revisit_above_m = sigma.max(rv.above_m) + rv.retry_growth_m;
        }
    }

    /// The rover is lost (its pose carried on by its wheels and gyro, on the map as it was
    /// when it lost its place): it drives to `place`, where its lidar saw enough to find
    /// itself again, instead of whatever it was doing. An operator's goal waits until it
    /// knows where it is again.
    pub fn start_relocalising(&mut self, now: Time, place: Point2) {
        // The frontier it was heading for when it got lost lies where its scans are likely
        // to be poor again: left to a peer, or to later.
        if let Some(g) = self.goal
            && g.kind == GoalKind::Frontier
        {
            self.blacklist.push(g.point);
        }
        self.drop_goal(now, "lost its place", false);
        self.start_goal(now, place, GoalKind::Relocalise);
    }

    /// Whether the operator's goal is set and not yet reached or refused.
    pub fn has_operator_goal(&self) -> bool {
        self.operator_goal.is_some()
    }

    /// Forgets the operator's goal, and stops driving to it, saying `why`.
    pub fn forget_operator_goal(&mut self, now: Time, why: &str) {
        if self.goal.is_some_and(|g| g.kind == GoalKind::Operator) {
            self.drop_goal(now, why, false);
        }
        self.operator_goal = None;
    }

    /// Whether it is driving to a place to find itself again.
    pub fn relocalising(&self) -> bool {
        self.goal.is_some_and(|g| g.kind == GoalKind::Relocalise)
    }

    /// The rover knows where it is again after being lost for `lost_for`: a drive to find
    /// itself ends (and a rover that was done replans, home again from where the drive
    /// took it), the goal it had keeps no deadline set before (it did not steer while
    /// lost), and the stall rule's clock is moved on by the time lost, in which nothing
    /// could be mapped.
    pub fn relocalised(&mut self, now: Time, lost_for: Duration) {
        if self.relocalising() {
            self.drop_goal(now, "found its place again", false);
            self.done = false;
        }
        if let Some(g) = self.goal.as_mut() {
            g.deadline = None;
        }
        self.history.clear();
        self.replan_now = true;
        if let Some((known, since)) = self.grown {
            self.grown = Some((known, since + lost_for));
        }
    }

    /// Whether it wants a fresh map now.
    pub fn wants_map(&self, now: Time) -> bool {
        now >= self.next_map || self.replan_now
    }

    /// The operator's goal (pre-empts exploration), or `None` to cancel it. Returns whether
    /// it was taken: a goal whose coordinates are not numbers is refused with an event.
    pub fn set_operator_goal(&mut self, now: Time, goal: Option<Point2>) -> bool {
        // A goal at no place on any map (a corrupt command) is refused, and said so.
        if goal.is_some_and(|p| !(p.x_m.is_finite() && p.y_m.is_finite())) {
            self.event(
                now,
                "operator goal refused: its coordinates are not numbers".into(),
            );
            return false;
        }
        self.operator_goal = goal;
        self.done = false;
        // A lost rover's drive to find itself goes on: the goal is taken once it knows
        // where it is.
        if !self.relocalising()
            && (self.goal.is_some_and(|g| g.kind == GoalKind::Operator) || goal.is_some())
        {
            self.drop_goal(now, "operator goal changed", false);
        }
        self.replan_now = true;
        true
    }

    /// A peer said where it is going (`None`: nowhere).
    pub fn hear_peer(&mut self, now: Time, peer: RoverId, target: Option<Point2>) {
        if peer == self.id {
            return;
        }
        match target {
            Some(p) => {
                // A senior peer took our frontier: give way at once rather than at the next
                // map update (both chose at the same moment, before hearing each other).
                let taken = self.cfg.explore.taken_radius_m();
                if peer.0 < self.id.0
                    && self.goal.is_some_and(|g| {
                        g.kind == GoalKind::Frontier && g.point.distance_m(p) <= taken
                    })
                {
                    self.replan_now = true;
                }
                self.peers.insert(peer, (p, now));
            }
            None => {
                self.peers.remove(&peer);
            }
        }
    }

    fn drop_goal(&mut self, now: Time, why: &str, blacklist: bool) {
        if let Some(g) = self.goal.take() {
            if blacklist && g.kind == GoalKind::Frontier {
                self.blacklist.push(g.point);
            }
            self.event(
                now,
                format!(
                    "gave up {:?} goal ({:.1}, {:.1}): {why}",
                    g.kind, g.point.x_m, g.point.y_m
                ),
            );
            if g.kind == GoalKind::Operator && blacklist {
                self.operator_goal = None;
            }
            if g.kind == GoalKind::Revisit {
                // Given up (not pre-empted by the operator): the place closed nothing.
                if blacklist {
                    self.revisit_closed_nothing(g.point);
                }
                self.revisit_ended(now, g.started);
            }
            if g.kind == GoalKind::Home && blacklist {
                self.home_failures += 1;
                if self.home_failures >= MAX_HOME_TRIES {
                    // Stay where it is rather than try for ever.
                    self.event(now, "cannot get home: staying here".to_string());
                    self.done = true;
                }
            }
        }
        self.follower.set_path(Vec::new());
        self.replan_now = true;
    }

    /// A peer said which ground its map knows.
    pub fn hear_explored(&mut self, now: Time, peer: RoverId, area: ExploredArea) {
        if peer != self.id {
            self.peer_areas.insert(peer, (area, now));
        }
    }

    /// Works out in `seen_cache`, per cell of `map` (the map of `map_generation`), whether a
    /// peer (heard from recently) has mapped it.
    fn update_seen_by_peers(&mut self, now: Time, map: &Grid<i8>) {
        let live: Vec<&ExploredArea> = self
            .peer_areas
            .values()
            .filter(|(_, heard)| now - *heard <= self.cfg.claim_lifetime)
            .map(|(a, _)| a)
            .collect();
        // Peers send their areas every few seconds, mostly unchanged once the hall is mapped:
        // the same map and the same cells known (whenever they were sent) mark the same cells.
        let same_cells = |a: &ExploredArea, b: &ExploredArea| {
            (a.origin, a.resolution_m, a.width, a.height)
                == (b.origin, b.resolution_m, b.width, b.height)
                && a.known == b.known
        };
        // Checked against the map the cache was worked out on, not the last map seen: a map
        // that grew while the rover drove to a goal other than a frontier (an operator's,
        // home; no frontiers looked for) is the last map seen by the time exploring resumes,
        // and a cache sized for the map before it sent the frontier tracker past its end.
        let same = self
            .seen_cache
            .as_ref()
            .is_some_and(|(generation, areas, _)| {
                *generation == self.map_generation
                    && areas.len() == live.len()
                    && areas.iter().zip(&live).all(|(a, b)| same_cells(a, b))
            });
        if !same {
            let seen = seen_by(&live, map);
            let areas = live.into_iter().cloned().collect();
            self.seen_cache = Some((self.map_generation, areas, seen));
        }
    }

    /// Peers' live claims; a peer with a higher id than ours does not displace our current
    /// target (so two rovers that picked nearby frontiers at once do not both leave them).
    fn claims(&self, now: Time, current: Option<Point2>) -> Vec<PeerClaim> {
        self.peers
            .iter()
            .filter(|(_, (_, heard))| now - *heard <= self.cfg.claim_lifetime)
            .filter(|(peer, (target, _))| {
                let taking_ours = current
                    .is_some_and(|c| c.distance_m(*target) <= self.cfg.explore.taken_radius_m());
                !(peer.0 > self.id.0 && taking_ours)
            })
            .map(|(_, (target, _))| PeerClaim { target: *target })
            .collect()
    }

    /// The rover stands outside its own map: nothing to plan on but the costmap kept.
    ///
    /// A goal not yet planned cannot be planned from here, so it is given up, and an
    /// operator's goal that would start now is refused, each saying why: a lost rover's
    /// dead-reckoned pose can leave the map it had when it got lost, and its drive back
    /// (or the operator's goal) would otherwise count an empty path as arrival, or wait
    /// for ever. A goal already on its way keeps its path: a map that grows catches up.
    /// An operator's goal waiting for a lost rover's drive back is not refused when that
    /// drive is given up: the rover tries its next place, or gives up and drops it then.
    fn off_map(&mut self, now: Time, costmap: Costmap) {
        const WHY: &str = "the rover is off its own map";
        self.event(now, WHY.into());
        self.costmap = Some(costmap);
        let refuse_operator = self.operator_goal_would_start();
        if self.goal.is_some() && self.follower.path().is_empty() {
            self.drop_goal(now, WHY, true);
        }
        if let Some(op) = self.operator_goal
            && refuse_operator
        {
            self.event(
                now,
                format!(
                    "refused Operator goal ({:.1}, {:.1}): {WHY}",
                    op.x_m, op.y_m
                ),
            );
            self.operator_goal = None;
        }
    }

    /// Whether an operator's goal, if set, pre-empts the current goal at the next map: all
    /// but a drive to it already and a drive to find the rover's place again.
    fn operator_goal_would_start(&self) -> bool {
        self.goal
            .is_none_or(|g| !matches!(g.kind, GoalKind::Operator | GoalKind::Relocalise))
    }

    /// A fresh map (-1 unknown, 0 free, 1 free but unjudged, 90 hazard, 100 obstacle) with
    /// the rover at `pose`:
    /// revises the goal and the path.
    pub fn on_map(&mut self, now: Time, map: &Grid<i8>, pose: Pose2) {
        self.next_map = now + self.cfg.replan_period;
        self.replan_now = false;
        self.bumps.retain(|(_, t)| now - *t < BUMP_LIFETIME);
        let padded;
        let map = match self.cfg.plan_margin_m {
            Some(margin_m) if margin_m > 0.0 => {
                padded = padded_with_unknown(map, margin_m);
                &padded
            }
            _ => map,
        };
        let bumped;
        let map = if self.bumps.is_empty() {
            map
        } else {
            bumped = self.with_bumps(map);
            &bumped
        };
        let (costmap, explored) = match (self.costmap.take(), &self.costmap_source) {
            (Some(kept), Some((source, explored))) if source == map => (kept, *explored),
            (kept, source) => {
                let explored = map
                    .cells()
                    .iter()
                    .filter(|v| !still_to_explore(**v))
                    .count();
                // Redone only around what changed since the map it was made from.
                let costmap = match (kept, source) {
                    (Some(kept), Some((source, _))) => kept.updated(source, map, &self.cfg.costmap),
                    _ => Costmap::from_map(map, &self.cfg.costmap),
                };
                self.costmap_source = Some((map.clone(), explored));
                self.map_generation += 1;
                (costmap, explored)
            }
        };
        let here = pose.position();
        let geo = *costmap.geometry();
        // Checked before anything below changes state; the flood's own check then holds.
        if geo.world_to_cell(here).is_none() {
            return self.off_map(now, costmap);
        }
        let stalled = self.stalled(now, explored, map.geometry().resolution_m);
        // Operator goals first (a rover driving to find itself takes them once it has; one
        // that gave up drives them as they come).
        if let Some(op) = self.operator_goal
            && self.operator_goal_would_start()
        {
            self.start_goal(now, op, GoalKind::Operator);
        }
        self.revise_revisit(now, here, stalled);
        // A revisit that ended moved the stall rule's clock on by its drive.
        let stalled = stalled && self.stalled(now, explored, map.geometry().resolution_m);
        let current = self.goal.map(|g| g.point);
        // A rover on its way home because no frontier was left keeps looking: ground that
        // turns up on the way (a peer's claim lapsing, a corner its map redrew) is taken
        // from there, not after the drive home and back. One sent home because its map
        // stopped growing does not, even where the drive home maps a little (its frontiers
        // are the ones driving up to does not map).
        let exploring = self.cfg.autonomous
            && self.goal.is_none_or(|g| {
                g.kind == GoalKind::Frontier
                    || (g.kind == GoalKind::Home && !self.home_for_stall && !stalled)
            });
        let frontiers = if exploring {
            self.update_seen_by_peers(now, map);
            let seen = self
                .seen_cache
                .as_ref()
                .and_then(|(_, _, seen)| seen.as_deref());
            self.frontiers
                .update(map, &costmap, self.cfg.explore.min_frontier_cells, seen)
        } else {
            Vec::new()
        };
        // The travel costs are read at the frontiers and at the goal only, so the flood
        // stops once it has reached them (at once, for a rover with none) or once it is so
        // far past the nearest frontier that no farther one can be worth more (a frontier
        // the rover cannot reach would otherwise have it flood all its known ground at every
        // replan: half the default mission's time).
        let goal_cell = current.and_then(|p| geo.world_to_cell(p));
        let targets: Vec<Cell> = frontiers
            .iter()
            .flat_map(|f| f.cells.iter().copied())
            .chain(goal_cell)
            .collect();
        let max_gain = self.cfg.explore.max_gain();
        let bound = FloodBound {
            beyond_first: (max_gain + KEEP_GOAL_MARGIN) as f32,
            must_reach: goal_cell,
        };
        let Ok((mut field, flood_limit)) = self
            .planner
            .travel_costs_bounded(&costmap, here, true, &targets, bound)
        else {
            return self.off_map(now, costmap);
        };
        if exploring {
            let claims = self.claims(now, current);
            let explore = ExploreConfig {
                unjudged_must_pay: self.cfg.explore.unjudged_must_pay
                    || (self.cfg.endgame_unjudged_must_pay && self.ran_out_of_frontiers),
                ..self.cfg.explore
            };
            let rank = |field: &[f32]| {
                rank_frontiers(&frontiers, &geo, field, &claims, &self.blacklist, &explore)
            };
            let (mut options, mut free) = rank(&field);
            // A frontier the bounded flood did not reach costs more than its limit, so is
            // worth less than the greatest gain less that; if the best it did reach is worth
            // less (the near ones blacklisted or a peer's), flood on to the end.
            if let Some(limit) = flood_limit
                && free
                    .first()
                    .is_none_or(|c| c.utility < max_gain - f64::from(limit))
            {
                let Ok(full) =
                    self.planner
                        .travel_costs_until(&costmap, here, true, Some(&targets))
                else {
                    return self.off_map(now, costmap);
                };
                field = full;
                (options, free) = rank(&field);
            }
            if stalled {
                if self.goal.is_some() {
                    self.goal = None;
                    self.follower.set_path(Vec::new());
                }
                if !self.done {
                    let minutes = self.cfg.stall_window.as_secs_f64() / 60.0;
                    self.event(
                        now,
                        format!("no new ground mapped in {minutes:.0} min: returning home"),
                    );
                    self.start_goal(now, self.cfg.home, GoalKind::Home);
                    self.home_for_stall = true;
                }
            } else {
                self.choose_frontier(now, &free, !options.is_empty());
                if options.is_empty() && !self.done && self.goal.is_none() {
                    self.ran_out_of_frontiers = true;
                    self.event(now, "no reachable frontier left: returning home".into());
                    self.start_goal(now, self.cfg.home, GoalKind::Home);
                    self.home_for_stall = false;
                }
            }
        }
        let reachable = |p: Point2| {
            geo.world_to_cell(p)
                .is_some_and(|c| field[geo.index(c)].is_finite())
        };
        let Some(goal) = self.goal else {
            self.costmap = Some(costmap);
            return;
        };
        if self
            .follower
            .blocked_ahead(here, &costmap, self.cfg.check_ahead_m, 0.4)
        {
            self.event(
                now,
                "new map data blocks the path ahead: replanning".to_string(),
            );
        }
        // Frontiers lie on known ground and the field already holds the way there; other
        // goals may lie beyond the map's known part, and A* plans into the unknown for them.
        let plan = if goal.kind == GoalKind::Frontier {
            match geo.world_to_cell(goal.point) {
                Some(cell) if reachable(goal.point) => self
                    .planner
                    .path_from_field(&costmap, cell)
                    .map_err(|e| e.to_string()),
                _ => Err("no path over known ground".to_string()),
            }
        } else {
            self.planner
                .plan(&costmap, here, goal.point)
                .map_err(|e| e.to_string())
        };
        match plan {
            Ok(plan) => {
                let path = smooth(&costmap, &plan.cells, self.cfg.max_leg_m);
                if let Some(g) = self.goal.as_mut()
                    && g.deadline.is_none()
                {
                    let slack = self.cfg.goal_slack.as_secs_f64();
                    g.deadline = Some(
                        now + Duration::from_secs_f64(
                            plan.cost / self.cfg.min_progress_speed_m_s + slack,
                        ),
                    );
                }
                self.follower.set_path(path);
            }
            Err(why) => {
                self.drop_goal(now, &why, true);
                if goal.kind == GoalKind::Home {
                    // Home is cut off: stay where it is rather than search forever.
                    self.done = true;
                }
            }
        }
        self.costmap = Some(costmap);
    }

    /// Whether the explored part of the map (`known` cells, `r` metres a side: known, and
    /// judged where the lidar alone saw it) has not grown by
    /// [`NavigationConfig::stall_growth_m2`] for the stall window: no frontier is then worth a
    /// drive until it grows again.
    fn stalled(&mut self, now: Time, known: usize, r: f64) -> bool {
        let step = (self.cfg.stall_growth_m2 / (r * r)).ceil() as usize;
        let since = match self.grown {
            Some((before, since)) if known < before + step => since,
            _ => {
                self.grown = Some((known, now));
                now
            }
        };
        now - since >= self.cfg.stall_window
    }

    fn start_goal(&mut self, now: Time, point: Point2, kind: GoalKind) {
        // A revisit taken over by another goal (the operator's, a drive to find itself) ends.
        if let Some(g) = self.goal
            && g.kind == GoalKind::Revisit
            && kind != GoalKind::Revisit
        {
            self.revisit_ended(now, g.started);
        }
        if kind == GoalKind::Frontier {
            // Exploring again (new ground appeared): it must come home again after.
            self.done = false;
        }
        self.goal = Some(Goal {
            point,
            kind,
            deadline: None,
            attempts: 0,
            started: now,
        });
        self.history.clear();
        self.event(
            now,
            format!("{kind:?} goal ({:.1}, {:.1})", point.x_m, point.y_m),
        );
    }

    /// Keeps the current frontier while it is still among the options and not much worse
    /// than the best; otherwise takes the best. `peers_have_some`: frontiers within reach
    /// are left that peers are mapping (what the event for a dropped goal says).
    fn choose_frontier(&mut self, now: Time, options: &[Candidate], peers_have_some: bool) {
        let Some(best) = options.first() else {
            if let Some(g) = self.goal
                && g.kind == GoalKind::Frontier
            {
                let why = if peers_have_some {
                    "none left that no peer is mapping"
                } else {
                    "no frontier left within reach"
                };
                self.event(
                    now,
                    format!(
                        "dropped frontier ({:.1}, {:.1}): {why}",
                        g.point.x_m, g.point.y_m
                    ),
                );
                self.goal = None;
            }
            return;
        };
        if let Some(g) = self.goal {
            let still = options.iter().find(|c| same_target(c.goal, g.point));
            if let Some(c) = still
                && c.utility >= best.utility - KEEP_GOAL_MARGIN
            {
                // The frontier's reachable cell may have moved a little as the map filled in.
                if let Some(goal) = self.goal.as_mut() {
                    goal.point = c.goal;
                }
                return;
            }
        }
        if self.goal.is_some_and(|g| same_target(g.point, best.goal)) {
            return;
        }
        self.start_goal(now, best.goal, GoalKind::Frontier);
    }

    /// The velocity for the rover at `pose` (moving at `speed_m_s`) now; `guard` says what
    /// the rover's own sensors see around it.
    pub fn steer(&mut self, now: Time, pose: Pose2, speed_m_s: f64, guard: Guarded) -> (f64, f64) {
        if let Some(r) = self.recovery {
            if now < r.back_until {
                return (if guard.rear_blocked { 0.0 } else { -0.12 }, 0.0);
            }
            if now < r.turn_until {
                return (0.0, 0.6 * r.turn_dir);
            }
            self.recovery = None;
            self.replan_now = true;
            self.history.clear();
        }
        let Some(goal) = self.goal else {
            return (0.0, 0.0);
        };
        self.history.push_back((now, pose.position()));
        while self
            .history
            .front()
            .is_some_and(|(t, _)| now - *t > self.cfg.stuck_window)
        {
            self.history.pop_front();
        }
        if goal.deadline.is_some_and(|d| now > d) {
            self.drop_goal(now, "it took too long", true);
            return (0.0, 0.0);
        }
        let window_full = self.history.front().is_some_and(|(t, _)| {
            (now - *t).as_secs_f64() >= self.cfg.stuck_window.as_secs_f64() - 1.0
        });
        if window_full {
            let start = self
                .history
                .front()
                .map(|(_, p)| *p)
                .unwrap_or(pose.position());
            let moved = self
                .history
                .iter()
                .map(|(_, p)| p.distance_m(start))
                .fold(0.0, f64::max);
            if moved < self.cfg.stuck_distance_m {
                return self.stuck(now, pose);
            }
        }
        match self.follower.steer(pose, speed_m_s, self.costmap.as_ref()) {
            Steer::Arrived => {
                self.event(
                    now,
                    format!(
                        "reached {:?} goal ({:.1}, {:.1})",
                        goal.kind, goal.point.x_m, goal.point.y_m
                    ),
                );
                self.goal = None;
                self.follower.set_path(Vec::new());
                match goal.kind {
                    GoalKind::Home => self.done = true,
                    GoalKind::Operator => self.operator_goal = None,
                    GoalKind::Revisit => {
                        self.revisit_closed_nothing(goal.point);
                        self.revisit_ended(now, goal.started);
                    }
                    GoalKind::Frontier | GoalKind::Relocalise => {}
                }
                self.replan_now = true;
                (0.0, 0.0)
            }
            Steer::Drive { v_m_s, w_rad_s } => {
                if v_m_s > 0.0 && guard.front_blocked {
                    // Something the map does not show yet: stop, look again, replan (not on
                    // every scan: the map needs a moment to show it).
                    if self
                        .last_forced_replan
                        .is_none_or(|t| now - t >= FORCED_REPLAN_PERIOD)
                    {
                        self.last_forced_replan = Some(now);
                        self.replan_now = true;
                    }
                    return (0.0, 0.0);
                }
                (v_m_s, w_rad_s)
            }
        }
    }

    /// `map` with the places the rover got stuck drawn in as obstacles. A rock below the
    /// lidar's plane that the depth camera missed (9 cm high, beside the step limit of 8)
    /// stopped a rover; its map still showed free ground there, so every replan led back
    /// into it (7 collisions in 90 s in the default mission, seed 1). Robots' bumpers
    /// mark their maps the same way (Nav2's collision monitor and bumper layers).
    fn with_bumps(&self, map: &Grid<i8>) -> Grid<i8> {
        let mut out = map.clone();
        let g = *map.geometry();
        for (p, _) in &self.bumps {
            for c in g.cells_within(*p, BUMP_RADIUS_M) {
                if let Some(v) = out.get_mut(c.x, c.y) {
                    *v = 100;
                }
            }
        }
        out
    }

    fn stuck(&mut self, now: Time, pose: Pose2) -> (f64, f64) {
        let Some(goal) = self.goal.as_mut() else {
            return (0.0, 0.0);
        };
        self.bumps
            .push((pose.transform_point(Point2::new(BUMP_AHEAD_M, 0.0)), now));
        goal.attempts += 1;
        let attempts = goal.attempts;
        self.history.clear();
        if attempts > self.cfg.max_attempts {
            self.drop_goal(now, "no progress after recoveries", true);
            return (0.0, 0.0);
        }
        self.event(
            now,
            format!("no progress: backing off and looking around (attempt {attempts})"),
        );
        let back_until = now + Duration::from_secs(2);
        self.recovery = Some(Recovery {
            back_until,
            turn_until: back_until + Duration::from_millis(2500),
            turn_dir: if attempts % 2 == 1 { 1.0 } else { -1.0 },
        });
        (0.0, 0.0)
    }
}

/// What the rover's own sensors say about its immediate surroundings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Guarded {
    /// Something is right in front of the rover.
    pub front_blocked: bool,
    /// Something is right behind it.
    pub rear_blocked: bool,
}

/// Per cell of `map`, whether one of `areas` (peers' explored areas) has mapped it; `None`
/// without any.
fn seen_by(areas: &[&ExploredArea], map: &Grid<i8>) -> Option<Vec<bool>> {
    if areas.is_empty() {
        return None;
    }
    let geo = *map.geometry();
    // Where each of our cells' centres lies in each peer's area, worked out per row and
    // per column rather than per cell.
    let lookups: Vec<(&ExploredArea, CentreLookup)> = areas
        .iter()
        .filter_map(|a| Some((*a, CentreLookup::new(&a.geometry()?, &geo))))
        .collect();
    let mut seen = vec![false; geo.len()];
    for (y, row) in map.cells().chunks(geo.width).enumerate() {
        for (x, v) in row.iter().enumerate() {
            seen[y * geo.width + x] = still_to_explore(*v)
                && lookups
                    .iter()
                    .any(|(a, l)| l.index(x, y).is_some_and(|i| a.is_known_at(i)));
        }
    }
    Some(seen)
}

/// `map` with `margin_m` of unknown cells (-1) added on every side, on the same lattice.
fn padded_with_unknown(map: &Grid<i8>, margin_m: f64) -> Grid<i8> {
    let g = *map.geometry();
    let n = (margin_m / g.resolution_m).ceil() as usize;
    let geometry = GridGeometry {
        width: g.width + 2 * n,
        height: g.height + 2 * n,
        resolution_m: g.resolution_m,
        origin: Point2::new(
            g.origin.x_m - n as f64 * g.resolution_m,
            g.origin.y_m - n as f64 * g.resolution_m,
        ),
    };
    let mut cells = vec![-1i8; geometry.width * geometry.height];
    for (y, row) in map.cells().chunks_exact(g.width.max(1)).enumerate() {
        let start = (y + n) * geometry.width + n;
        cells[start..start + g.width].copy_from_slice(row);
    }
    Grid::from_cells(geometry, cells).expect("one cell per place")
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_core::GridGeometry;

    #[test]
    fn a_map_padded_for_planning_keeps_every_cell_where_it_lies() {
        let g = GridGeometry {
            width: 3,
            height: 2,
            resolution_m: 0.1,
            origin: Point2::new(1.0, -2.0),
        };
        let map = Grid::from_cells(g, vec![0, 100, 90, 1, -1, 0]).expect("6 cells");
        // 0.25 m of margin is 3 cells of 0.1 m.
        let padded = padded_with_unknown(&map, 0.25);
        let p = padded.geometry();
        assert_eq!((p.width, p.height), (9, 8));
        for y in 0..8 {
            for x in 0..9 {
                let centre = p.cell_center(Cell { x, y });
                let want = g
                    .world_to_cell(centre)
                    .map_or(-1, |c| map.cells()[c.y * 3 + c.x]);
                assert_eq!(padded.cells()[y * 9 + x], want, "({x}, {y})");
            }
        }
    }

    /// A 10 x 10 m room (walls round it), known in its west half, unknown in its east half;
    /// `walled` adds a closed box of wall around (2.5, 8.5).
    fn room(walled: bool) -> Grid<i8> {
        let g = GridGeometry {
            width: 100,
            height: 100,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut map = Grid::new(g, -1i8);
        for y in 0..100 {
            for x in 0..100 {
                let wall = x == 0 || y == 0 || x == 99 || y == 99;
                let boxed = walled
                    && (15..=35).contains(&x)
                    && (75..=95).contains(&y)
                    && (x == 15 || x == 35 || y == 75 || y == 95);
                let v = if wall || boxed {
                    100
                } else if x < 50 {
                    0
                } else {
                    -1
                };
                *map.get_mut(x, y).expect("inside") = v;
            }
        }
        map
    }

    fn navigator() -> Navigator {
        Navigator::new(RoverId(1), NavigationConfig::new(Point2::new(1.0, 1.0)))
    }

    #[test]
    fn a_walled_in_operator_goal_is_refused_once_and_exploration_resumes() {
        let mut nav = navigator();
        let map = room(true);
        let pose = Pose2::new(2.0, 2.0, 0.0);
        nav.set_operator_goal(Time::ZERO, Some(Point2::new(2.5, 8.5)));
        nav.on_map(Time::ZERO, &map, pose);
        let events = nav.take_events();
        assert!(
            events
                .iter()
                .any(|e| e.what.starts_with("gave up Operator") && e.what.contains("no path")),
            "{events:?}"
        );
        // The next map update goes back to the frontier, not to the goal.
        nav.on_map(Time::from_secs_f64(3.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        assert!(
            nav.take_events()
                .iter()
                .all(|e| !e.what.contains("Operator")),
        );
    }

    #[test]
    fn a_map_grown_while_driving_to_an_operators_goal_is_explored_with_the_peers_coverage_redone() {
        let mut nav = navigator();
        let pose = Pose2::new(2.0, 2.0, 0.0);
        // A peer knows the room's west half, as this rover does.
        let mut known = vec![0u8; 100 * 100 / 8];
        for i in (0..100 * 100).filter(|i| i % 100 < 50) {
            known[i / 8] |= 1 << (i % 8);
        }
        let area = ExploredArea {
            header: realms_core::msgs::Header::default(),
            origin: Point2::new(0.0, 0.0),
            resolution_m: 0.1,
            width: 100,
            height: 100,
            known,
        };
        let at = Time::from_secs_f64;
        nav.hear_explored(at(0.0), RoverId(2), area);
        nav.on_map(at(0.0), &room(false), pose);
        // Off to the operator's goal, the map grows by a strip along its north side: no
        // frontiers are looked for on it.
        nav.set_operator_goal(at(1.0), Some(Point2::new(4.0, 4.0)));
        let small = room(false);
        let mut grown = Grid::new(
            GridGeometry {
                height: 110,
                ..*small.geometry()
            },
            -1i8,
        );
        for (i, v) in small.cells().iter().enumerate() {
            *grown.get_mut(i % 100, i / 100).expect("inside") = *v;
        }
        nav.on_map(at(2.0), &grown, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Operator));
        // Exploring again on the same grown map: the peers' coverage is worked out on it.
        nav.set_operator_goal(at(3.0), None);
        nav.on_map(at(4.0), &grown, pose);
        nav.on_map(at(5.0), &grown, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
    }

    /// A navigator that revisits, with the stall rule's window `stall_s`.
    fn revisiting_navigator(stall_s: i64) -> Navigator {
        let mut cfg = NavigationConfig::new(Point2::new(1.0, 1.0));
        cfg.revisit = Some(RevisitConfig::default());
        cfg.stall_window = Duration::from_secs(stall_s);
        Navigator::new(RoverId(1), cfg)
    }

    #[test]
    fn a_rover_whose_pose_grew_uncertain_drives_back_to_anchored_ground_until_a_closure_ties_it_back()
     {
        // The map never grows here: with a stall window of 5 s, exploring would end at the
        // first map after the revisit if its 6 s counted on the stall rule's clock (3 s of
        // exploring before it, then the revisit's own time paused).
        let mut nav = revisiting_navigator(5);
        let map = room(false);
        let pose = Pose2::new(4.0, 5.0, 0.0);
        let anchored = Point2::new(2.0, 2.0);
        let at = Time::from_secs_f64;
        // Under the bound: exploring.
        nav.set_localisation(Some((0.24, Some(anchored))));
        nav.on_map(at(0.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        nav.take_events();
        // Past it: back to the anchored place, the frontier left.
        nav.set_localisation(Some((0.3, Some(anchored))));
        nav.on_map(at(3.0), &map, pose);
        assert_eq!(nav.goal(), Some((anchored, GoalKind::Revisit)));
        let events = nav.take_events();
        assert!(
            events
                .iter()
                .any(|e| e.what.starts_with("position uncertain to 0.30 m")),
            "{events:?}"
        );
        // Still uncertain on the way (the closure not yet made): it keeps going.
        nav.set_localisation(Some((0.2, Some(anchored))));
        nav.on_map(at(6.0), &map, pose);
        assert_eq!(nav.goal(), Some((anchored, GoalKind::Revisit)));
        // A closure brought it back within 0.15 m: exploring again, from where it is.
        nav.set_localisation(Some((0.1, Some(anchored))));
        nav.on_map(at(9.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        let events = nav.take_events();
        assert!(
            events.iter().any(|e| e.what.starts_with("pose tied back")),
            "{events:?}"
        );
        // The place closed the loop: it may be taken again.
        assert!(nav.may_revisit(anchored));
    }

    #[test]
    fn a_rover_whose_every_drive_out_ends_in_a_revisit_still_runs_out_of_exploring() {
        // Each drive towards the frontier grows the pose uncertain within 6 s, and each
        // revisit ties it back within 4 s; the map never grows. The 6 s of each drive out
        // count against exploring, the revisits do not: with a window of 20 s it ends in
        // the fourth drive out and the rover heads home. (When each revisit restarted the
        // stall rule's clock, it went on so for the whole mission.)
        let mut nav = revisiting_navigator(20);
        let map = room(false);
        let pose = Pose2::new(4.0, 5.0, 0.0);
        let anchored = Point2::new(2.0, 2.0);
        let mut kinds = Vec::new();
        for cycle in 0..8 {
            let t0 = 10.0 * cycle as f64;
            for (dt, sigma) in [(0.0, 0.1), (3.0, 0.2), (6.0, 0.3), (8.0, 0.2)] {
                nav.set_localisation(Some((sigma, Some(anchored))));
                nav.on_map(Time::from_secs_f64(t0 + dt), &map, pose);
                kinds.push(nav.goal().map(|g| g.1));
            }
        }
        let revisits = kinds
            .windows(2)
            .filter(|w| w[0] != Some(GoalKind::Revisit) && w[1] == Some(GoalKind::Revisit))
            .count();
        assert_eq!(revisits, 3, "{kinds:?}");
        assert_eq!(kinds.last(), Some(&Some(GoalKind::Home)), "{kinds:?}");
    }

    #[test]
    fn a_revisit_that_closed_no_loop_waits_until_the_pose_grows_more_uncertain() {
        let mut nav = revisiting_navigator(300);
        let map = room(false);
        let anchored = Point2::new(2.0, 2.0);
        let elsewhere = Point2::new(4.0, 2.0);
        let at = Time::from_secs_f64;
        let pose = Pose2::new(4.0, 5.0, 0.0);
        nav.set_localisation(Some((0.3, Some(anchored))));
        nav.on_map(at(0.0), &map, pose);
        assert_eq!(nav.goal(), Some((anchored, GoalKind::Revisit)));
        // It gets there and no closure comes: the revisit ends.
        let there = Pose2::new(anchored.x_m, anchored.y_m, 0.0);
        let guard = Guarded::default();
        let mut arrived = false;
        for k in 0..10 {
            nav.steer(at(1.0 + 0.1 * f64::from(k)), there, 0.0, guard);
            arrived |= nav.goal().is_none();
        }
        assert!(arrived, "{:?}", nav.take_events());
        // That place is not taken again; others are.
        assert!(!nav.may_revisit(anchored));
        assert!(nav.may_revisit(elsewhere));
        // Back out exploring, not again at the same uncertainty, nor a little more ...
        nav.on_map(at(3.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        nav.set_localisation(Some((0.5, Some(elsewhere))));
        nav.on_map(at(6.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        // ... but once it has grown by another 0.25 m.
        nav.set_localisation(Some((0.56, Some(elsewhere))));
        nav.on_map(at(9.0), &map, pose);
        assert_eq!(nav.goal(), Some((elsewhere, GoalKind::Revisit)));
        // Given up (the deadline passed): that place is not taken again either.
        nav.steer(at(10_000.0), pose, 0.0, guard);
        assert_eq!(nav.goal(), None);
        assert!(!nav.may_revisit(elsewhere));
        // A closure that cut the uncertainty under the first bound, even short of 0.15 m,
        // brings the bound back: past 0.25 m again, a revisit starts.
        let third = Point2::new(3.0, 8.0);
        nav.set_localisation(Some((0.2, Some(third))));
        nav.on_map(at(10_003.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        nav.set_localisation(Some((0.3, Some(third))));
        nav.on_map(at(10_006.0), &map, pose);
        assert_eq!(nav.goal(), Some((third, GoalKind::Revisit)));
        // Without a place to go back to, none starts, and none until the uncertainty has
        // grown by 0.25 m more, wherever it leads; where the rover stood is not held against
        // a place.
        let mut nav = revisiting_navigator(300);
        nav.set_localisation(Some((0.3, None)));
        nav.on_map(at(0.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        assert!(nav.may_revisit(pose.position()));
        nav.set_localisation(Some((0.5, Some(anchored))));
        nav.on_map(at(3.0), &map, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        nav.set_localisation(Some((0.56, Some(anchored))));
        nav.on_map(at(6.0), &map, pose);
        assert_eq!(nav.goal(), Some((anchored, GoalKind::Revisit)));
    }

    #[test]
    fn a_rover_without_revisits_explores_on_however_uncertain_its_pose() {
        let mut nav = navigator();
        let map = room(false);
        nav.set_localisation(Some((2.0, Some(Point2::new(2.0, 2.0)))));
        nav.on_map(Time::ZERO, &map, Pose2::new(4.0, 5.0, 0.0));
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        assert_eq!(nav.anchored(), None);
    }

    #[test]
    fn a_rover_going_home_for_want_of_frontiers_takes_one_that_turns_up_on_the_way() {
        let mut nav = navigator();
        let pose = Pose2::new(2.0, 5.0, 0.0);
        // The whole room known: nothing left to explore.
        let mut whole = room(false);
        for v in whole.cells_mut() {
            if *v < 0 {
                *v = 0;
            }
        }
        let at = Time::from_secs_f64;
        nav.on_map(at(0.0), &room(false), pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Frontier));
        nav.take_events();
        nav.on_map(at(3.0), &whole, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Home));
        // No peer took the frontier: the event says it is gone.
        let events = nav.take_events();
        assert!(
            events.iter().any(|e| e.what.starts_with("dropped frontier")
                && e.what.ends_with("no frontier left within reach")),
            "{events:?}"
        );
        // On the way, the east half is unknown again (a peer's coverage lapsed, the map
        // was redrawn): its frontier is taken from where the rover is.
        nav.on_map(at(6.0), &room(false), pose);
        let (goal, kind) = nav.goal().expect("a goal");
        assert_eq!(kind, GoalKind::Frontier);
        assert!((goal.x_m - 5.0).abs() < 0.3, "{goal:?}");
    }

    #[test]
    fn a_lost_rover_keeps_driving_to_find_itself_and_takes_the_operators_goal_after() {
        let mut nav = navigator();
        let map = room(false);
        let pose = Pose2::new(2.0, 5.0, 0.0);
        let at = Time::from_secs_f64;
        nav.on_map(at(0.0), &map, pose);
        let (frontier, kind) = nav.goal().expect("a frontier");
        assert_eq!(kind, GoalKind::Frontier);
        // Lost on the way there: it drives back to where it saw enough.
        let place = Point2::new(1.5, 8.0);
        nav.start_relocalising(at(1.0), place);
        assert_eq!(nav.goal(), Some((place, GoalKind::Relocalise)));
        // The operator's goal waits ...
        let operator = Point2::new(3.0, 3.0);
        nav.set_operator_goal(at(2.0), Some(operator));
        nav.on_map(at(3.0), &map, pose);
        assert_eq!(nav.goal(), Some((place, GoalKind::Relocalise)));
        // ... until it knows where it is again.
        nav.relocalised(at(4.0), Duration::from_secs(3));
        assert!(!nav.relocalising());
        nav.on_map(at(4.0), &map, pose);
        assert_eq!(nav.goal(), Some((operator, GoalKind::Operator)));
        // The frontier it was lost on the way to is not taken again.
        assert!(nav.blacklist().contains(&frontier));
    }

    #[test]
    fn a_rover_off_its_own_map_gives_up_the_goal_it_cannot_plan_and_refuses_the_operators() {
        let mut nav = navigator();
        let map = room(false);
        let at = Time::from_secs_f64;
        nav.on_map(at(0.0), &map, Pose2::new(2.0, 5.0, 0.0));
        nav.take_events();
        // Lost, its dead-reckoned pose drifted west of the map it had: the drive back
        // cannot be planned, and must not count as arrival.
        let off = Pose2::new(-2.0, 5.0, 0.0);
        nav.start_relocalising(at(1.0), Point2::new(1.5, 8.0));
        nav.on_map(at(1.0), &map, off);
        assert_eq!(nav.goal(), None);
        assert_eq!(nav.steer(at(1.1), off, 0.0, Guarded::default()), (0.0, 0.0));
        let events = nav.take_events();
        assert!(
            events
                .iter()
                .any(|e| e.what.starts_with("gave up Relocalise")
                    && e.what.contains("off its own map")),
            "{events:?}"
        );
        assert!(
            events.iter().all(|e| !e.what.starts_with("reached")),
            "{events:?}"
        );
        // An operator's goal waiting for the drive back is not refused with it: the rover
        // tries its next place, and drops the goal itself if it gives up.
        nav.start_relocalising(at(1.2), Point2::new(1.5, 2.0));
        nav.set_operator_goal(at(1.3), Some(Point2::new(3.0, 3.0)));
        nav.on_map(at(1.3), &map, off);
        assert_eq!(nav.goal(), None);
        assert!(nav.has_operator_goal());
        nav.forget_operator_goal(at(1.4), "the rover gave up finding itself");
        nav.take_events();
        // The operator's goal is refused, saying why, rather than left waiting unsaid.
        nav.set_operator_goal(at(2.0), Some(Point2::new(3.0, 3.0)));
        nav.on_map(at(2.0), &map, off);
        assert!(!nav.has_operator_goal());
        assert_eq!(nav.goal(), None);
        let events = nav.take_events();
        assert!(
            events
                .iter()
                .any(|e| e.what.starts_with("refused Operator")
                    && e.what.contains("off its own map")),
            "{events:?}"
        );
        // A goal already on its way keeps its path while the map catches up.
        let on = Pose2::new(2.0, 5.0, 0.0);
        nav.set_operator_goal(at(3.0), Some(Point2::new(3.0, 3.0)));
        nav.on_map(at(3.0), &map, on);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Operator));
        nav.on_map(at(6.0), &map, off);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Operator));
        assert!(nav.has_operator_goal());
    }

    #[test]
    fn after_running_out_of_frontiers_the_endgame_rule_leaves_far_scraps_of_unjudged_ground() {
        let at = Time::from_secs_f64;
        // The whole room known and judged but for a strip in its east half that only the
        // lidar saw (ground behind a rock, still to be judged).
        let whole = || {
            let mut map = room(false);
            for v in map.cells_mut() {
                if *v < 0 {
                    *v = 0;
                }
            }
            map
        };
        let mut scrap = whole();
        for y in 40..60 {
            for x in 85..88 {
                *scrap.get_mut(x, y).expect("inside") = realms_nav::frontier::UNJUDGED;
            }
        }
        let goal_after = |endgame: bool, ran_out: bool, from: Pose2| {
            let mut nav = Navigator::new(
                RoverId(1),
                NavigationConfig {
                    endgame_unjudged_must_pay: endgame,
                    ..NavigationConfig::new(Point2::new(1.0, 1.0))
                },
            );
            if ran_out {
                nav.on_map(at(0.0), &whole(), from);
                assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Home));
            }
            nav.on_map(at(3.0), &scrap, from);
            nav.goal().map(|g| g.1)
        };
        let far = Pose2::new(2.0, 5.0, 0.0);
        let near = Pose2::new(8.0, 5.0, 0.0);
        // Without the rule the rover drives 6 m for the strip; with it, it goes home.
        assert_eq!(goal_after(false, true, far), Some(GoalKind::Frontier));
        assert_eq!(goal_after(true, true, far), Some(GoalKind::Home));
        // A strip beside it is still worth the look ...
        assert_eq!(goal_after(true, true, near), Some(GoalKind::Frontier));
        // ... and before the rover first ran out of frontiers, so is the far one.
        assert_eq!(goal_after(true, false, far), Some(GoalKind::Frontier));
    }

    #[test]
    fn a_rover_whose_map_stops_growing_ends_exploring_and_goes_home() {
        let mut nav = navigator();
        // The east half stays unknown whatever the rover does: its frontier never clears.
        let map = room(false);
        let mut pose = Pose2::new(2.0, 5.0, 0.0);
        let mut went_home = None;
        for k in 0..4000 {
            let now = Time::from_secs_f64(k as f64 * 0.1);
            if nav.wants_map(now) {
                nav.on_map(now, &map, pose);
            }
            nav.steer(now, pose, 0.3, Guarded::default());
            // The rover drives straight at its goal, 3 cm a step.
            if let Some((goal, _)) = nav.goal() {
                let d = goal.distance_m(pose.position());
                if d > 0.05 {
                    let s = (0.03 / d).min(1.0);
                    pose = Pose2::new(
                        pose.x_m + s * (goal.x_m - pose.x_m),
                        pose.y_m + s * (goal.y_m - pose.y_m),
                        0.0,
                    );
                }
            }
            for e in nav.take_events() {
                if e.what.starts_with("no new ground") {
                    went_home.get_or_insert(e.t.as_secs_f64());
                }
            }
        }
        // Five minutes after the first map, at the next map after that (every 3 s).
        let t = went_home.expect("it gave exploring up");
        assert!((300.0..303.0).contains(&t), "at {t} s");
        // Home by the end, and it stays there.
        assert_eq!(nav.activity(), Activity::Done);
    }

    #[test]
    fn a_rover_sent_home_by_a_stalled_map_looks_for_no_frontier_on_the_way() {
        let mut nav = navigator();
        // The east half stays unknown whatever the rover does, until it has given up.
        let map = room(false);
        let pose = Pose2::new(2.0, 5.0, 0.0);
        let mut k = 0;
        while nav.goal().map(|g| g.1) != Some(GoalKind::Home) {
            let now = Time::from_secs_f64(k as f64);
            nav.on_map(now, &map, pose);
            k += 3;
            assert!(k < 400, "never sent home");
        }
        // On the way home the map grows by a strip of 3 m² beside the frontier: no longer
        // stalled, but the frontier is one driving up to does not map.
        let mut grown = map.clone();
        for y in 10..90 {
            for x in 50..54 {
                *grown.get_mut(x, y).expect("inside") = 0;
            }
        }
        nav.on_map(Time::from_secs_f64(k as f64), &grown, pose);
        assert_eq!(nav.goal().map(|g| g.1), Some(GoalKind::Home));
    }

    #[test]
    fn a_rover_that_makes_no_progress_backs_off_then_gives_the_goal_up() {
        let mut cfg = NavigationConfig::new(Point2::new(1.0, 1.0));
        // No deadline in the way: the recoveries are under test.
        cfg.goal_slack = Duration::from_secs(3600);
        let mut nav = Navigator::new(RoverId(1), cfg);
        let map = room(false);
        // The rover's wheels turn but it goes nowhere: its pose never changes.
        let pose = Pose2::new(2.0, 5.0, 0.0);
        let mut recoveries = Vec::new();
        let mut gave_up = None;
        for k in 0..3000 {
            let now = Time::from_secs_f64(k as f64 * 0.1);
            if nav.wants_map(now) {
                nav.on_map(now, &map, pose);
            }
            nav.steer(now, pose, 0.0, Guarded::default());
            for e in nav.take_events() {
                if e.what.starts_with("no progress") {
                    recoveries.push(e.t.as_secs_f64());
                }
                if e.what.starts_with("gave up Frontier") && gave_up.is_none() {
                    gave_up = Some((e.t.as_secs_f64(), e.what));
                }
            }
            if gave_up.is_some() {
                break;
            }
        }
        assert_eq!(recoveries.len(), 3, "{recoveries:?}");
        // Where it got stuck, just ahead of its front, is an obstacle in its maps since.
        let ahead = pose.transform_point(Point2::new(BUMP_AHEAD_M, 0.0));
        let costmap = nav.costmap.as_ref().expect("a costmap");
        assert_eq!(costmap.cost_at(ahead), realms_nav::costmap::LETHAL);
        assert_eq!(
            costmap.cost_at(Point2::new(2.0, 6.0)),
            0,
            "and nowhere else"
        );
        // The first attempt waits out the 20 s window.
        assert!((recoveries[0] - 19.0).abs() < 1.0, "{recoveries:?}");
        let (t, why) = gave_up.expect("the goal was given up");
        assert!(why.contains("no progress"), "{why}");
        assert!(t < 100.0, "gave up at {t} s");
        assert_eq!(nav.blacklist().len(), 1);
    }

    #[test]
    fn where_a_rover_got_stuck_is_an_obstacle_until_the_mark_expires() {
        let mut nav = navigator();
        let map = room(false);
        let pose = Pose2::new(2.0, 5.0, 0.0);
        let ahead = pose.transform_point(Point2::new(BUMP_AHEAD_M, 0.0));
        nav.on_map(Time::ZERO, &map, pose);
        let cost = |nav: &Navigator| nav.costmap.as_ref().expect("a costmap").cost_at(ahead);
        assert_eq!(cost(&nav), 0, "open ground before");
        nav.stuck(Time::from_secs_f64(10.0), pose);
        nav.on_map(Time::from_secs_f64(13.0), &map, pose);
        assert_eq!(cost(&nav), realms_nav::costmap::LETHAL);
        // The map itself is left as it was.
        assert_eq!(map.at_world(ahead), Some(&0));
        nav.on_map(Time::from_secs_f64(10.0) + BUMP_LIFETIME, &map, pose);
        assert_eq!(cost(&nav), 0, "forgotten after its lifetime");
    }
}
