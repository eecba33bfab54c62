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
//! (to 17 digits). Below the tableau: the method's trial step on the [`Integrator`].
#![allow(clippy::excessive_precision)]

use super::error::dump;
use super::integrator::{Integrator, Interp, LagSegment, Trial};
use super::segment::SegmentInputs;
use super::SimError;
use crate::model::Dynamics;
use crate::numerics::linalg;

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

/// The coefficients of the non-autonomous term, gamma_i = sum_{j<=i} Gamma_ij (Hairer &
/// Wanner IV.7, eq. (7.4')): stage i adds gamma_i h^2 f_t (gamma_4 = gamma + sum g_4j = 0, the
/// method being stiffly accurate).
pub(crate) const D: [f64; 4] = [GAMMA, GAMMA + G21, GAMMA + G31 + G32, 0.0];

pub(crate) const BH1: f64 = 0.378_109_031_458_193_69;
pub(crate) const BH2: f64 = -0.096_042_292_212_423_178;
pub(crate) const BH3: f64 = 0.5;
pub(crate) const BH4: f64 = 0.217_933_260_754_229_5;

/// ROS34PW2's dense output: the cubic Hermite interpolant while h times the bound on the
/// Jacobian's spectral radius ([`Integrator::jac_rho`]) is at most this, else the stages'
/// continuous extension ([`Transformed::d`]).
pub(crate) const STIFF_DENSE: f64 = 50.0;

/// Steps a finite-difference Jacobian is reused before it is recomputed.
pub(crate) const JAC_MAX_AGE: usize = 12;
/// A rejected step recomputes the Jacobian if it is at least this many steps old.
pub(crate) const JAC_REFRESH_ON_REJECT: usize = 3;

/// The tableau in the transformed stage variables u_i = sum_j Gamma_ij k_j (Hairer & Wanner,
/// Solving ODEs II, IV.7, eq. (7.25)), Gamma = (g_ij) + gamma I:
///
/// ```text
/// (I - gamma h J) u_i = gamma (h f(t + alpha_i h, y + sum_j a~_ij u_j) + sum_j c_ij u_j)
/// y_new = y + sum_i m_i u_i,   error estimate = sum_i e_i u_i
/// ```
///
/// with a~ = A Gamma^-1, c = diag(1/gamma) - Gamma^-1 (below the diagonal), m = b Gamma^-1 and
/// e = (b - bh) Gamma^-1. The same method as the k form for any J (a change of variables), but
/// without the products J sum_j g_ij k_j.
pub(crate) struct Transformed {
    pub(crate) a21: f64,
    pub(crate) a31: f64,
    pub(crate) a32: f64,
    pub(crate) a41: f64,
    pub(crate) a42: f64,
    pub(crate) a43: f64,
    pub(crate) c21: f64,
    pub(crate) c31: f64,
    pub(crate) c32: f64,
    pub(crate) c41: f64,
    pub(crate) c42: f64,
    pub(crate) c43: f64,
    pub(crate) m: [f64; 4],
    pub(crate) e: [f64; 4],
    /// The continuous extension's coefficients on the u_i ([`Transformed::new`]):
    /// `y(t + s h) = (1 - s) y + s (y_new + (1 - s) sum_i d_i u_i)`.
    pub(crate) d: [f64; 4],
}

impl Transformed {
    /// The transformed coefficients computed from the published tableau.
    pub(crate) fn new() -> Self {
        let gam = [
            [GAMMA, 0.0, 0.0, 0.0],
            [G21, GAMMA, 0.0, 0.0],
            [G31, G32, GAMMA, 0.0],
            [G41, G42, G43, GAMMA],
        ];
        // Gamma^-1 by forward substitution, column by column
        let mut gi = [[0.0; 4]; 4];
        for col in 0..4 {
            for r in col..4 {
                let rhs = if r == col { 1.0 } else { 0.0 };
                let s: f64 = (col..r).map(|j| gam[r][j] * gi[j][col]).sum();
                gi[r][col] = (rhs - s) / gam[r][r];
            }
        }
        let a = [
            [0.0; 4],
            [A21, 0.0, 0.0, 0.0],
            [A31, A32, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        let at = |i: usize, j: usize| (0..4).map(|k| a[i][k] * gi[k][j]).sum::<f64>();
        let row = |v: [f64; 4]| -> [f64; 4] {
            std::array::from_fn(|j| (0..4).map(|k| v[k] * gi[k][j]).sum())
        };
        // The continuous extension y(t + s h) = y + sum_i b_i(s) k_i with
        // b(s) = s b + s (1 - s) p: second order for every s (W-conditions b(s).1 = s,
        // b(s).alpha = s^2 / 2, b(s).g = 0, with alpha and g = Gamma 1 the row sums of A and
        // Gamma; they hold at s = 1 and, as b satisfies them, give p.1 = 0, p.alpha = -1/2,
        // p.g = 0), and stiffly linear: on y' = lambda y with h lambda -> -inf the stages tend to
        // k = -B^-1 1 y (B = A + Gamma), and p.B^-1 1 = 0 makes y(t + s h) = (1 - s) y, the
        // straight line to the L-stable step's 0. A cubic Hermite interpolant uses f at the
        // end points instead, whose errors a stiff state multiplies by |lambda| h.
        let alpha = [0.0, ALPHA2, ALPHA3, 1.0];
        let g: [f64; 4] = std::array::from_fn(|i| gam[i].iter().sum());
        let mut v = [0.0; 4];
        for i in 0..4 {
            let s: f64 = (0..i).map(|j| (a[i][j] + gam[i][j]) * v[j]).sum();
            v[i] = (1.0 - s) / gam[i][i];
        }
        let p = solve4([[1.0; 4], alpha, g, v], [0.0, -0.5, 0.0, 0.0]);
        Self {
            a21: at(1, 0),
            a31: at(2, 0),
            a32: at(2, 1),
            a41: at(3, 0),
            a42: at(3, 1),
            a43: at(3, 2),
            c21: -gi[1][0],
            c31: -gi[2][0],
            c32: -gi[2][1],
            c41: -gi[3][0],
            c42: -gi[3][1],
            c43: -gi[3][2],
            m: row([B1, B2, B3, B4]),
            e: row([B1 - BH1, B2 - BH2, B3 - BH3, B4 - BH4]),
            d: row(p),
        }
    }
}

/// The solution x of `m x = r` (4 x 4, by [`linalg::lu_factor`] and [`linalg::lu_solve`]; for
/// the coefficients above, computed once; the matrix is regular, `Transformed`'s unit test
/// checks the conditions it solves).
fn solve4(mut m: [[f64; 4]; 4], mut r: [f64; 4]) -> [f64; 4] {
    let mut piv = [0; 4];
    let regular = linalg::lu_factor::<4, 4>(&mut m, &mut piv);
    debug_assert!(
        regular,
        "the continuous extension's conditions are independent"
    );
    let dinv: [f64; 4] = std::array::from_fn(|k| 1.0 / m[k][k]);
    linalg::lu_solve::<4, 4>(&m, &piv, &dinv, &mut r);
    r
}

/// [`Transformed`], computed once.
pub(crate) static TRANSFORMED: std::sync::LazyLock<Transformed> =
    std::sync::LazyLock::new(Transformed::new);

/// LU factors of I - gamma h J_zz, where J_zz is the Jacobian with the rows and columns of the
/// closed-form lag states (if `reduced`) replaced by those of the identity: on the other states
/// (z) the iteration matrix of the W-method, decoupled from the lag states, which the solve
/// leaves at 0. When the lag states are the trailing ones (the engine models), only the leading
/// `nz` x `nz` block is factored and solved, with loop bounds fixed at compile time for the
/// block sizes of the engine models ([`block_size`]); otherwise the full N x N matrix is, the lag
/// entries masked to 0. Full N x N storage with fixed loop bounds: for N = 8 faster than a
/// 5 x 5 block of run-time size. (Stage solves by the block's inverse, 2-3.5 % faster on the
/// WHTC, were measured and not kept: they moved the tuning's step 3 off; docs/integrator.md,
/// session 20.)
pub(super) struct IterationMatrix<const N: usize> {
    /// Step size \[s\] the factors were made for.
    pub(super) h: f64,
    /// Whether the lag states are left out.
    pub(super) reduced: bool,
    /// Size of the factored leading block ([`block_size`]; `None`: the whole matrix, masked).
    pub(super) block: Option<usize>,
    /// LU factors of the leading block (L unit lower, U upper).
    pub(super) lu: [[f64; N]; N],
    /// Row permutation of the LU factors.
    pub(super) piv: [usize; N],
    /// 1 / U_aa: the back substitution multiplies instead of dividing.
    pub(super) dinv: [f64; N],
    /// 1 on the z states, 0 on the lag states of a reduced matrix.
    pub(super) mask: [f64; N],
}

/// The leading block of an `N`-state iteration matrix without the lag states `is_lag`: their
/// count subtracted from N if they are the trailing states and the result is one of the block
/// sizes compiled in (5, 7, 9: the 8-, 10- and 12-state engine models without their three
/// actuator states), else `None` (the whole matrix, lag entries masked). An `Option`, not N for
/// the whole matrix: a 5-, 7- or 9-state system whose lags are not trailing is no leading block
/// (until session 20 it took those paths unmasked).
pub(super) fn block_size<const N: usize>(is_lag: &[bool; N]) -> Option<usize> {
    let n_lag = is_lag.iter().filter(|&&l| l).count();
    let nz = N - n_lag;
    let trailing = is_lag.iter().enumerate().all(|(i, &l)| l == (i >= nz));
    (trailing && matches!(nz, 5 | 7 | 9)).then_some(nz)
}

/// Set the leading `Z` x `Z` block of `lu` to I - `gh` J (the same arithmetic as the full
/// masked matrix on that block; the rest of `lu` is left as it is, unread by
/// `lu_factor::<N, Z>` and `lu_solve::<N, Z>` apart from being moved with its rows).
#[inline]
fn leading_block<const N: usize, const Z: usize>(
    lu: &mut [[f64; N]; N],
    j: &[[f64; N]; N],
    gh: f64,
) {
    for a in 0..Z.min(N) {
        for b in 0..Z.min(N) {
            lu[a][b] = -gh * j[a][b];
        }
        lu[a][a] += 1.0;
    }
}

impl<const N: usize> IterationMatrix<N> {
    /// Factor `lu` (set to I - gamma h J_zz) on its leading block (all of it if none); false if
    /// singular.
    fn factor(&mut self) -> bool {
        let (lu, piv) = (&mut self.lu, &mut self.piv);
        let ok = match self.block {
            Some(5) => linalg::lu_factor::<N, 5>(lu, piv),
            Some(7) => linalg::lu_factor::<N, 7>(lu, piv),
            Some(9) => linalg::lu_factor::<N, 9>(lu, piv),
            _ => linalg::lu_factor::<N, N>(lu, piv),
        };
        for a in 0..self.block.unwrap_or(N) {
            self.dinv[a] = 1.0 / self.lu[a][a];
        }
        ok
    }

    /// Solve (I - gamma h J_zz) x = r on the z states in place; the lag entries of `r` become 0.
    #[inline]
    pub(super) fn solve(&self, r: &mut [f64; N]) {
        let (lu, piv, dinv) = (&self.lu, &self.piv, &self.dinv);
        let Some(nz) = self.block else {
            for (v, m) in r.iter_mut().zip(&self.mask) {
                *v *= m;
            }
            linalg::lu_solve::<N, N>(lu, piv, dinv, r);
            return;
        };
        match nz {
            5 => linalg::lu_solve::<N, 5>(lu, piv, dinv, r),
            7 => linalg::lu_solve::<N, 7>(lu, piv, dinv, r),
            _ => linalg::lu_solve::<N, 9>(lu, piv, dinv, r),
        }
        for v in r.iter_mut().skip(nz) {
            *v = 0.0;
        }
    }
}

impl<const N: usize, M: Dynamics<N>> Integrator<'_, N, M> {
    /// One trial step of the Rosenbrock-W method ROS34PW2 (see [`rosw`]).
    ///
    /// On a segment with closed-form lag states (`lag_seg` not empty) the method integrates the
    /// other states only, as the non-autonomous system dz/dt = f_z(z, a(t), u(t)) with the exact
    /// lag solution a(t): the stages take a(t + alpha_i h), the iteration matrix is
    /// I - gamma h J_zz (J without the lag rows and columns), and the lag states' error estimate
    /// is zero. This is the W-method applied to the smaller system, so order and error control
    /// are those of ROS34PW2.
    ///
    /// With [`SimOptions::rosw_time_derivative`] (the default) the stages carry the
    /// non-autonomous term gamma_i h^2 f_t, f_t the derivative of the integrated system in t
    /// ([`Integrator::time_derivative`]: one evaluation, along the inputs' slopes and the lag
    /// states' rates). A W-method admits an approximate f_t as it admits an approximate J (time
    /// as a state, f_t its Jacobian column), so f_t is lagged like J: recomputed with J and at
    /// the first step of every segment where the inputs' slopes changed (not at the kinks of
    /// the delayed commands that drive closed-form lag states only: the lag states' rates are
    /// continuous there, and f_t with them; 1.3 % fewer evaluations). Without it the method
    /// is of order 3 as well, but after each input kink its error constant holds the jump of
    /// the slopes. On the WHTC the term (with the first-step rules of RODAS4, which it makes
    /// pay) saves 19 % of the trial steps, 21 % of the factorizations and 11 % of the
    /// evaluations, and lowers the deviation from 6.6e-5 to 3.9e-5 (`docs/integrator.md`, "The
    /// non-autonomous term of ROS34PW2").
    ///
    /// [`SimOptions::rosw_time_derivative`]: super::SimOptions::rosw_time_derivative
    pub(super) fn step_rosw(
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
            GAMMA,
            JAC_MAX_AGE,
            |s, inp, fresh, lag_seg, w| {
                let with_ft = s.opts.rosw_time_derivative;
                let start = inp.segment_start();
                if with_ft && (fresh || s.ft_segment != start) {
                    // The inputs' slopes at this segment; with closed-form lags the delayed
                    // commands enter f only through the lag states, whose rates are continuous
                    // at their commands' kinks: their slopes do not count.
                    // (`ft_slopes` starts as NaN: unequal to any slopes)
                    let du = inp.rates(t);
                    let mut slopes = du.to_array();
                    if !lag_seg.is_empty() {
                        slopes[4] = 0.0;
                        slopes[5] = 0.0;
                    }
                    if fresh || slopes != s.ft_slopes {
                        s.ft = s.time_derivative(inp, t, f0, lag_seg, &du)?;
                        s.ft_slopes = slopes;
                    }
                    s.ft_segment = start;
                }
                s.rosw_stages(inp, t, h, t_new, f0, lag_seg, w, with_ft)
            },
        )
    }

    /// Set up the iteration matrix I - `gamma` h J ([`Integrator::iteration_matrix`], J at most
    /// `max_age` steps old) and run a Rosenbrock method's `stages` with it, the segment's lag
    /// states and whether J was just recomputed. The lag states and the factors are moved out
    /// of `self` for the stages (which borrow it mutably) and put back whatever happens.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn with_iteration_matrix<F>(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        f0: &[f64; N],
        gamma: f64,
        max_age: usize,
        stages: F,
    ) -> Result<Trial<N, M::Memory>, SimError>
    where
        F: FnOnce(
            &mut Self,
            &mut SegmentInputs,
            bool,
            &[LagSegment],
            &IterationMatrix<N>,
        ) -> Result<Trial<N, M::Memory>, SimError>,
    {
        let lag_seg = std::mem::take(&mut self.lag_seg);
        let trial = self
            .iteration_matrix(inp, t, h, f0, &lag_seg, gamma, max_age)
            .and_then(|fresh| {
                let w = self.lu.take().expect("iteration matrix set up");
                let trial = stages(self, inp, fresh, &lag_seg, &w);
                self.lu = Some(w);
                trial
            });
        self.lag_seg = lag_seg;
        trial
    }

    /// Make `self.lu` the iteration matrix I - `gamma` h J for step size `h`, with the Jacobian
    /// J recomputed at (t, y) when it is missing or `max_age` or more accepted steps old (a
    /// Rosenbrock method that needs the exact Jacobian passes 1: a fresh one at every step, kept
    /// for the retries of a rejected step, which start from the same point). Returns whether J
    /// was recomputed.
    ///
    /// (I - gamma h J) is refactored only when J, h or the set of lag states changed, e.g. not
    /// for the second of two equal steps that split a segment remainder (h equal up to rounding:
    /// the factors of I - gamma h' J with |h'/h - 1| <= 1e-9 are those of I - gamma h J' with
    /// J' = (h'/h) J, and a W-method admits any J'; in the transformed stage variables J
    /// appears nowhere else).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn iteration_matrix(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        gamma: f64,
        max_age: usize,
    ) -> Result<bool, SimError> {
        let reduced = !lag_seg.is_empty();
        let mut is_lag = [false; N];
        for l in lag_seg {
            is_lag[l.state] = true;
        }
        let fresh = self.jac.is_none() || self.jac_age >= max_age || (!reduced && !self.jac_full);
        if fresh {
            let j = self.jacobian(inp, t, f0, &is_lag)?;
            let sc = self.model.state_scales();
            self.jac_rho = (0..N)
                .filter(|&r| !is_lag[r])
                .map(|r| {
                    (0..N)
                        .filter(|&c| !is_lag[c])
                        .map(|c| j[r][c].abs() * sc[c] / sc[r])
                        .sum::<f64>()
                })
                .fold(0.0, f64::max);
            self.jac = Some(j);
            self.jac_full = !reduced;
            self.jac_age = 0;
            self.lu = None;
        }
        if let Some(w) = &self.lu {
            if w.reduced == reduced && (w.h - h).abs() <= 1e-9 * h {
                return Ok(fresh);
            }
        }
        let j = self.jac.as_ref().expect("Jacobian set above");
        let mut w = self.lu.take().unwrap_or_else(|| {
            Box::new(IterationMatrix {
                h,
                reduced,
                block: None,
                lu: [[0.0; N]; N],
                piv: [0; N],
                dinv: [0.0; N],
                mask: [1.0; N],
            })
        });
        w.h = h;
        w.reduced = reduced;
        w.block = block_size(&is_lag);
        let gh = gamma * h;
        match w.block {
            // leading block only: the factor and the solve of a leading block read nothing else
            Some(5) => leading_block::<N, 5>(&mut w.lu, j, gh),
            Some(7) => leading_block::<N, 7>(&mut w.lu, j, gh),
            Some(9) => leading_block::<N, 9>(&mut w.lu, j, gh),
            _ => {
                for a in 0..N {
                    w.mask[a] = if is_lag[a] { 0.0 } else { 1.0 };
                    for b in 0..N {
                        w.lu[a][b] = if is_lag[a] || is_lag[b] {
                            0.0
                        } else {
                            -gamma * h * j[a][b]
                        };
                    }
                    w.lu[a][a] += 1.0;
                }
            }
        }
        if !w.factor() {
            return Err(self.singular(t, h));
        }
        self.stats.lu += 1;
        self.lu = Some(w);
        Ok(fresh)
    }

    /// The four stages of ROS34PW2 with the iteration matrix `w`, in the transformed stage
    /// variables u_i = sum_j Gamma_ij k_j of Hairer & Wanner IV.7 (eq. (7.25)), which need no
    /// products J k (see [`Transformed`]), with the non-autonomous term `self.ft` if `with_ft`.
    #[allow(clippy::too_many_arguments)]
    fn rosw_stages(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        w: &IterationMatrix<N>,
        with_ft: bool,
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let c = &*TRANSFORMED;
        let y = self.y;
        let ft = self.ft;
        let hh = h * h;
        // u_i = (I - gamma h J_zz)^-1 gamma (h f_i + sum_j c_ij u_j + gamma_i h^2 f_t) on the z
        // states; 0 on the lag states (their values are exact, the increments are not used).
        // The factors were made for w.h, i.e. for the Jacobian (w.h / h) J: a W-method admits
        // any.
        let stage = |f: &[f64; N], cu: [f64; N], d: f64| -> [f64; N] {
            let mut r: [f64; N] = if with_ft {
                std::array::from_fn(|i| GAMMA * (h * f[i] + cu[i] + hh * d * ft[i]))
            } else {
                std::array::from_fn(|i| GAMMA * (h * f[i] + cu[i]))
            };
            w.solve(&mut r);
            r
        };
        // exact lag states at t + s
        let exact = |yt: &mut [f64; N], s: f64| LagSegment::advance_all(lag_seg, t, &y, yt, s);
        let u1 = stage(f0, [0.0; N], D[0]);
        // stage 2
        let mut y2: [f64; N] = std::array::from_fn(|i| y[i] + c.a21 * u1[i]);
        exact(&mut y2, ALPHA2 * h);
        let f2 = self.rhs(inp, t + ALPHA2 * h, &y2)?.dx;
        let u2 = stage(&f2, std::array::from_fn(|i| c.c21 * u1[i]), D[1]);
        // stage 3
        let mut y3: [f64; N] = std::array::from_fn(|i| y[i] + c.a31 * u1[i] + c.a32 * u2[i]);
        exact(&mut y3, ALPHA3 * h);
        let f3 = self.rhs(inp, t + ALPHA3 * h, &y3)?.dx;
        let u3 = stage(
            &f3,
            std::array::from_fn(|i| c.c31 * u1[i] + c.c32 * u2[i]),
            D[2],
        );
        // stage 4 (alpha4 = 1)
        let mut y4: [f64; N] =
            std::array::from_fn(|i| y[i] + c.a41 * u1[i] + c.a42 * u2[i] + c.a43 * u3[i]);
        exact(&mut y4, t_new - t);
        let f4 = self.rhs(inp, t_new, &y4)?.dx;
        let u4 = stage(
            &f4,
            std::array::from_fn(|i| c.c41 * u1[i] + c.c42 * u2[i] + c.c43 * u3[i]),
            D[3],
        );
        let [m1, m2, m3, m4] = c.m;
        let mut y1: [f64; N] =
            std::array::from_fn(|i| y[i] + m1 * u1[i] + m2 * u2[i] + m3 * u3[i] + m4 * u4[i]);
        for l in lag_seg {
            y1[l.state] = y4[l.state];
        }
        let [e1, e2, e3, e4] = c.e;
        let e: [f64; N] =
            std::array::from_fn(|i| e1 * u1[i] + e2 * u2[i] + e3 * u3[i] + e4 * u4[i]);
        // cubic Hermite (from f at the end points) while the step is short against the fast
        // modes; the stages' continuous extension when f's errors there would be amplified
        let dense = if h * self.jac_rho <= STIFF_DENSE {
            None
        } else {
            let [d1, d2, d3, d4] = c.d;
            Some(Interp::Rodas {
                y0: y,
                y1,
                c3: std::array::from_fn(|i| d1 * u1[i] + d2 * u2[i] + d3 * u3[i] + d4 * u4[i]),
                c4: [0.0; N],
            })
        };
        Ok(Trial {
            y1,
            err: self.error_norm(&self.y, &y1, &e),
            e,
            dense,
            f1: None,
        })
    }

    pub(super) fn singular(&self, t: f64, h: f64) -> SimError {
        SimError::NonFinite {
            t,
            what: "Newton matrix (I - gamma h J) for",
            name: format!("step h = {h:e}"),
            value: f64::NAN,
            state: dump(self.model, &self.y),
            hint:
                "the Jacobian is singular or non-finite; the model may have left its valid region"
                    .into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One step of the k form (module docs) and of the transformed form ([`Transformed`]) on
    /// y' = lambda y with a W-matrix mu != lambda agree to rounding (both y_new and the error
    /// estimate).
    #[test]
    fn transformed_stages_equal_k_form() {
        let (lambda, mu, h, y0) = (-3.0_f64, -2.2_f64, 0.37_f64, 1.3_f64);
        let f = |y: f64| lambda * y;
        let d = 1.0 - GAMMA * h * mu;
        // k form
        let k1 = h * f(y0) / d;
        let k2 = (h * f(y0 + A21 * k1) + h * mu * G21 * k1) / d;
        let k3 = (h * f(y0 + A31 * k1 + A32 * k2) + h * mu * (G31 * k1 + G32 * k2)) / d;
        let k4 = (h * f(y0 + k3) + h * mu * (G41 * k1 + G42 * k2 + G43 * k3)) / d;
        let y_k = y0 + B1 * k1 + B2 * k2 + B3 * k3 + B4 * k4;
        let e_k = (B1 - BH1) * k1 + (B2 - BH2) * k2 + (B3 - BH3) * k3 + (B4 - BH4) * k4;
        // transformed form
        let c = Transformed::new();
        let u1 = GAMMA * h * f(y0) / d;
        let u2 = GAMMA * (h * f(y0 + c.a21 * u1) + c.c21 * u1) / d;
        let u3 = GAMMA * (h * f(y0 + c.a31 * u1 + c.a32 * u2) + c.c31 * u1 + c.c32 * u2) / d;
        let u4 = GAMMA
            * (h * f(y0 + c.a41 * u1 + c.a42 * u2 + c.a43 * u3)
                + c.c41 * u1
                + c.c42 * u2
                + c.c43 * u3)
            / d;
        let y_u = y0 + c.m[0] * u1 + c.m[1] * u2 + c.m[2] * u3 + c.m[3] * u4;
        let e_u = c.e[0] * u1 + c.e[1] * u2 + c.e[2] * u3 + c.e[3] * u4;
        assert!((y_u - y_k).abs() < 1e-14, "{y_u} {y_k}");
        assert!((e_u - e_k).abs() < 1e-14, "{e_u} {e_k}");
        assert!(
            e_k.abs() > 1e-4,
            "the test must exercise the error estimate: {e_k}"
        );
    }

    /// The continuous extension ([`Transformed::d`]) in the k form, b(s) = s b + s (1 - s) p
    /// with p = d Gamma: second-order W-conditions at every s, and on y' = lambda y with
    /// h lambda = -1e9 (W exact) the straight line (1 - s) y0 from y0 to the step's ~0, where
    /// the Hermite cubic is off by about 0.15 |h lambda| times the end points' error.
    #[test]
    fn continuous_extension_is_second_order_and_stiffly_linear() {
        let c = Transformed::new();
        let gam = [
            [GAMMA, 0.0, 0.0, 0.0],
            [G21, GAMMA, 0.0, 0.0],
            [G31, G32, GAMMA, 0.0],
            [G41, G42, G43, GAMMA],
        ];
        let p: [f64; 4] = std::array::from_fn(|j| (0..4).map(|k| c.d[k] * gam[k][j]).sum());
        let b = [B1, B2, B3, B4];
        let alpha = [0.0, ALPHA2, ALPHA3, 1.0];
        let g: [f64; 4] = std::array::from_fn(|i| gam[i].iter().sum());
        let dot = |x: [f64; 4], y: [f64; 4]| (0..4).map(|i| x[i] * y[i]).sum::<f64>();
        for s in [0.1, 0.3, 0.5, 0.8, 1.0] {
            let bs: [f64; 4] = std::array::from_fn(|i| s * b[i] + s * (1.0 - s) * p[i]);
            assert!((dot(bs, [1.0; 4]) - s).abs() < 1e-13, "s = {s}");
            assert!((dot(bs, alpha) - s * s / 2.0).abs() < 1e-13, "s = {s}");
            assert!(dot(bs, g).abs() < 1e-13, "s = {s}");
        }
        // one step of the transformed form on y' = lambda y with W = lambda, very stiff
        let (z, y0) = (-1e9_f64, 1.0_f64);
        let d = 1.0 - GAMMA * z;
        let u1 = GAMMA * z * y0 / d;
        let u2 = GAMMA * (z * (y0 + c.a21 * u1) + c.c21 * u1) / d;
        let u3 = GAMMA * (z * (y0 + c.a31 * u1 + c.a32 * u2) + c.c31 * u1 + c.c32 * u2) / d;
        let u4 = GAMMA
            * (z * (y0 + c.a41 * u1 + c.a42 * u2 + c.a43 * u3)
                + c.c41 * u1
                + c.c42 * u2
                + c.c43 * u3)
            / d;
        let u = [u1, u2, u3, u4];
        let y1 = y0 + dot(c.m, u);
        let c3 = dot(c.d, u);
        assert!(y1.abs() < 1e-8, "{y1}");
        for s in [0.1, 0.5, 0.9] {
            let ys = (1.0 - s) * y0 + s * (y1 + (1.0 - s) * c3);
            assert!((ys - (1.0 - s) * y0).abs() < 1e-7, "s = {s}: {ys}");
        }
    }

    /// The W-method order conditions (J arbitrary; Hairer & Wanner IV.7, "W-methods"): with
    /// A = (a_ij) and G = (g_ij) plus gamma on the diagonal, the Taylor expansion of
    /// k_i = h f(y + sum_j a_ij k_j) + h J sum_{j<=i} g_ij k_j separates the elementary
    /// differentials with J from those with f', so order 3 needs b 1 = 1; b A1 = 1/2, b G1 = 0;
    /// b (A1)^2 = 1/3, b A A1 = 1/6, b A G1 = b G A1 = b G G1 = 0 (with J = f' the last four
    /// combine to the Rosenbrock condition of [`order_conditions`]), and the embedded method the
    /// first three. This is what makes the lagged Jacobian and the omitted f_t harmless. The
    /// screened ROS3Pw and ROS3PRw (Rosenbrock order 3) fail it at order 3, the ROS34PRw
    /// coefficients found at order 2 (docs/integrator.md, session 9).
    #[test]
    fn w_order_conditions() {
        let a = [
            [0.0; 4],
            [A21, 0.0, 0.0, 0.0],
            [A31, A32, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        let g = [
            [GAMMA, 0.0, 0.0, 0.0],
            [G21, GAMMA, 0.0, 0.0],
            [G31, G32, GAMMA, 0.0],
            [G41, G42, G43, GAMMA],
        ];
        let a1: [f64; 4] = std::array::from_fn(|i| a[i].iter().sum());
        let g1: [f64; 4] = std::array::from_fn(|i| g[i].iter().sum());
        let mul = |m: &[[f64; 4]; 4], v: &[f64; 4]| -> [f64; 4] {
            std::array::from_fn(|i| (0..4).map(|j| m[i][j] * v[j]).sum())
        };
        let dot = |u: &[f64; 4], v: &[f64; 4]| (0..4).map(|i| u[i] * v[i]).sum::<f64>();
        let close = |x: f64, want: f64, what: &str| {
            assert!((x - want).abs() < 1e-12, "{what}: {x} instead of {want}");
        };
        for (v, name) in [([B1, B2, B3, B4], "b"), ([BH1, BH2, BH3, BH4], "bh")] {
            close(dot(&v, &[1.0; 4]), 1.0, name);
            close(dot(&v, &a1), 0.5, name);
            close(dot(&v, &g1), 0.0, name);
        }
        let b = [B1, B2, B3, B4];
        close(dot(&b, &a1.map(|x| x * x)), 1.0 / 3.0, "b (A1)^2");
        close(dot(&b, &mul(&a, &a1)), 1.0 / 6.0, "b A A1");
        close(dot(&b, &mul(&a, &g1)), 0.0, "b A G1");
        close(dot(&b, &mul(&g, &a1)), 0.0, "b G A1");
        close(dot(&b, &mul(&g, &g1)), 0.0, "b G G1");
        // the embedded method is of W-order 2 only (else it would be no error estimate)
        let bh = [BH1, BH2, BH3, BH4];
        assert!((dot(&bh, &mul(&a, &a1)) - 1.0 / 6.0).abs() > 1e-3);
    }

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
