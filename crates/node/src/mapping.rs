//! A rover's SLAM on board: feeds its lidar scans, and wheel odometry with the gyro's heading,
//! to the
//! [`Mapper`](realms_slam::mapper::Mapper), and publishes what the rest of the mission needs
//! to know: the pose with its covariance after every scan, every change of localisation state
//! with its reason, and the map now and then.
//!
//! The map frame is the odometry frame at the first scan, so a rover that starts where its
//! odometry says (as in the simulator, where odometry starts at the true pose) maps in the
//! arena's frame until it drifts.

use crate::Outgoing;
use realms_core::geometry::{Quaternion, Vec3, normalize_angle_rad};
use realms_core::msgs::{
    Header, Imu, LaserScan, LocalisationStatus, MapMetaData, Message, OccupancyGrid, Odometry,
    Pose3, PoseWithCovariance, PoseWithCovarianceStamped,
};
use realms_core::{Duration, Point2, Pose2, RoverId, Time};
use realms_slam::health::LocalisationState;
use realms_slam::mapper::{Mapper, MapperConfig};
use realms_slam::occupancy::CellState;

/// Setup of the on-board SLAM.
#[derive(Clone, Debug, PartialEq)]
pub struct MappingConfig {
    /// The lidar's position forward of the base, metres (it looks straight ahead).
    pub lidar_x_m: f64,
    /// SLAM tuning.
    pub mapper: MapperConfig,
    /// How often the map is published.
    pub map_period: Duration,
}

/// SLAM tuned for the simulated rover: the lidar reaches 12 m, the arena is small, and the
/// rover is slow, so keyframes are sparser than on the office logs.
pub fn rover_mapper_config() -> MapperConfig {
    let mut cfg = MapperConfig::default();
    cfg.frontend.max_range_m = 12.0;
    cfg.keyframe_translation_m = 0.3;
    cfg.keyframe_rotation_rad = 10f64.to_radians();
    cfg
}

/// The on-board SLAM of one rover.
#[derive(Debug)]
pub struct Mapping {
    id: RoverId,
    cfg: MappingConfig,
    mapper: Mapper,
    /// The two latest odometry poses (wheel translation, gyro heading), oldest first, to
    /// interpolate at a scan's stamp.
    odometry: Vec<(Time, Pose2)>,
    last_wheel: Option<Pose2>,
    gyro_yaw_rad: f64,
    last_gyro: Option<Time>,
    gyro_heard: bool,
    next_map: Time,
}

impl Mapping {
    /// SLAM for rover `id`.
    pub fn new(id: RoverId, cfg: MappingConfig) -> Self {
        Mapping {
            id,
            mapper: Mapper::new(cfg.mapper),
            cfg,
            odometry: Vec::new(),
            last_wheel: None,
            gyro_yaw_rad: 0.0,
            last_gyro: None,
            gyro_heard: false,
            next_map: Time::ZERO,
        }
    }

    /// The localisation state now.
    pub fn state(&self) -> LocalisationState {
        self.mapper.state()
    }

    /// The pose estimate now, in the map frame.
    pub fn pose(&self) -> Pose2 {
        self.mapper.pose()
    }

    /// Takes a wheel odometry reading. Its translation is kept; its heading is replaced by
    /// the gyro's once the gyro has been heard (skid steering makes wheel headings poor: a few
    /// per cent of every turn, and more when the wheels slip).
    pub fn on_odometry(&mut self, odom: &Odometry) {
        let p = &odom.pose.pose;
        let wheel = Pose2::new(p.position.x, p.position.y, p.orientation.yaw_rad());
        let fused = match (self.last_wheel, self.odometry.last()) {
            (Some(prev), Some((_, fused_prev))) if self.gyro_heard => {
                // The wheel motion in the wheel frame, replayed along the gyro's heading.
                let step = prev.inverse() * wheel;
                let turned = normalize_angle_rad(self.gyro_yaw_rad - fused_prev.yaw_rad);
                let mid_yaw = fused_prev.yaw_rad + turned / 2.0;
                let (s, c) = mid_yaw.sin_cos();
                let forward = step.x_m;
                Pose2::new(
                    fused_prev.x_m + c * forward,
                    fused_prev.y_m + s * forward,
                    self.gyro_yaw_rad,
                )
            }
            _ => {
                self.gyro_yaw_rad = wheel.yaw_rad;
                wheel
            }
        };
        self.last_wheel = Some(wheel);
        if self.odometry.len() == 2 {
            self.odometry.remove(0);
        }
        self.odometry.push((odom.header.stamp, fused));
    }

    /// Takes a gyro reading: integrates its yaw rate since the previous one.
    pub fn on_imu(&mut self, imu: &Imu) {
        let t = imu.header.stamp;
        if let Some(prev) = self.last_gyro
            && t > prev
        {
            self.gyro_yaw_rad += imu.angular_velocity.z * (t - prev).as_secs_f64();
        }
        self.last_gyro = Some(t);
        self.gyro_heard = true;
    }

    /// Odometry at `t`, interpolated (or extrapolated a little) from the latest two readings.
    fn odometry_at(&self, t: Time) -> Option<Pose2> {
        match self.odometry.as_slice() {
            [] => None,
            [(_, p)] => Some(*p),
            [(t0, p0), (t1, p1)] => {
                let span = (*t1 - *t0).as_secs_f64();
                if span <= 0.0 {
                    return Some(*p1);
                }
                // Never more than one reading's span beyond the newest.
                let s = ((t - *t0).as_secs_f64() / span).clamp(0.0, 2.0);
                Some(p0.interpolate(p1, s))
            }
            _ => unreachable!("at most two readings are kept"),
        }
    }

    fn header(&self, stamp: Time) -> Header {
        Header {
            stamp,
            frame_id: format!("{}/map", self.id.namespace()),
        }
    }

    /// Takes a lidar scan; pushes the pose (and any change of state, and the map when due)
    /// to `out`.
    pub fn on_scan(&mut self, scan: &LaserScan, out: &mut Vec<Outgoing>) {
        let stamp = scan.header.stamp;
        let Some(odom) = self.odometry_at(stamp) else {
            // No odometry yet: nothing to anchor the map frame to.
            return;
        };
        let max = (self.cfg.mapper.frontend.max_range_m as f32).min(scan.range_max_m);
        let min = (self.cfg.mapper.frontend.min_range_m as f32).max(scan.range_min_m);
        let points: Vec<Point2> = scan
            .ranges_m
            .iter()
            .enumerate()
            .filter(|(_, r)| r.is_finite() && **r >= min && **r < max)
            .map(|(i, r)| {
                let a = (scan.angle_min_rad + i as f32 * scan.angle_increment_rad) as f64;
                let r = *r as f64;
                Point2::new(self.cfg.lidar_x_m + r * a.cos(), r * a.sin())
            })
            .collect();
        let tracked = self.mapper.add_points(stamp.as_secs_f64(), odom, points);
        for (_, change) in self.mapper.take_transitions() {
            out.push(Outgoing {
                topic: self.id.topic("localisation"),
                message: Message::Localisation(LocalisationStatus {
                    header: self.header(stamp),
                    state: change.state,
                    reason: change.reason,
                }),
            });
        }
        out.push(Outgoing {
            topic: self.id.topic("pose"),
            message: Message::Pose(Box::new(PoseWithCovarianceStamped {
                header: self.header(stamp),
                pose: PoseWithCovariance {
                    pose: Pose3 {
                        position: Vec3::new(tracked.pose.x_m, tracked.pose.y_m, 0.0),
                        orientation: Quaternion::from_roll_pitch_yaw(
                            0.0,
                            0.0,
                            tracked.pose.yaw_rad,
                        ),
                    },
                    covariance: self.covariance(tracked.state),
                },
            })),
        });
        if stamp >= self.next_map {
            self.publish_map(stamp, out);
        }
    }

    /// Publishes the map now (and restarts the period).
    pub fn publish_map(&mut self, now: Time, out: &mut Vec<Outgoing>) {
        self.next_map = now + self.cfg.map_period;
        out.push(Outgoing {
            topic: self.id.topic("map"),
            message: Message::Map(self.map(now)),
        });
    }

    /// The pose covariance: from the last match's information when tracking (scaled to a
    /// floor of a centimetre and a fraction of a degree), and huge when lost.
    fn covariance(&self, state: LocalisationState) -> [[f64; 6]; 6] {
        let mut c = [[0.0; 6]; 6];
        // z, roll and pitch are not estimated.
        for i in [2, 3, 4] {
            c[i][i] = 1e6;
        }
        let (var_xy, var_yaw) = match state {
            LocalisationState::Lost => (1e4, 10.0),
            _ => {
                let h = self.mapper.last_information();
                let per_axis = |v: f64| if v > 1e-9 { 1.0 / v } else { 1e4 };
                (
                    per_axis(h[0][0].min(h[1][1])).max(1e-4),
                    per_axis(h[2][2]).max(3e-5),
                )
            }
        };
        c[0][0] = var_xy;
        c[1][1] = var_xy;
        c[5][5] = var_yaw;
        c
    }

    /// The map now, as a ROS occupancy grid.
    pub fn map(&self, stamp: Time) -> OccupancyGrid {
        let states = self.mapper.render_map().states();
        let g = states.geometry();
        OccupancyGrid {
            header: self.header(stamp),
            info: MapMetaData {
                resolution_m: g.resolution_m as f32,
                width: g.width as u32,
                height: g.height as u32,
                origin: Pose3 {
                    position: Vec3::new(g.origin.x_m, g.origin.y_m, 0.0),
                    orientation: Quaternion::IDENTITY,
                },
            },
            data: states
                .cells()
                .iter()
                .map(|c| match c {
                    CellState::Unknown => OccupancyGrid::UNKNOWN,
                    CellState::Free => OccupancyGrid::FREE,
                    CellState::Occupied => OccupancyGrid::OCCUPIED,
                })
                .collect(),
        }
    }
}
