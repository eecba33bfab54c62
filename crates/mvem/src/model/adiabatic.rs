//! The adiabatic intake and exhaust manifolds of section 9, shared by the 10- and 12-state
//! variants: the energy and mass balances of eqs (80)-(81) and the oxygen mass fractions of
//! eq. (83), with the temperature states.

use super::common::Shared;
use crate::components::manifold;
use crate::params::Params;

/// The manifold states of the extensions.
#[derive(Debug, Clone, Copy)]
pub(super) struct ManifoldStates {
    /// Intake manifold pressure p_im \[Pa\].
    pub p_im: f64,
    /// Exhaust manifold pressure p_em \[Pa\].
    pub p_em: f64,
    /// Intake manifold temperature T_im \[K\].
    pub t_im: f64,
    /// Exhaust manifold temperature T_em \[K\].
    pub t_em: f64,
    /// Intake manifold oxygen mass fraction X_Oim [-].
    pub x_oim: f64,
    /// Exhaust manifold oxygen mass fraction X_Oem [-].
    pub x_oem: f64,
}

/// Derivatives of the manifold states.
#[derive(Debug, Clone, Copy)]
pub(super) struct ManifoldDerivatives {
    /// dp_im/dt [Pa/s], eq. (80).
    pub dp_im: f64,
    /// dp_em/dt [Pa/s], eq. (81).
    pub dp_em: f64,
    /// dT_im/dt [K/s], eq. (80).
    pub dt_im: f64,
    /// dT_em/dt [K/s], eq. (81).
    pub dt_em: f64,
    /// dX_Oim/dt [1/s], eq. (83).
    pub dx_oim: f64,
    /// dX_Oem/dt [1/s], eq. (83).
    pub dx_oem: f64,
}

/// The adiabatic manifolds with the flows and signals of `sh`:
/// - intake manifold, eq. (80): in W_ic + W_egr at T_im,in = `intake_manifold.t_im` (the
///   cooling temperature, eq. (73)), out `w_im_out` at T_im; `w_ic` is the charge air flow into
///   the manifold (W_c in the 10-state model, eq. (82); the forward intercooler flow of eq. (86)
///   in the 12-state model), `w_im_out` is W_ei (plus the intercooler back flow in the
///   12-state model);
/// - exhaust manifold, eq. (81): in W_eo at T_em,in (eq. (25)), out W_t + W_egr at T_em;
/// - oxygen mass fractions, eq. (83) (eq. (9) with the temperature states and W_ic; out-flows
///   do not change a mass fraction).
#[inline(always)]
pub(super) fn manifolds(
    p: &Params,
    sh: &Shared,
    x: &ManifoldStates,
    w_ic: f64,
    w_im_out: f64,
) -> ManifoldDerivatives {
    let gas = &p.gas;
    let sg = &sh.signals;
    let t_im_in = p.intake_manifold.t_im; // eq. (80): constant inflow temperature
    let w_in_im = w_ic + sg.w_egr;
    let im = manifold::adiabatic(
        gas.r_a,
        gas.c_va,
        p.intake_manifold.v_im,
        x.p_im,
        x.t_im,
        w_in_im,
        t_im_in * w_in_im,
        w_im_out,
    );
    let em = manifold::adiabatic(
        gas.r_e,
        gas.c_ve,
        p.exhaust_manifold.v_em,
        x.p_em,
        x.t_em,
        sg.w_eo,
        sg.t_em_in * sg.w_eo,
        sg.w_t + sg.w_egr,
    );
    let o_im = manifold::intake(
        gas.r_a,
        x.t_im,
        p.intake_manifold.v_im,
        x.p_im,
        x.x_oim,
        x.x_oem,
        p.intake_manifold.x_oc,
        w_ic,
        sg.w_egr,
        sg.w_ei,
    );
    let o_em = manifold::exhaust(
        gas.r_e,
        x.t_em,
        p.exhaust_manifold.v_em,
        x.p_em,
        x.x_oem,
        sh.x_oe,
        sg.w_eo,
        sg.w_t,
        sg.w_egr,
    );
    ManifoldDerivatives {
        dp_im: im.dp,
        dp_em: em.dp,
        dt_im: im.dt,
        dt_em: em.dt,
        dx_oim: o_im.dx_o,
        dx_oem: o_em.dx_o,
    }
}
