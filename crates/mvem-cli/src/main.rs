//! `mvem`: command-line front end of the mvem diesel engine model (Wahlström & Eriksson 2011).
//!
//! This file only parses the command line and dispatches; each subcommand lives in
//! `commands/`. Exit codes: 0 ok, 1 runtime or solver failure, 2 usage or input-file error.

// Index loops over small fixed-size state arrays read like the equations they implement.
#![allow(clippy::needless_range_loop)]

mod commands;
mod common;
mod plot;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Mean-value model of a diesel engine with VGT and EGR (Wahlström & Eriksson 2011).
#[derive(Debug, Parser)]
#[command(
    name = "mvem",
    version,
    after_help = "\
Examples:
  mvem demo
  mvem simulate --scenario vgt-step-nmp --out step.csv --plot step.svg
  mvem simulate --inputs data/whtc_inputs_10hz.csv --out whtc.csv --dt 0.1
  mvem steady --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 75 --json
  mvem bench --repeat 3
  mvem params check my_params.toml
  mvem robustness --runs 10000 --model all --out robustness.md

Exit codes: 0 ok, 1 runtime or solver failure, 2 usage or input-file error."
)]
struct Cli {
    #[command(subcommand)]
    cmd: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate an input time series or a built-in scenario; write every state and signal to CSV.
    Simulate(commands::simulate::Args),
    /// Steady state (equilibrium) at constant inputs, with validity flags and eigenvalues.
    Steady(commands::steady::Args),
    /// The authors' two VGT demonstration steps: CSVs, a figure and the W_c step metrics.
    Demo(commands::demo::Args),
    /// Simulation speed and accuracy on the WHTC cycle; cost of one model evaluation.
    Bench(commands::bench::Args),
    /// Show or check parameter sets.
    Params(commands::params::Args),
    /// Robustness sweep: random inputs and start states; panics, NaN/inf, invariants.
    Robustness(commands::robustness::Args),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            // help and version go to stdout with code 0; usage errors to stderr with code 2
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() {
                common::EXIT_USAGE
            } else {
                common::EXIT_OK
            });
        }
    };
    let result = match &cli.cmd {
        Command::Simulate(a) => commands::simulate::run(a),
        Command::Steady(a) => commands::steady::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::Bench(a) => commands::bench::run(a),
        Command::Params(a) => commands::params::run(a),
        Command::Robustness(a) => commands::robustness::run(a),
    };
    match result {
        Ok(()) => ExitCode::from(common::EXIT_OK),
        Err(e) => {
            eprintln!("error: {}", common::error_message(&e));
            ExitCode::from(common::exit_code(&e))
        }
    }
}
