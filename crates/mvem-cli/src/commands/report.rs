//! `mvem report`: built-in analysis reports. `figs` reproduces the paper's dynamic figures
//! (Figs 8-12: the EGR step with a non-minimum-phase p_im, the VGT steps with a non-minimum-phase
//! W_c, overshoot and sign reversal, and the model-order comparison); `sign-reversal` maps the
//! DC gain of u_vgt -> W_c and the RHP zeros of u_egr -> p_im over two input grids.

use crate::commands::map::{self, MapRun};
use crate::commands::step::{self, InputArg, StepCase};
use crate::common::{self, ModelArgs, SolverArgs};
use crate::plot::{self, Figure, Panel, Series};
use crate::plot_maps;
use anyhow::{Context, Result};
use mvem::analysis::map::{Axis, Grid};
use mvem::analysis::steady::steady_state;
use mvem::model::{AnyModel, Drive, ModelOrder};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Arguments of `mvem report`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem report figs --out out/report
  mvem report sign-reversal --out out/report --n 41")]
pub struct Args {
    #[command(subcommand)]
    pub kind: Kind,
}

/// The reports.
#[derive(Debug, clap::Subcommand)]
pub enum Kind {
    /// The paper's dynamic figures 8-12 (PNG and SVG) and their step metrics.
    #[command(after_help = "\
Examples:
  mvem report figs --out out/report
  mvem report figs --out out/report --params my.toml

Writes DIR/fig08_egr_step_1200rpm, DIR/fig08_egr_step_1900rpm (EGR steps, NMP in p_im),
DIR/fig09_vgt_step_nmp (u_vgt 75 -> 65 %: NMP in W_c, negative DC gain),
DIR/fig10_vgt_step_overshoot (u_vgt 30 -> 25 %: overshoot in W_c, positive DC gain) and
DIR/fig11_12_model_orders (W_c of the 8-, 10- and 12-state models for both VGT steps), each as
.png and .svg, and prints the step metrics. The paper's Fig. 8 point (1200 rpm, u_vgt 60 %) has
no EGR flow with the published parameters (p_im >= p_em); the report checks that and uses
(1200 rpm, 200 mg/cycle, u_vgt 40 %) and (1900 rpm, 180 mg/cycle, u_vgt 60 %) instead.")]
    Figs(FigsArgs),
    /// DC gain u_vgt -> W_c and RHP zeros of u_egr -> p_im over (u_vgt x u_egr) and (n_e x u_delta).
    #[command(after_help = "\
Examples:
  mvem report sign-reversal --out out/report
  mvem report sign-reversal --out out/report --n 61 --threads 2

Writes DIR/sign_reversal_vgt_egr.{png,svg,csv} (u_vgt x u_egr at 1500 rpm, 110 mg) and
DIR/sign_reversal_speed_load.{png,svg,csv} (n_e x u_delta at u_egr 80 %, u_vgt 75 %): the DC gain
of u_vgt -> W_c with its sign-change boundary, and the DC gain of u_egr -> p_im with the region
where it has a right-half-plane zero. Grid edges sit just inside the input saturations (where the
linearization is one-sided).")]
    SignReversal(SignArgs),
}

/// Arguments of `mvem report figs`.
#[derive(Debug, clap::Args)]
pub struct FigsArgs {
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/report")]
    pub out: PathBuf,
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub solver: SolverArgs,
}

/// Arguments of `mvem report sign-reversal`.
#[derive(Debug, clap::Args)]
pub struct SignArgs {
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/report")]
    pub out: PathBuf,
    /// Grid points per axis (2-400).
    #[arg(long, value_name = "N", default_value = "41")]
    pub n: usize,
    /// Worker threads (0: all cores; at most 1024).
    #[arg(long, value_name = "N", default_value = "0", value_parser = common::threads_arg)]
    pub threads: usize,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Run `mvem report`.
pub fn run(a: &Args) -> Result<()> {
    match &a.kind {
        Kind::Figs(f) => figs(f),
        Kind::SignReversal(s) => sign_reversal(s),
    }
}

fn prepare_dir(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(common::usage(format!(
            "--out {}: exists and is not a directory",
            dir.display()
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| common::usage(format!("--out {}: {e}", dir.display())))
}

fn write_all(dir: &Path, files: Vec<(String, Vec<u8>)>) -> Result<Vec<String>> {
    let mut written = Vec::new();
    for (name, bytes) in files {
        let p = dir.join(&name);
        mvem::io::output::write_atomic(&p, &bytes)
            .with_context(|| format!("cannot write {}", p.display()))?;
        written.push(p.display().to_string());
    }
    Ok(written)
}

/// One step of the report: file name, label, stepped input, point before, value after, outputs.
struct Spec {
    file: &'static str,
    label: &'static str,
    input: InputArg,
    before: Drive,
    to: f64,
    outputs: &'static [&'static str],
}

fn specs() -> Vec<Spec> {
    vec![
        Spec {
            file: "fig08_egr_step_1200rpm",
            label: "Fig. 8 equivalent: EGR step, NMP in p_im",
            input: InputArg::UEgr,
            before: Drive::new(1200.0, 200.0, 50.0, 40.0),
            to: 60.0,
            outputs: &["p_im", "W_egr", "x_egr", "p_em", "W_c"],
        },
        Spec {
            file: "fig08_egr_step_1900rpm",
            label: "Fig. 8 equivalent: EGR step, NMP in p_im",
            input: InputArg::UEgr,
            before: Drive::new(1900.0, 180.0, 50.0, 60.0),
            to: 60.0,
            outputs: &["p_im", "W_egr", "x_egr", "p_em", "W_c"],
        },
        Spec {
            file: "fig09_vgt_step_nmp",
            label: "Figs 9, 11 equivalent: VGT step, NMP in W_c",
            input: InputArg::UVgt,
            before: Drive::new(1500.0, 110.0, 80.0, 75.0),
            to: 65.0,
            outputs: &["W_c", "n_t", "p_im", "p_em", "x_egr"],
        },
        Spec {
            file: "fig10_vgt_step_overshoot",
            label: "Figs 10, 12 equivalent: overshoot in W_c",
            input: InputArg::UVgt,
            before: Drive::new(1500.0, 110.0, 80.0, 30.0),
            to: 25.0,
            outputs: &["W_c", "n_t", "p_im", "p_em", "x_egr"],
        },
    ]
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

fn figs(a: &FigsArgs) -> Result<()> {
    let opts = a.solver.options(0.005)?;
    let (t_step, t_end) = (1.0, 8.0);
    common::check_samples(0.0, t_end, opts.dt_out)?;
    prepare_dir(&a.out)?;
    let params = a.model.load_params()?;
    let mo = a.model.options();
    let model = a.model.build()?;
    let mut out = String::new();
    let mut files = Vec::new();

    // The paper's Fig. 8 point: no EGR flow with the published parameters.
    let _ = writeln!(
        out,
        "Paper's Fig. 8 point (1200 rpm, u_vgt 60 %, u_egr 50 %): steady states over the load"
    );
    for u_delta in [50.0, 100.0, 150.0, 200.0, 250.0] {
        let d = Drive::new(1200.0, u_delta, 50.0, 60.0);
        let line = mvem::dispatch!(&model, m => match steady_state(m, &d) {
            Ok(ss) => format!(
                "  u_delta {u_delta:>5} mg/cycle: p_im {:.1} kPa, p_em {:.1} kPa, W_egr {:.2e} kg/s{}",
                step::steady_value(m, &ss, "p_im").unwrap_or(f64::NAN) * 1e-3,
                step::steady_value(m, &ss, "p_em").unwrap_or(f64::NAN) * 1e-3,
                ss.signals.w_egr,
                if ss.signals.w_egr <= 1e-9 { " (no EGR flow)" } else { "" }
            ),
            Err(e) => format!("  u_delta {u_delta:>5} mg/cycle: {e}"),
        });
        let _ = writeln!(out, "{line}");
    }
    let _ = writeln!(
        out,
        "The EGR steps below use (1200 rpm, 200 mg/cycle, u_vgt 40 %) and (1900 rpm, 180 mg/cycle, u_vgt 60 %).\n"
    );

    let mut cases: Vec<StepCase> = Vec::new();
    for s in specs() {
        let c = common::with_spinner(s.file, || {
            mvem::dispatch!(&model, m => step::run_step(m, s.input, s.before, s.to, t_step, t_end, &strings(s.outputs), &opts))
        })
        .with_context(|| s.file.to_string())?;
        let fig = step::figure(&c, Some(s.label));
        for (ext, fmt) in [("png", plot::Format::Png), ("svg", plot::Format::Svg)] {
            files.push((format!("{}.{ext}", s.file), plot::render(&fig, fmt)?));
        }
        let _ = writeln!(out, "{}: {}", s.file, s.label);
        out.push_str(&step::text(&c));
        out.push('\n');
        cases.push(c);
    }

    // Figs 11-12 (and 13-14): W_c of the 8-, 10- and 12-state models for both VGT steps.
    let mut fig = Figure::new(2);
    fig.panel_size = (760, 360);
    fig.title = Some(
        "Figs 11-14 equivalent: VGT steps with the 8-, 10- and 12-state models (n_e 1500 rpm, u_delta 110 mg/cycle, u_egr 80 %)".into(),
    );
    let _ = writeln!(
        out,
        "fig11_12_model_orders: W_c for the 8-, 10- and 12-state models"
    );
    for s in specs().iter().filter(|s| s.input == InputArg::UVgt) {
        let mut p = Panel::new("t [s]", "W_c [kg/s]").title(format!(
            "u_vgt {} → {} % at t = {t_step} s",
            s.before.u_vgt_pct, s.to
        ));
        for (k, order) in [ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve]
            .into_iter()
            .enumerate()
        {
            let mm = AnyModel::new(order, params.clone(), mo).context("cannot build the model")?;
            let c = mvem::dispatch!(&mm, m => step::run_step(m, s.input, s.before, s.to, t_step, t_end, &strings(&["W_c"]), &opts))
                .with_context(|| format!("{:?}-state model", order))?;
            let n = mm.order().states();
            p = p.with(Series::line(
                format!("{n}-state model"),
                c.sol.t(),
                c.sol.get("W_c").unwrap_or_default(),
                k,
            ));
            if let Some((_, Ok(m))) = c.metrics.first() {
                let _ = writeln!(
                    out,
                    "  {} -> {} %, {n:>2} states: W_c {:.5} -> {:.5} kg/s, DC gain {:+.4e} kg/s per % ({}), NMP {}, overshoot {:.1} %",
                    s.before.u_vgt_pct, s.to, m.y0, m.y_final, m.dc_gain, m.gain_sign, m.non_minimum_phase, m.overshoot_pct
                );
            }
        }
        fig.panels.push(p);
    }
    for (ext, fmt) in [("png", plot::Format::Png), ("svg", plot::Format::Svg)] {
        files.push((
            format!("fig11_12_model_orders.{ext}"),
            plot::render(&fig, fmt)?,
        ));
    }
    files.push(("figs_summary.txt".into(), out.clone().into_bytes()));
    let written = write_all(&a.out, files)?;
    print!("{out}");
    println!("\nWrote {}", written.join(", "));
    Ok(())
}

fn sign_reversal(a: &SignArgs) -> Result<()> {
    if !(2..=400).contains(&a.n) {
        return Err(common::usage(format!("--n {}: must lie in 2..=400", a.n)));
    }
    prepare_dir(&a.out)?;
    let model = a.model.build()?;
    let channels = vec!["u_vgt->W_c".to_string(), "u_egr->p_im".to_string()];
    let grids = [
        (
            "sign_reversal_vgt_egr",
            Grid::two(
                Drive::new(1500.0, 110.0, 0.0, 0.0),
                Axis::linspace("u_vgt", 20.5, 99.5, a.n),
                Axis::linspace("u_egr", 0.5, 99.5, a.n),
            )?,
        ),
        (
            "sign_reversal_speed_load",
            Grid::two(
                Drive::new(0.0, 0.0, 80.0, 75.0),
                Axis::linspace("n_e", 800.0, 2000.0 - 0.5, a.n),
                Axis::linspace("u_delta", 20.0, 250.0 - 0.5, a.n),
            )?,
        ),
    ];
    let mut files = Vec::new();
    let mut out = String::new();
    for (name, grid) in &grids {
        let (csv, fig) = mvem::dispatch!(&model, m => {
            let r: MapRun<_> = map::compute(m, grid, &channels, a.threads)?;
            map::report_failures(&r, 10);
            let _ = writeln!(out, "{name}: {}", map::title(grid));
            for (ch, res) in &r.channels {
                let ok: Vec<_> = res.iter().filter_map(|c| c.as_ref().ok()).collect();
                let _ = writeln!(
                    out,
                    "  {ch}: {} of {} points analysed; DC gain < 0 at {}, > 0 at {}; RHP zero at {}",
                    ok.len(),
                    res.len(),
                    ok.iter().filter(|c| c.dc_gain < 0.0).count(),
                    ok.iter().filter(|c| c.dc_gain > 0.0).count(),
                    ok.iter().filter(|c| c.zeros.has_rhp()).count()
                );
            }
            let mut f = plot_maps::MapFigure::new(2);
            f.title = Some(format!("Sign reversal and RHP zeros: {}", map::title(grid).replace("Steady-state map at ", "")));
            for (ch, res) in &r.channels {
                f.panels.push(map::channel_panel(&r, ch, res));
            }
            (map::csv_text(m, &r)?, f)
        });
        files.push((format!("{name}.csv"), csv.into_bytes()));
        for (ext, fmt) in [("png", plot::Format::Png), ("svg", plot::Format::Svg)] {
            files.push((format!("{name}.{ext}"), plot_maps::render(&fig, fmt)?));
        }
    }
    let written = write_all(&a.out, files)?;
    print!("{out}");
    println!("\nWrote {}", written.join(", "));
    Ok(())
}
