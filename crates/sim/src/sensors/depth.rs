//! RealSense D455-like depth camera: an organised point cloud in the optical frame (z forward,
//! x right, y down), depth noise growing with range squared as stereo does, nothing closer than
//! the minimum or beyond the maximum depth. Unlike the lidar it sees crater rims and bowls and
//! rocks below the lidar plane.

use super::{Frame3, gaussian};
use crate::raycast::HeightPyramid;
use crate::rng::SimRng;
use crate::scenario::DepthCamera;
use realms_core::Time;
pub use realms_core::geometry::Intrinsics;
use realms_core::msgs::{Header, PointCloud};

/// The optical frame (z forward, x right, y down) as a child of a body frame (x forward,
/// y left, z up).
pub const BODY_FROM_OPTICAL: [[f64; 3]; 3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];

/// Casts every pixel of a `width x height` image from `world_from_optical`, column by column.
/// The rays of a column leave the camera in one plane, so each column is cast as a fan
/// ([`realms_sim::raycast::FanCaster`](crate::raycast::FanCaster)): one pass over the ground
/// for the whole column, then a short exact walk a pixel. Rays are cast along the unnormalised
/// optical ray `r = ((u - cx) / fx, (v - cy) / fy, 1)`, so the ray parameter of a hit is its
/// optical depth z. Calls `visit(u, v, r, z)` with the optical depth of the hit, or `None`
/// beyond `z_max_m`, column by column, bottom row first.
pub fn cast_image(
    world: &HeightPyramid,
    world_from_optical: &Frame3,
    k: &Intrinsics,
    width: u32,
    height: u32,
    z_max_m: f64,
    mut visit: impl FnMut(u32, u32, [f64; 3], Option<f64>),
) {
    if width == 0 || height == 0 {
        return;
    }
    // A ray r (z = 1) travels |r| per unit of optical depth; the image's corners have the
    // longest.
    let longest = [
        (0, 0),
        (width - 1, 0),
        (0, height - 1),
        (width - 1, height - 1),
    ]
    .into_iter()
    .map(|(u, v)| {
        let r = k.ray(u, v);
        (r[0] * r[0] + r[1] * r[1] + 1.0).sqrt()
    })
    .fold(0.0, f64::max);
    let mut fan = world.fan_caster(world_from_optical.origin, z_max_m * longest * (1.0 + 1e-9));
    let mut rays = Vec::with_capacity(height as usize);
    let mut dirs = Vec::with_capacity(height as usize);
    let mut hits = vec![None; height as usize];
    // A pixel's ray is its column's x and its row's y (the divisions of `Intrinsics::ray`, done
    // once per column and row instead of once per pixel).
    let row_y: Vec<f64> = (0..height).map(|v| k.ray(0, v)[1]).collect();
    for u in 0..width {
        rays.clear();
        dirs.clear();
        let x = k.ray(u, 0)[0];
        // Bottom row first: the fan's rays must climb in turn.
        for &y in row_y.iter().rev() {
            let r = [x, y, 1.0];
            rays.push(r);
            dirs.push(world_from_optical.rotate(r));
        }
        fan.cast(&dirs, z_max_m, &mut hits);
        for (rows_up, (r, hit)) in rays.iter().zip(&hits).enumerate() {
            visit(u, height - 1 - rows_up as u32, *r, *hit);
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
    measured(
        spec,
        &cast_depths(world, world_from_optical, spec),
        rng,
        stamp,
        frame_id,
    )
}

/// Every pixel's true optical depth from `world_from_optical`, row by row (`None`: nothing
/// within the camera's maximum depth).
pub fn cast_depths(
    world: &HeightPyramid,
    world_from_optical: &Frame3,
    spec: &DepthCamera,
) -> Vec<Option<f64>> {
    let k = Intrinsics::from_fov(spec.width, spec.height, spec.hfov_deg, spec.vfov_deg);
    let w = spec.width;
    let mut depths = vec![None; (w * spec.height) as usize];
    cast_image(
        world,
        world_from_optical,
        &k,
        w,
        spec.height,
        spec.range_max_m,
        |u, v, _, hit| depths[(v * w + u) as usize] = hit,
    );
    depths
}

/// The frame of the pixels' true depths `depths` ([`cast_depths`]): each given its noise in
/// the order [`cast_image`] visits them (column by column, bottom row first), so a frame
/// measured from depths cast earlier draws the noise a fresh cast would.
pub fn measured(
    spec: &DepthCamera,
    depths: &[Option<f64>],
    rng: &mut SimRng,
    stamp: Time,
    frame_id: &str,
) -> PointCloud {
    let k = Intrinsics::from_fov(spec.width, spec.height, spec.hfov_deg, spec.vfov_deg);
    let (w, h) = (spec.width, spec.height);
    let mut points = vec![[f32::NAN; 3]; (w * h) as usize];
    // A pixel's ray is its column's x and its row's y, as `cast_image` makes it.
    let row_y: Vec<f64> = (0..h).map(|v| k.ray(0, v)[1]).collect();
    for u in 0..w {
        let x = k.ray(u, 0)[0];
        for v in (0..h).rev() {
            let i = (v * w + u) as usize;
            let Some(z) = depths[i] else { continue };
            if z < spec.range_min_m {
                continue;
            }
            let z_noisy = z + gaussian(rng, spec.noise_per_m2 * z * z);
            let y = row_y[v as usize];
            points[i] = [(x * z_noisy) as f32, (y * z_noisy) as f32, z_noisy as f32];
        }
    }
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
