//! Speed/torque demand cycles for the closed loop (`mvem closed-loop --cycle FILE.csv`, the
//! explorer's closed-loop mode): a CSV with the columns `t` \[s\], `n_e` \[rpm\] and `M_ref` \[Nm\]
//! (any order, other columns ignored, `#` comments), linear between rows
//! ([`crate::control::Demand`]).

use super::csv_columns::{read_columns, ColumnsError};
use super::{format_err as err, IoError};
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
                "missing column(s) {} (needed: t [s], n_e [rpm], M_ref [Nm]; found: {})",
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
            "c.csv, line 1: missing column(s) M_ref (needed: t [s], n_e [rpm], M_ref [Nm]; found: t, n_e)"
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
}
