//! `mvem params show | check`: print a parameter set, or validate a parameter file listing
//! every problem.

use crate::common;
use anyhow::Result;
use mvem::params::Params;
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// Arguments of `mvem params`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem params show > my_params.toml
  mvem params show --format json
  mvem params check my_params.toml

Parameter files: TOML with one section per component ([gas], [ambient], [intake_manifold],
[exhaust_manifold], [cylinder], [exhaust_pipe], [egr_valve], [egr_actuator], [turbine],
[vgt_actuator], [compressor], [turbo], [initial], optional [intercooler]), the same structure as
JSON, or the authors' flat JSON ({\"parameters\": {\"V_im\": ..., \"c_wpsiVec\": [...], ...}}).
SI units unless noted. `mvem params show` prints every key.")]
pub struct Args {
    #[command(subcommand)]
    pub cmd: Cmd,
}

/// `mvem params` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Cmd {
    /// Print a parameter set (default: the built-in published set).
    #[command(after_help = "\
Examples:
  mvem params show
  mvem params show --params my_params.toml --format json")]
    Show {
        /// Parameter file to print instead of the published set (validated first).
        #[arg(long, value_name = "FILE")]
        params: Option<PathBuf>,
        /// Output format.
        #[arg(long, value_enum, default_value = "toml")]
        format: ShowFormat,
    },
    /// Validate a parameter file: list every problem, exit 2 if there is any.
    #[command(after_help = "\
Examples:
  mvem params check my_params.toml
  mvem params check data/wahlstrom_eriksson_2011_parameters.json

A valid file may still get warnings on stderr (exit code 0) for implausible values: a
displacement v_d outside 0.1-300 dm^3 (it is in m^3), gamma or R inconsistent with c_p and c_V,
a c_mlin that is not c_m at w_tlin.")]
    Check {
        /// The parameter file (TOML, nested JSON or the authors' flat JSON).
        #[arg(value_name = "FILE")]
        file: PathBuf,
    },
}

/// `--format` of `params show`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ShowFormat {
    /// TOML (the project's parameter file format).
    Toml,
    /// JSON with the same structure.
    Json,
}

/// Run `mvem params`.
pub fn run(a: &Args) -> Result<()> {
    match &a.cmd {
        Cmd::Show { params, format } => {
            let p = match params {
                Some(f) => mvem::io::params::load_params(f)?,
                None => Params::published(),
            };
            match format {
                ShowFormat::Toml => print!("{}", mvem::io::params::to_toml(&p)),
                ShowFormat::Json => println!("{}", mvem::io::params::to_json(&p)),
            }
            Ok(())
        }
        Cmd::Check { file } => {
            let problems = check_file(file);
            if problems.is_empty() {
                // valid: what is implausible all the same (warnings, exit code 0)
                if let Ok(p) = mvem::io::params::load_params(file) {
                    for w in p.plausibility_warnings() {
                        eprintln!("warning: {}: {w}", file.display());
                    }
                }
                println!("{}: valid parameter set", file.display());
                Ok(())
            } else {
                Err(common::usage(format!(
                    "{}: {} problem(s):\n  - {}",
                    file.display(),
                    problems.len(),
                    problems.join("\n  - ")
                )))
            }
        }
    }
}

/// Every problem of a parameter file: syntax, unknown and missing keys, wrong types, and the
/// value checks of [`Params::validate`] (run with the faulty entries replaced by the published
/// values, so that the value problems of the remaining entries are reported too).
pub fn check_file(path: &Path) -> Vec<String> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) => return vec![format!("cannot read: {e}")],
    };
    let mut problems = Vec::new();
    // the [test_cell] section, by its own loader
    if let Err(e) = mvem::io::test_cell::parse_test_cell(&text, path) {
        problems.push(e.to_string());
    }
    // TOML's nan and inf become JSON null below: their fields, to say so
    let mut non_finite = Vec::new();
    let nested = if text.trim_start().starts_with('{') {
        let v: Value = match serde_json::from_str(&text) {
            Ok(v) => v,
            Err(e) => return vec![format!("line {}, column {}: {e}", e.line(), e.column())],
        };
        match v.get("parameters") {
            Some(flat) => match flat_to_nested(flat, &mut problems) {
                Some(n) => n,
                None => return problems,
            },
            None => v,
        }
    } else {
        match toml::from_str::<toml::Value>(&text) {
            Ok(t) => {
                non_finite_floats(&t, "", &mut non_finite);
                match serde_json::to_value(t) {
                    Ok(v) => v,
                    Err(e) => return vec![e.to_string()],
                }
            }
            Err(e) => {
                let line = e
                    .span()
                    .map(|s| text[..s.start.min(text.len())].lines().count().max(1));
                let loc = line.map(|l| format!("line {l}: ")).unwrap_or_default();
                return vec![format!("{loc}{}", e.message())];
            }
        }
    };
    let Ok(reference) = serde_json::to_value(Params::published()) else {
        return vec!["internal error: cannot serialize the published set".into()];
    };
    let patched = structure(&nested, &reference, &mut problems);
    // "expected a number, found null" for a nan in the file: say what the file has
    for (path, text) in &non_finite {
        let key = path.split('[').next().unwrap_or(path);
        for p in problems.iter_mut() {
            if p.starts_with(&format!("{key}: expected ")) {
                *p = format!("{path} = {text}: not a finite number (parameters must be finite)");
            }
        }
    }
    match serde_json::from_value::<Params>(patched) {
        Ok(p) => {
            if let Err(issues) = p.validate() {
                problems.extend(issues.0.iter().map(|i| i.to_string()));
            }
        }
        Err(e) => problems.push(e.to_string()),
    }
    problems
}

/// The paths (`section.key`, `section.key[i]`) and text of the non-finite floats (`nan`,
/// `inf`, `-inf`) of a TOML value.
fn non_finite_floats(v: &toml::Value, path: &str, out: &mut Vec<(String, String)>) {
    match v {
        toml::Value::Float(f) if !f.is_finite() => out.push((
            path.to_string(),
            // as TOML writes them
            if f.is_nan() {
                "nan".into()
            } else if *f > 0.0 {
                "inf".into()
            } else {
                "-inf".into()
            },
        )),
        toml::Value::Table(t) => {
            for (k, x) in t {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                non_finite_floats(x, &p, out);
            }
        }
        toml::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                // 1-based, as the parameter registry and `params show` (c_vol1) name them
                non_finite_floats(x, &mvem::params::element_name(path, &[i]), out);
            }
        }
        _ => {}
    }
}

/// The authors' flat keys mapped to sections; unknown keys reported.
fn flat_to_nested(flat: &Value, problems: &mut Vec<String>) -> Option<Value> {
    let Some(obj) = flat.as_object() else {
        problems.push("`parameters` must be an object".into());
        return None;
    };
    let mut root = Map::new();
    for (k, v) in obj {
        match mvem::io::params::FLAT_KEYS.iter().find(|(f, _)| f == k) {
            None => problems.push(format!("unknown parameter `{k}`")),
            Some((_, dotted)) => {
                let (sec, field) = dotted.split_once('.').unwrap_or(("", dotted));
                if let Value::Object(m) = root
                    .entry(sec.to_string())
                    .or_insert_with(|| Value::Object(Map::new()))
                {
                    m.insert(field.to_string(), v.clone());
                }
            }
        }
    }
    Some(Value::Object(root))
}

/// Sections with defaults (may be absent).
const OPTIONAL_SECTIONS: [&str; 3] = ["intercooler", "input_saturation", "integrator_limits"];

/// Compare `given` with the structure of `reference` (the published set), report unknown,
/// missing and mistyped entries, and return `given` with those fixed from `reference`.
fn structure(given: &Value, reference: &Value, problems: &mut Vec<String>) -> Value {
    let (Some(g), Some(r)) = (given.as_object(), reference.as_object()) else {
        problems.push("expected a table of sections".into());
        return reference.clone();
    };
    let mut out = Map::new();
    // the test cell's section (tau_Me, written by `mvem tune`) is not a model parameter; its
    // own loader checks it (`mvem::io::test_cell`)
    for k in g
        .keys()
        .filter(|k| !r.contains_key(*k) && k.as_str() != mvem::io::test_cell::SECTION)
    {
        problems.push(format!("unknown section `{k}`"));
    }
    for (sec, rsec) in r {
        let Some(gsec) = g.get(sec) else {
            if !OPTIONAL_SECTIONS.contains(&sec.as_str()) {
                problems.push(format!("missing section `{sec}`"));
            }
            out.insert(sec.clone(), rsec.clone());
            continue;
        };
        let (Some(gs), Some(rs)) = (gsec.as_object(), rsec.as_object()) else {
            problems.push(format!("`{sec}` must be a section (table)"));
            out.insert(sec.clone(), rsec.clone());
            continue;
        };
        let mut sec_out = Map::new();
        for k in gs.keys().filter(|k| !rs.contains_key(*k)) {
            problems.push(format!("{sec}.{k}: unknown key"));
        }
        for (field, rv) in rs {
            let name = format!("{sec}.{field}");
            let v = match gs.get(field) {
                None => {
                    problems.push(format!("{name}: missing key"));
                    rv.clone()
                }
                Some(gv) => match type_problem(gv, rv) {
                    Some(p) => {
                        problems.push(format!("{name}: {p}"));
                        rv.clone()
                    }
                    None => gv.clone(),
                },
            };
            sec_out.insert(field.clone(), v);
        }
        out.insert(sec.clone(), Value::Object(sec_out));
    }
    Value::Object(out)
}

fn type_problem(given: &Value, reference: &Value) -> Option<String> {
    if same_shape(given, reference) {
        None
    } else {
        Some(format!("expected {}, found {given}", describe(reference)))
    }
}

/// Whether `given` has the shape of `reference`: a number, or a list of the same length whose
/// elements have the shapes of the reference elements.
fn same_shape(given: &Value, reference: &Value) -> bool {
    match (given, reference) {
        (Value::Array(g), Value::Array(r)) => {
            g.len() == r.len() && g.iter().zip(r).all(|(a, b)| same_shape(a, b))
        }
        (_, Value::Array(_)) => false,
        (g, _) => g.is_number(),
    }
}

fn describe(reference: &Value) -> String {
    match reference {
        Value::Array(r) => match r.first() {
            Some(Value::Array(_)) => format!("a list of {} lists ({})", r.len(), describe(&r[0])),
            _ => format!("a list of {} numbers", r.len()),
        },
        _ => "a number".into(),
    }
}
