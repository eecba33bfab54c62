//! Simulation: input schedules, exact transport delays, adaptive error-controlled integration.
//!
//! Two integrators, chosen by measurement (`docs/integrator.md`): the default Rosenbrock-W
//! method ROS34PW2 ([`Method::Rosenbrock34`], order 3(2), L-stable, lagged finite-difference
//! Jacobian) and the explicit Dormand-Prince 5(4) pair ([`Method::Dopri5`], 4th-order dense
//! output). The 8-state model is mildly stiff (fastest poles about -116 1/s at idle, median
//! -72 1/s along the WHTC), so the explicit pair is stability-limited; the W-method is not, and
//! takes far fewer steps on smooth stretches. A third, the Rosenbrock method RODAS4
//! ([`Method::Rodas4`], order 4(3), fresh Jacobian and input-slope time derivative every step),
//! is more accurate per tolerance but measured no cheaper on the drive cycle; so is the
//! exponential Rosenbrock method exprb32 ([`Method::Exprb32`], order 3(2), the linearized
//! dynamics integrated exactly through phi functions of h J; twice the instructions of ROS34PW2
//! at equal accuracy on the WHTC).
//!
//! The transport delays ([`Dynamics::input_delays`]) act on known input functions, so they are
//! exact: the delayed command is the schedule evaluated at `t - tau` (constant history before
//! the first row). The integrator never steps over an input change: the time axis is split at
//! every breakpoint of every channel (jumps and kinks), shifted by the delay of each channel that
//! feeds a delay, and each segment is integrated with the inputs evaluated strictly inside the
//! segment, so a step on either side of a jump sees one smooth input.
//!
//! The actuator states ([`Dynamics::linear_lags`]) are first-order lags of those delayed commands;
//! on a segment the command is piecewise linear, so by default they are integrated in closed form
//! there and the W-method integrates the other states only ([`SimOptions::exact_actuators`],
//! `docs/integrator.md`). The delayed commands drive nothing else, so their breakpoints need not
//! be stop times: with [`SimOptions::stop_at_lag_breakpoints`] off (the plant stepper's default,
//! [`stepper::plant_options`]) a step runs across them and the closed form follows the command
//! piece by piece inside the step.
//!
//! The simulator depends on [`crate::model`] only, through the [`Dynamics`] trait (names, scales,
//! bounds, derivatives, output signals, input delays, lag states, the opaque [`Dynamics::Memory`]);
//! it reads no parameter and names no component. Starting at a steady state is a convenience
//! one layer up (`simulate_from_steady`, next to the steady-state solver).
//!
//! Files: `options` ([`SimOptions`], [`Method`]), `error` ([`SimError`]), `solution`
//! ([`Solution`], [`SimStats`]), `segment` ([`SegmentInputs`], [`stop_times`]), `integrator`
//! (the restartable [`Integrator`]: step control, segments, dense output, closed-form lags),
//! `rosw`, `rodas`, `exprb` and `dopri5` (each method's tableau and trial step), [`input`] (schedules),
//! `chunks` (time-parallel chunks of one open-loop run, [`SimOptions::time_chunks`]).

mod chunks;
mod differences;
mod dopri5;
mod error;
mod exprb;
pub mod input;
mod integrator;
mod options;
mod rodas;
mod rosw;
mod segment;
mod solution;
pub mod stepper;

pub use chunks::{split_times, ChunkGuess, JUNCTION_TOL};
pub use error::{SimError, StateDump};
pub use input::{BreakKind, InputSchedule, ScheduleError, Side};
pub use integrator::Integrator;
pub use options::{Method, SimOptions, MAX_TIME_CHUNKS};
pub use segment::{stop_times, SegmentInputs};
pub use solution::{Block, Junction, SignalEvaluator, SimStats, Solution, MAX_ROWS};

use crate::model::Dynamics;

/// Where the simulation starts (the steady-state start is `simulate_from_steady`, one layer up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start<const N: usize> {
    /// A given state (clipped into the integrator limits of the authors' implementation).
    State([f64; N]),
}

/// Simulate `model` driven by `sched` from `t0` to `t_end`.
///
/// The result has an output sample every `opts.dt_out` from `t0` and at `t_end`. Output samples
/// at an input step show the value after the step (inputs are right-continuous).
pub fn simulate<const N: usize, M: Dynamics<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    start: Start<N>,
    opts: &SimOptions,
) -> Result<Solution, SimError> {
    simulate_with_guess(model, sched, t0, t_end, start, opts, None)
}

/// [`simulate`] writing its samples to `sol`, an empty solution of `model`'s states (e.g. a
/// [`Solution::streaming`] one, whose blocks a writer consumes while the integration goes on),
/// returned with the statistics. On success a streaming solution's last block is sent and its
/// sender dropped ([`Solution::finish_stream`]); on failure `sol` is dropped with its sender,
/// so in both cases a receiver reading until the channel closes ends.
pub fn simulate_into<const N: usize, M: Dynamics<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    start: Start<N>,
    opts: &SimOptions,
    sol: Solution,
) -> Result<Solution, SimError> {
    simulate_into_with_guess(model, sched, t0, t_end, start, opts, sol, None)
}

/// [`simulate`] with a guess of the state at a time for the time-parallel chunks
/// ([`SimOptions::time_chunks`] > 1; e.g. the steady state at the inputs there,
/// `analysis::steady::chunk_guess`). Without a guess, or where it returns `None`, a chunk
/// starts its warm-up from the initial state. The guess changes only how fast a chunk's
/// warm-up converges, never the result's correctness (a chunk that does not meet its
/// predecessor within [`JUNCTION_TOL`] is integrated again sequentially).
pub fn simulate_with_guess<const N: usize, M: Dynamics<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    start: Start<N>,
    opts: &SimOptions,
    guess: Option<&ChunkGuess<N>>,
) -> Result<Solution, SimError> {
    // (the interval is checked once, by simulate_into_with_guess, before any work)
    let sol = Solution::new(&model.state_names());
    simulate_into_with_guess(model, sched, t0, t_end, start, opts, sol, guess)
}

/// [`simulate_into`] with a guess for the time-parallel chunks (see [`simulate_with_guess`]).
/// With [`SimOptions::time_chunks`] > 1 the samples of chunk 0 reach `sol` (and its receiver)
/// while it is integrated, those of the other chunks after their junction is verified.
#[allow(clippy::too_many_arguments)]
pub fn simulate_into_with_guess<const N: usize, M: Dynamics<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    start: Start<N>,
    opts: &SimOptions,
    sol: Solution,
    guess: Option<&ChunkGuess<N>>,
) -> Result<Solution, SimError> {
    check_interval(opts, t0, t_end)?;
    simulate_checked(model, sched, t0, t_end, start, opts, sol, guess)
}

/// [`simulate_into_with_guess`] after [`check_interval`] accepted the options and the interval,
/// so that a simulation checks them once (`analysis::steady::simulate_from_steady` checks them
/// before it solves the steady start, then runs this).
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate_checked<const N: usize, M: Dynamics<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    start: Start<N>,
    opts: &SimOptions,
    mut sol: Solution,
    guess: Option<&ChunkGuess<N>>,
) -> Result<Solution, SimError> {
    if !sol.is_streaming() {
        // a solution that keeps every sample: room for all of them (a streaming one holds a block)
        let samples = ((t_end - t0) / opts.dt_out).ceil() + 2.0;
        sol.reserve(samples.min(1e7) as usize);
    }
    let Start::State(y0) = start;
    if opts.time_chunks > 1 {
        return chunks::simulate_chunked(model, sched, t0, t_end, y0, opts, sol, guess);
    }
    let mut run = Integrator::new(model, sched, t0, y0, opts)?;
    // (the interval was checked: not again for the integrator's one call)
    run.advance_checked(t_end, &mut sol, true)?;
    sol.stats = run.stats;
    sol.finish_stream();
    Ok(sol)
}

/// The largest time magnitude a simulation accepts \[s\] (about 31.7 years): at 1e9 s doubles
/// are 1.2e-7 s apart, far below the actuator delays and the integrator's smallest steps; far
/// beyond it the time axis no longer resolves them, and a horizon of 1e300 s ran for minutes
/// before failing (QA). [`check_interval`] and [`Integrator::advance`] refuse later times.
pub const MAX_TIME: f64 = 1e9;

/// Check the options and the interval `[t0, t_end]` of a simulation (before any other work, so
/// that a caller computing a start state first reports bad options first): both times finite
/// and within [`MAX_TIME`], `t_end` after `t0`, and at most [`MAX_ROWS`] output samples every
/// `opts.dt_out` ([`check_horizon`]).
pub fn check_interval(opts: &SimOptions, t0: f64, t_end: f64) -> Result<(), SimError> {
    opts.validate()?;
    if !(t0.is_finite() && t_end.is_finite() && t_end > t0) {
        return Err(SimError::BadInterval { t0, t_end });
    }
    check_horizon(t0, t_end, opts.dt_out)
}

/// Refuse an interval `[t0, t_end]` (finite, ordered) with a time beyond [`MAX_TIME`] in
/// magnitude, or with more than [`MAX_ROWS`] output samples every `dt_out` seconds, naming the
/// values and the limit.
pub fn check_horizon(t0: f64, t_end: f64, dt_out: f64) -> Result<(), SimError> {
    #[cfg(test)]
    tests::HORIZON_CHECKS.with(|n| n.set(n.get() + 1));
    let num = crate::numerics::Num;
    if let Some((name, t)) = [("start time", t0), ("end time", t_end)]
        .into_iter()
        .find(|(_, t)| t.abs() > MAX_TIME)
    {
        return Err(SimError::BadHorizon {
            t0,
            t_end,
            message: format!(
                "{name} {} s is beyond the {MAX_TIME:e} s (about 31.7 years) a simulation \
                 accepts (times must resolve the actuator delays and the integrator's steps)",
                num(t)
            ),
        });
    }
    let samples = (t_end - t0) / dt_out;
    if samples > MAX_ROWS {
        return Err(SimError::BadHorizon {
            t0,
            t_end,
            message: format!(
                "output interval {} s: {samples:.3e} output samples from {} s to {} s, more \
                 than the {MAX_ROWS:e} a simulation may produce; use a larger output interval \
                 or a shorter horizon",
                num(dt_out),
                num(t0),
                num(t_end)
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::steady::{simulate_from_steady, simulate_from_steady_into};
    use crate::model::{Drive, Engine8};
    use std::cell::Cell;

    thread_local! {
        /// Calls of [`check_horizon`] on this thread.
        pub(super) static HORIZON_CHECKS: Cell<usize> = const { Cell::new(0) };
    }

    /// A simulation checks its interval once: `simulate` ran `check_interval` twice (in
    /// `simulate_with_guess` and again in `simulate_into_with_guess`) and the integrator's
    /// `advance` checked the same horizon a third time; `simulate_from_steady` (`mvem
    /// simulate`) once more before its steady state. A bad horizon is still refused.
    #[test]
    fn a_simulation_checks_its_horizon_once() {
        let m = Engine8::new(
            crate::params::Params::published(),
            crate::model::ModelOptions::default(),
        )
        .unwrap();
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let sched = InputSchedule::constant(d);
        let x = crate::analysis::steady::steady_state(&m, &d).unwrap().x;
        for chunks in [1, 2] {
            let opts = SimOptions {
                dt_out: 0.05,
                time_chunks: chunks,
                ..SimOptions::default()
            };
            HORIZON_CHECKS.with(|n| n.set(0));
            simulate(&m, &sched, 0.0, 0.2, Start::State(x), &opts).unwrap();
            assert_eq!(HORIZON_CHECKS.with(Cell::get), 1, "time_chunks {chunks}");
            HORIZON_CHECKS.with(|n| n.set(0));
            let sol = Solution::new(&m.state_names());
            simulate_into(&m, &sched, 0.0, 0.2, Start::State(x), &opts, sol).unwrap();
            assert_eq!(HORIZON_CHECKS.with(Cell::get), 1, "time_chunks {chunks}");
            let e = simulate(&m, &sched, 0.0, 2.0 * MAX_TIME, Start::State(x), &opts).unwrap_err();
            assert!(matches!(e, SimError::BadHorizon { .. }), "{e}");
            // from the steady state (checked before the steady state is solved)
            HORIZON_CHECKS.with(|n| n.set(0));
            simulate_from_steady(&m, &sched, 0.0, 0.2, &opts).unwrap();
            assert_eq!(HORIZON_CHECKS.with(Cell::get), 1, "time_chunks {chunks}");
            HORIZON_CHECKS.with(|n| n.set(0));
            let sol = Solution::new(&m.state_names());
            simulate_from_steady_into(&m, &sched, 0.0, 0.2, &opts, sol).unwrap();
            assert_eq!(HORIZON_CHECKS.with(Cell::get), 1, "time_chunks {chunks}");
            let e = simulate_from_steady(&m, &sched, 0.0, 2.0 * MAX_TIME, &opts).unwrap_err();
            assert!(e.to_string().contains("beyond the 1e9 s"), "{e}");
        }
        // the integrator advanced by hand checks each call's horizon
        let opts = SimOptions::default();
        let mut run = Integrator::new(&m, &sched, 0.0, x, &opts).unwrap();
        let mut sol = Solution::new(&m.state_names());
        HORIZON_CHECKS.with(|n| n.set(0));
        run.advance(0.1, &mut sol, false).unwrap();
        assert_eq!(HORIZON_CHECKS.with(Cell::get), 1);
        let e = run.advance(2.0 * MAX_TIME, &mut sol, false).unwrap_err();
        assert!(matches!(e, SimError::BadHorizon { .. }), "{e}");
    }
}
