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
/// from the bottom row up so each ray starts near its neighbour's hit. Calls
/// `visit(u, v, ray_in_optical, hit)` with the hit distance along the unit ray.
pub fn cast_image(
    world: &HeightPyramid,
    world_from_optical: &Frame3,
    k: &Intrinsics,
    width: u32,
    height: u32,
    t_max_m: f64,
    mut visit: impl FnMut(u32, u32, [f64; 3], Option<f64>),
) {
    // Unit rays in the optical frame, computed once per image.
    let units: Vec<[f64; 3]> = (0..height)
        .flat_map(|v| (0..width).map(move |u| (u, v)))
        .map(|(u, v)| {
            let r = k.ray(u, v);
            let norm = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            [r[0] / norm, r[1] / norm, r[2] / norm]
        })
        .collect();
    for u in 0..width {
        let mut prev: Option<(f64, f64)> = None; // (hit distance, horizontal part of ray)
        for v in (0..height).rev() {
            let unit = units[(v * width + u) as usize];
            let dir = world_from_optical.rotate(unit);
            let horiz = (dir[0] * dir[0] + dir[1] * dir[1]).sqrt().max(1e-9);
            // A ray higher in a column stays above the one below it, so it cannot hit before
            // that ray's hit (or, after a miss, its reach) horizontally; start a bit short.
            // Exact for a level camera; with roll the rays fan sideways a little, and the
            // cast checks that the start is still above the ground.
            let hint = prev.map_or(0.0, |(t, h)| 0.97 * t * h / horiz);
            let hit = world.cast_from_hint(world_from_optical.origin, dir, 0.0, hint, t_max_m);
            prev = Some((hit.unwrap_or(t_max_m), horiz));
            visit(u, v, unit, hit);
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
    // The farthest ray (a corner pixel) reaches range_max in depth at this distance.
    let corner = k.ray(0, 0);
    let t_max = spec.range_max_m * (corner[0].powi(2) + corner[1].powi(2) + 1.0).sqrt();
    cast_image(
        world,
        world_from_optical,
        &k,
        w,
        h,
        t_max,
        |u, v, unit, hit| {
            let Some(t) = hit else { return };
            let z = t * unit[2];
            if z < spec.range_min_m || z > spec.range_max_m {
                return;
            }
            let z_noisy = z + gaussian(rng, spec.noise_per_m2 * z * z);
            let s = z_noisy / unit[2];
            points[(v * w + u) as usize] =
                [(unit[0] * s) as f32, (unit[1] * s) as f32, z_noisy as f32];
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
