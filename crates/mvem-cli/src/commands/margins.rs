//! `mvem margins`: stability margins of the baseline controller's air-path loops at an
//! operating point (`mvem::control::margins`).

use crate::common::{self, ModelArgs};
use anyhow::{Context, Result};
use mvem::control::baseline::BaselineTuning;
use mvem::control::margins::{
    baseline_loops, margins_at, margins_report_json, LoopAnalysis, LoopMargins,
};
use mvem::model::{Drive, Model};
use std::path::PathBuf;

/// Arguments of `mvem margins`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem margins --n-e 1500 --u-delta 110 --u-egr 50 --u-vgt 60
  mvem margins --n-e 1200 --u-delta 60 --u-egr 30 --u-vgt 70 --tuning car_controller.toml --json

The loops are the baseline controller's main air-path loops (docs/control.md): lambda_O -> u_egr
and x_egr -> u_vgt, discrete PIs sampled every 10 ms, around the sampled linear model at the
steady state of the given inputs (zero-order hold, actuator delays exact; mvem linearize --ts).
Per loop, with the other loop open and closed: the gain margin (the factor on the loop's kp and
ki at which the closed loop's poles reach the unit circle, from the closed-loop eigenvalues),
the phase margin at the gain crossover, the delay margin, and the peak of |1/(1+L)|. The
limiters, selectors and saturations of the controller are not part of the linear analysis.

With --json, stdout holds one JSON object: \"operating_point\", \"model_states\", \"ts\",
\"stable\", \"max_pole_all\", \"steady_state_warnings\" (the steady state's flags when it is not
physically valid, as mvem steady; the margins are given all the same), \"loops\" [{name, input,
output, kp, ki, alone, others_closed}],
each margins object {inert, stable, gain_margin, gain_margin_db, gain_margin_hz, gain_reduction_margin,
phase_margin_deg, gain_crossover_hz, delay_margin_s, peak_sensitivity, peak_sensitivity_hz}.")]
pub struct Args {
    /// The operating point (--n-e, --u-delta, --u-egr, --u-vgt).
    #[command(flatten)]
    pub point: common::PointArgs,
    /// The baseline controllers' tuning: a TOML file of `BaselineTuning` fields, as `mvem
    /// closed-loop --tuning` [default: the built-in tuning].
    #[arg(long, value_name = "FILE.toml")]
    pub tuning: Option<PathBuf>,
    /// Print one JSON object on stdout instead of the table.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Run `mvem margins`.
pub fn run(a: &Args) -> Result<()> {
    let d = a.point.drive(a.model.input_ranges()?.as_ref())?;
    let tuning = match &a.tuning {
        Some(p) => crate::commands::closed_loop::read_tuning(p)?,
        None => BaselineTuning::default(),
    };
    let model = a.model.build()?;
    mvem::dispatch!(&model, m => report(m, &d, &tuning, a.json))
}

fn report<const N: usize, M: Model<N>>(
    m: &M,
    d: &Drive,
    tuning: &BaselineTuning,
    json: bool,
) -> Result<()> {
    let (_, an) = margins_at(
        m,
        d,
        &baseline_loops(tuning, d, &m.params().input_saturation),
        tuning.ts,
    )
    .map_err(anyhow::Error::msg)
    .context("loop margins")?;
    if json {
        let v = margins_report_json(d, N, &an);
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print_table(d, N, &an);
    }
    Ok(())
}

fn print_table(d: &Drive, n: usize, an: &LoopAnalysis) {
    println!(
        "Loop margins at n_e = {} rpm, u_delta = {} mg/cycle, u_egr = {} %, u_vgt = {} % ({n} \
         states); PI loops sampled every {} s",
        d.n_e_rpm, d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct, an.ts
    );
    println!(
        "Every loop closed: {} (largest closed-loop pole |z| = {:.6})\n",
        if an.max_pole_all < 1.0 {
            "stable"
        } else {
            "UNSTABLE"
        },
        an.max_pole_all
    );
    println!(
        "  {:<17} {:<12} {:<31} {:<25} {:<13} peak |1/(1+L)|",
        "loop", "other loop", "gain margin", "phase margin", "delay margin"
    );
    for (k, l) in an.loops.iter().enumerate() {
        for (other, mm) in [("open", &an.alone[k]), ("closed", &an.others_closed[k])] {
            let [gm, pm, dm, ms] = cells(mm);
            println!(
                "  {:<17} {:<12} {gm:<31} {pm:<25} {dm:<13} {ms}",
                l.name, other
            );
        }
    }
    if !an.steady_state_warnings.is_empty() {
        println!(
            "\nwarning: the steady state of these inputs is not physically valid ({}): the \
             margins are those of the linear model there",
            an.steady_state_warnings.join(", ")
        );
    }
    for ((l, m), mo) in an.loops.iter().zip(&an.alone).zip(&an.others_closed) {
        if m.inert && !mo.inert {
            println!(
                "\n{}: {} does not move {} at this point (no EGR flow?): no feedback by itself; \
                 with the other loop closed it has some, through that loop",
                l.name, l.input, l.output
            );
        } else if m.inert {
            println!(
                "\n{}: {} moves none of the loops' outputs, or no loop command moves {}, at this \
                 point (no EGR flow?): the loop is left open in the others' figures",
                l.name, l.input, l.output
            );
        } else if m.stable && m.gain_crossover_hz.is_none() && m.gain_margin.is_none() {
            println!(
                "\n{}: |L| < 1 at every frequency and no gain up to 1e4 destabilizes it: {} barely \
                 moves {} at this point (a saturated valve area?)",
                l.name, l.input, l.output
            );
        }
    }
    let low: Vec<&str> = an
        .loops
        .iter()
        .zip(&an.alone)
        .filter_map(|(l, m)| m.gain_reduction_margin.map(|_| l.name.as_str()))
        .collect();
    if !low.is_empty() {
        println!(
            "\nconditionally stable (unstable below a gain factor): {}",
            low.join(", ")
        );
    }
}

/// A table row's gain margin, phase margin, delay margin and peak sensitivity.
fn cells(mm: &LoopMargins) -> [String; 4] {
    if mm.inert {
        return ["no effect here".into(), "-".into(), "-".into(), "1".into()];
    }
    if !mm.stable {
        return [
            "UNSTABLE".into(),
            "-".into(),
            "-".into(),
            format!("{:.3}", mm.peak_sensitivity),
        ];
    }
    [
        match (mm.gain_margin, mm.gain_margin_hz) {
            (Some(gm), Some(f)) => format!("{gm:.3} ({:.1} dB) at {} Hz", 20.0 * gm.log10(), hz(f)),
            _ => "none up to 1e4".into(),
        },
        match (mm.phase_margin_deg, mm.gain_crossover_hz) {
            (Some(pm), Some(f)) => format!("{pm:.1} deg at {} Hz", hz(f)),
            _ => "no crossover".into(),
        },
        mm.delay_margin_s
            .map_or("-".into(), |s| format!("{s:.3} s")),
        format!(
            "{:.3} at {} Hz",
            mm.peak_sensitivity,
            hz(mm.peak_sensitivity_hz)
        ),
    ]
}

/// A frequency with four significant digits.
fn hz(f: f64) -> String {
    format!("{:.3e}", f)
        .parse::<f64>()
        .map_or_else(|_| f.to_string(), |v| v.to_string())
}
