//! `mvem step`: a step in any input at any operating point, simulated with the nonlinear model,
//! with step-response metrics per output (wrong-way excursion, overshoot, rise and settling
//! time, DC gain and its sign; definitions in `mvem::analysis::step`).

use crate::common::{self, ModelArgs, SolverArgs};
use crate::plot::{self, Figure, Panel, Series};
use anyhow::{Context, Result};
use clap::ValueEnum;
use mvem::analysis::experiment::{self, OutputError, StepSpec};
use mvem::analysis::json::step_json;
use mvem::analysis::linearize::DEFAULT_OUTPUTS;
use mvem::analysis::step::StepMetrics;
use mvem::model::{Drive, Model};
use mvem::sim::{SimOptions, Solution};
use serde_json::Value;
use std::path::PathBuf;

/// An input channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InputArg {
    /// Engine speed [rpm].
    #[value(name = "n_e")]
    NE,
    /// Injected fuel [mg/cycle/cylinder].
    #[value(name = "u_delta")]
    UDelta,
    /// EGR valve command [%].
    #[value(name = "u_egr")]
    UEgr,
    /// VGT command [%].
    #[value(name = "u_vgt")]
    UVgt,
}

impl InputArg {
    /// Index in [`Drive::to_array`] (and the channel of [`InputSchedule::steps`]).
    pub fn slot(self) -> usize {
        match self {
            InputArg::NE => 0,
            InputArg::UDelta => 1,
            InputArg::UEgr => 2,
            InputArg::UVgt => 3,
        }
    }

    /// Name (`u_vgt`).
    pub fn name(self) -> &'static str {
        Drive::NAMES[self.slot()]
    }
}

/// Arguments of `mvem step`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem step --input u_vgt --from 75 --to 65 --n-e 1500 --u-delta 110 --u-egr 80
  mvem step --input u_vgt --to 25 --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 30 --json
  mvem step --input u_egr --from 50 --to 55 --n-e 1200 --u-delta 200 --u-vgt 40 --plot egr.png
  mvem step --input n_e --from 1500 --to 1600 --u-delta 110 --u-egr 80 --u-vgt 75 --out n.csv

The stepped input starts at --from (or at its operating-point option) and jumps to --to at
--t-step; the other three inputs are held at their options. The run starts at the steady state
before the step; initial and final values of the metrics are the steady states before and after
the step. Metrics per output: DC gain (output unit per unit of the input change the model sees:
a --to that the input saturation clamps counts up to the limit) and its sign, the wrong-way
(non-minimum-phase) excursion and its time, overshoot [%], rise time 10-90 % and settling time
(2 % band) [s]. With --json, stdout holds one JSON object with \"input\", \"from\", \"to\",
\"t_step\", \"operating_point\" and \"outputs\" (an object keyed by output name).")]
pub struct Args {
    /// The stepped input.
    #[arg(long, value_enum)]
    pub input: InputArg,
    /// Value before the step (default: the operating-point option of that input).
    #[arg(long, value_name = "V", allow_negative_numbers = true)]
    pub from: Option<f64>,
    /// Value after the step.
    #[arg(long, value_name = "V", allow_negative_numbers = true)]
    pub to: f64,
    /// The operating point; inputs that are not given otherwise are required.
    #[command(flatten)]
    pub point: common::OptionalPointArgs,
    /// Time of the step [s].
    #[arg(long = "t-step", value_name = "S", default_value = "1")]
    pub t_step: f64,
    /// End time [s].
    #[arg(long = "t-end", value_name = "S", default_value = "10")]
    pub t_end: f64,
    /// Outputs (comma separated state or signal names) [default: p_im,p_em,W_c,n_t,x_egr,lambda_O,M_e]
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub outputs: Vec<String>,
    /// Print one JSON object on stdout instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Write a figure of the input and the outputs (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    /// Write the simulation (every state and signal) to this CSV file.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub solver: SolverArgs,
}

/// A simulated step and its metrics.
pub struct StepCase {
    /// The stepped input.
    pub input: InputArg,
    /// Inputs before the step.
    pub before: Drive,
    /// Value after the step.
    pub to: f64,
    /// Step time [s].
    pub t_step: f64,
    /// The simulation.
    pub sol: Solution,
    /// Per output: name and metrics, or why there are none (e.g. no change).
    pub metrics: Vec<(String, Result<StepMetrics, OutputError>)>,
    /// Whether both steady states are physically valid (flags otherwise).
    pub flags: Vec<String>,
    /// The step's size and the tolerances it was simulated at, when they were scaled down
    /// from the given ones ([`experiment::step_tolerance`]).
    pub scaled_tolerance: Option<(f64, f64, f64)>,
    /// Whether the response stands out of the integration error ([`experiment::StepRun::resolved`]).
    pub resolved: bool,
    /// Spacing of the samples the metrics were taken from [s].
    pub metrics_dt: f64,
}

pub use mvem::analysis::experiment::steady_value;

/// Simulate a step of `input` from its value in `before` to `to` at `t_step`, up to `t_end`,
/// and measure `outputs` (the core's step experiment, [`experiment::run_step`]).
#[allow(clippy::too_many_arguments)]
pub fn run_step<const N: usize, M: Model<N>>(
    m: &M,
    input: InputArg,
    before: Drive,
    to: f64,
    t_step: f64,
    t_end: f64,
    outputs: &[String],
    opts: &SimOptions,
) -> Result<StepCase> {
    let spec = StepSpec {
        before,
        input: input.slot(),
        to,
        t_step,
        t_end,
    };
    let run = experiment::run_step(m, &spec, opts)?;
    let metrics = outputs
        .iter()
        .map(|name| (name.clone(), run.metrics(name)))
        .collect();
    let flags = run.flags();
    let scaled_tolerance = (run.opts_used.rtol < opts.rtol || run.opts_used.atol < opts.atol)
        .then_some((run.size, run.opts_used.rtol, run.opts_used.atol));
    let resolved = run.resolved();
    let metrics_dt = run.metrics_dt();
    Ok(StepCase {
        input,
        before,
        to,
        t_step,
        sol: run.sol,
        metrics,
        flags,
        scaled_tolerance,
        resolved,
        metrics_dt,
    })
}

/// Run `mvem step`.
pub fn run(a: &Args) -> Result<()> {
    let slot = a.input.slot();
    for (what, v) in [("--from", a.from), ("--to", Some(a.to))] {
        if let Some(v) = v.filter(|v| !v.is_finite()) {
            return Err(common::usage(format!("{what} {v}: must be finite")));
        }
    }
    let given = a.point.given();
    let mut v = [0.0; 4];
    for k in 0..4 {
        v[k] = if k == slot {
            match (a.from, given[k]) {
                (Some(f), Some(g)) if f != g => {
                    return Err(common::usage(format!(
                        "--from {f} and {} {g} disagree; give one of them",
                        common::INPUT_OPTIONS[k]
                    )))
                }
                (Some(f), _) | (None, Some(f)) => f,
                (None, None) => {
                    return Err(common::usage(format!(
                        "the value before the step is missing: give --from or {}",
                        common::INPUT_OPTIONS[k]
                    )))
                }
            }
        } else {
            given[k].ok_or_else(|| {
                common::usage(format!(
                    "{} is required (the operating point)",
                    common::INPUT_OPTIONS[k]
                ))
            })?
        };
    }
    let before = Drive::from_array(v);
    let ranges = a.model.input_ranges()?;
    common::check_drive(&before, ranges.as_ref())?;
    let mut after = v;
    after[slot] = a.to;
    common::check_drive(&Drive::from_array(after), ranges.as_ref())
        .map_err(|e| common::usage(format!("--to: {}", common::error_message(&e))))?;
    if a.to == v[slot] {
        return Err(common::usage(format!(
            "--to {}: equals the value before the step",
            a.to
        )));
    }
    if !(a.t_step.is_finite() && a.t_step >= 0.0) {
        return Err(common::usage(format!(
            "--t-step {}: must be finite and >= 0",
            a.t_step
        )));
    }
    if !(a.t_end.is_finite() && a.t_end > a.t_step) {
        return Err(common::usage(format!(
            "--t-end {}: must be finite and after --t-step {}",
            a.t_end, a.t_step
        )));
    }
    let opts = a.solver.options(0.005)?;
    common::check_samples(0.0, a.t_end, opts.dt_out)?;
    for (p, what) in [(&a.plot, "--plot"), (&a.out, "--out")] {
        if let Some(p) = p {
            common::check_output_path(p, what)?;
        }
    }
    if let Some(p) = &a.plot {
        plot::Format::of(p)?;
    }
    let outputs: Vec<String> = if a.outputs.is_empty() {
        DEFAULT_OUTPUTS.iter().map(|s| s.to_string()).collect()
    } else {
        // each name once, in the order given (a name listed twice was a second, identical row
        // of the table; the JSON, `mvem linearize --outputs` and the explorer's /api/step keep
        // it once)
        let mut seen = std::collections::HashSet::new();
        a.outputs
            .iter()
            .map(|s| s.trim().to_string())
            .filter(|s| seen.insert(s.clone()))
            .collect()
    };
    let model = a.model.build()?;
    let case = common::with_spinner("simulating the step", || {
        mvem::dispatch!(&model, m => {
            for o in &outputs {
                if !m.state_names().contains(&o.as_str()) && !mvem::model::Signals::NAMES.contains(&o.as_str()) {
                    return Err(common::usage(format!(
                        "--outputs: unknown output {o:?}; known: the states {} and the signals {}",
                        m.state_names().join(", "),
                        mvem::model::Signals::NAMES.join(", ")
                    )));
                }
            }
            run_step(m, a.input, before, a.to, a.t_step, a.t_end, &outputs, &opts)
        })
    })?;
    for f in &case.flags {
        eprintln!("warning: not physically valid: {f}");
    }
    if let Some((size, rtol, atol)) = case.scaled_tolerance {
        eprintln!(
            "note: the step moves the air-path states by {size:.2e} of their magnitude: simulated at rtol {rtol:.1e}, atol {atol:.1e} (the tolerances scaled to the step's size; docs/analysis.md)"
        );
    }
    if !case.resolved {
        eprintln!("warning: {UNRESOLVED}");
    }
    if case.metrics_dt > experiment::METRICS_DT * (1.0 + 1e-9) {
        eprintln!(
            "warning: the metrics are taken from samples {} s apart (the horizon --t-end {} s in at most {} samples); features shorter than that (the W_c dip after a VGT step lasts about 0.1 s) are missed: shorten --t-end for finer metrics",
            mvem::numerics::Num(case.metrics_dt),
            a.t_end,
            experiment::METRICS_MAX_SAMPLES
        );
    }
    // render before writing anything
    let fig = match &a.plot {
        Some(p) => Some((p, plot::render(&figure(&case, None), plot::Format::of(p)?)?)),
        None => None,
    };
    if let Some(p) = &a.out {
        mvem::io::output::write_solution_csv(&case.sol, p)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some((p, bytes)) = fig {
        mvem::io::output::write_atomic(p, &bytes)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&to_json(&case))?);
    } else {
        print!("{}", text(&case));
    }
    Ok(())
}

/// The warning of a step that the integration cannot resolve.
const UNRESOLVED: &str = "the step hardly moves the engine (the air-path states by less than 100 times the integration tolerance, or by less than 2e-6 of their magnitude): the wrong-way, overshoot, rise and settling figures describe the integration error, not a response; the DC gains (from the steady states) hold";

fn to_json(c: &StepCase) -> Value {
    let t_end = c.sol.t().last().copied().unwrap_or(c.t_step);
    let spec = StepSpec {
        before: c.before,
        input: c.input.slot(),
        to: c.to,
        t_step: c.t_step,
        t_end,
    };
    let mut warnings = c.flags.clone();
    if !c.resolved {
        warnings.push(UNRESOLVED.to_string());
    }
    let mut v = step_json(&spec, &warnings, &c.metrics);
    if let Some((size, rtol, atol)) = c.scaled_tolerance {
        v["tolerance"] = serde_json::json!({"step_size": size, "rtol": rtol, "atol": atol});
    }
    v
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |s| format!("{s:.3}"))
}

/// Title of a step: `u_vgt 75 -> 65 % at t = 1 s`.
pub fn step_title(c: &StepCase) -> String {
    format!(
        "{} {} → {} {} at t = {} s",
        c.input.name(),
        c.before.to_array()[c.input.slot()],
        c.to,
        common::unit(c.input.name()),
        c.t_step
    )
}

/// The metrics table.
pub fn text(c: &StepCase) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Step {} ({})",
        step_title(c),
        common::fmt_drive(&c.before)
    );
    let _ = writeln!(
        s,
        "Initial and final values: steady states before and after the step.\n"
    );
    let _ = writeln!(
        s,
        "{:<10} {:>13} {:>13} {:>12} {:>8} {:>13} {:>8} {:>9} {:>8} {:>9}",
        "output",
        "y0",
        "y_final",
        "DC gain",
        "sign",
        "wrong way",
        "at [s]",
        "overshoot",
        "rise",
        "settling"
    );
    let _ = writeln!(
        s,
        "{:<10} {:>13} {:>13} {:>12} {:>8} {:>13} {:>8} {:>9} {:>8} {:>9}",
        "", "", "", "(per unit)", "", "(% change)", "", "[%]", "[s]", "[s]"
    );
    for (n, r) in &c.metrics {
        match r {
            Err(e) => {
                let _ = writeln!(s, "{n:<10} {e}");
            }
            Ok(m) => {
                let (ww, wt) = match m.wrong_way {
                    Some(w) => (
                        format!(
                            "{:.2}{}",
                            w.relative * 100.0,
                            if m.non_minimum_phase { " NMP" } else { "" }
                        ),
                        format!("{:.3}", w.time),
                    ),
                    None => ("none".into(), "-".into()),
                };
                let _ = writeln!(
                    s,
                    "{n:<10} {:>13.6e} {:>13.6e} {:>12.4e} {:>8} {:>13} {:>8} {:>9.2} {:>8} {:>9}",
                    m.y0,
                    m.y_final,
                    m.dc_gain,
                    m.gain_sign.to_string(),
                    ww,
                    wt,
                    m.overshoot_pct,
                    fmt_opt(m.rise_time),
                    fmt_opt(m.settling_time)
                );
            }
        }
    }
    let units: Vec<String> = c
        .metrics
        .iter()
        .map(|(n, _)| format!("{n} [{}]", common::unit(n)))
        .collect();
    let _ = writeln!(
        s,
        "\nUnits: {}; DC gain in output unit per {}.\nNMP: wrong-way excursion above 0.5 % of the final change (non-minimum phase).",
        units.join(", "),
        common::unit(c.input.name())
    );
    // what a `-` under rise or settling means (it was not said: the user could not tell a
    // response that never settles from one the run stopped too early for)
    let open = c.metrics.iter().any(|(_, r)| {
        r.as_ref()
            .is_ok_and(|m| m.rise_time.is_none() || m.settling_time.is_none())
    });
    if let (true, Some(t)) = (open, c.sol.columns.first().and_then(|t| t.last())) {
        let _ = writeln!(
            s,
            "-: not within the run: rise to 90 % of the final change, or settling into its 2 % band, not reached by t = {} s (a longer --t-end shows it).",
            mvem::numerics::Num(*t)
        );
    }
    s
}

/// Display scale and unit for plotting (pressures in kPa).
pub fn display(name: &str) -> (f64, String) {
    match common::unit(name) {
        "Pa" => (1e-3, "kPa".into()),
        u => (1.0, u.to_string()),
    }
}

/// The input panel then one panel per output (two columns), with the steady states before and
/// after and the wrong-way extremum marked. `label` prefixes the title.
pub fn figure(c: &StepCase, label: Option<&str>) -> Figure {
    let mut f = Figure::new(2);
    f.panel_size = (700, 290);
    let others: Vec<String> = Drive::NAMES
        .iter()
        .zip(c.before.to_array())
        .filter(|(n, _)| **n != c.input.name())
        .map(|(n, v)| format!("{n} {v} {}", common::unit(n)))
        .collect();
    // a label (e.g. the report's "Fig. 10 equivalent: ...") heads the figure, not the input
    // panel; the operating point then moves to the input panel's title
    f.title = Some(match label {
        None => format!("Step {}; {}", step_title(c), others.join(", ")),
        Some(l) => format!("{l}; {}", step_title(c)),
    });
    let t = c.sol.t();
    let (t0, t1) = (t[0], t[t.len() - 1]);
    let inp = c.input.name();
    let col = |n: &str| c.sol.get(n).map(|v| v.to_vec()).unwrap_or_default();
    let mut p = Panel::new("t [s]", format!("{inp} [{}]", common::unit(inp)))
        .title(match label {
            None => format!("Input {inp}"),
            Some(_) => format!("Input {inp} ({})", others.join(", ")),
        })
        .with(Series::line(format!("command {inp}"), t, &col(inp), 6));
    let actual = match c.input {
        InputArg::UEgr => Some("u_egr_actual"),
        InputArg::UVgt => Some("u_vgt_actual"),
        _ => None,
    };
    if let Some(a) = actual {
        p = p.with(Series::line("actuator position", t, &col(a), 0));
    }
    f.panels.push(p);
    for (k, (n, r)) in c.metrics.iter().enumerate() {
        let (sc, unit) = display(n);
        let y: Vec<f64> = col(n).iter().map(|v| v * sc).collect();
        let color = [0, 1, 2, 3, 4, 5][k % 6];
        let mut p = Panel::new("t [s]", format!("{n} [{unit}]")).with(Series::line(
            n.as_str(),
            t,
            &y,
            color,
        ));
        match r {
            Ok(m) => {
                let what = if m.non_minimum_phase {
                    format!(
                        "non-minimum phase ({:.1} % wrong way)",
                        m.wrong_way.map_or(0.0, |w| w.relative * 100.0)
                    )
                } else if m.overshoot_pct > 0.5 {
                    format!("overshoot {:.1} %", m.overshoot_pct)
                } else {
                    "no NMP, no overshoot".into()
                };
                p = p
                    .title(format!("{n}: DC gain {}, {what}", m.gain_sign))
                    .with(Series::hline("steady state before", t0, t1, m.y0 * sc, 6))
                    .with(Series::hline(
                        "steady state after",
                        t0,
                        t1,
                        m.y_final * sc,
                        1,
                    ));
                if let Some(w) = m.wrong_way.filter(|_| m.non_minimum_phase) {
                    p = p.with(Series::markers(
                        format!("wrong-way extremum at {:.2} s", w.time),
                        &[w.time],
                        &[w.value * sc],
                        3,
                    ));
                }
            }
            Err(e) => {
                p = p.title(format!("{n}: {e}"));
            }
        }
        f.panels.push(p);
    }
    f
}
