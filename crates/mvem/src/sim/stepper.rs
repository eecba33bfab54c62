//! A plant that is advanced sample by sample: the building block of closed-loop simulation.
//!
//! [`Plant`] carries everything the model needs from one controller sample to the next: the
//! state, the cylinder-temperature memory (one-iteration mode), the time, the command history
//! (so the actuator transport delays tau_degr and tau_dvgt, eqs (40), (41), (57), stay exact
//! across samples) and the integrator's warm state (step size, lagged Jacobian and its LU
//! factors). [`Plant::step`] holds the given commands for `dt` (zero-order hold) and integrates
//! with the same [`Integrator`] as [`simulate`](super::simulate), so stepping a schedule sample by
//! sample gives the same trajectory as simulating it (up to the integration tolerance).
//!
//! The command history is one [`InputSchedule`] of zero-order-hold rows, appended in place
//! ([`InputSchedule::hold`]: the delayed copies of a command change become stop times at
//! t + tau) and trimmed to the largest delay, so a step costs the same at t = 10 s and at
//! t = 1800 s. The integrator is not rebuilt per sample: its owned state (step size, error
//! history, lagged Jacobian, LU factors, tolerances, limits, the closed-form lag plans) moves
//! into the [`Integrator`] for the step and back, so a step allocates nothing and repeats no
//! set-up (no option checks, no initial memory, no copy or re-validation of the history).

use super::integrator::LagSegment;
use super::rosw::IterationMatrix;
use super::{Integrator, SimError, SimOptions, SimStats, Solution};
use crate::model::{Drive, Engine10, Engine12, Engine8, LinearLag, Model, ModelInput, Signals};
use crate::sim::{InputSchedule, Side};

/// The integrator's owned state carried between samples (see the module docs).
struct Carry<const N: usize> {
    h: f64,
    err_old: f64,
    atol: [f64; N],
    bounds: [(f64, f64); N],
    jac: Option<[[f64; N]; N]>,
    jac_age: usize,
    jac_full: bool,
    jac_rho: f64,
    lu: Option<Box<IterationMatrix<N>>>,
    lags: Vec<LinearLag>,
    lag_seg: Vec<LagSegment>,
}

/// An `N`-state model advanced sample by sample with held commands (see the module docs).
pub struct Plant<const N: usize, M: Model<N>> {
    model: M,
    opts: SimOptions,
    t: f64,
    y: [f64; N],
    memory: M::Memory,
    /// Command history: zero-order-hold rows (a change at t is two rows at t).
    sched: InputSchedule,
    /// The model's input delays \[s\] ([`Model::input_delays`]) of channels 2 and 3.
    delays: [f64; 2],
    /// Largest transport delay [s]: history older than t - tau_max is dropped.
    tau_max: f64,
    carry: Carry<N>,
    stats: SimStats,
    signals: Signals,
    /// The inputs at the current time: the held commands and the delayed ones the actuators
    /// see (from the left at a command change).
    input: ModelInput,
    /// Never written: the integrator is run without output samples.
    scratch: Solution,
}

/// The options a plant stepped with held commands runs with by default (the closed loop, the
/// Python `Plant`): [`SimOptions::default`] with [`SimOptions::stop_at_lag_breakpoints`] off, so
/// the delayed copy of a command change (tau_degr = 65 ms puts it 5 ms into a 10 ms sample) is no
/// stop time: the actuator states follow it in closed form inside the step, and a sample is one
/// integrator segment instead of about two (`docs/control.md`, performance). And with
/// [`SimOptions::rosw_time_derivative`] off: a 10 ms sample is a segment of about one step, so the
/// term's evaluation at every segment start saves no step (the closed-loop WHTC measured 1.13 M
/// evaluations and 12 004 rejections with it against 0.94 M and 1 560 without, at the same wall
/// time; `docs/integrator.md`, "The non-autonomous term of ROS34PW2").
pub fn plant_options() -> SimOptions {
    SimOptions {
        stop_at_lag_breakpoints: false,
        rosw_time_derivative: false,
        ..SimOptions::default()
    }
}

/// Output interval that never comes: the stepper reads the state, not output samples (a step
/// is at most [`MAX_STEP_LENGTH`], far shorter).
const NO_OUTPUT: f64 = 1e300;

/// Longest step [`Plant::step`] takes \[s\] (about 11.6 days with the commands held; longer
/// steps are refused: before session 27 a step of 1e308 s reached the output interval that never
/// comes and filled the memory with samples).
pub const MAX_STEP_LENGTH: f64 = 1e6;

impl<const N: usize, M: Model<N>> Plant<N, M> {
    /// Start at `t0` in the state `y0` with the commands `d` held since forever (the delayed
    /// commands equal `d`). Starting at the steady state of `d` is one layer up:
    /// `analysis::steady::plant_from_steady`.
    pub fn from_state(
        model: M,
        d: Drive,
        t0: f64,
        y0: [f64; N],
        opts: &SimOptions,
    ) -> Result<Self, SimError> {
        opts.validate()?;
        check_drive(&d, t0)?;
        if !t0.is_finite() {
            return Err(SimError::BadInterval { t0, t_end: t0 });
        }
        let mut opts = opts.clone();
        opts.dt_out = NO_OUTPUT;
        let delays = model.input_delays().delayed;
        let tau_max = delays[0].max(delays[1]).max(0.0);
        let scratch = Solution::new(&model.state_names());
        let sched = InputSchedule::new(vec![t0], vec![d.to_array()])
            .expect("commands and time checked finite");
        // the integrator checks the state, sets the initial memory (fixed point) and its
        // tolerances, limits and lag states, which the plant then carries
        let run = Integrator::new(&model, &sched, t0, y0, &opts)?;
        let (y, memory) = (run.y, run.memory);
        let carry = Carry {
            h: 0.0,
            err_old: 1e-4,
            atol: run.atol,
            bounds: run.bounds,
            jac: None,
            jac_age: usize::MAX,
            jac_full: false,
            jac_rho: 0.0,
            lu: None,
            lags: run.lags,
            lag_seg: run.lag_seg,
        };
        let input = ModelInput::constant(d);
        let signals = model.eval(&y, &input, memory).signals;
        Ok(Self {
            model,
            opts,
            t: t0,
            y,
            memory,
            sched,
            delays,
            tau_max,
            carry,
            stats: SimStats::default(),
            signals,
            input,
            scratch,
        })
    }

    /// Current time \[s\].
    pub fn t(&self) -> f64 {
        self.t
    }

    /// Current state.
    pub fn state(&self) -> &[f64; N] {
        &self.y
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// Signals at the current time, with the commands of the last step (left limit).
    pub fn signals(&self) -> &Signals {
        &self.signals
    }

    /// The commands held during the last step (the initial commands before the first step).
    pub fn command(&self) -> Drive {
        Drive::from_array(*self.sched.rows().last().expect("history never empty"))
    }

    /// Solver statistics summed over all steps.
    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// The inputs at the current time: the commands held in the last step and the delayed
    /// commands u_egr(t - tau_degr), u_vgt(t - tau_dvgt) \[%\] the actuators see now, from
    /// the command history (from the left at a command change). The right-hand side at the
    /// current state is `model().eval(state(), &input(), ..)`.
    pub fn input(&self) -> ModelInput {
        self.input
    }

    /// Number of history rows kept (for tests of the trimming).
    pub fn history_len(&self) -> usize {
        self.sched.times().len()
    }

    /// Hold the commands `d` for `dt` seconds and integrate; returns the signals at the end
    /// (with the commands `d`, i.e. the left limit before the next command change).
    pub fn step(&mut self, dt: f64, d: Drive) -> Result<&Signals, SimError> {
        if !(dt > 0.0 && dt <= MAX_STEP_LENGTH) {
            return Err(SimError::BadOption {
                field: "dt",
                value: dt,
                constraint: "step length must be > 0 and at most 1e6 s",
            });
        }
        check_drive(&d, self.t)?;
        let t = self.t;
        let t_end = t + dt;
        if t_end <= t {
            return Err(SimError::BadInterval { t0: t, t_end });
        }
        // zero-order hold: a change at t is the pair (t, old), (t, new)
        self.sched
            .hold(t, d.to_array())
            .expect("commands checked finite, time increasing");
        // drop rows no delayed lookup in [t, t_end] can reach (before t - tau_max)
        self.sched
            .drop_before(t - self.tau_max - 1e-9 * t.abs().max(1.0));
        let c = &mut self.carry;
        let mut run = Integrator {
            model: &self.model,
            sched: &self.sched,
            opts: self.opts.clone(),
            t,
            y: self.y,
            memory: self.memory,
            f: None,
            h: c.h,
            err_old: c.err_old,
            atol: c.atol,
            bounds: c.bounds,
            next_out: 1, // no output samples (the interval is NO_OUTPUT)
            t_out0: t,
            jac: c.jac.take(),
            ft: [0.0; N], // recomputed at the first step of a segment (RODAS4 with J)
            ft_segment: f64::NAN,
            ft_slopes: [f64::NAN; 6],
            lu: c.lu.take(),
            jac_age: c.jac_age,
            h_first: 0.0,
            worst_rejected: None,
            last_failure: None,
            jac_full: c.jac_full,
            jac_rho: c.jac_rho,
            lags: std::mem::take(&mut c.lags),
            lag_seg: std::mem::take(&mut c.lag_seg),
            stats: SimStats::default(),
            cancel: crate::numerics::cancel::current(),
        };
        let res = run.advance(t_end, &mut self.scratch, false);
        c.h = run.h;
        c.err_old = run.err_old;
        c.jac = run.jac.take();
        c.jac_age = run.jac_age;
        c.jac_full = run.jac_full;
        c.jac_rho = run.jac_rho;
        c.lu = run.lu.take();
        c.lags = std::mem::take(&mut run.lags);
        c.lag_seg = std::mem::take(&mut run.lag_seg);
        // the run writes no samples (NO_OUTPUT), so `outputs` adds 0
        self.stats.add_work(&run.stats);
        res?;
        self.y = run.y;
        self.memory = run.memory;
        self.t = t_end;
        // signals at t_end from the left: commands d, delayed commands of the history
        let mut hint = 0;
        let u = ModelInput {
            now: d,
            u_egr_delayed: self
                .sched
                .value_hint(2, t_end - self.delays[0], Side::Left, &mut hint),
            u_vgt_delayed: self
                .sched
                .value_hint(3, t_end - self.delays[1], Side::Left, &mut hint),
        };
        self.signals = self.model.eval(&self.y, &u, self.memory).signals;
        self.input = u;
        Ok(&self.signals)
    }
}

fn check_drive(d: &Drive, t: f64) -> Result<(), SimError> {
    for (name, v) in Drive::NAMES.iter().zip(d.to_array()) {
        if !v.is_finite() {
            return Err(SimError::BadCommand { name, value: v, t });
        }
    }
    Ok(())
}

/// A [`Plant`] of the variant chosen at run time (`--model 8|10|12`).
pub enum AnyPlant {
    /// 8 states.
    Eight(Box<Plant<8, Engine8>>),
    /// 10 states.
    Ten(Box<Plant<10, Engine10>>),
    /// 12 states.
    Twelve(Box<Plant<12, Engine12>>),
}

macro_rules! each {
    ($s:expr, $p:ident => $body:expr) => {
        match $s {
            AnyPlant::Eight($p) => $body,
            AnyPlant::Ten($p) => $body,
            AnyPlant::Twelve($p) => $body,
        }
    };
}

impl AnyPlant {
    /// See [`Plant::step`].
    pub fn step(&mut self, dt: f64, d: Drive) -> Result<&Signals, SimError> {
        each!(self, p => p.step(dt, d))
    }

    /// Current time \[s\].
    pub fn t(&self) -> f64 {
        each!(self, p => p.t())
    }

    /// Current state.
    pub fn state(&self) -> &[f64] {
        each!(self, p => p.state().as_slice())
    }

    /// State names.
    pub fn state_names(&self) -> Vec<&'static str> {
        each!(self, p => p.model().state_names().to_vec())
    }

    /// Signals at the current time.
    pub fn signals(&self) -> &Signals {
        each!(self, p => p.signals())
    }

    /// Solver statistics summed over all steps.
    pub fn stats(&self) -> SimStats {
        each!(self, p => p.stats())
    }

    /// See [`Plant::input`].
    pub fn input(&self) -> ModelInput {
        each!(self, p => p.input())
    }

    /// Value of a state or signal by name (states first: `p_im`, `p_em`, `omega_t`, ...).
    pub fn get(&self, name: &str) -> Option<f64> {
        each!(self, p => {
            let names = p.model().state_names();
            match names.iter().position(|n| *n == name) {
                Some(i) => Some(p.state()[i]),
                None => p.signals().get(name),
            }
        })
    }
}
