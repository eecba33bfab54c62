//! Turbine: efficiency (section 6.2.1, eqs (43)-(51)), mass flow (section 6.2.2, eqs (52)-(56))
//! and the VGT actuator (section 6.2.3, eq. (57)).

use super::{pow_ln, Semantics};
use crate::params::{Turbine, VgtActuator};

/// Turbine pressure ratio Pi_t = p_es / p_em with p_es = p_amb, eq. (44); the authors cap it at
/// 0.9999 (item 31), which keeps 1 - Pi_t^K_t and the BSR denominator positive.
#[inline]
pub fn pi_t(p_amb: f64, p_em: f64, sem: Semantics) -> f64 {
    let pi = p_amb / p_em; // eq. (44)
    if sem.authors() {
        pi.min(0.9999)
    } else {
        pi
    }
}

/// Effective area ratio f_vgt [-], eq. (56): c_f2 + c_f1 sqrt(max(0, 1 - ((u - c_vgt2)/c_vgt1)^2)),
/// `u_vgt` (actuator output) in %; the authors add an outer max(0, .) (item 35).
#[inline]
pub fn f_vgt(t: &Turbine, u_vgt: f64, sem: Semantics) -> f64 {
    let a = (u_vgt - t.c_vgt2) / t.c_vgt1;
    let f = t.c_f2 + t.c_f1 * (1.0 - a * a).max(0.0).sqrt(); // eq. (56)
    if sem.authors() {
        f.max(0.0)
    } else {
        f
    }
}

/// Choking function f_Pi_t [-], eq. (53): sqrt(1 - Pi_t^K_t) (in the form of
/// [`expansion_terms`]).
#[inline]
pub fn f_pi_t(t: &Turbine, pi_t: f64) -> f64 {
    one_minus_pow_ln(t.k_t, pi_t.ln()).sqrt()
}

/// 1 - x^a from ln x, as -expm1(a ln x) (accurate near x = 1, where 1 - powf cancels).
#[inline]
fn one_minus_pow_ln(a: f64, ln_x: f64) -> f64 {
    -(a * ln_x).exp_m1()
}

/// The two powers of the turbine pressure ratio in one evaluation, from one logarithm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExpansionTerms {
    /// Choking function f_Pi_t = sqrt(1 - Pi_t^K_t) [-], eq. (53).
    pub f_pi_t: f64,
    /// Isentropic enthalpy-drop factor 1 - Pi_t^(1 - 1/gamma_e) [-], eqs (48), (50).
    pub dh: f64,
}

/// [`f_pi_t`] (eq. (53)) and the factor 1 - Pi_t^(1 - 1/gamma_e) of eqs (48) and (50), with
/// one ln(Pi_t) shared by both powers: 1 - Pi_t^a = -expm1(a ln Pi_t), within a few units in
/// the last place of the exact value for every Pi_t. The `powf` form 1 - Pi_t^a loses
/// eps/2 / (1 - Pi_t^a) relative to the rounding of Pi_t^a near 1 (up to ~1e-11 for
/// 1 - Pi_t^(1 - 1/gamma_e) at the authors' cap Pi_t = 0.9999), which bounds the difference
/// between the two forms. Same special values: Pi_t = 0 gives (1, 1), Pi_t > 1 NaN for f_Pi_t,
/// Pi_t < 0 NaN.
#[inline]
pub fn expansion_terms(t: &Turbine, gamma_e: f64, pi_t: f64) -> ExpansionTerms {
    let ln = pi_t.ln();
    ExpansionTerms {
        f_pi_t: one_minus_pow_ln(t.k_t, ln).sqrt(),
        dh: one_minus_pow_ln(1.0 - 1.0 / gamma_e, ln),
    }
}

/// Turbine mass flow W_t [kg/s], eq. (55): A_vgtmax p_em f_Pi_t f_vgt / sqrt(T_em R_e).
#[inline]
pub fn w_t(t: &Turbine, p_em: f64, t_em: f64, r_e: f64, f_pi_t: f64, f_vgt: f64) -> f64 {
    t.a_vgtmax * p_em * f_pi_t * f_vgt / (t_em * r_e).sqrt()
}

/// c_m(omega_t), eq. (51): c_m1 max(0, omega_t - c_m2)^c_m3. The authors' implementation
/// (item 33) uses w = max(omega_t, c_m2) and a linear branch below w_tlin:
/// c_m = c_mlin (w - c_m2)/(w_tlin - c_m2).
#[inline]
pub fn c_m(t: &Turbine, omega_t: f64, sem: Semantics) -> f64 {
    let w = omega_t.max(t.c_m[1]);
    if sem.authors() && w < t.w_tlin {
        t.c_mlin * (w - t.c_m[1]) / (t.w_tlin - t.c_m[1])
    } else {
        t.c_m[0] * pow_ln(w - t.c_m[1], t.c_m[2]) // eq. (51)
    }
}

/// Signals of the turbine efficiency and power model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurbinePower {
    /// Blade speed ratio BSR [-], eq. (50) (authors: limited to [0, 2 BSR_opt], item 32).
    pub bsr: f64,
    /// Total turbine efficiency eta_tm [-], eq. (49) (authors: limited to [0.2, 1], item 34).
    pub eta_tm: f64,
    /// Turbine power times mechanical efficiency P_t eta_m \[W\], eq. (48).
    pub p_t_eta_m: f64,
}

/// Turbine efficiency and power, eqs (48)-(51):
/// ```text
/// BSR = R_t omega_t / sqrt(2 c_pe T_em (1 - Pi_t^(1 - 1/gamma_e)))
/// eta_tm = eta_tm,max - c_m (BSR - BSR_opt)^2
/// P_t eta_m = eta_tm W_t c_pe T_em (1 - Pi_t^(1 - 1/gamma_e))
/// ```
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn power(
    t: &Turbine,
    c_pe: f64,
    gamma_e: f64,
    t_em: f64,
    pi_t: f64,
    omega_t: f64,
    w_t: f64,
    sem: Semantics,
) -> TurbinePower {
    let dh = one_minus_pow_ln(1.0 - 1.0 / gamma_e, pi_t.ln());
    power_dh(t, c_pe, t_em, dh, omega_t, w_t, sem)
}

/// [`power`] with the enthalpy-drop factor dh = 1 - Pi_t^(1 - 1/gamma_e) given (from
/// [`expansion_terms`]).
#[inline]
pub fn power_dh(
    t: &Turbine,
    c_pe: f64,
    t_em: f64,
    dh: f64,
    omega_t: f64,
    w_t: f64,
    sem: Semantics,
) -> TurbinePower {
    let mut bsr = t.r_t * omega_t / (2.0 * c_pe * t_em * dh).sqrt(); // eq. (50)
    if sem.authors() {
        bsr = bsr.clamp(0.0, 2.0 * t.bsr_opt); // item 32
    }
    let d = bsr - t.bsr_opt;
    let mut eta_tm = t.eta_tmmax - c_m(t, omega_t, sem) * d * d; // eq. (49)
    if sem.authors() {
        eta_tm = eta_tm.clamp(0.2, 1.0); // item 34
    }
    TurbinePower {
        bsr,
        eta_tm,
        p_t_eta_m: eta_tm * w_t * c_pe * t_em * dh, // eq. (48)
    }
}

/// VGT actuator derivative, eq. (57): (u_vgt(t - tau_dvgt) - u_vgt_act)/tau_vgt [%/s].
#[inline]
pub fn actuator_derivative(a: &VgtActuator, u_delayed: f64, u_vgt_act: f64) -> f64 {
    (u_delayed - u_vgt_act) / a.tau_vgt
}

/// VGT actuator unit step response of eq. (57) [-]: the output `s` seconds after a unit step of
/// the (undelayed, saturated) command, from rest: 1 - e^(-(s - tau_dvgt)/tau_vgt) (0 for
/// s <= tau_dvgt). Used with [`super::actuator::position`].
pub fn actuator_step_response(a: &VgtActuator, s: f64) -> f64 {
    let s = s - a.tau_dvgt;
    if s <= 0.0 {
        0.0
    } else {
        1.0 - (-s / a.tau_vgt).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;

    #[test]
    fn c_m_branches_are_continuous_at_w_tlin() {
        let p = Params::published();
        let t = &p.turbine;
        let below = c_m(t, t.w_tlin * (1.0 - 1e-12), Semantics::Authors);
        let above = c_m(t, t.w_tlin, Semantics::Authors);
        assert!((below - above).abs() < 1e-6, "{below} {above}");
        assert!((above - t.c_mlin).abs() < 1e-3);
        // linear branch halfway: c_mlin/2
        let mid = 0.5 * (t.w_tlin + t.c_m[1]);
        assert!((c_m(t, mid, Semantics::Authors) - 0.5 * t.c_mlin).abs() < 1e-12);
        // paper: power law, max(0, .) at and below c_m2
        assert_eq!(c_m(t, 100.0, Semantics::Paper), 0.0);
        let pw = t.c_m[0] * (mid - t.c_m[1]).powf(t.c_m[2]);
        assert!((c_m(t, mid, Semantics::Paper) / pw - 1.0).abs() < 1e-15);
    }

    #[test]
    fn vgt_area_and_choking_by_hand() {
        let p = Params::published();
        let t = &p.turbine;
        // u = 117.14 (= c_vgt2): f = c_f2 + c_f1 = 1.17165
        assert!((f_vgt(t, t.c_vgt2, Semantics::Authors) - (t.c_f1 + t.c_f2)).abs() < 1e-12);
        // u = 50: a = (50-117.1447)/126.8719 = -0.5292325; sqrt(1-0.2800871) = 0.8484774
        // f = -0.7763119 + 1.9479627*0.8484774 = 0.8764894
        assert!((f_vgt(t, 50.0, Semantics::Authors) - 0.8764894).abs() < 1e-6);
        // tiny openings: the outer clamp at 0 (authors only)
        assert_eq!(f_vgt(t, 0.0, Semantics::Authors), 0.0);
        assert!(f_vgt(t, 0.0, Semantics::Paper) < 0.0);
        // Pi_t capped at 0.9999 for the authors
        assert_eq!(pi_t(1.0e5, 0.9e5, Semantics::Authors), 0.9999);
        assert!(pi_t(1.0e5, 0.9e5, Semantics::Paper) > 1.0);
        // f_Pi_t(0.5) = sqrt(1 - 0.5^2.8901927) = sqrt(1 - 0.1348855) = 0.9301153
        assert!((f_pi_t(t, 0.5) - 0.9301153).abs() < 1e-6);
    }

    #[test]
    fn expansion_terms_match_the_powers() {
        // One shared ln(Pi_t) with expm1 against the two `powf` forms. Bound: `powf` rounds
        // Pi_t^a to within eps/2 absolute, so 1 - Pi_t^a from it is within eps/2 / (1 - Pi_t^a)
        // relative; the ln/expm1 form is within a few eps relative. The difference is
        // <= eps / (1 - Pi_t^a) + 8 eps relative: a few eps for Pi_t <= 0.5, the old form's own
        // rounding error (up to ~1e-11 for 1 - Pi_t^(1 - 1/gamma_e)) at the cap 0.9999.
        let p = Params::published();
        let t = &p.turbine;
        let ge = p.gas.gamma_e;
        let eps = f64::EPSILON;
        for k in 0..=2000 {
            let pi = 0.02 + (0.9999 - 0.02) * k as f64 / 2000.0;
            let ex = expansion_terms(t, ge, pi);
            let one_minus_k = 1.0 - pi.powf(t.k_t);
            let dh = 1.0 - pi.powf(1.0 - 1.0 / ge);
            let rel_f = (ex.f_pi_t / one_minus_k.sqrt() - 1.0).abs();
            let rel_dh = (ex.dh / dh - 1.0).abs();
            assert!(
                rel_f <= 0.5 * eps / one_minus_k + 8.0 * eps,
                "{pi} {rel_f:e}"
            );
            assert!(rel_dh <= eps / dh + 8.0 * eps, "{pi} {rel_dh:e}");
        }
        // Special values as with powf.
        assert_eq!(expansion_terms(t, ge, 0.0).f_pi_t, 1.0);
        assert_eq!(expansion_terms(t, ge, 0.0).dh, 1.0);
        assert!(expansion_terms(t, ge, 1.1).f_pi_t.is_nan());
        assert!(expansion_terms(t, ge, -0.1).dh.is_nan());
        // power() (from Pi_t) and power_dh() (from expansion_terms) agree to rounding.
        let a = power(
            t,
            p.gas.c_pe,
            ge,
            800.0,
            0.5,
            9000.0,
            0.3,
            Semantics::Authors,
        );
        let ex = expansion_terms(t, ge, 0.5);
        let b = power_dh(t, p.gas.c_pe, 800.0, ex.dh, 9000.0, 0.3, Semantics::Authors);
        assert!((a.p_t_eta_m / b.p_t_eta_m - 1.0).abs() < 1e-14);
    }

    #[test]
    fn efficiency_limits() {
        let p = Params::published();
        let t = &p.turbine;
        // At BSR = BSR_opt the efficiency is eta_tm,max.
        let dh = 1.0 - 0.5f64.powf(1.0 - 1.0 / p.gas.gamma_e);
        let omega = t.bsr_opt * (2.0 * p.gas.c_pe * 800.0 * dh).sqrt() / t.r_t;
        let pw = power(
            t,
            p.gas.c_pe,
            p.gas.gamma_e,
            800.0,
            0.5,
            omega,
            0.3,
            Semantics::Authors,
        );
        assert!((pw.bsr - t.bsr_opt).abs() < 1e-12);
        assert!((pw.eta_tm - t.eta_tmmax).abs() < 1e-12);
        assert!((pw.p_t_eta_m - t.eta_tmmax * 0.3 * p.gas.c_pe * 800.0 * dh).abs() < 1e-6);
        // Far off-design: the authors clamp eta_tm at 0.2 and BSR at 2 BSR_opt.
        let off = power(
            t,
            p.gas.c_pe,
            p.gas.gamma_e,
            800.0,
            0.999,
            2.0e4,
            0.3,
            Semantics::Authors,
        );
        assert_eq!(off.bsr, 2.0 * t.bsr_opt);
        assert_eq!(off.eta_tm, 0.2);
    }
}
