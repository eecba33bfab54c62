//! `mvem bench`: simulation speed and accuracy on the WHTC drive cycle (or any input CSV), and
//! the cost of one model evaluation.

use crate::common::{self, ModelArgs, SolverArgs};
use anyhow::{Context, Result};
use mvem::analysis::ensemble::{simulate_many, Case};
use mvem::analysis::steady::chunk_guess;
use mvem::model::{AnyModel, Model, ModelInput};
use mvem::numerics::Num;
use mvem::sim::{
    simulate, simulate_into_with_guess, InputSchedule, SimOptions, SimStats, Solution, Start,
};
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `mvem bench`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem bench
  mvem bench --rtol 1e-8 --repeat 3
  mvem bench --inputs my_cycle.csv --dt 0.01 --evals 100000
  mvem bench --ensemble 8
  mvem bench --model 12 --time-parallel 4

Prints wall time (min and median over the repeats) of the integration storing t, the state and
the inputs at every output sample (as an integrator storing its states; the CVODE peer's timed
integration does that), the time to evaluate all output signals of those samples afterwards
(what `mvem simulate` adds), solver statistics, the real-time factor
(simulated seconds per wall second), the time of one model evaluation, and the deviation from a
tight (rtol 1e-10, every state integrated numerically) reference run of p_im, p_em (scaled by
1e5 Pa), X_Oim, X_Oem (by 0.1) and omega_t (by 1e4 rad/s) over the output samples.

--ensemble N times N runs of the cycle (each from its steady start) with the library's
ensemble call (mvem::analysis::ensemble::simulate_many, as mvem.simulate_many in Python) on
1 worker thread and on one thread per core, alternately, and prints the speed-up.

--time-parallel N (default 2) also times the same simulation integrated in N time chunks on N
threads (SimOptions::time_chunks), alternating with the sequential runs, and prints its
junctions and its deviation from the reference; 1 times the sequential run only. The
sequential line is one thread; the time-parallel line uses N cores.")]
pub struct Args {
    /// Input CSV [default: the built-in WHTC cycle, 1800 s at 10 Hz]
    #[arg(long, value_name = "FILE.csv")]
    pub inputs: Option<PathBuf>,
    /// Number of timed runs.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: u32,
    /// Number of model evaluations timed.
    #[arg(long, default_value_t = 1_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub evals: u64,
    /// Skip the rtol 1e-10 accuracy reference run.
    #[arg(long)]
    pub no_reference: bool,
    /// Instead: time N runs of the cycle at once on 1 thread and on all cores (the scaling).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=10000))]
    pub ensemble: Option<u32>,
    /// Also time the run in N time chunks on N threads (1: the sequential run only).
    #[arg(long, value_name = "N", default_value_t = 2,
          value_parser = clap::value_parser!(u32).range(1..=mvem::sim::MAX_TIME_CHUNKS as i64))]
    pub time_parallel: u32,
    #[command(flatten)]
    pub solver: SolverArgs,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Scales of the accuracy comparison: (state, scale).
const COMPARE: [(&str, f64); 5] = [
    ("p_im", 1e5),
    ("p_em", 1e5),
    ("X_Oim", 0.1),
    ("X_Oem", 0.1),
    ("omega_t", 1e4),
];

/// Run `mvem bench`.
pub fn run(a: &Args) -> Result<()> {
    let opts = a.solver.options(0.1)?;
    let model = a.model.build()?;
    let (sched, source, t0, t_end) =
        common::cycle_inputs(a.inputs.as_deref(), a.model.input_ranges()?.as_ref())?;
    common::check_samples(t0, t_end, opts.dt_out)?;
    if let Some(n) = a.ensemble {
        return ensemble(&model, n as usize, a.repeat, &sched, &source, &opts);
    }
    println!(
        "mvem bench: {source}, t = {} .. {} s, rtol {:e}, atol {:e}, output every {} s",
        Num(t0),
        Num(t_end),
        opts.rtol,
        opts.atol,
        Num(opts.dt_out)
    );
    mvem::dispatch!(&model, m => bench(m, a, &sched, t0, t_end, &opts))
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let s = Instant::now();
    let v = f();
    (v, s.elapsed().as_secs_f64())
}

fn bench<const N: usize, M: Model<N>>(
    m: &M,
    a: &Args,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    opts: &SimOptions,
) -> Result<()> {
    // The start is computed once; the timed runs measure the integration only.
    let x0 = mvem::analysis::steady::steady_state(m, &sched.at(t0))
        .context("steady state at the first inputs")?
        .x;
    // the time-parallel runs alternate with the sequential ones (the same load for both)
    let par_opts = (a.time_parallel > 1).then(|| SimOptions {
        time_chunks: a.time_parallel as usize,
        ..opts.clone()
    });
    let guess = chunk_guess(m, sched);
    let mut walls = Vec::new();
    let mut par_walls = Vec::new();
    let mut last: Option<Solution> = None;
    let mut last_par: Option<Solution> = None;
    // Timed: the integration storing t, the state and the inputs at the output times (as the
    // CVODE peer's timed integration stores its states), then, timed apart, the output signals
    // of those samples (`Solution::with_signals`, what `simulate` computes while it integrates).
    let run_into = |o: &SimOptions, g: Option<&_>| {
        let sol = Solution::deferred(m);
        simulate_into_with_guess(m, sched, t0, t_end, Start::State(x0), o, sol, g)
    };
    let mut signal_walls = Vec::new();
    for i in 0..a.repeat {
        let msg = format!("run {}/{}", i + 1, a.repeat);
        let (sol, w) = common::with_spinner(&msg, || timed(|| run_into(opts, None)));
        walls.push(w);
        let (sol, ws) = timed(|| sol.map(|s| s.with_signals(m)));
        signal_walls.push(ws);
        last = Some(sol.context("simulation failed")?);
        if let Some(po) = &par_opts {
            let msg = format!("run {}/{}, {} time chunks", i + 1, a.repeat, po.time_chunks);
            let (sol, w) = common::with_spinner(&msg, || timed(|| run_into(po, Some(&guess))));
            par_walls.push(w);
            last_par = Some(sol.context("time-parallel simulation failed")?);
        }
    }
    let sol = last.context("no run")?;
    // the signals of the last time-parallel run only (its deviation below), untimed
    let last_par = last_par.map(|s| s.with_signals(m));
    walls.sort_by(f64::total_cmp);
    par_walls.sort_by(f64::total_cmp);
    signal_walls.sort_by(f64::total_cmp);
    let (min, median) = (walls[0], median(&walls));
    let par_median = (!par_walls.is_empty()).then(|| self::median(&par_walls));
    let st: SimStats = sol.stats;
    println!("\nSimulation ({} runs, 1 thread)", a.repeat);
    println!(
        "  wall time          min {}, median {} (the states at the output times, as the peer)",
        common::fmt_duration(min),
        common::fmt_duration(median)
    );
    println!(
        "  output signals     min {}, median {} more for all {} columns of the output samples",
        common::fmt_duration(signal_walls[0]),
        common::fmt_duration(self::median(&signal_walls)),
        sol.names.len()
    );
    println!(
        "  steps              {} accepted, {} rejected",
        st.steps, st.rejected
    );
    println!("  RHS evaluations    {}", st.rhs_evals);
    println!("  breakpoints        {}", st.breakpoints);
    println!("  output samples     {}", st.outputs);
    println!(
        "  real-time factor   {:.0} (simulated s per wall s, median run)",
        (t_end - t0) / median
    );
    if let Some(par) = &last_par {
        let ps = par.stats;
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        println!(
            "\nTime-parallel ({} runs alternated with the above; {} chunks on {} threads, {threads} cores)",
            a.repeat, ps.chunks.max(1), ps.chunks.max(1)
        );
        println!(
            "  wall time          min {}, median {} ({:.2}x, {:.2}x the sequential)",
            common::fmt_duration(par_walls[0]),
            common::fmt_duration(par_median.unwrap_or(f64::NAN)),
            par_walls[0] / min,
            par_median.unwrap_or(f64::NAN) / median
        );
        println!(
            "  steps              {} accepted, {} rejected (all chunks, warm-ups included)",
            ps.steps, ps.rejected
        );
        println!(
            "  RHS evaluations    {} ({:+.1} % against the sequential)",
            ps.rhs_evals,
            100.0 * (ps.rhs_evals as f64 / st.rhs_evals as f64 - 1.0)
        );
        if ps.chunks > 0 {
            println!(
                "  junctions          {}",
                crate::commands::simulate::junction_summary(&ps, &par.junctions)
            );
        } else {
            println!("  junctions          none: too few stop times to split (sequential)");
        }
    }

    // One model evaluation at a state in the middle of the run.
    let mid = sol.len() / 2;
    let tm = sol.t()[mid];
    let names = m.state_names();
    let mut x = [0.0; N];
    for (i, n) in names.iter().enumerate() {
        x[i] = sol.get(n).context("state column")?[mid];
    }
    let p = m.params();
    let mut u = ModelInput::constant(sched.at(tm));
    u.u_egr_delayed = sched.at(tm - p.egr_actuator.tau_degr).u_egr_pct;
    u.u_vgt_delayed = sched.at(tm - p.vgt_actuator.tau_dvgt).u_vgt_pct;
    let mem = m.cylinder_fixed_point(&x, &u);
    let ((), w) = common::with_spinner("timing model evaluations", || {
        timed(|| {
            for _ in 0..a.evals {
                black_box(m.eval(black_box(&x), black_box(&u), black_box(mem)));
            }
        })
    });
    let ((), wd) = common::with_spinner("timing derivative evaluations", || {
        timed(|| {
            for _ in 0..a.evals {
                black_box(m.derivatives(black_box(&x), black_box(&u), black_box(mem)));
            }
        })
    });
    println!(
        "\nModel evaluation (state at t = {} s, {} calls): {} per call with all signals \
         (Model::eval), {} for the derivatives alone (Model::derivatives, what the integrator calls)",
        tidy_time(tm),
        a.evals,
        common::fmt_duration(w / a.evals as f64),
        common::fmt_duration(wd / a.evals as f64)
    );
    // Where the sequential run's time goes, estimated from that cost (one state, a warm cache:
    // an estimate, not a profile): the right-hand side at this cost, the rest per trial step.
    if a.evals >= 1000 {
        let rhs = wd / a.evals as f64 * st.rhs_evals as f64;
        let trials = (st.steps + st.rejected) as f64;
        println!(
            "  in the run above (estimate): its {} RHS evaluations at this cost take {} ({:.0} % of \
             the min run), everything else the integrator does {} per trial step ({} trial steps)",
            st.rhs_evals,
            common::fmt_duration(rhs),
            100.0 * rhs / min,
            common::fmt_duration(((min - rhs) / trials).max(0.0)),
            st.steps + st.rejected
        );
    }

    if a.no_reference {
        return Ok(());
    }
    // The reference integrates every state numerically (no closed-form actuator states), so
    // the comparison also checks the closed form.
    let ref_opts = SimOptions {
        rtol: 1e-10,
        atol: 1e-12,
        exact_actuators: false,
        ..opts.clone()
    };
    let (reference, w) = common::with_spinner("reference run (rtol 1e-10)", || {
        timed(|| simulate(m, sched, t0, t_end, Start::State(x0), &ref_opts))
    });
    let reference = reference.context("reference simulation (rtol 1e-10) failed")?;
    println!(
        "\nAccuracy against rtol 1e-10 (reference run {}, {} steps): max |deviation| / scale over {} samples",
        common::fmt_duration(w),
        reference.stats.steps,
        sol.len()
    );
    let deviation = |s: &Solution, name: &str, scale: f64| {
        let (Some(y), Some(r)) = (s.get(name), reference.get(name)) else {
            return None;
        };
        let (mut worst, mut at) = (0.0f64, t0);
        for i in 0..y.len().min(r.len()) {
            let e = (y[i] - r[i]).abs() / scale;
            if e > worst {
                worst = e;
                at = s.t()[i];
            }
        }
        Some((worst, at))
    };
    for (name, scale) in COMPARE {
        let Some((worst, at)) = deviation(&sol, name, scale) else {
            continue;
        };
        let par = last_par
            .as_ref()
            .and_then(|p| deviation(p, name, scale))
            .map(|(w, _)| format!(", time-parallel {w:.2e}"))
            .unwrap_or_default();
        println!(
            "  {name:<8} {worst:.2e}  (scale {scale:e}, at t = {} s{par})",
            tidy_time(at)
        );
    }
    Ok(())
}

/// `--ensemble N`: N runs of the cycle with [`simulate_many`] on 1 thread and on all cores,
/// alternately `repeat` times; min and median wall times and the speed-up of the minima.
fn ensemble(
    model: &AnyModel,
    n: usize,
    repeat: u32,
    sched: &InputSchedule,
    source: &str,
    opts: &SimOptions,
) -> Result<()> {
    let cores = rayon::current_num_threads();
    println!(
        "mvem bench --ensemble {n}: {n} runs of {source} (each from its steady start), rtol {:e}, \
         output every {} s; 1 thread vs {cores} threads (one per core), {repeat} alternated repeats",
        opts.rtol, opts.dt_out
    );
    let cases: Vec<Case> = (0..n)
        .map(|_| Case {
            model: model.clone(),
            inputs: sched.clone(),
            t_end: None,
            start: None,
        })
        .collect();
    let mut walls = [Vec::new(), Vec::new()];
    for i in 0..repeat {
        for (k, threads) in [1, cores].into_iter().enumerate() {
            let msg = format!("repeat {}/{repeat}, {threads} thread(s)", i + 1);
            let (runs, w) =
                common::with_spinner(&msg, || timed(|| simulate_many(&cases, opts, threads)));
            for r in runs? {
                r.context("ensemble run failed")?;
            }
            walls[k].push(w);
        }
    }
    for w in &mut walls {
        w.sort_by(f64::total_cmp);
    }
    for (w, threads) in walls.iter().zip([1, cores]) {
        println!(
            "  {threads:>2} thread(s)   min {}, median {}  ({} per run)",
            common::fmt_duration(w[0]),
            common::fmt_duration(median(w)),
            common::fmt_duration(w[0] / n as f64)
        );
    }
    println!(
        "  speed-up      {:.2}x (min), {:.2}x (median) on {cores} threads",
        walls[0][0] / walls[1][0],
        median(&walls[0]) / median(&walls[1])
    );
    Ok(())
}

/// A sample time for printing: rounded to 1 ns, so that the sum of output steps prints as the
/// time it stands for (151.2, not 151.20000000000002).
fn tidy_time(t: f64) -> f64 {
    (t * 1e9).round() / 1e9
}

fn median(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}
