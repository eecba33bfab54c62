//! Other Rosenbrock-W tableaus, screened against the default ROS34PW2 on the WHTC
//! (docs/integrator.md, "Tableaus and per-evaluation cost"), in the k form of Hairer & Wanner,
//! Solving ODEs II, section IV.7, eq. (7.4) without the f_t term (a W-method admits any J,
//! including one whose time column is zero):
//!
//! ```text
//! (I - gamma_ii h J) k_i = h f(t + alpha_i h, y + sum_j a_ij k_j) + h J sum_{j<i} g_ij k_j
//! y_new = y + sum_i b_i k_i,   error estimate = sum_i (b_i - bh_i) k_i
//! ```
//!
//! with gamma_ii = gamma for every stage, or 0 for an explicit first stage. Two stages with the
//! same row of `a` (same argument, same time) share one evaluation of f.
//!
//! Some of these methods evaluate a stage after the end of the step (alpha_i > 1). The inputs
//! are then the segment's linear pieces extended beyond the step ([`SegmentInputs::at_extended`])
//! and the closed-form lag states their exact solution extended likewise: the stage sees the
//! smooth continuation of the inputs of the step, never the inputs after the next stop time.
#![allow(clippy::excessive_precision)]

use super::integrator::{Integrator, LagSegment, Trial};
use super::rosw::IterationMatrix;
use super::segment::SegmentInputs;
use super::SimError;
use crate::model::Dynamics;

/// An `S`-stage Rosenbrock-W tableau in the k form above.
pub(crate) struct WTableau<const S: usize> {
    /// The diagonal gamma of the stages with a linear solve.
    pub(crate) gamma: f64,
    /// Whether stage 1 is explicit (gamma_11 = 0).
    pub(crate) explicit_first: bool,
    /// Stage arguments a_ij (strictly lower triangular).
    pub(crate) a: [[f64; S]; S],
    /// Couplings g_ij (strictly lower triangular; the diagonal is `gamma`).
    pub(crate) g: [[f64; S]; S],
    pub(crate) b: [f64; S],
    /// The embedded method of order one less.
    pub(crate) bh: [f64; S],
}

impl<const S: usize> WTableau<S> {
    /// Stage time alpha_i = sum_j a_ij.
    pub(crate) fn alpha(&self, i: usize) -> f64 {
        self.a[i].iter().sum()
    }

    /// The earlier stage with the same argument as stage `i` (the same row of `a`), if any.
    pub(crate) fn same_as(&self, i: usize) -> Option<usize> {
        (0..i).find(|&j| self.a[j] == self.a[i])
    }

    /// beta_ij = a_ij + g_ij with the diagonal gamma_ii (Hairer & Wanner IV.7).
    pub(crate) fn beta(&self, i: usize, j: usize) -> f64 {
        if i == j {
            if i == 0 && self.explicit_first {
                0.0
            } else {
                self.gamma
            }
        } else {
            self.a[i][j] + self.g[i][j]
        }
    }
}

/// ROS34PRw of J. Rang, "Improved traditional Rosenbrock-Wanner methods for stiff ODEs and
/// DAEs", J. Comput. Appl. Math. 286 (2015) 128-144, Table 3: 4 stages, W-order 3 (embedded
/// 2), L-stable, stiffly accurate, order 3 on the Prothero-Robinson problem. Stages 3 and 4
/// have the same argument (alpha = 1): 3 evaluations of f per step, the first one being the
/// end-of-step derivative of the previous step. Stage 2 lies at 1.3076 h.
pub(crate) const ROS34PRW: WTableau<4> = WTableau {
    gamma: 0.435_866_521_508_459,
    explicit_first: false,
    a: [
        [0.0; 4],
        [1.307_599_564_525_377_1, 0.0, 0.0, 0.0],
        [0.5, 0.5, 0.0, 0.0],
        [0.5, 0.5, 0.0, 0.0],
    ],
    g: [
        [0.0; 4],
        [-1.307_599_564_525_377_1, 0.0, 0.0, 0.0],
        [
            -0.709_885_758_609_721_7,
            -0.559_967_359_602_777_66,
            0.0,
            0.0,
        ],
        [
            -0.155_508_568_075_520_85,
            -0.953_885_165_751_122_25,
            0.673_527_212_318_184_13,
            0.0,
        ],
    ],
    b: [
        0.344_491_431_924_479_17,
        -0.453_885_165_751_122_31,
        0.673_527_212_318_184_13,
        0.435_866_521_508_459,
    ],
    bh: [
        0.5,
        -0.257_388_120_865_220_78,
        0.435_420_087_247_750_44,
        0.321_968_033_617_470_34,
    ],
};

/// ROS3Pw of J. Rang and L. Angermann, "New Rosenbrock W-methods of order 3 for partial
/// differential algebraic equations of index 1", BIT 45 (2005) 761-787 (PETSc's TSROSWRA3PW):
/// 3 stages, W-order 3 (embedded 2), strongly A-stable with R(inf) = 0.73 (not L-stable).
/// Stage 2 lies at 1.577 h.
pub(crate) const ROS3PW: WTableau<3> = WTableau {
    gamma: 0.788_675_134_594_812_87,
    explicit_first: false,
    a: [
        [0.0; 3],
        [1.577_350_269_189_625_7, 0.0, 0.0],
        [0.5, 0.0, 0.0],
    ],
    g: [
        [0.0; 3],
        [-1.577_350_269_189_625_7, 0.0, 0.0],
        [-0.670_753_175_473_054_80, -0.170_753_175_473_054_82, 0.0],
    ],
    b: [
        0.105_662_432_702_593_55,
        0.049_038_105_676_657_971,
        0.845_299_461_620_748_43,
    ],
    bh: [
        -0.178_632_794_954_081_80,
        1.0 / 3.0,
        0.845_299_461_620_748_43,
    ],
};

/// ROS3PRw of J. Rang (2015, above), Table 2: 3 stages, W-order 3 (embedded 2), order 3 on the
/// Prothero-Robinson problem. Stages 2 and 3 lie at 2.366 h and 1.268 h.
pub(crate) const ROS3PRW: WTableau<3> = WTableau {
    gamma: 0.788_675_134_594_812_87,
    explicit_first: false,
    a: [
        [0.0; 3],
        [2.366_025_403_784_438_8, 0.0, 0.0],
        [0.5, 0.767_949_192_431_122_70, 0.0],
    ],
    g: [
        [0.0; 3],
        [-2.366_025_403_784_438_8, 0.0, 0.0],
        [-0.867_912_182_803_551_65, -0.873_066_958_946_423_17, 0.0],
    ],
    b: [
        0.505_448_678_408_517_59,
        -0.115_716_876_036_375_59,
        0.610_268_197_627_858,
    ],
    bh: [
        0.289_731_802_372_141_97,
        0.100_000_000_000_000_01,
        0.610_268_197_627_858,
    ],
};

/// ASSP3P3S1C of E. Constantinescu (PETSc's TSROSWASSP3P3S1C): 3 stages, the first explicit,
/// W-order 3 (embedded 2), A-stable, with the SSP Runge-Kutta method of Shu & Osher as explicit
/// part: every stage inside the step (alpha = 0, 1, 1/2).
pub(crate) const ASSP3P3S1C: WTableau<3> = {
    const G: f64 = 0.788_675_134_594_812_88; // (3 + sqrt 3) / 6
    WTableau {
        gamma: G,
        explicit_first: true,
        a: [[0.0; 3], [1.0, 0.0, 0.0], [0.25, 0.25, 0.0]],
        g: [[0.0; 3], [-G, 0.0, 0.0], [-G / 4.0, -3.0 * G / 4.0, 0.0]],
        b: [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
        bh: [0.25, 0.25, 0.5],
    }
};

impl<const N: usize, M: Dynamics<N>> Integrator<'_, N, M> {
    /// One trial step of the W-method `tab` (module docs), with a lagged Jacobian as ROS34PW2
    /// and the same closed-form lag states.
    pub(super) fn step_wtab<const S: usize>(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        tab: &WTableau<S>,
    ) -> Result<Trial<N, M::Memory>, SimError> {
        self.with_iteration_matrix(
            inp,
            t,
            h,
            f0,
            tab.gamma,
            super::rosw::JAC_MAX_AGE,
            |s, inp, _, lag_seg, w| s.wtab_stages(inp, t, h, t_new, f0, lag_seg, w, tab),
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn wtab_stages<const S: usize>(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        w: &IterationMatrix<N>,
        tab: &WTableau<S>,
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let y = self.y;
        let jac = self.jac.expect("Jacobian set up with the iteration matrix");
        let mut is_lag = [false; N];
        for l in lag_seg {
            is_lag[l.state] = true;
        }
        // the factors are those of I - gamma w.h J, i.e. of the Jacobian (w.h / h) J: the
        // coupling products use the same, h (w.h / h) J v = w.h J v
        let hj = w.h;
        // experiment: MVEM_FT=step|seg adds gamma_i h^2 f_t (f_t per step or per segment)
        static FT: std::sync::LazyLock<u8> =
            std::sync::LazyLock::new(|| match std::env::var("MVEM_FT").as_deref() {
                Ok("step") => 1,
                Ok("seg") => 2,
                _ => 0,
            });
        let ft = match (*FT, self.ft_seg) {
            (0, _) => [0.0; N],
            (2, Some(v)) => v,
            _ => {
                let v = self.time_derivative(inp, t, f0, lag_seg)?;
                self.ft_seg = Some(v);
                v
            }
        };
        let mut k = [[0.0; N]; S];
        let mut f = [[0.0; N]; S];
        for i in 0..S {
            f[i] = if i == 0 {
                *f0
            } else if let Some(p) = tab.same_as(i) {
                f[p]
            } else {
                let s = tab.alpha(i) * h;
                let mut yi: [f64; N] = std::array::from_fn(|n| {
                    y[n] + (0..i).map(|j| tab.a[i][j] * k[j][n]).sum::<f64>()
                });
                LagSegment::advance_all(lag_seg, t, &y, &mut yi, s);
                let u = inp.at_extended(t + s);
                self.rhs_with(t + s, &yi, &u)?.dx
            };
            let gi: f64 = (0..=i)
                .map(|j| if j == i { tab.beta(i, i) } else { tab.g[i][j] })
                .sum();
            let gk: [f64; N] =
                std::array::from_fn(|n| (0..i).map(|j| tab.g[i][j] * k[j][n]).sum::<f64>());
            let mut r: [f64; N] = std::array::from_fn(|a| {
                let jg: f64 = (0..N).map(|b| jac[a][b] * gk[b]).sum();
                h * f[i][a] + hj * jg + gi * hj * h * ft[a]
            });
            if !(i == 0 && tab.explicit_first) {
                w.solve(&mut r);
            }
            for (v, &l) in r.iter_mut().zip(&is_lag) {
                if l {
                    *v = 0.0;
                }
            }
            k[i] = r;
        }
        let mut y1: [f64; N] =
            std::array::from_fn(|n| y[n] + (0..S).map(|i| tab.b[i] * k[i][n]).sum::<f64>());
        LagSegment::advance_all(lag_seg, t, &y, &mut y1, t_new - t);
        let e: [f64; N] = std::array::from_fn(|n| {
            (0..S)
                .map(|i| (tab.b[i] - tab.bh[i]) * k[i][n])
                .sum::<f64>()
        });
        Ok(Trial {
            y1,
            err: self.error_norm(&self.y, &y1, &e),
            e,
            dense: None,
            f1: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The order conditions of a W-method (J arbitrary; Hairer & Wanner IV.7, "W-methods"):
    /// with A = (a_ij) and G = (g_ij) plus gamma_ii on the diagonal, the Taylor expansion of
    /// k_i = h f(y + sum_j a_ij k_j) + h J sum_{j<=i} g_ij k_j separates the elementary
    /// differentials with J from those with f'. Returns the residuals of
    /// [b 1 - 1, b A1 - 1/2, b G1, b (A1)^2 - 1/3, b A A1 - 1/6, b A G1, b G A1, b G G1] for `v`
    /// (b or bh) and of the Rosenbrock (J = f') order-3 condition b (A + G)(A + G) 1 - 1/6.
    fn residuals<const S: usize>(tab: &WTableau<S>, v: &[f64; S]) -> ([f64; 8], f64) {
        let g = |i: usize, j: usize| {
            if i == j {
                tab.beta(i, i)
            } else {
                tab.g[i][j]
            }
        };
        let a1: Vec<f64> = (0..S).map(|i| tab.alpha(i)).collect();
        let g1: Vec<f64> = (0..S).map(|i| (0..=i).map(|j| g(i, j)).sum()).collect();
        let dot = |w: &dyn Fn(usize) -> f64| (0..S).map(|i| v[i] * w(i)).sum::<f64>();
        let aa = |i: usize, u: &[f64]| (0..i).map(|j| tab.a[i][j] * u[j]).sum::<f64>();
        let ga = |i: usize, u: &[f64]| (0..=i).map(|j| g(i, j) * u[j]).sum::<f64>();
        let w = [
            dot(&|_| 1.0) - 1.0,
            dot(&|i| a1[i]) - 0.5,
            dot(&|i| g1[i]),
            dot(&|i| a1[i] * a1[i]) - 1.0 / 3.0,
            dot(&|i| aa(i, &a1)) - 1.0 / 6.0,
            dot(&|i| aa(i, &g1)),
            dot(&|i| ga(i, &a1)),
            dot(&|i| ga(i, &g1)),
        ];
        (w, w[4] + w[5] + w[6] + w[7])
    }

    /// W-order of `v` (0..=3) from the residuals, to 1e-12.
    fn w_order(r: &[f64; 8]) -> usize {
        let ok = |k: std::ops::Range<usize>| r[k].iter().all(|x| x.abs() < 1e-12);
        if !ok(0..1) {
            0
        } else if !ok(1..3) {
            1
        } else if !ok(3..8) {
            2
        } else {
            3
        }
    }

    fn check<const S: usize>(tab: &WTableau<S>, name: &str, w_b: usize, w_bh: usize) {
        let (rb, rosen) = residuals(tab, &tab.b);
        let (rbh, _) = residuals(tab, &tab.bh);
        assert_eq!(w_order(&rb), w_b, "{name} b: residuals {rb:?}");
        assert_eq!(w_order(&rbh), w_bh, "{name} bh: residuals {rbh:?}");
        // every tableau is a Rosenbrock method of order 3 with the exact Jacobian
        assert!(rb[3].abs() < 1e-12 && rosen.abs() < 1e-12, "{name}: {rb:?}");
        let rosen2 = rb[1] + rb[2];
        assert!(rosen2.abs() < 1e-12, "{name}: Rosenbrock order 2 {rosen2}");
    }

    /// W-orders (b; embedded bh): ASSP3P3S1C 3; 2, ROS3Pw 2; 1, ROS3PRw 2; 1, ROS34PRw (as
    /// transcribed) 1; 1, while all four are Rosenbrock methods of order 3.
    #[test]
    fn w_order_conditions() {
        check(&ASSP3P3S1C, "ASSP3P3S1C", 3, 2);
        check(&ROS3PW, "ROS3Pw", 2, 1);
        check(&ROS3PRW, "ROS3PRw", 2, 1);
        check(&ROS34PRW, "ROS34PRw", 1, 1);
    }

    /// The checker itself on the default ROS34PW2 (a W-method of order 3(2)).
    #[test]
    fn w_order_conditions_hold_for_ros34pw2() {
        use crate::sim::rosw::*;
        let tab = WTableau {
            gamma: GAMMA,
            explicit_first: false,
            a: [
                [0.0; 4],
                [A21, 0.0, 0.0, 0.0],
                [A31, A32, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
            g: [
                [0.0; 4],
                [G21, 0.0, 0.0, 0.0],
                [G31, G32, 0.0, 0.0],
                [G41, G42, G43, 0.0],
            ],
            b: [B1, B2, B3, B4],
            bh: [BH1, BH2, BH3, BH4],
        };
        check(&tab, "ROS34PW2", 3, 2);
    }

    #[test]
    fn stage_sharing() {
        assert_eq!(ROS34PRW.same_as(3), Some(2));
        assert_eq!(ROS34PRW.same_as(2), None);
        assert_eq!(ROS3PW.same_as(2), None);
    }
}
