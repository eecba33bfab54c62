//! Named numeric columns of a CSV file: the reader shared by the demand cycles
//! ([`super::csv_demand`]) and the tuning campaigns' stationary and dynamic files
//! ([`crate::tuning::data`]). Columns in any order, other columns ignored, blanks around names
//! and fields trimmed, `#` comment lines skipped; every value a number, with its 1-based line.
//! (The input time series have their own reader with a fast path, [`super::csv_inputs`].)
//!
//! Both read the comma-separated files mvem writes and, as a spreadsheet in a locale with a
//! decimal comma exports them, files separated by `;` or tabs whose numbers may be written
//! `1,5` ([`Dialect`]).

/// How a CSV text separates its fields and writes its numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dialect {
    /// Field separator: `,`, or `;` / tab.
    pub delimiter: u8,
    /// Whether a number may use a decimal comma (`1,5`): only when the separator is not `,`.
    pub decimal_comma: bool,
}

impl Dialect {
    /// The dialect of `text`, from its header (the first line that is neither blank nor a
    /// `comment` line): `;` or tab when the header has no comma but that separator (`;` first),
    /// with decimal commas allowed; `,` otherwise.
    pub fn of(text: &str, comment: Option<u8>) -> Self {
        let header = header_line(text, comment);
        let other = |sep: char| !header.contains(',') && header.contains(sep);
        match (other(';'), other('\t')) {
            (true, _) => Self::with(b';'),
            (false, true) => Self::with(b'\t'),
            _ => Self {
                delimiter: b',',
                decimal_comma: false,
            },
        }
    }

    fn with(delimiter: u8) -> Self {
        Self {
            delimiter,
            decimal_comma: true,
        }
    }

    /// A (trimmed) field as a number: `str::parse`, and with a decimal comma a field with one
    /// `,` and no `.` read with the comma as the point (`-1,5e3` is -1500).
    pub fn number(&self, field: &str) -> Option<f64> {
        if let Ok(v) = field.parse::<f64>() {
            return Some(v);
        }
        if self.decimal_comma && field.matches(',').count() == 1 && !field.contains('.') {
            return field.replacen(',', ".", 1).parse().ok();
        }
        None
    }
}

/// The header of `text`: its first line (trimmed) that is neither blank nor a `comment` line
/// ("" when there is none).
pub fn header_line(text: &str, comment: Option<u8>) -> &str {
    text.lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && comment.is_none_or(|c| !l.as_bytes().starts_with(&[c])))
        .unwrap_or("")
}

/// A header name and the unit in brackets or parentheses after it (`p_im [kPa]`, `T_em (degC)`,
/// `Speed [%]`): the one reading of such headers, shared by the demand cycles, the normalized
/// cycles' column names, `mvem campaign --init` and the campaign loader.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeaderUnit<'a> {
    /// The text before the first `[` or `(` (the whole header without one), untrimmed.
    pub name: &'a str,
    /// The text between that bracket and the first `]` or `)` after it (or the end), trimmed;
    /// `None` when there is no bracket or nothing in it.
    pub unit: Option<&'a str>,
    /// Whether the unit's closing bracket ends the header (`p_im [kPa]`, not `p_im [kPa] avg`
    /// or `p_im [kPa`).
    pub closed: bool,
}

impl<'a> HeaderUnit<'a> {
    /// The unit the header gives its column: the one in brackets that end the header
    /// (`p_im [kPa]`; not `p_im [kPa] avg`), as the campaign loader and `campaign --init` read
    /// it.
    pub fn closed_unit(&self) -> Option<&'a str> {
        self.unit.filter(|_| self.closed)
    }
}

/// `header` split at its unit in brackets ([`HeaderUnit`]).
pub fn split_unit(header: &str) -> HeaderUnit<'_> {
    let Some(open) = header.find(['[', '(']) else {
        return HeaderUnit {
            name: header,
            unit: None,
            closed: false,
        };
    };
    let rest = &header[open + 1..];
    let close = rest.find([']', ')']);
    let inner = &rest[..close.unwrap_or(rest.len())];
    HeaderUnit {
        name: &header[..open],
        unit: Some(inner.trim()).filter(|u| !u.is_empty()),
        closed: close.is_some_and(|c| c + 1 == rest.len()),
    }
}

/// Why a CSV's named columns could not be read: each caller words it for its own file.
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnsError {
    /// The header cannot be read.
    Header(String),
    /// Required columns are missing (in the order asked), with the columns found.
    Missing {
        /// The names not found.
        missing: Vec<String>,
        /// The header's names.
        found: Vec<String>,
    },
    /// A malformed record (e.g. a different number of fields), at its line if known.
    Record {
        /// 1-based line.
        line: Option<usize>,
        /// The CSV reader's message.
        message: String,
    },
    /// A field is missing or not a number.
    NotANumber {
        /// 1-based line.
        line: usize,
        /// Index of the column in the names asked for.
        column: usize,
        /// The field's text (empty if missing).
        field: String,
    },
}

/// The file line of a csv crate record position. The crate takes a record's position where
/// the previous record ended, before its line end and any blank or comment lines (line and
/// byte), i.e. one line early after a CRLF line end and one per blank or comment line: the record
/// starts after the line-end bytes and the comment lines (starting with `comment`) at that
/// position, and each `\n` among them is one more line.
pub(crate) fn file_line(text: &str, p: &csv::Position, comment: Option<u8>) -> usize {
    let b = text.as_bytes();
    let mut k = (p.byte() as usize).min(b.len());
    let mut line = p.line() as usize;
    while k < b.len() {
        let line_start = k == 0 || b[k - 1] == b'\n';
        match b[k] {
            b'\r' => k += 1,
            b'\n' => {
                line += 1;
                k += 1;
            }
            c if line_start && Some(c) == comment => {
                match b[k..].iter().position(|&x| x == b'\n') {
                    Some(n) => {
                        line += 1;
                        k += n + 1;
                    }
                    None => break,
                }
            }
            _ => break,
        }
    }
    line
}

/// A reader of `text` in its dialect: fields trimmed, `#` comment lines skipped.
fn reader(text: &str) -> (Dialect, csv::Reader<&[u8]>) {
    let dialect = Dialect::of(text, Some(b'#'));
    let rdr = csv::ReaderBuilder::new()
        .delimiter(dialect.delimiter)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    (dialect, rdr)
}

/// The column names of `text`'s header (trimmed), read as [`read_columns`] reads it.
pub fn header_names(text: &str) -> Result<Vec<String>, ColumnsError> {
    let (_, mut rdr) = reader(text);
    let header = rdr
        .headers()
        .map_err(|e| ColumnsError::Header(e.to_string()))?;
    Ok(header.iter().map(str::to_string).collect())
}

/// The values of the columns `names` (in that order) of every data row of `text`, each row with
/// its 1-based line in the file.
pub fn read_columns(text: &str, names: &[&str]) -> Result<Vec<(usize, Vec<f64>)>, ColumnsError> {
    let column_of = |h: &str| names.iter().position(|c| *c == h);
    read_columns_matched(text, names, &column_of, false).map(|(_, rows)| rows)
}

/// [`read_columns`] with an optional units row under the header (a record without a number,
/// [`read_columns_matched`]), returned with its line.
pub fn read_columns_with_units(text: &str, names: &[&str]) -> Result<UnitsAndRows, ColumnsError> {
    let column_of = |h: &str| names.iter().position(|c| *c == h);
    read_columns_matched(text, names, &column_of, true)
}

/// [`read_columns`] with the header's names matched by `column_of` (a header name -> the index
/// in `names` of the column it is, or `None`; the first header name matching a column is
/// taken) and, with `units_row`, the first record taken as a units row when none of its fields
/// matched is a number (`s,rpm,Nm`; an empty field is no number): returned with its 1-based
/// line and the rows, its fields in `names`' order.
pub fn read_columns_matched(
    text: &str,
    names: &[&str],
    column_of: &dyn Fn(&str) -> Option<usize>,
    units_row: bool,
) -> Result<UnitsAndRows, ColumnsError> {
    let (dialect, mut rdr) = reader(text);
    let header = rdr
        .headers()
        .map_err(|e| ColumnsError::Header(e.to_string()))?
        .clone();
    let col = |want: usize| header.iter().position(|h| column_of(h) == Some(want));
    let missing: Vec<String> = (0..names.len())
        .filter(|&c| col(c).is_none())
        .map(|c| names[c].to_string())
        .collect();
    if !missing.is_empty() {
        return Err(ColumnsError::Missing {
            missing,
            found: header.iter().map(str::to_string).collect(),
        });
    }
    let idx: Vec<usize> = (0..names.len())
        .map(|c| col(c).unwrap_or_default())
        .collect();
    let mut rows = Vec::new();
    let mut units = None;
    for rec in rdr.records() {
        let rec = rec.map_err(|e| ColumnsError::Record {
            line: e.position().map(|p| file_line(text, p, Some(b'#'))),
            message: e.to_string(),
        })?;
        let line = rec.position().map_or(0, |p| file_line(text, p, Some(b'#')));
        if units_row && rows.is_empty() && units.is_none() {
            let field = |i: usize| rec.get(i).unwrap_or("");
            if idx.iter().all(|&i| dialect.number(field(i)).is_none()) {
                units = Some((line, idx.iter().map(|&i| field(i).to_string()).collect()));
                continue;
            }
        }
        let mut row = Vec::with_capacity(names.len());
        for (column, &i) in idx.iter().enumerate() {
            let field = rec.get(i).unwrap_or("");
            row.push(
                dialect
                    .number(field)
                    .ok_or_else(|| ColumnsError::NotANumber {
                        line,
                        column,
                        field: field.to_string(),
                    })?,
            );
        }
        rows.push((line, row));
    }
    Ok((units, rows))
}

/// A units row (its 1-based line and its fields in the asked columns' order), if any, and the
/// data rows each with its 1-based line ([`read_columns_matched`]).
pub type UnitsAndRows = (Option<(usize, Vec<String>)>, Vec<(usize, Vec<f64>)>);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_by_name_with_their_lines_and_every_problem_named() {
        // the lines after blank and comment lines and a CRLF line end
        let text = "# comment\n b , a ,x\n1, 2 ,q\r\n\n# more\n\n3,4,r\n#\n5,6,s";
        assert_eq!(
            read_columns(text, &["a", "b"]).unwrap(),
            vec![
                (3, vec![2.0, 1.0]),
                (7, vec![4.0, 3.0]),
                (9, vec![6.0, 5.0])
            ]
        );
        assert_eq!(
            read_columns(text, &["a", "c", "d"]).unwrap_err(),
            ColumnsError::Missing {
                missing: vec!["c".into(), "d".into()],
                found: vec!["b".into(), "a".into(), "x".into()],
            }
        );
        assert_eq!(
            read_columns("a,b\n1,2\n1,zz\n", &["b"]).unwrap_err(),
            ColumnsError::NotANumber {
                line: 3,
                column: 0,
                field: "zz".into()
            }
        );
        assert!(matches!(
            read_columns("a,b\n1,2\n1\n", &["a"]).unwrap_err(),
            ColumnsError::Record { line: Some(3), .. }
        ));
        assert_eq!(read_columns("a,b\n", &["a"]).unwrap(), vec![]);
    }

    #[test]
    fn a_unit_in_brackets_is_split_from_the_name() {
        let h = |name, unit, closed| HeaderUnit { name, unit, closed };
        assert_eq!(split_unit("p_im [kPa]"), h("p_im ", Some("kPa"), true));
        assert_eq!(split_unit("T_em(degC)"), h("T_em", Some("degC"), true));
        assert_eq!(
            split_unit("p_im [ kPa ] avg"),
            h("p_im ", Some("kPa"), false)
        );
        assert_eq!(split_unit("p_im [kPa"), h("p_im ", Some("kPa"), false));
        assert_eq!(split_unit("a []"), h("a ", None, true));
        assert_eq!(split_unit("p_im"), h("p_im", None, false));
        // a units row is a record without a number; its line is the file's
        let (units, rows) = read_columns_matched(
            "t,a\n# c\ns,\n0,1\n",
            &["a", "t"],
            &|h| ["a", "t"].iter().position(|c| *c == h),
            true,
        )
        .unwrap();
        assert_eq!(units, Some((3, vec![String::new(), "s".into()])));
        assert_eq!(rows, vec![(4, vec![1.0, 0.0])]);
        // a record with a number is data (and its other field not a number)
        assert_eq!(
            read_columns_matched(
                "t,a\ns,1\n",
                &["t", "a"],
                &|h| ["t", "a"].iter().position(|c| *c == h),
                true
            )
            .unwrap_err(),
            ColumnsError::NotANumber {
                line: 2,
                column: 0,
                field: "s".into()
            }
        );
    }

    #[test]
    fn spreadsheet_exports_with_semicolons_or_tabs_and_decimal_commas() {
        // the same table as a spreadsheet in a decimal-comma locale writes it
        let comma = "# x\nt,a,b\n0,1.5,-2e3\n1,2,0.25\n";
        let semi = "# x\nt;a;b\n0;1,5;-2e3\n1;2;0,25\n";
        let tab = "t\ta\tb\n0\t1,5\t-2e3\n1\t2.0\t0,25\n";
        let want = read_columns(comma, &["b", "a"]).unwrap();
        assert_eq!(read_columns(semi, &["b", "a"]).unwrap(), want);
        let tab_rows = read_columns(tab, &["b", "a"]).unwrap();
        let values = |r: &[(usize, Vec<f64>)]| r.iter().map(|x| x.1.clone()).collect::<Vec<_>>();
        assert_eq!(values(&tab_rows), values(&want));
        // a comma file never takes a decimal comma (a quoted "1,5" is not a number there), and
        // a thousands separator is not a number in either
        assert!(matches!(
            read_columns("a,b\n\"1,5\",2\n", &["a"]).unwrap_err(),
            ColumnsError::NotANumber { line: 2, .. }
        ));
        assert_eq!(
            read_columns("a;b\n1.234,5;2\n", &["a"]).unwrap_err(),
            ColumnsError::NotANumber {
                line: 2,
                column: 0,
                field: "1.234,5".into()
            }
        );
        assert_eq!(Dialect::of("\n# c;d\na,b\n", Some(b'#')).delimiter, b',');
        assert_eq!(Dialect::of("a;b\n1,5;2", None).number("1,5"), Some(1.5));
        assert_eq!(Dialect::of("a,b\n", None).number("1,5"), None);
    }
}
