//! Parameter tuning: the least-squares machinery the tuning steps are built on.
//!
//! - [`lsq`] (in [`crate::numerics`], re-exported here): bounded nonlinear least squares (Trust Region Reflective with Coleman–Li
//!   scaling), finite-difference or user Jacobians, typed errors, linearized parameter
//!   statistics for identifiability reports. Verified on the NIST StRD nonlinear regression
//!   problems (`tests/nist.rs`, `docs/nist.md`).
//! - [`varpro`] (in [`crate::numerics`], re-exported here): separable nonlinear least squares `min ||y - Phi(alpha) c||` by variable
//!   projection (Golub–Pereyra), the linear coefficients eliminated by linear least squares.
//! - [`data`]: campaign formats (stationary/dynamic CSV, manifest) with validated loading.
//! - [`draft`]: a first manifest for a directory of a test cell's CSV files (kinds, roles,
//!   rates, steps and units guessed, each guess noted).
//! - [`lab`]: virtual test cell generating campaigns from known parameters.
//! - [`steps`]: tuning steps 1 (static submodels, one file per submodel) and 2 (actuators) of
//!   section 8.1.
//! - [`constants`]: the ambient conditions (from the stationary data) and the engine constants
//!   no step estimates, with checks against the campaign.
//! - [`complete`]: steps 3 (V_im, V_em, J_t), 4 (tau_Me) and 5 (cost (77)) on the complete model.
//! - [`twelve`]: the three 12-state steps of section 9.2.1 (k_ic, V_ic, cost (77) with W_ic).
//! - [`pipeline`]: steps 1-5 chained, from data only (and the 12-state steps).
//! - [`request`]: one tuning run on a campaign directory as the front ends ask for it (settings
//!   by the command line's names, constants checked, warnings and notes).
//! - [`scale`]: the engine's scale measured at the stationary points, which the boxes of the
//!   scale-dependent parameters of steps 1 and 5 follow.
//! - [`settled`]: settled operating points at the ends of the dynamic sets' command steps
//!   (compressor flow points for step 1).
//! - [`sensors`]: first-order lags of the test cell's sensors (Table 6), known or fitted.
//! - [`summary`]: what a campaign holds and which steps it supports, before any tuning.
//! - [`uncertainty`]: standard errors and identifiability of every tuned parameter.
//! - [`validate`]: relative errors (eqs (4), (5)) and error tables.
//!
//! Overview, results and open items: `docs/tuning.md`.

pub mod complete;
pub mod constants;
pub mod data;
pub mod draft;
pub mod lab;
pub mod pipeline;
pub mod request;
pub mod scale;
pub mod sensors;
pub mod settled;
pub mod steps;
pub mod summary;
pub mod twelve;
pub mod uncertainty;
pub mod validate;

pub use crate::numerics::{lsq, varpro};
