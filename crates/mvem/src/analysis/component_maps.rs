//! Component maps like the paper's figures, computed from the component functions alone (no
//! model, no simulation): the compressor map with efficiency contours and speed lines (Fig. 7),
//! the turbine flow functions and efficiency (Fig. 5), the EGR flow functions (Fig. 3), and the
//! same functions at given operating points (to draw a simulation on the maps). Front ends only
//! draw the curves.

use crate::components::{compressor, egr, turbine, Semantics};
use crate::params::Params;

/// A curve y(x).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// Abscissae.
    pub x: Vec<f64>,
    /// Ordinates.
    pub y: Vec<f64>,
}

/// A field z(x, y) on a grid: `z[i * y.len() + j]` at `(x[i], y[j])`.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Grid abscissae.
    pub x: Vec<f64>,
    /// Grid ordinates.
    pub y: Vec<f64>,
    /// Values, x-major.
    pub z: Vec<f64>,
}

/// `n` evenly spaced values from `lo` to `hi` (both included; `n` >= 2).
pub fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

/// Range of the compressor map: W_c in [0, 0.6] kg/s, Pi_c in [1, 4].
pub const COMPRESSOR_RANGE: ((f64, f64), (f64, f64)) = ((0.0, 0.6), (1.0, 4.0));

/// Turbo speeds of the compressor speed lines [rad/s].
pub const SPEED_LINES: [f64; 6] = [4000.0, 6000.0, 8000.0, 10000.0, 12000.0, 14000.0];

/// Turbo speeds [rad/s] of the turbine efficiency curves: c_m (eq. (51)) is 0 below
/// c_m2 = 2769 rad/s, rises on the authors' linear branch up to w_tlin = 2797 rad/s and is almost
/// constant above (c_m3 = 0.01).
pub const TURBINE_EFFICIENCY_SPEEDS: [f64; 4] = [2775.0, 2785.0, 2797.0, 10000.0];

/// The compressor map (Fig. 7).
#[derive(Debug, Clone, PartialEq)]
pub struct CompressorMap {
    /// Efficiency eta_c (eq. (62)) over W_c [kg/s] (x) and Pi_c [-] (y).
    pub efficiency: Grid,
    /// Speed lines Pi_c over W_c (eqs (66)-(72)) at the turbo speeds [rad/s] of
    /// [`SPEED_LINES`], each ending where the square root of eq. (71) reaches 0 (surge side).
    pub speed_lines: Vec<(f64, Curve)>,
}

/// The compressor map of the parameters `p` (ambient inlet conditions).
pub fn compressor_map(p: &Params, sem: Semantics) -> CompressorMap {
    let c = &p.compressor;
    let g = &p.gas;
    let (t_amb, p_amb) = (p.ambient.t_amb, p.ambient.p_amb);
    let ((w_lo, w_hi), (pi_lo, pi_hi)) = COMPRESSOR_RANGE;
    let wx = linspace(w_lo, w_hi, 181);
    let py = linspace(pi_lo, pi_hi, 181);
    let z = wx
        .iter()
        .flat_map(|&w| {
            py.iter()
                .map(move |&pi| compressor::efficiency(c, w, pi, sem))
        })
        .collect();
    let speed_lines = SPEED_LINES
        .iter()
        .map(|&omega| {
            let mut line = Curve {
                x: Vec::new(),
                y: Vec::new(),
            };
            for pi in linspace(pi_lo, pi_hi, 400) {
                let iso = compressor::isentropic_term(pi, g.gamma_a);
                let f = compressor::flow(c, g.c_pa, g.r_a, t_amb, p_amb, iso, omega, sem);
                if f.phi_c - c.c_phi2 > 1e-9 {
                    line.x.push(f.w_c);
                    line.y.push(pi);
                }
            }
            (omega, line)
        })
        .collect();
    CompressorMap {
        efficiency: Grid { x: wx, y: py, z },
        speed_lines,
    }
}

/// The turbine maps (Fig. 5).
#[derive(Debug, Clone, PartialEq)]
pub struct TurbineMaps {
    /// Choking function f_Pi_t over Pi_t in [0.2, 1] (eq. (53)).
    pub f_pi_t: Curve,
    /// Effective area f_vgt over the VGT's command range (`input_saturation.u_vgt`, the
    /// authors' [20, 100] %) (eq. (56)).
    pub f_vgt: Curve,
    /// Efficiency eta_tm over BSR (eqs (49)-(51)) at the turbo speeds [rad/s] of
    /// [`TURBINE_EFFICIENCY_SPEEDS`] (Pi_t = 0.5, T_em chosen to give each BSR).
    pub efficiency: Vec<(f64, Curve)>,
}

/// The turbine maps of the parameters `p`.
pub fn turbine_maps(p: &Params, sem: Semantics) -> TurbineMaps {
    let t = &p.turbine;
    let g = &p.gas;
    let pis = linspace(0.2, 1.0, 200);
    let [u_lo, u_hi] = p.input_saturation.u_vgt;
    let us = linspace(u_lo, u_hi, 200);
    let (f_pi_t, f_vgt) = turbine_points(p, sem, &pis, &us);
    // eta_tm at fixed omega_t as a function of BSR, through turbine::power with T_em chosen to
    // give each BSR: BSR = R_t omega / sqrt(2 c_pe T_em dh) => T_em = (R_t omega / BSR)^2 / (2 c_pe dh)
    let pi_t = 0.5;
    let dh = 1.0 - f64::powf(pi_t, 1.0 - 1.0 / g.gamma_e);
    let efficiency = TURBINE_EFFICIENCY_SPEEDS
        .iter()
        .map(|&omega| {
            let bsrs = linspace(0.05, 2.0 * t.bsr_opt, 120);
            let y = bsrs
                .iter()
                .map(|&bsr| {
                    let t_em = (t.r_t * omega / bsr).powi(2) / (2.0 * g.c_pe * dh);
                    turbine::power(t, g.c_pe, g.gamma_e, t_em, pi_t, omega, 0.1, sem).eta_tm
                })
                .collect();
            (omega, Curve { x: bsrs, y })
        })
        .collect();
    TurbineMaps {
        f_pi_t: Curve { x: pis, y: f_pi_t },
        f_vgt: Curve { x: us, y: f_vgt },
        efficiency,
    }
}

/// f_Pi_t at the turbine pressure ratios `pi_t` (eq. (53)) and f_vgt at the VGT positions
/// `u_vgt` [%] (eq. (56)).
pub fn turbine_points(
    p: &Params,
    sem: Semantics,
    pi_t: &[f64],
    u_vgt: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let t = &p.turbine;
    (
        pi_t.iter().map(|&pi| turbine::f_pi_t(t, pi)).collect(),
        u_vgt.iter().map(|&u| turbine::f_vgt(t, u, sem)).collect(),
    )
}

/// The EGR valve maps (Fig. 3).
#[derive(Debug, Clone, PartialEq)]
pub struct EgrMaps {
    /// Flow function Psi_egr over p_im / p_em in [0.2, 1.05] (eqs (34)-(35): choked below
    /// Pi_egr,opt, no flow above 1).
    pub psi_egr: Curve,
    /// Effective area f_egr over the EGR valve's command range (`input_saturation.u_egr`, the
    /// authors' [0, 100] %) (eq. (38)).
    pub f_egr: Curve,
}

/// The EGR valve maps of the parameters `p`.
pub fn egr_maps(p: &Params, sem: Semantics) -> EgrMaps {
    let v = &p.egr_valve;
    let ratios = linspace(0.2, 1.05, 300);
    let psi = ratios
        .iter()
        .map(|&r| egr::psi_egr(v, egr::pi_egr(v, r, 1.0)))
        .collect();
    let [u_lo, u_hi] = p.input_saturation.u_egr;
    let us = linspace(u_lo, u_hi, 300);
    let (_, f) = egr_points(p, sem, &[], &us);
    EgrMaps {
        psi_egr: Curve { x: ratios, y: psi },
        f_egr: Curve { x: us, y: f },
    }
}

/// Psi_egr at the EGR pressure ratios `pi_egr` (eq. (34)) and f_egr at the EGR valve positions
/// `u_egr` [%] (eq. (38)).
pub fn egr_points(
    p: &Params,
    sem: Semantics,
    pi_egr: &[f64],
    u_egr: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let v = &p.egr_valve;
    (
        pi_egr.iter().map(|&x| egr::psi_egr(v, x)).collect(),
        u_egr.iter().map(|&u| egr::f_egr(v, u, sem)).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_are_the_component_functions() {
        let p = Params::published();
        let sem = Semantics::Authors;
        let c = compressor_map(&p, sem);
        assert_eq!(c.efficiency.z.len(), 181 * 181);
        // grid point (i, j) is eta_c at (x[i], y[j])
        let (i, j) = (60, 40);
        assert_eq!(
            c.efficiency.z[i * 181 + j],
            compressor::efficiency(&p.compressor, c.efficiency.x[i], c.efficiency.y[j], sem)
        );
        // speed lines: faster lines reach higher pressure ratios
        let top = |k: usize| c.speed_lines[k].1.y.iter().cloned().fold(0.0, f64::max);
        assert!(c.speed_lines.iter().all(|(_, l)| !l.x.is_empty()));
        assert!(top(5) > top(0));
        let t = turbine_maps(&p, sem);
        assert_eq!(t.f_pi_t.y[199], turbine::f_pi_t(&p.turbine, 1.0));
        // eta_tm peaks at BSR_opt with eta_tm,max on the fast line
        let (_, fast) = &t.efficiency[3];
        let peak = fast.y.iter().cloned().fold(0.0, f64::max);
        assert!((peak - p.turbine.eta_tmmax).abs() < 0.01 * p.turbine.eta_tmmax);
        let e = egr_maps(&p, sem);
        assert_eq!(e.f_egr.y[0], egr::f_egr(&p.egr_valve, 0.0, sem));
        assert_eq!(e.psi_egr.x.len(), 300);
    }
}
