//! `realms`: the command line of the realms multi-rover mission framework.
//!
//! Parsing happens in two steps (ripgrep's habit): clap turns flags into [`cli::Args`], and
//! each subcommand resolves them into settings before doing anything. This binary is the only
//! place that reads the wall clock.

// The binary is the one place allowed to read the wall clock (progress, wall time, benches).
#![allow(clippy::disallowed_methods)]

mod bench;
mod bench_compare;
mod bench_logs;
mod bench_merge;
mod bench_merge_rovers;
mod bench_missions;
mod bench_nav;
mod bench_net;
mod bench_slam;
mod bench_slam_closures;
mod bench_slam_drift;
mod bench_slip;
mod cli;
mod merge;
mod mission;
mod slam;

use clap::Parser;

fn main() -> std::process::ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("REALMS_LOG")
                .unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = cli::Args::parse();
    let result = match args.command {
        cli::Command::Mission(m) => mission::run(m),
        cli::Command::Scenario(s) => mission::scenario(s),
        cli::Command::Bench(b) => bench::run(b),
        cli::Command::Slam(a) => slam::run(a),
        cli::Command::SlamEval(a) => slam::eval(a),
        cli::Command::Merge(a) => merge::run(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
