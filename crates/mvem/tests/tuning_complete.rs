//! Tuning steps 3-5 and the pipeline on small virtual campaigns (cheap: a few seconds in
//! release). Every search starts from generic values, never from the true parameters.

use mvem::params::Params;
use mvem::tuning::complete::{
    self, naive_theta, param_value, static_theta, step3, step4, Cost77, Step3Start, Step5Options,
    StepLevels, STATIC_PARAMS,
};
use mvem::tuning::data::Role;
use mvem::tuning::lab::{self, first_order_lag, LabOptions, Noise};
use mvem::tuning::pipeline::{self, parse_steps, PipelineOptions};

fn small(
    noise: Noise,
    sets: &[&str],
    max_steps: usize,
    n_stat: usize,
) -> mvem::tuning::data::Campaign {
    let opts = LabOptions {
        noise,
        n_stationary: n_stat,
        sets: Some(sets.iter().map(|s| s.to_string()).collect()),
        max_steps: Some(max_steps),
        ..LabOptions::default()
    };
    lab::campaign(&Params::published(), &opts).unwrap().0
}

/// The validation of the tuned `p` on the sets of `c` with the role validation, with the test
/// cell `rep` estimated.
fn validation_of(
    c: &mvem::tuning::data::Campaign,
    p: &Params,
    rep: &pipeline::TuneReport,
) -> mvem::tuning::validate::ValidationReport {
    mvem::tuning::validate::validate_campaign_with(
        mvem::model::ModelOrder::Eight,
        c,
        p,
        rep.tau_me_s,
        &rep.sensor_lags.unwrap_or_default(),
        Some(&[Role::Validation]),
    )
    .unwrap()
}

#[test]
fn first_order_lag_matches_closed_form() {
    // step at t = 0 (u jumps between samples 0 and 1 linearly, then constant): compare with the
    // exact response of the lag to that piecewise-linear input
    let tau = 0.7;
    let t: Vec<f64> = (0..200).map(|k| k as f64 * 0.05).collect();
    let u: Vec<f64> = t.iter().map(|&x| 2.0 * x + 1.0).collect(); // ramp: y = u - 2 tau (1 - e^-t/tau)
    let y = first_order_lag(&t, &u, tau);
    for (k, &x) in t.iter().enumerate() {
        let exact = 2.0 * x + 1.0 - 2.0 * tau * (1.0 - (-x / tau).exp());
        assert!((y[k] - exact).abs() < 1e-12, "t {x}: {} vs {exact}", y[k]);
    }
    assert_eq!(first_order_lag(&t, &u, 0.0), u);
}

#[test]
fn lab_table1_sets_have_the_published_shape() {
    let c = small(Noise::NONE, &["B", "I", "A"], 3, 13);
    for (name, hz, kind) in [
        ("A", 1.0, "vgt-egr"),
        ("B", 100.0, "vgt-egr"),
        ("I", 10.0, "fuel"),
    ] {
        let (info, d) = c.dataset(name).unwrap();
        assert_eq!(info.sample_rate_hz, hz);
        assert_eq!(info.steps, Some(3));
        let dt = d.t[1] - d.t[0];
        assert!((dt - 1.0 / hz).abs() < 1e-12, "{name}: dt {dt}");
        // exactly 3 command changes
        assert_eq!(complete::step_indices(d).len(), 3, "{name}");
        assert_eq!(
            serde_json::to_value(info.kind).unwrap(),
            serde_json::Value::from(kind)
        );
    }
    assert!(c.dataset("B").unwrap().0.roles.contains(&Role::Dynamic));
    assert!(c.dataset("J").is_some());
    assert_eq!(c.manifest.true_tau_me_s, Some(1.0));
    // deterministic
    let again = small(Noise::NONE, &["B", "I", "A"], 3, 13);
    assert_eq!(again, c);
}

#[test]
fn steps_3_and_4_recover_dynamics_noise_free() {
    // noise-free campaign (B, C, I; 6 steps each): V_im, V_em, J_t from the generic start
    // (38 dm^3, 38 dm^3, 1e-4 kg m^2) and tau_Me from 0.3 s. Measured: 3e-4 relative.
    let p = Params::published();
    let c = small(Noise::NONE, &["B", "C", "I"], 6, 13);
    let sets: Vec<_> = ["B", "C"].iter().map(|n| c.dataset(n).unwrap().1).collect();
    let (q, rep) = step3(&p, &sets, &c.stationary, &Step3Start::default(), 100).unwrap();
    assert!(rep.converged);
    for (name, truth) in [("v_im", 0.022), ("v_em", 0.02), ("j_t", 2e-4)] {
        let v = param_value(&q, name).unwrap();
        assert!(((v - truth) / truth).abs() < 3e-3, "{name}: {v} vs {truth}");
    }
    let (tau, rep4) = step4(
        &q,
        c.dataset("I").unwrap().1,
        &c.stationary,
        StepLevels::LeastSquares,
    )
    .unwrap();
    assert!((tau - 1.0).abs() < 1e-3, "tau_Me {tau}");
    // the torque jumps at fuel steps; the lag is applied on a 0.02 s grid here and a 0.01 s
    // grid in the lab (a ramp over one interval), hence up to 0.5 % at the step samples
    assert!(rep4.errors[0].mean_abs_rel_err < 1e-3, "{:?}", rep4.errors);
    assert!(rep4.errors[0].max_abs_rel_err < 1e-2, "{:?}", rep4.errors);
    // the residuals of step 4 as a function of the engine parameters (for the uncertainty of
    // what it holds fixed) are the step's own at its optimum: same length, same values to the
    // interpolation of one simulation (the search lags a single run per trial tau)
    let set_i = c.dataset("I").unwrap().1;
    let lin = rep4.linearization.as_ref().expect("step 4 linearization");
    let r = complete::torque_residuals(set_i, &c.stationary, tau, StepLevels::LeastSquares)(&q);
    assert_eq!(r.len(), lin.jacobian.nrows());
    let cost: f64 = r.iter().map(|x| x * x).sum();
    assert!(
        (0.5 * cost - rep4.cost).abs() <= 1e-9 * rep4.cost.max(1e-12),
        "{} vs {}",
        0.5 * cost,
        rep4.cost
    );
    // an engine parameter step 4 holds fixed moves the residuals (J_t shapes the torque
    // transients through the turbo speed)
    let mut q2 = q.clone();
    q2.turbo.j_t *= 1.2;
    let r2 = complete::torque_residuals(set_i, &c.stationary, tau, StepLevels::LeastSquares)(&q2);
    let d: f64 = r.iter().zip(&r2).map(|(a, b)| (a - b).powi(2)).sum();
    assert!(
        d > 1e-6 * cost.max(1e-12),
        "J_t +20 %: change {d}, cost {cost}"
    );
}

/// `mvem lab --seed 5` sets B and C with 13 stationary points (realistic noise; the Table 6
/// sensor lags when `sensor_lags`), published parameters.
fn seed5_b_c(sensor_lags: bool) -> mvem::tuning::data::Campaign {
    let opts = LabOptions {
        seed: 5,
        noise: Noise::REALISTIC,
        n_stationary: 13,
        sets: Some(vec!["B".into(), "C".into()]),
        sensor_lags,
        ..LabOptions::default()
    };
    lab::campaign(&Params::published(), &opts).unwrap().0
}

#[test]
fn step_3_on_noisy_responses_with_the_true_static_parameters() {
    // `mvem lab --seed 5` sets B and C (realistic noise: 0.5 % per sample at 100 Hz), the true
    // static parameters: step 3 from its generic start. With the levels of each step fitted by
    // least squares (default) V_im is within 3 of its standard errors of the truth; with the
    // means of sessions 1-15 the 20-sample mean before each step carries its noise into the
    // whole step and V_im ends more than 4 of them off. Measured: -6.8 % (z -2.05) and -9.1 %
    // (z -4.76), with the central-difference covariance Jacobian of session 18
    // (`complete::covariance_jacobian`); with the search's noisy forward differences the
    // standard errors moved by up to 1.6x with the integrator's step sequence (z -2.1 or -3.4,
    // and -5.4 for the means).
    let p = Params::published();
    let c = seed5_b_c(false);
    let sets: Vec<_> = ["B", "C"].iter().map(|n| c.dataset(n).unwrap().1).collect();
    let z_of = |levels: StepLevels| {
        let start = Step3Start {
            window: complete::ResponseWindow {
                levels,
                ..complete::ResponseWindow::UNIFORM
            },
            ..Step3Start::default()
        };
        let (q, rep) = step3(&p, &sets, &c.stationary, &start, 100).unwrap();
        let e = &rep.uncertainty.iter().find(|(n, _)| n == "v_im").unwrap().1;
        let v = param_value(&q, "v_im").unwrap();
        (v - 0.022) / e.std_error
    };
    let z_ls = z_of(StepLevels::LeastSquares);
    assert!(
        z_ls.abs() < 3.0,
        "least squares: V_im {z_ls} standard errors off"
    );
    let z_means = z_of(StepLevels::Means);
    assert!(
        z_means.abs() > 4.0,
        "means: V_im {z_means} standard errors off"
    );
}

#[test]
fn step_3_fits_the_sensor_lags_of_a_lagged_test_cell() {
    // `mvem lab --seed 5 --sensor-lags` sets B and C (Table 6 lags: p_im 15 ms, p_em 20 ms,
    // W_c 20 ms, n_t 6 ms; realistic noise), the true static parameters. Without lags in the
    // model step 3 gives the lags to the volumes and J_t: V_em more than 5 of its standard
    // errors off. With the lags fitted, V_im, V_em and J_t are within 3 standard errors of the
    // truth and the p_em and W_c time constants within 5 ms of theirs.
    let p = Params::published();
    let c = seed5_b_c(true);
    let sets: Vec<_> = ["B", "C"].iter().map(|n| c.dataset(n).unwrap().1).collect();
    let z = |q: &Params, rep: &complete::CompleteReport, name: &str| {
        let e = &rep.uncertainty.iter().find(|(n, _)| n == name).unwrap().1;
        (param_value(q, name).unwrap() - param_value(&p, name).unwrap()) / e.std_error
    };
    let (q, rep) = step3(&p, &sets, &c.stationary, &Step3Start::default(), 100).unwrap();
    let z_em = z(&q, &rep, "v_em");
    assert!(
        z_em.abs() > 5.0,
        "without lags: V_em {z_em} standard errors off"
    );
    let start = Step3Start {
        fit_lags: true,
        ..Step3Start::default()
    };
    let (q, rep) = step3(&p, &sets, &c.stationary, &start, 100).unwrap();
    for name in ["v_im", "v_em", "j_t"] {
        let zz = z(&q, &rep, name);
        assert!(zz.abs() < 3.0, "with lags: {name} {zz} standard errors off");
    }
    let l = rep.sensor_lags;
    assert!((l.p_em - 0.020).abs() < 0.005, "{l:?}");
    assert!((l.w_c - 0.020).abs() < 0.005, "{l:?}");
    assert_eq!(rep.params.len(), 7);
}

#[test]
fn cost_77_vanishes_at_the_truth_and_grows_away_from_it() {
    let p = Params::published();
    let c = small(Noise::NONE, &["A", "B"], 3, 20);
    let sets: Vec<_> = ["A", "B"].iter().map(|n| c.dataset(n).unwrap().1).collect();
    let cost = Cost77::new(&p, &c.stationary, &sets, &Step5Options::default());
    // A at 1 Hz as it is, B (100 Hz) subsampled to 10 Hz; 4 outputs; 7 submodels x 20 points
    let (na, nb) = (
        c.dataset("A").unwrap().1.t.len(),
        c.dataset("B").unwrap().1.t.len(),
    );
    assert_eq!(cost.len(), 4 * (na + nb.div_ceil(10)) + 7 * 20);
    // rows without B (an oscillating set leaves the linearization): A's, none of B's
    // subsampled rows, every stationary row
    let keep = cost.rows_without(&["B".to_string()]);
    assert_eq!(keep.len(), cost.len());
    assert!(keep[..4 * na].iter().all(|k| *k));
    assert!(keep[4 * na..4 * (na + nb.div_ceil(10))].iter().all(|k| !*k));
    assert!(keep[4 * (na + nb.div_ceil(10))..].iter().all(|k| *k));
    assert!(cost.rows_without(&[]).iter().all(|k| *k));
    let th = static_theta(&p);
    let v0 = cost.cost(&th);
    // only the integration error of the lab (rtol 1e-6) remains
    assert!(v0 < 1e-10, "cost at the truth {v0}");
    let mut th2 = th.clone();
    let k = STATIC_PARAMS.iter().position(|s| s.name == "k_t").unwrap();
    th2[k] *= 1.02;
    let v1 = cost.cost(&th2);
    assert!(v1 > 1e3 * v0.max(1e-14), "{v1} vs {v0}");
    // the naive start of eq. (78) lies in the bounds and follows its three cases
    for (s, v) in STATIC_PARAMS.iter().zip(naive_theta()) {
        let want = if s.hi < 1.0 {
            s.hi
        } else if s.lo <= 1.0 {
            1.0
        } else {
            s.lo
        };
        assert_eq!(v, want, "{}", s.name);
    }
}

/// Cost (77) with further compressor flow points (`Step5Options::flow_points`): the W_c term of
/// the second row runs over the stationary and the flow points, weighted by
/// `1 / sqrt(beta N (M + K))` (its mean over its own points); every other row is unchanged.
#[test]
fn cost77_w_c_row_takes_the_further_flow_points() {
    let p = Params::published();
    let c = small(Noise::REALISTIC, &["A", "B"], 3, 20);
    let sets: Vec<_> = ["A", "B"].iter().map(|n| c.dataset(n).unwrap().1).collect();
    let flow = mvem::tuning::settled::flow_points(&c);
    let k = flow.len();
    assert!(k > 0);
    let plain = Cost77::new(&p, &c.stationary, &sets, &Step5Options::default());
    let opts = Step5Options {
        flow_points: flow.clone(),
        ..Step5Options::default()
    };
    let cost = Cost77::new(&p, &c.stationary, &sets, &opts);
    assert_eq!(cost.len(), plain.len() + k);
    let (b0, b1) = (plain.blocks(), cost.blocks());
    assert_eq!(b1.len(), b0.len());
    assert_eq!(b1[..b1.len() - 1], b0[..b0.len() - 1]);
    assert_eq!(*b1.last().unwrap(), 20 + k);
    let (r0, r1) = (plain.residuals_at(&p), cost.residuals_at(&p));
    let before_w_c = r0.len() - 20;
    assert_eq!(r0[..before_w_c], r1[..before_w_c]);
    let pts: Vec<_> = c
        .stationary
        .iter()
        .map(mvem::tuning::steps::FlowPoint::of)
        .chain(flow)
        .collect();
    let (meas, model) = mvem::tuning::steps::w_c_flow_series(&p, &pts);
    let mean = meas.iter().sum::<f64>() / meas.len() as f64;
    let w = 1.0 / ((7 * (20 + k)) as f64).sqrt();
    for (i, r) in r1[before_w_c..].iter().enumerate() {
        let want = w * (meas[i] - model[i]) / mean;
        assert!((r - want).abs() <= 1e-15, "row {i}: {r} vs {want}");
    }
}

/// The settled ends of the command steps are stationary measurements of the compressor flow:
/// on a noise-free campaign the true flow map (eqs (66)-(72)) reproduces the measured W_c there
/// at the measured Pi_c and n_t, to the settling left after `settled::SETTLE_S` (the lab's
/// holds: 4-10 s). Sets A-I at 1-100 Hz; the first two steps of each.
#[test]
fn settled_step_ends_lie_on_the_true_compressor_flow_map() {
    let truth = Params::published();
    let c = small(
        Noise::NONE,
        &["A", "B", "C", "D", "E", "F", "G", "H", "I"],
        6,
        10,
    );
    let pts = mvem::tuning::settled::flow_points(&c);
    assert!(pts.len() >= 9 * 4, "{}", pts.len());
    let (meas, model) = mvem::tuning::steps::w_c_flow_series(&truth, &pts);
    let mean = meas.iter().sum::<f64>() / meas.len() as f64;
    let worst = meas
        .iter()
        .zip(&model)
        .map(|(a, b)| (a - b).abs() / mean)
        .fold(0.0, f64::max);
    // settled to 0.5 % of the mean flow (the W_c sensor noise of Noise::REALISTIC)
    assert!(
        worst < 5e-3,
        "worst relative W_c error at a settled step end {worst}"
    );
}

#[test]
fn pipeline_on_a_tiny_noisy_campaign() {
    let base = Params::published();
    let c = small(Noise::REALISTIC, &["A", "B", "C", "I", "Q"], 4, 40);
    let mut opts = PipelineOptions::default();
    opts.step5.max_evaluations = 80;
    let (p, rep) = pipeline::tune(&c, &base, &opts).unwrap();
    let r5 = rep.step5.as_ref().unwrap();
    assert!(
        r5.cost_end < r5.cost_start,
        "{} -> {}",
        r5.cost_start,
        r5.cost_end
    );
    assert!(rep.tau_me_s.is_some() && rep.step3.is_some());
    // the tuned model reproduces the validation sets to better than 2 % per output
    let v = validation_of(&c, &p, &rep);
    // validation role: A, I, Q
    assert_eq!(v.datasets.len(), 3);
    // it settles like the engine wherever the commands are held (no limit cycle, the
    // oscillation check of validate and of the tune report)
    assert!(rep.oscillations.is_empty(), "{:?}", rep.oscillations);
    assert!(v.oscillation_rows().is_empty());
    // and it runs on every set of the campaign
    assert!(rep.failed_sets.is_empty(), "{:?}", rep.failed_sets);
    // step 1's compressor-flow fit used the stationary points and the settled ends of the
    // static-tuning sets' steps (A, B, C, I here)
    let settled = mvem::tuning::settled::flow_points(&c).len();
    assert!(settled > 0);
    assert_eq!(rep.step1_settled_flow_points, settled);
    let fits = &rep.step1.as_ref().unwrap().fits;
    let w_c = fits.iter().find(|f| f.submodel == "W_c").unwrap();
    assert_eq!(w_c.n_points, 40 + settled);
    assert!(fits
        .iter()
        .filter(|f| f.submodel != "W_c")
        .all(|f| f.n_points == 40));
    for d in &v.datasets {
        for o in &d.outputs {
            let e = o.mean_abs_rel_err;
            assert!(e < 0.02, "{} {}: {e}", d.name, o.output);
        }
    }
    // failing steps are named: no dynamic-tuning set
    let c2 = small(Noise::NONE, &["A"], 2, 20);
    let e = pipeline::tune(
        &c2,
        &base,
        &PipelineOptions {
            steps: [false, false, true, false, false],
            ..opts
        },
    )
    .unwrap_err();
    assert_eq!(e.step, 3);
    assert!(e.to_string().contains("tuning step 3"), "{e}");
}

#[test]
fn step_selection_parses() {
    assert_eq!(parse_steps("1-5").unwrap(), [true; 5]);
    assert_eq!(parse_steps("1-4").unwrap(), [true, true, true, true, false]);
    assert_eq!(
        parse_steps("3,5").unwrap(),
        [false, false, true, false, true]
    );
    assert!(parse_steps("0-2").is_err());
    assert!(parse_steps("4-2").is_err());
    assert!(parse_steps("x").is_err());
}

/// The pipeline on a small campaign of the published engine scaled physically to 2.5 times its
/// flow (`tests/data/engine_32l_scaled.toml`, 31.85 dm^3, 16 cylinders; seed 4, 82 stationary
/// points, sets A, B, C, I, Q, J of 4 steps; step 5 limited to 80 evaluations): the method
/// works on the engine's scale. Before the boxes followed the campaign (`tuning::scale`), step
/// 1's W_copt ended on the published engine's edge of 2 kg/s and the report said so; the
/// tuned model reproduces the validation sets as well as on the published engine (below 2 %
/// per output), and step 3's start and bounds (scaled by V_d and R_c) recover J_t.
/// (~30 s in the ci profile on 2 cores; `full_tuning_of_a_2_5x_engine` is the whole method.)
#[test]
fn pipeline_on_a_larger_engine() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/engine_32l_scaled.toml");
    let truth = mvem::io::params::load_params(&path).unwrap();
    let opts = LabOptions {
        seed: 4,
        noise: Noise::REALISTIC,
        n_stationary: 82,
        sets: Some(
            ["A", "B", "C", "I", "Q", "J"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ),
        max_steps: Some(4),
        envelope: lab::Envelope {
            full_load_mg: 206.25,
            ..lab::Envelope::PUBLISHED
        },
        ..LabOptions::default()
    };
    let c = lab::campaign(&truth, &opts).unwrap().0;
    let mut popts = PipelineOptions::default();
    popts.step5.max_evaluations = 80;
    let (p, rep) = pipeline::tune(&c, &truth, &popts).unwrap();
    assert!(
        !rep.caveats.iter().any(|c| c.contains("w_copt")),
        "{:?}",
        rep.caveats
    );
    assert!(p.compressor.w_copt > 2.0, "{}", p.compressor.w_copt);
    let v = validation_of(&c, &p, &rep);
    for d in &v.datasets {
        for o in &d.outputs {
            let e = o.mean_abs_rel_err;
            eprintln!("{} {}: {e}", d.name, o.output);
            assert!(e < 0.02, "{} {}: {e}", d.name, o.output);
        }
    }
    let rel = |a: f64, b: f64| (a / b - 1.0).abs();
    eprintln!(
        "J_t {} (true {}), V_im {} ({}), V_em {} ({}), tau_Me {:?}",
        p.turbo.j_t,
        truth.turbo.j_t,
        p.intake_manifold.v_im,
        truth.intake_manifold.v_im,
        p.exhaust_manifold.v_em,
        truth.exhaust_manifold.v_em,
        rep.tau_me_s
    );
    assert!(rel(p.turbo.j_t, truth.turbo.j_t) < 0.2, "{}", p.turbo.j_t);
    assert!(rel(rep.tau_me_s.unwrap(), 1.0) < 0.05, "{:?}", rep.tau_me_s);
}
