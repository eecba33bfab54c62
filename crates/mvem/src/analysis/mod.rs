//! Analysis computed from the model: steady state (equilibrium) with validity flags, step-response
//! metrics, the section-9 extension comparison and the cylinder-out temperature study.

pub mod extensions;
pub mod steady;
pub mod step;
