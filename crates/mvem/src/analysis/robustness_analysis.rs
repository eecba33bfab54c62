//! Robustness sweep of the analysis calls behind `mvem steady`, `mvem linearize` and
//! `mvem map`: random, seeded operating points over the whole input box, zero and negative
//! speeds included, under both semantics, each call run on a worker thread with a time limit.
//! A call may return a result or an error with a message; it must not hang (run past the time
//! limit), panic, or return a result holding NaN/inf.
//!
//! The calls, as the CLI makes them:
//! - **steady**: [`steady_state`] at the point; a result must have a finite state, finite
//!   signals and finite eigenvalues.
//! - **linearize**: the steady state, [`linearize_steady`] with `strict = false`, the poles and
//!   the zeros of every channel ([`zeros::poles`], [`zeros::all_channels`]); A, B, C, D, the
//!   poles and the zeros must be finite.
//! - **map**: a 3 x 3 [`steady_map`] over n_e (the point's speed to 1500 rpm) and u_vgt (the
//!   point's value to 60 %), warm starts on, one thread; every converged point must be finite.
//!
//! Run `k` of seed `s` is fully determined by `(s, k)` ([`Rng`]), as in the simulation sweep.

use super::linearize::{linearize_steady, LinearizeOptions};
use super::map::{steady_map, Axis, Grid, MapOptions};
use super::robustness::Rng;
use super::steady::{steady_state, SteadyState};
use super::zeros::{self, ZeroOptions};
use crate::components::Semantics;
use crate::model::{AnyModel, Drive, Model, ModelOptions, ModelOrder};
use crate::params::Params;
use std::collections::BTreeMap;
use std::fmt;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// Input box of the analysis sweep: (min, max) per channel (n_e \[rpm\], u_delta \[mg\], u_egr [%],
/// u_vgt [%]). Wider than the simulation sweep's: negative and zero speeds and fuel included.
pub const ANALYSIS_BOX: [(f64, f64); 4] = [
    (-500.0, 2500.0),
    (-50.0, 300.0),
    (-20.0, 120.0),
    (-20.0, 120.0),
];

/// Speeds drawn with probability 1/4 instead of the uniform draw: the edge cases of the box.
pub const SPECIAL_SPEEDS: [f64; 4] = [0.0, -100.0, 1e-9, 500.0];

/// An analysis call of the sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Call {
    /// `mvem steady`: equilibrium, flags, eigenvalues.
    Steady,
    /// `mvem linearize`: equilibrium, linear model, poles, zeros of every channel.
    Linearize,
    /// `mvem map`: a 3 x 3 steady-state map.
    Map,
}

impl Call {
    /// All three calls.
    pub const ALL: [Call; 3] = [Call::Steady, Call::Linearize, Call::Map];

    /// Lower-case name (the CLI command).
    pub fn name(self) -> &'static str {
        match self {
            Call::Steady => "steady",
            Call::Linearize => "linearize",
            Call::Map => "map",
        }
    }
}

/// What one call did.
#[derive(Debug, Clone, PartialEq)]
pub enum CallOutcome {
    /// A result, every number finite.
    Ok,
    /// An error with a message (the CLI prints it and exits 1 or 2).
    Error(String),
    /// A result holding NaN/inf (named).
    NonFinite(String),
    /// The call panicked (message).
    Panic(String),
    /// The call did not return within the time limit.
    Hang,
}

/// Configuration of an analysis sweep.
#[derive(Debug, Clone)]
pub struct AnalysisSweepConfig {
    /// Operating points per (model order, semantics); each gets all three calls.
    pub points: u64,
    /// Seed.
    pub seed: u64,
    /// Model orders.
    pub orders: Vec<ModelOrder>,
    /// Semantics (default both).
    pub semantics: Vec<Semantics>,
    /// Time limit per call.
    pub timeout: Duration,
    /// Worker threads.
    pub threads: usize,
}

impl Default for AnalysisSweepConfig {
    fn default() -> Self {
        Self {
            points: 100,
            seed: 1,
            orders: vec![ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve],
            semantics: vec![Semantics::Authors, Semantics::Paper],
            timeout: Duration::from_secs(10),
            threads: 2,
        }
    }
}

/// Counts of one (model states, semantics, call).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CallCounts {
    /// Calls made.
    pub calls: u64,
    /// Results, every number finite.
    pub ok: u64,
    /// Errors with a message.
    pub errors: u64,
    /// Results with NaN/inf.
    pub nonfinite: u64,
    /// Panics.
    pub panics: u64,
    /// Calls past the time limit.
    pub hangs: u64,
    /// Slowest call that returned \[s\].
    pub slowest: f64,
    /// Examples of bad outcomes: (point, outcome), at most 5.
    pub examples: Vec<(Drive, CallOutcome)>,
    /// Error messages by first 60 characters: (count, example point).
    pub error_kinds: BTreeMap<String, (u64, Drive)>,
}

/// Results of an analysis sweep by (model states, semantics, call).
#[derive(Debug, Clone, Default)]
pub struct AnalysisReport {
    /// Counts per (states, "authors"/"paper", call).
    pub counts: BTreeMap<(usize, &'static str, Call), CallCounts>,
    /// Time limit per call \[s\].
    pub timeout: f64,
    /// Wall-clock time \[s\].
    pub seconds: f64,
    /// Model orders that could not be built from the parameters.
    pub unavailable: Vec<usize>,
}

impl AnalysisReport {
    /// No hang, no panic, no NaN/inf in any result.
    pub fn clean(&self) -> bool {
        self.counts
            .values()
            .all(|c| c.hangs == 0 && c.panics == 0 && c.nonfinite == 0)
    }

    /// Totals over all entries: (calls, ok, errors, nonfinite, panics, hangs).
    pub fn totals(&self) -> [u64; 6] {
        self.counts.values().fold([0; 6], |mut t, c| {
            for (a, b) in
                t.iter_mut()
                    .zip([c.calls, c.ok, c.errors, c.nonfinite, c.panics, c.hangs])
            {
                *a += b;
            }
            t
        })
    }
}

fn semantics_name(s: Semantics) -> &'static str {
    if s.authors() {
        "authors"
    } else {
        "paper"
    }
}

/// Operating point `run` of a sweep with seed `seed` (see [`ANALYSIS_BOX`], [`SPECIAL_SPEEDS`]).
pub fn analysis_point(seed: u64, run: u64) -> Drive {
    let mut r = Rng::new(seed, run);
    let mut a: [f64; 4] = std::array::from_fn(|c| r.range(ANALYSIS_BOX[c].0, ANALYSIS_BOX[c].1));
    if r.unit() < 0.25 {
        a[0] = SPECIAL_SPEEDS[r.below(SPECIAL_SPEEDS.len())];
    }
    Drive::from_array(a)
}

fn nonfinite<'a>(what: &str, v: impl IntoIterator<Item = &'a f64>) -> Option<String> {
    v.into_iter()
        .find(|x| !x.is_finite())
        .map(|x| format!("{what} holds {x}"))
}

fn check_steady<const N: usize>(ss: &SteadyState<N>) -> Option<String> {
    let ev: Vec<f64> = ss.eigenvalues.iter().flat_map(|e| [e.0, e.1]).collect();
    nonfinite("state", &ss.x)
        .or_else(|| nonfinite("signals", &ss.signals.values()))
        .or_else(|| nonfinite("eigenvalues", &ev))
}

/// Make one call at `d` on the calling thread (no time limit; see [`run_call`]).
pub fn call_once<const N: usize, M: Model<N>>(m: &M, call: Call, d: &Drive) -> CallOutcome {
    let res: Result<Option<String>, String> = match call {
        Call::Steady => steady_state(m, d)
            .map(|ss| check_steady(&ss))
            .map_err(|e| e.to_string()),
        Call::Linearize => steady_state(m, d)
            .map_err(|e| e.to_string())
            .and_then(|ss| {
                let opts = LinearizeOptions {
                    strict: false,
                    ..LinearizeOptions::default()
                };
                let lin = linearize_steady(m, &ss, &opts).map_err(|e| e.to_string())?;
                let poles = zeros::poles(&lin).map_err(|e| format!("poles: {e}"))?;
                let pz: Vec<f64> = poles.iter().flat_map(|z| [z.re, z.im]).collect();
                let mut zs = Vec::new();
                for ch in zeros::all_channels(&lin, &ZeroOptions::default())
                    .into_iter()
                    .flatten()
                {
                    zs.extend(ch.zeros.finite.iter().flat_map(|z| [z.re, z.im]));
                    zs.push(ch.dc_gain);
                }
                Ok(nonfinite("A", lin.a.iter())
                    .or_else(|| nonfinite("B", lin.b.iter()))
                    .or_else(|| nonfinite("C", lin.c.iter()))
                    .or_else(|| nonfinite("D", lin.d.iter()))
                    .or_else(|| nonfinite("poles", &pz))
                    .or_else(|| nonfinite("zeros or DC gains", &zs)))
            }),
        Call::Map => {
            let grid = Grid::two(
                *d,
                Axis::linspace("n_e", d.n_e_rpm, 1500.0, 3),
                Axis::linspace("u_vgt", d.u_vgt_pct, 60.0, 3),
            );
            match grid {
                Err(e) => Err(e.to_string()),
                Ok(g) => {
                    let opts = MapOptions {
                        threads: 1,
                        ..MapOptions::default()
                    };
                    steady_map(m, &g, &opts, None)
                        .map(|map| {
                            map.points
                                .iter()
                                .filter_map(|p| p.result.as_ref().ok())
                                .find_map(check_steady)
                        })
                        .map_err(|e| e.to_string())
                }
            }
        }
    };
    match res {
        Ok(None) => CallOutcome::Ok,
        Ok(Some(what)) => CallOutcome::NonFinite(what),
        Err(msg) => CallOutcome::Error(msg),
    }
}

/// Make one call at `d` on a worker thread, waiting at most `timeout`: a call that does not
/// return in time is reported as [`CallOutcome::Hang`] (its thread is left running, detached),
/// a panic as [`CallOutcome::Panic`]. Returns the outcome and the elapsed time \[s\].
pub fn run_call(model: &AnyModel, call: Call, d: Drive, timeout: Duration) -> (CallOutcome, f64) {
    let (tx, rx) = mpsc::channel();
    let m = model.clone();
    let start = Instant::now();
    let spawned = std::thread::Builder::new()
        .name(format!("mvem-{}", call.name()))
        .spawn(move || {
            let r = catch_unwind(AssertUnwindSafe(
                || crate::dispatch!(&m, mm => call_once(mm, call, &d)),
            ));
            let o = r.unwrap_or_else(|payload| {
                CallOutcome::Panic(
                    payload
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| payload.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "non-string panic payload".into()),
                )
            });
            let _ = tx.send(o);
        });
    if let Err(e) = spawned {
        return (
            CallOutcome::Error(format!("cannot start a thread: {e}")),
            0.0,
        );
    }
    let o = match rx.recv_timeout(timeout) {
        Ok(o) => o,
        Err(mpsc::RecvTimeoutError::Timeout) => CallOutcome::Hang,
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            CallOutcome::Panic("worker thread ended without a result".into())
        }
    };
    (o, start.elapsed().as_secs_f64())
}

/// Run the sweep: for every model order and semantics, `cfg.points` operating points, each
/// with the three calls, on `cfg.threads` threads.
pub fn analysis_sweep(params: &Params, cfg: &AnalysisSweepConfig) -> AnalysisReport {
    use rayon::prelude::*;
    let start = Instant::now();
    let mut report = AnalysisReport {
        timeout: cfg.timeout.as_secs_f64(),
        ..Default::default()
    };
    let mut models = Vec::new();
    for &order in &cfg.orders {
        for &sem in &cfg.semantics {
            let opts = ModelOptions {
                semantics: sem,
                ..ModelOptions::default()
            };
            match AnyModel::new(order, params.clone(), opts) {
                Ok(m) => models.push((order.states(), semantics_name(sem), m)),
                Err(_) => {
                    if !report.unavailable.contains(&order.states()) {
                        report.unavailable.push(order.states());
                    }
                }
            }
        }
    }
    let jobs: Vec<(usize, u64, Call)> = (0..models.len())
        .flat_map(|mi| (0..cfg.points).flat_map(move |k| Call::ALL.map(|c| (mi, k, c))))
        .collect();
    let pool = match rayon::ThreadPoolBuilder::new()
        .num_threads(cfg.threads.max(1))
        .build()
    {
        Ok(p) => p,
        Err(_) => rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("a one-thread pool"),
    };
    let outcomes: Vec<(usize, Drive, Call, CallOutcome, f64)> = pool.install(|| {
        jobs.par_iter()
            .map(|&(mi, k, call)| {
                let d = analysis_point(cfg.seed, k);
                let (o, secs) = run_call(&models[mi].2, call, d, cfg.timeout);
                (mi, d, call, o, secs)
            })
            .collect()
    });
    for (mi, d, call, o, secs) in outcomes {
        let (n, sem, _) = &models[mi];
        let c = report.counts.entry((*n, sem, call)).or_default();
        c.calls += 1;
        if o != CallOutcome::Hang {
            c.slowest = c.slowest.max(secs);
        }
        let bad = match &o {
            CallOutcome::Ok => {
                c.ok += 1;
                false
            }
            CallOutcome::Error(msg) => {
                c.errors += 1;
                let key: String = msg.chars().take(60).collect();
                c.error_kinds.entry(key).or_insert((0, d)).0 += 1;
                msg.trim().is_empty()
            }
            CallOutcome::NonFinite(_) => {
                c.nonfinite += 1;
                true
            }
            CallOutcome::Panic(_) => {
                c.panics += 1;
                true
            }
            CallOutcome::Hang => {
                c.hangs += 1;
                true
            }
        };
        if bad && c.examples.len() < 5 {
            c.examples.push((d, o));
        }
    }
    report.seconds = start.elapsed().as_secs_f64();
    report
}

impl fmt::Display for AnalysisReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [calls, ok, errors, nonfinite, panics, hangs] = self.totals();
        writeln!(
            f,
            "analysis sweep (steady, linearize, map): {calls} calls in {:.1} s, time limit {} s per call",
            self.seconds, self.timeout
        )?;
        writeln!(
            f,
            "totals: {ok} results, {errors} errors with a message, {nonfinite} NaN/inf, {panics} panics, {hangs} hangs"
        )?;
        for n in &self.unavailable {
            writeln!(f, "  ({n}-state model not available: skipped)")?;
        }
        writeln!(
            f,
            "{:<8} {:<8} {:<10} {:>6} {:>6} {:>6} {:>7} {:>6} {:>6} {:>9}",
            "states",
            "sem.",
            "call",
            "calls",
            "ok",
            "errors",
            "NaN/inf",
            "panic",
            "hang",
            "slowest"
        )?;
        for ((n, sem, call), c) in &self.counts {
            writeln!(
                f,
                "{n:<8} {sem:<8} {:<10} {:>6} {:>6} {:>6} {:>7} {:>6} {:>6} {:>8.3}s",
                call.name(),
                c.calls,
                c.ok,
                c.errors,
                c.nonfinite,
                c.panics,
                c.hangs,
                c.slowest
            )?;
        }
        for ((n, sem, call), c) in &self.counts {
            for (d, o) in &c.examples {
                writeln!(
                    f,
                    "  {n} states, {sem}, {} at n_e={} u_delta={} u_egr={} u_vgt={}: {o:?}",
                    call.name(),
                    d.n_e_rpm,
                    d.u_delta_mg,
                    d.u_egr_pct,
                    d.u_vgt_pct
                )?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_replay_and_cover_the_special_speeds() {
        assert_eq!(analysis_point(3, 17), analysis_point(3, 17));
        let pts: Vec<Drive> = (0..400).map(|k| analysis_point(1, k)).collect();
        for s in SPECIAL_SPEEDS {
            assert!(pts.iter().any(|d| d.n_e_rpm == s), "{s}");
        }
        assert!(pts.iter().any(|d| d.n_e_rpm < 0.0 && d.n_e_rpm != -100.0));
    }

    #[test]
    fn a_call_past_its_time_limit_is_a_hang() {
        // the 12-state map at a cold start takes far more than a microsecond
        let m = AnyModel::new(
            ModelOrder::Twelve,
            Params::published(),
            ModelOptions::default(),
        )
        .unwrap();
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let (o, _) = run_call(&m, Call::Map, d, Duration::from_micros(1));
        assert_eq!(o, CallOutcome::Hang);
        let (o, _) = run_call(&m, Call::Steady, d, Duration::from_secs(30));
        assert_eq!(o, CallOutcome::Ok);
    }
}
