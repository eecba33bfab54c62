//! Input time series from CSV: header `time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct` (any
//! column order), one row per time, linear interpolation between rows, two rows with the same
//! time are a step. Every problem is reported with file, line and column. Also `;`- or
//! tab-separated with decimal commas (`1,5`), as spreadsheets in such locales export
//! ([`super::csv_columns::Dialect`]).

use super::{format_err as err, IoError};
use crate::numerics::Num;
use crate::params::InputSaturation;
use crate::sim::input::{InputSchedule, ScheduleError, INPUT_COLUMNS};
use std::path::Path;

/// The rows of an input table read by the csv crate: times, inputs and the file line of each
/// row; every problem of the file named with its line and column.
fn csv_table(text: &str, path: &Path) -> Result<Table, IoError> {
    // `;` or tab separated with decimal commas, as spreadsheets in such locales export
    let dialect = super::csv_columns::Dialect::of(text, Some(b'#'));
    let mut rdr = csv::ReaderBuilder::new()
        .delimiter(dialect.delimiter)
        .flexible(true) // a wrong field count is reported below, with a hint
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
        let line = e.position().map(|p| file_line(text, p));
        err(path, line, None, format!("malformed CSV: {e}"))
    })? {
        let line = rec.position().map(|p| file_line(text, p)).unwrap_or(0);
        if rec.len() != headers.len() {
            let hint = if rec.len() > headers.len() && dialect.delimiter == b',' {
                " (a decimal comma? write 1.5, or separate the fields by `;`)"
            } else {
                ""
            };
            return Err(err(
                path,
                Some(line),
                None,
                format!(
                    "expected {} fields, found {}{hint}",
                    headers.len(),
                    rec.len()
                ),
            ));
        }
        let mut vals = [0.0; 5];
        for k in 0..5 {
            let s = rec[index[k]].trim();
            let v: f64 = dialect.number(s).ok_or_else(|| {
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
    Ok((times, rows, lines))
}

/// The file line of a csv crate record position (no comment lines in these files).
fn file_line(text: &str, p: &csv::Position) -> usize {
    super::csv_columns::file_line(text, p, None)
}

/// Times, the inputs (n_e, u_delta, u_egr, u_vgt) and the file line of each data row.
type Table = (Vec<f64>, Vec<[f64; 4]>, Vec<usize>);

/// Parse CSV text into a schedule. `path` is used in messages only.
///
/// A plain file (a header of the five names, then lines of five comma-separated numbers) is
/// read directly (`plain_table`: half the csv crate's cost for the built-in WHTC); anything
/// else (quotes, comments, blank lines, a field that is not a finite number, a wrong field
/// count) is read by the csv crate, which names the line and column of every problem. Both read the same
/// numbers (`str::parse` or an exact equivalent).
pub fn parse_inputs_csv(text: &str, path: &Path) -> Result<InputSchedule, IoError> {
    // an empty file (or one of blank lines and comments only, after a byte-order mark) has no
    // header to name a column of
    if super::csv_columns::header_line(text.trim_start_matches('\u{feff}'), Some(b'#')).is_empty() {
        return Err(err(
            path,
            None,
            None,
            format!(
                "the file is empty: expected a header ({}) and data rows",
                INPUT_COLUMNS.join(",")
            ),
        ));
    }
    let (times, rows, lines) = match plain_table(text) {
        Some(t) => t,
        None => csv_table(text, path)?,
    };
    if times.is_empty() {
        return Err(err(path, None, None, "no data rows".into()));
    }
    InputSchedule::new(times, rows).map_err(|e| schedule_error(path, &lines, "time_s", e))
}

/// A [`ScheduleError`] of a table read from `path` as the file's error: the schedule counts
/// data rows from 0, the message names the file line of the row (`lines`, one per data row)
/// only, and a time out of order the time column `time_column` (also the demand reader's,
/// [`super::csv_demand::parse_demand_csv`]).
pub(crate) fn schedule_error(
    path: &Path,
    lines: &[usize],
    time_column: &str,
    e: ScheduleError,
) -> IoError {
    match e {
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
            Some(time_column),
            format!("time {t} s is not monotonic (previous {prev} s){detail}"),
        ),
        ScheduleError::Empty => err(path, None, None, e.to_string()),
    }
}

/// The common case of an input table without the csv crate: an ASCII header line of the five
/// column names (any order, blanks around them), then lines of exactly five fields, each a
/// finite number (blanks around it), separated by `\n` or `\r\n`, an optional final line
/// break. `None` for anything else, which [`csv_table`] then reads or reports: a quote or a
/// `#` is in no number, so a quoted field, a comment or a lone `\r` gives `None` too.
fn plain_table(text: &str) -> Option<Table> {
    let header = text.split('\n').next()?;
    if !header.is_ascii() {
        return None;
    }
    let mut index = [usize::MAX; 5];
    let mut n = 0;
    for (i, h) in header.split(',').enumerate() {
        let k = INPUT_COLUMNS.iter().position(|c| *c == h.trim())?;
        if index[k] != usize::MAX {
            return None;
        }
        index[k] = i;
        n += 1;
    }
    if n != 5 {
        return None;
    }
    let rough = text.len() / 40;
    let (mut times, mut rows, mut line_no) = (
        Vec::with_capacity(rough),
        Vec::with_capacity(rough),
        Vec::with_capacity(rough),
    );
    // one pass over the bytes: each field ends at the next `,` (the first four) or line end
    // (the fifth); a `,` or line end anywhere else is a wrong field count
    let b = text.as_bytes();
    let mut p = header.len() + 1;
    while p < b.len() {
        let mut vals = [0.0; 5];
        for (k, v) in vals.iter_mut().enumerate() {
            let (end, x) = scan_decimal(b, p);
            if b.get(end).copied().unwrap_or(b'\n') != if k < 4 { b',' } else { b'\n' } {
                return None;
            }
            *v = match x {
                Some(x) => x,
                None => plain_field(&text[p..end])?,
            };
            p = end + 1;
        }
        let v = |k: usize| vals[index[k]];
        times.push(v(0));
        rows.push([v(1), v(2), v(3), v(4)]);
        // header on line 1, no blank or comment lines
        line_no.push(times.len() + 1);
    }
    (!times.is_empty()).then_some((times, rows, line_no))
}

/// A field of [`plain_table`] that [`scan_decimal`] did not read as it stands: a finite number
/// with blanks around it (read as `str::parse` reads the trimmed text), else `None`.
fn plain_field(f: &str) -> Option<f64> {
    let t = f.trim();
    plain_decimal(t.as_bytes()).or_else(|| t.parse::<f64>().ok().filter(|x| x.is_finite()))
}

/// Powers of ten exactly representable as f64 (10^22 < 2^53 x 2^22).
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// A decimal `[+-]digits[.digits]` of at most 19 digits whose digits, as an integer m, are
/// below 2^53 and with at most 22 after the point: m / 10^k of two exactly representable
/// numbers, one correctly rounded division (Clinger's fast path), i.e. the nearest f64, which
/// is what `str::parse` returns. `None` for anything else (exponents, more digits, text).
fn plain_decimal(s: &[u8]) -> Option<f64> {
    let (end, x) = scan_decimal(s, 0);
    if end == s.len() {
        x
    } else {
        None
    }
}

/// The field of `b` from `p` to the next `,`, `\n` or the end: that position, and the field's
/// value if it is a decimal [`plain_decimal`] reads (one pass over the bytes).
fn scan_decimal(b: &[u8], mut p: usize) -> (usize, Option<f64>) {
    let neg = b.get(p) == Some(&b'-');
    if neg || b.get(p) == Some(&b'+') {
        p += 1;
    }
    let (mut m, mut digits, mut frac, mut plain) = (0u64, 0usize, None::<usize>, true);
    while let Some(&c) = b.get(p) {
        match c {
            b'0'..=b'9' => {
                if digits < 19 {
                    m = m * 10 + u64::from(c - b'0');
                } else {
                    plain = false;
                }
                digits += 1;
                if let Some(k) = &mut frac {
                    *k += 1;
                }
            }
            b'.' if frac.is_none() => frac = Some(0),
            b',' | b'\n' => break,
            _ => plain = false,
        }
        p += 1;
    }
    if !plain || digits == 0 || m >= 1 << 53 {
        return (p, None);
    }
    let x = POW10.get(frac.unwrap_or(0)).map(|d| m as f64 / d);
    (p, x.map(|x| if neg { -x } else { x }))
}

/// Read an input CSV file.
pub fn load_inputs_csv(path: &Path) -> Result<InputSchedule, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::File {
        path: path.to_path_buf(),
        source,
    })?;
    parse_inputs_csv(&text, path)
}

/// Ranges of the authors' input saturations (items 1-4), per channel, with names: the defaults
/// ([`input_ranges`] of the default [`InputSaturation`]).
pub const INPUT_RANGES: [(&str, f64, f64); 4] = {
    use crate::model::{N_E_RANGE, U_DELTA_RANGE, U_EGR_RANGE, U_VGT_RANGE};
    [
        ("n_e_rpm", N_E_RANGE.0, N_E_RANGE.1),
        ("u_delta_mg", U_DELTA_RANGE.0, U_DELTA_RANGE.1),
        ("u_egr_pct", U_EGR_RANGE.0, U_EGR_RANGE.1),
        ("u_vgt_pct", U_VGT_RANGE.0, U_VGT_RANGE.1),
    ]
};

/// The input saturation ranges of a parameter set (items 1-4): its `input_saturation`.
pub fn input_ranges(s: &InputSaturation) -> [(&'static str, f64, f64); 4] {
    [
        ("n_e_rpm", s.n_e[0], s.n_e[1]),
        ("u_delta_mg", s.u_delta[0], s.u_delta[1]),
        ("u_egr_pct", s.u_egr[0], s.u_egr[1]),
        ("u_vgt_pct", s.u_vgt[0], s.u_vgt[1]),
    ]
}

/// For each channel whose values leave its saturation range (`ranges`, e.g. [`input_ranges`]),
/// one warning naming the channel, its range, how many of the input rows lie outside it (below
/// and above, with the extreme value on each side), the first time it happens (where the linear
/// interpolation between the rows crosses the limit), and the values of the whole channel.
pub fn range_warnings(s: &InputSchedule, ranges: &[(&str, f64, f64); 4]) -> Vec<String> {
    range_warnings_of_rows(
        s.times().iter().copied().zip(s.rows().iter().copied()),
        ranges,
    )
}

/// The values of one channel outside a range `[lo, hi]`: how many lie below and above it, the
/// lowest below and the highest above. The count shared by the input files' range warnings
/// ([`range_warnings_of_rows`]) and a tuning campaign's command-range warnings
/// ([`crate::tuning::constants::commands_outside_ranges`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outside {
    /// Values below the range.
    pub below: usize,
    /// Values above the range.
    pub above: usize,
    /// The lowest value below (+inf without one).
    pub min_below: f64,
    /// The highest value above (-inf without one).
    pub max_above: f64,
}

impl Outside {
    /// No value outside.
    pub const NONE: Self = Self {
        below: 0,
        above: 0,
        min_below: f64::INFINITY,
        max_above: f64::NEG_INFINITY,
    };

    /// The values of `values` outside `[lo, hi]`.
    pub fn of(values: impl IntoIterator<Item = f64>, lo: f64, hi: f64) -> Self {
        let mut o = Self::NONE;
        for v in values {
            o.add(v, lo, hi);
        }
        o
    }

    /// Count `v` if it lies outside `[lo, hi]`; whether it does.
    pub fn add(&mut self, v: f64, lo: f64, hi: f64) -> bool {
        if v < lo {
            self.below += 1;
            self.min_below = self.min_below.min(v);
        } else if v > hi {
            self.above += 1;
            self.max_above = self.max_above.max(v);
        } else {
            return false;
        }
        true
    }

    /// How many values lie outside.
    pub fn count(&self) -> usize {
        self.below + self.above
    }

    /// The sides as text, "`3 below, down to X; 1 above, up to Y`", each extreme written by
    /// `extreme(value, below)`.
    pub fn sides(&self, extreme: impl Fn(f64, bool) -> String) -> String {
        let mut sides = Vec::with_capacity(2);
        if self.below > 0 {
            sides.push(format!(
                "{} below, down to {}",
                self.below,
                extreme(self.min_below, true)
            ));
        }
        if self.above > 0 {
            sides.push(format!(
                "{} above, up to {}",
                self.above,
                extreme(self.max_above, false)
            ));
        }
        sides.join("; ")
    }
}

/// Per channel: the rows outside its range, the first time it leaves the range, and the
/// extremes of the whole channel.
#[derive(Clone, Copy)]
struct Excursion {
    outside: Outside,
    first: Option<f64>,
    min: f64,
    max: f64,
}

impl Excursion {
    const NONE: Self = Self {
        outside: Outside::NONE,
        first: None,
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
    };
}

/// [`range_warnings`] of input rows `(t [s], [n_e, u_delta, u_egr, u_vgt])` that are not (yet) an
/// [`InputSchedule`] (the Python API checks its rows so).
pub fn range_warnings_of_rows(
    rows: impl IntoIterator<Item = (f64, [f64; 4])>,
    ranges: &[(&str, f64, f64); 4],
) -> Vec<String> {
    let mut ex = [Excursion::NONE; 4];
    let mut n = 0usize;
    let mut prev: Option<(f64, [f64; 4])> = None;
    for (t, r) in rows {
        n += 1;
        for (c, (_, lo, hi)) in ranges.iter().enumerate() {
            let (v, e) = (r[c], &mut ex[c]);
            e.min = e.min.min(v);
            e.max = e.max.max(v);
            if e.outside.add(v, *lo, *hi) {
                e.first.get_or_insert_with(|| match prev {
                    // the input is linear between the rows: it crosses the limit in between
                    Some((tp, rp)) if t > tp && (*lo..=*hi).contains(&rp[c]) => {
                        let limit = if v > *hi { *hi } else { *lo };
                        tp + (limit - rp[c]) / (v - rp[c]) * (t - tp)
                    }
                    _ => t,
                });
            }
        }
        prev = Some((t, r));
    }
    ranges
        .iter()
        .zip(ex)
        .filter_map(|((name, lo, hi), e)| {
            let t = e.first?;
            Some(format!(
                "{name} is outside its range [{lo}, {hi}] at {} of {n} input rows ({}), first at \
                 t = {} s (the whole channel runs from {} to {}); the authors' saturation clamps \
                 it (the paper's semantics use it as given; the ranges are input_saturation of \
                 the parameter file)",
                e.outside.count(),
                e.outside.sides(|v, _| Num(v).to_string()),
                // to the microsecond: a crossing between rows is interpolated (0.9090909... s)
                Num((t * 1e6).round() / 1e6),
                Num(e.min),
                Num(e.max)
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<InputSchedule, String> {
        parse_inputs_csv(s, Path::new("in.csv")).map_err(|e| e.to_string())
    }

    /// An empty file said "missing column `time_s`" (session 43's user review).
    #[test]
    fn an_empty_file_says_so() {
        for text in ["", "\n\n", "# only a comment\n", "\u{feff}", "  \r\n"] {
            let e = parse_inputs_csv(text, Path::new("in.csv"))
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with("in.csv: the file is empty: expected a header (time_s,"),
                "{text:?}: {e}"
            );
        }
        // a header alone is no empty file
        let e = parse_inputs_csv(
            "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n",
            Path::new("in.csv"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("no data rows"), "{e}");
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
    fn semicolon_and_tab_files_with_decimal_commas_read_the_same_schedule() {
        let comma = parse(
            "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1500,110.5,80,75\n1.5,1500,110.5,80,65\n",
        )
        .unwrap();
        for text in [
            "time_s;n_e_rpm;u_delta_mg;u_egr_pct;u_vgt_pct\n0;1500;110,5;80;75\n1,5;1500;110,5;80;65\n",
            "time_s\tn_e_rpm\tu_delta_mg\tu_egr_pct\tu_vgt_pct\r\n0\t1500\t110,5\t80\t75\r\n1,5\t1500\t110.5\t80\t65\r\n",
        ] {
            let s = parse(text).unwrap();
            for t in [0.0, 0.75, 1.5] {
                assert_eq!(s.at(t), comma.at(t), "{text:?} at {t}");
            }
        }
        // a decimal comma in a comma-separated file is a field count error, named by line
        let e = parse("time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1500,110,5,80,75\n")
            .unwrap_err();
        assert!(
            e.contains("line 2") && e.contains("expected 5 fields, found 6 (a decimal comma?"),
            "{e}"
        );
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
        // CRLF line ends: the same lines (the csv crate alone said one line early)
        let crlf = |s: String| parse(&s.replace('\n', "\r\n")).unwrap_err();
        let e = crlf(format!("{h}0,1500,110,80,75\n1,1500,abc,80,75\n"));
        assert_eq!(
            e,
            "in.csv, line 3, column u_delta_mg: `abc` is not a number"
        );
        let e = crlf(format!(
            "{h}0,1500,110,80,75\n2,1500,110,80,75\n1,1500,110,80,75\n"
        ));
        assert!(e.starts_with("in.csv, line 4, column time_s"), "{e}");
        let e = crlf(format!("{h}# note\n0,1500,110,80,75\n1,1500,110,80\n"));
        assert!(e.starts_with("in.csv, line 4"), "{e}");
        // blank lines, LF and CRLF
        let blank = format!("{h}0,1500,110,80,75\n\n\n1,1500,abc,80,75\n");
        let e = parse(&blank).unwrap_err();
        assert!(e.starts_with("in.csv, line 5, column u_delta_mg"), "{e}");
        let e = crlf(blank);
        assert!(e.starts_with("in.csv, line 5, column u_delta_mg"), "{e}");
    }

    /// The direct reader's decimals are `str::parse`'s bit for bit: 200 000 random decimals
    /// of 1-19 digits with the point anywhere, signs, leading zeros; the forms it leaves to
    /// `str::parse` give `None`.
    #[test]
    fn plain_decimals_equal_str_parse() {
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut direct = 0;
        for _ in 0..200_000 {
            let r = next();
            let digits = 1 + (r % 19) as usize;
            let mut t = String::new();
            match (r >> 8) % 3 {
                0 => t.push('-'),
                1 => t.push('+'),
                _ => {}
            }
            let dot = ((r >> 16) % (digits as u64 + 2)) as usize;
            for i in 0..digits {
                if i == dot {
                    t.push('.');
                }
                t.push(char::from(b'0' + (next() % 10) as u8));
            }
            if dot == digits {
                t.push('.');
            }
            let want: f64 = t.parse().unwrap();
            if let Some(v) = plain_decimal(t.as_bytes()) {
                assert_eq!(v.to_bits(), want.to_bits(), "{t}");
                direct += 1;
            }
        }
        assert!(direct > 150_000, "{direct} read directly");
        for (t, v) in [
            ("500.000000", 500.0),
            ("-0", -0.0),
            ("0.1", 0.1),
            (".5", 0.5),
        ] {
            assert_eq!(
                plain_decimal(t.as_bytes()).unwrap().to_bits(),
                f64::to_bits(v)
            );
        }
        for t in [
            "",
            "-",
            ".",
            "1e5",
            "1.2.3",
            "inf",
            "NaN",
            "1 2",
            "12345678901234567890",
        ] {
            assert_eq!(plain_decimal(t.as_bytes()), None, "{t}");
        }
        // 2^53 and more digits: left to str::parse
        assert_eq!(plain_decimal(b"9007199254740992"), None);
        assert_eq!(
            plain_decimal(b"9007199254740991").unwrap(),
            9007199254740991.0
        );
    }

    /// The direct reader and the csv crate read the same table from the built-in WHTC (also
    /// with CRLF line ends and no final line break) and from reordered, blank-padded columns;
    /// files with comments, quotes, blank lines or bad fields go to the csv crate.
    #[test]
    fn plain_table_equals_csv_crate() {
        let whtc = include_str!("../../../../data/whtc_inputs_10hz.csv");
        let crlf = whtc.replace('\n', "\r\n");
        let h = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n";
        let cases = [
            whtc.to_string(),
            crlf.trim_end().to_string(),
            " u_vgt_pct,time_s ,n_e_rpm,u_delta_mg,u_egr_pct\n75, 0,1500,110,80\n65,1e0,+1500,-0,80".into(),
        ];
        for c in &cases {
            let plain = plain_table(c).expect("a plain table");
            let full = csv_table(c, Path::new("x")).unwrap();
            assert_eq!(plain.0.len(), full.0.len());
            let bits = |t: &Table| -> Vec<u64> {
                t.0.iter()
                    .chain(t.1.iter().flatten())
                    .map(|v| v.to_bits())
                    .collect()
            };
            assert!(bits(&plain) == bits(&full));
            // the file line of each row (CRLF too: `file_line`)
            let lines: Vec<usize> = (2..plain.0.len() + 2).collect();
            assert!(plain.2 == lines);
            assert!(full.2 == lines, "csv crate line numbers");
        }
        assert_eq!(cases[0].lines().count(), 18_002);
        for c in [
            format!("{h}0,1500,110,80,75\n# note\n1,1500,110,80,65\n"),
            format!("{h}0,1500,110,80,75\n\n1,1500,110,80,65\n"),
            format!("{h}\"0\",1500,110,80,75\n"),
            format!("{h}0,1500,110,80\n"),
            format!("{h}0,1500,110,80,75,1\n"),
            format!("{h}0,1500,NaN,80,75\n"),
            format!("{h}0,1500,abc,80,75\n"),
            h.to_string(),
            "time_s,n_e_rpm,u_delta_mg,u_egr_pct\n0,1,1,1\n".into(),
            "time_s,time_s,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1,1,1,1\n".into(),
            "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\r0,1,1,1,1\r".into(),
        ] {
            assert!(plain_table(&c).is_none(), "{c:?}");
        }
    }

    /// A fuel of 0 below the range [1, 250] read "(values from 0 to 0)" (the extremes of the
    /// values outside only, which read as a channel that is 0 throughout): the warning counts the
    /// rows below and above with their extremes and gives the whole channel's values.
    #[test]
    fn a_range_warning_counts_the_rows_outside_and_gives_the_channel() {
        let h = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n";
        let s = parse(&format!(
            "{h}0,1500,0,80,75\n1,1500,0,80,75\n2,1500,110,80,75\n3,1500,300,80,75\n4,1500,120,80,75\n"
        ))
        .unwrap();
        let w = range_warnings(&s, &INPUT_RANGES);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].starts_with(
                "u_delta_mg is outside its range [1, 250] at 3 of 5 input rows (2 below, down to \
                 0; 1 above, up to 300), first at t = 0 s (the whole channel runs from 0 to 300); \
                 the authors' saturation clamps it"
            ),
            "{}",
            w[0]
        );
        // one side only: the other is not named
        let s = parse(&format!("{h}0,1500,110,80,75\n2,1500,110,80,0\n")).unwrap();
        let w = range_warnings(&s, &INPUT_RANGES);
        assert!(
            w[0].starts_with(
                "u_vgt_pct is outside its range [20, 100] at 1 of 2 input rows (1 below, down to \
                 0), first at t = 1.466667 s"
            ),
            "{}",
            w[0]
        );
        assert!(
            w[0].contains("(the whole channel runs from 0 to 75)"),
            "{}",
            w[0]
        );
    }

    #[test]
    fn out_of_range_inputs_warn_once_per_channel() {
        let h = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n";
        let s = parse(&format!(
            "{h}0,1500,110,80,10\n1,1500,110,80,5\n2,2500,110,80,50\n"
        ))
        .unwrap();
        let w = range_warnings(&s, &INPUT_RANGES);
        assert_eq!(w.len(), 2);
        // 1500 rpm at 1 s, 2500 rpm at 2 s: 2000 rpm at 1.5 s
        assert!(
            w[0].starts_with(
                "n_e_rpm is outside its range [500, 2000] at 1 of 3 input rows (1 above, up to \
                 2500), first at t = 1.5 s (the whole channel runs from 1500 to 2500)"
            ),
            "{}",
            w[0]
        );
        assert_eq!(
            w[1],
            "u_vgt_pct is outside its range [20, 100] at 2 of 3 input rows (2 below, down to 5), \
             first at t = 0 s (the whole channel runs from 5 to 50); the authors' saturation \
             clamps it (the paper's semantics use it as given; the ranges are \
             input_saturation of the parameter file)"
        );
        // the authors' ranges are the default parameter set's; another engine's speed range
        let authors = [
            ("n_e_rpm", 500.0, 2000.0),
            ("u_delta_mg", 1.0, 250.0),
            ("u_egr_pct", 0.0, 100.0),
            ("u_vgt_pct", 20.0, 100.0),
        ];
        assert_eq!(INPUT_RANGES, authors);
        assert_eq!(input_ranges(&InputSaturation::default()), authors);
        let car = InputSaturation {
            n_e: [700.0, 4500.0],
            u_delta: [1.0, 80.0],
            ..InputSaturation::default()
        };
        let w = range_warnings(&s, &input_ranges(&car));
        assert_eq!(w.len(), 2);
        assert!(
            w[0].starts_with(
                "u_delta_mg is outside its range [1, 80] at 3 of 3 input rows (3 above, up to \
                 110), first at t = 0 s"
            ),
            "{}",
            w[0]
        );
        assert!(w[1].starts_with("u_vgt_pct"));
        // and its VGT command range (session 39): a VGT commanded 0-100 % takes 5 % as given,
        // one commanded 10-90 % clamps it
        let full = InputSaturation {
            u_vgt: [0.0, 100.0],
            ..car.clone()
        };
        let w = range_warnings(&s, &input_ranges(&full));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].starts_with("u_delta_mg"), "{w:?}");
        let mid = InputSaturation {
            u_vgt: [10.0, 90.0],
            ..car
        };
        let w = range_warnings(&s, &input_ranges(&mid));
        assert!(
            w[1].starts_with(
                "u_vgt_pct is outside its range [10, 90] at 1 of 3 input rows (1 below, down to 5)"
            ),
            "{w:?}"
        );
    }
}
