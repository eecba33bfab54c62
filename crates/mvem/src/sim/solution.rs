//! The simulation result: named columns at the output times, and solver statistics; or, for a
//! streaming solution, the same samples handed on in blocks while the simulation runs.

use crate::model::{Dynamics, ModelInput, Signals};
use std::sync::mpsc::SyncSender;

/// A block of consecutive output samples of a [`Solution::streaming`] simulation: one vector per
/// entry of [`Solution::names`], all of the same length.
pub type Block = Vec<Vec<f64>>;

/// Most rows a run may be asked to produce (output samples of a simulation, controller samples
/// of a closed loop): about 20 GB of CSV, certainly a mistaken output interval or time column.
/// The front ends and the closed loop refuse more before anything runs.
pub const MAX_ROWS: f64 = 5e7;

/// Solver statistics (of a time-parallel run, [`super::SimOptions::time_chunks`]: the work of
/// every chunk, warm-ups and discarded chunks included; `outputs` counts the solution's samples).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
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
    /// Time chunks integrated in parallel ([`super::SimOptions::time_chunks`]; 0: the
    /// sequential run).
    pub chunks: usize,
    /// Chunks whose junction check failed (or whose run failed), integrated again by the
    /// previous chunk's integrator.
    pub chunks_rerun: usize,
    /// Largest junction difference: max over the states of |y_prev - y_chunk| / (atol_i + rtol
    /// max(|y_prev|, |y_chunk|)) at a chunk's first time (0 without chunks; infinite when a
    /// chunk's run failed). [`super::Solution::junctions`] lists each.
    pub junction_max: f64,
}

impl SimStats {
    /// Add the work counters of `o` (steps, rejections, evaluations, stops, Jacobians, LU,
    /// samples) to these.
    pub(super) fn add_work(&mut self, o: &SimStats) {
        self.steps += o.steps;
        self.rejected += o.rejected;
        self.rhs_evals += o.rhs_evals;
        self.breakpoints += o.breakpoints;
        self.jacobians += o.jacobians;
        self.lu += o.lu;
        self.outputs += o.outputs;
    }
}

/// The junction of a time-parallel chunk with the previous one ([`super::SimOptions::time_chunks`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Junction {
    /// The chunk's first time \[s\] (a stop time where the inputs are continuous).
    pub t: f64,
    /// Max over the states of |y_prev - y_chunk| / (atol_i + rtol max(|y_prev|, |y_chunk|))
    /// (infinite: the chunk's run failed).
    pub diff: f64,
    /// Whether the chunk's samples were kept (`diff` <= [`super::JUNCTION_TOL`]); otherwise
    /// the previous chunk's integrator integrated the chunk again.
    pub accepted: bool,
}

/// Simulation result: named columns sampled at the output times.
///
/// A [`Solution::streaming`] solution keeps only the block of samples being filled and sends
/// every completed block to a receiver (a writer on another thread formats the output while the
/// integration goes on; memory stays bounded however long the run).
#[derive(Debug, Clone)]
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
    /// Junctions of a time-parallel run, in time order (empty: sequential).
    pub junctions: Vec<Junction>,
    /// Column of each entry of [`Signals::NAMES`] (`None`: the signal is a state column).
    signal_columns: Vec<Option<usize>>,
    /// Where completed blocks go (`None`: the columns keep every sample).
    stream: Option<Stream>,
    /// The samples hold what the signals are computed from, not the signals
    /// ([`Solution::streaming_deferred`]).
    raw: bool,
}

/// The receiving end of a streaming solution.
#[derive(Debug, Clone)]
struct Stream {
    tx: SyncSender<Block>,
    /// Samples per block.
    rows: usize,
    /// The receiver hung up (e.g. its writer failed): later samples are dropped.
    closed: bool,
}

/// Columns of a deferred block after `t` and the states: the [`ModelInput`] of each sample
/// (n_e, u_delta, u_egr, u_vgt at t, then u_egr and u_vgt delayed).
const INPUT_COLUMNS: usize = 6;

/// Two solutions are equal when their names, samples, statistics and guards are (where a
/// streaming solution sends its blocks, and the list of junctions, are not part of its value).
impl PartialEq for Solution {
    fn eq(&self, o: &Self) -> bool {
        self.names == o.names
            && self.columns == o.columns
            && self.stats == o.stats
            && self.guards_seen == o.guards_seen
    }
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
            junctions: Vec::new(),
            signal_columns,
            stream: None,
            raw: false,
        }
    }

    /// An empty solution with the columns of this one that keeps every sample (raw like this
    /// one if this one is [`Solution::streaming_deferred`]): a time-parallel chunk's buffer,
    /// appended to this one later ([`Solution::append`]).
    pub(super) fn kept_like(&self) -> Self {
        Self {
            names: self.names.clone(),
            columns: vec![Vec::new(); self.columns.len()],
            stats: SimStats::default(),
            guards_seen: 0,
            junctions: Vec::new(),
            signal_columns: self.signal_columns.clone(),
            stream: None,
            raw: self.raw,
        }
    }

    /// Append the samples of `other` (made by [`Solution::kept_like`] of this one), sending
    /// full blocks on if this solution is streaming.
    pub(super) fn append(&mut self, other: &Solution) {
        let rows = other.columns[0].len();
        let mut done = 0;
        while done < rows {
            let room = match &self.stream {
                Some(st) => st.rows.saturating_sub(self.columns[0].len()).max(1),
                None => rows,
            };
            let n = room.min(rows - done);
            for (c, o) in self.columns.iter_mut().zip(&other.columns) {
                c.extend_from_slice(&o[done..done + n]);
            }
            done += n;
            self.block_full();
        }
        self.guards_seen |= other.guards_seen;
    }

    /// An empty solution like [`Solution::new`] that sends every `rows` samples as one
    /// [`Block`] to `tx` and keeps only the block being filled. The simulation blocks while the
    /// channel is full (bounded memory); if the receiver hung up, later samples are dropped (the
    /// receiver's side reports its failure). [`Solution::finish_stream`] (called by
    /// [`super::simulate_into`] on success) sends the last, partial block and drops `tx`, so a
    /// receiver that reads until the channel closes ends when the simulation does.
    pub fn streaming(state_names: &[&'static str], rows: usize, tx: SyncSender<Block>) -> Self {
        let mut s = Self::new(state_names);
        let rows = rows.max(1);
        s.stream = Some(Stream {
            tx,
            rows,
            closed: false,
        });
        s.reserve(rows);
        s
    }

    /// A streaming solution like [`Solution::streaming`] whose blocks hold, per sample, only
    /// what the output signals are computed from: `t`, the state and the [`ModelInput`] (raw
    /// blocks of 1 + N + 6 columns). The receiver turns each block into the columns of
    /// [`Solution::names`] with a [`SignalEvaluator`] of the same model, bit for bit the block
    /// [`Solution::streaming`] would have sent: the model evaluations of the output samples
    /// move to the receiver's thread. A model whose evaluation depends on its memory
    /// ([`Dynamics::holds_memory`]) gets the plain [`Solution::streaming`] (the evaluator then
    /// passes its blocks through), so the simulation must use this `model`.
    pub fn streaming_deferred<const N: usize, M: Dynamics<N>>(
        model: &M,
        rows: usize,
        tx: SyncSender<Block>,
    ) -> Self {
        let mut s = Self::streaming(&model.state_names(), rows, tx);
        if !model.holds_memory() {
            let rows = rows.max(1);
            s.columns = vec![Vec::with_capacity(rows); 1 + N + INPUT_COLUMNS];
            s.raw = true;
        }
        s
    }

    /// An empty solution like [`Solution::new`] that keeps every sample but stores per sample
    /// only what the output signals are computed from (`t`, the state, the [`ModelInput`]), as
    /// [`Solution::streaming_deferred`] does: the integration then costs no model evaluation per
    /// output sample, as an integrator that stores the states at the output times (the CVODE
    /// peer's timed integration does). Until [`Solution::with_signals`] adds them, only `t` and
    /// the state columns can be read ([`Solution::get`] returns `None` for a signal). A model
    /// holding memory ([`Dynamics::holds_memory`]) gets [`Solution::new`] (its signals are
    /// evaluated while it integrates).
    pub fn deferred<const N: usize, M: Dynamics<N>>(model: &M) -> Self {
        let mut s = Self::new(&model.state_names());
        if !model.holds_memory() {
            s.columns = vec![Vec::new(); 1 + N + INPUT_COLUMNS];
            s.raw = true;
        }
        s
    }

    /// This solution with its signal columns: those of a [`Solution::deferred`] one are
    /// evaluated here, by the same function on the same state and inputs as the integrator of
    /// a [`Solution::new`] one would (the same bits); any other solution is returned as it is.
    /// `model` must be the one that was simulated.
    pub fn with_signals<const N: usize, M: Dynamics<N>>(mut self, model: &M) -> Self {
        if !self.raw || self.stream.is_some() {
            return self;
        }
        let mut ev = SignalEvaluator::new(model);
        let raw = std::mem::take(&mut self.columns);
        self.columns = ev.block(raw);
        self.guards_seen |= ev.guards_seen();
        self.raw = false;
        self
    }

    /// Number of columns that hold what their name says (a raw solution holds `t` and the
    /// states, then inputs that are no named column).
    fn named_columns(&self) -> usize {
        if self.raw {
            self.columns.len() - INPUT_COLUMNS
        } else {
            self.columns.len()
        }
    }

    /// Whether output samples are pushed without their signals
    /// ([`Solution::streaming_deferred`]).
    pub(super) fn defers_signals(&self) -> bool {
        self.raw
    }

    /// Whether the samples are sent on in blocks ([`Solution::streaming`]) rather than kept.
    pub fn is_streaming(&self) -> bool {
        self.stream.is_some()
    }

    /// Send the samples held (the last, partial block) and drop the sender: the solution keeps
    /// its names, statistics and guards, no samples, and is no longer streaming. No effect on a
    /// solution that is not streaming.
    pub fn finish_stream(&mut self) {
        if self.stream.is_none() {
            return;
        }
        self.send_block();
        if self.raw {
            self.columns = vec![Vec::new(); self.names.len()];
            self.raw = false;
        }
        self.stream = None;
    }

    /// Send the samples held as one block (streaming solutions with samples only).
    fn send_block(&mut self) {
        let Some(s) = &mut self.stream else {
            return;
        };
        if self.columns[0].is_empty() {
            return;
        }
        let fresh = || Vec::with_capacity(s.rows);
        let block: Block = self
            .columns
            .iter_mut()
            .map(|c| std::mem::replace(c, fresh()))
            .collect();
        if !s.closed && s.tx.send(block).is_err() {
            s.closed = true;
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
        self.block_full();
    }

    /// A sample of a [`Solution::streaming_deferred`] solution: `t`, the state and the inputs
    /// the signals are computed from.
    pub(super) fn push_deferred<const N: usize>(&mut self, t: f64, y: &[f64; N], u: &ModelInput) {
        self.columns[0].push(t);
        for i in 0..N {
            self.columns[1 + i].push(y[i]);
        }
        let inputs = u.to_array();
        for (k, v) in inputs.into_iter().enumerate() {
            self.columns[1 + N + k].push(v);
        }
        self.block_full();
    }

    /// Send the block if it is full (streaming solutions).
    fn block_full(&mut self) {
        if let Some(st) = &self.stream {
            if self.columns[0].len() >= st.rows {
                self.send_block();
            }
        }
    }

    /// Column by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .filter(|&i| i < self.named_columns())
            .map(|i| self.columns[i].as_slice())
    }

    /// Output times.
    pub fn t(&self) -> &[f64] {
        &self.columns[0]
    }

    /// Number of samples held (of a streaming solution: in the block being filled).
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
            .zip(&self.columns[..self.named_columns()])
            .map(|(n, c)| (n.as_str(), c[i]))
            .collect()
    }
}

/// The receiving end of a [`Solution::streaming_deferred`] simulation: evaluates the output
/// signals of each raw block, on the thread that calls [`SignalEvaluator::block`], and returns
/// the block [`Solution::streaming`] would have sent (the same function on the same state and
/// inputs: the same bits).
#[derive(Debug)]
pub struct SignalEvaluator<'m, const N: usize, M: Dynamics<N>> {
    model: &'m M,
    /// Fills the columns of [`Solution::names`] as the integrator would.
    out: Solution,
    deferred: bool,
}

impl<'m, const N: usize, M: Dynamics<N>> SignalEvaluator<'m, N, M> {
    /// The evaluator of `model`'s [`Solution::streaming_deferred`] blocks.
    pub fn new(model: &'m M) -> Self {
        Self {
            model,
            out: Solution::new(&model.state_names()),
            deferred: !model.holds_memory(),
        }
    }

    /// The block of [`Solution::names`] columns of the raw block `raw` (a block that is not
    /// raw, of a model holding memory, is returned as it is).
    pub fn block(&mut self, raw: Block) -> Block {
        if !self.deferred {
            return raw;
        }
        let rows = raw[0].len();
        self.out.reserve(rows);
        for i in 0..rows {
            let y: [f64; N] = std::array::from_fn(|k| raw[1 + k][i]);
            let u = ModelInput::from_array(std::array::from_fn(|k| raw[1 + N + k][i]));
            // the model's memory is not read when it holds none (`Dynamics::holds_memory`)
            let ev = self.model.eval(&y, &u, self.model.memory_start(&y, &u));
            self.out.push(raw[0][i], &y, &ev.signals);
        }
        self.out.columns.iter_mut().map(std::mem::take).collect()
    }

    /// Guards of the authors' implementation active at any sample evaluated so far (the
    /// [`Solution::guards_seen`] of a deferred simulation).
    pub fn guards_seen(&self) -> u32 {
        self.out.guards_seen
    }
}
