//! Drive cycles for the closed loop (`mvem closed-loop --cycle FILE`, the explorer's closed-loop
//! mode, Python's `closed_loop(cycle=PATH)`), in one of two forms told apart by the header
//! ([`parse_cycle_file`]):
//!
//! - a speed/torque demand: a CSV with the columns `t` \[s\], `n_e` \[rpm\] and `M_ref` \[Nm\]
//!   (any order, other columns ignored, `#` comments), linear between rows
//!   ([`crate::control::Demand`]);
//! - a normalized cycle as UN GTR No. 4 publishes them (`Time Speed Torque` with speed and
//!   torque in percent, "m" for motoring: `data/whtc_normalized.tsv`, the WHSC, a user's own),
//!   denormalized with the engine's mapping curve as the built-in WHTC is
//!   ([`crate::control::cycle::parse_normalized_table`]).

use super::csv_columns::{header_names, read_columns_matched, split_unit, ColumnsError};
use super::csv_inputs::schedule_error;
use super::{format_err as err, IoError};
use crate::control::cycle::{
    bare_name, header_fields, is_normalized_header, parse_normalized_table,
};
use crate::control::drive::CycleSource;
use crate::control::Demand;
use crate::sim::input::check_time_order;
use crate::tuning::data::units_of;
use std::path::Path;

/// The columns a demand CSV needs, in [`parse_demand_csv`]'s order.
pub const DEMAND_COLUMNS: [&str; 3] = ["t", "n_e", "M_ref"];

/// The unit each of [`DEMAND_COLUMNS`] is in (a column given in another unit of the same
/// quantity is converted, [`crate::tuning::data`]'s table).
const DEMAND_UNITS: [&str; 3] = ["s", "r/min", "Nm"];

/// Which of [`DEMAND_COLUMNS`] a header name is, as the normalized cycles' parser reads names
/// (case ignored, a unit in brackets after the name apart): `t` or a name starting with `time`,
/// `n_e`, `M_ref`.
pub fn demand_column(header: &str) -> Option<usize> {
    let n = bare_name(header);
    if n == "t" || n.starts_with("time") {
        Some(0)
    } else if n == "n_e" {
        Some(1)
    } else if n == "m_ref" {
        Some(2)
    } else {
        None
    }
}

/// Read a demand cycle from CSV text (`path` only names it in messages): the columns `t` \[s\],
/// `n_e` \[rpm\], `M_ref` \[Nm\] in any order, other columns ignored, the names read as the
/// normalized cycles' ([`demand_column`]: `Time` for `t`, case ignored), each with an optional
/// unit in brackets (`n_e [rpm]`) or an optional units row under the header (`s,rpm,Nm`); a
/// column in another unit of its quantity is converted (`ms`, `krpm`, `rad/s`, `kNm`), an
/// unknown unit refused. Every problem is named: a missing or doubled column (with the columns
/// found), a unit, a field that is not a number (its line and column), times out of order (its
/// line: a time before the previous row's, or a third row at one time; two rows at one time are
/// a step, as in `simulate --inputs`, [`check_time_order`]), and what [`Demand::new`] refuses
/// (too few rows, non-finite values: the row counted after the header and the units row). The speeds are checked against an engine's range when the cycle
/// runs ([`Demand::check_speeds`]).
pub fn parse_demand_csv(text: &str, path: &Path) -> Result<Demand, IoError> {
    let header = header_names(text).map_err(|e| {
        let m = match e {
            ColumnsError::Header(m) => m,
            other => format!("{other:?}"),
        };
        err(path, Some(1), None, format!("cannot read the header: {m}"))
    })?;
    for c in 0..DEMAND_COLUMNS.len() {
        let named: Vec<&String> = header
            .iter()
            .filter(|h| demand_column(h) == Some(c))
            .collect();
        if named.len() > 1 {
            return Err(err(
                path,
                Some(1),
                None,
                format!(
                    "the columns {} all name {} (give it once)",
                    named
                        .iter()
                        .map(|h| format!("'{h}'"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    DEMAND_COLUMNS[c]
                ),
            ));
        }
    }
    let (units_row, rows) = read_columns_matched(text, &DEMAND_COLUMNS, &demand_column, true)
        .map_err(|e| match e {
            ColumnsError::Header(m) => {
                err(path, Some(1), None, format!("cannot read the header: {m}"))
            }
            ColumnsError::Missing { missing, found } => err(
                path,
                Some(1),
                None,
                format!(
                    "missing column(s) {} (needed: t [s], n_e [rpm], M_ref [Nm], or for a \
                     normalized cycle time [s], speed [%], torque [%]; found: {})",
                    missing.join(", "),
                    found.join(", ")
                ),
            ),
            ColumnsError::Record { line, message } => err(path, line, None, message),
            ColumnsError::NotANumber {
                line,
                column,
                field,
            } => err(
                path,
                Some(line),
                Some(DEMAND_COLUMNS[column]),
                format!("'{field}' is not a number"),
            ),
        })?;
    // each column's conversion to its unit: from the header's brackets, else the units row
    let mut scale = [(1.0, 0.0); 3];
    for (c, conv) in scale.iter_mut().enumerate() {
        let name = header
            .iter()
            .find(|h| demand_column(h) == Some(c))
            .map_or("", String::as_str);
        let (unit, place) = match (split_unit(name).unit, &units_row) {
            (Some(u), _) => (u.to_string(), "the header"),
            (None, Some((_, r))) => (r[c].trim().to_string(), "the units row"),
            (None, None) => continue,
        };
        if unit.is_empty() {
            continue;
        }
        let known = units_of(DEMAND_UNITS[c]);
        match known.iter().find(|k| k.0 == unit) {
            Some(&(_, s, o)) => *conv = (s, o),
            None => {
                let hint = if unit == "%" {
                    " (a normalized cycle has the columns time [s], speed [%], torque [%])"
                } else {
                    ""
                };
                return Err(err(
                    path,
                    None,
                    Some(DEMAND_COLUMNS[c]),
                    format!(
                        "unit '{unit}' in {place} is not a unit of {} (one of {}){hint}",
                        DEMAND_COLUMNS[c],
                        known.iter().map(|k| k.0).collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
        }
    }
    let (mut t, mut n, mut m, mut lines) = (vec![], vec![], vec![], vec![]);
    let conv = |c: usize, v: f64| scale[c].0 * v + scale[c].1;
    for (line, v) in rows {
        t.push(conv(0, v[0]));
        n.push(conv(1, v[1]));
        m.push(conv(2, v[2]));
        lines.push(line);
    }
    // the order of the times as `simulate --inputs` reads it (two rows at one time are a step),
    // named with the file's line
    for i in 0..t.len() {
        check_time_order(&t, i).map_err(|e| schedule_error(path, &lines, "t", e))?;
    }
    let k = t.len();
    let after = if units_row.is_some() {
        "the header and the units row"
    } else {
        "the header"
    };
    Demand::new(t, n, m, vec![false; k])
        .map(|d| d.with_lines(lines))
        .map_err(|e| {
            err(
                path,
                None,
                None,
                format!("{e} (rows counted after {after})"),
            )
        })
}

/// Read a drive cycle (`path` only names it in messages): a normalized cycle when the header
/// names a speed and a torque column but not all of `t`, `n_e`, `M_ref`
/// ([`parse_normalized_table`]), else a speed/torque demand ([`parse_demand_csv`]). Every problem
/// is named with its line.
pub fn parse_cycle_file(text: &str, path: &Path) -> Result<CycleSource, IoError> {
    let fields = header_fields(text);
    let demand =
        (0..DEMAND_COLUMNS.len()).all(|c| fields.iter().any(|f| demand_column(f) == Some(c)));
    if !demand && is_normalized_header(&fields) {
        return parse_normalized_table(text)
            .map(CycleSource::Normalized)
            .map_err(|m| err(path, None, None, format!("normalized cycle, {m}")));
    }
    parse_demand_csv(text, path).map(CycleSource::Demand)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Demand, String> {
        parse_demand_csv(text, Path::new("c.csv")).map_err(|e| e.to_string())
    }

    #[test]
    fn reads_the_columns_in_any_order_and_names_every_problem() {
        let d = parse("# a comment\nM_ref, t ,extra,n_e\n100,0,x,1200\n300,2,y,1400\n").unwrap();
        let p = d.at(1.0);
        assert_eq!((p.n_e, p.m_ref), (1300.0, 200.0));
        assert_eq!(
            parse("t,n_e\n0,1000\n1,1000\n").unwrap_err(),
            "c.csv, line 1: missing column(s) M_ref (needed: t [s], n_e [rpm], M_ref [Nm], or for a \
             normalized cycle time [s], speed [%], torque [%]; found: t, n_e)"
        );
        assert_eq!(
            parse("t,n_e,M_ref\n0,1000,100\n1,fast,100\n").unwrap_err(),
            "c.csv, line 3, column n_e: 'fast' is not a number"
        );
        // the file's line, after comment and blank lines
        assert_eq!(
            parse("t,n_e,M_ref\n0,1000,100\n# a pause\n\n1,fast,100\n").unwrap_err(),
            "c.csv, line 5, column n_e: 'fast' is not a number"
        );
        let e = parse("t,n_e,M_ref\n0,1000,100\n2,1000,100\n1,1000,100\n").unwrap_err();
        assert_eq!(
            e,
            "c.csv, line 4, column t: time 1 s is not monotonic (previous 2 s)"
        );
        let e = parse("t,n_e,M_ref\n0,1000,100\n").unwrap_err();
        assert!(e.contains("c.csv: "), "{e}");
        let e = parse("t,n_e,M_ref\n0,1000,100\n1,1000\n").unwrap_err();
        assert!(e.contains("line 3"), "{e}");
    }

    /// The checks of a demand read from a file (the engine's speed range here) name the file's
    /// line, as the reader's own errors do: the third row below is line 6 (a comment, the
    /// header, a units row and a blank line before it; it was named "row 3"), also after a cut
    /// by `--duration` ([`Demand::until`]); a demand built from arrays names its 1-based row.
    #[test]
    fn the_checks_of_a_file_name_its_lines() {
        let d = parse("# my cycle\nt,n_e,M_ref\ns,rpm,Nm\n0,1000,100\n\n2,1000,100\n3,2500,100\n")
            .unwrap();
        let e = d.check_speeds((500.0, 2000.0)).unwrap_err().to_string();
        assert_eq!(
            e,
            "demand: line 7 (t = 3 s): speed 2500 rpm is outside the model's range [500, 2000] \
             rpm (the parameter set's [input_saturation] n_e)"
        );
        let e = d.check_speeds((1500.0, 2600.0)).unwrap_err().to_string();
        assert!(
            e.starts_with("demand: line 4 (t = 0 s): speed 1000 rpm"),
            "{e}"
        );
        // cut between the second and the third row: the cut point (t = 2.5 s, 1750 rpm) is
        // named by the line of the row after it
        let cut = d.until(2.5).unwrap();
        let e = cut.check_speeds((500.0, 1700.0)).unwrap_err().to_string();
        assert!(
            e.starts_with("demand: line 7 (t = 2.5 s): speed 1750 rpm"),
            "{e}"
        );
        let e = cut.check_speeds((1001.0, 2000.0)).unwrap_err().to_string();
        assert!(e.starts_with("demand: line 4 (t = 0 s)"), "{e}");
        let arrays = Demand::new(
            vec![0.0, 1.0],
            vec![1000.0, 2500.0],
            vec![0.0; 2],
            vec![false; 2],
        )
        .unwrap();
        let e = arrays
            .check_speeds((500.0, 2000.0))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("demand: row 2 (t = 1 s)"), "{e}");
    }

    /// Two rows at one time are a step (session 41; before, "time must increase"), as in
    /// `simulate --inputs`: the demand before the time is the first row's segment, at and after
    /// it the second row's; a third row at one time and a time going back are refused naming the
    /// file's line (after comments and a units row too), in the words of `simulate --inputs`.
    #[test]
    fn a_repeated_time_is_a_step() {
        let d = parse("t,n_e,M_ref\n0,1200,100\n2,1200,100\n2,1300,1500\n4,1300,1500\n").unwrap();
        assert_eq!(d.times(), &[0.0, 2.0, 2.0, 4.0]);
        let at = |t: f64| {
            let p = d.at(t);
            (p.n_e, p.m_ref)
        };
        assert_eq!(at(1.999), (1200.0, 100.0));
        assert_eq!(at(2.0), (1300.0, 1500.0));
        assert_eq!(at(3.0), (1300.0, 1500.0));
        // a step at the first time: the second row from the start
        let d = parse("t,n_e,M_ref\n0,1200,100\n0,1200,900\n1,1200,900\n").unwrap();
        assert_eq!(d.at(0.0).m_ref, 900.0);
        // cut at the step (a --duration): both rows kept, the step still at the end
        let d = parse("t,n_e,M_ref\n0,1200,100\n2,1200,100\n2,1200,1500\n4,1200,1500\n").unwrap();
        let cut = d.until(2.0).unwrap();
        assert_eq!(cut.times(), &[0.0, 2.0, 2.0]);
        assert_eq!((cut.at(1.999).m_ref, cut.at(2.0).m_ref), (100.0, 1500.0));
        let cut = d.until(3.0).unwrap();
        assert_eq!(cut.times(), &[0.0, 2.0, 2.0, 3.0]);
        assert_eq!(cut.at(2.5).m_ref, 1500.0);
        assert_eq!(
            parse("t,n_e,M_ref\n0,1200,100\n2,1200,100\n2,1200,900\n2,1200,1500\n").unwrap_err(),
            "c.csv, line 5, column t: time 2 s is not monotonic (previous 2 s) (more than two \
             rows with the same time)"
        );
        assert_eq!(
            parse("# c\nt,n_e,M_ref\ns,rpm,Nm\n0,1200,100\n2,1200,100\n\n1.5,1200,100\n")
                .unwrap_err(),
            "c.csv, line 7, column t: time 1.5 s is not monotonic (previous 2 s)"
        );
        // the rule is the input schedules' (the same function): Demand::new names the row
        let e = crate::control::Demand::new(
            vec![0.0, 1.0, 1.0, 1.0],
            vec![1200.0; 4],
            vec![100.0; 4],
            vec![false; 4],
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("row 4: time 1 s is not monotonic (previous 1 s) (more than two rows"),
            "{e}"
        );
    }

    /// A demand's header is read as the normalized cycles' are: units in brackets or in a units
    /// row (converted: ms, krpm, kNm), `Time` for `t`, case ignored; an unknown unit, a column
    /// named twice and columns of different lengths are named.
    #[test]
    fn a_demand_header_may_carry_units_and_other_spellings() {
        let want = parse("t,n_e,M_ref\n0,1000,200\n5,1200,500\n").unwrap();
        let close = |d: &Demand| {
            [0.0, 1.0, 2.5, 5.0].iter().all(|&t| {
                let (a, b) = (d.at(t), want.at(t));
                (a.n_e - b.n_e).abs() < 1e-9 && (a.m_ref - b.m_ref).abs() < 1e-9
            }) && d.span() == want.span()
        };
        for text in [
            "t [s],n_e [rpm],M_ref [Nm]\n0,1000,200\n5,1200,500\n",
            "t,n_e,M_ref\ns,rpm,Nm\n0,1000,200\n5,1200,500\n",
            "Time,n_e,M_ref\n0,1000,200\n5,1200,500\n",
            "T,N_E,m_ref\n0,1000,200\n5,1200,500\n",
            "time [ms],n_e (krpm),M_ref [kNm]\n0,1,0.2\n5000,1.2,0.5\n",
            "t;n_e;M_ref\ns;rpm;Nm\n0;1000;200\n5;1200;500\n",
        ] {
            assert!(close(&parse(text).unwrap()), "{text}");
            assert!(matches!(cycle(text), Ok(CycleSource::Demand(_))), "{text}");
        }
        let e = parse("t,n_e [%],M_ref\n0,50,200\n5,60,500\n").unwrap_err();
        assert!(
            e.contains("column n_e: unit '%' in the header is not a unit of n_e (one of r/min")
                && e.contains("a normalized cycle"),
            "{e}"
        );
        let e = parse("t,n_e,M_ref\ns,rpm,lbft\n0,1000,200\n5,1200,500\n").unwrap_err();
        assert!(
            e.contains("unit 'lbft' in the units row is not a unit of M_ref"),
            "{e}"
        );
        let e = parse("t,time,n_e,M_ref\n0,0,1000,200\n5,5,1200,500\n").unwrap_err();
        assert!(e.contains("the columns 't', 'time' all name t"), "{e}");
        let e = parse("t,n_e,M_ref\ns,rpm,Nm\n0,1000,200\n").unwrap_err();
        assert!(e.contains("after the header and the units row"), "{e}");
        let e = Demand::new(vec![0.0, 1.0], vec![1000.0], vec![1.0, 2.0], vec![false; 2])
            .unwrap_err()
            .to_string();
        assert!(e.contains("different lengths: t 2, n_e 1, M_ref 2"), "{e}");
    }

    fn cycle(text: &str) -> Result<CycleSource, String> {
        parse_cycle_file(text, Path::new("c.txt")).map_err(|e| e.to_string())
    }

    fn rows(text: &str) -> Vec<crate::control::cycle::NormalizedRow> {
        match cycle(text) {
            Ok(CycleSource::Normalized(r)) => r,
            other => panic!("expected a normalized cycle, got {other:?}"),
        }
    }

    #[test]
    fn a_cycle_file_is_a_demand_or_a_normalized_cycle_by_its_header() {
        // the built-in WHTC table (tabs, a units row) reads as a normalized cycle, row for row
        let whtc = rows(crate::control::cycle::WHTC_NORMALIZED);
        assert_eq!(whtc.len(), 1800);
        assert_eq!(whtc[0], (1.0, 0.0, Some(0.0)));
        assert!(whtc.iter().any(|r| r.2.is_none()), "motoring rows");
        // the same rows with other separators, names with units, columns in another order
        let text: String = std::iter::once("Torque [%];Time [s];Speed [%]".to_string())
            .chain(whtc.iter().map(|(t, n, m)| {
                let m = m.map_or("m".to_string(), |v| v.to_string().replace('.', ","));
                format!("{m};{t};{}", n.to_string().replace('.', ","))
            }))
            .collect::<Vec<_>>()
            .join("\n");
        assert_eq!(rows(&text), whtc);
        let spaces = "time speed torque\n0 0 0\n10 55 100\n20 55 M\n";
        assert_eq!(
            rows(spaces),
            vec![
                (0.0, 0.0, Some(0.0)),
                (10.0, 55.0, Some(100.0)),
                (20.0, 55.0, None)
            ]
        );
        // the separator is the header's for every row: a blank-separated row with a decimal
        // comma is not split at the comma
        assert_eq!(
            rows("time speed torque\n0 0 0\n10 50,5 20\n"),
            vec![(0.0, 0.0, Some(0.0)), (10.0, 50.5, Some(20.0))]
        );
        // a demand stays a demand (also with extra speed/torque columns)
        for text in [
            "t,n_e,M_ref\n0,1000,100\n1,1000,200\n",
            "t,n_e,M_ref,speed,torque\n0,1000,100,1,1\n1,1000,200,1,1\n",
        ] {
            assert!(matches!(cycle(text), Ok(CycleSource::Demand(_))), "{text}");
        }
        // neither: the demand's message, which names both forms
        let e = cycle("time,rpm,Nm\n0,1000,100\n1,1000,200\n").unwrap_err();
        assert!(
            e.contains("normalized cycle time [s], speed [%], torque [%]"),
            "{e}"
        );
    }

    #[test]
    fn a_normalized_cycle_names_the_line_of_every_problem() {
        let bad = |text: &str, want: &str| {
            let e = cycle(text).unwrap_err();
            assert!(e.starts_with("c.txt: normalized cycle, "), "{e}");
            assert!(e.contains(want), "{want:?} not in {e:?}");
        };
        bad(
            "t speed torque\n0 0 0\n1 fast 0\n",
            "line 3: speed 'fast' is not a number",
        );
        bad(
            "t speed torque\n0 0 0\n1 1500 50\n",
            "line 3: speed 1500 % is outside [0, 120] %",
        );
        bad(
            "t speed torque\n0 0 0\n1 50 -3\n",
            "line 3: torque -3 % is outside [0, 100] %",
        );
        bad("t speed torque\n0 0 0\n1 50 101\n", "torque 101 %");
        bad(
            "t speed torque\n0 0 0\n1 50 10\n0.5 50 10\n",
            "line 4: time 0.5 s is not monotonic (previous 1 s)",
        );
        bad("t speed torque\n0 0 0\n1 50\n", "line 3: expected 3 fields");
        bad(
            "t\tspeed\ttorque\ns\trpm\tNm\n0\t0\t0\n",
            "line 2: the speed column's unit is 'rpm'",
        );
        bad(
            "t speed torque\n# only one row\n0 0 0\n",
            "needs at least two rows",
        );
        bad("speed torque\n0 0\n1 1\n", "line 1: no time column");
    }

    /// Two rows at one time in a normalized cycle are a step, as in a demand file (before, the
    /// second row was refused: "time 1 s is not after the previous row's 1 s"): the rows are
    /// kept, the denormalized demand jumps there (right-continuous), also out of a motoring row;
    /// a third row at that time is refused naming its line, in the demand reader's words.
    #[test]
    fn a_normalized_cycle_may_repeat_a_time_as_a_step() {
        let text = "Time\tSpeed\tTorque\n0\t20\tm\n2\t20\tm\n2\t30\t80\n4\t30\t80\n";
        assert_eq!(
            rows(text),
            vec![
                (0.0, 20.0, None),
                (2.0, 20.0, None),
                (2.0, 30.0, Some(80.0)),
                (4.0, 30.0, Some(80.0))
            ]
        );
        let m = crate::model::AnyModel::new(
            crate::model::ModelOrder::Eight,
            crate::params::Params::published(),
            Default::default(),
        )
        .unwrap();
        let curve = crate::control::cycle::MappingCurve::compute(&m, Default::default()).unwrap();
        let speeds = curve.reference_speeds(curve.n_e_range().0);
        let d = crate::control::cycle::whtc_demand(&rows(text), &curve, &speeds).unwrap();
        assert_eq!(d.times(), &[0.0, 2.0, 2.0, 4.0]);
        let (before, at, after) = (d.at(1.999), d.at(2.0), d.at(3.0));
        assert!(before.motoring && !at.motoring && !after.motoring);
        assert_eq!(at, after);
        assert_eq!(at.m_ref, 0.8 * curve.m_max_at(at.n_e));
        assert_eq!(before.m_ref, curve.m_motor_at(before.n_e));
        assert!(at.n_e > before.n_e, "{at:?} {before:?}");
        let e = cycle("t speed torque\n0 0 0\n1 50 10\n1 50 20\n1 50 30\n").unwrap_err();
        assert!(
            e.contains(
                "line 5: time 1 s is not monotonic (previous 1 s) (more than two rows with the \
                 same time)"
            ),
            "{e}"
        );
    }

    /// A row with more fields than the header names is refused naming its line and the extra
    /// fields (they were ignored: `1,50,20,7` read as 1 s, 50 %, 20 %), in every separation and
    /// for the units row; a trailing separator is named as such; a header with a trailing
    /// separator (a spreadsheet's export) and rows with the same are read.
    #[test]
    fn a_normalized_cycle_refuses_extra_fields() {
        let bad = |text: &str, want: &str| {
            let e = cycle(text).unwrap_err();
            assert!(e.contains(want), "{want:?} not in {e:?}");
        };
        bad(
            "Time,Speed,Torque\n0,0,0\n1,50,20,7\n",
            "line 3: expected 3 fields as the header on line 1 names, found 4: extra 7",
        );
        bad(
            "# a comment\nTime;Speed;Torque\n0;0;0\n\n1;50;20;7;x\n",
            "line 5: expected 3 fields as the header on line 2 names, found 5: extra 7, x",
        );
        bad(
            "Time\tSpeed\tTorque\ns\t%\t%\tkg\n0\t0\t0\n",
            "line 2: expected 3 fields as the header on line 1 names, found 4: extra kg",
        );
        bad(
            "time speed torque\n0 0 0\n1 50 20 7\n",
            "line 3: expected 3 fields as the header on line 1 names, found 4: extra 7",
        );
        bad(
            "Time;Speed;Torque\n0;0;0\n1;50;20;\n",
            "line 3: expected 3 fields as the header on line 1 names, found 4 (a separator at \
             the end of the line?)",
        );
        assert_eq!(
            rows("Time;Speed;Torque;\n0;0;0;\n1;50,5;m;\n"),
            vec![(0.0, 0.0, Some(0.0)), (1.0, 50.5, None)]
        );
    }

    /// Quoted fields of a delimited table are unquoted (the csv crate): quoted names, a quoted
    /// "m", a quoted number holding the separator; `"Time","Speed","Torque"` was not even taken
    /// for a normalized cycle's header (its time column was not found). Between blanks a quote
    /// is refused, naming the line.
    #[test]
    fn a_normalized_cycle_reads_quoted_fields() {
        let want = vec![
            (0.0, 0.0, Some(0.0)),
            (1.5, 50.0, None),
            (3.0, 60.5, Some(20.0)),
        ];
        assert_eq!(
            rows("\"Time [s]\",\"Speed [%]\",\"Torque [%]\"\n0,0,0\n\"1.5\",50,\"m\"\n3,60.5,20\n"),
            want
        );
        assert_eq!(
            rows("\"Time\";\"Speed\";\"Torque\"\n0;0;0\n1,5;50;\"m\"\n3;\"60,5\";20\n"),
            want
        );
        // a quoted comma in a comma-separated row is one field
        assert_eq!(
            rows("Speed,Torque,Time,Note\n0,0,0,\"idle, warm\"\n50,m,1.5,\"a, b\"\n60.5,20,3,x\n"),
            want
        );
        let e = cycle("time speed torque\n0 0 0\n1 \"50\" 20\n").unwrap_err();
        assert!(
            e.contains("line 3: field \"50\" is quoted, but the fields are separated by blanks"),
            "{e}"
        );
    }
}
