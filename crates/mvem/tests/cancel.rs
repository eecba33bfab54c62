//! Cancelling simulations (`mvem::numerics::cancel`): the integrator polls the token of the
//! thread that created it before every trial step and stops with `SimError::Cancelled`, naming
//! the time and the state reached. Checked for one run (a token cancelled before the run and one
//! cancelled from another thread during it), a run in time chunks on several threads, an
//! ensemble, and a run without a token (never cancelled).

use mvem::analysis::ensemble::{simulate_many, Case};
use mvem::analysis::steady::{simulate_from_steady, steady_state, SimFromSteadyError, SteadyError};
use mvem::model::{AnyModel, Engine8, ModelOptions, ModelOrder};
use mvem::numerics::cancel::{with_token, CancelToken};
use mvem::params::Params;
use mvem::sim::{simulate, InputSchedule, SimError, SimOptions, Solution, Start};
use std::time::Duration;

fn whtc() -> InputSchedule {
    let text = include_str!("../../../data/whtc_inputs_10hz.csv");
    mvem::io::csv_inputs::parse_inputs_csv(text, std::path::Path::new("whtc")).unwrap()
}

/// A slow run: the whole WHTC at rtol 1e-10 (about 20 times the default run's work).
fn tight(chunks: usize) -> SimOptions {
    SimOptions {
        rtol: 1e-10,
        atol: 1e-10,
        dt_out: 0.1,
        time_chunks: chunks,
        ..SimOptions::default()
    }
}

fn model() -> Engine8 {
    Engine8::new(Params::published(), ModelOptions::default()).unwrap()
}

/// The run `simulate_from_steady(WHTC, opts)` with `token`, cancelled `after` it starts (None:
/// before it starts).
fn run_cancelled(opts: &SimOptions, after: Option<Duration>) -> SimFromSteadyError {
    let (m, sched) = (model(), whtc());
    let token = CancelToken::new();
    if after.is_none() {
        token.cancel();
    }
    std::thread::scope(|s| {
        if let Some(d) = after {
            let t = token.clone();
            s.spawn(move || {
                std::thread::sleep(d);
                t.cancel();
            });
        }
        with_token(&token, || {
            refused(simulate_from_steady(&m, &sched, 0.0, 1800.0, opts))
        })
    })
}

/// The error of a run that should have failed (the solution is not printed: it is large).
fn refused<E>(r: Result<Solution, E>) -> E {
    match r {
        Ok(sol) => panic!(
            "the run was not cancelled: it reached t = {:?}",
            sol.t().last()
        ),
        Err(e) => e,
    }
}

fn cancelled_at(e: &SimFromSteadyError) -> f64 {
    match e {
        SimFromSteadyError::Sim(SimError::Cancelled { t, state }) => {
            assert_eq!(state.0.len(), 8, "{e}");
            assert!(state.0.iter().all(|(_, v)| v.is_finite()), "{e}");
            let msg = e.to_string();
            assert!(
                msg.contains("cancelled at t = ") && msg.contains("state: [p_im="),
                "{msg}"
            );
            *t
        }
        other => panic!("expected SimError::Cancelled, got {other}"),
    }
}

#[test]
fn a_cancelled_token_stops_the_run_before_its_first_step() {
    // from a given state: the integration stops at its start
    let (m, sched) = (model(), whtc());
    let x0 = steady_state(&m, &sched.at(0.0)).unwrap().x;
    let token = CancelToken::new();
    token.cancel();
    let e = with_token(&token, || {
        refused(simulate(
            &m,
            &sched,
            0.0,
            1800.0,
            Start::State(x0),
            &tight(1),
        ))
    });
    assert_eq!(cancelled_at(&SimFromSteadyError::Sim(e)), 0.0);
    // from the steady state: the settling simulation of the steady-state search is cancelled,
    // reported as a cancellation (not as an equilibrium that was not found)
    match run_cancelled(&tight(1), None) {
        SimFromSteadyError::Steady(e @ SteadyError::Cancelled { .. }) => {
            assert!(
                e.to_string()
                    .starts_with("cancelled while settling at n_e=500 rpm"),
                "{e}"
            );
        }
        other => panic!("expected SteadyError::Cancelled, got {other}"),
    }
}

#[test]
fn a_run_cancelled_from_another_thread_stops_where_it_is() {
    // the sequential run takes seconds at rtol 1e-10; 50 ms in it is far from the end
    let t = cancelled_at(&run_cancelled(&tight(1), Some(Duration::from_millis(50))));
    assert!(t > 0.0 && t < 1800.0, "stopped at t = {t}");
}

#[test]
fn a_run_in_time_chunks_is_cancelled_on_every_thread() {
    // chunk 0 runs on the calling thread, the others on their own: all carry the token, so the
    // call returns the first chunk's cancellation (the others stop too, or it would wait)
    let e = run_cancelled(&tight(2), Some(Duration::from_millis(50)));
    let t = cancelled_at(&e);
    assert!(t > 0.0 && t < 1800.0, "stopped at t = {t}");
}

#[test]
fn the_runs_of_an_ensemble_stop_inside_the_run() {
    let m = AnyModel::new(
        ModelOrder::Eight,
        Params::published(),
        ModelOptions::default(),
    )
    .unwrap();
    let cases: Vec<Case> = (0..2)
        .map(|_| Case {
            model: m.clone(),
            inputs: whtc(),
            t_end: None,
            start: None,
        })
        .collect();
    let token = CancelToken::new();
    let out = std::thread::scope(|s| {
        let t = token.clone();
        s.spawn(move || {
            std::thread::sleep(Duration::from_millis(50));
            t.cancel();
        });
        with_token(&token, || simulate_many(&cases, &tight(1), 2)).unwrap()
    });
    // both runs had started (two threads for two cases): each stops inside its integration
    for r in &out {
        let e = match r {
            Ok(_) => panic!("a run of the ensemble was not cancelled"),
            Err(e) => &e.error,
        };
        let t = cancelled_at(e);
        assert!(t > 0.0 && t < 1800.0, "stopped at t = {t}");
    }
}

#[test]
fn without_a_token_nothing_is_cancelled() {
    // a cancelled token on another thread does not reach this one
    let token = CancelToken::new();
    token.cancel();
    let (m, sched) = (model(), whtc());
    let sol = simulate_from_steady(&m, &sched, 0.0, 20.0, &SimOptions::default()).unwrap();
    assert_eq!(sol.t().last().copied(), Some(20.0));
}
