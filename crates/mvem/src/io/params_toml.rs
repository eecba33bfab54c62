//! The parameter file for hand editing: TOML with one section per parameter group, each group
//! and key preceded by its one-line description (with the paper's equation numbers) and unit
//! from the parameter metadata ([`Params::GROUPS`]), numbers in their shortest form that reads
//! back to the same value (`2.33e-14`, not `0.0000000000000233`).

use crate::params::{FieldMeta, Params};
use std::fmt::Write as _;

/// The shortest decimal text that parses back to `v` exactly, as a TOML float (`1011.0`,
/// `2.33e-14`, `1e16`, `inf`, `nan`).
pub fn toml_float(v: f64) -> String {
    // Rust's `Debug` of f64 is the shortest round-trip representation, with an exponent for
    // very small and very large magnitudes and a `.0` on integral values: valid TOML floats.
    format!("{v:?}")
}

fn value_text(f: &FieldMeta, x: &[f64]) -> String {
    let list = |x: &[f64]| {
        let v: Vec<String> = x.iter().map(|v| toml_float(*v)).collect();
        format!("[{}]", v.join(", "))
    };
    match f.shape {
        [] => toml_float(x[0]),
        [_, m] => {
            let rows: Vec<String> = x.chunks(*m).map(list).collect();
            format!("[{}]", rows.join(", "))
        }
        _ => list(x),
    }
}

/// The parameter set `p` as an annotated TOML document (loads back to `p` exactly).
pub fn to_annotated_toml(p: &Params) -> String {
    let mut s = String::new();
    s.push_str(
        "# mvem parameter set: one section per component of the mean-value engine model\n\
         # (Wahlstrom & Eriksson 2011; equation numbers are the paper's). Each key is preceded by\n\
         # its description and [unit]; SI units unless the unit says otherwise.\n",
    );
    for g in &Params::GROUPS {
        let _ = write!(s, "\n# {}\n[{}]\n", g.title, g.key);
        for f in g.fields {
            let x = p.scalars(g.key, f.name).unwrap_or(&[]);
            // the symbols of a vector (a matrix's description names its entries)
            let symbols = if f.shape.len() == 1 {
                let names: Vec<&str> = f.elements.iter().map(|e| e.0).collect();
                format!(" ({})", names.join(", "))
            } else {
                String::new()
            };
            let _ = writeln!(s, "# {}{symbols} [{}]", f.description, f.unit_text());
            let _ = writeln!(s, "{} = {}", f.name, value_text(f, x));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_short_and_round_trip() {
        assert_eq!(toml_float(2.33e-14), "2.33e-14");
        assert_eq!(toml_float(1011.0), "1011.0");
        assert_eq!(toml_float(0.022), "0.022");
        assert_eq!(toml_float(1.9e7), "19000000.0");
        for v in [
            2.33e-14,
            1e16,
            -3.5e-8,
            101111.34146341463,
            1.3964088397790055,
        ] {
            let t: toml::Value = toml::from_str(&format!("x = {}", toml_float(v))).unwrap();
            assert_eq!(t["x"].as_float(), Some(v));
        }
    }

    #[test]
    fn built_in_file_is_the_annotated_output() {
        // crates/mvem/data/published.toml is `mvem params show --format toml` of the published
        // set: after a change of the metadata, regenerate it with that command
        assert_eq!(
            crate::params::PUBLISHED_TOML,
            to_annotated_toml(&Params::published())
        );
    }

    #[test]
    fn annotated_file_loads_back_identically() {
        let mut p = Params::published();
        // a perturbed set: values of every magnitude, every scalar changed
        for (k, info) in Params::registry().iter().enumerate() {
            let v = p.value_mut(info).unwrap();
            *v *= 1.0 + 1e-9 * (k as f64 + 1.0) / 7.0;
        }
        p.compressor.c_wpsi[0] = -2.3300000000000001e-14;
        for q in [Params::published(), p] {
            let text = to_annotated_toml(&q);
            let back: Params = toml::from_str(&text).unwrap();
            assert_eq!(back, q);
            assert!(!text.contains("0.00000000"), "{text}");
        }
        let text = to_annotated_toml(&Params::published());
        // every key has a comment with its unit and the equation numbers are there
        assert!(text.contains("# Turbocharger inertia J_t (eq. (42)) [kg m^2]\nj_t = "));
        assert!(text.contains(
            "# Volumetric efficiency coefficients (eq. (12)) (c_vol1, c_vol2, c_vol3) [Pa^-1/2, rpm^-1/2, -]\nc_vol = ["
        ));
        assert!(text.contains("\n# Turbocharger shaft (eq. (42))\n[turbo]\n"));
        assert!(text.contains("q_c = [["));
    }
}
