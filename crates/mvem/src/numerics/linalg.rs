//! Dense LU with partial pivoting for the small (8-12) iteration matrices of the Rosenbrock
//! method, on fixed-size arrays (no allocation; nalgebra's LU needs type-level dimensions that
//! a const-generic state size cannot provide).

/// Factor the leading `n` x `n` block of `a` in place (L unit lower, U upper), row permutation
/// in `piv`. Returns false if a pivot is zero or non-finite (singular or NaN matrix).
pub(crate) fn lu_factor<const N: usize>(
    a: &mut [[f64; N]; N],
    piv: &mut [usize; N],
    n: usize,
) -> bool {
    for k in 0..n {
        let mut p = k;
        let mut best = a[k][k].abs();
        for r in k + 1..n {
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
        for r in k + 1..n {
            let l = a[r][k] * inv;
            a[r][k] = l;
            if l != 0.0 {
                for c in k + 1..n {
                    a[r][c] -= l * a[k][c];
                }
            }
        }
    }
    true
}

/// Solve A x = b in place for the leading `n` x `n` block factored by [`lu_factor`] (the first
/// `n` entries of `b`).
pub(crate) fn lu_solve<const N: usize>(
    lu: &[[f64; N]; N],
    piv: &[usize; N],
    b: &mut [f64; N],
    n: usize,
) {
    for k in 0..n {
        b.swap(k, piv[k]);
    }
    for r in 1..n {
        let mut s = b[r];
        for c in 0..r {
            s -= lu[r][c] * b[c];
        }
        b[r] = s;
    }
    for r in (0..n).rev() {
        let mut s = b[r];
        for c in r + 1..n {
            s -= lu[r][c] * b[c];
        }
        b[r] = s / lu[r][r];
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
        assert!(lu_factor(&mut a, &mut piv, 3));
        lu_solve(&a, &piv, &mut b, 3);
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-14);
        }
        let mut s = [[1.0, 2.0], [2.0, 4.0]];
        assert!(!lu_factor(&mut s, &mut [0; 2], 2));
        // the leading 2x2 block of a 3x3 matrix
        let mut a = [[2.0, 1.0, 9.0], [1.0, 3.0, 9.0], [9.0, 9.0, 9.0]];
        let mut b = [3.0, 5.0, 7.0];
        let mut piv = [0; 3];
        assert!(lu_factor(&mut a, &mut piv, 2));
        lu_solve(&a, &piv, &mut b, 2);
        assert!((b[0] - 0.8).abs() < 1e-15 && (b[1] - 1.4).abs() < 1e-15 && b[2] == 7.0);
    }
}
