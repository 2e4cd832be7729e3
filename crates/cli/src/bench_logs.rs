//! `realms bench logs`: the SLAM `realms slam` runs, on the recorded logs of the standard 2D
//! benchmark (Kümmerle et al. 2009), beside the published figures.
//!
//! Each log is read, run through the mapper with its default setup, and its trajectory
//! scored against the log's relations. Mean translation is the benchmark's figure; the
//! median shows what most relations see, since one missed loop closure moves the mean by a
//! factor of ten. Speed is the log's duration over the wall time of the SLAM alone, and the
//! scans it took per wall second.

use crate::cli::BenchLogsArgs;
use anyhow::{Context, Result};
use realms_slam::carmen::CarmenLog;
use realms_slam::eval::{read_relations, relative_pose_error};
use realms_slam::mapper::{Mapper, MapperConfig};
use std::time::Instant;

/// Published figures (Hess et al., ICRA 2016, Tables II and V; `../shared/data/slam/
/// SOURCES.md`): graph mapping's translation (m) and Cartographer's translation (m) and
/// rotation (deg).
fn published(log: &str) -> Option<(f64, f64, f64)> {
    match log {
        "intel" => Some((0.031, 0.0229, 0.453)),
        "aces" => Some((0.044, 0.0375, 0.373)),
        "mit-csail" => Some((0.004, 0.0319, 0.369)),
        _ => None,
    }
}

/// `realms bench logs`.
pub fn run(args: BenchLogsArgs) -> Result<()> {
    println!(
        "| log | scans | translation mean +- std | median | rotation mean | median | closures | speed | scans per second | graph mapping | Cartographer |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for name in &args.logs {
        let clf = args.data.join(format!("{name}.clf"));
        let mut log =
            CarmenLog::read_file(&clf).with_context(|| format!("reading {}", clf.display()))?;
        log.retime_stale_odometry();
        let rel_path = args.data.join(format!("{name}.relations"));
        let relations = read_relations(&rel_path)?;
        let start = Instant::now();
        // As `realms slam` runs by default: matches refined on the hits.
        let mut mapper = Mapper::new(MapperConfig {
            ndt_refine: Some(realms_slam::ndt::NdtConfig::default()),
            ..MapperConfig::default()
        });
        for scan in &log.scans {
            mapper.add_scan(scan);
        }
        mapper.finish();
        let wall_s = start.elapsed().as_secs_f64();
        let e = relative_pose_error(&mapper.trajectory(), &relations)
            .with_context(|| format!("scoring {name} against {}", rel_path.display()))?;
        let (graph, carto) = match published(name) {
            Some((g, ct, cr)) => (format!("{g} m"), format!("{ct} m, {cr} deg")),
            None => ("-".into(), "-".into()),
        };
        println!(
            "| {name} | {} | {:.4} +- {:.4} m | {:.4} m | {:.3} deg | {:.3} deg | {} | {:.0}x | {:.0} | {graph} | {carto} |",
            log.scans.len(),
            e.trans_mean_m,
            e.trans_std_m,
            e.trans_median_m,
            e.rot_mean_deg,
            e.rot_median_deg,
            mapper.closures,
            log.duration_s() / wall_s,
            log.scans.len() as f64 / wall_s,
        );
    }
    Ok(())
}
