//! Turbocharger shaft (section 6.1, eq. (42)).

/// Turbo speed derivative d(omega_t)/dt [rad/s^2], eq. (42): (P_t eta_m - P_c)/(J_t omega_t),
/// powers in W, inertia in kg m^2, omega_t in rad/s.
#[inline]
pub fn omega_derivative(j_t: f64, omega_t: f64, p_t_eta_m: f64, p_c: f64) -> f64 {
    (p_t_eta_m - p_c) / (j_t * omega_t)
}

/// Turbo speed in rpm from rad/s: n_t = omega_t 30 / pi.
#[inline]
pub fn n_t_rpm(omega_t: f64) -> f64 {
    omega_t * 30.0 / std::f64::consts::PI
}

#[cfg(test)]
mod tests {
    #[test]
    fn by_hand() {
        // (1000 - 600) / (2e-4 * 5000) = 400
        assert!((super::omega_derivative(2e-4, 5000.0, 1000.0, 600.0) - 400.0).abs() < 1e-9);
        assert!((super::n_t_rpm(std::f64::consts::PI) - 30.0).abs() < 1e-12);
    }
}
