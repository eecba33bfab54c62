//! Shared fixtures: reference data of `tests/reference/` (made by an independent
//! implementation of the authors' model, see its README).
#![allow(dead_code)]

use std::path::PathBuf;

/// Path of a file in the repository's `tests/reference/`.
pub fn reference(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/reference")
        .join(name)
}

/// A CSV table: header and rows of strings.
pub struct Table {
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    pub fn read(name: &str) -> Table {
        let mut r = csv::Reader::from_path(reference(name)).unwrap();
        let header = r.headers().unwrap().iter().map(str::to_string).collect();
        let rows = r
            .records()
            .map(|x| x.unwrap().iter().map(str::to_string).collect())
            .collect();
        Table { header, rows }
    }
    pub fn col(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    }
    pub fn f(&self, row: usize, name: &str) -> f64 {
        self.rows[row][self.col(name)].parse().unwrap()
    }
    pub fn column(&self, name: &str) -> Vec<f64> {
        (0..self.rows.len()).map(|r| self.f(r, name)).collect()
    }
}
