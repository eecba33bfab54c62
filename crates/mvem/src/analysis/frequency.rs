//! Frequency response of the linearized model with the actuator transport delays **exact**:
//! the Bode diagram of every input-output channel at an operating point.
//!
//! The continuous linearization ([`super::linearize`], without Padé states) is that of the
//! undelayed system. Its input columns are split ([`super::discrete::delay_split`]) into the
//! current commands' part and the delayed copies' part g (u_egr(t - tau_degr), u_vgt(t -
//! tau_dvgt) drive only the actuator states, eqs (40), (41), (57)); a delay is the factor
//! e^(-j w tau) in the frequency domain, so
//!
//! ```text
//! G(j w) = C (j w I - A)^-1 (B_now + g e^(-j w tau)) + D_now + g_d e^(-j w tau)
//! ```
//!
//! with no approximation of the delays (a Padé model, [`frequency_response_rational`], matches
//! it only while w tau is small). Units: output unit per input unit (e.g. kg/s per % for
//! u_vgt -> W_c); the phase in degrees, continuous from its value in (-180, 180] at the lowest
//! frequency: it is followed on an internal grid at most 5 % apart in f and pi/8 of the longest
//! delay's phase apart, so the caller's spacing does not matter (three points at 0.1, 1 and
//! 10 Hz get the phases of a fine grid). At f -> 0 the response is the DC gain
//! (C (-A)^-1 B + D).

use super::discrete::{delay_split, DelaySplit};
use super::linearize::{converged, linearize, LinearModel, LinearizeError, LinearizeOptions};
use crate::model::{Drive, Model};
use nalgebra::{Complex, DMatrix, DVector};

/// Most frequencies of one response.
pub const MAX_POINTS: usize = 100_000;

/// The frequency response of the linear model at an operating point.
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyResponse {
    /// Frequencies \[Hz\], strictly increasing.
    pub f_hz: Vec<f64>,
    /// Input names (`u_delta`, `u_egr`, `u_vgt`, `n_e`).
    pub input_names: Vec<String>,
    /// Output names.
    pub output_names: Vec<String>,
    /// `g[k]`: the complex gains at `f_hz[k]` (outputs x inputs; output unit per input unit).
    pub g: Vec<DMatrix<Complex<f64>>>,
    /// `phase_deg[k]`: their phases \[deg\], continuous along the frequencies (followed on a grid
    /// fine enough for the delays and the poles whatever the spacing of `f_hz`), the first in
    /// (-180, 180].
    pub phase_deg: Vec<DMatrix<f64>>,
    /// The delays \[s\] of u_egr and u_vgt in the response (exact), or 0 where a Padé model's
    /// response was taken ([`frequency_response_rational`]).
    pub delays: [f64; 2],
}

impl FrequencyResponse {
    /// The complex gains of the channel `input -> output` over the frequencies (None: not a
    /// channel of this response).
    pub fn channel(&self, input: &str, output: &str) -> Option<Vec<Complex<f64>>> {
        let (o, i) = self.index(input, output)?;
        Some(self.g.iter().map(|g| g[(o, i)]).collect())
    }

    /// The (output, input) position of `input -> output` in the gain matrices.
    fn index(&self, input: &str, output: &str) -> Option<(usize, usize)> {
        let i = self.input_names.iter().position(|n| n == input)?;
        let o = self.output_names.iter().position(|n| n == output)?;
        Some((o, i))
    }

    /// Magnitude (output unit per input unit) and phase \[deg\] of `input -> output`, the phase
    /// continuous along the frequencies ([`FrequencyResponse::phase_deg`]).
    pub fn magnitude_phase(&self, input: &str, output: &str) -> Option<(Vec<f64>, Vec<f64>)> {
        let (o, i) = self.index(input, output)?;
        let mag = self.g.iter().map(|g| g[(o, i)].norm()).collect();
        let phase = self.phase_deg.iter().map(|p| p[(o, i)]).collect();
        Some((mag, phase))
    }
}

/// `n` frequencies from `f_min` to `f_max` \[Hz\], evenly spaced in log scale (both ends
/// included; `n` = 1 gives `f_min`). Checked: 0 < f_min <= f_max finite, 1 <= n <=
/// [`MAX_POINTS`] (`f_min < f_max` when n > 1).
pub fn log_grid(f_min: f64, f_max: f64, n: usize) -> Result<Vec<f64>, LinearizeError> {
    let bad = |field: &'static str, value: f64, constraint: &'static str| {
        Err(LinearizeError::BadOption {
            field,
            value,
            constraint,
        })
    };
    if !(f_min.is_finite() && f_min > 0.0) {
        return bad("f_min", f_min, "must be a frequency > 0 Hz");
    }
    if !(f_max.is_finite() && f_max >= f_min) {
        return bad("f_max", f_max, "must be finite and at least f_min");
    }
    if n == 0 || n > MAX_POINTS {
        return bad("points", n as f64, "must be 1 to 100000");
    }
    if n > 1 && f_max == f_min {
        return bad("f_max", f_max, "must exceed f_min for more than one point");
    }
    let (a, b) = (f_min.ln(), f_max.ln());
    Ok((0..n)
        .map(|k| match k {
            0 => f_min,
            _ if k + 1 == n => f_max,
            _ => (a + (b - a) * k as f64 / (n - 1) as f64).exp(),
        })
        .collect())
}

/// The frequencies of a grid written `FMIN:FMAX:N` (\[Hz\], \[Hz\], points; [`log_grid`]), as
/// `mvem linearize --bode` and the explorer's API take it, with at most `max_points` points. The
/// message says what is wrong with the text.
pub fn parse_grid(spec: &str, max_points: usize) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = spec.split(':').map(str::trim).collect();
    let [lo, hi, n] = parts[..] else {
        return Err("expected FMIN:FMAX:N (Hz, Hz, points), e.g. 0.01:100:200".into());
    };
    let num = |s: &str, what: &str| {
        s.parse::<f64>()
            .map_err(|_| format!("{what} '{s}' is not a number"))
    };
    let (lo, hi) = (num(lo, "FMIN")?, num(hi, "FMAX")?);
    let n: usize = n
        .parse()
        .map_err(|_| format!("N '{n}' is not a whole number of points"))?;
    if n > max_points {
        return Err(format!("at most {max_points} points"));
    }
    log_grid(lo, hi, n).map_err(|e| e.to_string())
}

fn check_grid(f_hz: &[f64]) -> Result<(), LinearizeError> {
    if f_hz.is_empty() || f_hz.len() > MAX_POINTS {
        return Err(LinearizeError::BadOption {
            field: "points",
            value: f_hz.len() as f64,
            constraint: "must be 1 to 100000",
        });
    }
    for (k, &f) in f_hz.iter().enumerate() {
        if !(f.is_finite() && f >= 0.0) || (k > 0 && f <= f_hz[k - 1]) {
            return Err(LinearizeError::BadOption {
                field: "f_hz",
                value: f,
                constraint: "frequencies must be finite, >= 0 Hz and strictly increasing",
            });
        }
    }
    Ok(())
}

/// The frequency response of `m` at state `x` and inputs `d` (usually a steady state) at the
/// frequencies `f_hz` \[Hz\] (finite, >= 0, increasing), the delays exact (module
/// documentation). `opts` as for [`linearize`] (its outputs are the response's; `pade_order`
/// must be 0: the delays are exact here).
pub fn frequency_response<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    opts: &LinearizeOptions,
    f_hz: &[f64],
) -> Result<FrequencyResponse, LinearizeError> {
    check_pade(opts.pade_order)?;
    check_grid(f_hz)?;
    let lin = linearize(m, x, d, opts)?;
    frequency_response_linear(m, x, d, &lin, f_hz)
}

/// [`frequency_response`] of a linearization `lin` of `m` at `x`, `d` already made (without
/// Padé states): the same result without linearizing again.
pub fn frequency_response_linear<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    lin: &LinearModel,
    f_hz: &[f64],
) -> Result<FrequencyResponse, LinearizeError> {
    check_pade(lin.pade_order)?;
    check_grid(f_hz)?;
    // as linearize: the converged model (the memory is a property of the integration)
    let conv = converged(m);
    let split = delay_split(conv.as_ref().unwrap_or(m), x, d, lin)?;
    respond(lin, Some((&split, lin.delays)), f_hz)
}

/// The response of the rational model `lin` as it is, `C (j w I - A)^-1 B + D` (with Padé
/// states the delays' approximation; without, the undelayed system): to compare a Padé model
/// with [`frequency_response`].
pub fn frequency_response_rational(
    lin: &LinearModel,
    f_hz: &[f64],
) -> Result<FrequencyResponse, LinearizeError> {
    check_grid(f_hz)?;
    respond(lin, None, f_hz)
}

fn check_pade(order: usize) -> Result<(), LinearizeError> {
    if order != 0 {
        return Err(LinearizeError::BadOption {
            field: "pade_order",
            value: order as f64,
            constraint: "must be 0 for the frequency response (the delays are exact there)",
        });
    }
    Ok(())
}

fn respond(
    lin: &LinearModel,
    delayed: Option<(&DelaySplit, [f64; 2])>,
    f_hz: &[f64],
) -> Result<FrequencyResponse, LinearizeError> {
    let n = lin.a.nrows();
    let (p, ni) = (lin.c.nrows(), lin.b.ncols());
    let cx = |m: &DMatrix<f64>| m.map(|v| Complex::new(v, 0.0));
    // in the states' scaled coordinates (x = S z), where A is well conditioned: the pressures
    // (1e5 Pa) and the oxygen fractions (0.1) otherwise differ by 1e6 in one matrix
    let s: Vec<f64> = lin.state_scales.clone();
    let a_s = DMatrix::from_fn(n, n, |i, j| lin.a[(i, j)] * s[j] / s[i]);
    let c_s = cx(&DMatrix::from_fn(p, n, |o, j| lin.c[(o, j)] * s[j]));
    let scale_rows =
        |b: &DMatrix<f64>| DMatrix::from_fn(b.nrows(), b.ncols(), |i, k| b[(i, k)] / s[i]);
    let (b_now, d_now) = match delayed {
        Some((sp, _)) => (cx(&scale_rows(&sp.b_now)), cx(&sp.d_now)),
        None => (cx(&scale_rows(&lin.b)), cx(&lin.d)),
    };
    let g_del = delayed.map(|(sp, _)| (cx(&scale_rows(&sp.g)), cx(&sp.gd)));
    let delays = delayed.map_or([0.0; 2], |(_, t)| t);
    let gain_at = |f: f64| -> Result<DMatrix<Complex<f64>>, LinearizeError> {
        let w = 2.0 * std::f64::consts::PI * f;
        let mut bw = b_now.clone();
        let mut dw = d_now.clone();
        if let Some((g, gd)) = &g_del {
            for q in 0..2 {
                let e = Complex::from_polar(1.0, -w * delays[q]);
                for r in 0..n {
                    bw[(r, 1 + q)] += g[(r, q)] * e;
                }
                for o in 0..p {
                    dw[(o, 1 + q)] += gd[(o, q)] * e;
                }
            }
        }
        let mut m = cx(&(-&a_s));
        for i in 0..n {
            m[(i, i)] += Complex::new(0.0, w);
        }
        let lu = m.lu();
        let mut g = dw;
        for k in 0..ni {
            let rhs = DVector::from_iterator(n, bw.column(k).iter().copied());
            let z = lu
                .solve(&rhs)
                .filter(|z| z.iter().all(|v| v.re.is_finite() && v.im.is_finite()));
            let Some(z) = z else {
                return Err(LinearizeError::BadOption {
                    field: "f_hz",
                    value: f,
                    constraint: "j w I - A is singular there (a pole on the imaginary axis)",
                });
            };
            let y = &c_s * z;
            for o in 0..p {
                g[(o, k)] += y[o];
            }
        }
        Ok(g)
    };
    // The phase is followed along a grid finer than the caller's, so that it is continuous
    // whatever the caller's spacing: between two frequencies at most 5 % apart in f (the
    // rational part: a pole or zero turns the phase by at most a few degrees per such step) and
    // at most pi/8 of the longest delay's phase (w tau).
    let tau = delays[0].max(delays[1]);
    let mut out = Vec::with_capacity(f_hz.len());
    let mut phase = Vec::with_capacity(f_hz.len());
    let mut prev: Option<DMatrix<f64>> = None;
    let mut budget = MAX_FOLLOWED;
    for (k, &f) in f_hz.iter().enumerate() {
        if let (Some(_), Some(&f0)) = (&prev, k.checked_sub(1).map(|j| &f_hz[j])) {
            for fi in between(f0, f, tau, &mut budget) {
                let g = gain_at(fi)?;
                prev = Some(follow(prev.as_ref(), &g));
            }
        }
        let g = gain_at(f)?;
        let ph = follow(prev.as_ref(), &g);
        prev = Some(ph.clone());
        phase.push(ph);
        out.push(g);
    }
    Ok(FrequencyResponse {
        f_hz: f_hz.to_vec(),
        input_names: lin.input_names.clone(),
        output_names: lin.output_names.clone(),
        g: out,
        phase_deg: phase,
        delays,
    })
}

/// Most intermediate frequencies of one response's phase following (beyond them the phase is
/// unwrapped between the caller's frequencies only: a delay's phase at extreme frequencies).
pub const MAX_FOLLOWED: usize = 200_000;

/// The frequencies strictly between `f0` and `f1` \[Hz\] on which the phase is followed (see
/// `respond`): at most 5 % apart in f and pi/8 of `tau` apart in phase; from f0 = 0, from
/// f1 / 1e6 up. Takes them from `budget`.
fn between(f0: f64, f1: f64, tau: f64, budget: &mut usize) -> Vec<f64> {
    let lo = if f0 > 0.0 { f0 } else { f1 * 1e-6 };
    let half = (*budget / 2) as f64;
    // geometric steps for the ratio, arithmetic ones for the delay's phase: the union keeps the
    // finer of the two everywhere
    let by_ratio = ((f1 / lo).ln() / 1.05f64.ln()).ceil().max(1.0).min(half) as usize;
    let by_delay = (2.0 * std::f64::consts::PI * (f1 - lo) * tau / (std::f64::consts::PI / 8.0))
        .ceil()
        .min(half) as usize;
    let mut v: Vec<f64> = Vec::with_capacity(by_ratio + by_delay + 1);
    if f0 == 0.0 && lo < f1 {
        v.push(lo);
    }
    for j in 1..by_ratio {
        v.push(lo * (f1 / lo).powf(j as f64 / by_ratio as f64));
    }
    for j in 1..by_delay {
        v.push(lo + (f1 - lo) * j as f64 / by_delay as f64);
    }
    v.retain(|&x| x > f0 && x < f1);
    v.sort_by(f64::total_cmp);
    *budget = budget.saturating_sub(v.len());
    v
}

/// The phases [deg] of `g`, each moved by a multiple of 360 deg to lie within 180 deg of
/// `prev`'s (the first: in (-180, 180]).
fn follow(prev: Option<&DMatrix<f64>>, g: &DMatrix<Complex<f64>>) -> DMatrix<f64> {
    DMatrix::from_fn(g.nrows(), g.ncols(), |o, i| {
        follow_phase(prev.map(|q| q[(o, i)]), g[(o, i)])
    })
}

/// The phase of `g` \[deg\], moved by a multiple of 360 deg to lie within 180 deg of `prev`
/// (without one: in (-180, 180]): a phase followed along increasing frequencies.
pub fn follow_phase(prev: Option<f64>, g: Complex<f64>) -> f64 {
    let p = g.arg().to_degrees();
    match prev {
        None => p,
        Some(q) => p + 360.0 * ((q - p) / 360.0).round(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_grid_spans_its_ends_and_refuses_bad_ranges() {
        let g = log_grid(0.01, 100.0, 5).unwrap();
        assert_eq!(g.len(), 5);
        assert_eq!((g[0], g[4]), (0.01, 100.0));
        for (v, want) in g.iter().zip([0.01, 0.1, 1.0, 10.0, 100.0]) {
            assert!((v / want - 1.0).abs() < 1e-14, "{v} vs {want}");
        }
        assert_eq!(log_grid(2.0, 2.0, 1).unwrap(), vec![2.0]);
        for (a, b, n, field) in [
            (0.0, 1.0, 3, "f_min"),
            (f64::NAN, 1.0, 3, "f_min"),
            (1.0, 0.5, 3, "f_max"),
            (1.0, f64::INFINITY, 3, "f_max"),
            (1.0, 1.0, 3, "f_max"),
            (0.1, 1.0, 0, "points"),
            (0.1, 1.0, MAX_POINTS + 1, "points"),
        ] {
            let e = log_grid(a, b, n).unwrap_err().to_string();
            assert!(e.contains(field), "{a} {b} {n}: {e}");
        }
    }

    #[test]
    fn a_grid_spec_names_what_is_wrong() {
        assert_eq!(
            parse_grid(" 0.01 : 100 : 5 ", 10),
            log_grid(0.01, 100.0, 5).map_err(|e| e.to_string())
        );
        for (spec, want) in [
            ("1:100", "expected FMIN:FMAX:N"),
            ("a:100:5", "FMIN 'a' is not a number"),
            ("1:b:5", "FMAX 'b' is not a number"),
            ("1:100:x", "N 'x' is not a whole number of points"),
            ("1:100:11", "at most 10 points"),
            ("0:100:5", "f_min = 0"),
        ] {
            let e = parse_grid(spec, 10).unwrap_err();
            assert!(e.contains(want), "{spec}: {e}");
        }
    }

    #[test]
    fn the_followed_grid_is_fine_enough_and_bounded() {
        let mut budget = MAX_FOLLOWED;
        let v = between(1.0, 10.0, 0.0, &mut budget);
        assert!(v
            .windows(2)
            .all(|w| w[1] / w[0] <= 1.05 + 1e-12 && w[1] > w[0]));
        assert!(v[0] / 1.0 <= 1.05 + 1e-12 && 10.0 / v[v.len() - 1] <= 1.05 + 1e-12);
        // a delay of 0.1 s from 10 to 100 Hz: steps of at most 1/16 / 0.1 s = 0.625 Hz
        let v = between(10.0, 100.0, 0.1, &mut budget);
        assert!(v.windows(2).all(|w| w[1] - w[0] <= 0.625 + 1e-9), "{v:?}");
        // from 0 Hz: geometric from f1 / 1e6
        let v = between(0.0, 1.0, 0.0, &mut budget);
        assert_eq!(v[0], 1e-6);
        // the budget bounds the work
        let mut small = 10;
        let v = between(1.0, 1e6, 1.0, &mut small);
        assert!(
            v.len() <= 10 && small == 10 - v.len(),
            "{} {small}",
            v.len()
        );
        let mut none = 0;
        assert!(between(1.0, 1e6, 1.0, &mut none).is_empty());
    }
}
