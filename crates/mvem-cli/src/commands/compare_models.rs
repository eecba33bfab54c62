//! `mvem compare-models`: the paper's Figs 11-14 — the 8-, 10- and 12-state models side by side
//! after the two VGT steps at n_e 1500 rpm, u_delta 110 mg, u_egr 80 % (u_vgt 75 -> 65 % and
//! 30 -> 25 %), with the stationary differences to the 8-state model and whether the
//! non-minimum-phase dip, the overshoot and the sign reversal of the DC gain in W_c persist.
//! The computation is `mvem::analysis::extensions::compare_vgt_steps`.

use crate::common::{self, ActuatorsArg, CylinderTempArg, ModelArg, ModelArgs, SemanticsArg};
use crate::outdir::{self, Files};
use crate::plot::{Figure, Panel, Series};
use anyhow::{Context, Result};
use mvem::analysis::extensions::{
    compare_vgt_steps, sign_reversal, CompareOptions, StepComparison, StepResponse, VgtStep,
};
use mvem::model::{AnyModel, ModelOrder};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `mvem compare-models`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem compare-models
  mvem compare-models --out results/models --params my_params.toml

Writes, in DIR: vgt_step_75_to_65.{svg,png} (paper Figs 11 and 13), vgt_step_30_to_25.{svg,png}
(Figs 12 and 14), vgt_steps_key.{svg,png} (both steps, W_c, p_im, T_em), one CSV per step (every compared signal of every model: W_c_8, W_c_10, W_c_12,
...) and report.md, the tables also printed on stdout: the W_c features per model (DC gain,
non-minimum-phase dip, overshoot), whether they persist in the extensions, and the stationary
differences of the 10- and 12-state steady states to the 8-state ones.")]
pub struct Args {
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/compare-models")]
    pub out: PathBuf,
    /// Parameter file: TOML, nested JSON, or the authors' flat JSON (with the intercooler
    /// parameters of the 12-state model) [default: the built-in published set]
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Equations: the authors' implementation or the paper's plain equations.
    #[arg(long, value_enum, default_value = "authors")]
    pub semantics: SemanticsArg,
    /// Relative tolerance of the simulations (atol = rtol / 100 of each state's scale).
    #[arg(long, value_name = "R", default_value_t = 1e-8)]
    pub rtol: f64,
    /// Output interval [s].
    #[arg(long, value_name = "S", default_value_t = 0.01)]
    pub dt: f64,
}

/// The orders compared, with their plot colour and line style (10 dashed: it lies on top of 8).
const ORDERS: [(ModelOrder, &str, usize, bool); 3] = [
    (ModelOrder::Eight, "8 states", 0, false),
    (ModelOrder::Ten, "10 states", 1, true),
    (ModelOrder::Twelve, "12 states", 2, false),
];

/// Signals returned by the comparison (plotted, written, and compared at steady state).
const SIGNALS: [&str; 15] = [
    "u_vgt",
    "u_vgt_actual",
    "W_c",
    "p_im",
    "p_em",
    "p_c",
    "n_t",
    "x_egr",
    "lambda_O",
    "M_e",
    "T_im",
    "T_em",
    "T_e",
    "W_egr",
    "W_ic",
];

/// Signals of the stationary-difference tables.
const STATIONARY: [&str; 12] = [
    "p_im", "p_em", "p_c", "W_c", "W_egr", "n_t", "x_egr", "lambda_O", "M_e", "T_im", "T_em", "T_e",
];

/// Run `mvem compare-models`.
pub fn run(a: &Args) -> Result<()> {
    outdir::check(&a.out)?;
    if !(a.rtol.is_finite() && a.rtol >= 1e-12 && a.rtol < 1.0) {
        return Err(common::usage(format!(
            "--rtol {}: must lie in [1e-12, 1)",
            a.rtol
        )));
    }
    if !(a.dt.is_finite() && a.dt > 0.0) {
        return Err(common::usage(format!("--dt {}: must be > 0", a.dt)));
    }
    common::check_samples(0.0, 8.0, a.dt)?;
    let margs = ModelArgs {
        params: a.params.clone(),
        model: ModelArg::Eight,
        semantics: a.semantics,
        cylinder_temp: CylinderTempArg::Converged,
        actuators: ActuatorsArg::Dynamic,
        ..ModelArgs::default()
    };
    let p = margs.load_params()?;
    let opts = margs.options();
    // Build every order first: parameter problems (e.g. k_ic = 0) are input errors.
    for (order, ..) in ORDERS {
        AnyModel::new(order, p.clone(), opts)
            .with_context(|| format!("cannot build the {}-state model", order.states()))?;
    }
    let co = CompareOptions {
        orders: ORDERS.iter().map(|o| o.0).collect(),
        rtol: a.rtol,
        dt_out: a.dt,
        signals: SIGNALS.iter().map(|s| s.to_string()).collect(),
    };
    let cases = VgtStep::paper_cases();
    let r = common::with_spinner("simulating 2 steps x 3 models", || {
        compare_vgt_steps(&p, opts, &cases, &co).map_err(anyhow::Error::from)
    })
    .context("model comparison failed")?;

    let report = report(&r, a.rtol);
    let mut files = Files::default();
    for (c, (stem, figs)) in r.iter().zip([
        ("vgt_step_75_to_65", "Figs 11 and 13"),
        ("vgt_step_30_to_25", "Figs 12 and 14"),
    ]) {
        files.figure(stem, &figure(c, figs))?;
        files.add(format!("{stem}.csv"), csv(c));
    }
    files.figure("vgt_steps_key", &key_figure(&r))?;
    files.add("report.md", report.clone());
    let written = files.write(&a.out)?;
    print!("{report}");
    println!("\n{}", outdir::wrote(&written));
    Ok(())
}

fn label(order: ModelOrder) -> &'static str {
    ORDERS
        .iter()
        .find(|o| o.0 == order)
        .map(|o| o.1)
        .unwrap_or("?")
}

fn series_of(r: &StepResponse, name: &str, scale: f64) -> Vec<f64> {
    r.series(name)
        .map(|v| v.iter().map(|x| x * scale).collect())
        .unwrap_or_default()
}

/// 5 x 2 panels, every model in each: u_vgt, W_c, p_im, p_em, p_c, n_t, x_egr, M_e, T_im, T_em.
fn figure(c: &StepComparison, paper_figs: &str) -> Figure {
    let s = &c.step;
    let mut f = Figure::new(2);
    f.title = Some(format!(
        "VGT step {} → {} % at {} s ({} rpm, {} mg/cycle, u_egr {} %): 8, 10, 12 states (paper {paper_figs})",
        s.u_vgt_from, s.u_vgt_to, s.t_step, s.n_e_rpm, s.u_delta_mg, s.u_egr_pct
    ));
    f.panel_size = (700, 270);
    let panels: [(&str, &str, &str, f64); 9] = [
        ("W_c", "W_c [kg/s]", "Compressor mass flow", 1.0),
        ("p_im", "p_im [kPa]", "Intake manifold pressure", 1e-3),
        ("p_em", "p_em [kPa]", "Exhaust manifold pressure", 1e-3),
        (
            "p_c",
            "p_c [kPa]",
            "Compressor outlet pressure (= p_im for 8, 10)",
            1e-3,
        ),
        ("n_t", "n_t [krpm]", "Turbo speed", 1e-3),
        ("x_egr", "x_egr [-]", "EGR fraction", 1.0),
        ("M_e", "M_e [Nm]", "Engine torque", 1.0),
        (
            "T_im",
            "T_im [K]",
            "Intake manifold temperature (constant for 8)",
            1.0,
        ),
        ("T_em", "T_em [K]", "Exhaust manifold temperature", 1.0),
    ];
    let r8 = &c.responses[0];
    f.panels.push(
        Panel::new("t [s]", "u_vgt [%]")
            .title("VGT command and position")
            .with(Series::dashed(
                "command u_vgt",
                &r8.t,
                &series_of(r8, "u_vgt", 1.0),
                6,
            ))
            .with(Series::line(
                "position (all models)",
                &r8.t,
                &series_of(r8, "u_vgt_actual", 1.0),
                0,
            )),
    );
    for (name, ylabel, title, scale) in panels {
        let title = title.to_string();
        f.panels
            .push(models_panel(c, (name, &LEGEND), ylabel, title, scale));
    }
    f
}

/// Panels that carry the model legend: those where the lower right corner is free after both
/// steps (a legend elsewhere would hide the steady state before the step).
const LEGEND: [&str; 5] = ["p_im", "p_em", "p_c", "n_t", "T_em"];

/// One signal of every model in one panel (with the legend if `name` is in `legend`).
fn models_panel(
    c: &StepComparison,
    (name, legend): (&str, &[&str]),
    ylabel: &str,
    title: String,
    scale: f64,
) -> Panel {
    let mut panel = Panel::new("t [s]", ylabel).title(title);
    for r in &c.responses {
        let (_, lab, color, dashed) = ORDERS
            .iter()
            .copied()
            .find(|o| o.0 == r.order)
            .unwrap_or((r.order, "?", 6, false));
        let y = series_of(r, name, scale);
        let lab = if legend.contains(&name) { lab } else { "" };
        panel = panel.with(if dashed {
            Series::dashed(lab, &r.t, &y, color)
        } else {
            Series::line(lab, &r.t, &y, color)
        });
    }
    panel
}

/// The key figure: both steps side by side (columns), W_c, p_im and T_em of every model.
fn key_figure(r: &[StepComparison]) -> Figure {
    let mut f = Figure::new(r.len());
    let s = &r[0].step;
    f.title = Some(format!(
        "8, 10, 12 states after VGT steps ({} rpm, {} mg/cycle, u_egr {} %; paper Figs 11-14)",
        s.n_e_rpm, s.u_delta_mg, s.u_egr_pct
    ));
    f.panel_size = (560, 250);
    let rows: [(&str, &str, &str, f64); 3] = [
        ("W_c", "W_c [kg/s]", "W_c", 1.0),
        ("p_im", "p_im [kPa]", "p_im", 1e-3),
        ("T_em", "T_em [K]", "T_em", 1.0),
    ];
    for (name, ylabel, what, scale) in rows {
        for c in r {
            let title = format!(
                "{what}, u_vgt {} → {} %",
                c.step.u_vgt_from, c.step.u_vgt_to
            );
            f.panels
                .push(models_panel(c, (name, &["p_im"]), ylabel, title, scale));
        }
    }
    f
}

/// Every compared signal of every model, one row per output time.
fn csv(c: &StepComparison) -> String {
    let mut s = String::from("t");
    for name in SIGNALS {
        for r in &c.responses {
            let _ = write!(s, ",{name}_{}", r.order.states());
        }
    }
    s.push('\n');
    let t = &c.responses[0].t;
    for (i, ti) in t.iter().enumerate() {
        let _ = write!(s, "{ti}");
        for name in SIGNALS {
            for r in &c.responses {
                let v = r.series(name).and_then(|v| v.get(i)).copied();
                let _ = write!(s, ",{}", v.unwrap_or(f64::NAN));
            }
        }
        s.push('\n');
    }
    s
}

fn yes(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "no"
    }
}

/// A relative difference in percent, scientific when tiny.
fn pct(v: f64) -> String {
    let p = 100.0 * v;
    if p == 0.0 {
        "0".into()
    } else if p.abs() < 1e-3 {
        format!("{p:+.1e} %")
    } else {
        format!("{p:+.3} %")
    }
}

fn value(r: &StepResponse, name: &str, after: bool) -> f64 {
    let v = if after {
        &r.steady_after
    } else {
        &r.steady_before
    };
    v.iter()
        .find(|(n, _)| n == name)
        .map_or(f64::NAN, |(_, x)| *x)
}

/// The Markdown report: W_c features, persistence, stationary differences.
fn report(r: &[StepComparison], rtol: f64) -> String {
    let mut s = String::new();
    let s0 = &r[0].step;
    let _ = writeln!(
        s,
        "# 8- vs 10- vs 12-state models: VGT steps (paper Figs 11-14)\n\n\
         Operating point n_e {} rpm, u_delta {} mg/cycle, u_egr {} %; u_vgt steps at t = {} s, \
         simulated from the steady state to {} s (rtol {rtol:e}). Initial and final values are \
         the steady states before and after the step. NMP: a move of W_c opposite to its final \
         change larger than 0.5 % of the change, before W_c has moved 0.5 % the right way; \
         overshoot: the largest excursion beyond the final value.\n",
        s0.n_e_rpm, s0.u_delta_mg, s0.u_egr_pct, s0.t_step, s0.t_end
    );
    let _ = writeln!(s, "## Compressor flow W_c\n");
    let _ = writeln!(
        s,
        "| step | model | W_c before [kg/s] | W_c after [kg/s] | DC gain [kg/s per %] | NMP (dip / change, at) | overshoot | accepted steps |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for c in r {
        for resp in &c.responses {
            let w = &resp.w_c;
            let nmp = match w.wrong_way {
                Some(e) if w.non_minimum_phase => {
                    format!("yes ({:.2}, {:.2} s after)", e.relative, e.time - w.t_step)
                }
                _ => "no".into(),
            };
            let _ = writeln!(
                s,
                "| {} -> {} % | {} | {:.5} | {:.5} | {:+.3e} | {nmp} | {:.1} % | {} |",
                c.step.u_vgt_from,
                c.step.u_vgt_to,
                label(resp.order),
                w.y0,
                w.y_final,
                w.dc_gain,
                w.overshoot_pct,
                resp.steps
            );
        }
    }
    let _ = writeln!(s, "\n## Do the W_c features persist in the extensions?\n");
    let _ = writeln!(
        s,
        "| model | NMP dip after {0} -> {1} % | overshoot > 0.5 % after {2} -> {3} % | sign reversal of the DC gain |",
        r[0].step.u_vgt_from,
        r[0].step.u_vgt_to,
        r.get(1).map_or(f64::NAN, |c| c.step.u_vgt_from),
        r.get(1).map_or(f64::NAN, |c| c.step.u_vgt_to)
    );
    let _ = writeln!(s, "|---|---|---|---|");
    for (order, ..) in ORDERS {
        let nmp = r[0]
            .response(order)
            .is_some_and(|x| x.w_c.non_minimum_phase);
        let over = r
            .get(1)
            .and_then(|c| c.response(order))
            .is_some_and(|x| x.w_c.overshoot_pct > 0.5);
        let rev = sign_reversal(r, order).unwrap_or(false);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} |",
            label(order),
            yes(nmp),
            yes(over),
            yes(rev)
        );
    }
    let _ = writeln!(
        s,
        "\n## Stationary differences to the 8-state model\n\n\
         (value - 8-state value) / |8-state value| at the steady states; the 10-state model has \
         the same equilibria (its temperatures equal their inflow values), the 12-state model \
         differs through the intercooler pressure drop.\n"
    );
    // one column group per distinct u_vgt (before and after of both steps)
    let mut points: Vec<(usize, bool)> = Vec::new();
    for (k, _) in r.iter().enumerate() {
        points.push((k, false));
        points.push((k, true));
    }
    let mut head = String::from("| signal |");
    let mut rule = String::from("|---|");
    for &(k, after) in &points {
        let st = &r[k].step;
        let u = if after { st.u_vgt_to } else { st.u_vgt_from };
        let _ = write!(head, " u_vgt {u} %: 8 states | 10 vs 8 | 12 vs 8 |");
        rule.push_str("---|---|---|");
    }
    let _ = writeln!(s, "{head}\n{rule}");
    for name in STATIONARY {
        let unit = common::unit(name);
        let _ = write!(
            s,
            "| {name}{} |",
            if unit.is_empty() || unit == "-" {
                String::new()
            } else {
                format!(" [{unit}]")
            }
        );
        for &(k, after) in &points {
            let c = &r[k];
            let base = c.response(ModelOrder::Eight).map(|x| value(x, name, after));
            let diff = |o: ModelOrder| {
                c.stationary
                    .iter()
                    .find(|d| d.order == o && d.signal == name)
                    .map_or("-".into(), |d| pct(if after { d.after } else { d.before }))
            };
            let _ = write!(
                s,
                " {} | {} | {} |",
                base.map_or("-".into(), common::fmt_value),
                diff(ModelOrder::Ten),
                diff(ModelOrder::Twelve)
            );
        }
        s.push('\n');
    }
    // dynamic closeness, for the text of the figures
    let _ = writeln!(
        s,
        "\n## Largest distance between the responses\n\nmax over t of |y_model - y_8| / (range of y_8 over the step response):\n"
    );
    let _ = writeln!(s, "| step | signal | 10 vs 8 | 12 vs 8 |");
    let _ = writeln!(s, "|---|---|---|---|");
    for c in r {
        for name in ["W_c", "p_im", "p_em", "n_t"] {
            let Some(y8) = c.response(ModelOrder::Eight).and_then(|x| x.series(name)) else {
                continue;
            };
            let dist = |o: ModelOrder| {
                c.response(o)
                    .and_then(|x| x.series(name))
                    .map_or("-".into(), |y| format!("{:.3}", max_distance(y8, y)))
            };
            let _ = writeln!(
                s,
                "| {} -> {} % | {name} | {} | {} |",
                c.step.u_vgt_from,
                c.step.u_vgt_to,
                dist(ModelOrder::Ten),
                dist(ModelOrder::Twelve)
            );
        }
    }
    s
}

/// max |y - y_ref| / (max y_ref - min y_ref).
fn max_distance(y_ref: &[f64], y: &[f64]) -> f64 {
    let (lo, hi) = y_ref
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    let d = y_ref
        .iter()
        .zip(y)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    d / (hi - lo)
}
