//! Poles, transmission zeros and DC gains of a linear model.
//!
//! **Poles** are the eigenvalues of A (balanced, then the real Schur form of nalgebra).
//!
//! **Zeros** are the values s where the Rosenbrock system matrix
//! `S(s) = [[A - sI, B], [C, D]]` drops below its normal rank. nalgebra has no QZ algorithm
//! (faer 0.24 has one, but is a heavy dependency for a 3x3 pencil), so the pencil is reduced to
//! a standard eigenproblem by the orthogonal deflation of Emami-Naeini & Van Dooren (1982),
//! "Computation of zeros of linear multivariable systems", Automatica 18(4):
//!
//! 1. *reduce*: compress the rows of D by an SVD (`U^T D = [0; D+]`); if D has full row rank,
//!    stop. Otherwise compress the columns of the rows `C1` that have no feedthrough
//!    (`C1 V = [0, C12]`, rank mu); the mu state directions seen by `C1` carry infinite zeros
//!    and are eliminated: the zeros of S are those of the smaller system
//!    `(A11, B1, [A21; C21], [B2; D+])` with n - mu states. Identically zero rows are dropped
//!    (they lower the normal rank only).
//! 2. apply *reduce* to the dual (transposed) system, after which D is square and invertible;
//! 3. the zeros are the eigenvalues of `A - B D^-1 C` (of A when no input/output is left).
//!
//! Every rank decision uses singular values against `tol` (absolute), by default
//! [`ZeroOptions::rel_tol`] times the Frobenius norm of the (scaled) system matrix, so infinite
//! zeros are removed structurally and never show up as large finite ones.
//!
//! The zeros of the pencil are the *invariant* zeros; they include the decoupling zeros
//! (uncontrollable or unobservable modes, e.g. the EGR actuator poles seen from u_vgt).
//! [`transmission_zeros`] first removes those by the orthogonal controllability and
//! observability staircase (Varga's algorithm) and returns the zeros of the minimal
//! realization: the zeros of the transfer function G(s).
//!
//! For a [`LinearModel`] the system is first scaled by the state, input and output scales
//! (zeros and poles are invariant under such diagonal scaling) so that the tolerances are
//! meaningful. Channels are named `"u_vgt->W_c"`.
//!
//! The square MIMO system of the EGR/VGT control problem is chosen by the caller
//! ([`mimo_zeros`] with inputs and outputs); [`MIMO_INPUTS`] and [`MIMO_OUTPUTS`] are the
//! defaults offered to front ends: (u_delta, u_egr, u_vgt) -> (M_e, x_egr, lambda_O). For a
//! non-square selection the same functions return the zeros where the system loses its
//! normal rank ([`Zeros::normal_rank`]).

use super::linearize::{Kink, LinearModel};
pub use nalgebra::Complex;
use nalgebra::{DMatrix, DVector};

/// Default inputs of the square MIMO system: fuel, EGR valve, VGT position.
pub const MIMO_INPUTS: [&str; 3] = ["u_delta", "u_egr", "u_vgt"];
/// Default outputs of the square MIMO system: torque, EGR fraction, oxygen-to-fuel ratio.
pub const MIMO_OUTPUTS: [&str; 3] = ["M_e", "x_egr", "lambda_O"];

/// A state-space system (A, B, C, D).
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace {
    /// n x n.
    pub a: DMatrix<f64>,
    /// n x m.
    pub b: DMatrix<f64>,
    /// p x n.
    pub c: DMatrix<f64>,
    /// p x m.
    pub d: DMatrix<f64>,
}

/// Why poles, zeros or gains could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ZerosError {
    /// Matrix dimensions do not fit.
    #[error("dimension mismatch: {0}")]
    Dimensions(String),
    /// A matrix entry is NaN or infinite.
    #[error("non-finite entry in {0}")]
    NonFinite(&'static str),
    /// An input name is not an input of the linear model.
    #[error("unknown input {name:?}; known: {known}")]
    UnknownInput {
        /// The name asked for.
        name: String,
        /// Known inputs.
        known: String,
    },
    /// An output name is not an output of the linear model.
    #[error("unknown output {name:?}; known (linearize with it among the outputs): {known}")]
    UnknownOutput {
        /// The name asked for.
        name: String,
        /// Known outputs.
        known: String,
    },
    /// A channel is not written `input->output`.
    #[error("channel {0:?} is not of the form input->output (e.g. u_vgt->W_c)")]
    BadChannel(String),
    /// An eigenvalue or singular value iteration did not converge.
    #[error("{0} did not converge")]
    NoConvergence(&'static str),
    /// A is singular: the DC gain is infinite (integrator or marginally stable mode).
    #[error("A is singular (an eigenvalue at 0): no finite DC gain")]
    Singular,
    /// The channel passes a kink of the model at the operating point.
    #[error("the operating point sits at a kink on this channel: {}", .0.iter().map(|k| k.to_string()).collect::<Vec<_>>().join("; "))]
    Kink(Vec<Kink>),
}

/// Options of the zero computation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZeroOptions {
    /// Rank tolerance relative to the Frobenius norm of the system matrix (default 1e-9;
    /// linearized entries are accurate to about that).
    pub rel_tol: f64,
}

impl Default for ZeroOptions {
    fn default() -> Self {
        Self { rel_tol: 1e-9 }
    }
}

/// Zeros of a system.
#[derive(Debug, Clone, PartialEq)]
pub struct Zeros {
    /// Finite zeros [1/s], sorted by decreasing real part (right half plane first), then
    /// increasing imaginary part.
    pub finite: Vec<Complex<f64>>,
    /// Number of states of the realization analysed (after removing uncontrollable and
    /// unobservable modes for transmission zeros).
    pub order: usize,
    /// Normal rank of the transfer matrix G(s).
    pub normal_rank: usize,
}

impl Zeros {
    /// Zeros with positive real part (beyond 1e-9 (1 + |z|), to ignore round-off at 0).
    pub fn rhp(&self) -> Vec<Complex<f64>> {
        self.finite
            .iter()
            .copied()
            .filter(|z| z.re > 1e-9 * (1.0 + z.norm()))
            .collect()
    }

    /// Whether there is a right-half-plane zero (non-minimum phase).
    pub fn has_rhp(&self) -> bool {
        !self.rhp().is_empty()
    }
}

impl StateSpace {
    /// A system; dimensions are checked.
    pub fn new(
        a: DMatrix<f64>,
        b: DMatrix<f64>,
        c: DMatrix<f64>,
        d: DMatrix<f64>,
    ) -> Result<Self, ZerosError> {
        let n = a.nrows();
        let dim = |ok: bool, what: String| {
            if ok {
                Ok(())
            } else {
                Err(ZerosError::Dimensions(what))
            }
        };
        dim(a.ncols() == n, format!("A is {}x{}", n, a.ncols()))?;
        dim(b.nrows() == n, format!("B has {} rows, A {}", b.nrows(), n))?;
        dim(
            c.ncols() == n,
            format!("C has {} columns, A {}", c.ncols(), n),
        )?;
        dim(
            d.nrows() == c.nrows() && d.ncols() == b.ncols(),
            format!(
                "D is {}x{}, expected {}x{}",
                d.nrows(),
                d.ncols(),
                c.nrows(),
                b.ncols()
            ),
        )?;
        for (m, name) in [(&a, "A"), (&b, "B"), (&c, "C"), (&d, "D")] {
            if m.iter().any(|v| !v.is_finite()) {
                return Err(ZerosError::NonFinite(name));
            }
        }
        Ok(Self { a, b, c, d })
    }

    /// Number of states.
    pub fn n(&self) -> usize {
        self.a.nrows()
    }

    /// Frobenius norm of the system matrix [[A, B], [C, D]].
    pub fn norm(&self) -> f64 {
        (self.a.norm_squared()
            + self.b.norm_squared()
            + self.c.norm_squared()
            + self.d.norm_squared())
        .sqrt()
    }

    /// The system with scaled variables x = Sx x~, u = Su u~, y = Sy y~.
    pub fn scaled(&self, sx: &[f64], su: &[f64], sy: &[f64]) -> StateSpace {
        let (n, m, p) = (self.n(), self.b.ncols(), self.c.nrows());
        StateSpace {
            a: DMatrix::from_fn(n, n, |i, j| self.a[(i, j)] * sx[j] / sx[i]),
            b: DMatrix::from_fn(n, m, |i, k| self.b[(i, k)] * su[k] / sx[i]),
            c: DMatrix::from_fn(p, n, |o, j| self.c[(o, j)] * sx[j] / sy[o]),
            d: DMatrix::from_fn(p, m, |o, k| self.d[(o, k)] * su[k] / sy[o]),
        }
    }

    fn dual(&self) -> StateSpace {
        StateSpace {
            a: self.a.transpose(),
            b: self.c.transpose(),
            c: self.b.transpose(),
            d: self.d.transpose(),
        }
    }
}

/// Eigenvalues of a square matrix: diagonal balancing (Parlett & Reinsch), then the real
/// Schur form. Sorted by decreasing real part, then increasing imaginary part.
pub fn eigenvalues(a: &DMatrix<f64>) -> Result<Vec<Complex<f64>>, ZerosError> {
    if a.nrows() != a.ncols() {
        return Err(ZerosError::Dimensions(format!(
            "eigenvalues of a {}x{} matrix",
            a.nrows(),
            a.ncols()
        )));
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(ZerosError::NonFinite("A"));
    }
    if a.nrows() == 0 {
        return Ok(Vec::new());
    }
    let bal = balance(a);
    let schur = nalgebra::linalg::Schur::try_new(bal, f64::EPSILON, 100_000)
        .ok_or(ZerosError::NoConvergence("Schur decomposition"))?;
    let mut ev: Vec<Complex<f64>> = schur.complex_eigenvalues().iter().copied().collect();
    sort_complex(&mut ev);
    Ok(ev)
}

fn sort_complex(v: &mut [Complex<f64>]) {
    v.sort_by(|x, y| y.re.total_cmp(&x.re).then(x.im.total_cmp(&y.im)));
}

/// Diagonal similarity balancing by powers of two (Parlett & Reinsch 1969; as LAPACK gebal
/// without permutations): row and column norms of the off-diagonal part made comparable.
fn balance(a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let mut m = a.clone();
    let radix: f64 = 2.0;
    for _sweep in 0..100 {
        let mut done = true;
        for i in 0..n {
            let mut c = 0.0;
            let mut r = 0.0;
            for j in 0..n {
                if j != i {
                    c += m[(j, i)].abs();
                    r += m[(i, j)].abs();
                }
            }
            if c == 0.0 || r == 0.0 {
                continue;
            }
            let s = c + r;
            let mut f = 1.0;
            let mut g = r / radix;
            while c < g {
                f *= radix;
                c *= radix * radix;
            }
            g = r * radix;
            while c > g {
                f /= radix;
                c /= radix * radix;
            }
            if (c + r) / f < 0.95 * s {
                done = false;
                for j in 0..n {
                    m[(i, j)] /= f;
                    m[(j, i)] *= f;
                }
            }
        }
        if done {
            break;
        }
    }
    m
}

/// Orthogonal p x p matrix U whose first `rank` columns span the column space of `m`
/// (p x q), with the rank decided against `tol`.
fn left_basis(m: &DMatrix<f64>, tol: f64) -> Result<(DMatrix<f64>, usize), ZerosError> {
    let p = m.nrows();
    if p == 0 {
        return Ok((DMatrix::zeros(0, 0), 0));
    }
    // pad with p zero columns so that the SVD returns a full U
    let mut padded = DMatrix::zeros(p, m.ncols() + p);
    padded.view_mut((0, 0), (p, m.ncols())).copy_from(m);
    let svd = padded
        .try_svd(true, false, f64::EPSILON, 100_000)
        .ok_or(ZerosError::NoConvergence("SVD"))?;
    let rank = svd.singular_values.iter().filter(|s| **s > tol).count();
    Ok((svd.u.expect("requested"), rank))
}

/// Orthogonal n x n matrix V whose first `rank` columns span the row space of `m` (q x n).
fn right_basis(m: &DMatrix<f64>, tol: f64) -> Result<(DMatrix<f64>, usize), ZerosError> {
    let (u, r) = left_basis(&m.transpose(), tol)?;
    Ok((u, r))
}

/// Stack two matrices vertically.
fn vstack(top: &DMatrix<f64>, bottom: &DMatrix<f64>) -> DMatrix<f64> {
    let cols = top.ncols().max(bottom.ncols());
    let mut out = DMatrix::zeros(top.nrows() + bottom.nrows(), cols);
    if top.nrows() > 0 {
        out.view_mut((0, 0), top.shape()).copy_from(top);
    }
    if bottom.nrows() > 0 {
        out.view_mut((top.nrows(), 0), bottom.shape())
            .copy_from(bottom);
    }
    out
}

/// One pass of the Emami-Naeini & Van Dooren reduction: returns a system with the same finite
/// zeros whose D has full row rank, and the number of state directions eliminated.
fn reduce(mut s: StateSpace, tol: f64) -> Result<(StateSpace, usize), ZerosError> {
    let mut eliminated = 0;
    loop {
        let n = s.n();
        let p = s.c.nrows();
        if p == 0 {
            return Ok((s, eliminated));
        }
        let (u, rho) = left_basis(&s.d, tol)?;
        if rho == p {
            return Ok((s, eliminated));
        }
        let ut = u.transpose();
        let cu = &ut * &s.c;
        let du = &ut * &s.d;
        let c2 = cu.rows(0, rho).into_owned();
        let d2 = du.rows(0, rho).into_owned();
        let c1 = cu.rows(rho, p - rho).into_owned();
        let (v, mu) = if n == 0 {
            (DMatrix::zeros(0, 0), 0)
        } else {
            right_basis(&c1, tol)?
        };
        if mu == 0 {
            // the rows without feedthrough are zero: drop them (normal rank only)
            s.c = c2;
            s.d = d2;
            return Ok((s, eliminated));
        }
        let nu = n - mu;
        // V' = [null space of C1 (nu), row space of C1 (mu)]
        let mut vp = DMatrix::zeros(n, n);
        vp.view_mut((0, 0), (n, nu)).copy_from(&v.columns(mu, nu));
        vp.view_mut((0, nu), (n, mu)).copy_from(&v.columns(0, mu));
        let at = vp.transpose() * &s.a * &vp;
        let bt = vp.transpose() * &s.b;
        let c2t = &c2 * &vp;
        let a11 = at.view((0, 0), (nu, nu)).into_owned();
        let a21 = at.view((nu, 0), (mu, nu)).into_owned();
        let b1 = bt.rows(0, nu).into_owned();
        let b2 = bt.rows(nu, mu).into_owned();
        let c21 = c2t.columns(0, nu).into_owned();
        s = StateSpace {
            a: a11,
            b: b1,
            c: vstack(&a21, &c21),
            d: vstack(&b2, &d2),
        };
        eliminated += mu;
    }
}

/// Invariant zeros of `sys` (zeros of the Rosenbrock pencil, including decoupling zeros) and
/// the normal rank of its transfer matrix; rank decisions against the absolute `tol`.
pub fn invariant_zeros(sys: &StateSpace, tol: f64) -> Result<Zeros, ZerosError> {
    let n0 = sys.n();
    let (r1, e1) = reduce(sys.clone(), tol)?;
    let (r2d, e2) = reduce(r1.dual(), tol)?;
    let r = r2d.dual();
    let (nf, mf, pf) = (r.n(), r.b.ncols(), r.c.nrows());
    if mf != pf {
        return Err(ZerosError::Dimensions(format!(
            "reduced feedthrough is {pf}x{mf}, not square (rank tolerance {tol:e})"
        )));
    }
    // rank S(s) = nf + mf + eliminated; normal rank of G = rank S - n0
    let normal_rank = nf + mf + e1 + e2 - n0;
    let mut finite = if nf == 0 {
        Vec::new()
    } else if mf == 0 {
        eigenvalues(&r.a)?
    } else {
        let lu = r.d.clone().lu();
        let x = lu
            .solve(&r.c)
            .ok_or(ZerosError::Dimensions("reduced D is singular".into()))?;
        eigenvalues(&(&r.a - &r.b * x))?
    };
    sort_complex(&mut finite);
    Ok(Zeros {
        finite,
        order: n0,
        normal_rank,
    })
}

/// Controllable part of (A, B, C) by the orthogonal staircase (Varga 1981): returns the
/// controllable subsystem.
fn controllable_part(s: &StateSpace, tol: f64) -> Result<StateSpace, ZerosError> {
    let n = s.n();
    let mut a = s.a.clone();
    let mut b = s.b.clone();
    let mut c = s.c.clone();
    let mut start = 0;
    let mut prev = 0;
    while start < n {
        let g = if start == 0 {
            b.clone()
        } else {
            a.view((start, prev), (n - start, start - prev))
                .into_owned()
        };
        let (u, r) = left_basis(&g, tol)?;
        if r == 0 {
            break;
        }
        // apply Q = diag(I_start, U): A <- Q^T A Q, B <- Q^T B, C <- C Q
        let k = n - start;
        let rows = u.transpose() * a.view((start, 0), (k, n));
        a.view_mut((start, 0), (k, n)).copy_from(&rows);
        let cols = a.view((0, start), (n, k)) * &u;
        a.view_mut((0, start), (n, k)).copy_from(&cols);
        let brow = u.transpose() * b.view((start, 0), (k, b.ncols()));
        b.view_mut((start, 0), (k, b.ncols())).copy_from(&brow);
        let ccol = c.view((0, start), (c.nrows(), k)) * &u;
        c.view_mut((0, start), (c.nrows(), k)).copy_from(&ccol);
        prev = start;
        start += r;
    }
    let nc = start;
    Ok(StateSpace {
        a: a.view((0, 0), (nc, nc)).into_owned(),
        b: b.rows(0, nc).into_owned(),
        c: c.columns(0, nc).into_owned(),
        d: s.d.clone(),
    })
}

/// Minimal realization: the controllable and observable part (orthogonal staircases), with
/// rank decisions against the absolute `tol`. Same transfer function, no decoupling modes.
pub fn minimal_realization(sys: &StateSpace, tol: f64) -> Result<StateSpace, ZerosError> {
    let ctrl = controllable_part(sys, tol)?;
    Ok(controllable_part(&ctrl.dual(), tol)?.dual())
}

/// Transmission zeros: the invariant zeros of the minimal realization (the zeros of G(s));
/// `order` of the result is the minimal order.
pub fn transmission_zeros(sys: &StateSpace, tol: f64) -> Result<Zeros, ZerosError> {
    invariant_zeros(&minimal_realization(sys, tol)?, tol)
}

/// DC gain `G(0) = D - C A^-1 B` of a system.
pub fn dc_gain(sys: &StateSpace) -> Result<DMatrix<f64>, ZerosError> {
    if sys.n() == 0 {
        return Ok(sys.d.clone());
    }
    // refuse (numerically) singular A: smallest |pivot| relative to the norm
    let lu = sys.a.clone().lu();
    let x = lu.solve(&sys.b).ok_or(ZerosError::Singular)?;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(ZerosError::Singular);
    }
    Ok(&sys.d - &sys.c * x)
}

/// A SISO channel of a linear model: its minimal realization's poles, transmission zeros and
/// DC gain.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Input name.
    pub input: String,
    /// Output name.
    pub output: String,
    /// Transmission zeros (of the minimal realization of this channel).
    pub zeros: Zeros,
    /// Poles of the minimal realization [1/s].
    pub poles: Vec<Complex<f64>>,
    /// DC gain in output units per input unit (e.g. kg/s per %).
    pub dc_gain: f64,
}

impl Channel {
    /// Relative degree: minimal order minus the number of finite zeros.
    pub fn relative_degree(&self) -> usize {
        self.zeros.order - self.zeros.finite.len()
    }
}

/// Split `"u_vgt->W_c"` into (input, output).
pub fn parse_channel(s: &str) -> Result<(String, String), ZerosError> {
    match s.split_once("->") {
        Some((i, o)) if !i.trim().is_empty() && !o.trim().is_empty() => {
            Ok((i.trim().to_string(), o.trim().to_string()))
        }
        _ => Err(ZerosError::BadChannel(s.to_string())),
    }
}

fn indices(
    lin: &LinearModel,
    inputs: &[&str],
    outputs: &[&str],
) -> Result<(Vec<usize>, Vec<usize>), ZerosError> {
    let ins = inputs
        .iter()
        .map(|n| {
            lin.input_index(n).ok_or_else(|| ZerosError::UnknownInput {
                name: n.to_string(),
                known: lin.input_names.join(", "),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let outs = outputs
        .iter()
        .map(|n| {
            lin.output_index(n)
                .ok_or_else(|| ZerosError::UnknownOutput {
                    name: n.to_string(),
                    known: lin.output_names.join(", "),
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((ins, outs))
}

/// The scaled subsystem `inputs -> outputs` of a linear model (see the module doc), with the
/// input and output scales used.
pub fn scaled_subsystem(
    lin: &LinearModel,
    inputs: &[&str],
    outputs: &[&str],
) -> Result<(StateSpace, Vec<f64>, Vec<f64>), ZerosError> {
    let (ins, outs) = indices(lin, inputs, outputs)?;
    let n = lin.n_states();
    let b = DMatrix::from_fn(n, ins.len(), |i, k| lin.b[(i, ins[k])]);
    let c = DMatrix::from_fn(outs.len(), n, |o, j| lin.c[(outs[o], j)]);
    let d = DMatrix::from_fn(outs.len(), ins.len(), |o, k| lin.d[(outs[o], ins[k])]);
    let sys = StateSpace::new(lin.a.clone(), b, c, d)?;
    let su: Vec<f64> = ins.iter().map(|&k| lin.input_scales[k]).collect();
    let sy: Vec<f64> = outs.iter().map(|&o| lin.output_scales[o]).collect();
    Ok((sys.scaled(&lin.state_scales, &su, &sy), su, sy))
}

fn check_kinks(lin: &LinearModel, inputs: &[&str], outputs: &[&str]) -> Result<(), ZerosError> {
    let mut hit: Vec<Kink> = Vec::new();
    for i in inputs {
        for o in outputs {
            for k in lin.kinks_affecting(i, o) {
                if !hit.contains(k) {
                    hit.push(k.clone());
                }
            }
        }
    }
    if hit.is_empty() {
        Ok(())
    } else {
        Err(ZerosError::Kink(hit))
    }
}

/// Poles of a linear model: eigenvalues of A [1/s].
pub fn poles(lin: &LinearModel) -> Result<Vec<Complex<f64>>, ZerosError> {
    let n = lin.n_states();
    let s = &lin.state_scales;
    eigenvalues(&DMatrix::from_fn(n, n, |i, j| lin.a[(i, j)] * s[j] / s[i]))
}

/// Transmission zeros, poles and DC gain of the SISO channel `input -> output`. Fails with
/// [`ZerosError::Kink`] when a kink of the model lies on the channel.
pub fn siso(
    lin: &LinearModel,
    input: &str,
    output: &str,
    opts: &ZeroOptions,
) -> Result<Channel, ZerosError> {
    check_kinks(lin, &[input], &[output])?;
    let (sys, su, sy) = scaled_subsystem(lin, &[input], &[output])?;
    let tol = opts.rel_tol * sys.norm();
    let min = minimal_realization(&sys, tol)?;
    let zeros = invariant_zeros(&min, tol)?;
    let poles = eigenvalues(&min.a)?;
    // the minimal realization has the same G(0), and no unrelated mode can make A singular
    let g = dc_gain(&min)?;
    Ok(Channel {
        input: input.to_string(),
        output: output.to_string(),
        zeros,
        poles,
        dc_gain: g[(0, 0)] * sy[0] / su[0],
    })
}

/// [`siso`] for a channel written `"input->output"`.
pub fn channel(lin: &LinearModel, spec: &str, opts: &ZeroOptions) -> Result<Channel, ZerosError> {
    let (i, o) = parse_channel(spec)?;
    siso(lin, &i, &o, opts)
}

/// Every SISO channel (inputs x outputs) of a linear model, each with its own result.
pub fn all_channels(lin: &LinearModel, opts: &ZeroOptions) -> Vec<Result<Channel, ZerosError>> {
    let mut out = Vec::new();
    for i in &lin.input_names {
        for o in &lin.output_names {
            out.push(siso(lin, i, o, opts));
        }
    }
    out
}

/// Transmission zeros of the MIMO subsystem `inputs -> outputs` (square: the zeros where
/// det G(s) = 0; otherwise where G loses its normal rank). Fails with [`ZerosError::Kink`]
/// when a kink lies on any of its channels.
pub fn mimo_zeros(
    lin: &LinearModel,
    inputs: &[&str],
    outputs: &[&str],
    opts: &ZeroOptions,
) -> Result<Zeros, ZerosError> {
    check_kinks(lin, inputs, outputs)?;
    let (sys, _, _) = scaled_subsystem(lin, inputs, outputs)?;
    let tol = opts.rel_tol * sys.norm();
    transmission_zeros(&sys, tol)
}

/// DC-gain matrix `-C A^-1 B + D` of the whole linear model (outputs x inputs, in output units
/// per input unit).
pub fn dc_gain_matrix(lin: &LinearModel) -> Result<DMatrix<f64>, ZerosError> {
    let ins: Vec<&str> = lin.input_names.iter().map(|s| s.as_str()).collect();
    let outs: Vec<&str> = lin.output_names.iter().map(|s| s.as_str()).collect();
    let (sys, su, sy) = scaled_subsystem(lin, &ins, &outs)?;
    let g = dc_gain(&sys)?;
    Ok(DMatrix::from_fn(g.nrows(), g.ncols(), |o, k| {
        g[(o, k)] * sy[o] / su[k]
    }))
}

/// Frequency response G(j omega) of a system at `omega` [rad/s] (for checks and plots).
pub fn frequency_response(
    sys: &StateSpace,
    omega: f64,
) -> Result<DMatrix<Complex<f64>>, ZerosError> {
    let n = sys.n();
    let s = Complex::new(0.0, omega);
    let m = DMatrix::from_fn(n, n, |i, j| {
        let v = Complex::new(-sys.a[(i, j)], 0.0);
        if i == j {
            v + s
        } else {
            v
        }
    });
    let bc = sys.b.map(|v| Complex::new(v, 0.0));
    let x = m.lu().solve(&bc).ok_or(ZerosError::Singular)?;
    let cc = sys.c.map(|v| Complex::new(v, 0.0));
    Ok(sys.d.map(|v| Complex::new(v, 0.0)) + cc * x)
}

/// Smallest singular value of the Rosenbrock matrix S(z) relative to its largest: 0 at an
/// invariant zero of a square system (an independent check of computed zeros).
pub fn rosenbrock_rank_gap(sys: &StateSpace, z: Complex<f64>) -> f64 {
    let (n, m, p) = (sys.n(), sys.b.ncols(), sys.c.nrows());
    let mut s = DMatrix::<Complex<f64>>::zeros(n + p, n + m);
    for i in 0..n {
        for j in 0..n {
            s[(i, j)] = Complex::new(sys.a[(i, j)], 0.0) - if i == j { z } else { 0.0.into() };
        }
        for k in 0..m {
            s[(i, n + k)] = sys.b[(i, k)].into();
        }
    }
    for o in 0..p {
        for j in 0..n {
            s[(n + o, j)] = sys.c[(o, j)].into();
        }
        for k in 0..m {
            s[(n + o, n + k)] = sys.d[(o, k)].into();
        }
    }
    let sv: DVector<f64> = s.singular_values();
    let max = sv.max();
    if max == 0.0 {
        0.0
    } else {
        sv.min() / max
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn balancing_keeps_the_eigenvalues_of_a_badly_scaled_matrix() {
        // diag(1e5, 1, 1e-4) similarity of a matrix with eigenvalues -1, -2, -3
        let v = DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 1.0]);
        let l = DMatrix::from_diagonal(&DVector::from_vec(vec![-1.0, -2.0, -3.0]));
        let a = &v * l * v.clone().try_inverse().unwrap();
        let s = [1e5, 1.0, 1e-4];
        let bad = DMatrix::from_fn(3, 3, |i, j| a[(i, j)] * s[j] / s[i]);
        let b = balance(&bad);
        let ev = eigenvalues(&bad).unwrap();
        for (z, want) in ev.iter().zip([-1.0, -2.0, -3.0]) {
            assert!((z.re - want).abs() < 1e-9 && z.im.abs() < 1e-9, "{ev:?}");
        }
        // balancing brings the off-diagonal norms together
        let spread = |m: &DMatrix<f64>| {
            let v: Vec<f64> = m.iter().filter(|v| **v != 0.0).map(|v| v.abs()).collect();
            v.iter().cloned().fold(0.0, f64::max) / v.iter().cloned().fold(f64::INFINITY, f64::min)
        };
        assert!(spread(&b) < 1e-3 * spread(&bad));
    }

    #[test]
    fn left_basis_is_orthogonal_and_spans_the_columns() {
        let m = DMatrix::from_row_slice(3, 2, &[1.0, 2.0, 2.0, 4.0, 0.0, 0.0]);
        let (u, r) = left_basis(&m, 1e-12).unwrap();
        assert_eq!(r, 1);
        assert!((u.transpose() * &u - DMatrix::identity(3, 3)).norm() < 1e-14);
        // the columns of m have no component outside the first column of U
        let rest = u.columns(1, 2).transpose() * &m;
        assert!(rest.norm() < 1e-13);
        let (v, r) = right_basis(&m.transpose(), 1e-12).unwrap();
        assert_eq!((v.nrows(), r), (3, 1));
    }

    #[test]
    fn rhp_classification_ignores_round_off_at_the_origin() {
        let z = Zeros {
            finite: vec![Complex::new(1e-14, 0.0), Complex::new(-3.0, 1.0)],
            order: 2,
            normal_rank: 1,
        };
        assert!(!z.has_rhp());
        let z = Zeros {
            finite: vec![Complex::new(1e-3, 0.0)],
            order: 1,
            normal_rank: 1,
        };
        assert_eq!(z.rhp().len(), 1);
    }

    #[test]
    fn channels_parse() {
        assert_eq!(
            parse_channel(" u_egr -> p_im ").unwrap(),
            ("u_egr".to_string(), "p_im".to_string())
        );
        assert!(parse_channel("->p_im").is_err());
    }
}
