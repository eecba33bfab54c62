//! The Python API in plain Rust (no Python types), so it is tested by `cargo test` and the
//! pyo3 layer only converts values.

use mvem::analysis::discrete::{discretize_linear, DiscreteModel};
use mvem::analysis::ensemble::{simulate_many, Case};
use mvem::analysis::experiment::{run_step, StepRunError, StepSpec};
use mvem::analysis::linearize::{linearize_steady, LinearModel, LinearizeError, LinearizeOptions};
use mvem::analysis::steady::{simulate_from_steady, steady_state, SimFromSteadyError};
use mvem::analysis::step::StepMetrics;
use mvem::analysis::zeros::{self, ZeroOptions, MIMO_INPUTS, MIMO_OUTPUTS};
use mvem::model::{
    AnyModel, CylinderTemp, Drive, Model, ModelInput, ModelOptions, ModelOrder, Signals,
};
use mvem::params::Params;
use mvem::sim::{InputSchedule, SimError, SimOptions, Start};
use nalgebra::DMatrix;
use serde_json::Value;
use std::path::Path;

/// An error for Python: `Value` becomes `ValueError` (bad input or parameters), `Runtime`
/// becomes `RuntimeError` (solver failure).
#[derive(Debug, Clone, PartialEq)]
pub enum CoreError {
    /// Bad input, option or parameter.
    Value(String),
    /// The solver failed.
    Runtime(String),
}

impl std::fmt::Display for CoreError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CoreError::Value(m) | CoreError::Runtime(m) => f.write_str(m),
        }
    }
}

/// Result of a core call.
pub type CoreResult<T> = Result<T, CoreError>;

/// The published parameter set as a JSON document (`{group: {field: value}}`).
pub fn published_json() -> String {
    serde_json::to_string(&Params::published()).expect("parameters serialize")
}

/// One variable of the model's metadata: (kind, name, unit, description); kind is "time",
/// "input", "state" or "signal" (the core's [`mvem::model::meta`]).
pub type VariableRow = (&'static str, &'static str, &'static str, &'static str);

/// Every variable of every model variant, with its unit and description.
pub fn variables() -> Vec<VariableRow> {
    use mvem::model::meta;
    let row = |kind, v: &'static mvem::model::VarMeta| (kind, v.name, v.unit, v.description);
    std::iter::once(row("time", &meta::TIME))
        .chain(meta::INPUTS.iter().map(|v| row("input", v)))
        .chain(meta::STATES.iter().map(|v| row("state", v)))
        .chain(Signals::META.iter().map(|v| row("signal", v)))
        .collect()
}

/// Every scalar parameter (the core's registry): (path, symbol, unit, description, published
/// value).
pub fn parameters() -> Vec<(String, &'static str, &'static str, String, f64)> {
    let p = Params::published();
    Params::registry()
        .iter()
        .map(|i| (i.path.clone(), i.symbol, i.unit, i.describe(), p.value(i)))
        .collect()
}

/// Merge the overrides `over` into the parameter document `base` (at `path`). A key with an
/// index (`c_vol[1]`, `q_c[1][2]`: one element, named as the registry names it) is not merged
/// but collected in `elements` with its full path, to be set on the parsed set
/// ([`set_element`]).
fn merge(
    base: &mut Value,
    over: &Value,
    path: &str,
    elements: &mut Vec<(String, Value)>,
) -> CoreResult<()> {
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                // dotted keys: "turbo.j_t" = value
                if let Some((head, rest)) = k.split_once('.') {
                    let mut nested = serde_json::Map::new();
                    nested.insert(rest.to_string(), v.clone());
                    let head_path = if path.is_empty() {
                        head.to_string()
                    } else {
                        format!("{path}.{head}")
                    };
                    let slot = b
                        .get_mut(head)
                        .ok_or_else(|| CoreError::Value(format!("unknown parameter `{p}`")))?;
                    merge(slot, &Value::Object(nested), &head_path, elements)?;
                    continue;
                }
                // at the top level, a scalar by the name the tuning report gives it (its
                // paper symbol `c_vol1`, `a3`, or its field `c_vol[1]`): one element
                let by_name = if path.is_empty() && !b.contains_key(k) {
                    registry_paths(k)
                } else {
                    Vec::new()
                };
                if !by_name.is_empty() {
                    elements.extend(by_name.iter().map(|f| (f.to_string(), v.clone())));
                    continue;
                }
                if k.contains('[') {
                    elements.push((p, v.clone()));
                    continue;
                }
                let slot = b
                    .get_mut(k)
                    .ok_or_else(|| CoreError::Value(format!("unknown parameter `{p}`")))?;
                merge(slot, v, &p, elements)?;
            }
            Ok(())
        }
        (b @ Value::Number(_), Value::Number(_)) => {
            *b = over.clone();
            Ok(())
        }
        (b @ Value::Array(_), Value::Array(_)) => {
            *b = over.clone();
            Ok(())
        }
        (_, o) => Err(CoreError::Value(format!(
            "parameter `{path}`: unexpected value {o} (numbers, lists or tables of them)"
        ))),
    }
}

/// The registry paths of the scalar parameter `name` as the tuning report's `correlated_with`,
/// `at_bounds` and messages name it: its path, its paper symbol where unique (`c_vol1`,
/// `w_copt`; [`mvem::params::ParamInfo::find`]; `a3` names both symmetric entries of Q_c, and
/// both are set) or its field and index without the group (`c_vol[1]`,
/// [`mvem::params::element_name`]) where one group has it. Empty otherwise.
fn registry_paths(name: &str) -> Vec<&'static str> {
    let reg = Params::registry();
    if let Some(i) = mvem::params::ParamInfo::find(name) {
        if i.path == name {
            return vec![i.path.as_str()];
        }
        return reg
            .iter()
            .filter(|r| r.symbol == name)
            .map(|r| r.path.as_str())
            .collect();
    }
    let fields: Vec<&str> = reg
        .iter()
        .filter(|i| i.path.split_once('.').map(|(_, f)| f) == Some(name))
        .map(|i| i.path.as_str())
        .collect();
    if fields.len() == 1 {
        fields
    } else {
        Vec::new()
    }
}

/// Set the element `path` (`cylinder.c_vol[1]`: a path of the parameter registry, indices
/// 1-based as in [`parameters`], the FMU and `mvem params show`'s c_vol1) of `p` to `v`. An
/// index 0 or past the end is refused with the field's element names.
fn set_element(p: &mut Params, path: &str, v: &Value) -> CoreResult<()> {
    let x = v.as_f64().ok_or_else(|| {
        CoreError::Value(format!("parameter `{path}`: expected a number, got {v}"))
    })?;
    let reg = Params::registry();
    if let Some(slot) = reg
        .iter()
        .find(|i| i.path == path)
        .and_then(|i| p.value_mut(i))
    {
        *slot = x;
        return Ok(());
    }
    let field = path.split('[').next().unwrap_or(path);
    let of_field: Vec<&mvem::params::ParamInfo> = reg
        .iter()
        .filter(|i| field.split_once('.') == Some((i.group, i.field)))
        .collect();
    let (Some(first), Some(last)) = (of_field.first(), of_field.last()) else {
        return Err(CoreError::Value(format!("unknown parameter `{path}`")));
    };
    let zero = path.contains("[0]");
    Err(CoreError::Value(format!(
        "parameter `{path}`: {}; `{field}` has the elements {}{}",
        if zero {
            "indices are 1-based, as parameters(), the FMU and `mvem params show` name them"
        } else {
            "no such element"
        },
        first.path,
        if of_field.len() > 1 {
            format!(" ({}) to {} ({})", first.symbol, last.path, last.symbol)
        } else {
            String::new()
        }
    )))
}

/// Parameters: the published set with the overrides of `json` (nested `{group: {field: v}}`,
/// dotted `{"group.field": v}`, one element by its registry path `{"cylinder.c_vol[1]": v}`,
/// 1-based, or one scalar by the name the tuning report uses, `{"c_vol1": v}`,
/// `registry_paths`), validated.
pub fn params_from_overrides(json: &str) -> CoreResult<Params> {
    let over: Value = serde_json::from_str(json)
        .map_err(|e| CoreError::Value(format!("params: not a JSON-like mapping: {e}")))?;
    if !over.is_object() {
        return Err(CoreError::Value(
            "params must be a dict or a path to a TOML/JSON file".into(),
        ));
    }
    let mut doc = serde_json::to_value(Params::published()).expect("parameters serialize");
    let mut elements = Vec::new();
    merge(&mut doc, &over, "", &mut elements)?;
    let mut p: Params =
        serde_json::from_value(doc).map_err(|e| CoreError::Value(format!("params: {e}")))?;
    for (path, v) in &elements {
        set_element(&mut p, path, v)?;
    }
    p.validate()
        .map_err(|e| CoreError::Value(format!("invalid parameters: {e}")))?;
    Ok(p)
}

/// Parameters from a TOML or JSON file.
pub fn params_from_path(path: &Path) -> CoreResult<Params> {
    mvem::io::params::load_params(path).map_err(|e| CoreError::Value(e.to_string()))
}

/// Model variant and cylinder-temperature mode of a call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Variant {
    /// 8, 10 or 12 states.
    pub order: ModelOrder,
    /// Cylinder-out temperature fixed point.
    pub cylinder_temp: CylinderTemp,
}

impl Variant {
    /// From the Python arguments `model` (8, 10, 12) and `cylinder_temp`
    /// ("converged", "one-iteration").
    pub fn parse(model: i64, cylinder_temp: &str) -> CoreResult<Self> {
        let order = usize::try_from(model)
            .ok()
            .and_then(ModelOrder::from_states)
            .ok_or_else(|| CoreError::Value(format!("model = {model}: expected 8, 10 or 12")))?;
        let cylinder_temp = match cylinder_temp {
            "converged" => CylinderTemp::Converged,
            "one-iteration" => CylinderTemp::OneIteration,
            other => {
                return Err(CoreError::Value(format!(
                    "cylinder_temp = {other:?}: expected \"converged\" or \"one-iteration\""
                )))
            }
        };
        Ok(Self {
            order,
            cylinder_temp,
        })
    }
}

fn model(params: Option<Params>, v: Variant) -> CoreResult<AnyModel> {
    let p = params.unwrap_or_else(Params::published);
    let opts = ModelOptions {
        cylinder_temp: v.cylinder_temp,
        ..ModelOptions::default()
    };
    AnyModel::new(v.order, p, opts)
        .map_err(|e| CoreError::Value(format!("invalid parameters: {e}")))
}

fn check_finite(d: [f64; 4]) -> CoreResult<()> {
    for (i, v) in d.iter().enumerate() {
        if !v.is_finite() {
            return Err(CoreError::Value(format!(
                "{} = {v} is not finite",
                Drive::NAMES[i]
            )));
        }
    }
    Ok(())
}

/// Simulation options of the Python API.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimArgs {
    /// End time \[s\]; `None`: the last input time.
    pub t_end: Option<f64>,
    /// Output interval \[s\].
    pub dt: f64,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance (relative to the state scales).
    pub atol: f64,
    /// Integrate the actuator states numerically too (default false: in closed form, see
    /// `SimOptions::exact_actuators`).
    pub numeric_actuators: bool,
    /// Time chunks integrated at once, one thread each (`SimOptions::time_chunks`; 1: the
    /// sequential run).
    pub time_parallel: usize,
}

impl Default for SimArgs {
    fn default() -> Self {
        let d = SimOptions::default();
        Self {
            t_end: None,
            dt: d.dt_out,
            rtol: d.rtol,
            atol: d.atol,
            numeric_actuators: !d.exact_actuators,
            time_parallel: d.time_chunks,
        }
    }
}

impl SimArgs {
    /// The simulator options (validated; the output interval is `dt`).
    fn options(&self) -> CoreResult<SimOptions> {
        let opts = SimOptions {
            rtol: self.rtol,
            atol: self.atol,
            dt_out: self.dt,
            exact_actuators: !self.numeric_actuators,
            time_chunks: self.time_parallel,
            ..SimOptions::default()
        };
        opts.validate()
            .map_err(|e| CoreError::Value(e.to_string()))?;
        Ok(opts)
    }
}

/// Simulate from the steady state at the first input row. `rows` are
/// `[time_s, n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct]` (linear interpolation between rows,
/// two rows with the same time make a step). Returns column names and columns.
pub fn simulate_rows(
    rows: &[[f64; 5]],
    args: SimArgs,
    params: Option<Params>,
    variant: Variant,
) -> CoreResult<(Vec<String>, Vec<Vec<f64>>)> {
    simulate_rows_from(rows, args, params, variant, None)
}

/// A start state given to [`simulate_rows_from`]: values in the model's state order, or named.
#[derive(Debug, Clone, PartialEq)]
pub enum StartState {
    /// One value per state, in `state_names` order.
    Values(Vec<f64>),
    /// Every state by name.
    Named(Vec<(String, f64)>),
}

/// [`simulate_rows`] from the state `x0` at the first input time (None: the steady state of the
/// first inputs). The command history before the first row is that row (the delayed commands
/// start there). The state must be finite; the integrator clips it into the authors' limits
/// (a caller warns of that with [`start_state_warnings`]).
pub fn simulate_rows_from(
    rows: &[[f64; 5]],
    args: SimArgs,
    params: Option<Params>,
    variant: Variant,
    x0: Option<&StartState>,
) -> CoreResult<(Vec<String>, Vec<Vec<f64>>)> {
    let c = case(rows, &args, params, variant)?;
    let opts = args.options()?;
    let t_end = c.t_end.expect("set by case()");
    let t0 = c.inputs.t_first();
    let sol = mvem::dispatch!(&c.model, m => match x0 {
        None => simulate_from_steady(m, &c.inputs, t0, t_end, &opts).map_err(steady_sim_error),
        Some(x0) => {
            let x = start_state(m, x0)?;
            let guess = mvem::analysis::steady::chunk_guess(m, &c.inputs);
            mvem::sim::simulate_with_guess(m, &c.inputs, t0, t_end, Start::State(x), &opts, Some(&guess))
                .map_err(sim_error)
        }
    })?;
    Ok((sol.names, sol.columns))
}

/// The warnings of a start state `x0` (checked as [`simulate_rows_from`] checks it) for the
/// model of `params` and `variant`: one per state outside the integrator limits, which clip it
/// ([`mvem::model::start_clip_warnings`], as `mvem simulate --initial-state` warns).
pub fn start_state_warnings(
    params: Option<&Params>,
    variant: Variant,
    x0: &StartState,
) -> CoreResult<Vec<String>> {
    let m = model(params.cloned(), variant)?;
    mvem::dispatch!(&m, m => {
        let x = start_state(m, x0)?;
        Ok(mvem::model::start_clip_warnings(
            &m.state_names(),
            &m.state_bounds(),
            &x,
            mvem::model::STARTS_FROM,
        ))
    })
}

/// The state array of `x0` for model `m`: every state, finite, no unknown names
/// ([`mvem::model::meta::state_from_named`] for named values).
fn start_state<const N: usize, M: Model<N>>(m: &M, x0: &StartState) -> CoreResult<[f64; N]> {
    use mvem::model::meta::{state_from_named, NamedStateError};
    let names = m.state_names();
    let bad = |msg: String| CoreError::Value(format!("x0: {msg}"));
    match x0 {
        StartState::Values(v) => {
            let x: [f64; N] = v.as_slice().try_into().map_err(|_| {
                bad(format!(
                    "expected {N} values ({}), got {}",
                    names.join(", "),
                    v.len()
                ))
            })?;
            if let Some(i) = x.iter().position(|v| !v.is_finite()) {
                let e = NamedStateError::NonFinite {
                    name: names[i].to_string(),
                    value: x[i],
                };
                return Err(bad(e.to_string()));
            }
            Ok(x)
        }
        StartState::Named(kv) => state_from_named(&names, kv).map_err(|e| bad(e.to_string())),
    }
}

/// The model, the schedule and the end time of one simulation (checked).
fn case(
    rows: &[[f64; 5]],
    args: &SimArgs,
    params: Option<Params>,
    variant: Variant,
) -> CoreResult<Case> {
    let m = model(params, variant)?;
    let sched = InputSchedule::new(
        rows.iter().map(|r| r[0]).collect(),
        rows.iter().map(|r| [r[1], r[2], r[3], r[4]]).collect(),
    )
    .map_err(|e| CoreError::Value(format!("inputs: {e}")))?;
    let t0 = sched.t_first();
    let t_end = args.t_end.unwrap_or(sched.t_last());
    if !(t_end.is_finite() && t_end > t0) {
        return Err(CoreError::Value(format!(
            "t_end = {t_end} must be finite and after the first input time {t0} (give t_end, or inputs spanning a time interval)"
        )));
    }
    check_rows(t0, t_end, args.dt)?;
    Ok(Case {
        model: m,
        inputs: sched,
        t_end: Some(t_end),
        start: None,
    })
}

/// Most output rows a simulation returned to Python may have: every column is kept in memory
/// (and copied into a numpy array), so 1e7 rows of the 8-state model's 44 columns are about
/// 3.5 GB, twice that while copied. The command line streams to a file instead and allows
/// [`mvem::sim::MAX_ROWS`].
pub const MAX_KEPT_ROWS: f64 = 1e7;

/// Refuse an output grid from `t0` to `t_end` every `dt` seconds with more than
/// [`MAX_KEPT_ROWS`] rows, before anything is simulated (`dt` itself is checked with the other
/// options).
fn check_rows(t0: f64, t_end: f64, dt: f64) -> CoreResult<()> {
    let rows = (t_end - t0) / dt + 1.0;
    if dt > 0.0 && rows > MAX_KEPT_ROWS {
        let num = mvem::numerics::Num;
        return Err(CoreError::Value(format!(
            "dt = {}: {rows:.3e} output rows from {} s to {} s, more than the {MAX_KEPT_ROWS:e} \
             a simulation returned to Python may hold in memory; use a larger dt or a shorter \
             t_end (or `mvem simulate`, which streams to a file)",
            num(dt),
            num(t0),
            num(t_end)
        )));
    }
    Ok(())
}

fn steady_sim_error(e: SimFromSteadyError) -> CoreError {
    match e {
        SimFromSteadyError::Sim(e) => sim_error(e),
        e => CoreError::Runtime(e.to_string()),
    }
}

/// Columns of one simulation: names and values.
pub type Columns = (Vec<String>, Vec<Vec<f64>>);

/// Many simulations at once on `threads` worker threads (`None`: one per core), each from the
/// steady state at its first input row ([`mvem::analysis::ensemble::simulate_many`]). Run `i`
/// has the input rows `runs[i].0` and the parameters `runs[i].1`; its result or its error
/// (prefixed "run i: ") is in slot `i`. The outer error is a bad option (threads, tolerances).
pub fn simulate_many_rows(
    runs: Vec<Run>,
    args: SimArgs,
    variant: Variant,
    threads: Option<usize>,
) -> CoreResult<Vec<CoreResult<Columns>>> {
    simulate_many_rows_from(
        runs.into_iter().map(Ok).collect(),
        &[],
        args,
        variant,
        threads,
    )
}

/// One run of [`simulate_many_rows`]: its input rows and parameters (`None`: published).
pub type Run = (Vec<[f64; 5]>, Option<Params>);

/// [`simulate_many_rows`] with start states: run `i` starts from `starts[i]` where that is
/// given (`starts` may be shorter than `runs`, even empty), else from the steady state of its
/// first inputs. A bad start state is that run's error, and so is a run given as an error (its
/// inputs or parameters could not be read): not run, the others are.
pub fn simulate_many_rows_from(
    runs: Vec<CoreResult<Run>>,
    starts: &[Option<StartState>],
    args: SimArgs,
    variant: Variant,
    threads: Option<usize>,
) -> CoreResult<Vec<CoreResult<Columns>>> {
    let opts = args.options()?;
    if threads == Some(0) {
        return Err(CoreError::Value(
            "threads = 0: give at least 1 (or None: one per core)".into(),
        ));
    }
    let prefix = |i: usize, e: CoreError| match e {
        CoreError::Value(m) => CoreError::Value(format!("run {i}: {m}")),
        CoreError::Runtime(m) => CoreError::Runtime(format!("run {i}: {m}")),
    };
    // checked cases; a bad one keeps its error and is not run
    let mut out: Vec<Option<CoreResult<Columns>>> = Vec::with_capacity(runs.len());
    let mut cases = Vec::new();
    let mut index = Vec::new();
    for (i, run) in runs.into_iter().enumerate() {
        let start = starts.get(i).and_then(Option::as_ref);
        let checked = run
            .and_then(|(rows, p)| case(&rows, &args, p, variant))
            .and_then(|mut c| {
                if let Some(s) = start {
                    c.start = Some(
                        mvem::dispatch!(&c.model, m => start_state(m, s).map(|x| x.to_vec()))?,
                    );
                }
                Ok(c)
            });
        match checked {
            Ok(c) => {
                cases.push(c);
                index.push(i);
                out.push(None);
            }
            Err(e) => out.push(Some(Err(prefix(i, e)))),
        }
    }
    let sols = simulate_many(&cases, &opts, threads.unwrap_or(0))
        .map_err(|e| CoreError::Runtime(e.to_string()))?;
    for (k, r) in sols.into_iter().enumerate() {
        let i = index[k];
        out[i] = Some(
            r.map(|s| (s.names, s.columns))
                .map_err(|e| prefix(i, steady_sim_error(e.error))),
        );
    }
    Ok(out
        .into_iter()
        .map(|r| r.expect("every run has a result"))
        .collect())
}

fn sim_error(e: SimError) -> CoreError {
    match e {
        SimError::BadOption { .. }
        | SimError::BadCommand { .. }
        | SimError::BadInterval { .. }
        | SimError::BadHorizon { .. } => CoreError::Value(e.to_string()),
        other => CoreError::Runtime(other.to_string()),
    }
}

/// A steady state for Python.
#[derive(Debug, Clone, PartialEq)]
pub struct Steady {
    /// Named values: inputs, states, signals.
    pub values: Vec<(String, f64)>,
    /// Whether no invalidating guard is active.
    pub physically_valid: bool,
    /// Active guard flags.
    pub flags: Vec<String>,
}

/// Steady state at the given inputs.
pub fn steady(d: [f64; 4], params: Option<Params>, variant: Variant) -> CoreResult<Steady> {
    check_finite(d)?;
    let m = model(params, variant)?;
    mvem::dispatch!(&m, m => steady_of(m, d))
}

fn steady_of<const N: usize, M: Model<N>>(m: &M, d: [f64; 4]) -> CoreResult<Steady> {
    let ss =
        steady_state(m, &Drive::from_array(d)).map_err(|e| CoreError::Runtime(e.to_string()))?;
    let mut values: Vec<(String, f64)> = ["n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct"]
        .iter()
        .zip(d)
        .map(|(n, v)| (n.to_string(), v))
        .collect();
    for (n, v) in m.state_names().iter().zip(ss.x) {
        values.push((n.to_string(), v));
    }
    for (n, v) in Signals::NAMES.iter().zip(ss.signals.values()) {
        // a signal named like a state (T_em in the 10-state model) is the state's value
        if !m.state_names().contains(n) {
            values.push((n.to_string(), v));
        }
    }
    Ok(Steady {
        values,
        physically_valid: ss.physically_valid(),
        flags: ss.flags.clone(),
    })
}

/// Options of [`linearize_at`].
#[derive(Debug, Clone, PartialEq)]
pub struct LinArgs {
    /// Output names (states or signals); `None`: the library's default outputs.
    pub outputs: Option<Vec<String>>,
    /// Refuse an operating point at a kink of the model.
    pub strict: bool,
    /// Padé order of the actuator delays (0: the undelayed system).
    pub pade_order: usize,
    /// Also sample the model at this time \[s\] with the delays exact
    /// (`mvem::analysis::discrete`).
    pub ts: Option<f64>,
}

impl Default for LinArgs {
    fn default() -> Self {
        Self {
            outputs: None,
            strict: true,
            pade_order: 0,
            ts: None,
        }
    }
}

/// Complex numbers as (re, im) \[1/s\], or why they could not be computed.
pub type ZerosResult = Result<Vec<(f64, f64)>, String>;

/// A linearization with its poles, DC gains and zeros.
#[derive(Debug, Clone)]
pub struct Lin {
    /// The linear model (A, B, C, D, names, operating point).
    pub lin: LinearModel,
    /// Eigenvalues of A \[1/s\] as (re, im).
    pub eigenvalues: Vec<(f64, f64)>,
    /// DC-gain matrix (outputs x inputs), or why there is none.
    pub dc_gain: Result<DMatrix<f64>, String>,
    /// Transmission zeros \[1/s\] of every SISO channel `"input->output"`, or why there are none
    /// (e.g. a kink on the channel).
    pub zeros: Vec<(String, ZerosResult)>,
    /// Transmission zeros of (u_delta, u_egr, u_vgt) -> (M_e, x_egr, lambda_O), when those
    /// outputs are linearized.
    pub mimo_zeros: Option<ZerosResult>,
    /// The model sampled at [`LinArgs::ts`], when given.
    pub discrete: Option<DiscreteModel>,
}

fn pairs(z: &[zeros::Complex<f64>]) -> Vec<(f64, f64)> {
    z.iter().map(|c| (c.re, c.im)).collect()
}

/// Linearize at the steady state of the inputs `d` (n_e, u_delta, u_egr, u_vgt) and compute
/// poles, DC gains and zeros (`mvem::analysis::{linearize, zeros}`).
pub fn linearize_at(
    d: [f64; 4],
    params: Option<Params>,
    variant: Variant,
    args: &LinArgs,
) -> CoreResult<Lin> {
    check_finite(d)?;
    let opts = linearize_options(args)?;
    let m = model(params, variant)?;
    let (lin, discrete) = mvem::dispatch!(&m, m => {
        let drive = Drive::from_array(d);
        let ss = steady_state(m, &drive)
            .map_err(|e| CoreError::Runtime(format!("steady state: {e}")))?;
        let lin = linearize_steady(m, &ss, &opts).map_err(lin_err)?;
        let discrete = match args.ts {
            Some(ts) => Some(discretize_linear(m, &ss.x, &drive, &lin, ts).map_err(lin_err)?),
            None => None,
        };
        Ok::<_, CoreError>((lin, discrete))
    })?;
    let eigenvalues = zeros::poles(&lin)
        .map(|p| pairs(&p))
        .map_err(|e| CoreError::Runtime(format!("eigenvalues: {e}")))?;
    let dc_gain = zeros::dc_gain_matrix(&lin).map_err(|e| e.to_string());
    let zo = ZeroOptions::default();
    let mut zs = Vec::new();
    for i in &lin.input_names {
        for o in &lin.output_names {
            let r = zeros::siso(&lin, i, o, &zo)
                .map(|c| pairs(&c.zeros.finite))
                .map_err(|e| e.to_string());
            zs.push((format!("{i}->{o}"), r));
        }
    }
    let mimo_zeros = MIMO_OUTPUTS
        .iter()
        .all(|o| lin.output_index(o).is_some())
        .then(|| {
            zeros::mimo_zeros(&lin, &MIMO_INPUTS, &MIMO_OUTPUTS, &zo)
                .map(|z| pairs(&z.finite))
                .map_err(|e| e.to_string())
        });
    Ok(Lin {
        discrete,
        lin,
        eigenvalues,
        dc_gain,
        zeros: zs,
        mimo_zeros,
    })
}

/// The linearization options of `args` (its outputs, strict, Padé order), checked.
fn linearize_options(args: &LinArgs) -> CoreResult<LinearizeOptions> {
    let mut opts = LinearizeOptions {
        strict: args.strict,
        pade_order: args.pade_order,
        ..LinearizeOptions::default()
    };
    if let Some(o) = &args.outputs {
        opts.outputs = o.clone();
    }
    opts.validate()
        .map_err(|e| CoreError::Value(e.to_string()))?;
    Ok(opts)
}

/// A linearization's error for Python: bad options and outputs are `Value`, the rest `Runtime`.
fn lin_err(e: LinearizeError) -> CoreError {
    match e {
        LinearizeError::BadOption { .. } | LinearizeError::UnknownOutput { .. } => {
            CoreError::Value(e.to_string())
        }
        other => CoreError::Runtime(other.to_string()),
    }
}

/// The frequency response with exact delays at the steady state of `d`
/// (`mvem::analysis::frequency::frequency_response`): the frequencies \[Hz\], the inputs and
/// outputs, and per channel the complex gains.
pub fn frequency_response_at(
    d: [f64; 4],
    params: Option<Params>,
    variant: Variant,
    f_hz: &[f64],
    args: &LinArgs,
) -> CoreResult<mvem::analysis::frequency::FrequencyResponse> {
    check_finite(d)?;
    let opts = linearize_options(args)?;
    let m = model(params, variant)?;
    mvem::dispatch!(&m, m => {
        let drive = Drive::from_array(d);
        let ss = steady_state(m, &drive)
            .map_err(|e| CoreError::Runtime(format!("steady state: {e}")))?;
        mvem::analysis::frequency::frequency_response(m, &ss.x, &drive, &opts, f_hz)
            .map_err(lin_err)
    })
}

/// Step metrics of samples (`mvem::analysis::step::StepMetrics::compute`).
pub fn step_metrics(
    t: &[f64],
    y: &[f64],
    t_step: f64,
    y0: f64,
    y_final: f64,
    du: f64,
) -> CoreResult<StepMetrics> {
    StepMetrics::compute(t, y, t_step, y0, y_final, du).map_err(|e| CoreError::Value(e.to_string()))
}

/// A simulated step response with its metrics.
#[derive(Debug, Clone)]
pub struct StepResponse {
    /// Metrics; y0 and y_final are the steady states before and after the step.
    pub metrics: StepMetrics,
    /// Output times \[s\].
    pub t: Vec<f64>,
    /// The output.
    pub y: Vec<f64>,
}

/// Step of input `input` (n_e, u_delta, u_egr, u_vgt) from `d` to `to` at `t_step`, simulated
/// from the steady state to `t_end`; metrics of `output` with the initial and final values from
/// the steady states before and after the step (as `mvem demo`).
#[allow(clippy::too_many_arguments)]
pub fn step_response(
    d: [f64; 4],
    input: &str,
    to: f64,
    output: &str,
    t_step: f64,
    t_end: f64,
    args: SimArgs,
    params: Option<Params>,
    variant: Variant,
) -> CoreResult<StepResponse> {
    check_finite(d)?;
    let ch = Drive::NAMES
        .iter()
        .position(|n| *n == input)
        .ok_or_else(|| {
            CoreError::Value(format!(
                "input {input:?}: expected one of {}",
                Drive::NAMES.join(", ")
            ))
        })?;
    for (what, v) in [("to", to), ("t_step", t_step), ("t_end", t_end)] {
        if !v.is_finite() {
            return Err(CoreError::Value(format!("{what} = {v} is not finite")));
        }
    }
    if !(t_step >= 0.0 && t_end > t_step) {
        return Err(CoreError::Value(format!(
            "need 0 <= t_step < t_end (t_step = {t_step}, t_end = {t_end})"
        )));
    }
    let opts = args.options()?;
    check_rows(0.0, t_end, args.dt)?;
    let spec = StepSpec {
        before: Drive::from_array(d),
        input: ch,
        to,
        t_step,
        t_end,
    };
    let m = model(params, variant)?;
    mvem::dispatch!(&m, m => {
        if !m.state_names().contains(&output) && !Signals::NAMES.contains(&output) {
            return Err(CoreError::Value(format!(
                "output {output:?}: expected a state ({}) or a signal ({})",
                m.state_names().join(", "),
                Signals::NAMES.join(", ")
            )));
        }
        let run = run_step(m, &spec, &opts).map_err(|e| match e {
            StepRunError::Sim(e) => sim_error(e),
            e @ (StepRunError::SteadyBefore { .. } | StepRunError::SteadyAfter { .. }) => {
                CoreError::Runtime(e.to_string())
            }
            e => CoreError::Value(e.to_string()),
        })?;
        let metrics = run.metrics(output).map_err(|e| CoreError::Value(e.to_string()))?;
        let y = run.sol.get(output).unwrap_or(&[]).to_vec();
        Ok(StepResponse { metrics, t: run.sol.t().to_vec(), y })
    })
}

/// A plant advanced sample by sample with held commands (`mvem.Plant`): state, cylinder
/// temperature memory, exact actuator delays and the integrator's warm state carry over
/// between calls (`mvem::sim::stepper`).
pub struct CorePlant {
    plant: mvem::sim::stepper::AnyPlant,
    model: AnyModel,
    names: Vec<String>,
}

impl CorePlant {
    /// Start at t = 0 in the steady state of the commands `d` = (n_e, u_delta, u_egr, u_vgt).
    pub fn new(d: [f64; 4], params: Option<Params>, variant: Variant) -> CoreResult<Self> {
        check_finite(d)?;
        let model = model(params, variant)?;
        let plant = Self::start(&model, d)?;
        let mut names: Vec<String> = plant.state_names().iter().map(|s| s.to_string()).collect();
        for s in Signals::NAMES {
            if !names.iter().any(|n| n.as_str() == *s) {
                names.push(s.to_string());
            }
        }
        Ok(Self {
            plant,
            model,
            names,
        })
    }

    fn start(model: &AnyModel, d: [f64; 4]) -> CoreResult<mvem::sim::stepper::AnyPlant> {
        mvem::analysis::steady::any_plant_from_steady(
            model.clone(),
            Drive::from_array(d),
            0.0,
            &mvem::sim::stepper::plant_options(),
        )
        .map_err(|e| CoreError::Runtime(e.to_string()))
    }

    /// Back to t = 0 in the steady state of `d`.
    pub fn reset(&mut self, d: [f64; 4]) -> CoreResult<()> {
        check_finite(d)?;
        self.plant = Self::start(&self.model, d)?;
        Ok(())
    }

    /// Hold `d` for `dt` seconds.
    pub fn step(&mut self, dt: f64, d: [f64; 4]) -> CoreResult<()> {
        self.plant
            .step(dt, Drive::from_array(d))
            .map(|_| ())
            .map_err(|e| match e {
                SimError::BadOption { .. }
                | SimError::BadCommand { .. }
                | SimError::BadHorizon { .. } => CoreError::Value(e.to_string()),
                other => CoreError::Runtime(other.to_string()),
            })
    }

    /// Time \[s\].
    pub fn t(&self) -> f64 {
        self.plant.t()
    }

    /// State vector.
    pub fn state(&self) -> Vec<f64> {
        self.plant.state().to_vec()
    }

    /// The delayed commands (u_egr(t - tau_degr), u_vgt(t - tau_dvgt)) \[%\] the actuators
    /// see now ([`mvem::sim::stepper::Plant::input`]).
    pub fn delayed_commands(&self) -> [f64; 2] {
        let u = self.plant.input();
        [u.u_egr_delayed, u.u_vgt_delayed]
    }

    /// Output names: the states, then the signals that are not states.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Output values in [`CorePlant::names`] order.
    pub fn outputs(&self) -> Vec<f64> {
        let x = self.plant.state();
        let s = self.plant.signals();
        let n = x.len();
        let mut v = x.to_vec();
        v.extend(
            self.names[n..]
                .iter()
                .map(|name| s.get(name).unwrap_or(f64::NAN)),
        );
        v
    }
}

/// The drive cycle of [`closed_loop`].
#[derive(Debug, Clone, PartialEq)]
pub enum CycleArg {
    /// The WHTC denormalized with the engine's mapping curve.
    Whtc,
    /// A speed/torque demand: times \[s\], n_e \[rpm\], M_ref \[Nm\] (linear between rows).
    Demand {
        /// Times \[s\], strictly increasing.
        t: Vec<f64>,
        /// Engine speed \[rpm\].
        n_e: Vec<f64>,
        /// Torque demand \[Nm\].
        m_ref: Vec<f64>,
    },
    /// A cycle file: a speed/torque demand (t, n_e, M_ref) or a normalized cycle (time, speed
    /// [%], torque [%]), as `mvem closed-loop --cycle FILE` reads it.
    File(std::path::PathBuf),
}

/// A closed-loop run for Python: the trajectory's columns and the summary (`stats.json` of
/// `mvem closed-loop`) as JSON text.
#[derive(Debug, Clone)]
pub struct ClosedLoopRun {
    /// Column names (`mvem::control::Trajectory::NAMES`).
    pub names: Vec<String>,
    /// One column per name, one row per 10 ms controller sample.
    pub columns: Vec<Vec<f64>>,
    /// `{"stats", "violations", "passes", "reference_speeds_rpm", "solver",
    /// "controller_tuning", "sample_time_s"}`.
    pub summary: String,
}

/// The baseline tuning from a JSON object of `BaselineTuning` fields (the others default;
/// unknown keys refused), validated.
fn baseline_tuning(tuning: Option<&str>) -> CoreResult<mvem::control::baseline::BaselineTuning> {
    use mvem::control::baseline::BaselineTuning;
    let tuning: BaselineTuning = match tuning {
        None => BaselineTuning::default(),
        Some(text) => mvem::io::settings_from_json(text)
            .map_err(|e| CoreError::Value(format!("tuning: {e}")))?,
    };
    tuning
        .validate()
        .map_err(|e| CoreError::Value(e.to_string()))?;
    Ok(tuning)
}

/// The margins of the baseline's air-path loops at the steady state of `d`
/// (`control::margins`, `mvem margins --json`): the JSON object of the CLI.
pub fn loop_margins(
    d: [f64; 4],
    tuning: Option<&str>,
    params: Option<Params>,
    variant: Variant,
) -> CoreResult<String> {
    use mvem::control::margins::{baseline_loops, margins_at, margins_report_json};
    check_finite(d)?;
    let tuning = baseline_tuning(tuning)?;
    let m = model(params, variant)?;
    let drive = Drive::from_array(d);
    let (_, an) =
        mvem::dispatch!(&m, m => margins_at(m, &drive, &baseline_loops(&tuning, &drive, &m.params().input_saturation), tuning.ts))
            .map_err(CoreError::Runtime)?;
    Ok(margins_report_json(&drive, m.order().states(), &an).to_string())
}

/// The drive cycle `cycle` with the baseline EGR/VGT and engine controllers (tuning: a JSON
/// object of `BaselineTuning` fields, the others default; unknown keys refused), the core's
/// `control::drive::run_cycle` as `mvem closed-loop` runs it. A demand the engine cannot follow
/// and a bad tuning are `Value` errors naming the row or field; a failed plant is `Runtime`.
pub fn closed_loop(
    cycle: CycleArg,
    tuning: Option<&str>,
    params: Option<Params>,
    variant: Variant,
    duration: Option<f64>,
    margins: Option<f64>,
) -> CoreResult<ClosedLoopRun> {
    use mvem::control::cycle::Demand;
    use mvem::control::drive::{run_cycle, CycleSource, Scheme};
    use mvem::control::{ControlError, Trajectory};
    let tuning = baseline_tuning(tuning)?;
    if let Some(every) = margins {
        if !(every.is_finite() && every > 0.0) {
            return Err(CoreError::Value(format!(
                "margins: {every} s between analysed samples must be > 0"
            )));
        }
    }
    let m = model(params, variant)?;
    let source = match cycle {
        CycleArg::Whtc => CycleSource::Whtc,
        CycleArg::Demand { t, n_e, m_ref } => {
            let k = t.len();
            CycleSource::Demand(
                Demand::new(t, n_e, m_ref, vec![false; k])
                    .map_err(|e| CoreError::Value(format!("cycle: {e}")))?,
            )
        }
        CycleArg::File(path) => {
            let text = std::fs::read_to_string(&path).map_err(|e| {
                CoreError::Value(format!(
                    "cycle: {}: {e} (give \"whtc\", a demand, or the path of a cycle file)",
                    path.display()
                ))
            })?;
            mvem::io::csv_demand::parse_cycle_file(&text, &path)
                .map_err(|e| CoreError::Value(format!("cycle: {e}")))?
        }
    };
    let run = run_cycle(&m, source, Scheme::Baseline(tuning), duration).map_err(|e| match e {
        ControlError::Demand(_) | ControlError::BadSampleTime(_) => {
            CoreError::Value(format!("cycle: {e}"))
        }
        other => CoreError::Runtime(other.to_string()),
    })?;
    let mut summary = mvem::analysis::json::cycle_run_json(&run, Some(&tuning));
    if let Some(every) = margins {
        use mvem::control::along;
        let points = along::along_trajectory(&m, &run.traj, &tuning, every)
            .map_err(|e| CoreError::Value(format!("margins: {e}")))?;
        let mut v = along::summary_json(every, &along::summarize(&points));
        v["samples"] = along::points_json(&points);
        summary["margins"] = v;
    }
    Ok(ClosedLoopRun {
        names: Trajectory::NAMES.iter().map(|s| s.to_string()).collect(),
        columns: run.traj.columns,
        summary: summary.to_string(),
    })
}

/// Input order of [`PointModel`]: that of `steady`, `Plant` and the simulate columns (n_e \[rpm\],
/// u_delta \[mg/cycle/cylinder\], u_egr \[%\], u_vgt \[%\]).
pub const POINT_INPUTS: [&str; 4] = ["n_e", "u_delta", "u_egr", "u_vgt"];

/// Columns of the library's linear model ([`mvem::analysis::linearize::INPUT_NAMES`]: u_delta,
/// u_egr, u_vgt, n_e) for each [`POINT_INPUTS`] entry.
const LIN_COLUMN: [usize; 4] = [3, 0, 1, 2];

/// The right-hand side `dx/dt = f(x, u)` and its Jacobians at a point of the state space, for
/// optimal control (`mvem.Model`): the model is built (and its parameters validated) once.
///
/// The commands are held: the delayed commands the actuators see equal the given u_egr, u_vgt
/// (`ModelInput::constant`), so for a model with explicit delays the columns of u_egr and u_vgt
/// are the derivatives with respect to the commands u_egr(t - tau_degr), u_vgt(t - tau_dvgt)
/// (the current commands enter no derivative). The cylinder-out temperature is the converged
/// fixed point (section 4.2).
#[derive(Debug, Clone)]
pub struct PointModel {
    model: AnyModel,
}

/// `f(x, u)` and its Jacobians at one point ([`PointModel::jacobian`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PointJacobian {
    /// dx/dt at the point (n).
    pub dx: Vec<f64>,
    /// A = df/dx (n x n, row-major) \[1/s\].
    pub a: Vec<f64>,
    /// B = df/du (n x 4, row-major; columns in [`POINT_INPUTS`] order), per input unit.
    pub b: Vec<f64>,
    /// The outputs at the point (p).
    pub y: Vec<f64>,
    /// C = dy/dx (p x n, row-major).
    pub c: Vec<f64>,
    /// D = dy/du (p x 4, row-major; [`POINT_INPUTS`] order).
    pub d: Vec<f64>,
    /// Output names (p).
    pub output_names: Vec<String>,
    /// Kinks of the model within the difference stencils (empty at a smooth point).
    pub kinks: Vec<String>,
}

impl PointModel {
    /// The model of `order` with the parameters `params` (None: the published set).
    pub fn new(params: Option<Params>, order: ModelOrder) -> CoreResult<Self> {
        let model = model(
            params,
            Variant {
                order,
                cylinder_temp: CylinderTemp::Converged,
            },
        )?;
        Ok(Self { model })
    }

    /// State names (n).
    pub fn state_names(&self) -> Vec<String> {
        mvem::dispatch!(&self.model, m => m.state_names().iter().map(|s| s.to_string()).collect())
    }

    /// Number of states n.
    pub fn n_states(&self) -> usize {
        self.model.order().states()
    }

    /// Typical magnitudes of the states (n), in their units.
    pub fn state_scales(&self) -> Vec<f64> {
        mvem::dispatch!(&self.model, m => m.state_scales().to_vec())
    }

    /// dx/dt (n) at state `x` and held commands `u` ([`POINT_INPUTS`] order).
    pub fn derivatives(&self, x: &[f64], u: [f64; 4]) -> CoreResult<Vec<f64>> {
        mvem::dispatch!(&self.model, m => {
            let (x, input) = point(m, x, u)?;
            // the derivatives without the signals (bitwise those of eval)
            let dx = m.derivatives(&x, &input, m.memory_start(&x, &input)).dx;
            finite_rows(&m.state_names(), &dx)?;
            Ok(dx.to_vec())
        })
    }

    /// Every signal ([`Signals::NAMES`] order) and the active guard labels at `x`, `u`.
    pub fn signals(&self, x: &[f64], u: [f64; 4]) -> CoreResult<(Vec<f64>, Vec<String>)> {
        mvem::dispatch!(&self.model, m => {
            let (x, input) = point(m, x, u)?;
            let ev = m.eval(&x, &input, m.memory_start(&x, &input));
            let flags = mvem::model::Guard::ALL
                .iter()
                .filter(|g| ev.signals.has(**g))
                .map(|g| g.label().to_string())
                .collect();
            Ok((ev.signals.values().to_vec(), flags))
        })
    }

    /// f(x, u), A = df/dx, B = df/du and, for `outputs` (state or signal names), y, C, D at
    /// state `x` and held commands `u`, by the library's Richardson-extrapolated central
    /// differences (`mvem::analysis::linearize`: entries to about 1e-9 relative). With
    /// `strict`, a point within the difference stencil of a kink of the model is an error;
    /// otherwise the averaged slopes are returned and the kinks listed.
    pub fn jacobian(
        &self,
        x: &[f64],
        u: [f64; 4],
        outputs: &[String],
        strict: bool,
    ) -> CoreResult<PointJacobian> {
        let lin = mvem::dispatch!(&self.model, m => {
            let (x, input) = point(m, x, u)?;
            // the library wants at least one output: without any, a state is linearized and
            // dropped
            let opts = LinearizeOptions {
                outputs: if outputs.is_empty() {
                    vec![m.state_names()[0].to_string()]
                } else {
                    outputs.to_vec()
                },
                strict,
                ..LinearizeOptions::default()
            };
            mvem::analysis::linearize::linearize(m, &x, &input.now, &opts).map_err(|e| match e {
                LinearizeError::Kink(_) => CoreError::Runtime(e.to_string()),
                other => CoreError::Value(other.to_string()),
            })
        })?;
        let n = lin.a.nrows();
        let row_major = |m: &DMatrix<f64>, cols: &[usize]| -> Vec<f64> {
            (0..m.nrows())
                .flat_map(|i| cols.iter().map(move |&j| m[(i, j)]))
                .collect()
        };
        let all: Vec<usize> = (0..n).collect();
        let keep = !outputs.is_empty();
        let some = |v: Vec<f64>| if keep { v } else { Vec::new() };
        Ok(PointJacobian {
            dx: lin.dx0.clone(),
            a: row_major(&lin.a, &all),
            b: row_major(&lin.b, &LIN_COLUMN),
            y: some(lin.y0.clone()),
            c: some(row_major(&lin.c, &all)),
            d: some(row_major(&lin.d, &LIN_COLUMN)),
            output_names: if keep {
                lin.output_names.clone()
            } else {
                Vec::new()
            },
            kinks: lin.kinks.iter().map(|k| k.to_string()).collect(),
        })
    }
}

/// The state array and the held input of a point, checked: the state's length and finite
/// values, finite inputs, and n_e > 0 where the paper's equations need it.
fn point<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64],
    u: [f64; 4],
) -> CoreResult<([f64; N], ModelInput)> {
    let names = m.state_names();
    let x: [f64; N] = x.try_into().map_err(|_| {
        CoreError::Value(format!(
            "state: expected {N} values ({}), got {}",
            names.join(", "),
            x.len()
        ))
    })?;
    for (name, v) in names.iter().zip(x) {
        if !v.is_finite() {
            return Err(CoreError::Value(format!(
                "state {name} = {v} is not finite"
            )));
        }
    }
    check_finite(u)?;
    let d = Drive::from_array(u);
    d.check(m.options().semantics)
        .map_err(|e| CoreError::Value(e.to_string()))?;
    Ok((x, ModelInput::constant(d)))
}

/// An error naming the first non-finite derivative.
fn finite_rows(names: &[&str], dx: &[f64]) -> CoreResult<()> {
    match names.iter().zip(dx).find(|(_, v)| !v.is_finite()) {
        Some((name, v)) => Err(CoreError::Value(format!(
            "d{name}/dt = {v}: the model is not finite at this state (outside its physical range?)"
        ))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_lists_every_output_column_with_a_unit() {
        let vars = variables();
        let m = mvem::model::Engine12::published();
        for n in m.state_names().iter().chain(Signals::NAMES) {
            let v = vars.iter().find(|v| v.1 == *n).unwrap();
            assert!(!v.2.is_empty(), "{n}");
        }
        let ps = parameters();
        let j_t = ps.iter().find(|p| p.0 == "turbo.j_t").unwrap();
        assert_eq!((j_t.2, j_t.4), ("kg m^2", Params::published().turbo.j_t));
    }

    #[test]
    fn steady_equals_library() {
        let s = steady([1500.0, 110.0, 80.0, 75.0], None, Variant::default()).unwrap();
        let lib = steady_state(
            &mvem::model::Engine8::published(),
            &Drive::new(1500.0, 110.0, 80.0, 75.0),
        )
        .unwrap();
        let get = |n: &str| s.values.iter().find(|(k, _)| k == n).unwrap().1;
        assert_eq!(get("p_im"), lib.x[0]);
        assert_eq!(get("W_c"), lib.signals.w_c);
        assert!(s.physically_valid);
        assert!(matches!(
            steady([f64::NAN, 1.0, 1.0, 1.0], None, Variant::default()),
            Err(CoreError::Value(_))
        ));
    }

    /// `mvem.Model`: at a steady state the derivatives vanish and the Jacobians are the
    /// library's linearization with B's columns in (n_e, u_delta, u_egr, u_vgt) order; bad
    /// points are refused naming the field.
    #[test]
    fn point_model_is_the_linearization_at_a_steady_state() {
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let m = mvem::model::Engine8::published();
        let ss = steady_state(&m, &d).unwrap();
        let lin = linearize_steady(&m, &ss, &LinearizeOptions::default()).unwrap();
        let pm = PointModel::new(None, ModelOrder::Eight).unwrap();
        let u = [1500.0, 110.0, 80.0, 75.0];
        let dx = pm.derivatives(&ss.x, u).unwrap();
        for (v, s) in dx.iter().zip(pm.state_scales()) {
            assert!(v.abs() < 1e-9 * s, "{v}");
        }
        let outputs: Vec<String> = lin.output_names.clone();
        let j = pm.jacobian(&ss.x, u, &outputs, true).unwrap();
        for r in 0..8 {
            for c in 0..8 {
                assert_eq!(j.a[r * 8 + c], lin.a[(r, c)]);
            }
            for (c, &lc) in LIN_COLUMN.iter().enumerate() {
                assert_eq!(j.b[r * 4 + c], lin.b[(r, lc)], "B[{r}, {c}]");
            }
        }
        assert_eq!(j.y, lin.y0);
        assert_eq!(j.d[4 * 2], lin.d[(2, 3)]); // dW_c/dn_e
        assert!(j.kinks.is_empty());
        let none = pm.jacobian(&ss.x, u, &[], true).unwrap();
        assert!(none.c.is_empty() && none.output_names.is_empty() && none.a == j.a);

        let err = |r: CoreResult<Vec<f64>>| match r {
            Err(CoreError::Value(m)) => m,
            other => panic!("{other:?}"),
        };
        assert!(err(pm.derivatives(&ss.x[..7], u)).contains("expected 8 values"));
        let mut x = ss.x;
        x[4] = f64::NAN;
        assert!(err(pm.derivatives(&x, u)).contains("omega_t = NaN"));
        assert!(
            err(pm.derivatives(&ss.x, [f64::INFINITY, 110.0, 80.0, 75.0])).contains("n_e = inf")
        );
        assert!(matches!(
            pm.jacobian(&ss.x, u, &["W_x".to_string()], false),
            Err(CoreError::Value(m)) if m.contains("W_x")
        ));
        // omega_t on the c_m kink (max(omega_t, c_m2), item 33; no guard bit): refused when
        // strict, listed otherwise
        let mut on_kink = ss.x;
        on_kink[4] = Params::published().turbine.c_m[1];
        assert!(matches!(
            pm.jacobian(&on_kink, u, &[], true),
            Err(CoreError::Runtime(_))
        ));
        assert!(!pm
            .jacobian(&on_kink, u, &[], false)
            .unwrap()
            .kinks
            .is_empty());
        let at = [1500.0, 110.0, 0.0, 75.0];
        // the command alone at its saturation limit is differenced on the inner side
        assert!(pm.jacobian(&ss.x, at, &[], true).unwrap().kinks.is_empty());
    }

    /// `mvem.closed_loop`: 10 s of the WHTC give 1001 samples of every trajectory column and
    /// the tuning used in the summary; a tuning with an unknown key or an invalid value, and a
    /// demand outside the speed range, are `Value` errors naming them.
    #[test]
    fn closed_loop_runs_and_refuses_bad_tunings() {
        let r = closed_loop(
            CycleArg::Whtc,
            Some(r#"{"lambda_limit": 1.25}"#),
            None,
            Variant::default(),
            Some(10.0),
            None,
        )
        .unwrap();
        assert_eq!(r.columns.len(), r.names.len());
        assert!(r.columns.iter().all(|c| c.len() == 1001));
        let v: Value = serde_json::from_str(&r.summary).unwrap();
        assert_eq!(v["controller_tuning"]["lambda_limit"], 1.25);
        assert_eq!(v["sample_time_s"], 0.01);
        let value_err = |tuning: Option<&str>, cycle: CycleArg| match closed_loop(
            cycle,
            tuning,
            None,
            Variant::default(),
            Some(1.0),
            None,
        ) {
            Err(CoreError::Value(m)) => m,
            other => panic!("{:?}", other.map(|r| r.summary)),
        };
        assert!(value_err(Some(r#"{"lamda_limit": 1.1}"#), CycleArg::Whtc).contains("lamda_limit"));
        assert!(
            value_err(Some(r#"{"smoke_margin": 2}"#), CycleArg::Whtc).contains("smoke_margin = 2")
        );
        let fast = CycleArg::Demand {
            t: vec![0.0, 1.0],
            n_e: vec![1500.0, 2500.0],
            m_ref: vec![100.0, 100.0],
        };
        assert!(value_err(None, fast).contains("2500 rpm"));
    }

    /// QA: parameters() and the FMU name elements 1-based (`cylinder.c_vol[1]` is c_vol1) but
    /// overrides refused those names. An element is set by its registry path; index 0 is
    /// refused saying the indices are 1-based, an index past the end naming the elements, and
    /// a validation message names the element 1-based.
    #[test]
    fn overrides_set_elements_by_their_one_based_paths() {
        let published = Params::published();
        let p = params_from_overrides(
            r#"{"cylinder.c_vol[3]": 1.2, "compressor": {"q_c[1][2]": 0.5, "q_c[2][1]": 0.5}}"#,
        )
        .unwrap();
        let mut c_vol = published.cylinder.c_vol;
        c_vol[2] = 1.2;
        assert_eq!(p.cylinder.c_vol, c_vol);
        assert_eq!(p.compressor.q_c[0][1], 0.5);
        assert_eq!(p.compressor.q_c[1][0], 0.5);
        assert_eq!(p.compressor.q_c[0][0], published.compressor.q_c[0][0]);
        // every path parameters() lists is accepted and sets that scalar
        for (path, ..) in parameters().iter().filter(|r| r.0.contains('[')) {
            let info = mvem::params::ParamInfo::find(path).unwrap();
            let v = published.value(info);
            let q = params_from_overrides(&format!(r#"{{"{path}": {v:e}}}"#)).unwrap();
            assert_eq!(q, published, "{path}");
        }
        let e = params_from_overrides(r#"{"cylinder.c_vol[0]": 1.2}"#)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "parameter `cylinder.c_vol[0]`: indices are 1-based, as parameters(), the FMU and \
             `mvem params show` name them; `cylinder.c_vol` has the elements cylinder.c_vol[1] \
             (c_vol1) to cylinder.c_vol[3] (c_vol3)"
        );
        let e = params_from_overrides(r#"{"cylinder": {"c_vol[4]": 1.2}}"#)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("parameter `cylinder.c_vol[4]`: no such element"),
            "{e}"
        );
        // the tuning report's names (correlated_with, at_bounds): paper symbols, and fields
        // with their 1-based index (session 38; `c_vol1` was an unknown parameter)
        let q = params_from_overrides(r#"{"c_vol1": 1.2, "a3": 0.5, "c_egr[2]": 0.01}"#).unwrap();
        assert_eq!(q.cylinder.c_vol[0], 1.2);
        assert_eq!((q.compressor.q_c[0][1], q.compressor.q_c[1][0]), (0.5, 0.5));
        assert_eq!(q.egr_valve.c_egr[1], 0.01);
        for (path, symbol, ..) in parameters() {
            let Some(info) = mvem::params::ParamInfo::find(symbol) else {
                continue; // a symbol of several scalars (r_c of compressor and cylinder)
            };
            let v = published.value(info);
            let q = params_from_overrides(&format!(r#"{{"{symbol}": {v:e}}}"#)).unwrap();
            assert_eq!(q, published, "{symbol} ({path})");
        }
        let e = params_from_overrides(r#"{"c_vo1": 1.2}"#)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "unknown parameter `c_vo1`");
        let e = params_from_overrides(r#"{"cylinder.c_vo[1]": 1.2}"#)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "unknown parameter `cylinder.c_vo[1]`");
        let e = params_from_overrides(r#"{"egr_valve.c_egr[1]": 1.0}"#)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("egr_valve.c_egr[1] = 1: c_egr1 must be < 0"),
            "{e}"
        );
    }

    #[test]
    fn overrides_merge_and_reject_unknown() {
        let p =
            params_from_overrides(r#"{"turbo": {"j_t": 1e-4}, "ambient.p_amb": 1.0e5}"#).unwrap();
        assert_eq!(p.turbo.j_t, 1e-4);
        assert_eq!(p.ambient.p_amb, 1.0e5);
        assert_eq!(p.gas, Params::published().gas);
        let e = params_from_overrides(r#"{"turbo": {"jt": 1}}"#).unwrap_err();
        assert!(e.to_string().contains("turbo.jt"), "{e}");
        assert!(matches!(
            params_from_overrides(r#"{"turbo": {"j_t": -1}}"#),
            Err(CoreError::Value(_))
        ));
    }

    /// `time_parallel=2`: the library's time-parallel run (the same columns and rows, values
    /// within a tenth of rtol of the sequential run on 300 s of the WHTC); 0 is refused.
    #[test]
    fn simulate_time_parallel() {
        let text = include_str!("../../../data/whtc_inputs_10hz.csv");
        let rows: Vec<[f64; 5]> = text
            .lines()
            .skip(1)
            .take(3001)
            .map(|l| {
                let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
                [v[0], v[1], v[2], v[3], v[4]]
            })
            .collect();
        let args = |k| SimArgs {
            dt: 0.1,
            time_parallel: k,
            ..SimArgs::default()
        };
        let (ns, seq) = simulate_rows(&rows, args(1), None, Variant::default()).unwrap();
        let (np, par) = simulate_rows(&rows, args(2), None, Variant::default()).unwrap();
        assert_eq!(ns, np);
        assert_eq!(seq[0], par[0]);
        let p_im = ns.iter().position(|n| n == "p_im").unwrap();
        assert_ne!(seq[p_im], par[p_im], "not the time-parallel run");
        for (a, b) in seq[p_im].iter().zip(&par[p_im]) {
            assert!((a - b).abs() <= 1e-7 * a, "{a} vs {b}");
        }
        assert!(matches!(
            simulate_rows(&rows, args(0), None, Variant::default()),
            Err(CoreError::Value(_))
        ));
    }

    #[test]
    fn simulate_rejects_bad_rows_and_options() {
        let rows = [
            [0.0, 1500.0, 110.0, 80.0, 75.0],
            [1.0, 1500.0, 110.0, 80.0, 75.0],
        ];
        let (names, cols) =
            simulate_rows(&rows, SimArgs::default(), None, Variant::default()).unwrap();
        assert_eq!(names[0], "t");
        assert_eq!(cols[0].len(), 101);
        let bad = [[0.0, f64::NAN, 110.0, 80.0, 75.0]];
        assert!(matches!(
            simulate_rows(&bad, SimArgs::default(), None, Variant::default()),
            Err(CoreError::Value(_))
        ));
        let args = SimArgs {
            rtol: -1.0,
            ..SimArgs::default()
        };
        assert!(matches!(
            simulate_rows(&rows, args, None, Variant::default()),
            Err(CoreError::Value(_))
        ));
        let one = [[0.0, 1500.0, 110.0, 80.0, 75.0]];
        assert!(matches!(
            simulate_rows(&one, SimArgs::default(), None, Variant::default()),
            Err(CoreError::Value(_))
        ));
        // 1e8 + 1 output rows are refused before anything runs (the run would take hours and
        // its columns tens of GB); the message names dt and the interval
        let long = SimArgs {
            t_end: Some(1e6),
            ..SimArgs::default()
        };
        match simulate_rows(&rows, long, None, Variant::default()) {
            Err(CoreError::Value(m)) => {
                assert!(m.contains("dt = 0.01") && m.contains("1.000e8"), "{m}")
            }
            other => panic!("expected a refusal, got {:?}", other.map(|r| r.0)),
        }
        let runs = vec![(rows.to_vec(), None)];
        let many = simulate_many_rows(runs, long, Variant::default(), Some(1)).unwrap();
        assert!(matches!(&many[0], Err(CoreError::Value(m)) if m.starts_with("run 0: dt = 0.01")));
        let step = step_response(
            [1500.0, 110.0, 80.0, 75.0],
            "u_vgt",
            65.0,
            "p_im",
            1.0,
            1e6,
            SimArgs::default(),
            None,
            Variant::default(),
        );
        assert!(matches!(step, Err(CoreError::Value(m)) if m.contains("dt = 0.01")));
    }

    #[test]
    fn linearize_equals_library_and_checks_arguments() {
        let d = [1500.0, 110.0, 80.0, 75.0];
        let r = linearize_at(d, None, Variant::default(), &LinArgs::default()).unwrap();
        let m = mvem::model::Engine8::published();
        let ss = steady_state(&m, &Drive::from_array(d)).unwrap();
        let lib = linearize_steady(&m, &ss, &LinearizeOptions::default()).unwrap();
        assert_eq!(r.lin, lib);
        assert_eq!(r.eigenvalues.len(), 8);
        assert!(r.eigenvalues.iter().all(|e| e.0 < 0.0));
        let g = r.dc_gain.unwrap();
        assert_eq!(g.shape(), (7, 4));
        // the u_vgt -> W_c channel of the demo point is non-minimum phase (a RHP zero)
        let z = &r.zeros.iter().find(|(c, _)| c == "u_vgt->W_c").unwrap().1;
        assert!(z.as_ref().unwrap().iter().any(|z| z.0 > 0.0), "{z:?}");
        assert!(r.mimo_zeros.is_some());
        let v12 = Variant::parse(12, "converged").unwrap();
        let r12 = linearize_at(d, None, v12, &LinArgs::default()).unwrap();
        assert_eq!(r12.lin.a.shape(), (12, 12));
        let bad = LinArgs {
            outputs: Some(vec!["nope".into()]),
            ..LinArgs::default()
        };
        let e = linearize_at(d, None, Variant::default(), &bad).unwrap_err();
        assert!(
            matches!(&e, CoreError::Value(m) if m.contains("nope")),
            "{e}"
        );
        assert!(Variant::parse(9, "converged").is_err());
        assert!(Variant::parse(8, "once").is_err());
    }

    #[test]
    fn step_response_metrics_are_those_of_the_samples() {
        let d = [1500.0, 110.0, 80.0, 75.0];
        // the metrics come from samples METRICS_DT apart whatever dt: at that dt they are
        // those of the samples returned, and a coarser dt gives the same metrics
        let args = SimArgs {
            dt: mvem::analysis::experiment::METRICS_DT,
            ..SimArgs::default()
        };
        let coarse = step_response(
            d,
            "u_vgt",
            65.0,
            "W_c",
            1.0,
            4.0,
            SimArgs {
                dt: 0.02,
                ..SimArgs::default()
            },
            None,
            Variant::default(),
        )
        .unwrap();
        let r = step_response(
            d,
            "u_vgt",
            65.0,
            "W_c",
            1.0,
            4.0,
            args,
            None,
            Variant::default(),
        )
        .unwrap();
        assert!(r.metrics.non_minimum_phase);
        assert_eq!(r.metrics.du, -10.0);
        let again = step_metrics(&r.t, &r.y, 1.0, r.metrics.y0, r.metrics.y_final, -10.0).unwrap();
        assert_eq!(again, r.metrics);
        assert_eq!(coarse.metrics, r.metrics);
        assert_eq!(coarse.t.len(), 201);
        let with = |input: &str, output: &str| {
            step_response(
                d,
                input,
                65.0,
                output,
                1.0,
                4.0,
                args,
                None,
                Variant::default(),
            )
        };
        assert!(matches!(with("u_x", "W_c"), Err(CoreError::Value(m)) if m.contains("u_x")));
        assert!(matches!(with("u_vgt", "W_x"), Err(CoreError::Value(m)) if m.contains("W_x")));
    }
}

/// What [`tune`] returns, as JSON texts for the Python layer.
#[derive(Debug)]
pub struct TuneOut {
    /// The tuned parameter set (the nested form `params=` takes).
    pub params_json: String,
    /// The test-cell quantities (tau_me, sensor time constants) estimated or kept.
    pub test_cell_json: String,
    /// The parameter file `mvem tune --out FILE.toml` writes (parameters and `[test_cell]`).
    pub toml: String,
    /// The report `mvem tune --report DIR` writes as `tune_report.json`.
    pub report_json: String,
    /// Warnings and notes (`warning: ...`, `note: ...`), as `mvem tune` prints them.
    pub messages: Vec<String>,
}

/// The paper's tuning steps on the campaign in `data` (the core's
/// `tuning::request::tune_campaign`, as `mvem tune` runs it). `base`: the engine's constants and
/// the parameters of the steps not run, with its parameter file's test-cell section (`None`: the
/// published set). `settings`: a JSON object of `TuneSettings` fields (the command line's
/// option names in snake case; unknown names refused). A bad setting or campaign file is a
/// `Value` error naming it; a failed step is `Runtime`.
pub fn tune(
    data: &Path,
    base: Option<(Params, Option<mvem::io::test_cell::TestCell>)>,
    order: ModelOrder,
    settings: Option<&str>,
) -> CoreResult<TuneOut> {
    use mvem::tuning::request::{tune_campaign, RequestError, TuneSettings};
    let settings: TuneSettings = match settings {
        None => TuneSettings::default(),
        Some(text) => mvem::io::settings_from_json(text)
            .map_err(|e| CoreError::Value(format!("tuning settings: {e}")))?,
    };
    let given = base.is_some();
    let (base, cell) = base.unwrap_or_else(|| (Params::published(), None));
    let run =
        tune_campaign(data, &base, cell.as_ref(), given, order, &settings).map_err(
            |e| match e {
                RequestError::Pipeline(e) => CoreError::Runtime(e.to_string()),
                other => CoreError::Value(other.to_string()),
            },
        )?;
    let json = |v: serde_json::Result<String>| {
        v.map_err(|e| CoreError::Runtime(format!("tuning result: {e}")))
    };
    Ok(TuneOut {
        params_json: json(serde_json::to_string(&run.params))?,
        test_cell_json: json(serde_json::to_string(&run.test_cell))?,
        toml: mvem::io::test_cell::params_with_test_cell_text(&run.params, &run.test_cell, false),
        report_json: json(serde_json::to_string(&run.report))?,
        messages: run.messages,
    })
}

/// What [`validate`] returns.
#[derive(Debug)]
pub struct ValidateOut {
    /// The summary (`validation.json` of `mvem validate`).
    pub summary_json: String,
    /// The dynamometer time constant tau_Me \[s\] applied, if any.
    pub tau_me: Option<f64>,
    /// The sensor time constants (p_im, p_em, W_c, n_t) \[s\] applied.
    pub sensor_lags: [f64; 4],
    /// Notes and warnings, as `mvem validate` prints them.
    pub messages: Vec<String>,
    /// Per validated dynamic data set (when asked): its name, time \[s\] and per output the
    /// measured and simulated series (as `mvem validate --report` plots them).
    pub traces: Vec<Trace>,
}

/// One data set's measured and simulated outputs.
#[derive(Debug)]
pub struct Trace {
    /// Data set name.
    pub set: String,
    /// Sample times \[s\].
    pub t: Vec<f64>,
    /// (output, measured, simulated).
    pub outputs: Vec<(String, Vec<f64>, Vec<f64>)>,
}

/// Draft `data/manifest.toml` from the CSV files in `data` as `mvem campaign --init` does
/// (`mvem::tuning::draft`; an existing manifest is kept unless `force`): the notes on what was
/// guessed.
pub fn draft_manifest(data: &std::path::Path, force: bool) -> CoreResult<Vec<String>> {
    use mvem::tuning::draft::{write_draft, WriteDraftError};
    let d = write_draft(data, force).map_err(|e| match e {
        WriteDraftError::Exists(p) => {
            CoreError::Value(format!("{}: exists; force=True replaces it", p.display()))
        }
        WriteDraftError::Data(e) => CoreError::Value(e.to_string()),
        WriteDraftError::Write(m) => CoreError::Runtime(m),
    })?;
    Ok(d.notes)
}

/// What the campaign in `data` holds and which tuning steps it supports, as JSON (the object of
/// `mvem campaign --json`; `mvem::tuning::summary`). A campaign that does not load is a
/// [`CoreError::Value`] naming the file, line and column.
pub fn campaign(data: &std::path::Path) -> CoreResult<String> {
    let c = mvem::tuning::data::load_campaign(data).map_err(|e| CoreError::Value(e.to_string()))?;
    serde_json::to_string(&mvem::tuning::summary::summarize(&c))
        .map_err(|e| CoreError::Runtime(e.to_string()))
}

/// The relative errors (eqs (4), (5)) of `params` on the campaign in `data`, as `mvem validate`
/// computes them (the core's `tuning::request::validate_campaign`); with `traces`, also the
/// measured and simulated outputs of each validated dynamic set.
pub fn validate(
    data: &Path,
    params: (Params, Option<mvem::io::test_cell::TestCell>),
    order: ModelOrder,
    tau_me: Option<f64>,
    sensor_lags: Option<&str>,
    roles: Option<&str>,
    traces: bool,
) -> CoreResult<ValidateOut> {
    use mvem::tuning::data::StepKind;
    use mvem::tuning::request::{validate_campaign, RequestError};
    let (p, cell) = params;
    let run = validate_campaign(data, &p, cell.as_ref(), order, tau_me, sensor_lags, roles)
        .map_err(|e| match e {
            RequestError::Setting(_) | RequestError::Data(_) => CoreError::Value(e.to_string()),
            other => CoreError::Runtime(other.to_string()),
        })?;
    let mut out = Vec::new();
    if traces {
        let c = &run.campaign;
        for (info, d) in c.manifest.datasets.iter().zip(&c.dynamic) {
            if !run.report.datasets.iter().any(|x| x.name == d.name) {
                continue;
            }
            let outputs = match info.kind {
                StepKind::Actuator => [("u_egr", "u_egr_pos", true), ("u_vgt", "u_vgt_pos", false)]
                    .into_iter()
                    .filter_map(|(cmd, pos, egr)| {
                        let (u, y) = (d.get(cmd)?, d.get(pos)?);
                        let model = mvem::tuning::steps::actuator_response(&p, &d.t, u, egr);
                        Some((pos.to_string(), y.to_vec(), model))
                    })
                    .collect(),
                _ => {
                    let rtol = SimOptions::default().rtol;
                    let sims = mvem::tuning::validate::simulated_outputs(
                        order,
                        &p,
                        d,
                        run.tau_me,
                        &run.sensor_lags,
                        rtol,
                    )
                    .map_err(|e| CoreError::Runtime(format!("data set {}: {e}", d.name)))?;
                    sims.into_iter()
                        .filter_map(|(name, sim)| {
                            Some((name.to_string(), d.get(name)?.to_vec(), sim))
                        })
                        .collect()
                }
            };
            out.push(Trace {
                set: d.name.clone(),
                t: d.t.clone(),
                outputs,
            });
        }
    }
    Ok(ValidateOut {
        summary_json: run.report.summary_json().to_string(),
        tau_me: run.tau_me,
        sensor_lags: run.sensor_lags.as_array(),
        messages: run.messages,
        traces: out,
    })
}

/// A virtual test-cell campaign written to `out` as `mvem lab` writes it (the core's
/// `tuning::request::write_lab_campaign`): `settings` a JSON object of `LabSettings` fields
/// (unknown names refused). Returns (stationary points, data set names, dynamic samples).
pub fn lab(
    out: &Path,
    params: Option<Params>,
    order: ModelOrder,
    settings: Option<&str>,
) -> CoreResult<(usize, Vec<String>, usize)> {
    use mvem::tuning::request::{write_lab_campaign, LabSettings, RequestError};
    let settings: LabSettings = match settings {
        None => LabSettings::default(),
        Some(text) => mvem::io::settings_from_json(text)
            .map_err(|e| CoreError::Value(format!("lab settings: {e}")))?,
    };
    let p = params.unwrap_or_else(Params::published);
    let c = write_lab_campaign(out, &p, order, &settings).map_err(|e| match e {
        RequestError::Setting(_) => CoreError::Value(e.to_string()),
        other => CoreError::Runtime(other.to_string()),
    })?;
    Ok((
        c.stationary.len(),
        c.dynamic.iter().map(|d| d.name.clone()).collect(),
        c.dynamic.iter().map(|d| d.t.len()).sum(),
    ))
}
