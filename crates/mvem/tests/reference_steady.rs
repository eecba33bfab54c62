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

/// `Model::derivatives` (the integrator's path, which skips the signal-only work) gives
/// bitwise the `dx` and `memory_next` of `Model::eval`, for the 8-, 10- and 12-state models: at
/// the 90 reference states and, for each, 20 perturbed states (up to +-30 % per state, some
/// outside the integrator limits), with every option combination.
#[test]
fn derivatives_path_equals_eval() {
    use mvem::components::cylinder::SeligerIterate;
    use mvem::components::Semantics;
    use mvem::model::{
        Actuators, CylinderTemp, Engine10, Engine12, Model, ModelInput, ModelOptions,
    };
    fn check<const N: usize, M: Model<N, Memory = SeligerIterate>>(
        m: &M,
        x: &[f64; N],
        u: &ModelInput,
        mem: SeligerIterate,
    ) {
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        let ev = m.eval(x, u, mem);
        let dv = m.derivatives(x, u, mem);
        for i in 0..N {
            assert!(
                same(ev.dx[i], dv.dx[i]),
                "{N} states, {:?}, x = {x:?}: state {i}: {} vs {}",
                m.options(),
                ev.dx[i],
                dv.dx[i]
            );
        }
        assert!(same(ev.memory_next.x_r, dv.memory_next.x_r));
        assert!(same(ev.memory_next.t_1, dv.memory_next.t_1));
        // the channels the model declares unused (InputDelays::current false) do not change
        // the derivatives: the simulator passes NaN for them (SegmentInputs::at_derivatives)
        let current = m.input_delays().current;
        let mut arr = u.to_array();
        for c in 0..4 {
            if !current[c] {
                arr[c] = f64::NAN;
            }
        }
        let dn = m.derivatives(x, &ModelInput::from_array(arr), mem);
        for i in 0..N {
            assert!(
                same(dn.dx[i], dv.dx[i]),
                "{N} states, {:?}, unused inputs NaN: state {i}: {} vs {}",
                m.options(),
                dn.dx[i],
                dv.dx[i]
            );
        }
        assert!(same(dn.memory_next.x_r, dv.memory_next.x_r));
        assert!(same(dn.memory_next.t_1, dv.memory_next.t_1));
    }
    let t = Table::read("steady_states.csv");
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = move || {
        // xorshift64*: a reproducible sequence in [-1, 1)
        seed ^= seed >> 12;
        seed ^= seed << 25;
        seed ^= seed >> 27;
        (seed.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    };
    let mut checked = 0;
    for semantics in [Semantics::Authors, Semantics::Paper] {
        for cylinder_temp in [CylinderTemp::Converged, CylinderTemp::OneIteration] {
            for actuators in [Actuators::Dynamic, Actuators::Bypass] {
                let opts = ModelOptions {
                    semantics,
                    cylinder_temp,
                    actuators,
                };
                let m8 = Engine8::published().with_options(opts);
                let m10 = Engine10::published().with_options(opts);
                let m12 = Engine12::published().with_options(opts);
                for r in 0..t.rows.len() {
                    let d = Drive::new(
                        t.f(r, "n_e_rpm"),
                        t.f(r, "u_delta_mg"),
                        t.f(r, "u_egr_pct"),
                        t.f(r, "u_vgt_pct"),
                    );
                    let x0: [f64; 8] = std::array::from_fn(|i| t.f(r, STATES[i]));
                    for k in 0..21 {
                        let mut v = |scale: f64| if k == 0 { 1.0 } else { 1.0 + scale * uniform() };
                        let x8: [f64; 8] = std::array::from_fn(|i| x0[i] * v(0.3));
                        let x10 =
                            Engine10::from_8_state(&x8, 300.0 * v(0.1), t.f(r, "T_em") * v(0.1));
                        let x12 = Engine12::from_10_state(&x10, x8[0] * v(0.05), 320.0 * v(0.1));
                        let mut u = ModelInput::constant(d);
                        u.u_egr_delayed += 20.0 * uniform();
                        u.u_vgt_delayed += 20.0 * uniform();
                        let mem = SeligerIterate {
                            x_r: 0.03 + 0.02 * uniform(),
                            t_1: 330.0 + 30.0 * uniform(),
                        };
                        check(&m8, &x8, &u, mem);
                        check(&m10, &x10, &u, mem);
                        check(&m12, &x12, &u, mem);
                        checked += 1;
                    }
                }
            }
        }
    }
    assert_eq!(checked, 8 * 90 * 21);
}
