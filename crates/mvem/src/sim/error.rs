//! Simulation errors: what failed, when, and the state at that time.

use crate::model::{Dynamics, ModelInput, Signals};
use std::fmt;

/// A failed simulation: what, when, and the state at that time.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// An option is out of range.
    #[error("option {field} = {}: {constraint}", crate::numerics::Num(*value))]
    BadOption {
        /// Option name.
        field: &'static str,
        /// Value.
        value: f64,
        /// Constraint.
        constraint: &'static str,
    },
    /// A command given to the plant stepper is not a finite number.
    #[error("command {name} = {} at t = {} s: must be finite", crate::numerics::Num(*value), crate::numerics::Num(*t))]
    BadCommand {
        /// Input name (`n_e`, `u_delta`, `u_egr`, `u_vgt`).
        name: &'static str,
        /// Value.
        value: f64,
        /// The plant's time \[s\].
        t: f64,
    },
    /// The end time is not after the start time.
    #[error("end time {t_end} s must be after start time {t0} s")]
    BadInterval {
        /// Start.
        t0: f64,
        /// End.
        t_end: f64,
    },
    /// The interval or its output grid is beyond what the simulator handles: a time beyond
    /// [`super::MAX_TIME`] in magnitude, or more than [`super::MAX_ROWS`] output samples.
    #[error("{message}")]
    BadHorizon {
        /// Start \[s\].
        t0: f64,
        /// End \[s\].
        t_end: f64,
        /// What is too large, naming the values and the limit.
        message: String,
    },
    /// A derivative or the initial state is NaN or infinite.
    #[error("non-finite {what} {name} = {value} at t = {} s; state: {state}. Hint: {hint}", crate::numerics::Num(*t))]
    NonFinite {
        /// Time \[s\].
        t: f64,
        /// "derivative of" / "initial state".
        what: &'static str,
        /// State name.
        name: String,
        /// Value.
        value: f64,
        /// The state at that time, formatted.
        state: StateDump,
        /// What probably went wrong; for a derivative, first the model's algebraic signals that
        /// are not finite there (`"non-finite signals: T_c, eta_c, P_c; ..."`: where the NaN
        /// starts).
        hint: Box<str>,
    },
    /// The step size fell below the resolution of the time axis.
    #[error("step size {h:e} s too small at t = {} s; limiting state: {limiting}; state: {state}. Hint: the model may have left its valid region (equilibrium lost, inputs out of range), or the tolerance is too tight", crate::numerics::Num(*t))]
    StepSizeTooSmall {
        /// Time \[s\].
        t: f64,
        /// Step size \[s\].
        h: f64,
        /// The state whose error estimate limited the step, with that error.
        limiting: String,
        /// State.
        state: StateDump,
    },
    /// More steps than allowed.
    #[error("more than {max_steps} steps before t = {} s; state: {state}. Hint: the model may have left its valid region (equilibrium lost; inputs far out of range make the model stiff), or the tolerance is very tight; a library caller with long or fast-varying inputs may allow more steps (SimOptions::max_steps)", crate::numerics::Num(*t))]
    TooManySteps {
        /// Limit.
        max_steps: usize,
        /// Time reached.
        t: f64,
        /// State.
        state: StateDump,
    },
    /// The caller's cancellation token ([`crate::numerics::cancel`], e.g. Ctrl-C in Python)
    /// asked the run to stop; `t` is where it stopped, with the state there.
    #[error("cancelled at t = {} s (a cancellation request, e.g. Ctrl-C); state: {state}", crate::numerics::Num(*t))]
    Cancelled {
        /// Time reached \[s\].
        t: f64,
        /// State.
        state: StateDump,
    },
}

/// A state vector with its names, for error messages.
#[derive(Debug, Clone, PartialEq)]
pub struct StateDump(pub Vec<(&'static str, f64)>);

impl fmt::Display for StateDump {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self.0.iter().map(|(n, v)| format!("{n}={v:.6e}")).collect();
        write!(f, "[{}]", parts.join(", "))
    }
}

pub(super) fn dump<const N: usize, M: Dynamics<N>>(m: &M, y: &[f64; N]) -> StateDump {
    StateDump(
        m.state_names()
            .iter()
            .copied()
            .zip(y.iter().copied())
            .collect(),
    )
}

/// The hint of a non-finite derivative of `m` at `y`, `u`: `"non-finite signals: a, b; "` for
/// the algebraic signals that are NaN or infinite there (where the NaN comes from), then the
/// model's [`Dynamics::nonfinite_hint`].
pub(super) fn nonfinite_hint<const N: usize, M: Dynamics<N>>(
    m: &M,
    y: &[f64; N],
    u: &ModelInput,
    memory: M::Memory,
) -> Box<str> {
    let ev = m.eval(y, u, memory);
    let bad: Vec<&str> = Signals::NAMES
        .iter()
        .zip(ev.signals.values())
        .filter(|(_, v)| !v.is_finite())
        .map(|(n, _)| *n)
        .collect();
    if bad.is_empty() {
        m.nonfinite_hint().into()
    } else {
        format!(
            "non-finite signals: {}; {}",
            bad.join(", "),
            m.nonfinite_hint()
        )
        .into()
    }
}
