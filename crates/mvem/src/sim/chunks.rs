//! Time-parallel integration of one open-loop simulation ([`SimOptions::time_chunks`]).
//!
//! An open-loop run of a model that holds no memory is a function of its state at any time and
//! the inputs after it, and the engine models forget their state within seconds (the slowest
//! mode is the turbo shaft; the actuator states are closed-form lags). So the time axis is cut
//! into chunks integrated at the same time:
//!
//! 1. [`split_times`]: K - 1 stop times where the inputs are continuous (kinks, never jumps),
//!    chosen so that every chunk, its warm-up included, holds about the same estimated work (a
//!    third each of time, the inputs' total variation and the stop count);
//! 2. chunk 0 is the sequential run from the start up to the first split, on the calling
//!    thread, writing its samples to the solution (streamed on if it streams); chunk k > 0
//!    starts [`SimOptions::chunk_overlap`] before its split from a guess (the caller's, e.g. the
//!    steady state at the inputs there, else the initial state), integrates the warm-up without
//!    output, then its own interval into a buffer, on a thread of its own;
//! 3. in time order, the state the previous chunk reached at the split is compared with the
//!    chunk's state there in the integrator's scaled max norm; at most [`JUNCTION_TOL`] and
//!    the chunk's samples are appended, otherwise (or when the chunk's run failed) the previous
//!    chunk's integrator goes on over the chunk's interval: the sequential run from there, so
//!    the result is correct whatever the guess, and a failure is reported with the time and
//!    state of the run that met it.

use super::input::InputSchedule;
use super::integrator::Integrator;
use super::options::SimOptions;
use super::segment::{stop_margin, stop_times_except, SegmentInputs};
use super::solution::{Junction, SimStats, Solution};
use super::SimError;
use crate::model::Dynamics;

/// A guess of the state at a time (a time-parallel chunk's start; `None`: the simulation's
/// initial state is taken).
pub type ChunkGuess<'g, const N: usize> = dyn Fn(f64) -> Option<[f64; N]> + Sync + 'g;

/// Largest junction difference (max over the states of |dy_i| / (atol_i + rtol |y_i|)) at which
/// a chunk's samples are kept. One tolerance unit is what every accepted step may add to the
/// error; at 0.1 the junction adds a tenth of one step's allowance to the chunk's start, which
/// the contracting dynamics then damp (on the WHTC the sequential run's own deviation from a
/// tight reference is about 15 such units; `docs/integrator.md`).
pub const JUNCTION_TOL: f64 = 0.1;

/// Estimated work of integrating up to `t`, as a fraction of the work up to `t_end`: a third
/// each of the time elapsed since `t0`, the inputs' total variation since `t0` (each channel's
/// changes divided by its range) and the number of stop times passed. The steps follow the
/// transients the inputs start and their size (over the WHTC's 10 s intervals the RHS
/// evaluations correlate 0.92 with the variation), every stop costs at least one step (0.75
/// with the stop count), and a quiet stretch still takes steps. Measured on three 1800 s cycles
/// (the WHTC, the WHTC with u_delta linear between whole seconds, the closed loop's commands at
/// 10 Hz), a cut at half the estimated work leaves 50.1, 50.6 and 51.6 % of the evaluations
/// before it (with time and variation only: 47.2, 47.4, 50.1 %; `docs/integrator.md`, session
/// 26).
struct WorkEstimate<'s> {
    t0: f64,
    span: f64,
    /// Row times and the normalized total variation up to each.
    times: Vec<f64>,
    tv: Vec<f64>,
    /// The stop times in `(t0, t_end)`, sorted.
    stops: &'s [(f64, bool)],
    /// Whether the inputs vary in `[t0, t_end]` (else the variation term is left out).
    varies: bool,
}

impl<'s> WorkEstimate<'s> {
    fn new(sched: &InputSchedule, stops: &'s [(f64, bool)], t0: f64, t_end: f64) -> Self {
        let (times, rows) = (sched.times(), sched.rows());
        let mut range = [0.0f64; 4];
        for (c, r) in range.iter_mut().enumerate() {
            let (lo, hi) = rows
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                    (a.min(x[c]), b.max(x[c]))
                });
            *r = hi - lo;
        }
        let mut tv = Vec::with_capacity(times.len());
        let mut acc = 0.0;
        for i in 0..rows.len() {
            if i > 0 {
                for c in 0..4 {
                    if range[c] > 0.0 {
                        acc += (rows[i][c] - rows[i - 1][c]).abs() / range[c];
                    }
                }
            }
            tv.push(acc);
        }
        let lo = stops.partition_point(|s| s.0 <= t0);
        let hi = stops.partition_point(|s| s.0 < t_end);
        let mut me = Self {
            t0,
            span: t_end - t0,
            times: times.to_vec(),
            tv,
            stops: &stops[lo..hi.max(lo)],
            varies: false,
        };
        // normalized to the variation in [t0, t_end]
        let (a, b) = (me.variation(t0), me.variation(t_end));
        let total = b - a;
        for v in &mut me.tv {
            *v = if total > 0.0 { (*v - a) / total } else { 0.0 };
        }
        me.varies = total > 0.0;
        me
    }

    /// The total variation up to `t` (linear inside a row interval).
    fn variation(&self, t: f64) -> f64 {
        let ts = &self.times;
        let i = ts.partition_point(|x| *x <= t);
        if i == 0 {
            return self.tv.first().copied().unwrap_or(0.0);
        }
        if i == ts.len() {
            return self.tv[i - 1];
        }
        let (ta, tb) = (ts[i - 1], ts[i]);
        self.tv[i - 1] + (self.tv[i] - self.tv[i - 1]) * (t - ta) / (tb - ta)
    }

    /// The fraction of the stops passed at `t`: linear from 0 at `t0` through the stops (the
    /// k-th of n at k / n), 1 from the last stop on.
    fn stops_passed(&self, t: f64) -> f64 {
        let n = self.stops.len();
        let k = self.stops.partition_point(|s| s.0 <= t);
        if k == n {
            return 1.0;
        }
        let ta = if k == 0 { self.t0 } else { self.stops[k - 1].0 };
        let tb = self.stops[k].0;
        let frac = if tb > ta {
            ((t - ta) / (tb - ta)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (k as f64 + frac) / n as f64
    }

    /// The estimated work up to `t` (0 at `t0`, 1 at `t_end`; increasing): the mean of the
    /// terms that are defined (the variation's when the inputs vary in `[t0, t_end]`, the stops'
    /// when there is one).
    fn at(&self, t: f64) -> f64 {
        let mut sum = (t - self.t0) / self.span;
        let mut terms = 1.0;
        if self.varies {
            sum += self.variation(t);
            terms += 1.0;
        }
        if !self.stops.is_empty() {
            sum += self.stops_passed(t);
            terms += 1.0;
        }
        sum / terms
    }

    /// The time by which the work `w` is done (bisection).
    fn time_of(&self, w: f64) -> f64 {
        let (mut lo, mut hi) = (self.t0, self.t0 + self.span);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.at(mid) < w {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }
}

/// The stop times (of `stops`, sorted, between `t0` and `t_end`) at which `[t0, t_end]` is cut
/// into at most `chunks` chunks of about equal estimated work (`WorkEstimate`): chunk 0 from
/// `t0`, chunk k > 0 from its split plus its warm-up (`overlap` before the split). Every split
/// is a stop without a jump (`(t, false)`) after densely spaced stops (`kink_from`), lies more
/// than `overlap` after `t0`, and every chunk holds at least as much work of its own as its
/// warm-up does. At most one chunk per `overlap` seconds. Fewer chunks when that is not
/// possible; empty: the sequential run.
pub fn split_times(
    stops: &[(f64, bool)],
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    chunks: usize,
    overlap: f64,
) -> Vec<f64> {
    let n = stops.len();
    if n < 16 || chunks < 2 || t_end.partial_cmp(&t0) != Some(std::cmp::Ordering::Greater) {
        return Vec::new();
    }
    let w = WorkEstimate::new(sched, stops, t0, t_end);
    // the splits for a target work per chunk (None: they do not fit before t_end)
    let place = |k: usize, target: f64| -> Option<Vec<f64>> {
        let mut v = Vec::with_capacity(k - 1);
        let mut from = 0.0;
        for _ in 1..k {
            let want = from + target;
            if want >= 1.0 {
                return None;
            }
            let t = w.time_of(want);
            v.push(t);
            from = w.at((t - overlap).max(t0));
        }
        Some(v)
    };
    let warm = |t: f64| w.at(t) - w.at((t - overlap).max(t0));
    // the calm of the stops, each computed once when a split candidate first needs it
    // (kink_from ranks the candidates by it; NaN: not computed yet)
    let mut calm = vec![f64::NAN; n];
    // a chunk shorter than its warm-up would spend more on the warm-up than on its own
    // interval: at most one chunk per `overlap` seconds (this also bounds the search below,
    // whose cost grows with the square of the chunk count)
    let by_time = ((t_end - t0) / overlap).floor().max(1.0) as usize;
    for k in (2..=chunks.min(n / 8).min(by_time)).rev() {
        // the last chunk's work decreases as the target grows: bisection for equal work
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            match place(k, mid) {
                Some(v) if 1.0 - w.at((v[k - 2] - overlap).max(t0)) > mid => lo = mid,
                _ => hi = mid,
            }
        }
        let Some(cont) = place(k, lo) else {
            continue;
        };
        // snapped to stops where a junction can be checked
        let mut splits: Vec<f64> = Vec::with_capacity(k - 1);
        for t in cont {
            let Some(ts) = kink_from(stops, &mut calm, stops.partition_point(|s| s.0 < t)) else {
                break;
            };
            if splits.last().is_some_and(|&p| ts <= p) || ts - overlap <= t0 {
                break;
            }
            splits.push(ts);
        }
        if splits.len() + 1 < k {
            continue;
        }
        // each chunk's own work at least its warm-up's
        let ends: Vec<f64> = splits.iter().copied().chain([t_end]).collect();
        if (0..k - 1).all(|j| w.at(ends[j + 1]) - w.at(splits[j]) >= warm(splits[j])) {
            return splits;
        }
    }
    Vec::new()
}

/// Stops on either side of the balanced index among which a split is chosen
/// ([`kink_from`]).
const SPLIT_WINDOW: usize = 128;

/// Time before a split candidate whose largest gap between stops ranks it \[s\]
/// ([`kink_from`]).
const SPLIT_CALM: f64 = 10.0;

/// A stop without a jump near index `i` (never the first or the last stop): of those within
/// [`SPLIT_WINDOW`] stops, the one whose preceding [`SPLIT_CALM`] seconds have the shortest
/// largest gap between stops. Where the inputs change at every row, two runs whose states agree
/// also take the same steps, since every segment's steps end at its stop; in a quiet stretch the
/// step sizes grow without such a bound, differently in two runs that started differently, and
/// at the next kink their states differ by up to a few tolerance units for a few seconds
/// (measured on the WHTC, `docs/integrator.md`): no place for a junction.
fn kink_from(stops: &[(f64, bool)], calm: &mut [f64], i: usize) -> Option<f64> {
    let lo = i.saturating_sub(SPLIT_WINDOW).max(1);
    let hi = (i + SPLIT_WINDOW).min(stops.len().saturating_sub(1));
    for j in lo..hi {
        if calm[j].is_nan() {
            calm[j] = calm_gap(stops, j);
        }
    }
    (lo..hi)
        .filter(|&j| !stops[j].1)
        // the gap to 0.1 s, the row spacing of a 10 Hz cycle (equal gaps: the candidate
        // nearest the balanced index)
        .min_by_key(|&j| ((calm[j] * 10.0).ceil() as i64, j.abs_diff(i)))
        .map(|j| stops[j].0)
}

/// For stop `j` (from 1), the largest gap between consecutive stops in the [`SPLIT_CALM`]
/// seconds before it (from the last stop before that window); 0 for stop 0.
fn calm_gap(stops: &[(f64, bool)], j: usize) -> f64 {
    if j == 0 {
        return 0.0;
    }
    let from = stops[..j].partition_point(|s| s.0 < stops[j].0 - SPLIT_CALM);
    stops[from.max(1) - 1..=j]
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .fold(0.0, f64::max)
}

/// Index of the first output sample at or after the split `tk` (within the rounding the
/// integrator allows: a sample within [`SegmentInputs::delta`] before `tk` belongs to the
/// segment after it, as in the sequential run).
fn first_sample(t0: f64, dt: f64, tk: f64) -> u64 {
    let at = |i: u64| t0 + i as f64 * dt;
    let lo = tk - SegmentInputs::delta(tk);
    let mut i = ((tk - t0) / dt).floor().max(0.0) as u64;
    while i > 0 && at(i - 1) >= lo {
        i -= 1;
    }
    while at(i) < lo {
        i += 1;
    }
    i
}

/// The scaled difference of two states (max over the states of |a_i - b_i| / (atol_i + rtol
/// max(|a_i|, |b_i|)), with `atol` per state).
fn junction_diff<const N: usize>(a: &[f64; N], b: &[f64; N], atol: &[f64; N], rtol: f64) -> f64 {
    (0..N)
        .map(|i| (a[i] - b[i]).abs() / (atol[i] + rtol * a[i].abs().max(b[i].abs())))
        .fold(
            0.0,
            |m: f64, d| if d.is_nan() { f64::INFINITY } else { m.max(d) },
        )
}

/// The part of `stops` (the stop times of the whole run) strictly inside `(a, b)`, with the
/// margins of [`stop_times_except`] (what it would list from `a` to `b`).
fn within(stops: &[(f64, bool)], a: f64, b: f64) -> &[(f64, bool)] {
    let lo = stops.partition_point(|s| s.0 <= a + stop_margin(a));
    let hi = stops.partition_point(|s| s.0 < b - stop_margin(b));
    &stops[lo..hi.max(lo)]
}

/// A chunk k > 0 after its run on its thread.
struct Chunk<'a, const N: usize, M: Dynamics<N>> {
    /// The integrator at the chunk's end (`None`: the run failed).
    run: Option<Integrator<'a, N, M>>,
    /// The state at the chunk's first time, after the warm-up.
    y_start: Option<[f64; N]>,
    /// The chunk's samples.
    out: Solution,
    /// The work done (also of a failed run).
    stats: SimStats,
}

/// Chunk `k > 0` on `[tk, t_end]` (the last if `last`), from `guess` (else `y0`) at `tk -
/// overlap`: the warm-up writes no sample (the output index starts at `tk`'s).
#[allow(clippy::too_many_arguments)]
fn run_chunk<'a, const N: usize, M: Dynamics<N>>(
    model: &'a M,
    sched: &'a InputSchedule,
    t0: f64,
    tk: f64,
    t_end: f64,
    last: bool,
    y0: [f64; N],
    opts: &SimOptions,
    guess: Option<&ChunkGuess<N>>,
    stops: &[(f64, bool)],
    mut out: Solution,
) -> Chunk<'a, N, M> {
    let ts = (tk - opts.chunk_overlap).max(t0);
    let y = guess.and_then(|g| g(ts)).unwrap_or(y0);
    let mut run = match Integrator::new(model, sched, ts, y, opts) {
        Ok(r) => r,
        Err(_) => {
            return Chunk {
                run: None,
                y_start: None,
                out,
                stats: SimStats::default(),
            }
        }
    };
    run.t_out0 = t0;
    run.next_out = first_sample(t0, opts.dt_out, tk);
    out.reserve(((t_end - tk) / opts.dt_out).ceil().min(1e7) as usize + 2);
    if run
        .advance_stops(tk, &mut out, false, within(stops, ts, tk))
        .is_err()
    {
        return Chunk {
            run: None,
            y_start: None,
            out,
            stats: run.stats,
        };
    }
    debug_assert!(out.is_empty(), "a warm-up wrote samples");
    let y_start = run.y;
    let ok = run
        .advance_stops(t_end, &mut out, last, within(stops, tk, t_end))
        .is_ok();
    Chunk {
        stats: run.stats,
        run: ok.then_some(run),
        y_start: Some(y_start),
        out,
    }
}

/// [`super::simulate_into`] in time-parallel chunks (see the module): `opts.time_chunks > 1`
/// and a model without memory; otherwise, or with too few stop times to split, the sequential
/// run.
#[allow(clippy::too_many_arguments)]
pub(super) fn simulate_chunked<const N: usize, M: Dynamics<N>>(
    model: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    y0: [f64; N],
    opts: &SimOptions,
    mut sol: Solution,
    guess: Option<&ChunkGuess<N>>,
) -> Result<Solution, SimError> {
    let mut first = Integrator::new(model, sched, t0, y0, opts)?;
    let stops = if opts.time_chunks > 1 && !model.holds_memory() && opts.stop_at_breakpoints {
        stop_times_except(model, sched, t0, t_end, first.skip_lag_stops())
    } else {
        Vec::new()
    };
    let splits = split_times(
        &stops,
        sched,
        t0,
        t_end,
        opts.time_chunks,
        opts.chunk_overlap,
    );
    if splits.is_empty() {
        // (the interval [t0, t_end] was checked by the caller, `simulate_into_with_guess`)
        first.advance_checked(t_end, &mut sol, true)?;
        sol.stats = first.stats;
        sol.finish_stream();
        return Ok(sol);
    }
    let k_all = splits.len() + 1;
    // chunk k covers [starts[k], ends[k]]
    let starts: Vec<f64> = std::iter::once(t0).chain(splits.iter().copied()).collect();
    let ends: Vec<f64> = splits
        .iter()
        .copied()
        .chain(std::iter::once(t_end))
        .collect();
    let y_first = first.y;
    // the chunks' threads poll the caller's cancellation token, as the first chunk does
    let cancel = crate::numerics::cancel::current();
    std::thread::scope(|s| {
        let handles: Vec<_> = (1..k_all)
            .map(|k| {
                let out = sol.kept_like();
                let (tk, te) = (starts[k], ends[k]);
                let last = k + 1 == k_all;
                let stops = &stops;
                let cancel = cancel.as_ref();
                s.spawn(move || {
                    let run = || {
                        run_chunk(
                            model, sched, t0, tk, te, last, y_first, opts, guess, stops, out,
                        )
                    };
                    crate::numerics::cancel::with_token_if(cancel, run)
                })
            })
            .collect();
        let mut total = SimStats::default();
        let mut junctions = Vec::with_capacity(k_all - 1);
        // chunk 0: the sequential run up to the first split (a failure is final)
        first.advance_stops(ends[0], &mut sol, false, within(&stops, t0, ends[0]))?;
        let mut prev = first;
        for (k, h) in (1..k_all).zip(handles) {
            let chunk = match h.join() {
                Ok(c) => c,
                Err(panic) => std::panic::resume_unwind(panic),
            };
            let last = k + 1 == k_all;
            // the previous chunk stopped where this one's samples start
            debug_assert_eq!(prev.next_out, first_sample(t0, opts.dt_out, starts[k]));
            let diff = match (&chunk.run, chunk.y_start) {
                (Some(_), Some(ys)) => junction_diff(&prev.y, &ys, &prev.atol, opts.rtol),
                _ => f64::INFINITY,
            };
            let accepted = diff <= JUNCTION_TOL;
            junctions.push(Junction {
                t: starts[k],
                diff,
                accepted,
            });
            match chunk.run {
                Some(run) if accepted => {
                    // the previous integrator retires; this one's work is counted when it does
                    total.add_work(&prev.stats);
                    sol.append(&chunk.out);
                    prev = run;
                }
                _ => {
                    // a discarded chunk's work counts, its samples are not the solution's
                    total.add_work(&chunk.stats);
                    total.outputs -= chunk.stats.outputs;
                    total.chunks_rerun += 1;
                    let part = within(&stops, starts[k], ends[k]);
                    prev.advance_stops(ends[k], &mut sol, last, part)?;
                }
            }
        }
        total.add_work(&prev.stats);
        total.chunks = k_all;
        total.junction_max = junctions.iter().map(|j| j.diff).fold(0.0, f64::max);
        sol.stats = total;
        sol.junctions = junctions;
        sol.finish_stream();
        Ok(sol)
    })
}

#[cfg(test)]
mod tests {
    use super::{first_sample, junction_diff, split_times};
    use crate::sim::InputSchedule;

    /// A 200 s schedule with a kink at every 0.1 s row: n_e zigzags by `amp(t)` rpm per row;
    /// every row a stop, every tenth a jump.
    fn zigzag(amp: impl Fn(f64) -> f64) -> (InputSchedule, Vec<(f64, bool)>) {
        let times: Vec<f64> = (0..=2000).map(|i| i as f64 * 0.1).collect();
        let rows = times
            .iter()
            .enumerate()
            .map(|(i, t)| {
                [
                    1500.0 + if i % 2 == 0 { 0.0 } else { amp(*t) },
                    100.0,
                    50.0,
                    50.0,
                ]
            })
            .collect();
        let stops = times[1..2000]
            .iter()
            .enumerate()
            .map(|(i, t)| (*t, (i + 1) % 10 == 0))
            .collect();
        (InputSchedule::new(times, rows).unwrap(), stops)
    }

    #[test]
    fn splits_balance_the_estimated_work_and_avoid_jumps() {
        // uniform activity: work(t) = t / 200, chunk 1 from t1 - 5: t1 / 200 = 1 - (t1 - 5) / 200
        let (sched, stops) = zigzag(|_| 10.0);
        let s = split_times(&stops, &sched, 0.0, 200.0, 2, 5.0);
        assert_eq!(s.len(), 1);
        assert!((s[0] - 102.5).abs() <= 0.15, "split at {}", s[0]);
        let i = stops.iter().position(|x| x.0 == s[0]).unwrap();
        assert!(!stops[i].1, "split at a jump");
        // 4 chunks: t1 = (t2 - t1) + 5 = (t3 - t2) + 5 = (200 - t3) + 5 -> t1 = 53.75
        let s4 = split_times(&stops, &sched, 0.0, 200.0, 4, 5.0);
        assert_eq!(s4.len(), 3);
        for (got, want) in s4.iter().zip([53.75, 102.5, 151.25]) {
            assert!((got - want).abs() <= 0.15, "{s4:?}");
        }
        // ten times the variation in the first half: a stop at every row, so work(t) = (t /
        // 200 + t / 110 + t / 200) / 3 there, and work(t1) + work(t1 - 5) = 1 gives (2 t1 - 5)
        // (1 / 300 + 1 / 330) = 1, t1 = 81.07
        let (busy, stops_b) = zigzag(|t| if t < 100.0 { 100.0 } else { 10.0 });
        let s = split_times(&stops_b, &busy, 0.0, 200.0, 2, 5.0);
        assert!((s[0] - 81.07).abs() <= 0.15, "split at {}", s[0]);
        // too short for the warm-up: sequential; too few stops: sequential
        assert!(split_times(&stops[..40], &sched, 0.0, 4.0, 2, 5.0).is_empty());
        assert!(split_times(&stops[..10], &sched, 0.0, 1.0, 2, 0.1).is_empty());
        // more chunks than fit (each at least its 19 s warm-up's work: 181 >= 19 k): 9
        assert_eq!(split_times(&stops, &sched, 0.0, 200.0, 40, 19.0).len(), 8);
        // at most one chunk per warm-up length (200 s / 5 s = 40), even when 256 are asked
        let many = split_times(&stops, &sched, 0.0, 200.0, 256, 5.0);
        assert!(
            (2..=40).contains(&(many.len() + 1)),
            "{} chunks",
            many.len() + 1
        );
    }

    /// The estimate runs from 0 at the start to 1 at the end, increasing, with or without
    /// varying inputs and stops (a term that is not defined is left out, not counted as 0).
    #[test]
    fn work_estimate_spans_zero_to_one() {
        let (sched, stops) = zigzag(|t| if t < 100.0 { 100.0 } else { 10.0 });
        let flat =
            InputSchedule::new(vec![0.0, 200.0], vec![[1500.0, 100.0, 50.0, 50.0]; 2]).unwrap();
        for (sched, stops) in [(&sched, &stops[..]), (&sched, &[][..]), (&flat, &[][..])] {
            let w = super::WorkEstimate::new(sched, stops, 0.0, 200.0);
            assert_eq!(w.at(0.0), 0.0);
            assert!((w.at(200.0) - 1.0).abs() < 1e-12, "{}", w.at(200.0));
            let mut last = 0.0;
            for k in 1..=400 {
                let a = w.at(k as f64 * 0.5);
                assert!(a >= last, "not increasing at {} s", k as f64 * 0.5);
                last = a;
            }
        }
    }

    #[test]
    fn first_sample_matches_the_grid() {
        assert_eq!(first_sample(0.0, 0.1, 30.0), 300);
        assert_eq!(first_sample(0.0, 0.1, 30.05), 301);
        // within rounding before the split: the sample belongs to the chunk
        assert_eq!(first_sample(0.0, 0.1, 0.30000000000000004), 3);
        assert_eq!(first_sample(1.0, 0.01, 1.0), 0);
    }

    #[test]
    fn junction_difference_is_scaled() {
        let d = junction_diff(&[1.0, 2.0], &[1.0 + 2e-6, 2.0], &[1e-6, 1e-6], 1e-6);
        // 2e-6 / (1e-6 + 1e-6 * 1.000002)
        assert!((d - 0.999999).abs() < 1e-5, "{d}");
        assert_eq!(
            junction_diff(&[f64::NAN], &[1.0], &[1e-6], 1e-6),
            f64::INFINITY
        );
    }
}
