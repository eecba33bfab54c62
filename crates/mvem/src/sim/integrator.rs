//! The restartable integrator: step-size control, segments between stop times, dense output,
//! closed-form lag states. Each method's stages live next to its tableau ([`super::rosw`],
//! [`super::dopri5`]).

use super::dopri5::Dense;
use super::error::{dump, nonfinite_hint};
use super::input::InputSchedule;
use super::options::{Method, SimOptions};
use super::rosw::{self, IterationMatrix};
use super::segment::{stop_times_except, SegmentInputs};
use super::solution::{SimStats, Solution};
use super::SimError;
use crate::model::{Dynamics, LagCommand, LinearLag, ModelInput};

/// Restartable integrator state (the solver does not own the model or the inputs).
pub struct Integrator<'a, const N: usize, M: Dynamics<N>> {
    pub(super) model: &'a M,
    pub(super) sched: &'a InputSchedule,
    pub(super) opts: SimOptions,
    /// Current time \[s\].
    pub t: f64,
    /// Current state.
    pub y: [f64; N],
    /// The model's memory ([`Dynamics::Memory`]), held from the last accepted step when
    /// [`Dynamics::holds_memory`].
    pub memory: M::Memory,
    pub(super) f: Option<[f64; N]>,
    pub(super) h: f64,
    pub(super) err_old: f64,
    pub(super) atol: [f64; N],
    pub(super) bounds: [(f64, f64); N],
    pub(super) next_out: u64,
    pub(super) t_out0: f64,
    pub(super) jac: Option<[[f64; N]; N]>,
    /// df/dt of the integrated system, the non-autonomous term: at the point of `jac` (RODAS4
    /// and exprb32), or lagged like `jac` and recomputed at the first step of every segment
    /// where the inputs' slopes changed (ROS34PW2 with [`SimOptions::rosw_time_derivative`]).
    pub(super) ft: [f64; N],
    /// ROS34PW2: the start of the segment on which `ft` was computed (NaN: none yet).
    pub(super) ft_segment: f64,
    /// ROS34PW2: the inputs' slopes with which `ft` was computed.
    pub(super) ft_slopes: [f64; 6],
    /// Iteration matrix of the current Jacobian and step size (boxed: it is moved out and back
    /// at every step).
    pub(super) lu: Option<Box<IterationMatrix<N>>>,
    pub(super) jac_age: usize,
    /// A bound on the spectral radius of `jac` on the integrated states \[1/s\]: the largest
    /// row sum of |J_ij| s_j / s_i with the state scales s (Gershgorin, in the scaled states).
    /// ROS34PW2 picks its dense output by h times this ([`rosw::STIFF_DENSE`]).
    pub(super) jac_rho: f64,
    /// RODAS4, exprb32 and ROS34PW2 with its non-autonomous term: step size proposed after the
    /// first accepted step of the last segment
    /// (0: none).
    pub(super) h_first: f64,
    /// The state with the largest scaled error in the last rejected step and that error, since
    /// the last accepted step (across segments: a step size that collapsed in one segment is
    /// reported with its limiting state when the next segment cannot start).
    pub(super) worst_rejected: Option<(usize, f64)>,
    /// The error of the last trial step that left the model's domain, since the last accepted
    /// step (across segments, as `worst_rejected`).
    pub(super) last_failure: Option<SimError>,
    /// Whether `jac` has all columns (false: the columns of the lag states were skipped).
    pub(super) jac_full: bool,
    /// States integrated in closed form (empty: none; see [`SimOptions::exact_actuators`]).
    pub(super) lags: Vec<LinearLag>,
    /// Their closed-form solution on the current segment (empty: no lags, all states are
    /// integrated with the W-method).
    pub(super) lag_seg: Vec<LagSegment>,
    /// Statistics so far.
    pub stats: SimStats,
    /// The cancellation token of the thread that created the integrator
    /// ([`crate::numerics::cancel::current`]), polled before every trial step.
    pub(super) cancel: Option<crate::numerics::cancel::CancelToken>,
}

/// One linear piece of a lag's saturated, delayed driving command in simulation time:
/// `c(t) = c0 + beta (t - t0)` from `t0` to the next piece's `t0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LagPiece {
    t0: f64,
    c0: f64,
    beta: f64,
}

impl LagPiece {
    pub(super) fn new(t0: f64, c0: f64, beta: f64) -> Self {
        Self { t0, c0, beta }
    }

    pub(super) fn constant(t0: f64, c: f64) -> Self {
        Self::new(t0, c, 0.0)
    }

    /// Whether `next` is this piece continued (both constant at the same value).
    pub(super) fn continues_as(&self, next: &LagPiece) -> bool {
        self.beta == 0.0 && next.beta == 0.0 && self.c0 == next.c0
    }

    /// Whether `next`, which ends at `t_end`, lies on this piece's line to rounding: at both of
    /// its ends within 1e-12 relative (at least 1e-12 absolute). Schedule rows that lie on one
    /// straight line are no breakpoints, but each row interval is its own piece of the
    /// schedule, with a slope that differs in the last digits (e.g. 5.55000000000189 and
    /// 5.549999999998735 %/s on the WHTC); one line for both saves the closed form a piece
    /// boundary (an `exp`) and changes the command by at most that 1e-12.
    pub(super) fn extends_to(&self, next: &LagPiece, t_end: f64) -> bool {
        let line = |t: f64| self.c0 + self.beta * (t - self.t0);
        let tol = 1e-12 * next.c0.abs().max(1.0);
        let end = next.c0 + next.beta * (t_end - next.t0);
        (line(next.t0) - next.c0).abs() <= tol && (line(t_end) - end).abs() <= tol
    }

    /// Exact solution of dx/dt = (c(t) - x) / tau at `t + s` from `x` at `t` on this piece:
    /// x(t + s) = c(t + s) - beta tau + (x - c(t) + beta tau) exp(-s / tau).
    #[inline(always)]
    fn advance(&self, tau: f64, t: f64, x: f64, s: f64) -> f64 {
        let c = |t: f64| self.c0 + self.beta * (t - self.t0);
        let bt = self.beta * tau;
        c(t + s) - bt + (x - c(t) + bt) * (-s / tau).exp()
    }
}

/// A lag state on one segment: `dx/dt = (c(t) - x)/tau` with the driving command `c(t)`
/// (delayed, saturated) piecewise linear on the segment: one piece when the command's
/// breakpoints are stop times, more when a step may run across them
/// ([`SimOptions::stop_at_lag_breakpoints`]).
#[derive(Debug, Clone)]
pub(super) struct LagSegment {
    pub(super) state: usize,
    tau: f64,
    /// Sorted by start time; the first covers everything before the second.
    pieces: Vec<LagPiece>,
}

impl LagSegment {
    /// Exact solution at `t + s` from `x` at `t` (piece by piece across the command's
    /// breakpoints in between: the solution of a linear ODE with a piecewise-linear input).
    #[inline(always)]
    pub(super) fn advance(&self, t: f64, x: f64, s: f64) -> f64 {
        // one piece (the command's breakpoints are stop times): inline, without the search
        if let [p] = self.pieces.as_slice() {
            return p.advance(self.tau, t, x, s);
        }
        self.advance_pieces(t, x, s)
    }

    /// [`Self::advance`] on a segment with more than one piece (kept out of line).
    #[inline(never)]
    fn advance_pieces(&self, t: f64, x: f64, s: f64) -> f64 {
        let p = &self.pieces;
        let end = t + s;
        let mut k = self.piece_at(t);
        if k + 1 == p.len() || p[k + 1].t0 >= end {
            // within one piece (the offset s itself, not (t + s) - t)
            return p[k].advance(self.tau, t, x, s);
        }
        let (mut t, mut x) = (t, x);
        while k + 1 < p.len() && p[k + 1].t0 < end {
            let tb = p[k + 1].t0;
            x = p[k].advance(self.tau, t, x, tb - t);
            t = tb;
            k += 1;
        }
        p[k].advance(self.tau, t, x, end - t)
    }

    /// Rate dx/dt = (c(t) - x) / tau of the lag at `t` with state `x` (eqs (40), (41), (57)).
    #[inline]
    pub(super) fn rate(&self, t: f64, x: f64) -> f64 {
        let p = &self.pieces[self.piece_at(t)];
        let c = p.c0 + p.beta * (t - p.t0);
        (c - x) / self.tau
    }

    /// Index of the piece holding `t` (at a piece boundary the later piece; a segment has few
    /// pieces: a linear scan).
    #[inline]
    fn piece_at(&self, t: f64) -> usize {
        let p = &self.pieces;
        let mut k = 0;
        while k + 1 < p.len() && p[k + 1].t0 <= t {
            k += 1;
        }
        k
    }

    /// Every lag state of `lag_seg` at `t + s` from `y` at `t`, written into `yt` (the stages
    /// of the Rosenbrock methods take the exact lag values).
    #[inline]
    pub(super) fn advance_all<const N: usize>(
        lag_seg: &[LagSegment],
        t: f64,
        y: &[f64; N],
        yt: &mut [f64; N],
        s: f64,
    ) {
        for l in lag_seg {
            yt[l.state] = l.advance(t, y[l.state], s);
        }
    }
}

/// What the integrator keeps of a model evaluation (not the signals, which are only needed at
/// output samples: moving them costs more than the arithmetic of a step).
pub(super) struct Rhs<const N: usize, Mem> {
    pub(super) dx: [f64; N],
    pub(super) memory_next: Mem,
}

/// Result of one trial step.
pub(super) struct Trial<const N: usize, Mem> {
    pub(super) y1: [f64; N],
    pub(super) err: f64,
    /// Local error estimate per state.
    pub(super) e: [f64; N],
    /// The method's own dense output (else cubic Hermite from the end points and derivatives;
    /// ROS34PW2 gives its stages' continuous extension for steps long against the fast modes).
    pub(super) dense: Option<Interp<N>>,
    /// f(t_new, y1) and the model memory computed there, if the method has it.
    pub(super) f1: Option<([f64; N], Mem)>,
}

/// RODAS4: the last step of a segment may be up to this factor longer than the proposed step
/// (unless a step of the segment was rejected), instead of two steps; its error grows by at most
/// 1.3^5 = 3.7 where the proposal came from an error far below 1.
const RODAS_STRETCH: f64 = 1.3;

/// err^(-1/order), by [`inv_cbrt`] for the third-order method (a fraction of `powf`'s cost).
#[inline]
fn inv_root(err: f64, order: f64) -> f64 {
    if order == 3.0 {
        inv_cbrt(err)
    } else if order == 4.0 {
        1.0 / err.sqrt().sqrt()
    } else {
        err.powf(-1.0 / order)
    }
}

/// x^(-1/3) for a positive normal `x` (else 1 / `cbrt`): an estimate from the exponent bits,
/// then four division-free Newton steps y (4 - x y^3) / 3 (quadratic convergence from about
/// 3 %), within a few units in the last place of 1 / cbrt(x) (test `inv_cbrt_is_one_over_cbrt`)
/// at under half the cost of `cbrt` and a division (measured 7 against 16 ns per call).
#[inline]
fn inv_cbrt(x: f64) -> f64 {
    if !(x.is_normal() && x > 0.0) {
        return 1.0 / x.cbrt();
    }
    let mut y = f64::from_bits(0x553e_f0ff_289d_d796_u64.wrapping_sub(x.to_bits() / 3));
    for _ in 0..4 {
        y = y * (4.0 - x * y * y * y) * (1.0 / 3.0);
    }
    y
}

/// Dense output of an accepted step.
pub(super) enum Interp<const N: usize> {
    Dopri(Dense<N>),
    /// RODAS4's continuous extension of order 3 (`rodas.f`, `CONTRO`):
    /// y(t + s h) = (1 - s) y0 + s (y1 + (1 - s) (c3 + s c4)). It uses the stages, not f at the
    /// end points, whose errors a stiff problem amplifies by |lambda|.
    Rodas {
        y0: [f64; N],
        y1: [f64; N],
        c3: [f64; N],
        c4: [f64; N],
    },
    /// exprb32's continuous extension ([`super::exprb::ExprbDense`]).
    Exprb(Box<super::exprb::ExprbDense<N>>),
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
            Interp::Exprb(d) => d.eval(theta),
            Interp::Rodas { y0, y1, c3, c4 } => {
                let s = theta;
                std::array::from_fn(|i| {
                    (1.0 - s) * y0[i] + s * (y1[i] + (1.0 - s) * (c3[i] + s * c4[i]))
                })
            }
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

impl<'a, const N: usize, M: Dynamics<N>> Integrator<'a, N, M> {
    /// Start at `(t0, y0)` with the model's [`Dynamics::initial_memory`] there.
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
                    hint: "give a finite initial state".into(),
                });
            }
        }
        let bounds = model.state_bounds();
        let y = crate::model::clip_state(&y0, &bounds);
        let scales = model.state_scales();
        // The model's memory for a simulation starting here (the engine models in one-iteration
        // mode: the converged cylinder fixed point of the initial state, as the authors'
        // runSimEngine sets x_r_Init, T_1_Init from the settling run).
        let memory =
            model.initial_memory(&y, &SegmentInputs::new(model, sched, t0, t0 + 1.0).at(t0));
        let mut me = Self {
            model,
            sched,
            opts: opts.clone(),
            t: t0,
            y,
            memory,
            f: None,
            h: 0.0,
            err_old: 1e-4,
            atol: std::array::from_fn(|i| opts.atol * scales[i]),
            bounds,
            next_out: 0,
            t_out0: t0,
            jac: None,
            ft: [0.0; N],
            ft_segment: f64::NAN,
            ft_slopes: [f64::NAN; 6],
            lu: None,
            jac_age: usize::MAX,
            jac_rho: 0.0,
            h_first: 0.0,
            worst_rejected: None,
            last_failure: None,
            jac_full: false,
            lags: Vec::new(),
            lag_seg: Vec::new(),
            stats: SimStats::default(),
            cancel: crate::numerics::cancel::current(),
        };
        if opts.exact_actuators && opts.method.is_rosenbrock() {
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
        Ok(me)
    }

    fn inputs(&self, a: f64, b: f64) -> SegmentInputs<'a> {
        SegmentInputs::new(self.model, self.sched, a, b)
    }

    #[inline]
    pub(super) fn rhs(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        y: &[f64; N],
    ) -> Result<Rhs<N, M::Memory>, SimError> {
        let u = inp.at(t);
        self.rhs_with(t, y, &u)
    }

    /// [`Self::rhs`] with the inputs `u` given (`t` only for error reports).
    #[inline]
    pub(super) fn rhs_with(
        &mut self,
        t: f64,
        y: &[f64; N],
        u: &ModelInput,
    ) -> Result<Rhs<N, M::Memory>, SimError> {
        self.stats.rhs_evals += 1;
        let ev = self.model.derivatives(y, u, self.memory);
        if !ev.dx.iter().sum::<f64>().is_finite() {
            let i = ev.dx.iter().position(|v| !v.is_finite()).unwrap_or(0);
            return Err(SimError::NonFinite {
                t,
                what: "derivative of",
                name: self.model.state_names()[i].to_string(),
                value: ev.dx[i],
                state: dump(self.model, y),
                hint: nonfinite_hint(self.model, y, u, self.memory),
            });
        }
        Ok(Rhs {
            dx: ev.dx,
            memory_next: ev.memory_next,
        })
    }

    fn output(&mut self, inp: &mut SegmentInputs, sol: &mut Solution, t: f64, y: &[f64; N]) {
        let u = inp.at(t);
        if sol.defers_signals() {
            // the receiver evaluates the signals (`Solution::streaming_deferred`)
            sol.push_deferred(t, y, &u);
        } else {
            let ev = self.model.eval(y, &u, self.memory);
            sol.push(t, y, &ev.signals);
        }
        self.stats.outputs += 1;
    }

    fn out_time(&self, k: u64) -> f64 {
        self.t_out0 + k as f64 * self.opts.dt_out
    }

    /// Integrate to `t_end`, writing output samples at the output grid (and at `t_end` if
    /// `final_sample`). A `t_end` beyond [`super::MAX_TIME`], or more than [`super::MAX_ROWS`]
    /// output samples to it, is refused before any step ([`super::check_horizon`]).
    pub fn advance(
        &mut self,
        t_end: f64,
        sol: &mut Solution,
        final_sample: bool,
    ) -> Result<(), SimError> {
        super::check_horizon(self.t, t_end, self.opts.dt_out)?;
        self.advance_checked(t_end, sol, final_sample)
    }

    /// [`Self::advance`] to a `t_end` whose interval from `self.t` [`super::check_interval`]
    /// has already accepted (a whole simulation's, from its start).
    pub(super) fn advance_checked(
        &mut self,
        t_end: f64,
        sol: &mut Solution,
        final_sample: bool,
    ) -> Result<(), SimError> {
        let skip = self.skip_lag_stops();
        let stops = if self.opts.stop_at_breakpoints {
            stop_times_except(self.model, self.sched, self.t, t_end, skip)
        } else {
            Vec::new()
        };
        self.advance_stops(t_end, sol, final_sample, &stops)
    }

    /// [`Self::advance`] with its stop times given: `stops` as [`stop_times_except`] lists them
    /// from `self.t` to `t_end` (a time-parallel chunk takes its part of one list for the whole
    /// run, [`super::chunks`]).
    pub(super) fn advance_stops(
        &mut self,
        t_end: f64,
        sol: &mut Solution,
        final_sample: bool,
        stops: &[(f64, bool)],
    ) -> Result<(), SimError> {
        // the stops, then t_end
        let first_end = stops.first().map_or(t_end, |s| s.0);
        let seg_ends = stops.iter().copied().chain(std::iter::once((t_end, false)));
        // made for the first segment (a plant step has one to three: set up once, not twice)
        // the delayed commands of closed-form lags enter only derivatives the integrator does
        // not use, whether or not their breakpoints are stop times
        let lag_only = self.lag_commands();
        let mut inp =
            SegmentInputs::with_lag_only(self.model, self.sched, self.t, first_end, lag_only);
        for (k, (b, jump)) in seg_ends.enumerate() {
            if k > 0 {
                inp.set_segment(self.t, b);
            }
            self.plan_lags(&mut inp, self.t, b);
            if matches!(self.opts.method, Method::Rodas4 | Method::Exprb32) {
                // J and f_t belong to one point and one segment's inputs
                self.jac_age = usize::MAX;
            }
            // f(b, y) from the left is the next segment's first derivative only at a kink; at a
            // jump the next segment recomputes it with the new inputs, and after t_end nobody
            // uses it (the final sample is evaluated on its own)
            let f_at_end = !jump && b < t_end;
            self.segment(&mut inp, b, sol, f_at_end)?;
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

    /// The closed-form lag solutions on the segment `[a, b]`: each lag's saturated, delayed
    /// command as linear pieces ([`SegmentInputs::lag_pieces`]; the lags of one command with the
    /// same saturation share them).
    fn plan_lags(&mut self, inp: &mut SegmentInputs, a: f64, b: f64) {
        if self.lags.is_empty() {
            return;
        }
        if self.lag_seg.len() != self.lags.len() {
            self.lag_seg = self
                .lags
                .iter()
                .map(|l| LagSegment {
                    state: l.state,
                    tau: l.tau,
                    pieces: Vec::with_capacity(4),
                })
                .collect();
        }
        for i in 0..self.lags.len() {
            let lag = self.lags[i];
            let same = i > 0
                && self.lags[i - 1].command == lag.command
                && self.lags[i - 1].saturation == lag.saturation;
            let (done, rest) = self.lag_seg.split_at_mut(i);
            let seg = &mut rest[0];
            seg.state = lag.state;
            seg.tau = lag.tau;
            if same {
                seg.pieces.clone_from(&done[i - 1].pieces);
            } else {
                inp.lag_pieces(lag.command, a, b, lag.saturation, &mut seg.pieces);
            }
        }
    }

    /// Whether the stop times at the delayed channels 2 and 3 are left out: they drive only
    /// closed-form lag states and [`SimOptions::stop_at_lag_breakpoints`] is off.
    pub(super) fn skip_lag_stops(&self) -> [bool; 2] {
        if self.opts.stop_at_lag_breakpoints {
            [false; 2]
        } else {
            self.lag_commands()
        }
    }

    /// Which delayed commands (u_egr, u_vgt) drive closed-form lag states.
    fn lag_commands(&self) -> [bool; 2] {
        let mut driven = [false; 2];
        for l in &self.lags {
            match l.command {
                LagCommand::Egr => driven[0] = true,
                LagCommand::Vgt => driven[1] = true,
            }
        }
        driven
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

    /// Integrate one segment up to `b` (inputs smooth inside). Without `f_at_end` the
    /// derivative at `b` is not needed afterwards (a jump or the end follows): the last step
    /// skips its end-of-step evaluation unless dense output or the model's memory needs it, and
    /// `self.f` is left `None`.
    fn segment(
        &mut self,
        inp: &mut SegmentInputs,
        b: f64,
        sol: &mut Solution,
        f_at_end: bool,
    ) -> Result<(), SimError> {
        let holds_memory = self.model.holds_memory();
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
        // RODAS4: the first step after a stop (in the transient the kink starts) is limited far
        // more than the steps after it, so it starts from the proposal of the last segment's
        // first step, and the last step of a segment may stretch to 1.3 x the proposal while no
        // step of the segment was rejected (docs/integrator.md; exprb32 uses the same rules:
        // with one step size it made 6.7 k more rejections). ROS34PW2 uses them with its
        // non-autonomous term (5 % fewer evaluations on the WHTC; without the term they save
        // 1 % and it keeps one step size, as before the term).
        let first_step_rules = match self.opts.method {
            Method::Rodas4 | Method::Exprb32 => true,
            Method::Rosenbrock34 => self.opts.rosw_time_derivative,
            Method::Dopri5 => false,
        };
        let max_stretch = if first_step_rules {
            RODAS_STRETCH
        } else {
            1.01
        };
        let mut first = first_step_rules;
        let mut rejected_here = false;
        if first_step_rules && self.h_first > 0.0 {
            self.h = self.h.min(self.h_first);
        }
        while self.t < b {
            if self.stats.steps + self.stats.rejected >= self.opts.max_steps {
                return Err(SimError::TooManySteps {
                    max_steps: self.opts.max_steps,
                    t: self.t,
                    state: dump(self.model, &self.y),
                });
            }
            if self.cancel.as_ref().is_some_and(|c| c.is_cancelled()) {
                return Err(SimError::Cancelled {
                    t: self.t,
                    state: dump(self.model, &self.y),
                });
            }
            let t = self.t;
            let mut h = self.h.min(self.opts.h_max);
            // (never beyond h_max)
            let stretch = if rejected_here || b - t > self.opts.h_max {
                1.01
            } else {
                max_stretch
            };
            let last = t + h * stretch >= b;
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
                let limiting = match self.worst_rejected {
                    Some((i, e)) => format!(
                        "{} (scaled local error {e:.3e} in the last rejected step)",
                        self.model.state_names()[i]
                    ),
                    None => {
                        // no rejection: the step is small because the state moves fast (the
                        // initial step of a segment follows |dx/dt| / tolerance); name the
                        // fastest state (the scaled "error" f0 over one second)
                        let (i, rate) = self.worst_state(&self.y, &self.y, &f0);
                        format!(
                            "{} (no step was rejected for accuracy; the fastest state, |dx/dt| = \
                             {rate:.3e} tolerance units per second)",
                            self.model.state_names()[i],
                        )
                    }
                };
                return Err(self
                    .last_failure
                    .take()
                    .unwrap_or(SimError::StepSizeTooSmall {
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
                Method::Rodas4 => self.step_rodas4(inp, t, h, t_new, &f0),
                Method::Exprb32 => self.step_exprb32(inp, t, h, t_new, &f0),
            };
            let trial = match trial {
                Ok(tr) => tr,
                Err(e @ SimError::NonFinite { .. }) => {
                    // A trial stage left the model's domain: shrink the step and retry.
                    self.last_failure = Some(e);
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
                rejected_here = true;
                self.stats.rejected += 1;
                self.worst_rejected = Some(self.worst_state(&self.y, &trial.y1, &trial.e));
                let fac = if err.is_finite() {
                    (0.9 * inv_root(err, order)).max(0.2)
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
            self.last_failure = None;
            self.worst_rejected = None;
            self.stats.steps += 1;
            self.jac_age = self.jac_age.saturating_add(1);
            let y = self.y;
            let y1 = trial.y1;
            // the segment's last step before a jump or the end, without output samples in it:
            // f(t_new, y1) is needed neither for dense output nor as the next step's f0
            // output times at or past this are not in [t, t_new) (t_new itself belongs to the
            // next segment or the end)
            let beyond_step = |to: f64| {
                to >= t_new - SegmentInputs::delta(t_new) || to >= b - SegmentInputs::delta(b)
            };
            let f_unused = last && !f_at_end && beyond_step(self.out_time(self.next_out));
            if f_unused && !holds_memory && trial.f1.is_none() {
                self.accept(h, err, order, t_new, &y1);
                if first {
                    // a segment of one step: its first step's proposal too (RODAS4)
                    self.h_first = self.h;
                }
                break;
            }
            // state and derivative at the end of the step, for dense output and the next step
            let (f1, memory_next) = match trial.f1 {
                Some(fm) => fm,
                None => {
                    let ev = self.rhs(inp, t_new, &y1)?;
                    (ev.dx, ev.memory_next)
                }
            };
            let dense = match trial.dense {
                Some(d) => d,
                None => Interp::Hermite {
                    y0: y,
                    y1,
                    f0,
                    f1,
                    h,
                },
            };
            // outputs in [t, t_new)
            loop {
                let to = self.out_time(self.next_out);
                if beyond_step(to) {
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
            let clipped = self.accept(h, err, order, t_new, &y1);
            if first {
                self.h_first = self.h;
                first = false;
            }
            if holds_memory {
                self.memory = memory_next;
            }
            if f_unused {
                break;
            }
            if holds_memory || clipped {
                let (tt, yy) = (self.t, self.y);
                f0 = self.rhs(inp, tt, &yy)?.dx;
            } else {
                f0 = f1;
            }
        }
        self.f = if self.t >= b && !f_at_end {
            None
        } else {
            Some(f0)
        };
        Ok(())
    }

    /// Move to the end of an accepted step of size `h` and scaled error `err`: the next step
    /// size, the error memory, the time `t_new` and the state `y1` clipped into the integrator
    /// limits. Returns whether the clip changed the state.
    #[inline]
    fn accept(&mut self, h: f64, err: f64, order: f64, t_new: f64, y1: &[f64; N]) -> bool {
        self.h = h * Self::step_factor(err, self.err_old, order);
        self.err_old = err.max(1e-4);
        self.t = t_new;
        let y1c = crate::model::clip_state(y1, &self.bounds);
        let clipped = y1c != *y1;
        self.y = y1c;
        clipped
    }

    /// Step-size factor after an accepted step with error `err` (the previous accepted step's
    /// `err_old`), limited to [0.2, 5] (order < 5) or [0.2, 10].
    #[inline]
    fn step_factor(err: f64, err_old: f64, order: f64) -> f64 {
        let fac = if order >= 5.0 {
            0.9 * err.max(1e-10).powf(-0.7 / order) * err_old.powf(0.4 / order)
        } else {
            0.9 * inv_root(err.max(1e-10), order)
        };
        fac.clamp(0.2, if order >= 5.0 { 10.0 } else { 5.0 })
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
    pub(super) fn error_norm(&self, y0: &[f64; N], y1: &[f64; N], e: &[f64; N]) -> f64 {
        let mut err = 0.0;
        for i in 0..N {
            let s = self.scaled_error(i, y0, y1, e);
            err += s * s;
        }
        (err / N as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::inv_cbrt;

    #[test]
    fn inv_cbrt_is_one_over_cbrt() {
        let mut worst = 0.0f64;
        for k in 0..=20_000 {
            // 1e-300 .. 1e300 and the step controller's range 1e-10 .. 1e6 densely
            for x in [
                10f64.powf(-300.0 + 600.0 * k as f64 / 20_000.0),
                10f64.powf(-10.0 + 16.0 * k as f64 / 20_000.0),
            ] {
                let want = 1.0 / x.cbrt();
                worst = worst.max((inv_cbrt(x) / want - 1.0).abs());
            }
        }
        assert!(
            worst <= 4.0 * f64::EPSILON,
            "worst relative difference {worst:e}"
        );
        assert_eq!(inv_cbrt(8.0), 0.5);
        assert_eq!(inv_cbrt(1.0), 1.0);
        // not normal: 1 / cbrt
        assert_eq!(inv_cbrt(0.0), f64::INFINITY);
        assert!(inv_cbrt(f64::NAN).is_nan());
        assert_eq!(inv_cbrt(f64::INFINITY), 0.0);
        assert_eq!(inv_cbrt(-8.0), -0.5);
    }
}
