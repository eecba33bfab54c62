//! Loop margins along a closed-loop run: at every analysed sample of a [`Trajectory`] of the
//! baseline controller, the margins of the air-path loops that were in feedback at that sample
//! ([`InCharge`]: the main loop or the limiter of each command, none where the command sat at a
//! limit or the lambda_O error at its cap), around the steady state of the sample's commands
//! (a frozen operating point: the plant the loops would settle in if the commands stayed).
//! `mvem closed-loop --margins EVERY`, `docs/control.md`, "Loop margins along a cycle".
//!
//! Not in the analysis: the fuel path (the torque PI, the smoke limiter that makes u_delta a
//! function of lambda_O, the set-points' dependence on u_delta), the selectors' switching
//! itself (each sample is analysed with the loops it had) and the difference between the
//! trajectory's state and the steady state of its commands during transients.

use super::baseline::BaselineTuning;
use super::margins::{loop_analysis_json, margins_at, LoopAnalysis, LoopMargins, PiLoop};
use super::{InCharge, Trajectory};
use crate::model::{AnyModel, Drive};
use crate::numerics::cancel;
use crate::params::InputSaturation;
use rayon::prelude::*;

/// What the analysis found at one sample.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// No air-path loop was in feedback (both commands at a limit or without an error to feed
    /// back, or the sample had no loop code).
    NoLoop,
    /// The margins of the loops in feedback ([`LoopAnalysis`] without its frequency grids).
    Analysed(LoopAnalysis),
    /// The point could not be analysed (no steady state, a kink of the model the loops see):
    /// the reason.
    Refused(String),
}

/// One analysed sample.
#[derive(Debug, Clone, PartialEq)]
pub struct AlongPoint {
    /// Time of the sample \[s\].
    pub t: f64,
    /// The commands given at the sample and the engine speed (the frozen operating point).
    pub drive: Drive,
    /// Which loop gave u_egr.
    pub egr: Option<InCharge>,
    /// Which loop gave u_vgt.
    pub vgt: Option<InCharge>,
    /// The analysis.
    pub outcome: Outcome,
}

/// The baseline's loops in feedback for the given selector outcomes: lambda_O -> u_egr or the
/// limiter x_egr -> u_egr (its error x_egr,s + d_x - x_egr is r - y: gains negated in the
/// y - r convention of [`PiLoop`]); x_egr -> u_vgt or the limiter lambda_O -> u_vgt; each
/// with the gains of its schedule at the operating point's commands `d` (the EGR-valve loops'
/// at `d.u_egr_pct`, [`BaselineTuning::egr_gain_factor_in`]; the VGT loops' at `d.u_vgt_pct`,
/// [`BaselineTuning::vgt_gain_factor_in`]; each in the engine's command range of `limits`, the
/// parameter set's `input_saturation`, as the controller schedules them).
pub fn loops_in_charge(
    t: &BaselineTuning,
    egr: Option<InCharge>,
    vgt: Option<InCharge>,
    d: &Drive,
    limits: &InputSaturation,
) -> Vec<PiLoop> {
    let pi = |name: &str, input: &str, output: &str, (kp, ki): (f64, f64)| PiLoop {
        name: name.into(),
        input: input.into(),
        output: output.into(),
        kp,
        ki,
    };
    let mut loops = Vec::with_capacity(2);
    let g = t.egr_gain_factor_in(d.u_egr_pct, limits.egr());
    match egr {
        Some(InCharge::Main) => loops.push(pi(
            "lambda_O->u_egr",
            "u_egr",
            "lambda_O",
            (g * t.lambda_egr.0, g * t.lambda_egr.1),
        )),
        Some(InCharge::Limiter) => loops.push(pi(
            "x_egr->u_egr (limiter)",
            "u_egr",
            "x_egr",
            (-g * t.x_egr_egr.0, -g * t.x_egr_egr.1),
        )),
        Some(InCharge::None) | None => {}
    }
    let g = t.vgt_gain_factor_in(d.u_vgt_pct, limits.vgt());
    match vgt {
        Some(InCharge::Main) => loops.push(pi(
            "x_egr->u_vgt",
            "u_vgt",
            "x_egr",
            (g * t.x_egr_vgt.0, g * t.x_egr_vgt.1),
        )),
        Some(InCharge::Limiter) => loops.push(pi(
            "lambda_O->u_vgt (limiter)",
            "u_vgt",
            "lambda_O",
            (g * t.lambda_vgt.0, g * t.lambda_vgt.1),
        )),
        Some(InCharge::None) | None => {}
    }
    loops
}

/// The margins at every `every_s` seconds of `traj` (from its second row: the first has the
/// starting commands, given by no loop), with the loops in feedback at each sample, on all
/// cores. Errors: `every_s` not a positive number, a trajectory without the loop columns,
/// "cancelled" when the calling thread's token ([`crate::numerics::cancel`]) is cancelled.
pub fn along_trajectory(
    model: &AnyModel,
    traj: &Trajectory,
    tuning: &BaselineTuning,
    every_s: f64,
) -> Result<Vec<AlongPoint>, String> {
    if !(every_s.is_finite() && every_s > 0.0) {
        return Err(format!("every {every_s} s: must be a number > 0"));
    }
    let col = |name: &str| {
        traj.get(name)
            .ok_or_else(|| format!("the trajectory has no column {name}"))
    };
    let (t, n_e, u_delta) = (col("t")?, col("n_e")?, col("u_delta")?);
    let (u_egr, u_vgt) = (col("u_egr")?, col("u_vgt")?);
    let (egr, vgt) = (col("egr_loop")?, col("vgt_loop")?);
    let limits = model.params().input_saturation.clone();
    let rows: Vec<usize> = if t.len() < 2 {
        Vec::new()
    } else {
        // the first row at or after each multiple of every_s from the second row's time
        let t1 = t[1];
        let mut picked = Vec::new();
        let mut next = t1;
        for (k, &tk) in t.iter().enumerate().skip(1) {
            if tk >= next - 1e-9 * every_s.max(1.0) {
                picked.push(k);
                next = t1 + ((tk - t1) / every_s + 1e-9).floor() * every_s + every_s;
            }
        }
        picked
    };
    // on rayon's workers with the caller's cancellation token: a cancelled run stops before
    // its next sample (and inside the steady-state search of the current one)
    let points: Vec<AlongPoint> = rows
        .par_iter()
        .map(cancel::carry(|&k: &usize| {
            if cancel::requested() {
                return None;
            }
            let drive = Drive::new(n_e[k], u_delta[k], u_egr[k], u_vgt[k]);
            let (e, v) = (InCharge::from_code(egr[k]), InCharge::from_code(vgt[k]));
            let loops = loops_in_charge(tuning, e, v, &drive, &limits);
            let outcome = if loops.is_empty() {
                Outcome::NoLoop
            } else {
                match crate::dispatch!(model, m => margins_at(m, &drive, &loops, tuning.ts)) {
                    Ok((_, mut a)) => {
                        // the grids are 4 000 points per loop: not kept for every sample
                        a.f_hz = Vec::new();
                        a.l_alone = Vec::new();
                        a.l_others_closed = Vec::new();
                        Outcome::Analysed(a)
                    }
                    Err(e) => Outcome::Refused(e),
                }
            };
            Some(AlongPoint {
                t: t[k],
                drive,
                egr: e,
                vgt: v,
                outcome,
            })
        }))
        .collect::<Option<_>>()
        .filter(|_| !cancel::requested())
        .ok_or_else(|| "cancelled".to_string())?;
    Ok(points)
}

/// The extremes of one loop along the run (with the other loop closed where it ran).
#[derive(Debug, Clone, PartialEq)]
pub struct LoopExtremes {
    /// The loop's name.
    pub name: String,
    /// Samples analysed with it in feedback.
    pub points: usize,
    /// Of those, samples where the loop (with the other closed) is unstable.
    pub unstable: usize,
    /// Of those, samples where it has no effect (no EGR flow).
    pub inert: usize,
    /// Smallest gain margin and its sample's time \[s\].
    pub min_gain_margin: Option<(f64, f64)>,
    /// Smallest phase margin \[deg\] and its time \[s\].
    pub min_phase_margin_deg: Option<(f64, f64)>,
    /// Largest peak |1/(1+L)| and its time \[s\].
    pub max_peak_sensitivity: Option<(f64, f64)>,
}

/// What [`along_trajectory`]'s points add up to.
#[derive(Debug, Clone, PartialEq)]
pub struct AlongSummary {
    /// Samples looked at.
    pub points: usize,
    /// Of those, analysed.
    pub analysed: usize,
    /// Without a loop in feedback.
    pub no_loop: usize,
    /// Refused (the reasons are in the points).
    pub refused: usize,
    /// Times \[s\] of the analysed samples whose loops together are unstable.
    pub unstable_t: Vec<f64>,
    /// Analysed samples whose steady state is not physically valid (`steady_state_warnings`).
    pub invalid_steady: usize,
    /// Per loop name, in order of first appearance.
    pub loops: Vec<LoopExtremes>,
}

/// Sum up the points.
pub fn summarize(points: &[AlongPoint]) -> AlongSummary {
    let mut s = AlongSummary {
        points: points.len(),
        analysed: 0,
        no_loop: 0,
        refused: 0,
        unstable_t: Vec::new(),
        invalid_steady: 0,
        loops: Vec::new(),
    };
    // keep (v, t) in `cur` if v beats the value there (`lower`: smaller, else larger)
    let keep = |cur: &mut Option<(f64, f64)>, v: Option<f64>, t: f64, lower: bool| {
        if let Some(v) = v {
            if cur.is_none_or(|(c, _)| if lower { v < c } else { v > c }) {
                *cur = Some((v, t));
            }
        }
    };
    for p in points {
        let a = match &p.outcome {
            Outcome::NoLoop => {
                s.no_loop += 1;
                continue;
            }
            Outcome::Refused(_) => {
                s.refused += 1;
                continue;
            }
            Outcome::Analysed(a) => a,
        };
        s.analysed += 1;
        if !a.steady_state_warnings.is_empty() {
            s.invalid_steady += 1;
        }
        if a.max_pole_all >= 1.0 {
            s.unstable_t.push(p.t);
        }
        for (l, m) in a.loops.iter().zip(&a.others_closed) {
            let k = match s.loops.iter().position(|e| e.name == l.name) {
                Some(k) => k,
                None => {
                    s.loops.push(LoopExtremes {
                        name: l.name.clone(),
                        points: 0,
                        unstable: 0,
                        inert: 0,
                        min_gain_margin: None,
                        min_phase_margin_deg: None,
                        max_peak_sensitivity: None,
                    });
                    s.loops.len() - 1
                }
            };
            let e = &mut s.loops[k];
            e.points += 1;
            if m.inert {
                e.inert += 1;
                continue;
            }
            if !m.stable {
                e.unstable += 1;
                continue;
            }
            keep(&mut e.min_gain_margin, m.gain_margin, p.t, true);
            keep(&mut e.min_phase_margin_deg, m.phase_margin_deg, p.t, true);
            keep(
                &mut e.max_peak_sensitivity,
                Some(m.peak_sensitivity),
                p.t,
                false,
            );
        }
    }
    s
}

/// The CSV columns of [`points_csv`].
pub const CSV_COLUMNS: [&str; 23] = [
    "t",
    "n_e",
    "u_delta",
    "u_egr",
    "u_vgt",
    "egr_loop",
    "vgt_loop",
    "status",
    "stable",
    "max_pole",
    "egr_loop_name",
    "egr_gain_margin",
    "egr_gain_margin_hz",
    "egr_phase_margin_deg",
    "egr_delay_margin_s",
    "egr_peak_sensitivity",
    "vgt_loop_name",
    "vgt_gain_margin",
    "vgt_gain_margin_hz",
    "vgt_phase_margin_deg",
    "vgt_delay_margin_s",
    "vgt_peak_sensitivity",
    "steady_valid",
];

/// The points as CSV (header [`CSV_COLUMNS`]; the margins with the other loop closed; empty
/// where a figure does not exist; `status` analysed / no loop / refused: REASON (quoted by
/// the CSV rules where it holds a comma or a quote);
/// `steady_valid` 0 where the steady state of the commands is not physically valid).
pub fn points_csv(points: &[AlongPoint]) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    let num = |v: Option<f64>| v.map(|v| format!("{v}")).unwrap_or_default();
    // (writing to memory cannot fail)
    w.write_record(CSV_COLUMNS).expect("in memory");
    for p in points {
        let d = &p.drive;
        let mut cells = vec![
            format!("{}", p.t),
            format!("{}", d.n_e_rpm),
            format!("{}", d.u_delta_mg),
            format!("{}", d.u_egr_pct),
            format!("{}", d.u_vgt_pct),
            format!("{}", InCharge::code(p.egr)),
            format!("{}", InCharge::code(p.vgt)),
        ];
        match &p.outcome {
            Outcome::Analysed(a) => {
                cells.push("analysed".into());
                cells.push(if a.max_pole_all < 1.0 { "1" } else { "0" }.into());
                cells.push(format!("{}", a.max_pole_all));
                for input in ["u_egr", "u_vgt"] {
                    let k = a.loops.iter().position(|l| l.input == input);
                    let m: Option<&LoopMargins> = k.map(|k| &a.others_closed[k]);
                    cells.push(k.map(|k| a.loops[k].name.clone()).unwrap_or_default());
                    let f = |g: fn(&LoopMargins) -> Option<f64>| num(m.and_then(g));
                    cells.push(f(|m| m.gain_margin));
                    cells.push(f(|m| m.gain_margin_hz));
                    cells.push(f(|m| m.phase_margin_deg));
                    cells.push(f(|m| m.delay_margin_s));
                    cells.push(f(|m| Some(m.peak_sensitivity)));
                }
                let valid = a.steady_state_warnings.is_empty();
                cells.push(if valid { "1" } else { "0" }.into());
            }
            other => {
                cells.push(match other {
                    Outcome::Refused(r) => format!("refused: {r}"),
                    _ => "no loop".into(),
                });
                cells.resize(CSV_COLUMNS.len(), String::new());
            }
        }
        w.write_record(&cells).expect("in memory");
    }
    String::from_utf8(w.into_inner().expect("in memory")).expect("UTF-8 text")
}

/// The summary as JSON (`stats.json`'s `"margins"`): `every_s`, the counts, `unstable_t`,
/// `invalid_steady` (analysed samples at a physically invalid steady state), and
/// per loop {name, points, unstable, inert, min_gain_margin {value, t}, min_phase_margin_deg,
/// max_peak_sensitivity} (`null` where none).
pub fn summary_json(every_s: f64, s: &AlongSummary) -> serde_json::Value {
    let at = |v: Option<(f64, f64)>| {
        v.map(|(v, t)| serde_json::json!({"value": v, "t": t}))
            .unwrap_or(serde_json::Value::Null)
    };
    serde_json::json!({
        "every_s": every_s,
        "points": s.points,
        "analysed": s.analysed,
        "no_loop": s.no_loop,
        "refused": s.refused,
        "unstable_t": s.unstable_t,
        "invalid_steady": s.invalid_steady,
        "loops": s.loops.iter().map(|l| serde_json::json!({
            "name": l.name,
            "points": l.points,
            "unstable": l.unstable,
            "inert": l.inert,
            "min_gain_margin": at(l.min_gain_margin),
            "min_phase_margin_deg": at(l.min_phase_margin_deg),
            "max_peak_sensitivity": at(l.max_peak_sensitivity),
        })).collect::<Vec<_>>(),
    })
}

/// The points as JSON: per sample {t, n_e, u_delta, u_egr, u_vgt, egr_loop, vgt_loop (codes,
/// `null` for none), status ("analysed", "no loop", "refused"), reason (refused only), and
/// for an analysed sample the keys of `mvem margins --json` ([`loop_analysis_json`]: ts,
/// stable, max_pole_all, steady_state_warnings, loops [{name, input, output, kp, ki, alone,
/// others_closed}])}.
pub fn points_json(points: &[AlongPoint]) -> serde_json::Value {
    let code = |v: Option<InCharge>| {
        let c = InCharge::code(v);
        if c.is_nan() {
            serde_json::Value::Null
        } else {
            serde_json::json!(c)
        }
    };
    serde_json::Value::Array(
        points
            .iter()
            .map(|p| {
                let d = &p.drive;
                let mut v = serde_json::json!({
                    "t": p.t, "n_e": d.n_e_rpm, "u_delta": d.u_delta_mg, "u_egr": d.u_egr_pct,
                    "u_vgt": d.u_vgt_pct, "egr_loop": code(p.egr), "vgt_loop": code(p.vgt),
                });
                match &p.outcome {
                    Outcome::NoLoop => v["status"] = "no loop".into(),
                    Outcome::Refused(r) => {
                        v["status"] = "refused".into();
                        v["reason"] = r.as_str().into();
                    }
                    Outcome::Analysed(a) => {
                        v["status"] = "analysed".into();
                        // the analysis as `mvem margins --json` gives it
                        if let (Some(v), serde_json::Value::Object(a)) =
                            (v.as_object_mut(), loop_analysis_json(a))
                        {
                            v.extend(a);
                        }
                    }
                }
                v
            })
            .collect(),
    )
}
