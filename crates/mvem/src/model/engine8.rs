//! The paper's 8-state model (sections 3-7): states (eq. (1))
//! `x = (p_im, p_em, X_Oim, X_Oem, omega_t, u_egr1, u_egr2, u_vgt)`.

use super::common::{self, Ports, Shared};
use super::{
    clip_state, limit_derivatives, saturate_u_egr, saturate_u_vgt, Derivatives, Drive, Evaluation,
    Model, ModelInput, ModelOptions,
};
use crate::components::cylinder::{CylinderConsts, SeligerIterate};
use crate::components::manifold;
use crate::params::{ParamIssues, Params};

/// State indices of [`Engine8`].
pub mod ix {
    /// Intake manifold pressure p_im \[Pa\].
    pub const P_IM: usize = 0;
    /// Exhaust manifold pressure p_em \[Pa\].
    pub const P_EM: usize = 1;
    /// Intake manifold oxygen mass fraction X_Oim [-].
    pub const X_OIM: usize = 2;
    /// Exhaust manifold oxygen mass fraction X_Oem [-].
    pub const X_OEM: usize = 3;
    /// Turbo speed omega_t [rad/s].
    pub const OMEGA_T: usize = 4;
    /// EGR actuator state u_egr1 [%].
    pub const U_EGR1: usize = 5;
    /// EGR actuator state u_egr2 [%].
    pub const U_EGR2: usize = 6;
    /// VGT actuator state [%].
    pub const U_VGT: usize = 7;
}

/// The 8-state mean-value engine model of Wahlstrom & Eriksson (2011).
#[derive(Debug, Clone)]
pub struct Engine8 {
    p: Params,
    opts: ModelOptions,
    bounds: [(f64, f64); 8],
    /// Parameter-only cylinder constants (powers of r_c), shared with the extensions.
    pub(crate) cc: CylinderConsts,
}

/// State names of the 8-state model (reference-data names).
pub const STATE_NAMES_8: [&str; 8] = [
    "p_im",
    "p_em",
    "X_Oim",
    "X_Oem",
    "omega_t",
    "u_egr1",
    "u_egr2",
    "u_vgt_act",
];

impl Engine8 {
    /// Build the model from validated parameters (every parameter problem is reported).
    pub fn new(p: Params, opts: ModelOptions) -> Result<Self, ParamIssues> {
        p.validate()?;
        let bounds = state_bounds_8(&p, &opts);
        let cc = CylinderConsts::new(&p.gas, &p.cylinder);
        Ok(Self {
            p,
            opts,
            bounds,
            cc,
        })
    }

    /// The published parameters with default options (authors' implementation, converged T_e).
    pub fn published() -> Self {
        Self::new(Params::published(), ModelOptions::default())
            .expect("published parameters are valid")
    }
}

/// Integrator limits of the authors' implementation (items 9-12, 37); none for the paper.
fn state_bounds_8(p: &Params, opts: &ModelOptions) -> [(f64, f64); 8] {
    let inf = f64::INFINITY;
    if opts.semantics.authors() {
        let pa = p.ambient.p_amb;
        let w = std::f64::consts::PI / 30.0;
        [
            (0.5 * pa, 10.0 * pa), // item 9
            (0.5 * pa, 20.0 * pa), // item 10
            (0.0, 1.0),            // item 11
            (0.0, 1.0),            // item 12
            // item 37, the parameter set's range (default 100-200 000 rpm)
            (
                p.integrator_limits.n_t[0] * w,
                p.integrator_limits.n_t[1] * w,
            ),
            (-inf, inf),
            (-inf, inf),
            (-inf, inf),
        ]
    } else {
        [(-inf, inf); 8]
    }
}

impl Model<8> for Engine8 {
    engine_memory!(8);

    fn state_names(&self) -> [&'static str; 8] {
        STATE_NAMES_8
    }

    fn state_scales(&self) -> [f64; 8] {
        [1e5, 1e5, 0.1, 0.1, 1e4, 100.0, 100.0, 100.0]
    }

    fn with_options(&self, opts: ModelOptions) -> Self {
        let bounds = state_bounds_8(&self.p, &opts);
        Self {
            p: self.p.clone(),
            opts,
            cc: self.cc,
            bounds,
        }
    }

    fn params(&self) -> &Params {
        &self.p
    }

    fn options(&self) -> &ModelOptions {
        &self.opts
    }

    fn state_bounds(&self) -> [(f64, f64); 8] {
        self.bounds
    }

    fn actuator_state_values(&self, d: &Drive) -> Vec<(usize, f64)> {
        let s = self.opts.semantics;
        let limits = &self.p.input_saturation;
        let ue = saturate_u_egr(d.u_egr_pct, s, limits);
        vec![
            (ix::U_EGR1, ue),
            (ix::U_EGR2, ue),
            (ix::U_VGT, saturate_u_vgt(d.u_vgt_pct, s, limits)),
        ]
    }

    fn linear_lags(&self) -> Vec<super::LinearLag> {
        super::actuator_lags(
            &self.p,
            self.opts.semantics,
            [ix::U_EGR1, ix::U_EGR2, ix::U_VGT],
        )
    }

    fn initial_guess(&self, d: &Drive) -> [f64; 8] {
        let pa = self.p.ambient.p_amb;
        // load: the fuel over the top of the set's fuel range (the authors': 250 mg)
        let load = (d.u_delta_mg / self.p.input_saturation.u_delta[1]).clamp(0.0, 1.0);
        let mut x = [
            pa * (1.0 + 1.0 * load),
            pa * (1.1 + 1.4 * load),
            self.p.intake_manifold.x_oc * 0.95,
            0.1,
            3000.0 + 6000.0 * load,
            0.0,
            0.0,
            0.0,
        ];
        for (i, v) in self.actuator_state_values(d) {
            x[i] = v;
        }
        x
    }

    eval_from_evaluate!(8);
}

impl Engine8 {
    /// The shared algebraic part (with the signals if `SIGNALS`, see [`common::evaluate`]),
    /// the derivatives and whether a state is at an integrator limit.
    #[inline(always)]
    fn evaluate<const SIGNALS: bool>(
        &self,
        x_raw: &[f64; 8],
        u: &ModelInput,
        memory: SeligerIterate,
    ) -> (Shared, [f64; 8], bool) {
        let p = &self.p;
        let gas = &p.gas;
        let t_im = p.intake_manifold.t_im;

        // States, clipped into the integrator limits (items 9-12, 37).
        let x = clip_state(x_raw, &self.bounds);
        let [p_im, p_em, x_oim, x_oem, omega_t, u_egr1, u_egr2, u_vgt_state] = x;

        // Everything but the manifolds: T_im constant (eq. (73)), T_em from eq. (25),
        // compressor outlet = intake manifold, ideal intercooler.
        let ports = Ports {
            p_im,
            p_em,
            x_oim,
            omega_t,
            u_egr1,
            u_egr2,
            u_vgt: u_vgt_state,
            t_im,
            t_em: None,
            p_c: None,
            w_ic: None,
        };
        let sh = common::evaluate::<SIGNALS>(p, &self.cc, &self.opts, &ports, u, memory);
        let sg = &sh.signals;

        // State equations: isothermal manifolds (6), (9).
        let im = manifold::intake(
            gas.r_a,
            t_im,
            p.intake_manifold.v_im,
            p_im,
            x_oim,
            x_oem,
            p.intake_manifold.x_oc,
            sg.w_c,
            sg.w_egr,
            sg.w_ei,
        );
        let em = manifold::exhaust(
            gas.r_e,
            sg.t_em,
            p.exhaust_manifold.v_em,
            p_em,
            x_oem,
            sh.x_oe,
            sg.w_eo,
            sg.w_t,
            sg.w_egr,
        );
        let mut dx = [
            im.dp,
            em.dp,
            im.dx_o,
            em.dx_o,
            sh.d_omega_t,
            sh.d_u_egr1,
            sh.d_u_egr2,
            sh.d_u_vgt,
        ];
        let at_limit =
            self.opts.semantics.authors() && limit_derivatives(&x, &mut dx, &self.bounds);
        (sh, dx, at_limit)
    }
}
