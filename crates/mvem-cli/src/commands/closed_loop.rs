//! `mvem closed-loop`: a drive cycle with the baseline EGR/VGT and engine controllers (or the
//! open-loop WHTC schedule) around the model; trajectory, cycle statistics and figures.

use crate::common::{self, ModelArgs};
use crate::outdir::{self, Files};
use crate::plot::{Figure, Panel, Series};
use anyhow::{Context, Result};
use clap::ValueEnum;
use mvem::control::baseline::{Baseline, BaselineTuning, OpenLoop};
use mvem::control::cycle::{
    parse_normalized_table, whtc_demand, Demand, MappingCurve, MappingOptions, ReferenceSpeeds,
    WHTC_NORMALIZED,
};
use mvem::control::stats::CycleStats;
use mvem::control::{self, Controller, Trajectory};
use mvem::model::AnyModel;
use mvem::sim::{SimOptions, SimStats};
use std::path::{Path, PathBuf};

/// Arguments of `mvem closed-loop`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem closed-loop --cycle whtc --out out/closed-loop --plot
  mvem closed-loop --cycle whtc --controller open-loop --out out/open-loop --json
  mvem closed-loop --cycle my_cycle.csv --out out/mine

--cycle whtc: the WHTC (UN GTR No. 4) denormalized with this engine's mapping curve (full-load
torque at lambda_O >= 1.2, motoring torque for the \"m\" points), speeds 0 s..1800 s.
--cycle FILE.csv: a header with the columns t [s], n_e [rpm], M_ref [Nm] (any order, more
columns ignored), time strictly increasing, n_e in [500, 2000] rpm, M_ref at most the full-load
torque; linear between rows.

Writes DIR/trajectory.csv (one row per 10 ms controller sample; the commands u_delta, u_egr,
u_vgt are held until the next row), DIR/stats.json and with --plot DIR/closed_loop.svg/.png.
--json prints the statistics to stdout. Nothing is written unless the whole run succeeds.")]
pub struct Args {
    /// Drive cycle: `whtc` or a CSV file with t, n_e, M_ref.
    #[arg(long, value_name = "whtc|FILE.csv", default_value = "whtc")]
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

/// A finished run.
pub struct Run {
    /// One row per sample.
    pub traj: Trajectory,
    /// Statistics.
    pub stats: CycleStats,
    /// Regulation limit violations (empty: pass).
    pub violations: Vec<String>,
    /// Reference speeds of the mapping curve.
    pub speeds: ReferenceSpeeds,
    /// Solver statistics of the plant.
    pub solver: SimStats,
    /// Wall time of the run [s].
    pub wall_s: f64,
}

/// The WHTC table with the first sample repeated at t = 0 (as data/whtc_inputs_10hz.csv).
fn whtc_table() -> Result<Vec<(f64, f64, Option<f64>)>> {
    let mut table = parse_normalized_table(WHTC_NORMALIZED)
        .map_err(|e| anyhow::anyhow!("built-in WHTC table: {e}"))?;
    let first = table[0];
    table.insert(0, (0.0, first.1, first.2));
    Ok(table)
}

/// Read a user's cycle CSV: columns t, n_e, M_ref.
fn read_cycle_csv(path: &Path) -> Result<Demand> {
    let name = path.display().to_string();
    let text =
        std::fs::read_to_string(path).map_err(|e| common::usage(format!("--cycle {name}: {e}")))?;
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    let headers = rdr
        .headers()
        .map_err(|e| common::usage(format!("{name}: line 1: cannot read the header: {e}")))?
        .clone();
    let col = |want: &str| headers.iter().position(|h| h == want);
    let missing: Vec<&str> = ["t", "n_e", "M_ref"]
        .into_iter()
        .filter(|c| col(c).is_none())
        .collect();
    if !missing.is_empty() {
        return Err(common::usage(format!(
            "{name}: line 1: missing column(s) {} (needed: t [s], n_e [rpm], M_ref [Nm]; found: {})",
            missing.join(", "),
            headers.iter().collect::<Vec<_>>().join(", ")
        )));
    }
    let idx = [
        col("t").unwrap(),
        col("n_e").unwrap(),
        col("M_ref").unwrap(),
    ];
    let (mut t, mut n, mut m) = (vec![], vec![], vec![]);
    for (i, rec) in rdr.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| common::usage(format!("{name}: line {line}: {e}")))?;
        let mut v = [0.0; 3];
        for (k, &c) in idx.iter().enumerate() {
            let field = rec.get(c).unwrap_or("");
            v[k] = field.parse::<f64>().map_err(|_| {
                common::usage(format!(
                    "{name}: line {line}: {} = '{field}' is not a number",
                    ["t", "n_e", "M_ref"][k]
                ))
            })?;
        }
        t.push(v[0]);
        n.push(v[1]);
        m.push(v[2]);
    }
    let k = t.len();
    Demand::new(t, n, m, vec![false; k])
        .map_err(|e| common::usage(format!("{name}: {e} (rows counted after the header)")))
}

/// Build the demand and controller, run the loop and compute the statistics.
pub fn run_cycle(
    model: &AnyModel,
    cycle: &str,
    controller: ControllerArg,
    duration: Option<f64>,
) -> Result<Run> {
    let start = std::time::Instant::now();
    let curve = MappingCurve::compute(model, MappingOptions::default())
        .context("cannot compute the engine's mapping curve")?;
    let speeds = curve.reference_speeds(500.0);
    let whtc = cycle == "whtc";
    let demand =
        match (whtc, controller) {
            (true, ControllerArg::Baseline) => whtc_demand(&whtc_table()?, &curve, &speeds)?,
            (true, ControllerArg::OpenLoop) => {
                // the open-loop schedule has its own speed trace: the reference torque is the
                // normalized torque on this engine's curve at that speed
                let sched = common::whtc_schedule()?;
                let table = whtc_table()?;
                let (mut t, mut n, mut m, mut mot) = (vec![], vec![], vec![], vec![]);
                for &(ti, _, tq) in &table {
                    let ne = sched.at(ti).n_e_rpm;
                    t.push(ti);
                    n.push(ne);
                    m.push(match tq {
                        Some(p) => p / 100.0 * curve.m_max_at(ne),
                        None => curve.m_motor_at(ne),
                    });
                    mot.push(tq.is_none());
                }
                Demand::new(t, n, m, mot)?
            }
            (false, ControllerArg::OpenLoop) => return Err(common::usage(
                "--controller open-loop runs the open-loop WHTC schedule only: use --cycle whtc",
            )),
            (false, ControllerArg::Baseline) => {
                let d = read_cycle_csv(Path::new(cycle))?;
                d.check_feasible(&curve, 0.01)
                    .map_err(|e| common::usage(format!("--cycle {cycle}: {e}")))?;
                d
            }
        };
    let demand = match duration {
        None => demand,
        Some(s) => {
            let (t0, t1) = demand.span();
            if !(s.is_finite() && s > 0.0) {
                return Err(common::usage(format!("--duration {s}: must be > 0")));
            }
            truncate(&demand, (t0 + s).min(t1))?
        }
    };
    let mut ctrl: Box<dyn Controller> = match controller {
        ControllerArg::Baseline => Box::new(
            Baseline::new(model, &curve, BaselineTuning::default())
                .context("cannot set up the baseline controller")?,
        ),
        ControllerArg::OpenLoop => Box::new(OpenLoop {
            schedule: common::whtc_schedule()?,
            ts: 0.01,
        }),
    };
    let (traj, solver) = control::run(
        model.clone(),
        &demand,
        ctrl.as_mut(),
        &SimOptions::default(),
    )
    .context("closed-loop simulation failed")?;
    let stats = CycleStats::compute(&traj, curve.m_peak(), 1.2);
    let violations = stats.violations(1.05);
    Ok(Run {
        traj,
        stats,
        violations,
        speeds,
        solver,
        wall_s: start.elapsed().as_secs_f64(),
    })
}

/// The demand up to `t_end` (linear at the cut).
fn truncate(d: &Demand, t_end: f64) -> Result<Demand> {
    let ts: Vec<f64> = d.times().iter().cloned().filter(|&t| t < t_end).collect();
    let mut t = ts.clone();
    t.push(t_end);
    let pts: Vec<_> = t.iter().map(|&x| d.at(x)).collect();
    Ok(Demand::new(
        t,
        pts.iter().map(|p| p.n_e).collect(),
        pts.iter().map(|p| p.m_ref).collect(),
        pts.iter().map(|p| p.motoring).collect(),
    )?)
}

/// The trajectory as CSV text.
pub fn trajectory_csv(traj: &Trajectory) -> String {
    let mut s = Trajectory::NAMES.join(",");
    s.push('\n');
    for i in 0..traj.len() {
        let row: Vec<String> = traj
            .columns
            .iter()
            .map(|c| {
                let v = c[i];
                if v.is_nan() {
                    "NaN".to_string()
                } else {
                    // shortest representation that reads back exactly
                    format!("{v}")
                }
            })
            .collect();
        s.push_str(&row.join(","));
        s.push('\n');
    }
    s
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
    fig.panels = vec![
        Panel::new("t [s]", "torque [Nm]")
            .title("torque tracking")
            .with(Series::line("M_ref", &t, &dec("M_ref"), 1))
            .with(Series::line("M_e", &t, &dec("M_e"), 0)),
        Panel::new("t [s]", "lambda_O [-]")
            .title("oxygen/fuel ratio")
            .with(Series::line(
                "lambda_O,s (clipped at 5)",
                &t,
                &dec("lambda_O_ref")
                    .iter()
                    .map(|v| v.min(5.0))
                    .collect::<Vec<_>>(),
                1,
            ))
            .with(Series::line(
                "lambda_O (clipped at 5)",
                &t,
                &dec("lambda_O")
                    .iter()
                    .map(|v| v.min(5.0))
                    .collect::<Vec<_>>(),
                0,
            ))
            .with(Series::hline("limit 1.2", t[0], *t.last().unwrap(), 1.2, 3)),
        Panel::new("t [s]", "x_egr [-]")
            .title("EGR fraction")
            .with(Series::line("x_egr,s", &t, &dec("x_egr_ref"), 1))
            .with(Series::line("x_egr", &t, &dec("x_egr"), 0)),
        Panel::new("t [s]", "command")
            .title("actuator commands")
            .with(Series::line("u_egr [%]", &t, &dec("u_egr"), 0))
            .with(Series::line("u_vgt [%]", &t, &dec("u_vgt"), 1))
            .with(Series::line("u_delta [mg]", &t, &dec("u_delta"), 2)),
        Panel::new("t [s]", "p_em - p_im [bar]")
            .title("pumping pressure difference")
            .with(Series::line("p_em - p_im", &t, &pe, 0)),
    ];
    fig.panel_size = (1400, 300);
    fig
}

fn stats_json(a: &Args, r: &Run) -> serde_json::Value {
    serde_json::json!({
        "cycle": a.cycle,
        "controller": a.controller.to_possible_value().map(|v| v.get_name().to_string()),
        "model_states": a.model.order().states(),
        "sample_time_s": 0.01,
        "reference_speeds_rpm": r.speeds,
        "stats": r.stats,
        "violations": r.violations,
        "passes": r.violations.is_empty(),
        "solver": {"steps": r.solver.steps, "rejected": r.solver.rejected, "rhs_evals": r.solver.rhs_evals},
        "wall_time_s": r.wall_s,
    })
}

/// Run `mvem closed-loop`.
pub fn run(a: &Args) -> Result<()> {
    outdir::check(&a.out)?;
    let model = a.model.build()?;
    let r = run_cycle(&model, &a.cycle, a.controller, a.duration)?;
    let json = stats_json(a, &r);
    let mut files = Files::default();
    files.add("trajectory.csv", trajectory_csv(&r.traj));
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
        files.figure("closed_loop", &figure(&r.traj, &title))?;
    }
    let written = files.write(&a.out)?;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json).expect("serializable")
        );
    } else {
        let s = &r.stats;
        println!(
            "torque regression: slope {:.3}, intercept {:.1} Nm, R^2 {:.3}, SEE {:.1} Nm ({:.1} % of {:.0} Nm)",
            s.torque.slope,
            s.torque.intercept,
            s.torque.r2,
            s.torque.see,
            100.0 * s.torque.see / s.m_max,
            s.m_max
        );
        println!(
            "positive work {:.3} kWh (reference {:.3} kWh, {:+.2} %); fuel {:.3} kg, BSFC {:.1} g/kWh",
            s.work_act_kwh,
            s.work_ref_kwh,
            100.0 * s.work_error,
            s.fuel_kg,
            s.bsfc_g_kwh
        );
        println!(
            "lambda_O min {:.3} (t = {:.2} s), below {} in {:.2} % of fired samples; x_egr RMS error {:.4}; mean p_em - p_im {:.0} Pa",
            s.lambda_o_min,
            s.lambda_o_min_t,
            s.lambda_limit,
            100.0 * s.lambda_below_limit_share,
            s.x_egr_rms_error,
            s.pmep_mean_pa
        );
        if r.violations.is_empty() {
            println!("regulation limits: pass");
        } else {
            println!("regulation limits: FAIL: {}", r.violations.join("; "));
        }
        println!("{} samples in {:.2} s", r.traj.len(), r.wall_s);
    }
    eprintln!("{}", outdir::wrote(&written));
    Ok(())
}
