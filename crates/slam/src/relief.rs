//! The rover's travel between two depth frames, from the relief of the ground they both see.
//!
//! A 2D lidar beside a long, bare wall tells nothing of where along the wall the rover is, and
//! the wheels slip by 3-20 % (BENCHMARKS.md, "A rover turning in place holds its position").
//! The depth camera sees the ground in front of the rover: small rocks, crater rims and the
//! floor's undulation. Here a reference frame's points become an elevation patch (the mean
//! height per cell, in the rover's gravity-levelled frame), and a later frame's points are
//! fitted onto it by Gauss-Newton over the planar motion, its heading and a height offset:
//! each point's residual is its height against the patch's at the point's place, so only
//! where the ground has relief does a point say anything about the motion. The fit reports
//! its information (how firmly the relief pins each direction), so flat ground is known to
//! say nothing rather than taken as a standstill. This is the elevation-map registration of
//! rough-terrain odometry (e.g. Kleinert et al., "Inertial aided monocular SLAM for GPS-denied
//! navigation", 2010, and the 2.5D map matching of Forkel et al., RA-L 2021), in its
//! simplest form: one frame against one reference frame.

use realms_core::Pose2;

/// Tuning of [`register`] and [`ElevationPatch::from_points`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReliefConfig {
    /// Side of the patch's cells, metres.
    pub cell_m: f64,
    /// Reference points within this horizontal range of the rover make the patch, metres.
    pub reference_range_m: f64,
    /// A registered frame's points within this horizontal range are fitted, metres (the
    /// nearer ground is seen densely and with little noise).
    pub frame_range_m: f64,
    /// Nearer points are left out (the camera's own blind zone and the rover's body), metres.
    pub min_range_m: f64,
    /// A point's height noise: `noise_m + noise_per_m2 * range^2` (stereo depth noise grows
    /// with the square of the range).
    pub noise_m: f64,
    /// See `noise_m`.
    pub noise_per_m2: f64,
    /// Gauss-Newton iterations.
    pub iterations: usize,
    /// Pull towards the guessed planar position, per square metre (not per point: it only
    /// keeps flat ground from moving the fit).
    pub prior_translation: f64,
    /// Pull towards the guessed heading, per square radian (the gyro's heading over half a
    /// second is far better than any relief).
    pub prior_rotation: f64,
    /// A fit needs this many points on the patch.
    pub min_points: usize,
}

impl Default for ReliefConfig {
    fn default() -> Self {
        ReliefConfig {
            cell_m: 0.1,
            reference_range_m: 4.5,
            frame_range_m: 3.0,
            min_range_m: 0.4,
            noise_m: 0.005,
            noise_per_m2: 0.005,
            iterations: 12,
            prior_translation: 1.0,
            prior_rotation: 1e6,
            min_points: 200,
        }
    }
}

/// The ground's height per cell around a reference frame's rover (its levelled frame: x
/// forward, y left, z up), from the frame's points.
#[derive(Clone, Debug)]
pub struct ElevationPatch {
    cell_m: f64,
    x0_m: f64,
    y0_m: f64,
    width: usize,
    height: usize,
    /// Mean height per cell, NaN where no point fell.
    z_m: Vec<f64>,
    /// The variance of that mean, square metres.
    var_m2: Vec<f64>,
}

impl ElevationPatch {
    /// The patch of `points` (levelled frame; non-finite ones are skipped) within the
    /// reference range; `None` if none are.
    pub fn from_points(points: &[[f64; 3]], cfg: &ReliefConfig) -> Option<ElevationPatch> {
        let kept: Vec<(&[f64; 3], f64)> = within(points, cfg.min_range_m, cfg.reference_range_m)
            .map(|(p, r)| (p, weight(cfg, r)))
            .collect();
        let first = kept.first()?.0;
        let (mut lo, mut hi) = ([first[0], first[1]], [first[0], first[1]]);
        for (p, _) in &kept {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        let c = cfg.cell_m;
        let (x0_m, y0_m) = ((lo[0] / c).floor() * c, (lo[1] / c).floor() * c);
        let width = ((hi[0] - x0_m) / c).floor() as usize + 1;
        let height = ((hi[1] - y0_m) / c).floor() as usize + 1;
        let mut sums = vec![(0.0f64, 0.0f64); width * height];
        for (p, w) in kept {
            let (i, j) = (
                ((p[0] - x0_m) / c).floor() as usize,
                ((p[1] - y0_m) / c).floor() as usize,
            );
            if i < width && j < height {
                let s = &mut sums[j * width + i];
                s.0 += w * p[2];
                s.1 += w;
            }
        }
        Some(ElevationPatch {
            cell_m: c,
            x0_m,
            y0_m,
            width,
            height,
            z_m: sums
                .iter()
                .map(|(zw, w)| if *w > 0.0 { zw / w } else { f64::NAN })
                .collect(),
            var_m2: sums
                .iter()
                .map(|(_, w)| if *w > 0.0 { 1.0 / w } else { f64::NAN })
                .collect(),
        })
    }

    /// Cells holding a height.
    pub fn known_cells(&self) -> usize {
        self.z_m.iter().filter(|z| z.is_finite()).count()
    }

    /// The height at `(x, y)` and its gradient, bilinear between the four nearest cell
    /// centres; `None` unless all four hold a height.
    pub fn height_and_gradient(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        self.lookup(x, y).map(|(z, g, _)| (z, g))
    }

    /// [`ElevationPatch::height_and_gradient`], with the variance of the height (the four
    /// cells' variances, weighted as their heights are).
    fn lookup(&self, x: f64, y: f64) -> Option<(f64, [f64; 2], f64)> {
        let c = self.cell_m;
        let (u, v) = ((x - self.x0_m) / c - 0.5, (y - self.y0_m) / c - 0.5);
        if !(u >= 0.0 && v >= 0.0) {
            return None;
        }
        let (i, j) = (u.floor() as usize, v.floor() as usize);
        if i + 1 >= self.width || j + 1 >= self.height {
            return None;
        }
        let (fu, fv) = (u - i as f64, v - j as f64);
        let at = |i: usize, j: usize| self.z_m[j * self.width + i];
        let (z00, z10, z01, z11) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
        if !(z00.is_finite() && z10.is_finite() && z01.is_finite() && z11.is_finite()) {
            return None;
        }
        let z = z00 * (1.0 - fu) * (1.0 - fv)
            + z10 * fu * (1.0 - fv)
            + z01 * (1.0 - fu) * fv
            + z11 * fu * fv;
        let dzdu = (z10 - z00) * (1.0 - fv) + (z11 - z01) * fv;
        let dzdv = (z01 - z00) * (1.0 - fu) + (z11 - z10) * fu;
        let var = |i: usize, j: usize| self.var_m2[j * self.width + i];
        let (w00, w10, w01, w11) = (
            (1.0 - fu) * (1.0 - fv),
            fu * (1.0 - fv),
            (1.0 - fu) * fv,
            fu * fv,
        );
        let v = w00 * w00 * var(i, j)
            + w10 * w10 * var(i + 1, j)
            + w01 * w01 * var(i, j + 1)
            + w11 * w11 * var(i + 1, j + 1);
        Some((z, [dzdu / c, dzdv / c], v))
    }
}

/// A frame fitted onto a reference patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Registration {
    /// The frame's rover in the reference's levelled frame (planar position and heading).
    pub motion: Pose2,
    /// The frame's rover's height above the reference's, metres.
    pub climb_m: f64,
    /// How firmly the relief pins (x, y, heading) of `motion`, the height offset and the
    /// priors taken out: the inverse of the fit's covariance.
    pub information: [[f64; 3]; 3],
    /// Points that landed on the patch.
    pub points: usize,
    /// Root mean square of their height residuals, metres.
    pub rms_m: f64,
}

impl Registration {
    /// The standard deviation of the fit's position along the unit direction `(dx, dy)` of
    /// the plane (infinite where the relief says nothing), metres.
    pub fn sigma_along_m(&self, dx: f64, dy: f64) -> f64 {
        let m = &self.information;
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        if det.abs() < 1e-18 {
            return f64::INFINITY;
        }
        let cov = crate::posegraph::invert(m);
        let var = cov[0][0] * dx * dx + 2.0 * cov[0][1] * dx * dy + cov[1][1] * dy * dy;
        if var > 0.0 { var.sqrt() } else { f64::INFINITY }
    }
}

/// Fits `points` (a later frame, its own levelled frame) onto `reference`, starting from
/// `guess` (that frame's rover in the reference's frame, e.g. from the wheels and the gyro).
/// `None` if too few points land on the patch or the fit does not settle.
pub fn register(
    reference: &ElevationPatch,
    points: &[[f64; 3]],
    guess: Pose2,
    cfg: &ReliefConfig,
) -> Option<Registration> {
    let kept: Vec<([f64; 3], f64)> = within(points, cfg.min_range_m, cfg.frame_range_m)
        .map(|(p, r)| (*p, weight(cfg, r)))
        .collect();
    // Unknowns: x, y, heading, climb.
    let mut x = [guess.x_m, guess.y_m, guess.yaw_rad, 0.0];
    let mut last = None;
    for _ in 0..cfg.iterations {
        let system = normal_equations(reference, &kept, &x)?;
        if system.points < cfg.min_points {
            return None;
        }
        let mut h = system.h;
        let mut g = system.g;
        let prior = [
            cfg.prior_translation,
            cfg.prior_translation,
            cfg.prior_rotation,
        ];
        let target = [guess.x_m, guess.y_m, guess.yaw_rad];
        for k in 0..3 {
            h[k][k] += prior[k];
            g[k] += prior[k] * (target[k] - x[k]);
        }
        let step = solve4(&h, &g)?;
        for k in 0..4 {
            x[k] += step[k];
        }
        let small = step[0].abs() < 1e-5 && step[1].abs() < 1e-5 && step[2].abs() < 1e-6;
        last = Some(system);
        if small {
            break;
        }
    }
    let system = normal_equations(reference, &kept, &x).or(last)?;
    if system.points < cfg.min_points {
        return None;
    }
    // The climb is a nuisance: its information is folded into the other three (Schur
    // complement), so a point's height offset explains nothing twice.
    let h = system.h;
    let mut information = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            information[a][b] = h[a][b] - h[a][3] * h[3][b] / h[3][3].max(1e-12);
        }
    }
    Some(Registration {
        motion: Pose2::new(x[0], x[1], x[2]),
        climb_m: x[3],
        information,
        points: system.points,
        rms_m: (system.sum_r2 / system.points.max(1) as f64).sqrt(),
    })
}

/// A patch's gradient counts as relief where its square exceeds this many times its noise's
/// variance.
const RELIEF_SIGNIFICANCE2: f64 = 9.0;

/// Gauss-Newton's system at `x` (weighted by each point's noise, Cauchy-discounted).
struct System {
    h: [[f64; 4]; 4],
    g: [f64; 4],
    points: usize,
    sum_r2: f64,
}

fn normal_equations(
    reference: &ElevationPatch,
    points: &[([f64; 3], f64)],
    x: &[f64; 4],
) -> Option<System> {
    // Cauchy's scale in noise deviations: a rock's side the reference saw from elsewhere is
    // not the ground's height.
    const CAUCHY2: f64 = 9.0;
    let (s, c) = x[2].sin_cos();
    let mut sys = System {
        h: [[0.0; 4]; 4],
        g: [0.0; 4],
        points: 0,
        sum_r2: 0.0,
    };
    for (p, w) in points {
        let (qx, qy) = (c * p[0] - s * p[1] + x[0], s * p[0] + c * p[1] + x[1]);
        let Some((z, [gx, gy], var)) = reference.lookup(qx, qy) else {
            continue;
        };
        // The point's noise and the patch's.
        let w = 1.0 / (1.0 / w + var);
        // The patch's gradient is noisy too (about 2 var / cell^2 in each direction): where
        // it is no larger than its noise it is no relief, and it must not count as such
        // (flat ground would otherwise claim to pin the travel to millimetres). Shrunk as
        // a Wiener filter would.
        let g2 = gx * gx + gy * gy;
        let noise2 = 2.0 * var / (reference.cell_m * reference.cell_m);
        let shrink = if g2 > RELIEF_SIGNIFICANCE2 * noise2 {
            1.0
        } else {
            0.0
        };
        let (gx, gy) = (gx * shrink, gy * shrink);
        // Residual: the point's height in the reference frame against the patch's there.
        let r = p[2] + x[3] - z;
        let dqx_dt = -s * p[0] - c * p[1];
        let dqy_dt = c * p[0] - s * p[1];
        let j = [-gx, -gy, -(gx * dqx_dt + gy * dqy_dt), 1.0];
        let robust = w / (1.0 + r * r * w / CAUCHY2);
        for a in 0..4 {
            sys.g[a] -= robust * j[a] * r;
            for b in 0..4 {
                sys.h[a][b] += robust * j[a] * j[b];
            }
        }
        sys.points += 1;
        sys.sum_r2 += r * r;
    }
    (sys.points > 0).then_some(sys)
}

/// The points of `points` (finite ones) whose horizontal range lies in `[min, max]`, with
/// that range.
fn within(points: &[[f64; 3]], min: f64, max: f64) -> impl Iterator<Item = (&[f64; 3], f64)> {
    points.iter().filter_map(move |p| {
        let r = p[0].hypot(p[1]);
        (p.iter().all(|v| v.is_finite()) && r >= min && r <= max).then_some((p, r))
    })
}

/// A point's weight, the inverse of its height variance.
fn weight(cfg: &ReliefConfig, range_m: f64) -> f64 {
    let sigma = cfg.noise_m + cfg.noise_per_m2 * range_m * range_m;
    1.0 / (sigma * sigma)
}

/// Solves a symmetric positive definite 4 x 4 system by Cholesky; `None` if it is not.
fn solve4(a: &[[f64; 4]; 4], b: &[f64; 4]) -> Option<[f64; 4]> {
    let mut l = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..=i {
            let sum = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if sum <= 0.0 {
                    return None;
                }
                l[i][j] = sum.sqrt();
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    let mut y = [0.0; 4];
    for i in 0..4 {
        y[i] = (b[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0; 4];
    for i in (0..4).rev() {
        x[i] = (y[i] - (i + 1..4).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ground with an undulation and a few rocks (bumps 4-8 cm high, 10-15 cm across), or
    /// flat, in the world frame.
    fn ground(x: f64, y: f64, rocks: bool) -> f64 {
        if !rocks {
            return 0.0;
        }
        let mut z = 0.03 * (0.7 * x).sin() * (0.5 * y).cos();
        for (rx, ry, h, s) in [
            (1.2, 0.3, 0.06, 0.07),
            (1.9, -0.6, 0.04, 0.06),
            (2.6, 0.5, 0.08, 0.08),
            (3.1, -0.2, 0.05, 0.05),
            (3.8, 0.9, 0.07, 0.07),
        ] {
            let d2 = (x - rx).powi(2) + (y - ry).powi(2);
            z += h * (-d2 / (2.0 * s * s)).exp();
        }
        z
    }

    /// What a forward-looking depth camera on a rover at `pose` sees: the ground's points
    /// from 0.4 m to 4.5 m ahead within +-43 degrees, on a fan of rays, in the rover's
    /// levelled frame (z from the ground under the rover), with height noise growing with
    /// range, from a fixed pseudo-random sequence.
    fn frame(pose: Pose2, rocks: bool, seed: u64) -> Vec<[f64; 3]> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut noise = move || {
            // Sum of uniforms: close enough to Gaussian for a test, deterministic.
            let mut s = 0.0;
            for _ in 0..4 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s += ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5;
            }
            s
        };
        let base = ground(pose.x_m, pose.y_m, rocks);
        let mut points = Vec::new();
        for i in 0..100 {
            let r = 0.4 + 4.1 * (i as f64 / 99.0).powi(2);
            for k in 0..106 {
                let a = (-43.0 + 86.0 * k as f64 / 105.0f64).to_radians();
                let (lx, ly) = (r * a.cos(), r * a.sin());
                let w = pose.transform_point(realms_core::Point2::new(lx, ly));
                let z = ground(w.x_m, w.y_m, rocks) - base;
                let sigma = 0.002 + 0.004 * r * r;
                points.push([lx, ly, z + sigma * noise()]);
            }
        }
        points
    }

    #[test]
    fn the_travel_between_two_frames_is_found_on_rocky_ground() {
        let cfg = ReliefConfig::default();
        let a = Pose2::new(0.0, 0.0, 0.0);
        let b = Pose2::new(0.42, 0.05, 0.06);
        let patch = ElevationPatch::from_points(&frame(a, true, 1), &cfg).expect("a patch");
        let truth = a.inverse() * b;
        // The wheels over-report by 15 %.
        let guess = Pose2::new(truth.x_m * 1.15, truth.y_m * 1.15, truth.yaw_rad);
        let fit = register(&patch, &frame(b, true, 2), guess, &cfg).expect("a fit");
        let err = fit.motion.position().distance_m(truth.position());
        assert!(err < 0.01, "{:?} against {truth:?}: {err} m", fit.motion);
        let sigma = fit.sigma_along_m(1.0, 0.0);
        assert!(sigma < 0.01, "along the travel: {sigma} m");
        // The wheels' 6 cm error is well outside what the fit claims.
        assert!(guess.position().distance_m(truth.position()) > 5.0 * sigma);
    }

    #[test]
    fn flat_ground_says_nothing_of_the_travel() {
        let cfg = ReliefConfig::default();
        let a = Pose2::new(0.0, 0.0, 0.0);
        let b = Pose2::new(0.4, 0.0, 0.0);
        let patch = ElevationPatch::from_points(&frame(a, false, 1), &cfg).expect("a patch");
        let guess = Pose2::new(0.46, 0.0, 0.0);
        let fit = register(&patch, &frame(b, false, 2), guess, &cfg).expect("a fit");
        // It stays at the guess, and says it cannot tell.
        let (moved, sigma) = (
            fit.motion.position().distance_m(guess.position()),
            fit.sigma_along_m(1.0, 0.0),
        );
        assert!(moved < 0.005, "{:?}", fit.motion);
        assert!(sigma > 0.1, "{sigma}");
    }

    #[test]
    fn a_frame_that_misses_the_patch_is_not_fitted() {
        let cfg = ReliefConfig::default();
        let patch =
            ElevationPatch::from_points(&frame(Pose2::IDENTITY, true, 1), &cfg).expect("a patch");
        // Turned round: it sees the ground behind the reference, which the patch never saw.
        let b = Pose2::new(0.0, 0.0, std::f64::consts::PI);
        assert!(register(&patch, &frame(b, true, 2), b, &cfg).is_none());
    }

    #[test]
    fn heights_between_cells_are_bilinear() {
        let cfg = ReliefConfig {
            min_range_m: 0.0,
            cell_m: 0.05,
            ..ReliefConfig::default()
        };
        // One point per cell centre of a plane z = 0.1 x + 0.2 y.
        let mut points = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (x, y) = (1.0 + (i as f64 + 0.5) * 0.05, (j as f64 + 0.5) * 0.05);
                points.push([x, y, 0.1 * x + 0.2 * y]);
            }
        }
        let patch = ElevationPatch::from_points(&points, &cfg).expect("a patch");
        assert_eq!(patch.known_cells(), 400);
        let (z, g) = patch.height_and_gradient(1.33, 0.41).expect("inside");
        assert!((z - (0.133 + 0.082)).abs() < 1e-9, "{z}");
        assert!(
            (g[0] - 0.1).abs() < 1e-9 && (g[1] - 0.2).abs() < 1e-9,
            "{g:?}"
        );
        assert!(patch.height_and_gradient(0.5, 0.4).is_none());
    }
}
