//! Sensors against analytic answers in hand-built worlds.

mod common;

use common::{flat_world, idle_until, scenario};
use realms_core::geometry::{Vec3, normalize_angle_rad};
use realms_core::msgs::{Header, LaserScan, Message, PointCloud, Twist, TwistStamped};
use realms_core::{Duration, Point2, Pose2, RoverId, Time};
use realms_sim::World;
use realms_sim::terrain::{Boulder, Crater, Rect};

fn first_scan(out: &[(realms_core::Topic, Message)]) -> LaserScan {
    out.iter()
        .find_map(|(_, m)| match m {
            Message::LaserScan(s) => Some(s.clone()),
            _ => None,
        })
        .expect("a scan was published")
}

fn first_cloud(out: &[(realms_core::Topic, Message)]) -> PointCloud {
    out.iter()
        .find_map(|(_, m)| match m {
            Message::PointCloud(c) => Some(c.clone()),
            _ => None,
        })
        .expect("a depth frame was published")
}

/// One default rover whose lidar has no noise, so ranges compare exactly with geometry.
fn noiseless_lidar() -> realms_sim::Scenario {
    let mut s = scenario(1);
    s.rovers.lidar.noise_m = 0.0;
    s.rovers.lidar.noise_per_m = 0.0;
    s
}

/// One rover at (5, 10) facing a 1 m wall whose face is 7 m east of it (x = 12 m).
fn facing_the_east_wall(s: &realms_sim::Scenario) -> World {
    flat_world(s, &[Pose2::new(5.0, 10.0, 0.0)], |t| {
        t.add_wall(
            Rect {
                min: Point2::new(12.0, 0.0),
                max: Point2::new(12.5, 20.0),
            },
            1.0,
        );
    })
}

fn beam_angle(scan: &LaserScan, i: usize) -> f64 {
    scan.angle_min_rad as f64 + i as f64 * scan.angle_increment_rad as f64
}

/// World coordinates of every valid depth point.
fn cloud_in_world(world: &World, cloud: &PointCloud) -> Vec<[f64; 3]> {
    let body = world.rovers().next().expect("one rover");
    let world_from_optical = World::world_from_base(body).compose(&world.base_from_optical());
    cloud
        .points_in_sensor
        .iter()
        .filter(|p| !p[2].is_nan())
        .map(|p| world_from_optical.transform([p[0] as f64, p[1] as f64, p[2] as f64]))
        .collect()
}

#[test]
fn lidar_ranges_to_a_wall_match_geometry() {
    let s = noiseless_lidar();
    let mut world = facing_the_east_wall(&s);
    let scan = first_scan(&idle_until(&mut world, Time::from_secs_f64(0.2)));
    assert_eq!(scan.ranges_m.len(), 360);
    let mut checked = 0;
    for (i, r) in scan.ranges_m.iter().enumerate() {
        let a = beam_angle(&scan, i);
        if a.abs() < 40f64.to_radians() {
            let expected = 7.0 / a.cos();
            assert!(
                (*r as f64 - expected).abs() < 1e-3,
                "beam {a:.3} rad: {r} vs {expected}"
            );
            checked += 1;
        }
    }
    assert!(checked > 70);
    // Behind the rover the west wall is 4.8 m away (its face at x = 0.2).
    let back = scan.ranges_m[0] as f64;
    assert!((back - 4.8).abs() < 1e-3, "{back}");
}

/// A sweeping lidar measures each beam at its own time, from where the rover then was: on a
/// rover turning in place, every beam that meets the east wall reads the wall's distance
/// along the direction the beam had at its own instant, and the early beams of a scan read
/// clearly other ranges than a scan taken at once from the last pose would.
#[test]
fn a_sweeping_lidar_measures_each_beam_from_the_pose_of_its_own_time() {
    let mut s = noiseless_lidar();
    s.rovers.lidar.sweeps = true;
    let mut world = facing_the_east_wall(&s);
    // Turn in place at 1 rad/s, recording the state at every physics step.
    let step = Duration::from_secs_f64(s.rovers.physics_step_s);
    let (mut states, mut out) = (vec![(Time::ZERO, 0.0)], Vec::new());
    let mut t = Time::ZERO;
    while t < Time::from_secs_f64(3.0) {
        world.command(
            RoverId(1),
            TwistStamped {
                header: Header {
                    stamp: t,
                    frame_id: "rover1/base_link".into(),
                },
                twist: Twist {
                    linear: Vec3::new(0.0, 0.0, 0.0),
                    angular: Vec3::new(0.0, 0.0, 1.0),
                },
            },
        );
        t += step;
        world.advance_to(t, &mut out);
        let body = world.rovers().next().expect("one rover");
        assert!((body.pose.x_m - 5.0).abs() < 1e-9 && (body.pose.y_m - 10.0).abs() < 1e-9);
        states.push((t, body.pose.yaw_rad));
    }
    // Between two physics steps the rover turns at a steady rate.
    let yaw_at = |at: Time| {
        let k = states.partition_point(|(ts, _)| *ts <= at);
        let (t0, y0) = states[k - 1];
        let Some(&(t1, y1)) = states.get(k) else {
            return y0;
        };
        y0 + normalize_angle_rad(y1 - y0) * (at - t0).as_secs_f64() / (t1 - t0).as_secs_f64()
    };
    let scan = out
        .iter()
        .rev()
        .find_map(|(_, m)| match m {
            Message::LaserScan(s) => Some(s.clone()),
            _ => None,
        })
        .expect("scans were published");
    let sweep = scan.sweep().as_secs_f64();
    assert!(
        (sweep - 0.1 * 359.0 / 360.0).abs() < 1e-6,
        "sweep {sweep} s"
    );
    let last_yaw = yaw_at(scan.last_beam_time());
    let (mut checked, mut skewed) = (0, 0);
    for (i, r) in scan.ranges_m.iter().enumerate() {
        let a = beam_angle(&scan, i);
        let own = normalize_angle_rad(a + yaw_at(scan.header.stamp + scan.beam_offset(i)));
        if own.abs() < 40f64.to_radians() {
            let expected = 7.0 / own.cos();
            assert!(
                (*r as f64 - expected).abs() < 1e-3,
                "beam {i}: {r} against {expected}"
            );
            checked += 1;
            let at_once = normalize_angle_rad(a + last_yaw);
            if at_once.abs() < 40f64.to_radians() && (7.0 / at_once.cos() - expected).abs() > 0.05 {
                skewed += 1;
            }
        }
    }
    assert!(checked > 70, "{checked}");
    assert!(
        skewed > 20,
        "{skewed} beams read differently from a scan at once"
    );
}

#[test]
fn lidar_noise_has_the_configured_spread() {
    let s = scenario(1);
    let mut world = facing_the_east_wall(&s);
    let out = idle_until(&mut world, Time::from_secs_f64(20.0));
    let errors: Vec<f64> = out
        .iter()
        .filter_map(|(_, m)| match m {
            Message::LaserScan(s) => Some(s.ranges_m[180] as f64 - 7.0),
            _ => None,
        })
        .collect();
    assert!(errors.len() >= 190);
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    let std = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / errors.len() as f64).sqrt();
    let sigma = s.rovers.lidar.noise_m + s.rovers.lidar.noise_per_m * 7.0;
    assert!(
        mean.abs() < 4.0 * sigma / (errors.len() as f64).sqrt(),
        "bias {mean}"
    );
    assert!(
        std > 0.8 * sigma && std < 1.2 * sigma,
        "std {std} vs {sigma}"
    );
}

#[test]
fn lidar_sees_a_tall_boulder_where_its_surface_crosses_the_beam() {
    let s = noiseless_lidar();
    let boulder = Boulder {
        center: Point2::new(8.0, 13.0),
        radius_m: 0.5,
        height_m: 0.5,
    };
    let mut world = flat_world(&s, &[Pose2::new(5.0, 13.0, 0.0)], |t| {
        t.add_boulder(boulder)
    });
    let scan = first_scan(&idle_until(&mut world, Time::from_secs_f64(0.2)));
    // A hemisphere of radius 0.5 is 0.3 m high at 0.4 m from its centre: 3 - 0.4 = 2.6 m.
    let r = scan.ranges_m[180] as f64;
    assert!((r - 2.6).abs() < 0.06, "{r}");
}

#[test]
fn depth_matches_a_flat_floor_with_range_squared_noise() {
    let s = scenario(1);
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |_| {});
    let cloud = first_cloud(&idle_until(&mut world, Time::from_secs_f64(0.6)));
    assert_eq!((cloud.width, cloud.height), (106, 60));
    let d = &s.rovers.depth;
    let mut valid = 0;
    for p in cloud.points_in_sensor.iter().filter(|p| !p[2].is_nan()) {
        let z = p[2] as f64;
        assert!(
            z >= d.range_min_m - 0.5 && z <= d.range_max_m + 1.0,
            "depth {z}"
        );
        valid += 1;
    }
    // Each valid point lies on the floor (z = 0) up to the depth noise along its ray.
    for w in cloud_in_world(&world, &cloud) {
        let range = (w[0] - 3.2).hypot(w[1] - 10.0);
        let sigma = d.noise_per_m2 * range * range;
        assert!(
            w[2].abs() < 0.01 + 5.0 * sigma * 0.5,
            "point {w:?} off the floor"
        );
    }
    // The lower part of the image sees floor within range; the top sees nothing.
    assert!(valid > 106 * 20, "{valid} valid points");
    let top_row = &cloud.points_in_sensor[..106];
    assert!(top_row.iter().all(|p| p[2].is_nan()));
}

#[test]
fn noise_free_depth_matches_each_pixel_ray_and_keeps_left_on_the_left() {
    let mut s = scenario(1);
    s.rovers.depth.noise_per_m2 = 0.0;
    // A tall rock ahead and to the left (+y of a rover facing +x).
    let rock = Boulder {
        center: Point2::new(5.0, 11.0),
        radius_m: 0.3,
        height_m: 0.6,
    };
    let mut world = flat_world(&s, &[Pose2::new(3.0, 10.0, 0.0)], |t| t.add_boulder(rock));
    let cloud = first_cloud(&idle_until(&mut world, Time::from_secs_f64(0.6)));
    let body = world.rovers().next().expect("one rover");
    let optical = World::world_from_base(body).compose(&world.base_from_optical());
    let d = &s.rovers.depth;
    let k =
        realms_sim::sensors::depth::Intrinsics::from_fov(d.width, d.height, d.hfov_deg, d.vfov_deg);
    let (mut floor_pixels, mut rock_pixels) = (0, 0);
    for v in 0..d.height {
        for u in 0..d.width {
            let p = cloud.points_in_sensor[(v * d.width + u) as usize];
            let r = k.ray(u, v);
            let dir = optical.rotate(r);
            // Where this pixel's ray meets the floor (z = 0), as optical depth.
            let floor_z = (dir[2] < 0.0).then(|| -optical.origin[2] / dir[2]);
            let world_p = (!p[2].is_nan())
                .then(|| optical.transform([p[0] as f64, p[1] as f64, p[2] as f64]));
            match world_p {
                Some(w)
                    if Point2::new(w[0], w[1]).distance_m(rock.center) < rock.radius_m + 0.05 =>
                {
                    // On the rock: nearer than the floor behind it, and in the left half.
                    rock_pixels += 1;
                    assert!(u < d.width / 2, "rock pixel at u = {u}");
                    assert!(floor_z.is_none_or(|z| (p[2] as f64) <= z + 1e-4));
                }
                Some(_) => {
                    floor_pixels += 1;
                    let z = floor_z.expect("a floor point lies on a downward ray");
                    assert!(
                        (p[2] as f64 - z).abs() < 1e-4,
                        "pixel ({u}, {v}): {} vs {z}",
                        p[2]
                    );
                    assert!(
                        (p[0] as f64 - r[0] * z).abs() < 1e-4
                            && (p[1] as f64 - r[1] * z).abs() < 1e-4
                    );
                }
                None => {
                    // No return: the floor is out of range there (or the ray looks up).
                    assert!(
                        floor_z.is_none_or(|z| !(d.range_min_m..=d.range_max_m).contains(&z)),
                        "pixel ({u}, {v}) lost"
                    );
                }
            }
        }
    }
    assert!(
        floor_pixels > 2000 && rock_pixels > 20,
        "{floor_pixels} floor, {rock_pixels} rock pixels"
    );
}

#[test]
fn crater_is_invisible_to_the_lidar_and_visible_to_the_depth_camera() {
    let s = noiseless_lidar();
    let crater = Crater {
        center: Point2::new(7.0, 10.0),
        radius_m: 1.0,
        depth_m: 0.3,
        rim_m: 0.06,
    };
    let mut world = flat_world(&s, &[Pose2::new(4.5, 10.0, 0.0)], |t| t.add_crater(crater));
    let out = idle_until(&mut world, Time::from_secs_f64(0.6));
    let scan = first_scan(&out);
    // Straight ahead the beam flies over the crater to the east wall at x = 19.8.
    for i in 170..=190 {
        let r = scan.ranges_m[i] as f64;
        assert!(r > 10.0, "beam {i} stopped at {r} m");
    }
    let points = cloud_in_world(&world, &first_cloud(&out));
    let inside_deep = points
        .iter()
        .filter(|p| Point2::new(p[0], p[1]).distance_m(crater.center) < 0.8 && p[2] < -0.1)
        .count();
    assert!(
        inside_deep > 20,
        "only {inside_deep} points inside the bowl"
    );
    let on_rim = points
        .iter()
        .filter(|p| {
            (Point2::new(p[0], p[1]).distance_m(crater.center) - 1.0).abs() < 0.1 && p[2] > 0.03
        })
        .count();
    assert!(on_rim > 3, "only {on_rim} points on the raised rim");
}

#[test]
fn a_rock_below_the_lidar_plane_is_seen_only_by_the_depth_camera() {
    let s = noiseless_lidar();
    let rock = Boulder {
        center: Point2::new(6.0, 10.0),
        radius_m: 0.2,
        height_m: 0.15,
    };
    let mut world = flat_world(&s, &[Pose2::new(4.5, 10.0, 0.0)], |t| t.add_boulder(rock));
    let out = idle_until(&mut world, Time::from_secs_f64(0.6));
    assert!(first_scan(&out).ranges_m[180] > 10.0);
    let points = cloud_in_world(&world, &first_cloud(&out));
    let on_rock = points
        .iter()
        .filter(|p| Point2::new(p[0], p[1]).distance_m(rock.center) < 0.2 && p[2] > 0.08)
        .count();
    assert!(on_rock > 5, "only {on_rock} points on the rock");
}

#[test]
fn camera_renders_only_when_wanted_and_shows_light_and_shadow() {
    let mut s = scenario(1);
    // Higher than the default 8 degrees, whose shadows from the 1 m walls of this small test
    // world would cover most of the floor in view; from the left, so the rock's shadow falls
    // across the view instead of hiding behind the rock.
    s.sun.elevation_deg = 20.0;
    s.sun.azimuth_deg = 90.0;
    let image = |with_rock: bool| {
        let rock = Boulder {
            center: Point2::new(7.0, 10.0),
            radius_m: 0.6,
            height_m: 0.6,
        };
        let mut world = flat_world(&s, &[Pose2::new(4.0, 10.0, 0.0)], |t| {
            if with_rock {
                t.add_boulder(rock)
            }
        });
        let none = idle_until(&mut world, Time::from_secs_f64(3.0));
        assert!(
            !none.iter().any(|(_, m)| matches!(m, Message::Image(_))),
            "rendered unasked"
        );
        world.set_camera_wanted(realms_core::RoverId(1), true);
        let out = idle_until(&mut world, Time::from_secs_f64(5.0));
        let images: Vec<_> = out
            .into_iter()
            .filter_map(|(_, m)| match m {
                Message::Image(img) => Some(img),
                _ => None,
            })
            .collect();
        assert_eq!(images.len(), 2, "1 Hz for 2 s");
        images.into_iter().next().expect("two images")
    };
    let (plain, rocky) = (image(false), image(true));
    assert_eq!(plain.data.len(), (plain.width * plain.height) as usize);
    assert!(
        plain.data[..plain.width as usize].iter().all(|p| *p == 0),
        "the sky is black"
    );
    let lit = plain.data.iter().filter(|p| **p > 60).count();
    assert!(lit > plain.data.len() / 4, "lit floor pixels: {lit}");
    // The rock's shadow falls to its right: floor that was lit without the rock goes dark.
    let shadowed = plain
        .data
        .iter()
        .zip(&rocky.data)
        .filter(|(before, after)| **before > 60 && **after < 15)
        .count();
    assert!(shadowed > 100, "shadowed floor pixels: {shadowed}");
}

#[test]
fn the_shadow_map_agrees_with_shadow_rays_over_the_default_arena() {
    // The camera reads its shadows from a map of the terrain worked out once; before, each
    // pixel cast a ray towards the sun. Over the default arena's rocks, craters and walls,
    // from random points of the ground the sun faces, both must give the same verdict but at
    // a shadow's very edge, under the default low sun and others.
    use rand::{Rng, SeedableRng};
    use realms_sim::sensors::shadows::SunShadows;
    let mut s = scenario(1);
    let world = World::new(&s);
    let (terrain, pyramid) = (world.terrain(), world.pyramid());
    let g = *terrain.heights.geometry();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    for (elevation_deg, azimuth_deg) in [
        (s.sun.elevation_deg, s.sun.azimuth_deg),
        (20.0, 90.0),
        (35.0, 200.0),
        (5.0, 315.0),
    ] {
        s.sun.elevation_deg = elevation_deg;
        s.sun.azimuth_deg = azimuth_deg;
        let shadows = SunShadows::new(&terrain.heights, &s.sun);
        let (se, ce) = elevation_deg.to_radians().sin_cos();
        let (sa, ca) = azimuth_deg.to_radians().sin_cos();
        let to_sun = [ce * ca, ce * sa, se];
        let (mut checked, mut agree, mut shaded, mut shaded_agree) = (0, 0, 0, 0);
        while checked < 20_000 {
            let c = realms_core::Cell {
                x: rng.random_range(0..g.width),
                y: rng.random_range(0..g.height),
            };
            let n = terrain.surface_normal(c.x, c.y);
            if n[0] * to_sun[0] + n[1] * to_sun[1] + n[2] * to_sun[2] <= 0.0 {
                continue;
            }
            // Anywhere on the cell's top, started off it as the camera starts.
            let centre = g.cell_center(c);
            let top = terrain.heights.cells()[g.index(c)] as f64;
            let (dx, dy) = (rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5));
            let start = [
                centre.x_m + dx * g.resolution_m + 0.03 * to_sun[0],
                centre.y_m + dy * g.resolution_m + 0.03 * to_sun[1],
                top + 0.03 * to_sun[2] + 0.005,
            ];
            let by_ray = pyramid.cast(start, to_sun, 0.0, 40.0).is_none();
            let by_map = shadows.lit(start);
            checked += 1;
            agree += usize::from(by_map == by_ray);
            shaded += usize::from(!by_ray);
            shaded_agree += usize::from(!by_ray && !by_map);
        }
        let share = agree as f64 / checked as f64;
        let shaded_share = shaded_agree as f64 / shaded as f64;
        assert!(
            share >= 0.98 && shaded_share >= 0.95,
            "sun {elevation_deg} deg up at {azimuth_deg} deg: {:.2} % agree, {:.2} % of the {shaded} points the rays shade",
            100.0 * share,
            100.0 * shaded_share
        );
        // Shadows there are, under every sun tried.
        assert!(
            shaded > checked / 100,
            "sun {elevation_deg} deg: {shaded} shaded"
        );
    }
}

mod exactness {
    use super::*;
    use proptest::prelude::*;
    use realms_sim::sensors::Frame3;
    use realms_sim::sensors::depth::{BODY_FROM_OPTICAL, Intrinsics, cast_image};

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// Every pixel of the column-coherent image caster equals an independent cast of that
        /// pixel's ray, on rocky ground, with the camera rolled and pitched.
        #[test]
        fn image_casting_equals_per_pixel_casting(
            seed in 0u64..500, x in 6.0..14.0f64, y in 6.0..14.0f64, yaw in -3.1..3.1f64,
            roll in -0.12..0.12f64, pitch in -0.12..0.12f64,
        ) {
            let mut s = scenario(1);
            s.seed = seed;
            let world = flat_world(&s, &[Pose2::new(x, y, yaw)], |t| {
                for i in 0..60u64 {
                    let h = |k: u64| ((seed * 7919 + i * 104_729 + k * 31) % 1000) as f64 / 1000.0;
                    t.add_boulder(Boulder {
                        center: Point2::new(1.0 + 18.0 * h(1), 1.0 + 18.0 * h(2)),
                        radius_m: 0.05 + 0.3 * h(3),
                        height_m: 0.05 + 0.5 * h(4),
                    });
                }
            });
            let base = Frame3::from_rpy([x, y, 0.0], roll, pitch, yaw);
            let optical = base.compose(&Frame3::from_rpy([0.2, 0.0, 0.25], 0.0, 15f64.to_radians(), 0.0))
                .compose(&Frame3 { origin: [0.0; 3], rot: BODY_FROM_OPTICAL });
            let k = Intrinsics::from_fov(106, 60, 87.0, 58.0);
            let mut mismatches = Vec::new();
            cast_image(world.pyramid(), &optical, &k, 106, 60, 6.0, |u, v, r, hit| {
                let dir = optical.rotate(r);
                let reference = world.pyramid().cast(optical.origin, dir, 0.0, 6.0);
                let same = match (hit, reference) {
                    (Some(a), Some(b)) => (a - b).abs() < 1e-9,
                    (a, b) => a == b,
                };
                if !same {
                    mismatches.push((u, v, hit, reference));
                }
            });
            prop_assert!(mismatches.is_empty(), "{} pixels differ, e.g. {:?}", mismatches.len(), &mismatches[..mismatches.len().min(3)]);
        }
    }
}

/// A head turning slower than once a second is no sweep a receiver takes for one, so such a
/// lidar measures at once and says so, rather than spreading beams over times its scan's
/// stamp and `time_increment_s` would not tell apart.
#[test]
fn a_lidar_turning_slower_than_once_a_second_measures_at_once() {
    let mut s = noiseless_lidar();
    s.rovers.lidar.sweeps = true;
    s.rovers.lidar.rate_hz = 0.5;
    let mut world = flat_world(&s, &[Pose2::new(5.0, 10.0, 0.0)], |_| {});
    let scan = first_scan(&idle_until(&mut world, Time::from_secs_f64(2.5)));
    assert_eq!(scan.time_increment_s, 0.0);
    assert_eq!(scan.sweep(), Duration::ZERO);
    let step = Duration::from_secs_f64(s.rovers.physics_step_s);
    assert_eq!(
        scan.header.stamp.as_ns() % step.as_ns(),
        0,
        "a physics step's state"
    );
}

/// Kept for a benchmark, each sweep's twin is taken at once from the pose of its last beam
/// with the same noise: on a rover standing still the two are the same scan, on one turning
/// they are not.
#[test]
fn each_sweep_keeps_a_twin_taken_at_once_from_its_last_beam() {
    let mut s = scenario(1);
    s.rovers.lidar.sweeps = true;
    let mut world = flat_world(&s, &[Pose2::new(5.0, 10.0, 0.0)], |_| {});
    world.keep_lidar_twins();
    let standing = idle_until(&mut world, Time::from_secs_f64(1.0));
    let turning = common::drive(&mut world, RoverId(1), 0.0, 1.0, 2.0);
    let twins = world.take_lidar_twins();
    assert_eq!(twins.len(), 1);
    let scans: Vec<&LaserScan> = standing
        .iter()
        .chain(&turning)
        .filter_map(|(_, m)| match m {
            Message::LaserScan(s) => Some(s),
            _ => None,
        })
        .collect();
    assert_eq!(twins[0].len(), scans.len(), "one twin per sweep");
    let mut differing = 0;
    for (scan, twin) in scans.iter().zip(&twins[0]) {
        assert_eq!(twin.header.stamp, scan.last_beam_time());
        assert_eq!(twin.sweep(), Duration::ZERO);
        if scan.header.stamp < Time::from_secs_f64(0.9) {
            assert_eq!(
                twin.ranges_m, scan.ranges_m,
                "standing still at {:?}",
                scan.header.stamp
            );
        } else if twin.ranges_m != scan.ranges_m {
            differing += 1;
        }
    }
    assert!(
        differing >= 15,
        "{differing} turning sweeps differ from their twins"
    );
    assert!(world.take_lidar_twins()[0].is_empty(), "taken once");
}

#[test]
fn a_still_rover_measured_on_its_last_cast_reads_what_a_fresh_cast_gives() {
    // Rover 1 stands, drives, turns, and stands again; rover 2 stands throughout. With the
    // casts of a rover that has not moved reused and without, every message is the same
    // to the byte: the same true ranges, the same noise drawn on them in the same order.
    let run = |reuse: bool| {
        let s = scenario(2);
        let mut world = flat_world(
            &s,
            &[Pose2::new(5.0, 10.0, 0.3), Pose2::new(14.0, 6.0, 2.0)],
            |t| {
                t.add_boulder(Boulder {
                    center: Point2::new(9.0, 11.0),
                    radius_m: 0.4,
                    height_m: 0.3,
                })
            },
        );
        world.reuse_still_casts(reuse);
        let mut out = idle_until(&mut world, Time::from_secs_f64(2.0));
        out.extend(common::drive(&mut world, RoverId(1), 0.3, 0.0, 2.0));
        out.extend(common::drive(&mut world, RoverId(1), 0.0, 0.8, 1.0));
        out.extend(common::drive(&mut world, RoverId(1), 0.0, 0.0, 3.0));
        let bytes: Vec<(String, Vec<u8>)> = out
            .iter()
            .map(|(topic, m)| (topic.to_string(), realms_core::codec::encode(m)))
            .collect();
        (bytes, world.still_casts())
    };
    let (reused, still) = run(true);
    let (cast, still_too) = run(false);
    assert_eq!(still, still_too);
    // Rover 2's eight seconds and rover 1's standing stretches: most of the 96 scans and 16
    // frames a rover takes in that time were taken where the one before was.
    assert!(still > 100, "{still} casts from where the last one was");
    let kinds = |b: &[(String, Vec<u8>)], suffix: &str| {
        b.iter().filter(|(t, _)| t.ends_with(suffix)).count()
    };
    assert!(kinds(&reused, "/scan") > 150 && kinds(&reused, "/depth/points") > 25);
    assert_eq!(reused.len(), cast.len());
    for (i, (a, b)) in reused.iter().zip(&cast).enumerate() {
        assert!(a == b, "message {i} on {} differs", a.0);
    }
}
