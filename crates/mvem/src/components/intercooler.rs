//! Intercooler flow restriction of the 12-state extension (section 9.2, eq. (86)).

use crate::params::Intercooler;

/// Mass flow through the intercooler W_ic [kg/s], eq. (86), an incompressible restriction:
/// ```text
/// W_ic = sqrt(p_c (p_c - p_im) / (T_ic k_ic))            for p_c >= p_im
/// W_ic = -sqrt(p_im (p_im - p_c) / (T_im k_ic))          for p_c <  p_im (back flow)
/// ```
/// The paper states only the forward branch. Back flow (which the paper's square root leaves
/// undefined) is taken as the same restriction flown the other way, with the density of the
/// upstream volume (the intake manifold: p_im, T_im); the flow is then signed, continuous, finite
/// and odd in p_c - p_im, and zero at p_c = p_im. Pressures in Pa, temperatures in K, k_ic in
/// Pa^2 s^2/(K kg^2) (must be > 0).
#[inline]
pub fn w_ic(ic: &Intercooler, p_c: f64, t_ic: f64, p_im: f64, t_im: f64) -> f64 {
    let dp = p_c - p_im;
    if dp >= 0.0 {
        (p_c * dp / (t_ic * ic.k_ic)).sqrt() // eq. (86)
    } else {
        -(p_im * -dp / (t_im * ic.k_ic)).sqrt()
    }
}

/// Pressure drop p_c - p_im \[Pa\] that drives a forward flow `w` [kg/s] at the upstream
/// temperature `t_ic` \[K\] into the intake manifold at `p_im` \[Pa\]: eq. (86) solved for p_c,
/// `p_c (p_c - p_im) = w^2 T_ic k_ic`, positive root.
#[inline]
pub fn pressure_drop(ic: &Intercooler, w: f64, t_ic: f64, p_im: f64) -> f64 {
    let c = w * w * t_ic * ic.k_ic;
    // p_c = (p_im + sqrt(p_im^2 + 4c))/2, written without cancellation:
    2.0 * c / (p_im + (p_im * p_im + 4.0 * c).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_values_and_inverse() {
        let ic = Intercooler {
            v_ic: 0.02,
            k_ic: 4.0e7,
        };
        // sqrt(3e5 * 1e4 / (400 * 4e7)) = sqrt(3e9 / 1.6e10) = sqrt(0.1875)
        let w = w_ic(&ic, 3.0e5, 400.0, 2.9e5, 320.0);
        assert!((w - 0.1875f64.sqrt()).abs() < 1e-15);
        // back flow with the intake manifold upstream: -sqrt(3e5 * 1e4 / (320 * 4e7))
        let wb = w_ic(&ic, 2.9e5, 400.0, 3.0e5, 320.0);
        assert!((wb + (3.0e9f64 / (320.0 * 4.0e7)).sqrt()).abs() < 1e-15);
        assert_eq!(w_ic(&ic, 2.0e5, 400.0, 2.0e5, 300.0), 0.0);
        // the inverse gives back the pressure drop
        let dp = pressure_drop(&ic, w, 400.0, 2.9e5);
        assert!((dp - 1.0e4).abs() < 1e-8, "{dp}");
    }
}
