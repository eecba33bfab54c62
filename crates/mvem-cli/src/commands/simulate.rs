//! `mvem simulate`: simulate an input CSV or a built-in scenario and write every state and
//! signal (or the ones chosen with `--signals`) to a CSV or Parquet file (optionally a figure).

use crate::common::{self, ModelArgs, Scenario, SolverArgs};
use crate::plot::{self, Figure, Panel, Series};
use anyhow::{Context, Result};
use mvem::analysis::steady::{chunk_guess, simulate_from_steady, simulate_from_steady_into};
use mvem::model::Model;
use mvem::numerics::Num;
use mvem::sim::{
    simulate_into_with_guess, simulate_with_guess, Block, InputSchedule, Junction, SignalEvaluator,
    SimOptions, SimStats, Solution, Start,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `mvem simulate`.
#[derive(Debug, clap::Args)]
#[command(
    group(clap::ArgGroup::new("source").required(true).args(["inputs", "scenario"])),
    after_help = "\
Examples:
  mvem simulate --scenario vgt-step-nmp --out step.csv --plot step.png
  mvem simulate --inputs data/whtc_inputs_10hz.csv --out whtc.csv --dt 0.1
  mvem simulate --inputs my.csv --out my_out.csv --params my_params.toml --rtol 1e-8
  mvem simulate --inputs data/whtc_inputs_10hz.csv --out whtc.parquet --signals p_im,W_c,lambda_O
  mvem simulate --scenario whtc --out whtc.csv --time-parallel 2

Input CSV header (any column order): time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct
Rows are interpolated linearly; two rows with the same time are a step.

Dynamometer: M_e is the engine torque of the model. A test cell measures it through the
dynamometer lag of eq. (76), a test-cell property that `mvem tune` writes to the [test_cell]
section of its output file (tau_me). When that section is present in --params, or with
--tau-me, the output gets a column M_dynamo: M_e through that first-order lag (what `mvem
validate` compares with the measured torque); --tau-me overrides the file. Likewise the
section's sensor time constants (tau_p_im, tau_p_em, tau_w_c, tau_n_t, fitted by `mvem tune`)
give columns p_im_sensor, p_em_sensor, W_c_sensor, n_t_sensor: what those sensors read, the
lag applied on the output grid (exact for an output linear between samples; use a --dt well
below the time constants)."
)]
pub struct Args {
    /// Input time series (CSV: time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct).
    #[arg(long, value_name = "FILE.csv")]
    pub inputs: Option<PathBuf>,
    /// A built-in scenario instead of --inputs.
    #[arg(long, value_enum)]
    pub scenario: Option<Scenario>,
    /// Output file: a `t` column, every state and every signal (or --signals). Parquet when
    /// the name ends in .parquet (one DOUBLE column per signal), CSV otherwise (shortest
    /// round-trip numbers).
    #[arg(long, value_name = "OUT.csv|OUT.parquet")]
    pub out: PathBuf,
    /// Write only these columns (states or signals, comma separated), after `t`.
    #[arg(long, value_name = "A,B,...", value_delimiter = ',')]
    pub signals: Option<Vec<String>>,
    /// End time [s] [default: the last input row, or the scenario's end]
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub t_end: Option<f64>,
    /// Also draw a figure of the main signals (.svg or .png).
    #[arg(long, value_name = "OUT.svg|png")]
    pub plot: Option<PathBuf>,
    /// Start from this state (JSON object: state name -> value) instead of the steady state
    /// at the first inputs.
    #[arg(long, value_name = "FILE.json")]
    pub initial_state: Option<PathBuf>,
    /// Dynamometer time constant tau_Me [s] of eq. (76): adds the column M_dynamo [default:
    /// `tau_me` of the [test_cell] section of --params; without it no M_dynamo].
    #[arg(long = "tau-me", value_name = "S")]
    pub tau_me: Option<f64>,
    /// Integrate in N time chunks at once, one thread each (each chunk after the first starts
    /// 30 s early from the steady state at its inputs; its samples are kept only where its
    /// state meets the previous chunk's within 0.1 tolerance units, otherwise the chunk is
    /// integrated again sequentially). The result agrees with the sequential run to far below
    /// the tolerance but not bit for bit; 1 (default): the sequential run. See
    /// docs/integrator.md.
    #[arg(long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=mvem::sim::MAX_TIME_CHUNKS as i64))]
    pub time_parallel: u32,
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub solver: SolverArgs,
}

/// Run `mvem simulate`.
pub fn run(a: &Args) -> Result<()> {
    // Everything that can be checked is checked before the (possibly long) simulation.
    common::check_output_path(&a.out, "--out")?;
    if let Some(p) = &a.plot {
        plot::Format::of(p)?;
        common::check_output_path(p, "--plot")?;
    }
    let opts = SimOptions {
        time_chunks: a.time_parallel as usize,
        ..a.solver.options(0.01)?
    };
    if let Some(t) = a.tau_me {
        if !(t.is_finite() && t > 0.0) {
            return Err(common::usage(format!("--tau-me {t}: must be > 0")));
        }
    }
    let model = a.model.build()?;
    // the tuned dynamometer constant of the parameter file's [test_cell] section; --tau-me
    // overrides
    let cell = match &a.model.params {
        Some(p) => mvem::io::test_cell::load_test_cell(p)
            .map_err(|e| common::usage(format!("--params {}: {e}", p.display())))?,
        None => None,
    };
    let tau_me = a.tau_me.or(cell.as_ref().and_then(|c| c.tau_me));
    // what the test cell measures: (model signal, column, time constant)
    let mut sensors: Vec<Sensor> = Vec::new();
    if let Some(t) = tau_me {
        sensors.push(("M_e", "M_dynamo".into(), t));
    }
    if let Some(l) = cell.as_ref().and_then(mvem::io::test_cell::TestCell::lags) {
        for name in mvem::tuning::sensors::LAGGED_OUTPUTS {
            if l.of(name) > 0.0 {
                sensors.push((name, format!("{name}_sensor"), l.of(name)));
            }
        }
    }
    let (sched, default_end, source) = match (&a.inputs, a.scenario) {
        (Some(path), _) => {
            let s = common::load_inputs(path, a.model.input_ranges()?.as_ref())?;
            let end = s.t_last();
            (s, end, path.display().to_string())
        }
        (None, Some(sc)) => {
            let (s, end) = sc.schedule()?;
            (s, end, format!("scenario {}", sc.name()))
        }
        (None, None) => return Err(common::usage("give --inputs FILE or --scenario NAME")),
    };
    // inputs the model cannot be evaluated at (n_e <= 0 with the paper's equations)
    let sem = a.model.options().semantics;
    for (t, row) in sched.times().iter().zip(sched.rows()) {
        mvem::model::Drive::from_array(*row)
            .check(sem)
            .map_err(|e| common::usage(format!("{source}: inputs at t = {t} s: {e}")))?;
    }
    let t0 = sched.t_first();
    let t_end = a.t_end.unwrap_or(default_end);
    if !(t_end.is_finite() && t_end > t0) {
        return Err(common::usage(format!(
            "end time {t_end} s must be after the first input time {t0} s{}",
            if a.t_end.is_none() {
                " (the inputs have a single time; give --t-end)"
            } else {
                ""
            }
        )));
    }
    common::check_samples(t0, t_end, opts.dt_out)?;
    let initial = match &a.initial_state {
        Some(p) => Some(read_initial_state(p)?),
        None => None,
    };

    let started = Instant::now();
    let msg = format!("simulating {source} from {t0} s to {t_end} s");
    let initial_path = a.initial_state.as_deref();
    let written = match &a.plot {
        // the figure needs every sample, and is rendered before anything is written
        Some(p) => {
            let mut sol = common::with_spinner(
                &msg,
                || mvem::dispatch!(&model, m => run_model(m, &sched, t0, t_end, initial.as_ref(), initial_path, &opts, None)),
            )?;
            for (src, name, tau) in &sensors {
                // eq. (76) for the torque: what the test cell measures
                if let Some(v) = sol.get(src).map(<[f64]>::to_vec) {
                    let y = mvem::tuning::lab::first_order_lag(sol.t(), &v, *tau);
                    sol.names.push(name.clone());
                    sol.columns.push(y);
                }
            }
            let wall = started.elapsed().as_secs_f64();
            // Render the figure before writing anything, so that a failure leaves no file
            // behind.
            let figure = plot::render(&solution_figure(&sol), plot::Format::of(p)?)?;
            let cols = mvem::io::output::select_columns(&sol, a.signals.as_deref())
                .map_err(|e| common::usage(format!("--signals: {e}")))?;
            mvem::io::output::write_columns(&cols, &a.out)
                .with_context(|| format!("cannot write {}", a.out.display()))?;
            mvem::io::output::write_atomic(p, &figure)
                .with_context(|| format!("cannot write {}", p.display()))?;
            Written {
                stats: sol.stats,
                guards_seen: sol.guards_seen,
                columns: cols.len(),
                wall,
                junctions: sol.junctions,
            }
        }
        None => {
            let w = stream_to_file(
                a,
                &model,
                &sched,
                t0,
                t_end,
                initial.as_ref(),
                &sensors,
                &opts,
                &msg,
            )?;
            Written {
                wall: started.elapsed().as_secs_f64(),
                ..w
            }
        }
    };
    let wall = written.wall;
    let st = written.stats;
    eprintln!(
        "simulated {source}, t = {} .. {} s, in {} wall time: {} steps ({} rejected), {} RHS evaluations, {} input breakpoints",
        Num(t0),
        Num(t_end),
        common::fmt_duration(wall),
        st.steps,
        st.rejected,
        st.rhs_evals,
        st.breakpoints
    );
    if st.chunks > 0 {
        eprintln!(
            "time-parallel: {}",
            junction_summary(&st, &written.junctions)
        );
    }
    eprintln!(
        "wrote {} samples x {} columns to {}{}",
        st.outputs,
        written.columns,
        a.out.display(),
        a.plot
            .as_ref()
            .map(|p| format!(" and a figure to {}", p.display()))
            .unwrap_or_default()
    );
    let guards: Vec<&str> = mvem::model::Guard::ALL
        .iter()
        .filter(|g| written.guards_seen & (**g as u32) != 0 && g.invalidates())
        .map(|g| g.label())
        .collect();
    if !guards.is_empty() {
        eprintln!(
            "note: saturations of the authors' implementation were active at some samples: {}",
            guards.join(", ")
        );
    }
    Ok(())
}

/// Read `--initial-state` (`linearize --state`): a JSON object of state name -> value.
pub fn read_initial_state(path: &Path) -> Result<BTreeMap<String, f64>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| common::usage(format!("{}: {e}", path.display())))?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| common::usage(format!("{}: {e}", path.display())))?;
    let obj = v.as_object().ok_or_else(|| {
        common::usage(format!(
            "{}: expected a JSON object of state name -> value",
            path.display()
        ))
    })?;
    let mut out = BTreeMap::new();
    for (k, v) in obj {
        let x = v.as_f64().ok_or_else(|| {
            common::usage(format!(
                "{}: field {k}: {v} is not a number",
                path.display()
            ))
        })?;
        out.insert(k.clone(), x);
    }
    Ok(out)
}

/// The state vector of model `m` from named values (every state required, no unknown names;
/// [`mvem::model::meta::state_from_named`]), errors naming the file and the field.
pub fn state_from_map<const N: usize, M: Model<N>>(
    m: &M,
    values: &BTreeMap<String, f64>,
    source: &Path,
    then: &str,
) -> Result<[f64; N]> {
    use mvem::model::meta::{state_from_named, NamedStateError};
    let src = source.display();
    let named: Vec<(String, f64)> = values.iter().map(|(k, v)| (k.clone(), *v)).collect();
    let x = state_from_named(&m.state_names(), &named).map_err(|e| {
        common::usage(match e {
            NamedStateError::Unknown { name, states } => {
                format!("{src}: field {name}: unknown state (the states are {states})")
            }
            NamedStateError::Missing(n) => format!("{src}: field {n}: missing state"),
            NamedStateError::NonFinite { name, value } => {
                format!("{src}: field {name}: {value} is not finite")
            }
        })
    })?;
    // the integrator limits (the authors' limited integrators, items 9-12 and 37) clip the start
    for w in mvem::model::start_clip_warnings(&m.state_names(), &m.state_bounds(), &x, then) {
        eprintln!("warning: {src}: field {w}");
    }
    Ok(x)
}

/// Simulate from `initial` (or the steady state at the first inputs) into `into` (a streaming
/// solution), or into a new solution that keeps every sample.
#[allow(clippy::too_many_arguments)]
fn run_model<const N: usize, M: Model<N>>(
    m: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    initial: Option<&BTreeMap<String, f64>>,
    initial_path: Option<&Path>,
    opts: &SimOptions,
    into: Option<Solution>,
) -> Result<Solution> {
    let start = match initial {
        Some(map) => Some(Start::State(state_from_map(
            m,
            map,
            initial_path.unwrap_or(Path::new("initial state")),
            mvem::model::STARTS_FROM,
        )?)),
        None => None,
    };
    // the time-parallel chunks start from the steady state at their inputs
    let guess = chunk_guess(m, sched);
    match (start, into) {
        (Some(x0), None) => simulate_with_guess(m, sched, t0, t_end, x0, opts, Some(&guess))
            .context("simulation failed"),
        (Some(x0), Some(sol)) => {
            simulate_into_with_guess(m, sched, t0, t_end, x0, opts, sol, Some(&guess))
                .context("simulation failed")
        }
        (None, None) => {
            simulate_from_steady(m, sched, t0, t_end, opts).context("simulation failed")
        }
        (None, Some(sol)) => {
            simulate_from_steady_into(m, sched, t0, t_end, opts, sol).context("simulation failed")
        }
    }
}

/// One line on the chunks of a time-parallel run: how many, how many integrated again, and
/// each junction's difference in tolerance units.
pub fn junction_summary(st: &SimStats, junctions: &[Junction]) -> String {
    let each: Vec<String> = junctions
        .iter()
        .map(|j| {
            format!(
                "t = {} s: {:.2e}{}",
                j.t,
                j.diff,
                if j.accepted { "" } else { " (re-run)" }
            )
        })
        .collect();
    format!(
        "{} chunks, {} re-run; junction differences (tolerance units, limit {}): {}",
        st.chunks,
        st.chunks_rerun,
        mvem::sim::JUNCTION_TOL,
        each.join(", ")
    )
}

/// What `mvem simulate` wrote.
struct Written {
    stats: SimStats,
    /// The junctions of a time-parallel run.
    junctions: Vec<Junction>,
    guards_seen: u32,
    /// Columns written.
    columns: usize,
    /// Wall time of the simulation [s] (with the overlapping writing when streamed).
    wall: f64,
}

/// Samples per block of a streamed simulation: CSV blocks are formatted while the next ones
/// are computed (small blocks: little formatting left when the simulation ends); Parquet
/// blocks are row groups (larger: fewer, fuller row groups for readers).
const CSV_BLOCK_ROWS: usize = 1024;
const PARQUET_BLOCK_ROWS: usize = 8192;

/// Simulate and write `--out` at the same time: the simulation sends blocks of samples to a
/// writer thread that evaluates their output signals (`Solution::streaming_deferred`: the
/// model evaluations of the samples leave the integrating thread), selects the columns
/// (`--signals`), adds M_dynamo (eq. (76)) and formats them (`io::output::write_streaming`:
/// the file appears only if everything succeeded).
#[allow(clippy::too_many_arguments)]
fn stream_to_file(
    a: &Args,
    model: &mvem::model::AnyModel,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    initial: Option<&BTreeMap<String, f64>>,
    sensors: &[Sensor],
    opts: &SimOptions,
    msg: &str,
) -> Result<Written> {
    mvem::dispatch!(model, m => stream_model(a, m, sched, t0, t_end, initial, sensors, opts, msg))
}

/// A column of what the test cell measures: the model signal, the column's name and the
/// sensor's first-order time constant [s].
type Sensor = (&'static str, String, f64);

/// [`stream_to_file`] for one model variant.
#[allow(clippy::too_many_arguments)]
fn stream_model<const N: usize, M: Model<N>>(
    a: &Args,
    m: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    initial: Option<&BTreeMap<String, f64>>,
    sensors: &[Sensor],
    opts: &SimOptions,
    msg: &str,
) -> Result<Written> {
    use mvem::io::output::{select_names, write_streaming, StreamError};
    let mut names = Solution::new(&m.state_names()).names;
    // (source column, lag carried from block to block) per sensor column
    let mut lags: Vec<(usize, mvem::tuning::lab::FirstOrderLag)> = Vec::new();
    for (src, name, tau) in sensors {
        if let Some(k) = names.iter().position(|n| n == src) {
            names.push(name.clone());
            lags.push((k, mvem::tuning::lab::FirstOrderLag::new(*tau)));
        }
    }
    let selected = select_names(&names, a.signals.as_deref())
        .map_err(|e| common::usage(format!("--signals: {e}")))?;
    let header: Vec<&str> = selected.iter().map(|i| names[*i].as_str()).collect();
    let mut signals = SignalEvaluator::new(m);
    let map = |raw: Block| -> Block {
        let mut block = signals.block(raw);
        for (k, lag) in &mut lags {
            // eq. (76) for the torque: what the test cell measures
            let y = block[0]
                .iter()
                .zip(&block[*k])
                .map(|(t, u)| lag.next(*t, *u))
                .collect();
            block.push(y);
        }
        // each column is selected at most once
        selected
            .iter()
            .map(|i| std::mem::take(&mut block[*i]))
            .collect()
    };
    let rows = if mvem::io::output::is_parquet(&a.out) {
        PARQUET_BLOCK_ROWS
    } else {
        CSV_BLOCK_ROWS
    };
    let initial_path = a.initial_state.as_deref();
    let sol = write_streaming(&a.out, &header, 4, map, |tx| {
        common::with_spinner(msg, || {
            let into = Solution::streaming_deferred(m, rows, tx);
            run_model(m, sched, t0, t_end, initial, initial_path, opts, Some(into))
        })
    })
    .map_err(|e| match e {
        StreamError::Produce(e) => e,
        StreamError::Io(e) => {
            anyhow::Error::new(e).context(format!("cannot write {}", a.out.display()))
        }
    })?;
    Ok(Written {
        stats: sol.stats,
        junctions: sol.junctions,
        // a deferred simulation's guards are seen where its signals are evaluated
        guards_seen: sol.guards_seen | signals.guards_seen(),
        columns: header.len(),
        wall: 0.0,
    })
}

/// The main signals of a simulation: actuators, pressures, flows, turbo speed, lambda_O.
pub fn solution_figure(sol: &Solution) -> Figure {
    let t = sol.t();
    let col = |n: &str| sol.get(n).map(|c| c.to_vec()).unwrap_or_default();
    let scaled = |n: &str, k: f64| col(n).iter().map(|v| v * k).collect::<Vec<f64>>();
    let x = "t [s]";
    let mut f = Figure::new(1);
    f.panel_size = (1100, 270);
    f.panels.push(
        Panel::new(x, "position [%]")
            .title("Actuators: commands (dashed) and positions")
            .with(Series::dashed("u_vgt command", t, &col("u_vgt"), 0))
            .with(Series::line("u_vgt position", t, &col("u_vgt_actual"), 0))
            .with(Series::dashed("u_egr command", t, &col("u_egr"), 1))
            .with(Series::line("u_egr position", t, &col("u_egr_actual"), 1)),
    );
    f.panels.push(
        Panel::new(x, "pressure [kPa]")
            .title("Manifold pressures")
            .with(Series::line("p_im", t, &scaled("p_im", 1e-3), 0))
            .with(Series::line("p_em", t, &scaled("p_em", 1e-3), 1)),
    );
    f.panels.push(
        Panel::new(x, "mass flow [kg/s]")
            .title("Compressor and EGR mass flows")
            .with(Series::line("W_c", t, &col("W_c"), 0))
            .with(Series::line("W_egr", t, &col("W_egr"), 1)),
    );
    f.panels.push(
        Panel::new(x, "n_t [krpm]")
            .title("Turbocharger speed")
            .with(Series::line("n_t", t, &scaled("n_t", 1e-3), 2)),
    );
    f.panels.push(
        Panel::new(x, "lambda_O [-]")
            .title("Oxygen-to-fuel ratio")
            .with(Series::line("lambda_O", t, &col("lambda_O"), 3)),
    );
    f
}
