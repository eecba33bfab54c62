//! Time constants of the test cell's sensors for the dynamic outputs p_im, p_em, W_c and n_t.
//!
//! The paper neglects them (appendix 2, Table 6: at most 15 ms for p_im, 20 ms for p_em and
//! W_c, 6 ms for n_t, against system time constants of 0.1-1 s). A tuning method that neglects
//! them on a test cell that has them gives them to the parameters that shape the fast part of
//! the step responses: on an `mvem lab --sensor-lags` campaign step 3 returned V_im +38 %,
//! V_em +76 % and J_t +23 % with standard errors of 4-10 % (docs/tuning.md, session 17). The
//! tuning therefore models each sensor as a first-order lag `tau dy/dt = x - y` on the
//! simulated output ([`SensorLags::apply`]), with the time constants known
//! ([`SensorLagMode::Known`]) or fitted in step 3 with V_im, V_em and J_t
//! ([`SensorLagMode::Fit`]), and writes them to the `[test_cell]` section of the tuned
//! parameter file, where `validate` reads them. The torque sensor's lag is the dynamometer
//! time constant tau_Me of eq. (76), tuned in step 4.

use serde::{Deserialize, Serialize};

/// The outputs with a sensor lag, in the order of `SensorLags::get` (and of
/// [`super::complete::DYN_OUTPUTS`]).
pub const LAGGED_OUTPUTS: [&str; 4] = ["p_im", "p_em", "W_c", "n_t"];

/// Names of the time constants (keys of the `[test_cell]` section and of the tuning's
/// parameter list), in the order of [`LAGGED_OUTPUTS`].
pub const LAG_NAMES: [&str; 4] = ["tau_p_im", "tau_p_em", "tau_w_c", "tau_n_t"];

/// Largest sensor time constant accepted \[s\] (bound of the fit; a value read from a file or the
/// command line above it is an error): ten times Table 6's largest.
pub const MAX_LAG_S: f64 = 0.2;

/// Output grid of a simulation whose outputs pass through a lag: at most this far apart \[s\]
/// (the lag filter is exact for an input linear between grid points; 2 ms is the grid of the
/// virtual test cell's lags).
pub const LAG_GRID_S: f64 = 0.002;

/// Data sampled at most this far apart \[s\] are simulated on the [`LAG_GRID_S`] grid when a
/// lag is positive ([`SensorLags::grid`]): twice Table 6's largest time constant.
pub const LAG_REFINE_MAX_DT_S: f64 = 0.04;

/// First-order sensor time constants \[s\] of p_im, p_em, W_c and n_t (0: no lag).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorLags {
    /// Intake manifold pressure sensor \[s\].
    pub p_im: f64,
    /// Exhaust manifold pressure sensor \[s\].
    pub p_em: f64,
    /// Compressor mass flow sensor \[s\].
    pub w_c: f64,
    /// Turbo speed sensor \[s\].
    pub n_t: f64,
}

impl SensorLags {
    /// No lags.
    pub const NONE: Self = Self {
        p_im: 0.0,
        p_em: 0.0,
        w_c: 0.0,
        n_t: 0.0,
    };

    /// The maxima of the paper's Table 6 (p_im 15 ms, p_em 20 ms, W_c 20 ms, n_t 6 ms), as
    /// `mvem lab --sensor-lags` applies them.
    pub const TABLE6: Self = Self {
        p_im: 0.015,
        p_em: 0.020,
        w_c: 0.020,
        n_t: 0.006,
    };

    /// Whether any lag is positive.
    pub fn any(&self) -> bool {
        self.as_array().iter().any(|t| *t > 0.0)
    }

    /// The four time constants in the order of [`LAGGED_OUTPUTS`] \[s\].
    pub fn as_array(&self) -> [f64; 4] {
        [self.p_im, self.p_em, self.w_c, self.n_t]
    }

    /// From the four time constants in the order of [`LAGGED_OUTPUTS`] \[s\].
    pub fn from_array(a: [f64; 4]) -> Self {
        Self {
            p_im: a[0],
            p_em: a[1],
            w_c: a[2],
            n_t: a[3],
        }
    }

    /// Time constant of the sensor of `output` (a name of [`LAGGED_OUTPUTS`]; 0 for any other
    /// output) \[s\].
    pub fn of(&self, output: &str) -> f64 {
        LAGGED_OUTPUTS
            .iter()
            .position(|o| *o == output)
            .map_or(0.0, |k| self.as_array()[k])
    }

    /// Position of a time constant's name in [`LAG_NAMES`].
    pub fn index(name: &str) -> Option<usize> {
        LAG_NAMES.iter().position(|n| *n == name)
    }

    /// Set the time constant at position `k` of [`LAG_NAMES`] \[s\] (ignored beyond 3).
    pub fn set(&mut self, k: usize, v: f64) {
        let mut a = self.as_array();
        if let Some(x) = a.get_mut(k) {
            *x = v;
        }
        *self = Self::from_array(a);
    }

    /// The simulation output grid for data sampled every `dt` \[s\]: `dt` divided into equal
    /// parts of at most [`LAG_GRID_S`] when a lag is positive and `dt` at most
    /// [`LAG_REFINE_MAX_DT_S`] (the 100 Hz step responses of steps 3 and 7); `dt` itself
    /// otherwise (no lag, or data sampled far slower than the sensors: step 5's 10 Hz rows and
    /// 1 Hz sets, where the lag acts on the output interpolated between the samples and a finer
    /// grid would multiply the simulations' output by up to 500 for a correction below the
    /// noise). The choice depends on the data, not on the size of the lags, so the residuals
    /// of a fit stay continuous in them.
    pub fn grid(&self, dt: f64) -> f64 {
        if self.any() && dt > LAG_GRID_S && dt <= LAG_REFINE_MAX_DT_S {
            dt / (dt / LAG_GRID_S).ceil()
        } else {
            dt
        }
    }

    /// The sensor's view of the simulated `output` on the grid `t`: the lag of `output`
    /// applied to `v` (exact for `v` linear between grid points, starting in steady state),
    /// or `v` itself when it has none.
    pub fn apply(&self, output: &str, t: &[f64], v: &[f64]) -> Vec<f64> {
        let tau = self.of(output);
        if tau > 0.0 {
            super::lab::first_order_lag(t, v, tau)
        } else {
            v.to_vec()
        }
    }

    /// Check every time constant: finite, in [0, [`MAX_LAG_S`]]; the error names it.
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in LAG_NAMES.iter().zip(self.as_array()) {
            if !(v.is_finite() && (0.0..=MAX_LAG_S).contains(&v)) {
                return Err(format!(
                    "{name} = {v}: a sensor time constant must be a finite time in [0, {MAX_LAG_S}] s"
                ));
            }
        }
        Ok(())
    }

    /// Parse `table6`, `none`, or a comma-separated list `p_im=0.015,p_em=0.02,W_c=0.02,
    /// n_t=0.006` \[s\] (outputs not named: 0; names as in [`LAGGED_OUTPUTS`] or
    /// [`LAG_NAMES`]).
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim() {
            "table6" => return Ok(Self::TABLE6),
            "none" => return Ok(Self::NONE),
            _ => {}
        }
        let mut out = Self::NONE;
        for part in s.split(',') {
            let (name, value) = part.split_once('=').ok_or_else(|| {
                format!("{part:?}: expected OUTPUT=SECONDS (e.g. p_im=0.015), table6 or none")
            })?;
            let name = name.trim();
            let k = LAGGED_OUTPUTS
                .iter()
                .position(|o| o.eq_ignore_ascii_case(name))
                .or_else(|| Self::index(name))
                .ok_or_else(|| format!("{name:?}: not a lagged output (p_im, p_em, W_c, n_t)"))?;
            let v: f64 = value
                .trim()
                .parse()
                .map_err(|_| format!("{name} = {value:?}: not a number of seconds"))?;
            out.set(k, v);
        }
        out.check()?;
        Ok(out)
    }
}

/// How the tuning treats the sensor lags.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum SensorLagMode {
    /// No lags (the paper: appendix 2).
    None,
    /// Known time constants (data sheets), applied in steps 3-5 and the validation.
    Known(SensorLags),
    /// Fitted in step 3 with V_im, V_em and J_t (bounds [0, [`MAX_LAG_S`]]), then held in
    /// step 5 and the repeated step 3 fits them again. The default.
    #[default]
    Fit,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_and_check() {
        assert_eq!(SensorLags::parse("table6").unwrap(), SensorLags::TABLE6);
        assert_eq!(SensorLags::parse("none").unwrap(), SensorLags::NONE);
        let l = SensorLags::parse("p_im=0.01, W_c=0.02,tau_n_t=0.003").unwrap();
        assert_eq!(l.as_array(), [0.01, 0.0, 0.02, 0.003]);
        assert_eq!(l.of("W_c"), 0.02);
        assert_eq!(l.of("M_e"), 0.0);
        let e = SensorLags::parse("p_im=-0.01").unwrap_err();
        assert!(e.contains("tau_p_im"), "{e}");
        assert!(SensorLags::parse("x_egr=0.01")
            .unwrap_err()
            .contains("x_egr"));
        assert!(SensorLags::parse("p_im=abc").unwrap_err().contains("p_im"));
        assert!(SensorLags::parse("p_im=NaN").is_err());
    }

    #[test]
    fn the_grid_divides_the_sample_interval() {
        let l = SensorLags::TABLE6;
        assert!((l.grid(0.01) - 0.002).abs() < 1e-15);
        assert_eq!(l.grid(0.1), 0.1);
        assert!((l.grid(0.003) - 0.0015).abs() < 1e-15);
        assert_eq!(l.grid(1.0), 1.0);
        assert_eq!(SensorLags::NONE.grid(0.01), 0.01);
    }

    #[test]
    fn a_lag_of_a_ramp_trails_it_by_tau() {
        // x = t: the lag's output tends to t - tau (1 - exp(-t/tau)) exactly
        let tau = 0.02;
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 0.002).collect();
        let l = SensorLags {
            p_em: tau,
            ..SensorLags::NONE
        };
        let y = l.apply("p_em", &t, &t);
        for (ti, yi) in t.iter().zip(&y) {
            let exact = ti - tau * (1.0 - (-ti / tau).exp());
            assert!((yi - exact).abs() < 1e-12, "{ti}: {yi} vs {exact}");
        }
        assert_eq!(l.apply("p_im", &t, &t), t);
    }
}
