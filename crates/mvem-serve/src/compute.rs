//! The computations behind the API: each takes a checked request and a model and returns the
//! JSON answer. They run on the blocking pool (see `api::Work`); none touches the file system.

use mvem::analysis::experiment::{run_step, StepRunError, StepSpec};
use mvem::analysis::json::{drive_json, linear_model_json, steady_json, step_json, unit};
use mvem::analysis::linearize::{linearize_steady, LinearizeError, LinearizeOptions};
use mvem::analysis::map::{dc_gain_map, steady_map, Axis, ChannelMapOptions, Grid, MapOptions};
use mvem::analysis::steady::{simulate_from_steady, steady_state};
use mvem::components::Semantics;
use mvem::control::along;
use mvem::control::baseline::BaselineTuning;
use mvem::control::drive::{self, CycleSource, Scheme};
use mvem::control::{ControlError, Trajectory};
use mvem::io::csv_demand::parse_cycle_file;
use mvem::io::csv_inputs::{input_ranges, range_warnings};
use mvem::model::{saturate_inputs, AnyModel, Drive, Model, Signals};
use mvem::numerics::Num;
use mvem::params::Params;
use mvem::sim::{InputSchedule, SimOptions};
use serde::Deserialize;
use serde_json::{json, Map, Value};
use std::sync::Arc;

/// Why a computation gave no answer.
#[derive(Debug)]
pub(crate) enum Fail {
    /// The request is wrong (HTTP 400); the message names the parameter.
    Input(String),
    /// The model could not answer at a well-formed request, e.g. no equilibrium (HTTP 422).
    Model(String),
}

fn input(msg: impl Into<String>) -> Fail {
    Fail::Input(msg.into())
}

/// Largest number of points on one axis of a map.
pub const MAX_MAP_SIDE: usize = 41;
/// Largest number of points of a map.
pub const MAX_MAP_POINTS: usize = 41 * 41;
/// Longest step-response horizon [s].
const MAX_HORIZON: f64 = 60.0;
/// Most output samples of one simulated series.
const MAX_SAMPLES: f64 = 50_000.0;
/// Most output series of one simulation (and outputs of one linearization).
pub(crate) const MAX_OUTPUTS: usize = 32;
/// Output interval of a step response [s] (the CLI's `mvem step` default).
const STEP_DT: f64 = 0.005;

/// Check output names against the model's states and signals.
fn check_outputs<const N: usize, M: Model<N>>(
    m: &M,
    field: &str,
    outputs: &[String],
) -> Result<(), Fail> {
    if outputs.len() > MAX_OUTPUTS {
        return Err(input(format!(
            "{field}: {} names, at most {MAX_OUTPUTS}",
            outputs.len()
        )));
    }
    for o in outputs {
        if o != "t"
            && !m.state_names().contains(&o.as_str())
            && !Signals::NAMES.contains(&o.as_str())
        {
            return Err(input(format!(
                "{field}: unknown output {o:?}; known: the states {} and the signals {}",
                m.state_names().join(", "),
                Signals::NAMES.join(", ")
            )));
        }
    }
    Ok(())
}

/// `mvem steady --json`.
pub(crate) fn steady<const N: usize, M: Model<N>>(m: &M, d: &Drive) -> Result<Value, Fail> {
    let ss = steady_state(m, d).map_err(|e| Fail::Model(format!("steady state: {e}")))?;
    Ok(steady_json(m, &ss))
}

/// `mvem linearize --json` (with `--pade K`, `--outputs`, `--ts` and `--bode`).
pub(crate) fn linearize<const N: usize, M: Model<N>>(
    m: &M,
    d: &Drive,
    pade: usize,
    outputs: &[String],
    ts: Option<f64>,
    bode: Option<&[f64]>,
) -> Result<Value, Fail> {
    let mut opts = LinearizeOptions {
        pade_order: pade,
        strict: false,
        ..LinearizeOptions::default()
    };
    if !outputs.is_empty() {
        opts.outputs = outputs.to_vec();
    }
    let ss = steady_state(m, d).map_err(|e| Fail::Model(format!("steady state: {e}")))?;
    let lin = linearize_steady(m, &ss, &opts).map_err(|e| match e {
        LinearizeError::UnknownOutput { .. } => input(format!("outputs: {e}")),
        LinearizeError::BadOption { .. } => input(e.to_string()),
        other => Fail::Model(format!("linearization: {other}")),
    })?;
    let mut v = linear_model_json(&lin, &ss);
    if let Some(ts) = ts {
        let dm = mvem::analysis::discrete::discretize_linear(m, &ss.x, d, &lin, ts).map_err(
            |e| match e {
                LinearizeError::BadOption { .. } => input(e.to_string()),
                other => Fail::Model(format!("sampled model: {other}")),
            },
        )?;
        v["discrete"] = mvem::analysis::json::discrete_model_json(&dm);
    }
    if let Some(f) = bode {
        let fr = mvem::analysis::frequency::frequency_response_linear(m, &ss.x, d, &lin, f)
            .map_err(|e| match e {
                LinearizeError::BadOption { .. } => input(e.to_string()),
                other => Fail::Model(format!("frequency response: {other}")),
            })?;
        v["frequency_response"] = mvem::analysis::json::frequency_response_json(&fr);
    }
    Ok(v)
}

/// An operating point in a JSON body (the CLI's units).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Point {
    /// Engine speed [rpm].
    pub n_e: f64,
    /// Injected fuel [mg/cycle/cylinder].
    pub u_delta: f64,
    /// EGR valve command [%].
    pub u_egr: f64,
    /// VGT command [%].
    pub u_vgt: f64,
}

impl Point {
    pub(crate) fn drive(&self) -> Drive {
        Drive::new(self.n_e, self.u_delta, self.u_egr, self.u_vgt)
    }
}

/// Body of `POST /api/margins`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MarginsRequest {
    /// Operating point.
    pub point: Point,
    /// The baseline controllers' tuning (`BaselineTuning` fields; the others keep their
    /// defaults), as `mvem margins --tuning`.
    #[serde(default)]
    pub tuning: Option<BaselineTuning>,
    /// Model order 8, 10 or 12 (default 8).
    #[serde(default)]
    pub model: Option<u32>,
    /// Parameter set (default: the first the server was started with).
    #[serde(default)]
    pub params: Option<String>,
}

/// `POST /api/margins`: the object of `mvem margins --json` (`control::margins`).
pub(crate) fn margins<const N: usize, M: Model<N>>(
    m: &M,
    r: &MarginsRequest,
) -> Result<Value, Fail> {
    use mvem::control::margins::{baseline_loops, margins_at, margins_report_json};
    let tuning = r.tuning.unwrap_or_default();
    tuning
        .validate()
        .map_err(|e| input(format!("tuning: {e}")))?;
    let d = r.point.drive();
    let (_, a) = margins_at(
        m,
        &d,
        &baseline_loops(&tuning, &d, &m.params().input_saturation),
        tuning.ts,
    )
    .map_err(|e| Fail::Model(format!("loop margins: {e}")))?;
    Ok(margins_report_json(&d, N, &a))
}

/// Body of `POST /api/step`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct StepRequest {
    /// Operating point before the step.
    pub point: Point,
    /// Stepped input: `n_e`, `u_delta`, `u_egr` or `u_vgt`.
    pub input: String,
    /// Its value after the step.
    pub target: f64,
    /// End time [s] (default 10).
    #[serde(default = "default_horizon")]
    pub horizon: f64,
    /// Step time [s] (default 1).
    #[serde(default = "default_t_step")]
    pub t_step: f64,
    /// Outputs (default p_im, p_em, W_c, n_t, x_egr, lambda_O, M_e).
    #[serde(default)]
    pub outputs: Vec<String>,
    /// Model order 8, 10 or 12 (default 8).
    #[serde(default)]
    pub model: Option<u32>,
    /// Parameter set (default: the first the server was started with).
    #[serde(default)]
    pub params: Option<String>,
}

fn default_horizon() -> f64 {
    10.0
}

fn default_t_step() -> f64 {
    1.0
}

impl StepRequest {
    /// Checks that need no model.
    pub(crate) fn check(&self) -> Result<usize, Fail> {
        let slot = Drive::NAMES
            .iter()
            .position(|n| *n == self.input)
            .ok_or_else(|| {
                input(format!(
                    "input: {:?} is not an input; one of {}",
                    self.input,
                    Drive::NAMES.join(", ")
                ))
            })?;
        let before = self.point.drive().to_array();
        if self.target == before[slot] {
            return Err(input(format!(
                "target {}: equals the value of {} before the step",
                self.target, self.input
            )));
        }
        if !(self.horizon > 0.0 && self.horizon <= MAX_HORIZON) {
            return Err(input(format!(
                "horizon {}: must lie in (0, {MAX_HORIZON}] s",
                self.horizon
            )));
        }
        if self.t_step.is_nan() || self.t_step < 0.0 {
            return Err(input(format!("t_step {}: must be >= 0 s", self.t_step)));
        }
        // (named by the horizon: the page sets it, the step time is the default 1 s)
        if self.t_step >= self.horizon {
            return Err(input(format!(
                "horizon {}: must be after the step at t_step = {} s",
                self.horizon, self.t_step
            )));
        }
        Ok(slot)
    }
}

/// `POST /api/step`: the metrics (as `mvem step --json`) and the sampled responses.
pub(crate) fn step<const N: usize, M: Model<N>>(
    m: &M,
    r: &StepRequest,
    slot: usize,
) -> Result<Value, Fail> {
    let outputs: Vec<String> = if r.outputs.is_empty() {
        mvem::analysis::linearize::DEFAULT_OUTPUTS
            .iter()
            .map(|s| s.to_string())
            .collect()
    } else {
        r.outputs.iter().map(|s| s.trim().to_string()).collect()
    };
    check_outputs(m, "outputs", &outputs)?;
    let opts = SimOptions {
        dt_out: STEP_DT,
        ..SimOptions::default()
    };
    let spec = StepSpec {
        before: r.point.drive(),
        input: slot,
        to: r.target,
        t_step: r.t_step,
        t_end: r.horizon,
    };
    let run = run_step(m, &spec, &opts).map_err(|e| match e {
        StepRunError::BadStep { .. } | StepRunError::Schedule(_) => input(e.to_string()),
        other => Fail::Model(other.to_string()),
    })?;
    let mut series = Map::new();
    let mut metrics = Vec::with_capacity(outputs.len());
    for n in &outputs {
        metrics.push((n.clone(), run.metrics(n)));
        series.insert(n.clone(), json!(run.sol.get(n).unwrap_or_default()));
    }
    // the inputs as the model applies them: the authors' saturation clamps a value outside
    // its range (n_e and u_delta: the parameter set's input_saturation), which `mvem step`
    // warns about on stderr; here a warning each (the point before the step, the stepped
    // input after it)
    let sem = m.options().semantics;
    let limits = &m.params().input_saturation;
    let (applied_before, _) = saturate_inputs(&spec.before, sem, limits);
    let (applied_after, _) = saturate_inputs(&spec.after(), sem, limits);
    let mut warnings = run.flags();
    if sem.authors() {
        let ranges = input_ranges(limits);
        let before = spec.before.to_array();
        let clamped = applied_before.to_array();
        for (k, (name, lo, hi)) in ranges.iter().enumerate() {
            if before[k] != clamped[k] {
                warnings.push(format!(
                    "{name} = {} is outside [{lo}, {hi}]; the authors' saturation clamps it to {}",
                    Num(before[k]),
                    Num(clamped[k])
                ));
            }
        }
        let (name, lo, hi) = ranges[slot];
        let to = applied_after.to_array()[slot];
        if to != r.target {
            warnings.push(format!(
                "the step to {name} = {} is outside [{lo}, {hi}]; the authors' saturation clamps it to {} \
                 (the DC gains are per the change asked for, {}, not the one applied, {})",
                Num(r.target),
                Num(to),
                Num(r.target - spec.from()),
                Num(to - applied_before.to_array()[slot])
            ));
        }
    }
    let (from, to) = (spec.from(), r.target);
    let (from_applied, to_applied) = (
        applied_before.to_array()[slot],
        applied_after.to_array()[slot],
    );
    let at = |t: f64, a: f64, b: f64| if t < r.t_step { a } else { b };
    let u: Vec<f64> = run.sol.t().iter().map(|&t| at(t, from, to)).collect();
    let u_applied: Vec<f64> = run
        .sol
        .t()
        .iter()
        .map(|&t| at(t, from_applied, to_applied))
        .collect();
    let mut v = step_json(&spec, &warnings, &metrics);
    v["t"] = json!(run.sol.t());
    v["u"] = json!(u);
    v["u_applied"] = json!(u_applied);
    v["from_applied"] = json!(from_applied);
    v["to_applied"] = json!(to_applied);
    v["series"] = Value::Object(series);
    Ok(v)
}

/// How a drive cycle is run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CycleMode {
    /// The cycle's u_egr and u_vgt commands applied as recorded.
    Open,
    /// The WHTC driven by the baseline EGR/VGT and engine controllers of `mvem::control`
    /// (`mvem closed-loop --cycle whtc`).
    Closed,
}

impl CycleMode {
    /// Names of the modes (`/api/models` "modes").
    pub const NAMES: [&'static str; 2] = ["open", "closed"];

    /// From the `mode` field of `POST /api/simulate`.
    pub(crate) fn parse(s: Option<&str>) -> Result<Self, Fail> {
        match s.unwrap_or("open") {
            "open" => Ok(CycleMode::Open),
            "closed" => Ok(CycleMode::Closed),
            other => Err(input(format!(
                "mode: {other:?} is not a mode; one of \"open\", \"closed\""
            ))),
        }
    }
}

/// Body of `POST /api/simulate`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SimulateRequest {
    /// A cycle the server was started with (`"whtc"`: data/whtc_inputs_10hz.csv). Exclusive
    /// with `csv`.
    #[serde(default)]
    pub cycle: Option<String>,
    /// An input table in the CSV format of `mvem simulate --inputs` (columns time_s,
    /// n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct).
    #[serde(default)]
    pub csv: Option<String>,
    /// Output interval [s] (default 0.1).
    #[serde(default)]
    pub dt: Option<f64>,
    /// `dt` is the finest output interval wanted: a cycle that would give more than
    /// [`MAX_SAMPLES`] samples at it is sampled at the smallest multiple of 10 ms that gives at
    /// most that many, with a warning (default false: such a `dt` is a 400). The explorer sets
    /// it, so that a cycle of several hours runs there at its 0.2 s.
    #[serde(default)]
    pub fit_dt: bool,
    /// Series to return (default: W_c, p_im, p_em, x_egr, lambda_O, M_e, n_t, T_em).
    #[serde(default)]
    pub outputs: Vec<String>,
    /// `"open"` (default) or `"closed"` (the WHTC with the baseline controllers; `cycle`
    /// `"whtc"` only).
    #[serde(default)]
    pub mode: Option<String>,
    /// Model order 8, 10 or 12 (default 8).
    #[serde(default)]
    pub model: Option<u32>,
    /// Parameter set.
    #[serde(default)]
    pub params: Option<String>,
    /// The baseline controllers' tuning in `"closed"` mode (`BaselineTuning` fields; the others
    /// keep their defaults), as `mvem closed-loop --tuning`.
    #[serde(default)]
    pub tuning: Option<BaselineTuning>,
    /// In `"closed"` mode, the loop margins of the air-path loops in feedback every `margins`
    /// seconds of the run (`mvem closed-loop --margins S`, `mvem::control::along`): at least
    /// the controller sample and at most [`MAX_MARGINS_SAMPLES`] samples over the cycle.
    #[serde(default)]
    pub margins: Option<f64>,
}

/// Series of the drive-cycle panel.
pub(crate) const CYCLE_OUTPUTS: [&str; 8] = [
    "W_c", "p_im", "p_em", "x_egr", "lambda_O", "M_e", "n_t", "T_em",
];

/// What a cycle request runs (each mode with what it can run).
pub(crate) enum CycleInput {
    /// Open loop: an input schedule.
    Open(Arc<InputSchedule>),
    /// Closed loop: the built-in WHTC (its speed and torque demand built in) or a user's cycle
    /// (`"csv"`): a speed/torque demand (columns t, n_e, M_ref) or a normalized cycle (time,
    /// speed [%], torque [%]; `parse_cycle_file`).
    Closed(CycleSource),
}

/// Longest closed-loop demand a request may run \[s\] (twice the WHTC: about 1 s of CPU for the
/// 8-state model at the 10 ms controller sample).
pub const MAX_CLOSED_SPAN: f64 = 3600.0;

/// Most samples of the loop margins along one closed-loop run (`"margins"`): each is a steady
/// state and the loops' margins, about 40 ms of CPU for the 8-state model, so 1000 take some
/// 20 s on 2 cores, inside the request time limit (the WHTC every 1.8 s or more; `mvem
/// closed-loop --margins` has no such limit).
pub const MAX_MARGINS_SAMPLES: f64 = 1000.0;

impl SimulateRequest {
    /// What to run (in its mode), its name and the output interval (checks that need no model).
    pub(crate) fn schedule(
        &self,
        cycles: &[(String, Arc<InputSchedule>)],
    ) -> Result<(CycleInput, String, f64), Fail> {
        let mode = CycleMode::parse(self.mode.as_deref())?;
        if let Some(csv) = &self.csv {
            check_text(csv)?;
        }
        if let Some(t) = &self.tuning {
            if mode != CycleMode::Closed {
                return Err(input(
                    "tuning: sets the baseline controllers of mode \"closed\"",
                ));
            }
            t.validate().map_err(|e| input(format!("tuning: {e}")))?;
        }
        if self.margins.is_some() && mode != CycleMode::Closed {
            return Err(input(
                "margins: analyses the baseline controllers' loops of mode \"closed\"",
            ));
        }
        if let (CycleMode::Closed, None, Some(csv)) = (mode, &self.cycle, &self.csv) {
            // a speed/torque demand or a normalized cycle, as `mvem closed-loop --cycle FILE`
            let source = parse_cycle_file(csv, std::path::Path::new("csv"))
                .map_err(|e| input(format!("{e} (mode \"closed\" reads a speed/torque demand: columns t [s], n_e [rpm], M_ref [Nm], or a normalized cycle: time [s], speed [%], torque [%])")))?;
            let (t0, t1) = source.span().map_err(|e| input(format!("csv: {e}")))?;
            if t1 - t0 > MAX_CLOSED_SPAN {
                return Err(input(format!(
                    "csv: the demand spans {} s ({} to {} s); mode \"closed\" runs at most {MAX_CLOSED_SPAN} s",
                    Num(t1 - t0),
                    Num(t0),
                    Num(t1)
                )));
            }
            let dt = self.output_interval(t0, t1)?;
            self.check_margins(t0, t1)?;
            return Ok((CycleInput::Closed(source), "csv".to_string(), dt));
        }
        let (sched, name) = match (&self.cycle, &self.csv) {
            (Some(c), None) => match cycles.iter().find(|(n, _)| n == c) {
                Some((n, s)) => (s.clone(), n.clone()),
                None => {
                    return Err(input(format!(
                        "cycle: {c:?} is not a cycle of this server; one of {}",
                        cycles
                            .iter()
                            .map(|(n, _)| format!("{n:?}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    )))
                }
            },
            (None, Some(csv)) => {
                let s = mvem::io::csv_inputs::parse_inputs_csv(csv, std::path::Path::new("csv"))
                    .map_err(|e| input(e.to_string()))?;
                check_changes(&s)?;
                (Arc::new(s), "csv".to_string())
            }
            (Some(_), Some(_)) => return Err(input("cycle and csv: give one of them")),
            (None, None) => return Err(input("cycle or csv: one is required")),
        };
        if mode == CycleMode::Closed && name != "whtc" {
            return Err(input(
                "mode \"closed\": runs the WHTC (\"cycle\": \"whtc\") or a speed/torque demand (\"csv\" with the columns t, n_e, M_ref)",
            ));
        }
        let (t0, t1) = (sched.t_first(), sched.t_last());
        if t1 <= t0 {
            return Err(input(format!(
                "{name}: the inputs span no time (first and last row at {} s)",
                Num(t0)
            )));
        }
        let dt = self.output_interval(t0, t1)?;
        let what = match mode {
            CycleMode::Open => CycleInput::Open(sched),
            CycleMode::Closed => {
                let (t0, t1) = CycleSource::Whtc
                    .span()
                    .map_err(|e| Fail::Model(format!("the WHTC: {e}")))?;
                self.check_margins(t0, t1)?;
                CycleInput::Closed(CycleSource::Whtc)
            }
        };
        Ok((what, name, dt))
    }

    /// `dt` (default 0.1 s), checked: positive, and at most [`MAX_SAMPLES`] samples from `t0`
    /// to `t1`.
    fn output_interval(&self, t0: f64, t1: f64) -> Result<f64, Fail> {
        let mut dt = self.dt.unwrap_or(0.1);
        if self.fit_dt && dt.is_finite() && dt > 0.0 && (t1 - t0) / dt + 1.0 > MAX_SAMPLES {
            dt = fitted_interval(t1 - t0);
        }
        if !(dt.is_finite() && dt > 0.0) || (t1 - t0) / dt + 1.0 > MAX_SAMPLES {
            return Err(input(format!(
                "dt {}: must be > 0 and give at most {MAX_SAMPLES} samples from {} to {} s",
                Num(dt),
                Num(t0),
                Num(t1)
            )));
        }
        Ok(dt)
    }

    /// `margins` (closed mode) for a demand from `t0` to `t1` \[s\], checked: a spacing \[s\] of
    /// at least the controller sample that gives at most [`MAX_MARGINS_SAMPLES`] samples.
    fn check_margins(&self, t0: f64, t1: f64) -> Result<(), Fail> {
        let Some(every) = self.margins else {
            return Ok(());
        };
        if !(every.is_finite() && every >= drive::SAMPLE_TIME) {
            return Err(input(format!(
                "margins {}: the seconds between analysed samples must be at least the \
                 controller sample {} s",
                Num(every),
                drive::SAMPLE_TIME
            )));
        }
        if (t1 - t0) / every > MAX_MARGINS_SAMPLES {
            return Err(input(format!(
                "margins {}: the {} s of the cycle every {} s are {} samples; the server \
                 analyses at most {MAX_MARGINS_SAMPLES} (here margins >= {} s; mvem closed-loop \
                 --margins has no limit)",
                Num(every),
                Num(t1 - t0),
                Num(every),
                ((t1 - t0) / every).floor(),
                Num((t1 - t0) / MAX_MARGINS_SAMPLES)
            )));
        }
        Ok(())
    }
}

/// A `"csv"` that is text: no control characters but tab, CR and LF, no U+FFFD (what a browser
/// reads of bytes that are not UTF-8). A binary file is named so, without echoing its bytes in
/// the error of a header it does not have.
fn check_text(csv: &str) -> Result<(), Fail> {
    let bad = |c: char| (c.is_control() && !matches!(c, '\t' | '\r' | '\n')) || c == '\u{FFFD}';
    if let Some((k, line)) = csv.lines().enumerate().find(|(_, l)| l.contains(bad)) {
        let col = line.chars().position(bad).unwrap_or(0) + 1;
        return Err(input(format!(
            "csv, line {}, character {col}: not a text table (a control character or bytes \
             that are not UTF-8: is it a binary file?)",
            k + 1
        )));
    }
    Ok(())
}

/// Inputs whose change between two rows is finite (the schedule interpolates linearly; values
/// such as 1e308 and -1e308 would overflow to a NaN input in the middle of the run).
fn check_changes(s: &InputSchedule) -> Result<(), Fail> {
    let (t, rows) = (s.times(), s.rows());
    for k in 1..rows.len() {
        for (c, name) in ["n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct"]
            .iter()
            .enumerate()
        {
            let (a, b) = (rows[k - 1][c], rows[k][c]);
            if !(b - a).is_finite() {
                return Err(input(format!(
                    "csv, column {name}: from {} at t = {} s to {} at t = {} s, a change too large \
                     to interpolate",
                    Num(a),
                    Num(t[k - 1]),
                    Num(b),
                    Num(t[k])
                )));
            }
        }
    }
    Ok(())
}

/// The smallest multiple of 10 ms that samples `span` \[s\] in at most [`MAX_SAMPLES`]
/// samples (`"fit_dt"`).
fn fitted_interval(span: f64) -> f64 {
    let mut k = (span / (MAX_SAMPLES - 1.0) / 0.01).ceil();
    // (the rounding of k * 0.01)
    while span / (k * 0.01) + 1.0 > MAX_SAMPLES {
        k += 1.0;
    }
    k * 0.01
}

/// `POST /api/simulate`.
pub(crate) fn simulate_cycle(
    model: &AnyModel,
    r: &SimulateRequest,
    what: &CycleInput,
    name: &str,
    dt: f64,
) -> Result<Value, Fail> {
    let mut v = match what {
        CycleInput::Open(sched) => {
            mvem::dispatch!(model, m => open_cycle(m, r, sched, name, dt))
        }
        CycleInput::Closed(source) => closed_cycle(model, r, source.clone(), name, dt),
    }?;
    let asked = r.dt.unwrap_or(0.1);
    if dt != asked {
        // `"fit_dt"` widened the interval
        let note = format!(
            "sampled every {} s: dt {} s would give more than {MAX_SAMPLES} samples",
            Num(dt),
            Num(asked)
        );
        if let Some(Value::Array(w)) = v.get_mut("warnings") {
            w.push(json!(note));
        }
    }
    Ok(v)
}

/// The open-loop cycle from the steady state at its first inputs.
fn open_cycle<const N: usize, M: Model<N>>(
    m: &M,
    r: &SimulateRequest,
    sched: &InputSchedule,
    name: &str,
    dt: f64,
) -> Result<Value, Fail> {
    let outputs: Vec<String> = if r.outputs.is_empty() {
        CYCLE_OUTPUTS.iter().map(|s| s.to_string()).collect()
    } else {
        r.outputs.clone()
    };
    check_outputs(m, "outputs", &outputs)?;
    let opts = SimOptions {
        dt_out: dt,
        ..SimOptions::default()
    };
    let (t0, t1) = (sched.t_first(), sched.t_last());
    let sol = simulate_from_steady(m, sched, t0, t1, &opts)
        .map_err(|e| Fail::Model(format!("simulation failed: {e}")))?;
    let mut series = Map::new();
    let mut units = Map::new();
    for n in &outputs {
        series.insert(n.clone(), json!(sol.get(n).unwrap_or_default()));
        units.insert(n.clone(), json!(unit(n)));
    }
    let rows: Vec<Drive> = sol.t().iter().map(|&t| sched.at(t)).collect();
    let (inputs, inputs_applied) = inputs_json(&rows, m.options().semantics, m.params());
    for n in Drive::NAMES {
        units.insert(n.to_string(), json!(unit(n)));
    }
    // inputs outside the parameter set's saturation ranges are clamped by the model: say so,
    // as `mvem simulate` warns on stderr
    let warnings = range_warnings(sched, &input_ranges(&m.params().input_saturation));
    Ok(json!({
        "source": name,
        "mode": "open",
        "warnings": warnings,
        "t": sol.t(),
        "series": Value::Object(series),
        "inputs": inputs,
        "inputs_applied": inputs_applied,
        "units": Value::Object(units),
        "stats": {"steps": sol.stats.steps, "rejected": sol.stats.rejected, "rhs_evals": sol.stats.rhs_evals},
    }))
}

/// The inputs of a run's samples as commanded (`"inputs"`: the schedule's or the controllers'
/// values) and as the model applies them (`"inputs_applied"`: the authors' saturation clamps a
/// value outside its range, [`saturate_inputs`]; the paper's semantics use them as given), each
/// an object of the four input series.
fn inputs_json(rows: &[Drive], sem: Semantics, p: &Params) -> (Value, Value) {
    let applied: Vec<Drive> = rows
        .iter()
        .map(|d| saturate_inputs(d, sem, &p.input_saturation).0)
        .collect();
    let object = |ds: &[Drive]| {
        let mut o = Map::new();
        for (k, n) in Drive::NAMES.iter().enumerate() {
            let v: Vec<f64> = ds.iter().map(|d| d.to_array()[k]).collect();
            o.insert(n.to_string(), json!(v));
        }
        Value::Object(o)
    };
    (object(rows), object(&applied))
}

/// Series of the closed-loop mode: the plant's outputs and the references.
pub(crate) const CLOSED_OUTPUTS: [&str; 9] = [
    "W_c",
    "p_im",
    "p_em",
    "x_egr",
    "x_egr_ref",
    "lambda_O",
    "lambda_O_ref",
    "M_e",
    "M_ref",
];

/// The WHTC or a speed/torque demand with the baseline controllers (the core's
/// [`drive::run_cycle`], as `mvem closed-loop --cycle whtc|FILE.csv`): the trajectory every `dt`
/// (rounded to a whole number of 10 ms controller samples), the cycle statistics and the
/// regulation check; with `margins` also the loop margins along the run (`"margins"`:
/// [`along::summary_json`] and [`along::points_json`], as `mvem closed-loop --margins`). A
/// demand the engine cannot follow (speeds outside its range, torque above its full load) is
/// the request's error.
fn closed_cycle(
    model: &AnyModel,
    r: &SimulateRequest,
    source: CycleSource,
    name: &str,
    dt: f64,
) -> Result<Value, Fail> {
    let outputs: Vec<String> = if r.outputs.is_empty() {
        CLOSED_OUTPUTS.iter().map(|s| s.to_string()).collect()
    } else {
        r.outputs.clone()
    };
    if outputs.len() > MAX_OUTPUTS {
        return Err(input(format!(
            "outputs: {} names, at most {MAX_OUTPUTS}",
            outputs.len()
        )));
    }
    let columns: Vec<&str> = Trajectory::NAMES
        .iter()
        .filter(|n| **n != "t" && !Drive::NAMES.contains(n))
        .copied()
        .collect();
    if let Some(o) = outputs.iter().find(|o| !columns.contains(&o.as_str())) {
        return Err(input(format!(
            "outputs: {o:?} is not a closed-loop series; known: {}",
            columns.join(", ")
        )));
    }
    let tuning = r.tuning.unwrap_or_default();
    let run =
        drive::run_cycle(model, source, Scheme::Baseline(tuning), None).map_err(|e| match e {
            e @ ControlError::Demand(_) => input(format!("csv: {e}")),
            e => Fail::Model(format!("closed loop: {e}")),
        })?;
    let every = ((dt / drive::SAMPLE_TIME).round() as usize).max(1);
    let col = |n: &str| -> Vec<f64> {
        run.traj
            .get(n)
            .unwrap_or_default()
            .iter()
            .step_by(every)
            .copied()
            .collect()
    };
    let mut series = Map::new();
    let mut units = Map::new();
    for n in &outputs {
        series.insert(n.clone(), json!(col(n)));
        units.insert(n.clone(), json!(Trajectory::unit(n)));
    }
    let cols: Vec<Vec<f64>> = Drive::NAMES.iter().map(|n| col(n)).collect();
    let rows: Vec<Drive> = (0..cols[0].len())
        .map(|i| Drive::new(cols[0][i], cols[1][i], cols[2][i], cols[3][i]))
        .collect();
    let (inputs, inputs_applied) = mvem::dispatch!(model, m => {
        inputs_json(&rows, m.options().semantics, m.params())
    });
    for n in Drive::NAMES {
        units.insert(n.to_string(), json!(Trajectory::unit(n)));
    }
    let mut v = json!({
        "source": name,
        "mode": "closed",
        "t": col("t"),
        "series": Value::Object(series),
        "inputs": inputs,
        "inputs_applied": inputs_applied,
        "units": Value::Object(units),
        "stats": {"steps": run.solver.steps, "rejected": run.solver.rejected, "rhs_evals": run.solver.rhs_evals},
        "sample_time_s": drive::SAMPLE_TIME,
        "cycle_stats": run.stats,
        "violations": run.violations,
        "passes": run.violations.is_empty(),
        "warnings": run.warnings,
        "controller_tuning": tuning,
    });
    if let Some(every) = r.margins {
        // on the worker's cancellation token (api::Work): stops when the request times out
        let points = along::along_trajectory(model, &run.traj, &tuning, every)
            .map_err(|e| Fail::Model(format!("loop margins: {e}")))?;
        v["margins"] = json!({
            "summary": along::summary_json(every, &along::summarize(&points)),
            "samples": along::points_json(&points),
        });
    }
    Ok(v)
}

/// One axis of `POST /api/map`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AxisRequest {
    /// Input name.
    pub input: String,
    /// First value.
    pub lo: f64,
    /// Last value.
    pub hi: f64,
    /// Number of values (2..=41).
    pub n: usize,
}

/// The channel of `POST /api/map`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ChannelRequest {
    /// Input of the channel (`u_delta`, `u_egr`, `u_vgt`, `n_e`).
    pub input: String,
    /// Output of the channel (a state or signal).
    pub output: String,
}

/// Body of `POST /api/map`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct MapRequest {
    /// The inputs held fixed (the varied two are overridden).
    pub base: Point,
    /// First (outer) axis.
    pub x: AxisRequest,
    /// Second (inner) axis.
    pub y: AxisRequest,
    /// Channel whose DC gain is mapped.
    pub channel: ChannelRequest,
    /// Model order 8, 10 or 12 (default 8).
    #[serde(default)]
    pub model: Option<u32>,
    /// Parameter set.
    #[serde(default)]
    pub params: Option<String>,
}

impl MapRequest {
    /// The grid (checks that need no model).
    pub(crate) fn grid(&self) -> Result<Grid, Fail> {
        let mut axes = Vec::new();
        for (field, a) in [("x", &self.x), ("y", &self.y)] {
            if !(2..=MAX_MAP_SIDE).contains(&a.n) {
                return Err(input(format!(
                    "{field}.n {}: must lie in [2, {MAX_MAP_SIDE}]",
                    a.n
                )));
            }
            if !(a.lo.is_finite() && a.hi.is_finite() && a.lo < a.hi) {
                return Err(input(format!(
                    "{field}.lo {} and {field}.hi {}: need lo < hi",
                    a.lo, a.hi
                )));
            }
            axes.push(Axis::linspace(&a.input, a.lo, a.hi, a.n));
        }
        if self.x.n * self.y.n > MAX_MAP_POINTS {
            return Err(input(format!(
                "x.n * y.n = {}: at most {MAX_MAP_POINTS} points",
                self.x.n * self.y.n
            )));
        }
        if !["u_delta", "u_egr", "u_vgt", "n_e"].contains(&self.channel.input.as_str()) {
            return Err(input(format!(
                "channel.input: {:?} is not an input; one of {}",
                self.channel.input,
                Drive::NAMES.join(", ")
            )));
        }
        Grid::new(self.base.drive(), axes).map_err(|e| input(format!("x, y: {e}")))
    }
}

/// `POST /api/map`: the DC gain of the channel at every grid point (rayon, in parallel).
pub(crate) fn map<const N: usize, M: Model<N>>(
    m: &M,
    r: &MapRequest,
    grid: &Grid,
) -> Result<Value, Fail> {
    check_outputs(m, "channel.output", std::slice::from_ref(&r.channel.output))?;
    let smap = steady_map(m, grid, &MapOptions::default(), None)
        .map_err(|e| Fail::Model(format!("map: {e}")))?;
    let gains = dc_gain_map(
        m,
        &smap,
        &r.channel.input,
        &r.channel.output,
        &ChannelMapOptions::default(),
        None,
    )
    .map_err(|e| Fail::Model(format!("map: {e}")))?;
    let mut gain = Vec::with_capacity(gains.len());
    let mut sign = Vec::with_capacity(gains.len());
    let mut errors = Vec::new();
    let mut valid = Vec::with_capacity(gains.len());
    for (p, g) in smap.points.iter().zip(&gains) {
        valid.push(p.result.as_ref().is_ok_and(|s| s.physically_valid()));
        match g {
            Ok(v) => {
                gain.push(json!(v));
                sign.push(json!(if *v > 0.0 {
                    1
                } else if *v < 0.0 {
                    -1
                } else {
                    0
                }));
            }
            Err(e) => {
                gain.push(Value::Null);
                sign.push(Value::Null);
                errors.push(json!({"index": p.index, "error": e}));
            }
        }
    }
    Ok(json!({
        "x": {"input": grid.axes[0].input, "values": grid.axes[0].values, "unit": unit(&grid.axes[0].input)},
        "y": {"input": grid.axes[1].input, "values": grid.axes[1].values, "unit": unit(&grid.axes[1].input)},
        "channel": {"input": r.channel.input, "output": r.channel.output,
                    "unit": mvem::model::meta::gain_unit(unit(&r.channel.output), unit(&r.channel.input))},
        "base": drive_json(&grid.base),
        "order": "row-major, y fastest: index i * y.n + j is (x.values[i], y.values[j])",
        "dc_gain": gain,
        "sign": sign,
        "physically_valid": valid,
        "errors": errors,
    }))
}
