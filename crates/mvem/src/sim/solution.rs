//! The simulation result: named columns at the output times, and solver statistics.

use crate::model::Signals;

/// Solver statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected steps.
    pub rejected: usize,
    /// Model (right-hand side) evaluations, excluding output evaluations.
    pub rhs_evals: usize,
    /// Input breakpoints the integrator stopped at.
    pub breakpoints: usize,
    /// Jacobian evaluations (finite differences; Rosenbrock method only).
    pub jacobians: usize,
    /// LU factorizations of the iteration matrix (Rosenbrock method only).
    pub lu: usize,
    /// Output samples.
    pub outputs: usize,
}

/// Simulation result: named columns sampled at the output times.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Column names: `t`, the states, then the [`Signals::NAMES`] that are not state names
    /// (each name once; `T_im`, `T_em`, `p_c` are states of the 10/12-state models).
    pub names: Vec<String>,
    /// Column data, one vector per name.
    pub columns: Vec<Vec<f64>>,
    /// Solver statistics.
    pub stats: SimStats,
    /// Guards of the authors' implementation that were active at any output sample.
    pub guards_seen: u32,
    /// Column of each entry of [`Signals::NAMES`] (`None`: the signal is a state column).
    signal_columns: Vec<Option<usize>>,
}

impl Solution {
    /// An empty solution with the columns `t`, the states and the signals.
    pub fn new(state_names: &[&'static str]) -> Self {
        let mut names = vec!["t".to_string()];
        names.extend(state_names.iter().map(|s| s.to_string()));
        // A signal that is also a state (T_im, T_em, p_c of the 10/12-state models) appears
        // once, as the state.
        names.extend(
            Signals::NAMES
                .iter()
                .filter(|s| !state_names.contains(s))
                .map(|s| s.to_string()),
        );
        let mut c = state_names.len();
        let signal_columns = Signals::NAMES
            .iter()
            .map(|s| {
                (!state_names.contains(s)).then(|| {
                    c += 1;
                    c
                })
            })
            .collect();
        let columns = vec![Vec::new(); names.len()];
        Self {
            names,
            columns,
            stats: SimStats::default(),
            guards_seen: 0,
            signal_columns,
        }
    }

    /// Reserve room for `n` more samples in every column.
    pub(super) fn reserve(&mut self, n: usize) {
        for c in &mut self.columns {
            c.reserve(n);
        }
    }

    pub(super) fn push<const N: usize>(&mut self, t: f64, y: &[f64; N], s: &Signals) {
        self.columns[0].push(t);
        for i in 0..N {
            self.columns[1 + i].push(y[i]);
        }
        // signal columns follow the states in `Signals::NAMES` order, minus the state names
        for (col, v) in self.signal_columns.iter().zip(s.values()) {
            if let Some(c) = col {
                self.columns[*c].push(v);
            }
        }
        self.guards_seen |= s.guards;
    }

    /// Column by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    /// Output times.
    pub fn t(&self) -> &[f64] {
        &self.columns[0]
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.columns[0].len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.columns[0].is_empty()
    }

    /// Row `i` as (name, value) pairs.
    pub fn row(&self, i: usize) -> Vec<(&str, f64)> {
        self.names
            .iter()
            .zip(&self.columns)
            .map(|(n, c)| (n.as_str(), c[i]))
            .collect()
    }
}
