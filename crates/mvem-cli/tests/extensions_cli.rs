//! End-to-end tests of the section-9 commands: `mvem compare-models` (Figs 11-14) against the
//! independent reference step data, `mvem te-study` (Fig. 2) against its own CSV, the 10/12-state
//! CSV and JSON outputs (each column name once), and bad input.

mod common;

use common::{col, files, mvem, read_csv, reference, stderr, stdout, usage_error};

#[test]
fn compare_models_matches_the_reference_and_reports_persistence() {
    let d = tempfile::tempdir().unwrap();
    let o = mvem(
        d.path(),
        &["compare-models", "--out", "cmp", "--rtol", "1e-7"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = d.path().join("cmp");
    assert_eq!(
        files(&dir),
        [
            "report.md",
            "vgt_step_30_to_25.csv",
            "vgt_step_30_to_25.png",
            "vgt_step_30_to_25.svg",
            "vgt_step_75_to_65.csv",
            "vgt_step_75_to_65.png",
            "vgt_step_75_to_65.svg",
            "vgt_steps_key.png",
            "vgt_steps_key.svg",
        ]
    );
    // the 8-state W_c of both steps against the independent reference implementation
    for step in ["75_to_65", "30_to_25"] {
        let (h, rows) = read_csv(&dir.join(format!("vgt_step_{step}.csv")));
        let (rh, rrows) = read_csv(&reference(&format!("step_vgt_{step}.csv")));
        assert_eq!(rows.len(), 801);
        assert_eq!(rows.len(), rrows.len());
        let (a, b) = (col(&h, "W_c_8"), col(&rh, "W_c"));
        for (r, rr) in rows.iter().zip(&rrows) {
            assert!(((r[a] - rr[b]) / rr[b]).abs() < 1e-4, "{step} t = {}", r[0]);
        }
        // the 10-state model starts on the same equilibrium; the 12-state one below it
        let (w10, w12) = (col(&h, "W_c_10"), col(&h, "W_c_12"));
        assert!(((rows[0][w10] - rows[0][a]) / rows[0][a]).abs() < 1e-8);
        assert!(rows[0][w12] < rows[0][a]);
        // p_c = p_im in the 8- and 10-state models, above it in the 12-state one
        assert_eq!(rows[0][col(&h, "p_c_8")], rows[0][col(&h, "p_im_8")]);
        assert!(rows[0][col(&h, "p_c_12")] > rows[0][col(&h, "p_im_12")]);
    }
    let out = stdout(&o);
    let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(out.starts_with(&report));
    for order in [8, 10, 12] {
        assert!(
            report.contains(&format!("| {order} states | yes | yes | yes |")),
            "{report}"
        );
    }
    assert!(report.contains("| p_im [Pa] | 149592.1"), "{report}");
    for f in ["vgt_step_75_to_65.png", "vgt_steps_key.png"] {
        let png = std::fs::read(dir.join(f)).unwrap();
        assert_eq!(&png[1..4], b"PNG");
    }
}

#[test]
fn compare_models_bad_input_exits_2_without_output() {
    let d = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--rtol", "0"], "--rtol 0"),
        (vec!["--dt", "0"], "--dt 0"),
    ] {
        let mut a = vec!["compare-models", "--out", "cmp"];
        a.extend(args);
        let err = usage_error(d.path(), &a);
        assert!(err.contains(needle), "{err}");
    }
    // k_ic = 0 cannot make a 12-state model: the message names the field
    let published = mvem(d.path(), &["params", "show"]);
    let toml = stdout(&published).replace("k_ic = 19000000.0", "k_ic = 0.0");
    assert!(toml.contains("k_ic = 0.0"));
    std::fs::write(d.path().join("p.toml"), toml).unwrap();
    let err = usage_error(
        d.path(),
        &["compare-models", "--out", "cmp", "--params", "p.toml"],
    );
    assert!(err.contains("k_ic"), "{err}");
    assert_eq!(files(d.path()), ["p.toml"]);
    for cmd in ["compare-models", "te-study"] {
        let o = mvem(d.path(), &[cmd, "--help"]);
        assert!(o.status.success());
        assert!(stdout(&o).contains("Examples:\n  mvem "), "{cmd}");
    }
}

#[test]
fn te_study_reports_the_largest_error_and_where() {
    let d = tempfile::tempdir().unwrap();
    // 30 s: a load step down and up again at 1200 rpm
    std::fs::write(
        d.path().join("in.csv"),
        "time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n\
         0,1200,150,30,50\n10,1200,150,30,50\n10.5,1200,20,30,50\n20,1200,20,30,50\n20.5,1200,180,30,50\n30,1200,180,30,50\n",
    )
    .unwrap();
    let o = mvem(
        d.path(),
        &[
            "te-study", "--inputs", "in.csv", "--out", "te", "--rtol", "1e-4",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let dir = d.path().join("te");
    assert_eq!(
        files(&dir),
        ["report.md", "te_study.csv", "te_study.png", "te_study.svg"]
    );
    let (h, rows) = read_csv(&dir.join("te_study.csv"));
    assert_eq!(rows.len(), 301);
    let (c, one, e) = (
        col(&h, "T_e_converged"),
        col(&h, "T_e_one_iteration"),
        col(&h, "rel_error"),
    );
    let mut worst = (0.0f64, 0.0);
    for r in &rows {
        assert!(((r[one] - r[c]) / r[c] - r[e]).abs() < 1e-15);
        if r[e].abs() > worst.0 {
            worst = (r[e].abs(), r[0]);
        }
    }
    // the load changes move T_e by hundreds of kelvin; the lagging iterate shows there
    assert!(worst.0 > 1e-6 && worst.0 < 1e-2, "{worst:?}");
    assert!(
        (10.0..11.5).contains(&worst.1) || (20.0..21.5).contains(&worst.1),
        "{worst:?}"
    );
    let out = stdout(&o);
    assert!(
        out.contains(&format!(
            "| max abs relative error of T_e | {:.3e}",
            worst.0
        )),
        "{out}"
    );
    assert!(
        out.contains(&format!("| at | t = {:.2} s", worst.1)),
        "{out}"
    );
    assert!(
        out.contains("| operating point there | n_e 1200 rpm"),
        "{out}"
    );

    let err = usage_error(d.path(), &["te-study", "--out", "te2", "--rtol", "2"]);
    assert!(err.contains("--rtol 2"), "{err}");
    assert!(!d.path().join("te2").exists());
}

#[test]
fn extension_outputs_name_each_column_once() {
    let d = tempfile::tempdir().unwrap();
    for model in ["10", "12"] {
        let out = format!("s{model}.csv");
        let o = mvem(
            d.path(),
            &[
                "simulate",
                "--scenario",
                "vgt-step-nmp",
                "--t-end",
                "1.5",
                "--model",
                model,
                "--out",
                &out,
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let (h, rows) = read_csv(&d.path().join(&out));
        let mut seen = std::collections::HashSet::new();
        for n in &h {
            assert!(seen.insert(n), "--model {model}: column {n} twice");
        }
        for n in ["T_im", "T_em", "W_c", "T_em_in"] {
            col(&h, n);
        }
        if model == "12" {
            col(&h, "p_c");
            col(&h, "T_ic");
        }
        // the start is the steady state: the manifold temperatures at their inflow values
        let r = &rows[0];
        assert!((r[col(&h, "T_em")] - r[col(&h, "T_em_in")]).abs() < 1e-6 * r[col(&h, "T_em")]);

        let steady = [
            "steady",
            "--n-e",
            "1500",
            "--u-delta",
            "110",
            "--u-egr",
            "80",
            "--u-vgt",
            "75",
            "--model",
            model,
        ];
        let o = mvem(d.path(), &[&steady[..], &["--json"]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let t_im = v["T_im"].as_f64().unwrap();
        assert!((t_im - 300.61857).abs() < 1e-4, "{t_im}");
        let tables = mvem(d.path(), &steady);
        let t = stdout(&tables);
        assert_eq!(t.matches("\n  T_em ").count(), 1, "{t}");
    }
}
