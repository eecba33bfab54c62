//! Numerics shared by the simulator and the tuning, with no knowledge of the engine model.
//!
//! - [`linalg`]: dense LU with partial pivoting on fixed-size arrays (the Rosenbrock iteration
//!   matrices of [`crate::sim`]).
//! - [`lsq`]: bounded nonlinear least squares (Trust Region Reflective with Coleman–Li
//!   scaling), finite-difference or user Jacobians, typed errors, linearized parameter
//!   statistics. Verified on the NIST StRD nonlinear regression problems (`tests/nist.rs`).
//! - [`varpro`]: separable nonlinear least squares `min ||y - Phi(alpha) c||` by variable
//!   projection (Golub–Pereyra).

pub(crate) mod linalg;
pub mod lsq;
pub mod varpro;

/// Iteration limit of every SVD in the crate (`nalgebra::SVD::try_new`; 0 would mean no limit,
/// and a non-finite matrix would then never converge). A decomposition that needs more is
/// reported as failed instead of running forever.
pub const SVD_MAX_ITER: usize = 10_000;
