//! Intake and exhaust manifolds: isothermal control volumes with pressure and oxygen mass
//! fraction states (section 3, eqs (6)-(9)), and the adiabatic control volume with a temperature
//! state of the section-9 extensions (eqs (80), (81), (85)).

/// Time derivatives of one isothermal control volume (eqs (6) and (9)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeDerivatives {
    /// dp/dt [Pa/s].
    pub dp: f64,
    /// dX_O/dt [1/s].
    pub dx_o: f64,
}

/// Intake manifold, eqs (6) and (9):
/// ```text
/// dp_im/dt   = R_a T_im / V_im (W_c + W_egr - W_ei)
/// dX_Oim/dt  = R_a T_im / (p_im V_im) ((X_Oem - X_Oim) W_egr + (X_Oc - X_Oim) W_c)
/// ```
/// Pressures in Pa, temperatures in K, volume in m^3, flows in kg/s, gas constant in J/(kg K).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn intake(
    r_a: f64,
    t_im: f64,
    v_im: f64,
    p_im: f64,
    x_oim: f64,
    x_oem: f64,
    x_oc: f64,
    w_c: f64,
    w_egr: f64,
    w_ei: f64,
) -> VolumeDerivatives {
    let k = r_a * t_im / v_im; // eq. (6)
    VolumeDerivatives {
        dp: k * (w_c + w_egr - w_ei),
        dx_o: k / p_im * ((x_oem - x_oim) * w_egr + (x_oc - x_oim) * w_c), // eq. (9)
    }
}

/// Exhaust manifold, eqs (6) and (9):
/// ```text
/// dp_em/dt   = R_e T_em / V_em (W_eo - W_t - W_egr)
/// dX_Oem/dt  = R_e T_em / (p_em V_em) (X_Oe - X_Oem) W_eo
/// ```
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn exhaust(
    r_e: f64,
    t_em: f64,
    v_em: f64,
    p_em: f64,
    x_oem: f64,
    x_oe: f64,
    w_eo: f64,
    w_t: f64,
    w_egr: f64,
) -> VolumeDerivatives {
    let k = r_e * t_em / v_em; // eq. (6)
    VolumeDerivatives {
        dp: k * (w_eo - w_t - w_egr),
        dx_o: k / p_em * (x_oe - x_oem) * w_eo, // eq. (9)
    }
}

/// EGR fraction in the intake manifold, eq. (7); the authors cap it at 0.9 (item 13).
#[inline]
pub fn egr_fraction(w_egr: f64, w_c: f64, authors: bool) -> f64 {
    let x = w_egr / (w_c + w_egr); // eq. (7)
    if authors {
        x.min(0.9)
    } else {
        x
    }
}

/// Time derivatives of one adiabatic control volume (section 9, eqs (80), (81), (85)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdiabaticDerivatives {
    /// dp/dt [Pa/s].
    pub dp: f64,
    /// dT/dt [K/s].
    pub dt: f64,
}

/// Adiabatic control volume (the section-9 extensions, eqs (80), (81), (85)): mass and
/// internal-energy balance of an ideal gas with constant properties, no heat transfer:
/// ```text
/// dT/dt = R T / (p V c_v) [ c_v W_in (T_in - T) + R (T_in W_in - T W_out) ]
/// dp/dt = R T / V (W_in - W_out) + p / T dT/dt
/// ```
/// The in-flows enter with their own temperatures, given as `w_in` = sum of W_in [kg/s] and
/// `wt_in` = sum of W_in T_in [kg K/s] (so that several in-flows with different temperatures
/// can enter); the out-flows `w_out` [kg/s] leave at the volume temperature `t` \[K\]. With
/// c_p = c_v + R these are d(pV/(RT))/dt = W_in - W_out and d(c_v pV/R)/dt =
/// c_p (T_in W_in - T W_out). Pressure in Pa, volume in m^3, gas constants in J/(kg K).
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn adiabatic(
    r: f64,
    c_v: f64,
    v: f64,
    p: f64,
    t: f64,
    w_in: f64,
    wt_in: f64,
    w_out: f64,
) -> AdiabaticDerivatives {
    let k = r * t / v;
    let dt = k / (p * c_v) * (c_v * (wt_in - t * w_in) + r * (wt_in - t * w_out)); // eqs (80), (81), (85)
    AdiabaticDerivatives {
        dp: k * (w_in - w_out) + p / t * dt, // eqs (80), (81), (85)
        dt,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_values() {
        // R_a T_im / V_im = 287*300/0.02 = 4.305e6; net flow 0.2+0.05-0.24 = 0.01 -> 43050 Pa/s.
        let d = intake(287.0, 300.0, 0.02, 2.0e5, 0.2, 0.1, 0.23, 0.2, 0.05, 0.24);
        assert!((d.dp - 43050.0).abs() < 1e-6);
        // dX = 4.305e6/2e5 * ((0.1-0.2)*0.05 + (0.23-0.2)*0.2) = 21.525 * 0.001 = 0.021525
        assert!((d.dx_o - 0.021525).abs() < 1e-12);
        // R_e T_em / V_em = 286*800/0.02 = 1.144e7; net 0.25-0.2-0.04 = 0.01 -> 114400 Pa/s.
        let e = exhaust(286.0, 800.0, 0.02, 2.5e5, 0.1, 0.12, 0.25, 0.2, 0.04);
        assert!((e.dp - 114400.0).abs() < 1e-6);
        // dX = 1.144e7/2.5e5*(0.02)*0.25 = 45.76*0.005 = 0.2288
        assert!((e.dx_o - 0.2288).abs() < 1e-12);
        assert_eq!(egr_fraction(0.1, 0.3, true), 0.25);
        assert_eq!(egr_fraction(10.0, 0.1, true), 0.9);
        assert!(egr_fraction(10.0, 0.1, false) > 0.9);
    }

    #[test]
    fn adiabatic_hand_values() {
        // Steady in-flow = out-flow at T_in = T: no change at all.
        let d = adiabatic(287.0, 724.0, 0.02, 2.0e5, 320.0, 0.3, 0.3 * 320.0, 0.3);
        assert_eq!((d.dp, d.dt), (0.0, 0.0));
        // Filling a closed volume (no out-flow) with gas at T_in = T: the compression heats it,
        // dT/dt = R T/(p V c_v) R T W = 8.61e6/(1e5*724) * 287*30 = 1023.93 K/s.
        let d = adiabatic(287.0, 724.0, 0.01, 1.0e5, 300.0, 0.1, 30.0, 0.0);
        let dt = 8.61e6 / (1.0e5 * 724.0) * (287.0 * 30.0);
        assert!((d.dt - dt).abs() < 1e-9 * dt, "{} vs {dt}", d.dt);
        // ... and dp/dt = gamma R T W / V (adiabatic filling): (724+287)/724 * 8.61e6 * 0.1.
        let dp = (724.0 + 287.0) / 724.0 * 8.61e6 * 0.1;
        assert!((d.dp - dp).abs() < 1e-9 * dp, "{} vs {dp}", d.dp);
    }
}
