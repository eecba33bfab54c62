//! Bounded nonlinear least squares: minimize `0.5 * ||r(theta)||^2` subject to
//! `lo <= theta <= hi`.
//!
//! # Method
//!
//! Trust Region Reflective (TRF) of Branch, Coleman & Li (1999), the algorithm behind
//! `scipy.optimize.least_squares(method='trf')`, which this module follows step by step:
//!
//! - **Coleman–Li scaling** (Coleman & Li 1996): with the gradient `g = J^T r`, each variable
//!   whose descent direction points to a finite bound gets the scaling `v_j` = distance to that
//!   bound, the others `v_j = 1`. The trust-region subproblem is solved in the variables
//!   `theta = theta_k + D p_h`, `D = diag(v^(1/2) * x_scale)`, with the extra diagonal term
//!   `diag(g * dv * x_scale)` (`dv_j = +-1` where `v_j` is a distance) that makes its solution
//!   approach the Karush–Kuhn–Tucker point of the bounded problem, so steps shrink smoothly near
//!   an active bound instead of zig-zagging against it.
//!   One deviation from scipy: the distance, measured in `x_scale` units, is capped at 1 (with
//!   `dv_j = 0` where capped), so a bound more than one scaled unit away leaves the metric as
//!   without bounds. Uncapped, far bounds distort the metric; e.g. NIST MGH10 from start 1 with
//!   the box `[-10 |b0|, 10 |b0|]` then stalls at `b1 -> 0` while the unbounded solver
//!   converges. Near the bounds, where the convergence theory needs it, the scaling is
//!   unchanged (cf. the family of affine scalings analysed by Heinkenschloss, Ulbrich & Ulbrich
//!   1999).
//! - **Exact trust-region subproblem** of the augmented linear least-squares problem by the
//!   SVD and Moré's (1978) safeguarded Newton iteration on the Levenberg–Marquardt parameter
//!   (the MINPACK `lmpar` idea; the parameter is carried over between steps). Without bounds
//!   this is exactly Levenberg–Marquardt with Moré's scaling.
//! - **Step selection**: if the trust-region step leaves the box it is cut at the first bound;
//!   the best (by the quadratic model) of (a) the cut step pulled back to stay strictly
//!   interior, (b) the step reflected at the bound, (c) the scaled steepest-descent (Cauchy)
//!   step is taken. Iterates stay strictly inside the box.
//! - **Radius update** as MINPACK/scipy: ratio of actual to predicted reduction below 0.25
//!   shrinks the radius to a quarter of the step, above 0.75 with the step at the boundary
//!   doubles it.
//!
//! A trial point whose residuals are not all finite is a failed step: the radius shrinks to a
//! quarter of the step and the step is recomputed (no panic, no error). Only the starting point
//! must give finite residuals.
//!
//! # Scaling (`x_scale`)
//!
//! [`XScale::Jac`] (default) scales each variable by the inverse norm of its Jacobian column,
//! updated as the running maximum of the column norms (Moré 1978, MINPACK `mode = 1`), which
//! makes the method invariant to the units of the parameters. [`XScale::Fixed`] uses the given
//! typical magnitudes.
//!
//! # Termination
//!
//! - `ftol`: an accepted step with `dF < ftol * F` and ratio > 0.25 (F the cost).
//! - `xtol`: `||dtheta / s|| < xtol * (xtol + ||theta / s||)` with `s` the current `x_scale`
//!   (for `Jac`: the inverse column norms; the MINPACK test on the scaled step).
//! - `gtol`: the scale-free first-order optimality measure
//!   `max_j |g_j| / (||J_j|| ||r||)` (the cosine between the residual and Jacobian column j,
//!   MINPACK's `gtol` test) falls below `gtol`. For a variable whose descent direction points to
//!   a finite bound at distance `v_j` the term is multiplied by `min(1, v_j ||J_j|| / ||r||)`,
//!   the relative change of the residual norm that moving to that bound can make, so the measure
//!   vanishes at a KKT point with active bounds.
//! - `rel_offset_tol` (off by default, 0): the Bates-Watts relative offset
//!   `R = (||Q_1^T r|| / sqrt(p)) / (||Q_2^T r|| / sqrt(m - p))` ([`relative_offset`]; `Q_1` the
//!   column space of the Jacobian, `Q_2` its complement, `p` its numerical rank) falls below
//!   the tolerance, tested under a finite-difference (or user) Jacobian. A statistical rule:
//!   the full Gauss-Newton step `delta` from the point satisfies `||J delta|| = ||Q_1^T r||`, so
//!   every parameter is within `R sqrt(p)` of its linearized standard error from the
//!   linearized optimum (`|delta_k| <= ||J delta|| sqrt((J^T J)^-1_kk)`), however flat the
//!   cost is in some direction (Bates & Watts 1981; 1988, sec. 2.2.3). A search that walks a
//!   flat valley (steps that lower the cost by more than `ftol` but by far less than the
//!   noise) stops there.
//! - `max_evaluations`: every call of the residual function counts, including those of the
//!   finite-difference Jacobian. The limit is checked before each trial step; a Jacobian in
//!   progress is completed, so the count can exceed the limit by up to `2 n`.
//!
//! # Jacobian
//!
//! User-supplied ([`least_squares_with_jacobian`]) or by finite differences ([`FiniteDiff`]):
//! forward differences with step `h_j = sqrt(eps) * max(|theta_j|, s_j)` (about `1.5e-8`
//! relative; `s_j` the fixed `x_scale`, or 1 when `theta_j = 0` with `Jac` scaling) or central
//! differences with `h_j = eps^(1/3) * max(|theta_j|, s_j)` (about `6e-6` relative), which
//! minimizes truncation plus rounding error for smooth residuals (Nocedal & Wright 2006,
//! sec. 8.1). For noisy residuals (e.g. simulations with an adaptive integrator) set
//! [`LsqOptions::fd_rel_step`] to about the square root (forward) or cube root (central) of the
//! relative noise. A step that would leave the box is taken to the other side (forward) or
//! replaced by the one-sided second-order formula (central); a step whose residuals are not
//! finite is retried on the other side.
//!
//! # Broyden updates
//!
//! With [`LsqOptions::broyden_updates`] = k > 0 and finite differences, an accepted step whose
//! actual reduction agreed with the prediction (ratio >= 0.25) updates the Jacobian by Broyden's
//! (1965) rank-1 secant formula `J += (r_new - r - J s) s^T / (s^T s)` (one evaluation, the trial
//! step's) instead of recomputing it (n evaluations), at most k times in a row; the secant version
//! of Levenberg–Marquardt (Madsen, Nielsen & Tingleff 2004, sec. 3.4; the updates MINPACK's
//! `hybrd` uses between Jacobians). A rejected or non-finite trial step, a step with ratio < 0.25,
//! and any convergence test (`ftol`, `xtol`, `gtol`) met under an updated Jacobian recompute it by
//! finite differences at the current point instead of shrinking the radius or stopping: the
//! solver stops only on tests met with a finite-difference Jacobian, and the reported Jacobian
//! (parameter statistics) is always a finite-difference one at `theta` (recomputed after the
//! evaluation limit if needed, so the count can exceed the limit by `n`).
//!
//! # Parameter statistics
//!
//! [`LsqResult::stats`] (or [`param_stats`]) gives the linearized covariance
//! `sigma^2 (J^T J)^-1`, `sigma^2 = ||r||^2 / (m - n)`, standard errors, correlations and the
//! singular values of the column-normalized Jacobian (its condition number measures how well
//! the parameters are identified). Directions with singular values below
//! `eps * max(m, n) * s_max` are unidentifiable: parameters in them get an infinite standard
//! error.
//!
//! # Verification
//!
//! `tests/nist.rs` solves all 27 NIST StRD nonlinear regression problems from both of NIST's
//! start points and checks the certified values (at least 6 significant digits with an exact or
//! central-difference Jacobian, 4 with forward differences) and standard deviations; the
//! per-problem digits are in `docs/nist.md`.
//!
//! # References
//!
//! - M. A. Branch, T. F. Coleman, Y. Li, "A subspace, interior, and conjugate gradient method
//!   for large-scale bound-constrained minimization problems", SIAM J. Sci. Comput. 21(1),
//!   1–23, 1999.
//! - T. F. Coleman, Y. Li, "An interior trust region approach for nonlinear minimization
//!   subject to bounds", SIAM J. Optim. 6(2), 418–445, 1996.
//! - M. Heinkenschloss, M. Ulbrich, S. Ulbrich, "Superlinear and quadratic convergence of
//!   affine-scaling interior-point Newton methods for problems with simple bounds without
//!   strict complementarity assumption", Math. Program. 86, 615–635, 1999.
//! - D. M. Bates, D. G. Watts, "A relative offset orthogonality convergence criterion for
//!   nonlinear least squares", Technometrics 23(2), 179–183, 1981; "Nonlinear regression
//!   analysis and its applications", Wiley, 1988.
//! - C. G. Broyden, "A class of methods for solving nonlinear simultaneous equations", Math.
//!   Comp. 19, 577–593, 1965.
//! - K. Madsen, H. B. Nielsen, O. Tingleff, "Methods for non-linear least squares problems",
//!   2nd ed., IMM, Technical University of Denmark, 2004.
//! - J. J. Moré, "The Levenberg–Marquardt algorithm: implementation and theory", Numerical
//!   Analysis, Lecture Notes in Mathematics 630, 105–116, Springer, 1978.
//! - J. Nocedal, S. J. Wright, "Numerical Optimization", 2nd ed., Springer, 2006.
//! - SciPy `scipy/optimize/_lsq/trf.py` and `common.py` (BSD-3), whose structure is followed.

use nalgebra::{DMatrix, DVector, SVD};

/// Box constraints `lo <= theta <= hi` (infinite entries: no bound).
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bounds (`-inf`: none).
    pub lo: Vec<f64>,
    /// Upper bounds (`+inf`: none).
    pub hi: Vec<f64>,
}

impl Bounds {
    /// No bounds on `n` parameters.
    pub fn none(n: usize) -> Self {
        Self {
            lo: vec![f64::NEG_INFINITY; n],
            hi: vec![f64::INFINITY; n],
        }
    }

    /// Bounds from lower and upper vectors.
    pub fn new(lo: Vec<f64>, hi: Vec<f64>) -> Self {
        Self { lo, hi }
    }

    /// Whether no entry is finite.
    pub fn is_unbounded(&self) -> bool {
        self.lo.iter().chain(&self.hi).all(|b| b.is_infinite())
    }
}

/// Variable scaling of the trust region (see the module documentation).
#[derive(Debug, Clone, PartialEq, Default)]
pub enum XScale {
    /// Inverse Jacobian column norms, running maximum (MINPACK `mode = 1`).
    #[default]
    Jac,
    /// Typical magnitude of each parameter (same unit as the parameter, > 0).
    Fixed(Vec<f64>),
}

/// Finite-difference scheme for the Jacobian when none is supplied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FiniteDiff {
    /// Forward differences: `n` evaluations, about 8 correct digits.
    #[default]
    Forward,
    /// Central differences: `2 n` evaluations, about 10 correct digits.
    Central,
}

/// Options of [`least_squares`]. Defaults: `ftol = xtol = gtol = 1e-8`,
/// `max_evaluations = 200 (n + 1)`, Jacobian scaling, forward differences.
#[derive(Debug, Clone, PartialEq)]
pub struct LsqOptions {
    /// Relative cost-reduction tolerance (>= 0).
    pub ftol: f64,
    /// Relative scaled-step tolerance (>= 0).
    pub xtol: f64,
    /// First-order optimality tolerance (dimensionless, >= 0).
    pub gtol: f64,
    /// Limit on residual evaluations, finite-difference ones included (`None`: `200 (n + 1)`).
    pub max_evaluations: Option<usize>,
    /// Variable scaling.
    pub x_scale: XScale,
    /// Finite-difference scheme (ignored with a user Jacobian).
    pub finite_diff: FiniteDiff,
    /// Relative finite-difference step (`None`: `sqrt(eps)` forward, `eps^(1/3)` central).
    pub fd_rel_step: Option<f64>,
    /// Initial trust-region radius as a multiple of `||theta0 / s||` (1 if that is 0); > 0.
    pub initial_radius_factor: f64,
    /// Most consecutive Broyden rank-1 updates of a finite-difference Jacobian before it is
    /// recomputed (0: a new Jacobian after every accepted step). See the module documentation
    /// ("Broyden updates"); ignored with a user Jacobian.
    pub broyden_updates: usize,
    /// Tolerance of the Bates-Watts relative offset ([`relative_offset`], module documentation
    /// "Termination"; >= 0, 0: the test is off).
    pub rel_offset_tol: f64,
}

impl Default for LsqOptions {
    fn default() -> Self {
        Self {
            ftol: 1e-8,
            xtol: 1e-8,
            gtol: 1e-8,
            max_evaluations: None,
            x_scale: XScale::Jac,
            finite_diff: FiniteDiff::Forward,
            fd_rel_step: None,
            initial_radius_factor: 1.0,
            broyden_updates: 0,
            rel_offset_tol: 0.0,
        }
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// First-order optimality measure below `gtol`.
    Gtol,
    /// Relative cost reduction below `ftol`.
    Ftol,
    /// Relative scaled step below `xtol`.
    Xtol,
    /// Both `ftol` and `xtol` satisfied.
    FtolAndXtol,
    /// Bates-Watts relative offset below `rel_offset_tol`.
    RelativeOffset,
    /// Residual-evaluation limit reached (not converged).
    MaxEvaluations,
}

impl Termination {
    /// Short name of the test ("gtol", "ftol", "xtol", "ftol+xtol", "relative offset",
    /// "evaluation limit").
    pub fn name(self) -> &'static str {
        match self {
            Termination::Gtol => "gtol",
            Termination::Ftol => "ftol",
            Termination::Xtol => "xtol",
            Termination::FtolAndXtol => "ftol+xtol",
            Termination::RelativeOffset => "relative offset",
            Termination::MaxEvaluations => "evaluation limit",
        }
    }

    /// Whether a convergence test (not the evaluation limit) stopped the solver.
    pub fn converged(self) -> bool {
        !matches!(self, Termination::MaxEvaluations)
    }
}

/// Errors of [`least_squares`]; failed trial steps are not errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LsqError {
    /// No parameters.
    #[error("no parameters to fit")]
    NoParameters,
    /// Bounds or x_scale of the wrong length.
    #[error("{what} has length {got}, expected {expected} (number of parameters)")]
    Length {
        /// Which vector.
        what: &'static str,
        /// Its length.
        got: usize,
        /// Number of parameters.
        expected: usize,
    },
    /// `lo[index] >= hi[index]` or a bound is NaN.
    #[error("bounds of parameter {index}: lo = {lo} must be < hi = {hi}")]
    InvalidBounds {
        /// Parameter index.
        index: usize,
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// The start is not finite or outside the bounds.
    #[error("start theta0[{index}] = {value} is not finite or outside [{lo}, {hi}]")]
    InfeasibleStart {
        /// Parameter index.
        index: usize,
        /// Value.
        value: f64,
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// An option is out of range.
    #[error("option {name} = {} is out of range ({rule})", crate::numerics::Num(*value))]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// Value.
        value: f64,
        /// Admissible range.
        rule: &'static str,
    },
    /// The residual function returned no residuals.
    #[error("the residual function returned an empty vector")]
    NoResiduals,
    /// The residual vector changed length between evaluations.
    #[error("the residual function returned {got} residuals, earlier {expected}")]
    ResidualLength {
        /// Length now.
        got: usize,
        /// Length at the start.
        expected: usize,
    },
    /// A residual is not finite at the start.
    #[error("residual {index} is {value} at the start point")]
    NonFiniteStart {
        /// Residual index.
        index: usize,
        /// Value.
        value: f64,
    },
    /// The Jacobian has the wrong shape.
    #[error("the Jacobian is {got:?}, expected {expected:?} (residuals x parameters)")]
    JacobianShape {
        /// Its shape.
        got: (usize, usize),
        /// Expected shape.
        expected: (usize, usize),
    },
    /// The Jacobian could not be evaluated with finite entries at an accepted point.
    #[error("Jacobian column {column} (row {row}) is not finite at theta = {theta:?}")]
    NonFiniteJacobian {
        /// Parameter (column).
        column: usize,
        /// Residual (row).
        row: usize,
        /// The point.
        theta: Vec<f64>,
    },
    /// The SVD did not converge (only for non-finite or pathological matrices).
    #[error("singular value decomposition failed to converge")]
    Svd,
    /// The caller cancelled the search ([`super::cancel`]) after `evaluations` residual
    /// evaluations.
    #[error("cancelled after {evaluations} residual evaluations")]
    Cancelled {
        /// Residual evaluations before the cancellation.
        evaluations: usize,
    },
}

/// Outcome of [`least_squares`].
#[derive(Debug, Clone, PartialEq)]
pub struct LsqResult {
    /// Parameters at the solution.
    pub theta: Vec<f64>,
    /// Cost `0.5 * ||r||^2` at the solution.
    pub cost: f64,
    /// Residuals at the solution.
    pub residuals: Vec<f64>,
    /// Jacobian `dr/dtheta` at the solution (m x n).
    pub jacobian: DMatrix<f64>,
    /// First-order optimality measure at the solution (see the module documentation).
    pub optimality: f64,
    /// Per parameter: -1 at the lower bound, +1 at the upper, 0 free ("at": within
    /// `max(xtol, 1e-10) * max(1, |bound|)`).
    pub active: Vec<i8>,
    /// Residual-function calls, finite-difference ones included.
    pub n_eval: usize,
    /// Jacobian evaluations (user or finite-difference).
    pub n_jac: usize,
    /// Outer iterations (Jacobian updates).
    pub n_iter: usize,
    /// Why the solver stopped.
    pub termination: Termination,
    /// Bates-Watts relative offset at the solution ([`relative_offset`]).
    pub rel_offset: f64,
}

impl LsqResult {
    /// Linearized parameter statistics at the solution (see [`param_stats`]).
    pub fn stats(&self) -> ParamStats {
        param_stats(&self.jacobian, &self.residuals)
    }
}

/// Linearized statistics of a least-squares fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamStats {
    /// Degrees of freedom `m - n` (0 if `m <= n`).
    pub dof: usize,
    /// Residual variance estimate `||r||^2 / (m - n)` (NaN if `m <= n`).
    pub sigma2: f64,
    /// Covariance `sigma2 (J^T J)^-1` (pseudo-inverse over the identifiable subspace).
    pub covariance: DMatrix<f64>,
    /// Standard errors (infinite for unidentifiable parameters).
    pub std_err: Vec<f64>,
    /// Correlation matrix (NaN rows/columns for unidentifiable parameters).
    pub correlation: DMatrix<f64>,
    /// Singular values of the column-normalized Jacobian, descending (dimensionless).
    pub singular_values: Vec<f64>,
    /// Right singular vectors (columns) of the column-normalized Jacobian, same order.
    pub directions: DMatrix<f64>,
    /// Numerical rank.
    pub rank: usize,
}

impl ParamStats {
    /// Condition number of the column-normalized Jacobian (infinite if rank deficient).
    pub fn condition(&self) -> f64 {
        match (self.singular_values.first(), self.singular_values.last()) {
            (Some(&a), Some(&b)) if b > 0.0 && self.rank == self.singular_values.len() => a / b,
            _ => f64::INFINITY,
        }
    }
}

/// Bates-Watts relative offset of residuals `r` (m) with Jacobian `J` (m x n) at a point:
/// `(||Q_1^T r|| / sqrt(p)) / (||Q_2^T r|| / sqrt(m - p))`, `Q_1` the left singular vectors of
/// the column-normalized Jacobian with singular values above `eps max(m, n) s_max` (rank p, as
/// in [`param_stats`]). 0 at a (linearized) optimum, `r` orthogonal to the Jacobian's columns;
/// NaN when `m <= p`; infinite when the residuals lie in the column space.
pub fn relative_offset(jacobian: &DMatrix<f64>, residuals: &[f64]) -> f64 {
    match split_by_span(jacobian, residuals, false) {
        Some(s) => (s.in_span / s.rank as f64).sqrt() / s.variance.sqrt(),
        None => f64::NAN,
    }
}

/// The residuals `r` split by the column space of the Jacobian (see [`relative_offset`]).
struct SpanSplit {
    /// `||Q_1^T r||^2`: the decrease of `||r||^2` the Gauss-Newton model predicts.
    in_span: f64,
    /// `||Q_2^T r||^2 / (m - p)`: the residual variance.
    variance: f64,
    /// Numerical rank p.
    rank: usize,
    /// The rank-truncated Gauss-Newton step `-J^+ r` (when asked for).
    step: Option<DVector<f64>>,
}

/// [`SpanSplit`] of `residuals` by `jacobian`; `None` when `m <= p`, `p = 0` or the SVD fails.
fn split_by_span(jacobian: &DMatrix<f64>, residuals: &[f64], with_step: bool) -> Option<SpanSplit> {
    let (m, n) = jacobian.shape();
    if m == 0 || n == 0 || residuals.len() != m {
        return None;
    }
    let mut js = jacobian.clone();
    let mut norms = vec![0.0; n];
    for (j, mut c) in js.column_iter_mut().enumerate() {
        let cn = c.norm();
        if cn > 0.0 && cn.is_finite() {
            c.scale_mut(1.0 / cn);
            norms[j] = cn;
        } else {
            c.fill(0.0);
        }
    }
    let svd = SVD::try_new(js, true, with_step, f64::EPSILON * 5.0, super::SVD_MAX_ITER)?;
    let u = svd.u.as_ref().expect("u requested");
    let s = &svd.singular_values;
    let tol = f64::EPSILON * m.max(n) as f64 * s.iter().copied().fold(0.0, f64::max);
    let r = DVector::from_column_slice(residuals);
    let mut in_span = 0.0;
    let mut p = 0usize;
    let mut step = with_step.then(|| DVector::zeros(n));
    for (k, sk) in s.iter().enumerate() {
        if *sk > tol {
            let c = u.column(k).dot(&r);
            in_span += c * c;
            p += 1;
            if let (Some(d), Some(vt)) = (step.as_mut(), svd.v_t.as_ref()) {
                // in the column-normalized variables: -v_k (u_k^T r) / s_k
                *d -= vt.row(k).transpose() * (c / sk);
            }
        }
    }
    if m <= p || p == 0 {
        return None;
    }
    if let Some(d) = step.as_mut() {
        for (dj, nj) in d.iter_mut().zip(&norms) {
            *dj = if *nj > 0.0 { *dj / nj } else { 0.0 };
        }
    }
    let rest = (r.norm_squared() - in_span).max(0.0);
    Some(SpanSplit {
        in_span,
        variance: rest / (m - p) as f64,
        rank: p,
        step,
    })
}

/// The cost measured along the Gauss-Newton step from a point ([`gauss_newton_line`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GaussNewtonLine {
    /// Decrease of `||r||^2` the Gauss-Newton model predicts for the whole step, in residual
    /// variances: `||Q_1^T r||^2 / sigma^2 = R^2 p` ([`relative_offset`] R, p the rank,
    /// `sigma^2 = ||Q_2^T r||^2 / (m - p)`).
    pub predicted: f64,
    /// Largest decrease of `||r||^2` measured at the fractions `t` of the step, in the same
    /// residual variances (negative: the cost rose at every `t`).
    pub measured: f64,
    /// The fraction of the step where [`GaussNewtonLine::measured`] was found.
    pub t: f64,
    /// The point there (projected into the bounds).
    pub theta: Vec<f64>,
    /// Residual evaluations made (one per `t`).
    pub n_eval: usize,
}

/// The decrease of `||r||^2` actually available along the rank-truncated Gauss-Newton step
/// `delta = -J^+ r` from `theta` (residuals `residuals`, Jacobian `jacobian` there), measured at
/// `theta + t delta` for each `t` of `fractions`, each point projected into `bounds` as the
/// solver projects a trial step (a coordinate beyond its bound put just inside it). The
/// Gauss-Newton model predicts `||r(t)||^2 = ||r||^2 - (2 t - t^2) ||Q_1^T r||^2`, the
/// decrease the relative offset measures ([`relative_offset`]); where the residuals' own
/// curvature (`sum r_i Hess r_i`, left out of `J^T J`) dominates along the step, as in the
/// flat directions of a badly determined fit, the cost rises from a small `t` on and the
/// measured decrease is far below the prediction. Points whose residuals are not all finite
/// are skipped. `None` when the relative offset is undefined (`m <= p`) or no point was finite.
pub fn gauss_newton_line<F>(
    mut residual: F,
    theta: &[f64],
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    bounds: &Bounds,
    fractions: &[f64],
) -> Option<GaussNewtonLine>
where
    F: FnMut(&[f64]) -> Vec<f64>,
{
    let split = split_by_span(jacobian, residuals, true)?;
    let delta = split.step?;
    if delta.len() != theta.len() || !split.variance.is_finite() || split.variance <= 0.0 {
        return None;
    }
    let x = DVector::from_column_slice(theta);
    let lo = DVector::from_column_slice(&bounds.lo);
    let hi = DVector::from_column_slice(&bounds.hi);
    let ss0: f64 = residuals.iter().map(|r| r * r).sum();
    let mut best: Option<GaussNewtonLine> = None;
    let mut n_eval = 0;
    for &t in fractions {
        let xt = make_strictly_feasible(&(&x + &delta * t), &lo, &hi, 0.0);
        let r = residual(xt.as_slice());
        n_eval += 1;
        if r.len() != residuals.len() || !r.iter().all(|v| v.is_finite()) {
            continue;
        }
        let down = (ss0 - r.iter().map(|v| v * v).sum::<f64>()) / split.variance;
        if best.as_ref().is_none_or(|b| down > b.measured) {
            best = Some(GaussNewtonLine {
                predicted: split.in_span / split.variance,
                measured: down,
                t,
                theta: xt.iter().copied().collect(),
                n_eval: 0,
            });
        }
    }
    best.map(|b| GaussNewtonLine { n_eval, ..b })
}

/// Linearized statistics from a Jacobian (m x n) and residuals at a least-squares solution.
///
/// The Jacobian's columns are normalized (zero columns: unidentifiable) before the SVD, so the
/// rank decision and the singular values do not depend on the parameters' units.
pub fn param_stats(jacobian: &DMatrix<f64>, residuals: &[f64]) -> ParamStats {
    let (m, n) = jacobian.shape();
    let dof = m.saturating_sub(n);
    let rss: f64 = residuals.iter().map(|r| r * r).sum();
    let sigma2 = if dof > 0 { rss / dof as f64 } else { f64::NAN };
    let norms: Vec<f64> = (0..n).map(|j| jacobian.column(j).norm()).collect();
    let mut js = jacobian.clone();
    for j in 0..n {
        if norms[j] > 0.0 && norms[j].is_finite() {
            js.column_mut(j).scale_mut(1.0 / norms[j]);
        } else {
            js.column_mut(j).fill(0.0);
        }
    }
    let mut cov = DMatrix::from_element(n, n, f64::NAN);
    let mut std_err = vec![f64::INFINITY; n];
    let mut corr = DMatrix::from_element(n, n, f64::NAN);
    let (sv, vecs, rank) =
        match SVD::try_new(js, false, true, f64::EPSILON * 5.0, super::SVD_MAX_ITER) {
            Some(svd) if m > 0 && n > 0 => {
                let s: Vec<f64> = svd.singular_values.iter().copied().collect();
                let vt = svd.v_t.expect("v_t requested");
                let tol = f64::EPSILON * m.max(n) as f64 * s.first().copied().unwrap_or(0.0);
                let rank = s.iter().filter(|&&x| x > tol).count();
                // Right singular vectors as columns (n x k); pad to n x n for a full basis.
                let k = vt.nrows();
                let mut v = DMatrix::zeros(n, n);
                for i in 0..k {
                    for j in 0..n {
                        v[(j, i)] = vt[(i, j)];
                    }
                }
                let mut s_full = s.clone();
                s_full.resize(n, 0.0);
                (s_full, v, rank.min(k))
            }
            _ => (vec![0.0; n], DMatrix::identity(n, n), 0),
        };
    // Unidentifiable parameters: a non-negligible weight in a null direction.
    let mut identifiable = vec![true; n];
    for j in 0..n {
        if !(norms[j] > 0.0 && norms[j].is_finite()) {
            identifiable[j] = false;
        }
        for i in rank..n {
            if vecs[(j, i)].abs() > 1e-8 {
                identifiable[j] = false;
            }
        }
    }
    // cov = D^-1 V_r S_r^-2 V_r^T D^-1 sigma2.
    for a in 0..n {
        for b in 0..n {
            let mut acc = 0.0;
            for i in 0..rank {
                acc += vecs[(a, i)] * vecs[(b, i)] / (sv[i] * sv[i]);
            }
            cov[(a, b)] = acc * sigma2 / (norms[a] * norms[b]);
        }
    }
    for j in 0..n {
        if identifiable[j] {
            std_err[j] = cov[(j, j)].sqrt();
        }
    }
    for a in 0..n {
        for b in 0..n {
            if identifiable[a] && identifiable[b] {
                let d = (cov[(a, a)] * cov[(b, b)]).sqrt();
                corr[(a, b)] = if a == b { 1.0 } else { cov[(a, b)] / d };
            }
        }
    }
    ParamStats {
        dof,
        sigma2,
        covariance: cov,
        std_err,
        correlation: corr,
        singular_values: sv,
        directions: vecs,
        rank,
    }
}

/// Minimize `0.5 ||r(theta)||^2` over `bounds`, from `theta0`, with a finite-difference
/// Jacobian (see the module documentation).
///
/// ```
/// use mvem::numerics::lsq::{least_squares, Bounds, LsqOptions};
/// // Fit y = a exp(b t) to exact data with b bounded to [-2, 0].
/// let t = [0.0f64, 0.5, 1.0, 1.5, 2.0];
/// let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.7 * t).exp()).collect();
/// let r = |p: &[f64]| t.iter().zip(&y).map(|(t, y)| p[0] * (p[1] * t).exp() - y).collect();
/// let b = Bounds::new(vec![f64::NEG_INFINITY, -2.0], vec![f64::INFINITY, 0.0]);
/// let fit = least_squares(r, &[1.0, -0.1], &b, &LsqOptions::default()).unwrap();
/// assert!((fit.theta[0] - 2.0).abs() < 1e-6 && (fit.theta[1] + 0.7).abs() < 1e-6);
/// ```
pub fn least_squares<F>(
    mut residual: F,
    theta0: &[f64],
    bounds: &Bounds,
    opts: &LsqOptions,
) -> Result<LsqResult, LsqError>
where
    F: FnMut(&[f64]) -> Vec<f64>,
{
    trf(&mut residual, None, theta0, bounds, opts)
}

/// As [`least_squares`] for a residual function that may be called from several threads at
/// once: the columns of each finite-difference Jacobian are evaluated in parallel (rayon), the
/// trial steps in order. Every column is computed exactly as by [`least_squares`] (same steps,
/// same order of operations), so for a residual function whose value does not depend on the
/// thread calling it the result, the iterates and the evaluation counts are bitwise those of
/// [`least_squares`]; only the wall time of a Jacobian drops (by up to the number of cores).
pub fn least_squares_par<F>(
    residual: F,
    theta0: &[f64],
    bounds: &Bounds,
    opts: &LsqOptions,
) -> Result<LsqResult, LsqError>
where
    F: Fn(&[f64]) -> Vec<f64> + Sync,
{
    let mut seq = |th: &[f64]| residual(th);
    trf_with(&mut seq, None, Some(&residual), theta0, bounds, opts)
}

/// As [`least_squares`] with a user Jacobian `dr/dtheta` (m x n) at `theta`.
pub fn least_squares_with_jacobian<F, J>(
    mut residual: F,
    mut jacobian: J,
    theta0: &[f64],
    bounds: &Bounds,
    opts: &LsqOptions,
) -> Result<LsqResult, LsqError>
where
    F: FnMut(&[f64]) -> Vec<f64>,
    J: FnMut(&[f64]) -> DMatrix<f64>,
{
    trf(&mut residual, Some(&mut jacobian), theta0, bounds, opts)
}

type ResidualFn<'a> = &'a mut dyn FnMut(&[f64]) -> Vec<f64>;
type JacobianFn<'a> = &'a mut dyn FnMut(&[f64]) -> DMatrix<f64>;
type ParResidualFn<'a> = &'a (dyn Fn(&[f64]) -> Vec<f64> + Sync);

/// Counts residual evaluations and checks their length.
struct Evaluator<'a> {
    f: ResidualFn<'a>,
    jac: Option<JacobianFn<'a>>,
    /// The same residual function, callable from several threads (finite-difference columns
    /// in parallel, [`least_squares_par`]).
    par: Option<ParResidualFn<'a>>,
    m: usize,
    n_eval: usize,
    n_jac: usize,
    lo: DVector<f64>,
    hi: DVector<f64>,
    method: FiniteDiff,
    rel_step: f64,
    typical: Option<DVector<f64>>,
}

fn all_finite(v: &DVector<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Residuals of length `m` (else [`LsqError::ResidualLength`]).
fn checked(r: Vec<f64>, m: usize) -> Result<DVector<f64>, LsqError> {
    if r.len() != m {
        return Err(LsqError::ResidualLength {
            got: r.len(),
            expected: m,
        });
    }
    Ok(DVector::from_vec(r))
}

/// What a finite-difference column needs besides the residual function.
struct FdSpec<'a> {
    lo: &'a DVector<f64>,
    hi: &'a DVector<f64>,
    method: FiniteDiff,
    rel_step: f64,
    typical: Option<&'a DVector<f64>>,
}

type EvalFn<'a> = &'a mut dyn FnMut(&DVector<f64>) -> Result<DVector<f64>, LsqError>;

/// Residuals at `x + t e_j` (None if not finite).
fn shifted(
    eval: EvalFn,
    x: &DVector<f64>,
    j: usize,
    t: f64,
) -> Result<Option<DVector<f64>>, LsqError> {
    let mut xs = x.clone();
    xs[j] += t;
    let r = eval(&xs)?;
    Ok(all_finite(&r).then_some(r))
}

/// [`fd_column`] with residuals by `f` (checked to have `m` entries), and the number of
/// evaluations it made.
fn counted_fd_column(
    spec: &FdSpec,
    f: &mut dyn FnMut(&[f64]) -> Vec<f64>,
    m: usize,
    x: &DVector<f64>,
    f0: &DVector<f64>,
    j: usize,
) -> (Result<DVector<f64>, LsqError>, usize) {
    let mut count = 0;
    let mut eval = |xs: &DVector<f64>| {
        count += 1;
        checked(f(xs.as_slice()), m)
    };
    let c = fd_column(spec, &mut eval, x, f0, j);
    (c, count)
}

/// One finite-difference column (see the module documentation for the step), residuals by
/// `eval`.
fn fd_column(
    spec: &FdSpec,
    eval: EvalFn,
    x: &DVector<f64>,
    f0: &DVector<f64>,
    j: usize,
) -> Result<DVector<f64>, LsqError> {
    let xj = x[j];
    let base = match spec.typical {
        Some(t) => xj.abs().max(t[j]),
        None if xj != 0.0 => xj.abs(),
        None => 1.0,
    };
    let mut h = spec.rel_step * base;
    let (lo, hi) = (spec.lo[j], spec.hi[j]);
    let room_up = hi - xj;
    let room_down = xj - lo;
    let nonfinite = || LsqError::NonFiniteJacobian {
        column: j,
        row: 0,
        theta: x.iter().copied().collect(),
    };
    // Exactly representable step towards +/-.
    let step = |s: f64| (xj + s) - xj;
    match spec.method {
        FiniteDiff::Forward => {
            if h > room_up.max(room_down) {
                h = 0.5 * room_up.max(room_down);
            }
            let mut order = [1.0, -1.0];
            if h > room_up {
                order = [-1.0, 1.0];
            }
            for sgn in order {
                let room = if sgn > 0.0 { room_up } else { room_down };
                if h > room {
                    continue;
                }
                let t = step(sgn * h);
                if let Some(r) = shifted(eval, x, j, t)? {
                    return Ok((r - f0) / t);
                }
            }
            Err(nonfinite())
        }
        FiniteDiff::Central => {
            if h <= room_up && h <= room_down {
                let tp = step(h);
                let tm = step(-h);
                let rp = shifted(eval, x, j, tp)?;
                let rm = shifted(eval, x, j, tm)?;
                match (rp, rm) {
                    (Some(rp), Some(rm)) => return Ok((rp - rm) / (tp - tm)),
                    (Some(rp), None) => return Ok((rp - f0) / tp),
                    (None, Some(rm)) => return Ok((rm - f0) / tm),
                    (None, None) => return Err(nonfinite()),
                }
            }
            // One-sided second order: (-3 f0 + 4 f(h) - f(2h)) / (2h) into the room.
            let (sgn, room) = if room_up >= room_down {
                (1.0, room_up)
            } else {
                (-1.0, room_down)
            };
            if 2.0 * h > room {
                h = 0.5 * room;
            }
            let t1 = step(sgn * h);
            let t2 = step(2.0 * sgn * h);
            let r1 = shifted(eval, x, j, t1)?.ok_or_else(nonfinite)?;
            match shifted(eval, x, j, t2)? {
                Some(r2) => Ok((r1 * 4.0 - r2 - f0 * 3.0) / (2.0 * t1)),
                None => Ok((r1 - f0) / t1),
            }
        }
    }
}

impl Evaluator<'_> {
    fn eval(&mut self, x: &DVector<f64>) -> Result<DVector<f64>, LsqError> {
        self.check_cancelled()?;
        self.n_eval += 1;
        checked((self.f)(x.as_slice()), self.m)
    }

    fn check_cancelled(&self) -> Result<(), LsqError> {
        if super::cancel::requested() {
            return Err(LsqError::Cancelled {
                evaluations: self.n_eval,
            });
        }
        Ok(())
    }

    fn jacobian(&mut self, x: &DVector<f64>, f0: &DVector<f64>) -> Result<DMatrix<f64>, LsqError> {
        self.check_cancelled()?;
        self.n_jac += 1;
        let n = x.len();
        let jm = if let Some(jf) = self.jac.as_mut() {
            let jm = jf(x.as_slice());
            if jm.shape() != (self.m, n) {
                return Err(LsqError::JacobianShape {
                    got: jm.shape(),
                    expected: (self.m, n),
                });
            }
            jm
        } else {
            let spec = FdSpec {
                lo: &self.lo,
                hi: &self.hi,
                method: self.method,
                rel_step: self.rel_step,
                typical: self.typical.as_ref(),
            };
            let m = self.m;
            let cols: Vec<(Result<DVector<f64>, LsqError>, usize)> = match self.par {
                Some(par) => {
                    use rayon::prelude::*;
                    (0..n)
                        .into_par_iter()
                        .map(|j| counted_fd_column(&spec, &mut |xs| par(xs), m, x, f0, j))
                        .collect()
                }
                None => {
                    let f = &mut self.f;
                    let mut cols = Vec::with_capacity(n);
                    for j in 0..n {
                        // a cancellation is also seen between the columns
                        if super::cancel::requested() {
                            let done: usize = cols.iter().map(|c: &(_, usize)| c.1).sum();
                            return Err(LsqError::Cancelled {
                                evaluations: self.n_eval + done,
                            });
                        }
                        cols.push(counted_fd_column(&spec, &mut **f, m, x, f0, j));
                    }
                    cols
                }
            };
            let mut jm = DMatrix::zeros(m, n);
            for (j, (col, count)) in cols.into_iter().enumerate() {
                self.n_eval += count;
                jm.set_column(j, &col?);
            }
            jm
        };
        for j in 0..n {
            for i in 0..self.m {
                if !jm[(i, j)].is_finite() {
                    return Err(LsqError::NonFiniteJacobian {
                        column: j,
                        row: i,
                        theta: x.iter().copied().collect(),
                    });
                }
            }
        }
        Ok(jm)
    }
}

/// Checks inputs, then runs the TRF iteration.
fn trf<'a>(
    residual: ResidualFn<'a>,
    jac: Option<JacobianFn<'a>>,
    theta0: &[f64],
    bounds: &Bounds,
    opts: &LsqOptions,
) -> Result<LsqResult, LsqError> {
    trf_with(residual, jac, None, theta0, bounds, opts)
}

/// [`trf`] with the residual function also callable from several threads (`par`).
fn trf_with<'a>(
    residual: ResidualFn<'a>,
    jac: Option<JacobianFn<'a>>,
    par: Option<ParResidualFn<'a>>,
    theta0: &[f64],
    bounds: &Bounds,
    opts: &LsqOptions,
) -> Result<LsqResult, LsqError> {
    let n = theta0.len();
    if n == 0 {
        return Err(LsqError::NoParameters);
    }
    for (what, got) in [
        ("bounds.lo", bounds.lo.len()),
        ("bounds.hi", bounds.hi.len()),
    ] {
        if got != n {
            return Err(LsqError::Length {
                what,
                got,
                expected: n,
            });
        }
    }
    for i in 0..n {
        let (lo, hi) = (bounds.lo[i], bounds.hi[i]);
        if lo.is_nan() || hi.is_nan() || lo >= hi || lo == f64::INFINITY || hi == f64::NEG_INFINITY
        {
            return Err(LsqError::InvalidBounds { index: i, lo, hi });
        }
        let v = theta0[i];
        if !v.is_finite() || v < lo || v > hi {
            return Err(LsqError::InfeasibleStart {
                index: i,
                value: v,
                lo,
                hi,
            });
        }
    }
    for (name, value) in [
        ("ftol", opts.ftol),
        ("xtol", opts.xtol),
        ("gtol", opts.gtol),
        ("rel_offset_tol", opts.rel_offset_tol),
    ] {
        if value.is_nan() || value < 0.0 {
            return Err(LsqError::InvalidOption {
                name,
                value,
                rule: ">= 0",
            });
        }
    }
    if !(opts.initial_radius_factor > 0.0 && opts.initial_radius_factor.is_finite()) {
        return Err(LsqError::InvalidOption {
            name: "initial_radius_factor",
            value: opts.initial_radius_factor,
            rule: "finite, > 0",
        });
    }
    if let Some(s) = opts.fd_rel_step {
        if !(s > 0.0 && s < 1.0) {
            return Err(LsqError::InvalidOption {
                name: "fd_rel_step",
                value: s,
                rule: "in (0, 1)",
            });
        }
    }
    let typical = match &opts.x_scale {
        XScale::Jac => None,
        XScale::Fixed(s) => {
            if s.len() != n {
                return Err(LsqError::Length {
                    what: "x_scale",
                    got: s.len(),
                    expected: n,
                });
            }
            if let Some(&bad) = s.iter().find(|v| !(**v > 0.0 && v.is_finite())) {
                return Err(LsqError::InvalidOption {
                    name: "x_scale",
                    value: bad,
                    rule: "finite, > 0",
                });
            }
            Some(DVector::from_column_slice(s))
        }
    };
    let max_eval = opts.max_evaluations.unwrap_or(200 * (n + 1)).max(1);
    let rel_step = opts.fd_rel_step.unwrap_or(match opts.finite_diff {
        FiniteDiff::Forward => f64::EPSILON.sqrt(),
        FiniteDiff::Central => f64::EPSILON.cbrt(),
    });
    let lo = DVector::from_column_slice(&bounds.lo);
    let hi = DVector::from_column_slice(&bounds.hi);
    let has_jac = jac.is_some();
    let x0 = make_strictly_feasible(&DVector::from_column_slice(theta0), &lo, &hi, 1e-10);

    let mut ev = Evaluator {
        f: residual,
        jac,
        par,
        m: 0,
        n_eval: 0,
        n_jac: 0,
        lo: lo.clone(),
        hi: hi.clone(),
        method: opts.finite_diff,
        rel_step,
        typical: typical.clone(),
    };
    // First evaluation fixes m.
    ev.check_cancelled()?;
    ev.n_eval += 1;
    let r0 = (ev.f)(x0.as_slice());
    if r0.is_empty() {
        return Err(LsqError::NoResiduals);
    }
    ev.m = r0.len();
    if let Some((index, &value)) = r0.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(LsqError::NonFiniteStart { index, value });
    }
    let f0 = DVector::from_vec(r0);
    Trf {
        ev,
        lo,
        hi,
        typical,
        ftol: opts.ftol,
        xtol: opts.xtol,
        gtol: opts.gtol,
        max_eval,
        radius_factor: opts.initial_radius_factor,
        broyden: if has_jac { 0 } else { opts.broyden_updates },
        rel_offset_tol: opts.rel_offset_tol,
    }
    .run(x0, f0)
}

struct Trf<'a> {
    ev: Evaluator<'a>,
    lo: DVector<f64>,
    hi: DVector<f64>,
    typical: Option<DVector<f64>>,
    ftol: f64,
    xtol: f64,
    gtol: f64,
    max_eval: usize,
    radius_factor: f64,
    broyden: usize,
    rel_offset_tol: f64,
}

fn column_norms(j: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_iterator(j.ncols(), j.column_iter().map(|c| c.norm()))
}

impl Trf<'_> {
    /// Coleman–Li scaling vector `v` and its derivative sign `dv`.
    fn cl_scaling(&self, x: &DVector<f64>, g: &DVector<f64>) -> (DVector<f64>, DVector<f64>) {
        let n = x.len();
        let mut v = DVector::from_element(n, 1.0);
        let mut dv = DVector::zeros(n);
        for j in 0..n {
            if g[j] < 0.0 && self.hi[j].is_finite() {
                v[j] = self.hi[j] - x[j];
                dv[j] = -1.0;
            }
            if g[j] > 0.0 && self.lo[j].is_finite() {
                v[j] = x[j] - self.lo[j];
                dv[j] = 1.0;
            }
        }
        (v, dv)
    }

    /// Scale-free first-order optimality (module documentation, "gtol").
    fn optimality(
        &self,
        jm: &DMatrix<f64>,
        f: &DVector<f64>,
        g: &DVector<f64>,
        v: &DVector<f64>,
        dv: &DVector<f64>,
    ) -> f64 {
        let fnorm = f.norm();
        if fnorm == 0.0 {
            return 0.0;
        }
        let mut opt: f64 = 0.0;
        for j in 0..g.len() {
            let cn = jm.column(j).norm();
            if cn == 0.0 {
                continue;
            }
            let mut c = g[j].abs() / (cn * fnorm);
            if dv[j] != 0.0 {
                c *= (v[j] * cn / fnorm).min(1.0);
            }
            opt = opt.max(c);
        }
        opt
    }

    fn run(mut self, x0: DVector<f64>, f0: DVector<f64>) -> Result<LsqResult, LsqError> {
        let n = x0.len();
        let m = f0.len();
        let mut x = x0;
        let mut f = f0;
        let mut jm = self.ev.jacobian(&x, &f)?;
        let mut cost = 0.5 * f.norm_squared();
        let mut g = jm.tr_mul(&f);
        let jac_scale = self.typical.is_none();
        let mut scale_inv = match &self.typical {
            None => column_norms(&jm).map(|c| if c == 0.0 { 1.0 } else { c }),
            Some(t) => t.map(|s| 1.0 / s),
        };
        let (v, dv) = self.cl_scaling(&x, &g);
        let (v, _) = scaled_cl(v, dv, &scale_inv);
        let mut delta = self.radius_factor
            * x.component_mul(&scale_inv)
                .component_div(&v.map(f64::sqrt))
                .norm();
        if delta == 0.0 || !delta.is_finite() {
            delta = self.radius_factor;
        }
        let mut alpha = 0.0;
        let mut termination: Option<Termination> = None;
        let mut n_iter = 0;
        let mut opt;
        // `jm` is a finite-difference (or user) Jacobian at `x` (not a Broyden update), and the
        // number of Broyden updates since it was computed
        let mut fresh = true;
        let mut n_updates = 0;

        loop {
            super::progress::report(|| super::progress::Progress::Search {
                evaluations: self.ev.n_eval,
                cost,
            });
            let (v, dv) = self.cl_scaling(&x, &g);
            opt = self.optimality(&jm, &f, &g, &v, &dv);
            if opt < self.gtol {
                if !fresh {
                    // a Broyden Jacobian cannot certify optimality: recompute, test again
                    jm = self.ev.jacobian(&x, &f)?;
                    g = jm.tr_mul(&f);
                    (fresh, n_updates) = (true, 0);
                    continue;
                }
                termination = Some(Termination::Gtol);
            } else if self.rel_offset_tol > 0.0 && fresh {
                let r = relative_offset(&jm, f.as_slice());
                if std::env::var_os("MVEM_LSQ_TRACE").is_some() {
                    eprintln!(
                        "lsq: iter {n_iter} eval {} cost {:.6e} rel_offset {r:.3e}",
                        self.ev.n_eval, cost
                    );
                }
                if r < self.rel_offset_tol {
                    termination = Some(Termination::RelativeOffset);
                }
            }
            if termination.is_some() {
                break;
            }
            if self.ev.n_eval >= self.max_eval {
                termination = Some(Termination::MaxEvaluations);
                break;
            }
            // Variables in "hat" space: first x_scale, then Coleman–Li.
            let (v, dv) = scaled_cl(v, dv, &scale_inv);
            let scale = scale_inv.map(|s| 1.0 / s);
            let d = v.map(f64::sqrt).component_mul(&scale);
            let diag_h = g.component_mul(&dv).component_mul(&scale);
            let g_h = d.component_mul(&g);
            let mut j_h = jm.clone();
            for j in 0..n {
                j_h.column_mut(j).scale_mut(d[j]);
            }
            let mut j_aug = DMatrix::zeros(m + n, n);
            j_aug.view_mut((0, 0), (m, n)).copy_from(&j_h);
            for j in 0..n {
                j_aug[(m + j, j)] = diag_h[j].max(0.0).sqrt();
            }
            let mut f_aug = DVector::zeros(m + n);
            f_aug.rows_mut(0, m).copy_from(&f);
            let svd = SVD::try_new(j_aug, true, true, f64::EPSILON * 5.0, super::SVD_MAX_ITER)
                .ok_or(LsqError::Svd)?;
            let u = svd.u.as_ref().expect("u requested");
            let v_t = svd.v_t.as_ref().expect("v_t requested");
            let s = &svd.singular_values;
            let uf = u.tr_mul(&f_aug);
            let theta_pull = (1.0 - opt).max(0.995);

            let mut actual_reduction = -1.0;
            let mut ratio = 0.0;
            let mut x_new = x.clone();
            let mut f_new = f.clone();
            let mut cost_new = cost;
            // with a Broyden Jacobian, a failed step or a convergence test asks for a new one
            let mut refresh = false;
            while actual_reduction <= 0.0 && self.ev.n_eval < self.max_eval {
                let (p_h, a) = solve_lsq_trust_region(m + n, &uf, s, v_t, delta, alpha);
                alpha = a;
                let p = d.component_mul(&p_h);
                let (step, step_h, predicted) =
                    self.select_step(&x, &j_h, &diag_h, &g_h, p, p_h, &d, delta, theta_pull);
                x_new = make_strictly_feasible(&(&x + &step), &self.lo, &self.hi, 0.0);
                let step = &x_new - &x;
                let step_h_norm = step_h.norm();
                let step_norm = step.component_mul(&scale_inv).norm();
                let x_norm = x.component_mul(&scale_inv).norm();
                let xtol_ok = step_norm < self.xtol * (self.xtol + x_norm);
                f_new = self.ev.eval(&x_new)?;
                if !all_finite(&f_new) {
                    if !fresh {
                        refresh = true;
                        break;
                    }
                    // Failed trial step: shrink the trust region.
                    delta = 0.25 * step_h_norm;
                    if xtol_ok || (delta.is_nan() || delta <= 0.0) {
                        termination = Some(Termination::Xtol);
                        break;
                    }
                    continue;
                }
                cost_new = 0.5 * f_new.norm_squared();
                actual_reduction = cost - cost_new;
                let (delta_new, r) = update_tr_radius(
                    delta,
                    actual_reduction,
                    predicted,
                    step_h_norm,
                    step_h_norm > 0.95 * delta,
                );
                ratio = r;
                let ftol_ok = actual_reduction < self.ftol * cost && ratio > 0.25;
                termination = match (ftol_ok, xtol_ok) {
                    (true, true) => Some(Termination::FtolAndXtol),
                    (true, false) => Some(Termination::Ftol),
                    (false, true) => Some(Termination::Xtol),
                    (false, false) => None,
                };
                if !fresh && (termination.is_some() || actual_reduction <= 0.0) {
                    // not a convergence test nor a reason to shrink the radius while the
                    // Jacobian is a secant approximation: take the step if it descends and
                    // recompute the Jacobian
                    termination = None;
                    refresh = true;
                    if actual_reduction > 0.0 && delta_new > 0.0 {
                        alpha *= delta / delta_new;
                        delta = delta_new;
                    }
                    break;
                }
                if termination.is_some() {
                    break;
                }
                if delta_new > 0.0 {
                    alpha *= delta / delta_new;
                }
                delta = delta_new;
                if delta.is_nan() || delta <= 0.0 {
                    termination = Some(Termination::Xtol);
                    break;
                }
            }
            let accepted = actual_reduction > 0.0 && all_finite(&f_new);
            if accepted {
                let s = &x_new - &x;
                if self.broyden > 0 && !refresh && ratio >= 0.25 && n_updates < self.broyden {
                    // Broyden (1965) rank-1 secant update: J s = f_new - f afterwards
                    let ss = s.norm_squared();
                    if ss > 0.0 {
                        let y = &f_new - &f - &jm * &s;
                        jm.ger(1.0 / ss, &y, &s, 1.0);
                    }
                    x = x_new;
                    f = f_new;
                    cost = cost_new;
                    g = jm.tr_mul(&f);
                    fresh = false;
                    n_updates += 1;
                } else {
                    x = x_new;
                    f = f_new;
                    cost = cost_new;
                    refresh = true;
                }
            }
            // (after a converged step too: the reported Jacobian is the one at theta)
            if refresh && (termination.is_none() || accepted) {
                jm = self.ev.jacobian(&x, &f)?;
                g = jm.tr_mul(&f);
                (fresh, n_updates) = (true, 0);
                if jac_scale {
                    let cn = column_norms(&jm);
                    scale_inv = scale_inv.zip_map(&cn, f64::max);
                }
            }
            n_iter += 1;
        }
        if !fresh {
            // the reported Jacobian (parameter statistics) is a finite-difference one at theta
            jm = self.ev.jacobian(&x, &f)?;
        }
        let termination = termination.unwrap_or(Termination::MaxEvaluations);
        let active = find_active(&x, &self.lo, &self.hi, self.xtol.max(1e-10));
        let rel_offset = relative_offset(&jm, f.as_slice());
        Ok(LsqResult {
            theta: x.iter().copied().collect(),
            cost,
            residuals: f.iter().copied().collect(),
            jacobian: jm,
            optimality: opt,
            active,
            n_eval: self.ev.n_eval,
            n_jac: self.ev.n_jac,
            n_iter,
            termination,
            rel_offset,
        })
    }

    /// Best of the interior-pulled trust-region step, its reflection at the first bound hit,
    /// and the scaled Cauchy step (Branch, Coleman & Li 1999; scipy `select_step`). Returns the
    /// step in original and hat variables and the predicted cost reduction.
    #[allow(clippy::too_many_arguments)]
    fn select_step(
        &self,
        x: &DVector<f64>,
        j_h: &DMatrix<f64>,
        diag_h: &DVector<f64>,
        g_h: &DVector<f64>,
        mut p: DVector<f64>,
        mut p_h: DVector<f64>,
        d: &DVector<f64>,
        delta: f64,
        theta: f64,
    ) -> (DVector<f64>, DVector<f64>, f64) {
        let (lo, hi) = (&self.lo, &self.hi);
        let xp = x + &p;
        if (0..x.len()).all(|j| xp[j] >= lo[j] && xp[j] <= hi[j]) {
            let value = evaluate_quadratic(j_h, g_h, &p_h, diag_h);
            return (p, p_h, -value);
        }
        let (p_stride, hits) = step_size_to_bound(x, &p, lo, hi);
        // Reflected direction.
        let mut r_h = p_h.clone();
        for j in 0..x.len() {
            if hits[j] != 0 {
                r_h[j] = -r_h[j];
            }
        }
        let r = d.component_mul(&r_h);
        // Cut the trust-region step at the bound.
        p *= p_stride;
        p_h *= p_stride;
        let x_on_bound = x + &p;
        let to_tr = intersect_trust_region(&p_h, &r_h, delta)
            .map(|t| t.1)
            .unwrap_or(0.0);
        let (to_bound, _) = step_size_to_bound(&x_on_bound, &r, lo, hi);
        let r_stride = to_bound.min(to_tr);
        let (r_lo, r_hi) = if r_stride > 0.0 {
            let l = (1.0 - theta) * p_stride / r_stride;
            let u = if r_stride == to_bound {
                theta * to_bound
            } else {
                to_tr
            };
            (l, u)
        } else {
            (0.0, -1.0)
        };
        let mut r_step = None;
        if r_lo <= r_hi {
            let (a, b, c) = build_quadratic_1d(j_h, g_h, &r_h, diag_h, Some(&p_h));
            let (t, value) = minimize_quadratic_1d(a, b, r_lo, r_hi, c);
            let rh = &r_h * t + &p_h;
            let rr = d.component_mul(&rh);
            r_step = Some((rr, rh, value));
        }
        // Pull the cut step strictly inside.
        p *= theta;
        p_h *= theta;
        let p_value = evaluate_quadratic(j_h, g_h, &p_h, diag_h);
        // Scaled anti-gradient (Cauchy) step.
        let ag_h = -g_h;
        let ag = d.component_mul(&ag_h);
        let ag_norm = ag_h.norm();
        let to_tr = if ag_norm > 0.0 { delta / ag_norm } else { 0.0 };
        let (to_bound, _) = step_size_to_bound(x, &ag, lo, hi);
        let ag_max = if to_bound < to_tr {
            theta * to_bound
        } else {
            to_tr
        };
        let (a, b, _) = build_quadratic_1d(j_h, g_h, &ag_h, diag_h, None);
        let (t, ag_value) = minimize_quadratic_1d(a, b, 0.0, ag_max, 0.0);
        let r_value = r_step.as_ref().map(|r| r.2).unwrap_or(f64::INFINITY);
        if p_value < r_value && p_value < ag_value {
            (p, p_h, -p_value)
        } else if r_value < p_value && r_value < ag_value {
            let (rr, rh, v) = r_step.expect("finite r_value");
            (rr, rh, -v)
        } else {
            (ag * t, ag_h * t, -ag_value)
        }
    }
}

/// Coleman–Li vector in the `x_scale`d variables: distances divided by the scale, capped at 1
/// (a bound farther than one scaled unit leaves the metric as without bounds: `v = 1`,
/// `dv = 0`; see the module documentation).
fn scaled_cl(
    mut v: DVector<f64>,
    mut dv: DVector<f64>,
    scale_inv: &DVector<f64>,
) -> (DVector<f64>, DVector<f64>) {
    for j in 0..v.len() {
        if dv[j] != 0.0 {
            v[j] *= scale_inv[j];
            if v[j] >= 1.0 {
                v[j] = 1.0;
                dv[j] = 0.0;
            }
        }
    }
    (v, dv)
}

/// Solution of `min ||J p + f||` subject to `||p|| <= delta` from the SVD of `J`
/// (`uf = U^T f`), by Moré's (1978) safeguarded Newton iteration on the Levenberg–Marquardt
/// parameter `alpha` (relative tolerance 0.01, at most 10 iterations; scipy
/// `solve_lsq_trust_region`). Returns the step and the parameter (0 for the Gauss–Newton step).
fn solve_lsq_trust_region(
    rows: usize,
    uf: &DVector<f64>,
    s: &DVector<f64>,
    v_t: &DMatrix<f64>,
    delta: f64,
    alpha0: f64,
) -> (DVector<f64>, f64) {
    let k = s.len();
    let n = v_t.ncols();
    let suf = DVector::from_iterator(k, (0..k).map(|i| s[i] * uf[i]));
    let combine = |coef: &DVector<f64>| -> DVector<f64> {
        let mut p = DVector::zeros(n);
        for i in 0..k {
            p.axpy(-coef[i], &v_t.row(i).transpose(), 1.0);
        }
        p
    };
    let threshold = f64::EPSILON * rows as f64 * s[0];
    let full_rank = k == n && s[k - 1] > threshold;
    if full_rank {
        let p = combine(&DVector::from_iterator(k, (0..k).map(|i| uf[i] / s[i])));
        if p.norm() <= delta {
            return (p, 0.0);
        }
    }
    let phi_and_derivative = |alpha: f64| -> (f64, f64) {
        let mut pn2 = 0.0;
        let mut d3 = 0.0;
        for i in 0..k {
            let den = s[i] * s[i] + alpha;
            pn2 += (suf[i] / den).powi(2);
            d3 += suf[i] * suf[i] / (den * den * den);
        }
        let pn = pn2.sqrt();
        (pn - delta, -d3 / pn)
    };
    let suf_norm = suf.norm();
    if suf_norm == 0.0 {
        return (DVector::zeros(n), alpha0);
    }
    let mut alpha_upper = suf_norm / delta;
    let mut alpha_lower = if full_rank {
        let (phi, dphi) = phi_and_derivative(0.0);
        -phi / dphi
    } else {
        0.0
    };
    let mut alpha = if !full_rank && alpha0 == 0.0 {
        (0.001 * alpha_upper).max((alpha_lower * alpha_upper).sqrt())
    } else {
        alpha0
    };
    for _ in 0..10 {
        if alpha < alpha_lower || alpha > alpha_upper {
            alpha = (0.001 * alpha_upper).max((alpha_lower * alpha_upper).sqrt());
        }
        let (phi, dphi) = phi_and_derivative(alpha);
        if phi < 0.0 {
            alpha_upper = alpha;
        }
        let ratio = phi / dphi;
        alpha_lower = alpha_lower.max(alpha - ratio);
        alpha -= (phi + delta) * ratio / delta;
        if phi.abs() < 0.01 * delta {
            break;
        }
    }
    let coef = DVector::from_iterator(k, (0..k).map(|i| suf[i] / (s[i] * s[i] + alpha)));
    let mut p = combine(&coef);
    let pn = p.norm();
    if pn > 0.0 {
        // Put p on the trust-region boundary exactly (it is only slightly changed).
        p *= delta / pn;
    }
    (p, alpha)
}

/// New radius and ratio of actual to predicted reduction (Moré 1978 / scipy).
fn update_tr_radius(
    delta: f64,
    actual: f64,
    predicted: f64,
    step_norm: f64,
    bound_hit: bool,
) -> (f64, f64) {
    let ratio = if predicted > 0.0 {
        actual / predicted
    } else if predicted == 0.0 && actual == 0.0 {
        1.0
    } else {
        0.0
    };
    let delta = if ratio < 0.25 {
        0.25 * step_norm
    } else if ratio > 0.75 && bound_hit {
        2.0 * delta
    } else {
        delta
    };
    (delta, ratio)
}

/// `0.5 (||J s||^2 + s^T diag(q) s) + g^T s`.
fn evaluate_quadratic(
    j: &DMatrix<f64>,
    g: &DVector<f64>,
    s: &DVector<f64>,
    diag: &DVector<f64>,
) -> f64 {
    let js = j * s;
    let q = js.norm_squared() + s.component_mul(diag).dot(s);
    0.5 * q + g.dot(s)
}

/// Coefficients of the quadratic `a t^2 + b t + c` of the model along `s0 + t s`.
fn build_quadratic_1d(
    j: &DMatrix<f64>,
    g: &DVector<f64>,
    s: &DVector<f64>,
    diag: &DVector<f64>,
    s0: Option<&DVector<f64>>,
) -> (f64, f64, f64) {
    let v = j * s;
    let a = 0.5 * (v.norm_squared() + s.component_mul(diag).dot(s));
    let mut b = g.dot(s);
    let mut c = 0.0;
    if let Some(s0) = s0 {
        let u = j * s0;
        b += u.dot(&v) + s0.component_mul(diag).dot(s);
        c = 0.5 * u.norm_squared() + g.dot(s0) + 0.5 * s0.component_mul(diag).dot(s0);
    }
    (a, b, c)
}

/// Minimum of `a t^2 + b t + c` over `[lo, hi]`: (t, value).
fn minimize_quadratic_1d(a: f64, b: f64, lo: f64, hi: f64, c: f64) -> (f64, f64) {
    let mut cands = vec![lo, hi];
    if a != 0.0 {
        let ext = -0.5 * b / a;
        if lo < ext && ext < hi {
            cands.push(ext);
        }
    }
    cands
        .into_iter()
        .map(|t| (t, t * (a * t + b) + c))
        .fold(
            (lo, f64::INFINITY),
            |best, cur| if cur.1 < best.1 { cur } else { best },
        )
}

/// Largest `t` with `x + t s` inside the box, and per component the sign of `s` where that
/// bound is hit.
fn step_size_to_bound(
    x: &DVector<f64>,
    s: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
) -> (f64, Vec<i8>) {
    let n = x.len();
    let steps: Vec<f64> = (0..n)
        .map(|j| {
            if s[j] == 0.0 {
                f64::INFINITY
            } else {
                ((lo[j] - x[j]) / s[j]).max((hi[j] - x[j]) / s[j])
            }
        })
        .collect();
    let min = steps.iter().copied().fold(f64::INFINITY, f64::min);
    let hits = (0..n)
        .map(|j| {
            if steps[j] == min && s[j] != 0.0 {
                s[j].signum() as i8
            } else {
                0
            }
        })
        .collect();
    (min, hits)
}

/// Both roots `t1 <= t2` of `||x + t s|| = delta` (None if `s = 0` or `x` is outside).
fn intersect_trust_region(x: &DVector<f64>, s: &DVector<f64>, delta: f64) -> Option<(f64, f64)> {
    let a = s.dot(s);
    if a == 0.0 {
        return None;
    }
    let b = x.dot(s);
    let c = x.dot(x) - delta * delta;
    if c > 0.0 {
        // Round-off: x marginally outside; treat as on the boundary.
        let t = -2.0 * b / a;
        return Some((t.min(0.0), t.max(0.0)));
    }
    let d = (b * b - a * c).sqrt();
    let q = -(b + d.copysign(b));
    if q == 0.0 {
        return Some((0.0, 0.0));
    }
    let (t1, t2) = (q / a, c / q);
    Some(if t1 < t2 { (t1, t2) } else { (t2, t1) })
}

/// Moves points on or outside a bound strictly inside: to the next float (`rstep = 0`) or by
/// `rstep * max(1, |bound|)`; if that crosses the other bound, to the box middle.
fn make_strictly_feasible(
    x: &DVector<f64>,
    lo: &DVector<f64>,
    hi: &DVector<f64>,
    rstep: f64,
) -> DVector<f64> {
    let mut out = x.clone();
    let active = find_active(x, lo, hi, rstep);
    for j in 0..x.len() {
        match active[j] {
            -1 => {
                out[j] = if rstep == 0.0 {
                    next_toward(lo[j], hi[j])
                } else {
                    lo[j] + rstep * lo[j].abs().max(1.0)
                }
            }
            1 => {
                out[j] = if rstep == 0.0 {
                    next_toward(hi[j], lo[j])
                } else {
                    hi[j] - rstep * hi[j].abs().max(1.0)
                }
            }
            _ => {}
        }
        if out[j] < lo[j] || out[j] > hi[j] {
            out[j] = 0.5 * (lo[j] + hi[j]);
        }
    }
    out
}

/// The float next to `a` in the direction of `b`.
fn next_toward(a: f64, b: f64) -> f64 {
    if a == b || a.is_nan() || b.is_nan() {
        return a;
    }
    if a == 0.0 {
        return f64::from_bits(1).copysign(b - a);
    }
    let bits = a.to_bits();
    let up = (b > a) == (a > 0.0);
    f64::from_bits(if up { bits + 1 } else { bits - 1 })
}

/// Active bounds: -1 lower, +1 upper, 0 none (within `rtol * max(1, |bound|)`; exact for 0).
fn find_active(x: &DVector<f64>, lo: &DVector<f64>, hi: &DVector<f64>, rtol: f64) -> Vec<i8> {
    (0..x.len())
        .map(|j| {
            if rtol == 0.0 {
                if x[j] <= lo[j] {
                    return -1;
                }
                if x[j] >= hi[j] {
                    return 1;
                }
                return 0;
            }
            let ld = x[j] - lo[j];
            let ud = hi[j] - x[j];
            if lo[j].is_finite() && ld <= ud.min(rtol * lo[j].abs().max(1.0)) {
                -1
            } else if hi[j].is_finite() && ud <= ld.min(rtol * hi[j].abs().max(1.0)) {
                1
            } else {
                0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exp_data() -> (Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..20).map(|i| i as f64 * 0.25).collect();
        let y = t.iter().map(|t| 3.0 * (-0.8 * t).exp() + 0.5).collect();
        (t, y)
    }

    fn exp_residual<'a>(t: &'a [f64], y: &'a [f64]) -> impl FnMut(&[f64]) -> Vec<f64> + 'a {
        move |p: &[f64]| {
            t.iter()
                .zip(y)
                .map(|(t, y)| p[0] * (-p[1] * t).exp() + p[2] - y)
                .collect()
        }
    }

    #[test]
    fn unbounded_exact_fit_forward_and_central() {
        let (t, y) = exp_data();
        for fd in [FiniteDiff::Forward, FiniteDiff::Central] {
            let opts = LsqOptions {
                finite_diff: fd,
                ..LsqOptions::default()
            };
            let fit = least_squares(
                exp_residual(&t, &y),
                &[1.0, 0.1, 0.0],
                &Bounds::none(3),
                &opts,
            )
            .unwrap();
            assert!(fit.termination.converged(), "{:?}", fit.termination);
            for (a, b) in fit.theta.iter().zip([3.0, 0.8, 0.5]) {
                assert!((a - b).abs() < 1e-7, "{fd:?}: {:?}", fit.theta);
            }
            assert!(fit.cost < 1e-14);
        }
    }

    /// Three Gaussian peaks (9 parameters) on 120 points with a deterministic pseudo-noise.
    fn peaks_residual(p: &[f64]) -> Vec<f64> {
        (0..120)
            .map(|i| {
                let t = i as f64 / 10.0;
                let truth = 2.0 * (-((t - 3.0) / 0.8).powi(2)).exp()
                    + 1.5 * (-((t - 6.0) / 1.2).powi(2)).exp()
                    + 1.0 * (-((t - 9.0) / 0.6).powi(2)).exp();
                let noise = 0.01 * (((i * 7919) % 23) as f64 / 11.0 - 1.0);
                let model: f64 = p
                    .chunks(3)
                    .map(|c| c[0] * (-((t - c[1]) / c[2]).powi(2)).exp())
                    .sum();
                model - truth - noise
            })
            .collect()
    }

    #[test]
    fn broyden_updates_reach_the_same_optimum_with_fewer_evaluations() {
        let x0 = [1.5, 2.6, 1.0, 1.0, 6.5, 1.0, 0.8, 8.7, 0.8];
        let mut lo = vec![0.0; 9];
        lo[6] = 0.7; // third amplitude >= 0.7: not active at the optimum (about 1.0)
        let b = Bounds::new(lo, vec![10.0; 9]);
        let run = |k: usize| {
            let opts = LsqOptions {
                broyden_updates: k,
                ..LsqOptions::default()
            };
            least_squares(peaks_residual, &x0, &b, &opts).unwrap()
        };
        let plain = run(0);
        let secant = run(4);
        assert!(plain.termination.converged(), "{:?}", plain.termination);
        assert!(secant.termination.converged(), "{:?}", secant.termination);
        for (a, b) in secant.theta.iter().zip(&plain.theta) {
            assert!((a - b).abs() < 1e-6 * b.abs().max(1.0), "{a} {b}");
        }
        assert!((secant.cost / plain.cost - 1.0).abs() < 1e-9);
        // the reported Jacobian is a finite-difference one at the optimum, not a secant one
        for (a, b) in secant.jacobian.iter().zip(plain.jacobian.iter()) {
            assert!((a - b).abs() < 1e-5 * (1.0 + b.abs()), "{a} {b}");
        }
        assert!(
            secant.n_eval < plain.n_eval,
            "{} vs {}",
            secant.n_eval,
            plain.n_eval
        );
    }

    #[test]
    fn relative_offset_of_a_linear_model_by_hand() {
        // r(a, b) = a + b x - y: at theta, r = r* + J (theta - theta*) with r* orthogonal to the
        // columns of J, so R = (||J d|| / sqrt(2)) / (||r*|| / sqrt(m - 2))
        let m = 30;
        let x: Vec<f64> = (0..m).map(|i| i as f64 / 3.0).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, x)| 1.0 + 0.5 * x + 0.1 * (((i * 7919) % 13) as f64 / 6.0 - 1.0))
            .collect();
        let j = DMatrix::from_fn(m, 2, |i, k| if k == 0 { 1.0 } else { x[i] });
        let res =
            |a: f64, b: f64| -> Vec<f64> { x.iter().zip(&y).map(|(x, y)| a + b * x - y).collect() };
        // the least-squares solution from the normal equations
        let jt_y = j.tr_mul(&DVector::from_column_slice(&y));
        let th = (j.tr_mul(&j)).try_inverse().unwrap() * jt_y;
        let r_opt = res(th[0], th[1]);
        assert!(relative_offset(&j, &r_opt) < 1e-10);
        let d = DVector::from_column_slice(&[0.03, -0.004]);
        let r = res(th[0] + d[0], th[1] + d[1]);
        let rss: f64 = r_opt.iter().map(|v| v * v).sum();
        let want = ((&j * &d).norm() / 2f64.sqrt()) / (rss / (m - 2) as f64).sqrt();
        let got = relative_offset(&j, &r);
        assert!((got / want - 1.0).abs() < 1e-8, "{got} {want}");
        // the column scaling does not change it
        let js = DMatrix::from_fn(m, 2, |i, k| j[(i, k)] * if k == 0 { 1e6 } else { 1e-3 });
        assert!((relative_offset(&js, &r) / want - 1.0).abs() < 1e-8);
    }

    /// A Rosenbrock-like residual (10 (y - x^2), 1 - x) with four residuals the parameters do
    /// not move (2, -1, 1, 0: residual variance 6 / (6 - 2) = 1.5), and its exact Jacobian.
    fn rosenbrock_with_noise(th: &[f64]) -> Vec<f64> {
        vec![
            10.0 * (th[1] - th[0] * th[0]),
            1.0 - th[0],
            2.0,
            -1.0,
            1.0,
            0.0,
        ]
    }

    fn rosenbrock_jacobian(th: &[f64]) -> DMatrix<f64> {
        let mut j = DMatrix::zeros(6, 2);
        j[(0, 0)] = -20.0 * th[0];
        j[(0, 1)] = 10.0;
        j[(1, 0)] = -1.0;
        j
    }

    #[test]
    fn the_cost_along_the_gauss_newton_step_by_hand() {
        let ts = [1.0, 0.1, 0.01, 0.001];
        // on the valley y = x^2 at x = -2: r = (0, 3), the Gauss-Newton step (3, -12) gives
        // y - x^2 = -9 t^2, so ||r(t)||^2 = 8100 t^4 + 9 (1 - t)^2 + 6 where J^T J predicts
        // 15 - 9 (2 t - t^2): R^2 p = 9 / 1.5 = 6 residual variances, R = 1.73 > 1 / sqrt(2)
        // (the relative-offset rule: stopped short); measured, the best is t = 0.1 with
        // 9 - 8.1 = 0.9, i.e. 0.6 residual variances (t = 1: the cost rises by 8091)
        let th = [-2.0, 4.0];
        let (r, j) = (rosenbrock_with_noise(&th), rosenbrock_jacobian(&th));
        let big_r = relative_offset(&j, &r);
        assert!((big_r - 3f64.sqrt()).abs() < 1e-12, "{big_r}");
        let line = gauss_newton_line(rosenbrock_with_noise, &th, &j, &r, &Bounds::none(2), &ts)
            .expect("a line");
        assert!((line.predicted - 6.0).abs() < 1e-9, "{line:?}");
        assert!((line.predicted - big_r * big_r * 2.0).abs() < 1e-9);
        assert_eq!((line.t, line.n_eval), (0.1, 4));
        assert!((line.measured - 0.6).abs() < 1e-9, "{line:?}");
        assert!((line.theta[0] + 1.7).abs() < 1e-12 && (line.theta[1] - 2.8).abs() < 1e-12);
        // off the valley at (0, 1): r = (10, 1), the step (1, -1) removes most of r_1 first:
        // t = 0.1 gives 8.9^2 + 0.9^2 = 80.02 against 101, 13.99 residual variances (of 67.3
        // predicted), t = 1 only 1
        let th = [0.0, 1.0];
        let (r, j) = (rosenbrock_with_noise(&th), rosenbrock_jacobian(&th));
        let line = gauss_newton_line(rosenbrock_with_noise, &th, &j, &r, &Bounds::none(2), &ts)
            .expect("a line");
        assert!((line.predicted - 101.0 / 1.5).abs() < 1e-9, "{line:?}");
        assert_eq!(line.t, 0.1);
        assert!((line.measured - 20.98 / 1.5).abs() < 1e-9, "{line:?}");
        // the points are projected into the bounds as the solver's trial steps: x <= 0.05
        let b = Bounds::new(vec![-1.0, -1.0], vec![0.05, 2.0]);
        let line = gauss_newton_line(rosenbrock_with_noise, &th, &j, &r, &b, &ts).expect("a line");
        assert!(
            line.theta[0] < 0.05 && line.theta[0] > 0.05 - 1e-15,
            "{line:?}"
        );
        // no residual variance left (m = p): undefined, as the relative offset
        let two = |t: &[f64]| rosenbrock_with_noise(t)[..2].to_vec();
        let j2 = rosenbrock_jacobian(&th).rows(0, 2).into_owned();
        assert!(gauss_newton_line(two, &th, &j2, &r[..2], &Bounds::none(2), &ts).is_none());
    }

    #[test]
    fn relative_offset_stops_the_search_within_its_bound() {
        let x0 = [1.5, 2.6, 1.0, 1.0, 6.5, 1.0, 0.8, 8.7, 0.8];
        let mut lo = vec![0.0; 9];
        lo[6] = 0.7;
        let b = Bounds::new(lo, vec![10.0; 9]);
        let run = |tol: f64| {
            let opts = LsqOptions {
                rel_offset_tol: tol,
                ..LsqOptions::default()
            };
            least_squares(peaks_residual, &x0, &b, &opts).unwrap()
        };
        let full = run(0.0);
        let tol = 0.3;
        let early = run(tol);
        assert_eq!(early.termination, Termination::RelativeOffset);
        assert!(early.termination.converged());
        assert!(early.rel_offset < tol, "{}", early.rel_offset);
        assert!(full.rel_offset < 1e-3, "{}", full.rel_offset);
        assert!(
            early.n_eval < full.n_eval,
            "{} {}",
            early.n_eval,
            full.n_eval
        );
        // every parameter within R sqrt(p) (plus the nonlinearity of one step) of its
        // standard error from the converged optimum
        let st = full.stats();
        for k in 0..9 {
            let z = (early.theta[k] - full.theta[k]).abs() / st.std_err[k];
            assert!(z < 1.5 * tol * 3.0, "{k}: {z}");
        }
        // a negative tolerance is refused
        let opts = LsqOptions {
            rel_offset_tol: -1.0,
            ..LsqOptions::default()
        };
        assert!(matches!(
            least_squares(peaks_residual, &x0, &b, &opts),
            Err(LsqError::InvalidOption {
                name: "rel_offset_tol",
                ..
            })
        ));
    }

    #[test]
    fn parallel_jacobian_columns_give_bitwise_the_same_search() {
        // forward and central differences, with a bound the difference step must respect
        let x0 = [1.5, 2.6, 1.0, 1.0, 6.5, 1.0, 0.8, 8.7, 0.8];
        let mut lo = vec![0.0; 9];
        lo[6] = 0.7;
        let b = Bounds::new(lo, vec![10.0; 9]);
        for finite_diff in [FiniteDiff::Forward, FiniteDiff::Central] {
            let opts = LsqOptions {
                finite_diff,
                ..LsqOptions::default()
            };
            let seq = least_squares(peaks_residual, &x0, &b, &opts).unwrap();
            let par = least_squares_par(peaks_residual, &x0, &b, &opts).unwrap();
            assert!(seq.termination.converged(), "{:?}", seq.termination);
            assert_eq!(par.theta, seq.theta);
            assert_eq!(par.residuals, seq.residuals);
            assert_eq!(par.jacobian, seq.jacobian);
            assert_eq!(
                (par.n_eval, par.n_jac, par.n_iter),
                (seq.n_eval, seq.n_jac, seq.n_iter)
            );
            assert_eq!(par.termination, seq.termination);
        }
    }

    #[test]
    fn active_bound_reaches_kkt_point() {
        // Same data, but the rate is bounded to <= 0.5: the constrained minimum has p1 = 0.5
        // and the other two parameters solve the linear least-squares problem at p1 = 0.5.
        let (t, y) = exp_data();
        let b = Bounds::new(
            vec![f64::NEG_INFINITY, 0.0, f64::NEG_INFINITY],
            vec![f64::INFINITY, 0.5, f64::INFINITY],
        );
        let fit = least_squares(
            exp_residual(&t, &y),
            &[1.0, 0.1, 0.0],
            &b,
            &LsqOptions::default(),
        )
        .unwrap();
        assert!((fit.theta[1] - 0.5).abs() < 1e-7, "{:?}", fit.theta);
        assert_eq!(fit.active, vec![0, 1, 0]);
        // Linear least squares for (p0, p2) at p1 = 0.5.
        let a = DMatrix::from_fn(
            t.len(),
            2,
            |i, j| if j == 0 { (-0.5 * t[i]).exp() } else { 1.0 },
        );
        let c = a
            .clone()
            .svd(true, true)
            .solve(&DVector::from_column_slice(&y), 1e-14)
            .unwrap();
        assert!(
            (fit.theta[0] - c[0]).abs() < 1e-6 && (fit.theta[2] - c[1]).abs() < 1e-6,
            "{:?} vs {c}",
            fit.theta
        );
        // The gradient pushes against the bound (g_1 < 0 for an upper bound).
        let g = fit
            .jacobian
            .tr_mul(&DVector::from_column_slice(&fit.residuals));
        assert!(g[1] < 0.0 && g[0].abs() < 1e-6 && g[2].abs() < 1e-6, "{g}");
    }

    #[test]
    fn start_on_bound_and_lower_bound_active() {
        // min (x0 - 2)^2 + (x1 + 1)^2 with x0 in [-1, 1], x1 >= 0: solution (1, 0).
        let r = |p: &[f64]| vec![p[0] - 2.0, p[1] + 1.0];
        let b = Bounds::new(vec![-1.0, 0.0], vec![1.0, f64::INFINITY]);
        let fit = least_squares(r, &[1.0, 0.0], &b, &LsqOptions::default()).unwrap();
        assert!(
            (fit.theta[0] - 1.0).abs() < 1e-7 && fit.theta[1].abs() < 1e-7,
            "{:?}",
            fit.theta
        );
        assert_eq!(fit.active, vec![1, -1]);
    }

    #[test]
    fn rosenbrock_with_user_jacobian() {
        let r = |p: &[f64]| vec![10.0 * (p[1] - p[0] * p[0]), 1.0 - p[0]];
        let j = |p: &[f64]| DMatrix::from_row_slice(2, 2, &[-20.0 * p[0], 10.0, -1.0, 0.0]);
        let fit = least_squares_with_jacobian(
            r,
            j,
            &[-1.2, 1.0],
            &Bounds::none(2),
            &LsqOptions::default(),
        )
        .unwrap();
        assert!((fit.theta[0] - 1.0).abs() < 1e-8 && (fit.theta[1] - 1.0).abs() < 1e-8);
        // Bounded: x0 <= 0.5 gives the constrained minimum (0.5, 0.25).
        let b = Bounds::new(vec![f64::NEG_INFINITY; 2], vec![0.5, f64::INFINITY]);
        let fit =
            least_squares_with_jacobian(r, j, &[-1.2, 1.0], &b, &LsqOptions::default()).unwrap();
        assert!(
            (fit.theta[0] - 0.5).abs() < 1e-8 && (fit.theta[1] - 0.25).abs() < 1e-8,
            "{:?}",
            fit.theta
        );
    }

    #[test]
    fn non_finite_trial_steps_are_rejected_not_fatal() {
        // ln(p) is NaN for p < 0: the Gauss-Newton step from p = 4 with a large initial
        // trust region (p - 24) lands there.
        let calls = std::cell::Cell::new(0usize);
        let nan_calls = std::cell::Cell::new(0usize);
        let r = |p: &[f64]| {
            calls.set(calls.get() + 1);
            if p[0] < 0.0 {
                nan_calls.set(nan_calls.get() + 1);
            }
            vec![p[0].ln() - 0.01f64.ln()]
        };
        let opts = LsqOptions {
            initial_radius_factor: 100.0,
            ..LsqOptions::default()
        };
        let fit = least_squares(r, &[4.0], &Bounds::none(1), &opts).unwrap();
        assert!((fit.theta[0] - 0.01).abs() < 1e-8, "{:?}", fit.theta);
        assert_eq!(fit.n_eval, calls.get());
        assert!(
            nan_calls.get() > 0,
            "test did not exercise the non-finite path"
        );
    }

    #[test]
    fn a_cancelled_search_stops_at_its_next_evaluation() {
        use crate::numerics::cancel::{with_token, CancelToken};
        let (t, y) = exp_data();
        let token = CancelToken::new();
        let calls = std::cell::Cell::new(0usize);
        let mut inner = exp_residual(&t, &y);
        let r = |th: &[f64]| {
            calls.set(calls.get() + 1);
            if calls.get() == 7 {
                token.cancel(); // as another thread would, during the 7th evaluation
            }
            inner(th)
        };
        let e = with_token(&token, || {
            least_squares(
                r,
                &[1.0, 0.1, 0.0],
                &Bounds::none(3),
                &LsqOptions::default(),
            )
        })
        .unwrap_err();
        // no residual evaluation after the one that saw the request
        assert!(
            matches!(e, LsqError::Cancelled { evaluations } if evaluations >= 7),
            "{e:?}"
        );
        assert_eq!(calls.get(), 7);
        // without a token (or outside its scope) the same search runs to its end
        let fit = least_squares(
            exp_residual(&t, &y),
            &[1.0, 0.1, 0.0],
            &Bounds::none(3),
            &LsqOptions::default(),
        )
        .unwrap();
        assert!(fit.termination.converged());
    }

    #[test]
    fn max_evaluations_is_reported() {
        let (t, y) = exp_data();
        let opts = LsqOptions {
            max_evaluations: Some(8),
            ..LsqOptions::default()
        };
        let fit = least_squares(
            exp_residual(&t, &y),
            &[1.0, 0.1, 0.0],
            &Bounds::none(3),
            &opts,
        )
        .unwrap();
        assert_eq!(fit.termination, Termination::MaxEvaluations);
        assert!(!fit.termination.converged());
        assert!(fit.n_eval <= 8 + 3, "{}", fit.n_eval);
    }

    #[test]
    fn typed_errors() {
        let r = |p: &[f64]| vec![p[0]];
        let o = LsqOptions::default();
        assert_eq!(
            least_squares(r, &[], &Bounds::none(0), &o),
            Err(LsqError::NoParameters)
        );
        assert!(matches!(
            least_squares(r, &[2.0], &Bounds::new(vec![0.0], vec![1.0]), &o),
            Err(LsqError::InfeasibleStart { index: 0, .. })
        ));
        assert!(matches!(
            least_squares(r, &[0.5], &Bounds::new(vec![1.0], vec![0.0]), &o),
            Err(LsqError::InvalidBounds { index: 0, .. })
        ));
        assert!(matches!(
            least_squares(r, &[0.5], &Bounds::none(2), &o),
            Err(LsqError::Length { .. })
        ));
        assert!(matches!(
            least_squares(|_: &[f64]| vec![f64::NAN], &[0.5], &Bounds::none(1), &o),
            Err(LsqError::NonFiniteStart { index: 0, .. })
        ));
        assert_eq!(
            least_squares(|_: &[f64]| vec![], &[0.5], &Bounds::none(1), &o),
            Err(LsqError::NoResiduals)
        );
        let bad = LsqOptions {
            ftol: -1.0,
            ..LsqOptions::default()
        };
        assert!(matches!(
            least_squares(r, &[0.5], &Bounds::none(1), &bad),
            Err(LsqError::InvalidOption { name: "ftol", .. })
        ));
        let bad = LsqOptions {
            x_scale: XScale::Fixed(vec![0.0]),
            ..LsqOptions::default()
        };
        assert!(matches!(
            least_squares(r, &[0.5], &Bounds::none(1), &bad),
            Err(LsqError::InvalidOption {
                name: "x_scale",
                ..
            })
        ));
        let mut k = 0;
        let changing = |p: &[f64]| {
            k += 1;
            vec![p[0]; k]
        };
        assert!(matches!(
            least_squares(changing, &[0.5], &Bounds::none(1), &o),
            Err(LsqError::ResidualLength { .. })
        ));
        let j = |_: &[f64]| DMatrix::zeros(2, 1);
        assert!(matches!(
            least_squares_with_jacobian(r, j, &[0.5], &Bounds::none(1), &o),
            Err(LsqError::JacobianShape { .. })
        ));
    }

    #[test]
    fn stats_of_straight_line_match_textbook_formulas() {
        // y = a + b x: var(b) = sigma^2 / Sxx, var(a) = sigma^2 (1/n + xbar^2/Sxx).
        let x = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let y = [0.1, 0.9, 2.2, 2.9, 4.1, 4.8];
        let r = |p: &[f64]| x.iter().zip(&y).map(|(x, y)| p[0] + p[1] * x - y).collect();
        let fit = least_squares(r, &[0.0, 0.0], &Bounds::none(2), &LsqOptions::default()).unwrap();
        let st = fit.stats();
        let n = x.len() as f64;
        let xbar = x.iter().sum::<f64>() / n;
        let sxx: f64 = x.iter().map(|x| (x - xbar).powi(2)).sum();
        let rss: f64 = fit.residuals.iter().map(|r| r * r).sum();
        let s2 = rss / (n - 2.0);
        assert_eq!(st.dof, 4);
        assert!((st.sigma2 - s2).abs() < 1e-12);
        // Forward-difference Jacobian: about 8 correct digits.
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6 * b.abs();
        assert!(close(st.std_err[1], (s2 / sxx).sqrt()));
        assert!(close(
            st.std_err[0],
            (s2 * (1.0 / n + xbar * xbar / sxx)).sqrt()
        ));
        let cab = -xbar * s2 / sxx;
        assert!(close(
            st.correlation[(0, 1)],
            cab / (st.std_err[0] * st.std_err[1])
        ));
        assert_eq!(st.rank, 2);
        assert!(st.condition().is_finite());
    }

    #[test]
    fn stats_flag_unidentifiable_parameters() {
        // y = (a + b) x: only a + b is identifiable; c is separate.
        let x = [1.0, 2.0, 3.0, 4.0];
        let jm = DMatrix::from_fn(4, 3, |i, j| if j < 2 { x[i] } else { 1.0 });
        let st = param_stats(&jm, &[0.1, -0.1, 0.05, 0.0]);
        assert_eq!(st.rank, 2);
        assert!(st.std_err[0].is_infinite() && st.std_err[1].is_infinite());
        assert!(st.std_err[2].is_finite());
        assert!(st.condition().is_infinite());
    }
}
