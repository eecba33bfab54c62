//! # mvem: mean-value engine model of a diesel engine with VGT and EGR
//!
//! A Rust implementation of Wahlström & Eriksson (2011), "Modelling diesel engines with a
//! variable-geometry turbocharger and exhaust gas recirculation by optimization of model
//! parameters for capturing non-linear system dynamics", reproducing the authors' Simulink
//! implementation by default and the paper's plain equations as an option.
//!
//! The crate reads like the paper, and data flows one way:
//!
//! ```text
//! params (validated, immutable) -> components (pure functions, sections 3-7)
//!        -> model (8-state assembly, eq. (1)-(2)) -> sim (inputs, delays, integrator)
//!        -> Solution -> analysis (steady state, ...) / io (files)
//! ```
//!
//! - [`params`]: one typed group per component, the published set built in, validation.
//! - [`components`]: manifolds, cylinder, EGR valve and actuator, turbine, VGT actuator,
//!   compressor, turbo shaft; each function cites its equation number.
//! - [`model`]: the assembled model behind the [`model::Model`] trait; every algebraic signal
//!   is computed by the same function as the derivatives.
//! - [`sim`]: input schedules (constants, steps, CSV time series), exact transport delays,
//!   adaptive error-controlled integration that stops at input breakpoints.
//! - [`numerics`]: dense LU for the integrator, bounded nonlinear least squares and variable
//!   projection for the tuning (no model knowledge).
//! - [`analysis`]: steady state (equilibrium) with physical-validity flags.
//! - [`io`]: parameter files (TOML/JSON), input CSV reading, atomic output writing.
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
pub mod error;
pub mod io;
pub mod model;
pub mod numerics;
pub mod params;
pub mod sim;
pub mod tuning;

pub use error::Error;
