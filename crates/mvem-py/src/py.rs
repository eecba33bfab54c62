//! The pyo3 layer: conversions only (see [`crate::core`]).

use crate::core::{self, CoreError, SimArgs};
use mvem::params::Params;
use mvem::sim::input::INPUT_COLUMNS;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

fn to_py_err(e: CoreError) -> PyErr {
    match e {
        CoreError::Value(m) => PyValueError::new_err(m),
        CoreError::Runtime(m) => PyRuntimeError::new_err(m),
    }
}

fn parse_params(py: Python<'_>, params: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Params>> {
    let Some(obj) = params else { return Ok(None) };
    if obj.is_none() {
        return Ok(None);
    }
    if obj.is_instance_of::<PyDict>() {
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
    arr.call_method0("tolist")?.extract()
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
    let rows: Vec<Vec<f64>> = arr.call_method0("tolist")?.extract()?;
    Ok(rows
        .into_iter()
        .map(|r| std::array::from_fn(|c| r[c]))
        .collect())
}

/// Simulate the 8-state model from the steady state at the first input row.
///
/// inputs: dict with columns time_s [s], n_e_rpm [rpm], u_delta_mg [mg/cycle/cylinder],
///     u_egr_pct [%], u_vgt_pct [%] (1-D arrays), or a 2-D array with these 5 columns. Values are
///     interpolated linearly between rows; two rows with the same time make a step.
/// t_end: end time [s] (default: the last input time; inputs are held after it).
/// dt: output interval [s]. rtol, atol: integrator tolerances (atol relative to the state scales).
/// params: None (published set), a dict of overrides ({"turbo": {"j_t": 1e-4}} or
///     {"turbo.j_t": 1e-4}) or a path to a TOML/JSON parameter file.
///
/// Returns a dict of numpy arrays: "t" [s], the states (p_im [Pa], p_em [Pa], X_Oim, X_Oem [-],
/// omega_t [rad/s], u_egr1, u_egr2, u_vgt_act [%]) and every signal (W_c [kg/s], n_t [rpm], ...).
/// Raises ValueError for bad inputs/options/parameters, RuntimeError if the solver fails.
#[pyfunction]
#[pyo3(signature = (inputs, t_end=None, dt=0.01, rtol=1e-6, atol=1e-8, params=None))]
fn simulate<'py>(
    py: Python<'py>,
    inputs: &Bound<'py, PyAny>,
    t_end: Option<f64>,
    dt: f64,
    rtol: f64,
    atol: f64,
    params: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let rows = input_rows(py, inputs)?;
    let p = parse_params(py, params)?;
    let args = SimArgs {
        t_end,
        dt,
        rtol,
        atol,
    };
    let (names, cols) = py
        .allow_threads(move || core::simulate_rows(&rows, args, p))
        .map_err(to_py_err)?;
    let np = py.import("numpy")?;
    let out = PyDict::new(py);
    for (n, c) in names.into_iter().zip(cols) {
        out.set_item(n, np.call_method1("array", (c,))?)?;
    }
    Ok(out)
}

/// Steady state (equilibrium) at constant inputs.
///
/// n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]; params as in simulate.
/// Returns a dict of floats (the inputs as n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct, the 8
/// states and every signal, SI units) plus "physically_valid" (bool) and "flags" (list of the
/// active guard saturations). Raises ValueError for non-finite inputs or bad parameters,
/// RuntimeError if no equilibrium is found.
#[pyfunction]
#[pyo3(signature = (n_e, u_delta, u_egr, u_vgt, params=None))]
fn steady<'py>(
    py: Python<'py>,
    n_e: f64,
    u_delta: f64,
    u_egr: f64,
    u_vgt: f64,
    params: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let p = parse_params(py, params)?;
    let s = py
        .allow_threads(move || core::steady([n_e, u_delta, u_egr, u_vgt], p))
        .map_err(to_py_err)?;
    let out = PyDict::new(py);
    for (n, v) in s.values {
        out.set_item(n, v)?;
    }
    out.set_item("physically_valid", s.physically_valid)?;
    out.set_item("flags", s.flags)?;
    Ok(out)
}

/// The published parameter set of Wahlstrom & Eriksson (2011) as a nested dict
/// {group: {field: value}} (SI units; see the parameter file data/published.toml).
#[pyfunction]
fn published_params(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    let text = PyString::new(py, &core::published_json());
    py.import("json")?.call_method1("loads", (text,))
}

/// mvem: mean-value diesel engine model (VGT + EGR) of Wahlstrom & Eriksson (2011).
#[pymodule]
#[pyo3(name = "_mvem")]
fn mvem_native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(steady, m)?)?;
    m.add_function(wrap_pyfunction!(published_params, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
