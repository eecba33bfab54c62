//! Numerics shared by the simulator and the tuning, with no knowledge of the engine model.
//!
//! - [`cancel`]: a token another thread sets to stop a long computation (the least-squares
//!   search, the tuning, an ensemble) at its next checkpoint; [`progress`]: what such a
//!   computation reports as it goes (tuning steps, search iterations) to an observer.
//! - `linalg`: dense LU with partial pivoting on fixed-size arrays (the Rosenbrock iteration
//!   matrices of [`crate::sim`]).
//! - [`lsq`]: bounded nonlinear least squares (Trust Region Reflective with Coleman–Li
//!   scaling), finite-difference or user Jacobians, typed errors, linearized parameter
//!   statistics. Verified on the NIST StRD nonlinear regression problems (`tests/nist.rs`).
//! - [`varpro`]: separable nonlinear least squares `min ||y - Phi(alpha) c||` by variable
//!   projection (Golub–Pereyra).

pub mod cancel;
pub(crate) mod linalg;
pub mod lsq;
pub mod progress;
pub mod varpro;

/// Run `f` with `value` in the thread-local slot `key` (the per-thread cancellation token of
/// [`cancel`], the observer of [`progress`]); the slot's previous value is restored afterwards,
/// also when `f` panics.
fn with_thread_value<T: Clone + 'static, R>(
    key: &'static std::thread::LocalKey<std::cell::RefCell<Option<T>>>,
    value: &T,
    f: impl FnOnce() -> R,
) -> R {
    struct Restore<T: 'static>(
        &'static std::thread::LocalKey<std::cell::RefCell<Option<T>>>,
        Option<T>,
    );
    impl<T: 'static> Drop for Restore<T> {
        fn drop(&mut self) {
            let prev = self.1.take();
            self.0.with(|c| *c.borrow_mut() = prev);
        }
    }
    let prev = key.with(|c| c.borrow_mut().replace(value.clone()));
    let _restore = Restore(key, prev);
    f()
}

/// Iteration limit of every SVD in the crate (`nalgebra::SVD::try_new`; 0 would mean no limit,
/// and a non-finite matrix would then never converge). A decomposition that needs more is
/// reported as failed instead of running forever.
pub const SVD_MAX_ITER: usize = 10_000;

/// A number for messages: as Rust prints it (shortest round trip) for magnitudes in
/// [1e-6, 1e12) and zero, in scientific notation otherwise, so a user's `1e300` is echoed as
/// `1e300` and not as 301 digits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        if v == 0.0 || !v.is_finite() || (1e-6..1e12).contains(&v.abs()) {
            write!(f, "{v}")
        } else {
            write!(f, "{v:e}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Num;

    #[test]
    fn numbers_in_messages_stay_short() {
        let cases = [
            (75.0, "75"),
            (0.1, "0.1"),
            (1800.0, "1800"),
            (1e300, "1e300"),
            (-2.5e-300, "-2.5e-300"),
            (1e-7, "1e-7"),
            (0.0, "0"),
            (f64::NAN, "NaN"),
            (f64::NEG_INFINITY, "-inf"),
        ];
        for (v, text) in cases {
            assert_eq!(Num(v).to_string(), text);
        }
    }
}
