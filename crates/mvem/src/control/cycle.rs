//! Drive cycles for the closed loop: the engine's mapping curve, the WHTC denormalization of
//! UN GTR No. 4 and speed/torque demands.
//!
//! The mapping curve is this model's full-load torque over speed with the smoke limit: at each
//! speed of the parameter set's `[input_saturation] n_e` range (default the authors' 500-2000
//! rpm) the largest u_delta (at most the top of its `u_delta` range, default 250 mg) whose
//! steady state has lambda_O >= the limit, with the EGR valve closed and the VGT at
//! [`MappingOptions::u_vgt`]; the motoring curve is the steady torque at the minimum fuel (the
//! bottom of the `u_delta` range, default 1 mg, EGR closed, VGT open). So the closed loop
//! follows the engine the parameter set describes, not the authors'. From it the regulation's
//! reference speeds (n_idle given; [`super::drive::run_cycle`] takes the bottom of the speed
//! range): n_lo (lowest speed at 55 % of the maximum power), n_hi (highest speed at 70 %),
//! n_pref (where the integral of the full-load torque from n_idle reaches 51 % of its value up to
//! n_95h, the highest speed at 95 % power), and the denormalized speed
//! `n = n_norm/100 (0.45 n_lo + 0.45 n_pref + 0.1 n_hi - n_idle) 2.0327 + n_idle`,
//! torque `M = M_norm/100 M_max(n)` and, for the "m" points, the motoring torque.

use super::ControlError;
use crate::analysis::steady::{steady_state, steady_state_with, SteadyOptions};
use crate::dispatch;
use crate::io::csv_columns::{file_line, header_line, Dialect};
use crate::model::{AnyModel, Drive, Signals};
use crate::numerics::Num;
use crate::sim::input::{check_time_order, ScheduleError};

/// How the mapping curve is computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MappingOptions {
    /// Smoke limit: smallest steady lambda_O at full load [-] (default 1.2).
    pub lambda_min: f64,
    /// VGT position at full load [%] (default 35).
    pub u_vgt: f64,
    /// Speed grid step \[rpm\] (default 100).
    pub dn: f64,
}

impl Default for MappingOptions {
    fn default() -> Self {
        Self {
            lambda_min: 1.2,
            u_vgt: 35.0,
            dn: 100.0,
        }
    }
}

/// Full-load (smoke-limited) and motoring torque over speed.
#[derive(Debug, Clone, PartialEq)]
pub struct MappingCurve {
    /// Speeds \[rpm\].
    pub n_e: Vec<f64>,
    /// Full-load fuel u_delta [mg/cycle/cylinder].
    pub u_full: Vec<f64>,
    /// Full-load torque \[Nm\].
    pub m_max: Vec<f64>,
    /// Motoring torque at the minimum fuel \[Nm\] (negative: friction and pumping).
    pub m_motor: Vec<f64>,
    /// Fuel range of the parameter set's input saturation [mg/cycle/cylinder]: the motoring
    /// fuel and the largest full-load fuel.
    pub u_delta_range: (f64, f64),
    /// Options used.
    pub opts: MappingOptions,
}

/// Linear interpolation in a sorted table, held constant outside.
pub fn interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    interp_at(xs, ys, x, xs.partition_point(|&v| v <= x))
}

/// [`interp`] with `k = xs.partition_point(|&v| v <= x)` already known.
fn interp_at(xs: &[f64], ys: &[f64], x: f64, k: usize) -> f64 {
    let n = xs.len();
    // (at the first time itself the right value: a step there, two rows at xs[0], is taken)
    if x < xs[0] {
        return ys[0];
    }
    if x >= xs[n - 1] {
        return ys[n - 1];
    }
    let i = k.min(n - 1);
    let (x0, x1) = (xs[i - 1], xs[i]);
    ys[i - 1] + (ys[i] - ys[i - 1]) * (x - x0) / (x1 - x0)
}

/// Steady signals of `model` at `d` (warm-started from `guess` when given).
pub(crate) fn steady_signals(
    model: &AnyModel,
    d: &Drive,
    guess: &mut Option<Vec<f64>>,
) -> Result<Signals, String> {
    dispatch!(model, m => {
        let g = guess.as_ref().and_then(|g| g.as_slice().try_into().ok());
        let ss = match g {
            Some(g) => steady_state_with(m, d, Some(&g), &SteadyOptions::default())
                .or_else(|_| steady_state(m, d)),
            None => steady_state(m, d),
        }
        .map_err(|e| e.to_string())?;
        *guess = Some(ss.x.to_vec());
        Ok(ss.signals)
    })
}

impl MappingCurve {
    /// Compute the curve of `model` over the speed and fuel ranges of its parameter set's
    /// `[input_saturation]` (see the module documentation).
    pub fn compute(model: &AnyModel, opts: MappingOptions) -> Result<Self, ControlError> {
        let sat = dispatch!(model, m => crate::model::Model::params(m).input_saturation.clone());
        let [lo, hi] = sat.n_e;
        let [u_min, u_max] = sat.u_delta;
        if !(opts.dn.is_finite() && opts.dn > 0.0) {
            return Err(ControlError::Setup(format!(
                "mapping curve: speed step {} rpm must be > 0",
                opts.dn
            )));
        }
        let k = ((hi - lo) / opts.dn).round().max(1.0) as usize;
        let mut c = MappingCurve {
            n_e: Vec::new(),
            u_full: Vec::new(),
            m_max: Vec::new(),
            m_motor: Vec::new(),
            u_delta_range: (u_min, u_max),
            opts,
        };
        let setup = |e: String| ControlError::Setup(format!("mapping curve: {e}"));
        let mut guess = None;
        let mut u = u_max;
        for i in 0..=k {
            let n = lo + (hi - lo) * i as f64 / k as f64;
            // lambda_O ~ air / fuel and the air changes slowly with the fuel: the fixed-point
            // iteration u <- u lambda_O(u) / lambda_min converges in a few steps
            let mut s = Signals::default();
            for _ in 0..30 {
                let d = Drive::new(n, u, 0.0, opts.u_vgt);
                s = steady_signals(model, &d, &mut guess).map_err(setup)?;
                let u_new = (u * s.lambda_o / opts.lambda_min).clamp(u_min, u_max);
                if (u_new - u).abs() < 1e-4 * u {
                    break;
                }
                if u >= u_max && u_new >= u_max {
                    break;
                }
                u = u_new;
            }
            let mut g0 = None;
            let s0 =
                steady_signals(model, &Drive::new(n, u_min, 0.0, 100.0), &mut g0).map_err(setup)?;
            c.n_e.push(n);
            c.u_full.push(u);
            c.m_max.push(s.m_e);
            c.m_motor.push(s0.m_e);
        }
        Ok(c)
    }

    /// Speed range of the curve \[rpm\] (the parameter set's `[input_saturation] n_e`).
    pub fn n_e_range(&self) -> (f64, f64) {
        (self.n_e[0], *self.n_e.last().unwrap())
    }

    /// Motoring (minimum) fuel [mg/cycle/cylinder].
    pub fn u_delta_min(&self) -> f64 {
        self.u_delta_range.0
    }

    /// Full-load torque at `n` \[Nm\].
    pub fn m_max_at(&self, n: f64) -> f64 {
        interp(&self.n_e, &self.m_max, n)
    }

    /// Full-load fuel at `n` [mg/cycle/cylinder].
    pub fn u_full_at(&self, n: f64) -> f64 {
        interp(&self.n_e, &self.u_full, n)
    }

    /// What limits the full-load torque at `n`, in words: the fuel cap (the top of the
    /// `u_delta` range) where the full-load fuel reaches it, else the smoke limit lambda_O.
    pub fn limit_at(&self, n: f64) -> String {
        let u_max = self.u_delta_range.1;
        if self.u_full_at(n) >= u_max * (1.0 - 1e-6) {
            format!(
                "fuel-limited at the top of the u_delta range, {} mg/cycle",
                Num(u_max)
            )
        } else {
            format!(
                "smoke-limited at lambda_O = {}, {:.1} mg/cycle",
                Num(self.opts.lambda_min),
                self.u_full_at(n)
            )
        }
    }

    /// Motoring torque at `n` \[Nm\].
    pub fn m_motor_at(&self, n: f64) -> f64 {
        interp(&self.n_e, &self.m_motor, n)
    }

    /// Largest full-load torque \[Nm\].
    pub fn m_peak(&self) -> f64 {
        self.m_max.iter().cloned().fold(f64::MIN, f64::max)
    }

    /// The regulation's reference speeds from this curve (n_idle given).
    pub fn reference_speeds(&self, n_idle: f64) -> ReferenceSpeeds {
        // fine resampling of power P = M omega
        let (lo, hi) = (self.n_e[0], *self.n_e.last().unwrap());
        let m = 3001;
        let ns: Vec<f64> = (0..m)
            .map(|i| lo + (hi - lo) * i as f64 / (m - 1) as f64)
            .collect();
        let p: Vec<f64> = ns
            .iter()
            .map(|&n| self.m_max_at(n) * n * std::f64::consts::PI / 30.0)
            .collect();
        let p_max = p.iter().cloned().fold(f64::MIN, f64::max);
        let first_at = |f: f64| ns[p.iter().position(|&v| v >= f * p_max).unwrap_or(0)];
        let last_at = |f: f64| ns[p.iter().rposition(|&v| v >= f * p_max).unwrap_or(m - 1)];
        let n_lo = first_at(0.55);
        let n_hi = last_at(0.70);
        let n_95h = last_at(0.95);
        // n_pref: integral of M_max from n_idle reaches 51 % of the integral up to n_95h
        let mut cum = vec![0.0; m];
        for i in 1..m {
            let inside = |n: f64| n >= n_idle && n <= n_95h;
            let a = if inside(ns[i - 1]) && inside(ns[i]) {
                0.5 * (self.m_max_at(ns[i - 1]) + self.m_max_at(ns[i])) * (ns[i] - ns[i - 1])
            } else {
                0.0
            };
            cum[i] = cum[i - 1] + a;
        }
        let total = cum[m - 1];
        let n_pref = ns[cum.iter().position(|&v| v >= 0.51 * total).unwrap_or(0)];
        ReferenceSpeeds {
            n_idle,
            n_lo,
            n_pref,
            n_hi,
            n_95h,
            p_max,
        }
    }
}

/// The reference speeds of UN GTR No. 4 (section 7.4.2) \[rpm\] and the maximum power \[W\].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReferenceSpeeds {
    /// Idle speed \[rpm\].
    pub n_idle: f64,
    /// Lowest speed with 55 % of the maximum power \[rpm\].
    pub n_lo: f64,
    /// Preferred speed \[rpm\].
    pub n_pref: f64,
    /// Highest speed with 70 % of the maximum power \[rpm\].
    pub n_hi: f64,
    /// Highest speed with 95 % of the maximum power \[rpm\].
    pub n_95h: f64,
    /// Maximum power on the mapping curve \[W\].
    pub p_max: f64,
}

impl ReferenceSpeeds {
    /// Denormalize a WHTC speed [% ] to rpm.
    pub fn denormalize(&self, n_norm_pct: f64) -> f64 {
        n_norm_pct / 100.0
            * (0.45 * self.n_lo + 0.45 * self.n_pref + 0.1 * self.n_hi - self.n_idle)
            * 2.0327
            + self.n_idle
    }
}

/// A demand at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemandPoint {
    /// Speed \[rpm\].
    pub n_e: f64,
    /// Torque \[Nm\].
    pub m_ref: f64,
    /// Motoring point.
    pub motoring: bool,
}

/// A speed/torque demand over time: linear between rows; motoring at a motoring row and between
/// two of them. Between a motoring row and a fired one the torque runs linearly from the
/// motoring torque to the fired row's (UN GTR No. 4 interpolates its 1 Hz reference so), and the
/// engine is fired there: it follows that rising demand instead of being held at the minimum
/// fuel until the fired row (up to a second of a tip-in out of motoring, e.g. 1840 Nm behind the
/// demand at t = 1238 s of the WHTC, before).
#[derive(Debug, Clone, PartialEq)]
pub struct Demand {
    t: Vec<f64>,
    n_e: Vec<f64>,
    m_ref: Vec<f64>,
    motoring: Vec<bool>,
    /// The file's line (1-based) of each row, for a demand read from a file
    /// ([`Demand::with_lines`]): the checks name it instead of the row's number, which differs
    /// from the line by the header, a units row, comments and blank lines.
    lines: Option<Vec<usize>>,
}

impl Demand {
    /// Build from rows; checks finite values, the order of the times (not decreasing, two rows
    /// at one time a step where the demand jumps, no third: [`check_time_order`]) and at least
    /// two rows (the message names the row, 1-based). The speeds are checked against an engine's range
    /// by [`Demand::check_speeds`].
    pub fn new(
        t: Vec<f64>,
        n_e: Vec<f64>,
        m_ref: Vec<f64>,
        motoring: Vec<bool>,
    ) -> Result<Self, ControlError> {
        let bad = |s: String| Err(ControlError::Demand(s));
        if n_e.len() != t.len() || m_ref.len() != t.len() || motoring.len() != t.len() {
            return bad(format!(
                "the columns have different lengths: t {}, n_e {}, M_ref {}, motoring {} (one \
                 value per row in each)",
                t.len(),
                n_e.len(),
                m_ref.len(),
                motoring.len()
            ));
        }
        if t.len() < 2 {
            return bad("needs at least two rows of (t, n_e, M_ref)".into());
        }
        for i in 0..t.len() {
            for (name, v) in [("t", t[i]), ("n_e", n_e[i]), ("M_ref", m_ref[i])] {
                if !v.is_finite() {
                    return bad(format!("row {}: {name} = {v} is not finite", i + 1));
                }
            }
            // (two rows at one time are a step, as in an input schedule)
            if let Err(ScheduleError::NonMonotonic {
                row,
                t,
                prev,
                detail,
            }) = check_time_order(&t, i)
            {
                return bad(format!(
                    "row {}: time {t} s is not monotonic (previous {prev} s){detail}",
                    row + 1
                ));
            }
        }
        Ok(Self {
            t,
            n_e,
            m_ref,
            motoring,
            lines: None,
        })
    }

    /// The same demand with the file's line (1-based) of each row, named by the checks
    /// ([`Demand::check_speeds`], [`Demand::check_feasible`], [`Demand::below_motoring`]) as
    /// "line L" instead of "row i". `lines` must have one entry per row (else it is ignored).
    pub fn with_lines(mut self, lines: Vec<usize>) -> Self {
        if lines.len() == self.t.len() {
            self.lines = Some(lines);
        }
        self
    }

    /// Where row `i` (0-based) is: "line L" of the file it was read from, else "row i+1".
    fn place(&self, i: usize) -> String {
        match &self.lines {
            Some(l) => format!("line {}", l[i]),
            None => format!("row {}", i + 1),
        }
    }

    /// The demand up to `t_end` \[s\]: its rows up to `t_end` (both rows of a step), then the
    /// demand at `t_end` where no row is there (linear at the cut).
    pub fn until(&self, t_end: f64) -> Result<Self, ControlError> {
        let k = self.t.partition_point(|&v| v <= t_end);
        let mut t = self.t[..k].to_vec();
        let mut n_e = self.n_e[..k].to_vec();
        let mut m_ref = self.m_ref[..k].to_vec();
        let mut motoring = self.motoring[..k].to_vec();
        let mut lines = self.lines.as_ref().map(|l| l[..k].to_vec());
        if t.last() != Some(&t_end) {
            let p = self.at(t_end);
            t.push(t_end);
            n_e.push(p.n_e);
            m_ref.push(p.m_ref);
            motoring.push(p.motoring);
            // (the cut lies before the next row: named by that row's line)
            if let (Some(l), Some(all)) = (lines.as_mut(), self.lines.as_ref()) {
                l.push(all[k.min(all.len() - 1)]);
            }
        }
        let d = Self::new(t, n_e, m_ref, motoring)?;
        Ok(match lines {
            Some(l) => d.with_lines(l),
            None => d,
        })
    }

    /// First and last time \[s\].
    pub fn span(&self) -> (f64, f64) {
        (self.t[0], *self.t.last().unwrap())
    }

    /// Row times \[s\].
    pub fn times(&self) -> &[f64] {
        &self.t
    }

    /// The demand at `t`.
    pub fn at(&self, t: f64) -> DemandPoint {
        // one search for the three columns (the loop asks every sample)
        let k = self.t.partition_point(|&v| v <= t);
        let i = k.max(1) - 1;
        // on the row itself, before the first or after the last row: that row's flag; between
        // rows: motoring only between two motoring rows
        let between = k > 0 && k < self.t.len() && t > self.t[i];
        DemandPoint {
            n_e: interp_at(&self.t, &self.n_e, t, k),
            m_ref: interp_at(&self.t, &self.m_ref, t, k),
            motoring: self.motoring[i] && (!between || self.motoring[i + 1]),
        }
    }

    /// Check that every speed lies in `range` \[rpm\] (the engine's, [`MappingCurve::n_e_range`];
    /// the message names the row, 1-based, or the file's line ([`Demand::with_lines`]), and its
    /// time).
    pub fn check_speeds(&self, range: (f64, f64)) -> Result<(), ControlError> {
        let (lo, hi) = range;
        match self.n_e.iter().position(|n| !(lo..=hi).contains(n)) {
            None => Ok(()),
            Some(i) => Err(ControlError::Demand(format!(
                "{} (t = {} s): speed {} rpm is outside the model's range [{lo}, {hi}] rpm \
                 (the parameter set's [input_saturation] n_e)",
                self.place(i),
                Num(self.t[i]),
                Num(self.n_e[i])
            ))),
        }
    }

    /// Check that the engine can follow: torque at most `tol` above the full-load curve and,
    /// at fired points, at least the motoring torque (the message names the row and time).
    pub fn check_feasible(&self, curve: &MappingCurve, tol: f64) -> Result<(), ControlError> {
        for i in 0..self.t.len() {
            let m_max = curve.m_max_at(self.n_e[i]);
            if self.m_ref[i] > m_max * (1.0 + tol) {
                return Err(ControlError::Demand(format!(
                    "{} (t = {} s): torque {} Nm at {:.0} rpm is above the engine's full-load torque {:.1} Nm ({}); the engine cannot follow this demand",
                    self.place(i),
                    Num(self.t[i]),
                    Num((self.m_ref[i] * 10.0).round() / 10.0),
                    self.n_e[i],
                    m_max,
                    curve.limit_at(self.n_e[i])
                )));
            }
        }
        Ok(())
    }

    /// The note on fired rows whose torque is below the motoring torque (the engine at its
    /// minimum fuel cannot brake harder; the controller gives the minimum fuel there): how
    /// many, and the first's row, time, speed, torque and motoring torque. `None`: none.
    pub fn below_motoring(&self, curve: &MappingCurve) -> Option<String> {
        let below: Vec<usize> = (0..self.t.len())
            .filter(|&i| !self.motoring[i] && self.m_ref[i] < curve.m_motor_at(self.n_e[i]))
            .collect();
        let &i = below.first()?;
        Some(format!(
            "{} row(s) of the demand ask for less torque than the engine's motoring torque (at \
             the minimum fuel; the engine gives that instead), the first {} (t = {} s): {} Nm \
             at {:.0} rpm, motoring torque {:.1} Nm",
            below.len(),
            self.place(i),
            Num(self.t[i]),
            Num(self.m_ref[i]),
            self.n_e[i],
            curve.m_motor_at(self.n_e[i])
        ))
    }
}

/// A normalized cycle of UN GTR No. 4 (the WHTC, or any table normalized the same way,
/// [`parse_normalized_table`]) denormalized for an engine: the speed by
/// [`ReferenceSpeeds::denormalize`], clamped into the engine's speed range; the torque as the
/// percentage of the full-load torque at that speed, the motoring torque at the "m" rows.
/// `table`: (time \[s\], speed [%], torque [%] or None for "m").
pub fn whtc_demand(
    table: &[NormalizedRow],
    curve: &MappingCurve,
    speeds: &ReferenceSpeeds,
) -> Result<Demand, ControlError> {
    let (mut t, mut n, mut m, mut mot) = (vec![], vec![], vec![], vec![]);
    for &(ti, n_pct, m_pct) in table {
        let (lo, hi) = curve.n_e_range();
        let ne = speeds.denormalize(n_pct).clamp(lo, hi);
        t.push(ti);
        n.push(ne);
        match m_pct {
            Some(p) => {
                m.push(p / 100.0 * curve.m_max_at(ne));
                mot.push(false);
            }
            None => {
                m.push(curve.m_motor_at(ne));
                mot.push(true);
            }
        }
    }
    Demand::new(t, n, m, mot)
}

/// One row of a normalized cycle (UN GTR No. 4): time \[s\], speed [%], torque [%] (`None`:
/// motoring, "m").
pub type NormalizedRow = (f64, f64, Option<f64>);

/// Highest normalized speed accepted [%] (the WHTC reaches 100 %; a larger value is most likely
/// a speed in rpm in a file taken for a normalized one).
pub const MAX_SPEED_PCT: f64 = 120.0;

/// How a cycle table separates its fields, from its header: the CSV dialect ([`Dialect::of`]:
/// `;` or tab with decimal commas allowed, else `,`), whose fields may be quoted (`"1,5"`, read
/// by the csv crate), or runs of blanks when the header has no comma either (as
/// `Time Speed Torque`; decimal commas allowed; no quoting: a quote is refused). `#` starts a
/// comment line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableFields {
    dialect: Dialect,
    blanks: bool,
}

/// A table's rows that are neither blank nor comments, each with its 1-based line in the text and
/// its fields (trimmed, unquoted).
pub type TableRows = Vec<(usize, Vec<String>)>;

impl TableFields {
    /// The separation of `text`'s fields, read off its header.
    pub fn of(text: &str) -> Self {
        let dialect = Dialect::of(text, Some(b'#'));
        let blanks = dialect.delimiter == b',' && !header_line(text, Some(b'#')).contains(',');
        Self {
            dialect: Dialect {
                decimal_comma: dialect.decimal_comma || blanks,
                ..dialect
            },
            blanks,
        }
    }

    /// Every row of `text` that is neither blank nor a comment, split into its fields. A
    /// delimited table is read by the csv crate (quoted fields unquoted, a quoted field may hold
    /// the separator); in a blank-separated one a field with a quote is refused, naming its line.
    pub fn rows(&self, text: &str) -> Result<TableRows, String> {
        let mut out = Vec::new();
        if self.blanks {
            for (i, line) in text.lines().enumerate() {
                let f: Vec<String> = line.split_whitespace().map(str::to_string).collect();
                if f.first().is_none_or(|x| x.starts_with('#')) {
                    continue;
                }
                if let Some(q) = f.iter().find(|x| x.contains('"')) {
                    return Err(format!(
                        "line {}: field {q} is quoted, but the fields are separated by blanks, \
                         where quotes are not read (separate them by tabs, semicolons or commas \
                         to quote a field)",
                        i + 1
                    ));
                }
                out.push((i + 1, f));
            }
            return Ok(out);
        }
        let mut rdr = csv::ReaderBuilder::new()
            .delimiter(self.dialect.delimiter)
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        for rec in rdr.records() {
            let rec = rec.map_err(|e| {
                let line = e.position().map(|p| file_line(text, p, Some(b'#')));
                format!("line {}: {e}", line.map_or("?".into(), |l| l.to_string()))
            })?;
            let f: Vec<String> = rec.iter().map(str::to_string).collect();
            // a line of blanks, or a comment indented by blanks
            if f.iter().all(String::is_empty) || f[0].starts_with('#') {
                continue;
            }
            let line = rec.position().map_or(0, |p| file_line(text, p, Some(b'#')));
            out.push((line, f));
        }
        Ok(out)
    }

    /// A field as a number ([`Dialect::number`]).
    pub fn number(&self, field: &str) -> Option<f64> {
        self.dialect.number(field)
    }
}

/// The header fields of a cycle table (its first row that is neither blank nor a `#` comment),
/// split as its rows are ([`TableFields::rows`]; empty if the text has no row or cannot be
/// split).
pub fn header_fields(text: &str) -> Vec<String> {
    let fields = TableFields::of(text);
    let first = header_line(text, Some(b'#'));
    fields
        .rows(first)
        .ok()
        .and_then(|r| r.into_iter().next())
        .map_or_else(Vec::new, |(_, f)| f)
}

/// A header name without its unit in brackets, lower case ("Speed [%]" -> "speed").
pub fn bare_name(field: &str) -> String {
    crate::io::csv_columns::split_unit(field)
        .name
        .trim()
        .to_ascii_lowercase()
}

/// Whether a header row names the columns of a normalized cycle (a "speed" and a "torque"
/// column, as `data/whtc_normalized.tsv`: `Time Speed Torque`).
pub fn is_normalized_header(fields: &[String]) -> bool {
    let names: Vec<String> = fields.iter().map(|f| bare_name(f)).collect();
    names.iter().any(|n| n.contains("speed")) && names.iter().any(|n| n.contains("torque"))
}

/// Parse a normalized cycle as UN GTR No. 4 publishes them (the WHTC, the WHSC's ramped modes, or
/// a user's own cycle normalized the same way): a header naming a time, a speed and a torque
/// column (in any order: "t" or a name starting with "time", the names containing "speed" and
/// "torque"; units in brackets after a name are ignored; without a header the first three
/// columns in that order), an optional units row
/// (the speed's and torque's units must be %), then one row per time: time \[s\], speed [%] in
/// [0, [`MAX_SPEED_PCT`]], torque [%] in [0, 100] or "m" for motoring. Fields are separated by
/// tabs, semicolons, commas or blanks, as the header is ([`TableFields`]), and may be quoted
/// except between blanks; every row has the header's number of fields (three without a header):
/// an extra field is refused, not ignored. `#` starts a comment line. Errors name the line
/// (1-based); times must not decrease, and two rows at one time are a step (the demand jumps
/// there; a third row at that time is refused).
pub fn parse_normalized_table(text: &str) -> Result<Vec<NormalizedRow>, String> {
    let fields = TableFields::of(text);
    let mut out: Vec<NormalizedRow> = Vec::new();
    let mut cols = [0usize, 1, 2];
    // the header's line and number of fields (without a header: 3 fields)
    let mut header: Option<(usize, usize)> = None;
    let mut units_checked = false;
    for (line, f) in fields.rows(text)? {
        // every row has the header's fields: an extra one is refused, not ignored
        if let Some((h_line, width)) = header.filter(|h| h.1 != f.len()) {
            let more = match f.get(width..) {
                Some(extra) if extra.iter().all(String::is_empty) => {
                    " (a separator at the end of the line?)".to_string()
                }
                Some(extra) => format!(": extra {}", extra.join(", ")),
                None => String::new(),
            };
            return Err(format!(
                "line {line}: expected {width} fields as the header on line {h_line} names, \
                 found {}{more}",
                f.len()
            ));
        }
        let numeric = fields.number(&f[0]).is_some();
        if !numeric && out.is_empty() {
            if header.is_none() {
                header = Some((line, f.len()));
                let names: Vec<String> = f.iter().map(|x| bare_name(x)).collect();
                let find = |pred: &dyn Fn(&str) -> bool, what: &str| {
                    names.iter().position(|n| pred(n)).ok_or_else(|| {
                        format!(
                            "line {line}: no {what} column in the header ({}); a normalized \
                             cycle has time [s], speed [%] and torque [%] columns",
                            f.join(", ")
                        )
                    })
                };
                cols = [
                    find(&|n| n == "t" || n.starts_with("time"), "time")?,
                    find(&|n| n.contains("speed"), "speed")?,
                    find(&|n| n.contains("torque"), "torque")?,
                ];
            } else if !units_checked {
                units_checked = true;
                for (k, what) in [(1, "speed"), (2, "torque")] {
                    let unit = f.get(cols[k]).map_or("", String::as_str);
                    if !unit.is_empty() && unit != "%" {
                        return Err(format!(
                            "line {}: the {what} column's unit is '{unit}', not %: this reads \
                             normalized cycles only (for speeds in rpm and torques in Nm give \
                             the columns t, n_e, M_ref)",
                            line
                        ));
                    }
                }
            } else {
                return Err(format!(
                    "line {}: '{}' is not a number (a third row of names?)",
                    line, f[0]
                ));
            }
            continue;
        }
        if header.is_none() && f.len() != 3 {
            return Err(format!(
                "line {line}: expected 3 fields (time, speed, torque; no header), found {}",
                f.len()
            ));
        }
        let num = |s: &str, what: &str| {
            fields
                .number(s)
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("line {}: {what} '{s}' is not a number", line))
        };
        let t = num(&f[cols[0]], "time")?;
        let n = num(&f[cols[1]], "speed")?;
        if !(0.0..=MAX_SPEED_PCT).contains(&n) {
            return Err(format!(
                "line {}: speed {n} % is outside [0, {MAX_SPEED_PCT}] % (normalized speeds are \
                 percent; for speeds in rpm give the columns t, n_e, M_ref)",
                line
            ));
        }
        let tq = f[cols[2]].as_str();
        let m = if tq.eq_ignore_ascii_case("m") {
            None
        } else {
            let v = num(tq, "torque")?;
            if !(0.0..=100.0).contains(&v) {
                return Err(format!(
                    "line {}: torque {v} % is outside [0, 100] % (motoring: \"m\")",
                    line
                ));
            }
            Some(v)
        };
        // two rows at one time are a step, as in a demand or an input file
        // ([`check_time_order`]): the last two rows' times and this one
        let k = out.len().min(2);
        let mut times = [0.0; 3];
        for (slot, row) in times.iter_mut().zip(&out[out.len() - k..]) {
            *slot = row.0;
        }
        times[k] = t;
        if let Err(ScheduleError::NonMonotonic { prev, detail, .. }) =
            check_time_order(&times[..=k], k)
        {
            return Err(format!(
                "line {line}: time {t} s is not monotonic (previous {prev} s){detail}"
            ));
        }
        out.push((t, n, m));
    }
    if out.len() < 2 {
        return Err("needs at least two rows (time, speed, torque)".into());
    }
    Ok(out)
}

/// The normalized WHTC table shipped with the crate (`data/whtc_normalized.tsv`).
pub const WHTC_NORMALIZED: &str = include_str!("../../../../data/whtc_normalized.tsv");
