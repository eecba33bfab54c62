//! End-to-end tests of the analysis commands (`linearize`, `step`, `map`, `components`,
//! `report`): the JSON contract, the acceptance facts of the control analysis (actuator poles,
//! RHP zero and sign reversal of u_vgt -> W_c), agreement with the library, CSV shape and
//! validity flags, figures, and bad input.

use mvem::analysis::linearize::{linearize_steady, LinearizeOptions};
use mvem::analysis::steady::steady_state;
use mvem::analysis::step::StepMetrics;
use mvem::analysis::zeros::dc_gain_matrix;
use mvem::model::{Drive, Engine8, Signals, STATE_NAMES_8};
use mvem::sim::{simulate, InputSchedule, SimOptions, Start};
use serde_json::Value;
use std::path::Path;
mod common;

use common::{json_of, mvem, stderr, stdout};

/// `mvem linearize` at 1500 rpm, 110 mg, u_egr 80 % and `u_vgt`, then `extra`.
fn lin_args<'a>(u_vgt: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "linearize",
        "--n-e",
        "1500",
        "--u-delta",
        "110",
        "--u-egr",
        "80",
        "--u-vgt",
        u_vgt,
    ];
    args.extend_from_slice(extra);
    args
}

fn lin_json(dir: &Path, u_vgt: &str, extra: &[&str]) -> Value {
    let mut extra = extra.to_vec();
    extra.push("--json");
    json_of(&mvem(dir, &lin_args(u_vgt, &extra)))
}

/// The library's view of `lin_args("75", ..)`: the model, the inputs, their steady state and
/// the CLI's linearization options (non-strict).
fn cli_point() -> (
    Engine8,
    Drive,
    mvem::analysis::steady::SteadyState<8>,
    LinearizeOptions,
) {
    let m = Engine8::published();
    let drive = Drive::from_array([1500.0, 110.0, 80.0, 75.0]);
    let ss = steady_state(&m, &drive).unwrap();
    let opts = LinearizeOptions {
        strict: false,
        ..LinearizeOptions::default()
    };
    (m, drive, ss, opts)
}

fn complex_list(v: &Value) -> Vec<(f64, f64)> {
    v.as_array()
        .unwrap_or_else(|| panic!("not a list: {v}"))
        .iter()
        .map(|z| (z["re"].as_f64().unwrap(), z["im"].as_f64().unwrap()))
        .collect()
}

fn matrix(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| {
            r.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect()
}

fn index(v: &Value, key: &str, name: &str) -> usize {
    v[key]
        .as_array()
        .unwrap()
        .iter()
        .position(|s| s == name)
        .unwrap_or_else(|| panic!("{name} not in {key}"))
}

#[test]
fn linearize_json_contract_and_acceptance_facts() {
    let d = tempfile::tempdir().unwrap();
    let v = lin_json(d.path(), "75", &[]);
    for k in [
        "eigenvalues",
        "zeros",
        "dc_gain",
        "A",
        "B",
        "C",
        "D",
        "state_names",
        "input_names",
        "output_names",
        "units",
        "operating_point",
    ] {
        assert!(v.get(k).is_some(), "key {k} missing");
    }
    // every SISO channel plus MIMO, each a list of {re, im}
    let zeros = v["zeros"].as_object().unwrap();
    assert_eq!(zeros.len(), 4 * 7 + 1);
    for i in ["u_delta", "u_egr", "u_vgt", "n_e"] {
        for o in ["p_im", "p_em", "W_c", "n_t", "x_egr", "lambda_O", "M_e"] {
            complex_list(&zeros[&format!("{i}->{o}")]);
        }
    }
    complex_list(&zeros["MIMO"]);
    // shapes: 8 states, 4 inputs, 7 outputs
    let (a, b, c, dd) = (
        matrix(&v["A"]),
        matrix(&v["B"]),
        matrix(&v["C"]),
        matrix(&v["D"]),
    );
    assert_eq!((a.len(), a[0].len()), (8, 8));
    assert_eq!((b.len(), b[0].len()), (8, 4));
    assert_eq!((c.len(), c[0].len()), (7, 8));
    assert_eq!((dd.len(), dd[0].len()), (7, 4));
    // the actuator poles -1/tau_vgt = -40, -1/tau_egr1 = -20, -1/tau_egr2 = -1/0.13
    let ev = complex_list(&v["eigenvalues"]);
    assert_eq!(ev.len(), 8);
    for want in [-40.0, -20.0, -1.0 / 0.13] {
        assert!(
            ev.iter().any(|z| (z.0 - want).abs() < 1e-6 && z.1 == 0.0),
            "{want} not in {ev:?}"
        );
    }
    // u_vgt -> W_c: RHP zero and negative DC gain at 75 %, neither at 30 %
    let (wc, uvgt) = (
        index(&v, "output_names", "W_c"),
        index(&v, "input_names", "u_vgt"),
    );
    assert!(complex_list(&zeros["u_vgt->W_c"]).iter().any(|z| z.0 > 0.0));
    let g75 = matrix(&v["dc_gain"])[wc][uvgt];
    assert!(g75 < 0.0, "{g75}");
    let v30 = lin_json(d.path(), "30", &[]);
    assert!(complex_list(&v30["zeros"]["u_vgt->W_c"])
        .iter()
        .all(|z| z.0 < 0.0));
    let g30 = matrix(&v30["dc_gain"])[wc][uvgt];
    assert!(g30 > 0.0, "{g30}");

    // the JSON carries the library's numbers unchanged (serde round trip of f64 is exact)
    let m = Engine8::published();
    let ss = steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 75.0)).unwrap();
    let lin = linearize_steady(
        &m,
        &ss,
        &LinearizeOptions {
            strict: false,
            ..LinearizeOptions::default()
        },
    )
    .unwrap();
    for (i, row) in a.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            assert_eq!(*v, lin.a[(i, j)], "A[{i}][{j}]");
        }
    }
    let g = dc_gain_matrix(&lin).unwrap();
    assert_eq!(g75, g[(wc, uvgt)]);
    // units and names
    assert_eq!(v["units"]["inputs"][3], "rpm");
    assert_eq!(v["units"]["outputs"][wc], "kg/s");
    assert_eq!(v["state_names"][0], STATE_NAMES_8[0]);
}

#[test]
fn linearize_pade_models_and_text() {
    let d = tempfile::tempdir().unwrap();
    // Pade order 2 on both delays: 4 extra states; the actuator poles stay, and the delay's
    // all-pass zeros (RHP) appear in the u_vgt channels
    let v = lin_json(d.path(), "75", &["--pade", "2"]);
    assert_eq!(matrix(&v["A"]).len(), 12);
    assert_eq!(v["pade_order"], 2);
    let ev = complex_list(&v["eigenvalues"]);
    assert!(ev.iter().any(|z| (z.0 + 40.0).abs() < 1e-6));
    assert!(complex_list(&v["zeros"]["u_vgt->p_em"])
        .iter()
        .any(|z| z.0 > 0.0));
    // the 10-state model: 10 states, same channel facts at 75 %
    let v10 = lin_json(d.path(), "75", &["--model", "10"]);
    assert_eq!(matrix(&v10["A"]).len(), 10);
    assert!(complex_list(&v10["zeros"]["u_vgt->W_c"])
        .iter()
        .any(|z| z.0 > 0.0));
    // text output names the sections
    let o = mvem(d.path(), &lin_args("75", &[]));
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    for s in ["Poles", "DC gain", "u_vgt->W_c", "RHP zero", "MIMO"] {
        assert!(out.contains(s), "{s} missing in {out}");
    }
}

/// `linearize --ts`: the sampled model in the JSON (the library's `discretize`, to the bit), its
/// registers and poles, the text section, and the refused combinations.
/// `--bode`: the library's frequency response in the JSON to the bit, the CSV and the plot
/// written, the table printed, and bad grids, channels and --pade refused (exit code 2).
#[test]
fn linearize_frequency_response_with_exact_delays() {
    let d = tempfile::tempdir().unwrap();
    let csv = d.path().join("bode.csv");
    let png = d.path().join("bode.png");
    let v = lin_json(
        d.path(),
        "75",
        &[
            "--bode",
            "0.01:100:41",
            "--bode-out",
            csv.to_str().unwrap(),
            "--plot",
            png.to_str().unwrap(),
        ],
    );
    let fv = &v["frequency_response"];
    let f: Vec<f64> = serde_json::from_value(fv["f_hz"].clone()).unwrap();
    assert_eq!(f.len(), 41);
    assert_eq!((f[0], f[40]), (0.01, 100.0));
    assert_eq!(fv["delays_s"]["u_vgt"], 0.04);
    // the library's response, bit for bit (the CLI linearizes non-strict)
    let (m, drive, ss, opts) = cli_point();
    let fr = mvem::analysis::frequency::frequency_response(&m, &ss.x, &drive, &opts, &f).unwrap();
    let (mag, phase) = fr.magnitude_phase("u_vgt", "W_c").unwrap();
    let got_mag: Vec<f64> =
        serde_json::from_value(fv["channels"]["u_vgt->W_c"]["mag"].clone()).unwrap();
    let got_phase: Vec<f64> =
        serde_json::from_value(fv["channels"]["u_vgt->W_c"]["phase_deg"].clone()).unwrap();
    assert_eq!((got_mag, got_phase), (mag.clone(), phase.clone()));
    // the sign reversal of u_vgt -> W_c: a negative DC gain (phase near 180 deg at 0.01 Hz)
    let dc = dc_gain_matrix(&linearize_steady(&m, &ss, &opts).unwrap()).unwrap();
    assert!(dc[(index(&v, "output_names", "W_c"), 2)] < 0.0);
    assert!((phase[0] - 180.0).abs() < 30.0, "{}", phase[0]);
    // CSV: f_hz and a magnitude and a phase per channel (4 inputs x 7 outputs)
    let text = std::fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    assert_eq!(header.len(), 1 + 2 * 4 * 7);
    assert_eq!(
        &header[..3],
        ["f_hz", "u_delta->p_im mag", "u_delta->p_im phase_deg"]
    );
    assert_eq!(text.lines().count(), 42);
    assert!(std::fs::metadata(&png).unwrap().len() > 10_000);
    // the text table of the chosen channels
    let o = mvem(
        d.path(),
        &lin_args("75", &["--bode", "0.1:10:3", "--channels", "u_egr->x_egr"]),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("u_egr -> x_egr   |G| [- per %]"), "{out}");
    assert!(!out.contains("u_vgt -> W_c   |G|"), "{out}");
    for (extra, want) in [
        (
            vec!["--bode", "0:10:5"],
            "f_min = 0: must be a frequency > 0 Hz",
        ),
        (vec!["--bode", "1:10"], "expected FMIN:FMAX:N"),
        (vec!["--bode", "1:10:x"], "N 'x' is not a whole number"),
        (
            vec!["--bode", "1:10:5", "--pade", "2"],
            "--bode with --pade",
        ),
        (
            vec!["--bode", "1:10:5", "--channels", "u_vgt-W_c"],
            "is not input->output",
        ),
        (
            vec!["--bode", "1:10:5", "--channels", "u_vgt->T_em"],
            "add it with --outputs",
        ),
        (vec!["--bode", "1:10:5", "--plot", "bode.txt"], "bode.txt"),
    ] {
        let o = mvem(d.path(), &lin_args("75", &extra));
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(want), "{extra:?}: {}", stderr(&o));
    }
}

#[test]
fn linearize_sampled_model_with_exact_delays() {
    let d = tempfile::tempdir().unwrap();
    let v = lin_json(d.path(), "75", &["--ts", "0.02"]);
    let dv = &v["discrete"];
    assert_eq!(dv["ts"], 0.02);
    // 0.065 s = 3 samples + 5 ms (4 registers), 0.04 s = 2 samples (2 registers)
    assert_eq!(dv["delay_samples"]["u_egr"]["whole"], 3);
    assert_eq!(dv["delay_samples"]["u_vgt"]["whole"], 2);
    assert_eq!(dv["delay_samples"]["u_vgt"]["remainder_s"], 0.0);
    let names: Vec<&str> = dv["state_names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 14);
    assert_eq!(
        &names[8..],
        [
            "u_egr(k-1)",
            "u_egr(k-2)",
            "u_egr(k-3)",
            "u_egr(k-4)",
            "u_vgt(k-1)",
            "u_vgt(k-2)"
        ]
    );
    assert_eq!(dv["state_units"][8], "%");
    // the library's model, bit for bit
    let (m, drive, ss, opts) = cli_point();
    let dm = mvem::analysis::discrete::discretize(&m, &ss.x, &drive, &opts, 0.02).unwrap();
    let phi = matrix(&dv["Phi"]);
    let gamma = matrix(&dv["Gamma"]);
    for (i, (phi_row, gamma_row)) in phi.iter().zip(&gamma).enumerate() {
        for (j, v) in phi_row.iter().enumerate() {
            assert_eq!(*v, dm.phi[(i, j)], "Phi[{i}][{j}]");
        }
        for (j, v) in gamma_row.iter().enumerate() {
            assert_eq!(*v, dm.gamma[(i, j)], "Gamma[{i}][{j}]");
        }
    }
    assert_eq!((phi.len(), gamma.len()), (14, 14));
    // shift registers: u_vgt(k-2)(k+1) = u_vgt(k-1)(k); u_egr(k-1)(k+1) = u_egr(k)
    assert_eq!(phi[13][12], 1.0);
    assert_eq!(gamma[8][1], 1.0);
    // poles: e^(lambda ts) of the continuous ones (-40 1/s: the VGT actuator) and 6 at 0
    let poles = complex_list(&dv["poles"]);
    assert!(
        poles
            .iter()
            .any(|z| (z.0 - (-40.0f64 * 0.02).exp()).abs() < 1e-9),
        "{poles:?}"
    );
    assert_eq!(
        poles.iter().filter(|z| z.0.hypot(z.1) < 1e-12).count(),
        6,
        "{poles:?}"
    );
    assert!(poles.iter().all(|z| z.0.hypot(z.1) < 1.0));
    // text
    let o = mvem(d.path(), &lin_args("75", &["--ts", "0.02"]));
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("Sampled with a zero-order hold at ts = 0.02 s"),
        "{out}"
    );
    assert!(out.contains("u_egr 0.065 s = 3 samples + 5 ms"), "{out}");
    assert!(out.contains("Gamma"), "{out}");
    // refused: with --pade, outside [1e-3, 100] s
    for (extra, msg) in [
        (vec!["--ts", "0.01", "--pade", "2"], "--ts with --pade"),
        (
            vec!["--ts", "1e-5"],
            "--ts 0.00001: must lie in [0.001, 100] s",
        ),
        (vec!["--ts", "nan"], "--ts NaN"),
    ] {
        let o = mvem(d.path(), &lin_args("75", &extra));
        assert_eq!(o.status.code(), Some(2), "{extra:?}");
        assert!(stderr(&o).contains(msg), "{extra:?}: {}", stderr(&o));
    }
}

/// `linearize --state FILE.json`: at the steady state (written with 17 digits) the same
/// matrices as without it and dx0 about 0; at a state of a transient (p_im +5 %) the library's
/// linearization at that state to the bit, dx0 its derivatives, `"steady_state": false`; a
/// state file without every state is exit 2 naming the field.
#[test]
fn linearize_at_a_given_state() {
    let d = tempfile::tempdir().unwrap();
    let m = Engine8::published();
    let ss = steady_state(&m, &Drive::new(1500.0, 110.0, 80.0, 75.0)).unwrap();
    let write = |name: &str, x: &[f64; 8]| {
        let obj: serde_json::Map<String, Value> = STATE_NAMES_8
            .iter()
            .zip(x)
            .map(|(n, v)| (n.to_string(), serde_json::json!(v)))
            .collect();
        std::fs::write(d.path().join(name), Value::Object(obj).to_string()).unwrap();
    };
    write("ss.json", &ss.x);
    let mut x1 = ss.x;
    x1[0] *= 1.05;
    write("x1.json", &x1);
    let base = lin_json(d.path(), "75", &[]);
    let at_ss = lin_json(d.path(), "75", &["--state", "ss.json"]);
    assert_eq!(base["steady_state"], true);
    assert_eq!(at_ss["steady_state"], false);
    for k in ["A", "B", "C", "D"] {
        assert_eq!(at_ss[k], base[k], "{k}");
    }
    let dx0 = matrix(&serde_json::json!([at_ss["dx0"].clone()]))[0].clone();
    for (v, s) in dx0.iter().zip(mvem::model::Model::state_scales(&m)) {
        assert!(v.abs() < 1e-9 * s, "{v}");
    }
    let at_x1 = lin_json(d.path(), "75", &["--state", "x1.json"]);
    let lib = mvem::analysis::linearize::linearize(
        &m,
        &x1,
        &Drive::new(1500.0, 110.0, 80.0, 75.0),
        &LinearizeOptions {
            strict: false,
            ..LinearizeOptions::default()
        },
    )
    .unwrap();
    let a = matrix(&at_x1["A"]);
    let lib_a: Vec<Vec<f64>> = (0..8)
        .map(|r| (0..8).map(|c| lib.a[(r, c)]).collect())
        .collect();
    assert_eq!(a, lib_a);
    let dx0 = matrix(&serde_json::json!([at_x1["dx0"].clone()]))[0].clone();
    assert_eq!(dx0, lib.dx0);
    assert!(
        dx0[0] < -1e5,
        "p_im above its equilibrium falls: {}",
        dx0[0]
    );
    std::fs::write(d.path().join("bad.json"), r#"{"p_im": 1.5e5}"#).unwrap();
    let err = common::usage_error(d.path(), &lin_args("75", &["--state", "bad.json"]));
    assert!(err.contains("field p_em: missing state"), "{err}");
    // a given state that is not physically valid is called so, not an equilibrium
    let mut x2 = ss.x;
    x2[0] = 0.5 * ss.x[1];
    write("x2.json", &x2);
    let o = mvem(d.path(), &lin_args("75", &["--state", "x2.json"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("warning: the given state is not physically valid; flags: ")
            && !err.contains("equilibrium"),
        "{err}"
    );
    // a value beyond the integrator limits: linearized at the limit, said so (it read "the
    // simulation starts from", a simulation's words)
    let mut x3 = ss.x;
    x3[4] = 1e6; // omega_t, above its limit
    write("x3.json", &x3);
    let o = mvem(d.path(), &lin_args("75", &["--state", "x3.json"]));
    let err = stderr(&o);
    let hi = mvem::model::Model::state_bounds(&m)[4].1;
    let want = format!(
        "field omega_t: 1000000 is outside the integrator limits [{}, {}]: the model is \
         evaluated (and linearized) at the limit, {}",
        mvem::numerics::Num(mvem::model::Model::state_bounds(&m)[4].0),
        mvem::numerics::Num(hi),
        mvem::numerics::Num(hi)
    );
    assert!(err.contains(&want) && !err.contains("simulation"), "{err}");
}

/// A state or signal of a steady state.
fn value(ss: &mvem::analysis::steady::SteadyState<8>, name: &str) -> f64 {
    match STATE_NAMES_8.iter().position(|s| *s == name) {
        Some(i) => ss.x[i],
        None => ss.signals.get(name).unwrap(),
    }
}

#[test]
fn step_json_metrics_match_the_library() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &[
            "step",
            "--input",
            "u_vgt",
            "--from",
            "75",
            "--to",
            "65",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--t-end",
            "8",
            "--json",
            "--plot",
            "s.png",
            "--out",
            "s.csv",
        ],
    );
    let v = json_of(&o);
    assert!(d.path().join("s.png").is_file() && d.path().join("s.csv").is_file());
    // the same step with the library (same defaults: rtol 1e-6, output every 5 ms)
    let m = Engine8::published();
    let before = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let after = Drive::new(1500.0, 110.0, 80.0, 65.0);
    let (ss0, ss1) = (
        steady_state(&m, &before).unwrap(),
        steady_state(&m, &after).unwrap(),
    );
    let opts = SimOptions {
        rtol: 1e-6,
        atol: 1e-6, // the CLI default: atol = rtol
        dt_out: 0.005,
        ..SimOptions::default()
    };
    let sched = InputSchedule::steps(before, &[(1.0, 3, 65.0)]).unwrap();
    let sol = simulate(&m, &sched, 0.0, 8.0, Start::State(ss0.x), &opts).unwrap();
    for name in ["W_c", "p_im", "n_t"] {
        let want = StepMetrics::compute(
            sol.t(),
            sol.get(name).unwrap(),
            1.0,
            value(&ss0, name),
            value(&ss1, name),
            -10.0,
        )
        .unwrap();
        let got = &v["outputs"][name];
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-12);
        assert!(
            close(got["dc_gain"].as_f64().unwrap(), want.dc_gain),
            "{name}"
        );
        assert!(
            close(got["overshoot_pct"].as_f64().unwrap(), want.overshoot_pct)
                || want.overshoot_pct == 0.0
        );
        assert_eq!(got["non_minimum_phase"], want.non_minimum_phase, "{name}");
        assert_eq!(got["gain_sign"], want.gain_sign.to_string());
        if let Some(w) = want.wrong_way {
            assert!(close(got["wrong_way"]["value"].as_f64().unwrap(), w.value));
            assert!(close(got["wrong_way"]["time"].as_f64().unwrap(), w.time));
        }
        if let Some(r) = want.rise_time {
            assert!(close(got["rise_time"].as_f64().unwrap(), r));
        }
    }
    // the demonstration facts: W_c non-minimum phase with a negative DC gain
    assert_eq!(v["outputs"]["W_c"]["non_minimum_phase"], true);
    assert_eq!(v["outputs"]["W_c"]["gain_sign"], "negative");
    assert_eq!(v["input"], "u_vgt");
    assert_eq!(v["from"], 75.0);
}

#[test]
fn step_json_of_an_output_without_change_has_its_values_and_gain() {
    // EGR valve shut: W_egr is 0 before and after a VGT step; its metrics have no direction,
    // but the JSON still gives the steady values and the gain 0
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &[
            "step",
            "--input",
            "u_vgt",
            "--from",
            "75",
            "--to",
            "65",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--u-egr",
            "0",
            "--outputs",
            "W_egr,W_c",
            "--json",
        ],
    );
    let v = json_of(&o);
    let w = &v["outputs"]["W_egr"];
    assert!(
        w["error"].as_str().unwrap().contains("zero final change"),
        "{w}"
    );
    assert_eq!(w["y0"], 0.0);
    assert_eq!(w["y_final"], 0.0);
    assert_eq!(w["dc_gain"], 0.0);
    assert!(w["dc_gain"].as_f64().unwrap().is_sign_positive());
    assert!(v["outputs"]["W_c"]["error"].is_null());
}

#[test]
fn step_in_any_input() {
    let d = tempfile::tempdir().unwrap();
    // EGR step at a point with EGR flow: non-minimum phase in p_im (implementation notes, item 40)
    let v = json_of(&mvem(
        d.path(),
        &[
            "step",
            "--input",
            "u_egr",
            "--to",
            "60",
            "--n-e",
            "1200",
            "--u-delta",
            "200",
            "--u-egr",
            "50",
            "--u-vgt",
            "40",
            "--outputs",
            "p_im,W_egr",
            "--json",
            "--t-end",
            "6",
        ],
    ));
    assert_eq!(v["outputs"]["p_im"]["non_minimum_phase"], true);
    assert_eq!(v["outputs"]["W_egr"]["gain_sign"], "positive");
    // speed step: fuel and speed are inputs too
    let v = json_of(&mvem(
        d.path(),
        &[
            "step",
            "--input",
            "n_e",
            "--from",
            "1500",
            "--to",
            "1550",
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--u-vgt",
            "75",
            "--outputs",
            "W_c",
            "--json",
            "--t-end",
            "4",
        ],
    ));
    assert_eq!(v["outputs"]["W_c"]["gain_sign"], "positive");
}

/// The fuel u_delta is in mg/cycle (per cycle and cylinder) throughout `mvem step`'s text and
/// figure, the unit of the explorer and the CSVs: before session 42 the operating point said
/// `u_delta 110 mg` on the line whose title said `mg/cycle` (a fuel step's `100 -> 120
/// mg/cycle`), and the figure's title `u_delta 110 mg`.
#[test]
fn step_text_and_figure_give_the_fuel_in_mg_per_cycle() {
    let d = tempfile::tempdir().unwrap();
    let step = |args: &str| {
        let a = format!("step {args} --outputs p_im --t-end 3");
        mvem(d.path(), &a.split(' ').collect::<Vec<_>>())
    };
    let o = step("--input u_delta --from 100 --to 120 --n-e 1500 --u-egr 20 --u-vgt 50");
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert_eq!(
        text.lines().next().unwrap(),
        "Step u_delta 100 → 120 mg/cycle at t = 1 s (n_e 1500 rpm, u_delta 100 mg/cycle, u_egr \
         20 %, u_vgt 50 %)",
        "{text}"
    );
    assert!(
        text.contains("DC gain in output unit per mg/cycle."),
        "{text}"
    );
    // a VGT step's figure names the held fuel in its title
    let o =
        step("--input u_vgt --from 75 --to 65 --n-e 1500 --u-delta 110 --u-egr 80 --plot s.svg");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).starts_with(
            "Step u_vgt 75 → 65 % at t = 1 s (n_e 1500 rpm, u_delta 110 mg/cycle, u_egr 80 %, \
             u_vgt 75 %)\n"
        ),
        "{}",
        stdout(&o)
    );
    let svg = std::fs::read_to_string(d.path().join("s.svg")).unwrap();
    assert!(
        svg.contains("n_e 1500 rpm, u_delta 110 mg/cycle, u_egr 80 %") && !svg.contains(" mg,"),
        "{}",
        &svg[..svg.len().min(3000)]
    );
}

/// A `-` under rise or settling is explained below the table: a step whose slow mode (about
/// -0.5 1/s at 1200 rpm, 60 mg/cycle) has not settled by `--t-end 4` shows `-` for p_im's
/// settling, and the note names the end of the run; with nothing open there is no note. Before
/// session 43 the `-` stood unexplained.
#[test]
fn step_text_explains_what_is_not_reached() {
    let d = tempfile::tempdir().unwrap();
    let step = |t_end: &str| {
        let a = format!(
            "step --input u_egr --from 40 --to 50 --n-e 1200 --u-delta 60 --u-vgt 50 --outputs p_im,u_egr_actual --t-end {t_end}"
        );
        let o = mvem(d.path(), &a.split(' ').collect::<Vec<_>>());
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let text = step("4");
    let row = text.lines().find(|l| l.starts_with("p_im ")).unwrap();
    assert!(row.ends_with(" -"), "{text}");
    assert!(
        text.contains(
            "\n-: not within the run: rise to 90 % of the final change, or settling into its 2 % \
             band, not reached by t = 4 s (a longer --t-end shows it).\n"
        ),
        "{text}"
    );
    // settled within 30 s: no `-`, no note
    let text = step("30");
    assert!(!text.contains("not within the run"), "{text}");
    // an output listed twice is one row (it was two identical rows), in the order given
    let a = "step --input u_vgt --to 65 --n-e 1500 --u-delta 110 --u-egr 80 --u-vgt 75 --outputs W_c,p_im,W_c --t-end 3";
    let o = mvem(d.path(), &a.split(' ').collect::<Vec<_>>());
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let rows: Vec<&str> = text
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .filter(|w| ["W_c", "p_im"].contains(w))
        .collect();
    assert_eq!(rows, ["W_c", "p_im"], "{text}");
}

#[test]
fn map_csv_shape_flags_and_values() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &[
            "map",
            "--axis",
            "u_egr=0:100:3",
            "--axis",
            "u_vgt=30,60,90",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--out",
            "m.csv",
            "--plot",
            "m.svg",
            "--channel",
            "u_vgt->W_c",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let mut r = csv::Reader::from_path(d.path().join("m.csv")).unwrap();
    let h: Vec<String> = r.headers().unwrap().iter().map(str::to_string).collect();
    let rows: Vec<csv::StringRecord> = r.records().map(|x| x.unwrap()).collect();
    assert_eq!(rows.len(), 9);
    let col = |n: &str| {
        h.iter()
            .position(|x| x == n)
            .unwrap_or_else(|| panic!("no {n}"))
    };
    for n in STATE_NAMES_8.iter().chain(Signals::NAMES) {
        col(n);
    }
    // row-major, last axis fastest; values equal independent cold solves
    let m = Engine8::published();
    for (k, row) in rows.iter().enumerate() {
        let (ue, uv) = ([0.0, 50.0, 100.0][k / 3], [30.0, 60.0, 90.0][k % 3]);
        assert_eq!(row[col("u_egr_pct")].parse::<f64>().unwrap(), ue);
        assert_eq!(row[col("u_vgt_pct")].parse::<f64>().unwrap(), uv);
        let ss = steady_state(&m, &Drive::new(1500.0, 110.0, ue, uv)).unwrap();
        assert_eq!(&row[col("converged")], "1");
        assert_eq!(
            &row[col("physically_valid")],
            if ss.physically_valid() { "1" } else { "0" }
        );
        assert_eq!(&row[col("flags")], ss.flags.join(";"));
        let p_im: f64 = row[col("p_im")].parse().unwrap();
        assert!(
            (p_im - ss.x[0]).abs() < 1e-6 * ss.x[0],
            "{p_im} {}",
            ss.x[0]
        );
        let g: f64 = row[col("u_vgt->W_c:dc_gain")].parse().unwrap();
        assert!(g.is_finite());
    }
    // the sign reversal along u_vgt at u_egr 100 %: positive at 30 %, negative at 90 %
    let g = |k: usize| rows[k][col("u_vgt->W_c:dc_gain")].parse::<f64>().unwrap();
    assert!(g(6) > 0.0 && g(8) < 0.0, "{} {}", g(6), g(8));
    assert_eq!(&rows[8][col("u_vgt->W_c:rhp_zero")], "1");
    let svg = std::fs::read_to_string(d.path().join("m.svg")).unwrap();
    assert!(
        svg.contains("u_egr [%]") && svg.contains("lambda_O [-]") && svg.contains("sign change")
    );
}

#[test]
fn map_keeps_points_without_equilibrium() {
    let d = tempfile::tempdir().unwrap();
    // the paper's plain equations have no equilibrium at (500 rpm, 1 mg)
    let o = mvem(
        d.path(),
        &[
            "map",
            "--axis",
            "n_e=500,1500",
            "--axis",
            "u_delta=1,110",
            "--u-egr",
            "40",
            "--u-vgt",
            "70",
            "--semantics",
            "paper",
            "--out",
            "m.csv",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(
        err.contains("point (n_e 500 rpm, u_delta 1 mg/cycle, u_egr ")
            && err.contains("no equilibrium"),
        "{err}"
    );
    let mut r = csv::Reader::from_path(d.path().join("m.csv")).unwrap();
    let rows: Vec<csv::StringRecord> = r.records().map(|x| x.unwrap()).collect();
    assert_eq!(rows.len(), 4);
    assert_eq!(&rows[0][4], "0");
    assert!(rows[0][7].contains("no equilibrium"));
    assert_eq!(&rows[3][4], "1");
}

#[test]
fn report_and_component_figures_are_written() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(d.path(), &["report", "figs", "--out", "rep"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("(no EGR flow)"), "{out}");
    for f in [
        "fig08_egr_step_1200rpm.png",
        "fig08_egr_step_1900rpm.svg",
        "fig09_vgt_step_nmp.png",
        "fig10_vgt_step_overshoot.png",
        "fig11_12_model_orders.png",
    ] {
        let b = std::fs::read(d.path().join("rep").join(f)).unwrap();
        assert!(b.len() > 1000, "{f}");
    }
    // a simulation CSV overlaid on the component maps
    let o = mvem(
        d.path(),
        &[
            "step",
            "--input",
            "u_vgt",
            "--from",
            "75",
            "--to",
            "65",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--out",
            "s.csv",
        ],
    );
    assert!(o.status.success());
    let o = mvem(
        d.path(),
        &["components", "--overlay", "s.csv", "--out", "comp"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let svg = std::fs::read_to_string(d.path().join("comp/compressor.svg")).unwrap();
    assert!(svg.contains("W_c [kg/s]") && svg.contains("Pi_c [-]") && svg.contains("s.csv"));
    for f in ["turbine.png", "egr.png"] {
        assert_eq!(
            &std::fs::read(d.path().join("comp").join(f)).unwrap()[1..4],
            b"PNG"
        );
    }
}

#[test]
fn bad_analysis_input_exits_2_with_a_clear_message() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("bad.csv"), "t,foo\n0,1\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "linearize",
                "--n-e",
                "nan",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
                "--u-vgt",
                "75",
            ],
            "--n-e NaN",
        ),
        (
            vec![
                "linearize",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
                "--u-vgt",
                "75",
                "--outputs",
                "W_x",
            ],
            "unknown output \"W_x\"",
        ),
        (
            vec![
                "linearize",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
                "--u-vgt",
                "75",
                "--pade",
                "5",
            ],
            "--pade",
        ),
        (
            vec![
                "step",
                "--input",
                "u_vgt",
                "--to",
                "65",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
            ],
            "give --from or --u-vgt",
        ),
        (
            vec![
                "step",
                "--input",
                "u_vgt",
                "--from",
                "75",
                "--to",
                "75",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
            ],
            "equals the value before",
        ),
        (
            vec![
                "step",
                "--input",
                "u_vgt",
                "--from",
                "75",
                "--to",
                "65",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
            ],
            "--n-e is required",
        ),
        (
            vec![
                "step",
                "--input",
                "u_vgt",
                "--from",
                "75",
                "--to",
                "65",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-egr",
                "80",
                "--plot",
                "x.pdf",
            ],
            ".svg or .png",
        ),
        (
            vec!["map", "--axis", "u_foo=1:2:3", "--n-e", "1500"],
            "unknown input \"u_foo\"",
        ),
        (
            vec![
                "map",
                "--axis",
                "u_egr=0:100:3",
                "--u-delta",
                "110",
                "--u-vgt",
                "50",
            ],
            "--n-e is required",
        ),
        (
            vec![
                "map",
                "--axis",
                "u_egr=0:100:1",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-vgt",
                "50",
            ],
            "N must lie in",
        ),
        (
            vec![
                "map",
                "--axis",
                "u_egr=50,10",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-vgt",
                "50",
            ],
            "strictly increasing",
        ),
        (
            vec![
                "map",
                "--axis",
                "u_egr=0:100:3",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--u-vgt",
                "50",
                "--plot",
                "m.png",
            ],
            "exactly two --axis",
        ),
        (
            vec![
                "map",
                "--axis",
                "u_egr=0:100:3",
                "--axis",
                "u_vgt=20:90:3",
                "--n-e",
                "1500",
                "--u-delta",
                "110",
                "--channel",
                "u_vgt=>W_c",
            ],
            "input->output",
        ),
        (
            vec!["components", "--overlay", "missing.csv"],
            "missing.csv",
        ),
        (vec!["components", "--overlay", "bad.csv"], "no column W_c"),
        (vec!["report", "sign-reversal", "--n", "1"], "--n 1"),
    ];
    for (args, want) in cases {
        let o = mvem(d.path(), &args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(e.contains(want), "{args:?}: `{want}` not in {e}");
        assert!(!e.contains("panicked"), "{e}");
    }
    // no output file is left by a failed run
    assert!(!d.path().join("m.png").exists());
}

/// An input on an --axis whose first value lies outside its saturation range was warned of
/// twice: once per axis and once as the point's placeholder (session 43's user review). An
/// input given by its option is still warned of once.
#[test]
fn map_warns_of_an_axis_out_of_range_once() {
    let d = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let mut all = vec!["map", "--n-e", "1500", "--u-delta", "110", "--out", "m.csv"];
        all.extend_from_slice(args);
        let o = mvem(d.path(), &all);
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let err = run(&["--axis", "u_egr=0:100:3", "--axis", "u_vgt=10:100:3"]);
    assert_eq!(err.matches("10 is outside").count(), 0, "{err}");
    assert_eq!(
        err.matches("warning: --axis u_vgt: 1 value(s) outside [20, 100] (e.g. 10)")
            .count(),
        1,
        "{err}"
    );
    let err = run(&["--axis", "u_egr=0:100:3", "--u-vgt", "10"]);
    assert_eq!(
        err.matches("warning: u_vgt_pct = 10 is outside [20, 100]")
            .count(),
        1,
        "{err}"
    );
}
