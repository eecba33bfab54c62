//! The plant stepper (`mvem::sim::stepper`): stepping sample by sample equals `simulate`, bad
//! commands are errors, every variant runs.
use mvem::analysis::steady::{any_plant_from_steady, plant_from_steady, steady_state};
use mvem::model::{AnyModel, Drive, Engine8, Model, ModelOrder};
use mvem::params::Params;
use mvem::sim::{simulate, InputSchedule, SimOptions, Start};

/// The paper's VGT step (Fig. 9: 75 -> 65 % at 1 s, 1500 rpm, 110 mg, u_egr 80 %), stepped
/// 10 ms at a time, equals `simulate` of the same schedule at every sample.
#[test]
fn stepping_equals_simulate_on_the_vgt_step() {
    let m = Engine8::published();
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let d1 = Drive::new(1500.0, 110.0, 80.0, 65.0);
    let sched = InputSchedule::steps(d0, &[(1.0, 3, 65.0)]).unwrap();
    let opts = SimOptions::default();
    let x0 = steady_state(&m, &d0).unwrap().x;
    let sol = simulate(&m, &sched, 0.0, 4.0, Start::State(x0), &opts).unwrap();
    let mut plant = plant_from_steady(m.clone(), d0, 0.0, &opts).unwrap();
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
    // both runs are error-controlled at rtol = atol = 1e-6 (scaled): agreement to ~1e-5
    assert!(worst_x < 2e-5, "worst scaled state deviation {worst_x:e}");
    assert!(
        worst_w < 1e-4,
        "worst W_c deviation {worst_w:e} of its span"
    );
    // the history is trimmed to the delays
    assert!(plant.history_len() <= 4, "history {}", plant.history_len());
}

#[test]
fn bad_commands_and_steps_are_errors() {
    let m = Engine8::published();
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let mut plant = plant_from_steady(m, d0, 0.0, &SimOptions::default()).unwrap();
    let e = plant.step(0.0, d0).unwrap_err().to_string();
    assert!(e.contains("dt"), "{e}");
    let e = plant
        .step(0.01, Drive::new(1500.0, f64::NAN, 80.0, 75.0))
        .unwrap_err()
        .to_string();
    assert!(e.contains("u_delta"), "{e}");
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
