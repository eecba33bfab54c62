//! The plant stepper (`mvem::sim::stepper`): stepping sample by sample equals `simulate`, bad
//! commands are errors, every variant runs.
use mvem::analysis::steady::{any_plant_from_steady, plant_from_steady, steady_state};
use mvem::model::{AnyModel, Drive, Engine8, Model, ModelOrder};
use mvem::params::Params;
use mvem::sim::{simulate, InputSchedule, SimOptions, Start};

/// The paper's VGT step (Fig. 9: 75 -> 65 % at 1 s, 1500 rpm, 110 mg, u_egr 80 %), stepped
/// 10 ms at a time, equals `simulate` of the same schedule at every sample.
///
/// Both with the simulator's default options and with the plant's
/// ([`mvem::sim::stepper::plant_options`]: the delayed command change is no stop time, the
/// actuator states follow it in closed form inside a step), against `simulate` with the defaults.
#[test]
fn stepping_equals_simulate_on_the_vgt_step() {
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let d1 = Drive::new(1500.0, 110.0, 80.0, 65.0);
    for opts in [SimOptions::default(), mvem::sim::stepper::plant_options()] {
        // both runs are error-controlled at rtol = atol = 1e-6 (scaled): agreement to ~1e-5
        check_stepping(d0, d1, 3, &opts, 2e-5, 1e-4);
    }
}

/// An EGR step (80 -> 60 % at 1 s): its delayed copy (tau_degr = 65 ms) falls 5 ms into a
/// sample, a stop time with the default options and none with the plant's; both equal
/// `simulate` (W_c moves by only 1.2 g/s here: its tolerance of 5e-3 of the span is 6 mg/s).
#[test]
fn stepping_equals_simulate_on_an_egr_step_across_its_delayed_copy() {
    let d0 = Drive::new(1500.0, 110.0, 80.0, 65.0);
    let d1 = Drive::new(1500.0, 110.0, 60.0, 65.0);
    let with_stops = check_stepping(d0, d1, 2, &SimOptions::default(), 3e-5, 5e-3);
    assert_eq!(with_stops.breakpoints, 1, "{with_stops:?}");
    let across = check_stepping(d0, d1, 2, &mvem::sim::stepper::plant_options(), 3e-5, 5e-3);
    assert_eq!(across.breakpoints, 0, "{across:?}");
}

/// Step the plant (options `opts`) from the steady state of `d0` 10 ms at a time for 4 s, with
/// `d1` from 1 s on (channel `ch` changes), and compare every sample with `simulate` of the same
/// schedule (default options): the scaled states within `x_tol`, W_c within `w_tol` of its span;
/// the plant's statistics.
fn check_stepping(
    d0: Drive,
    d1: Drive,
    ch: usize,
    opts: &SimOptions,
    x_tol: f64,
    w_tol: f64,
) -> mvem::sim::SimStats {
    let m = Engine8::published();
    let sched = InputSchedule::steps(d0, &[(1.0, ch, d1.to_array()[ch])]).unwrap();
    let x0 = steady_state(&m, &d0).unwrap().x;
    let sol = simulate(
        &m,
        &sched,
        0.0,
        4.0,
        Start::State(x0),
        &SimOptions::default(),
    )
    .unwrap();
    let mut plant = plant_from_steady(m.clone(), d0, 0.0, opts).unwrap();
    let names = m.state_names();
    let scales = m.state_scales();
    let w_c = sol.get("W_c").unwrap();
    let span =
        w_c.iter().cloned().fold(f64::MIN, f64::max) - w_c.iter().cloned().fold(f64::MAX, f64::min);
    let (mut worst_x, mut worst_w) = (0.0f64, 0.0f64);
    for k in 1..=400 {
        let t_k = k as f64 * 0.01;
        // the command of the sample interval [t_{k-1}, t_k)
        let d = if (k - 1) as f64 * 0.01 >= 1.0 - 1e-9 {
            d1
        } else {
            d0
        };
        plant.step(0.01, d).unwrap();
        let i = sol
            .t()
            .iter()
            .position(|&t| (t - t_k).abs() < 1e-9)
            .unwrap();
        for (j, n) in names.iter().enumerate() {
            let e = (plant.state()[j] - sol.get(n).unwrap()[i]).abs() / scales[j];
            worst_x = worst_x.max(e);
        }
        worst_w = worst_w.max((plant.signals().w_c - w_c[i]).abs() / span);
    }
    assert!((plant.t() - 4.0).abs() < 1e-9);
    eprintln!(
        "{:?}: worst state {worst_x:e}, W_c {worst_w:e} of span {span:e}",
        plant.stats()
    );
    assert!(worst_x < x_tol, "worst scaled state deviation {worst_x:e}");
    assert!(
        worst_w < w_tol,
        "worst W_c deviation {worst_w:e} of its span"
    );
    // the history is trimmed to the delays
    assert!(plant.history_len() <= 4, "history {}", plant.history_len());
    plant.stats()
}

#[test]
fn bad_commands_and_steps_are_errors() {
    let m = Engine8::published();
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let mut plant = plant_from_steady(m.clone(), d0, 0.0, &SimOptions::default()).unwrap();
    let e = plant.step(0.0, d0).unwrap_err().to_string();
    assert!(e.contains("dt"), "{e}");
    // a step longer than MAX_STEP_LENGTH (1e6 s) is refused; 1e308 s once filled the memory
    for dt in [1e308, f64::INFINITY, f64::NAN, 2e6] {
        let e = plant.step(dt, d0).unwrap_err().to_string();
        assert!(e.contains("at most 1e6 s"), "{dt}: {e}");
    }
    // the longest step runs (the steady state held: 10^6 s in a few large steps)
    let mut held = plant_from_steady(m, d0, 0.0, &SimOptions::default()).unwrap();
    held.step(mvem::sim::stepper::MAX_STEP_LENGTH, d0).unwrap();
    assert_eq!(held.t(), 1e6);
    let e = plant
        .step(0.01, Drive::new(1500.0, f64::NAN, 80.0, 75.0))
        .unwrap_err()
        .to_string();
    assert_eq!(e, "command u_delta = NaN at t = 0 s: must be finite");
    // a failed call leaves the plant usable
    plant.step(0.01, d0).unwrap();
    assert!((plant.t() - 0.01).abs() < 1e-15);
}

#[test]
fn any_plant_runs_every_variant() {
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    for order in [8, 10, 12] {
        let m = AnyModel::new(
            ModelOrder::from_states(order).unwrap(),
            Params::published(),
            Default::default(),
        )
        .unwrap();
        let mut p = any_plant_from_steady(m, d0, 0.0, &SimOptions::default()).unwrap();
        let w0 = p.signals().w_c;
        for _ in 0..50 {
            p.step(0.01, Drive::new(1500.0, 110.0, 80.0, 65.0)).unwrap();
        }
        assert_eq!(p.state().len(), order);
        // the paper's non-minimum-phase dip: W_c falls first after closing the VGT
        assert!(p.get("W_c").unwrap() != w0);
        assert!(p.get("p_im").unwrap() > 1e5);
    }
}

/// `Plant::input`: the delayed commands the actuators see follow the command history
/// (tau_dvgt = 40 ms, tau_degr = 65 ms); the model's right-hand side at the plant's state and
/// that input moves the VGT actuator state toward the delayed command, so it is what the
/// integrator followed: the actuator's next 1 ms agrees with it to first order.
#[test]
fn the_plant_reports_the_delayed_commands_its_actuators_see() {
    let m = Engine8::published();
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let d1 = Drive::new(1500.0, 110.0, 60.0, 65.0);
    let mut p = plant_from_steady(m.clone(), d0, 0.0, &SimOptions::default()).unwrap();
    assert_eq!(p.input(), mvem::model::ModelInput::constant(d0));
    p.step(0.01, d0).unwrap();
    let mut seen = Vec::new();
    for _ in 0..10 {
        p.step(0.01, d1).unwrap(); // the change at t = 0.01 s
        let u = p.input();
        assert_eq!(u.now, d1);
        seen.push((p.t(), u.u_egr_delayed, u.u_vgt_delayed));
    }
    for (t, egr, vgt) in &seen {
        let since = t - 0.01;
        // a sample at exactly tau after the change is either side, by rounding of t - tau
        let want = |tau: f64, old: f64, new: f64| match since - tau {
            e if e.abs() < 1e-9 => None,
            e if e > 0.0 => Some(new),
            _ => Some(old),
        };
        if let Some(w) = want(0.04, 75.0, 65.0) {
            assert_eq!(*vgt, w, "u_vgt at t = {t}");
        }
        if let Some(w) = want(0.065, 80.0, 60.0) {
            assert_eq!(*egr, w, "u_egr at t = {t}");
        }
    }
    // 60 ms after the change: the VGT actuator follows 65 %, the EGR actuators still 80 %
    let t_now = p.t();
    let mut p = plant_from_steady(m.clone(), d0, 0.0, &SimOptions::default()).unwrap();
    p.step(0.01, d0).unwrap();
    for _ in 0..6 {
        p.step(0.01, d1).unwrap();
    }
    assert!(p.t() < t_now);
    let x = *p.state();
    let dx = m.eval(&x, &p.input(), m.memory_start(&x, &p.input())).dx;
    let before = x[7];
    p.step(0.001, d1).unwrap();
    let slope = (p.state()[7] - before) / 0.001;
    assert!(dx[7] < 0.0, "u_vgt_act moves toward 65 %: {}", dx[7]);
    assert!(
        (slope - dx[7]).abs() < 0.02 * dx[7].abs(),
        "{slope} vs {}",
        dx[7]
    );
    assert!(dx[5].abs() < 1e-9, "u_egr1 still sees 80 %: {}", dx[5]);
}
