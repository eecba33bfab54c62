//! Coefficients of the Rosenbrock method RODAS4 of E. Hairer and G. Wanner (Solving ODEs II,
//! 2nd ed., Springer 1996, section VI.4, Table 4.2 "RODAS"; the coefficients of `rodas.f`,
//! `ROCOE` with METH = 1, version of October 28, 1996), and the method's trial step.
//!
//! Six stages, order 4 with an embedded order-3 solution, L-stable and stiffly accurate. Every
//! stage lies inside the step (alpha = 0, 0.386, 0.21, 0.63, 1, 1), so the inputs are never read
//! beyond the next stop time. Published in the transformed stage variables of Hairer & Wanner
//! IV.7, eq. (7.25), the form mvem's ROS34PW2 uses too ([`super::rosw::Transformed`]):
//!
//! ```text
//! (I - gamma h J) u_i = gamma (h f(t + alpha_i h, y + sum_j a_ij u_j) + sum_j c_ij u_j)
//!                       + gamma h^2 d_i f_t
//! y_new = y + a_51 u_1 + ... + a_54 u_4 + u_5 + u_6,   error estimate = u_6
//! ```
//!
//! Unlike a W-method, RODAS4 has order 4 only with the exact Jacobian J = df/dy at (t, y) and
//! the exact time derivative f_t = df/dt (the non-autonomous term): both are computed afresh at
//! every step, J by forward differences and f_t by a directional difference along the known
//! input slopes (the inputs are linear between stop times), see [`Integrator::step_rodas4`].
#![allow(clippy::excessive_precision)]

use super::integrator::{Integrator, Interp, LagSegment, Trial};
use super::rosw::IterationMatrix;
use super::segment::SegmentInputs;
use super::SimError;
use crate::model::Dynamics;

/// A six-stage Rosenbrock method of the RODAS family in the transformed form above (the
/// structure of `rodas.f`): stage times 0, `c[0..3]`, 1, 1; f_t coefficients `d` (gamma_5 =
/// gamma_6 = 0); stage arguments `a` (rows 2..5; stage 6 is y5 + u5); couplings `cc` (rows
/// 2..6); dense output `d2`, `d3`.
pub(crate) struct Tableau {
    pub(crate) gamma: f64,
    pub(crate) c: [f64; 3],
    pub(crate) d: [f64; 4],
    pub(crate) a2: [f64; 1],
    pub(crate) a3: [f64; 2],
    pub(crate) a4: [f64; 3],
    pub(crate) a5: [f64; 4],
    pub(crate) c2: [f64; 1],
    pub(crate) c3: [f64; 2],
    pub(crate) c4: [f64; 3],
    pub(crate) c5: [f64; 4],
    pub(crate) c6: [f64; 5],
    pub(crate) d2: [f64; 5],
    pub(crate) d3: [f64; 5],
}

/// RODAS4 (`rodas.f` METH = 1; Hairer & Wanner, Table VI.4.2).
pub(crate) const RODAS4: Tableau = Tableau {
    gamma: 0.25,
    c: [0.386, 0.21, 0.63],
    d: [0.25, -0.1043, 0.1035, -0.036_200_000_000_000_23],
    a2: [1.544],
    a3: [0.946_678_528_081_582_6, 0.255_701_169_898_328_4],
    a4: [
        3.314_825_187_068_521,
        2.896_124_015_972_201,
        0.998_641_913_997_781_7,
    ],
    a5: [
        1.221_224_509_226_641,
        6.019_134_481_288_629,
        12.537_083_329_320_87,
        -0.687_886_036_105_895,
    ],
    c2: [-5.6688],
    c3: [-2.430_093_356_833_875, -0.206_359_915_709_191_5],
    c4: [
        -0.107_352_905_815_137_5,
        -9.594_562_251_023_355,
        -20.470_286_148_096_16,
    ],
    c5: [
        7.496_443_313_967_647,
        -10.246_804_314_643_52,
        -33.999_903_528_199_05,
        11.708_908_932_061_6,
    ],
    c6: [
        8.083_246_795_921_522,
        -7.981_132_988_064_893,
        -31.521_594_328_743_71,
        16.319_305_431_231_36,
        -6.058_818_238_834_054,
    ],
    d2: [
        10.126_235_083_445_86,
        -7.487_995_877_610_167,
        -34.800_918_615_557_47,
        -7.992_771_707_568_823,
        1.025_137_723_295_662,
    ],
    d3: [
        -0.676_280_339_280_125_3,
        6.087_714_651_680_015,
        16.430_843_208_924_78,
        24.767_225_114_183_86,
        -6.594_389_125_716_872,
    ],
};

/// The tableau [`Method::Rodas4`](super::Method::Rodas4) uses.
pub(crate) const TABLEAU: &Tableau = &RODAS4;

impl<const N: usize, M: Dynamics<N>> Integrator<'_, N, M> {
    /// One trial step of RODAS4 (see [`rodas`](self)) with the Jacobian and f_t at (t, y),
    /// computed at the first trial from this point and kept for the retries.
    ///
    /// On a segment with closed-form lag states (`lag_seg` not empty) the method integrates the
    /// other states z as the non-autonomous system dz/dt = f_z(z, a(t), u(t)) with the exact lag
    /// solution a(t), as [`Integrator::step_rosw`] does: the stages take a(t + alpha_i h), the
    /// iteration matrix is I - gamma h J_zz, f_t contains df_z/da a'(t), and the lag states'
    /// error estimate is zero.
    pub(super) fn step_rodas4(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
    ) -> Result<Trial<N, M::Memory>, SimError> {
        self.with_iteration_matrix(
            inp,
            t,
            h,
            f0,
            TABLEAU.gamma,
            1,
            |s, inp, fresh, lag_seg, w| {
                if fresh {
                    let du = inp.rates(t);
                    s.ft = s.time_derivative(inp, t, f0, lag_seg, &du)?;
                }
                s.rodas4_stages(inp, t, h, t_new, f0, lag_seg, w)
            },
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn rodas4_stages(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        w: &IterationMatrix<N>,
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let m = TABLEAU;
        let g = m.gamma;
        let y = self.y;
        let ft = self.ft;
        let hh = h * h;
        // u_i = (I - gamma h J_zz)^-1 (gamma (h f_i + sum_j c_ij u_j) + gamma h^2 d_i f_t)
        let stage = |f: &[f64; N], cu: [f64; N], d: f64| -> [f64; N] {
            let mut r: [f64; N] = std::array::from_fn(|i| g * (h * f[i] + cu[i] + hh * d * ft[i]));
            w.solve(&mut r);
            r
        };
        // exact lag states at t + s
        let exact = |yt: &mut [f64; N], s: f64| LagSegment::advance_all(lag_seg, t, &y, yt, s);
        let [c2, c3, c4] = m.c;
        let [d1, d2, d3, d4] = m.d;
        let u1 = stage(f0, [0.0; N], d1);
        let mut y2: [f64; N] = std::array::from_fn(|i| y[i] + m.a2[0] * u1[i]);
        exact(&mut y2, c2 * h);
        let f2 = self.rhs(inp, t + c2 * h, &y2)?.dx;
        let u2 = stage(&f2, std::array::from_fn(|i| m.c2[0] * u1[i]), d2);
        let [a31, a32] = m.a3;
        let mut y3: [f64; N] = std::array::from_fn(|i| y[i] + a31 * u1[i] + a32 * u2[i]);
        exact(&mut y3, c3 * h);
        let f3 = self.rhs(inp, t + c3 * h, &y3)?.dx;
        let [c31, c32] = m.c3;
        let u3 = stage(&f3, std::array::from_fn(|i| c31 * u1[i] + c32 * u2[i]), d3);
        let [a41, a42, a43] = m.a4;
        let mut y4: [f64; N] =
            std::array::from_fn(|i| y[i] + a41 * u1[i] + a42 * u2[i] + a43 * u3[i]);
        exact(&mut y4, c4 * h);
        let f4 = self.rhs(inp, t + c4 * h, &y4)?.dx;
        let [c41, c42, c43] = m.c4;
        let u4 = stage(
            &f4,
            std::array::from_fn(|i| c41 * u1[i] + c42 * u2[i] + c43 * u3[i]),
            d4,
        );
        // stages 5 and 6 at t + h (alpha_5 = alpha_6 = 1, gamma_5 = gamma_6 = 0)
        let s1 = t_new - t;
        let [a51, a52, a53, a54] = m.a5;
        let mut y5: [f64; N] =
            std::array::from_fn(|i| y[i] + a51 * u1[i] + a52 * u2[i] + a53 * u3[i] + a54 * u4[i]);
        exact(&mut y5, s1);
        let f5 = self.rhs(inp, t_new, &y5)?.dx;
        let [c51, c52, c53, c54] = m.c5;
        let u5 = stage(
            &f5,
            std::array::from_fn(|i| c51 * u1[i] + c52 * u2[i] + c53 * u3[i] + c54 * u4[i]),
            0.0,
        );
        // the embedded (order 3) solution is the argument of stage 6
        let mut y6: [f64; N] = std::array::from_fn(|i| y5[i] + u5[i]);
        exact(&mut y6, s1);
        let f6 = self.rhs(inp, t_new, &y6)?.dx;
        let [c61, c62, c63, c64, c65] = m.c6;
        let u6 = stage(
            &f6,
            std::array::from_fn(|i| {
                c61 * u1[i] + c62 * u2[i] + c63 * u3[i] + c64 * u4[i] + c65 * u5[i]
            }),
            0.0,
        );
        let mut y1: [f64; N] = std::array::from_fn(|i| y6[i] + u6[i]);
        for l in lag_seg {
            y1[l.state] = y6[l.state];
        }
        let dense = |d: &[f64; 5]| -> [f64; N] {
            std::array::from_fn(|i| {
                d[0] * u1[i] + d[1] * u2[i] + d[2] * u3[i] + d[3] * u4[i] + d[4] * u5[i]
            })
        };
        Ok(Trial {
            y1,
            err: self.error_norm(&self.y, &y1, &u6),
            e: u6,
            dense: Some(Interp::Rodas {
                y0: y,
                y1,
                c3: dense(&m.d2),
                c4: dense(&m.d3),
            }),
            f1: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tableau as full 6 x 6 matrices: a~ (stage arguments), c (stage couplings), m
    /// (solution weights), mh (embedded weights).
    type Mat6 = [[f64; 6]; 6];

    fn transformed(m: &Tableau) -> (Mat6, Mat6, [f64; 6], [f64; 6]) {
        let [a51, a52, a53, a54] = m.a5;
        let a = [
            [0.0; 6],
            [m.a2[0], 0.0, 0.0, 0.0, 0.0, 0.0],
            [m.a3[0], m.a3[1], 0.0, 0.0, 0.0, 0.0],
            [m.a4[0], m.a4[1], m.a4[2], 0.0, 0.0, 0.0],
            [a51, a52, a53, a54, 0.0, 0.0],
            [a51, a52, a53, a54, 1.0, 0.0],
        ];
        let c = [
            [0.0; 6],
            [m.c2[0], 0.0, 0.0, 0.0, 0.0, 0.0],
            [m.c3[0], m.c3[1], 0.0, 0.0, 0.0, 0.0],
            [m.c4[0], m.c4[1], m.c4[2], 0.0, 0.0, 0.0],
            [m.c5[0], m.c5[1], m.c5[2], m.c5[3], 0.0, 0.0],
            [m.c6[0], m.c6[1], m.c6[2], m.c6[3], m.c6[4], 0.0],
        ];
        (
            a,
            c,
            [a51, a52, a53, a54, 1.0, 1.0],
            [a51, a52, a53, a54, 1.0, 0.0],
        )
    }

    /// Back from the transformed form to Hairer & Wanner's (7.4): Gamma^-1 = I/gamma - c, the
    /// stage coefficients alpha = a~ Gamma, the weights b = m Gamma. Then the order conditions
    /// of Table IV.7.1 up to order 4 for b, up to order 3 for the embedded weights, the stage
    /// times alpha_i = sum_j alpha_ij against the published c (and 1, 1), and the f_t
    /// coefficients gamma_i = sum_j Gamma_ij against the published d (and 0, 0).
    #[test]
    fn order_conditions() {
        check_tableau("RODAS4", &RODAS4);
    }

    fn check_tableau(name: &str, m: &Tableau) {
        let (at, c, mw, mh) = transformed(m);
        let g = m.gamma;
        // Gamma^-1 (lower triangular), then Gamma by forward substitution
        let gi: [[f64; 6]; 6] = std::array::from_fn(|i| {
            std::array::from_fn(|j| if i == j { 1.0 / g } else { -c[i][j] })
        });
        let mut gam = [[0.0; 6]; 6];
        for col in 0..6 {
            for r in col..6 {
                let rhs = if r == col { 1.0 } else { 0.0 };
                let s: f64 = (col..r).map(|j| gi[r][j] * gam[j][col]).sum();
                gam[r][col] = (rhs - s) / gi[r][r];
            }
        }
        let alpha: [[f64; 6]; 6] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..6).map(|k| at[i][k] * gam[k][j]).sum())
        });
        let row = |v: [f64; 6]| -> [f64; 6] {
            std::array::from_fn(|j| (0..6).map(|k| v[k] * gam[k][j]).sum())
        };
        let (b, bh) = (row(mw), row(mh));
        let ai: [f64; 6] = std::array::from_fn(|i| alpha[i].iter().sum());
        for (x, y) in ai.iter().zip([0.0, m.c[0], m.c[1], m.c[2], 1.0, 1.0]) {
            assert!((x - y).abs() < 1e-12, "{name}: alpha_i {ai:?}");
        }
        let gsum: [f64; 6] = std::array::from_fn(|i| gam[i].iter().sum());
        for (x, y) in gsum.iter().zip([m.d[0], m.d[1], m.d[2], m.d[3], 0.0, 0.0]) {
            assert!((x - y).abs() < 1e-12, "{name}: gamma_i {gsum:?}");
        }
        // beta_ij = alpha_ij + gamma_ij below the diagonal, beta'_i = sum_{j<i} beta_ij
        let beta: [[f64; 6]; 6] = std::array::from_fn(|i| {
            std::array::from_fn(|j| if j < i { alpha[i][j] + gam[i][j] } else { 0.0 })
        });
        let bp: [f64; 6] = std::array::from_fn(|i| beta[i].iter().sum());
        let s1 = |w: &[f64; 6]| -> f64 { w.iter().sum() };
        let s2 = |w: &[f64; 6]| -> f64 { (0..6).map(|i| w[i] * bp[i]).sum() };
        let s3a = |w: &[f64; 6]| -> f64 { (0..6).map(|i| w[i] * ai[i] * ai[i]).sum() };
        let bbp: [f64; 6] = std::array::from_fn(|i| (0..6).map(|j| beta[i][j] * bp[j]).sum());
        let s3b = |w: &[f64; 6]| -> f64 { (0..6).map(|i| w[i] * bbp[i]).sum() };
        for (wn, w) in [("b", &b), ("bh", &bh)] {
            assert!((s1(w) - 1.0).abs() < 1e-12, "{name} {wn} order 1");
            assert!((s2(w) - (0.5 - g)).abs() < 1e-12, "{name} {wn} order 2");
            assert!((s3a(w) - 1.0 / 3.0).abs() < 1e-12, "{name} {wn} order 3a");
            assert!(
                (s3b(w) - (1.0 / 6.0 - g + g * g)).abs() < 1e-12,
                "{name} {wn} order 3b"
            );
        }
        // order 4 (b only)
        let o4a: f64 = (0..6).map(|i| b[i] * ai[i].powi(3)).sum();
        let o4b: f64 = (0..6)
            .map(|i| b[i] * ai[i] * (0..6).map(|j| alpha[i][j] * bp[j]).sum::<f64>())
            .sum();
        let o4c: f64 = (0..6)
            .map(|i| b[i] * (0..6).map(|j| beta[i][j] * ai[j] * ai[j]).sum::<f64>())
            .sum();
        let o4d: f64 = (0..6)
            .map(|i| b[i] * (0..6).map(|j| beta[i][j] * bbp[j]).sum::<f64>())
            .sum();
        assert!((o4a - 0.25).abs() < 1e-12, "{name}: {o4a}");
        assert!((o4b - (1.0 / 8.0 - g / 3.0)).abs() < 1e-12, "{name}: {o4b}");
        assert!(
            (o4c - (1.0 / 12.0 - g / 3.0)).abs() < 1e-12,
            "{name}: {o4c}"
        );
        assert!(
            (o4d - (1.0 / 24.0 - g / 2.0 + 1.5 * g * g - g * g * g)).abs() < 1e-12,
            "{name}: {o4d}"
        );
        // the embedded solution is not of order 4 (else the error estimate would vanish)
        let e4: f64 = (0..6).map(|i| bh[i] * ai[i].powi(3)).sum();
        assert!((e4 - 0.25).abs() > 1e-3, "{name}: {e4}");
        // stiffly accurate: b is the last row of beta plus gamma on the diagonal
        for j in 0..5 {
            assert!((b[j] - beta[5][j]).abs() < 1e-12, "{name}: b_{j}");
        }
        assert!((b[5] - g).abs() < 1e-12);
    }
}
