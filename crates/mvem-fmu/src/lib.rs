//! # mvem-fmu: the mvem engine model as an FMI 2.0 FMU (Model Exchange and Co-Simulation)
//!
//! The crate builds a shared library with a hand-written FMI 2.0 C ABI ([`ffi`]) over a safe
//! instance ([`instance::Instance`]), and a packager ([`build::build`], used by `mvem fmu` and
//! the binary `mvem-fmu-build`) that writes `modelDescription.xml` from the same variable table
//! ([`vars`]) and zips it with the library and `resources/mvem.json` (the
//! [`vars::FmuConfig`]: model variant 8/10/12, cylinder-temperature mode, parameters) into an
//! `.fmu`. One library serves every configuration: it reads the JSON at `fmi2Instantiate`.
//!
//! ```text
//! cargo build --release -p mvem-cli -p mvem-fmu
//! target/release/mvem fmu --out mvem.fmu --model 10 [--params P.toml]
//! ```
//!
//! See `docs/fmu-python.md` for the variables, the start (steady state of the start inputs),
//! and how the actuator transport delays are handled in each interface.

pub mod build;
pub mod ffi;
pub mod instance;
pub mod vars;
