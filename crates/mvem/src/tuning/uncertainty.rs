//! How well each tuned parameter is known: linearized (Gauss-Newton) standard errors at the
//! optimum of the step that tuned it, and an identifiability flag with its reason.
//!
//! For a step with residuals r (m) and Jacobian J = dr/dtheta (m x n, parameter units) at the
//! optimum the covariance is `Cov = s^2 (J^T J)^-1` ([`super::lsq::param_stats`], pseudo-inverse
//! over the numerically identifiable subspace) with the residual variance
//! `s^2 = ||r||^2 / (m - n)`. Two corrections keep it honest:
//!
//! * **Rows of different noise levels and correlated residuals.** The residuals are split in
//!   blocks (per data set and output, per submodel); the covariance is the sandwich
//!   `(J^T J)^-1 J^T S J (J^T J)^-1` with `S` the block's mean square residual times the AR(1)
//!   variance-inflation factor `(1 + rho) / (1 - rho)`, rho the block's lag-1 autocorrelation
//!   (samples of a dynamic response are not independent; 0 for white noise, limited to
//!   [0, 0.98]) ([`block_covariance`]).
//! * **Identifiability.** A parameter is reported identifiable when its standard error is
//!   finite, its relative standard error `se / |value|` is at most
//!   [`MAX_REL_STD_ERR`] (25 %) and no other parameter of the same step correlates with it by more
//!   than [`MAX_CORRELATION`] in absolute value. The reason is stated ("rel. std. error 290 %",
//!   "correlation 0.998 with c_m3", "not in the column space of J (singular value 0)").
//!   The standard errors are conditional on the parameters the step holds fixed and assume the
//!   search reached its optimum (docs/tuning.md lists where this fails).
//!   `correlated_with` lists the parameters with |correlation| > [`LIST_CORRELATION`].
//!
//! The estimate of a parameter tuned by several steps is that of the last one (step 5 replaces
//! the step-1 values of the static parameters; the dynamics steps 3-4 repeated after step 5
//! replace steps 3-4).

use super::complete::{param_mut, param_value, set_named, STATIC_PARAMS};
use super::data::{DynamicData, StationaryPoint};
use super::lsq::{param_stats, ParamStats};
use super::steps::{actuator_response, submodel_series, Step1Report};
use crate::params::Params;
use nalgebra::DMatrix;
use serde::Serialize;

/// Largest relative standard error of an identifiable parameter.
pub const MAX_REL_STD_ERR: f64 = 0.25;
/// Largest |correlation| with another parameter of the same step of an identifiable parameter.
pub const MAX_CORRELATION: f64 = 0.99;
/// Correlations above this (absolute) are listed in `correlated_with`.
pub const LIST_CORRELATION: f64 = 0.95;

/// How well one tuned parameter is known.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParamEstimate {
    /// Tuned value (units of the parameter file).
    pub value: f64,
    /// Linearized standard error (same units); infinite when not determined by the data.
    pub std_error: f64,
    /// Whether the campaign determines the parameter (see the module documentation).
    pub identifiable: bool,
    /// Parameters of the same step with |correlation| > [`LIST_CORRELATION`] (name, correlation).
    pub correlated_with: Vec<(String, f64)>,
    /// Why the parameter is (not) identifiable.
    pub reason: String,
    /// Tuning step whose optimum gave the estimate (1-5; 6-8 the 12-state steps).
    pub step: u8,
}

/// Lag-1 autocorrelation of `r` (0 for fewer than 3 values or zero variance).
pub fn lag1_autocorrelation(r: &[f64]) -> f64 {
    if r.len() < 3 {
        return 0.0;
    }
    let n = r.len() as f64;
    let m = r.iter().sum::<f64>() / n;
    let c0: f64 = r.iter().map(|x| (x - m) * (x - m)).sum();
    if c0 <= 0.0 {
        return 0.0;
    }
    let c1: f64 = r.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    c1 / c0
}

/// Central-difference Jacobian of `res` at `theta` (steps `1e-6 max(|theta_i|, scale_i)`).
pub fn fd_jacobian(
    mut res: impl FnMut(&[f64]) -> Vec<f64>,
    theta: &[f64],
    scale: &[f64],
) -> DMatrix<f64> {
    let m = res(theta).len();
    let mut j = DMatrix::zeros(m, theta.len());
    let mut th = theta.to_vec();
    for k in 0..theta.len() {
        let h = 1e-6 * theta[k].abs().max(scale[k]);
        th[k] = theta[k] + h;
        let rp = res(&th);
        th[k] = theta[k] - h;
        let rm = res(&th);
        th[k] = theta[k];
        for i in 0..m.min(rp.len()).min(rm.len()) {
            j[(i, k)] = (rp[i] - rm[i]) / (2.0 * h);
        }
    }
    j
}

/// Estimates of the parameters `names` (values `theta`, typical magnitudes `scale`) from the
/// Jacobian and residuals at the optimum of step `step`, the residuals in one block (one noise
/// level). See [`estimates_blocks`].
pub fn estimates(
    names: &[&str],
    theta: &[f64],
    scale: &[f64],
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    step: u8,
) -> Vec<(String, ParamEstimate)> {
    estimates_blocks(names, theta, scale, jacobian, residuals, &[], step)
}

/// Block-sandwich covariance: `(J^T J)^-1 J^T S J (J^T J)^-1` with `S` diagonal, constant in
/// each block of residuals (lengths `blocks`, the rest one block): the block's mean square
/// residual times its AR(1) inflation `(1 + rho)/(1 - rho)`. With one block of white residuals
/// this is the Gauss-Newton covariance `s^2 (J^T J)^-1` (up to the degrees of freedom). Blocks
/// are the rows of a cost with different noise levels (a data set's output, a submodel).
pub fn block_covariance(
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    blocks: &[usize],
) -> DMatrix<f64> {
    block_covariance_and_step(jacobian, residuals, blocks).0
}

/// [`block_covariance`] and the remaining Gauss-Newton step `-(J^T J)^+ J^T r` at the point
/// (zero at an interior optimum; large where the search stopped before converging).
pub fn block_covariance_and_step(
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    blocks: &[usize],
) -> (DMatrix<f64>, Vec<f64>) {
    let (m, n) = jacobian.shape();
    let st: ParamStats = param_stats(jacobian, residuals);
    // (J^T J)^+ = cov / sigma2 (pseudo-inverse over the identifiable subspace)
    let inv = st.covariance.map(|c| c / st.sigma2);
    let mut w = vec![0.0; m];
    let mut start = 0;
    let mut lens: Vec<usize> = blocks.to_vec();
    let used: usize = lens.iter().sum();
    if used < m {
        lens.push(m - used);
    }
    let dof = (m as f64 / m.saturating_sub(n).max(1) as f64).max(1.0);
    for len in lens {
        let end = (start + len).min(m);
        if end <= start {
            continue;
        }
        let r = &residuals[start..end];
        let ms = r.iter().map(|x| x * x).sum::<f64>() / r.len() as f64;
        let rho = lag1_autocorrelation(r).clamp(0.0, 0.98);
        let v = ms * dof * (1.0 + rho) / (1.0 - rho);
        for x in &mut w[start..end] {
            *x = v;
        }
        start = end;
    }
    let mut jsj = DMatrix::zeros(n, n);
    for i in 0..m {
        let row = jacobian.row(i);
        for a in 0..n {
            let ra = row[a] * w[i];
            if ra == 0.0 {
                continue;
            }
            for b in 0..n {
                jsj[(a, b)] += ra * row[b];
            }
        }
    }
    let g = jacobian.tr_mul(&nalgebra::DVector::from_column_slice(residuals));
    let step = (&inv * g).iter().map(|x| -x).collect();
    (&inv * jsj * &inv, step)
}

/// Estimates of the parameters `names` (see [`estimates`]) with residual `blocks` of different
/// noise levels ([`block_covariance`]).
pub fn estimates_blocks(
    names: &[&str],
    theta: &[f64],
    scale: &[f64],
    jacobian: &DMatrix<f64>,
    residuals: &[f64],
    blocks: &[usize],
    step: u8,
) -> Vec<(String, ParamEstimate)> {
    let (cov, _) = block_covariance_and_step(jacobian, residuals, blocks);
    let n = names.len();
    let se: Vec<f64> = (0..n)
        .map(|k| {
            let v = cov[(k, k)];
            if v.is_finite() && v > 0.0 {
                v.sqrt()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    let corr_of = |a: usize, b: usize| cov[(a, b)] / (se[a] * se[b]);
    names
        .iter()
        .enumerate()
        .map(|(k, n)| {
            let se = se[k];
            // relative to the value: a parameter not distinguishable from 0 is not identifiable
            let _ = scale;
            let rel = se / theta[k].abs();
            let mut corr: Vec<(String, f64)> = (0..names.len())
                .filter(|&i| i != k)
                .map(|i| (names[i].to_string(), corr_of(k, i)))
                .filter(|(_, c)| c.is_finite() && c.abs() > LIST_CORRELATION)
                .collect();
            corr.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            let worst = corr.first().cloned();
            let (identifiable, reason) = if !se.is_finite() {
                (
                    false,
                    "not determined by the data (a zero singular value of the Jacobian involves it)"
                        .to_string(),
                )
            } else if rel > MAX_REL_STD_ERR {
                (false, format!("rel. std. error {:.0} %", 100.0 * rel))
            } else if let Some((w, c)) = worst.filter(|(_, c)| c.abs() > MAX_CORRELATION) {
                (false, format!("correlation {c:.4} with {w}"))
            } else {
                (true, format!("rel. std. error {:.2} %", 100.0 * rel))
            };
            (
                n.to_string(),
                ParamEstimate {
                    value: theta[k],
                    std_error: se,
                    identifiable,
                    correlated_with: corr,
                    reason,
                    step,
                },
            )
        })
        .collect()
}

/// Typical magnitude of a tunable parameter: its [`STATIC_PARAMS`] scale, else |value| (1 if 0).
fn typical_scale(name: &str, value: f64) -> f64 {
    STATIC_PARAMS
        .iter()
        .find(|s| s.name == name)
        .map(|s| s.scale)
        .unwrap_or(if value != 0.0 { value.abs() } else { 1.0 })
}

/// Estimates of the step-1 parameters: per submodel, the Jacobian of its residuals
/// (measured - modelled, eq. (4) units) by central differences at the fitted values.
pub fn step1_estimates(
    p: &Params,
    pts: &[StationaryPoint],
    rep: &Step1Report,
) -> Vec<(String, ParamEstimate)> {
    let mut out = Vec::new();
    for f in &rep.fits {
        let names: Vec<&str> = f.params.iter().map(|(n, _)| n.as_str()).collect();
        let theta: Vec<f64> = names
            .iter()
            .map(|n| param_value(p, n).unwrap_or(f64::NAN))
            .collect();
        let scale: Vec<f64> = names
            .iter()
            .zip(&theta)
            .map(|(n, v)| typical_scale(n, *v))
            .collect();
        let res = |th: &[f64]| -> Vec<f64> {
            let mut q = p.clone();
            set_named(&mut q, &names, th);
            match submodel_series(&q, pts) {
                Ok(all) => all
                    .into_iter()
                    .find(|s| s.0 == f.submodel)
                    .map(|(_, meas, model)| meas.iter().zip(&model).map(|(a, b)| a - b).collect())
                    .unwrap_or_default(),
                Err(_) => vec![f64::NAN; pts.len()],
            }
        };
        let r = res(&theta);
        let j = fd_jacobian(res, &theta, &scale);
        out.extend(estimates(&names, &theta, &scale, &j, &r, 1));
    }
    out
}

/// Estimates of the step-2 actuator parameters from the actuator set `j` (positions against
/// the responses to the saturated commands).
pub fn step2_estimates(p: &Params, j: &DynamicData) -> Vec<(String, ParamEstimate)> {
    let mut out = Vec::new();
    for (names, cmd, pos, egr) in [
        (
            &["tau_egr1", "tau_egr2", "tau_degr", "k_egr"][..],
            "u_egr",
            "u_egr_pos",
            true,
        ),
        (&["tau_vgt", "tau_dvgt"][..], "u_vgt", "u_vgt_pos", false),
    ] {
        let (Some(u), Some(y)) = (j.get(cmd), j.get(pos)) else {
            continue;
        };
        let theta: Vec<f64> = names
            .iter()
            .map(|n| param_value(p, n).unwrap_or(f64::NAN))
            .collect();
        let scale: Vec<f64> = theta.iter().map(|v| v.abs().max(1e-3)).collect();
        let res = |th: &[f64]| -> Vec<f64> {
            let mut q = p.clone();
            set_named(&mut q, names, th);
            actuator_response(&q, &j.t, u, egr)
                .iter()
                .zip(y)
                .map(|(m, y)| m - y)
                .collect()
        };
        let r = res(&theta);
        let jac = fd_jacobian(res, &theta, &scale);
        out.extend(estimates(names, &theta, &scale, &jac, &r, 2));
    }
    out
}

/// The TOML path of a tunable parameter in a parameter file ("exhaust_manifold.v_em",
/// "cylinder.c_vol[0]", "compressor.q_c[0][1]"), found by marking the field that
/// [`param_mut`] names in a copy of `p` and locating the mark in its serialized form.
pub fn toml_path(p: &Params, name: &str) -> Option<String> {
    const MARK: f64 = -1.234_567_890_123e300;
    let mut q = p.clone();
    *param_mut(&mut q, name)? = MARK;
    let v = serde_json::to_value(&q).ok()?;
    fn find(v: &serde_json::Value, path: String) -> Option<String> {
        match v {
            serde_json::Value::Object(o) => o.iter().find_map(|(k, x)| {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                find(x, p)
            }),
            serde_json::Value::Array(a) => a
                .iter()
                .enumerate()
                .find_map(|(i, x)| find(x, format!("{path}[{i}]"))),
            serde_json::Value::Number(n) => (n.as_f64() == Some(MARK)).then_some(path),
            _ => None,
        }
    }
    find(&v, String::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_paths_of_parameters() {
        let p = Params::published();
        assert_eq!(
            toml_path(&p, "v_em").as_deref(),
            Some("exhaust_manifold.v_em")
        );
        assert_eq!(
            toml_path(&p, "c_vol2").as_deref(),
            Some("cylinder.c_vol[1]")
        );
        assert_eq!(toml_path(&p, "a3").as_deref(), Some("compressor.q_c[0][1]"));
        assert_eq!(
            toml_path(&p, "tau_vgt").as_deref(),
            Some("vgt_actuator.tau_vgt")
        );
        assert_eq!(toml_path(&p, "nonsense"), None);
    }

    #[test]
    fn straight_line_standard_errors_by_hand() {
        // y = a + b x with residuals +-e alternating: s^2 = n e^2 / (n - 2); J = -[1, x]
        let x: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let e = 0.1;
        let r: Vec<f64> = (0..10).map(|i| if i % 2 == 0 { e } else { -e }).collect();
        let j = DMatrix::from_fn(10, 2, |i, k| if k == 0 { -1.0 } else { -x[i] });
        let est = estimates(&["a", "b"], &[1.0, 2.0], &[1.0, 1.0], &j, &r, 1);
        let s2 = 10.0 * e * e / 8.0;
        let sxx: f64 = x.iter().map(|v| (v - 4.5) * (v - 4.5)).sum();
        // alternating residuals: negative autocorrelation, clamped to 0 (no deflation)
        assert!((est[1].1.std_error - (s2 / sxx).sqrt()).abs() < 1e-12);
        let sa = (s2 * (1.0 / 10.0 + 4.5 * 4.5 / sxx)).sqrt();
        assert!((est[0].1.std_error - sa).abs() < 1e-12);
        assert!(est[0].1.identifiable && est[1].1.identifiable);
    }

    #[test]
    fn flags_collinear_and_imprecise_parameters() {
        // two nearly equal columns: huge correlation; both not identifiable
        let j = DMatrix::from_fn(50, 2, |i, k| {
            let t = i as f64 / 50.0;
            if k == 0 {
                t
            } else {
                t * (1.0 + 1e-4 * t * t)
            }
        });
        let r: Vec<f64> = (0..50)
            .map(|i| 1e-3 * ((i * 7919) % 13) as f64 - 6e-3)
            .collect();
        let est = estimates(&["p", "q"], &[1.0, 1.0], &[1.0, 1.0], &j, &r, 5);
        for (_, e) in &est {
            assert!(!e.identifiable, "{e:?}");
            assert!(!e.correlated_with.is_empty());
        }
        // autocorrelated residuals inflate the error
        let smooth: Vec<f64> = (0..50).map(|i| 1e-3 * (i as f64 / 8.0).sin()).collect();
        let white: Vec<f64> = (0..50)
            .map(|i| if i % 2 == 0 { 7e-4 } else { -7e-4 })
            .collect();
        let jl = DMatrix::from_fn(50, 1, |i, _| i as f64);
        let a = estimates(&["x"], &[1.0], &[1.0], &jl, &smooth, 1)[0]
            .1
            .std_error;
        let b = estimates(&["x"], &[1.0], &[1.0], &jl, &white, 1)[0]
            .1
            .std_error;
        let ns: f64 = smooth.iter().map(|v| v * v).sum::<f64>();
        let nw: f64 = white.iter().map(|v| v * v).sum::<f64>();
        let rho = lag1_autocorrelation(&smooth).min(0.98);
        assert!(rho > 0.9, "{rho}");
        let want = (ns / nw).sqrt() * ((1.0 + rho) / (1.0 - rho)).sqrt();
        assert!((a / b / want - 1.0).abs() < 1e-9, "{a} {b} {want}");
    }
}
