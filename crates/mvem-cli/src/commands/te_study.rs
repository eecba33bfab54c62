//! `mvem te-study`: the cylinder-out temperature study of the paper's section 4.2.3 (Fig. 2):
//! an input cycle (the WHTC by default) simulated with the fixed point of eq. (24) converged at
//! every evaluation and with one iteration per evaluation warm-started from the previous
//! accepted step (the authors' Memory blocks); the relative error of T_e, its maximum and mean,
//! and where the maximum occurs. The computation is
//! `mvem::analysis::extensions::cylinder_temp_study`.

use crate::common::{self, ModelArgs};
use crate::outdir::{self, Files};
use crate::plot::{Figure, Panel, Series};
use anyhow::{Context, Result};
use mvem::analysis::extensions::{cylinder_temp_study, CylinderTempOptions, CylinderTempStudy};
use mvem::model::Drive;
use mvem::sim::InputSchedule;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Arguments of `mvem te-study`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem te-study
  mvem te-study --rtol 1e-3 --out results/te-1e-3
  mvem te-study --model 10 --inputs my_cycle.csv

Writes, in DIR: te_study.{svg,png} (T_e of both runs, the relative error with its maximum marked,
close-ups of T_e and of the difference around the maximum), te_study.csv (t, inputs, T_e of both runs, relative error) and
report.md, also printed on stdout. Both runs start from the same converged steady state; the
one-iteration result depends on the accepted step sequence and hence on --rtol. --cylinder-temp
is ignored (both variants are run).")]
pub struct Args {
    /// Input CSV [default: the built-in WHTC cycle, 1800 s at 10 Hz]
    #[arg(long, value_name = "FILE.csv")]
    pub inputs: Option<PathBuf>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/te-study")]
    pub out: PathBuf,
    /// Relative tolerance of both simulations (atol = rtol / 100 of each state's scale).
    #[arg(long, value_name = "R", default_value_t = 1e-6)]
    pub rtol: f64,
    /// Output interval [s]; the errors are evaluated at these samples.
    #[arg(long, value_name = "S", default_value_t = 0.1)]
    pub dt: f64,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Run `mvem te-study`.
pub fn run(a: &Args) -> Result<()> {
    outdir::check(&a.out)?;
    if !(a.rtol.is_finite() && a.rtol > 0.0 && a.rtol < 1.0) {
        return Err(common::usage(format!(
            "--rtol {}: must lie in (0, 1)",
            a.rtol
        )));
    }
    if !(a.dt.is_finite() && a.dt > 0.0) {
        return Err(common::usage(format!("--dt {}: must be > 0", a.dt)));
    }
    let model = a.model.build()?;
    let (sched, source, t0, t_end) =
        common::cycle_inputs(a.inputs.as_deref(), a.model.input_ranges()?.as_ref())?;
    common::check_samples(t0, t_end, a.dt)?;
    let co = CylinderTempOptions {
        rtol: a.rtol,
        dt_out: a.dt,
    };
    let n = model.order().states();
    let study = common::with_spinner("simulating twice (converged, one iteration)", || {
        mvem::dispatch!(&model, m => cylinder_temp_study(m, &sched, t0, t_end, &co))
            .map_err(anyhow::Error::from)
    })
    .context("cylinder-out temperature study failed")?;
    if study.t.is_empty() || !study.max_abs_rel_error.is_finite() {
        anyhow::bail!("the study produced no finite T_e samples");
    }
    let report = report(&study, &sched, &source, n);
    let mut files = Files::default();
    files.figure("te_study", &figure(&study, &source, n))?;
    files.add("te_study.csv", csv(&study, &sched));
    files.add("report.md", report.clone());
    let written = files.write(&a.out)?;
    print!("{report}");
    println!("\n{}", outdir::wrote(&written));
    Ok(())
}

fn index_of_max(st: &CylinderTempStudy) -> usize {
    st.t.iter()
        .position(|t| *t == st.t_max)
        .unwrap_or(st.t.len() / 2)
}

fn drive_text(d: &Drive) -> String {
    format!(
        "n_e {:.0} rpm, u_delta {:.1} mg/cycle, u_egr {:.1} %, u_vgt {:.1} %",
        d.n_e_rpm, d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct
    )
}

/// Four panels: T_e of both runs over the cycle, the relative error with its maximum, and
/// close-ups of T_e and of the difference around the maximum.
fn figure(st: &CylinderTempStudy, source: &str, n: usize) -> Figure {
    let mut f = Figure::new(1);
    let name = source
        .trim_start_matches("<built-in ")
        .trim_end_matches('>');
    f.title = Some(format!(
        "T_e: one fixed-point iteration vs converged ({n} states, {name}, rtol {:e})",
        st.rtol
    ));
    f.panel_size = (1300, 260);
    let x = "t [s]";
    let pct: Vec<f64> = st.rel_error.iter().map(|e| 100.0 * e).collect();
    let i = index_of_max(st);
    f.panels.push(
        Panel::new(x, "T_e [K]")
            .title("Cylinder-out temperature T_e over the cycle")
            .with(Series::line(
                "converged fixed point",
                &st.t,
                &st.t_e_converged,
                0,
            ))
            .with(Series::dashed(
                "one iteration per step",
                &st.t,
                &st.t_e_one_iteration,
                1,
            )),
    );
    f.panels.push(
        Panel::new(x, "relative error of T_e [%]")
            .title(format!(
                "(one iteration - converged) / converged: max |error| {:.3} % at t = {:.2} s, mean {:.2e} %",
                100.0 * st.max_abs_rel_error,
                st.t_max,
                100.0 * st.mean_abs_rel_error
            ))
            .with(Series::line("relative error", &st.t, &pct, 2))
            .with(Series::markers(
                format!("max at t = {:.2} s", st.t_max),
                &[st.t[i]],
                &[pct[i]],
                1,
            )),
    );
    // close-up: 5 s either side of the maximum
    let (lo, hi) = (st.t_max - 5.0, st.t_max + 5.0);
    let idx: Vec<usize> = (0..st.t.len())
        .filter(|&k| st.t[k] >= lo && st.t[k] <= hi)
        .collect();
    let pick = |v: &[f64]| idx.iter().map(|&k| v[k]).collect::<Vec<f64>>();
    let tz = pick(&st.t);
    f.panels.push(
        Panel::new(x, "T_e [K]")
            .title(format!(
                "Close-up around the maximum (t = {:.2} s)",
                st.t_max
            ))
            .with(Series::line(
                "converged fixed point",
                &tz,
                &pick(&st.t_e_converged),
                0,
            ))
            .with(Series::dashed(
                "one iteration per step",
                &tz,
                &pick(&st.t_e_one_iteration),
                1,
            ))
            .with(Series::markers(
                "largest error",
                &[st.t[i]],
                &[st.t_e_one_iteration[i]],
                1,
            )),
    );
    let diff: Vec<f64> = idx
        .iter()
        .map(|&k| st.t_e_one_iteration[k] - st.t_e_converged[k])
        .collect();
    f.panels.push(
        Panel::new(x, "T_e difference [K]")
            .title("Close-up: one iteration - converged")
            .with(Series::line(
                "T_e,one iteration - T_e,converged",
                &tz,
                &diff,
                2,
            ))
            .with(Series::markers(
                "largest relative error",
                &[st.t[i]],
                &[st.t_e_one_iteration[i] - st.t_e_converged[i]],
                1,
            )),
    );
    f
}

fn csv(st: &CylinderTempStudy, sched: &InputSchedule) -> String {
    let mut s = String::from(
        "t,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct,T_e_converged,T_e_one_iteration,rel_error\n",
    );
    for k in 0..st.t.len() {
        let d = sched.at(st.t[k]);
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            st.t[k],
            d.n_e_rpm,
            d.u_delta_mg,
            d.u_egr_pct,
            d.u_vgt_pct,
            st.t_e_converged[k],
            st.t_e_one_iteration[k],
            st.rel_error[k]
        );
    }
    s
}

fn report(st: &CylinderTempStudy, sched: &InputSchedule, source: &str, n: usize) -> String {
    let mut s = String::new();
    let i = index_of_max(st);
    let d = sched.at(st.t_max);
    let d_before = sched.at(st.t_max - 1.0);
    let mut sorted: Vec<f64> = st.rel_error.iter().map(|e| e.abs()).collect();
    sorted.sort_by(f64::total_cmp);
    let p99 = sorted[((sorted.len() - 1) as f64 * 0.99).round() as usize];
    let over = |thr: f64| sorted.iter().filter(|e| **e > thr).count();
    let _ = writeln!(
        s,
        "# Cylinder-out temperature: one iteration vs converged (paper section 4.2.3, Fig. 2)\n\n\
         {n}-state model, inputs {source}, t = {} .. {} s, rtol {:e}, atol {:e} x state scale; \
         errors at {} output samples.\n",
        st.t[0],
        st.t[st.t.len() - 1],
        st.rtol,
        st.atol,
        st.t.len()
    );
    let _ = writeln!(s, "| figure | value |\n|---|---|");
    let _ = writeln!(
        s,
        "| max abs relative error of T_e | {:.3e} ({:.4} %) |",
        st.max_abs_rel_error,
        100.0 * st.max_abs_rel_error
    );
    let _ = writeln!(
        s,
        "| at | t = {:.2} s: T_e {:.2} K converged, {:.2} K one iteration |",
        st.t_max, st.t_e_converged[i], st.t_e_one_iteration[i]
    );
    let _ = writeln!(s, "| operating point there | {} |", drive_text(&d));
    let _ = writeln!(s, "| 1 s earlier | {} |", drive_text(&d_before));
    let _ = writeln!(
        s,
        "| mean abs relative error | {:.3e} ({:.5} %) |",
        st.mean_abs_rel_error,
        100.0 * st.mean_abs_rel_error
    );
    let _ = writeln!(s, "| 99th percentile of abs relative error | {p99:.3e} |");
    let _ = writeln!(
        s,
        "| samples with abs error > 0.01 % / > 0.1 % | {} / {} of {} |",
        over(1e-4),
        over(1e-3),
        sorted.len()
    );
    let _ = writeln!(
        s,
        "| accepted steps, converged / one iteration | {} / {} |",
        st.steps_converged, st.steps_one_iteration
    );
    let _ = writeln!(
        s,
        "\nThe paper reports a maximum of 0.15 % on the ETC (ode23s, rtol 1e-3) against a 1.7 % mean \
         error of the exhaust temperature model versus measurements."
    );
    s
}
