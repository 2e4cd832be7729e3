//! `realms bench compare`: two `realms bench missions --json` runs on the same seeds, set side
//! by side mission by mission, with how far chance alone could move each figure.
//!
//! Any change to a rover's SLAM or navigation sends the rovers along other paths, and single
//! rovers' grades then swing by tens of points both ways (BENCHMARKS.md). A difference of
//! sixteen missions' means is only worth reading beside the spread such swings give it. This
//! pairs the missions by seed and draws the missions again with replacement (a paired
//! bootstrap, Efron & Tibshirani, "An Introduction to the Bootstrap", 1993): the interval
//! that holds the middle 95 % of the redrawn differences is how sure the difference is. An
//! interval that holds 0 says the runs do not tell the two setups apart.

use crate::bench::{mean, pooled};
use crate::cli::BenchCompareArgs;
use anyhow::{Context, Result, bail};
use rand::{Rng, SeedableRng};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// What one mission holds for the figures compared: its rovers' grades, the lander's merged
/// map and the mission's length.
#[derive(Clone, Debug, PartialEq)]
struct Mission {
    rovers: Vec<Rover>,
    merged: Option<f64>,
    length_s: f64,
}

/// One rover's grades, as `bench missions --json` names them.
#[derive(Clone, Debug, PartialEq)]
struct Rover {
    occupied_correct: Option<f64>,
    trajectory_rmse_m: Option<f64>,
    pose_within_0_2_m: f64,
    /// Crater cells near the path ...
    path_hazards: usize,
    /// ... and the share of them marked.
    path_hazards_flagged: f64,
}

/// A figure over a set of missions, as `bench missions` sums it up.
struct Figure {
    name: &'static str,
    unit: Unit,
    /// Whether a larger value is the better one.
    higher_is_better: bool,
    over: fn(&[&Mission]) -> Option<f64>,
}

#[derive(Clone, Copy)]
enum Unit {
    Percent,
    Metres,
    Seconds,
}

impl Unit {
    fn show(self, v: f64) -> String {
        match self {
            Unit::Percent => format!("{:.2} %", 100.0 * v),
            Unit::Metres => format!("{v:.4} m"),
            Unit::Seconds => format!("{v:.0} s"),
        }
    }
}

/// The mean over every rover of the missions of what `of` gives it (rovers without it left
/// out).
fn rover_mean(missions: &[&Mission], of: impl Fn(&Rover) -> Option<f64>) -> Option<f64> {
    mean_of(
        missions
            .iter()
            .flat_map(|m| m.rovers.iter().filter_map(&of)),
    )
}

/// The mean of `values`; none without any.
fn mean_of(values: impl Iterator<Item = f64>) -> Option<f64> {
    let values: Vec<f64> = values.collect();
    (!values.is_empty()).then(|| mean(&values))
}

const FIGURES: &[Figure] = &[
    Figure {
        name: "occupied cells right, mean rover",
        unit: Unit::Percent,
        higher_is_better: true,
        over: |m| rover_mean(m, |r| r.occupied_correct),
    },
    Figure {
        name: "final trajectory RMS, mean rover",
        unit: Unit::Metres,
        higher_is_better: false,
        over: |m| rover_mean(m, |r| r.trajectory_rmse_m),
    },
    Figure {
        name: "published pose within 0.2 m, mean rover",
        unit: Unit::Percent,
        higher_is_better: true,
        over: |m| rover_mean(m, |r| Some(r.pose_within_0_2_m)),
    },
    Figure {
        name: "crater cells near the paths marked, all rovers",
        unit: Unit::Percent,
        higher_is_better: true,
        over: |missions| {
            let rovers = || missions.iter().flat_map(|m| &m.rovers);
            (rovers().any(|r| r.path_hazards > 0))
                .then(|| pooled(rovers().map(|r| (r.path_hazards_flagged, r.path_hazards))))
        },
    },
    Figure {
        name: "lander's merged map, mean",
        unit: Unit::Percent,
        higher_is_better: true,
        over: |missions| mean_of(missions.iter().filter_map(|m| m.merged)),
    },
    Figure {
        name: "mission length, mean",
        unit: Unit::Seconds,
        higher_is_better: false,
        over: |missions| mean_of(missions.iter().map(|m| m.length_s)),
    },
];

/// `value[key]` as a number; an error naming the file, the mission and the field otherwise.
fn number(value: &Value, key: &str, whence: &str) -> Result<f64> {
    value
        .get(key)
        .and_then(Value::as_f64)
        .with_context(|| format!("{whence}: `{key}` is missing or not a number"))
}

/// `value[key]` as a number, `null` or absent being none.
fn optional(value: &Value, key: &str, whence: &str) -> Result<Option<f64>> {
    match value.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => v
            .as_f64()
            .map(Some)
            .with_context(|| format!("{whence}: `{key}` is not a number")),
    }
}

/// The missions of one `bench missions --json` output, by seed.
fn parse(text: &str, file: &Path) -> Result<BTreeMap<u64, Mission>> {
    let name = file.display();
    let root: Value = serde_json::from_str(text)
        .with_context(|| format!("{name}: not the JSON `realms bench missions --json` prints"))?;
    let Some(missions) = root.get("missions").and_then(Value::as_array) else {
        bail!("{name}: no `missions` list (is it `realms bench missions --json` output?)");
    };
    let mut by_seed = BTreeMap::new();
    for (i, m) in missions.iter().enumerate() {
        let whence = format!("{name}, mission {}", i + 1);
        let seed = m
            .get("seed")
            .and_then(Value::as_u64)
            .with_context(|| format!("{whence}: `seed` is missing or not a whole number"))?;
        let whence = format!("{name}, seed {seed}");
        let Some(rovers) = m.get("rovers").and_then(Value::as_array) else {
            bail!("{whence}: no `rovers` list");
        };
        let rovers = rovers
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let whence = format!("{whence}, rover {}", k + 1);
                Ok(Rover {
                    occupied_correct: optional(r, "occupied_correct", &whence)?,
                    trajectory_rmse_m: optional(r, "trajectory_rmse_m", &whence)?,
                    pose_within_0_2_m: number(r, "pose_within_0_2_m", &whence)?,
                    path_hazards: r
                        .get("path_hazards")
                        .and_then(Value::as_u64)
                        .and_then(|n| usize::try_from(n).ok())
                        .with_context(|| {
                            format!("{whence}: `path_hazards` is missing or not a whole number")
                        })?,
                    path_hazards_flagged: number(r, "path_hazards_flagged", &whence)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let mission = Mission {
            rovers,
            merged: optional(m, "merged_occupied_correct", &whence)?,
            length_s: number(m, "sim_duration_s", &whence)?,
        };
        if by_seed.insert(seed, mission).is_some() {
            bail!("{whence}: the seed comes twice");
        }
    }
    Ok(by_seed)
}

/// One figure compared: both runs' values, the intervals holding the middle 95 % of the
/// baseline's figure and of the differences over `resamples` redrawings of the paired
/// missions, and how many missions came out better and worse on their own.
#[derive(Clone, Debug, PartialEq)]
struct Compared {
    baseline: f64,
    candidate: f64,
    /// The middle 95 % of the baseline's own figure over the redrawings.
    baseline_interval: (f64, f64),
    interval: (f64, f64),
    better: usize,
    worse: usize,
}

fn compare(
    figure: &Figure,
    pairs: &[(&Mission, &Mission)],
    resamples: usize,
    rng: &mut impl Rng,
) -> Option<Compared> {
    let (a, b): (Vec<&Mission>, Vec<&Mission>) = pairs.iter().copied().unzip();
    let baseline = (figure.over)(&a)?;
    let candidate = (figure.over)(&b)?;
    let (mut better, mut worse) = (0, 0);
    for (x, y) in pairs {
        if let (Some(x), Some(y)) = ((figure.over)(&[x]), (figure.over)(&[y])) {
            let gain = if figure.higher_is_better {
                y - x
            } else {
                x - y
            };
            if gain > 0.0 {
                better += 1;
            } else if gain < 0.0 {
                worse += 1;
            }
        }
    }
    let mut differences = Vec::with_capacity(resamples);
    let mut baselines = Vec::with_capacity(resamples);
    let (mut ra, mut rb) = (
        Vec::with_capacity(pairs.len()),
        Vec::with_capacity(pairs.len()),
    );
    for _ in 0..resamples {
        ra.clear();
        rb.clear();
        for _ in 0..pairs.len() {
            let (x, y) = pairs[rng.random_range(0..pairs.len())];
            ra.push(x);
            rb.push(y);
        }
        if let (Some(x), Some(y)) = ((figure.over)(&ra), (figure.over)(&rb)) {
            differences.push(y - x);
            baselines.push(x);
        }
    }
    let middle_95 = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let at = |q: f64| {
            let i = ((v.len() as f64 - 1.0) * q).round() as usize;
            v.get(i).copied().unwrap_or(f64::NAN)
        };
        (at(0.025), at(0.975))
    };
    Some(Compared {
        baseline,
        candidate,
        baseline_interval: middle_95(baselines),
        interval: middle_95(differences),
        better,
        worse,
    })
}

/// `realms bench compare`.
pub fn run(args: BenchCompareArgs) -> Result<()> {
    let read = |path: &Path| -> Result<BTreeMap<u64, Mission>> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        parse(&text, path)
    };
    let (a, b) = (read(&args.baseline)?, read(&args.candidate)?);
    let pairs: Vec<(&Mission, &Mission)> = a
        .iter()
        .filter_map(|(seed, x)| b.get(seed).map(|y| (x, y)))
        .collect();
    if pairs.is_empty() {
        bail!(
            "{} and {} share no seed: compare runs over the same seeds",
            args.baseline.display(),
            args.candidate.display()
        );
    }
    let only = a.len() + b.len() - 2 * pairs.len();
    println!("# realms bench compare");
    println!();
    println!(
        "baseline {}, candidate {}: {} missions paired by seed{}; the interval holds the middle 95 % of the differences over {} redrawings of the pairs (a paired bootstrap: an interval holding 0 does not tell the two apart)",
        args.baseline.display(),
        args.candidate.display(),
        pairs.len(),
        if only > 0 {
            format!(" ({only} in one run only, left out)")
        } else {
            String::new()
        },
        args.resamples
    );
    println!();
    println!(
        "| figure | baseline (its own 95 % interval) | candidate | difference | 95 % interval of the difference | missions better / worse |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for figure in FIGURES {
        let Some(c) = compare(figure, &pairs, args.resamples, &mut rng) else {
            continue;
        };
        let signed = |v: f64| {
            let shown = figure.unit.show(v.abs());
            if v < 0.0 {
                format!("-{shown}")
            } else {
                format!("+{shown}")
            }
        };
        println!(
            "| {} | {} ({} to {}) | {} | {} | {} to {} | {} / {} |",
            figure.name,
            figure.unit.show(c.baseline),
            figure.unit.show(c.baseline_interval.0),
            figure.unit.show(c.baseline_interval.1),
            figure.unit.show(c.candidate),
            signed(c.candidate - c.baseline),
            signed(c.interval.0),
            signed(c.interval.1),
            c.better,
            c.worse
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mission(pose: f64, rmse: f64, length_s: f64) -> Mission {
        Mission {
            rovers: vec![Rover {
                occupied_correct: Some(0.9),
                trajectory_rmse_m: Some(rmse),
                pose_within_0_2_m: pose,
                path_hazards: 100,
                path_hazards_flagged: 0.95,
            }],
            merged: Some(0.9),
            length_s,
        }
    }

    fn figure(name: &str) -> &'static Figure {
        FIGURES
            .iter()
            .find(|f| f.name.starts_with(name))
            .expect("a figure of that name")
    }

    #[test]
    fn a_steady_gain_is_told_apart_from_chance_and_swings_both_ways_are_not() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        // Every mission's pose 2 points better, give or take a tenth: the interval is about
        // the gain and leaves 0 out.
        let base: Vec<Mission> = (0..16)
            .map(|i| mission(0.90, 0.08, 2500.0 + i as f64))
            .collect();
        let steady: Vec<Mission> = (0..16)
            .map(|i| mission(0.92 + 0.001 * (i % 3) as f64, 0.08, 2500.0))
            .collect();
        let pairs: Vec<_> = base.iter().zip(&steady).collect();
        let c = compare(figure("published pose"), &pairs, 2000, &mut rng)
            .expect("both runs have poses");
        assert!((c.candidate - c.baseline - 0.021).abs() < 0.001, "{c:?}");
        assert!(c.interval.0 > 0.015 && c.interval.1 < 0.025, "{c:?}");
        // The baseline's own interval is about its 90 %, which every mission has.
        assert!((c.baseline_interval.0 - 0.9).abs() < 1e-9, "{c:?}");
        assert!((c.baseline_interval.1 - 0.9).abs() < 1e-9, "{c:?}");
        assert_eq!((c.better, c.worse), (16, 0));
        // Half the missions 9 points better and half 7 worse: a mean gain of a point, an
        // interval that holds 0.
        let swinging: Vec<Mission> = (0..16)
            .map(|i| mission(if i % 2 == 0 { 0.99 } else { 0.83 }, 0.08, 2500.0))
            .collect();
        let pairs: Vec<_> = base.iter().zip(&swinging).collect();
        let c = compare(figure("published pose"), &pairs, 2000, &mut rng)
            .expect("both runs have poses");
        assert!((c.candidate - c.baseline - 0.01).abs() < 1e-9, "{c:?}");
        assert!(c.interval.0 < 0.0 && c.interval.1 > 0.0, "{c:?}");
        assert_eq!((c.better, c.worse), (8, 8));
        // Lower is better for the trajectory's error and the mission's length.
        let shorter: Vec<Mission> = (0..16).map(|_| mission(0.90, 0.07, 2400.0)).collect();
        let pairs: Vec<_> = base.iter().zip(&shorter).collect();
        for name in ["final trajectory", "mission length"] {
            let c = compare(figure(name), &pairs, 200, &mut rng).expect("both runs have it");
            assert_eq!((c.better, c.worse), (16, 0), "{name}");
        }
    }

    #[test]
    fn crater_cells_are_pooled_over_every_rover_as_bench_missions_pools_them() {
        let mut a = mission(0.9, 0.08, 2500.0);
        a.rovers[0].path_hazards = 300;
        a.rovers[0].path_hazards_flagged = 0.9;
        let b = mission(0.9, 0.08, 2500.0);
        // (270 + 95) of (300 + 100) cells, not the mean of 90 and 95 %.
        let pooled = (figure("crater").over)(&[&a, &b]).expect("crater cells near the paths");
        assert!((pooled - 365.0 / 400.0).abs() < 1e-12, "{pooled}");
    }

    #[test]
    fn bad_files_say_which_mission_and_field() {
        let file = Path::new("run.json");
        let err = |text: &str| format!("{:#}", parse(text, file).expect_err("a bad file"));
        assert!(err("not json").contains("run.json: not the JSON"));
        assert!(err(r#"{"summary": {}}"#).contains("no `missions` list"));
        let missing = r#"{"missions": [{"seed": 4, "sim_duration_s": 10, "rovers": [{"pose_within_0_2_m": 0.9, "path_hazards": 3}]}]}"#;
        let e = err(missing);
        assert!(e.contains("seed 4, rover 1: `path_hazards_flagged`"), "{e}");
        let twice = r#"{"missions": [{"seed": 4, "sim_duration_s": 10, "rovers": []}, {"seed": 4, "sim_duration_s": 10, "rovers": []}]}"#;
        assert!(err(twice).contains("seed 4: the seed comes twice"));
        let ok = r#"{"missions": [{"seed": 4, "sim_duration_s": 10, "merged_occupied_correct": null, "rovers": [{"occupied_correct": null, "trajectory_rmse_m": 0.1, "pose_within_0_2_m": 0.9, "path_hazards": 3, "path_hazards_flagged": 1.0}]}]}"#;
        let parsed = parse(ok, file).expect("a good file");
        assert_eq!(parsed[&4].rovers[0].occupied_correct, None);
        assert_eq!(parsed[&4].merged, None);
    }
}
