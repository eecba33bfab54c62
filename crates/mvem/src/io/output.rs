//! Result files, always written atomically: the data go to a temporary file in the target's
//! directory, which is renamed over the target only when complete.

use super::IoError;
use crate::sim::Solution;
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Write `bytes` to `path` atomically (temporary file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Write to `path` atomically through a buffered writer: `fill` writes the content to a
/// temporary file in the target's directory, which is flushed and renamed over the
/// target only when `fill` succeeded (on any error the temporary file is removed).
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), IoError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_else(|| "out".into());
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let res = (|| {
        let f = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::with_capacity(1 << 16, f);
        fill(&mut w)?;
        // no fsync: the rename is atomic for every reader; durability across a power loss is
        // left to the file system (an fsync of a WHTC CSV took 30 ms, more than its formatting)
        w.into_inner().map_err(|e| e.into_error())?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(source) = res {
        let _ = std::fs::remove_file(&tmp);
        return Err(IoError::File {
            path: path.to_path_buf(),
            source,
        });
    }
    Ok(())
}

/// Named columns of a solution to write: `t` first, then `signals` in the order given
/// (states or signals; `None`: every column). An unknown name is an error listing the known
/// ones.
pub fn select_columns<'a>(
    sol: &'a Solution,
    signals: Option<&[String]>,
) -> Result<Vec<(&'a str, &'a [f64])>, String> {
    let all = || {
        sol.names
            .iter()
            .zip(&sol.columns)
            .map(|(n, c)| (n.as_str(), c.as_slice()))
    };
    let Some(names) = signals else {
        return Ok(all().collect());
    };
    let mut out: Vec<(&str, &[f64])> = all().take(1).collect();
    for n in names {
        let n = n.trim();
        if n == "t" {
            continue;
        }
        match all().find(|(k, _)| *k == n) {
            Some(c) if !out.iter().any(|(k, _)| *k == n) => out.push(c),
            Some(_) => return Err(format!("signal {n:?} is listed twice")),
            None => {
                return Err(format!(
                    "unknown signal {n:?}; known: {}",
                    sol.names[1..].join(", ")
                ))
            }
        }
    }
    Ok(out)
}

/// Write columns as CSV: a header of the names, then one line per sample, each number in the
/// shortest representation that reads back to the same f64 (ryu; `NaN`, `inf`, `-inf` for
/// non-finite values), without an allocation per field. Long outputs are formatted in row
/// blocks on up to 4 rayon workers (formatting, not the simulation, dominates writing) and written in
/// order: the same bytes as one thread.
pub fn write_csv(w: &mut dyn Write, cols: &[(&str, &[f64])]) -> std::io::Result<()> {
    let names: Vec<&str> = cols.iter().map(|c| c.0).collect();
    w.write_all(names.join(",").as_bytes())?;
    w.write_all(b"\n")?;
    let rows = cols.first().map_or(0, |c| c.1.len());
    let threads = rayon::current_num_threads().min(4);
    // below about 100 k numbers a thread costs more than it saves
    if threads < 2 || rows * cols.len() < 100_000 {
        let mut out = Vec::with_capacity(cols.len() * 24 * rows.min(4096));
        for block in (0..rows).step_by(4096) {
            out.clear();
            csv_rows(cols, block..(block + 4096).min(rows), &mut out);
            w.write_all(&out)?;
        }
        return Ok(());
    }
    // one block per worker of rayon's pool (the crate's one parallelism mechanism: inside an
    // ensemble or a map the blocks share that pool instead of starting threads of their own)
    let per = rows.div_ceil(threads);
    let blocks: Vec<Vec<u8>> = (0..rows)
        .into_par_iter()
        .step_by(per)
        .map(|a| {
            let r = a..(a + per).min(rows);
            let mut out = Vec::with_capacity(cols.len() * 20 * r.len());
            csv_rows(cols, r, &mut out);
            out
        })
        .collect();
    for b in blocks {
        w.write_all(&b)?;
    }
    Ok(())
}

/// The CSV lines of the rows `r` of `cols` appended to `out` (see [`write_csv`]).
fn csv_rows(cols: &[(&str, &[f64])], r: std::ops::Range<usize>, out: &mut Vec<u8>) {
    let mut buf = ryu::Buffer::new();
    for i in r {
        for (j, (_, c)) in cols.iter().enumerate() {
            if j > 0 {
                out.push(b',');
            }
            out.extend_from_slice(buf.format(c[i]).as_bytes());
        }
        out.push(b'\n');
    }
}

/// The solution as CSV text (every column; see [`write_csv`]).
pub fn solution_csv(sol: &Solution) -> String {
    let mut out = Vec::with_capacity(sol.len() * sol.names.len() * 20);
    let cols = select_columns(sol, None).expect("every column exists");
    write_csv(&mut out, &cols).expect("writing to memory cannot fail");
    String::from_utf8(out).expect("ASCII")
}

/// Write the solution as CSV atomically.
pub fn write_solution_csv(sol: &Solution, path: &Path) -> Result<(), IoError> {
    let cols = select_columns(sol, None).expect("every column exists");
    write_columns(&cols, path)
}

/// Write columns atomically to `path`: Parquet when the name ends in `.parquet` (one DOUBLE
/// column per name, [`write_parquet`]), CSV otherwise ([`write_csv`]).
pub fn write_columns(cols: &[(&str, &[f64])], path: &Path) -> Result<(), IoError> {
    let parquet = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("parquet"));
    write_atomic_with(path, |w| {
        if parquet {
            write_parquet(w, cols)
        } else {
            write_csv(w, cols)
        }
    })
}

/// Write columns as an Apache Parquet file: one row group, one required DOUBLE column per name
/// (plain encoding, uncompressed: the values are the f64 bits, as in memory), readable by
/// pyarrow, pandas and polars.
pub fn write_parquet<W: Write + Send>(w: W, cols: &[(&str, &[f64])]) -> std::io::Result<()> {
    use parquet::basic::{Repetition, Type as PhysicalType};
    use parquet::column::writer::ColumnWriter;
    use parquet::file::properties::WriterProperties;
    use parquet::file::writer::SerializedFileWriter;
    use parquet::schema::types::Type;
    use std::sync::Arc;
    let err = |e: parquet::errors::ParquetError| std::io::Error::other(e.to_string());
    let fields = cols
        .iter()
        .map(|(n, _)| {
            Type::primitive_type_builder(n, PhysicalType::DOUBLE)
                .with_repetition(Repetition::REQUIRED)
                .build()
                .map(Arc::new)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(err)?;
    let schema = Type::group_type_builder("mvem")
        .with_fields(fields)
        .build()
        .map_err(err)?;
    let props = WriterProperties::builder()
        .set_dictionary_enabled(false)
        .set_created_by(format!("mvem {}", env!("CARGO_PKG_VERSION")))
        .build();
    let mut fw = SerializedFileWriter::new(w, Arc::new(schema), Arc::new(props)).map_err(err)?;
    let mut rg = fw.next_row_group().map_err(err)?;
    for (_, c) in cols {
        let Some(mut cw) = rg.next_column().map_err(err)? else {
            break;
        };
        match cw.untyped() {
            ColumnWriter::DoubleColumnWriter(t) => {
                t.write_batch(c, None, None).map_err(err)?;
            }
            _ => return Err(std::io::Error::other("parquet: column is not DOUBLE")),
        }
        cw.close().map_err(err)?;
    }
    rg.close().map_err(err)?;
    fw.close().map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The multi-threaded CSV (row blocks) is byte for byte the single-threaded one, for a row
    /// count that does not divide evenly, with non-finite values.
    #[test]
    fn csv_blocks_equal_one_pass() {
        let rows = 30_001;
        let a: Vec<f64> = (0..rows).map(|i| (i as f64 * 0.37).sin() * 1e5).collect();
        let b: Vec<f64> = (0..rows)
            .map(|i| match i % 7919 {
                0 => f64::NAN,
                1 => f64::NEG_INFINITY,
                _ => 1.0 / (i as f64 + 0.5),
            })
            .collect();
        let cols: Vec<(&str, &[f64])> = vec![("t", &a), ("x", &b), ("y", &a), ("z", &b)];
        let mut threaded = Vec::new();
        write_csv(&mut threaded, &cols).unwrap();
        let mut one = b"t,x,y,z\n".to_vec();
        csv_rows(&cols, 0..rows, &mut one);
        assert!(rows * cols.len() >= 100_000, "must take the threaded path");
        assert_eq!(threaded.len(), one.len());
        assert!(threaded == one);
        assert_eq!(threaded.iter().filter(|&&c| c == b'\n').count(), rows + 1);
    }

    /// A step response written as CSV and as Parquet: the same names, and every value of the
    /// Parquet file equal to the CSV's to 1e-12 relative (the CSV's shortest round-trip
    /// numbers read back exactly, so they are in fact identical); `--signals`-style selection.
    #[test]
    fn parquet_equals_csv_and_selection_keeps_t_first() {
        use crate::model::{Drive, Engine8};
        use crate::sim::{simulate, InputSchedule, SimOptions, Start};
        use parquet::file::reader::{FileReader, SerializedFileReader};
        use parquet::record::RowAccessor;
        let m = Engine8::published();
        let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let sched = InputSchedule::steps(d0, &[(1.0, 3, 65.0)]).unwrap();
        // io does not name analysis: start at the model's initial guess (any trajectory will do)
        let sol = simulate(
            &m,
            &sched,
            0.0,
            3.0,
            Start::State(crate::model::Model::initial_guess(&m, &d0)),
            &SimOptions::default(),
        )
        .unwrap();
        let d = tempfile::tempdir().unwrap();
        let cols = select_columns(&sol, None).unwrap();
        write_columns(&cols, &d.path().join("s.csv")).unwrap();
        write_columns(&cols, &d.path().join("s.parquet")).unwrap();
        let text = std::fs::read_to_string(d.path().join("s.csv")).unwrap();
        let mut lines = text.lines();
        let names: Vec<&str> = lines.next().unwrap().split(',').collect();
        assert_eq!(
            names,
            sol.names.iter().map(String::as_str).collect::<Vec<_>>()
        );
        let csv: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(csv.len(), sol.len());
        let r = SerializedFileReader::new(std::fs::File::open(d.path().join("s.parquet")).unwrap())
            .unwrap();
        let fields: Vec<String> = r
            .metadata()
            .file_metadata()
            .schema()
            .get_fields()
            .iter()
            .map(|f| f.name().to_string())
            .collect();
        assert_eq!(fields, sol.names);
        let mut rows = 0;
        for (i, row) in r.get_row_iter(None).unwrap().enumerate() {
            let row = row.unwrap();
            for (j, want) in csv[i].iter().enumerate() {
                let got = row.get_double(j).unwrap();
                assert!(
                    (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{} row {i}: {got} vs {want}",
                    names[j]
                );
                // shortest round trip: the CSV text reads back to the very f64
                assert_eq!(want.to_bits(), sol.columns[j][i].to_bits());
            }
            rows += 1;
        }
        assert_eq!(rows, sol.len());
        let sel = select_columns(&sol, Some(&["W_c".into(), "p_im".into()])).unwrap();
        assert_eq!(
            sel.iter().map(|c| c.0).collect::<Vec<_>>(),
            ["t", "W_c", "p_im"]
        );
        let e = select_columns(&sol, Some(&["W_cc".into()])).unwrap_err();
        assert!(
            e.contains("unknown signal \"W_cc\"") && e.contains("lambda_O"),
            "{e}"
        );
        assert!(select_columns(&sol, Some(&["W_c".into(), "W_c".into()])).is_err());
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.csv");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "two");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);
        // a directory that does not exist: error, nothing created
        let bad = d.path().join("nope").join("b.csv");
        let e = write_atomic(&bad, b"x").unwrap_err().to_string();
        assert!(e.contains("nope"), "{e}");
    }
}
