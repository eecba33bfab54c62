//! Typed errors of each layer, wrapped by [`Error`].

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
    /// Steady-state failure.
    #[error(transparent)]
    Steady(#[from] crate::analysis::steady::SteadyError),
    /// File or format problem (with file, line, column where known).
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}
