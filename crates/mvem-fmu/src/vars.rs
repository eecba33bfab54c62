//! The FMU's variable table: value references, names, causalities, descriptions and units,
//! and the configuration ([`FmuConfig`]: model variant, cylinder-temperature mode, parameter
//! set) that one shared library reads from the FMU's `resources/` at instantiation.
//!
//! One table serves the C ABI (value-reference lookup) and the generated
//! `modelDescription.xml`, so the two cannot disagree. Layout of the value references
//! (`n` = 8, 10 or 12 states):
//!
//! | range          | what                                                              |
//! |----------------|-------------------------------------------------------------------|
//! | 0..4           | inputs n_e \[rpm\], u_delta \[mg/cycle/cyl\], u_egr \[%\], u_vgt \[%\]    |
//! | 100..100+n     | the states (also outputs): p_im, p_em, (T_im, T_em, ...) ...      |
//! | 200..200+n     | their derivatives der(p_im), ...                                  |
//! | 300..300+S     | the algebraic signals of [`Signals::NAMES`] (outputs), except the  |
//! |                | ones named like a state (T_im, T_em, p_c in the 10/12-state models)|
//! | 1000..1000+P   | every scalar parameter of [`Params`] (tunable, `group.field[i]`)  |

use mvem::model::{
    CylinderTemp, ModelOrder, Signals, STATE_NAMES_10, STATE_NAMES_12, STATE_NAMES_8,
};
use mvem::params::{ParamInfo, Params};
use serde_json::{json, Value};

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

/// Name of the configuration file inside the FMU's `resources/` folder.
pub const CONFIG_FILE: &str = "mvem.json";

/// Start values of the inputs n_e \[rpm\], u_delta \[mg/cycle\], u_egr \[%\], u_vgt \[%\] (the demo
/// operating point); names, units and descriptions are the core's
/// ([`mvem::model::meta::INPUTS`]).
pub const INPUT_STARTS: [f64; 4] = [1500.0, 110.0, 80.0, 75.0];

/// Name of input `i` (n_e, u_delta, u_egr, u_vgt).
pub fn input_name(i: usize) -> &'static str {
    mvem::model::meta::INPUTS[i].name
}

/// What the FMU simulates: written to `resources/mvem.json` by the packager and read by the
/// shared library at `fmi2Instantiate`, so one binary serves every variant and parameter set.
#[derive(Debug, Clone, PartialEq)]
pub struct FmuConfig {
    /// Model variant (8, 10 or 12 states).
    pub order: ModelOrder,
    /// Cylinder-out temperature fixed point: `Converged` (Model Exchange and Co-Simulation) or
    /// `OneIteration` (Co-Simulation only: the memory is held between accepted solver steps,
    /// so the right-hand side is not a pure function of the state).
    pub cylinder_temp: CylinderTemp,
    /// Parameter set (the start values of the parameter variables).
    pub params: Params,
}

impl Default for FmuConfig {
    fn default() -> Self {
        Self {
            order: ModelOrder::Eight,
            cylinder_temp: CylinderTemp::Converged,
            params: Params::published(),
        }
    }
}

impl FmuConfig {
    /// The JSON document stored as `resources/mvem.json`.
    pub fn to_json(&self) -> String {
        let doc = json!({
            "format": "mvem-fmu-config-1",
            "model": self.order.states(),
            "cylinder_temp": match self.cylinder_temp {
                CylinderTemp::Converged => "converged",
                CylinderTemp::OneIteration => "one-iteration",
            },
            "params": self.params,
        });
        serde_json::to_string_pretty(&doc).expect("configuration serializes")
    }

    /// Parse and validate `resources/mvem.json`; the message names the field.
    pub fn from_json(text: &str) -> Result<Self, String> {
        let doc: Value = serde_json::from_str(text).map_err(|e| format!("{CONFIG_FILE}: {e}"))?;
        let model = doc["model"]
            .as_u64()
            .and_then(|n| ModelOrder::from_states(n as usize))
            .ok_or_else(|| {
                format!(
                    "{CONFIG_FILE}: model = {} (expected 8, 10 or 12)",
                    doc["model"]
                )
            })?;
        let cylinder_temp = match doc["cylinder_temp"].as_str() {
            Some("converged") => CylinderTemp::Converged,
            Some("one-iteration") => CylinderTemp::OneIteration,
            _ => {
                return Err(format!(
                "{CONFIG_FILE}: cylinder_temp = {} (expected \"converged\" or \"one-iteration\")",
                doc["cylinder_temp"]
            ))
            }
        };
        let params: Params = serde_json::from_value(doc["params"].clone())
            .map_err(|e| format!("{CONFIG_FILE}: params: {e}"))?;
        params
            .validate()
            .map_err(|e| format!("{CONFIG_FILE}: invalid parameters: {e}"))?;
        Ok(Self {
            order: model,
            cylinder_temp,
            params,
        })
    }

    /// Whether the Model Exchange interface is offered (only with a pure right-hand side).
    pub fn model_exchange(&self) -> bool {
        self.cylinder_temp == CylinderTemp::Converged
    }

    /// Start values of the parameter variables, in [`param_table`] order.
    pub fn param_values(&self) -> Vec<f64> {
        param_table().iter().map(|p| self.params.value(p)).collect()
    }

    /// The layout of the variables of this variant.
    pub fn layout(&self) -> Layout {
        Layout::new(self.order)
    }
}

/// The variables that depend on the model variant: states and exposed signals.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// State names.
    pub states: &'static [&'static str],
    /// Whether signal `i` of [`Signals::NAMES`] is a variable (not when a state has its name).
    pub signal_exposed: Vec<bool>,
}

impl Layout {
    /// The layout of the variant `order`.
    pub fn new(order: ModelOrder) -> Self {
        let states: &'static [&'static str] = match order {
            ModelOrder::Eight => &STATE_NAMES_8,
            ModelOrder::Ten => &STATE_NAMES_10,
            ModelOrder::Twelve => &STATE_NAMES_12,
        };
        let signal_exposed = Signals::NAMES.iter().map(|n| !states.contains(n)).collect();
        Self {
            states,
            signal_exposed,
        }
    }

    /// Number of continuous states.
    pub fn n_states(&self) -> usize {
        self.states.len()
    }

    /// What the value reference `vr` refers to.
    pub fn lookup(&self, vr: u32) -> Option<Kind> {
        let n = self.n_states() as u32;
        let i = |base: u32| (vr - base) as usize;
        match vr {
            v if v < VR_INPUT + 4 => Some(Kind::Input(i(VR_INPUT))),
            v if (VR_STATE..VR_STATE + n).contains(&v) => Some(Kind::State(i(VR_STATE))),
            v if (VR_DER..VR_DER + n).contains(&v) => Some(Kind::Derivative(i(VR_DER))),
            v if (VR_SIGNAL..VR_SIGNAL + Signals::COUNT as u32).contains(&v)
                && self.signal_exposed[i(VR_SIGNAL)] =>
            {
                Some(Kind::Signal(i(VR_SIGNAL)))
            }
            v if (VR_PARAM..VR_PARAM + param_table().len() as u32).contains(&v) => {
                Some(Kind::Param(i(VR_PARAM)))
            }
            _ => None,
        }
    }
}

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

/// Every scalar parameter, in the order of the core's parameter registry (file order); the
/// variable name is the parameter's path ([`ParamInfo::path`], e.g. `turbine.c_m[1]`).
pub fn param_table() -> &'static [ParamInfo] {
    Params::registry()
}

/// Build a [`Params`] from flat parameter values (same order as [`param_table`]).
pub fn params_from_values(values: &[f64]) -> Result<Params, String> {
    let mut p = Params::published();
    for (info, v) in param_table().iter().zip(values) {
        if !v.is_finite() {
            return Err(format!("parameter {} = {v} is not finite", info.path));
        }
        if let Some(x) = p.value_mut(info) {
            *x = *v;
        }
    }
    Ok(p)
}

/// Names of the signals as FMU variables: the four saturated inputs are renamed `<name>_sat`
/// so they do not clash with the inputs.
pub fn signal_name(i: usize) -> String {
    let n = Signals::NAMES[i];
    if mvem::model::meta::INPUTS.iter().any(|v| v.name == n) {
        format!("{n}_sat")
    } else {
        n.to_string()
    }
}

/// The model's GUID: a hash of the crate version, the configuration (variant, cylinder
/// temperature mode) and the variable table with its start values, so an FMU whose
/// `modelDescription.xml` and `resources/mvem.json` (or binary) disagree is refused at
/// instantiation.
pub fn guid(cfg: &FmuConfig) -> String {
    // FNV-1a over every name and start value
    let mut h: u64 = 0xcbf29ce484222325;
    let mut eat = |s: &str| {
        for b in s.bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x100000001b3);
        }
        h ^= 0xff;
        h = h.wrapping_mul(0x100000001b3);
    };
    eat(env!("CARGO_PKG_VERSION"));
    eat(&format!("{:?}/{:?}", cfg.order, cfg.cylinder_temp));
    for v in &mvem::model::meta::INPUTS {
        eat(v.name);
    }
    let layout = cfg.layout();
    for n in layout.states {
        eat(n);
    }
    for (i, n) in Signals::NAMES.iter().enumerate() {
        if layout.signal_exposed[i] {
            eat(n);
        }
    }
    for (p, v) in param_table().iter().zip(cfg.param_values()) {
        eat(&p.path);
        eat(&format!("{v:e}"));
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_round_trip_through_flat_values() {
        let vals: Vec<f64> = FmuConfig::default().param_values();
        assert!(vals.len() > 60, "{} parameters", vals.len());
        let p = params_from_values(&vals).unwrap();
        assert_eq!(p, Params::published());
        let names: Vec<&str> = param_table().iter().map(|p| p.path.as_str()).collect();
        assert!(names.contains(&"vgt_actuator.tau_dvgt"));
        assert!(names.contains(&"compressor.q_c[2][1]"));
    }

    #[test]
    fn lookup_covers_ranges_and_rejects_gaps() {
        let l = Layout::new(ModelOrder::Eight);
        assert_eq!(l.lookup(3), Some(Kind::Input(3)));
        assert_eq!(l.lookup(4), None);
        assert_eq!(l.lookup(107), Some(Kind::State(7)));
        assert_eq!(l.lookup(108), None);
        assert_eq!(l.lookup(200), Some(Kind::Derivative(0)));
        assert_eq!(l.lookup(300), Some(Kind::Signal(0)));
        assert_eq!(l.lookup(300 + Signals::COUNT as u32), None);
        assert_eq!(l.lookup(1000), Some(Kind::Param(0)));
        assert_eq!(l.lookup(u32::MAX), None);
        assert_eq!(signal_name(0), "n_e_sat");
        let l12 = Layout::new(ModelOrder::Twelve);
        assert_eq!(l12.lookup(111), Some(Kind::State(11)));
        assert_eq!(l12.lookup(112), None);
        // the signals named like a state (T_im, T_em, p_c) are not variables of the 12-state FMU
        for name in ["T_im", "T_em", "p_c"] {
            let j = Signals::NAMES.iter().position(|n| *n == name).unwrap();
            assert_eq!(l12.lookup(VR_SIGNAL + j as u32), None, "{name}");
            assert!(l.lookup(VR_SIGNAL + j as u32).is_some(), "{name}");
        }
    }

    #[test]
    fn config_round_trips_and_guid_depends_on_it() {
        let mut c = FmuConfig {
            order: ModelOrder::Ten,
            cylinder_temp: CylinderTemp::OneIteration,
            params: Params::published(),
        };
        c.params.turbo.j_t *= 1.5;
        let back = FmuConfig::from_json(&c.to_json()).unwrap();
        assert_eq!(back, c);
        assert!(!c.model_exchange());
        let g = guid(&c);
        assert_eq!(g, guid(&back));
        assert_ne!(g, guid(&FmuConfig::default()));
        let mut other = c.clone();
        other.order = ModelOrder::Twelve;
        assert_ne!(g, guid(&other));
        let e = FmuConfig::from_json(r#"{"model": 9, "cylinder_temp": "converged"}"#).unwrap_err();
        assert!(e.contains("model = 9"), "{e}");
    }
}
