//! `mvem closed-loop`: a drive cycle with the baseline EGR/VGT and engine controllers (or the
//! open-loop WHTC schedule) around the model; trajectory, cycle statistics and figures.

use crate::common::{self, ModelArgs};
use crate::outdir::{self, Files};
use crate::plot::{Figure, Panel, Series};
use anyhow::Result;
use clap::ValueEnum;
use mvem::control::along::{self, AlongPoint, AlongSummary, Outcome};
use mvem::control::baseline::BaselineTuning;
use mvem::control::drive::{self, CycleRun, CycleSource, Scheme};
use mvem::control::{ControlError, Trajectory};
use mvem::io::output::{write_streaming, StreamError};
use mvem::model::AnyModel;
use mvem::sim::Block;
use std::path::{Path, PathBuf};
use std::sync::mpsc::SyncSender;

/// Arguments of `mvem closed-loop`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem closed-loop --cycle whtc --out out/closed-loop --plot
  mvem closed-loop --cycle whtc --controller open-loop --out out/open-loop --json
  mvem closed-loop --cycle my_cycle.csv --out out/mine
  mvem closed-loop --cycle whsc_normalized.tsv --out out/whsc
  mvem closed-loop --params car.toml --tuning car_controller.toml --out out/car

--cycle whtc: the WHTC (UN GTR No. 4) denormalized with this engine's mapping curve (full-load
torque at lambda_O >= 1.2, motoring torque for the \"m\" points), speeds 0 s..1800 s.
--cycle FILE.csv: a header with the columns t [s], n_e [rpm], M_ref [Nm] (any order, more
columns ignored, case ignored, `Time` for t; a unit in brackets after a name, `n_e [rpm]`, or a
units row under the header, converted where it is another unit of the quantity: ms, krpm,
rad/s, kNm), time increasing (two rows at one time are a step there, as in simulate --inputs),
n_e in the model's speed range (the parameter set's [input_saturation] n_e, default 500-2000
rpm), M_ref at most the full-load torque (a torque below the motoring torque is run at the
minimum fuel, with a warning); linear between rows.
The run samples every 10 ms from the cycle's first time: a cycle end or a --duration off that
grid runs the samples up to it (a warning says so); a --duration under 0.01 s is refused.
Needs the authors' semantics (--semantics paper has no idle equilibrium).
--cycle FILE (normalized): a cycle as UN GTR No. 4 publishes them (the WHTC, the WHSC's ramped
modes, your own), told apart by its header: a time [s], a speed [%] and a torque [%] column
(e.g. `Time Speed Torque`, an optional units row `s % %`; tab, semicolon, comma or space
separated; fields may be quoted except between spaces; every row has the header's fields, an
extra one is refused), speed 0-120 %, torque 0-100 % or \"m\" for motoring; denormalized with this
engine's mapping curve and reference speeds exactly as the built-in WHTC (speeds clamped into the
model's range, with a warning). data/whtc_normalized.tsv is an example (it starts at t = 1 s; the
built-in WHTC repeats its first row at 0 s).

Writes DIR/trajectory.csv (one row per 10 ms controller sample; the commands u_delta, u_egr,
u_vgt are held until the next row; egr_loop / vgt_loop say which loop gave u_egr / u_vgt: 1 the
main loop, 2 the limiter, 0 none in feedback, at a limit or at the lambda_O error cap),
DIR/stats.json and with --plot DIR/closed_loop.svg/.png. --json prints the statistics to stdout.
Nothing is written unless the whole run succeeds (a failed write removes this run's files
again); the files of a previous run in DIR that this one does not write (figures, margins.csv)
are removed. Statistics that do not apply (the torque regression of a constant demand, the
BSFC of an idle cycle) are null with the reason (\"not_applicable\"), not a failure.

--margins S (baseline controller): every S seconds of the run (S rounded to a multiple of the
10 ms sample time, with a warning), the gain, phase and delay margins
and the peak |1/(1+L)| of the air-path loops that were in feedback at that sample (as mvem
margins, the other loop closed), around the steady state of the sample's commands: DIR/margins.csv
(one row per analysed sample), a \"margins\" summary in stats.json (smallest margins per loop,
the times where the loops together are unstable) and with --plot DIR/margins.svg/.png. The fuel
path (torque PI, smoke limiter) and the selectors' switching are outside the linear analysis.")]
pub struct Args {
    /// Drive cycle: `whtc`, a CSV file with t, n_e, M_ref, or a normalized cycle (time, speed %,
    /// torque %).
    #[arg(long, value_name = "whtc|FILE", default_value = "whtc")]
    pub cycle: String,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Controller.
    #[arg(long, value_enum, default_value = "baseline")]
    pub controller: ControllerArg,
    #[command(flatten)]
    pub model: ModelArgs,
    /// Print the cycle statistics as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Write the figures.
    #[arg(long)]
    pub plot: bool,
    /// Run only the first S seconds of the cycle.
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// The baseline controllers' tuning: a TOML file of `BaselineTuning` fields (the rest keep
    /// their defaults), e.g. `lambda_limit = 1.1` or `torque = [0.03, 3.0]` (docs/control.md).
    #[arg(long, value_name = "FILE.toml")]
    pub tuning: Option<PathBuf>,
    /// Loop margins of the air-path loops in feedback every S seconds of the run (baseline
    /// controller; DIR/margins.csv).
    #[arg(long, value_name = "S")]
    pub margins: Option<f64>,
}

/// `--controller`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ControllerArg {
    /// PID loops on lambda_O and x_egr with min selectors, torque-following fuel with a smoke
    /// limiter (docs/control.md).
    Baseline,
    /// The open-loop commands of data/whtc_inputs_10hz.csv, sampled every 10 ms (WHTC only).
    OpenLoop,
}

/// A finished run: the core's [`CycleRun`] and its wall time.
pub struct Run {
    /// The run.
    pub run: CycleRun,
    /// Wall time of the run [s].
    pub wall_s: f64,
}

/// Read a user's cycle file: a demand (columns t, n_e, M_ref) or a normalized cycle
/// ([`mvem::io::csv_demand::parse_cycle_file`]).
fn read_cycle_file(path: &Path) -> Result<CycleSource> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        let hint = if path
            .to_str()
            .is_some_and(|p| p.eq_ignore_ascii_case("whtc"))
        {
            " (the built-in WHTC is `--cycle whtc`, lower case)"
        } else {
            ""
        };
        common::usage(format!("--cycle {}: {e}{hint}", path.display()))
    })?;
    mvem::io::csv_demand::parse_cycle_file(&text, path).map_err(|e| common::usage(e.to_string()))
}

/// Read `--tuning`: the baseline controllers' tuning from TOML, checked.
pub fn read_tuning(path: &Path) -> Result<BaselineTuning> {
    let name = path.display();
    let text = std::fs::read_to_string(path)
        .map_err(|e| common::usage(format!("--tuning {name}: {e}")))?;
    let t: BaselineTuning = toml::from_str(&text)
        .map_err(|e| common::usage(format!("--tuning {name}: {}", e.to_string().trim_end())))?;
    t.validate()
        .map_err(|e| common::usage(format!("--tuning {name}: {e}")))?;
    Ok(t)
}

/// Run the cycle `cycle` (`whtc` or a CSV file) with `controller` (the baseline with `tuning`;
/// the core's [`drive::run_cycle_with`]; `on_row` sees the trajectory after each row).
pub fn run_cycle(
    model: &AnyModel,
    cycle: &str,
    controller: ControllerArg,
    tuning: BaselineTuning,
    duration: Option<f64>,
    on_row: &mut dyn FnMut(&Trajectory),
) -> Result<Run> {
    let start = std::time::Instant::now();
    let whtc = cycle == "whtc";
    if !whtc && controller == ControllerArg::OpenLoop {
        return Err(common::usage(
            "--controller open-loop runs the open-loop WHTC schedule only: use --cycle whtc",
        ));
    }
    if let Some(s) = duration {
        drive::check_duration(s, drive::SAMPLE_TIME)
            .map_err(|e| common::usage(format!("--duration {e}")))?;
    }
    let source = if whtc {
        CycleSource::Whtc
    } else {
        read_cycle_file(Path::new(cycle))?
    };
    let scheme = match controller {
        ControllerArg::Baseline => Scheme::Baseline(tuning),
        ControllerArg::OpenLoop => Scheme::OpenLoop(common::whtc_schedule()?),
    };
    let run = match drive::run_cycle_with(model, source, scheme, duration, on_row) {
        Ok(r) => r,
        // a user's demand the engine cannot follow
        Err(e @ ControlError::Demand(_)) if !whtc => {
            return Err(common::usage(format!("--cycle {cycle}: {e}")))
        }
        Err(e @ ControlError::Setup(_)) => return Err(e.into()),
        Err(e) => return Err(anyhow::Error::new(e).context("closed-loop simulation failed")),
    };
    for w in &run.warnings {
        // the core's "duration" is this command's --duration
        let w = w
            .strip_prefix("duration ")
            .map_or(w.clone(), |r| format!("--duration {r}"));
        eprintln!("warning: --cycle {cycle}: {w}");
    }
    Ok(Run {
        run,
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// Rows per block handed to the trajectory writer.
const BLOCK: usize = 4096;

/// Send the trajectory rows not sent yet (`sent` of them were) as one block when a whole
/// block is waiting, or whatever is left with `all`. A writer that stopped on an error has
/// closed the channel; [`write_streaming`] reports its error, so a failed send is ignored.
fn send_rows(traj: &Trajectory, sent: &mut usize, tx: &SyncSender<Block>, all: bool) {
    let n = traj.len();
    if n == *sent || (!all && n - *sent < BLOCK) {
        return;
    }
    let rows = traj.columns.iter().map(|c| c[*sent..n].to_vec()).collect();
    *sent = n;
    let _ = tx.send(rows);
}

fn figure(traj: &Trajectory, title: &str) -> Figure {
    // every 10th sample (10 Hz) keeps the figure light
    let dec = |name: &str| -> Vec<f64> {
        traj.get(name)
            .unwrap()
            .iter()
            .step_by(10)
            .cloned()
            .collect()
    };
    let t = dec("t");
    let pe: Vec<f64> = dec("p_em")
        .iter()
        .zip(dec("p_im"))
        .map(|(a, b)| (a - b) / 1e5)
        .collect();
    let mut fig = Figure::new(1);
    fig.title = Some(title.to_string());
    // a drive cycle's dense traces fill every corner of a panel: the legends go in a row above
    // the axes, which then fit the data
    fig.panels = vec![
        Panel::new("t [s]", "torque [Nm]")
            .legend_above()
            .title("torque tracking")
            .with(Series::line("M_ref", &t, &dec("M_ref"), 1))
            .with(Series::line("M_e", &t, &dec("M_e"), 0)),
        Panel::new("t [s]", "lambda_O [-]")
            .legend_above()
            .title("oxygen/fuel ratio (clipped at 5; dashed: the limit 1.2)")
            .with(Series::line(
                "lambda_O,s",
                &t,
                &dec("lambda_O_ref")
                    .iter()
                    .map(|v| v.min(5.0))
                    .collect::<Vec<_>>(),
                1,
            ))
            .with(Series::line(
                "lambda_O",
                &t,
                &dec("lambda_O")
                    .iter()
                    .map(|v| v.min(5.0))
                    .collect::<Vec<_>>(),
                0,
            ))
            .with(Series::hline("", t[0], *t.last().unwrap(), 1.2, 3)),
        Panel::new("t [s]", "x_egr [-]")
            .legend_above()
            .title("EGR fraction")
            .with(Series::line("x_egr,s", &t, &dec("x_egr_ref"), 1))
            .with(Series::line("x_egr", &t, &dec("x_egr"), 0)),
        Panel::new("t [s]", "command")
            .legend_above()
            .title("actuator commands")
            .with(Series::line("u_egr [%]", &t, &dec("u_egr"), 0))
            .with(Series::line("u_vgt [%]", &t, &dec("u_vgt"), 1))
            .with(Series::line("u_delta [mg]", &t, &dec("u_delta"), 2)),
        Panel::new("t [s]", "p_em - p_im [bar]")
            .legend_above()
            .title("pumping pressure difference")
            .with(Series::line("p_em - p_im", &t, &pe, 0)),
    ];
    fig.panel_size = (1400, 320);
    fig
}

fn stats_json(a: &Args, w: &Run, tuning: &BaselineTuning) -> serde_json::Value {
    let baseline = a.controller == ControllerArg::Baseline;
    let mut v = mvem::analysis::json::cycle_run_json(&w.run, baseline.then_some(tuning));
    v["cycle"] = serde_json::json!(a.cycle);
    v["controller"] = serde_json::json!(a
        .controller
        .to_possible_value()
        .map(|v| v.get_name().to_string()));
    v["model_states"] = serde_json::json!(a.model.order().states());
    v["wall_time_s"] = serde_json::json!(w.wall_s);
    v
}

/// Run `mvem closed-loop`.
pub fn run(a: &Args) -> Result<()> {
    outdir::check(&a.out)?;
    let tuning = match (&a.tuning, a.controller) {
        (Some(_), ControllerArg::OpenLoop) => {
            return Err(common::usage(
                "--tuning sets the baseline controllers; --controller open-loop has none",
            ))
        }
        (Some(p), ControllerArg::Baseline) => read_tuning(p)?,
        (None, _) => BaselineTuning::default(),
    };
    if let Some(every) = a.margins {
        if a.controller == ControllerArg::OpenLoop {
            return Err(common::usage(
                "--margins analyses the baseline controller's loops; --controller open-loop has none",
            ));
        }
        if !(every.is_finite() && every > 0.0) {
            return Err(common::usage(format!(
                "--margins {every}: must be a finite number of seconds > 0"
            )));
        }
    }
    if a.model.semantics == common::SemanticsArg::Paper {
        return Err(common::usage(format!(
            "--semantics paper: {}; use --semantics authors (the default)",
            drive::PAPER_SEMANTICS_REFUSED
        )));
    }
    // the analysed samples lie on the 10 ms grid: a spacing off it would alternate between
    // its neighbours
    let margins_every = a.margins.map(|every| {
        let ts = drive::SAMPLE_TIME;
        let on_grid = ((every / ts).round() * ts).max(ts);
        if (on_grid - every).abs() > 1e-9 * every.max(1.0) {
            eprintln!(
                "warning: --margins {every}: not a multiple of the {ts} s sample time; analyses \
                 every {} s",
                mvem::numerics::Num(on_grid)
            );
        }
        on_grid
    });
    let model = a.model.build()?;
    // DIR/trajectory.csv (every column, shortest round-trip numbers, `NaN` for a missing
    // set-point) is formatted and written on a second thread while the loop runs
    // (`io::output::write_streaming`): the loop is sequential, so formatting the 180 001 WHTC
    // rows (50 MB) overlaps it instead of following it. The file appears only once the loop,
    // the statistics and the figure have succeeded; on a failure the temporary file is
    // removed, and DIR too if this run created it, so nothing partial is left.
    let created = !a.out.exists();
    std::fs::create_dir_all(&a.out)
        .map_err(|e| common::usage(format!("--out {}: {e}", a.out.display())))?;
    let path = a.out.join("trajectory.csv");
    let produced = write_streaming(
        &path,
        &Trajectory::NAMES,
        4,
        |b| b,
        |tx| {
            let mut sent = 0;
            let w = run_cycle(
                &model,
                &a.cycle,
                a.controller,
                tuning,
                a.duration,
                &mut |traj| send_rows(traj, &mut sent, &tx, false),
            )?;
            send_rows(&w.run.traj, &mut sent, &tx, true);
            let mut json = stats_json(a, &w, &tuning);
            let mut files = Files::default();
            let margins = match margins_every {
                Some(every) => {
                    let points = along::along_trajectory(&model, &w.run.traj, &tuning, every)
                        .map_err(anyhow::Error::msg)?;
                    let summary = along::summarize(&points);
                    json["margins"] = along::summary_json(every, &summary);
                    files.add("margins.csv", along::points_csv(&points));
                    if a.plot {
                        files.figure("margins", &margins_figure(&points, &summary))?;
                    }
                    Some(summary)
                }
                None => None,
            };
            files.add(
                "stats.json",
                serde_json::to_string_pretty(&json).expect("serializable") + "\n",
            );
            if a.plot {
                let title = format!(
                    "{} on the {} ({}-state model)",
                    json["controller"].as_str().unwrap_or(""),
                    a.cycle,
                    a.model.order().states()
                );
                files.figure("closed_loop", &figure(&w.run.traj, &title))?;
            }
            // a termination signal after the loop (mvem's handler cancels the token): fail
            // here, so that the temporary trajectory file is removed, not renamed
            if mvem::numerics::cancel::requested() {
                anyhow::bail!("cancelled (a termination signal) before the files were written");
            }
            Ok((w, json, files, margins))
        },
    );
    let (w, json, files, margins) = match produced {
        Ok(v) => v,
        Err(e) => {
            if created {
                let _ = std::fs::remove_dir(&a.out); // only if still empty
            }
            return Err(match e {
                StreamError::Produce(e) => e,
                StreamError::Io(e) => {
                    anyhow::Error::new(e).context(format!("cannot write {}", path.display()))
                }
            });
        }
    };
    let r = &w.run;
    // trajectory.csv first: the other files are written once everything is computed; if one
    // of them fails, none of this run's files is left (trajectory.csv removed again)
    let mut written = vec![path.clone()];
    match files.write(&a.out) {
        Ok(w) => written.extend(w),
        Err(e) => {
            outdir::remove_all(&written);
            if created {
                let _ = std::fs::remove_dir(&a.out);
            }
            return Err(e);
        }
    }
    // a previous run's figures or margins that this run does not write would sit beside its
    // results as if they were its own
    let stale = outdir::remove_stale(&a.out, &OUR_FILES, &files);
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json).expect("serializable")
        );
    } else {
        let s = &r.stats;
        match &s.torque.not_applicable {
            None => println!(
                "torque regression: slope {:.3}, intercept {:.1} Nm, R^2 {:.3}, SEE {:.1} Nm ({:.1} % of {:.0} Nm)",
                s.torque.slope,
                s.torque.intercept,
                s.torque.r2,
                s.torque.see,
                100.0 * s.torque.see / s.m_max,
                s.m_max
            ),
            Some(why) => println!(
                "torque regression: not applicable ({} samples with positive reference torque; {why})",
                s.torque.samples
            ),
        }
        let or_na = |v: f64, f: &dyn Fn(f64) -> String| {
            if v.is_finite() {
                f(v)
            } else {
                "n/a".to_string()
            }
        };
        println!(
            "positive work {:.3} kWh (reference {:.3} kWh, {}); fuel {:.3} kg, BSFC {}",
            s.work_act_kwh,
            s.work_ref_kwh,
            or_na(s.work_error, &|v| format!("{:+.2} %", 100.0 * v)),
            s.fuel_kg,
            or_na(s.bsfc_g_kwh, &|v| format!("{v:.1} g/kWh"))
        );
        for why in &s.not_applicable {
            println!("  not applicable: {why}");
        }
        if s.fired == 0 {
            println!(
                "lambda_O: no fired sample; mean p_em - p_im {:.0} Pa",
                s.pmep_mean_pa
            );
        } else {
            println!(
                "lambda_O min {:.3} (t = {:.2} s), below {} in {:.2} % of fired samples; x_egr RMS error {}; mean p_em - p_im {:.0} Pa",
                s.lambda_o_min,
                s.lambda_o_min_t,
                s.lambda_limit,
                100.0 * s.lambda_below_limit_share,
                or_na(s.x_egr_rms_error, &|v| format!("{v:.4}")),
                s.pmep_mean_pa
            );
        }
        if r.violations.is_empty() {
            println!("regulation limits: pass");
        } else {
            println!("regulation limits: FAIL: {}", r.violations.join("; "));
        }
        if !r.setpoint_adjustments.is_empty() {
            // the limit each line gives is the one the controller applies (`u_egr_limit`: the
            // valve's position set-point plus the tuning's egr_open_beyond_setpoint)
            let beyond = tuning.egr_open_beyond_setpoint;
            let how = if beyond == 0.0 {
                "the lambda_O loop opens it no further".to_string()
            } else {
                format!(
                    "the lambda_O loop opens it up to egr_open_beyond_setpoint = {} % further",
                    mvem::numerics::Num(beyond)
                )
            };
            println!(
                "set-point maps: {} cell(s) whose pair (lambda_O,s, x_egr,s) the actuators cannot \
                 reach together; the EGR valve's position is their third set-point ({how}):",
                r.setpoint_adjustments.len()
            );
            for c in &r.setpoint_adjustments {
                let set = if c.u_egr_limit == c.u_egr_max {
                    String::new()
                } else {
                    format!("set-point {:.1} %; ", c.u_egr_max)
                };
                println!(
                    "  {:.0} rpm, L {:.2} ({:.1} mg/cycle): u_egr <= {:.1} % ({set}{})",
                    c.n_e, c.load, c.u_delta, c.u_egr_limit, c.reason
                );
            }
        }
        println!("{} samples in {:.2} s", r.traj.len(), w.wall_s);
        if let Some(m) = &margins {
            print_margins(m);
        }
    }
    eprintln!("{}", outdir::wrote(&written));
    if !stale.is_empty() {
        eprintln!(
            "Removed {} of a previous run in {} (not written by this one)",
            stale.join(", "),
            a.out.display()
        );
    }
    Ok(())
}

/// The files `mvem closed-loop` may write in its directory besides trajectory.csv and
/// stats.json (which every run writes).
const OUR_FILES: [&str; 5] = [
    "closed_loop.svg",
    "closed_loop.png",
    "margins.csv",
    "margins.svg",
    "margins.png",
];

/// A sample time for the output: rounded to 1e-9 s (`t0 + k T_s` prints as 12.03, not
/// 12.030000000000001).
fn time(t: f64) -> mvem::numerics::Num {
    mvem::numerics::Num((t * 1e9).round() / 1e9)
}

/// The margins summary's lines (`--margins`).
fn print_margins(m: &AlongSummary) {
    println!(
        "loop margins at {} samples: {} analysed ({} at a physically invalid steady state), {} \
         without a loop in feedback, {} refused",
        m.points, m.analysed, m.invalid_steady, m.no_loop, m.refused
    );
    if m.unstable_t.is_empty() {
        println!("  every analysed sample's loops stable together");
    } else {
        let shown: Vec<String> = m
            .unstable_t
            .iter()
            .take(8)
            .map(|t| format!("{}", time(*t)))
            .collect();
        println!(
            "  loops UNSTABLE together at {} samples: t = {}{} s",
            m.unstable_t.len(),
            shown.join(", "),
            if m.unstable_t.len() > 8 { ", ..." } else { "" }
        );
    }
    let at = |v: Option<(f64, f64)>, unit: &str| {
        v.map_or("-".to_string(), |(v, t)| {
            format!("{v:.3}{unit} (t = {} s)", time(t))
        })
    };
    for l in &m.loops {
        println!(
            "  {:<26} {:>5} samples ({} unstable, {} without effect): gain margin min {}, phase \
             margin min {}, peak |1/(1+L)| max {}",
            l.name,
            l.points,
            l.unstable,
            l.inert,
            at(l.min_gain_margin, ""),
            at(l.min_phase_margin_deg, " deg"),
            at(l.max_peak_sensitivity, "")
        );
    }
}

/// `--margins --plot`: the gain and phase margins (the other loop closed) of each loop while it
/// was in feedback, over time, and the rate of the closed loops' slowest mode.
fn margins_figure(points: &[AlongPoint], s: &AlongSummary) -> Figure {
    let series = |name: &str, f: &dyn Fn(&mvem::control::margins::LoopMargins) -> Option<f64>| {
        let (mut t, mut v) = (Vec::new(), Vec::new());
        for p in points {
            if let Outcome::Analysed(a) = &p.outcome {
                if let Some(k) = a.loops.iter().position(|l| l.name == name) {
                    if let Some(y) = f(&a.others_closed[k]) {
                        t.push(p.t);
                        v.push(y);
                    }
                }
            }
        }
        (t, v)
    };
    let mut g = Panel::new("t [s]", "gain margin [dB]").title("gain margin (other loop closed)");
    // the loops' colours are the gain margin panel's: one legend, over that panel's top
    let mut ph = Panel::new("t [s]", "phase margin [deg]")
        .title("phase margin (other loop closed; colours as above)");
    for (c, l) in s.loops.iter().enumerate() {
        let (t, v) = series(&l.name, &|m| m.gain_margin.map(|g| 20.0 * g.log10()));
        g = g.with(Series::markers(l.name.clone(), &t, &v, c).radius(2));
        let (t, v) = series(&l.name, &|m| m.phase_margin_deg);
        ph = ph.with(Series::markers("", &t, &v, c).radius(2));
    }
    let (mut t, mut v) = (Vec::new(), Vec::new());
    for p in points {
        if let Outcome::Analysed(a) = &p.outcome {
            t.push(p.t);
            // the slowest mode's rate: ln |z| per sample time (> 0 grows)
            v.push(a.max_pole_all.ln() / a.ts);
        }
    }
    let mut poles = Panel::new("t [s]", "ln|z| / Ts [1/s]")
        .title("slowest closed-loop mode, every loop in feedback closed (> 0: unstable)");
    if let (Some(t0), Some(t1)) = (t.first().copied(), t.last().copied()) {
        poles = poles
            .with(Series::markers("ln|z| / Ts of the largest |z|", &t, &v, 0).radius(2))
            .with(Series::hline("stability boundary", t0, t1, 0.0, 3));
    }
    let mut fig = Figure::new(1);
    fig.title = Some(
        "loop margins along the run (frozen at the steady state of each sample's commands)".into(),
    );
    fig.panels = vec![g, ph, poles];
    fig.panel_size = (1400, 300);
    fig
}
