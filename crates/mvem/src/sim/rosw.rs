//! Coefficients of the Rosenbrock-W method ROS34PW2 of J. Rang and L. Angermann, "New
//! Rosenbrock W-methods of order 3 for partial differential algebraic equations of index 1",
//! BIT Numerical Mathematics 45 (2005) 761-787 (Table 4.4), in the form of Hairer & Wanner,
//! Solving ODEs II, section IV.7:
//!
//! ```text
//! (I - gamma h J) k_i = h f(t + alpha_i h, y + sum_j a_ij k_j) + h J sum_j g_ij k_j
//! y_new = y + sum_i b_i k_i,   error estimate = sum_i (b_i - bh_i) k_i
//! ```
//!
//! A W-method: its order does not depend on J being the exact Jacobian, so a lagged
//! finite-difference Jacobian is reused over several steps (and the non-autonomous f_t term may
//! be omitted). Order 3, embedded order 2, L-stable, stiffly accurate. Coefficients as published
//! (to 17 digits).
#![allow(clippy::excessive_precision)]

pub(crate) const GAMMA: f64 = 0.435_866_521_508_459;

pub(crate) const A21: f64 = 0.871_733_043_016_918_01;
pub(crate) const A31: f64 = 0.844_570_600_153_694_23;
pub(crate) const A32: f64 = -0.112_990_642_364_841_85;
// a41 = a42 = 0, a43 = 1

pub(crate) const ALPHA2: f64 = A21;
pub(crate) const ALPHA3: f64 = A31 + A32;

pub(crate) const G21: f64 = -0.871_733_043_016_918_01;
pub(crate) const G31: f64 = -0.903_380_570_130_440_82;
pub(crate) const G32: f64 = 0.054_180_672_388_095_326;
pub(crate) const G41: f64 = 0.242_123_807_060_953_46;
pub(crate) const G42: f64 = -1.223_250_583_904_514_7;
pub(crate) const G43: f64 = 0.545_260_255_335_102_14;

pub(crate) const B1: f64 = 0.242_123_807_060_953_46;
pub(crate) const B2: f64 = -1.223_250_583_904_514_7;
pub(crate) const B3: f64 = 1.545_260_255_335_102_0;
pub(crate) const B4: f64 = GAMMA;

pub(crate) const BH1: f64 = 0.378_109_031_458_193_69;
pub(crate) const BH2: f64 = -0.096_042_292_212_423_178;
pub(crate) const BH3: f64 = 0.5;
pub(crate) const BH4: f64 = 0.217_933_260_754_229_5;

/// Steps a finite-difference Jacobian is reused before it is recomputed.
pub(crate) const JAC_MAX_AGE: usize = 12;
/// A rejected step recomputes the Jacobian if it is at least this many steps old.
pub(crate) const JAC_REFRESH_ON_REJECT: usize = 3;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_conditions() {
        // Hairer & Wanner IV.7 with beta_ij = a_ij + g_ij, beta_i' = sum_{j<i} beta_ij, g = GAMMA:
        // order 1: sum b = 1; order 2: sum b_i beta_i' = 1/2 - g; order 3: sum b_i alpha_i^2 = 1/3,
        // sum b_i beta_ij beta_j' = 1/6 - g + g^2 (the W-method conditions hold too, see tests in sim).
        let b = [B1, B2, B3, B4];
        assert!((b.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        let bh = [BH1, BH2, BH3, BH4];
        assert!((bh.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        let alpha = [0.0, ALPHA2, ALPHA3, 1.0];
        let a = [
            [0.0; 4],
            [A21, 0.0, 0.0, 0.0],
            [A31, A32, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        let g = [
            [0.0; 4],
            [G21, 0.0, 0.0, 0.0],
            [G31, G32, 0.0, 0.0],
            [G41, G42, G43, 0.0],
        ];
        let beta: Vec<f64> = (0..4)
            .map(|i| (0..i).map(|j| a[i][j] + g[i][j]).sum())
            .collect();
        let o2: f64 = (0..4).map(|i| b[i] * beta[i]).sum();
        assert!((o2 - (0.5 - GAMMA)).abs() < 1e-12, "{o2}");
        let o3a: f64 = (0..4).map(|i| b[i] * alpha[i] * alpha[i]).sum();
        assert!((o3a - 1.0 / 3.0).abs() < 1e-12, "{o3a}");
        let o3b: f64 = (0..4)
            .map(|i| b[i] * (0..i).map(|j| (a[i][j] + g[i][j]) * beta[j]).sum::<f64>())
            .sum();
        assert!(
            (o3b - (1.0 / 6.0 - GAMMA + GAMMA * GAMMA)).abs() < 1e-12,
            "{o3b}"
        );
        // stiffly accurate: b_i = a_4i + g_4i (i < 4), b_4 = gamma
        for i in 0..3 {
            assert!((b[i] - (a[3][i] + g[3][i])).abs() < 1e-14);
        }
    }
}
