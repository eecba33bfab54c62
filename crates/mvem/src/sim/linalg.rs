//! Dense LU with partial pivoting for the small (8-12) iteration matrices of the Rosenbrock
//! method, on fixed-size arrays (no allocation; nalgebra's LU needs type-level dimensions that
//! a const-generic state size cannot provide).

/// Factor `a` in place (L unit lower, U upper), row permutation in `piv`. Returns false if a
/// pivot is zero or non-finite (singular or NaN matrix).
pub(crate) fn lu_factor<const N: usize>(a: &mut [[f64; N]; N], piv: &mut [usize; N]) -> bool {
    for k in 0..N {
        let mut p = k;
        let mut best = a[k][k].abs();
        for r in k + 1..N {
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
        for r in k + 1..N {
            let l = a[r][k] * inv;
            a[r][k] = l;
            if l != 0.0 {
                for c in k + 1..N {
                    a[r][c] -= l * a[k][c];
                }
            }
        }
    }
    true
}

/// Solve A x = b in place with the factors of [`lu_factor`].
pub(crate) fn lu_solve<const N: usize>(lu: &[[f64; N]; N], piv: &[usize; N], b: &mut [f64; N]) {
    for k in 0..N {
        b.swap(k, piv[k]);
    }
    for r in 1..N {
        let mut s = b[r];
        for c in 0..r {
            s -= lu[r][c] * b[c];
        }
        b[r] = s;
    }
    for r in (0..N).rev() {
        let mut s = b[r];
        for c in r + 1..N {
            s -= lu[r][c] * b[c];
        }
        b[r] = s / lu[r][r];
    }
}

/// y = A x.
pub(crate) fn mat_vec<const N: usize>(a: &[[f64; N]; N], x: &[f64; N]) -> [f64; N] {
    std::array::from_fn(|r| (0..N).map(|c| a[r][c] * x[c]).sum())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_pivoting_system() {
        let a0 = [[0.0, 2.0, 1.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]];
        let x = [1.0, -2.0, 3.0];
        let mut b = mat_vec(&a0, &x);
        let mut a = a0;
        let mut piv = [0; 3];
        assert!(lu_factor(&mut a, &mut piv));
        lu_solve(&a, &piv, &mut b);
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-14);
        }
        let mut s = [[1.0, 2.0], [2.0, 4.0]];
        assert!(!lu_factor(&mut s, &mut [0; 2]));
    }
}
