//! The algebraic part shared by every model variant: inputs and their saturations, actuator
//! outputs, cylinder, EGR valve, turbine, compressor, torque, the turbo shaft and actuator
//! derivatives, the guard flags and the [`Signals`] record.
//!
//! The variants differ only in their control volumes (isothermal manifolds, eqs (6), (9), in
//! [`Engine8`](super::Engine8); adiabatic manifolds, eqs (80)-(83), in
//! [`Engine10`](super::Engine10); plus the volume before the intercooler, eqs (84)-(87), in
//! [`Engine12`](super::Engine12)) and in which temperatures and pressures the flows see. Those
//! port conditions are the [`Ports`] given to [`evaluate`]; everything else is computed here
//! once, from the pure component functions.

use super::{
    saturate_inputs, saturate_u_egr, saturate_u_vgt, Actuators, CylinderTemp, Guard, ModelInput,
    ModelOptions, Signals,
};
use crate::components::cylinder::{self, CylinderConsts, SeligerInputs, SeligerIterate};
use crate::components::{compressor, egr, manifold, poly2, turbine, turbo};
use crate::params::Params;

/// The conditions the shared algebraic part sees (states already clipped into their limits).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Ports {
    /// Intake manifold pressure p_im \[Pa\].
    pub p_im: f64,
    /// Exhaust manifold pressure p_em \[Pa\].
    pub p_em: f64,
    /// Intake manifold oxygen mass fraction X_Oim [-].
    pub x_oim: f64,
    /// Turbo speed omega_t [rad/s].
    pub omega_t: f64,
    /// EGR actuator states u_egr1, u_egr2 [%].
    pub u_egr1: f64,
    /// See `u_egr1`.
    pub u_egr2: f64,
    /// VGT actuator state [%].
    pub u_vgt: f64,
    /// Temperature of the gas the cylinders draw, T_im [K]: the constant of eq. (73) in the
    /// 8-state model, the state of eq. (80) in the extensions. Used by W_ei (eq. (11)) and as
    /// the intake temperature of the Seliger cycle (eq. (21)).
    pub t_im: f64,
    /// Exhaust manifold temperature seen by the EGR valve and the turbine [K]: `None` for the
    /// isothermal model (the value of eq. (25)), the state of eq. (81) in the extensions.
    pub t_em: Option<f64>,
    /// Compressor outlet pressure [Pa]: `None` = p_im (eq. (59)), the state p_c of eq. (85)
    /// in the 12-state model (eq. (87)).
    pub p_c: Option<f64>,
    /// Flow into the intake manifold from the intercooler W_ic [kg/s]: `None` = W_c (ideal
    /// intercooler, eq. (82)), eq. (86) in the 12-state model. Used for the EGR fraction
    /// (eq. (7) with W_ic for W_c) and the W_ic signal.
    pub w_ic: Option<f64>,
}

/// Result of the shared algebraic part.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shared {
    /// Every signal; `guards` lacks only the state-limit bit, which the variant adds after it
    /// has limited its derivatives.
    pub signals: Signals,
    /// Cylinder-out oxygen mass fraction X_Oe [-] as used by the exhaust manifold (eq. (16),
    /// authors: >= 0).
    pub x_oe: f64,
    /// dω_t/dt [rad/s^2], eq. (42).
    pub d_omega_t: f64,
    /// du_egr1/dt, du_egr2/dt [%/s], eqs (40)-(41).
    pub d_u_egr1: f64,
    /// See `d_u_egr1`.
    pub d_u_egr2: f64,
    /// du_vgt/dt [%/s], eq. (57).
    pub d_u_vgt: f64,
    /// Cylinder-temperature memory to hold after an accepted step.
    pub memory_next: SeligerIterate,
}

/// Evaluate the shared algebraic part at `s` with inputs `u` (see the module documentation).
///
/// With `SIGNALS = false` (for [`Model::derivatives`]) the work that feeds no derivative is
/// left out: the torque M_e (eqs (26)-(31)), n_t and x_egr are NaN and `guards` holds only
/// the input-saturation and fixed-point bits. Every other value is the same, bit for bit.
///
/// [`Model::derivatives`]: super::Model::derivatives
#[inline(always)]
pub(crate) fn evaluate<const SIGNALS: bool>(
    p: &Params,
    cc: &CylinderConsts,
    opts: &ModelOptions,
    s: &Ports,
    u: &ModelInput,
    memory: SeligerIterate,
) -> Shared {
    let sem = opts.semantics;
    let authors = sem.authors();
    let gas = &p.gas;
    let (t_amb, p_amb) = (p.ambient.t_amb, p.ambient.p_amb);
    let (p_im, p_em, x_oim, omega_t, t_im) = (s.p_im, s.p_em, s.x_oim, s.omega_t, s.t_im);

    // Inputs: saturations before the delays (items 1-4).
    let (d, mut guards) = saturate_inputs(&u.now, sem, &p.input_saturation);
    let ue_delayed = saturate_u_egr(u.u_egr_delayed, sem, &p.input_saturation);
    let uv_delayed = saturate_u_vgt(u.u_vgt_delayed, sem, &p.input_saturation);

    // Actuator outputs (eq. (39), state of eq. (57)) or the bypass switch (item 6).
    let (u_egr_act, u_vgt_act) = match opts.actuators {
        Actuators::Dynamic => (
            egr::actuator_output(&p.egr_actuator, s.u_egr1, s.u_egr2),
            s.u_vgt,
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
    let sel = SeligerInputs {
        pi_e: p_em / p_im, // eq. (18)
        w_f,
        w_ei,
        t_im,
    };
    let (t_e, used, memory_next) = match opts.cylinder_temp {
        CylinderTemp::Converged => {
            let fp = cylinder::cylinder_out_temp_converged(gas, cyl, cc, &sel, sem);
            if !fp.converged {
                guards |= Guard::FixedPointNotConverged as u32;
            }
            (fp.t_e, fp.at, fp.at)
        }
        CylinderTemp::OneIteration => {
            let st = cylinder::cylinder_out_temp_step(gas, cyl, cc, &sel, memory, sem);
            (st.t_e, memory, st.next)
        }
    };
    // T_em of eq. (25): the manifold temperature of the isothermal model, the inflow
    // temperature T_em,in of the adiabatic exhaust manifold (eq. (81)).
    let t_em_in = cylinder::exhaust_temp_drop(&p.exhaust_pipe, gas.c_pe, t_amb, t_e, w_eo, sem);
    let t_em = s.t_em.unwrap_or(t_em_in);

    // EGR valve, eqs (32)-(38).
    let eg = egr::egr_flow(&p.egr_valve, p_im, p_em, t_em, gas.r_e, u_egr_act, sem);
    let w_egr = eg.w_egr;

    // Turbine, eqs (43)-(56).
    let tb = &p.turbine;
    let pi_t = turbine::pi_t(p_amb, p_em, sem);
    let f_vgt = turbine::f_vgt(tb, u_vgt_act, sem);
    let ex = turbine::expansion_terms(tb, gas.gamma_e, pi_t); // eqs (48), (50), (53)
    let w_t = turbine::w_t(tb, p_em, t_em, gas.r_e, ex.f_pi_t, f_vgt);
    let tp = turbine::power_dh(tb, gas.c_pe, t_em, ex.dh, omega_t, w_t, sem);

    // Compressor, eqs (58)-(72); outlet pressure p_im (eq. (59)) or p_c (eq. (87)).
    let cp = &p.compressor;
    let p_c_out = s.p_c.unwrap_or(p_im);
    let pi_c = compressor::pi_c(p_c_out, p_amb, sem);
    let isentropic = compressor::isentropic_term(pi_c, gas.gamma_a);
    let cf = compressor::flow(
        cp, gas.c_pa, gas.r_a, t_amb, p_amb, isentropic, omega_t, sem,
    );
    let w_c = cf.w_c;
    let eta_c = compressor::efficiency(cp, w_c, pi_c, sem);
    let cpow = compressor::power(gas.c_pa, t_amb, isentropic, w_c, eta_c);
    let w_ic = s.w_ic.unwrap_or(w_c); // eq. (82) or (86)

    // Turbo (42); actuators (40), (41), (57).
    let d_omega_t = turbo::omega_derivative(p.turbo.j_t, omega_t, tp.p_t_eta_m, cpow.p_c);
    let (d_u_egr1, d_u_egr2) =
        egr::actuator_derivatives(&p.egr_actuator, ue_delayed, s.u_egr1, s.u_egr2);
    let d_u_vgt = turbine::actuator_derivative(&p.vgt_actuator, uv_delayed, s.u_vgt);

    // Signals that feed no derivative: torque (eqs (26)-(31)), EGR fraction (eq. (7)), n_t.
    let (m_e, x_egr, n_t) = if SIGNALS {
        (
            cylinder::torque(cyl, cc, d.u_delta_mg, d.n_e_rpm, p_im, p_em, lambda_o, sem),
            manifold::egr_fraction(w_egr, w_ic, authors),
            turbo::n_t_rpm(omega_t),
        )
    } else {
        (f64::NAN, f64::NAN, f64::NAN)
    };

    // Guard and regime flags (reporting only; they do not change the values).
    if SIGNALS && authors {
        let raw_pi_c = p_c_out / p_amb;
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
        set(w_egr / (w_ic + w_egr) > 0.9, Guard::XEgrMax);
        set(omega_t.max(tb.c_m[1]) < tb.w_tlin, Guard::CmLinear);
    }
    let ratio = p_im / p_em;
    if SIGNALS && ratio < p.egr_valve.pi_egropt {
        guards |= Guard::EgrChoked as u32;
    } else if SIGNALS && ratio >= 1.0 {
        guards |= Guard::EgrNoFlow as u32;
    }
    if SIGNALS && cf.psi_c.is_finite() {
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
        n_t,
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
        p_c_out,
        w_ic,
        t_em_in,
        guards,
    };
    Shared {
        signals,
        x_oe,
        d_omega_t,
        d_u_egr1,
        d_u_egr2,
        d_u_vgt,
        memory_next,
    }
}

/// [`Evaluation`](super::Evaluation) from a variant's shared part, derivatives and whether a
/// state is at an integrator limit (the [`Guard::StateLimit`] bit).
#[inline(always)]
pub(crate) fn evaluation<const N: usize>(
    sh: Shared,
    dx: [f64; N],
    at_limit: bool,
) -> super::Evaluation<N> {
    let mut signals = sh.signals;
    if at_limit {
        signals.guards |= Guard::StateLimit as u32;
    }
    super::Evaluation {
        dx,
        signals,
        memory_next: sh.memory_next,
    }
}

/// [`Derivatives`](super::Derivatives) from a variant's shared part (evaluated without the
/// signals) and derivatives.
#[inline(always)]
pub(crate) fn derivatives<const N: usize>(sh: &Shared, dx: [f64; N]) -> super::Derivatives<N> {
    super::Derivatives {
        dx,
        memory_next: sh.memory_next,
    }
}

/// A smaller model's state-indexed array `small` placed at the indices `map` of an extension's
/// `N`-array whose other entries are `fill` (states, scales, limits of the 8-state model in the
/// 10-state one, of the 10-state model in the 12-state one).
pub(crate) fn embed<T: Copy, const M: usize, const N: usize>(
    small: &[T; M],
    map: &[usize; M],
    fill: T,
) -> [T; N] {
    let mut out = [fill; N];
    for (k, &i) in map.iter().enumerate() {
        out[i] = small[k];
    }
    out
}

/// The inverse of [`embed`]: the entries of `x` at the indices `map`.
pub(crate) fn restrict<T: Copy, const M: usize, const N: usize>(
    x: &[T; N],
    map: &[usize; M],
) -> [T; M] {
    std::array::from_fn(|k| x[map[k]])
}

/// Actuator (index, value) pairs of a smaller model at the extension's indices `map`.
pub(crate) fn remap_indices(v: Vec<(usize, f64)>, map: &[usize]) -> Vec<(usize, f64)> {
    v.into_iter().map(|(k, x)| (map[k], x)).collect()
}
