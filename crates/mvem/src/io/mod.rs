//! Files: parameter sets (TOML/JSON), input time series (CSV), results (CSV), written
//! atomically (temporary file + rename) so that a failure never leaves a partial file. (The JSON
//! objects of analysis results are built one layer up, in `analysis::json`.)

pub mod csv_columns;
pub mod csv_demand;
pub mod csv_inputs;
pub mod output;
pub mod params;
pub mod params_toml;
pub mod test_cell;

use std::path::{Path, PathBuf};

/// A file or format problem, naming the file and, where known, line and column.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// Reading or writing failed.
    #[error("{path}: {source}")]
    File {
        /// File.
        path: PathBuf,
        /// OS error.
        source: std::io::Error,
    },
    /// The content is malformed.
    #[error("{path}{}: {message}", location(.line, .column))]
    Format {
        /// File.
        path: PathBuf,
        /// 1-based line, if known.
        line: Option<usize>,
        /// Column name or number, if known.
        column: Option<String>,
        /// What is wrong.
        message: String,
    },
    /// The parameters are invalid (every problem listed).
    #[error("{path}: {issues}")]
    Params {
        /// File.
        path: PathBuf,
        /// Problems.
        issues: crate::params::ParamIssues,
    },
}

/// An [`IoError::Format`] naming `path` and, where known, the 1-based line and the column.
pub(crate) fn format_err(
    path: &Path,
    line: Option<usize>,
    column: Option<&str>,
    message: String,
) -> IoError {
    IoError::Format {
        path: path.to_path_buf(),
        line,
        column: column.map(str::to_string),
        message,
    }
}

fn location(line: &Option<usize>, column: &Option<String>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!(", line {l}, column {c}"),
        (Some(l), None) => format!(", line {l}"),
        (None, Some(c)) => format!(", column {c}"),
        (None, None) => String::new(),
    }
}
