//! Typed errors of the lower layers (params, sim, io), wrapped by [`Error`].
//!
//! The layers above keep their own typed errors (e.g. `analysis::steady::SteadyError`,
//! `analysis::steady::SimFromSteadyError`): this module points down only.

use crate::params::ParamIssues;

/// Any error of the library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Invalid parameters (every problem listed with its field).
    #[error(transparent)]
    Params(#[from] ParamIssues),
    /// Simulation failure (with time and state).
    #[error(transparent)]
    Sim(#[from] crate::sim::SimError),
    /// File or format problem (with file, line, column where known).
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}
