//! The paper's 8-state model (sections 3-7): states (eq. (1))
//! `x = (p_im, p_em, X_Oim, X_Oem, omega_t, u_egr1, u_egr2, u_vgt)`.

use super::{
    clip_state, limit_derivatives, saturate_inputs, saturate_u_egr, saturate_u_vgt, Actuators,
    CylinderTemp, Drive, Evaluation, Guard, Model, ModelInput, ModelOptions, Signals,
};
use crate::components::cylinder::{self, CylinderConsts, SeligerInputs, SeligerIterate};
use crate::components::{compressor, egr, manifold, poly2, turbine, turbo};
use crate::params::{ParamIssues, Params};

/// State indices of [`Engine8`].
pub mod ix {
    /// Intake manifold pressure p_im [Pa].
    pub const P_IM: usize = 0;
    /// Exhaust manifold pressure p_em [Pa].
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
    cc: CylinderConsts,
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
            (0.5 * pa, 10.0 * pa),     // item 9
            (0.5 * pa, 20.0 * pa),     // item 10
            (0.0, 1.0),                // item 11
            (0.0, 1.0),                // item 12
            (100.0 * w, 200000.0 * w), // item 37
            (-inf, inf),
            (-inf, inf),
            (-inf, inf),
        ]
    } else {
        [(-inf, inf); 8]
    }
}

impl Model<8> for Engine8 {
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
            bounds,
            cc: self.cc,
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
        let ue = saturate_u_egr(d.u_egr_pct, s);
        vec![
            (ix::U_EGR1, ue),
            (ix::U_EGR2, ue),
            (ix::U_VGT, saturate_u_vgt(d.u_vgt_pct, s)),
        ]
    }

    fn initial_guess(&self, d: &Drive) -> [f64; 8] {
        let pa = self.p.ambient.p_amb;
        let load = (d.u_delta_mg / 250.0).clamp(0.0, 1.0);
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

    #[inline]
    fn eval(&self, x_raw: &[f64; 8], u: &ModelInput, memory: SeligerIterate) -> Evaluation<8> {
        let p = &self.p;
        let sem = self.opts.semantics;
        let authors = sem.authors();
        let gas = &p.gas;
        let (t_amb, p_amb) = (p.ambient.t_amb, p.ambient.p_amb);
        let t_im = p.intake_manifold.t_im;

        // Inputs: saturations before the delays (items 1-4).
        let (d, mut guards) = saturate_inputs(&u.now, sem);
        let ue_delayed = saturate_u_egr(u.u_egr_delayed, sem);
        let uv_delayed = saturate_u_vgt(u.u_vgt_delayed, sem);

        // States, clipped into the integrator limits (items 9-12, 37).
        let x = clip_state(x_raw, &self.bounds);
        let [p_im, p_em, x_oim, x_oem, omega_t, u_egr1, u_egr2, u_vgt_state] = x;

        // Actuator outputs (eq. (39), state of eq. (57)) or the bypass switch (item 6).
        let (u_egr_act, u_vgt_act) = match self.opts.actuators {
            Actuators::Dynamic => (
                egr::actuator_output(&p.egr_actuator, u_egr1, u_egr2),
                u_vgt_state,
            ),
            Actuators::Bypass => (d.u_egr_pct, d.u_vgt_pct),
        };

        // Cylinder flows, eqs (11)-(16).
        let cyl = &p.cylinder;
        let eta_vol = cylinder::eta_vol(cyl, p_im, d.n_e_rpm);
        let w_ei = cylinder::w_ei(cyl, eta_vol, p_im, d.n_e_rpm, gas.r_a, t_im);
        let w_f = cylinder::w_f(cyl, d.u_delta_mg, d.n_e_rpm);
        let w_eo = w_f + w_ei; // eq. (14)
        let of_s = p.of_s();
        let lambda_o = cylinder::lambda_o(w_ei, x_oim, w_f, of_s);
        let x_oe_raw = (w_ei * x_oim - w_f * of_s) / w_eo;
        let x_oe = cylinder::x_oe(w_ei, x_oim, w_f, of_s, w_eo, sem);

        // Cylinder-out temperature, eqs (17)-(24), and the pipe heat loss, eq. (25).
        let s = SeligerInputs {
            pi_e: p_em / p_im, // eq. (18)
            w_f,
            w_ei,
            t_im,
        };
        let (t_e, used, memory_next) = match self.opts.cylinder_temp {
            CylinderTemp::Converged => {
                let fp = cylinder::cylinder_out_temp_converged(gas, cyl, &self.cc, &s, sem);
                if !fp.converged {
                    guards |= Guard::FixedPointNotConverged as u32;
                }
                (fp.t_e, fp.at, fp.at)
            }
            CylinderTemp::OneIteration => {
                let st = cylinder::cylinder_out_temp_step(gas, cyl, &self.cc, &s, memory, sem);
                (st.t_e, memory, st.next)
            }
        };
        let t_em = cylinder::exhaust_temp_drop(&p.exhaust_pipe, gas.c_pe, t_amb, t_e, w_eo, sem);

        // EGR valve, eqs (32)-(38).
        let eg = egr::egr_flow(&p.egr_valve, p_im, p_em, t_em, gas.r_e, u_egr_act, sem);
        let w_egr = eg.w_egr;

        // Turbine, eqs (43)-(56).
        let tb = &p.turbine;
        let pi_t = turbine::pi_t(p_amb, p_em, sem);
        let f_vgt = turbine::f_vgt(tb, u_vgt_act, sem);
        let w_t = turbine::w_t(tb, p_em, t_em, gas.r_e, turbine::f_pi_t(tb, pi_t), f_vgt);
        let tp = turbine::power(tb, gas.c_pe, gas.gamma_e, t_em, pi_t, omega_t, w_t, sem);

        // Compressor, eqs (58)-(72).
        let cp = &p.compressor;
        let pi_c = compressor::pi_c(p_im, p_amb, sem);
        let isentropic = compressor::isentropic_term(pi_c, gas.gamma_a);
        let cf = compressor::flow(
            cp, gas.c_pa, gas.r_a, t_amb, p_amb, isentropic, omega_t, sem,
        );
        let w_c = cf.w_c;
        let eta_c = compressor::efficiency(cp, w_c, pi_c, sem);
        let cpow = compressor::power(gas.c_pa, t_amb, isentropic, w_c, eta_c);

        // State equations: manifolds (6), (9); turbo (42); actuators (40), (41), (57).
        let im = manifold::intake(
            gas.r_a,
            t_im,
            p.intake_manifold.v_im,
            p_im,
            x_oim,
            x_oem,
            p.intake_manifold.x_oc,
            w_c,
            w_egr,
            w_ei,
        );
        let em = manifold::exhaust(
            gas.r_e,
            t_em,
            p.exhaust_manifold.v_em,
            p_em,
            x_oem,
            x_oe,
            w_eo,
            w_t,
            w_egr,
        );
        let d_omega = turbo::omega_derivative(p.turbo.j_t, omega_t, tp.p_t_eta_m, cpow.p_c);
        let (d_u1, d_u2) = egr::actuator_derivatives(&p.egr_actuator, ue_delayed, u_egr1, u_egr2);
        let d_uv = turbine::actuator_derivative(&p.vgt_actuator, uv_delayed, u_vgt_state);
        let mut dx = [im.dp, em.dp, im.dx_o, em.dx_o, d_omega, d_u1, d_u2, d_uv];
        if authors && limit_derivatives(&x, &mut dx, &self.bounds) {
            guards |= Guard::StateLimit as u32;
        }

        let m_e = cylinder::torque(
            cyl,
            &self.cc,
            d.u_delta_mg,
            d.n_e_rpm,
            p_im,
            p_em,
            lambda_o,
            sem,
        );
        let x_egr = manifold::egr_fraction(w_egr, w_c, authors);

        // Guard and regime flags (reporting only; they do not change the values).
        if authors {
            let raw_pi_c = p_im / p_amb;
            let mut set = |c: bool, g: Guard| {
                if c {
                    guards |= g as u32;
                }
            };
            set(x_oe_raw < 0.0, Guard::XOe);
            set(lambda_o < 1.0, Guard::LambdaBelowOne);
            set(t_e >= 1500.0, Guard::TeMax);
            set(used.x_r <= 0.0 || used.x_r >= 1.0, Guard::XrRange);
            set(used.t_1 <= 273.0, Guard::T1Min);
            set(eg.f_egr <= 0.0 && u_egr_act < 0.0, Guard::FEgrMin);
            set(raw_pi_c < 1.0, Guard::PiCMin);
            set(poly2(&cp.c_wpsi, omega_t) < 0.0, Guard::CPsi1Min);
            set(poly2(&cp.c_wphi, omega_t) < 0.1, Guard::CPhi1Min);
            set(cf.phi_c <= 0.0, Guard::PhiCMin);
            set(w_c <= 1e-4, Guard::WcMin);
            set(eta_c <= 0.2, Guard::EtaCMin);
            set(p_amb / p_em > 0.9999, Guard::PiTMax);
            set(tp.bsr <= 0.0 || tp.bsr >= 2.0 * tb.bsr_opt, Guard::BsrRange);
            set(tp.eta_tm <= 0.2 || tp.eta_tm >= 1.0, Guard::EtaTmRange);
            set(f_vgt <= 0.0, Guard::FVgtMin);
            set(w_egr / (w_c + w_egr) > 0.9, Guard::XEgrMax);
            set(omega_t.max(tb.c_m[1]) < tb.w_tlin, Guard::CmLinear);
        }
        let ratio = p_im / p_em;
        if ratio < p.egr_valve.pi_egropt {
            guards |= Guard::EgrChoked as u32;
        } else if ratio >= 1.0 {
            guards |= Guard::EgrNoFlow as u32;
        }
        if cf.psi_c.is_finite() {
            let c_psi1 = poly2(&cp.c_wpsi, omega_t);
            let c_psi1 = if authors { c_psi1.max(0.0) } else { c_psi1 };
            let dd = cf.psi_c - cp.c_psi2;
            if 1.0 - c_psi1 * dd * dd < 0.0 {
                guards |= Guard::PhiEllipse as u32;
            }
        }

        let signals = Signals {
            n_e: d.n_e_rpm,
            u_delta: d.u_delta_mg,
            u_egr: d.u_egr_pct,
            u_vgt: d.u_vgt_pct,
            u_egr_actual: u_egr_act,
            u_vgt_actual: u_vgt_act,
            w_c,
            w_egr,
            w_t,
            w_ei,
            w_eo,
            w_f,
            t_e,
            t_em,
            t_c: cpow.t_c,
            x_r: used.x_r,
            t_1: used.t_1,
            x_egr,
            lambda_o,
            x_oe,
            m_e,
            n_t: turbo::n_t_rpm(omega_t),
            eta_c,
            eta_tm: tp.eta_tm,
            bsr: tp.bsr,
            pi_c,
            pi_t,
            p_c: cpow.p_c,
            p_t_eta_m: tp.p_t_eta_m,
            eta_vol,
            pi_egr: eg.pi_egr,
            t_im,
            p_c_out: p_im,
            w_ic: w_c,
            guards,
        };
        Evaluation {
            dx,
            signals,
            memory_next,
        }
    }
}
