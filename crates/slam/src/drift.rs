//! How far a rover's pose may be from the truth, for the covariance it publishes.
//!
//! A scan match says how well the scan fits the submap it was matched to: a centimetre or
//! two, whether the submap sits where the arena is or a metre off. What an operator (or a
//! planner, or a merge) needs is how far the pose may be from where the rover really is,
//! and that grows with the path that ties the pose to the start: each metre driven adds a
//! little drift, more where the scans did not pin the travel and the wheels carried it, and
//! a loop closure back to a place mapped earlier cuts the path short. So the uncertainty
//! here is the length of the shortest path through the pose graph from the start (a known
//! pose) to the newest keyframe, each edge weighted by the drift it can carry: Dijkstra's
//! projection of uncertainty through a graph of local frames, after Bosse, Newman, Leonard
//! and Teller, "Simultaneous Localization and Map Building in Large-Scale Cyclic
//! Environments Using the Atlas Framework" (IJRR 2004), with drift that grows linearly
//! along the path as a map's does (a heading off by a little turns everything after it).
//! The heading's own path runs to the nearest keyframe whose heading a wall measured
//! ([`crate::walls`]), or to the start.

use crate::posegraph::{Edge, PoseGraph};

/// How much drift each stretch of path can carry (standard deviations, growing linearly).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseUncertainty {
    /// Standard deviation at the start itself, and the least ever published, metres.
    pub floor_m: f64,
    /// Position drift per metre of path the scans matched, metres.
    pub per_m: f64,
    /// ... more per metre of travel the scans did not pin along the heading: the wheels
    /// carried it, and their slip is known only to a few per cent, metres.
    pub weak_per_m: f64,
    /// ... more per metre of travel no scan was matched on, metres.
    pub unmatched_per_m: f64,
    /// A loop closure stands for this much matched path, metres.
    pub closure_m: f64,
    /// Standard deviation of the heading where a wall or the start measured it, radians.
    pub heading_floor_rad: f64,
    /// Heading drift per metre of path from there, radians.
    pub heading_per_m_rad: f64,
}

/// What a stretch of the graph adds to the uncertainty.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Travel {
    /// Metres driven (for a closure: none, it is counted as [`PoseUncertainty::closure_m`]).
    pub driven_m: f64,
    /// Of which the scans did not pin along the heading.
    pub weak_m: f64,
    /// Of which no scan was matched.
    pub unmatched_m: f64,
}

impl PoseUncertainty {
    /// The position standard deviation `travel` adds, metres.
    pub fn position_m(&self, travel: Travel) -> f64 {
        self.per_m * travel.driven_m
            + self.weak_per_m * travel.weak_m
            + self.unmatched_per_m * travel.unmatched_m
    }

    /// The heading standard deviation `travel` adds, radians.
    pub fn heading_rad(&self, travel: Travel) -> f64 {
        self.heading_per_m_rad * travel.driven_m
    }

    fn closure(&self) -> Travel {
        Travel {
            driven_m: self.closure_m,
            ..Travel::default()
        }
    }
}

/// The uncertainty of every keyframe from the start, kept as the graph grows: keyframes
/// appended with their sequential edges extend it, and a closure (which can shorten any
/// path) has it worked out again. The mapper only ever appends to its graph's edges and
/// heading priors; anything else is searched again from scratch.
#[derive(Clone, Debug, Default)]
pub struct PathsFromStart {
    edges: usize,
    heading_anchors: usize,
    position_m: Vec<f64>,
    heading_rad: Vec<f64>,
}

impl PathsFromStart {
    /// The position and heading standard deviations of the newest keyframe of `graph`
    /// (`None` without one, or if no path reaches it), brought up to date; `travel` says
    /// what each sequential edge drove. The graph's heading priors anchor the heading.
    pub fn newest(
        &mut self,
        model: &PoseUncertainty,
        graph: &PoseGraph,
        travel: impl Fn(&Edge) -> Travel,
    ) -> Option<(f64, f64)> {
        let anchored = &graph.heading_priors;
        let n = graph.nodes.len();
        let newest = n.checked_sub(1)?;
        let known = self.position_m.len();
        let appended_only = self.edges <= graph.edges.len()
            && known <= n
            && graph.edges[self.edges..]
                .iter()
                .all(|e| !e.robust && e.to == e.from + 1 && e.to < n && e.to >= known)
            && anchored
                .get(self.heading_anchors..)
                .is_some_and(|new| new.iter().all(|p| p.node >= known));
        if appended_only && known > 0 {
            self.position_m.resize(n, f64::INFINITY);
            self.heading_rad.resize(n, f64::INFINITY);
            for p in &anchored[self.heading_anchors..] {
                self.heading_rad[p.node] = 0.0;
            }
            for e in &graph.edges[self.edges..] {
                let t = travel(e);
                let p = self.position_m[e.from] + model.position_m(t);
                self.position_m[e.to] = self.position_m[e.to].min(p);
                let h = self.heading_rad[e.from] + model.heading_rad(t);
                self.heading_rad[e.to] = self.heading_rad[e.to].min(h);
            }
        } else {
            let travel = &travel;
            let length = |of: fn(&PoseUncertainty, Travel) -> f64| {
                move |e: &Edge| {
                    if e.robust {
                        of(model, model.closure())
                    } else {
                        of(model, travel(e))
                    }
                }
            };
            self.position_m = graph.path_lengths_from(&[0], length(PoseUncertainty::position_m));
            let sources: Vec<usize> = std::iter::once(0)
                .chain(anchored.iter().map(|p| p.node))
                .collect();
            self.heading_rad =
                graph.path_lengths_from(&sources, length(PoseUncertainty::heading_rad));
        }
        self.edges = graph.edges.len();
        self.heading_anchors = anchored.len();
        // Every keyframe is joined to the one before, so the start reaches it; a graph
        // built otherwise gets no answer rather than an infinite one.
        let (position_m, heading_rad) = (self.position_m[newest], self.heading_rad[newest]);
        (position_m.is_finite() && heading_rad.is_finite()).then_some((
            model.floor_m + position_m,
            model.heading_floor_rad + heading_rad,
        ))
    }

    /// Each keyframe's position standard deviation from the start, less the model's floor,
    /// as the last call to [`newest`](Self::newest) left them (infinite where no path
    /// reached).
    pub fn position_m(&self) -> &[f64] {
        &self.position_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::posegraph::HeadingPrior;
    use realms_core::Pose2;

    fn model() -> PoseUncertainty {
        PoseUncertainty {
            floor_m: 0.01,
            per_m: 0.01,
            weak_per_m: 0.04,
            unmatched_per_m: 0.2,
            closure_m: 2.0,
            heading_floor_rad: 0.001,
            heading_per_m_rad: 0.002,
        }
    }

    /// A straight drive east in hops of 1 m: `n` keyframes.
    fn drive(n: usize) -> PoseGraph {
        let mut g = PoseGraph::default();
        for k in 0..n {
            g.nodes.push(Pose2::new(k as f64, 0.0, 0.0));
            if k > 0 {
                g.edges.push(sequential(k));
            }
        }
        g
    }

    fn sequential(to: usize) -> Edge {
        Edge {
            from: to - 1,
            to,
            measurement: Pose2::new(1.0, 0.0, 0.0),
            information: [1.0; 3],
            information_axis_rad: 0.0,
            robust: false,
        }
    }

    fn travel(weak_from: usize) -> impl Fn(&Edge) -> Travel {
        move |e: &Edge| Travel {
            driven_m: 1.0,
            weak_m: if e.to > weak_from { 1.0 } else { 0.0 },
            unmatched_m: 0.0,
        }
    }

    #[test]
    fn the_uncertainty_grows_along_the_path_and_a_closure_cuts_it_short() {
        let m = model();
        let mut graph = drive(11);
        let mut paths = PathsFromStart::default();
        // Ten metres driven, the last three unpinned along the heading.
        let (p, h) = paths
            .newest(&m, &graph, travel(7))
            .expect("the graph has keyframes");
        assert!((p - (0.01 + 10.0 * 0.01 + 3.0 * 0.04)).abs() < 1e-12, "{p}");
        assert!((h - (0.001 + 10.0 * 0.002)).abs() < 1e-12, "{h}");
        // Two more metres, extended without a search; a wall measured the heading at 11.
        for k in 11..13 {
            graph.nodes.push(Pose2::new(k as f64, 0.0, 0.0));
            graph.edges.push(sequential(k));
        }
        graph.heading_priors.push(HeadingPrior {
            node: 11,
            yaw_rad: 0.0,
            information: 1.0,
        });
        let (p, h) = paths
            .newest(&m, &graph, travel(7))
            .expect("the graph has keyframes");
        assert!((p - (0.01 + 12.0 * 0.01 + 5.0 * 0.04)).abs() < 1e-12, "{p}");
        assert!((h - (0.001 + 0.002)).abs() < 1e-12, "{h}");
        // A closure from the start to the newest: 2 m of matched path instead of 12.
        graph.edges.push(Edge {
            from: 0,
            to: 12,
            robust: true,
            ..sequential(12)
        });
        let (p, _) = paths
            .newest(&m, &graph, travel(7))
            .expect("the graph has keyframes");
        assert!((p - (0.01 + 2.0 * 0.01)).abs() < 1e-12, "{p}");
        // And the keyframes after it carry on from there, extended again.
        graph.nodes.push(Pose2::new(13.0, 0.0, 0.0));
        graph.edges.push(sequential(13));
        let extended = paths
            .newest(&m, &graph, travel(7))
            .expect("the graph has keyframes");
        let searched = PathsFromStart::default()
            .newest(&m, &graph, travel(7))
            .expect("the graph has keyframes");
        assert_eq!(extended, searched);
        assert!((extended.0 - (0.01 + 2.0 * 0.01 + 0.01 + 0.04)).abs() < 1e-12);
    }

    #[test]
    fn no_keyframe_or_no_path_no_uncertainty() {
        let mut graph = PoseGraph::default();
        let mut paths = PathsFromStart::default();
        assert_eq!(paths.newest(&model(), &graph, travel(0)), None);
        // A keyframe nothing joins to the start.
        graph.nodes = vec![Pose2::default(); 2];
        assert_eq!(paths.newest(&model(), &graph, travel(0)), None);
    }
}
