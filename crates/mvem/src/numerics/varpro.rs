//! Separable nonlinear least squares by variable projection.
//!
//! Minimizes `|| W (y - Phi(alpha) c) ||^2` over nonlinear parameters `alpha` (optionally
//! bounded) and linear coefficients `c` (unconstrained), `W = diag(weights)`. For fixed
//! `alpha` the best `c` solves a linear least-squares problem, `c(alpha) = (W Phi)^+ W y`
//! (SVD, minimum norm if `W Phi` is rank deficient); substituting it leaves the projected
//! residual `rho(alpha) = W Phi c(alpha) - W y = -P_perp(alpha) W y`, which
//! [`lsq`](super::lsq) minimizes over `alpha` alone (Golub & Pereyra 1973). Fewer unknowns in
//! the nonlinear search and no start values needed for `c`: variable projection usually
//! converges from farther away and in fewer iterations than a joint fit.
//!
//! The Jacobian of `rho` is the exact Golub–Pereyra expression (not Kaufman's 1975
//! simplification that drops the second term): with `A = W Phi = U S V^T` (thin SVD, the
//! numerical rank kept) and `D_j = W dPhi/dalpha_j`,
//!
//! ```text
//! d rho / d alpha_j = P_perp D_j c  -  U S^-1 V^T (D_j^T rho),   P_perp = I - U U^T.
//! ```
//!
//! `dPhi/dalpha_j` is supplied by the user ([`Varpro::derivatives`]) or obtained by finite
//! differences of `Phi` with the scheme and step rules of [`lsq`](super::lsq)
//! ([`LsqOptions::finite_diff`], [`LsqOptions::fd_rel_step`]; forward differences use
//! `sqrt(eps)`, central `eps^(1/3)` relative steps, one-sided near a bound).
//!
//! A basis with non-finite entries at a trial `alpha` makes that a failed trial step of the
//! outer solver, like a non-finite residual.
//!
//! References:
//! - G. H. Golub, V. Pereyra, "The differentiation of pseudo-inverses and nonlinear least
//!   squares problems whose variables separate", SIAM J. Numer. Anal. 10(2), 413–432, 1973.
//! - L. Kaufman, "A variable projection method for solving separable nonlinear least squares
//!   problems", BIT 15, 49–57, 1975.
//! - G. H. Golub, V. Pereyra, "Separable nonlinear least squares: the variable projection
//!   method and its applications", Inverse Problems 19, R1–R26, 2003.
//!
//! Tuning uses, e.g.: EGR flow (`Pi_egropt | c_egr1..3`), turbine efficiency
//! (`BSR_opt, c_m2, c_m3 | eta_tmmax, c_m1`), compressor efficiency
//! (`W_copt, pi_copt, c_pi | eta_cmax, a1, a2, a3`), compressor flow
//! (`c_psi2, c_phi2 | six polynomial coefficients`): the closure returns one basis column per
//! linear parameter, evaluated at every operating point.

use super::lsq::{
    least_squares_with_jacobian, param_stats, Bounds, FiniteDiff, LsqError, LsqOptions, LsqResult,
    ParamStats,
};
use nalgebra::{DMatrix, DVector, SVD};
use std::cell::RefCell;

/// Errors of [`Varpro::fit`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VarproError {
    /// The outer (nonlinear) least-squares solve failed.
    #[error(transparent)]
    Lsq(#[from] LsqError),
    /// No observations.
    #[error("no observations")]
    NoData,
    /// An observation is not finite.
    #[error("observation y[{index}] = {value} is not finite")]
    NonFiniteData {
        /// Index.
        index: usize,
        /// Value.
        value: f64,
    },
    /// Weights of the wrong length, negative or not finite.
    #[error("weights: {0}")]
    Weights(String),
    /// The basis has the wrong shape.
    #[error(
        "basis Phi(alpha) is {got:?}, expected {expected:?} (observations x linear parameters)"
    )]
    BasisShape {
        /// Its shape.
        got: (usize, usize),
        /// Expected (columns: as at the start).
        expected: (usize, usize),
    },
    /// A basis derivative has the wrong shape.
    #[error("dPhi/dalpha_{index} is {got:?}, expected {expected:?}")]
    DerivativeShape {
        /// Nonlinear parameter index.
        index: usize,
        /// Its shape.
        got: (usize, usize),
        /// Expected.
        expected: (usize, usize),
    },
    /// The basis is not finite at the start.
    #[error("basis Phi(alpha0) has a non-finite entry at ({row}, {col})")]
    NonFiniteStart {
        /// Row (observation).
        row: usize,
        /// Column (linear parameter).
        col: usize,
    },
}

/// Outcome of [`Varpro::fit`].
#[derive(Debug, Clone, PartialEq)]
pub struct VarproResult {
    /// Nonlinear parameters.
    pub alpha: Vec<f64>,
    /// Linear coefficients.
    pub c: Vec<f64>,
    /// Unweighted residuals `y - Phi(alpha) c`.
    pub residuals: Vec<f64>,
    /// Weighted residual norm `||W (y - Phi c)||`.
    pub residual_norm: f64,
    /// Numerical rank of `W Phi(alpha)` at the solution.
    pub rank: usize,
    /// Outer solve over `alpha` (its Jacobian is that of the projected residual).
    pub lsq: LsqResult,
    /// Jacobian of the weighted residual `W (Phi c - y)` with respect to `(alpha, c)`.
    pub jacobian: DMatrix<f64>,
}

impl VarproResult {
    /// Linearized statistics of all parameters, ordered `(alpha, c)`.
    pub fn stats(&self) -> ParamStats {
        let w_res: Vec<f64> = self.lsq.residuals.clone();
        param_stats(&self.jacobian, &w_res)
    }
}

type BasisFn<'a> = Box<dyn FnMut(&[f64]) -> DMatrix<f64> + 'a>;
type DerivFn<'a> = Box<dyn FnMut(&[f64], usize) -> DMatrix<f64> + 'a>;

/// A separable least-squares problem `y ~ Phi(alpha) c` (builder; see the module docs).
///
/// ```
/// use mvem::numerics::varpro::Varpro;
/// use nalgebra::DMatrix;
/// // y = 2 exp(-0.5 t) + 1 exp(-3 t): alpha = (0.5, 3), c = (2, 1).
/// let t: Vec<f64> = (0..30).map(|i| 0.1 * i as f64).collect();
/// let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.5 * t).exp() + (-3.0 * t).exp()).collect();
/// let phi = |a: &[f64]| DMatrix::from_fn(t.len(), 2, |i, j| (-a[j] * t[i]).exp());
/// let fit = Varpro::new(&y, phi).fit(&[0.1, 1.0]).unwrap();
/// assert!((fit.alpha[0] - 0.5).abs() < 1e-6 && (fit.c[1] - 1.0).abs() < 1e-6);
/// ```
pub struct Varpro<'a> {
    y: Vec<f64>,
    phi: BasisFn<'a>,
    dphi: Option<DerivFn<'a>>,
    weights: Option<Vec<f64>>,
    bounds: Option<Bounds>,
    opts: LsqOptions,
}

impl<'a> Varpro<'a> {
    /// Observations `y` (length m) and the basis `Phi(alpha)` (m x k, one column per linear
    /// coefficient).
    pub fn new(y: &[f64], phi: impl FnMut(&[f64]) -> DMatrix<f64> + 'a) -> Self {
        Self {
            y: y.to_vec(),
            phi: Box::new(phi),
            dphi: None,
            weights: None,
            bounds: None,
            opts: LsqOptions::default(),
        }
    }

    /// Exact basis derivatives: `dphi(alpha, j) = dPhi/dalpha_j` (m x k).
    pub fn derivatives(mut self, dphi: impl FnMut(&[f64], usize) -> DMatrix<f64> + 'a) -> Self {
        self.dphi = Some(Box::new(dphi));
        self
    }

    /// Observation weights (>= 0, length m): the residual `i` is multiplied by `w_i`.
    pub fn weights(mut self, w: &[f64]) -> Self {
        self.weights = Some(w.to_vec());
        self
    }

    /// Box constraints on `alpha`.
    pub fn bounds(mut self, b: Bounds) -> Self {
        self.bounds = Some(b);
        self
    }

    /// Options of the outer solver over `alpha` (also the finite-difference scheme for
    /// `dPhi/dalpha`).
    pub fn options(mut self, opts: LsqOptions) -> Self {
        self.opts = opts;
        self
    }

    /// Fits from the nonlinear start `alpha0`.
    pub fn fit(self, alpha0: &[f64]) -> Result<VarproResult, VarproError> {
        let Varpro {
            y,
            phi,
            dphi,
            weights,
            bounds,
            opts,
        } = self;
        let m = y.len();
        if m == 0 {
            return Err(VarproError::NoData);
        }
        if let Some((index, &value)) = y.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(VarproError::NonFiniteData { index, value });
        }
        let w = match weights {
            None => DVector::from_element(m, 1.0),
            Some(w) => {
                if w.len() != m {
                    return Err(VarproError::Weights(format!(
                        "length {} but {m} observations",
                        w.len()
                    )));
                }
                if let Some((i, v)) = w
                    .iter()
                    .enumerate()
                    .find(|(_, v)| !(**v >= 0.0 && v.is_finite()))
                {
                    return Err(VarproError::Weights(format!(
                        "w[{i}] = {v} is not finite and >= 0"
                    )));
                }
                DVector::from_vec(w)
            }
        };
        let p = alpha0.len();
        let bounds = bounds.unwrap_or_else(|| Bounds::none(p));
        let state = RefCell::new(State {
            phi,
            dphi,
            wy: w.component_mul(&DVector::from_vec(y.clone())),
            w: w.clone(),
            m,
            k: 0,
            cache: None,
            error: None,
            lo: bounds.lo.clone(),
            hi: bounds.hi.clone(),
            fd: opts.finite_diff,
            rel_step: opts.fd_rel_step,
        });
        // Start: shape and finiteness of the basis.
        {
            let mut st = state.borrow_mut();
            let a0 = (st.phi)(alpha0);
            if a0.nrows() != m || a0.ncols() == 0 {
                return Err(VarproError::BasisShape {
                    got: a0.shape(),
                    expected: (m, a0.ncols().max(1)),
                });
            }
            st.k = a0.ncols();
            for j in 0..a0.ncols() {
                for i in 0..m {
                    if !a0[(i, j)].is_finite() {
                        return Err(VarproError::NonFiniteStart { row: i, col: j });
                    }
                }
            }
        }
        let residual = |a: &[f64]| -> Vec<f64> {
            let mut st = state.borrow_mut();
            match st.projection(a) {
                Some(pr) => pr.rho.iter().copied().collect(),
                None => vec![f64::NAN; st.m],
            }
        };
        let jacobian = |a: &[f64]| -> DMatrix<f64> {
            let mut st = state.borrow_mut();
            st.jacobian(a)
                .unwrap_or_else(|| DMatrix::from_element(st.m, a.len(), f64::NAN))
        };
        let lsq = least_squares_with_jacobian(residual, jacobian, alpha0, &bounds, &opts);
        let mut st = state.into_inner();
        if let Some(e) = st.error.take() {
            return Err(e);
        }
        let lsq = lsq?;
        let pr = st
            .projection(&lsq.theta)
            .ok_or(VarproError::NonFiniteStart { row: 0, col: 0 })?;
        let (c, rank, rho) = (pr.c.clone(), pr.rank, pr.rho.clone());
        // Full Jacobian of W (Phi c - y) in (alpha, c).
        let k = st.k;
        let mut jac = DMatrix::zeros(m, p + k);
        let derivs = st.derivatives(&lsq.theta).unwrap_or_default();
        for (j, dj) in derivs.iter().enumerate() {
            jac.set_column(j, &(dj * &c));
        }
        let a_w = st
            .weighted_basis(&lsq.theta)
            .unwrap_or_else(|| DMatrix::zeros(m, k));
        jac.view_mut((0, p), (m, k)).copy_from(&a_w);
        let phi = (st.phi)(&lsq.theta);
        let residuals: Vec<f64> = (0..m).map(|i| y[i] - (phi.row(i) * &c)[0]).collect();
        Ok(VarproResult {
            alpha: lsq.theta.clone(),
            c: c.iter().copied().collect(),
            residuals,
            residual_norm: rho.norm(),
            rank,
            lsq,
            jacobian: jac,
        })
    }
}

/// Linear solve at one `alpha`.
#[derive(Clone)]
struct Projection {
    alpha: Vec<f64>,
    /// Left singular vectors of the numerical range (m x r).
    u: DMatrix<f64>,
    /// Kept singular values (r).
    s: DVector<f64>,
    /// Right singular vectors (k x r).
    v: DMatrix<f64>,
    c: DVector<f64>,
    /// W Phi c - W y.
    rho: DVector<f64>,
    rank: usize,
}

struct State<'a> {
    phi: BasisFn<'a>,
    dphi: Option<DerivFn<'a>>,
    w: DVector<f64>,
    wy: DVector<f64>,
    m: usize,
    k: usize,
    cache: Option<Projection>,
    error: Option<VarproError>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    fd: FiniteDiff,
    rel_step: Option<f64>,
}

impl State<'_> {
    /// `W Phi(alpha)`, None if not finite or of the wrong shape (the error is recorded).
    fn weighted_basis(&mut self, a: &[f64]) -> Option<DMatrix<f64>> {
        let mut ph = (self.phi)(a);
        if ph.shape() != (self.m, self.k) {
            self.error.get_or_insert(VarproError::BasisShape {
                got: ph.shape(),
                expected: (self.m, self.k),
            });
            return None;
        }
        for i in 0..self.m {
            ph.row_mut(i).scale_mut(self.w[i]);
        }
        ph.iter().all(|v| v.is_finite()).then_some(ph)
    }

    fn projection(&mut self, a: &[f64]) -> Option<&Projection> {
        if self.cache.as_ref().is_none_or(|c| c.alpha != a) {
            self.cache = None;
            let aw = self.weighted_basis(a)?;
            let svd = SVD::try_new(
                aw.clone(),
                true,
                true,
                f64::EPSILON * 5.0,
                super::SVD_MAX_ITER,
            )?;
            let u = svd.u?;
            let v_t = svd.v_t?;
            let s = svd.singular_values;
            let tol = f64::EPSILON * self.m.max(self.k) as f64 * s.get(0).copied().unwrap_or(0.0);
            let r = s.iter().filter(|&&x| x > tol).count();
            let u = u.columns(0, r).into_owned();
            let v = v_t.rows(0, r).transpose();
            let s = s.rows(0, r).into_owned();
            let utb = u.tr_mul(&self.wy);
            let c = &v * utb.component_div(&s);
            let rho = &aw * &c - &self.wy;
            self.cache = Some(Projection {
                alpha: a.to_vec(),
                u,
                s,
                v,
                c,
                rho,
                rank: r,
            });
        }
        self.cache.as_ref()
    }

    /// `W dPhi/dalpha_j` for every j (user or finite differences), None if not finite.
    fn derivatives(&mut self, a: &[f64]) -> Option<Vec<DMatrix<f64>>> {
        let p = a.len();
        let mut out = Vec::with_capacity(p);
        if let Some(dphi) = self.dphi.as_mut() {
            for j in 0..p {
                let mut d = dphi(a, j);
                if d.shape() != (self.m, self.k) {
                    self.error.get_or_insert(VarproError::DerivativeShape {
                        index: j,
                        got: d.shape(),
                        expected: (self.m, self.k),
                    });
                    return None;
                }
                for i in 0..self.m {
                    d.row_mut(i).scale_mut(self.w[i]);
                }
                out.push(d);
            }
        } else {
            let base = self.weighted_basis(a)?;
            let rel = self.rel_step.unwrap_or(match self.fd {
                FiniteDiff::Forward => f64::EPSILON.sqrt(),
                FiniteDiff::Central => f64::EPSILON.cbrt(),
            });
            for j in 0..p {
                let h = rel * if a[j] != 0.0 { a[j].abs() } else { 1.0 };
                let at = |s: f64| {
                    let mut x = a.to_vec();
                    x[j] += s;
                    x
                };
                let (lo, hi) = (self.lo[j], self.hi[j]);
                let fits = |t: f64| a[j] + t >= lo && a[j] + t <= hi;
                let exact = |t: f64| (a[j] + t) - a[j];
                let mut d = None;
                if self.fd == FiniteDiff::Central && fits(h) && fits(-h) {
                    let (tp, tm) = (exact(h), exact(-h));
                    if let (Some(bp), Some(bm)) =
                        (self.weighted_basis(&at(tp)), self.weighted_basis(&at(tm)))
                    {
                        d = Some((bp - bm) / (tp - tm));
                    }
                }
                if d.is_none() {
                    for t in [h, -h, 0.5 * (hi - a[j]), -0.5 * (a[j] - lo)] {
                        if t != 0.0 && t.is_finite() && t.abs() <= h && fits(t) {
                            let t = exact(t);
                            if let Some(b1) = self.weighted_basis(&at(t)) {
                                d = Some((b1 - &base) / t);
                                break;
                            }
                        }
                    }
                }
                out.push(d?);
            }
        }
        out.iter()
            .all(|d| d.iter().all(|v| v.is_finite()))
            .then_some(out)
    }

    /// Golub–Pereyra Jacobian of the projected residual.
    fn jacobian(&mut self, a: &[f64]) -> Option<DMatrix<f64>> {
        let pr = self.projection(a)?.clone();
        let derivs = self.derivatives(a)?;
        let mut jm = DMatrix::zeros(self.m, a.len());
        for (j, dj) in derivs.iter().enumerate() {
            let dc = dj * &pr.c;
            let perp = &dc - &pr.u * pr.u.tr_mul(&dc);
            let second = &pr.u * (pr.v.tr_mul(&dj.tr_mul(&pr.rho))).component_div(&pr.s);
            jm.set_column(j, &(perp - second));
        }
        Some(jm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_exp(t: &[f64], a: &[f64]) -> DMatrix<f64> {
        DMatrix::from_fn(t.len(), 2, |i, j| (-a[j] * t[i]).exp())
    }

    #[test]
    fn two_exponentials_exact_data() {
        let t: Vec<f64> = (0..40).map(|i| 0.1 * i as f64).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|t| 3.0 * (-0.4 * t).exp() - 1.5 * (-2.5 * t).exp())
            .collect();
        let fit = Varpro::new(&y, |a: &[f64]| two_exp(&t, a))
            .fit(&[1.0, 5.0])
            .unwrap();
        for (a, b) in fit.alpha.iter().zip([0.4, 2.5]) {
            assert!((a - b).abs() < 1e-8, "{:?}", fit.alpha);
        }
        for (a, b) in fit.c.iter().zip([3.0, -1.5]) {
            assert!((a - b).abs() < 1e-8, "{:?}", fit.c);
        }
        assert!(fit.residual_norm < 1e-10);
        assert_eq!(fit.rank, 2);
    }

    /// Noisy data: the variable-projection solution must be a stationary point of the full
    /// problem in (alpha, c) and match a joint fit with `lsq`.
    #[test]
    fn noisy_two_exponentials_match_joint_fit() {
        let t: Vec<f64> = (0..60).map(|i| 0.08 * i as f64).collect();
        // Deterministic pseudo-noise.
        let noise = |i: usize| 0.01 * ((i as f64 * 12.9898).sin() * 43758.5453).fract();
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(i, t)| 2.0 * (-0.7 * t).exp() + 0.8 * (-4.0 * t).exp() + noise(i))
            .collect();
        let w: Vec<f64> = (0..t.len()).map(|i| 1.0 + 0.01 * i as f64).collect();
        let dphi = |a: &[f64], j: usize| {
            DMatrix::from_fn(t.len(), 2, |i, col| {
                if col == j {
                    -t[i] * (-a[j] * t[i]).exp()
                } else {
                    0.0
                }
            })
        };
        let opts = LsqOptions {
            ftol: 1e-14,
            xtol: 1e-14,
            gtol: 1e-14,
            ..LsqOptions::default()
        };
        let vp = Varpro::new(&y, |a: &[f64]| two_exp(&t, a))
            .derivatives(dphi)
            .weights(&w)
            .options(opts.clone())
            .fit(&[0.3, 2.0])
            .unwrap();
        // FD basis derivatives give the same answer.
        let vp_fd = Varpro::new(&y, |a: &[f64]| two_exp(&t, a))
            .weights(&w)
            .options(LsqOptions {
                finite_diff: FiniteDiff::Central,
                ..opts.clone()
            })
            .fit(&[0.3, 2.0])
            .unwrap();
        let joint = crate::numerics::lsq::least_squares(
            |p: &[f64]| {
                t.iter()
                    .enumerate()
                    .map(|(i, t)| {
                        w[i] * (p[2] * (-p[0] * t).exp() + p[3] * (-p[1] * t).exp() - y[i])
                    })
                    .collect()
            },
            &[0.3, 2.0, 1.0, 1.0],
            &Bounds::none(4),
            &LsqOptions {
                finite_diff: FiniteDiff::Central,
                ..opts
            },
        )
        .unwrap();
        let all = [vp.alpha.clone(), vp.c.clone()].concat();
        let all_fd = [vp_fd.alpha.clone(), vp_fd.c.clone()].concat();
        for i in 0..4 {
            assert!(
                (all[i] - joint.theta[i]).abs() < 1e-7 * joint.theta[i].abs(),
                "{all:?} vs {:?}",
                joint.theta
            );
            assert!(
                (all_fd[i] - all[i]).abs() < 1e-7 * all[i].abs(),
                "{all_fd:?} vs {all:?}"
            );
        }
        // Full gradient J^T r vanishes at the solution (scaled by column and residual norms).
        let g = vp
            .jacobian
            .tr_mul(&DVector::from_column_slice(&vp.lsq.residuals));
        for j in 0..4 {
            let cos = g[j].abs() / (vp.jacobian.column(j).norm() * vp.residual_norm);
            assert!(cos < 1e-6, "column {j}: {cos}");
        }
        // Residuals are unweighted y - Phi c.
        let r0 = y[0] - (vp.c[0] + vp.c[1]);
        assert!((vp.residuals[0] - r0).abs() < 1e-12);
        let st = vp.stats();
        assert_eq!(st.rank, 4);
        assert!(st.std_err.iter().all(|s| s.is_finite() && *s > 0.0));
    }

    #[test]
    fn bounded_alpha() {
        // Single exponential with the rate bounded below the true one: alpha at the bound.
        let t: Vec<f64> = (0..20).map(|i| 0.2 * i as f64).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * (-1.0 * t).exp()).collect();
        let fit = Varpro::new(&y, |a: &[f64]| {
            DMatrix::from_fn(t.len(), 1, |i, _| (-a[0] * t[i]).exp())
        })
        .bounds(Bounds::new(vec![0.0], vec![0.6]))
        .fit(&[0.1])
        .unwrap();
        assert!((fit.alpha[0] - 0.6).abs() < 1e-7, "{:?}", fit.alpha);
        assert_eq!(fit.lsq.active, vec![1]);
    }

    #[test]
    fn errors() {
        let y = [1.0, 2.0, 3.0];
        let phi = |_: &[f64]| DMatrix::from_element(3, 1, 1.0);
        assert!(matches!(
            Varpro::new(&[], phi).fit(&[1.0]),
            Err(VarproError::NoData)
        ));
        assert!(matches!(
            Varpro::new(&[1.0, f64::NAN, 1.0], phi).fit(&[1.0]),
            Err(VarproError::NonFiniteData { index: 1, .. })
        ));
        assert!(matches!(
            Varpro::new(&y, phi).weights(&[1.0]).fit(&[1.0]),
            Err(VarproError::Weights(_))
        ));
        assert!(matches!(
            Varpro::new(&y, phi).weights(&[1.0, -1.0, 1.0]).fit(&[1.0]),
            Err(VarproError::Weights(_))
        ));
        let wrong = |_: &[f64]| DMatrix::from_element(2, 1, 1.0);
        assert!(matches!(
            Varpro::new(&y, wrong).fit(&[1.0]),
            Err(VarproError::BasisShape { .. })
        ));
        let nan = |_: &[f64]| DMatrix::from_element(3, 1, f64::NAN);
        assert!(matches!(
            Varpro::new(&y, nan).fit(&[1.0]),
            Err(VarproError::NonFiniteStart { .. })
        ));
        assert!(matches!(
            Varpro::new(&y, phi)
                .bounds(Bounds::new(vec![2.0], vec![3.0]))
                .fit(&[1.0]),
            Err(VarproError::Lsq(LsqError::InfeasibleStart { .. }))
        ));
    }
}
