//! Which frontier a rover should drive to next, decided by each rover alone from what it has
//! heard of its peers.
//!
//! A frontier is worth its length (what the rover will see there) less the cost of driving
//! to it; a stretch beside ground the lidar already saw, still to be judged by the depth
//! camera, is worth less than one beside unknown ground, so the map spreads first and the
//! ground is looked at on the way and after. Coordination follows Burgard et al., "Coordinated Multi-Robot Exploration" (IEEE
//! T-RO 21, 2005): a target a peer has claimed lowers the worth of every frontier near it, in
//! proportion to how much of it the peer will see, so rovers spread out without a central
//! allocator. Rovers that hear nothing from their peers still explore, only less well
//! (they may duplicate work). Targets the rover failed to reach are blacklisted.

use crate::frontier::Frontier;
use realms_core::{Cell, GridGeometry, Point2};

/// Exploration tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExploreConfig {
    /// Frontiers shorter than this many cells are noise.
    pub min_frontier_cells: usize,
    /// A metre of frontier is worth this many metres of (cost-weighted) driving.
    pub gain_per_m: f64,
    /// A frontier is only worth it up to this length, metres: a rover sees about this much
    /// of a long frontier from one spot.
    pub max_gain_m: f64,
    /// A metre of frontier beside ground only the lidar saw is worth this fraction of one
    /// beside unknown ground: there the rover adds the depth camera's verdict on a strip a
    /// few metres deep, where the lidar would map a wide new stretch.
    pub unjudged_gain_fraction: f64,
    /// A frontier beside no unknown ground (only ground the lidar saw, still to be judged)
    /// is a candidate only where it is worth more than the drive to it; frontiers beside
    /// unknown ground always are, the map must be whole. Without this a rover whose map is
    /// whole crosses and recrosses the hall for the last scraps of unjudged ground (the
    /// foot of a wall, behind a rock), a few square metres a visit. Not the rovers' default:
    /// over sixteen missions it cut them by a quarter with the same coverage, but the
    /// crater cells near the paths came out 4 points less marked (BENCHMARKS.md, "The
    /// missions' last quarter"; `realms bench missions --nav-variant unjudged-must-pay`).
    pub unjudged_must_pay: bool,
    /// A peer's target discounts frontiers within this distance, metres (about what the
    /// peer will map on arrival).
    pub peer_radius_m: f64,
    /// Frontiers within this distance of a blacklisted target are skipped, metres.
    pub blacklist_radius_m: f64,
}

/// A candidate whose worth peers' targets discount by this fraction or more is taken.
pub const TAKEN_FRACTION: f64 = 0.75;

impl Candidate {
    /// Whether a peer's target is so close that the peer will map it on its way.
    pub fn taken_by_peer(&self) -> bool {
        self.discount >= TAKEN_FRACTION * self.gain
    }
}

impl ExploreConfig {
    /// The most any frontier can be worth (a frontier of [`max_gain_m`](Self::max_gain_m)
    /// or longer), in the planner's cost.
    pub fn max_gain(&self) -> f64 {
        self.gain_per_m * self.max_gain_m
    }

    /// A single peer target this close to a frontier takes it (see
    /// [`Candidate::taken_by_peer`]), metres.
    pub fn taken_radius_m(&self) -> f64 {
        self.peer_radius_m * (1.0 - TAKEN_FRACTION)
    }
}

impl Default for ExploreConfig {
    fn default() -> Self {
        ExploreConfig {
            min_frontier_cells: 8,
            gain_per_m: 3.0,
            max_gain_m: 4.0,
            unjudged_gain_fraction: 0.25,
            unjudged_must_pay: false,
            peer_radius_m: 6.0,
            blacklist_radius_m: 1.0,
        }
    }
}

/// A candidate target, with how it was scored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Where to drive: the reachable frontier cell nearest the frontier's centroid.
    pub goal: Point2,
    /// Its cell.
    pub cell: Cell,
    /// The frontier's worth, metres of driving.
    pub gain: f64,
    /// How much of that worth peers' targets take away (0..=gain).
    pub discount: f64,
    /// Cost of the drive there (metres stretched by costs).
    pub travel: f64,
    /// Worth less cost less the peers' discount.
    pub utility: f64,
}

/// What the rover knows of the rest of the fleet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeerClaim {
    /// The target the peer said it is driving to.
    pub target: Point2,
}

/// Candidate targets from `frontiers` (of a map with geometry `geo`, found by
/// [`detect`](crate::frontier::detect) or a [`FrontierTracker`](crate::frontier::FrontierTracker)),
/// best first, given the travel costs from the rover's position (the Dijkstra field of
/// [`Planner::travel_costs`](crate::Planner::travel_costs) on the same map's costmap).
/// Unreachable and blacklisted frontiers are left out.
pub fn candidates(
    frontiers: &[Frontier],
    geo: &GridGeometry,
    travel: &[f32],
    peers: &[PeerClaim],
    blacklist: &[Point2],
    cfg: &ExploreConfig,
) -> Vec<Candidate> {
    let mut out: Vec<Candidate> = frontiers
        .iter()
        .filter_map(|f| score(f, geo, travel, peers, blacklist, cfg))
        .collect();
    out.sort_by(|a, b| b.utility.total_cmp(&a.utility).then(a.cell.cmp(&b.cell)));
    out
}

fn score(
    f: &Frontier,
    geo: &GridGeometry,
    travel: &[f32],
    peers: &[PeerClaim],
    blacklist: &[Point2],
    cfg: &ExploreConfig,
) -> Option<Candidate> {
    let cell = f
        .cells
        .iter()
        .filter(|c| travel[geo.index(**c)].is_finite())
        .min_by(|a, b| {
            let da = geo.cell_center(**a).distance_m(f.centroid);
            let db = geo.cell_center(**b).distance_m(f.centroid);
            da.total_cmp(&db).then(a.cmp(b))
        })
        .copied()?;
    let goal = geo.cell_center(cell);
    if blacklist
        .iter()
        .any(|b| b.distance_m(goal) < cfg.blacklist_radius_m)
    {
        return None;
    }
    let unjudged = f.cells.len() - f.beside_unknown;
    let length_m =
        (f.beside_unknown as f64 + cfg.unjudged_gain_fraction * unjudged as f64) * geo.resolution_m;
    let gain = (cfg.gain_per_m * length_m).min(cfg.max_gain());
    let discount: f64 = peers
        .iter()
        .map(|p| {
            let d = p.target.distance_m(goal);
            if d < cfg.peer_radius_m {
                gain * (1.0 - d / cfg.peer_radius_m)
            } else {
                0.0
            }
        })
        .sum::<f64>()
        .min(gain);
    let travel = travel[geo.index(cell)] as f64;
    // Worth against the drive alone: a peer heading there lowers the utility, but the rover
    // still waits on such a frontier in case the peer fails (see `Candidate::taken_by_peer`).
    if cfg.unjudged_must_pay && f.beside_unknown == 0 && gain <= travel {
        return None;
    }
    Some(Candidate {
        goal,
        cell,
        gain,
        discount,
        travel,
        utility: gain - discount - travel,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frontier::detect;
    use crate::planner::{Planner, PlannerConfig};
    use crate::{Costmap, CostmapConfig};
    use realms_core::Grid;

    /// The candidates of `map` with nobody's coverage to discount.
    fn candidates_of(
        map: &Grid<i8>,
        cm: &Costmap,
        travel: &[f32],
        peers: &[PeerClaim],
        blacklist: &[Point2],
        cfg: &ExploreConfig,
    ) -> Vec<Candidate> {
        let frontiers = detect(map, cm, cfg.min_frontier_cells, None);
        candidates(&frontiers, map.geometry(), travel, peers, blacklist, cfg)
    }

    /// A 20 x 4 m corridor known in its middle third, open to the unknown at both ends; the
    /// rover stands left of centre.
    fn corridor() -> (Grid<i8>, Costmap, Vec<f32>) {
        let g = GridGeometry {
            width: 200,
            height: 40,
            resolution_m: 0.1,
            origin: Point2::new(0.0, 0.0),
        };
        let mut map = Grid::new(g, -1i8);
        for y in 0..40 {
            for x in 70..130 {
                *map.get_mut(x, y).expect("inside") = if y == 0 || y == 39 { 100 } else { 0 };
            }
        }
        let cm = Costmap::from_map(&map, &CostmapConfig::default());
        let mut planner = Planner::new(PlannerConfig::default());
        let travel = planner
            .travel_costs(&cm, Point2::new(9.0, 2.0), true)
            .expect("inside");
        (map, cm, travel)
    }

    #[test]
    fn the_nearer_of_two_equal_frontiers_wins() {
        let (map, cm, travel) = corridor();
        let c = candidates_of(&map, &cm, &travel, &[], &[], &ExploreConfig::default());
        assert_eq!(c.len(), 2);
        assert!((c[0].goal.x_m - 7.05).abs() < 1e-9, "{c:?}");
        assert!((c[1].goal.x_m - 12.95).abs() < 1e-9, "{c:?}");
        assert!(c[0].utility > c[1].utility);
    }

    #[test]
    fn a_peer_s_claim_sends_the_rover_the_other_way() {
        let (map, cm, travel) = corridor();
        let cfg = ExploreConfig::default();
        let mine = candidates_of(&map, &cm, &travel, &[], &[], &cfg)[0];
        let peer = PeerClaim { target: mine.goal };
        let c = candidates_of(&map, &cm, &travel, &[peer], &[], &cfg);
        assert!((c[0].goal.x_m - 12.95).abs() < 1e-9, "{c:?}");
        assert_ne!(c[0].goal, peer.target);
    }

    #[test]
    fn a_blacklisted_target_is_not_offered_again() {
        let (map, cm, travel) = corridor();
        let c = candidates_of(
            &map,
            &cm,
            &travel,
            &[],
            &[Point2::new(7.05, 2.05)],
            &ExploreConfig::default(),
        );
        assert_eq!(c.len(), 1);
        assert!((c[0].goal.x_m - 12.95).abs() < 1e-9, "{c:?}");
    }

    /// With the corridor's whole west end seen by the lidar alone, a rover near its east end
    /// finds the judged edge to the west not worth the drive once unjudged ground must pay:
    /// only the edge to the unknown east is left. Beside it, the same west edge is worth it.
    #[test]
    fn unjudged_ground_must_be_worth_the_drive_when_it_must_pay() {
        let (mut map, cm, _) = corridor();
        for y in 0..40 {
            for x in 0..70 {
                *map.get_mut(x, y).expect("inside") = if y == 0 || y == 39 {
                    100
                } else {
                    crate::frontier::UNJUDGED
                };
            }
        }
        let mut planner = Planner::new(PlannerConfig::default());
        let pay = ExploreConfig {
            unjudged_must_pay: true,
            ..ExploreConfig::default()
        };
        let west = |c: &[Candidate]| c.iter().any(|c| (c.goal.x_m - 7.05).abs() < 1e-9);
        let east = |c: &[Candidate]| c.iter().any(|c| (c.goal.x_m - 12.95).abs() < 1e-9);

        let far = planner
            .travel_costs(&cm, Point2::new(12.5, 2.0), true)
            .expect("inside");
        let free = candidates_of(&map, &cm, &far, &[], &[], &ExploreConfig::default());
        assert!(west(&free) && east(&free), "{free:?}");
        let west_free = free.iter().find(|c| c.goal.x_m < 10.0).expect("west");
        assert!(west_free.utility < 0.0, "{west_free:?}");
        let paying = candidates_of(&map, &cm, &far, &[], &[], &pay);
        assert!(!west(&paying) && east(&paying), "{paying:?}");

        let near = planner
            .travel_costs(&cm, Point2::new(7.6, 2.0), true)
            .expect("inside");
        let paying = candidates_of(&map, &cm, &near, &[], &[], &pay);
        assert!(west(&paying) && east(&paying), "{paying:?}");
    }
}
