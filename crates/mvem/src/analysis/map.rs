//! Operating maps: steady states over a grid of inputs, and control properties (DC gain, RHP
//! zeros) of a channel over such a grid.
//!
//! A [`Grid`] varies one to four of the inputs (n_e, u_delta, u_egr, u_vgt) over given values
//! and holds the others at a base point. [`steady_map`] solves every grid point in parallel
//! (rayon) and warm-starts Newton from a converged neighbour:
//!
//! - level 1 solves the line along the first axis (other indices 0) sequentially, from the
//!   model's initial guess;
//! - level j solves, in parallel over the already solved points `(i_0, .., i_{j-2}, 0, ..)`,
//!   the lines along axis j-1, each point starting from its predecessor on the line.
//!
//! A warm start that fails, or lands on an unstable equilibrium, is retried by the full
//! [`steady_state_with`] procedure (model guess, settling simulations). Points without an
//! equilibrium are kept, with the solver's message ([`MapPoint::result`]); they are never
//! dropped. Points are stored row-major (the last axis varies fastest).
//!
//! The channel maps ([`channel_map`], [`dc_gain_map`], [`rhp_zero_map`]) linearize every
//! converged point. A point where a kink of the model lies on the channel is marked with the
//! reason (see [`crate::analysis::linearize`]); in particular the input saturations of the
//! authors' implementation (the parameter set's `input_saturation`, by default n_e in [500,
//! 2000] rpm, u_delta in [1, 250] mg, u_egr in [0, 100] %, u_vgt in [20, 100] %) make a channel
//! one-sided exactly at those limits, so grid edges on them give marked points: place the
//! edges just inside (e.g. u_vgt from 20.5 %).

use super::linearize::{linearize, LinearizeOptions};
use super::steady::{steady_state_with, SteadyOptions, SteadyState};
use super::zeros::{siso, Channel, ZeroOptions};
use crate::model::{Drive, InputError, Model};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// One axis of a grid: an input (`n_e`, `u_delta`, `u_egr`, `u_vgt`) and its values (user
/// units: rpm, mg/cycle/cylinder, %, %).
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// Input name ([`Drive::NAMES`]).
    pub input: String,
    /// Values.
    pub values: Vec<f64>,
}

impl Axis {
    /// An axis with the given values.
    pub fn new(input: &str, values: Vec<f64>) -> Self {
        Self {
            input: input.to_string(),
            values,
        }
    }

    /// `n` evenly spaced values from `lo` to `hi` inclusive (n >= 2; n = 1 gives `lo`).
    pub fn linspace(input: &str, lo: f64, hi: f64, n: usize) -> Self {
        let values = if n <= 1 {
            vec![lo]
        } else {
            (0..n)
                .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
                .collect()
        };
        Self::new(input, values)
    }
}

/// Why a map could not be set up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    /// The grid is malformed.
    #[error("bad grid: {0}")]
    Grid(String),
    /// The thread pool could not be built.
    #[error("thread pool: {0}")]
    Threads(String),
    /// A grid point the model cannot be evaluated at (n_e <= 0 with the paper's equations;
    /// checked for every point before any is solved).
    #[error("grid point {index:?}: {source}")]
    Input {
        /// Multi-index of the first such point.
        index: Vec<usize>,
        /// What is wrong.
        #[source]
        source: InputError,
    },
}

/// A grid over one to four inputs; the other inputs are held at `base`.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Values of the inputs that are not varied.
    pub base: Drive,
    /// Varied inputs (distinct), outermost first.
    pub axes: Vec<Axis>,
    /// Index into [`Drive::to_array`] of each axis.
    slots: Vec<usize>,
}

impl Grid {
    /// A grid; checks that there are 1-4 distinct known axes with finite values.
    pub fn new(base: Drive, axes: Vec<Axis>) -> Result<Self, MapError> {
        if axes.is_empty() || axes.len() > 4 {
            return Err(MapError::Grid(format!(
                "{} axes given, 1 to 4 needed",
                axes.len()
            )));
        }
        for (name, v) in Drive::NAMES.iter().zip(base.to_array()) {
            if !v.is_finite() {
                return Err(MapError::Grid(format!(
                    "base input {name} = {v} is not finite"
                )));
            }
        }
        let mut slots = Vec::new();
        for ax in &axes {
            let Some(s) = Drive::NAMES.iter().position(|n| *n == ax.input) else {
                return Err(MapError::Grid(format!(
                    "unknown input {:?} (known: {})",
                    ax.input,
                    Drive::NAMES.join(", ")
                )));
            };
            if slots.contains(&s) {
                return Err(MapError::Grid(format!("input {} appears twice", ax.input)));
            }
            if ax.values.is_empty() {
                return Err(MapError::Grid(format!("axis {} has no values", ax.input)));
            }
            if let Some(v) = ax.values.iter().find(|v| !v.is_finite()) {
                return Err(MapError::Grid(format!(
                    "axis {} has a non-finite value {v}",
                    ax.input
                )));
            }
            slots.push(s);
        }
        Ok(Self { base, axes, slots })
    }

    /// Two inputs varied, the others at `base`.
    pub fn two(base: Drive, first: Axis, second: Axis) -> Result<Self, MapError> {
        Self::new(base, vec![first, second])
    }

    /// All four inputs varied (axes in [`Drive::NAMES`] order: n_e, u_delta, u_egr, u_vgt).
    pub fn full(
        n_e: Vec<f64>,
        u_delta: Vec<f64>,
        u_egr: Vec<f64>,
        u_vgt: Vec<f64>,
    ) -> Result<Self, MapError> {
        let first = |v: &Vec<f64>| v.first().copied().unwrap_or(f64::NAN);
        let base = Drive::new(first(&n_e), first(&u_delta), first(&u_egr), first(&u_vgt));
        Self::new(
            base,
            vec![
                Axis::new("n_e", n_e),
                Axis::new("u_delta", u_delta),
                Axis::new("u_egr", u_egr),
                Axis::new("u_vgt", u_vgt),
            ],
        )
    }

    /// Number of values per axis.
    pub fn dims(&self) -> Vec<usize> {
        self.axes.iter().map(|a| a.values.len()).collect()
    }

    /// Number of grid points.
    pub fn len(&self) -> usize {
        self.dims().iter().product()
    }

    /// Whether the grid has no points (never, for a checked grid).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Multi-index (one per axis) of a row-major flat index.
    pub fn multi_index(&self, mut flat: usize) -> Vec<usize> {
        let dims = self.dims();
        let mut idx = vec![0; dims.len()];
        for k in (0..dims.len()).rev() {
            idx[k] = flat % dims[k];
            flat /= dims[k];
        }
        idx
    }

    /// Row-major flat index of a multi-index.
    pub fn flat_index(&self, idx: &[usize]) -> usize {
        let dims = self.dims();
        idx.iter().zip(&dims).fold(0, |acc, (i, d)| acc * d + i)
    }

    /// Inputs at a multi-index.
    pub fn drive_at(&self, idx: &[usize]) -> Drive {
        let mut a = self.base.to_array();
        for (k, &i) in idx.iter().enumerate() {
            a[self.slots[k]] = self.axes[k].values[i];
        }
        Drive::from_array(a)
    }
}

/// Options of [`steady_map`].
#[derive(Debug, Clone, PartialEq)]
pub struct MapOptions {
    /// Steady-state solver options (used for the cold start and the retries).
    pub steady: SteadyOptions,
    /// Warm-start Newton from a converged neighbour (default true).
    pub warm_start: bool,
    /// Worker threads (0 = rayon's global pool, default).
    pub threads: usize,
}

impl Default for MapOptions {
    fn default() -> Self {
        Self {
            steady: SteadyOptions::default(),
            warm_start: true,
            threads: 0,
        }
    }
}

/// One grid point of a steady-state map.
#[derive(Debug, Clone, PartialEq)]
pub struct MapPoint<const N: usize> {
    /// Multi-index (one per axis).
    pub index: Vec<usize>,
    /// Inputs.
    pub drive: Drive,
    /// The equilibrium (state, signals, flags, `physically_valid()`), or why none was found.
    pub result: Result<SteadyState<N>, String>,
    /// Whether the warm start from the neighbour was used (false: cold start or retry).
    pub warm: bool,
}

/// A steady-state map: every grid point, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadyMap<const N: usize> {
    /// The grid.
    pub grid: Grid,
    /// Points, row-major (last axis fastest).
    pub points: Vec<MapPoint<N>>,
}

impl<const N: usize> SteadyMap<N> {
    /// Number of points with an equilibrium.
    pub fn converged(&self) -> usize {
        self.points.iter().filter(|p| p.result.is_ok()).count()
    }

    /// Point at a multi-index.
    pub fn at(&self, idx: &[usize]) -> &MapPoint<N> {
        &self.points[self.grid.flat_index(idx)]
    }

    /// A signal (any [`crate::model::Signals::NAMES`] entry) or state over the map (NaN where
    /// there is no equilibrium or the name is unknown), row-major.
    pub fn values(&self, name: &str, state_names: &[&str]) -> Vec<f64> {
        let si = state_names.iter().position(|s| *s == name);
        self.points
            .iter()
            .map(|p| match &p.result {
                Ok(ss) => match si {
                    Some(i) => ss.x[i],
                    None => ss.signals.get(name).unwrap_or(f64::NAN),
                },
                Err(_) => f64::NAN,
            })
            .collect()
    }
}

/// Progress callback: `(points done, total)`.
pub type Progress<'a> = &'a (dyn Fn(usize, usize) + Sync);

fn run_in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> Result<T, MapError> {
    super::ensemble::in_pool(threads, f).map_err(|e| MapError::Threads(e.reason))
}

/// Solve one point: warm start from `guess` (Newton only), else the full procedure.
fn solve_point<const N: usize, M: Model<N>>(
    m: &M,
    d: &Drive,
    guess: Option<&[f64; N]>,
    opts: &MapOptions,
) -> (Result<SteadyState<N>, String>, bool) {
    if let (true, Some(g)) = (opts.warm_start, guess) {
        let quick = SteadyOptions {
            settle: false,
            ..opts.steady.clone()
        };
        if let Ok(ss) = steady_state_with(m, d, Some(g), &quick) {
            if ss.eigenvalues.iter().all(|e| e.0 < 0.0) {
                return (Ok(ss), true);
            }
        }
    }
    (
        steady_state_with(m, d, None, &opts.steady).map_err(|e| e.to_string()),
        false,
    )
}

/// Steady states over `grid` (see the module documentation). `progress` is called after each
/// point with (done, total).
pub fn steady_map<const N: usize, M: Model<N>>(
    m: &M,
    grid: &Grid,
    opts: &MapOptions,
    progress: Option<Progress<'_>>,
) -> Result<SteadyMap<N>, MapError> {
    let sem = m.options().semantics;
    for f in 0..grid.len() {
        let index = grid.multi_index(f);
        grid.drive_at(&index)
            .check(sem)
            .map_err(|source| MapError::Input { index, source })?;
    }
    let dims = grid.dims();
    let total = grid.len();
    let done = AtomicUsize::new(0);
    let tick = || {
        let k = done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(p) = progress {
            p(k, total);
        }
    };
    let mut slots: Vec<Option<MapPoint<N>>> = vec![None; total];
    run_in_pool(opts.threads, || {
        let k = dims.len();
        for level in 1..=k {
            let axis = level - 1;
            // starts: multi-indices with axes >= axis equal to 0 and axes < axis free
            let n_lines: usize = dims[..axis].iter().product();
            let lines: Vec<Vec<(usize, MapPoint<N>)>> = (0..n_lines)
                .into_par_iter()
                .map(|line| {
                    let mut idx = vec![0usize; k];
                    let mut rem = line;
                    for a in (0..axis).rev() {
                        idx[a] = rem % dims[a];
                        rem /= dims[a];
                    }
                    let first = if level == 1 { 0 } else { 1 };
                    let mut guess: Option<[f64; N]> = if level == 1 {
                        None
                    } else {
                        slots[grid.flat_index(&idx)]
                            .as_ref()
                            .and_then(|p| p.result.as_ref().ok().map(|s| s.x))
                    };
                    let mut out = Vec::with_capacity(dims[axis]);
                    for i in first..dims[axis] {
                        idx[axis] = i;
                        let d = grid.drive_at(&idx);
                        let (result, warm) = solve_point(m, &d, guess.as_ref(), opts);
                        if let Ok(ss) = &result {
                            guess = Some(ss.x);
                        }
                        out.push((
                            grid.flat_index(&idx),
                            MapPoint {
                                index: idx.clone(),
                                drive: d,
                                result,
                                warm,
                            },
                        ));
                        tick();
                    }
                    out
                })
                .collect();
            for line in lines {
                for (f, p) in line {
                    slots[f] = Some(p);
                }
            }
        }
    })?;
    let points = slots
        .into_iter()
        .map(|p| p.expect("every grid point is solved exactly once"))
        .collect();
    Ok(SteadyMap {
        grid: grid.clone(),
        points,
    })
}

/// Options of the channel maps.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ChannelMapOptions {
    /// Linearization options (the outputs are replaced by the channel's output; `strict` is
    /// ignored: kinks are judged per channel).
    pub linearize: LinearizeOptions,
    /// Zero computation options.
    pub zeros: ZeroOptions,
    /// Worker threads (0 = rayon's global pool).
    pub threads: usize,
}

/// The SISO channel `input -> output` (DC gain, transmission zeros, poles) at every point of a
/// steady-state map, in parallel. A point gives an error message when it has no equilibrium,
/// when a kink of the model lies on the channel there, or when the DC gain is infinite.
pub fn channel_map<const N: usize, M: Model<N>>(
    m: &M,
    map: &SteadyMap<N>,
    input: &str,
    output: &str,
    opts: &ChannelMapOptions,
    progress: Option<Progress<'_>>,
) -> Result<Vec<Result<Channel, String>>, MapError> {
    let total = map.points.len();
    let done = AtomicUsize::new(0);
    let mut lo = opts.linearize.clone();
    lo.outputs = vec![output.to_string()];
    lo.strict = false;
    run_in_pool(opts.threads, || {
        map.points
            .par_iter()
            .map(|p| {
                let r = match &p.result {
                    Err(e) => Err(format!("no equilibrium: {e}")),
                    Ok(ss) => linearize(m, &ss.x, &ss.drive, &lo)
                        .map_err(|e| e.to_string())
                        .and_then(|lin| {
                            siso(&lin, input, output, &opts.zeros).map_err(|e| e.to_string())
                        }),
                };
                let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                if let Some(cb) = progress {
                    cb(k, total);
                }
                r
            })
            .collect()
    })
}

/// DC gain of `input -> output` over a steady-state map (output units per input unit), e.g.
/// `("u_vgt", "W_c")` in kg/s per % for the sign-reversal map.
pub fn dc_gain_map<const N: usize, M: Model<N>>(
    m: &M,
    map: &SteadyMap<N>,
    input: &str,
    output: &str,
    opts: &ChannelMapOptions,
    progress: Option<Progress<'_>>,
) -> Result<Vec<Result<f64, String>>, MapError> {
    Ok(channel_map(m, map, input, output, opts, progress)?
        .into_iter()
        .map(|r| r.map(|c| c.dc_gain))
        .collect())
}

/// Whether `input -> output` has a right-half-plane transmission zero at each point of a
/// steady-state map, e.g. `("u_egr", "p_im")`.
pub fn rhp_zero_map<const N: usize, M: Model<N>>(
    m: &M,
    map: &SteadyMap<N>,
    input: &str,
    output: &str,
    opts: &ChannelMapOptions,
    progress: Option<Progress<'_>>,
) -> Result<Vec<Result<bool, String>>, MapError> {
    Ok(channel_map(m, map, input, output, opts, progress)?
        .into_iter()
        .map(|r| r.map(|c| c.zeros.has_rhp()))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_indices_round_trip_row_major() {
        let g = Grid::new(
            Drive::new(1500.0, 110.0, 50.0, 50.0),
            vec![
                Axis::linspace("u_vgt", 20.0, 100.0, 3),
                Axis::new("n_e", vec![1000.0, 2000.0]),
                Axis::linspace("u_egr", 0.0, 90.0, 4),
            ],
        )
        .unwrap();
        assert_eq!(g.dims(), vec![3, 2, 4]);
        assert_eq!(g.len(), 24);
        for f in 0..24 {
            assert_eq!(g.flat_index(&g.multi_index(f)), f);
        }
        assert_eq!(g.multi_index(1), vec![0, 0, 1]);
        let d = g.drive_at(&[2, 1, 3]);
        assert_eq!(d.to_array(), [2000.0, 110.0, 90.0, 100.0]);
        assert_eq!(Axis::linspace("n_e", 1.0, 2.0, 1).values, vec![1.0]);
        assert_eq!(Axis::linspace("n_e", 0.0, 1.0, 5).values[4], 1.0);
    }
}
