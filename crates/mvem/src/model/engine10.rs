//! The 10-state extension of section 9.1: adiabatic manifolds with temperature states.
//! States (eq. (79)): `x = (p_im, p_em, T_im, T_em, X_Oim, X_Oem, omega_t, u_egr1, u_egr2, u_vgt)`.
//!
//! Intake manifold (eq. (80)): the in-flows W_ic = W_c (ideal intercooler, eq. (82)) and W_egr
//! enter at the constant temperature T_im,in = `intake_manifold.t_im` (the intercooler and EGR
//! cooler cooling temperature, eq. (73)); W_ei leaves at the state T_im. Exhaust manifold
//! (eq. (81)): W_eo enters at T_em,in = the exhaust temperature of eq. (25); W_t and W_egr
//! leave at the state T_em. Every flow sees its upstream volume's state: W_ei (eq. (11)) and
//! the Seliger cycle's intake temperature (eq. (21)) use the T_im state; the EGR flow
//! (eq. (32)), the turbine flow (eq. (55)) and power (eq. (48)) use the T_em state. Oxygen
//! mass fractions: eq. (83). All other submodels, saturations and integrator limits are those
//! of the 8-state model; the parameters are the same (the paper keeps every tuned value).
//!
//! Temperature integrator limits: none with [`Semantics::Paper`](crate::components::Semantics);
//! with the authors' semantics T_im, T_em >= T_amb / 2 (an mvem addition, mirroring the
//! pressures' >= p_amb / 2 of items 9-10: a floor that keeps the gas law and the flow
//! functions defined and is never reached in normal operation; reaching it sets
//! [`Guard::StateLimit`](super::Guard::StateLimit)).
//!
//! At an equilibrium the adiabatic balances give T_im = T_im,in and T_em = T_em,in, so the
//! steady states equal those of [`Engine8`] (checked in `tests/extensions.rs`).

use super::adiabatic::{self, ManifoldStates};
use super::common::{self, embed, remap_indices, restrict, Ports, Shared};
use super::Engine8;
use super::{
    clip_state, limit_derivatives, Derivatives, Drive, Evaluation, Model, ModelInput, ModelOptions,
    Signals,
};
use crate::components::cylinder::SeligerIterate;
use crate::params::{ParamIssues, Params};

/// State indices of [`Engine10`].
pub mod ix {
    /// Intake manifold pressure p_im \[Pa\].
    pub const P_IM: usize = 0;
    /// Exhaust manifold pressure p_em \[Pa\].
    pub const P_EM: usize = 1;
    /// Intake manifold temperature T_im \[K\].
    pub const T_IM: usize = 2;
    /// Exhaust manifold temperature T_em \[K\].
    pub const T_EM: usize = 3;
    /// Intake manifold oxygen mass fraction X_Oim [-].
    pub const X_OIM: usize = 4;
    /// Exhaust manifold oxygen mass fraction X_Oem [-].
    pub const X_OEM: usize = 5;
    /// Turbo speed omega_t [rad/s].
    pub const OMEGA_T: usize = 6;
    /// EGR actuator state u_egr1 [%].
    pub const U_EGR1: usize = 7;
    /// EGR actuator state u_egr2 [%].
    pub const U_EGR2: usize = 8;
    /// VGT actuator state [%].
    pub const U_VGT: usize = 9;
}

/// State names of the 10-state model.
pub const STATE_NAMES_10: [&str; 10] = [
    "p_im",
    "p_em",
    "T_im",
    "T_em",
    "X_Oim",
    "X_Oem",
    "omega_t",
    "u_egr1",
    "u_egr2",
    "u_vgt_act",
];

/// Where each 8-state index sits in the 10-state vector.
const FROM_8: [usize; 8] = [
    ix::P_IM,
    ix::P_EM,
    ix::X_OIM,
    ix::X_OEM,
    ix::OMEGA_T,
    ix::U_EGR1,
    ix::U_EGR2,
    ix::U_VGT,
];

/// The 10-state model of section 9.1 (adiabatic manifolds).
#[derive(Debug, Clone)]
pub struct Engine10 {
    /// The 8-state model with the same parameters and options (its limits, guesses).
    pub(crate) base: Engine8,
    bounds: [(f64, f64); 10],
}

/// Lower/upper integrator limit of a temperature state (see the module documentation).
pub(super) fn temperature_bounds(p: &Params, opts: &ModelOptions) -> (f64, f64) {
    if opts.semantics.authors() {
        (0.5 * p.ambient.t_amb, f64::INFINITY)
    } else {
        (f64::NEG_INFINITY, f64::INFINITY)
    }
}

fn state_bounds_10(base: &Engine8) -> [(f64, f64); 10] {
    let tb = temperature_bounds(base.params(), base.options());
    embed(&base.state_bounds(), &FROM_8, tb)
}

impl Engine10 {
    /// Build the model from validated parameters (every parameter problem is reported).
    pub fn new(p: Params, opts: ModelOptions) -> Result<Self, ParamIssues> {
        let base = Engine8::new(p, opts)?;
        let bounds = state_bounds_10(&base);
        Ok(Self { base, bounds })
    }

    /// The published parameters with default options (authors' implementation, converged T_e).
    pub fn published() -> Self {
        Self::new(Params::published(), ModelOptions::default())
            .expect("published parameters are valid")
    }

    /// The 10-state vector of an 8-state vector `x8` with manifold temperatures `t_im`, `t_em` \[K\].
    pub fn from_8_state(x8: &[f64; 8], t_im: f64, t_em: f64) -> [f64; 10] {
        let mut x = embed(x8, &FROM_8, 0.0);
        x[ix::T_IM] = t_im;
        x[ix::T_EM] = t_em;
        x
    }

    /// The 8 states shared with [`Engine8`] (p_im, p_em, X_Oim, X_Oem, omega_t, actuators).
    pub fn to_8_state(x: &[f64; 10]) -> [f64; 8] {
        restrict(x, &FROM_8)
    }
}

impl Model<10> for Engine10 {
    engine_memory!(10);

    fn state_names(&self) -> [&'static str; 10] {
        STATE_NAMES_10
    }

    fn state_scales(&self) -> [f64; 10] {
        embed(&self.base.state_scales(), &FROM_8, 1e3) // temperatures: 1000 K
    }

    fn with_options(&self, opts: ModelOptions) -> Self {
        let base = self.base.with_options(opts);
        let bounds = state_bounds_10(&base);
        Self { base, bounds }
    }

    fn params(&self) -> &Params {
        self.base.params()
    }

    fn options(&self) -> &ModelOptions {
        self.base.options()
    }

    fn state_bounds(&self) -> [(f64, f64); 10] {
        self.bounds
    }

    fn actuator_state_values(&self, d: &Drive) -> Vec<(usize, f64)> {
        remap_indices(self.base.actuator_state_values(d), &FROM_8)
    }

    fn reduced_8(&self) -> Option<&Engine8> {
        Some(&self.base)
    }

    fn lift_equilibrium_8(&self, x8: &[f64; 8], s8: &Signals) -> Option<[f64; 10]> {
        Some(Self::from_8_state(
            x8,
            self.params().intake_manifold.t_im,
            s8.t_em,
        ))
    }

    /// The 8-state guess, T_im = T_im,in and T_em = T_em,in (eq. (25)) evaluated at that guess
    /// (the values they take at any equilibrium).
    fn linear_lags(&self) -> Vec<super::LinearLag> {
        super::actuator_lags(
            self.params(),
            self.options().semantics,
            [ix::U_EGR1, ix::U_EGR2, ix::U_VGT],
        )
    }

    fn initial_guess(&self, d: &Drive) -> [f64; 10] {
        let p = self.params();
        let x8 = self.base.initial_guess(d);
        let t_im = p.intake_manifold.t_im;
        let mut x = Self::from_8_state(&x8, t_im, p.ambient.t_amb);
        let memory = SeligerIterate {
            x_r: 0.0,
            t_1: t_im,
        };
        let ev = self.eval(&x, &ModelInput::constant(*d), memory);
        if ev.signals.t_em_in.is_finite() {
            x[ix::T_EM] = ev.signals.t_em_in;
        }
        x
    }

    eval_from_evaluate!(10);
}

impl Engine10 {
    /// The shared algebraic part (with the signals if `SIGNALS`, see [`common::evaluate`]),
    /// the derivatives and whether a state is at an integrator limit.
    #[inline(always)]
    fn evaluate<const SIGNALS: bool>(
        &self,
        x_raw: &[f64; 10],
        u: &ModelInput,
        memory: SeligerIterate,
    ) -> (Shared, [f64; 10], bool) {
        let p = self.params();
        let opts = self.options();

        // States, clipped into the integrator limits (items 9-12, 37; temperature floors).
        let x = clip_state(x_raw, &self.bounds);
        let [p_im, p_em, t_im, t_em, x_oim, x_oem, omega_t, u_egr1, u_egr2, u_vgt] = x;

        // Everything but the manifolds, with the flows seeing the temperature states.
        let ports = Ports {
            p_im,
            p_em,
            x_oim,
            omega_t,
            u_egr1,
            u_egr2,
            u_vgt,
            t_im,
            t_em: Some(t_em),
            p_c: None,
            w_ic: None, // eq. (82): W_ic = W_c
        };
        let sh = common::evaluate::<SIGNALS>(p, &self.base.cc, opts, &ports, u, memory);
        let sg = &sh.signals;

        // The adiabatic manifolds, eqs (80), (81), (83): W_ic = W_c in, W_ei out.
        let mx = ManifoldStates {
            p_im,
            p_em,
            t_im,
            t_em,
            x_oim,
            x_oem,
        };
        let m = adiabatic::manifolds(p, &sh, &mx, sg.w_ic, sg.w_ei);
        let mut dx = [
            m.dp_im,
            m.dp_em,
            m.dt_im,
            m.dt_em,
            m.dx_oim,
            m.dx_oem,
            sh.d_omega_t,
            sh.d_u_egr1,
            sh.d_u_egr2,
            sh.d_u_vgt,
        ];
        let at_limit = opts.semantics.authors() && limit_derivatives(&x, &mut dx, &self.bounds);
        (sh, dx, at_limit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_maps_round_trip() {
        let x8 = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0];
        let x = Engine10::from_8_state(&x8, 300.0, 800.0);
        assert_eq!(Engine10::to_8_state(&x), x8);
        assert_eq!((x[ix::T_IM], x[ix::T_EM]), (300.0, 800.0));
        for (i8, name) in crate::model::STATE_NAMES_8.iter().enumerate() {
            assert_eq!(STATE_NAMES_10[FROM_8[i8]], *name);
        }
    }

    #[test]
    fn equals_engine8_when_temperatures_sit_at_their_inflow_values() {
        // With T_im = T_im,in and T_em = T_em,in every flow and signal of the 10-state model
        // equals the 8-state one; the pressure derivatives differ only by the adiabatic factor.
        let m8 = Engine8::published();
        let m10 = Engine10::published();
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let x8 = m8.initial_guess(&d);
        let u = ModelInput::constant(d);
        let mem = SeligerIterate {
            x_r: 0.0,
            t_1: 300.0,
        };
        let e8 = m8.eval(&x8, &u, mem);
        let x = Engine10::from_8_state(&x8, m8.params().intake_manifold.t_im, e8.signals.t_em);
        let e10 = m10.eval(&x, &u, mem);
        assert_eq!(e8.signals, e10.signals);
        // oxygen, turbo and actuator derivatives are identical
        for (i8, &i) in FROM_8.iter().enumerate().skip(2) {
            assert_eq!(e8.dx[i8], e10.dx[i], "state {}", STATE_NAMES_10[i]);
        }
    }
}
