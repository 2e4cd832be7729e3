//! CARMEN laser logs, the format of the standard 2D SLAM benchmark (Kümmerle et al. 2009).
//!
//! Reads `FLASER` (front laser with the odometry pose at the scan), `ODOM` and
//! `ROBOTLASER1` lines; skips comments and message types it does not use (`PARAM`, `TRUEPOS`,
//! ...). Lines need not be in time order: scans and odometry are sorted by their ipc timestamp.
//! A malformed line is an error naming its line number; nothing panics.

use realms_core::Pose2;
use std::io::BufRead;

/// One laser scan with the odometry pose at which it was taken.
#[derive(Clone, Debug, PartialEq)]
pub struct LaserReading {
    /// ipc timestamp, seconds (the key the benchmark relations use).
    pub timestamp_s: f64,
    /// Angle of the first beam in the laser frame, radians.
    pub angle_min_rad: f64,
    /// Angle between beams, radians.
    pub angle_increment_rad: f64,
    /// Longest valid range; readings at or beyond it are "no return".
    pub max_range_m: f64,
    /// Ranges, metres, first beam first.
    pub ranges_m: Vec<f32>,
    /// Odometry pose of the robot at the scan.
    pub odom: Pose2,
    /// Pose of the laser on the robot (`robot_from_laser`); identity for FLASER.
    pub robot_from_laser: Pose2,
}

/// An odometry reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OdomReading {
    /// ipc timestamp, seconds.
    pub timestamp_s: f64,
    /// Odometry pose.
    pub pose: Pose2,
}

/// A whole log, sorted by timestamp.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CarmenLog {
    /// Laser scans in time order.
    pub scans: Vec<LaserReading>,
    /// Odometry in time order.
    pub odometry: Vec<OdomReading>,
}

/// Why a log could not be read.
#[derive(Debug, thiserror::Error)]
pub enum CarmenError {
    /// The file could not be read.
    #[error("cannot read {path}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("line {line}: {what}")]
    Line {
        /// 1-based line number.
        line: usize,
        /// What was wrong.
        what: String,
    },
}

/// Max range assumed for FLASER lines, which carry none: SICK lasers report ~81.9 m for "no
/// return"; ACES reports 50 m. Anything at or above this is treated as no return.
pub const FLASER_MAX_RANGE_M: f64 = 50.0;

/// A laser message carries the odometry pose its robot process last knew. In some logs that
/// pose is a fraction of a second older than the scan (ACES: 80 ms, median), so in a fast
/// turn the scan is predicted 10-20 degrees from where it was taken, beyond what the local
/// match converges from. Where the median staleness exceeds this, seconds,
/// [`CarmenLog::retime_stale_odometry`] interpolates the odometry at each scan's time from
/// the `ODOM` stream instead. (Intel's median is 0.3 ms: there the `ODOM` times come in
/// bursts of one millisecond, and the pose the laser message carries is the better one.)
pub const STALE_ODOMETRY_S: f64 = 0.02;

/// How many `ODOM` readings on each side of a scan's time are looked through for the one
/// whose pose the scan carries.
const STALENESS_SEARCH_READINGS: usize = 20;

impl CarmenLog {
    /// How much older than its scan the odometry pose a laser message carries is, seconds:
    /// the median, over the scans whose pose is one of the `ODOM` readings near their time,
    /// of the scan's time less that reading's (the nearest in time with that pose). `None`
    /// without `ODOM` readings the scans' poses come from.
    pub fn odometry_staleness_s(&self) -> Option<f64> {
        let mut lags: Vec<f64> = self
            .scans
            .iter()
            .filter_map(|scan| {
                let k = self
                    .odometry
                    .partition_point(|o| o.timestamp_s < scan.timestamp_s);
                let near = &self.odometry[k.saturating_sub(STALENESS_SEARCH_READINGS)
                    ..(k + STALENESS_SEARCH_READINGS).min(self.odometry.len())];
                near.iter()
                    .filter(|o| o.pose == scan.odom)
                    .map(|o| scan.timestamp_s - o.timestamp_s)
                    .min_by(|a, b| a.abs().total_cmp(&b.abs()))
            })
            .collect();
        if lags.is_empty() {
            return None;
        }
        let mid = lags.len() / 2;
        Some(*lags.select_nth_unstable_by(mid, f64::total_cmp).1)
    }

    /// The `ODOM` stream interpolated at `time_s`; `None` outside it.
    pub fn odometry_at(&self, time_s: f64) -> Option<Pose2> {
        let k = self.odometry.partition_point(|o| o.timestamp_s < time_s);
        let after = self.odometry.get(k)?;
        if after.timestamp_s == time_s {
            return Some(after.pose);
        }
        let before = self.odometry.get(k.checked_sub(1)?)?;
        let span = after.timestamp_s - before.timestamp_s;
        let s = if span > 0.0 {
            (time_s - before.timestamp_s) / span
        } else {
            1.0
        };
        Some(before.pose.interpolate(&after.pose, s))
    }

    /// Where the laser messages carry odometry more than [`STALE_ODOMETRY_S`] older than
    /// themselves (median), gives each scan within the `ODOM` stream the odometry
    /// interpolated at its own time. Returns the staleness found and how many scans were
    /// given new odometry (none where it is fresh or unknown).
    pub fn retime_stale_odometry(&mut self) -> (Option<f64>, usize) {
        let staleness = self.odometry_staleness_s();
        if !staleness.is_some_and(|s| s > STALE_ODOMETRY_S) {
            return (staleness, 0);
        }
        let mut retimed = 0;
        for k in 0..self.scans.len() {
            if let Some(odom) = self.odometry_at(self.scans[k].timestamp_s) {
                self.scans[k].odom = odom;
                retimed += 1;
            }
        }
        (staleness, retimed)
    }

    /// Reads a log file.
    pub fn read_file(path: &std::path::Path) -> Result<CarmenLog, CarmenError> {
        let io = |source| CarmenError::Io {
            path: path.display().to_string(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        CarmenLog::read(std::io::BufReader::new(file)).map_err(|e| match e {
            CarmenError::Io { source, .. } => io(source),
            other => other,
        })
    }

    /// Reads a log from any reader.
    pub fn read(reader: impl BufRead) -> Result<CarmenLog, CarmenError> {
        let mut log = CarmenLog::default();
        for (i, line) in reader.lines().enumerate() {
            let line_no = i + 1;
            let line = line.map_err(|source| CarmenError::Io {
                path: String::new(),
                source,
            })?;
            let mut fields = line.split_ascii_whitespace();
            let Some(kind) = fields.next() else { continue };
            let rest: Vec<&str> = fields.collect();
            let err = |what: String| CarmenError::Line {
                line: line_no,
                what,
            };
            match kind {
                "FLASER" => log.scans.push(parse_flaser(&rest).map_err(err)?),
                "ROBOTLASER1" => log.scans.push(parse_robotlaser(&rest).map_err(err)?),
                "ODOM" => log.odometry.push(parse_odom(&rest).map_err(err)?),
                k if k.starts_with('#') => {}
                _ => {} // PARAM, TRUEPOS, RAWLASER...: not used here
            }
        }
        log.scans
            .sort_by(|a, b| a.timestamp_s.total_cmp(&b.timestamp_s));
        log.odometry
            .sort_by(|a, b| a.timestamp_s.total_cmp(&b.timestamp_s));
        Ok(log)
    }

    /// Duration from the first to the last scan, seconds.
    pub fn duration_s(&self) -> f64 {
        match (self.scans.first(), self.scans.last()) {
            (Some(a), Some(b)) => b.timestamp_s - a.timestamp_s,
            _ => 0.0,
        }
    }
}

fn num(fields: &[&str], i: usize, name: &str) -> Result<f64, String> {
    let s = fields
        .get(i)
        .ok_or_else(|| format!("missing {name} (field {})", i + 2))?;
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{name} {s:?} is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("{name} is not finite"))
    }
}

/// The farthest a logged position may lie from the log's origin, metres: a robot's log
/// spans a building or a campus, and a position 1e20 m off (a corrupt digit string still
/// parses) would ask the map for more cells than memory holds.
pub const MAX_POSITION_M: f64 = 1e5;

/// The longest maximum range a laser line may claim, metres (the longest lidars reach a few
/// hundred).
pub const MAX_LASER_RANGE_M: f64 = 1e4;

/// [`num`] for a position or offset, at most [`MAX_POSITION_M`] from zero.
fn position(fields: &[&str], i: usize, name: &str) -> Result<f64, String> {
    let v = num(fields, i, name)?;
    if v.abs() <= MAX_POSITION_M {
        Ok(v)
    } else {
        Err(format!(
            "{name} {v:e} m is implausibly far (at most {MAX_POSITION_M:e} m from the origin)"
        ))
    }
}

fn count(fields: &[&str], i: usize, name: &str) -> Result<usize, String> {
    let s = fields.get(i).ok_or_else(|| format!("missing {name}"))?;
    let n: usize = s
        .parse()
        .map_err(|_| format!("{name} {s:?} is not a count"))?;
    if n > 100_000 {
        return Err(format!("{name} {n} is implausibly large"));
    }
    Ok(n)
}

fn ranges(fields: &[&str], start: usize, n: usize) -> Result<Vec<f32>, String> {
    (start..start + n)
        .map(|i| {
            let r = num(fields, i, "range")?;
            if r < 0.0 {
                Err(format!("range {r} is negative"))
            } else {
                Ok(r as f32)
            }
        })
        .collect()
}

/// `FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp`
fn parse_flaser(f: &[&str]) -> Result<LaserReading, String> {
    let n = count(f, 0, "number of readings")?;
    if n < 2 {
        return Err(format!("{n} readings: a scan needs at least 2"));
    }
    let ranges_m = ranges(f, 1, n)?;
    let o = 1 + n;
    let odom = Pose2::new(
        position(f, o + 3, "odom_x")?,
        position(f, o + 4, "odom_y")?,
        num(f, o + 5, "odom_theta")?,
    );
    let timestamp_s = num(f, o + 6, "ipc_timestamp")?;
    // 180 degrees, right to left; 181 and 361 beams include both ends.
    let fov = std::f64::consts::PI;
    let increment = if n % 2 == 1 {
        fov / (n - 1) as f64
    } else {
        fov / n as f64
    };
    Ok(LaserReading {
        timestamp_s,
        angle_min_rad: -fov / 2.0,
        angle_increment_rad: increment,
        max_range_m: FLASER_MAX_RANGE_M,
        ranges_m,
        odom,
        robot_from_laser: Pose2::IDENTITY,
    })
}

/// `ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode n r1..rn
/// m rem1..remm laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
/// forward_safety side_safety turn_axis ipc_timestamp host logger_timestamp`
fn parse_robotlaser(f: &[&str]) -> Result<LaserReading, String> {
    let start = num(f, 1, "start_angle")?;
    let res = num(f, 3, "angular_resolution")?;
    let max_range = num(f, 4, "maximum_range")?;
    if !(max_range > 0.0 && max_range <= MAX_LASER_RANGE_M) {
        return Err(format!(
            "maximum_range {max_range:e} m is implausible (above 0, at most {MAX_LASER_RANGE_M:e} m)"
        ));
    }
    let n = count(f, 7, "number of readings")?;
    let ranges_m = ranges(f, 8, n)?;
    let m = count(f, 8 + n, "number of remissions")?;
    let o = 9 + n + m;
    let laser = Pose2::new(
        position(f, o, "laser_x")?,
        position(f, o + 1, "laser_y")?,
        num(f, o + 2, "laser_theta")?,
    );
    let robot = Pose2::new(
        position(f, o + 3, "robot_x")?,
        position(f, o + 4, "robot_y")?,
        num(f, o + 5, "robot_theta")?,
    );
    let timestamp_s = num(f, o + 11, "ipc_timestamp")?;
    Ok(LaserReading {
        timestamp_s,
        angle_min_rad: start,
        angle_increment_rad: res,
        max_range_m: max_range,
        ranges_m,
        odom: robot,
        robot_from_laser: robot.inverse() * laser,
    })
}

/// `ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp`
fn parse_odom(f: &[&str]) -> Result<OdomReading, String> {
    Ok(OdomReading {
        pose: Pose2::new(
            position(f, 0, "x")?,
            position(f, 1, "y")?,
            num(f, 2, "theta")?,
        ),
        timestamp_s: num(f, 6, "ipc_timestamp")?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_flaser_odom_and_robotlaser_out_of_order() {
        let text = "\\
# comment
PARAM robot_width 0.5
FLASER 4 1.0 2.0 3.0 4.0 0 0 0 1.5 2.5 0.1 100.5 host 100.5
ODOM 1.0 2.0 0.3 0.1 0.0 0 99.0 host 99.0
FLASER 3 1.0 2.0 3.0 0 0 0 1.0 2.0 0.0 100.0 host 100.0
ROBOTLASER1 0 -1.5 3.0 1.0 30.0 0.01 0 4 1 2 3 4 0 1.08775825619 2.04794255386 0.5 1 2 0.5 0 0 0 0 0 101.0 host 101.0
";
        let log = CarmenLog::read(text.as_bytes()).expect("valid");
        let t: Vec<f64> = log.scans.iter().map(|s| s.timestamp_s).collect();
        assert_eq!(t, vec![100.0, 100.5, 101.0]);
        assert_eq!(log.scans[0].ranges_m, vec![1.0, 2.0, 3.0]);
        // 3 beams over 180 degrees including both ends: 90 degrees apart.
        assert!((log.scans[0].angle_increment_rad - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((log.scans[1].angle_increment_rad - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(log.scans[1].odom, Pose2::new(1.5, 2.5, 0.1));
        let rl = &log.scans[2];
        assert_eq!(
            (rl.angle_min_rad, rl.angle_increment_rad, rl.max_range_m),
            (-1.5, 1.0, 30.0)
        );
        assert_eq!(rl.odom, Pose2::new(1.0, 2.0, 0.5));
        let mount = rl.robot_from_laser;
        assert!(
            (mount.x_m - 0.1).abs() < 1e-9 && mount.y_m.abs() < 1e-9 && mount.yaw_rad.abs() < 1e-12
        );
        assert_eq!(log.odometry.len(), 1);
        assert_eq!(log.odometry[0].pose, Pose2::new(1.0, 2.0, 0.3));
    }

    #[test]
    fn stale_odometry_is_interpolated_at_the_scans_time_and_fresh_odometry_kept() {
        // A robot turning at 1 rad/s, its odometry read every 0.1 s; each laser message
        // carries the reading from 0.1 s before the scan.
        let mut text = String::new();
        for k in 0..20 {
            let t = k as f64 * 0.1;
            text += &format!("ODOM 0 0 {t:.1} 0 0 0 {t:.1} h 0\n");
        }
        for k in 1..10 {
            let t = k as f64 * 0.2 + 0.05;
            let carried = t - 0.15;
            text += &format!("FLASER 2 1 1 0 0 {carried:.1} 0 0 {carried:.1} {t} h 0\n");
        }
        let mut log = CarmenLog::read(text.as_bytes()).expect("valid");
        let stale = log.odometry_staleness_s().expect("poses from ODOM");
        assert!((stale - 0.15).abs() < 1e-9, "{stale}");
        assert_eq!(log.retime_stale_odometry(), (Some(stale), 9));
        for scan in &log.scans {
            // Interpolated halfway between two readings: the heading at the scan's time.
            assert!(
                (scan.odom.yaw_rad - scan.timestamp_s).abs() < 1e-9,
                "{} at {}",
                scan.odom.yaw_rad,
                scan.timestamp_s
            );
        }

        // The same robot whose laser messages carry the reading taken with the scan.
        let mut fresh = String::new();
        for k in 0..20 {
            let t = k as f64 * 0.1;
            fresh += &format!("ODOM 0 0 {t:.1} 0 0 0 {t:.1} h 0\n");
            if k % 2 == 1 {
                fresh += &format!("FLASER 2 1 1 0 0 {t:.1} 0 0 {t:.1} {:.4} h 0\n", t + 0.0003);
            }
        }
        let mut log = CarmenLog::read(fresh.as_bytes()).expect("valid");
        let before = log.scans.clone();
        let (staleness, retimed) = log.retime_stale_odometry();
        assert!(staleness.is_some_and(|s| s.abs() < 1e-3), "{staleness:?}");
        assert_eq!((retimed, &log.scans), (0, &before));
    }

    #[test]
    fn corrupt_lines_name_their_line_number() {
        for (text, line, needle) in [
            (
                "ODOM 1 2 3 0 0 0 5 h 5\nFLASER 3 1.0 x 3.0 0 0 0 0 0 0 1 h 1\n",
                2,
                "range",
            ),
            ("FLASER 300 1.0 2.0\n", 1, "missing range"),
            ("\n\nODOM 1 2\n", 3, "missing"),
            ("FLASER 99999999999 1\n", 1, "implausibly large"),
            ("FLASER 2 1 -2 0 0 0 0 0 0 1 h 1\n", 1, "negative"),
            ("ODOM 1 2 nan 0 0 0 1 h 1\n", 1, "not finite"),
            // A corrupt digit string that still parses: 1e20 m would overflow the map.
            (
                "ODOM 0 0 0 0 0 0 1 h 1\nODOM 99999999999999999999 0 0 0 0 0 2 h 2\n",
                2,
                "implausibly far",
            ),
            ("FLASER 2 1 1 0 0 0 0 -1e20 0 1 h 1\n", 1, "odom_y"),
            (
                "ROBOTLASER1 0 -1.5 3.0 1.0 1e30 0.01 0 2 1 2 0 0 0 0 0 0 0 0 0 0 0 0 1.0 h 1.0\n",
                1,
                "maximum_range",
            ),
        ] {
            match CarmenLog::read(text.as_bytes()) {
                Err(CarmenError::Line { line: l, what }) => {
                    assert_eq!(l, line, "{text:?}: {what}");
                    assert!(what.contains(needle), "{text:?}: {what}");
                }
                other => panic!("{text:?} gave {other:?}"),
            }
        }
    }

    proptest::proptest! {
        #[test]
        fn arbitrary_text_never_panics(text in "(FLASER|ODOM|ROBOTLASER1)?[ 0-9a-z.\\\\-]{0,200}(\\n[A-Z]{0,6}[ 0-9.\\\\-]{0,80}){0,5}") {
            let _ = CarmenLog::read(text.as_bytes());
        }
    }
}
