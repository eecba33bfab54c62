//! `mvem robustness`: the robustness sweep of `mvem::analysis::robustness` ("never crash, never
//! lie") at the 8-, 10- and 12-state models, in parallel, with a report (text, JSON, Markdown).

use crate::common::{self, SemanticsArg};
use anyhow::{Context, Result};
use clap::ValueEnum;
use mvem::analysis::robustness::{sweep_with_progress, SweepConfig, SweepReport, ViolationMap};
use mvem::analysis::robustness_analysis::{analysis_sweep, AnalysisSweepConfig};
use mvem::components::Semantics;
use mvem::model::ModelOrder;
use mvem::sim::Method;
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `mvem robustness`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem robustness --runs 300 --t-end 20
  mvem robustness --runs 10000 --seed 1 --model all --out robustness.md
  mvem robustness --runs 1000 --model 12 --json > sweep.json

Every run is a simulation of --t-end seconds with random, seeded inputs (steps, ramps,
WHTC-like motoring/full-load jumps; n_e 300-2500 rpm, u_delta 0-300 mg, u_egr and u_vgt
-20..120 %) from a random start state (near, perturbed or far from equilibrium), integrators
alternating. Every output sample is checked for NaN/inf and the model's invariants (see
docs/robustness.md). Run k of seed S is the same scenario at every model order.
Exit code 1 if any run panicked, produced NaN/inf, violated an invariant or ended in an error
without time, state and hint; runs ending in a located error are counted by class.

With --analysis, the sweep calls the analyses behind `mvem steady`, `mvem linearize` and
`mvem map` instead, at --runs random operating points per model order and semantics (both
semantics unless --semantics is given explicitly), over n_e -500..2500 rpm (0, -100 and 1e-9 rpm
included), u_delta -50..300 mg, u_egr and u_vgt -20..120 %, each call on a worker thread with
the --timeout limit. Exit code 1 if any call hung, panicked or returned NaN/inf.")]
pub struct Args {
    /// Runs per model order.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// Seed of the random scenarios.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Model order(s) to sweep.
    #[arg(long, value_enum, default_value = "all")]
    pub model: OrderArg,
    /// Simulated time per run [s].
    #[arg(
        long = "t-end",
        default_value_t = 60.0,
        value_name = "S",
        allow_negative_numbers = true
    )]
    pub t_end: f64,
    /// Integrators, alternating by run.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "rosenbrock34,dopri5"
    )]
    pub methods: Vec<MethodArg>,
    /// Worker threads [default: all cores].
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads: Option<u64>,
    /// Parameter file [default: the built-in published set].
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Equations: the authors' implementation or the paper's plain equations [default:
    /// authors; with --analysis both].
    #[arg(long, value_enum)]
    pub semantics: Option<SemanticsArg>,
    /// Print the report as one JSON object on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also write the report as Markdown to this file (atomically).
    #[arg(long, value_name = "FILE.md")]
    pub out: Option<PathBuf>,
    /// Sweep the analysis calls (steady, linearize, map) instead of simulations.
    #[arg(long)]
    pub analysis: bool,
    /// Time limit per analysis call [s] (--analysis).
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub timeout: f64,
}

/// `--model` of `mvem robustness`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum OrderArg {
    /// The 8-state model.
    #[value(name = "8")]
    Eight,
    /// The 10-state model.
    #[value(name = "10")]
    Ten,
    /// The 12-state model.
    #[value(name = "12")]
    Twelve,
    /// All three, one sweep each.
    All,
}

/// `--methods`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Rosenbrock (ROS3P-type) 3(4), L-stable.
    Rosenbrock34,
    /// Dormand-Prince 5(4), explicit.
    Dopri5,
}

/// Run `mvem robustness`.
pub fn run(a: &Args) -> Result<()> {
    if !(a.t_end.is_finite() && a.t_end > 0.0) {
        return Err(common::usage(format!("--t-end {}: must be > 0", a.t_end)));
    }
    if let Some(p) = &a.out {
        common::check_output_path(p, "--out")?;
    }
    let params = match &a.params {
        None => mvem::params::Params::published(),
        Some(p) => mvem::io::params::load_params(p)
            .with_context(|| format!("cannot use parameter file {}", p.display()))?,
    };
    if a.analysis {
        return run_analysis(a, &params);
    }
    let orders = orders_of(a.model);
    let threads = threads_of(a);
    let base = SweepConfig {
        runs: a.runs,
        seed: a.seed,
        t_end: a.t_end,
        methods: a
            .methods
            .iter()
            .map(|m| match m {
                MethodArg::Rosenbrock34 => Method::Rosenbrock34,
                MethodArg::Dopri5 => Method::Dopri5,
            })
            .collect(),
        threads,
        ..SweepConfig::default()
    };
    let mut base = base;
    base.model.semantics = semantics_of(a.semantics.unwrap_or(SemanticsArg::Authors));
    let pb = common::stderr_is_terminal().then(|| {
        let pb = indicatif::ProgressBar::new(a.runs * orders.len() as u64);
        pb.set_draw_target(indicatif::ProgressDrawTarget::stderr());
        if let Ok(style) = indicatif::ProgressStyle::with_template(
            "{msg} [{bar:40}] {pos}/{len} runs [{elapsed} / eta {eta}]",
        ) {
            pb.set_style(style.progress_chars("=> "));
        }
        pb
    });
    let mut reports = Vec::new();
    for order in orders {
        if let Some(pb) = &pb {
            pb.set_message(format!("{}-state model", order.states()));
        }
        let cfg = SweepConfig {
            orders: vec![order],
            ..base.clone()
        };
        let tick = || {
            if let Some(pb) = &pb {
                pb.inc(1);
            }
        };
        let r = sweep_with_progress(&params, &cfg, &tick);
        if !r.unavailable.is_empty() {
            return Err(common::usage(format!(
                "the {}-state model cannot be built from these parameters",
                order.states()
            )));
        }
        reports.push((order.states(), r));
    }
    if let Some(pb) = &pb {
        pb.finish_and_clear();
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&to_json(a, &reports))?);
    } else {
        for (n, r) in &reports {
            println!("== {n}-state model ==\n{r}");
        }
    }
    if let Some(p) = &a.out {
        mvem::io::output::write_atomic(p, markdown(a, &reports).as_bytes())
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    let dirty: Vec<String> = reports
        .iter()
        .filter(|(_, r)| !r.clean())
        .map(|(n, _)| format!("{n}-state"))
        .collect();
    if !dirty.is_empty() {
        anyhow::bail!(
            "robustness sweep not clean ({}): panics, NaN/inf, invariant violations or unlocated errors (see the report)",
            dirty.join(", ")
        );
    }
    Ok(())
}

fn semantics_of(s: SemanticsArg) -> Semantics {
    match s {
        SemanticsArg::Authors => Semantics::Authors,
        SemanticsArg::Paper => Semantics::Paper,
    }
}

/// The model orders of `--model`.
fn orders_of(m: OrderArg) -> Vec<ModelOrder> {
    match m {
        OrderArg::Eight => vec![ModelOrder::Eight],
        OrderArg::Ten => vec![ModelOrder::Ten],
        OrderArg::Twelve => vec![ModelOrder::Twelve],
        OrderArg::All => vec![ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve],
    }
}

fn threads_of(a: &Args) -> usize {
    a.threads.map(|t| t as usize).unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    })
}

/// `mvem robustness --analysis`.
fn run_analysis(a: &Args, params: &mvem::params::Params) -> Result<()> {
    if !(a.timeout.is_finite() && a.timeout > 0.0) {
        return Err(common::usage(format!(
            "--timeout {}: must be > 0",
            a.timeout
        )));
    }
    let semantics = match a.semantics {
        Some(s) => vec![semantics_of(s)],
        None => vec![Semantics::Authors, Semantics::Paper],
    };
    let cfg = AnalysisSweepConfig {
        points: a.runs,
        seed: a.seed,
        orders: orders_of(a.model),
        semantics,
        timeout: std::time::Duration::from_secs_f64(a.timeout),
        threads: threads_of(a),
    };
    let r = common::with_spinner("analysis sweep (steady, linearize, map)", || {
        analysis_sweep(params, &cfg)
    });
    if !r.unavailable.is_empty() {
        return Err(common::usage(format!(
            "the {:?}-state model(s) cannot be built from these parameters",
            r.unavailable
        )));
    }
    if a.json {
        let [calls, ok, errors, nonfinite, panics, hangs] = r.totals();
        let rows: Vec<Value> = r
            .counts
            .iter()
            .map(|((n, sem, call), c)| {
                json!({"states": n, "semantics": sem, "call": call.name(), "calls": c.calls,
                       "ok": c.ok, "errors": c.errors, "nonfinite": c.nonfinite,
                       "panics": c.panics, "hangs": c.hangs, "slowest_s": c.slowest})
            })
            .collect();
        let v = json!({"seed": a.seed, "points": a.runs, "timeout_s": a.timeout,
                       "calls": calls, "ok": ok, "errors": errors, "nonfinite": nonfinite,
                       "panics": panics, "hangs": hangs, "seconds": r.seconds,
                       "clean": r.clean(), "per_call": rows});
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("{r}");
    }
    if let Some(p) = &a.out {
        let md = format!(
            "# mvem robustness sweep of the analysis calls\n\n`mvem robustness --analysis --runs {} --seed {} --timeout {}`, mvem {}\n\n```\n{r}```\n",
            a.runs,
            a.seed,
            a.timeout,
            env!("CARGO_PKG_VERSION")
        );
        mvem::io::output::write_atomic(p, md.as_bytes())
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if !r.clean() {
        anyhow::bail!("analysis sweep not clean: hangs, panics or NaN/inf (see the report)");
    }
    Ok(())
}

fn violations_json(map: &ViolationMap) -> Value {
    Value::Array(
        map.iter()
            .map(|((inv, method), (runs, samples, worst, excess, run))| {
                json!({"invariant": inv, "method": method, "runs": runs, "samples": samples,
                       "worst_value": worst, "worst_relative_excess": excess, "example_run": run})
            })
            .collect(),
    )
}

/// The JSON report: settings and one object per model order.
fn to_json(a: &Args, reports: &[(usize, SweepReport)]) -> Value {
    let models: Vec<Value> = reports
        .iter()
        .map(|(n, r)| {
            json!({
                "states": n,
                "runs": r.runs,
                "completed": r.completed,
                "errors": r.errors.iter().map(|(c, (k, run, msg))| json!({
                    "class": c, "count": k, "example_run": run, "example_message": msg,
                })).collect::<Vec<_>>(),
                "unlocated_errors": r.unlocated_errors,
                "panics": r.panics.iter().map(|(run, m)| json!({"run": run, "message": m}))
                    .collect::<Vec<_>>(),
                "samples_checked": r.samples,
                "nonfinite_samples": r.nonfinite_samples,
                "nonfinite_runs": r.nonfinite_runs,
                "violations": violations_json(&r.violations),
                "numerical_excursions": violations_json(&r.numerical),
                "per_method": r.per_variant.iter().map(|((_, m), (ok, err))|
                    json!({"method": m, "completed": ok, "errors": err})).collect::<Vec<_>>(),
                "per_kind": r.per_kind.iter().map(|(k, (ok, err))|
                    json!({"kind": k, "completed": ok, "errors": err})).collect::<Vec<_>>(),
                "seconds": r.seconds,
                "threads": r.threads,
                "clean": r.clean(),
            })
        })
        .collect();
    json!({
        "seed": a.seed,
        "runs_per_model": a.runs,
        "t_end_s": a.t_end,
        "semantics": format!("{:?}", a.semantics.unwrap_or(SemanticsArg::Authors)).to_lowercase(),
        "models": models,
    })
}

/// The Markdown report: a summary table (one column per model order) and the details.
fn markdown(a: &Args, reports: &[(usize, SweepReport)]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# mvem robustness sweep\n\n`mvem robustness --runs {} --seed {} --t-end {}` ({} semantics), \
         mvem {}\n",
        a.runs,
        a.seed,
        a.t_end,
        format!("{:?}", a.semantics.unwrap_or(SemanticsArg::Authors)).to_lowercase(),
        env!("CARGO_PKG_VERSION")
    );
    let head: Vec<String> = reports.iter().map(|(n, _)| format!("{n} states")).collect();
    let _ = writeln!(s, "| quantity | {} |", head.join(" | "));
    let _ = writeln!(s, "|---|{}", "---:|".repeat(reports.len()));
    let row = |s: &mut String, label: &str, f: &dyn Fn(&SweepReport) -> String| {
        let cells: Vec<String> = reports.iter().map(|(_, r)| f(r)).collect();
        let _ = writeln!(s, "| {label} | {} |", cells.join(" | "));
    };
    row(&mut s, "runs", &|r| r.runs.to_string());
    row(&mut s, "runs completed", &|r| r.completed.to_string());
    row(&mut s, "runs ending in a located error", &|r| {
        (r.runs - r.completed - r.panics.len() as u64 - r.unlocated_errors).to_string()
    });
    row(&mut s, "errors without t/state/hint", &|r| {
        r.unlocated_errors.to_string()
    });
    row(&mut s, "panics", &|r| r.panics.len().to_string());
    row(&mut s, "output samples checked", &|r| r.samples.to_string());
    row(&mut s, "samples with NaN/inf", &|r| {
        r.nonfinite_samples.to_string()
    });
    row(&mut s, "invariant violations (runs)", &|r| {
        r.violations.values().map(|v| v.0).sum::<u64>().to_string()
    });
    row(
        &mut s,
        "numerical X_O excursions within 100x tolerance (runs)",
        &|r| r.numerical.values().map(|v| v.0).sum::<u64>().to_string(),
    );
    row(&mut s, "worst numerical excursion (relative)", &|r| {
        r.numerical
            .values()
            .map(|v| v.3)
            .fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))))
            .map_or("-".into(), |x| format!("{x:.1e}"))
    });
    row(&mut s, "wall time [s] (threads)", &|r| {
        format!("{:.0} ({})", r.seconds, r.threads)
    });
    for (n, r) in reports {
        let _ = writeln!(s, "\n## {n}-state model\n\n```\n{r}```");
    }
    s
}
