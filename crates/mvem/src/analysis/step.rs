//! Step-response metrics of a sampled signal y(t): final change, DC gain and its sign,
//! non-minimum-phase (wrong-way) excursion, overshoot, rise time and settling time.
//!
//! All metrics are defined on the normalized progress `z(t) = (y(t) - y0) / (y_final - y0)`,
//! which starts at 0 and ends at 1 whatever the direction of the response:
//!
//! - **Final change** `y_final - y0` and **DC gain** `(y_final - y0) / du`; `y_final` is best
//!   taken from the steady state at the new input ([`crate::analysis::steady`]) rather than the
//!   last sample, so that a response that has not fully settled is still measured correctly.
//! - **Wrong-way excursion**: the minimum of `z` over every sample after the step, i.e. the
//!   largest excursion opposite to the final change anywhere in the response (value and time),
//!   not only before the first move: a response that first moves slightly the right way and
//!   then dips (u_vgt 75 -> 65 % at 1500 rpm, 110 mg, u_egr 80 %: lambda_O rises by 1.4 % of
//!   its final change, then falls 11 % below its start) is caught. The response counts as
//!   **non-minimum phase** when this excursion exceeds [`StepMetrics::THRESHOLD`] = 0.5 % of
//!   |final change| (above integration and sampling noise, below any wrong-way move a
//!   controller would notice). For a linear system an odd number of real right-half-plane
//!   zeros gives an initial wrong-way move; an even number (the lambda_O case: two) a later
//!   dip, which is why the whole response is searched. An underdamped response that swings
//!   back beyond its start also counts; [`Excursion::time`] tells them apart.
//! - **Overshoot** `max(z - 1, 0) * 100` % over the samples after the step (the largest
//!   excursion beyond the final value relative to |final change|).
//! - **Rise time** from the first crossing of `z = 0.1` to the first crossing of `z = 0.9`
//!   (linear interpolation between samples).
//! - **Settling time** after the step until `|z - 1|` stays within 0.02 (2 % band) for the rest
//!   of the record (linear interpolation at the last exit from the band).
//!
//! Extrema are taken at the samples (no interpolation): sample densely enough for the
//! accuracy you need (errors are O(dt^2) in value and O(dt) in time).

use std::fmt;

/// Sign of a DC gain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GainSign {
    /// The output moves in the same direction as the input.
    Positive,
    /// The output moves against the input.
    Negative,
}

impl fmt::Display for GainSign {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            GainSign::Positive => "positive",
            GainSign::Negative => "negative",
        })
    }
}

/// An extremum of the response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excursion {
    /// Signal value at the extremum (units of y).
    pub value: f64,
    /// Absolute time of the extremum \[s\].
    pub time: f64,
    /// Size relative to |final change| [-] (0.05 = 5 %), always >= 0.
    pub relative: f64,
}

/// Metrics of one step response (see the module documentation for the definitions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMetrics {
    /// Time of the input step \[s\].
    pub t_step: f64,
    /// Value before the step (units of y).
    pub y0: f64,
    /// Final value (units of y).
    pub y_final: f64,
    /// Input change du (units of the input).
    pub du: f64,
    /// Final change y_final - y0 (units of y).
    pub change: f64,
    /// DC gain change / du (units of y per unit of input).
    pub dc_gain: f64,
    /// Sign of the DC gain.
    pub gain_sign: GainSign,
    /// The largest excursion opposite to the final change anywhere after the step (`None` if it
    /// never goes the wrong way by more than [`StepMetrics::NOISE`]).
    pub wrong_way: Option<Excursion>,
    /// Whether the wrong-way excursion exceeds [`StepMetrics::THRESHOLD`] = 0.5 % of |final
    /// change| (non-minimum phase).
    pub non_minimum_phase: bool,
    /// Overshoot beyond the final value, % of |final change| (0 if none).
    pub overshoot_pct: f64,
    /// The sample furthest beyond the final value (`None` if the response never passes it).
    pub peak: Option<Excursion>,
    /// Rise time 10 % -> 90 % \[s\] (`None` if 90 % is never reached).
    pub rise_time: Option<f64>,
    /// Settling time into the 2 % band, measured from the step \[s\] (`None` if the last sample
    /// is outside the band).
    pub settling_time: Option<f64>,
}

/// Why metrics could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepError {
    /// Time and value arrays differ in length, or there is no sample after the step.
    #[error("step metrics: {0}")]
    BadData(&'static str),
    /// A value is NaN or infinite.
    #[error("step metrics: non-finite {what}")]
    NonFinite {
        /// Which quantity.
        what: &'static str,
    },
    /// The input does not change: nothing to normalize by.
    #[error("step metrics: zero {what}; the response has no direction")]
    Zero {
        /// "input change".
        what: &'static str,
    },
    /// The final value equals the initial value to [`StepMetrics::ZERO`] of its magnitude (e.g.
    /// W_egr where the EGR valve has no flow): the response has no direction, so no excursion,
    /// overshoot, rise or settling; the DC gain is `change / du` (0 or rounding of the steady
    /// states).
    #[error(
        "step metrics: zero final change ({} -> {}, DC gain {}); the response has no direction",
        crate::numerics::Num(*y0),
        crate::numerics::Num(*y_final),
        crate::numerics::Num(self.dc_gain())
    )]
    NoChange {
        /// Steady value before the step.
        y0: f64,
        /// Steady value after the step.
        y_final: f64,
        /// Input change (effective) the gain is per.
        du: f64,
    },
}

impl StepError {
    /// The DC gain of a [`StepError::NoChange`] response, `(y_final - y0) / du` (NaN for the
    /// other errors).
    pub fn dc_gain(&self) -> f64 {
        match self {
            // (+ 0.0: a zero change gives 0, not -0, for a negative du)
            Self::NoChange { y0, y_final, du } => (y_final - y0) / du + 0.0,
            _ => f64::NAN,
        }
    }
}

impl StepMetrics {
    /// Threshold for counting a wrong-way excursion as non-minimum phase: 0.5 % of |final
    /// change|.
    pub const THRESHOLD: f64 = 0.005;
    /// Settling band: 2 % of |final change|.
    pub const BAND: f64 = 0.02;
    /// A final change up to this fraction of max(|y0|, |y_final|) is zero (rounding of the
    /// steady states, e.g. a channel without gain where the EGR valve has no flow): no
    /// direction, no metrics.
    pub const ZERO: f64 = 1e-9;
    /// Wrong-way excursions up to this fraction of |final change| are rounding noise (not reported).
    pub const NOISE: f64 = 1e-9;

    /// Metrics of the samples `(t[i], y[i])` for a step of size `du` at `t_step`, from `y0` to
    /// `y_final`. Samples before `t_step` are ignored; `t` must be increasing.
    pub fn compute(
        t: &[f64],
        y: &[f64],
        t_step: f64,
        y0: f64,
        y_final: f64,
        du: f64,
    ) -> Result<Self, StepError> {
        if t.len() != y.len() {
            return Err(StepError::BadData("time and value arrays differ in length"));
        }
        for (what, v) in [
            ("step time", t_step),
            ("initial value", y0),
            ("final value", y_final),
            ("input change", du),
        ] {
            if !v.is_finite() {
                return Err(StepError::NonFinite { what });
            }
        }
        if t.iter().chain(y).any(|v| !v.is_finite()) {
            return Err(StepError::NonFinite { what: "sample" });
        }
        let change = y_final - y0;
        if du == 0.0 {
            return Err(StepError::Zero {
                what: "input change",
            });
        }
        if change.abs() <= Self::ZERO * y0.abs().max(y_final.abs()) {
            return Err(StepError::NoChange { y0, y_final, du });
        }
        let first = t.partition_point(|&ti| ti < t_step);
        let (t, y) = (&t[first..], &y[first..]);
        if t.is_empty() {
            return Err(StepError::BadData("no sample at or after the step time"));
        }
        let z: Vec<f64> = y.iter().map(|v| (v - y0) / change).collect();

        // Wrong way: minimum of z over the whole response after the step.
        let wrong_way = argmin(&z)
            .filter(|&i| -z[i] > Self::NOISE)
            .map(|i| Excursion {
                value: y[i],
                time: t[i],
                relative: -z[i],
            });
        let non_minimum_phase = wrong_way.is_some_and(|w| w.relative > Self::THRESHOLD);

        // Overshoot: maximum of z beyond 1.
        let peak = argmax(&z).filter(|&i| z[i] > 1.0).map(|i| Excursion {
            value: y[i],
            time: t[i],
            relative: z[i] - 1.0,
        });
        let overshoot_pct = peak.map_or(0.0, |p| p.relative * 100.0);

        // Rise time 10-90 %.
        let rise_time = match (crossing(t, &z, 0.1), crossing(t, &z, 0.9)) {
            (Some(a), Some(b)) => Some(b - a),
            _ => None,
        };

        // Settling: last exit from the band.
        let outside = |v: f64| (v - 1.0).abs() > Self::BAND;
        let settling_time = match z.iter().rposition(|&v| outside(v)) {
            None => Some(0.0),
            Some(k) if k + 1 == z.len() => None,
            Some(k) => {
                // interpolate the band edge between samples k (outside) and k+1 (inside)
                let edge = if z[k] > 1.0 {
                    1.0 + Self::BAND
                } else {
                    1.0 - Self::BAND
                };
                Some(interp(t[k], z[k], t[k + 1], z[k + 1], edge) - t_step)
            }
        };

        Ok(Self {
            t_step,
            y0,
            y_final,
            du,
            change,
            dc_gain: change / du,
            gain_sign: if change / du > 0.0 {
                GainSign::Positive
            } else {
                GainSign::Negative
            },
            wrong_way,
            non_minimum_phase,
            overshoot_pct,
            peak,
            rise_time,
            settling_time,
        })
    }
}

fn argmin(v: &[f64]) -> Option<usize> {
    (0..v.len()).min_by(|&a, &b| v[a].total_cmp(&v[b]))
}

fn argmax(v: &[f64]) -> Option<usize> {
    // first maximum (max_by returns the last of equal elements)
    (0..v.len()).rev().max_by(|&a, &b| v[a].total_cmp(&v[b]))
}

/// Time where the line through (t0, z0), (t1, z1) reaches `level`.
fn interp(t0: f64, z0: f64, t1: f64, z1: f64, level: f64) -> f64 {
    if z1 == z0 {
        t1
    } else {
        t0 + (level - z0) / (z1 - z0) * (t1 - t0)
    }
}

/// First time z reaches `level` from below (interpolated).
fn crossing(t: &[f64], z: &[f64], level: f64) -> Option<f64> {
    let k = z.iter().position(|&v| v >= level)?;
    if k == 0 {
        return Some(t[0]);
    }
    Some(interp(t[k - 1], z[k - 1], t[k], z[k], level))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of f on [0, t_end] every dt, shifted so that the step is at `t_step`.
    fn sample(f: impl Fn(f64) -> f64, t_step: f64, t_end: f64, dt: f64) -> (Vec<f64>, Vec<f64>) {
        let n = (t_end / dt).round() as usize;
        let t: Vec<f64> = (0..=n).map(|i| t_step + i as f64 * dt).collect();
        let y = t.iter().map(|&ti| f(ti - t_step)).collect();
        (t, y)
    }

    #[test]
    fn first_order() {
        // y = 2 + 3 (1 - e^{-t/tau}) for a unit input step: gain 3, no overshoot, no NMP,
        // rise time tau ln 9, settling time tau ln 50.
        let tau = 0.7;
        let (t, y) = sample(|s| 2.0 + 3.0 * (1.0 - (-s / tau).exp()), 1.0, 20.0, 1e-4);
        let m = StepMetrics::compute(&t, &y, 1.0, 2.0, 5.0, 1.0).unwrap();
        assert_eq!(m.change, 3.0);
        assert_eq!(m.dc_gain, 3.0);
        assert_eq!(m.gain_sign, GainSign::Positive);
        assert!(m.wrong_way.is_none() && !m.non_minimum_phase);
        assert_eq!(m.overshoot_pct, 0.0);
        assert!(m.peak.is_none());
        let rise = tau * 9f64.ln();
        assert!((m.rise_time.unwrap() - rise).abs() < 1e-6, "{m:?}");
        let settle = tau * 50f64.ln();
        assert!((m.settling_time.unwrap() - settle).abs() < 1e-6, "{m:?}");
    }

    #[test]
    fn a_response_without_change_keeps_its_values_and_zero_gain() {
        // a channel without flow (W_egr with the valve shut): y stays 0 through a step of -10
        let (t, y) = sample(|_| 0.0, 1.0, 5.0, 0.01);
        let e = StepMetrics::compute(&t, &y, 1.0, 0.0, 0.0, -10.0).unwrap_err();
        assert_eq!(
            e,
            StepError::NoChange {
                y0: 0.0,
                y_final: 0.0,
                du: -10.0
            }
        );
        // 0, not -0 (which JSON and the CLI would print as -0)
        assert!(e.dc_gain() == 0.0 && e.dc_gain().is_sign_positive());
        assert!(
            e.to_string()
                .contains("zero final change (0 -> 0, DC gain 0)"),
            "{e}"
        );
        // rounding of the steady states (1e-12 of the value) has a gain, but no direction
        let e = StepMetrics::compute(&t, &y, 1.0, 2.0, 2.0 + 2e-12, 0.5).unwrap_err();
        assert!((e.dc_gain() / 4e-12 - 1.0).abs() < 1e-3, "{e}");
        assert!(e.to_string().contains("DC gain 4.000"), "{e}");
        // no input change: no gain either
        let e = StepMetrics::compute(&t, &y, 1.0, 0.0, 1.0, 0.0).unwrap_err();
        assert!(matches!(e, StepError::Zero { .. }) && e.dc_gain().is_nan());
    }

    #[test]
    fn second_order_underdamped() {
        // y = 1 - e^{-zeta w t} / sqrt(1 - zeta^2) sin(w_d t + acos zeta):
        // overshoot exp(-zeta pi / sqrt(1 - zeta^2)) at t_p = pi / w_d.
        let (zeta, w): (f64, f64) = (0.3, 2.0);
        let wd = w * (1.0 - zeta * zeta).sqrt();
        let phi = zeta.acos();
        let f = |s: f64| {
            1.0 - (-zeta * w * s).exp() / (1.0 - zeta * zeta).sqrt() * (wd * s + phi).sin()
        };
        let (t, y) = sample(f, 0.0, 30.0, 1e-4);
        let m = StepMetrics::compute(&t, &y, 0.0, 0.0, 1.0, 1.0).unwrap();
        let os = (-zeta * std::f64::consts::PI / (1.0 - zeta * zeta).sqrt()).exp() * 100.0;
        assert!(
            (m.overshoot_pct - os).abs() < 1e-5,
            "{} vs {os}",
            m.overshoot_pct
        );
        let p = m.peak.unwrap();
        assert!((p.time - std::f64::consts::PI / wd).abs() < 2e-4, "{p:?}");
        assert!(!m.non_minimum_phase);
        // settling: inside the band afterwards, outside just before, and within the envelope bound
        let ts = m.settling_time.unwrap();
        let bound = (1.0 / (0.02 * (1.0 - zeta * zeta).sqrt())).ln() / (zeta * w);
        assert!(ts > 0.5 * bound && ts <= bound, "{ts} vs envelope {bound}");
        assert!((f(ts - 1e-3) - 1.0).abs() > 0.02 && (f(ts + 1e-3) - 1.0).abs() <= 0.02);
        for s in [ts + 0.01, ts + 1.0, ts + 5.0] {
            assert!((f(s) - 1.0).abs() <= 0.02);
        }
    }

    #[test]
    fn non_minimum_phase_response_with_negative_direction() {
        // g(s) = 1 - 3 e^{-s} + 2 e^{-2s}: g(0) = 0, g'(0) = -1, minimum -1/8 at s = ln(4/3),
        // then monotone to 1. Mirror it (y = 10 - 4 g) and drive it with du = +2, so the output
        // falls: gain -2, wrong-way excursion up to 10 + 0.5 = 10.5 (12.5 %).
        let g = |s: f64| 1.0 - 3.0 * (-s).exp() + 2.0 * (-2.0 * s).exp();
        let (t, y) = sample(|s| 10.0 - 4.0 * g(s), 2.0, 25.0, 1e-4);
        let m = StepMetrics::compute(&t, &y, 2.0, 10.0, 6.0, 2.0).unwrap();
        assert_eq!(m.dc_gain, -2.0);
        assert_eq!(m.gain_sign, GainSign::Negative);
        assert!(m.non_minimum_phase);
        let w = m.wrong_way.unwrap();
        assert!((w.value - 10.5).abs() < 1e-7, "{w:?}");
        assert!((w.relative - 0.125).abs() < 1e-7, "{w:?}");
        assert!((w.time - (2.0 + (4.0f64 / 3.0).ln())).abs() < 1e-4, "{w:?}");
        assert_eq!(m.overshoot_pct, 0.0);
        // rise: g = 0.1 and 0.9 with x = e^{-s}: 2x^2 - 3x + (1 - level) = 0
        let at = |level: f64| -((3.0 - (9.0 - 8.0 * (1.0 - level)).sqrt()) / 4.0f64).ln();
        let rise = at(0.9) - at(0.1);
        assert!(
            (m.rise_time.unwrap() - rise).abs() < 1e-6,
            "{m:?} vs {rise}"
        );
    }

    #[test]
    fn small_wrong_way_is_not_nmp() {
        let (t, y) = (vec![0.0, 1.0, 2.0, 3.0], vec![0.0, -0.003, 0.5, 1.0]);
        let m = StepMetrics::compute(&t, &y, 0.0, 0.0, 1.0, 1.0).unwrap();
        let w = m.wrong_way.unwrap();
        assert_eq!((w.time, w.value, w.relative), (1.0, -0.003, 0.003));
        assert!(!m.non_minimum_phase);
    }

    #[test]
    fn late_wrong_way_excursion_counts() {
        // A 0.3 % initial dip, a move the right way, an overshoot, then a swing 20 % below the
        // start at t = 4: the wrong-way excursion is the late one, and it is NMP.
        let (t, y) = (
            vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            vec![0.0, -0.003, 0.5, 1.5, -0.2, 1.01, 1.0],
        );
        let m = StepMetrics::compute(&t, &y, 0.0, 0.0, 1.0, 1.0).unwrap();
        let w = m.wrong_way.unwrap();
        assert_eq!((w.time, w.value), (4.0, -0.2));
        assert!((w.relative - 0.2).abs() < 1e-15);
        assert!(m.non_minimum_phase);
        assert!((m.overshoot_pct - 50.0).abs() < 1e-12);
        assert_eq!(m.peak.unwrap().time, 3.0);
        // last exit from the band between t = 4 (z = -0.2) and t = 5 (z = 1.01)
        let ts = 4.0 + (0.98 + 0.2) / 1.21;
        assert!((m.settling_time.unwrap() - ts).abs() < 1e-12);
        // rise: z = 0.1 between t = 1 and 2, z = 0.9 between t = 2 and 3
        let rise = (2.0 + 0.4) - (1.0 + 0.103 / 0.503);
        assert!((m.rise_time.unwrap() - rise).abs() < 1e-12);
    }

    #[test]
    fn bad_input_is_an_error() {
        let t = [0.0, 1.0];
        assert!(StepMetrics::compute(&t, &[0.0], 0.0, 0.0, 1.0, 1.0).is_err());
        assert!(StepMetrics::compute(&t, &[0.0, 1.0], 0.0, 1.0, 1.0, 1.0).is_err());
        assert!(StepMetrics::compute(&t, &[0.0, 1.0], 0.0, 0.0, 1.0, 0.0).is_err());
        assert!(StepMetrics::compute(&t, &[0.0, f64::NAN], 0.0, 0.0, 1.0, 1.0).is_err());
        assert!(StepMetrics::compute(&t, &[0.0, 1.0], 5.0, 0.0, 1.0, 1.0).is_err());
        // unsettled: last sample outside the band
        let m = StepMetrics::compute(&t, &[0.0, 0.5], 0.0, 0.0, 1.0, 1.0).unwrap();
        assert_eq!(m.settling_time, None);
        assert_eq!(m.rise_time, None);
    }
}
