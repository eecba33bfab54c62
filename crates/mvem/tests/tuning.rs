//! Tuning: virtual test cell + steps 1-2 recover the parameters that generated the data.

use mvem::params::Params;
use mvem::tuning::lab::{self, LabOptions, Noise};
use mvem::tuning::steps::{step1, Step1Start};

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

#[test]
fn step1_noise_free_recovers_published() {
    let p = Params::published();
    let opts = LabOptions {
        noise: Noise::NONE,
        n_stationary: 40,
        ..LabOptions::default()
    };
    let (truth, _) = lab::stationary(&p, &opts).unwrap();
    let (q, rep) = step1(&p, &truth, &Step1Start::default()).unwrap();
    for f in &rep.fits {
        eprintln!("{:8} mean {:.2e} max {:.2e} n_eval {} {:?}", f.submodel, f.mean_abs_rel_err, f.max_abs_rel_err, f.n_eval, f.params);
    }
    eprintln!("{:?}\n{:?}", p.turbine, q.turbine);
    eprintln!("{:?}\n{:?}", p.compressor, q.compressor);
    let _ = rel;
}
