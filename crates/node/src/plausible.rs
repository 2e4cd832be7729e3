//! Whether a sensor message holds numbers its sensor can give.
//!
//! On a real rover the messages come from drivers, and a driver's glitch or a corrupt field
//! that still decodes can carry any number: a wheel pose 1e20 m out, a NaN yaw rate, a scan
//! claiming a reach of 1e20 m or a NaN spacing between beams. Taken in, such a number
//! travels through the pose into the map, whose grids would grow to hold it. The rover
//! drops such a message whole and counts it ([`crate::rover::RoverNode::rejected_inputs`]);
//! a sensor that keeps sending them falls silent to the rover, which its silence rules
//! already handle. Readings a sensor does give for "nothing there" stay: a range of
//! infinity or NaN (no return), a depth point of NaN (no return).

use realms_core::geometry::{Quaternion, Vec3};
use realms_core::msgs::{Imu, LaserScan, Message, Odometry, PointCloud};
use realms_core::{Duration, Time};

/// The farthest a wheel pose may lie from where the wheels started, metres: a rover's
/// odometry over a mission spans kilometres at most.
pub const MAX_ODOMETRY_M: f64 = 1e6;
/// The fastest a rover body turns or accelerates, with a wide margin: rad/s ...
pub const MAX_TURN_RATE_RAD_S: f64 = 1e3;
/// ... and m/s^2.
pub const MAX_ACCELERATION_M_S2: f64 = 1e4;
/// The longest reach a lidar may claim, metres.
pub const MAX_LIDAR_RANGE_M: f32 = 1e4;
/// The farthest a depth point may lie from the camera, metres.
pub const MAX_DEPTH_POINT_M: f32 = 1e4;

/// How far ahead of the rover's own clock a sensor message may be stamped. Its drivers stamp
/// readings as they take them, on the rover's computer, so a reading from the future is a
/// corrupt stamp or a clock set wrong; taken in, it would make every later reading look
/// stale (the gyro's and the wheels' readings are taken in stamp order) ...
pub const MAX_STAMP_AHEAD: Duration = Duration::from_secs(1);
/// ... and how far behind it: the rover acts on readings a few seconds old at most.
pub const MAX_STAMP_AGE: Duration = Duration::from_secs(3600);

/// Why the stamp of `message` cannot be right at `now` on the rover's clock, if it is one of
/// a rover's own sensor messages stamped more than [`MAX_STAMP_AHEAD`] ahead of it or
/// [`MAX_STAMP_AGE`] behind; `None` for any other message.
pub fn implausible_stamp(message: &Message, now: Time) -> Option<&'static str> {
    let sensor = matches!(
        message,
        Message::Odometry(_) | Message::Imu(_) | Message::LaserScan(_) | Message::PointCloud(_)
    );
    let stamp = message.stamp();
    if !sensor {
        None
    } else if stamp > now + MAX_STAMP_AHEAD {
        Some("sensor stamp more than 1 s ahead of the rover's clock")
    } else if stamp < now - MAX_STAMP_AGE {
        Some("sensor stamp more than an hour behind the rover's clock")
    } else {
        None
    }
}

/// What is impossible in `message`, if it is one of a rover's own sensor messages
/// (odometry, IMU, lidar, depth camera) and holds a number its sensor cannot give; `None`
/// for any other message.
pub fn implausible(message: &Message) -> Option<&'static str> {
    match message {
        Message::Odometry(odom) => implausible_odometry(odom),
        Message::Imu(imu) => implausible_imu(imu),
        Message::LaserScan(scan) => implausible_scan(scan),
        Message::PointCloud(cloud) => implausible_cloud(cloud),
        _ => None,
    }
}

fn finite_quaternion(q: &Quaternion) -> bool {
    [q.x, q.y, q.z, q.w].iter().all(|v| v.is_finite())
}

fn within(v: &Vec3, limit: f64) -> bool {
    [v.x, v.y, v.z]
        .iter()
        .all(|c| c.is_finite() && c.abs() <= limit)
}

fn implausible_odometry(odom: &Odometry) -> Option<&'static str> {
    let pose = &odom.pose.pose;
    if !within(&pose.position, MAX_ODOMETRY_M) {
        return Some("odometry position not finite or beyond 1e6 m");
    }
    if !finite_quaternion(&pose.orientation) {
        return Some("odometry orientation not finite");
    }
    None
}

fn implausible_imu(imu: &Imu) -> Option<&'static str> {
    if !within(&imu.angular_velocity, MAX_TURN_RATE_RAD_S) {
        return Some("IMU angular velocity not finite or beyond 1e3 rad/s");
    }
    // The accelerometer may be absent (its covariance -1), its numbers then unread.
    if imu.linear_acceleration_covariance[0][0] >= 0.0
        && !within(&imu.linear_acceleration, MAX_ACCELERATION_M_S2)
    {
        return Some("IMU acceleration not finite or beyond 1e4 m/s^2");
    }
    None
}

fn implausible_scan(scan: &LaserScan) -> Option<&'static str> {
    let angles = [
        scan.angle_min_rad,
        scan.angle_max_rad,
        scan.angle_increment_rad,
    ];
    if !angles
        .iter()
        .all(|a| a.is_finite() && a.abs() <= 4.0 * std::f32::consts::PI)
    {
        return Some("scan angles not finite or beyond two turns");
    }
    if !(scan.range_min_m.is_finite()
        && scan.range_max_m.is_finite()
        && 0.0 <= scan.range_min_m
        && scan.range_min_m < scan.range_max_m
        && scan.range_max_m <= MAX_LIDAR_RANGE_M)
    {
        return Some("scan range limits not 0 <= min < max <= 1e4 m");
    }
    if !(scan.time_increment_s.is_finite() && scan.scan_time_s.is_finite()) {
        return Some("scan times not finite");
    }
    None
}

fn implausible_cloud(cloud: &PointCloud) -> Option<&'static str> {
    let far = cloud
        .points_in_sensor
        .iter()
        .flatten()
        .any(|c| c.is_infinite() || c.abs() > MAX_DEPTH_POINT_M);
    far.then_some("depth point infinite or beyond 1e4 m")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_sensors_give_passes_and_what_they_cannot_is_named() {
        let mut odom = Odometry::default();
        odom.pose.pose.orientation = Quaternion::IDENTITY;
        odom.pose.pose.position.x = 250.0;
        assert_eq!(
            implausible(&Message::Odometry(Box::new(odom.clone()))),
            None
        );
        odom.pose.pose.position.x = 1e20;
        assert!(implausible(&Message::Odometry(Box::new(odom.clone()))).is_some());
        odom.pose.pose.position.x = 0.0;
        odom.pose.pose.orientation.z = f64::NAN;
        assert!(implausible(&Message::Odometry(Box::new(odom))).is_some());

        let mut imu = Imu::default();
        imu.angular_velocity.z = 0.5;
        imu.linear_acceleration.z = 9.81;
        assert_eq!(implausible(&Message::Imu(Box::new(imu.clone()))), None);
        imu.linear_acceleration.x = f64::INFINITY;
        assert!(implausible(&Message::Imu(Box::new(imu.clone()))).is_some());
        // Without an accelerometer its numbers are not read.
        imu.linear_acceleration_covariance[0][0] = -1.0;
        assert_eq!(implausible(&Message::Imu(Box::new(imu.clone()))), None);
        imu.angular_velocity.z = f64::NAN;
        assert!(implausible(&Message::Imu(Box::new(imu))).is_some());

        let mut scan = crate::test_scan(realms_core::Time::ZERO, vec![1.0, f32::INFINITY]);
        scan.ranges_m.push(f32::NAN);
        assert_eq!(implausible(&Message::LaserScan(scan.clone())), None);
        for wreck in [
            |s: &mut LaserScan| s.range_max_m = 1e20,
            |s: &mut LaserScan| s.range_max_m = f32::NAN,
            |s: &mut LaserScan| s.range_min_m = -1.0,
            |s: &mut LaserScan| s.angle_increment_rad = f32::NAN,
            |s: &mut LaserScan| s.angle_min_rad = 1e20,
            |s: &mut LaserScan| s.time_increment_s = f32::INFINITY,
        ] {
            let mut s = scan.clone();
            wreck(&mut s);
            assert!(implausible(&Message::LaserScan(s)).is_some());
        }

        let mut cloud = PointCloud {
            width: 2,
            height: 1,
            points_in_sensor: vec![[0.1, 0.2, 3.0], [f32::NAN; 3]],
            ..PointCloud::default()
        };
        assert_eq!(implausible(&Message::PointCloud(cloud.clone())), None);
        cloud.points_in_sensor[1] = [0.0, 0.0, 1e20];
        assert!(implausible(&Message::PointCloud(cloud)).is_some());
    }

    #[test]
    fn stamps_ahead_of_the_clock_or_an_hour_behind_it_are_named() {
        let now = Time::ZERO + Duration::from_secs(100);
        let imu_at = |stamp: Time| {
            let mut imu = Imu::default();
            imu.header.stamp = stamp;
            Message::Imu(Box::new(imu))
        };
        for fine in [now, Time::ZERO, now + MAX_STAMP_AHEAD, now - MAX_STAMP_AGE] {
            assert_eq!(implausible_stamp(&imu_at(fine), now), None, "{fine}");
        }
        for off in [
            now + MAX_STAMP_AHEAD + Duration(1),
            now + Duration::from_secs(60),
            now - MAX_STAMP_AGE - Duration(1),
            Time(i64::MIN),
            Time(i64::MAX),
        ] {
            assert!(implausible_stamp(&imu_at(off), now).is_some(), "{off}");
        }
        // Only a rover's own sensor messages carry stamps it checks.
        let goal = Message::NavGoal(realms_core::msgs::NavGoal {
            header: realms_core::msgs::Header {
                stamp: Time(i64::MAX),
                frame_id: "map".into(),
            },
            target: None,
        });
        assert_eq!(implausible_stamp(&goal, now), None);
    }
}
