//! Test-cell quantities in a parameter file: the optional `[test_cell]` section.
//!
//! `mvem tune` estimates quantities of the test cell, not of the engine (the dynamometer time
//! constant tau_Me of eq. (76)); they are written after the model parameters in a separate
//! section so that `validate` can reproduce the measured signals:
//!
//! ```toml
//! [test_cell]
//! tau_me = 1.0016   # dynamometer (torque sensor) time constant tau_Me [s], eq. (76)
//! tau_p_im = 0.0151 # sensor time constants [s] of p_im, p_em, W_c, n_t (Table 6; tuning step 3)
//! tau_p_em = 0.0197
//! tau_w_c = 0.0203
//! tau_n_t = 0.0058
//! ```
//!
//! The parameter loader ([`super::params::parse_params`]) ignores the section (its lines are
//! blanked, so line numbers of errors elsewhere stay right); [`parse_test_cell`] reads it.
//! In JSON parameter files the section is the top-level key `"test_cell"`.

use super::IoError;
use crate::params::Params;
use crate::tuning::sensors::SensorLags;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Name of the section.
pub const SECTION: &str = "test_cell";

/// Test-cell quantities estimated by the tuning (not model parameters).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestCell {
    /// Dynamometer time constant tau_Me \[s\] of eq. (76) (tuning step 4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_me: Option<f64>,
    /// Intake manifold pressure sensor time constant \[s\] ([`crate::tuning::sensors`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_p_im: Option<f64>,
    /// Exhaust manifold pressure sensor time constant \[s\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_p_em: Option<f64>,
    /// Compressor mass flow sensor time constant \[s\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_w_c: Option<f64>,
    /// Turbo speed sensor time constant \[s\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tau_n_t: Option<f64>,
}

impl TestCell {
    /// Whether nothing is set.
    pub fn is_empty(&self) -> bool {
        self.tau_me.is_none() && self.lags().is_none()
    }

    /// The sensor lags, when any is given (those not given: 0, no lag).
    pub fn lags(&self) -> Option<SensorLags> {
        let a = [self.tau_p_im, self.tau_p_em, self.tau_w_c, self.tau_n_t];
        a.iter()
            .any(Option::is_some)
            .then(|| SensorLags::from_array(a.map(|v| v.unwrap_or(0.0))))
    }

    /// The value of the key `name` of the section (`tau_me`, `tau_p_im`, ...), None when
    /// not set or not a key.
    pub fn get(&self, name: &str) -> Option<f64> {
        match name {
            "tau_me" => self.tau_me,
            "tau_p_im" => self.tau_p_im,
            "tau_p_em" => self.tau_p_em,
            "tau_w_c" => self.tau_w_c,
            "tau_n_t" => self.tau_n_t,
            _ => None,
        }
    }

    /// Set the sensor lags (all four written, zeros included).
    pub fn with_lags(mut self, l: SensorLags) -> Self {
        let [a, b, c, d] = l.as_array();
        (self.tau_p_im, self.tau_p_em, self.tau_w_c, self.tau_n_t) =
            (Some(a), Some(b), Some(c), Some(d));
        self
    }
}

fn is_header(line: &str) -> bool {
    line.trim_start().starts_with('[')
}

fn is_section_header(line: &str) -> bool {
    let t = line.trim();
    t.strip_prefix('[')
        .and_then(|r| r.split('#').next())
        .map(|r| r.trim_end().strip_suffix(']').map(str::trim) == Some(SECTION))
        .unwrap_or(false)
}

/// Split a TOML document into (the document without the `[test_cell]` section, the section
/// alone), both with the other lines blanked so that line numbers are those of the file.
/// The section runs from its header to the next table header.
pub fn split_toml(text: &str) -> (String, Option<String>) {
    let mut rest = String::with_capacity(text.len());
    let mut sec = String::new();
    let mut inside = false;
    let mut found = false;
    for line in text.split_inclusive('\n') {
        if is_section_header(line) {
            inside = true;
            found = true;
        } else if inside && is_header(line) {
            inside = false;
        }
        let nl = if line.ends_with('\n') { "\n" } else { "" };
        if inside {
            rest.push_str(nl);
            sec.push_str(line);
        } else {
            rest.push_str(line);
            sec.push_str(nl);
        }
    }
    (rest, found.then_some(sec))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Doc {
    test_cell: TestCell,
}

fn check(tc: TestCell, path: &Path) -> Result<TestCell, IoError> {
    if let Some(t) = tc.tau_me {
        if !(t.is_finite() && t > 0.0) {
            return Err(IoError::Format {
                path: path.to_path_buf(),
                line: None,
                column: Some("test_cell.tau_me".into()),
                message: format!("test_cell.tau_me = {t}: must be a finite time > 0 s"),
            });
        }
    }
    if let Some(l) = tc.lags() {
        l.check().map_err(|message| IoError::Format {
            path: path.to_path_buf(),
            line: None,
            column: Some("test_cell".into()),
            message: format!("test_cell.{message}"),
        })?;
    }
    Ok(tc)
}

/// The `[test_cell]` section of a parameter document (TOML or JSON), None when absent.
pub fn parse_test_cell(text: &str, path: &Path) -> Result<Option<TestCell>, IoError> {
    if text.trim_start().starts_with('{') {
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| IoError::Format {
            path: path.to_path_buf(),
            line: Some(e.line()),
            column: None,
            message: e.to_string(),
        })?;
        let Some(s) = v.get(SECTION) else {
            return Ok(None);
        };
        let tc: TestCell = serde_json::from_value(s.clone()).map_err(|e| IoError::Format {
            path: path.to_path_buf(),
            line: None,
            column: Some(SECTION.into()),
            message: e.to_string(),
        })?;
        return check(tc, path).map(Some);
    }
    let (_, Some(sec)) = split_toml(text) else {
        return Ok(None);
    };
    let doc: Doc = toml::from_str(&sec).map_err(|e| IoError::Format {
        path: path.to_path_buf(),
        line: e
            .span()
            .map(|s| sec[..s.start.min(sec.len())].lines().count().max(1)),
        column: None,
        message: e.message().to_string(),
    })?;
    check(doc.test_cell, path).map(Some)
}

/// Read the `[test_cell]` section of a parameter file (None when absent).
pub fn load_test_cell(path: &Path) -> Result<Option<TestCell>, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::File {
        path: path.to_path_buf(),
        source,
    })?;
    parse_test_cell(&text, path)
}

/// Write a parameter file atomically with the test-cell section after the model parameters
/// (TOML: a `[test_cell]` table; `.json`: a top-level key `"test_cell"`). An empty `tc` writes
/// the parameters alone.
pub fn save_params_with_test_cell(p: &Params, tc: &TestCell, path: &Path) -> Result<(), IoError> {
    let json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let text = params_with_test_cell_text(p, tc, json);
    super::output::write_atomic(path, text.as_bytes())
}

/// The text [`save_params_with_test_cell`] writes: TOML, or JSON when `json`.
pub fn params_with_test_cell_text(p: &Params, tc: &TestCell, json: bool) -> String {
    if json {
        let mut v = serde_json::to_value(p).expect("parameters serialize");
        if !tc.is_empty() {
            if let Some(o) = v.as_object_mut() {
                o.insert(
                    SECTION.into(),
                    serde_json::to_value(tc).expect("test cell serializes"),
                );
            }
        }
        serde_json::to_string_pretty(&v).expect("parameters serialize")
    } else {
        let mut s = super::params::to_toml(p);
        if !tc.is_empty() {
            s.push_str(
                "\n# Test-cell quantities estimated by `mvem tune` (not model parameters).\n\
                 # tau_me: dynamometer time constant tau_Me [s], eq. (76); tau_p_im, tau_p_em,\n\
                 # tau_w_c, tau_n_t: sensor time constants [s] of p_im, p_em, W_c, n_t\n",
            );
            s.push_str(&format!("[{SECTION}]\n"));
            s.push_str(&toml::to_string(tc).expect("test cell serializes"));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::params::parse_params;

    #[test]
    fn section_round_trips_and_params_ignore_it() {
        let dir = std::env::temp_dir().join(format!("mvem_tc_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = Params::published();
        let tc = TestCell {
            tau_me: Some(1.0016),
            ..TestCell::default()
        }
        .with_lags(SensorLags::TABLE6);
        for name in ["t.toml", "t.json"] {
            let f = dir.join(name);
            save_params_with_test_cell(&p, &tc, &f).unwrap();
            let text = std::fs::read_to_string(&f).unwrap();
            assert_eq!(parse_params(&text, &f).unwrap(), p, "{name}");
            assert_eq!(
                parse_test_cell(&text, &f).unwrap(),
                Some(tc.clone()),
                "{name}"
            );
            assert_eq!(tc.get("tau_me"), Some(1.0016));
            assert_eq!(tc.get("tau_p_em"), Some(0.02));
            assert_eq!(tc.get("tau_x"), None);
        }
        let plain = super::super::params::to_toml(&p);
        assert_eq!(parse_test_cell(&plain, Path::new("p.toml")).unwrap(), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn section_errors_name_the_field_and_keep_line_numbers() {
        let p = super::super::params::to_toml(&Params::published());
        let bad = format!("{p}\n[test_cell]\ntau_me = -1.0\n");
        let e = parse_test_cell(&bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("test_cell.tau_me = -1"), "{e}");
        let bad = format!("{p}\n[test_cell]\ntau_p_em = 0.5\n");
        let e = parse_test_cell(&bad, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("test_cell.tau_p_em = 0.5"), "{e}");
        let unknown = format!("{p}\n[test_cell]\ntau_mee = 1.0\n");
        let e = parse_test_cell(&unknown, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        // the line of the section (toml reports the table) or of the key
        let key = unknown.lines().count();
        assert!(
            e.contains("unknown field `tau_mee`")
                && (e.contains(&format!("line {key}")) || e.contains(&format!("line {}", key - 1))),
            "{e}"
        );
        // a section in the middle: an error after it keeps its line number
        let mid = format!(
            "[test_cell]\ntau_me = 1.0\n{}",
            p.replace("v_im = 0.022\n", "v_imm = 1\n")
        );
        let e = parse_params(&mid, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        // the loader names the line of the unknown key itself
        let want = mid.lines().position(|l| l.starts_with("v_imm")).unwrap() + 1;
        assert!(
            e.contains(&format!("line {want},")) || e.contains(&format!("line {want}:")),
            "{e}"
        );
    }
}
