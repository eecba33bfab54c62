//! The paper's submodels (sections 3-7) as pure functions of port conditions, inputs and the
//! component's own parameters. No function here knows the state vector; the assembly into a
//! model lives in [`crate::model`].
//!
//! Every function cites its equation number. Where the authors' Simulink implementation adds
//! a saturation or switch (see `../shared/spec/authors-implementation.md`, cited as "item N"),
//! the function takes a [`Semantics`] argument and applies it only for [`Semantics::Authors`].

pub mod compressor;
pub mod cylinder;
pub mod egr;
pub mod intercooler;
pub mod manifold;
pub mod turbine;
pub mod turbo;

use serde::{Deserialize, Serialize};

/// Which equations to use where the authors' implementation and the paper differ.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Semantics {
    /// The authors' Simulink implementation (default): every saturation, switch and integrator
    /// limit of the implementation notes, items 1-37.
    #[default]
    Authors,
    /// The paper's plain equations (6)-(73): only the limits written in the paper
    /// (eqs (35), (38), (51), (56), (71)); no input saturations, no integrator limits.
    Paper,
}

impl Semantics {
    /// True for the authors' implementation.
    #[inline]
    pub fn authors(self) -> bool {
        matches!(self, Semantics::Authors)
    }
}

/// Horner evaluation of c[0] x^2 + c[1] x + c[2] (the paper's coefficient order).
#[inline]
pub fn poly2(c: &[f64; 3], x: f64) -> f64 {
    (c[0] * x + c[1]) * x + c[2]
}
