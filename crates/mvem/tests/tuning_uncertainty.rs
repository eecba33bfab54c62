//! Honest uncertainty of the tuning pipeline on full virtual campaigns (issue 14): every tuned
//! parameter lies within 3 reported standard errors of the truth with a relative standard
//! error of at most 25 %, or is flagged not identifiable with a reason; the physically
//! meaningful parameters stay identifiable.
//!
//! eta_tm,max may be flagged when its vertex BSR_opt lies outside the measured blade speed
//! ratios (the pipeline says so); then the combination it reports instead, eta_tm at the
//! measured point where it is best determined, must lie within 3 standard errors of the true eta_tm
//! there. eta_c,max is always flagged (errors in variables, session 10); then the combination
//! eta_c at the measured point where it is best determined must lie within 3 standard errors of
//! the true eta_c there. "Most" physically meaningful parameters (issue 14): at least 8 of the
//! 10 below.
//!
//! Heavy (the full pipeline on seeds 1-4: 184 s on a quiet 2-core machine; CI has 25 minutes
//! on 2 cores for everything): `#[ignore]`d, run by
//! `scripts/tuning-uncertainty.sh` (`cargo test --release -p mvem --test tuning_uncertainty --
//! --ignored`). It passes on seeds 1-4 since session 17 (344 s beside a CI run): every
//! parameter reported identifiable lies within 3 standard errors, eta_tm and eta_c at their
//! measured points too, and at most two of V_im, V_em, J_t are flagged. Before, seed 2 failed
//! (V_im, V_em, J_t flagged, rel. std. errors 59, 145, 26 %, session 16) and, before session
//! 16's least-squares step levels, seed 4 as well (`scripts/tuning-compare.py`). The sensor
//! time constants that step 3 fits by default are 0 in these campaigns. Session 18 found that
//! the standard errors of steps 3 and 5 moved with the integrator's step sequence (their
//! Jacobians were the searches' forward differences at 1e-4, noise-dominated in some columns):
//! a 1e-14 change of the model made seed 2 flag V_im, V_em and J_t, and seed 4 report eta_c
//! 3.9 standard errors off. Since both covariances use central differences at 3e-3
//! (`complete::covariance_jacobian`) it passes on seeds 1-4 again (271 s).
//!
//! Session 21: that pass rests on noise as well. The propagated part `S C_f S^T` of steps 3-5
//! uses J_f of the fixed parameters by forward differences at 1e-4, and its noise inflates the
//! fixed-parameter standard errors of V_im, V_em and J_t by 2-6x; with an accurate J_f (branch
//! `jf-directional`) this test fails on seeds 1, 2 and 4 (J_t 4 standard errors off, seed 4's
//! V_im 6.5), because step 3 inherits the bias of the static maps step 5 flags (compressor
//! efficiency, turbine), which no linear propagation of their covariance bounds
//! (docs/tuning.md, session 21). A numeric change of the integrator can flip its outcome
//! either way (the inverse stage solves did, session 20). Session 22: that J_f is on main as
//! `PipelineOptions::fixed_jacobian = SigmaPoints` (`mvem tune --fixed-jacobian sigma-points`,
//! not the default); its standard errors agree between builds within 2.4 % where forward
//! differences move by up to 6.9x, and over lab seeds 1-8 they give z rms 2.2 / 2.0 / 7.9 for
//! V_im, V_em, J_t (forward: 0.93 / 0.71 / 0.61) (docs/tuning.md, session 22).

use mvem::components::{compressor, turbine, Semantics};
use mvem::params::Params;
use mvem::tuning::lab::{self, LabOptions};
use mvem::tuning::pipeline::{self, PipelineOptions, TuneReport};
use mvem::tuning::steps::bsr_series;
use mvem::tuning::uncertainty::Combination;

/// Parameters that must be identifiable (volumes, inertia, actuator time constants, peak
/// efficiencies, the dynamometer constant).
const MEANINGFUL: [&str; 10] = [
    "intake_manifold.v_im",
    "exhaust_manifold.v_em",
    "turbo.j_t",
    "vgt_actuator.tau_vgt",
    "vgt_actuator.tau_dvgt",
    "egr_actuator.tau_egr1",
    "egr_actuator.tau_egr2",
    "turbine.eta_tmmax",
    "compressor.eta_cmax",
    "test_cell.tau_me",
];

/// The combination `name` of the report (panics when it is missing: the pipeline must report it
/// when it flags the parameter it stands for).
fn combination<'r>(rep: &'r TuneReport, name: &str) -> &'r Combination {
    rep.combinations
        .iter()
        .find(|k| k.name == name)
        .unwrap_or_else(|| panic!("combination {name} reported"))
}

/// The coordinate `name` of the point where a combination is evaluated.
fn coordinate(k: &Combination, name: &str) -> f64 {
    k.at.iter()
        .find(|(x, _)| x == name)
        .map(|x| x.1)
        .unwrap_or_else(|| panic!("{}: no coordinate {name}", k.name))
}

/// A complaint when combination `k` is more than 3 standard errors from the true value `t`
/// or its relative standard error is above 25 %; `what` names it.
fn off(k: &Combination, t: f64, what: &str) -> Option<String> {
    let z = (k.value - t) / k.std_error;
    let rel = k.std_error / k.value.abs();
    (!(z.abs() <= 3.0 && rel <= 0.25)).then(|| {
        format!(
            "{what} = {:.4} (true {t:.4}) is {z:.1} std. errors off, rel. std. error {:.2} %",
            k.value,
            100.0 * rel
        )
    })
}

fn check_campaign(seed: u64) -> Vec<String> {
    let truth = Params::published();
    let opts = LabOptions {
        seed,
        ..LabOptions::default()
    };
    let (c, _) = lab::campaign(&truth, &opts).unwrap();
    let (tuned, rep) = pipeline::tune(&c, &truth, &PipelineOptions::default()).unwrap();
    let mut bad = Vec::new();
    assert!(rep.parameters.len() >= 45, "{}", rep.parameters.len());
    for (path, e) in &rep.parameters {
        let t = if path == "test_cell.tau_me" {
            opts.tau_me_s
        } else if path.starts_with("test_cell.tau_") {
            0.0 // the campaign has no sensor lags
        } else {
            // the report's keys are registry names (1-based), read as they are
            truth
                .get(path)
                .unwrap_or_else(|| panic!("no true value of {path}"))
        };
        let z = (e.value - t) / e.std_error;
        let rel = e.std_error / e.value.abs();
        if e.identifiable && !(z.abs() <= 3.0 && rel <= 0.25) {
            bad.push(format!(
                "seed {seed}: {path} = {:.6e} (true {t:.6e}) is {z:.1} std. errors off, \
                 rel. std. error {:.2} %, reported identifiable",
                e.value,
                100.0 * rel
            ));
        }
        if !e.identifiable {
            assert!(!e.reason.is_empty(), "{path}: no reason");
        }
    }
    let mut not_identifiable = Vec::new();
    for m in MEANINGFUL {
        let e = &rep.parameters[m];
        if e.identifiable {
            continue;
        }
        if m == "turbine.eta_tmmax" && e.reason.contains("outside the measured BSR range") {
            // the combination instead: eta_tm (eq. (49)) at the measured point where the
            // pipeline says it is best determined, against the truth's eta_tm there
            let k = combination(&rep, "turbine.eta_tm_at_bsr");
            let (b, w) = (coordinate(k, "bsr"), coordinate(k, "omega_t"));
            // a measured point of the campaign
            assert!(bsr_series(&tuned, &c.stationary)
                .iter()
                .any(|(x, y)| *x == b && *y == w));
            let tt = &truth.turbine;
            let t =
                tt.eta_tmmax - turbine::c_m(tt, w, Semantics::Authors) * (b - tt.bsr_opt).powi(2);
            bad.extend(off(k, t, &format!("seed {seed}: eta_tm at BSR {b:.3}")));
            continue;
        }
        if m == "compressor.eta_cmax" && e.reason.contains("errors in variables") {
            // the combination instead: eta_c (eq. (62)) at the measured stationary point where
            // the pipeline says it is best determined, against the truth's eta_c there
            let k = combination(&rep, "compressor.eta_c_at_point");
            let (w, pi) = (coordinate(k, "w_c"), coordinate(k, "pi_c"));
            // a measured point of the campaign
            assert!(c
                .stationary
                .iter()
                .any(|s| s.w_c == w && compressor::pi_c(s.p_c, s.p_amb, Semantics::Authors) == pi));
            let t = compressor::efficiency(&truth.compressor, w, pi, Semantics::Authors);
            let what = format!("seed {seed}: eta_c at W_c {w:.3} kg/s, Pi_c {pi:.3}");
            bad.extend(off(k, t, &what));
            continue;
        }
        not_identifiable.push(format!("{m} ({})", e.reason));
    }
    if not_identifiable.len() > 2 {
        bad.push(format!(
            "seed {seed}: {} of the {} meaningful parameters not identifiable: {}",
            not_identifiable.len(),
            MEANINGFUL.len(),
            not_identifiable.join("; ")
        ));
    }
    bad
}

#[test]
#[ignore = "heavy (about 3-8 minutes on 2 cores; passes since session 17, by the noise of J_f: docs/tuning.md, session 21); scripts/tuning-uncertainty.sh"]
fn tuned_parameters_lie_within_their_standard_errors() {
    let bad: Vec<String> = [1, 2, 3, 4].into_iter().flat_map(check_campaign).collect();
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
