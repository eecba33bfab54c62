//! Honest uncertainty of the tuning pipeline on full virtual campaigns (issue 14): every tuned
//! parameter lies within 3 reported standard errors of the truth with a relative standard
//! error of at most 25 %, or is flagged not identifiable with a reason; the physically
//! meaningful parameters stay identifiable.
//!
//! Heavy (the full pipeline on seeds 1-4, about a minute per campaign on 2 cores): `#[ignore]`d in CI, run
//! by `scripts/tuning-uncertainty.sh` (`cargo test --release -p mvem --test tuning_uncertainty
//! -- --ignored`).

use mvem::params::Params;
use mvem::tuning::lab::{self, LabOptions};
use mvem::tuning::pipeline::{self, PipelineOptions};

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

fn check_campaign(seed: u64) -> Vec<String> {
    let truth = Params::published();
    let opts = LabOptions {
        seed,
        ..LabOptions::default()
    };
    let (c, _) = lab::campaign(&truth, &opts).unwrap();
    let (_, rep) = pipeline::tune(&c, &truth, &PipelineOptions::default()).unwrap();
    let mut bad = Vec::new();
    assert!(rep.parameters.len() >= 45, "{}", rep.parameters.len());
    for (path, e) in &rep.parameters {
        let t = if path == "test_cell.tau_me" {
            opts.tau_me_s
        } else {
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
    for m in MEANINGFUL {
        let e = &rep.parameters[m];
        if !e.identifiable {
            bad.push(format!("seed {seed}: {m} not identifiable ({})", e.reason));
        }
    }
    bad
}

#[test]
#[ignore = "heavy: the full pipeline on four campaigns; scripts/tuning-uncertainty.sh"]
fn tuned_parameters_lie_within_their_standard_errors() {
    let bad: Vec<String> = [1, 2, 3, 4].into_iter().flat_map(check_campaign).collect();
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
