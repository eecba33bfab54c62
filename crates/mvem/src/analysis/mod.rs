//! Analysis computed from the model: steady state (equilibrium) with validity flags.

pub mod linearize;
pub mod map;
pub mod steady;
pub mod zeros;
