//! End-to-end tests of the `mvem` binary: outputs checked against `tests/reference/` (an
//! independent implementation of the authors' model), exit codes and messages of bad input,
//! and that failed runs leave no output file.

mod common;

use common::{col, files, json_of, mvem, read_csv, reference, stderr, stdout};
use mvem::model::{Signals, STATE_NAMES_8};
use std::path::PathBuf;

const HEADER: &str = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct";

#[test]
fn simulate_scenario_matches_reference() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &[
            "simulate",
            "--scenario",
            "vgt-step-nmp",
            "--out",
            "out.csv",
            "--plot",
            "out.svg",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    for word in ["wall time", "steps", "RHS evaluations", "801 samples"] {
        assert!(err.contains(word), "summary lacks `{word}`: {err}");
    }
    let (h, rows) = read_csv(&d.path().join("out.csv"));
    // columns: t, the 8 states, every signal
    let mut want = vec!["t".to_string()];
    want.extend(STATE_NAMES_8.iter().map(|s| s.to_string()));
    want.extend(Signals::NAMES.iter().map(|s| s.to_string()));
    assert_eq!(h, want);
    assert_eq!(rows.len(), 801, "0..8 s every 10 ms");
    let (rh, rrows) = read_csv(&reference("step_vgt_75_to_65.csv"));
    assert_eq!(rrows.len(), rows.len());
    // W_c at the bottom of the non-minimum-phase dip, t = 1.21 s (row 121)
    let i = 121;
    assert!((rows[i][0] - 1.21).abs() < 1e-12);
    let (got, want) = (rows[i][col(&h, "W_c")], rrows[i][col(&rh, "W_c")]);
    assert!(
        ((got - want) / want).abs() < 1e-4,
        "W_c(1.21) = {got}, reference {want}"
    );
    // and every sample of the main signals to 1e-4 relative
    for name in ["p_im", "p_em", "W_c", "n_t", "lambda_O"] {
        let (a, b) = (col(&h, name), col(&rh, name));
        for (r, rr) in rows.iter().zip(&rrows) {
            assert!(
                ((r[a] - rr[b]) / rr[b]).abs() < 1e-4,
                "{name} at t = {}: {} vs {}",
                r[0],
                r[a],
                rr[b]
            );
        }
    }
    let svg = std::fs::read_to_string(d.path().join("out.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("W_c"));
    assert_eq!(files(d.path()), ["out.csv", "out.svg"]);
}

#[test]
fn simulate_csv_with_png_plot_and_initial_state() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("in.csv"),
        format!("{HEADER}\n0,1500,110,80,30\n0.5,1500,110,80,30\n0.5,1500,110,80,25\n2,1500,110,80,25\n"),
    )
    .unwrap();
    // the steady state at u_vgt 30 % from steady --json, used as the initial state
    let o = mvem(
        d.path(),
        &[
            "steady",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--u-vgt",
            "30",
            "--json",
        ],
    );
    let v = json_of(&o);
    let state: serde_json::Map<String, serde_json::Value> = STATE_NAMES_8
        .iter()
        .map(|n| (n.to_string(), v[*n].clone()))
        .collect();
    std::fs::write(
        d.path().join("x0.json"),
        serde_json::to_string(&state).unwrap(),
    )
    .unwrap();
    let o = mvem(
        d.path(),
        &[
            "simulate",
            "--inputs",
            "in.csv",
            "--out",
            "out.csv",
            "--plot",
            "fig.png",
            "--initial-state",
            "x0.json",
            "--dt",
            "0.1",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let (h, rows) = read_csv(&d.path().join("out.csv"));
    assert_eq!(
        rows.len(),
        21,
        "0..2 s every 0.1 s (end time = last input row)"
    );
    assert_eq!(rows[20][0], 2.0);
    let p = col(&h, "p_im");
    assert!((rows[0][p] - v["p_im"].as_f64().unwrap()).abs() < 1e-9 * rows[0][p]);
    // the step at 0.5 s reaches the VGT position after the delay
    let u = col(&h, "u_vgt_actual");
    assert_eq!(rows[0][u], 30.0);
    assert!(rows[20][u] < 25.1);
    let png = std::fs::read(d.path().join("fig.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    // an initial state with a missing or unknown state is an input error
    std::fs::write(d.path().join("bad.json"), r#"{"p_im": 1.5e5}"#).unwrap();
    let o = mvem(
        d.path(),
        &[
            "simulate",
            "--inputs",
            "in.csv",
            "--out",
            "o2.csv",
            "--initial-state",
            "bad.json",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("bad.json: field p_em: missing state"),
        "{}",
        stderr(&o)
    );
    assert!(!d.path().join("o2.csv").exists());

    // a state outside the integrator limits is clipped with a warning naming it (the message
    // Python's x0 warns with too: mvem::model::start_clip_warnings)
    let mut high = state.clone();
    high.insert("p_im".into(), serde_json::json!(1e8));
    std::fs::write(
        d.path().join("high.json"),
        serde_json::to_string(&high).unwrap(),
    )
    .unwrap();
    let o = mvem(
        d.path(),
        &[
            "simulate",
            "--inputs",
            "in.csv",
            "--out",
            "o3.csv",
            "--initial-state",
            "high.json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let warning = stderr(&o)
        .lines()
        .find(|l| l.contains("integrator limits"))
        .map(str::to_string);
    assert!(
        warning.as_deref().is_some_and(|w| w.starts_with(
            "warning: high.json: field p_im: 100000000 is outside the integrator limits ["
        ) && w.contains("]: the simulation starts from ")),
        "{}",
        stderr(&o)
    );
}

/// Run `mvem` with `args` twice in `dir`, streaming (`--out streamed.csv`) and writing after a
/// figure (`--out after.csv --plot fig.svg`); assert the same bytes; the CSV's header and rows.
fn streamed_and_after(dir: &std::path::Path, args: &[&str]) -> (Vec<String>, Vec<Vec<f64>>) {
    let run = |extra: &[&str]| {
        let o = mvem(dir, &[args, extra].concat());
        assert!(o.status.success(), "{}", stderr(&o));
    };
    run(&["--out", "streamed.csv"]);
    run(&["--out", "after.csv", "--plot", "fig.svg"]);
    let streamed = std::fs::read(dir.join("streamed.csv")).unwrap();
    assert!(streamed == std::fs::read(dir.join("after.csv")).unwrap());
    read_csv(&dir.join("streamed.csv"))
}

/// Without `--plot` the output is written while the simulation runs (blocks of samples to a
/// writer thread); with it, after. Both give the same bytes, also with `--signals` and the
/// dynamometer column M_dynamo (`--tau-me`, a filter carried from block to block), over more
/// samples than one block.
#[test]
fn streamed_output_equals_written_after() {
    let d = tempfile::tempdir().unwrap();
    let base = [
        "simulate",
        "--scenario",
        "vgt-step-nmp",
        "--t-end",
        "3",
        "--dt",
        "0.001",
        "--tau-me",
        "0.4",
        "--signals",
        "M_dynamo,p_im,M_e,lambda_O",
    ];
    let (h, rows) = streamed_and_after(d.path(), &base);
    assert_eq!(h, ["t", "M_dynamo", "p_im", "M_e", "lambda_O"]);
    assert_eq!(rows.len(), 3001);
    // the lag starts at M_e and follows it
    assert_eq!(rows[0][1], rows[0][3]);
    assert!(rows.iter().any(|r| (r[1] - r[3]).abs() > 1e-3 * r[3].abs()));
}

/// The sensor time constants of a parameter file's [test_cell] section (written by `mvem
/// tune`) give `simulate` the columns the sensors read, streamed or written after alike.
#[test]
fn sensor_columns_from_the_test_cell_section() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(d.path(), &["params", "show"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut text = String::from_utf8(o.stdout).unwrap();
    text.push_str("\n[test_cell]\ntau_p_em = 0.02\ntau_n_t = 0.006\n");
    std::fs::write(d.path().join("p.toml"), text).unwrap();
    let base = [
        "simulate",
        "--scenario",
        "vgt-step-nmp",
        "--t-end",
        "3",
        "--dt",
        "0.001",
        "--params",
        "p.toml",
        "--signals",
        "p_em,p_em_sensor,n_t_sensor",
    ];
    let (h, rows) = streamed_and_after(d.path(), &base);
    assert_eq!(h, ["t", "p_em", "p_em_sensor", "n_t_sensor"]);
    // the sensor starts at the signal and trails it by its time constant
    assert_eq!(rows[0][1], rows[0][2]);
    assert!(rows.iter().any(|r| (r[1] - r[2]).abs() > 1e-3 * r[1].abs()));
    // no p_im sensor in the section, so no column for it
    let o = mvem(
        d.path(),
        &[&base[..9], &["--signals", "p_im_sensor", "--out", "x.csv"]].concat(),
    );
    assert!(!o.status.success() && stderr(&o).contains("p_im_sensor"));
}

#[test]
fn steady_json_matches_reference_row_1() {
    let d = tempfile::tempdir().unwrap();
    let (rh, rrows) = read_csv(&reference("steady_states.csv"));
    let r = &rrows[0];
    let input = |n: &str| r[col(&rh, n)].to_string();
    let o = mvem(
        d.path(),
        &[
            "steady",
            "--n-e",
            &input("n_e_rpm"),
            "--u-delta",
            &input("u_delta_mg"),
            "--u-egr",
            &input("u_egr_pct"),
            "--u-vgt",
            &input("u_vgt_pct"),
            "--json",
        ],
    );
    let v = json_of(&o);
    let obj = v.as_object().unwrap();
    for k in STATE_NAMES_8.iter().chain(Signals::NAMES) {
        assert!(obj[*k].is_number(), "key {k}");
    }
    for k in ["physically_valid", "flags", "eigenvalues", "inputs"] {
        assert!(obj.contains_key(k), "key {k}");
    }
    assert_eq!(obj["physically_valid"], true);
    assert_eq!(obj["inputs"]["u_vgt_pct"], 25.0);
    let eig = obj["eigenvalues"].as_array().unwrap();
    assert_eq!(eig.len(), 5);
    assert!(eig.iter().all(|e| e["re"].as_f64().unwrap() < 0.0));
    // every state and signal of the reference row to 1e-6 relative
    let mut compared = 0;
    for (j, name) in rh.iter().enumerate() {
        if name.ends_with("_rpm") || name.ends_with("_mg") || name.ends_with("_pct") {
            continue;
        }
        let Some(got) = obj.get(name).and_then(|x| x.as_f64()) else {
            continue;
        };
        let want = r[j];
        let err = (got - want).abs() / want.abs().max(1e-12);
        let tol = if want == 0.0 { 1e-12 } else { 1e-6 };
        assert!(
            err < tol || (want == 0.0 && got.abs() < 1e-12),
            "{name}: {got} vs {want}"
        );
        compared += 1;
    }
    assert!(compared >= 30, "compared {compared} values");
}

#[test]
fn steady_invalid_point_warns_and_strict_fails() {
    let d = tempfile::tempdir().unwrap();
    let (rh, rrows) = read_csv(&reference("steady_states.csv"));
    // the reference marks physically_valid False (read as NaN by read_csv: not a number);
    // find it from the raw file instead
    let mut rdr = csv::Reader::from_path(reference("steady_states.csv")).unwrap();
    let hdr = rdr.headers().unwrap().clone();
    let (vi, fi) = (
        hdr.iter().position(|h| h == "physically_valid").unwrap(),
        hdr.iter().position(|h| h == "flags").unwrap(),
    );
    let (k, flags) = rdr
        .records()
        .map(|r| r.unwrap())
        .enumerate()
        .find(|(_, r)| &r[vi] == "False")
        .map(|(k, r)| (k, r[fi].to_string()))
        .expect("an invalid reference point");
    let r = &rrows[k];
    let a = |n: &str| r[col(&rh, n)].to_string();
    let args = [
        "steady",
        "--n-e",
        &a("n_e_rpm"),
        "--u-delta",
        &a("u_delta_mg"),
        "--u-egr",
        &a("u_egr_pct"),
        "--u-vgt",
        &a("u_vgt_pct"),
    ];
    let o = mvem(d.path(), &args);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let err = stderr(&o);
    let first_flag = flags.split(';').next().unwrap().trim().to_string();
    assert!(
        err.contains("not physically valid") && err.contains(&first_flag),
        "{err} (reference flags {flags})"
    );
    let mut strict = args.to_vec();
    strict.push("--strict");
    let o = mvem(d.path(), &strict);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
}

/// Each bad input: exit code 2, the message names the location, and no output file.
#[test]
fn bad_inputs_exit_2_with_location_and_no_output() {
    let d = tempfile::tempdir().unwrap();
    let good_params = mvem::io::params::to_toml(&mvem::params::Params::published());
    assert!(good_params.contains("v_im = 0.022\n"));
    let csv_cases: [(&str, String, &[&str]); 5] = [
        (
            "malformed line",
            format!("{HEADER}\n0,1500,110,80,75\n1,1500,110,80\n"),
            &["line 3", "expected 5 fields, found 4"],
        ),
        (
            "non-monotonic time",
            format!("{HEADER}\n0,1500,110,80,75\n2,1500,110,80,75\n1,1500,110,80,75\n"),
            &["line 4", "column time_s", "not monotonic"],
        ),
        (
            "NaN value",
            format!("{HEADER}\n0,1500,110,80,75\n1,1500,NaN,80,75\n"),
            &["line 3", "column u_delta_mg", "NaN"],
        ),
        (
            "unknown column",
            format!("{HEADER},extra\n0,1500,110,80,75,1\n"),
            &["line 1", "column extra", "unknown column"],
        ),
        (
            "missing column",
            "time_s,n_e_rpm,u_delta_mg,u_egr_pct\n0,1500,110,80\n".to_string(),
            &["column u_vgt_pct", "missing column"],
        ),
    ];
    for (what, text, needles) in csv_cases {
        std::fs::write(d.path().join("in.csv"), text).unwrap();
        let o = mvem(
            d.path(),
            &["simulate", "--inputs", "in.csv", "--out", "out.csv"],
        );
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert!(err.contains("in.csv"), "{what}: {err}");
        for n in needles {
            assert!(err.contains(n), "{what}: `{n}` not in {err}");
        }
        assert_eq!(files(d.path()), ["in.csv"], "{what}: output left behind");
    }

    let param_cases = [
        (
            "negative volume",
            good_params.replace("v_im = 0.022\n", "v_im = -0.022\n"),
            "intake_manifold.v_im = -0.022",
        ),
        (
            "unknown key",
            good_params.replace("v_im = 0.022\n", "v_im = 0.022\nv_imm = 1.0\n"),
            "unknown field `v_imm`",
        ),
        (
            "missing key",
            good_params.replace("v_im = 0.022\n", ""),
            "missing field `v_im`",
        ),
    ];
    for (what, text, needle) in param_cases {
        std::fs::write(d.path().join("p.toml"), text).unwrap();
        let o = mvem(
            d.path(),
            &[
                "simulate",
                "--scenario",
                "vgt-step-nmp",
                "--params",
                "p.toml",
                "--out",
                "out.csv",
            ],
        );
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert!(
            err.contains("p.toml") && err.contains(needle),
            "{what}: {err}"
        );
        assert_eq!(
            files(d.path()),
            ["in.csv", "p.toml"],
            "{what}: output left behind"
        );
    }

    let opt_cases: [(&str, &[&str], &str); 7] = [
        (
            "rtol 0",
            &["--scenario", "vgt-step-nmp", "--rtol", "0"],
            "--rtol 0",
        ),
        (
            "unknown scenario",
            &["--scenario", "vgt-step-sideways"],
            "invalid value 'vgt-step-sideways'",
        ),
        (
            "both sources",
            &["--scenario", "whtc", "--inputs", "in.csv"],
            "cannot be used with",
        ),
        (
            "missing input file",
            &["--inputs", "nope.csv"],
            "error: nope.csv: No such file or directory (os error 2)\n",
        ),
        (
            "end before start",
            &["--scenario", "vgt-step-nmp", "--t-end", "-3"],
            "end time -3 s must be after the first input time 0 s",
        ),
        (
            // QA: ran for minutes before failing; refused at once (the library's MAX_TIME)
            "absurd horizon",
            &[
                "--scenario",
                "vgt-step-nmp",
                "--t-end",
                "1e300",
                "--dt",
                "1e299",
            ],
            "error: end time 1e300 s is beyond the 1e9 s (about 31.7 years)",
        ),
        (
            "bad figure type",
            &["--scenario", "vgt-step-nmp", "--plot", "fig.pdf"],
            "fig.pdf: figure files must end in .svg or .png",
        ),
    ];
    for (what, args, needle) in opt_cases {
        let mut v = vec!["simulate", "--out", "out.csv"];
        v.extend_from_slice(args);
        let o = mvem(d.path(), &v);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert!(err.contains(needle), "{what}: `{needle}` not in {err}");
        assert_eq!(
            files(d.path()),
            ["in.csv", "p.toml"],
            "{what}: output left behind"
        );
    }
}

#[test]
fn out_of_range_inputs_warn_once_and_succeed() {
    let d = tempfile::tempdir().unwrap();
    let rows: String = (0..20)
        .map(|i| format!("{},1500,110,80,10\n", i as f64 * 0.1))
        .collect();
    std::fs::write(d.path().join("in.csv"), format!("{HEADER}\n{rows}")).unwrap();
    let o = mvem(
        d.path(),
        &["simulate", "--inputs", "in.csv", "--out", "out.csv"],
    );
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert_eq!(err.matches("warning").count(), 1, "{err}");
    assert_eq!(err.matches("u_vgt_pct").count(), 1, "{err}");
    assert!(
        err.contains(
            "u_vgt_pct is outside its range [20, 100] at 20 of 20 input rows (20 below, down to \
             10), first at t = 0 s (the whole channel runs from 10 to 10)"
        ),
        "{err}"
    );
    let (h, rows) = read_csv(&d.path().join("out.csv"));
    // the authors' saturation clamps the command to 20 %
    assert_eq!(rows[0][col(&h, "u_vgt")], 20.0);
}

#[test]
fn demo_writes_files_and_reports_the_sign_reversal() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(d.path(), &["demo", "--out", "demo"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = d.path().join("demo");
    assert_eq!(
        files(&dir),
        [
            "demo.png",
            "demo.svg",
            "vgt_step_30_to_25.csv",
            "vgt_step_75_to_65.csv"
        ]
    );
    let (_, r1) = read_csv(&dir.join("vgt_step_75_to_65.csv"));
    assert_eq!(r1.len(), 801);
    let out = stdout(&o);
    let case2 = out.find("Case 2").expect("case 2 in the summary");
    let (c1, c2) = out.split_at(case2);
    assert!(c1.contains("Case 1: u_vgt 75 → 65 %"), "{out}");
    assert!(c1.contains("kg/s per %: negative"), "{out}");
    assert!(c1.contains("W_c = 0.23965 kg/s at t = 1.21 s"), "{out}");
    assert!(c1.contains(": non-minimum phase"), "{out}");
    assert!(c1.contains("overshoot: none"), "{out}");
    assert!(c2.contains("u_vgt 30 → 25 %"), "{out}");
    assert!(c2.contains("kg/s per %: positive"), "{out}");
    assert!(c2.contains("overshoot: 18.9 %"), "{out}");
    assert!(
        out.contains("Sign reversal: case 1 (u_vgt 75 → 65 % at t = 1 s) shows a non-minimum-phase W_c response with negative DC gain"),
        "{out}"
    );
}

#[test]
fn params_show_is_annotated_and_loads_back_identically() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(d.path(), &["params", "show", "--format", "toml"]);
    assert!(o.status.success());
    let text = stdout(&o);
    // the built-in parameter file is exactly this output (regenerate it with this command)
    assert_eq!(text, mvem::params::PUBLISHED_TOML);
    // units, one-line descriptions and equation numbers as comments; short numbers
    assert!(
        text.contains("# Turbocharger inertia J_t (eq. (42)) [kg m^2]\nj_t = "),
        "{text}"
    );
    assert!(text.contains("\n# Intake manifold control volume (eqs (6)-(9)) and the ideal intercooler (eq. (73))\n[intake_manifold]\n"));
    assert!(!text.contains("0.0000000"), "{text}");
    for line in text
        .lines()
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with('['))
    {
        assert!(line.contains(" = "), "{line}");
    }
    // the file loads back to the same parameter set (compared as JSON, exact numbers)
    std::fs::write(d.path().join("p.toml"), &text).unwrap();
    let json = |args: &[&str]| json_of(&mvem(d.path(), args));
    assert_eq!(
        json(&["params", "show", "--params", "p.toml", "--format", "json"]),
        json(&["params", "show", "--format", "json"])
    );
}

#[test]
fn params_show_and_check() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(d.path(), &["params", "show"]);
    assert!(o.status.success());
    std::fs::write(d.path().join("p.toml"), stdout(&o)).unwrap();
    let o = mvem(d.path(), &["params", "check", "p.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // the published set is clean: no plausibility warning
    assert!(!stderr(&o).contains("warning"), "{}", stderr(&o));
    // QA findings: litres typed as m^3 are valid but warned (exit code 0); a nan names itself
    let p = std::fs::read_to_string(d.path().join("p.toml")).unwrap();
    assert!(p.contains("v_d = 0.01274\n"));
    std::fs::write(
        d.path().join("l.toml"),
        p.replace("v_d = 0.01274\n", "v_d = 5.0\n"),
    )
    .unwrap();
    let o = mvem(d.path(), &["params", "check", "l.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: l.toml: cylinder.v_d = 5 m^3 (5000 dm^3) is outside"),
        "{}",
        stderr(&o)
    );
    // the [test_cell] section `mvem tune` writes is checked by its own loader, not refused
    std::fs::write(
        d.path().join("tc.toml"),
        format!("{p}\n[test_cell]\ntau_me = 1.0\n"),
    )
    .unwrap();
    let o = mvem(d.path(), &["params", "check", "tc.toml"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    std::fs::write(
        d.path().join("tcb.toml"),
        format!("{p}\n[test_cell]\ntau_me = -1.0\n"),
    )
    .unwrap();
    let o = mvem(d.path(), &["params", "check", "tcb.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("test_cell.tau_me = -1"),
        "{}",
        stderr(&o)
    );
    let h = p.lines().find(|l| l.starts_with("h_tot = ")).unwrap();
    std::fs::write(d.path().join("n.toml"), p.replace(h, "h_tot = nan")).unwrap();
    let o = mvem(d.path(), &["params", "check", "n.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("exhaust_pipe.h_tot = nan: not a finite number"),
        "{}",
        stderr(&o)
    );
    // elements are named 1-based, as `params show` (c_vol1..3) and the registry name them
    let c = p.lines().find(|l| l.starts_with("c_vol = ")).unwrap();
    std::fs::write(
        d.path().join("v.toml"),
        p.replace(c, "c_vol = [nan, -0.0034, 1.15]"),
    )
    .unwrap();
    let o = mvem(d.path(), &["params", "check", "v.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("cylinder.c_vol[1] = nan: not a finite number"),
        "{}",
        stderr(&o)
    );
    let o = mvem(
        d.path(),
        &["params", "show", "--params", "p.toml", "--format", "json"],
    );
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["intake_manifold"]["v_im"], 0.022);
    // the authors' flat JSON
    let flat = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/wahlstrom_eriksson_2011_parameters.json");
    let o = mvem(d.path(), &["params", "check", flat.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));

    // every problem is listed: unknown key, missing key, wrong type, two bad values
    let text = std::fs::read_to_string(d.path().join("p.toml"))
        .unwrap()
        .replace("v_im = 0.022\n", "v_imm = 0.022\n")
        .replace("v_em = 0.02\n", "v_em = -0.02\n")
        .replace("j_t = 0.0002", "j_t = \"small\"")
        .replace("r_c = 17.0", "r_c = -17.0");
    std::fs::write(d.path().join("bad.toml"), text).unwrap();
    let o = mvem(d.path(), &["params", "check", "bad.toml"]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    for n in [
        "5 problem(s)",
        "intake_manifold.v_imm: unknown key",
        "intake_manifold.v_im: missing key",
        "turbo.j_t: expected a number",
        "exhaust_manifold.v_em = -0.02",
        "cylinder.r_c = -17",
    ] {
        assert!(err.contains(n), "`{n}` not in {err}");
    }
}

#[test]
fn every_command_has_help_with_an_example() {
    let d = tempfile::tempdir().unwrap();
    for cmd in [
        vec!["--help"],
        vec!["simulate", "--help"],
        vec!["steady", "--help"],
        vec!["demo", "--help"],
        vec!["bench", "--help"],
        vec!["params", "--help"],
        vec!["params", "show", "--help"],
        vec!["params", "check", "--help"],
        vec!["linearize", "--help"],
        vec!["step", "--help"],
        vec!["map", "--help"],
        vec!["components", "--help"],
        vec!["report", "--help"],
        vec!["report", "figs", "--help"],
        vec!["report", "sign-reversal", "--help"],
    ] {
        let o = mvem(d.path(), &cmd);
        assert!(o.status.success(), "{cmd:?}");
        let out = stdout(&o);
        assert!(out.contains("Examples:\n  mvem "), "{cmd:?}: {out}");
    }
    // no arguments: usage error
    let o = mvem(d.path(), &[]);
    assert_eq!(o.status.code(), Some(2));
}

/// `mvem ... | head`: a reader that closes the pipe early ends the program quietly (SIGPIPE),
/// never with a Rust panic message.
#[cfg(unix)]
#[test]
fn closed_stdout_pipe_is_not_a_panic() {
    use std::io::Read;
    use std::process::Stdio;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_mvem"))
        // a 12 x 12 map to stdout: ~120 kB of CSV, more than a pipe buffer holds
        .args([
            "map",
            "--axis",
            "u_egr=0:100:12",
            "--axis",
            "u_vgt=20:100:12",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run mvem");
    // read one byte, then close our end of the pipe before the program has written everything
    let mut out = child.stdout.take().unwrap();
    let mut byte = [0u8; 1];
    out.read_exact(&mut byte).unwrap();
    drop(out);
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let status = child.wait().unwrap();
    assert!(!err.contains("panicked"), "stderr: {err}");
    assert_ne!(status.code(), Some(101), "a panic exit code: {status:?}");
}

/// `--time-parallel 2` (two time chunks on two threads): the same rows and columns as the
/// sequential run, the values within the integration tolerance, the junction reported; `mvem
/// bench` prints both timings and the junctions.
#[test]
fn time_parallel_simulate_and_bench() {
    let d = tempfile::tempdir().unwrap();
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "simulate",
            "--scenario",
            "whtc",
            "--t-end",
            "300",
            "--dt",
            "0.1",
            "--out",
            out,
        ];
        args.extend_from_slice(extra);
        let o = mvem(d.path(), &args);
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let seq = run("seq.csv", &[]);
    assert!(!seq.contains("time-parallel"), "{seq}");
    let par = run("par.csv", &["--time-parallel", "2"]);
    assert!(par.contains("time-parallel: 2 chunks, 0 re-run"), "{par}");
    let (hs, rs) = read_csv(&d.path().join("seq.csv"));
    let (hp, rp) = read_csv(&d.path().join("par.csv"));
    assert_eq!(hs, hp);
    assert_eq!(rs.len(), rp.len());
    assert_eq!(rs.len(), 3001);
    for name in ["t", "p_im", "p_em", "omega_t", "W_c"] {
        let c = col(&hs, name);
        for (a, b) in rs.iter().zip(&rp) {
            // within a tenth of rtol 1e-6 (measured: 1e-9 and below)
            assert!(
                (a[c] - b[c]).abs() <= 1e-7 * a[c].abs().max(1e-3),
                "{name}: {} vs {} at t = {}",
                a[c],
                b[c],
                a[0]
            );
        }
    }
    // bench on a 300 s part of the cycle: both lines
    let text = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/whtc_inputs_10hz.csv"),
    )
    .unwrap();
    let short: Vec<&str> = text.lines().take(3002).collect();
    std::fs::write(d.path().join("short.csv"), short.join("\n")).unwrap();
    let o = mvem(
        d.path(),
        &[
            "bench",
            "--inputs",
            "short.csv",
            "--repeat",
            "1",
            "--evals",
            "1000",
            "--no-reference",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("Simulation (1 runs, 1 thread)"), "{out}");
    // the estimate of where the run's time goes names the run's own counts
    let field = |prefix: &str| -> Vec<u64> {
        let line = out
            .lines()
            .find(|l| l.trim_start().starts_with(prefix))
            .unwrap();
        line.split(|c: char| !c.is_ascii_digit())
            .filter_map(|w| w.parse().ok())
            .collect()
    };
    let (steps, evals) = (field("steps")[..2].to_vec(), field("RHS evaluations")[0]);
    let est = out
        .lines()
        .find(|l| l.contains("in the run above (estimate)"))
        .unwrap();
    assert!(
        est.contains(&format!("its {evals} RHS evaluations")),
        "{est}"
    );
    assert!(
        est.contains(&format!("({} trial steps)", steps[0] + steps[1])),
        "{est}"
    );
    assert!(out.contains("Time-parallel (1 runs alternated"), "{out}");
    assert!(
        out.contains("junctions          2 chunks, 0 re-run"),
        "{out}"
    );
}

#[test]
fn a_spreadsheet_export_with_semicolons_and_decimal_commas_simulates_the_same() {
    let d = tempfile::tempdir().unwrap();
    let comma = format!("{HEADER}\n0,1500,110.5,80,75\n1.5,1500,110.5,80,75\n1.5,1500,110.5,80,65\n4,1500,110.5,80,65\n");
    let semi = comma.replace(',', ";").replace('.', ",");
    std::fs::write(d.path().join("comma.csv"), &comma).unwrap();
    std::fs::write(d.path().join("semi.csv"), &semi).unwrap();
    for (inp, out) in [("comma.csv", "a.csv"), ("semi.csv", "b.csv")] {
        let o = mvem(d.path(), &["simulate", "--inputs", inp, "--out", out]);
        assert!(o.status.success(), "{inp}: {}", stderr(&o));
    }
    let (a, b) = (
        std::fs::read(d.path().join("a.csv")).unwrap(),
        std::fs::read(d.path().join("b.csv")).unwrap(),
    );
    assert!(a.len() > 1000 && a == b, "the same output, byte for byte");
}
