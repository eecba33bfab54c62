//! Input time series from CSV: header `time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct` (any
//! column order), one row per time, linear interpolation between rows, two rows with the same
//! time are a step. Every problem is reported with file, line and column.

use super::IoError;
use crate::numerics::Num;
use crate::sim::input::{InputSchedule, ScheduleError, INPUT_COLUMNS};
use std::path::Path;

fn err(path: &Path, line: Option<usize>, column: Option<&str>, message: String) -> IoError {
    IoError::Format {
        path: path.to_path_buf(),
        line,
        column: column.map(str::to_string),
        message,
    }
}

/// Parse CSV text into a schedule. `path` is used in messages only.
pub fn parse_inputs_csv(text: &str, path: &Path) -> Result<InputSchedule, IoError> {
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::Headers) // fields are trimmed where they are parsed (cheaper)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    let headers = rdr
        .headers()
        .map_err(|e| err(path, Some(1), None, format!("cannot read header: {e}")))?
        .clone();
    let mut index = [usize::MAX; 5];
    for (i, h) in headers.iter().enumerate() {
        match INPUT_COLUMNS.iter().position(|c| *c == h) {
            Some(k) if index[k] != usize::MAX => {
                return Err(err(
                    path,
                    Some(1),
                    Some(h),
                    format!("duplicate column `{h}`"),
                ))
            }
            Some(k) => index[k] = i,
            None => {
                return Err(err(
                    path,
                    Some(1),
                    Some(h),
                    format!(
                        "unknown column `{h}` (expected exactly: {})",
                        INPUT_COLUMNS.join(",")
                    ),
                ))
            }
        }
    }
    if let Some(k) = index.iter().position(|i| *i == usize::MAX) {
        return Err(err(
            path,
            Some(1),
            Some(INPUT_COLUMNS[k]),
            format!("missing column `{}`", INPUT_COLUMNS[k]),
        ));
    }
    let mut times = Vec::new();
    let mut rows = Vec::new();
    let mut lines = Vec::new();
    // one record reused for every row (no allocation per row)
    let mut rec = csv::StringRecord::new();
    while rdr.read_record(&mut rec).map_err(|e| {
        let line = e.position().map(|p| p.line() as usize);
        err(path, line, None, format!("malformed CSV: {e}"))
    })? {
        let line = rec.position().map(|p| p.line() as usize).unwrap_or(0);
        if rec.len() != headers.len() {
            return Err(err(
                path,
                Some(line),
                None,
                format!("expected {} fields, found {}", headers.len(), rec.len()),
            ));
        }
        let mut vals = [0.0; 5];
        for k in 0..5 {
            let s = rec[index[k]].trim();
            let v: f64 = s.parse().map_err(|_| {
                err(
                    path,
                    Some(line),
                    Some(INPUT_COLUMNS[k]),
                    format!("`{s}` is not a number"),
                )
            })?;
            if !v.is_finite() {
                return Err(err(
                    path,
                    Some(line),
                    Some(INPUT_COLUMNS[k]),
                    format!("{v} is not finite"),
                ));
            }
            vals[k] = v;
        }
        times.push(vals[0]);
        rows.push([vals[1], vals[2], vals[3], vals[4]]);
        lines.push(line);
    }
    if times.is_empty() {
        return Err(err(path, None, None, "no data rows".into()));
    }
    // the schedule counts data rows from 0; the messages here name the file line only
    InputSchedule::new(times, rows).map_err(|e| match e {
        ScheduleError::NonFinite { row, column, value } => err(
            path,
            lines.get(row).copied(),
            Some(column),
            format!("{value} is not finite"),
        ),
        ScheduleError::NonMonotonic {
            row,
            t,
            prev,
            detail,
        } => err(
            path,
            lines.get(row).copied(),
            Some("time_s"),
            format!("time {t} s is not monotonic (previous {prev} s){detail}"),
        ),
        ScheduleError::Empty => err(path, None, None, e.to_string()),
    })
}

/// Read an input CSV file.
pub fn load_inputs_csv(path: &Path) -> Result<InputSchedule, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::File {
        path: path.to_path_buf(),
        source,
    })?;
    parse_inputs_csv(&text, path)
}

/// Ranges of the authors' input saturations (items 1-4), per channel, with names.
pub const INPUT_RANGES: [(&str, f64, f64); 4] = [
    ("n_e_rpm", 500.0, 2000.0),
    ("u_delta_mg", 1.0, 250.0),
    ("u_egr_pct", 0.0, 100.0),
    ("u_vgt_pct", 20.0, 100.0),
];

/// For each channel whose values leave the authors' saturation range, one warning naming the
/// first time it happens and the extreme value.
pub fn range_warnings(s: &InputSchedule) -> Vec<String> {
    range_warnings_of_rows(s.times().iter().copied().zip(s.rows().iter().copied()))
}

/// [`range_warnings`] of input rows `(t [s], [n_e, u_delta, u_egr, u_vgt])` that are not (yet) an
/// [`InputSchedule`] (the Python API checks its rows so).
pub fn range_warnings_of_rows(rows: impl IntoIterator<Item = (f64, [f64; 4])>) -> Vec<String> {
    let mut first: [Option<f64>; 4] = [None; 4];
    let mut vmin = [f64::INFINITY; 4];
    let mut vmax = [f64::NEG_INFINITY; 4];
    for (t, r) in rows {
        for (c, (_, lo, hi)) in INPUT_RANGES.iter().enumerate() {
            let v = r[c];
            if v < *lo || v > *hi {
                first[c].get_or_insert(t);
                vmin[c] = vmin[c].min(v);
                vmax[c] = vmax[c].max(v);
            }
        }
    }
    INPUT_RANGES
        .iter()
        .enumerate()
        .filter_map(|(c, (name, lo, hi))| {
            first[c].map(|t| {
                format!(
                    "{name} leaves [{lo}, {hi}] first at t = {} s (values from {} to {}); the authors' saturation clamps it (the paper's semantics use it as given)",
                    Num(t),
                    Num(vmin[c]),
                    Num(vmax[c])
                )
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<InputSchedule, String> {
        parse_inputs_csv(s, Path::new("in.csv")).map_err(|e| e.to_string())
    }

    #[test]
    fn reads_columns_in_any_order() {
        let s = parse(
            "u_vgt_pct,time_s,n_e_rpm,u_delta_mg,u_egr_pct\n75,0,1500,110,80\n65,1,1500,110,80\n",
        )
        .unwrap();
        assert_eq!(s.at(0.5).u_vgt_pct, 70.0);
    }

    #[test]
    fn blanks_around_names_and_numbers_are_ignored() {
        let s = parse(
            " time_s , n_e_rpm,u_delta_mg ,u_egr_pct,\tu_vgt_pct\n 0 ,1500, 110,80 ,75\n# note\n1,\t1500,110,80,65 \n",
        )
        .unwrap();
        assert_eq!(s.at(0.5).u_vgt_pct, 70.0);
        assert_eq!(s.at(1.0).n_e_rpm, 1500.0);
        let e =
            parse("time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0, ,110,80,75\n").unwrap_err();
        assert_eq!(e, "in.csv, line 2, column n_e_rpm: `` is not a number");
    }

    #[test]
    fn errors_name_line_and_column() {
        let h = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n";
        let e = parse(&format!("{h}0,1500,110,80,75\n1,1500,abc,80,75\n")).unwrap_err();
        assert_eq!(
            e,
            "in.csv, line 3, column u_delta_mg: `abc` is not a number"
        );
        let e = parse(&format!("{h}0,1500,110,80,75\n1,1500,NaN,80,75\n")).unwrap_err();
        assert_eq!(e, "in.csv, line 3, column u_delta_mg: NaN is not finite");
        let e = parse(&format!(
            "{h}0,1500,110,80,75\n2,1500,110,80,75\n1,1500,110,80,75\n"
        ))
        .unwrap_err();
        assert!(
            e.starts_with("in.csv, line 4, column time_s: time 1 s is not monotonic"),
            "{e}"
        );
        let e = parse("time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct,extra\n").unwrap_err();
        assert!(
            e.contains("line 1, column extra: unknown column `extra`"),
            "{e}"
        );
        let e = parse("time_s,n_e_rpm,u_delta_mg,u_egr_pct\n0,1,1,1\n").unwrap_err();
        assert!(e.contains("missing column `u_vgt_pct`"), "{e}");
        let e = parse(&format!("{h}0,1500,110,80\n")).unwrap_err();
        assert!(e.contains("line 2"), "{e}");
        let e = parse(h).unwrap_err();
        assert!(e.contains("no data rows"), "{e}");
    }

    #[test]
    fn out_of_range_inputs_warn_once_per_channel() {
        let h = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n";
        let s = parse(&format!(
            "{h}0,1500,110,80,10\n1,1500,110,80,5\n2,2500,110,80,50\n"
        ))
        .unwrap();
        let w = range_warnings(&s);
        assert_eq!(w.len(), 2);
        assert!(w[0].starts_with("n_e_rpm leaves [500, 2000] first at t = 2 s"));
        assert!(
            w[1].starts_with("u_vgt_pct leaves [20, 100] first at t = 0 s (values from 5 to 10)")
        );
    }
}
