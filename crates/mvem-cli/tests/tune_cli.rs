//! End-to-end tests of `mvem lab`, `mvem tune` and `mvem validate`: a tiny campaign, JSON
//! output, bad-data errors (file, line, column; exit code 2), a failing step (exit code 1,
//! named step) that leaves no output file.

mod common;

use common::{mvem, published_toml, stderr, write_published_with};

#[test]
fn lab_tune_validate_roundtrip_and_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let o = mvem(
        d,
        &[
            "lab",
            "--out",
            "c",
            "--sets",
            "B,C,I,Q",
            "--max-steps",
            "3",
            "--n-stationary",
            "20",
            "--noise",
            "none",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for f in [
        "manifest.toml",
        "stationary.csv",
        "B.csv",
        "J.csv",
        "true_params.toml",
    ] {
        assert!(d.join("c").join(f).is_file(), "{f}");
    }
    // the true parameters validate to (nearly) zero error on their own noise-free data
    let o = mvem(
        d,
        &[
            "validate",
            "--data",
            "c",
            "--params",
            "c/true_params.toml",
            "--tau-me",
            "1",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for set in ["B", "C", "I", "Q"] {
        for out in ["p_im", "p_em", "W_c", "n_t", "M_e"] {
            let e = v["datasets"][set][out].as_f64().unwrap();
            // per cent; M_e of the fuel set I: the dynamometer lag sees a torque jump as a ramp
            // over one output interval (0.01 s in the lab, 0.02 s here): 0.04 %
            assert!(e < 0.1, "{set} {out}: {e} %");
        }
    }
    assert!(v["stationary"]["W_c"].as_f64().unwrap() < 1e-6);
    // step 1: the compressor flow fit takes the settled ends of the holds of B, C and I
    // (roles static) next to the 20 stationary points; `--settled-flow-points false` does not
    let settled = |extra: &[&str]| {
        let mut args = vec!["tune", "--data", "c", "--steps", "1", "--out", "s1.toml"];
        args.extend_from_slice(&["--report", "r1"]);
        args.extend_from_slice(extra);
        let o = mvem(d, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        let rep: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join("r1/tune_report.json")).unwrap()).unwrap();
        let n = rep["step1_settled_flow_points"].as_u64().unwrap();
        let fits = rep["step1"]["fits"].as_array().unwrap();
        let w_c = fits.iter().find(|f| f["submodel"] == "W_c").unwrap();
        assert_eq!(w_c["n_points"].as_u64().unwrap(), 20 + n);
        let md = String::from_utf8_lossy(&o.stdout).into_owned();
        assert_eq!(md.contains("settled"), n > 0, "{md}");
        n
    };
    assert!(settled(&[]) > 0);
    assert_eq!(settled(&["--settled-flow-points", "false"]), 0);
    // step 3 alone with one more option, written to l.toml and the report rl
    let step3_with = |option: &str, value: &str| {
        let args = ["tune", "--data", "c", "--steps", "3", option, value];
        let mut args = args.to_vec();
        args.extend_from_slice(&["--out", "l.toml", "--report", "rl"]);
        mvem(d, &args)
    };
    // either way of matching the step levels recovers V_im from noise-free data; another value
    // is a usage error
    for levels in ["least-squares", "means"] {
        let o = step3_with("--step-levels", levels);
        assert!(o.status.success(), "{levels}: {}", stderr(&o));
        let rep: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join("rl/tune_report.json")).unwrap()).unwrap();
        let v = rep["parameters"]["intake_manifold.v_im"]["value"]
            .as_f64()
            .unwrap();
        assert!((v / 0.022 - 1.0).abs() < 0.01, "{levels}: V_im {v}");
        assert_eq!(rep["step_levels"], levels);
    }
    let o = step3_with("--step-levels", "median");
    assert!(!o.status.success() && stderr(&o).contains("--step-levels"));
    // sensor lags: by default step 3 fits them (here none: each within 2 ms of 0); given ones
    // are written to [test_cell], and validate applies them; a bad value is a usage error
    let rep: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("rl/tune_report.json")).unwrap()).unwrap();
    for k in ["tau_p_im", "tau_p_em", "tau_w_c", "tau_n_t"] {
        let v = rep["parameters"][format!("test_cell.{k}")]["value"]
            .as_f64()
            .unwrap();
        assert!(v.abs() < 0.002, "{k} = {v}");
        // on noise-free lag-free data each ends on its bound 0, is held there for the others'
        // standard errors and says so
        let e = &rep["parameters"][format!("test_cell.{k}")];
        if v <= 1e-4 {
            assert_eq!(e["identifiable"], false, "{k}");
            assert!(
                e["reason"].as_str().unwrap().contains("bound 0"),
                "{k}: {e}"
            );
        }
    }
    let v_im = &rep["parameters"]["intake_manifold.v_im"];
    assert_eq!(v_im["identifiable"], true, "{v_im}");
    let o = step3_with("--sensor-lags", "table6");
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(d.join("l.toml")).unwrap();
    assert!(text.contains("tau_p_em = 0.02"), "{text}");
    let o = mvem(d, &["validate", "--data", "c", "--params", "l.toml"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("sensor time constants"),
        "{}",
        stderr(&o)
    );
    for bad in ["x_egr=0.01", "p_im=-1", "p_em"] {
        let o = step3_with("--sensor-lags", bad);
        assert!(!o.status.success(), "{bad}");
        assert!(
            stderr(&o).contains("--sensor-lags"),
            "{bad}: {}",
            stderr(&o)
        );
    }
    // steps 3-4 only (base: published): runs, writes the parameter file and the report
    let o = mvem(
        d,
        &[
            "tune", "--data", "c", "--steps", "3-4", "--out", "t.toml", "--report", "rep",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("t.toml").is_file() && d.join("rep/tune_report.json").is_file());
    let md = String::from_utf8_lossy(&o.stdout);
    assert!(
        md.contains("| intake_manifold.v_im |") && md.contains("| test_cell.tau_me |"),
        "{md}"
    );
    // uncertainty per parameter-file path
    let rep: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("rep/tune_report.json")).unwrap()).unwrap();
    for path in [
        "intake_manifold.v_im",
        "exhaust_manifold.v_em",
        "turbo.j_t",
        "test_cell.tau_me",
    ] {
        let e = &rep["parameters"][path];
        assert!(e["value"].as_f64().unwrap() > 0.0, "{path}: {e}");
        assert!(e["std_error"].as_f64().is_some(), "{path}: {e}");
        assert!(
            e["identifiable"].is_boolean() && e["correlated_with"].is_array(),
            "{e}"
        );
    }
    // tau_Me is written to the [test_cell] section; validate uses it (equal to --tau-me)
    let toml = std::fs::read_to_string(d.join("t.toml")).unwrap();
    assert!(toml.contains("[test_cell]\ntau_me = "), "{toml}");
    let tau = rep["parameters"]["test_cell.tau_me"]["value"]
        .as_f64()
        .unwrap();
    assert!((tau - 1.0).abs() < 1e-2, "{tau}");
    let val = |extra: &[&str]| {
        let mut args = vec!["validate", "--data", "c", "--params", "t.toml", "--json"];
        args.extend_from_slice(extra);
        let o = mvem(d, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let tau_s = format!("{tau:e}");
    let (auto, given) = (val(&[]), val(&["--tau-me", &tau_s]));
    assert_eq!(auto, given);
    let unfiltered = val(&["--tau-me", "0.001"]);
    assert_ne!(
        auto["datasets"]["I"]["M_e"],
        unfiltered["datasets"]["I"]["M_e"]
    );

    // a failing step is named, exit code 1, nothing written (no actuator set J)
    std::fs::create_dir(d.join("noj")).unwrap();
    for f in ["stationary.csv", "B.csv", "C.csv", "I.csv", "Q.csv"] {
        std::fs::copy(d.join("c").join(f), d.join("noj").join(f)).unwrap();
    }
    let m = std::fs::read_to_string(d.join("c/manifest.toml")).unwrap();
    let cut = m.find("[[dataset]]\nname = \"J\"").unwrap();
    std::fs::write(d.join("noj/manifest.toml"), &m[..cut]).unwrap();
    let o = mvem(
        d,
        &[
            "tune", "--data", "noj", "--steps", "2", "--out", "x.toml", "--report", "xr",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("tuning step 2 (actuators from the actuator set)")
            && stderr(&o).contains("no actuator data set")
            && stderr(&o).contains("this campaign supports steps 1,3,4,5"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("x.toml").exists() && !d.join("xr").exists());

    // bad data: a non-number in B.csv -> exit 2, message names file, line and column
    let b = std::fs::read_to_string(d.join("c/B.csv")).unwrap();
    let mut lines: Vec<String> = b.lines().map(str::to_string).collect();
    let mut cells: Vec<String> = lines[3].split(',').map(str::to_string).collect();
    cells[2] = "abc".into();
    lines[3] = cells.join(",");
    std::fs::write(d.join("c/B.csv"), lines.join("\n")).unwrap();
    let o = mvem(d, &["tune", "--data", "c", "--out", "y.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("B.csv") && e.contains('4') && e.contains("p_em"),
        "{e}"
    );
    assert!(!d.join("y.toml").exists());
    // usage errors
    let o = mvem(
        d,
        &["tune", "--data", "c", "--out", "y.toml", "--steps", "0-9"],
    );
    assert_eq!(o.status.code(), Some(2));
    let o = mvem(d, &["lab", "--out", "z", "--noise", "loud"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--noise"));
}

#[test]
fn lab_tune_validate_12_state() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let lab = |out: &str, model: &str| {
        mvem(
            d,
            &[
                "lab",
                "--out",
                out,
                "--sets",
                "B",
                "--max-steps",
                "2",
                "--n-stationary",
                "13",
                "--noise",
                "none",
                "--model",
                model,
            ],
        )
    };
    let o = lab("c12", "12");
    assert!(o.status.success(), "{}", stderr(&o));
    // the stationary CSV carries p_c before the intercooler, above p_im
    let csv = std::fs::read_to_string(d.join("c12/stationary.csv")).unwrap();
    let head: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    for line in csv.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        assert!(v[col("p_c")] > v[col("p_im")] + 100.0, "{line}");
    }
    // the true parameters validate to ~0 with the 12-state model (W_ic row included) and not
    // with the 8-state model (no intercooler drop)
    let val = |model: &str| {
        let o = mvem(
            d,
            &[
                "validate",
                "--data",
                "c12",
                "--params",
                "c12/true_params.toml",
                "--json",
                "--model",
                model,
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let v12 = val("12");
    assert!(v12["stationary"]["W_ic"].as_f64().unwrap() < 1e-4);
    let e12 = v12["datasets"]["B"]["p_im"].as_f64().unwrap();
    let e8 = val("8")["datasets"]["B"]["p_im"].as_f64().unwrap();
    assert!(e12 < 0.01 && e8 > 10.0 * e12, "p_im: 12 {e12} %, 8 {e8} %");
    // step 3 and the 12-state steps 6 (k_ic) and 7 (V_ic, ...): the output has the intercooler
    let o = mvem(
        d,
        &[
            "tune",
            "--data",
            "c12",
            "--steps",
            "3",
            "--model",
            "12",
            "--params",
            "c12/true_params.toml",
            "--out",
            "t12.toml",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let md = String::from_utf8_lossy(&o.stdout);
    assert!(md.contains("Step 6") && md.contains("| k_ic |"), "{md}");
    let t: toml::Value =
        toml::from_str(&std::fs::read_to_string(d.join("t12.toml")).unwrap()).unwrap();
    let k = t["intercooler"]["k_ic"].as_float().unwrap();
    assert!((k / 1.9e7 - 1.0).abs() < 1e-5, "k_ic {k}");
    // bad usage: --model 10 (nothing to tune), --model 13; exit 2, nothing written
    for m in ["10", "13"] {
        let o = mvem(
            d,
            &["tune", "--data", "c12", "--model", m, "--out", "bad.toml"],
        );
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains("--model"), "{}", stderr(&o));
    }
    let o = mvem(d, &["lab", "--out", "z", "--model", "9"]);
    assert_eq!(o.status.code(), Some(2));
    // bad step-3 weights: named, exit 2, nothing written
    for (flag, v) in [
        ("--step3-window", "0"),
        ("--step3-window", "NaN"),
        ("--step3-tail-weight", "0"),
        ("--step3-tail-weight", "1.5"),
    ] {
        let o = mvem(d, &["tune", "--data", "c12", "--out", "bad.toml", flag, v]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(flag), "{}", stderr(&o));
        assert!(!d.join("bad.toml").exists());
    }
    // an 8-state campaign has no intercooler drop: step 6 fails by name, exit 1
    let o = lab("c8", "8");
    assert!(o.status.success(), "{}", stderr(&o));
    let o = mvem(
        d,
        &[
            "tune", "--data", "c8", "--steps", "2", "--model", "12", "--out", "bad.toml",
        ],
    );
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("tuning step 6"), "{}", stderr(&o));
    assert!(!d.join("bad.toml").exists());
}

/// `mvem lab --out c --no-dynamic --n-stationary 30 EXTRA...` in `d` (a stationary campaign of
/// 30 points for step 1), which must succeed.
fn stationary_campaign(d: &std::path::Path, extra: &[&str]) {
    let mut args = vec!["lab", "--out", "c", "--no-dynamic", "--n-stationary", "30"];
    args.extend_from_slice(extra);
    let o = mvem(d, &args);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `mvem lab --out c --sets SETS --max-steps 2 --n-stationary 20` in `d` (a small campaign with
/// the actuator set J), which must succeed.
fn small_campaign(d: &std::path::Path, sets: &str) {
    let args = [
        "lab",
        "--out",
        "c",
        "--sets",
        sets,
        "--max-steps",
        "2",
        "--n-stationary",
        "20",
    ];
    let o = mvem(d, &args);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `mvem tune --data c --steps 1 --out t.toml --report REP EXTRA...` in `d`: its stderr and
/// report.
fn tune_step1(d: &std::path::Path, extra: &[&str], rep: &str) -> (String, serde_json::Value) {
    let mut args = vec![
        "tune", "--data", "c", "--steps", "1", "--out", "t.toml", "--report", rep,
    ];
    args.extend_from_slice(extra);
    let o = mvem(d, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join(rep).join("tune_report.json")).unwrap())
            .unwrap();
    (stderr(&o), json)
}

/// A campaign of another engine (4 cylinders of 15.9 dm^3 in all, the published turbo,
/// measured at 95 kPa and 288 K): `mvem tune` without --params says that it uses the published engine's
/// constants, names the constants that differ from the campaign's true engine, and flags the
/// volumetric and indicated efficiencies they imply; the ambient comes from the stationary
/// points. With the engine's constants in --params none of that appears.
#[test]
fn tune_checks_the_engine_constants_and_takes_the_ambient_from_the_data() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let text = published_toml(d);
    let set = |t: &str, key: &str, val: &str| -> String {
        let mut n = 0;
        let out: Vec<String> = t
            .lines()
            .map(|l| {
                if l.starts_with(&format!("{key} = ")) && n == 0 {
                    n += 1;
                    format!("{key} = {val}")
                } else {
                    l.to_string()
                }
            })
            .collect();
        assert_eq!(n, 1, "{key}");
        out.join("\n") + "\n"
    };
    let mut other = set(&text, "n_cyl", "4.0");
    other = set(&other, "v_d", "0.0159");
    other = set(&other, "p_amb", "95000.0");
    other = set(&other, "t_amb", "288.0");
    other = set(&other, "t_w", "288.0");
    std::fs::write(d.join("other.toml"), other).unwrap();
    stationary_campaign(d, &["--params", "other.toml"]);
    let tune = |extra: &[&str], rep: &str| tune_step1(d, extra, rep);
    let (err, json) = tune(&[], "r1");
    assert!(
        err.contains("constants are the published engine's"),
        "{err}"
    );
    assert!(err.contains("warning: the constants used differ"), "{err}");
    assert!(
        err.contains("cylinder.v_d 0.01274 (the campaign's engine: 0.0159)"),
        "{err}"
    );
    assert!(err.contains("cylinder.n_cyl 6"), "{err}");
    let caveats: Vec<&str> = json["caveats"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    // the implied volumetric efficiency (about 0.92 x 1.25) and indicated efficiency (4/6)
    assert!(
        caveats.iter().any(|c| c.contains("volumetric efficiency")),
        "{caveats:?}"
    );
    assert!(
        caveats.iter().any(|c| c.contains("n_cyl = 6")),
        "{caveats:?}"
    );
    assert!(caveats.iter().any(|c| c.contains("differ")), "{caveats:?}");
    // the ambient of the campaign: 30 points with 0.5 % and 1 K noise
    let p_amb = json["ambient"]["p_amb"]["used"].as_f64().unwrap();
    let t_amb = json["ambient"]["t_amb"]["used"].as_f64().unwrap();
    assert_eq!(json["ambient"]["p_amb"]["from_data"], true);
    assert!((p_amb / 95_000.0 - 1.0).abs() < 0.003, "{p_amb}");
    assert!((t_amb - 288.0).abs() < 0.8, "{t_amb}");
    let tuned = std::fs::read_to_string(d.join("t.toml")).unwrap();
    assert!(tuned.contains(&format!("p_amb = {p_amb:?}")), "{p_amb}");
    // with the engine's constants: nothing to say about them; step 1's compressor-efficiency
    // peak ends on its box's W_copt = 2 kg/s (this campaign's largest W_c lies below 0.8 kg/s,
    // where the box is the published one, tuning::scale), which is said
    let (err, json) = tune(&["--params", "other.toml"], "r2");
    assert!(!err.contains("constants"), "{err}");
    let caveats = json["caveats"].as_array().unwrap();
    assert_eq!(caveats.len(), 1, "{json}");
    assert!(
        caveats[0]
            .as_str()
            .unwrap()
            .starts_with("step 1 ended with w_copt = 2.0000e0 (bound 2e0)"),
        "{json}"
    );
    assert_eq!(json["ambient"]["p_amb"]["from_data"], false, "{json}");
    // the published constants and --ambient params: the file's 101.1 kPa and 298.5 K
    let (_, json) = tune(&["--ambient", "params"], "r3");
    let a = &json["ambient"];
    assert_eq!(a["p_amb"]["from_data"], false);
    assert_eq!(a["p_amb"]["used"], a["p_amb"]["file"]);
    assert!((a["p_amb"]["file"].as_f64().unwrap() - 101_111.34).abs() < 0.01);
}

/// `mvem lab --speeds` maps the design onto another engine's speeds, within the model's speed
/// saturation (the parameter file's `input_saturation`), and refuses a design beyond it.
#[test]
fn lab_envelope_is_checked_against_the_input_saturation() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let o = mvem(d, &["lab", "--out", "c", "--speeds", "1750:4250"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("1125-4042 r/min"), "{err}");
    assert!(err.contains("speed range 500-2000 r/min"), "{err}");
    let o = mvem(d, &["lab", "--out", "c", "--speeds", "4000"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("expected LO:HI"), "{}", stderr(&o));
    // a smaller speed range and less fuel: the ESC points move with it
    let o = mvem(
        d,
        &[
            "lab",
            "--out",
            "c",
            "--speeds",
            "1000:2000",
            "--full-load",
            "180",
            "--no-dynamic",
            "--n-stationary",
            "13",
            "--noise",
            "none",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(d.join("c/stationary.csv")).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
    let (ne, ud) = (col("n_e"), col("u_delta"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    // idle 600 -> 750 r/min at 10 % of 180 mg; ESC A (1200) -> 1250 r/min at 100 %
    assert!((rows[0][ne] - 750.0).abs() < 1e-9 && (rows[0][ud] - 18.0).abs() < 1e-9);
    assert!((rows[1][ne] - 1250.0).abs() < 1e-9 && (rows[1][ud] - 180.0).abs() < 1e-9);
}

/// A campaign of an engine that runs beyond the authors' 500-2000 rpm and 250 mg, tuned with a
/// parameter file that does not set `[input_saturation]`: by default the ranges are widened to
/// the campaign (said on stderr and in the report, written to --out); `--input-ranges params`
/// keeps the file's and the report says the points ran clamped.
#[test]
fn tune_widens_the_input_ranges_to_the_campaign() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write_published_with(
        d,
        "wide.toml",
        &[
            ("n_e = [500.0, 2000.0]", "n_e = [500.0, 2600.0]"),
            ("u_delta = [1.0, 250.0]", "u_delta = [1.0, 280.0]"),
        ],
    );
    stationary_campaign(
        d,
        &[
            "--params",
            "wide.toml",
            "--speeds",
            "1000:2500",
            "--full-load",
            "260",
        ],
    );
    let tune = |extra: &[&str], rep: &str| tune_step1(d, extra, rep);
    let (err, json) = tune(&[], "r1");
    assert!(
        err.contains("warning: input_saturation widened to the campaign: n_e 500-"),
        "{err}"
    );
    let w = &json["input_saturation"];
    let hi = w["n_e"][1].as_f64().unwrap();
    assert!(hi > 2000.0 && hi < 2600.0, "{w}");
    assert_eq!(w["n_e_file"][1], 2000.0);
    assert_eq!(w["u_delta"][1], 260.0, "{w}");
    let tuned = std::fs::read_to_string(d.join("t.toml")).unwrap();
    assert!(tuned.contains(&format!("n_e = [500.0, {hi:?}]")), "{tuned}");
    assert!(tuned.contains("u_delta = [1.0, 260.0]"), "{tuned}");
    let md = std::fs::read_to_string(d.join("r1").join("tune_report.md")).unwrap();
    assert!(md.contains("**Note:** input_saturation widened"), "{md}");
    assert!(json["caveats"].as_array().unwrap().iter().all(|c| !c
        .as_str()
        .unwrap()
        .contains("outside the model's input saturation")));
    // the file's ranges: nothing widened, the clamped points named
    let (err, json) = tune(&["--input-ranges", "params"], "r2");
    assert!(!err.contains("widened"), "{err}");
    assert!(json["input_saturation"].is_null(), "{json}");
    assert!(
        json["caveats"].as_array().unwrap().iter().any(|c| c
            .as_str()
            .unwrap()
            .contains("outside the model's input saturation")),
        "{json}"
    );
    // the wide engine's own file: nothing to widen
    let (err, json) = tune(&["--params", "wide.toml"], "r3");
    assert!(!err.contains("widened"), "{err}");
    assert!(json["input_saturation"].is_null(), "{json}");
}

#[test]
fn campaign_summary_says_which_steps_the_data_support() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_campaign(d, "B,C,Q");
    let o = mvem(d, &["campaign", "--data", "c", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["stationary_points"], 20);
    // B, C, Q and the actuator set J; no fuel set: step 4 is not supported
    let sets: Vec<&str> = v["datasets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert_eq!(sets, ["B", "Q", "C", "J"]);
    let ok = supported(&v);
    assert_eq!(ok, [true, true, true, false, true]);
    assert_eq!(v["steps"][2]["uses"], "sets B, C");
    let o = mvem(d, &["campaign", "--data", "c"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("NO  step 4 (tau_Me): no fuel-step set"),
        "{text}"
    );
    // a bad campaign: the loader's error, exit code 2
    std::fs::write(d.join("c").join("manifest.toml"), "stationary = 3\n").unwrap();
    let o = mvem(d, &["campaign", "--data", "c"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("manifest.toml"), "{}", stderr(&o));
}

#[test]
fn campaign_init_drafts_a_manifest_that_loads() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_campaign(d, "B,I");
    std::fs::remove_file(d.join("c/manifest.toml")).unwrap();
    let o = mvem(d, &["campaign", "--data", "c", "--init", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("B.csv: set B, kind vgt-egr, roles static, dynamic"));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // B, I and the actuator set J: every step supported
    let ok = supported(&v);
    assert_eq!(ok, [true; 5]);
    let text = std::fs::read_to_string(d.join("c/manifest.toml")).unwrap();
    assert!(text.starts_with("# drafted by `mvem campaign --init`"));
    // an existing manifest is kept unless --force
    let o = mvem(d, &["campaign", "--data", "c", "--init"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--force replaces it"), "{}", stderr(&o));
    assert!(mvem(d, &["campaign", "--data", "c", "--init", "--force"])
        .status
        .success());
}

/// The "supported" flags of `mvem campaign --json`'s steps 1-5.
fn supported(v: &serde_json::Value) -> Vec<bool> {
    v["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["supported"].as_bool().unwrap())
        .collect()
}

/// QA findings: `mvem validate` ran engine speeds beyond `[input_saturation]` and turbo speeds
/// above `[integrator_limits]` clamped without a word (tune warned of the first only), and
/// `--roles validation` on a campaign without such a set printed the stationary table alone.
#[test]
fn validate_warns_of_clamped_inputs_and_of_roles_without_sets() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let wide = [
        ("n_e = [500.0, 2000.0]", "n_e = [500.0, 2600.0]"),
        ("u_delta = [1.0, 250.0]", "u_delta = [1.0, 280.0]"),
    ];
    write_published_with(d, "wide.toml", &wide);
    write_published_with(d, "pub.toml", &[]);
    let slow = [
        wide[0],
        wide[1],
        ("n_t = [100.0, 200000.0]", "n_t = [100.0, 50000.0]"),
    ];
    write_published_with(d, "slow.toml", &slow);
    stationary_campaign(
        d,
        &[
            "--params",
            "wide.toml",
            "--speeds",
            "1000:2500",
            "--full-load",
            "260",
        ],
    );
    let validate = |params: &str| {
        let o = mvem(
            d,
            &[
                "validate",
                "--data",
                "c",
                "--params",
                params,
                "--roles",
                "validation",
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let err = validate("pub.toml");
    assert!(
        err.contains("warning: no data set has the role validation: only the stationary points"),
        "{err}"
    );
    assert!(
        err.contains("lie outside the model's input saturation (n_e 500-2000 rpm"),
        "{err}"
    );
    assert!(!err.contains("integrator"), "{err}");
    let err = validate("wide.toml");
    assert!(!err.contains("input saturation"), "{err}");
    let err = validate("slow.toml");
    assert!(
        err.contains("measure turbo speeds above the model's limit n_t = 50000 rpm"),
        "{err}"
    );
}

/// A name copied from `mvem tune`'s report names the element the user means: the keys of
/// tune_report.json "parameters" and the rows of tune_report.md count vector and matrix
/// elements from 1, as the parameter registry, `mvem params check` and Python's `params=` do, so
/// "cylinder.c_fric[1]" is the first number of `c_fric` in the written file's [cylinder] section,
/// and the truth the .md table compares it with is c_fric1's. Before, the report counted from 0
/// ("cylinder.c_fric[0]" for c_fric1) and its paths named other elements where pasted.
#[test]
fn tune_report_names_elements_as_the_parameter_file_counts_them() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    stationary_campaign(d, &[]);
    let (_, json) = tune_step1(d, &[], "rep");
    let file: toml::Value =
        toml::from_str(&std::fs::read_to_string(d.join("t.toml")).unwrap()).unwrap();
    // the value at a report key in the parsed file, indices 1-based
    let at = |key: &str| -> Option<f64> {
        let (section, rest) = key.split_once('.')?;
        let mut parts = rest.split('[');
        let mut v = file.get(section)?.get(parts.next()?)?;
        for i in parts {
            let i: usize = i.trim_end_matches(']').parse().ok()?;
            v = v.as_array()?.get(i.checked_sub(1)?)?;
        }
        v.as_float()
    };
    let params = json["parameters"].as_object().unwrap();
    let mut elements = 0;
    for (key, e) in params {
        assert_eq!(at(key), e["value"].as_f64(), "{key}");
        let info = mvem::params::ParamInfo::find(key).unwrap();
        assert_eq!(&info.path, key);
        elements += usize::from(key.contains('['));
    }
    assert!(elements >= 20, "{elements}");
    assert!(
        params.contains_key("cylinder.c_fric[1]") && !params.contains_key("cylinder.c_fric[0]")
    );
    let c_fric = file["cylinder"]["c_fric"].as_array().unwrap();
    assert_eq!(
        params["cylinder.c_fric[1]"]["value"].as_f64(),
        c_fric[0].as_float()
    );
    // the .md table: the same name, against the truth of that element
    let md = std::fs::read_to_string(d.join("rep").join("tune_report.md")).unwrap();
    let row = md
        .lines()
        .find(|l| l.starts_with("| cylinder.c_fric[1] |"))
        .unwrap_or_else(|| panic!("{md}"));
    let truth = mvem::params::Params::published().cylinder.c_fric[0];
    assert!(row.contains(&format!("| {truth:.6e} |")), "{row}");
    assert!(md.contains("Elements are counted from 1"), "{md}");
}

/// Session 40: `mvem tune` and `mvem validate` warn of EGR and VGT commands outside their
/// parameter file's command ranges (`[input_saturation] u_egr`, `u_vgt`) as `mvem campaign
/// --params` does (before, only `campaign` did, and the model ran them clamped without a word).
/// The lab's actuator set J commands the VGT down to 10 %: below the published [20, 100] %.
#[test]
fn campaign_tune_and_validate_warn_of_commands_outside_the_command_ranges() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    small_campaign(d, "I");
    write_published_with(d, "pub.toml", &[]);
    let vgt = ("u_vgt = [20.0, 100.0]", "u_vgt = [10.0, 100.0]");
    write_published_with(d, "wide.toml", &[vgt]);
    write_published_with(
        d,
        "egr30.toml",
        &[vgt, ("u_egr = [0.0, 100.0]", "u_egr = [0.0, 30.0]")],
    );
    let j_vgt = |set: &str| {
        format!(
            "warning: set J (J.csv): u_vgt leaves the VGT command range [20, 100] % of {set} \
             (input_saturation.u_vgt) at 100 of 5000 samples (100 below, down to 10 % (10 \
             points of % under 20 %)); the model runs these commands clamped"
        )
    };
    // campaign --params: the file's ranges, named by the file
    let campaign = |params: &[&str]| {
        let mut args = vec!["campaign", "--data", "c"];
        args.extend_from_slice(params);
        let o = mvem(d, &args);
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).to_string()
    };
    let out = campaign(&[]);
    assert!(out.contains(&j_vgt("the published parameters")), "{out}");
    let out = campaign(&["--params", "pub.toml"]);
    assert!(out.contains(&j_vgt("pub.toml")), "{out}");
    assert!(!campaign(&["--params", "wide.toml"]).contains("leaves the"));
    let out = campaign(&["--params", "egr30.toml"]);
    assert!(
        out.contains(
            "warning: the stationary points (stationary.csv): u_egr leaves the EGR-valve command \
             range [0, 30] % of egr30.toml (input_saturation.u_egr) at "
        ) && !out.contains("u_vgt leaves"),
        "{out}"
    );
    // tune (step 2 alone, on the actuator set) and validate: the same warnings on stderr
    let run = |args: &[&str]| {
        let o = mvem(d, args);
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let tune = |params: &[&str]| {
        let mut args = vec!["tune", "--data", "c", "--steps", "2", "--out", "t.toml"];
        args.extend_from_slice(params);
        run(&args)
    };
    let err = tune(&[]);
    assert!(err.contains(&j_vgt("the published parameters")), "{err}");
    let err = tune(&["--params", "pub.toml"]);
    assert!(err.contains(&j_vgt("the parameters given")), "{err}");
    assert!(!tune(&["--params", "wide.toml"]).contains("leaves the"));
    let validate = |params: &str| {
        run(&[
            "validate", "--data", "c", "--params", params, "--roles", "actuator",
        ])
    };
    let err = validate("pub.toml");
    assert!(err.contains(&j_vgt("the parameters validated")), "{err}");
    assert!(!validate("wide.toml").contains("leaves the"));
    let err = validate("egr30.toml");
    assert!(
        err.contains(
            "u_egr leaves the EGR-valve command range [0, 30] % of the parameters validated"
        ),
        "{err}"
    );
}
