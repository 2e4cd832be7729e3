//! The scenario: everything that defines a mission, read from strict TOML.
//!
//! Every section has defaults (the ESA-ESRIC analogue of DESIGN.md), so a file only states what
//! it changes. Unknown keys are errors, and so are values out of range; errors name the file,
//! the key and what was expected.

use serde::{Deserialize, Serialize};
use std::path::Path;

/// A whole mission definition.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    /// Seed of every random choice in the mission.
    pub seed: u64,
    /// Mission length in simulated seconds.
    pub duration_s: f64,
    /// The hall.
    pub arena: Arena,
    /// The lander.
    pub lander: Lander,
    /// Negative obstacles.
    pub craters: Craters,
    /// Rocks.
    pub boulders: Boulders,
    /// Resource targets.
    pub targets: Targets,
    /// The sun (lights the camera images).
    pub sun: Sun,
    /// The fleet and its hardware.
    pub rovers: Rovers,
    /// Scheduled faults.
    pub faults: Vec<Fault>,
    /// The mesh radio and the ground link (`realms-net`).
    pub network: realms_net::NetworkConfig,
}

/// The hall: a flat-ish floor inside walls.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Arena {
    /// Extent along x, metres.
    pub width_m: f64,
    /// Extent along y, metres.
    pub length_m: f64,
    /// Heightfield cell edge, metres.
    pub resolution_m: f64,
    /// Wall height above the floor, metres.
    pub wall_height_m: f64,
    /// Wall thickness, metres.
    pub wall_thickness_m: f64,
    /// Peak amplitude of the floor's undulation, metres.
    pub undulation_m: f64,
    /// Shortest wavelength of the undulation, metres.
    pub undulation_wavelength_m: f64,
}

/// The lander: a box the rovers start beside.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Lander {
    /// Centre x, metres.
    pub x_m: f64,
    /// Centre y, metres.
    pub y_m: f64,
    /// Footprint edge, metres.
    pub size_m: f64,
    /// Height, metres.
    pub height_m: f64,
}

/// Most craters a scenario may ask for (small and large together).
pub const MOST_CRATERS: u64 = 1_000;
/// Most small boulders a scenario may ask for (about 55 a square metre of the default hall).
pub const MOST_SMALL_BOULDERS: u64 = 100_000;
/// Most large boulders a scenario may ask for.
pub const MOST_LARGE_BOULDERS: u64 = 10_000;
/// Most resource targets a scenario may ask for.
pub const MOST_TARGETS: u64 = 1_000;
/// The largest size of anything in a scenario (a wall, the lander, a crater, a rock), metres:
/// far beyond any hall, and small enough for the terrain's cell arithmetic.
pub const MOST_LENGTH_M: f64 = 1_000.0;

/// Craters: bowls with raised rims, placed by the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Craters {
    /// Number of small craters.
    pub small_count: u32,
    /// Rim-to-rim diameter of a small crater, metres.
    pub small_diameter_m: f64,
    /// Depth of a small crater below the floor, metres.
    pub small_depth_m: f64,
    /// Number of large craters.
    pub large_count: u32,
    /// Rim-to-rim diameter of a large crater, metres.
    pub large_diameter_m: f64,
    /// Depth of a large crater below the floor, metres.
    pub large_depth_m: f64,
    /// Rim height above the floor as a fraction of the depth.
    pub rim_fraction: f64,
}

/// Boulders: many small ones from a power-law size distribution, and a few large ones.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Boulders {
    /// Number of small boulders.
    pub small_count: u32,
    /// Smallest diameter drawn, metres.
    pub small_min_diameter_m: f64,
    /// Largest diameter drawn, metres.
    pub small_max_diameter_m: f64,
    /// Exponent b of the cumulative size-frequency law N(>D) ~ D^-b (Golombek & Rapp 1997).
    pub size_exponent: f64,
    /// Number of large boulders.
    pub large_count: u32,
    /// Smallest large-boulder diameter, metres.
    pub large_min_diameter_m: f64,
    /// Largest large-boulder diameter, metres.
    pub large_max_diameter_m: f64,
    /// Height over diameter (a half-buried rock is about 0.5).
    pub height_ratio: f64,
}

/// Resource targets the mission looks for.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Targets {
    /// Number of targets.
    pub count: u32,
}

/// Direction of the light.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Sun {
    /// Elevation above the horizon, degrees (low: long hard shadows).
    pub elevation_deg: f64,
    /// Azimuth, degrees counter-clockwise from +x.
    pub azimuth_deg: f64,
}

/// The fleet: how many rovers and their hardware (modelled on the Leo Rover).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Rovers {
    /// Number of rovers.
    pub count: u8,
    /// Body length, metres.
    pub length_m: f64,
    /// Body width, metres.
    pub width_m: f64,
    /// Top speed, m/s.
    pub max_speed_m_s: f64,
    /// Top yaw rate, rad/s.
    pub max_yaw_rate_rad_s: f64,
    /// Linear acceleration limit, m/s^2.
    pub max_accel_m_s2: f64,
    /// Yaw acceleration limit, rad/s^2.
    pub max_yaw_accel_rad_s2: f64,
    /// Steepest slope it can climb, degrees.
    pub max_slope_deg: f64,
    /// Highest step it can drive over, metres.
    pub max_step_m: f64,
    /// A `cmd_vel` older than this stops the rover (the driver's dead-man), seconds.
    pub cmd_timeout_s: f64,
    /// Physics step, seconds.
    pub physics_step_s: f64,
    /// 2D lidar.
    pub lidar: Lidar,
    /// Depth camera.
    pub depth: DepthCamera,
    /// Grayscale camera.
    pub camera: Camera,
    /// Wheel odometry and slip.
    pub odometry: Odometry,
    /// Yaw gyro.
    pub imu: Imu,
}

/// RPLIDAR A2M8-like 2D lidar.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Lidar {
    /// Scans per second.
    pub rate_hz: f64,
    /// Beams per 360 degree scan.
    pub beams: u32,
    /// Shortest range, metres.
    pub range_min_m: f64,
    /// Longest range, metres.
    pub range_max_m: f64,
    /// Range noise standard deviation at zero range, metres.
    pub noise_m: f64,
    /// Extra noise standard deviation per metre of range.
    pub noise_per_m: f64,
    /// Mount height above the ground, metres.
    pub mount_height_m: f64,
    /// Mount offset forward of the rover centre, metres.
    pub mount_x_m: f64,
    /// Whether each beam is measured at its own time during the scan, as the spinning head
    /// of a real RPLIDAR does (the message's `time_increment_s` says when), rather than every
    /// beam at once from one pose. Off by default for now: de-skewed, it maps as well on one
    /// path, but the rovers then drive other paths (BENCHMARKS.md, "A lidar that sweeps").
    pub sweeps: bool,
}

/// RealSense D455-like depth camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthCamera {
    /// Frames per second.
    pub rate_hz: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Vertical field of view, degrees.
    pub vfov_deg: f64,
    /// Closest depth, metres.
    pub range_min_m: f64,
    /// Farthest depth, metres.
    pub range_max_m: f64,
    /// Depth noise sigma = this * z^2 (stereo error grows with range squared), 1/m.
    pub noise_per_m2: f64,
    /// Mount offset forward of the rover centre, metres.
    pub mount_x_m: f64,
    /// Mount height above the ground, metres.
    pub mount_height_m: f64,
    /// Downward tilt of the optical axis, degrees.
    pub tilt_down_deg: f64,
}

/// Small grayscale camera, rendered only while someone subscribes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Camera {
    /// Frames per second.
    pub rate_hz: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
}

/// Wheel odometry: what the encoders report, and how the ground makes the wheels slip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Odometry {
    /// Messages per second.
    pub rate_hz: f64,
    /// Relative standard deviation of each wheel-speed reading.
    pub speed_noise_frac: f64,
    /// Slip on flat firm ground (fraction of wheel speed lost).
    pub slip_base: f64,
    /// Extra slip per unit of slope (tan of the slope angle).
    pub slip_per_slope: f64,
    /// Extra slip on the loosest ground.
    pub slip_loose: f64,
    /// Standard deviation of the skid-steer yaw scale error (fixed per rover).
    pub yaw_scale_error_std: f64,
}

/// IMU: a gyro (the yaw rate; the roll and pitch rates too with `tilt_rates`) and an
/// accelerometer (gravity in the tilted body, so the rover's pitch and roll, plus the body's
/// own acceleration with `body_acceleration`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Imu {
    /// Messages per second.
    pub rate_hz: f64,
    /// White noise standard deviation, rad/s.
    pub gyro_noise_rad_s: f64,
    /// Standard deviation of the constant bias drawn per rover, rad/s.
    pub gyro_bias_std_rad_s: f64,
    /// Accelerometer white noise standard deviation per axis, m/s^2.
    pub accel_noise_m_s2: f64,
    /// Whether the accelerometer also feels the body's own acceleration, as a real one
    /// does: along x the change of the body's speed since the last sample (a slip burst's
    /// body all but stops while its wheels turn on; a collision stops it at once), along y
    /// a turn's centripetal acceleration. On by default; off, the accelerometer reads
    /// gravity alone, as if the body never sped up, slowed down or turned.
    pub body_acceleration: bool,
    /// Whether the gyro measures the body's roll and pitch rates too (a three-axis gyro, as
    /// the Leo Rover's IMU has): about the body's x and y axes, as the pose's roll and pitch
    /// change and its heading turns with the body tilted, with the same white noise as the
    /// yaw rate and no bias. Off, x and y read 0; z is the heading's rate either way.
    pub tilt_rates: bool,
}

/// A scheduled fault.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// What goes wrong.
    pub kind: FaultKind,
    /// Which rover, e.g. `rover2`.
    pub rover: String,
    /// When it starts, mission seconds.
    pub at_s: f64,
    /// How long it lasts, seconds (ignored for `power_off`, which is permanent).
    #[serde(default)]
    pub duration_s: f64,
    /// For `sensor_dropout`: which sensor (`lidar`, `depth`, `camera`, `odometry`, `imu`).
    #[serde(default)]
    pub sensor: Option<SensorKind>,
}

/// Kinds of fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// The wheels spin with little grip: odometry reports motion that did not happen.
    SlipBurst,
    /// One sensor stops publishing.
    SensorDropout,
    /// The rover shuts down for good.
    PowerOff,
}

impl FaultKind {
    /// The kind as a scenario file names it.
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::SlipBurst => "slip_burst",
            FaultKind::SensorDropout => "sensor_dropout",
            FaultKind::PowerOff => "power_off",
        }
    }
}

/// The rover's sensors, as named in faults.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorKind {
    /// 2D lidar.
    Lidar,
    /// Depth camera.
    Depth,
    /// Grayscale camera.
    Camera,
    /// Wheel odometry.
    Odometry,
    /// Gyro.
    Imu,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            seed: 1,
            duration_s: 4.0 * 3600.0,
            arena: Arena::default(),
            lander: Lander::default(),
            craters: Craters::default(),
            boulders: Boulders::default(),
            targets: Targets::default(),
            sun: Sun::default(),
            rovers: Rovers::default(),
            faults: vec![
                Fault {
                    kind: FaultKind::SlipBurst,
                    rover: "rover1".into(),
                    at_s: 400.0,
                    duration_s: 8.0,
                    sensor: None,
                },
                // DESIGN's mid-mission failure: five minutes in, with over a third of the
                // hall still unknown (exploration ends after 10-20 minutes), so the others
                // must map its share.
                Fault {
                    kind: FaultKind::PowerOff,
                    rover: "rover2".into(),
                    at_s: 300.0,
                    duration_s: 0.0,
                    sensor: None,
                },
            ],
            network: realms_net::NetworkConfig {
                ground: realms_net::GroundLinkConfig {
                    // Ten minutes without the ground while the fleet explores, and again
                    // later in the mission.
                    blackouts_s: vec![[600.0, 1200.0], [7200.0, 7800.0]],
                    ..realms_net::GroundLinkConfig::default()
                },
                ..realms_net::NetworkConfig::default()
            },
        }
    }
}

impl Default for Arena {
    fn default() -> Self {
        Arena {
            width_m: 50.0,
            length_m: 36.0,
            resolution_m: 0.05,
            wall_height_m: 1.0,
            wall_thickness_m: 0.2,
            undulation_m: 0.06,
            undulation_wavelength_m: 6.0,
        }
    }
}

impl Default for Lander {
    fn default() -> Self {
        Lander {
            x_m: 25.0,
            y_m: 3.0,
            size_m: 2.5,
            height_m: 1.4,
        }
    }
}

impl Default for Craters {
    fn default() -> Self {
        Craters {
            small_count: 2,
            small_diameter_m: 2.0,
            small_depth_m: 0.3,
            large_count: 1,
            large_diameter_m: 6.0,
            large_depth_m: 0.8,
            rim_fraction: 0.2,
        }
    }
}

impl Default for Boulders {
    fn default() -> Self {
        Boulders {
            small_count: 600,
            small_min_diameter_m: 0.05,
            small_max_diameter_m: 0.5,
            size_exponent: 2.5,
            large_count: 12,
            large_min_diameter_m: 0.7,
            large_max_diameter_m: 1.6,
            height_ratio: 0.5,
        }
    }
}

impl Default for Targets {
    fn default() -> Self {
        Targets { count: 5 }
    }
}

impl Default for Sun {
    fn default() -> Self {
        Sun {
            elevation_deg: 8.0,
            azimuth_deg: 200.0,
        }
    }
}

impl Default for Rovers {
    fn default() -> Self {
        Rovers {
            count: 3,
            length_m: 0.447,
            width_m: 0.433,
            max_speed_m_s: 0.4,
            max_yaw_rate_rad_s: 1.0,
            max_accel_m_s2: 0.5,
            max_yaw_accel_rad_s2: 2.0,
            max_slope_deg: 20.0,
            max_step_m: 0.08,
            cmd_timeout_s: 0.5,
            physics_step_s: 0.02,
            lidar: Lidar::default(),
            depth: DepthCamera::default(),
            camera: Camera::default(),
            odometry: Odometry::default(),
            imu: Imu::default(),
        }
    }
}

impl Default for Lidar {
    fn default() -> Self {
        Lidar {
            rate_hz: 10.0,
            beams: 360,
            range_min_m: 0.15,
            range_max_m: 12.0,
            noise_m: 0.01,
            noise_per_m: 0.002,
            mount_height_m: 0.3,
            mount_x_m: 0.0,
            sweeps: false,
        }
    }
}

impl Default for DepthCamera {
    fn default() -> Self {
        DepthCamera {
            rate_hz: 2.0,
            width: 106,
            height: 60,
            hfov_deg: 87.0,
            vfov_deg: 58.0,
            range_min_m: 0.4,
            range_max_m: 6.0,
            noise_per_m2: 0.005,
            mount_x_m: 0.2,
            mount_height_m: 0.25,
            tilt_down_deg: 15.0,
        }
    }
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            rate_hz: 1.0,
            width: 160,
            height: 120,
            hfov_deg: 90.0,
        }
    }
}

impl Default for Odometry {
    fn default() -> Self {
        Odometry {
            rate_hz: 20.0,
            speed_noise_frac: 0.02,
            slip_base: 0.03,
            slip_per_slope: 0.6,
            slip_loose: 0.12,
            yaw_scale_error_std: 0.05,
        }
    }
}

impl Default for Imu {
    fn default() -> Self {
        Imu {
            rate_hz: 50.0,
            gyro_noise_rad_s: 0.003,
            gyro_bias_std_rad_s: 0.002,
            accel_noise_m_s2: 0.02,
            body_acceleration: true,
            tilt_rates: false,
        }
    }
}

/// Why a scenario could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file could not be read.
    #[error("cannot read scenario {file}")]
    Read {
        /// The file.
        file: String,
        /// What the OS said.
        source: std::io::Error,
    },
    /// The TOML is malformed, has an unknown key or a value of the wrong type.
    #[error("scenario {file}: {message}")]
    Parse {
        /// The file.
        file: String,
        /// The parser's account, with line, column and key.
        message: String,
    },
    /// A value is of the right type but out of range.
    #[error("scenario {file}: key `{key}` {expected}, got {got}")]
    Invalid {
        /// The file.
        file: String,
        /// Dotted key path.
        key: String,
        /// What was expected.
        expected: String,
        /// What was found.
        got: String,
    },
}

impl Scenario {
    /// Reads and checks a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
            file: file.clone(),
            source,
        })?;
        Scenario::parse(&text, &file)
    }

    /// Parses and checks scenario TOML; `file` names the source in errors.
    pub fn parse(text: &str, file: &str) -> Result<Scenario, ScenarioError> {
        let scenario: Scenario = toml::from_str(text).map_err(|e| ScenarioError::Parse {
            file: file.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        scenario.validate(file)?;
        Ok(scenario)
    }

    /// Sets the fleet to `count` rovers, as a command line's override of the scenario does,
    /// and returns the faults it scheduled for rovers no longer in the fleet, which are
    /// dropped: a fault written for the scenario's own fleet says nothing of a smaller one.
    pub fn resize_fleet(&mut self, count: u8) -> Vec<Fault> {
        self.rovers.count = count;
        let (kept, dropped) = std::mem::take(&mut self.faults)
            .into_iter()
            .partition(|f| realms_core::RoverId::parse(&f.rover).is_none_or(|id| id.0 <= count));
        self.faults = kept;
        dropped
    }

    /// The default scenario as TOML (what `realms scenario --print-default` prints).
    pub fn default_toml() -> String {
        to_toml(&Scenario::default())
    }

    /// Checks value ranges; `file` names the source in errors.
    pub fn validate(&self, file: &str) -> Result<(), ScenarioError> {
        let err = |key: &str, expected: &str, got: String| ScenarioError::Invalid {
            file: file.to_string(),
            key: key.to_string(),
            expected: expected.to_string(),
            got,
        };
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(err(key, "must be a positive number", v.to_string()))
            }
        };
        let non_negative = |key: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(err(key, "must be zero or more", v.to_string()))
            }
        };
        // Every number first: a key no rule below names (a mount offset, the sun's azimuth,
        // a radio constant) must still be a number the simulation can compute with.
        if let Ok(value) = toml::Value::try_from(self)
            && let Some((key, v)) = first_non_finite(&value, "")
        {
            return Err(err(&key, "must be a finite number", v.to_string()));
        }
        let a = &self.arena;
        positive("duration_s", self.duration_s)?;
        let net = &self.network;
        non_negative("network.ground.delay_s", net.ground.delay_s)?;
        positive("network.ground.bandwidth_bps", net.ground.bandwidth_bps)?;
        if !(0.0..1.0).contains(&net.ground.loss) {
            return Err(err(
                "network.ground.loss",
                "must be at least 0 and below 1",
                net.ground.loss.to_string(),
            ));
        }
        for (i, [from, to]) in net.ground.blackouts_s.iter().enumerate() {
            if !(from.is_finite() && to.is_finite() && *from >= 0.0 && from < to) {
                return Err(err(
                    &format!("network.ground.blackouts_s[{i}]"),
                    "[start_s, end_s] with 0 <= start < end",
                    format!("[{from}, {to}]"),
                ));
            }
        }
        if !(1..=8).contains(&net.ground.map_copies) {
            return Err(err(
                "network.ground.map_copies",
                "from 1 to 8",
                net.ground.map_copies.to_string(),
            ));
        }
        positive("network.route_interval_s", net.route_interval_s)?;
        positive("network.radio.goodput_fraction", net.radio.goodput_fraction)?;
        if net.radio.mcs.is_empty() {
            return Err(err(
                "network.radio.mcs",
                "at least one [snr_db, rate_mbps] pair",
                "[]".to_string(),
            ));
        }
        if net.queue_bytes < 1500 {
            return Err(err(
                "network.queue_bytes",
                "room for at least one full frame (1500)",
                net.queue_bytes.to_string(),
            ));
        }
        positive("arena.width_m", a.width_m)?;
        positive("arena.length_m", a.length_m)?;
        positive("arena.resolution_m", a.resolution_m)?;
        if a.resolution_m > 0.1 {
            return Err(err(
                "arena.resolution_m",
                "must be at most 0.1 (rocks and crater rims need fine cells)",
                a.resolution_m.to_string(),
            ));
        }
        let cells = (a.width_m / a.resolution_m) * (a.length_m / a.resolution_m);
        if cells > 50e6 {
            return Err(err(
                "arena",
                "must have at most 50 million cells (width * length / resolution^2)",
                format!("{cells:.0}"),
            ));
        }
        positive("arena.wall_height_m", a.wall_height_m)?;
        positive("arena.wall_thickness_m", a.wall_thickness_m)?;
        non_negative("arena.undulation_m", a.undulation_m)?;
        positive("arena.undulation_wavelength_m", a.undulation_wavelength_m)?;
        let l = &self.lander;
        positive("lander.size_m", l.size_m)?;
        positive("lander.height_m", l.height_m)?;
        if !(l.x_m > 0.0 && l.x_m < a.width_m && l.y_m > 0.0 && l.y_m < a.length_m) {
            return Err(err(
                "lander",
                "must be inside the arena",
                format!("({}, {})", l.x_m, l.y_m),
            ));
        }
        let c = &self.craters;
        positive("craters.small_diameter_m", c.small_diameter_m)?;
        positive("craters.small_depth_m", c.small_depth_m)?;
        positive("craters.large_diameter_m", c.large_diameter_m)?;
        positive("craters.large_depth_m", c.large_depth_m)?;
        non_negative("craters.rim_fraction", c.rim_fraction)?;
        let b = &self.boulders;
        // Each is placed by drawing spots until one is clear of what is already placed, so
        // counts far beyond what the arena holds would run the generation for hours.
        for (key, count, most) in [
            (
                "craters.small_count + craters.large_count",
                u64::from(c.small_count) + u64::from(c.large_count),
                MOST_CRATERS,
            ),
            (
                "boulders.small_count",
                u64::from(b.small_count),
                MOST_SMALL_BOULDERS,
            ),
            (
                "boulders.large_count",
                u64::from(b.large_count),
                MOST_LARGE_BOULDERS,
            ),
            ("targets.count", u64::from(self.targets.count), MOST_TARGETS),
        ] {
            if count > most {
                return Err(err(
                    key,
                    &format!("must be at most {most}"),
                    count.to_string(),
                ));
            }
        }
        positive("boulders.small_min_diameter_m", b.small_min_diameter_m)?;
        if b.small_max_diameter_m < b.small_min_diameter_m {
            return Err(err(
                "boulders.small_max_diameter_m",
                "must be at least boulders.small_min_diameter_m",
                b.small_max_diameter_m.to_string(),
            ));
        }
        positive("boulders.size_exponent", b.size_exponent)?;
        positive("boulders.large_min_diameter_m", b.large_min_diameter_m)?;
        if b.large_max_diameter_m < b.large_min_diameter_m {
            return Err(err(
                "boulders.large_max_diameter_m",
                "must be at least boulders.large_min_diameter_m",
                b.large_max_diameter_m.to_string(),
            ));
        }
        positive("boulders.height_ratio", b.height_ratio)?;
        // Sizes far beyond any hall: a rock or crater 1e300 m across overflows the terrain's
        // cell arithmetic.
        for (key, length_m) in [
            ("arena.wall_height_m", a.wall_height_m),
            ("arena.wall_thickness_m", a.wall_thickness_m),
            ("arena.undulation_m", a.undulation_m),
            ("arena.undulation_wavelength_m", a.undulation_wavelength_m),
            ("lander.size_m", l.size_m),
            ("lander.height_m", l.height_m),
            ("craters.small_diameter_m", c.small_diameter_m),
            ("craters.small_depth_m", c.small_depth_m),
            ("craters.large_diameter_m", c.large_diameter_m),
            ("craters.large_depth_m", c.large_depth_m),
            ("boulders.small_max_diameter_m", b.small_max_diameter_m),
            ("boulders.large_max_diameter_m", b.large_max_diameter_m),
        ] {
            if length_m > MOST_LENGTH_M {
                return Err(err(
                    key,
                    &format!("must be at most {MOST_LENGTH_M} m"),
                    length_m.to_string(),
                ));
            }
        }
        if !(0.0..=90.0).contains(&self.sun.elevation_deg) {
            return Err(err(
                "sun.elevation_deg",
                "must be between 0 and 90",
                self.sun.elevation_deg.to_string(),
            ));
        }
        let r = &self.rovers;
        if r.count == 0 || r.count > 16 {
            return Err(err("rovers.count", "must be 1 to 16", r.count.to_string()));
        }
        for (key, v) in [
            ("rovers.length_m", r.length_m),
            ("rovers.width_m", r.width_m),
            ("rovers.max_speed_m_s", r.max_speed_m_s),
            ("rovers.max_yaw_rate_rad_s", r.max_yaw_rate_rad_s),
            ("rovers.max_accel_m_s2", r.max_accel_m_s2),
            ("rovers.max_yaw_accel_rad_s2", r.max_yaw_accel_rad_s2),
            ("rovers.max_slope_deg", r.max_slope_deg),
            ("rovers.max_step_m", r.max_step_m),
            ("rovers.cmd_timeout_s", r.cmd_timeout_s),
            ("rovers.physics_step_s", r.physics_step_s),
            ("rovers.lidar.rate_hz", r.lidar.rate_hz),
            ("rovers.lidar.range_min_m", r.lidar.range_min_m),
            ("rovers.lidar.range_max_m", r.lidar.range_max_m),
            ("rovers.lidar.mount_height_m", r.lidar.mount_height_m),
            ("rovers.depth.rate_hz", r.depth.rate_hz),
            ("rovers.depth.hfov_deg", r.depth.hfov_deg),
            ("rovers.depth.vfov_deg", r.depth.vfov_deg),
            ("rovers.depth.range_min_m", r.depth.range_min_m),
            ("rovers.depth.range_max_m", r.depth.range_max_m),
            ("rovers.depth.mount_height_m", r.depth.mount_height_m),
            ("rovers.camera.rate_hz", r.camera.rate_hz),
            ("rovers.camera.hfov_deg", r.camera.hfov_deg),
            ("rovers.odometry.rate_hz", r.odometry.rate_hz),
            ("rovers.imu.rate_hz", r.imu.rate_hz),
        ] {
            positive(key, v)?;
        }
        for (key, v) in [
            ("rovers.lidar.noise_m", r.lidar.noise_m),
            ("rovers.lidar.noise_per_m", r.lidar.noise_per_m),
            ("rovers.depth.noise_per_m2", r.depth.noise_per_m2),
            (
                "rovers.odometry.speed_noise_frac",
                r.odometry.speed_noise_frac,
            ),
            ("rovers.odometry.slip_base", r.odometry.slip_base),
            ("rovers.odometry.slip_per_slope", r.odometry.slip_per_slope),
            ("rovers.odometry.slip_loose", r.odometry.slip_loose),
            (
                "rovers.odometry.yaw_scale_error_std",
                r.odometry.yaw_scale_error_std,
            ),
            ("rovers.imu.gyro_noise_rad_s", r.imu.gyro_noise_rad_s),
            ("rovers.imu.gyro_bias_std_rad_s", r.imu.gyro_bias_std_rad_s),
            ("rovers.imu.accel_noise_m_s2", r.imu.accel_noise_m_s2),
        ] {
            non_negative(key, v)?;
        }
        // Periods must be whole, positive nanoseconds the clock can add up over a mission.
        for (key, hz) in [
            ("rovers.lidar.rate_hz", r.lidar.rate_hz),
            ("rovers.depth.rate_hz", r.depth.rate_hz),
            ("rovers.camera.rate_hz", r.camera.rate_hz),
            ("rovers.odometry.rate_hz", r.odometry.rate_hz),
            ("rovers.imu.rate_hz", r.imu.rate_hz),
        ] {
            if !(0.001..=10_000.0).contains(&hz) {
                return Err(err(
                    key,
                    "must be between 0.001 and 10000 Hz",
                    hz.to_string(),
                ));
            }
        }
        if !(1e-4..=0.1).contains(&r.physics_step_s) {
            return Err(err(
                "rovers.physics_step_s",
                "must be between 0.0001 and 0.1 s",
                r.physics_step_s.to_string(),
            ));
        }
        if self.duration_s > 1e7 {
            return Err(err(
                "duration_s",
                "must be at most 1e7 s (115 days)",
                self.duration_s.to_string(),
            ));
        }
        for (key, deg) in [
            ("rovers.depth.hfov_deg", r.depth.hfov_deg),
            ("rovers.depth.vfov_deg", r.depth.vfov_deg),
            ("rovers.camera.hfov_deg", r.camera.hfov_deg),
        ] {
            if deg >= 170.0 {
                return Err(err(
                    key,
                    "must be below 170 degrees (a pinhole camera)",
                    deg.to_string(),
                ));
            }
        }
        if r.max_slope_deg >= 80.0 {
            return Err(err(
                "rovers.max_slope_deg",
                "must be below 80 degrees",
                r.max_slope_deg.to_string(),
            ));
        }
        // Rovers start in a line beside the lander; the line must fit inside the walls.
        let line_m = f64::from(r.count) * (r.width_m + 0.8);
        let clear = l.size_m / 2.0 + 1.2 + r.length_m;
        let room = (a.width_m.min(a.length_m) / 2.0) - a.wall_thickness_m;
        if line_m > a.width_m.max(a.length_m) - 2.0 * a.wall_thickness_m || clear > room {
            return Err(err(
                "rovers.count",
                "must fit in a line beside the lander inside the arena",
                format!(
                    "{} rovers in a {} x {} m arena",
                    r.count, a.width_m, a.length_m
                ),
            ));
        }
        if r.lidar.range_max_m <= r.lidar.range_min_m {
            return Err(err(
                "rovers.lidar.range_max_m",
                "must exceed rovers.lidar.range_min_m",
                r.lidar.range_max_m.to_string(),
            ));
        }
        if r.depth.range_max_m <= r.depth.range_min_m {
            return Err(err(
                "rovers.depth.range_max_m",
                "must exceed rovers.depth.range_min_m",
                r.depth.range_max_m.to_string(),
            ));
        }
        if r.lidar.beams == 0 || r.lidar.beams > 4096 {
            return Err(err(
                "rovers.lidar.beams",
                "must be 1 to 4096",
                r.lidar.beams.to_string(),
            ));
        }
        for (key, w, h) in [
            ("rovers.depth", r.depth.width, r.depth.height),
            ("rovers.camera", r.camera.width, r.camera.height),
        ] {
            if w == 0 || h == 0 || w > 2048 || h > 2048 {
                return Err(err(
                    &format!("{key}.width/height"),
                    "must be 1 to 2048 pixels",
                    format!("{w} x {h}"),
                ));
            }
        }
        if r.odometry.slip_base >= 1.0 {
            return Err(err(
                "rovers.odometry.slip_base",
                "must be below 1",
                r.odometry.slip_base.to_string(),
            ));
        }
        for (i, f) in self.faults.iter().enumerate() {
            let key = |k: &str| format!("faults[{i}].{k}");
            match realms_core::RoverId::parse(&f.rover) {
                Some(id) if id.0 >= 1 && id.0 <= r.count => {}
                _ => {
                    return Err(err(
                        &key("rover"),
                        &format!(
                            "must name a rover of the fleet (rover1 .. rover{})",
                            r.count
                        ),
                        format!("{:?}", f.rover),
                    ));
                }
            }
            non_negative(&key("at_s"), f.at_s)?;
            non_negative(&key("duration_s"), f.duration_s)?;
            if f.kind == FaultKind::SensorDropout && f.sensor.is_none() {
                return Err(err(
                    &key("sensor"),
                    "must name the sensor that drops out (lidar, depth, camera, odometry, imu)",
                    "nothing".into(),
                ));
            }
        }
        Ok(())
    }
}

/// The first float in `value` (a scenario as TOML) that is not finite, with its key (dotted
/// from `prefix`, arrays indexed).
fn first_non_finite(value: &toml::Value, prefix: &str) -> Option<(String, f64)> {
    let join = |key: &str| {
        if prefix.is_empty() {
            key.to_string()
        } else {
            format!("{prefix}.{key}")
        }
    };
    match value {
        toml::Value::Float(v) if !v.is_finite() => Some((prefix.to_string(), *v)),
        toml::Value::Table(table) => table
            .iter()
            .find_map(|(key, v)| first_non_finite(v, &join(key))),
        toml::Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(i, v)| first_non_finite(v, &format!("{prefix}[{i}]"))),
        _ => None,
    }
}

/// Any scenario as TOML, in the layout `--print-default` uses: tables, one key a line,
/// arrays on their key's line.
pub fn to_toml(s: &Scenario) -> String {
    toml::to_string(s).expect("a scenario is plain data and always serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_round_trips_through_toml() {
        let text = Scenario::default_toml();
        let back = Scenario::parse(&text, "default").expect("default parses");
        assert_eq!(back, Scenario::default());
        // One key a line, the radio's rate table and the blackouts included: a reader edits
        // the printed default, so no array is spread over a staircase of lines.
        for line in text.lines() {
            assert!(
                line.is_empty() || line.starts_with('[') || line.contains(" = "),
                "{line:?}"
            );
        }
    }

    #[test]
    fn partial_files_take_defaults() {
        let s = Scenario::parse("seed = 7\n[rovers]\ncount = 2\n", "t.toml").expect("valid");
        assert_eq!(s.seed, 7);
        assert_eq!(s.rovers.count, 2);
        assert_eq!(s.arena, Arena::default());
    }

    #[test]
    fn a_smaller_fleet_drops_the_faults_of_the_rovers_it_no_longer_has() {
        let mut s = Scenario::default();
        let before = s.faults.clone();
        assert!(
            before.iter().any(|f| f.rover == "rover1")
                && before.iter().any(|f| f.rover == "rover2"),
            "the default schedules faults for rover1 and rover2: {before:?}"
        );
        let dropped = s.resize_fleet(1);
        assert_eq!(s.rovers.count, 1);
        assert!(dropped.iter().all(|f| f.rover != "rover1"), "{dropped:?}");
        assert!(
            s.faults.iter().all(|f| f.rover == "rover1"),
            "{:?}",
            s.faults
        );
        assert_eq!(s.faults.len() + dropped.len(), before.len());
        s.validate("default")
            .expect("a one-rover fleet of the default is valid");
        // A larger fleet keeps every fault.
        let mut s = Scenario::default();
        assert!(s.resize_fleet(5).is_empty());
        assert_eq!(s.faults, before);
        s.validate("default").expect("valid");
        // Each kind's name is the one a scenario file uses.
        for kind in [
            FaultKind::SlipBurst,
            FaultKind::SensorDropout,
            FaultKind::PowerOff,
        ] {
            let f: Fault = toml::from_str(&format!(
                "kind = \"{}\"\nrover = \"rover1\"\nat_s = 1.0\n",
                kind.name()
            ))
            .expect("the name parses");
            assert_eq!(f.kind, kind);
        }
    }

    #[test]
    fn unknown_key_names_file_and_key() {
        let e = Scenario::parse("[arena]\nwidht_m = 3.0\n", "bad.toml").expect_err("unknown key");
        let msg = e.to_string();
        assert!(msg.contains("bad.toml") && msg.contains("widht_m"), "{msg}");
    }

    #[test]
    fn wrong_type_and_range_are_errors() {
        let e = Scenario::parse("[arena]\nwidth_m = \"wide\"\n", "t.toml").expect_err("type");
        assert!(e.to_string().contains("width_m"), "{e}");
        let e = Scenario::parse("[arena]\nresolution_m = -1.0\n", "t.toml").expect_err("range");
        assert!(e.to_string().contains("arena.resolution_m"), "{e}");
        let e = Scenario::parse(
            "[[faults]]\nkind = \"power_off\"\nrover = \"rover9\"\nat_s = 3.0\n",
            "t.toml",
        )
        .expect_err("no such rover");
        assert!(e.to_string().contains("faults[0].rover"), "{e}");
        for (text, key) in [
            ("[rovers.lidar]\nrate_hz = 1e12\n", "rovers.lidar.rate_hz"),
            (
                "[rovers]\nphysics_step_s = 1e-12\n",
                "rovers.physics_step_s",
            ),
            (
                "[rovers.depth]\nhfov_deg = 200.0\n",
                "rovers.depth.hfov_deg",
            ),
            ("[rovers]\nmax_slope_deg = 90.0\n", "rovers.max_slope_deg"),
            // Counts the generation would spend hours placing.
            ("[targets]\ncount = 1001\n", "targets.count"),
            (
                "[boulders]\nsmall_count = 4000000000\n",
                "boulders.small_count",
            ),
            ("[boulders]\nlarge_count = 10001\n", "boulders.large_count"),
            // Numbers no other rule names, and sizes the arena cannot hold (found by
            // mutating the default; each made the mission panic).
            (
                "[boulders]\nlarge_max_diameter_m = inf\n",
                "boulders.large_max_diameter_m",
            ),
            (
                "[boulders]\nlarge_min_diameter_m = 1e300\nlarge_max_diameter_m = 1e300\n",
                "boulders.large_max_diameter_m",
            ),
            ("[sun]\nazimuth_deg = nan\n", "sun.azimuth_deg"),
            (
                "[rovers.lidar]\nmount_x_m = -inf\n",
                "rovers.lidar.mount_x_m",
            ),
            (
                "[craters]\nlarge_diameter_m = 1e5\n",
                "craters.large_diameter_m",
            ),
            ("[arena]\nwall_height_m = 1e300\n", "arena.wall_height_m"),
            (
                "[network.radio]\nmcs = [[4.0, nan]]\n",
                "network.radio.mcs[0][1]",
            ),
            (
                "[craters]\nsmall_count = 4000000000\nlarge_count = 4000000000\n",
                "craters.small_count + craters.large_count",
            ),
            (
                "[rovers]\ncount = 16\n[arena]\nwidth_m = 4.0\nlength_m = 4.0\n[lander]\nx_m = 2.0\ny_m = 2.0\n",
                "rovers.count",
            ),
        ] {
            let e = Scenario::parse(text, "t.toml").expect_err(key);
            assert!(e.to_string().contains(key), "{e}");
        }
        Scenario::parse(
            "[targets]\ncount = 1000\n[boulders]\nlarge_count = 10000\n",
            "t.toml",
        )
        .expect("counts at their limits");
        let e = Scenario::parse(
            "[[faults]]\nkind = \"melt\"\nrover = \"rover1\"\nat_s = 3.0\n",
            "t.toml",
        )
        .expect_err("unknown kind");
        assert!(e.to_string().contains("melt"), "{e}");
    }
}
