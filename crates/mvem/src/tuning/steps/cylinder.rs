//! Step 1, cylinder submodels: volumetric efficiency (eqs (11)-(12)), torque (eqs (26)-(31)) and
//! exhaust manifold temperature (eqs (17)-(25)).

use super::{
    best_fit, derive, fit_report, linear_lsq, lsq_opts, need, Derived, FitReport, Series,
    StepError, SEM,
};
use crate::components::cylinder;
use crate::params::Params;
use crate::tuning::data::StationaryPoint;
use crate::tuning::lsq::Bounds;
use nalgebra::DMatrix;
use std::f64::consts::PI;

/// W_ei,meas = W_c / (1 - x_egr) and the model of eqs (11)-(12).
pub(super) fn w_ei_series(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Series {
    pts.iter()
        .zip(d)
        .map(|(s, d)| {
            let ev = cylinder::eta_vol(&p.cylinder, s.p_im, s.n_e);
            (
                d.w_ei,
                cylinder::w_ei(&p.cylinder, ev, s.p_im, s.n_e, p.gas.r_a, s.t_im),
            )
        })
        .unzip()
}

/// Measured torque and the model of eqs (26)-(31) (lambda_O >= 1).
pub(super) fn torque_series(p: &Params, pts: &[StationaryPoint]) -> Series {
    let cc = cylinder::CylinderConsts::new(&p.gas, &p.cylinder);
    pts.iter()
        .map(|s| {
            let m = cylinder::torque(&p.cylinder, &cc, s.u_delta, s.n_e, s.p_im, s.p_em, 1.0, SEM);
            (s.m_e, m)
        })
        .unzip()
}

/// Measured T_em and the model of eqs (17)-(25).
pub(super) fn t_em_series(p: &Params, pts: &[StationaryPoint], d: &[Derived]) -> Series {
    pts.iter()
        .zip(d)
        .map(|(s, d)| (s.t_em, t_em_model(p, s, d)))
        .unzip()
}

/// Volumetric efficiency, eqs (11)-(12): linear LS of W_ei = W_c / (1 - x_egr).
pub fn fit_w_ei(p: &mut Params, pts: &[StationaryPoint]) -> Result<FitReport, StepError> {
    need("W_ei", pts.len(), 3)?;
    let d = derive(p, pts)?;
    let cyl = &p.cylinder;
    let r_a = p.gas.r_a;
    let k: Vec<f64> = pts
        .iter()
        .map(|s| s.p_im * s.n_e * cyl.v_d / (120.0 * r_a * s.t_im)) // eq. (11)
        .collect();
    let a = DMatrix::from_fn(pts.len(), 3, |i, j| match j {
        0 => k[i] * pts[i].p_im.sqrt(), // eq. (12)
        1 => k[i] * pts[i].n_e.sqrt(),
        _ => k[i],
    });
    let y: Vec<f64> = d.iter().map(|d| d.w_ei).collect();
    let c = linear_lsq(&a, &y);
    p.cylinder.c_vol = [c[0], c[1], c[2]];
    let (meas, model) = w_ei_series(p, pts, &d);
    Ok(fit_report(
        "W_ei",
        vec![("c_vol1", c[0]), ("c_vol2", c[1]), ("c_vol3", c[2])],
        &meas,
        &model,
        0,
    ))
}

/// Torque, eqs (26)-(31): linear LS of M_e + M_p = M_e + V_d (p_em - p_im) / (4 pi) in
/// eta_igch and c_fric (lambda_O >= 1 assumed at the stationary points).
pub fn fit_torque(p: &mut Params, pts: &[StationaryPoint]) -> Result<FitReport, StepError> {
    need("M_e", pts.len(), 4)?;
    let cyl = p.cylinder.clone();
    let cc = cylinder::CylinderConsts::new(&p.gas, &cyl);
    let f = 1.0 / (4.0 * PI);
    let a = DMatrix::from_fn(pts.len(), 4, |i, j| {
        let s = &pts[i];
        let n = s.n_e / 1000.0;
        match j {
            0 => s.u_delta * 1e-6 * cyl.n_cyl * cyl.q_hv * cc.otto_factor * f, // eqs (28)-(29)
            1 => -cyl.v_d * 1e5 * n * n * f,                                   // eqs (30)-(31)
            2 => -cyl.v_d * 1e5 * n * f,
            _ => -cyl.v_d * 1e5 * f,
        }
    });
    let y: Vec<f64> = pts
        .iter()
        .map(|s| s.m_e + cyl.v_d * (s.p_em - s.p_im) * f)
        .collect();
    let c = linear_lsq(&a, &y);
    p.cylinder.eta_igch = c[0];
    p.cylinder.c_fric = [c[1], c[2], c[3]];
    let (meas, model) = torque_series(p, pts);
    Ok(fit_report(
        "M_e",
        vec![
            ("eta_igch", c[0]),
            ("c_fric1", c[1]),
            ("c_fric2", c[2]),
            ("c_fric3", c[3]),
        ],
        &meas,
        &model,
        0,
    ))
}

fn t_em_model(p: &Params, s: &StationaryPoint, d: &Derived) -> f64 {
    let cc = cylinder::CylinderConsts::new(&p.gas, &p.cylinder);
    let inp = cylinder::SeligerInputs {
        pi_e: s.p_em / s.p_im, // eq. (18)
        w_f: d.w_f,
        w_ei: d.w_ei,
        t_im: s.t_im,
    };
    let fp = cylinder::cylinder_out_temp_converged(&p.gas, &p.cylinder, &cc, &inp, SEM); // eq. (24)
    cylinder::exhaust_temp_drop(
        &p.exhaust_pipe,
        p.gas.c_pe,
        s.t_amb,
        fp.t_e,
        d.w_ei + d.w_f,
        SEM,
    ) // eq. (25)
}

/// Exhaust manifold temperature, eqs (17)-(25): bounded NLS in eta_sc, x_cv, h_tot with
/// W_ei = W_c / (1 - x_egr) and W_f from eq. (13).
pub fn fit_t_em(
    p: &mut Params,
    pts: &[StationaryPoint],
    start: [f64; 3],
) -> Result<FitReport, StepError> {
    need("T_em", pts.len(), 4)?;
    let d = derive(p, pts)?;
    let y: Vec<f64> = pts.iter().map(|s| s.t_em).collect();
    let mut q = p.clone();
    let set = |q: &mut Params, th: &[f64]| {
        q.cylinder.eta_sc = th[0];
        q.cylinder.x_cv = th[1];
        q.exhaust_pipe.h_tot = th[2];
    };
    let res = |th: &[f64]| {
        set(&mut q, th);
        pts.iter()
            .zip(&d)
            .zip(&y)
            .map(|((s, d), y)| (t_em_model(&q, s, d) - y) / 100.0)
            .collect::<Vec<f64>>()
    };
    let fit = best_fit(
        "T_em",
        res,
        &[start.to_vec()],
        &Bounds::new(vec![0.3, 0.0, 0.0], vec![2.0, 1.0, 2000.0]),
        &lsq_opts(),
    )?;
    set(p, &fit.theta);
    let (meas, model) = t_em_series(p, pts, &d);
    Ok(fit_report(
        "T_em",
        vec![
            ("eta_sc", fit.theta[0]),
            ("x_cv", fit.theta[1]),
            ("h_tot", fit.theta[2]),
        ],
        &meas,
        &model,
        fit.n_eval,
    ))
}
