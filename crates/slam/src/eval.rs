//! The relative pose error of Kümmerle et al., "On measuring the accuracy of SLAM algorithms"
//! (Autonomous Robots, 2009): for each ground-truth relation d* between the poses at t1 and
//! t2, e = d*^-1 (+) (x(t1)^-1 (+) x(t2)); report the mean and standard deviation of |e_xy|
//! and |e_theta| over all relations.

use crate::trajectory::StampedPose;
use realms_core::Pose2;
use realms_core::geometry::normalize_angle_rad;

/// A ground-truth relation: the pose at `t2_s` in the robot frame at `t1_s`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Relation {
    /// Earlier timestamp.
    pub t1_s: f64,
    /// Later timestamp.
    pub t2_s: f64,
    /// `pose(t1)^-1 (+) pose(t2)`.
    pub delta: Pose2,
}

/// Why relations could not be read or evaluated.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The relations file could not be read or has a bad line.
    #[error(transparent)]
    File(#[from] crate::numeric_lines::TextFileError),
    /// Nothing to evaluate.
    #[error(
        "no relation has estimated poses at both of its timestamps ({missing} relations lack one)"
    )]
    NoOverlap {
        /// Relations without estimates.
        missing: usize,
    },
}

/// Parses a `.relations` file: `t1 t2 x y z roll pitch yaw` per line.
pub fn parse_relations(text: &str, path: &str) -> Result<Vec<Relation>, EvalError> {
    let rows = crate::numeric_lines::parse_named(text, path, 8, "t1 t2 x y z roll pitch yaw")?;
    Ok(rows
        .into_iter()
        .map(|v| Relation {
            t1_s: v[0],
            t2_s: v[1],
            delta: Pose2::new(v[2], v[3], v[7]),
        })
        .collect())
}

/// Reads a `.relations` file.
pub fn read_relations(path: &std::path::Path) -> Result<Vec<Relation>, EvalError> {
    parse_relations(
        &crate::numeric_lines::read(path)?,
        &path.display().to_string(),
    )
}

/// The relative pose error over a set of relations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativePoseError {
    /// Relations evaluated.
    pub relations: usize,
    /// Relations skipped because the trajectory has no pose at one of their timestamps.
    pub missing: usize,
    /// Mean translational error, metres.
    pub trans_mean_m: f64,
    /// Standard deviation of the translational error, metres.
    pub trans_std_m: f64,
    /// Mean rotational error, degrees.
    pub rot_mean_deg: f64,
    /// Standard deviation of the rotational error, degrees.
    pub rot_std_deg: f64,
    /// Median translational error, metres: what most relations show, where one missed loop
    /// closure moves the mean by a factor of ten.
    pub trans_median_m: f64,
    /// Median rotational error, degrees.
    pub rot_median_deg: f64,
}

/// Timestamps match if they differ by less than this (logs print microseconds).
const STAMP_TOLERANCE_S: f64 = 1e-4;

fn pose_at(sorted: &[StampedPose], t: f64) -> Option<Pose2> {
    let i = sorted.partition_point(|p| p.timestamp_s < t);
    [i.checked_sub(1), Some(i)]
        .into_iter()
        .flatten()
        .filter_map(|j| sorted.get(j))
        .find(|p| (p.timestamp_s - t).abs() < STAMP_TOLERANCE_S)
        .map(|p| p.pose)
}

/// Evaluates a trajectory (any order) against relations.
pub fn relative_pose_error(
    trajectory: &[StampedPose],
    relations: &[Relation],
) -> Result<RelativePoseError, EvalError> {
    let mut sorted = trajectory.to_vec();
    sorted.sort_by(|a, b| a.timestamp_s.total_cmp(&b.timestamp_s));
    let mut trans = Vec::with_capacity(relations.len());
    let mut rot = Vec::with_capacity(relations.len());
    let mut missing = 0;
    for r in relations {
        let (Some(a), Some(b)) = (pose_at(&sorted, r.t1_s), pose_at(&sorted, r.t2_s)) else {
            missing += 1;
            continue;
        };
        let e = r.delta.inverse() * (a.inverse() * b);
        trans.push(e.x_m.hypot(e.y_m));
        rot.push(normalize_angle_rad(e.yaw_rad).abs().to_degrees());
    }
    if trans.is_empty() {
        return Err(EvalError::NoOverlap { missing });
    }
    let (tm, ts) = mean_std(&trans);
    let (rm, rs) = mean_std(&rot);
    Ok(RelativePoseError {
        relations: trans.len(),
        missing,
        trans_mean_m: tm,
        trans_std_m: ts,
        rot_mean_deg: rm,
        rot_std_deg: rs,
        trans_median_m: median(&mut trans),
        rot_median_deg: median(&mut rot),
    })
}

/// The median (the mean of the middle two for an even count); `v` is sorted in place.
fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_checked_error() {
        // Truth: 1 m forward. Estimate: 1.1 m forward and 0.1 rad turned.
        let rel = [Relation {
            t1_s: 1.0,
            t2_s: 2.0,
            delta: Pose2::new(1.0, 0.0, 0.0),
        }];
        let traj = [
            StampedPose {
                timestamp_s: 2.00001,
                pose: Pose2::new(3.1, 2.0, 0.1),
            },
            StampedPose {
                timestamp_s: 1.0,
                pose: Pose2::new(2.0, 2.0, 0.0),
            },
        ];
        let e = relative_pose_error(&traj, &rel).expect("overlap");
        assert_eq!(e.relations, 1);
        assert!((e.trans_mean_m - 0.1).abs() < 1e-9, "{e:?}");
        assert!((e.rot_mean_deg - 0.1f64.to_degrees()).abs() < 1e-9);
        assert!((e.trans_median_m - 0.1).abs() < 1e-9, "{e:?}");
        let none = relative_pose_error(&traj[..1], &rel);
        assert!(matches!(none, Err(EvalError::NoOverlap { missing: 1 })));
    }

    #[test]
    fn the_median_is_the_middle_relation_and_ignores_one_outlier() {
        // Three relations of 1 m forward; the estimate is 0.01, 0.02 and 5 m off.
        let rel: Vec<Relation> = (0..3)
            .map(|k| Relation {
                t1_s: 2.0 * k as f64,
                t2_s: 2.0 * k as f64 + 1.0,
                delta: Pose2::new(1.0, 0.0, 0.0),
            })
            .collect();
        let traj: Vec<StampedPose> = [0.01, 0.02, 5.0]
            .iter()
            .enumerate()
            .flat_map(|(k, off)| {
                let t = 2.0 * k as f64;
                [
                    StampedPose {
                        timestamp_s: t,
                        pose: Pose2::IDENTITY,
                    },
                    StampedPose {
                        timestamp_s: t + 1.0,
                        pose: Pose2::new(1.0 + off, 0.0, 0.0),
                    },
                ]
            })
            .collect();
        let e = relative_pose_error(&traj, &rel).expect("overlap");
        assert!((e.trans_median_m - 0.02).abs() < 1e-9, "{e:?}");
        assert!((e.trans_mean_m - 5.03 / 3.0).abs() < 1e-9, "{e:?}");
    }

    #[test]
    fn bad_relations_lines_are_errors() {
        let e = parse_relations("1 2 0 0 0 0 0 0\n1 2 3\n", "r.rel").expect_err("short line");
        assert!(e.to_string().contains("r.rel line 2"), "{e}");
    }
}
