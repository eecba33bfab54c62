//! Result files, always written atomically: the data go to a temporary file in the target's
//! directory, which is renamed over the target only when complete.

use super::IoError;
use crate::sim::Solution;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Write `bytes` to `path` atomically (temporary file + fsync + rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let file_err = |p: &Path, source| IoError::File {
        path: p.to_path_buf(),
        source,
    };
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
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if let Err(e) = res {
        let _ = std::fs::remove_file(&tmp);
        return Err(file_err(path, e));
    }
    Ok(())
}

/// The solution as CSV text (header = column names; shortest round-trip number format).
pub fn solution_csv(sol: &Solution) -> String {
    let mut s = String::with_capacity(sol.len() * sol.names.len() * 20);
    s.push_str(&sol.names.join(","));
    s.push('\n');
    for i in 0..sol.len() {
        for (j, c) in sol.columns.iter().enumerate() {
            if j > 0 {
                s.push(',');
            }
            use std::fmt::Write as _;
            let _ = write!(s, "{}", c[i]);
        }
        s.push('\n');
    }
    s
}

/// Write the solution as CSV atomically.
pub fn write_solution_csv(sol: &Solution, path: &Path) -> Result<(), IoError> {
    write_atomic(path, solution_csv(sol).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

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
