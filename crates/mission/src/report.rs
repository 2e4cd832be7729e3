//! The results folder of a mission and `mission.json`, its stable contract (documented in
//! `docs/mission-json.md`; later issues add fields, never change or remove them).

use crate::Mission;
use crate::slam_record::{RoverSlamSummary, map_grid};
use realms_core::map_server::{self, Trinary};
use realms_core::msgs::OccupancyGrid;
use realms_merge::MapCell;
use realms_node::lander_merge::MergedMap;
use realms_sim::SimEvent;
use realms_sim::render;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Schema identifier written into every `mission.json`.
pub const SCHEMA: &str = "realms.mission/1";

/// The behaviour driving the rovers.
pub const BEHAVIOUR: &str = "autonomous frontier exploration (realms-nav)";

/// `mission.json`.
#[derive(Clone, Debug, Serialize)]
pub struct MissionReport {
    /// Schema identifier.
    pub schema: &'static str,
    /// Version of realms that ran the mission.
    pub realms_version: &'static str,
    /// Where the scenario came from: a file path, or `default`.
    pub scenario: String,
    /// The seed.
    pub seed: u64,
    /// Simulated mission time, seconds.
    pub sim_duration_s: f64,
    /// Wall-clock time the run took, seconds (varies run to run).
    pub wall_s: f64,
    /// Simulated seconds per wall second (varies run to run).
    pub speedup: f64,
    /// Wall time every rover's SLAM took, summed, seconds (varies run to run).
    pub slam_wall_s: f64,
    /// Simulated seconds per second of the fleet's SLAM: how much faster than real time one
    /// core runs SLAM for every rover (varies run to run).
    pub slam_speedup: f64,
    /// What drove the rovers.
    pub behaviour: &'static str,
    /// The arena.
    pub arena: ArenaSummary,
    /// Per rover.
    pub rovers: Vec<RoverSummary>,
    /// Collision episodes, all rovers.
    pub collisions: u32,
    /// Hazard-cell entries, all rovers.
    pub hazard_entries: u32,
    /// Stuck events, all rovers.
    pub stuck_events: u32,
    /// Final fraction of the explorable area that some rover's map knows.
    pub coverage: f64,
    /// `[t_s, fraction]` each time a map arrived.
    pub coverage_series: Vec<[f64; 2]>,
    /// When coverage first reached 90 %, seconds (absent if it did not).
    pub time_to_90_s: Option<f64>,
    /// When coverage first reached 95 %, seconds (absent if it did not).
    pub time_to_95_s: Option<f64>,
    /// Whether every rover finished exploring (and returned home, or gave up getting there)
    /// before the time was up.
    pub exploration_complete: bool,
    /// Everything notable, in time order.
    pub events: Vec<SimEvent>,
    /// Messages published per topic.
    pub messages: BTreeMap<String, u64>,
    /// The network: traffic per rover and node, map updates against full grids, the
    /// ground's map lag, drops.
    pub network: crate::netreport::NetworkSummary,
    /// The lander's merge of the rovers' maps (absent if fewer than two maps reached it).
    pub merge: Option<MergeSummary>,
    /// The other files in the folder.
    pub files: BTreeMap<&'static str, &'static str>,
}

/// What the arena held.
#[derive(Clone, Debug, Serialize)]
pub struct ArenaSummary {
    /// Extent along x, metres.
    pub width_m: f64,
    /// Extent along y, metres.
    pub length_m: f64,
    /// Heightfield cell, metres.
    pub resolution_m: f64,
    /// Ground-truth explorable area, square metres.
    pub explorable_area_m2: f64,
    /// Craters placed.
    pub craters: usize,
    /// Boulders placed.
    pub boulders: usize,
    /// Boulders a rover cannot drive over.
    pub blocking_boulders: usize,
    /// Resource targets placed.
    pub targets: usize,
}

/// One rover's mission.
#[derive(Clone, Debug, Serialize)]
pub struct RoverSummary {
    /// Namespace.
    pub name: String,
    /// Distance over ground, metres.
    pub distance_m: f64,
    /// Collision episodes.
    pub collisions: u32,
    /// Times stuck.
    pub stuck_events: u32,
    /// Hazard-cell entries.
    pub hazard_entries: u32,
    /// Still powered at the end.
    pub powered: bool,
    /// Stuck at the end.
    pub stuck: bool,
    /// Final true pose `[x_m, y_m, yaw_rad]`.
    pub final_pose: [f64; 3],
    /// What its SLAM achieved.
    pub slam: RoverSlamSummary,
}

/// Why the results could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Folder or file I/O.
    #[error("cannot write {path}")]
    Io {
        /// What.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// An image.
    #[error(transparent)]
    Image(#[from] realms_core::grid::GridExportError),
}

/// Rover colours in pictures, cycled.
pub const ROVER_COLORS: [[u8; 3]; 6] = [
    [230, 60, 50],
    [40, 160, 230],
    [60, 200, 80],
    [230, 140, 30],
    [180, 80, 220],
    [20, 200, 190],
];

impl MissionReport {
    /// Summarises a mission.
    pub fn new(mission: &Mission, scenario_source: &str, wall_s: f64) -> MissionReport {
        let world = mission.world();
        let s = world.scenario();
        let t = world.terrain();
        let rovers: Vec<RoverSummary> = world
            .rovers()
            .zip(mission.slam_records())
            .map(|(b, record)| RoverSummary {
                name: b.id.to_string(),
                distance_m: b.stats.distance_m,
                collisions: b.stats.collisions,
                stuck_events: b.stats.stuck_events,
                hazard_entries: b.stats.hazard_entries,
                powered: b.powered,
                stuck: b.stuck,
                final_pose: [b.pose.x_m, b.pose.y_m, b.pose.yaw_rad],
                slam: record.summary(
                    world.truth(),
                    record
                        .map
                        .as_ref()
                        .map(|_| map_stem(&b.id.to_string()) + ".png"),
                ),
            })
            .collect();
        let sim_duration_s = mission.now().as_secs_f64();
        let slam_wall_s = mission.slam_wall_s();
        let per_wall_s = |w: f64| if w > 0.0 { sim_duration_s / w } else { 0.0 };
        MissionReport {
            schema: SCHEMA,
            realms_version: env!("CARGO_PKG_VERSION"),
            scenario: scenario_source.to_string(),
            seed: s.seed,
            sim_duration_s,
            wall_s,
            speedup: per_wall_s(wall_s),
            slam_wall_s,
            slam_speedup: per_wall_s(slam_wall_s),
            behaviour: BEHAVIOUR,
            arena: ArenaSummary {
                width_m: s.arena.width_m,
                length_m: s.arena.length_m,
                resolution_m: s.arena.resolution_m,
                explorable_area_m2: world.truth().explorable_area_m2,
                craters: t.craters.len(),
                boulders: t.boulders.len(),
                blocking_boulders: t
                    .boulders
                    .iter()
                    .filter(|b| b.height_m > s.rovers.max_step_m)
                    .count(),
                targets: t.targets.len(),
            },
            collisions: rovers.iter().map(|r| r.collisions).sum(),
            hazard_entries: rovers.iter().map(|r| r.hazard_entries).sum(),
            stuck_events: rovers.iter().map(|r| r.stuck_events).sum(),
            coverage: mission.coverage().fraction(),
            coverage_series: mission
                .coverage()
                .series()
                .iter()
                .map(|(t, f)| [*t, *f])
                .collect(),
            time_to_90_s: mission.coverage().time_to(0.9),
            time_to_95_s: mission.coverage().time_to(0.95),
            exploration_complete: mission.exploration_over(),
            rovers,
            events: world.events().to_vec(),
            messages: mission
                .bus()
                .counts()
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
            network: crate::netreport::NetworkSummary::new(mission),
            merge: merge_summary(mission),
            files: {
                let mut files = BTreeMap::from([
                    ("truth", "truth.png"),
                    ("trajectories", "trajectories.png"),
                    ("trajectories_csv", "trajectories.csv"),
                    ("slam_csv", "slam.csv"),
                    ("coverage", "coverage.png"),
                ]);
                if mission.network().is_some() {
                    files.insert("network", "network.png");
                }
                if merged(mission).is_some() {
                    files.insert("merged_map", "merged_map.png");
                }
                files
            },
        }
    }
}

/// The lander's merged map, if it made one.
fn merged(mission: &Mission) -> Option<&MergedMap> {
    mission
        .station(realms_net::NodeAddr::Lander)
        .and_then(|s| s.merged())
}

/// `mission.json`'s `merge`.
#[derive(Clone, Debug, Serialize)]
pub struct MergeSummary {
    /// The rover whose map frame the merged map is in.
    pub reference: String,
    /// How each other rover's map joined.
    pub maps: Vec<MergeLinkSummary>,
    /// Of the merged map's occupied cells, the fraction within one cell of a true
    /// lidar-visible obstacle (as each rover's map is graded; the reference's frame is the
    /// arena's).
    pub occupied_correct: f64,
    /// The same with every map the merge placed put at its known start instead: what the
    /// merge's own poses gain or lose.
    pub occupied_correct_at_known_starts: f64,
    /// Merges the lander ran (every 120 s once two maps were in, and at the end, skipping
    /// those when no map had changed).
    pub merges_run: usize,
}

/// One rover's map in the merge.
#[derive(Clone, Debug, Serialize)]
pub struct MergeLinkSummary {
    /// The rover.
    pub rover: String,
    /// Pose of its map's frame in the reference's, `[x_m, y_m, yaw_rad]`, if merged.
    pub pose: Option<[f64; 3]>,
    /// Confidence, 0..1.
    pub confidence: f64,
    /// Whether the maps confirmed the pose (false: placed at the known start, unchecked).
    pub confirmed: bool,
    /// Share of obstacle points (both maps) at the known start within 0.5 m of the other
    /// map's structure, among those and the ones on its open ground farther off; `None`
    /// with nothing to compare.
    pub agreement_at_start: Option<f64>,
    /// Why the maps could not confirm a pose, for a map placed at its known start.
    pub unconfirmed_because: Option<String>,
    /// Why it was left out.
    pub refused: Option<String>,
    /// Whether its map has drifted from the known start (beyond 0.3 m or 2 deg).
    pub drifted: bool,
    /// How far, metres.
    pub drift_m: f64,
}

impl MergeLinkSummary {
    /// Whether the map was placed away from its known start (the reference's frame: every
    /// rover's map frame is the arena's). A drifted map stays there unless the maps
    /// contradict it.
    pub fn placed_off_known_start(&self) -> bool {
        self.pose.is_some_and(|p| p != [0.0; 3])
    }
}

fn merge_summary(mission: &Mission) -> Option<MergeSummary> {
    let m = merged(mission)?;
    let truth = mission.world().truth();
    let occupied_correct = |cells: &realms_core::Grid<MapCell>| {
        let values = cells.map(|c| c.to_occupancy());
        crate::slam_record::grade_grid(&values, truth, &[]).occupied_correct
    };
    // The maps the merge placed, each at its known start.
    let lander = mission.station(realms_net::NodeAddr::Lander)?;
    let placed: Vec<realms_merge::Map> = std::iter::once(m.reference)
        .chain(
            m.links
                .iter()
                .filter(|l| l.reference_from_map.is_some())
                .map(|l| l.rover),
        )
        .filter_map(|r| lander.map(r))
        .map(realms_node::lander_merge::to_merge_map)
        .collect();
    let at_starts = realms_merge::compose::compose(
        &placed,
        &vec![Some(realms_core::Pose2::IDENTITY); placed.len()],
    )
    .0;
    Some(MergeSummary {
        merges_run: lander.merges_run(),
        occupied_correct: occupied_correct(&m.cells),
        occupied_correct_at_known_starts: occupied_correct(&at_starts),
        reference: m.reference.to_string(),
        maps: m
            .links
            .iter()
            .map(|l| MergeLinkSummary {
                rover: l.rover.to_string(),
                pose: l.reference_from_map.map(|p| [p.x_m, p.y_m, p.yaw_rad]),
                confidence: l.confidence,
                confirmed: l.confirmed,
                agreement_at_start: l.agreement_at_start,
                unconfirmed_because: l.unconfirmed_because.clone(),
                refused: l.refused.clone(),
                drifted: l.drifted,
                drift_m: l.drift_m,
            })
            .collect(),
    })
}

/// Writes `merged_map.png` (every known cell in the colour of the first rover whose map
/// knew it, obstacles black, hazards orange, unknown grey) and the map_server pair
/// `merged_map.pgm` + `.yaml`.
fn write_merged(m: &MergedMap, dir: &Path) -> Result<(), ReportError> {
    let geo = *m.cells.geometry();
    let pixels: Vec<[u8; 3]> = m
        .cells
        .cells()
        .iter()
        .zip(m.contribution.cells())
        .map(|(c, bits)| match c {
            MapCell::Unknown => [205, 205, 205],
            MapCell::Occupied => [0, 0, 0],
            MapCell::Hazard => [240, 140, 20],
            MapCell::Free => {
                let rover = bits.trailing_zeros() as usize;
                let k = m
                    .rovers
                    .get(rover)
                    .map_or(0, |r| r.0.saturating_sub(1) as usize);
                let c = ROVER_COLORS[k % ROVER_COLORS.len()];
                [c[0] / 2 + 120, c[1] / 2 + 120, c[2] / 2 + 120]
            }
        })
        .collect();
    if let Some(img) = realms_core::Grid::from_cells(geo, pixels) {
        img.write_png(&dir.join("merged_map.png"), |c| *c)?;
    }
    map_server::write_with_hazards(&m.cells, dir, "merged_map", |c| c.with_hazard())?;
    Ok(())
}

/// File stem of a rover's map in the results folder.
fn map_stem(rover: &str) -> String {
    format!("{rover}_map")
}

/// Writes `<rover>_map.png` (unknown grey, free white, occupied black, hazard orange) and
/// the ROS map_server pair `<rover>_map.pgm` + `.yaml` (hazards occupied to map_server, and
/// kept for `realms merge`: [`map_server::write_with_hazards`]).
pub fn write_map(map: &OccupancyGrid, dir: &Path, rover: &str) -> Result<(), ReportError> {
    let Some(grid) = map_grid(map) else {
        // A map whose size does not match its data is not drawn; the grade still says so.
        return Ok(());
    };
    let stem = map_stem(rover);
    grid.write_png(&dir.join(format!("{stem}.png")), |v| match *v {
        OccupancyGrid::FREE => [254, 254, 254],
        OccupancyGrid::OCCUPIED => [0, 0, 0],
        OccupancyGrid::HAZARD => [240, 140, 20],
        _ => [205, 205, 205],
    })?;
    map_server::write_with_hazards(&grid, dir, &stem, |v| match *v {
        OccupancyGrid::FREE => (Trinary::Free, false),
        OccupancyGrid::UNKNOWN => (Trinary::Unknown, false),
        OccupancyGrid::HAZARD => (Trinary::Occupied, true),
        _ => (Trinary::Occupied, false),
    })?;
    Ok(())
}

/// Writes `coverage.png`: the arena with every explorable cell in the colour of the rover
/// that mapped it first, and in dark red where no rover's final map knows it,
/// above the coverage-over-time curve.
fn write_coverage(
    mission: &Mission,
    truth_img: &realms_core::Grid<[u8; 3]>,
    path: &Path,
) -> Result<(), ReportError> {
    let cov = mission.coverage();
    let known = cov.known_by().cells();
    let first = cov.first_by();
    let mut explorable = vec![false; known.len()];
    for &i in cov.explorable() {
        explorable[i] = true;
    }
    let mut map = truth_img.clone();
    for (i, px) in map.cells_mut().iter_mut().enumerate() {
        if !explorable[i] {
            *px = [px[0] / 2 + 100, px[1] / 2 + 100, px[2] / 2 + 100];
        } else if known[i] == 0 {
            *px = [110, 20, 20];
        } else {
            let rover = first[i].saturating_sub(1) as usize;
            let c = ROVER_COLORS[rover % ROVER_COLORS.len()];
            *px = [c[0] / 2 + 120, c[1] / 2 + 120, c[2] / 2 + 120];
        }
    }
    let chart = crate::chart::coverage_chart(
        &[crate::chart::Series {
            color: [30, 30, 30],
            points: cov.series().to_vec(),
        }],
        mission.now().as_secs_f64(),
    );
    // The map on top, the chart below, both centred on the wider one.
    let (mw, mh) = (map.width(), map.height());
    let (cw, ch) = (chart.width(), chart.height());
    let width = mw.max(cw);
    let geo = realms_core::GridGeometry {
        width,
        height: mh + ch,
        resolution_m: 1.0,
        origin: realms_core::Point2::new(0.0, 0.0),
    };
    let mut out = realms_core::Grid::new(geo, [255u8, 255, 255]);
    let (mx, cx) = ((width - mw) / 2, (width - cw) / 2);
    for y in 0..mh {
        for x in 0..mw {
            if let (Some(d), Some(s)) = (out.get_mut(mx + x, ch + y), map.get(x, y)) {
                *d = *s;
            }
        }
    }
    for y in 0..ch {
        for x in 0..cw {
            if let (Some(d), Some(s)) = (out.get_mut(cx + x, y), chart.get(x, y)) {
                *d = *s;
            }
        }
    }
    out.write_png(path, |c| *c)?;
    Ok(())
}

/// Writes the results folder: `mission.json`, `truth.png`, `trajectories.png`,
/// `trajectories.csv`, and each rover's map. Creates the folder if needed.
pub fn write_results(
    mission: &Mission,
    dir: &Path,
    scenario_source: &str,
    wall_s: f64,
) -> Result<MissionReport, ReportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ReportError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let world = mission.world();
    let truth_img = render::truth_image(world.terrain(), world.truth());
    truth_img.write_png(&dir.join("truth.png"), |c| *c)?;

    let mut traj_img = truth_img.map(|c| {
        // Fade the terrain so the paths stand out.
        [c[0] / 2 + 100, c[1] / 2 + 100, c[2] / 2 + 100]
    });
    for (i, points) in mission.trajectory_points().iter().enumerate() {
        render::draw_path(
            &mut traj_img,
            points,
            ROVER_COLORS[i % ROVER_COLORS.len()],
            3,
        );
    }
    traj_img.write_png(&dir.join("trajectories.png"), |c| *c)?;

    let mut csv = String::from("t_s,rover,x_m,y_m,yaw_rad\n");
    for (body, samples) in world.rovers().zip(mission.trajectories()) {
        for s in samples {
            csv.push_str(&format!(
                "{:.3},{},{:.4},{:.4},{:.5}\n",
                s.t.as_secs_f64(),
                body.id,
                s.x_m,
                s.y_m,
                s.yaw_rad
            ));
        }
    }
    let csv_path = dir.join("trajectories.csv");
    std::fs::write(&csv_path, csv).map_err(io(&csv_path))?;

    let mut csv = String::from(
        "t_s,rover,slam_x_m,slam_y_m,slam_yaw_rad,odom_x_m,odom_y_m,odom_yaw_rad,true_x_m,true_y_m,true_yaw_rad,final_x_m,final_y_m,final_yaw_rad,sigma_xy_m,sigma_yaw_rad\n",
    );
    for (body, record) in world.rovers().zip(mission.slam_records()) {
        for c in &record.checks {
            csv.push_str(&format!("{:.3},{}", c.t.as_secs_f64(), body.id));
            let poses = [
                Some(c.estimate),
                Some(c.odometry),
                Some(c.truth),
                c.optimised,
            ];
            for pose in poses {
                match pose {
                    Some(p) => {
                        csv.push_str(&format!(",{:.4},{:.4},{:.5}", p.x_m, p.y_m, p.yaw_rad))
                    }
                    None => csv.push_str(",,,"),
                }
            }
            match c.sigma {
                Some((m, rad)) => csv.push_str(&format!(",{m:.4},{rad:.5}")),
                None => csv.push_str(",,"),
            }
            csv.push('\n');
        }
    }
    let csv_path = dir.join("slam.csv");
    std::fs::write(&csv_path, csv).map_err(io(&csv_path))?;

    for (body, record) in world.rovers().zip(mission.slam_records()) {
        if let Some(map) = &record.map {
            write_map(map, dir, &body.id.to_string())?;
        }
    }

    write_coverage(mission, &truth_img, &dir.join("coverage.png"))?;
    if let Some(m) = merged(mission) {
        write_merged(m, dir)?;
    }
    if let Some(chart) = crate::netreport::network_chart(mission, &ROVER_COLORS) {
        chart.write_png(&dir.join("network.png"), |c| *c)?;
    }

    let report = MissionReport::new(mission, scenario_source, wall_s);
    let json = serde_json::to_string_pretty(&report)
        .expect("the report is plain data and always serialises");
    let json_path = dir.join("mission.json");
    std::fs::write(&json_path, json + "\n").map_err(io(&json_path))?;
    Ok(report)
}
