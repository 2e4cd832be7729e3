//! How fast a rover's tracked pose drifts, by how far it is from the arena's edge, for
//! `realms bench slam`. The final maps swing by ten points a rover from any change; the
//! drift of the pose as tracked, over short windows, is a steadier measure of tracking.
//!
//! A window is [`WINDOW_SCANS`] consecutive scans. Its error is the tracked motion over the
//! window against the true motion, both in the frame of the window's first pose. A window is
//! left out if the rover was not tracking, if it travelled under [`MIN_TRAVEL_M`], or if any
//! one scan's tracked step left its true step by more than [`JUMP_M`] or [`JUMP_RAD`]: an
//! optimisation or a relocalisation moved the pose there, which is not drift.

use realms_core::{Point2, Pose2};

/// Scans in a window (5 s of a 10 Hz lidar).
pub const WINDOW_SCANS: usize = 50;
/// A window must cover at least this much travel, metres.
const MIN_TRAVEL_M: f64 = 0.5;
/// One scan's step off its true step by more than this is a jump, not drift ...
const JUMP_M: f64 = 0.03;
/// ... or by more than this, radians.
const JUMP_RAD: f64 = 0.01;
/// Upper edges of the bands of distance to the arena's edge, metres; the last band is open.
pub const BAND_EDGES_M: [f64; 2] = [6.0, 10.0];

/// Drift summed over the windows of one band.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Band {
    /// True travel of the windows, metres.
    pub travel_m: f64,
    /// Their position errors, summed, metres.
    pub position_error_m: f64,
    /// Their heading errors' sizes, summed, radians.
    pub heading_error_rad: f64,
}

impl Band {
    /// Position error as a share of the travel.
    pub fn position_share(&self) -> f64 {
        self.position_error_m / self.travel_m.max(1e-9)
    }

    /// Heading error per metre of travel, degrees.
    pub fn heading_deg_per_m(&self) -> f64 {
        self.heading_error_rad.to_degrees() / self.travel_m.max(1e-9)
    }

    /// Adds another band's windows.
    pub fn add(&mut self, other: &Band) {
        self.travel_m += other.travel_m;
        self.position_error_m += other.position_error_m;
        self.heading_error_rad += other.heading_error_rad;
    }
}

/// One scan: true pose, tracked pose, and whether the rover was tracking.
pub type Scan = (Pose2, Pose2, bool);

/// The drift of `scans` in each band of distance from the edge of the box `arena` (corner,
/// opposite corner), nearest band first ([`BAND_EDGES_M`]). A window counts in the band of
/// its scan nearest the edge.
pub fn drift_by_band(scans: &[Scan], arena: (Point2, Point2)) -> [Band; 3] {
    let mut bands = [Band::default(); 3];
    let jump = |a: &Scan, b: &Scan| {
        let truth = a.0.inverse() * b.0;
        let tracked = a.1.inverse() * b.1;
        let d = tracked.relative_to(&truth);
        d.x_m.hypot(d.y_m) > JUMP_M || d.yaw_rad.abs() > JUMP_RAD
    };
    let to_edge = |p: Point2| {
        (p.x_m - arena.0.x_m)
            .min(arena.1.x_m - p.x_m)
            .min(p.y_m - arena.0.y_m)
            .min(arena.1.y_m - p.y_m)
    };
    for window in scans.chunks_exact(WINDOW_SCANS + 1) {
        if window.iter().any(|s| !s.2) || window.windows(2).any(|w| jump(&w[0], &w[1])) {
            continue;
        }
        let (first, last) = (&window[0], &window[WINDOW_SCANS]);
        let truth = first.0.inverse() * last.0;
        let tracked = first.1.inverse() * last.1;
        let travel_m = truth.x_m.hypot(truth.y_m);
        if travel_m < MIN_TRAVEL_M {
            continue;
        }
        let nearest = window
            .iter()
            .map(|s| to_edge(s.0.position()))
            .fold(f64::INFINITY, f64::min);
        let band = BAND_EDGES_M
            .iter()
            .position(|edge| nearest < *edge)
            .unwrap_or(BAND_EDGES_M.len());
        let b = &mut bands[band];
        b.travel_m += travel_m;
        b.position_error_m += (tracked.x_m - truth.x_m).hypot(tracked.y_m - truth.y_m);
        b.heading_error_rad +=
            realms_core::geometry::normalize_angle_rad(tracked.yaw_rad - truth.yaw_rad).abs();
    }
    bands
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A drive east along `y_m` at 5 cm a scan whose tracked pose falls behind by
    /// `lag_per_m` of the travel, with a jump of 0.5 m at scan `jump_at`, if any.
    fn drive(y_m: f64, lag_per_m: f64, jump_at: Option<usize>) -> Vec<Scan> {
        let mut offset = 0.0;
        (0..4 * (WINDOW_SCANS + 1))
            .map(|k| {
                let x = 15.0 + 0.05 * k as f64;
                if Some(k) == jump_at {
                    offset += 0.5;
                }
                let truth = Pose2::new(x, y_m, 0.0);
                let tracked = Pose2::new(x - lag_per_m * 0.05 * k as f64 + offset, y_m, 0.0);
                (truth, tracked, true)
            })
            .collect()
    }

    #[test]
    fn a_lag_of_a_centimetre_a_metre_is_one_percent_in_its_band() {
        let arena = (Point2::new(0.0, 0.0), Point2::new(50.0, 36.0));
        // 3 m from the south edge: the nearest band. Four windows of 2.5 m.
        let near = drift_by_band(&drive(3.0, 0.01, None), arena);
        assert!((near[0].travel_m - 10.0).abs() < 1e-9, "{near:?}");
        assert!((near[0].position_share() - 0.01).abs() < 1e-9, "{near:?}");
        assert_eq!(near[1], Band::default());
        // 18 m from every edge: the far band.
        let far = drift_by_band(&drive(18.0, 0.02, None), arena);
        assert!((far[2].position_share() - 0.02).abs() < 1e-9, "{far:?}");
        assert_eq!(far[0], Band::default());
    }

    #[test]
    fn a_window_holding_a_jump_is_left_out() {
        let arena = (Point2::new(0.0, 0.0), Point2::new(50.0, 36.0));
        let bands = drift_by_band(&drive(3.0, 0.01, Some(WINDOW_SCANS + 10)), arena);
        assert!((bands[0].travel_m - 7.5).abs() < 1e-9, "{bands:?}");
        assert!((bands[0].position_share() - 0.01).abs() < 1e-9, "{bands:?}");
    }
}
