//! Linearization `dx = A dx + B du`, `dy = C dx + D du` of a model at an operating point.
//!
//! Inputs, in column order, are `(u_delta, u_egr, u_vgt, n_e)` in user units (mg/cycle/cylinder,
//! %, %, rpm) — the reference procedure of the implementation notes (§4, "Linearization").
//! The transport delays tau_degr and tau_dvgt act on inputs only and have no states, so the
//! linear model is that of the **undelayed** system: perturbing `u_egr` moves the current and
//! the delayed command together. A delayed channel's linear response is the undelayed one
//! shifted by the delay; optionally the delays are replaced by Padé approximants of order 1-3
//! as extra states ([`LinearizeOptions::pade_order`]).
//!
//! Outputs are any state name (exact rows of C) or any [`Signals::NAMES`] entry; the default
//! set is [`DEFAULT_OUTPUTS`] (p_im, p_em, W_c, n_t, x_egr, lambda_O, M_e).
//!
//! ## Derivatives
//! Central differences on [`Model::eval`], Richardson-extrapolated: with `D(h)` the central
//! difference at step `h` and steps `h, 2h, ..., 2^L h`, the table
//! `R_{k,j} = (4^j R_{k,j-1} - R_{k+1,j-1}) / (4^j - 1)` removes the error terms `h^2 .. h^(2L)`,
//! so `L = 1` (the default, 4 evaluations per direction) is exact for quartic functions and has
//! an `O(h^4)` truncation error. The step is `h = rel_step * max(|v|, scale)` rounded to a power
//! of two, with `scale` the state scale of the model or the input scale ([`INPUT_SCALES`]); the
//! denominators use the exactly representable differences of the perturbed values.
//! The default `rel_step = 1e-4` balances the truncation error `(h/scale)^4 ~ 1e-16` against
//! the evaluation noise (the converged cylinder-temperature fixed point, relative 1e-12
//! tolerance, contributes ~1e-14) divided by `h/scale`: measured entry accuracy is ~1e-9
//! relative (see the tests).
//!
//! ## Kinks
//! The authors' implementation has many `min`/`max`/switch blocks (input saturations,
//! integrator limits, `Pi_c >= 1`, the c_m linear branch, ...). Where the operating point sits
//! on or within the difference stencil of such a kink, a central difference is the average of
//! two one-sided slopes, not a derivative. Two independent checks find it:
//!
//! 1. a [`crate::model::Guard`] bit (every saturation of the implementation has one) differs
//!    between the stencil points of a direction;
//! 2. the one-sided slopes are inconsistent. With `S(h) = (f(h) - 2 f(0) + f(-h)) / h` (the
//!    difference of the one-sided slopes), a smooth function has `T1 = |S(2h) - 2 S(h)| =
//!    O(h^3)` and `T2 = |D(h) - D(2h)| = O(h^2)`, while a slope jump `J` at a distance `c < h`
//!    gives `T1 = J |3c - 2h| / (2h)` and `T2 = J c / (4h)`: never both small. An entry is
//!    flagged when `T1 > kink_tol * ref` or `T2 > 100 kink_tol * ref`, `ref` being the row's
//!    largest scaled entry ([`LinearizeOptions::kink_tol`], default 1e-6; smooth points score
//!    below 0.1 of that, see [`LinearModel::kink_score`]). This also catches the kinks without
//!    a guard bit (e.g. `max(omega_t, c_m2)` in item 33).
//!
//! A flagged direction is differenced again with steps h/16 and h/256: a kink at a distance
//! from the point (or strong curvature, e.g. near Pi_c = 1 where the compressor efficiency has
//! a root singularity) then leaves the stencil and the direction is accepted. What remains is
//! a kink at (within 2h/256 of) the operating point. With [`LinearizeOptions::strict`]
//! (default) that is an error; otherwise it is listed in [`LinearModel::kinks`], and
//! [`LinearModel::kinks_affecting`] tells whether it lies on a signal path of a given
//! input-output channel (the zeros and DC-gain functions refuse such channels).

use super::steady::SteadyState;
use crate::model::{CylinderTemp, Drive, Guard, InputError, Model, ModelInput, Signals};
use nalgebra::DMatrix;
use std::fmt;

/// Input names of the linear model, in column order (user units: mg, %, %, rpm).
pub const INPUT_NAMES: [&str; 4] = ["u_delta", "u_egr", "u_vgt", "n_e"];

/// Typical magnitudes of the inputs in [`INPUT_NAMES`] order (mg, %, %, rpm), used for step
/// sizes and scaling.
pub const INPUT_SCALES: [f64; 4] = [100.0, 100.0, 100.0, 1000.0];

/// Default outputs: p_im \[Pa\], p_em \[Pa\], W_c [kg/s], n_t \[rpm\], x_egr [-], lambda_O [-],
/// M_e \[Nm\].
pub const DEFAULT_OUTPUTS: [&str; 7] = ["p_im", "p_em", "W_c", "n_t", "x_egr", "lambda_O", "M_e"];

/// Options of [`linearize`].
#[derive(Debug, Clone, PartialEq)]
pub struct LinearizeOptions {
    /// Output names: state names or [`Signals::NAMES`] entries (default [`DEFAULT_OUTPUTS`]).
    pub outputs: Vec<String>,
    /// Relative step: `h = rel_step * max(|v|, scale)` (default 1e-4).
    pub rel_step: f64,
    /// Richardson extrapolation levels L (0 = plain central differences, 1 = default, <= 3).
    /// Costs `2 (L + 1)` model evaluations per direction.
    pub richardson: usize,
    /// Order of the Padé approximants of the actuator delays added as states (0 = none,
    /// the undelayed system; 1-3): `pade_order` states per delayed channel (named
    /// `pade_egr_1`, ...), none for a channel whose delay is 0 (its delayed copy is the command).
    pub pade_order: usize,
    /// Fail with [`LinearizeError::Kink`] when any kink is found (default true); otherwise
    /// return the model with [`LinearModel::kinks`] filled in.
    pub strict: bool,
    /// Relative threshold of the one-sided slope test (default 1e-6; see the module doc).
    pub kink_tol: f64,
}

impl Default for LinearizeOptions {
    fn default() -> Self {
        Self {
            outputs: DEFAULT_OUTPUTS.iter().map(|s| s.to_string()).collect(),
            rel_step: 1e-4,
            richardson: 1,
            pade_order: 0,
            strict: true,
            kink_tol: 1e-6,
        }
    }
}

impl LinearizeOptions {
    /// Check the options; the message names the field.
    pub fn validate(&self) -> Result<(), LinearizeError> {
        let bad = |field: &'static str, value: f64, constraint: &'static str| {
            Err(LinearizeError::BadOption {
                field,
                value,
                constraint,
            })
        };
        if !(self.rel_step.is_finite() && self.rel_step > 0.0 && self.rel_step <= 0.1) {
            return bad("rel_step", self.rel_step, "must lie in (0, 0.1]");
        }
        if self.richardson > 3 {
            return bad("richardson", self.richardson as f64, "must be 0..=3");
        }
        if self.pade_order > 3 {
            return bad("pade_order", self.pade_order as f64, "must be 0..=3");
        }
        if !(self.kink_tol.is_finite() && self.kink_tol > 0.0) {
            return bad("kink_tol", self.kink_tol, "must be finite and > 0");
        }
        if self.outputs.is_empty() {
            return bad("outputs", 0.0, "at least one output is needed");
        }
        Ok(())
    }
}

/// A non-smooth point found inside the difference stencil of one direction.
#[derive(Debug, Clone, PartialEq)]
pub struct Kink {
    /// The perturbed variable: a state name or an input name (`u_egr`, or with Padé states
    /// `u_egr(now)` / `u_egr(delayed)`).
    pub variable: String,
    /// Labels of the guards that switch inside the stencil (may be empty).
    pub guards: Vec<&'static str>,
    /// Rows whose one-sided slopes disagree (`d(p_im)/dt` for a state derivative, an output
    /// name otherwise; may be empty when only a guard switched).
    pub rows: Vec<String>,
}

impl fmt::Display for Kink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "kink in direction {}", self.variable)?;
        if !self.guards.is_empty() {
            write!(f, " (switching: {})", self.guards.join(", "))?;
        }
        if !self.rows.is_empty() {
            write!(f, " (one-sided slopes differ in: {})", self.rows.join(", "))?;
        }
        Ok(())
    }
}

/// An input direction whose operating point sits at a limit of the input's saturation (the
/// authors' items 1-4: u_vgt at 20 %, n_e at the parameter set's top speed, ...), or an
/// actuator state at the limit of its command's range (the EGR valve shut, u_egr1 = u_egr2 =
/// 0, where f_egr >= 0 switches): the central difference would average the slopes of the two
/// sides. The column is the one-sided derivative on the side where fewer saturations are active
/// instead (the inner side of an input's range; the open valve's branch), which is what a point
/// just inside the range linearizes to.
#[derive(Debug, Clone, PartialEq)]
pub struct OneSided {
    /// The input (`u_vgt`, or with Padé states `u_vgt(now)` / `u_vgt(delayed)`) or actuator
    /// state (`u_egr1`).
    pub variable: String,
    /// Its value at the operating point (its unit).
    pub value: f64,
    /// The limit it sits at (its unit).
    pub limit: f64,
    /// +1: the derivative is taken upward, -1 downward.
    pub side: i8,
    /// A state beside (not at) a kink without a limit (e.g. omega_t just above c_m2 of eq.
    /// (51)): the column is the one-sided derivative on the point's own side, where the
    /// one-sided slopes agree; `limit` is then the point's own value.
    pub beside_kink: bool,
}

impl fmt::Display for OneSided {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let dir = if self.side > 0 { "upward" } else { "downward" };
        if self.beside_kink {
            return write!(
                f,
                "{} = {} lies beside a kink of the model, within the difference stencil: its \
                 column is the one-sided derivative {dir}, on the point's side of the kink",
                self.variable,
                crate::numerics::Num(self.value)
            );
        }
        write!(
            f,
            "{} = {} sits at a limit ({}) of its range: its column is the one-sided derivative {dir}, on the side where fewer saturations are active",
            self.variable,
            crate::numerics::Num(self.value),
            crate::numerics::Num(self.limit)
        )
    }
}

/// Why no linear model was returned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LinearizeError {
    /// An option is out of range.
    #[error("linearize option {field} = {}: {constraint}", crate::numerics::Num(*value))]
    BadOption {
        /// Option name.
        field: &'static str,
        /// Value.
        value: f64,
        /// Constraint.
        constraint: &'static str,
    },
    /// An output name is neither a state nor a signal.
    #[error("unknown output {name:?}; known: the states {states} and the signals {signals}")]
    UnknownOutput {
        /// The name asked for.
        name: String,
        /// State names, comma separated.
        states: String,
        /// Signal names, comma separated.
        signals: String,
    },
    /// The state, an input, or a model evaluation is not finite.
    #[error("non-finite {what} = {value} at the operating point")]
    NonFinite {
        /// What (e.g. `state p_im`, `derivative of omega_t`, `output W_c`).
        what: String,
        /// Value.
        value: f64,
    },
    /// An input the model cannot be evaluated at (n_e <= 0 with the paper's equations;
    /// [`Drive::check`]).
    #[error("{0}")]
    Input(#[from] InputError),
    /// The operating point sits at (or within the difference stencil of) a kink.
    #[error("the operating point sits at a kink of the model: {}; the derivative is one-sided there (set strict = false to obtain the averaged slopes with the kinks listed)", .0.iter().map(|k| k.to_string()).collect::<Vec<_>>().join("; "))]
    Kink(Vec<Kink>),
}

/// A continuous-time linear model `dx' = A dx + B du`, `dy = C dx + D du` in deviation
/// variables around the operating point (`x0`, `u0`, `y0`), in the model's units (Pa, -, rad/s,
/// %; inputs mg, %, %, rpm; outputs in their signal units).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearModel {
    /// State matrix (n x n) [1/s].
    pub a: DMatrix<f64>,
    /// Input matrix (n x 4).
    pub b: DMatrix<f64>,
    /// Output matrix (p x n).
    pub c: DMatrix<f64>,
    /// Feedthrough matrix (p x 4).
    pub d: DMatrix<f64>,
    /// State names: the model's states, then Padé states `pade_egr_1..`, `pade_vgt_1..`.
    pub state_names: Vec<String>,
    /// Input names ([`INPUT_NAMES`]).
    pub input_names: Vec<String>,
    /// Output names.
    pub output_names: Vec<String>,
    /// Operating state (Padé states 0).
    pub x0: Vec<f64>,
    /// Operating inputs (u_delta \[mg\], u_egr [%], u_vgt [%], n_e \[rpm\]).
    pub u0: [f64; 4],
    /// Outputs at the operating point.
    pub y0: Vec<f64>,
    /// State derivatives at the operating point (about 0 at a steady state).
    pub dx0: Vec<f64>,
    /// Typical magnitudes of the states (for scaling).
    pub state_scales: Vec<f64>,
    /// Typical magnitudes of the inputs ([`INPUT_SCALES`]).
    pub input_scales: Vec<f64>,
    /// Typical magnitudes of the outputs (|y0|, or the state scale for state outputs).
    pub output_scales: Vec<f64>,
    /// Kinks found in the difference stencils (empty for a smooth point).
    pub kinks: Vec<Kink>,
    /// Input and actuator-state directions at a saturation limit, differenced on one side
    /// ([`OneSided`]; not kinks).
    pub one_sided: Vec<OneSided>,
    /// Largest last Richardson correction, relative to the row's largest scaled entry (an
    /// upper estimate of the error of the previous extrapolation order; 0 with `richardson = 0`).
    pub correction: f64,
    /// Largest score of the one-sided slope test over all entries: the measure relative to its
    /// threshold (`kink_tol` times the row's largest scaled entry); above 1 in a direction
    /// listed in [`LinearModel::kinks`], typically below 0.1 at smooth points.
    pub kink_score: f64,
    /// Padé order of the delay approximation (0 = undelayed system).
    pub pade_order: usize,
    /// Delays \[s\] of the (u_egr, u_vgt) channels that the linear model omits (or approximates).
    pub delays: [f64; 2],
    /// Model evaluations used.
    pub evaluations: usize,
}

/// Output selector: a state (exact row of C) or a signal.
#[derive(Debug, Clone, Copy)]
enum Sel {
    State(usize),
    Signal(usize),
}

fn resolve_outputs(
    state_names: &[&'static str],
    outputs: &[String],
) -> Result<Vec<Sel>, LinearizeError> {
    outputs
        .iter()
        .map(|name| {
            if let Some(i) = state_names.iter().position(|s| s == name) {
                Ok(Sel::State(i))
            } else if let Some(j) = Signals::NAMES.iter().position(|s| s == name) {
                Ok(Sel::Signal(j))
            } else {
                Err(LinearizeError::UnknownOutput {
                    name: name.clone(),
                    states: state_names.join(", "),
                    signals: Signals::NAMES.join(", "),
                })
            }
        })
        .collect()
}

/// A perturbation direction.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Dir {
    State(usize),
    /// Input (index into INPUT_NAMES); `now` / `delayed` select which copies move.
    Input {
        k: usize,
        now: bool,
        delayed: bool,
    },
}

/// Linearize `m` at its steady state `ss` (see [`linearize`]).
pub fn linearize_steady<const N: usize, M: Model<N>>(
    m: &M,
    ss: &SteadyState<N>,
    opts: &LinearizeOptions,
) -> Result<LinearModel, LinearizeError> {
    linearize(m, &ss.x, &ss.drive, opts)
}

/// Linearize `m` at state `x` and constant inputs `d` (any point; at a steady state the result
/// is the usual small-signal model). See the module documentation for the method.
///
/// A model in [`CylinderTemp::OneIteration`] mode is linearized in converged mode: the
/// one-iteration memory is a property of the integration, and its fixed point is the
/// converged solution.
pub fn linearize<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    opts: &LinearizeOptions,
) -> Result<LinearModel, LinearizeError> {
    let conv = converged(m);
    linearize_impl(conv.as_ref().unwrap_or(m), x, d, opts)
}

/// `m` in [`CylinderTemp::Converged`] mode when it runs in one-iteration mode (None: it is
/// converged already): the linear analyses work on the converged model, the memory of the
/// one-iteration mode being a property of the integration.
pub fn converged<const N: usize, M: Model<N>>(m: &M) -> Option<M> {
    (m.options().cylinder_temp == CylinderTemp::OneIteration).then(|| {
        let mut o = *m.options();
        o.cylinder_temp = CylinderTemp::Converged;
        m.with_options(o)
    })
}

/// Rows of one evaluation: the N derivatives then the signal outputs.
struct Rows {
    n: usize,
    sig: Vec<(usize, usize)>, // (row index, signal index)
}

impl Rows {
    #[inline]
    fn fill<const N: usize>(&self, dx: &[f64; N], s: &Signals, out: &mut [f64]) {
        out[..self.n].copy_from_slice(dx);
        if !self.sig.is_empty() {
            let v = s.values();
            for &(r, j) in &self.sig {
                out[r] = v[j];
            }
        }
    }
}

fn linearize_impl<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    opts: &LinearizeOptions,
) -> Result<LinearModel, LinearizeError> {
    opts.validate()?;
    let names = m.state_names();
    for i in 0..N {
        if !x[i].is_finite() {
            return Err(LinearizeError::NonFinite {
                what: format!("state {}", names[i]),
                value: x[i],
            });
        }
    }
    for (name, v) in Drive::NAMES.iter().zip(d.to_array()) {
        if !v.is_finite() {
            return Err(LinearizeError::NonFinite {
                what: format!("input {name}"),
                value: v,
            });
        }
    }
    d.check(m.options().semantics)?;
    let sel = resolve_outputs(&names, &opts.outputs)?;
    let p = sel.len();
    let nrow = N + p;
    let rows = Rows {
        n: N,
        sig: sel
            .iter()
            .enumerate()
            .filter_map(|(r, s)| match s {
                Sel::Signal(j) => Some((N + r, *j)),
                Sel::State(_) => None,
            })
            .collect(),
    };
    let u0 = [d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct, d.n_e_rpm];
    let pade = opts.pade_order;
    let mut dirs: Vec<Dir> = (0..N).map(Dir::State).collect();
    for k in 0..4 {
        if pade > 0 && (k == 1 || k == 2) {
            dirs.push(Dir::Input {
                k,
                now: true,
                delayed: false,
            });
        } else {
            dirs.push(Dir::Input {
                k,
                now: true,
                delayed: true,
            });
        }
    }
    if pade > 0 {
        for k in [1, 2] {
            dirs.push(Dir::Input {
                k,
                now: false,
                delayed: true,
            });
        }
    }
    let dir_name = |dir: &Dir| -> String {
        match *dir {
            Dir::State(i) => names[i].to_string(),
            Dir::Input { k, now, delayed } => match (now, delayed) {
                (true, true) => INPUT_NAMES[k].to_string(),
                (true, false) => format!("{}(now)", INPUT_NAMES[k]),
                _ => format!("{}(delayed)", INPUT_NAMES[k]),
            },
        }
    };
    let scales = m.state_scales();
    let mem = m.memory_start(x, &ModelInput::constant(*d));
    let u_base = ModelInput::constant(*d);
    let mut evaluations = 0usize;

    // Base point.
    let e0 = m.eval(x, &u_base, mem);
    evaluations += 1;
    let mut f0 = vec![0.0; nrow];
    rows.fill(&e0.dx, &e0.signals, &mut f0);
    for (r, v) in f0.iter().enumerate() {
        if !v.is_finite() {
            let what = if r < N {
                format!("derivative of {}", names[r])
            } else {
                format!("output {}", opts.outputs[r - N])
            };
            return Err(LinearizeError::NonFinite { what, value: *v });
        }
    }
    let g0 = e0.signals.guards;

    let levels = opts.richardson;
    let ndir = dirs.len();
    let differ = Differ {
        m,
        x,
        u_base,
        mem,
        rows: &rows,
        f0: &f0,
        g0,
        levels,
        state_rows: sel
            .iter()
            .enumerate()
            .filter_map(|(o, s)| match s {
                Sel::State(i) => Some((N + o, *i)),
                Sel::Signal(_) => None,
            })
            .collect(),
    };
    let mut work = Work::new(nrow, levels);
    // Jacobian of all rows w.r.t. all directions, the slope-consistency measure and the last
    // Richardson correction.
    let mut jac = DMatrix::<f64>::zeros(nrow, ndir);
    let mut incons = DMatrix::<f64>::zeros(nrow, ndir);
    let mut corr = DMatrix::<f64>::zeros(nrow, ndir);
    let mut col_scale = vec![0.0; ndir];
    let mut h0 = vec![0.0; ndir];
    let mut v0s = vec![0.0; ndir];
    let mut switched = vec![0u32; ndir];
    let non_finite = |c: usize, r: usize, v: f64| {
        let what = if r < N {
            format!(
                "derivative of {} (perturbing {})",
                names[r],
                dir_name(&dirs[c])
            )
        } else {
            format!(
                "output {} (perturbing {})",
                opts.outputs[r - N],
                dir_name(&dirs[c])
            )
        };
        LinearizeError::NonFinite { what, value: v }
    };
    let store = |c: usize,
                 work: &Work,
                 jac: &mut DMatrix<f64>,
                 incons: &mut DMatrix<f64>,
                 corr: &mut DMatrix<f64>| {
        jac.column_mut(c).copy_from_slice(&work.d);
        incons.column_mut(c).copy_from_slice(&work.incons);
        corr.column_mut(c).copy_from_slice(&work.corr);
    };

    // Pass 1: every direction at the nominal step.
    for (c, dir) in dirs.iter().enumerate() {
        let (v0, sc) = match *dir {
            Dir::State(i) => (x[i], scales[i]),
            Dir::Input { k, .. } => (u0[k], INPUT_SCALES[k]),
        };
        col_scale[c] = sc;
        v0s[c] = v0;
        h0[c] = pow2_step(opts.rel_step * v0.abs().max(sc));
    }
    evaluations += ndir * 2 * (levels + 1);
    for c in 0..ndir {
        switched[c] = differ.column(&dirs[c], v0s[c], h0[c], &mut work);
        if let Some(r) = work.d.iter().position(|v| !v.is_finite()) {
            return Err(non_finite(c, r, work.d[r]));
        }
        store(c, &work, &mut jac, &mut incons, &mut corr);
    }

    // Row references: the largest scaled entry of each row.
    let reference: Vec<f64> = (0..nrow)
        .map(|r| {
            (0..ndir)
                .map(|c| (jac[(r, c)] * col_scale[c]).abs())
                .fold(0.0, f64::max)
        })
        .collect();
    let is_inconsistent = |c: usize, r: usize, incons: &DMatrix<f64>| -> bool {
        levels >= 1
            && reference[r] > 0.0
            && incons[(r, c)] * col_scale[c] > opts.kink_tol * reference[r]
    };
    let inconsistent_rows = |c: usize, incons: &DMatrix<f64>| -> Vec<usize> {
        (0..nrow)
            .filter(|&r| is_inconsistent(c, r, incons))
            .collect()
    };

    // Pass 2: a direction whose stencil switches a guard or shows inconsistent one-sided
    // slopes is retried with steps h/16 and h/256; a kink at a distance from the point is
    // then outside the stencil. What remains is a kink at (or within 2h/256 of) the point.
    let row_name = |r: usize| -> String {
        if r < N {
            format!("d({})/dt", names[r])
        } else {
            opts.outputs[r - N].clone()
        }
    };
    let mut kinks: Vec<Kink> = Vec::new();
    let mut one_sided: Vec<OneSided> = Vec::new();
    // the saturation ranges the model applies (none under the paper's semantics), in the
    // linear model's input order (u_delta, u_egr, u_vgt, n_e)
    let sem = m.options().semantics;
    let (egr_lim, vgt_lim) = crate::model::command_saturation(sem, &m.params().input_saturation);
    let ranges = crate::io::csv_inputs::input_ranges(&m.params().input_saturation);
    let input_limits = |k: usize| -> (f64, f64) {
        if !sem.authors() {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let (_, lo, hi) = ranges[[1, 2, 3, 0][k]];
        (lo, hi)
    };
    let actuators: Vec<usize> = m.actuator_state_values(d).iter().map(|(i, _)| *i).collect();
    for c in 0..ndir {
        if switched[c] == 0 && !(0..nrow).any(|r| is_inconsistent(c, r, &incons)) {
            continue;
        }
        let mut bad = Vec::new();
        for attempt in 1..=2 {
            let h = h0[c] / 16f64.powi(attempt);
            switched[c] = differ.column(&dirs[c], v0s[c], h, &mut work);
            evaluations += 2 * (levels + 1);
            if let Some(r) = work.d.iter().position(|v| !v.is_finite()) {
                return Err(non_finite(c, r, work.d[r]));
            }
            store(c, &work, &mut jac, &mut incons, &mut corr);
            bad = inconsistent_rows(c, &incons);
            if switched[c] == 0 && bad.is_empty() {
                break;
            }
        }
        if switched[c] != 0 || !bad.is_empty() {
            // an input at a limit of its saturation, or an actuator state at the limit of its
            // command's range (the EGR valve shut: u_egr1 = u_egr2 = 0): the derivative on the
            // side where fewer saturations are active (the inner side of the input's range; for
            // the actuator states the open valve's branch, which a point just inside the
            // command's range linearizes)
            let limits = match dirs[c] {
                Dir::Input { k, .. } => Some(input_limits(k)),
                Dir::State(i) if actuators.contains(&i) => Some(if names[i].starts_with("u_egr") {
                    egr_lim
                } else {
                    vgt_lim
                }),
                Dir::State(_) => None,
            };
            if let Some((lo, hi)) = limits {
                let reach = h0[c] * f64::from(1u32 << (levels + 1));
                let at = if (v0s[c] - lo).abs() <= reach {
                    Some(lo)
                } else if (hi - v0s[c]).abs() <= reach {
                    Some(hi)
                } else {
                    None
                };
                if let Some(limit) = at {
                    // from the limit itself, each side's stencil on one side of it
                    let mut sides = Vec::with_capacity(2);
                    for side in [1i8, -1] {
                        let (sw, g) =
                            differ.one_sided_column(&dirs[c], limit, h0[c], side, &mut work);
                        evaluations += levels + 2;
                        if let Some(r) = work.d.iter().position(|v| !v.is_finite()) {
                            return Err(non_finite(c, r, work.d[r]));
                        }
                        if sw == 0 {
                            sides.push((side, g, work.d.clone(), work.corr.clone()));
                        }
                    }
                    let pick = match sides.as_slice() {
                        [one] => Some(one),
                        // both smooth: the one whose active guards are a strict subset
                        [a, b] if a.1 & b.1 == a.1 && a.1 != b.1 => Some(a),
                        [a, b] if a.1 & b.1 == b.1 && a.1 != b.1 => Some(b),
                        _ => None,
                    };
                    if let Some((side, _, d, cr)) = pick {
                        adopt_one_sided(c, d, cr, &mut jac, &mut corr, &mut incons);
                        one_sided.push(OneSided {
                            variable: dir_name(&dirs[c]),
                            value: v0s[c],
                            limit,
                            side: *side,
                            beside_kink: false,
                        });
                        continue;
                    }
                }
            }
            if limits.is_none() && levels >= 1 {
                // a state's kink near the point but not at it (within the finest stencil,
                // 2h/256; e.g. omega_t a few mrad/s above c_m2, where eq. (51)'s c_m leaves
                // zero): the point lies on one side's branch, whose one-sided slopes from the
                // point agree while the other side's straddle the kink. That side is the
                // point's derivative. Both sides smooth: the kink is at the point, refused.
                let h = h0[c] / 256.0;
                let mut sides = Vec::with_capacity(2);
                for side in [1i8, -1] {
                    let (sw, _) = differ.one_sided_column(&dirs[c], v0s[c], h, side, &mut work);
                    evaluations += levels + 2;
                    if let Some(r) = work.d.iter().position(|v| !v.is_finite()) {
                        return Err(non_finite(c, r, work.d[r]));
                    }
                    // the slopes at h and 2h, scaled as the inconsistency test
                    let spread = (0..nrow)
                        .filter(|&r| reference[r] > 0.0)
                        .map(|r| {
                            (work.dk[r] - work.dk[nrow + r]).abs() * col_scale[c] / reference[r]
                        })
                        .fold(0.0, f64::max);
                    sides.push((side, sw, spread, work.d.clone(), work.corr.clone()));
                }
                let (a, b) = (&sides[0], &sides[1]);
                let smooth = |x: &(i8, u32, f64, Vec<f64>, Vec<f64>),
                              y: &(i8, u32, f64, Vec<f64>, Vec<f64>)| {
                    x.1 == 0 && y.2 > opts.kink_tol && x.2 < 1e-3 * y.2
                };
                let pick = if smooth(a, b) {
                    Some(a)
                } else if smooth(b, a) {
                    Some(b)
                } else {
                    None
                };
                if let Some((side, _, _, d, cr)) = pick {
                    adopt_one_sided(c, d, cr, &mut jac, &mut corr, &mut incons);
                    one_sided.push(OneSided {
                        variable: dir_name(&dirs[c]),
                        value: v0s[c],
                        limit: v0s[c],
                        side: *side,
                        beside_kink: true,
                    });
                    continue;
                }
            }
            kinks.push(Kink {
                variable: dir_name(&dirs[c]),
                guards: Guard::ALL
                    .iter()
                    .filter(|g| switched[c] & (**g as u32) != 0)
                    .map(|g| g.label())
                    .collect(),
                rows: bad.iter().map(|&r| row_name(r)).collect(),
            });
        }
    }

    let mut correction: f64 = 0.0;
    let mut kink_score: f64 = 0.0;
    for r in 0..nrow {
        if reference[r] == 0.0 {
            continue;
        }
        for c in 0..ndir {
            correction = correction.max(corr[(r, c)] * col_scale[c] / reference[r]);
            kink_score =
                kink_score.max(incons[(r, c)] * col_scale[c] / (opts.kink_tol * reference[r]));
        }
    }
    if opts.strict && !kinks.is_empty() {
        return Err(LinearizeError::Kink(kinks));
    }

    // Assemble A, B, C, D (with Padé states for the delayed copies of u_egr, u_vgt; a channel
    // whose delay is 0 needs none: its delayed copy is the command, exp(0 s) = 1).
    let p_ = m.params();
    let delays = [p_.egr_actuator.tau_degr, p_.vgt_actuator.tau_dvgt];
    let pade_states = delays.map(|tau| if tau > 0.0 { pade } else { 0 });
    let np = pade_states[0] + pade_states[1];
    let n = N + np;
    let mut a = DMatrix::zeros(n, n);
    let mut b = DMatrix::zeros(n, 4);
    let mut cm = DMatrix::zeros(p, n);
    let mut dm = DMatrix::zeros(p, 4);
    for r in 0..nrow {
        for c in 0..(N + 4) {
            let v = jac[(r, c)];
            match (r < N, c < N) {
                (true, true) => a[(r, c)] = v,
                (true, false) => b[(r, c - N)] = v,
                (false, true) => cm[(r - N, c)] = v,
                (false, false) => dm[(r - N, c - N)] = v,
            }
        }
    }
    let mut state_names: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let mut state_scales: Vec<f64> = scales.to_vec();
    if pade > 0 {
        for (q, (k, tau)) in [(1usize, delays[0]), (2usize, delays[1])]
            .into_iter()
            .enumerate()
        {
            let kq = pade_states[q];
            // z' = pa z + pb u_k;   w = pc z + pd u_k  (w replaces the delayed command);
            // without states (delay 0) w = u_k
            let (pa, pb, pc, pd) = if kq > 0 {
                pade_realization(tau, kq)
            } else {
                (Vec::new(), Vec::new(), Vec::new(), 1.0)
            };
            let off = N + pade_states[..q].iter().sum::<usize>();
            let col = N + 4 + q; // the delayed-copy direction
            for i in 0..kq {
                for j in 0..kq {
                    a[(off + i, off + j)] = pa[i][j];
                }
                b[(off + i, k)] = pb[i];
            }
            for r in 0..nrow {
                let g = jac[(r, col)];
                if g == 0.0 {
                    continue;
                }
                for j in 0..kq {
                    if r < N {
                        a[(r, off + j)] += g * pc[j];
                    } else {
                        cm[(r - N, off + j)] += g * pc[j];
                    }
                }
                if r < N {
                    b[(r, k)] += g * pd;
                } else {
                    dm[(r - N, k)] += g * pd;
                }
            }
            let tag = if k == 1 { "egr" } else { "vgt" };
            for j in 0..kq {
                state_names.push(format!("pade_{tag}_{}", j + 1));
                state_scales.push(INPUT_SCALES[k]);
            }
        }
    }
    let mut x0v = x.to_vec();
    x0v.extend(std::iter::repeat_n(0.0, np));
    let y0: Vec<f64> = sel
        .iter()
        .enumerate()
        .map(|(o, s)| match s {
            Sel::State(i) => x[*i],
            Sel::Signal(_) => f0[N + o],
        })
        .collect();
    let output_scales = sel
        .iter()
        .zip(&y0)
        .map(|(s, y)| match s {
            Sel::State(i) => scales[*i],
            Sel::Signal(_) => {
                if y.abs() > 1e-300 {
                    y.abs()
                } else {
                    1.0
                }
            }
        })
        .collect();
    Ok(LinearModel {
        a,
        b,
        c: cm,
        d: dm,
        state_names,
        input_names: INPUT_NAMES.iter().map(|s| s.to_string()).collect(),
        output_names: opts.outputs.clone(),
        x0: x0v,
        u0,
        y0,
        dx0: f0[..N].to_vec(),
        state_scales,
        input_scales: INPUT_SCALES.to_vec(),
        output_scales,
        kinks,
        one_sided,
        correction,
        kink_score,
        pade_order: pade,
        delays,
        evaluations,
    })
}

/// Work buffers of one difference column.
struct Work {
    /// Central differences per level ([lev * nrow + r]).
    dk: Vec<f64>,
    /// Second differences per level.
    sk: Vec<f64>,
    fp: Vec<f64>,
    fm: Vec<f64>,
    /// Results: extrapolated derivative, last correction, slope inconsistency (per row).
    d: Vec<f64>,
    corr: Vec<f64>,
    incons: Vec<f64>,
}

impl Work {
    fn new(nrow: usize, levels: usize) -> Self {
        Self {
            dk: vec![0.0; (levels + 1) * nrow],
            sk: vec![0.0; (levels + 1) * nrow],
            fp: vec![0.0; nrow],
            fm: vec![0.0; nrow],
            d: vec![0.0; nrow],
            corr: vec![0.0; nrow],
            incons: vec![0.0; nrow],
        }
    }
}

/// Weights 1 / (4^j - 1) of the Richardson table of central differences (errors in h^2, h^4, ...).
const INV_W_CENTRAL: [f64; 4] = [0.0, 1.0 / 3.0, 1.0 / 15.0, 1.0 / 63.0];
/// Takes a one-sided column `c` into the Jacobian: its derivatives `d` and their Richardson
/// corrections `cr`, with no inconsistency left (the side was chosen because its slopes agree).
fn adopt_one_sided(
    c: usize,
    d: &[f64],
    cr: &[f64],
    jac: &mut DMatrix<f64>,
    corr: &mut DMatrix<f64>,
    incons: &mut DMatrix<f64>,
) {
    jac.column_mut(c).copy_from_slice(d);
    corr.column_mut(c).copy_from_slice(cr);
    incons.column_mut(c).fill(0.0);
}

/// Weights 1 / (2^j - 1) of the Richardson table of one-sided differences (errors in h, h^2, ...).
const INV_W_ONE_SIDED: [f64; 4] = [0.0, 1.0, 1.0 / 3.0, 1.0 / 7.0];

/// The Richardson-extrapolated value of row `r` from its differences at steps h, 2h, ..., 2^L h
/// (`dk[lev * nrow + r]`): `R_{k,j} = R_{k,j-1} + (R_{k,j-1} - R_{k+1,j-1}) inv_w[j]`; returns
/// `R_{0,L}` and |the last correction|.
fn richardson(dk: &[f64], nrow: usize, r: usize, levels: usize, inv_w: &[f64; 4]) -> (f64, f64) {
    let mut t = [0.0; 4];
    for (lev, tv) in t.iter_mut().enumerate().take(levels + 1) {
        *tv = dk[lev * nrow + r];
    }
    let mut last = 0.0;
    for j in 1..=levels {
        for k in 0..=(levels - j) {
            let delta = (t[k] - t[k + 1]) * inv_w[j];
            if k == 0 {
                last = delta;
            }
            t[k] += delta;
        }
    }
    (t[0], last.abs())
}

/// Everything one difference column needs.
struct Differ<'a, const N: usize, M: Model<N>> {
    m: &'a M,
    x: &'a [f64; N],
    u_base: ModelInput,
    mem: M::Memory,
    rows: &'a Rows,
    f0: &'a [f64],
    g0: u32,
    levels: usize,
    /// (row, state) of the outputs that are states: exact rows.
    state_rows: Vec<(usize, usize)>,
}

impl<const N: usize, M: Model<N>> Differ<'_, N, M> {
    /// Richardson-extrapolated central differences of every row in direction `dir` (value
    /// `v0`) with base step `h`, into `w.d`, `w.corr`, `w.incons`; returns the guard bits that
    /// switch inside the stencil.
    fn column(&self, dir: &Dir, v0: f64, h: f64, w: &mut Work) -> u32 {
        let nrow = self.f0.len();
        let levels = self.levels;
        let mut switched = 0u32;
        for lev in 0..=levels {
            let hl = h * f64::from(1u32 << lev);
            let vp = v0 + hl;
            let vm = v0 - hl;
            for (v, plus) in [(vp, true), (vm, false)] {
                let (xx, uu) = perturbed(self.x, &self.u_base, dir, v);
                let e = self.m.eval(&xx, &uu, self.mem);
                let out = if plus { &mut w.fp } else { &mut w.fm };
                self.rows.fill(&e.dx, &e.signals, out);
                switched |= e.signals.guards ^ self.g0;
            }
            // exactly representable differences of the perturbed values
            let inv_den = 1.0 / (vp - vm);
            let inv_half = 2.0 * inv_den;
            let dl = &mut w.dk[lev * nrow..(lev + 1) * nrow];
            let sl = &mut w.sk[lev * nrow..(lev + 1) * nrow];
            for r in 0..nrow {
                dl[r] = (w.fp[r] - w.fm[r]) * inv_den;
                sl[r] = (w.fp[r] - 2.0 * self.f0[r] + w.fm[r]) * inv_half;
            }
        }
        for r in 0..nrow {
            (w.d[r], w.corr[r]) = richardson(&w.dk, nrow, r, levels, &INV_W_CENTRAL);
            // smooth: S(2h) - 2 S(h) = O(h^3) and D(h) - D(2h) = O(h^2) (weighted 1/100)
            w.incons[r] = if levels >= 1 {
                let t1 = (w.sk[nrow + r] - 2.0 * w.sk[r]).abs();
                let t2 = (w.dk[r] - w.dk[nrow + r]).abs();
                t1.max(0.01 * t2)
            } else {
                0.0
            };
        }
        for &(r, i) in &self.state_rows {
            w.d[r] = if *dir == Dir::State(i) { 1.0 } else { 0.0 };
            w.corr[r] = 0.0;
            w.incons[r] = 0.0;
        }
        switched
    }

    /// Richardson-extrapolated one-sided differences of every row in direction `dir` from the
    /// value `v_from` (the saturation limit; evaluated there, as the point may sit only near
    /// it), steps `side * h, 2 h, ..., 2^L h`: `R_{k,j} = (2^j R_{k,j-1} - R_{k+1,j-1}) /
    /// (2^j - 1)` (`O(h^(L+1))`), into `w.d`, `w.corr` (`w.incons` zero); returns the guard bits that
    /// switch within the stencil on that side (the limit itself excluded) and the guards
    /// active there.
    fn one_sided_column(
        &self,
        dir: &Dir,
        v_from: f64,
        h: f64,
        side: i8,
        w: &mut Work,
    ) -> (u32, u32) {
        let nrow = self.f0.len();
        let levels = self.levels;
        let mut switched = 0u32;
        let (x0, u0) = perturbed(self.x, &self.u_base, dir, v_from);
        let e0 = self.m.eval(&x0, &u0, self.mem);
        let mut f_from = vec![0.0; nrow];
        self.rows.fill(&e0.dx, &e0.signals, &mut f_from);
        let mut g_side = None;
        for lev in 0..=levels {
            let v = v_from + f64::from(side) * h * f64::from(1u32 << lev);
            let (xx, uu) = perturbed(self.x, &self.u_base, dir, v);
            let e = self.m.eval(&xx, &uu, self.mem);
            self.rows.fill(&e.dx, &e.signals, &mut w.fp);
            // a guard that switches between the stencil points of this side
            let g = *g_side.get_or_insert(e.signals.guards);
            switched |= e.signals.guards ^ g;
            let inv = 1.0 / (v - v_from);
            let dl = &mut w.dk[lev * nrow..(lev + 1) * nrow];
            for r in 0..nrow {
                dl[r] = (w.fp[r] - f_from[r]) * inv;
            }
        }
        for r in 0..nrow {
            (w.d[r], w.corr[r]) = richardson(&w.dk, nrow, r, levels, &INV_W_ONE_SIDED);
            w.incons[r] = 0.0;
        }
        for &(r, i) in &self.state_rows {
            w.d[r] = if *dir == Dir::State(i) { 1.0 } else { 0.0 };
            w.corr[r] = 0.0;
        }
        (switched, g_side.unwrap_or(0))
    }
}

/// The derivative of the model's derivatives and signals along a direction of its state and
/// inputs: `d/de [f, signals](x + e v_x, u + e v_u)` at `e = 0`, for FMI's
/// `fmi2GetDirectionalDerivative` and other Jacobian-vector products.
///
/// `v_u` is the direction of the six input values of [`ModelInput::to_array`] (n_e \[rpm\],
/// u_delta \[mg\], u_egr, u_vgt, delayed u_egr, delayed u_vgt \[%\]). The method is that of
/// [`linearize`] in one direction: central differences at steps `e` and `2e`,
/// Richardson-extrapolated (4 evaluations, `O(e^4)`), with `e` a power of two such that the
/// largest scaled component of the direction moves by about `rel_step` (1e-4 in [`linearize`])
/// of its scale (the state scales and [`INPUT_SCALES`]). At a kink it returns the averaged
/// slopes, without a check. `memory` is the cylinder-temperature memory held by the caller.
///
/// Returns `(d f, d signals)` (N values, then [`Signals::NAMES`] order); zeros for a zero
/// direction; an error naming the row when a value is not finite.
pub fn directional_derivative<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    u: &ModelInput,
    memory: M::Memory,
    v_x: &[f64; N],
    v_u: &[f64; 6],
    rel_step: f64,
) -> Result<(Vec<f64>, Vec<f64>), LinearizeError> {
    sided_derivative(m, x, u, memory, v_x, v_u, rel_step, false)
}

/// [`directional_derivative`], or with `one_sided` the derivative on the side of the direction
/// only (forward differences at steps `e` and `2e`, Richardson-extrapolated, `O(e^2)`): at a
/// saturation limit, the slope on the side the direction points to (for a delayed copy of an
/// input that [`linearize`] differenced on one side, [`OneSided`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn sided_derivative<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    u: &ModelInput,
    memory: M::Memory,
    v_x: &[f64; N],
    v_u: &[f64; 6],
    rel_step: f64,
    one_sided: bool,
) -> Result<(Vec<f64>, Vec<f64>), LinearizeError> {
    if let Some(v) = v_x.iter().chain(v_u).find(|v| !v.is_finite()) {
        return Err(LinearizeError::NonFinite {
            what: "direction".into(),
            value: *v,
        });
    }
    let scales = m.state_scales();
    let input_scale = |k: usize| INPUT_SCALES[[3, 0, 1, 2, 1, 2][k]];
    let size = (0..N)
        .map(|i| v_x[i].abs() / scales[i])
        .chain((0..6).map(|k| v_u[k].abs() / input_scale(k)))
        .fold(0.0, f64::max);
    let n_sig = Signals::NAMES.len();
    if size == 0.0 {
        return Ok((vec![0.0; N], vec![0.0; n_sig]));
    }
    if !(rel_step > 0.0 && rel_step.is_finite()) {
        return Err(LinearizeError::BadOption {
            field: "rel_step",
            value: rel_step,
            constraint: "must be > 0 and finite",
        });
    }
    let e = pow2_step(rel_step / size);
    let u0 = u.to_array();
    let at = |k: f64| -> Vec<f64> {
        let xx: [f64; N] = std::array::from_fn(|i| x[i] + k * e * v_x[i]);
        let uu = ModelInput::from_array(std::array::from_fn(|j| u0[j] + k * e * v_u[j]));
        let ev = m.eval(&xx, &uu, memory);
        ev.dx.into_iter().chain(ev.signals.values()).collect()
    };
    let d: Vec<f64> = if one_sided {
        let (p0, p1, p2) = (at(0.0), at(1.0), at(2.0));
        (0..N + n_sig)
            .map(|r| {
                let d1 = (p1[r] - p0[r]) / e;
                let d2 = (p2[r] - p0[r]) / (2.0 * e);
                2.0 * d1 - d2
            })
            .collect()
    } else {
        let (p1, m1, p2, m2) = (at(1.0), at(-1.0), at(2.0), at(-2.0));
        (0..N + n_sig)
            .map(|r| {
                let d1 = (p1[r] - m1[r]) / (2.0 * e);
                let d2 = (p2[r] - m2[r]) / (4.0 * e);
                (4.0 * d1 - d2) / 3.0
            })
            .collect()
    };
    if let Some(r) = d.iter().position(|v| !v.is_finite()) {
        let names = m.state_names();
        let what = if r < N {
            format!("directional derivative of d{}/dt", names[r])
        } else {
            format!("directional derivative of {}", Signals::NAMES[r - N])
        };
        return Err(LinearizeError::NonFinite { what, value: d[r] });
    }
    let sig = d[N..].to_vec();
    let mut dx = d;
    dx.truncate(N);
    Ok((dx, sig))
}

/// Largest power of two not above `h` (h > 0).
#[inline]
pub(crate) fn pow2_step(h: f64) -> f64 {
    2f64.powi(h.log2().floor() as i32)
}

/// State and inputs with the direction's variable set to `v`.
#[inline]
fn perturbed<const N: usize>(
    x: &[f64; N],
    u: &ModelInput,
    dir: &Dir,
    v: f64,
) -> ([f64; N], ModelInput) {
    let mut xx = *x;
    let mut uu = *u;
    match *dir {
        Dir::State(i) => xx[i] = v,
        Dir::Input { k, now, delayed } => match k {
            0 => uu.now.u_delta_mg = v,
            1 => {
                if now {
                    uu.now.u_egr_pct = v;
                }
                if delayed {
                    uu.u_egr_delayed = v;
                }
            }
            2 => {
                if now {
                    uu.now.u_vgt_pct = v;
                }
                if delayed {
                    uu.u_vgt_delayed = v;
                }
            }
            _ => uu.now.n_e_rpm = v,
        },
    }
    (xx, uu)
}

/// Coefficients (ascending powers of s) of the [k/k] Padé approximant of exp(-tau s):
/// numerator N(s) and denominator D(s) with D(s) = sum c_j (tau s)^j, N(s) = sum c_j (-tau s)^j,
/// c_j = (2k - j)! k! / ((2k)! j! (k - j)!).
pub fn pade_coefficients(tau: f64, order: usize) -> (Vec<f64>, Vec<f64>) {
    let fact = |n: usize| (1..=n).fold(1.0, |a, b| a * b as f64);
    let k = order;
    let mut num = Vec::with_capacity(k + 1);
    let mut den = Vec::with_capacity(k + 1);
    for j in 0..=k {
        let c = fact(2 * k - j) * fact(k) / (fact(2 * k) * fact(j) * fact(k - j));
        let t = tau.powi(j as i32);
        den.push(c * t);
        num.push(c * t * if j % 2 == 0 { 1.0 } else { -1.0 });
    }
    (num, den)
}

/// State-space realization (A, B, C, D) of the order-`k` Padé approximant of exp(-tau s)
/// (tau > 0): the controllable canonical form of the approximant in the scaled variable
/// `tau s` (the delay 1), with A and B divided by tau, which is the canonical form of exp(-tau s)
/// under the diagonal similarity `z_j = tau^(k-j) w_j`: every entry of A and B is O(1/tau) and of
/// C O(1) (the states have the input's units), and no power of tau is formed, so any positive
/// finite delay gives finite matrices (1e-300 s to 1e300 s).
#[allow(clippy::type_complexity)]
pub fn pade_realization(tau: f64, k: usize) -> (Vec<Vec<f64>>, Vec<f64>, Vec<f64>, f64) {
    let (num, den) = pade_coefficients(1.0, k);
    // monic denominator: s^k + a_{k-1} s^{k-1} + ... + a_0
    let lead = den[k];
    let a: Vec<f64> = den.iter().map(|c| c / lead).collect();
    let nn: Vec<f64> = num.iter().map(|c| c / lead).collect();
    // feedthrough dd = (-1)^k; strictly proper remainder n(s) - dd d(s), degree < k
    let dd = nn[k];
    // Controllable canonical form with z_1 = the lowest state: z_j' = z_{j+1},
    // z_k' = -sum a_j z_{j+1} + u; for the delay tau, A / tau and B / tau
    let mut am = vec![vec![0.0; k]; k];
    let mut bm = vec![0.0; k];
    let cm: Vec<f64> = (0..k).map(|j| nn[j] - dd * a[j]).collect();
    for j in 0..k - 1 {
        am[j][j + 1] = 1.0 / tau;
    }
    for j in 0..k {
        am[k - 1][j] = -a[j] / tau;
    }
    bm[k - 1] = 1.0 / tau;
    (am, bm, cm, dd)
}

impl LinearModel {
    /// Number of states.
    pub fn n_states(&self) -> usize {
        self.a.nrows()
    }

    /// Column of an input name (`u_delta`, `u_egr`, `u_vgt`, `n_e`).
    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.input_names.iter().position(|s| s == name)
    }

    /// Row of an output name.
    pub fn output_index(&self, name: &str) -> Option<usize> {
        self.output_names.iter().position(|s| s == name)
    }

    /// Index of a state name.
    pub fn state_index(&self, name: &str) -> Option<usize> {
        self.state_names.iter().position(|s| s == name)
    }

    /// Whether no kink was found.
    pub fn is_smooth(&self) -> bool {
        self.kinks.is_empty()
    }

    /// States on a signal path from input `k` to output `o` (structurally: reachable from the
    /// input through the nonzero entries of B and A, and reaching the output through A and C).
    pub fn path_states(&self, k: usize, o: usize) -> Vec<usize> {
        let n = self.n_states();
        let mut fwd = vec![false; n];
        let mut stack: Vec<usize> = (0..n).filter(|&i| self.b[(i, k)] != 0.0).collect();
        for &i in &stack {
            fwd[i] = true;
        }
        while let Some(j) = stack.pop() {
            for i in 0..n {
                if !fwd[i] && self.a[(i, j)] != 0.0 {
                    fwd[i] = true;
                    stack.push(i);
                }
            }
        }
        let mut bwd = vec![false; n];
        let mut stack: Vec<usize> = (0..n).filter(|&j| self.c[(o, j)] != 0.0).collect();
        for &j in &stack {
            bwd[j] = true;
        }
        while let Some(i) = stack.pop() {
            for j in 0..n {
                if !bwd[j] && self.a[(i, j)] != 0.0 {
                    bwd[j] = true;
                    stack.push(j);
                }
            }
        }
        (0..n).filter(|&i| fwd[i] && bwd[i]).collect()
    }

    /// Kinks that lie on a signal path of the channel `input -> output`: the kink's direction
    /// is the input or a path state, and the rows it disturbs (if known) include a path state's
    /// derivative or the output. Unknown names give all kinks.
    pub fn kinks_affecting(&self, input: &str, output: &str) -> Vec<&Kink> {
        let (Some(k), Some(o)) = (self.input_index(input), self.output_index(output)) else {
            return self.kinks.iter().collect();
        };
        let path = self.path_states(k, o);
        let path_names: Vec<&str> = path.iter().map(|&i| self.state_names[i].as_str()).collect();
        let path_rows: Vec<String> = path_names.iter().map(|s| format!("d({s})/dt")).collect();
        self.kinks
            .iter()
            .filter(|kink| {
                let var = kink.variable.as_str();
                let on_path = var == input
                    || var.starts_with(&format!("{input}("))
                    || path_names.contains(&var);
                let rows_hit = kink.rows.is_empty()
                    || kink
                        .rows
                        .iter()
                        .any(|r| r == output || path_rows.iter().any(|p| p == r));
                on_path && rows_hit
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The DC gain of the linearization (`D - C A^-1 B`, [`crate::analysis::zeros::dc_gain_matrix`],
    /// what the FMU answers in Initialization Mode) equals central differences of the steady
    /// state itself (Newton at u +- e v, Richardson-extrapolated over e and e/2), for the 8-, 10-
    /// and 12-state models at two operating points, to 1e-7 relative (they agree to about
    /// 1e-11), for the states and six signals.
    #[test]
    fn dc_gain_is_the_derivative_of_the_steady_state() {
        use crate::analysis::steady::steady_state;
        use crate::analysis::zeros::dc_gain_matrix;
        use crate::model::{Engine10, Engine12, Engine8};
        const SIGNALS: [&str; 6] = ["W_c", "W_egr", "W_t", "lambda_O", "T_em", "x_egr"];
        fn check<const N: usize, M: Model<N>>(m: &M, d: Drive, v: [f64; 4]) {
            let x = steady_state(m, &d).unwrap().x;
            let names = m.state_names();
            let opts = LinearizeOptions {
                outputs: names
                    .iter()
                    .chain(SIGNALS.iter())
                    .map(|s| s.to_string())
                    .collect(),
                ..LinearizeOptions::default()
            };
            let g = dc_gain_matrix(&linearize(m, &x, &d, &opts).unwrap()).unwrap();
            // the linear model's inputs: u_delta, u_egr, u_vgt, n_e
            let v_lin = [v[1], v[2], v[3], v[0]];
            let gain = |row: usize| -> f64 { (0..4).map(|c| g[(row, c)] * v_lin[c]).sum() };
            let dx: Vec<f64> = (0..N).map(gain).collect();
            let ds: Vec<f64> = (0..SIGNALS.len()).map(|k| gain(N + k)).collect();
            let at = |e: f64| -> (Vec<f64>, Vec<f64>) {
                let de = Drive::new(
                    d.n_e_rpm + e * v[0],
                    d.u_delta_mg + e * v[1],
                    d.u_egr_pct + e * v[2],
                    d.u_vgt_pct + e * v[3],
                );
                let xe = steady_state(m, &de).unwrap().x;
                let ue = ModelInput::constant(de);
                let ev = m.eval(&xe, &ue, m.memory_start(&xe, &ue));
                (xe.to_vec(), ev.signals.values().to_vec())
            };
            let e = 0.02;
            let (p1, m1, p2, m2) = (at(e), at(-e), at(e / 2.0), at(-e / 2.0));
            let rich = |a: &[f64], b: &[f64], c: &[f64], dd: &[f64], k: usize| {
                let d1 = (a[k] - b[k]) / (2.0 * e);
                let d2 = (c[k] - dd[k]) / e;
                (4.0 * d2 - d1) / 3.0
            };
            let scales = m.state_scales();
            for i in 0..N {
                let fd = rich(&p1.0, &m1.0, &p2.0, &m2.0, i);
                assert!(
                    (dx[i] - fd).abs() <= 1e-7 * (fd.abs() + 1e-3 * scales[i]),
                    "N = {N}, {d:?}, state {}: {} vs {fd}",
                    m.state_names()[i],
                    dx[i]
                );
            }
            for (k, name) in SIGNALS.iter().enumerate() {
                let j = Signals::NAMES.iter().position(|s| s == name).unwrap();
                let fd = rich(&p1.1, &m1.1, &p2.1, &m2.1, j);
                assert!(
                    (ds[k] - fd).abs() <= 1e-7 * (fd.abs() + 1e-6 * p1.1[j].abs().max(1e-3)),
                    "N = {N}, {d:?}, {name}: {} vs {fd}",
                    ds[k]
                );
            }
        }
        for (d, v) in [
            (
                Drive::new(1500.0, 110.0, 80.0, 75.0),
                [20.0, 2.0, -1.0, 1.0],
            ),
            (
                Drive::new(1200.0, 60.0, 30.0, 45.0),
                [-15.0, 1.0, 2.0, -2.0],
            ),
        ] {
            check(&Engine8::published(), d, v);
            check(&Engine10::published(), d, v);
            check(&Engine12::published(), d, v);
        }
    }

    /// A directional derivative is the linearization's Jacobian times the direction (both
    /// Richardson-extrapolated differences, one along the direction, the other per column),
    /// off equilibrium; moving only the current u_egr (not its delayed copy) moves no state
    /// derivative but the signal u_egr.
    #[test]
    fn directional_derivative_is_the_jacobian_times_the_direction() {
        use crate::analysis::steady::steady_state;
        let m = crate::model::Engine8::published();
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let mut x = steady_state(&m, &d).unwrap().x;
        x[0] *= 1.05;
        x[4] *= 0.97;
        let d = Drive::new(1400.0, 130.0, 60.0, 55.0);
        let opts = LinearizeOptions {
            outputs: vec!["W_c".into(), "lambda_O".into()],
            ..LinearizeOptions::default()
        };
        let lin = linearize(&m, &x, &d, &opts).unwrap();
        let u = ModelInput::constant(d);
        let mem = m.memory_start(&x, &u);
        let scales = m.state_scales();
        let v_x: [f64; 8] =
            std::array::from_fn(|i| scales[i] * [0.3, -0.2, 0.1, 0.5, -0.4, 0.2, 0.1, -0.3][i]);
        // (u_delta, u_egr, u_vgt, n_e) of the linear model; the delayed copies move along
        let v_lin = [10.0, -5.0, 3.0, 50.0];
        let v_u = [50.0, 10.0, -5.0, 3.0, -5.0, 3.0];
        let (df, ds) = directional_derivative(&m, &x, &u, mem, &v_x, &v_u, 1e-4).unwrap();
        // tolerance: 1e-8 of the sum of the terms' magnitudes (both ~1e-9 accurate)
        for r in 0..8 {
            let terms: Vec<f64> = (0..8)
                .map(|c| lin.a[(r, c)] * v_x[c])
                .chain((0..4).map(|c| lin.b[(r, c)] * v_lin[c]))
                .collect();
            let jv: f64 = terms.iter().sum();
            let size: f64 = terms.iter().map(|t| t.abs()).sum();
            assert!(
                (df[r] - jv).abs() <= 1e-8 * size,
                "row {r}: {} vs {jv}",
                df[r]
            );
        }
        for (o, name) in ["W_c", "lambda_O"].iter().enumerate() {
            let j = Signals::NAMES.iter().position(|s| s == name).unwrap();
            let jv: f64 = (0..8).map(|c| lin.c[(o, c)] * v_x[c]).sum::<f64>()
                + (0..4).map(|c| lin.d[(o, c)] * v_lin[c]).sum::<f64>();
            assert!(
                (ds[j] - jv).abs() <= 1e-8 * jv.abs().max(lin.output_scales[o]),
                "{name}"
            );
        }
        // only the current u_egr: no state derivative moves; the signal u_egr does, by 1
        let (df, ds) = directional_derivative(
            &m,
            &x,
            &u,
            mem,
            &[0.0; 8],
            &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
            1e-4,
        )
        .unwrap();
        assert!(df.iter().all(|v| *v == 0.0), "{df:?}");
        let j = Signals::NAMES.iter().position(|s| *s == "u_egr").unwrap();
        assert!((ds[j] - 1.0).abs() < 1e-12, "{}", ds[j]);
        // a zero direction gives zeros without evaluating; a NaN one is refused
        let (z, _) = directional_derivative(&m, &x, &u, mem, &[0.0; 8], &[0.0; 6], 1e-4).unwrap();
        assert_eq!(z, vec![0.0; 8]);
        let mut bad = [0.0; 8];
        bad[2] = f64::NAN;
        assert!(directional_derivative(&m, &x, &u, mem, &bad, &[0.0; 6], 1e-4).is_err());
    }

    #[test]
    fn steps_are_powers_of_two_not_above_the_request() {
        for h in [1e-4, 0.01, 3.0, 10.0, 123.456] {
            let p = pow2_step(h);
            assert!(p <= h && p > 0.5 * h, "{h} -> {p}");
            assert_eq!(p.log2().fract(), 0.0);
        }
    }

    #[test]
    fn pade_coefficients_by_hand() {
        // [1/1]: (1 - tau s/2)/(1 + tau s/2); [2/2]: 1 +- tau s/2 + (tau s)^2/12;
        // [3/3]: 1 +- tau s/2 + (tau s)^2/10 +- (tau s)^3/120
        let tau = 0.04;
        let (n1, d1) = pade_coefficients(tau, 1);
        assert_eq!(n1, vec![1.0, -tau / 2.0]);
        assert_eq!(d1, vec![1.0, tau / 2.0]);
        let (n2, d2) = pade_coefficients(tau, 2);
        assert!((d2[2] - tau * tau / 12.0).abs() < 1e-18 && (n2[2] - d2[2]).abs() < 1e-18);
        let (n3, d3) = pade_coefficients(tau, 3);
        assert!((d3[2] - tau * tau / 10.0).abs() < 1e-18);
        assert!((d3[3] - tau.powi(3) / 120.0).abs() < 1e-20 && (n3[3] + d3[3]).abs() < 1e-20);
        // the realization has the approximant's feedthrough (-1)^k
        for k in 1..=3 {
            let (_, _, _, d) = pade_realization(tau, k);
            assert_eq!(d, if k % 2 == 0 { 1.0 } else { -1.0 });
        }
    }

    #[test]
    fn perturbations_move_the_right_copies_of_an_input() {
        let x = [1.0, 2.0];
        let u = ModelInput::constant(Drive::new(1500.0, 110.0, 80.0, 75.0));
        let both = Dir::Input {
            k: 2,
            now: true,
            delayed: true,
        };
        let (_, uu) = perturbed(&x, &u, &both, 76.0);
        assert_eq!((uu.now.u_vgt_pct, uu.u_vgt_delayed), (76.0, 76.0));
        let delayed = Dir::Input {
            k: 1,
            now: false,
            delayed: true,
        };
        let (_, uu) = perturbed(&x, &u, &delayed, 81.0);
        assert_eq!((uu.now.u_egr_pct, uu.u_egr_delayed), (80.0, 81.0));
        let (xx, uu) = perturbed(&x, &u, &Dir::State(1), 5.0);
        assert_eq!((xx, uu), ([1.0, 5.0], u));
        let (_, uu) = perturbed(
            &x,
            &u,
            &Dir::Input {
                k: 3,
                now: true,
                delayed: true,
            },
            1600.0,
        );
        assert_eq!(uu.now.n_e_rpm, 1600.0);
    }
}
