//! Simulation: input schedules, exact transport delays, adaptive error-controlled integration.
//!
//! Two integrators, chosen by measurement (`docs/integrator.md`): the default Rosenbrock-W
//! method ROS34PW2 ([`Method::Rosenbrock34`], order 3(2), L-stable, lagged finite-difference
//! Jacobian) and the explicit Dormand-Prince 5(4) pair ([`Method::Dopri5`], 4th-order dense
//! output). The 8-state model is mildly stiff (fastest poles about -116 1/s at idle, median
//! -72 1/s along the WHTC), so the explicit pair is stability-limited; the W-method is not, and
//! takes far fewer steps on smooth stretches.
//!
//! The transport delays of the actuators act on known input functions, so they are exact: the
//! delayed command is the schedule evaluated at `t - tau` (constant history before the first
//! row). The integrator never steps over an input change: the time axis is split at every
//! breakpoint of every channel (jumps and kinks), shifted by the delay of each channel that
//! feeds a delay, and each segment is integrated with the inputs evaluated strictly inside the
//! segment, so a step on either side of a jump sees one smooth input.
//!
//! The actuator states ([`Model::linear_lags`]) are first-order lags of those delayed commands;
//! on a segment the command is linear, so by default they are integrated in closed form there and
//! the W-method integrates the other states only ([`SimOptions::exact_actuators`],
//! `docs/integrator.md`).

mod dopri5;
pub mod input;
mod linalg;
mod rosw;
pub mod stepper;

pub use input::{BreakKind, InputSchedule, ScheduleError, Side};

use crate::components::cylinder::SeligerIterate;
use crate::model::{Actuators, CylinderTemp, LagCommand, LinearLag, Model, ModelInput, Signals};
use dopri5::*;
use std::fmt;

/// Integration and output options.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Relative tolerance (default 1e-6).
    pub rtol: f64,
    /// Absolute tolerance, relative to each state's scale (1e5 Pa for pressures, 0.1 for oxygen
    /// fractions, 1e4 rad/s for omega_t, 100 % for actuator states); default 1e-6 (0.1 Pa,
    /// 1e-7, 0.01 rad/s, 1e-4 %).
    pub atol: f64,
    /// Output interval [s] (default 0.01); the end time is always output.
    pub dt_out: f64,
    /// Maximum step size [s] (default: unbounded).
    pub h_max: f64,
    /// Stop at input breakpoints (default true). With `false` the step is bounded by
    /// `h_max` only (set it to the row spacing), for comparison.
    pub stop_at_breakpoints: bool,
    /// Maximum number of steps before giving up.
    pub max_steps: usize,
    /// Integration method.
    pub method: Method,
    /// Integrate the actuator states ([`Model::linear_lags`]: first-order lags of the delayed,
    /// saturated commands, eqs (40), (41), (57)) in closed form on every segment where their
    /// driving command is linear, and the other states by the W-method with them as known
    /// functions of time (default true; [`Method::Rosenbrock34`] only). `false` integrates all
    /// states with the W-method, for comparison.
    pub exact_actuators: bool,
}

/// Integration method (see `docs/integrator.md` for the measured comparison).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Rosenbrock-W method ROS34PW2 (Rang & Angermann 2005): 4 stages, order 3(2), L-stable,
    /// stiffly accurate, valid with an approximate (lagged, finite-difference) Jacobian. Default:
    /// the model is mildly stiff (poles down to about -120 1/s at idle) and the drive cycle has
    /// an input breakpoint every ~0.13 s on average, so a one-step linearly implicit method wins.
    #[default]
    Rosenbrock34,
    /// Dormand-Prince 5(4), explicit, with 4th-order dense output (Hairer's DOPRI5).
    Dopri5,
}

impl Method {
    /// Classical order of the propagating method.
    pub fn order(self) -> u32 {
        match self {
            Method::Rosenbrock34 => 3,
            Method::Dopri5 => 5,
        }
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            atol: 1e-6,
            dt_out: 0.01,
            h_max: f64::INFINITY,
            stop_at_breakpoints: true,
            max_steps: 50_000_000,
            method: Method::default(),
            exact_actuators: true,
        }
    }
}

impl SimOptions {
    /// Check the options; the message names the field.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |field: &'static str, value: f64, constraint: &'static str| {
            Err(SimError::BadOption {
                field,
                value,
                constraint,
            })
        };
        if !(self.rtol.is_finite() && self.rtol > 0.0 && self.rtol < 1.0) {
            return bad("rtol", self.rtol, "must lie in (0, 1)");
        }
        if self.rtol < 1e-13 {
            return bad("rtol", self.rtol, "must be >= 1e-13 (double precision)");
        }
        if !(self.atol.is_finite() && self.atol > 0.0) {
            return bad("atol", self.atol, "must be finite and > 0");
        }
        if !(self.dt_out.is_finite() && self.dt_out > 0.0) {
            return bad("dt", self.dt_out, "output interval must be finite and > 0");
        }
        if self.h_max.is_nan() || self.h_max <= 0.0 {
            return bad("h_max", self.h_max, "must be > 0");
        }
        Ok(())
    }
}

/// Solver statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected steps.
    pub rejected: usize,
    /// Model (right-hand side) evaluations, excluding output evaluations.
    pub rhs_evals: usize,
    /// Input breakpoints the integrator stopped at.
    pub breakpoints: usize,
    /// Jacobian evaluations (finite differences; Rosenbrock method only).
    pub jacobians: usize,
    /// LU factorizations of the iteration matrix (Rosenbrock method only).
    pub lu: usize,
    /// Output samples.
    pub outputs: usize,
}

/// A failed simulation: what, when, and the state at that time.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// An option is out of range.
    #[error("option {field} = {value}: {constraint}")]
    BadOption {
        /// Option name.
        field: &'static str,
        /// Value.
        value: f64,
        /// Constraint.
        constraint: &'static str,
    },
    /// The end time is not after the start time.
    #[error("end time {t_end} s must be after start time {t0} s")]
    BadInterval {
        /// Start.
        t0: f64,
        /// End.
        t_end: f64,
    },
    /// A derivative or the initial state is NaN or infinite.
    #[error("non-finite {what} {name} = {value} at t = {t} s; state: {state}. Hint: {hint}")]
    NonFinite {
        /// Time [s].
        t: f64,
        /// "derivative of" / "initial state".
        what: &'static str,
        /// State name.
        name: String,
        /// Value.
        value: f64,
        /// The state at that time, formatted.
        state: StateDump,
        /// What probably went wrong.
        hint: &'static str,
    },
    /// The step size fell below the resolution of the time axis.
    #[error("step size {h:e} s too small at t = {t} s; limiting state: {limiting}; state: {state}. Hint: the model may have left its valid region (equilibrium lost, inputs out of range), or the tolerance is too tight")]
    StepSizeTooSmall {
        /// Time [s].
        t: f64,
        /// Step size [s].
        h: f64,
        /// The state whose error estimate limited the step, with that error.
        limiting: String,
        /// State.
        state: StateDump,
    },
    /// More steps than allowed.
    #[error("more than {max_steps} steps before t = {t} s; state: {state}. Hint: raise SimOptions::max_steps for long or fast-varying inputs, loosen a very tight tolerance, or check the inputs (equilibrium lost, inputs far out of range make the model stiff)")]
    TooManySteps {
        /// Limit.
        max_steps: usize,
        /// Time reached.
        t: f64,
        /// State.
        state: StateDump,
    },
    /// The initial state could not be computed.
    #[error("initial steady state: {0}")]
    Initial(String),
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

fn dump<const N: usize, M: Model<N>>(m: &M, y: &[f64; N]) -> StateDump {
    StateDump(
        m.state_names()
            .iter()
            .copied()
            .zip(y.iter().copied())
            .collect(),
    )
}

/// Simulation result: named columns sampled at the output times.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Column names: `t`, the states, then the [`Signals::NAMES`] that are not state names
    /// (each name once; `T_im`, `T_em`, `p_c` are states of the 10/12-state models).
    pub names: Vec<String>,
    /// Column data, one vector per name.
    pub columns: Vec<Vec<f64>>,
    /// Solver statistics.
    pub stats: SimStats,
    /// Guards of the authors' implementation that were active at any output sample.
    pub guards_seen: u32,
    /// Column of each entry of [`Signals::NAMES`] (`None`: the signal is a state column).
    signal_columns: Vec<Option<usize>>,
}

impl Solution {
    /// An empty solution with the columns `t`, the states and the signals.
    pub fn new(state_names: &[&'static str]) -> Self {
        let mut names = vec!["t".to_string()];
        names.extend(state_names.iter().map(|s| s.to_string()));
        // A signal that is also a state (T_im, T_em, p_c of the 10/12-state models) appears
        // once, as the state.
        names.extend(
            Signals::NAMES
                .iter()
                .filter(|s| !state_names.contains(s))
                .map(|s| s.to_string()),
        );
        let mut c = state_names.len();
        let signal_columns = Signals::NAMES
            .iter()
            .map(|s| {
                (!state_names.contains(s)).then(|| {
                    c += 1;
                    c
                })
            })
            .collect();
        let columns = vec![Vec::new(); names.len()];
        Self {
            names,
            columns,
            stats: SimStats::default(),
            guards_seen: 0,
            signal_columns,
        }
    }

    /// Reserve room for `n` more samples in every column.
    fn reserve(&mut self, n: usize) {
        for c in &mut self.columns {
            c.reserve(n);
        }
    }

    fn push<const N: usize>(&mut self, t: f64, y: &[f64; N], s: &Signals) {
        self.columns[0].push(t);
        for i in 0..N {
            self.columns[1 + i].push(y[i]);
        }
        // signal columns follow the states in `Signals::NAMES` order, minus the state names
        for (col, v) in self.signal_columns.iter().zip(s.values()) {
            if let Some(c) = col {
                self.columns[*c].push(v);
            }
        }
        self.guards_seen |= s.guards;
    }

    /// Column by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    /// Output times.
    pub fn t(&self) -> &[f64] {
        &self.columns[0]
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.columns[0].len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.columns[0].is_empty()
    }

    /// Row `i` as (name, value) pairs.
    pub fn row(&self, i: usize) -> Vec<(&str, f64)> {
        self.names
            .iter()
            .zip(&self.columns)
            .map(|(n, c)| (n.as_str(), c[i]))
            .collect()
    }
}

/// A linear piece of a schedule channel: (t_lo, t_hi, t_ref, v_ref, slope), see
/// [`InputSchedule::piece`].
type Piece = (f64, f64, f64, f64, f64);

/// The inputs of the model over time plus the delays: evaluates [`ModelInput`] for one
/// integration segment `[a, b]` between consecutive stop times, always from inside the segment
/// (so a step at `a` or `b` is seen from the correct side).
pub struct SegmentInputs<'a> {
    sched: &'a InputSchedule,
    tau_egr: f64,
    tau_vgt: f64,
    hints: [usize; 6],
    /// The two most recently used linear pieces per lookup: (t_lo, t_hi, t_ref, v_ref, slope).
    /// Pieces come from the schedule alone, so the cache stays valid from one segment to the
    /// next. Two, because the undelayed u_egr and u_vgt commands are not stop times when the
    /// actuators are dynamic (only their delayed copies are), so a segment can straddle one of
    /// their kinks and the stages of a step alternate between the two pieces.
    pieces: [[Piece; 2]; 6],
    /// Lookup window per lookup: inputs are evaluated at times clamped strictly inside the
    /// segment (shifted back by the lookup's delay), or unclamped if the segment is too short.
    window: [(f64, f64); 6],
    /// Per lookup, the linear piece (t_ref, v_ref, slope) that covers the whole window of the
    /// current segment, if one does (always for the lookups whose kinks are stop times).
    linear: [Option<(f64, f64, f64)>; 6],
    /// Chord (t_ref, v_ref, slope) of the delayed u_egr and u_vgt commands over the window of
    /// the current segment, in lookup time. Their kinks are stop times, so on a segment they
    /// are linear up to the schedule's collinearity tolerance (rows within
    /// [`InputSchedule::collinear_tol`] of a line are not breakpoints).
    chords: [Option<(f64, f64, f64)>; 2],
}

impl<'a> SegmentInputs<'a> {
    /// Inputs of `model` driven by `sched` on the segment `[a, b]`.
    pub fn new<const N: usize, M: Model<N>>(
        model: &M,
        sched: &'a InputSchedule,
        a: f64,
        b: f64,
    ) -> Self {
        let p = model.params();
        let mut me = Self {
            sched,
            tau_egr: p.egr_actuator.tau_degr,
            tau_vgt: p.vgt_actuator.tau_dvgt,
            hints: [0; 6],
            pieces: [[(f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0, 0.0); 2]; 6],
            window: [(f64::NEG_INFINITY, f64::INFINITY); 6],
            linear: [None; 6],
            chords: [None; 2],
        };
        me.set_segment(a, b);
        me
    }

    /// Move to the segment `[a, b]` (keeps the search cursors and cached pieces).
    pub fn set_segment(&mut self, a: f64, b: f64) {
        for k in 0..6 {
            let shift = self.shift(k);
            let lo = a - shift + Self::delta(a);
            let hi = b - shift - Self::delta(b);
            self.window[k] = if hi > lo {
                (lo, hi)
            } else {
                (f64::NEG_INFINITY, f64::INFINITY)
            };
        }
        for k in 0..6 {
            let (lo, hi) = self.window[k];
            self.linear[k] = None;
            if lo.is_finite() {
                let mut pc = self.pieces[k][0];
                if !(pc.0 <= lo && lo <= pc.1) {
                    pc = self
                        .sched
                        .piece(Self::CHANNEL[k], lo, Side::Right, &mut self.hints[k]);
                    self.pieces[k] = [pc, self.pieces[k][0]];
                }
                if pc.0 <= lo && hi <= pc.1 {
                    self.linear[k] = Some((pc.2, pc.3, pc.4));
                }
            }
        }
        for (i, k) in [4, 5].into_iter().enumerate() {
            let (lo, hi) = self.window[k];
            self.chords[i] = match self.linear[k] {
                Some(line) => Some(line),
                None if lo.is_finite() => {
                    let ch = Self::CHANNEL[k];
                    let v_lo = self
                        .sched
                        .value_hint(ch, lo, Side::Right, &mut self.hints[k]);
                    let v_hi = self
                        .sched
                        .value_hint(ch, hi, Side::Right, &mut self.hints[k]);
                    Some((lo, v_lo, (v_hi - v_lo) / (hi - lo)))
                }
                None => None,
            };
        }
    }

    /// The delayed command `cmd` on the current segment as a line in simulation time t,
    /// `v(t) = v_ref + slope (t - t_ref)` (its chord over the segment; `None` for a segment
    /// shorter than the lookup margins).
    fn delayed_line(&self, cmd: LagCommand) -> Option<(f64, f64, f64)> {
        let i = match cmd {
            LagCommand::Egr => 0,
            LagCommand::Vgt => 1,
        };
        let shift = self.shift(4 + i);
        self.chords[i].map(|(t_ref, v_ref, slope)| (t_ref + shift, v_ref, slope))
    }

    /// Delay [s] of lookup `k` (the actuator delays for the delayed commands, else none).
    #[inline(always)]
    fn shift(&self, k: usize) -> f64 {
        match k {
            4 => self.tau_egr,
            5 => self.tau_vgt,
            _ => 0.0,
        }
    }

    /// Schedule channel of each lookup (n_e, u_delta, u_egr, u_vgt, delayed u_egr, delayed
    /// u_vgt).
    const CHANNEL: [usize; 6] = [0, 1, 2, 3, 2, 3];

    #[inline]
    fn delta(t: f64) -> f64 {
        1e-12 * t.abs().max(1.0)
    }

    /// Value of lookup `k` (channel [`Self::CHANNEL`]`[k]`, delayed by [`Self::shift`]) at `t`.
    #[inline(always)]
    fn value(&mut self, k: usize, t: f64) -> f64 {
        let (lo, hi) = self.window[k];
        let tq = (t - self.shift(k)).clamp(lo, hi);
        if let Some((t_ref, v_ref, slope)) = self.linear[k] {
            return v_ref + slope * (tq - t_ref);
        }
        let p0 = &self.pieces[k][0];
        if p0.0 <= tq && tq <= p0.1 {
            return p0.3 + p0.4 * (tq - p0.2);
        }
        let p1 = &self.pieces[k][1];
        let pc = if p1.0 <= tq && tq <= p1.1 {
            *p1
        } else {
            self.sched
                .piece(Self::CHANNEL[k], tq, Side::Right, &mut self.hints[k])
        };
        self.pieces[k] = [pc, self.pieces[k][0]];
        pc.3 + pc.4 * (tq - pc.2)
    }

    /// Model inputs at `t` in the segment: current values and delayed actuator commands.
    #[inline]
    pub fn at(&mut self, t: f64) -> ModelInput {
        let now = crate::model::Drive::new(
            self.value(0, t),
            self.value(1, t),
            self.value(2, t),
            self.value(3, t),
        );
        ModelInput {
            now,
            u_egr_delayed: self.value(4, t),
            u_vgt_delayed: self.value(5, t),
        }
    }
}

/// Where the simulation starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start<const N: usize> {
    /// The steady state at the first inputs (default).
    SteadyState,
    /// A given state (clipped into the integrator limits of the authors' implementation).
    State([f64; N]),
}

/// Sorted stop times in (t0, t_end) with a flag for jumps: every breakpoint of every channel,
/// shifted by the delay of the path it feeds (n_e, u_delta: none; u_egr: tau_degr, u_vgt:
/// tau_dvgt, plus no shift when the actuators are bypassed).
pub fn stop_times<const N: usize, M: Model<N>>(
    m: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
) -> Vec<(f64, bool)> {
    let p = m.params();
    let bypass = m.options().actuators == Actuators::Bypass;
    let mut v: Vec<(f64, bool)> = Vec::new();
    let mut add = |ch: usize, shifts: &[f64]| {
        for (tb, kind) in sched.breakpoints(ch) {
            for s in shifts {
                v.push((tb + s, kind == BreakKind::Jump));
            }
        }
    };
    add(0, &[0.0]);
    add(1, &[0.0]);
    let (te, tv) = (p.egr_actuator.tau_degr, p.vgt_actuator.tau_dvgt);
    if bypass {
        add(2, &[0.0, te]);
        add(3, &[0.0, tv]);
    } else {
        add(2, &[te]);
        add(3, &[tv]);
    }
    v.retain(|(t, _)| {
        *t > t0 + SegmentInputs::delta(t0) * 10.0 && *t < t_end - SegmentInputs::delta(t_end) * 10.0
    });
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    // merge stops closer than the input evaluation margin
    let mut out: Vec<(f64, bool)> = Vec::with_capacity(v.len());
    for (t, jump) in v {
        match out.last_mut() {
            Some(last) if t - last.0 <= 10.0 * SegmentInputs::delta(t) => last.1 |= jump,
            _ => out.push((t, jump)),
        }
    }
    out
}

/// Simulate `model` driven by `sched` from `t0` to `t_end`.
///
/// The result has an output sample every `opts.dt_out` from `t0` and at `t_end`. Output samples
/// at an input step show the value after the step (inputs are right-continuous).
pub fn simulate<const N: usize, M: Model<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    start: Start<N>,
    opts: &SimOptions,
) -> Result<Solution, SimError> {
    opts.validate()?;
    if !(t0.is_finite() && t_end.is_finite() && t_end > t0) {
        return Err(SimError::BadInterval { t0, t_end });
    }
    let y0 = match start {
        Start::State(y) => y,
        Start::SteadyState => {
            let mut h = 0;
            let d = crate::model::Drive::from_array(std::array::from_fn(|c| {
                sched.value_hint(c, t0, Side::Right, &mut h)
            }));
            crate::analysis::steady::steady_state(model, &d)
                .map_err(|e| SimError::Initial(e.to_string()))?
                .x
        }
    };
    let mut run = Integrator::new(model, sched, t0, y0, opts)?;
    let mut sol = Solution::new(&model.state_names());
    let samples = ((t_end - t0) / opts.dt_out).ceil() + 2.0;
    sol.reserve(samples.min(1e7) as usize);
    run.advance(t_end, &mut sol, true)?;
    sol.stats = run.stats;
    Ok(sol)
}

/// Restartable integrator state (the solver does not own the model or the inputs).
pub struct Integrator<'a, const N: usize, M: Model<N>> {
    model: &'a M,
    sched: &'a InputSchedule,
    opts: SimOptions,
    /// Current time [s].
    pub t: f64,
    /// Current state.
    pub y: [f64; N],
    /// Cylinder-temperature memory (one-iteration mode).
    pub memory: SeligerIterate,
    f: Option<[f64; N]>,
    h: f64,
    err_old: f64,
    atol: [f64; N],
    bounds: [(f64, f64); N],
    next_out: u64,
    t_out0: f64,
    jac: Option<[[f64; N]; N]>,
    /// Iteration matrix of the current Jacobian and step size (boxed: it is moved out and back
    /// at every step).
    lu: Option<Box<IterationMatrix<N>>>,
    jac_age: usize,
    /// Whether `jac` has all columns (false: the columns of the lag states were skipped).
    jac_full: bool,
    /// States integrated in closed form (empty: none; see [`SimOptions::exact_actuators`]).
    lags: Vec<LinearLag>,
    /// Their closed-form solution on the current segment (empty: the segment is integrated
    /// with the W-method in all states).
    lag_seg: Vec<LagSegment>,
    /// Statistics so far.
    pub stats: SimStats,
}

/// LU factors of I - gamma h J_zz, where J_zz is the Jacobian restricted to the states the
/// W-method integrates (all states, or all but the closed-form lag states if `reduced`), and J_zz
/// itself, both in the leading m x m block of the z coordinates.
struct IterationMatrix<const N: usize> {
    /// Step size [s] the factors were made for.
    h: f64,
    /// Whether the lag states are left out.
    reduced: bool,
    /// The integrated states: z[0..m] are state indices.
    z: [usize; N],
    m: usize,
    lu: [[f64; N]; N],
    piv: [usize; N],
    jz: [[f64; N]; N],
}

/// A lag state on one segment: `dx/dt = (c(t) - x)/tau` with the driving command
/// `c(t) = c_a + beta (t - t_a)` (already saturated; linear on the whole segment).
#[derive(Debug, Clone, Copy)]
struct LagSegment {
    state: usize,
    tau: f64,
    t_a: f64,
    c_a: f64,
    beta: f64,
}

impl LagSegment {
    /// Exact solution at `t + s` from `x` at `t`:
    /// x(t + s) = c(t + s) - beta tau + (x - c(t) + beta tau) exp(-s / tau).
    #[inline]
    fn advance(&self, t: f64, x: f64, s: f64) -> f64 {
        let c = |t: f64| self.c_a + self.beta * (t - self.t_a);
        let bt = self.beta * self.tau;
        c(t + s) - bt + (x - c(t) + bt) * (-s / self.tau).exp()
    }
}

/// What the integrator keeps of a model evaluation (not the signals, which are only needed at
/// output samples: moving them costs more than the arithmetic of a step).
struct Rhs<const N: usize> {
    dx: [f64; N],
    memory_next: SeligerIterate,
}

/// Result of one trial step.
struct Trial<const N: usize> {
    y1: [f64; N],
    err: f64,
    /// Local error estimate per state.
    e: [f64; N],
    dense: Option<Dense<N>>,
    /// f(t_new, y1) and the cylinder-temperature memory computed there, if the method has it.
    f1: Option<([f64; N], SeligerIterate)>,
}

/// Dense output of an accepted step.
enum Interp<const N: usize> {
    Dopri(Dense<N>),
    Hermite {
        y0: [f64; N],
        y1: [f64; N],
        f0: [f64; N],
        f1: [f64; N],
        h: f64,
    },
}

impl<const N: usize> Interp<N> {
    fn eval(&self, theta: f64) -> [f64; N] {
        match self {
            Interp::Dopri(d) => d.eval(theta),
            Interp::Hermite { y0, y1, f0, f1, h } => {
                // cubic Hermite interpolation (3rd order, matches ROS34PW2's order)
                let t = theta;
                let h00 = (1.0 + 2.0 * t) * (1.0 - t) * (1.0 - t);
                let h10 = t * (1.0 - t) * (1.0 - t);
                let h01 = t * t * (3.0 - 2.0 * t);
                let h11 = t * t * (t - 1.0);
                std::array::from_fn(|i| {
                    h00 * y0[i] + h10 * h * f0[i] + h01 * y1[i] + h11 * h * f1[i]
                })
            }
        }
    }
}

impl<'a, const N: usize, M: Model<N>> Integrator<'a, N, M> {
    /// Start at `(t0, y0)`; the cylinder-temperature memory starts at the converged fixed point.
    pub fn new(
        model: &'a M,
        sched: &'a InputSchedule,
        t0: f64,
        y0: [f64; N],
        opts: &SimOptions,
    ) -> Result<Self, SimError> {
        opts.validate()?;
        for (i, v) in y0.iter().enumerate() {
            if !v.is_finite() {
                return Err(SimError::NonFinite {
                    t: t0,
                    what: "initial state",
                    name: model.state_names()[i].to_string(),
                    value: *v,
                    state: dump(model, &y0),
                    hint: "give a finite initial state",
                });
            }
        }
        let bounds = model.state_bounds();
        let y = crate::model::clip_state(&y0, &bounds);
        let scales = model.state_scales();
        let mut me = Self {
            model,
            sched,
            opts: opts.clone(),
            t: t0,
            y,
            memory: SeligerIterate {
                x_r: 0.0,
                t_1: 300.0,
            },
            f: None,
            h: 0.0,
            err_old: 1e-4,
            atol: std::array::from_fn(|i| opts.atol * scales[i]),
            bounds,
            next_out: 0,
            t_out0: t0,
            jac: None,
            lu: None,
            jac_age: usize::MAX,
            jac_full: false,
            lags: Vec::new(),
            lag_seg: Vec::new(),
            stats: SimStats::default(),
        };
        if opts.exact_actuators && opts.method == Method::Rosenbrock34 {
            let lags = model.linear_lags();
            // the closed form knows no integrator limits: only for unbounded lag states
            let ok = lags.iter().all(|l| {
                l.state < N
                    && l.tau.is_finite()
                    && l.tau > 0.0
                    && bounds[l.state] == (f64::NEG_INFINITY, f64::INFINITY)
            });
            if ok {
                me.lag_seg.reserve(lags.len());
                me.lags = lags;
            }
        }
        // Memory starts at the converged fixed point of the initial state (the authors'
        // runSimEngine sets x_r_Init, T_1_Init from the settling run).
        if model.options().cylinder_temp == CylinderTemp::OneIteration {
            let mut inp = me.inputs(t0, t0 + 1.0);
            let u = inp.at(t0);
            me.memory = model.cylinder_fixed_point(&me.y, &u);
        }
        Ok(me)
    }

    fn inputs(&self, a: f64, b: f64) -> SegmentInputs<'a> {
        SegmentInputs::new(self.model, self.sched, a, b)
    }

    #[inline]
    fn rhs(&mut self, inp: &mut SegmentInputs, t: f64, y: &[f64; N]) -> Result<Rhs<N>, SimError> {
        self.stats.rhs_evals += 1;
        let u = inp.at(t);
        let ev = self.model.derivatives(y, &u, self.memory);
        if !ev.dx.iter().sum::<f64>().is_finite() {
            let i = ev.dx.iter().position(|v| !v.is_finite()).unwrap_or(0);
            return Err(SimError::NonFinite {
                t,
                what: "derivative of",
                name: self.model.state_names()[i].to_string(),
                value: ev.dx[i],
                state: dump(self.model, y),
                hint: if self.model.options().semantics.authors() {
                    "inputs far outside the model's range, or parameters without a physical operating point"
                } else {
                    "the paper's equations have no guards: a pressure ratio or flow left its physical range; try --semantics authors"
                },
            });
        }
        Ok(Rhs {
            dx: ev.dx,
            memory_next: ev.memory_next,
        })
    }

    fn output(&mut self, inp: &mut SegmentInputs, sol: &mut Solution, t: f64, y: &[f64; N]) {
        let u = inp.at(t);
        let ev = self.model.eval(y, &u, self.memory);
        sol.push(t, y, &ev.signals);
        self.stats.outputs += 1;
    }

    fn out_time(&self, k: u64) -> f64 {
        self.t_out0 + k as f64 * self.opts.dt_out
    }

    /// Integrate to `t_end`, writing output samples at the output grid (and at `t_end` if
    /// `final_sample`).
    pub fn advance(
        &mut self,
        t_end: f64,
        sol: &mut Solution,
        final_sample: bool,
    ) -> Result<(), SimError> {
        let stops = if self.opts.stop_at_breakpoints {
            stop_times(self.model, self.sched, self.t, t_end)
        } else {
            Vec::new()
        };
        let mut seg_ends: Vec<(f64, bool)> = stops;
        seg_ends.push((t_end, false));
        let mut inp = self.inputs(self.t, t_end);
        for (b, jump) in seg_ends {
            inp.set_segment(self.t, b);
            self.plan_lags(&inp, self.t, b);
            self.segment(&mut inp, b, sol)?;
            if b < t_end {
                self.stats.breakpoints += 1;
            }
            if jump {
                self.f = None;
            }
        }
        if final_sample {
            // outputs strictly before t_end were written by the segments; t_end itself here,
            // with the inputs of the last segment (left limit).
            let mut inp = self.inputs(self.t - 1.0, self.t);
            let y = self.y;
            let t = self.t;
            self.output(&mut inp, sol, t, &y);
            while self.out_time(self.next_out) <= t_end + SegmentInputs::delta(t_end) {
                self.next_out += 1;
            }
        }
        Ok(())
    }

    /// The closed-form lag solutions on the segment `[a, b]`, if every lag's saturated command is
    /// linear there (else none: the W-method integrates all states on this segment).
    fn plan_lags(&mut self, inp: &SegmentInputs, a: f64, b: f64) {
        self.lag_seg.clear();
        for lag in &self.lags {
            let Some((t_ref, v_ref, slope)) = inp.delayed_line(lag.command) else {
                self.lag_seg.clear();
                return;
            };
            let (va, vb) = (v_ref + slope * (a - t_ref), v_ref + slope * (b - t_ref));
            let (lo, hi) = lag.saturation;
            let (c_a, beta) = if lo <= va.min(vb) && va.max(vb) <= hi {
                (va, slope)
            } else if va.max(vb) <= lo {
                (lo, 0.0)
            } else if va.min(vb) >= hi {
                (hi, 0.0)
            } else {
                // the command crosses its saturation inside the segment
                self.lag_seg.clear();
                return;
            };
            self.lag_seg.push(LagSegment {
                state: lag.state,
                tau: lag.tau,
                t_a: a,
                c_a,
                beta,
            });
        }
    }

    fn initial_step(
        &mut self,
        inp: &mut SegmentInputs,
        f0: &[f64; N],
        span: f64,
    ) -> Result<f64, SimError> {
        // Hairer & Wanner's starting step (HINIT of dopri5.f), order 5.
        let sc: [f64; N] = std::array::from_fn(|i| self.atol[i] + self.opts.rtol * self.y[i].abs());
        let norm = |v: &[f64; N]| -> f64 {
            (v.iter().zip(&sc).map(|(a, s)| (a / s).powi(2)).sum::<f64>() / N as f64).sqrt()
        };
        let d0 = norm(&self.y);
        let d1 = norm(f0);
        let mut h0 = if d0 < 1e-10 || d1 < 1e-10 {
            1e-6
        } else {
            0.01 * d0 / d1
        };
        h0 = h0.min(span).min(self.opts.h_max);
        let y1: [f64; N] = std::array::from_fn(|i| self.y[i] + h0 * f0[i]);
        let t = self.t;
        let f1 = self.rhs(inp, t + h0, &y1)?.dx;
        let df: [f64; N] = std::array::from_fn(|i| f1[i] - f0[i]);
        let d2 = norm(&df) / h0;
        let h1 = if d1.max(d2) <= 1e-15 {
            (h0 * 1e-3).max(1e-6)
        } else {
            (0.01 / d1.max(d2)).powf(0.2)
        };
        Ok((100.0 * h0).min(h1).min(span).min(self.opts.h_max))
    }

    /// Integrate one segment up to `b` (inputs smooth inside).
    fn segment(
        &mut self,
        inp: &mut SegmentInputs,
        b: f64,
        sol: &mut Solution,
    ) -> Result<(), SimError> {
        let one_iter = self.model.options().cylinder_temp == CylinderTemp::OneIteration;
        // Output samples at the segment start (e.g. t0, or a breakpoint on the output grid).
        while self.out_time(self.next_out) < b - SegmentInputs::delta(b)
            && self.out_time(self.next_out) <= self.t + SegmentInputs::delta(self.t)
        {
            let (t, y) = (self.t, self.y);
            self.output(inp, sol, t, &y);
            self.next_out += 1;
        }
        let mut f0 = match self.f {
            Some(f) => f,
            None => {
                let (t, y) = (self.t, self.y);
                self.rhs(inp, t, &y)?.dx
            }
        };
        if self.h <= 0.0 {
            let span = b - self.t;
            self.h = self.initial_step(inp, &f0, span)?;
        }
        let mut last_failure: Option<SimError> = None;
        let mut worst_rejected: Option<(usize, f64)> = None;
        while self.t < b {
            if self.stats.steps + self.stats.rejected >= self.opts.max_steps {
                return Err(SimError::TooManySteps {
                    max_steps: self.opts.max_steps,
                    t: self.t,
                    state: dump(self.model, &self.y),
                });
            }
            let t = self.t;
            let mut h = self.h.min(self.opts.h_max);
            let last = t + h * 1.01 >= b;
            if last {
                h = b - t;
            } else if t + 2.0 * h > b {
                // two equal steps instead of a full one and a short remainder (the short step
                // would also shrink the next segment's first step)
                h = 0.5 * (b - t);
            }
            if h <= 1e-14 * t.abs().max(1.0) {
                if last {
                    // the segment end is within rounding of t: just move there
                    self.t = b;
                    break;
                }
                let limiting = match worst_rejected {
                    Some((i, e)) => format!(
                        "{} (scaled local error {e:.3e} in the last rejected step)",
                        self.model.state_names()[i]
                    ),
                    None => "none (no step was rejected for accuracy)".to_string(),
                };
                return Err(last_failure.unwrap_or(SimError::StepSizeTooSmall {
                    t,
                    h,
                    limiting,
                    state: dump(self.model, &self.y),
                }));
            }
            let t_new = if last { b } else { t + h };
            let trial = match self.opts.method {
                Method::Dopri5 => self.step_dopri5(inp, t, h, t_new, &f0),
                Method::Rosenbrock34 => self.step_rosw(inp, t, h, t_new, &f0),
            };
            let trial = match trial {
                Ok(tr) => tr,
                Err(e @ SimError::NonFinite { .. }) => {
                    // A trial stage left the model's domain: shrink the step and retry.
                    last_failure = Some(e);
                    self.stats.rejected += 1;
                    self.h = h * 0.25;
                    self.jac_age = usize::MAX;
                    continue;
                }
                Err(e) => return Err(e),
            };
            let err = trial.err;
            let order = self.opts.method.order() as f64;
            if err.is_nan() || err > 1.0 {
                self.stats.rejected += 1;
                worst_rejected = Some(self.worst_state(&self.y, &trial.y1, &trial.e));
                let fac = if err.is_finite() {
                    (0.9 * err.powf(-1.0 / order)).max(0.2)
                } else {
                    0.2
                };
                self.h = h * fac;
                if self.jac_age >= rosw::JAC_REFRESH_ON_REJECT {
                    self.jac_age = usize::MAX; // refresh a lagged Jacobian before retrying
                }
                continue;
            }
            // accept
            last_failure = None;
            worst_rejected = None;
            self.stats.steps += 1;
            self.jac_age = self.jac_age.saturating_add(1);
            let y = self.y;
            let y1 = trial.y1;
            // state and derivative at the end of the step, for dense output and the next step
            let (f1, memory_next) = match trial.f1 {
                Some(fm) => fm,
                None => {
                    let ev = self.rhs(inp, t_new, &y1)?;
                    (ev.dx, ev.memory_next)
                }
            };
            let dense = match trial.dense {
                Some(d) => Interp::Dopri(d),
                None => Interp::Hermite {
                    y0: y,
                    y1,
                    f0,
                    f1,
                    h,
                },
            };
            // outputs in [t, t_new) (t_new itself belongs to the next segment or the end)
            loop {
                let to = self.out_time(self.next_out);
                if to >= t_new - SegmentInputs::delta(t_new) || to >= b - SegmentInputs::delta(b) {
                    break;
                }
                let theta = ((to - t) / h).clamp(0.0, 1.0);
                let mut yo = dense.eval(theta);
                for l in &self.lag_seg {
                    yo[l.state] = l.advance(t, y[l.state], to - t);
                }
                let yo = crate::model::clip_state(&yo, &self.bounds);
                self.output(inp, sol, to, &yo);
                self.next_out += 1;
            }
            let fac = if order >= 5.0 {
                0.9 * err.max(1e-10).powf(-0.7 / order) * self.err_old.powf(0.4 / order)
            } else {
                0.9 * err.max(1e-10).powf(-1.0 / order)
            };
            self.h = h * fac.clamp(0.2, if order >= 5.0 { 10.0 } else { 5.0 });
            self.err_old = err.max(1e-4);
            self.t = t_new;
            let y1c = crate::model::clip_state(&y1, &self.bounds);
            let clipped = y1c != y1;
            self.y = y1c;
            if one_iter {
                self.memory = memory_next;
            }
            if one_iter || clipped {
                let (tt, yy) = (self.t, self.y);
                f0 = self.rhs(inp, tt, &yy)?.dx;
            } else {
                f0 = f1;
            }
        }
        self.f = Some(f0);
        Ok(())
    }

    /// One Dormand-Prince 5(4) trial step.
    fn step_dopri5(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
    ) -> Result<Trial<N>, SimError> {
        let y = self.y;
        let k1 = *f0;
        let mut yt = [0.0; N];
        for i in 0..N {
            yt[i] = y[i] + h * A21 * k1[i];
        }
        let k2 = self.rhs(inp, t + C2 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        let k3 = self.rhs(inp, t + C3 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        let k4 = self.rhs(inp, t + C4 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        let k5 = self.rhs(inp, t + C5 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] =
                y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        let k6 = self.rhs(inp, t_new, &yt)?.dx;
        let mut y1 = [0.0; N];
        for i in 0..N {
            y1[i] =
                y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        let ev7 = self.rhs(inp, t_new, &y1)?;
        let k7 = ev7.dx;
        let mut e = [0.0; N];
        for i in 0..N {
            e[i] =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
        }
        Ok(Trial {
            y1,
            err: self.error_norm(&y, &y1, &e),
            e,
            dense: Some(Dense::new(&y, &y1, &k1, &k3, &k4, &k5, &k6, &k7, h)),
            f1: Some((k7, ev7.memory_next)),
        })
    }

    /// Error estimate of state `i` scaled by atol_i + rtol max(|y0_i|, |y1_i|).
    #[inline]
    fn scaled_error(&self, i: usize, y0: &[f64; N], y1: &[f64; N], e: &[f64; N]) -> f64 {
        e[i] / (self.atol[i] + self.opts.rtol * y0[i].abs().max(y1[i].abs()))
    }

    /// The state with the largest scaled error estimate and that error (for failure reports).
    fn worst_state(&self, y0: &[f64; N], y1: &[f64; N], e: &[f64; N]) -> (usize, f64) {
        (0..N)
            .map(|i| (i, self.scaled_error(i, y0, y1, e).abs()))
            .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a })
    }

    /// RMS of the scaled error estimate.
    fn error_norm(&self, y0: &[f64; N], y1: &[f64; N], e: &[f64; N]) -> f64 {
        let mut err = 0.0;
        for i in 0..N {
            let s = self.scaled_error(i, y0, y1, e);
            err += s * s;
        }
        (err / N as f64).sqrt()
    }

    /// Finite-difference Jacobian df/dy at (t, y) with f(t, y) = f0 (forward differences,
    /// step sqrt(eps) relative to max(|y_i|, scale_i)); the columns with `skip[c]` stay zero.
    fn jacobian(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        f0: &[f64; N],
        skip: &[bool; N],
    ) -> Result<[[f64; N]; N], SimError> {
        let y = self.y;
        let scales = self.model.state_scales();
        let mut j = [[0.0; N]; N];
        for c in (0..N).filter(|&c| !skip[c]) {
            let mut yp = y;
            let mut d = 1.5e-8 * y[c].abs().max(scales[c]);
            if yp[c] + d > self.bounds[c].1 {
                d = -d;
            }
            yp[c] += d;
            let fp = self.rhs(inp, t, &yp)?.dx;
            for r in 0..N {
                j[r][c] = (fp[r] - f0[r]) / d;
            }
        }
        self.stats.jacobians += 1;
        Ok(j)
    }

    /// One trial step of the Rosenbrock-W method ROS34PW2 (see [`rosw`]).
    ///
    /// On a segment with closed-form lag states (`lag_seg` not empty) the method integrates the
    /// other states only, as the non-autonomous system dz/dt = f_z(z, a(t), u(t)) with the exact
    /// lag solution a(t): the stages take a(t + alpha_i h), the iteration matrix is
    /// I - gamma h J_zz (J without the lag rows and columns), and the lag states' error estimate
    /// is zero. This is the W-method applied to the smaller system, so order and error control
    /// are those of ROS34PW2.
    fn step_rosw(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
    ) -> Result<Trial<N>, SimError> {
        // moved out for the step (the stages borrow self mutably), put back whatever happens
        let lag_seg = std::mem::take(&mut self.lag_seg);
        let trial = self
            .iteration_matrix(inp, t, h, f0, &lag_seg)
            .and_then(|()| {
                let w = self.lu.take().expect("iteration matrix set up");
                let trial = self.rosw_stages(inp, t, h, t_new, f0, &lag_seg, &w);
                self.lu = Some(w);
                trial
            });
        self.lag_seg = lag_seg;
        trial
    }

    /// Make `self.lu` the iteration matrix for step size `h` (lagged Jacobian).
    ///
    /// (I - gamma h J) is refactored only when J, h or the set of lag states changed, e.g. not
    /// for the second of two equal steps that split a segment remainder (h equal up to rounding:
    /// the factors of I - gamma h' J with |h'/h - 1| <= 1e-9 are those of I - gamma h J' with
    /// J' = (h'/h) J, a W-method admits any J', and the stage terms h J' g k use the same J').
    fn iteration_matrix(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
    ) -> Result<(), SimError> {
        use rosw::*;
        let reduced = !lag_seg.is_empty();
        let mut is_lag = [false; N];
        for l in lag_seg {
            is_lag[l.state] = true;
        }
        if self.jac.is_none() || self.jac_age >= JAC_MAX_AGE || (!reduced && !self.jac_full) {
            let j = self.jacobian(inp, t, f0, &is_lag)?;
            self.jac = Some(j);
            self.jac_full = !reduced;
            self.jac_age = 0;
            self.lu = None;
        }
        if let Some(w) = &self.lu {
            if w.reduced == reduced && (w.h - h).abs() <= 1e-9 * h {
                return Ok(());
            }
        }
        let j = self.jac.as_ref().expect("Jacobian set above");
        let mut w = self.lu.take().unwrap_or_else(|| {
            Box::new(IterationMatrix {
                h,
                reduced,
                z: [0; N],
                m: 0,
                lu: [[0.0; N]; N],
                piv: [0; N],
                jz: [[0.0; N]; N],
            })
        });
        w.h = h;
        w.reduced = reduced;
        w.m = 0;
        for i in (0..N).filter(|&i| !is_lag[i]) {
            w.z[w.m] = i;
            w.m += 1;
        }
        let (m, z) = (w.m, w.z);
        for a in 0..m {
            for b in 0..m {
                w.jz[a][b] = j[z[a]][z[b]];
                w.lu[a][b] = -GAMMA * h * w.jz[a][b];
            }
            w.lu[a][a] += 1.0;
        }
        let IterationMatrix { lu, piv, .. } = &mut *w;
        if !linalg::lu_factor(lu, piv, m) {
            return Err(self.singular(t, h));
        }
        self.stats.lu += 1;
        self.lu = Some(w);
        Ok(())
    }

    /// The four stages of ROS34PW2 with the iteration matrix `w`.
    #[allow(clippy::too_many_arguments)]
    fn rosw_stages(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        w: &IterationMatrix<N>,
    ) -> Result<Trial<N>, SimError> {
        use rosw::*;
        let (m, z) = (w.m.min(N), &w.z);
        let js = w.h / h;
        let y = self.y;
        // k = (I - gamma h J_zz)^-1 h (f + J_zz g) on the z states; 0 on the lag states
        // (their values are exact, the increments are not used)
        let stage = |f: &[f64; N], g: Option<&[f64; N]>| -> [f64; N] {
            let mut r = [0.0; N];
            match g {
                None => {
                    for a in 0..m {
                        r[a] = h * f[z[a]];
                    }
                }
                Some(g) => {
                    let mut gz = [0.0; N];
                    for b in 0..m {
                        gz[b] = g[z[b]];
                    }
                    for a in 0..m {
                        let row = &w.jz[a];
                        let mut s = 0.0;
                        for b in 0..m {
                            s += row[b] * gz[b];
                        }
                        r[a] = h * (f[z[a]] + js * s);
                    }
                }
            }
            linalg::lu_solve(&w.lu, &w.piv, &mut r, m);
            let mut k = [0.0; N];
            for a in 0..m {
                k[z[a]] = r[a];
            }
            k
        };
        // exact lag states at t + s
        let exact = |yt: &mut [f64; N], s: f64| {
            for l in lag_seg {
                yt[l.state] = l.advance(t, y[l.state], s);
            }
        };
        let k1 = stage(f0, None);
        // stage 2
        let mut y2: [f64; N] = std::array::from_fn(|i| y[i] + A21 * k1[i]);
        exact(&mut y2, ALPHA2 * h);
        let f2 = self.rhs(inp, t + ALPHA2 * h, &y2)?.dx;
        let k2 = stage(&f2, Some(&std::array::from_fn(|i| G21 * k1[i])));
        // stage 3
        let mut y3: [f64; N] = std::array::from_fn(|i| y[i] + A31 * k1[i] + A32 * k2[i]);
        exact(&mut y3, ALPHA3 * h);
        let f3 = self.rhs(inp, t + ALPHA3 * h, &y3)?.dx;
        let k3 = stage(
            &f3,
            Some(&std::array::from_fn(|i| G31 * k1[i] + G32 * k2[i])),
        );
        // stage 4 (a41 = a42 = 0, a43 = 1, alpha4 = 1)
        let mut y4: [f64; N] = std::array::from_fn(|i| y[i] + k3[i]);
        exact(&mut y4, t_new - t);
        let f4 = self.rhs(inp, t_new, &y4)?.dx;
        let g4: [f64; N] = std::array::from_fn(|i| G41 * k1[i] + G42 * k2[i] + G43 * k3[i]);
        let k4 = stage(&f4, Some(&g4));
        let mut y1: [f64; N] =
            std::array::from_fn(|i| y[i] + B1 * k1[i] + B2 * k2[i] + B3 * k3[i] + B4 * k4[i]);
        for l in lag_seg {
            y1[l.state] = y4[l.state];
        }
        let e: [f64; N] = std::array::from_fn(|i| {
            (B1 - BH1) * k1[i] + (B2 - BH2) * k2[i] + (B3 - BH3) * k3[i] + (B4 - BH4) * k4[i]
        });
        Ok(Trial {
            y1,
            err: self.error_norm(&self.y, &y1, &e),
            e,
            dense: None,
            f1: None,
        })
    }

    fn singular(&self, t: f64, h: f64) -> SimError {
        SimError::NonFinite {
            t,
            what: "Newton matrix (I - gamma h J) for",
            name: format!("step h = {h:e}"),
            value: f64::NAN,
            state: dump(self.model, &self.y),
            hint:
                "the Jacobian is singular or non-finite; the model may have left its valid region",
        }
    }
}
