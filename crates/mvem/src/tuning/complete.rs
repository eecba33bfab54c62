//! Tuning steps 3-5 on the complete model (paper section 8.1).
//!
//! - [`step3`]: V_im, V_em, J_t by eqs (74)-(75): least squares of the normalized step
//!   responses of p_im, p_em, W_c, n_t (K = 4) in the dynamic sets (B, C: J = 2), each set's
//!   sum normalized by its number of samples L_j.
//! - [`step4`]: tau_Me of the dynamometer lag eq. (76) by the same problem with K = 1,
//!   w_1 = M_dynamo^norm, on the fuel-step set I.
//! - [`step5`]: the static parameters by the combined cost (77): dynamic errors of the complete
//!   model on the static-tuning sets (A-I, 10 Hz) normalized by the stationary means and
//!   weighted by gamma_j, plus the submodel errors z_1..z_7 (W_ei, T_em, W_egr, eta_tm, W_t,
//!   eta_c, W_c) at the stationary points weighted by 1/beta (eta_tm as the relative error of
//!   the compressor temperature rise T_c - T_amb it implies, [`steps::fit_series`]: not in the
//!   paper, which compares the derived efficiency); box bounds, Q_c projected on the
//!   positive semidefinite cone at every evaluation. Data sets are simulated in parallel (rayon).
//!
//! **Normalized step responses** (eq. (75)): "each output and each step response is normalized
//! so that the initial and final values for each step response are the same for both the
//! measurements and the simulations". For each step (from one command change to the next) the
//! simulated response is mapped affinely onto the measured one, `a + b (sim - s0)`, with the
//! offset `a` and gain `b` fitted by least squares over the whole step ([`StepLevels`]; only
//! shifted, b = 1, when the simulated or measured change is below 1 % of the output's
//! stationary mean, where a scale would amplify noise), and the residual is divided by the
//! measured step amplitude (the mean over the 0.2 s before the step against the mean over its
//! last 20 %, at least that 1 %). The residuals then carry only dynamic errors, as in the
//! paper. Sessions 1-15 took the levels from those two means ([`StepLevels::Means`], `mvem tune
//! --step-levels means`), whose noise biased the volumes.

use super::data::{DataSetInfo, DynamicData, Role, StationaryPoint};
use super::lab::first_order_lag;
use super::lsq::{
    gauss_newton_line, least_squares, least_squares_par, Bounds, FiniteDiff, GaussNewtonLine,
    LsqOptions, LsqResult, Termination, XScale,
};
use super::scale::CampaignScale;
use super::sensors::{SensorLags, LAG_NAMES, MAX_LAG_S};
use super::steps::{self, project_q_c, FitReport, StepError};
use super::uncertainty::{
    block_covariance, estimates, estimates_from_cov, fd_column, Linearization, ParamEstimate,
};
use super::validate::{interp, sample_interval, simulate_set, stationary_means};
use crate::model::ModelOrder;
use crate::params::Params;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The outputs of eqs (75) and (77): p_im, p_em, W_c, n_t.
pub const DYN_OUTPUTS: [&str; 4] = ["p_im", "p_em", "W_c", "n_t"];

/// Relative integration tolerance of the simulations inside the searches: tight, so that the
/// finite-difference Jacobians are not dominated by the adaptive step sequence.
pub const SEARCH_RTOL: f64 = 1e-8;

/// Default of [`Step5Options::restarts`]: one restart. Step 5's path along its flat directions
/// changes with 1e-13 changes of the model, and on some campaigns it then stops by xtol far from
/// its optimum; measured in session 14 (docs/tuning.md): `mvem lab` seed 4 stopped after 254
/// evaluations at relative offset 1.73 (validation 1.83x the noise floor), with one restart
/// after 3 027 at 1.22x. Session 11 (forward-difference restarts) had left it off: 254 -> 2 783
/// evaluations for 0.4 % of cost. A campaign that stops by the relative offset (converged) or
/// below [`STEP5_RESTART_REL_OFFSET`] never restarts.
pub const STEP5_RESTARTS: usize = 1;

/// Relative offset above which an ftol/xtol stop of step 5 is restarted (and above
/// [`Step5Options::rel_offset_tol`]): where the Gauss-Newton step still predicts a decrease of
/// more than one residual variance per parameter (R^2 p residual variances for p parameters;
/// the estimate up to R sqrt(p) standard errors from the optimum). Session 14
/// (docs/tuning.md): below it, on `mvem lab` seeds 1, 3, 6, 7, a restart changed the validation
/// error by 0.01x the noise floor or less and cost up to 2.2x the time (seed 1: 434 -> 1 218
/// evaluations).
pub const STEP5_RESTART_REL_OFFSET: f64 = 1.0;

/// Relative finite-difference step of the searches (about the square root of the relative
/// simulation noise).
pub const FD_STEP: f64 = 1e-4;

/// Relative step of the central differences of the covariance Jacobians of steps 3 (7) and 5
/// (8) (`covariance_jacobian`).
pub const COV_FD_STEP: f64 = 3e-3;

/// The Jacobian of a covariance at the fit (columns `kept` of the search's parameters, bounds
/// `lo`, `hi`, scales `scale`): central differences at [`COV_FD_STEP`] max(|theta|, scale),
/// where both sides lie inside the bounds (else the search's column). The search's own Jacobian
/// (forward differences at [`FD_STEP`]) is dominated by the simulation noise in some columns:
/// on `mvem lab --seed 5` sets B and C the norm of step 3's V_im column was 6.19 or 5.25 for
/// fits 0.1 % apart, after a change of the model by 1e-14 relative that only moved the
/// integrator's step sequence, and V_im's standard error moved by 1.6x with it (session 18).
/// Noise adds to the columns' norms, so it makes standard errors too small. A 30x larger step
/// with central differences (truncation O(step^2)) takes that noise below 1 %; it costs two
/// residual evaluations per parameter, once.
fn covariance_jacobian(
    res: &(dyn Fn(&[f64]) -> Vec<f64> + Sync),
    fit: &LsqResult,
    kept: &[usize],
    lo: &[f64],
    hi: &[f64],
    scale: &[f64],
) -> DMatrix<f64> {
    let mut jac = fit.jacobian.select_columns(kept.iter());
    let cols: Vec<Option<Vec<f64>>> = kept
        .par_iter()
        .map(|&k| {
            let v = fit.theta[k];
            let h = COV_FD_STEP * v.abs().max(scale[k]);
            if !(h > 0.0 && v - h >= lo[k] && v + h <= hi[k]) {
                return None;
            }
            let col = fd_column(res, &fit.theta, k, h, FiniteDiff::Central, &[]);
            (col.len() == jac.nrows() && col.iter().all(|x| x.is_finite())).then_some(col)
        })
        .collect();
    for (c, col) in cols.into_iter().enumerate() {
        if let Some(col) = col {
            jac.set_column(c, &DVector::from_vec(col));
        }
    }
    jac
}

fn solver_err(submodel: &'static str, message: impl ToString) -> StepError {
    StepError::Solver {
        submodel,
        message: message.to_string(),
    }
}

/// Sample indices at which a command (u_egr, u_vgt, u_delta) changes.
pub fn step_indices(d: &DynamicData) -> Vec<usize> {
    let cols: Vec<&[f64]> = ["u_egr", "u_vgt", "u_delta"]
        .iter()
        .filter_map(|c| d.get(c))
        .collect();
    (1..d.t.len())
        .filter(|&i| cols.iter().any(|c| c[i] != c[i - 1]))
        .collect()
}

/// Step segments [i0, i1): from each command change to the next one (or the end).
pub fn segments(d: &DynamicData) -> Vec<(usize, usize)> {
    let s = step_indices(d);
    let n = d.t.len();
    s.iter()
        .enumerate()
        .map(|(k, &i0)| (i0, s.get(k + 1).copied().unwrap_or(n)))
        .filter(|(a, b)| b > a)
        .collect()
}

fn mean_of(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Normalized step-response residuals of one output (module documentation), each multiplied
/// by `w`: those within `window` after their step appended to `win`, the later ones (also
/// multiplied by the window's tail weight) to `tail`. `floor`: 1 % of the output's stationary
/// mean.
#[allow(clippy::too_many_arguments)]
fn normalized_residuals(
    t: &[f64],
    meas: &[f64],
    sim: &[f64],
    segs: &[(usize, usize)],
    floor: f64,
    w: f64,
    window: &ResponseWindow,
    win: &mut Vec<f64>,
    tail: &mut Vec<f64>,
) {
    let dt = if t.len() > 1 {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    } else {
        1.0
    };
    let pre = ((0.2 / dt).round() as usize).max(1);
    for &(i0, i1) in segs {
        let a0 = i0.saturating_sub(pre);
        let (m0, s0) = if i0 > a0 {
            (mean_of(&meas[a0..i0]), mean_of(&sim[a0..i0]))
        } else {
            (meas[i0], sim[i0])
        };
        let tail_len = ((i1 - i0) / 5).max(1);
        let (m1, s1) = (
            mean_of(&meas[i1 - tail_len..i1]),
            mean_of(&sim[i1 - tail_len..i1]),
        );
        let amp = (m1 - m0).abs().max(floor);
        let scaled = (s1 - s0).abs() > floor && (m1 - m0).abs() > floor;
        // the simulated response mapped onto the measured one: meas ~ a + b (sim - s0)
        let (a, b) = match window.levels {
            StepLevels::Means => {
                let b = if scaled {
                    ((m1 - m0) / (s1 - s0)).clamp(0.2, 5.0)
                } else {
                    1.0
                };
                (m0, b)
            }
            StepLevels::LeastSquares => level_fit(&meas[i0..i1], &sim[i0..i1], s0, scaled),
        };
        for i in i0..i1 {
            let adj = a + b * (sim[i] - s0);
            let r = w * (meas[i] - adj) / amp;
            if window.contains(t[i] - t[i0]) {
                win.push(r);
            } else {
                tail.push(window.tail_weight * r);
            }
        }
    }
}

/// The offset `a` and gain `b` of `meas ~ a + b (sim - s0)` over one step response by least
/// squares ([`StepLevels::LeastSquares`]); the gain `b` (limited to [0.2, 5] as the
/// [`StepLevels::Means`] scale) only when `scaled`, else 1 (a shift only).
fn level_fit(meas: &[f64], sim: &[f64], s0: f64, scaled: bool) -> (f64, f64) {
    let n = meas.len().max(1) as f64;
    let xm = sim.iter().map(|s| s - s0).sum::<f64>() / n;
    let ym = mean_of(meas);
    let b = if scaled {
        let (sxy, sxx) = meas.iter().zip(sim).fold((0.0, 0.0), |(sxy, sxx), (y, s)| {
            let x = s - s0 - xm;
            (sxy + x * (y - ym), sxx + x * x)
        });
        if sxx > 0.0 {
            (sxy / sxx).clamp(0.2, 5.0)
        } else {
            1.0
        }
    } else {
        1.0
    };
    (ym - b * xm, b)
}

/// How the simulated step response is made to share the measured one's initial and final
/// levels (eq. (75): "each output and each step response is normalized so that the initial and
/// final values for each step response are the same for both the measurements and the
/// simulations").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StepLevels {
    /// The measured levels are means: 0.2 s before the step and the step's last 20 %; the
    /// simulated response is mapped affinely onto them (sessions 1-15). At 100 Hz and 0.5 %
    /// noise the 20-sample initial mean is off by about 0.1 % of the output, a constant error
    /// over the whole step that the volumes absorb: with the true static parameters, step 3 on
    /// nine `mvem lab` campaigns gave V_im -11 to +35 % (docs/tuning.md, session 16).
    Means,
    /// The offset and gain of the affine map fitted by least squares over the whole step
    /// response (variable projection of the two levels per step and output, `level_fit`):
    /// every sample of the step informs the levels, and the residual carries only the shape.
    /// Default (session 16).
    LeastSquares,
}

/// Weights in time of the normalized step responses of step 3 (and of the 12-state step
/// that fits V_ic with them): samples within `seconds` after their command step weigh 1, the
/// later ones `tail_weight`. The default is eq. (75), every sample alike
/// ([`ResponseWindow::UNIFORM`]); [`ResponseWindow::VOLUMES`] (0.5 s, 0.1) puts the weight where
/// the manifolds and the turbo inertia set the response. Measured on nine `mvem lab` campaigns
/// (docs/tuning.md, session 11), the window halves V_em's spread (34 -> 15 %) and V_im's bias,
/// but changes step 5's path: step 5 then stopped earlier on three of them and their
/// validation errors rose (the different engine's p_im on set T 0.45 -> 1.46 % against a
/// noise floor of 0.45 %), so it is an option, not the default.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ResponseWindow {
    /// Length of the fully weighted part after each command step \[s\].
    pub seconds: f64,
    /// Weight of the later samples (1: uniform, as eq. (75)).
    pub tail_weight: f64,
    /// How the simulated levels are matched to the measured ones.
    pub levels: StepLevels,
}

impl ResponseWindow {
    /// Every sample weighs 1, as in eq. (75).
    pub const UNIFORM: Self = Self {
        seconds: f64::INFINITY,
        tail_weight: 1.0,
        levels: StepLevels::LeastSquares,
    };

    /// 0.5 s after each step fully weighted, the rest 0.1 (`mvem tune --step3-window 0.5`).
    pub const VOLUMES: Self = Self {
        seconds: 0.5,
        tail_weight: 0.1,
        levels: StepLevels::LeastSquares,
    };

    /// Whether a sample `since` seconds after its step is in the fully weighted part.
    fn contains(&self, since: f64) -> bool {
        since < self.seconds - 1e-9
    }

    /// Residual blocks of one output of a set, in the order [`normalized_residuals`] writes
    /// them: each step's samples in the window, then each step's later ones. One block per step
    /// because the residuals of a step share its amplitude normalization (so their variance
    /// differs from step to step) and its fitted levels.
    fn blocks(&self, t: &[f64], segs: &[(usize, usize)]) -> Vec<usize> {
        let win: Vec<usize> = segs
            .iter()
            .map(|&(a, b)| (a..b).filter(|&i| self.contains(t[i] - t[a])).count())
            .collect();
        let tail = segs.iter().zip(&win).map(|(&(a, b), w)| b - a - w);
        win.iter().copied().chain(tail).collect()
    }
}

impl Default for ResponseWindow {
    /// [`ResponseWindow::UNIFORM`], eq. (75).
    fn default() -> Self {
        Self::UNIFORM
    }
}

fn count_segment_samples(segs: &[(usize, usize)]) -> usize {
    segs.iter().map(|(a, b)| b - a).sum()
}

fn search_opts(max_eval: usize, scale: Vec<f64>) -> LsqOptions {
    LsqOptions {
        ftol: 1e-6,
        xtol: 1e-6,
        gtol: 1e-8,
        max_evaluations: Some(max_eval),
        x_scale: XScale::Fixed(scale),
        finite_diff: FiniteDiff::Forward,
        fd_rel_step: Some(FD_STEP),
        ..LsqOptions::default()
    }
}

/// Start values and bounds of step 3 (generic, not the published values).
#[derive(Debug, Clone, PartialEq)]
pub struct Step3Start {
    /// Start [V_im [m^3], V_em [m^3], J_t [kg m^2]].
    pub theta: [f64; 3],
    /// Lower bounds.
    pub lo: [f64; 3],
    /// Upper bounds.
    pub hi: [f64; 3],
    /// Floor of the step amplitude in the normalization, as a fraction of the output's
    /// stationary mean (module documentation).
    pub amp_floor: f64,
    /// Weights of the responses in time ([`ResponseWindow`]).
    pub window: ResponseWindow,
    /// Sensor lags of p_im, p_em, W_c, n_t ([`super::sensors`]): held, or the start of their
    /// fit when `fit_lags`.
    pub lags: SensorLags,
    /// Fit the four sensor time constants with V_im, V_em, J_t (bounds [0,
    /// [`MAX_LAG_S`]]).
    pub fit_lags: bool,
}

/// Start of each sensor time constant when step 3 fits them \[s\] (inside Table 6's range, away
/// from the bound 0 so that the first finite differences see both sides).
pub const LAG_START_S: f64 = 0.01;

/// A fitted sensor time constant at most this large \[s\] counts as on its bound 0 (a tenth of a
/// millisecond: nothing 100 Hz data can tell from no lag), see [`fit_dynamic`].
pub const LAG_AT_BOUND_S: f64 = 1e-4;

/// A fitted sensor time constant within this distance \[s\] of [`MAX_LAG_S`] counts as on its
/// upper bound (the step's 2 ms output grid), see [`fit_dynamic`].
pub const LAG_AT_UPPER_S: f64 = 2e-3;

/// Whether a fitted sensor time constant `tau` \[s\] counts as on its upper bound
/// [`MAX_LAG_S`] (within [`LAG_AT_UPPER_S`]).
pub fn lag_at_upper_bound(tau: f64) -> bool {
    tau >= MAX_LAG_S - LAG_AT_UPPER_S
}

impl Default for Step3Start {
    /// Start: both manifolds 38 dm^3 (three displacement volumes of a 12.7 l engine),
    /// J_t = 1e-4 kg m^2; bounds: volumes 2-200 dm^3, J_t 1e-5 - 1e-3 kg m^2. For the
    /// published engine; [`Step3Start::scaled_to`] scales them to another.
    fn default() -> Self {
        Self {
            theta: [0.038, 0.038, 1e-4],
            lo: [0.002, 0.002, 1e-5],
            hi: [0.2, 0.2, 1e-3],
            amp_floor: 0.01,
            window: ResponseWindow::default(),
            lags: SensorLags::NONE,
            fit_lags: false,
        }
    }
}

impl Step3Start {
    /// The start and bounds of V_im, V_em, J_t, given for the published engine (its
    /// displacement [`PUBLISHED_V_D`] and compressor radius [`PUBLISHED_R_C`]), scaled to the
    /// engine of `p`: the volumes by V_d / 12.74 dm^3 (manifolds and intercooler grow with the
    /// displacement), J_t by (R_c / 40 mm)^5 (a wheel's inertia grows with its mass times its
    /// radius squared). The identity, bit for bit, for the published engine. The pipeline
    /// applies it to [`super::pipeline::PipelineOptions::step3`].
    pub fn scaled_to(&self, p: &Params) -> Self {
        let v = p.cylinder.v_d / PUBLISHED_V_D;
        let j = (p.compressor.r_c / PUBLISHED_R_C).powi(5);
        let s = [v, v, j];
        let mut out = self.clone();
        for i in 0..3 {
            out.theta[i] = self.theta[i] * s[i];
            out.lo[i] = self.lo[i] * s[i];
            out.hi[i] = self.hi[i] * s[i];
        }
        out
    }
}

/// Displacement V_d of the published engine \[m^3\] (the engine [`Step3Start::default`] is for).
pub const PUBLISHED_V_D: f64 = 0.01274;

/// Compressor radius R_c of the published engine \[m\] (the engine [`Step3Start::default`] is for).
pub const PUBLISHED_R_C: f64 = 0.04;

/// The stop judgment of a report with the fields `step`, `converged`, `stopped_by`,
/// `rel_offset`, `params`, `n_eval`, `gauss_newton_decrease`, `gauss_newton_t`, `uncertainty`
/// ([`Step5Report`], [`CompleteReport`]): its `stop_note` and `early_stop` ([`SearchStop`]),
/// and `flag_early_stop` of its estimates.
macro_rules! search_end {
    ($report:ty) => {
        impl $report {
            /// How the search stopped, for the judgment of [`SearchStop`].
            fn search_stop(&self) -> SearchStop<'_> {
                SearchStop {
                    step: self.step,
                    converged: self.converged,
                    stopped_by: &self.stopped_by,
                    rel_offset: self.rel_offset,
                    n_params: self.params.len(),
                    n_eval: self.n_eval,
                    gauss_newton_decrease: self.gauss_newton_decrease,
                    gauss_newton_t: self.gauss_newton_t,
                }
            }

            /// A note on where the search stopped when the relative offset R says away from the
            /// least-squares optimum: farther than the noise, or at it within the noise by the
            /// cost measured along the Gauss-Newton step (`SearchStop::stop_note`); `None`
            /// otherwise.
            pub fn stop_note(&self) -> Option<String> {
                self.search_stop().stop_note()
            }

            /// Why the search did not reach its optimum, as a reason for the estimates it gave
            /// (`ParamEstimate::flag_not_converged`): its evaluation limit, or ftol/xtol farther
            /// from the optimum than the noise (`SearchStop::early_stop`). `None` when it
            /// converged.
            pub fn early_stop(&self) -> Option<String> {
                self.search_stop().early_stop()
            }

            /// Flag the estimates (`uncertainty`) as not converged, with [`Self::early_stop`]
            /// as the reason, when the search did not reach its optimum.
            pub fn flag_early_stop(&mut self) {
                if let Some(why) = self.early_stop() {
                    for (_, e) in &mut self.uncertainty {
                        e.flag_not_converged(&why);
                    }
                }
            }
        }
    };
}

/// Report of a complete-model step: fitted parameters, the search statistics and per-output
/// errors (eq. (5), mean and max absolute relative error over the sets used).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompleteReport {
    /// Tuning step: 3, 4, or 7 for the second step of the 12-state model (section 9.2.1), as
    /// the messages name it.
    pub step: u8,
    /// Fitted parameters (name, value).
    pub params: Vec<(String, f64)>,
    /// Per output: (name, mean abs rel error, max abs rel error), unnormalized eq. (5).
    pub errors: Vec<FitReport>,
    /// Cost `0.5 ||r||^2` at the start of the search (as `cost`).
    pub cost_start: f64,
    /// Final cost `0.5 ||r||^2` of the search (r its residuals).
    pub cost: f64,
    /// Residual evaluations (the one at the start and those along the Gauss-Newton step
    /// included).
    pub n_eval: usize,
    /// Whether a convergence test stopped the search.
    pub converged: bool,
    /// Which rule stopped the search ([`super::lsq::Termination::name`]: "relative offset",
    /// "ftol", "xtol", "ftol+xtol", "gtol", "evaluation limit").
    pub stopped_by: String,
    /// Bates-Watts relative offset at the end ([`super::lsq::relative_offset`]).
    pub rel_offset: f64,
    /// As [`Step5Report::gauss_newton_decrease`] (steps 3 and 7; `None`: not measured).
    pub gauss_newton_decrease: Option<f64>,
    /// As [`Step5Report::gauss_newton_t`].
    pub gauss_newton_t: Option<f64>,
    /// Linearized relative standard errors of the parameters at the end of the search, as
    /// [`Step5Report::rel_std_err`] (`sigma^2 (J^T J)^-1` of the search's last Jacobian,
    /// [`LsqResult::stats`], relative to `max(|value|, 1e-3 typical magnitude)`; infinite for
    /// unidentifiable directions). `uncertainty` has the standard errors of the block
    /// covariance at the estimate that the tuning reports.
    pub rel_std_err: Vec<(String, f64)>,
    /// Standard error and identifiability of each fitted parameter ([`super::uncertainty`]).
    pub uncertainty: Vec<(String, ParamEstimate)>,
    /// Sensor lags the step simulated with (fitted when their names are in `params`).
    pub sensor_lags: SensorLags,
    /// Jacobian and covariance at the estimate (not serialized).
    #[serde(skip)]
    pub linearization: Option<Linearization>,
}

search_end!(CompleteReport);

/// Per-output eq. (5) errors of `p` (model `order`) on `sets` (pooled over the sets).
pub(crate) fn output_errors(
    order: ModelOrder,
    p: &Params,
    sets: &[&DynamicData],
    stat: &[StationaryPoint],
    outputs: &[&str],
    tau_me: Option<f64>,
    lags: &SensorLags,
) -> Result<Vec<FitReport>, StepError> {
    let means = stationary_means(stat);
    let sims: Vec<_> = sets
        .par_iter()
        .map(|d| super::validate::simulated_outputs(order, p, d, tau_me, lags, SEARCH_RTOL))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| solver_err("complete model", e))?;
    let mut reps = Vec::new();
    for name in outputs {
        let k = ["p_im", "p_em", "W_c", "n_t", "M_e"]
            .iter()
            .position(|n| n == name)
            .unwrap_or(0);
        let mut e = Vec::new();
        for (d, sim) in sets.iter().zip(&sims) {
            let (Some(meas), Some((_, model))) = (d.get(name), sim.iter().find(|s| s.0 == *name))
            else {
                continue;
            };
            let norm = means[k].unwrap_or_else(|| mean_of(meas));
            e.extend(meas.iter().zip(model).map(|(a, b)| ((a - b) / norm).abs()));
        }
        reps.push(FitReport {
            submodel: name.to_string(),
            params: vec![],
            mean_abs_rel_err: mean_of(&e),
            max_abs_rel_err: e.iter().cloned().fold(0.0, f64::max),
            n_points: e.len(),
            n_eval: 0,
        });
    }
    Ok(reps)
}

/// Step 3: V_im, V_em, J_t by eqs (74)-(75) on the normalized step responses of `sets`
/// (the dynamic-tuning VGT/EGR sets, B and C), starting from `start` (never from `base`).
pub fn step3(
    base: &Params,
    sets: &[&DynamicData],
    stat: &[StationaryPoint],
    start: &Step3Start,
    max_eval: usize,
) -> Result<(Params, CompleteReport), StepError> {
    let mut names = vec!["v_im", "v_em", "j_t"];
    let (mut theta0, mut lo, mut hi) = (start.theta.to_vec(), start.lo.to_vec(), start.hi.to_vec());
    let mut scale = vec![0.02, 0.02, 1e-4];
    let mut max_eval = max_eval;
    if start.fit_lags {
        names.extend(LAG_NAMES);
        for t in start.lags.as_array() {
            theta0.push(if t > 0.0 {
                t.min(MAX_LAG_S)
            } else {
                LAG_START_S
            });
            lo.push(0.0);
            hi.push(MAX_LAG_S);
            scale.push(0.01);
        }
        // the same number of Jacobians as for the three parameters alone
        max_eval = max_eval * (names.len() + 1) / 4;
    }
    let fit = DynamicFit {
        order: ModelOrder::Eight,
        names: &names,
        theta0: &theta0,
        lo: &lo,
        hi: &hi,
        scale: &scale,
        amp_floor: start.amp_floor,
        window: start.window,
        lags: start.lags,
        max_eval,
    };
    let name = if start.fit_lags {
        "step 3 (V_im, V_em, J_t, sensor lags)"
    } else {
        "step 3 (V_im, V_em, J_t)"
    };
    fit_dynamic(name, base, sets, stat, &fit)
}

/// A least-squares problem of the form (74)-(75): named dynamic parameters (names of
/// [`param_mut`]) fitted to the normalized step responses of p_im, p_em, W_c, n_t, simulated
/// with the model `order`.
#[derive(Debug, Clone)]
pub struct DynamicFit<'a> {
    /// Model simulated.
    pub order: ModelOrder,
    /// Parameter names.
    pub names: &'a [&'a str],
    /// Start values.
    pub theta0: &'a [f64],
    /// Lower bounds.
    pub lo: &'a [f64],
    /// Upper bounds.
    pub hi: &'a [f64],
    /// Typical magnitudes (scaling of the search).
    pub scale: &'a [f64],
    /// Floor of the step amplitude (fraction of the stationary mean), see [`Step3Start`].
    pub amp_floor: f64,
    /// Weights of the responses in time.
    pub window: ResponseWindow,
    /// Sensor lags of the simulated outputs; those whose names ([`LAG_NAMES`]) are in `names`
    /// are fitted from these values' positions in `theta0`.
    pub lags: SensorLags,
    /// Limit on residual evaluations.
    pub max_eval: usize,
}

/// Solve a problem of the form (74)-(75) ([`DynamicFit`]) on `sets`, the other parameters
/// from `base`.
pub fn fit_dynamic(
    name: &'static str,
    base: &Params,
    sets: &[&DynamicData],
    stat: &[StationaryPoint],
    f: &DynamicFit,
) -> Result<(Params, CompleteReport), StepError> {
    if sets.is_empty() {
        return Err(StepError::TooFewPoints {
            submodel: name,
            n: 0,
            needed: 1,
        });
    }
    let set_all = |p: &mut Params, lags: &mut SensorLags, th: &[f64]| {
        for (n, v) in f.names.iter().zip(th) {
            if let Some(k) = SensorLags::index(n) {
                lags.set(k, *v);
            } else if let Some(x) = param_mut(p, n) {
                *x = *v;
            }
        }
    };
    let segs: Vec<_> = sets.iter().map(|d| segments(d)).collect();
    let n_res: usize = segs.iter().map(|s| 4 * count_segment_samples(s)).sum();
    if n_res == 0 {
        return Err(solver_err(
            name,
            "the dynamic sets contain no command steps",
        ));
    }
    let res_at = dynamic_residuals(f.order, sets, stat, f.amp_floor, f.window);
    let res = |th: &[f64]| -> Vec<f64> {
        let mut q = base.clone();
        let mut lags = f.lags;
        set_all(&mut q, &mut lags, th);
        res_at(&q, &lags)
    };
    // the cost at the (clamped) start, for the report
    let start: Vec<f64> = f
        .theta0
        .iter()
        .zip(f.lo.iter().zip(f.hi))
        .map(|(v, (l, h))| v.clamp(*l, *h))
        .collect();
    let cost_start = 0.5 * res(&start).iter().map(|r| r * r).sum::<f64>();
    let mut fit = least_squares(
        res,
        f.theta0,
        &Bounds::new(f.lo.to_vec(), f.hi.to_vec()),
        &search_opts(f.max_eval, f.scale.to_vec()),
    )
    .map_err(|e| solver_err(name, e))?;
    fit.n_eval += 1;
    let line = line_when_short(&res, &mut fit, f.lo, f.hi);
    let mut p = base.clone();
    let mut lags = f.lags;
    set_all(&mut p, &mut lags, &fit.theta);
    let errors = output_errors(f.order, &p, sets, stat, &DYN_OUTPUTS, None, &lags)?;
    // residual blocks: each set's outputs (different noise levels and step amplitudes), each
    // in its window and after it (different weights)
    let blocks: Vec<usize> = sets
        .iter()
        .zip(&segs)
        .flat_map(|(d, sg)| f.window.blocks(&d.t, sg).repeat(DYN_OUTPUTS.len()))
        .collect();
    // a sensor lag that ended on its bound 0 (the data see no lag there) or on its upper bound
    // [`MAX_LAG_S`] is held at the bound for the covariance of the others (an active
    // constraint): its column would otherwise carry a variance the bound forbids into every
    // parameter correlated with it
    let at_upper = |k: usize| lag_at_upper_bound(fit.theta[k]);
    let at_bound = |k: usize| {
        SensorLags::index(f.names[k]).is_some() && (fit.theta[k] <= LAG_AT_BOUND_S || at_upper(k))
    };
    let kept: Vec<usize> = (0..f.names.len()).filter(|&k| !at_bound(k)).collect();
    let names: Vec<&str> = kept.iter().map(|&k| f.names[k]).collect();
    let theta: Vec<f64> = kept.iter().map(|&k| fit.theta[k]).collect();
    let jacobian = covariance_jacobian(&res, &fit, &kept, f.lo, f.hi, f.scale);
    let covariance = block_covariance(&jacobian, &fit.residuals, &blocks);
    let step = if f.order == ModelOrder::Twelve { 7 } else { 3 };
    let mut uncertainty = estimates_from_cov(&names, &theta, &covariance, step);
    uncertainty.extend((0..f.names.len()).filter(|&k| at_bound(k)).map(|k| {
        let e = ParamEstimate {
            value: fit.theta[k],
            std_error: f64::INFINITY,
            identifiable: false,
            converged: true,
            correlated_with: Vec::new(),
            reason: if at_upper(k) {
                format!(
                    "at its upper bound {:.0} ms: no test-cell sensor is that slow, so the lag \
                     stands in for something the model gets wrong (it trades with V_im, V_em, \
                     J_t and the static maps; session 24 in docs/tuning.md); held there for the \
                     other parameters' standard errors",
                    MAX_LAG_S * 1e3
                )
            } else {
                "at its bound 0 (the data show no lag of this sensor); held there for the \
                 other parameters' standard errors"
                    .to_string()
            },
            step,
        };
        (f.names[k].to_string(), e)
    }));
    let linearization = Some(Linearization {
        names: names.iter().map(|s| s.to_string()).collect(),
        jacobian,
        covariance,
    });
    Ok((
        p,
        CompleteReport {
            step,
            params: f
                .names
                .iter()
                .zip(&fit.theta)
                .map(|(n, v)| (n.to_string(), *v))
                .collect(),
            errors,
            cost_start,
            cost: fit.cost,
            n_eval: fit.n_eval,
            converged: fit.termination.converged(),
            stopped_by: fit.termination.name().to_string(),
            rel_offset: fit.rel_offset,
            gauss_newton_decrease: line.as_ref().map(|l| l.measured),
            gauss_newton_t: line.as_ref().map(|l| l.t),
            rel_std_err: rel_std_errors(&fit, f.names, &fit.theta, f.scale),
            uncertainty,
            sensor_lags: lags,
            linearization,
        },
    ))
}

/// The residual every row of a data set gets when the set does not simulate (or lacks an
/// output) in the residual functions of steps 3-5 ([`dynamic_residuals`], [`torque_residuals`],
/// [`Cost77::residuals`]): large and finite, so that a search steps back, and exact, so that
/// a linearization can tell a failed evaluation (`uncertainty::sigma_point_jacobian_named`).
pub const FAILED_RESIDUAL: f64 = 10.0;

/// Residuals of a problem of the form (74)-(75) ([`fit_dynamic`]) on `sets` as a function of
/// the whole parameter set: the normalized step responses of p_im, p_em, W_c, n_t of the
/// model `order` seen through the sensor lags given with the parameters (amplitude floor
/// `amp_floor`, [`Step3Start`]), weighted in time by `window`; per set and output those in the
/// window, then the later ones; residuals of 10 (large, finite) when a set does not simulate.
pub fn dynamic_residuals<'a>(
    order: ModelOrder,
    sets: &'a [&'a DynamicData],
    stat: &[StationaryPoint],
    amp_floor: f64,
    window: ResponseWindow,
) -> impl Fn(&Params, &SensorLags) -> Vec<f64> + 'a {
    let means = stationary_means(stat);
    let segs: Vec<_> = sets.iter().map(|d| segments(d)).collect();
    let n_res: usize = segs.iter().map(|s| 4 * count_segment_samples(s)).sum();
    move |q: &Params, lags: &SensorLags| -> Vec<f64> {
        let parts: Vec<Option<Vec<f64>>> = sets
            .par_iter()
            .zip(&segs)
            .map(|(d, sg)| {
                let dt = lags.grid(sample_interval(d));
                let sim = simulate_set(order, q, d, dt, SEARCH_RTOL).ok()?;
                let w = 1.0 / (count_segment_samples(sg).max(1) as f64).sqrt(); // 1/L_j, eq. (75)
                let mut r = Vec::new();
                let mut tail = Vec::new();
                for (k, name) in DYN_OUTPUTS.iter().enumerate() {
                    let meas = d.get(name)?;
                    let s = lags.apply(name, sim.t(), sim.get(name)?);
                    let simv: Vec<f64> = d.t.iter().map(|&t| interp(sim.t(), &s, t)).collect();
                    let floor = amp_floor * means[k].unwrap_or_else(|| mean_of(meas)).abs();
                    tail.clear();
                    normalized_residuals(
                        &d.t, meas, &simv, sg, floor, w, &window, &mut r, &mut tail,
                    );
                    r.extend_from_slice(&tail);
                }
                Some(r)
            })
            .collect();
        let mut out = Vec::with_capacity(n_res);
        for p in parts {
            match p {
                Some(v) => out.extend(v),
                None => return vec![FAILED_RESIDUAL; n_res], // failed simulation: large, finite cost
            }
        }
        out
    }
}

/// M_e of the model on the grid of `set` (at most 10 ms apart, before the dynamometer lag):
/// times \[s\] and torque \[Nm\].
fn simulated_torque(p: &Params, set: &DynamicData) -> Result<(Vec<f64>, Vec<f64>), String> {
    let dt = sample_interval(set).min(0.01);
    let sol = simulate_set(ModelOrder::Eight, p, set, dt, SEARCH_RTOL)?;
    let m_e = sol.get("M_e").ok_or("no M_e")?.to_vec();
    Ok((sol.t().to_vec(), m_e))
}

/// The normalized torque step responses of step 4 (eq. (76)) on a fuel-step set: its measured
/// M_e, its step segments, the amplitude floor (1 % of the stationary mean torque) \[Nm\] and the
/// weight 1/sqrt(L) of the residuals.
struct TorqueSteps<'a> {
    set: &'a DynamicData,
    meas: &'a [f64],
    segs: Vec<(usize, usize)>,
    floor: f64,
    w: f64,
    levels: StepLevels,
}

impl<'a> TorqueSteps<'a> {
    fn new(
        set: &'a DynamicData,
        meas: &'a [f64],
        stat: &[StationaryPoint],
        levels: StepLevels,
    ) -> Self {
        let segs = segments(set);
        let floor = 0.01
            * stationary_means(stat)[4]
                .unwrap_or_else(|| mean_of(meas))
                .abs();
        let w = 1.0 / (count_segment_samples(&segs).max(1) as f64).sqrt();
        Self {
            set,
            meas,
            segs,
            floor,
            w,
            levels,
        }
    }

    /// Residuals of the model torque `m_e` at times `ts` (before the lag) through the
    /// dynamometer lag tau_Me = `tau` \[s\], eq. (76), sampled at the set's times.
    fn residuals(&self, ts: &[f64], m_e: &[f64], tau: f64) -> Vec<f64> {
        let f = first_order_lag(ts, m_e, tau);
        let sim: Vec<f64> = self.set.t.iter().map(|&t| interp(ts, &f, t)).collect();
        let mut r = Vec::with_capacity(count_segment_samples(&self.segs));
        normalized_residuals(
            &self.set.t,
            self.meas,
            &sim,
            &self.segs,
            self.floor,
            self.w,
            // eq. (76): every sample alike
            &ResponseWindow {
                levels: self.levels,
                ..ResponseWindow::UNIFORM
            },
            &mut r,
            &mut Vec::new(),
        );
        r
    }
}

/// The residuals of step 4 (eq. (76)) with tau_Me = `tau` fixed, as a function of the whole
/// parameter set (for the uncertainty of the parameters step 4 holds fixed): the normalized
/// torque step responses of `set` through the dynamometer lag; residuals of 10 (large, finite)
/// when the set does not simulate or has no M_e. `levels`: as in step 4.
pub fn torque_residuals<'a>(
    set: &'a DynamicData,
    stat: &[StationaryPoint],
    tau: f64,
    levels: StepLevels,
) -> impl Fn(&Params) -> Vec<f64> + 'a {
    let n_res = count_segment_samples(&segments(set));
    let steps = set
        .get("M_e")
        .filter(|m| m.len() == set.t.len())
        .map(|meas| TorqueSteps::new(set, meas, stat, levels));
    move |q: &Params| -> Vec<f64> {
        let fit = steps
            .as_ref()
            .and_then(|st| Some((st, simulated_torque(q, set).ok()?)));
        match fit {
            Some((st, (ts, m_e))) => st.residuals(&ts, &m_e, tau),
            None => vec![FAILED_RESIDUAL; n_res],
        }
    }
}

/// Step 4: tau_Me of eq. (76) on the normalized torque step responses of `set` (the fuel-step
/// set I, 10 Hz), K = 1, J = 1. The engine states do not depend on tau_Me: the set is simulated
/// once and the simulated M_e filtered for each trial value. Start 0.3 s, bounds 0.005-20 s.
/// `levels`: how the simulated torque steps share the measured levels ([`StepLevels`]).
pub fn step4(
    p: &Params,
    set: &DynamicData,
    stat: &[StationaryPoint],
    levels: StepLevels,
) -> Result<(f64, CompleteReport), StepError> {
    const NAME: &str = "step 4 (tau_Me)";
    let meas = set.get("M_e").ok_or(StepError::MissingColumn {
        set: set.name.clone(),
        column: "M_e",
    })?;
    let steps = TorqueSteps::new(set, meas, stat, levels);
    if steps.segs.is_empty() {
        return Err(solver_err(NAME, "the torque set contains no command steps"));
    }
    let (ts, m_e) = simulated_torque(p, set).map_err(|e| solver_err(NAME, e))?;
    let res = |th: &[f64]| steps.residuals(&ts, &m_e, th[0]);
    let opts = LsqOptions {
        fd_rel_step: Some(1e-6),
        ..search_opts(200, vec![0.3])
    };
    let cost_start = 0.5 * res(&[0.3]).iter().map(|r| r * r).sum::<f64>();
    let fit = least_squares(res, &[0.3], &Bounds::new(vec![0.005], vec![20.0]), &opts)
        .map_err(|e| solver_err(NAME, e))?;
    let tau = fit.theta[0];
    let errors = output_errors(
        ModelOrder::Eight,
        p,
        &[set],
        stat,
        &["M_e"],
        Some(tau),
        &SensorLags::NONE,
    )?;
    let uncertainty = estimates(
        &["tau_me"],
        &fit.theta,
        &[0.3],
        &fit.jacobian,
        &fit.residuals,
        4,
    );
    let linearization = Some(Linearization {
        names: vec!["tau_me".into()],
        jacobian: fit.jacobian.clone(),
        covariance: block_covariance(&fit.jacobian, &fit.residuals, &[]),
    });
    Ok((
        tau,
        CompleteReport {
            step: 4,
            params: vec![("tau_me".into(), tau)],
            errors,
            cost_start,
            cost: fit.cost,
            n_eval: fit.n_eval,
            converged: fit.termination.converged(),
            stopped_by: fit.termination.name().to_string(),
            rel_offset: fit.rel_offset,
            gauss_newton_decrease: None,
            gauss_newton_t: None,
            rel_std_err: rel_std_errors(&fit, &["tau_me"], &fit.theta, &[0.3]),
            uncertainty,
            sensor_lags: SensorLags::NONE,
            linearization,
        },
    ))
}

/// One static parameter of step 5: name, bounds (used by eq. (78) and the search) and a typical
/// magnitude (scaling of the search).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticParam {
    /// Name (as in the step-1 reports).
    pub name: &'static str,
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// Typical magnitude.
    pub scale: f64,
}

const fn sp(name: &'static str, lo: f64, hi: f64, scale: f64) -> StaticParam {
    StaticParam {
        name,
        lo,
        hi,
        scale,
    }
}

/// The static parameters theta of eq. (77) with their bounds (our choice: physically plausible
/// boxes wide enough for a 6-cylinder heavy-duty engine; the paper does not list its bounds).
/// Step 5 widens a box that excludes the step-1 estimate ([`bounds_containing`]), except for
/// the physical bounds ([`PHYSICAL_BOUNDS`]).
/// The torque parameters are not in theta (paper section 8.1: M_e is not in y_k, z_n).
pub const STATIC_PARAMS: [StaticParam; 35] = [
    sp("c_vol1", -0.01, 0.01, 1e-4),
    sp("c_vol2", -0.1, 0.1, 1e-3),
    sp("c_vol3", 0.0, 3.0, 1.0),
    sp("eta_sc", 0.5, 1.5, 1.0),
    sp("x_cv", 0.0, 1.0, 0.1),
    sp("h_tot", 1.0, 500.0, 100.0),
    sp("pi_egropt", 0.05, 0.99, 0.5),
    sp("c_egr1", -1e-3, -1e-8, 1e-4), // < 0: parameter validation (eq. (38))
    sp("c_egr2", -0.1, 0.1, 1e-2),
    sp("c_egr3", -1.0, 1.0, 0.1),
    sp("eta_tmmax", 0.3, 1.0, 0.8),
    sp("bsr_opt", 0.3, 1.5, 1.0),
    sp("c_m1", 0.0, 10.0, 1.0),
    sp("c_m2", 0.0, 2796.0, 1000.0), // upper bound replaced by 0.999 w_tlin, static_bounds
    sp("c_m3", 0.001, 3.0, 0.1),
    sp("k_t", 0.1, 10.0, 1.0),
    sp("c_f1", 0.0, 5.0, 1.0),
    sp("c_f2", -2.0, 2.0, 1.0),
    sp("c_vgt1", 50.0, 300.0, 100.0),
    sp("c_vgt2", 50.0, 300.0, 100.0),
    sp("eta_cmax", 0.3, 1.0, 0.7),
    sp("w_copt", 0.0, 2.0, 0.3),
    sp("pi_copt", 0.0, 5.0, 1.0),
    sp("c_pi", 0.05, 3.0, 0.3),
    sp("a1", 0.0, 100.0, 1.0),
    sp("a2", 0.0, 100.0, 1.0),
    sp("a3", -100.0, 100.0, 1.0),
    sp("c_psi2", -1.0, 1.0, 0.1),
    sp("c_phi2", -0.1, 0.1, 0.01),
    sp("c_wpsi1", -1e-5, 1e-5, 1e-8),
    sp("c_wpsi2", -0.1, 0.1, 1e-4),
    sp("c_wpsi3", -100.0, 100.0, 1.0),
    sp("c_wphi1", -1e-5, 1e-5, 1e-8),
    sp("c_wphi2", -0.1, 0.1, 1e-3),
    sp("c_wphi3", -100.0, 100.0, 10.0),
];

/// k_ic of eq. (86) [Pa^2 s^2/(K kg^2)], the additional static parameter of the 12-state model
/// (section 9.2.1, third step). Bounds: pressure drops from ~0.1 kPa to ~600 kPa at rated flow
/// (default 1.9e7 gives 12.5 kPa, docs/extensions.md).
pub const K_IC_PARAM: StaticParam = sp("k_ic", 1e5, 1e9, 1e7);

/// theta of eq. (77) for the model `order`: [`STATIC_PARAMS`], plus [`K_IC_PARAM`] for 12 states.
pub fn static_params(order: ModelOrder) -> Vec<StaticParam> {
    let mut v = STATIC_PARAMS.to_vec();
    if order == ModelOrder::Twelve {
        v.push(K_IC_PARAM);
    }
    v
}

/// theta of eq. (77) with the bounds that depend on the engine: c_m2 below 0.999 w_tlin of its
/// fixed constants (the authors' linear c_m branch starts at w_tlin > c_m2, item 33; the same
/// bound as step 1), the boxes of the scale-dependent parameters widened to the campaign's
/// measured `scale` ([`CampaignScale::apply`]; the published engine's campaigns keep
/// [`STATIC_PARAMS`]), all others as in [`STATIC_PARAMS`].
pub fn static_bounds(base: &Params, order: ModelOrder, scale: &CampaignScale) -> Vec<StaticParam> {
    let mut v: Vec<StaticParam> = static_params(order)
        .into_iter()
        .map(|s| scale.apply(s))
        .collect();
    for s in v.iter_mut() {
        if s.name == "c_m2" {
            s.hi = 0.999 * base.turbine.w_tlin;
        }
    }
    v
}

/// Parameters of theta of eq. (77) whose bounds are physical (the model's or the parameter
/// file's validity: x_cv in [0, 1], Pi_egropt < 1, c_egr1 < 0, efficiencies <= 1, c_m2 <
/// w_tlin, c_m3 > 0, K_t > 0, c_Pi > 0, Q_c positive semidefinite, k_ic > 0). The bounds of the
/// others are plausibility boxes ([`bounds_containing`]).
pub const PHYSICAL_BOUNDS: [&str; 12] = [
    "x_cv",
    "pi_egropt",
    "c_egr1",
    "eta_tmmax",
    "c_m2",
    "c_m3",
    "k_t",
    "eta_cmax",
    "c_pi",
    "a1",
    "a2",
    "k_ic",
];

/// The bounds of step 5 for the start `theta0` (the step-1 estimates): a plausibility box (not
/// in [`PHYSICAL_BOUNDS`]) that excludes the start is widened to contain it with a margin of
/// |start| (or the typical magnitude for a start of 0). The compressor-flow ellipse (c_Psi2,
/// c_Phi2 and the polynomials (69)-(70)) is flat along directions where these parameters trade
/// off, so step 1 can land anywhere along them (e.g. c_Phi2 = -0.7 on an engine with
/// c_Phi2 = 0): clamping the start into the box would break the fit that step 1 found.
pub fn bounds_containing(mut list: Vec<StaticParam>, theta0: &[f64]) -> Vec<StaticParam> {
    for (s, &v) in list.iter_mut().zip(theta0) {
        if PHYSICAL_BOUNDS.contains(&s.name) || !v.is_finite() {
            continue;
        }
        let margin = if v != 0.0 { v.abs() } else { s.scale };
        if v <= s.lo {
            s.lo = v - margin;
        }
        if v >= s.hi {
            s.hi = v + margin;
        }
    }
    list
}

/// Mutable reference to a tunable parameter by name: its symbol (the names of
/// [`STATIC_PARAMS`], the step-2 and step-3 names, `c_vol1`, `a3`, ...) or its path
/// (`cylinder.c_vol[1]`), from the parameter registry ([`Params::get_mut`]).
pub fn param_mut<'a>(p: &'a mut Params, name: &str) -> Option<&'a mut f64> {
    p.get_mut(name)
}

/// Value of a tunable parameter by name (see [`param_mut`]).
pub fn param_value(p: &Params, name: &str) -> Option<f64> {
    p.get(name)
}

/// theta of eq. (77) from a parameter set.
pub fn static_theta(p: &Params) -> Vec<f64> {
    theta_of(&STATIC_PARAMS, p)
}

/// Values of the parameters `list` in `p`.
pub fn theta_of(list: &[StaticParam], p: &Params) -> Vec<f64> {
    list.iter()
        .map(|s| param_value(p, s.name).unwrap_or(f64::NAN))
        .collect()
}

/// Write theta of eq. (77) into a parameter set: Q_c projected on the PSD cone (a3 symmetric),
/// c_mlin tied to c_m1 (w_tlin - c_m2)^c_m3 as in step 1.
pub fn set_static_theta(p: &mut Params, th: &[f64]) {
    set_theta_of(&STATIC_PARAMS, p, th)
}

/// Write the values `th` of the parameters `list` (see [`set_static_theta`]).
pub fn set_theta_of(list: &[StaticParam], p: &mut Params, th: &[f64]) {
    let names: Vec<&str> = list.iter().map(|s| s.name).collect();
    set_named(p, &names, th)
}

/// Write the values `th` of the parameters `names` ([`param_mut`] names) with the ties of
/// [`set_static_theta`] (Q_c symmetric and projected, c_mlin tied to c_m1).
pub fn set_named(p: &mut Params, names: &[&str], th: &[f64]) {
    for (n, v) in names.iter().zip(th) {
        if let Some(x) = param_mut(p, n) {
            *x = *v;
        }
    }
    let k = &mut p.compressor;
    k.q_c[1][0] = k.q_c[0][1];
    k.q_c = project_q_c(k.q_c);
    let t = &mut p.turbine;
    t.c_mlin = t.c_m[0] * (t.w_tlin - t.c_m[1]).max(0.0).powf(t.c_m[2]);
}

/// The naive initialization of eq. (78) from the bounds of [`STATIC_PARAMS`].
pub fn naive_theta() -> Vec<f64> {
    STATIC_PARAMS
        .iter()
        .map(|s| {
            if s.hi < 1.0 {
                s.hi
            } else if s.lo <= 1.0 {
                1.0
            } else {
                s.lo
            }
        })
        .collect()
}

/// Options of step 5 (cost (77)).
#[derive(Debug, Clone, PartialEq)]
pub struct Step5Options {
    /// beta of eq. (77) (weight 1/beta of the submodel row).
    pub beta: f64,
    /// gamma_j by data-set name (1 for sets not listed); paper: G 2, H 4.
    pub gammas: Vec<(String, f64)>,
    /// Include the first row (complete-model dynamic errors).
    pub dynamic_row: bool,
    /// Include the second row (submodel errors).
    pub static_row: bool,
    /// Sample rate of the dynamic terms \[Hz\] (paper: 10 Hz; sets sampled slower stay as they are).
    pub sample_hz: f64,
    /// Limit on cost evaluations (finite differences included). Default 3600 = 100 (n + 1)
    /// for the n = 35 static parameters: 100 finite-difference Jacobians, half the general
    /// default of [`super::lsq::LsqOptions`] (was 600 until the Jacobian columns ran in
    /// parallel; `mvem lab` seeds 2 and 4 need 1814 and 1161, docs/tuning.md).
    pub max_evaluations: usize,
    /// Most consecutive Broyden updates of the finite-difference Jacobian of (77) between two
    /// recomputations ([`super::lsq::LsqOptions::broyden_updates`]; 0, the default: none, a new
    /// Jacobian, n = 35 evaluations, after every accepted step). Measured on `mvem lab` seeds
    /// 1, 2, 4 with 4: no fewer evaluations to convergence (docs/tuning.md).
    pub broyden_updates: usize,
    /// Tolerance of the Bates-Watts relative offset stopping rule
    /// ([`super::lsq::relative_offset`]; 0: off, only ftol/xtol/gtol and the limit stop the
    /// search). Default [`STEP5_REL_OFFSET_TOL`] (docs/tuning.md, "Session 9").
    pub rel_offset_tol: f64,
    /// Most restarts of the search (a new central-difference Jacobian and trust region from
    /// where it stopped) when ftol or xtol stopped it with the relative offset above
    /// `rel_offset_tol` and [`STEP5_RESTART_REL_OFFSET`], i.e. far from the optimum; each
    /// restart is kept only when it lowers the cost. Default [`STEP5_RESTARTS`].
    pub restarts: usize,
    /// Model of the first row. With 12 states theta gets k_ic and the second row z_8 = W_ic
    /// (N = 8, section 9.2.1).
    pub model: ModelOrder,
    /// Further measured compressor flow points of the W_c submodel in the second row, besides
    /// the stationary points: the settled ends of the dynamic sets' holds that step 1's flow
    /// fit used ([`super::settled::flow_points`]; empty by default). Each submodel's term is
    /// then its mean over its own points (`1/(beta N M_n)`; eq. (77) when every M_n = M).
    pub flow_points: Vec<super::steps::FlowPoint>,
    /// Sensor lags of p_im, p_em, W_c, n_t in the first row ([`super::sensors`]; held, as
    /// step 3 tuned them). Default none.
    pub sensor_lags: SensorLags,
}

/// Default [`Step5Options::rel_offset_tol`]: `1 / sqrt(35)` for the 35 static parameters, so
/// the search stops when the Gauss-Newton step would lower cost (77) by less than one residual
/// variance (`||Q_1^T r||^2 = R^2 p s^2 < s^2`): the linearized optimum is then within one
/// standard error of the stopping point in the metric of the Gauss-Newton covariance (every
/// parameter within one of its standard errors). Bates and Watts' 0.001 was never reached on
/// `mvem lab` seed 1 (the offset stayed at 0.36 when xtol stopped, docs/tuning.md).
pub const STEP5_REL_OFFSET_TOL: f64 = 0.169;

impl Default for Step5Options {
    fn default() -> Self {
        Self {
            beta: 1.0,
            gammas: vec![("G".into(), 2.0), ("H".into(), 4.0)],
            dynamic_row: true,
            static_row: true,
            sample_hz: 10.0,
            max_evaluations: 3600,
            broyden_updates: 0,
            rel_offset_tol: STEP5_REL_OFFSET_TOL,
            restarts: STEP5_RESTARTS,
            model: ModelOrder::Eight,
            flow_points: Vec::new(),
            sensor_lags: SensorLags::NONE,
        }
    }
}

/// The cost function (77), ready to evaluate for any parameter set.
pub struct Cost77 {
    base: Params,
    stat: Vec<StationaryPoint>,
    sets: Vec<(DynamicData, f64)>,
    norms: [f64; 4],
    opts: Step5Options,
    list: Vec<StaticParam>,
    n_res: usize,
    /// Points of the W_c row when `opts.flow_points` is not empty: the stationary points, then
    /// those ([`steps::flow_points_with`]); empty otherwise (W_c on the stationary points).
    w_c_points: Vec<steps::FlowPoint>,
}

/// Subsample a set to at most `hz` (every k-th sample).
fn subsample(d: &DynamicData, hz: f64) -> DynamicData {
    let dt = sample_interval(d);
    let k = ((1.0 / hz) / dt).round().max(1.0) as usize;
    let idx: Vec<usize> = (0..d.t.len()).step_by(k).collect();
    DynamicData {
        name: d.name.clone(),
        t: idx.iter().map(|&i| d.t[i]).collect(),
        columns: d
            .columns
            .iter()
            .map(|(n, v)| (n.clone(), idx.iter().map(|&i| v[i]).collect()))
            .collect(),
    }
}

impl Cost77 {
    /// Build the cost from the stationary points and the static-tuning sets.
    pub fn new(
        base: &Params,
        stat: &[StationaryPoint],
        sets: &[&DynamicData],
        opts: &Step5Options,
    ) -> Self {
        let m = stationary_means(stat);
        let norms = std::array::from_fn(|k| m[k].unwrap_or(1.0));
        let sets: Vec<(DynamicData, f64)> = sets
            .iter()
            .map(|d| {
                let g = opts
                    .gammas
                    .iter()
                    .find(|(n, _)| *n == d.name)
                    .map_or(1.0, |g| g.1);
                (subsample(d, opts.sample_hz), g)
            })
            .collect();
        let mut c = Self {
            base: base.clone(),
            stat: stat.to_vec(),
            sets,
            norms,
            opts: opts.clone(),
            list: static_params(opts.model),
            n_res: 0,
            w_c_points: if opts.flow_points.is_empty() {
                Vec::new()
            } else {
                steps::flow_points_with(stat, &opts.flow_points)
            },
        };
        c.n_res = c.dyn_len() + c.stat_len();
        c
    }

    fn dyn_len(&self) -> usize {
        if self.opts.dynamic_row {
            self.sets.iter().map(|(d, _)| 4 * d.t.len()).sum()
        } else {
            0
        }
    }

    /// N of eq. (77): 7 submodels, 8 with W_ic for the 12-state model.
    fn n_z(&self) -> usize {
        if self.opts.model == ModelOrder::Twelve {
            8
        } else {
            7
        }
    }

    fn stat_len(&self) -> usize {
        if self.opts.static_row {
            self.n_z() * self.stat.len() + self.opts.flow_points.len()
        } else {
            0
        }
    }

    /// Points of each submodel in the second row (order of [`steps::fit_series`] without M_e,
    /// then W_ic): M, and M plus the further flow points for W_c (the seventh).
    fn submodel_points(&self) -> Vec<usize> {
        let mut m = vec![self.stat.len(); self.n_z()];
        m[6] += self.opts.flow_points.len();
        m
    }

    /// Lengths of the residual blocks in the order of [`Cost77::residuals`]: per data set its four
    /// outputs, then per submodel its stationary points.
    pub fn blocks(&self) -> Vec<usize> {
        let mut b = Vec::new();
        if self.opts.dynamic_row {
            for (d, _) in &self.sets {
                b.extend(std::iter::repeat_n(d.t.len(), DYN_OUTPUTS.len()));
            }
        }
        if self.opts.static_row {
            b.extend(self.submodel_points());
        }
        b
    }

    /// Residual blocks of the covariance ([`super::uncertainty::block_covariance`]): per data set
    /// and output one block (AR(1) inflation), every submodel residual its own block (a
    /// variance per stationary point: the derived measurements of eq. (4) are heteroscedastic,
    /// e.g. eta_c,meas of eq. (58) divides by T_c - T_amb, a few kelvin at light load).
    pub fn covariance_blocks(&self) -> Vec<usize> {
        let mut b = Vec::new();
        if self.opts.dynamic_row {
            for (d, _) in &self.sets {
                b.extend(std::iter::repeat_n(d.t.len(), DYN_OUTPUTS.len()));
            }
        }
        if self.opts.static_row {
            b.extend(std::iter::repeat_n(1, self.stat_len()));
        }
        b
    }

    /// Per residual (the order of [`Cost77::residuals`]) whether it belongs to a data set not
    /// named in `without` (the stationary rows always do).
    pub fn rows_without(&self, without: &[String]) -> Vec<bool> {
        let mut k = Vec::with_capacity(self.n_res);
        if self.opts.dynamic_row {
            for (d, _) in &self.sets {
                let kept = !without.contains(&d.name);
                k.extend(std::iter::repeat_n(kept, DYN_OUTPUTS.len() * d.t.len()));
            }
        }
        k.resize(self.n_res, true);
        k
    }

    /// Number of residuals.
    pub fn len(&self) -> usize {
        self.n_res
    }

    /// Whether there are no residuals.
    pub fn is_empty(&self) -> bool {
        self.n_res == 0
    }

    /// Parameter set for theta.
    pub fn params(&self, th: &[f64]) -> Params {
        let mut q = self.base.clone();
        set_theta_of(&self.list, &mut q, th);
        q
    }

    /// Residuals r with V(theta) = sum r^2 (eq. (77)); a failed simulation gives residuals of 10
    /// (finite, large) for its set.
    pub fn residuals(&self, th: &[f64]) -> Vec<f64> {
        self.residuals_at(&self.params(th))
    }

    /// Residuals of (77) at the whole parameter set `q` (see [`Cost77::residuals`]).
    pub fn residuals_at(&self, q: &Params) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.n_res);
        if self.opts.dynamic_row {
            let k_j = (4 * self.sets.len()) as f64;
            let parts: Vec<Vec<f64>> = self
                .sets
                .par_iter()
                .map(|(d, g)| {
                    let w = g / (k_j * d.t.len() as f64).sqrt();
                    let fail = vec![FAILED_RESIDUAL; 4 * d.t.len()];
                    let lags = &self.opts.sensor_lags;
                    let dt = lags.grid(sample_interval(d));
                    let Ok(sim) = simulate_set(self.opts.model, q, d, dt, SEARCH_RTOL) else {
                        return fail;
                    };
                    let mut r = Vec::with_capacity(4 * d.t.len());
                    for (k, name) in DYN_OUTPUTS.iter().enumerate() {
                        let (Some(meas), Some(s)) = (d.get(name), sim.get(name)) else {
                            return fail;
                        };
                        let s = lags.apply(name, sim.t(), s);
                        for (i, &t) in d.t.iter().enumerate() {
                            r.push(w * (meas[i] - interp(sim.t(), &s, t)) / self.norms[k]);
                        }
                    }
                    r
                })
                .collect();
            for p in parts {
                out.extend(p);
            }
        }
        if self.opts.static_row {
            match steps::fit_series(q, &self.stat) {
                Ok(mut series) => {
                    if self.opts.model == ModelOrder::Twelve {
                        // z_8 = W_ic (section 9.2.1): eq. (86) against the measured W_c
                        let (meas, model) = super::twelve::w_ic_series(q, &self.stat);
                        series.push(("W_ic".into(), meas, model));
                    }
                    for (name, meas, model) in series.iter_mut().filter(|s| s.0 != "M_e") {
                        if name == "W_c" && !self.w_c_points.is_empty() {
                            // the stationary points and the further flow points (step 1's fit)
                            (*meas, *model) = steps::w_c_flow_series(q, &self.w_c_points);
                        }
                        // 1 / (beta N M_n): each submodel's mean over its points
                        let w = 1.0 / (self.opts.beta * (self.n_z() * meas.len()) as f64).sqrt();
                        let mm = mean_of(meas);
                        out.extend(
                            meas.iter()
                                .zip(model.iter())
                                .map(|(a, b)| w * (a - b) / mm)
                                .map(|r| if r.is_finite() { r } else { 10.0 }),
                        );
                    }
                }
                Err(_) => out.extend(std::iter::repeat_n(10.0, self.stat_len())),
            }
        }
        out.resize(self.n_res, 10.0);
        out
    }

    /// V(theta) of eq. (77).
    pub fn cost(&self, th: &[f64]) -> f64 {
        self.residuals(th).iter().map(|r| r * r).sum()
    }
}

/// Report of step 5.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step5Report {
    /// Tuning step: 5, or 8 for the third step of the 12-state model (section 9.2.1; option
    /// `model` of [`Step5Options`]), as the messages name it.
    pub step: u8,
    /// Fitted static parameters (name, value).
    pub params: Vec<(String, f64)>,
    /// Cost (77) at the start and at the end.
    pub cost_start: f64,
    /// Final cost.
    pub cost_end: f64,
    /// Evaluations of (77) (finite differences included).
    pub n_eval: usize,
    /// Iterations (trust-region steps) of the search.
    pub n_iter: usize,
    /// Finite-difference Jacobians of (77) computed (n evaluations each; the others of the
    /// iterations were Broyden updates, [`Step5Options::broyden_updates`]).
    pub n_jacobians: usize,
    /// Whether a convergence test stopped the search.
    pub converged: bool,
    /// Which rule stopped the search ([`super::lsq::Termination::name`]: "relative offset",
    /// "ftol", "xtol", "ftol+xtol", "gtol", "evaluation limit").
    pub stopped_by: String,
    /// Bates-Watts relative offset at the end ([`super::lsq::relative_offset`]).
    pub rel_offset: f64,
    /// When ftol or xtol stopped the search with `R^2 p` above 1 (`R` the relative offset, `p`
    /// parameters: the Gauss-Newton step from the end point predicts a decrease of (77) of
    /// more than one residual variance): the largest decrease of (77) measured along that step
    /// at [`STEP5_LINE_FRACTIONS`] of it ([`super::lsq::gauss_newton_line`]), in residual
    /// variances (negative: it rose at each). Below 1 the search stopped at its optimum within
    /// the noise and its estimates are not flagged. `None`: not measured.
    pub gauss_newton_decrease: Option<f64>,
    /// The fraction of the Gauss-Newton step where [`Step5Report::gauss_newton_decrease`] was
    /// measured.
    pub gauss_newton_t: Option<f64>,
    /// Data sets left out of a first pass of step 5 because the model at its start oscillated on
    /// them where the engine does not (`PipelineOptions::stage_oscillating`); this report is
    /// the second pass, on every set, from the first pass's result (its evaluations, iterations
    /// and Jacobians included in the counts). Empty: one pass.
    pub first_pass_without: Vec<String>,
    /// Evaluations of that first pass and the rule that stopped it (as `stopped_by`); 0 and
    /// empty for one pass.
    pub first_pass_evaluations: usize,
    /// See [`Step5Report::first_pass_evaluations`].
    pub first_pass_stopped_by: String,
    /// Sets that simulate at step 5's start but not at the first pass's result (no stable
    /// steady start, a failed solve); when not empty the first pass was discarded and this
    /// report's pass started from step 5's start (the first pass's evaluations still counted).
    pub first_pass_discarded_for: Vec<String>,
    /// Data sets whose rows were left out of the linearization behind the standard errors
    /// because the tuned model oscillates on them where the engine does not: a limit cycle's
    /// phase moves with every parameter, so those rows of the finite-difference Jacobian are
    /// noise, large enough to pass for information (standard errors too small). Empty: every set.
    pub linearized_without: Vec<String>,
    /// What the standard errors do not cover, in words: step 8's are conditional on the
    /// parameters it holds fixed (the pipeline's `run_static_step`); `None` for step 5, whose
    /// standard errors carry the uncertainty of those parameters.
    pub uncertainty_note: Option<String>,
    /// Restarts of the search that lowered the cost after ftol/xtol stopped it away from the
    /// optimum ([`Step5Options::restarts`]).
    pub restarts: usize,
    /// Submodel errors (eq. (4)) after step 5.
    pub submodels: Vec<FitReport>,
    /// Complete-model errors (eq. (5)) on the sets of the cost, per output.
    pub dynamic: Vec<FitReport>,
    /// Wall time of one evaluation of (77) \[s\] (measured at the start value).
    pub eval_seconds: f64,
    /// Parameters at a bound at the end.
    pub at_bounds: Vec<String>,
    /// Linearized relative standard errors of the parameters (identifiability; infinite for
    /// unidentifiable directions).
    pub rel_std_err: Vec<(String, f64)>,
    /// Standard error and identifiability of each parameter ([`super::uncertainty`]).
    pub uncertainty: Vec<(String, ParamEstimate)>,
    /// Jacobian and covariance at the estimate (not serialized).
    #[serde(skip)]
    pub linearization: Option<Linearization>,
}

#[cfg(test)]
impl Step5Report {
    /// A report of `n` parameters p0, p1, ... (all 1) stopped by `stopped_by` at relative
    /// offset `rel_offset`, one pass, no linearization (unit tests).
    pub(crate) fn for_tests(n: usize, stopped_by: &str, rel_offset: f64) -> Self {
        Self {
            step: 5,
            params: (0..n).map(|k| (format!("p{k}"), 1.0)).collect(),
            cost_start: 2.0,
            cost_end: 1.0,
            n_eval: 10,
            n_iter: 2,
            n_jacobians: 2,
            converged: true,
            stopped_by: stopped_by.into(),
            rel_offset,
            gauss_newton_decrease: None,
            gauss_newton_t: None,
            first_pass_without: Vec::new(),
            first_pass_evaluations: 0,
            first_pass_stopped_by: String::new(),
            first_pass_discarded_for: Vec::new(),
            linearized_without: Vec::new(),
            uncertainty_note: None,
            restarts: 0,
            submodels: Vec::new(),
            dynamic: Vec::new(),
            eval_seconds: 0.01,
            at_bounds: Vec::new(),
            rel_std_err: Vec::new(),
            uncertainty: Vec::new(),
            linearization: None,
        }
    }
}

impl Step5Report {
    /// What a two-pass step 5 did ([`Step5Report::first_pass_without`]): the sets its first
    /// pass left out, how that pass ended, and whether the second pass started from its result
    /// or, when it was discarded ([`Step5Report::first_pass_discarded_for`]), from step 5's
    /// start. `None` for one pass.
    pub fn passes_note(&self) -> Option<String> {
        if self.first_pass_without.is_empty() {
            return None;
        }
        // the model the search starts from: after steps 1-4 (step 5), or steps 1-7 (step 8)
        let before = if self.step == 8 { "1-7" } else { "1-4" };
        let first = format!(
            "the model after steps {before} oscillates on set(s) {} where the engine does not, so \
             a first pass left them out ({} evaluations, stopped by: {})",
            self.first_pass_without.join(", "),
            self.first_pass_evaluations,
            self.first_pass_stopped_by
        );
        let step = self.step;
        Some(if self.first_pass_discarded_for.is_empty() {
            format!(
                "step {step} ran in two passes: {first}, and the second, on every set, started \
                 from its result (counts include both)"
            )
        } else {
            format!(
                "step {step}'s first pass was discarded: {first}, but set(s) {} no longer \
                 simulate at its result, so step {step} ran on every set from its start (counts \
                 include both)",
                self.first_pass_discarded_for.join(", ")
            )
        })
    }
}

search_end!(Step5Report);

/// How the search of a tuning step stopped (steps 5 and 8: [`Step5Report`]; steps 3, 4 and 7:
/// [`CompleteReport`]): the one judgment of whether it reached its optimum, for the reports'
/// notes and the estimates' `converged` flag.
struct SearchStop<'a> {
    /// Tuning step (1-5; 6-8 the 12-state steps), for the messages.
    step: u8,
    /// Whether a convergence test stopped the search.
    converged: bool,
    /// The rule that stopped it ([`super::lsq::Termination::name`]).
    stopped_by: &'a str,
    /// Bates-Watts relative offset at the end.
    rel_offset: f64,
    /// Parameters of the search.
    n_params: usize,
    /// Residual evaluations.
    n_eval: usize,
    /// Decrease of the cost measured along the Gauss-Newton step, in residual variances.
    gauss_newton_decrease: Option<f64>,
    /// The fraction of the Gauss-Newton step where it was measured.
    gauss_newton_t: Option<f64>,
}

impl SearchStop<'_> {
    /// How far the search stopped from the least-squares optimum when that exceeds the noise:
    /// a rule other than the relative offset or gtol stopped it with the Bates-Watts relative
    /// offset R above `1/sqrt(p)` (p parameters), so the Gauss-Newton step from the end point
    /// predicts a cost decrease of `R^2 p` residual variances and the estimate may lie up to
    /// `R sqrt(p)` standard errors (in the Gauss-Newton metric) from the optimum. Returns
    /// (`R^2 p`, `R sqrt(p)`); `None` otherwise.
    fn predicted_distance(&self) -> Option<(f64, f64)> {
        predicted_distance(self.stopped_by, self.rel_offset, self.n_params)
    }

    /// [`SearchStop::predicted_distance`] unless the decrease measured along the
    /// Gauss-Newton step ([`Step5Report::gauss_newton_decrease`]) is below one residual
    /// variance: then the search stopped at its optimum within the noise (session 39: the
    /// residuals' curvature in the flat directions of (77), which `J^T J` leaves out, makes
    /// the cost rise along the step where R predicted 4-109 residual variances).
    fn distance_to_optimum(&self) -> Option<(f64, f64)> {
        let d = self.predicted_distance()?;
        match self.gauss_newton_decrease {
            Some(measured) if measured < 1.0 => None,
            _ => Some(d),
        }
    }

    /// What the cost measured along the Gauss-Newton step says of a stop R calls short
    /// ("relative offset 3.800 predicts 505.4 residual variances, measured along the
    /// Gauss-Newton step at most 0.02 (t = 0.01)"); `None` when not measured.
    fn measured_line(&self) -> Option<String> {
        let (variances, _) = self.predicted_distance()?;
        let (measured, t) = (self.gauss_newton_decrease?, self.gauss_newton_t?);
        let at_most = if measured > 0.0 {
            format!("at most {} (t = {t})", variances_text(measured))
        } else {
            format!(
                "no decrease (the cost rose at each t, least by {})",
                variances_text(-measured)
            )
        };
        Some(format!(
            "relative offset {:.3} predicts {variances:.1} residual variances, measured along \
             the Gauss-Newton step {at_most}",
            self.rel_offset
        ))
    }

    /// A note on where the search stopped when R says away from the least-squares optimum
    /// (`predicted_distance`): farther than the noise by the decrease measured
    /// along the Gauss-Newton step, or R's prediction alone (not measured), which the reported
    /// standard errors do not include; or, when the measured decrease is below one residual
    /// variance, that it stopped at its optimum within the noise. `None` otherwise.
    fn stop_note(&self) -> Option<String> {
        let (variances, ses) = self.predicted_distance()?;
        if self.distance_to_optimum().is_none() {
            return Some(format!(
                "step {} stopped ({}) at its optimum within the noise: {}, below one residual \
                 variance ({} parameters)",
                self.step,
                self.stopped_by,
                self.measured_line()?,
                self.n_params,
            ));
        }
        let measured = self
            .measured_line()
            .map(|m| format!("; {m}"))
            .unwrap_or_default();
        Some(format!(
            "step {} stopped ({}) before its optimum: the Gauss-Newton step from its end point \
             predicts a cost decrease of {variances:.1} residual variances (relative offset {:.3}, \
             {} parameters), so the estimate may lie up to {ses:.1} standard errors from the \
             least-squares optimum; the standard errors do not include that distance{measured}",
            self.step, self.stopped_by, self.rel_offset, self.n_params,
        ))
    }

    /// Why the search did not reach its optimum, as a reason for the estimates it gave
    /// (`ParamEstimate::flag_not_converged`): stopped at its evaluation limit (`converged`
    /// false), or by ftol/xtol farther from the optimum than the noise
    /// (`distance_to_optimum`, with the decrease measured along the Gauss-Newton step when it
    /// was). `None` when it converged.
    fn early_stop(&self) -> Option<String> {
        if !self.converged {
            return Some(format!(
                "step {} stopped at its evaluation limit before converging, after {} evaluations",
                self.step, self.n_eval
            ));
        }
        let (_, ses) = self.distance_to_optimum()?;
        let measured = match (self.gauss_newton_decrease, self.gauss_newton_t) {
            (Some(d), Some(t)) => {
                format!(
                    "; measured along the Gauss-Newton step: {} residual variances at t = {t}",
                    variances_text(d)
                )
            }
            _ => String::new(),
        };
        Some(format!(
            "step {} stopped ({}) before its optimum (relative offset {:.3}: up to {ses:.1} \
             standard errors from it, not in the standard errors{measured})",
            self.step, self.stopped_by, self.rel_offset
        ))
    }
}

/// A number of residual variances with two decimals, or two digits in scientific notation
/// below 0.01 (`0.02`, `5.25`, `1.5e-3`).
fn variances_text(x: f64) -> String {
    if x != 0.0 && x.abs() < 0.01 {
        format!("{x:.1e}")
    } else {
        format!("{x:.2}")
    }
}

/// The fractions of the Gauss-Newton step at which step 5 measures the cost when it stopped
/// by ftol/xtol with `R^2 p > 1` ([`Step5Report::gauss_newton_decrease`]).
pub const STEP5_LINE_FRACTIONS: [f64; 4] = [1.0, 0.1, 0.01, 0.001];

/// (`R^2 p`, `R sqrt(p)`) of a search stopped by `stopped_by` at relative offset `r` with `p`
/// parameters when a rule other than the relative offset or gtol stopped it with `R^2 p > 1`
/// ([`Step5Report::predicted_distance`]); `None` otherwise.
fn predicted_distance(stopped_by: &str, r: f64, p: usize) -> Option<(f64, f64)> {
    let p = p as f64;
    let by_noise = matches!(stopped_by, "relative offset" | "gtol");
    if by_noise || !r.is_finite() || p < 1.0 || r * r * p <= 1.0 {
        return None;
    }
    Some((r * r * p, r * p.sqrt()))
}

/// The relative standard errors of a search's end ([`LsqResult::stats`]) by parameter name:
/// standard error over `max(|value|, 1e-3 scale)` (`values` the estimates, `scale` the
/// typical magnitudes).
fn rel_std_errors(
    fit: &LsqResult,
    names: &[&str],
    values: &[f64],
    scale: &[f64],
) -> Vec<(String, f64)> {
    let stats = fit.stats();
    names
        .iter()
        .zip(values)
        .zip(scale.iter().zip(&stats.std_err))
        .map(|((n, v), (s, e))| (n.to_string(), e / v.abs().max(s * 1e-3)))
        .collect()
}

/// The cost along the Gauss-Newton step from the end of `fit` ([`gauss_newton_line`] at
/// [`STEP5_LINE_FRACTIONS`], `res` the search's residuals, `lo`, `hi` its box) when ftol or
/// xtol stopped it with the relative offset R saying it is short of its optimum
/// ([`predicted_distance`]; session 39 found the cost rising along the step where R promised a
/// decrease); its evaluations (four) are added to `fit.n_eval`. `None` otherwise.
fn line_when_short(
    res: impl FnMut(&[f64]) -> Vec<f64>,
    fit: &mut LsqResult,
    lo: &[f64],
    hi: &[f64],
) -> Option<GaussNewtonLine> {
    if !fit.termination.converged()
        || predicted_distance(fit.termination.name(), fit.rel_offset, fit.theta.len()).is_none()
    {
        return None;
    }
    let line = gauss_newton_line(
        res,
        &fit.theta,
        &fit.jacobian,
        &fit.residuals,
        &Bounds::new(lo.to_vec(), hi.to_vec()),
        &STEP5_LINE_FRACTIONS,
    )?;
    fit.n_eval += line.n_eval;
    Some(line)
}

/// The box step 5 searches from `theta0` on `base` and the stationary points `stat`
/// ([`static_bounds`] at their [`CampaignScale`], widened to contain the start,
/// [`bounds_containing`]), in the order of its parameters.
pub fn step5_bounds(
    base: &Params,
    stat: &[StationaryPoint],
    theta0: &[f64],
    opts: &Step5Options,
) -> Vec<StaticParam> {
    let scale = CampaignScale::of(base, stat);
    bounds_containing(static_bounds(base, opts.model, &scale), theta0)
}

/// Step 5: minimize (77) over the static parameters from `theta0` (the step-1 values, or eq.
/// (78)), with the bounds of [`static_params`] (the start clipped into them; with the 12-state
/// model `theta0` ends with k_ic).
pub fn step5(
    base: &Params,
    stat: &[StationaryPoint],
    sets: &[&DynamicData],
    theta0: &[f64],
    opts: &Step5Options,
) -> Result<(Params, Step5Report), StepError> {
    const NAME: &str = "step 5 (cost (77))";
    if opts.static_row && stat.len() < 8 {
        return Err(StepError::TooFewPoints {
            submodel: NAME,
            n: stat.len(),
            needed: 8,
        });
    }
    let cost = Cost77::new(base, stat, sets, opts);
    if cost.is_empty() {
        return Err(solver_err(
            NAME,
            "no residuals (no data sets and no stationary row)",
        ));
    }
    let list = step5_bounds(base, stat, theta0, opts);
    let lo: Vec<f64> = list.iter().map(|s| s.lo).collect();
    let hi: Vec<f64> = list.iter().map(|s| s.hi).collect();
    let th0: Vec<f64> = theta0
        .iter()
        .zip(lo.iter().zip(&hi))
        .map(|(v, (l, h))| {
            let m = 1e-9 * (h - l);
            v.clamp(l + m, h - m)
        })
        .collect();
    let t0 = std::time::Instant::now();
    let cost_start = cost.cost(&th0);
    let eval_seconds = t0.elapsed().as_secs_f64();
    let scale: Vec<f64> = list.iter().map(|s| s.scale).collect();
    // the finite-difference columns in parallel (each evaluation also runs its data sets in
    // parallel): the same search, evaluation by evaluation, as `least_squares`
    let search = |from: &[f64], budget: usize, fd: FiniteDiff| {
        least_squares_par(
            |th: &[f64]| cost.residuals(th),
            from,
            &Bounds::new(lo.clone(), hi.clone()),
            &LsqOptions {
                broyden_updates: opts.broyden_updates,
                rel_offset_tol: opts.rel_offset_tol,
                finite_diff: fd,
                ..search_opts(budget, scale.clone())
            },
        )
        .map_err(|e| solver_err(NAME, e))
    };
    let mut fit: LsqResult = search(&th0, opts.max_evaluations, FiniteDiff::Forward)?;
    let (mut attempts, mut restarts) = (0, 0);
    // ftol/xtol stopped the search where the Gauss-Newton step still predicts a decrease of
    // more than one residual variance (relative offset above its tolerance): the trust region
    // had collapsed on failed steps, not at the optimum. Restart from there (a new Jacobian,
    // the initial trust radius) while that lowers the cost
    while attempts < opts.restarts
        && opts.rel_offset_tol > 0.0
        && fit.rel_offset > opts.rel_offset_tol.max(STEP5_RESTART_REL_OFFSET)
        && matches!(
            fit.termination,
            Termination::Xtol | Termination::Ftol | Termination::FtolAndXtol
        )
        && fit.n_eval + 2 * (th0.len() + 1) < opts.max_evaluations
    {
        attempts += 1;
        // central differences: where the forward-difference model failed (seed 5 of
        // docs/tuning.md, session 11: a forward restart did not lower the cost, a central one
        // did)
        let again = search(
            &fit.theta,
            opts.max_evaluations - fit.n_eval,
            FiniteDiff::Central,
        )?;
        let better = again.cost < fit.cost * (1.0 - 1e-9);
        let (n_eval, n_iter, n_jac) = (
            fit.n_eval + again.n_eval,
            fit.n_iter + again.n_iter,
            fit.n_jac + again.n_jac,
        );
        if better {
            fit = again;
            restarts += 1;
        }
        fit.n_eval = n_eval;
        fit.n_iter = n_iter;
        fit.n_jac = n_jac;
        if !better {
            break;
        }
    }
    let line = line_when_short(|th: &[f64]| cost.residuals(th), &mut fit, &lo, &hi);
    let p = cost.params(&fit.theta);
    let theta = theta_of(&list, &p);
    let at_bounds = list
        .iter()
        .zip(&theta)
        .filter(|(s, v)| {
            (**v - s.lo).abs() <= 1e-6 * (s.hi - s.lo) || (**v - s.hi).abs() <= 1e-6 * (s.hi - s.lo)
        })
        .map(|(s, _)| s.name.to_string())
        .collect();
    let names: Vec<&str> = list.iter().map(|s| s.name).collect();
    let all: Vec<usize> = (0..list.len()).collect();
    fit.jacobian = covariance_jacobian(&|th| cost.residuals(th), &fit, &all, &lo, &hi, &scale);
    let covariance = block_covariance(&fit.jacobian, &fit.residuals, &cost.covariance_blocks());
    let step = if opts.model == ModelOrder::Twelve {
        8
    } else {
        5
    };
    let uncertainty = estimates_from_cov(&names, &theta, &covariance, step);
    let linearization = Some(Linearization {
        names: names.iter().map(|s| s.to_string()).collect(),
        jacobian: fit.jacobian.clone(),
        covariance,
    });
    let rel_std_err = rel_std_errors(&fit, &names, &theta, &scale);
    let mut submodels: Vec<FitReport> = super::validate::stationary_errors(&p, stat)?
        .into_iter()
        .map(|o| FitReport {
            submodel: o.output,
            params: vec![],
            mean_abs_rel_err: o.mean_abs_rel_err,
            max_abs_rel_err: o.max_abs_rel_err,
            n_points: o.n,
            n_eval: 0,
        })
        .collect();
    if opts.model == ModelOrder::Twelve {
        let (meas, model) = super::twelve::w_ic_series(&p, stat);
        let (mean, max) = steps::rel_errors(&meas, &model);
        submodels.push(FitReport {
            submodel: "W_ic".into(),
            params: vec![],
            mean_abs_rel_err: mean,
            max_abs_rel_err: max,
            n_points: meas.len(),
            n_eval: 0,
        });
    }
    // empty when the final parameters cannot be simulated (reported, not an error here)
    let dynamic = if sets.is_empty() {
        vec![]
    } else {
        output_errors(
            opts.model,
            &p,
            sets,
            stat,
            &DYN_OUTPUTS,
            None,
            &opts.sensor_lags,
        )
        .unwrap_or_default()
    };
    Ok((
        p,
        Step5Report {
            step,
            params: list
                .iter()
                .zip(&theta)
                .map(|(s, v)| (s.name.to_string(), *v))
                .collect(),
            cost_start,
            // the solver's cost is 0.5 ||r||^2; (77) and `cost_start` are ||r||^2
            cost_end: 2.0 * fit.cost,
            n_eval: fit.n_eval,
            n_iter: fit.n_iter,
            n_jacobians: fit.n_jac,
            converged: fit.termination.converged(),
            stopped_by: fit.termination.name().to_string(),
            rel_offset: fit.rel_offset,
            gauss_newton_decrease: line.as_ref().map(|l| l.measured),
            gauss_newton_t: line.as_ref().map(|l| l.t),
            first_pass_without: Vec::new(),
            first_pass_evaluations: 0,
            first_pass_stopped_by: String::new(),
            first_pass_discarded_for: Vec::new(),
            linearized_without: Vec::new(),
            uncertainty_note: None,
            restarts,
            submodels,
            dynamic,
            eval_seconds,
            at_bounds,
            rel_std_err,
            uncertainty,
            linearization,
        },
    ))
}

/// Sets of a campaign with a role (manifest order).
pub fn sets_with_role<'a>(
    infos: &'a [DataSetInfo],
    data: &'a [DynamicData],
    role: Role,
    vgt_egr_only: bool,
) -> Vec<&'a DynamicData> {
    infos
        .iter()
        .zip(data)
        .filter(|(i, _)| i.roles.contains(&role))
        .filter(|(i, _)| !vgt_egr_only || i.kind == super::data::StepKind::VgtEgr)
        .map(|(_, d)| d)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_responses_are_weighted_in_their_window_by_hand() {
        // 10 Hz, steps at samples 3 and 10 (segments [3, 10) and [10, 14)); measured 0 before
        // the first step, 1 after it; the model is the measurement plus 0.1 on two samples
        let t: Vec<f64> = (0..14).map(|i| i as f64 * 0.1).collect();
        let meas: Vec<f64> = (0..14).map(|i| if i < 3 { 0.0 } else { 1.0 }).collect();
        let mut sim = meas.clone();
        sim[4] += 0.1; // 0.1 s after the first step: in the window
        sim[6] += 0.1; // 0.3 s after it: after the window
        let segs = [(3, 10), (10, 14)];
        let window = ResponseWindow {
            seconds: 0.25,
            tail_weight: 0.1,
            levels: StepLevels::Means,
        };
        // in the window: 0, 0.1, 0.2 s after each step; per step, the window then the rest
        assert_eq!(window.blocks(&t, &segs), [3, 3, 4, 1]);
        assert_eq!(ResponseWindow::UNIFORM.blocks(&t, &segs), [7, 4, 0, 0]);
        let (mut win, mut tail) = (Vec::new(), Vec::new());
        normalized_residuals(
            &t, &meas, &sim, &segs, 0.01, 2.0, &window, &mut win, &mut tail,
        );
        // initial and final levels agree (0 and 1), amplitude 1, weight 2
        let expect_win = [0.0, -0.2, 0.0, 0.0, 0.0, 0.0];
        let expect_tail = [0.1 * -0.2, 0.0, 0.0, 0.0, 0.0];
        assert_eq!((win.len(), tail.len()), (6, 5));
        for (a, b) in win
            .iter()
            .zip(expect_win)
            .chain(tail.iter().zip(expect_tail))
        {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}: {win:?} {tail:?}");
        }
        // uniform (eq. (75)): everything in the first list, unweighted
        let (mut all, mut none) = (Vec::new(), Vec::new());
        let u = ResponseWindow {
            levels: StepLevels::Means,
            ..ResponseWindow::UNIFORM
        };
        normalized_residuals(&t, &meas, &sim, &segs, 0.01, 2.0, &u, &mut all, &mut none);
        assert!(none.is_empty());
        assert!((all[1] + 0.2).abs() < 1e-12 && (all[3] + 0.2).abs() < 1e-12);
    }

    #[test]
    fn least_squares_levels_by_hand() {
        // meas = 2 + 3 (sim - s0) exactly: offset 2, gain 3, whatever s0
        let sim = [1.0, 1.0, 1.5, 2.0, 2.0];
        let meas: Vec<f64> = sim.iter().map(|s| 2.0 + 3.0 * (s - 1.0)).collect();
        let (a, b) = level_fit(&meas, &sim, 1.0, true);
        assert!(
            (a - 2.0).abs() < 1e-12 && (b - 3.0).abs() < 1e-12,
            "{a} {b}"
        );
        // shift only: the mean difference, gain 1
        // mean(sim - s0) = 0.5, mean(meas) = 2 + 3 * 0.5 = 3.5: a = 3.5 - 0.5
        let (a, b) = level_fit(&meas, &sim, 1.0, false);
        assert!((a - 3.0).abs() < 1e-12 && b == 1.0, "{a} {b}");
        // the gain is limited as the means' scale is; a flat response keeps gain 1
        let (_, b) = level_fit(&[0.0, 0.0, 10.0, 20.0, 20.0], &sim, 1.0, true);
        assert_eq!(b, 5.0);
        let (a, b) = level_fit(&[1.0, 2.0, 3.0], &[4.0, 4.0, 4.0], 4.0, true);
        assert!((a - 2.0).abs() < 1e-12 && b == 1.0, "{a} {b}");
        // in the residuals: a measured response that is the simulated one with other levels
        // leaves no residual, however noisy its pre-step samples are (which the means use)
        let t: Vec<f64> = (0..14).map(|i| i as f64 * 0.1).collect();
        let sim: Vec<f64> = (0..14)
            .map(|i| {
                if i < 3 {
                    0.0
                } else {
                    1.0 - (-(i as f64 - 2.0)).exp()
                }
            })
            .collect();
        let mut meas: Vec<f64> = sim.iter().map(|s| 5.0 + 2.0 * s).collect();
        meas[1] += 0.3; // noise before the step
        let segs = [(3, 14)];
        let (mut r, mut tail) = (Vec::new(), Vec::new());
        normalized_residuals(
            &t,
            &meas,
            &sim,
            &segs,
            0.01,
            1.0,
            &ResponseWindow::UNIFORM,
            &mut r,
            &mut tail,
        );
        assert_eq!(r.len(), 11);
        assert!(r.iter().all(|x| x.abs() < 1e-12), "{r:?}");
        // the means of sessions 1-15 carry that noise into every residual of the step
        let means = ResponseWindow {
            levels: StepLevels::Means,
            ..ResponseWindow::UNIFORM
        };
        r.clear();
        normalized_residuals(&t, &meas, &sim, &segs, 0.01, 1.0, &means, &mut r, &mut tail);
        assert!(r.iter().any(|x| x.abs() > 1e-2), "{r:?}");
    }

    fn report(stopped_by: &str, rel_offset: f64) -> Step5Report {
        Step5Report::for_tests(35, stopped_by, rel_offset)
    }

    #[test]
    fn a_two_pass_step_5_says_which_start_the_second_pass_took() {
        assert!(report("xtol", 0.1).passes_note().is_none());
        let mut r = report("xtol", 0.1);
        r.first_pass_without = vec!["A".into()];
        r.first_pass_evaluations = 3600;
        r.first_pass_stopped_by = "evaluation limit".into();
        let kept = r.passes_note().expect("a note");
        assert!(kept.starts_with("step 5 ran in two passes"), "{kept}");
        assert!(kept.contains("set(s) A"), "{kept}");
        assert!(
            kept.contains("(3600 evaluations, stopped by: evaluation limit)"),
            "{kept}"
        );
        assert!(kept.contains("started from its result"), "{kept}");
        r.first_pass_discarded_for = vec!["A".into(), "D".into()];
        let gone = r.passes_note().expect("a note");
        assert!(
            gone.starts_with("step 5's first pass was discarded"),
            "{gone}"
        );
        assert!(gone.contains("set(s) A, D no longer simulate"), "{gone}");
        assert!(gone.contains("from its start"), "{gone}");
        assert!(!gone.contains("started from its result"), "{gone}");
        // step 8 (the same machinery, session 43) names itself and its start
        r.step = 8;
        let gone = r.passes_note().expect("a note");
        assert!(
            gone.starts_with("step 8's first pass was discarded: the model after steps 1-7"),
            "{gone}"
        );
        assert!(gone.contains("so step 8 ran on every set"), "{gone}");
        r.first_pass_discarded_for.clear();
        let kept = r.passes_note().expect("a note");
        assert!(kept.starts_with("step 8 ran in two passes"), "{kept}");
    }

    #[test]
    fn a_step_5_stopped_away_from_its_optimum_says_how_far() {
        // xtol at R = 1.68 (mvem lab --seed 5): R^2 p = 98.8 residual variances, R sqrt(p) = 9.9
        let note = report("xtol", 1.68).stop_note().expect("a note");
        assert!(note.contains("(xtol)"), "{note}");
        assert!(note.contains("98.8 residual variances"), "{note}");
        assert!(note.contains("up to 9.9 standard errors"), "{note}");
        // stopped by the noise criteria, or within one residual variance: no note
        assert!(report("relative offset", 0.15).stop_note().is_none());
        assert!(report("gtol", 2.0).stop_note().is_none());
        assert!(report("ftol", 0.16).stop_note().is_none()); // R^2 p = 0.90
        assert!(report("ftol", 0.17).stop_note().is_some()); // 1.01
        assert!(report("evaluation limit", f64::NAN).stop_note().is_none());
    }

    /// Session 39: R = 3.8 on 35 parameters predicts 505 residual variances, but along the
    /// Gauss-Newton step the cost fell by at most 0.02 of one (the campaigns measured: 1e-4 to
    /// 0.05): the stop is at the optimum within the noise, a note, no flag. A measured decrease
    /// above one residual variance keeps R's flag and names it.
    #[test]
    fn a_stop_r_calls_short_is_judged_by_the_cost_along_the_gauss_newton_step() {
        let mut r = report("xtol", 3.8);
        // R alone (not measured): stopped short
        assert!(r.early_stop().is_some());
        r.gauss_newton_decrease = Some(0.02);
        r.gauss_newton_t = Some(0.01);
        assert_eq!(r.early_stop(), None);
        assert_eq!(
            r.stop_note().as_deref(),
            Some(
                "step 5 stopped (xtol) at its optimum within the noise: relative offset 3.800 \
                 predicts 505.4 residual variances, measured along the Gauss-Newton step at most \
                 0.02 (t = 0.01), below one residual variance (35 parameters)"
            )
        );
        // the cost rose at every t
        r.gauss_newton_decrease = Some(-1.5e-3);
        r.gauss_newton_t = Some(0.001);
        assert_eq!(r.early_stop(), None);
        let note = r.stop_note().expect("a note");
        assert!(
            note.contains("no decrease (the cost rose at each t, least by 1.5e-3)"),
            "{note}"
        );
        // a real decrease: flagged, with the measured figure
        r.gauss_newton_decrease = Some(5.25);
        r.gauss_newton_t = Some(0.1);
        assert_eq!(
            r.early_stop().as_deref(),
            Some(
                "step 5 stopped (xtol) before its optimum (relative offset 3.800: up to 22.5 \
                 standard errors from it, not in the standard errors; measured along the \
                 Gauss-Newton step: 5.25 residual variances at t = 0.1)"
            )
        );
        let note = r.stop_note().expect("a note");
        assert!(note.contains("before its optimum"), "{note}");
        assert!(note.ends_with("measured along the Gauss-Newton step at most 5.25 (t = 0.1)"));
        // exactly one residual variance is not within the noise; the evaluation limit is
        // flagged whatever was measured
        r.gauss_newton_decrease = Some(1.0);
        assert!(r.early_stop().is_some());
        r.gauss_newton_decrease = Some(0.02);
        r.converged = false;
        r.stopped_by = "evaluation limit".into();
        assert!(r
            .early_stop()
            .expect("flagged")
            .contains("evaluation limit"));
    }

    #[test]
    fn steps_7_and_8_are_judged_as_step_5_and_named() {
        // step 8 (the 12-state step 5, 36 parameters): xtol at R = 3.8, R sqrt(p) = 22.8
        let mut r8 = Step5Report {
            step: 8,
            gauss_newton_decrease: Some(5.25),
            gauss_newton_t: Some(0.1),
            ..Step5Report::for_tests(36, "xtol", 3.8)
        };
        let why = r8.early_stop().expect("flagged");
        let head = "step 8 stopped (xtol) before its optimum (relative offset 3.800: up to 22.8";
        assert!(why.starts_with(head), "{why}");
        r8.gauss_newton_decrease = Some(0.02);
        assert_eq!(r8.early_stop(), None);
        let note = r8.stop_note().expect("a note");
        assert!(
            note.starts_with("step 8 stopped (xtol) at its optimum within the noise"),
            "{note}"
        );
        // step 7 (4 parameters): ftol at R = 0.9 predicts R^2 p = 3.24 residual variances,
        // up to R sqrt(p) = 1.8 standard errors; not measured: flagged by R
        let mut r7 = CompleteReport {
            step: 7,
            params: ["v_ic", "v_im", "v_em", "j_t"]
                .iter()
                .map(|n| (n.to_string(), 1.0))
                .collect(),
            errors: Vec::new(),
            cost_start: 2.0,
            cost: 1.0,
            n_eval: 30,
            converged: true,
            stopped_by: "ftol".into(),
            rel_offset: 0.9,
            gauss_newton_decrease: None,
            gauss_newton_t: None,
            rel_std_err: Vec::new(),
            uncertainty: Vec::new(),
            sensor_lags: SensorLags::NONE,
            linearization: None,
        };
        assert_eq!(
            r7.early_stop().as_deref(),
            Some(
                "step 7 stopped (ftol) before its optimum (relative offset 0.900: up to 1.8 \
                 standard errors from it, not in the standard errors)"
            )
        );
        assert!(r7.stop_note().unwrap().contains("3.2 residual variances"));
        // measured below one residual variance: at its optimum within the noise
        r7.gauss_newton_decrease = Some(0.3);
        r7.gauss_newton_t = Some(0.01);
        assert_eq!(r7.early_stop(), None);
        // R^2 p below 1 (R = 0.45: 0.81): no note
        r7.rel_offset = 0.45;
        assert_eq!(r7.stop_note(), None);
        // the evaluation limit
        r7.converged = false;
        r7.stopped_by = "evaluation limit".into();
        assert_eq!(
            r7.early_stop().as_deref(),
            Some("step 7 stopped at its evaluation limit before converging, after 30 evaluations")
        );
    }
}
