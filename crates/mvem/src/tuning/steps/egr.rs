//! Step 1, EGR valve flow (eqs (32)-(38)).

use super::{
    derive, fit_report, lsq_opts, need, solver_err, Derived, FitReport, Series, StepError, SEM,
};
use crate::components::egr;
use crate::params::Params;
use crate::tuning::data::StationaryPoint;
use crate::tuning::lsq::Bounds;
use crate::tuning::varpro::Varpro;
use nalgebra::DMatrix;

/// W_egr,meas = W_c x_egr / (1 - x_egr) and the model of eqs (32)-(38).
pub(super) fn w_egr_series(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Series {
    pts.iter()
        .zip(d)
        .map(|(s, d)| {
            let f = egr::egr_flow(
                &p.egr_valve,
                s.p_im,
                s.p_em,
                s.t_em,
                p.gas.r_e,
                s.u_egr,
                SEM,
            );
            (d.w_egr, f.w_egr)
        })
        .unzip()
}

/// Largest c_egr1 step 1 gives (the upper bound of step 5's box, `complete::STATIC_PARAMS`):
/// eq. (38) needs c_egr1 < 0.
pub const C_EGR1_MAX: f64 = -1e-8;

/// EGR flow, eqs (32)-(38): varpro with Pi_egropt nonlinear, c_egr linear, c_egr1 at most
/// [`C_EGR1_MAX`]; W_egr,meas = W_c x_egr / (1 - x_egr).
pub fn fit_egr(
    p: &mut Params,
    pts: &[StationaryPoint],
    start: f64,
) -> Result<FitReport, StepError> {
    need("W_egr", pts.len(), 4)?;
    let d = derive(p, pts)?;
    let y: Vec<f64> = d.iter().map(|d| d.w_egr).collect();
    let base = p.egr_valve.clone();
    let r_e = p.gas.r_e;
    let phi = |alpha: &[f64]| {
        let mut v = base.clone();
        v.pi_egropt = alpha[0];
        DMatrix::from_fn(pts.len(), 3, |i, j| {
            let s = &pts[i];
            let pi = egr::pi_egr(&v, s.p_im, s.p_em); // eq. (35)
            let psi = egr::psi_egr(&v, pi); // eq. (34)
            let g = v.a_egrmax * s.p_em * psi / (s.t_em * r_e).sqrt(); // eqs (32), (37)
            g * s.u_egr.powi(2 - j as i32) // eq. (38)
        })
    };
    let fit = Varpro::new(&y, phi)
        .bounds(Bounds::new(vec![0.05], vec![0.99]))
        .options(lsq_opts())
        .fit(&[start])
        .map_err(|e| solver_err("W_egr")(e.to_string()))?;
    let mut c = [fit.c[0], fit.c[1], fit.c[2]];
    let mut alpha = fit.alpha[0];
    let mut n_eval = fit.lsq.n_eval;
    if c[0] >= C_EGR1_MAX {
        // eq. (38) needs c_egr1 < 0 (its area has a maximum at -c_egr2 / (2 c_egr1)); few
        // points with EGR can put the unconstrained optimum at c_egr1 >= 0 (QA: 8-10
        // stationary points gave +2.8e-5, and the tuned file was refused). The least-squares
        // problem is convex in c, so the constrained optimum has c_egr1 on its bound
        // C_EGR1_MAX: c_egr2, c_egr3 and Pi_egropt are refitted with the quadratic term
        // dropped (C_EGR1_MAX u_egr^2 is below 1e-4 of a flow coefficient at 100 %), and
        // [`super::at_bounds`] reports it.
        let phi2 = |alpha: &[f64]| {
            let m = phi(alpha);
            m.columns(1, 2).into_owned()
        };
        let fit2 = Varpro::new(&y, phi2)
            .bounds(Bounds::new(vec![0.05], vec![0.99]))
            .options(lsq_opts())
            .fit(&[alpha])
            .map_err(|e| solver_err("W_egr")(e.to_string()))?;
        c = [C_EGR1_MAX, fit2.c[0], fit2.c[1]];
        alpha = fit2.alpha[0];
        n_eval += fit2.lsq.n_eval;
    }
    p.egr_valve.pi_egropt = alpha;
    p.egr_valve.c_egr = c;
    let (meas, model) = w_egr_series(p, pts, &d);
    Ok(fit_report(
        "W_egr",
        vec![
            ("pi_egropt", alpha),
            ("c_egr1", c[0]),
            ("c_egr2", c[1]),
            ("c_egr3", c[2]),
        ],
        &meas,
        &model,
        n_eval,
    ))
}
