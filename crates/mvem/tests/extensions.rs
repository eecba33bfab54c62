//! The section-9 model extensions (10 and 12 states) against the 8-state model:
//! equal steady states (10 vs 8), the 12 -> 10 reduction as k_ic, V_ic -> 0, mass and energy
//! bookkeeping of the adiabatic volumes, the VGT steps of Figs 11-14 in all three models, and
//! the cylinder-out temperature study of section 4.2.3 (Fig. 2).

// Index loops over fixed-size state arrays compare the models state by state.
#![allow(clippy::needless_range_loop)]

use mvem::analysis::extensions::{
    compare_vgt_steps, cylinder_temp_study, sign_reversal, CompareOptions, CylinderTempOptions,
    VgtStep,
};
use mvem::analysis::steady::{
    simulate_from_steady, steady_state, steady_state_with, SteadyOptions,
};
use mvem::components::cylinder::SeligerIterate;
use mvem::components::{intercooler, Semantics};
use mvem::dispatch;
use mvem::model::{
    ix10, ix12, AnyModel, Drive, Engine10, Engine12, Engine8, Model, ModelInput, ModelOptions,
    ModelOrder, Signals,
};
use mvem::params::Params;
use mvem::sim::{InputSchedule, SimOptions};

/// |a - b| <= rtol max(|a|, |b|) (+ a floor for values that are exactly zero in one model).
fn close(a: f64, b: f64, rtol: f64) -> bool {
    (a - b).abs() <= rtol * a.abs().max(b.abs()) + 1e-300
}

/// Operating points across the range: 3 speeds x 3 fuel x 2 EGR x 2 VGT = 36.
fn grid() -> Vec<Drive> {
    let mut v = Vec::new();
    for n_e in [1000.0, 1500.0, 1900.0] {
        for u_delta in [40.0, 120.0, 220.0] {
            for u_egr in [0.0, 60.0] {
                for u_vgt in [35.0, 80.0] {
                    v.push(Drive::new(n_e, u_delta, u_egr, u_vgt));
                }
            }
        }
    }
    v
}

#[test]
fn ten_state_steady_states_equal_eight_state() {
    let m8 = Engine8::published();
    let m10 = Engine10::published();
    let t_im_in = m8.params().intake_manifold.t_im;
    let points = grid();
    assert!(points.len() >= 20);
    let mut worst = (0.0f64, String::new());
    for d in &points {
        let a = steady_state(&m8, d).unwrap();
        // from the model's own heuristic guess, not the 8-state seed of `steady_state`, so that
        // the equality is found independently of the 8-state solution
        let g = m10.initial_guess(d);
        let b = steady_state_with(&m10, d, Some(&g), &SteadyOptions::default()).unwrap();
        // at equilibrium the manifold temperatures equal their inflow temperatures
        assert!(close(b.x[ix10::T_IM], t_im_in, 1e-8), "T_im at {d:?}");
        assert!(
            close(b.x[ix10::T_EM], a.signals.t_em, 1e-8),
            "T_em at {d:?}"
        );
        let x8 = Engine10::to_8_state(&b.x);
        for (i, name) in m8.state_names().iter().enumerate() {
            let e = (x8[i] - a.x[i]).abs() / a.x[i].abs().max(1e-300);
            if e > worst.0 {
                worst = (e, format!("state {name} at {d:?}"));
            }
            assert!(
                close(x8[i], a.x[i], 1e-8),
                "{name} at {d:?}: {} vs {}",
                x8[i],
                a.x[i]
            );
        }
        for (k, name) in Signals::NAMES.iter().enumerate() {
            let (va, vb) = (a.signals.values()[k], b.signals.values()[k]);
            if va != 0.0 {
                let e = (va - vb).abs() / va.abs();
                if e > worst.0 {
                    worst = (e, format!("signal {name} at {d:?}"));
                }
            }
            assert!(close(va, vb, 1e-8), "{name} at {d:?}: {va} vs {vb}");
        }
        assert_eq!(a.flags, b.flags, "flags at {d:?}");
        assert_eq!(a.physically_valid(), b.physically_valid());
        // both equilibria are stable; the 10-state one has two more (temperature) eigenvalues
        assert_eq!(b.eigenvalues.len(), a.eigenvalues.len() + 2);
    }
    eprintln!(
        "10 vs 8 steady states at {} points: worst relative difference {:.2e} ({})",
        points.len(),
        worst.0,
        worst.1
    );
}

#[test]
fn extension_steady_states_need_no_settling_fallback() {
    // Seeded with the 8-state equilibrium (T_im = the cooled charge temperature, T_em of the
    // 8-state solution, p_c and T_ic from its compressor outlet), Newton alone converges for
    // the 10- and 12-state models; from the heuristic guess it often needs the settling
    // simulation.
    let m10 = Engine10::published();
    let m12 = Engine12::published();
    let points = grid();
    let (mut direct10, mut direct12, mut heuristic10) = (0, 0, 0);
    for d in &points {
        let a = steady_state(&m10, d).unwrap();
        let b = steady_state(&m12, d).unwrap();
        direct10 += usize::from(!a.settled);
        direct12 += usize::from(!b.settled);
        assert!(!a.settled && !b.settled, "settling needed at {d:?}");
        // few iterations: the 10-state seed is the equilibrium, the 12-state one is off by the
        // intercooler pressure drop only
        assert!(a.iterations <= 2, "{} iterations at {d:?}", a.iterations);
        assert!(b.iterations <= 15, "{} iterations at {d:?}", b.iterations);
        let g = m10.initial_guess(d);
        let h = steady_state_with(&m10, d, Some(&g), &SteadyOptions::default()).unwrap();
        heuristic10 += usize::from(!h.settled);
        assert!(close(h.x[ix10::P_IM], a.x[ix10::P_IM], 1e-8));
    }
    eprintln!(
        "Newton without settling at {} points: 10 states {direct10} (heuristic guess: {heuristic10}), 12 states {direct12}",
        points.len()
    );
    assert!(direct10 >= 20 && direct12 >= 20);
}

#[test]
fn ten_state_newton_converges_from_a_perturbed_start() {
    // The equality above is not an artefact of the start: from a start 5 % off in pressures
    // and turbo speed and 30/80 K off in the temperatures, Newton alone reaches the same point.
    let m8 = Engine8::published();
    let m10 = Engine10::published();
    let opts = SteadyOptions {
        settle: false,
        ..SteadyOptions::default()
    };
    for d in [
        Drive::new(1200.0, 50.0, 40.0, 30.0),
        Drive::new(1500.0, 110.0, 80.0, 75.0),
        Drive::new(1900.0, 200.0, 0.0, 50.0),
    ] {
        let a = steady_state(&m8, &d).unwrap();
        let mut g = Engine10::from_8_state(&a.x, 330.0, a.signals.t_em - 80.0);
        for i in [ix10::P_IM, ix10::P_EM, ix10::OMEGA_T] {
            g[i] *= 1.05;
        }
        let b = steady_state_with(&m10, &d, Some(&g), &opts).unwrap();
        assert!(!b.settled);
        let x8 = Engine10::to_8_state(&b.x);
        for i in 0..8 {
            assert!(close(x8[i], a.x[i], 1e-8), "state {i} at {d:?}");
        }
    }
}

#[test]
fn initial_guesses_and_actuator_states_are_sensible() {
    let m10 = Engine10::published();
    let m12 = Engine12::published();
    let p = Params::published();
    let u = |d: Drive| ModelInput::constant(d);
    let mem = SeligerIterate {
        x_r: 0.0,
        t_1: p.intake_manifold.t_im,
    };
    for d in grid() {
        // actuator states = saturated commands, at the right indices
        let a10 = m10.actuator_state_values(&d);
        let want10 = [
            (ix10::U_EGR1, d.u_egr_pct),
            (ix10::U_EGR2, d.u_egr_pct),
            (ix10::U_VGT, d.u_vgt_pct),
        ];
        assert_eq!(a10, want10);
        let a12 = m12.actuator_state_values(&d);
        let want12 = [
            (ix12::U_EGR1, d.u_egr_pct),
            (ix12::U_EGR2, d.u_egr_pct),
            (ix12::U_VGT, d.u_vgt_pct),
        ];
        assert_eq!(a12, want12);

        let g = m10.initial_guess(&d);
        let b = m10.state_bounds();
        for (i, v) in g.iter().enumerate() {
            assert!(
                v.is_finite() && *v >= b[i].0 && *v <= b[i].1,
                "guess {i}: {v}"
            );
        }
        for (i, v) in &a10 {
            assert_eq!(g[*i], *v);
        }
        assert_eq!(g[ix10::T_IM], p.intake_manifold.t_im);
        let ev = m10.eval(&g, &u(d), mem);
        assert_eq!(g[ix10::T_EM], ev.signals.t_em_in);
        assert!(g[ix10::T_EM] > p.ambient.t_amb && g[ix10::T_EM] < 1500.0);

        let g12 = m12.initial_guess(&d);
        let b12 = m12.state_bounds();
        for (i, v) in g12.iter().enumerate() {
            assert!(
                v.is_finite() && *v >= b12[i].0 && *v <= b12[i].1,
                "guess {i}: {v}"
            );
        }
        assert_eq!(Engine12::to_10_state(&g12)[..2], g[..2]);
        assert!(g12[ix12::P_C] > g12[ix12::P_IM]);
        assert!(g12[ix12::T_IC] >= p.ambient.t_amb);
    }
}

#[test]
fn solution_columns_are_unique_and_states_win() {
    // T_im, T_em and p_c are states of the extensions and signals of every model: each column
    // name appears once (the state); the 8-state model keeps them as signals.
    let sched =
        InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(0.05, 3, 65.0)]).unwrap();
    let opts = SimOptions {
        dt_out: 0.05,
        ..SimOptions::default()
    };
    for order in [ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve] {
        let any = AnyModel::new(order, Params::published(), ModelOptions::default()).unwrap();
        let sol = dispatch!(&any, m => simulate_from_steady(m, &sched, 0.0, 0.2, &opts)).unwrap();
        let mut seen = std::collections::HashSet::new();
        for n in &sol.names {
            assert!(seen.insert(n.as_str()), "{order:?}: column {n} twice");
        }
        let n_states = dispatch!(&any, m => m.state_names().len());
        let shared = match order {
            ModelOrder::Eight => 0,
            ModelOrder::Ten => 2,    // T_im, T_em
            ModelOrder::Twelve => 3, // T_im, T_em, p_c
        };
        assert_eq!(sol.names.len(), 1 + n_states + Signals::COUNT - shared);
        let col = |n: &str| sol.get(n).unwrap();
        let last = sol.len() - 1;
        // the signal columns after a dropped one are aligned: W_ic = W_c (eq. (82)) in the 8-
        // and 10-state models; T_em_in = T_em in the 8-state one; p_c = p_im unless 12 states
        match order {
            ModelOrder::Twelve => {
                assert!(col("p_c")[last] > col("p_im")[last]);
                assert!(close(col("W_ic")[last], col("W_c")[last], 0.05));
            }
            _ => {
                assert_eq!(col("W_ic"), col("W_c"));
                assert_eq!(col("p_c"), col("p_im"));
            }
        }
        if order == ModelOrder::Eight {
            assert_eq!(col("T_em_in"), col("T_em"));
        } else {
            assert!(close(col("T_em_in")[0], col("T_em")[0], 1e-6));
        }
        let csv = mvem::io::output::solution_csv(&sol);
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        assert_eq!(header, sol.names);
    }
}

#[test]
fn any_model_builds_and_dispatches_all_orders() {
    for (order, n) in [
        (ModelOrder::Eight, 8),
        (ModelOrder::Ten, 10),
        (ModelOrder::Twelve, 12),
    ] {
        let any = AnyModel::new(order, Params::published(), ModelOptions::default()).unwrap();
        assert_eq!(any.order(), order);
        assert_eq!(dispatch!(&any, m => m.state_names().len()), n);
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let w_c = dispatch!(&any, m => steady_state(m, &d).unwrap().signals.w_c);
        assert!(w_c > 0.2 && w_c < 0.26, "{order:?}: W_c = {w_c}");
    }
    let mut p = Params::published();
    p.intercooler.k_ic = 0.0;
    assert!(AnyModel::new(ModelOrder::Twelve, p.clone(), ModelOptions::default()).is_err());
    assert!(AnyModel::new(ModelOrder::Ten, p, ModelOptions::default()).is_ok());
}

fn engine12_scaled(k_scale: f64, v_scale: f64) -> Engine12 {
    let mut p = Params::published();
    p.intercooler.k_ic *= k_scale;
    p.intercooler.v_ic *= v_scale;
    Engine12::new(p, ModelOptions::default()).unwrap()
}

/// Max relative difference of the 10 shared states and of W_c between a 12- and 10-state
/// steady state.
fn diff_12_10(
    a: &mvem::analysis::steady::SteadyState<12>,
    b: &mvem::analysis::steady::SteadyState<10>,
) -> f64 {
    let x = Engine12::to_10_state(&a.x);
    let mut e = (a.signals.w_c - b.signals.w_c).abs() / b.signals.w_c;
    for i in 0..10 {
        e = e.max((x[i] - b.x[i]).abs() / b.x[i].abs().max(1e-300));
    }
    e
}

#[test]
fn twelve_state_steady_states_reduce_to_ten_state_as_k_ic_vanishes() {
    // k_ic scaled by 1, 1/4, 1/16: the stationary difference is first order in the pressure
    // drop. Much smaller k_ic is out of reach of the steady-state solver, not of the model:
    // p_c then has a time constant ~ V_ic k_ic (1.5 ms at the default, ~1.5 us at 1e-3 x),
    // which makes the finite-difference Newton Jacobian ill-conditioned (it stalls at 1/100 x
    // k_ic at some points) and the settling simulation stiff. So Newton alone is started from
    // the 10-state equilibrium with p_c, T_ic from eq. (86) and T_c there.
    let m10 = Engine10::published();
    let p = Params::published();
    let scales = [1.0, 0.25, 0.0625];
    let ms: Vec<Engine12> = scales.iter().map(|s| engine12_scaled(*s, 1.0)).collect();
    let newton = SteadyOptions {
        settle: false,
        ..SteadyOptions::default()
    };
    for d in [
        Drive::new(1200.0, 50.0, 40.0, 30.0),
        Drive::new(1500.0, 110.0, 80.0, 75.0),
        Drive::new(1500.0, 110.0, 80.0, 30.0),
        Drive::new(1900.0, 220.0, 0.0, 50.0),
    ] {
        let b = steady_state(&m10, &d).unwrap();
        let diffs: Vec<f64> = ms
            .iter()
            .map(|m| {
                let s = &b.signals;
                let p_im = b.x[ix10::P_IM];
                let dp = intercooler::pressure_drop(&m.params().intercooler, s.w_c, s.t_c, p_im);
                let guess = Engine12::from_10_state(&b.x, p_im + dp, s.t_c);
                let a = steady_state_with(m, &d, Some(&guess), &newton).unwrap();
                // at equilibrium: T_ic = T_c, W_ic = W_c and eq. (86) carries W_c
                let s = &a.signals;
                assert!(close(a.x[ix12::T_IC], s.t_c, 1e-9));
                assert!(close(s.w_ic, s.w_c, 1e-9));
                let dp = intercooler::pressure_drop(
                    &m.params().intercooler,
                    s.w_c,
                    s.t_c,
                    a.x[ix12::P_IM],
                );
                assert!(close(a.x[ix12::P_C] - a.x[ix12::P_IM], dp, 1e-4));
                assert!(close(a.x[ix12::T_IM], p.intake_manifold.t_im, 1e-9));
                diff_12_10(&a, &b)
            })
            .collect();
        let shown: Vec<String> = diffs.iter().map(|v| format!("{v:.3e}")).collect();
        eprintln!("12 vs 10 at {d:?}: max relative difference for k_ic x {scales:?}: {shown:?}");
        // the default pressure drop moves the steady state by percents ...
        assert!(diffs[0] > 1e-3 && diffs[0] < 0.2, "{diffs:?}");
        // ... and the difference shrinks in proportion to k_ic (first order in the pressure drop)
        for w in diffs.windows(2) {
            let ratio = w[1] / w[0];
            assert!(ratio > 0.22 && ratio < 0.28, "ratio {ratio:e} ({diffs:?})");
        }
    }
    // Further down, without the solver: the 10-state equilibrium lifted into the 12-state
    // space (p_c = p_im + drop of eq. (86), T_ic = T_c) is an equilibrium of the 12-state model
    // up to a residual of first order in k_ic, for k_ic x 1e-3 and 1e-6 as well.
    for d in [
        Drive::new(1200.0, 50.0, 40.0, 30.0),
        Drive::new(1500.0, 110.0, 80.0, 30.0),
        Drive::new(1900.0, 220.0, 0.0, 50.0),
    ] {
        let b = steady_state(&m10, &d).unwrap();
        let res: Vec<f64> = [1e-3, 1e-6]
            .iter()
            .map(|k| {
                let m = engine12_scaled(*k, 1.0);
                let (s, p_im) = (&b.signals, b.x[ix10::P_IM]);
                let dp = intercooler::pressure_drop(&m.params().intercooler, s.w_c, s.t_c, p_im);
                let x = Engine12::from_10_state(&b.x, p_im + dp, s.t_c);
                let ev = m.eval(
                    &x,
                    &ModelInput::constant(d),
                    SeligerIterate {
                        x_r: 0.0,
                        t_1: 300.0,
                    },
                );
                let sc = m.state_scales();
                (0..12)
                    .map(|i| (ev.dx[i] / sc[i]).abs())
                    .fold(0.0, f64::max)
            })
            .collect();
        eprintln!("lifted 10-state equilibrium at {d:?}: 12-state residual {:.3e} (k_ic x 1e-3), {:.3e} (x 1e-6) 1/s", res[0], res[1]);
        let ratio = res[1] / res[0];
        assert!(ratio > 0.5e-3 && ratio < 2e-3, "{res:?}");
    }

    // V_ic has no influence on the steady state at all
    let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let a = steady_state(&ms[0], &d).unwrap();
    for v in [0.1, 10.0] {
        let c = steady_state(&engine12_scaled(1.0, v), &d).unwrap();
        for i in 0..12 {
            assert!(close(c.x[i], a.x[i], 1e-9), "V_ic x{v}: state {i}");
        }
    }
}

/// max |y - y_ref| over the samples, relative to the range of `y_ref`.
fn max_distance(y_ref: &[f64], y: &[f64]) -> f64 {
    let range = y_ref.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - y_ref.iter().cloned().fold(f64::INFINITY, f64::min);
    let worst = y_ref
        .iter()
        .zip(y)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    worst / range
}

#[test]
fn twelve_state_step_response_converges_to_ten_state_as_v_ic_and_k_ic_vanish() {
    // u_vgt 75 -> 65 % at (1500 rpm, 110 mg, 80 %). V_ic and k_ic are scaled together by s;
    // the time constant of p_c scales like V_ic k_ic ~ s^2 (1.5 ms at s = 1; the L-stable
    // default integrator is not limited by it, an explicit one would need ~1/s^2 more steps).
    // The error is first order in s, so the trend over s = 1, 1/2, 1/4 is what is checked.
    let sched =
        InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(1.0, 3, 65.0)]).unwrap();
    let opts = SimOptions {
        rtol: 1e-8,
        atol: 1e-10,
        dt_out: 0.01,
        ..SimOptions::default()
    };
    let r10 = simulate_from_steady(&Engine10::published(), &sched, 0.0, 8.0, &opts).unwrap();
    let signals = ["W_c", "p_im", "p_em", "n_t"];
    let mut errs: Vec<[f64; 4]> = Vec::new();
    for s in [1.0, 0.5, 0.25] {
        let m = engine12_scaled(s, s);
        let r = simulate_from_steady(&m, &sched, 0.0, 8.0, &opts).unwrap();
        let e: [f64; 4] = std::array::from_fn(|k| {
            max_distance(r10.get(signals[k]).unwrap(), r.get(signals[k]).unwrap())
        });
        eprintln!(
            "s = {s}: max |12 - 10| / range: {signals:?} = {:?} ({} steps)",
            e.map(|v| format!("{v:.3e}")),
            r.stats.steps
        );
        errs.push(e);
    }
    for k in 0..4 {
        for w in errs.windows(2) {
            let ratio = w[1][k] / w[0][k];
            assert!(
                ratio > 0.35 && ratio < 0.65,
                "{}: halving s changed the error by {ratio}",
                signals[k]
            );
        }
    }
}

/// Gas properties of a volume: (R, c_v, c_p) [J/(kg K)].
type Gas = (f64, f64, f64);

/// Mass and internal-energy balance of one adiabatic volume `v` [m^3] holding `gas`, whose
/// pressure and temperature states sit at indices `ip`, `it` of `x` (derivatives `dx`): with
/// m = pV/(RT), U = c_v m T, dm/dt = W_in - W_out and dU/dt = c_p (T_in W_in - T W_out);
/// returns the two residuals relative to |W_in| + |W_out| resp. c_p T (|W_in| + |W_out|).
fn balance<const N: usize>(
    gas: Gas,
    v: f64,
    (x, dx): (&[f64; N], &[f64; N]),
    (ip, it): (usize, usize),
    (w_in, t_in, w_out): (f64, f64, f64),
) -> (f64, f64) {
    let (r, c_v, c_p) = gas;
    let (p, t, dp, dt) = (x[ip], x[it], dx[ip], dx[it]);
    let dm = v / (r * t) * dp - p * v / (r * t * t) * dt;
    let du = c_v * v / r * dp; // d(c_v m T)/dt = c_v V/R dp/dt
    let scale = w_in.abs() + w_out.abs();
    let mass = (dm - (w_in - w_out)).abs() / scale;
    let energy = (du - c_p * (t_in * w_in - t * w_out)).abs() / (c_p * t.max(t_in) * scale);
    (mass, energy)
}

struct Rng(u64);
impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((self.0 >> 11) as f64 / (1u64 << 53) as f64)
    }
}

fn random_drive(rng: &mut Rng) -> ModelInput {
    let d = Drive::new(
        rng.uniform(600.0, 2000.0),
        rng.uniform(10.0, 240.0),
        rng.uniform(0.0, 100.0),
        rng.uniform(25.0, 100.0),
    );
    ModelInput {
        now: d,
        u_egr_delayed: rng.uniform(0.0, 100.0),
        u_vgt_delayed: rng.uniform(25.0, 100.0),
    }
}

#[test]
fn ten_state_derivatives_balance_mass_and_internal_energy() {
    let mut rng = Rng(7);
    let mut worst = 0.0f64;
    for sem in [Semantics::Authors, Semantics::Paper] {
        let opts = ModelOptions {
            semantics: sem,
            ..ModelOptions::default()
        };
        let m = Engine10::new(Params::published(), opts).unwrap();
        let p = m.params().clone();
        let g = &p.gas;
        for _ in 0..500 {
            let x = [
                rng.uniform(1.1e5, 3.5e5),
                rng.uniform(1.2e5, 4.0e5),
                rng.uniform(290.0, 380.0),
                rng.uniform(500.0, 1000.0),
                rng.uniform(0.15, 0.2314),
                rng.uniform(0.02, 0.2),
                rng.uniform(3000.0, 12000.0),
                rng.uniform(0.0, 100.0),
                rng.uniform(0.0, 100.0),
                rng.uniform(25.0, 100.0),
            ];
            let u = random_drive(&mut rng);
            let mem = SeligerIterate {
                x_r: 0.03,
                t_1: 330.0,
            };
            let ev = m.eval(&x, &u, mem);
            let s = &ev.signals;
            let (air, exh) = ((g.r_a, g.c_va, g.c_pa), (g.r_e, g.c_ve, g.c_pe));
            let xs = (&x, &ev.dx);
            // intake manifold: in W_c + W_egr at T_im,in, out W_ei at T_im
            let w_in = s.w_c + s.w_egr;
            let (mi, ei) = balance(
                air,
                p.intake_manifold.v_im,
                xs,
                (ix10::P_IM, ix10::T_IM),
                (w_in, p.intake_manifold.t_im, s.w_ei),
            );
            // exhaust manifold: in W_eo at T_em,in (eq. (25)), out W_t + W_egr at T_em
            let (me, ee) = balance(
                exh,
                p.exhaust_manifold.v_em,
                xs,
                (ix10::P_EM, ix10::T_EM),
                (s.w_eo, s.t_em_in, s.w_t + s.w_egr),
            );
            worst = worst.max(mi).max(ei).max(me).max(ee);
            assert!(
                mi < 1e-10 && ei < 1e-10 && me < 1e-10 && ee < 1e-10,
                "{sem:?}: {mi:e} {ei:e} {me:e} {ee:e} at {x:?}"
            );
            // the flows see the states (W_ei with T_im, W_t with T_em)
            assert_eq!((s.t_im, s.t_em), (x[ix10::T_IM], x[ix10::T_EM]));
        }
    }
    eprintln!("10-state mass/energy balance: worst relative residual {worst:.2e}");
}

#[test]
fn twelve_state_derivatives_balance_mass_and_internal_energy() {
    let mut rng = Rng(11);
    let m = Engine12::published();
    let p = m.params().clone();
    let g = &p.gas;
    let mut back_flows = 0;
    for _ in 0..500 {
        let p_im = rng.uniform(1.1e5, 3.5e5);
        let x = [
            p_im,
            rng.uniform(1.2e5, 4.0e5),
            p_im + rng.uniform(-2e3, 2e4),
            rng.uniform(290.0, 380.0),
            rng.uniform(500.0, 1000.0),
            rng.uniform(300.0, 500.0),
            rng.uniform(0.15, 0.2314),
            rng.uniform(0.02, 0.2),
            rng.uniform(3000.0, 12000.0),
            rng.uniform(0.0, 100.0),
            rng.uniform(0.0, 100.0),
            rng.uniform(25.0, 100.0),
        ];
        let u = random_drive(&mut rng);
        let mem = SeligerIterate {
            x_r: 0.03,
            t_1: 330.0,
        };
        let ev = m.eval(&x, &u, mem);
        let s = &ev.signals;
        let t_cool = p.intake_manifold.t_im;
        let (fwd, back) = (s.w_ic.max(0.0), (-s.w_ic).max(0.0));
        if back > 0.0 {
            back_flows += 1;
        }
        // before the intercooler: in W_c at T_c (+ back flow cooled to T_im,in), out W_ic at T_ic
        let (air, exh) = ((g.r_a, g.c_va, g.c_pa), (g.r_e, g.c_ve, g.c_pe));
        let xs = (&x, &ev.dx);
        let (w_in, wt_in) = (s.w_c + back, s.t_c * s.w_c + t_cool * back);
        let ic = (ix12::P_C, ix12::T_IC);
        let (mc, ec) = balance(air, p.intercooler.v_ic, xs, ic, (w_in, wt_in / w_in, fwd));
        // intake manifold: in W_ic + W_egr at T_im,in, out W_ei (+ back flow) at T_im
        let (mi, ei) = balance(
            air,
            p.intake_manifold.v_im,
            xs,
            (ix12::P_IM, ix12::T_IM),
            (fwd + s.w_egr, t_cool, s.w_ei + back),
        );
        let (me, ee) = balance(
            exh,
            p.exhaust_manifold.v_em,
            xs,
            (ix12::P_EM, ix12::T_EM),
            (s.w_eo, s.t_em_in, s.w_t + s.w_egr),
        );
        for (what, v) in [
            ("ic mass", mc),
            ("ic energy", ec),
            ("im mass", mi),
            ("im energy", ei),
            ("em mass", me),
            ("em energy", ee),
        ] {
            assert!(v < 1e-10, "{what}: {v:e} at {x:?}");
        }
        // the compressor sees p_c (eq. (87))
        assert!(close(
            s.pi_c,
            (x[ix12::P_C] / p.ambient.p_amb).max(1.0),
            1e-15
        ));
    }
    assert!(
        back_flows > 10,
        "the sample covers back flow ({back_flows})"
    );
}

#[test]
fn vgt_steps_keep_nmp_overshoot_and_sign_reversal_in_all_model_orders() {
    // The paper's Figs 11-14: 8 vs 10 vs 12 states at (1500 rpm, 110 mg, 80 %).
    let cases = VgtStep::paper_cases();
    let r = compare_vgt_steps(
        &Params::published(),
        ModelOptions::default(),
        &cases,
        &CompareOptions::default(),
    )
    .unwrap();
    assert_eq!(r.len(), 2);
    let (nmp_case, over_case) = (&r[0], &r[1]);
    for order in [ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve] {
        let a = nmp_case.response(order).unwrap();
        let b = over_case.response(order).unwrap();
        eprintln!(
            "{order:?}: 75->65 W_c gain {:.3e} kg/s/%, NMP {} ({:.2} of the change); 30->25 gain {:.3e}, overshoot {:.1} %",
            a.w_c.dc_gain, a.w_c.non_minimum_phase, dip(a), b.w_c.dc_gain, b.w_c.overshoot_pct
        );
        // 75 -> 65: non-minimum phase, negative DC gain
        assert!(
            a.w_c.non_minimum_phase && dip(a) > 0.5,
            "{order:?}: {:?}",
            a.w_c
        );
        assert!(a.w_c.dc_gain < 0.0);
        // 30 -> 25: overshoot, positive DC gain, no NMP
        assert!(b.w_c.overshoot_pct > 10.0, "{order:?}: {:?}", b.w_c);
        assert!(b.w_c.dc_gain > 0.0 && !b.w_c.non_minimum_phase);
        assert_eq!(sign_reversal(&r, order), Some(true));
        assert_eq!(a.t.len(), 801);
        assert_eq!(a.series("W_c").unwrap().len(), 801);
    }
    // 10 vs 8: no stationary difference, responses close (the paper: "approximately the same")
    for c in &r {
        for sd in c.stationary.iter().filter(|s| s.order == ModelOrder::Ten) {
            assert!(
                sd.before.abs() < 1e-8 && sd.after.abs() < 1e-8,
                "{}: {sd:?}",
                c.step.label()
            );
        }
        let w8 = c
            .response(ModelOrder::Eight)
            .unwrap()
            .series("W_c")
            .unwrap();
        let w10 = c.response(ModelOrder::Ten).unwrap().series("W_c").unwrap();
        let dev = max_distance(w8, w10);
        eprintln!(
            "{}: max |W_c,10 - W_c,8| = {dev:.3} of the W_c range",
            c.step.label()
        );
        assert!(dev < 0.1, "{dev}");
        // 12 vs 8: stationary differences of a few percent (the pressure drop), as in Figs 13-14
        let p_im12 = c
            .stationary
            .iter()
            .find(|s| s.order == ModelOrder::Twelve && s.signal == "p_im")
            .unwrap();
        assert!(p_im12.before < -1e-3 && p_im12.before > -0.1, "{p_im12:?}");
    }
}

#[test]
fn one_iteration_cylinder_temperature_is_exact_at_a_steady_state() {
    // From a steady state at constant inputs the held iterate is the fixed point itself, so
    // one iteration per step reproduces the converged T_e.
    let sched = InputSchedule::constant(Drive::new(1500.0, 110.0, 80.0, 75.0));
    // (The two runs take different steps, so they agree to the integration tolerance.)
    let co = CylinderTempOptions {
        rtol: 1e-10,
        dt_out: 0.1,
    };
    let r = cylinder_temp_study(&Engine8::published(), &sched, 0.0, 5.0, &co).unwrap();
    assert_eq!(r.t.len(), 51);
    // At t = 0 both evaluate the same fixed point: the one-iteration T_e is the map's value
    // there, the converged T_e that of the closed form, which the converged path returns for
    // the published x_cv when an a-priori bound shows it within the fixed point's tolerance
    // (`cylinder::closed_form_is_converged`: within about 3e-14 of the map's value).
    assert!(r.rel_error[0].abs() < 1e-13, "{}", r.rel_error[0]);
    assert!(r.max_abs_rel_error < 1e-8, "{}", r.max_abs_rel_error);
}

#[test]
fn one_iteration_cylinder_temperature_error_on_the_whtc() {
    // Paper section 4.2.3, Fig. 2: max 0.15 % on the ETC with the authors' solver (ode23s).
    // Here the WHTC at rtol 1e-6; the value depends on the accepted step sequence.
    let sched = mvem::io::csv_inputs::load_inputs_csv(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/whtc_inputs_10hz.csv"),
    )
    .unwrap();
    let m = Engine8::published();
    let r = cylinder_temp_study(&m, &sched, 0.0, 1800.0, &CylinderTempOptions::default()).unwrap();
    eprintln!(
        "WHTC, rtol {:e}: T_e one-iteration vs converged: max {:.3e} at t = {} s, mean {:.3e} ({} / {} steps)",
        r.rtol, r.max_abs_rel_error, r.t_max, r.mean_abs_rel_error, r.steps_converged, r.steps_one_iteration
    );
    assert_eq!(r.t.len(), 18001);
    assert!(r.max_abs_rel_error > 0.0 && r.max_abs_rel_error < 1.5e-3);
    assert!(r.mean_abs_rel_error < 0.1 * r.max_abs_rel_error);
    let i = r.t.iter().position(|t| *t == r.t_max).unwrap();
    assert_eq!(r.rel_error[i].abs(), r.max_abs_rel_error);
    assert!(close(
        r.rel_error[i],
        (r.t_e_one_iteration[i] - r.t_e_converged[i]) / r.t_e_converged[i],
        1e-12
    ));
}

#[test]
fn intercooler_parameter_sensitivity() {
    // How much the 12-state results depend on the two unpublished parameters (numbers quoted
    // in docs/extensions.md): k_ic and V_ic halved and doubled, at the paper's two VGT steps.
    let co = CompareOptions {
        orders: vec![ModelOrder::Eight, ModelOrder::Twelve],
        ..CompareOptions::default()
    };
    let stat = |c: &mvem::analysis::extensions::StepComparison, name: &str| {
        let s = c.stationary.iter().find(|s| s.signal == name).unwrap();
        (s.before, s.after)
    };
    let mut base_dp = 0.0;
    for (k, v) in [(1.0, 1.0), (0.5, 1.0), (2.0, 1.0), (1.0, 0.5), (1.0, 2.0)] {
        let mut p = Params::published();
        p.intercooler.k_ic *= k;
        p.intercooler.v_ic *= v;
        let r =
            compare_vgt_steps(&p, ModelOptions::default(), &VgtStep::paper_cases(), &co).unwrap();
        let (a, b) = (
            r[0].response(ModelOrder::Twelve).unwrap(),
            r[1].response(ModelOrder::Twelve).unwrap(),
        );
        let (pim, wc) = (stat(&r[0], "p_im"), stat(&r[0], "W_c"));
        let dp = a.steady_before[2].1 - a.steady_before[0].1; // p_c - p_im
        eprintln!(
            "k_ic x{k}, V_ic x{v}: p_c - p_im {dp:.0} Pa; vs 8 states p_im {:+.2} %, W_c {:+.2} %; \
             75->65 NMP {:.2} of change at {:.2} s; 30->25 overshoot {:.1} %",
            100.0 * pim.0,
            100.0 * wc.0,
            dip(a),
            a.w_c.wrong_way.map_or(f64::NAN, |e| e.time - a.w_c.t_step),
            b.w_c.overshoot_pct
        );
        // the paper's qualitative features survive every variation
        assert!(a.w_c.non_minimum_phase && b.w_c.overshoot_pct > 10.0 && !b.w_c.non_minimum_phase);
        assert_eq!(sign_reversal(&r, ModelOrder::Twelve), Some(true));
        if (k, v) == (1.0, 1.0) {
            base_dp = dp;
        }
        if v == 1.0 && k != 1.0 {
            // the pressure drop scales almost like k_ic (W_c itself moves a little)
            assert!(
                dp / base_dp > 0.8 * k && dp / base_dp < 1.2 * k,
                "{dp} vs {base_dp}"
            );
        }
        if k == 1.0 && v != 1.0 {
            // V_ic changes only the dynamics
            assert!((dp - base_dp).abs() < 1e-6 * base_dp);
        }
    }
}

/// Size of the W_c wrong-way excursion relative to the final change (0 if none).
fn dip(r: &mvem::analysis::extensions::StepResponse) -> f64 {
    r.w_c.wrong_way.map_or(0.0, |e| e.relative)
}
