//! `mvem closed-loop`: a short closed-loop WHTC run end to end, and bad input (exit code 2, a
//! clear message, nothing written).

mod common;

use common::{
    col, files, json_of, mvem, read_csv, stderr, stdout, usage_error, write_published_with,
};

#[test]
fn short_whtc_run_writes_the_trajectory_and_statistics() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &[
            "closed-loop",
            "--cycle",
            "whtc",
            "--out",
            "cl",
            "--duration",
            "60",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        files(&d.path().join("cl")),
        ["stats.json", "trajectory.csv"]
    );
    let (h, rows) = read_csv(&d.path().join("cl").join("trajectory.csv"));
    for c in [
        "t",
        "n_e",
        "u_delta",
        "u_egr",
        "u_vgt",
        "M_ref",
        "M_e",
        "lambda_O",
        "lambda_O_ref",
        "x_egr",
        "x_egr_ref",
        "p_im",
        "p_em",
        "omega_t",
        "W_c",
    ] {
        col(&h, c);
    }
    assert_eq!(rows.len(), 6001, "0..60 s every 10 ms");
    let t = col(&h, "t");
    assert!((rows[1][t] - 0.01).abs() < 1e-12);
    // the torque follows the demand on the first minute (idle and the first accelerations)
    let json: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let slope = json["stats"]["torque"]["slope"].as_f64().unwrap();
    assert!((0.83..=1.03).contains(&slope), "{json}");
    assert!(
        json["stats"]["lambda_o_min"].as_f64().unwrap() >= 1.05,
        "{json}"
    );
}

#[test]
fn bad_input_is_exit_2_and_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    let err = usage_error(
        d.path(),
        &["closed-loop", "--out", "o", "--controller", "pid"],
    );
    assert!(err.contains("pid"), "{err}");

    std::fs::write(d.path().join("miss.csv"), "t,n_e\n0,1000\n1,1000\n").unwrap();
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "miss.csv", "--out", "o"],
    );
    assert!(err.contains("missing column(s) M_ref"), "{err}");

    std::fs::write(
        d.path().join("unsorted.csv"),
        "t,n_e,M_ref\n0,1000,100\n2,1000,100\n1,1000,100\n",
    )
    .unwrap();
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "unsorted.csv", "--out", "o"],
    );
    // (the file's line, as `simulate --inputs` names it; before session 41 "row 3: ... (time
    // must increase)")
    assert!(
        err.contains("unsorted.csv, line 4, column t: time 1 s is not monotonic (previous 2 s)"),
        "{err}"
    );

    std::fs::write(
        d.path().join("heavy.csv"),
        "t,n_e,M_ref\n0,1200,500\n5,1200,5000\n",
    )
    .unwrap();
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "heavy.csv", "--out", "o"],
    );
    assert!(
        err.contains("cannot follow") && err.contains("t = 5 s"),
        "{err}"
    );

    // a time column that would take forever: refused before the loop starts
    std::fs::write(
        d.path().join("long.csv"),
        "t,n_e,M_ref\n0,1500,500\n1e308,1500,600\n",
    )
    .unwrap();
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "long.csv", "--out", "o"],
    );
    assert!(
        err.contains("controller samples") && err.contains("at most 5e7"),
        "{err}"
    );

    let err = usage_error(
        d.path(),
        &[
            "closed-loop",
            "--cycle",
            "heavy.csv",
            "--controller",
            "open-loop",
            "--out",
            "o",
        ],
    );
    assert!(err.contains("--cycle whtc"), "{err}");
    assert!(
        !d.path().join("o").exists(),
        "nothing written after bad input"
    );
}

#[test]
fn a_users_cycle_runs() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("c.csv"),
        "t,n_e,M_ref\n0,1200,300\n2,1200,300\n2.5,1400,900\n6,1400,900\n",
    )
    .unwrap();
    let o = mvem(d.path(), &["closed-loop", "--cycle", "c.csv", "--out", "o"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (h, rows) = read_csv(&d.path().join("o").join("trajectory.csv"));
    let (m, r) = (col(&h, "M_e"), col(&h, "M_ref"));
    let last = rows.last().unwrap();
    assert!((last[m] - last[r]).abs() < 0.01 * last[r], "{last:?}");
    assert!(!stderr(&o).contains("--duration"), "{}", stderr(&o));
    // a duration beyond the cycle runs all of it and says so
    let o = mvem(
        d.path(),
        &[
            "closed-loop",
            "--cycle",
            "c.csv",
            "--duration",
            "100",
            "--out",
            "o2",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "warning: --cycle c.csv: --duration 100 s is longer than the cycle (6 s from 0 s to \
             6 s): ran all of it"
        ),
        "{}",
        stderr(&o)
    );
    let (_, rows2) = read_csv(&d.path().join("o2").join("trajectory.csv"));
    assert_eq!(rows2.len(), rows.len());
}

/// A run that fails after the trajectory was written (a late write: stats.json cannot be
/// written because a directory of that name is in the way) leaves none of its files: not
/// trajectory.csv, not a temporary file. `--semantics paper` is refused before anything runs
/// (exit 2, the reason: the paper's equations have no idle equilibrium), writing nothing.
#[test]
fn runtime_failure_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(d.path().join("old").join("stats.json")).unwrap();
    let o = mvem(
        d.path(),
        &["closed-loop", "--duration", "1", "--plot", "--out", "old"],
    );
    // (an output path that cannot be written is the user's: exit 2)
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("cannot write old/stats.json"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        files(&d.path().join("old")),
        ["stats.json"],
        "no file of the run or temporary file left"
    );

    let err = usage_error(
        d.path(),
        &["closed-loop", "--semantics", "paper", "--out", "new"],
    );
    assert!(
        err.contains("--semantics paper: the closed loop needs the authors' semantics")
            && err.contains("eq. (64)")
            && !err.contains("max_steps"),
        "{err}"
    );
    assert!(!d.path().join("new").exists());
}

/// The QA's inputs: a demand header with units (brackets or a units row, converted), `Time`;
/// durations off the 10 ms grid or shorter than two samples; a demand below the motoring
/// torque; the full-load limit named; a PI gain of three numbers; `--margins` off the grid;
/// infinite intervals; `--cycle WHTC`; a rerun into the same directory.
#[test]
fn cycle_and_option_edge_cases_are_named() {
    let d = tempfile::tempdir().unwrap();
    let w = |name: &str, text: &str| std::fs::write(d.path().join(name), text).unwrap();
    w("plain.csv", "t,n_e,M_ref\n0,1000,200\n5,1200,500\n");
    w(
        "brackets.csv",
        "t [s],n_e [rpm],M_ref [Nm]\n0,1000,200\n5,1200,500\n",
    );
    w(
        "units.csv",
        "Time,n_e,M_ref\ns,krpm,kNm\n0,1,0.2\n5,1.2,0.5\n",
    );
    let traj = |out: &str, cycle: &str| {
        let o = mvem(d.path(), &["closed-loop", "--cycle", cycle, "--out", out]);
        assert!(o.status.success(), "{cycle}: {}", stderr(&o));
        read_csv(&d.path().join(out).join("trajectory.csv")).1
    };
    let want = traj("p", "plain.csv");
    assert_eq!(want.len(), 501);
    for (out, cycle) in [("b", "brackets.csv"), ("u", "units.csv")] {
        let got = traj(out, cycle);
        assert_eq!(got.len(), want.len(), "{cycle}");
        for (a, b) in got.iter().zip(&want) {
            for (x, y) in a.iter().zip(b) {
                assert!(x == y || (x.is_nan() && y.is_nan()) || (x - y).abs() <= 1e-9 * y.abs());
            }
        }
    }
    w("pct.csv", "t,n_e [%],M_ref\n0,50,200\n5,60,500\n");
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "pct.csv", "--out", "x"],
    );
    assert!(
        err.contains("column n_e: unit '%' in the header is not a unit of n_e"),
        "{err}"
    );

    // durations: off the grid (rounded down, said), shorter than two samples (refused)
    let o = mvem(
        d.path(),
        &[
            "closed-loop",
            "--cycle",
            "plain.csv",
            "--duration",
            "2.005",
            "--out",
            "d",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--duration 2.005 s is not a multiple of the 0.01 s sample time: ran the samples up to 2 s"),
        "{}",
        stderr(&o)
    );
    assert!(
        !stderr(&o).contains("longer than the cycle"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        read_csv(&d.path().join("d").join("trajectory.csv")).1.len(),
        201
    );
    for (dur, want) in [
        (
            "0.005",
            "--duration 0.005 s: shorter than two controller samples",
        ),
        (
            "inf",
            "--duration inf: must be a finite number of seconds > 0",
        ),
        (
            "-1",
            "--duration -1: must be a finite number of seconds > 0",
        ),
    ] {
        let arg = format!("--duration={dur}");
        let err = usage_error(d.path(), &["closed-loop", &arg, "--out", "x"]);
        assert!(err.contains(want), "{err}");
    }
    let err = usage_error(d.path(), &["closed-loop", "--margins", "inf", "--out", "x"]);
    assert!(
        err.contains("--margins inf: must be a finite number"),
        "{err}"
    );
    let err = usage_error(d.path(), &["closed-loop", "--cycle", "WHTC", "--out", "x"]);
    assert!(err.contains("`--cycle whtc`, lower case"), "{err}");

    // below the motoring torque: a warning with the file's line, time and values (the line
    // after the comment and the header: "row 3" before, two lines off in the file)
    w(
        "brake.csv",
        "# braking\nt,n_e,M_ref\n0,1200,300\n5,1200,300\n6,1200,-2000\n8,1200,-2000\n",
    );
    let o = mvem(
        d.path(),
        &["closed-loop", "--cycle", "brake.csv", "--out", "m"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "2 row(s) of the demand ask for less torque than the engine's motoring torque"
        ) && stderr(&o).contains("the first line 5 (t = 6 s): -2000 Nm at 1200 rpm"),
        "{}",
        stderr(&o)
    );
    // above full load at 1200 rpm: the fuel cap, not the smoke limit
    w(
        "heavy.csv",
        "t,n_e,M_ref\ns,rpm,Nm\n0,1200,500\n\n5,1200,5000\n",
    );
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "heavy.csv", "--out", "x"],
    );
    assert!(
        err.contains("heavy.csv: demand: line 5 (t = 5 s): torque 5000 Nm at 1200 rpm")
            && err.contains("fuel-limited at the top of the u_delta range, 250 mg"),
        "{err}"
    );

    w("three.toml", "x_egr_vgt = [150, 800, 3]\n");
    let err = usage_error(
        d.path(),
        &["closed-loop", "--tuning", "three.toml", "--out", "x"],
    );
    assert!(
        err.contains("invalid length 3") && err.contains("[kp, ki]"),
        "{err}"
    );
    assert!(!d.path().join("x").exists());

    // --margins off the grid: rounded to it, said; a rerun without --margins removes the
    // previous run's margins.csv
    let o = mvem(
        d.path(),
        &[
            "closed-loop",
            "--cycle",
            "plain.csv",
            "--margins",
            "0.015",
            "--out",
            "g",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(
            "--margins 0.015: not a multiple of the 0.01 s sample time; analyses every 0.02 s"
        ),
        "{}",
        stderr(&o)
    );
    let (h, rows) = read_csv(&d.path().join("g").join("margins.csv"));
    let t = col(&h, "t");
    for r in rows.windows(2) {
        assert!((r[1][t] - r[0][t] - 0.02).abs() < 1e-9, "{r:?}");
    }
    let o = mvem(
        d.path(),
        &["closed-loop", "--cycle", "plain.csv", "--out", "g"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("Removed margins.csv of a previous run"),
        "{}",
        stderr(&o)
    );
    assert_eq!(files(&d.path().join("g")), ["stats.json", "trajectory.csv"]);
}

/// A user's cycle is checked against the parameter set's speed range ([input_saturation] n_e):
/// 2300 rpm is refused for the authors' engine (exit 2, the row, its time and the range) and
/// runs on an engine whose range reaches 2600 rpm; the WHTC's reference speeds follow it.
#[test]
fn a_cycle_follows_the_parameter_sets_speed_range() {
    let d = tempfile::tempdir().unwrap();
    write_published_with(
        d.path(),
        "wide.toml",
        &[("n_e = [500.0, 2000.0]", "n_e = [500.0, 2600.0]")],
    );
    std::fs::write(
        d.path().join("fast.csv"),
        "# a fast cycle\nt,n_e,M_ref\n0,1500,300\n2,1500,300\n3,2300,300\n15,2300,300\n",
    )
    .unwrap();
    let err = usage_error(
        d.path(),
        &["closed-loop", "--cycle", "fast.csv", "--out", "o"],
    );
    // (the file's line: the third row is line 5, after the comment and the header)
    assert!(
        err.contains("line 5 (t = 3 s): speed 2300 rpm") && err.contains("[500, 2000]"),
        "{err}"
    );
    let o = mvem(
        d.path(),
        &[
            "closed-loop",
            "--cycle",
            "fast.csv",
            "--params",
            "wide.toml",
            "--out",
            "o",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let (h, rows) = read_csv(&d.path().join("o").join("trajectory.csv"));
    let (n, m, r) = (col(&h, "n_e"), col(&h, "M_e"), col(&h, "M_ref"));
    let last = rows.last().unwrap();
    assert_eq!(last[n], 2300.0);
    // 12 s after the speed step the torque is tracked (0.01 % in this run; 1.3 % after 5 s,
    // while the air path still opens the VGT and the EGR valve)
    assert!((last[m] - last[r]).abs() < 0.002 * last[r], "{last:?}");
    let o = mvem(
        d.path(),
        &[
            "closed-loop",
            "--params",
            "wide.toml",
            "--duration",
            "1",
            "--json",
            "--out",
            "w",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let hi = json["reference_speeds_rpm"]["n_hi"].as_f64().unwrap();
    assert!(hi > 2000.0 && hi <= 2600.0, "{json}");
}

/// `--tuning FILE.toml` reaches the baseline controllers: on a tip-in at 1200 rpm the smoke
/// limiter holds lambda_O at 1.22 with the default lambda_lim = 1.2 and lets it fall to 1.12
/// with `lambda_limit = 1.1` (the cycle's own lambda_O >= 1.2 check then reports it);
/// stats.json echoes the tuning used. A value out of range, an unknown key and a tuning for the
/// open-loop schedule are usage errors naming them, and nothing is written.
#[test]
fn a_tuning_file_sets_the_baseline_controllers() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("tip.csv"),
        "t,n_e,M_ref\n0,1200,100\n2,1200,100\n2.2,1200,1500\n8,1200,1500\n",
    )
    .unwrap();
    std::fs::write(d.path().join("t.toml"), "lambda_limit = 1.1\n").unwrap();
    let run = |out: &str, extra: &[&str]| -> serde_json::Value {
        let mut args = vec!["closed-loop", "--cycle", "tip.csv", "--out", out];
        args.extend_from_slice(extra);
        let o = mvem(d.path(), &args);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = std::fs::read_to_string(d.path().join(out).join("stats.json")).unwrap();
        serde_json::from_str(&text).unwrap()
    };
    let default = run("a", &[]);
    let tuned = run("b", &["--tuning", "t.toml"]);
    let lambda_min = |v: &serde_json::Value| v["stats"]["lambda_o_min"].as_f64().unwrap();
    assert!(lambda_min(&default) > 1.2, "{}", lambda_min(&default));
    assert!(lambda_min(&tuned) < 1.15, "{}", lambda_min(&tuned));
    assert_eq!(default["controller_tuning"]["lambda_limit"], 1.2);
    assert_eq!(tuned["controller_tuning"]["lambda_limit"], 1.1);
    assert_eq!(
        tuned["controller_tuning"]["torque"],
        serde_json::json!([0.02, 2.0])
    );
    assert!(tuned["violations"][0]
        .as_str()
        .unwrap()
        .contains("lambda_O < 1.2"));

    for (name, text, want) in [
        (
            "low.toml",
            "lambda_limit = 0.9\n",
            "lambda_limit = 0.9: must be in [1, 5]",
        ),
        ("gain.toml", "torque = [-0.02, 2.0]\n", "torque[1] = -0.02"),
        (
            "typo.toml",
            "lamda_limit = 1.1\n",
            "unknown field `lamda_limit`",
        ),
    ] {
        std::fs::write(d.path().join(name), text).unwrap();
        let err = usage_error(
            d.path(),
            &[
                "closed-loop",
                "--cycle",
                "tip.csv",
                "--tuning",
                name,
                "--out",
                "c",
            ],
        );
        assert!(err.contains(name) && err.contains(want), "{err}");
    }
    let err = usage_error(
        d.path(),
        &[
            "closed-loop",
            "--controller",
            "open-loop",
            "--tuning",
            "t.toml",
            "--out",
            "c",
        ],
    );
    assert!(
        err.contains("--tuning sets the baseline controllers"),
        "{err}"
    );
    assert!(!d.path().join("c").exists());
}

/// `mvem margins`: the JSON holds the library's analysis to the bit, a tuning file's gains reach
/// it (both x_egr -> u_vgt gains doubled: that loop's gain margin halves, the other loop's alone
/// figures stay), the table names every loop, and a bad point or tuning is a usage error.
#[test]
fn margins_of_the_baseline_loops() {
    use mvem::control::baseline::BaselineTuning;
    use mvem::control::margins::{baseline_loops, loop_analysis_json, margins_at};
    use mvem::model::{Drive, Engine8};
    let d = tempfile::tempdir().unwrap();
    let point = [
        "--n-e",
        "1500",
        "--u-delta",
        "110",
        "--u-egr",
        "50",
        "--u-vgt",
        "60",
    ];
    let run = |extra: &[&str]| {
        let mut args = vec!["margins"];
        args.extend(point);
        args.extend(extra);
        mvem(d.path(), &args)
    };
    let o = run(&["--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let t = BaselineTuning::default();
    let op = Drive::new(1500.0, 110.0, 50.0, 60.0);
    let (_, a) = margins_at(
        &Engine8::published(),
        &op,
        &baseline_loops(&t, &op, &Default::default()),
        t.ts,
    )
    .unwrap();
    let lib = loop_analysis_json(&a);
    assert_eq!(j["loops"], lib["loops"]);
    assert_eq!(j["max_pole_all"], lib["max_pole_all"]);
    assert_eq!(j["stable"], true);
    assert_eq!(j["steady_state_warnings"], serde_json::json!([]));
    assert_eq!(j["model_states"], 8);
    assert_eq!(j["operating_point"]["u_vgt"], 60.0);
    let gm =
        |j: &serde_json::Value, k: usize| j["loops"][k]["alone"]["gain_margin"].as_f64().unwrap();
    // doubled x_egr -> u_vgt gains
    std::fs::write(d.path().join("t.toml"), "x_egr_vgt = [300.0, 1600.0]\n").unwrap();
    let doubled: serde_json::Value =
        serde_json::from_slice(&run(&["--json", "--tuning", "t.toml"]).stdout).unwrap();
    assert!(
        (gm(&doubled, 1) / gm(&j, 1) - 0.5).abs() < 1e-8,
        "{} {}",
        gm(&doubled, 1),
        gm(&j, 1)
    );
    assert_eq!(doubled["loops"][0]["alone"], j["loops"][0]["alone"]);
    assert_eq!(doubled["loops"][1]["kp"], 300.0);
    // the table
    let o = run(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    for want in [
        "lambda_O->u_egr",
        "x_egr->u_vgt",
        "gain margin",
        "phase margin",
        "Every loop closed: stable",
    ] {
        assert!(text.contains(want), "{want}: {text}");
    }
    // bad input
    let o = mvem(
        d.path(),
        &[
            "margins",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--u-egr",
            "nan",
            "--u-vgt",
            "60",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--u-egr NaN"), "{}", stderr(&o));
    std::fs::write(d.path().join("bad.toml"), "x_egr_vgt = [300.0, -1.0]\n").unwrap();
    let o = run(&["--tuning", "bad.toml"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("bad.toml"), "{}", stderr(&o));
}

/// `--margins S`: the loops in feedback analysed every S seconds of the run (DIR/margins.csv,
/// a summary in stats.json); each row's loop codes are the trajectory's at that time and its
/// margins the library's for those loops at the row's commands, to the bit; refused with the
/// open-loop schedule or a non-positive interval.
#[test]
fn margins_along_the_run() {
    use mvem::control::along::loops_in_charge;
    use mvem::control::baseline::BaselineTuning;
    use mvem::control::margins::margins_at;
    use mvem::control::InCharge;
    use mvem::model::{Drive, Engine8};
    let d = tempfile::tempdir().unwrap();
    let args = [
        "closed-loop",
        "--out",
        "cl",
        "--duration",
        "60",
        "--margins",
        "10",
        "--json",
    ];
    let o = mvem(d.path(), &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = d.path().join("cl");
    assert_eq!(files(&dir), ["margins.csv", "stats.json", "trajectory.csv"]);
    let json: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let m = &json["margins"];
    assert_eq!(m["points"], 6, "{m}");
    let count = |k: &str| m[k].as_u64().unwrap();
    assert_eq!(count("analysed") + count("no_loop") + count("refused"), 6);
    assert!(count("analysed") >= 4, "{m}");
    let (h, rows) = read_csv(&dir.join("margins.csv"));
    let (th, traj) = read_csv(&dir.join("trajectory.csv"));
    assert_eq!(rows.len(), 6);
    let tuning = BaselineTuning::default();
    let mut checked = 0;
    for r in &rows {
        let t = r[col(&h, "t")];
        let k = (t / 0.01).round() as usize;
        assert!((traj[k][col(&th, "t")] - t).abs() < 1e-9);
        for c in ["egr_loop", "vgt_loop", "u_egr", "u_vgt", "u_delta", "n_e"] {
            assert_eq!(
                r[col(&h, c)].to_bits(),
                traj[k][col(&th, c)].to_bits(),
                "{c}"
            );
        }
        let drive = Drive::new(
            r[col(&h, "n_e")],
            r[col(&h, "u_delta")],
            r[col(&h, "u_egr")],
            r[col(&h, "u_vgt")],
        );
        let loops = loops_in_charge(
            &tuning,
            InCharge::from_code(r[col(&h, "egr_loop")]),
            InCharge::from_code(r[col(&h, "vgt_loop")]),
            &drive,
            &Default::default(),
        );
        let Some(egr) = loops.iter().position(|l| l.input == "u_egr") else {
            continue;
        };
        let (_, a) = margins_at(&Engine8::published(), &drive, &loops, tuning.ts).unwrap();
        let gm = a.others_closed[egr].gain_margin.unwrap_or(f64::NAN);
        assert_eq!(
            r[col(&h, "egr_gain_margin")].to_bits(),
            gm.to_bits(),
            "t = {t}"
        );
        assert_eq!(r[col(&h, "max_pole")], a.max_pole_all);
        checked += 1;
    }
    assert!(checked >= 2, "{checked}");

    for (extra, want) in [
        (&["--margins", "0"][..], "--margins 0"),
        (
            &["--margins", "5", "--controller", "open-loop"][..],
            "open-loop",
        ),
    ] {
        let mut a = vec!["closed-loop", "--out", "o2", "--duration", "10"];
        a.extend(extra);
        let err = usage_error(d.path(), &a);
        assert!(err.contains(want), "{err}");
    }
    assert!(!d.path().join("o2").exists());
}

/// SIGTERM during `mvem closed-loop` (the loop running, its trajectory streaming into
/// `.trajectory.csv.tmp-PID`): the run stops through its error path, which removes the temporary
/// file and the output directory it created, and the process ends by SIGTERM. Before, the
/// default action killed it at once and the temporary file stayed until a later run's
/// housekeeping removed it (10 minutes after it was last written). A second run gets SIGINT
/// (Ctrl-C) the same way.
#[cfg(target_os = "linux")]
#[test]
fn a_termination_signal_leaves_no_temporary_file() {
    use std::os::unix::process::ExitStatusExt;
    use std::time::{Duration, Instant};
    for sig in [libc::SIGTERM, libc::SIGINT] {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("cl");
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_mvem"))
            .args(["closed-loop", "--cycle", "whtc", "--plot", "--out", "cl"])
            .current_dir(d.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let tmp = out.join(format!(".trajectory.csv.tmp-{}", child.id()));
        let start = Instant::now();
        while !tmp.exists() {
            assert!(
                child.try_wait().unwrap().is_none(),
                "the run ended before its temporary file was seen"
            );
            assert!(start.elapsed() < Duration::from_secs(60), "no {tmp:?}");
            std::thread::sleep(Duration::from_millis(2));
        }
        // SAFETY: kill() on the child's PID, which has not been waited for (still ours)
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, sig) }, 0);
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.signal(), Some(sig), "{:?}: {err}", o.status);
        assert!(err.contains("cancelled"), "{err}");
        assert!(!out.exists(), "left: {:?}", files(&out));
    }
}

/// The set-point maps' unreachable cells, as `mvem closed-loop` prints them and writes them to
/// stats.json (`setpoint_adjustments`), are the core's `SetpointMaps::adjusted` for the tuning
/// run: the same cells in the same order, the printed numbers to their printed digits, the JSON's
/// to 1e-12; the printed valve limit is the one the controller applies, the position set-point
/// plus `egr_open_beyond_setpoint` within the valve's range (30 %: 12.5 % -> 42.5 %; 100 %: the
/// open end everywhere), not the set-point alone.
#[test]
fn setpoint_adjustments_are_the_cores_with_the_tunings_valve_limit() {
    use mvem::control::baseline::{Baseline, BaselineTuning};
    use mvem::control::cycle::{MappingCurve, MappingOptions};
    use mvem::model::{AnyModel, ModelOrder};
    use mvem::params::Params;
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("c.csv"),
        "t,n_e,M_ref\n0,1200,100\n0.2,1200,100\n",
    )
    .unwrap();
    let m = AnyModel::new(ModelOrder::Eight, Params::published(), Default::default()).unwrap();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    for (out, beyond) in [("a", 0.0), ("b", 30.0), ("c", 100.0)] {
        let toml = format!("egr_open_beyond_setpoint = {beyond}\n");
        std::fs::write(d.path().join(format!("{out}.toml")), toml).unwrap();
        let tuning = BaselineTuning {
            egr_open_beyond_setpoint: beyond,
            ..BaselineTuning::default()
        };
        let cells = Baseline::new(&m, &curve, tuning).unwrap().maps.adjusted;
        assert!(cells.len() >= 10, "{}", cells.len());
        let o = mvem(
            d.path(),
            &[
                "closed-loop",
                "--cycle",
                "c.csv",
                "--tuning",
                &format!("{out}.toml"),
                "--out",
                out,
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let text = stdout(&o);
        let head = text
            .lines()
            .find(|l| l.starts_with("set-point maps: "))
            .unwrap_or_else(|| panic!("{text}"));
        assert!(head.contains(&format!("{} cell(s)", cells.len())), "{head}");
        assert_eq!(
            beyond == 0.0,
            head.contains("opens it no further"),
            "{head}"
        );
        let lines: Vec<&str> = text
            .lines()
            .skip_while(|l| !l.starts_with("set-point maps: "))
            .skip(1)
            .take_while(|l| l.starts_with("  ") && l.contains(" rpm, L "))
            .collect();
        assert_eq!(lines.len(), cells.len(), "{text}");
        // (printed numbers within half a unit of their last digit)
        let num = |s: &str| s.trim().parse::<f64>().unwrap_or_else(|_| panic!("{s:?}"));
        for (line, c) in lines.iter().zip(&cells) {
            // "  N rpm, L x (y mg/cycle): u_egr <= X % ([set-point S %; ]reason)"
            let (n, rest) = line.split_once(" rpm, L ").unwrap();
            let (l, rest) = rest.split_once(" (").unwrap();
            let (u, rest) = rest.split_once(" mg/cycle): u_egr <= ").unwrap();
            let (lim, rest) = rest.split_once(" % (").unwrap();
            assert!((num(n) - c.n_e).abs() <= 0.5 + 1e-9, "{line}");
            assert!((num(l) - c.load).abs() <= 0.005 + 1e-9, "{line}");
            assert!((num(u) - c.u_delta).abs() <= 0.05 + 1e-9, "{line}: {c:?}");
            let want = (c.u_egr_max + beyond).min(100.0);
            assert!(
                (num(lim) - want).abs() <= 0.05 + 1e-9,
                "{line}: want {want}"
            );
            assert!((c.u_egr_limit - want).abs() < 1e-12, "{c:?}");
            if want != c.u_egr_max {
                let set = rest.strip_prefix("set-point ").unwrap();
                let (s, _) = set.split_once(" %; ").unwrap();
                assert!((num(s) - c.u_egr_max).abs() <= 0.05 + 1e-9, "{line}");
            }
            assert!(line.ends_with(&format!("{})", c.reason)), "{line}");
        }
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(d.path().join(out).join("stats.json")).unwrap(),
        )
        .unwrap();
        let js = json["setpoint_adjustments"].as_array().unwrap();
        assert_eq!(js.len(), cells.len());
        for (j, c) in js.iter().zip(&cells) {
            for (key, v) in [
                ("n_e", c.n_e),
                ("load", c.load),
                ("u_delta", c.u_delta),
                ("lambda_o_s", c.lambda_o_s),
                ("x_egr_s", c.x_egr_s),
                ("x_egr_max", c.x_egr_max),
                ("u_egr_max", c.u_egr_max),
                ("u_egr_limit", c.u_egr_limit),
            ] {
                let got = j[key].as_f64().unwrap_or_else(|| panic!("{key}: {j}"));
                assert!((got - v).abs() <= 1e-12 * v.abs().max(1.0), "{key}: {j}");
            }
            assert_eq!(j["reason"], c.reason.as_str());
        }
    }
}

/// Session 41: a VGT command range beyond the VGT area map's (`input_saturation.u_vgt = [5,
/// 95]`, the map fitted on the authors' 20-100 %) on the tip-in at 1200 rpm (100 -> 1500 Nm).
/// Before, the x_egr -> u_vgt loop kept closing the VGT with the EGR valve shut (no EGR flow
/// for it to act on) and held it at 5 %: p_em ran to 2.02 MPa, M_e fell to 344 Nm, torque slope
/// 0.32, work -61 %. Now the exhaust back-pressure limit (`dp_vgt_limit`, 350 kPa) opens the
/// VGT where the VGT loops close it beyond that: slope 0.96, work -3.4 %, p_em at most 0.59
/// MPa, as the same tip-in with the authors' range (slope 0.97, work -3.0 %), and a warning
/// says so. With the limit out of the way (1e4 kPa) the optional conditional integration
/// (`vgt_release_below_egr = 0.01`: the x_egr loop leaves the VGT's selector while the valve is
/// shut) alone lets the VGT reopen (it ends above 30 %; before it stayed at 5 %) but the torque
/// dips on the way (slope 0.82). Session 42: the VGT still reaches 8.4 % there, below the
/// authors' 20 % the published VGT map was fitted on; a warning names when and how far.
#[test]
fn a_vgt_range_beyond_the_map_does_not_wreck_a_tip_in() {
    let d = tempfile::tempdir().unwrap();
    write_published_with(
        d.path(),
        "wide.toml",
        &[("u_vgt = [20.0, 100.0]", "u_vgt = [5.0, 95.0]")],
    );
    std::fs::write(
        d.path().join("tip.csv"),
        "t,n_e,M_ref\n0,1200,100\n2,1200,100\n2.2,1200,1500\n8,1200,1500\n",
    )
    .unwrap();
    std::fs::write(
        d.path().join("off.toml"),
        "dp_vgt_limit = 1e4\nvgt_release_below_egr = 0.01\n",
    )
    .unwrap();
    // (stats.json, trajectory columns, stderr)
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec!["closed-loop", "--cycle", "tip.csv", "--out", out];
        args.extend_from_slice(extra);
        let o = mvem(d.path(), &args);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = std::fs::read_to_string(d.path().join(out).join("stats.json")).unwrap();
        let j: serde_json::Value = serde_json::from_str(&text).unwrap();
        let (h, rows) = read_csv(&d.path().join(out).join("trajectory.csv"));
        (j, h, rows, stderr(&o))
    };
    let column = |h: &[String], rows: &[Vec<f64>], name: &str| -> Vec<f64> {
        let c = col(h, name);
        rows.iter().map(|r| r[c]).collect()
    };
    let max = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let slope = |j: &serde_json::Value| j["stats"]["torque"]["slope"].as_f64().unwrap();
    let work = |j: &serde_json::Value| j["stats"]["work_error"].as_f64().unwrap();

    let (j, h, rows, err) = run("wide", &["--params", "wide.toml"]);
    let p_em = column(&h, &rows, "p_em");
    let p_im = column(&h, &rows, "p_im");
    let dp: Vec<f64> = p_em.iter().zip(&p_im).map(|(e, i)| e - i).collect();
    // tolerances: the measured 0.964 / -3.4 % / 0.593 MPa / 408 kPa with room for a retuning,
    // far from the failure (0.32 / -61 % / 2.02 MPa)
    assert!(slope(&j) > 0.93, "torque slope {}", slope(&j));
    assert!(work(&j) > -0.05, "work error {}", work(&j));
    assert!(max(&p_em) < 0.7e6, "p_em max {} Pa", max(&p_em));
    // the limit holds the back-pressure within 100 kPa of 350 kPa (p_em lags the VGT)
    assert!(max(&dp) < 450e3, "p_em - p_im max {} Pa", max(&dp));
    assert_eq!(j["controller_tuning"]["dp_vgt_limit"], 350.0);
    assert!(j["passes"].as_bool().unwrap(), "{}", j["violations"]);
    assert!(
        err.contains("the exhaust back-pressure limit (p_em - p_im at most dp_vgt_limit = 350 kPa) opened the VGT"),
        "{err}"
    );
    let warned = j["warnings"].as_array().unwrap();
    assert!(
        warned
            .iter()
            .any(|w| w.as_str().unwrap().contains("exhaust back-pressure limit")),
        "{warned:?}"
    );

    // session 42: the VGT command below the authors' 20 % (down to 8.4 % measured), where the
    // published VGT map is extrapolated, is warned about with the first time and value, the
    // number of such samples and the most closed command, as the trajectory has them
    let t = column(&h, &rows, "t");
    let u_vgt = column(&h, &rows, "u_vgt");
    let below: Vec<usize> = (0..t.len()).filter(|&i| u_vgt[i] < 20.0).collect();
    let lowest = u_vgt.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(lowest < 10.0, "{lowest}");
    let k = below[0];
    let note = format!(
        "the VGT command left 20-100 %, the range of the authors' data the published VGT map \
         (eq. (56)) was fitted on, at t = {} s ({:.1} %), at {} sample(s) in all, down to {:.1} %",
        (t[k] * 100.0).round() / 100.0,
        u_vgt[k],
        below.len(),
        lowest
    );
    assert!(err.contains(&note), "{note}\n{err}");
    assert!(
        warned.iter().any(|w| w.as_str().unwrap().contains(&note)),
        "{warned:?}"
    );

    // the authors' range: the limit does not act (no warning), the same tip-in figures
    let (j20, h20, rows20, err20) = run("authors", &[]);
    assert!(!err20.contains("back-pressure"), "{err20}");
    assert!(!err20.contains("the VGT command left"), "{err20}");
    // (p_em at most 0.40 MPa there)
    let p_em20 = max(&column(&h20, &rows20, "p_em"));
    assert!(p_em20 < 0.45e6, "{p_em20}");
    assert!(
        (slope(&j) - slope(&j20)).abs() < 0.03,
        "{} vs {}",
        slope(&j),
        slope(&j20)
    );
    assert!(
        (work(&j) - work(&j20)).abs() < 0.02,
        "{} vs {}",
        work(&j),
        work(&j20)
    );

    // the optional conditional integration alone: the VGT does not stay at its closed end with
    // the valve shut (without it, and without the limit: 5 % from 3.1 s to the end)
    let (j, h, rows, _) = run("off", &["--params", "wide.toml", "--tuning", "off.toml"]);
    let u_vgt = column(&h, &rows, "u_vgt");
    assert!(u_vgt.last().unwrap() > &30.0, "{:?}", u_vgt.last());
    assert!(slope(&j) > 0.7, "{}", slope(&j));
}

/// Session 41: a demand CSV may repeat a time (a step there, as `simulate --inputs` reads it;
/// before, "time must increase" and exit 2). The tip-in at 1200 rpm as a step at 2 s runs as the
/// same tip-in with a 10 ms ramp (2 -> 2.01 s), one sample earlier: from the step on, M_e, p_em,
/// p_im, x_egr and the commands of the step's sample k equal the ramp's sample k + 1 within 1e-6
/// of their scale (1500 Nm, 1e5 Pa, 1, 100 %; measured at most 2.7e-7: the loops are all but at
/// rest before the step, so the shift is the only difference; 1.6e-6 for u_vgt at 1.9 s, where
/// they still settle), and the torque regressions agree within 0.01. A third row at one time and a time going back
/// are refused naming the line.
#[test]
fn a_demand_may_repeat_a_time_as_a_step() {
    let d = tempfile::tempdir().unwrap();
    let head = "t,n_e,M_ref\n0,1200,100\n2,1200,100\n";
    std::fs::write(
        d.path().join("step.csv"),
        format!("{head}2,1200,1500\n5,1200,1500\n"),
    )
    .unwrap();
    std::fs::write(
        d.path().join("ramp.csv"),
        format!("{head}2.01,1200,1500\n5.01,1200,1500\n"),
    )
    .unwrap();
    let run = |cycle: &str| {
        let out = format!("{cycle}.out");
        let o = mvem(
            d.path(),
            &["closed-loop", "--cycle", cycle, "--out", &out, "--json"],
        );
        let j = json_of(&o);
        let (h, rows) = read_csv(&d.path().join(&out).join("trajectory.csv"));
        (j, h, rows)
    };
    let (js, h, step) = run("step.csv");
    let (jr, _, ramp) = run("ramp.csv");
    let slope = |j: &serde_json::Value| j["stats"]["torque"]["slope"].as_f64().unwrap();
    assert!(
        (slope(&js) - slope(&jr)).abs() < 0.01,
        "{} vs {}",
        slope(&js),
        slope(&jr)
    );
    let t = col(&h, "t");
    let k0 = step.iter().position(|r| r[t] >= 2.0 - 1e-9).unwrap();
    assert_eq!(step.len() + 1, ramp.len());
    let mut worst = 0.0_f64;
    for (name, scale) in [
        ("M_e", 1500.0),
        ("p_em", 1e5),
        ("p_im", 1e5),
        ("x_egr", 1.0),
        ("u_delta", 100.0),
        ("u_egr", 100.0),
        ("u_vgt", 100.0),
    ] {
        let c = col(&h, name);
        for k in k0..step.len() {
            let e = (step[k][c] - ramp[k + 1][c]).abs() / scale;
            assert!(
                e < 1e-6,
                "{name} at t = {}: {} vs {} (ramp at {})",
                step[k][t],
                step[k][c],
                ramp[k + 1][c],
                ramp[k + 1][t]
            );
            worst = worst.max(e);
        }
    }
    // the step reaches the demand at 2.00 s: the sample there already asks for 1500 Nm
    let m_ref = col(&h, "M_ref");
    let at2 = step.iter().position(|r| (r[t] - 2.0).abs() < 1e-9).unwrap();
    assert_eq!((step[at2 - 1][m_ref], step[at2][m_ref]), (100.0, 1500.0));
    eprintln!("largest difference {worst:e} of the scale");

    for (name, text, want) in [
        (
            "three.csv",
            format!("{head}2,1200,900\n2,1200,1500\n5,1200,1500\n"),
            "three.csv, line 5, column t: time 2 s is not monotonic (previous 2 s) (more than \
             two rows with the same time)",
        ),
        (
            "back.csv",
            format!("{head}1.5,1200,1500\n5,1200,1500\n"),
            "back.csv, line 4, column t: time 1.5 s is not monotonic (previous 2 s)",
        ),
    ] {
        std::fs::write(d.path().join(name), text).unwrap();
        let err = usage_error(d.path(), &["closed-loop", "--cycle", name, "--out", "o"]);
        assert!(err.contains(want), "{err}");
    }
    assert!(!d.path().join("o").exists());
}
