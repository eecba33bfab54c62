//! Run-time choice of the model variant (`--model 8|10|12`) for front ends.
//!
//! Library code is generic over [`Model<N>`](super::Model); front ends that pick the variant at
//! run time hold an [`AnyModel`] and use [`dispatch!`](crate::dispatch) (or the convenience
//! methods here) to call the generic code. Results are returned in dimension-independent form
//! (named columns / named values).

use super::{Engine10, Engine12, Engine8, ModelOptions};
use crate::params::{ParamIssues, Params};
use serde::{Deserialize, Serialize};

/// Model variant: the paper's 8-state model or the section-9 extensions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum ModelOrder {
    /// 8 states (sections 3-7), the paper's proposed model.
    #[default]
    Eight,
    /// 10 states: adiabatic manifolds with temperature states (section 9.1).
    Ten,
    /// 12 states: plus the control volume before the intercooler (section 9.2).
    Twelve,
}

impl ModelOrder {
    /// Number of states.
    pub fn states(self) -> usize {
        match self {
            ModelOrder::Eight => 8,
            ModelOrder::Ten => 10,
            ModelOrder::Twelve => 12,
        }
    }

    /// From the number of states (8, 10 or 12).
    pub fn from_states(n: usize) -> Option<Self> {
        match n {
            8 => Some(ModelOrder::Eight),
            10 => Some(ModelOrder::Ten),
            12 => Some(ModelOrder::Twelve),
            _ => None,
        }
    }
}

/// A model whose variant is chosen at run time.
#[derive(Debug, Clone)]
pub enum AnyModel {
    /// The 8-state model.
    Eight(Engine8),
    /// The 10-state model (section 9.1).
    Ten(Engine10),
    /// The 12-state model (section 9.2).
    Twelve(Engine12),
}

/// Why a model could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// Invalid parameters.
    #[error(transparent)]
    Params(#[from] ParamIssues),
    /// The variant is not available.
    #[error("the {0}-state model is not available in this build")]
    Unavailable(usize),
}

impl AnyModel {
    /// Build the variant `order` from validated parameters.
    pub fn new(order: ModelOrder, p: Params, opts: ModelOptions) -> Result<Self, ModelError> {
        match order {
            ModelOrder::Eight => Ok(AnyModel::Eight(Engine8::new(p, opts)?)),
            ModelOrder::Ten => Ok(AnyModel::Ten(Engine10::new(p, opts)?)),
            ModelOrder::Twelve => Ok(AnyModel::Twelve(Engine12::new(p, opts)?)),
        }
    }

    /// The variant.
    pub fn order(&self) -> ModelOrder {
        match self {
            AnyModel::Eight(_) => ModelOrder::Eight,
            AnyModel::Ten(_) => ModelOrder::Ten,
            AnyModel::Twelve(_) => ModelOrder::Twelve,
        }
    }

    /// The variant's parameter set.
    pub fn params(&self) -> &Params {
        crate::dispatch!(self, m => super::Model::params(m))
    }
}

/// Call generic code on the concrete model inside an [`AnyModel`]:
/// `dispatch!(any, m => simulate(m, ...))`; `m` is `&EngineN` implementing `Model<N>`.
#[macro_export]
macro_rules! dispatch {
    ($any:expr, $m:ident => $body:expr) => {
        match $any {
            $crate::model::AnyModel::Eight($m) => $body,
            $crate::model::AnyModel::Ten($m) => $body,
            $crate::model::AnyModel::Twelve($m) => $body,
        }
    };
}
