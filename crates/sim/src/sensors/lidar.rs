//! RPLIDAR A2M8-like 2D lidar: a 360 degree fan of beams in the sensor's x-y plane, which tilts
//! with the rover (so on slopes it can hit the ground, and it never sees a crater bowl). Its
//! head turns once a scan, so each beam is measured at its own time and from wherever the
//! rover then was ([`sweep`]): a rover turning at 1 rad/s turns 5.7 degrees during a 10 Hz
//! scan, and SLAM must take that motion out of the scan as it would on the real sensor.

use super::{Frame3, gaussian};
use crate::raycast::HeightPyramid;
use crate::rng::SimRng;
use crate::scenario::Lidar;
use realms_core::msgs::{Header, LaserScan, sweep_duration};
use realms_core::{Duration, Time};

/// A stretch of a sweep's beams measured while the rover moves from one physics state to the
/// next: its heading turns and its position moves by the same amount from beam to beam.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepSegment {
    /// The first beam measured in it (the first segment's is 0).
    pub first_beam: usize,
    /// `world_from_lidar` when that beam was measured ...
    pub frame: Frame3,
    /// ... how far the origin moves from each beam to the next, metres ...
    pub origin_step_m: [f64; 3],
    /// ... and how far the frame turns about the world's vertical from each beam to the next.
    pub yaw_step_rad: f64,
}

impl SweepSegment {
    /// A segment in which the lidar stands still.
    pub fn still(first_beam: usize, frame: Frame3) -> Self {
        SweepSegment {
            first_beam,
            frame,
            origin_step_m: [0.0; 3],
            yaw_step_rad: 0.0,
        }
    }
}

/// Takes one instantaneous scan: every beam from `world_from_lidar` at `stamp`
/// (`time_increment_s` 0).
pub fn scan(
    world: &HeightPyramid,
    world_from_lidar: &Frame3,
    spec: &Lidar,
    rng: &mut SimRng,
    stamp: Time,
    frame_id: &str,
) -> LaserScan {
    let hits = cast_hits(world, &[SweepSegment::still(0, *world_from_lidar)], spec);
    measured(spec, &hits, false, rng, stamp, frame_id)
}

/// The time between beams of a sweeping scan: one turn of the head per scan.
pub fn time_increment_s(spec: &Lidar) -> f32 {
    (1.0 / spec.rate_hz / spec.beams as f64) as f32
}

/// How long a scan of `spec` takes from its first beam to its last, if it sweeps: `None` for
/// a lidar that measures at once, and for one whose head turns slower than once a second,
/// which no receiver would take for a sweep ([`LaserScan::sweep`]) and so measures at once.
pub fn sweep_length(spec: &Lidar) -> Option<Duration> {
    let sweep = sweep_duration(spec.beams as usize, time_increment_s(spec));
    (spec.sweeps && sweep > Duration::ZERO).then_some(sweep)
}

/// Takes one scan as a spinning lidar does, each beam at its own time (`stamp` the first
/// beam's, `time_increment_s(spec)` between beams) and from where the lidar then was: the
/// beams of each of `segments` from its first to the next one's.
pub fn sweep(
    world: &HeightPyramid,
    segments: &[SweepSegment],
    spec: &Lidar,
    rng: &mut SimRng,
    stamp: Time,
    frame_id: &str,
) -> LaserScan {
    measured(
        spec,
        &cast_hits(world, segments, spec),
        true,
        rng,
        stamp,
        frame_id,
    )
}

/// The scan of the beams' true ranges `hits` ([`cast_hits`]): each given its noise in beam
/// order, `sweeping` if each beam was measured at its own time.
pub fn measured(
    spec: &Lidar,
    hits: &[Option<f64>],
    sweeping: bool,
    rng: &mut SimRng,
    stamp: Time,
    frame_id: &str,
) -> LaserScan {
    let ranges = hits
        .iter()
        .map(|hit| match *hit {
            Some(t) => {
                let noisy = t + gaussian(rng, spec.noise_m + spec.noise_per_m * t);
                if noisy < spec.range_min_m || noisy > spec.range_max_m {
                    f32::INFINITY
                } else {
                    noisy as f32
                }
            }
            None => f32::INFINITY,
        })
        .collect();
    let increment = if sweeping {
        time_increment_s(spec)
    } else {
        0.0
    };
    message(spec, ranges, increment, stamp, frame_id)
}

/// Every beam's true range (`None`: nothing within the lidar's reach), in beam order, each
/// cast from where its segment puts the lidar.
pub fn cast_hits(
    world: &HeightPyramid,
    segments: &[SweepSegment],
    spec: &Lidar,
) -> Vec<Option<f64>> {
    let n = spec.beams as usize;
    let increment = std::f64::consts::TAU / n as f64;
    let angle_min = -std::f64::consts::PI;
    let mut ranges = Vec::with_capacity(n);
    // Beam i points at angle_min + i * increment: rotate the beam vector step by step
    // instead of two trig calls per beam (the drift over 360 steps is ~1e-13 rad). A
    // segment's turn is stepped the same way.
    let (s_inc, c_inc) = increment.sin_cos();
    let (mut s_a, mut c_a) = angle_min.sin_cos();
    // Beams are cast eight side by side (four were 2-4 % slower in the lidar-only trial, six
    // and twelve no faster; BENCHMARKS.md).
    const SIDE_BY_SIDE: usize = 8;
    let mut dirs = [[0.0; 3]; SIDE_BY_SIDE];
    let mut origins = [[0.0; 3]; SIDE_BY_SIDE];
    let mut done = 0;
    for (k, seg) in segments.iter().enumerate() {
        debug_assert!(
            k > 0 || seg.first_beam == 0,
            "the first segment starts at beam 0"
        );
        let until = segments.get(k + 1).map_or(n, |next| next.first_beam.min(n));
        let (s_turn, c_turn) = seg.yaw_step_rad.sin_cos();
        let (mut s_y, mut c_y) = (0.0f64, 1.0f64);
        let mut origin = seg.frame.origin;
        while done < until {
            let count = SIDE_BY_SIDE.min(until - done);
            for (dir, o) in dirs.iter_mut().zip(&mut origins).take(count) {
                let d = seg.frame.rotate([c_a, s_a, 0.0]);
                *dir = [c_y * d[0] - s_y * d[1], s_y * d[0] + c_y * d[1], d[2]];
                *o = origin;
                (c_a, s_a) = (c_a * c_inc - s_a * s_inc, s_a * c_inc + c_a * s_inc);
                (c_y, s_y) = (c_y * c_turn - s_y * s_turn, s_y * c_turn + c_y * s_turn);
                origin = [
                    origin[0] + seg.origin_step_m[0],
                    origin[1] + seg.origin_step_m[1],
                    origin[2] + seg.origin_step_m[2],
                ];
            }
            let hits = if count == SIDE_BY_SIDE {
                world.cast_side_by_side(origins, dirs, spec.range_max_m)
            } else {
                let mut hits = [None; SIDE_BY_SIDE];
                for ((hit, dir), o) in hits.iter_mut().zip(&dirs).zip(&origins).take(count) {
                    *hit = world.cast(*o, *dir, 0.0, spec.range_max_m);
                }
                hits
            };
            ranges.extend(hits.into_iter().take(count));
            done += count;
        }
    }
    ranges
}

/// The LaserScan message of a scan's ranges.
fn message(
    spec: &Lidar,
    ranges: Vec<f32>,
    time_increment_s: f32,
    stamp: Time,
    frame_id: &str,
) -> LaserScan {
    let n = spec.beams as usize;
    let increment = std::f64::consts::TAU / n as f64;
    let angle_min = -std::f64::consts::PI;
    let scan_time = 1.0 / spec.rate_hz;
    LaserScan {
        header: Header {
            stamp,
            frame_id: frame_id.to_string(),
        },
        angle_min_rad: angle_min as f32,
        angle_max_rad: (angle_min + (n - 1) as f64 * increment) as f32,
        angle_increment_rad: increment as f32,
        time_increment_s,
        scan_time_s: scan_time as f32,
        range_min_m: spec.range_min_m as f32,
        range_max_m: spec.range_max_m as f32,
        ranges_m: ranges,
        intensities: Vec::new(),
    }
}
