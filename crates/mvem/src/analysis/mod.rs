//! Analysis computed from the model: steady state (equilibrium) with validity flags.

pub mod robustness;
pub mod steady;
