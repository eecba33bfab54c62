//! The 12-state extension of section 9.2: the 10-state model plus an adiabatic control volume
//! between the compressor and the intercooler and a pressure drop over the intercooler.
//! States (eq. (84)):
//! `x = (p_im, p_em, p_c, T_im, T_em, T_ic, X_Oim, X_Oem, omega_t, u_egr1, u_egr2, u_vgt)`.
//!
//! - Control volume before the intercooler (eq. (85)), volume `intercooler.v_ic`: the
//!   compressor flow W_c enters at the compressor outlet temperature T_c (eq. (58)), W_ic leaves
//!   at the state T_ic. The compressor sees Pi_c = p_c / p_amb (eq. (87)).
//! - Intercooler flow W_ic (eq. (86)), restriction `intercooler.k_ic`, see
//!   [`intercooler::w_ic`]. The intake manifold (eq. (80)) gets W_ic instead of W_c, entering at
//!   the cooling temperature T_im,in = `intake_manifold.t_im` (ideal cooling, the pressure drop
//!   is the only non-ideality).
//! - Back flow (p_c < p_im, which the paper's square root leaves undefined): W_ic is signed
//!   (the same restriction flown backwards with the intake manifold's density), so the model
//!   stays finite and continuous through W_ic = 0. The flows are taken upwind: reversed gas
//!   leaves the intake manifold at T_im and with its oxygen fraction unchanged, and enters the
//!   volume before the intercooler cooled to T_im,in (the cooler is ideal in both directions).
//!   The composition of that volume is not a state of the paper's model; it is taken as air
//!   (X_Oc) throughout, so back flow of EGR gas is not tracked. With the authors' W_c >= 1e-4
//!   kg/s, back flow occurs only in brief transients where the compressor flow collapses.
//! - Everything else, including the temperature floors of the authors' semantics (T >= T_amb/2;
//!   p_c has the limits of p_im, item 9), is as in [`Engine10`].
//!
//! `k_ic` must be > 0 (k_ic -> 0 is the 10-state model, where p_c = p_im algebraically).

use super::adiabatic::{self, ManifoldStates};
use super::common::{self, embed, remap_indices, restrict, Ports, Shared};
use super::engine10::{self, temperature_bounds, Engine10};
use super::{
    clip_state, limit_derivatives, Derivatives, Drive, Engine8, Evaluation, Model, ModelInput,
    ModelOptions, Signals,
};
use crate::components::cylinder::SeligerIterate;
use crate::components::{intercooler, manifold};
use crate::params::{ParamIssue, ParamIssues, Params};

/// State indices of [`Engine12`].
pub mod ix {
    /// Intake manifold pressure p_im \[Pa\].
    pub const P_IM: usize = 0;
    /// Exhaust manifold pressure p_em \[Pa\].
    pub const P_EM: usize = 1;
    /// Pressure before the intercooler (compressor outlet) p_c \[Pa\].
    pub const P_C: usize = 2;
    /// Intake manifold temperature T_im \[K\].
    pub const T_IM: usize = 3;
    /// Exhaust manifold temperature T_em \[K\].
    pub const T_EM: usize = 4;
    /// Temperature before the intercooler T_ic \[K\].
    pub const T_IC: usize = 5;
    /// Intake manifold oxygen mass fraction X_Oim [-].
    pub const X_OIM: usize = 6;
    /// Exhaust manifold oxygen mass fraction X_Oem [-].
    pub const X_OEM: usize = 7;
    /// Turbo speed omega_t [rad/s].
    pub const OMEGA_T: usize = 8;
    /// EGR actuator state u_egr1 [%].
    pub const U_EGR1: usize = 9;
    /// EGR actuator state u_egr2 [%].
    pub const U_EGR2: usize = 10;
    /// VGT actuator state [%].
    pub const U_VGT: usize = 11;
}

/// State names of the 12-state model.
pub const STATE_NAMES_12: [&str; 12] = [
    "p_im",
    "p_em",
    "p_c",
    "T_im",
    "T_em",
    "T_ic",
    "X_Oim",
    "X_Oem",
    "omega_t",
    "u_egr1",
    "u_egr2",
    "u_vgt_act",
];

/// Where each 10-state index sits in the 12-state vector.
const FROM_10: [usize; 10] = [
    ix::P_IM,
    ix::P_EM,
    ix::T_IM,
    ix::T_EM,
    ix::X_OIM,
    ix::X_OEM,
    ix::OMEGA_T,
    ix::U_EGR1,
    ix::U_EGR2,
    ix::U_VGT,
];

/// The 12-state model of section 9.2 (temperature states, control volume before the
/// intercooler, intercooler pressure drop).
#[derive(Debug, Clone)]
pub struct Engine12 {
    /// The 10-state model with the same parameters and options (its limits, guesses).
    base: Engine10,
    bounds: [(f64, f64); 12],
}

fn state_bounds_12(base: &Engine10) -> [(f64, f64); 12] {
    let b10 = base.state_bounds();
    let mut b = embed(
        &b10,
        &FROM_10,
        temperature_bounds(base.params(), base.options()),
    );
    b[ix::P_C] = b10[engine10::ix::P_IM];
    b
}

impl Engine12 {
    /// Build the model from validated parameters (every parameter problem is reported);
    /// additionally `intercooler.k_ic` must be > 0.
    pub fn new(p: Params, opts: ModelOptions) -> Result<Self, ParamIssues> {
        let k_ic = p.intercooler.k_ic;
        let base = Engine10::new(p, opts)?;
        if k_ic <= 0.0 {
            return Err(ParamIssues(vec![ParamIssue {
                field: "intercooler.k_ic".into(),
                value: k_ic,
                constraint: "must be > 0 for the 12-state model (k_ic = 0, no pressure drop, \
                             is the 10-state model)"
                    .into(),
            }]));
        }
        let bounds = state_bounds_12(&base);
        Ok(Self { base, bounds })
    }

    /// The published parameters (with the default intercooler of `docs/extensions.md`) and
    /// default options.
    pub fn published() -> Self {
        Self::new(Params::published(), ModelOptions::default())
            .expect("published parameters are valid")
    }

    /// The 12-state vector of a 10-state vector `x10` with the intercooler-volume states
    /// `p_c` \[Pa\] and `t_ic` \[K\].
    pub fn from_10_state(x10: &[f64; 10], p_c: f64, t_ic: f64) -> [f64; 12] {
        let mut x = embed(x10, &FROM_10, 0.0);
        x[ix::P_C] = p_c;
        x[ix::T_IC] = t_ic;
        x
    }

    /// The 10 states shared with [`Engine10`].
    pub fn to_10_state(x: &[f64; 12]) -> [f64; 10] {
        restrict(x, &FROM_10)
    }
}

impl Model<12> for Engine12 {
    engine_memory!(12);

    fn state_names(&self) -> [&'static str; 12] {
        STATE_NAMES_12
    }

    fn state_scales(&self) -> [f64; 12] {
        let s10 = self.base.state_scales();
        let mut s = embed(&s10, &FROM_10, 0.0);
        s[ix::P_C] = s10[engine10::ix::P_IM];
        s[ix::T_IC] = s10[engine10::ix::T_IM];
        s
    }

    fn with_options(&self, opts: ModelOptions) -> Self {
        let base = self.base.with_options(opts);
        let bounds = state_bounds_12(&base);
        Self { base, bounds }
    }

    fn params(&self) -> &Params {
        self.base.params()
    }

    fn options(&self) -> &ModelOptions {
        self.base.options()
    }

    fn state_bounds(&self) -> [(f64, f64); 12] {
        self.bounds
    }

    fn actuator_state_values(&self, d: &Drive) -> Vec<(usize, f64)> {
        remap_indices(self.base.actuator_state_values(d), &FROM_10)
    }

    fn reduced_8(&self) -> Option<&Engine8> {
        self.base.reduced_8()
    }

    fn lift_equilibrium_8(&self, x8: &[f64; 8], s8: &Signals) -> Option<[f64; 12]> {
        let x10 = self.base.lift_equilibrium_8(x8, s8)?;
        let p_im = x10[engine10::ix::P_IM];
        let dp = intercooler::pressure_drop(&self.params().intercooler, s8.w_c, s8.t_c, p_im);
        Some(Self::from_10_state(&x10, p_im + dp, s8.t_c))
    }

    /// The 10-state guess; T_ic = the compressor outlet temperature T_c there and p_c = p_im
    /// plus the pressure drop (eq. (86)) that carries W_ei - W_egr (the intercooler flow at any
    /// equilibrium).
    fn linear_lags(&self) -> Vec<super::LinearLag> {
        super::actuator_lags(
            self.params(),
            self.options().semantics,
            [ix::U_EGR1, ix::U_EGR2, ix::U_VGT],
        )
    }

    fn initial_guess(&self, d: &Drive) -> [f64; 12] {
        let p = self.params();
        let x10 = self.base.initial_guess(d);
        let p_im = x10[engine10::ix::P_IM];
        let mut x = Self::from_10_state(&x10, p_im, p.ambient.t_amb);
        let memory = SeligerIterate {
            x_r: 0.0,
            t_1: p.intake_manifold.t_im,
        };
        let s = self.eval(&x, &ModelInput::constant(*d), memory).signals;
        let (t_ic, w) = (s.t_c, s.w_ei - s.w_egr);
        if t_ic.is_finite() && t_ic > 0.0 && w.is_finite() && w > 0.0 {
            x[ix::T_IC] = t_ic;
            x[ix::P_C] = p_im + intercooler::pressure_drop(&p.intercooler, w, t_ic, p_im);
        }
        x
    }

    eval_from_evaluate!(12);
}

impl Engine12 {
    /// The shared algebraic part (with the signals if `SIGNALS`, see [`common::evaluate`]),
    /// the derivatives and whether a state is at an integrator limit.
    #[inline(always)]
    fn evaluate<const SIGNALS: bool>(
        &self,
        x_raw: &[f64; 12],
        u: &ModelInput,
        memory: SeligerIterate,
    ) -> (Shared, [f64; 12], bool) {
        let p = self.params();
        let opts = self.options();
        let gas = &p.gas;
        let t_im_in = p.intake_manifold.t_im; // eq. (80): constant inflow temperature

        // States, clipped into the integrator limits (items 9-12, 37; temperature floors).
        let x = clip_state(x_raw, &self.bounds);
        let [p_im, p_em, p_c, t_im, t_em, t_ic, x_oim, x_oem, omega_t, u_egr1, u_egr2, u_vgt] = x;

        // Intercooler flow, eq. (86) (signed, see the module documentation).
        let w_ic = intercooler::w_ic(&p.intercooler, p_c, t_ic, p_im, t_im);
        let (w_ic_fwd, w_ic_back) = (w_ic.max(0.0), (-w_ic).max(0.0));

        // Everything but the control volumes; the compressor sees p_c (eq. (87)).
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
            p_c: Some(p_c),
            w_ic: Some(w_ic),
        };
        let sh = common::evaluate::<SIGNALS>(p, &self.base.base.cc, opts, &ports, u, memory);
        let sg = &sh.signals;

        // Control volume before the intercooler, eq. (85): in W_c at T_c, out W_ic at T_ic.
        let ic = manifold::adiabatic(
            gas.r_a,
            gas.c_va,
            p.intercooler.v_ic,
            p_c,
            t_ic,
            sg.w_c + w_ic_back,
            sg.t_c * sg.w_c + t_im_in * w_ic_back,
            w_ic_fwd,
        );
        // The adiabatic manifolds, eqs (80), (81), (83), with W_ic from eq. (86): the forward
        // flow enters the intake manifold, the back flow leaves it with W_ei.
        let mx = ManifoldStates {
            p_im,
            p_em,
            t_im,
            t_em,
            x_oim,
            x_oem,
        };
        let m = adiabatic::manifolds(p, &sh, &mx, w_ic_fwd, sg.w_ei + w_ic_back);
        let mut dx = [
            m.dp_im,
            m.dp_em,
            ic.dp,
            m.dt_im,
            m.dt_em,
            ic.dt,
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
        let x10 = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0];
        let x = Engine12::from_10_state(&x10, 3e5, 400.0);
        assert_eq!(Engine12::to_10_state(&x), x10);
        for (i10, name) in engine10::STATE_NAMES_10.iter().enumerate() {
            assert_eq!(STATE_NAMES_12[FROM_10[i10]], *name);
        }
        let m = Engine12::published();
        let b = m.state_bounds();
        assert_eq!(b[ix::P_C], b[ix::P_IM]);
        assert_eq!(b[ix::T_IC], b[ix::T_IM]);
        assert!(b[ix::T_IC].0 > 100.0 && b[ix::T_IC].1 == f64::INFINITY);
    }

    #[test]
    fn k_ic_zero_is_rejected_with_its_field() {
        let mut p = Params::published();
        p.intercooler.k_ic = 0.0;
        let e = Engine12::new(p, ModelOptions::default()).unwrap_err();
        assert_eq!(e.0.len(), 1);
        assert_eq!(e.0[0].field, "intercooler.k_ic");
        assert!(e.to_string().contains("10-state"), "{e}");
    }

    #[test]
    fn back_flow_is_finite_continuous_and_upwind() {
        // Around p_c = p_im the derivatives stay finite and continuous; reversed flow leaves
        // the intake manifold at T_im without changing X_Oim.
        let m = Engine12::published();
        let d = Drive::new(1500.0, 110.0, 80.0, 75.0);
        let mut x = m.initial_guess(&d);
        let u = ModelInput::constant(d);
        let mem = SeligerIterate {
            x_r: 0.0,
            t_1: 300.0,
        };
        let p_im = x[ix::P_IM];
        let mut prev: Option<[f64; 12]> = None;
        for k in -20..=20 {
            x[ix::P_C] = p_im + k as f64 * 0.01;
            let ev = m.eval(&x, &u, mem);
            assert!(ev.dx.iter().all(|v| v.is_finite()));
            assert_eq!(ev.signals.w_ic.signum(), if k >= 0 { 1.0 } else { -1.0 });
            if let Some(pr) = prev {
                for i in 0..12 {
                    let scale = m.state_scales()[i];
                    // |dW_ic/dp| ~ 1/sqrt(dp): over 0.01 Pa the change stays small
                    assert!(
                        (ev.dx[i] - pr[i]).abs() / scale < 0.2,
                        "{} jumps",
                        STATE_NAMES_12[i]
                    );
                }
            }
            prev = Some(ev.dx);
        }
    }
}
