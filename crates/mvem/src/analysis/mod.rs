//! Analysis computed from the model: steady state (equilibrium) with validity flags, step-response
//! metrics.

pub mod steady;
pub mod step;
