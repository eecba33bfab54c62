//! The pyo3 layer: conversions only (see [`crate::core`]).

use crate::core::{self, CoreError, LinArgs, SimArgs, Variant};
use mvem::analysis::step::{Excursion, StepMetrics};
use mvem::io::csv_inputs::{input_ranges, range_warnings_of_rows};
use mvem::numerics::Num;
use mvem::params::Params;
use mvem::sim::input::INPUT_COLUMNS;
use mvem::sim::MAX_TIME_CHUNKS;
use pyo3::exceptions::{PyOverflowError, PyRuntimeError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict, PyList, PyString, PyTuple};
use std::sync::{Mutex, PoisonError};

fn to_py_err(e: CoreError) -> PyErr {
    match e {
        CoreError::Value(m) => PyValueError::new_err(m),
        CoreError::Runtime(m) => PyRuntimeError::new_err(m),
    }
}

/// An integer argument as Python gave it: its value if it fits an i64, else its text. pyo3's
/// conversion to an unsigned or i64 parameter raised OverflowError for `time_parallel=-1` or
/// `model=2**70` (QA); [`IntArg::within`] raises ValueError naming the argument and the range.
/// Anything that is not an integer (`__index__`) is a TypeError naming the argument, as before.
enum IntArg {
    /// A value that fits an i64.
    Int(i64),
    /// A larger integer, as Python prints it.
    Big(String),
}

impl<'py> FromPyObject<'py> for IntArg {
    fn extract_bound(ob: &Bound<'py, PyAny>) -> PyResult<Self> {
        match ob.extract::<i64>() {
            Ok(v) => Ok(Self::Int(v)),
            Err(e) if e.is_instance_of::<PyOverflowError>(ob.py()) => {
                Ok(Self::Big(ob.str()?.to_string()))
            }
            Err(e) => Err(e),
        }
    }
}

impl std::fmt::Display for IntArg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Int(v) => write!(f, "{v}"),
            Self::Big(t) => f.write_str(t),
        }
    }
}

impl IntArg {
    /// The value if it lies in `lo..=hi`, else a ValueError naming `name`, the value and the
    /// range.
    fn within(&self, name: &str, lo: i64, hi: i64) -> PyResult<i64> {
        match self {
            Self::Int(v) if (lo..=hi).contains(v) => Ok(*v),
            _ => Err(PyValueError::new_err(format!(
                "{name} = {self}: expected an integer in [{lo}, {hi}]"
            ))),
        }
    }

    /// [`IntArg::within`] as a usize (`lo` >= 0).
    fn count(&self, name: &str, lo: usize, hi: usize) -> PyResult<usize> {
        let v = self.within(name, lo as i64, hi as i64)?;
        Ok(usize::try_from(v).expect("within a non-negative range"))
    }
}

/// The model variant of the arguments `model` (8, 10, 12) and `cylinder_temp`.
fn variant_of(model: &IntArg, cylinder_temp: &str) -> PyResult<Variant> {
    match model {
        IntArg::Int(m) => Variant::parse(*m, cylinder_temp).map_err(to_py_err),
        IntArg::Big(_) => Err(PyValueError::new_err(format!(
            "model = {model}: expected 8, 10 or 12"
        ))),
    }
}

/// The first float of a (nested) params mapping or list that is NaN or infinite: its path
/// (`group.field`, `[i]` 1-based for list elements, as the parameter names) and value.
fn non_finite_entry(obj: &Bound<'_, PyAny>, prefix: &str) -> PyResult<Option<(String, f64)>> {
    let join = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    if let Ok(d) = obj.downcast::<PyDict>() {
        for (k, v) in d.iter() {
            let key = k.str()?.to_string();
            if let Some(hit) = non_finite_entry(&v, &join(&key))? {
                return Ok(Some(hit));
            }
        }
    } else if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        for (i, v) in obj.try_iter()?.enumerate() {
            let v = v?;
            if let Some(hit) = non_finite_entry(&v, &mvem::params::element_name(prefix, &[i]))? {
                return Ok(Some(hit));
            }
        }
    } else if let Ok(x) = obj.downcast::<pyo3::types::PyFloat>() {
        let v = x.value();
        if !v.is_finite() {
            return Ok(Some((prefix.to_string(), v)));
        }
    }
    Ok(None)
}

fn parse_params(py: Python<'_>, params: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Params>> {
    let Some(obj) = params else { return Ok(None) };
    if obj.is_none() {
        return Ok(None);
    }
    if obj.is_instance_of::<PyDict>() {
        // JSON has no NaN or infinity (json.dumps writes tokens serde refuses without a name)
        if let Some((path, v)) = non_finite_entry(obj, "")? {
            return Err(PyValueError::new_err(format!(
                "params: `{path}` = {v} is not a finite number"
            )));
        }
        let json: String = py
            .import("json")?
            .call_method1("dumps", (obj,))
            .map_err(|e| PyValueError::new_err(format!("params: {e}")))?
            .extract()?;
        return core::params_from_overrides(&json)
            .map(Some)
            .map_err(to_py_err);
    }
    let os = py.import("os")?;
    let path: String = os
        .call_method1("fspath", (obj,))
        .map_err(|_| {
            PyValueError::new_err("params must be None, a dict or a path to a TOML/JSON file")
        })?
        .extract()
        .map_err(|_| PyValueError::new_err("params path must be a str path"))?;
    core::params_from_path(std::path::Path::new(&path))
        .map(Some)
        .map_err(to_py_err)
}

/// Issue `msg` as a Python `UserWarning` (attributed to the caller's line).
fn user_warning(py: Python<'_>, msg: String) -> PyResult<()> {
    let msg = std::ffi::CString::new(msg).unwrap_or_default();
    PyErr::warn(py, &py.get_type::<PyUserWarning>(), &msg, 1)
}

/// The input saturation ranges of a parameter set (`None`: the published set): its
/// `input_saturation` (n_e, u_delta and the EGR and VGT command ranges).
fn ranges_of(p: Option<&Params>) -> [(&'static str, f64, f64); 4] {
    match p {
        Some(p) => input_ranges(&p.input_saturation),
        None => input_ranges(&Default::default()),
    }
}

/// Whether a value of `values` (n_e, u_delta, u_egr, u_vgt) lies outside its range of
/// `ranges`: what [`warn_out_of_range`] warns about.
fn out_of_range(values: [f64; 4], ranges: &[(&str, f64, f64); 4]) -> bool {
    ranges
        .iter()
        .zip(values)
        .any(|((_, lo, hi), v)| outside(v, *lo, *hi))
}

/// Whether `v` is a finite value outside `[lo, hi]`: a non-finite value is refused with an
/// error where it is checked, so it gets no clamp warning first.
fn outside(v: f64, lo: f64, hi: f64) -> bool {
    v.is_finite() && (v < lo || v > hi)
}

/// The authors' implementation saturates the inputs (`mvem::io::csv_inputs::input_ranges` of the
/// parameter set `p`): a value outside its range is used clamped, and Python is told so by a
/// `UserWarning` naming the input, its value and the range (the CLI prints the same on stderr).
/// `what` says where.
fn warn_out_of_range(
    py: Python<'_>,
    what: &str,
    values: [f64; 4],
    ranges: &[(&str, f64, f64); 4],
) -> PyResult<()> {
    for ((name, lo, hi), v) in ranges.iter().zip(values) {
        if outside(v, *lo, *hi) {
            let msg = format!(
                "{what}: {name} = {} is outside [{lo}, {hi}]; the authors' saturation clamps it",
                Num(v)
            );
            user_warning(py, msg)?;
        }
    }
    Ok(())
}

/// The parameter set given from Python ([`parse_params`]), with the range warnings of the
/// operating point `point` (n_e, u_delta, u_egr, u_vgt) against its input saturation.
fn params_at_point(
    py: Python<'_>,
    params: Option<&Bound<'_, PyAny>>,
    what: &str,
    point: [f64; 4],
) -> PyResult<Option<Params>> {
    let p = parse_params(py, params)?;
    warn_out_of_range(py, what, point, &ranges_of(p.as_ref()))?;
    Ok(p)
}

/// [`warn_out_of_range`] for input rows (t, n_e, u_delta, u_egr, u_vgt): one warning per channel
/// that leaves its range, with the first time and the values outside, as the CLI prints them
/// (`mvem::io::csv_inputs::range_warnings_of_rows`).
fn warn_rows_out_of_range(
    py: Python<'_>,
    what: &str,
    rows: &[[f64; 5]],
    p: Option<&Params>,
) -> PyResult<()> {
    let rows = rows.iter().map(|r| (r[0], [r[1], r[2], r[3], r[4]]));
    for w in range_warnings_of_rows(rows, &ranges_of(p)) {
        user_warning(py, format!("{what}: {w}"))?;
    }
    Ok(())
}

fn float_list(np: &Bound<'_, PyModule>, obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f64>> {
    let arr = np
        .call_method1("asarray", (obj, "float64"))
        .map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?;
    let ndim: usize = arr.getattr("ndim")?.extract()?;
    if ndim != 1 {
        return Err(PyValueError::new_err(format!(
            "{what}: expected a 1-D array, got {ndim}-D"
        )));
    }
    f64_values(np, &arr)
}

/// A 1-D float64 numpy array holding `v`: through one bytearray (`numpy.frombuffer`, writable,
/// native byte order) instead of a list of Python floats, which costs an object per value (a
/// WHTC at 0.1 s returns 50 columns of 18 001 values).
fn f64_array<'py>(np: &Bound<'py, PyModule>, v: &[f64]) -> PyResult<Bound<'py, PyAny>> {
    if v.is_empty() {
        return np.call_method1("zeros", (0, "float64"));
    }
    // the values written straight into the bytearray's memory (no intermediate copy)
    let buf = PyByteArray::new_with(np.py(), std::mem::size_of_val(v), |b| {
        for (w, x) in b.chunks_exact_mut(8).zip(v) {
            w.copy_from_slice(&x.to_ne_bytes());
        }
        Ok(())
    })?;
    np.call_method1("frombuffer", (buf, "float64"))
}

/// The values of a float64 numpy array `arr` in C order, read through its bytes (`tobytes`)
/// instead of a list of Python floats.
fn f64_values(np: &Bound<'_, PyModule>, arr: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    let c = np.call_method1("ascontiguousarray", (arr, "float64"))?;
    let b = c.call_method0("tobytes")?;
    let bytes = b.downcast::<PyBytes>()?.as_bytes();
    Ok(bytes
        .chunks_exact(8)
        .map(|w| f64::from_ne_bytes(w.try_into().expect("chunks of 8 bytes")))
        .collect())
}

fn input_rows(py: Python<'_>, inputs: &Bound<'_, PyAny>) -> PyResult<Vec<[f64; 5]>> {
    let np = py.import("numpy")?;
    if let Ok(d) = inputs.downcast::<PyDict>() {
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for name in INPUT_COLUMNS {
            let col = d.get_item(name)?.ok_or_else(|| {
                PyValueError::new_err(format!(
                    "inputs: missing column `{name}` (need {})",
                    INPUT_COLUMNS.join(", ")
                ))
            })?;
            cols.push(float_list(&np, &col, &format!("inputs[{name:?}]"))?);
        }
        let n = cols[0].len();
        if let Some((i, c)) = cols.iter().enumerate().find(|(_, c)| c.len() != n) {
            return Err(PyValueError::new_err(format!(
                "inputs: column `{}` has {} values, `time_s` has {n}",
                INPUT_COLUMNS[i],
                c.len()
            )));
        }
        return Ok((0..n)
            .map(|k| std::array::from_fn(|c| cols[c][k]))
            .collect());
    }
    let arr = np
        .call_method1("asarray", (inputs, "float64"))
        .map_err(|e| PyValueError::new_err(format!("inputs: {e}")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    if shape.len() != 2 || shape[1] != 5 {
        return Err(PyValueError::new_err(format!(
            "inputs: expected a dict of columns or a 2-D array with 5 columns ({}), got shape {shape:?}",
            INPUT_COLUMNS.join(", ")
        )));
    }
    let flat = f64_values(&np, &arr)?;
    Ok(flat
        .chunks_exact(5)
        .map(|r| std::array::from_fn(|c| r[c]))
        .collect())
}

/// Simulate the 8-state model from the steady state at the first input row.
///
/// inputs: dict with columns time_s [s], n_e_rpm [rpm], u_delta_mg [mg/cycle/cylinder],
///     u_egr_pct [%], u_vgt_pct [%] (1-D arrays), or a 2-D array with these 5 columns. Values are
///     interpolated linearly between rows; two rows with the same time make a step.
/// t_end: end time [s] (default: the last input time; inputs are held after it).
/// dt: output interval [s]. rtol, atol: integrator tolerances (atol relative to the state scales;
///     default: equal to rtol, as the CLI and the library).
/// params: None (published set), a dict of overrides ({"turbo": {"j_t": 1e-4}} or
///     {"turbo.j_t": 1e-4}) or a path to a TOML/JSON parameter file.
/// model: 8 (the paper's model), 10 or 12 states (section 9 extensions).
/// cylinder_temp: "converged" (default) or "one-iteration" (the authors' Simulink Memory blocks).
/// numeric_actuators: integrate the actuator states numerically like the other states (default
///     False: in closed form on each segment between input breakpoints, docs/integrator.md).
/// time_parallel: integrate in this many time chunks at once (1 to 256), one thread each (default 1: the
///     sequential run, reproducible bits); the result agrees with the sequential run to far
///     below the tolerance (each chunk's start is checked; docs/integrator.md).
/// x0: start state (a dict of every state name -> value, or an array in state order; default
///     None: the steady state of the first input row). The commands before the first row are
///     that row's (so are the delayed commands at the start). A value outside the authors'
///     integrator limits is clipped into them, with a UserWarning naming the state, the value,
///     the limits and the value used (as `mvem simulate --initial-state` warns).
///
/// Returns a dict of numpy arrays: "t" [s], the states (8 states: p_im [Pa], p_em [Pa], X_Oim,
/// X_Oem [-], omega_t [rad/s], u_egr1, u_egr2, u_vgt_act [%]; 10 states add T_im, T_em [K];
/// 12 add p_c [Pa], T_ic [K]) and every signal (W_c [kg/s], n_t [rpm], ...; a signal named like
/// a state is the state). Raises ValueError for bad inputs/options/parameters, RuntimeError if
/// the solver fails.
#[pyfunction]
#[pyo3(signature = (inputs, t_end=None, dt=0.01, rtol=1e-6, atol=None, params=None, model=IntArg::Int(8), cylinder_temp="converged", numeric_actuators=false, time_parallel=IntArg::Int(1), x0=None), text_signature = r#"(inputs, t_end=None, dt=0.01, rtol=1e-6, atol=None, params=None, model=8, cylinder_temp="converged", numeric_actuators=False, time_parallel=1, x0=None)"#)]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    inputs: &Bound<'py, PyAny>,
    t_end: Option<f64>,
    dt: f64,
    rtol: f64,
    atol: Option<f64>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
    cylinder_temp: &str,
    numeric_actuators: bool,
    time_parallel: IntArg,
    x0: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, cylinder_temp)?;
    let time_parallel = time_parallel.count("time_parallel", 1, MAX_TIME_CHUNKS)?;
    let rows = input_rows(py, inputs)?;
    let p = parse_params(py, params)?;
    warn_rows_out_of_range(py, "simulate", &rows, p.as_ref())?;
    let args = SimArgs {
        time_parallel,
        ..sim_args(t_end, dt, rtol, atol, numeric_actuators)
    };
    let start = x0
        .filter(|x| !x.is_none())
        .map(|x| start_state(py, x))
        .transpose()?;
    if let Some(x) = &start {
        warn_start_clipped(py, "simulate", p.as_ref(), variant, x)?;
    }
    let cols = cancellable(py, move || {
        core::simulate_rows_from(&rows, args, p, variant, start.as_ref())
    })?
    .map_err(to_py_err)?;
    columns_dict(py, cols)
}

/// `x0` of simulate_many for `runs` runs: none, one start state for all (a dict or a 1-D
/// array), or one per run (a list of None / dict / array, or a 2-D array with a row per run).
/// The outer error is an `x0` that fits no run (a bad shared state, a list of the wrong length);
/// a bad per-run entry is that run's error (its message without the "run i: " prefix).
fn start_states(
    py: Python<'_>,
    x0: Option<&Bound<'_, PyAny>>,
    runs: usize,
) -> PyResult<Vec<PyResult<Option<core::StartState>>>> {
    let Some(x0) = x0.filter(|x| !x.is_none()) else {
        return Ok((0..runs).map(|_| Ok(None)).collect());
    };
    let per_run: Option<Vec<Bound<'_, PyAny>>> =
        if x0.is_instance_of::<PyList>() || x0.is_instance_of::<PyTuple>() {
            let items: Vec<Bound<'_, PyAny>> = x0.try_iter()?.collect::<PyResult<_>>()?;
            // a list of numbers is one state for all runs
            let numbers = items.iter().all(|i| i.extract::<f64>().is_ok());
            (!numbers).then_some(items)
        } else if x0.is_instance_of::<PyDict>() {
            None
        } else {
            let ndim: usize = py
                .import("numpy")?
                .call_method1("asarray", (x0,))?
                .getattr("ndim")?
                .extract()?;
            (ndim == 2)
                .then(|| x0.try_iter().and_then(|it| it.collect()).ok())
                .flatten()
        };
    match per_run {
        None => {
            let x = start_state(py, x0)?;
            Ok((0..runs).map(|_| Ok(Some(x.clone()))).collect())
        }
        Some(items) if items.len() != runs => Err(PyValueError::new_err(format!(
            "x0: {} start states for {runs} inputs (give one per run, or one for all)",
            items.len()
        ))),
        Some(items) => Ok(items
            .iter()
            .map(|x| {
                if x.is_none() {
                    Ok(None)
                } else {
                    start_state(py, x).map(Some)
                }
            })
            .collect()),
    }
}

/// The start state `x0` outside the integrator limits of the model of `p`, `variant` (which
/// clip it): one `UserWarning` per state, naming it, its value, the limits and the value the
/// run starts from, as `mvem simulate --initial-state` warns on stderr. A bad `x0` (a missing
/// or unknown state) is the ValueError.
fn warn_start_clipped(
    py: Python<'_>,
    what: &str,
    p: Option<&Params>,
    variant: Variant,
    x0: &core::StartState,
) -> PyResult<()> {
    for w in core::start_state_warnings(p, variant, x0).map_err(to_py_err)? {
        user_warning(py, format!("{what}: x0: {w}"))?;
    }
    Ok(())
}

/// `x0` of simulate: a dict of state name -> value, or an array of the states in order.
fn start_state(py: Python<'_>, x0: &Bound<'_, PyAny>) -> PyResult<core::StartState> {
    if let Ok(d) = x0.downcast::<PyDict>() {
        let mut kv = Vec::with_capacity(d.len());
        for (k, v) in d.iter() {
            let name: String = k
                .extract()
                .map_err(|_| PyValueError::new_err("x0: the keys must be state names"))?;
            let value: f64 = v
                .extract()
                .map_err(|_| PyValueError::new_err(format!("x0[{name:?}]: not a number")))?;
            kv.push((name, value));
        }
        return Ok(core::StartState::Named(kv));
    }
    let np = py.import("numpy")?;
    Ok(core::StartState::Values(float_list(&np, x0, "x0")?))
}

/// The simulation options of simulate and simulate_many (atol defaults to rtol).
fn sim_args(
    t_end: Option<f64>,
    dt: f64,
    rtol: f64,
    atol: Option<f64>,
    numeric_actuators: bool,
) -> SimArgs {
    SimArgs {
        t_end,
        dt,
        rtol,
        atol: atol.unwrap_or(rtol),
        numeric_actuators,
        time_parallel: 1,
    }
}

/// A simulation's columns as a dict of numpy arrays.
fn columns_dict(py: Python<'_>, (names, cols): core::Columns) -> PyResult<Bound<'_, PyDict>> {
    let np = py.import("numpy")?;
    let out = PyDict::new(py);
    // a signal named like a state (T_em in the 10-state model) comes after it: keep the state
    for (n, c) in names.into_iter().zip(cols) {
        if !out.contains(&n)? {
            out.set_item(n, f64_array(&np, &c)?)?;
        }
    }
    Ok(out)
}

/// Many simulations at once on all cores (parameter or input variations).
///
/// inputs: a list of inputs, each as in simulate (a dict of columns or a 2-D array); run i
///     simulates inputs[i] from the steady state at its first row.
/// params: None (published set), one dict of overrides or path for every run, or a list with one
///     entry (None, dict or path) per run (parameter variations: repeat the inputs).
/// threads: worker threads (None: one per core). The GIL is released while the runs execute;
///     Ctrl-C (KeyboardInterrupt) stops the ensemble once the runs in progress end.
/// on_error: "raise" (default): raise the first failed run's error (ValueError or
///     RuntimeError, "run i: ..."; a run whose inputs, parameters or x0 are invalid is raised
///     before any run starts, a solver failure after all runs); "return": a failed run's slot
///     holds its exception object instead of a dict (also for invalid inputs, parameters or x0
///     of that run), the other runs are run and returned as usual. Arguments shared by every
///     run (options, one params or x0 for all, lists of the wrong length) raise either way.
/// t_end, dt, rtol, atol, model, cylinder_temp, numeric_actuators: as in simulate, for every run.
/// x0: None (each run from the steady state at its first row), one start state for every run
///     (a dict or a 1-D array, as in simulate), or one per run (a list of None, dicts or arrays,
///     or a 2-D array with a row per run): scenarios from one estimated state, say. States
///     outside the integrator limits are clipped with a UserWarning, as in simulate.
///
/// Returns a list of dicts of numpy arrays, in the order of the inputs; each equals
/// simulate(inputs[i], ..., x0=x0[i]) of the same arguments.
#[pyfunction]
#[pyo3(signature = (inputs, params=None, threads=None, on_error="raise", t_end=None, dt=0.01, rtol=1e-6, atol=None, model=IntArg::Int(8), cylinder_temp="converged", numeric_actuators=false, x0=None), text_signature = r#"(inputs, params=None, threads=None, on_error="raise", t_end=None, dt=0.01, rtol=1e-6, atol=None, model=8, cylinder_temp="converged", numeric_actuators=False, x0=None)"#)]
#[allow(clippy::too_many_arguments)]
fn simulate_many<'py>(
    py: Python<'py>,
    inputs: &Bound<'py, PyAny>,
    params: Option<&Bound<'py, PyAny>>,
    threads: Option<IntArg>,
    on_error: &str,
    t_end: Option<f64>,
    dt: f64,
    rtol: f64,
    atol: Option<f64>,
    model: IntArg,
    cylinder_temp: &str,
    numeric_actuators: bool,
    x0: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let variant = variant_of(&model, cylinder_temp)?;
    let raise = match on_error {
        "raise" => true,
        "return" => false,
        other => {
            return Err(PyValueError::new_err(format!(
                "on_error = {other:?}: expected \"raise\" or \"return\""
            )))
        }
    };
    let threads = threads
        .map(|n| n.count("threads", 1, MAX_THREADS))
        .transpose()?;
    if inputs.is_instance_of::<PyDict>() || inputs.is_instance_of::<PyString>() {
        return Err(PyValueError::new_err(
            "inputs: expected a list of inputs (one dict or 2-D array per run)",
        ));
    }
    let items: Vec<Bound<'py, PyAny>> = inputs
        .try_iter()
        .map_err(|_| PyValueError::new_err("inputs: expected a list of inputs (one per run)"))?
        .collect::<PyResult<_>>()?;
    let n = items.len();
    // per run: its inputs, its parameters, its start state; the first problem is its error
    let per_run_params: Vec<PyResult<Option<Params>>> = match params {
        Some(list) if list.is_instance_of::<PyList>() || list.is_instance_of::<PyTuple>() => {
            let list: Vec<Bound<'py, PyAny>> = list.try_iter()?.collect::<PyResult<_>>()?;
            if list.len() != n {
                return Err(PyValueError::new_err(format!(
                    "params: a list of {} entries for {n} inputs (give one per run, or one for all)",
                    list.len()
                )));
            }
            list.iter().map(|p| parse_params(py, Some(p))).collect()
        }
        p => {
            let shared = parse_params(py, p)?;
            (0..n).map(|_| Ok(shared.clone())).collect()
        }
    };
    let starts = start_states(py, x0, n)?;
    let mut runs: Vec<core::CoreResult<core::Run>> = Vec::with_capacity(n);
    let mut run_starts = Vec::with_capacity(n);
    for (i, ((item, p), x)) in items.iter().zip(per_run_params).zip(starts).enumerate() {
        let what = format!("simulate_many run {i}");
        let run = (|| {
            let rows = input_rows(py, item)?;
            let p = p?;
            let x = x?;
            warn_rows_out_of_range(py, &what, &rows, p.as_ref())?;
            if let Some(x) = &x {
                warn_start_clipped(py, &what, p.as_ref(), variant, x)?;
            }
            Ok::<_, PyErr>(((rows, p), x))
        })();
        match run {
            Ok((r, x)) => {
                runs.push(Ok(r));
                run_starts.push(x);
            }
            // a warning turned into an error (warnings.simplefilter("error")) is raised as is
            Err(e) if raise || !e.is_instance_of::<PyValueError>(py) => {
                return Err(if e.is_instance_of::<PyValueError>(py) {
                    PyValueError::new_err(format!("run {i}: {}", e.value(py)))
                } else {
                    e
                });
            }
            Err(e) => {
                runs.push(Err(core::CoreError::Value(e.value(py).to_string())));
                run_starts.push(None);
            }
        }
    }
    let args = sim_args(t_end, dt, rtol, atol, numeric_actuators);
    let token = mvem::numerics::cancel::CancelToken::new();
    let results = interruptible(py, &token, None, move || {
        core::simulate_many_rows_from(runs, &run_starts, args, variant, threads)
    })?
    .map_err(to_py_err)?;
    let out = PyList::empty(py);
    for r in results {
        match r {
            Ok(cols) => out.append(columns_dict(py, cols)?)?,
            Err(e) if raise => return Err(to_py_err(e)),
            Err(e) => out.append(to_py_err(e).into_value(py))?,
        }
    }
    Ok(out)
}

/// Most worker threads `simulate_many` accepts.
const MAX_THREADS: usize = 1024;

/// A drive cycle in closed loop: the baseline EGR/VGT and engine controllers around the model,
/// as `mvem closed-loop` runs it (docs/control.md).
///
/// cycle: "whtc" or None (default: the WHTC denormalized with this engine's mapping curve), or a speed/torque
///     demand: a dict with arrays "t" [s], "n_e" [rpm], "M_ref" [Nm], or a 2-D array with these
///     3 columns (linear between rows, two rows at one time a step there; speeds in the
///     parameter set's range, torque at most the full-load torque), or the path of a cycle file (os.PathLike, or a str other than
///     "whtc"): a demand CSV (t, n_e, M_ref) or a normalized cycle (Time [s], Speed [%],
///     Torque [%], "m" motoring: UN GTR No. 4's form, denormalized as the WHTC), as
///     `mvem closed-loop --cycle FILE` reads it.
/// tuning: a dict of the baseline controllers' tuning fields (control::baseline::BaselineTuning:
///     lambda_limit, smoke_margin, torque=[kp, ki], x_egr_vgt, x_egr_egr, lambda_egr, lambda_vgt,
///     d_x, d_lambda, lambda_error_cap, u_vgt_full_load, vgt_gain_closed, vgt_gain_knee (the VGT
///     loops' gain schedule), egr_gain_closed, egr_gain_knee (the EGR-valve loops'),
///     vgt_hold_below_egr (the VGT hold near the shut EGR valve), egr_open_beyond_setpoint (how
///     far the valve may open beyond its position set-point where the set-point pair is out of
///     reach; 100: no limit), dp_vgt_limit, dp_vgt=[kp, ki] (the exhaust back-pressure limit on
///     the VGT, kPa), vgt_release_below_egr (the x_egr loop leaves the VGT alone below this EGR
///     command; 0: never), vgt_release_motored_band (the x_egr loop leaves the VGT alone while
///     motored with p_em <= p_im, back once p_em - p_im exceeds this band, kPa; 0: never)); the
///     others keep their defaults.
/// params, model: as in simulate. duration: run only the first seconds of the cycle.
/// margins: every so many seconds of the run, the loop margins of the air-path loops in feedback
///     at that sample (as `mvem closed-loop --margins S`; docs/control.md).
///
/// Returns a dict: "trajectory" (dict of numpy arrays, one row per 10 ms controller sample: t,
/// n_e, u_delta, u_egr, u_vgt, M_ref, M_e, lambda_O, lambda_O_ref, x_egr, x_egr_ref, ...,
/// egr_loop, vgt_loop: which loop gave the command, 1 main, 2 limiter, 0 none, NaN no loop),
/// with margins also "margins" (every_s, points, analysed, no_loop, refused, unstable_t,
/// loops: the extremes per loop, samples: a list of dicts per analysed sample, as loop_margins
/// gives them),
/// "stats" (the regulation's cycle statistics), "violations" (list of str), "passes" (bool),
/// "reference_speeds_rpm", "solver", "controller_tuning", "sample_time_s". ValueError for a bad
/// cycle, tuning or parameters (naming the row or field), RuntimeError if the plant fails.
#[pyfunction]
#[pyo3(signature = (cycle=None, tuning=None, params=None, model=IntArg::Int(8), duration=None, margins=None), text_signature = r#"(cycle=None, tuning=None, params=None, model=8, duration=None, margins=None)"#)]
fn closed_loop<'py>(
    py: Python<'py>,
    cycle: Option<&Bound<'py, PyAny>>,
    tuning: Option<&Bound<'py, PyAny>>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
    duration: Option<f64>,
    margins: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let np = py.import("numpy")?;
    let cycle = if cycle.is_none_or(|c| c.is_none()) {
        core::CycleArg::Whtc
    } else if let Some(name) = cycle.and_then(|c| c.extract::<String>().ok()) {
        if name == "whtc" {
            core::CycleArg::Whtc
        } else {
            core::CycleArg::File(name.into())
        }
    } else if let Some(path) = cycle
        .filter(|c| c.hasattr("__fspath__").unwrap_or(false))
        .map(|c| fspath(py, c, "cycle"))
    {
        core::CycleArg::File(path?.into())
    } else if let Some(d) = cycle.and_then(|c| c.downcast::<PyDict>().ok()) {
        let mut cols = Vec::new();
        for name in ["t", "n_e", "M_ref"] {
            let c = d.get_item(name)?.ok_or_else(|| {
                PyValueError::new_err(format!(
                    "cycle: missing column `{name}` (need t, n_e, M_ref)"
                ))
            })?;
            cols.push(float_list(&np, &c, &format!("cycle[{name:?}]"))?);
        }
        let m_ref = cols.pop().unwrap_or_default();
        let n_e = cols.pop().unwrap_or_default();
        let t = cols.pop().unwrap_or_default();
        core::CycleArg::Demand { t, n_e, m_ref }
    } else {
        let arr = np
            .call_method1("asarray", (cycle, "float64"))
            .map_err(|e| PyValueError::new_err(format!("cycle: {e}")))?;
        let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
        if shape.len() != 2 || shape[1] != 3 {
            return Err(PyValueError::new_err(format!(
                "cycle: expected \"whtc\", a dict of t, n_e, M_ref, or a 2-D array with these 3 columns, got shape {shape:?}"
            )));
        }
        let rows: Vec<Vec<f64>> = arr.call_method0("tolist")?.extract()?;
        core::CycleArg::Demand {
            t: rows.iter().map(|r| r[0]).collect(),
            n_e: rows.iter().map(|r| r[1]).collect(),
            m_ref: rows.iter().map(|r| r[2]).collect(),
        }
    };
    let tuning = tuning_json(py, tuning)?;
    let p = parse_params(py, params)?;
    let run = cancellable(py, move || {
        core::closed_loop(cycle, tuning.as_deref(), p, variant, duration, margins)
    })?
    .map_err(to_py_err)?;
    let out: Bound<'py, PyDict> = py
        .import("json")?
        .call_method1("loads", (run.summary,))?
        .downcast_into()?;
    let traj = PyDict::new(py);
    for (n, c) in run.names.iter().zip(run.columns) {
        traj.set_item(n, f64_array(&np, &c)?)?;
    }
    out.set_item("trajectory", traj)?;
    Ok(out)
}

/// A `tuning` argument (None or a dict of BaselineTuning fields) as the JSON text the core reads.
fn tuning_json(py: Python<'_>, tuning: Option<&Bound<'_, PyAny>>) -> PyResult<Option<String>> {
    match tuning {
        None => Ok(None),
        Some(t) if t.is_none() => Ok(None),
        Some(t) if t.is_instance_of::<PyDict>() => Ok(Some(
            py.import("json")?
                .call_method1("dumps", (t,))
                .map_err(|e| PyValueError::new_err(format!("tuning: {e}")))?
                .extract()?,
        )),
        Some(_) => Err(PyValueError::new_err(
            "tuning: expected a dict of BaselineTuning fields",
        )),
    }
}

/// Stability margins of the baseline controller's air-path loops (lambda_O -> u_egr,
/// x_egr -> u_vgt: discrete PIs sampled every 10 ms) at the steady state of constant inputs,
/// as `mvem margins --json` (docs/control.md, "Loop margins").
///
/// n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]; tuning: a dict of
/// BaselineTuning fields as in closed_loop; params, model as in simulate.
/// Returns a dict: "operating_point", "model_states", "ts", "stable" (every loop closed),
/// "max_pole_all", "steady_state_warnings" (flags of a physically invalid steady state),
/// "loops": [{"name", "input", "output", "kp", "ki", "alone", "others_closed"}],
/// each margins dict {"inert", "stable", "gain_margin", "gain_margin_db", "gain_margin_hz",
/// "gain_reduction_margin", "phase_margin_deg", "gain_crossover_hz", "delay_margin_s",
/// "peak_sensitivity", "peak_sensitivity_hz"} (None where a figure does not exist). ValueError
/// for non-finite inputs, a bad tuning or parameters; RuntimeError if there is no equilibrium
/// or the point sits at a kink the loops see.
#[pyfunction]
#[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, tuning=None, params=None, model=IntArg::Int(8)), text_signature = r#"(n_e, u_delta, u_egr, u_vgt, tuning=None, params=None, model=8)"#)]
#[allow(clippy::too_many_arguments)]
fn loop_margins<'py>(
    py: Python<'py>,
    n_e: f64,
    u_delta: f64,
    u_egr: f64,
    u_vgt: f64,
    tuning: Option<&Bound<'py, PyAny>>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let tuning = tuning_json(py, tuning)?;
    let p = params_at_point(py, params, "loop_margins", [n_e, u_delta, u_egr, u_vgt])?;
    let text = py
        .allow_threads(move || {
            core::loop_margins([n_e, u_delta, u_egr, u_vgt], tuning.as_deref(), p, variant)
        })
        .map_err(to_py_err)?;
    py.import("json")?
        .call_method1("loads", (text,))?
        .downcast_into()
        .map_err(Into::into)
}

/// Steady state (equilibrium) at constant inputs.
///
/// n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]; params, model as in simulate.
/// Returns a dict of floats (the inputs as n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct, the
/// states and every signal, SI units) plus "physically_valid" (bool) and "flags" (list of the
/// active guard saturations). Raises ValueError for non-finite inputs or bad parameters,
/// RuntimeError if no equilibrium is found.
#[pyfunction]
#[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, params=None, model=IntArg::Int(8)), text_signature = r#"(n_e, u_delta, u_egr, u_vgt, params=None, model=8)"#)]
fn steady<'py>(
    py: Python<'py>,
    n_e: f64,
    u_delta: f64,
    u_egr: f64,
    u_vgt: f64,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let p = params_at_point(py, params, "steady", [n_e, u_delta, u_egr, u_vgt])?;
    let s = py
        .allow_threads(move || core::steady([n_e, u_delta, u_egr, u_vgt], p, variant))
        .map_err(to_py_err)?;
    let out = PyDict::new(py);
    for (n, v) in s.values {
        out.set_item(n, v)?;
    }
    out.set_item("physically_valid", s.physically_valid)?;
    out.set_item("flags", s.flags)?;
    Ok(out)
}

fn matrix<'py>(
    np: &Bound<'py, PyModule>,
    m: &nalgebra::DMatrix<f64>,
) -> PyResult<Bound<'py, PyAny>> {
    let rows: Vec<Vec<f64>> = (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect();
    np.call_method1("array", (rows, "float64"))?
        .call_method1("reshape", (m.nrows(), m.ncols()))
}

fn complex_array<'py>(np: &Bound<'py, PyModule>, z: &[(f64, f64)]) -> PyResult<Bound<'py, PyAny>> {
    let re: Vec<f64> = z.iter().map(|c| c.0).collect();
    let im: Vec<f64> = z.iter().map(|c| c.1).collect();
    let re = np.call_method1("array", (re, "float64"))?;
    let im = np.call_method1("array", (im, "float64"))?;
    let j = np.getattr("complex128")?.call1((0.0, 1.0))?;
    re.call_method1("__add__", (im.call_method1("__mul__", (j,))?,))?
        .call_method1("astype", ("complex128",))
}

/// Frequency response of the linearized model at the steady state of constant inputs, the
/// actuator delays exact: G(jw) = C (jwI - A)^-1 B + D with the delayed commands' columns times
/// e^(-jw tau) (no Pade approximation).
///
/// n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]: the operating point.
/// f_hz: frequencies [Hz] (1-D, finite, >= 0, strictly increasing; e.g. numpy.logspace(-2, 2,
///     200)). outputs, strict, params, model: as in linearize.
///
/// Returns a dict: "f_hz" (array), "G" {"u_vgt->W_c": complex array (output unit per input
/// unit), ...} for every input (u_delta, u_egr, u_vgt, n_e) and output, "phase_deg" {channel:
/// array [deg]} continuous along the frequencies whatever their spacing (followed on a grid fine
/// enough for the delays), "input_names", "output_names", "delays" [s] of (u_egr, u_vgt).
/// abs(G) and phase_deg are the Bode diagram; at f = 0 the gains are the DC gains. Raises ValueError for bad arguments,
/// RuntimeError when there is no steady state (or a kink with strict).
#[pyfunction]
#[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, f_hz, outputs=None, strict=true, params=None, model=IntArg::Int(8)), text_signature = r#"(n_e, u_delta, u_egr, u_vgt, f_hz, outputs=None, strict=True, params=None, model=8)"#)]
#[allow(clippy::too_many_arguments)]
fn frequency_response<'py>(
    py: Python<'py>,
    n_e: f64,
    u_delta: f64,
    u_egr: f64,
    u_vgt: f64,
    f_hz: &Bound<'py, PyAny>,
    outputs: Option<Vec<String>>,
    strict: bool,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let np = py.import("numpy")?;
    let f = float_list(&np, f_hz, "f_hz")?;
    let p = params_at_point(
        py,
        params,
        "frequency_response",
        [n_e, u_delta, u_egr, u_vgt],
    )?;
    let args = LinArgs {
        outputs,
        strict,
        ..LinArgs::default()
    };
    let fr = py
        .allow_threads(move || {
            core::frequency_response_at([n_e, u_delta, u_egr, u_vgt], p, variant, &f, &args)
        })
        .map_err(to_py_err)?;
    let out = PyDict::new(py);
    out.set_item(
        "f_hz",
        np.call_method1("array", (fr.f_hz.clone(), "float64"))?,
    )?;
    let (g, ph) = (PyDict::new(py), PyDict::new(py));
    for i in &fr.input_names {
        for o in &fr.output_names {
            if let (Some(z), Some((_, phase))) = (fr.channel(i, o), fr.magnitude_phase(i, o)) {
                let pairs: Vec<(f64, f64)> = z.iter().map(|c| (c.re, c.im)).collect();
                g.set_item(format!("{i}->{o}"), complex_array(&np, &pairs)?)?;
                ph.set_item(
                    format!("{i}->{o}"),
                    np.call_method1("array", (phase, "float64"))?,
                )?;
            }
        }
    }
    out.set_item("G", g)?;
    out.set_item("phase_deg", ph)?;
    out.set_item("input_names", &fr.input_names)?;
    out.set_item("output_names", &fr.output_names)?;
    out.set_item("delays", fr.delays.to_vec())?;
    Ok(out)
}

/// Linearize at the steady state of constant inputs: dx' = A dx + B du, dy = C dx + D du.
///
/// n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]: the operating point.
/// outputs: output names (states or signals; default p_im, p_em, W_c, n_t, x_egr, lambda_O, M_e).
/// strict: raise RuntimeError when the point sits at a kink of the model (else the averaged
///     slopes are returned and the kinks listed). pade_order: 0 (undelayed system) to 3 (Pade
///     states for the actuator delays; none for a delay of 0). ts: also sample the model with a zero-order hold at
///     this time [s] (1e-3 to 100; pade_order 0), the actuator delays exact. params, model as
///     in simulate.
///
/// Returns a dict: "A" (n x n) [1/s], "B" (n x 4), "C" (p x n), "D" (p x 4) numpy arrays in the
/// model's units (states Pa, K, -, rad/s, %; inputs in "input_names" order u_delta [mg], u_egr
/// [%], u_vgt [%], n_e [rpm]; outputs in their signal units); "state_names", "input_names",
/// "output_names"; operating point "x0", "u0", "y0" (arrays); "eigenvalues" (complex array
/// [1/s]); "dc_gain" (p x 4 array, output units per input unit; None if A is singular);
/// "zeros" {"u_vgt->W_c": complex array [1/s], ...} of every SISO channel (None where a kink
/// lies on the channel); "mimo_zeros" of (u_delta, u_egr, u_vgt) -> (M_e, x_egr, lambda_O)
/// when those outputs are present; "kinks" (list of str); "one_sided" (list of str: inputs at a
/// saturation limit, differenced on the inner side); "delays" [s] of (u_egr, u_vgt); with
/// ts also "discrete": {"ts", "Phi", "Gamma", "C", "D" (arrays: dx(k+1) = Phi dx(k) + Gamma
/// du(k), dy(k) = C dx(k) + D du(k)), "state_names" (the model's states, then the delay
/// registers "u_egr(k-1)", ...), "input_names", "output_names", "delay_samples" [(whole
/// samples, remainder [s]) of u_egr, u_vgt]}.
/// Raises ValueError for bad arguments, RuntimeError when there is no steady state or a kink.
#[pyfunction]
#[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, outputs=None, strict=true, pade_order=IntArg::Int(0), params=None, model=IntArg::Int(8), ts=None), text_signature = r#"(n_e, u_delta, u_egr, u_vgt, outputs=None, strict=True, pade_order=0, params=None, model=8, ts=None)"#)]
#[allow(clippy::too_many_arguments)]
fn linearize<'py>(
    py: Python<'py>,
    n_e: f64,
    u_delta: f64,
    u_egr: f64,
    u_vgt: f64,
    outputs: Option<Vec<String>>,
    strict: bool,
    pade_order: IntArg,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
    ts: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let pade_order = pade_order.count("pade_order", 0, 3)?;
    let p = params_at_point(py, params, "linearize", [n_e, u_delta, u_egr, u_vgt])?;
    let args = LinArgs {
        outputs,
        strict,
        pade_order,
        ts,
    };
    let r = py
        .allow_threads(move || core::linearize_at([n_e, u_delta, u_egr, u_vgt], p, variant, &args))
        .map_err(to_py_err)?;
    let np = py.import("numpy")?;
    let out = PyDict::new(py);
    let l = &r.lin;
    out.set_item("A", matrix(&np, &l.a)?)?;
    out.set_item("B", matrix(&np, &l.b)?)?;
    out.set_item("C", matrix(&np, &l.c)?)?;
    out.set_item("D", matrix(&np, &l.d)?)?;
    out.set_item("state_names", &l.state_names)?;
    out.set_item("input_names", &l.input_names)?;
    out.set_item("output_names", &l.output_names)?;
    out.set_item("x0", np.call_method1("array", (l.x0.clone(),))?)?;
    out.set_item("u0", np.call_method1("array", (l.u0.to_vec(),))?)?;
    out.set_item("y0", np.call_method1("array", (l.y0.clone(),))?)?;
    out.set_item("eigenvalues", complex_array(&np, &r.eigenvalues)?)?;
    match &r.dc_gain {
        Ok(g) => out.set_item("dc_gain", matrix(&np, g)?)?,
        Err(_) => out.set_item("dc_gain", py.None())?,
    }
    let zs = PyDict::new(py);
    for (ch, z) in &r.zeros {
        match z {
            Ok(z) => zs.set_item(ch, complex_array(&np, z)?)?,
            Err(_) => zs.set_item(ch, py.None())?,
        }
    }
    out.set_item("zeros", zs)?;
    match &r.mimo_zeros {
        Some(Ok(z)) => out.set_item("mimo_zeros", complex_array(&np, z)?)?,
        _ => out.set_item("mimo_zeros", py.None())?,
    }
    let kinks: Vec<String> = l.kinks.iter().map(|k| k.to_string()).collect();
    out.set_item("kinks", PyList::new(py, kinks)?)?;
    let one_sided: Vec<String> = l.one_sided.iter().map(|k| k.to_string()).collect();
    out.set_item("one_sided", PyList::new(py, one_sided)?)?;
    out.set_item("delays", l.delays.to_vec())?;
    if let Some(dm) = &r.discrete {
        let dd = PyDict::new(py);
        dd.set_item("ts", dm.ts)?;
        dd.set_item("Phi", matrix(&np, &dm.phi)?)?;
        dd.set_item("Gamma", matrix(&np, &dm.gamma)?)?;
        dd.set_item("C", matrix(&np, &dm.c)?)?;
        dd.set_item("D", matrix(&np, &dm.d)?)?;
        dd.set_item("state_names", &dm.state_names)?;
        dd.set_item("input_names", &dm.input_names)?;
        dd.set_item("output_names", &dm.output_names)?;
        dd.set_item("delay_samples", dm.delay_samples.to_vec())?;
        out.set_item("discrete", dd)?;
    }
    Ok(out)
}

fn excursion<'py>(py: Python<'py>, e: Option<Excursion>) -> PyResult<Bound<'py, PyAny>> {
    match e {
        None => Ok(py.None().into_bound(py)),
        Some(e) => {
            let d = PyDict::new(py);
            d.set_item("value", e.value)?;
            d.set_item("time", e.time)?;
            d.set_item("relative", e.relative)?;
            Ok(d.into_any())
        }
    }
}

fn metrics_dict<'py>(py: Python<'py>, m: &StepMetrics) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("t_step", m.t_step)?;
    d.set_item("y0", m.y0)?;
    d.set_item("y_final", m.y_final)?;
    d.set_item("du", m.du)?;
    d.set_item("change", m.change)?;
    d.set_item("dc_gain", m.dc_gain)?;
    d.set_item("gain_sign", m.gain_sign.to_string())?;
    d.set_item("wrong_way", excursion(py, m.wrong_way)?)?;
    d.set_item("non_minimum_phase", m.non_minimum_phase)?;
    d.set_item("overshoot_pct", m.overshoot_pct)?;
    d.set_item("peak", excursion(py, m.peak)?)?;
    d.set_item("rise_time", m.rise_time)?;
    d.set_item("settling_time", m.settling_time)?;
    Ok(d)
}

/// Step-response metrics of samples y(t) for an input step of size du at t_step, from y0 to
/// y_final (mvem::analysis::step, the definitions of `mvem demo`).
///
/// Returns a dict: "change" = y_final - y0, "dc_gain" = change / du (units of y per unit of
/// input), "gain_sign" ("positive"/"negative"), "wrong_way" (None or {"value", "time" [s],
/// "relative" [-]}: the excursion against the final direction before the response moves 0.5 %),
/// "non_minimum_phase" (bool: wrong way by more than 0.5 %), "overshoot_pct" [%], "peak"
/// (None or like wrong_way), "rise_time" [s] (10-90 %, None if not reached), "settling_time"
/// [s] (2 % band, from the step; None if not settled), and the arguments. Raises ValueError
/// for arrays of different lengths, non-finite values or a zero change.
#[pyfunction]
fn step_metrics<'py>(
    py: Python<'py>,
    t: &Bound<'py, PyAny>,
    y: &Bound<'py, PyAny>,
    t_step: f64,
    y0: f64,
    y_final: f64,
    du: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let np = py.import("numpy")?;
    let t = float_list(&np, t, "t")?;
    let y = float_list(&np, y, "y")?;
    let m = core::step_metrics(&t, &y, t_step, y0, y_final, du).map_err(to_py_err)?;
    metrics_dict(py, &m)
}

/// Simulate a step of one input and measure the response of one output.
///
/// From the steady state at n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%], the
/// input `input` ("n_e", "u_delta", "u_egr" or "u_vgt") steps to `to` at t_step [s]; the
/// simulation runs to t_end [s]. The metrics of `output` (a state or signal name) use the
/// steady states before and after the step as y0 and y_final (as `mvem demo`).
/// dt, rtol, atol, params, model as in simulate.
///
/// Returns step_metrics' dict plus "t" and "y" (numpy arrays). ValueError for bad arguments,
/// RuntimeError when a steady state or the simulation fails.
#[pyfunction]
#[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, input="u_vgt", to=65.0, output="W_c", t_step=1.0, t_end=8.0, dt=0.01, rtol=1e-6, atol=None, params=None, model=IntArg::Int(8)), text_signature = r#"(n_e, u_delta, u_egr, u_vgt, input="u_vgt", to=65.0, output="W_c", t_step=1.0, t_end=8.0, dt=0.01, rtol=1e-6, atol=None, params=None, model=8)"#)]
#[allow(clippy::too_many_arguments)]
fn step_response<'py>(
    py: Python<'py>,
    n_e: f64,
    u_delta: f64,
    u_egr: f64,
    u_vgt: f64,
    input: &str,
    to: f64,
    output: &str,
    t_step: f64,
    t_end: f64,
    dt: f64,
    rtol: f64,
    atol: Option<f64>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let p = params_at_point(py, params, "step_response", [n_e, u_delta, u_egr, u_vgt])?;
    let args = SimArgs {
        t_end: None,
        dt,
        rtol,
        atol: atol.unwrap_or(rtol),
        ..SimArgs::default()
    };
    let (input, output) = (input.to_string(), output.to_string());
    let r = cancellable(py, move || {
        core::step_response(
            [n_e, u_delta, u_egr, u_vgt],
            &input,
            to,
            &output,
            t_step,
            t_end,
            args,
            p,
            variant,
        )
    })?
    .map_err(to_py_err)?;
    let np = py.import("numpy")?;
    let d = metrics_dict(py, &r.metrics)?;
    d.set_item("t", np.call_method1("array", (r.t,))?)?;
    d.set_item("y", np.call_method1("array", (r.y,))?)?;
    Ok(d)
}

/// The published parameter set of Wahlstrom & Eriksson (2011) as a nested dict
/// {group: {field: value}} (SI units; see the parameter file data/published.toml).
#[pyfunction]
fn published_params(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let text = PyString::new(py, &core::published_json());
    py.import("json")?.call_method1("loads", (text,))
}

/// Names, units and descriptions of the model's variables: a dict name -> {"kind": "time" |
/// "input" | "state" | "signal", "unit": str, "description": str} (the states of every variant;
/// a state and a signal of the same name, T_im, T_em, p_c, are listed once, as the state).
#[pyfunction]
fn variables(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let out = PyDict::new(py);
    for (kind, name, unit, description) in core::variables() {
        if out.contains(name)? {
            continue;
        }
        let d = PyDict::new(py);
        d.set_item("kind", kind)?;
        d.set_item("unit", unit)?;
        d.set_item("description", description)?;
        out.set_item(name, d)?;
    }
    Ok(out)
}

/// Every scalar parameter: a list of dicts {"path": "cylinder.c_vol[1]", "symbol": "c_vol1",
/// "unit": str, "description": str, "published": float}, in parameter-file order (the names
/// `params` overrides and the FMU use).
#[pyfunction]
fn parameters(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for (path, symbol, unit, description, value) in core::parameters() {
        let d = PyDict::new(py);
        d.set_item("path", path)?;
        d.set_item("symbol", symbol)?;
        d.set_item("unit", unit)?;
        d.set_item("description", description)?;
        d.set_item("published", value)?;
        out.append(d)?;
    }
    Ok(out)
}

/// A plant advanced sample by sample with the commands held (zero-order hold).
///
/// Plant(n_e, u_delta, u_egr, u_vgt, model=8, params=None) starts at t = 0 in the steady state of
/// these commands (n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]). step(dt, n_e=,
/// u_delta=, u_egr=, u_vgt=) holds the commands for dt [s] (0 < dt <= 1e6; a command left out
/// keeps its last value) and returns a dict of the outputs at the end: the states (p_im [Pa], p_em [Pa], X_Oim,
/// X_Oem [-], omega_t [rad/s], actuator states [%], ...) and every signal (W_c [kg/s], lambda_O,
/// x_egr [-], M_e [Nm], ...). State, cylinder-temperature memory, the exact actuator delays and
/// the integrator's warm state carry over between calls; the GIL is released while integrating.
/// t [s] and state (numpy array) are attributes; reset(...) starts again at t = 0.
/// ValueError for bad arguments, RuntimeError if the solver fails.
///
/// Threads: a Plant may be shared between Python threads; an internal lock serializes its
/// calls (one step integrates at a time, a second thread's call waits for it, and each step's
/// returned outputs are those of that step). It is one plant with one time: for runs in
/// parallel give each thread its own Plant.
#[pyclass(name = "Plant", module = "mvem", frozen)]
struct Plant {
    /// The plant and the commands held in its last step, behind the lock that makes a shared
    /// Plant safe: before it, a second thread's call while one integrated (GIL released) raised
    /// "Already borrowed" (QA).
    inner: Mutex<PlantState>,
    /// The parameter set's input saturation ranges (for the range warnings).
    ranges: [(&'static str, f64, f64); 4],
}

struct PlantState {
    plant: core::CorePlant,
    cmd: [f64; 4],
}

fn merge_cmd(
    cur: [f64; 4],
    n_e: Option<f64>,
    u_delta: Option<f64>,
    u_egr: Option<f64>,
    u_vgt: Option<f64>,
) -> [f64; 4] {
    [
        n_e.unwrap_or(cur[0]),
        u_delta.unwrap_or(cur[1]),
        u_egr.unwrap_or(cur[2]),
        u_vgt.unwrap_or(cur[3]),
    ]
}

impl Plant {
    /// Run `f` on the plant under its lock, with the GIL released: a thread waiting for the
    /// lock never holds the GIL, so the thread holding the lock can finish (and the other
    /// Python threads run meanwhile).
    fn locked<T: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut PlantState) -> T + Send) -> T {
        py.allow_threads(|| {
            // only a panic poisons the lock (pyo3 raises it as PanicException); the plant is
            // then used as the panic left it, as without the lock
            let mut g = self.inner.lock().unwrap_or_else(PoisonError::into_inner);
            f(&mut g)
        })
    }

    /// The outputs (names and values) of a plant.
    fn outputs_of(s: &PlantState) -> (Vec<String>, Vec<f64>) {
        (s.plant.names().to_vec(), s.plant.outputs())
    }
}

/// The outputs as a dict of floats.
fn outputs_dict(
    py: Python<'_>,
    (names, values): (Vec<String>, Vec<f64>),
) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    for (n, v) in names.iter().zip(values) {
        d.set_item(n, v)?;
    }
    Ok(d)
}

#[pymethods]
impl Plant {
    #[new]
    #[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, model=IntArg::Int(8), params=None), text_signature = r#"(n_e, u_delta, u_egr, u_vgt, model=8, params=None)"#)]
    fn new(
        py: Python<'_>,
        n_e: f64,
        u_delta: f64,
        u_egr: f64,
        u_vgt: f64,
        model: IntArg,
        params: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let variant = variant_of(&model, "converged")?;
        let p = parse_params(py, params)?;
        let cmd = [n_e, u_delta, u_egr, u_vgt];
        let ranges = ranges_of(p.as_ref());
        warn_out_of_range(py, "Plant", cmd, &ranges)?;
        let plant = py
            .allow_threads(move || core::CorePlant::new(cmd, p, variant))
            .map_err(to_py_err)?;
        Ok(Self {
            inner: Mutex::new(PlantState { plant, cmd }),
            ranges,
        })
    }

    /// Hold the commands for dt [s] (0 < dt <= 1e6); returns the outputs at the end (dict of
    /// floats).
    #[pyo3(signature = (dt, n_e=None, u_delta=None, u_egr=None, u_vgt=None))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        dt: f64,
        n_e: Option<f64>,
        u_delta: Option<f64>,
        u_egr: Option<f64>,
        u_vgt: Option<f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        // One lock per step: the commands are merged with the held ones and the plant steps
        // under the same lock (another thread cannot change the held commands in between).
        // Only a changed command outside its range stops first: its warning needs the GIL and
        // comes before the step (a warning made an error leaves the plant as it was), then the
        // lock is taken again and the step runs if the commands are still the ones warned of.
        let mut warned: Option<[f64; 4]> = None;
        loop {
            let ranges = &self.ranges;
            let r = self.locked(py, |s| {
                let cmd = merge_cmd(s.cmd, n_e, u_delta, u_egr, u_vgt);
                if cmd != s.cmd && warned != Some(cmd) && out_of_range(cmd, ranges) {
                    return Ok(Err(cmd));
                }
                s.plant.step(dt, cmd)?;
                s.cmd = cmd;
                Ok(Ok(Self::outputs_of(s)))
            });
            match r.map_err(to_py_err)? {
                Ok(out) => return outputs_dict(py, out),
                Err(cmd) => {
                    warn_out_of_range(py, "Plant.step", cmd, &self.ranges)?;
                    warned = Some(cmd);
                }
            }
        }
    }

    /// The outputs at the current time (dict of floats).
    fn outputs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = self.locked(py, |s| Self::outputs_of(s));
        outputs_dict(py, out)
    }

    /// Start again at t = 0 in the steady state of the commands (left out: the last ones).
    #[pyo3(signature = (n_e=None, u_delta=None, u_egr=None, u_vgt=None))]
    fn reset(
        &self,
        py: Python<'_>,
        n_e: Option<f64>,
        u_delta: Option<f64>,
        u_egr: Option<f64>,
        u_vgt: Option<f64>,
    ) -> PyResult<()> {
        let cmd = self.locked(py, |s| merge_cmd(s.cmd, n_e, u_delta, u_egr, u_vgt));
        warn_out_of_range(py, "Plant.reset", cmd, &self.ranges)?;
        self.locked(py, |s| {
            s.plant.reset(cmd)?;
            s.cmd = cmd;
            Ok(())
        })
        .map_err(to_py_err)
    }

    /// Time [s].
    #[getter]
    fn t(&self, py: Python<'_>) -> f64 {
        self.locked(py, |s| s.plant.t())
    }

    /// State vector (numpy array, in state_names order).
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let x = self.locked(py, |s| s.plant.state());
        py.import("numpy")?.call_method1("array", (x,))
    }

    /// State names.
    #[getter]
    fn state_names(&self, py: Python<'_>) -> Vec<String> {
        self.locked(py, |s| {
            let n = s.plant.state().len();
            s.plant.names()[..n].to_vec()
        })
    }

    /// The commands held in the last step: (n_e, u_delta, u_egr, u_vgt).
    #[getter]
    fn commands(&self, py: Python<'_>) -> (f64, f64, f64, f64) {
        let c = self.locked(py, |s| s.cmd);
        (c[0], c[1], c[2], c[3])
    }

    /// The delayed commands (u_egr(t - tau_degr), u_vgt(t - tau_dvgt)) [%] the actuators see
    /// now, from the command history. The right-hand side at the plant's state is
    /// Model.derivatives(plant.state, (n_e, u_delta, *plant.delayed_commands)), and
    /// Model.jacobian at that point linearizes along the run (e.g. for an extended Kalman
    /// filter).
    #[getter]
    fn delayed_commands(&self, py: Python<'_>) -> (f64, f64) {
        let [e, v] = self.locked(py, |s| s.plant.delayed_commands());
        (e, v)
    }
}

/// Points (x, u) of `Model` calls: a state array of shape (n,) with inputs (4,), or states
/// (K, n) with inputs (K, 4) or (4,) (the same for all). Returns the states, the inputs and
/// whether the call was batched.
type Points = (Vec<Vec<f64>>, Vec<[f64; 4]>, bool);

fn points<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    u: &Bound<'py, PyAny>,
    n: usize,
) -> PyResult<Points> {
    let np = py.import("numpy")?;
    let as_array =
        |obj: &Bound<'py, PyAny>, what: &str| -> PyResult<(Vec<usize>, Bound<'py, PyAny>)> {
            let arr = np
                .call_method1("asarray", (obj, "float64"))
                .map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?;
            Ok((arr.getattr("shape")?.extract()?, arr))
        };
    let (xs, xa) = as_array(x, "state")?;
    let (us, ua) = as_array(u, "inputs")?;
    let (states, batched): (Vec<Vec<f64>>, bool) = match xs.as_slice() {
        [m] if *m == n => (vec![xa.call_method0("tolist")?.extract()?], false),
        [_, m] if *m == n => (xa.call_method0("tolist")?.extract()?, true),
        _ => {
            return Err(PyValueError::new_err(format!(
                "state: expected shape ({n},) or (K, {n}), got {xs:?}"
            )))
        }
    };
    let k = states.len();
    if k == 0 {
        return Err(PyValueError::new_err(format!(
            "state: no points (shape {xs:?}); give at least one state"
        )));
    }
    let rows: Vec<Vec<f64>> = match us.as_slice() {
        [4] => vec![ua.call_method0("tolist")?.extract()?; k],
        [r, 4] if batched && *r == k => ua.call_method0("tolist")?.extract()?,
        _ => {
            return Err(PyValueError::new_err(format!(
                "inputs: expected (n_e, u_delta, u_egr, u_vgt) of shape (4,){}, got shape {us:?}",
                if batched {
                    format!(" or ({k}, 4) for {k} states")
                } else {
                    String::new()
                }
            )))
        }
    };
    let inputs = rows.iter().map(|r| [r[0], r[1], r[2], r[3]]).collect();
    Ok((states, inputs, batched))
}

/// One `UserWarning` per input channel whose value leaves the saturation range at some point,
/// naming the first such point.
fn warn_points_out_of_range(
    py: Python<'_>,
    what: &str,
    inputs: &[[f64; 4]],
    ranges: &[(&'static str, f64, f64); 4],
) -> PyResult<()> {
    for (c, (name, lo, hi)) in ranges.iter().enumerate() {
        let points: Vec<usize> = (0..inputs.len())
            // a non-finite value is refused with its point, not clamped
            .filter(|&k| outside(inputs[k][c], *lo, *hi))
            .collect();
        if let Some(&k) = points.first() {
            let at = if inputs.len() > 1 {
                format!(
                    " at point {k} ({} of {} points)",
                    points.len(),
                    inputs.len()
                )
            } else {
                String::new()
            };
            user_warning(
                py,
                format!(
                    "{what}: {name} = {}{at} is outside [{lo}, {hi}]; the authors' saturation clamps it",
                    Num(inputs[k][c])
                ),
            )?;
        }
    }
    Ok(())
}

/// A point's error, naming the point in a batched call.
fn at_point(e: CoreError, k: usize, batched: bool) -> PyErr {
    let e = if batched {
        match e {
            CoreError::Value(m) => CoreError::Value(format!("point {k}: {m}")),
            CoreError::Runtime(m) => CoreError::Runtime(format!("point {k}: {m}")),
        }
    } else {
        e
    };
    to_py_err(e)
}

/// `f` at every point, with the GIL released; an error names its point in a batched call.
fn each_point<T: Send>(
    py: Python<'_>,
    (xs, us, batched): &Points,
    f: impl Fn(&[f64], [f64; 4]) -> core::CoreResult<T> + Send + Sync,
) -> PyResult<Vec<T>> {
    py.allow_threads(|| {
        xs.iter()
            .zip(us)
            .enumerate()
            .map(|(k, (x, u))| f(x, *u).map_err(|e| (k, e)))
            .collect::<Result<Vec<T>, _>>()
    })
    .map_err(|(k, e)| at_point(e, k, *batched))
}

/// numpy array of `flat` with `shape`.
fn shaped<'py>(py: Python<'py>, flat: Vec<f64>, shape: Vec<usize>) -> PyResult<Bound<'py, PyAny>> {
    py.import("numpy")?
        .call_method1("array", (flat, "float64"))?
        .call_method1("reshape", (PyTuple::new(py, shape)?,))
}

/// The model's right-hand side dx/dt = f(x, u) at any state, and its Jacobians, for optimal
/// control and custom integrators: the parameters are validated once, each call evaluates.
///
/// Model(model=8, params=None): model 8 (the paper's), 10 or 12 states; params as in simulate.
/// Inputs u = (n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]) (input_names), held:
/// the actuators see u_egr, u_vgt as their delayed commands u_egr(t - tau_degr), u_vgt(t -
/// tau_dvgt) (the current commands enter no derivative), so a model with explicit delays passes
/// the delayed values. States in state_names order and units (Pa, -, rad/s, %; 10/12 states add
/// K and Pa). The cylinder-out temperature is the converged fixed point (section 4.2).
///
/// Every method takes one point (state of shape (n,), inputs (4,)) or K points (states (K, n),
/// inputs (K, 4) or (4,) for all) and returns arrays with a leading K axis when batched. Inputs
/// outside the parameter set's saturation are clamped by the model, with a UserWarning.
/// ValueError names the argument or the point (a non-finite state or input, a wrong shape, a
/// state where the model is not finite); the GIL is released while the model runs.
#[pyclass(name = "Model", module = "mvem")]
struct PyModel {
    inner: core::PointModel,
    ranges: [(&'static str, f64, f64); 4],
}

impl PyModel {
    /// The points of a call ([`points`]), with the range warnings naming `what`.
    fn points<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        what: &str,
    ) -> PyResult<Points> {
        let pts = points(py, x, u, self.inner.n_states())?;
        warn_points_out_of_range(py, what, &pts.1, &self.ranges)?;
        Ok(pts)
    }
}

#[pymethods]
impl PyModel {
    #[new]
    #[pyo3(signature = (model=IntArg::Int(8), params=None), text_signature = r#"(model=8, params=None)"#)]
    fn new(py: Python<'_>, model: IntArg, params: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let variant = variant_of(&model, "converged")?;
        let p = parse_params(py, params)?;
        let ranges = ranges_of(p.as_ref());
        let inner = core::PointModel::new(p, variant.order).map_err(to_py_err)?;
        Ok(Self { inner, ranges })
    }

    /// State names (n).
    #[getter]
    fn state_names(&self) -> Vec<String> {
        self.inner.state_names()
    }

    /// Input names, the order of u and of the columns of B and D: n_e, u_delta, u_egr, u_vgt.
    #[getter]
    fn input_names(&self) -> Vec<&'static str> {
        core::POINT_INPUTS.to_vec()
    }

    /// Typical magnitudes of the states (numpy array, state units), for scaling.
    #[getter]
    fn state_scales<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("numpy")?
            .call_method1("array", (self.inner.state_scales(),))
    }

    /// dx/dt [state units per s] at state x and inputs u: shape (n,), or (K, n) for K points.
    fn derivatives<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = self.inner.n_states();
        let pts = self.points(py, x, u, "Model.derivatives")?;
        let dx = each_point(py, &pts, |x, u| self.inner.derivatives(x, u))?;
        let shape = if pts.2 { vec![dx.len(), n] } else { vec![n] };
        shaped(py, dx.concat(), shape)
    }

    /// Every signal at x, u (W_c [kg/s], lambda_O, x_egr, M_e [Nm], ...): a dict of floats, or
    /// of arrays (K,) for K points; "flags": the active guard saturations (a list, or a list
    /// per point).
    fn signals<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let pts = self.points(py, x, u, "Model.signals")?;
        let batched = pts.2;
        let all = each_point(py, &pts, |x, u| self.inner.signals(x, u))?;
        let out = PyDict::new(py);
        let np = py.import("numpy")?;
        for (j, name) in mvem::model::Signals::NAMES.iter().enumerate() {
            if batched {
                let col: Vec<f64> = all.iter().map(|(v, _)| v[j]).collect();
                out.set_item(name, np.call_method1("array", (col, "float64"))?)?;
            } else {
                out.set_item(name, all[0].0[j])?;
            }
        }
        if batched {
            let flags: Vec<Vec<String>> = all.into_iter().map(|(_, f)| f).collect();
            out.set_item("flags", flags)?;
        } else {
            out.set_item("flags", all.into_iter().next().map(|(_, f)| f))?;
        }
        Ok(out)
    }

    /// f(x, u) and its Jacobians at x, u by Richardson-extrapolated central differences (the
    /// library's linearization: entries to about 1e-9 relative to the row's largest scaled
    /// entry; not exact derivatives).
    ///
    /// outputs: state or signal names whose y, C, D are wanted too (default none).
    /// strict: raise RuntimeError when a point lies within the difference stencil of a kink of
    ///     the model (a saturation or switch); default False: the averaged slopes, with the
    ///     kinks listed.
    ///
    /// Returns a dict of numpy arrays: "f" = dx/dt (n), "A" = df/dx (n, n) [1/s], "B" = df/du
    /// (n, 4) per input unit (columns in input_names order: n_e, u_delta, u_egr, u_vgt), and
    /// with outputs "y" (p), "C" (p, n), "D" (p, 4), each with a leading K axis when batched;
    /// "state_names", "input_names", "output_names"; "kinks" (a list of str, or a list per
    /// point).
    #[pyo3(signature = (x, u, outputs=None, strict=false))]
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        outputs: Option<Vec<String>>,
        strict: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let n = self.inner.n_states();
        let pts = self.points(py, x, u, "Model.jacobian")?;
        let batched = pts.2;
        let outputs = outputs.unwrap_or_default();
        let all = each_point(py, &pts, |x, u| self.inner.jacobian(x, u, &outputs, strict))?;
        let p = outputs.len();
        let k = all.len();
        let lead = |dims: &[usize]| -> Vec<usize> {
            if batched {
                std::iter::once(k).chain(dims.iter().copied()).collect()
            } else {
                dims.to_vec()
            }
        };
        let out = PyDict::new(py);
        let cat = |f: fn(&core::PointJacobian) -> &Vec<f64>| -> Vec<f64> {
            all.iter().flat_map(|j| f(j).iter().copied()).collect()
        };
        out.set_item("f", shaped(py, cat(|j| &j.dx), lead(&[n]))?)?;
        out.set_item("A", shaped(py, cat(|j| &j.a), lead(&[n, n]))?)?;
        out.set_item("B", shaped(py, cat(|j| &j.b), lead(&[n, 4]))?)?;
        if p > 0 {
            out.set_item("y", shaped(py, cat(|j| &j.y), lead(&[p]))?)?;
            out.set_item("C", shaped(py, cat(|j| &j.c), lead(&[p, n]))?)?;
            out.set_item("D", shaped(py, cat(|j| &j.d), lead(&[p, 4]))?)?;
        }
        out.set_item("state_names", self.inner.state_names())?;
        out.set_item("input_names", core::POINT_INPUTS.to_vec())?;
        out.set_item("output_names", all[0].output_names.clone())?;
        if batched {
            let kinks: Vec<Vec<String>> = all.into_iter().map(|j| j.kinks).collect();
            out.set_item("kinks", kinks)?;
        } else {
            out.set_item("kinks", all.into_iter().next().map(|j| j.kinks))?;
        }
        Ok(out)
    }
}

/// The paper's tuning steps (sections 3-6, 8.1) on a campaign directory, as `mvem tune` runs
/// them: the same parameters and report from the same campaign and settings.
///
/// data: the campaign directory (manifest.toml, docs/tuning-data.md). params: the engine's
/// constants and the parameters of the steps not run (None: the published set, whose constants
/// are right only for the published engine; a path also supplies its [test_cell] section).
/// model: 8 or 12. Keyword settings: the options of `mvem tune` in snake case (steps="1-5",
/// ambient, input_ranges, init, cost, beta, refine_dynamics, joint_uncertainty, fixed_jacobian,
/// max_evals, broyden, rel_offset, restarts, step5_single_pass, step5_first_pass_max,
/// settled_flow_points, step3_window (None: infinite), step3_tail_weight, step_levels,
/// sensor_lags); an unknown name is a ValueError. Returns a dict: "params" (the tuned set as a
/// nested dict, usable as params=), "test_cell" (tau_me and sensor time constants), "toml" (the
/// parameter file mvem tune writes), "report" (tune_report.json as a dict; its "parameters"
/// keyed by the paths of parameters(), elements 1-based, each usable as a params= key), "messages" (the
/// warnings and notes mvem tune prints; each "warning: ..." is also issued as a UserWarning).
/// ValueError for a bad setting, parameter set or campaign file (naming it), RuntimeError when a
/// step fails (naming it). Runs without the GIL; Ctrl-C (KeyboardInterrupt) stops the tuning
/// within one residual evaluation (one round of simulations) and raises KeyboardInterrupt.
/// progress: None or a callable, called with a dict {"stage": "step 5 (...)", "evaluations",
/// "cost", "elapsed_s"} at the start of each step (evaluations and cost None) and during its
/// least-squares searches (at most every 0.2 s); an exception it raises stops the tuning (as
/// Ctrl-C does) and is raised. The result does not depend on it.
#[pyfunction]
#[pyo3(signature = (data, params=None, model=IntArg::Int(8), *, progress=None, **settings), text_signature = r#"(data, params=None, model=8, *, progress=None, **settings)"#)]
fn tune<'py>(
    py: Python<'py>,
    data: &Bound<'py, PyAny>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
    progress: Option<&Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let data = std::path::PathBuf::from(fspath(py, data, "data")?);
    // a parameter file's [test_cell] section (tau_Me, sensor lags) comes along
    let base = match parse_params(py, params)? {
        None => None,
        Some(p) => Some((p, test_cell_of(py, params)?)),
    };
    let json = py.import("json")?;
    let settings = settings_json(py, settings, "tuning settings")?;
    let token = mvem::numerics::cancel::CancelToken::new();
    let failed = std::sync::Arc::new(std::sync::Mutex::new(None));
    let observer = match progress {
        None => None,
        Some(cb) if cb.is_none() => None,
        Some(cb) if !cb.is_callable() => {
            return Err(PyValueError::new_err(
                "progress: must be a callable (called with one dict) or None",
            ))
        }
        Some(cb) => Some(progress_observer(cb, &token, &failed)),
    };
    let out = interruptible(py, &token, observer.as_ref(), move || {
        core::tune(&data, base, variant.order, settings.as_deref())
    })?;
    if let Some(e) = failed.lock().unwrap_or_else(|e| e.into_inner()).take() {
        return Err(e);
    }
    let out = out.map_err(to_py_err)?;
    let d = PyDict::new(py);
    d.set_item("params", json.call_method1("loads", (out.params_json,))?)?;
    d.set_item(
        "test_cell",
        json.call_method1("loads", (out.test_cell_json,))?,
    )?;
    d.set_item("toml", out.toml)?;
    d.set_item("report", json.call_method1("loads", (out.report_json,))?)?;
    for m in &out.messages {
        if let Some(w) = m.strip_prefix("warning: ") {
            user_warning(py, w.to_string())?;
        }
    }
    d.set_item("messages", out.messages)?;
    Ok(d)
}

/// What a campaign directory holds and which tuning steps it supports, before any tuning, as
/// `mvem campaign --json`: a dict with "stationary_points", the ranges "n_e_rpm",
/// "u_delta_mg", "m_e_nm", "t_t", "renamed" and "units" (the manifest's [columns] and [units]),
/// "datasets" (per set: name, kind, roles, samples, duration_s, sample_rate_hz,
/// measured_rate_hz, command_steps, positions) and "steps" (per step 1-5: step, title,
/// supported, uses). ValueError naming the file, line and column when the campaign does not
/// load. init=True first drafts data/manifest.toml from the directory's CSV files as `mvem
/// campaign --init` does (kinds, roles, rates, steps and units guessed; the dict then has
/// "notes", what was guessed; an existing manifest is kept unless force=True).
#[pyfunction]
#[pyo3(signature = (data, init=false, force=false))]
fn campaign<'py>(
    py: Python<'py>,
    data: &Bound<'py, PyAny>,
    init: bool,
    force: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let data = std::path::PathBuf::from(fspath(py, data, "data")?);
    let notes = if init {
        let d = data.clone();
        Some(
            py.allow_threads(move || core::draft_manifest(&d, force))
                .map_err(to_py_err)?,
        )
    } else if force {
        return Err(PyValueError::new_err("force: only with init=True"));
    } else {
        None
    };
    let json = py
        .allow_threads(move || core::campaign(&data))
        .map_err(to_py_err)?;
    let d = py.import("json")?.call_method1("loads", (json,))?;
    if let Some(n) = notes {
        d.set_item("notes", n)?;
    }
    Ok(d)
}

/// The relative errors (eqs (4), (5), per cent) of a parameter set on a campaign directory, as
/// `mvem validate` computes them (its tables, like the paper's Tables 2-4).
///
/// params: None (the published set), a dict, or a path (whose [test_cell] section supplies
/// tau_Me and the sensor time constants, as `mvem tune` writes them). tau_me [s] and
/// sensor_lags ("none", "table6" or "p_im=0.015,...") override those; roles: e.g.
/// "validation" or "static,dynamic" (default: every set). Returns a dict: "datasets" ({set:
/// {output: percent}}), "stationary" ({submodel: percent}), "oscillations" (if any),
/// "tau_me", "sensor_lags" (dict, s), "messages"; with traces=True also "traces": {set: {"t":
/// array, output: {"measured": array, "simulated": array}}} (the curves of mvem validate's
/// figures). ValueError for a bad setting, parameter set or campaign file, RuntimeError when a
/// simulation fails (naming the set). Runs without the GIL.
#[pyfunction]
#[pyo3(signature = (data, params=None, model=IntArg::Int(8), tau_me=None, sensor_lags=None, roles=None, traces=false), text_signature = r#"(data, params=None, model=8, tau_me=None, sensor_lags=None, roles=None, traces=False)"#)]
#[allow(clippy::too_many_arguments)]
fn validate<'py>(
    py: Python<'py>,
    data: &Bound<'py, PyAny>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
    tau_me: Option<f64>,
    sensor_lags: Option<String>,
    roles: Option<String>,
    traces: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let data = std::path::PathBuf::from(fspath(py, data, "data")?);
    let p = parse_params(py, params)?.unwrap_or_else(Params::published);
    let cell = test_cell_of(py, params)?;
    let out = cancellable(py, move || {
        core::validate(
            &data,
            (p, cell),
            variant.order,
            tau_me,
            sensor_lags.as_deref(),
            roles.as_deref(),
            traces,
        )
    })?
    .map_err(to_py_err)?;
    let np = py.import("numpy")?;
    let d: Bound<'py, PyDict> = py
        .import("json")?
        .call_method1("loads", (out.summary_json,))?
        .downcast_into()?;
    d.set_item("tau_me", out.tau_me)?;
    let lags = PyDict::new(py);
    for (n, v) in ["p_im", "p_em", "W_c", "n_t"].iter().zip(out.sensor_lags) {
        lags.set_item(n, v)?;
    }
    d.set_item("sensor_lags", lags)?;
    for m in &out.messages {
        if let Some(w) = m.strip_prefix("warning: ") {
            user_warning(py, w.to_string())?;
        }
    }
    d.set_item("messages", out.messages)?;
    if traces {
        let all = PyDict::new(py);
        for tr in out.traces {
            let set = PyDict::new(py);
            set.set_item("t", f64_array(&np, &tr.t)?)?;
            for (name, meas, sim) in tr.outputs {
                let o = PyDict::new(py);
                o.set_item("measured", f64_array(&np, &meas)?)?;
                o.set_item("simulated", f64_array(&np, &sim)?)?;
                set.set_item(name, o)?;
            }
            all.set_item(tr.set, set)?;
        }
        d.set_item("traces", all)?;
    }
    Ok(d)
}

/// `obj` as a file-system path (str or os.PathLike), `what` naming the argument in the error.
fn fspath(py: Python<'_>, obj: &Bound<'_, PyAny>, what: &str) -> PyResult<String> {
    py.import("os")?
        .call_method1("fspath", (obj,))
        .and_then(|p| p.extract::<String>())
        .map_err(|_| PyValueError::new_err(format!("{what} must be a str path")))
}

/// The [test_cell] section (tau_Me, sensor lags) of `params` when it is a parameter file's
/// path (a dict or None has none).
fn test_cell_of(
    py: Python<'_>,
    params: Option<&Bound<'_, PyAny>>,
) -> PyResult<Option<mvem::io::test_cell::TestCell>> {
    match params.filter(|o| !o.is_none() && !o.is_instance_of::<PyDict>()) {
        Some(obj) => {
            let path = fspath(py, obj, "params")?;
            mvem::io::test_cell::load_test_cell(std::path::Path::new(&path))
                .map_err(|e| PyValueError::new_err(format!("params {path}: {e}")))
        }
        None => Ok(None),
    }
}

/// A virtual test-cell campaign (the stationary points, the dynamic sets of the paper's Table 1
/// and the actuator set J, with noise) generated from a parameter set and written to the
/// directory `out`, as `mvem lab` writes it (the same files for the same settings): input for
/// `tune` and `validate`.
///
/// params: the virtual engine (None: the published set). model: 8, 10 or 12 (the model that
/// plays the engine). Keyword settings: the options of `mvem lab` in snake case (seed=1,
/// noise="realistic" | "none" | "REL,KELVIN", n_stationary=82, tau_me=1.0, sensor_lags=False,
/// sets=None (a list of Table 1 names), max_steps=None, dynamic=True, speeds="900:2100",
/// full_load=220.0); an unknown name is a ValueError. Returns a dict: "dir", "stationary"
/// (number of points), "datasets" (names), "samples" (dynamic samples). Runs without the GIL.
#[pyfunction]
#[pyo3(signature = (out, params=None, model=IntArg::Int(8), **settings), text_signature = r#"(out, params=None, model=8, **settings)"#)]
fn lab<'py>(
    py: Python<'py>,
    out: &Bound<'py, PyAny>,
    params: Option<&Bound<'py, PyAny>>,
    model: IntArg,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    let variant = variant_of(&model, "converged")?;
    let dir = fspath(py, out, "out")?;
    let p = parse_params(py, params)?;
    let settings = settings_json(py, settings, "lab settings")?;
    let path = std::path::PathBuf::from(&dir);
    let (n_stationary, sets, samples) = cancellable(py, move || {
        core::lab(&path, p, variant.order, settings.as_deref())
    })?
    .map_err(to_py_err)?;
    let d = PyDict::new(py);
    d.set_item("dir", dir)?;
    d.set_item("stationary", n_stationary)?;
    d.set_item("datasets", sets)?;
    d.set_item("samples", samples)?;
    Ok(d)
}

/// Run `f` on a worker thread without the GIL so that Ctrl-C can stop it: this (the calling
/// Python) thread checks Python's signals every 50 ms while it waits; on KeyboardInterrupt (or
/// any exception a signal handler raises) it cancels the work through the worker's
/// [`CancelToken`] (the tuning's searches, the pipeline between its steps and an ensemble
/// before each run poll it: `mvem::numerics::cancel`), waits for the worker to reach its next
/// checkpoint and raises the handler's exception. A panic in the worker is resumed here, where
/// PyO3 turns it into a PanicException as for work run on this thread.
fn interruptible<T: Send>(
    py: Python<'_>,
    token: &mvem::numerics::cancel::CancelToken,
    observer: Option<&mvem::numerics::progress::Observer>,
    f: impl FnOnce() -> T + Send,
) -> PyResult<T> {
    use mvem::numerics::cancel::with_token;
    use mvem::numerics::progress::with_observer;
    use std::sync::{Condvar, Mutex, PoisonError};
    use std::time::Duration;
    /// Sets the flag and wakes the waiting thread when the worker ends, also by a panic.
    struct Done<'a>(&'a (Mutex<bool>, Condvar));
    impl Drop for Done<'_> {
        fn drop(&mut self) {
            *self.0 .0.lock().unwrap_or_else(PoisonError::into_inner) = true;
            self.0 .1.notify_all();
        }
    }
    let done = (Mutex::new(false), Condvar::new());
    let wait = |timeout: Duration| {
        let g = done.0.lock().unwrap_or_else(PoisonError::into_inner);
        let (g, _) = done
            .1
            .wait_timeout_while(g, timeout, |d| !*d)
            .unwrap_or_else(PoisonError::into_inner);
        *g
    };
    std::thread::scope(|s| {
        let (token, done) = (&token, &done);
        let worker = std::thread::Builder::new()
            .name("mvem-worker".into())
            // the size of a main thread's stack: the work ran on the caller's thread before
            .stack_size(8 << 20)
            .spawn_scoped(s, move || {
                let _done = Done(done);
                match observer {
                    Some(o) => with_observer(o, || with_token(token, f)),
                    None => with_token(token, f),
                }
            })
            .map_err(|e| PyRuntimeError::new_err(format!("cannot start a worker thread: {e}")))?;
        let join = |w: std::thread::ScopedJoinHandle<'_, T>| {
            w.join().unwrap_or_else(|p| std::panic::resume_unwind(p))
        };
        loop {
            if py.allow_threads(|| wait(Duration::from_millis(50))) {
                return Ok(join(worker));
            }
            if let Err(e) = py.check_signals() {
                token.cancel();
                py.allow_threads(|| while !wait(Duration::from_secs(3600)) {});
                drop(join(worker));
                return Err(e);
            }
        }
    })
}

/// [`interruptible`] with a token of its own and no progress: the long calls without a
/// progress callback (simulate, step_response, closed_loop, validate, lab). Ctrl-C stops the
/// simulation within one integrator step (`SimError::Cancelled`) and raises KeyboardInterrupt.
fn cancellable<T: Send>(py: Python<'_>, f: impl FnOnce() -> T + Send) -> PyResult<T> {
    interruptible(py, &mvem::numerics::cancel::CancelToken::new(), None, f)
}

/// A progress observer (`mvem::numerics::progress`) that calls the Python callable `cb` with a
/// dict {"stage": str, "evaluations": int or None, "cost": float or None, "elapsed_s": float}:
/// at the start of every stage, and for a search's iterations at most every 0.2 s. It runs on
/// the worker thread of [`interruptible`] and takes the GIL for the call (the waiting thread
/// releases it). An exception the callable raises cancels the work through `token` and is kept
/// in `failed` for the caller to raise.
fn progress_observer(
    cb: &Bound<'_, PyAny>,
    token: &mvem::numerics::cancel::CancelToken,
    failed: &std::sync::Arc<std::sync::Mutex<Option<PyErr>>>,
) -> mvem::numerics::progress::Observer {
    use mvem::numerics::progress::Progress;
    use std::time::{Duration, Instant};
    let cb = cb.clone().unbind();
    let (token, failed) = (token.clone(), failed.clone());
    let start = Instant::now();
    // the current stage and the time of the last search report
    let state = std::sync::Mutex::new((String::new(), None::<Instant>));
    std::sync::Arc::new(move |p: &Progress| {
        if token.is_cancelled() {
            return;
        }
        let mut st = state.lock().unwrap_or_else(|e| e.into_inner());
        let (evaluations, cost) = match p {
            Progress::Stage { name } => {
                st.0 = name.clone();
                st.1 = None;
                (None, None)
            }
            Progress::Search { evaluations, cost } => {
                if st
                    .1
                    .is_some_and(|t| t.elapsed() < Duration::from_millis(200))
                {
                    return;
                }
                st.1 = Some(Instant::now());
                (Some(*evaluations), Some(*cost))
            }
        };
        let stage = st.0.clone();
        drop(st);
        Python::with_gil(|py| {
            let call = || -> PyResult<()> {
                let d = PyDict::new(py);
                d.set_item("stage", &stage)?;
                d.set_item("evaluations", evaluations)?;
                d.set_item("cost", cost)?;
                d.set_item("elapsed_s", start.elapsed().as_secs_f64())?;
                cb.call1(py, (d,))?;
                Ok(())
            };
            if let Err(e) = call() {
                *failed.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                token.cancel();
            }
        });
    })
}

/// Keyword settings as a JSON object (None when there are none).
fn settings_json(
    py: Python<'_>,
    settings: Option<&Bound<'_, PyDict>>,
    what: &str,
) -> PyResult<Option<String>> {
    let Some(d) = settings.filter(|d| !d.is_empty()) else {
        return Ok(None);
    };
    // JSON has no inf or NaN: an infinite step3_window is its default (None), any other
    // non-finite number is refused here, naming the setting
    let d = d.copy()?;
    for (k, v) in d.clone().iter() {
        if let Ok(x) = v.extract::<f64>() {
            if !x.is_finite() && !v.is_instance_of::<pyo3::types::PyBool>() {
                let key: String = k.extract()?;
                if key == "step3_window" && x == f64::INFINITY {
                    d.set_item(k, py.None())?;
                } else {
                    return Err(PyValueError::new_err(format!(
                        "{what}: {key} = {x}: must be a finite number"
                    )));
                }
            }
        }
    }
    Ok(Some(
        py.import("json")?
            .call_method1("dumps", (d,))
            .map_err(|e| PyValueError::new_err(format!("{what}: {e}")))?
            .extract()?,
    ))
}

/// mvem: mean-value diesel engine model (VGT + EGR) of Wahlstrom & Eriksson (2011).
#[pymodule]
#[pyo3(name = "_mvem")]
fn mvem_native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_class::<PyModel>()?;
    m.add_function(wrap_pyfunction!(closed_loop, m)?)?;
    m.add_function(wrap_pyfunction!(tune, m)?)?;
    m.add_function(wrap_pyfunction!(validate, m)?)?;
    m.add_function(wrap_pyfunction!(campaign, m)?)?;
    m.add_function(wrap_pyfunction!(lab, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_many, m)?)?;
    m.add_function(wrap_pyfunction!(steady, m)?)?;
    m.add_function(wrap_pyfunction!(loop_margins, m)?)?;
    m.add_function(wrap_pyfunction!(published_params, m)?)?;
    m.add_function(wrap_pyfunction!(linearize, m)?)?;
    m.add_function(wrap_pyfunction!(frequency_response, m)?)?;
    m.add_function(wrap_pyfunction!(step_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(step_response, m)?)?;
    m.add_function(wrap_pyfunction!(variables, m)?)?;
    m.add_function(wrap_pyfunction!(parameters, m)?)?;
    m.add_class::<Plant>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
