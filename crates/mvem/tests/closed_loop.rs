//! Acceptance tests of the closed loop (issue 13): the WHTC with the baseline controllers meets
//! the regulation's torque regression limits, the positive work within +-5 % and the smoke
//! limit; the logged commands fed open-loop through `simulate` reproduce the plant; set-point
//! steps are stable.

use mvem::analysis::steady::steady_state;
use mvem::control::baseline::{Baseline, BaselineTuning};
use mvem::control::cycle::{whtc_demand, MappingCurve, MappingOptions};
use mvem::control::drive::whtc_table;
use mvem::control::stats::CycleStats;
use mvem::control::steps::setpoint_step;
use mvem::control::{run, Trajectory};
use mvem::model::{AnyModel, Drive, Engine8, ModelOrder};
use mvem::params::Params;
use mvem::sim::stepper::plant_options;
use mvem::sim::{InputSchedule, SimOptions};

fn model() -> AnyModel {
    AnyModel::new(ModelOrder::Eight, Params::published(), Default::default()).unwrap()
}

fn whtc_closed_loop(m: &AnyModel) -> (Trajectory, CycleStats) {
    let curve = MappingCurve::compute(m, MappingOptions::default()).unwrap();
    let speeds = curve.reference_speeds(curve.n_e_range().0);
    let demand = whtc_demand(&whtc_table().unwrap(), &curve, &speeds).unwrap();
    let mut ctrl = Baseline::new(m, &curve, BaselineTuning::default()).unwrap();
    // the plant's options, as `mvem closed-loop` runs it
    let (traj, solver) = run(m.clone(), &demand, &mut ctrl, &plant_options()).unwrap();
    eprintln!("{solver:?}");
    let stats = CycleStats::compute(&traj, curve.m_peak(), 1.2);
    (traj, stats)
}

/// The logged commands as a zero-order-hold schedule (a change at t_k is two rows at t_k).
fn commands_schedule(traj: &Trajectory) -> InputSchedule {
    let g = |n: &str| traj.get(n).unwrap();
    let (t, n, ud, ue, uv) = (g("t"), g("n_e"), g("u_delta"), g("u_egr"), g("u_vgt"));
    let mut times = vec![t[0]];
    let mut rows = vec![[n[0], ud[0], ue[0], uv[0]]];
    for k in 1..t.len() {
        let cur = [n[k], ud[k], ue[k], uv[k]];
        let last = *rows.last().unwrap();
        if cur != last {
            times.push(t[k]);
            rows.push(last);
            times.push(t[k]);
            rows.push(cur);
        }
    }
    InputSchedule::new(times, rows).unwrap()
}

#[test]
fn whtc_closed_loop_meets_the_regulation_and_is_the_real_model() {
    let m = model();
    let (traj, stats) = whtc_closed_loop(&m);
    eprintln!("{stats:#?}");
    let v = stats.violations(1.05);
    assert!(v.is_empty(), "violations: {v:?}");
    assert_eq!(traj.len(), 180_001);

    // the logged commands fed open-loop through simulate reproduce the plant
    let sched = commands_schedule(&traj);
    let e8 = Engine8::published();
    let t_end = *traj.get("t").unwrap().last().unwrap();
    let sol = mvem::analysis::steady::simulate_from_steady(
        &e8,
        &sched,
        0.0,
        t_end,
        &SimOptions::default(),
    )
    .unwrap();
    let mut worst = [0.0f64; 3];
    for (j, (name, scale)) in [("p_im", 1e5), ("p_em", 1e5), ("omega_t", 1e4)]
        .iter()
        .enumerate()
    {
        let a = traj.get(name).unwrap();
        let b = sol.get(name).unwrap();
        assert_eq!(a.len(), b.len());
        for i in 0..a.len() {
            worst[j] = worst[j].max((a[i] - b[i]).abs() / scale);
        }
    }
    eprintln!("open-loop replay: worst scaled deviation p_im, p_em, omega_t = {worst:?}");
    assert!(worst.iter().all(|w| *w < 2e-3), "{worst:?}");
}

/// Run the set-point steps `steps` at (1500 rpm, 110 mg) from `(l0, x0)`: each settles with no
/// limit cycle on the new set-point; rise and settling times printed for docs/control.md.
fn check_steps(m: &AnyModel, l0: f64, x0: f64, steps: &[(&str, (f64, f64))]) {
    let curve = MappingCurve::compute(m, MappingOptions::default()).unwrap();
    let tuning = BaselineTuning::default();
    for &(signal, after) in steps {
        let r = setpoint_step(
            m,
            &curve,
            tuning,
            1500.0,
            110.0,
            (l0, x0),
            after,
            signal,
            10.0,
            25.0,
        )
        .unwrap();
        let mt = &r.metrics;
        eprintln!(
            "{signal}: {:?} -> {:?}: from {:.4} to {:.4}, rise {:?} s, settling {:?} s, overshoot {:.1} %, tail p-p {:.2e}, final u_egr/u_vgt {:?}",
            (l0, x0), after, mt.y0, mt.y_final, mt.rise_time, mt.settling_time, mt.overshoot_pct, r.tail_peak_to_peak, r.final_commands
        );
        let target = if signal == "x_egr" { after.1 } else { after.0 };
        assert!(
            (mt.y_final - target).abs() < 0.02 * target.abs().max(0.1),
            "{signal} final {} vs {target}",
            mt.y_final
        );
        assert!(
            mt.settling_time.is_some_and(|s| s < 10.0),
            "{signal}: {mt:?}"
        );
        assert!(
            r.tail_peak_to_peak < 1e-3 * target.abs().max(0.1),
            "{signal}: limit cycle? {}",
            r.tail_peak_to_peak
        );
    }
}

#[test]
fn setpoint_steps_at_1500_rpm_110_mg_are_stable() {
    let m = model();
    // set-points reachable at this point: the steady state of the nominal actuator positions
    let e8 = Engine8::published();
    let ss = steady_state(&e8, &Drive::new(1500.0, 110.0, 50.0, 60.0)).unwrap();
    let (l0, x0) = (ss.signals.lambda_o, ss.signals.x_egr);
    check_steps(
        &m,
        l0,
        x0,
        &[("x_egr", (l0, x0 + 0.02)), ("lambda_O", (l0 + 0.2, x0))],
    );
}

#[test]
fn setpoint_steps_where_u_vgt_to_w_c_changes_sign_are_stable() {
    // With lambda_O,s low the EGR valve opens fully and the VGT alone holds x_egr. Pick x_egr,s
    // so that the VGT sits where the steady W_c(u_vgt) has its extremum: the DC gain
    // u_vgt -> W_c changes sign there (the paper's section 8.3.1, Figs 9-10).
    let e8 = Engine8::published();
    let w = |u_vgt: f64| {
        steady_state(&e8, &Drive::new(1500.0, 110.0, 100.0, u_vgt))
            .unwrap()
            .signals
    };
    let grid: Vec<f64> = (0..=24).map(|i| 25.0 + 2.5 * i as f64).collect();
    let wc: Vec<f64> = grid.iter().map(|&u| w(u).w_c).collect();
    let k = (1..grid.len() - 1)
        .find(|&k| (wc[k] - wc[k - 1]) * (wc[k + 1] - wc[k]) <= 0.0)
        .expect("W_c(u_vgt) has an extremum (sign reversal of the DC gain)");
    let u_star = grid[k];
    let x_star = w(u_star).x_egr;
    eprintln!("sign reversal of u_vgt -> W_c at u_vgt = {u_star} % (x_egr = {x_star:.4})");
    let m = model();
    check_steps(
        &m,
        1.05,
        x_star,
        &[
            ("x_egr", (1.05, x_star + 0.02)),
            ("x_egr", (1.05, x_star - 0.02)),
        ],
    );
}

#[test]
fn stepping_matches_the_open_loop_vgt_step() {
    // the plant of the closed loop = simulate, on the paper's VGT step (75 -> 65 % at 1 s)
    let e8 = Engine8::published();
    let d0 = Drive::new(1500.0, 110.0, 80.0, 75.0);
    let sched = InputSchedule::steps(d0, &[(1.0, 3, 65.0)]).unwrap();
    let sol =
        mvem::analysis::steady::simulate_from_steady(&e8, &sched, 0.0, 3.0, &SimOptions::default())
            .unwrap();
    let mut p =
        mvem::analysis::steady::plant_from_steady(e8, d0, 0.0, &SimOptions::default()).unwrap();
    let w = sol.get("W_c").unwrap();
    let span =
        w.iter().cloned().fold(f64::MIN, f64::max) - w.iter().cloned().fold(f64::MAX, f64::min);
    for k in 0..300 {
        let d = if k >= 100 {
            Drive {
                u_vgt_pct: 65.0,
                ..d0
            }
        } else {
            d0
        };
        let s = p.step(0.01, d).unwrap();
        assert!(
            (s.w_c - w[k + 1]).abs() < 1e-3 * span,
            "t = {}",
            (k + 1) as f64 * 0.01
        );
    }
}

/// The closed loop follows the engine the parameter set describes: the mapping curve, the
/// WHTC's denormalized speeds, the set-point maps' grid and the fuel limits come from its
/// `[input_saturation]`, not from the authors' 500-2000 rpm and 1-250 mg (before session 24 the
/// curve stopped at 2000 rpm and the cycle was squeezed into it whatever the engine).
#[test]
fn the_closed_loop_spans_the_parameter_sets_speed_and_fuel_range() {
    let published = MappingCurve::compute(&model(), MappingOptions::default()).unwrap();
    assert_eq!(published.n_e_range(), (500.0, 2000.0));
    assert_eq!(published.n_e.len(), 16); // 100 rpm steps
    let mut p = Params::published();
    p.input_saturation.n_e = [600.0, 2400.0];
    p.input_saturation.u_delta = [2.0, 200.0];
    let m = AnyModel::new(ModelOrder::Eight, p, Default::default()).unwrap();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    assert_eq!(curve.n_e_range(), (600.0, 2400.0));
    assert_eq!(curve.n_e.len(), 19);
    assert_eq!(curve.u_delta_range, (2.0, 200.0));
    // the full-load fuel stays inside the range, and reaches its top where the smoke limit
    // allows more (the published engine's curve goes above 200 mg)
    assert!(curve.u_full.iter().all(|&u| (2.0..=200.0).contains(&u)));
    assert!(published.u_full.iter().any(|&u| u > 200.0 + 1.0));
    assert!(curve.u_full.iter().any(|&u| (u - 200.0).abs() < 1e-9));
    // on the common speeds (600-2000 rpm) the motoring torque is the steady torque at 2 mg,
    // more than at 1 mg (less negative) by the indicated work of 1 mg
    for (k, &n) in curve.n_e.iter().enumerate().filter(|(_, &n)| n <= 2000.0) {
        let j = published.n_e.iter().position(|&x| x == n).unwrap();
        assert!(curve.m_motor[k] > published.m_motor[j], "{n} rpm");
    }
    // beyond 2000 rpm the curve is the model's, not the clamped 2000 rpm value
    let m2000 = curve.m_max_at(2000.0);
    let m2400 = curve.m_max_at(2400.0);
    assert!((m2400 - m2000).abs() > 1e-3 * m2000, "{m2000} {m2400}");
    // idle at the bottom of the range; the cycle's speeds inside the range
    let speeds = curve.reference_speeds(curve.n_e_range().0);
    assert_eq!(speeds.n_idle, 600.0);
    let demand = whtc_demand(&whtc_table().unwrap(), &curve, &speeds).unwrap();
    let ns: Vec<f64> = demand.times().iter().map(|&t| demand.at(t).n_e).collect();
    assert!(ns.iter().all(|&n| (600.0..=2400.0).contains(&n)));
    assert_eq!(ns.iter().cloned().fold(f64::MAX, f64::min), 600.0);
    // a demand outside the engine's range is refused, naming the row and its time
    let bad = mvem::control::cycle::Demand::new(
        vec![0.0, 1.0, 2.0],
        vec![1000.0, 2300.0, 2500.0],
        vec![0.0; 3],
        vec![false; 3],
    )
    .unwrap();
    assert!(bad.check_speeds(published.n_e_range()).is_err());
    let e = bad.check_speeds(curve.n_e_range()).unwrap_err().to_string();
    assert!(
        e.contains("row 3 (t = 2 s)") && e.contains("[600, 2400]"),
        "{e}"
    );
    // the baseline's set-point grid spans the range and its fuel limits are the set's
    let b = Baseline::new(&m, &curve, BaselineTuning::default()).unwrap();
    assert_eq!(b.maps.n_e.first(), Some(&600.0));
    assert_eq!(b.maps.n_e.last(), Some(&2400.0));
    assert_eq!(b.maps.u_delta_range, (2.0, 200.0));
}

/// Tunings at the edges of what `BaselineTuning::validate` accepts (the largest gains, the
/// strictest smoke limit, the widest bands) run a short speed/torque demand to its end or fail
/// with an error: never a panic, never a non-finite command. Before session 27 a smoke limit of
/// 9.9 or a torque gain of 1e308 passed the check and then panicked in the set-point maps or
/// the VGT limit.
#[test]
fn tunings_at_the_edges_of_the_accepted_ranges_run_or_fail_cleanly() {
    use mvem::control::cycle::Demand;
    let m = model();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    let demand = Demand::new(
        vec![0.0, 2.0, 4.0, 6.0],
        vec![1200.0, 1500.0, 1800.0, 900.0],
        vec![300.0, 1500.0, 200.0, 0.0],
        vec![false, false, false, true],
    )
    .unwrap();
    let base = BaselineTuning::default();
    let edges = [
        BaselineTuning {
            lambda_limit: 5.0,
            smoke_margin: 0.5,
            ..base
        },
        BaselineTuning {
            lambda_limit: 1.0,
            smoke_margin: 0.0,
            ..base
        },
        BaselineTuning {
            torque: (1e6, 1e6),
            x_egr_vgt: (1e6, 1e6),
            x_egr_egr: (1e6, 1e6),
            lambda_egr: (1e6, 1e6),
            lambda_vgt: (1e6, 1e6),
            ..base
        },
        BaselineTuning {
            torque: (0.0, 0.0),
            x_egr_vgt: (0.0, 0.0),
            x_egr_egr: (0.0, 0.0),
            lambda_egr: (0.0, 0.0),
            lambda_vgt: (0.0, 0.0),
            ..base
        },
        BaselineTuning {
            d_x: 1.0,
            d_lambda: 10.0,
            lambda_error_cap: 10.0,
            ..base
        },
        BaselineTuning {
            u_vgt_full_load: 20.0,
            ..base
        },
        BaselineTuning {
            u_vgt_full_load: 100.0,
            ..base
        },
    ];
    let mut finished = 0;
    for t in edges {
        t.validate().unwrap();
        let mut ctrl = Baseline::new(&m, &curve, t).unwrap();
        match run(m.clone(), &demand, &mut ctrl, &plant_options()) {
            Ok((traj, _)) => {
                finished += 1;
                let t_end = traj.get("t").unwrap().last().copied().unwrap();
                assert!(t_end >= 6.0 - 0.011, "ended at {t_end} s, {t:?}");
                for name in ["u_delta", "u_egr", "u_vgt", "M_e", "lambda_O"] {
                    let u = traj.get(name).unwrap();
                    assert!(u.iter().all(|v| v.is_finite()), "{name} not finite, {t:?}");
                }
            }
            Err(e) => assert!(!e.to_string().is_empty(), "{t:?}"),
        }
    }
    eprintln!("{finished} of {} edge tunings finished", edges.len());
    // the strictest smoke limit and the widest bands are ordinary tunings: they finish
    assert!(
        finished >= 5,
        "only {finished} of {} runs finished",
        edges.len()
    );
}

/// A user's normalized cycle (`CycleSource::Normalized`, read from a file as `mvem closed-loop
/// --cycle FILE` reads it) is denormalized exactly as the built-in WHTC: the WHTC's own table
/// written as a comma-separated file drives the same trajectory, bit for bit; a ramp between
/// two modes of a user's table (WHSC-like) follows the denormalized speed and torque.
#[test]
fn a_normalized_cycle_file_is_driven_as_the_built_in_whtc() {
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    use mvem::io::csv_demand::parse_cycle_file;
    let m = model();
    let text: String = std::iter::once("time,speed,torque".to_string())
        .chain(
            whtc_table()
                .unwrap()
                .iter()
                .map(|(t, n, q)| format!("{t},{n},{}", q.map_or("m".into(), |v| v.to_string()))),
        )
        .collect::<Vec<_>>()
        .join("\n");
    let file = parse_cycle_file(&text, std::path::Path::new("whtc.csv")).unwrap();
    assert!(matches!(file, CycleSource::Normalized(_)));
    let baseline = || Scheme::Baseline(BaselineTuning::default());
    let a = run_cycle(&m, CycleSource::Whtc, baseline(), Some(60.0)).unwrap();
    let b = run_cycle(&m, file, baseline(), Some(60.0)).unwrap();
    // bit for bit (the first row's loop codes are NaN)
    let bits = |t: &Trajectory| -> Vec<Vec<u64>> {
        t.columns
            .iter()
            .map(|c| c.iter().map(|v| v.to_bits()).collect())
            .collect()
    };
    assert!(bits(&a.traj) == bits(&b.traj), "the trajectories differ");
    assert_eq!(a.stats, b.stats);

    // a user's table: idle, a 20 s ramp to 55 % speed / 50 % torque, held
    let text = "Time [s]\tSpeed [%]\tTorque [%]\n0\t0\t0\n10\t0\t0\n30\t55\t50\n60\t55\t50\n";
    let CycleSource::Normalized(table) =
        parse_cycle_file(text, std::path::Path::new("modes.tsv")).unwrap()
    else {
        panic!("expected a normalized cycle")
    };
    let run = run_cycle(&m, CycleSource::Normalized(table.clone()), baseline(), None).unwrap();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    let speeds = curve.reference_speeds(curve.n_e_range().0);
    let n_55 = speeds.denormalize(55.0);
    let m_55 = 0.5 * curve.m_max_at(n_55);
    let col = |name: &str| {
        let k = Trajectory::NAMES.iter().position(|n| *n == name).unwrap();
        &run.traj.columns[k]
    };
    let (t, n_e, m_ref, m_e) = (col("t"), col("n_e"), col("M_ref"), col("M_e"));
    let last = t.len() - 1;
    assert!((t[last] - 60.0).abs() < 1e-9, "{}", t[last]);
    // the dynamometer holds the denormalized speed; the torque demand is half the full load
    assert!((n_e[last] - n_55).abs() < 1e-9, "{} vs {n_55}", n_e[last]);
    assert!(
        (m_ref[last] - m_55).abs() < 1e-6 * m_55,
        "{} vs {m_55}",
        m_ref[last]
    );
    // 30 s after the ramp the engine delivers it (the baseline's torque loop: within 1 %)
    assert!(
        (m_e[last] - m_55).abs() < 0.01 * m_55,
        "M_e {} vs {m_55}",
        m_e[last]
    );
    // the idle start: speed n_idle (the bottom of the range)
    assert!((n_e[0] - speeds.n_idle).abs() < 1e-9);
}

/// The trajectory's `egr_loop` / `vgt_loop` columns say which loop gave each command (1 main,
/// 2 limiter, 0 none in feedback): a command at its limit is no loop's, the lambda_O loop with
/// its error at the cap is none; the first row (the starting commands) and the open-loop
/// schedule have none (NaN). The loop margins along the run analyse exactly the loops in
/// feedback at each sample (`mvem closed-loop --margins`).
#[test]
fn the_loop_columns_name_the_loop_in_feedback_and_the_margins_follow_them() {
    use mvem::control::along::{along_trajectory, loops_in_charge, summarize, Outcome};
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    use mvem::control::InCharge;
    let m = model();
    let tuning = BaselineTuning::default();
    let run = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(tuning), Some(300.0)).unwrap();
    let traj = &run.traj;
    let g = |n: &str| traj.get(n).unwrap();
    let (u_egr, u_vgt, egr, vgt) = (g("u_egr"), g("u_vgt"), g("egr_loop"), g("vgt_loop"));
    let (lambda, lambda_ref) = (g("lambda_O"), g("lambda_O_ref"));
    let (n_e, u_delta) = (g("n_e"), g("u_delta"));
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    let maps = Baseline::new(&m, &curve, tuning).unwrap().maps;
    assert!(egr[0].is_nan() && vgt[0].is_nan());
    let mut seen = [[0usize; 3]; 2];
    for k in 1..traj.len() {
        let (e, v) = (InCharge::from_code(egr[k]), InCharge::from_code(vgt[k]));
        let (e, v) = (e.expect("a code"), v.expect("a code"));
        if u_egr[k] == 0.0 || u_egr[k] == 100.0 || u_vgt[k] == 20.0 {
            assert!(
                (u_egr[k] != 0.0 && u_egr[k] != 100.0) || e == InCharge::None,
                "row {k}: u_egr {} at a limit but {e:?}",
                u_egr[k]
            );
            assert!(u_vgt[k] != 20.0 || v == InCharge::None, "row {k}: {v:?}");
        }
        let lambda_err = lambda[k] - lambda_ref[k];
        match e {
            InCharge::Main => assert!(lambda_err < tuning.lambda_error_cap, "row {k}"),
            // the lambda_O loop's error at its cap, or the valve held at the maps' position
            // set-point where their pair is out of reach (session 39)
            InCharge::None if u_egr[k] > 0.0 && u_egr[k] < 100.0 => assert!(
                lambda_err >= tuning.lambda_error_cap
                    || u_egr[k] == maps.u_egr_max_at(n_e[k], u_delta[k]),
                "row {k}"
            ),
            _ => {}
        }
        for (c, x) in [(0, e), (1, v)] {
            seen[c][match x {
                InCharge::None => 0,
                InCharge::Main => 1,
                InCharge::Limiter => 2,
            }] += 1;
        }
    }
    // every case occurs in the first 300 s of the WHTC
    assert!(seen.iter().flatten().all(|&n| n > 0), "{seen:?}");

    let points = along_trajectory(&m, traj, &tuning, 20.0).unwrap();
    assert_eq!(points.len(), 15);
    assert!((points[0].t - 0.01).abs() < 1e-9 && (points[1].t - 20.01).abs() < 1e-9);
    for p in &points {
        let loops = loops_in_charge(&tuning, p.egr, p.vgt, &p.drive, &Default::default());
        match &p.outcome {
            Outcome::NoLoop => assert!(loops.is_empty()),
            Outcome::Analysed(a) => assert_eq!(a.loops, loops),
            Outcome::Refused(r) => panic!("t = {}: {r}", p.t),
        }
    }
    let s = summarize(&points);
    assert_eq!(s.points, s.analysed + s.no_loop + s.refused);
    assert!(s.analysed > 10, "{s:?}");
    // a cancelled caller (Python's Ctrl-C) gets an error, not a partial list
    let token = mvem::numerics::cancel::CancelToken::new();
    token.cancel();
    let r =
        mvem::numerics::cancel::with_token(&token, || along_trajectory(&m, traj, &tuning, 20.0));
    assert_eq!(r, Err("cancelled".to_string()));

    // the open-loop schedule: no loop
    let sched = mvem::io::csv_inputs::load_inputs_csv(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/whtc_inputs_10hz.csv"
    )))
    .unwrap();
    let open = run_cycle(&m, CycleSource::Whtc, Scheme::OpenLoop(sched), Some(5.0)).unwrap();
    assert!(open
        .traj
        .get("egr_loop")
        .unwrap()
        .iter()
        .all(|c| c.is_nan()));
}

/// The VGT loops' gain schedule (factor 0.5 at u_vgt = 20 %, 1 from 40 %: the default since
/// session 37) on the closed-loop WHTC: the regulation still passes and x_egr is held as well
/// (RMS error within 5 % of the unscheduled run's: 0.0228 against 0.0226), while the VGT command
/// moves less (total variation -24 %, reversals of its direction -47 % in this run; asserted:
/// -15 % and -30 %). The EGR-valve loops' optional schedule (0.5 at the shut valve, 1 from
/// 10 %) on top: the regulation passes, x_egr is held as well, and both commands move less than
/// with the VGT's schedule alone (reversals VGT 1 458 -> 1 210, EGR valve 1 106 -> 970 in this
/// run; asserted: -10 % and -5 %). The margins behind it: docs/control.md, "Gain scheduling of
/// the VGT loops" and "... of the EGR-valve loops".
#[test]
fn the_gain_schedules_calm_the_actuators_and_keep_the_regulation() {
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    let m = model();
    let plain = BaselineTuning::unscheduled();
    let scheduled = BaselineTuning {
        vgt_gain_closed: 0.5,
        vgt_gain_knee: 40.0,
        ..plain
    };
    assert_eq!(scheduled, BaselineTuning::default());
    let both = BaselineTuning {
        egr_gain_closed: 0.5,
        egr_gain_knee: 10.0,
        ..scheduled
    };
    // total variation [%] and direction reversals (moves above 0.01 %) of a command
    let motion_of = |traj: &Trajectory, name: &str| {
        let u = traj.get(name).unwrap();
        let (mut tv, mut reversals, mut last) = (0.0, 0usize, 0.0f64);
        for w in u.windows(2) {
            let d = w[1] - w[0];
            tv += d.abs();
            if d.abs() > 0.01 {
                if last != 0.0 && d.signum() != last {
                    reversals += 1;
                }
                last = d.signum();
            }
        }
        (tv, reversals)
    };
    let motion = |traj: &Trajectory| motion_of(traj, "u_vgt");
    let a = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(plain), None).unwrap();
    let b = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(scheduled), None).unwrap();
    assert!(b.violations.is_empty(), "{:?}", b.violations);
    let (ma, mb) = (motion(&a.traj), motion(&b.traj));
    eprintln!(
        "x_egr RMS error {} -> {}, VGT total variation {} -> {} %, reversals {} -> {}",
        a.stats.x_egr_rms_error, b.stats.x_egr_rms_error, ma.0, mb.0, ma.1, mb.1
    );
    assert!(b.stats.x_egr_rms_error < 1.05 * a.stats.x_egr_rms_error);
    assert!(mb.0 < 0.85 * ma.0, "{ma:?} -> {mb:?}");
    assert!((mb.1 as f64) < 0.7 * ma.1 as f64, "{ma:?} -> {mb:?}");
    // both schedules
    let c = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(both), None).unwrap();
    assert!(c.violations.is_empty(), "{:?}", c.violations);
    let mc = motion(&c.traj);
    let (eb, ec) = (motion_of(&b.traj, "u_egr"), motion_of(&c.traj, "u_egr"));
    eprintln!(
        "with the EGR-valve schedule: x_egr RMS error {}, VGT reversals {}, EGR reversals {} -> {}",
        c.stats.x_egr_rms_error, mc.1, eb.1, ec.1
    );
    assert!(c.stats.x_egr_rms_error < 1.05 * a.stats.x_egr_rms_error);
    assert!((mc.1 as f64) < 0.9 * mb.1 as f64, "{mb:?} -> {mc:?}");
    assert!((ec.1 as f64) < 0.95 * eb.1 as f64, "{eb:?} -> {ec:?}");
}

/// A run under the paper's plain equations is refused before anything is computed, with the
/// reason (no idle equilibrium, eq. (64)), not the mapping curve's settling failure; a duration
/// shorter than two samples is refused, one off the 10 ms grid runs the samples up to it and
/// says so.
#[test]
fn paper_semantics_and_durations_off_the_grid_are_named() {
    use mvem::components::Semantics;
    use mvem::control::drive::{run_cycle, CycleSource, Scheme, PAPER_SEMANTICS_REFUSED};
    use mvem::control::ControlError;
    use mvem::model::ModelOptions;
    let baseline = || Scheme::Baseline(BaselineTuning::default());
    let paper = AnyModel::new(
        ModelOrder::Eight,
        Params::published(),
        ModelOptions {
            semantics: Semantics::Paper,
            ..Default::default()
        },
    )
    .unwrap();
    match run_cycle(&paper, CycleSource::Whtc, baseline(), Some(1.0)) {
        Err(ControlError::Setup(m)) => assert_eq!(m, PAPER_SEMANTICS_REFUSED),
        other => panic!("{other:?}"),
    }
    let m = model();
    match run_cycle(&m, CycleSource::Whtc, baseline(), Some(0.005)) {
        Err(ControlError::Demand(e)) => assert!(e.contains("shorter than two"), "{e}"),
        other => panic!("{other:?}"),
    }
    let r = run_cycle(&m, CycleSource::Whtc, baseline(), Some(0.105)).unwrap();
    assert_eq!(r.traj.len(), 11);
    assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
    assert!(r.warnings[0].contains("not a multiple of the 0.01 s sample time"));
    let r = run_cycle(&m, CycleSource::Whtc, baseline(), Some(0.1)).unwrap();
    assert!(r.warnings.is_empty(), "{:?}", r.warnings);
}

/// How far the lambda_O set-point map departs from its rule between grid points: at the grid
/// points it is 0.9 x the steady lambda_O at the nominal actuator positions (at least the floor
/// 1.2 (1 + 2 x 0.02), at most 10); between them the bilinear interpolation of a quantity that
/// goes as 1 / u_delta at light load is not. Measured on a 4 x 4 sub-grid of every grid cell
/// (quarter steps in speed and load) where the rule is not at the floor or the cap (docs/control.md, "Set-point maps and
/// feed-forward", quotes the range printed here).
#[test]
fn the_lambda_setpoint_map_between_its_grid_points() {
    use mvem::control::baseline::{nominal_actuators, SetpointMaps};
    let m = model();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    let t = BaselineTuning::default();
    let maps = SetpointMaps::compute(&m, &curve, &t).unwrap();
    let e8 = Engine8::published();
    let floor = t.lambda_limit * (1.0 + 2.0 * t.smoke_margin);
    let u_min = maps.u_delta_range.0;
    let (mut lo, mut hi) = ((f64::INFINITY, 0.0, 0.0), (0.0, 0.0, 0.0));
    let mut at_grid: f64 = 0.0;
    for i in 0..maps.n_e.len() - 1 {
        for j in 0..maps.load.len() - 1 {
            let sub = [0.0, 0.25, 0.5, 0.75];
            for (a, b) in sub.iter().flat_map(|&a| sub.iter().map(move |&b| (a, b))) {
                let n = maps.n_e[i] + a * (maps.n_e[i + 1] - maps.n_e[i]);
                let l = maps.load[j] + b * (maps.load[j + 1] - maps.load[j]);
                let u = u_min + l * (maps.u_full_at(n) - u_min);
                let (ue, uv) = nominal_actuators(l);
                let Ok(ss) = steady_state(&e8, &Drive::new(n, u, ue, uv)) else {
                    continue;
                };
                let rule = 0.9 * ss.signals.lambda_o;
                if rule <= floor || rule >= 10.0 {
                    continue;
                }
                let r = maps.setpoints(n, u).0 / rule;
                if a == 0.0 && b == 0.0 {
                    at_grid = at_grid.max((r - 1.0).abs());
                    continue;
                }
                if r < lo.0 {
                    lo = (r, n, l);
                }
                if r > hi.0 {
                    hi = (r, n, l);
                }
            }
        }
    }
    eprintln!("set-point / rule between grid points: min {lo:?}, max {hi:?} (ratio, rpm, L)");
    assert!(
        at_grid < 1e-6,
        "at the grid points the rule holds: {at_grid}"
    );
    assert!(lo.0 > 0.5 && hi.0 < 1.5, "{lo:?} {hi:?}");
}

/// Between a motoring ("m") row and a fired row of a normalized cycle the torque demand runs
/// linearly from the motoring torque up to the fired row's, and the engine is fired there and
/// follows it. Before, the motoring flag of the "m" row was held until the fired row: the
/// controller gave the minimum fuel for that whole second while the demand rose to 80 % of the
/// full-load torque (QA: a 60 s cycle's tip-in out of motoring lagged the demand by 1 600 Nm;
/// on the WHTC 21.5 s of fired demand were motored, up to 1 840 Nm behind at t = 1238 s).
#[test]
fn a_tip_in_out_of_motoring_is_fired_as_the_demand_rises() {
    use mvem::control::cycle::Demand;
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    use mvem::io::csv_demand::parse_cycle_file;
    // the demand itself: motoring on an "m" row and between two, fired between "m" and fired
    let d = Demand::new(
        vec![0.0, 1.0, 2.0, 3.0, 4.0],
        vec![1000.0; 5],
        vec![-100.0, -100.0, -100.0, 900.0, 900.0],
        vec![true, true, true, false, false],
    )
    .unwrap();
    let flags: Vec<bool> = [-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 2.01, 2.5, 3.0, 3.5, 5.0]
        .iter()
        .map(|&t| d.at(t).motoring)
        .collect();
    assert_eq!(
        flags,
        [true, true, true, true, true, true, false, false, false, false, false]
    );
    assert_eq!(d.at(2.5).m_ref, 400.0);
    // and fired -> "m": fired until the "m" row, as before
    let d = Demand::new(
        vec![0.0, 1.0],
        vec![1000.0; 2],
        vec![900.0, -100.0],
        vec![false, true],
    )
    .unwrap();
    assert_eq!([d.at(0.5).motoring, d.at(1.0).motoring], [false, true]);

    // in closed loop: a load at 40 % speed, motoring for 5 s, then 80 % torque within 1 s
    let m = model();
    let text = "Time,Speed,Torque\n0,0,0\n5,40,50\n15,40,m\n20,40,m\n21,40,80\n26,40,80\n";
    let CycleSource::Normalized(table) =
        parse_cycle_file(text, std::path::Path::new("tip_in.csv")).unwrap()
    else {
        panic!("expected a normalized cycle")
    };
    let run = run_cycle(
        &m,
        CycleSource::Normalized(table),
        Scheme::Baseline(BaselineTuning::default()),
        None,
    )
    .unwrap();
    let col = |name: &str| {
        let k = Trajectory::NAMES.iter().position(|n| *n == name).unwrap();
        &run.traj.columns[k]
    };
    let (t, u_delta, mot, m_ref, m_e) = (
        col("t"),
        col("u_delta"),
        col("motoring"),
        col("M_ref"),
        col("M_e"),
    );
    let at = |x: f64| t.iter().position(|&v| (v - x).abs() < 1e-6).unwrap();
    // motored on the "m" rows and between them, at the minimum fuel
    assert_eq!((mot[at(17.0)], u_delta[at(17.0)]), (1.0, 1.0));
    assert_eq!(mot[at(20.0)], 1.0);
    // fired from the first sample after the "m" row on; fuel rises with the demand
    for x in [20.01, 20.5, 20.99] {
        assert_eq!(mot[at(x)], 0.0, "t = {x}");
    }
    assert!(u_delta[at(20.5)] > 20.0, "u_delta {} mg", u_delta[at(20.5)]);
    // at the fired row the torque is at least 60 % of the demand (turbo lag; before: the
    // motoring torque, about -200 Nm against 1 300 Nm)
    let k = at(21.0);
    eprintln!(
        "t 21: M_ref {} M_e {} u_delta {}",
        m_ref[k], m_e[k], u_delta[k]
    );
    assert!(
        m_e[k] > 0.6 * m_ref[k],
        "M_e {} vs M_ref {}",
        m_e[k],
        m_ref[k]
    );
    assert!(run.stats.torque.r2 > 0.88, "{:?}", run.stats.torque);
}

/// The largest closed-loop pole |z| of the air-path loops in feedback at the sample of `traj`
/// at time `t` \[s\] (the linearization at the steady state of that sample's commands, as
/// `--margins` does), with the sample's EGR command [%]; None: no loop in feedback.
fn pole_at(e8: &Engine8, traj: &Trajectory, tuning: &BaselineTuning, t: f64) -> Option<(f64, f64)> {
    use mvem::control::along::loops_in_charge;
    use mvem::control::margins::margins_at;
    use mvem::control::InCharge;
    let g = |n: &str| traj.get(n).unwrap();
    let k = g("t").iter().position(|&s| (s - t).abs() < 1e-6).unwrap();
    let d = Drive::new(g("n_e")[k], g("u_delta")[k], g("u_egr")[k], g("u_vgt")[k]);
    let (e, v) = (
        InCharge::from_code(g("egr_loop")[k]),
        InCharge::from_code(g("vgt_loop")[k]),
    );
    let loops = loops_in_charge(tuning, e, v, &d, &Default::default());
    if loops.is_empty() {
        return None;
    }
    let (_, a) = margins_at(e8, &d, &loops, tuning.ts).unwrap();
    Some((a.max_pole_all, d.u_egr_pct))
}

/// Session 38: the VGT hold near the shut EGR valve (`vgt_hold_below_egr`, off by default). At
/// the WHTC's fast instabilities of the default tuning (442, 1101 and 1436 s: the valve at
/// 0.1-0.4 % under the lambda_O loop, the VGT at 20-31 % under the x_egr loop) the two main
/// loops are in feedback together and unstable, the slowest mode growing by more than 0.5 % per
/// 10 ms sample (|z| 1.0135, 1.0193, 1.0161 measured; since session 39's valve position
/// set-points the default's run passes 1436 s with its loops stable, |z| 0.995, and the test
/// checks 442 and 1101 s): their pairing's relative gain is 0.007-0.03 there
/// (`examples/loop_interaction.rs`). With the hold at 5 % the x_egr loop does
/// not close the VGT there, and at the same samples of that run no loop pair is unstable. On
/// the whole cycle the regulation still passes, the mean p_em - p_im falls (19 781 -> 18 815 Pa
/// measured; asserted: at least 3 % lower) and x_egr is held about as well (RMS error 0.0228 ->
/// 0.0234; asserted: within 5 %). docs/control.md, "Session 38".
#[test]
fn the_vgt_hold_ends_the_fast_instabilities_at_the_shut_egr_valve() {
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    let m = model();
    let e8 = Engine8::published();
    let default = BaselineTuning::default();
    let hold = BaselineTuning {
        vgt_hold_below_egr: 5.0,
        ..default
    };
    let a = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(default), None).unwrap();
    let b = run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(hold), None).unwrap();
    assert!(b.violations.is_empty(), "{:?}", b.violations);
    // (1436.01 s too until session 39, whose valve position set-points made the default's
    // loops stable there)
    for t in [442.01, 1101.01] {
        let (z, u_egr) = pole_at(&e8, &a.traj, &default, t).expect("loops in feedback");
        assert!(
            z > 1.005 && u_egr < 1.0,
            "default, t = {t}: |z| {z}, u_egr {u_egr}"
        );
        let held = pole_at(&e8, &b.traj, &hold, t);
        eprintln!("t = {t}: default |z| {z} (u_egr {u_egr} %), with the hold {held:?}");
        assert!(held.is_none_or(|(z, _)| z < 1.0), "hold, t = {t}: {held:?}");
    }
    let (sa, sb) = (&a.stats, &b.stats);
    eprintln!(
        "PMEP {} -> {} Pa, x_egr RMS error {} -> {}",
        sa.pmep_mean_pa, sb.pmep_mean_pa, sa.x_egr_rms_error, sb.x_egr_rms_error
    );
    assert!(sb.pmep_mean_pa < 0.97 * sa.pmep_mean_pa);
    assert!(sb.x_egr_rms_error < 1.05 * sa.x_egr_rms_error);
}

/// The closed loop held at (n rpm, u mg) with the maps' own set-points (no override) for 40 s:
/// (u_egr, u_vgt) at every sample, and the windup events.
fn held_at_maps_setpoints(
    m: &AnyModel,
    maps: mvem::control::baseline::SetpointMaps,
    tuning: BaselineTuning,
    n: f64,
    u: f64,
) -> (Vec<f64>, Vec<f64>, Vec<f64>, usize) {
    let mut c = Baseline::with_maps(maps, tuning);
    c.fuel_override = u;
    let d = mvem::control::Demand::new(vec![0.0, 40.0], vec![n, n], vec![0.0; 2], vec![false; 2])
        .unwrap();
    let (traj, _) = run(m.clone(), &d, &mut c, &plant_options()).unwrap();
    let g = |k: &str| traj.get(k).unwrap().to_vec();
    (g("t"), g("u_egr"), g("u_vgt"), c.windup_events().len())
}

/// Session 39: at 800 rpm / 180 mg the maps' pair cannot be reached (p_em below p_im: no valve
/// position gives EGR, and lambda_O stays above lambda_O,s); the cells around it are reported
/// with the valve position set there, and the closed loop with the maps' set-points is at rest
/// within 2 s (both commands within 0.1 % from 2 s to 40 s), without a windup. The maps without
/// the valve position set-point (as before session 39) wind the valve open at about 2.6 %/s to
/// 100 % (a windup event; the valve moves more than 50 % after 2 s): what the test fails with
/// when the reachability check is taken out.
#[test]
fn an_unreachable_setpoint_pair_holds_the_valve_at_its_position_set_point() {
    let m = model();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    let maps = Baseline::new(&m, &curve, BaselineTuning::default())
        .unwrap()
        .maps;
    // 800 rpm lies between the 750 and 1000 rpm cells, 180 mg between L 0.75 and 1
    for n in [750.0, 1000.0] {
        for l in [0.75, 1.0] {
            let c = maps
                .adjusted
                .iter()
                .find(|c| c.n_e == n && c.load == l)
                .unwrap_or_else(|| panic!("cell {n} rpm L {l} not reported"));
            // the nominal valve position 50 (1 - L) is its position set-point
            assert!((c.u_egr_max - 50.0 * (1.0 - l)).abs() < 1e-12, "{c:?}");
            assert!(c.lambda_o_reached > c.lambda_o_s, "{c:?}");
            assert!(c.reason.contains("lambda_O"), "{}", c.reason);
        }
    }
    let cap = maps.u_egr_max_at(800.0, 180.0);
    assert!(cap > 0.0 && cap < 20.0, "{cap}");
    // the limit each cell reports is the controller's tuning's: the set-point itself by default,
    // the set-point + egr_open_beyond_setpoint within the valve's range for another tuning
    assert!(maps.adjusted.iter().all(|c| c.u_egr_limit == c.u_egr_max));
    let wider = BaselineTuning {
        egr_open_beyond_setpoint: 30.0,
        ..BaselineTuning::default()
    };
    let wide = Baseline::with_maps(maps.clone(), wider).maps;
    for c in &wide.adjusted {
        assert_eq!(c.u_egr_limit, (c.u_egr_max + 30.0).min(100.0), "{c:?}");
    }
    let band = |v: &[f64], t: &[f64], from: f64| {
        let i = t.partition_point(|&s| s < from);
        let w = &v[i..];
        w.iter().cloned().fold(f64::MIN, f64::max) - w.iter().cloned().fold(f64::MAX, f64::min)
    };
    let (t, ue, uv, windups) =
        held_at_maps_setpoints(&m, maps.clone(), BaselineTuning::default(), 800.0, 180.0);
    assert!(band(&ue, &t, 2.0) < 0.1, "u_egr p-p {}", band(&ue, &t, 2.0));
    assert!(band(&uv, &t, 2.0) < 0.1, "u_vgt p-p {}", band(&uv, &t, 2.0));
    assert!(
        (ue[ue.len() - 1] - cap).abs() < 0.5,
        "{} {cap}",
        ue[ue.len() - 1]
    );
    assert_eq!(windups, 0);
    // the maps without the valve position set-point: the valve winds open
    let mut free = maps.clone();
    for row in &mut free.u_egr_max {
        row.iter_mut().for_each(|c| *c = 100.0);
    }
    let (t, ue, uv, windups) =
        held_at_maps_setpoints(&m, free.clone(), BaselineTuning::default(), 800.0, 180.0);
    assert!(
        band(&ue, &t, 2.0) > 50.0,
        "u_egr p-p {}",
        band(&ue, &t, 2.0)
    );
    assert_eq!(ue[ue.len() - 1], 100.0);
    assert!(windups >= 1);
    // the same with the valve's command range ending at 80 % (a parameter set's
    // input_saturation.u_egr): wound to 80 %, and the windup is reported at that end (session
    // 41; before, the watch looked for 100 % and reported none)
    let mut narrow = free.clone();
    narrow.u_egr_range = (0.0, 80.0);
    let (tn, uen, _, windups_n) =
        held_at_maps_setpoints(&m, narrow, BaselineTuning::default(), 800.0, 180.0);
    assert!(
        band(&uen, &tn, 2.0) > 40.0,
        "u_egr p-p {}",
        band(&uen, &tn, 2.0)
    );
    assert_eq!(uen[uen.len() - 1], 80.0);
    assert!(windups_n >= 1, "no windup reported at the range's open end");
    // the tuning's switch back to that behaviour: the valve may open 100 % beyond its position
    // set-point, i.e. without limit: the same commands to the bit
    let open = BaselineTuning {
        egr_open_beyond_setpoint: 100.0,
        ..BaselineTuning::default()
    };
    let (t2, ue2, uv2, windups2) = held_at_maps_setpoints(&m, maps, open, 800.0, 180.0);
    assert_eq!((t2, ue2, uv2, windups2), (t, ue, uv, windups));
}

/// Session 42: the x_egr -> u_vgt loop's release while motored with p_em <= p_im
/// (`vgt_release_motored_band`, off by default). A fuel cut at 1000 rpm from 1 700 Nm (the
/// demand steps below the motoring torque at 10.01 s): the spinning turbo's boost outlasts the
/// exhaust's energy, p_em is below p_im and no EGR flows (0.2 s by default, where the closed VGT
/// lifts p_em; 1.1 s released), while x_egr,s jumps from 0 to 0.143. By default the x_egr loop holds the VGT at its closed end (20 %)
/// until 12 s and x_egr then overshoots its set-point (0.160 measured); released, the VGT is
/// the lambda_O limiter's (wide open at 10.1-11.1 s, since session 43's torque PI no longer
/// sends the fuel up to 28 mg after the cut, which brought lambda_O down to 11 near its bound
/// 10 for a few samples; 70 % at 11 s before) and the loop returns without a bump once p_em - p_im
/// exceeds the band (x_egr without overshoot, within 5 % of x_egr,s 1.7 s sooner; 1.4 s before session 43). Fired, the
/// option does not act even with p_em <= p_im (the first 10 s are the default's to the bit:
/// there closing the VGT is what raises p_em above p_im). docs/control.md, "Session 42".
#[test]
fn the_vgt_is_left_to_the_lambda_limiter_while_motored_without_egr_flow() {
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    use mvem::io::csv_demand::parse_cycle_file;
    let m = model();
    let text = "t,n_e,M_ref\n0,1000,1700\n10,1000,1700\n10.01,1000,-500\n25,1000,-500\n";
    let go = |tuning: BaselineTuning| {
        let src = parse_cycle_file(text, std::path::Path::new("tip_out.csv")).unwrap();
        assert!(matches!(src, CycleSource::Demand(_)));
        let run = run_cycle(&m, src, Scheme::Baseline(tuning), None).unwrap();
        let col = |name: &str| {
            let k = Trajectory::NAMES.iter().position(|n| *n == name).unwrap();
            run.traj.columns[k].clone()
        };
        let names = ["t", "u_vgt", "x_egr", "x_egr_ref", "p_em", "p_im"];
        let c: Vec<Vec<f64>> = names.iter().map(|n| col(n)).collect();
        c
    };
    let def = go(BaselineTuning::default());
    let rel = go(BaselineTuning {
        vgt_release_motored_band: 0.5,
        ..BaselineTuning::default()
    });
    let t = &def[0];
    let at = |x: f64| t.iter().position(|&v| (v - x).abs() < 1e-6).unwrap();
    // fired (up to 10 s, p_em - p_im down to -2 Pa at its end): the same commands to the bit
    let k10 = at(10.0);
    assert_eq!(def[1][..=k10], rel[1][..=k10]);
    // motored without EGR flow: p_em below p_im in both runs at 10.05 s (the default's closed
    // VGT lifts p_em above p_im by 10.5 s, the released run's after 11 s)
    let no_flow = |r: &[Vec<f64>], x: f64| {
        let k = at(x);
        assert!(
            r[4][k] < r[5][k],
            "t = {x}: p_em {} p_im {}",
            r[4][k],
            r[5][k]
        );
        assert!(r[2][k] < 1e-6, "t = {x}: x_egr {}", r[2][k]);
    };
    no_flow(&def, 10.05);
    for x in [10.05, 10.5, 11.0] {
        no_flow(&rel, x);
    }
    // the default's x_egr loop holds the VGT at its closed end; released, it is open
    for x in [10.2, 10.5, 11.0] {
        let k = at(x);
        assert!(def[1][k] <= 20.5, "default, t = {x}: u_vgt {} %", def[1][k]);
    }
    for x in [10.2, 10.5, 11.0] {
        let k = at(x);
        assert!(rel[1][k] > 99.0, "released, t = {x}: u_vgt {} %", rel[1][k]);
    }
    assert!(
        rel[1][at(11.5)] > 85.0,
        "released: u_vgt {} %",
        rel[1][at(11.5)]
    );
    // x_egr after the fuel cut: the default overshoots x_egr,s by more than 5 %, the release
    // not by more than 1 %; the release is within 5 % of x_egr,s from 14 s on, the default not
    let k = at(10.01);
    let x_s = rel[3][t.len() - 1];
    let peak = |r: &[Vec<f64>]| r[2][k..].iter().cloned().fold(f64::MIN, f64::max);
    assert!(
        peak(&def) > 1.05 * x_s,
        "default peak {} x_egr,s {x_s}",
        peak(&def)
    );
    assert!(
        peak(&rel) < 1.01 * x_s,
        "released peak {} x_egr,s {x_s}",
        peak(&rel)
    );
    let settled = |r: &[Vec<f64>]| (at(14.0)..t.len()).all(|i| (r[2][i] - x_s).abs() <= 0.05 * x_s);
    assert!(settled(&rel) && !settled(&def));
    // both back at the same rest (the loop's return is bumpless): VGT within 0.1 % at 25 s
    let kn = t.len() - 1;
    assert!(
        (def[1][kn] - rel[1][kn]).abs() < 0.1,
        "{} {}",
        def[1][kn],
        rel[1][kn]
    );
}

/// Session 42: with `vgt_release_below_egr = 0.01` (session 41's value) the WHTC has a fast
/// instability where the default has none: the valve command creeps off its shut end to just
/// above the release threshold, so the x_egr -> u_vgt loop is back in the VGT's selector (x_egr
/// 0 against x_egr,s 0.14) while the lambda_O loop holds the valve all but shut: the pair of
/// session 38. Since session 43 (the torque PI against the previous demand: a slightly
/// different fuel trajectory) that sample of the 1 s margin grid is 598.01 s (valve 0.095 %,
/// |z| 1.015 measured; the default's sample has the VGT at its 20 % end, the valve's lambda_O
/// loop alone and stable, |z| 0.984); it was 480.01 s (valve 0.099 %, |z| 1.027; the default
/// with no loop in feedback), where the valve now stays shut. A threshold of 0.5 % covers that
/// sample (loops stable or not in feedback there) and keeps the option's pumping gain (mean
/// p_em - p_im 7.4 % below the default's, asserted: 5 %) at an x_egr RMS error 1.5 % above the
/// default's (asserted: within 3 %). docs/control.md, "Session 42" and "Session 43".
#[test]
fn a_release_threshold_above_the_valves_creep_ends_the_instability_where_the_valve_creeps() {
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    let m = model();
    let e8 = Engine8::published();
    let with = |v: f64| BaselineTuning {
        vgt_release_below_egr: v,
        ..BaselineTuning::default()
    };
    let go =
        |t: BaselineTuning| run_cycle(&m, CycleSource::Whtc, Scheme::Baseline(t), None).unwrap();
    let (def, r001, r05) = (go(BaselineTuning::default()), go(with(0.01)), go(with(0.5)));
    let t = 598.01;
    let at_def = pole_at(&e8, &def.traj, &BaselineTuning::default(), t);
    assert!(at_def.is_none_or(|(z, _)| z < 1.0), "default: {at_def:?}");
    let (z, u_egr) = pole_at(&e8, &r001.traj, &with(0.01), t).expect("loops in feedback");
    assert!(
        z > 1.005 && (0.01..0.5).contains(&u_egr),
        "0.01 %: |z| {z}, u_egr {u_egr}"
    );
    let at05 = pole_at(&e8, &r05.traj, &with(0.5), t);
    eprintln!("t = {t}: 0.01 %: |z| {z} (u_egr {u_egr} %); 0.5 %: {at05:?}");
    assert!(at05.is_none_or(|(z, _)| z < 1.0), "0.5 %: {at05:?}");
    assert!(r05.violations.is_empty(), "{:?}", r05.violations);
    let (sd, s5) = (&def.stats, &r05.stats);
    assert!(s5.pmep_mean_pa < 0.95 * sd.pmep_mean_pa);
    assert!(s5.x_egr_rms_error < 1.03 * sd.x_egr_rms_error);
}

/// Session 43: a step of the torque demand moves the fuel by the feed-forward's step; the torque
/// PI does not kick at it. The torque measured at a sample answers the previous fuel command,
/// given for the previous sample's demand, and the PI compares the two; before, it compared the
/// new demand with that torque, read the whole step as a torque error for one sample (kp + ki
/// Ts = 0.04 mg/Nm: -68 mg for a 1 700 Nm step), drove the fuel to its minimum at a step down
/// and, when its tracking anti-windup had stored the clamped proportional part, sent it back up
/// at the next sample: at a fuel cut from 1 700 Nm at 1000 rpm 1 -> 28 -> 9.7 -> 1 mg/cycle.
/// At 1000, 1500 and 2000 rpm:
/// - fuel cuts (a demand below the motoring torque): the fuel never rises (tolerance 1e-9 mg)
///   and is at its minimum from the sample after the step at the latest (measured: from the
///   step's own sample; before, 28-36 mg at the next sample);
/// - every step: the fuel at the step's sample is the previous fuel plus the feed-forward's
///   change, limited to [u_min, smoke limit], within 0.5 mg (the PI's error before the step
///   is a steady one; before, 12-38 mg away at the steps down and the small tip-in, the
///   large tip-ins at the smoke limit);
/// - tip-ins: in the 0.2 s after the step the fuel falls only where the smoke limiter takes it
///   down (never more than 0.05 mg below min(previous fuel, smoke limit); before, 5.6-12.3 mg
///   below at the sample after the step).
///
/// Each of the 11 cases fails without the fix (checked with the PI's error against the new
/// demand).
///
/// docs/control.md, "Session 43".
#[test]
fn a_torque_demand_step_moves_the_fuel_by_the_feed_forward_without_a_kick() {
    use mvem::control::cycle::Demand;
    let m = model();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    let tuning = BaselineTuning::default();
    let base = Baseline::new(&m, &curve, tuning).unwrap();
    let (u_min, u_max) = base.maps.u_delta_range;
    let smoke = tuning.lambda_limit * (1.0 + tuning.smoke_margin);
    let t_step = 5.0;
    // (speed [rpm], torque before, torque after [Nm]), held 5 s, stepped at 5 s, held 1 s
    let cuts = [
        (1000.0, 1700.0, -500.0),
        (1500.0, 1700.0, -500.0),
        (2000.0, 1400.0, -500.0),
    ];
    let downs = [
        (1000.0, 1700.0, 100.0),
        (1500.0, 1700.0, 100.0),
        (2000.0, 1400.0, 100.0),
        (1500.0, 900.0, 600.0),
    ];
    let ups = [
        (1000.0, 100.0, 1700.0),
        (1500.0, 100.0, 1700.0),
        (2000.0, 100.0, 1400.0),
        (1500.0, 300.0, 600.0),
    ];
    let mut failures = Vec::new();
    for &(n, from, to) in cuts.iter().chain(&downs).chain(&ups) {
        let d = Demand::new(
            vec![0.0, t_step, t_step, t_step + 1.0],
            vec![n; 4],
            vec![from, from, to, to],
            vec![false; 4],
        )
        .unwrap();
        let mut ctrl = base.clone();
        let (traj, _) = run(m.clone(), &d, &mut ctrl, &plant_options()).unwrap();
        let (t, u, lam) = (
            traj.get("t").unwrap(),
            traj.get("u_delta").unwrap(),
            traj.get("lambda_O").unwrap(),
        );
        let k0 = t.iter().position(|&x| (x - t_step).abs() < 1e-9).unwrap();
        let case = format!("{n} rpm, {from} -> {to} Nm");
        // the smoke limiter's cap at sample k: the previous fuel at the measured lambda_O
        let u_smoke = |k: usize| u[k - 1] * lam[k] / smoke;
        // the step's sample: the previous fuel plus the feed-forward's change, limited
        let d_ff = base.maps.fuel_for_torque(n, to) - base.maps.fuel_for_torque(n, from);
        let hi = u_max.min(u_smoke(k0)).max(u_min);
        let expected = (u[k0 - 1] + d_ff).clamp(u_min, hi);
        eprintln!(
            "{case}: fuel {:.2} -> {:.2} (expected {expected:.2}) -> {:.2} -> {:.2} mg",
            u[k0 - 1],
            u[k0],
            u[k0 + 1],
            u[k0 + 2]
        );
        if (u[k0] - expected).abs() > 0.5 {
            failures.push(format!(
                "{case}: fuel at the step {} mg, the feed-forward's step gives {expected} mg",
                u[k0]
            ));
        }
        if to < curve.m_motor_at(n) {
            // a fuel cut: never up, at the minimum from the sample after the step
            for k in k0..u.len() {
                if u[k] > u[k - 1] + 1e-9 {
                    failures.push(format!(
                        "{case}: the fuel rises at t = {}: {} -> {} mg",
                        t[k],
                        u[k - 1],
                        u[k]
                    ));
                    break;
                }
            }
            if let Some(k) = (k0 + 1..u.len()).find(|&k| (u[k] - u_min).abs() > 1e-9) {
                failures.push(format!(
                    "{case}: fuel {} mg at t = {}, not the minimum {u_min} mg",
                    u[k], t[k]
                ));
            }
        }
        if to > from {
            // a tip-in: down only with the smoke limiter
            for k in k0 + 1..=k0 + 20 {
                let floor = u[k - 1].min(u_smoke(k));
                if u[k] < floor - 0.05 {
                    failures.push(format!(
                        "{case}: fuel {} mg at t = {}, below the previous {} mg and the smoke \
                         limit {} mg",
                        u[k],
                        t[k],
                        u[k - 1],
                        u_smoke(k)
                    ));
                    break;
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
