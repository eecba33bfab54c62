//! All 90 reference steady states (`tests/reference/steady_states.csv`): states within 1e-6
//! relative, signals within 1e-5 relative (published parameters, authors' semantics,
//! converged cylinder-out temperature).

mod common;
use common::Table;
use mvem::analysis::steady::steady_state;
use mvem::model::{Drive, Engine8};

const STATES: [&str; 8] = [
    "p_im",
    "p_em",
    "X_Oim",
    "X_Oem",
    "omega_t",
    "u_egr1",
    "u_egr2",
    "u_vgt_act",
];
const SIGNALS: [&str; 24] = [
    "W_c",
    "W_egr",
    "W_t",
    "W_ei",
    "W_eo",
    "W_f",
    "T_e",
    "T_em",
    "T_c",
    "x_r",
    "T_1",
    "x_egr",
    "lambda_O",
    "X_Oe",
    "M_e",
    "n_t",
    "eta_c",
    "eta_tm",
    "BSR",
    "Pi_c",
    "Pi_t",
    "P_c",
    "P_t_eta_m",
    "eta_vol",
];

/// Relative error with a floor for values that are zero in the reference (W_egr, x_egr at
/// closed EGR, u_egr at 0 %): the floor is 1e-6 of the column's largest magnitude.
fn rel(got: f64, want: f64, floor: f64) -> f64 {
    (got - want).abs() / want.abs().max(floor)
}

#[test]
fn all_reference_steady_states() {
    let t = Table::read("steady_states.csv");
    let m = Engine8::published();
    let floors = |name: &str| t.column(name).iter().fold(0.0f64, |a, b| a.max(b.abs())) * 1e-6;
    let mut worst: Vec<(f64, String)> = Vec::new();
    let mut valid_mismatch = Vec::new();
    for r in 0..t.rows.len() {
        let d = Drive::new(
            t.f(r, "n_e_rpm"),
            t.f(r, "u_delta_mg"),
            t.f(r, "u_egr_pct"),
            t.f(r, "u_vgt_pct"),
        );
        let ss = steady_state(&m, &d).unwrap_or_else(|e| panic!("row {r}: {e}"));
        for (i, n) in STATES.iter().enumerate() {
            let e = rel(ss.x[i], t.f(r, n), floors(n));
            assert!(
                e < 1e-6,
                "row {r} {d:?}: state {n} = {} expected {} (rel {e:.2e})",
                ss.x[i],
                t.f(r, n)
            );
            worst.push((e, format!("{n} row {r}")));
        }
        for n in SIGNALS {
            let got = ss.signals.get(n).unwrap();
            let e = rel(got, t.f(r, n), floors(n));
            assert!(
                e < 1e-5,
                "row {r} {d:?}: signal {n} = {got} expected {} (rel {e:.2e})",
                t.f(r, n)
            );
            worst.push((e, format!("{n} row {r}")));
        }
        let valid = t.rows[r][t.col("physically_valid")] == "True";
        if valid != ss.physically_valid() {
            valid_mismatch.push(format!("row {r}: reference {valid}, flags {:?}", ss.flags));
        }
        let flags = &t.rows[r][t.col("flags")];
        for f in flags.split(';').filter(|f| !f.is_empty()) {
            assert!(
                ss.flags.iter().any(|g| g == f),
                "row {r}: flag {f} missing in {:?}",
                ss.flags
            );
        }
    }
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    eprintln!("worst relative errors: {:?}", &worst[..5]);
    assert!(valid_mismatch.is_empty(), "{valid_mismatch:#?}");
}

#[test]
fn mass_flows_balance_at_steady_state() {
    let m = Engine8::published();
    for d in [
        Drive::new(1500.0, 110.0, 80.0, 75.0),
        Drive::new(1200.0, 180.0, 40.0, 30.0),
        Drive::new(1900.0, 60.0, 0.0, 50.0),
    ] {
        let s = steady_state(&m, &d).unwrap().signals;
        // eq. (6) at equilibrium: W_c + W_egr = W_ei and W_eo = W_t + W_egr
        assert!(((s.w_c + s.w_egr) / s.w_ei - 1.0).abs() < 1e-9, "{d:?}");
        assert!(((s.w_t + s.w_egr) / s.w_eo - 1.0).abs() < 1e-9, "{d:?}");
        // eq. (14)
        assert!((s.w_eo - s.w_ei - s.w_f).abs() < 1e-15);
    }
}
