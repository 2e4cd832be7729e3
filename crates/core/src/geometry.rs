//! Geometry: SE(2) poses for everything planar, and the small 3D types the ROS-shaped
//! messages need.
//!
//! Transforms are named `target_from_source` (rerun's convention), so composition reads
//! left to right: `world_from_sensor = world_from_rover * rover_from_sensor`.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::ops::Mul;

/// Wraps an angle to (-pi, pi].
pub fn normalize_angle_rad(a: f64) -> f64 {
    let mut r = a % (2.0 * PI);
    if r <= -PI {
        r += 2.0 * PI;
    } else if r > PI {
        r -= 2.0 * PI;
    }
    r
}

/// A point in a plane, in metres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point2 {
    /// x in metres.
    pub x_m: f64,
    /// y in metres.
    pub y_m: f64,
}

impl Point2 {
    /// A point at (x, y) metres.
    pub const fn new(x_m: f64, y_m: f64) -> Self {
        Point2 { x_m, y_m }
    }

    /// Euclidean distance to another point.
    pub fn distance_m(self, other: Point2) -> f64 {
        (self.x_m - other.x_m).hypot(self.y_m - other.y_m)
    }
}

/// A rigid transform in the plane (SE(2)): a rotation by `yaw_rad` then a translation.
/// As a pose, it is the frame of a body expressed in some parent frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose2 {
    /// Translation x in metres.
    pub x_m: f64,
    /// Translation y in metres.
    pub y_m: f64,
    /// Rotation in radians, kept in (-pi, pi] by the constructors and operations here.
    pub yaw_rad: f64,
}

impl Pose2 {
    /// The identity transform.
    pub const IDENTITY: Pose2 = Pose2 {
        x_m: 0.0,
        y_m: 0.0,
        yaw_rad: 0.0,
    };

    /// A pose at (x, y) with heading `yaw_rad` (normalised).
    pub fn new(x_m: f64, y_m: f64, yaw_rad: f64) -> Self {
        Pose2 {
            x_m,
            y_m,
            yaw_rad: normalize_angle_rad(yaw_rad),
        }
    }

    /// The translation part as a point.
    pub fn position(&self) -> Point2 {
        Point2::new(self.x_m, self.y_m)
    }

    /// `self * other`: apply `other` first, then `self`.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let (s, c) = self.yaw_rad.sin_cos();
        Pose2::new(
            self.x_m + c * other.x_m - s * other.y_m,
            self.y_m + s * other.x_m + c * other.y_m,
            self.yaw_rad + other.yaw_rad,
        )
    }

    /// The inverse transform: `a_from_b.inverse()` is `b_from_a`.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.yaw_rad.sin_cos();
        Pose2::new(
            -(c * self.x_m + s * self.y_m),
            s * self.x_m - c * self.y_m,
            -self.yaw_rad,
        )
    }

    /// Maps a point from the source frame into the target frame.
    pub fn transform_point(&self, p: Point2) -> Point2 {
        let (s, c) = self.yaw_rad.sin_cos();
        Point2::new(
            self.x_m + c * p.x_m - s * p.y_m,
            self.y_m + s * p.x_m + c * p.y_m,
        )
    }

    /// The pose relative to `base`: `base.inverse() * self`.
    pub fn relative_to(&self, base: &Pose2) -> Pose2 {
        base.inverse().compose(self)
    }

    /// Interpolates on SE(2)'s product form: translation linearly, heading along the shorter
    /// arc. `s = 0` gives `self`, `s = 1` gives `other`.
    pub fn interpolate(&self, other: &Pose2, s: f64) -> Pose2 {
        let dyaw = normalize_angle_rad(other.yaw_rad - self.yaw_rad);
        Pose2::new(
            self.x_m + s * (other.x_m - self.x_m),
            self.y_m + s * (other.y_m - self.y_m),
            self.yaw_rad + s * dyaw,
        )
    }
}

impl Mul for Pose2 {
    type Output = Pose2;
    fn mul(self, rhs: Pose2) -> Pose2 {
        self.compose(&rhs)
    }
}

/// A 3D vector (geometry_msgs/Vector3, and points).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vec3 {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
}

impl Vec3 {
    /// A vector from components.
    pub const fn new(x: f64, y: f64, z: f64) -> Self {
        Vec3 { x, y, z }
    }
}

/// Pinhole intrinsics for a field of view and resolution (the K of a ROS CameraInfo): the
/// simulator casts its cameras' pixels through them, and the rover reads a depth pixel's ray
/// from them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length in pixels, horizontal.
    pub fx: f64,
    /// Focal length in pixels, vertical.
    pub fy: f64,
    /// Principal point, x.
    pub cx: f64,
    /// Principal point, y.
    pub cy: f64,
}

impl Intrinsics {
    /// Intrinsics of a centred pinhole camera.
    pub fn from_fov(width: u32, height: u32, hfov_deg: f64, vfov_deg: f64) -> Self {
        Intrinsics {
            fx: width as f64 / 2.0 / (hfov_deg.to_radians() / 2.0).tan(),
            fy: height as f64 / 2.0 / (vfov_deg.to_radians() / 2.0).tan(),
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
        }
    }

    /// The optical-frame ray through a pixel centre, with z = 1.
    pub fn ray(&self, u: u32, v: u32) -> [f64; 3] {
        [
            (u as f64 + 0.5 - self.cx) / self.fx,
            (v as f64 + 0.5 - self.cy) / self.fy,
            1.0,
        ]
    }
}

/// A unit quaternion (geometry_msgs/Quaternion), Hamilton convention, `w` the scalar part.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
    /// z component.
    pub z: f64,
    /// scalar component.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion::IDENTITY
    }
}

impl Quaternion {
    /// No rotation.
    pub const IDENTITY: Quaternion = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };

    /// From intrinsic Z-Y-X Euler angles (yaw, then pitch, then roll), as ROS `tf2` does.
    pub fn from_roll_pitch_yaw(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Self {
        let (sr, cr) = (roll_rad * 0.5).sin_cos();
        let (sp, cp) = (pitch_rad * 0.5).sin_cos();
        let (sy, cy) = (yaw_rad * 0.5).sin_cos();
        Quaternion {
            w: cr * cp * cy + sr * sp * sy,
            x: sr * cp * cy - cr * sp * sy,
            y: cr * sp * cy + sr * cp * sy,
            z: cr * cp * sy - sr * sp * cy,
        }
    }

    /// The yaw (rotation about z) of this orientation.
    pub fn yaw_rad(&self) -> f64 {
        (2.0 * (self.w * self.z + self.x * self.y))
            .atan2(1.0 - 2.0 * (self.y * self.y + self.z * self.z))
    }
}

/// A line fitted through points by total least squares: the main axis of their spread.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    /// The points' centroid, on the line.
    pub centre: Point2,
    /// The line's direction, in (-pi/2, pi/2]: a line has no sense.
    pub direction_rad: f64,
    /// How many points it was fitted to.
    pub points: usize,
}

impl LineFit {
    /// Fits the line through `points`; `None` for fewer than `min_points` (at least 2).
    pub fn through<'a>(
        points: impl Iterator<Item = &'a Point2> + Clone,
        min_points: usize,
    ) -> Option<LineFit> {
        let (mut n, mut sx, mut sy) = (0usize, 0.0, 0.0);
        for p in points.clone() {
            n += 1;
            sx += p.x_m;
            sy += p.y_m;
        }
        if n < min_points.max(2) {
            return None;
        }
        let (cx, cy) = (sx / n as f64, sy / n as f64);
        let (mut vxx, mut vxy, mut vyy) = (0.0, 0.0, 0.0);
        for p in points {
            let (dx, dy) = (p.x_m - cx, p.y_m - cy);
            vxx += dx * dx;
            vxy += dx * dy;
            vyy += dy * dy;
        }
        Some(LineFit {
            centre: Point2::new(cx, cy),
            direction_rad: 0.5 * (2.0 * vxy).atan2(vxx - vyy),
            points: n,
        })
    }

    /// Where `p` lies from the centre, along the line and across it (left positive).
    pub fn along_across(&self, p: Point2) -> (f64, f64) {
        let (s, c) = self.direction_rad.sin_cos();
        let (dx, dy) = (p.x_m - self.centre.x_m, p.y_m - self.centre.y_m);
        (dx * c + dy * s, -dx * s + dy * c)
    }
}

/// A circle fitted to points by Kåsa's algebraic least squares ("A circle fitting procedure
/// and its error analysis", IEEE Trans. Instrumentation and Measurement, 1976): the circle
/// minimising the sum of the squares of `x^2 + y^2 + D x + E y + F` over the points, worked
/// out about their mean so the sums stay small far from the origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CircleFit {
    /// The points' mean.
    pub mean: Point2,
    /// The centre's offset from the mean, metres.
    pub centre_from_mean: (f64, f64),
    /// Radius, metres.
    pub radius_m: f64,
}

impl CircleFit {
    /// The circle through `points`, or `None` for fewer than three, points on a line, or a
    /// fit with no real radius.
    pub fn of(points: &[Point2]) -> Option<CircleFit> {
        if points.len() < 3 {
            return None;
        }
        let n = points.len() as f64;
        let (mx, my) = (
            points.iter().map(|p| p.x_m).sum::<f64>() / n,
            points.iter().map(|p| p.y_m).sum::<f64>() / n,
        );
        // Normal equations of x^2 + y^2 + d x + e y + f = 0 in least squares.
        let mut m = [[0.0f64; 3]; 3];
        let mut v = [0.0f64; 3];
        for p in points {
            let (x, y) = (p.x_m - mx, p.y_m - my);
            let row = [x, y, 1.0];
            let rhs = -(x * x + y * y);
            for r in 0..3 {
                v[r] += row[r] * rhs;
                for c in 0..3 {
                    m[r][c] += row[r] * row[c];
                }
            }
        }
        let [d, e, f] = solve3_scaled(&m, &v)?;
        let (cx, cy) = (-d / 2.0, -e / 2.0);
        let r2 = cx * cx + cy * cy - f;
        (r2 > 0.0).then(|| CircleFit {
            mean: Point2::new(mx, my),
            centre_from_mean: (cx, cy),
            radius_m: r2.sqrt(),
        })
    }

    /// The root mean square of the points' distances from the circle, metres: how thin
    /// they lie about it.
    pub fn rms_off_m(&self, points: &[Point2]) -> f64 {
        let (cx, cy) = self.centre_from_mean;
        (points
            .iter()
            .map(|p| {
                ((p.x_m - self.mean.x_m - cx).hypot(p.y_m - self.mean.y_m - cy) - self.radius_m)
                    .powi(2)
            })
            .sum::<f64>()
            / points.len().max(1) as f64)
            .sqrt()
    }

    /// The centre.
    pub fn centre(&self) -> Point2 {
        Point2::new(
            self.mean.x_m + self.centre_from_mean.0,
            self.mean.y_m + self.centre_from_mean.1,
        )
    }
}

/// `m x = v` by Cramer's rule; `None` when `m` is singular against its own scale (points on a
/// line, for [`CircleFit`]).
fn solve3_scaled(m: &[[f64; 3]; 3], v: &[f64; 3]) -> Option<[f64; 3]> {
    let det = |a: &[[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    let scale = m.iter().flatten().map(|x| x.abs()).fold(0.0, f64::max);
    if d.abs() <= 1e-12 * scale.powi(3) {
        return None;
    }
    Some(std::array::from_fn(|k| {
        let mut mk = *m;
        for r in 0..3 {
            mk[r][k] = v[r];
        }
        det(&mk) / d
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_circle_is_fitted_to_an_arc_and_not_to_a_line() {
        let arc: Vec<Point2> = (0..20)
            .map(|k| {
                let a = 0.1 * k as f64;
                Point2::new(3.0 + 1.5 * a.cos(), -2.0 + 1.5 * a.sin())
            })
            .collect();
        let c = CircleFit::of(&arc).expect("a circle");
        assert!(c.centre().distance_m(Point2::new(3.0, -2.0)) < 1e-9);
        assert!((c.radius_m - 1.5).abs() < 1e-9);
        assert!(c.rms_off_m(&arc) < 1e-9);
        let line: Vec<Point2> = (0..10)
            .map(|k| Point2::new(k as f64, 2.0 * k as f64))
            .collect();
        assert_eq!(CircleFit::of(&line), None);
    }

    #[test]
    fn a_line_through_noisy_points_along_30_degrees() {
        let a = 30f64.to_radians();
        let (s, c) = a.sin_cos();
        let points: Vec<Point2> = (0..20)
            .map(|i| {
                let t = i as f64 * 0.1;
                // Symmetric about the middle, so the noise has no trend along the line.
                let off = if matches!(i % 4, 0 | 3) { 0.01 } else { -0.01 };
                Point2::new(1.0 + t * c - off * s, 2.0 + t * s + off * c)
            })
            .collect();
        let fit = LineFit::through(points.iter(), 3).expect("enough points");
        assert!(
            (fit.direction_rad - a).abs() < 1e-9,
            "{}",
            fit.direction_rad
        );
        assert_eq!(fit.points, 20);
        let (along, across) = fit.along_across(points[0]);
        assert!(
            (along + 0.95).abs() < 1e-9 && (across - 0.01).abs() < 1e-9,
            "{along} {across}"
        );
        // Folded to (-pi/2, pi/2]: the same line from the other end.
        let reversed: Vec<Point2> = points.iter().rev().copied().collect();
        let back = LineFit::through(reversed.iter(), 3).expect("enough points");
        assert!((back.direction_rad - a).abs() < 1e-9);
        assert!(LineFit::through(points[..2].iter(), 3).is_none());
    }
    use proptest::prelude::*;

    fn close(a: &Pose2, b: &Pose2) -> bool {
        (a.x_m - b.x_m).abs() < 1e-9
            && (a.y_m - b.y_m).abs() < 1e-9
            && normalize_angle_rad(a.yaw_rad - b.yaw_rad).abs() < 1e-9
    }

    fn pose() -> impl Strategy<Value = Pose2> {
        (-100.0..100.0f64, -100.0..100.0f64, -10.0..10.0f64)
            .prop_map(|(x, y, t)| Pose2::new(x, y, t))
    }

    #[test]
    fn hand_checked_composition() {
        // A rover at (1, 2) facing +y sees a point 1 m ahead at world (1, 3).
        let world_from_rover = Pose2::new(1.0, 2.0, PI / 2.0);
        let p = world_from_rover.transform_point(Point2::new(1.0, 0.0));
        assert!((p.x_m - 1.0).abs() < 1e-12 && (p.y_m - 3.0).abs() < 1e-12);
        let world_from_sensor = world_from_rover * Pose2::new(0.5, 0.0, PI / 2.0);
        assert!(close(&world_from_sensor, &Pose2::new(1.0, 2.5, PI)));
    }

    #[test]
    fn interpolation_takes_the_short_arc() {
        let a = Pose2::new(0.0, 0.0, 3.0);
        let b = Pose2::new(2.0, 0.0, -3.0);
        let mid = a.interpolate(&b, 0.5);
        assert!((mid.x_m - 1.0).abs() < 1e-12);
        assert!((mid.yaw_rad.abs() - PI).abs() < 1e-9, "{}", mid.yaw_rad);
    }

    #[test]
    fn quaternion_yaw_round_trips() {
        let q = Quaternion::from_roll_pitch_yaw(0.1, -0.2, 2.5);
        assert!((q.yaw_rad() - 2.5).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn inverse_undoes_compose(a in pose(), b in pose()) {
            prop_assert!(close(&(a.inverse() * (a * b)), &b));
            prop_assert!(close(&(a * a.inverse()), &Pose2::IDENTITY));
        }

        #[test]
        fn composition_is_associative(a in pose(), b in pose(), c in pose()) {
            prop_assert!(close(&((a * b) * c), &(a * (b * c))));
        }

        #[test]
        fn angles_stay_normalised(t in -1000.0..1000.0f64) {
            let n = normalize_angle_rad(t);
            prop_assert!(n > -PI - 1e-12 && n <= PI + 1e-12);
            prop_assert!(((t - n) / (2.0 * PI) - ((t - n) / (2.0 * PI)).round()).abs() < 1e-9);
        }
    }
}
