//! A first manifest for a directory of a test cell's CSV files (`mvem campaign --data DIR
//! --init`): which file is the stationary one, each other file's kind, roles, sample rate and
//! steps, and units guessed where a column's values are outside its plausible range in mvem's
//! unit but inside it in another. Everything guessed is listed in notes for the user to check;
//! the draft is then loaded like any manifest.
//!
//! The guesses: a file with every stationary column (Table 5; `T_t` optional) is the stationary
//! file (the first in name order if several); a file with `t` and the actuator columns only is
//! an actuator set (role `actuator`); a file with the dynamic columns is a fuel-step set when
//! only u_delta steps, else a VGT/EGR set; both get the role `static`, and `dynamic` when
//! sampled at 10 Hz or faster ([`DYNAMIC_MIN_RATE_HZ`]: the paper's B, C and I; its 1 Hz sets,
//! fuel steps V too, only show settled levels). With at least three static sets, one that is
//! only static (a slow fuel-step set first, as the paper's V) is held back with the role
//! `validation` alone. Files that are neither are skipped, with the columns they lack.
//!
//! Headers that are not mvem's names are matched when they differ only in case, spaces,
//! underscores, hyphens and dots (`P_IM`, `p im`, `Time` for `t`) and may carry a unit in
//! brackets or parentheses (`p_im [kPa]`, `T_em (degC)`): the draft's `[columns]` then maps the
//! column to the header and `[units]` takes a unit it knows (an unknown one is a note, and the
//! column's unit is guessed from its values as for a bare header). `[columns]` holds one header
//! per column for all files, so a file that heads a column differently from a file drafted
//! before it is skipped, naming both. Files that give a column in different units, each file
//! saying its own (`P_IM [kPa]` in one, `P_IM [bar]` or `P_IM` over a units row `bar` in
//! another), are drafted together without the column in `[units]`: the loader reads each
//! file's unit from its header or units row.

use super::data::{
    campaign_columns, conversion, dynamic_required, known_unit, read, times_look_like_ms,
    unit_names, units_of, Column, DataError, DataSetInfo, Manifest, Role, StepKind,
    ACTUATOR_COLUMNS, DYNAMIC_COLUMNS, OPTIONAL_DYNAMIC_COLUMNS, STATIONARY_COLUMNS,
};
use super::summary::{manifest_name, median, median_step, roles_text, steps_in};
use crate::io::csv_columns::{header_names, read_columns_with_units, split_unit};
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

/// The units (other than mvem's, in [`units_of`] order) in which every value of `c` lies in
/// its plausible range, if the values are not all in range in mvem's unit: the first is the
/// guess, the others fit the ranges as well (W_c of 90 logged in kg/h is in range in g/s too).
fn guess_units(c: &Column, values: &[f64]) -> Vec<&'static str> {
    let in_range = |s: f64, o: f64| {
        values
            .iter()
            .all(|v| (c.min..=c.max).contains(&(s * v + o)))
    };
    if values.is_empty() || in_range(1.0, 0.0) {
        return Vec::new();
    }
    units_of(c.unit)
        .iter()
        .skip(1)
        .filter(|&&(_, s, o)| in_range(s, o))
        .map(|u| u.0)
        .collect()
}

/// Commands and positions in % that a test cell may log as fractions 0..1 (`[units]` `-`).
const PERCENT_COLUMNS: [&str; 4] = ["u_egr", "u_vgt", "u_egr_pos", "u_vgt_pos"];

/// A header name without case, spaces, underscores, hyphens and dots.
fn normalized(name: &str) -> String {
    name.chars()
        .filter(|c| !matches!(c, ' ' | '_' | '-' | '.'))
        .flat_map(char::to_lowercase)
        .collect()
}

/// How a file heads one of mvem's columns.
#[derive(Debug, Clone, PartialEq)]
struct Heading {
    /// The header name in the file.
    header: String,
    /// The unit the header gives in brackets, or the file's units row, where mvem knows it
    /// (and it is not mvem's).
    unit: Option<&'static str>,
    /// Whether the units row gives a unit mvem does not know (the loader refuses that unless
    /// `[units]` declares the column).
    unknown_in_row: bool,
    /// Whether the file gives the column a unit mvem knows (its brackets or its units row),
    /// mvem's own included: `t [s]` is a time in seconds, a bare `t` one whose unit is guessed.
    given: bool,
    /// The header's name before a unit mvem knows in brackets that end it (`P_IM` of
    /// `P_IM [kPa]`): the loader finds such a header by that name in each file.
    base: Option<String>,
    /// Whether the files drafted head the column alike but not with the same text (`M_E [Nm]`
    /// in one, `M_E` in another): `[columns]` then gets the name without the brackets.
    mixed: bool,
}

impl Heading {
    /// The header and what the file says of its unit, for messages: "`p_im [kPa]` (in kPa)".
    fn describe(&self) -> String {
        let unit = match (self.unit, self.given, self.unknown_in_row) {
            (Some(u), _, _) => format!(" (in {u})"),
            (None, true, _) => " (in mvem's unit)".to_string(),
            (None, false, true) => " (its units row's unit not known)".to_string(),
            (None, false, false) => " (no unit)".to_string(),
        };
        format!("`{}`{unit}", self.header)
    }

    /// Whether `self` and `other` head their column alike for the manifest, which holds one
    /// header per column: the same header, or the same name before a known unit in brackets
    /// ([`Heading::name`]: the loader finds `P_IM [kPa]` by `P_IM` in each file) where both
    /// files give the unit (a bare header's unit may be guessed from its values); and the same
    /// unit, mvem's own or none being the same (where the files differ only in an unknown
    /// units-row unit, `[units]` declares mvem's unit, which serves both), or units that both
    /// files give themselves (in brackets or a units row: the loader reads each file's, and
    /// `[units]` then declares none for the column).
    fn alike(&self, other: &Heading) -> bool {
        let named = self.header == other.header
            || (self.name() == other.name() && self.given && other.given);
        named && (self.unit == other.unit || (self.given && other.given))
    }

    /// The header without a known unit in brackets that ends it (`P_IM` of `P_IM [kPa]`), else
    /// the header.
    fn name(&self) -> &str {
        self.base.as_deref().unwrap_or(&self.header)
    }

    /// What `[columns]` gives: the header, or its name without the brackets where the files
    /// head the column differently ([`Heading::mixed`]).
    fn columns_entry(&self) -> &str {
        if self.mixed {
            self.name()
        } else {
            &self.header
        }
    }
}

/// mvem's column a header names (see the module documentation), the unit in its brackets where
/// known (None for mvem's own unit), and a note for a bracketed unit mvem does not know.
fn match_header(h: &str) -> Option<(Column, Option<&'static str>, Option<String>, bool)> {
    let h = h.trim();
    let (base, unit) = match split_unit(h) {
        s if s.closed => (s.name, s.unit),
        _ => (h, None),
    };
    let key = normalized(base);
    let key = if key == "time" { "t".to_string() } else { key };
    let c = campaign_columns().find(|c| normalized(c.name) == key)?;
    let Some(u) = unit else {
        return Some((c, None, None, false));
    };
    let (unit, note) = unit_of_column(&c, u, h);
    let given = note.is_none();
    Some((c, unit, note, given))
}

/// The unit `u` that `place` (a header, a units row) gives column `c`, as [`Heading::unit`]
/// takes it: `None` for mvem's own unit, and a note for a unit mvem does not know (the column's
/// unit is then guessed from its values).
fn unit_of_column(c: &Column, u: &str, place: &str) -> (Option<&'static str>, Option<String>) {
    match known_unit(c.unit, u) {
        Some(k) if k.0 == c.unit || (k.1 == 1.0 && k.2 == 0.0) => (None, None),
        Some(k) => (Some(k.0), None),
        None => (
            None,
            Some(format!(
                "{place}: unit `{u}` not known for {} (mvem's unit {}; known: {}), guessed from \
                 the values",
                c.name,
                c.unit,
                unit_names(c.unit)
            )),
        ),
    }
}

/// The units a file's units row (a row of units under the header, [`read_columns_with_units`])
/// gives the columns of `heads` that their headers give none, as the headers' brackets are
/// taken ([`unit_of_column`]); notes for unknown units and for a units-row unit that
/// contradicts the header's (the loader refuses the file then).
fn units_from_row(f: &str, text: &str, heads: &mut BTreeMap<&'static str, Heading>) -> Vec<String> {
    let names: Vec<&str> = heads.values().map(|g| g.header.as_str()).collect();
    let Some((line, cells)) = read_columns_with_units(text, &names).ok().and_then(|r| r.0) else {
        return Vec::new();
    };
    let mut notes = Vec::new();
    for ((name, g), cell) in heads.iter_mut().zip(cells) {
        let cell = cell.trim();
        let Some(c) = campaign_columns()
            .find(|c| c.name == *name)
            .filter(|_| !cell.is_empty())
        else {
            continue;
        };
        let place = format!("{f}: units row (line {line}), column `{}`", g.header);
        let (unit, note) = unit_of_column(&c, cell, &place);
        match split_unit(&g.header)
            .closed_unit()
            .and_then(|b| known_unit(c.unit, b))
        {
            Some(b) if known_unit(c.unit, cell).is_some_and(|r| (r.1, r.2) != (b.1, b.2)) => {
                notes.push(format!(
                    "{place}: `{cell}`, but its header says `{}`: the campaign cannot be loaded \
                     until they agree",
                    b.0
                ));
            }
            Some(_) => {}
            None => {
                g.unknown_in_row = note.is_some();
                g.given = note.is_none();
                notes.extend(note);
                g.unit = unit;
            }
        }
    }
    notes
}

/// How a file with `header` heads mvem's columns: exact names first, then matched ones
/// ([`match_header`]); notes for unknown units and for a column headed twice.
fn headings(f: &str, header: &[String]) -> (BTreeMap<&'static str, Heading>, Vec<String>) {
    let mut map = BTreeMap::new();
    let mut notes = Vec::new();
    for h in header {
        if let Some(c) = campaign_columns().find(|c| c.name == h) {
            map.insert(
                c.name,
                Heading {
                    header: h.clone(),
                    unit: None,
                    unknown_in_row: false,
                    given: false,
                    base: None,
                    mixed: false,
                },
            );
        }
    }
    for h in header {
        if map.values().any(|g| &g.header == h) {
            continue;
        }
        let Some((c, unit, note, given)) = match_header(h) else {
            continue;
        };
        if let Some(g) = map.get(c.name) {
            notes.push(format!(
                "{f}: column `{h}` not used (`{}` already gives {})",
                g.header, c.name
            ));
            continue;
        }
        // a known unit in brackets that end the header (not `p_im [kPa] avg`)
        let split = split_unit(h.trim());
        let base = (given && split.closed_unit().is_some()).then(|| split.name.trim().to_string());
        notes.extend(note.map(|n| format!("{f}: {n}")));
        map.insert(
            c.name,
            Heading {
                header: h.clone(),
                unit,
                unknown_in_row: false,
                given,
                base,
                mixed: false,
            },
        );
    }
    (map, notes)
}

/// The values of the columns `cols` of a file (those it heads), by column: in mvem's units
/// where the header gives a unit, else as written.
fn columns(
    text: &str,
    cols: &[Column],
    heads: &BTreeMap<&'static str, Heading>,
) -> Vec<(Column, Vec<f64>)> {
    let have: Vec<Column> = cols
        .iter()
        .filter(|c| heads.contains_key(c.name))
        .copied()
        .collect();
    let names: Vec<&str> = have.iter().map(|c| heads[c.name].header.as_str()).collect();
    match read_columns_with_units(text, &names) {
        Ok((_, rows)) => have
            .iter()
            .enumerate()
            .map(|(k, c)| {
                // a unit of the header is one of the column's (match_header): converted as
                // the loader converts a [units] entry
                let (a, b) = heads[c.name]
                    .unit
                    .and_then(|u| conversion(c.name, u).ok())
                    .unwrap_or((1.0, 0.0));
                (*c, rows.iter().map(|r| a * r.1[k] + b).collect())
            })
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
    // the stationary file first (the first one in name order): [columns] and [units] hold the
    // headers and units of the files drafted first, and a file that heads a column otherwise is
    // skipped, so a stationary file sorted after the dynamic files (`steady.csv` after
    // `run_B.csv`) was skipped for heading a column otherwise than they do, and the draft
    // failed with "no stationary file"
    let lacks_stationary = |heads: &BTreeMap<&'static str, Heading>| -> Vec<String> {
        (STATIONARY_COLUMNS.iter())
            .map(|c| c.name)
            .filter(|n| *n != "T_t" && !heads.contains_key(n))
            .map(str::to_string)
            .collect()
    };
    // the files read in this search are kept for the draft below, which would read them again
    let mut read_before: BTreeMap<String, String> = BTreeMap::new();
    let first_stationary = files.iter().position(|f| {
        read(&dir.join(f)).is_ok_and(|text| {
            let header = header_names(&text).unwrap_or_default();
            let found = lacks_stationary(&headings(f, &header).0).is_empty();
            read_before.insert(f.clone(), text);
            found
        })
    });
    if let Some(k) = first_stationary {
        let f = files.remove(k);
        files.insert(0, f);
    }
    let mut notes = Vec::new();
    let mut stationary: Option<String> = None;
    // the file nearest to a stationary file (the fewest stationary columns missing): its name,
    // the columns it lacks and its header, for the error when there is none
    let mut nearest: Option<(String, Vec<String>, Vec<String>)> = None;
    let mut sets = Vec::new();
    // every value of each column over the files, for the unit guesses
    let mut values: BTreeMap<&'static str, (Column, Vec<f64>)> = BTreeMap::new();
    let mut keep = |cols: Vec<(Column, Vec<f64>)>| {
        for (c, v) in cols {
            values.entry(c.name).or_insert((c, Vec::new())).1.extend(v);
        }
    };
    // the dynamic files whose bare times look like ms (with why) and those that do not
    let (mut ms_times, mut s_times) = (Vec::new(), Vec::new());
    // the dynamic files whose header or units row says their time is in seconds
    let mut s_given = Vec::new();
    // the header and unit of each column, from the first file drafted that heads it
    let mut headed: BTreeMap<&'static str, (Heading, String)> = BTreeMap::new();
    // the unit each file drafted gives each column (None: mvem's, or none), for the note of a
    // column whose files give different units
    let mut file_units: BTreeMap<&'static str, Vec<(String, Option<&'static str>)>> =
        BTreeMap::new();
    for f in &files {
        let text = match read_before.remove(f) {
            Some(text) => text,
            None => read(&dir.join(f))?,
        };
        let header = header_names(&text).unwrap_or_default();
        let (mut heads, mut head_notes) = headings(f, &header);
        head_notes.extend(units_from_row(f, &text, &mut heads));
        let st_missing = lacks_stationary(&heads);
        if nearest
            .as_ref()
            .is_none_or(|n| st_missing.len() < n.1.len())
        {
            nearest = Some((f.clone(), st_missing.clone(), header.clone()));
        }
        let clash = heads.iter().find_map(|(name, g)| {
            headed
                .get(name)
                .filter(|(h, _)| !h.alike(g))
                .map(|(h, other)| (name, g, h, other))
        });
        if let Some((name, g, h, other)) = clash {
            notes.push(format!(
                "{f}: skipped (heads {name} {}, {other} heads it {}: [columns] and [units] \
                 hold one header and unit per column; files may give a column in different \
                 units where each gives its own, in its header's brackets or a units row)",
                g.describe(),
                h.describe()
            ));
            continue;
        }
        notes.extend(head_notes);
        let accept = |headed: &mut BTreeMap<&'static str, (Heading, String)>,
                      file_units: &mut BTreeMap<
            &'static str,
            Vec<(String, Option<&'static str>)>,
        >| {
            for (name, g) in &heads {
                let e = headed.entry(name).or_insert_with(|| (g.clone(), f.clone()));
                e.0.mixed |= e.0.header != g.header;
                // files that may each give their own unit ([`Heading::alike`])
                file_units
                    .entry(name)
                    .or_default()
                    .push((f.clone(), g.unit));
                // a units-row unit mvem does not know in any file: `[units]` declares the
                // column's unit for all of them
                e.0.unknown_in_row |= g.unknown_in_row;
            }
        };
        let has = |n: &str| heads.contains_key(n);
        let lacks = |cols: &mut dyn Iterator<Item = &str>| -> Vec<String> {
            cols.filter(|n| !has(n)).map(str::to_string).collect()
        };
        if st_missing.is_empty() {
            if stationary.is_none() {
                stationary = Some(f.clone());
                keep(columns(&text, &STATIONARY_COLUMNS, &heads));
                accept(&mut headed, &mut file_units);
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
        let mut cols = columns(&text, &dynamic_required(StepKind::VgtEgr), &heads);
        // a bare time column whose times only make sense in ms (the loader's check,
        // data::times_look_like_ms): guessed in ms, as a bare column's unit is guessed from its
        // values, and the rate computed in seconds
        if heads.get("t").is_some_and(|g| g.given && g.unit.is_none()) {
            // in seconds by its header or units row
            s_given.push(f.clone());
        } else if heads.get("t").is_some_and(|g| g.unit.is_none()) {
            if let Some(t) = cols.iter_mut().find(|c| c.0.name == "t") {
                match times_look_like_ms(&t.1, None) {
                    Some((_, why)) => {
                        t.1.iter_mut().for_each(|x| *x *= 1e-3);
                        ms_times.push(format!("{f}: {why}"));
                    }
                    None => s_times.push(f.clone()),
                }
            }
        }
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
                (StepKind::Fuel, vec![Role::Static], fuel)
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
        // a set sampled slower than DYNAMIC_MIN_RATE_HZ shows the settled levels of its
        // steps, not their responses: static only (step 5), as the paper's 1 Hz sets
        if kind != StepKind::Actuator && rate >= DYNAMIC_MIN_RATE_HZ {
            roles.insert(usize::from(kind == StepKind::VgtEgr), Role::Dynamic);
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
        accept(&mut headed, &mut file_units);
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
            steps: Some(steps),
        });
    }
    let Some(stationary) = stationary else {
        // the nearest file: what it lacks and what it heads, so that a test cell's own names
        // can be mapped ([columns] of a manifest written by hand); a file that has every
        // column but was skipped says why in its note
        let nearest = match &nearest {
            Some((f, missing, header)) if !missing.is_empty() => format!(
                "; nearest: {f}, which lacks {} among its columns {} (where it names them \
                 otherwise, write manifest.toml by hand with a [columns] table of mvem's name \
                 = the file's header, e.g. p_im = \"MAP\")",
                missing.join(", "),
                header.join(", "),
            ),
            Some((f, _, _)) => notes
                .iter()
                .find(|n| n.starts_with(&format!("{f}: skipped")))
                .map_or(String::new(), |n| format!("; {n}")),
            None => String::new(),
        };
        return Err(DataError::Format {
            path: dir.to_path_buf(),
            message: format!(
                "no stationary file among {} CSV files (one with the columns {} is needed, \
                 T_t optional; docs/tuning-data.md){nearest}",
                files.len(),
                STATIONARY_COLUMNS
                    .iter()
                    .map(|c| c.name)
                    .filter(|n| *n != "T_t")
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    };
    let mut units = BTreeMap::new();
    let mut renamed = BTreeMap::new();
    for (name, (g, _)) in &headed {
        let h = g.columns_entry();
        if g.mixed {
            notes.push(format!(
                "{name}: headed `{h}`, with its unit in brackets in some files (the loader \
                 finds `{h} [unit]` in each file)"
            ));
        }
        if h != *name {
            if !g.mixed {
                notes.push(format!("{name}: headed `{h}`"));
            }
            renamed.insert(name.to_string(), h.to_string());
        }
    }
    // whether the files drafted give the column `name` in different units, each its own
    let units_differ =
        |name: &str| (file_units.get(name)).is_some_and(|v| v.iter().any(|(_, u)| *u != v[0].1));
    // a column the files give in different units, each its own: no [units] entry (it would
    // contradict the files in another unit), the note says each file's
    let per_file = |name: &str, mvem_unit: &str| -> Option<String> {
        let (g, _) = headed.get(name).filter(|_| units_differ(name))?;
        let mut by_unit: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
        for (f, u) in file_units.get(name).into_iter().flatten() {
            by_unit.entry(u.unwrap_or(mvem_unit)).or_default().push(f);
        }
        let each: Vec<String> = (by_unit.iter())
            .map(|(u, files)| format!("{u} in {}", files.join(", ")))
            .collect();
        Some(format!(
            "{name}: each file in its own unit ({}; headed `{}`), not in [units]: the loader \
             reads each file's header or units row",
            each.join("; "),
            g.columns_entry()
        ))
    };
    for (name, (c, v)) in &values {
        if let Some(note) = per_file(name, c.unit) {
            // the values are converted by each file's unit: they must lie in the range
            notes.push(match v.iter().find(|x| !(c.min..=c.max).contains(*x)) {
                None => note,
                Some(x) => format!(
                    "{note}; but a value is {x} {} in mvem's unit, outside {}..{}: check the \
                     units",
                    c.unit, c.min, c.max
                ),
            });
            continue;
        }
        if let Some(u) = headed.get(name).and_then(|(g, _)| g.unit) {
            // the header's unit (the values are converted): they must lie in the range
            let out = v.iter().find(|x| !(c.min..=c.max).contains(*x));
            notes.push(match out {
                None => format!("{name}: in {u} (its header says so)"),
                Some(x) => format!(
                    "{name}: in {u} (its header says so), but a value is {x} {} in mvem's unit, \
                     outside {}..{}: check the unit",
                    c.unit, c.min, c.max
                ),
            });
            units.insert(name.to_string(), u.to_string());
        } else if let Some((&u, others)) = guess_units(c, v).split_first() {
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                    (a.min(*x), b.max(*x))
                });
            notes.push(format!(
                "{name}: in {u}? (its values, {lo}..{hi}, lie outside {}..{} {} but inside in \
                 {u}{})",
                c.min,
                c.max,
                c.unit,
                if others.is_empty() {
                    String::new()
                } else {
                    format!(
                        "; also inside in {}: the first unit that fits is the guess, check the \
                         test cell's",
                        others.join(", ")
                    )
                }
            ));
            units.insert(name.to_string(), u.to_string());
        } else if PERCENT_COLUMNS.contains(name)
            && v.iter().all(|x| (0.0..=1.0).contains(x))
            && v.iter().any(|x| *x > 0.0)
        {
            // in range as % too, so no unit is guessed: a fraction 0..1 would be read as 0-1 %
            notes.push(format!(
                "{name}: every value lies in 0..1: if the test cell logs it as a fraction, not \
                 in %, set [units] {name} = \"-\" (read as it is, 1 means 1 %)"
            ));
        }
        // a unit of the units row mvem does not know, no other guessed: declared in mvem's
        // unit, which the loader takes over the row's (its values lie in range in it)
        if !units.contains_key(*name) && headed.get(name).is_some_and(|(g, _)| g.unknown_in_row) {
            notes.push(format!(
                "{name}: in {} (its values lie in range; the units row's unit is not known)",
                c.unit
            ));
            units.insert(name.to_string(), c.unit.to_string());
        }
    }
    // a unit a header gives for a column whose values are not checked against a range above:
    // the time (`t [ms]`, `Time [ms]`), which the sample rates were computed in
    for (name, (g, _)) in &headed {
        if units_differ(name) {
            if !values.contains_key(name) {
                let mvem_unit = campaign_columns()
                    .find(|c| c.name == *name)
                    .map_or("", |c| c.unit);
                notes.extend(per_file(name, mvem_unit));
            }
            continue;
        }
        if let (Some(u), false) = (g.unit, units.contains_key(*name)) {
            notes.push(format!("{name}: in {u} (its header says so)"));
            units.insert(name.to_string(), u.to_string());
        }
    }
    if !ms_times.is_empty() && !units.contains_key("t") {
        if s_times.is_empty() && s_given.is_empty() {
            notes.push(format!("t: in ms? ({})", ms_times.join("; ")));
            units.insert("t".to_string(), "ms".to_string());
        } else {
            // [units] holds one unit for all files: `t = "ms"` would read the files in seconds
            // 1000 times too slow (the loader only warns of their rates then) or contradict
            // their own unit; without it the loader refuses the files in ms, naming them
            let seconds: Vec<String> = [
                (&s_given, "as a header or units row says"),
                (&s_times, "as their values look"),
            ]
            .iter()
            .filter(|(files, _)| !files.is_empty())
            .map(|(files, why)| format!("{} ({why})", files.join(", ")))
            .collect();
            notes.push(format!(
                "t: not drafted: the times of some files look like ms ({}), but those of {} are \
                 in seconds, and [units] holds one unit for all files: give the files in ms \
                 their unit (a header `t [ms]` or a units row) or convert them to seconds (the \
                 loader refuses them until then)",
                ms_times.join("; "),
                seconds.join("; ")
            ));
        }
    }
    notes.push(hold_back_for_validation(&mut sets));
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
            columns: renamed,
            units,
            datasets: sets,
        },
        notes,
    })
}

/// The slowest sample rate \[Hz\] at which `campaign --init` gives a set the role `dynamic`:
/// the paper's dynamic sets (B, C, I) are sampled at 10-100 Hz, its 1 Hz sets only show the
/// settled levels of their steps (roles static and validation, Table 1), and the fastest time
/// constants steps 3-4 fit (the manifolds', the turbo's, tau_Me about 1 s) need several
/// samples within a step's response.
pub const DYNAMIC_MIN_RATE_HZ: f64 = 10.0;

/// The fewest static-role sets that leave one to hold back for validation: step 5 then still
/// has two operating points.
pub const VALIDATION_MIN_STATIC_SETS: usize = 3;

/// Hold one set back for validation (its roles become only `validation`) when enough remain
/// for the tuning: of the sets that are static only (not needed by steps 2-4), a slow fuel-step
/// set (the paper's V) if there is one, else the last VGT/EGR set in name order, and only when
/// at least [`VALIDATION_MIN_STATIC_SETS`] sets have the role static. A note says which and
/// why, or why none.
fn hold_back_for_validation(sets: &mut [DataSetInfo]) -> String {
    let statics = sets
        .iter()
        .filter(|s| s.roles.contains(&Role::Static))
        .count();
    let only_static = |s: &DataSetInfo| s.roles == [Role::Static];
    let pick = sets
        .iter()
        .rposition(|s| only_static(s) && s.kind == StepKind::Fuel)
        .or_else(|| sets.iter().rposition(only_static));
    match pick {
        Some(k) if statics >= VALIDATION_MIN_STATIC_SETS => {
            sets[k].roles = vec![Role::Validation];
            format!(
                "set {} held back for validation (role \"validation\" only; {} of {statics} sets \
                 with the role \"static\" remain for step 5): give the role to other sets you \
                 hold back, or \"static\" back to tune on it",
                sets[k].name,
                statics - 1
            )
        }
        _ => format!(
            "no set has the role \"validation\" ({statics} with the role \"static\", a set is \
             held back from {VALIDATION_MIN_STATIC_SETS} on): give it to sets you hold back from \
             the tuning"
        ),
    }
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
            sets: Some(vec![
                "B".into(),
                "G".into(),
                "I".into(),
                "J".into(),
                "V".into(),
            ]),
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
        // the 1 Hz fuel steps of V show settled levels, not tau_Me's response: not dynamic
        // (it was [dynamic, static]); with four static sets it is held back for validation,
        // as the paper's V (Table 1)
        assert_eq!(by_name("V").roles, [Role::Validation]);
        assert!(
            d.notes.iter().any(|n| n.starts_with(
                "set V held back for validation (role \"validation\" only; 3 of 4 sets with \
                 the role \"static\" remain for step 5)"
            )),
            "{:?}",
            d.notes
        );
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

    /// A test cell's stationary log under its own names: the draft's error names the nearest
    /// file, the columns it lacks and its header, and how to map them (before, it listed the
    /// columns needed, T_t among them, and no file: the user could not tell which file came
    /// near or what to rename).
    #[test]
    fn no_stationary_file_names_the_nearest_and_what_it_lacks() {
        let dir = tempfile::tempdir().unwrap();
        let w = |name: &str, text: &str| std::fs::write(dir.path().join(name), text).unwrap();
        w(
            "steady_points.csv",
            "n_e;u_delta;M_e;Boost [kPa];p_em [kPa];p_c [kPa];p_amb [kPa];T_amb [degC];\
             T_im [degC];T_em [degC];T_c [degC];n_t;MAF [g/s];u_egr;u_vgt;x_egr\n\
             1200;100;800;150;160;151;101;25;30;500;80;60000;250;30;60;0,1\n",
        );
        w("notes.csv", "a,b\n1,2\n");
        let e = draft_manifest(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains(
                "no stationary file among 2 CSV files (one with the columns M_e, n_e, n_t, \
                 p_amb, p_c, p_em, p_im, T_amb, T_c, T_em, T_im, u_egr, u_vgt, u_delta, W_c, \
                 x_egr is needed, T_t optional; docs/tuning-data.md); nearest: \
                 steady_points.csv, which lacks p_im, W_c among its columns n_e, u_delta, M_e, \
                 Boost [kPa], p_em [kPa], p_c [kPa], p_amb [kPa], T_amb [degC], T_im [degC], \
                 T_em [degC], T_c [degC], n_t, MAF [g/s], u_egr, u_vgt, x_egr (where it names \
                 them otherwise, write manifest.toml by hand with a [columns] table"
            ),
            "{e}"
        );
    }

    #[test]
    fn one_static_only_set_is_held_back_for_validation_when_three_remain() {
        let set = |name: &str, kind: StepKind, roles: &[Role]| DataSetInfo {
            name: name.into(),
            roles: roles.to_vec(),
            kind,
            file: format!("{name}.csv"),
            sample_rate_hz: 1.0,
            speed_rpm: None,
            load_pct: None,
            steps: Some(3),
        };
        let (st, dy) = (&[Role::Static][..], &[Role::Static, Role::Dynamic][..]);
        let mut sets = vec![
            set("A", StepKind::VgtEgr, st),
            set("B", StepKind::VgtEgr, dy),
            set("D", StepKind::VgtEgr, st),
        ];
        let note = hold_back_for_validation(&mut sets);
        assert_eq!(sets[2].roles, [Role::Validation], "{note}");
        assert_eq!(
            (sets[0].roles.as_slice(), sets[1].roles.as_slice()),
            (st, dy)
        );
        // two static sets: none held back, and the note says from how many
        let mut two = sets[..2].to_vec();
        assert_eq!(
            hold_back_for_validation(&mut two),
            "no set has the role \"validation\" (2 with the role \"static\", a set is held \
             back from 3 on): give it to sets you hold back from the tuning"
        );
        assert_eq!(two, sets[..2]);
        // only dynamic sets besides one static: none either (steps 3-4 need them)
        let mut dyn3 = vec![
            set("B", StepKind::VgtEgr, dy),
            set("C", StepKind::VgtEgr, dy),
            set("I", StepKind::Fuel, &[Role::Dynamic, Role::Static]),
        ];
        let before = dyn3.clone();
        assert!(hold_back_for_validation(&mut dyn3).starts_with("no set has"));
        assert_eq!(dyn3, before);
    }

    /// A small campaign of the published engine: 13 stationary points, sets I and J of 2 steps.
    fn small_ij_campaign() -> crate::tuning::data::Campaign {
        let opts = LabOptions {
            max_steps: Some(2),
            n_stationary: 13,
            sets: Some(vec!["I".into(), "J".into()]),
            ..LabOptions::default()
        };
        campaign(&Params::published(), &opts).unwrap().0
    }

    /// `c` saved in a temporary directory, and the paths of its CSV files.
    fn saved(c: &crate::tuning::data::Campaign) -> (tempfile::TempDir, Vec<PathBuf>) {
        let dir = tempfile::tempdir().unwrap();
        save_campaign(dir.path(), c).unwrap();
        let files = std::iter::once(&c.manifest.stationary)
            .chain(c.manifest.datasets.iter().map(|s| &s.file))
            .map(|f| dir.path().join(f))
            .collect();
        (dir, files)
    }

    /// (mvem's name, the test cell's header, value in its unit from mvem's)
    type Rename<'a> = (&'a str, &'a str, fn(f64) -> f64);

    /// Rewrite the columns of a CSV file: each (mvem's name, new header, conversion of the
    /// values) present in its header.
    fn rewrite(path: &Path, renames: &[Rename]) {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        let mut header: Vec<String> = lines
            .next()
            .unwrap()
            .split(',')
            .map(str::to_string)
            .collect();
        let mut convs = Vec::new();
        for &(name, new, conv) in renames {
            if let Some(k) = header.iter().position(|h| h == name) {
                header[k] = new.to_string();
                convs.push((k, conv));
            }
        }
        let mut out = vec![header.join(",")];
        for l in lines {
            let mut v: Vec<String> = l.split(',').map(str::to_string).collect();
            for &(k, conv) in &convs {
                v[k] = format!("{:?}", conv(v[k].parse::<f64>().unwrap()));
            }
            out.push(v.join(","));
        }
        std::fs::write(path, out.join("\n") + "\n").unwrap();
    }

    /// QA finding: a time column headed `t [ms]` or `Time [ms]` was mapped to `t`, its sample
    /// rates computed in seconds, but `[units]` got no `t = "ms"`: the loader then read the
    /// times as seconds (a 100 Hz set as 0.1 Hz) and the tuning went on with volumes 1000
    /// times too large. The header's time unit is drafted and the campaign loads as it was.
    #[test]
    fn a_time_unit_in_the_header_is_drafted() {
        let c = small_ij_campaign();
        for header in ["t [ms]", "Time [ms]"] {
            let dir = tempfile::tempdir().unwrap();
            save_campaign(dir.path(), &c).unwrap();
            for s in &c.manifest.datasets {
                rewrite(&dir.path().join(&s.file), &[("t", header, |v| 1e3 * v)]);
            }
            std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
            let d = draft_manifest(dir.path()).unwrap();
            let m = &d.manifest;
            assert_eq!(m.units.get("t").map(String::as_str), Some("ms"), "{header}");
            assert!(d.notes.iter().any(|n| n == "t: in ms (its header says so)"));
            for (s, orig) in m.datasets.iter().zip(&c.manifest.datasets) {
                assert_eq!(s.sample_rate_hz, orig.sample_rate_hz, "{}", s.name);
            }
            std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
            let back = load_campaign(dir.path()).unwrap();
            for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
                for (x, y) in a.t.iter().zip(&b.t) {
                    assert!((x - y).abs() <= 1e-9 * y.abs().max(1.0), "{x} vs {y}");
                }
            }
        }
    }

    /// Insert a units row under the header of the CSV file `path`: the unit of each (header,
    /// unit) given, empty cells for the other columns.
    fn add_units_row(path: &Path, units: &[(&str, &str)]) {
        let text = std::fs::read_to_string(path).unwrap();
        let (head, rest) = text.split_once('\n').unwrap();
        let row: Vec<&str> = head
            .split(',')
            .map(|h| units.iter().find(|u| u.0 == h).map_or("", |u| u.1))
            .collect();
        std::fs::write(path, format!("{head}\n{}\n{rest}", row.join(","))).unwrap();
    }

    /// Session 40: a test cell's stationary file sorted after its dynamic files (the lab's
    /// `stationary.csv` after `I.csv`) that heads a column otherwise than they do (`p_im [kPa]`
    /// against a bare `p_im`) was skipped as a clash with them, and the draft failed with "no
    /// stationary file among 3 CSV files", the skip's note unprinted. The stationary file is
    /// drafted first now; the dynamic file that heads p_im otherwise is skipped, saying why.
    #[test]
    fn the_stationary_file_is_drafted_first() {
        let c = small_ij_campaign();
        let (dir, _) = saved(&c);
        rewrite(
            &dir.path().join("stationary.csv"),
            &[("p_im", "p_im [kPa]", |v| v / 1e3)],
        );
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        assert_eq!(d.manifest.stationary, "stationary.csv");
        assert_eq!(
            d.manifest.units.get("p_im").map(String::as_str),
            Some("kPa")
        );
        let sets: Vec<&str> = d
            .manifest
            .datasets
            .iter()
            .map(|s| s.name.as_str())
            .collect();
        assert_eq!(sets, ["J"], "{:?}", d.notes);
        assert!(
            d.notes.iter().any(|n| n
                == "I.csv: skipped (heads p_im `p_im` (no unit), stationary.csv heads it `p_im \
                    [kPa]` (in kPa): [columns] and [units] hold one header and unit per column; \
                    files may give a column in different units where each gives its own, in its \
                    header's brackets or a units row)"),
            "{:?}",
            d.notes
        );
        std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        for (a, b) in back.stationary.iter().zip(&c.stationary) {
            assert!(
                (a.p_im - b.p_im).abs() <= 1e-9 * b.p_im,
                "{} vs {}",
                a.p_im,
                b.p_im
            );
        }
    }

    /// Session 40: files that head a column by the same name and unit but write the unit
    /// otherwise (`M_e [Nm]` in the stationary file, `M_e (Nm)` in I; `N_E [rpm]` and `N_E`
    /// over a units row `rpm`; `p_im [kPa]` and `p_im (kPa)`) were counted as heading it
    /// otherwise and I was skipped, though the loader finds `NAME [unit]` by `NAME` in each
    /// file. Now they are drafted together, `[columns]` giving the name without brackets, and
    /// the campaign loads as the lab wrote it. (A bare header without a units row still differs
    /// from a bracketed one: its unit may be guessed from its values.)
    #[test]
    fn headers_that_differ_only_by_their_unit_in_brackets_are_drafted_together() {
        let c = small_ij_campaign();
        let (dir, _) = saved(&c);
        rewrite(
            &dir.path().join("stationary.csv"),
            &[
                ("M_e", "M_e [Nm]", |v| v),
                ("n_e", "N_E [rpm]", |v| v),
                ("p_im", "p_im [kPa]", |v| v / 1e3),
            ],
        );
        let i = dir.path().join("I.csv");
        rewrite(
            &i,
            &[
                ("M_e", "M_e (Nm)", |v| v),
                ("n_e", "N_E", |v| v),
                ("p_im", "p_im (kPa)", |v| v / 1e3),
            ],
        );
        add_units_row(&i, &[("N_E", "rpm")]);
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        let m = &d.manifest;
        let sets: Vec<&str> = m.datasets.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(sets, ["I", "J"], "{:?}", d.notes);
        let cols: Vec<(&str, &str)> = (m.columns.iter())
            .map(|(a, b)| (a.as_str(), b.as_str()))
            .collect();
        assert_eq!(cols, [("n_e", "N_E")]);
        let units: Vec<(&str, &str)> = (m.units.iter())
            .map(|(a, b)| (a.as_str(), b.as_str()))
            .collect();
        assert_eq!(units, [("p_im", "kPa")]);
        assert!(
            d.notes.iter().any(|n| n
                == "n_e: headed `N_E`, with its unit in brackets in some files (the loader finds \
                    `N_E [unit]` in each file)"),
            "{:?}",
            d.notes
        );
        std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        for (a, b) in back.stationary.iter().zip(&c.stationary) {
            for (x, y) in a.values().iter().zip(b.values()) {
                assert!(close(*x, y), "{x} vs {y}");
            }
        }
        for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
            for n in ["n_e", "p_im", "M_e", "u_vgt"] {
                let (Some(x), Some(y)) = (a.get(n), b.get(n)) else {
                    continue;
                };
                assert_eq!(x.len(), y.len());
                assert!(
                    x.iter().zip(y).all(|(x, y)| close(*x, *y)),
                    "{} {n}",
                    a.name
                );
            }
        }
    }

    /// Session 39: files that differ in their time unit. `[units]` holds one unit per column,
    /// but the draft wrote `t = "ms"` when any bare time column looked like ms: the files in
    /// seconds beside it were then either read 1000 times too slow (bare: the loader only
    /// warned of their rates) or refused for their own units row's `s` against the manifest's
    /// `ms`. Now `t` is not drafted then, a note names both kinds of files, and the loader
    /// refuses the file in ms by name until it is given its unit; the file's own units row
    /// then loads the campaign as the lab wrote it.
    #[test]
    fn files_in_ms_beside_files_in_seconds_get_no_time_unit_in_the_draft() {
        let c = small_ij_campaign();
        // I in ms without a unit; J in seconds, said by its units row or only by its values
        for j_says_s in [true, false] {
            let (dir, _) = saved(&c);
            let (i, j) = (dir.path().join("I.csv"), dir.path().join("J.csv"));
            rewrite(&i, &[("t", "t", |v| 1e3 * v)]);
            if j_says_s {
                add_units_row(&j, &[("t", "s")]);
            }
            std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
            let d = draft_manifest(dir.path()).unwrap();
            assert_eq!(d.manifest.units.get("t"), None, "{:?}", d.notes);
            let note = d
                .notes
                .iter()
                .find(|n| n.starts_with("t: not drafted"))
                .unwrap_or_else(|| panic!("{:?}", d.notes));
            let j_note = if j_says_s {
                "J.csv (as a header or units row says)"
            } else {
                "J.csv (as their values look)"
            };
            assert!(
                note.contains("I.csv: its median time step is 100 s") && note.contains(j_note),
                "{note}"
            );
            // the rates are drafted as the lab's (I's computed in ms)
            for (s, orig) in d.manifest.datasets.iter().zip(&c.manifest.datasets) {
                assert_eq!(s.sample_rate_hz, orig.sample_rate_hz, "{}", s.name);
            }
            std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
            let e = load_campaign(dir.path()).unwrap_err().to_string();
            assert!(
                e.contains("I.csv: line 3, column `t`: the time has no unit"),
                "{e}"
            );
            add_units_row(&i, &[("t", "ms")]);
            let back = load_campaign(dir.path()).unwrap();
            for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
                assert_eq!(a.t.len(), b.t.len());
                for (x, y) in a.t.iter().zip(&b.t) {
                    assert!((x - y).abs() <= 1e-9 * y.abs().max(1.0), "{x} vs {y}");
                }
            }
        }
    }

    /// Session 39: files that differ in their time unit load together when each says its
    /// own: I headed `t [ms]`, J's bare `t` in seconds, the lab's manifest (no `[columns]`, no
    /// `[units]`); before, I's `t` was a missing column.
    #[test]
    fn a_time_unit_in_one_files_header_is_that_files_alone() {
        let c = small_ij_campaign();
        let (dir, _) = saved(&c);
        rewrite(&dir.path().join("I.csv"), &[("t", "t [ms]", |v| 1e3 * v)]);
        let back = load_campaign(dir.path()).unwrap();
        for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
            assert_eq!((a.name.as_str(), a.t.len()), (b.name.as_str(), b.t.len()));
            for (x, y) in a.t.iter().zip(&b.t) {
                assert!(
                    (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                    "{}: {x} vs {y}",
                    a.name
                );
            }
        }
    }

    /// Session 39: a units row with a unit mvem does not know in one file only (`percent` for
    /// u_vgt in J, none in I) made the draft skip J ("heads u_vgt `u_vgt`, I.csv heads it
    /// `u_vgt`", the same header twice); `[units]` declaring mvem's unit serves both files, so
    /// both are drafted and the campaign loads. Headings that do differ are named with their
    /// units.
    #[test]
    fn an_unknown_units_row_unit_in_one_file_does_not_skip_it() {
        let c = small_ij_campaign();
        let (dir, _) = saved(&c);
        add_units_row(&dir.path().join("J.csv"), &[("u_vgt", "percent")]);
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        let names: Vec<&str> = d
            .manifest
            .datasets
            .iter()
            .map(|s| s.name.as_str())
            .collect();
        assert_eq!(names, ["I", "J"], "{:?}", d.notes);
        assert_eq!(
            d.manifest.units.get("u_vgt").map(String::as_str),
            Some("%"),
            "{:?}",
            d.notes
        );
        std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        assert_eq!(back.dynamic.len(), c.dynamic.len());
        // a header that differs is still skipped, and the note says how each file heads it
        let (dir, _) = saved(&c);
        rewrite(&dir.path().join("J.csv"), &[("u_vgt", "u_vgt [%]", |v| v)]);
        let d = draft_manifest(dir.path()).unwrap();
        assert!(
            d.notes.iter().any(|n| n
                == "J.csv: skipped (heads u_vgt `u_vgt [%]` (in mvem's unit), stationary.csv \
                    heads it `u_vgt` (no unit): [columns] and [units] hold one header and unit \
                    per column; files may give a column in different units where each gives \
                    its own, in its header's brackets or a units row)"),
            "{:?}",
            d.notes
        );
    }

    /// Session 42: files that give a column in different units, each its own (the stationary
    /// file `P_IM` over a units row `kPa`, I `P_IM [bar]`; I `t [ms]`, J `t [s]`), were skipped but the first (`[units]` holds one unit per column), though the
    /// loader reads each file's unit from its header or units row. Now they are drafted
    /// together, the column in `[columns]` by its name and not in `[units]`, a note giving each
    /// file's unit, and the campaign loads as the lab wrote it.
    #[test]
    fn files_that_give_a_column_in_their_own_units_are_drafted_together() {
        let c = small_ij_campaign();
        let (dir, _) = saved(&c);
        let path = |f: &str| dir.path().join(f);
        rewrite(&path("stationary.csv"), &[("p_im", "P_IM", |v| v / 1e3)]);
        add_units_row(&path("stationary.csv"), &[("P_IM", "kPa")]);
        rewrite(
            &path("I.csv"),
            &[
                ("p_im", "P_IM [bar]", |v| v / 1e5),
                ("t", "t [ms]", |v| 1e3 * v),
            ],
        );
        rewrite(&path("J.csv"), &[("t", "t [s]", |v| v)]);
        std::fs::remove_file(path("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        let m = &d.manifest;
        let sets: Vec<&str> = m.datasets.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(sets, ["I", "J"], "{:?}", d.notes);
        for (s, orig) in m.datasets.iter().zip(&c.manifest.datasets) {
            assert_eq!(s.sample_rate_hz, orig.sample_rate_hz, "{}", s.name);
        }
        let cols: Vec<(&str, &str)> = (m.columns.iter())
            .map(|(a, b)| (a.as_str(), b.as_str()))
            .collect();
        assert_eq!(cols, [("p_im", "P_IM")]);
        assert!(m.units.is_empty(), "{:?}", m.units);
        for want in [
            "p_im: each file in its own unit (bar in I.csv; kPa in stationary.csv; headed `P_IM`), \
             not in [units]: the loader reads each file's header or units row",
            "t: each file in its own unit (ms in I.csv; s in J.csv; headed `t`), not in [units]: \
             the loader reads each file's header or units row",
        ] {
            assert!(d.notes.iter().any(|n| n == want), "{want}\n{:?}", d.notes);
        }
        std::fs::write(path("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        assert_eq!(back.stationary.len(), c.stationary.len());
        for (a, b) in back.stationary.iter().zip(&c.stationary) {
            assert!(close(a.p_im, b.p_im), "{} vs {}", a.p_im, b.p_im);
        }
        assert_eq!(back.dynamic.len(), c.dynamic.len());
        for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
            assert_eq!(a.t.len(), b.t.len(), "{}", a.name);
            assert!(
                a.t.iter().zip(&b.t).all(|(x, y)| close(*x, *y)),
                "{}",
                a.name
            );
            // (J, an actuator set, has no p_im)
            assert_eq!(a.get("p_im").is_some(), a.name == "I", "{}", a.name);
            if let (Some(x), Some(y)) = (a.get("p_im"), b.get("p_im")) {
                assert!(x.iter().zip(y).all(|(x, y)| close(*x, *y)), "{}", a.name);
            }
        }
    }

    /// Test-cell exports write a row of units under the header (session 38): the draft reads
    /// it as the headers' brackets (the units into `[units]`, the sample rates in seconds, the
    /// unit guesses from the converted values) and the loader reads the files with it; a unit
    /// the row gives against the header's is noted (the loader refuses it).
    #[test]
    fn a_units_row_is_drafted_like_units_in_brackets() {
        let c = small_ij_campaign();
        let (dir, files) = saved(&c);
        for path in files {
            rewrite(
                &path,
                &[("t", "t", |v| 1e3 * v), ("p_im", "p_im", |v| v / 1e3)],
            );
            let text = std::fs::read_to_string(&path).unwrap();
            let (head, rest) = text.split_once('\n').unwrap();
            let units: Vec<&str> = head
                .split(',')
                .map(|h| match h {
                    "t" => "ms",
                    "p_im" => "kPa",
                    "n_e" => "1/min",
                    "u_delta" => "mg/Hub",
                    _ => "",
                })
                .collect();
            std::fs::write(&path, format!("{head}\n{}\n{rest}", units.join(","))).unwrap();
        }
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        let m = &d.manifest;
        let want = [("p_im", "kPa"), ("t", "ms")].map(|(a, b)| (a.to_string(), b.to_string()));
        assert_eq!(m.units, BTreeMap::from(want), "{:?}", d.notes);
        assert!(
            d.notes
                .iter()
                .any(|n| n == "p_im: in kPa (its header says so)"),
            "{:?}",
            d.notes
        );
        for (s, orig) in m.datasets.iter().zip(&c.manifest.datasets) {
            assert_eq!(s.sample_rate_hz, orig.sample_rate_hz, "{}", s.name);
            assert_eq!(s.steps, orig.steps, "{}", s.name);
        }
        std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        for (a, b) in back.stationary.iter().zip(&c.stationary) {
            assert!((a.p_im - b.p_im).abs() <= 1e-9 * b.p_im);
        }
        for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
            assert!((a.t[1] - b.t[1]).abs() <= 1e-9 * b.t[1].abs().max(1.0));
        }
        // the row against the header's brackets: noted
        for f in [&c.manifest.stationary, &c.manifest.datasets[0].file] {
            let path = dir.path().join(f);
            let text = std::fs::read_to_string(&path).unwrap();
            std::fs::write(&path, text.replacen("p_im", "p_im [bar]", 1)).unwrap();
        }
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        assert!(
            d.notes.iter().any(|n| n
                == &format!(
                    "{}: units row (line 2), column `p_im [bar]`: `kPa`, but its header says \
                     `bar`: the campaign cannot be loaded until they agree",
                    c.manifest.stationary
                )),
            "{:?}",
            d.notes
        );
    }

    /// QA finding: a campaign whose times are in ms with no unit anywhere (a bare `t` header,
    /// no `[units]`) loaded, and tune read ms as s. The loader refuses it, naming the file, the
    /// line and the column and how to declare the unit; the draft guesses `t = "ms"` (noted),
    /// and a declared unit is taken as it is. The check looks at the median step (100 Hz and
    /// 10 Hz sets in ms: 10 and 100), the span (a 1 kHz log in ms) and the manifest's rate.
    #[test]
    fn times_in_ms_without_a_unit_are_refused() {
        let c = small_ij_campaign();
        let dir = tempfile::tempdir().unwrap();
        save_campaign(dir.path(), &c).unwrap();
        // the lab's own campaign (seconds) loads
        load_campaign(dir.path()).unwrap();
        let manifest = std::fs::read_to_string(dir.path().join("manifest.toml")).unwrap();
        for s in &c.manifest.datasets {
            rewrite(&dir.path().join(&s.file), &[("t", "t", |v| 1e3 * v)]);
        }
        let e = load_campaign(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("I.csv: line 3, column `t`: the time has no unit")
                && e.contains("median time step is 100 s")
                && e.contains("`t = \"ms\"` in the manifest's [units]")
                && e.contains("t [ms]"),
            "{e}"
        );
        // declared: in ms it is the campaign as it was; in s it is taken as said
        let with_units = |u: &str| {
            let m = format!("{manifest}\n[units]\nt = \"{u}\"\n");
            std::fs::write(dir.path().join("manifest.toml"), m).unwrap();
            load_campaign(dir.path())
        };
        let back = with_units("ms").unwrap();
        for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
            for (x, y) in a.t.iter().zip(&b.t) {
                assert!((x - y).abs() <= 1e-9 * y.abs().max(1.0), "{x} vs {y}");
            }
        }
        assert!(with_units("s").is_ok());
        // the draft guesses ms and computes the rates in seconds
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        assert_eq!(d.manifest.units.get("t").map(String::as_str), Some("ms"));
        assert!(
            d.notes
                .iter()
                .any(|n| n.starts_with("t: in ms? (I.csv: its median")),
            "{:?}",
            d.notes
        );
        for (s, orig) in d.manifest.datasets.iter().zip(&c.manifest.datasets) {
            assert_eq!(s.sample_rate_hz, orig.sample_rate_hz, "{}", s.name);
        }
        // a 1 kHz log in ms steps by 1 but spans more than a day; a manifest rate 1000 times
        // the times' own
        let t: Vec<f64> = (0..100_000).map(f64::from).collect();
        assert!(times_look_like_ms(&t, None)
            .unwrap()
            .1
            .contains("no dynamic set lasts a day"));
        let t: Vec<f64> = (0..100).map(f64::from).collect();
        assert!(times_look_like_ms(&t, None).is_none());
        assert!(times_look_like_ms(&t, Some(1000.0)).is_some());
        assert!(times_look_like_ms(&t, Some(1.0)).is_none());
    }

    /// QA findings: W_c logged in kg/h without a unit was guessed as g/s (the first unit in
    /// which it is in range) without saying that kg/h fits as well, and commands logged as
    /// fractions 0..1 were taken for 0-1 % without a word. Both are notes now.
    #[test]
    fn ambiguous_guesses_are_named() {
        let c = small_ij_campaign();
        let (dir, files) = saved(&c);
        for path in files {
            rewrite(
                &path,
                &[
                    ("W_c", "W_c", |v| 3600.0 * v),
                    ("u_vgt", "u_vgt", |v| v / 100.0),
                ],
            );
        }
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        let d = draft_manifest(dir.path()).unwrap();
        let note = |start: &str| d.notes.iter().find(|n| n.starts_with(start)).cloned();
        let w_c = note("W_c: in g/s?").unwrap_or_else(|| panic!("{:?}", d.notes));
        assert!(w_c.contains("also inside in kg/h"), "{w_c}");
        let u = note("u_vgt: every value lies in 0..1").unwrap_or_else(|| panic!("{:?}", d.notes));
        assert!(u.contains("[units] u_vgt = \"-\""), "{u}");
        assert!(note("u_egr: every value").is_none(), "{:?}", d.notes);
    }

    /// A test cell's own headers: other case, spaces, a unit in brackets (`p_im [kPa]`,
    /// `T_em (degC)`, `Time [s]`, `u_egr [-]` as a fraction): the draft maps them in `[columns]`,
    /// takes the bracketed units into `[units]`, and the campaign then loads with mvem's values;
    /// a file heading a column differently from the others is skipped, naming both; an unknown
    /// bracketed unit is a note.
    #[test]
    fn renamed_headers_with_units_are_drafted() {
        let opts = LabOptions {
            max_steps: Some(3),
            sets: Some(vec!["B".into(), "I".into(), "J".into()]),
            ..LabOptions::default()
        };
        let (c, _) = campaign(&Params::published(), &opts).unwrap();
        let dir = tempfile::tempdir().unwrap();
        save_campaign(dir.path(), &c).unwrap();
        let renames: [Rename; 5] = [
            ("p_im", "p_im [kPa]", |v| v / 1e3),
            ("T_em", "T_em (degC)", |v| v - 273.15),
            ("n_e", "N_E", |v| v),
            ("t", "Time [s]", |v| v),
            ("u_egr", "u egr [-]", |v| v / 100.0),
        ];
        let files: Vec<String> = std::iter::once(c.manifest.stationary.clone())
            .chain(c.manifest.datasets.iter().map(|s| s.file.clone()))
            .collect();
        for f in &files {
            rewrite(&dir.path().join(f), &renames);
        }
        std::fs::remove_file(dir.path().join("manifest.toml")).unwrap();
        // another file that heads p_im in Pa under mvem's name: not in the one [columns] table
        let b = std::fs::read_to_string(dir.path().join("B.csv")).unwrap();
        std::fs::write(
            dir.path().join("Z.csv"),
            b.replacen("p_im [kPa]", "p_im", 1),
        )
        .unwrap();
        // an unknown unit
        std::fs::write(
            dir.path().join("Y.csv"),
            b.replacen("N_E", "N_E [furlong/s]", 1),
        )
        .unwrap();

        let d = draft_manifest(dir.path()).unwrap();
        let m = &d.manifest;
        eprintln!("{}", d.toml().unwrap());
        let cols: Vec<(&str, &str)> = m
            .columns
            .iter()
            .map(|(a, b)| (a.as_str(), b.as_str()))
            .collect();
        assert_eq!(
            cols,
            [
                ("T_em", "T_em (degC)"),
                ("n_e", "N_E"),
                ("p_im", "p_im [kPa]"),
                ("t", "Time [s]"),
                ("u_egr", "u egr [-]")
            ]
        );
        let units: Vec<(&str, &str)> = m
            .units
            .iter()
            .map(|(a, b)| (a.as_str(), b.as_str()))
            .collect();
        assert_eq!(units, [("T_em", "degC"), ("p_im", "kPa"), ("u_egr", "-")]);
        let names: Vec<&str> = m.datasets.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["B", "I", "J"]);
        assert!(
            d.notes
                .iter()
                .any(|n| n.starts_with("Y.csv: skipped") && n.contains("`N_E [furlong/s]`")),
            "{:?}",
            d.notes
        );
        // the headers one by one
        let m = |h: &str| match_header(h).map(|(c, u, note, _)| (c.name, u, note.is_some()));
        assert_eq!(m("P_IM"), Some(("p_im", None, false)));
        assert_eq!(m(" p_im [kPa] "), Some(("p_im", Some("kPa"), false)));
        assert_eq!(m("p_im [KPA]"), Some(("p_im", Some("kPa"), false)));
        assert_eq!(m("T_em (K)"), Some(("T_em", None, false)));
        assert_eq!(m("time [ms]"), Some(("t", Some("ms"), false)));
        assert_eq!(m("x egr [%]"), Some(("x_egr", Some("%"), false)));
        assert_eq!(m("N_E [furlong/s]"), Some(("n_e", None, true)));
        assert_eq!(m("p_im2"), None);
        assert_eq!(m("[kPa]"), None);
        assert!(
            d.notes.iter().any(|n| n.starts_with("Z.csv: skipped")
                && n.contains("`p_im`")
                && n.contains("`p_im [kPa]`")),
            "{:?}",
            d.notes
        );
        std::fs::remove_file(dir.path().join("Y.csv")).unwrap();
        std::fs::remove_file(dir.path().join("Z.csv")).unwrap();
        std::fs::write(dir.path().join("manifest.toml"), d.toml().unwrap()).unwrap();
        let back = load_campaign(dir.path()).unwrap();
        for (a, b) in back.stationary.iter().zip(&c.stationary) {
            assert!((a.p_im - b.p_im).abs() <= 1e-9 * b.p_im);
            assert!((a.t_em - b.t_em).abs() <= 1e-9 * b.t_em);
            assert!((a.u_egr - b.u_egr).abs() <= 1e-9 * b.u_egr.abs().max(1.0));
            assert_eq!(a.n_e, b.n_e);
        }
        assert_eq!(back.dynamic.len(), c.dynamic.len());
        for (a, b) in back.dynamic.iter().zip(&c.dynamic) {
            assert_eq!(a.t, b.t);
        }
    }
}
