//! The HTTP API of `mvem serve` on loopback: answers, errors naming the parameter, size and
//! concurrency limits, query parsing under random input, and a load of concurrent requests.

use mvem::analysis::steady::steady_state;
use mvem::control::baseline::BaselineTuning;
use mvem::control::drive::{self, CycleSource, Scheme};
use mvem::model::{AnyModel, Drive, Engine8};
use mvem_serve::client::{self, Reply};
use mvem_serve::{Config, Running};
use proptest::prelude::*;
use std::net::SocketAddr;
use std::sync::OnceLock;
use std::time::Duration;

const WHTC: &str = include_str!("../../../data/whtc_inputs_10hz.csv");
const POINT: &str = "n_e=1500&u_delta=110&u_egr=80&u_vgt=75";

/// One server for the tests of this file (each test makes its own requests).
fn server() -> SocketAddr {
    static S: OnceLock<Running> = OnceLock::new();
    S.get_or_init(|| {
        let mut c = Config::local(0);
        c.cycles = vec![("whtc".into(), WHTC)];
        // the published set with an engine speed range to 3000 rpm (its input saturation)
        let mut second = mvem::params::Params::published();
        second.input_saturation.n_e = [500.0, 3000.0];
        c.params.push(("second".into(), second));
        mvem_serve::start(c).expect("start the server")
    })
    .addr
}

fn get(target: &str) -> Reply {
    client::get(server(), target).unwrap_or_else(|e| panic!("GET {target}: {e}"))
}

fn post(target: &str, body: &str) -> Reply {
    client::post(server(), target, body.as_bytes()).unwrap_or_else(|e| panic!("POST {target}: {e}"))
}

/// A 400 whose `error` names `name`.
fn assert_400_naming(r: &Reply, name: &str, what: &str) {
    let body = String::from_utf8_lossy(&r.body);
    assert_eq!(r.status, 400, "{what}: {body}");
    let e = r.json()["error"].as_str().unwrap_or_default().to_string();
    assert!(e.contains(name), "{what}: error {e:?} should name {name}");
}

#[test]
fn health_models_and_page() {
    let h = get("/api/health");
    assert_eq!(h.status, 200);
    assert_eq!(h.json()["status"], "ok");
    let m = get("/api/models").json();
    assert_eq!(m["params"], serde_json::json!(["published", "second"]));
    // the explorer's sliders span each set's input saturation
    assert_eq!(
        m["input_ranges"],
        serde_json::json!({
            "published": {"n_e": [500.0, 2000.0], "u_delta": [1.0, 250.0], "u_egr": [0.0, 100.0], "u_vgt": [20.0, 100.0]},
            "second": {"n_e": [500.0, 3000.0], "u_delta": [1.0, 250.0], "u_egr": [0.0, 100.0], "u_vgt": [20.0, 100.0]},
        })
    );
    assert_eq!(m["cycles"], serde_json::json!(["whtc"]));
    assert_eq!(m["units"]["p_im"], "Pa");
    assert_eq!(m["units"]["T_ic"], "K", "12-state names have units");
    // the closed loop's references have units too
    assert_eq!(m["units"]["M_ref"], "Nm");
    assert_eq!(m["units"]["lambda_O_ref"], "-");
    assert_eq!(m["units"]["x_egr_ref"], "-");
    // the closed loop's controller tuning: the core's defaults and a row per field a user sets
    let tuning = &m["controller_tuning"];
    assert_eq!(
        tuning["defaults"],
        serde_json::to_value(mvem::control::baseline::BaselineTuning::default()).unwrap()
    );
    let fields = tuning["fields"].as_array().unwrap();
    assert_eq!(
        fields.len(),
        mvem::control::baseline::BaselineTuning::FIELDS.len()
    );
    assert_eq!(fields.len(), 21);
    assert_eq!(fields[2]["name"], "torque");
    assert_eq!(fields[2]["unit"], "mg/Nm, mg/(Nm s)");
    assert!(fields.iter().all(|f| tuning["defaults"]
        .get(f["name"].as_str().unwrap())
        .is_some()));
    for (path, ty) in [
        ("/", "text/html"),
        ("/app.js", "text/javascript"),
        ("/app.css", "text/css"),
    ] {
        let r = get(path);
        assert_eq!(r.status, 200, "{path}");
        assert!(r.header("content-type").unwrap().starts_with(ty), "{path}");
    }
    let r = get("/nothing/here");
    assert_eq!(r.status, 404);
    assert!(r.json()["error"].is_string());
}

#[test]
fn steady_equals_the_library_and_every_model_and_set_answers() {
    let r = get(&format!("/api/steady?{POINT}"));
    assert_eq!(r.status, 200);
    let v = r.json();
    let ss = steady_state(
        &Engine8::published(),
        &Drive::new(1500.0, 110.0, 80.0, 75.0),
    )
    .unwrap();
    assert_eq!(v["p_im"].as_f64().unwrap().to_bits(), ss.x[0].to_bits());
    assert_eq!(
        v["W_c"].as_f64().unwrap().to_bits(),
        ss.signals.w_c.to_bits()
    );
    assert_eq!(v["physically_valid"], true);
    for (model, states) in [("8", 8), ("10", 10), ("12", 12)] {
        let r = get(&format!("/api/steady?{POINT}&model={model}&params=second"));
        assert_eq!(r.status, 200, "model {model}");
        assert_eq!(
            r.json()["eigenvalues"].as_array().unwrap().len(),
            states - 3,
            "model {model}: eigenvalues of the non-actuator states"
        );
    }
}

#[test]
fn bad_or_missing_parameters_give_400_naming_them() {
    let full = |drop: &str, set: &str| {
        let mut q: Vec<String> = POINT
            .split('&')
            .filter(|kv| !kv.starts_with(&format!("{drop}=")))
            .map(str::to_string)
            .collect();
        if !set.is_empty() {
            q.push(set.to_string());
        }
        format!("/api/steady?{}", q.join("&"))
    };
    for name in ["n_e", "u_delta", "u_egr", "u_vgt"] {
        assert_400_naming(&get(&full(name, "")), name, &format!("missing {name}"));
        for bad in ["NaN", "inf", "-inf", "abc", "", "1e999", "0x10", "1,5"] {
            let r = get(&full(name, &format!("{name}={bad}")));
            assert_400_naming(&r, name, &format!("{name}={bad}"));
        }
    }
    assert_400_naming(
        &get(&format!("/api/steady?{POINT}&model=9")),
        "model",
        "model 9",
    );
    assert_400_naming(
        &get(&format!("/api/steady?{POINT}&params=../etc/passwd")),
        "params",
        "params",
    );
    assert_400_naming(
        &get(&format!("/api/steady?{POINT}&n_e=1500")),
        "n_e",
        "twice",
    );
    assert_400_naming(
        &get(&format!("/api/steady?{POINT}&u_vtg=3")),
        "u_vtg",
        "unknown",
    );
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&pade=7")),
        "pade",
        "pade",
    );
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&ts=1e-6")),
        "ts",
        "sample time",
    );
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&ts=0.01&pade=2")),
        "ts",
        "pade",
    );
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&outputs=W_c,nope")),
        "nope",
        "outputs",
    );
    for (bode, what) in [
        ("0:100:10", "f_min"),
        ("1:100", "FMIN:FMAX:N"),
        ("1:100:x", "whole number"),
        ("1:100:5000", "at most 2000 points"),
    ] {
        assert_400_naming(
            &get(&format!("/api/linearize?{POINT}&bode={bode}")),
            "bode",
            what,
        );
    }
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&bode=1:10:5&pade=1")),
        "bode",
        "pade",
    );
    // bodies
    let step = |s: &str| post("/api/step", s);
    assert_400_naming(&step("{"), "body", "truncated JSON");
    assert_400_naming(
        &step(
            r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80}, "input": "u_vgt", "target": 65}"#,
        ),
        "u_vgt",
        "missing point field",
    );
    assert_400_naming(
        &step(
            r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vtg", "target": 65}"#,
        ),
        "input",
        "bad input",
    );
    assert_400_naming(
        &step(
            r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 75}"#,
        ),
        "target",
        "no step",
    );
    assert_400_naming(
        &step(
            r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 65, "horizon": 1e6}"#,
        ),
        "horizon",
        "long horizon",
    );
    assert_400_naming(
        &step(
            r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 65, "colour": 1}"#,
        ),
        "colour",
        "unknown field",
    );
    assert_400_naming(
        &step(
            r#"{"point": {"n_e": 1e999, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 65}"#,
        ),
        "body",
        "number out of range",
    );
    let map = |x: &str| {
        post(
            "/api/map",
            &format!(
                r#"{{"base": {{"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}}, {x}, "y": {{"input": "u_vgt", "lo": 20.5, "hi": 100, "n": 3}}, "channel": {{"input": "u_vgt", "output": "W_c"}}}}"#
            ),
        )
    };
    assert_400_naming(
        &map(r#""x": {"input": "u_egr", "lo": 0, "hi": 100, "n": 1000}"#),
        "x.n",
        "grid too large",
    );
    assert_400_naming(
        &map(r#""x": {"input": "u_egr", "lo": 100, "hi": 0, "n": 3}"#),
        "x.lo",
        "reversed axis",
    );
    assert_400_naming(
        &map(r#""x": {"input": "u_vgt", "lo": 20.5, "hi": 100, "n": 3}"#),
        "u_vgt",
        "same input twice",
    );
    assert_400_naming(
        &post("/api/simulate", r#"{"cycle": "nedc"}"#),
        "cycle",
        "unknown cycle",
    );
    // a body's type error names the field by its path; trailing text is refused
    assert_400_naming(
        &post(
            "/api/margins",
            r#"{"point": {"n_e": "fast", "u_delta": 110, "u_egr": 50, "u_vgt": 60}}"#,
        ),
        "body: point.n_e: invalid type",
        "a string for a number",
    );
    assert_400_naming(
        &post("/api/simulate", r#"{"cycle": "whtc", "dt": 1} {"#),
        "body: trailing characters",
        "two values",
    );
    assert_400_naming(
        &post("/api/simulate", r#"{"cycle": "whtc", "mode": "mpc"}"#),
        "mode",
        "unknown mode",
    );
    assert_400_naming(
        &post(
            "/api/simulate",
            r#"{"csv": "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1500,110,80,75\n2,1500,110,80,65\n", "mode": "closed"}"#,
        ),
        "mode \"closed\" reads a speed/torque demand",
        "closed loop on an inputs CSV",
    );
    assert_400_naming(
        &post(
            "/api/simulate",
            r#"{"cycle": "whtc", "mode": "closed", "outputs": ["T_em"]}"#,
        ),
        "outputs",
        "not a closed-loop series",
    );
    assert_400_naming(
        &post(
            "/api/simulate",
            r#"{"csv": "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1500,110,80,abc\n"}"#,
        ),
        "line 2",
        "bad CSV cell",
    );
    assert_400_naming(
        &post("/api/simulate", r#"{"cycle": "whtc", "dt": 1e-6}"#),
        "dt",
        "too many samples",
    );
    // the server is fine afterwards
    assert_eq!(get(&format!("/api/steady?{POINT}")).status, 200);
}

#[test]
fn an_oversized_body_gets_413() {
    let big = format!(r#"{{"csv": "{}"}}"#, "x".repeat(5 << 20));
    let r = post("/api/simulate", &big);
    assert_eq!(r.status, 413, "{}", String::from_utf8_lossy(&r.body));
    assert!(r.json()["error"].as_str().unwrap().contains("too large"));
    assert_eq!(get("/api/health").status, 200);
}

#[test]
fn step_map_and_cycle_answer() {
    let r = post(
        "/api/step",
        r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 30}, "input": "u_vgt", "target": 25, "horizon": 6, "model": 10}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    // the paper's second VGT step: W_c overshoots with a positive DC gain (Fig. 8)
    assert_eq!(v["outputs"]["W_c"]["gain_sign"], "positive");
    assert!(v["outputs"]["W_c"]["overshoot_pct"].as_f64().unwrap() > 1.0);

    let r = post(
        "/api/map",
        r#"{"base": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75},
            "x": {"input": "u_egr", "lo": 0, "hi": 100, "n": 5},
            "y": {"input": "u_vgt", "lo": 20.5, "hi": 100, "n": 6},
            "channel": {"input": "u_vgt", "output": "W_c"}}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    let sign = v["sign"].as_array().unwrap();
    assert_eq!(sign.len(), 30);
    // the gain's unit as the page and the CLI's map write it
    assert_eq!(v["channel"]["unit"], "kg/s/%");
    // the sign reversal of u_vgt -> W_c: both signs occur over the map (section 8 of the paper)
    assert!(
        sign.iter().any(|s| s == 1) && sign.iter().any(|s| s == -1),
        "{sign:?}"
    );

    let r = post("/api/simulate", r#"{"cycle": "whtc", "dt": 1.0}"#);
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    let t = v["t"].as_array().unwrap();
    assert_eq!(t.len(), 1801, "0..1800 s at 1 s");
    assert_eq!(v["series"]["M_e"].as_array().unwrap().len(), 1801);
    assert_eq!(v["inputs"]["n_e"].as_array().unwrap().len(), 1801);
    let csv = r#"{"csv": "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1500,110,80,75\n2,1500,110,80,65\n", "dt": 0.5, "outputs": ["W_c"]}"#;
    let v = post("/api/simulate", csv).json();
    assert_eq!(v["t"].as_array().unwrap().len(), 5);
    assert_eq!(v["series"].as_object().unwrap().len(), 1);
}

#[test]
fn closed_loop_mode_answers_with_the_cores_trajectory() {
    let m = get("/api/models").json();
    assert_eq!(m["modes"], serde_json::json!(["open", "closed"]));
    let r = post(
        "/api/simulate",
        r#"{"cycle": "whtc", "mode": "closed", "dt": 1.0}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    assert_eq!(v["mode"], "closed");
    let t: Vec<f64> = serde_json::from_value(v["t"].clone()).unwrap();
    assert_eq!(t.len(), 1801, "0..1800 s at 1 s");
    // the same run as `mvem closed-loop --cycle whtc`, every 100th 10 ms sample, to the bit
    let run = drive::run_cycle(
        &AnyModel::Eight(Engine8::published()),
        CycleSource::Whtc,
        Scheme::Baseline(BaselineTuning::default()),
        None,
    )
    .unwrap();
    let every100 = |n: &str| -> Vec<f64> {
        run.traj
            .get(n)
            .unwrap()
            .iter()
            .step_by(100)
            .copied()
            .collect()
    };
    assert_eq!(t, every100("t"));
    for (key, n) in [
        ("series", "M_e"),
        ("series", "M_ref"),
        ("series", "lambda_O"),
        ("inputs", "u_vgt"),
    ] {
        let got: Vec<f64> = serde_json::from_value(v[key][n].clone()).unwrap();
        assert_eq!(got, every100(n), "{n}");
    }
    assert_eq!(v["units"]["M_ref"], "Nm");
    assert_eq!(v["passes"], run.violations.is_empty());
    assert_eq!(
        v["cycle_stats"]["torque"]["r2"].as_f64().unwrap(),
        run.stats.torque.r2
    );
    // the second set's engine runs to 3000 rpm: its WHTC is denormalized over that range
    let r = post(
        "/api/simulate",
        r#"{"cycle": "whtc", "mode": "closed", "dt": 1.0, "params": "second"}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let n_e: Vec<f64> = serde_json::from_value(r.json()["inputs"]["n_e"].clone()).unwrap();
    let top = n_e.iter().cloned().fold(f64::MIN, f64::max);
    let published_top = every100("n_e").into_iter().fold(f64::MIN, f64::max);
    assert!(
        published_top <= 2000.0 && top > 2000.0,
        "{published_top} {top}"
    );
}

/// `"tuning"` in closed mode reaches the baseline controllers (a smoke limit of 1.1 lets
/// lambda_O fall to 1.11 on the WHTC, which then fails the cycle's lambda_O >= 1.2 check) and is
/// echoed; a bad field, an unknown key and a tuning in open mode are 400 naming them.
#[test]
fn closed_loop_mode_takes_the_controllers_tuning() {
    let r = post(
        "/api/simulate",
        r#"{"cycle": "whtc", "mode": "closed", "dt": 10.0, "tuning": {"lambda_limit": 1.1}}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    assert_eq!(v["controller_tuning"]["lambda_limit"], 1.1);
    assert_eq!(
        v["controller_tuning"]["torque"],
        serde_json::json!([0.02, 2.0])
    );
    let lambda_min = v["cycle_stats"]["lambda_o_min"].as_f64().unwrap();
    assert!(lambda_min < 1.15, "{lambda_min}");
    assert_eq!(v["passes"], false);
    for (body, want) in [
        (
            r#"{"cycle": "whtc", "mode": "closed", "tuning": {"lambda_limit": 0.8}}"#,
            "lambda_limit = 0.8",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "tuning": {"lamda_limit": 1.1}}"#,
            "lamda_limit",
        ),
        (
            r#"{"cycle": "whtc", "tuning": {"lambda_limit": 1.1}}"#,
            "sets the baseline controllers",
        ),
        // these two once passed the check and then broke the run: answered 500
        (
            r#"{"cycle": "whtc", "mode": "closed", "tuning": {"lambda_limit": 9.9}}"#,
            "lambda_limit = 9.9: must be in [1, 5]",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "tuning": {"torque": [1e308, 2]}}"#,
            "torque[1] = 1e308: must be in [0, 1e6]",
        ),
    ] {
        let r = post("/api/simulate", body);
        let text = String::from_utf8_lossy(&r.body).to_string();
        assert_eq!(r.status, 400, "{text}");
        assert!(text.contains(want), "{text}");
    }
}

/// `POST /api/margins`: the object of `mvem margins --json` (the library's report) to the bit,
/// with the default tuning and a given one (both x_egr -> u_vgt gains doubled: that loop's gain
/// margin halves); a bad tuning, an unknown field and a missing point are 400s naming them.
#[test]
fn margins_equal_the_library() {
    use mvem::control::margins::{baseline_loops, margins_at, margins_report_json};
    let d = Drive::new(1500.0, 110.0, 50.0, 60.0);
    let r = post(
        "/api/margins",
        r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 50, "u_vgt": 60}}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let t = BaselineTuning::default();
    let (_, a) = margins_at(
        &Engine8::published(),
        &d,
        &baseline_loops(&t, &d, &Default::default()),
        t.ts,
    )
    .unwrap();
    assert_eq!(r.json(), margins_report_json(&d, 8, &a));
    let doubled = post(
        "/api/margins",
        r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 50, "u_vgt": 60},
            "tuning": {"x_egr_vgt": [300, 1600]}, "model": 8}"#,
    )
    .json();
    let gm = |v: &serde_json::Value| v["loops"][1]["alone"]["gain_margin"].as_f64().unwrap();
    assert!((gm(&doubled) / gm(&r.json()) - 0.5).abs() < 1e-8);
    let point = r#""point": {"n_e": 1500, "u_delta": 110, "u_egr": 50, "u_vgt": 60}"#;
    for (body, name) in [
        (
            format!(r#"{{{point}, "tuning": {{"x_egr_vgt": [-1, 800]}}}}"#),
            "x_egr_vgt",
        ),
        (format!(r#"{{{point}, "tunning": {{}}}}"#), "tunning"),
        (r#"{"model": 8}"#.to_string(), "point"),
    ] {
        assert_400_naming(&post("/api/margins", &body), name, &body);
    }
}

/// `"margins": S` in closed mode: the loop margins along the run are the library's
/// (`control::along` on the core's run of the same cycle, as `mvem closed-loop --margins S`):
/// summary and samples equal to the bit, here the WHTC every 30 s (60 samples, the one at
/// 1050.01 s unstable with the default tuning: docs/control.md); a demand's margins too. In
/// open mode, below the controller sample and with too many samples, `margins` is a 400
/// naming it.
#[test]
fn closed_loop_mode_gives_the_loop_margins_along_the_run() {
    use mvem::control::along;
    let r = post(
        "/api/simulate",
        r#"{"cycle": "whtc", "mode": "closed", "dt": 10.0, "margins": 30}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let v = r.json();
    let model = AnyModel::Eight(Engine8::published());
    let tuning = BaselineTuning::default();
    let run = drive::run_cycle(&model, CycleSource::Whtc, Scheme::Baseline(tuning), None).unwrap();
    let points = along::along_trajectory(&model, &run.traj, &tuning, 30.0).unwrap();
    let s = along::summarize(&points);
    assert_eq!(v["margins"]["summary"], along::summary_json(30.0, &s));
    assert_eq!(v["margins"]["samples"], along::points_json(&points));
    // the numbers themselves, so that two empty answers could not agree: 0.01 s, 30.01 s, ...
    // 1770.01 s
    assert_eq!(s.points, 60);
    assert_eq!(v["margins"]["summary"]["points"], 60);
    assert_eq!(
        v["margins"]["summary"]["analysed"].as_u64(),
        Some(s.analysed as u64)
    );
    assert!(s.analysed >= 50, "{s:?}");
    let unstable: Vec<f64> =
        serde_json::from_value(v["margins"]["summary"]["unstable_t"].clone()).unwrap();
    assert_eq!(unstable, s.unstable_t);
    // with the default gain schedules one of these samples is unstable (1050.01 s in this
    // run; without them 690.01 s and others)
    assert!(!unstable.is_empty(), "{unstable:?}");
    // one analysed sample's gain margin (the first loop, the other closed) to the bit
    let (k, a) = points
        .iter()
        .enumerate()
        .find_map(|(k, p)| match &p.outcome {
            along::Outcome::Analysed(a) if a.others_closed[0].gain_margin.is_some() => Some((k, a)),
            _ => None,
        })
        .expect("an analysed sample with a gain margin");
    let sample = &v["margins"]["samples"][k];
    assert_eq!(sample["t"].as_f64(), Some(points[k].t));
    assert_eq!(
        sample["loops"][0]["others_closed"]["gain_margin"].as_f64(),
        a.others_closed[0].gain_margin
    );
    // without "margins", none
    let plain = post(
        "/api/simulate",
        r#"{"cycle": "whtc", "mode": "closed", "dt": 100.0}"#,
    );
    assert!(plain.json().get("margins").is_none());
    // a speed/torque demand every 0.5 s: 0.01, 0.51, ... 5.51 s
    let csv = "t,n_e,M_ref\n0,1200,300\n2,1200,300\n2.5,1400,900\n6,1400,900\n";
    let body = serde_json::json!({"csv": csv, "mode": "closed", "dt": 0.5, "margins": 0.5});
    let r = post("/api/simulate", &body.to_string());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let (_, run) = closed_csv(csv);
    let points = along::along_trajectory(&model, &run.traj, &tuning, 0.5).unwrap();
    assert_eq!(points.len(), 12);
    assert_eq!(r.json()["margins"]["samples"], along::points_json(&points));
    // 400s naming margins: open mode, below the controller sample, not a number, too many
    // samples (the WHTC's 1800 s every 1 s; at most MAX_MARGINS_SAMPLES) and a demand's
    for (body, want) in [
        (
            r#"{"cycle": "whtc", "margins": 10}"#.to_string(),
            "margins: analyses the baseline controllers' loops of mode \"closed\"",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "margins": 0.001}"#.to_string(),
            "margins 0.001: the seconds between analysed samples must be at least the controller sample 0.01 s",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "margins": 0}"#.to_string(),
            "margins 0: ",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "margins": -5}"#.to_string(),
            "margins -5: ",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "margins": "often"}"#.to_string(),
            "body: margins: invalid type: string \"often\", expected f64",
        ),
        (
            r#"{"cycle": "whtc", "mode": "closed", "margins": 1}"#.to_string(),
            "margins 1: the 1800 s of the cycle every 1 s are 1800 samples; the server analyses at most 1000 (here margins >= 1.8 s",
        ),
        (
            serde_json::json!({"csv": "t,n_e,M_ref\n0,1200,300\n20,1200,300\n", "mode": "closed", "margins": 0.01})
                .to_string(),
            "margins 0.01: the 20 s of the cycle every 0.01 s are 2000 samples",
        ),
    ] {
        let r = post("/api/simulate", &body);
        assert_400_naming(&r, "margins", &body);
        let e = r.json()["error"].as_str().unwrap_or_default().to_string();
        assert!(e.contains(want), "{body}: {e}");
    }
}

/// An open-loop run of an uploaded file is the run of the same rows as a server cycle: the
/// WHTC's text sent as `"csv"` answers the same series as `"cycle": "whtc"`, to the bit.
#[test]
fn open_loop_csv_equals_the_same_cycle_by_name() {
    let by_name = post("/api/simulate", r#"{"cycle": "whtc", "dt": 2.0}"#);
    assert_eq!(by_name.status, 200);
    let body = serde_json::json!({"csv": WHTC, "dt": 2.0});
    let by_text = post("/api/simulate", &body.to_string());
    assert_eq!(
        by_text.status,
        200,
        "{}",
        String::from_utf8_lossy(&by_text.body)
    );
    let (a, b) = (by_name.json(), by_text.json());
    assert_eq!(b["source"], "csv");
    for key in ["t", "series", "inputs", "stats"] {
        assert_eq!(a[key], b[key], "{key}");
    }
    assert_eq!(a["t"].as_array().unwrap().len(), 901);
    // the WHTC stays inside the published set's input ranges
    assert_eq!(a["warnings"], serde_json::json!([]));
}

/// Inputs outside the parameter set's saturation ranges run clamped, and the answer says so
/// (one warning per channel naming the time the input, linear between the rows, crosses the
/// range, how many input rows lie outside it and the values of the whole channel), as
/// `mvem simulate` warns on stderr.
#[test]
fn open_loop_csv_outside_the_input_ranges_warns() {
    let csv = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n\
               0,1200,100,50,50\n2,2600,100,50,50\n4,1200,300,50,50\n";
    let body = serde_json::json!({"csv": csv, "dt": 1.0});
    let r = post("/api/simulate", &body.to_string());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let w: Vec<String> = serde_json::from_value(r.json()["warnings"].clone()).unwrap();
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        // 1200 rpm at 0 s, 2600 at 2 s: 2000 rpm at 8/7 s
        w[0].starts_with(
            "n_e_rpm is outside its range [500, 2000] at 1 of 3 input rows (1 above, up to \
             2600), first at t = 1.142857 s"
        ) && w[0].contains("s (the whole channel runs from 1200 to 2600)"),
        "{w:?}"
    );
    assert!(
        w[1].starts_with(
            "u_delta_mg is outside its range [1, 250] at 1 of 3 input rows (1 above, up to 300), \
             first at t = 3.5 s (the whole channel runs from 100 to 300)"
        ),
        "{w:?}"
    );
    // the inputs as commanded and as the model applied them (clamped into the ranges)
    let j = r.json();
    assert_eq!(j["t"], serde_json::json!([0.0, 1.0, 2.0, 3.0, 4.0]));
    assert_eq!(
        j["inputs"]["n_e"],
        serde_json::json!([1200.0, 1900.0, 2600.0, 1900.0, 1200.0])
    );
    assert_eq!(
        j["inputs_applied"]["n_e"],
        serde_json::json!([1200.0, 1900.0, 2000.0, 1900.0, 1200.0])
    );
    assert_eq!(j["inputs"]["u_delta"][4], 300.0);
    assert_eq!(j["inputs_applied"]["u_delta"][4], 250.0);
    assert_eq!(j["inputs_applied"]["u_vgt"], j["inputs"]["u_vgt"]);
}

/// A cycle longer than 50 000 samples at the asked `dt` (3 h at 0.2 s: 54 001) is a 400 naming
/// `dt`; with `"fit_dt": true` (what the explorer sends, whose `dt` the user cannot set) it runs
/// at the smallest multiple of 10 ms that fits (0.22 s: 49 092 samples) and says so. Before,
/// the explorer could not run such a file at all and showed "dt 0.2: must be > 0 and give at
/// most 50000 samples", a dt the page has no field for.
#[test]
fn a_long_cycle_is_sampled_coarser_with_fit_dt() {
    let csv = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n\
               0,1200,100,50,50\n5400,1600,150,40,60\n10800,1000,60,50,50\n";
    let r = post(
        "/api/simulate",
        &serde_json::json!({"csv": csv, "dt": 0.2}).to_string(),
    );
    assert_400_naming(
        &r,
        "dt 0.2: must be > 0 and give at most 50000 samples from 0 to 10800 s",
        "a 3 h cycle at 0.2 s",
    );
    let body = serde_json::json!({"csv": csv, "dt": 0.2, "fit_dt": true, "outputs": ["p_im"]});
    let r = post("/api/simulate", &body.to_string());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let j = r.json();
    let t: Vec<f64> = serde_json::from_value(j["t"].clone()).unwrap();
    assert_eq!(t.len(), 49_092);
    assert!(
        (t[1] - 0.22).abs() < 1e-12 && t[t.len() - 1] <= 10800.0,
        "{:?}",
        &t[..2]
    );
    assert_eq!(
        j["warnings"],
        serde_json::json!(["sampled every 0.22 s: dt 0.2 s would give more than 50000 samples"])
    );
    // a cycle that fits is sampled at dt, without a note
    let short =
        "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1200,100,50,50\n10,1200,100,50,50\n";
    let body = serde_json::json!({"csv": short, "dt": 0.2, "fit_dt": true, "outputs": ["p_im"]});
    let j = post("/api/simulate", &body.to_string()).json();
    assert_eq!(j["t"].as_array().unwrap().len(), 51);
    assert_eq!(j["warnings"], serde_json::json!([]));
}

/// The API's closed-loop run of the cycle file `csv` (every 0.5 s) and the core's run of the
/// same text (`parse_cycle_file`, `run_cycle` with the default tuning, as `mvem closed-loop`).
fn closed_csv(csv: &str) -> (serde_json::Value, drive::CycleRun) {
    let body = serde_json::json!({"csv": csv, "mode": "closed", "dt": 0.5});
    let r = post("/api/simulate", &body.to_string());
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let source = mvem::io::csv_demand::parse_cycle_file(csv, std::path::Path::new("csv")).unwrap();
    let run = drive::run_cycle(
        &AnyModel::Eight(Engine8::published()),
        source,
        Scheme::Baseline(BaselineTuning::default()),
        None,
    )
    .unwrap();
    (r.json(), run)
}

/// Mode `"closed"` with `"csv"`: a speed/torque demand (t, n_e, M_ref), the core's run of it
/// to the bit (as `mvem closed-loop --cycle FILE.csv`); a demand the engine cannot follow, one
/// longer than the limit and a malformed one are 400 naming the problem.
#[test]
fn closed_loop_mode_runs_a_speed_torque_demand() {
    let csv = "t,n_e,M_ref\n0,1200,300\n2,1200,300\n2.5,1400,900\n6,1400,900\n";
    let (v, run) = closed_csv(csv);
    assert_eq!(
        (v["mode"].as_str(), v["source"].as_str()),
        (Some("closed"), Some("csv"))
    );
    let every50 = |n: &str| -> Vec<f64> {
        run.traj
            .get(n)
            .unwrap()
            .iter()
            .step_by(50)
            .copied()
            .collect()
    };
    let t: Vec<f64> = serde_json::from_value(v["t"].clone()).unwrap();
    assert_eq!(t, every50("t"));
    assert_eq!(t.len(), 13, "0..6 s every 0.5 s");
    for (key, n) in [
        ("series", "M_e"),
        ("series", "M_ref"),
        ("inputs", "u_delta"),
    ] {
        let got: Vec<f64> = serde_json::from_value(v[key][n].clone()).unwrap();
        assert_eq!(got, every50(n), "{n}");
    }
    assert_eq!(
        v["cycle_stats"]["work_error"].as_f64().unwrap(),
        run.stats.work_error
    );
    for (csv, want) in [
        // 5000 Nm is above the published engine's full load
        ("t,n_e,M_ref\n0,1200,500\n5,1200,5000\n", "cannot follow"),
        // beyond the engine's speed range (the published set: 500-2000 rpm)
        ("t,n_e,M_ref\n0,1200,300\n5,2600,300\n", "n_e"),
        ("t,n_e,M_ref\n0,1200,300\n4000,1200,300\n", "at most 3600 s"),
        (
            "t,n_e,M_ref\n0,1200,300\n1,fast,300\n",
            "line 3, column n_e",
        ),
        ("t,n_e\n0,1200\n1,1200\n", "missing column(s) M_ref"),
        // a normalized cycle's own checks
        (
            "Time,Speed,Torque\n0,0,0\n5,50,130\n",
            "torque 130 % is outside [0, 100] %",
        ),
    ] {
        let body = serde_json::json!({"csv": csv, "mode": "closed"});
        let r = post("/api/simulate", &body.to_string());
        let text = String::from_utf8_lossy(&r.body).to_string();
        assert_eq!(r.status, 400, "{csv}: {text}");
        assert!(text.contains(want), "{csv}: {text}");
    }
}

/// Mode `"closed"` with `"csv"` of a normalized cycle (UN GTR No. 4's form: Time, Speed [%],
/// Torque [%], "m" motoring): the core's run of it to the bit, as `mvem closed-loop --cycle FILE`.
#[test]
fn closed_loop_mode_runs_a_normalized_cycle() {
    let csv = "Time\tSpeed\tTorque\ns\t%\t%\n0\t0\t0\n2\t0\t0\n4\t40\t60\n6\t40\tm\n";
    let (v, run) = closed_csv(csv);
    assert!(matches!(
        mvem::io::csv_demand::parse_cycle_file(csv, std::path::Path::new("csv")),
        Ok(CycleSource::Normalized(_))
    ));
    for n in ["M_ref", "M_e"] {
        let want: Vec<f64> = run
            .traj
            .get(n)
            .unwrap()
            .iter()
            .step_by(50)
            .copied()
            .collect();
        let got: Vec<f64> = serde_json::from_value(v["series"][n].clone()).unwrap();
        assert_eq!(got, want, "{n}");
    }
    assert_eq!(
        v["cycle_stats"]["work_error"].as_f64().unwrap(),
        run.stats.work_error
    );
}

#[test]
fn saturated_server_answers_503_with_retry_after() {
    let mut c = Config::local(0);
    c.cycles = vec![("whtc".into(), WHTC)];
    c.limits.workers = 1;
    c.limits.max_queue = 0;
    let s = mvem_serve::start(c).unwrap();
    let addr = s.addr;
    // one long computation (the closed-loop WHTC: about 0.4 s on a quiet machine, against the
    // milliseconds of a steady request) holds the only worker; a request meanwhile is refused,
    // not queued. The server's own count of admitted requests (/api/health "busy") says when
    // the long one holds the worker, so a loaded machine cannot reorder the two; should the
    // long one end between that poll and the steady request (a 200), the attempt is repeated.
    let busy = || {
        client::get(addr, "/api/health").unwrap().json()["busy"]
            .as_u64()
            .unwrap()
    };
    let mut saw_503 = None;
    for _attempt in 0..5 {
        let long = std::thread::spawn(move || {
            client::post(
                addr,
                "/api/simulate",
                br#"{"cycle": "whtc", "mode": "closed", "dt": 1.0}"#,
            )
            .unwrap()
        });
        while busy() == 0 && !long.is_finished() {
            std::thread::sleep(Duration::from_millis(1));
        }
        let r = client::get(addr, &format!("/api/steady?{POINT}")).unwrap();
        assert_eq!(long.join().unwrap().status, 200);
        if r.status == 503 {
            saw_503 = Some(r);
            break;
        }
    }
    let r = saw_503.expect("a 503 while the only worker is busy");
    assert_eq!(r.header("retry-after"), Some("1"));
    assert!(r.json()["error"].as_str().unwrap().contains("busy"));
    assert_eq!(
        client::get(addr, &format!("/api/steady?{POINT}"))
            .unwrap()
            .status,
        200
    );
    s.stop().unwrap();
}

/// A computation that outlives its request's time limit is cancelled (`api::Work`'s token) and
/// frees its worker: the loop margins of the WHTC at the finest spacing the server takes
/// (1000 samples, about 40 s of CPU: 20 s on 2 cores) under a 2 s limit answer 503, and the
/// only worker is free again within a few seconds (a steady state gets it; its own 2 s limit
/// makes each try that still waits a 503).
#[test]
fn a_computation_past_the_time_limit_is_cancelled_and_frees_its_worker() {
    let mut c = Config::local(0);
    c.cycles = vec![("whtc".into(), WHTC)];
    c.limits.workers = 1;
    c.limits.request_timeout = Duration::from_secs(2);
    let s = mvem_serve::start(c).unwrap();
    let t0 = std::time::Instant::now();
    let r = client::post(
        s.addr,
        "/api/simulate",
        br#"{"cycle": "whtc", "mode": "closed", "dt": 10.0, "margins": 1.8}"#,
    )
    .unwrap();
    assert_eq!(r.status, 503, "{}", String::from_utf8_lossy(&r.body));
    let e = r.json()["error"].as_str().unwrap_or_default().to_string();
    assert!(e.contains("took longer than 2 s"), "{e}");
    // the cancelled analysis's last samples may wait for rayon's workers, which the other tests
    // of this file share: a few tries
    let freed = (0..4).find_map(|_| {
        let r = client::get(s.addr, &format!("/api/steady?{POINT}")).unwrap();
        (r.status == 200).then(|| t0.elapsed())
    });
    assert!(
        freed.is_some(),
        "the worker still busy 10 s after the request's start"
    );
    s.stop().unwrap();
}

#[test]
fn load_400_requests_from_32_threads_no_5xx_no_drop() {
    let targets: Vec<String> = ["8", "10", "12"]
        .iter()
        .map(|m| format!("/api/steady?{POINT}&model={m}"))
        .chain([
            "/api/health".to_string(),
            "/api/steady?n_e=oops".to_string(),
        ])
        .collect();
    let r = client::load(server(), &targets, 400, 32);
    assert_eq!(r.server_errors, 0);
    assert_eq!(r.dropped, 0);
    assert_eq!(r.client_errors, 80, "the bad query is 1 in 5");
    assert_eq!(r.ok, 320);
    assert_eq!(get("/api/health").status, 200);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// Any query string (arbitrary bytes, percent-encoded or not) gets 200, 400 or 422, never a
    /// 5xx or a dropped connection.
    #[test]
    fn query_parsing_never_fails_the_server(
        raw in proptest::collection::vec(any::<u8>(), 0..80),
        keys in proptest::collection::vec(
            prop_oneof![Just("n_e"), Just("u_delta"), Just("u_egr"), Just("u_vgt"), Just("model"),
                        Just("params"), Just("pade"), Just("outputs"), Just("x")], 0..7),
        vals in proptest::collection::vec(
            prop_oneof![any::<f64>().prop_map(|v| v.to_string()), Just("NaN".to_string()),
                        Just("1e400".to_string()), Just("%ZZ".to_string()), Just("%00".to_string()),
                        "[ -~]{0,12}".prop_map(|s| s)], 0..7),
        route in prop_oneof![Just("steady"), Just("linearize")],
    ) {
        let mut q: String = keys.iter().zip(vals.iter()).map(|(k, v)| {
            let enc: String = v.bytes().map(|b| match b {
                b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'.' | b'-' | b'%' | b',' => (b as char).to_string(),
                _ => format!("%{b:02X}"),
            }).collect();
            format!("{k}={enc}")
        }).collect::<Vec<_>>().join("&");
        // raw bytes, escaped so that the request line stays one line
        q.push('&');
        q.extend(raw.iter().map(|b| format!("%{b:02X}")));
        let r = client::get(server(), &format!("/api/{route}?{q}")).expect("an answer");
        prop_assert!(matches!(r.status, 200 | 400 | 422), "status {} for {q}", r.status);
        prop_assert!(r.json()["error"].is_string() || r.status == 200);
    }
}

/// A step to a command outside its range: the warning `mvem step` prints on stderr (the
/// authors' saturation clamps it), and the input as applied beside the one asked for.
#[test]
fn a_step_outside_the_input_range_warns_and_gives_the_applied_input() {
    let r = post(
        "/api/step",
        r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 5, "horizon": 3}"#,
    );
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let j = r.json();
    let w: Vec<&str> = j["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        w.iter()
            .any(|m| m.contains("u_vgt_pct = 5 is outside [20, 100]")
                && m.contains("clamps it to 20")),
        "{w:?}"
    );
    assert_eq!(j["to"], 5.0);
    assert_eq!(j["to_applied"], 20.0);
    assert_eq!(j["from_applied"], 75.0);
    let (u, ua) = (
        j["u"].as_array().unwrap(),
        j["u_applied"].as_array().unwrap(),
    );
    assert_eq!(u.len(), ua.len());
    assert_eq!(u.last().unwrap(), 5.0);
    assert_eq!(ua.last().unwrap(), 20.0);
    assert_eq!(ua[0], 75.0);
    // the point before the step outside its range too (n_e above the published 2000 rpm)
    let r = post(
        "/api/step",
        r#"{"point": {"n_e": 2500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 65, "horizon": 3}"#,
    );
    let j = r.json();
    assert!(
        j["warnings"].as_array().unwrap().iter().any(|m| m
            .as_str()
            .unwrap()
            .contains("n_e_rpm = 2500 is outside [500, 2000]")),
        "{j}"
    );
    // inside the ranges: no warning, the applied input the asked one
    let j = post(
        "/api/step",
        r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 65, "horizon": 3}"#,
    )
    .json();
    assert_eq!(j["warnings"], serde_json::json!([]));
    assert_eq!(j["u"], j["u_applied"]);
}

/// The QA findings on the API's edges: each a 400 (405, 413) that names the problem in JSON.
#[test]
fn edge_requests_are_named_in_json() {
    // a horizon before the default step time names the horizon (the page has no t_step)
    assert_400_naming(
        &post(
            "/api/step",
            r#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75}, "input": "u_vgt", "target": 65, "horizon": 0.5}"#,
        ),
        "horizon 0.5: must be after the step at t_step = 1 s",
        "horizon before the step",
    );
    // Bode frequencies over eight decades at most: 1e-4 to 1e4 Hz
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&bode=1e-300:1e300:200")),
        "bode \"1e-300:1e300:200\": the frequencies must lie in [0.0001, 10000] Hz",
        "extreme Bode range",
    );
    assert_eq!(
        get(&format!("/api/linearize?{POINT}&bode=0.0001:10000:50")).status,
        200
    );
    // outputs of a linearization: each once, at most 32
    let j = get(&format!("/api/linearize?{POINT}&outputs=W_c,p_im,W_c")).json();
    assert_eq!(j["output_names"], serde_json::json!(["W_c", "p_im"]));
    let many = (0..40)
        .map(|k| format!("x{k}"))
        .collect::<Vec<_>>()
        .join(",");
    assert_400_naming(
        &get(&format!("/api/linearize?{POINT}&outputs={many}")),
        "outputs: 40 names, at most 32",
        "40 outputs",
    );
    // another method: 405 with a JSON error
    for (method, path) in [
        ("GET", "/api/step"),
        ("POST", "/api/steady"),
        ("PUT", "/api/map"),
    ] {
        let r =
            client::request(server(), method, path, Some(b"{}"), Duration::from_secs(10)).unwrap();
        assert_eq!(r.status, 405, "{method} {path}");
        let e = r.json()["error"].as_str().unwrap_or_default().to_string();
        assert!(e.contains("not allowed"), "{method} {path}: {e:?}");
    }
    // a binary file: named so, its bytes not echoed
    let r = post(
        "/api/simulate",
        &serde_json::json!({"csv": "time_s,n_e\u{0}\u{1}\u{FFFD}\u{FFFD} x\n0,1\n"}).to_string(),
    );
    assert_400_naming(&r, "csv, line 1, character 11: not a text table", "binary");
    let e = r.json()["error"].as_str().unwrap().to_string();
    assert!(!e.contains('\u{0}') && !e.contains('\u{FFFD}'), "{e:?}");
    // inputs whose change overflows: the column named, not a 422 of a NaN input
    assert_400_naming(
        &post(
            "/api/simulate",
            r#"{"csv": "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n0,1500,110,80,-1e308\n5,1500,110,80,1e308\n"}"#,
        ),
        "csv, column u_vgt_pct: from -1e308 at t = 0 s to 1e308 at t = 5 s",
        "overflowing change",
    );
    // 413 names the limit
    let big = format!(r#"{{"csv": "{}"}}"#, "x".repeat(5 << 20));
    let r = post("/api/simulate", &big);
    assert_eq!(r.status, 413);
    assert!(
        r.json()["error"]
            .as_str()
            .unwrap()
            .contains("too large (the limit is 4 MiB)"),
        "{:?}",
        r.json()
    );
}
