//! A small grayscale camera rendered from the terrain under a low sun: Lambertian shading,
//! hard shadows (read from the terrain's shadow map, [`SunShadows`]), black sky, as in a
//! lunar analogue hall lit by one lamp. Rendered only when someone subscribes, so it costs
//! nothing otherwise.

use super::Frame3;
use super::depth::{Intrinsics, cast_image};
use super::shadows::SunShadows;
use crate::raycast::HeightPyramid;
use crate::scenario::Camera;
use crate::terrain::{SurfaceKind, Terrain};
use realms_core::Time;
use realms_core::msgs::{Header, Image};

/// Renders one `mono8` image from `world_from_optical`, lit by the sun whose shadows over
/// `terrain` are `shadows`.
pub fn render(
    world: &HeightPyramid,
    terrain: &Terrain,
    shadows: &SunShadows,
    world_from_optical: &Frame3,
    spec: &Camera,
    stamp: Time,
    frame_id: &str,
) -> Image {
    let sun = shadows.sun();
    let (w, h) = (spec.width, spec.height);
    let vfov_deg = 2.0
        * ((h as f64 / w as f64) * (spec.hfov_deg.to_radians() / 2.0).tan())
            .atan()
            .to_degrees();
    let k = Intrinsics::from_fov(w, h, spec.hfov_deg, vfov_deg);
    let (se, ce) = sun.elevation_deg.to_radians().sin_cos();
    let (sa, ca) = sun.azimuth_deg.to_radians().sin_cos();
    let to_sun = [ce * ca, ce * sa, se];
    let exposure = 1.5 / se.max(0.1);
    let g = *terrain.geometry();
    let mut data = vec![0u8; (w * h) as usize];
    cast_image(
        world,
        world_from_optical,
        &k,
        w,
        h,
        30.0,
        |u, v, ray, hit| {
            let Some(z) = hit else { return };
            let dir = world_from_optical.rotate(ray);
            let o = world_from_optical.origin;
            let p = [o[0] + dir[0] * z, o[1] + dir[1] * z, o[2] + dir[2] * z];
            let Some(cell) = g.world_to_cell(realms_core::Point2::new(p[0], p[1])) else {
                return;
            };
            let (x, y) = (cell.x, cell.y);
            let normal = terrain.surface_normal(x, y);
            let lambert =
                (normal[0] * to_sun[0] + normal[1] * to_sun[1] + normal[2] * to_sun[2]).max(0.0);
            // Seen from just off the surface towards the sun, as a shadow ray would start, so
            // a lit wall face is not taken for its own column and the floor is not shaded by
            // the small steps between its cells (up to a centimetre or so).
            let lit = lambert > 0.0
                && shadows.lit([
                    p[0] + 0.03 * to_sun[0],
                    p[1] + 0.03 * to_sun[1],
                    p[2] + 0.03 * to_sun[2] + 0.005,
                ]);
            let albedo = match terrain.kind.cells()[g.index(cell)] {
                SurfaceKind::Floor => 0.30 + 0.06 * texture(x, y),
                SurfaceKind::Rock => 0.42 + 0.08 * texture(x / 2, y / 2),
                SurfaceKind::Wall => 0.6,
                SurfaceKind::Lander => 0.85,
                SurfaceKind::Target => 0.95,
            };
            let light = 0.03 + if lit { lambert } else { 0.0 };
            let value = (albedo * light * exposure * 255.0).clamp(0.0, 255.0);
            data[(v * w + u) as usize] = value as u8;
        },
    );
    Image {
        header: Header {
            stamp,
            frame_id: frame_id.to_string(),
        },
        height: h,
        width: w,
        encoding: "mono8".into(),
        step: w,
        data,
    }
}

/// Deterministic per-cell texture in [-1, 1] (a hash, so the regolith looks grainy).
fn texture(x: usize, y: usize) -> f64 {
    let mut v = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    v ^= v >> 29;
    v = v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    v ^= v >> 32;
    (v % 2001) as f64 / 1000.0 - 1.0
}
