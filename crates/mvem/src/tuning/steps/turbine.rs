//! Step 1, turbine submodels: efficiency (eqs (43)-(51)) and mass flow (eqs (52)-(56)).

use super::{
    derive, fit_report, lsq_opts, need, solver_err, Derived, FitReport, Series, StepError, SEM,
};
use crate::components::turbine;
use crate::params::Params;
use crate::tuning::data::StationaryPoint;
use crate::tuning::lsq::Bounds;
use crate::tuning::varpro::Varpro;
use nalgebra::DMatrix;

/// eta_tm,meas of eq. (47) with P_t eta_m = P_c at steady state,
/// W_c c_pa (T_c - T_amb) / (W_t c_pe T_em dh), and dh = 1 - Pi_t^(1 - 1/gamma_e).
fn eta_tm_meas(p: &Params, s: &StationaryPoint, d: &Derived) -> (f64, f64) {
    let g = &p.gas;
    let dh = 1.0 - d.pi_t.powf(1.0 - 1.0 / g.gamma_e);
    let eta = s.w_c * g.c_pa * (s.t_c - s.t_amb) / (d.w_t * g.c_pe * s.t_em * dh); // eq. (47)
    (eta, dh)
}

/// Weights of the eta_tm fit: dT_c/deta_tm = W_t c_pe T_em dh / (W_c c_pa) \[K\] at each point
/// (eq. (47) solved for T_c), so that the weighted residual (eta_tm,meas - eta_tm) w is the
/// error of the measured compressor temperature rise T_c - T_amb in kelvin (the "T_c domain").
/// eta_tm,meas is T_c - T_amb (a few kelvin at idle, 1 K sensor noise) divided by w: its noise
/// is 10-30 % at idle and below 1 % at full load, and an unweighted fit is decided by the idle
/// points (at the authors' c_m = 0 below c_m2 they fix eta_tm,max alone).
pub(crate) fn eta_tm_weights(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Vec<f64> {
    pts.iter()
        .zip(d)
        .map(|(s, d)| {
            let (eta, _) = eta_tm_meas(p, s, d);
            let w = (s.t_c - s.t_amb) / eta; // = W_t c_pe T_em dh / (W_c c_pa), eq. (47)
            if w.is_finite() {
                w.abs()
            } else {
                0.0
            }
        })
        .collect()
}

/// eta_tm,meas (eq. (47)) and the model of eqs (43)-(51) with the authors' limits.
pub(super) fn eta_tm_series(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Series {
    let g = &p.gas;
    pts.iter()
        .zip(d)
        .map(|(s, d)| {
            let pw = turbine::power(
                &p.turbine, g.c_pe, g.gamma_e, s.t_em, d.pi_t, d.omega_t, d.w_t, SEM,
            );
            (eta_tm_meas(p, s, d).0, pw.eta_tm)
        })
        .unzip()
}

/// Blade speed ratio BSR (eq. (50)) and turbine speed omega_t [rad/s] at each stationary
/// point, from the measurements and the constants of `p` (NaN where not defined): the
/// regressors of the turbine-efficiency fit.
pub fn bsr_series(p: &Params, pts: &[StationaryPoint]) -> Vec<(f64, f64)> {
    let Ok(d) = derive(p, pts) else {
        return vec![(f64::NAN, f64::NAN); pts.len()];
    };
    pts.iter()
        .zip(&d)
        .map(|(s, d)| {
            let (_, dh) = eta_tm_meas(p, s, d);
            let bsr = p.turbine.r_t * d.omega_t / (2.0 * p.gas.c_pe * s.t_em * dh).sqrt(); // eq. (50)
            (bsr, d.omega_t)
        })
        .collect()
}

/// The eta_tm fit in the T_c domain: the measured compressor temperature rise T_c - T_amb
/// and the one the model implies, eta_tm [`eta_tm_weights`] (eq. (47) solved for T_c).
pub(super) fn eta_tm_dt_series(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Series {
    let (_, model) = eta_tm_series(p, pts, d);
    let w = eta_tm_weights(p, pts, d);
    pts.iter()
        .zip(model.iter().zip(&w))
        .map(|(s, (m, w))| (s.t_c - s.t_amb, m * w))
        .unzip()
}

/// W_t,meas = W_c + W_f and the model of eqs (52)-(56).
pub(super) fn w_t_series(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Series {
    let t = &p.turbine;
    pts.iter()
        .zip(d)
        .map(|(s, d)| {
            let fv = turbine::f_vgt(t, s.u_vgt, SEM);
            let f_pi = turbine::f_pi_t(t, d.pi_t);
            (d.w_t, turbine::w_t(t, s.p_em, s.t_em, p.gas.r_e, f_pi, fv))
        })
        .unzip()
}

/// c_m(omega_t) / c_m1 of the authors' implementation (eq. (51), item 33), c_mlin tied to c_m1.
fn c_m_shape(omega: f64, c_m2: f64, c_m3: f64, w_tlin: f64) -> f64 {
    let w = omega.max(c_m2);
    if w < w_tlin {
        (w_tlin - c_m2).powf(c_m3) * (w - c_m2) / (w_tlin - c_m2)
    } else {
        (w - c_m2).powf(c_m3)
    }
}

/// Turbine efficiency, eqs (43)-(51): varpro with BSR_opt, c_m2, c_m3 nonlinear and
/// eta_tm,max, c_m1 linear; eta_tm,meas by eq. (47) with P_t eta_m = P_c at steady state:
/// W_c c_pa (T_c - T_amb) / (W_t c_pe T_em (1 - Pi_t^(1 - 1/gamma_e))), W_t = W_c + W_f.
/// Weighted by `eta_tm_weights`: least squares of the measured T_c, not of the derived
/// eta_tm,meas.
pub fn fit_eta_tm(
    p: &mut Params,
    pts: &[StationaryPoint],
    start: [f64; 3],
) -> Result<FitReport, StepError> {
    need("eta_tm", pts.len(), 5)?;
    let d = derive(p, pts)?;
    let g = &p.gas;
    let mut y = Vec::with_capacity(pts.len());
    let mut bsr = Vec::with_capacity(pts.len());
    for (i, (s, d)) in pts.iter().zip(&d).enumerate() {
        let (eta, dh) = eta_tm_meas(p, s, d);
        let b = p.turbine.r_t * d.omega_t / (2.0 * g.c_pe * s.t_em * dh).sqrt(); // eq. (50)
        if !eta.is_finite() || !b.is_finite() {
            return Err(StepError::BadMeasurement {
                submodel: "eta_tm",
                point: i,
                what: "eta_tm,meas or BSR",
            });
        }
        y.push(eta);
        bsr.push(b);
    }
    let w_tlin = p.turbine.w_tlin;
    let omega: Vec<f64> = d.iter().map(|d| d.omega_t).collect();
    // residuals in the T_c domain (kelvin), see eta_tm_weights
    let wts = eta_tm_weights(p, pts, &d);
    let phi = |a: &[f64]| {
        DMatrix::from_fn(pts.len(), 2, |i, j| {
            if j == 0 {
                1.0
            } else {
                let db = bsr[i] - a[0];
                -c_m_shape(omega[i], a[1], a[2], w_tlin) * db * db // eq. (49)
            }
        })
    };
    let hi_cm2 = 0.999 * w_tlin;
    // c_m2 and c_m3 are weakly identified (c_m is nearly flat in omega_t for small c_m3): a
    // single start often ends in a local minimum, so the search is repeated from a small grid
    // around the start (c_m2 at fractions of its upper bound, c_m3 scaled) and the best
    // physically valid fit kept (with noisy data the lowest residual can have eta_tm,max > 1).
    let mut best: Option<crate::tuning::varpro::VarproResult> = None;
    let mut n_eval = 0;
    for f2 in [start[1] / hi_cm2, 0.2, 0.6, 0.9, 0.98] {
        for f3 in [1.0, 0.1, 0.03] {
            let s0 = [
                start[0],
                (f2 * hi_cm2).clamp(0.0, 0.999 * hi_cm2),
                start[2] * f3,
            ];
            let r = Varpro::new(&y, phi)
                .weights(&wts)
                .bounds(Bounds::new(vec![0.2, 0.0, 1e-4], vec![2.0, hi_cm2, 3.0]))
                .options(lsq_opts())
                .fit(&s0);
            if let Ok(r) = r {
                n_eval += r.lsq.n_eval;
                // a physically valid fit (eta_tm,max <= 1, c_m1 >= 0; parameter validation)
                // beats an invalid one whatever the residuals, then the lower residual wins
                let valid = |r: &crate::tuning::varpro::VarproResult| {
                    r.c[0] > 0.0 && r.c[0] <= 1.0 && r.c[1] >= 0.0
                };
                if best
                    .as_ref()
                    .is_none_or(|b| (valid(&r), -r.residual_norm) > (valid(b), -b.residual_norm))
                {
                    best = Some(r);
                }
            }
        }
    }
    let fit = best.ok_or_else(|| solver_err("eta_tm")("no start converged".into()))?;
    // [eta_tmmax, bsr_opt, c_m1, c_m2, c_m3]
    let mut th = [fit.c[0], fit.alpha[0], fit.c[1], fit.alpha[1], fit.alpha[2]];
    if !(th[0] > 0.0 && th[0] <= 1.0 && th[2] >= 0.0) {
        // no valid varpro fit: all five by bounded NLS (eta_tm,max <= 1, c_m1 >= 0) from the
        // best fit moved into the bounds
        let res = |a: &[f64]| -> Vec<f64> {
            (0..pts.len())
                .map(|i| {
                    let db = bsr[i] - a[1];
                    wts[i]
                        * (a[0] - a[2] * c_m_shape(omega[i], a[3], a[4], w_tlin) * db * db - y[i])
                })
                .collect()
        };
        let lo = [0.3, 0.2, 0.0, 0.0, 1e-4];
        let hi = [1.0, 2.0, 10.0, hi_cm2, 3.0];
        let s0: Vec<f64> = (0..5)
            .map(|k| th[k].clamp(lo[k], hi[k] - 1e-6 * (hi[k] - lo[k])))
            .collect();
        let r = super::best_fit(
            "eta_tm",
            res,
            &[s0],
            &Bounds::new(lo.to_vec(), hi.to_vec()),
            &lsq_opts(),
        )?;
        n_eval += r.n_eval;
        th.copy_from_slice(&r.theta);
    }
    let t = &mut p.turbine;
    t.bsr_opt = th[1];
    t.c_m = [th[2], th[3], th[4]];
    t.eta_tmmax = th[0];
    t.c_mlin = t.c_m[0] * (t.w_tlin - t.c_m[1]).powf(t.c_m[2]);
    let model: Vec<f64> = (0..pts.len())
        .map(|i| {
            let db = bsr[i] - t.bsr_opt;
            t.eta_tmmax - turbine::c_m(t, omega[i], SEM) * db * db
        })
        .collect();
    Ok(fit_report(
        "eta_tm",
        vec![
            ("eta_tmmax", t.eta_tmmax),
            ("bsr_opt", t.bsr_opt),
            ("c_m1", t.c_m[0]),
            ("c_m2", t.c_m[1]),
            ("c_m3", t.c_m[2]),
        ],
        &y,
        &model,
        n_eval,
    ))
}

/// Turbine flow, eqs (52)-(56): W_t,meas = W_c + W_f; K_t, c_vgt1, c_vgt2 nonlinear,
/// c_f1, c_f2 linear (variable projection).
pub fn fit_w_t(
    p: &mut Params,
    pts: &[StationaryPoint],
    start: [f64; 3],
) -> Result<FitReport, StepError> {
    need("W_t", pts.len(), 6)?;
    let d = derive(p, pts)?;
    let y: Vec<f64> = d.iter().map(|d| d.w_t).collect();
    let base = p.turbine.clone();
    let r_e = p.gas.r_e;
    let phi = |a: &[f64]| {
        let mut t = base.clone();
        t.k_t = a[0];
        DMatrix::from_fn(pts.len(), 2, |i, j| {
            let s = &pts[i];
            let g = t.a_vgtmax * s.p_em * turbine::f_pi_t(&t, d[i].pi_t) / (s.t_em * r_e).sqrt(); // eqs (53), (55)
            if j == 0 {
                let z = (s.u_vgt - a[2]) / a[1];
                g * (1.0 - z * z).max(0.0).sqrt() // eq. (56): c_f1 term
            } else {
                g // c_f2 term
            }
        })
    };
    let fit = Varpro::new(&y, phi)
        .bounds(Bounds::new(vec![1.0, 10.0, 0.0], vec![6.0, 1000.0, 400.0]))
        .options(lsq_opts())
        .fit(&start)
        .map_err(|e| solver_err("W_t")(e.to_string()))?;
    let t = &mut p.turbine;
    t.k_t = fit.alpha[0];
    t.c_vgt1 = fit.alpha[1];
    t.c_vgt2 = fit.alpha[2];
    t.c_f1 = fit.c[0];
    t.c_f2 = fit.c[1];
    let (meas, model) = w_t_series(p, pts, &d);
    Ok(fit_report(
        "W_t",
        vec![
            ("k_t", p.turbine.k_t),
            ("c_f1", p.turbine.c_f1),
            ("c_f2", p.turbine.c_f2),
            ("c_vgt1", p.turbine.c_vgt1),
            ("c_vgt2", p.turbine.c_vgt2),
        ],
        &meas,
        &model,
        fit.lsq.n_eval,
    ))
}
