//! Report directories: check an `--out DIR` before computing, render figures to SVG and PNG,
//! and write all files of a report atomically (each file via a temporary file and a rename)
//! once everything has been computed and rendered.

use crate::common;
use crate::plot::{self, Figure};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Refuse an `--out` path that exists and is not a directory (before any computation).
pub fn check(dir: &Path) -> Result<()> {
    if dir.as_os_str().is_empty() {
        return Err(common::usage("--out: empty directory name"));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(common::usage(format!(
            "--out {}: exists and is not a directory",
            dir.display()
        )));
    }
    Ok(())
}

/// Files of a report, collected in memory and written together by [`Files::write`].
#[derive(Default)]
pub struct Files(Vec<(String, Vec<u8>)>);

impl Files {
    /// Add a file `name` with `bytes`.
    pub fn add(&mut self, name: impl Into<String>, bytes: impl Into<Vec<u8>>) {
        self.0.push((name.into(), bytes.into()));
    }

    /// Add `STEM.svg` and `STEM.png` of a figure (`plot::render` encodes PNGs at the best
    /// compression).
    pub fn figure(&mut self, stem: &str, fig: &Figure) -> Result<()> {
        self.add(format!("{stem}.svg"), plot::render(fig, plot::Format::Svg)?);
        self.add(format!("{stem}.png"), plot::render(fig, plot::Format::Png)?);
        Ok(())
    }

    /// Create `dir` if missing and write every file atomically; returns the paths written. On a
    /// failure the files this call already wrote are removed again (none of the set is left).
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir)
            .map_err(|e| common::usage(format!("--out {}: {e}", dir.display())))?;
        let mut written = Vec::with_capacity(self.0.len());
        for (name, bytes) in &self.0 {
            let p = dir.join(name);
            if let Err(e) = mvem::io::output::write_atomic(&p, bytes)
                .with_context(|| format!("cannot write {}", p.display()))
            {
                remove_all(&written);
                return Err(e);
            }
            written.push(p);
        }
        Ok(written)
    }

    /// Whether the set holds a file `name`.
    pub fn has(&self, name: &str) -> bool {
        self.0.iter().any(|(n, _)| n == name)
    }
}

/// Remove `paths` (best effort: a run that failed cleans up what it wrote).
pub fn remove_all(paths: &[PathBuf]) {
    for p in paths {
        let _ = std::fs::remove_file(p);
    }
}

/// Remove the files among `ours` (names a command writes in its `--out` directory) that a
/// previous run left in `dir` and this run did not write (`files`), so that the directory holds
/// one run's results; returns their names.
pub fn remove_stale(dir: &Path, ours: &[&str], files: &Files) -> Vec<String> {
    let mut removed = Vec::new();
    for name in ours {
        let p = dir.join(name);
        if !files.has(name) && p.is_file() && std::fs::remove_file(&p).is_ok() {
            removed.push(name.to_string());
        }
    }
    removed
}

/// "Wrote a, b, c" for the end of a command's output.
pub fn wrote(paths: &[PathBuf]) -> String {
    format!(
        "Wrote {}",
        paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    )
}
