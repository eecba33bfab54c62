//! Names, units and descriptions of the parameters, declared once with the parameter groups
//! (the `param_group!` declarations in `params/mod.rs`), and the registry of every scalar
//! parameter by name.
//!
//! A scalar parameter has one canonical name, its path in the parameter file: `turbo.j_t`,
//! `cylinder.c_vol[1]` (1-based indices, as in Modelica and the FMU), `compressor.q_c[1][2]`.
//! It also has the paper's symbol (`j_t`, `c_vol1`, `a3`), used by the tuning reports, which
//! [`ParamInfo::find`] accepts where it is unique. The parameter file writer, `mvem params
//! show`, the FMU's variables and the tuning read their names, units and descriptions here.

use super::Params;
use std::sync::OnceLock;

/// The name of one element of a vector or matrix: `base` (`cylinder.c_vol`, or a field of
/// another file such as the controller tuning's `torque`) with the element's 0-based
/// `position` (one index for a vector, row and column for a matrix) written 1-based, as
/// Modelica, the FMU and the parameter registry count: `cylinder.c_vol[1]` is c_vol1,
/// `compressor.q_c[1][2]` is a3. Every user-visible text that names an element (the registry's
/// paths, validation messages, the tuning reports, controller-tuning errors) names it here, so
/// a name copied from any of them is accepted where parameters are named
/// ([`ParamInfo::find`], Python's `params=`).
pub fn element_name(base: &str, position: &[usize]) -> String {
    let mut name = base.to_string();
    for i in position {
        name.push_str(&format!("[{}]", i + 1));
    }
    name
}

/// A field of a parameter group: a scalar, a vector or a matrix of scalars.
pub trait Scalars {
    /// Shape: `[]` for a scalar, `[n]` for a vector, `[rows, columns]` for a matrix.
    const SHAPE: &'static [usize];
    /// The scalars in row-major order.
    fn flat(&self) -> &[f64];
    /// The scalars in row-major order, mutable.
    fn flat_mut(&mut self) -> &mut [f64];
}

impl Scalars for f64 {
    const SHAPE: &'static [usize] = &[];
    fn flat(&self) -> &[f64] {
        std::slice::from_ref(self)
    }
    fn flat_mut(&mut self) -> &mut [f64] {
        std::slice::from_mut(self)
    }
}

impl<const N: usize> Scalars for [f64; N] {
    const SHAPE: &'static [usize] = &[N];
    fn flat(&self) -> &[f64] {
        self
    }
    fn flat_mut(&mut self) -> &mut [f64] {
        self
    }
}

impl<const N: usize, const M: usize> Scalars for [[f64; M]; N] {
    const SHAPE: &'static [usize] = &[N, M];
    fn flat(&self) -> &[f64] {
        self.as_flattened()
    }
    fn flat_mut(&mut self) -> &mut [f64] {
        self.as_flattened_mut()
    }
}

/// Metadata of one field of a parameter group.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FieldMeta {
    /// Field name (the key in the parameter file), e.g. `c_vol`.
    pub name: &'static str,
    /// One-line description with the paper's equation numbers.
    pub description: &'static str,
    /// Shape ([`Scalars::SHAPE`]).
    pub shape: &'static [usize],
    /// Symbol and unit of each scalar in row-major order, e.g. `("c_vol1", "Pa^-1/2")`; unit
    /// `-` for dimensionless.
    pub elements: &'static [(&'static str, &'static str)],
}

impl FieldMeta {
    /// The unit(s) as written in a comment: `Pa`, or `Pa^-1/2, rpm^-1/2, -` (one per element
    /// unless they agree).
    pub fn unit_text(&self) -> String {
        let first = self.elements[0].1;
        if self.elements.iter().all(|e| e.1 == first) {
            first.to_string()
        } else {
            let u: Vec<&str> = self.elements.iter().map(|e| e.1).collect();
            u.join(", ")
        }
    }
}

/// Metadata of one parameter group (a section of the parameter file).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GroupMeta {
    /// Section key, e.g. `intake_manifold`.
    pub key: &'static str,
    /// One-line title with the paper's section or equation numbers.
    pub title: &'static str,
    /// Fields in file order.
    pub fields: &'static [FieldMeta],
}

/// One scalar parameter of the registry ([`Params::registry`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamInfo {
    /// Canonical name: the path in the parameter file, e.g. `cylinder.c_vol[1]` (1-based).
    pub path: String,
    /// Group key, e.g. `cylinder`.
    pub group: &'static str,
    /// Field name, e.g. `c_vol`.
    pub field: &'static str,
    /// Index of the scalar in the field, row-major, 0-based.
    pub index: usize,
    /// The paper's symbol, e.g. `c_vol1` (the field name for a scalar field).
    pub symbol: &'static str,
    /// Unit (`-` for dimensionless).
    pub unit: &'static str,
    /// Description of the field (one line, with equation numbers).
    pub description: &'static str,
}

impl ParamInfo {
    /// The parameter named `name`: a path (`turbo.j_t`, `cylinder.c_vol[1]`) or a symbol
    /// (`j_t`, `c_vol1`) that belongs to exactly one parameter.
    pub fn find(name: &str) -> Option<&'static ParamInfo> {
        let reg = Params::registry();
        if let Some(p) = reg.iter().find(|p| p.path == name) {
            return Some(p);
        }
        let mut it = reg.iter().filter(|p| p.symbol == name);
        let first = it.next()?;
        // a symbol that names several scalars (a3 of Q_c, r_c) resolves to the first only if
        // all of them are the same field (the symmetric Q_c entry)
        if it.all(|p| p.group == first.group && p.field == first.field) {
            Some(first)
        } else {
            None
        }
    }

    /// One-line description of this scalar: the field's, with the symbol for vectors and
    /// matrices.
    pub fn describe(&self) -> String {
        if self.symbol == self.field {
            self.description.to_string()
        } else {
            format!("{}: {}", self.description, self.symbol)
        }
    }
}

impl Params {
    /// Metadata of every group, in file order.
    pub const GROUPS: [GroupMeta; 16] = [
        super::Gas::META,
        super::Ambient::META,
        super::IntakeManifold::META,
        super::ExhaustManifold::META,
        super::Cylinder::META,
        super::ExhaustPipe::META,
        super::EgrValve::META,
        super::EgrActuator::META,
        super::Turbine::META,
        super::VgtActuator::META,
        super::Compressor::META,
        super::Turbo::META,
        super::Initial::META,
        super::Intercooler::META,
        super::InputSaturation::META,
        super::IntegratorLimits::META,
    ];

    /// The scalars of `group.field` in row-major order.
    pub fn scalars(&self, group: &str, field: &str) -> Option<&[f64]> {
        match group {
            "gas" => self.gas.scalars(field),
            "ambient" => self.ambient.scalars(field),
            "intake_manifold" => self.intake_manifold.scalars(field),
            "exhaust_manifold" => self.exhaust_manifold.scalars(field),
            "cylinder" => self.cylinder.scalars(field),
            "exhaust_pipe" => self.exhaust_pipe.scalars(field),
            "egr_valve" => self.egr_valve.scalars(field),
            "egr_actuator" => self.egr_actuator.scalars(field),
            "turbine" => self.turbine.scalars(field),
            "vgt_actuator" => self.vgt_actuator.scalars(field),
            "compressor" => self.compressor.scalars(field),
            "turbo" => self.turbo.scalars(field),
            "initial" => self.initial.scalars(field),
            "intercooler" => self.intercooler.scalars(field),
            "input_saturation" => self.input_saturation.scalars(field),
            "integrator_limits" => self.integrator_limits.scalars(field),
            _ => None,
        }
    }

    /// The scalars of `group.field`, mutable.
    pub fn scalars_mut(&mut self, group: &str, field: &str) -> Option<&mut [f64]> {
        match group {
            "gas" => self.gas.scalars_mut(field),
            "ambient" => self.ambient.scalars_mut(field),
            "intake_manifold" => self.intake_manifold.scalars_mut(field),
            "exhaust_manifold" => self.exhaust_manifold.scalars_mut(field),
            "cylinder" => self.cylinder.scalars_mut(field),
            "exhaust_pipe" => self.exhaust_pipe.scalars_mut(field),
            "egr_valve" => self.egr_valve.scalars_mut(field),
            "egr_actuator" => self.egr_actuator.scalars_mut(field),
            "turbine" => self.turbine.scalars_mut(field),
            "vgt_actuator" => self.vgt_actuator.scalars_mut(field),
            "compressor" => self.compressor.scalars_mut(field),
            "turbo" => self.turbo.scalars_mut(field),
            "initial" => self.initial.scalars_mut(field),
            "intercooler" => self.intercooler.scalars_mut(field),
            "input_saturation" => self.input_saturation.scalars_mut(field),
            "integrator_limits" => self.integrator_limits.scalars_mut(field),
            _ => None,
        }
    }

    /// Every scalar parameter, in file order (groups, fields, row-major elements).
    pub fn registry() -> &'static [ParamInfo] {
        static CELL: OnceLock<Vec<ParamInfo>> = OnceLock::new();
        CELL.get_or_init(|| {
            let mut out = Vec::new();
            for g in &Params::GROUPS {
                for f in g.fields {
                    for (k, (symbol, unit)) in f.elements.iter().enumerate() {
                        let field = format!("{}.{}", g.key, f.name);
                        let path = match f.shape {
                            [_] => element_name(&field, &[k]),
                            [_, m] => element_name(&field, &[k / m, k % m]),
                            _ => field,
                        };
                        out.push(ParamInfo {
                            path,
                            group: g.key,
                            field: f.name,
                            index: k,
                            symbol,
                            unit,
                            description: f.description,
                        });
                    }
                }
            }
            out
        })
    }

    /// Value of the scalar `info`.
    pub fn value(&self, info: &ParamInfo) -> f64 {
        self.scalars(info.group, info.field)
            .and_then(|s| s.get(info.index).copied())
            .unwrap_or(f64::NAN)
    }

    /// Mutable reference to the scalar `info` (`None` only for an `info` not of
    /// [`Params::registry`]).
    pub fn value_mut(&mut self, info: &ParamInfo) -> Option<&mut f64> {
        self.scalars_mut(info.group, info.field)?
            .get_mut(info.index)
    }

    /// Value of the parameter `name` (a path or a unique symbol, see [`ParamInfo::find`]).
    pub fn get(&self, name: &str) -> Option<f64> {
        ParamInfo::find(name).map(|i| self.value(i))
    }

    /// Mutable reference to the parameter `name` (see [`Params::get`]).
    pub fn get_mut(&mut self, name: &str) -> Option<&mut f64> {
        self.value_mut(ParamInfo::find(name)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_covers_every_serialized_scalar_with_a_unit_and_description() {
        // every number of the serialized set is one registry entry, in the same places
        let p = Params::published();
        let doc = serde_json::to_value(&p).unwrap();
        let mut n = 0;
        for info in Params::registry() {
            let mut v = &doc[info.group][info.field];
            let f = Params::GROUPS
                .iter()
                .find(|g| g.key == info.group)
                .and_then(|g| g.fields.iter().find(|f| f.name == info.field))
                .unwrap();
            match f.shape {
                [] => {}
                [_] => v = &v[info.index],
                [_, m] => v = &v[info.index / m][info.index % m],
                _ => unreachable!(),
            }
            assert_eq!(v.as_f64(), Some(p.value(info)), "{}", info.path);
            assert!(!info.unit.is_empty() && !info.description.is_empty());
            n += 1;
        }
        fn count(v: &serde_json::Value) -> usize {
            match v {
                serde_json::Value::Number(_) => 1,
                serde_json::Value::Array(a) => a.iter().map(count).sum(),
                serde_json::Value::Object(o) => o.values().map(count).sum(),
                _ => 0,
            }
        }
        assert_eq!(n, count(&doc));
        let mut paths: Vec<&str> = Params::registry().iter().map(|p| p.path.as_str()).collect();
        paths.sort();
        paths.dedup();
        assert_eq!(paths.len(), n, "paths are unique");
    }

    #[test]
    fn names_resolve_to_the_right_scalar() {
        let mut p = Params::published();
        assert_eq!(p.get("cylinder.c_vol[2]"), Some(p.cylinder.c_vol[1]));
        assert_eq!(p.get("c_vol2"), Some(p.cylinder.c_vol[1]));
        assert_eq!(p.get("compressor.q_c[1][2]"), Some(p.compressor.q_c[0][1]));
        assert_eq!(p.get("a3"), Some(p.compressor.q_c[0][1]));
        assert_eq!(p.get("a2"), Some(p.compressor.q_c[1][1]));
        assert_eq!(p.get("turbo.j_t"), Some(p.turbo.j_t));
        // r_c is both the compression ratio and the compressor radius: only the paths work
        assert_eq!(p.get("r_c"), None);
        assert_eq!(p.get("compressor.r_c"), Some(p.compressor.r_c));
        assert_eq!(p.get("cylinder.c_vol[4]"), None);
        *p.get_mut("exhaust_manifold.v_em").unwrap() = 0.03;
        assert_eq!(p.exhaust_manifold.v_em, 0.03);
        let info = ParamInfo::find("c_m2").unwrap();
        assert_eq!((info.path.as_str(), info.unit), ("turbine.c_m[2]", "rad/s"));
    }

    #[test]
    fn element_names_count_from_1() {
        assert_eq!(element_name("cylinder.c_fric", &[0]), "cylinder.c_fric[1]");
        assert_eq!(
            element_name("compressor.q_c", &[0, 1]),
            "compressor.q_c[1][2]"
        );
        assert_eq!(element_name("torque", &[1]), "torque[2]");
        assert_eq!(element_name("turbo.j_t", &[]), "turbo.j_t");
        // the registry's paths are these names: the first friction coefficient is [1]
        let info = ParamInfo::find("c_fric1").unwrap();
        assert_eq!(info.path, element_name("cylinder.c_fric", &[info.index]));
        assert_eq!(info.path, "cylinder.c_fric[1]");
    }
}
