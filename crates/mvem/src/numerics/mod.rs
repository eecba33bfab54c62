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
