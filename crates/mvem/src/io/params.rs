//! Parameter files: TOML (the project's format, `crates/mvem/data/published.toml`), JSON of the
//! same structure, and the authors' flat JSON (`wahlstrom_eriksson_2011_parameters.json`,
//! keys like `c_wpsiVec`). Loading validates: unknown or missing fields and invalid values are
//! errors that name the field (and line/column where the parser knows them).

use super::{format_err, IoError};
use crate::params::Params;
use std::path::Path;

/// Mapping between the authors' flat keys and the project's `section.field` paths (one place).
pub const FLAT_KEYS: &[(&str, &str)] = &[
    ("c_pa", "gas.c_pa"),
    ("c_pe", "gas.c_pe"),
    ("c_va", "gas.c_va"),
    ("c_ve", "gas.c_ve"),
    ("R_a", "gas.r_a"),
    ("R_e", "gas.r_e"),
    ("gamma_a", "gas.gamma_a"),
    ("gamma_e", "gas.gamma_e"),
    ("p_amb", "ambient.p_amb"),
    ("T_amb", "ambient.t_amb"),
    ("V_im", "intake_manifold.v_im"),
    ("T_im", "intake_manifold.t_im"),
    ("X_Oc", "intake_manifold.x_oc"),
    ("V_em", "exhaust_manifold.v_em"),
    ("V_d", "cylinder.v_d"),
    ("n_cyl", "cylinder.n_cyl"),
    ("r_c", "cylinder.r_c"),
    ("q_HV", "cylinder.q_hv"),
    ("AFs", "cylinder.afs"),
    ("c_volVec", "cylinder.c_vol"),
    ("eta_sc", "cylinder.eta_sc"),
    ("x_cv", "cylinder.x_cv"),
    ("gamma_c", "cylinder.gamma_c"),
    ("eta_igch", "cylinder.eta_igch"),
    ("c_fricVec", "cylinder.c_fric"),
    ("T_w", "exhaust_pipe.t_w"),
    ("h_tot", "exhaust_pipe.h_tot"),
    ("d_pipe", "exhaust_pipe.d_pipe"),
    ("l_pipe", "exhaust_pipe.l_pipe"),
    ("n_pipe", "exhaust_pipe.n_pipe"),
    ("A_egrmax", "egr_valve.a_egrmax"),
    ("PI_egropt", "egr_valve.pi_egropt"),
    ("c_egr", "egr_valve.c_egr"),
    ("tau_egr1", "egr_actuator.tau_egr1"),
    ("tau_egr2", "egr_actuator.tau_egr2"),
    ("tau_degr", "egr_actuator.tau_degr"),
    ("K_egr", "egr_actuator.k_egr"),
    ("A_vgtmax", "turbine.a_vgtmax"),
    ("K_t", "turbine.k_t"),
    ("c_f1", "turbine.c_f1"),
    ("c_f2", "turbine.c_f2"),
    ("c_vgt1", "turbine.c_vgt1"),
    ("c_vgt2", "turbine.c_vgt2"),
    ("R_t", "turbine.r_t"),
    ("eta_tmmax", "turbine.eta_tmmax"),
    ("BSR_opt", "turbine.bsr_opt"),
    ("c_mVec", "turbine.c_m"),
    ("w_tlin", "turbine.w_tlin"),
    ("c_mlin", "turbine.c_mlin"),
    ("tau_vgt", "vgt_actuator.tau_vgt"),
    ("tau_dvgt", "vgt_actuator.tau_dvgt"),
    ("R_c", "compressor.r_c"),
    ("c_psi2", "compressor.c_psi2"),
    ("c_phi2", "compressor.c_phi2"),
    ("c_wpsiVec", "compressor.c_wpsi"),
    ("c_wphiVec", "compressor.c_wphi"),
    ("eta_cmax", "compressor.eta_cmax"),
    ("w_copt", "compressor.w_copt"),
    ("pi_copt", "compressor.pi_copt"),
    ("c_pi", "compressor.c_pi"),
    ("Q_c", "compressor.q_c"),
    ("J_t", "turbo.j_t"),
    ("p_im_Init", "initial.p_im"),
    ("p_em_Init", "initial.p_em"),
    ("omega_t_Init", "initial.omega_t"),
    ("x_r_Init", "initial.x_r"),
    ("T_1_Init", "initial.t_1"),
    ("uInit_egr", "initial.u_egr"),
    ("uInit_vgt", "initial.u_vgt"),
    ("V_ic", "intercooler.v_ic"),
    ("k_ic", "intercooler.k_ic"),
];

/// Parse a parameter document (TOML, nested JSON or the authors' flat JSON) and validate it.
/// `path` is used in error messages only.
pub fn parse_params(text: &str, path: &Path) -> Result<Params, IoError> {
    let trimmed = text.trim_start();
    let p: Params = if trimmed.starts_with('{') {
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| {
            format_err(
                path,
                Some(e.line()),
                Some(&e.column().to_string()),
                e.to_string(),
            )
        })?;
        match v.get("parameters") {
            Some(flat) => {
                let mut nested = flat_to_nested(flat, path)?;
                // the test-cell section is not a model parameter (read by super::test_cell)
                if let Some(o) = nested.as_object_mut() {
                    o.remove(super::test_cell::SECTION);
                }
                serde_json::from_value(nested)
                    .map_err(|e| format_err(path, None, None, e.to_string()))?
            }
            // nested JSON with a test-cell section: drop it and read the rest
            None if v.get(super::test_cell::SECTION).is_some() => {
                let mut nested = v;
                if let Some(o) = nested.as_object_mut() {
                    o.remove(super::test_cell::SECTION);
                }
                serde_json::from_value(nested)
                    .map_err(|e| format_err(path, None, None, e.to_string()))?
            }
            // nested JSON: parse the text again into the typed structure, so that an unknown
            // or missing field is reported at its line and column
            None => serde_json::from_str(text).map_err(|e| {
                format_err(
                    path,
                    Some(e.line()),
                    Some(&e.column().to_string()),
                    e.to_string(),
                )
            })?,
        }
    } else {
        // the [test_cell] section (blanked, line numbers kept) is read by super::test_cell
        let (text, _) = super::test_cell::split_toml(text);
        let text = text.as_str();
        toml::from_str(text).map_err(|e| {
            // 1-based line of the span's start: newlines before it, plus one
            let line = e.span().map(|s| line_of(text, s.start));
            format_err(path, line, None, e.message().to_string())
        })?
    };
    p.validate().map_err(|issues| IoError::Params {
        path: path.to_path_buf(),
        issues,
    })?;
    Ok(p)
}

/// 1-based line number of byte offset `at` in `text` (offsets past the end: the last line).
pub(crate) fn line_of(text: &str, at: usize) -> usize {
    let at = at.min(text.len());
    text.as_bytes()[..at]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

fn flat_to_nested(flat: &serde_json::Value, path: &Path) -> Result<serde_json::Value, IoError> {
    let obj = flat
        .as_object()
        .ok_or_else(|| format_err(path, None, Some("parameters"), "must be an object".into()))?;
    let mut root = serde_json::Map::new();
    for (k, v) in obj {
        let Some((_, dotted)) = FLAT_KEYS.iter().find(|(f, _)| f == k) else {
            return Err(format_err(
                path,
                None,
                Some(k),
                format!("unknown parameter `{k}`"),
            ));
        };
        let (sec, field) = dotted.split_once('.').expect("dotted path");
        let entry = root
            .entry(sec.to_string())
            .or_insert_with(|| serde_json::Value::Object(Default::default()));
        entry
            .as_object_mut()
            .expect("section object")
            .insert(field.to_string(), v.clone());
    }
    Ok(serde_json::Value::Object(root))
}

/// Read and validate a parameter file (format by content: JSON if it starts with `{`).
pub fn load_params(path: &Path) -> Result<Params, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::File {
        path: path.to_path_buf(),
        source,
    })?;
    parse_params(&text, path)
}

/// Serialize as TOML.
pub fn to_toml(p: &Params) -> String {
    super::params_toml::to_annotated_toml(p)
}

/// Serialize as (nested) JSON.
pub fn to_json(p: &Params) -> String {
    serde_json::to_string_pretty(p).expect("parameters serialize")
}

/// Write a parameter file atomically; JSON if the extension is `.json`, TOML otherwise.
pub fn save_params(p: &Params, path: &Path) -> Result<(), IoError> {
    let json = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    let text = if json { to_json(p) } else { to_toml(p) };
    super::output::write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_toml_and_json() {
        let p = Params::published();
        let t = parse_params(&to_toml(&p), Path::new("x.toml")).unwrap();
        assert_eq!(t, p);
        let j = parse_params(&to_json(&p), Path::new("x.json")).unwrap();
        assert_eq!(j, p);
    }

    #[test]
    fn authors_flat_json_equals_builtin() {
        let text = include_str!("../../../../data/wahlstrom_eriksson_2011_parameters.json");
        let p = parse_params(text, Path::new("flat.json")).unwrap();
        assert_eq!(p, Params::published());
    }

    #[test]
    fn errors_name_the_field() {
        let good = to_toml(&Params::published());
        let missing = good.replace("v_im = 0.022\n", "");
        let e = parse_params(&missing, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field `v_im`"), "{e}");
        let unknown = good.replace("v_im = 0.022\n", "v_im = 0.022\nv_imm = 1.0\n");
        let e = parse_params(&unknown, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown field `v_imm`") && e.contains("line"),
            "{e}"
        );
        // the line of the typo'd key itself (not the one before it)
        let typo = good.replace("v_im = 0.022\n", "v_imx = 0.022\n");
        let want = typo.lines().position(|l| l.starts_with("v_imx")).unwrap() + 1;
        let e = parse_params(&typo, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains(&format!("line {want}")), "line {want}: {e}");
        let json = serde_json::to_string_pretty(&Params::published())
            .unwrap()
            .replace("\"v_im\"", "\"v_imx\"");
        let want = json.lines().position(|l| l.contains("v_imx")).unwrap() + 1;
        let e = parse_params(&json, Path::new("p.json"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown field `v_imx`") && e.contains(&format!("line {want}")),
            "line {want}: {e}"
        );
        let neg = good.replace("j_t = 0.0002", "j_t = -0.0002");
        let e = parse_params(&neg, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("turbo.j_t = -0.0002: must be > 0"), "{e}");
        let nan = good.replace("j_t = 0.0002", "j_t = nan");
        let e = parse_params(&nan, Path::new("p.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("turbo.j_t = NaN: must be finite"), "{e}");
        let e = parse_params("{\"parameters\": {\"V_imm\": 1}}", Path::new("f.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown parameter `V_imm`"), "{e}");
        let e = parse_params("not = [valid", Path::new("f.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("f.toml, line 1"), "{e}");
    }
}
