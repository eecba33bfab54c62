//! `mvem lab`: the virtual test cell: a tuning campaign (stationary points, the dynamic sets of
//! the paper's Table 1, the actuator set J) generated from a parameter set, with noise.

use crate::common;
use anyhow::Result;
use mvem::params::Params;
use mvem::tuning::lab::{self, LabOptions, Noise};
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
pub fn parse_noise(s: &str) -> Result<Noise> {
    match s {
        "realistic" => Ok(Noise::REALISTIC),
        "none" => Ok(Noise::NONE),
        _ => {
            let bad = || {
                common::usage(format!(
                    "--noise {s:?}: expected realistic, none or REL,KELVIN (e.g. 0.005,1)"
                ))
            };
            let (a, b) = s.split_once(',').ok_or_else(bad)?;
            let rel: f64 = a.trim().parse().map_err(|_| bad())?;
            let temp_k: f64 = b.trim().parse().map_err(|_| bad())?;
            if !(rel.is_finite()
                && (0.0..0.5).contains(&rel)
                && temp_k.is_finite()
                && temp_k >= 0.0)
            {
                return Err(common::usage(format!(
                    "--noise {s:?}: REL must be in [0, 0.5), KELVIN >= 0"
                )));
            }
            Ok(Noise { rel, temp_k })
        }
    }
}

/// Run `mvem lab`.
pub fn run(a: &Args) -> Result<()> {
    let noise = parse_noise(&a.noise)?;
    if a.n_stationary < 13 {
        return Err(common::usage(format!(
            "--n-stationary {}: at least 13 (the ESC points)",
            a.n_stationary
        )));
    }
    if !(a.tau_me.is_finite() && a.tau_me >= 0.0) {
        return Err(common::usage(format!(
            "--tau-me {}: must be >= 0",
            a.tau_me
        )));
    }
    let sets = match &a.sets {
        None => None,
        Some(s) => {
            let v: Vec<String> = s.split(',').map(|x| x.trim().to_string()).collect();
            for n in &v {
                if !lab::TABLE1.iter().any(|r| r.name == n) {
                    return Err(common::usage(format!(
                        "--sets: unknown data set {n:?} (Table 1: A-I, Q-V)"
                    )));
                }
            }
            Some(v)
        }
    };
    if a.max_steps == Some(0) {
        return Err(common::usage("--max-steps 0: at least 1"));
    }
    if a.out.exists() && !a.out.is_dir() {
        return Err(common::usage(format!(
            "--out {}: exists and is not a directory",
            a.out.display()
        )));
    }
    let params = match &a.params {
        None => Params::published(),
        Some(p) => mvem::io::params::load_params(p)
            .map_err(|e| common::usage(format!("--params {}: {e}", p.display())))?,
    };
    let bad = || common::usage(format!("--speeds {:?}: expected LO:HI in r/min", a.speeds));
    let (lo, hi) = a.speeds.split_once(':').ok_or_else(bad)?;
    let envelope = lab::Envelope {
        n_lo_rpm: lo.trim().parse().map_err(|_| bad())?,
        n_hi_rpm: hi.trim().parse().map_err(|_| bad())?,
        full_load_mg: a.full_load,
    };
    envelope
        .validate(&params.input_saturation)
        .map_err(|e| common::usage(format!("--speeds/--full-load: {e}")))?;
    let opts = LabOptions {
        envelope,
        seed: a.seed,
        noise,
        n_stationary: a.n_stationary,
        dynamic: !a.no_dynamic,
        sets,
        max_steps: a.max_steps,
        tau_me_s: a.tau_me,
        sensor_lags: a.sensor_lags,
        model: a.model.order(),
        ..LabOptions::default()
    };
    let t = std::time::Instant::now();
    // everything is generated in memory before the first file is written
    let c = common::with_spinner("generating the campaign", || lab::campaign(&params, &opts))
        .map_err(|e| anyhow::anyhow!("virtual test cell: {e}"))?
        .0;
    mvem::tuning::data::save_campaign(&a.out, &c)
        .map_err(|e| anyhow::anyhow!("writing the campaign: {e}"))?;
    mvem::io::params::save_params(&params, &a.out.join("true_params.toml"))?;
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
