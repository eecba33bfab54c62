//! Failure honesty and the robustness sweep through the `mvem` binary:
//! - a solver failure exits with code 1 and a message naming the time, the offending state or
//!   the whole state, its value and a hint, and writes no output file (not even a temporary
//!   one);
//! - `mvem robustness` runs the sweep at every model order and reports it as text, JSON and
//!   Markdown; bad options exit with code 2.

use std::path::Path;
mod common;

use common::{files, mvem, mvem_within, stderr};

const HEADER: &str = "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct";

/// Full load with the EGR valve over-open and the VGT closed beyond its range, then motoring at
/// 300 rpm: far outside the paper's plain equations (no guards).
fn write_absurd_inputs(dir: &Path) {
    std::fs::write(
        dir.join("in.csv"),
        format!(
            "{HEADER}\n0,2500,300,120,-20\n0.5,2500,300,120,-20\n0.5,2500,0,120,-20\n\
             1,2500,0,120,-20\n1,300,0,120,-20\n3,300,0,120,-20\n"
        ),
    )
    .unwrap();
}

/// The paper's equations from a state far off (p_im 0.3 bar, p_em 25 bar): the turbine's
/// pressure ratio leaves its domain at once. Exit 1; the message names t, the offending state,
/// its value, the whole state and a hint; no output or figure is written.
#[test]
fn solver_failure_is_located_exits_1_and_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    write_absurd_inputs(d.path());
    std::fs::write(
        d.path().join("x0.json"),
        r#"{"p_im":30000,"p_em":2500000,"X_Oim":0.23,"X_Oem":0,"omega_t":200,
            "u_egr1":120,"u_egr2":120,"u_vgt_act":-20}"#,
    )
    .unwrap();
    let before = files(d.path());
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
            "--semantics",
            "paper",
        ],
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let msg = err.lines().find(|l| l.starts_with("error:")).unwrap();
    // time, offending state, its value, the state dump, the hint
    assert!(msg.contains("at t = 0 s"), "{msg}");
    assert!(msg.contains("derivative of omega_t = NaN"), "{msg}");
    assert!(
        msg.contains("p_im=3.000000e4") && msg.contains("p_em=2.500000e6"),
        "{msg}"
    );
    assert!(
        msg.contains("Hint:") && msg.contains("--semantics authors"),
        "{msg}"
    );
    assert_eq!(files(d.path()), before, "a failed run wrote a file");
}

/// A failure after output blocks were already written (streamed: at t = 2.15 s, more than
/// 2000 samples of 1 ms in): exit 1 with the located error, and neither the output file nor
/// its temporary file is left; an existing file of that name is kept as it was.
#[test]
fn failure_while_streaming_leaves_no_file() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("in.csv"),
        format!(
            "{HEADER}\n0,1500,110,80,75\n2,1500,110,80,75\n2,2500,300,120,-20\n4,300,0,120,-20\n"
        ),
    )
    .unwrap();
    let args = [
        "simulate",
        "--inputs",
        "in.csv",
        "--dt",
        "0.001",
        "--semantics",
        "paper",
        "--out",
    ];
    let before = files(d.path());
    for out in ["out.csv", "out.parquet"] {
        let o = mvem(d.path(), &[&args[..], &[out]].concat());
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains("at t = 2.1"), "{err}");
        assert_eq!(files(d.path()), before, "a failed run left a file");
    }
    std::fs::write(d.path().join("out.csv"), "old").unwrap();
    let o = mvem(d.path(), &[&args[..], &["out.csv"]].concat());
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        std::fs::read_to_string(d.path().join("out.csv")).unwrap(),
        "old"
    );
}

/// The extended models with the paper's equations have no equilibrium at these inputs: the
/// settling simulation's step size collapses. Exit 1, the message names the time, every state
/// (including the temperatures and, at 12 states, p_c) and the hint; nothing is written.
#[test]
fn lost_equilibrium_is_located_for_10_and_12_states() {
    let d = tempfile::tempdir().unwrap();
    write_absurd_inputs(d.path());
    let before = files(d.path());
    for (model, state) in [("10", "T_em="), ("12", "p_c=")] {
        let o = mvem(
            d.path(),
            &[
                "simulate",
                "--inputs",
                "in.csv",
                "--out",
                "out.csv",
                "--semantics",
                "paper",
                "--model",
                model,
            ],
        );
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{model}: {err}");
        let msg = err.lines().find(|l| l.starts_with("error:")).unwrap();
        assert!(
            msg.contains("no equilibrium found at n_e=2500 rpm"),
            "{msg}"
        );
        // how the blow-up ends depends on round-off (step size collapse, non-finite state, or
        // the step budget running out within a fraction of a second): each names time and state
        assert!(
            msg.contains("too small at t = ")
                || msg.contains("non-finite")
                || msg.contains("steps before t = "),
            "{msg}"
        );
        assert!(msg.contains(state) && msg.contains("Hint:"), "{msg}");
        assert!(msg.contains("equilibrium lost"), "{msg}");
        if msg.contains("too small at t = ") {
            // the state whose error estimate forced the step down is named
            let limiting = msg
                .split("limiting state: ")
                .nth(1)
                .and_then(|r| r.split(' ').next())
                .unwrap_or("");
            assert!(
                msg.contains(&format!("{limiting}=")) && !limiting.is_empty(),
                "{msg}"
            );
        }
        assert_eq!(
            files(d.path()),
            before,
            "{model}: a failed run wrote a file"
        );
    }
}

/// `mvem robustness` at all three orders: every run completes cleanly (the authors' guards),
/// the JSON and the Markdown report agree on the counts, and every sample was checked.
#[test]
fn robustness_command_reports_every_order() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &[
            "robustness",
            "--runs",
            "6",
            "--t-end",
            "2",
            "--seed",
            "5",
            "--model",
            "all",
            "--threads",
            "2",
            "--json",
            "--out",
            "report.md",
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["runs_per_model"], 6);
    let models = v["models"].as_array().unwrap();
    let states: Vec<u64> = models
        .iter()
        .map(|m| m["states"].as_u64().unwrap())
        .collect();
    assert_eq!(states, [8, 10, 12]);
    for m in models {
        assert_eq!(m["runs"], 6, "{m}");
        assert_eq!(m["completed"], 6, "{m}");
        assert_eq!(m["nonfinite_samples"], 0, "{m}");
        assert_eq!(m["panics"].as_array().unwrap().len(), 0, "{m}");
        assert_eq!(m["violations"].as_array().unwrap().len(), 0, "{m}");
        assert_eq!(m["clean"], true, "{m}");
        // 2 s at 0.01 s plus the end sample, per run
        assert_eq!(m["samples_checked"], 6 * 201, "{m}");
        // both integrators ran
        assert_eq!(m["per_method"].as_array().unwrap().len(), 2, "{m}");
    }
    let md = std::fs::read_to_string(d.path().join("report.md")).unwrap();
    assert!(
        md.contains("| quantity | 8 states | 10 states | 12 states |"),
        "{md}"
    );
    assert!(md.contains("| runs completed | 6 | 6 | 6 |"), "{md}");
    assert!(md.contains("| samples with NaN/inf | 0 | 0 | 0 |"), "{md}");
    assert_eq!(files(d.path()), ["report.md"]);
}

#[test]
fn robustness_bad_options_exit_2() {
    let d = tempfile::tempdir().unwrap();
    for (args, what) in [
        (&["--t-end", "-1"][..], "--t-end -1: must be > 0"),
        (&["--runs", "0"][..], "--runs"),
        (&["--model", "9"][..], "--model"),
        (&["--methods", "euler"][..], "--methods"),
        (&["--out", "no/such/dir/r.md"][..], "does not exist"),
        (&["--params", "missing.toml"][..], "missing.toml"),
    ] {
        let mut a = vec!["robustness"];
        a.extend_from_slice(args);
        for (k, v) in [("--runs", "1"), ("--t-end", "1")] {
            if !a.contains(&k) {
                a.extend([k, v]);
            }
        }
        let o = mvem(d.path(), &a);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(what), "{args:?}: {err}");
    }
    assert!(files(d.path()).is_empty());
}

/// Inputs the paper's equations cannot evaluate (n_e <= 0: sqrt(n_e) in eq. (12), 0/0 in the
/// cylinder temperature) used to hang `steady`, `linearize`, `map` and `simulate` in an
/// unbounded eigenvalue iteration. Every such command now ends at once with exit code 2 and a
/// message naming n_e, and writes nothing. (Limit 60 s for a loaded machine; they take
/// milliseconds.)
#[test]
fn paper_semantics_at_zero_or_negative_speed_ends_with_exit_2() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("zero.csv"),
        format!("{HEADER}\n0,1500,110,80,75\n1,0,110,80,75\n2,0,110,80,75\n"),
    )
    .unwrap();
    let before = files(d.path());
    let point = |n_e: &'static str| {
        vec![
            "--n-e",
            n_e,
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--u-vgt",
            "75",
            "--semantics",
            "paper",
        ]
    };
    let mut cases: Vec<Vec<&str>> = Vec::new();
    for n_e in ["0", "-100"] {
        for cmd in ["steady", "linearize"] {
            let mut c = vec![cmd];
            c.extend(point(n_e));
            cases.push(c);
        }
    }
    cases.push(vec![
        "map",
        "--axis",
        "n_e=0,1500",
        "--u-delta",
        "110",
        "--u-egr",
        "80",
        "--u-vgt",
        "75",
        "--semantics",
        "paper",
        "--out",
        "map.csv",
    ]);
    cases.push(vec![
        "simulate",
        "--inputs",
        "zero.csv",
        "--out",
        "out.csv",
        "--semantics",
        "paper",
    ]);
    for args in &cases {
        let o = mvem_within(d.path(), args, 60.0);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains("n_e") && err.contains("paper"),
            "{args:?}: {err}"
        );
    }
    assert_eq!(files(d.path()), before, "a failed run wrote a file");
    // the authors' semantics saturate n_e to 500 rpm (item 1): a result, with a warning flag
    let o = mvem_within(
        d.path(),
        &[
            "steady",
            "--n-e",
            "0",
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--u-vgt",
            "75",
        ],
        60.0,
    );
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

/// `mvem robustness --analysis`: steady, linearize and map over the whole input box (zero and
/// negative speeds included) under both semantics, each call with a time limit: no hang, no
/// panic, no NaN/inf (exit 0), and the report counts the calls.
#[test]
fn analysis_sweep_is_clean() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem_within(
        d.path(),
        &[
            "robustness",
            "--analysis",
            "--runs",
            "4",
            "--model",
            "8",
            "--timeout",
            "60",
            "--json",
        ],
        600.0,
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // 4 points x 3 calls x 2 semantics
    assert_eq!(v["calls"], 24, "{v}");
    assert_eq!(
        (
            v["hangs"].as_u64(),
            v["panics"].as_u64(),
            v["nonfinite"].as_u64()
        ),
        (Some(0), Some(0), Some(0))
    );
    assert_eq!(v["clean"], true);
}
