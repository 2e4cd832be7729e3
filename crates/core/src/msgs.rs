//! Message types for the hardware-facing topics, shaped field for field like their ROS 2
//! counterparts (sensor_msgs, nav_msgs, geometry_msgs) so a bridge to real drivers is a
//! mechanical mapping. Units are ROS's (metres, radians, seconds); names add the unit where
//! ROS leaves it implicit. Stamps are mission [`Time`].

use crate::geometry::{Point2, Quaternion, Vec3};
use crate::time::{Duration, Time};
use serde::{Deserialize, Serialize};

/// std_msgs/Header: when the data was taken and in which frame it is expressed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time on the mission clock.
    pub stamp: Time,
    /// Frame of the data, e.g. `rover1/laser`.
    pub frame_id: String,
}

/// sensor_msgs/LaserScan. Beams without a return are `+inf` (REP 117).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    /// Stamp of the first beam.
    pub header: Header,
    /// Angle of the first beam, counter-clockwise from the sensor's x axis.
    pub angle_min_rad: f32,
    /// Angle of the last beam.
    pub angle_max_rad: f32,
    /// Angle between beams.
    pub angle_increment_rad: f32,
    /// Time between beams.
    pub time_increment_s: f32,
    /// Time between scans.
    pub scan_time_s: f32,
    /// Shortest range the sensor reports.
    pub range_min_m: f32,
    /// Longest range the sensor reports.
    pub range_max_m: f32,
    /// One range per beam.
    pub ranges_m: Vec<f32>,
    /// One intensity per beam, or empty.
    pub intensities: Vec<f32>,
}

impl LaserScan {
    /// How long the sweep from the first beam to the last took: `time_increment_s` times
    /// the beams after the first, or zero (an instantaneous scan) where that is no plausible
    /// sweep: negative, not finite, or over a second, which no spinning lidar of the field
    /// takes. A scan from a driver or the network decides nothing here by itself.
    pub fn sweep(&self) -> Duration {
        sweep_duration(self.ranges_m.len(), self.time_increment_s)
    }

    /// When the last beam was measured: the instant a scan's beams are all brought to once
    /// the motion during the sweep is taken out of them.
    pub fn last_beam_time(&self) -> Time {
        self.header.stamp + self.sweep()
    }

    /// When beam `i` was measured, counted from the stamp (the first beam's time).
    pub fn beam_offset(&self, i: usize) -> Duration {
        if self.sweep() == Duration::ZERO {
            return Duration::ZERO;
        }
        beam_offset(i, self.time_increment_s)
    }
}

/// When beam `i` of a sweep `time_increment_s` apart is measured, counted from its first: the
/// one rule a lidar and a receiver both time a beam by, to the nanosecond.
pub fn beam_offset(i: usize, time_increment_s: f32) -> Duration {
    Duration::from_secs_f64(i as f64 * time_increment_s as f64)
}

/// [`LaserScan::sweep`] for a scan of `beams` beams `time_increment_s` apart.
pub fn sweep_duration(beams: usize, time_increment_s: f32) -> Duration {
    let s = beams.saturating_sub(1) as f64 * time_increment_s as f64;
    if s.is_finite() && s > 0.0 && s <= 1.0 {
        Duration::from_secs_f64(s)
    } else {
        Duration::ZERO
    }
}

/// geometry_msgs/Pose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose3 {
    /// Position in metres.
    pub position: Vec3,
    /// Orientation.
    pub orientation: Quaternion,
}

/// geometry_msgs/Twist: linear velocity in m/s, angular in rad/s.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: Vec3,
    /// Angular velocity, rad/s.
    pub angular: Vec3,
}

/// A 6x6 covariance over (x, y, z, roll, pitch, yaw), row-major as in ROS.
pub type Covariance6 = [[f64; 6]; 6];
/// A 3x3 covariance, row-major.
pub type Covariance3 = [[f64; 3]; 3];

/// geometry_msgs/PoseWithCovariance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose3,
    /// Its uncertainty.
    pub covariance: Covariance6,
}

/// geometry_msgs/TwistWithCovariance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Its uncertainty.
    pub covariance: Covariance6,
}

/// nav_msgs/Odometry: the pose in `header.frame_id` (`odom`), the twist in `child_frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and the odometry frame.
    pub header: Header,
    /// The body frame, e.g. `rover1/base_link`.
    pub child_frame_id: String,
    /// Integrated pose in the odometry frame.
    pub pose: PoseWithCovariance,
    /// Velocity in the body frame.
    pub twist: TwistWithCovariance,
}

/// sensor_msgs/Imu. A covariance whose first element is -1 marks the field as not provided.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    /// Stamp and the IMU frame.
    pub header: Header,
    /// Orientation estimate, if provided.
    pub orientation: Quaternion,
    /// Its covariance (-1 in `[0][0]`: not provided).
    pub orientation_covariance: Covariance3,
    /// Angular velocity in rad/s (yaw rate in `z`).
    pub angular_velocity: Vec3,
    /// Its covariance.
    pub angular_velocity_covariance: Covariance3,
    /// Linear acceleration in m/s^2.
    pub linear_acceleration: Vec3,
    /// Its covariance (-1 in `[0][0]`: not provided).
    pub linear_acceleration_covariance: Covariance3,
}

/// geometry_msgs/TwistStamped, the form `cmd_vel` takes here so a receiver can drop a stale
/// command instead of executing it late.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    /// When the command was issued, and its frame (the rover's base, e.g. `rover1/base_link`).
    pub header: Header,
    /// The commanded velocity.
    pub twist: Twist,
}

/// An organised point cloud from a depth camera (sensor_msgs/PointCloud2 with `x, y, z`
/// float32 fields): `width x height` points row by row, in the camera's optical frame
/// (z forward, x right, y down); pixels without a return are NaN.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud {
    /// Stamp and the optical frame.
    pub header: Header,
    /// Points per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width * height` points, `[x, y, z]` in metres.
    pub points_in_sensor: Vec<[f32; 3]>,
}

/// sensor_msgs/Image; here always `mono8` (one byte per pixel, rows top-down).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Stamp and the camera's optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding, e.g. `mono8`.
    pub encoding: String,
    /// Bytes per row.
    pub step: u32,
    /// Pixel bytes.
    pub data: Vec<u8>,
}

/// geometry_msgs/PoseWithCovarianceStamped: a rover's SLAM pose in its map frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    /// Stamp (of the scan the pose is for) and the map frame, e.g. `rover1/map`.
    pub header: Header,
    /// The pose and its uncertainty.
    pub pose: PoseWithCovariance,
}

/// What a rover can say about its own localisation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum LocalisationState {
    /// Scan matching and odometry agree.
    #[default]
    Tracking,
    /// Scan matching tracks, but wheel odometry disagrees with it, or the wheels' turns with the
    /// gyro's (slip, a failed encoder).
    OdometryUnreliable,
    /// The scans no longer fit the map: the pose is unknown and the map is frozen until the
    /// rover relocalises.
    Lost,
}

/// A change of a rover's localisation state, and why (`localisation`; no ROS counterpart,
/// sent only on change).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LocalisationStatus {
    /// When the change was noticed (the scan's stamp), and the map frame.
    pub header: Header,
    /// The new state.
    pub state: LocalisationState,
    /// Why, in words for the operator.
    pub reason: String,
}

/// What a rover's navigation is doing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum NavActivity {
    /// No goal (waiting for a map, or standing still while lost).
    #[default]
    Idle,
    /// Driving to a frontier it chose.
    Exploring,
    /// Driving to the operator's goal.
    OperatorGoal,
    /// Exploration is over; driving home.
    ReturningHome,
    /// Backing off after getting stuck.
    Recovering,
    /// Exploration is over and the rover is home.
    Done,
    /// Lost, and no view it turned through or drove back to matched its map: stopped,
    /// waiting for the operator (its map is kept as it was when it got lost). An operator's
    /// goal is then driven on its wheels and gyro (`OperatorGoal` while it drives).
    Lost,
    /// Its pose grew too uncertain: driving back to ground it mapped while it knew where it
    /// was, to tie the pose back to it by a loop closure, before exploring on.
    Revisiting,
    /// Lost: turning on the spot to find itself (no target), then, if no view it turned
    /// through matched its map, driving on its wheels and gyro back to a place where its
    /// lidar saw enough to find itself again (the target).
    Relocalising,
}

/// A rover's navigation state and target (`nav/status`; no ROS counterpart). Sent when
/// either changes and every few seconds; peers read the target to split the exploration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NavStatus {
    /// When, and the rover's map frame the target is in.
    pub header: Header,
    /// What it is doing.
    pub activity: NavActivity,
    /// Where it is heading, if anywhere.
    pub target: Option<Point2>,
    /// The latest thing that happened, in words for the operator (a goal set, reached or
    /// given up and why).
    pub reason: String,
}

/// Which ground a rover's map knows, coarsely (`nav/explored`; no ROS counterpart): one bit
/// per cell, set where most of the cell is known (and, where the lidar saw it free, judged
/// by the depth camera). Peers use it so they do not drive to frontiers another rover has
/// already seen past. Sent every few seconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ExploredArea {
    /// When, and the rover's map frame.
    pub header: Header,
    /// Lower-left corner of cell (0, 0).
    pub origin: Point2,
    /// Cell edge, metres.
    pub resolution_m: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Row-major from the origin's row, bit `i % 8` of byte `i / 8` for cell `i`.
    pub known: Vec<u8>,
}

impl ExploredArea {
    /// Whether the cell holding `p` is known; false outside the area or past the end of a
    /// short bit array (the message came from outside and may be malformed).
    pub fn is_known(&self, p: Point2) -> bool {
        self.geometry()
            .and_then(|g| g.world_to_cell(p).map(|c| g.index(c)))
            .is_some_and(|i| self.is_known_at(i))
    }

    /// The area's cells as a grid geometry; `None` if its resolution is not a positive
    /// number (the message came from outside).
    pub fn geometry(&self) -> Option<crate::GridGeometry> {
        let r = self.resolution_m as f64;
        (r > 0.0).then_some(crate::GridGeometry {
            width: self.width as usize,
            height: self.height as usize,
            resolution_m: r,
            origin: self.origin,
        })
    }

    /// Whether the cell with row-major index `i` is known; false past the end of a short
    /// bit array.
    pub fn is_known_at(&self, i: usize) -> bool {
        self.known
            .get(i / 8)
            .is_some_and(|byte| byte & (1 << (i % 8)) != 0)
    }
}

/// An operator's goal for a rover (`nav/goal`, like Nav2's goal pose): drive to `target`
/// (in the rover's map frame), or with `None` cancel the goal and resume exploring.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NavGoal {
    /// When it was issued, and the frame.
    pub header: Header,
    /// Where to go; `None` cancels.
    pub target: Option<Point2>,
}

/// nav_msgs/MapMetaData.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    /// Cell edge, metres.
    pub resolution_m: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// The pose of cell (0, 0)'s outer corner in the map frame.
    pub origin: Pose3,
}

/// nav_msgs/OccupancyGrid, row-major from the origin. Cell values follow ROS (-1 unknown,
/// 0 free, 100 occupied) with one addition: [`OccupancyGrid::HAZARD`] marks ground the
/// rover must not drive on that the lidar does not see (crater slopes, low rocks).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Stamp and the map frame.
    pub header: Header,
    /// Geometry.
    pub info: MapMetaData,
    /// One value per cell.
    pub data: Vec<i8>,
}

impl OccupancyGrid {
    /// Never observed.
    pub const UNKNOWN: i8 = -1;
    /// Observed free.
    pub const FREE: i8 = 0;
    /// Not drivable though the lidar sees nothing there.
    pub const HAZARD: i8 = 90;
    /// An obstacle the lidar sees.
    pub const OCCUPIED: i8 = 100;
}

/// Where the lander placed each rover's map in the merged map (`lander/map/transforms`; no
/// ROS counterpart, the role of a tf2 static transform per map with its confidence). The
/// ground holds every rover's map already, so the transforms are all it needs to draw the
/// merged map itself: a few dozen bytes on the ground link instead of a whole grid.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapTransforms {
    /// When the lander merged, and the reference map's frame (the first rover's).
    pub header: Header,
    /// One per other rover's map the lander merged or refused.
    pub maps: Vec<MapTransform>,
}

/// One rover's map in [`MapTransforms`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapTransform {
    /// The rover's map frame (`rover2/map`).
    pub child_frame_id: String,
    /// Pose of that frame in the reference's, `None` where the map was left out.
    pub pose: Option<Point2>,
    /// Its heading, radians.
    pub yaw_rad: f64,
    /// 0..1 (0 for a map placed at its known start unconfirmed).
    pub confidence: f64,
    /// Whether the maps confirmed the pose.
    pub confirmed: bool,
}

/// One map update on the wire.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapUpdate {
    /// Increases by one per update sent.
    pub seq: u64,
    /// The update this one changes; `None`: a snapshot, which needs nothing before it.
    pub base: Option<u64>,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Cell edge, metres.
    pub resolution_m: f64,
    /// Lower-left corner of cell (0, 0).
    pub origin: Point2,
    /// Changed stretches, in row-major order of the new geometry.
    pub runs: Vec<Run>,
}

/// `len` cells of value `value` starting `skip` cells after the end of the previous run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Run {
    /// Unchanged cells before this run.
    pub skip: u32,
    /// Cells in the run.
    pub len: u32,
    /// Their new value.
    pub value: i8,
}

impl MapUpdate {
    /// Whether this update is a snapshot.
    pub fn is_snapshot(&self) -> bool {
        self.base.is_none()
    }
}

/// One node's traffic, as the network statistics report it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NodeTrafficStats {
    /// The node (`rover1`, `lander`, `ground`).
    pub node: String,
    /// Bytes it published, one copy per receiver, headers included.
    pub sent_bytes: u64,
    /// Bytes delivered to it.
    pub received_bytes: u64,
    /// Bytes it relayed for others.
    pub relayed_bytes: u64,
    /// Bytes waiting in its queues now.
    pub queued_bytes: u64,
}

/// The network's traffic so far (`lander/network/stats`), for the operator's network
/// monitor.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NetworkStats {
    /// When.
    pub header: Header,
    /// Per node.
    pub nodes: Vec<NodeTrafficStats>,
    /// Packets dropped, all reasons.
    pub dropped: u64,
    /// Messages that did not decode.
    pub malformed: u64,
    /// Path changes.
    pub route_changes: u64,
}

/// A compact map update from a rover (changed cells since its last update; see
/// `realms_net::mapdelta`), stamped with the time of the map it brings the receiver to.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapDelta {
    /// The time of the rover's map, and its map frame.
    pub header: Header,
    /// The cells.
    pub update: MapUpdate,
}

/// Every message that can travel between nodes. New kinds are appended at the end so older
/// encodings keep decoding.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    /// `scan`: the 2D lidar.
    LaserScan(LaserScan),
    /// `odom`: wheel odometry.
    Odometry(Box<Odometry>),
    /// `imu`: the gyro.
    Imu(Box<Imu>),
    /// `cmd_vel`: a velocity command.
    CmdVel(TwistStamped),
    /// `depth/points`: the depth camera.
    PointCloud(PointCloud),
    /// `camera/image`: the grayscale camera.
    Image(Image),
    /// `pose`: a rover's SLAM pose.
    Pose(Box<PoseWithCovarianceStamped>),
    /// `localisation`: a change of a rover's localisation state.
    Localisation(LocalisationStatus),
    /// `map`: a rover's map.
    Map(OccupancyGrid),
    /// `nav/status`: what a rover's navigation is doing.
    NavStatus(NavStatus),
    /// `nav/goal`: an operator's goal for a rover.
    NavGoal(NavGoal),
    /// `nav/explored`: the ground a rover's map knows, coarsely.
    Explored(ExploredArea),
    /// A compact map update (`roverN/map/delta`).
    MapDelta(Box<MapDelta>),
    /// A request for a full map snapshot (`roverN/map/request`): the receiver missed an
    /// update.
    MapRequest(Header),
    /// The network's traffic so far (`lander/network/stats`).
    NetworkStats(Box<NetworkStats>),
    /// Where the lander placed each rover's map (`lander/map/transforms`).
    MapTransforms(MapTransforms),
}

impl Message {
    /// Acquisition or issue time of the message.
    pub fn stamp(&self) -> Time {
        match self {
            Message::LaserScan(m) => m.header.stamp,
            Message::Odometry(m) => m.header.stamp,
            Message::Imu(m) => m.header.stamp,
            Message::CmdVel(m) => m.header.stamp,
            Message::PointCloud(m) => m.header.stamp,
            Message::Image(m) => m.header.stamp,
            Message::Pose(m) => m.header.stamp,
            Message::Localisation(m) => m.header.stamp,
            Message::Map(m) => m.header.stamp,
            Message::NavStatus(m) => m.header.stamp,
            Message::NavGoal(m) => m.header.stamp,
            Message::Explored(m) => m.header.stamp,
            Message::MapDelta(m) => m.header.stamp,
            Message::MapRequest(h) => h.stamp,
            Message::NetworkStats(m) => m.header.stamp,
            Message::MapTransforms(m) => m.header.stamp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(beams: usize, time_increment_s: f32) -> LaserScan {
        LaserScan {
            header: Header {
                stamp: Time::from_secs_f64(10.0),
                frame_id: "rover1/laser".into(),
            },
            time_increment_s,
            ranges_m: vec![1.0; beams],
            ..LaserScan::default()
        }
    }

    #[test]
    fn a_sweep_runs_from_the_stamp_to_the_last_beam() {
        let s = scan(360, 0.1 / 360.0);
        let sweep = s.sweep().as_secs_f64();
        // time_increment_s is an f32: a few nanoseconds off the exact sweep.
        assert!((sweep - 0.1 * 359.0 / 360.0).abs() < 1e-7, "{sweep}");
        assert_eq!(s.last_beam_time(), s.header.stamp + s.sweep());
        assert_eq!(s.beam_offset(0), Duration::ZERO);
        assert_eq!(s.beam_offset(359), s.sweep());
    }

    #[test]
    fn a_scan_claiming_no_plausible_sweep_is_taken_as_measured_at_once() {
        // From a driver or the network: nothing here may panic or move a beam in time.
        for ti in [0.0, -1e-3, f32::NAN, f32::INFINITY, f32::MAX, 0.01] {
            let s = scan(360, ti);
            assert_eq!(s.sweep(), Duration::ZERO, "time_increment_s {ti}");
            assert_eq!(s.last_beam_time(), s.header.stamp);
            assert_eq!(s.beam_offset(200), Duration::ZERO);
        }
        assert_eq!(scan(0, 1e-3).sweep(), Duration::ZERO, "no beams");
        assert_eq!(scan(1, 1e-3).sweep(), Duration::ZERO, "one beam");
    }
}
