//! How well each tuned parameter is known: linearized (Gauss-Newton) standard errors at the
//! optimum of the step that tuned it, and an identifiability flag with its reason.
//!
//! For a step with residuals r (m) and Jacobian J = dr/dtheta (m x n, parameter units) at the
//! optimum the covariance is `Cov = s^2 (J^T J)^-1` ([`super::lsq::param_stats`], pseudo-inverse
//! over the numerically identifiable subspace) with the residual variance
//! `s^2 = ||r||^2 / (m - n)`. Two corrections keep it honest:
//!
//! * **Rows of different noise levels and correlated residuals.** The residuals are split in
//!   blocks (per data set and output, per submodel); the covariance is the sandwich
//!   `(J^T J)^-1 J^T S J (J^T J)^-1` with `S` the block's mean square residual times the AR(1)
//!   variance-inflation factor `(1 + rho) / (1 - rho)`, rho the block's lag-1 autocorrelation
//!   (samples of a dynamic response are not independent; 0 for white noise, limited to
//!   [0, 0.98]) ([`block_covariance`]).
//! * **Identifiability.** A parameter is reported identifiable when its standard error is
//!   finite, its relative standard error `se / |value|` is at most
//!   [`MAX_REL_STD_ERR`] (25 %) and no other parameter of the same step correlates with it by more
//!   than [`MAX_CORRELATION`] in absolute value. The reason is stated ("rel. std. error 290 %",
//!   "correlation 0.998 with c_m3", "not in the column space of J (singular value 0)").
//! * **Parameters a step holds fixed.** Steps 3, 4 and 5 hold the estimates of the earlier
//!   steps fixed (step 3 the static and actuator parameters, step 4 those and V_im, V_em, J_t,
//!   step 5 the actuators, V_im, V_em, J_t);
//!   their errors move the step's optimum. With the step's Jacobian J, the Jacobian J_f of its
//!   residuals with respect to the fixed parameters and their covariance C_f (from the steps
//!   that estimated them, [`NamedCov`]), the sensitivity of the optimum is `dtheta/dphi = -S`,
//!   `S = (J^T J)^+ J^T J_f`, and the reported covariance is `Cov + S C_f S^T` ([`with_fixed`]).
//!   J_f by forward differences at the estimate ([`fd_jacobian_named`]; or along the principal
//!   axes of C_f, [`sigma_point_jacobian_named`], [`FixedJacobian`]). The pipeline carries
//!   the full covariance of every step forward (cross-covariances between steps neglected), so step 3 after step 5 carries
//!   the static parameters' uncertainty, and step 5 that of the first step-3 pass, which in
//!   turn carries that of step 1.
//! * **Step 5 and the repeated step 3 jointly.** The first step 5 runs on the V_im, V_em, J_t
//!   of the first step-3 pass (on the step-1 static parameters; rel. std. errors 100-270 % on
//!   `mvem lab` seed 2), so chained, its covariance carries theirs and the repeated step 3
//!   receives it back through the static parameters (seed 2, step 5 converged: step-5 standard
//!   errors 10-100 times their own, V_im 720 %). That is right for a result that depends on
//!   the first pass, but the linear propagation of the first pass's flat directions (volumes on
//!   the step-1 static parameters) explodes. With `PipelineOptions::joint_uncertainty` (`mvem
//!   tune --joint-uncertainty true`; off by default, see docs/tuning.md, session 9) the
//!   pipeline runs a second round (step 5 on the repeated step 3's volumes, then step 3
//!   again), whose result is, to first order, the fixed point of the alternation and no longer
//!   depends on the first pass, and reports both steps with their joint covariance there
//!   ([`joint_covariance`]).
//! * **A search stopped by its evaluation limit** (step 5 on `mvem lab` seeds 2 and 4 with the
//!   former limit of 600 evaluations) reports the covariance at its end point and says
//!   `converged: false`; the pipeline then flags step 5's parameters, as it does where ftol or
//!   xtol stopped step 5 far from its optimum (the Bates-Watts relative offset,
//!   [`super::complete::Step5Report::early_stop`]), and the parameters of steps 3-4 repeated on
//!   such a step 5's static maps (`converged: false`, never identifiable). Adding the remaining
//!   Gauss-Newton step as a bias (`Cov + delta delta^T`) was tried and rejected: in the flat
//!   directions of cost (77) that step is 1e3-1e7 times the parameters and flagged everything.
//! * **eta_tm in the T_c domain.** Step 1 fits eta_tm to the compressor temperature rise it
//!   implies, and the submodel row of step 5 compares it so ([`super::steps::fit_series`]). Its
//!   step-1 covariance is still that of the unweighted residuals in efficiency units (the
//!   estimator the paper's step 1 uses, less efficient, so the standard error is conservative).
//! * `correlated_with` lists the parameters with |correlation| > [`LIST_CORRELATION`].
//!
//! The estimate of a parameter tuned by several steps is that of the last one (step 5 replaces
//! the step-1 values of the static parameters; the dynamics steps 3-4 repeated after step 5
//! replace steps 3-4).

use super::complete::{param_value, set_named, FAILED_RESIDUAL, STATIC_PARAMS};
use super::data::{DynamicData, StationaryPoint};
use super::lsq::{param_stats, FiniteDiff, ParamStats};
use super::steps::{
    actuator_response, flow_points_with, submodel_series, w_c_flow_series, FlowPoint, Step1Report,
};
use crate::params::Params;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Largest relative standard error of an identifiable parameter.
pub const MAX_REL_STD_ERR: f64 = 0.25;
/// Largest |correlation| with another parameter of the same step of an identifiable parameter.
pub const MAX_CORRELATION: f64 = 0.99;
/// Correlations above this (absolute) are listed in `correlated_with`.
pub const LIST_CORRELATION: f64 = 0.95;

/// How well one tuned parameter is known.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamEstimate {
    /// Tuned value (units of the parameter file).
    pub value: f64,
    /// Linearized standard error (same units); infinite when not determined by the data.
    pub std_error: f64,
    /// Whether the campaign determines the parameter (see the module documentation).
    pub identifiable: bool,
    /// Parameters of the same step with |correlation| > [`LIST_CORRELATION`] (name, correlation).
    pub correlated_with: Vec<(String, f64)>,
    /// Why the parameter is (not) identifiable.
    pub reason: String,
    /// Tuning step whose optimum gave the estimate (1-5; 6-8 the 12-state steps).
    pub step: u8,
    /// Whether the searches behind the estimate reached their optimum: false when it comes
    /// from a step 3, 4, 5, 7 or 8 that stopped at its evaluation limit or before its optimum
    /// ([`super::complete::Step5Report::early_stop`],
    /// [`super::complete::CompleteReport::early_stop`]), or from steps 3-4 or 7 run on the
    /// static maps of such a step 5 or 8. Such an estimate is never reported identifiable
    /// (`reason` names the stop): its standard error does not include the distance to the
    /// optimum.
    pub converged: bool,
}

impl ParamEstimate {
    /// Report the parameter as not identifiable because of `why`, keeping the earlier reason
    /// after it in parentheses (e.g. its relative standard error). No effect on an estimate
    /// already flagged, whose reason stays the first one found.
    pub fn flag(&mut self, why: &str) {
        if self.identifiable {
            self.flag_first(why);
        }
    }

    /// [`Self::flag`] also when the estimate is already flagged: `why` becomes the first
    /// reason (for a cause that explains the earlier flags), the earlier reason follows it.
    pub fn flag_first(&mut self, why: &str) {
        self.identifiable = false;
        self.reason = format!("{why} ({})", self.reason);
    }

    /// Mark the estimate as coming from a search that did not reach its optimum (`why` names
    /// the stop): not converged, and not identifiable with `why` as the first reason; an
    /// estimate already flagged keeps its reason with `why` added after it.
    pub fn flag_not_converged(&mut self, why: &str) {
        self.converged = false;
        if self.identifiable {
            self.flag(why);
        } else {
            self.reason = format!("{}; {why}", self.reason);
        }
    }
}

/// A function of several tuned parameters that the campaign determines although they are not
/// identifiable one by one (e.g. eta_tm at the measured blade speed ratios when eta_tm,max and
/// BSR_opt trade against each other), with its linearized standard error.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Combination {
    /// Short name ("turbine.eta_tm_at_bsr").
    pub name: String,
    /// What it is (equation, where it is evaluated).
    pub description: String,
    /// Where it is evaluated (name, value), e.g. ("bsr", 0.668), ("omega_t", 8100.0).
    pub at: Vec<(String, f64)>,
    /// Value.
    pub value: f64,
    /// Linearized standard error `sqrt(g^T C g)`, `g` its gradient over the parameters of
    /// `cov` it depends on; infinite when their covariance is not finite.
    pub std_error: f64,
}

/// Linearized standard error of a scalar function `f` of the parameters `names` (of
/// [`param_mut`](super::complete::param_mut)) at `p`: `sqrt(g^T C g)` with `g` by central differences (steps
/// `1e-6 max(|value|, typical magnitude)`, ties of [`set_named`] applied) and `C` their block of
/// `cov`; names absent from `cov` or `p` contribute nothing. Infinite when an entry of the
/// block is not finite.
pub fn function_std_error(
    f: impl Fn(&Params) -> f64,
    p: &Params,
    names: &[&str],
    cov: &NamedCov,
) -> f64 {
    let have: Vec<(&str, usize, f64)> = names
        .iter()
        .filter_map(|n| {
            let i = cov.names.iter().position(|x| x == n)?;
            Some((*n, i, param_value(p, n)?))
        })
        .collect();
    let g: Vec<f64> = have
        .iter()
        .map(|(n, _, v)| {
            let h = 1e-6 * v.abs().max(typical_scale(n, *v));
            let at = |x: f64| {
                let mut q = p.clone();
                set_named(&mut q, &[n], &[x]);
                f(&q)
            };
            (at(v + h) - at(v - h)) / (2.0 * h)
        })
        .collect();
    let mut var = 0.0;
    for (a, (_, ia, _)) in have.iter().enumerate() {
        for (b, (_, ib, _)) in have.iter().enumerate() {
            let c = cov.cov[(*ia, *ib)];
            if !c.is_finite() {
                return f64::INFINITY;
            }
            var += g[a] * c * g[b];
        }
    }
    var.max(0.0).sqrt()
}

/// Lag-1 autocorrelation of `r` (0 for fewer than 3 values or zero variance).
pub fn lag1_autocorrelation(r: &[f64]) -> f64 {
    if r.len() < 3 {
        return 0.0;
    }
    let n = r.len() as f64;
    let m = r.iter().sum::<f64>() / n;
    let c0: f64 = r.iter().map(|x| (x - m) * (x - m)).sum();
    if c0 <= 0.0 {
        return 0.0;
    }
    let c1: f64 = r.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    c1 / c0
}

/// Finite-difference Jacobian of `res` at `theta` with the steps `h`, the one used for every
/// linearization of this module: `Central` (2 n evaluations) or `Forward` (n + 1), the columns
/// in parallel ([`fd_column`]). Rows missing from a shorter evaluation stay zero.
pub fn fd_jacobian(
    res: impl Fn(&[f64]) -> Vec<f64> + Sync,
    theta: &[f64],
    h: &[f64],
    method: FiniteDiff,
) -> DMatrix<f64> {
    use rayon::prelude::*;
    let r0 = res(theta);
    let m = r0.len();
    let cols: Vec<Vec<f64>> = (0..theta.len())
        .into_par_iter()
        .map(|k| fd_column(&res, theta, k, h[k], method, &r0))
        .collect();
    let mut j = DMatrix::zeros(m, theta.len());
    for (k, col) in cols.iter().enumerate() {
        for (i, v) in col.iter().take(m).enumerate() {
            j[(i, k)] = *v;
        }
    }
    j
}

/// Column `k` of the finite-difference Jacobian of `res` at `theta` with the step `h`:
/// `(res(theta + h e_k) - res(theta - h e_k)) / (2 h)` (`Central`) or `(res(theta + h e_k) -
/// r0) / h` (`Forward`, `r0 = res(theta)`), as long as the shorter of the two vectors. The one
/// difference quotient of the tuning's covariances ([`fd_jacobian`] and step 3's and 5's
/// `complete::covariance_jacobian`).
pub fn fd_column(
    res: &(impl Fn(&[f64]) -> Vec<f64> + ?Sized),
    theta: &[f64],
    k: usize,
    h: f64,
    method: FiniteDiff,
    r0: &[f64],
) -> Vec<f64> {
    let mut th = theta.to_vec();
    th[k] = theta[k] + h;
    let rp = res(&th);
    match method {
        FiniteDiff::Central => {
            th[k] = theta[k] - h;
            let rm = res(&th);
            rp.iter()
                .zip(&rm)
                .map(|(a, b)| (a - b) / (2.0 * h))
                .collect()
        }
        FiniteDiff::Forward => rp.iter().zip(r0).map(|(a, b)| (a - b) / h).collect(),
    }
}

/// Central-difference steps of the step-1 and step-2 linearizations (cheap, smooth residuals):
/// `1e-6 max(|theta_k|, scale_k)`.
fn central_steps(theta: &[f64], scale: &[f64]) -> Vec<f64> {
    theta
        .iter()
        .zip(scale)
        .map(|(t, s)| 1e-6 * t.abs().max(*s))
        .collect()
}

/// Estimates of the parameters `names` (values `theta`, typical magnitudes `scale`) from the
/// Jacobian and residuals at the optimum of step `step`, the residuals in one block (one noise
/// level). See [`estimates_blocks`].
pub fn estimates(
    names: &[&str],
    theta: &[f64],
    scale: &[f64],
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    step: u8,
) -> Vec<(String, ParamEstimate)> {
    estimates_blocks(names, theta, scale, jacobian, residuals, &[], step)
}

/// Block-sandwich covariance: `(J^T J)^-1 J^T S J (J^T J)^-1` with `S` diagonal, constant in
/// each block of residuals (lengths `blocks`, the rest one block): the block's mean square
/// residual times its AR(1) inflation `(1 + rho)/(1 - rho)`. With one block of white residuals
/// this is the Gauss-Newton covariance `s^2 (J^T J)^-1` (up to the degrees of freedom). Blocks
/// are the rows of a cost with different noise levels (a data set's output, a submodel).
///
/// A parameter whose column of `jacobian` is zero (or not finite) has no effect on the
/// residuals at the point: its variance is infinite (not determined) and its covariances are
/// zero, and the others' covariance is that of the remaining columns (pseudo-inverse over the
/// identifiable subspace). Before session 43 such a column made `(J^T J)^+` NaN in its row and
/// column and the products spread the NaN to every entry, so one such parameter (a3 clamped to
/// the edge of the PSD cone of Q_c, step 8 on a small noisy campaign) left every parameter of
/// the step with an infinite standard error.
pub fn block_covariance(
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    blocks: &[usize],
) -> DMatrix<f64> {
    block_covariance_and_step(jacobian, residuals, blocks).0
}

/// [`block_covariance`] and the remaining Gauss-Newton step `-(J^T J)^+ J^T r` at the point
/// (zero at an interior optimum; large where the search stopped before converging).
pub fn block_covariance_and_step(
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    blocks: &[usize],
) -> (DMatrix<f64>, Vec<f64>) {
    let n = jacobian.ncols();
    // a zero (or non-finite) column has no entry in (J^T J)^+: param_stats leaves NaN there,
    // which the products below would spread to every entry; such columns are set to zero and
    // left out
    let dead: Vec<bool> = (0..n)
        .map(|j| {
            let c = jacobian.column(j);
            c.iter().any(|x| !x.is_finite()) || c.iter().all(|x| *x == 0.0)
        })
        .collect();
    let mut live = jacobian.clone();
    for (j, _) in dead.iter().enumerate().filter(|(_, d)| **d) {
        live.column_mut(j).fill(0.0);
    }
    let jacobian = &live;
    let m = jacobian.nrows();
    let st: ParamStats = param_stats(jacobian, residuals);
    // (J^T J)^+ = cov / sigma2 (pseudo-inverse over the identifiable subspace)
    let inv = DMatrix::from_fn(n, n, |a, b| {
        if dead[a] || dead[b] {
            0.0
        } else {
            st.covariance[(a, b)] / st.sigma2
        }
    });
    let mut w = vec![0.0; m];
    let mut start = 0;
    let mut lens: Vec<usize> = blocks.to_vec();
    let used: usize = lens.iter().sum();
    if used < m {
        lens.push(m - used);
    }
    // degrees of freedom of the columns that enter (a dead column uses none)
    let n_live = dead.iter().filter(|d| !**d).count();
    let dof = (m as f64 / m.saturating_sub(n_live).max(1) as f64).max(1.0);
    for len in lens {
        let end = (start + len).min(m);
        if end <= start {
            continue;
        }
        let r = &residuals[start..end];
        let ms = r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64;
        let rho = lag1_autocorrelation(r).clamp(0.0, 0.98);
        let v = ms * dof * (1.0 + rho) / (1.0 - rho);
        for x in &mut w[start..end] {
            *x = v;
        }
        start = end;
    }
    let mut jsj = DMatrix::zeros(n, n);
    for i in 0..m {
        let row = jacobian.row(i);
        for a in 0..n {
            let ra = row[a] * w[i];
            if ra == 0.0 {
                continue;
            }
            for b in 0..n {
                jsj[(a, b)] += ra * row[b];
            }
        }
    }
    let g = jacobian.tr_mul(&nalgebra::DVector::from_column_slice(residuals));
    let step = (&inv * g).iter().map(|x| -x).collect();
    let mut cov = &inv * jsj * &inv;
    for (j, _) in dead.iter().enumerate().filter(|(_, d)| **d) {
        // not determined by the data: infinite variance, no correlation (as joint_covariance)
        cov[(j, j)] = f64::INFINITY;
    }
    (cov, step)
}

/// Estimates of the parameters `names` (see [`estimates`]) with residual `blocks` of different
/// noise levels ([`block_covariance`]).
pub fn estimates_blocks(
    names: &[&str],
    theta: &[f64],
    scale: &[f64],
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    blocks: &[usize],
    step: u8,
) -> Vec<(String, ParamEstimate)> {
    let _ = scale;
    let cov = block_covariance(jacobian, residuals, blocks);
    estimates_from_cov(names, theta, &cov, step)
}

/// The linearization of a step at its estimate (not serialized): what the pipeline needs to
/// add the uncertainty of the parameters the step held fixed ([`with_fixed`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Linearization {
    /// Names of the step's parameters (columns of `jacobian`).
    pub names: Vec<String>,
    /// Jacobian of the step's residuals (m x n).
    pub jacobian: DMatrix<f64>,
    /// Covariance of the step's parameters, conditional on the fixed ones.
    pub covariance: DMatrix<f64>,
}

/// Covariance of named parameters (the names of [`param_mut`](super::complete::param_mut)), in their units.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NamedCov {
    /// Parameter names (order of the rows and columns of `cov`).
    pub names: Vec<String>,
    /// Covariance matrix.
    pub cov: DMatrix<f64>,
}

impl NamedCov {
    /// A covariance of `names`.
    pub fn new(names: &[&str], cov: DMatrix<f64>) -> Self {
        Self {
            names: names.iter().map(|s| s.to_string()).collect(),
            cov,
        }
    }

    /// Insert the block `other`, replacing the rows and columns of its names (a later estimate
    /// of the same parameters); cross-covariances between the blocks are zero.
    pub fn set_block(&mut self, other: &NamedCov) {
        let keep: Vec<usize> = (0..self.names.len())
            .filter(|&i| !other.names.contains(&self.names[i]))
            .collect();
        let (k, n) = (keep.len(), other.names.len());
        let mut cov = DMatrix::zeros(k + n, k + n);
        for (a, &i) in keep.iter().enumerate() {
            for (b, &j) in keep.iter().enumerate() {
                cov[(a, b)] = self.cov[(i, j)];
            }
        }
        cov.view_mut((k, k), (n, n)).copy_from(&other.cov);
        let mut names: Vec<String> = keep.iter().map(|&i| self.names[i].clone()).collect();
        names.extend(other.names.iter().cloned());
        *self = NamedCov { names, cov };
    }

    /// The block of the parameters not in `exclude` (non-finite entries set to zero).
    pub fn without(&self, exclude: &[&str]) -> NamedCov {
        let idx: Vec<usize> = (0..self.names.len())
            .filter(|&i| !exclude.contains(&self.names[i].as_str()))
            .collect();
        let cov = DMatrix::from_fn(idx.len(), idx.len(), |a, b| {
            let v = self.cov[(idx[a], idx[b])];
            if v.is_finite() {
                v
            } else {
                0.0
            }
        });
        NamedCov {
            names: idx.iter().map(|&i| self.names[i].clone()).collect(),
            cov,
        }
    }
}

/// Covariance of a step's estimates including the uncertainty of the parameters it holds fixed
/// (module documentation): `cov + S cov_fixed S^T`, `S = (J^T J)^+ J^T J_fixed`, with `jacobian`
/// J (m x n) of the step's own parameters and `j_fixed` (m x k) of the fixed ones.
pub fn with_fixed(
    jacobian: &DMatrix<f64>,
    cov: &DMatrix<f64>,
    j_fixed: &DMatrix<f64>,
    cov_fixed: &DMatrix<f64>,
) -> DMatrix<f64> {
    if j_fixed.ncols() == 0 || j_fixed.nrows() != jacobian.nrows() {
        return cov.clone();
    }
    let s = sensitivity(jacobian, j_fixed);
    cov + &s * cov_fixed * s.transpose()
}

/// Sensitivity `S = (J^T J)^+ J^T J_fixed` of a step's optimum to the parameters it holds fixed
/// (`d(own)/d(fixed) = -S`), the pseudo-inverse over the identifiable subspace.
pub fn sensitivity(jacobian: &DMatrix<f64>, j_fixed: &DMatrix<f64>) -> DMatrix<f64> {
    let m = jacobian.nrows();
    // (J^T J)^+ over the identifiable subspace (param_stats with unit residuals: cov / sigma2)
    let st = param_stats(jacobian, &vec![1.0; m]);
    let pinv = st.covariance.map(|c| if c.is_finite() { c } else { 0.0 }) / st.sigma2;
    pinv * jacobian.tr_mul(j_fixed)
}

/// The linearization of one step of a block-coordinate estimator: the step's parameters
/// `names`, their covariance `cov` conditional on the parameters the step held fixed, and the
/// sensitivity `s` of its optimum to those (`fixed`): `d(own)/d(fixed) = -s`,
/// `s = (J^T J)^+ J^T J_fixed` (as in [`with_fixed`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Conditional {
    /// The step's own parameters.
    pub names: Vec<String>,
    /// Their covariance with the fixed parameters held at their values.
    pub cov: DMatrix<f64>,
    /// The parameters the step held fixed (columns of `s`).
    pub fixed: Vec<String>,
    /// Sensitivity of the optimum (n x k).
    pub s: DMatrix<f64>,
}

/// Joint covariance of steps that each held the others' parameters fixed, at a fixed point of
/// their alternation (step 5 holds V_im, V_em, J_t fixed, the repeated step 3 the static
/// parameters): linearized, every step b satisfies
/// `d_b + sum_{c != b} S_bc d_c + S_b,ext d_ext = e_b`, `Cov(e_b)` = its conditional
/// covariance, so with `K = I + [S_bc]` the joint covariance is
/// `K^-1 (diag(Cov_b) + S_ext C_ext S_ext^T) K^-T` (cross-covariances of the e_b neglected, as
/// between all steps). It describes estimates at a fixed point of the alternation (each the
/// optimum of its step given the others' final values); chaining (`Cov_b + S C_f S^T`, C_f
/// the covariance of the values the step held fixed when it ran) describes one pass. `ext` is the covariance of every other estimate (the actuators, ...); fixed parameters in
/// neither contribute nothing (as in [`NamedCov::without`]). A parameter with an infinite own
/// variance (not determined by its step's data) keeps an infinite variance. `None` when `K` is
/// singular (the alternation does not contract in some direction).
pub fn joint_covariance(blocks: &[&Conditional], ext: &NamedCov) -> Option<NamedCov> {
    let names: Vec<String> = blocks.iter().flat_map(|b| b.names.clone()).collect();
    let n = names.len();
    let pos = |name: &str| names.iter().position(|x| x == name);
    let epos = |name: &str| ext.names.iter().position(|x| x == name);
    let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
    let mut k = DMatrix::<f64>::identity(n, n);
    let mut e = DMatrix::<f64>::zeros(n, ext.names.len());
    let mut d = DMatrix::<f64>::zeros(n, n);
    let mut undetermined = vec![false; n];
    let mut row0 = 0;
    for b in blocks {
        let nb = b.names.len();
        for i in 0..nb {
            for j in 0..nb {
                d[(row0 + i, row0 + j)] = finite(b.cov[(i, j)]);
            }
            let v = b.cov[(i, i)];
            undetermined[row0 + i] = !(v.is_finite() && v > 0.0);
        }
        for (c, f) in b.fixed.iter().enumerate() {
            // a parameter of this step itself is not a fixed one
            if b.names.contains(f) {
                continue;
            }
            if let Some(col) = pos(f) {
                for i in 0..nb {
                    k[(row0 + i, col)] += finite(b.s[(i, c)]);
                }
            } else if let Some(col) = epos(f) {
                for i in 0..nb {
                    e[(row0 + i, col)] += finite(b.s[(i, c)]);
                }
            }
        }
        row0 += nb;
    }
    let c_ext = ext.cov.map(finite);
    let k_inv = k.try_inverse()?;
    let mid = d + &e * c_ext * e.transpose();
    let mut cov = &k_inv * mid * k_inv.transpose();
    if cov.iter().any(|v| !v.is_finite()) {
        return None;
    }
    for (i, u) in undetermined.iter().enumerate() {
        if *u {
            cov[(i, i)] = f64::INFINITY;
        }
    }
    Some(NamedCov { names, cov })
}

/// Forward-difference Jacobian (m x k, [`fd_jacobian`]) of `res` at `p` with respect to the
/// parameters `names` ([`param_mut`](super::complete::param_mut) names, ties of [`set_named`] applied); steps
/// `FD_STEP max(|value|, typical magnitude)`. Columns of parameters `p` does not have are zero.
pub fn fd_jacobian_named(
    res: impl Fn(&Params) -> Vec<f64> + Sync,
    p: &Params,
    names: &[String],
) -> DMatrix<f64> {
    let have: Vec<usize> = (0..names.len())
        .filter(|&k| param_value(p, &names[k]).is_some())
        .collect();
    let own: Vec<&str> = have.iter().map(|&k| names[k].as_str()).collect();
    let theta: Vec<f64> = own.iter().filter_map(|n| param_value(p, n)).collect();
    let h: Vec<f64> = own
        .iter()
        .zip(&theta)
        .map(|(n, v)| super::complete::FD_STEP * typical_scale(n, *v).max(v.abs()))
        .collect();
    let jh = fd_jacobian(
        |th: &[f64]| {
            let mut q = p.clone();
            set_named(&mut q, &own, th);
            res(&q)
        },
        &theta,
        &h,
        FiniteDiff::Forward,
    );
    let mut j = DMatrix::zeros(jh.nrows(), names.len());
    for (c, &k) in have.iter().enumerate() {
        j.set_column(k, &jh.column(c));
    }
    j
}

/// How a step's Jacobian J_f with respect to the parameters it holds fixed is computed
/// ([`with_fixed`]; `mvem tune --fixed-jacobian`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FixedJacobian {
    /// Forward differences at `complete::FD_STEP` (1e-4) relative ([`fd_jacobian_named`]): the
    /// default, as since session 10. On the dynamic steps (3, 4, 5) the change of the
    /// residuals over that step is not far above the simulations' noise (rtol 1e-8), so some
    /// columns are noise, and `S C_f S^T` is distorted by it (V_im, V_em, J_t: 0.6-200 times
    /// the sigma points' standard errors over eight `mvem lab` campaigns, median 4-6x) and
    /// moves with the simulations' last bits (up to 6.9x between two builds; docs/tuning.md,
    /// sessions 21 and 22).
    #[default]
    Forward,
    /// Central differences along the principal axes of C_f, one standard deviation each way
    /// ([`sigma_point_jacobian_named`]): the directions that carry the fixed parameters'
    /// uncertainty, at the size of that uncertainty, far above the simulations' noise.
    SigmaPoints,
}

/// Whether a residual vector holds a failed evaluation: a non-finite entry, or the
/// [`FAILED_RESIDUAL`] that the residual functions of steps 3-5 give every row of a data set
/// that does not simulate (step 5's cost only that set's rows, steps 3 and 4 all rows).
fn failed_residuals(r: &[f64]) -> bool {
    r.iter().any(|v| !v.is_finite() || *v == FAILED_RESIDUAL)
}

/// J_f (m x k) of `res` at `p` with respect to the parameters of `fixed` (its names, in that
/// order), from central differences along the principal axes of their covariance: with
/// `C_f = D R D` (D the standard deviations, R the correlation matrix, `R = U M U^T`), the
/// directions are the columns of `L = D U M^(1/2)` (so `L L^T = C_f`), and
/// `g_j = (res(p + s l_j) - res(p - s l_j)) / (2 s)` with s = 1 (one standard deviation), halved
/// up to 8 times while a side gives invalid parameters or a failed evaluation (a non-finite
/// entry, or the [`FAILED_RESIDUAL`] of a data set that does not simulate). Then
/// `J_f = G L^+`, so that `J_f C_f J_f^T = G G^T`: the propagated covariance `S C_f S^T` of [`with_fixed`] is that of the residuals' response to one standard
/// deviation of each independent combination of the fixed parameters (a second-order-accurate
/// "statistical" linearization, the sigma points of the unscented transform), and J_f's other
/// uses (the joint covariance's couplings) see the same columns. Directions of the correlation
/// matrix with an eigenvalue below 1e-12 of the largest carry no variance and are left out;
/// parameters with zero or non-finite variance ([`NamedCov::without`] sets those to 0) get the
/// forward differences of [`fd_jacobian_named`]. Directions in parallel.
pub fn sigma_point_jacobian_named(
    res: impl Fn(&Params) -> Vec<f64> + Sync,
    p: &Params,
    fixed: &NamedCov,
) -> DMatrix<f64> {
    use rayon::prelude::*;
    let k = fixed.names.len();
    let value: Vec<Option<f64>> = fixed.names.iter().map(|n| param_value(p, n)).collect();
    let sd: Vec<f64> = (0..k)
        .map(|i| {
            let v = fixed.cov[(i, i)];
            if value[i].is_some() && v.is_finite() && v > 0.0 {
                v.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    // the parameters with a variance: their correlation matrix and its eigenvectors
    let var: Vec<usize> = (0..k).filter(|&i| sd[i] > 0.0).collect();
    let nv = var.len();
    let corr = DMatrix::from_fn(nv, nv, |a, b| {
        let (i, j) = (var[a], var[b]);
        let c = 0.5 * (fixed.cov[(i, j)] + fixed.cov[(j, i)]) / (sd[i] * sd[j]);
        if c.is_finite() {
            c
        } else {
            0.0
        }
    });
    if nv == 0 {
        // nothing to propagate: every column by forward differences
        return fd_jacobian_named(&res, p, &fixed.names);
    }
    let eig = corr.symmetric_eigen();
    let mu_max = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let dirs: Vec<usize> = (0..nv)
        .filter(|&j| eig.eigenvalues[j] > 1e-12 * mu_max)
        .collect();
    let names: Vec<&str> = var.iter().map(|&i| fixed.names[i].as_str()).collect();
    let theta: Vec<f64> = var.iter().map(|&i| value[i].unwrap_or(0.0)).collect();
    let m = res(p).len();
    // l_j = D u_j sqrt(mu_j) over the parameters with a variance
    let l = |j: usize| -> Vec<f64> {
        let s = eig.eigenvalues[j].sqrt();
        (0..nv)
            .map(|a| sd[var[a]] * eig.eigenvectors[(a, j)] * s)
            .collect()
    };
    let eval = |th: &[f64]| -> Option<Vec<f64>> {
        let mut q = p.clone();
        set_named(&mut q, &names, th);
        if q.validate().is_err() {
            return None;
        }
        let r = res(&q);
        (r.len() == m && !failed_residuals(&r)).then_some(r)
    };
    let cols: Vec<Vec<f64>> = dirs
        .par_iter()
        .map(|&j| {
            let lj = l(j);
            let mut s = 1.0;
            for _ in 0..9 {
                let plus: Vec<f64> = theta.iter().zip(&lj).map(|(t, d)| t + s * d).collect();
                let minus: Vec<f64> = theta.iter().zip(&lj).map(|(t, d)| t - s * d).collect();
                if let (Some(rp), Some(rm)) = (eval(&plus), eval(&minus)) {
                    return rp
                        .iter()
                        .zip(&rm)
                        .map(|(a, b)| (a - b) / (2.0 * s))
                        .collect();
                }
                s *= 0.5;
            }
            // no valid pair within 1/256 standard deviation: no information on this direction
            vec![0.0; m]
        })
        .collect();
    // J_f = G L^+, L^+ = M^(-1/2) U^T D^(-1) on the parameters with a variance
    let mut jf = DMatrix::zeros(m, k);
    for (g, &j) in cols.iter().zip(&dirs) {
        let inv = 1.0 / eig.eigenvalues[j].sqrt();
        for (a, &i) in var.iter().enumerate() {
            let w = eig.eigenvectors[(a, j)] * inv / sd[i];
            if w == 0.0 {
                continue;
            }
            for (r, gv) in g.iter().enumerate() {
                jf[(r, i)] += gv * w;
            }
        }
    }
    // the parameters without a variance: forward differences (they propagate nothing, but
    // the joint covariance's couplings use their columns)
    let rest: Vec<usize> = (0..k)
        .filter(|&i| sd[i] == 0.0 && value[i].is_some())
        .collect();
    if !rest.is_empty() {
        let names: Vec<String> = rest.iter().map(|&i| fixed.names[i].clone()).collect();
        let jr = fd_jacobian_named(&res, p, &names);
        if jr.nrows() == m {
            for (c, &i) in rest.iter().enumerate() {
                jf.set_column(i, &jr.column(c));
            }
        }
    }
    jf
}

/// Estimates of the parameters `names` (values `theta`) from their covariance `cov` (step
/// `step`): standard errors, correlations, identifiability (module documentation).
pub fn estimates_from_cov(
    names: &[&str],
    theta: &[f64],
    cov: &DMatrix<f64>,
    step: u8,
) -> Vec<(String, ParamEstimate)> {
    let n = names.len();
    let se: Vec<f64> = (0..n)
        .map(|k| {
            let v = cov[(k, k)];
            if v.is_finite() && v > 0.0 {
                v.sqrt()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    let corr_of = |a: usize, b: usize| cov[(a, b)] / (se[a] * se[b]);
    names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let se = se[k];
            // relative to the value: a parameter not distinguishable from 0 is not identifiable
            let rel = se / theta[k].abs();
            let mut corr: Vec<(String, f64)> = (0..names.len())
                .filter(|&i| i != k)
                .map(|i| (names[i].to_string(), corr_of(k, i)))
                .filter(|(_, c)| c.is_finite() && c.abs() > LIST_CORRELATION)
                .collect();
            corr.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            let worst = corr.first().cloned();
            let (identifiable, reason) = if !se.is_finite() {
                (
                    false,
                    "not determined by the data (a zero singular value of the Jacobian involves it)"
                        .to_string(),
                )
            } else if rel > MAX_REL_STD_ERR {
                (false, format!("rel. std. error {:.0} %", 100.0 * rel))
            } else if let Some((w, c)) = worst.filter(|(_, c)| c.abs() > MAX_CORRELATION) {
                (false, format!("correlation {c:.4} with {w}"))
            } else {
                (true, format!("rel. std. error {:.2} %", 100.0 * rel))
            };
            (
                n.to_string(),
                ParamEstimate {
                    value: theta[k],
                    std_error: se,
                    identifiable,
                    correlated_with: corr,
                    reason,
                    step,
                    converged: true,
                },
            )
        })
        .collect()
}

/// Typical magnitude of a tunable parameter: its [`STATIC_PARAMS`] scale, else |value| (1 if 0).
fn typical_scale(name: &str, value: f64) -> f64 {
    STATIC_PARAMS
        .iter()
        .find(|s| s.name == name)
        .map(|s| s.scale)
        .unwrap_or(if value != 0.0 { value.abs() } else { 1.0 })
}

/// Estimates of the step-1 parameters: per submodel, the Jacobian of its residuals
/// (measured - modelled, eq. (4) units) by central differences at the fitted values; and their
/// covariance (one block per submodel). `flow_extra`: the further compressor flow points the
/// W_c fit used besides the stationary points ([`super::steps::step1_with`]).
pub fn step1_estimates(
    p: &Params,
    pts: &[StationaryPoint],
    flow_extra: &[FlowPoint],
    rep: &Step1Report,
) -> (Vec<(String, ParamEstimate)>, NamedCov) {
    let mut out = Vec::new();
    let mut all = NamedCov::default();
    let flow = flow_points_with(pts, flow_extra);
    for f in &rep.fits {
        let names: Vec<&str> = f.params.iter().map(|(n, _)| n.as_str()).collect();
        let theta: Vec<f64> = names
            .iter()
            .map(|n| param_value(p, n).unwrap_or(f64::NAN))
            .collect();
        let scale: Vec<f64> = names
            .iter()
            .zip(&theta)
            .map(|(n, v)| typical_scale(n, *v))
            .collect();
        // eta_tm, eta_c in efficiency units (conservative, module documentation)
        let res = |th: &[f64]| -> Vec<f64> {
            let mut q = p.clone();
            set_named(&mut q, &names, th);
            if f.submodel == "W_c" {
                // the points of the fit (stationary and further flow points)
                let (meas, model) = w_c_flow_series(&q, &flow);
                return meas.iter().zip(&model).map(|(a, b)| a - b).collect();
            }
            match submodel_series(&q, pts) {
                Ok(all) => all
                    .into_iter()
                    .find(|s| s.0 == f.submodel)
                    .map(|(_, meas, model)| meas.iter().zip(&model).map(|(a, b)| a - b).collect())
                    .unwrap_or_default(),
                Err(_) => vec![f64::NAN; pts.len()],
            }
        };
        let r = res(&theta);
        let j = fd_jacobian(
            res,
            &theta,
            &central_steps(&theta, &scale),
            FiniteDiff::Central,
        );
        // a variance per point (heteroscedastic derived measurements, Cost77::covariance_blocks)
        let cov = block_covariance(&j, &r, &vec![1; r.len()]);
        out.extend(estimates_from_cov(&names, &theta, &cov, 1));
        all.set_block(&NamedCov::new(&names, cov));
    }
    (out, all)
}

/// Estimates of the step-2 actuator parameters from the actuator set `j` (positions against
/// the responses to the saturated commands), and their covariance.
pub fn step2_estimates(p: &Params, j: &DynamicData) -> (Vec<(String, ParamEstimate)>, NamedCov) {
    let mut out = Vec::new();
    let mut all = NamedCov::default();
    for (names, cmd, pos, egr) in [
        (
            &["tau_egr1", "tau_egr2", "tau_degr", "k_egr"][..],
            "u_egr",
            "u_egr_pos",
            true,
        ),
        (&["tau_vgt", "tau_dvgt"][..], "u_vgt", "u_vgt_pos", false),
    ] {
        let (Some(u), Some(y)) = (j.get(cmd), j.get(pos)) else {
            continue;
        };
        let theta: Vec<f64> = names
            .iter()
            .map(|n| param_value(p, n).unwrap_or(f64::NAN))
            .collect();
        let scale: Vec<f64> = theta.iter().map(|v| v.abs().max(1e-3)).collect();
        let res = |th: &[f64]| -> Vec<f64> {
            let mut q = p.clone();
            set_named(&mut q, names, th);
            actuator_response(&q, &j.t, u, egr)
                .iter()
                .zip(y)
                .map(|(m, y)| m - y)
                .collect()
        };
        let r = res(&theta);
        let jac = fd_jacobian(
            res,
            &theta,
            &central_steps(&theta, &scale),
            FiniteDiff::Central,
        );
        let cov = block_covariance(&jac, &r, &[]);
        out.extend(estimates_from_cov(names, &theta, &cov, 2));
        all.set_block(&NamedCov::new(names, cov));
    }
    (out, all)
}

/// The path of a tunable parameter in the parameter registry, which names the tuning report's
/// parameters ("exhaust_manifold.v_em"; elements 1-based, [`crate::params::element_name`]:
/// `"cylinder.c_vol[1]"` is c_vol1, `"compressor.q_c[1][2]"` is a3), from its path or its
/// symbol ([`crate::params::ParamInfo::find`], which [`param_mut`](super::complete::param_mut) resolves too). The name is
/// accepted as it is by [`Params::get`], Python's `params=` and `mvem.parameters()`.
pub fn toml_path(name: &str) -> Option<&'static str> {
    crate::params::ParamInfo::find(name).map(|i| i.path.as_str())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A parameter with a zero column (no effect on the residuals: a3 clamped to the edge of
    /// Q_c's PSD cone in step 8, session 43) is not determined, and the others keep the
    /// covariance of their own columns; before, the NaN of its row of (J^T J)^+ spread to
    /// every entry and every parameter read an infinite standard error.
    #[test]
    fn a_zero_column_leaves_the_other_parameters_their_covariance() {
        // two parameters by hand: columns x = (1, 2, 3, 4, 5, 6) and 1, residuals +-0.1 in
        // one block; the zero column between them
        let m = 6;
        let x: Vec<f64> = (1..=m).map(|i| i as f64).collect();
        let res = [0.1, -0.1, 0.1, 0.1, -0.1, -0.1];
        let j3 = DMatrix::from_fn(m, 3, |i, k| [x[i], 0.0, 1.0][k]);
        let c = block_covariance(&j3, &res, &[]);
        // by hand: J^T J = [[91, 21], [21, 6]], det 105, inverse [[6, -21], [-21, 91]] / 105;
        // mean square 0.01, dof factor m / (m - 2) (the zero column uses no degree of
        // freedom), lag-1 autocorrelation of the residuals -1/6, clamped to 0: covariance
        // 0.01 * 1.5 * (J^T J)^-1
        let s2 = 0.01 * 6.0 / 4.0;
        let want = [[6.0, -21.0], [-21.0, 91.0]].map(|r| r.map(|v| s2 * v / 105.0));
        for (a, ka) in [(0, 0), (1, 2)] {
            for (b, kb) in [(0, 0), (1, 2)] {
                let (got, w) = (c[(ka, kb)], want[a][b]);
                assert!(
                    (got - w).abs() <= 1e-12 * w.abs(),
                    "{ka},{kb}: {got} vs {w}"
                );
            }
        }
        // the zero column: not determined, uncorrelated
        assert_eq!(c[(1, 1)], f64::INFINITY);
        assert!((0..3)
            .filter(|&k| k != 1)
            .all(|k| c[(1, k)] == 0.0 && c[(k, 1)] == 0.0));
        let e = estimates_from_cov(&["a", "dead", "b"], &[1.0, 2.0, 3.0], &c, 8);
        assert!(e[0].1.std_error.is_finite() && e[2].1.std_error.is_finite());
        assert!(!e[1].1.identifiable && e[1].1.std_error == f64::INFINITY);
        // and the same as without the column
        let j2 = DMatrix::from_fn(m, 2, |i, k| [x[i], 1.0][k]);
        let c2 = block_covariance(&j2, &res, &[]);
        assert!((c2[(0, 1)] - c[(0, 2)]).abs() <= 1e-15);
    }

    /// A residual function of V_im, V_em, J_t and eta_tmmax that is linear in them (J_f known
    /// exactly), plus a deterministic "rounding noise" of amplitude `noise` that changes with
    /// the last bits of the parameters, as a simulation's does.
    fn linear_residuals(noise: f64) -> impl Fn(&Params) -> Vec<f64> + Sync {
        move |q: &Params| {
            let th = [q.intake_manifold.v_im, q.exhaust_manifold.v_em, q.turbo.j_t];
            let e = q.turbine.eta_tmmax;
            (0..40)
                .map(|i| {
                    let x = i as f64;
                    let lin = (1.0 + x) * th[0] - 0.5 * x * th[1]
                        + 100.0 * (x - 20.0) * th[2]
                        + 0.01 * x * e;
                    // noise: a hash of the bits, uniform in [-noise, noise]
                    let bits = th[0].to_bits()
                        ^ th[1].to_bits().rotate_left(17)
                        ^ th[2].to_bits().rotate_left(31)
                        ^ e.to_bits().rotate_left(47)
                        ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                    let h = bits.wrapping_mul(0xD6E8_FEB8_6659_FD93) >> 11;
                    lin + noise * (2.0 * (h as f64 / (1u64 << 53) as f64) - 1.0)
                })
                .collect()
        }
    }

    /// The sigma-point J_f is exact on a linear residual function, its propagated covariance
    /// J_f C_f J_f^T is not disturbed by a rounding noise that makes forward differences at
    /// 1e-4 useless, and a parameter without a variance gets a forward-difference column.
    #[test]
    fn sigma_point_jacobian_is_exact_on_linear_residuals_and_robust_to_noise() {
        let p = Params::published();
        let names = ["v_im", "v_em", "j_t", "eta_tmmax"];
        let th = [
            p.intake_manifold.v_im,
            p.exhaust_manifold.v_em,
            p.turbo.j_t,
            p.turbine.eta_tmmax,
        ];
        // 5 % standard deviations, V_im and J_t correlated -0.9, eta_tmmax without a variance
        let sd = [0.05 * th[0], 0.05 * th[1], 0.05 * th[2], 0.0];
        let corr = |a: usize, b: usize| match (a.min(b), a.max(b)) {
            _ if a == b => 1.0,
            (0, 2) => -0.9,
            (0, 1) => 0.3,
            _ => 0.0,
        };
        let cov = DMatrix::from_fn(4, 4, |a, b| corr(a, b) * sd[a] * sd[b]);
        let fixed = NamedCov::new(&names, cov.clone());
        let exact = DMatrix::from_fn(40, 4, |i, c| {
            let x = i as f64;
            [1.0 + x, -0.5 * x, 100.0 * (x - 20.0), 0.01 * x][c]
        });
        let rel = |a: &DMatrix<f64>, b: &DMatrix<f64>| (a - b).norm() / b.norm();
        let jf = sigma_point_jacobian_named(linear_residuals(0.0), &p, &fixed);
        assert!(rel(&jf, &exact) < 1e-8, "{}", rel(&jf, &exact));
        // noise 1e-7: far below the response to one standard deviation (about 1e-4 .. 1e-2),
        // not below the response to the forward step of 1e-4 relative (about 1e-7 .. 1e-4)
        let noisy = linear_residuals(1e-7);
        let prop = |j: &DMatrix<f64>| j * &cov * j.transpose();
        let want = prop(&exact);
        let sig = prop(&sigma_point_jacobian_named(&noisy, &p, &fixed));
        let fwd = prop(&fd_jacobian_named(
            &noisy,
            &p,
            names.map(String::from).as_ref(),
        ));
        // measured: 2.4e-6 and 2.4e-3 (the noise over the step: 1e-7 / 1e-3 and 1e-7 / 1e-4)
        assert!(rel(&sig, &want) < 2e-5, "sigma points {}", rel(&sig, &want));
        assert!(rel(&fwd, &want) > 5e-4, "forward {}", rel(&fwd, &want));
        // a data set that does not simulate beyond +0.6 standard deviations of V_im (its rows
        // FAILED_RESIDUAL, the others fine, as step 5's cost): those directions are halved
        let v0 = th[0];
        let failing = |q: &Params| {
            let mut r = linear_residuals(0.0)(q);
            if q.intake_manifold.v_im > v0 + 0.6 * sd[0] {
                r[..5].fill(FAILED_RESIDUAL);
            }
            r
        };
        let jf1 = sigma_point_jacobian_named(failing, &p, &fixed);
        assert!(rel(&jf1, &exact) < 1e-8, "{}", rel(&jf1, &exact));
        // no parameter with a variance: every column by forward differences
        let none = NamedCov::new(&names, DMatrix::zeros(4, 4));
        let jf0 = sigma_point_jacobian_named(linear_residuals(0.0), &p, &none);
        assert!(rel(&jf0, &exact) < 1e-6, "{}", rel(&jf0, &exact));
        // eta_tmmax (no variance): its column by forward differences, the noise-free value
        let jf = sigma_point_jacobian_named(linear_residuals(0.0), &p, &fixed);
        for i in 0..40 {
            assert!((jf[(i, 3)] - exact[(i, 3)]).abs() < 1e-6 * (1.0 + exact[(i, 3)].abs()));
        }
    }

    #[test]
    fn standard_error_of_a_function_of_parameters_by_hand() {
        // f = eta_tmmax - 2 bsr_opt: var f = var a + 4 var b - 4 cov(a, b)
        let p = Params::published();
        let cov = NamedCov::new(
            &["eta_tmmax", "bsr_opt", "k_t"],
            DMatrix::from_row_slice(3, 3, &[4e-4, 1e-4, 0.0, 1e-4, 9e-4, 0.0, 0.0, 0.0, 1.0]),
        );
        let f = |q: &Params| q.turbine.eta_tmmax - 2.0 * q.turbine.bsr_opt;
        let got = function_std_error(f, &p, &["eta_tmmax", "bsr_opt", "c_m1"], &cov);
        let want = (4e-4_f64 + 4.0 * 9e-4 - 4.0 * 1e-4).sqrt();
        assert!((got / want - 1.0).abs() < 1e-6, "{got} {want}");
        // a parameter the function depends on with an undetermined variance
        let mut inf = cov.clone();
        inf.cov[(1, 1)] = f64::INFINITY;
        assert!(function_std_error(f, &p, &["eta_tmmax", "bsr_opt"], &inf).is_infinite());
    }

    #[test]
    fn toml_paths_of_parameters() {
        assert_eq!(toml_path("v_em"), Some("exhaust_manifold.v_em"));
        // elements 1-based, as the registry, the FMU and Python's params= name them
        assert_eq!(toml_path("c_vol2"), Some("cylinder.c_vol[2]"));
        assert_eq!(toml_path("c_fric1"), Some("cylinder.c_fric[1]"));
        assert_eq!(toml_path("a3"), Some("compressor.q_c[1][2]"));
        assert_eq!(toml_path("tau_vgt"), Some("vgt_actuator.tau_vgt"));
        assert_eq!(toml_path("nonsense"), None);
        // every name the tuning steps tune resolves to a path that names the same scalar
        let p = Params::published();
        for name in [
            "c_vol1", "c_vol3", "a1", "a2", "a3", "c_m1", "c_wphi3", "c_egr2",
        ] {
            let path = toml_path(name).unwrap();
            assert_eq!(p.get(path), param_value(&p, name), "{name} {path}");
        }
    }

    #[test]
    fn fixed_parameter_uncertainty_by_hand() {
        // r = y - a x - b z with b fixed: the optimum a*(b) = (x.y - b x.z)/(x.x), so
        // da*/db = -(x.z)/(x.x) and Var(a) = Var(a | b) + (x.z / x.x)^2 Var(b)
        let x: Vec<f64> = (0..20).map(|i| 1.0 + i as f64).collect();
        let z: Vec<f64> = (0..20).map(|i| ((i * 7) % 5) as f64).collect();
        let j = DMatrix::from_fn(20, 1, |i, _| -x[i]);
        let jf = DMatrix::from_fn(20, 1, |i, _| -z[i]);
        let cov = DMatrix::from_element(1, 1, 0.04);
        let var_b = 0.25;
        let got = with_fixed(&j, &cov, &jf, &DMatrix::from_element(1, 1, var_b));
        let xz: f64 = x.iter().zip(&z).map(|(a, b)| a * b).sum();
        let xx: f64 = x.iter().map(|a| a * a).sum();
        let want = 0.04 + (xz / xx).powi(2) * var_b;
        assert!((got[(0, 0)] / want - 1.0).abs() < 1e-12, "{got} {want}");
        // no fixed parameters: unchanged
        assert_eq!(
            with_fixed(&j, &cov, &DMatrix::zeros(20, 0), &DMatrix::zeros(0, 0)),
            cov
        );
    }

    #[test]
    fn joint_covariance_of_two_alternating_steps_by_hand() {
        // a = e_a - 0.5 b - 2 x, b = e_b - 0.4 a (x external): K = [[1, .5], [.4, 1]],
        // det 0.8, K^-1 = [[1, -.5], [-.4, 1]] / 0.8
        let a = Conditional {
            names: vec!["a".into()],
            cov: DMatrix::from_element(1, 1, 4.0),
            fixed: vec!["b".into(), "x".into(), "unknown".into()],
            s: DMatrix::from_row_slice(1, 3, &[0.5, 2.0, 7.0]),
        };
        let b = Conditional {
            names: vec!["b".into()],
            cov: DMatrix::from_element(1, 1, 9.0),
            fixed: vec!["a".into()],
            s: DMatrix::from_element(1, 1, 0.4),
        };
        let ext = NamedCov::new(&["x"], DMatrix::from_element(1, 1, 0.25));
        let got = joint_covariance(&[&a, &b], &ext).unwrap();
        assert_eq!(got.names, ["a", "b"]);
        // middle: diag(4 + 2^2 0.25, 9) = diag(5, 9)
        let ki = DMatrix::from_row_slice(2, 2, &[1.0, -0.5, -0.4, 1.0]) / 0.8;
        let want = &ki * DMatrix::from_row_slice(2, 2, &[5.0, 0.0, 0.0, 9.0]) * ki.transpose();
        for (g, w) in got.cov.iter().zip(want.iter()) {
            assert!((g - w).abs() < 1e-12 * w.abs().max(1.0), "{g} {w}");
        }
        // by hand: var a = (5 + 0.25 * 9) / 0.64
        assert!((got.cov[(0, 0)] - 7.25 / 0.64).abs() < 1e-12);
        // a loop that does not contract: K singular
        let b1 = Conditional {
            s: DMatrix::from_element(1, 1, 2.0),
            ..b.clone()
        };
        assert!(joint_covariance(&[&a, &b1], &ext).is_none());
        // an undetermined own parameter stays undetermined
        let a_inf = Conditional {
            cov: DMatrix::from_element(1, 1, f64::INFINITY),
            ..a
        };
        let got = joint_covariance(&[&a_inf, &b], &ext).unwrap();
        assert!(got.cov[(0, 0)].is_infinite() && got.cov[(1, 1)].is_finite());
    }

    #[test]
    fn named_covariance_blocks_replace_and_restrict() {
        let mut c = NamedCov::new(
            &["a", "b"],
            DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.5, 2.0]),
        );
        c.set_block(&NamedCov::new(
            &["b", "c"],
            DMatrix::from_row_slice(2, 2, &[3.0, 0.1, 0.1, 4.0]),
        ));
        assert_eq!(c.names, ["a", "b", "c"]);
        // b replaced, its old cross-covariance with a dropped
        assert_eq!(c.cov[(0, 0)], 1.0);
        assert_eq!(c.cov[(0, 1)], 0.0);
        assert_eq!(c.cov[(1, 1)], 3.0);
        assert_eq!(c.cov[(2, 1)], 0.1);
        let w = c.without(&["b"]);
        assert_eq!(w.names, ["a", "c"]);
        assert_eq!(w.cov, DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 4.0]));
    }

    #[test]
    fn step5_bounds_contain_the_step1_start() {
        use crate::tuning::complete::{bounds_containing, STATIC_PARAMS};
        let mut th: Vec<f64> = STATIC_PARAMS.iter().map(|s| 0.5 * (s.lo + s.hi)).collect();
        let k = |n: &str| STATIC_PARAMS.iter().position(|s| s.name == n).unwrap();
        th[k("c_phi2")] = -0.72; // plausibility box [-0.1, 0.1]: widened
        th[k("c_egr1")] = 1.0; // physical bound (< 0): kept
        let b = bounds_containing(STATIC_PARAMS.to_vec(), &th);
        assert_eq!((b[k("c_phi2")].lo, b[k("c_phi2")].hi), (-1.44, 0.1));
        assert_eq!(b[k("c_egr1")].hi, -1e-8);
        assert_eq!(b[k("c_vol3")], STATIC_PARAMS[k("c_vol3")]);
    }

    #[test]
    fn straight_line_standard_errors_by_hand() {
        // y = a + b x with residuals +-e alternating: s^2 = n e^2 / (n - 2); J = -[1, x]
        let x: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let e = 0.1;
        let r: Vec<f64> = (0..10).map(|i| if i % 2 == 0 { e } else { -e }).collect();
        let j = DMatrix::from_fn(10, 2, |i, k| if k == 0 { -1.0 } else { -x[i] });
        let est = estimates(&["a", "b"], &[1.0, 2.0], &[1.0, 1.0], &j, &r, 1);
        let s2 = 10.0 * e * e / 8.0;
        let sxx: f64 = x.iter().map(|v| (v - 4.5) * (v - 4.5)).sum();
        // alternating residuals: negative autocorrelation, clamped to 0 (no deflation)
        assert!((est[1].1.std_error - (s2 / sxx).sqrt()).abs() < 1e-12);
        let sa = (s2 * (1.0 / 10.0 + 4.5 * 4.5 / sxx)).sqrt();
        assert!((est[0].1.std_error - sa).abs() < 1e-12);
        assert!(est[0].1.identifiable && est[1].1.identifiable);
    }

    #[test]
    fn flags_collinear_and_imprecise_parameters() {
        // two nearly equal columns: huge correlation; both not identifiable
        let j = DMatrix::from_fn(50, 2, |i, k| {
            let t = i as f64 / 50.0;
            if k == 0 {
                t
            } else {
                t * (1.0 + 1e-4 * t * t)
            }
        });
        let r: Vec<f64> = (0..50)
            .map(|i| 1e-3 * ((i * 7919) % 13) as f64 - 6e-3)
            .collect();
        let est = estimates(&["p", "q"], &[1.0, 1.0], &[1.0, 1.0], &j, &r, 5);
        for (_, e) in &est {
            assert!(!e.identifiable, "{e:?}");
            assert!(!e.correlated_with.is_empty());
        }
        // autocorrelated residuals inflate the error
        let smooth: Vec<f64> = (0..50).map(|i| 1e-3 * (i as f64 / 8.0).sin()).collect();
        let white: Vec<f64> = (0..50)
            .map(|i| if i % 2 == 0 { 7e-4 } else { -7e-4 })
            .collect();
        let jl = DMatrix::from_fn(50, 1, |i, _| i as f64);
        let a = estimates(&["x"], &[1.0], &[1.0], &jl, &smooth, 1)[0]
            .1
            .std_error;
        let b = estimates(&["x"], &[1.0], &[1.0], &jl, &white, 1)[0]
            .1
            .std_error;
        let ns: f64 = smooth.iter().map(|v| v * v).sum::<f64>();
        let nw: f64 = white.iter().map(|v| v * v).sum::<f64>();
        let rho = lag1_autocorrelation(&smooth).min(0.98);
        assert!(rho > 0.9, "{rho}");
        let want = (ns / nw).sqrt() * ((1.0 + rho) / (1.0 - rho)).sqrt();
        assert!((a / b / want - 1.0).abs() < 1e-9, "{a} {b} {want}");
    }
}
