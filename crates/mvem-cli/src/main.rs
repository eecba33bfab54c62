//! `mvem`: command-line front end of the mvem diesel engine model (Wahlström & Eriksson 2011).
//!
//! This file only parses the command line and dispatches; each subcommand lives in
//! `commands/`. Exit codes: 0 ok, 1 runtime or solver failure, 2 usage or input-file error.

// Index loops over small fixed-size state arrays read like the equations they implement.
#![allow(clippy::needless_range_loop)]

mod commands;
mod common;
mod outdir;
mod plot;
mod plot_maps;

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
  mvem linearize --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 75 --json
  mvem step --input u_vgt --from 75 --to 65 --n-e 1500 --u-delta 110 --u-egr 80 --plot step.png
  mvem map --axis u_egr=0:100:41 --axis u_vgt=20:100:41 --n-e 1500 --u-delta 110 --out map.csv --plot map.png
  mvem components --out out/components
  mvem report figs --out out/report
  mvem bench --repeat 3
  mvem compare-models --out out/compare-models
  mvem te-study --out out/te-study
  mvem params check my_params.toml
  mvem fmu --out mvem.fmu --model 10
  mvem robustness --runs 10000 --model all --out robustness.md
  mvem serve --open
  mvem closed-loop --cycle whtc --out out/closed-loop --plot

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
    /// Linear model (A, B, C, D) at a steady state: poles, transmission zeros, DC gains.
    Linearize(commands::linearize::Args),
    /// Step in any input at any operating point, with step-response metrics per output.
    Step(commands::step::Args),
    /// Steady states over a grid of inputs: CSV with validity flags, heat maps, DC-gain and
    /// RHP-zero (sign-reversal) maps of SISO channels.
    Map(commands::map::Args),
    /// Component maps like the paper's figures (compressor, turbine, EGR valve), with the
    /// operating points of a simulation overlaid.
    Components(commands::components::Args),
    /// Built-in reports: the paper's dynamic figures 8-12, the sign-reversal maps.
    Report(commands::report::Args),
    /// The authors' two VGT demonstration steps: CSVs, a figure and the W_c step metrics.
    Demo(commands::demo::Args),
    /// Simulation speed and accuracy on the WHTC cycle; cost of one model evaluation.
    Bench(commands::bench::Args),
    /// Show or check parameter sets.
    Params(commands::params::Args),
    /// Package an FMI 2.0 FMU (Model Exchange + Co-Simulation) of the 8-, 10- or 12-state model.
    Fmu(commands::fmu::Args),
    /// Virtual test cell: a tuning campaign generated from a parameter set, with noise.
    Lab(commands::lab::Args),
    /// What a tuning campaign holds and which tuning steps it supports (before tuning).
    Campaign(commands::campaign::Args),
    /// Parameter estimation: the paper's five tuning steps on a campaign.
    Tune(commands::tune::Args),
    /// Relative errors of a parameter set on a campaign: tables and figures.
    Validate(commands::validate::Args),
    /// The 8-, 10- and 12-state models after the paper's VGT steps (Figs 11-14): figures and tables.
    CompareModels(commands::compare_models::Args),
    /// Cylinder-out temperature with one fixed-point iteration vs converged on a cycle (Fig. 2).
    TeStudy(commands::te_study::Args),
    /// Robustness sweep: random inputs and start states; panics, NaN/inf, invariants.
    Robustness(commands::robustness::Args),
    /// Web explorer: a local page and JSON API (steady state, linearization, steps, maps,
    /// drive cycles).
    Serve(commands::serve::Args),
    /// A drive cycle (the WHTC or a speed/torque CSV) in closed loop: baseline EGR/VGT and
    /// torque controllers around the model; trajectory, cycle statistics, figures.
    ClosedLoop(commands::closed_loop::Args),
    /// Stability margins of the baseline controller's air-path loops at an operating point
    /// (gain, phase and delay margins, peak sensitivity; exact actuator delays).
    Margins(commands::margins::Args),
}

/// Restore the default SIGPIPE action so that `mvem ... | head` ends quietly when the reader
/// closes the pipe (Rust ignores SIGPIPE, which turns the closed pipe into a panic in `println!`).
fn reset_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called once at start-up, before any thread exists; SIG_DFL is a valid action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The cancellation token that SIGTERM and SIGINT cancel ([`on_termination`]), and the signal
/// that did (0: none).
static TERMINATION: std::sync::OnceLock<mvem::numerics::cancel::CancelToken> =
    std::sync::OnceLock::new();
static TERMINATED_BY: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

/// The handler of SIGTERM and SIGINT while a writer of large files runs: it only cancels the
/// token (an atomic store) and records the signal, both async-signal-safe, and restores the
/// default action, so that a second signal ends the process at once.
#[cfg(unix)]
extern "C" fn on_termination(sig: libc::c_int) {
    TERMINATED_BY.store(sig, std::sync::atomic::Ordering::SeqCst);
    if let Some(t) = TERMINATION.get() {
        t.cancel();
    }
    // SAFETY: signal() is async-signal-safe; SIG_DFL is a valid action.
    unsafe {
        libc::signal(sig, libc::SIG_DFL);
    }
}

/// Run `f` (a command that streams its output through a temporary file, `mvem closed-loop`,
/// `mvem simulate`) so that SIGTERM or SIGINT (Ctrl-C) stops it through its error path, which
/// removes the temporary file (`.NAME.tmp-PID`, left behind by a killed run before): the signal
/// cancels the core's cancellation token (`mvem::numerics::cancel`, polled by the integrator
/// before every step and by the margins analysis), the command fails and cleans up, and the
/// process then ends by the same signal (exit status 128 + its number for the shell). Not used
/// for commands that do not poll the token (`mvem serve` keeps the default actions).
fn with_termination_cleanup(f: impl FnOnce() -> anyhow::Result<()>) -> anyhow::Result<()> {
    let token = TERMINATION.get_or_init(mvem::numerics::cancel::CancelToken::new);
    #[cfg(unix)]
    // SAFETY: the handler only performs async-signal-safe operations (atomic stores, signal()).
    unsafe {
        let h = on_termination as extern "C" fn(libc::c_int) as libc::sighandler_t;
        libc::signal(libc::SIGTERM, h);
        libc::signal(libc::SIGINT, h);
    }
    let r = mvem::numerics::cancel::with_token(token, f);
    let sig = TERMINATED_BY.load(std::sync::atomic::Ordering::SeqCst);
    #[cfg(unix)]
    if sig != 0 {
        if let Err(e) = &r {
            eprintln!("error: {}", common::error_message(e));
        }
        // SAFETY: the handler restored the default action, which ends the process.
        unsafe {
            libc::raise(sig);
        }
    }
    let _ = sig;
    r
}

fn main() -> ExitCode {
    reset_sigpipe();
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
        Command::Simulate(a) => with_termination_cleanup(|| commands::simulate::run(a)),
        Command::Steady(a) => commands::steady::run(a),
        Command::Margins(a) => commands::margins::run(a),
        Command::Linearize(a) => commands::linearize::run(a),
        Command::Step(a) => commands::step::run(a),
        Command::Map(a) => commands::map::run(a),
        Command::Components(a) => commands::components::run(a),
        Command::Report(a) => commands::report::run(a),
        Command::Demo(a) => commands::demo::run(a),
        Command::Bench(a) => commands::bench::run(a),
        Command::Params(a) => commands::params::run(a),
        Command::Fmu(a) => commands::fmu::run(a),
        Command::Lab(a) => commands::lab::run(a),
        Command::Tune(a) => commands::tune::run(a),
        Command::Validate(a) => commands::validate::run(a),
        Command::Campaign(a) => commands::campaign::run(a),
        Command::CompareModels(a) => commands::compare_models::run(a),
        Command::TeStudy(a) => commands::te_study::run(a),
        Command::Robustness(a) => commands::robustness::run(a),
        Command::Serve(a) => commands::serve::run(a),
        Command::ClosedLoop(a) => with_termination_cleanup(|| commands::closed_loop::run(a)),
    };
    match result {
        Ok(()) => ExitCode::from(common::EXIT_OK),
        Err(e) => {
            eprintln!("error: {}", common::error_message(&e));
            ExitCode::from(common::exit_code(&e))
        }
    }
}
