//! Cycle statistics: the regulation's regression of actual on reference values (UN GTR No. 4,
//! validation of the test run) and the air-path figures of merit.

use super::Trajectory;
use serde::Serialize;

/// Least-squares line `actual = slope * reference + intercept`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Regression {
    /// Slope [-] (NaN, `null` in JSON, where not applicable).
    pub slope: f64,
    /// Intercept [unit of the quantity] (NaN where not applicable).
    pub intercept: f64,
    /// Coefficient of determination R^2 [-] (NaN where not applicable).
    pub r2: f64,
    /// Standard error of estimate of actual on reference [unit] (NaN where not applicable).
    pub see: f64,
    /// Number of samples.
    pub samples: usize,
    /// Why the regression is not applicable (`None`: it is): fewer than
    /// [`Regression::MIN_SAMPLES`] samples, or a reference whose standard deviation is below
    /// [`Regression::MIN_SPREAD`] of its largest magnitude (a constant demand: the line would
    /// be fitted to the tracking error's noise).
    pub not_applicable: Option<String>,
}

impl Regression {
    /// Fewest samples of a regression (two parameters and at least one degree of freedom).
    pub const MIN_SAMPLES: usize = 3;
    /// Smallest standard deviation of the reference, relative to its largest magnitude [-].
    pub const MIN_SPREAD: f64 = 0.01;

    /// Whether the figures are applicable.
    pub fn applicable(&self) -> bool {
        self.not_applicable.is_none()
    }
}

/// Regression of `y` (actual) on `x` (reference); not applicable (NaN figures and the reason)
/// for fewer than [`Regression::MIN_SAMPLES`] samples or a reference that hardly varies
/// ([`Regression::MIN_SPREAD`]).
pub fn regression(x: &[f64], y: &[f64]) -> Regression {
    let n = x.len().min(y.len());
    let nf = n as f64;
    let none = |why: String| Regression {
        slope: f64::NAN,
        intercept: f64::NAN,
        r2: f64::NAN,
        see: f64::NAN,
        samples: n,
        not_applicable: Some(why),
    };
    if n < Regression::MIN_SAMPLES {
        return none(format!(
            "{n} sample(s), fewer than {}",
            Regression::MIN_SAMPLES
        ));
    }
    let mx = x[..n].iter().sum::<f64>() / nf;
    let my = y[..n].iter().sum::<f64>() / nf;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (dx, dy) = (x[i] - mx, y[i] - my);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let sd = (sxx / nf).sqrt();
    let big = x[..n].iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    if sd.is_nan() || sd <= Regression::MIN_SPREAD * big {
        return none(format!(
            "the reference hardly varies (standard deviation {sd:.3e}, below {} % of its largest \
             magnitude {big:.3e}): the line would fit the tracking error's noise",
            100.0 * Regression::MIN_SPREAD
        ));
    }
    let slope = sxy / sxx;
    let intercept = my - slope * mx;
    let sse = (syy - slope * sxy).max(0.0);
    Regression {
        slope,
        intercept,
        r2: if syy > 0.0 {
            sxy * sxy / (sxx * syy)
        } else {
            1.0
        },
        see: (sse / (nf - 2.0)).sqrt(),
        samples: n,
        not_applicable: None,
    }
}

/// Smallest positive work of a cycle for its work error and BSFC \[kWh\]: below it (an idle or
/// motored cycle) the ratios divide by numerical noise and are not applicable.
pub const MIN_WORK_KWH: f64 = 1e-3;

/// Statistics of one cycle run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CycleStats {
    /// Speed regression \[rpm\] (all samples): the dynamometer holds the reference speed (n_e
    /// is an input of the model), so actual = reference by construction (slope 1, R^2 1, SEE
    /// 0) where the speed varies; kept because the regulation's validation lists it.
    pub speed: Regression,
    /// Torque regression \[Nm\] (samples with positive reference torque).
    pub torque: Regression,
    /// Power regression \[kW\] (samples with positive reference torque).
    pub power: Regression,
    /// Largest full-load torque of the engine \[Nm\] (for the SEE limit).
    pub m_max: f64,
    /// Positive cycle work, reference \[kWh\].
    pub work_ref_kwh: f64,
    /// Positive cycle work, actual \[kWh\].
    pub work_act_kwh: f64,
    /// Actual / reference positive work - 1 [-] (NaN, `null` in JSON, when the reference work
    /// is below [`MIN_WORK_KWH`]: see `not_applicable`).
    pub work_error: f64,
    /// Smallest lambda_O over fired samples [-] (NaN without a fired sample).
    pub lambda_o_min: f64,
    /// Time of the smallest lambda_O \[s\].
    pub lambda_o_min_t: f64,
    /// Share of fired samples with lambda_O below the limit [-].
    pub lambda_below_limit_share: f64,
    /// The limit [-].
    pub lambda_limit: f64,
    /// RMS of x_egr,s - x_egr over fired samples with a set-point [-] (at motoring and minimum
    /// fuel the EGR fraction is not controlled).
    pub x_egr_rms_error: f64,
    /// Mean pumping mean effective pressure p_em - p_im \[Pa\].
    pub pmep_mean_pa: f64,
    /// Fuel mass \[kg\].
    pub fuel_kg: f64,
    /// Brake-specific fuel consumption over the positive work [g/kWh] (NaN when the actual work
    /// is below [`MIN_WORK_KWH`]: see `not_applicable`).
    pub bsfc_g_kwh: f64,
    /// The figures not applicable to this run, each with the reason (`"work_error: ..."`,
    /// `"bsfc_g_kwh: ..."`; the regressions carry their own).
    pub not_applicable: Vec<String>,
    /// Samples, of which fired (not motoring, u_delta above the minimum).
    pub samples: usize,
    /// Fired samples.
    pub fired: usize,
}

impl CycleStats {
    /// Statistics of `traj` (one row per sample of constant spacing).
    pub fn compute(traj: &Trajectory, m_max: f64, lambda_limit: f64) -> Self {
        let g = |n: &str| traj.get(n).expect("trajectory column");
        let (t, n_e, m_ref, m_e) = (g("t"), g("n_e"), g("M_ref"), g("M_e"));
        let (lam, u_d, mot) = (g("lambda_O"), g("u_delta"), g("motoring"));
        let (x, x_ref, p_im, p_em, w_f) =
            (g("x_egr"), g("x_egr_ref"), g("p_im"), g("p_em"), g("W_f"));
        let n = traj.len();
        let omega = |i: usize| n_e[i] * std::f64::consts::PI / 30.0;
        let dt = if n > 1 {
            (t[n - 1] - t[0]) / (n - 1) as f64
        } else {
            0.0
        };
        let pos: Vec<usize> = (0..n).filter(|&i| m_ref[i] > 0.0).collect();
        let sel = |v: &dyn Fn(usize) -> f64| pos.iter().map(|&i| v(i)).collect::<Vec<f64>>();
        let torque = regression(&sel(&|i| m_ref[i]), &sel(&|i| m_e[i]));
        let power = regression(
            &sel(&|i| m_ref[i] * omega(i) / 1e3),
            &sel(&|i| m_e[i] * omega(i) / 1e3),
        );
        let speed = regression(n_e, n_e);
        // positive work: trapezoid-free sum over samples (rows are sample-and-hold intervals)
        let (mut w_ref, mut w_act, mut fuel, mut pmep) = (0.0, 0.0, 0.0, 0.0);
        let (mut lmin, mut lmin_t, mut below, mut fired) = (f64::INFINITY, f64::NAN, 0, 0);
        let (mut xe2, mut nx) = (0.0, 0);
        for i in 0..n {
            let h = if i + 1 < n { dt } else { 0.0 };
            w_ref += (m_ref[i] * omega(i)).max(0.0) * h;
            w_act += (m_e[i] * omega(i)).max(0.0) * h;
            fuel += w_f[i] * h;
            pmep += (p_em[i] - p_im[i]) * h;
            // fired: the fuel of the interval before this sample was above the minimum
            let was_fired = i > 0 && mot[i - 1] == 0.0 && u_d[i - 1] > 1.0 + 1e-9;
            if was_fired {
                fired += 1;
                if lam[i] < lmin {
                    lmin = lam[i];
                    lmin_t = t[i];
                }
                if lam[i] < lambda_limit {
                    below += 1;
                }
            }
            if was_fired && x_ref[i].is_finite() {
                xe2 += (x_ref[i] - x[i]).powi(2);
                nx += 1;
            }
        }
        let span = (t[n - 1] - t[0]).max(f64::MIN_POSITIVE);
        let kwh = 3.6e6;
        let mut not_applicable = Vec::new();
        let (w_ref_kwh, w_act_kwh) = (w_ref / kwh, w_act / kwh);
        let work_error = if w_ref_kwh >= MIN_WORK_KWH {
            w_act / w_ref - 1.0
        } else {
            not_applicable.push(format!(
                "work_error: the reference's positive work {w_ref_kwh:.3e} kWh is below \
                 {MIN_WORK_KWH} kWh"
            ));
            f64::NAN
        };
        let bsfc_g_kwh = if w_act_kwh >= MIN_WORK_KWH {
            fuel * 1e3 / w_act_kwh
        } else {
            not_applicable.push(format!(
                "bsfc_g_kwh: the positive work {w_act_kwh:.3e} kWh is below {MIN_WORK_KWH} kWh"
            ));
            f64::NAN
        };
        CycleStats {
            speed,
            torque,
            power,
            m_max,
            work_ref_kwh: w_ref_kwh,
            work_act_kwh: w_act_kwh,
            work_error,
            lambda_o_min: if fired > 0 { lmin } else { f64::NAN },
            lambda_o_min_t: lmin_t,
            lambda_below_limit_share: below as f64 / fired.max(1) as f64,
            lambda_limit,
            x_egr_rms_error: if nx > 0 {
                (xe2 / nx as f64).sqrt()
            } else {
                f64::NAN
            },
            pmep_mean_pa: pmep / span,
            fuel_kg: fuel,
            bsfc_g_kwh,
            not_applicable,
            samples: n,
            fired,
        }
    }

    /// Violations of the regulation's torque regression limits (slope 0.83-1.03, R^2 >= 0.88,
    /// SEE <= 13 % of the maximum torque), the positive work (+-5 %) and lambda_O (never below
    /// `lambda_floor`, below the limit in at most 1 % of fired samples). Empty: all pass. A
    /// criterion that is not applicable (a constant demand's regression, an idle cycle's work)
    /// is no violation: the reasons are in [`Regression::not_applicable`] and
    /// [`CycleStats::not_applicable`].
    pub fn violations(&self, lambda_floor: f64) -> Vec<String> {
        let mut v = Vec::new();
        let tq = &self.torque;
        // a regression that is not applicable has no criterion
        if tq.applicable() {
            if !(0.83..=1.03).contains(&tq.slope) {
                v.push(format!("torque slope {:.3} outside [0.83, 1.03]", tq.slope));
            }
            if tq.r2 < 0.88 || tq.r2.is_nan() {
                v.push(format!("torque R^2 {:.3} < 0.88", tq.r2));
            }
            if tq.see > 0.13 * self.m_max || tq.see.is_nan() {
                v.push(format!(
                    "torque SEE {:.1} Nm > 13 % of {:.0} Nm",
                    tq.see, self.m_max
                ));
            }
        }
        let work_applicable = self.work_ref_kwh >= MIN_WORK_KWH;
        if work_applicable && (self.work_error.abs() > 0.05 || self.work_error.is_nan()) {
            v.push(format!(
                "positive work {:.3} kWh vs reference {:.3} kWh ({:+.1} %)",
                self.work_act_kwh,
                self.work_ref_kwh,
                100.0 * self.work_error
            ));
        }
        if self.lambda_o_min < lambda_floor {
            v.push(format!(
                "lambda_O min {:.3} at t = {:.2} s < {lambda_floor}",
                self.lambda_o_min, self.lambda_o_min_t
            ));
        }
        if self.lambda_below_limit_share > 0.01 {
            v.push(format!(
                "lambda_O < {} in {:.2} % of fired samples (> 1 %)",
                self.lambda_limit,
                100.0 * self.lambda_below_limit_share
            ));
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regression_of_a_known_line() {
        let x: Vec<f64> = (0..100).map(|i| i as f64).collect();
        let y: Vec<f64> = x
            .iter()
            .map(|v| 0.9 * v + 2.0 + if (*v as usize) % 2 == 0 { 0.5 } else { -0.5 })
            .collect();
        let r = regression(&x, &y);
        assert!((r.slope - 0.9).abs() < 1e-3, "{r:?}");
        assert!((r.intercept - 2.0).abs() < 0.1, "{r:?}");
        assert!(r.r2 > 0.99 && r.r2 < 1.0);
        // residuals +-0.5 around the fitted line: SEE ~ 0.5
        assert!((r.see - 0.5).abs() < 0.02, "{r:?}");
        assert!(r.applicable());
    }

    /// A trajectory of `n` 10 ms samples at 1200 rpm: reference torque `m_ref(i)`, actual
    /// `m_e(i)`, fuel flow `w_f`, fired at `u_delta`.
    fn traj(
        n: usize,
        m_ref: &dyn Fn(usize) -> f64,
        m_e: &dyn Fn(usize) -> f64,
        w_f: f64,
    ) -> Trajectory {
        let mut columns = vec![vec![0.0; n]; Trajectory::NAMES.len()];
        let mut set = |name: &str, f: &dyn Fn(usize) -> f64| {
            let k = Trajectory::NAMES.iter().position(|c| *c == name).unwrap();
            columns[k] = (0..n).map(f).collect();
        };
        set("t", &|i| i as f64 * 0.01);
        set("n_e", &|_| 1200.0);
        set("M_ref", m_ref);
        set("M_e", m_e);
        set("W_f", &|_| w_f);
        set("u_delta", &|_| 50.0);
        set("lambda_O", &|_| 2.0);
        set("p_im", &|_| 1.5e5);
        set("p_em", &|_| 1.7e5);
        Trajectory { columns }
    }

    /// A constant demand: the torque and power regressions are not applicable (NaN, `null` in
    /// JSON, with the reason), not a violation; the work and BSFC are. An idle run (no positive
    /// reference torque, numerical-noise work): no regression from zero samples, and neither a
    /// work error nor a BSFC.
    #[test]
    fn constant_and_idle_cycles_have_no_garbage_statistics() {
        let noise = |i: usize| 500.0 + 1e-3 * ((i * 7919) % 13) as f64;
        let s = CycleStats::compute(&traj(1000, &|_| 500.0, &noise, 0.005), 2000.0, 1.2);
        for r in [&s.torque, &s.power, &s.speed] {
            assert!(
                !r.applicable() && r.slope.is_nan() && r.see.is_nan(),
                "{r:?}"
            );
            assert!(
                r.not_applicable.as_ref().unwrap().contains("hardly varies"),
                "{r:?}"
            );
        }
        assert!(s.violations(1.05).is_empty(), "{:?}", s.violations(1.05));
        assert!(s.work_error.abs() < 1e-3 && s.bsfc_g_kwh > 0.0, "{s:?}");
        let j = serde_json::to_value(&s).unwrap();
        assert!(j["torque"]["slope"].is_null() && j["torque"]["not_applicable"].is_string());

        let idle = CycleStats::compute(
            &traj(1000, &|_| 0.0, &|i| 1e-9 * i as f64, 1e-4),
            2000.0,
            1.2,
        );
        assert_eq!(idle.torque.samples, 0);
        assert!(
            idle.torque.r2.is_nan() && !idle.torque.applicable(),
            "{idle:?}"
        );
        assert!(
            idle.work_error.is_nan() && idle.bsfc_g_kwh.is_nan(),
            "{idle:?}"
        );
        assert_eq!(idle.not_applicable.len(), 2, "{:?}", idle.not_applicable);
        assert!(
            idle.violations(1.05).is_empty(),
            "{:?}",
            idle.violations(1.05)
        );
    }
}
