//! The rover's sensors. Each is a plain function from the world (the height pyramid), the
//! sensor's pose and a seeded generator to a ROS-shaped message; scheduling them is the
//! [`World`](crate::world::World)'s job.

pub mod camera;
pub mod depth;
pub mod lidar;
pub mod proprio;
pub mod shadows;

/// A sensor's last noiseless cast and what it was cast from. The ground does not move, so a
/// rover that stands still (parked at home, waiting for a plan, powered but idle) would cast
/// the same rays again to the same answers: only the noise drawn on them is new. The poses
/// compare bit for bit, so a reused cast is the cast that would have been made.
#[derive(Clone, Debug)]
pub struct LastCast<K, V> {
    last: Option<(K, V)>,
    repeats: u64,
}

impl<K, V> Default for LastCast<K, V> {
    fn default() -> Self {
        LastCast {
            last: None,
            repeats: 0,
        }
    }
}

impl<K: PartialEq, V> LastCast<K, V> {
    /// The cast from `from`: the kept one if it was cast from there and `reuse` allows, else
    /// `cast(&from)`, kept.
    pub fn get_or_cast(&mut self, from: K, reuse: bool, cast: impl FnOnce(&K) -> V) -> &V {
        if matches!(&self.last, Some((k, _)) if *k == from) {
            self.repeats += 1;
            if !reuse {
                self.last = None;
            }
        } else {
            self.last = None;
        }
        &self
            .last
            .get_or_insert_with(|| {
                let v = cast(&from);
                (from, v)
            })
            .1
    }

    /// How many casts were asked for from where the one before was cast (and answered from
    /// it, where reuse was allowed).
    pub fn repeats(&self) -> u64 {
        self.repeats
    }

    /// Forgets the kept cast (the world it was cast in changed).
    pub fn clear(&mut self) {
        self.last = None;
    }
}

/// A rigid 3D frame: `world_from_sensor` as an origin and a rotation matrix (columns are the
/// sensor's axes in the world).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame3 {
    /// Origin in the world, metres.
    pub origin: [f64; 3],
    /// Rotation, row-major.
    pub rot: [[f64; 3]; 3],
}

impl Frame3 {
    /// A frame from position and intrinsic Z-Y-X Euler angles (ROS roll, pitch, yaw).
    pub fn from_rpy(origin: [f64; 3], roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Self {
        let (sr, cr) = roll_rad.sin_cos();
        let (sp, cp) = pitch_rad.sin_cos();
        let (sy, cy) = yaw_rad.sin_cos();
        Frame3 {
            origin,
            rot: [
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ],
        }
    }

    /// Rotates a vector from the frame into the world.
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rot;
        [
            r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
            r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
            r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2],
        ]
    }

    /// Maps a point from the frame into the world.
    pub fn transform(&self, p: [f64; 3]) -> [f64; 3] {
        let v = self.rotate(p);
        [
            v[0] + self.origin[0],
            v[1] + self.origin[1],
            v[2] + self.origin[2],
        ]
    }

    /// This frame turned by the angle of (`sin`, `cos`) about the world's vertical through its
    /// origin.
    pub fn turned_about_vertical(&self, (sin, cos): (f64, f64)) -> Frame3 {
        let r = &self.rot;
        Frame3 {
            origin: self.origin,
            rot: [
                [0, 1, 2].map(|col| cos * r[0][col] - sin * r[1][col]),
                [0, 1, 2].map(|col| sin * r[0][col] + cos * r[1][col]),
                r[2],
            ],
        }
    }

    /// `self * child`: the child's frame expressed in this frame's parent.
    pub fn compose(&self, child: &Frame3) -> Frame3 {
        let mut rot = [[0.0; 3]; 3];
        for (i, row) in rot.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.rot[i][k] * child.rot[k][j]).sum();
            }
        }
        Frame3 {
            origin: self.transform(child.origin),
            rot,
        }
    }
}

/// A standard normal draw, scaled.
pub(crate) fn gaussian(rng: &mut crate::rng::SimRng, sigma: f64) -> f64 {
    use rand_distr::Distribution;
    if sigma <= 0.0 {
        return 0.0;
    }
    let z: f64 = rand_distr::StandardNormal.sample(rng);
    z * sigma
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pitch_down_points_the_nose_down() {
        // REP 103: positive pitch rotates x towards -z.
        let f = Frame3::from_rpy([0.0; 3], 0.0, 0.3, 0.0);
        let fwd = f.rotate([1.0, 0.0, 0.0]);
        assert!(fwd[2] < 0.0 && (fwd[2] + 0.3f64.sin()).abs() < 1e-12);
        let composed = Frame3::from_rpy([1.0, 0.0, 0.0], 0.0, 0.0, 1.0).compose(&Frame3::from_rpy(
            [1.0, 0.0, 0.0],
            0.0,
            0.0,
            0.5,
        ));
        let expect = Frame3::from_rpy([1.0 + 1f64.cos(), 1f64.sin(), 0.0], 0.0, 0.0, 1.5);
        for i in 0..3 {
            assert!((composed.origin[i] - expect.origin[i]).abs() < 1e-12);
            for j in 0..3 {
                assert!((composed.rot[i][j] - expect.rot[i][j]).abs() < 1e-12);
            }
        }
    }
}
