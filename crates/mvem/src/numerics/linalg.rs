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
}
