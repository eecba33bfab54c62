//! # mvem-py: Python bindings of mvem
//!
//! The Python package `mvem` (built with maturin from this crate, see `pyproject.toml`) offers
//! `simulate`, `steady` and `published_params`. The logic is plain Rust in [`core`] (tested by
//! `cargo test`); the pyo3 layer (feature `extension-module`, enabled by maturin only) converts
//! values, releases the GIL around the model calls and maps errors to `ValueError` (bad inputs
//! or parameters) and `RuntimeError` (solver failures). See `docs/fmu-python.md`.

pub mod core;

#[cfg(feature = "extension-module")]
mod py;
