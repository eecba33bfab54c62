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

/// A settings object (a struct with `#[serde(default)]`: every field optional) from JSON text,
/// as the front ends pass keyword arguments and request bodies. The error names the first key
/// whose value is refused (`beta: invalid type: string "x", expected f64`), without the JSON
/// text's line and column, which a caller that built the text from its own arguments would not
/// recognize.
pub fn settings_from_json<T: serde::de::DeserializeOwned>(text: &str) -> Result<T, String> {
    let strip = |e: serde_json::Error| {
        let s = e.to_string();
        match s.rfind(" at line ") {
            Some(i) if s[i..].contains(" column ") => s[..i].to_string(),
            _ => s,
        }
    };
    match serde_json::from_str::<T>(text) {
        Ok(v) => Ok(v),
        Err(e) => {
            if let Ok(serde_json::Value::Object(map)) = serde_json::from_str(text) {
                for (k, v) in map {
                    let one = serde_json::Value::Object(std::iter::once((k.clone(), v)).collect());
                    if let Err(e) = serde_json::from_value::<T>(one) {
                        let msg = strip(e);
                        return Err(if msg.contains(&format!("`{k}`")) {
                            msg
                        } else {
                            format!("{k}: {msg}")
                        });
                    }
                }
            }
            Err(strip(e))
        }
    }
}

#[cfg(test)]
mod settings_tests {
    use super::settings_from_json;
    use crate::tuning::request::TuneSettings;

    #[test]
    fn the_refused_key_is_named_without_a_position() {
        let e = settings_from_json::<TuneSettings>(r#"{"steps": "1-4", "beta": "x"}"#).unwrap_err();
        assert_eq!(e, "beta: invalid type: string \"x\", expected f64");
        let e = settings_from_json::<TuneSettings>(r#"{"betta": 1}"#).unwrap_err();
        assert!(
            e.starts_with("unknown field `betta`, expected one of"),
            "{e}"
        );
        let e = settings_from_json::<TuneSettings>("[1]").unwrap_err();
        assert!(!e.contains("line 1"), "{e}");
        let s = settings_from_json::<TuneSettings>(r#"{"steps": "1,2"}"#).unwrap();
        assert_eq!(s.steps, "1,2");
    }
}
