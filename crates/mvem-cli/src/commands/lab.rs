//! `mvem lab`: the virtual test cell: a tuning campaign (stationary points, the dynamic sets of
//! the paper's Table 1, the actuator set J) generated from a parameter set, with noise.

use crate::common;
use anyhow::Result;
use mvem::params::Params;
use mvem::tuning::request::{self, LabSettings, RequestError, SettingError};
use std::path::PathBuf;

/// Arguments of `mvem lab`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem lab --out campaign                       # published parameters, seed 1, realistic noise
  mvem lab --out c2 --seed 7 --noise none --sensor-lags
  mvem lab --out small --sets B,C,I --max-steps 4 --n-stationary 30
  mvem lab --out c12 --model 12                 # virtual engine: the 12-state model
  mvem lab --params car.toml --speeds 1750:4250 --full-load 60 --out car   # another engine

Writes DIR/manifest.toml, DIR/stationary.csv, one CSV per data set (A-I, Q-V, J) and
DIR/true_params.toml (formats: docs/tuning-data.md). --noise: realistic (0.5 % relative on
pressures, flows, speeds, torque, x_egr, positions; 1 K on temperatures), none, or REL,KELVIN.
With --model 12 the stationary p_c is the pressure before the intercooler (above p_im by the
intercooler drop of eq. (86)); with 8 or 10 states p_c = p_im.")]
pub struct Args {
    /// Output directory (created).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Parameters of the virtual engine [default: the published set].
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Seed of the random generator (same seed, same campaign).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Measurement noise: realistic, none, or REL,KELVIN (e.g. 0.01,2).
    #[arg(long, default_value = "realistic", value_name = "SPEC")]
    pub noise: String,
    /// Number of stationary points (the 13 ESC points included, >= 13).
    #[arg(long = "n-stationary", default_value_t = 82, value_name = "N")]
    pub n_stationary: usize,
    /// Dynamometer time constant tau_Me of eq. (76) [s] (0: none).
    #[arg(long = "tau-me", default_value_t = 1.0, value_name = "S")]
    pub tau_me: f64,
    /// Apply the sensor time constants of the paper's Table 6 (n_t, p_em, p_im, W_c).
    #[arg(long = "sensor-lags")]
    pub sensor_lags: bool,
    /// Only these dynamic sets of Table 1 (comma separated, e.g. B,C,I).
    #[arg(long, value_name = "LIST")]
    pub sets: Option<String>,
    /// At most this many steps per dynamic set.
    #[arg(long = "max-steps", value_name = "N")]
    pub max_steps: Option<usize>,
    /// Stationary points and actuator set only (no Table 1 sets).
    #[arg(long = "no-dynamic")]
    pub no_dynamic: bool,
    /// Model of the virtual engine (number of states).
    #[arg(long, value_enum, default_value = "8")]
    pub model: common::ModelArg,
    /// The engine's ESC speeds n_lo:n_hi [r/min]: the design's speeds (ESC A/B/C at 25/50/75 %
    /// between them, idle, the random points, Table 1's sets) are the published engine's
    /// (900:2100) mapped onto them.
    #[arg(long, default_value = "900:2100", value_name = "LO:HI")]
    pub speeds: String,
    /// Injected fuel at 100 % load [mg/cycle/cylinder].
    #[arg(long = "full-load", default_value_t = 220.0, value_name = "MG")]
    pub full_load: f64,
}

/// Parse `--noise`.
pub fn run(a: &Args) -> Result<()> {
    let settings = LabSettings {
        seed: a.seed,
        noise: a.noise.clone(),
        n_stationary: a.n_stationary,
        tau_me: a.tau_me,
        sensor_lags: a.sensor_lags,
        sets: a
            .sets
            .as_ref()
            .map(|s| s.split(',').map(|x| x.trim().to_string()).collect()),
        max_steps: a.max_steps,
        dynamic: !a.no_dynamic,
        speeds: a.speeds.clone(),
        full_load: a.full_load,
    };
    let flag =
        |e: SettingError| common::usage(format!("--{}{}", e.field.replace('_', "-"), e.detail));
    let params = match &a.params {
        None => Params::published(),
        Some(p) => mvem::io::params::load_params(p)
            .map_err(|e| common::usage(format!("--params {}: {e}", p.display())))?,
    };
    let t = std::time::Instant::now();
    // everything is generated in memory before the first file is written
    let c = common::with_spinner("generating the campaign", || {
        request::write_lab_campaign(&a.out, &params, a.model.order(), &settings)
    })
    .map_err(|e| match e {
        RequestError::Setting(e) => flag(e),
        other => anyhow::Error::from(other),
    })?;
    let samples: usize = c.dynamic.iter().map(|d| d.t.len()).sum();
    eprintln!(
        "wrote {}: {} stationary points, {} data sets ({} samples), true parameters; {}",
        a.out.display(),
        c.stationary.len(),
        c.dynamic.len(),
        samples,
        common::fmt_duration(t.elapsed().as_secs_f64())
    );
    Ok(())
}
