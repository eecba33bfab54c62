//! Assembled model variants behind one interface.
//!
//! A model is `dx/dt = f(x, u(t), u_egr(t - tau_degr), u_vgt(t - tau_dvgt))` (eq. (2)) plus
//! every algebraic signal, computed by one function, [`Model::eval`]. The 8-state model of the
//! paper (sections 3-7) is [`Engine8`]; the section-9 extensions implement the same trait.

/// `Model::eval` and `Model::derivatives` of a variant from its
/// `evaluate::<SIGNALS>(x, u, memory) -> (Shared, dx, at_limit)`: one code path, with the
/// signal-only work compiled out of `derivatives` (bitwise the same `dx` and memory).
macro_rules! eval_from_evaluate {
    ($n:literal) => {
        #[inline]
        fn eval(&self, x: &[f64; $n], u: &ModelInput, memory: SeligerIterate) -> Evaluation<$n> {
            let (sh, dx, at_limit) = self.evaluate::<true>(x, u, memory);
            common::evaluation(sh, dx, at_limit)
        }

        #[inline]
        fn derivatives(
            &self,
            x: &[f64; $n],
            u: &ModelInput,
            memory: SeligerIterate,
        ) -> Derivatives<$n> {
            let (sh, dx, _) = self.evaluate::<false>(x, u, memory);
            common::derivatives(&sh, dx)
        }
    };
}

/// The memory items of the engine models' [`Model`] impls: the cylinder-temperature iterate
/// (x_r, T_1) of eq. (24), held between steps in [`CylinderTemp::OneIteration`] mode.
macro_rules! engine_memory {
    ($n:literal) => {
        type Memory = SeligerIterate;
        fn memory_start(&self, _x: &[f64; $n], _u: &ModelInput) -> SeligerIterate {
            super::engine_memory_start(self.params())
        }
        fn initial_memory(&self, x: &[f64; $n], u: &ModelInput) -> SeligerIterate {
            super::engine_initial_memory(self, x, u)
        }
        fn holds_memory(&self) -> bool {
            self.options().cylinder_temp == super::CylinderTemp::OneIteration
        }
    };
}

mod adiabatic;
mod any;
mod common;
mod dynamics;
mod engine10;
mod engine12;
mod engine8;
pub mod meta;
mod signals;

pub use any::{AnyModel, ModelError, ModelOrder};
pub use dynamics::Dynamics;

pub use engine10::{ix as ix10, Engine10, STATE_NAMES_10};
pub use engine12::{ix as ix12, Engine12, STATE_NAMES_12};
pub use engine8::{ix, Engine8, STATE_NAMES_8};
pub use meta::VarMeta;
pub use signals::{Guard, Signals};

use crate::components::cylinder::SeligerIterate;
use crate::components::Semantics;
use crate::params::Params;
use serde::{Deserialize, Serialize};

/// The four model inputs in the paper's user units (eqs (2)-(3)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Drive {
    /// Engine speed n_e \[rpm\] (a measured disturbance).
    pub n_e_rpm: f64,
    /// Injected fuel u_delta [mg/cycle/cylinder].
    pub u_delta_mg: f64,
    /// EGR valve command u_egr [%] (0 closed, 100 open).
    pub u_egr_pct: f64,
    /// VGT command u_vgt [%] (0 closed, 100 open).
    pub u_vgt_pct: f64,
}

impl Drive {
    /// A constant operating point.
    pub fn new(n_e_rpm: f64, u_delta_mg: f64, u_egr_pct: f64, u_vgt_pct: f64) -> Self {
        Self {
            n_e_rpm,
            u_delta_mg,
            u_egr_pct,
            u_vgt_pct,
        }
    }

    /// Values in the order (n_e, u_delta, u_egr, u_vgt).
    pub fn to_array(self) -> [f64; 4] {
        [
            self.n_e_rpm,
            self.u_delta_mg,
            self.u_egr_pct,
            self.u_vgt_pct,
        ]
    }

    /// From (n_e, u_delta, u_egr, u_vgt).
    pub fn from_array(a: [f64; 4]) -> Self {
        Self::new(a[0], a[1], a[2], a[3])
    }

    /// Input names in [`Drive::to_array`] order.
    pub const NAMES: [&'static str; 4] = ["n_e", "u_delta", "u_egr", "u_vgt"];

    /// Whether the model can be evaluated at these inputs under `sem`: every value finite, and
    /// for the paper's plain equations n_e > 0 (eq. (12) takes sqrt(n_e), and at n_e = 0 the
    /// cylinder flows (11), (13) vanish, so the in-cylinder temperature rise W_f q_HV /
    /// (W_ei + W_f) of eq. (17) is 0/0). The authors' implementation saturates n_e to
    /// 500-2000 rpm (item 1) and evaluates every finite input.
    pub fn check(&self, sem: Semantics) -> Result<(), InputError> {
        for (name, value) in Self::NAMES.iter().zip(self.to_array()) {
            if !value.is_finite() {
                return Err(InputError {
                    name,
                    value,
                    reason: "is not finite",
                });
            }
        }
        if !sem.authors() && self.n_e_rpm <= 0.0 {
            return Err(InputError {
                name: "n_e",
                value: self.n_e_rpm,
                reason: "must be > 0 rpm with the paper's equations (sqrt(n_e) in eq. (12), \
                         0/0 in eq. (17)); the authors' semantics saturate it to 500-2000 rpm",
            });
        }
        Ok(())
    }
}

/// An input the model cannot be evaluated at ([`Drive::check`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("input {name} = {} {reason}", crate::numerics::Num(*value))]
pub struct InputError {
    /// Input name (`n_e`, `u_delta`, `u_egr`, `u_vgt`).
    pub name: &'static str,
    /// Its value (user units: rpm, mg, %).
    pub value: f64,
    /// What is wrong with it.
    pub reason: &'static str,
}

/// What one model evaluation sees of the inputs: the current values and the actuator commands
/// delayed by the transport delays tau_degr and tau_dvgt (eqs (40)-(41), (57)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelInput {
    /// Inputs at time t.
    pub now: Drive,
    /// EGR command at t - tau_degr [%].
    pub u_egr_delayed: f64,
    /// VGT command at t - tau_dvgt [%].
    pub u_vgt_delayed: f64,
}

impl ModelInput {
    /// Constant inputs (no history): the delayed commands equal the current ones.
    pub fn constant(d: Drive) -> Self {
        Self {
            now: d,
            u_egr_delayed: d.u_egr_pct,
            u_vgt_delayed: d.u_vgt_pct,
        }
    }

    /// The six values (n_e \[rpm\], u_delta [mg/cycle], u_egr [%], u_vgt [%], delayed u_egr [%],
    /// delayed u_vgt [%]), in this order.
    pub fn to_array(&self) -> [f64; 6] {
        [
            self.now.n_e_rpm,
            self.now.u_delta_mg,
            self.now.u_egr_pct,
            self.now.u_vgt_pct,
            self.u_egr_delayed,
            self.u_vgt_delayed,
        ]
    }

    /// The inverse of [`ModelInput::to_array`].
    pub fn from_array(v: [f64; 6]) -> Self {
        Self {
            now: Drive::new(v[0], v[1], v[2], v[3]),
            u_egr_delayed: v[4],
            u_vgt_delayed: v[5],
        }
    }
}

/// How the cylinder-out temperature fixed point (eq. (24)) is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CylinderTemp {
    /// Iterate to a relative change <= 1e-12 from (x_r, T_1) = (0, T_im) at every evaluation:
    /// a pure function of state and inputs (default; what steady-state solvers, linearization and
    /// FMUs need; the reference data use it).
    #[default]
    Converged,
    /// The authors' Simulink semantics: one iteration per evaluation from the (x_r, T_1) held
    /// since the last accepted solver step (Memory blocks, item 17); results depend on the step
    /// sequence, as in Simulink.
    OneIteration,
}

/// Whether the actuator dynamics are used (the authors' switch, item 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Actuators {
    /// The valve positions are the actuator model outputs (eqs (39)-(41), (57)).
    #[default]
    Dynamic,
    /// The saturated, undelayed commands pass straight through; the actuator states are still
    /// integrated, as in the authors' implementation.
    Bypass,
}

/// Model options (all enums, defaults = the authors' implementation with converged T_e).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ModelOptions {
    /// Authors' implementation or the paper's plain equations.
    pub semantics: Semantics,
    /// Cylinder-out temperature solution.
    pub cylinder_temp: CylinderTemp,
    /// Actuator dynamics on or bypassed.
    pub actuators: Actuators,
}

/// Result of one model evaluation (`Mem`: the model's [`Model::Memory`]).
#[derive(Debug, Clone, Copy)]
pub struct Evaluation<const N: usize, Mem = SeligerIterate> {
    /// State derivatives dx/dt (units of the state per second).
    pub dx: [f64; N],
    /// All algebraic signals.
    pub signals: Signals,
    /// The memory to hold after an accepted step (the engine models: the cylinder-temperature
    /// iterate in one-iteration mode; the fixed point itself in converged mode).
    pub memory_next: Mem,
}

/// The delayed input command that drives a [`LinearLag`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LagCommand {
    /// u_egr(t - tau_degr) (eqs (40), (41)).
    Egr,
    /// u_vgt(t - tau_dvgt) (eq. (57)).
    Vgt,
}

/// A state that is a first-order lag of a saturated, delayed input command,
/// `dx/dt = (clamp(u(t - tau_d), lo, hi) - x) / tau`: the actuator states u_egr1, u_egr2
/// (eqs (40), (41)) and u_vgt (eq. (57)). They depend on nothing but the inputs, so the simulator
/// can integrate them in closed form (see `sim`); [`Model::eval`] must give exactly this derivative
/// (tested for every model). The delayed lookup of a command that drives a lag must enter no
/// other state's derivative (the engine models: the delayed u_egr and u_vgt drive the actuator
/// states only; tested), so that the simulator may run a step across its breakpoints
/// (`SimOptions::stop_at_lag_breakpoints`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearLag {
    /// State index.
    pub state: usize,
    /// Time constant tau \[s\].
    pub tau: f64,
    /// Driving command.
    pub command: LagCommand,
    /// Saturation (lo, hi) of the delayed command [%] (infinite: none).
    pub saturation: (f64, f64),
}

/// Saturation range of the engine speed n_e \[rpm\] in the authors' implementation (item 1): their
/// engine's speed range (the default of `input_saturation.n_e`).
pub const N_E_RANGE: (f64, f64) = (500.0, 2000.0);
/// Saturation range of the injected fuel u_delta [mg/cycle/cylinder] in the authors'
/// implementation (item 2; the default of `input_saturation.u_delta`).
pub const U_DELTA_RANGE: (f64, f64) = (1.0, 250.0);
/// Saturation range [%] of the EGR command in the authors' implementation (item 3; the default
/// of `input_saturation.u_egr`).
pub const U_EGR_RANGE: (f64, f64) = (0.0, 100.0);
/// Saturation range [%] of the VGT command in the authors' implementation (item 4; the default
/// of `input_saturation.u_vgt`).
pub const U_VGT_RANGE: (f64, f64) = (20.0, 100.0);

/// The saturations (EGR, VGT) [%] the model applies to the commands before the actuators:
/// the parameter set's `input_saturation.u_egr`, `u_vgt` (`limits`; the authors' are
/// [`U_EGR_RANGE`], [`U_VGT_RANGE`]) for the authors' implementation, none (infinite) for the
/// paper's equations.
pub fn command_saturation(
    sem: Semantics,
    limits: &crate::params::InputSaturation,
) -> ((f64, f64), (f64, f64)) {
    let none = (f64::NEG_INFINITY, f64::INFINITY);
    if sem.authors() {
        (limits.egr(), limits.vgt())
    } else {
        (none, none)
    }
}

/// The three actuator lags (u_egr1, u_egr2, u_vgt at the given state indices).
pub(crate) fn actuator_lags(p: &Params, sem: Semantics, ix: [usize; 3]) -> Vec<LinearLag> {
    let (egr, vgt) = command_saturation(sem, &p.input_saturation);
    vec![
        LinearLag {
            state: ix[0],
            tau: p.egr_actuator.tau_egr1,
            command: LagCommand::Egr,
            saturation: egr,
        },
        LinearLag {
            state: ix[1],
            tau: p.egr_actuator.tau_egr2,
            command: LagCommand::Egr,
            saturation: egr,
        },
        LinearLag {
            state: ix[2],
            tau: p.vgt_actuator.tau_vgt,
            command: LagCommand::Vgt,
            saturation: vgt,
        },
    ]
}

/// What an integrator needs of one model evaluation: [`Evaluation`] without the signals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Derivatives<const N: usize, Mem = SeligerIterate> {
    /// State derivatives dx/dt (units of the state per second).
    pub dx: [f64; N],
    /// The memory to hold after an accepted step.
    pub memory_next: Mem,
}

/// How the simulator feeds a model's inputs: the transport delays of eq. (2) and which
/// input channels enter the dynamics undelayed.
///
/// A model sees the four [`Drive`] channels at time t ([`ModelInput::now`]) and two delayed
/// lookups, channel 2 at `t - delayed[0]` ([`ModelInput::u_egr_delayed`]) and channel 3 at
/// `t - delayed[1]` ([`ModelInput::u_vgt_delayed`]). The simulator evaluates both exactly from
/// the schedule and stops at every breakpoint of a channel that enters the dynamics: the
/// channels with `current[c]` at their breakpoints, channels 2 and 3 also at their breakpoints
/// shifted by their delays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputDelays {
    /// Delays \[s\] of the delayed lookups of channels 2 and 3 (>= 0, finite).
    pub delayed: [f64; 2],
    /// Whether the current value of each channel (in [`Drive::to_array`] order) enters the
    /// derivatives (its breakpoints are then stop times).
    pub current: [bool; 4],
}

impl InputDelays {
    /// The engine models': u_egr delayed by tau_degr (eqs (40)-(41)), u_vgt by tau_dvgt
    /// (eq. (57)); the undelayed commands drive the dynamics only with the actuators bypassed
    /// (item 6).
    pub fn engine(p: &Params, actuators: Actuators) -> Self {
        let bypass = actuators == Actuators::Bypass;
        Self {
            delayed: [p.egr_actuator.tau_degr, p.vgt_actuator.tau_dvgt],
            current: [true, true, bypass, bypass],
        }
    }
}

/// A mean-value engine model with `N` states.
///
/// The simulator sees a model only through [`Dynamics`] (implemented for every `Model` by
/// forwarding): [`Model::state_names`], [`Model::state_scales`], [`Model::state_bounds`],
/// [`Model::derivatives`] (steps) and [`Model::eval`] (output samples), [`Model::input_delays`],
/// [`Model::linear_lags`], the memory contract ([`Model::Memory`], [`Model::initial_memory`],
/// [`Model::holds_memory`]) and [`Model::nonfinite_hint`]. The rest (parameters, options, steady
/// state guesses, the extensions' links to the 8-state model) is for the analyses above `sim`.
pub trait Model<const N: usize>: Send + Sync {
    /// State an evaluation carries from one accepted step to the next (the engine models: the
    /// cylinder-temperature iterate (x_r, T_1) of eq. (24); `()` for a model without memory).
    /// Opaque to the simulator, which only stores [`Evaluation::memory_next`] after accepted
    /// steps when [`Model::holds_memory`] is true.
    type Memory: Copy + PartialEq + std::fmt::Debug + Send + Sync;
    /// State names (reference-data names: `p_im`, `p_em`, `X_Oim`, ...).
    fn state_names(&self) -> [&'static str; N];
    /// Typical magnitudes of the states (used for scaling in solvers and error norms).
    fn state_scales(&self) -> [f64; N];
    /// Parameters.
    fn params(&self) -> &Params;
    /// Options.
    fn options(&self) -> &ModelOptions;
    /// Lower and upper integrator limits of each state (infinite where none).
    fn state_bounds(&self) -> [(f64, f64); N];
    /// Evaluate derivatives and signals at state `x` and inputs `u`, with the cylinder
    /// temperature memory `memory` (used only in [`CylinderTemp::OneIteration`]).
    fn eval(
        &self,
        x: &[f64; N],
        u: &ModelInput,
        memory: Self::Memory,
    ) -> Evaluation<N, Self::Memory>;
    /// The derivatives and cylinder-temperature memory of [`Model::eval`] without the
    /// signals, for integrators and Jacobians: bitwise the same `dx` and `memory_next` (the
    /// variants compile the same code with the signal-only work - torque, guard flags, the
    /// signal record - left out).
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
    /// Indices of the states that are actuator states (set to the saturated commands at steady state).
    fn actuator_state_values(&self, d: &Drive) -> Vec<(usize, f64)>;
    /// The states that are first-order lags of delayed input commands (default: none).
    fn linear_lags(&self) -> Vec<LinearLag> {
        Vec::new()
    }
    /// The input delays and the channels that enter the dynamics undelayed (default: the
    /// engine's, [`InputDelays::engine`] from [`Model::params`] and [`Model::options`]).
    fn input_delays(&self) -> InputDelays {
        InputDelays::engine(self.params(), self.options().actuators)
    }
    /// The memory an evaluation starts from when none is held (steady state, linearization,
    /// the start of the converged fixed point search): for the engine models (x_r, T_1) =
    /// (0, T_im).
    fn memory_start(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory;
    /// The memory a simulation starting at `x`, `u` holds (default [`Model::memory_start`];
    /// the engine models in one-iteration mode: the converged fixed point, as the authors'
    /// runSimEngine sets x_r_Init, T_1_Init from the settling run).
    fn initial_memory(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory {
        self.memory_start(x, u)
    }
    /// Whether [`Model::eval`] depends on the memory, so that the simulator must hold
    /// [`Evaluation::memory_next`] after each accepted step (default false; the engine models:
    /// [`CylinderTemp::OneIteration`]).
    fn holds_memory(&self) -> bool {
        false
    }
    /// What probably went wrong when a derivative is NaN or infinite (for the simulator's
    /// error message).
    fn nonfinite_hint(&self) -> &'static str {
        if self.options().semantics.authors() {
            "inputs far outside the model's range, or parameters without a physical operating point"
        } else {
            "the paper's equations have no guards: a pressure ratio or flow left its physical range; try --semantics authors"
        }
    }
    /// Initial guess for the steady state at `d`, for iterative solvers.
    fn initial_guess(&self, d: &Drive) -> [f64; N];
    /// The same model with other options.
    fn with_options(&self, opts: ModelOptions) -> Self
    where
        Self: Sized;

    /// For the extensions: the 8-state model with the same parameters and options (`None` for
    /// the 8-state model). The steady-state solver solves it first and starts the extension's
    /// Newton iteration from its equilibrium, lifted by [`Model::lift_equilibrium_8`].
    fn reduced_8(&self) -> Option<&Engine8> {
        None
    }

    /// This model's state at the 8-state equilibrium `x8` with signals `s8` (the seed of the
    /// steady-state solver; `None` for the 8-state model). The 10-state model takes T_im = the
    /// cooled charge temperature and T_em = the 8-state T_em (the values at any equilibrium);
    /// the 12-state model adds T_ic = the compressor outlet temperature T_c and p_c = p_im plus
    /// the intercooler pressure drop (eq. (86)) carrying W_c.
    fn lift_equilibrium_8(&self, _x8: &[f64; 8], _s8: &Signals) -> Option<[f64; N]> {
        None
    }

    /// The converged cylinder-temperature fixed point (x_r, T_1) at `x`, `u` (the initial
    /// memory of a one-iteration simulation).
    fn cylinder_fixed_point(&self, x: &[f64; N], u: &ModelInput) -> Self::Memory
    where
        Self: Sized,
    {
        let mut o = *self.options();
        o.cylinder_temp = CylinderTemp::Converged;
        let start = self.memory_start(x, u);
        self.with_options(o).eval(x, u, start).memory_next
    }
}

/// The engine models' memory at the start of an evaluation: (x_r, T_1) = (0, T_im) with the
/// intake manifold temperature parameter T_im \[K\].
pub(crate) fn engine_memory_start(p: &Params) -> SeligerIterate {
    SeligerIterate {
        x_r: 0.0,
        t_1: p.intake_manifold.t_im,
    }
}

/// The engine models' memory of a simulation starting at `x`, `u`: the converged fixed point in
/// one-iteration mode (else the start, which converged evaluations do not read).
pub(crate) fn engine_initial_memory<const N: usize, M: Model<N, Memory = SeligerIterate>>(
    m: &M,
    x: &[f64; N],
    u: &ModelInput,
) -> SeligerIterate {
    if m.options().cylinder_temp == CylinderTemp::OneIteration {
        m.cylinder_fixed_point(x, u)
    } else {
        m.memory_start(x, u)
    }
}

/// Input saturations of the authors' implementation (items 1-4), returned with guard bits:
/// n_e, u_delta and the commands into the ranges of `limits` (the parameter set's; the
/// authors' are [`N_E_RANGE`], [`U_DELTA_RANGE`], [`U_EGR_RANGE`], [`U_VGT_RANGE`]).
pub fn saturate_inputs(
    d: &Drive,
    sem: Semantics,
    limits: &crate::params::InputSaturation,
) -> (Drive, u32) {
    if !sem.authors() {
        return (*d, 0);
    }
    let mut g = 0;
    let mut clamp = |v: f64, lo: f64, hi: f64, bit: Guard| {
        if v < lo {
            g |= bit as u32;
            lo
        } else if v > hi {
            g |= bit as u32;
            hi
        } else {
            v // also NaN, as f64::clamp
        }
    };
    let out = Drive::new(
        clamp(d.n_e_rpm, limits.n_e[0], limits.n_e[1], Guard::InputNe),
        clamp(
            d.u_delta_mg,
            limits.u_delta[0],
            limits.u_delta[1],
            Guard::InputUDelta,
        ),
        clamp(
            d.u_egr_pct,
            limits.u_egr[0],
            limits.u_egr[1],
            Guard::InputUEgr,
        ),
        clamp(
            d.u_vgt_pct,
            limits.u_vgt[0],
            limits.u_vgt[1],
            Guard::InputUVgt,
        ),
    );
    (out, g)
}

/// Authors' saturation of a delayed EGR command (item 3, applied before the delay) into
/// `limits.u_egr` (the parameter set's).
#[inline]
pub fn saturate_u_egr(u: f64, sem: Semantics, limits: &crate::params::InputSaturation) -> f64 {
    if sem.authors() {
        u.clamp(limits.u_egr[0], limits.u_egr[1])
    } else {
        u
    }
}

/// Authors' saturation of a delayed VGT command (item 4, applied before the delay) into
/// `limits.u_vgt` (the parameter set's).
#[inline]
pub fn saturate_u_vgt(u: f64, sem: Semantics, limits: &crate::params::InputSaturation) -> f64 {
    if sem.authors() {
        u.clamp(limits.u_vgt[0], limits.u_vgt[1])
    } else {
        u
    }
}

/// Limited-integrator emulation (items 9-12, 37): clip each state into its bounds before use.
/// Returns the clipped state and whether any state was outside or on a bound.
#[inline]
pub fn clip_state<const N: usize>(x: &[f64; N], bounds: &[(f64, f64); N]) -> [f64; N] {
    // f64::clamp without its lo <= hi assertion (the bounds are built with lo <= hi): the
    // same value for every input, NaN included.
    std::array::from_fn(|i| {
        let (v, (lo, hi)) = (x[i], bounds[i]);
        if v < lo {
            lo
        } else if v > hi {
            hi
        } else {
            v
        }
    })
}

/// [`start_clip_warnings`]' words for a simulation's start state.
pub const STARTS_FROM: &str = "the simulation starts from";
/// [`start_clip_warnings`]' words for a state the model is evaluated (linearized) at: its
/// right-hand side clips the state, so the Jacobian's column is that of the limit.
pub const EVALUATED_AT: &str = "the model is evaluated (and linearized) at the limit,";

/// The states of a given state `x` outside the integrator limits `bounds` (which clip it, see
/// [`clip_state`]), one message each naming the state, its value, the limits and, after
/// `then`, the value used: with `then` = [`STARTS_FROM`], `p_im: 1e8 is outside the integrator
/// limits [500, 1e7]: the simulation starts from 1e7` (the CLI's `simulate --initial-state` and
/// Python's `x0` warn with them; `linearize --state` with [`EVALUATED_AT`]).
pub fn start_clip_warnings(
    names: &[&str],
    bounds: &[(f64, f64)],
    x: &[f64],
    then: &str,
) -> Vec<String> {
    use crate::numerics::Num;
    names
        .iter()
        .zip(bounds)
        .zip(x)
        .filter(|((_, (lo, hi)), v)| *v < lo || *v > hi)
        .map(|((name, (lo, hi)), v)| {
            format!(
                "{name}: {} is outside the integrator limits [{}, {}]: {then} {}",
                Num(*v),
                Num(*lo),
                Num(*hi),
                Num(v.clamp(*lo, *hi))
            )
        })
        .collect()
}

/// Limited-integrator emulation: zero each derivative that points outward at or beyond its bound.
/// Returns whether any state is at a limit.
#[inline]
pub fn limit_derivatives<const N: usize>(
    x: &[f64; N],
    dx: &mut [f64; N],
    bounds: &[(f64, f64); N],
) -> bool {
    let mut at = false;
    for i in 0..N {
        let (lo, hi) = bounds[i];
        if x[i] > lo && x[i] < hi {
            // strictly inside (the usual case): one test
            continue;
        }
        if (x[i] <= lo && dx[i] < 0.0) || (x[i] >= hi && dx[i] > 0.0) {
            dx[i] = 0.0;
            at = true;
        } else if x[i] <= lo || x[i] >= hi {
            at = true;
        }
    }
    at
}
