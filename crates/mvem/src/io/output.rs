//! Result files, always written atomically: the data go to a temporary file in the target's
//! directory, which is renamed over the target only when complete.

use super::IoError;
use crate::sim::{Block, Solution};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, SyncSender};

/// Write `bytes` to `path` atomically (temporary file + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    write_atomic_with(path, |w| w.write_all(bytes))
}

/// Write to `path` atomically through a buffered writer: `fill` writes the content to a
/// temporary file in the target's directory, which is flushed and renamed over the
/// target only when `fill` succeeded (on any error the temporary file is removed).
///
/// Where `path` is not a regular file the rename would replace what is there, so:
/// - a symbolic link to a regular file: the file it points to is written (atomically, in its
///   own directory), the link stays;
/// - an existing file that is no regular file (`/dev/null`, `/dev/stdout`, a named pipe): the
///   content is written into it directly (a device or a pipe has no partial state to guard;
///   the rename replaced `/dev/null` itself with a regular file when run as root).
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> Result<(), IoError> {
    let fail = |source| IoError::File {
        path: path.to_path_buf(),
        source,
    };
    // (follows symbolic links)
    if let Ok(meta) = std::fs::metadata(path) {
        let link = std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink());
        if meta.is_file() && link {
            let real = std::fs::canonicalize(path).map_err(fail)?;
            return write_atomic_with(&real, fill).map_err(|e| match e {
                IoError::File { source, .. } => fail(source),
                other => other,
            });
        } else if !meta.is_file() && !meta.is_dir() {
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .map_err(fail)?;
            let mut w = std::io::BufWriter::with_capacity(1 << 16, f);
            return fill(&mut w)
                .and_then(|()| w.into_inner().map(drop).map_err(|e| e.into_error()))
                .map_err(fail);
        }
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_else(|| "out".into());
    remove_stale_temporaries(&dir, &name);
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

/// Remove the temporary files `.NAME.tmp-PID` that an earlier writer of `dir/NAME` left behind
/// when it was killed before it could rename or remove them (a signal, a power loss), if that
/// process no longer runs and the file was last written more than 10 minutes ago (a writer in
/// another PID namespace sharing the directory is invisible in `/proc`, but it writes its file
/// at least every block). Linux only (it asks `/proc/PID`); elsewhere nothing is removed. Errors
/// are ignored: this is housekeeping, the write itself does not depend on it.
fn remove_stale_temporaries(dir: &Path, name: &str) {
    if !cfg!(target_os = "linux") {
        return;
    }
    let prefix = format!(".{name}.tmp-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let file = e.file_name();
        let Some(pid) = file.to_str().and_then(|f| f.strip_prefix(&prefix)) else {
            continue;
        };
        let Ok(pid) = pid.parse::<u32>() else {
            continue;
        };
        let idle = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|m| m.elapsed().ok())
            .is_some_and(|age| age > std::time::Duration::from_secs(600));
        if idle && pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// Named columns of a solution to write: `t` first, then `signals` in the order given
/// (states or signals; `None`: every column). An unknown name is an error listing the known
/// ones.
pub fn select_columns<'a>(
    sol: &'a Solution,
    signals: Option<&[String]>,
) -> Result<Vec<(&'a str, &'a [f64])>, String> {
    Ok(select_names(&sol.names, signals)?
        .into_iter()
        .map(|i| (sol.names[i].as_str(), sol.columns[i].as_slice()))
        .collect())
}

/// The indices in `names` (`t` first) of the columns [`select_columns`] selects.
pub fn select_names(names: &[String], signals: Option<&[String]>) -> Result<Vec<usize>, String> {
    let Some(wanted) = signals else {
        return Ok((0..names.len()).collect());
    };
    let mut out = vec![0];
    for n in wanted {
        let n = n.trim();
        if n == "t" {
            continue;
        }
        match names.iter().position(|k| k == n) {
            Some(i) if !out.contains(&i) => out.push(i),
            Some(_) => return Err(format!("signal {n:?} is listed twice")),
            None => {
                return Err(format!(
                    "unknown signal {n:?}; known: {}",
                    names[1..].join(", ")
                ))
            }
        }
    }
    Ok(out)
}

/// Write columns as CSV: a header of the names, then one line per sample, each number in the
/// shortest representation that reads back to the same f64 (ryu's format; `NaN`, `inf`, `-inf`
/// for non-finite values), without an allocation per field. Long outputs are formatted in row
/// blocks on up to 4 rayon workers (formatting, not the simulation, dominates writing) and written in
/// order: the same bytes as one thread.
pub fn write_csv(w: &mut dyn Write, cols: &[(&str, &[f64])]) -> std::io::Result<()> {
    let names: Vec<&str> = cols.iter().map(|c| c.0).collect();
    w.write_all(names.join(",").as_bytes())?;
    w.write_all(b"\n")?;
    let data: Vec<&[f64]> = cols.iter().map(|c| c.1).collect();
    let rows = cols.first().map_or(0, |c| c.1.len());
    let threads = rayon::current_num_threads().min(4);
    // below about 100 k numbers a thread costs more than it saves
    if threads < 2 || rows * cols.len() < 100_000 {
        let mut out = Vec::with_capacity(cols.len() * 24 * rows.min(4096));
        for block in (0..rows).step_by(4096) {
            out.clear();
            csv_rows(&data, block..(block + 4096).min(rows), &mut out);
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
            csv_rows(&data, r, &mut out);
            out
        })
        .collect();
    for b in blocks {
        w.write_all(&b)?;
    }
    Ok(())
}

/// The CSV lines of the rows `r` of `cols` appended to `out` (see [`write_csv`]).
fn csv_rows(cols: &[&[f64]], r: std::ops::Range<usize>, out: &mut Vec<u8>) {
    let mut buf = zmij::Buffer::new();
    for i in r {
        for (j, c) in cols.iter().enumerate() {
            if j > 0 {
                out.push(b',');
            }
            push_number(&mut buf, c[i], out);
        }
        out.push(b'\n');
    }
}

/// `x` in the shortest representation that reads back to the same f64, appended to `out`:
/// ryu's format (`1.0`, `0.00001`, `1e-6`, `1e16`, `NaN`, `inf`), formatted by zmij (about twice
/// as fast), which writes the same digits but a positive exponent with a sign (`1e+16`).
#[inline]
fn push_number(buf: &mut zmij::Buffer, x: f64, out: &mut Vec<u8>) {
    let s = buf.format(x).as_bytes();
    // positive exponents start at 1e16
    if x.abs() >= 1e16 {
        out.extend(s.iter().filter(|&&b| b != b'+'));
    } else {
        out.extend_from_slice(s);
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
    write_atomic_with(path, |w| {
        if is_parquet(path) {
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
    let names: Vec<&str> = cols.iter().map(|c| c.0).collect();
    let data: Vec<&[f64]> = cols.iter().map(|c| c.1).collect();
    let mut t = TableWriter::parquet(w, &names)?;
    t.write(&data)?;
    t.finish().map(drop)
}

/// A table of named f64 columns written block by block (the blocks are consecutive rows):
/// CSV, a header and then each block's lines exactly as [`write_csv`] formats them, or
/// Parquet, one row group per block with the column types of [`write_parquet`].
pub struct TableWriter<W: Write + Send> {
    format: Table<W>,
    columns: usize,
}

enum Table<W: Write + Send> {
    Csv { w: W, line: Vec<u8> },
    Parquet(parquet::file::writer::SerializedFileWriter<W>),
}

fn parquet_err(e: parquet::errors::ParquetError) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

impl<W: Write + Send> TableWriter<W> {
    /// A CSV table with the header `names`.
    pub fn csv(mut w: W, names: &[&str]) -> std::io::Result<Self> {
        w.write_all(names.join(",").as_bytes())?;
        w.write_all(b"\n")?;
        Ok(Self {
            format: Table::Csv {
                w,
                line: Vec::new(),
            },
            columns: names.len(),
        })
    }

    /// A Parquet table of required DOUBLE columns `names` (plain encoding, no dictionary, no
    /// compression).
    pub fn parquet(w: W, names: &[&str]) -> std::io::Result<Self> {
        use parquet::basic::{Repetition, Type as PhysicalType};
        use parquet::file::properties::WriterProperties;
        use parquet::file::writer::SerializedFileWriter;
        use parquet::schema::types::Type;
        use std::sync::Arc;
        let fields = names
            .iter()
            .map(|n| {
                Type::primitive_type_builder(n, PhysicalType::DOUBLE)
                    .with_repetition(Repetition::REQUIRED)
                    .build()
                    .map(Arc::new)
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(parquet_err)?;
        let schema = Type::group_type_builder("mvem")
            .with_fields(fields)
            .build()
            .map_err(parquet_err)?;
        let props = WriterProperties::builder()
            .set_dictionary_enabled(false)
            .set_created_by(format!("mvem {}", env!("CARGO_PKG_VERSION")))
            .build();
        let fw =
            SerializedFileWriter::new(w, Arc::new(schema), Arc::new(props)).map_err(parquet_err)?;
        Ok(Self {
            format: Table::Parquet(fw),
            columns: names.len(),
        })
    }

    /// A Parquet table if `path` ends in `.parquet` (any case), else a CSV table.
    pub fn for_path(w: W, path: &Path, names: &[&str]) -> std::io::Result<Self> {
        if is_parquet(path) {
            Self::parquet(w, names)
        } else {
            Self::csv(w, names)
        }
    }

    /// Append the rows of `cols`: one slice per name, all of the same length.
    pub fn write(&mut self, cols: &[&[f64]]) -> std::io::Result<()> {
        let rows = cols.first().map_or(0, |c| c.len());
        if cols.len() != self.columns || cols.iter().any(|c| c.len() != rows) {
            return Err(std::io::Error::other(format!(
                "table block: {} columns of lengths {:?}, expected {} columns of one length",
                cols.len(),
                cols.iter().map(|c| c.len()).collect::<Vec<_>>(),
                self.columns
            )));
        }
        match &mut self.format {
            Table::Csv { w, line } => {
                line.clear();
                csv_rows(cols, 0..rows, line);
                w.write_all(line)
            }
            Table::Parquet(fw) => {
                use parquet::column::writer::ColumnWriter;
                let mut rg = fw.next_row_group().map_err(parquet_err)?;
                for c in cols {
                    let Some(mut cw) = rg.next_column().map_err(parquet_err)? else {
                        break;
                    };
                    match cw.untyped() {
                        ColumnWriter::DoubleColumnWriter(t) => {
                            t.write_batch(c, None, None).map_err(parquet_err)?;
                        }
                        _ => return Err(std::io::Error::other("parquet: column is not DOUBLE")),
                    }
                    cw.close().map_err(parquet_err)?;
                }
                rg.close().map_err(parquet_err).map(drop)
            }
        }
    }

    /// Complete the table (Parquet: the footer) and return the writer.
    pub fn finish(self) -> std::io::Result<W> {
        match self.format {
            Table::Csv { w, .. } => Ok(w),
            Table::Parquet(fw) => fw.into_inner().map_err(parquet_err),
        }
    }
}

/// Whether `path` names a Parquet file (ends in `.parquet`, any case).
pub fn is_parquet(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("parquet"))
}

/// Why [`write_streaming`] failed.
#[derive(Debug)]
pub enum StreamError<E> {
    /// The computation producing the blocks failed.
    Produce(E),
    /// Writing failed.
    Io(IoError),
}

/// Write a table to `path` atomically while `produce` computes it. `produce` runs on the
/// calling thread and sends blocks of consecutive rows (for example a
/// [`Solution::streaming`] simulation, `crate::sim::simulate_into`); a second thread passes
/// each block through `map` (to select or add columns: the result has one column per entry
/// of `names`) and appends it to the file as it arrives, CSV or Parquet by the file name as in
/// [`write_columns`]: formatting overlaps the computation, and at most `in_flight` blocks wait
/// in between. The channel must be closed (every sender dropped) when `produce` returns.
///
/// The file appears, renamed from its temporary file, only if `produce` returned `Ok` and every
/// write succeeded; otherwise the temporary file is removed and nothing is left behind. A
/// failure of `produce` is reported before a write error.
pub fn write_streaming<T, E>(
    path: &Path,
    names: &[&str],
    in_flight: usize,
    mut map: impl FnMut(Block) -> Block + Send,
    produce: impl FnOnce(SyncSender<Block>) -> Result<T, E>,
) -> Result<T, StreamError<E>> {
    let (tx, rx) = sync_channel::<Block>(in_flight.max(1));
    let mut produced: Option<Result<T, E>> = None;
    let written = write_atomic_with(path, |w| {
        std::thread::scope(|s| {
            // a plain scoped thread, not rayon's pool: it blocks on the channel
            let writer = s.spawn(move || -> std::io::Result<()> {
                let mut table = TableWriter::for_path(w, path, names)?;
                for block in rx {
                    let block = map(block);
                    let cols: Vec<&[f64]> = block.iter().map(Vec::as_slice).collect();
                    table.write(&cols)?;
                }
                table.finish().map(drop)
            });
            let r = produce(tx);
            let failed = r.is_err();
            produced = Some(r);
            let w = writer
                .join()
                .unwrap_or_else(|p| std::panic::resume_unwind(p));
            if failed {
                // remove the temporary file: the computation did not complete
                return Err(std::io::Error::other("the computation failed"));
            }
            w
        })
    });
    match (produced, written) {
        (Some(Err(e)), _) => Err(StreamError::Produce(e)),
        (Some(Ok(t)), Ok(())) => Ok(t),
        (_, Err(e)) => Err(StreamError::Io(e)),
        (None, Ok(())) => unreachable!("write_atomic_with ran the closure"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Session 39: `mvem simulate --out /dev/null` (as root) renamed its temporary file over
    /// `/dev/null`, which became a regular file collecting every later write to it (and
    /// `--out /dev/stdout` replaced that link). A named pipe stands for such a file here: it is
    /// written into and stays a pipe; a symbolic link to a regular file stays a link, the file
    /// it points to gets the content; a plain file is replaced atomically as before.
    #[cfg(target_os = "linux")]
    #[test]
    fn special_files_and_links_are_written_into_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let ok = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap();
        assert!(ok.success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_atomic(&fifo, b"t,p_im\n0,1e5\n").unwrap();
        assert_eq!(reader.join().unwrap(), b"t,p_im\n0,1e5\n");
        let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
        assert!(kind.is_fifo(), "{kind:?}");
        // no temporary left beside it
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

        let real = dir.path().join("real.csv");
        std::fs::write(&real, "old").unwrap();
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
        write_atomic(&real, b"newer").unwrap();
        assert_eq!(std::fs::read(&link).unwrap(), b"newer");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
    }

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
        csv_rows(&[&a, &b, &a, &b], 0..rows, &mut one);
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

    /// The CSV numbers are ryu's text (the format before zmij formatted them): random bit
    /// patterns (every exponent, NaN payloads, subnormals), decimal magnitudes around the
    /// switches to exponent notation, integers.
    #[test]
    fn numbers_are_ryu_text() {
        let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut values = vec![
            0.0,
            -0.0,
            1.0,
            0.1,
            1e15,
            1e16,
            -1e16,
            1e17,
            1e-5,
            1e-6,
            1e16 - 2.0, // the largest f64 below 1e16
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::MIN,
        ];
        for _ in 0..200_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let m = (state >> 11) as f64 / (1u64 << 53) as f64;
            let e = (state % 45) as i32 - 22;
            values.extend([
                f64::from_bits(state),
                m * 10f64.powi(e),
                -m * 10f64.powi(e),
                (state % 1_000_000) as f64 * 0.1,
            ]);
        }
        let (mut zb, mut rb) = (zmij::Buffer::new(), ryu::Buffer::new());
        let mut out = Vec::new();
        for x in values {
            out.clear();
            push_number(&mut zb, x, &mut out);
            assert_eq!(std::str::from_utf8(&out).unwrap(), rb.format(x), "{x:e}");
        }
    }

    /// A simulation streamed block by block into CSV and Parquet files (`write_streaming`,
    /// a streaming `Solution`): the CSV is byte for byte the one of the kept solution, the
    /// Parquet file (one row group per block) holds the same values bit for bit, the statistics
    /// are the same, and a `map` that selects columns selects them. The same with the signals
    /// evaluated on the writer's thread (`Solution::streaming_deferred`): the same bytes and
    /// guards (the fuel cut to 2 mg at 1.3 s activates some).
    #[test]
    fn streamed_simulation_equals_kept() {
        use crate::model::{Drive, Engine8, Model};
        use crate::sim::{simulate, simulate_into, InputSchedule, SimOptions, Start};
        use parquet::file::reader::{FileReader, SerializedFileReader};
        use parquet::record::RowAccessor;
        let m = Engine8::published();
        let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let sched = InputSchedule::steps(d0, &[(0.7, 3, 65.0), (1.3, 1, 2.0)]).unwrap();
        let opts = SimOptions {
            dt_out: 1e-3,
            ..SimOptions::default()
        };
        let x0 = Start::State(m.initial_guess(&d0));
        let kept = simulate(&m, &sched, 0.0, 2.5, x0, &opts).unwrap();
        assert!(kept.len() > 5 * 300, "several blocks");
        let d = tempfile::tempdir().unwrap();
        let names: Vec<&str> = kept.names.iter().map(String::as_str).collect();
        let run = |path: &Path, sel: &[usize]| {
            let header: Vec<&str> = sel.iter().map(|i| names[*i]).collect();
            let map = |mut b: Block| sel.iter().map(|i| std::mem::take(&mut b[*i])).collect();
            write_streaming(path, &header, 2, map, |tx| {
                let into = Solution::streaming(&m.state_names(), 300, tx);
                simulate_into(&m, &sched, 0.0, 2.5, x0, &opts, into)
            })
            .unwrap()
        };
        let all: Vec<usize> = (0..names.len()).collect();
        let streamed = run(&d.path().join("s.csv"), &all);
        assert_eq!(streamed.stats, kept.stats);
        assert_eq!(streamed.guards_seen, kept.guards_seen);
        assert!(streamed.is_empty() && !streamed.is_streaming());
        write_solution_csv(&kept, &d.path().join("k.csv")).unwrap();
        let (s, k) = (
            std::fs::read(d.path().join("s.csv")).unwrap(),
            std::fs::read(d.path().join("k.csv")).unwrap(),
        );
        assert!(s == k, "streamed CSV differs from the kept solution's");

        // the signals evaluated by the writer from raw blocks (`Solution::streaming_deferred`,
        // `SignalEvaluator`): the same bytes and guards, the raw blocks 1 + 8 + 6 wide
        let mut eval = crate::sim::SignalEvaluator::new(&m);
        let mut widths = Vec::new();
        let map = |raw: Block| {
            widths.push(raw.len());
            eval.block(raw)
        };
        let deferred = write_streaming(&d.path().join("d.csv"), &names, 2, map, |tx| {
            let into = Solution::streaming_deferred(&m, 300, tx);
            simulate_into(&m, &sched, 0.0, 2.5, x0, &opts, into)
        })
        .unwrap();
        assert_eq!(deferred.stats, kept.stats);
        assert_eq!(deferred.guards_seen, 0, "seen by the evaluator");
        assert_eq!(eval.guards_seen(), kept.guards_seen);
        assert_ne!(kept.guards_seen, 0, "a test of the guards needs some");
        assert_eq!(deferred.columns.len(), names.len());
        assert_eq!(widths.len(), kept.len().div_ceil(300));
        assert!(widths.iter().all(|w| *w == 15), "{widths:?}");
        let dd = std::fs::read(d.path().join("d.csv")).unwrap();
        assert!(dd == k, "deferred signals differ from the kept solution's");

        // a model whose evaluation reads its memory (one-iteration cylinder temperature) is
        // evaluated while it integrates: full blocks, passed through, the same as kept
        let one = Engine8::new(
            m.params().clone(),
            crate::model::ModelOptions {
                cylinder_temp: crate::model::CylinderTemp::OneIteration,
                ..Default::default()
            },
        )
        .unwrap();
        let kept1 = simulate(&one, &sched, 0.0, 2.5, x0, &opts).unwrap();
        let mut eval1 = crate::sim::SignalEvaluator::new(&one);
        let mut widths1 = Vec::new();
        let map1 = |raw: Block| {
            widths1.push(raw.len());
            eval1.block(raw)
        };
        let d1 = write_streaming(&d.path().join("d1.csv"), &names, 2, map1, |tx| {
            let into = Solution::streaming_deferred(&one, 300, tx);
            simulate_into(&one, &sched, 0.0, 2.5, x0, &opts, into)
        })
        .unwrap();
        assert_eq!(d1.guards_seen, kept1.guards_seen);
        assert!(widths1.iter().all(|w| *w == names.len()), "{widths1:?}");
        write_solution_csv(&kept1, &d.path().join("k1.csv")).unwrap();
        assert!(
            std::fs::read(d.path().join("d1.csv")).unwrap()
                == std::fs::read(d.path().join("k1.csv")).unwrap()
        );

        let sel = [0, 3, 20];
        run(&d.path().join("s.parquet"), &sel);
        let r = SerializedFileReader::new(std::fs::File::open(d.path().join("s.parquet")).unwrap())
            .unwrap();
        assert_eq!(r.metadata().num_row_groups(), kept.len().div_ceil(300));
        let mut rows = 0;
        for (i, row) in r.get_row_iter(None).unwrap().enumerate() {
            let row = row.unwrap();
            for (j, c) in sel.iter().enumerate() {
                assert_eq!(
                    row.get_double(j).unwrap().to_bits(),
                    kept.columns[*c][i].to_bits()
                );
            }
            rows += 1;
        }
        assert_eq!(rows, kept.len());
    }

    /// A killed writer's `.NAME.tmp-PID` is removed by the next write of NAME.
    #[test]
    #[cfg(target_os = "linux")]
    fn stale_temporaries_of_dead_writers_are_removed() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("x.csv");
        // a pid above the kernel's maximum (4194304) never runs; our own pid does (a write
        // going on in another thread of this process)
        let dead = d.path().join(".x.csv.tmp-4999999");
        let live = d.path().join(format!(".x.csv.tmp-{}", std::process::id()));
        let other = d.path().join(".y.csv.tmp-4999999");
        let not_pid = d.path().join(".x.csv.tmp-abc");
        let recent = d.path().join(".x.csv.tmp-4999998");
        let old = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
        for f in [&dead, &other, &not_pid, &live, &recent] {
            std::fs::write(f, b"partial").unwrap();
            if f != &recent {
                let h = std::fs::File::options().write(true).open(f).unwrap();
                h.set_modified(old).unwrap();
            }
        }
        remove_stale_temporaries(d.path(), "x.csv");
        assert!(!dead.exists(), "the dead writer's temporary is removed");
        assert!(
            recent.exists(),
            "a temporary written in the last 10 minutes stays"
        );
        assert!(live.exists(), "this process's temporary stays");
        assert!(other.exists(), "another file's temporary stays");
        assert!(not_pid.exists(), "a name that is not .NAME.tmp-PID stays");
        write_atomic(&p, b"a\n1\n").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"a\n1\n");
    }

    /// Nothing is left behind when the computation fails after blocks were written, nor when
    /// writing fails (here: blocks of the wrong width) while the computation goes on; the
    /// computation's error comes first.
    #[test]
    fn streaming_failure_leaves_nothing() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("x.csv");
        let block = || vec![vec![1.0; 1000], vec![2.0; 1000]];
        let e = write_streaming(
            &p,
            &["t", "a"],
            1,
            |b| b,
            |tx| {
                for _ in 0..5 {
                    tx.send(block()).unwrap();
                }
                Err::<(), _>("diverged")
            },
        )
        .unwrap_err();
        assert!(matches!(e, StreamError::Produce("diverged")), "{e:?}");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);

        // the writer fails at the first block; the producer's later sends find the channel
        // closed and it still ends
        let sent = write_streaming(
            &p,
            &["t", "a", "b"],
            1,
            |b| b,
            |tx| Ok::<_, ()>((0..50).filter(|_| tx.send(block()).is_ok()).count()),
        );
        match sent {
            Err(StreamError::Io(e)) => assert!(e.to_string().contains("columns"), "{e}"),
            other => panic!("{other:?}"),
        }
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);

        // an existing file is kept when the new one fails
        std::fs::write(&p, "old").unwrap();
        let _ = write_streaming(
            &p,
            &["t", "a"],
            1,
            |b| b,
            |tx| {
                tx.send(block()).unwrap();
                Err::<(), _>(())
            },
        );
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "old");
        assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 1);
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
