//! The five tuning steps of the paper (sections 2.3, 4-6, 8.1). Implemented so far:
//!
//! - [`step1`]: initialization of the static submodels from stationary data (sections 4-6):
//!   linear least squares for the volumetric efficiency (c_vol via W_ei, eqs (11)-(12)) and the
//!   torque (eta_igch, c_fric, eqs (26)-(31)); variable projection ([`super::varpro`]) for the
//!   EGR flow (Pi_egropt | c_egr), turbine efficiency (BSR_opt, c_m2, c_m3 | eta_tm,max, c_m1),
//!   compressor efficiency (W_copt, pi_copt, c_pi | eta_cmax, a1, a2, a3, then the PSD
//!   projection of Q_c) and compressor flow (c_Psi2, c_Phi2 | the six polynomial
//!   coefficients); bounded nonlinear least squares ([`super::lsq`]) for the exhaust manifold
//!   temperature (eta_sc, x_cv, h_tot, eqs (17)-(25)). The turbine flow (K_t, c_f1, c_f2,
//!   c_vgt1, c_vgt2, eqs (52)-(56)) is solved by variable projection with c_f1, c_f2 as the
//!   linear part: the same minimum as the paper's plain NLS, with no start values needed for
//!   c_f1, c_f2.
//! - [`step2`]: actuator parameters from the normalized, time-shifted step responses of data
//!   set J (sections 5.2, 6.2.3).
//!
//! Every nonlinear search starts from the fixed generic values of [`Step1Start`], never from
//! the parameters in the `base` set; `base` only supplies the constants that are not tuned
//! (gas properties, geometry, A_egrmax, A_vgtmax, R_t, R_c, T_w, w_tlin).
//!
//! The models follow the authors' implementation (e.g. the linear c_m branch below w_tlin,
//! item 33, with c_mlin tied to c_m1 (w_tlin - c_m2)^c_m3 so that c_m is continuous; the
//! Pi_c >= 1 and Pi_t <= 0.9999 limits). Points where an authors' guard would be active are
//! expected to be absent (the virtual test cell only keeps physically valid equilibria).
//!
//! Relative errors are those of eq. (4): (measured - modelled) / mean(measured).
//!
//! Steps 3-5 (complete model) are in [`super::complete`], the chain in [`super::pipeline`].

mod actuators;
mod compressor;
mod cylinder;
mod egr;
mod turbine;

pub use actuators::{actuator_response, step2, Step2Start};
pub use compressor::{
    fit_eta_c, fit_w_c, flow_points_with, project_q_c, w_c_flow_series, FlowPoint,
};
pub use cylinder::{fit_t_em, fit_torque, fit_w_ei};
pub use egr::{fit_egr, C_EGR1_MAX};
pub use turbine::{bsr_series, fit_eta_tm, fit_w_t};

use super::data::StationaryPoint;
use super::lsq::{least_squares, Bounds, LsqOptions, LsqResult};
use super::scale::CampaignScale;
use crate::components::{compressor as comp, cylinder as cyl, turbine as turb, Semantics};
use crate::params::Params;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::f64::consts::PI;

pub(crate) const SEM: Semantics = Semantics::Authors;

/// Errors of the tuning steps.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// Too few data points for the submodel.
    #[error("{submodel}: {n} data points, at least {needed} needed")]
    TooFewPoints {
        /// Submodel.
        submodel: &'static str,
        /// Points available.
        n: usize,
        /// Points needed.
        needed: usize,
    },
    /// A derived measurement is not finite (e.g. T_c <= T_amb, x_egr = 1).
    #[error("{submodel}: derived measurement at point {point} is not finite ({what})")]
    BadMeasurement {
        /// Submodel.
        submodel: &'static str,
        /// Point index (0-based).
        point: usize,
        /// Which quantity.
        what: &'static str,
    },
    /// The solver failed.
    #[error("{submodel}: {message}")]
    Solver {
        /// Submodel.
        submodel: &'static str,
        /// Message.
        message: String,
    },
    /// A data set lacks a column.
    #[error("data set {set}: missing column {column}")]
    MissingColumn {
        /// Data set.
        set: String,
        /// Column.
        column: &'static str,
    },
    /// The caller cancelled the tuning ([`crate::numerics::cancel`]).
    #[error("cancelled")]
    Cancelled,
}

/// Result of fitting one submodel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitReport {
    /// Submodel name (e.g. "W_egr").
    pub submodel: String,
    /// Fitted parameters (name, value).
    pub params: Vec<(String, f64)>,
    /// Mean absolute relative error (eq. (4)) over the points [-].
    pub mean_abs_rel_err: f64,
    /// Maximum absolute relative error [-].
    pub max_abs_rel_err: f64,
    /// Number of points / samples used.
    pub n_points: usize,
    /// Residual-function evaluations of the nonlinear search (0 for linear problems).
    pub n_eval: usize,
}

/// Generic start values of the nonlinear parameters of step 1 (not the published values).
#[derive(Debug, Clone, PartialEq)]
pub struct Step1Start {
    /// Pi_egropt [-].
    pub pi_egropt: f64,
    /// [BSR_opt, c_m2 [rad/s], c_m3].
    pub eta_tm: [f64; 3],
    /// [W_copt [kg/s], pi_copt, c_pi].
    pub eta_c: [f64; 3],
    /// [c_Psi2, c_Phi2].
    pub w_c: [f64; 2],
    /// [K_t, c_vgt1 [%], c_vgt2 [%]].
    pub w_t: [f64; 3],
    /// [eta_sc, x_cv, h_tot [W/(m^2 K)]].
    pub t_em: [f64; 3],
}

impl Default for Step1Start {
    fn default() -> Self {
        Self {
            pi_egropt: 0.5,
            eta_tm: [0.7, 1000.0, 0.5],
            eta_c: [0.2, 0.8, 0.5],
            w_c: [0.2, 0.02],
            w_t: [1.5, 100.0, 100.0],
            t_em: [1.0, 0.5, 50.0],
        }
    }
}

/// Report of step 1: one [`FitReport`] per submodel.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step1Report {
    /// Submodel fits in the order W_ei, M_e, W_egr, eta_tm, W_t, T_em, eta_c, W_c.
    pub fits: Vec<FitReport>,
}

/// Step 1's parameters on or beyond an edge of step 5's box for them
/// ([`crate::tuning::complete::STATIC_PARAMS`] at the campaign's `scale`,
/// [`CampaignScale::apply`]; where step 1 bounds a search, Pi_egropt, W_copt, pi_copt, c_pi,
/// and c_egr1 <= [`C_EGR1_MAX`], its bounds are those boxes): (name, value, the bound). A value
/// there is where a search stopped, not an optimum the data show. Within 1e-6 of the box's
/// width counts as on it; physical limits (x_cv in [0, 1], peak efficiencies at most 1, lower
/// bounds 0) are not reported.
pub fn at_bounds(r: &Step1Report, scale: &CampaignScale) -> Vec<(String, f64, f64)> {
    let mut out = Vec::new();
    for (name, v) in r.fits.iter().flat_map(|f| &f.params) {
        let Some(b) = crate::tuning::complete::STATIC_PARAMS
            .iter()
            .find(|b| b.name == name)
            .map(|b| scale.apply(*b))
        else {
            continue;
        };
        // physical limits, where a value is no sign of a search stopped short: a fraction
        // (x_cv in [0, 1]), a peak efficiency at most 1, a quantity that cannot be negative
        // (lower bounds 0); and c_m2's upper bound, 0.999 w_tlin of the engine
        // (`complete::static_bounds`), not the box's
        let physical_hi = matches!(name.as_str(), "x_cv" | "eta_tmmax" | "eta_cmax" | "c_m2");
        let tol = 1e-6 * (b.hi - b.lo);
        if *v <= b.lo + tol && b.lo != 0.0 {
            out.push((name.clone(), *v, b.lo));
        } else if *v >= b.hi - tol && !physical_hi {
            out.push((name.clone(), *v, b.hi));
        }
    }
    out
}

/// Relative errors of eq. (4): mean and max of |meas - mod| / mean(meas).
pub fn rel_errors(meas: &[f64], model: &[f64]) -> (f64, f64) {
    let n = meas.len().max(1) as f64;
    let mean = meas.iter().sum::<f64>() / n;
    let mut sum = 0.0;
    let mut max: f64 = 0.0;
    for (a, b) in meas.iter().zip(model) {
        let e = ((a - b) / mean).abs();
        sum += e;
        max = max.max(e);
    }
    (sum / n, max)
}

/// Linear least squares `min ||A c - y||` with column scaling, via SVD (minimum norm).
pub fn linear_lsq(a: &DMatrix<f64>, y: &[f64]) -> Vec<f64> {
    let mut a = a.clone();
    let scale: Vec<f64> = (0..a.ncols())
        .map(|j| {
            let n = a.column(j).norm();
            if n > 0.0 {
                n
            } else {
                1.0
            }
        })
        .collect();
    for (j, s) in scale.iter().enumerate() {
        a.column_mut(j).scale_mut(1.0 / s);
    }
    let dim = a.nrows().max(a.ncols()) as f64;
    let Some(svd) = nalgebra::SVD::try_new(
        a,
        true,
        true,
        f64::EPSILON * 5.0,
        crate::numerics::SVD_MAX_ITER,
    ) else {
        // not converged (non-finite data): no fit, as when the solve fails below
        return vec![0.0; scale.len()];
    };
    let tol = f64::EPSILON * dim * svd.singular_values.max();
    let c = svd
        .solve(&DVector::from_column_slice(y), tol)
        .unwrap_or_else(|_| DVector::zeros(scale.len()));
    c.iter().zip(&scale).map(|(c, s)| c / s).collect()
}

pub(crate) fn fit_report(
    name: &str,
    params: Vec<(&str, f64)>,
    meas: &[f64],
    model: &[f64],
    n_eval: usize,
) -> FitReport {
    let (mean, max) = rel_errors(meas, model);
    FitReport {
        submodel: name.into(),
        params: params
            .into_iter()
            .map(|(n, v)| (n.to_string(), v))
            .collect(),
        mean_abs_rel_err: mean,
        max_abs_rel_err: max,
        n_points: meas.len(),
        n_eval,
    }
}

/// Quantities derived from a stationary point that several submodels use.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Derived {
    pub(crate) omega_t: f64,
    pub(crate) w_f: f64,
    pub(crate) w_ei: f64,
    pub(crate) w_egr: f64,
    pub(crate) w_t: f64,
    pub(crate) pi_t: f64,
    pub(crate) pi_c: f64,
}

pub(crate) fn derive(p: &Params, pts: &[StationaryPoint]) -> Result<Vec<Derived>, StepError> {
    pts.iter()
        .enumerate()
        .map(|(i, s)| {
            let w_f = cyl::w_f(&p.cylinder, s.u_delta, s.n_e);
            let w_ei = s.w_c / (1.0 - s.x_egr);
            if !w_ei.is_finite() {
                return Err(StepError::BadMeasurement {
                    submodel: "W_ei",
                    point: i,
                    what: "W_c / (1 - x_egr)",
                });
            }
            Ok(Derived {
                omega_t: s.n_t * PI / 30.0,
                w_f,
                w_ei,
                w_egr: s.w_c * s.x_egr / (1.0 - s.x_egr),
                w_t: s.w_c + w_f,
                pi_t: turb::pi_t(s.p_amb, s.p_em, SEM),
                pi_c: comp::pi_c(s.p_c, s.p_amb, SEM),
            })
        })
        .collect()
}

/// Stationary points step 1 needs: the most of its submodels fitted to them alone (eta_c's 7
/// parameters, [`fit_eta_c`]; W_c's 8 may include the settled ends of command steps).
pub const STEP1_MIN_POINTS: usize = 7;

pub(crate) fn need(submodel: &'static str, n: usize, needed: usize) -> Result<(), StepError> {
    if n < needed {
        Err(StepError::TooFewPoints {
            submodel,
            n,
            needed,
        })
    } else {
        Ok(())
    }
}

pub(crate) fn solver_err(submodel: &'static str) -> impl Fn(String) -> StepError {
    move |message| StepError::Solver { submodel, message }
}

pub(crate) fn lsq_opts() -> LsqOptions {
    LsqOptions {
        ftol: 1e-14,
        xtol: 1e-14,
        gtol: 1e-14,
        max_evaluations: Some(4000),
        finite_diff: super::lsq::FiniteDiff::Central,
        ..LsqOptions::default()
    }
}

/// Step 1: initialize every static submodel from stationary data. `base` supplies the
/// constants that are not tuned; the tuned fields are overwritten (their values in `base` are
/// never used as start values). Returns the new parameter set and the report.
pub fn step1(
    base: &Params,
    pts: &[StationaryPoint],
    start: &Step1Start,
) -> Result<(Params, Step1Report), StepError> {
    step1_with(base, pts, &[], start)
}

/// [`step1`] with further measured compressor flow points (`flow_extra`, e.g. the settled ends
/// of the dynamic sets' command steps, [`crate::tuning::settled`]) in the compressor-flow fit
/// ([`fit_w_c`]) next to the stationary points; the other submodels use the stationary points
/// only.
pub fn step1_with(
    base: &Params,
    pts: &[StationaryPoint],
    flow_extra: &[FlowPoint],
    start: &Step1Start,
) -> Result<(Params, Step1Report), StepError> {
    let flow = flow_points_with(pts, flow_extra);
    let mut p = base.clone();
    let fits = vec![
        fit_w_ei(&mut p, pts)?,
        fit_torque(&mut p, pts)?,
        fit_egr(&mut p, pts, start.pi_egropt)?,
        fit_eta_tm(&mut p, pts, start.eta_tm)?,
        fit_w_t(&mut p, pts, start.w_t)?,
        fit_t_em(&mut p, pts, start.t_em)?,
        fit_eta_c(&mut p, pts, start.eta_c)?,
        fit_w_c(&mut p, &flow, start.w_c)?,
    ];
    Ok((p, Step1Report { fits }))
}

/// Derived measurement and submodel prediction of every static submodel at the stationary
/// points, with the parameters `p` (no fitting): (name, measured, modelled), in the order
/// W_ei, M_e, W_egr, eta_tm, W_t, T_em, eta_c, W_c. The measurements are derived as in the
/// fits above (e.g. W_egr,meas = W_c x_egr / (1 - x_egr)).
pub type SubmodelSeries = (String, Vec<f64>, Vec<f64>);

/// Measured and modelled values of one submodel at the stationary points.
pub(crate) type Series = (Vec<f64>, Vec<f64>);

/// See [`SubmodelSeries`].
pub fn submodel_series(
    p: &Params,
    pts: &[StationaryPoint],
) -> Result<Vec<SubmodelSeries>, StepError> {
    let d = derive(p, pts)?;
    let all: [(&str, Series); 8] = [
        ("W_ei", cylinder::w_ei_series(p, pts, &d)),
        ("M_e", cylinder::torque_series(p, pts)),
        ("W_egr", egr::w_egr_series(p, pts, &d)),
        ("eta_tm", turbine::eta_tm_series(p, pts, &d)),
        ("W_t", turbine::w_t_series(p, pts, &d)),
        ("T_em", cylinder::t_em_series(p, pts, &d)),
        ("eta_c", compressor::eta_c_series(p, pts, &d)),
        ("W_c", compressor::w_c_series(p, pts, &d)),
    ];
    Ok(all
        .into_iter()
        .map(|(n, (meas, model))| (n.to_string(), meas, model))
        .collect())
}

/// The quantities the step-1 fits compare, (name, measured, modelled) per submodel in the order
/// of [`submodel_series`]: the same, except that eta_tm is compared in the T_c domain, as the
/// measured compressor temperature rise T_c - T_amb against the rise its model implies (eq.
/// (47) solved for T_c; `turbine::eta_tm_weights`). Step 5's submodel row uses these.
pub fn fit_series(p: &Params, pts: &[StationaryPoint]) -> Result<Vec<SubmodelSeries>, StepError> {
    let d = derive(p, pts)?;
    let mut all = submodel_series(p, pts)?;
    for s in all.iter_mut() {
        let (meas, model) = match s.0.as_str() {
            "eta_tm" => turbine::eta_tm_dt_series(p, pts, &d),
            _ => continue,
        };
        (s.1, s.2) = (meas, model);
    }
    Ok(all)
}

/// Bounded nonlinear least squares of `res` from each of `starts` ([`super::lsq`]); the fit
/// with the lowest cost is returned, its `n_eval` counting the evaluations of all starts.
/// Solver errors name `submodel`.
pub(crate) fn best_fit(
    submodel: &'static str,
    mut res: impl FnMut(&[f64]) -> Vec<f64>,
    starts: &[Vec<f64>],
    bounds: &Bounds,
    opts: &LsqOptions,
) -> Result<LsqResult, StepError> {
    let mut best: Option<LsqResult> = None;
    let mut n_eval = 0;
    for s0 in starts {
        let f = least_squares(&mut res, s0, bounds, opts)
            .map_err(|e| solver_err(submodel)(e.to_string()))?;
        n_eval += f.n_eval;
        if best.as_ref().is_none_or(|b| f.cost < b.cost) {
            best = Some(f);
        }
    }
    let mut fit = best.ok_or_else(|| solver_err(submodel)("no start".into()))?;
    fit.n_eval = n_eval;
    Ok(fit)
}
