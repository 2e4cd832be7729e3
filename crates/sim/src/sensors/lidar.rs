//! RPLIDAR A2M8-like 2D lidar: a 360 degree fan of beams in the sensor's x-y plane, which tilts
//! with the rover (so on slopes it can hit the ground, and it never sees a crater bowl).

use super::{Frame3, gaussian};
use crate::raycast::HeightPyramid;
use crate::rng::SimRng;
use crate::scenario::Lidar;
use realms_core::Time;
use realms_core::msgs::{Header, LaserScan};

/// Takes one scan from `world_from_lidar`.
pub fn scan(
    world: &HeightPyramid,
    world_from_lidar: &Frame3,
    spec: &Lidar,
    rng: &mut SimRng,
    stamp: Time,
    frame_id: &str,
) -> LaserScan {
    let n = spec.beams as usize;
    let increment = std::f64::consts::TAU / n as f64;
    let angle_min = -std::f64::consts::PI;
    let mut ranges = Vec::with_capacity(n);
    // Beam i points at angle_min + i * increment: rotate the beam vector step by step
    // instead of two trig calls per beam (the drift over 360 steps is ~1e-13 rad).
    let (s_inc, c_inc) = increment.sin_cos();
    let (mut s_a, mut c_a) = angle_min.sin_cos();
    // Beams are cast eight side by side, then given their noise in order (four were 2-4 %
    // slower in the lidar-only trial, six and twelve no faster; BENCHMARKS.md).
    const SIDE_BY_SIDE: usize = 8;
    let mut dirs = [[0.0; 3]; SIDE_BY_SIDE];
    let mut done = 0;
    while done < n {
        let count = SIDE_BY_SIDE.min(n - done);
        for dir in dirs.iter_mut().take(count) {
            *dir = world_from_lidar.rotate([c_a, s_a, 0.0]);
            (c_a, s_a) = (c_a * c_inc - s_a * s_inc, s_a * c_inc + c_a * s_inc);
        }
        let hits = if count == SIDE_BY_SIDE {
            world.cast_side_by_side(world_from_lidar.origin, dirs, spec.range_max_m)
        } else {
            let mut hits = [None; SIDE_BY_SIDE];
            for (hit, dir) in hits.iter_mut().zip(&dirs).take(count) {
                *hit = world.cast(world_from_lidar.origin, *dir, 0.0, spec.range_max_m);
            }
            hits
        };
        for hit in hits.into_iter().take(count) {
            let range = match hit {
                Some(t) => {
                    let noisy = t + gaussian(rng, spec.noise_m + spec.noise_per_m * t);
                    if noisy < spec.range_min_m || noisy > spec.range_max_m {
                        f32::INFINITY
                    } else {
                        noisy as f32
                    }
                }
                None => f32::INFINITY,
            };
            ranges.push(range);
        }
        done += count;
    }
    let scan_time = 1.0 / spec.rate_hz;
    LaserScan {
        header: Header {
            stamp,
            frame_id: frame_id.to_string(),
        },
        angle_min_rad: angle_min as f32,
        angle_max_rad: (angle_min + (n - 1) as f64 * increment) as f32,
        angle_increment_rad: increment as f32,
        time_increment_s: (scan_time / n as f64) as f32,
        scan_time_s: scan_time as f32,
        range_min_m: spec.range_min_m as f32,
        range_max_m: spec.range_max_m as f32,
        ranges_m: ranges,
        intensities: Vec::new(),
    }
}
