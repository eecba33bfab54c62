//! Analysis computed from the model: steady state (equilibrium) with validity flags,
//! linearization (continuous, and sampled with the delays exact), poles and transmission zeros, operating maps, ensembles of simulations on all
//! cores, step-response metrics, the section-9 extension comparison, the cylinder-out
//! temperature study and the robustness sweep.

pub mod component_maps;
pub mod discrete;
pub mod ensemble;
pub mod experiment;
pub mod extensions;
pub mod frequency;
pub mod json;
pub mod linearize;
pub mod map;
pub mod robustness;
pub mod robustness_analysis;
pub mod steady;
pub mod step;
pub mod zeros;
