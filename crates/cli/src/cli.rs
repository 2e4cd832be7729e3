//! Raw command-line flags, as clap parses them. Subcommands resolve them into settings.

use clap::{Args as ClapArgs, Parser, Subcommand};
use std::path::PathBuf;

/// realms: a team of planetary rovers run as one mission.
#[derive(Debug, Parser)]
#[command(name = "realms", version, about)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a simulated mission headless and write its results folder.
    Mission(MissionArgs),
    /// Print or check scenario files.
    Scenario(ScenarioArgs),
    /// Measure performance.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Run 2D lidar SLAM on a recorded CARMEN log.
    Slam(SlamArgs),
    /// Relative pose error of a trajectory against benchmark relations (Kümmerle et al. 2009).
    SlamEval(SlamEvalArgs),
    /// Merge ROS map_server maps (PGM + YAML) taken from unknown relative poses.
    Merge(MergeArgs),
}

/// `realms merge`.
#[derive(Debug, ClapArgs)]
pub struct MergeArgs {
    /// Map YAML files; the first is the reference whose frame the others are placed in.
    #[arg(required = true, num_args = 2..)]
    pub maps: Vec<PathBuf>,
    /// The merged map's YAML (its PGM is written beside it, with the same stem).
    #[arg(long)]
    pub out: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// The maps share one frame (rovers started from known places): check each against the
    /// first near where its YAML origin puts it, within 3 m and 10 deg, instead of searching
    /// every pose. A map the first shares too little structure with to confirm a pose is
    /// placed as given, marked unconfirmed; one that contradicts it is refused.
    #[arg(long)]
    pub known_start: bool,
    /// The maps were built by different robots, each with its own SLAM drift (a few
    /// decimetres): merge them as precisely as they agree, not to a few centimetres. The
    /// maps `realms mission` writes carry their hazards, and a hazard one rover saw on
    /// ground another only swept with its lidar is no disagreement.
    #[arg(long)]
    pub rover_maps: bool,
}

/// `realms slam`.
#[derive(Debug, ClapArgs)]
pub struct SlamArgs {
    /// CARMEN log (FLASER, ODOM, ROBOTLASER1 lines).
    #[arg(long)]
    pub carmen: PathBuf,
    /// Output folder: trajectory.txt, map.pgm + map.yaml, map.png.
    #[arg(long)]
    pub out: PathBuf,
    /// Also evaluate against these relations and print the error.
    #[arg(long)]
    pub relations: Option<PathBuf>,
    /// Finest map cell, metres.
    #[arg(long, default_value_t = 0.05)]
    pub resolution_m: f64,
    /// Map resolutions the matcher goes through, coarse to fine.
    #[arg(long, default_value_t = 3)]
    pub levels: usize,
    /// Gauss-Newton iterations per resolution.
    #[arg(long, default_value_t = 6)]
    pub iterations: usize,
    /// Fill in the surface between neighbouring beams' endpoints up to this far apart before
    /// matching and mapping into the submaps, metres (0: use the endpoints as they are). The
    /// scan-matching-only frontend does not fill, so it cannot go with `--no-loop-closure`.
    #[arg(long, default_value_t = 0.0, conflicts_with = "no_loop_closure")]
    pub fill_gap_m: f64,
    /// Let each scan clear a cell at most once, and never a cell a beam ends in
    /// (Cartographer's update), instead of once per beam crossing it.
    #[arg(long)]
    pub miss_once_per_scan: bool,
    /// How each optimisation of the pose graph solves its linear systems: `block-jacobi`
    /// (conjugate gradients stopped after 500 iterations), `chain` (conjugate gradients
    /// preconditioned by the chain of poses, to the optimum) or `elimination` (exactly, in
    /// minimum-degree order).
    #[arg(long, value_enum, default_value_t = GraphSolverArg::BlockJacobi, conflicts_with = "no_loop_closure")]
    pub graph_solver: GraphSolverArg,
    /// After each optimisation, give the keyframes of the submaps still being built their
    /// optimised poses, rather than keeping the poses their cells were drawn with and moving
    /// them as one block.
    #[arg(long, conflicts_with = "no_loop_closure")]
    pub no_track_in_submap: bool,
    /// Scan matching against one global map only: no submaps, pose graph or loop closures.
    #[arg(long)]
    pub no_loop_closure: bool,
    /// Accept a loop closure only at or above this match score (mean occupancy at the scan's
    /// endpoints, 0..1).
    #[arg(long, default_value_t = 0.5)]
    pub loop_min_score: f64,
    /// Take each scan's odometry as its laser message carries it, even where those poses are
    /// older than their scans (by default the odometry is then interpolated at each scan's
    /// time from the ODOM lines).
    #[arg(long)]
    pub odometry_as_logged: bool,
    /// Take each tracking match from the occupancy grid as it is, without refining it on the
    /// tracking submap's hits themselves (per-cell means and spreads), which the rovers do
    /// and which frees it of the grid's pull towards cell centres.
    #[arg(long, conflicts_with = "no_loop_closure")]
    pub no_refine_on_hits: bool,
}

/// `realms slam-eval`.
#[derive(Debug, ClapArgs)]
pub struct SlamEvalArgs {
    /// `timestamp x y theta` per line.
    #[arg(long)]
    pub trajectory: PathBuf,
    /// `.relations` file: `t1 t2 x y z roll pitch yaw` per line.
    #[arg(long)]
    pub relations: PathBuf,
}

/// `realms mission`.
#[derive(Debug, ClapArgs)]
pub struct MissionArgs {
    /// Scenario TOML (default: the built-in ESA-ESRIC analogue, see `realms scenario --print-default`).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Override the scenario's seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Override the mission length, e.g. `4h`, `90m`, `30s`.
    #[arg(long)]
    pub duration: Option<String>,
    /// Results folder (default: `runs/<date>-<time>-seed<N>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Override the number of rovers.
    #[arg(long)]
    pub rovers: Option<u8>,
    /// Drop the scenario's scheduled faults (slip bursts, sensor dropouts, power loss).
    #[arg(long)]
    pub no_faults: bool,
    /// Deliver every message between nodes at once and intact, instead of over the
    /// scenario's simulated mesh radio and ground link (delay, bandwidth, blackouts).
    #[arg(long)]
    pub ideal_comms: bool,
    /// Keep running to the full duration even after exploration is complete.
    #[arg(long)]
    pub full_duration: bool,
    /// Run the rovers with this SLAM variant of `realms bench slam` instead of the setup as
    /// it is (the report names it); join several with `+`. For looking into what a variant
    /// changes in a whole mission, with all its files.
    #[arg(long)]
    pub variant: Option<String>,
    /// Run the rovers with this change to their navigation, as `realms bench missions
    /// --nav-variant` names them (e.g. `revisit`, or `revisit+endgame-must-pay`; the report
    /// names it).
    #[arg(long)]
    pub nav_variant: Option<String>,
}

/// `realms scenario`.
#[derive(Debug, ClapArgs)]
pub struct ScenarioArgs {
    /// Print the default scenario as TOML.
    #[arg(long, conflicts_with = "check")]
    pub print_default: bool,
    /// Check a scenario file and print what it resolves to.
    #[arg(long)]
    pub check: Option<PathBuf>,
}

/// `realms bench`.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Simulated seconds per wall second, and the cost of each sensor.
    Sim(BenchSimArgs),
    /// Planning time for cross-arena paths, A* against Dijkstra.
    Plan(BenchPlanArgs),
    /// Coverage over time for several fleet sizes and seeds.
    Explore(BenchExploreArgs),
    /// The field's relay experiment on the radio model: 220 m direct against a relay.
    NetRelay(BenchNetRelayArgs),
    /// Cost of the simulated network: messages per wall second for fleets of several sizes.
    NetSim(BenchNetSimArgs),
    /// Map merging on generated pairs with a known answer: success, wrong merges, refusals, time.
    Merge(BenchMergeArgs),
    /// Slip bursts during whole missions: how soon they are reported, false alarms, the pose after.
    Slip(BenchSlipArgs),
    /// The rovers' SLAM replayed on a mission's captured sensor input: error against the truth and cost, per variant.
    Slam(BenchSlamArgs),
    /// SLAM on the recorded logs of the standard 2D benchmark (Intel, ACES, MIT CSAIL) against the published figures.
    Logs(BenchLogsArgs),
    /// Whole missions, one per seed, run as `realms mission` runs them: each rover's map and trajectory against the truth, the crater cells near its path, the lander's merged map.
    Missions(BenchMissionsArgs),
    /// Two `bench missions --json` runs on the same seeds side by side, mission by mission, with the interval chance alone would move each difference within.
    Compare(BenchCompareArgs),
}

/// `realms bench compare`.
#[derive(Debug, ClapArgs)]
pub struct BenchCompareArgs {
    /// The baseline run: what `realms bench missions --json` printed.
    pub baseline: std::path::PathBuf,
    /// The run compared with it, over the same seeds.
    pub candidate: std::path::PathBuf,
    /// Redrawings of the paired missions for the intervals.
    #[arg(long, default_value_t = 10_000)]
    pub resamples: usize,
}

/// `realms bench missions`.
#[derive(Debug, ClapArgs)]
pub struct BenchMissionsArgs {
    /// Missions, one per seed.
    #[arg(long, default_value_t = 16)]
    pub seeds: u64,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub first_seed: u64,
    /// Time limit per mission (it ends sooner once the arena is explored, as `realms
    /// mission` does), e.g. `4h` (default: the scenario's).
    #[arg(long)]
    pub duration: Option<String>,
    /// Missions run at once (default: one per core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Scenario TOML (default: the built-in one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
    /// Run the rovers with this SLAM variant of `realms bench slam` instead of the setup as
    /// it is (the missions' paths then differ too); join several with `+`, e.g.
    /// `weak-floor-100-own+gaps-to-6m`.
    #[arg(long)]
    pub variant: Option<String>,
    /// Run the rovers with this change to their navigation: `unjudged-must-pay` (a frontier
    /// beside ground only the lidar saw is driven to only where it is worth the drive),
    /// `revisit` (a rover whose position grew uncertain past 0.25 m drives back to ground it
    /// mapped while it knew where it was, to close the loop), `revisit-0.4m` (past 0.4 m),
    /// `endgame-must-pay` (as `unjudged-must-pay`, once a rover has found no frontier left),
    /// `plan-margin-10m` (the planner may plan through 10 m of unknown past the map's edge);
    /// join several with `+`, e.g. `revisit+endgame-must-pay`.
    #[arg(long)]
    pub nav_variant: Option<String>,
}

/// `realms bench logs`.
#[derive(Debug, ClapArgs)]
pub struct BenchLogsArgs {
    /// Folder holding `NAME.clf` and `NAME.relations` for each log.
    #[arg(long, default_value = "../shared/data/slam")]
    pub data: PathBuf,
    /// Logs to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "intel,aces,mit-csail")]
    pub logs: Vec<String>,
}

/// `realms bench slam`.
#[derive(Debug, ClapArgs)]
pub struct BenchSlamArgs {
    /// Missions, one per seed.
    #[arg(long, default_value_t = 3)]
    pub seeds: u64,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub first_seed: u64,
    /// Length of each mission, e.g. `10m`.
    #[arg(long, default_value = "10m")]
    pub duration: String,
    /// SLAM variants to replay beside the setup as it is (repeat the flag for several); join
    /// variants with `+` to replay them together, e.g. `weak-floor-100-own+gaps-to-6m`.
    #[arg(long)]
    pub variant: Vec<String>,
    /// Drop the scenario's scheduled faults (slip bursts, sensor dropouts, power loss).
    #[arg(long)]
    pub no_faults: bool,
    /// Run the missions over the simulated radio, as `realms mission` does (default: ideal
    /// communication). The rovers then drive the paths the default mission's report grades.
    #[arg(long)]
    pub radio: bool,
    /// Replace the wheels' odometry by the truth's motion before the replays (wheels that
    /// neither slip nor drift, taken at their word from the start), to see what the wheels'
    /// errors cost.
    #[arg(long)]
    pub perfect_wheels: bool,
    /// Remove what the rovers' start-up calibration leaves of each gyro's bias before the
    /// replays (the IMU's rates after the calibration shifted so the bias it measured is
    /// the true one), to see what the gyro's leftover bias costs.
    #[arg(long)]
    pub exact_gyro_bias: bool,
    /// Run the missions with the sweeping lidar and keep each scan's twin taken at once from
    /// the pose of its last beam (the same noise stream), then replay every rover's SLAM on
    /// the twins too (`at-once-twin`): the two lidars compared on one path.
    #[arg(long)]
    pub lidar_twins: bool,
    /// Seeds run at once (default: one per core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Scenario TOML (default: the built-in one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Also write each replay's poses, scan by scan, to
    /// `DIR/seed<N>-<rover>-<variant>.csv` (time, truth, tracked and final pose, state,
    /// closures so far, the wheels' odometry as published), to see when and where an error
    /// grew, and each replay's final map as `DIR/seed<N>-<rover>-<variant>_map.png` (and the
    /// map_server pair), as `realms mission` writes a rover's.
    #[arg(long, value_name = "DIR")]
    pub trajectories: Option<PathBuf>,
}

/// `realms bench slip`.
#[derive(Debug, ClapArgs)]
pub struct BenchSlipArgs {
    /// Missions, one per seed.
    #[arg(long, default_value_t = 4)]
    pub seeds: u64,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub first_seed: u64,
    /// Time limit per mission (it ends sooner once the arena is explored), e.g. `40m`.
    #[arg(long, default_value = "40m")]
    pub duration: String,
    /// Mean time between one rover's slip bursts, seconds.
    #[arg(long, default_value_t = 120.0)]
    pub period_s: f64,
    /// Run the rovers with this SLAM variant of `realms bench slam` instead of the setup as
    /// it is (the missions' paths then differ too); join several with `+`, e.g.
    /// `weak-floor-100-own+gaps-to-6m`.
    #[arg(long)]
    pub variant: Option<String>,
    /// Run the rovers with this change to their navigation, as `realms bench missions
    /// --nav-variant` names them (e.g. `revisit`).
    #[arg(long)]
    pub nav_variant: Option<String>,
    /// Missions run at once (default: one per core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Scenario TOML (default: the built-in one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
}

/// `realms bench net-sim`.
#[derive(Debug, ClapArgs)]
pub struct BenchNetSimArgs {
    /// Fleet sizes, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "3,20")]
    pub rovers: Vec<u8>,
    /// Simulated seconds per trial.
    #[arg(long, default_value_t = 120)]
    pub seconds: u32,
    /// Trials per fleet size (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub trials: usize,
}

/// `realms bench merge`.
#[derive(Debug, ClapArgs)]
pub struct BenchMergeArgs {
    /// Pairs per source kind and overlap.
    #[arg(long, default_value_t = 20)]
    pub pairs: usize,
    /// Seed of the generated pairs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Overlaps to test, percent, comma-separated.
    #[arg(long, default_value = "5,10,20,40")]
    pub overlaps: String,
    /// Source kinds, comma-separated: real, sim-building, lunar-sparse, lunar-very-sparse,
    /// and lunar-rovers, lunar-rovers-known-start (the rovers' own maps from three default
    /// missions, binned by overlap: a row covers its overlap up to the next one asked for,
    /// the last up to 100 %, and pairs under the first are left out; not run unless asked
    /// for: the missions take minutes).
    #[arg(
        long,
        default_value = "real,sim-building,lunar-sparse,lunar-very-sparse"
    )]
    pub kinds: String,
    /// Folder of the recorded maps (default: `../shared/data/maps` from the working folder).
    #[arg(long)]
    pub maps: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// One line per pair on stderr (errors, evidence, verdict).
    #[arg(long)]
    pub verbose: bool,
    /// Write every generated pair here as PNG images (for looking at the cases).
    #[arg(long)]
    pub dump: Option<PathBuf>,
    /// Walls of the two maps laid parallel within this many degrees hold the heading
    /// (`Params::wall_pin_rad`; 0 turns the rule off, for comparison). Default: the
    /// merge's own setting for the kind.
    #[arg(long)]
    pub wall_pin_deg: Option<f64>,
}

/// `realms bench net-relay`.
#[derive(Debug, ClapArgs)]
pub struct BenchNetRelayArgs {
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    pub json: bool,
    /// Random shadowing draws for the medians.
    #[arg(long, default_value_t = 1000)]
    pub draws: usize,
    /// Seed of the shadowing draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// `realms bench plan`.
#[derive(Debug, ClapArgs)]
pub struct BenchPlanArgs {
    /// Trials per path (the median is reported).
    #[arg(long, default_value_t = 15)]
    pub trials: usize,
    /// Scenario TOML (default: the built-in one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
}

/// `realms bench explore`.
#[derive(Debug, ClapArgs)]
pub struct BenchExploreArgs {
    /// Fleet sizes, comma-separated.
    #[arg(long, default_value = "1,2,3")]
    pub rovers: String,
    /// Seeds per fleet size.
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// The first seed.
    #[arg(long, default_value_t = 1)]
    pub first_seed: u64,
    /// Time limit per mission, e.g. `90m`.
    #[arg(long, default_value = "90m")]
    pub duration: String,
    /// Missions run at once (default: one per core).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// Write the median coverage curves here as a PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Rovers do not hear each other's navigation messages (targets, explored ground):
    /// exploration as it degrades when the radio is silent.
    #[arg(long)]
    pub no_peer_messages: bool,
    /// Scenario TOML (default: the built-in one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
}

/// `realms bench sim`.
#[derive(Debug, ClapArgs)]
pub struct BenchSimArgs {
    /// Simulated time per speed trial, e.g. `120s`.
    #[arg(long, default_value = "120s")]
    pub duration: String,
    /// Speed trials (the median is reported; 0 skips them).
    #[arg(long, default_value_t = 3)]
    pub trials: usize,
    /// Sensor frames timed per sensor (the median is reported).
    #[arg(long, default_value_t = 200)]
    pub frames: usize,
    /// Scenario TOML (default: the built-in one).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Which sensors to time (the speed trials always run unless `--trials 0`).
    #[arg(long, value_enum, default_value_t = BenchSensor::All)]
    pub sensor: BenchSensor,
    /// Skip plain ray casting, in the paired trials and in the sensor timings (for profiling
    /// the fast path alone; no ratio or speedup is then reported).
    #[arg(long)]
    pub no_plain: bool,
}

/// Sensor selection for `realms bench sim`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchSensor {
    /// Every sensor.
    All,
    /// The 2D lidar.
    Lidar,
    /// The depth camera.
    Depth,
    /// The grayscale camera.
    Camera,
    /// None.
    None,
}

/// `--graph-solver`: how the pose graph's linear systems are solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum GraphSolverArg {
    /// Conjugate gradients, block-Jacobi preconditioned, stopped after 500 iterations.
    BlockJacobi,
    /// Conjugate gradients preconditioned by the chain of poses, to the optimum.
    Chain,
    /// Block elimination in minimum-degree order, exact.
    Elimination,
}

impl From<GraphSolverArg> for realms_slam::posegraph::GraphSolver {
    fn from(arg: GraphSolverArg) -> Self {
        match arg {
            GraphSolverArg::BlockJacobi => Self::BlockJacobi,
            GraphSolverArg::Chain => Self::Chain,
            GraphSolverArg::Elimination => Self::Elimination,
        }
    }
}
