//! `realms slam` and `realms slam-eval`: SLAM on recorded CARMEN logs and the benchmark's
//! relative pose error.

use crate::cli::{SlamArgs, SlamEvalArgs};
use anyhow::{Context, Result};
use realms_core::map_server::{self, Trinary};
use realms_slam::carmen::CarmenLog;
use realms_slam::eval::{RelativePoseError, read_relations, relative_pose_error};
use realms_slam::frontend::{Frontend, FrontendConfig};
use realms_slam::occupancy::CellState;
use realms_slam::trajectory;

/// `realms slam`.
pub fn run(args: SlamArgs) -> Result<()> {
    let mut log = CarmenLog::read_file(&args.carmen)
        .with_context(|| format!("reading {}", args.carmen.display()))?;
    if !args.odometry_as_logged {
        retime_odometry(&mut log);
    }
    anyhow::ensure!(
        !log.scans.is_empty(),
        "{} holds no laser scans",
        args.carmen.display()
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let start = std::time::Instant::now();
    anyhow::ensure!(
        args.resolution_m > 0.001 && args.resolution_m <= 1.0,
        "--resolution-m must be between 0.001 and 1 m"
    );
    anyhow::ensure!((1..=8).contains(&args.levels), "--levels must be 1 to 8");
    let mut cfg = FrontendConfig {
        resolution_m: args.resolution_m,
        levels: args.levels,
        ..FrontendConfig::default()
    };
    cfg.matcher.iterations = args.iterations.clamp(1, 100);
    if args.fill_gap_m > 0.0 {
        cfg.densify = Some(realms_slam::frontend::Densify {
            max_gap_m: args.fill_gap_m,
            spacing_m: args.resolution_m,
        });
    }
    if args.miss_once_per_scan {
        cfg.miss_rule = realms_slam::occupancy::MissRule::OncePerScan;
    }
    let mut frontend = Frontend::new(cfg);
    let mcfg = realms_slam::mapper::MapperConfig {
        frontend: cfg,
        loop_min_score: args.loop_min_score,
        graph_solver: args.graph_solver.into(),
        track_in_submap_frame: !args.no_track_in_submap,
        ndt_refine: (!args.no_refine_on_hits).then(realms_slam::ndt::NdtConfig::default),
        ..Default::default()
    };
    let mut mapper = realms_slam::mapper::Mapper::new(mcfg);
    for scan in &log.scans {
        if !args.no_loop_closure {
            mapper.add_scan(scan);
            for (t, change) in mapper.take_transitions() {
                println!(
                    "{:.1} s into the log: {:?}: {}",
                    t - log.scans[0].timestamp_s,
                    change.state,
                    change.reason
                );
            }
        } else {
            frontend.add_scan(scan);
        }
    }
    let (trajectory, map) = if !args.no_loop_closure {
        mapper.finish();
        (mapper.trajectory(), mapper.render_map())
    } else {
        (frontend.trajectory().to_vec(), frontend.map().clone())
    };
    let wall_s = start.elapsed().as_secs_f64();
    if !args.no_loop_closure {
        println!("{} loop closures", mapper.closures);
        println!(
            "fast turns: headings searched at {} scans, the searched heading's match kept at {}",
            mapper.fast_turn_searches, mapper.fast_turn_taken
        );
        println!(
            "stalled turns: matched again from the carried-on turn at {} scans, kept at {}",
            mapper.stall_turn_searches, mapper.stall_turn_taken
        );
    }
    let duration = log.duration_s();
    println!(
        "{} scans over {:.0} s of log in {:.2} s ({:.0}x faster than the log, {:.0} scans/s)",
        log.scans.len(),
        duration,
        wall_s,
        duration / wall_s,
        log.scans.len() as f64 / wall_s
    );

    let traj_path = args.out.join("trajectory.txt");
    std::fs::write(&traj_path, trajectory::to_text(&trajectory))
        .with_context(|| format!("writing {}", traj_path.display()))?;
    let states = map.states();
    let trinary = states.map(|c| match c {
        CellState::Unknown => Trinary::Unknown,
        CellState::Free => Trinary::Free,
        CellState::Occupied => Trinary::Occupied,
    });
    let yaml = map_server::write(&trinary, &args.out, "map")?;
    states.write_png(&args.out.join("map.png"), |c| match c {
        CellState::Unknown => [205, 205, 205],
        CellState::Free => [254, 254, 254],
        CellState::Occupied => [0, 0, 0],
    })?;
    println!(
        "wrote {}, {}, map.pgm, map.png",
        traj_path.display(),
        yaml.display()
    );
    if let Some(rel) = &args.relations {
        let relations = read_relations(rel)?;
        print_error(&relative_pose_error(&trajectory, &relations)?);
    }
    Ok(())
}

/// `realms slam-eval`.
/// Gives each scan the odometry at its own time where the log's laser messages carry
/// stale odometry ([`CarmenLog::retime_stale_odometry`]), and says so.
pub(crate) fn retime_odometry(log: &mut CarmenLog) {
    if let (Some(stale_s), retimed @ 1..) = log.retime_stale_odometry() {
        println!(
            "odometry: the laser messages carry poses {:.0} ms older than their scans (median); \
             odometry interpolated at the scans' times for {retimed} of {} scans",
            stale_s * 1e3,
            log.scans.len()
        );
    }
}

pub fn eval(args: SlamEvalArgs) -> Result<()> {
    let traj = trajectory::read_file(&args.trajectory)?;
    let relations = read_relations(&args.relations)?;
    print_error(&relative_pose_error(&traj, &relations)?);
    Ok(())
}

fn print_error(e: &RelativePoseError) {
    println!(
        "relative pose error over {} relations{}: translation {:.4} +- {:.4} m, rotation {:.3} +- {:.3} deg",
        e.relations,
        if e.missing > 0 {
            format!(" ({} without poses, skipped)", e.missing)
        } else {
            String::new()
        },
        e.trans_mean_m,
        e.trans_std_m,
        e.rot_mean_deg,
        e.rot_std_deg
    );
}
