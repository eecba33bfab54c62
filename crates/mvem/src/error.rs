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

/// A number as an error message shows it: the shortest round-trip decimal for magnitudes in
/// [1e-4, 1e9) (and 0, NaN, inf), scientific notation outside (`1e308`, not 309 digits).
pub fn num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e9).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn num_is_short_at_every_magnitude() {
        for (v, s) in [
            (1.2, "1.2"),
            (-0.99, "-0.99"),
            (0.0, "0"),
            (1e308, "1e308"),
            (-2.5e-300, "-2.5e-300"),
            (123456789.0, "123456789"),
            (1e9, "1e9"),
            (f64::NAN, "NaN"),
            (f64::NEG_INFINITY, "-inf"),
        ] {
            assert_eq!(super::num(v), s);
        }
    }
}
