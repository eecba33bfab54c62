//! The scale of a campaign's engine, measured at its stationary points, and the search boxes of
//! steps 1 and 5 that depend on it.
//!
//! Most tuned parameters are dimensionless (efficiencies, pressure ratios, exponents, the VGT
//! command law in %), or are made so by a declared constant (the effective-area maps of eqs
//! (37)-(38) and (54)-(56) by A_egrmax and A_vgtmax, the turbine-efficiency speed c_m2 by
//! w_tlin, the volumes and J_t of step 3 by V_d and R_c, [`super::complete::Step3Start`]).
//! The boxes of the others were sized for the published engine's campaigns, whose largest
//! compressor flow is 0.57-0.74 kg/s: W_copt (kg/s) and Q_c's a1, a3 ((kg/s)^-2, (kg/s)^-1) of
//! eqs (62)-(65), pi_copt of eq. (64) (the pressure ratio's range) and k_ic of eq. (86)
//! (Pa^2 s^2/(K kg^2)). A campaign of an engine with 2.5 times the flow had the step-1 W_copt
//! cut at 2 kg/s (docs/tuning.md, "Boxes scaled to the campaign").
//!
//! [`CampaignScale::apply`] scales those boxes by the measured scale where it lies outside the
//! published campaigns' band, and never narrows one: each bound is `max(today's, data's)`, so
//! the published engine's campaigns search the same boxes, bit for bit. The same rule widens
//! the effective-area coefficients' boxes when the measured flows need a larger area ratio than
//! the published engine's (a declared A_egrmax or A_vgtmax too small for the engine).

use super::complete::StaticParam;
use super::data::StationaryPoint;
use crate::components::compressor;
use crate::params::Params;

/// Largest measured compressor flow \[kg/s\] up to which the flow boxes are the published ones
/// (W_copt <= 2 kg/s, k_ic >= 1e5): the published engine's campaigns reach 0.57-0.74 kg/s.
pub const W_C_MAX_HI: f64 = 0.8;

/// Largest measured compressor flow \[kg/s\] down to which the boxes of the inverse flow scale
/// are the published ones (a1 <= 100 (kg/s)^-2, |a3| <= 100 (kg/s)^-1).
pub const W_C_MAX_LO: f64 = 0.5;

/// Largest measured (Pi_c - 1)^0.5 up to which pi_copt's box is the published one (at most 5):
/// the published engine's campaigns reach 1.38-1.78 (Pi_c 2.9-4.2).
pub const PI_C_TERM_HI: f64 = 2.0;

/// Largest measured VGT area ratio (eq. (52) with f_Pit <= 1) up to which the boxes of c_f1,
/// c_f2 are the published ones: the published engine's campaigns reach 1.06-1.12.
pub const F_VGT_HI: f64 = 2.0;

/// Largest measured EGR area ratio (eq. (32) with Psi_egr <= 1) up to which the boxes of c_egr
/// are the published ones: the published engine's campaigns reach 0.48-0.60.
pub const F_EGR_HI: f64 = 1.2;

/// What a campaign measured of its engine's scale (stationary points only). A quantity that
/// could not be measured (no points, no EGR) is NaN and leaves its boxes as they are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CampaignScale {
    /// Largest compressor flow W_c \[kg/s\].
    pub w_c_max: f64,
    /// Largest (Pi_c - 1)^0.5 (eqs (59), (64) with c_pi = 0.5, step 1's start exponent).
    pub pi_c_term_max: f64,
    /// Largest W_t sqrt(T_em R_e) / (A_vgtmax p_em), W_t = W_c + W_f: the VGT area ratio
    /// f_Pit f_vgt of eq. (52), a lower bound of f_vgt (f_Pit <= 1).
    pub f_vgt_max: f64,
    /// Largest W_egr sqrt(T_em R_e) / (A_egrmax p_em), W_egr = W_c x_egr / (1 - x_egr): the
    /// EGR area ratio Psi_egr f_egr of eq. (32), a lower bound of f_egr (Psi_egr <= 1).
    pub f_egr_max: f64,
}

impl CampaignScale {
    /// Nothing measured: every box as sized for the published engine.
    pub const NONE: Self = Self {
        w_c_max: f64::NAN,
        pi_c_term_max: f64::NAN,
        f_vgt_max: f64::NAN,
        f_egr_max: f64::NAN,
    };

    /// The scale of the stationary points `pts`, with the constants (A_egrmax, A_vgtmax, R_e,
    /// the fuel of eq. (13)) of `p`. Non-finite values are skipped.
    pub fn of(p: &Params, pts: &[StationaryPoint]) -> Self {
        let max = |v: &mut dyn Iterator<Item = f64>| {
            v.filter(|x| x.is_finite())
                .fold(f64::NAN, |m: f64, x| if m >= x { m } else { x })
        };
        let r_e = p.gas.r_e;
        let density = |s: &StationaryPoint| (s.t_em * r_e).sqrt() / s.p_em; // eqs (32), (52)
        Self {
            w_c_max: max(&mut pts.iter().map(|s| s.w_c)),
            pi_c_term_max: max(&mut pts.iter().map(|s| {
                (compressor::pi_c(s.p_c, s.p_amb, super::steps::SEM) - 1.0)
                    .max(0.0)
                    .sqrt()
            })),
            f_vgt_max: max(&mut pts.iter().map(|s| {
                let w_f = crate::components::cylinder::w_f(&p.cylinder, s.u_delta, s.n_e);
                (s.w_c + w_f) * density(s) / p.turbine.a_vgtmax // eq. (52)
            })),
            f_egr_max: max(&mut pts.iter().map(|s| {
                s.w_c * s.x_egr / (1.0 - s.x_egr) * density(s) / p.egr_valve.a_egrmax
                // eq. (32)
            })),
        }
    }

    /// The factors by which the boxes grow: (flow up, flow down, pressure ratio, VGT area, EGR
    /// area), each at least 1 (1 where not measured).
    fn factors(&self) -> [f64; 5] {
        let up = |x: f64, band: f64| if x > band { x / band } else { 1.0 };
        [
            up(self.w_c_max, W_C_MAX_HI),
            // a small engine: W_C_MAX_LO / w_c_max, where positive and below the band
            if self.w_c_max > 0.0 && self.w_c_max < W_C_MAX_LO {
                W_C_MAX_LO / self.w_c_max
            } else {
                1.0
            },
            up(self.pi_c_term_max, PI_C_TERM_HI),
            up(self.f_vgt_max, F_VGT_HI),
            up(self.f_egr_max, F_EGR_HI),
        ]
    }

    /// The box of one static parameter (a [`super::complete::STATIC_PARAMS`] entry or
    /// [`super::complete::K_IC_PARAM`]) for this scale: widened as the module documentation
    /// says, never narrowed; the others unchanged.
    pub fn apply(&self, mut b: StaticParam) -> StaticParam {
        let [up, down, pi, vgt, egr] = self.factors();
        let (lo, hi) = match b.name {
            // the peak-efficiency flow, eq. (63): x the largest flow / 0.8 kg/s
            "w_copt" => (b.lo, b.hi * up),
            // eq. (86): the same pressure drop at `up` times the flow needs k_ic / up^2
            "k_ic" => (b.lo / (up * up), b.hi),
            // Q_c of eq. (65) weighs (W_c - W_copt)^2 and (W_c - W_copt)(pi_c - pi_copt)
            "a1" => (b.lo, b.hi * down * down),
            "a3" => (b.lo * down, b.hi * down),
            // eq. (64): the pressure-ratio axis
            "pi_copt" => (b.lo, b.hi * pi),
            // eq. (56): f_vgt = c_f2 + c_f1 sqrt(...)
            "c_f1" | "c_f2" => (b.lo * vgt, b.hi * vgt),
            // eq. (38): f_egr = c_egr1 u^2 + c_egr2 u + c_egr3; c_egr1's upper bound < 0 stays
            "c_egr1" => (b.lo * egr, b.hi),
            "c_egr2" | "c_egr3" => (b.lo * egr, b.hi * egr),
            _ => (b.lo, b.hi),
        };
        b.lo = lo;
        b.hi = hi;
        b
    }
}
