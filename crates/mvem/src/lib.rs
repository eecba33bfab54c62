//! # mvem: mean-value engine model of a diesel engine with VGT and EGR
//!
//! A Rust implementation of Wahlström & Eriksson (2011), "Modelling diesel engines with a
//! variable-geometry turbocharger and exhaust gas recirculation by optimization of model
//! parameters for capturing non-linear system dynamics", reproducing the authors' Simulink
//! implementation by default and the paper's plain equations as an option.
//!
//! The crate reads like the paper, and data flows one way (`ARCHITECTURE.md` at the
//! repository root: what each layer may import, where each kind of change goes):
//!
//! ```text
//! params ─► components ─► model ─► sim ─► io, analysis ─► tuning, control ─► front ends
//! ```
//!
//! - [`params`]: one typed group per component, the published set built in, validation; the
//!   names, units and descriptions of every parameter and the registry of every scalar by name
//!   ([`params::Params::registry`], `cylinder.c_vol[1]`).
//! - [`components`]: manifolds, cylinder, EGR valve and actuator, turbine, VGT actuator,
//!   compressor, intercooler, turbo shaft: pure functions, each citing its equation number.
//! - [`model`]: the assembled model variants behind the [`model::Model`] trait; every algebraic
//!   signal is computed by the same function as the derivatives; names, units and descriptions
//!   of inputs, states and signals ([`model::meta`]).
//! - [`sim`]: input schedules (constants, steps, CSV time series), exact transport delays,
//!   adaptive error-controlled integration that stops at input breakpoints; knows the model
//!   only through the trait.
//! - [`io`]: parameter files (TOML/JSON, annotated TOML), input CSV reading, atomic output
//!   writing.
//! - [`analysis`]: steady state with physical-validity flags, linearization, zeros, maps,
//!   step metrics and the step experiment ([`analysis::experiment::run_step`]) that every front
//!   end uses.
//! - [`numerics`]: dense LU for the integrator, bounded nonlinear least squares and variable
//!   projection for the tuning (no model knowledge).
//! - [`tuning`]: parameter estimation (section 8).
//!
//! ```
//! use mvem::{model::{Drive, Engine8}, analysis::steady::steady_state};
//! let m = Engine8::published();
//! let ss = steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 75.0)).unwrap();
//! assert!(ss.signals.w_c > 0.2 && ss.physically_valid());
//! ```

// Index loops over small fixed-size state arrays read like the equations they implement.
#![allow(clippy::needless_range_loop)]

pub mod analysis;
pub mod components;
pub mod control;
pub mod error;
pub mod io;
pub mod model;
pub mod numerics;
pub mod params;
pub mod sim;
pub mod tuning;

pub use error::Error;
