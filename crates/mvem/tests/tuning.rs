//! Tuning: the virtual test cell generates data from the published parameters; steps 1 and 2
//! recover them (noise-free: to tight tolerances; noisy: within stated bounds). Each step
//! starts from generic values (`Step1Start`, `Step2Start`), never from the published ones.

use mvem::model::ModelOrder;
use mvem::params::Params;
use mvem::tuning::data::{self, StationaryPoint};
use mvem::tuning::lab::{self, LabOptions, Noise};
use mvem::tuning::sensors::SensorLags;
use mvem::tuning::steps::{step1, step2, Step1Start, Step2Start};
use mvem::tuning::validate;

/// |a - b| / max(|b|, floor): relative error, absolute below `floor` (for parameters whose
/// true value is 0: c_egr3, c_Psi2, c_Phi2, x_cv ~ 2e-14).
fn err(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / b.abs().max(floor)
}

fn published_value(p: &Params, name: &str) -> f64 {
    let (c, t, e, k, v) = (
        &p.cylinder,
        &p.turbine,
        &p.egr_valve,
        &p.compressor,
        &p.exhaust_pipe,
    );
    match name {
        "c_vol1" => c.c_vol[0],
        "c_vol2" => c.c_vol[1],
        "c_vol3" => c.c_vol[2],
        "eta_igch" => c.eta_igch,
        "c_fric1" => c.c_fric[0],
        "c_fric2" => c.c_fric[1],
        "c_fric3" => c.c_fric[2],
        "pi_egropt" => e.pi_egropt,
        "c_egr1" => e.c_egr[0],
        "c_egr2" => e.c_egr[1],
        "c_egr3" => e.c_egr[2],
        "eta_tmmax" => t.eta_tmmax,
        "bsr_opt" => t.bsr_opt,
        "c_m1" => t.c_m[0],
        "c_m2" => t.c_m[1],
        "c_m3" => t.c_m[2],
        "k_t" => t.k_t,
        "c_f1" => t.c_f1,
        "c_f2" => t.c_f2,
        "c_vgt1" => t.c_vgt1,
        "c_vgt2" => t.c_vgt2,
        "eta_sc" => c.eta_sc,
        "x_cv" => c.x_cv,
        "h_tot" => v.h_tot,
        "eta_cmax" => k.eta_cmax,
        "w_copt" => k.w_copt,
        "pi_copt" => k.pi_copt,
        "c_pi" => k.c_pi,
        "a1" => k.q_c[0][0],
        "a2" => k.q_c[1][1],
        "a3" => k.q_c[0][1],
        "c_psi2" => k.c_psi2,
        "c_phi2" => k.c_phi2,
        "c_wpsi1" => k.c_wpsi[0],
        "c_wpsi2" => k.c_wpsi[1],
        "c_wpsi3" => k.c_wpsi[2],
        "c_wphi1" => k.c_wphi[0],
        "c_wphi2" => k.c_wphi[1],
        "c_wphi3" => k.c_wphi[2],
        "tau_egr1" => p.egr_actuator.tau_egr1,
        "tau_egr2" => p.egr_actuator.tau_egr2,
        "tau_degr" => p.egr_actuator.tau_degr,
        "k_egr" => p.egr_actuator.k_egr,
        "tau_vgt" => p.vgt_actuator.tau_vgt,
        "tau_dvgt" => p.vgt_actuator.tau_dvgt,
        _ => panic!("unknown parameter {name}"),
    }
}

fn stationary(noise: Noise, n: usize, seed: u64) -> (Vec<StationaryPoint>, Vec<StationaryPoint>) {
    let opts = LabOptions {
        noise,
        n_stationary: n,
        seed,
        ..LabOptions::default()
    };
    lab::stationary(&Params::published(), &opts).unwrap()
}

#[test]
fn step1_noise_free_recovers_published_parameters() {
    let p = Params::published();
    let (truth, _) = stationary(Noise::NONE, 40, 1);
    let (_, rep) = step1(&p, &truth, &Step1Start::default()).unwrap();
    for f in &rep.fits {
        eprintln!(
            "{:8} mean {:.2e} max {:.2e} n_eval {}",
            f.submodel, f.mean_abs_rel_err, f.max_abs_rel_err, f.n_eval
        );
        // every submodel reproduces its measurements (eq. (4)) to 1e-8
        assert!(
            f.max_abs_rel_err < 1e-8,
            "{}: {}",
            f.submodel,
            f.max_abs_rel_err
        );
        for (name, v) in &f.params {
            let truth = published_value(&p, name);
            // c_m2, c_m3: c_m(omega) = c_m1 (omega - c_m2)^c_m3 with c_m3 = 0.01 is nearly
            // constant in omega; these two are identified only to about 1e-4 (the fit residual
            // is 1e-9 relative). x_cv: true value 2e-14, at its lower bound.
            let (tol, floor) = match name.as_str() {
                "c_m2" | "c_m3" | "c_m1" => (1e-3, 1e-12),
                "x_cv" => (1e-8, 1.0),
                "c_egr3" | "c_psi2" | "c_phi2" => (1e-8, 1.0),
                _ => (1e-6, 1e-12),
            };
            let e = err(*v, truth, floor);
            eprintln!("    {name:10} {v:.10e} true {truth:.10e} err {e:.1e}");
            assert!(e < tol, "{name}: {v} vs {truth} (err {e:.2e} > {tol:.0e})");
        }
    }
}

#[test]
fn step1_noisy_submodel_errors_bounded() {
    // 82 points, realistic noise (0.5 % relative, 1 K). Bounds: the paper reports 0.9-6.1 %
    // mean error on real data (sections 4-6); with our noise model the fitted submodels should
    // explain the data to about the noise level of each derived measurement (eta_c,meas and
    // eta_tm,meas amplify the 1 K temperature noise through T_c - T_amb ~ 30-120 K).
    let p = Params::published();
    let (truth, meas) = stationary(Noise::REALISTIC, 82, 7);
    let (q, rep) = step1(&p, &meas, &Step1Start::default()).unwrap();
    // W_egr: Psi_egr depends on 1 - p_im/p_em, which is small at low load, so 0.5 % noise on
    // both pressures gives tens of per cent at single points (the paper: 6.1 % mean, 22.2 %
    // max on real data).
    let bound = |s: &str| match s {
        // W_c: Psi_c and Phi_c carry the noise of n_t (squared) and p_c as well
        "eta_c" | "eta_tm" | "W_c" => 0.03,
        "W_egr" => 0.08,
        _ => 0.012,
    };
    for f in &rep.fits {
        eprintln!(
            "{:8} mean {:.2e} max {:.2e}",
            f.submodel, f.mean_abs_rel_err, f.max_abs_rel_err
        );
        assert!(
            f.mean_abs_rel_err < bound(&f.submodel),
            "{}: mean {}",
            f.submodel,
            f.mean_abs_rel_err
        );
    }
    // The tuned submodels predict the noise-free truth (eq. (4) against the true outputs).
    let v = validate::stationary_errors(&q, &truth).unwrap();
    for r in &v {
        eprintln!(
            "vs truth {:8} mean {:.2e} max {:.2e}",
            r.output, r.mean_abs_rel_err, r.max_abs_rel_err
        );
        assert!(
            r.mean_abs_rel_err
                < if r.output == "eta_c" || r.output == "W_c" {
                    0.02
                } else {
                    0.01
                },
            "{}: {}",
            r.output,
            r.mean_abs_rel_err
        );
    }
}

#[test]
fn step2_recovers_actuator_parameters() {
    let p = Params::published();
    for (noise, tol) in [(Noise::NONE, 1e-6), (Noise::REALISTIC, 0.03)] {
        let opts = LabOptions {
            noise,
            ..LabOptions::default()
        };
        let j = lab::actuator_set(&p, &opts);
        let (_, reps) = step2(&p, &j, &Step2Start::default()).unwrap();
        for f in &reps {
            for (name, v) in &f.params {
                let truth = published_value(&p, name);
                let e = err(*v, truth, 1e-12);
                eprintln!("{name:9} {v:.8} true {truth:.8} err {e:.1e}");
                assert!(e < tol, "{name}: {v} vs {truth}, noise {noise:?}");
            }
        }
    }
}

#[test]
fn campaign_roundtrip_is_deterministic() {
    let p = Params::published();
    let opts = LabOptions {
        n_stationary: 15,
        ..LabOptions::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let c = lab::generate(&p, &opts, dir.path()).unwrap();
    let back = data::load_campaign(dir.path()).unwrap();
    assert_eq!(back, c);
    let again = lab::campaign(&p, &opts).unwrap().0;
    assert_eq!(again, c, "same seed, same campaign");
    let other = lab::campaign(&p, &LabOptions { seed: 2, ..opts })
        .unwrap()
        .0;
    assert_ne!(other.stationary, c.stationary);
    assert_eq!(
        mvem::io::params::load_params(&dir.path().join("true_params.toml")).unwrap(),
        p
    );
}

#[test]
fn validation_tables_dynamic_and_actuator() {
    use mvem::model::Drive;
    let p = Params::published();
    let opts = LabOptions {
        noise: Noise::NONE,
        ..LabOptions::default()
    };
    // VGT and EGR steps at 1500 r/min, 50 % load, sampled at 10 Hz
    let d0 = Drive::new(1500.0, 0.5 * lab::U_DELTA_MAX, 20.0, 60.0);
    let steps = [(2.0, 3, 40.0), (5.0, 2, 40.0), (8.0, 3, 60.0)];
    let set = lab::step_set(&p, &opts, "E", d0, &steps, 10.0, 10.0).unwrap();
    assert_eq!(set.t.len(), 101);
    let (truth, _) = stationary(Noise::NONE, 15, 3);
    // the same model on its own data: only the resampling of the commands differs
    // the measured torque is M_dynamo (eq. (76), tau_Me = 1 s in the lab): filter the model too
    let own = validate::dynamic_errors_with(
        mvem::model::ModelOrder::Eight,
        &p,
        &set,
        &truth,
        Some(opts.tau_me_s),
        &SensorLags::NONE,
    )
    .unwrap();
    assert_eq!(own.outputs.len(), 5);
    for o in &own.outputs {
        assert!(
            o.max_abs_rel_err < 1e-4,
            "{}: {}",
            o.output,
            o.max_abs_rel_err
        );
    }
    // a 50 % larger intake manifold changes the transients (p_im visibly)
    let mut q = p.clone();
    q.intake_manifold.v_im *= 1.5;
    q.turbo.j_t *= 1.5;
    let other = validate::dynamic_errors(&q, &set, &truth).unwrap();
    let pim = other.outputs.iter().find(|o| o.output == "n_t").unwrap();
    assert!(pim.max_abs_rel_err > 1e-3, "{pim:?}");
    // actuator set: exact with the true parameters
    let j = lab::actuator_set(&p, &opts);
    let a = validate::actuator_errors(&p, &j).unwrap();
    assert!(a.outputs.iter().all(|o| o.max_abs_rel_err < 1e-12), "{a:?}");
    let report = validate::ValidationReport {
        stationary: validate::stationary_errors(&p, &truth).unwrap(),
        datasets: vec![own, a],
    };
    assert!(report.stationary.iter().all(|o| o.max_abs_rel_err < 1e-9));
    let md = report.to_markdown();
    assert!(md.contains("| p_im |") && md.contains("| W_egr |"), "{md}");
    assert_eq!(report.to_csv().lines().count(), 1 + 8 + 5 + 2);
    serde_json::to_string(&report).unwrap();
}

/// A campaign with the sensor lags of Table 6 (`mvem lab --sensor-lags`) is reproduced by the
/// true parameters seen through the same lags (each lag exact for an input linear between the
/// 2 ms grid points: both grids 2 ms), and not without them: the lag moves p_em by more than
/// 0.1 % of its mean on a VGT step.
#[test]
fn sensor_lags_reproduce_a_lagged_campaign() {
    use mvem::model::Drive;
    let p = Params::published();
    let opts = LabOptions {
        noise: Noise::NONE,
        sensor_lags: true,
        tau_me_s: 0.0,
        ..LabOptions::default()
    };
    let d0 = Drive::new(1500.0, 0.5 * lab::U_DELTA_MAX, 20.0, 60.0);
    let steps = [(1.0, 3, 40.0), (3.0, 2, 40.0), (5.0, 3, 60.0)];
    let set = lab::step_set(&p, &opts, "B", d0, &steps, 7.0, 100.0).unwrap();
    let (truth, _) = stationary(Noise::NONE, 15, 3);
    let err = |lags: &SensorLags| {
        validate::dynamic_errors_with(ModelOrder::Eight, &p, &set, &truth, None, lags).unwrap()
    };
    let with = err(&SensorLags::TABLE6);
    for o in with.outputs.iter().filter(|o| o.output != "M_e") {
        assert!(
            o.max_abs_rel_err < 2e-5,
            "{}: {}",
            o.output,
            o.max_abs_rel_err
        );
    }
    let without = err(&SensorLags::NONE);
    let pem = without.outputs.iter().find(|o| o.output == "p_em").unwrap();
    assert!(pem.max_abs_rel_err > 1e-3, "{pem:?}");
}

/// Step 1's compressor-efficiency fit reaches the least-squares optimum on another engine: on
/// the 2-litre engine of `tests/data/engine_2l.toml` (W_c a third of the published engine's),
/// with the published start alone the variable projection ended in a local minimum whose
/// projected map missed the measured eta_c by 9.2-9.9 % on average (seeds 2 and 3; the true map
/// 3.0 %), and the complete model then settled 30 % low in boost on the high-load sets. With
/// the ellipse centres at the data's quartiles as further starts the fit is at least as good as
/// the true map on its own criterion (it is that criterion's optimum), on every seed.
#[test]
fn eta_c_fit_reaches_the_optimum_on_a_2_litre_engine() {
    let truth = engine("engine_2l.toml");
    for seed in [1, 2, 3] {
        let meas = lab_stationary(
            &truth,
            seed,
            lab::Envelope {
                n_lo_rpm: 1750.0,
                n_hi_rpm: 4250.0,
                full_load_mg: 52.0,
            },
        );
        let (fit, _) = step1(&truth, &meas, &Step1Start::default()).unwrap();
        let (e_fit, e_true) = (
            mean_err(&fit, &meas, "eta_c"),
            mean_err(&truth, &meas, "eta_c"),
        );
        eprintln!("seed {seed}: eta_c mean error {e_fit:.4} (true map {e_true:.4})");
        assert!(e_fit < 0.04, "seed {seed}: {e_fit}");
        assert!(e_fit <= 1.02 * e_true, "seed {seed}: {e_fit} vs {e_true}");
    }
}

/// QA finding: `mvem lab` on a 5-litre engine with a small turbocharger (`tests/data/
/// engine_5l.toml`, speeds 1000-2600 rpm, 130 mg at full load) wrote a stationary point with
/// p_em = 1.15 MPa, which its own loader refused (outside the plausible 0.05-1 MPa, since
/// widened to 2 MPa). The lab redraws points near a range's edge, so what it writes loads.
#[test]
fn the_lab_writes_only_what_its_loader_accepts() {
    let truth = engine("engine_5l.toml");
    let opts = LabOptions {
        seed: 1,
        n_stationary: 82,
        dynamic: false,
        envelope: lab::Envelope {
            n_lo_rpm: 1000.0,
            n_hi_rpm: 2600.0,
            full_load_mg: 130.0,
        },
        ..LabOptions::default()
    };
    let (c, _) = lab::campaign(&truth, &opts).unwrap();
    let dir = tempfile::tempdir().unwrap();
    data::save_campaign(dir.path(), &c).unwrap();
    let back = data::load_campaign(dir.path()).unwrap();
    assert_eq!(back.stationary.len(), 82);
    let max_p_em = back.stationary.iter().map(|s| s.p_em).fold(0.0, f64::max);
    assert!(max_p_em <= data::PLAUSIBLE_P_MAX, "{max_p_em}");
}

/// QA (a larger engine than the loader's old ranges): `mvem lab` on a 100-litre, 20-cylinder
/// engine (`tests/data/engine_102l_scaled.toml`, 528 mg at full load) stopped with "no
/// physically valid steady state found for stationary point 1 after 200 draws": the point was
/// valid, but its fuel was beyond the loader's 500 mg, so no campaign of the engine could be
/// written or loaded. The ranges hold such an engine now (`data::PLAUSIBLE_*`); where a point
/// still leaves them, the error says which value and range.
#[test]
fn a_100_litre_engines_campaign_is_written_and_loads() {
    let big = engine("engine_102l_scaled.toml");
    let envelope = lab::Envelope {
        n_lo_rpm: 700.0,
        n_hi_rpm: 1800.0,
        full_load_mg: 528.0,
    };
    let opts = LabOptions {
        seed: 3,
        n_stationary: 13,
        dynamic: false,
        envelope,
        ..LabOptions::default()
    };
    let (c, _) = lab::campaign(&big, &opts).unwrap();
    let dir = tempfile::tempdir().unwrap();
    data::save_campaign(dir.path(), &c).unwrap();
    let back = data::load_campaign(dir.path()).unwrap();
    let max = |f: fn(&StationaryPoint) -> f64| back.stationary.iter().map(f).fold(0.0, f64::max);
    assert_eq!(back.stationary.len(), 13);
    assert_eq!(max(|s| s.u_delta), 528.0);
    // the loaded points are a large engine's (seed 3: W_c 4.1 kg/s, M_e 14.8 kNm)
    assert!(max(|s| s.w_c) > 3.0, "{}", max(|s| s.w_c));
    assert!(max(|s| s.m_e) > 1.2e4, "{}", max(|s| s.m_e));
    // the same cylinders' fuel of 5 cylinders four times the size: 2112 mg, beyond 2000 mg
    let mut huge = big.clone();
    huge.cylinder.n_cyl = 5.0;
    huge.input_saturation.u_delta = [1.0, 2200.0];
    let opts = LabOptions {
        envelope: lab::Envelope {
            full_load_mg: 4.0 * 528.0,
            ..envelope
        },
        ..opts
    };
    let e = lab::campaign(&huge, &opts).unwrap_err().to_string();
    assert!(
        e.starts_with(
            "no physically valid steady state found for stationary point 1 after 200 draws (the \
             last: n_e "
        ),
        "{e}"
    );
    assert!(
        e.contains(
            "u_delta = 2112 mg/cycle at or within five noise standard deviations of the edge of \
             the loader's plausible range [0, 2000] mg/cycle"
        ),
        "{e}"
    );
}

/// QA finding: with 8 stationary points (`tests/data/stationary_8_points.csv`, of the 5-litre
/// engine of `tests/data/engine_5l.toml`) the EGR fit put c_egr1 at +2.8e-5, and the tuned
/// file was refused ("c_egr1 must be < 0"). Step 1 keeps c_egr1 at most `C_EGR1_MAX` (the
/// constrained least-squares optimum), the result is a valid parameter set, and the bound is
/// reported.
#[test]
fn step1_keeps_c_egr1_negative_on_few_points() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let base = mvem::io::params::load_params(&dir.join("engine_5l.toml")).unwrap();
    let pts = data::load_stationary_csv(
        &dir.join("stationary_8_points.csv"),
        &data::Layout::default(),
    )
    .unwrap();
    assert_eq!(pts.len(), 8);
    let (p, r) = step1(&base, &pts, &Step1Start::default()).unwrap();
    assert_eq!(p.egr_valve.c_egr[0], mvem::tuning::steps::C_EGR1_MAX);
    assert!(p.validate().is_ok(), "{:?}", p.validate());
    let at =
        mvem::tuning::steps::at_bounds(&r, &mvem::tuning::scale::CampaignScale::of(&base, &pts));
    assert!(at.iter().any(|(n, _, _)| n == "c_egr1"), "{at:?}");
    // a fit all the same (22 % mean error of eq. (4) on 8 points, 4 of them with the valve open)
    let egr = r.fits.iter().find(|f| f.submodel == "W_egr").unwrap();
    assert!(egr.mean_abs_rel_err < 0.3, "{egr:?}");
}

/// A parameter file of `tests/data`.
fn engine(file: &str) -> Params {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(file);
    mvem::io::params::load_params(&path).unwrap()
}

/// The 82 noisy stationary points `mvem lab --params FILE --seed SEED` writes in `envelope`.
fn lab_stationary(truth: &Params, seed: u64, envelope: lab::Envelope) -> Vec<StationaryPoint> {
    let opts = LabOptions {
        seed,
        noise: Noise::REALISTIC,
        n_stationary: 82,
        dynamic: false,
        envelope,
        ..LabOptions::default()
    };
    lab::stationary(truth, &opts).unwrap().1
}

/// The published envelope with `full_load_mg` at full load.
fn full_load(full_load_mg: f64) -> lab::Envelope {
    lab::Envelope {
        full_load_mg,
        ..lab::Envelope::PUBLISHED
    }
}

/// Mean error of eq. (4) of the submodel `what` with `p` at the points `pts`.
fn mean_err(p: &Params, pts: &[StationaryPoint], what: &str) -> f64 {
    validate::stationary_errors(p, pts)
        .unwrap()
        .into_iter()
        .find(|o| o.output == what)
        .unwrap()
        .mean_abs_rel_err
}

/// The boxes of steps 1 and 5 follow the campaign's measured scale (`tuning::scale`) only
/// outside the band of the published engine's campaigns: on those (seeds 1-8, largest W_c
/// 0.57-0.74 kg/s) every box is `STATIC_PARAMS`' own, so their tuning is unchanged bit for bit.
#[test]
fn the_published_campaigns_keep_the_published_boxes() {
    use mvem::tuning::complete::{K_IC_PARAM, STATIC_PARAMS};
    use mvem::tuning::scale::CampaignScale;
    let p = Params::published();
    for seed in 1..=8 {
        let s = CampaignScale::of(&p, &lab_stationary(&p, seed, full_load(220.0)));
        for b in STATIC_PARAMS.iter().chain([&K_IC_PARAM]) {
            assert_eq!(s.apply(*b), *b, "seed {seed}: {s:?}");
        }
    }
    // nothing measured: nothing widened
    let none = CampaignScale::of(&p, &[]);
    assert_eq!(none.apply(STATIC_PARAMS[21]), STATIC_PARAMS[21]);
}

/// QA finding: step 1's compressor-efficiency box was the published engine's (W_copt at most
/// 2 kg/s). On the published engine scaled physically to 2.5 times its flow
/// (`tests/data/engine_32l_scaled.toml`), seed 4 put W_copt on that edge, where the same
/// campaign of the published engine has it at 1.77 kg/s (2.8 times its largest flow): the
/// search was cut by the box, not stopped by the data. The box now grows with the largest
/// measured W_c (2.5 times it, at least 2 kg/s): W_copt is off every edge and the fit at the
/// data is at least as good as the true map's.
#[test]
fn step1_boxes_follow_a_larger_engines_flow() {
    use mvem::tuning::scale::CampaignScale;
    let truth = engine("engine_32l_scaled.toml");
    let pts = lab_stationary(&truth, 4, full_load(206.25));
    let scale = CampaignScale::of(&truth, &pts);
    // 1.6 kg/s: the box of W_copt is 2.5 times it, the published one's 2 kg/s is below
    assert!((1.5..1.7).contains(&scale.w_c_max), "{scale:?}");
    let w_copt_box = mvem::tuning::complete::STATIC_PARAMS
        .iter()
        .find(|b| b.name == "w_copt")
        .map(|b| scale.apply(*b))
        .unwrap();
    assert!((w_copt_box.hi / (2.5 * scale.w_c_max) - 1.0).abs() < 1e-12);
    let (fit, r) = step1(&truth, &pts, &Step1Start::default()).unwrap();
    let at = mvem::tuning::steps::at_bounds(&r, &scale);
    assert!(
        !at.iter().any(|(n, _, _)| n == "w_copt" || n == "pi_copt"),
        "{at:?}"
    );
    let w_copt = fit.compressor.w_copt;
    assert!(w_copt > 2.0 && w_copt < 0.99 * w_copt_box.hi, "{w_copt}");
    let (e_fit, e_true) = (
        mean_err(&fit, &pts, "eta_c"),
        mean_err(&truth, &pts, "eta_c"),
    );
    assert!(e_fit <= 1.02 * e_true, "{e_fit} vs {e_true}");
}

/// A small engine's Q_c: a1 weighs (W_c - W_copt)^2 in (kg/s)^-2, so the published engine
/// scaled to 0.39 of its flow (`tests/data/engine_5l_scaled.toml`, 5 dm^3, 4 cylinders) has
/// a1 = 3.09 / 0.39^2 = 20, and one of a tenth of the flow 309, beyond the published box of
/// [0, 100] that step 5 keeps (a1 >= 0 is a physical bound, not widened around the start). The
/// box of a1 grows with (0.5 kg/s / W_c,max)^2 below 0.5 kg/s, that of a3 with its first power.
#[test]
fn q_c_boxes_follow_a_smaller_engines_flow() {
    use mvem::tuning::complete::STATIC_PARAMS;
    use mvem::tuning::scale::CampaignScale;
    let truth = engine("engine_5l_scaled.toml");
    let pts = lab_stationary(&truth, 1, full_load(129.5));
    let scale = CampaignScale::of(&truth, &pts);
    let bx = |n: &str| {
        STATIC_PARAMS
            .iter()
            .find(|b| b.name == n)
            .map(|b| scale.apply(*b))
            .unwrap()
    };
    let k = 0.5 / scale.w_c_max;
    assert!(k > 1.7, "{scale:?}");
    let near = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-12;
    assert!(near(bx("a1").hi, 100.0 * k * k), "{:?}", bx("a1"));
    assert!(near(bx("a3").lo, -100.0 * k) && near(bx("a3").hi, 100.0 * k));
    // the true a1 lies inside, with the published box's margin
    assert!(truth.compressor.q_c[0][0] < 0.2 * bx("a1").hi);
    // an area the engine's file declares too small for its flows (half the true A_vgtmax)
    // widens the boxes of c_f1, c_f2 (eq. (52)): f_vgt must reach twice the published range
    let mut half = truth.clone();
    half.turbine.a_vgtmax *= 0.5;
    let s2 = CampaignScale::of(&half, &pts);
    assert!((s2.f_vgt_max / scale.f_vgt_max - 2.0).abs() < 1e-9);
    let c_f1 = STATIC_PARAMS.iter().find(|b| b.name == "c_f1").unwrap();
    assert!(s2.apply(*c_f1).hi > c_f1.hi);
    assert_eq!(scale.apply(*c_f1), *c_f1);
}

/// The names of the tuned parameters in `text` (a reason, a caveat): the words that look like a
/// parameter path with an element index ("egr_valve.c_egr[1]").
fn element_names_in(text: &str) -> Vec<&str> {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || "_.[]".contains(c)))
        .map(|w| w.trim_end_matches('.'))
        .filter(|w| w.contains('.') && w.ends_with(']'))
        .collect()
}

/// A name taken from a tuning report is accepted verbatim where parameters are named: every key
/// of the report's "parameters" (step 1 on a small virtual campaign: the vectors c_vol, c_fric,
/// c_egr, c_m, c_wpsi, c_wphi and the matrix q_c) is a path of the parameter registry, 1-based as
/// the FMU, `mvem params check` and Python's `params=` count, and reads back the tuned value
/// with [`Params::get`] (Python's overrides resolve the same registry paths). Before, the report
/// named c_fric1 "cylinder.c_fric[0]", which `Params::get` does not know, and c_fric2
/// "cylinder.c_fric[1]", which it reads as c_fric1.
#[test]
fn report_names_are_registry_names_that_read_back_the_tuned_values() {
    use mvem::params::ParamInfo;
    use mvem::tuning::pipeline::{self, PipelineOptions};
    let truth = Params::published();
    let lab_opts = LabOptions {
        n_stationary: 30,
        dynamic: false,
        ..LabOptions::default()
    };
    let (c, _) = lab::campaign(&truth, &lab_opts).unwrap();
    let opts = PipelineOptions {
        steps: [true, false, false, false, false],
        ..PipelineOptions::default()
    };
    let (tuned, rep) = pipeline::tune(&c, &truth, &opts).unwrap();
    let mut elements = Vec::new();
    for (key, e) in &rep.parameters {
        let info = ParamInfo::find(key).unwrap_or_else(|| panic!("{key}: not a parameter name"));
        assert_eq!(&info.path, key, "the report's key is the registry's path");
        assert_eq!(
            tuned.get(key),
            Some(e.value),
            "{key} reads back the tuned value"
        );
        if key.contains('[') {
            elements.push(key.as_str());
        }
        // the parameters a reason names are registry names too
        for name in element_names_in(&e.reason) {
            let found = ParamInfo::find(name).map(|i| i.path.as_str());
            assert_eq!(
                found,
                Some(name),
                "{key}: reason names {name}: {}",
                e.reason
            );
        }
    }
    for text in &rep.caveats {
        for name in element_names_in(text) {
            let found = ParamInfo::find(name).map(|i| i.path.as_str());
            assert_eq!(found, Some(name), "caveat names {name}: {text}");
        }
    }
    // every element of the step-1 vectors and of Q_c (a3 once: the symmetric entry)
    assert!(elements.len() >= 20, "{elements:?}");
    // 1-based: the first friction coefficient is [1], the third [3], there is no [0]
    assert_eq!(
        rep.parameters["cylinder.c_fric[1]"].value,
        tuned.cylinder.c_fric[0]
    );
    assert_eq!(
        rep.parameters["cylinder.c_fric[3]"].value,
        tuned.cylinder.c_fric[2]
    );
    assert!(!rep.parameters.contains_key("cylinder.c_fric[0]"));
    assert_eq!(
        rep.parameters["compressor.q_c[1][2]"].value,
        tuned.compressor.q_c[0][1]
    );
    assert_eq!(
        ParamInfo::find("cylinder.c_fric[1]").unwrap().symbol,
        "c_fric1"
    );
}
