//! The exponential Rosenbrock method exprb32 of M. Hochbruck, A. Ostermann and J. Schweitzer,
//! "Exponential Rosenbrock-type methods", SIAM J. Numer. Anal. 47 (2009) 786-803 (section 5,
//! the embedded pair of order 3 with the exponential Rosenbrock-Euler method of order 2; also
//! Hochbruck & Ostermann, "Exponential integrators", Acta Numerica 19 (2010) 209-286, Table
//! 2.4), in its non-autonomous form, and the matrix functions phi_1..phi_3 it needs.
//!
//! With J = df/dy and v = df/dt at (t, y), g(t, u) = f(t, u) - J u - v t is the nonlinear
//! remainder, and the method integrates the linear part exactly:
//!
//! ```text
//! A = h J,  F0 = f(t, y)
//! U2 = y + h phi_1(A) F0 + h^2 phi_2(A) v                  (exponential Rosenbrock-Euler)
//! D2 = g(t + h, U2) - g(t, y) = f(t + h, U2) - F0 - J (U2 - y) - h v
//! y_new = U2 + 2 h phi_3(A) D2,   error estimate = 2 h phi_3(A) D2
//! ```
//!
//! (the non-autonomous form is the autonomous method applied to (y, t) with the time as a
//! state: the augmented Jacobian [[J, v], [0, 0]] turns h phi_1 into h phi_1(A) F0 +
//! h^2 phi_2(A) v and leaves the D2 correction on the y rows.) Order 3 needs the exact J and v
//! at every step (Hochbruck, Ostermann & Schweitzer, Theorem 4.3 and Table 5.1); both are
//! computed afresh at every step as for RODAS4 ([`super::rodas`]): J by forward differences,
//! v by the directional difference along the inputs' slopes. On a segment with closed-form lag
//! states the method integrates the other states z, dz/dt = f_z(z, a(t), u(t)), with J = J_zz.
//!
//! phi_0(z) = e^z, phi_{k+1}(z) = (phi_k(z) - 1/k!)/z. The matrix functions are computed by
//! scaling and squaring (Skaflestad & Wright, "The scaling and modified squaring method for
//! matrix functions related to the exponential", Appl. Numer. Math. 59 (2009) 783-799): a
//! truncated Taylor series of phi_3(B) for B = A / 2^s with ||B||_1 <= 1/2, phi_2 = 1/2 + B
//! phi_3, phi_1 = 1 + B phi_2, phi_0 = 1 + B phi_1, then s doublings
//! phi_k(2B) = 2^-k [phi_0(B) phi_k(B) + sum_{j=1..k} phi_j(B) / (k - j)!]. The matrix is first
//! balanced by the state scales (phi(D^-1 A D) = D^-1 phi(A) D), so that its norm measures
//! the dynamics, not the units.

use super::integrator::{Integrator, Interp, LagSegment, Trial};
use super::segment::SegmentInputs;
use super::SimError;
use crate::model::Dynamics;

/// A dense `Z` x `Z` matrix.
pub(crate) type Mat<const Z: usize> = [[f64; Z]; Z];

/// C = A B (plain triple loop with loop bounds fixed at compile time).
#[inline]
fn mul<const Z: usize>(a: &Mat<Z>, b: &Mat<Z>) -> Mat<Z> {
    let mut c = [[0.0; Z]; Z];
    for i in 0..Z {
        for k in 0..Z {
            let aik = a[i][k];
            for j in 0..Z {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

/// The 1-norm (largest absolute column sum).
fn norm1<const Z: usize>(a: &Mat<Z>) -> f64 {
    (0..Z)
        .map(|j| (0..Z).map(|i| a[i][j].abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// phi_1(A), phi_2(A), phi_3(A) by scaling and squaring (module docs); NaN if `A` is not
/// finite. Out of line: its cost per call is measured (`docs/integrator.md`).
#[inline(never)]
pub(crate) fn phi123<const Z: usize>(a: &Mat<Z>) -> [Mat<Z>; 3] {
    let nrm = norm1(a);
    if !nrm.is_finite() {
        return [[[f64::NAN; Z]; Z]; 3];
    }
    // s halvings bring the norm to <= 1/2
    let s = if nrm > 0.5 {
        (nrm / 0.5).log2().ceil().max(0.0) as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let b: Mat<Z> = a.map(|r| r.map(|x| x * scale));
    let bn = nrm * scale;
    // Taylor series phi_3(B) = sum_k B^k / (k + 3)!, truncated after the term k = m: the
    // remainder is at most bn^(m+1) / (m + 4)! (1 + bn + ...) <= 2 bn^(m+1) / (m + 4)!, below
    // 2^-53 / 6 relative to phi_3(0) = 1/6 (m <= 11 for bn <= 1/2)
    let mut m = 0usize;
    let mut term = bn / 24.0; // bn^(m+1) / (m+4)! for m = 0
    while m < 20 && 2.0 * term > f64::EPSILON / 12.0 {
        m += 1;
        term *= bn / (m + 4) as f64;
    }
    // 1 / (k + 3)! for k = 0..=m
    let mut inv_fact = [0.0f64; 21];
    let mut f = 1.0 / 6.0;
    for (k, v) in inv_fact.iter_mut().enumerate() {
        *v = f;
        f /= (k + 4) as f64;
    }
    let diag = |c: f64| -> Mat<Z> {
        let mut d = [[0.0; Z]; Z];
        for (i, r) in d.iter_mut().enumerate() {
            r[i] = c;
        }
        d
    };
    // Horner: P = 1/(m+3)!; P = 1/(k+3)! + B P for k = m-1 .. 0
    let mut p3 = diag(inv_fact[m]);
    for k in (0..m).rev() {
        p3 = mul(&b, &p3);
        for (i, r) in p3.iter_mut().enumerate() {
            r[i] += inv_fact[k];
        }
    }
    let next = |p: &Mat<Z>, c: f64| -> Mat<Z> {
        let mut q = mul(&b, p);
        for (i, r) in q.iter_mut().enumerate() {
            r[i] += c;
        }
        q
    };
    let mut p2 = next(&p3, 0.5);
    let mut p1 = next(&p2, 1.0);
    // phi_0(B) = I + B phi_1(B) at the base only; doubled by squaring (I + C phi_1(C) at a
    // large C = 2^i B loses the decayed components to cancellation, and the doublings amplify
    // that: relative errors 1e-6 at ||C|| ~ 2000 on a stiff non-normal 2 x 2, test)
    let mut p0 = next(&p1, 1.0);
    for doubling in 0..s {
        let (e1, e2, e3) = (mul(&p0, &p1), mul(&p0, &p2), mul(&p0, &p3));
        for i in 0..Z {
            for j in 0..Z {
                let (q1, q2, q3) = (p1[i][j], p2[i][j], p3[i][j]);
                p3[i][j] = 0.125 * (e3[i][j] + 0.5 * q1 + q2 + q3);
                p2[i][j] = 0.25 * (e2[i][j] + q1 + q2);
                p1[i][j] = 0.5 * (e1[i][j] + q1);
            }
        }
        if doubling + 1 < s {
            p0 = mul(&p0, &p0);
        }
    }
    [p1, p2, p3]
}

/// phi_1..phi_3 of h J on the integrated states, balanced by the state scales: the leading
/// `Z` x `Z` block when the lag states are the trailing ones, else the full matrix with the
/// lag rows and columns zero (`mask`).
pub(super) struct PhiBlock<const Z: usize> {
    /// phi_k(D^-1 h J D), k = 1, 2, 3, D = diag(scales).
    phi: [Mat<Z>; 3],
}

impl<const Z: usize> PhiBlock<Z> {
    fn new<const N: usize>(j: &[[f64; N]; N], h: f64, scales: &[f64; N], mask: &[f64; N]) -> Self {
        let a: Mat<Z> = std::array::from_fn(|r| {
            std::array::from_fn(|c| h * j[r][c] * scales[c] / scales[r] * mask[r] * mask[c])
        });
        Self { phi: phi123(&a) }
    }

    /// phi_k(h J) x on the integrated states (0 on the others; `x`'s entries there are ignored
    /// through `mask`).
    #[inline]
    fn apply<const N: usize>(
        &self,
        k: usize,
        x: &[f64; N],
        scales: &[f64; N],
        mask: &[f64; N],
    ) -> [f64; N] {
        let p = &self.phi[k - 1];
        let xs: [f64; Z] = std::array::from_fn(|c| x[c] / scales[c] * mask[c]);
        let mut y = [0.0; N];
        for r in 0..Z {
            let mut acc = 0.0;
            for c in 0..Z {
                acc += p[r][c] * xs[c];
            }
            y[r] = acc * scales[r] * mask[r];
        }
        y
    }
}

/// The continuous extension of an exprb32 step: the same construction at t + tau, tau = theta h
/// (variation of constants with the nonlinear remainder interpolated quadratically, g(t + s) -
/// g(t) ~ (s/h)^2 D2, which is where 2 h phi_3 comes from at tau = h):
///
/// ```text
/// y(t + tau) ~ y + tau phi_1(tau J) F0 + tau^2 phi_2(tau J) v + 2 tau^3 / h^2 phi_3(tau J) D2
/// ```
///
/// Unlike the cubic Hermite interpolation it follows the fast modes inside a long step (exprb32
/// integrates them exactly and takes steps of seconds where the inputs are constant). Costs one
/// evaluation of the phi functions per output sample inside a step.
pub(super) struct ExprbDense<const N: usize> {
    y0: [f64; N],
    h: f64,
    f0: [f64; N],
    v: [f64; N],
    d2: [f64; N],
    j: [[f64; N]; N],
    scales: [f64; N],
    mask: [f64; N],
    nz: usize,
}

impl<const N: usize> ExprbDense<N> {
    /// The state at t + theta h (the lag states are y0's: the caller sets them).
    pub(super) fn eval(&self, theta: f64) -> [f64; N] {
        match self.nz {
            5 => self.eval_block::<5>(theta),
            7 => self.eval_block::<7>(theta),
            9 => self.eval_block::<9>(theta),
            _ => self.eval_block::<N>(theta),
        }
    }

    fn eval_block<const Z: usize>(&self, theta: f64) -> [f64; N] {
        let tau = theta * self.h;
        if tau <= 0.0 {
            return self.y0;
        }
        let (s, m) = (&self.scales, &self.mask);
        let phi = PhiBlock::<Z>::new(&self.j, tau, s, m);
        let a = phi.apply(1, &self.f0, s, m);
        let b = phi.apply(2, &self.v, s, m);
        let c = phi.apply(3, &self.d2, s, m);
        let c3 = 2.0 * tau * theta * theta;
        std::array::from_fn(|i| self.y0[i] + tau * a[i] + tau * tau * b[i] + c3 * c[i])
    }
}

impl<const N: usize, M: Dynamics<N>> Integrator<'_, N, M> {
    /// One trial step of exprb32 (see [`exprb`](self)) with the Jacobian and f_t at (t, y),
    /// computed at the first trial from this point and kept for the retries (or, with
    /// `jac_max_age` > 1, reused for that many accepted steps: an experiment, see
    /// `docs/integrator.md`).
    pub(super) fn step_exprb32(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let lag_seg = std::mem::take(&mut self.lag_seg);
        let trial = self.exprb32_inner(inp, t, h, t_new, f0, &lag_seg);
        self.lag_seg = lag_seg;
        trial
    }

    fn exprb32_inner(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let mut is_lag = [false; N];
        for l in lag_seg {
            is_lag[l.state] = true;
        }
        let reduced = !lag_seg.is_empty();
        let fresh =
            self.jac.is_none() || self.jac_age >= JAC_MAX_AGE || (!reduced && !self.jac_full);
        if fresh {
            let j = self.jacobian(inp, t, f0, &is_lag)?;
            self.jac = Some(j);
            self.jac_full = !reduced;
            self.jac_age = 0;
            let du = inp.rates(t);
            self.ft = self.time_derivative(inp, t, f0, lag_seg, &du)?;
        }
        let nz = super::rosw::block_size(&is_lag);
        match nz {
            Some(5) => self.exprb32_block::<5>(inp, t, h, t_new, f0, lag_seg, &is_lag),
            Some(7) => self.exprb32_block::<7>(inp, t, h, t_new, f0, lag_seg, &is_lag),
            Some(9) => self.exprb32_block::<9>(inp, t, h, t_new, f0, lag_seg, &is_lag),
            _ => self.exprb32_block::<N>(inp, t, h, t_new, f0, lag_seg, &is_lag),
        }
    }

    /// The step with the phi functions on the leading `Z` x `Z` block (`Z` = N: all states,
    /// the lag rows and columns masked).
    #[allow(clippy::too_many_arguments)]
    fn exprb32_block<const Z: usize>(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        is_lag: &[bool; N],
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let y = self.y;
        let scales = self.model.state_scales();
        let mask: [f64; N] = std::array::from_fn(|i| if is_lag[i] { 0.0 } else { 1.0 });
        let j = self.jac.expect("Jacobian set above");
        let v = self.ft;
        let phi = PhiBlock::<Z>::new(&j, h, &scales, &mask);
        if !phi.phi.iter().flatten().flatten().all(|x| x.is_finite()) {
            return Err(self.singular(t, h));
        }
        // U2 = y + h phi_1(A) F0 + h^2 phi_2(A) v on z; the exact lag states at t + h
        let p1f = phi.apply(1, f0, &scales, &mask);
        let p2v = phi.apply(2, &v, &scales, &mask);
        let hh = h * h;
        let mut u2: [f64; N] = std::array::from_fn(|i| y[i] + h * p1f[i] + hh * p2v[i]);
        let s1 = t_new - t;
        LagSegment::advance_all(lag_seg, t, &y, &mut u2, s1);
        let f2 = self.rhs(inp, t_new, &u2)?.dx;
        // D2 = f(t + h, U2) - F0 - J (U2 - y) - h v on z (J's lag columns are zero)
        let du: [f64; N] = std::array::from_fn(|i| u2[i] - y[i]);
        let d2: [f64; N] = std::array::from_fn(|r| {
            let jd: f64 = (0..N).map(|c| j[r][c] * du[c] * mask[c]).sum();
            (f2[r] - f0[r] - jd - h * v[r]) * mask[r]
        });
        let p3d = phi.apply(3, &d2, &scales, &mask);
        let e: [f64; N] = std::array::from_fn(|i| 2.0 * h * p3d[i]);
        let y1: [f64; N] = std::array::from_fn(|i| u2[i] + e[i]);
        let nz = if Z == N { N } else { Z };
        Ok(Trial {
            y1,
            err: self.error_norm(&self.y, &y1, &e),
            e,
            dense: Some(Interp::Exprb(Box::new(ExprbDense {
                y0: y,
                h,
                f0: *f0,
                v,
                d2,
                j,
                scales,
                mask,
                nz,
            }))),
            f1: None,
        })
    }
}

/// Accepted steps a Jacobian (and f_t) is used for: 1, a fresh one at every step (the method as
/// published; kept for the retries of a rejected step from the same point). Reusing them over
/// 2, 4 or all steps of a segment (an exponential W-type use, order not guaranteed) was
/// measured: fewer evaluations per step, but more steps and a larger deviation at a given
/// tolerance, no saving at equal accuracy (`docs/integrator.md`).
const JAC_MAX_AGE: usize = 1;

#[cfg(test)]
mod tests {
    use super::*;

    /// phi_0..phi_3 of a scalar: the Taylor series for |z| < 2 (60 terms), else the recurrence
    /// phi_{k+1} = (phi_k - 1/k!)/z from e^z.
    fn phi_scalar(z: f64) -> [f64; 4] {
        if z.abs() < 2.0 {
            std::array::from_fn(|k| {
                // sum_n z^n / (n + k)!
                let mut f = 1.0;
                for i in 1..=k {
                    f /= i as f64;
                }
                let (mut s, mut term) = (0.0, f);
                for n in 0..60 {
                    s += term;
                    term *= z / (n + k + 1) as f64;
                }
                s
            })
        } else {
            let p0 = z.exp();
            let p1 = (p0 - 1.0) / z;
            let p2 = (p1 - 1.0) / z;
            let p3 = (p2 - 0.5) / z;
            [p0, p1, p2, p3]
        }
    }

    fn rel_err<const Z: usize>(a: &Mat<Z>, b: &Mat<Z>) -> f64 {
        let d: Mat<Z> = std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] - b[i][j]));
        norm1(&d) / norm1(b)
    }

    #[test]
    fn phi_of_diagonal_matrices() {
        let zs = [
            0.0, -1e-8, 1e-3, -0.3, 0.49, -0.9, -1.7, 2.5, -3.0, -12.0, -57.0, -300.0, 5.0,
        ];
        let mut worst: f64 = 0.0;
        for &z in &zs {
            let a: Mat<1> = [[z]];
            let p = phi123(&a);
            let want = phi_scalar(z);
            for k in 1..=3 {
                let r = (p[k - 1][0][0] / want[k] - 1.0).abs();
                worst = worst.max(r);
                assert!(r < 1e-13, "phi_{k}({z}): {} vs {}", p[k - 1][0][0], want[k]);
            }
        }
        // a 5 x 5 diagonal matrix: each entry its scalar phi
        let d = [-0.2, -4.0, -35.0, -120.0, 0.7];
        let a: Mat<5> =
            std::array::from_fn(|i| std::array::from_fn(|j| if i == j { d[i] } else { 0.0 }));
        let p = phi123(&a);
        for (i, &z) in d.iter().enumerate() {
            let want = phi_scalar(z);
            for k in 1..=3 {
                let r = (p[k - 1][i][i] / want[k] - 1.0).abs();
                worst = worst.max(r);
                assert!(r < 1e-13, "phi_{k}({z}) in 5 x 5: {r:e}");
            }
        }
        eprintln!("worst relative error, diagonal: {worst:e}");
    }

    /// A stiff, diagonalizable 2 x 2 matrix h [[-2, 1], [998, -999]] (eigenvalues -h, -1000 h,
    /// eigenvectors (1, 1) and (1, -998)) against V phi(diag) V^-1, for h up to 16 (15
    /// doublings: the error grows with them, to 1.4e-13).
    #[test]
    fn phi_of_stiff_matrices() {
        let v = [[1.0, 1.0], [1.0, -998.0]];
        let det = -998.0 - 1.0;
        let vi = [[-998.0 / det, -1.0 / det], [-1.0 / det, 1.0 / det]];
        for h in [0.01, 0.3, 1.0, 4.0, 16.0] {
            let a: Mat<2> = [[-2.0 * h, h], [998.0 * h, -999.0 * h]];
            let p = phi123(&a);
            let (l1, l2) = (phi_scalar(-h), phi_scalar(-1000.0 * h));
            for k in 1..=3 {
                let d = [[l1[k], 0.0], [0.0, l2[k]]];
                let want = mul(&mul(&v, &d), &vi);
                let r = rel_err(&p[k - 1], &want);
                // and on the slow eigenvector, where the result is small
                let slow = [
                    p[k - 1][0][0] + p[k - 1][0][1],
                    p[k - 1][1][0] + p[k - 1][1][1],
                ];
                let rs = (slow[0] / l1[k] - 1.0)
                    .abs()
                    .max((slow[1] / l1[k] - 1.0).abs());
                eprintln!("h {h}: phi_{k} relative error {r:e}, on the slow eigenvector {rs:e}");
                assert!(r < 5e-13 && rs < 5e-13, "h {h}: phi_{k} {r:e} {rs:e}");
            }
        }
    }

    /// phi_k of an upper triangular matrix by Parlett's recurrence (distinct eigenvalues):
    /// F T = T F gives f_ij = t_ij (f_jj - f_ii) / (t_jj - t_ii) + sum_{i<l<j} (t_il f_lj -
    /// f_il t_lj) / (t_jj - t_ii).
    fn parlett<const Z: usize>(t: &Mat<Z>, k: usize) -> Mat<Z> {
        let mut f = [[0.0; Z]; Z];
        for i in 0..Z {
            f[i][i] = phi_scalar(t[i][i])[k];
        }
        for d in 1..Z {
            for i in 0..Z - d {
                let j = i + d;
                let mut s = t[i][j] * (f[j][j] - f[i][i]);
                for l in i + 1..j {
                    s += t[i][l] * f[l][j] - f[i][l] * t[l][j];
                }
                f[i][j] = s / (t[j][j] - t[i][i]);
            }
        }
        f
    }

    /// Non-normal matrices: triangular ones against Parlett's recurrence, and a full 5 x 5
    /// Q T Q^T with a Householder reflection Q (orthogonal and symmetric, so exact inverse)
    /// against Q phi(T) Q; the recurrence A phi_{k+1}(A) = phi_k(A) - I/k! on top.
    #[test]
    fn phi_of_non_normal_matrices() {
        // 2 x 2 with a large coupling (|t_12| >> |eigenvalues|)
        let t2: Mat<2> = [[-3.0, 400.0], [0.0, -45.0]];
        let p = phi123(&t2);
        for k in 1..=3 {
            let r = rel_err(&p[k - 1], &parlett(&t2, k));
            eprintln!("2 x 2: phi_{k} relative error {r:e}");
            assert!(r < 1e-13, "2 x 2 phi_{k}: {r:e}");
        }
        // 5 x 5 triangular, eigenvalues of the engine's h J (h ~ 0.1: -0.02 ... -12), couplings
        let t5: Mat<5> = [
            [-0.021, 3.0, -7.0, 0.5, 20.0],
            [0.0, -0.9, 11.0, -2.0, 4.0],
            [0.0, 0.0, -4.3, 6.0, -30.0],
            [0.0, 0.0, 0.0, -7.7, 9.0],
            [0.0, 0.0, 0.0, 0.0, -12.4],
        ];
        let p = phi123(&t5);
        let mut pt = [[[0.0; 5]; 5]; 3];
        for k in 1..=3 {
            pt[k - 1] = parlett(&t5, k);
            let r = rel_err(&p[k - 1], &pt[k - 1]);
            eprintln!("5 x 5 triangular: phi_{k} relative error {r:e}");
            assert!(r < 1e-13, "5 x 5 phi_{k}: {r:e}");
        }
        // Q = I - 2 w w^T / (w^T w)
        let w = [1.0, -2.0, 0.5, 3.0, -1.5];
        let ww: f64 = w.iter().map(|x| x * x).sum();
        let q: Mat<5> = std::array::from_fn(|i| {
            std::array::from_fn(|j| f64::from(u8::from(i == j)) - 2.0 * w[i] * w[j] / ww)
        });
        let a = mul(&mul(&q, &t5), &q);
        let p = phi123(&a);
        for k in 1..=3 {
            let want = mul(&mul(&q, &pt[k - 1]), &q);
            let r = rel_err(&p[k - 1], &want);
            eprintln!("5 x 5 full: phi_{k} relative error {r:e}");
            assert!(r < 1e-13, "5 x 5 full phi_{k}: {r:e}");
        }
        // A phi_3 = phi_2 - I/2, A phi_2 = phi_1 - I
        for (k, c) in [(2usize, 0.5), (1, 1.0)] {
            let ap = mul(&a, &p[k]);
            let want: Mat<5> = std::array::from_fn(|i| {
                std::array::from_fn(|j| p[k - 1][i][j] - if i == j { c } else { 0.0 })
            });
            let r = rel_err(&ap, &want);
            assert!(r < 1e-13, "recurrence phi_{}: {r:e}", k + 1);
        }
    }
}
