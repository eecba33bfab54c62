//! Time-parallel integration of one open-loop simulation ([`SimOptions::time_chunks`]).
//!
//! An open-loop run of a model that holds no memory is a function of its state at any time and
//! the inputs after it, and the engine models forget their state within seconds (the slowest
//! mode is the turbo shaft; the actuator states are closed-form lags). So the time axis is cut
//! into chunks integrated at the same time:
//!
//! 1. [`split_times`]: K - 1 stop times where the inputs are continuous (kinks, never jumps),
//!    chosen so that every chunk, its warm-up included, holds about the same number of stop
//!    times (the steps follow the stops, not the time);
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
use super::segment::{stop_times_except, SegmentInputs};
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

/// The stop times (of `stops`, sorted) at which `[t0, ..]` is cut into at most `chunks` chunks
/// of about equal work: chunk 0 from `t0`, chunk k > 0 from its split, plus the stops of its
/// warm-up (`overlap` before the split). Every split is a stop without a jump (`(t, false)`)
/// and lies more than `overlap` after `t0`, and every chunk holds at least as many stops of its
/// own as its warm-up does. Fewer chunks when there are too few stops; empty:
/// the sequential run.
pub fn split_times(stops: &[(f64, bool)], t0: f64, chunks: usize, overlap: f64) -> Vec<f64> {
    let n = stops.len();
    let count = |t: f64| stops.partition_point(|s| s.0 < t);
    for k in (2..=chunks.min(n / 8)).rev() {
        // target work per chunk: the stops plus the warm-ups' stops, shared equally; the
        // warm-ups depend on where the splits fall, so the target is refined twice
        let span = stops[n - 1].0 - t0;
        let warm_guess = n as f64 * (overlap / span).min(1.0);
        let mut target = (n as f64 + (k - 1) as f64 * warm_guess) / k as f64;
        let mut splits = Vec::new();
        for _ in 0..3 {
            splits.clear();
            let mut warm = 0usize;
            let mut next = 0.0f64;
            for _ in 1..k {
                // a chunk's own stops at least its warm-up's (else fewer chunks)
                if target < 2.0 * warm as f64 {
                    break;
                }
                next += target - warm as f64;
                let Some(t) = kink_from(stops, next.round().max(1.0) as usize) else {
                    break;
                };
                if splits.last().is_some_and(|&p| t <= p) || t - overlap <= t0 {
                    break;
                }
                splits.push(t);
                let i = count(t);
                warm = i - count(t - overlap);
                next = i as f64;
            }
            if splits.len() + 1 < k {
                break;
            }
            let warm_all: usize = splits.iter().map(|&t| count(t) - count(t - overlap)).sum();
            target = (n + warm_all) as f64 / k as f64;
        }
        if splits.len() + 1 == k {
            return splits;
        }
    }
    Vec::new()
}

/// Stops on either side of the balanced index among which a split is chosen
/// ([`kink_from`]).
const SPLIT_WINDOW: usize = 128;

/// Time before a split candidate whose largest gap between stops ranks it [s]
/// ([`kink_from`]).
const SPLIT_CALM: f64 = 10.0;

/// A stop without a jump near index `i` (never the first or the last stop): of those within
/// [`SPLIT_WINDOW`] stops, the one whose preceding [`SPLIT_CALM`] seconds have the shortest
/// largest gap between stops. Where the inputs change at every row, two runs whose states agree
/// also take the same steps, since every segment's steps end at its stop; in a quiet stretch the
/// step sizes grow without such a bound, differently in two runs that started differently, and
/// at the next kink their states differ by up to a few tolerance units for a few seconds
/// (measured on the WHTC, `docs/integrator.md`): no place for a junction.
fn kink_from(stops: &[(f64, bool)], i: usize) -> Option<f64> {
    let lo = i.saturating_sub(SPLIT_WINDOW).max(1);
    let hi = (i + SPLIT_WINDOW).min(stops.len().saturating_sub(1));
    (lo..hi)
        .filter(|&j| !stops[j].1)
        .min_by_key(|&j| {
            let from = stops[..j].partition_point(|s| s.0 < stops[j].0 - SPLIT_CALM);
            let gap = stops[from.max(1) - 1..=j]
                .windows(2)
                .map(|w| w[1].0 - w[0].0)
                .fold(0.0, f64::max);
            // the gap to 1 ms (equal gaps: the candidate nearest the balanced index)
            ((gap * 1e3).round() as i64, j.abs_diff(i))
        })
        .map(|j| stops[j].0)
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
    if run.advance(tk, &mut out, false).is_err() {
        return Chunk {
            run: None,
            y_start: None,
            out,
            stats: run.stats,
        };
    }
    debug_assert!(out.is_empty(), "a warm-up wrote samples");
    let y_start = run.y;
    let ok = run.advance(t_end, &mut out, last).is_ok();
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
    let splits = if opts.time_chunks > 1 && !model.holds_memory() && opts.stop_at_breakpoints {
        let stops = stop_times_except(model, sched, t0, t_end, first.skip_lag_stops());
        split_times(&stops, t0, opts.time_chunks, opts.chunk_overlap)
    } else {
        Vec::new()
    };
    if splits.is_empty() {
        first.advance(t_end, &mut sol, true)?;
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
    std::thread::scope(|s| {
        let handles: Vec<_> = (1..k_all)
            .map(|k| {
                let out = sol.kept_like();
                let (tk, te) = (starts[k], ends[k]);
                let last = k + 1 == k_all;
                s.spawn(move || {
                    run_chunk(model, sched, t0, tk, te, last, y_first, opts, guess, out)
                })
            })
            .collect();
        let mut total = SimStats::default();
        let mut junctions = Vec::with_capacity(k_all - 1);
        // chunk 0: the sequential run up to the first split (a failure is final)
        first.advance(ends[0], &mut sol, false)?;
        let mut prev = first;
        for (k, h) in (1..k_all).zip(handles) {
            let chunk = match h.join() {
                Ok(c) => c,
                Err(panic) => std::panic::resume_unwind(panic),
            };
            let last = k + 1 == k_all;
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
                    prev.advance(ends[k], &mut sol, last)?;
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

    #[test]
    fn splits_balance_stops_and_avoid_jumps() {
        // 1000 stops, one per 0.1 s from 0.1 s, every tenth a jump
        let stops: Vec<(f64, bool)> = (1..=1000).map(|i| (i as f64 * 0.1, i % 10 == 0)).collect();
        let s = split_times(&stops, 0.0, 2, 5.0);
        assert_eq!(s.len(), 1);
        // chunk 0 holds i stops, chunk 1 1000 - i plus its 50 warm-up stops: i = 525 (+- the
        // step to a kink)
        let i = stops.iter().position(|x| x.0 == s[0]).unwrap() + 1;
        assert!((525..=527).contains(&i), "split after {i} stops");
        assert!(!stops[i - 1].1, "split at a jump");
        let s4 = split_times(&stops, 0.0, 4, 5.0);
        assert_eq!(s4.len(), 3);
        let idx: Vec<usize> = s4
            .iter()
            .map(|t| stops.iter().position(|x| x.0 == *t).unwrap() + 1)
            .collect();
        // equal work: i1 = i2 - i1 + 50 = i3 - i2 + 50 = 1000 - i3 + 50 -> i1 = 287.5
        let work = [
            idx[0],
            idx[1] - idx[0] + 50,
            idx[2] - idx[1] + 50,
            1000 - idx[2] + 50,
        ];
        for w in work {
            assert!((284..=292).contains(&w), "work {work:?}");
        }
        // too short for the warm-up: sequential; too few stops: sequential
        assert!(split_times(&stops[..40], 0.0, 2, 5.0).is_empty());
        assert!(split_times(&stops[..10], 0.0, 2, 0.1).is_empty());
        // more chunks than fit (each holds at least its warm-up's 190 stops): fewer
        assert_eq!(split_times(&stops, 0.0, 40, 19.0).len(), 3);
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
