//! Integration and output options, and the choice of method.

use super::SimError;

/// Integration and output options.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Relative tolerance (default 1e-6).
    pub rtol: f64,
    /// Absolute tolerance, relative to each state's scale (1e5 Pa for pressures, 0.1 for oxygen
    /// fractions, 1e4 rad/s for omega_t, 100 % for actuator states); default 1e-6 (0.1 Pa,
    /// 1e-7, 0.01 rad/s, 1e-4 %).
    pub atol: f64,
    /// Output interval \[s\] (default 0.01); the end time is always output.
    pub dt_out: f64,
    /// Maximum step size \[s\] (default: unbounded).
    pub h_max: f64,
    /// Stop at input breakpoints (default true). With `false` the step is bounded by
    /// `h_max` only (set it to the row spacing), for comparison.
    pub stop_at_breakpoints: bool,
    /// Maximum number of steps before giving up.
    pub max_steps: usize,
    /// Integration method.
    pub method: Method,
    /// Integrate the actuator states ([`Model::linear_lags`](crate::model::Model::linear_lags):
    /// first-order lags of the delayed, saturated commands, eqs (40), (41), (57)) in closed form
    /// on every segment where their driving command is linear, and the other states by the
    /// W-method with them as known functions of time (default true; the Rosenbrock methods
    /// [`Method::Rosenbrock34`], [`Method::Rodas4`] and [`Method::Exprb32`] only). `false`
    /// integrates all states numerically, for comparison.
    pub exact_actuators: bool,
    /// With the actuator states in closed form ([`SimOptions::exact_actuators`]): stop at the
    /// breakpoints of the delayed commands that drive them (default true). `false` lets a step
    /// run across a delayed command's jump or kink: the closed form follows the piecewise-linear,
    /// saturated delayed command exactly inside the step, and the other states see a kink in the
    /// actuator state there, which the error control handles. A plant stepped with held commands
    /// (closed loop) then makes one segment per sample instead of about two (the EGR delay puts
    /// the delayed copy of every command change inside a sample); `docs/control.md`.
    pub stop_at_lag_breakpoints: bool,
    /// ROS34PW2 ([`Method::Rosenbrock34`]): add the non-autonomous term gamma_i h^2 f_t to its
    /// stages (default true), f_t = df/dt of the integrated system by one difference along the
    /// inputs' slopes, recomputed with the Jacobian and at the first step of every segment
    /// between input breakpoints where the slopes changed. `false` omits it (the default of
    /// earlier versions, kept for comparison): the W-method is of order 3 either way, but the term carries the slope
    /// changes at the input kinks into the stages, which saves steps (`docs/integrator.md`,
    /// "The non-autonomous term of ROS34PW2").
    pub rosw_time_derivative: bool,
    /// Time-parallel integration of one open-loop simulation in this many chunks, each on its
    /// own thread (default 1: the sequential run, bit for bit). Chunk k > 0 starts
    /// [`SimOptions::chunk_overlap`] before its first time from a guess, and its samples are
    /// kept only if its state at that time agrees with the previous chunk's within
    /// [`super::JUNCTION_TOL`] tolerance units; otherwise the previous chunk's integrator
    /// continues over it (the sequential run: correct always). Models holding memory
    /// ([`crate::model::Dynamics::holds_memory`]) and runs without stop times integrate
    /// sequentially. See [`super::simulate_into_with_guess`] and `docs/integrator.md`.
    pub time_chunks: usize,
    /// Warm-up of each time-parallel chunk after the first \[s\] (default 30 s: on the WHTC the
    /// difference from the sequential run of a start at the steady state of the inputs there
    /// fell below 0.1 tolerance units within at most 28 s, the slowest steady-state pole being
    /// -0.21 1/s; `docs/integrator.md`).
    pub chunk_overlap: f64,
}

/// Integration method (see `docs/integrator.md` for the measured comparison).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Rosenbrock-W method ROS34PW2 (Rang & Angermann 2005): 4 stages, order 3(2), L-stable,
    /// stiffly accurate, valid with an approximate (lagged, finite-difference) Jacobian. Default:
    /// the model is mildly stiff (poles down to about -120 1/s at idle) and the drive cycle has
    /// an input breakpoint every ~0.13 s on average, so a one-step linearly implicit method wins.
    /// With the non-autonomous term gamma_i h^2 f_t in its stages by default
    /// ([`SimOptions::rosw_time_derivative`]).
    #[default]
    Rosenbrock34,
    /// Dormand-Prince 5(4), explicit, with 4th-order dense output (Hairer's DOPRI5).
    Dopri5,
    /// Rosenbrock method RODAS4 (Hairer & Wanner): 6 stages, order 4(3), L-stable, stiffly
    /// accurate, all stages inside the step. Not a W-method: a fresh finite-difference Jacobian
    /// and the time derivative along the (piecewise linear) inputs at every step; see
    /// `docs/integrator.md` for the measured comparison with ROS34PW2.
    Rodas4,
    /// Exponential Rosenbrock method exprb32 (Hochbruck, Ostermann & Schweitzer 2009): order
    /// 3 with the exponential Rosenbrock-Euler method (order 2) as embedded method, the
    /// linearized dynamics integrated exactly through the matrix functions phi_1..phi_3 of
    /// h J. Needs the exact Jacobian and time derivative: computed afresh at every step as for
    /// RODAS4, with RODAS4's step-control rules. Not the default: at equal accuracy on the WHTC
    /// it takes fewer trial steps than ROS34PW2 but twice the instructions (the Jacobian, f_t
    /// and the phi functions at every step); see `docs/integrator.md`.
    Exprb32,
}

impl Method {
    /// Classical order of the propagating method.
    pub fn order(self) -> u32 {
        match self {
            Method::Rosenbrock34 => 3,
            Method::Dopri5 => 5,
            Method::Rodas4 => 4,
            Method::Exprb32 => 3,
        }
    }

    /// Whether the method is linearly implicit (a Rosenbrock method: Jacobian, iteration
    /// matrix; closed-form lag states available, see [`SimOptions::exact_actuators`]).
    pub fn is_rosenbrock(self) -> bool {
        matches!(
            self,
            Method::Rosenbrock34 | Method::Rodas4 | Method::Exprb32
        )
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
            stop_at_lag_breakpoints: true,
            rosw_time_derivative: true,
            time_chunks: 1,
            chunk_overlap: 30.0,
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
        if !(1..=MAX_TIME_CHUNKS).contains(&self.time_chunks) {
            return bad(
                "time_chunks",
                self.time_chunks as f64,
                "must lie in 1..=256",
            );
        }
        if !(self.chunk_overlap.is_finite() && self.chunk_overlap > 0.0) {
            return bad(
                "chunk_overlap",
                self.chunk_overlap,
                "must be finite and > 0",
            );
        }
        Ok(())
    }
}

/// Most time chunks of one simulation ([`SimOptions::time_chunks`]).
pub const MAX_TIME_CHUNKS: usize = 256;
