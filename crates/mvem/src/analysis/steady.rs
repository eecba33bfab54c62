//! Steady state (equilibrium) f(x, u) = 0 at constant inputs.
//!
//! The actuator states equal the saturated commands at equilibrium, so the solve is over the
//! remaining states (5 for the 8-state model) in scaled variables (state / typical magnitude),
//! residuals scaled the same way (units 1/s). Method: damped Newton with a finite-difference
//! Jacobian and a backtracking line search that keeps the iterate inside the integrator limits;
//! if that fails or lands on an unstable equilibrium, a settling simulation (40 s, then 200 s)
//! from the guess provides a new start, as the reference procedure does. Without a given guess,
//! the 10- and 12-state models start from the 8-state equilibrium lifted into their state space
//! (temperatures at their inflow values, p_c from the intercooler pressure drop).
//!
//! A converged equilibrium is always checked: [`SteadyState::flags`] lists every active guard
//! saturation of the authors' implementation, lambda_O < 1, integrator limits, an unstable
//! linearization, and the model regimes (choked EGR, no EGR flow, linear c_m branch).
//! [`SteadyState::physically_valid`] is false when any invalidating flag is present.

use crate::analysis::zeros;
use crate::model::{AnyModel, Drive, Guard, InputError, Model, ModelInput, Signals};
use crate::sim::stepper::{AnyPlant, Plant};
use crate::sim::{
    check_interval, simulate, simulate_checked, InputSchedule, Side, SimError, SimOptions,
    Solution, Start,
};
use nalgebra::{DMatrix, DVector};

/// A converged equilibrium.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadyState<const N: usize> {
    /// Inputs as given.
    pub drive: Drive,
    /// Equilibrium state.
    pub x: [f64; N],
    /// Signals at the equilibrium.
    pub signals: Signals,
    /// Max |dx_i / scale_i| at the solution [1/s].
    pub residual: f64,
    /// Newton iterations used (total over attempts).
    pub iterations: usize,
    /// Whether a settling simulation was needed.
    pub settled: bool,
    /// Eigenvalues (re, im) of the Jacobian of the solved (non-actuator) states [1/s], sorted
    /// by decreasing real part, then increasing imaginary part.
    pub eigenvalues: Vec<(f64, f64)>,
    /// Flags: guard saturations, lambda_O<1, integrator limits, `unstable`, regimes.
    pub flags: Vec<String>,
    /// Whether any flag invalidates the point as a physical equilibrium.
    invalid: bool,
}

impl<const N: usize> SteadyState<N> {
    /// No invalidating flag: no guard saturation of the authors' implementation is active,
    /// lambda_O >= 1, no state at an integrator limit and the equilibrium is stable.
    pub fn physically_valid(&self) -> bool {
        !self.invalid
    }
}

/// Why no equilibrium was returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SteadyError {
    /// An input the model cannot be evaluated at (NaN, infinite, or n_e <= 0 with the paper's
    /// equations; [`Drive::check`]).
    #[error("{0}")]
    Input(#[from] InputError),
    /// Neither Newton nor the settling simulations reached the tolerance.
    #[error("no equilibrium found at n_e={} rpm, u_delta={} mg/cycle, u_egr={} %, u_vgt={} %: {reason} (best residual {residual:.3e} 1/s at {state})", .drive.n_e_rpm, .drive.u_delta_mg, .drive.u_egr_pct, .drive.u_vgt_pct)]
    NoConvergence {
        /// Inputs.
        drive: Drive,
        /// Best scaled residual [1/s].
        residual: f64,
        /// Best state, formatted.
        state: String,
        /// What failed.
        reason: String,
    },
    /// The settling simulation was cancelled by the caller's token
    /// ([`crate::numerics::cancel`]): no verdict on the equilibrium.
    #[error("cancelled while settling at n_e={} rpm, u_delta={} mg/cycle, u_egr={} %, u_vgt={} % (a cancellation request, e.g. Ctrl-C)", .drive.n_e_rpm, .drive.u_delta_mg, .drive.u_egr_pct, .drive.u_vgt_pct)]
    Cancelled {
        /// Inputs.
        drive: Drive,
    },
}

/// Why [`simulate_from_steady`] failed: no initial equilibrium, or the simulation itself.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimFromSteadyError {
    /// The steady state at the first inputs was not found.
    #[error("initial steady state: {0}")]
    Steady(#[from] SteadyError),
    /// The simulation failed (options, interval, or integration).
    #[error("{0}")]
    Sim(#[from] SimError),
    /// A given start state ([`super::ensemble::Case::start`]) has the wrong number of values.
    #[error("start state: expected {expected} values (the model's states), got {got}")]
    StartLength {
        /// The model's number of states.
        expected: usize,
        /// The values given.
        got: usize,
    },
    /// Not run: the caller cancelled the ensemble before this run started
    /// ([`crate::numerics::cancel`]).
    #[error("not run: the ensemble was cancelled")]
    Cancelled,
}

/// Simulate `model` driven by `sched` from `t0` to `t_end`, starting at the steady state at
/// the inputs just before `t0` (left limit: a step at `t0`, two rows with the time `t0`, is a
/// step the run shows, as the delayed commands' history before `t0` holds the values before
/// it): [`steady_state`], then [`simulate`]. Options and the interval are checked first.
pub fn simulate_from_steady<const N: usize, M: Model<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    opts: &SimOptions,
) -> Result<Solution, SimFromSteadyError> {
    let start = steady_start(model, sched, t0, t_end, opts)?;
    let guess = chunk_guess(model, sched);
    let sol = Solution::new(&model.state_names());
    // (steady_start checked the interval)
    Ok(simulate_checked(
        model,
        sched,
        t0,
        t_end,
        start,
        opts,
        sol,
        Some(&guess),
    )?)
}

/// The start of a time-parallel chunk ([`SimOptions::time_chunks`]): the steady state at the
/// inputs at `t` (right limit; Newton only, no settling simulation: `None` if it does not
/// converge, and the chunk then starts from the simulation's initial state).
pub fn chunk_guess<'a, const N: usize, M: Model<N>>(
    model: &'a M,
    sched: &'a InputSchedule,
) -> impl Fn(f64) -> Option<[f64; N]> + Sync + 'a {
    move |t| {
        let opts = SteadyOptions {
            settle: false,
            ..SteadyOptions::default()
        };
        steady_state_with(model, &sched.at(t), None, &opts)
            .ok()
            .map(|s| s.x)
    }
}

/// [`simulate_from_steady`] writing its samples to `sol` (e.g. a [`Solution::streaming`] one;
/// see [`simulate_into`](crate::sim::simulate_into)). A failure of the steady state drops `sol`
/// and its sender.
pub fn simulate_from_steady_into<const N: usize, M: Model<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    opts: &SimOptions,
    sol: Solution,
) -> Result<Solution, SimFromSteadyError> {
    let start = steady_start(model, sched, t0, t_end, opts)?;
    let guess = chunk_guess(model, sched);
    // (steady_start checked the interval)
    Ok(simulate_checked(
        model,
        sched,
        t0,
        t_end,
        start,
        opts,
        sol,
        Some(&guess),
    )?)
}

/// The steady state at the inputs just before `t0` (left limit), after checking the options
/// and the interval.
fn steady_start<const N: usize, M: Model<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    opts: &SimOptions,
) -> Result<Start<N>, SimFromSteadyError> {
    check_interval(opts, t0, t_end)?;
    let mut h = 0;
    let d = Drive::from_array(std::array::from_fn(|c| {
        sched.value_hint(c, t0, Side::Left, &mut h)
    }));
    Ok(Start::State(steady_state(model, &d)?.x))
}

/// A [`Plant`] (the model advanced sample by sample with held commands) started at `t0` in the
/// steady state of the commands `d`, held since forever.
pub fn plant_from_steady<const N: usize, M: Model<N>>(
    model: M,
    d: Drive,
    t0: f64,
    opts: &SimOptions,
) -> Result<Plant<N, M>, SimFromSteadyError> {
    let x0 = steady_state(&model, &d)?.x;
    Ok(Plant::from_state(model, d, t0, x0, opts)?)
}

/// [`plant_from_steady`] for the variant chosen at run time (`--model 8|10|12`).
pub fn any_plant_from_steady(
    model: AnyModel,
    d: Drive,
    t0: f64,
    opts: &SimOptions,
) -> Result<AnyPlant, SimFromSteadyError> {
    Ok(match model {
        AnyModel::Eight(m) => AnyPlant::Eight(Box::new(plant_from_steady(m, d, t0, opts)?)),
        AnyModel::Ten(m) => AnyPlant::Ten(Box::new(plant_from_steady(m, d, t0, opts)?)),
        AnyModel::Twelve(m) => AnyPlant::Twelve(Box::new(plant_from_steady(m, d, t0, opts)?)),
    })
}

/// Options of the steady-state solver.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadyOptions {
    /// Convergence: max scaled residual [1/s].
    pub tol: f64,
    /// Newton iteration limit per attempt.
    pub max_iter: usize,
    /// Allow the settling-simulation fallback.
    pub settle: bool,
}

impl Default for SteadyOptions {
    fn default() -> Self {
        Self {
            tol: 1e-10,
            max_iter: 60,
            settle: true,
        }
    }
}

/// Steady state at `d` from the model's initial guess (see the module documentation; the
/// extensions start from the 8-state equilibrium, see [`Model::lift_equilibrium_8`]).
pub fn steady_state<const N: usize, M: Model<N>>(
    m: &M,
    d: &Drive,
) -> Result<SteadyState<N>, SteadyError> {
    steady_state_with(m, d, None, &SteadyOptions::default())
}

/// Steady state at `d` starting from `guess` (e.g. a neighbouring operating point).
pub fn steady_state_with<const N: usize, M: Model<N>>(
    m: &M,
    d: &Drive,
    guess: Option<&[f64; N]>,
    opts: &SteadyOptions,
) -> Result<SteadyState<N>, SteadyError> {
    d.check(m.options().semantics)?;
    // At an equilibrium the one-iteration memory equals the fixed point: solve with the
    // converged cylinder-out temperature whatever the model's option.
    if m.options().cylinder_temp != crate::model::CylinderTemp::Converged {
        let mut o = *m.options();
        o.cylinder_temp = crate::model::CylinderTemp::Converged;
        return steady_state_with(&m.with_options(o), d, guess, opts);
    }
    let fixed = m.actuator_state_values(d);
    let mut x0 = match guess {
        Some(g) => *g,
        None => seed_from_8(m, d, opts).unwrap_or_else(|| m.initial_guess(d)),
    };
    for (i, v) in &fixed {
        x0[*i] = *v;
    }
    let solver = Newton::new(m, d, &fixed);
    let mut iterations = 0;
    let mut best: Option<([f64; N], f64)> = None;
    let mut reason = String::from("Newton did not converge");

    let attempt = |start: [f64; N],
                   settled: bool,
                   iterations: &mut usize,
                   best: &mut Option<([f64; N], f64)>,
                   reason: &mut String|
     -> Option<SteadyState<N>> {
        let r = solver.solve(start, opts);
        *iterations += r.iterations;
        if best.as_ref().is_none_or(|b| r.residual < b.1) {
            *best = Some((r.x, r.residual));
        }
        if r.residual <= opts.tol {
            match solver.finish(r.x, r.residual, *iterations, settled) {
                Ok(ss) if ss.eigenvalues.iter().all(|e| e.0 < 0.0) || !opts.settle => {
                    return Some(ss)
                }
                Ok(_) => *reason = "Newton converged to an unstable equilibrium".into(),
                Err(why) => *reason = why,
            }
        } else if let Some(why) = r.why {
            *reason = why;
        }
        None
    };

    if let Some(ss) = attempt(x0, false, &mut iterations, &mut best, &mut reason) {
        return Ok(ss);
    }
    if opts.settle {
        let sched = InputSchedule::constant(*d);
        // A budget: settling at constant inputs takes hundreds of steps; a run that needs
        // 20 000 (fast oscillation, equilibrium lost; a few tens of ms) fails with
        // TooManySteps, reported as the reason, instead of running for minutes.
        let sim_opts = SimOptions {
            rtol: 1e-6,
            atol: 1e-8,
            dt_out: 1e9,
            max_steps: 20_000,
            ..SimOptions::default()
        };
        let mut start = x0;
        for dur in [40.0, 200.0] {
            match simulate(m, &sched, 0.0, dur, Start::State(start), &sim_opts) {
                Ok(sol) => {
                    let names = m.state_names();
                    let last = sol.len() - 1;
                    for (i, n) in names.iter().enumerate() {
                        start[i] = sol.get(n).map(|c| c[last]).unwrap_or(start[i]);
                    }
                    for (i, v) in &fixed {
                        start[*i] = *v;
                    }
                    if let Some(ss) = attempt(start, true, &mut iterations, &mut best, &mut reason)
                    {
                        return Ok(ss);
                    }
                }
                Err(SimError::Cancelled { .. }) => {
                    return Err(SteadyError::Cancelled { drive: *d });
                }
                // the settling run's own step budget, which no caller sets: no hint to raise it
                Err(SimError::TooManySteps {
                    max_steps,
                    t,
                    state,
                    ..
                }) => {
                    reason = format!(
                        "the settling run did not settle within its {max_steps} steps (stopped at \
                         t = {} s; state: {state}): the model is too stiff here or has no \
                         equilibrium at these inputs",
                        crate::numerics::Num(t)
                    );
                    break;
                }
                Err(e) => {
                    reason = format!("settling simulation failed: {e}");
                    break;
                }
            }
        }
    }
    let (bx, br) = best.unwrap_or((x0, f64::INFINITY));
    let names = m.state_names();
    let state = names
        .iter()
        .zip(bx.iter())
        .map(|(n, v)| format!("{n}={v:.6e}"))
        .collect::<Vec<_>>()
        .join(", ");
    Err(SteadyError::NoConvergence {
        drive: *d,
        residual: br,
        state: format!("[{state}]"),
        reason,
    })
}

/// For the extensions (10, 12 states): the 8-state equilibrium at `d`, lifted into the
/// extension's state space ([`Model::lift_equilibrium_8`]); `None` for the 8-state model or if
/// the 8-state solve fails. The 10-state steady states equal the 8-state ones and the 12-state
/// ones differ by the intercooler pressure drop, so Newton converges from there without the
/// settling fallback that the heuristic guess often needs.
fn seed_from_8<const N: usize, M: Model<N>>(
    m: &M,
    d: &Drive,
    opts: &SteadyOptions,
) -> Option<[f64; N]> {
    let m8 = m.reduced_8()?;
    let ss8 = steady_state_with(m8, d, None, opts).ok()?;
    let x = m.lift_equilibrium_8(&ss8.x, &ss8.signals)?;
    x.iter().all(|v| v.is_finite()).then_some(x)
}

struct NewtonResult<const N: usize> {
    x: [f64; N],
    residual: f64,
    iterations: usize,
    why: Option<String>,
}

struct Newton<'a, const N: usize, M: Model<N>> {
    m: &'a M,
    u: ModelInput,
    free: Vec<usize>,
    scale: [f64; N],
    bounds: [(f64, f64); N],
}

impl<'a, const N: usize, M: Model<N>> Newton<'a, N, M> {
    fn new(m: &'a M, d: &Drive, fixed: &[(usize, f64)]) -> Self {
        let free = (0..N)
            .filter(|i| !fixed.iter().any(|f| f.0 == *i))
            .collect();
        Self {
            m,
            u: ModelInput::constant(*d),
            free,
            scale: m.state_scales(),
            bounds: m.state_bounds(),
        }
    }

    fn memory(&self, x: &[f64; N]) -> M::Memory {
        self.m.memory_start(x, &self.u)
    }

    /// Scaled residual of the free states.
    fn residual(&self, x: &[f64; N]) -> DVector<f64> {
        let ev = self.m.eval(x, &self.u, self.memory(x));
        DVector::from_iterator(
            self.free.len(),
            self.free.iter().map(|&i| ev.dx[i] / self.scale[i]),
        )
    }

    fn jacobian(&self, x: &[f64; N], r0: &DVector<f64>) -> DMatrix<f64> {
        let n = self.free.len();
        let mut j = DMatrix::zeros(n, n);
        for (c, &i) in self.free.iter().enumerate() {
            let mut xp = *x;
            let mut h = 1e-7 * (x[i].abs() / self.scale[i]).max(1.0);
            // step inward if at an upper bound
            if (x[i] + h * self.scale[i]) > self.bounds[i].1 {
                h = -h;
            }
            xp[i] += h * self.scale[i];
            let rp = self.residual(&xp);
            for r in 0..n {
                j[(r, c)] = (rp[r] - r0[r]) / h;
            }
        }
        j
    }

    fn solve(&self, mut x: [f64; N], opts: &SteadyOptions) -> NewtonResult<N> {
        let mut r = self.residual(&x);
        let norm = |v: &DVector<f64>| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let mut res = norm(&r);
        if !res.is_finite() {
            return NewtonResult {
                x,
                residual: f64::INFINITY,
                iterations: 0,
                why: Some("non-finite residual at the start".into()),
            };
        }
        for it in 0..opts.max_iter {
            if res <= opts.tol * 0.01 {
                return NewtonResult {
                    x,
                    residual: res,
                    iterations: it,
                    why: None,
                };
            }
            let j = self.jacobian(&x, &r);
            let Some(dz) = j.lu().solve(&(-&r)) else {
                return NewtonResult {
                    x,
                    residual: res,
                    iterations: it,
                    why: Some("singular Jacobian (a guard saturation may freeze a state)".into()),
                };
            };
            // step length: keep inside the limits (at most to 99 % of the way to a bound)
            let mut alpha: f64 = 1.0;
            for (c, &i) in self.free.iter().enumerate() {
                let step = dz[c] * self.scale[i];
                let (lo, hi) = self.bounds[i];
                if step < 0.0 && lo.is_finite() {
                    alpha = alpha.min(0.99 * (x[i] - lo) / -step);
                } else if step > 0.0 && hi.is_finite() {
                    alpha = alpha.min(0.99 * (hi - x[i]) / step);
                }
                // without integrator limits (paper semantics) keep positive states positive
                if step < 0.0 && !lo.is_finite() && x[i] > 0.0 {
                    alpha = alpha.min(0.9 * x[i] / -step);
                }
            }
            let f0 = r.norm_squared();
            let mut accepted = false;
            for _ in 0..30 {
                let mut xn = x;
                for (c, &i) in self.free.iter().enumerate() {
                    xn[i] += alpha * dz[c] * self.scale[i];
                }
                let rn = self.residual(&xn);
                let fnn = rn.norm_squared();
                if fnn.is_finite() && fnn <= (1.0 - 1e-4 * alpha) * f0 {
                    let small_step = dz.iter().all(|v| (alpha * v).abs() < 1e-14);
                    x = xn;
                    r = rn;
                    res = norm(&r);
                    accepted = true;
                    if small_step && res <= opts.tol {
                        return NewtonResult {
                            x,
                            residual: res,
                            iterations: it + 1,
                            why: None,
                        };
                    }
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                return NewtonResult {
                    x,
                    residual: res,
                    iterations: it + 1,
                    why: Some("line search failed (no descent direction)".into()),
                };
            }
        }
        NewtonResult {
            x,
            residual: res,
            iterations: opts.max_iter,
            why: Some(format!("iteration limit {} reached", opts.max_iter)),
        }
    }

    fn finish(
        &self,
        x: [f64; N],
        residual: f64,
        iterations: usize,
        settled: bool,
    ) -> Result<SteadyState<N>, String> {
        let ev = self.m.eval(&x, &self.u, self.memory(&x));
        let r0 = self.residual(&x);
        let j = self.jacobian(&x, &r0);
        // bounded and checked (finite entries, balancing, an iteration limit), sorted by
        // decreasing real part
        let eigenvalues: Vec<(f64, f64)> = zeros::eigenvalues(&j)
            .map_err(|e| format!("eigenvalues of the Jacobian at the solution: {e}"))?
            .iter()
            .map(|c| (c.re, c.im))
            .collect();
        let mut flags: Vec<String> = Vec::new();
        let mut invalid = false;
        for g in Guard::ALL {
            if ev.signals.has(*g) {
                flags.push(g.label().to_string());
                invalid |= g.invalidates();
            }
        }
        if eigenvalues.iter().any(|e| e.0 >= 0.0) {
            flags.push("unstable".into());
            invalid = true;
        }
        Ok(SteadyState {
            drive: self.u.now,
            x,
            signals: ev.signals,
            residual,
            iterations,
            settled,
            eigenvalues,
            flags,
            invalid,
        })
    }
}
