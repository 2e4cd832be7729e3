//! Proprioceptive sensors: wheel odometry (the encoder-integrated pose, which drifts with slip
//! and the skid-steer yaw error) and an IMU: a yaw gyro (true rate plus a fixed bias and white
//! noise) and an accelerometer (gravity in the tilted body frame plus white noise).

use super::gaussian;
use crate::rng::SimRng;
use crate::rover::RoverBody;
use crate::scenario::Rovers;
use realms_core::Time;
use realms_core::geometry::{Quaternion, Vec3};
use realms_core::msgs::{
    Header, Imu, Odometry, Pose3, PoseWithCovariance, Twist, TwistWithCovariance,
};

/// The odometry message for a rover's current encoder state.
pub fn odometry(body: &RoverBody, spec: &Rovers, stamp: Time) -> Odometry {
    let ns = body.id.namespace();
    let p = &body.odom_pose;
    let mut pose_cov = [[0.0; 6]; 6];
    let mut twist_cov = [[0.0; 6]; 6];
    let rel = spec.odometry.speed_noise_frac.max(1e-3);
    // Nominal per-message uncertainty; z, roll and pitch are not estimated (large variance).
    for (i, v) in [
        (0, 0.01),
        (1, 0.01),
        (2, 1e6),
        (3, 1e6),
        (4, 1e6),
        (5, 0.02),
    ] {
        pose_cov[i][i] = v;
    }
    twist_cov[0][0] = (rel * spec.max_speed_m_s).powi(2);
    twist_cov[5][5] =
        (spec.odometry.yaw_scale_error_std.max(rel) * spec.max_yaw_rate_rad_s).powi(2);
    Odometry {
        header: Header {
            stamp,
            frame_id: format!("{ns}/odom"),
        },
        child_frame_id: format!("{ns}/base_link"),
        pose: PoseWithCovariance {
            pose: Pose3 {
                position: Vec3::new(p.x_m, p.y_m, 0.0),
                orientation: Quaternion::from_roll_pitch_yaw(0.0, 0.0, p.yaw_rad),
            },
            covariance: pose_cov,
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vec3::new(body.odom_speed_m_s, 0.0, 0.0),
                angular: Vec3::new(0.0, 0.0, body.odom_yaw_rate_rad_s),
            },
            covariance: twist_cov,
        },
    }
}

/// Standard gravity, m/s^2 (the analogue hall is on Earth).
const GRAVITY_M_S2: f64 = 9.81;

/// The IMU message: the true yaw rate plus bias and noise, and the accelerometer's specific
/// force: gravity seen in the tilted body frame (REP 103: x forward, z up) plus noise, and
/// the body's own acceleration `felt` (along x and y, m/s^2) if the scenario has it felt
/// ([`crate::scenario::Imu::body_acceleration`]); and about x and y, if the scenario's gyro
/// measures them ([`crate::scenario::Imu::tilt_rates`]), the body's angular velocity from the
/// rates of its roll and pitch (`tilt_rates`, rad/s) and its heading's.
pub fn imu(
    body: &RoverBody,
    spec: &Rovers,
    rng: &mut SimRng,
    stamp: Time,
    felt: Option<(f64, f64)>,
    tilt_rates: Option<(f64, f64)>,
) -> Imu {
    let sigma = spec.imu.gyro_noise_rad_s;
    let not_provided = [[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
    let var = sigma * sigma;
    let (sp, cp) = body.pitch_rad.sin_cos();
    let (sr, cr) = body.roll_rad.sin_cos();
    let a_sigma = spec.imu.accel_noise_m_s2;
    let a_var = a_sigma * a_sigma;
    let gyro_z = body.yaw_rate_rad_s + body.gyro_bias_rad_s + gaussian(rng, sigma);
    let mut accel = Vec3::new(
        -GRAVITY_M_S2 * sp + gaussian(rng, a_sigma),
        GRAVITY_M_S2 * cp * sr + gaussian(rng, a_sigma),
        GRAVITY_M_S2 * cp * cr + gaussian(rng, a_sigma),
    );
    if let Some((along, across)) = felt {
        accel.x += along;
        accel.y += across;
    }
    // The body's angular velocity from the rates of its Z-Y-X angles (REP 103): the heading
    // turns about the world's vertical, which a tilted body sees partly about its x and y.
    let (mut gyro_x, mut gyro_y) = (0.0, 0.0);
    if let Some((roll_rate, pitch_rate)) = tilt_rates {
        let yaw_rate = body.yaw_rate_rad_s;
        gyro_x = roll_rate - yaw_rate * sp + gaussian(rng, sigma);
        gyro_y = pitch_rate * cr + yaw_rate * cp * sr + gaussian(rng, sigma);
    }
    Imu {
        header: Header {
            stamp,
            frame_id: format!("{}/imu", body.id.namespace()),
        },
        orientation: Quaternion::IDENTITY,
        orientation_covariance: not_provided,
        angular_velocity: Vec3::new(gyro_x, gyro_y, gyro_z),
        angular_velocity_covariance: [[var, 0.0, 0.0], [0.0, var, 0.0], [0.0, 0.0, var]],
        linear_acceleration: accel,
        linear_acceleration_covariance: [[a_var, 0.0, 0.0], [0.0, a_var, 0.0], [0.0, 0.0, a_var]],
    }
}
