//! EGR valve: mass flow (section 5.1, eqs (32)-(38)) and actuator (section 5.2, eqs (39)-(41)).

use super::{poly2, Semantics};
use crate::params::{EgrActuator, EgrValve};

/// Signals of the EGR valve flow model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgrFlow {
    /// EGR mass flow W_egr [kg/s], eq. (32).
    pub w_egr: f64,
    /// Limited pressure ratio Pi_egr [-], eq. (35).
    pub pi_egr: f64,
    /// Parabolic flow function Psi_egr [-], eq. (34).
    pub psi_egr: f64,
    /// Effective area ratio f_egr [-], eq. (38).
    pub f_egr: f64,
}

/// Pressure ratio over the valve, eq. (35): p_im/p_em limited to [Pi_egropt, 1] (choked flow
/// below, no back flow above; item 22).
#[inline]
pub fn pi_egr(v: &EgrValve, p_im: f64, p_em: f64) -> f64 {
    (p_im / p_em).clamp(v.pi_egropt, 1.0)
}

/// Parabolic flow function, eq. (34): 1 - ((1 - Pi_egr)/(1 - Pi_egropt) - 1)^2.
#[inline]
pub fn psi_egr(v: &EgrValve, pi_egr: f64) -> f64 {
    let a = (1.0 - pi_egr) / (1.0 - v.pi_egropt) - 1.0;
    1.0 - a * a
}

/// Effective area ratio, eq. (38): the polynomial c_egr1 u^2 + c_egr2 u + c_egr3 up to its
/// vertex u = -c_egr2/(2 c_egr1), constant above. The authors clamp the result at 0 (item 23),
/// which matters when the overshooting actuator output is negative. `u_egr` in %.
#[inline]
pub fn f_egr(v: &EgrValve, u_egr: f64, sem: Semantics) -> f64 {
    let vertex = -v.c_egr[1] / (2.0 * v.c_egr[0]);
    let f = poly2(&v.c_egr, u_egr.min(vertex)); // eq. (38)
    if sem.authors() {
        f.max(0.0)
    } else {
        f
    }
}

/// EGR mass flow, eqs (32)-(38): W_egr = A_egrmax f_egr p_em Psi_egr / sqrt(T_em R_e).
/// Pressures in Pa, T_em in K, `u_egr` (the actuator output) in %.
#[inline]
pub fn egr_flow(
    v: &EgrValve,
    p_im: f64,
    p_em: f64,
    t_em: f64,
    r_e: f64,
    u_egr: f64,
    sem: Semantics,
) -> EgrFlow {
    let pi_egr = pi_egr(v, p_im, p_em);
    let psi_egr = psi_egr(v, pi_egr);
    let f_egr = f_egr(v, u_egr, sem);
    let a_egr = v.a_egrmax * f_egr; // eq. (37)
    EgrFlow {
        w_egr: a_egr * p_em * psi_egr / (t_em * r_e).sqrt(), // eq. (32)
        pi_egr,
        psi_egr,
        f_egr,
    }
}

/// EGR actuator output, eq. (39): u_egr = K_egr u_egr1 - (K_egr - 1) u_egr2 [%].
#[inline]
pub fn actuator_output(a: &EgrActuator, u_egr1: f64, u_egr2: f64) -> f64 {
    a.k_egr * u_egr1 - (a.k_egr - 1.0) * u_egr2
}

/// EGR actuator state derivatives, eqs (40)-(41), driven by the delayed command
/// u_egr(t - tau_degr) [%]. Returns (du_egr1/dt, du_egr2/dt) [%/s].
#[inline]
pub fn actuator_derivatives(
    a: &EgrActuator,
    u_delayed: f64,
    u_egr1: f64,
    u_egr2: f64,
) -> (f64, f64) {
    (
        (u_delayed - u_egr1) / a.tau_egr1, // eq. (40)
        (u_delayed - u_egr2) / a.tau_egr2, // eq. (41)
    )
}

/// EGR actuator unit step response of eqs (39)-(41) [-]: the output `s` seconds after a
/// unit step of the (undelayed, saturated) command, from rest:
/// K_egr (1 - e^(-s'/tau_egr1)) - (K_egr - 1)(1 - e^(-s'/tau_egr2)), s' = s - tau_degr (0 for
/// s' <= 0). Used with [`super::actuator::position`] by the actuator fit and the virtual test cell.
pub fn actuator_step_response(a: &EgrActuator, s: f64) -> f64 {
    let s = s - a.tau_degr;
    if s <= 0.0 {
        return 0.0;
    }
    a.k_egr * (1.0 - (-s / a.tau_egr1).exp()) - (a.k_egr - 1.0) * (1.0 - (-s / a.tau_egr2).exp())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;

    #[test]
    fn area_polynomial_by_hand() {
        let p = Params::published();
        let v = &p.egr_valve;
        // vertex at -0.0177806/(2 * -0.000111042) = 80.0625 %
        let vertex = -v.c_egr[1] / (2.0 * v.c_egr[0]);
        assert!((vertex - 80.0625).abs() < 1e-3, "{vertex}");
        // f(40) = -0.000111042*1600 + 0.0177806*40 = -0.177668 + 0.711224 = 0.533557
        assert!((f_egr(v, 40.0, Semantics::Authors) - 0.5335564).abs() < 1e-6);
        // above the vertex the area is constant
        assert_eq!(
            f_egr(v, 90.0, Semantics::Authors),
            f_egr(v, 100.0, Semantics::Authors)
        );
        // negative (overshooting) actuator output: clamp at 0 for the authors only
        assert_eq!(f_egr(v, -5.0, Semantics::Authors), 0.0);
        assert!(f_egr(v, -5.0, Semantics::Paper) < 0.0);
    }

    #[test]
    fn flow_function_limits() {
        let p = Params::published();
        let v = &p.egr_valve;
        // choked: Psi = 1 at and below Pi_egropt; no back flow: Psi = 0 at Pi >= 1.
        assert_eq!(psi_egr(v, pi_egr(v, 1.0e5, 3.0e5)), 1.0);
        assert_eq!(psi_egr(v, pi_egr(v, 2.0e5, 1.9e5)), 0.0);
        // halfway: Pi = (1 + Pi_opt)/2 -> a = 0.5 - 1 -> Psi = 0.75
        let mid = 0.5 * (1.0 + v.pi_egropt);
        assert!((psi_egr(v, mid) - 0.75).abs() < 1e-12);
        let f = egr_flow(v, 1.0e5, 2.0e5, 800.0, 286.0, 40.0, Semantics::Authors);
        let expect = 4e-4 * f.f_egr * 2.0e5 * 1.0 / (800.0f64 * 286.0).sqrt();
        assert!((f.w_egr - expect).abs() < 1e-15);
    }

    #[test]
    fn actuator_overshoot_gain() {
        let p = Params::published();
        // K_egr = 1.8: u = 1.8 u1 - 0.8 u2
        assert!((actuator_output(&p.egr_actuator, 10.0, 5.0) - 14.0).abs() < 1e-12);
        let (d1, d2) = actuator_derivatives(&p.egr_actuator, 20.0, 10.0, 10.0);
        assert!((d1 - 200.0).abs() < 1e-9 && (d2 - 10.0 / 0.13).abs() < 1e-9);
    }
}
