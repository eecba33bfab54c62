//! Robustness sweep ("never crash, never lie"): many simulations with random, seeded input
//! sequences and start states, each checked for panics, clear errors, non-finite output and the
//! physical invariants of the authors' implementation at every output sample.
//!
//! Each run `k` of a sweep with seed `s` is fully determined by `(s, k)` (SplitMix64 stream), so
//! any failing run can be replayed alone with [`scenario`] and [`run_scenario`]. The inputs cover
//! the input box of the authors' saturations and beyond: n_e 300-2500 rpm, u_delta 0-300 mg,
//! u_egr and u_vgt -20..120 %, as steps, ramps, WHTC-like motoring/full-load jumps, or a mix.
//! Start states are steady states (a small bank per model, computed once) perturbed by a few
//! percent ("near") or tens of percent ("perturbed"), or drawn anywhere inside the integrator
//! limits ("far").
//!
//! Invariants checked at every output sample (authors' semantics; tolerance [`INVARIANT_TOL`]
//! relative):
//! - `0 <= X_Oim, X_Oem <= X_Oc` (oxygen fractions of mixtures of air and exhaust, eqs (6), (9));
//! - `p_im` in `[0.5, 10] p_amb`, `p_em` in `[0.5, 20] p_amb` (integrator limits, items 9-10);
//! - every other state with a finite integrator limit within it: `omega_t` (item 37), and in
//!   the extended models `p_c` (as `p_im`) and the temperatures `T_im`, `T_em`, `T_ic`
//!   (`>= 0.5 T_amb`);
//! - `lambda_O >= 0`, and `lambda_O > 0` wherever `X_Oim > 0` (eq. (15): lambda_O is
//!   proportional to X_Oim, which may sit at its integrator limit 0 after oxygen-free EGR);
//! - `W_c >= 1e-4` kg/s (compressor flow floor of the authors' implementation), `W_t >= 0`,
//!   `W_egr >= 0` (authors' semantics: no reverse flow, eqs (32), (55)), `W_ei >= 0`,
//!   `W_eo >= 0`, `W_f >= 0` (eqs (11), (13), (14)), and `W_ic` with the sign of `p_c - p_im`
//!   (eq. (86), signed back flow in the 12-state model; `W_ic = W_c` otherwise);
//! - every value of every output column finite.

use crate::model::{AnyModel, Drive, Model, ModelOptions, ModelOrder};
use crate::params::Params;
use crate::sim::{simulate, InputSchedule, Method, SimError, SimOptions, Solution, Start};
use std::collections::BTreeMap;
use std::fmt;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Relative tolerance of the invariant checks (rounding of the integrator's clipping and of
/// the mixing equations).
pub const INVARIANT_TOL: f64 = 1e-9;

/// Allowed excursion of a *state* beyond an invariant bound that the model does not enforce by
/// an integrator limit (X_Oim, X_Oem <= X_Oc), in units of the solver's error tolerance at the
/// bound, `rtol + atol * scale / |bound|` (relative to the bound; `atol` is scaled by the
/// state's scale, as in the integrator; see [`state_allowance`]): the exact solution stays
/// inside, the numerical one only to within its (global) integration error. Excursions within
/// this allowance are counted and reported separately as numerical, larger ones are violations.
pub const STATE_SLACK_RTOL: f64 = 100.0;

/// Allowed relative excursion of a state beyond `bound`: [`STATE_SLACK_RTOL`] times the solver's
/// error tolerance there, `rtol + atol * scale / |bound|` (`scale`: the state's scale, by which
/// the integrator multiplies `atol`).
pub fn state_allowance(opts: &SimOptions, scale: f64, bound: f64) -> f64 {
    STATE_SLACK_RTOL * (opts.rtol + opts.atol * scale / bound.abs())
}

/// Minimum compressor flow of the authors' implementation [kg/s].
pub const W_C_MIN: f64 = 1e-4;

/// Deterministic pseudo-random numbers (SplitMix64; no external dependency, stable across
/// platforms and versions, so a (seed, run) pair always replays the same scenario).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// Generator for run `run` of the sweep with seed `seed`.
    pub fn new(seed: u64, run: u64) -> Self {
        let mut r = Rng(seed ^ 0x9E37_79B9_7F4A_7C15u64.wrapping_mul(run.wrapping_add(1)));
        r.next_u64();
        r
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform integer in [0, n).
    pub fn below(&mut self, n: usize) -> usize {
        (self.unit() * n as f64) as usize % n.max(1)
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.unit().max(1e-300);
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// Extended input box of the sweep: (min, max) per channel (n_e \[rpm\], u_delta \[mg\],
/// u_egr [%], u_vgt [%]); the authors' saturations are 500-2000 rpm, 1-250 mg, 0-100 %, 20-100 %.
pub const INPUT_BOX: [(f64, f64); 4] = [
    (300.0, 2500.0),
    (0.0, 300.0),
    (-20.0, 120.0),
    (-20.0, 120.0),
];

/// Shape of the random input sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum InputKind {
    /// Held values with random steps on random channels.
    Steps,
    /// Piecewise-linear ramps between random points.
    Ramps,
    /// WHTC-like: jumps between motoring (u_delta = 0) and full load, with speed jumps.
    Whtc,
    /// Steps and ramps mixed, one knot type at random per knot.
    Mixed,
}

/// How far from equilibrium the run starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum StartKind {
    /// A steady state perturbed by about 2 %.
    Near,
    /// A steady state perturbed by about 30 %.
    Perturbed,
    /// Anywhere inside the integrator limits (uniform / log-uniform per state).
    Far,
}

/// One random scenario (model-independent part).
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Run index.
    pub run: u64,
    /// Input shape.
    pub input: InputKind,
    /// Start kind.
    pub start: StartKind,
    /// Inputs.
    pub sched: InputSchedule,
    /// Integration method.
    pub method: Method,
    /// Generator positioned after the inputs, for drawing the start state.
    pub rng: Rng,
}

fn random_row(r: &mut Rng) -> [f64; 4] {
    std::array::from_fn(|c| r.range(INPUT_BOX[c].0, INPUT_BOX[c].1))
}

/// Random input sequence on `[0, t_end]` (knots every 0.2-15 s).
pub fn random_inputs(r: &mut Rng, kind: InputKind, t_end: f64) -> InputSchedule {
    let mut times = vec![0.0];
    let mut rows = vec![random_row(r)];
    let mut t = 0.0;
    let mut cur = rows[0];
    loop {
        let dwell = match kind {
            InputKind::Whtc => r.range(0.2, 6.0),
            _ => r.range(0.5, 15.0),
        };
        t += dwell;
        if t >= t_end {
            break;
        }
        let mut next = cur;
        let jump = match kind {
            InputKind::Steps => {
                // one to four channels change
                for _ in 0..1 + r.below(4) {
                    let c = r.below(4);
                    next[c] = r.range(INPUT_BOX[c].0, INPUT_BOX[c].1);
                }
                true
            }
            InputKind::Ramps => {
                next = random_row(r);
                false
            }
            InputKind::Whtc => {
                // motoring <-> full load, speed jumps, valves anywhere
                let motoring = cur[1] > 100.0;
                next[1] = if motoring {
                    r.range(0.0, 1.0)
                } else {
                    r.range(230.0, 300.0)
                };
                next[0] = r.range(INPUT_BOX[0].0, INPUT_BOX[0].1);
                if r.unit() < 0.5 {
                    next[2] = r.range(INPUT_BOX[2].0, INPUT_BOX[2].1);
                    next[3] = r.range(INPUT_BOX[3].0, INPUT_BOX[3].1);
                }
                r.unit() < 0.8
            }
            InputKind::Mixed => {
                next = random_row(r);
                r.unit() < 0.5
            }
        };
        if jump {
            times.push(t);
            rows.push(cur);
        }
        times.push(t);
        rows.push(next);
        cur = next;
    }
    times.push(t_end);
    rows.push(cur);
    InputSchedule::new(times, rows).expect("generated schedule is finite and monotonic")
}

/// The model-independent scenario of run `run` of a sweep with seed `seed`.
pub fn scenario(seed: u64, run: u64, t_end: f64, methods: &[Method]) -> Scenario {
    let mut r = Rng::new(seed, run);
    let input = [
        InputKind::Steps,
        InputKind::Ramps,
        InputKind::Whtc,
        InputKind::Mixed,
    ][r.below(4)];
    let start = match r.unit() {
        u if u < 0.4 => StartKind::Near,
        u if u < 0.7 => StartKind::Perturbed,
        _ => StartKind::Far,
    };
    let method = methods[(run as usize) % methods.len().max(1)];
    let sched = random_inputs(&mut r, input, t_end);
    Scenario {
        run,
        input,
        start,
        sched,
        method,
        rng: r,
    }
}

/// Steady states of a model at a few operating points (dimension-independent), the base of
/// the near and perturbed start states.
#[derive(Debug, Clone)]
pub struct StartBank {
    /// Equilibrium states.
    pub states: Vec<Vec<f64>>,
}

/// Operating points of the start bank: idle to full load at three speeds, valves mid-range.
pub const BANK_POINTS: [[f64; 4]; 9] = [
    [600.0, 5.0, 0.0, 100.0],
    [800.0, 40.0, 30.0, 60.0],
    [1000.0, 100.0, 50.0, 40.0],
    [1200.0, 150.0, 20.0, 50.0],
    [1500.0, 200.0, 0.0, 40.0],
    [1500.0, 60.0, 80.0, 30.0],
    [1800.0, 240.0, 10.0, 70.0],
    [1900.0, 120.0, 60.0, 25.0],
    [1300.0, 10.0, 100.0, 100.0],
];

impl StartBank {
    /// Compute the bank for `model` (points without a steady state are skipped).
    pub fn new<const N: usize, M: Model<N>>(model: &M) -> Self {
        let states = BANK_POINTS
            .iter()
            .filter_map(|d| {
                crate::analysis::steady::steady_state(model, &Drive::from_array(*d)).ok()
            })
            .map(|s| s.x.to_vec())
            .collect();
        Self { states }
    }
}

/// Start state of a scenario for `model` (drawn from `r`).
pub fn start_state<const N: usize, M: Model<N>>(
    model: &M,
    bank: &StartBank,
    kind: StartKind,
    r: &mut Rng,
) -> [f64; N] {
    let names = model.state_names();
    let bounds = model.state_bounds();
    let scales = model.state_scales();
    let p = model.params();
    let x_oc = p.intake_manifold.x_oc;
    let base: [f64; N] = match bank.states.get(r.below(bank.states.len().max(1))) {
        Some(v) => std::array::from_fn(|i| v[i]),
        None => model.initial_guess(&Drive::from_array(BANK_POINTS[0])),
    };
    let sigma = match kind {
        StartKind::Near => 0.02,
        StartKind::Perturbed => 0.3,
        StartKind::Far => 0.0,
    };
    std::array::from_fn(|i| {
        let name = names[i];
        let (lo, hi) = bounds[i];
        let is_o2 = name.starts_with("X_O");
        let is_act = name.starts_with("u_");
        let v = if kind == StartKind::Far {
            if is_o2 {
                r.range(0.0, x_oc)
            } else if is_act {
                r.range(-20.0, 120.0)
            } else if lo.is_finite() && hi.is_finite() && lo > 0.0 {
                // log-uniform inside the limits
                (lo.ln() + r.unit() * (hi.ln() - lo.ln())).exp()
            } else {
                // no limits (e.g. temperatures of the extended models): +-50 % of the base
                base[i] * r.range(0.5, 1.5)
            }
        } else if is_act {
            base[i] + sigma * 100.0 * r.normal()
        } else {
            base[i] + sigma * base[i].abs().max(scales[i] * 0.1) * r.normal()
        };
        let v = if is_o2 { v.clamp(0.0, x_oc) } else { v };
        v.clamp(lo, hi)
    })
}

/// What happened in one run.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The simulation completed.
    Completed {
        /// Output samples checked.
        samples: usize,
        /// Samples with a non-finite value in any column.
        nonfinite_samples: usize,
        /// Invariant violations.
        violations: Vec<Violation>,
        /// Numerical excursions of states within the allowance [`STATE_SLACK_RTOL`].
        numerical: Vec<Violation>,
    },
    /// The simulation returned an error.
    Error {
        /// Error class (variant and, for non-finite values, what and which state).
        class: String,
        /// Whether the message names the time, the state and gives a hint.
        located: bool,
        /// Full message.
        message: String,
    },
    /// The simulation panicked.
    Panic(String),
}

/// Error class of a simulation error: the variant, plus what and where for non-finite values.
pub fn error_class(e: &SimError) -> String {
    match e {
        SimError::BadOption { field, .. } => format!("BadOption({field})"),
        SimError::BadCommand { name, .. } => format!("BadCommand({name})"),
        SimError::BadInterval { .. } => "BadInterval".into(),
        SimError::BadHorizon { .. } => "BadHorizon".into(),
        SimError::NonFinite { what, name, .. } => format!("NonFinite({what} {name})"),
        SimError::StepSizeTooSmall { .. } => "StepSizeTooSmall".into(),
        SimError::TooManySteps { .. } => "TooManySteps".into(),
        SimError::Cancelled { .. } => "Cancelled".into(),
    }
}

/// Whether an error message locates the failure: names a time (`t = `) and a state dump
/// (`state: [`), and for the integration failures gives a hint.
pub fn error_is_located(e: &SimError) -> bool {
    let m = e.to_string();
    match e {
        SimError::NonFinite { .. } | SimError::StepSizeTooSmall { .. } => {
            m.contains("t = ") && m.contains("state: [") && m.contains("Hint:")
        }
        SimError::TooManySteps { .. } | SimError::Cancelled { .. } => {
            m.contains("t = ") && m.contains("state: [")
        }
        _ => !m.is_empty(),
    }
}

/// Integrator limits of `model`'s states that are finite on at least one side, as
/// (state name, lower, upper): the states checked by [`check_solution`] beyond its fixed list.
pub fn state_limits<const N: usize, M: Model<N>>(model: &M) -> Vec<(&'static str, f64, f64)> {
    model
        .state_names()
        .iter()
        .zip(model.state_bounds())
        .filter(|(_, (lo, hi))| lo.is_finite() || hi.is_finite())
        .map(|(n, (lo, hi))| (*n, lo, hi))
        .collect()
}

/// Check every output sample of `sol` against the invariants (see the module documentation).
/// `limits` are the states' integrator limits ([`state_limits`]; states with a stricter fixed
/// check, `p_im`, `p_em`, `X_Oim`, `X_Oem`, are skipped); `slack` is the relative excursion of
/// X_Oim, X_Oem beyond X_Oc counted as numerical, not as a violation ([`state_allowance`]).
/// Returns (non-finite samples, violations, numerical excursions).
pub fn check_solution(
    sol: &Solution,
    p: &Params,
    limits: &[(&'static str, f64, f64)],
    slack: f64,
) -> (usize, Vec<Violation>, Vec<Violation>) {
    let n = sol.len();
    let mut nonfinite = 0;
    for i in 0..n {
        if sol.columns.iter().any(|c| !c[i].is_finite()) {
            nonfinite += 1;
        }
    }
    let tol = INVARIANT_TOL;
    let pa = p.ambient.p_amb;
    let x_oc = p.intake_manifold.x_oc;
    // (label, column, lower, upper, allowance relative to the bound)
    let inf = f64::INFINITY;
    let mut checks: Vec<(String, &str, f64, f64, f64)> = vec![
        ("X_Oim in [0, X_Oc]".into(), "X_Oim", 0.0, x_oc, slack),
        ("X_Oem in [0, X_Oc]".into(), "X_Oem", 0.0, x_oc, slack),
        (
            "p_im in [0.5, 10] p_amb".into(),
            "p_im",
            0.5 * pa,
            10.0 * pa,
            0.0,
        ),
        (
            "p_em in [0.5, 20] p_amb".into(),
            "p_em",
            0.5 * pa,
            20.0 * pa,
            0.0,
        ),
        ("lambda_O >= 0".into(), "lambda_O", 0.0, inf, 0.0),
        ("W_c >= 1e-4".into(), "W_c", W_C_MIN, inf, 0.0),
        ("W_t >= 0".into(), "W_t", 0.0, inf, 0.0),
        ("W_egr >= 0".into(), "W_egr", 0.0, inf, 0.0),
        ("W_ei >= 0".into(), "W_ei", 0.0, inf, 0.0),
        ("W_eo >= 0".into(), "W_eo", 0.0, inf, 0.0),
        ("W_f >= 0".into(), "W_f", 0.0, inf, 0.0),
    ];
    for &(name, lo, hi) in limits {
        if !matches!(name, "p_im" | "p_em" | "X_Oim" | "X_Oem") {
            checks.push((
                format!("{name} within integrator limits"),
                name,
                lo,
                hi,
                0.0,
            ));
        }
    }
    let mut hard = Vec::new();
    let mut numerical = Vec::new();
    for (label, col, lo, hi, allow) in checks {
        let Some(c) = sol.get(col) else { continue };
        let mut worst: [Option<Violation>; 2] = [None, None];
        for &v in c {
            // excess beyond the bound, relative to the bound (absolute for a zero bound)
            let excess = if v < lo {
                (lo - v) / if lo == 0.0 { 1.0 } else { lo.abs() }
            } else if v > hi {
                (v - hi) / hi.abs()
            } else {
                0.0
            };
            if excess <= tol {
                continue;
            }
            let tier = usize::from(excess > allow);
            let w = worst[tier].get_or_insert_with(|| Violation {
                invariant: label.clone(),
                samples: 0,
                worst: v,
                excess,
            });
            w.samples += 1;
            if excess > w.excess {
                w.excess = excess;
                w.worst = v;
            }
        }
        let [num, bad] = worst;
        numerical.extend(num);
        hard.extend(bad);
    }
    // lambda_O > 0 wherever the intake holds oxygen (eq. (15): lambda_O is proportional to
    // X_Oim, so it is exactly 0 when X_Oim sits at its integrator limit 0)
    if let (Some(l), Some(x)) = (sol.get("lambda_O"), sol.get("X_Oim")) {
        let bad: Vec<f64> = l
            .iter()
            .zip(x)
            .filter(|(l, x)| **x > 0.0 && (l.is_nan() || **l <= 0.0))
            .map(|(l, _)| *l)
            .collect();
        if let Some(w) = bad.first() {
            hard.push(Violation {
                invariant: "lambda_O > 0 where X_Oim > 0".into(),
                samples: bad.len(),
                worst: *w,
                excess: 1.0,
            });
        }
    }
    // the intercooler flow follows the pressure drop p_c - p_im (eq. (86), signed)
    if let (Some(w), Some(pc), Some(pim)) = (sol.get("W_ic"), sol.get("p_c"), sol.get("p_im")) {
        let bad: Vec<f64> = w
            .iter()
            .zip(pc.iter().zip(pim))
            .filter(|(w, (pc, pim))| **w * (**pc - **pim) < 0.0)
            .map(|(w, _)| *w)
            .collect();
        if let Some(w) = bad.first() {
            hard.push(Violation {
                invariant: "W_ic has the sign of p_c - p_im".into(),
                samples: bad.len(),
                worst: *w,
                excess: 1.0,
            });
        }
    }
    (nonfinite, hard, numerical)
}

/// An invariant that failed at some output samples of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct Violation {
    /// Invariant label.
    pub invariant: String,
    /// Samples outside the bound.
    pub samples: usize,
    /// Value at the worst sample.
    pub worst: f64,
    /// Excess beyond the bound at the worst sample, relative to the bound (absolute for a zero
    /// bound).
    pub excess: f64,
}

/// Run one scenario on `model` from a start state drawn with the scenario's generator.
/// Never panics: a panic inside the simulation is caught and returned as [`Outcome::Panic`].
pub fn run_scenario<const N: usize, M: Model<N>>(
    model: &M,
    bank: &StartBank,
    sc: &Scenario,
    t_end: f64,
    base_opts: &SimOptions,
) -> Outcome {
    let mut r = sc.rng.clone();
    let res = catch_unwind(AssertUnwindSafe(|| {
        let x0 = start_state(model, bank, sc.start, &mut r);
        let opts = SimOptions {
            method: sc.method,
            ..base_opts.clone()
        };
        let limits = state_limits(model);
        let x_oc = model.params().intake_manifold.x_oc;
        let scale = model
            .state_names()
            .iter()
            .position(|n| *n == "X_Oim")
            .map_or(0.0, |i| model.state_scales()[i]);
        let slack = state_allowance(&opts, scale, x_oc);
        match simulate(model, &sc.sched, 0.0, t_end, Start::State(x0), &opts) {
            Ok(sol) => {
                let (nonfinite_samples, violations, numerical) =
                    check_solution(&sol, model.params(), &limits, slack);
                Outcome::Completed {
                    samples: sol.len(),
                    nonfinite_samples,
                    violations,
                    numerical,
                }
            }
            Err(e) => Outcome::Error {
                class: error_class(&e),
                located: error_is_located(&e),
                message: e.to_string(),
            },
        }
    }));
    match res {
        Ok(o) => o,
        Err(payload) => Outcome::Panic(
            payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "non-string panic payload".into()),
        ),
    }
}

/// Configuration of a sweep.
#[derive(Debug, Clone)]
pub struct SweepConfig {
    /// Number of runs (split over model orders and methods).
    pub runs: u64,
    /// Index of the first run (runs `first_run .. first_run + runs`; a sweep split into chunks
    /// gives the same runs as one sweep).
    pub first_run: u64,
    /// Seed.
    pub seed: u64,
    /// Simulated time per run \[s\].
    pub t_end: f64,
    /// Model orders to sweep (unavailable orders are reported and skipped).
    pub orders: Vec<ModelOrder>,
    /// Integration methods (alternating by run index).
    pub methods: Vec<Method>,
    /// Solver options (method overridden per run).
    pub sim: SimOptions,
    /// Model options (default: authors' semantics, converged T_e).
    pub model: ModelOptions,
    /// Worker threads.
    pub threads: usize,
}

impl Default for SweepConfig {
    fn default() -> Self {
        Self {
            runs: 10_000,
            first_run: 0,
            seed: 1,
            t_end: 60.0,
            orders: vec![ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve],
            methods: vec![Method::Rosenbrock34, Method::Dopri5],
            sim: SimOptions::default(),
            model: ModelOptions::default(),
            threads: 2,
        }
    }
}

/// Violations by (invariant, method): (runs, samples, worst value, worst relative excess,
/// example run).
pub type ViolationMap = BTreeMap<(String, String), (u64, u64, f64, f64, u64)>;

/// Aggregated results of a sweep.
#[derive(Debug, Clone, Default)]
pub struct SweepReport {
    /// Runs attempted.
    pub runs: u64,
    /// Runs that completed without error.
    pub completed: u64,
    /// Runs per (model states, method) that completed / errored.
    pub per_variant: BTreeMap<(usize, String), (u64, u64)>,
    /// Errors by class: (count, example run, example message).
    pub errors: BTreeMap<String, (u64, u64, String)>,
    /// Errors whose message does not locate the failure (time, state, hint).
    pub unlocated_errors: u64,
    /// Panics: (run, message).
    pub panics: Vec<(u64, String)>,
    /// Output samples checked.
    pub samples: u64,
    /// Samples with a NaN/inf in any column.
    pub nonfinite_samples: u64,
    /// Runs with a non-finite sample.
    pub nonfinite_runs: u64,
    /// Violations by (invariant, method): (runs, samples, worst value, worst relative excess,
    /// example run).
    pub violations: ViolationMap,
    /// Numerical excursions within the state allowance, same layout.
    pub numerical: ViolationMap,
    /// Model orders skipped because the variant is not available in this build.
    pub unavailable: Vec<usize>,
    /// Runs by (input kind, start kind): (completed, errors).
    pub per_kind: BTreeMap<String, (u64, u64)>,
    /// Wall-clock time \[s\].
    pub seconds: f64,
    /// Threads used.
    pub threads: usize,
}

impl SweepReport {
    /// No panic, no non-finite output, no invariant violation, every error located.
    pub fn clean(&self) -> bool {
        self.panics.is_empty()
            && self.nonfinite_samples == 0
            && self.violations.is_empty()
            && self.unlocated_errors == 0
    }

    /// Add the results of another sweep (e.g. the next chunk of runs of the same sweep).
    pub fn merge(&mut self, o: SweepReport) {
        self.runs += o.runs;
        self.completed += o.completed;
        for (k, v) in o.per_variant {
            let e = self.per_variant.entry(k).or_default();
            e.0 += v.0;
            e.1 += v.1;
        }
        for (k, v) in o.per_kind {
            let e = self.per_kind.entry(k).or_default();
            e.0 += v.0;
            e.1 += v.1;
        }
        for (k, v) in o.errors {
            self.errors.entry(k).or_insert((0, v.1, v.2)).0 += v.0;
        }
        self.unlocated_errors += o.unlocated_errors;
        self.panics.extend(o.panics);
        self.samples += o.samples;
        self.nonfinite_samples += o.nonfinite_samples;
        self.nonfinite_runs += o.nonfinite_runs;
        for (mine, theirs) in [
            (&mut self.violations, o.violations),
            (&mut self.numerical, o.numerical),
        ] {
            for (k, v) in theirs {
                let e = mine.entry(k).or_insert((0, 0, v.2, v.3, v.4));
                e.0 += v.0;
                e.1 += v.1;
                if v.3 > e.3 {
                    e.2 = v.2;
                    e.3 = v.3;
                    e.4 = v.4;
                }
            }
        }
        for n in o.unavailable {
            if !self.unavailable.contains(&n) {
                self.unavailable.push(n);
            }
        }
        self.seconds += o.seconds;
        self.threads = self.threads.max(o.threads);
    }

    fn add(&mut self, states: usize, sc: &Scenario, o: Outcome) {
        self.runs += 1;
        let v = self
            .per_variant
            .entry((states, format!("{:?}", sc.method)))
            .or_default();
        let k = self
            .per_kind
            .entry(format!("{:?}/{:?}", sc.input, sc.start))
            .or_default();
        match o {
            Outcome::Completed {
                samples,
                nonfinite_samples,
                violations,
                numerical,
            } => {
                self.completed += 1;
                v.0 += 1;
                k.0 += 1;
                self.samples += samples as u64;
                self.nonfinite_samples += nonfinite_samples as u64;
                if nonfinite_samples > 0 {
                    self.nonfinite_runs += 1;
                }
                let method = format!("{:?}", sc.method);
                for (map, list) in [
                    (&mut self.violations, violations),
                    (&mut self.numerical, numerical),
                ] {
                    for v in list {
                        let e = map
                            .entry((v.invariant, method.clone()))
                            .or_insert((0, 0, v.worst, v.excess, sc.run));
                        e.0 += 1;
                        e.1 += v.samples as u64;
                        if v.excess > e.3 {
                            e.2 = v.worst;
                            e.3 = v.excess;
                            e.4 = sc.run;
                        }
                    }
                }
            }
            Outcome::Error {
                class,
                located,
                message,
            } => {
                v.1 += 1;
                k.1 += 1;
                if !located {
                    self.unlocated_errors += 1;
                }
                let e = self.errors.entry(class).or_insert((0, sc.run, message));
                e.0 += 1;
            }
            Outcome::Panic(msg) => {
                v.1 += 1;
                k.1 += 1;
                self.panics.push((sc.run, msg));
            }
        }
    }
}

impl fmt::Display for SweepReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "robustness sweep: {} runs in {:.1} s on {} threads",
            self.runs, self.seconds, self.threads
        )?;
        for n in &self.unavailable {
            writeln!(
                f,
                "  ({n}-state model not available in this build: skipped)"
            )?;
        }
        writeln!(f, "{:<40} {:>12}", "quantity", "value")?;
        let row = |f: &mut fmt::Formatter<'_>, k: &str, v: String| writeln!(f, "{k:<40} {v:>12}");
        row(f, "runs completed", self.completed.to_string())?;
        row(
            f,
            "runs ending in an error",
            (self.runs - self.completed - self.panics.len() as u64).to_string(),
        )?;
        row(
            f,
            "  of which not located (t/state/hint)",
            self.unlocated_errors.to_string(),
        )?;
        row(f, "panics", self.panics.len().to_string())?;
        row(f, "output samples checked", self.samples.to_string())?;
        row(
            f,
            "samples with NaN/inf",
            self.nonfinite_samples.to_string(),
        )?;
        row(f, "runs with NaN/inf", self.nonfinite_runs.to_string())?;
        row(
            f,
            "invariant violations (runs)",
            self.violations
                .values()
                .map(|v| v.0)
                .sum::<u64>()
                .to_string(),
        )?;
        row(
            f,
            "numerical state excursions (runs)",
            self.numerical
                .values()
                .map(|v| v.0)
                .sum::<u64>()
                .to_string(),
        )?;
        writeln!(f, "\nper model / method: completed / errors")?;
        for ((n, m), (ok, err)) in &self.per_variant {
            writeln!(f, "  {n:>2} states {m:<14} {ok:>8} / {err}")?;
        }
        writeln!(f, "\nper input / start kind: completed / errors")?;
        for (k, (ok, err)) in &self.per_kind {
            writeln!(f, "  {k:<28} {ok:>8} / {err}")?;
        }
        if !self.errors.is_empty() {
            writeln!(f, "\nerrors by class: count, example run, example message")?;
            for (c, (n, run, msg)) in &self.errors {
                writeln!(f, "  {c:<40} {n:>6}  run {run}: {msg}")?;
            }
        }
        for (title, map) in [
            ("invariant violations", &self.violations),
            (
                "numerical excursions of states (within the allowance, not violations)",
                &self.numerical,
            ),
        ] {
            if !map.is_empty() {
                writeln!(
                    f,
                    "\n{title}: runs, samples, worst value, worst relative excess, run"
                )?;
                for ((c, m), (runs, samples, worst, excess, run)) in map {
                    writeln!(
                        f,
                        "  {c:<24} {m:<13} {runs:>6} {samples:>9} {worst:>14.7e} {excess:>9.2e}  run {run}"
                    )?;
                }
            }
        }
        for (run, msg) in &self.panics {
            writeln!(f, "panic in run {run}: {msg}")?;
        }
        Ok(())
    }
}

/// Run a sweep: `cfg.runs` runs split round-robin over the available model orders, methods
/// alternating, in parallel on `cfg.threads` threads.
pub fn sweep(params: &Params, cfg: &SweepConfig) -> SweepReport {
    sweep_with_progress(params, cfg, &|| {})
}

/// [`sweep`], calling `progress` once after each finished run (from the worker threads; for a
/// progress bar).
pub fn sweep_with_progress(
    params: &Params,
    cfg: &SweepConfig,
    progress: &(dyn Fn() + Sync),
) -> SweepReport {
    use rayon::prelude::*;
    let start = std::time::Instant::now();
    let mut report = SweepReport {
        threads: cfg.threads,
        ..Default::default()
    };
    let mut models: Vec<(AnyModel, StartBank)> = Vec::new();
    for &order in &cfg.orders {
        match AnyModel::new(order, params.clone(), cfg.model) {
            Ok(m) => {
                let bank = crate::dispatch!(&m, mm => StartBank::new(mm));
                models.push((m, bank));
            }
            Err(_) => report.unavailable.push(order.states()),
        }
    }
    if models.is_empty() {
        report.seconds = start.elapsed().as_secs_f64();
        return report;
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads.max(1))
        .build()
        .expect("thread pool");
    let outcomes: Vec<(usize, Scenario, Outcome)> = pool.install(|| {
        (cfg.first_run..cfg.first_run + cfg.runs)
            .into_par_iter()
            .map(|run| {
                let (m, bank) = &models[(run as usize) % models.len()];
                // methods alternate within each model order
                let sc = scenario(cfg.seed, run, cfg.t_end, &cfg.methods);
                let sc = Scenario {
                    method: cfg.methods[((run as usize) / models.len()) % cfg.methods.len()],
                    ..sc
                };
                let o = crate::dispatch!(m, mm => run_scenario(mm, bank, &sc, cfg.t_end, &cfg.sim));
                progress();
                (m.order().states(), sc, o)
            })
            .collect()
    });
    for (n, sc, o) in outcomes {
        report.add(n, &sc, o);
    }
    report.seconds = start.elapsed().as_secs_f64();
    report
}
