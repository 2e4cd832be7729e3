//! `realms merge A.yaml B.yaml [C.yaml ...] --out merged.yaml [--json]`: merges ROS
//! map_server maps taken from unknown relative poses, prints where each later map's frame
//! lies in the first map's frame (or why it was refused) and writes the merged map, plus a
//! PNG of which map contributed each cell. With `--known-start` the maps share one frame
//! and each is checked where it is instead of searched for.

use crate::cli::MergeArgs;
use anyhow::{Context, Result};
use realms_merge::compose::{self, KnownStartMerged, Merged};
use realms_merge::{MapCell, Params, PriorWindow};
use serde_json::json;

/// Colours of the contribution image, by map index (cycled).
const PALETTE: [[u8; 3]; 6] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
];

/// `realms merge`.
pub fn run(args: MergeArgs) -> Result<()> {
    let maps = args
        .maps
        .iter()
        .map(|p| realms_merge::io::read(p).with_context(|| format!("reading {}", p.display())))
        .collect::<Result<Vec<_>>>()?;
    let params = if args.rover_maps {
        Params::for_rover_maps()
    } else {
        Params::default()
    };
    if args.known_start {
        let merged = compose::merge_known_start(&maps, &params, &PriorWindow::default())?;
        return report_known_start(&args, &merged);
    }
    let merged = compose::merge(&maps, &params)?;
    let yaml = write_merged(&args, &merged.grid, &merged.contribution)?;
    let png = args.out.with_extension("contributions.png");
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report_json(&args, &merged))?
        );
        return Ok(());
    }
    for (path, p) in args.maps.iter().zip(&merged.placements).skip(1) {
        match (p.reference_from_map, &p.refusal) {
            (Some(pose), _) => println!(
                "{}: x_m {:.3} y_m {:.3} yaw_rad {:.4} ({:.2} deg) confidence {:.2}{}",
                path.display(),
                pose.x_m,
                pose.y_m,
                pose.yaw_rad,
                pose.yaw_rad.to_degrees(),
                p.confidence,
                p.via
                    .filter(|v| *v != 0)
                    .map(|v| format!(" (placed via {})", args.maps[v].display()))
                    .unwrap_or_default()
            ),
            (None, reason) => println!(
                "{}: refused: {}",
                path.display(),
                reason.as_deref().unwrap_or("not placed")
            ),
        }
    }
    for i in &merged.inconsistencies {
        println!(
            "warning: {} -> {} disagrees with the chain of other links by {:.2} m, {:.1} deg",
            args.maps[i.fixed].display(),
            args.maps[i.moving].display(),
            i.error_m,
            i.error_rad.to_degrees()
        );
    }
    let placed = merged
        .placements
        .iter()
        .filter(|p| p.reference_from_map.is_some())
        .count();
    println!(
        "merged {placed} of {} maps into {} (contributions: {})",
        maps.len(),
        yaml.display(),
        png.display()
    );
    Ok(())
}

/// A map's entry in `--json` output when it was placed: the pose of its frame in the first
/// map's frame, and how sure the merge is.
fn placed_entry(
    name: String,
    pose: realms_core::Pose2,
    confidence: f64,
) -> serde_json::Map<String, serde_json::Value> {
    let mut entry = serde_json::Map::new();
    entry.extend([
        ("map".into(), json!(name)),
        ("x_m".into(), json!(pose.x_m)),
        ("y_m".into(), json!(pose.y_m)),
        ("yaw_rad".into(), json!(pose.yaw_rad)),
        ("confidence".into(), json!(confidence)),
    ]);
    entry
}

/// A map's entry in `--json` output when it was left out, with why.
fn refused_entry(name: String, refusal: Option<&str>) -> serde_json::Value {
    json!({ "map": name, "refused": refusal.unwrap_or("not placed") })
}

/// Writes the merged map and prints each map's check, as text or JSON.
fn report_known_start(args: &MergeArgs, merged: &KnownStartMerged) -> Result<()> {
    let yaml = write_merged(args, &merged.grid, &merged.contribution)?;
    let entries: Vec<serde_json::Value> = args.maps[1..]
        .iter()
        .zip(&merged.checks)
        .map(|(path, c)| {
            let name = path.display().to_string();
            match c.placed {
                Some(pose) => {
                    let mut entry = placed_entry(name, pose, c.confidence());
                    entry.extend([
                        ("confirmed".into(), json!(c.confirmed)),
                        ("drifted".into(), json!(c.confirmed.then_some(c.drifted))),
                        ("drift_m".into(), json!(c.confirmed.then_some(c.drift_m))),
                        ("agreement_at_start".into(), json!(c.loose_agreement)),
                        ("unconfirmed_because".into(), json!(c.unconfirmed_because())),
                    ]);
                    entry.into()
                }
                None => refused_entry(name, c.refusal.as_deref()),
            }
        })
        .collect();
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({ "maps": entries }))?
        );
        return Ok(());
    }
    for (path, c) in args.maps[1..].iter().zip(&merged.checks) {
        let name = path.display();
        match (c.placed, &c.refusal) {
            (Some(p), _) if c.confirmed => println!(
                "{name}: confirmed at x_m {:.3} y_m {:.3} yaw_rad {:.4} ({:.2} deg), confidence {:.2}, {:.2} m from its known start{}",
                p.x_m,
                p.y_m,
                p.yaw_rad,
                p.yaw_rad.to_degrees(),
                c.estimate.confidence,
                c.drift_m,
                match (c.drifted, c.moved) {
                    (false, _) => "",
                    (true, false) => {
                        " (drifted; kept at its known start, which nothing in the maps contradicts)"
                    }
                    (true, true) => " (drifted; the maps contradict its known start)",
                }
            ),
            (Some(_), _) => println!(
                "{name}: placed at its known start, unconfirmed ({})",
                c.unconfirmed_because().unwrap_or("no pose confirmed")
            ),
            (None, why) => println!(
                "{name}: refused: {}",
                why.as_deref().unwrap_or("not placed")
            ),
        }
    }
    let placed = 1 + merged.checks.iter().filter(|c| c.placed.is_some()).count();
    println!(
        "merged {placed} of {} maps into {}",
        args.maps.len(),
        yaml.display()
    );
    Ok(())
}

/// Writes the merged map's YAML + PGM and the contribution PNG beside it; returns the YAML.
fn write_merged(
    args: &MergeArgs,
    grid: &realms_core::Grid<MapCell>,
    contribution: &realms_core::Grid<u64>,
) -> Result<std::path::PathBuf> {
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let yaml = realms_merge::io::write(grid, &args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    write_contributions(
        grid,
        contribution,
        &args.out.with_extension("contributions.png"),
    )?;
    Ok(yaml)
}

/// `{"maps": [...]}`, one entry per map after the first.
fn report_json(args: &MergeArgs, merged: &Merged) -> serde_json::Value {
    let entries: Vec<serde_json::Value> = args
        .maps
        .iter()
        .zip(&merged.placements)
        .skip(1)
        .map(|(path, p)| {
            let name = path.display().to_string();
            match p.reference_from_map {
                Some(pose) => placed_entry(name, pose, p.confidence).into(),
                None => refused_entry(name, p.refusal.as_deref()),
            }
        })
        .collect();
    json!({ "maps": entries })
}

fn write_contributions(
    grid: &realms_core::Grid<MapCell>,
    contribution: &realms_core::Grid<u64>,
    path: &std::path::Path,
) -> Result<()> {
    let cells = grid.cells();
    let contributions = contribution.cells();
    let image = contribution.map(|_| [0u8; 3]);
    let colours: Vec<[u8; 3]> = cells
        .iter()
        .zip(contributions)
        .map(|(c, mask)| {
            if *mask == 0 {
                return [128, 128, 128];
            }
            if matches!(c, MapCell::Occupied | MapCell::Hazard) {
                return [0, 0, 0];
            }
            // The lowest-numbered contributing map's colour, lightened.
            let i = mask.trailing_zeros() as usize % PALETTE.len();
            PALETTE[i].map(|v| v / 2 + 128)
        })
        .collect();
    let image = realms_core::Grid::from_cells(*image.geometry(), colours)
        .context("contribution image size")?;
    image
        .write_png(path, |c| *c)
        .with_context(|| format!("writing {}", path.display()))
}
