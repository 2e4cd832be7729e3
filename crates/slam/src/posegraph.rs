//! A 2D pose graph: poses as nodes, relative-pose measurements (odometry, scan matches, loop
//! closures) as edges, optimised by Gauss-Newton with a Huber loss on loop-closure edges so a
//! wrong closure cannot drag the whole map (Grisetti et al., "A Tutorial on Graph-Based SLAM",
//! 2010). The normal equations are block-sparse (3 x 3 blocks). They are solved exactly by
//! block elimination in minimum-degree order (the `elimination` module), or by conjugate
//! gradients preconditioned by block-Jacobi (each pose's own block) or by the chain of
//! consecutive poses solved exactly (subgraph preconditioning, after Dellaert, Carlson, Ila,
//! Ni & Thorpe, "Subgraph-preconditioned Conjugate Gradients for Large Scale SLAM", IROS
//! 2010). A graph is its odometry chain plus loop closures, so with the chain the iterations
//! only have to spread the closures; with block-Jacobi a chain of `n` poses needs about `n`
//! iterations, and the solve is capped before that on long missions.

use realms_core::Pose2;
use realms_core::geometry::normalize_angle_rad;

/// A measured relative pose between two nodes: `measurement = pose[from]^-1 * pose[to]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    /// Earlier node.
    pub from: usize,
    /// Later node.
    pub to: usize,
    /// Measured pose of `to` in the frame of `from`.
    pub measurement: Pose2,
    /// Information (inverse variance) of x, y and theta.
    pub information: [f64; 3],
    /// The axes of the x and y information, turned this far from the measured pose's own
    /// (0: along them). A match pinned firmly across a wall and loosely along it has
    /// information along the wall's axes, not the robot's.
    pub information_axis_rad: f64,
    /// Loop closures get a robust (Huber) loss; sequential edges do not.
    pub robust: bool,
}

/// A heading measured for one node against a fixed reference, not against another node
/// (a wall along a direction seen from the start, [`crate::walls`]). Weighted by the graph's
/// robust loss, as loop closures are: a run that is not the wall it seemed cannot drag the
/// map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeadingPrior {
    /// The node.
    pub node: usize,
    /// Its measured heading, radians.
    pub yaw_rad: f64,
    /// Information (inverse variance) of that heading, 1 / rad^2.
    pub information: f64,
}

/// The graph.
#[derive(Clone, Debug, Default)]
pub struct PoseGraph {
    /// Node poses; node 0 is held fixed.
    pub nodes: Vec<Pose2>,
    /// Constraints.
    pub edges: Vec<Edge>,
    /// Headings measured node by node against a fixed reference.
    pub heading_priors: Vec<HeadingPrior>,
    /// How each Gauss-Newton step's linear system is solved.
    pub solver: GraphSolver,
    /// How loop closures that disagree with the rest of the graph are discounted.
    pub loss: RobustLoss,
}

/// The robust loss on loop-closure edges, applied as a weight on the edge's information at
/// each Gauss-Newton step (iteratively reweighted least squares), by the squared
/// Mahalanobis length `chi2` of its residual.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum RobustLoss {
    /// Huber's, at one standard deviation: weight `1 / sqrt(chi2)` beyond it. A closure a
    /// metre off still pulls with a twentieth of its weight.
    #[default]
    Huber,
    /// Dynamic covariance scaling (Agarwal, Tipaldi, Spinello, Stachniss & Burgard, "Robust
    /// Map Optimization Using Dynamic Covariance Scaling", ICRA 2013): weight
    /// `(2 phi / (phi + chi2))^2` beyond `chi2 = phi`, which falls with the fourth power of
    /// the error, so a closure that disagrees with the rest by far all but drops out.
    DynamicCovarianceScaling {
        /// Where the discount starts, in `chi2`.
        phi: f64,
    },
}

impl RobustLoss {
    /// The weight on an edge's information at squared Mahalanobis length `chi2`.
    fn weight(&self, chi2: f64) -> f64 {
        match *self {
            RobustLoss::Huber => {
                if chi2.sqrt() > HUBER_K {
                    HUBER_K / chi2.sqrt()
                } else {
                    1.0
                }
            }
            RobustLoss::DynamicCovarianceScaling { phi } => {
                let s = (2.0 * phi / (phi + chi2)).min(1.0);
                s * s
            }
        }
    }
}

/// How each Gauss-Newton step's linear system is solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GraphSolver {
    /// Each pose's own 3 x 3 block inverted: cheap, but a chain of `n` poses needs about
    /// `n` iterations to carry a correction from one end to the other, and the solve stops
    /// at 500. On the recorded logs that partial solve is the better map (BENCHMARKS.md).
    #[default]
    BlockJacobi,
    /// The block-tridiagonal part (each pose with its neighbours in the sequence) solved
    /// exactly: corrections travel along the chain in one iteration, and the solve reaches
    /// the optimum on graphs of any length.
    Chain,
    /// Exactly, by block elimination in minimum-degree order (the `elimination` module): the
    /// optimum of each step without the iterations' hundreds of passes over every edge.
    /// Falls back to the chain if the system is not positive definite.
    Elimination,
}

impl PoseGraph {
    /// An edge's length for [`PoseGraph::path_length_within`]: a sequential edge counts its
    /// measured translation, a robust edge (a loop closure) `closure_m`.
    pub fn travelled_m(edge: &Edge, closure_m: f64) -> f64 {
        if edge.robust {
            closure_m
        } else {
            edge.measurement.x_m.hypot(edge.measurement.y_m)
        }
    }

    /// The length of the shortest path from node `a` to node `b` through the graph, if it is
    /// at most `limit_m`, each edge counting `edge_length_m(edge)` (see
    /// [`PoseGraph::travelled_m`]). Dijkstra's search, abandoned past the limit. Each call
    /// rebuilds the adjacency from every edge, so it suits occasional questions (the mapper
    /// asks only about closures that want more than a small correction), not one per scan.
    pub fn path_length_within(
        &self,
        a: usize,
        b: usize,
        limit_m: f64,
        edge_length_m: impl Fn(&Edge) -> f64,
    ) -> Option<f64> {
        let n = self.nodes.len();
        if a >= n || b >= n {
            return None;
        }
        let mut reached = None;
        self.shortest_paths(&[a], limit_m, edge_length_m, |node, d| {
            if node == b {
                reached = Some(d);
                return true;
            }
            false
        });
        reached
    }

    /// The length of the shortest path through the graph from the nearest of `sources` to
    /// every node (infinite where none leads), each edge counting `edge_length_m(edge)`:
    /// Dijkstra's search from all of them at once.
    pub fn path_lengths_from(
        &self,
        sources: &[usize],
        edge_length_m: impl Fn(&Edge) -> f64,
    ) -> Vec<f64> {
        self.shortest_paths(sources, f64::INFINITY, edge_length_m, |_, _| false)
    }

    /// Dijkstra's search from `sources` over paths of at most `limit_m`, calling `settled`
    /// with each node as its length becomes final, and stopping when it returns true;
    /// returns the lengths found (infinite where not reached).
    fn shortest_paths(
        &self,
        sources: &[usize],
        limit_m: f64,
        edge_length_m: impl Fn(&Edge) -> f64,
        mut settled: impl FnMut(usize, f64) -> bool,
    ) -> Vec<f64> {
        use std::cmp::Reverse;
        use std::collections::BinaryHeap;
        let n = self.nodes.len();
        // The adjacency in two flat arrays (node `k`'s neighbours are
        // `neighbours[start[k]..start[k + 1]]`, in the order of the edges): a list per node
        // cost more in allocations than the search itself. Each neighbour keeps its edge, and
        // an edge's length is asked only when the search reaches it: the search abandoned at
        // the limit reaches few, and the length (a root, for a sequential edge) cost more
        // than the rest of the build.
        let within = |e: &&Edge| e.from < n && e.to < n;
        let mut start = vec![0usize; n + 1];
        for e in self.edges.iter().filter(within) {
            start[e.from + 1] += 1;
            start[e.to + 1] += 1;
        }
        for k in 0..n {
            start[k + 1] += start[k];
        }
        let mut neighbours = vec![(0usize, 0usize); start[n]];
        let mut filled = start.clone();
        for (i, e) in self.edges.iter().enumerate().filter(|(_, e)| within(e)) {
            neighbours[filled[e.from]] = (e.to, i);
            filled[e.from] += 1;
            neighbours[filled[e.to]] = (e.from, i);
            filled[e.to] += 1;
        }
        let mut best = vec![f64::INFINITY; n];
        let mut frontier = BinaryHeap::new();
        for &a in sources.iter().filter(|a| **a < n) {
            best[a] = 0.0;
            // Lengths are non-negative, so their bit patterns order like the numbers.
            frontier.push(Reverse((0f64.to_bits(), a)));
        }
        while let Some(Reverse((bits, node))) = frontier.pop() {
            let d = f64::from_bits(bits);
            if d > best[node] {
                continue;
            }
            if settled(node, d) {
                break;
            }
            for &(next, edge) in &neighbours[start[node]..start[node + 1]] {
                let via = d + edge_length_m(&self.edges[edge]);
                if via <= limit_m && via < best[next] {
                    best[next] = via;
                    frontier.push(Reverse((via.to_bits(), next)));
                }
            }
        }
        best
    }
}

/// Huber threshold on the Mahalanobis length of a residual.
const HUBER_K: f64 = 1.0;

pub(crate) type Block = [[f64; 3]; 3];

/// `e = z^-1 (+) (x_i^-1 (+) x_j)` and its Jacobians with respect to `x_i` and `x_j`.
fn residual(xi: &Pose2, xj: &Pose2, z: &Pose2) -> ([f64; 3], Block, Block) {
    let (si, ci) = xi.yaw_rad.sin_cos();
    let (sz, cz) = z.yaw_rad.sin_cos();
    let (dx, dy) = (xj.x_m - xi.x_m, xj.y_m - xi.y_m);
    // R_i^T (t_j - t_i)
    let (lx, ly) = (ci * dx + si * dy, -si * dx + ci * dy);
    let (ux, uy) = (lx - z.x_m, ly - z.y_m);
    let e = [
        cz * ux + sz * uy,
        -sz * ux + cz * uy,
        normalize_angle_rad(xj.yaw_rad - xi.yaw_rad - z.yaw_rad),
    ];
    // M = R_z^T R_i^T; d(R_i^T)/dtheta_i (t_j - t_i) = (-si dx + ci dy, -ci dx - si dy) = (ly, -lx)
    let m = [
        [cz * ci - sz * si, cz * si + sz * ci],
        [-sz * ci + cz * -si, -sz * si + cz * ci],
    ];
    let d = [cz * ly + sz * -lx, -sz * ly + cz * -lx];
    let a = [
        [-m[0][0], -m[0][1], d[0]],
        [-m[1][0], -m[1][1], d[1]],
        [0.0, 0.0, -1.0],
    ];
    let b = [
        [m[0][0], m[0][1], 0.0],
        [m[1][0], m[1][1], 0.0],
        [0.0, 0.0, 1.0],
    ];
    (e, a, b)
}

/// [`residual`] of edge `e` at the nodes' poses now, its x and y rows turned onto the axes
/// of the edge's information.
fn edge_residual(nodes: &[Pose2], e: &Edge) -> ([f64; 3], Block, Block) {
    let (mut r, mut a, mut b) = residual(&nodes[e.from], &nodes[e.to], &e.measurement);
    if e.information_axis_rad != 0.0 {
        let (s, c) = e.information_axis_rad.sin_cos();
        let turn = |u: f64, v: f64| (c * u + s * v, -s * u + c * v);
        (r[0], r[1]) = turn(r[0], r[1]);
        for m in [&mut a, &mut b] {
            let [x, y, _] = m;
            for (u, v) in x.iter_mut().zip(y.iter_mut()) {
                (*u, *v) = turn(*u, *v);
            }
        }
    }
    (r, a, b)
}

fn at_w_b(a: &Block, w: &[f64; 3], b: &Block) -> Block {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[k][r] * w[k] * b[k][c]).sum();
        }
    }
    out
}

pub(crate) fn add_block(m: &mut Block, d: &Block) {
    for r in 0..3 {
        for c in 0..3 {
            m[r][c] += d[r][c];
        }
    }
}

impl PoseGraph {
    /// The squared Mahalanobis error of `edge` at the nodes' poses now (no robust weight).
    pub fn edge_error2(&self, edge: &Edge) -> f64 {
        let (r, _, _) = edge_residual(&self.nodes, edge);
        (0..3).map(|k| r[k] * r[k] * edge.information[k]).sum()
    }

    /// Drops the robust edges (loop closures) whose squared Mahalanobis error at the
    /// nodes' poses now exceeds `limit`; returns how many went. After an optimisation these
    /// are the closures the rest of the graph disagrees with.
    pub fn drop_robust_edges_beyond(&mut self, limit: f64) -> usize {
        let edges = std::mem::take(&mut self.edges);
        let before = edges.len();
        self.edges = edges
            .into_iter()
            .filter(|e| !e.robust || self.edge_error2(e) <= limit)
            .collect();
        before - self.edges.len()
    }

    /// The total weighted squared error (robust edges and heading priors Huber-weighted).
    pub fn chi2(&self) -> f64 {
        let huber = |m2: f64| {
            if m2.sqrt() > HUBER_K {
                2.0 * HUBER_K * m2.sqrt() - HUBER_K * HUBER_K
            } else {
                m2
            }
        };
        let edges: f64 = self
            .edges
            .iter()
            .map(|e| {
                let m2 = self.edge_error2(e);
                if e.robust { huber(m2) } else { m2 }
            })
            .sum();
        let priors: f64 = self
            .heading_priors
            .iter()
            .filter_map(|p| self.heading_prior_error2(p))
            .map(huber)
            .sum();
        edges + priors
    }

    /// The squared Mahalanobis error of `prior` at its node's heading now (`None` if the
    /// node does not exist).
    pub fn heading_prior_error2(&self, prior: &HeadingPrior) -> Option<f64> {
        let node = self.nodes.get(prior.node)?;
        let r = normalize_angle_rad(node.yaw_rad - prior.yaw_rad);
        Some(r * r * prior.information)
    }

    /// Runs up to `iterations` Gauss-Newton steps; stops early when a step changes nothing.
    pub fn optimize(&mut self, iterations: usize) {
        self.optimize_with_later_cap(iterations, usize::MAX);
    }

    /// [`optimize`](Self::optimize), the iterative solvers' steps after the first capped
    /// at `later_cap` iterations: the first step makes the large correction, the later
    /// ones refine it.
    pub fn optimize_with_later_cap(&mut self, iterations: usize, later_cap: usize) {
        let n = self.nodes.len();
        if n < 2 {
            return;
        }
        for step in 0..iterations {
            let mut diag = vec![[[0.0; 3]; 3]; n];
            // Off-diagonal blocks: (i, j, H_ij) with i != j; H_ji is its transpose.
            let mut off: Vec<(usize, usize, Block)> = Vec::with_capacity(self.edges.len());
            let mut g = vec![[0.0; 3]; n];
            for e in &self.edges {
                if e.from >= n || e.to >= n || e.from == e.to {
                    continue;
                }
                let (r, a, b) = edge_residual(&self.nodes, e);
                let m2: f64 = (0..3).map(|k| r[k] * r[k] * e.information[k]).sum();
                let scale = if e.robust { self.loss.weight(m2) } else { 1.0 };
                let w = [
                    e.information[0] * scale,
                    e.information[1] * scale,
                    e.information[2] * scale,
                ];
                add_block(&mut diag[e.from], &at_w_b(&a, &w, &a));
                add_block(&mut diag[e.to], &at_w_b(&b, &w, &b));
                off.push((e.from, e.to, at_w_b(&a, &w, &b)));
                for c in 0..3 {
                    g[e.from][c] += (0..3).map(|k| a[k][c] * w[k] * r[k]).sum::<f64>();
                    g[e.to][c] += (0..3).map(|k| b[k][c] * w[k] * r[k]).sum::<f64>();
                }
            }
            for p in &self.heading_priors {
                if p.node >= n {
                    continue;
                }
                let r = normalize_angle_rad(self.nodes[p.node].yaw_rad - p.yaw_rad);
                let w = p.information * self.loss.weight(r * r * p.information);
                diag[p.node][2][2] += w;
                g[p.node][2] += w * r;
            }
            // Hold node 0 where it is.
            for (k, row) in diag[0].iter_mut().enumerate() {
                row[k] += 1e9;
            }
            let rhs: Vec<[f64; 3]> = g.iter().map(|v| [-v[0], -v[1], -v[2]]).collect();
            // Capped: with block-Jacobi, a few hundred iterations resolve the large-scale
            // correction and later Gauss-Newton steps refine; the chain needs far fewer.
            let cap = (4 * n + 100).min(500);
            let cap = if step == 0 { cap } else { cap.min(later_cap) };
            let chain_solve = || {
                let chain = ChainFactor::new(&diag, &off);
                conjugate_gradient(&diag, &off, &rhs, 1e-10, cap, |r, z| chain.solve_into(r, z))
            };
            let step = match self.solver {
                GraphSolver::BlockJacobi => {
                    let pre: Vec<Block> = diag.iter().map(invert).collect();
                    conjugate_gradient(&diag, &off, &rhs, 1e-10, cap, |r, z| {
                        block_jacobi(&pre, r, z)
                    })
                }
                GraphSolver::Chain => chain_solve(),
                GraphSolver::Elimination => {
                    crate::elimination::solve(&diag, &off, &rhs).unwrap_or_else(chain_solve)
                }
            };
            let mut largest = 0.0f64;
            for (p, d) in self.nodes.iter_mut().zip(&step) {
                *p = Pose2::new(p.x_m + d[0], p.y_m + d[1], p.yaw_rad + d[2]);
                largest = largest.max(d[0].abs()).max(d[1].abs()).max(d[2].abs());
            }
            if largest < 1e-6 {
                break;
            }
        }
    }
}

/// `y = H x` for the block-sparse symmetric H, into `y` (as long as `x`).
fn multiply_into(
    diag: &[Block],
    off: &[(usize, usize, Block)],
    x: &[[f64; 3]],
    y: &mut [[f64; 3]],
) {
    for ((o, d), v) in y.iter_mut().zip(diag).zip(x) {
        for (r, out) in o.iter_mut().enumerate() {
            *out = (0..3).map(|c| d[r][c] * v[c]).sum();
        }
    }
    // `off` never holds a node's edge to itself, so each edge's two rows are apart.
    for (i, j, h) in off {
        let (xi, xj) = (x[*i], x[*j]);
        let (mut yi, mut yj) = (y[*i], y[*j]);
        for r in 0..3 {
            yi[r] += (0..3).map(|c| h[r][c] * xj[c]).sum::<f64>();
            yj[r] += (0..3).map(|c| h[c][r] * xi[c]).sum::<f64>();
        }
        y[*i] = yi;
        y[*j] = yj;
    }
}

fn dot(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(u, v)| u[0] * v[0] + u[1] * v[1] + u[2] * v[2])
        .sum()
}

/// Inverts a symmetric positive definite 3 x 3 block (identity if singular).
pub(crate) fn invert(m: &Block) -> Block {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if det.abs() < 1e-300 {
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    }
    let c =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    [
        [
            c(1, 2, 1, 2) / det,
            -c(0, 2, 1, 2) / det,
            c(0, 1, 1, 2) / det,
        ],
        [
            -c(1, 2, 0, 2) / det,
            c(0, 2, 0, 2) / det,
            -c(0, 1, 0, 2) / det,
        ],
        [
            c(1, 2, 0, 1) / det,
            -c(0, 2, 0, 1) / det,
            c(0, 1, 0, 1) / det,
        ],
    ]
}

/// `m v` for a 3 x 3 block.
pub(crate) fn block_times(m: &Block, v: &[f64; 3]) -> [f64; 3] {
    let mut o = [0.0; 3];
    for (i, out) in o.iter_mut().enumerate() {
        *out = (0..3).map(|c| m[i][c] * v[c]).sum();
    }
    o
}

/// `m^T v` for a 3 x 3 block.
pub(crate) fn block_transpose_times(m: &Block, v: &[f64; 3]) -> [f64; 3] {
    let mut o = [0.0; 3];
    for (i, out) in o.iter_mut().enumerate() {
        *out = (0..3).map(|c| m[c][i] * v[c]).sum();
    }
    o
}

/// `a b` for 3 x 3 blocks.
pub(crate) fn block_product(a: &Block, b: &Block) -> Block {
    let mut o = [[0.0; 3]; 3];
    for (r, row) in o.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    o
}

pub(crate) fn transpose(m: &Block) -> Block {
    let mut o = [[0.0; 3]; 3];
    for (r, row) in o.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = m[c][r];
        }
    }
    o
}

/// The block-Jacobi preconditioner applied: each block's inverse `pre[i]` times `r[i]`,
/// into `z`; returns `r . z`, summed pose by pose as [`dot`] sums.
fn block_jacobi(pre: &[Block], r: &[[f64; 3]], z: &mut [[f64; 3]]) -> f64 {
    let mut rz = 0.0;
    for ((z, p), v) in z.iter_mut().zip(pre).zip(r) {
        let zi = block_times(p, v);
        *z = zi;
        rz += v[0] * zi[0] + v[1] * zi[1] + v[2] * zi[2];
    }
    rz
}

/// The block-tridiagonal part of the normal equations, factored: every diagonal block, and
/// the blocks between consecutive poses. The rest (loop closures' off-diagonal blocks) is
/// left to the iterations. It is positive definite whenever the whole system is: each
/// edge between consecutive poses is kept whole, and every other edge keeps its diagonal
/// blocks, which are positive semi-definite on their own.
struct ChainFactor {
    /// `D_i^-1` of the block LDL^T factorisation (the block Thomas algorithm).
    d_inv: Vec<Block>,
    /// `U_i = H_(i-1, i)`, the block above the diagonal in row `i - 1` (zero for `i = 0`).
    upper: Vec<Block>,
}

impl ChainFactor {
    fn new(diag: &[Block], off: &[(usize, usize, Block)]) -> Self {
        let n = diag.len();
        let mut upper = vec![[[0.0; 3]; 3]; n];
        for (i, j, h) in off {
            if *j == i + 1 {
                add_block(&mut upper[*j], h);
            } else if *i == j + 1 {
                add_block(&mut upper[*i], &transpose(h));
            }
        }
        let mut d_inv: Vec<Block> = Vec::with_capacity(n);
        for i in 0..n {
            let mut d = diag[i];
            if i > 0 {
                // D_i = H_ii - U_i^T D_(i-1)^-1 U_i
                let s = block_product(
                    &transpose(&upper[i]),
                    &block_product(&d_inv[i - 1], &upper[i]),
                );
                for r in 0..3 {
                    for c in 0..3 {
                        d[r][c] -= s[r][c];
                    }
                }
            }
            d_inv.push(invert(&d));
        }
        ChainFactor { d_inv, upper }
    }

    /// Solves the tridiagonal system for `r`, into `out`; returns `r . out`.
    fn solve_into(&self, r: &[[f64; 3]], out: &mut [[f64; 3]]) -> f64 {
        out.copy_from_slice(&self.solve(r));
        dot(r, out)
    }

    /// Solves the tridiagonal system for `r`.
    fn solve(&self, r: &[[f64; 3]]) -> Vec<[f64; 3]> {
        let n = r.len();
        // Forward: y_i = r_i - U_i^T D_(i-1)^-1 y_(i-1).
        let mut y = r.to_vec();
        for i in 1..n {
            let s =
                block_transpose_times(&self.upper[i], &block_times(&self.d_inv[i - 1], &y[i - 1]));
            for c in 0..3 {
                y[i][c] -= s[c];
            }
        }
        // Backward: x_i = D_i^-1 (y_i - U_(i+1) x_(i+1)).
        let mut x = vec![[0.0; 3]; n];
        for i in (0..n).rev() {
            let mut v = y[i];
            if i + 1 < n {
                let s = block_times(&self.upper[i + 1], &x[i + 1]);
                for c in 0..3 {
                    v[c] -= s[c];
                }
            }
            x[i] = block_times(&self.d_inv[i], &v);
        }
        x
    }
}

/// Preconditioned conjugate gradients for H x = b, `apply_pre(r, z)` writing the
/// preconditioner's inverse applied to `r` into `z` and returning `r . z`. The iterations'
/// vectors are kept and written in place: a graph of a few thousand poses runs hundreds of
/// them per solve.
fn conjugate_gradient(
    diag: &[Block],
    off: &[(usize, usize, Block)],
    b: &[[f64; 3]],
    tol: f64,
    max_iter: usize,
    apply_pre: impl Fn(&[[f64; 3]], &mut [[f64; 3]]) -> f64,
) -> Vec<[f64; 3]> {
    let n = b.len();
    let mut x = vec![[0.0; 3]; n];
    let mut r = b.to_vec();
    let mut z = vec![[0.0; 3]; n];
    let mut rz = apply_pre(&r, &mut z);
    let mut p = z.clone();
    let mut hp = vec![[0.0; 3]; n];
    let b_norm = dot(b, b).sqrt().max(1e-300);
    let mut rr = dot(&r, &r);
    for _ in 0..max_iter {
        if rr.sqrt() <= tol * b_norm {
            break;
        }
        multiply_into(diag, off, &p, &mut hp);
        let php = dot(&p, &hp);
        if php <= 0.0 {
            break;
        }
        let alpha = rz / php;
        // The next residual's squared norm summed as it is made, in `dot`'s order.
        rr = 0.0;
        for i in 0..n {
            // Summed from the values in hand, not read back from memory: reading a whole
            // residual just written element by element stalled on every pose.
            let mut ri = r[i];
            for c in 0..3 {
                x[i][c] += alpha * p[i][c];
                ri[c] -= alpha * hp[i][c];
            }
            r[i] = ri;
            rr += ri[0] * ri[0] + ri[1] * ri[1] + ri[2] * ri[2];
        }
        let rz_new = apply_pre(&r, &mut z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            for c in 0..3 {
                p[i][c] = z[i][c] + beta * p[i][c];
            }
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn odometry_edge(from: usize, m: Pose2) -> Edge {
        Edge {
            from,
            to: from + 1,
            measurement: m,
            information: [100.0, 100.0, 400.0],
            information_axis_rad: 0.0,
            robust: false,
        }
    }

    #[test]
    fn path_length_takes_closures_as_shortcuts_and_stops_at_the_limit() {
        let hop = |e: &Edge| PoseGraph::travelled_m(e, 2.0);
        let mut graph = PoseGraph {
            nodes: vec![Pose2::IDENTITY; 11],
            edges: (0..10)
                .map(|k| odometry_edge(k, Pose2::new(1.0, 0.0, 0.0)))
                .collect(),
            ..PoseGraph::default()
        };
        assert_eq!(graph.path_length_within(0, 10, 100.0, hop), Some(10.0));
        assert_eq!(graph.path_length_within(10, 3, 100.0, hop), Some(7.0));
        assert_eq!(graph.path_length_within(0, 10, 9.5, hop), None);
        // A closure from node 1 to node 9: 1 + 2 + 1 beats the 10 m along the chain.
        graph.edges.push(Edge {
            from: 1,
            to: 9,
            measurement: Pose2::new(8.0, 0.0, 0.0),
            information: [400.0, 400.0, 2500.0],
            information_axis_rad: 0.0,
            robust: true,
        });
        assert_eq!(graph.path_length_within(0, 10, 100.0, hop), Some(4.0));
        assert_eq!(graph.path_length_within(0, 10, 3.9, hop), None);
        assert_eq!(graph.path_length_within(0, 11, 100.0, hop), None);
    }

    #[test]
    fn heading_priors_hold_a_drifting_chain_and_a_wrong_one_is_discounted() {
        // A straight chain of 40 steps whose odometry turns 0.2 degrees a step that the
        // robot did not: by the end it faces 7.8 degrees off. Its heading information is a
        // gyro's over a second (the rovers' keyframe edges).
        let drift = 0.2f64.to_radians();
        let mut graph = PoseGraph {
            nodes: vec![Pose2::IDENTITY],
            ..PoseGraph::default()
        };
        for k in 0..40 {
            let measured = Pose2::new(1.0, 0.0, drift);
            let last = *graph.nodes.last().expect("seeded");
            graph.nodes.push(last * measured);
            graph.edges.push(Edge {
                information: [100.0, 100.0, 1e5],
                ..odometry_edge(k, measured)
            });
        }
        let heading_error = |g: &PoseGraph| {
            g.nodes
                .iter()
                .map(|p| normalize_angle_rad(p.yaw_rad).abs())
                .fold(0.0, f64::max)
        };
        let mut free = graph.clone();
        free.optimize(5);
        assert!(heading_error(&free) > 7f64.to_radians());
        // Every fourth node's true heading (0) measured to 0.1 degree.
        let sigma = 0.1f64.to_radians();
        for node in (4..=40).step_by(4) {
            graph.heading_priors.push(HeadingPrior {
                node,
                yaw_rad: 0.0,
                information: 1.0 / (sigma * sigma),
            });
        }
        let mut held = graph.clone();
        held.optimize(5);
        let err = heading_error(&held);
        assert!(err < 0.5f64.to_radians(), "{}", err.to_degrees());
        assert!(held.chi2().is_finite());
        // One more, 3 degrees off at node 22 (a run that was not the wall it seemed): the
        // loss caps its pull, so it turns its node by far less than it claims.
        graph.heading_priors.push(HeadingPrior {
            node: 22,
            yaw_rad: 3f64.to_radians(),
            information: 1.0 / (sigma * sigma),
        });
        graph.optimize(5);
        let turned = normalize_angle_rad(graph.nodes[22].yaw_rad).abs();
        assert!(turned < 1f64.to_radians(), "{}", turned.to_degrees());
        assert!(heading_error(&graph) < 1f64.to_radians());
    }

    /// A square loop of 4 x 10 steps of 1 m, odometry turning 2 % too little at each corner
    /// and stretching 3 % along each side.
    fn drifting_square() -> (Vec<Pose2>, PoseGraph) {
        let mut truth = vec![Pose2::IDENTITY];
        let mut graph = PoseGraph {
            nodes: vec![Pose2::IDENTITY],
            edges: Vec::new(),
            ..PoseGraph::default()
        };
        for k in 0..40 {
            let turn = if k % 10 == 9 {
                std::f64::consts::FRAC_PI_2
            } else {
                0.0
            };
            let step = Pose2::new(1.0, 0.0, turn);
            truth.push(*truth.last().expect("seeded") * step);
            let measured = Pose2::new(1.03, 0.0, turn * 0.98);
            graph
                .nodes
                .push(*graph.nodes.last().expect("seeded") * measured);
            graph.edges.push(odometry_edge(k, measured));
        }
        (truth, graph)
    }

    fn max_error(a: &[Pose2], b: &[Pose2]) -> f64 {
        a.iter()
            .zip(b)
            .map(|(p, q)| p.position().distance_m(q.position()))
            .fold(0.0, f64::max)
    }

    /// A long loop (a circle of `n` poses) whose edges all agree with the truth, but whose
    /// poses start from odometry that turned 1 % too little: the optimum is the truth.
    fn consistent_circle(n: usize, solver: GraphSolver) -> (Vec<Pose2>, PoseGraph) {
        let turn = std::f64::consts::TAU / n as f64;
        let step = Pose2::new(0.3, 0.0, turn);
        let mut truth = vec![Pose2::IDENTITY];
        let mut graph = PoseGraph {
            nodes: vec![Pose2::IDENTITY],
            solver,
            ..PoseGraph::default()
        };
        for k in 0..n - 1 {
            truth.push(truth[k] * step);
            graph
                .nodes
                .push(graph.nodes[k] * Pose2::new(0.3, 0.0, turn * 0.99));
            graph.edges.push(odometry_edge(k, step));
        }
        // The closure from the last pose back to the first, as a scan match would give it.
        graph.edges.push(Edge {
            from: 0,
            to: n - 1,
            measurement: truth[0].inverse() * truth[n - 1],
            information: [1000.0, 1000.0, 4000.0],
            information_axis_rad: 0.0,
            robust: true,
        });
        (truth, graph)
    }

    #[test]
    fn the_chain_and_elimination_solve_a_long_loop_where_block_jacobi_stalls() {
        // 2000 poses, as a rover's hour of driving: block-Jacobi's 500 iterations a step
        // cannot carry the closure's correction round the loop.
        for solver in [GraphSolver::Chain, GraphSolver::Elimination] {
            let (truth, mut exact) = consistent_circle(2000, solver);
            let before = max_error(&truth, &exact.nodes);
            assert!(before > 3.0, "drift {before}");
            exact.optimize(5);
            let solved = max_error(&truth, &exact.nodes);
            assert!(solved < 1e-6, "{solver:?}: {solved} m off the optimum");
        }
        let (truth, mut jacobi) = consistent_circle(2000, GraphSolver::BlockJacobi);
        jacobi.optimize(5);
        let stalled = max_error(&truth, &jacobi.nodes);
        assert!(stalled > 1e-3, "block-Jacobi: {stalled} m");
    }

    #[test]
    fn every_solver_reaches_the_same_optimum_on_a_small_loop() {
        let (_, mut a) = drifting_square();
        let (_, mut b) = drifting_square();
        let (_, mut c) = drifting_square();
        b.solver = GraphSolver::Chain;
        c.solver = GraphSolver::Elimination;
        for g in [&mut a, &mut b, &mut c] {
            g.edges.push(Edge {
                from: 0,
                to: 40,
                measurement: Pose2::IDENTITY,
                information: [1000.0, 1000.0, 4000.0],
                information_axis_rad: 0.0,
                robust: true,
            });
            g.optimize(20);
        }
        for other in [&b, &c] {
            let gap = max_error(&a.nodes, &other.nodes);
            assert!(gap < 1e-6, "{:?}: {gap}", other.solver);
            let turn = a
                .nodes
                .iter()
                .zip(&other.nodes)
                .map(|(p, q)| normalize_angle_rad(p.yaw_rad - q.yaw_rad).abs())
                .fold(0.0, f64::max);
            assert!(turn < 1e-8, "{:?}: {turn}", other.solver);
        }
    }

    /// The drifting square with its loop closed: node 40 is back at node 0 (a scan match
    /// would say so).
    fn closed_square() -> (Vec<Pose2>, PoseGraph) {
        let (truth, mut graph) = drifting_square();
        graph.edges.push(Edge {
            from: 0,
            to: 40,
            measurement: truth[0].inverse() * truth[40],
            information: [1000.0, 1000.0, 4000.0],
            information_axis_rad: 0.0,
            robust: true,
        });
        (truth, graph)
    }

    #[test]
    fn a_cap_on_the_later_steps_leaves_the_first_step_whole() {
        let (_, graph) = closed_square();
        let mut one_step = graph.clone();
        one_step.optimize(1);
        let mut capped = graph.clone();
        capped.optimize_with_later_cap(3, 0);
        assert_eq!(
            capped.nodes, one_step.nodes,
            "later steps with no iterations move nothing"
        );
        let mut refined = graph.clone();
        refined.optimize_with_later_cap(3, 20);
        assert!(refined.chi2() < one_step.chi2(), "later steps refine");
    }

    #[test]
    fn a_loop_with_drifting_odometry_closes() {
        let (truth, mut graph) = closed_square();
        let before = max_error(&truth, &graph.nodes);
        assert!(before > 1.0, "drift {before}");
        let chi_before = graph.chi2();
        graph.optimize(20);
        assert!(graph.chi2() < chi_before * 0.1);
        let after = max_error(&truth, &graph.nodes);
        // Biased odometry (every side stretched): one closure spreads the error, it cannot
        // remove the bias, so it roughly halves the worst error.
        assert!(
            after < 0.6 * before,
            "max error {before:.2} m -> {after:.2} m"
        );
        assert!(
            graph.nodes[40]
                .position()
                .distance_m(graph.nodes[0].position())
                < 0.1
        );
    }

    /// The closed square optimised (the answer), its true closure, and the square before
    /// optimising with a false closure added: node 20 claimed to sit where node 0 is (a
    /// repetitive-scene mismatch), as confident as the true one.
    fn closed_square_and_a_false_closure() -> (PoseGraph, Edge, PoseGraph) {
        let (_, mut graph) = closed_square();
        let closure = *graph.edges.last().expect("the closure");
        let mut good = graph.clone();
        good.optimize(20);
        graph.edges.push(Edge {
            to: 20,
            measurement: Pose2::IDENTITY,
            ..closure
        });
        (good, closure, graph)
    }

    #[test]
    fn a_wrong_closure_does_far_less_damage_under_the_robust_loss() {
        let (good, _, mut graph) = closed_square_and_a_false_closure();
        let mut naive = graph.clone();
        graph.optimize(20);
        for e in &mut naive.edges {
            e.robust = false;
        }
        naive.optimize(20);
        // Huber bounds the pull of a residual, so the false closure does much less damage
        // than under plain least squares. (Rejecting it outright is the job of closure
        // verification, before an edge ever reaches the graph.)
        let moved = max_error(&good.nodes, &graph.nodes);
        let moved_naive = max_error(&good.nodes, &naive.nodes);
        let gap = |g: &PoseGraph| g.nodes[20].position().distance_m(g.nodes[0].position());
        assert!(
            moved < 0.5 * moved_naive && gap(&graph) > 2.0 * gap(&naive),
            "robust: moved {moved:.2} m, gap {:.2} m; plain: moved {moved_naive:.2} m, gap {:.2} m",
            gap(&graph),
            gap(&naive)
        );
        // Dynamic covariance scaling discounts it further still, with either solver.
        for solver in [GraphSolver::BlockJacobi, GraphSolver::Elimination] {
            let (_, start) = drifting_square();
            let mut dcs = PoseGraph {
                nodes: start.nodes,
                edges: graph.edges.clone(),
                solver,
                loss: RobustLoss::DynamicCovarianceScaling { phi: 5.0 },
                ..PoseGraph::default()
            };
            dcs.optimize(20);
            let moved_dcs = max_error(&good.nodes, &dcs.nodes);
            assert!(
                moved_dcs < 0.5 * moved,
                "{solver:?}: DCS moved {moved_dcs:.3} m, Huber {moved:.3} m"
            );
        }
    }

    #[test]
    fn a_closure_the_optimised_graph_disagrees_with_is_dropped_and_the_true_one_kept() {
        let (good, closure, mut graph) = closed_square_and_a_false_closure();
        // The true closure, once optimised, sits well within the limit.
        assert_eq!(good.clone().drop_robust_edges_beyond(16.0), 0);
        graph.optimize(20);
        let edges = graph.edges.len();
        assert_eq!(graph.drop_robust_edges_beyond(16.0), 1);
        assert_eq!(graph.edges.len(), edges - 1);
        assert!(!graph.edges.iter().any(|e| e.to == 20 && e.robust));
        assert!(graph.edges.contains(&closure));
        graph.optimize(20);
        let moved = max_error(&good.nodes, &graph.nodes);
        assert!(moved < 0.01, "{moved}");
    }

    #[test]
    fn dynamic_covariance_scaling_keeps_agreeing_closures_whole_and_drops_far_ones() {
        let dcs = RobustLoss::DynamicCovarianceScaling { phi: 5.0 };
        assert_eq!(dcs.weight(0.0), 1.0);
        assert_eq!(dcs.weight(5.0), 1.0);
        // chi2 = 45: (10 / 50)^2.
        assert!((dcs.weight(45.0) - 0.04).abs() < 1e-12);
        // Huber at the same residual keeps 1 / sqrt(45), four times as much.
        assert!((RobustLoss::Huber.weight(45.0) - 45f64.sqrt().recip()).abs() < 1e-12);
    }

    /// Node 1 held loosely at (1, 0) by one edge and firmly along one axis at (2, 1) by
    /// another: it goes to the firm edge along that axis only.
    fn pinned_along(axis_rad: f64) -> Pose2 {
        let mut graph = PoseGraph {
            nodes: vec![Pose2::IDENTITY, Pose2::new(1.0, 0.0, 0.0)],
            ..PoseGraph::default()
        };
        graph.edges.push(Edge {
            information: [1.0, 1.0, 1.0],
            ..odometry_edge(0, Pose2::new(1.0, 0.0, 0.0))
        });
        graph.edges.push(Edge {
            measurement: Pose2::new(2.0, 1.0, 0.0),
            information: [1e4, 0.0, 1.0],
            information_axis_rad: axis_rad,
            ..odometry_edge(0, Pose2::IDENTITY)
        });
        graph.optimize(5);
        graph.nodes[1]
    }

    #[test]
    fn an_edge_pins_only_along_its_information_axes() {
        let along_x = pinned_along(0.0);
        assert!((along_x.x_m - 2.0).abs() < 1e-3, "{along_x:?}");
        assert!(along_x.y_m.abs() < 1e-3, "{along_x:?}");
        let along_y = pinned_along(std::f64::consts::FRAC_PI_2);
        assert!((along_y.x_m - 1.0).abs() < 1e-3, "{along_y:?}");
        assert!((along_y.y_m - 1.0).abs() < 1e-3, "{along_y:?}");
        // Turned 45 degrees the firm axis is (1, 1): the node lands on the line through
        // (2, 1) across it.
        let diagonal = pinned_along(std::f64::consts::FRAC_PI_4);
        let across = (diagonal.x_m - 2.0 + diagonal.y_m - 1.0) / 2f64.sqrt();
        assert!(across.abs() < 1e-3, "{diagonal:?}");
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let xi = Pose2::new(1.0, -2.0, 0.7);
        let xj = Pose2::new(3.0, 0.5, -1.2);
        let z = Pose2::new(1.5, 2.0, 0.3);
        let (e0, a, b) = residual(&xi, &xj, &z);
        let h = 1e-6;
        for k in 0..3 {
            let bump = |p: &Pose2| {
                let mut v = [p.x_m, p.y_m, p.yaw_rad];
                v[k] += h;
                Pose2::new(v[0], v[1], v[2])
            };
            let (ei, _, _) = residual(&bump(&xi), &xj, &z);
            let (ej, _, _) = residual(&xi, &bump(&xj), &z);
            for r in 0..3 {
                assert!(((ei[r] - e0[r]) / h - a[r][k]).abs() < 1e-4, "A[{r}][{k}]");
                assert!(((ej[r] - e0[r]) / h - b[r][k]).abs() < 1e-4, "B[{r}][{k}]");
            }
        }
    }
}
