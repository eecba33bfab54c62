//! Compressor: efficiency (section 6.3.1, eqs (58)-(65)) and mass flow (section 6.3.2,
//! eqs (66)-(72)).

use super::{poly2, pow_ln, Semantics};
use crate::params::Compressor;
use std::f64::consts::PI;

/// Compressor pressure ratio Pi_c = p_im/p_amb, eq. (59); the authors limit it to >= 1
/// (item 24). For the 12-state model the numerator is p_c (eq. (87)).
#[inline]
pub fn pi_c(p_out: f64, p_amb: f64, sem: Semantics) -> f64 {
    let pi = p_out / p_amb;
    if sem.authors() {
        pi.max(1.0)
    } else {
        pi
    }
}

/// Isentropic temperature-ratio term Pi_c^(1 - 1/gamma_a) - 1 [-] shared by eqs (58), (60),
/// (61) and (66); computed once per evaluation.
#[inline]
pub fn isentropic_term(pi_c: f64, gamma_a: f64) -> f64 {
    pi_c.powf(1.0 - 1.0 / gamma_a) - 1.0
}

/// Energy transfer coefficient Psi_c [-], eq. (66):
/// 2 c_pa T_amb (Pi_c^(1 - 1/gamma_a) - 1) / (R_c^2 omega_t^2), `r_c` \[m\], `omega_t` [rad/s],
/// `isentropic` from [`isentropic_term`].
#[inline]
pub fn energy_coefficient(r_c: f64, c_pa: f64, t_amb: f64, isentropic: f64, omega_t: f64) -> f64 {
    2.0 * c_pa * t_amb * isentropic / (r_c * r_c * omega_t * omega_t)
}

/// Volumetric flow coefficient Phi_c [-] of a mass flow `w_c` [kg/s], eq. (72) solved for
/// Phi_c (eq. (67) of the tuning): W_c R_a T_amb / (p_amb pi R_c^3 omega_t).
#[inline]
pub fn flow_coefficient(r_c: f64, r_a: f64, t_amb: f64, p_amb: f64, omega_t: f64, w_c: f64) -> f64 {
    r_a * t_amb / (p_amb * PI * r_c.powi(3) * omega_t) * w_c
}

/// Signals of the compressor flow model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressorFlow {
    /// Energy transfer coefficient Psi_c [-], eq. (66).
    pub psi_c: f64,
    /// Volumetric flow coefficient Phi_c [-], eq. (71).
    pub phi_c: f64,
    /// Mass flow W_c [kg/s], eq. (72) (authors: >= 1e-4, item 28).
    pub w_c: f64,
}

/// Compressor mass flow, eqs (66)-(72):
/// ```text
/// Psi_c = 2 c_pa T_amb (Pi_c^(1 - 1/gamma_a) - 1) / (R_c^2 omega_t^2)
/// Phi_c = sqrt(max(0, (1 - c_Psi1 (Psi_c - c_Psi2)^2) / c_Phi1)) + c_Phi2
/// W_c = p_amb pi R_c^3 omega_t / (R_a T_amb) Phi_c
/// ```
/// c_Psi1, c_Phi1 are quadratics in omega_t [rad/s] (eqs (69)-(70)). The authors clamp
/// c_Psi1 >= 0, c_Phi1 >= 0.1 (item 25), Phi_c >= 0 (item 27) and W_c >= 1e-4 kg/s (item 28).
/// `isentropic` = Pi_c^(1 - 1/gamma_a) - 1 ([`isentropic_term`]).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn flow(
    c: &Compressor,
    c_pa: f64,
    r_a: f64,
    t_amb: f64,
    p_amb: f64,
    isentropic: f64,
    omega_t: f64,
    sem: Semantics,
) -> CompressorFlow {
    let psi_c = energy_coefficient(c.r_c, c_pa, t_amb, isentropic, omega_t); // eq. (66)
    let mut c_psi1 = poly2(&c.c_wpsi, omega_t); // eq. (69)
    let mut c_phi1 = poly2(&c.c_wphi, omega_t); // eq. (70)
    if sem.authors() {
        c_psi1 = c_psi1.max(0.0);
        c_phi1 = c_phi1.max(0.1);
    }
    let d = psi_c - c.c_psi2;
    let mut phi_c = ((1.0 - c_psi1 * d * d) / c_phi1).max(0.0).sqrt() + c.c_phi2; // eq. (71)
    if sem.authors() {
        phi_c = phi_c.max(0.0);
    }
    let mut w_c = p_amb * PI * c.r_c.powi(3) * omega_t / (r_a * t_amb) * phi_c; // eq. (72)
    if sem.authors() {
        w_c = w_c.max(1e-4);
    }
    CompressorFlow { psi_c, phi_c, w_c }
}

/// Compressor efficiency eta_c [-], eqs (62)-(65): eta_cmax - chi^T Q_c chi with
/// chi = [W_c - W_copt, (Pi_c - 1)^c_pi - pi_copt]; the authors limit it to >= 0.2 (item 29).
#[inline]
pub fn efficiency(c: &Compressor, w_c: f64, pi_c: f64, sem: Semantics) -> f64 {
    let x0 = w_c - c.w_copt; // eq. (63)
    let x1 = pow_ln(pi_c - 1.0, c.c_pi) - c.pi_copt; // eqs (63)-(64)
    let q = &c.q_c;
    let eta = c.eta_cmax - (q[0][0] * x0 * x0 + 2.0 * q[0][1] * x0 * x1 + q[1][1] * x1 * x1); // eq. (62), (65)
    if sem.authors() {
        eta.max(0.2)
    } else {
        eta
    }
}

/// Compressor outlet temperature and power.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressorPower {
    /// Temperature after the compressor T_c \[K\], from eq. (58).
    pub t_c: f64,
    /// Compressor power P_c \[W\], eq. (61).
    pub p_c: f64,
}

/// Outlet temperature and power, eqs (58)-(61): T_c = T_amb + T_amb (Pi_c^(1-1/gamma_a) - 1)/eta_c,
/// P_c = W_c c_pa (T_c - T_amb).
#[inline]
pub fn power(c_pa: f64, t_amb: f64, isentropic: f64, w_c: f64, eta_c: f64) -> CompressorPower {
    let dt = t_amb * isentropic / eta_c; // eq. (58)
    CompressorPower {
        t_c: t_amb + dt,
        p_c: w_c * c_pa * dt, // eq. (61)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;

    #[test]
    fn efficiency_peak_and_clamp() {
        let p = Params::published();
        let c = &p.compressor;
        // at the optimum chi = 0: eta = eta_cmax
        let pi_opt = 1.0 + c.pi_copt.powf(1.0 / c.c_pi);
        let e = efficiency(c, c.w_copt, pi_opt, Semantics::Authors);
        assert!((e - c.eta_cmax).abs() < 1e-12);
        // far away: clamped at 0.2 for the authors only
        assert_eq!(efficiency(c, 2.0, 1.0, Semantics::Authors), 0.2);
        assert!(efficiency(c, 2.0, 1.0, Semantics::Paper) < 0.2);
    }

    #[test]
    fn power_by_hand() {
        // T_amb = 300, Pi_c = 2, gamma = 1.4: 2^(0.285714) = 1.219014; dT = 300*0.219014/0.7 = 93.863
        let pw = power(1011.0, 300.0, isentropic_term(2.0, 1.4), 0.3, 0.7);
        let dt = 300.0 * (2f64.powf(1.0 - 1.0 / 1.4) - 1.0) / 0.7;
        assert!((dt - 93.863).abs() < 1e-3);
        assert!((pw.t_c - 300.0 - dt).abs() < 1e-12 && (pw.p_c - 0.3 * 1011.0 * dt).abs() < 1e-9);
    }

    #[test]
    fn flow_guards() {
        let p = Params::published();
        let c = &p.compressor;
        let g = &p.gas;
        // Pi_c below 1 is lifted to 1 by the authors
        assert_eq!(pi_c(0.9e5, 1.0e5, Semantics::Authors), 1.0);
        // at Pi_c = 1, Psi_c = 0 and Phi_c = sqrt(1/c_Phi1) (c_Psi2 = c_Phi2 = 0)
        let w = 6000.0;
        let f = flow(
            c,
            g.c_pa,
            g.r_a,
            298.0,
            1.0e5,
            isentropic_term(1.0, g.gamma_a),
            w,
            Semantics::Authors,
        );
        let c_phi1 = poly2(&c.c_wphi, w).max(0.1);
        assert!(f.psi_c.abs() < 1e-15);
        assert!((f.phi_c - (1.0 / c_phi1).sqrt()).abs() < 1e-12);
        // surge side: very high pressure ratio at low speed -> Phi_c = 0 -> W_c = 1e-4 floor
        let s = flow(
            c,
            g.c_pa,
            g.r_a,
            298.0,
            1.0e5,
            isentropic_term(4.0, g.gamma_a),
            2000.0,
            Semantics::Authors,
        );
        assert_eq!(s.w_c, 1e-4);
    }
}
