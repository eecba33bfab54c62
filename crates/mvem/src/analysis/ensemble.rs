//! Ensembles: many simulations at once (parameter or input variations) on all cores.
//!
//! [`simulate_many`] runs every [`Case`] (a model with its parameters, an input schedule, an end
//! time) from the steady state at its first inputs, as [`simulate_from_steady`], or from its
//! given start state, one case per task on a rayon thread pool. The runs are independent: one that fails (no initial
//! equilibrium, a solver failure) gives a [`RunError`] naming its index in its own slot and the
//! others go on. Results come back in the order of the cases. A caller that cancels
//! ([`crate::numerics::cancel`]) gets the runs not yet started as
//! [`SimFromSteadyError::Cancelled`].
//!
//! The runs share nothing but the read-only options, so on a machine with k idle cores k runs
//! take about as long as one (`mvem bench --ensemble 8` measures the scaling; `docs/python.md`
//! and the README give the numbers).

use super::steady::{chunk_guess, simulate_from_steady, SimFromSteadyError};
use crate::model::{AnyModel, Model};
use crate::sim::{simulate_with_guess, InputSchedule, SimOptions, Solution, Start};
use rayon::prelude::*;

/// One run of an ensemble.
#[derive(Debug, Clone)]
pub struct Case {
    /// The model: variant (8/10/12 states), parameters and options.
    pub model: AnyModel,
    /// The inputs; the run starts at the first row's time in the steady state of its inputs.
    pub inputs: InputSchedule,
    /// End time \[s\] (`None`: the last input time).
    pub t_end: Option<f64>,
    /// The state at the first input time, in the model's state order (`None`: the steady state
    /// of the first inputs). The commands before the first row are that row's.
    pub start: Option<Vec<f64>>,
}

/// A failed run of an ensemble: its index in the cases and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("run {index}: {error}")]
pub struct RunError {
    /// 0-based index of the case.
    pub index: usize,
    /// What failed.
    pub error: SimFromSteadyError,
}

/// The ensemble could not start (the worker threads).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("cannot start {threads} worker threads: {reason}")]
pub struct PoolError {
    /// Threads asked for.
    pub threads: usize,
    /// The system's reason.
    pub reason: String,
}

/// Run `f` on a pool of `threads` worker threads (0: rayon's global pool, one thread per core).
pub(crate) fn in_pool<T: Send>(
    threads: usize,
    f: impl FnOnce() -> T + Send,
) -> Result<T, PoolError> {
    if threads == 0 {
        return Ok(f());
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| PoolError {
            threads,
            reason: e.to_string(),
        })?;
    Ok(pool.install(f))
}

/// Simulate every case with `opts` on `threads` worker threads (0: one per core); see the
/// module documentation. The outer error is the thread pool's, the inner ones the runs'.
pub fn simulate_many(
    cases: &[Case],
    opts: &SimOptions,
    threads: usize,
) -> Result<Vec<Result<Solution, RunError>>, PoolError> {
    // the caller's cancellation token, polled by the workers before each run
    let cancel = crate::numerics::cancel::current();
    // (taken here: `in_pool` runs its closure on a worker of the pool, without the token)
    let run = crate::numerics::cancel::carry(|(index, c): (usize, &Case)| {
        if cancel.as_ref().is_some_and(|t| t.is_cancelled()) {
            return Err(RunError {
                index,
                error: SimFromSteadyError::Cancelled,
            });
        }
        let t0 = c.inputs.t_first();
        let t_end = c.t_end.unwrap_or(c.inputs.t_last());
        // (the run's integrator polls the carried token too: a long run stops within
        // one step)
        crate::dispatch!(&c.model, m => run_case(m, c, t0, t_end, opts))
            .map_err(|error| RunError { index, error })
    });
    in_pool(threads, || cases.par_iter().enumerate().map(&run).collect())
}

/// One case from its start state or the steady state at its first inputs.
fn run_case<const N: usize, M: Model<N>>(
    m: &M,
    c: &Case,
    t0: f64,
    t_end: f64,
    opts: &SimOptions,
) -> Result<Solution, SimFromSteadyError> {
    match &c.start {
        None => simulate_from_steady(m, &c.inputs, t0, t_end, opts),
        Some(v) => {
            let x: [f64; N] =
                v.as_slice()
                    .try_into()
                    .map_err(|_| SimFromSteadyError::StartLength {
                        expected: N,
                        got: v.len(),
                    })?;
            let guess = chunk_guess(m, &c.inputs);
            Ok(simulate_with_guess(
                m,
                &c.inputs,
                t0,
                t_end,
                Start::State(x),
                opts,
                Some(&guess),
            )?)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Drive, ModelOrder};
    use crate::params::Params;
    use crate::sim::SimError;

    fn case(u_vgt_to: f64, j_t: f64) -> Case {
        let mut p = Params::published();
        p.turbo.j_t = j_t;
        Case {
            model: AnyModel::new(ModelOrder::Eight, p, Default::default()).unwrap(),
            inputs: InputSchedule::steps(
                Drive::new(1500.0, 110.0, 80.0, 75.0),
                &[(1.0, 3, u_vgt_to)],
            )
            .unwrap(),
            t_end: Some(3.0),
            start: None,
        }
    }

    #[test]
    fn runs_equal_single_simulations_in_order_and_a_failure_stays_in_its_slot() {
        let j_t = Params::published().turbo.j_t;
        let mut cases = vec![case(65.0, j_t), case(60.0, 2.0 * j_t), case(70.0, j_t)];
        // run 1 ends before it starts: its own error, the others run
        cases[1].t_end = Some(-1.0);
        let opts = SimOptions::default();
        let out = simulate_many(&cases, &opts, 2).unwrap();
        assert_eq!(out.len(), 3);
        for i in [0, 2] {
            let c = &cases[i];
            let single = crate::dispatch!(&c.model, m => simulate_from_steady(m, &c.inputs, 0.0, 3.0, &opts))
                .unwrap();
            let many = out[i].as_ref().unwrap();
            // the same computation on another thread: bit-identical
            assert_eq!(many.columns, single.columns, "run {i}");
        }
        let e = out[1].as_ref().unwrap_err();
        assert_eq!(e.index, 1);
        assert!(matches!(
            e.error,
            SimFromSteadyError::Sim(SimError::BadInterval { .. })
        ));
        assert!(e.to_string().starts_with("run 1: end time -1 s"), "{e}");
        // the parameter variation changed the response (the runs are not copies)
        let w = |i: usize| *out[i].as_ref().unwrap().get("W_c").unwrap().last().unwrap();
        assert!((w(0) - w(2)).abs() > 1e-4, "{} {}", w(0), w(2));
    }

    /// A case with a start state: from the steady state it is the default run to the bit;
    /// from another state the run starts there; a start of the wrong length is that run's error.
    #[test]
    fn a_case_starts_from_its_given_state() {
        use crate::analysis::steady::steady_state;
        let j_t = Params::published().turbo.j_t;
        let opts = SimOptions::default();
        let x_ss = steady_state(
            &crate::model::Engine8::published(),
            &Drive::new(1500.0, 110.0, 80.0, 75.0),
        )
        .unwrap()
        .x;
        let mut cases = vec![
            case(65.0, j_t),
            case(65.0, j_t),
            case(65.0, j_t),
            case(65.0, j_t),
        ];
        cases[1].start = Some(x_ss.to_vec());
        let mut x1 = x_ss;
        x1[0] *= 1.1;
        cases[2].start = Some(x1.to_vec());
        cases[3].start = Some(vec![1.0; 7]);
        let out = simulate_many(&cases, &opts, 2).unwrap();
        let p_im = |i: usize| out[i].as_ref().unwrap().get("p_im").unwrap().to_vec();
        assert_eq!(p_im(1), p_im(0));
        assert_eq!(p_im(2)[0], x1[0]);
        assert!((p_im(2)[10] - p_im(0)[10]).abs() > 1e3);
        let e = out[3].as_ref().unwrap_err();
        assert!(matches!(
            e.error,
            SimFromSteadyError::StartLength {
                expected: 8,
                got: 7
            }
        ));
        assert!(e.to_string().contains("expected 8 values"), "{e}");
    }

    #[test]
    fn a_cancelled_ensemble_reports_the_runs_it_did_not_start() {
        use crate::numerics::cancel::{with_token, CancelToken};
        let cases: Vec<Case> = (0..4).map(|k| case(60.0 + k as f64, 0.1)).collect();
        let opts = SimOptions::default();
        let token = CancelToken::new();
        let sols = with_token(&token, || simulate_many(&cases, &opts, 2)).unwrap();
        assert!(sols.iter().all(Result::is_ok));
        token.cancel();
        let sols = with_token(&token, || simulate_many(&cases, &opts, 2)).unwrap();
        for (i, s) in sols.iter().enumerate() {
            assert_eq!(
                s.as_ref().unwrap_err(),
                &RunError {
                    index: i,
                    error: SimFromSteadyError::Cancelled
                }
            );
        }
        // the token is the caller's: outside its scope the ensemble runs
        assert!(simulate_many(&cases, &opts, 2)
            .unwrap()
            .iter()
            .all(Result::is_ok));
    }
}
