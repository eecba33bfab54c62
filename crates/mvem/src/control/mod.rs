//! Closed-loop simulation: discrete-time controllers around the plant.
//!
//! A [`Controller`] is called every [`Controller::sample_time`] seconds (default 10 ms) with a
//! [`Measurement`] and returns the commands u_delta, u_egr, u_vgt, held until the next sample
//! (zero-order hold). The plant is a [`Plant`](crate::sim::stepper::Plant): the real model with
//! exact actuator delays across samples, started at the steady state of the first commands. The
//! engine speed n_e is an input of the model, so the dynamometer holds the reference speed.
//!
//! - [`pid`]: discrete PID with tracking anti-windup for selector structures.
//! - [`baseline`]: the EGR/VGT controller (PID loops on lambda_O and x_egr combined by min
//!   selectors, after Wahlström, Eriksson and Nielsen 2010) and the torque-following engine
//!   controller with a smoke limiter; the open-loop schedule as a "controller" for comparison.
//! - [`cycle`]: the engine's mapping curve, the WHTC denormalization (UN GTR No. 4), demands.
//! - [`stats`]: the regulation's cycle statistics and the air-path figures of merit.
//! - [`margins`]: stability margins of discrete PI loops around the sampled linear model;
//!   [`along`]: those of the loops in feedback along a closed-loop run.
//! - [`drive`]: a whole cycle run (mapping curve, demand, controller, loop, statistics), shared
//!   by `mvem closed-loop` and the closed-loop mode of `mvem serve`.
//!
//! `docs/control.md` describes the design, the tuning and the results.

pub mod along;
pub mod baseline;
pub mod cycle;
pub mod drive;
pub mod margins;
pub mod pid;
pub mod stats;
pub mod steps;

use crate::analysis::steady::{any_plant_from_steady, SimFromSteadyError};
use crate::model::{AnyModel, Drive, Signals};
use crate::numerics::Num;
use crate::sim::{SimError, SimOptions, MAX_ROWS};
pub use cycle::Demand;

/// What a controller sees at a sample.
#[derive(Debug, Clone, Copy)]
pub struct Measurement<'a> {
    /// Sample time \[s\].
    pub t: f64,
    /// Reference speed held by the dynamometer = engine speed \[rpm\].
    pub n_e: f64,
    /// Torque demand \[Nm\].
    pub m_ref: f64,
    /// The demand is a motoring point (WHTC "m").
    pub motoring: bool,
    /// Every signal of the plant at this sample (the controller documents which it uses).
    pub signals: &'a Signals,
    /// Intake manifold pressure p_im \[Pa\] (state).
    pub p_im: f64,
    /// Exhaust manifold pressure p_em \[Pa\] (state).
    pub p_em: f64,
    /// Turbo speed omega_t [rad/s] (state).
    pub omega_t: f64,
    /// Oxygen mass fraction in the intake manifold X_Oim [-] (state).
    pub x_oim: f64,
}

/// Commands for the next sample interval and the set-points behind them (for logging).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// Injected fuel u_delta [mg/cycle/cylinder].
    pub u_delta: f64,
    /// EGR valve command u_egr [%].
    pub u_egr: f64,
    /// VGT command u_vgt [%].
    pub u_vgt: f64,
    /// Oxygen/fuel ratio set-point lambda_O,s [-] (NaN: none).
    pub lambda_o_ref: f64,
    /// EGR fraction set-point x_egr,s [-] (NaN: none).
    pub x_egr_ref: f64,
    /// Which feedback loop gave `u_egr` (`None`: no loop, e.g. an open-loop schedule or the
    /// first commands before any measurement).
    pub egr_loop: Option<InCharge>,
    /// Which feedback loop gave `u_vgt` (`None` as for `egr_loop`).
    pub vgt_loop: Option<InCharge>,
}

/// Which of a selector structure's loops is in feedback on a command at a sample: what a
/// linear analysis of the loops that ran must close ([`along::along_trajectory`]). For the
/// baseline ([`baseline::Baseline`]): the main loops lambda_O -> u_egr and x_egr -> u_vgt, the
/// limiters x_egr -> u_egr and lambda_O -> u_vgt.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InCharge {
    /// The command's main loop won its selector, within the command's limits.
    Main,
    /// The command's limiter loop won its selector, within the command's limits.
    Limiter,
    /// No loop feeds the measurement back: the command sits at one of its limits (clamped, or
    /// a loop's output exactly there: one-sided), or the loop that won sees a constant error
    /// (the lambda_O error at its cap).
    None,
}

impl InCharge {
    /// The code of the trajectory columns `egr_loop` / `vgt_loop`: 1 main loop, 2 limiter, 0
    /// no feedback; NaN (`None`): no loop.
    pub fn code(v: Option<Self>) -> f64 {
        match v {
            Some(Self::Main) => 1.0,
            Some(Self::Limiter) => 2.0,
            Some(Self::None) => 0.0,
            None => f64::NAN,
        }
    }

    /// The inverse of [`InCharge::code`] (NaN or an unknown code: `None`).
    pub fn from_code(c: f64) -> Option<Self> {
        match c {
            1.0 => Some(Self::Main),
            2.0 => Some(Self::Limiter),
            0.0 => Some(Self::None),
            _ => None,
        }
    }
}

/// A discrete-time controller.
pub trait Controller {
    /// Sample time \[s\] (default 10 ms).
    fn sample_time(&self) -> f64 {
        0.01
    }
    /// The commands before the first measurement (the plant starts in their steady state), for
    /// the demand at the start.
    fn start(&mut self, t0: f64, n_e: f64, m_ref: f64, motoring: bool) -> Output;
    /// The commands for the interval after the sample `m`.
    fn update(&mut self, m: &Measurement) -> Output;
    /// What the controller did during the run that its user should know (each a sentence;
    /// e.g. the baseline's loops that wound an actuator to its end, [`baseline::WindupEvent`]).
    fn notes(&self) -> Vec<String> {
        Vec::new()
    }
}

/// Why a closed-loop run failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ControlError {
    /// The plant failed (time and state in the message).
    #[error("plant: {0}")]
    Sim(#[from] SimError),
    /// The plant's initial steady state was not found (or its start failed).
    #[error("plant start: {0}")]
    Start(#[from] SimFromSteadyError),
    /// A controller gave a NaN or infinite command.
    #[error("controller gave {name} = {value} at t = {t} s")]
    BadCommand {
        /// Time \[s\].
        t: f64,
        /// Command name.
        name: &'static str,
        /// Value.
        value: f64,
    },
    /// The sample time is not usable.
    #[error("sample time {0} s must be finite and > 0")]
    BadSampleTime(f64),
    /// The demand is empty or not usable.
    #[error("demand: {0}")]
    Demand(String),
    /// A set-up computation (mapping curve, steady-state maps) failed.
    #[error("{0}")]
    Setup(String),
}

/// One row per controller sample: the commands given to the plant (held until the next row),
/// the demand and the plant's outputs at the sample.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// Columns in [`Trajectory::NAMES`] order.
    pub columns: Vec<Vec<f64>>,
}

impl Trajectory {
    /// Column names (units: [`Trajectory::UNITS`]).
    pub const NAMES: [&'static str; 19] = [
        "t",
        "n_e",
        "u_delta",
        "u_egr",
        "u_vgt",
        "M_ref",
        "M_e",
        "lambda_O",
        "lambda_O_ref",
        "x_egr",
        "x_egr_ref",
        "p_im",
        "p_em",
        "omega_t",
        "W_c",
        "W_f",
        "motoring",
        "egr_loop",
        "vgt_loop",
    ];

    /// Unit of each column, in [`Trajectory::NAMES`] order (`motoring` is 1 on samples where
    /// the engine is motored, else 0; `egr_loop` and `vgt_loop` say which loop gave the row's
    /// u_egr and u_vgt, [`InCharge::code`]: 1 the main loop, 2 the limiter, 0 none in feedback,
    /// NaN no loop).
    pub const UNITS: [&'static str; 19] = [
        "s", "rpm", "mg/cycle", "%", "%", "Nm", "Nm", "-", "-", "-", "-", "Pa", "Pa", "rad/s",
        "kg/s", "kg/s", "-", "-", "-",
    ];

    /// Unit of the column `name` (`""` for a name that is not a column).
    pub fn unit(name: &str) -> &'static str {
        Self::NAMES
            .iter()
            .position(|n| *n == name)
            .map_or("", |i| Self::UNITS[i])
    }

    /// Column by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        Self::NAMES
            .iter()
            .position(|n| *n == name)
            .map(|i| self.columns[i].as_slice())
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Run `ctrl` on the plant `model` along `demand` from its first to its last time.
///
/// At every sample t_k the controller sees the plant at t_k and its commands are held on
/// [t_k, t_k + T_s); the dynamometer holds n_e = the reference speed at t_k over the same
/// interval. The plant starts at the steady state of [`Controller::start`]'s commands.
pub fn run(
    model: AnyModel,
    demand: &Demand,
    ctrl: &mut dyn Controller,
    opts: &SimOptions,
) -> Result<(Trajectory, crate::sim::SimStats), ControlError> {
    run_with(model, demand, ctrl, opts, &mut |_| {})
}

/// [`run`], calling `on_row` with the trajectory so far after each row is appended (e.g. to
/// write the rows out while the loop runs). A demand longer than [`MAX_ROWS`] samples (one
/// trajectory row each) is refused before anything runs.
pub fn run_with(
    model: AnyModel,
    demand: &Demand,
    ctrl: &mut dyn Controller,
    opts: &SimOptions,
    on_row: &mut dyn FnMut(&Trajectory),
) -> Result<(Trajectory, crate::sim::SimStats), ControlError> {
    let ts = ctrl.sample_time();
    if !(ts.is_finite() && ts > 0.0) {
        return Err(ControlError::BadSampleTime(ts));
    }
    let (t0, t1) = demand.span();
    let samples = (t1 - t0) / ts + 1.0;
    if samples > MAX_ROWS {
        return Err(ControlError::Demand(format!(
            "{samples:.3e} controller samples of {} s from {} s to {} s (at most \
             {MAX_ROWS:e}, about {:.0} days at 10 ms); shorten the cycle",
            Num(ts),
            Num(t0),
            Num(t1),
            MAX_ROWS * 0.01 / 86400.0,
        )));
    }
    let n = ((t1 - t0) / ts + 1e-9).floor() as usize;
    if n == 0 {
        return Err(ControlError::Demand(format!(
            "the demand spans {} s from {} s, shorter than two controller samples ({} s apart)",
            Num(t1 - t0),
            Num(t0),
            Num(ts)
        )));
    }
    let d0 = demand.at(t0);
    let out0 = ctrl.start(t0, d0.n_e, d0.m_ref, d0.motoring);
    check_output(&out0, t0)?;
    let drive = |n_e: f64, o: &Output| Drive::new(n_e, o.u_delta, o.u_egr, o.u_vgt);
    let mut plant = any_plant_from_steady(model, drive(d0.n_e, &out0), t0, opts)?;
    let ix = |name: &str| {
        plant
            .state_names()
            .iter()
            .position(|s| *s == name)
            .expect("every variant has p_im, p_em, omega_t, X_Oim")
    };
    let (i_pim, i_pem, i_wt, i_xo) = (ix("p_im"), ix("p_em"), ix("omega_t"), ix("X_Oim"));
    let mut traj = Trajectory {
        // (not vec![..; k]: a cloned Vec does not keep the capacity)
        columns: (0..Trajectory::NAMES.len())
            .map(|_| Vec::with_capacity(n + 1))
            .collect(),
    };
    for k in 0..=n {
        let t = t0 + k as f64 * ts;
        let d = demand.at(t);
        let s = *plant.signals();
        let x = plant.state();
        let m = Measurement {
            t,
            n_e: d.n_e,
            m_ref: d.m_ref,
            motoring: d.motoring,
            signals: &s,
            p_im: x[i_pim],
            p_em: x[i_pem],
            omega_t: x[i_wt],
            x_oim: x[i_xo],
        };
        let o = if k == 0 { out0 } else { ctrl.update(&m) };
        check_output(&o, t)?;
        let row = [
            t,
            d.n_e,
            o.u_delta,
            o.u_egr,
            o.u_vgt,
            d.m_ref,
            s.m_e,
            s.lambda_o,
            o.lambda_o_ref,
            s.x_egr,
            o.x_egr_ref,
            m.p_im,
            m.p_em,
            m.omega_t,
            s.w_c,
            s.w_f,
            if d.motoring { 1.0 } else { 0.0 },
            InCharge::code(o.egr_loop),
            InCharge::code(o.vgt_loop),
        ];
        for (c, v) in traj.columns.iter_mut().zip(row) {
            c.push(v);
        }
        on_row(&traj);
        if k < n {
            plant.step(ts, drive(d.n_e, &o))?;
        }
    }
    Ok((traj, plant.stats()))
}

fn check_output(o: &Output, t: f64) -> Result<(), ControlError> {
    for (name, value) in [
        ("u_delta", o.u_delta),
        ("u_egr", o.u_egr),
        ("u_vgt", o.u_vgt),
    ] {
        if !value.is_finite() {
            return Err(ControlError::BadCommand { t, name, value });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::Trajectory;

    #[test]
    fn trajectory_units_agree_with_the_model_metadata() {
        let mut own = 0;
        for (n, u) in Trajectory::NAMES.iter().zip(Trajectory::UNITS) {
            let model = crate::model::meta::unit(n);
            if model.is_empty() {
                own += 1; // a column of the closed loop only (references, motoring flag)
            } else {
                assert_eq!(u, model, "{n}");
            }
            assert_eq!(Trajectory::unit(n), u);
        }
        assert_eq!(own, 6);
        assert_eq!(Trajectory::unit("M_ref"), "Nm");
        assert_eq!(Trajectory::unit("nope"), "");
    }
}
