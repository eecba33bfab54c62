//! Set-point steps of the baseline air-path controller (docs/control.md): prints rise and
//! settling times for the default tuning, or for gains given as
//! `KEY=VALUE` arguments (x_vgt_kp, x_vgt_ki, x_egr_kp, x_egr_ki, l_egr_kp, l_egr_ki, l_vgt_kp,
//! l_vgt_ki, l_cap, and the gain schedules' vgt_closed, vgt_knee, egr_closed, egr_knee, and vgt_hold, the
//! EGR command below which the x_egr loop may not close the VGT), runs
//! the closed-loop WHTC with them when `whtc` is given, and with `grid` the steps x_egr,s +0.02
//! and lambda_O,s +0.2 from the set-point maps' values at 20 operating points (800-2000 rpm,
//! 40-180 mg), with a count of those that settle without a limit cycle.
//!
//! `cargo run --release -p mvem --example setpoint_steps -- x_vgt_ki=600 whtc`

use mvem::analysis::steady::steady_state;
use mvem::control::baseline::{Baseline, BaselineTuning};
use mvem::control::cycle::{whtc_demand, MappingCurve, MappingOptions};
use mvem::control::drive::whtc_table;
use mvem::control::stats::CycleStats;
use mvem::control::steps::setpoint_step;
use mvem::model::{AnyModel, Drive, Engine8, ModelOrder};
use mvem::params::Params;
use mvem::sim::stepper::plant_options;

fn main() {
    let mut tuning = BaselineTuning::default();
    let (mut whtc, mut grid, mut settle) = (false, false, false);
    for a in std::env::args().skip(1) {
        if a == "settle" {
            settle = true;
            continue;
        }
        if a == "whtc" {
            whtc = true;
            continue;
        }
        if a == "grid" {
            grid = true;
            continue;
        }
        let (k, v) = a.split_once('=').expect("KEY=VALUE");
        let v: f64 = v.parse().expect("number");
        match k {
            "x_vgt_kp" => tuning.x_egr_vgt.0 = v,
            "x_vgt_ki" => tuning.x_egr_vgt.1 = v,
            "x_egr_kp" => tuning.x_egr_egr.0 = v,
            "x_egr_ki" => tuning.x_egr_egr.1 = v,
            "l_egr_kp" => tuning.lambda_egr.0 = v,
            "l_egr_ki" => tuning.lambda_egr.1 = v,
            "l_vgt_kp" => tuning.lambda_vgt.0 = v,
            "l_vgt_ki" => tuning.lambda_vgt.1 = v,
            "l_cap" => tuning.lambda_error_cap = v,
            "vgt_closed" => tuning.vgt_gain_closed = v,
            "vgt_knee" => tuning.vgt_gain_knee = v,
            "egr_closed" => tuning.egr_gain_closed = v,
            "egr_knee" => tuning.egr_gain_knee = v,
            "vgt_hold" => tuning.vgt_hold_below_egr = v,
            _ => panic!("unknown key {k}"),
        }
    }
    let m = AnyModel::new(ModelOrder::Eight, Params::published(), Default::default()).unwrap();
    let curve = MappingCurve::compute(&m, MappingOptions::default()).unwrap();
    if settle {
        let pts: Vec<(f64, f64)> = match std::env::var("SETTLE_AT") {
            Ok(v) => v
                .split(',')
                .map(|p| {
                    let (n, u) = p.split_once(':').expect("N:U");
                    (n.parse().expect("rpm"), u.parse().expect("mg"))
                })
                .collect(),
            Err(_) => vec![
                (800.0, 180.0),
                (1100.0, 130.0),
                (1100.0, 180.0),
                (1400.0, 80.0),
            ],
        };
        for (n, u) in pts {
            settle_at(&m, &curve, tuning, n, u);
        }
        return;
    }
    let e8 = Engine8::published();
    let ss = steady_state(&e8, &Drive::new(1500.0, 110.0, 50.0, 60.0)).unwrap();
    let (l0, x0) = (ss.signals.lambda_o, ss.signals.x_egr);
    let x_star = steady_state(&e8, &Drive::new(1500.0, 110.0, 100.0, 50.0))
        .unwrap()
        .signals
        .x_egr;
    let cases = [
        ("x_egr", (l0, x0), (l0, x0 + 0.02)),
        ("lambda_O", (l0, x0), (l0 + 0.2, x0)),
        ("x_egr", (1.05, x_star), (1.05, x_star + 0.02)),
        ("x_egr", (1.05, x_star), (1.05, x_star - 0.02)),
    ];
    for (signal, before, after) in cases {
        match setpoint_step(
            &m, &curve, tuning, 1500.0, 110.0, before, after, signal, 10.0, 25.0,
        ) {
            Ok(r) => {
                let mt = r.metrics;
                println!(
                    "{signal:8} {before:.3?} -> {after:.3?}: {:.4} -> {:.4}, rise {:.2?} s, settling {:.2?} s, overshoot {:.1} %, tail p-p {:.1e}, u_egr/u_vgt {:.1?}",
                    mt.y0, mt.y_final, mt.rise_time, mt.settling_time, mt.overshoot_pct, r.tail_peak_to_peak, r.final_commands
                );
            }
            Err(e) => println!("{signal}: {e}"),
        }
    }
    if grid {
        step_grid(&m, &curve, tuning);
    }
    if whtc {
        let speeds = curve.reference_speeds(curve.n_e_range().0);
        let demand = whtc_demand(&whtc_table().unwrap(), &curve, &speeds).unwrap();
        let mut ctrl = Baseline::new(&m, &curve, tuning).unwrap();
        if std::env::var("NO_REACH").is_ok() {
            // the maps before session 39: no valve position set-point anywhere
            for row in &mut ctrl.maps.u_egr_max {
                row.iter_mut().for_each(|c| *c = 100.0);
            }
        }
        let t = std::time::Instant::now();
        let (traj, _) =
            mvem::control::run(m.clone(), &demand, &mut ctrl, &plant_options()).unwrap();
        let s = CycleStats::compute(&traj, curve.m_peak(), 1.2);
        println!(
            "WHTC: torque slope {:.3} R2 {:.3} SEE {:.1}; work {:+.2} %; lambda min {:.3}; x_egr rms {:.4}; pmep {:.0} Pa; bsfc {:.1}; violations {:?}; {:.2} s",
            s.torque.slope, s.torque.r2, s.torque.see, 100.0 * s.work_error, s.lambda_o_min,
            s.x_egr_rms_error, s.pmep_mean_pa, s.bsfc_g_kwh, s.violations(1.05), t.elapsed().as_secs_f64()
        );
        let ev = ctrl.windup_events();
        println!("windup events: {}", ev.len());
        for e in ev.iter().take(10) {
            println!("  {e}");
        }
    }
}

/// The set-point steps x_egr,s +0.02 and lambda_O,s +0.2 from the maps' set-points at a grid of
/// operating points; a step counts as settled when it settles into its 2 % band and the stepped
/// signal's last 2 s vary by less than 10 % of the step (no limit cycle).
fn step_grid(m: &AnyModel, curve: &MappingCurve, tuning: BaselineTuning) {
    let maps = Baseline::new(m, curve, tuning).unwrap().maps;
    for c in &maps.adjusted {
        println!(
            "adjusted cell {:.0} rpm L {:.2} ({:.1} mg): u_egr <= {:.1} % ({})",
            c.n_e, c.load, c.u_delta, c.u_egr_max, c.reason
        );
    }
    let (mut settled, mut total) = (0, 0);
    for n in [800.0, 1100.0, 1400.0, 1700.0, 2000.0] {
        for u in [40.0, 80.0, 130.0, 180.0] {
            let (l0, x0) = maps.setpoints(n, u);
            // before the step the maps' own set-points (NaN: with their valve position
            // set-point where the pair is out of reach), after it the stepped one given
            let maps_own = (f64::NAN, f64::NAN);
            // where the map's pair is out of reach lambda_O rests above lambda_O,s (the valve
            // held at its position set-point): the lambda_O step is then taken from the
            // lambda_O at rest, so that it moves the loop (a step from lambda_O,s would stay
            // below it)
            let rest = rest_lambda(m, &maps, tuning, n, u);
            let l_from = if maps.u_egr_max_at(n, u) < 100.0 {
                rest.max(l0)
            } else {
                l0
            };
            for (signal, after, du) in [
                ("x_egr", (f64::NAN, x0 + 0.02), 0.02),
                ("lambda_O", (l_from + 0.2, f64::NAN), 0.2),
            ] {
                total += 1;
                match setpoint_step(m, curve, tuning, n, u, maps_own, after, signal, 10.0, 25.0) {
                    Ok(r) => {
                        let ok =
                            r.metrics.settling_time.is_some() && r.tail_peak_to_peak < 0.1 * du;
                        settled += usize::from(ok);
                        let u_egr = r.traj.get("u_egr").unwrap();
                        let i_step = r.traj.get("t").unwrap().partition_point(|&t| t < 10.0);
                        println!(
                            "{n:6.0} rpm {u:5.0} mg {signal:8}: settling {:.2?} s, overshoot {:5.1} %, tail p-p {:.1e}, u_egr/u_egr(8-10 s) {:.1}/{:.1} %, u_egr/u_vgt {:.1?}{}",
                            r.metrics.settling_time, r.metrics.overshoot_pct, r.tail_peak_to_peak,
                            u_egr[i_step - 200], u_egr[i_step], r.final_commands,
                            if ok { "" } else { "  NOT SETTLED" }
                        );
                    }
                    Err(e) => println!("{n:6.0} rpm {u:5.0} mg {signal:8}: {e}"),
                }
            }
        }
    }
    println!("grid: {settled} of {total} steps settled");
}

/// The closed loop held at (n rpm, u mg) with the maps' set-points for 60 s, with the maps as
/// made (the valve's position set-point at cells out of reach) and without it (every cell
/// 100 %, the maps before session 39): the commands and signals at a few times.
fn settle_at(m: &AnyModel, curve: &MappingCurve, tuning: BaselineTuning, n: f64, u: f64) {
    use mvem::control::{run, Demand};
    let made = Baseline::new(m, curve, tuning).unwrap();
    let mut free = made.maps.clone();
    for row in &mut free.u_egr_max {
        row.iter_mut().for_each(|c| *c = 100.0);
    }
    for (label, maps) in [("adjusted", made.maps.clone()), ("no limit", free)] {
        let mut c = Baseline::with_maps(maps, tuning);
        c.fuel_override = u;
        let d = Demand::new(vec![0.0, 60.0], vec![n, n], vec![0.0; 2], vec![false; 2]).unwrap();
        let (traj, _) = run(m.clone(), &d, &mut c, &plant_options()).unwrap();
        let col = |k: &str| traj.get(k).unwrap().to_vec();
        let (t, ue, uv, l, x, ls, xs) = (
            col("t"),
            col("u_egr"),
            col("u_vgt"),
            col("lambda_O"),
            col("x_egr"),
            col("lambda_O_ref"),
            col("x_egr_ref"),
        );
        print!(
            "{n:.0} rpm {u:.0} mg {label}: set-points {:.3}/{:.4};",
            ls[1], xs[1]
        );
        for ts in [0.0, 5.0, 10.0, 20.0, 40.0, 59.99] {
            let i = t.partition_point(|&v| v < ts);
            print!(
                " t {ts:.0}: {:.1}/{:.1} % {:.3}/{:.4};",
                ue[i], uv[i], l[i], x[i]
            );
        }
        println!();
        for e in c.windup_events() {
            println!("  windup {e}");
        }
    }
}

/// lambda_O after 10 s of the closed loop at (n rpm, u mg) with the maps' own set-points.
fn rest_lambda(
    m: &AnyModel,
    maps: &mvem::control::baseline::SetpointMaps,
    tuning: BaselineTuning,
    n: f64,
    u: f64,
) -> f64 {
    use mvem::control::{run, Demand};
    let mut c = Baseline::with_maps(maps.clone(), tuning);
    c.fuel_override = u;
    let d = Demand::new(vec![0.0, 10.0], vec![n, n], vec![0.0; 2], vec![false; 2]).unwrap();
    let (traj, _) = run(m.clone(), &d, &mut c, &plant_options()).unwrap();
    *traj.get("lambda_O").unwrap().last().unwrap()
}
