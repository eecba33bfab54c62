//! The authors' two demonstration steps (`tests/reference/step_vgt_*.csv`): n_e 1500 rpm,
//! u_delta 110 mg, u_egr 80 %, u_vgt step at t = 1 s, from the steady state, to t = 8 s.
//! Every 10 ms sample of p_im, p_em, W_c, n_t must lie within 1e-3 of that signal's range over
//! the run (the acceptance bound); we also assert the much tighter 1e-6 of range
//! actually achieved at rtol 1e-9, so a regression in accuracy is visible.

mod common;
use common::Table;
use mvem::analysis::steady::simulate_from_steady;
use mvem::model::{Drive, Engine8};
use mvem::sim::{InputSchedule, SimOptions};

fn run(file: &str, from: f64, to: f64, rtol: f64) -> (Table, mvem::sim::Solution) {
    let t = Table::read(file);
    let m = Engine8::published();
    let sched =
        InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, from), &[(1.0, 3, to)]).unwrap();
    let opts = SimOptions {
        rtol,
        atol: rtol * 1e-2,
        dt_out: 0.01,
        ..SimOptions::default()
    };
    let sol = simulate_from_steady(&m, &sched, 0.0, 8.0, &opts).unwrap();
    (t, sol)
}

fn worst_range_error(t: &Table, sol: &mvem::sim::Solution, name: &str) -> (f64, f64) {
    let want = t.column(name);
    let got = sol.get(name).unwrap();
    assert_eq!(want.len(), got.len(), "sample count for {name}");
    let tt = t.column("t");
    for (a, b) in tt.iter().zip(sol.t()) {
        assert!((a - b).abs() < 1e-9, "time grid {a} vs {b}");
    }
    let lo = want.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = want.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let range = hi - lo;
    let mut worst = (0.0, 0.0);
    for i in 0..want.len() {
        let e = (got[i] - want[i]).abs() / range;
        if e > worst.0 {
            worst = (e, tt[i]);
        }
    }
    worst
}

fn check(file: &str, from: f64, to: f64) {
    for rtol in [1e-9, 1e-6] {
        let (t, sol) = run(file, from, to, rtol);
        for name in [
            "p_im", "p_em", "W_c", "n_t", "X_Oim", "X_Oem", "W_egr", "lambda_O", "T_em",
        ] {
            let (e, at) = worst_range_error(&t, &sol, name);
            eprintln!("{file} rtol {rtol:e}: {name} worst {e:.2e} of range at t = {at}");
            assert!(
                e < 1e-3,
                "{file}: {name} off by {e:.2e} of its range at t = {at}"
            );
            if rtol == 1e-9 {
                assert!(
                    e < 1e-6,
                    "{file}: {name} off by {e:.2e} of its range at t = {at} (rtol 1e-9)"
                );
            }
        }
    }
}

#[test]
fn vgt_step_75_to_65_matches_reference() {
    check("step_vgt_75_to_65.csv", 75.0, 65.0);
}

#[test]
fn vgt_step_30_to_25_matches_reference() {
    check("step_vgt_30_to_25.csv", 30.0, 25.0);
}
