//! Robustness ("never crash, never lie"):
//! - a CI-sized subset of the sweep of `examples/robustness.rs` (300 runs of 20 s, both
//!   integrators, seeded): no panic, no NaN/inf in any output sample, no invariant violation,
//!   every error located;
//! - failure honesty: absurd tolerances, parameters or start states give a located error (time,
//!   state dump, hint), never garbage; a failed write leaves no partial file;
//! - regression tests for the fuzzing findings (`fuzz/`).

use mvem::analysis::robustness::{
    error_is_located, scenario, start_state, sweep, StartBank, StartKind, SweepConfig,
};
use mvem::analysis::steady::{simulate_from_steady, SimFromSteadyError};
use mvem::components::Semantics;
use mvem::io::output::write_atomic;
use mvem::model::{Drive, Engine8, ModelOptions, ModelOrder};
use mvem::params::Params;
use mvem::sim::{simulate, InputSchedule, Method, SimError, SimOptions, Start};

/// The simulation error of a run from steady state (the steady state itself must succeed).
fn sim_err(e: SimFromSteadyError) -> SimError {
    match e {
        SimFromSteadyError::Sim(e) => e,
        e => panic!("no initial steady state: {e}"),
    }
}

#[test]
fn sweep_subset_is_clean() {
    let cfg = SweepConfig {
        runs: 300,
        seed: 7,
        t_end: 20.0,
        orders: vec![ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve],
        threads: 2,
        ..SweepConfig::default()
    };
    let r = sweep(&Params::published(), &cfg);
    println!("{r}");
    assert_eq!(r.runs, 300);
    assert!(r.panics.is_empty(), "panics: {:?}", r.panics);
    assert_eq!(r.nonfinite_samples, 0, "NaN/inf in output");
    assert!(r.violations.is_empty(), "violations: {:?}", r.violations);
    assert_eq!(r.unlocated_errors, 0);
    // the authors' model with its guards completes every run of this subset
    assert_eq!(r.completed, 300, "errors: {:?}", r.errors);
    // at least 20 s x 100 samples/s + 1 per run were checked
    assert!(r.samples >= 300 * 2001, "samples {}", r.samples);
    assert!(
        r.per_variant.len() >= 2,
        "both methods ran: {:?}",
        r.per_variant
    );
}

/// Scenarios are reproducible from (seed, run).
#[test]
fn scenarios_replay() {
    let m = [Method::Rosenbrock34, Method::Dopri5];
    let a = scenario(3, 17, 60.0, &m);
    let b = scenario(3, 17, 60.0, &m);
    assert_eq!(a.sched, b.sched);
    assert_eq!((a.input, a.start, a.method), (b.input, b.start, b.method));
    let c = scenario(3, 18, 60.0, &m);
    assert_ne!(a.sched, c.sched);
    // far start states lie inside the integrator limits, oxygen fractions within [0, X_Oc]
    let e = Engine8::published();
    let bank = StartBank::new(&e);
    assert!(bank.states.len() >= 8, "bank {}", bank.states.len());
    let mut r = a.rng.clone();
    for _ in 0..100 {
        let x = start_state(&e, &bank, StartKind::Far, &mut r);
        assert!(x[0] >= 0.5e5 && x[0] <= 10.0 * 101300.0, "{x:?}");
        assert!(x[2] >= 0.0 && x[2] <= 0.2314 && x[3] >= 0.0 && x[3] <= 0.2314);
    }
}

fn assert_located(e: &SimError) {
    let m = e.to_string();
    assert!(error_is_located(e), "not located: {m}");
    assert!(
        m.contains("p_im=") && m.contains("omega_t="),
        "state dump: {m}"
    );
}

/// Step-count exhaustion is reported with the time reached and the state.
#[test]
fn too_many_steps_is_located() {
    let m = Engine8::published();
    let sched =
        InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 30.0), &[(1.0, 3, 25.0)]).unwrap();
    let opts = SimOptions {
        rtol: 1e-12,
        atol: 1e-14,
        max_steps: 50,
        ..SimOptions::default()
    };
    let e = sim_err(simulate_from_steady(&m, &sched, 0.0, 8.0, &opts).unwrap_err());
    assert!(matches!(e, SimError::TooManySteps { max_steps: 50, t, .. } if t > 0.0 && t < 8.0));
    assert_located(&e);
}

/// Absurd tolerances are rejected before integration, naming the option.
/// QA: a horizon of 1e300 s (with an output interval that keeps the grid small) ran for
/// minutes before failing. Times beyond MAX_TIME and output grids beyond MAX_ROWS are refused
/// before any step, naming the value, through every entry: the simulation, a restartable
/// integrator (the FMU's fmi2DoStep) and the plant stepper.
#[test]
fn absurd_horizons_are_refused_up_front() {
    use mvem::model::Dynamics;
    use mvem::sim::{stepper::Plant, Integrator, Solution, MAX_TIME};
    let m = Engine8::published();
    let d = Drive::new(1500.0, 110.0, 80.0, 30.0);
    let sched = InputSchedule::constant(d);
    let coarse = SimOptions {
        dt_out: 1e299,
        ..SimOptions::default()
    };
    let start = std::time::Instant::now();
    let e = sim_err(simulate_from_steady(&m, &sched, 0.0, 1e300, &coarse).unwrap_err());
    assert!(matches!(e, SimError::BadHorizon { .. }), "{e}");
    assert!(
        e.to_string()
            .starts_with("end time 1e300 s is beyond the 1e9 s"),
        "{e}"
    );
    let e = sim_err(simulate_from_steady(&m, &sched, -2e9, 1.0, &coarse).unwrap_err());
    assert!(
        e.to_string()
            .starts_with("start time -2000000000 s is beyond"),
        "{e}"
    );
    // within MAX_TIME but 1e10 output samples
    let e =
        sim_err(simulate_from_steady(&m, &sched, 0.0, 1e8, &SimOptions::default()).unwrap_err());
    assert!(
        e.to_string()
            .starts_with("output interval 0.01 s: 1.000e10 output samples from 0 s to 100000000 s"),
        "{e}"
    );
    // the restartable integrator (the FMU's fmi2DoStep)
    let x = mvem::analysis::steady::steady_state(&m, &d).unwrap().x;
    let mut run = Integrator::new(&m, &sched, 0.0, x, &coarse).unwrap();
    let mut sol = Solution::new(&m.state_names());
    let e = run.advance(2.0 * MAX_TIME, &mut sol, false).unwrap_err();
    assert!(matches!(e, SimError::BadHorizon { .. }), "{e}");
    // the plant stepper: steps of at most 1e6 s, up to MAX_TIME
    let mut p = Plant::from_state(m.clone(), d, MAX_TIME - 1.0, x, &SimOptions::default()).unwrap();
    let e = p.step(2.0, d).unwrap_err();
    assert!(matches!(e, SimError::BadHorizon { .. }), "{e}");
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
    // a long horizon within the limits runs (a few steps at steady state)
    let sol = simulate_from_steady(
        &m,
        &sched,
        0.0,
        1e9,
        &SimOptions {
            dt_out: 1e8,
            ..coarse
        },
    )
    .unwrap();
    assert_eq!(sol.t().len(), 11);
}

#[test]
fn absurd_options_are_rejected() {
    let m = Engine8::published();
    let sched = InputSchedule::constant(Drive::new(1500.0, 110.0, 80.0, 30.0));
    for (opts, field) in [
        (
            SimOptions {
                rtol: 1e-16,
                ..SimOptions::default()
            },
            "rtol",
        ),
        (
            SimOptions {
                atol: f64::NAN,
                ..SimOptions::default()
            },
            "atol",
        ),
        (
            SimOptions {
                dt_out: 0.0,
                ..SimOptions::default()
            },
            "dt",
        ),
    ] {
        let e = sim_err(simulate_from_steady(&m, &sched, 0.0, 1.0, &opts).unwrap_err());
        assert!(
            matches!(e, SimError::BadOption { field: f, .. } if f == field),
            "{e}"
        );
    }
    let e = sim_err(
        simulate_from_steady(&m, &sched, 0.0, f64::NAN, &SimOptions::default()).unwrap_err(),
    );
    assert!(matches!(e, SimError::BadInterval { .. }), "{e}");
    let mut x = mvem::analysis::steady::steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 30.0))
        .unwrap()
        .x;
    x[4] = f64::INFINITY;
    let e = simulate(
        &m,
        &sched,
        0.0,
        1.0,
        Start::State(x),
        &SimOptions::default(),
    )
    .unwrap_err();
    assert!(
        matches!(&e, SimError::NonFinite { name, t, .. } if name == "omega_t" && *t == 0.0),
        "{e}"
    );
    assert_located(&e);
}

/// The paper's plain equations have no guards: driven far outside their range from a far-off
/// state they leave the domain (negative pressure ratio under a fractional power). The solver
/// must stop with a located error, or complete with finite output -- never return NaN.
#[test]
fn paper_semantics_far_off_fails_cleanly() {
    let opts = ModelOptions {
        semantics: Semantics::Paper,
        ..ModelOptions::default()
    };
    let m = Engine8::new(Params::published(), opts).unwrap();
    let sched = InputSchedule::steps(
        Drive::new(2500.0, 300.0, 120.0, -20.0),
        &[(0.5, 1, 0.0), (1.0, 0, 300.0)],
    )
    .unwrap();
    let x0 = [0.3e5, 25.0e5, 0.23, 0.0, 200.0, 120.0, 120.0, -20.0];
    let mut failed = 0;
    for method in [Method::Rosenbrock34, Method::Dopri5] {
        let o = SimOptions {
            method,
            ..SimOptions::default()
        };
        match simulate(&m, &sched, 0.0, 3.0, Start::State(x0), &o) {
            Ok(sol) => {
                for c in &sol.columns {
                    assert!(c.iter().all(|v| v.is_finite()), "{method:?}: NaN in output");
                }
            }
            Err(e) => {
                failed += 1;
                assert_located(&e);
            }
        }
    }
    // at least one method hits the domain boundary (documented in docs/robustness.md)
    assert!(failed >= 1);
}

/// The paper's compressor efficiency takes (Pi_c - 1)^c_pi (eq. (64)): at idle (the WHTC's first
/// point, 500 rpm and 1 mg) the settling run reaches p_im < p_amb, and the error names the
/// signals that are not finite there (docs/authors-implementation.md, "Where the paper's plain
/// equations have no operating point").
#[test]
fn paper_semantics_at_idle_names_the_nonfinite_signals() {
    let opts = ModelOptions {
        semantics: Semantics::Paper,
        ..ModelOptions::default()
    };
    let m = Engine8::new(Params::published(), opts).unwrap();
    let sched = InputSchedule::constant(Drive::new(500.0, 1.0, 50.0, 65.0));
    let x0 = [
        1.011113e5, 1.025627e5, 0.2313534, 0.2299631, 311.9571, 50.0, 50.0, 65.0,
    ];
    let e = simulate(
        &m,
        &sched,
        0.0,
        1.0,
        Start::State(x0),
        &SimOptions::default(),
    )
    .unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(&e, SimError::NonFinite { name, hint, .. }
            if name == "omega_t" && hint.starts_with("non-finite signals: T_c, eta_c, P_c; ")),
        "{msg}"
    );
    assert!(
        msg.contains("Hint: non-finite signals: T_c, eta_c, P_c; the paper's"),
        "{msg}"
    );
    // the authors' implementation limits Pi_c >= 1 there (item 24) and runs on
    let m = Engine8::new(Params::published(), ModelOptions::default()).unwrap();
    let sol = simulate(
        &m,
        &sched,
        0.0,
        1.0,
        Start::State(x0),
        &SimOptions::default(),
    )
    .unwrap();
    assert!(sol.columns.iter().all(|c| c.iter().all(|v| v.is_finite())));
}

/// Absurd parameters that still validate (a 1000x too light turbo) either integrate to finite
/// output or stop with a located error.
#[test]
fn absurd_parameters_fail_cleanly() {
    let mut p = Params::published();
    p.turbo.j_t *= 1e-3;
    p.intake_manifold.v_im *= 1e-3;
    let m = Engine8::new(p, ModelOptions::default()).unwrap();
    let sched = InputSchedule::steps(
        Drive::new(1500.0, 250.0, 0.0, 20.0),
        &[(0.2, 1, 0.0), (0.4, 3, 100.0)],
    )
    .unwrap();
    let x0 = [1.0e5, 1.2e5, 0.2, 0.1, 5000.0, 0.0, 0.0, 20.0];
    for method in [Method::Rosenbrock34, Method::Dopri5] {
        let o = SimOptions {
            method,
            max_steps: 200_000,
            ..SimOptions::default()
        };
        match simulate(&m, &sched, 0.0, 1.0, Start::State(x0), &o) {
            Ok(sol) => {
                for c in &sol.columns {
                    assert!(c.iter().all(|v| v.is_finite()), "{method:?}: NaN in output");
                }
            }
            Err(e) => assert_located(&e),
        }
    }
}

/// A failed write never leaves a partial file or a temporary file, and never replaces an
/// existing file; a failed simulation has no output to write (the front ends write only
/// `Ok` solutions, through `write_atomic`).
#[test]
fn failed_write_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    // target is a directory: the rename fails
    let target = dir.path().join("out.csv");
    std::fs::create_dir(&target).unwrap();
    std::fs::write(target.join("keep"), b"x").unwrap();
    assert!(write_atomic(&target, b"a,b\n1,2\n").is_err());
    assert!(target.is_dir() && target.join("keep").exists());
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    assert_eq!(
        names,
        vec!["out.csv".to_string()],
        "leftover temporary file"
    );
    // missing directory: error naming the file, nothing created
    let missing = dir.path().join("no/such/dir/out.csv");
    let e = write_atomic(&missing, b"x").unwrap_err();
    assert!(e.to_string().contains("out.csv"), "{e}");
    assert!(!missing.exists());
}

/// Every integration failure gives a hint, `TooManySteps` included.
#[test]
fn too_many_steps_has_a_hint() {
    let m = Engine8::published();
    let sched =
        InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 30.0), &[(1.0, 3, 25.0)]).unwrap();
    let opts = SimOptions {
        max_steps: 50,
        ..SimOptions::default()
    };
    let e = sim_err(simulate_from_steady(&m, &sched, 0.0, 8.0, &opts).unwrap_err());
    assert!(matches!(e, SimError::TooManySteps { .. }), "{e}");
    assert!(e.to_string().contains("Hint:"), "no hint: {e}");
}

/// The analysis calls (steady, linearize, map) at 40 random points of the whole input box
/// (n_e -500..2500 rpm with 0, -100 and 1e-9 rpm drawn often) under both semantics, each call
/// on a worker thread with a 60 s limit (they take milliseconds to seconds): no hang, no panic, no NaN/inf
/// in any result; under the paper's semantics every point with n_e <= 0 is an error naming n_e.
#[test]
fn analysis_calls_never_hang_panic_or_return_nan() {
    use mvem::analysis::robustness_analysis::{
        analysis_point, analysis_sweep, AnalysisSweepConfig, Call,
    };
    let cfg = AnalysisSweepConfig {
        points: 40,
        orders: vec![mvem::model::ModelOrder::Eight],
        timeout: std::time::Duration::from_secs(60),
        ..AnalysisSweepConfig::default()
    };
    let r = analysis_sweep(&mvem::params::Params::published(), &cfg);
    eprintln!("{r}");
    assert!(r.clean(), "{r}");
    let [calls, ok, errors, ..] = r.totals();
    assert_eq!(calls, 40 * 3 * 2);
    assert!(ok > 0 && errors > 0, "{r}");
    let nonpositive = (0..40)
        .filter(|&k| analysis_point(1, k).n_e_rpm <= 0.0)
        .count() as u64;
    assert!(nonpositive >= 3, "the sweep must include n_e <= 0");
    for call in Call::ALL {
        let c = &r.counts[&(8, "paper", call)];
        let n_e_errors: u64 = c
            .error_kinds
            .iter()
            .filter(|(msg, _)| msg.contains("n_e"))
            .map(|(_, (n, _))| *n)
            .sum();
        assert!(n_e_errors >= nonpositive, "{call:?}: {r}");
    }
}
