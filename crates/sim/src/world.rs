//! The simulated world: terrain, ground truth and rovers on one integer-nanosecond clock.
//!
//! A discrete-event loop: physics steps at a fixed rate, every sensor of every rover fires at
//! its own rate (phases staggered so rovers do not all fire at once), and scheduled faults
//! start and end. Sensor data leaves as `(topic, message)` pairs for the message bus; velocity
//! commands come in through [`World::command`]. Nothing here reads a clock.

use crate::raycast::HeightPyramid;
use crate::rng::{Purpose, SimRng, Streams};
use crate::rover::{RoverBody, StepOutcome};
use crate::scenario::{FaultKind, Scenario, SensorKind};
use crate::scheduler::Scheduler;
use crate::sensors::depth::BODY_FROM_OPTICAL;
use crate::sensors::lidar::SweepSegment;
use crate::sensors::shadows::SunShadows;
use crate::sensors::{Frame3, LastCast, camera, depth, lidar, proprio};
use crate::terrain::Terrain;
use crate::truth::GroundTruth;
use realms_core::geometry::normalize_angle_rad;
use realms_core::msgs::{LaserScan, Message, TwistStamped, beam_offset};
use realms_core::{Duration, RoverId, Time, Topic};
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::sync::OnceLock;

/// Something notable that happened in the world.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SimEvent {
    /// When, mission seconds.
    pub t_s: f64,
    /// What.
    pub kind: SimEventKind,
    /// To which rover.
    pub rover: String,
}

/// Kinds of world event (the `kind` of a `mission.json` event).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SimEventKind {
    /// A rover ran into an obstacle.
    Collision,
    /// A rover's centre entered a hazard cell.
    HazardEntry,
    /// A rover is trapped.
    Stuck,
    /// A rover shut down.
    PowerOff,
    /// A rover's wheels lost grip.
    SlipBurstStart,
    /// Grip came back.
    SlipBurstEnd,
    /// A sensor stopped publishing.
    SensorDropoutStart,
    /// It publishes again.
    SensorDropoutEnd,
}

#[derive(Clone, Copy, Debug)]
enum Due {
    Physics,
    Sensor(usize, SensorKind),
    FaultStart(usize),
    FaultEnd(usize),
}

#[derive(Debug)]
struct RoverSlot {
    body: RoverBody,
    lidar_rng: SimRng,
    depth_rng: SimRng,
    motion_rng: SimRng,
    gyro_rng: SimRng,
    /// When the IMU last sampled and the body's speed then (for its acceleration since).
    imu_speed_mark: Option<(Time, f64)>,
    /// When the IMU last sampled and the body's roll and pitch then (for their rates since).
    imu_tilt_mark: Option<(Time, f64, f64)>,
    camera_wanted: bool,
    dropped: BTreeMap<SensorKind, u32>,
    /// `world_from_lidar` and the heading at each physics step of the last scan's length,
    /// oldest first, for a sweeping lidar's beams (each from where the rover was at its time).
    lidar_frames: VecDeque<(Time, Frame3, f64)>,
    /// The last scan's true ranges and the segments they were cast from.
    lidar_cast: LastCast<Vec<SweepSegment>, Vec<Option<f64>>>,
    /// The last depth frame's true depths and the frame they were cast from.
    depth_cast: LastCast<Frame3, Vec<Option<f64>>>,
}

/// The whole simulated world.
#[derive(Debug)]
pub struct World {
    scenario: Scenario,
    terrain: Terrain,
    truth: GroundTruth,
    pyramid: HeightPyramid,
    /// Where the sun's shadows fall, worked out when a camera is first rendered.
    shadows: OnceLock<SunShadows>,
    rovers: Vec<RoverSlot>,
    queue: Scheduler<Due>,
    now: Time,
    /// The time of the world's state: the latest physics step's.
    state_time: Time,
    events: Vec<SimEvent>,
    physics_dt: Duration,
    /// Each rover's sweeping scans taken again at once, once asked for
    /// ([`World::keep_lidar_twins`]).
    lidar_twins: Option<Vec<Vec<LaserScan>>>,
    /// A still rover's scans and depth frames are measured on its last cast (`LastCast`).
    reuse_casts: bool,
}

impl World {
    /// Generates the scenario's arena and puts its rovers at their starts.
    pub fn new(scenario: &Scenario) -> World {
        World::with_terrain(scenario, Terrain::generate(scenario))
    }

    /// A world on a given terrain (hand-built test worlds); rovers start at
    /// `terrain.rover_starts`, one per start up to the scenario's rover count.
    pub fn with_terrain(scenario: &Scenario, terrain: Terrain) -> World {
        let truth = GroundTruth::derive(&terrain, scenario);
        let pyramid = HeightPyramid::new(&terrain.heights);
        let streams = Streams::new(scenario.seed);
        let spec = &scenario.rovers;
        let rovers: Vec<RoverSlot> = terrain
            .rover_starts
            .iter()
            .take(spec.count as usize)
            .enumerate()
            .map(|(i, start)| {
                let n = (i + 1) as u8;
                let mut motion_rng = streams.rng(Purpose::Odometry(n));
                RoverSlot {
                    body: RoverBody::new(RoverId(n), *start, spec, &terrain, &mut motion_rng),
                    lidar_rng: streams.rng(Purpose::Lidar(n)),
                    depth_rng: streams.rng(Purpose::Depth(n)),
                    motion_rng,
                    gyro_rng: streams.rng(Purpose::Gyro(n)),
                    imu_speed_mark: None,
                    imu_tilt_mark: None,
                    camera_wanted: false,
                    dropped: BTreeMap::new(),
                    lidar_frames: VecDeque::new(),
                    lidar_cast: LastCast::default(),
                    depth_cast: LastCast::default(),
                }
            })
            .collect();
        let mut queue = Scheduler::new();
        let physics_dt = Duration::from_secs_f64(spec.physics_step_s);
        // The step at time t integrates (t - dt, t], so the state at t is the state of time t;
        // it runs before the sensors due at t, which must see that state.
        queue.push_first(Time::ZERO + physics_dt, Due::Physics);
        for i in 0..rovers.len() {
            // Stagger phases so the fleet's sensors do not all fire on the same nanosecond. A
            // sensor firing between physics steps sees the state of the latest step, and its
            // message is stamped with that step's time: like a real sensor's latency, and
            // every stamp is the time of what it shows.
            let phase = |ms: i64| Time::ZERO + Duration::from_millis(ms * i as i64);
            queue.push(phase(7), Due::Sensor(i, SensorKind::Lidar));
            queue.push(
                phase(11) + Duration::from_millis(50),
                Due::Sensor(i, SensorKind::Depth),
            );
            queue.push(
                phase(13) + Duration::from_millis(20),
                Due::Sensor(i, SensorKind::Camera),
            );
            queue.push(phase(3), Due::Sensor(i, SensorKind::Odometry));
            queue.push(phase(1), Due::Sensor(i, SensorKind::Imu));
        }
        for (k, f) in scenario.faults.iter().enumerate() {
            queue.push(Time::from_secs_f64(f.at_s), Due::FaultStart(k));
            if f.kind != FaultKind::PowerOff {
                queue.push(Time::from_secs_f64(f.at_s + f.duration_s), Due::FaultEnd(k));
            }
        }
        let mut world = World {
            physics_dt,
            scenario: scenario.clone(),
            terrain,
            truth,
            pyramid,
            shadows: OnceLock::new(),
            rovers,
            queue,
            now: Time::ZERO,
            state_time: Time::ZERO,
            events: Vec::new(),
            lidar_twins: None,
            reuse_casts: true,
        };
        world.keep_lidar_frames(Time::ZERO);
        world
    }

    /// Swaps the accelerated ray caster for plain cell-by-cell marching (same results,
    /// slower): the baseline `realms bench sim` measures against in the same run.
    pub fn use_plain_ray_casting(&mut self) {
        self.pyramid = HeightPyramid::with_max_level(&self.terrain.heights, 0);
        for slot in &mut self.rovers {
            slot.lidar_cast.clear();
            slot.depth_cast.clear();
        }
    }

    /// Whether a rover that has not moved since its last scan or depth frame is measured on
    /// that one's true ranges (the default) or cast again to the same answers: the sensors'
    /// own cost is measured with every frame cast (`realms bench sim`).
    pub fn reuse_still_casts(&mut self, reuse: bool) {
        self.reuse_casts = reuse;
    }

    /// How many lidar scans and depth frames were taken from where the one before was (and
    /// measured on its true ranges, unless [`World::reuse_still_casts`] said not to).
    pub fn still_casts(&self) -> u64 {
        self.rovers
            .iter()
            .map(|s| s.lidar_cast.repeats() + s.depth_cast.repeats())
            .sum()
    }

    /// The scenario this world runs.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The terrain.
    pub fn terrain(&self) -> &Terrain {
        &self.terrain
    }

    /// Ground truth.
    pub fn truth(&self) -> &GroundTruth {
        &self.truth
    }

    /// The height pyramid the sensors cast against.
    pub fn pyramid(&self) -> &HeightPyramid {
        &self.pyramid
    }

    /// The time of the last processed event.
    pub fn now(&self) -> Time {
        self.now
    }

    /// The rovers' physical state, rover 1 first.
    pub fn rovers(&self) -> impl Iterator<Item = &RoverBody> {
        self.rovers.iter().map(|s| &s.body)
    }

    /// Everything notable so far.
    pub fn events(&self) -> &[SimEvent] {
        &self.events
    }

    /// When the next world event is due.
    pub fn next_due(&self) -> Option<Time> {
        self.queue.peek_time()
    }

    /// Hands a velocity command to a rover's driver. Like a real driver it ignores commands
    /// it cannot execute: to an unknown rover, with non-finite values, or stamped in the
    /// future (which would never go stale and would defeat the dead-man timeout). Returns
    /// whether the command was accepted.
    pub fn command(&mut self, rover: RoverId, cmd: TwistStamped) -> bool {
        let t = &cmd.twist;
        let finite = [
            t.linear.x,
            t.linear.y,
            t.linear.z,
            t.angular.x,
            t.angular.y,
            t.angular.z,
        ]
        .iter()
        .all(|v| v.is_finite());
        let now = self.now;
        match self.slot_mut(rover) {
            Some(slot) if finite && cmd.header.stamp <= now => {
                slot.body.command = Some(cmd);
                true
            }
            _ => false,
        }
    }

    /// Whether anyone wants a rover's camera images (they are rendered only then).
    pub fn set_camera_wanted(&mut self, rover: RoverId, wanted: bool) {
        if let Some(slot) = self.slot_mut(rover) {
            slot.camera_wanted = wanted;
        }
    }

    fn slot_mut(&mut self, rover: RoverId) -> Option<&mut RoverSlot> {
        self.rovers.iter_mut().find(|s| s.body.id == rover)
    }

    /// Processes every event due at or before `until`, appending published sensor messages.
    pub fn advance_to(&mut self, until: Time, out: &mut Vec<(Topic, Message)>) {
        while let Some((t, due)) = self.queue.pop_due(until) {
            self.now = t;
            match due {
                Due::Physics => {
                    self.physics(t);
                    self.state_time = t;
                    self.keep_lidar_frames(t);
                    self.queue.push_first(t + self.physics_dt, Due::Physics);
                }
                Due::Sensor(i, kind) => {
                    let spec = &self.scenario.rovers;
                    let period = Duration::from_rate_hz(match kind {
                        SensorKind::Lidar => spec.lidar.rate_hz,
                        SensorKind::Depth => spec.depth.rate_hz,
                        SensorKind::Camera => spec.camera.rate_hz,
                        SensorKind::Odometry => spec.odometry.rate_hz,
                        SensorKind::Imu => spec.imu.rate_hz,
                    });
                    if let Some(msg) = self.sense(i, kind, self.state_time) {
                        out.push(msg);
                    }
                    self.queue.push(t + period, Due::Sensor(i, kind));
                }
                Due::FaultStart(k) => self.fault(k, t, true),
                Due::FaultEnd(k) => self.fault(k, t, false),
            }
        }
        self.now = self.now.max(until);
    }

    /// From now on, every sweeping scan is also taken at once from the pose of its last beam,
    /// with the same noise, and kept ([`World::take_lidar_twins`]); nothing is published for
    /// it. Two replays of a rover's SLAM, one on its sweeps and one on their twins, then
    /// compare the two lidars on one path (`realms bench slam --lidar-twins`), where two
    /// missions, one with each, part ways at the first decision they take differently.
    pub fn keep_lidar_twins(&mut self) {
        self.lidar_twins = Some(vec![Vec::new(); self.rovers.len()]);
    }

    /// Each rover's twins kept so far, in the order of their sweeps (empty without
    /// [`World::keep_lidar_twins`], or while the lidar does not sweep).
    pub fn take_lidar_twins(&mut self) -> Vec<Vec<LaserScan>> {
        match &mut self.lidar_twins {
            None => vec![Vec::new(); self.rovers.len()],
            Some(twins) => twins.iter_mut().map(std::mem::take).collect(),
        }
    }

    /// Records each rover's `world_from_lidar` at the state of time `t`, and forgets those
    /// no beam of a scan due from now on can need.
    fn keep_lidar_frames(&mut self, t: Time) {
        let Some(sweep) = lidar::sweep_length(&self.scenario.rovers.lidar) else {
            return;
        };
        let base_from_lidar = self.base_from_lidar();
        let oldest_needed = t - sweep - self.physics_dt;
        for slot in &mut self.rovers {
            let frame = World::world_from_base(&slot.body).compose(&base_from_lidar);
            let frames = &mut slot.lidar_frames;
            frames.push_back((t, frame, slot.body.pose.yaw_rad));
            while frames.len() >= 2 && frames[1].0 <= oldest_needed {
                frames.pop_front();
            }
        }
    }

    fn physics(&mut self, t: Time) {
        let dt = self.physics_dt.as_secs_f64();
        let spec = &self.scenario.rovers;
        for slot in &mut self.rovers {
            let outcomes = slot.body.step(
                spec,
                &self.terrain,
                &self.truth,
                t,
                dt,
                &mut slot.motion_rng,
            );
            for o in outcomes {
                let kind = match o {
                    StepOutcome::Moved => continue,
                    StepOutcome::Collided => SimEventKind::Collision,
                    StepOutcome::EnteredHazard => SimEventKind::HazardEntry,
                    StepOutcome::GotStuck => SimEventKind::Stuck,
                };
                self.events.push(SimEvent {
                    t_s: t.as_secs_f64(),
                    kind,
                    rover: slot.body.id.to_string(),
                });
            }
        }
    }

    /// `world_from_base`: the rover's base frame on the ground, tilted with the terrain.
    pub fn world_from_base(body: &RoverBody) -> Frame3 {
        Frame3::from_rpy(
            [body.pose.x_m, body.pose.y_m, body.z_m],
            body.roll_rad,
            body.pitch_rad,
            body.pose.yaw_rad,
        )
    }

    /// `base_from_lidar` for this scenario's rovers.
    pub fn base_from_lidar(&self) -> Frame3 {
        let l = &self.scenario.rovers.lidar;
        Frame3::from_rpy([l.mount_x_m, 0.0, l.mount_height_m], 0.0, 0.0, 0.0)
    }

    /// `base_from_optical` of the depth camera (the grayscale camera shares its mount).
    pub fn base_from_optical(&self) -> Frame3 {
        let d = &self.scenario.rovers.depth;
        let body = Frame3::from_rpy(
            [d.mount_x_m, 0.0, d.mount_height_m],
            0.0,
            d.tilt_down_deg.to_radians(),
            0.0,
        );
        body.compose(&Frame3 {
            origin: [0.0; 3],
            rot: BODY_FROM_OPTICAL,
        })
    }

    fn sense(&mut self, i: usize, kind: SensorKind, t: Time) -> Option<(Topic, Message)> {
        let base_from_lidar = self.base_from_lidar();
        let base_from_optical = self.base_from_optical();
        let spec = &self.scenario.rovers;
        let slot = &mut self.rovers[i];
        if !slot.body.powered || slot.dropped.get(&kind).is_some_and(|n| *n > 0) {
            return None;
        }
        let id = slot.body.id;
        let ns = id.namespace();
        let world_from_base = World::world_from_base(&slot.body);
        Some(match kind {
            SensorKind::Lidar => {
                let pose = world_from_base.compose(&base_from_lidar);
                let frame = format!("{ns}/laser");
                let sweeping = lidar::sweep_length(&spec.lidar);
                let (stamp, segments) = if let Some(sweep) = sweeping {
                    // The last beam is measured now, the first a sweep earlier; each from
                    // where the rover was at its own time.
                    let stamp = t - sweep;
                    if let Some(twins) = &mut self.lidar_twins {
                        let mut same_noise = slot.lidar_rng.clone();
                        twins[i].push(lidar::scan(
                            &self.pyramid,
                            &pose,
                            &spec.lidar,
                            &mut same_noise,
                            t,
                            &frame,
                        ));
                    }
                    let segments = sweep_segments(
                        &slot.lidar_frames,
                        pose,
                        stamp,
                        spec.lidar.beams as usize,
                        lidar::time_increment_s(&spec.lidar),
                    );
                    (stamp, segments)
                } else {
                    (t, vec![SweepSegment::still(0, pose)])
                };
                let pyramid = &self.pyramid;
                let hits = slot
                    .lidar_cast
                    .get_or_cast(segments, self.reuse_casts, |segments| {
                        lidar::cast_hits(pyramid, segments, &spec.lidar)
                    });
                let scan = lidar::measured(
                    &spec.lidar,
                    hits,
                    sweeping.is_some(),
                    &mut slot.lidar_rng,
                    stamp,
                    &frame,
                );
                (id.topic("scan"), Message::LaserScan(scan))
            }
            SensorKind::Depth => {
                let pose = world_from_base.compose(&base_from_optical);
                let frame = format!("{ns}/depth_optical");
                let pyramid = &self.pyramid;
                let depths = slot.depth_cast.get_or_cast(pose, self.reuse_casts, |pose| {
                    depth::cast_depths(pyramid, pose, &spec.depth)
                });
                let cloud = depth::measured(&spec.depth, depths, &mut slot.depth_rng, t, &frame);
                (id.topic("depth/points"), Message::PointCloud(cloud))
            }
            SensorKind::Camera => {
                if !slot.camera_wanted {
                    return None;
                }
                let pose = world_from_base.compose(&base_from_optical);
                let frame = format!("{ns}/camera_optical");
                let shadows = self
                    .shadows
                    .get_or_init(|| SunShadows::new(&self.terrain.heights, &self.scenario.sun));
                let image = camera::render(
                    &self.pyramid,
                    &self.terrain,
                    shadows,
                    &pose,
                    &spec.camera,
                    t,
                    &frame,
                );
                (id.topic("camera/image"), Message::Image(image))
            }
            SensorKind::Odometry => (
                id.topic("odom"),
                Message::Odometry(Box::new(proprio::odometry(&slot.body, spec, t))),
            ),
            SensorKind::Imu => {
                let body = &slot.body;
                let felt = spec.imu.body_acceleration.then(|| {
                    // The speed's change since the last sample, as an accelerometer averages
                    // it over its sample; the first sample has nothing to compare with.
                    let along = match slot.imu_speed_mark.replace((t, body.speed_m_s)) {
                        Some((t0, v0)) if t > t0 => {
                            (body.speed_m_s - v0) / t.since(t0).as_secs_f64()
                        }
                        _ => 0.0,
                    };
                    (along, body.speed_m_s * body.yaw_rate_rad_s)
                });
                let tilt_rates = spec.imu.tilt_rates.then(|| {
                    let now = (t, body.roll_rad, body.pitch_rad);
                    match slot.imu_tilt_mark.replace(now) {
                        Some((t0, roll0, pitch0)) if t > t0 => {
                            let dt = t.since(t0).as_secs_f64();
                            ((body.roll_rad - roll0) / dt, (body.pitch_rad - pitch0) / dt)
                        }
                        _ => (0.0, 0.0),
                    }
                });
                (
                    id.topic("imu"),
                    Message::Imu(Box::new(proprio::imu(
                        body,
                        spec,
                        &mut slot.gyro_rng,
                        t,
                        felt,
                        tilt_rates,
                    ))),
                )
            }
        })
    }

    fn fault(&mut self, k: usize, t: Time, starting: bool) {
        let fault = self.scenario.faults[k].clone();
        let Some(id) = RoverId::parse(&fault.rover) else {
            return; // validated at load; a hand-built scenario may still name nobody
        };
        let end = Time::from_secs_f64(fault.at_s + fault.duration_s);
        let Some(slot) = self.slot_mut(id) else {
            return;
        };
        let kind = match (fault.kind, starting) {
            (FaultKind::PowerOff, _) => {
                slot.body.powered = false;
                SimEventKind::PowerOff
            }
            (FaultKind::SlipBurst, true) => {
                // Overlapping bursts: the later end wins.
                let until = slot.body.slip_burst_until.map_or(end, |u| u.max(end));
                slot.body.slip_burst_until = Some(until);
                SimEventKind::SlipBurstStart
            }
            (FaultKind::SlipBurst, false) => SimEventKind::SlipBurstEnd,
            (FaultKind::SensorDropout, start) => {
                let sensor = fault.sensor.unwrap_or(SensorKind::Lidar);
                let n = slot.dropped.entry(sensor).or_insert(0);
                if start {
                    *n += 1;
                    SimEventKind::SensorDropoutStart
                } else {
                    *n = n.saturating_sub(1);
                    SimEventKind::SensorDropoutEnd
                }
            }
        };
        self.events.push(SimEvent {
            t_s: t.as_secs_f64(),
            kind,
            rover: id.to_string(),
        });
    }
}

/// The segments a sweep's beams are cast from ([`lidar::sweep`]): beam `i`, measured at
/// `stamp + i * increment`, from where the lidar was then, between the two states of
/// `history` around that time. Between two physics steps the rover turned at a steady rate
/// along a short arc, so its heading is interpolated and its position taken on the chord
/// (under a micrometre off the arc at the rovers' speeds); its pitch and roll are those of
/// the earlier step, as every other sensor sees them. Beams before the oldest state are
/// measured from it, and with no history at all, every beam from `now`.
fn sweep_segments(
    history: &VecDeque<(Time, Frame3, f64)>,
    now: Frame3,
    stamp: Time,
    beams: usize,
    increment_s: f32,
) -> Vec<lidar::SweepSegment> {
    let beam_time = |i: usize| stamp + beam_offset(i, increment_s);
    let Some(&(_, oldest, _)) = history.front() else {
        return vec![lidar::SweepSegment::still(0, now)];
    };
    let mut segments = Vec::new();
    // The state at or before beam i's time: history[k].
    let mut k: Option<usize> = None;
    for i in 0..beams {
        let at = beam_time(i);
        let mut next = k.map_or(0, |k| k + 1);
        while next < history.len() && history[next].0 <= at {
            next += 1;
        }
        let state = next.checked_sub(1);
        if i > 0 && state == k {
            continue;
        }
        k = state;
        segments.push(match state {
            None => lidar::SweepSegment::still(i, oldest),
            Some(j) if j + 1 == history.len() => lidar::SweepSegment::still(i, history[j].1),
            Some(j) => {
                let ((t0, f0, yaw0), (t1, f1, yaw1)) = (history[j], history[j + 1]);
                let span = (t1 - t0).as_secs_f64();
                let yaw_rate = normalize_angle_rad(yaw1 - yaw0) / span;
                let velocity = [0, 1, 2].map(|a| (f1.origin[a] - f0.origin[a]) / span);
                let since = (at - t0).as_secs_f64();
                lidar::SweepSegment {
                    first_beam: i,
                    frame: Frame3 {
                        origin: [0, 1, 2].map(|a| f0.origin[a] + velocity[a] * since),
                        ..f0.turned_about_vertical((yaw_rate * since).sin_cos())
                    },
                    origin_step_m: velocity.map(|v| v * increment_s as f64),
                    yaw_step_rad: yaw_rate * increment_s as f64,
                }
            }
        });
    }
    segments
}
