//! Loop closures graded against the truth, for `realms bench slam`: each closure a rover's
//! mapper verified, against the true relative pose of its two keyframes.
//!
//! A closure measures a keyframe's pose in the frame of its submap's first keyframe; the
//! truth's relative pose of those two keyframes is what it should have measured (up to the
//! submap's own small drift while it was drawn).

use realms_core::Pose2;
use realms_slam::mapper::{ClosureRecord, Mapper};

/// An accepted closure farther than this from the truth's relative pose counts as wrong ...
pub const WRONG_CLOSURE_M: f64 = 0.1;
/// ... or turned more than this, degrees.
pub const WRONG_CLOSURE_DEG: f64 = 1.0;

/// The columns of a `--trajectories` closures file.
const CSV_HEADER: &str = "from_t_s,to_t_s,error_m,error_deg,along_weakest_m,search_score,rival_score,score,weakest_information,strongest_information,heading_information,within_drift,accepted,on_walls,from_behind";

/// One verified closure against the truth.
#[derive(Clone, Copy, Debug)]
pub struct GradedClosure {
    /// The closure as the mapper recorded it.
    pub record: ClosureRecord,
    /// The time of the submap's first keyframe, seconds ...
    pub from_t_s: f64,
    /// ... and of the keyframe it closed.
    pub to_t_s: f64,
    /// How far its measurement is from the truth's, metres ...
    pub error_m: f64,
    /// ... turned, degrees ...
    pub error_deg: f64,
    /// ... and the part of the error along the direction its match pins least, metres.
    pub along_weakest_m: f64,
    /// The smaller eigenvalue of its match's translation information ...
    pub weakest_information: f64,
    /// ... and the larger.
    pub strongest_information: f64,
}

impl GradedClosure {
    /// Whether it is accepted and wrong ([`WRONG_CLOSURE_M`], [`WRONG_CLOSURE_DEG`]).
    pub fn accepted_wrong(&self) -> bool {
        self.record.accepted
            && (self.error_m > WRONG_CLOSURE_M || self.error_deg > WRONG_CLOSURE_DEG)
    }
}

/// Grades `record`, joining keyframes taken at `from_t_s` and `to_t_s`, whose true poses
/// were `from` and `to`.
pub fn grade(
    record: &ClosureRecord,
    (from_t_s, from): (f64, Pose2),
    (to_t_s, to): (f64, Pose2),
) -> GradedClosure {
    let want = from.inverse() * to;
    let measured = record.edge.measurement;
    let d = measured.relative_to(&want);
    // The error in the submap's frame, where the match's information is.
    let (dx, dy) = (measured.x_m - want.x_m, measured.y_m - want.y_m);
    let i = &record.information;
    let (weakest, strongest, (ux, uy)) =
        realms_slam::ndt::eigen_symmetric2(i[0][0], i[0][1], i[1][1]);
    GradedClosure {
        record: *record,
        from_t_s,
        to_t_s,
        error_m: d.x_m.hypot(d.y_m),
        error_deg: d.yaw_rad.abs().to_degrees(),
        along_weakest_m: (dx * ux + dy * uy).abs(),
        weakest_information: weakest,
        strongest_information: strongest,
    }
}

/// Every closure `mapper` verified, graded; `truth_at` gives the true pose at a keyframe's
/// time (closures whose keyframes it does not know are left out).
pub fn grade_all(mapper: &Mapper, truth_at: impl Fn(f64) -> Option<Pose2>) -> Vec<GradedClosure> {
    mapper
        .closure_records()
        .iter()
        .filter_map(|r| {
            let t0 = mapper.keyframe_time_s(r.edge.from)?;
            let t1 = mapper.keyframe_time_s(r.edge.to)?;
            Some(grade(r, (t0, truth_at(t0)?), (t1, truth_at(t1)?)))
        })
        .collect()
}

/// `graded` as CSV, one closure a line.
pub fn csv(graded: &[GradedClosure]) -> String {
    let mut text = format!("{CSV_HEADER}\n");
    for g in graded {
        let r = &g.record;
        text += &format!(
            "{:.3},{:.3},{:.4},{:.3},{:.4},{:.3},{:.3},{:.3},{:.1},{:.1},{:.1},{},{},{},{}\n",
            g.from_t_s,
            g.to_t_s,
            g.error_m,
            g.error_deg,
            g.along_weakest_m,
            r.search_score,
            r.rival_score,
            r.score,
            g.weakest_information,
            g.strongest_information,
            r.information[2][2],
            r.within_drift,
            r.accepted,
            r.on_walls,
            r.from_behind
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use realms_slam::posegraph::Edge;

    #[test]
    fn a_closure_slid_along_its_weak_direction_is_graded_wrong_along_it() {
        // The keyframe truly 2 m ahead of the submap's first, facing north-east; the match
        // pins the submap's x firmly and its y weakly, and measured it 0.12 m off along y.
        let (from, to) = (Pose2::new(1.0, 1.0, 0.0), Pose2::new(3.0, 1.0, 0.8));
        let record = ClosureRecord {
            edge: Edge {
                from: 0,
                to: 7,
                measurement: Pose2::new(2.0, 0.12, 0.8),
                information: [400.0, 400.0, 2500.0],
                information_axis_rad: 0.0,
                robust: true,
            },
            search_score: 0.8,
            rival_score: 0.0,
            score: 0.75,
            information: [[5000.0, 0.0, 0.0], [0.0, 300.0, 0.0], [0.0, 0.0, 1e5]],
            within_drift: true,
            on_walls: 0,
            from_behind: 0,
            accepted: true,
        };
        let g = grade(&record, (10.0, from), (20.0, to));
        assert!((g.error_m - 0.12).abs() < 1e-9, "{g:?}");
        assert!(g.error_deg.abs() < 1e-9, "{g:?}");
        assert!((g.along_weakest_m - 0.12).abs() < 1e-9, "{g:?}");
        assert_eq!(
            (g.weakest_information, g.strongest_information),
            (300.0, 5000.0)
        );
        assert!(g.accepted_wrong());
        let refused = ClosureRecord {
            accepted: false,
            ..record
        };
        assert!(!grade(&refused, (10.0, from), (20.0, to)).accepted_wrong());
        assert_eq!(csv(&[g]).lines().count(), 2);
    }
}
