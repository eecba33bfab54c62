//! Packaging: `modelDescription.xml` from the variable table, and the `.fmu` zip archive.

use crate::vars::{self, FmuConfig};
use mvem::model::{meta, CylinderTemp, Signals};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

/// The model identifier (name of the shared library inside the FMU).
pub const MODEL_IDENTIFIER: &str = "mvem";

/// Units used in the model description (name, factor to SI, SI exponents kg, m, s, K, rad).
const UNITS: &[(&str, f64, [i32; 5])] = &[
    ("Pa", 1.0, [1, -1, -2, 0, 0]),
    ("K", 1.0, [0, 0, 0, 1, 0]),
    ("kg/s", 1.0, [1, 0, -1, 0, 0]),
    ("rad/s", 1.0, [0, 0, -1, 0, 1]),
    ("rpm", std::f64::consts::PI / 30.0, [0, 0, -1, 0, 1]),
    ("N.m", 1.0, [1, 2, -2, 0, 0]),
    ("W", 1.0, [1, 2, -3, 0, 0]),
    ("%", 0.01, [0, 0, 0, 0, 0]),
    ("1", 1.0, [0, 0, 0, 0, 0]),
    ("mg/cycle", 1e-6, [1, 0, 0, 0, 0]),
    ("s", 1.0, [0, 0, 1, 0, 0]),
    ("m", 1.0, [0, 1, 0, 0, 0]),
    ("m2", 1.0, [0, 2, 0, 0, 0]),
    ("m3", 1.0, [0, 3, 0, 0, 0]),
    ("kg.m2", 1.0, [1, 2, 0, 0, 0]),
    ("J/(kg.K)", 1.0, [0, 2, -2, -1, 0]),
    ("J/kg", 1.0, [0, 2, -2, 0, 0]),
    ("W/(m2.K)", 1.0, [1, 0, -3, -1, 0]),
    // the states' time derivatives ([`der_unit`])
    ("Pa/s", 1.0, [1, -1, -3, 0, 0]),
    ("K/s", 1.0, [0, 0, -1, 1, 0]),
    ("1/s", 1.0, [0, 0, -1, 0, 0]),
    ("rad/s2", 1.0, [0, 0, -2, 0, 1]),
    ("%/s", 0.01, [0, 0, -1, 0, 0]),
];

/// The FMI unit of a unit of the core's metadata (`None` for the few without a definition
/// here, e.g. the polynomial coefficients' `Pa^-1/2`).
fn fmi_unit(unit: &str) -> Option<&'static str> {
    let u = match unit {
        "-" => "1",
        "Nm" => "N.m",
        "m^2" => "m2",
        "m^3" => "m3",
        "kg m^2" => "kg.m2",
        "J/(kg K)" => "J/(kg.K)",
        "W/(m^2 K)" => "W/(m2.K)",
        u => u,
    };
    declared(u)
}

/// `unit` as declared in [`UNITS`] (`None` if it is not).
fn declared(unit: &str) -> Option<&'static str> {
    UNITS.iter().map(|(n, ..)| *n).find(|n| *n == unit)
}

/// The FMI unit of the time derivative of a quantity in the FMI unit `unit` (`Pa` -> `Pa/s`,
/// `1` -> `1/s`, `rad/s` -> `rad/s2`), declared in [`UNITS`]; `None` if it is not.
fn der_unit(unit: &str) -> Option<&'static str> {
    let d = match unit {
        "1" => "1/s".to_string(),
        u if u.ends_with("/s") => format!("{u}2"),
        u => format!("{u}/s"),
    };
    declared(&d)
}

/// A description with the unit appended, e.g. `Turbocharger inertia J_t (eq. (42)) [kg m^2]`.
fn with_unit(description: &str, unit: &str) -> String {
    format!("{description} [{unit}]")
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// One row of the model description.
struct Row {
    vr: u32,
    name: String,
    description: String,
    causality: &'static str,
    variability: &'static str,
    initial: Option<&'static str>,
    start: Option<f64>,
    unit: Option<&'static str>,
    derivative_of: Option<usize>,
}

fn rows(cfg: &FmuConfig) -> Vec<Row> {
    let layout = cfg.layout();
    let mut rows = Vec::new();
    for (i, (v, start)) in meta::INPUTS.iter().zip(vars::INPUT_STARTS).enumerate() {
        rows.push(Row {
            vr: vars::VR_INPUT + i as u32,
            name: v.name.to_string(),
            description: with_unit(v.description, v.unit),
            causality: "input",
            variability: "continuous",
            initial: None,
            start: Some(start),
            unit: fmi_unit(v.unit),
            derivative_of: None,
        });
    }
    for (i, name) in layout.states.iter().enumerate() {
        let (unit, description) = match meta::state(name) {
            Some(v) => (fmi_unit(v.unit), with_unit(v.description, v.unit)),
            None => (None, String::new()),
        };
        rows.push(Row {
            vr: vars::VR_STATE + i as u32,
            name: name.to_string(),
            description: format!("{description} (state)"),
            causality: "output",
            variability: "continuous",
            initial: Some("calculated"),
            start: None,
            unit,
            derivative_of: None,
        });
    }
    for (i, name) in layout.states.iter().enumerate() {
        // the state's unit per second (QA: the derivatives had no unit)
        let unit = meta::state(name)
            .and_then(|v| fmi_unit(v.unit))
            .and_then(der_unit);
        rows.push(Row {
            vr: vars::VR_DER + i as u32,
            name: format!("der({name})"),
            description: format!(
                "Time derivative of {name} [{}]",
                unit.unwrap_or("per second")
            ),
            causality: "local",
            variability: "continuous",
            initial: Some("calculated"),
            start: None,
            unit,
            derivative_of: Some(i),
        });
    }
    for (i, v) in Signals::META.iter().enumerate() {
        if !layout.signal_exposed[i] {
            continue;
        }
        rows.push(Row {
            vr: vars::VR_SIGNAL + i as u32,
            name: vars::signal_name(i),
            unit: fmi_unit(v.unit),
            description: with_unit(v.description, v.unit),
            causality: "output",
            variability: "continuous",
            initial: Some("calculated"),
            start: None,
            derivative_of: None,
        });
    }
    let starts = cfg.param_values();
    for (i, (p, start)) in vars::param_table().iter().zip(starts).enumerate() {
        rows.push(Row {
            vr: vars::VR_PARAM + i as u32,
            name: p.path.clone(),
            unit: fmi_unit(p.unit),
            description: with_unit(&p.describe(), p.unit),
            causality: "parameter",
            variability: "tunable",
            initial: Some("exact"),
            start: Some(start),
            derivative_of: None,
        });
    }
    debug_assert!(rows.iter().all(|r| layout.lookup(r.vr).is_some()));
    rows
}

/// The `modelDescription.xml` text of the configuration `cfg`.
pub fn model_description(cfg: &FmuConfig) -> String {
    let rows = rows(cfg);
    let n = cfg.layout().n_states();
    let cyl = match cfg.cylinder_temp {
        CylinderTemp::Converged => "converged cylinder-out temperature",
        CylinderTemp::OneIteration => "one-iteration cylinder-out temperature (Co-Simulation only)",
    };
    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="2.0" modelName="mvem" guid="{}" description="Mean-value diesel engine model with VGT and EGR (Wahlstrom and Eriksson 2011), {n} states, {cyl}; starts at the steady state of the start inputs" generationTool="mvem-fmu {}" variableNamingConvention="flat" numberOfEventIndicators="0">"#,
        vars::guid(cfg),
        env!("CARGO_PKG_VERSION")
    );
    if cfg.model_exchange() {
        let _ = writeln!(
            x,
            r#"  <ModelExchange modelIdentifier="{MODEL_IDENTIFIER}" canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="false" canSerializeFMUstate="false" providesDirectionalDerivative="true"/>"#
        );
    }
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false" maxOutputDerivativeOrder="0" canRunAsynchronuously="false" canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="false" canSerializeFMUstate="false" providesDirectionalDerivative="true"/>"#
    );
    let _ = writeln!(x, "  <UnitDefinitions>");
    for (name, factor, e) in UNITS {
        let labels = ["kg", "m", "s", "K", "rad"];
        let mut attrs = String::new();
        for (l, v) in labels.iter().zip(e) {
            if *v != 0 {
                let _ = write!(attrs, r#" {l}="{v}""#);
            }
        }
        if *factor != 1.0 {
            let _ = write!(attrs, r#" factor="{factor:e}""#);
        }
        let _ = writeln!(
            x,
            r#"    <Unit name="{}"><BaseUnit{attrs}/></Unit>"#,
            xml_escape(name)
        );
    }
    let _ = writeln!(x, "  </UnitDefinitions>");
    let _ = writeln!(
        x,
        r#"  <DefaultExperiment startTime="0" stopTime="8" tolerance="1e-06" stepSize="0.01"/>"#
    );
    let _ = writeln!(x, "  <ModelVariables>");
    let mut index_of_vr = HashMap::new();
    for (k, r) in rows.iter().enumerate() {
        index_of_vr.insert(r.vr, k + 1);
        let _ = write!(
            x,
            r#"    <ScalarVariable name="{}" valueReference="{}" description="{}" causality="{}" variability="{}""#,
            xml_escape(&r.name),
            r.vr,
            xml_escape(&r.description),
            r.causality,
            r.variability
        );
        if let Some(i) = r.initial {
            let _ = write!(x, r#" initial="{i}""#);
        }
        let _ = write!(x, "><Real");
        if let Some(u) = r.unit {
            let _ = write!(x, r#" unit="{}""#, xml_escape(u));
        }
        if let Some(s) = r.start {
            let _ = write!(x, r#" start="{s:e}""#);
        }
        if let Some(d) = r.derivative_of {
            // states follow the 4 inputs, 1-based
            let _ = write!(x, r#" derivative="{}""#, 4 + d + 1);
        }
        let _ = writeln!(x, "/></ScalarVariable>");
    }
    let _ = writeln!(x, "  </ModelVariables>");
    let _ = writeln!(x, "  <ModelStructure>");
    let idx = |r: &Row| index_of_vr[&r.vr];
    let _ = writeln!(x, "    <Outputs>");
    for r in rows.iter().filter(|r| r.causality == "output") {
        let _ = writeln!(x, r#"      <Unknown index="{}"/>"#, idx(r));
    }
    let _ = writeln!(x, "    </Outputs>");
    let _ = writeln!(x, "    <Derivatives>");
    for r in rows.iter().filter(|r| r.derivative_of.is_some()) {
        let _ = writeln!(x, r#"      <Unknown index="{}"/>"#, idx(r));
    }
    let _ = writeln!(x, "    </Derivatives>");
    let _ = writeln!(x, "    <InitialUnknowns>");
    for r in rows
        .iter()
        .filter(|r| r.causality == "output" || r.derivative_of.is_some())
    {
        let _ = writeln!(x, r#"      <Unknown index="{}"/>"#, idx(r));
    }
    let _ = writeln!(x, "    </InitialUnknowns>");
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}

fn crc32(data: &[u8]) -> u32 {
    let mut table = [0u32; 256];
    for (i, t) in table.iter_mut().enumerate() {
        let mut c = i as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
        *t = c;
    }
    let mut crc = 0xFFFF_FFFFu32;
    for b in data {
        crc = table[((crc ^ *b as u32) & 0xFF) as usize] ^ (crc >> 8);
    }
    !crc
}

/// A zip archive of stored (uncompressed) entries; enough for an FMU and free of dependencies.
pub fn zip_stored(entries: &[(&str, &[u8])]) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in entries {
        let size = u32::try_from(data.len()).map_err(|_| format!("{name}: larger than 4 GiB"))?;
        let offset = u32::try_from(out.len()).map_err(|_| "archive larger than 4 GiB")?;
        let crc = crc32(data);
        let n = name.as_bytes();
        // local file header
        out.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
        out.extend_from_slice(&20u16.to_le_bytes()); // version needed
        out.extend_from_slice(&0u16.to_le_bytes()); // flags
        out.extend_from_slice(&0u16.to_le_bytes()); // method: stored
        out.extend_from_slice(&0u16.to_le_bytes()); // time
        out.extend_from_slice(&0x21u16.to_le_bytes()); // date 1980-01-01
        out.extend_from_slice(&crc.to_le_bytes());
        out.extend_from_slice(&size.to_le_bytes());
        out.extend_from_slice(&size.to_le_bytes());
        out.extend_from_slice(&(n.len() as u16).to_le_bytes());
        out.extend_from_slice(&0u16.to_le_bytes());
        out.extend_from_slice(n);
        out.extend_from_slice(data);
        // central directory entry
        central.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
        central.extend_from_slice(&(3u16 << 8 | 20).to_le_bytes()); // made by unix, 2.0
        central.extend_from_slice(&20u16.to_le_bytes());
        central.extend_from_slice(&0u16.to_le_bytes());
        central.extend_from_slice(&0u16.to_le_bytes());
        central.extend_from_slice(&0u16.to_le_bytes());
        central.extend_from_slice(&0x21u16.to_le_bytes());
        central.extend_from_slice(&crc.to_le_bytes());
        central.extend_from_slice(&size.to_le_bytes());
        central.extend_from_slice(&size.to_le_bytes());
        central.extend_from_slice(&(n.len() as u16).to_le_bytes());
        central.extend_from_slice(&0u16.to_le_bytes()); // extra
        central.extend_from_slice(&0u16.to_le_bytes()); // comment
        central.extend_from_slice(&0u16.to_le_bytes()); // disk
        central.extend_from_slice(&0u16.to_le_bytes()); // internal attrs
        central.extend_from_slice(&(0o100644u32 << 16).to_le_bytes()); // external attrs
        central.extend_from_slice(&offset.to_le_bytes());
        central.extend_from_slice(n);
    }
    let cd_offset = out.len() as u32;
    let cd_size = central.len() as u32;
    out.extend_from_slice(&central);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    out.extend_from_slice(&cd_size.to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    Ok(out)
}

/// Write the FMU archive `out` of the configuration `cfg` from the shared library `so` (the
/// cdylib `libmvem_fmu.so` built from this crate in release mode). The archive holds
/// `modelDescription.xml`, `binaries/linux64/mvem.so` and `resources/mvem.json` (the
/// configuration the library reads at instantiation). The file is written atomically.
pub fn build(out: &Path, so: &Path, cfg: &FmuConfig) -> Result<(), String> {
    let lib = std::fs::read(so).map_err(|e| format!("{}: {e}", so.display()))?;
    if !lib.starts_with(b"\x7fELF") {
        return Err(format!(
            "{}: not an ELF shared library (the FMU is built for linux64)",
            so.display()
        ));
    }
    let xml = model_description(cfg);
    let so_name = format!("binaries/linux64/{MODEL_IDENTIFIER}.so");
    let config = cfg.to_json();
    let res_name = format!("resources/{}", vars::CONFIG_FILE);
    let zip = zip_stored(&[
        ("modelDescription.xml", xml.as_bytes()),
        (&so_name, &lib),
        (&res_name, config.as_bytes()),
    ])?;
    mvem::io::output::write_atomic(out, &zip).map_err(|e| format!("{}: {e}", out.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_known_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn description_lists_every_variable_once_with_docs() {
        let x = model_description(&FmuConfig::default());
        let n = x.matches("<ScalarVariable ").count();
        assert_eq!(n, 4 + 8 + 8 + Signals::COUNT + vars::param_table().len());
        assert!(x.contains(r#"name="turbo.j_t""#));
        assert!(x.contains("Turbocharger inertia J_t"));
        assert!(x.contains(r#"name="W_c" valueReference"#));
        assert!(x.contains(r#"derivative="5""#));
        // every parameter has a description
        assert!(!x.contains(r#"description="" causality="parameter""#));
        assert!(x.contains("<ModelExchange "));
    }

    /// QA: the der(x) variables had no unit. Each has its state's unit per second, declared in
    /// the UnitDefinitions with the state unit's base units and factor, the second's exponent
    /// one lower; for every variant.
    #[test]
    fn derivatives_have_the_state_unit_per_second() {
        use mvem::model::ModelOrder;
        let def = |u: &str| UNITS.iter().find(|d| d.0 == u).map(|d| (d.1, d.2));
        for order in [ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve] {
            let cfg = FmuConfig {
                order,
                ..FmuConfig::default()
            };
            let rows = rows(&cfg);
            let n = cfg.layout().n_states() as u32;
            let states: Vec<&Row> = rows
                .iter()
                .filter(|r| (vars::VR_STATE..vars::VR_STATE + n).contains(&r.vr))
                .collect();
            let ders: Vec<&Row> = rows.iter().filter(|r| r.derivative_of.is_some()).collect();
            assert_eq!(ders.len(), cfg.layout().n_states());
            assert_eq!(states.len(), ders.len());
            for (d, x) in ders.iter().zip(&states) {
                assert_eq!(d.name, format!("der({})", x.name));
                let (xu, du) = (
                    x.unit.unwrap(),
                    d.unit.unwrap_or_else(|| panic!("{}", d.name)),
                );
                let ((fx, ex), (fd, ed)) = (def(xu).unwrap(), def(du).unwrap());
                assert_eq!(fd, fx, "{du} vs {xu}");
                let mut want = ex;
                want[2] -= 1;
                assert_eq!(ed, want, "{du} vs {xu}");
                assert!(
                    d.description.ends_with(&format!("[{du}]")),
                    "{}",
                    d.description
                );
            }
            let x = model_description(&cfg);
            assert!(x.contains(r#"name="der(p_im)""#));
            assert!(x.contains(r#"<Unit name="Pa/s"><BaseUnit kg="1" m="-1" s="-3"/></Unit>"#));
            assert!(x.contains(r#"<Unit name="%/s"><BaseUnit s="-1" factor="1e-2"/></Unit>"#));
            assert!(!x.contains("[per second]"));
        }
    }

    #[test]
    fn twelve_state_description_has_its_states_and_no_duplicate_names() {
        use mvem::model::ModelOrder;
        let cfg = FmuConfig {
            order: ModelOrder::Twelve,
            cylinder_temp: CylinderTemp::OneIteration,
            ..FmuConfig::default()
        };
        let x = model_description(&cfg);
        // T_im, T_em and p_c are states here; their signals are not listed again
        let n = x.matches("<ScalarVariable ").count();
        assert_eq!(
            n,
            4 + 12 + 12 + Signals::COUNT - 3 + vars::param_table().len()
        );
        let mut names: Vec<&str> = x
            .split(r#"<ScalarVariable name=""#)
            .skip(1)
            .map(|r| r.split('"').next().unwrap())
            .collect();
        let total = names.len();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), total);
        assert!(x.contains(r#"name="der(T_ic)""#));
        assert_eq!(
            x.matches("<Unknown ").count(),
            (12 + Signals::COUNT - 3) * 2 + 24
        );
        // one-iteration: Co-Simulation only
        assert!(!x.contains("<ModelExchange "));
        assert!(x.contains("<CoSimulation "));
    }
}
