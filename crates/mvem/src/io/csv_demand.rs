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

use super::csv_columns::{read_columns, ColumnsError};
use super::{format_err as err, IoError};
use crate::control::cycle::{header_fields, is_normalized_header, parse_normalized_table};
use crate::control::drive::CycleSource;
use crate::control::Demand;
use std::path::Path;

/// The columns a demand CSV needs, in [`parse_demand_csv`]'s order.
pub const DEMAND_COLUMNS: [&str; 3] = ["t", "n_e", "M_ref"];

/// Read a demand cycle from CSV text (`path` only names it in messages). Every problem is named:
/// a missing column (with the columns found), a field that is not a number (its line and
/// column), and what [`Demand::new`] refuses (too few rows, times not increasing, non-finite
/// values: the row counted after the header). The speeds are checked against an engine's range
/// when the cycle runs ([`Demand::check_speeds`]).
pub fn parse_demand_csv(text: &str, path: &Path) -> Result<Demand, IoError> {
    let rows = read_columns(text, &DEMAND_COLUMNS).map_err(|e| match e {
        ColumnsError::Header(m) => err(path, Some(1), None, format!("cannot read the header: {m}")),
        ColumnsError::Missing { missing, found } => err(
            path,
            Some(1),
            None,
            format!(
                "missing column(s) {} (needed: t [s], n_e [rpm], M_ref [Nm], or for a normalized \
                 cycle time [s], speed [%], torque [%]; found: {})",
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
    let (mut t, mut n, mut m) = (vec![], vec![], vec![]);
    for (_, v) in rows {
        t.push(v[0]);
        n.push(v[1]);
        m.push(v[2]);
    }
    let k = t.len();
    Demand::new(t, n, m, vec![false; k]).map_err(|e| {
        err(
            path,
            None,
            None,
            format!("{e} (rows counted after the header)"),
        )
    })
}

/// Read a drive cycle (`path` only names it in messages): a normalized cycle when the header
/// names a speed and a torque column but not all of `t`, `n_e`, `M_ref`
/// ([`parse_normalized_table`]), else a speed/torque demand ([`parse_demand_csv`]). Every problem
/// is named with its line.
pub fn parse_cycle_file(text: &str, path: &Path) -> Result<CycleSource, IoError> {
    let fields = header_fields(text);
    let demand = DEMAND_COLUMNS.iter().all(|c| fields.contains(c));
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
        assert!(
            e.contains("row 3") && e.contains("time must increase"),
            "{e}"
        );
        let e = parse("t,n_e,M_ref\n0,1000,100\n").unwrap_err();
        assert!(e.contains("c.csv: "), "{e}");
        let e = parse("t,n_e,M_ref\n0,1000,100\n1,1000\n").unwrap_err();
        assert!(e.contains("line 3"), "{e}");
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
            "t speed torque\n0 0 0\n0 50 10\n",
            "line 3: time 0 s is not after",
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
}
