//! The Python API in plain Rust (no Python types), so it is tested by `cargo test` and the
//! pyo3 layer only converts values.

use mvem::analysis::steady::steady_state;
use mvem::model::{Drive, Engine8, Model, ModelOptions, Signals};
use mvem::params::Params;
use mvem::sim::{simulate, InputSchedule, SimError, SimOptions, Start};
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

fn merge(base: &mut Value, over: &Value, path: &str) -> CoreResult<()> {
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
                    let slot = b
                        .get_mut(head)
                        .ok_or_else(|| CoreError::Value(format!("unknown parameter `{p}`")))?;
                    merge(slot, &Value::Object(nested), head)?;
                    continue;
                }
                let slot = b
                    .get_mut(k)
                    .ok_or_else(|| CoreError::Value(format!("unknown parameter `{p}`")))?;
                merge(slot, v, &p)?;
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

/// Parameters: the published set with the overrides of `json` (nested `{group: {field: v}}` or
/// dotted `{"group.field": v}`), validated.
pub fn params_from_overrides(json: &str) -> CoreResult<Params> {
    let over: Value = serde_json::from_str(json)
        .map_err(|e| CoreError::Value(format!("params: not a JSON-like mapping: {e}")))?;
    if !over.is_object() {
        return Err(CoreError::Value(
            "params must be a dict or a path to a TOML/JSON file".into(),
        ));
    }
    let mut doc = serde_json::to_value(Params::published()).expect("parameters serialize");
    merge(&mut doc, &over, "")?;
    let p: Params =
        serde_json::from_value(doc).map_err(|e| CoreError::Value(format!("params: {e}")))?;
    p.validate()
        .map_err(|e| CoreError::Value(format!("invalid parameters: {e}")))?;
    Ok(p)
}

/// Parameters from a TOML or JSON file.
pub fn params_from_path(path: &Path) -> CoreResult<Params> {
    mvem::io::params::load_params(path).map_err(|e| CoreError::Value(e.to_string()))
}

fn model(params: Option<Params>) -> CoreResult<Engine8> {
    let p = params.unwrap_or_else(Params::published);
    Engine8::new(p, ModelOptions::default())
        .map_err(|e| CoreError::Value(format!("invalid parameters: {e}")))
}

/// Simulation options of the Python API.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimArgs {
    /// End time [s]; `None`: the last input time.
    pub t_end: Option<f64>,
    /// Output interval [s].
    pub dt: f64,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance (relative to the state scales).
    pub atol: f64,
}

impl Default for SimArgs {
    fn default() -> Self {
        let d = SimOptions::default();
        Self {
            t_end: None,
            dt: d.dt_out,
            rtol: d.rtol,
            atol: d.atol,
        }
    }
}

/// Simulate from the steady state at the first input row. `rows` are
/// `[time_s, n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct]` (linear interpolation between rows,
/// two rows with the same time make a step). Returns column names and columns.
pub fn simulate_rows(
    rows: &[[f64; 5]],
    args: SimArgs,
    params: Option<Params>,
) -> CoreResult<(Vec<String>, Vec<Vec<f64>>)> {
    let m = model(params)?;
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
    let opts = SimOptions {
        rtol: args.rtol,
        atol: args.atol,
        dt_out: args.dt,
        ..SimOptions::default()
    };
    opts.validate()
        .map_err(|e| CoreError::Value(e.to_string()))?;
    let sol = simulate(&m, &sched, t0, t_end, Start::SteadyState, &opts).map_err(|e| match e {
        SimError::BadOption { .. } | SimError::BadInterval { .. } => {
            CoreError::Value(e.to_string())
        }
        other => CoreError::Runtime(other.to_string()),
    })?;
    Ok((sol.names, sol.columns))
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
pub fn steady(d: [f64; 4], params: Option<Params>) -> CoreResult<Steady> {
    for (i, v) in d.iter().enumerate() {
        if !v.is_finite() {
            return Err(CoreError::Value(format!(
                "{} = {v} is not finite",
                ["n_e", "u_delta", "u_egr", "u_vgt"][i]
            )));
        }
    }
    let m = model(params)?;
    let ss =
        steady_state(&m, &Drive::from_array(d)).map_err(|e| CoreError::Runtime(e.to_string()))?;
    let mut values: Vec<(String, f64)> = ["n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct"]
        .iter()
        .zip(d)
        .map(|(n, v)| (n.to_string(), v))
        .collect();
    for (n, v) in m.state_names().iter().zip(ss.x) {
        values.push((n.to_string(), v));
    }
    for (n, v) in Signals::NAMES.iter().zip(ss.signals.values()) {
        // the saturated inputs would clash with nothing here, but keep the reference names
        values.push((n.to_string(), v));
    }
    Ok(Steady {
        values,
        physically_valid: ss.physically_valid(),
        flags: ss.flags.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steady_equals_library() {
        let s = steady([1500.0, 110.0, 80.0, 75.0], None).unwrap();
        let lib = steady_state(
            &Engine8::published(),
            &Drive::new(1500.0, 110.0, 80.0, 75.0),
        )
        .unwrap();
        let get = |n: &str| s.values.iter().find(|(k, _)| k == n).unwrap().1;
        assert_eq!(get("p_im"), lib.x[0]);
        assert_eq!(get("W_c"), lib.signals.w_c);
        assert!(s.physically_valid);
        assert!(matches!(
            steady([f64::NAN, 1.0, 1.0, 1.0], None),
            Err(CoreError::Value(_))
        ));
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

    #[test]
    fn simulate_rejects_bad_rows_and_options() {
        let rows = [
            [0.0, 1500.0, 110.0, 80.0, 75.0],
            [1.0, 1500.0, 110.0, 80.0, 75.0],
        ];
        let (names, cols) = simulate_rows(&rows, SimArgs::default(), None).unwrap();
        assert_eq!(names[0], "t");
        assert_eq!(cols[0].len(), 101);
        let bad = [[0.0, f64::NAN, 110.0, 80.0, 75.0]];
        assert!(matches!(
            simulate_rows(&bad, SimArgs::default(), None),
            Err(CoreError::Value(_))
        ));
        let args = SimArgs {
            rtol: -1.0,
            ..SimArgs::default()
        };
        assert!(matches!(
            simulate_rows(&rows, args, None),
            Err(CoreError::Value(_))
        ));
        let one = [[0.0, 1500.0, 110.0, 80.0, 75.0]];
        assert!(matches!(
            simulate_rows(&one, SimArgs::default(), None),
            Err(CoreError::Value(_))
        ));
    }
}
