//! How fast the WHTC forgets a time-parallel chunk's start (`SimOptions::time_chunks`,
//! `docs/integrator.md`): the sequential run, then runs from a guess at start times every
//! `--every` seconds (default 25), each compared with the sequential run at the common output
//! samples in tolerance units (max over the states of |dy_i| / (atol_i + rtol |y_i|)). Prints,
//! per start, the time after which the difference stays below 1 and 0.1 units, for the steady
//! state at the inputs there as the guess and for the cycle's initial state; then the slowest
//! pole of the steady states along the cycle (every second).
//!
//! `cargo run --release -p mvem --example chunk_decay [-- --model 8|10|12 --every S --span S]`
use mvem::analysis::steady::{chunk_guess, steady_state, steady_state_with, SteadyOptions};
use mvem::model::{Engine10, Engine12, Engine8, Model};
use mvem::sim::{simulate, SimOptions, Solution, Start};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let every: f64 = arg("--every").map_or(25.0, |v| v.parse().expect("--every"));
    let span: f64 = arg("--span").map_or(40.0, |v| v.parse().expect("--span"));
    let trace: Option<f64> = arg("--trace").map(|v| v.parse().expect("--trace"));
    match arg("--model").as_deref() {
        None | Some("8") => run(&Engine8::published(), every, span, trace),
        Some("10") => run(&Engine10::published(), every, span, trace),
        Some("12") => run(&Engine12::published(), every, span, trace),
        Some(other) => panic!("--model {other}: 8, 10 or 12"),
    }
}

fn states<const N: usize>(s: &Solution, names: &[&str; N], i: usize) -> [f64; N] {
    std::array::from_fn(|k| s.get(names[k]).unwrap()[i])
}

fn run<const N: usize, M: Model<N>>(m: &M, every: f64, span: f64, trace: Option<f64>) {
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    let sched = mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap();
    let opts = SimOptions {
        dt_out: 0.1,
        ..SimOptions::default()
    };
    let names = m.state_names();
    let scales = m.state_scales();
    let x0 = steady_state(m, &sched.at(0.0)).unwrap().x;
    let seq = simulate(m, &sched, 0.0, 1800.0, Start::State(x0), &opts).unwrap();
    let guess = chunk_guess(m, &sched);
    let units = |a: &[f64; N], b: &[f64; N]| {
        (0..N)
            .map(|i| {
                (a[i] - b[i]).abs()
                    / (opts.atol * scales[i] + opts.rtol * a[i].abs().max(b[i].abs()))
            })
            .fold(0.0, f64::max)
    };
    println!("start [s]  guess    units at start  below 1 after [s]  below 0.1 after [s]");
    let (mut worst1, mut worst01) = ([0.0f64; 2], [0.0f64; 2]);
    let mut s0 = trace.unwrap_or(every);
    while s0 + span <= 1800.0 {
        for (g, name) in [(guess(s0), "steady"), (Some(x0), "initial")]
            .into_iter()
            .enumerate()
            .map(|(k, (x, n))| ((k, x), n))
        {
            let (k, Some(xg)) = g else {
                let why = steady_state_with(
                    m,
                    &sched.at(s0),
                    None,
                    &SteadyOptions {
                        settle: false,
                        ..SteadyOptions::default()
                    },
                )
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default();
                println!("{s0:9.1}  {name:<7}  no guess: {why}");
                continue;
            };
            let r = simulate(m, &sched, s0, s0 + span, Start::State(xg), &opts).unwrap();
            let off = (s0 / 0.1).round() as usize;
            // the last 2 s left out: the run ends at a time that is no stop time of the
            // sequential run, so its last steps differ from the sequential ones (a split is a
            // stop time of both)
            let d: Vec<f64> = (0..r.len().saturating_sub(21))
                .map(|i| units(&states(&r, &names, i), &states(&seq, &names, off + i)))
                .collect();
            // the time after which the difference stays below the level
            let settle = |lvl: f64| {
                d.iter()
                    .rposition(|v| *v >= lvl)
                    .map_or(0.0, |i| (i + 1) as f64 * 0.1)
            };
            let (a, b) = (settle(1.0), settle(0.1));
            if trace.is_some() {
                for (i, v) in d.iter().enumerate().step_by(10) {
                    let worst = (0..N)
                        .map(|k| {
                            let (x, y) =
                                (states(&r, &names, i)[k], states(&seq, &names, off + i)[k]);
                            (
                                (x - y).abs()
                                    / (opts.atol * scales[k] + opts.rtol * x.abs().max(y.abs())),
                                k,
                            )
                        })
                        .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a });
                    println!(
                        "  {name} t = {:.1}: {v:.3e} ({})",
                        s0 + i as f64 * 0.1,
                        names[worst.1]
                    );
                }
            }
            worst1[k] = worst1[k].max(a);
            worst01[k] = worst01[k].max(b);
            println!("{s0:9.1}  {name:<7}  {:14.3e}  {a:17.1}  {b:19.1}", d[0]);
        }
        s0 += every;
        if trace.is_some() {
            return;
        }
    }
    println!(
        "longest: steady guess {} s (1 unit), {} s (0.1); initial state {} s, {} s (span {span} s: \
         {span} means not reached)",
        worst1[0], worst01[0], worst1[1], worst01[1]
    );
    let mut slow = (0.0f64, 0.0f64, f64::NEG_INFINITY);
    for k in 0..1800 {
        let t = k as f64;
        if let Ok(ss) = steady_state(m, &sched.at(t)) {
            if let Some(&(re, _)) = ss.eigenvalues.first() {
                if re > slow.2 {
                    slow = (t, -1.0 / re, re);
                }
            }
        }
    }
    println!(
        "slowest pole of the steady states along the cycle: {:.3} 1/s at t = {} s (time constant {:.2} s)",
        slow.2, slow.0, slow.1
    );
}
