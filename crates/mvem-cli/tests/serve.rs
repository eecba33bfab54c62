//! `mvem serve`: the API answers with the CLI's numbers to the last bit, and the server process
//! starts, answers and shuts down on a signal.

mod common;

use common::{json_of, mvem, stderr};
use mvem_serve::client;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// Points of the comparison (n_e, u_delta, u_egr, u_vgt, model): the VGT-step point, a low-load
/// point with the EGR valve closed, a high-load one, one outside the input ranges (clamped by
/// the authors' saturation), in the 8-, 10- and 12-state models.
const POINTS: [(f64, f64, f64, f64, &str); 6] = [
    (1500.0, 110.0, 80.0, 75.0, "8"),
    (1200.0, 50.0, 0.0, 25.0, "8"),
    (1800.0, 200.0, 40.0, 60.0, "10"),
    (1500.0, 110.0, 80.0, 30.0, "12"),
    (1000.0, 80.0, 60.0, 45.0, "12"),
    (2200.0, 110.0, 80.0, 75.0, "10"),
];

fn cli_json(args: &[&str]) -> Value {
    let dir = tempfile::tempdir().unwrap();
    json_of(&mvem(dir.path(), args))
}

/// Every number of `a` equals the one of `b` bit for bit (and the structure is the same).
fn assert_bitwise(a: &Value, b: &Value, path: &str) {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert_eq!(x.to_bits(), y.to_bits(), "{path}: {x:e} vs {y:e}");
        }
        (Value::Object(x), Value::Object(y)) => {
            let kx: Vec<_> = x.keys().collect();
            let ky: Vec<_> = y.keys().collect();
            assert_eq!(kx, ky, "{path}: keys");
            for (k, v) in x {
                assert_bitwise(v, &y[k], &format!("{path}.{k}"));
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}: length");
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                assert_bitwise(u, v, &format!("{path}[{i}]"));
            }
        }
        _ => assert_eq!(a, b, "{path}"),
    }
}

#[test]
fn api_steady_and_linearize_equal_the_cli_to_the_last_bit() {
    let server = mvem_serve::start(mvem_serve::Config::local(0)).unwrap();
    for (n_e, u_delta, u_egr, u_vgt, model) in POINTS {
        let (a, b, c, d) = (
            n_e.to_string(),
            u_delta.to_string(),
            u_egr.to_string(),
            u_vgt.to_string(),
        );
        let point = [
            "--n-e",
            &a,
            "--u-delta",
            &b,
            "--u-egr",
            &c,
            "--u-vgt",
            &d,
            "--model",
            model,
        ];
        let q = format!("n_e={a}&u_delta={b}&u_egr={c}&u_vgt={d}&model={model}");
        let cli = cli_json(&[&["steady", "--json"][..], &point[..]].concat());
        let r = client::get(server.addr, &format!("/api/steady?{q}")).unwrap();
        assert_eq!(r.status, 200, "{q}: {}", String::from_utf8_lossy(&r.body));
        let api = r.json();
        assert!(api["p_im"].as_f64().unwrap() > 1e5, "{q}: p_im");
        assert_bitwise(&api, &cli, &format!("steady {q}"));
    }
    // the linearization (matrices, zeros, DC gains), with Pade states and chosen outputs, the
    // sampled model and the frequency response; the command line of each query: the same
    // names as options (n_e -> --n-e, ...)
    for q in [
        "n_e=1500&u_delta=110&u_egr=80&u_vgt=75",
        "n_e=1500&u_delta=110&u_egr=40&u_vgt=75&ts=0.025",
        "n_e=1500&u_delta=110&u_egr=50&u_vgt=60&bode=0.01:100:40",
        "n_e=1200&u_delta=200&u_egr=50&u_vgt=40&model=12&pade=2&outputs=W_c,p_im,T_em",
    ] {
        let args: Vec<String> = q
            .split('&')
            .flat_map(|kv| {
                let (k, v) = kv.split_once('=').unwrap();
                [format!("--{}", k.replace('_', "-")), v.to_string()]
            })
            .collect();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let cli = cli_json(&[&["linearize", "--json"][..], &args[..]].concat());
        let r = client::get(server.addr, &format!("/api/linearize?{q}")).unwrap();
        assert_eq!(r.status, 200, "{q}: {}", String::from_utf8_lossy(&r.body));
        assert_bitwise(&r.json(), &cli, &format!("linearize {q}"));
    }
    server.stop().unwrap();
}

#[test]
fn api_step_metrics_equal_the_cli() {
    let server = mvem_serve::start(mvem_serve::Config::local(0)).unwrap();
    let cli = cli_json(&[
        "step",
        "--json",
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
    ]);
    let body = br#"{"point": {"n_e": 1500, "u_delta": 110, "u_egr": 80, "u_vgt": 75},
                    "input": "u_vgt", "target": 65, "horizon": 8}"#;
    let r = client::post(server.addr, "/api/step", body).unwrap();
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let api = r.json();
    assert_bitwise(&api["outputs"], &cli["outputs"], "step outputs");
    // the VGT step at this point is the paper's non-minimum-phase W_c response (Fig. 8)
    assert_eq!(api["outputs"]["W_c"]["non_minimum_phase"], true);
    assert_eq!(api["outputs"]["W_c"]["gain_sign"], "negative");
    let n = api["t"].as_array().unwrap().len();
    assert_eq!(n, 1601, "0..8 s at 5 ms");
    assert_eq!(api["series"]["W_c"].as_array().unwrap().len(), n);
    assert_eq!(api["u"].as_array().unwrap().len(), n);
    server.stop().unwrap();
}

#[test]
fn serve_prints_its_address_answers_and_stops_on_sigint() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mvem"))
        .args(["serve", "--port", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap_or_else(|| panic!("first line {line:?}"));
    assert!(url.starts_with("127.0.0.1:"), "binds loopback: {url}");
    let addr = url.parse().unwrap();
    let h = client::get(addr, "/api/health").unwrap();
    assert_eq!(h.status, 200);
    assert_eq!(h.json()["status"], "ok");
    let page = client::get(addr, "/").unwrap();
    assert_eq!(page.status, 200);
    let html = String::from_utf8_lossy(&page.body);
    assert!(html.contains("name=\"n_e\"") && html.contains("data-action=\"step\""));
    #[cfg(unix)]
    {
        // SAFETY: signalling our own child process by its id
        let rc = unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
        assert_eq!(rc, 0);
        let status = child.wait().unwrap();
        assert!(status.success(), "graceful exit on Ctrl-C: {status:?}");
    }
    #[cfg(not(unix))]
    {
        let _ = child.kill();
    }
}

#[test]
fn serve_refuses_a_bad_parameter_file_and_a_busy_port() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.toml"), "this is = not [valid").unwrap();
    let o = mvem(
        dir.path(),
        &["serve", "--port", "0", "--params", "bad.toml"],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("bad.toml"), "{}", stderr(&o));
    let server = mvem_serve::start(mvem_serve::Config::local(0)).unwrap();
    let port = server.addr.port().to_string();
    let o = mvem(dir.path(), &["serve", "--port", &port]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("cannot listen"), "{}", stderr(&o));
}
