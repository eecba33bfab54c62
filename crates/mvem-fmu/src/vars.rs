//! The FMU's variable table: value references, names, causalities, descriptions and units.
//!
//! One table serves the C ABI (value-reference lookup) and the generated
//! `modelDescription.xml`, so the two cannot disagree. Layout of the value references:
//!
//! | range          | what                                                              |
//! |----------------|-------------------------------------------------------------------|
//! | 0..4           | inputs n_e [rpm], u_delta [mg/cycle/cyl], u_egr [%], u_vgt [%]    |
//! | 100..108       | the 8 states (also outputs): p_im, p_em, X_Oim, X_Oem, omega_t, ... |
//! | 200..208       | their derivatives der(p_im), ...                                  |
//! | 300..300+S     | every algebraic signal of [`Signals::NAMES`] (outputs)            |
//! | 1000..1000+P   | every scalar parameter of [`Params`] (tunable, `group.field[i]`)  |

use mvem::model::{Signals, STATE_NAMES_8};
use mvem::params::Params;
use serde_json::Value;
use std::sync::OnceLock;

/// First value reference of the inputs.
pub const VR_INPUT: u32 = 0;
/// First value reference of the states.
pub const VR_STATE: u32 = 100;
/// First value reference of the state derivatives.
pub const VR_DER: u32 = 200;
/// First value reference of the algebraic signals.
pub const VR_SIGNAL: u32 = 300;
/// First value reference of the parameters.
pub const VR_PARAM: u32 = 1000;

/// Input names, descriptions, units and start values (the demo operating point).
pub const INPUTS: [(&str, &str, &str, f64); 4] = [
    ("n_e", "Engine speed n_e [rpm]", "rpm", 1500.0),
    (
        "u_delta",
        "Injected fuel u_delta [mg/cycle/cylinder]",
        "mg/cycle",
        110.0,
    ),
    (
        "u_egr",
        "EGR valve command u_egr [%] (0 closed, 100 open)",
        "%",
        80.0,
    ),
    (
        "u_vgt",
        "VGT command u_vgt [%] (0 closed, 100 open)",
        "%",
        75.0,
    ),
];

/// Units of the states (same order as [`STATE_NAMES_8`]).
pub const STATE_UNITS: [&str; 8] = ["Pa", "Pa", "1", "1", "rad/s", "%", "%", "%"];

/// Descriptions of the states.
pub const STATE_DESCRIPTIONS: [&str; 8] = [
    "Intake manifold pressure p_im [Pa] (state, eq. (6))",
    "Exhaust manifold pressure p_em [Pa] (state, eq. (6))",
    "Intake manifold oxygen mass fraction X_Oim [-] (state, eq. (9))",
    "Exhaust manifold oxygen mass fraction X_Oem [-] (state, eq. (9))",
    "Turbo speed omega_t [rad/s] (state, eq. (42))",
    "EGR actuator state u_egr1 [%] (state, eq. (40))",
    "EGR actuator state u_egr2 [%] (state, eq. (41))",
    "VGT actuator state u_vgt [%] (state, eq. (57))",
];

/// What a variable is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Input `i` (n_e, u_delta, u_egr, u_vgt).
    Input(usize),
    /// State `i`.
    State(usize),
    /// Derivative of state `i`.
    Derivative(usize),
    /// Algebraic signal `i` of [`Signals::NAMES`].
    Signal(usize),
    /// Scalar parameter `i` of [`param_table`].
    Param(usize),
}

/// One scalar parameter: its FMU name and the JSON path into the serialized [`Params`].
#[derive(Debug, Clone)]
pub struct ParamVar {
    /// Name, e.g. `turbine.c_m[1]` (1-based index like Modelica).
    pub name: String,
    /// Group (e.g. `turbine`) and field (e.g. `c_m`).
    pub group: String,
    /// Field name within the group.
    pub field: String,
    /// Array indices (0-based) for array fields.
    pub index: Vec<usize>,
    /// Published value.
    pub start: f64,
}

/// The serialized published parameters (the base document every parameter set is built from).
pub fn published_json() -> &'static Value {
    static CELL: OnceLock<Value> = OnceLock::new();
    CELL.get_or_init(|| {
        serde_json::to_value(Params::published()).expect("parameters serialize to JSON")
    })
}

fn flatten(v: &Value, group: &str, field: &str, index: &mut Vec<usize>, out: &mut Vec<ParamVar>) {
    match v {
        Value::Number(n) => {
            let mut name = format!("{group}.{field}");
            for i in index.iter() {
                name.push_str(&format!("[{}]", i + 1));
            }
            out.push(ParamVar {
                name,
                group: group.to_string(),
                field: field.to_string(),
                index: index.clone(),
                start: n.as_f64().unwrap_or(f64::NAN),
            });
        }
        Value::Array(a) => {
            for (i, e) in a.iter().enumerate() {
                index.push(i);
                flatten(e, group, field, index, out);
                index.pop();
            }
        }
        _ => {}
    }
}

/// Every scalar parameter of the published set, in document order.
pub fn param_table() -> &'static [ParamVar] {
    static CELL: OnceLock<Vec<ParamVar>> = OnceLock::new();
    CELL.get_or_init(|| {
        let mut out = Vec::new();
        if let Value::Object(groups) = published_json() {
            for (g, fields) in groups {
                if let Value::Object(fields) = fields {
                    for (f, v) in fields {
                        flatten(v, g, f, &mut Vec::new(), &mut out);
                    }
                }
            }
        }
        out
    })
}

/// Build a [`Params`] from flat parameter values (same order as [`param_table`]).
pub fn params_from_values(values: &[f64]) -> Result<Params, String> {
    let mut doc = published_json().clone();
    for (p, v) in param_table().iter().zip(values) {
        let num = serde_json::Number::from_f64(*v)
            .ok_or_else(|| format!("parameter {} = {v} is not finite", p.name))?;
        let mut slot = &mut doc[p.group.as_str()][p.field.as_str()];
        for i in &p.index {
            slot = &mut slot[*i];
        }
        *slot = Value::Number(num);
    }
    serde_json::from_value(doc).map_err(|e| format!("parameters: {e}"))
}

/// Names of the signals as FMU variables: the four saturated inputs are renamed `<name>_sat`
/// so they do not clash with the inputs.
pub fn signal_name(i: usize) -> String {
    let n = Signals::NAMES[i];
    if INPUTS.iter().any(|(name, ..)| *name == n) {
        format!("{n}_sat")
    } else {
        n.to_string()
    }
}

/// What the value reference `vr` refers to.
pub fn lookup(vr: u32) -> Option<Kind> {
    let i = |base: u32| (vr - base) as usize;
    match vr {
        v if v < VR_INPUT + 4 => Some(Kind::Input(i(VR_INPUT))),
        v if (VR_STATE..VR_STATE + 8).contains(&v) => Some(Kind::State(i(VR_STATE))),
        v if (VR_DER..VR_DER + 8).contains(&v) => Some(Kind::Derivative(i(VR_DER))),
        v if (VR_SIGNAL..VR_SIGNAL + Signals::COUNT as u32).contains(&v) => {
            Some(Kind::Signal(i(VR_SIGNAL)))
        }
        v if (VR_PARAM..VR_PARAM + param_table().len() as u32).contains(&v) => {
            Some(Kind::Param(i(VR_PARAM)))
        }
        _ => None,
    }
}

/// The state names (reference-data names).
pub fn state_name(i: usize) -> &'static str {
    STATE_NAMES_8[i]
}

/// The model's GUID: a hash of the variable table and the crate version, so an FMU whose
/// binary and `modelDescription.xml` come from different builds is refused at instantiation.
pub fn guid() -> &'static str {
    static CELL: OnceLock<String> = OnceLock::new();
    CELL.get_or_init(|| {
        // FNV-1a over every name and start value
        let mut h: u64 = 0xcbf29ce484222325;
        let mut eat = |s: &str| {
            for b in s.bytes() {
                h ^= b as u64;
                h = h.wrapping_mul(0x100000001b3);
            }
        };
        eat(env!("CARGO_PKG_VERSION"));
        for (n, ..) in INPUTS {
            eat(n);
        }
        for n in STATE_NAMES_8 {
            eat(n);
        }
        for n in Signals::NAMES {
            eat(n);
        }
        for p in param_table() {
            eat(&p.name);
            eat(&format!("{:e}", p.start));
        }
        let hex = format!("{h:016x}");
        format!(
            "{{{}-{}-4{}-8{}-{}{}}}",
            &hex[0..8],
            &hex[8..12],
            &hex[12..15],
            &hex[1..4],
            &hex[4..16],
            "0000"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_round_trip_through_flat_values() {
        let vals: Vec<f64> = param_table().iter().map(|p| p.start).collect();
        assert!(vals.len() > 60, "{} parameters", vals.len());
        let p = params_from_values(&vals).unwrap();
        assert_eq!(p, Params::published());
        let names: Vec<&str> = param_table().iter().map(|p| p.name.as_str()).collect();
        assert!(names.contains(&"vgt_actuator.tau_dvgt"));
        assert!(names.contains(&"compressor.q_c[2][1]"));
    }

    #[test]
    fn lookup_covers_ranges_and_rejects_gaps() {
        assert_eq!(lookup(3), Some(Kind::Input(3)));
        assert_eq!(lookup(4), None);
        assert_eq!(lookup(107), Some(Kind::State(7)));
        assert_eq!(lookup(108), None);
        assert_eq!(lookup(200), Some(Kind::Derivative(0)));
        assert_eq!(lookup(300), Some(Kind::Signal(0)));
        assert_eq!(lookup(300 + Signals::COUNT as u32), None);
        assert_eq!(lookup(1000), Some(Kind::Param(0)));
        assert_eq!(lookup(u32::MAX), None);
        assert_eq!(signal_name(0), "n_e_sat");
    }
}
