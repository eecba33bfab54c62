//! The EGR and VGT command ranges are parameters of the engine (session 39):
//! `input_saturation.u_egr` and `u_vgt` of the parameter set, by default the authors' Simulink
//! saturations [0, 100] % and [20, 100] % (docs/authors-implementation.md items 3-4). The model's
//! clamp, the controller and the loop analyses read them.

use mvem::analysis::steady::steady_state;
use mvem::control::along::{along_trajectory, loops_in_charge, Outcome};
use mvem::control::baseline::BaselineTuning;
use mvem::control::drive::{run_cycle, CycleSource, Scheme};
use mvem::control::margins::baseline_loops;
use mvem::model::{ix, AnyModel, Drive, Engine8, Guard, ModelOrder};
use mvem::params::Params;

/// The published parameters with the VGT commanded over `u_vgt` [%].
fn with_vgt_range(u_vgt: [f64; 2]) -> Params {
    let mut p = Params::published();
    p.input_saturation.u_vgt = u_vgt;
    p
}

/// Relative difference of two numbers.
fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// A VGT commanded 0-100 %: a steady state at u_vgt = 10 % is the model's at 10 % (it differs
/// from the one at 20 %: p_em, omega_t and W_c by more than 1 %), with no clamp flag; the
/// published parameters clamp 10 % to 20 % (the same steady state to 1e-9, flagged). Both
/// sets agree at 20 %, inside both ranges.
#[test]
fn a_vgt_range_from_0_runs_a_command_of_10_percent_as_given() {
    let at = |p: &Params, u_vgt: f64| {
        let m = Engine8::new(p.clone(), Default::default()).unwrap();
        steady_state(&m, &Drive::new(1500.0, 110.0, 40.0, u_vgt)).unwrap()
    };
    let published = Params::published();
    let wide = with_vgt_range([0.0, 100.0]);
    let (p10, p20) = (at(&published, 10.0), at(&published, 20.0));
    let (w10, w20) = (at(&wide, 10.0), at(&wide, 20.0));
    let vgt_flag = Guard::InputUVgt.label();
    assert_eq!(vgt_flag, "input:u_vgt in input_saturation.u_vgt");
    // published: clamped to 20 %
    for i in 0..8 {
        assert!(
            rel(p10.x[i], p20.x[i]) < 1e-9,
            "state {i}: {:?} {:?}",
            p10.x,
            p20.x
        );
    }
    assert!(p10.flags.iter().any(|f| f == vgt_flag), "{:?}", p10.flags);
    // 0-100 %: 10 % is not 20 %
    for (name, a, b) in [
        ("p_em", w10.x[ix::P_EM], w20.x[ix::P_EM]),
        ("omega_t", w10.x[ix::OMEGA_T], w20.x[ix::OMEGA_T]),
        ("W_c", w10.signals.w_c, w20.signals.w_c),
    ] {
        assert!(rel(a, b) > 0.01, "{name}: {a} at 10 % vs {b} at 20 %");
    }
    assert!(
        (w10.x[ix::U_VGT] - 10.0).abs() < 1e-9,
        "u_vgt state {}",
        w10.x[ix::U_VGT]
    );
    assert!(!w10.flags.iter().any(|f| f == vgt_flag), "{:?}", w10.flags);
    // inside both ranges the sets are the same model
    for i in 0..8 {
        assert!(rel(w20.x[i], p20.x[i]) < 1e-9, "state {i}");
    }
}

/// The ranges are validated like n_e and u_delta (finite, lo < hi, inside [0, 100] %), each
/// error naming the field; a parameter file whose `[input_saturation]` omits them (written
/// before session 39) takes the authors' ranges.
#[test]
fn the_command_ranges_are_validated_and_default_to_the_authors() {
    let text =
        mvem::params::PUBLISHED_TOML.replace("u_vgt = [20.0, 100.0]", "u_vgt = [60.0, 40.0]");
    assert_ne!(text, mvem::params::PUBLISHED_TOML);
    let e = mvem::io::params::parse_params(&text, std::path::Path::new("car.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(
            "input_saturation.u_vgt[2] = 40: the upper end of the range must exceed its lower end"
        ),
        "{e}"
    );
    let text = mvem::params::PUBLISHED_TOML.replace("u_egr = [0.0, 100.0]", "u_egr = [0.0, 120.0]");
    let e = mvem::io::params::parse_params(&text, std::path::Path::new("car.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("input_saturation.u_egr[2] = 120: must lie in [0, 100]"),
        "{e}"
    );
    // an older file: [input_saturation] with n_e and u_delta only
    let old = mvem::params::PUBLISHED_TOML
        .lines()
        .filter(|l| !l.starts_with("u_egr = [") && !l.starts_with("u_vgt = ["))
        .collect::<Vec<_>>()
        .join("\n");
    let p = mvem::io::params::parse_params(&old, std::path::Path::new("old.toml")).unwrap();
    assert_eq!(p.input_saturation.u_egr, [0.0, 100.0]);
    assert_eq!(p.input_saturation.u_vgt, [20.0, 100.0]);
    assert_eq!(p, Params::published());
}

/// An engine whose VGT is commanded 10-90 %: over the first 300 s of the closed-loop WHTC the
/// baseline's VGT command stays in [10, 90] % and reaches the closed end, 10 % (the authors'
/// range would stop it at 20 %); a tuning whose full-load VGT limit lies outside the range is
/// refused naming the field; the loop analyses along the run and at a point schedule the VGT
/// loops' gains on that range (at u_vgt = 15 %: 0.5 + 0.5 (15 - 10) / (40 - 10) of the gains,
/// not the authors' closed-end 0.5).
#[test]
fn the_closed_loop_and_its_margins_use_the_engines_vgt_range() {
    let p = with_vgt_range([10.0, 90.0]);
    let limits = p.input_saturation.clone();
    let m = AnyModel::new(ModelOrder::Eight, p, Default::default()).unwrap();
    let tuning = BaselineTuning::default();
    let run = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(tuning), Some(300.0)).unwrap();
    let u_vgt = run.traj.get("u_vgt").unwrap();
    let (lo, hi) = u_vgt
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    eprintln!("u_vgt {lo}..{hi}");
    assert!(lo >= 10.0 && hi <= 90.0, "u_vgt {lo}..{hi}");
    assert_eq!(lo, 10.0, "the closed end is reached");
    // the full-load limit must lie in the engine's range
    let curve = mvem::control::cycle::MappingCurve::compute(&m, Default::default()).unwrap();
    let narrow = AnyModel::new(
        ModelOrder::Eight,
        with_vgt_range([40.0, 100.0]),
        Default::default(),
    )
    .unwrap();
    let e = mvem::control::baseline::Baseline::new(&narrow, &curve, tuning)
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("u_vgt_full_load = 35: must be in [40, 100] %"),
        "{e}"
    );
    // the margins along the run: the loops of each analysed sample are scheduled on [10, 90]
    let points = along_trajectory(&m, &run.traj, &tuning, 20.0).unwrap();
    let mut analysed = 0;
    for pt in &points {
        if let Outcome::Analysed(a) = &pt.outcome {
            assert_eq!(
                a.loops,
                loops_in_charge(&tuning, pt.egr, pt.vgt, &pt.drive, &limits)
            );
            analysed += 1;
        }
    }
    assert!(analysed > 5, "{analysed}");
    // and at a point: the x_egr -> u_vgt gains at 15 %
    let d = Drive::new(1200.0, 60.0, 30.0, 15.0);
    let loops = baseline_loops(&tuning, &d, &limits);
    let g = 0.5 + 0.5 * 5.0 / 30.0;
    assert!((loops[1].kp - g * tuning.x_egr_vgt.0).abs() < 1e-12 * tuning.x_egr_vgt.0.abs());
    let authors = baseline_loops(&tuning, &d, &Params::published().input_saturation);
    assert!((authors[1].kp - 0.5 * tuning.x_egr_vgt.0).abs() < 1e-12 * tuning.x_egr_vgt.0.abs());
}
