//! The closed-form actuator states of the simulator (`SimOptions::exact_actuators`): the lag
//! description of every model matches its `eval`, the simulated actuator states equal an
//! independent fine-step integration of the lag, and the full simulation agrees with the
//! plain W-method (all states integrated numerically), also where a command crosses its
//! saturation inside a segment and with the delayed commands' breakpoints inside steps
//! (`SimOptions::stop_at_lag_breakpoints` off); the delayed commands drive the actuator states
//! only.

use mvem::analysis::steady::simulate_from_steady;
use mvem::components::cylinder::SeligerIterate;
use mvem::components::Semantics;
use mvem::model::{
    Actuators, Drive, Engine10, Engine12, Engine8, LagCommand, LinearLag, Model, ModelInput,
    ModelOptions,
};
use mvem::params::Params;
use mvem::sim::{InputSchedule, SimOptions, Solution};

fn options() -> Vec<ModelOptions> {
    let mut v = Vec::new();
    for semantics in [Semantics::Authors, Semantics::Paper] {
        for actuators in [Actuators::Dynamic, Actuators::Bypass] {
            v.push(ModelOptions {
                semantics,
                actuators,
                ..ModelOptions::default()
            });
        }
    }
    v
}

/// `eval`'s derivative of every lag state equals (clamp(u_delayed) - x) / tau, bit for bit up
/// to one rounding, at states and commands in and out of the saturation ranges.
fn check_lags<const N: usize, M: Model<N, Memory = SeligerIterate>>(m: &M, x_steady: [f64; N]) {
    let lags: Vec<LinearLag> = m.linear_lags();
    assert_eq!(lags.len(), 3, "three actuator states");
    let d = Drive::new(1500.0, 110.0, 40.0, 60.0);
    for (k, (ue, uv)) in [(40.0, 60.0), (-20.0, 10.0), (150.0, 130.0), (0.0, 20.0)]
        .into_iter()
        .enumerate()
    {
        let mut x = x_steady;
        for (i, l) in lags.iter().enumerate() {
            x[l.state] = 30.0 + 7.0 * (i + k) as f64;
        }
        let u = ModelInput {
            now: d,
            u_egr_delayed: ue,
            u_vgt_delayed: uv,
        };
        let memory = SeligerIterate {
            x_r: 0.0,
            t_1: 300.0,
        };
        let ev = m.eval(&x, &u, memory);
        for l in &lags {
            let cmd = match l.command {
                LagCommand::Egr => ue,
                LagCommand::Vgt => uv,
            };
            let target = cmd.clamp(l.saturation.0, l.saturation.1);
            let expect = (target - x[l.state]) / l.tau;
            let got = ev.dx[l.state];
            assert!(
                (got - expect).abs() <= 1e-14 * expect.abs().max(1.0),
                "state {} ({:?}, {:?}): eval {got} vs lag {expect}",
                l.state,
                m.options().semantics,
                m.options().actuators
            );
        }
    }
}

#[test]
fn lag_description_matches_eval_for_8_10_12_states() {
    let d = Drive::new(1500.0, 110.0, 40.0, 60.0);
    for o in options() {
        let m8 = Engine8::new(Params::published(), o).unwrap();
        let x8 = mvem::analysis::steady::steady_state(&m8, &d).unwrap().x;
        check_lags(&m8, x8);
        let m10 = Engine10::new(Params::published(), o).unwrap();
        let x10 = Engine10::from_8_state(&x8, 320.0, 900.0);
        check_lags(&m10, x10);
        let m12 = Engine12::new(Params::published(), o).unwrap();
        let x12 = mvem::analysis::steady::steady_state(&m12, &d).unwrap().x;
        check_lags(&m12, x12);
    }
}

/// The delayed commands enter the derivatives of the actuator states only (the contract of
/// `LinearLag` that lets a step run across their breakpoints): changing them leaves every other
/// derivative bit for bit unchanged, and changes every lag state's derivative.
fn check_delayed_drive_only_lags<const N: usize, M: Model<N, Memory = SeligerIterate>>(
    m: &M,
    x: [f64; N],
) {
    let lags = m.linear_lags();
    let d = Drive::new(1500.0, 110.0, 40.0, 60.0);
    let memory = SeligerIterate {
        x_r: 0.0,
        t_1: 300.0,
    };
    let at = |ue: f64, uv: f64| {
        m.eval(
            &x,
            &ModelInput {
                now: d,
                u_egr_delayed: ue,
                u_vgt_delayed: uv,
            },
            memory,
        )
        .dx
    };
    let base = at(40.0, 60.0);
    for (ue, uv) in [(70.0, 60.0), (40.0, 90.0), (10.0, 30.0)] {
        let dx = at(ue, uv);
        for i in 0..N {
            match lags.iter().find(|l| l.state == i) {
                None => assert_eq!(dx[i], base[i], "state {i} ({:?})", m.options()),
                Some(l) => {
                    let moved = match l.command {
                        LagCommand::Egr => ue != 40.0,
                        LagCommand::Vgt => uv != 60.0,
                    };
                    assert_eq!(dx[i] != base[i], moved, "lag state {i} ({:?})", m.options());
                }
            }
        }
    }
}

#[test]
fn delayed_commands_drive_only_the_actuator_states() {
    let d = Drive::new(1500.0, 110.0, 40.0, 60.0);
    for o in options() {
        let m8 = Engine8::new(Params::published(), o).unwrap();
        let x8 = mvem::analysis::steady::steady_state(&m8, &d).unwrap().x;
        check_delayed_drive_only_lags(&m8, x8);
        let m10 = Engine10::new(Params::published(), o).unwrap();
        check_delayed_drive_only_lags(&m10, Engine10::from_8_state(&x8, 320.0, 900.0));
        let m12 = Engine12::new(Params::published(), o).unwrap();
        let x12 = mvem::analysis::steady::steady_state(&m12, &d).unwrap().x;
        check_delayed_drive_only_lags(&m12, x12);
    }
}

/// Scalar lag dx/dt = (c(t) - x)/tau by classical RK4 with a fine fixed step (independent of the
/// simulator's closed form), sampled at `times`.
fn rk4_lag(c: impl Fn(f64) -> f64, tau: f64, x0: f64, times: &[f64]) -> Vec<f64> {
    let f = |t: f64, x: f64| (c(t) - x) / tau;
    let dt: f64 = 1e-5;
    let (mut t, mut x) = (times[0], x0);
    let mut out = Vec::with_capacity(times.len());
    for &ts in times {
        while t < ts - 1e-12 {
            let h = dt.min(ts - t);
            let k1 = f(t, x);
            let k2 = f(t + h / 2.0, x + h / 2.0 * k1);
            let k3 = f(t + h / 2.0, x + h / 2.0 * k2);
            let k4 = f(t + h, x + h * k3);
            x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            t += h;
        }
        out.push(x);
    }
    out
}

fn linear_interp(times: &[f64], vals: &[f64], t: f64) -> f64 {
    if t <= times[0] {
        return vals[0];
    }
    for i in 1..times.len() {
        if t <= times[i] {
            let s = (t - times[i - 1]) / (times[i] - times[i - 1]);
            return vals[i - 1] + s * (vals[i] - vals[i - 1]);
        }
    }
    *vals.last().unwrap()
}

/// `stop`: [`SimOptions::stop_at_lag_breakpoints`] (false: steps run across the delayed
/// commands' breakpoints, the closed form follows them inside the step).
fn run(sched: &InputSchedule, t_end: f64, exact: bool, stop: bool, rtol: f64) -> Solution {
    let m = Engine8::published();
    let opts = SimOptions {
        rtol,
        atol: rtol,
        dt_out: 0.01,
        exact_actuators: exact,
        stop_at_lag_breakpoints: stop,
        ..SimOptions::default()
    };
    simulate_from_steady(&m, sched, 0.0, t_end, &opts).unwrap()
}

/// Ramps of both commands; with `u_egr_top` > 100 the EGR command crosses its saturation inside a
/// segment (the closed form splits the command's piece there).
fn ramp_schedule(u_egr_top: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>, InputSchedule) {
    let times = vec![0.0, 0.5, 1.3, 2.0, 4.0];
    let u_egr = vec![40.0, 40.0, 60.0, u_egr_top, u_egr_top];
    let u_vgt = vec![60.0, 60.0, 45.0, 45.0, 70.0];
    let rows = times
        .iter()
        .enumerate()
        .map(|(i, _)| [1500.0, 110.0, u_egr[i], u_vgt[i]])
        .collect();
    let s = InputSchedule::new(times.clone(), rows).unwrap();
    (times, u_egr, u_vgt, s)
}

#[test]
fn simulated_actuator_states_equal_a_fine_step_integration_of_the_lags() {
    let p = Params::published();
    // 95 %: inside the range; 140 %: the EGR command crosses its saturation in a segment
    for (top, stop) in [(95.0, true), (95.0, false), (140.0, true), (140.0, false)] {
        check_fine_step(&p, top, stop);
    }
}

fn check_fine_step(p: &Params, top: f64, stop: bool) {
    let (times, u_egr, u_vgt, sched) = ramp_schedule(top);
    let sol = run(&sched, 5.0, true, stop, 1e-6);
    if !stop {
        // the delayed commands' kinks are no stop times (the undelayed ones drive nothing)
        assert_eq!(sol.stats.breakpoints, 0, "{:?}", sol.stats);
    }
    let t = sol.t();
    let (te, tv) = (p.egr_actuator.tau_degr, p.vgt_actuator.tau_dvgt);
    let egr = |t: f64| linear_interp(&times, &u_egr, t - te).clamp(0.0, 100.0);
    let vgt = |t: f64| linear_interp(&times, &u_vgt, t - tv).clamp(20.0, 100.0);
    let cases = [
        (
            "u_egr1",
            p.egr_actuator.tau_egr1,
            40.0,
            &egr as &dyn Fn(f64) -> f64,
        ),
        ("u_egr2", p.egr_actuator.tau_egr2, 40.0, &egr),
        ("u_vgt_act", p.vgt_actuator.tau_vgt, 60.0, &vgt),
    ];
    for (name, tau, x0, c) in cases {
        let reference = rk4_lag(c, tau, x0, t);
        let got = sol.get(name).unwrap();
        let worst = got
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // RK4 at 1e-5 s is accurate to ~1e-12 % here; the closed form to rounding
        assert!(
            worst < 1e-8,
            "{name} (top {top} %, stop {stop}): max |sim - rk4| = {worst:e} %"
        );
    }
}

fn max_scaled_dev(a: &Solution, b: &Solution) -> f64 {
    let scales = [
        ("p_im", 1e5),
        ("p_em", 1e5),
        ("X_Oim", 0.1),
        ("X_Oem", 0.1),
        ("omega_t", 1e4),
        ("u_egr1", 100.0),
        ("u_egr2", 100.0),
        ("u_vgt_act", 100.0),
    ];
    assert_eq!(a.t(), b.t());
    scales
        .iter()
        .map(|(n, s)| {
            let (x, y) = (a.get(n).unwrap(), b.get(n).unwrap());
            x.iter()
                .zip(y)
                .map(|(u, v)| (u - v).abs() / s)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[test]
fn closed_form_and_plain_w_method_agree_through_a_saturation_crossing() {
    let (_, _, _, sched) = ramp_schedule(140.0);
    let plain = run(&sched, 5.0, false, true, 1e-9);
    for stop in [true, false] {
        let exact = run(&sched, 5.0, true, stop, 1e-9);
        let dev = max_scaled_dev(&exact, &plain);
        assert!(dev < 1e-7, "stop {stop}: max scaled deviation {dev:e}");
    }
}

#[test]
fn closed_form_and_plain_w_method_agree_on_a_whtc_minute() {
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    let sched = mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap();
    let m = Engine8::published();
    let opts = |exact, stop| SimOptions {
        rtol: 1e-9,
        atol: 1e-9,
        dt_out: 0.1,
        exact_actuators: exact,
        stop_at_lag_breakpoints: stop,
        ..SimOptions::default()
    };
    let a = simulate_from_steady(&m, &sched, 600.0, 660.0, &opts(true, true)).unwrap();
    let b = simulate_from_steady(&m, &sched, 600.0, 660.0, &opts(false, true)).unwrap();
    let dev = max_scaled_dev(&a, &b);
    assert!(dev < 1e-6, "max scaled deviation {dev:e}");
    // steps across the delayed commands' breakpoints: as accurate
    let c = simulate_from_steady(&m, &sched, 600.0, 660.0, &opts(true, false)).unwrap();
    let dev = max_scaled_dev(&c, &b);
    assert!(
        dev < 1e-6,
        "across breakpoints: max scaled deviation {dev:e}"
    );
    assert!(
        c.stats.breakpoints < a.stats.breakpoints,
        "{:?} vs {:?}",
        c.stats,
        a.stats
    );
    // and the closed form takes fewer steps at the same tolerance
    assert!(
        a.stats.steps < b.stats.steps,
        "{:?} vs {:?}",
        a.stats,
        b.stats
    );
}
