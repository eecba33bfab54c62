//! Parameter tuning: the least-squares machinery the tuning steps are built on.
//!
//! - [`lsq`]: bounded nonlinear least squares (Trust Region Reflective with Coleman–Li
//!   scaling), finite-difference or user Jacobians, typed errors, linearized parameter
//!   statistics for identifiability reports. Verified on the NIST StRD nonlinear regression
//!   problems (`tests/nist.rs`, `docs/nist.md`).
//! - [`varpro`]: separable nonlinear least squares `min ||y - Phi(alpha) c||` by variable
//!   projection (Golub–Pereyra), the linear coefficients eliminated by linear least squares.

pub mod data;
pub mod lab;
pub mod lsq;
pub mod steps;
pub mod validate;
pub mod varpro;
