//! The inputs of one integration segment and the stop times between segments.
//!
//! The transport delays act on known input functions, so they are exact: a delayed lookup is
//! the schedule evaluated at `t - tau` (constant history before the first row). The time axis is
//! split at every breakpoint of every channel that drives the dynamics (jumps and kinks),
//! shifted by the delay of each delayed lookup ([`Dynamics::input_delays`]), and each segment sees
//! the inputs strictly from inside, so a step on either side of a jump sees one smooth input.

use super::input::{BreakKind, InputSchedule, Side};
use super::integrator::LagPiece;
use crate::model::{Dynamics, LagCommand, ModelInput};

/// A linear piece of a schedule channel: (t_lo, t_hi, t_ref, v_ref, slope), see
/// [`InputSchedule::piece`].
type Piece = (f64, f64, f64, f64, f64);

/// The inputs of the model over time plus the delays: evaluates [`ModelInput`] for one
/// integration segment `[a, b]` between consecutive stop times, always from inside the segment
/// (so a step at `a` or `b` is seen from the correct side).
pub struct SegmentInputs<'a> {
    sched: &'a InputSchedule,
    tau_egr: f64,
    tau_vgt: f64,
    hints: [usize; 6],
    /// The two most recently used linear pieces per lookup: (t_lo, t_hi, t_ref, v_ref, slope).
    /// Pieces come from the schedule alone, so the cache stays valid from one segment to the
    /// next. Two, because the undelayed u_egr and u_vgt commands are not stop times when the
    /// actuators are dynamic (only their delayed copies are), so a segment can straddle one of
    /// their kinks and the stages of a step alternate between the two pieces.
    pieces: [[Piece; 2]; 6],
    /// Lookup window per lookup: inputs are evaluated at times clamped strictly inside the
    /// segment (shifted back by the lookup's delay), or unclamped if the segment is too short.
    window: [(f64, f64); 6],
    /// Per lookup, the linear piece (t_ref, v_ref, slope) that covers the whole window of the
    /// current segment, if one does (always for the lookups whose kinks are stop times).
    linear: [Option<(f64, f64, f64)>; 6],
    /// Whether the delayed u_egr / u_vgt lookup drives only closed-form lag states: its value
    /// enters only derivatives the integrator does not use (the closed form gives those states,
    /// from [`Self::lag_pieces`]), so it is read from the line of its first piece on the segment,
    /// without searches (whether or not its breakpoints are stop times,
    /// [`super::SimOptions::stop_at_lag_breakpoints`]).
    lag_only: [bool; 2],
    /// Start of the current segment \[s\].
    start: f64,
}

impl<'a> SegmentInputs<'a> {
    /// Inputs of `model` driven by `sched` on the segment `[a, b]`.
    pub fn new<const N: usize, M: Dynamics<N>>(
        model: &M,
        sched: &'a InputSchedule,
        a: f64,
        b: f64,
    ) -> Self {
        Self::with_lag_only(model, sched, a, b, [false; 2])
    }

    /// [`SegmentInputs::new`] with the delayed lookups marked in `lag_only` read from their
    /// first piece (see the field).
    pub(super) fn with_lag_only<const N: usize, M: Dynamics<N>>(
        model: &M,
        sched: &'a InputSchedule,
        a: f64,
        b: f64,
        lag_only: [bool; 2],
    ) -> Self {
        let [tau_egr, tau_vgt] = model.input_delays().delayed;
        let mut me = Self {
            sched,
            tau_egr,
            tau_vgt,
            hints: [0; 6],
            pieces: [[(f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0, 0.0); 2]; 6],
            window: [(f64::NEG_INFINITY, f64::INFINITY); 6],
            linear: [None; 6],
            lag_only,
            start: f64::NAN,
        };
        me.set_segment(a, b);
        me
    }

    /// Start of the current segment \[s\] (the `a` of the last [`Self::set_segment`]).
    pub fn segment_start(&self) -> f64 {
        self.start
    }

    /// Move to the segment `[a, b]` (keeps the search cursors and cached pieces).
    pub fn set_segment(&mut self, a: f64, b: f64) {
        self.start = a;
        for k in 0..6 {
            let shift = self.shift(k);
            let lo = a - shift + Self::delta(a);
            let hi = b - shift - Self::delta(b);
            self.window[k] = if hi > lo {
                (lo, hi)
            } else {
                (f64::NEG_INFINITY, f64::INFINITY)
            };
        }
        for k in 0..6 {
            let (lo, hi) = self.window[k];
            self.linear[k] = None;
            if lo.is_finite() {
                let mut pc = self.pieces[k][0];
                if !(pc.0 <= lo && lo <= pc.1) {
                    pc = self
                        .sched
                        .piece(Self::CHANNEL[k], lo, Side::Right, &mut self.hints[k]);
                    self.pieces[k] = [pc, self.pieces[k][0]];
                }
                let lag_only = k >= 4 && self.lag_only[k - 4];
                if pc.0 <= lo && (hi <= pc.1 || lag_only) {
                    self.linear[k] = Some((pc.2, pc.3, pc.4));
                }
            }
        }
    }

    /// The delayed command `cmd` on the segment `[a, b]`, saturated to `sat`, as linear pieces in
    /// simulation time (written to `out`, sorted, the first starting at `a`): the schedule's rows
    /// shifted by the delay, split where the command crosses a saturation limit, so that the
    /// closed-form lag follows it exactly across jumps and kinks inside a step. Breakpoints within
    /// 10 [`Self::delta`] of either end belong to that end (as [`stop_times`] merges them).
    pub(super) fn lag_pieces(
        &mut self,
        cmd: LagCommand,
        a: f64,
        b: f64,
        sat: (f64, f64),
        out: &mut Vec<LagPiece>,
    ) {
        out.clear();
        let k = match cmd {
            LagCommand::Egr => 4,
            LagCommand::Vgt => 5,
        };
        let (ch, shift) = (Self::CHANNEL[k], self.shift(k));
        let (m_a, m_b) = (10.0 * Self::delta(a), 10.0 * Self::delta(b));
        let (lo, hi) = (a - shift, b - shift);
        // the first lookup strictly inside the segment (its middle if the segment is shorter
        // than the margins)
        let mut tq = if hi - lo > m_a + m_b {
            lo + m_a
        } else {
            0.5 * (lo + hi)
        };
        loop {
            let (_, t_hi, t_ref, v_ref, slope) =
                self.sched.piece(ch, tq, Side::Right, &mut self.hints[k]);
            // the first piece from a on (its line extended back over the margin); the last to b
            let start = if out.is_empty() { lo } else { tq };
            let last = t_hi >= hi - m_b;
            let end = if last { hi } else { t_hi };
            push_saturated(
                out,
                start + shift,
                end + shift,
                v_ref + slope * (start - t_ref),
                slope,
                sat,
            );
            if last {
                break;
            }
            tq = t_hi;
        }
    }

    /// Delay \[s\] of lookup `k` (the actuator delays for the delayed commands, else none).
    #[inline(always)]
    fn shift(&self, k: usize) -> f64 {
        match k {
            4 => self.tau_egr,
            5 => self.tau_vgt,
            _ => 0.0,
        }
    }

    /// Schedule channel of each lookup (n_e, u_delta, u_egr, u_vgt, delayed u_egr, delayed
    /// u_vgt).
    const CHANNEL: [usize; 6] = [0, 1, 2, 3, 2, 3];

    #[inline]
    pub(super) fn delta(t: f64) -> f64 {
        1e-12 * t.abs().max(1.0)
    }

    /// Value of lookup `k` (channel [`Self::CHANNEL`]`[k]`, delayed by [`Self::shift`]) at `t`.
    #[inline(always)]
    fn value(&mut self, k: usize, t: f64) -> f64 {
        let (tq, (t_ref, v_ref, slope)) = self.line_at(k, t);
        v_ref + slope * (tq - t_ref)
    }

    /// Time derivative of lookup `k` at `t`: the slope of the linear piece [`Self::value`]
    /// uses there (the one inside the segment: `t` is clamped to the window as for the value).
    fn rate(&mut self, k: usize, t: f64) -> f64 {
        let (_, (_, _, slope)) = self.line_at(k, t);
        slope
    }

    /// The lookup time of lookup `k` at `t` (shifted by its delay, clamped to the segment's
    /// window) and the line (t_ref, v_ref, slope) of the schedule piece there: the segment's
    /// line if one covers the window, else one of the two cached pieces, else a search (which
    /// replaces the older cached piece).
    #[inline(always)]
    fn line_at(&mut self, k: usize, t: f64) -> (f64, (f64, f64, f64)) {
        let (lo, hi) = self.window[k];
        let tq = (t - self.shift(k)).clamp(lo, hi);
        if let Some(line) = self.linear[k] {
            return (tq, line);
        }
        // a cached piece serves the times inside it and its start, not its end: at a
        // breakpoint the search's `Side::Right` decides (the piece that starts there), so the
        // value at a jump is the right limit whichever piece the cache held (it was the left
        // one after a lookup just before, e.g. output samples every 5 ms up to a jump of an
        // input that is a stop time only after its delay)
        let p0 = &self.pieces[k][0];
        if p0.0 <= tq && tq < p0.1 {
            return (tq, (p0.2, p0.3, p0.4));
        }
        let p1 = &self.pieces[k][1];
        let pc = if p1.0 <= tq && tq < p1.1 {
            *p1
        } else {
            self.sched
                .piece(Self::CHANNEL[k], tq, Side::Right, &mut self.hints[k])
        };
        self.pieces[k] = [pc, self.pieces[k][0]];
        (tq, (pc.2, pc.3, pc.4))
    }

    /// Time derivatives of the model inputs at `t` in the segment (the inputs are linear
    /// between stop times, so this is the slope of each lookup's piece inside the segment;
    /// nothing outside the segment's input window is read).
    pub fn rates(&mut self, t: f64) -> ModelInput {
        let now = crate::model::Drive::new(
            self.rate(0, t),
            self.rate(1, t),
            self.rate(2, t),
            self.rate(3, t),
        );
        ModelInput {
            now,
            u_egr_delayed: self.rate(4, t),
            u_vgt_delayed: self.rate(5, t),
        }
    }

    /// Model inputs at `t` in the segment: current values and delayed actuator commands.
    #[inline]
    pub fn at(&mut self, t: f64) -> ModelInput {
        let now = crate::model::Drive::new(
            self.value(0, t),
            self.value(1, t),
            self.value(2, t),
            self.value(3, t),
        );
        ModelInput {
            now,
            u_egr_delayed: self.value(4, t),
            u_vgt_delayed: self.value(5, t),
        }
    }
}

/// The saturated line `c0 + beta (t - t0)` on `[t0, t1]` appended to `out` as pieces: split
/// where it crosses a finite limit of `sat`, constant at the limit outside, a constant equal to
/// the last piece or a line on the last piece's line to rounding ([`LagPiece::extends_to`])
/// merged into it.
fn push_saturated(
    out: &mut Vec<LagPiece>,
    t0: f64,
    t1: f64,
    c0: f64,
    beta: f64,
    (lo, hi): (f64, f64),
) {
    let line = |t: f64| c0 + beta * (t - t0);
    // crossings of the limits strictly inside (t0, t1), in time order
    let mut cuts = [f64::INFINITY; 2];
    if beta != 0.0 {
        for (c, limit) in cuts.iter_mut().zip([lo, hi]) {
            let tc = t0 + (limit - c0) / beta;
            if limit.is_finite() && tc > t0 && tc < t1 {
                *c = tc;
            }
        }
        if cuts[1] < cuts[0] {
            cuts.swap(0, 1);
        }
    }
    let mut u0 = t0;
    for u1 in cuts.into_iter().filter(|c| c.is_finite()).chain([t1]) {
        let mid = line(0.5 * (u0 + u1));
        let piece = if mid < lo {
            LagPiece::constant(u0, lo)
        } else if mid > hi {
            LagPiece::constant(u0, hi)
        } else {
            LagPiece::new(u0, line(u0), beta)
        };
        match out.last() {
            Some(p) if p.continues_as(&piece) || p.extends_to(&piece, u1) => {}
            _ => out.push(piece),
        }
        u0 = u1;
    }
}

/// Sorted stop times in (t0, t_end) with a flag for jumps: every breakpoint of every channel
/// that drives the dynamics, shifted by the delay of the path it feeds ([`Dynamics::input_delays`];
/// the engine models: n_e, u_delta unshifted, u_egr by tau_degr, u_vgt by tau_dvgt, plus
/// unshifted u_egr, u_vgt when the actuators are bypassed).
pub fn stop_times<const N: usize, M: Dynamics<N>>(
    m: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
) -> Vec<(f64, bool)> {
    stop_times_except(m, sched, t0, t_end, [false; 2])
}

/// How close to the ends of an interval a stop is left out, and how close two stops are merged
/// into one: ten input evaluation margins ([`SegmentInputs::delta`]) at `t` \[s\]
/// ([`stop_times_except`]; a time-parallel chunk cuts its part of one stop list by the same
/// margins).
pub(super) fn stop_margin(t: f64) -> f64 {
    SegmentInputs::delta(t) * 10.0
}

/// [`stop_times`] without the delayed lookups of channels 2 and 3 marked in `skip_delayed`
/// (those that drive only closed-form lag states, [`super::SimOptions::stop_at_lag_breakpoints`]).
pub(super) fn stop_times_except<const N: usize, M: Dynamics<N>>(
    m: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    skip_delayed: [bool; 2],
) -> Vec<(f64, bool)> {
    let delays = m.input_delays();
    // no row after t0 - (the largest shift in use): no stop (a plant's history ends at its t;
    // with the delayed lookups skipped, every sample gets here without scanning the rows)
    let max_shift = (0..4)
        .filter(|&ch| delays.current[ch])
        .map(|_| 0.0)
        .chain(
            (0..2)
                .filter(|&k| !skip_delayed[k])
                .map(|k| delays.delayed[k]),
        )
        .fold(f64::NEG_INFINITY, f64::max);
    if sched.t_last() + max_shift <= t0 + stop_margin(t0) {
        return Vec::new();
    }
    let mut v: Vec<(f64, bool)> = Vec::with_capacity(8 * sched.times().len());
    for ch in 0..4 {
        let now = delays.current[ch].then_some(0.0);
        let delayed = ch
            .checked_sub(2)
            .filter(|&k| !skip_delayed[k])
            .map(|k| delays.delayed[k]);
        if now.is_none() && delayed.is_none() {
            continue;
        }
        for (tb, kind) in sched.breakpoints(ch) {
            for s in now.into_iter().chain(delayed) {
                v.push((tb + s, kind == BreakKind::Jump));
            }
        }
    }
    v.retain(|(t, _)| *t > t0 + stop_margin(t0) && *t < t_end - stop_margin(t_end));
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    // merge stops closer than the input evaluation margin
    let mut out: Vec<(f64, bool)> = Vec::with_capacity(v.len());
    for (t, jump) in v {
        match out.last_mut() {
            Some(last) if t - last.0 <= stop_margin(t) => last.1 |= jump,
            _ => out.push((t, jump)),
        }
    }
    out
}
