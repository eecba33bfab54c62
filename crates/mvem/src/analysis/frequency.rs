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
//! u_vgt -> W_c); the phase in degrees, unwrapped along the frequency grid from its value in
//! (-180, 180] at the lowest frequency. At f -> 0 the response is the DC gain
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
    /// The delays \[s\] of u_egr and u_vgt in the response (exact), or 0 where a Padé model's
    /// response was taken ([`frequency_response_rational`]).
    pub delays: [f64; 2],
}

impl FrequencyResponse {
    /// The complex gains of the channel `input -> output` over the frequencies (None: not a
    /// channel of this response).
    pub fn channel(&self, input: &str, output: &str) -> Option<Vec<Complex<f64>>> {
        let i = self.input_names.iter().position(|n| n == input)?;
        let o = self.output_names.iter().position(|n| n == output)?;
        Some(self.g.iter().map(|g| g[(o, i)]).collect())
    }

    /// Magnitude (output unit per input unit) and phase \[deg\] of `input -> output`, the phase
    /// unwrapped along the grid (see [`unwrap_deg`]).
    pub fn magnitude_phase(&self, input: &str, output: &str) -> Option<(Vec<f64>, Vec<f64>)> {
        let g = self.channel(input, output)?;
        let mag = g.iter().map(|z| z.norm()).collect();
        let phase = unwrap_deg(&g.iter().map(|z| z.arg().to_degrees()).collect::<Vec<_>>());
        Some((mag, phase))
    }
}

/// Phases \[deg\] made continuous: each value moved by a multiple of 360 deg to lie within 180
/// deg of its predecessor (a channel whose phase turns by more than 180 deg between two grid
/// points, e.g. a long delay on a coarse grid, needs a finer grid). The first value is kept.
pub fn unwrap_deg(phase: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(phase.len());
    let mut prev: Option<f64> = None;
    for &p in phase {
        let v = match prev {
            None => p,
            Some(q) => p + 360.0 * ((q - p) / 360.0).round(),
        };
        out.push(v);
        prev = Some(v);
    }
    out
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
    let mut out = Vec::with_capacity(f_hz.len());
    for &f in f_hz {
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
        out.push(g);
    }
    Ok(FrequencyResponse {
        f_hz: f_hz.to_vec(),
        input_names: lin.input_names.clone(),
        output_names: lin.output_names.clone(),
        g: out,
        delays,
    })
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
    fn unwrapping_removes_the_360_degree_jumps_only() {
        let p = unwrap_deg(&[-170.0, 175.0, 160.0, -179.0, 170.0]);
        assert_eq!(p, vec![-170.0, -185.0, -200.0, -179.0, -190.0]);
    }
}
