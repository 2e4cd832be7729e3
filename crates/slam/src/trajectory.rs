//! Trajectory files: one `timestamp x y theta` line per pose, the form `realms slam` writes and
//! `realms slam-eval` reads.

use realms_core::Pose2;
use std::fmt::Write as _;

/// A pose at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StampedPose {
    /// Seconds.
    pub timestamp_s: f64,
    /// Pose.
    pub pose: Pose2,
}

/// Why a trajectory could not be read.
pub type TrajectoryError = crate::numeric_lines::TextFileError;

/// Formats poses as `timestamp x y theta` lines.
pub fn to_text(poses: &[StampedPose]) -> String {
    let mut s = String::with_capacity(poses.len() * 48);
    for p in poses {
        let _ = writeln!(
            s,
            "{:.6} {:.6} {:.6} {:.6}",
            p.timestamp_s, p.pose.x_m, p.pose.y_m, p.pose.yaw_rad
        );
    }
    s
}

/// Parses `timestamp x y theta` lines (blank lines and `#` comments skipped); `path` names the
/// source in errors.
pub fn parse(text: &str, path: &str) -> Result<Vec<StampedPose>, TrajectoryError> {
    let rows = crate::numeric_lines::parse_named(text, path, 4, "timestamp x y theta")?;
    Ok(rows
        .into_iter()
        .map(|v| StampedPose {
            timestamp_s: v[0],
            pose: Pose2::new(v[1], v[2], v[3]),
        })
        .collect())
}

/// Reads a trajectory file.
pub fn read_file(path: &std::path::Path) -> Result<Vec<StampedPose>, TrajectoryError> {
    parse(
        &crate::numeric_lines::read(path)?,
        &path.display().to_string(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_rejects_bad_lines() {
        let poses = vec![
            StampedPose {
                timestamp_s: 976052857.337284,
                pose: Pose2::new(1.5, -2.25, 0.125),
            },
            StampedPose {
                timestamp_s: 976052857.5,
                pose: Pose2::new(0.0, 0.0, -3.0),
            },
        ];
        let back = parse(&to_text(&poses), "t").expect("valid");
        assert_eq!(back, poses);
        let e = parse("# x\n1 2 3 4\n1 2 three 4\n", "f.txt").expect_err("bad");
        assert!(e.to_string().contains("f.txt line 3"), "{e}");
        assert!(parse("1 2 3\n", "f").is_err());
        assert!(parse("1 2 3 inf\n", "f").is_err());
    }
}
