//! [`Dynamics`]: what the simulator needs of a model, and nothing else.
//!
//! `sim` is generic over this trait, not over [`Model`]: an ODE with no engine parameters and
//! no model options (the integrators' test problems in `tests/integrators.rs`) implements it
//! directly. Every [`Model`] is a `Dynamics` through the blanket implementation below, which
//! forwards to the model's own methods, so engine code keeps calling [`Model`] and the two never
//! disagree.

use super::{Derivatives, Evaluation, InputDelays, LinearLag, Model, ModelInput};

/// An `N`-state ODE `dx/dt = f(x, u(t), delayed commands, memory)` as the simulator sees it:
/// names, scales and bounds of the states, the right-hand side with its output record, the input
/// delays, the states that are linear lags of delayed commands, and the memory contract. See the
/// methods of the same names on [`Model`] for the engine models' meaning.
pub trait Dynamics<const N: usize>: Send + Sync {
    /// State an evaluation carries from one accepted step to the next (opaque to the
    /// simulator; `()` for an ODE without memory).
    type Memory: Copy + PartialEq + std::fmt::Debug + Send + Sync;
    /// State names (the columns of the solution).
    fn state_names(&self) -> [&'static str; N];
    /// Typical magnitudes of the states (error norms, finite-difference Jacobians).
    fn state_scales(&self) -> [f64; N];
    /// Lower and upper integrator limits of each state (infinite where none).
    fn state_bounds(&self) -> [(f64, f64); N];
    /// Derivatives and output signals at `x`, `u` with the held `memory`.
    fn eval(
        &self,
        x: &[f64; N],
        u: &ModelInput,
        memory: Self::Memory,
    ) -> Evaluation<N, Self::Memory>;
    /// [`Dynamics::eval`] without the signals (bitwise the same `dx` and `memory_next`).
    #[inline]
    fn derivatives(
        &self,
        x: &[f64; N],
        u: &ModelInput,
        memory: Self::Memory,
    ) -> Derivatives<N, Self::Memory> {
        let ev = self.eval(x, u, memory);
        Derivatives {
            dx: ev.dx,
            memory_next: ev.memory_next,
        }
    }
    /// The input delays and the channels that enter the dynamics undelayed.
    fn input_delays(&self) -> InputDelays;
    /// The states that are first-order lags of delayed input commands (default: none).
    fn linear_lags(&self) -> Vec<LinearLag> {
        Vec::new()
    }
    /// The memory an evaluation starts from when none is held.
    fn memory_start(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory;
    /// The memory a simulation starting at `x`, `u` holds (default [`Dynamics::memory_start`]).
    fn initial_memory(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory {
        self.memory_start(x, u)
    }
    /// Whether the simulator must hold [`Evaluation::memory_next`] after accepted steps.
    fn holds_memory(&self) -> bool {
        false
    }
    /// What probably went wrong when a derivative is NaN or infinite (for the error message).
    fn nonfinite_hint(&self) -> &'static str {
        "the right-hand side is not finite at this state and input"
    }
}

impl<const N: usize, M: Model<N>> Dynamics<N> for M {
    type Memory = <M as Model<N>>::Memory;
    #[inline]
    fn state_names(&self) -> [&'static str; N] {
        Model::state_names(self)
    }
    #[inline]
    fn state_scales(&self) -> [f64; N] {
        Model::state_scales(self)
    }
    #[inline]
    fn state_bounds(&self) -> [(f64, f64); N] {
        Model::state_bounds(self)
    }
    #[inline]
    fn eval(
        &self,
        x: &[f64; N],
        u: &ModelInput,
        memory: Self::Memory,
    ) -> Evaluation<N, Self::Memory> {
        Model::eval(self, x, u, memory)
    }
    #[inline]
    fn derivatives(
        &self,
        x: &[f64; N],
        u: &ModelInput,
        memory: Self::Memory,
    ) -> Derivatives<N, Self::Memory> {
        Model::derivatives(self, x, u, memory)
    }
    #[inline]
    fn input_delays(&self) -> InputDelays {
        Model::input_delays(self)
    }
    #[inline]
    fn linear_lags(&self) -> Vec<LinearLag> {
        Model::linear_lags(self)
    }
    #[inline]
    fn memory_start(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory {
        Model::memory_start(self, x, u)
    }
    #[inline]
    fn initial_memory(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory {
        Model::initial_memory(self, x, u)
    }
    #[inline]
    fn holds_memory(&self) -> bool {
        Model::holds_memory(self)
    }
    #[inline]
    fn nonfinite_hint(&self) -> &'static str {
        Model::nonfinite_hint(self)
    }
}
