//! JSON objects of the analysis results, shared by every front end (`mvem steady --json`,
//! `mvem linearize --json`, the HTTP API of `mvem serve`) so that they print the same numbers to
//! the last bit. `serde_json` writes every `f64` in its shortest round-trip form.

use crate::analysis::discrete::DiscreteModel;
use crate::analysis::experiment::{OutputError, StepSpec};
use crate::analysis::linearize::LinearModel;
use crate::analysis::steady::SteadyState;
use crate::analysis::step::{Excursion, StepError, StepMetrics};
use crate::analysis::zeros::{
    dc_gain_matrix, eigenvalues, mimo_zeros, poles, siso, Complex, ZeroOptions, MIMO_INPUTS,
    MIMO_OUTPUTS,
};
use crate::model::{Drive, Model, Signals};
use nalgebra::DMatrix;
use serde_json::{json, Map, Value};

/// Unit of a state, signal or input column (the core metadata, [`crate::model::meta::unit`]).
pub use crate::model::meta::unit;

/// The operating point `{"n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct"}`.
pub fn drive_json(d: &Drive) -> Value {
    json!({
        "n_e_rpm": d.n_e_rpm,
        "u_delta_mg": d.u_delta_mg,
        "u_egr_pct": d.u_egr_pct,
        "u_vgt_pct": d.u_vgt_pct,
    })
}

/// The flat JSON object of a steady state (`mvem steady --json`): every state and signal by
/// name, `physically_valid`, `flags`, `eigenvalues` [{re, im}], `inputs`, `residual`.
pub fn steady_json<const N: usize, M: Model<N>>(m: &M, ss: &SteadyState<N>) -> Value {
    let mut o = Map::new();
    for (n, v) in m.state_names().iter().zip(ss.x) {
        o.insert(n.to_string(), json!(v));
    }
    // T_im, T_em, p_c are states of the 10/12-state models: keep the state value
    for (n, v) in Signals::NAMES.iter().zip(ss.signals.values()) {
        o.entry(n.to_string()).or_insert(json!(v));
    }
    o.insert("physically_valid".into(), json!(ss.physically_valid()));
    o.insert("flags".into(), json!(ss.flags));
    o.insert(
        "eigenvalues".into(),
        Value::Array(
            ss.eigenvalues
                .iter()
                .map(|(re, im)| json!({"re": re, "im": im}))
                .collect(),
        ),
    );
    o.insert("inputs".into(), drive_json(&ss.drive));
    o.insert("residual".into(), json!(ss.residual));
    Value::Object(o)
}

fn cjson(z: &Complex<f64>) -> Value {
    json!({"re": z.re, "im": z.im})
}

fn rows(m: &DMatrix<f64>) -> Value {
    Value::Array(
        (0..m.nrows())
            .map(|i| json!((0..m.ncols()).map(|j| m[(i, j)]).collect::<Vec<f64>>()))
            .collect(),
    )
}

fn state_unit(name: &str) -> &'static str {
    if name.starts_with("pade_") || name.ends_with(')') {
        "%"
    } else {
        unit(name)
    }
}

/// Input units in [`crate::analysis::linearize`]'s input order (u_delta, u_egr, u_vgt, n_e).
const INPUT_UNITS: [&str; 4] = ["mg/cycle", "%", "%", "rpm"];

/// The frequency response as JSON: `{"f_hz": [...], "delays_s": {"u_egr", "u_vgt"},
/// "channels": {"u_vgt->W_c": {"mag": [...], "phase_deg": [...], "re": [...], "im": [...]}, ...}}`,
/// one channel per input and output (magnitude in output unit per input unit, the phase
/// continuous along the frequencies).
pub fn frequency_response_json(fr: &crate::analysis::frequency::FrequencyResponse) -> Value {
    let mut channels = serde_json::Map::new();
    for input in &fr.input_names {
        for output in &fr.output_names {
            let (Some(g), Some((mag, phase))) =
                (fr.channel(input, output), fr.magnitude_phase(input, output))
            else {
                continue;
            };
            channels.insert(
                format!("{input}->{output}"),
                json!({
                    "mag": mag,
                    "phase_deg": phase,
                    "re": g.iter().map(|z| z.re).collect::<Vec<_>>(),
                    "im": g.iter().map(|z| z.im).collect::<Vec<_>>(),
                }),
            );
        }
    }
    json!({
        "f_hz": fr.f_hz,
        "delays_s": {"u_egr": fr.delays[0], "u_vgt": fr.delays[1]},
        "channels": channels,
    })
}

/// The JSON object of a sampled linear model (`mvem linearize --ts`, the `"discrete"` key):
/// `"ts"`, `"Phi"`, `"Gamma"`, `"C"`, `"D"` (lists of rows), `"state_names"` (the model's states,
/// then the delay registers `u_egr(k-1)`, ...), `"state_units"`, `"input_names"`,
/// `"output_names"`, `"delays_s"`, `"delay_samples"` ({u_egr, u_vgt}: {"whole", "remainder_s"}),
/// `"poles"` (eigenvalues of Phi, {re, im}; the registers' poles are 0).
pub fn discrete_model_json(dm: &DiscreteModel) -> Value {
    // Phi = [[Phi_x, G], [0, shift]] is block upper triangular and the shift registers are
    // nilpotent: the poles are those of Phi_x and one 0 per register (exact zeros, which an
    // eigenvalue solver would return as roots of rounding, ~1e-8, the block being defective)
    let n = dm.continuous.n_states();
    let s = &dm.state_scales;
    // eigenvalues in the scaled coordinates (the same values, better conditioned), by the
    // routine of the continuous poles (balancing, real Schur form); null if it fails, as they
    let scaled = DMatrix::from_fn(n, n, |i, j| dm.phi[(i, j)] * s[j] / s[i]);
    let poles = match eigenvalues(&scaled) {
        Ok(p) => Value::Array(
            p.iter()
                .map(cjson)
                .chain((n..dm.n_states()).map(|_| json!({"re": 0.0, "im": 0.0})))
                .collect(),
        ),
        Err(_) => Value::Null,
    };
    let ds =
        |q: usize| json!({"whole": dm.delay_samples[q].0, "remainder_s": dm.delay_samples[q].1});
    json!({
        "ts": dm.ts,
        "Phi": rows(&dm.phi),
        "Gamma": rows(&dm.gamma),
        "C": rows(&dm.c),
        "D": rows(&dm.d),
        "state_names": dm.state_names,
        "state_units": dm.state_names.iter().map(|n| state_unit(n)).collect::<Vec<_>>(),
        "input_names": dm.input_names,
        "output_names": dm.output_names,
        "delays_s": {"u_egr": dm.delays[0], "u_vgt": dm.delays[1]},
        "delay_samples": {"u_egr": ds(0), "u_vgt": ds(1)},
        "poles": poles,
    })
}

/// The JSON object of a linear model at the steady state `ss` (`mvem linearize --json`):
/// matrices, poles, the transmission zeros of every SISO channel and of the MIMO system, DC
/// gains, names, units, kinks.
pub fn linear_model_json<const N: usize>(lin: &LinearModel, ss: &SteadyState<N>) -> Value {
    linear_json(lin, &ss.drive, ss.physically_valid(), &ss.flags, true)
}

/// [`linear_model_json`] at any point: the inputs `d`, whether the point is physically valid
/// and its flags (the active guards; `mvem linearize --state`). Away from a steady state the
/// poles and zeros are those of the frozen linear model, and `"dx0"` (the derivatives at the
/// point) is not zero.
pub fn linear_model_json_at(
    lin: &LinearModel,
    d: &Drive,
    physically_valid: bool,
    flags: &[String],
) -> Value {
    linear_json(lin, d, physically_valid, flags, false)
}

/// The object of both: `"steady_state"` says whether the point is an equilibrium.
fn linear_json(
    lin: &LinearModel,
    d: &Drive,
    physically_valid: bool,
    flags: &[String],
    steady: bool,
) -> Value {
    let zo = ZeroOptions::default();
    let mut o = Map::new();
    o.insert("operating_point".into(), drive_json(d));
    o.insert("steady_state".into(), json!(steady));
    o.insert("physically_valid".into(), json!(physically_valid));
    o.insert("flags".into(), json!(flags));
    o.insert("dx0".into(), json!(lin.dx0));
    o.insert("pade_order".into(), json!(lin.pade_order));
    o.insert(
        "delays_s".into(),
        json!({"u_egr": lin.delays[0], "u_vgt": lin.delays[1]}),
    );
    o.insert("state_names".into(), json!(lin.state_names));
    o.insert("input_names".into(), json!(lin.input_names));
    o.insert("output_names".into(), json!(lin.output_names));
    o.insert(
        "units".into(),
        json!({
            "states": lin.state_names.iter().map(|s| state_unit(s)).collect::<Vec<_>>(),
            "inputs": INPUT_UNITS,
            "outputs": lin.output_names.iter().map(|s| unit(s)).collect::<Vec<_>>(),
            "time": "s",
            "dc_gain": "output unit per input unit",
        }),
    );
    o.insert("x0".into(), json!(lin.x0));
    o.insert("y0".into(), json!(lin.y0));
    o.insert("A".into(), rows(&lin.a));
    o.insert("B".into(), rows(&lin.b));
    o.insert("C".into(), rows(&lin.c));
    o.insert("D".into(), rows(&lin.d));
    o.insert(
        "eigenvalues".into(),
        match poles(lin) {
            Ok(p) => Value::Array(p.iter().map(cjson).collect()),
            Err(_) => Value::Null,
        },
    );
    let mut zeros = Map::new();
    let mut errors = Map::new();
    for i in &lin.input_names {
        for out in &lin.output_names {
            let key = format!("{i}->{out}");
            match siso(lin, i, out, &zo) {
                Ok(c) => {
                    zeros.insert(
                        key,
                        Value::Array(c.zeros.finite.iter().map(cjson).collect()),
                    );
                }
                Err(e) => {
                    zeros.insert(key.clone(), Value::Null);
                    errors.insert(key, json!(e.to_string()));
                }
            }
        }
    }
    match mimo_zeros(lin, &MIMO_INPUTS, &MIMO_OUTPUTS, &zo) {
        Ok(z) => {
            zeros.insert(
                "MIMO".into(),
                Value::Array(z.finite.iter().map(cjson).collect()),
            );
        }
        Err(e) => {
            zeros.insert("MIMO".into(), Value::Null);
            errors.insert("MIMO".into(), json!(e.to_string()));
        }
    }
    o.insert("zeros".into(), Value::Object(zeros));
    o.insert(
        "mimo".into(),
        json!({"inputs": MIMO_INPUTS, "outputs": MIMO_OUTPUTS}),
    );
    if !errors.is_empty() {
        o.insert("zero_errors".into(), Value::Object(errors));
    }
    o.insert(
        "dc_gain".into(),
        match dc_gain_matrix(lin) {
            Ok(g) => rows(&g),
            Err(_) => Value::Null,
        },
    );
    o.insert(
        "kinks".into(),
        json!(lin.kinks.iter().map(|k| k.to_string()).collect::<Vec<_>>()),
    );
    o.insert(
        "one_sided".into(),
        json!(lin
            .one_sided
            .iter()
            .map(|k| k.to_string())
            .collect::<Vec<_>>()),
    );
    Value::Object(o)
}

fn opt(v: Option<f64>) -> Value {
    v.map_or(Value::Null, |x| json!(x))
}

fn excursion(e: Option<Excursion>) -> Value {
    e.map_or(
        Value::Null,
        |e| json!({"value": e.value, "time": e.time, "relative": e.relative}),
    )
}

/// The step experiment (`mvem step --json`, `/api/step` of `mvem serve`, which adds the
/// series): the stepped input with its unit, from, to, t_step, the operating point before the
/// step, the steady-state warnings and, per output, its metrics (or why there are none) and unit.
pub fn step_json(
    spec: &StepSpec,
    warnings: &[String],
    metrics: &[(String, Result<StepMetrics, OutputError>)],
) -> Value {
    let mut outs = Map::new();
    for (n, r) in metrics {
        let mut v = match r {
            Ok(m) => step_metrics_json(m),
            // no direction, but the steady values and the gain (0, or the rounding of the
            // steady states) are known
            Err(OutputError::Metrics(e @ StepError::NoChange { y0, y_final, .. })) => json!({
                "error": e.to_string(),
                "y0": y0,
                "y_final": y_final,
                "change": y_final - y0,
                "dc_gain": e.dc_gain(),
            }),
            Err(e) => json!({"error": e.to_string()}),
        };
        v["unit"] = json!(unit(n));
        outs.insert(n.clone(), v);
    }
    let input = Drive::NAMES[spec.input];
    json!({
        "input": input,
        "input_unit": unit(input),
        "from": spec.from(),
        "to": spec.to,
        "t_step": spec.t_step,
        "operating_point": drive_json(&spec.before),
        "warnings": warnings,
        "outputs": Value::Object(outs),
    })
}

/// The metrics of one step response (`mvem step --json`, per output).
pub fn step_metrics_json(m: &StepMetrics) -> Value {
    json!({
        "y0": m.y0,
        "y_final": m.y_final,
        "change": m.change,
        "dc_gain": m.dc_gain,
        "gain_sign": m.gain_sign.to_string(),
        "wrong_way": excursion(m.wrong_way),
        "non_minimum_phase": m.non_minimum_phase,
        "overshoot_pct": m.overshoot_pct,
        "peak": excursion(m.peak),
        "rise_time": opt(m.rise_time),
        "settling_time": opt(m.settling_time),
    })
}

/// The summary of a closed-loop cycle run (`stats.json` of `mvem closed-loop`, Python's
/// `mvem.closed_loop`): the tuning of the baseline controllers (null for another scheme), the
/// sample time, the mapping curve's reference speeds, the cycle statistics, the regulation's
/// violations and `passes`, the plant's solver counters.
pub fn cycle_run_json(
    run: &crate::control::drive::CycleRun,
    tuning: Option<&crate::control::baseline::BaselineTuning>,
) -> Value {
    json!({
        "controller_tuning": tuning,
        "sample_time_s": crate::control::drive::SAMPLE_TIME,
        "reference_speeds_rpm": run.speeds,
        "stats": run.stats,
        "violations": run.violations,
        "passes": run.violations.is_empty(),
        "warnings": run.warnings,
        "setpoint_adjustments": run.setpoint_adjustments,
        "solver": {"steps": run.solver.steps, "rejected": run.solver.rejected, "rhs_evals": run.solver.rhs_evals},
    })
}
