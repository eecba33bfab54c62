//! Dense LU with partial pivoting for the small (8-12) iteration matrices of the Rosenbrock
//! method, on fixed-size arrays (no allocation; nalgebra's LU needs type-level dimensions that
//! a const-generic state size cannot provide).

/// Factor the leading `Z` x `Z` block of `a` in place (L unit lower, U upper), row permutation
/// in `piv` (`piv[k] = k` for k >= Z). Returns false if a pivot is zero or non-finite (singular
/// or NaN matrix). Fixed loop bounds: the compiler unrolls the small blocks.
pub(crate) fn lu_factor<const N: usize, const Z: usize>(
    a: &mut [[f64; N]; N],
    piv: &mut [usize; N],
) -> bool {
    if Z > N {
        return lu_factor::<N, N>(a, piv);
    }
    for (k, p) in piv.iter_mut().enumerate().skip(Z) {
        *p = k;
    }
    for k in 0..Z {
        let mut p = k;
        let mut best = a[k][k].abs();
        for r in k + 1..Z {
            if a[r][k].abs() > best {
                best = a[r][k].abs();
                p = r;
            }
        }
        if !(best > 0.0 && best.is_finite()) {
            return false;
        }
        piv[k] = p;
        if p != k {
            a.swap(p, k);
        }
        let inv = 1.0 / a[k][k];
        for r in k + 1..Z {
            let l = a[r][k] * inv;
            a[r][k] = l;
            if l != 0.0 {
                for c in k + 1..Z {
                    a[r][c] -= l * a[k][c];
                }
            }
        }
    }
    true
}

/// Solve A_ZZ x = b in place on the leading `Z` entries of `b` (the rest untouched) for the
/// block factored by [`lu_factor`] with the same `Z`, given `dinv[k] = 1 / U_kk` (a
/// multiplication instead of a division per row; fixed loop bounds, so the compiler unrolls the
/// small systems completely).
pub(crate) fn lu_solve<const N: usize, const Z: usize>(
    lu: &[[f64; N]; N],
    piv: &[usize; N],
    dinv: &[f64; N],
    b: &mut [f64; N],
) {
    if Z > N {
        return lu_solve::<N, N>(lu, piv, dinv, b);
    }
    for k in 0..Z {
        b.swap(k, piv[k]);
    }
    for r in 1..Z {
        let mut s = b[r];
        for c in 0..r {
            s -= lu[r][c] * b[c];
        }
        b[r] = s;
    }
    for r in (0..Z).rev() {
        let mut s = b[r];
        for c in r + 1..Z {
            s -= lu[r][c] * b[c];
        }
        b[r] = s * dinv[r];
    }
}

/// The inverse of the leading `Z` x `Z` block factored by [`lu_factor`] with the same `Z`,
/// written to the leading block of `inv` (column j: the solve of the j-th unit vector; the
/// columns are independent, so they overlap in the pipeline). With it a solve is [`block_mul`]:
/// `Z` independent dot products instead of two dependent substitution sweeps with row swaps.
pub(crate) fn lu_inverse<const N: usize, const Z: usize>(
    lu: &[[f64; N]; N],
    piv: &[usize; N],
    dinv: &[f64; N],
    inv: &mut [[f64; N]; N],
) {
    let z = Z.min(N);
    for j in 0..z {
        let mut e = [0.0; N];
        e[j] = 1.0;
        lu_solve::<N, Z>(lu, piv, dinv, &mut e);
        for (row, v) in inv.iter_mut().zip(e).take(z) {
            row[j] = v;
        }
    }
}

/// b := A_ZZ b on the leading `Z` entries of `b` (the rest untouched): with the inverse of
/// [`lu_inverse`], a solve as `Z` independent dot products instead of two dependent
/// substitution sweeps with row swaps.
#[inline(always)]
pub(crate) fn block_mul<const N: usize, const Z: usize>(a: &[[f64; N]; N], b: &mut [f64; N]) {
    let z = Z.min(N);
    let mut x = [0.0; N];
    for (xr, row) in x.iter_mut().zip(a).take(z) {
        let mut s = 0.0;
        for c in 0..z {
            s += row[c] * b[c];
        }
        *xr = s;
    }
    b[..z].copy_from_slice(&x[..z]);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y = A x.
    fn mat_vec<const N: usize>(a: &[[f64; N]; N], x: &[f64; N]) -> [f64; N] {
        std::array::from_fn(|r| (0..N).map(|c| a[r][c] * x[c]).sum())
    }

    #[test]
    fn solves_a_pivoting_system() {
        let a0 = [[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]];
        let x = [1.0, -2.0, 3.0];
        let mut b = mat_vec(&a0, &x);
        let mut a = a0;
        let mut piv = [0; 3];
        assert!(lu_factor::<3, 3>(&mut a, &mut piv));
        let dinv: [f64; 3] = std::array::from_fn(|k| 1.0 / a[k][k]);
        lu_solve::<3, 3>(&a, &piv, &dinv, &mut b);
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-14);
        }
        let mut s = [[1.0, 2.0], [2.0, 4.0]];
        assert!(!lu_factor::<2, 2>(&mut s, &mut [0; 2]));
        // the leading 2x2 block of a 3x3 matrix is factored alone
        let mut a = [[2.0, 1.0, 9.0], [1.0, 3.0, 9.0], [9.0, 9.0, 9.0]];
        let mut piv = [0; 3];
        assert!(lu_factor::<3, 2>(&mut a, &mut piv));
        assert_eq!(a[2], [9.0, 9.0, 9.0]);
        assert_eq!(piv[2], 2);
        assert!((a[1][0] - 0.5).abs() < 1e-15 && (a[1][1] - 2.5).abs() < 1e-15);
        // and solved on that block alone: 2 x0 + x1 = 4, x0 + 3 x1 = 7 -> (1, 2); b[2] untouched
        let dinv: [f64; 3] = std::array::from_fn(|k| 1.0 / a[k][k]);
        let mut b = [4.0, 7.0, -5.0];
        lu_solve::<3, 2>(&a, &piv, &dinv, &mut b);
        assert!((b[0] - 1.0).abs() < 1e-15 && (b[1] - 2.0).abs() < 1e-15 && b[2] == -5.0);
    }

    #[test]
    fn inverse_times_vector_equals_the_lu_solve() {
        // a pivoting 5 x 5 block of a 7 x 7 array (rows 5, 6 and columns 5, 6 are not read)
        let a0: [[f64; 7]; 7] = std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                if r >= 5 || c >= 5 {
                    f64::NAN
                } else {
                    ((r * 7 + c * 3) % 5) as f64 - 1.5 + if r == (c + 2) % 5 { 4.0 } else { 0.0 }
                }
            })
        });
        let mut a = a0;
        let mut piv = [0; 7];
        assert!(lu_factor::<7, 5>(&mut a, &mut piv));
        assert!(
            piv.iter().take(5).enumerate().any(|(k, &p)| p != k),
            "pivots"
        );
        let dinv: [f64; 7] = std::array::from_fn(|k| 1.0 / a[k][k]);
        let mut inv = [[f64::NAN; 7]; 7];
        lu_inverse::<7, 5>(&a, &piv, &dinv, &mut inv);
        // rows and columns 5, 6 are not written
        assert!(inv[5].iter().chain(inv[6].iter()).all(|v| v.is_nan()));
        assert!(inv.iter().all(|row| row[5].is_nan() && row[6].is_nan()));
        // A A^-1 = I on the block
        for r in 0..5 {
            for c in 0..5 {
                let s: f64 = (0..5).map(|k| a0[r][k] * inv[k][c]).sum();
                assert!(
                    (s - if r == c { 1.0 } else { 0.0 }).abs() < 1e-14,
                    "{r} {c} {s}"
                );
            }
        }
        let b0 = [1.0, -2.0, 0.5, 3.0, -1.0, 7.0, 8.0];
        let (mut x, mut y) = (b0, b0);
        lu_solve::<7, 5>(&a, &piv, &dinv, &mut x);
        block_mul::<7, 5>(&inv, &mut y);
        for k in 0..5 {
            assert!((x[k] - y[k]).abs() <= 1e-14 * x[k].abs().max(1.0), "{k}");
        }
        assert_eq!(&y[5..], &b0[5..]);
    }
}
