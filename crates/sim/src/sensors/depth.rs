//! RealSense D455-like depth camera: an organised point cloud in the optical frame (z forward,
//! x right, y down), depth noise growing with range squared as stereo does, nothing closer than
//! the minimum or beyond the maximum depth. Unlike the lidar it sees crater rims and bowls and
//! rocks below the lidar plane.

use super::{Frame3, gaussian};
use crate::raycast::HeightPyramid;
use crate::rng::SimRng;
use crate::scenario::DepthCamera;
use realms_core::Time;
use realms_core::msgs::{Header, PointCloud};

/// Pinhole intrinsics for a field of view and resolution.
#[derive(Clone, Copy, Debug)]
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

/// The optical frame (z forward, x right, y down) as a child of a body frame (x forward,
/// y left, z up).
pub const BODY_FROM_OPTICAL: [[f64; 3]; 3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];

/// Casts every pixel of a `width x height` image from `world_from_optical`, column by column
/// from the bottom row up so each ray starts near its neighbour's hit. Rays are cast along the
/// unnormalised optical ray `r = ((u - cx) / fx, (v - cy) / fy, 1)`, so the ray parameter of a
/// hit is its optical depth z, and stepping up a column is three additions. Calls
/// `visit(u, v, r, z)` with the optical depth of the hit, or `None` beyond `z_max_m`, column
/// by column, bottom row first.
pub fn cast_image(
    world: &HeightPyramid,
    world_from_optical: &Frame3,
    k: &Intrinsics,
    width: u32,
    height: u32,
    z_max_m: f64,
    mut visit: impl FnMut(u32, u32, [f64; 3], Option<f64>),
) {
    // Neighbouring columns are cast side by side (their walks overlap on the core), then
    // visited one after the other.
    const SIDE_BY_SIDE: u32 = 4;
    if width == 0 || height == 0 {
        return;
    }
    let mut hits = vec![None; (SIDE_BY_SIDE * height) as usize];
    let mut u = 0;
    while u < width {
        let n = if u + SIDE_BY_SIDE <= width {
            cast_columns::<{ SIDE_BY_SIDE as usize }>(
                world,
                world_from_optical,
                k,
                u,
                height,
                z_max_m,
                &mut hits,
            );
            SIDE_BY_SIDE
        } else {
            cast_columns::<1>(world, world_from_optical, k, u, height, z_max_m, &mut hits);
            1
        };
        for (i, column) in hits
            .chunks_exact(height as usize)
            .take(n as usize)
            .enumerate()
        {
            let bottom = k.ray(u + i as u32, height - 1);
            for (rows_up, hit) in column.iter().enumerate() {
                let v = height - 1 - rows_up as u32;
                let r = [bottom[0], bottom[1] - rows_up as f64 / k.fy, 1.0];
                visit(u + i as u32, v, r, *hit);
            }
        }
        u += n;
    }
}

/// Casts columns `u0 .. u0 + N`, bottom row up, into `hits` (column after column).
fn cast_columns<const N: usize>(
    world: &HeightPyramid,
    world_from_optical: &Frame3,
    k: &Intrinsics,
    u0: u32,
    height: u32,
    z_max_m: f64,
    hits: &mut [Option<f64>],
) {
    let origin = world_from_optical.origin;
    // World direction of one pixel row up the image (towards smaller v).
    let row_up = world_from_optical.rotate([0.0, -1.0 / k.fy, 0.0]);
    let mut dirs: [[f64; 3]; N] =
        std::array::from_fn(|i| world_from_optical.rotate(k.ray(u0 + i as u32, height - 1)));
    let mut prev_z = [0.0; N];
    for rows_up in 0..height as usize {
        // A ray higher in a column usually hits no nearer than the one below it (or, after a
        // miss, than its reach), so that is where its search starts; the cast proves the
        // stretch before it empty first, because a tilted or rolled camera fans the rays
        // sideways and a thin silhouette can hide between them.
        let hints = prev_z.map(|z| 0.95 * z);
        let found = world.cast_from_hints(origin, dirs, 0.0, hints, z_max_m);
        for (i, hit) in found.into_iter().enumerate() {
            prev_z[i] = hit.unwrap_or(z_max_m);
            hits[i * height as usize + rows_up] = hit;
            for (d, up) in dirs[i].iter_mut().zip(row_up) {
                *d += up;
            }
        }
    }
}

/// Takes one depth frame from `world_from_optical`.
pub fn frame(
    world: &HeightPyramid,
    world_from_optical: &Frame3,
    spec: &DepthCamera,
    rng: &mut SimRng,
    stamp: Time,
    frame_id: &str,
) -> PointCloud {
    let k = Intrinsics::from_fov(spec.width, spec.height, spec.hfov_deg, spec.vfov_deg);
    let (w, h) = (spec.width, spec.height);
    let mut points = vec![[f32::NAN; 3]; (w * h) as usize];
    cast_image(
        world,
        world_from_optical,
        &k,
        w,
        h,
        spec.range_max_m,
        |u, v, r, hit| {
            let Some(z) = hit else { return };
            if z < spec.range_min_m {
                return;
            }
            let z_noisy = z + gaussian(rng, spec.noise_per_m2 * z * z);
            points[(v * w + u) as usize] = [
                (r[0] * z_noisy) as f32,
                (r[1] * z_noisy) as f32,
                z_noisy as f32,
            ];
        },
    );
    PointCloud {
        header: Header {
            stamp,
            frame_id: frame_id.to_string(),
        },
        width: w,
        height: h,
        points_in_sensor: points,
    }
}
