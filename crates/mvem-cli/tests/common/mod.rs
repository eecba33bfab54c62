//! Helpers shared by the end-to-end tests of the `mvem` binary.
// Each test crate uses a different subset.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Run `mvem` with `args` in `dir`.
pub fn mvem(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mvem"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run mvem")
}

/// Run `mvem` with `args` in `dir`, killing it and failing the test if it has not ended after
/// `limit` seconds (a hang).
pub fn mvem_within(dir: &Path, args: &[&str], limit: f64) -> Output {
    use std::time::{Duration, Instant};
    let mut child = Command::new(env!("CARGO_BIN_EXE_mvem"))
        .args(args)
        .current_dir(dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run mvem");
    let start = Instant::now();
    loop {
        if child.try_wait().expect("wait for mvem").is_some() {
            return child.wait_with_output().expect("collect mvem's output");
        }
        if start.elapsed().as_secs_f64() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("mvem {args:?} did not end within {limit} s (a hang)");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Standard output as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The JSON document on standard output of a successful run (fails the test with stderr
/// otherwise).
pub fn json_of(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", stderr(o));
    serde_json::from_slice(&o.stdout).expect("one JSON document on stdout")
}

/// A file of the reference data `tests/reference/`.
pub fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference")
        .join(name)
}

/// A CSV file as header + rows of numbers (non-numeric cells as NaN).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let header = r.headers().unwrap().iter().map(str::to_string).collect();
    let rows = r
        .records()
        .map(|x| {
            x.unwrap()
                .iter()
                .map(|c| c.parse().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    (header, rows)
}

/// Index of column `name` (panics if absent).
pub fn col(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

/// Every file in `dir` (to check that nothing, not even a temporary file, was left behind).
pub fn files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Run `mvem` with `args` in `dir`, expect exit code 2 (usage or input error) and return stderr.
pub fn usage_error(dir: &Path, args: &[&str]) -> String {
    let o = mvem(dir, args);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    err
}

/// The published parameter set as `mvem params show` prints it (TOML).
pub fn published_toml(dir: &Path) -> String {
    let o = mvem(dir, &["params", "show"]);
    assert!(o.status.success(), "{}", stderr(&o));
    stdout(&o)
}

/// Write `dir/name`: the published parameter set with each `(from, to)` line replaced (each
/// `from` must occur).
pub fn write_published_with(dir: &Path, name: &str, edits: &[(&str, &str)]) {
    let mut text = published_toml(dir);
    for (from, to) in edits {
        assert!(text.contains(from), "{from} not in the published set");
        text = text.replace(from, to);
    }
    std::fs::write(dir.join(name), text).unwrap();
}
