//! The paper's submodels (sections 3-7) as pure functions of port conditions, inputs and the
//! component's own parameters. No function here knows the state vector; the assembly into a
//! model lives in [`crate::model`].
//!
//! Every function cites its equation number. Where the authors' Simulink implementation adds
//! a saturation or switch (see `docs/authors-implementation.md`, cited as "item N"),
//! the function takes a [`Semantics`] argument and applies it only for [`Semantics::Authors`].

pub mod actuator;
pub mod compressor;
pub mod cylinder;
pub mod egr;
pub mod intercooler;
pub mod manifold;
pub mod turbine;
pub mod turbo;

use serde::{Deserialize, Serialize};

/// Which equations to use where the authors' implementation and the paper differ.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Semantics {
    /// The authors' Simulink implementation (default): every saturation, switch and integrator
    /// limit of the implementation notes, items 1-37.
    #[default]
    Authors,
    /// The paper's plain equations (6)-(73): only the limits written in the paper
    /// (eqs (35), (38), (51), (56), (71)); no input saturations, no integrator limits.
    Paper,
}

impl Semantics {
    /// True for the authors' implementation.
    #[inline]
    pub fn authors(self) -> bool {
        matches!(self, Semantics::Authors)
    }
}

/// Horner evaluation of `c[0] x^2 + c[1] x + c[2]` (the paper's coefficient order).
#[inline]
pub fn poly2(c: &[f64; 3], x: f64) -> f64 {
    (c[0] * x + c[1]) * x + c[2]
}

/// x^a as exp(a ln x) for x > 0 (`powf` otherwise, so every special case is `powf`'s). One
/// `ln` and one `exp` cost about three quarters of glibc's `pow`, which carries its logarithm
/// in double-double to round correctly; here the relative error is at most about
/// (|a ln x| + 2) eps instead of 0.52 eps: about 1e-15 or less for the powers of the model
/// (Pi_e^(1/gamma_a), (Pi_c - 1)^c_pi with c_pi = 0.27, (omega_t - c_m2)^c_m3 with
/// c_m3 = 0.01), where |a ln x| stays below about 6.
#[inline]
pub fn pow_ln(x: f64, a: f64) -> f64 {
    if x > 0.0 {
        (a * x.ln()).exp()
    } else {
        x.powf(a)
    }
}

#[cfg(test)]
mod tests {
    use super::pow_ln;

    #[test]
    fn pow_ln_is_powf_to_the_stated_bound() {
        let eps = f64::EPSILON;
        for &a in &[1.0 / 1.3964, 0.2708, 0.0100001, 2.89, 1.0] {
            for k in 0..=4000 {
                let x = 10f64.powf(-8.0 + 13.0 * k as f64 / 4000.0); // 1e-8 .. 1e5
                let (got, want) = (pow_ln(x, a), x.powf(a));
                let bound = ((a * x.ln()).abs() + 2.0) * eps;
                assert!((got / want - 1.0).abs() <= bound, "{x} {a}: {got} {want}");
            }
        }
        // Special values are powf's.
        assert_eq!(pow_ln(0.0, 0.27), 0.0);
        assert_eq!(pow_ln(1.0, 0.27), 1.0);
        assert_eq!(pow_ln(-2.0, 1.0), -2.0);
        assert!(pow_ln(-2.0, 0.27).is_nan() && pow_ln(f64::NAN, 0.27).is_nan());
        assert_eq!(pow_ln(f64::INFINITY, 0.27), f64::INFINITY);
    }
}
