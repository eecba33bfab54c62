//! Where the integration's work lies along a drive cycle: for every 10 s interval, the RHS
//! evaluations of the sequential run (the runs up to t = 10, 20, ... s, differenced), the inputs'
//! normalized total variation and the number of stop times; CSV on stdout. The data behind the
//! time-parallel work estimate (`docs/integrator.md`, session 26):
//! `cargo run --release -p mvem --example work_profile -- data/whtc_inputs_10hz.csv`.
use mvem::analysis::steady::simulate_from_steady;
use mvem::model::Engine8;
use mvem::sim::{stop_times, SimOptions};

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: work_profile INPUTS.csv");
    let text = std::fs::read_to_string(&path).expect("read the inputs");
    let sched = mvem::io::csv_inputs::parse_inputs_csv(&text, std::path::Path::new(&path))
        .unwrap_or_else(|e| panic!("{e}"));
    let m = Engine8::published();
    let t_end = *sched.times().last().unwrap();
    let opts = SimOptions {
        dt_out: 0.1,
        ..SimOptions::default()
    };
    let stops = stop_times(&m, &sched, 0.0, t_end);
    let (times, rows) = (sched.times(), sched.rows());
    let range: [f64; 4] = std::array::from_fn(|c| {
        let lo = rows.iter().map(|r| r[c]).fold(f64::INFINITY, f64::min);
        let hi = rows.iter().map(|r| r[c]).fold(f64::NEG_INFINITY, f64::max);
        hi - lo
    });
    let variation = |i: usize| -> f64 {
        (0..4)
            .filter(|&c| range[c] > 0.0)
            .map(|c| (rows[i][c] - rows[i - 1][c]).abs() / range[c])
            .sum()
    };
    let dt = 10.0;
    let mut before = 0;
    println!("t0,t1,evals,tv,stops");
    let mut k = 1;
    while k as f64 * dt <= t_end + 1e-9 {
        let (a, b) = ((k - 1) as f64 * dt, k as f64 * dt);
        let s = simulate_from_steady(&m, &sched, 0.0, b, &opts).unwrap_or_else(|e| panic!("{e}"));
        let tv: f64 = (1..rows.len())
            .filter(|&i| times[i] > a && times[i] <= b)
            .map(variation)
            .sum();
        let n = stops.iter().filter(|s| s.0 > a && s.0 <= b).count();
        println!("{a},{b},{},{tv},{n}", s.stats.rhs_evals - before);
        before = s.stats.rhs_evals;
        k += 1;
    }
}
