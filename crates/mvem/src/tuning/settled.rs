//! Settled operating points read from the dynamic data sets: the ends of their command steps.
//!
//! The paper tunes the static submodels on the stationary points and on "the data sets A to I"
//! (section 8.1, Table 1). Where a dynamic set holds its commands for a few seconds, the engine
//! settles, and the end of the hold is a stationary measurement of every quantity the set
//! records. For the compressor flow (eqs (66)-(72)) that is all of its inputs and its output:
//! p_c (= p_im in the 8- and 10-state models), n_t and W_c, with the campaign's ambient
//! conditions. These points reach where the stationary design does not: on `mvem lab`
//! campaigns the 82 stationary points hold 5 with Pi_c < 1.06, all at W_c <= 0.12 kg/s, while
//! set A (1200 rpm, 25 % load) settles around Pi_c 1.03 at W_c 0.12-0.14 kg/s on many of its
//! 77 steps. There, a flow map fitted to the stationary points alone can be 8-15 % low (seed 5),
//! and the tuned model then has no equilibrium where the engine sits (it oscillates,
//! docs/tuning.md, session 15). [`flow_points`] returns those points for step 1's compressor-flow
//! fit ([`super::steps::step1_with`]) and step 5's W_c submodel row
//! ([`super::complete::Step5Options::flow_points`]).
//!
//! A settled window is the part of a hold at least [`SETTLE_S`] after its step, to the end of
//! the hold; a hold shorter than that, or with fewer than two samples after it, gives no point.
//! The point is the window's mean of each signal.

use super::complete::segments;
use super::data::{Campaign, DynamicData, Role, StepKind};
use super::steps::FlowPoint;

/// Time after a command step from which a hold counts as settled \[s\]: several time constants
/// of the turbocharger speed (about 0.5-1 s at low load) and of the manifold pressures.
pub const SETTLE_S: f64 = 3.0;

/// Mean of `v` over the settled windows of `d` (one value per window, [`settled_windows`]).
fn window_means(v: &[f64], windows: &[(usize, usize)]) -> Vec<f64> {
    windows
        .iter()
        .map(|&(a, b)| v[a..b].iter().sum::<f64>() / (b - a) as f64)
        .collect()
}

/// Settled windows of a data set: per hold between command steps ([`segments`]), the sample
/// range `[a, b)` at least [`SETTLE_S`] after the hold's start, when it holds two samples or
/// more.
pub fn settled_windows(d: &DynamicData) -> Vec<(usize, usize)> {
    segments(d)
        .into_iter()
        .filter_map(|(s, e)| {
            let t0 = *d.t.get(s)? + SETTLE_S;
            let a = s + d.t[s..e].iter().position(|&t| t >= t0 - 1e-9)?;
            (e >= a + 2).then_some((a, e))
        })
        .collect()
}

/// Compressor flow points from the settled windows of the static-tuning VGT/EGR and fuel sets
/// (role "static"; not the actuator set), with the ambient pressure and temperature of the
/// stationary points (their mean: the dynamic sets do not record them). Empty without
/// stationary points; a set without p_im, n_t or W_c gives none; points whose means are not
/// finite and positive are left out.
pub fn flow_points(c: &Campaign) -> Vec<FlowPoint> {
    let n = c.stationary.len() as f64;
    if c.stationary.is_empty() {
        return Vec::new();
    }
    let p_amb = c.stationary.iter().map(|s| s.p_amb).sum::<f64>() / n;
    let t_amb = c.stationary.iter().map(|s| s.t_amb).sum::<f64>() / n;
    let mut out = Vec::new();
    for (info, d) in c.manifest.datasets.iter().zip(&c.dynamic) {
        if !info.roles.contains(&Role::Static) || info.kind == StepKind::Actuator {
            continue;
        }
        let (Some(p_im), Some(n_t), Some(w_c)) = (d.get("p_im"), d.get("n_t"), d.get("W_c")) else {
            continue;
        };
        let w = settled_windows(d);
        let (p_im, n_t, w_c) = (
            window_means(p_im, &w),
            window_means(n_t, &w),
            window_means(w_c, &w),
        );
        for k in 0..w.len() {
            let q = FlowPoint {
                p_c: p_im[k],
                p_amb,
                t_amb,
                n_t: n_t[k],
                w_c: w_c[k],
            };
            if [q.p_c, q.n_t, q.w_c]
                .iter()
                .all(|v| v.is_finite() && *v > 0.0)
            {
                out.push(q);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tuning::data::{DataSetInfo, Manifest, StationaryPoint};

    /// A VGT/EGR set at 2 Hz over 16 s with command steps at 2 s, 8 s and 10 s (holds of 6 s,
    /// 2 s and 6 s); in hold k (0 before the first step) p_im = 1.2e5 + 1e3 k Pa, W_c = 0.1 +
    /// 0.01 k kg/s and n_t = 1000 (k + 1) + t rpm.
    fn set() -> DynamicData {
        let t: Vec<f64> = (0..32).map(|i| i as f64 * 0.5).collect();
        let hold = |t: f64| [2.0, 8.0, 10.0].iter().filter(|&&s| t >= s).count() as f64;
        let col = |f: &dyn Fn(f64) -> f64| t.iter().map(|&x| f(x)).collect::<Vec<f64>>();
        DynamicData {
            name: "A".into(),
            columns: vec![
                ("n_e".into(), col(&|_| 1200.0)),
                ("u_delta".into(), col(&|_| 50.0)),
                ("u_egr".into(), col(&|_| 10.0)),
                ("u_vgt".into(), col(&|x| 40.0 + 10.0 * hold(x))),
                ("p_im".into(), col(&|x| 1.2e5 + 1e3 * hold(x))),
                ("n_t".into(), col(&|x| 1000.0 * (hold(x) + 1.0) + x)),
                ("W_c".into(), col(&|x| 0.1 + 0.01 * hold(x))),
            ],
            t,
        }
    }

    fn campaign(roles: Vec<Role>, kind: StepKind, stationary: Vec<StationaryPoint>) -> Campaign {
        Campaign {
            manifest: Manifest {
                stationary: "stationary.csv".into(),
                true_params: None,
                true_tau_me_s: None,
                true_sensor_lags_s: None,
                description: String::new(),
                columns: Default::default(),
                units: Default::default(),
                datasets: vec![DataSetInfo {
                    name: "A".into(),
                    roles,
                    kind,
                    file: "A.csv".into(),
                    sample_rate_hz: 2.0,
                    speed_rpm: None,
                    load_pct: None,
                    steps: Some(3),
                }],
            },
            stationary,
            dynamic: vec![set()],
        }
    }

    #[test]
    fn windows_start_settle_s_after_each_step_and_short_holds_give_none() {
        let d = set();
        // holds 2-8 s and 10-16 s: from 5 s to 7.5 s and from 13 s to 15.5 s; the 2-s hold
        // (8-10 s) is shorter than SETTLE_S; the stretch before the first step is no hold
        let w: Vec<(f64, f64)> = settled_windows(&d)
            .into_iter()
            .map(|(a, b)| (d.t[a], d.t[b - 1]))
            .collect();
        assert_eq!(w, vec![(5.0, 7.5), (13.0, 15.5)]);
    }

    #[test]
    fn flow_points_are_the_window_means_with_the_stationary_ambient() {
        let st = |p_amb, t_amb| StationaryPoint {
            p_amb,
            t_amb,
            ..StationaryPoint::default()
        };
        let stationary = vec![st(1.0e5, 300.0), st(1.02e5, 302.0)];
        let c = campaign(
            vec![Role::Static, Role::Validation],
            StepKind::VgtEgr,
            stationary.clone(),
        );
        let pts = flow_points(&c);
        // hold 1 (k = 1): n_t = 2000 + mean(5, 5.5, ..., 7.5) = 2006.25; hold 3: 4000 + 14.25
        let expect = [(1.21e5, 2006.25, 0.11), (1.23e5, 4014.25, 0.13)];
        assert_eq!(pts.len(), expect.len());
        for (q, (p_c, n_t, w_c)) in pts.iter().zip(expect) {
            assert_eq!((q.p_amb, q.t_amb), (1.01e5, 301.0));
            assert!((q.p_c - p_c).abs() < 1e-9, "{q:?}");
            assert!((q.n_t - n_t).abs() < 1e-9, "{q:?}");
            assert!((q.w_c - w_c).abs() < 1e-12, "{q:?}");
        }
        // an actuator set or a set without the static role gives none
        let none = campaign(vec![Role::Validation], StepKind::VgtEgr, stationary.clone());
        assert!(flow_points(&none).is_empty());
        let none = campaign(vec![Role::Static], StepKind::Actuator, stationary);
        assert!(flow_points(&none).is_empty());
        // without stationary points (no ambient conditions): none
        let none = campaign(vec![Role::Static], StepKind::VgtEgr, Vec::new());
        assert!(flow_points(&none).is_empty());
    }
}
