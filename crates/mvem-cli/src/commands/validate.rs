//! `mvem validate`: relative errors (eqs (4), (5)) of a parameter set on a campaign, as tables
//! like the paper's Tables 2-4, with figures of measured versus simulated signals.

use crate::common;
use crate::plot::{self, Figure, Panel, Series};
use anyhow::Result;
use mvem::tuning::data::StepKind;
use mvem::tuning::request::{self, RequestError};
use mvem::tuning::sensors::SensorLags;
use mvem::tuning::validate::{self as v, ValidationReport};
use serde_json::Value;
use std::path::PathBuf;

/// Arguments of `mvem validate`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem validate --data campaign --params tuned.toml --tau-me 1.0
  mvem validate --data campaign --params tuned.toml --roles validation --json
  mvem validate --data campaign --params tuned.toml --report val   # tables + figures

Tables: the stationary submodels (eq. (4): mean and max absolute relative error, per cent) and
the dynamic sets (eq. (5): mean absolute relative error per set and output, per cent, like the
paper's Tables 2-4). --json prints {\"datasets\": {SET: {OUTPUT: percent}}, \"stationary\":
{SUBMODEL: percent}}. --report DIR writes validation.md, validation.csv, validation.json and
one figure per set (SET.png, measured vs simulated). --tau-me applies the dynamometer lag of
eq. (76) to the simulated torque; without it the value in the parameter file's [test_cell]
section (written by `mvem tune`) is used, if any; likewise the sensor time constants of p_im,
p_em, W_c and n_t (--sensor-lags overrides: none, table6 or p_im=0.015,p_em=0.02,...).
--model 12 simulates the
12-state model and adds the intercooler flow W_ic (eq. (86), z_8 of section 9.2.1) to the
stationary table.")]
pub struct Args {
    /// Campaign directory.
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Parameter file to validate.
    #[arg(long, value_name = "FILE")]
    pub params: PathBuf,
    /// Dynamometer time constant tau_Me [s] of eq. (76) [default: `tau_me` of the parameter
    /// file's [test_cell] section; without it the torque is compared unfiltered].
    #[arg(long = "tau-me", value_name = "S")]
    pub tau_me: Option<f64>,
    /// Sensor time constants of p_im, p_em, W_c, n_t applied to the simulated outputs: `none`,
    /// `table6` or `p_im=0.015,p_em=0.02,W_c=0.02,n_t=0.006` [s] [default: those of the
    /// parameter file's [test_cell] section; without them none].
    #[arg(long = "sensor-lags", value_name = "none|table6|LIST")]
    pub sensor_lags: Option<String>,
    /// Only data sets with one of these roles (comma separated: static, dynamic, actuator,
    /// validation) [default: all].
    #[arg(long, value_name = "LIST")]
    pub roles: Option<String>,
    /// Print one JSON object (per data set and output: mean abs. rel. error in per cent).
    #[arg(long)]
    pub json: bool,
    /// Report directory (created): tables and figures.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Model simulated (number of states).
    #[arg(long, value_enum, default_value = "8")]
    pub model: common::ModelArg,
}

/// The JSON object of `--json` (and `validation.json`).
pub fn json(r: &ValidationReport) -> Value {
    r.summary_json()
}

/// Run `mvem validate`.
pub fn run(a: &Args) -> Result<()> {
    // the settings first: a bad one is refused before any file is read
    if let Some(t) = a.tau_me {
        if !(t.is_finite() && t > 0.0) {
            return Err(common::usage(format!("--tau-me {t}: must be > 0")));
        }
    }
    if let Some(r) = a.roles.as_deref() {
        request::parse_roles(r).map_err(|e| common::usage(format!("--{e}")))?;
    }
    if let Some(r) = &a.report {
        if r.exists() && !r.is_dir() {
            return Err(common::usage(format!(
                "--report {}: exists and is not a directory",
                r.display()
            )));
        }
    }
    let p = mvem::io::params::load_params(&a.params)
        .map_err(|e| common::usage(format!("--params {}: {e}", a.params.display())))?;
    // the tuned dynamometer constant and sensor lags of the file's [test_cell] section
    let cell = mvem::io::test_cell::load_test_cell(&a.params)
        .map_err(|e| common::usage(format!("--params {}: {e}", a.params.display())))?;
    let run = common::with_spinner("validating", || {
        request::validate_campaign(
            &a.data,
            &p,
            cell.as_ref(),
            a.model.order(),
            a.tau_me,
            a.sensor_lags.as_deref(),
            a.roles.as_deref(),
        )
    })
    .map_err(|e| match e {
        RequestError::Setting(e) => {
            common::usage(format!("--{}{}", e.field.replace('_', "-"), e.detail))
        }
        RequestError::Data(e) => common::usage(e.to_string()),
        other => anyhow::Error::from(other),
    })?;
    for m in &run.messages {
        eprintln!("{m}");
    }
    let (rep, c, tau_me, lags) = (&run.report, &run.campaign, run.tau_me, &run.sensor_lags);
    let md = rep.to_markdown();
    if let Some(dir) = &a.report {
        // render every file in memory first
        let mut files: Vec<(String, Vec<u8>)> = vec![
            ("validation.md".into(), md.clone().into_bytes()),
            ("validation.csv".into(), rep.to_csv().into_bytes()),
            (
                "validation.json".into(),
                serde_json::to_string_pretty(&json(rep))?.into_bytes(),
            ),
        ];
        for (info, d) in c.manifest.datasets.iter().zip(&c.dynamic) {
            if !rep.datasets.iter().any(|x| x.name == d.name) {
                continue;
            }
            let fig = match info.kind {
                StepKind::Actuator => actuator_figure(&p, d),
                _ => dynamic_figure(a.model.order(), &p, d, tau_me, lags)?,
            };
            files.push((
                format!("{}.png", d.name),
                plot::render(&fig, plot::Format::Png)?,
            ));
        }
        std::fs::create_dir_all(dir)
            .map_err(|e| common::usage(format!("--report {}: {e}", dir.display())))?;
        for (name, bytes) in &files {
            mvem::io::output::write_atomic(&dir.join(name), bytes)?;
        }
        eprintln!("wrote {} files to {}", files.len(), dir.display());
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&json(rep))?);
    } else {
        print!("{md}");
    }
    Ok(())
}

fn unit_scale(name: &str) -> (f64, &'static str) {
    match name {
        "p_im" | "p_em" => (1e-3, "kPa"),
        "W_c" => (1.0, "kg/s"),
        "n_t" => (1e-3, "krpm"),
        "M_e" => (1.0, "Nm"),
        _ => (1.0, "%"),
    }
}

fn dynamic_figure(
    order: mvem::model::ModelOrder,
    p: &mvem::params::Params,
    d: &mvem::tuning::data::DynamicData,
    tau_me: Option<f64>,
    lags: &SensorLags,
) -> Result<Figure> {
    let rtol = mvem::sim::SimOptions::default().rtol;
    let sims = v::simulated_outputs(order, p, d, tau_me, lags, rtol)
        .map_err(|e| anyhow::anyhow!("data set {}: {e}", d.name))?;
    let mut fig = Figure::new(1);
    fig.title = Some(format!("data set {}: measured vs simulated", d.name));
    for (name, sim) in &sims {
        let Some(meas) = d.get(name) else { continue };
        let (k, u) = unit_scale(name);
        let scale = |v: &[f64]| v.iter().map(|x| x * k).collect::<Vec<f64>>();
        let label = if *name == "M_e" && tau_me.is_some() {
            "simulated (dynamometer lag)"
        } else {
            "simulated"
        };
        fig.panels.push(
            Panel::new("time [s]", format!("{name} [{u}]"))
                .with(Series::line("measured", &d.t, &scale(meas), 0))
                .with(Series::dashed(label, &d.t, &scale(sim), 1)),
        );
    }
    Ok(fig)
}

fn actuator_figure(p: &mvem::params::Params, d: &mvem::tuning::data::DynamicData) -> Figure {
    let mut fig = Figure::new(1);
    fig.title = Some(format!("data set {}: actuator positions", d.name));
    for (cmd, pos, egr) in [("u_egr", "u_egr_pos", true), ("u_vgt", "u_vgt_pos", false)] {
        let (Some(u), Some(y)) = (d.get(cmd), d.get(pos)) else {
            continue;
        };
        let model = mvem::tuning::steps::actuator_response(p, &d.t, u, egr);
        fig.panels.push(
            Panel::new("time [s]", format!("{pos} [%]"))
                .with(Series::line("measured", &d.t, y, 0))
                .with(Series::dashed("model", &d.t, &model, 1))
                .with(Series::line("command", &d.t, u, 2)),
        );
    }
    fig
}
