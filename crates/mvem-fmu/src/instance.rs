//! The FMU instance in safe Rust: state machine, variable access, Model Exchange and
//! Co-Simulation semantics. The C ABI in [`crate::ffi`] only converts pointers and statuses.
//!
//! Transport delays (tau_degr, tau_dvgt): the instance keeps a history of the inputs, one entry
//! per change, recorded at the FMU's current time whenever an input is set (zero-order hold:
//! an input value holds from the time it was set until the next change). The delayed commands
//! are that history evaluated at `t - tau` (constant before the start). This is the same in
//! both interfaces:
//! - Co-Simulation: the history becomes an [`InputSchedule`] with a jump at every communication
//!   point where an input changed, and `fmi2DoStep` integrates with mvem's own simulator over
//!   it, so delays and the stops at delayed input jumps are exact.
//! - Model Exchange: the derivatives use the history at `t - tau`; `fmi2NewDiscreteStates`
//!   announces the next delayed jump as a time event (`nextEventTime`), so the importer's
//!   integrator stops there instead of stepping over the discontinuity. Inputs that the importer
//!   changes continuously between events are seen by the delayed path only at the times
//!   `fmi2SetReal` is called (the history is piecewise constant).
//!
//! Model variant and cylinder-temperature mode come from the [`FmuConfig`] (read from the
//! FMU's `resources/` by the C ABI). The one-iteration cylinder temperature (the authors'
//! Memory blocks) is offered in Co-Simulation only: its right-hand side depends on the
//! iterate held since the last accepted step, which a Model Exchange importer cannot provide.
//! In Co-Simulation the iterate is carried from one `fmi2DoStep` to the next.

use crate::vars::{self, FmuConfig, Kind, Layout};
use mvem::analysis::steady::steady_state;
use mvem::components::cylinder::SeligerIterate;
use mvem::model::{AnyModel, CylinderTemp, Drive, Model, ModelInput, ModelOptions, Signals};
use mvem::numerics::Num;
use mvem::params::Params;
use mvem::sim::{InputSchedule, Integrator, SimOptions, Solution};

/// FMI interface the instance was created for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interface {
    /// Model Exchange.
    ModelExchange,
    /// Co-Simulation.
    CoSimulation,
}

/// Where the instance is in the FMI 2.0 state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// After fmi2Instantiate / fmi2Reset.
    Instantiated,
    /// Between fmi2EnterInitializationMode and fmi2ExitInitializationMode.
    Initialization,
    /// Model Exchange event mode.
    Event,
    /// Model Exchange continuous-time mode.
    ContinuousTime,
    /// Co-Simulation step mode.
    StepComplete,
    /// After fmi2Terminate.
    Terminated,
    /// After an error: only fmi2Reset / fmi2FreeInstance are allowed.
    Failed,
}

/// FMI status of a failed call (the ABI maps it to fmi2Status).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Severity {
    /// The call was refused; the instance is unchanged and can go on (fmi2Discard).
    Discard,
    /// The call failed (fmi2Error).
    Error,
}

/// A refused or failed call: severity and message for the logger.
#[derive(Debug, Clone, PartialEq)]
pub struct FmuError {
    /// How bad.
    pub severity: Severity,
    /// Message naming the function, variable or value.
    pub message: String,
}

impl FmuError {
    fn error(message: impl Into<String>) -> Self {
        Self {
            severity: Severity::Error,
            message: message.into(),
        }
    }
    fn discard(message: impl Into<String>) -> Self {
        Self {
            severity: Severity::Discard,
            message: message.into(),
        }
    }
}

/// Result of an instance call.
pub type FmuResult<T> = Result<T, FmuError>;

/// Event information returned by [`Instance::new_discrete_states`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventInfo {
    /// Time of the next delayed input jump, if any.
    pub next_event_time: Option<f64>,
}

/// How far before the longest actuator delay the input history reaches \[s\] (a safety margin
/// for importers that set the time back within a step).
pub const HISTORY_MARGIN: f64 = 1.0;

/// One FMU instance.
pub struct Instance {
    /// Interface.
    pub interface: Interface,
    /// Phase.
    pub phase: Phase,
    config: FmuConfig,
    layout: Layout,
    params: Vec<f64>,
    model: AnyModel,
    inputs: [f64; 4],
    t: f64,
    t_start: f64,
    t_stop: Option<f64>,
    rtol: f64,
    x: Vec<f64>,
    /// Cylinder-temperature iterate held between steps (one-iteration mode, Co-Simulation).
    memory: SeligerIterate,
    /// Input history: (time from which the values hold, values), back to [`HISTORY_MARGIN`]
    /// beyond the longest delay.
    history: Vec<(f64, [f64; 4])>,
    /// States must be recomputed (initialization mode: inputs or parameters changed).
    dirty: bool,
}

/// A state vector as an array of the model's dimension.
fn arr<const N: usize>(x: &[f64]) -> [f64; N] {
    std::array::from_fn(|i| x[i])
}

/// Derivatives and signals of `model` at `x`, `u` with the cylinder-temperature `memory`.
fn eval_any(
    model: &AnyModel,
    x: &[f64],
    u: &ModelInput,
    memory: SeligerIterate,
) -> (Vec<f64>, Signals) {
    mvem::dispatch!(model, m => {
        let ev = m.eval(&arr(x), u, memory);
        (ev.dx.to_vec(), ev.signals)
    })
}

fn build_model(cfg: &FmuConfig, p: Params) -> Result<AnyModel, String> {
    let opts = ModelOptions {
        cylinder_temp: cfg.cylinder_temp,
        ..ModelOptions::default()
    };
    AnyModel::new(cfg.order, p, opts).map_err(|e| e.to_string())
}

impl Instance {
    /// A new instance of the configured variant, with the configured parameters and the start
    /// inputs of the model description.
    pub fn new(interface: Interface, config: &FmuConfig) -> Self {
        // the configuration's parameters were validated when it was read; fall back to the
        // published ones for the same variant rather than fail here
        let model = build_model(config, config.params.clone())
            .or_else(|_| build_model(config, Params::published()))
            .expect("the published parameters are valid");
        let layout = config.layout();
        Self {
            interface,
            phase: Phase::Instantiated,
            params: config.param_values(),
            model,
            inputs: vars::INPUT_STARTS,
            t: 0.0,
            t_start: 0.0,
            t_stop: None,
            rtol: 1e-6,
            x: vec![0.0; layout.n_states()],
            memory: SeligerIterate {
                x_r: 0.0,
                t_1: config.params.intake_manifold.t_im,
            },
            history: Vec::new(),
            dirty: true,
            config: config.clone(),
            layout,
        }
    }

    /// The configuration (variant, cylinder-temperature mode, start parameters).
    pub fn config(&self) -> &FmuConfig {
        &self.config
    }

    /// Number of continuous states.
    pub fn n_states(&self) -> usize {
        self.layout.n_states()
    }

    /// Back to the state after instantiation (fmi2Reset).
    pub fn reset(&mut self) {
        *self = Self::new(self.interface, &self.config);
    }

    /// Current time \[s\].
    pub fn time(&self) -> f64 {
        self.t
    }

    fn require(&self, what: &str, allowed: &[Phase]) -> FmuResult<()> {
        if allowed.contains(&self.phase) {
            Ok(())
        } else {
            Err(FmuError::error(format!(
                "{what} is not allowed in phase {:?}",
                self.phase
            )))
        }
    }

    fn require_me(&self, what: &str) -> FmuResult<()> {
        if self.interface == Interface::ModelExchange {
            Ok(())
        } else {
            Err(FmuError::error(format!(
                "{what} is a Model Exchange function; this instance is Co-Simulation"
            )))
        }
    }

    /// fmi2SetupExperiment.
    pub fn setup_experiment(
        &mut self,
        tolerance: Option<f64>,
        t_start: f64,
        t_stop: Option<f64>,
    ) -> FmuResult<()> {
        self.require("fmi2SetupExperiment", &[Phase::Instantiated])?;
        if !t_start.is_finite() {
            return Err(FmuError::error(format!(
                "fmi2SetupExperiment: startTime = {} is not finite",
                Num(t_start)
            )));
        }
        // the simulator's time axis ends at mvem::sim::MAX_TIME: refuse such an experiment here,
        // not at every later fmi2DoStep
        for (name, t) in [("startTime", Some(t_start)), ("stopTime", t_stop)] {
            if let Some(t) = t.filter(|t| t.abs() > mvem::sim::MAX_TIME) {
                return Err(FmuError::error(format!(
                    "fmi2SetupExperiment: {name} = {} s is beyond the {:e} s (about 31.7 years) \
                     a simulation accepts",
                    Num(t),
                    mvem::sim::MAX_TIME
                )));
            }
        }
        if let Some(tol) = tolerance {
            if !(1e-13..1.0).contains(&tol) {
                return Err(FmuError::error(format!(
                    "fmi2SetupExperiment: tolerance = {} must lie in [1e-13, 1)",
                    Num(tol)
                )));
            }
            self.rtol = tol;
        }
        if let Some(ts) = t_stop {
            if !(ts.is_finite() && ts >= t_start) {
                return Err(FmuError::error(format!(
                    "fmi2SetupExperiment: stopTime = {} must be finite and >= startTime = {}",
                    Num(ts),
                    Num(t_start)
                )));
            }
        }
        self.t_start = t_start;
        self.t = t_start;
        self.t_stop = t_stop;
        Ok(())
    }

    /// fmi2EnterInitializationMode.
    pub fn enter_initialization(&mut self) -> FmuResult<()> {
        self.require("fmi2EnterInitializationMode", &[Phase::Instantiated])?;
        self.phase = Phase::Initialization;
        self.dirty = true;
        Ok(())
    }

    /// Build the model from the parameter values and start at the steady state of the inputs.
    fn initialize_states(&mut self) -> FmuResult<()> {
        let p: Params = vars::params_from_values(&self.params).map_err(FmuError::error)?;
        self.model = build_model(&self.config, p)
            .map_err(|e| FmuError::error(format!("invalid parameters: {e}")))?;
        let d = Drive::from_array(self.inputs);
        let u = ModelInput::constant(d);
        let ss = mvem::dispatch!(&self.model, m => steady_state(m, &d).map(|ss| {
            (ss.x.to_vec(), m.cylinder_fixed_point(&ss.x, &u))
        }))
        .map_err(|e| {
            FmuError::error(format!(
                "no steady state at the start inputs n_e = {} rpm, u_delta = {} mg, u_egr = {} %, u_vgt = {} %: {e}",
                d.n_e_rpm, d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct
            ))
        })?;
        (self.x, self.memory) = ss;
        self.history = vec![(self.t, self.inputs)];
        self.dirty = false;
        Ok(())
    }

    fn ensure_initialized(&mut self) -> FmuResult<()> {
        if self.dirty {
            self.initialize_states()?;
        }
        Ok(())
    }

    /// fmi2ExitInitializationMode: computes the steady state at the current inputs.
    pub fn exit_initialization(&mut self) -> FmuResult<()> {
        self.require("fmi2ExitInitializationMode", &[Phase::Initialization])?;
        self.ensure_initialized()?;
        self.phase = match self.interface {
            Interface::ModelExchange => Phase::Event,
            Interface::CoSimulation => Phase::StepComplete,
        };
        Ok(())
    }

    /// fmi2Terminate.
    pub fn terminate(&mut self) -> FmuResult<()> {
        self.require(
            "fmi2Terminate",
            &[Phase::Event, Phase::ContinuousTime, Phase::StepComplete],
        )?;
        self.phase = Phase::Terminated;
        Ok(())
    }

    /// Input value at `tq` from the history (zero-order hold, right-continuous; constant before
    /// the first entry).
    fn history_at(&self, tq: f64, channel: usize) -> f64 {
        let k = self.history.partition_point(|(th, _)| *th <= tq);
        match k {
            0 => self
                .history
                .first()
                .map_or(self.inputs[channel], |h| h.1[channel]),
            k => self.history[k - 1].1[channel],
        }
    }

    /// Record the current inputs at the current time.
    fn record_inputs(&mut self) {
        let t = self.t;
        // the importer went back in time (e.g. a rejected step): forget the future
        while self.history.len() > 1 && self.history.last().is_some_and(|h| h.0 > t) {
            self.history.pop();
        }
        match self.history.last_mut() {
            Some(last) if last.1 == self.inputs => {}
            Some(last) if last.0 >= t => last.1 = self.inputs,
            _ => self.history.push((t, self.inputs)),
        }
        // forget what no query reaches: the delayed commands are read at t' - tau for t' at or
        // after the last recorded time (an importer does not return before it), so the entry
        // holding at t - max(tau) - HISTORY_MARGIN and the later ones suffice. Without this the
        // history grew with every input change and each fmi2DoStep rebuilt its schedule from
        // all of it (QA: 46 -> 297 us per step over 20 000 steps of a drive cycle).
        let [tau_egr, tau_vgt] = self.delays();
        let cutoff = t - tau_egr.max(tau_vgt) - HISTORY_MARGIN;
        let k = self.history.partition_point(|(th, _)| *th <= cutoff);
        if k > 1 {
            self.history.drain(..k - 1);
        }
    }

    /// The model's transport delays \[s\] of u_egr and u_vgt ([`Model::input_delays`]).
    fn delays(&self) -> [f64; 2] {
        mvem::dispatch!(&self.model, m => m.input_delays().delayed)
    }

    fn model_input(&self) -> ModelInput {
        if self.phase == Phase::Initialization || self.history.is_empty() {
            return ModelInput::constant(Drive::from_array(self.inputs));
        }
        let [tau_egr, tau_vgt] = self.delays();
        ModelInput {
            now: Drive::from_array(self.inputs),
            u_egr_delayed: self.history_at(self.t - tau_egr, 2),
            u_vgt_delayed: self.history_at(self.t - tau_vgt, 3),
        }
    }

    fn evaluate(&self) -> (Vec<f64>, Signals) {
        eval_any(&self.model, &self.x, &self.model_input(), self.memory)
    }

    /// fmi2GetReal for a batch of value references.
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> FmuResult<()> {
        self.require(
            "fmi2GetReal",
            &[
                Phase::Initialization,
                Phase::Event,
                Phase::ContinuousTime,
                Phase::StepComplete,
                Phase::Terminated,
            ],
        )?;
        self.ensure_initialized()?;
        let mut ev = None;
        for (vr, o) in vrs.iter().zip(out.iter_mut()) {
            let kind = self.layout.lookup(*vr).ok_or_else(|| {
                FmuError::error(format!("fmi2GetReal: unknown value reference {vr}"))
            })?;
            *o = match kind {
                Kind::Input(i) => self.inputs[i],
                Kind::State(i) => self.x[i],
                Kind::Param(i) => self.params[i],
                Kind::Derivative(i) => ev.get_or_insert_with(|| self.evaluate()).0[i],
                Kind::Signal(i) => ev.get_or_insert_with(|| self.evaluate()).1.values()[i],
            };
        }
        Ok(())
    }

    /// fmi2SetReal for a batch of value references (inputs and parameters).
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> FmuResult<()> {
        self.require(
            "fmi2SetReal",
            &[
                Phase::Instantiated,
                Phase::Initialization,
                Phase::Event,
                Phase::ContinuousTime,
                Phase::StepComplete,
            ],
        )?;
        let before_run = matches!(self.phase, Phase::Instantiated | Phase::Initialization);
        // check everything first: a refused call changes nothing
        for (vr, v) in vrs.iter().zip(values) {
            let kind = self.layout.lookup(*vr).ok_or_else(|| {
                FmuError::error(format!("fmi2SetReal: unknown value reference {vr}"))
            })?;
            let name = match kind {
                Kind::Input(i) => vars::input_name(i).to_string(),
                Kind::Param(i) => vars::param_table()[i].path.clone(),
                Kind::State(i) => {
                    return Err(FmuError::error(format!(
                    "fmi2SetReal: state {} (vr {vr}) is calculated; use fmi2SetContinuousStates",
                    self.layout.states[i]
                )))
                }
                Kind::Derivative(_) | Kind::Signal(_) => {
                    return Err(FmuError::error(format!(
                        "fmi2SetReal: vr {vr} is a calculated output and cannot be set"
                    )))
                }
            };
            if !v.is_finite() {
                return Err(FmuError::error(format!(
                    "fmi2SetReal: {name} = {v} is not finite"
                )));
            }
        }
        let old_params = self.params.clone();
        let mut params_changed = false;
        let mut inputs = self.inputs;
        for (vr, v) in vrs.iter().zip(values) {
            match self.layout.lookup(*vr) {
                Some(Kind::Input(i)) => inputs[i] = *v,
                Some(Kind::Param(i)) => {
                    params_changed |= self.params[i] != *v;
                    self.params[i] = *v;
                }
                _ => {}
            }
        }
        if params_changed && !before_run {
            // tunable change during the run: validate now, keep the old set if invalid
            let built =
                vars::params_from_values(&self.params).and_then(|p| build_model(&self.config, p));
            match built {
                Ok(m) => self.model = m,
                Err(e) => {
                    self.params = old_params;
                    return Err(FmuError::error(format!(
                        "fmi2SetReal: invalid parameters (kept the previous ones): {e}"
                    )));
                }
            }
        }
        self.inputs = inputs;
        if before_run {
            self.dirty = true;
        } else {
            self.record_inputs();
        }
        Ok(())
    }

    /// fmi2SetTime (Model Exchange).
    pub fn set_time(&mut self, t: f64) -> FmuResult<()> {
        self.require_me("fmi2SetTime")?;
        self.require("fmi2SetTime", &[Phase::Event, Phase::ContinuousTime])?;
        if !t.is_finite() {
            return Err(FmuError::error(format!(
                "fmi2SetTime: time = {} is not finite",
                Num(t)
            )));
        }
        // no stop-time check here: a Model Exchange importer's integrator may evaluate past its
        // output time and interpolate back (FMPy's CVODE does at the stop time), and the model
        // is defined there; Co-Simulation's fmi2DoStep refuses to compute past it
        self.t = t;
        Ok(())
    }

    /// fmi2SetContinuousStates.
    pub fn set_states(&mut self, x: &[f64]) -> FmuResult<()> {
        self.require_me("fmi2SetContinuousStates")?;
        self.require(
            "fmi2SetContinuousStates",
            &[Phase::Event, Phase::ContinuousTime],
        )?;
        self.check_len("fmi2SetContinuousStates", x.len())?;
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(FmuError::error(format!(
                "fmi2SetContinuousStates: {} = {} is not finite",
                self.layout.states[i], x[i]
            )));
        }
        self.x.copy_from_slice(x);
        Ok(())
    }

    /// fmi2GetContinuousStates.
    pub fn get_states(&mut self, out: &mut [f64]) -> FmuResult<()> {
        self.require_me("fmi2GetContinuousStates")?;
        self.require(
            "fmi2GetContinuousStates",
            &[
                Phase::Initialization,
                Phase::Event,
                Phase::ContinuousTime,
                Phase::Terminated,
            ],
        )?;
        self.check_len("fmi2GetContinuousStates", out.len())?;
        self.ensure_initialized()?;
        out.copy_from_slice(&self.x);
        Ok(())
    }

    fn check_len(&self, what: &str, n: usize) -> FmuResult<()> {
        let nx = self.n_states();
        if n == nx {
            Ok(())
        } else {
            Err(FmuError::error(format!("{what}: nx = {n} (expected {nx})")))
        }
    }

    /// fmi2GetDerivatives.
    pub fn get_derivatives(&mut self, out: &mut [f64]) -> FmuResult<()> {
        self.require_me("fmi2GetDerivatives")?;
        self.require(
            "fmi2GetDerivatives",
            &[
                Phase::Initialization,
                Phase::Event,
                Phase::ContinuousTime,
                Phase::Terminated,
            ],
        )?;
        self.check_len("fmi2GetDerivatives", out.len())?;
        self.ensure_initialized()?;
        let (dx, _) = self.evaluate();
        if let Some(i) = dx.iter().position(|v| !v.is_finite()) {
            return Err(FmuError::discard(format!(
                "fmi2GetDerivatives: derivative of {} is {} at t = {} (state outside the model's range)",
                self.layout.states[i], dx[i], self.t
            )));
        }
        out.copy_from_slice(&dx);
        Ok(())
    }

    /// fmi2GetDirectionalDerivative: `dv_unknown = (d unknowns / d knowns) dv_known` at the
    /// current time, state and inputs.
    ///
    /// In Initialization Mode the unknowns are the initial unknowns, and the states there are
    /// the steady state at the inputs: the knowns are the inputs, a state's change is that of the
    /// steady state (`-A^-1 B dv`, the DC gain `D - C A^-1 B` of the library's linearization there), a
    /// derivative's change is zero, an output's change is that of its steady-state value, and a
    /// change of u_egr or u_vgt includes its delayed copy (held at the same value).
    ///
    /// After initialization:
    /// Knowns: the inputs (both interfaces) and the states (Model Exchange). Unknowns: the state
    /// derivatives, the outputs (states and signals). The derivative with respect to an input
    /// is that of its current value: the delayed actuator commands come from the input history
    /// at `t - tau`, which a change now does not reach (with a delay of 0 they move along), so
    /// the state derivatives do not depend on the current u_egr, u_vgt. Computed along the seed
    /// by Richardson-extrapolated central differences
    /// ([`mvem::analysis::linearize::directional_derivative`], 4 model evaluations, about
    /// 1e-9 relative); at a kink of the model the averaged slopes.
    pub fn directional_derivative(
        &mut self,
        unknowns: &[u32],
        knowns: &[u32],
        dv_known: &[f64],
        out: &mut [f64],
    ) -> FmuResult<()> {
        const WHAT: &str = "fmi2GetDirectionalDerivative";
        self.require(
            WHAT,
            &[
                Phase::Initialization,
                Phase::Event,
                Phase::ContinuousTime,
                Phase::StepComplete,
                Phase::Terminated,
            ],
        )?;
        self.ensure_initialized()?;
        let initialization = self.phase == Phase::Initialization;
        let n = self.n_states();
        let mut v_x = vec![0.0; n];
        let mut v_u = [0.0; 6];
        let delays = self.delays();
        for (vr, dv) in knowns.iter().zip(dv_known) {
            if !dv.is_finite() {
                return Err(FmuError::error(format!(
                    "{WHAT}: the seed of vr {vr} is {dv}, not finite"
                )));
            }
            match self.layout.lookup(*vr) {
                Some(Kind::Input(i)) => {
                    v_u[i] += dv;
                    if i >= 2 && delays[i - 2] == 0.0 {
                        v_u[i + 2] += dv;
                    }
                }
                Some(Kind::State(_)) if initialization => {
                    return Err(FmuError::error(format!(
                        "{WHAT}: vr {vr} is a state; in Initialization Mode the states are the steady state at the inputs, so the knowns are the inputs"
                    )))
                }
                Some(Kind::State(i)) if self.interface == Interface::ModelExchange => v_x[i] += dv,
                Some(Kind::State(_)) => {
                    return Err(FmuError::error(format!(
                    "{WHAT}: vr {vr} is a state; the knowns of a Co-Simulation FMU are its inputs"
                )))
                }
                _ => {
                    return Err(FmuError::error(format!(
                        "{WHAT}: vr {vr} is not a known (an input, or a state in Model Exchange)"
                    )))
                }
            }
        }
        let mut kinds = Vec::with_capacity(unknowns.len());
        for vr in unknowns {
            match self.layout.lookup(*vr) {
                Some(k @ (Kind::State(_) | Kind::Derivative(_) | Kind::Signal(_))) => kinds.push(k),
                _ => {
                    return Err(FmuError::error(format!(
                        "{WHAT}: vr {vr} is not an unknown (a state derivative or an output)"
                    )))
                }
            }
        }
        if initialization {
            return self.initial_unknowns_derivative(&kinds, &v_u, out);
        }
        let u = self.model_input();
        let memory = self.memory;
        let (df, ds) = mvem::dispatch!(&self.model, m => {
            mvem::analysis::linearize::directional_derivative(
                m, &arr(&self.x), &u, memory, &arr(&v_x), &v_u, 1e-4,
            )
        })
        .map_err(|e| {
            FmuError::discard(format!(
                "{WHAT}: {e} at t = {} (state outside the model's range?)",
                self.t
            ))
        })?;
        for (k, o) in kinds.into_iter().zip(out.iter_mut()) {
            *o = match k {
                Kind::State(i) => v_x[i],
                Kind::Derivative(i) => df[i],
                Kind::Signal(i) => ds[i],
                Kind::Input(_) | Kind::Param(_) => unreachable!("refused above"),
            };
        }
        Ok(())
    }

    /// [`Self::directional_derivative`] in Initialization Mode, where the states are the
    /// steady state at the inputs: along the inputs' seed `v_u` (its first four entries, the
    /// current inputs; at a steady state the delayed commands move with them) the change of
    /// the steady state and of its outputs, i.e. the DC gain `D - C A^-1 B` of the library's
    /// linearization there ([`mvem::analysis::zeros::dc_gain_matrix`] of
    /// [`mvem::analysis::linearize::linearize`], the averaged slopes at a kink); a state
    /// derivative's change is zero.
    fn initial_unknowns_derivative(
        &self,
        kinds: &[Kind],
        v_u: &[f64; 6],
        out: &mut [f64],
    ) -> FmuResult<()> {
        const WHAT: &str = "fmi2GetDirectionalDerivative";
        use mvem::analysis::linearize::{linearize, LinearizeOptions};
        let outputs: Vec<String> = kinds
            .iter()
            .filter_map(|k| match *k {
                Kind::State(i) => Some(self.layout.states[i].to_string()),
                Kind::Signal(i) => Some(Signals::NAMES[i].to_string()),
                _ => None,
            })
            .collect();
        let gain = if outputs.is_empty() {
            None
        } else {
            let opts = LinearizeOptions {
                outputs,
                strict: false,
                ..LinearizeOptions::default()
            };
            let d = Drive::from_array(self.inputs);
            let lin = mvem::dispatch!(&self.model, m => linearize(m, &arr(&self.x), &d, &opts))
                .map_err(|e| {
                    FmuError::discard(format!("{WHAT}: {e} at the initial steady state"))
                })?;
            let g = mvem::analysis::zeros::dc_gain_matrix(&lin).map_err(|e| {
                FmuError::discard(format!(
                    "{WHAT}: no steady-state sensitivity at the initial inputs: {e}"
                ))
            })?;
            Some(g)
        };
        // the linear model's inputs are u_delta, u_egr, u_vgt, n_e
        let dv = [v_u[1], v_u[2], v_u[3], v_u[0]];
        let mut row = 0;
        for (k, o) in kinds.iter().zip(out.iter_mut()) {
            *o = match (k, &gain) {
                (Kind::State(_) | Kind::Signal(_), Some(g)) => {
                    row += 1;
                    (0..4).map(|c| g[(row - 1, c)] * dv[c]).sum()
                }
                _ => 0.0,
            };
        }
        Ok(())
    }

    /// fmi2GetNominalsOfContinuousStates: the model's state scales.
    pub fn nominals(&self, out: &mut [f64]) -> FmuResult<()> {
        self.require_me("fmi2GetNominalsOfContinuousStates")?;
        self.check_len("fmi2GetNominalsOfContinuousStates", out.len())?;
        let scales = mvem::dispatch!(&self.model, m => m.state_scales().to_vec());
        out.copy_from_slice(&scales);
        Ok(())
    }

    /// fmi2EnterEventMode.
    pub fn enter_event_mode(&mut self) -> FmuResult<()> {
        self.require_me("fmi2EnterEventMode")?;
        self.require("fmi2EnterEventMode", &[Phase::Event, Phase::ContinuousTime])?;
        self.phase = Phase::Event;
        Ok(())
    }

    /// fmi2EnterContinuousTimeMode.
    pub fn enter_continuous_time_mode(&mut self) -> FmuResult<()> {
        self.require_me("fmi2EnterContinuousTimeMode")?;
        self.require("fmi2EnterContinuousTimeMode", &[Phase::Event])?;
        self.phase = Phase::ContinuousTime;
        Ok(())
    }

    /// fmi2NewDiscreteStates: no discrete states; announces the next delayed input jump.
    pub fn new_discrete_states(&mut self) -> FmuResult<EventInfo> {
        self.require_me("fmi2NewDiscreteStates")?;
        self.require("fmi2NewDiscreteStates", &[Phase::Event])?;
        Ok(EventInfo {
            next_event_time: self.next_delayed_jump(),
        })
    }

    /// The first time after the current one at which a delayed actuator command jumps.
    pub fn next_delayed_jump(&self) -> Option<f64> {
        let [tau_egr, tau_vgt] = self.delays();
        let taus = [(2, tau_egr), (3, tau_vgt)];
        let eps = 1e-12 * self.t.abs().max(1.0);
        let mut next: Option<f64> = None;
        for w in self.history.windows(2) {
            for (ch, tau) in taus {
                if w[1].1[ch] != w[0].1[ch] {
                    let te = w[1].0 + tau;
                    if te > self.t + eps {
                        next = Some(next.map_or(te, |n: f64| n.min(te)));
                    }
                }
            }
        }
        next
    }

    /// fmi2CompletedIntegratorStep: nothing to update (the model is a pure function of the
    /// state, the inputs and the input history); never requests an event.
    pub fn completed_integrator_step(&mut self) -> FmuResult<()> {
        self.require_me("fmi2CompletedIntegratorStep")?;
        self.require("fmi2CompletedIntegratorStep", &[Phase::ContinuousTime])?;
        Ok(())
    }

    /// fmi2DoStep: integrate from `t_c` to `t_c + h` with the inputs held since `t_c`.
    pub fn do_step(&mut self, t_c: f64, h: f64) -> FmuResult<()> {
        if self.interface != Interface::CoSimulation {
            return Err(FmuError::error(
                "fmi2DoStep is a Co-Simulation function; this instance is Model Exchange",
            ));
        }
        self.require("fmi2DoStep", &[Phase::StepComplete])?;
        if !(h.is_finite() && h > 0.0) {
            return Err(FmuError::error(format!(
                "fmi2DoStep: communicationStepSize = {} must be finite and > 0",
                Num(h)
            )));
        }
        if !t_c.is_finite() || (t_c - self.t).abs() > 1e-9 * self.t.abs().max(1.0) {
            return Err(FmuError::error(format!(
                "fmi2DoStep: currentCommunicationPoint = {} differs from the FMU time {}",
                Num(t_c),
                Num(self.t)
            )));
        }
        let t_end = self.t + h;
        if t_end <= self.t || !t_end.is_finite() {
            return Err(FmuError::error(format!(
                "fmi2DoStep: communicationStepSize = {} at t = {} does not advance the time \
                 (below its resolution, or past the largest finite time)",
                Num(h),
                Num(self.t)
            )));
        }
        // FMI 2.0 (fmi2SetupExperiment): with a stop time defined, computing past it is an
        // error. A relative 1e-8 is allowed for rounding (FMPy clips its last communication
        // point to the stop time within `math.isclose`, 1e-9 relative).
        if let Some(ts) = self.t_stop {
            if t_end > ts + 1e-8 * ts.abs().max(1.0) {
                return Err(FmuError::error(format!(
                    "fmi2DoStep: time {} is past the stopTime {} given to fmi2SetupExperiment",
                    Num(t_end),
                    Num(ts)
                )));
            }
        }
        self.record_inputs();
        let sched = self.schedule()?;
        // Held inputs and a fresh integrator per communication step, as the plant of the closed
        // loop (`mvem::sim::stepper::plant_options`): without ROS34PW2's non-autonomous term,
        // whose evaluation at every segment start saves no step on segments this short.
        // the tolerance of fmi2SetupExperiment is the relative and the absolute one (relative
        // to each state's scale), as rtol and atol of `mvem simulate` and Python: with atol
        // fixed at 1e-6 a tighter tolerance stopped at an error of about 5e-7 (QA)
        let opts = SimOptions {
            rtol: self.rtol,
            atol: self.rtol,
            dt_out: h,
            rosw_time_derivative: false,
            ..SimOptions::default()
        };
        let one_iter = self.config.cylinder_temp == CylinderTemp::OneIteration;
        let (t0, x0, mem0) = (self.t, &self.x, self.memory);
        let stepped = mvem::dispatch!(&self.model, m => {
            Integrator::new(m, &sched, t0, arr(x0), &opts).and_then(|mut run| {
                if one_iter {
                    // carry the iterate held at the end of the previous step
                    run.memory = mem0;
                }
                let mut sink = Solution::new(&m.state_names());
                run.advance(t_end, &mut sink, false)?;
                Ok((run.y.to_vec(), run.memory))
            })
        })
        .map_err(|e| {
            FmuError::error(format!(
                "fmi2DoStep from t = {} to {}: {e}",
                Num(t0),
                Num(t_end)
            ))
        })?;
        self.x = stepped.0;
        if one_iter {
            self.memory = stepped.1;
        }
        self.t = t_end;
        Ok(())
    }

    /// The input history as a schedule (a jump at every recorded change).
    fn schedule(&self) -> FmuResult<InputSchedule> {
        let mut times = Vec::with_capacity(2 * self.history.len());
        let mut rows = Vec::with_capacity(2 * self.history.len());
        for (k, (t, v)) in self.history.iter().enumerate() {
            if k > 0 {
                times.push(*t);
                rows.push(self.history[k - 1].1);
            }
            times.push(*t);
            rows.push(*v);
        }
        InputSchedule::new(times, rows).map_err(|e| FmuError::error(format!("input history: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vars::{VR_DER, VR_INPUT, VR_PARAM, VR_SIGNAL, VR_STATE};
    use mvem::analysis::steady::simulate_from_steady;
    use mvem::model::{Engine12, Engine8, ModelOrder};

    fn vr_signal(name: &str) -> u32 {
        VR_SIGNAL + Signals::NAMES.iter().position(|n| *n == name).unwrap() as u32
    }

    fn started(iface: Interface) -> Instance {
        started_with(iface, &FmuConfig::default())
    }

    fn started_with(iface: Interface, cfg: &FmuConfig) -> Instance {
        let mut f = Instance::new(iface, cfg);
        f.setup_experiment(Some(1e-8), 0.0, Some(8.0)).unwrap();
        f.enter_initialization().unwrap();
        f.exit_initialization().unwrap();
        f
    }

    #[test]
    fn starts_at_steady_state_with_zero_derivatives() {
        let mut f = started(Interface::ModelExchange);
        let ss = steady_state(
            &Engine8::published(),
            &Drive::new(1500.0, 110.0, 80.0, 75.0),
        )
        .unwrap();
        let mut x = [0.0; 8];
        f.get_states(&mut x).unwrap();
        assert_eq!(x, ss.x);
        let mut dx = [0.0; 8];
        f.get_derivatives(&mut dx).unwrap();
        let scales = Engine8::published().state_scales();
        for i in 0..8 {
            assert!((dx[i] / scales[i]).abs() < 1e-6, "dx[{i}] = {}", dx[i]);
        }
        let mut w = [0.0];
        f.get_real(&[vr_signal("W_c")], &mut w).unwrap();
        assert_eq!(w[0], ss.signals.w_c);
    }

    /// fmi2GetDirectionalDerivative: at the start (a steady state, history = the start
    /// inputs) a state seed gives the library linearization's column of A and an input seed
    /// that of B for the undelayed inputs; the current u_egr moves no state derivative (the
    /// actuators see the history at t - tau_degr) but its output; bad calls are refused.
    #[test]
    fn directional_derivatives_are_the_linearizations_columns() {
        use mvem::analysis::linearize::{linearize, LinearizeOptions};
        let mut f = started(Interface::ModelExchange);
        let m = Engine8::published();
        let mut x = [0.0; 8];
        f.get_states(&mut x).unwrap();
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let opts = LinearizeOptions {
            outputs: vec!["W_c".into(), "M_e".into()],
            ..LinearizeOptions::default()
        };
        let lin = linearize(&m, &x, &d, &opts).unwrap();
        let ders: Vec<u32> = (0..8).map(|i| VR_DER + i).collect();
        let mut unknowns = ders.clone();
        unknowns.push(vr_signal("W_c"));
        unknowns.push(VR_STATE + 4);
        let mut out = vec![0.0; 10];
        let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-7 * scale;
        for j in 0..8u32 {
            f.directional_derivative(&unknowns, &[VR_STATE + j], &[1.0], &mut out)
                .unwrap();
            let col = lin.a.column(j as usize);
            let size = col.amax();
            for r in 0..8 {
                assert!(
                    close(out[r], col[r], size),
                    "A[{r}, {j}]: {} vs {}",
                    out[r],
                    col[r]
                );
            }
            assert!(
                close(out[8], lin.c[(0, j as usize)], lin.c.amax()),
                "C[W_c, {j}]"
            );
            assert_eq!(out[9], if j == 4 { 1.0 } else { 0.0 });
        }
        // u_delta (FMU input 1; the linear model's column 0) and n_e (input 0; column 3)
        for (input, col) in [(1u32, 0usize), (0, 3)] {
            f.directional_derivative(&unknowns, &[VR_INPUT + input], &[1.0], &mut out)
                .unwrap();
            let b = lin.b.column(col);
            for r in 0..8 {
                assert!(close(out[r], b[r], b.amax()), "B[{r}, {col}]");
            }
        }
        // the current u_egr: no state derivative, its saturated output by 1
        let u_egr_out = vr_signal("u_egr");
        let mut o = [0.0; 9];
        let mut unk = ders.clone();
        unk.push(u_egr_out);
        f.directional_derivative(&unk, &[VR_INPUT + 2], &[1.0], &mut o)
            .unwrap();
        assert!(o[..8].iter().all(|v| *v == 0.0), "{o:?}");
        assert!((o[8] - 1.0).abs() < 1e-12);
        // linear in the seed
        let mut two = [0.0; 9];
        f.directional_derivative(&unk, &[VR_STATE, VR_INPUT + 1], &[2e4, 4.0], &mut two)
            .unwrap();
        let mut a = [0.0; 9];
        let mut b = [0.0; 9];
        f.directional_derivative(&unk, &[VR_STATE], &[1e4], &mut a)
            .unwrap();
        f.directional_derivative(&unk, &[VR_INPUT + 1], &[2.0], &mut b)
            .unwrap();
        for r in 0..8 {
            assert!(
                close(two[r], 2.0 * (a[r] + b[r]), two[r].abs().max(1.0)),
                "{r}"
            );
        }
        // refused: a parameter as a known, an input as an unknown, a NaN seed
        assert!(f
            .directional_derivative(&ders, &[VR_PARAM], &[1.0], &mut out)
            .is_err());
        assert!(f
            .directional_derivative(&[VR_INPUT], &[VR_STATE], &[1.0], &mut out)
            .is_err());
        assert!(f
            .directional_derivative(&ders, &[VR_STATE], &[f64::NAN], &mut out)
            .is_err());
        // Co-Simulation: the knowns are the inputs
        let mut cs = started(Interface::CoSimulation);
        assert!(cs
            .directional_derivative(&[vr_signal("W_c")], &[VR_STATE], &[1.0], &mut out)
            .is_err());
        let mut w = [0.0];
        cs.directional_derivative(&[vr_signal("M_e")], &[VR_INPUT + 1], &[1.0], &mut w)
            .unwrap();
        let dm = lin.d[(1, 0)]; // torque per mg of fuel
        assert!(dm > 1.0 && close(w[0], dm, dm), "{} vs {dm}", w[0]);
    }

    /// fmi2GetDirectionalDerivative in Initialization Mode: the change of the initial unknowns
    /// (the steady state at the inputs, its outputs; the derivatives stay zero) per input, equal
    /// to central differences of the FMU's own initial states and outputs at shifted inputs
    /// (fmi2SetReal in Initialization Mode moves the steady state), u_egr included (its delayed
    /// copy moves along); a state as a known is refused there.
    #[test]
    fn initialization_mode_derivatives_follow_the_steady_state() {
        let n = 8u32;
        let mut unknowns: Vec<u32> = (0..n).map(|i| VR_STATE + i).collect();
        unknowns.extend((0..n).map(|i| VR_DER + i));
        unknowns.push(vr_signal("W_c"));
        unknowns.push(vr_signal("lambda_O"));
        // u_egr 60 %: away from the EGR valve's vertex at 80.06 % (eq. (38)), where the
        // differences below would straddle a kink
        let base = [1500.0, 110.0, 60.0, 75.0];
        // the initial unknowns' values at inputs shifted by e along `input`
        let values_at = |input: usize, e: f64| -> Vec<f64> {
            let mut f = Instance::new(Interface::ModelExchange, &FmuConfig::default());
            f.setup_experiment(Some(1e-8), 0.0, Some(8.0)).unwrap();
            f.enter_initialization().unwrap();
            let mut u = base;
            u[input] += e;
            f.set_real(&[VR_INPUT, VR_INPUT + 1, VR_INPUT + 2, VR_INPUT + 3], &u)
                .unwrap();
            let mut out = vec![0.0; unknowns.len()];
            f.get_real(&unknowns, &mut out).unwrap();
            out
        };
        let mut f = Instance::new(Interface::ModelExchange, &FmuConfig::default());
        f.setup_experiment(Some(1e-8), 0.0, Some(8.0)).unwrap();
        f.enter_initialization().unwrap();
        f.set_real(&[VR_INPUT, VR_INPUT + 1, VR_INPUT + 2, VR_INPUT + 3], &base)
            .unwrap();
        let mut dv = vec![0.0; unknowns.len()];
        for (input, step) in [(0usize, 10.0), (1, 2.0), (2, 1.0), (3, 1.0)] {
            f.directional_derivative(&unknowns, &[VR_INPUT + input as u32], &[1.0], &mut dv)
                .unwrap();
            let (p1, m1) = (values_at(input, step), values_at(input, -step));
            let (p2, m2) = (values_at(input, step / 2.0), values_at(input, -step / 2.0));
            let scales = Engine8::published().state_scales();
            for (r, vr) in unknowns.iter().enumerate() {
                let d1 = (p1[r] - m1[r]) / (2.0 * step);
                let d2 = (p2[r] - m2[r]) / step;
                let fd = (4.0 * d2 - d1) / 3.0;
                let scale = if r < n as usize {
                    scales[r] * 1e-6
                } else {
                    1e-9 * p1[r].abs().max(1.0)
                };
                if (n as usize..2 * n as usize).contains(&r) {
                    assert_eq!(dv[r], 0.0, "input {input}: derivative vr {vr}");
                } else {
                    assert!(
                        (dv[r] - fd).abs() <= 1e-6 * (fd.abs() + scale),
                        "input {input}, vr {vr}: {} vs {fd}",
                        dv[r]
                    );
                }
            }
            // u_egr and u_vgt move the steady state (through their delayed copies)
            assert!(dv[..n as usize].iter().any(|v| *v != 0.0), "input {input}");
        }
        assert!(f
            .directional_derivative(&unknowns, &[VR_STATE], &[1.0], &mut dv)
            .is_err());
    }

    /// Co-Simulation of a VGT step 75 -> 65 % at 0.5 s in 0.01 s communication steps; returns
    /// the final (p_im, W_c, T_em).
    fn co_sim_step(cfg: &FmuConfig) -> [f64; 3] {
        let mut f = started_with(Interface::CoSimulation, cfg);
        let mut t = 0.0;
        for k in 0..200 {
            if k == 50 {
                f.set_real(&[VR_INPUT + 3], &[65.0]).unwrap();
            }
            f.do_step(t, 0.01).unwrap();
            t = (k + 1) as f64 * 0.01;
        }
        let t_em = f
            .layout
            .states
            .iter()
            .position(|n| *n == "T_em")
            .map_or(vr_signal("T_em"), |i| VR_STATE + i as u32);
        let mut out = [0.0; 3];
        f.get_real(&[VR_STATE, vr_signal("W_c"), t_em], &mut out)
            .unwrap();
        out
    }

    fn library_step<const N: usize, M: Model<N>>(m: &M) -> [f64; 3] {
        let sched =
            InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(0.5, 3, 65.0)]).unwrap();
        let opts = SimOptions {
            rtol: 1e-8,
            ..SimOptions::default()
        };
        let sol = simulate_from_steady(m, &sched, 0.0, 2.0, &opts).unwrap();
        ["p_im", "W_c", "T_em"].map(|n| *sol.get(n).unwrap().last().unwrap())
    }

    fn assert_close(a: [f64; 3], b: [f64; 3], tol: f64) {
        for i in 0..3 {
            assert!((a[i] / b[i] - 1.0).abs() < tol, "{i}: {} vs {}", a[i], b[i]);
        }
    }

    #[test]
    fn co_simulation_step_matches_library_simulation() {
        let fmu = co_sim_step(&FmuConfig::default());
        assert_close(fmu, library_step(&Engine8::published()), 1e-6);
        let cfg12 = FmuConfig {
            order: ModelOrder::Twelve,
            ..FmuConfig::default()
        };
        let m12 = Engine12::new(Params::published(), ModelOptions::default()).unwrap();
        assert_close(co_sim_step(&cfg12), library_step(&m12), 1e-6);
    }

    /// A drive cycle's Co-Simulation changes the inputs at every communication step: the input
    /// history stays bounded (the longest delay plus HISTORY_MARGIN), and the run equals one
    /// with the whole history (the library's simulation of the same held inputs).
    #[test]
    fn the_input_history_stays_bounded() {
        let mut f = started(Interface::CoSimulation);
        let h = 0.01;
        let u_vgt = |k: usize| 70.0 + 5.0 * ((k as f64) * 0.05).sin();
        // (the helper's experiment stops at 8 s: 790 steps, ten times the history's bound)
        let n = 790;
        let mut max_len = 0;
        for k in 0..n {
            f.set_real(&[VR_INPUT + 3], &[u_vgt(k)]).unwrap();
            f.do_step(k as f64 * h, h).unwrap();
            max_len = max_len.max(f.history.len());
        }
        let tau = Params::published()
            .vgt_actuator
            .tau_dvgt
            .max(Params::published().egr_actuator.tau_degr);
        assert!(
            max_len as f64 <= (tau + HISTORY_MARGIN) / h + 3.0,
            "{max_len}"
        );
        // the same held inputs in the library (the history's pruning changes no bit: the run
        // with HISTORY_MARGIN = 1e9 gave the same p_im)
        let times: Vec<f64> = (0..n)
            .flat_map(|k| [k as f64 * h, k as f64 * h])
            .skip(1)
            .chain([n as f64 * h])
            .collect();
        let rows: Vec<[f64; 4]> = (0..n)
            .flat_map(|k| {
                let r = [1500.0, 110.0, 80.0, u_vgt(k)];
                [r, r]
            })
            .collect();
        let sched = InputSchedule::new(times, rows).unwrap();
        let opts = SimOptions {
            rtol: 1e-8,
            ..SimOptions::default()
        };
        let m = Engine8::published();
        // the instance starts at the steady state of its start inputs (u_vgt 75 %)
        let x0 = mvem::analysis::steady::steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 75.0))
            .unwrap()
            .x;
        let sol = mvem::sim::simulate(
            &m,
            &sched,
            0.0,
            n as f64 * h,
            mvem::sim::Start::State(x0),
            &opts,
        )
        .unwrap();
        let mut p_im = [0.0];
        f.get_real(&[VR_STATE], &mut p_im).unwrap();
        let lib = *sol.get("p_im").unwrap().last().unwrap();
        assert!((p_im[0] / lib - 1.0).abs() < 1e-6, "{} {lib}", p_im[0]);
    }

    /// fmi2SetupExperiment's tolerance is rtol and atol of the Co-Simulation's integrator: at
    /// 1e-11 the VGT step agrees with the library's rtol = atol = 1e-11 run to 1e-9 (with atol
    /// held at 1e-6 the error stayed near 5e-7 whatever the tolerance).
    #[test]
    fn the_co_simulation_tolerance_is_relative_and_absolute() {
        let mut f = Instance::new(Interface::CoSimulation, &FmuConfig::default());
        f.setup_experiment(Some(1e-11), 0.0, Some(8.0)).unwrap();
        f.enter_initialization().unwrap();
        f.exit_initialization().unwrap();
        for k in 0..200 {
            if k == 50 {
                f.set_real(&[VR_INPUT + 3], &[65.0]).unwrap();
            }
            f.do_step(k as f64 * 0.01, 0.01).unwrap();
        }
        let mut out = [0.0; 2];
        f.get_real(&[VR_STATE, VR_STATE + 1], &mut out).unwrap();
        let sched =
            InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(0.5, 3, 65.0)]).unwrap();
        let opts = SimOptions {
            rtol: 1e-11,
            atol: 1e-11,
            ..SimOptions::default()
        };
        let sol = simulate_from_steady(&Engine8::published(), &sched, 0.0, 2.0, &opts).unwrap();
        for (i, n) in ["p_im", "p_em"].iter().enumerate() {
            let lib = *sol.get(n).unwrap().last().unwrap();
            assert!(
                (out[i] / lib - 1.0).abs() < 1e-9,
                "{n}: {} vs {lib}",
                out[i]
            );
        }
    }

    #[test]
    fn one_iteration_co_simulation_matches_library_and_refuses_model_exchange() {
        let cfg = FmuConfig {
            cylinder_temp: CylinderTemp::OneIteration,
            ..FmuConfig::default()
        };
        let opts = ModelOptions {
            cylinder_temp: CylinderTemp::OneIteration,
            ..ModelOptions::default()
        };
        let m = Engine8::new(Params::published(), opts).unwrap();
        // the one-iteration solution depends on the step sequence: 1e-5 relative here
        assert_close(co_sim_step(&cfg), library_step(&m), 1e-5);
        assert!(!cfg.model_exchange());
    }

    /// x_egr of a one-iteration Co-Simulation of a fuel step 110 -> 150 mg at 0.5 s in 0.01 s
    /// communication steps with FMU tolerance `tol`, relative to the library's one-iteration
    /// simulation at rtol `lib_rtol`: the largest relative difference over (0.5, 2] s.
    fn one_iteration_fuel_step_difference(tol: f64, lib_rtol: f64) -> f64 {
        let cfg = FmuConfig {
            cylinder_temp: CylinderTemp::OneIteration,
            ..FmuConfig::default()
        };
        let mut f = Instance::new(Interface::CoSimulation, &cfg);
        f.setup_experiment(Some(tol), 0.0, Some(2.0)).unwrap();
        f.enter_initialization().unwrap();
        f.exit_initialization().unwrap();
        let m = Engine8::new(
            Params::published(),
            ModelOptions {
                cylinder_temp: CylinderTemp::OneIteration,
                ..ModelOptions::default()
            },
        )
        .unwrap();
        let sched = InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(0.5, 1, 150.0)])
            .unwrap();
        let opts = SimOptions {
            rtol: lib_rtol,
            atol: lib_rtol,
            ..SimOptions::default()
        };
        let sol = simulate_from_steady(&m, &sched, 0.0, 2.0, &opts).unwrap();
        let lib = sol.get("x_egr").unwrap();
        let mut worst: f64 = 0.0;
        for k in 0..200 {
            if k == 50 {
                f.set_real(&[VR_INPUT + 1], &[150.0]).unwrap();
            }
            f.do_step(k as f64 * 0.01, 0.01).unwrap();
            let mut x_egr = [0.0];
            f.get_real(&[vr_signal("x_egr")], &mut x_egr).unwrap();
            if k >= 50 {
                worst = worst.max((x_egr[0] / lib[k + 1] - 1.0).abs());
            }
        }
        worst
    }

    /// QA: after a fuel step the one-iteration Co-Simulation's x_egr was 4.9e-4 off the
    /// library's, where the docs said about 1e-5. The iterate is carried between fmi2DoStep
    /// calls as the library carries it between steps: at tolerance 1e-9 both agree to 2e-5
    /// (measured 3.7e-6; with the carry removed, each communication step starting from the
    /// converged fixed point, 1.05e-4: the test fails). At the default 1e-6 the one-iteration
    /// solution itself depends on the step sizes (the iterate lags one iteration per accepted
    /// step, and the fuel step moves its fixed point): 1.09e-3 here, about as much as the
    /// library at rtol 1e-6 differs from itself at 1e-9 (1.2e-3; docs/fmu-python.md).
    #[test]
    fn one_iteration_co_simulation_follows_a_fuel_step() {
        let tight = one_iteration_fuel_step_difference(1e-9, 1e-9);
        assert!(tight < 2e-5, "{tight:e}");
        let default = one_iteration_fuel_step_difference(1e-6, 1e-9);
        assert!(default < 3e-3, "{default:e}");
        eprintln!("one-iteration fuel step x_egr: {tight:e} (1e-9), {default:e} (1e-6)");
    }

    /// QA: the FMU accepted non-integer counts. n_cyl = 6.5 and n_pipe = 1.5 are refused at
    /// fmi2ExitInitializationMode, and during a run at fmi2SetReal (the previous value kept),
    /// with a message naming the parameter (logged by the C ABI).
    #[test]
    fn non_integer_counts_are_refused() {
        for (name, v, what) in [
            ("cylinder.n_cyl", 6.5, "cylinders"),
            ("exhaust_pipe.n_pipe", 1.5, "pipes"),
        ] {
            let vr = VR_PARAM
                + vars::param_table()
                    .iter()
                    .position(|p| p.path == name)
                    .unwrap() as u32;
            let msg = format!("{name} = {v}: a number of {what} must be a whole number");
            let mut f = Instance::new(Interface::CoSimulation, &FmuConfig::default());
            f.setup_experiment(None, 0.0, None).unwrap();
            f.enter_initialization().unwrap();
            f.set_real(&[vr], &[v]).unwrap();
            let e = f.exit_initialization().unwrap_err();
            assert!(e.message.contains(&msg), "{}", e.message);
            let mut g = started(Interface::CoSimulation);
            let mut old = [0.0];
            g.get_real(&[vr], &mut old).unwrap();
            let e = g.set_real(&[vr], &[v]).unwrap_err();
            assert!(e.message.contains(&msg), "{}", e.message);
            let mut now = [0.0];
            g.get_real(&[vr], &mut now).unwrap();
            assert_eq!(now, old);
            g.do_step(0.0, 0.1).unwrap();
        }
    }

    #[test]
    fn delayed_jump_is_announced_as_time_event() {
        let mut f = started(Interface::ModelExchange);
        let tau = Params::published().vgt_actuator.tau_dvgt;
        f.enter_continuous_time_mode().unwrap();
        f.set_time(1.0).unwrap();
        f.enter_event_mode().unwrap();
        f.set_real(&[VR_INPUT + 3], &[65.0]).unwrap();
        let ev = f.new_discrete_states().unwrap();
        assert_eq!(ev.next_event_time, Some(1.0 + tau));
        // before the delayed jump the VGT actuator still sees 75 %
        let mut d = [0.0];
        f.get_real(&[VR_DER + 7], &mut d).unwrap();
        assert_eq!(d[0], 0.0);
        f.set_time(1.0 + tau).unwrap();
        f.get_real(&[VR_DER + 7], &mut d).unwrap();
        assert!(d[0] < 0.0);
        assert_eq!(f.new_discrete_states().unwrap().next_event_time, None);
    }

    #[test]
    fn bad_calls_are_refused_without_changes() {
        let mut f = Instance::new(Interface::CoSimulation, &FmuConfig::default());
        assert!(f.do_step(0.0, 0.1).is_err()); // before initialization
        assert!(f.set_real(&[VR_INPUT], &[f64::NAN]).is_err());
        assert!(f.set_real(&[9999], &[1.0]).is_err());
        assert!(f.set_real(&[VR_STATE], &[1.0]).is_err());
        let mut f = started(Interface::CoSimulation);
        assert!(f.do_step(0.5, 0.1).is_err()); // wrong communication point
        assert!(f.do_step(0.0, -1.0).is_err());
        assert!(f.get_derivatives(&mut [0.0; 8]).is_err()); // ME-only
                                                            // invalid tunable parameter value is rejected and the old one kept
        let i = vars::param_table()
            .iter()
            .position(|p| p.path == "turbo.j_t")
            .unwrap();
        let vr = VR_PARAM + i as u32;
        let mut old = [0.0];
        f.get_real(&[vr], &mut old).unwrap();
        assert!(f.set_real(&[vr], &[-1.0]).is_err());
        let mut now = [0.0];
        f.get_real(&[vr], &mut now).unwrap();
        assert_eq!(old, now);
        f.do_step(0.0, 0.1).unwrap();
    }

    #[test]
    fn steps_past_the_stop_time_or_without_progress_are_refused() {
        // started(): stopTime 8 s
        let mut f = started(Interface::CoSimulation);
        f.do_step(0.0, 7.5).unwrap();
        let x = f.x.clone();
        let e = f.do_step(7.5, 0.6).unwrap_err();
        assert!(e.message.contains("past the stopTime 8"), "{}", e.message);
        assert_eq!(
            (f.time(), &f.x),
            (7.5, &x),
            "a refused step changes nothing"
        );
        // up to the stop time, and within the rounding allowance beyond it
        f.do_step(7.5, 0.5 + 4e-8).unwrap();
        assert!(f.do_step(f.time(), 1e-6).is_err());

        // without a stop time any length is allowed, but the time must advance
        let mut f = Instance::new(Interface::CoSimulation, &FmuConfig::default());
        f.setup_experiment(None, 1e9, None).unwrap();
        f.enter_initialization().unwrap();
        f.exit_initialization().unwrap();
        let e = f.do_step(1e9, 1e-8).unwrap_err(); // 1e9 + 1e-8 == 1e9
        assert!(
            e.message.contains("does not advance the time"),
            "{}",
            e.message
        );
        assert_eq!(f.time(), 1e9);
        // a step to beyond mvem::sim::MAX_TIME (1e9 s) is refused before any integration
        // (QA: an absurd horizon ran for minutes in the library), the instance unchanged
        let mut f = Instance::new(Interface::CoSimulation, &FmuConfig::default());
        f.setup_experiment(None, 0.0, None).unwrap();
        f.enter_initialization().unwrap();
        f.exit_initialization().unwrap();
        let e = f.do_step(0.0, 1e308).unwrap_err();
        assert!(
            e.message.contains("end time 1e308 s is beyond the 1e9 s"),
            "{}",
            e.message
        );
        assert_eq!(f.time(), 0.0);
        f.do_step(0.0, 1.0).unwrap();
        // an experiment starting or stopping beyond MAX_TIME is refused when it is set up
        for (start, stop, name) in [
            (1e17, None, "startTime = 1e17 s"),
            (-2e9, None, "startTime = -2000000000 s"),
            (0.0, Some(1e308), "stopTime = 1e308 s"),
        ] {
            let mut f = Instance::new(Interface::CoSimulation, &FmuConfig::default());
            let e = f.setup_experiment(None, start, stop).unwrap_err();
            assert!(
                e.message.contains(name) && e.message.contains("beyond the 1e9 s"),
                "{}",
                e.message
            );
        }

        // Model Exchange: fmi2SetTime may go past the stop time (an importer's integrator
        // evaluates there and interpolates back)
        let mut f = started(Interface::ModelExchange);
        f.enter_continuous_time_mode().unwrap();
        f.set_time(8.09).unwrap();
        let mut dx = [0.0; 8];
        f.get_derivatives(&mut dx).unwrap();
        assert!(dx.iter().all(|v| v.is_finite()));
    }
}
