//! Model parameters, one typed group per component of the paper (sections 3-7).
//!
//! [`Params`] is loaded once (TOML or JSON, see [`crate::io::params`]), validated with
//! [`Params::validate`] (every problem reported, each naming its field) and then treated as
//! immutable by the model. The authors' published set is built in: [`Params::published`].
//!
//! Units are SI unless a field says otherwise; actuator positions are in percent, engine speed
//! polynomials take rpm/1000 as the paper does (eq. (31)).

mod validate;

pub use validate::{ParamIssue, ParamIssues};

use serde::{Deserialize, Serialize};

/// Thermodynamic properties of air and exhaust gas (section 3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gas {
    /// Specific heat of air at constant pressure c_pa [J/(kg K)].
    pub c_pa: f64,
    /// Specific heat of exhaust gas at constant pressure c_pe [J/(kg K)].
    pub c_pe: f64,
    /// Specific heat of air at constant volume c_Va [J/(kg K)] (eqs (17), (19), (80)).
    pub c_va: f64,
    /// Specific heat of exhaust gas at constant volume c_Ve [J/(kg K)] (eq. (81)).
    pub c_ve: f64,
    /// Gas constant of air R_a [J/(kg K)].
    pub r_a: f64,
    /// Gas constant of exhaust gas R_e [J/(kg K)].
    pub r_e: f64,
    /// Ratio of specific heats of air gamma_a [-].
    pub gamma_a: f64,
    /// Ratio of specific heats of exhaust gas gamma_e [-].
    pub gamma_e: f64,
}

/// Ambient conditions (compressor inlet and turbine outlet, eqs (44), (59)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ambient {
    /// Ambient pressure p_amb [Pa]; also the turbine outlet pressure p_es (eq. (44)).
    pub p_amb: f64,
    /// Ambient temperature T_amb [K].
    pub t_amb: f64,
}

/// Intake manifold control volume (eqs (6)-(9)) and the ideal intercooler (eq. (73)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntakeManifold {
    /// Intake manifold volume V_im [m^3] (lumped with the intercooler volume).
    pub v_im: f64,
    /// Intake manifold temperature T_im [K] = intercooler cooling temperature (eq. (73)).
    pub t_im: f64,
    /// Oxygen mass fraction of air X_Oc [-] (eq. (9)).
    pub x_oc: f64,
}

/// Exhaust manifold control volume (eqs (6), (9)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExhaustManifold {
    /// Exhaust manifold volume V_em [m^3].
    pub v_em: f64,
}

/// Cylinder: flow (11)-(16), cylinder-out temperature (17)-(24), torque (26)-(31).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cylinder {
    /// Displaced volume V_d [m^3].
    pub v_d: f64,
    /// Number of cylinders n_cyl [-].
    pub n_cyl: f64,
    /// Compression ratio r_c [-].
    pub r_c: f64,
    /// Heating value of the fuel q_HV [J/kg].
    pub q_hv: f64,
    /// Stoichiometric air-to-fuel ratio (A/F)_s [-]; (O/F)_s = afs * x_oc (authors' implementation).
    pub afs: f64,
    /// Volumetric efficiency coefficients [c_vol1 [Pa^-1/2], c_vol2 [rpm^-1/2], c_vol3 [-]] (eq. (12)).
    pub c_vol: [f64; 3],
    /// Compensation factor for non-ideal cycles eta_sc [-] (eq. (17)).
    pub eta_sc: f64,
    /// Ratio of fuel consumed during constant-volume combustion x_cv [-] (eq. (17)).
    pub x_cv: f64,
    /// Ratio of specific heats in the cylinder gamma_cyl [-] (eq. (29); `gamma_c` in the authors' files).
    pub gamma_c: f64,
    /// Combustion chamber efficiency eta_igch [-] (eq. (29)).
    pub eta_igch: f64,
    /// Friction mean effective pressure polynomial [c_fric1, c_fric2, c_fric3] [bar] in n_e/1000 (eq. (30)).
    pub c_fric: [f64; 3],
}

/// Exhaust pipe heat loss between cylinder and exhaust manifold (eq. (25)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExhaustPipe {
    /// Wall temperature T_w [K] (the paper writes T_amb; implementation notes item 21).
    pub t_w: f64,
    /// Total heat transfer coefficient h_tot [W/(m^2 K)].
    pub h_tot: f64,
    /// Pipe diameter d_pipe [m].
    pub d_pipe: f64,
    /// Pipe length l_pipe [m] (omitted in the paper's eq. (25)).
    pub l_pipe: f64,
    /// Number of pipes n_pipe [-].
    pub n_pipe: f64,
}

/// EGR valve mass flow (eqs (32)-(38)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgrValve {
    /// Maximum effective area A_egrmax [m^2] (eq. (37)).
    pub a_egrmax: f64,
    /// Optimal pressure ratio Pi_egropt [-] (eqs (34)-(35)); must lie in (0, 1).
    pub pi_egropt: f64,
    /// Area polynomial [c_egr1 [%^-2], c_egr2 [%^-1], c_egr3 [-]] (eq. (38)).
    pub c_egr: [f64; 3],
}

/// EGR valve actuator: two first-order systems and a transport delay (eqs (39)-(41)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgrActuator {
    /// Time constant tau_egr1 [s].
    pub tau_egr1: f64,
    /// Time constant tau_egr2 [s].
    pub tau_egr2: f64,
    /// Transport delay tau_degr [s].
    pub tau_degr: f64,
    /// Overshoot gain K_egr [-] (eq. (39)).
    pub k_egr: f64,
}

/// Turbine flow (52)-(56) and efficiency (43)-(51).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Turbine {
    /// Maximum turbine area A_vgtmax [m^2] (eq. (52)).
    pub a_vgtmax: f64,
    /// Choking exponent K_t [-] (eq. (53)).
    pub k_t: f64,
    /// Ellipse parameter c_f1 [-] (eq. (56)).
    pub c_f1: f64,
    /// Ellipse parameter c_f2 [-] (eq. (56)).
    pub c_f2: f64,
    /// Ellipse parameter c_vgt1 [%] (eq. (56)).
    pub c_vgt1: f64,
    /// Ellipse parameter c_vgt2 [%] (eq. (56)).
    pub c_vgt2: f64,
    /// Turbine blade radius R_t [m] (eq. (50)).
    pub r_t: f64,
    /// Maximum turbine efficiency eta_tm,max [-] (eq. (49)).
    pub eta_tmmax: f64,
    /// Optimal blade speed ratio BSR_opt [-] (eq. (49)).
    pub bsr_opt: f64,
    /// c_m parameters [c_m1 [-], c_m2 [rad/s], c_m3 [-]] (eq. (51)).
    pub c_m: [f64; 3],
    /// Turbo speed below which c_m is linear in omega_t, w_tlin [rad/s] (authors' implementation, item 33).
    pub w_tlin: f64,
    /// Value of c_m at w_tlin for the linear branch, c_mlin [-] (authors' implementation, item 33).
    pub c_mlin: f64,
}

/// VGT actuator: first-order system with transport delay (eq. (57)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VgtActuator {
    /// Time constant tau_vgt [s].
    pub tau_vgt: f64,
    /// Transport delay tau_dvgt [s].
    pub tau_dvgt: f64,
}

/// Compressor efficiency (58)-(65) and mass flow (66)-(72).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Compressor {
    /// Compressor blade radius R_c [m] (eqs (66)-(67)).
    pub r_c: f64,
    /// Ellipse centre c_Psi2 [-] (eq. (68)).
    pub c_psi2: f64,
    /// Ellipse centre c_Phi2 [-] (eq. (68)).
    pub c_phi2: f64,
    /// c_Psi1(omega_t) polynomial [c_wPsi1 [s^2], c_wPsi2 [s], c_wPsi3 [-]] in omega_t [rad/s] (eq. (69)).
    pub c_wpsi: [f64; 3],
    /// c_Phi1(omega_t) polynomial [c_wPhi1 [s^2], c_wPhi2 [s], c_wPhi3 [-]] in omega_t [rad/s] (eq. (70)).
    pub c_wphi: [f64; 3],
    /// Maximum compressor efficiency eta_cmax [-] (eq. (62)).
    pub eta_cmax: f64,
    /// Optimal mass flow W_copt [kg/s] (eq. (63)).
    pub w_copt: f64,
    /// Optimal transformed pressure ratio pi_copt [-] (eq. (63)).
    pub pi_copt: f64,
    /// Pressure-ratio transformation exponent c_pi [-] (eq. (64)).
    pub c_pi: f64,
    /// Efficiency ellipse matrix Q_c = [[a1, a3], [a3, a2]] (eq. (65)); symmetric positive semidefinite.
    pub q_c: [[f64; 2]; 2],
}

/// Turbocharger shaft (eq. (42)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Turbo {
    /// Turbocharger inertia J_t [kg m^2].
    pub j_t: f64,
}

/// Initial values of the authors' Simulink file (not model constants). mvem starts from the
/// steady state by default; these are used by `--init authors` style starts and are kept so
/// that a parameter file round-trips.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Initial {
    /// Initial intake manifold pressure [Pa].
    pub p_im: f64,
    /// Initial exhaust manifold pressure [Pa].
    pub p_em: f64,
    /// Initial turbo speed [rad/s].
    pub omega_t: f64,
    /// Initial residual gas fraction memory x_r [-].
    pub x_r: f64,
    /// Initial T_1 memory [K].
    pub t_1: f64,
    /// Initial EGR actuator states and delay output [%].
    pub u_egr: f64,
    /// Initial VGT actuator state and delay output [%].
    pub u_vgt: f64,
}

/// Intercooler control volume of the 12-state extension (section 9.2, eqs (85)-(87)).
/// Not part of the published set; the defaults are derived from physics in
/// `docs/extensions.md` (the paper tunes both to data that are not published).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intercooler {
    /// Volume between compressor and intercooler V_ic [m^3] (eq. (85)); must be > 0.
    pub v_ic: f64,
    /// Intercooler flow restriction k_ic [Pa^2 s^2/(K kg^2)] of eq. (86),
    /// W_ic = sqrt(p_c (p_c - p_im) / (T_ic k_ic)); must be > 0 for the 12-state model.
    pub k_ic: f64,
}

impl Default for Intercooler {
    fn default() -> Self {
        // Derivation and sensitivity: docs/extensions.md.
        // V_ic: 2.0 m of 90 mm pipe (12.7 l) + compressor volute and diffuser (1.5 l) +
        // intercooler inlet tank (3.5 l) = 17.7 l, rounded to 18 l.
        // k_ic: eq. (86) solved for k_ic, k_ic = p_c dp / (T_ic W^2), with dp = 12.5 kPa at the
        // rated point of the published model (1900 rpm, 250 mg, u_egr 0 %, u_vgt 50 %:
        // W_c = 0.667 kg/s, p_c = 3.24e5 + 1.25e4 Pa, T_ic = T_c = 508 K): 1.861e7, rounded.
        Self {
            v_ic: 0.018,
            k_ic: 1.9e7,
        }
    }
}

/// The complete parameter set of the model: one group per component.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub gas: Gas,
    pub ambient: Ambient,
    pub intake_manifold: IntakeManifold,
    pub exhaust_manifold: ExhaustManifold,
    pub cylinder: Cylinder,
    pub exhaust_pipe: ExhaustPipe,
    pub egr_valve: EgrValve,
    pub egr_actuator: EgrActuator,
    pub turbine: Turbine,
    pub vgt_actuator: VgtActuator,
    pub compressor: Compressor,
    pub turbo: Turbo,
    pub initial: Initial,
    /// Extension parameters for the 12-state model (defaults if absent).
    #[serde(default)]
    pub intercooler: Intercooler,
}

/// The authors' published parameter set as a TOML document (the project file that holds it).
pub const PUBLISHED_TOML: &str = include_str!("../../data/published.toml");

impl Params {
    /// The published parameter set of Wahlstrom & Eriksson (2011), from the authors' package.
    pub fn published() -> Params {
        static CELL: std::sync::OnceLock<Params> = std::sync::OnceLock::new();
        CELL.get_or_init(|| {
            // The built-in file is part of the crate and covered by a test; a failure here is a
            // build defect, not a user error.
            toml::from_str(PUBLISHED_TOML).expect("built-in published parameter file parses")
        })
        .clone()
    }

    /// (O/F)_s: stoichiometric oxygen-to-fuel mass ratio [-] = (A/F)_s * X_Oc (implementation notes §1).
    pub fn of_s(&self) -> f64 {
        self.cylinder.afs * self.intake_manifold.x_oc
    }
}
