//! The full 2D SLAM (what `realms slam` runs): local tracking against submaps, keyframes in a
//! pose graph, and loop closures against finished submaps (the structure of Cartographer,
//! Hess et al., ICRA 2016, in miniature). Closures are verified by a match-score threshold
//! only so far; the benchmark figures are in BENCHMARKS.md.
//!
//! - Each submap keeps its grid in the frame of its first keyframe, so when the graph moves
//!   that keyframe the submap moves with it.
//! - Scans are tracked against the older of the (at most two) active submaps.
//! - A keyframe is added when the robot has moved enough; it is inserted into the active
//!   submaps and linked to the previous keyframe.
//! - Loop closure: for finished submaps near the current keyframe, a correlative grid search
//!   in a window around the current estimate, refined by Gauss-Newton, accepted only if the
//!   match scores high; accepted closures enter the graph as robust edges and the graph is
//!   re-optimised.

use crate::carmen::LaserReading;
use crate::frontend::FrontendConfig;
use crate::matcher::{MatcherConfig, MultiResMap, match_scan};
use crate::posegraph::{Edge, PoseGraph};
use crate::trajectory::StampedPose;
use realms_core::{Point2, Pose2};

/// Loop closures are searched at every this many keyframes.
const LOOP_EVERY_KEYFRAMES: usize = 4;
/// Accepted closures are folded into the graph at every this many keyframes.
const OPTIMIZE_EVERY_KEYFRAMES: usize = 20;
/// Candidate submaps searched per attempt (the nearest).
const LOOP_CANDIDATES: usize = 2;

/// SLAM tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapperConfig {
    /// Tracking (matcher, map resolution, range limits).
    pub frontend: FrontendConfig,
    /// A new keyframe after this much travel, metres.
    pub keyframe_translation_m: f64,
    /// ... or this much turning, radians.
    pub keyframe_rotation_rad: f64,
    /// Keyframes per submap.
    pub submap_keyframes: usize,
    /// Finished submaps whose origin is within this distance are searched for closures, m.
    pub loop_search_radius_m: f64,
    /// Half-width of the translation window of the closure search, metres.
    pub loop_window_m: f64,
    /// Half-width of the rotation window of the closure search, radians.
    pub loop_window_rad: f64,
    /// A closure is accepted only at or above this mean occupancy at the scan's endpoints.
    pub loop_min_score: f64,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            frontend: FrontendConfig::default(),
            keyframe_translation_m: 0.2,
            keyframe_rotation_rad: 6f64.to_radians(),
            submap_keyframes: 30,
            loop_search_radius_m: 5.0,
            loop_window_m: 1.0,
            loop_window_rad: 15f64.to_radians(),
            loop_min_score: 0.65,
        }
    }
}

#[derive(Debug)]
struct Submap {
    origin_node: usize,
    map: MultiResMap,
    keyframes: usize,
    finished: bool,
}

#[derive(Clone, Copy, Debug)]
struct ScanPose {
    timestamp_s: f64,
    keyframe: usize,
    keyframe_from_scan: Pose2,
}

/// The mapper.
#[derive(Debug)]
pub struct Mapper {
    cfg: MapperConfig,
    graph: PoseGraph,
    keyframe_points: Vec<Vec<Point2>>,
    submaps: Vec<Submap>,
    scans: Vec<ScanPose>,
    pose: Pose2,
    last_odom: Option<Pose2>,
    pending_closures: bool,
    /// Accepted loop closures.
    pub closures: usize,
}

impl Mapper {
    /// An empty mapper.
    pub fn new(cfg: MapperConfig) -> Self {
        Mapper {
            cfg,
            graph: PoseGraph::default(),
            keyframe_points: Vec::new(),
            submaps: Vec::new(),
            scans: Vec::new(),
            pose: Pose2::IDENTITY,
            last_odom: None,
            pending_closures: false,
            closures: 0,
        }
    }

    fn points(&self, scan: &LaserReading) -> Vec<Point2> {
        let f = &self.cfg.frontend;
        crate::frontend::scan_points(scan, f.min_range_m, f.max_range_m)
    }

    fn insert(&mut self, submap: usize, node: usize) {
        let origin = self.graph.nodes[self.submaps[submap].origin_node];
        let local = origin.inverse() * self.graph.nodes[node];
        let world: Vec<(Point2, bool)> = self.keyframe_points[node]
            .iter()
            .map(|p| (local.transform_point(*p), true))
            .collect();
        let s = &mut self.submaps[submap];
        s.map.insert(local.position(), &world);
        s.keyframes += 1;
    }

    /// Adds a scan.
    pub fn add_scan(&mut self, scan: &LaserReading) {
        let predicted = match self.last_odom {
            Some(prev) => self.pose * (prev.inverse() * scan.odom),
            None => scan.odom,
        };
        self.last_odom = Some(scan.odom);
        let points = self.points(scan);
        // Track against the older active submap, in its own frame.
        let tracking = self
            .submaps
            .iter()
            .position(|s| !s.finished && s.keyframes > 0);
        self.pose = match tracking {
            Some(i) if points.len() >= 10 => {
                let origin = self.graph.nodes[self.submaps[i].origin_node];
                let m = match_scan(
                    &self.submaps[i].map,
                    &points,
                    origin.inverse() * predicted,
                    &self.cfg.frontend.matcher,
                );
                origin * m.pose
            }
            _ => predicted,
        };
        let new_keyframe = match self.graph.nodes.last() {
            None => true,
            Some(last) => {
                let d = self.pose.relative_to(last);
                d.x_m.hypot(d.y_m) >= self.cfg.keyframe_translation_m
                    || d.yaw_rad.abs() >= self.cfg.keyframe_rotation_rad
            }
        };
        if new_keyframe && points.len() >= 10 {
            self.add_keyframe(points);
        }
        let keyframe = self.graph.nodes.len().saturating_sub(1);
        let kf_pose = self.graph.nodes.get(keyframe).copied().unwrap_or(self.pose);
        self.scans.push(ScanPose {
            timestamp_s: scan.timestamp_s,
            keyframe,
            keyframe_from_scan: kf_pose.inverse() * self.pose,
        });
    }

    fn add_keyframe(&mut self, points: Vec<Point2>) {
        let node = self.graph.nodes.len();
        self.graph.nodes.push(self.pose);
        self.keyframe_points.push(points);
        if node > 0 {
            let measurement = self.graph.nodes[node - 1].inverse() * self.pose;
            self.graph.edges.push(Edge {
                from: node - 1,
                to: node,
                measurement,
                information: [400.0, 400.0, 2500.0],
                robust: false,
            });
        }
        // Submaps: start one when there is none, a second halfway through the first, and
        // finish the older when it is full.
        let active: Vec<usize> = (0..self.submaps.len())
            .filter(|i| !self.submaps[*i].finished)
            .collect();
        let half = self.cfg.submap_keyframes / 2;
        if active.is_empty() || (active.len() == 1 && self.submaps[active[0]].keyframes >= half) {
            let f = &self.cfg.frontend;
            self.submaps.push(Submap {
                origin_node: node,
                map: MultiResMap::new(f.resolution_m, f.levels),
                keyframes: 0,
                finished: false,
            });
        }
        let active: Vec<usize> = (0..self.submaps.len())
            .filter(|i| !self.submaps[*i].finished)
            .collect();
        for s in active {
            self.insert(s, node);
            if self.submaps[s].keyframes >= self.cfg.submap_keyframes {
                self.submaps[s].finished = true;
            }
        }
        // Closures are searched every few keyframes and the graph re-optimised in batches:
        // both cost far more than tracking.
        if node.is_multiple_of(LOOP_EVERY_KEYFRAMES) && self.close_loops(node) {
            self.pending_closures = true;
        }
        if self.pending_closures && node.is_multiple_of(OPTIMIZE_EVERY_KEYFRAMES) {
            self.graph.optimize(3);
            self.pose = self.graph.nodes[node];
            self.pending_closures = false;
        }
    }

    /// Searches finished submaps near `node` for a closure; returns whether one was added.
    fn close_loops(&mut self, node: usize) -> bool {
        let pose = self.graph.nodes[node];
        let mut added = false;
        // The nearest finished submaps that do not contain this keyframe's neighbourhood.
        let mut candidates: Vec<(f64, usize)> = (0..self.submaps.len())
            .filter_map(|s| {
                let sub = &self.submaps[s];
                if !sub.finished || sub.origin_node + 2 * self.cfg.submap_keyframes > node {
                    return None;
                }
                let d = self.graph.nodes[sub.origin_node]
                    .position()
                    .distance_m(pose.position());
                (d <= self.cfg.loop_search_radius_m).then_some((d, s))
            })
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, s) in candidates.into_iter().take(LOOP_CANDIDATES) {
            let sub = &self.submaps[s];
            let origin = self.graph.nodes[sub.origin_node];
            let points = &self.keyframe_points[node];
            let prior = origin.inverse() * pose;
            let Some(found) = correlative_search(
                &sub.map,
                points,
                prior,
                self.cfg.loop_window_m,
                self.cfg.loop_window_rad,
            ) else {
                continue;
            };
            let refine = MatcherConfig {
                prior_translation_weight: 0.0,
                prior_rotation_weight: 0.0,
                ..self.cfg.frontend.matcher
            };
            let m = match_scan(&sub.map, points, found, &refine);
            if m.score >= self.cfg.loop_min_score {
                self.graph.edges.push(Edge {
                    from: sub.origin_node,
                    to: node,
                    measurement: m.pose,
                    information: [400.0, 400.0, 2500.0],
                    robust: true,
                });
                self.closures += 1;
                added = true;
            }
        }
        added
    }

    /// Every scan's pose, from the optimised keyframes.
    pub fn trajectory(&self) -> Vec<StampedPose> {
        self.scans
            .iter()
            .map(|s| StampedPose {
                timestamp_s: s.timestamp_s,
                pose: self
                    .graph
                    .nodes
                    .get(s.keyframe)
                    .map_or(s.keyframe_from_scan, |k| *k * s.keyframe_from_scan),
            })
            .collect()
    }

    /// A map of every keyframe at its optimised pose.
    pub fn render_map(&self) -> crate::occupancy::OccupancyGrid {
        let mut grid = crate::occupancy::OccupancyGrid::new(self.cfg.frontend.resolution_m);
        for (pose, points) in self.graph.nodes.iter().zip(&self.keyframe_points) {
            let world: Vec<(Point2, bool)> = points
                .iter()
                .map(|p| (pose.transform_point(*p), true))
                .collect();
            grid.insert(pose.position(), &world);
        }
        grid
    }

    /// Optimises the whole graph once more (at the end of a log).
    pub fn finish(&mut self) {
        self.graph.optimize(10);
    }
}

/// Best pose of `points` in `map` within a window around `prior`, by exhaustive search on the
/// coarsest level (cells as translation steps, rotation steps that move the farthest point by
/// about a cell); `None` if the map is empty there.
fn correlative_search(
    map: &MultiResMap,
    points: &[Point2],
    prior: Pose2,
    window_m: f64,
    window_rad: f64,
) -> Option<Pose2> {
    let coarse = map.coarsest();
    let step = coarse.resolution_m();
    // Rotation steps that move a point 8 m away by about a cell (farther points are few).
    let angle_step = (step / 8.0).max(0.5f64.to_radians());
    let n_t = (window_m / step).ceil() as i64;
    let n_a = (window_rad / angle_step).ceil() as i64;
    // Subsample for speed: every other point is plenty at the coarse level.
    let sample: Vec<Point2> = points.iter().step_by(2).copied().collect();
    let mut scored: Vec<(f64, i64, i64, i64)> = Vec::new();
    for ia in -n_a..=n_a {
        let yaw = prior.yaw_rad + ia as f64 * angle_step;
        let (s, c) = yaw.sin_cos();
        let rotated: Vec<(f64, f64)> = sample
            .iter()
            .map(|p| (c * p.x_m - s * p.y_m, s * p.x_m + c * p.y_m))
            .collect();
        for ix in -n_t..=n_t {
            for iy in -n_t..=n_t {
                let (x, y) = (prior.x_m + ix as f64 * step, prior.y_m + iy as f64 * step);
                let score: f64 = rotated
                    .iter()
                    .map(|(px, py)| {
                        coarse
                            .probability_and_gradient(Point2::new(x + px, y + py))
                            .0
                    })
                    .sum();
                scored.push((score, ix, iy, ia));
            }
        }
    }
    let &(best, bx, by, ba) = scored.iter().max_by(|a, b| a.0.total_cmp(&b.0))?;
    // Ambiguity: the best pose clearly away from the winner (corridors and repeated rooms
    // give near-ties, and those are the false closures).
    let rival = scored
        .iter()
        .filter(|(_, x, y, a)| (x - bx).abs() > 2 || (y - by).abs() > 2 || (a - ba).abs() > 3)
        .map(|s| s.0)
        .fold(f64::MIN, f64::max);
    let n = sample.len().max(1) as f64;
    let distinct = best - rival >= AMBIGUITY_MARGIN * n;
    let yaw = prior.yaw_rad + ba as f64 * angle_step;
    (best / n > 0.5 && distinct).then(|| {
        Pose2::new(
            prior.x_m + bx as f64 * step,
            prior.y_m + by as f64 * step,
            yaw,
        )
    })
}

/// How much better (in mean occupancy per point) the best closure pose must score than any
/// clearly different pose.
const AMBIGUITY_MARGIN: f64 = 0.03;
