//! A first manifest for a directory of a test cell's CSV files (`mvem campaign --data DIR
//! --init`): which file is the stationary one, each other file's kind, roles, sample rate and
//! steps, and units guessed where a column's values are outside its plausible range in mvem's
//! unit but inside it in another. Everything guessed is listed in notes for the user to check;
//! the draft is then loaded like any manifest.
//!
//! The guesses: a file with every stationary column (Table 5; `T_t` optional) is the stationary
//! file (the first in name order if several); a file with `t` and the actuator columns only is
//! an actuator set (role `actuator`); a file with the dynamic columns is a fuel-step set (roles
//! `dynamic`, `static`) when only u_delta steps, else a VGT/EGR set (role `static`, and
//! `dynamic` when sampled at 10 Hz or faster, as the paper's sets B and C); no set gets the
//! role `validation` (hold some back by hand). Files that are neither are skipped, with the
//! columns they lack.

use super::data::{
    dynamic_required, read, units_of, Column, DataError, DataSetInfo, Manifest, Role, StepKind,
    ACTUATOR_COLUMNS, DYNAMIC_COLUMNS, OPTIONAL_DYNAMIC_COLUMNS, STATIONARY_COLUMNS,
};
use super::summary::{manifest_name, median, median_step, roles_text, steps_in};
use crate::io::csv_columns::{header_names, read_columns};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A drafted manifest and what was guessed.
#[derive(Debug, Clone, PartialEq)]
pub struct ManifestDraft {
    /// The manifest.
    pub manifest: Manifest,
    /// What was guessed or skipped, one line each.
    pub notes: Vec<String>,
}

impl ManifestDraft {
    /// The manifest as TOML, the notes as comment lines first.
    pub fn toml(&self) -> Result<String, String> {
        let body = toml::to_string_pretty(&self.manifest).map_err(|e| e.to_string())?;
        let mut s = String::from(
            "# drafted by `mvem campaign --init`: check the roles, kinds and units below\n",
        );
        for n in &self.notes {
            s.push_str(&format!("# - {n}\n"));
        }
        s.push('\n');
        s.push_str(&body);
        Ok(s)
    }
}

/// The unit (other than mvem's) in which every value of `c` lies in its plausible range, if
/// the values are not all in range in mvem's unit.
fn guess_unit(c: &Column, values: &[f64]) -> Option<&'static str> {
    let in_range = |s: f64, o: f64| {
        values
            .iter()
            .all(|v| (c.min..=c.max).contains(&(s * v + o)))
    };
    if values.is_empty() || in_range(1.0, 0.0) {
        return None;
    }
    units_of(c.unit)
        .iter()
        .skip(1)
        .find(|&&(_, s, o)| in_range(s, o))
        .map(|u| u.0)
}

/// The values of the columns `cols` of a file (those it has), by column.
fn columns(text: &str, cols: &[Column]) -> Vec<(Column, Vec<f64>)> {
    let header = header_names(text).unwrap_or_default();
    let have: Vec<Column> = cols
        .iter()
        .filter(|c| header.iter().any(|h| h == c.name))
        .copied()
        .collect();
    let names: Vec<&str> = have.iter().map(|c| c.name).collect();
    match read_columns(text, &names) {
        Ok(rows) => have
            .iter()
            .enumerate()
            .map(|(k, c)| (*c, rows.iter().map(|r| r.1[k]).collect()))
            .collect(),
        Err(_) => Vec::new(),
    }
}

/// Draft a manifest for the CSV files in `dir` (see the module documentation). An error only
/// when the directory cannot be read or holds no stationary file.
pub fn draft_manifest(dir: &Path) -> Result<ManifestDraft, DataError> {
    let io = |source| DataError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut files: Vec<String> = std::fs::read_dir(dir)
        .map_err(io)?
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.to_ascii_lowercase().ends_with(".csv"))
        .collect();
    files.sort();
    let mut notes = Vec::new();
    let mut stationary: Option<String> = None;
    let mut sets = Vec::new();
    // every value of each column over the files, for the unit guesses
    let mut values: BTreeMap<&'static str, (Column, Vec<f64>)> = BTreeMap::new();
    let mut keep = |cols: Vec<(Column, Vec<f64>)>| {
        for (c, v) in cols {
            values.entry(c.name).or_insert((c, Vec::new())).1.extend(v);
        }
    };
    for f in &files {
        let text = read(&dir.join(f))?;
        let header = header_names(&text).unwrap_or_default();
        let has = |n: &str| header.iter().any(|h| h == n);
        let lacks = |cols: &mut dyn Iterator<Item = &str>| -> Vec<String> {
            cols.filter(|n| !has(n)).map(str::to_string).collect()
        };
        let st_missing = lacks(
            &mut STATIONARY_COLUMNS
                .iter()
                .map(|c| c.name)
                .filter(|n| *n != "T_t"),
        );
        if st_missing.is_empty() {
            if stationary.is_none() {
                stationary = Some(f.clone());
                keep(columns(&text, &STATIONARY_COLUMNS));
            } else {
                notes.push(format!("{f}: another stationary file, not used"));
            }
            continue;
        }
        if !has("t") {
            notes.push(format!(
                "{f}: skipped (no time column `t`; a stationary file lacks {})",
                st_missing.join(", ")
            ));
            continue;
        }
        let name = f[..f.len() - 4].to_string();
        let dyn_missing = lacks(
            &mut DYNAMIC_COLUMNS
                .iter()
                .map(|c| c.name)
                .filter(|n| !OPTIONAL_DYNAMIC_COLUMNS.contains(n)),
        );
        let act_missing = lacks(&mut ACTUATOR_COLUMNS.iter().copied());
        // t and every dynamic column the file has
        let cols = columns(&text, &dynamic_required(StepKind::VgtEgr));
        let get = |n: &str| cols.iter().find(|c| c.0.name == n).map(|c| &c.1);
        // the command steps, counted as `mvem campaign` counts them (tuning::summary)
        let steps = |names: &[&str]| -> usize {
            let chans: Vec<&[f64]> = names
                .iter()
                .filter_map(|n| get(n))
                .map(|v| &v[..])
                .collect();
            steps_in(&chans)
        };
        let (kind, roles, steps) = if dyn_missing.is_empty() {
            let fuel = steps(&["u_delta"]);
            let air = steps(&["u_egr", "u_vgt"]);
            if fuel > 0 && air == 0 {
                (StepKind::Fuel, vec![Role::Dynamic, Role::Static], fuel)
            } else {
                (
                    StepKind::VgtEgr,
                    vec![Role::Static],
                    steps(&["u_egr", "u_vgt", "u_delta"]),
                )
            }
        } else if act_missing.is_empty() {
            (
                StepKind::Actuator,
                vec![Role::Actuator],
                steps(&["u_egr", "u_vgt"]),
            )
        } else {
            notes.push(format!(
                "{f}: skipped (a dynamic set lacks {}; an actuator set lacks {})",
                dyn_missing.join(", "),
                act_missing.join(", ")
            ));
            continue;
        };
        let dt = get("t").map_or(0.0, |t| median_step(t));
        let rate = Some(dt).filter(|d| *d > 0.0).map_or(1.0, |d| {
            let r = 1.0 / d;
            // to 6 significant digits
            let scale = 10f64.powi(5 - r.log10().floor() as i32);
            (r * scale).round() / scale
        });
        let mut roles = roles;
        if kind == StepKind::VgtEgr && rate >= 10.0 {
            roles.push(Role::Dynamic);
        }
        let speed = get("n_e")
            .and_then(|n| median(n.clone()))
            .filter(|s| (300.0..=6000.0).contains(s))
            .map(f64::round);
        notes.push(format!(
            "{f}: set {name}, kind {}, roles {} ({steps} command steps, {rate} Hz)",
            manifest_name(&kind),
            roles_text(&roles)
        ));
        keep(cols.into_iter().filter(|c| c.0.name != "t").collect());
        sets.push(DataSetInfo {
            name,
            roles,
            kind,
            file: f.clone(),
            sample_rate_hz: rate,
            speed_rpm: if kind == StepKind::Actuator {
                None
            } else {
                speed
            },
            load_pct: None,
            steps,
        });
    }
    let Some(stationary) = stationary else {
        return Err(DataError::Format {
            path: dir.to_path_buf(),
            message: format!(
                "no stationary file among {} CSV files (one with the columns {} is needed; \
                 docs/tuning-data.md)",
                files.len(),
                STATIONARY_COLUMNS
                    .iter()
                    .map(|c| c.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    };
    let mut units = BTreeMap::new();
    for (name, (c, v)) in &values {
        if let Some(u) = guess_unit(c, v) {
            notes.push(format!(
                "{name}: in {u}? (its values lie outside {}..{} {} but inside in {u})",
                c.min, c.max, c.unit
            ));
            units.insert(name.to_string(), u.to_string());
        }
    }
    if !sets.iter().any(|s| s.roles.contains(&Role::Validation)) {
        notes.push(
            "no set has the role \"validation\": give it to sets you hold back from the tuning"
                .into(),
        );
    }
    Ok(ManifestDraft {
        manifest: Manifest {
            stationary,
            true_params: None,
            true_tau_me_s: None,
            true_sensor_lags_s: None,
            description: format!(
                "drafted by mvem campaign --init from {} CSV files",
                files.len()
            ),
            columns: BTreeMap::new(),
            units,
            datasets: sets,
        },
        notes,
    })
}

/// Why [`write_draft`] wrote nothing.
#[derive(Debug)]
pub enum WriteDraftError {
    /// `manifest.toml` exists and was not to be replaced (its path).
    Exists(PathBuf),
    /// The directory could not be drafted ([`draft_manifest`]).
    Data(DataError),
    /// The draft could not be serialized or written.
    Write(String),
}

/// Draft `dir/manifest.toml` ([`draft_manifest`]) and write it atomically, replacing an
/// existing one only when `replace`; the draft (its notes say what was guessed).
pub fn write_draft(dir: &Path, replace: bool) -> Result<ManifestDraft, WriteDraftError> {
    let path = dir.join("manifest.toml");
    if path.exists() && !replace {
        return Err(WriteDraftError::Exists(path));
    }
    let d = draft_manifest(dir).map_err(WriteDraftError::Data)?;
    let text = d.toml().map_err(WriteDraftError::Write)?;
    crate::io::output::write_atomic(&path, text.as_bytes())
        .map_err(|e| WriteDraftError::Write(e.to_string()))?;
    Ok(d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;
    use crate::tuning::data::{load_campaign, save_campaign};
    use crate::tuning::lab::{campaign, LabOptions};

    #[test]
    fn a_lab_campaign_without_its_manifest_is_drafted_back() {
        let opts = LabOptions {
            max_steps: Some(3),
            sets: Some(vec!["B".into(), "G".into(), "I".into(), "J".into()]),
            ..LabOptions::default()
        };
        let (c, _) = campaign(&Params::published(), &opts).unwrap();
        let dir = tempfile::tempdir().unwrap();
        save_campaign(dir.path(), &c).unwrap();
        // the test cell logs p_im in kPa (in every file): the draft guesses the unit
        let files = std::iter::once(&c.manifest.stationary)
            .chain(c.manifest.datasets.iter().map(|s| &s.file));
        for f in files {
            let path = dir.path().join(f);
            let text = std::fs::read_to_string(&path).unwrap();
            let mut lines = text.lines();
            let header: Vec<&str> = lines.next().unwrap().split(',').collect();
            let Some(k) = header.iter().position(|h| *h == "p_im") else {
                continue;
            };
            let mut out = vec![header.join(",")];
            for l in lines {
                let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
                f[k] = format!("{:?}", f[k].parse::<f64>().unwrap() / 1e3);
                out.push(f.join(","));
            }
            std::fs::write(&path, out.join("\n") + "\n").unwrap();
        }
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        std::fs::write(dir.path().join("notes.csv"), "a,b\n1,2\n").unwrap();

        let d = draft_manifest(dir.path()).unwrap();
        let m = &d.manifest;
        assert_eq!(m.stationary, c.manifest.stationary);
        assert_eq!(m.units.get("p_im").map(String::as_str), Some("kPa"));
        assert_eq!(m.units.len(), 1, "{:?}", m.units);
        let by_name = |n: &str| m.datasets.iter().find(|s| s.name == n).unwrap();
        for orig in &c.manifest.datasets {
            let s = by_name(&orig.name);
            assert_eq!(s.kind, orig.kind, "{}", orig.name);
            assert_eq!(s.steps, orig.steps, "{}", orig.name);
            assert_eq!(s.sample_rate_hz, orig.sample_rate_hz, "{}", orig.name);
        }
        assert_eq!(by_name("I").roles, [Role::Dynamic, Role::Static]);
        assert_eq!(by_name("J").roles, [Role::Actuator]);
        // B at 100 Hz tunes the dynamics, G at 1 Hz only the statics
        assert_eq!(by_name("B").roles, [Role::Static, Role::Dynamic]);
        assert_eq!(by_name("G").roles, [Role::Static]);
        assert!(d.notes.iter().any(|n| n.starts_with("notes.csv: skipped")));
        // written and loaded like any manifest, with the kPa converted back
        std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        for (a, b) in back.stationary.iter().zip(&c.stationary) {
            assert!((a.p_im - b.p_im).abs() <= 1e-9 * b.p_im);
        }
        assert_eq!(back.dynamic.len(), c.dynamic.len());
        // no stationary file: an error that lists what one needs
        let empty = tempfile::tempdir().unwrap();
        let e = draft_manifest(empty.path()).unwrap_err().to_string();
        assert!(e.contains("no stationary file among 0 CSV files"), "{e}");
    }
}
