//! One WHTC run with the default options and 0.1 s output, for instruction counting:
//! `valgrind --tool=callgrind target/release/examples/whtc_once`.
//!
//! With `--check REF.csv` it also prints the largest scaled deviation (p_im, p_em by 1e5 Pa,
//! X_Oim, X_Oem by 0.1, omega_t by 1e4 rad/s) from a rtol 1e-10 run, computed once and cached
//! in REF.csv (every state integrated numerically, so the closed-form actuator states are checked
//! too). `--rtol R` and `--atol A` (x the state scales) set the tolerances of the measured run (default
//! 1e-6 both, the library's defaults), `--method ros34pw2|rodas4|exprb32|dopri5`
//! its method (default: the library default); `--lags-across` runs it with
//! `SimOptions::stop_at_lag_breakpoints` off (the reference is the same), `--no-ft` with
//! `SimOptions::rosw_time_derivative` off. `--dump OUT.csv`
//! writes the compared columns of the measured run (t and the five states).
//!
//! `--time-parallel K` runs it in K time chunks (`SimOptions::time_chunks`, one thread each),
//! `--overlap W` sets their warm-up \[s\], `--guess initial` starts the warm-ups from the initial
//! state instead of the steady state at their inputs; the junctions are printed.
//! `--model 10|12` runs the 10- or 12-state model (give each model its own REF file).
//! `--inputs FILE.csv` runs another input file (0..1800 s) instead of the built-in WHTC (give it
//! its own REF file).
use mvem::analysis::steady::{simulate_from_steady, steady_state};
use mvem::model::{Engine10, Engine12, Engine8, Model};
use mvem::sim::{simulate_with_guess, Method, SimOptions, Solution, Start};

const COMPARE: [(&str, f64); 5] = [
    ("p_im", 1e5),
    ("p_em", 1e5),
    ("X_Oim", 0.1),
    ("X_Oem", 0.1),
    ("omega_t", 1e4),
];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1).cloned())
    };
    match arg("--model").as_deref() {
        None | Some("8") => run(&Engine8::published(), &args),
        Some("10") => run(&Engine10::published(), &args),
        Some("12") => run(&Engine12::published(), &args),
        Some(other) => panic!("--model {other}: 8, 10 or 12"),
    }
}

fn run<const N: usize, M: Model<N>>(m: &M, args: &[String]) {
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let text = match arg("--inputs") {
        Some(path) => std::fs::read_to_string(&path).expect("--inputs"),
        None => include_str!("../../../data/whtc_inputs_10hz.csv").to_string(),
    };
    let sched =
        mvem::io::csv_inputs::parse_inputs_csv(&text, std::path::Path::new("whtc")).unwrap();
    let opts = SimOptions {
        dt_out: 0.1,
        rtol: arg("--rtol").map_or(1e-6, |r| r.parse().expect("--rtol")),
        atol: arg("--atol").map_or(1e-6, |r| r.parse().expect("--atol")),
        method: match arg("--method").as_deref() {
            None => Method::default(),
            Some("ros34pw2") => Method::Rosenbrock34,
            Some("rodas4") => Method::Rodas4,
            Some("dopri5") => Method::Dopri5,
            Some("exprb32") => Method::Exprb32,
            Some(other) => panic!("--method {other}: ros34pw2, rodas4, exprb32 or dopri5"),
        },
        stop_at_lag_breakpoints: !args.iter().any(|a| a == "--lags-across"),
        rosw_time_derivative: !args.iter().any(|a| a == "--no-ft"),
        time_chunks: arg("--time-parallel").map_or(1, |k| k.parse().expect("--time-parallel")),
        chunk_overlap: arg("--overlap").map_or(30.0, |w| w.parse().expect("--overlap")),
        ..SimOptions::default()
    };
    let t = std::time::Instant::now();
    let s = if arg("--guess").as_deref() == Some("initial") {
        let x0 = steady_state(m, &sched.at(0.0)).unwrap().x;
        simulate_with_guess(m, &sched, 0.0, 1800.0, Start::State(x0), &opts, None).unwrap()
    } else {
        simulate_from_steady(m, &sched, 0.0, 1800.0, &opts).unwrap()
    };
    println!("{:?} {:?}", t.elapsed(), s.stats);
    for j in &s.junctions {
        println!(
            "junction t = {} s: diff {:.3e} tolerance units, {}",
            j.t,
            j.diff,
            if j.accepted { "accepted" } else { "re-run" }
        );
    }
    if let Some(path) = arg("--check") {
        let reference: Vec<Vec<f64>> = match std::fs::read_to_string(&path) {
            Ok(txt) => txt
                .lines()
                .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
                .collect(),
            Err(_) => {
                // every state integrated numerically: independent of the closed-form lags
                let ro = SimOptions {
                    rtol: 1e-10,
                    atol: 1e-12,
                    exact_actuators: false,
                    ..opts.clone()
                };
                let r = simulate_from_steady(m, &sched, 0.0, 1800.0, &ro).unwrap();
                let cols = columns(&r);
                let txt: Vec<String> = cols
                    .iter()
                    .map(|c| {
                        c.iter()
                            .map(|v| format!("{v:e}"))
                            .collect::<Vec<_>>()
                            .join(",")
                    })
                    .collect();
                std::fs::write(&path, txt.join("\n")).unwrap();
                cols
            }
        };
        let mine = columns(&s);
        if let Some(dump) = arg("--dump") {
            // the compared columns of this run, one line per sample (t, p_im, ..., omega_t)
            let txt: String = (0..mine[0].len())
                .map(|i| {
                    let row: Vec<String> = mine.iter().map(|c| format!("{:e}", c[i])).collect();
                    format!("{:.1},{}\n", i as f64 * opts.dt_out, row.join(","))
                })
                .collect();
            std::fs::write(dump, txt).unwrap();
        }
        let mut worst = 0.0f64;
        for (k, (name, scale)) in COMPARE.iter().enumerate() {
            let (d, at) = mine[k]
                .iter()
                .zip(&reference[k])
                .map(|(a, b)| (a - b).abs() / scale)
                .enumerate()
                .fold((0.0, 0), |m, (i, d)| if d > m.0 { (d, i) } else { m });
            print!("{name} {d:.2e} (t = {:.1} s)  ", at as f64 * opts.dt_out);
            worst = worst.max(d);
        }
        println!("\nmax dev {worst:.2e}");
    }
}

fn columns(s: &Solution) -> Vec<Vec<f64>> {
    COMPARE
        .iter()
        .map(|(n, _)| s.get(n).unwrap().to_vec())
        .collect()
}
