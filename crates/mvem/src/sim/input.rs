//! Input signals: constants, step schedules and time series of (n_e, u_delta, u_egr, u_vgt).
//!
//! An [`InputSchedule`] is a table of rows `(t, n_e, u_delta, u_egr, u_vgt)` interpolated
//! linearly between rows; two rows with the same time are a step (the value jumps there and the
//! schedule is right-continuous). Before the first row the first row is held (constant input
//! history for the transport delays); after the last row the last row is held.
//!
//! The simulator needs to know where the inputs are not smooth, so that it never steps over an
//! input change: [`InputSchedule::breakpoints`] lists, per channel, the jumps and the kinks
//! (rows where the slope changes). Rows that lie on the straight line through their
//! neighbours within [`InputSchedule::collinear_tol`] (default 1e-6 in the channel's unit, below
//! the resolution of a 6-decimal CSV) are not breakpoints; the values themselves are always
//! interpolated between the original rows.

use crate::model::Drive;

/// Which limit to take at a jump.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// lim s -> t from below (the value just before a step).
    Left,
    /// lim s -> t from above (the value at and after a step).
    Right,
}

/// Kind of an input breakpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BreakKind {
    /// The value is continuous, its slope is not.
    Kink,
    /// The value jumps (a step).
    Jump,
}

/// Piecewise-linear input table (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct InputSchedule {
    times: Vec<f64>,
    rows: Vec<[f64; 4]>,
    /// Collinearity tolerance per channel [channel unit] for breakpoint detection.
    pub collinear_tol: [f64; 4],
}

/// A problem with schedule data. The messages count rows from 1 (the second row is "row 2"), as
/// the closed loop's demands do; the fields hold the 0-based index.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScheduleError {
    /// No rows.
    #[error("input schedule has no rows")]
    Empty,
    /// A time or value is NaN or infinite.
    #[error("row {}: {column} = {value} is not finite", .row + 1)]
    NonFinite {
        /// 0-based row index.
        row: usize,
        /// Column name.
        column: &'static str,
        /// Offending value.
        value: f64,
    },
    /// Time decreases, or more than two rows share a time.
    #[error("row {}: time {t} s is not monotonic (previous {prev} s){detail}", .row + 1)]
    NonMonotonic {
        /// 0-based row index.
        row: usize,
        /// Its time.
        t: f64,
        /// Previous time.
        prev: f64,
        /// Extra explanation.
        detail: &'static str,
    },
}

/// Column names of a schedule row (CSV header of the input files).
pub const INPUT_COLUMNS: [&str; 5] = ["time_s", "n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct"];

/// The values of row `i` must be finite (the error names the row and the column).
fn check_values(i: usize, r: &[f64; 4]) -> Result<(), ScheduleError> {
    match r.iter().position(|v| !v.is_finite()) {
        Some(c) => Err(ScheduleError::NonFinite {
            row: i,
            column: INPUT_COLUMNS[c + 1],
            value: r[c],
        }),
        None => Ok(()),
    }
}

/// Whether row `i` of a table whose `times` are linear between rows, two rows at one time a
/// step (the value jumps there), may follow the rows before it: its time not before the
/// previous row's, and no third row at one time. The error names the 0-based row; the input
/// schedules and the closed loop's demands ([`crate::control::Demand`]) share this rule.
pub fn check_time_order(times: &[f64], i: usize) -> Result<(), ScheduleError> {
    if i == 0 {
        return Ok(());
    }
    let (t, prev) = (times[i], times[i - 1]);
    if t < prev {
        return Err(ScheduleError::NonMonotonic {
            row: i,
            t,
            prev,
            detail: "",
        });
    }
    if i > 1 && t == prev && times[i - 2] == prev {
        return Err(ScheduleError::NonMonotonic {
            row: i,
            t,
            prev,
            detail: " (more than two rows with the same time)",
        });
    }
    Ok(())
}

impl InputSchedule {
    /// Build from rows `(t, [n_e, u_delta, u_egr, u_vgt])`; times must be non-decreasing, at most
    /// two rows may share a time (a step).
    pub fn new(times: Vec<f64>, rows: Vec<[f64; 4]>) -> Result<Self, ScheduleError> {
        if times.is_empty() || times.len() != rows.len() {
            return Err(ScheduleError::Empty);
        }
        for (i, (t, r)) in times.iter().zip(&rows).enumerate() {
            if !t.is_finite() {
                return Err(ScheduleError::NonFinite {
                    row: i,
                    column: INPUT_COLUMNS[0],
                    value: *t,
                });
            }
            check_values(i, r)?;
            check_time_order(&times, i)?;
        }
        Ok(Self {
            times,
            rows,
            collinear_tol: [1e-6; 4],
        })
    }

    /// Constant inputs.
    pub fn constant(d: Drive) -> Self {
        Self::new(vec![0.0], vec![d.to_array()]).expect("finite constant")
    }

    /// A step schedule: start at `initial`, then at each `(t, channel, value)` (sorted by time is
    /// not required) the channel jumps to `value` and is held (zero-order hold).
    /// Channels: 0 = n_e, 1 = u_delta, 2 = u_egr, 3 = u_vgt.
    pub fn steps(initial: Drive, steps: &[(f64, usize, f64)]) -> Result<Self, ScheduleError> {
        let mut s: Vec<(f64, usize, f64)> = steps.to_vec();
        s.sort_by(|a, b| a.0.total_cmp(&b.0));
        let t0 = s.first().map(|x| x.0.min(0.0)).unwrap_or(0.0);
        let mut times = vec![t0];
        let mut rows = vec![initial.to_array()];
        let mut cur = initial.to_array();
        let mut i = 0;
        while i < s.len() {
            let t = s[i].0;
            let mut next = cur;
            while i < s.len() && s[i].0 == t {
                if s[i].1 > 3 {
                    return Err(ScheduleError::NonFinite {
                        row: i,
                        column: "channel",
                        value: s[i].1 as f64,
                    });
                }
                next[s[i].1] = s[i].2;
                i += 1;
            }
            if *times.last().unwrap() != t {
                times.push(t);
                rows.push(cur);
            }
            times.push(t);
            rows.push(next);
            cur = next;
        }
        Self::new(times, rows)
    }

    /// Hold the row `row` from `t` on (zero-order hold, appended in place): a change at `t` adds
    /// the pair (t, previous row), (t, row); an unchanged row adds nothing. `t` must not be
    /// before the last row.
    pub fn hold(&mut self, t: f64, row: [f64; 4]) -> Result<(), ScheduleError> {
        let n = self.times.len();
        let last = self.rows[n - 1];
        if row == last {
            return Ok(());
        }
        check_values(n, &row)?;
        let prev = self.times[n - 1];
        if t.is_nan() || t < prev {
            return Err(ScheduleError::NonMonotonic {
                row: n,
                t,
                prev,
                detail: " (a held row must not be before the last row)",
            });
        }
        if prev == t {
            if n >= 2 && self.times[n - 2] == t {
                // already a step at t: the new row replaces its right value
                self.rows[n - 1] = row;
                return Ok(());
            }
        } else {
            self.times.push(t);
            self.rows.push(last);
        }
        self.times.push(t);
        self.rows.push(row);
        Ok(())
    }

    /// Drop the rows that no lookup at or after `t` can reach: every row before the last row
    /// at or before `t` (that row stays, so the values from `t` on are unchanged).
    pub fn drop_before(&mut self, t: f64) {
        let k = self.times.partition_point(|&s| s <= t);
        if k >= 2 {
            self.times.drain(..k - 1);
            self.rows.drain(..k - 1);
        }
    }

    /// Row times \[s\].
    pub fn times(&self) -> &[f64] {
        &self.times
    }

    /// Row values `[n_e, u_delta, u_egr, u_vgt]`.
    pub fn rows(&self) -> &[[f64; 4]] {
        &self.rows
    }

    /// First row time \[s\].
    pub fn t_first(&self) -> f64 {
        self.times[0]
    }

    /// Last row time \[s\].
    pub fn t_last(&self) -> f64 {
        *self.times.last().unwrap()
    }

    /// Index `i` of the interval `[times[i], times[i+1]]` used at time `t` from `side`, with a
    /// cursor hint for O(1) sequential access. Returns `None` before the first / after the last row.
    fn interval(&self, t: f64, side: Side, hint: &mut usize) -> Option<usize> {
        let n = self.times.len();
        let ts = &self.times;
        let before = |tt: f64| match side {
            Side::Right => t < tt,
            Side::Left => t <= tt,
        };
        if before(ts[0]) {
            return None;
        }
        if !before(ts[n - 1]) {
            return Some(n - 1);
        }
        // find i with ts[i] "<=" t "<" ts[i+1] (side-aware)
        let mut i = (*hint).min(n - 2);
        if before(ts[i]) {
            // move back
            while i > 0 && before(ts[i]) {
                i -= 1;
            }
        } else {
            let mut steps = 0;
            while i + 1 < n - 1 && !before(ts[i + 1]) {
                i += 1;
                steps += 1;
                if steps > 16 {
                    // far away: binary search
                    let k = ts.partition_point(|&x| !before(x));
                    i = k.saturating_sub(1);
                    break;
                }
            }
        }
        *hint = i;
        Some(i)
    }

    /// Value of `channel` at `t` (side-aware at steps), using `hint` as a search cursor.
    #[inline]
    pub fn value_hint(&self, channel: usize, t: f64, side: Side, hint: &mut usize) -> f64 {
        match self.interval(t, side, hint) {
            None => self.rows[0][channel],
            Some(i) if i + 1 >= self.times.len() => self.rows[i][channel],
            Some(i) => {
                let (t0, t1) = (self.times[i], self.times[i + 1]);
                let (v0, v1) = (self.rows[i][channel], self.rows[i + 1][channel]);
                if t1 == t0 {
                    return match side {
                        Side::Left => v0,
                        Side::Right => v1,
                    };
                }
                let th = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
                v0 + th * (v1 - v0)
            }
        }
    }

    /// The linear piece that gives `channel`'s value at `t` (from `side` at steps): returns
    /// `(t_lo, t_hi, t_ref, v_ref, slope)`, valid for t_lo <= t <= t_hi, value = v_ref + slope (t - t_ref).
    pub fn piece(
        &self,
        channel: usize,
        t: f64,
        side: Side,
        hint: &mut usize,
    ) -> (f64, f64, f64, f64, f64) {
        let n = self.times.len();
        match self.interval(t, side, hint) {
            None => (
                f64::NEG_INFINITY,
                self.times[0],
                self.times[0],
                self.rows[0][channel],
                0.0,
            ),
            Some(i) if i + 1 >= n => (
                self.times[n - 1],
                f64::INFINITY,
                self.times[n - 1],
                self.rows[n - 1][channel],
                0.0,
            ),
            Some(i) => {
                let (t0, t1) = (self.times[i], self.times[i + 1]);
                let (v0, v1) = (self.rows[i][channel], self.rows[i + 1][channel]);
                if t1 == t0 {
                    let v = match side {
                        Side::Left => v0,
                        Side::Right => v1,
                    };
                    (t0, t0, t0, v, 0.0)
                } else {
                    (t0, t1, t0, v0, (v1 - v0) / (t1 - t0))
                }
            }
        }
    }

    /// All four inputs at `t` (right-continuous).
    pub fn at(&self, t: f64) -> Drive {
        let mut h = 0;
        Drive::from_array(std::array::from_fn(|c| {
            self.value_hint(c, t, Side::Right, &mut h)
        }))
    }

    /// Breakpoints of `channel`: sorted `(time, kind)` where the channel jumps or its slope
    /// changes by more than the collinearity tolerance allows.
    pub fn breakpoints(&self, channel: usize) -> Vec<(f64, BreakKind)> {
        let ts = &self.times;
        // the channel's values read in place (no copy: the closed loop's plant asks every sample)
        let v = |k: usize| self.rows[k][channel];
        let tol = self.collinear_tol[channel];
        let n = ts.len();
        // at most one breakpoint per row (sized once: a plant asks every sample)
        let mut out = Vec::with_capacity(n);
        // Start of the current linear piece; before the first row the value is constant.
        let mut s_t = f64::NEG_INFINITY;
        let mut s_v = v(0);
        let mut s_idx: Option<usize> = None; // first row index within the piece
        let mut k = 0;
        while k < n {
            if k + 1 < n && ts[k + 1] == ts[k] {
                // a step at ts[k]
                if v(k + 1) != v(k) {
                    out.push((ts[k], BreakKind::Jump));
                    s_t = ts[k];
                    s_v = v(k + 1);
                    s_idx = Some(k + 1);
                    k += 2;
                    continue;
                }
                k += 1;
                continue;
            }
            // does row k+1 (or the constant continuation after the last row) keep the piece linear?
            let (nt, nv) = if k + 1 < n {
                (ts[k + 1], v(k + 1))
            } else {
                (f64::INFINITY, v(k))
            };
            let linear = self.piece_is_linear(s_t, s_v, s_idx, k, nt, nv, channel, tol);
            if !linear {
                out.push((ts[k], BreakKind::Kink));
                s_t = ts[k];
                s_v = v(k);
                s_idx = Some(k);
            }
            k += 1;
        }
        out.dedup_by(|a, b| a.0 == b.0);
        out
    }

    /// Whether row `k` (and the piece's first row) lie within `tol` of the straight line from
    /// (s_t, s_v) to (nt, nv); infinite ends mean a constant piece.
    #[allow(clippy::too_many_arguments)]
    fn piece_is_linear(
        &self,
        s_t: f64,
        s_v: f64,
        s_idx: Option<usize>,
        k: usize,
        nt: f64,
        nv: f64,
        channel: usize,
        tol: f64,
    ) -> bool {
        let ts = &self.times;
        let v = |i: usize| self.rows[i][channel];
        // a constant piece continued by a constant (the zero-order-hold rows of a plant's
        // command history): on the line exactly, without the divisions below
        if v(k) == s_v && nv == s_v {
            return true;
        }
        let line = |t: f64| -> f64 {
            if s_t.is_infinite() || nt.is_infinite() {
                // constant piece (before the first or after the last row)
                if s_t.is_infinite() && nt.is_infinite() {
                    s_v
                } else if s_t.is_infinite() {
                    nv
                } else {
                    s_v
                }
            } else {
                s_v + (nv - s_v) * (t - s_t) / (nt - s_t)
            }
        };
        if s_t.is_infinite() && !nt.is_infinite() && (nv - s_v).abs() > tol {
            return false;
        }
        if nt.is_infinite() && !s_t.is_infinite() && (nv - s_v).abs() > tol {
            return false;
        }
        // O(1) per row: the rows before k were checked against earlier chords of this piece.
        let first = s_idx.unwrap_or(0);
        (v(first) - line(ts[first])).abs() <= tol && (v(k) - line(ts[k])).abs() <= tol
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sched(times: &[f64], col: &[f64]) -> InputSchedule {
        InputSchedule::new(
            times.to_vec(),
            col.iter().map(|v| [*v, 1.0, 2.0, 3.0]).collect(),
        )
        .unwrap()
    }

    #[test]
    fn interpolation_and_steps() {
        let s = sched(&[0.0, 1.0, 1.0, 2.0], &[0.0, 10.0, 20.0, 30.0]);
        let mut h = 0;
        assert_eq!(s.value_hint(0, -5.0, Side::Right, &mut h), 0.0);
        assert_eq!(s.value_hint(0, 0.5, Side::Right, &mut h), 5.0);
        assert_eq!(s.value_hint(0, 1.0, Side::Left, &mut h), 10.0);
        assert_eq!(s.value_hint(0, 1.0, Side::Right, &mut h), 20.0);
        assert_eq!(s.value_hint(0, 1.5, Side::Right, &mut h), 25.0);
        assert_eq!(s.value_hint(0, 9.0, Side::Right, &mut h), 30.0);
        // going back with a stale hint still works
        assert_eq!(s.value_hint(0, 0.25, Side::Right, &mut h), 2.5);
        let bp = s.breakpoints(0);
        assert_eq!(
            bp,
            vec![
                (0.0, BreakKind::Kink),
                (1.0, BreakKind::Jump),
                (2.0, BreakKind::Kink)
            ]
        );
        // constant channel: no breakpoints
        assert!(s.breakpoints(1).is_empty());
    }

    #[test]
    fn collinear_rows_are_not_breakpoints() {
        let s = sched(&[0.0, 1.0, 2.0, 3.0, 4.0], &[5.0, 5.0, 6.0, 7.0, 7.0]);
        let bp: Vec<f64> = s.breakpoints(0).iter().map(|b| b.0).collect();
        assert_eq!(bp, vec![1.0, 3.0]);
    }

    #[test]
    fn errors_name_row_and_column() {
        let e = InputSchedule::new(vec![0.0, 1.0], vec![[1.0; 4], [1.0, f64::NAN, 1.0, 1.0]]);
        assert_eq!(
            e.unwrap_err().to_string(),
            "row 2: u_delta_mg = NaN is not finite"
        );
        let e = InputSchedule::new(vec![0.0, 2.0, 1.0], vec![[1.0; 4]; 3]).unwrap_err();
        assert!(e.to_string().contains("row 3: time 1 s is not monotonic"));
        let e = InputSchedule::new(vec![0.0, 1.0, 1.0, 1.0], vec![[1.0; 4]; 4]).unwrap_err();
        assert!(e.to_string().contains("more than two rows"));
    }

    #[test]
    fn hold_appends_zero_order_hold_rows_and_drop_before_keeps_the_values() {
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let mut s = InputSchedule::constant(d);
        s.hold(1.0, d.to_array()).unwrap(); // unchanged: nothing
        assert_eq!(s.times(), &[0.0]);
        s.hold(1.0, [1500.0, 110.0, 80.0, 65.0]).unwrap();
        s.hold(1.0, [1500.0, 110.0, 80.0, 60.0]).unwrap(); // replaces the step's right value
        s.hold(2.0, [1500.0, 120.0, 80.0, 60.0]).unwrap();
        let built = InputSchedule::steps(d, &[(1.0, 3, 60.0), (2.0, 1, 120.0)]).unwrap();
        assert_eq!(s.times(), built.times());
        assert_eq!(s.rows(), built.rows());
        let e = s.hold(1.5, [0.0; 4]).unwrap_err();
        assert!(e.to_string().contains("before the last row"), "{e}");
        let e = s.hold(3.0, [f64::NAN, 0.0, 0.0, 0.0]).unwrap_err();
        assert_eq!(e.to_string(), "row 6: n_e_rpm = NaN is not finite");
        let before = [1.5, 2.0, 2.5].map(|t| s.at(t));
        s.drop_before(1.5);
        assert_eq!(s.times(), &[1.0, 2.0, 2.0]);
        assert_eq!([1.5, 2.0, 2.5].map(|t| s.at(t)), before);
    }

    #[test]
    fn step_builder() {
        let s =
            InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(1.0, 3, 65.0)]).unwrap();
        assert_eq!(s.at(0.999).u_vgt_pct, 75.0);
        assert_eq!(s.at(1.0).u_vgt_pct, 65.0);
        assert_eq!(s.at(100.0).u_vgt_pct, 65.0);
        assert_eq!(s.breakpoints(3), vec![(1.0, BreakKind::Jump)]);
    }
}
