//! # mvem-fmu: the mvem engine model as an FMI 2.0 FMU (Model Exchange and Co-Simulation)
//!
//! The crate builds a shared library with a hand-written FMI 2.0 C ABI ([`ffi`]) over a safe
//! instance ([`instance::Instance`]), and a packager ([`build::build`], binary
//! `mvem-fmu-build`) that writes `modelDescription.xml` from the same variable table
//! ([`vars`]) and zips it with the library into an `.fmu`.
//!
//! ```text
//! cargo run --release -p mvem-fmu --bin mvem-fmu-build -- --out mvem.fmu
//! ```
//!
//! See `docs/fmu-python.md` for the variables, the start (steady state of the start inputs),
//! and how the actuator transport delays are handled in each interface.

pub mod build;
pub mod ffi;
pub mod instance;
pub mod vars;
