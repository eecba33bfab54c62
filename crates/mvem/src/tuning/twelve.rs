//! Tuning of the 12-state model (paper section 9.2.1), three steps after the 8-state tuning:
//!
//! 1. [`fit_k_ic`]: k_ic by linear least squares of the intercooler pressure drop. Eq. (86)
//!    solved for the drop, `p_c - p_im = k_ic W_ic^2 T_ic / p_c`, is linear in k_ic. At a
//!    stationary point W_ic = W_c (mass balance of the volume before the intercooler, eq. (85))
//!    and T_ic = T_c (the adiabatic volume's energy balance with equal in- and out-flow), so
//!    with the measured p_c, p_im, W_c, T_c: `k_ic = sum(phi y) / sum(phi^2)`,
//!    `y = p_c,meas - p_im,meas`, `phi = W_c^2 T_c / p_c,meas`.
//! 2. V_ic, V_im, V_em, J_t by the problem (74)-(75) with the 12-state model
//!    ([`super::complete::fit_dynamic`]), started from the 8-state values and [`V_IC_START`].
//! 3. The static parameters and k_ic by (74), (77) with the 12-state model, N = 8,
//!    z_8 = W_ic (eq. (86) at the measured p_c, p_im, T_c against the measured W_c) and
//!    beta = [`BETA_12`] ([`super::complete::step5`] with `model` = 12).
//!
//! The pipeline ([`super::pipeline`]) runs them with `PipelineOptions::model` = 12.

use super::complete::CompleteReport;
use super::data::StationaryPoint;
use super::steps::{rel_errors, FitReport, StepError};
use super::uncertainty::Combination;
use crate::components::intercooler;
use crate::params::Params;

/// beta of the third step (section 9.2.1).
pub const BETA_12: f64 = 2.58;

/// Start and bounds of V_ic [m^3] in the second step for the published engine: start 10 dm^3
/// (not the default 18 dm^3), bounds 1-200 dm^3; the pipeline scales them to another engine by
/// its displacement, V_d / [`super::complete::PUBLISHED_V_D`], as step 3's volumes.
pub const V_IC_START: [f64; 3] = [0.01, 0.001, 0.2];

/// Measured W_ic (= W_c at a stationary point) and eq. (86) at the measured p_c, p_im and
/// T_ic = T_c with the parameters `p` [kg/s]; z_8 of section 9.2.1.
pub fn w_ic_series(p: &Params, pts: &[StationaryPoint]) -> (Vec<f64>, Vec<f64>) {
    pts.iter()
        .map(|s| {
            (
                s.w_c,
                intercooler::w_ic(&p.intercooler, s.p_c, s.t_c, s.p_im, s.t_im), // eq. (86)
            )
        })
        .unzip()
}

/// First step of section 9.2.1: k_ic [Pa^2 s^2/(K kg^2)] by linear least squares of
/// p_c - p_im (module documentation). The report's errors are those of the pressure drop.
pub fn fit_k_ic(pts: &[StationaryPoint]) -> Result<(f64, FitReport), StepError> {
    const NAME: &str = "k_ic (eq. (86))";
    if pts.is_empty() {
        return Err(StepError::TooFewPoints {
            submodel: NAME,
            n: 0,
            needed: 1,
        });
    }
    let y: Vec<f64> = pts.iter().map(|s| s.p_c - s.p_im).collect();
    let phi: Vec<f64> = pts.iter().map(|s| s.w_c * s.w_c * s.t_c / s.p_c).collect();
    if let Some(i) = phi.iter().chain(&y).position(|v| !v.is_finite()) {
        return Err(StepError::BadMeasurement {
            submodel: NAME,
            point: i % pts.len(),
            what: "p_c, p_im, W_c or T_c",
        });
    }
    let (sy, ss) = phi
        .iter()
        .zip(&y)
        .fold((0.0, 0.0), |(a, b), (f, v)| (a + f * v, b + f * f));
    if ss <= 0.0 {
        return Err(StepError::Solver {
            submodel: NAME,
            message: "no compressor flow at any stationary point".into(),
        });
    }
    let k = sy / ss;
    if k.is_nan() || k <= 0.0 {
        return Err(StepError::Solver {
            submodel: NAME,
            message: format!(
                "k_ic = {k:.4e} <= 0: the measured p_c is not above p_im (no intercooler drop \
                 in the data; is p_c measured before the intercooler?)"
            ),
        });
    }
    let model: Vec<f64> = phi.iter().map(|f| k * f).collect();
    let (mean, max) = rel_errors(&y, &model);
    Ok((
        k,
        FitReport {
            submodel: "p_c - p_im".into(),
            params: vec![("k_ic".into(), k)],
            mean_abs_rel_err: mean,
            max_abs_rel_err: max,
            n_points: pts.len(),
            n_eval: 0,
        },
    ))
}

/// V_ic + V_im [m^3], the intake-side volume in series with the small intercooler restriction,
/// with its standard error from step 7's covariance (`r`, the report of `complete::fit_dynamic`
/// on the 12-state model): `var(V_ic + V_im) = var V_ic + var V_im + 2 cov(V_ic, V_im)`.
/// Under noise the data determine the sum while V_ic and V_im trade against each other
/// (docs/tuning.md, "The 12-state model"). The covariance is step 7's own, conditional on the
/// static parameters it holds fixed. `None` when the report has no linearization with both or
/// the variance is not finite and positive.
pub fn intake_volume(r: &CompleteReport) -> Option<Combination> {
    let lin = r.linearization.as_ref()?;
    let at = |n: &str| lin.names.iter().position(|x| x == n);
    let (a, b) = (at("v_ic")?, at("v_im")?);
    let value_of = |n: &str| r.params.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
    let (v_ic, v_im) = (value_of("v_ic")?, value_of("v_im")?);
    let c = &lin.covariance;
    let var = c[(a, a)] + c[(b, b)] + 2.0 * c[(a, b)];
    if !(var.is_finite() && var > 0.0) {
        return None;
    }
    let corr = c[(a, b)] / (c[(a, a)] * c[(b, b)]).sqrt();
    Some(Combination {
        name: "intake.v_ic_plus_v_im".into(),
        description: format!(
            "V_ic + V_im [m^3] (step {}: V_ic {v_ic:.4e}, V_im {v_im:.4e}, correlation \
             {corr:.3}): the intake-side volume the data determine when V_ic and V_im trade \
             against each other; standard error from var V_ic + var V_im + 2 cov, conditional on \
             the static parameters",
            r.step
        ),
        at: Vec::new(),
        value: v_ic + v_im,
        std_error: var.sqrt(),
    })
}
