//! Model parameters, one typed group per component of the paper (sections 3-7).
//!
//! [`Params`] is loaded once (TOML or JSON, see [`crate::io::params`]), validated with
//! [`Params::validate`] (every problem reported, each naming its field) and then treated as
//! immutable by the model. The authors' published set is built in: [`Params::published`].
//!
//! Units are SI unless a field says otherwise; actuator positions are in percent, engine speed
//! polynomials take rpm/1000 as the paper does (eq. (31)).

mod meta;
mod validate;

pub use meta::{element_name, FieldMeta, GroupMeta, ParamInfo, Scalars};
pub use validate::{ParamIssue, ParamIssues};

use serde::{Deserialize, Serialize};

/// Declares one parameter group: the struct (serde, `deny_unknown_fields`) and its metadata
/// ([`FieldMeta`]: description and the symbol and unit of every scalar) from one list, so that
/// names, units and descriptions are written once (the field docs are generated from them).
macro_rules! param_group {
    (
        $title:literal
        $(#[$doc:meta])*
        $name:ident $key:literal $([$attr:meta])* {
            $( $field:ident : $ty:ty { $( $sym:ident : $unit:literal ),+ } $desc:literal ; )*
        }
    ) => {
        #[doc = concat!($title, ".")]
        $(#[$doc])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        $(#[$attr])*
        pub struct $name {
            $(
                #[doc = concat!($desc, ".")]
                $( #[doc = concat!("- `", stringify!($sym), "` \\[", $unit, "\\]")] )+
                pub $field: $ty,
            )*
        }

        impl $name {
            /// Metadata of the fields, in declaration (file) order.
            pub const META: GroupMeta = GroupMeta {
                key: $key,
                title: $title,
                fields: &[$(FieldMeta {
                    name: stringify!($field),
                    description: $desc,
                    shape: <$ty as Scalars>::SHAPE,
                    elements: &[$((stringify!($sym), $unit)),+],
                }),*],
            };

            /// The scalars of field `name` in row-major order (`None` for an unknown field).
            pub fn scalars(&self, name: &str) -> Option<&[f64]> {
                match name {
                    $(stringify!($field) => Some(Scalars::flat(&self.$field)),)*
                    _ => None,
                }
            }

            /// The scalars of field `name`, mutable.
            pub fn scalars_mut(&mut self, name: &str) -> Option<&mut [f64]> {
                match name {
                    $(stringify!($field) => Some(Scalars::flat_mut(&mut self.$field)),)*
                    _ => None,
                }
            }
        }
    };
}

param_group! {
    "Thermodynamic properties of air and exhaust gas (section 3)"
    Gas "gas" {
        c_pa: f64 { c_pa: "J/(kg K)" } "Specific heat of air at constant pressure";
        c_pe: f64 { c_pe: "J/(kg K)" } "Specific heat of exhaust gas at constant pressure";
        c_va: f64 { c_va: "J/(kg K)" } "Specific heat of air at constant volume c_Va (eqs (17), (19), (80))";
        c_ve: f64 { c_ve: "J/(kg K)" } "Specific heat of exhaust gas at constant volume c_Ve (eq. (81))";
        r_a: f64 { r_a: "J/(kg K)" } "Gas constant of air R_a";
        r_e: f64 { r_e: "J/(kg K)" } "Gas constant of exhaust gas R_e";
        gamma_a: f64 { gamma_a: "-" } "Ratio of specific heats of air";
        gamma_e: f64 { gamma_e: "-" } "Ratio of specific heats of exhaust gas";
    }
}

param_group! {
    "Ambient conditions (compressor inlet and turbine outlet, eqs (44), (59))"
    Ambient "ambient" {
        p_amb: f64 { p_amb: "Pa" } "Ambient pressure; also the turbine outlet pressure p_es (eq. (44))";
        t_amb: f64 { t_amb: "K" } "Ambient temperature T_amb (eq. (59))";
    }
}

param_group! {
    "Intake manifold control volume (eqs (6)-(9)) and the ideal intercooler (eq. (73))"
    IntakeManifold "intake_manifold" {
        v_im: f64 { v_im: "m^3" } "Intake manifold volume V_im, lumped with the intercooler volume (eq. (6))";
        t_im: f64 { t_im: "K" } "Intake manifold temperature T_im = intercooler cooling temperature (eq. (73))";
        x_oc: f64 { x_oc: "-" } "Oxygen mass fraction of air X_Oc (eq. (9))";
    }
}

param_group! {
    "Exhaust manifold control volume (eqs (6), (9))"
    ExhaustManifold "exhaust_manifold" {
        v_em: f64 { v_em: "m^3" } "Exhaust manifold volume V_em (eq. (6))";
    }
}

param_group! {
    "Cylinder: flow (11)-(16), cylinder-out temperature (17)-(24), torque (26)-(31)"
    Cylinder "cylinder" {
        v_d: f64 { v_d: "m^3" } "Displaced volume V_d (eqs (11), (27))";
        n_cyl: f64 { n_cyl: "-" } "Number of cylinders n_cyl (eqs (11), (13))";
        r_c: f64 { r_c: "-" } "Compression ratio r_c (eqs (12), (18), (29))";
        q_hv: f64 { q_hv: "J/kg" } "Heating value of the fuel q_HV (eqs (17), (27))";
        afs: f64 { afs: "-" } "Stoichiometric air-to-fuel ratio (A/F)_s; (O/F)_s = afs * x_oc (authors' implementation, eq. (15))";
        c_vol: [f64; 3] { c_vol1: "Pa^-1/2", c_vol2: "rpm^-1/2", c_vol3: "-" } "Volumetric efficiency coefficients (eq. (12))";
        eta_sc: f64 { eta_sc: "-" } "Compensation factor for non-ideal cycles eta_sc (eq. (17))";
        x_cv: f64 { x_cv: "-" } "Ratio of fuel consumed during constant-volume combustion x_cv (eq. (17))";
        gamma_c: f64 { gamma_c: "-" } "Ratio of specific heats in the cylinder gamma_cyl (eq. (29); `gamma_c` in the authors' files)";
        eta_igch: f64 { eta_igch: "-" } "Combustion chamber efficiency eta_igch (eq. (29))";
        c_fric: [f64; 3] { c_fric1: "bar", c_fric2: "bar", c_fric3: "bar" } "Friction mean effective pressure polynomial in n_e/1000 (eq. (30))";
    }
}

param_group! {
    "Exhaust pipe heat loss between cylinder and exhaust manifold (eq. (25))"
    ExhaustPipe "exhaust_pipe" {
        t_w: f64 { t_w: "K" } "Wall temperature T_w (eq. (25); the paper writes T_amb, implementation notes item 21)";
        h_tot: f64 { h_tot: "W/(m^2 K)" } "Total heat transfer coefficient h_tot (eq. (25))";
        d_pipe: f64 { d_pipe: "m" } "Pipe diameter d_pipe (eq. (25))";
        l_pipe: f64 { l_pipe: "m" } "Pipe length l_pipe (omitted in the paper's eq. (25))";
        n_pipe: f64 { n_pipe: "-" } "Number of pipes n_pipe (eq. (25))";
    }
}

param_group! {
    "EGR valve mass flow (eqs (32)-(38))"
    EgrValve "egr_valve" {
        a_egrmax: f64 { a_egrmax: "m^2" } "Maximum effective area A_egrmax (eq. (37))";
        pi_egropt: f64 { pi_egropt: "-" } "Optimal pressure ratio Pi_egropt, in (0, 1) (eqs (34)-(35))";
        c_egr: [f64; 3] { c_egr1: "%^-2", c_egr2: "%^-1", c_egr3: "-" } "Effective area polynomial (eq. (38))";
    }
}

param_group! {
    "EGR valve actuator: two first-order systems and a transport delay (eqs (39)-(41))"
    EgrActuator "egr_actuator" {
        tau_egr1: f64 { tau_egr1: "s" } "Time constant tau_egr1 (eq. (40))";
        tau_egr2: f64 { tau_egr2: "s" } "Time constant tau_egr2 (eq. (41))";
        tau_degr: f64 { tau_degr: "s" } "Transport delay tau_degr (eqs (40)-(41))";
        k_egr: f64 { k_egr: "-" } "Overshoot gain K_egr (eq. (39))";
    }
}

param_group! {
    "Turbine flow (52)-(56) and efficiency (43)-(51)"
    Turbine "turbine" {
        a_vgtmax: f64 { a_vgtmax: "m^2" } "Maximum turbine area A_vgtmax (eq. (52))";
        k_t: f64 { k_t: "-" } "Choking exponent K_t (eq. (53))";
        c_f1: f64 { c_f1: "-" } "Effective area ellipse parameter c_f1 (eq. (56))";
        c_f2: f64 { c_f2: "-" } "Effective area ellipse parameter c_f2 (eq. (56))";
        c_vgt1: f64 { c_vgt1: "%" } "Effective area ellipse parameter c_vgt1 (eq. (56))";
        c_vgt2: f64 { c_vgt2: "%" } "Effective area ellipse parameter c_vgt2 (eq. (56))";
        r_t: f64 { r_t: "m" } "Turbine blade radius R_t (eq. (50))";
        eta_tmmax: f64 { eta_tmmax: "-" } "Maximum turbine efficiency eta_tm,max (eq. (49))";
        bsr_opt: f64 { bsr_opt: "-" } "Optimal blade speed ratio BSR_opt (eq. (49))";
        c_m: [f64; 3] { c_m1: "-", c_m2: "rad/s", c_m3: "-" } "c_m(omega_t) parameters (eq. (51))";
        w_tlin: f64 { w_tlin: "rad/s" } "Turbo speed below which c_m is linear in omega_t (authors' implementation item 33, eq. (51))";
        c_mlin: f64 { c_mlin: "-" } "Value of c_m at w_tlin for the linear branch (authors' implementation item 33, eq. (51))";
    }
}

param_group! {
    "VGT actuator: first-order system with transport delay (eq. (57))"
    VgtActuator "vgt_actuator" {
        tau_vgt: f64 { tau_vgt: "s" } "Time constant tau_vgt (eq. (57))";
        tau_dvgt: f64 { tau_dvgt: "s" } "Transport delay tau_dvgt (eq. (57))";
    }
}

param_group! {
    "Compressor efficiency (58)-(65) and mass flow (66)-(72)"
    Compressor "compressor" {
        r_c: f64 { r_c: "m" } "Compressor blade radius R_c (eqs (66)-(67))";
        c_psi2: f64 { c_psi2: "-" } "Flow ellipse centre c_Psi2 (eq. (68))";
        c_phi2: f64 { c_phi2: "-" } "Flow ellipse centre c_Phi2 (eq. (68))";
        c_wpsi: [f64; 3] { c_wpsi1: "s^2", c_wpsi2: "s", c_wpsi3: "-" } "c_Psi1(omega_t) polynomial in omega_t [rad/s] (eq. (69))";
        c_wphi: [f64; 3] { c_wphi1: "s^2", c_wphi2: "s", c_wphi3: "-" } "c_Phi1(omega_t) polynomial in omega_t [rad/s] (eq. (70))";
        eta_cmax: f64 { eta_cmax: "-" } "Maximum compressor efficiency eta_c,max (eq. (62))";
        w_copt: f64 { w_copt: "kg/s" } "Optimal mass flow W_c,opt (eq. (63))";
        pi_copt: f64 { pi_copt: "-" } "Optimal transformed pressure ratio pi_c,opt (eq. (63))";
        c_pi: f64 { c_pi: "-" } "Pressure-ratio transformation exponent c_pi (eq. (64))";
        q_c: [[f64; 2]; 2] { a1: "-", a3: "-", a3: "-", a2: "-" } "Efficiency ellipse matrix Q_c = [[a1, a3], [a3, a2]], symmetric positive semidefinite (eq. (65))";
    }
}

param_group! {
    "Turbocharger shaft (eq. (42))"
    Turbo "turbo" {
        j_t: f64 { j_t: "kg m^2" } "Turbocharger inertia J_t (eq. (42))";
    }
}

param_group! {
    "Initial values of the authors' Simulink file (not model constants)"
    /// mvem starts from the
    /// steady state by default; these are used by `--init authors` style starts and are kept so
    /// that a parameter file round-trips.
    Initial "initial" {
        p_im: f64 { p_im: "Pa" } "Initial intake manifold pressure (authors' file, not used by default)";
        p_em: f64 { p_em: "Pa" } "Initial exhaust manifold pressure (authors' file, not used by default)";
        omega_t: f64 { omega_t: "rad/s" } "Initial turbo speed (authors' file, not used by default)";
        x_r: f64 { x_r: "-" } "Initial residual gas fraction memory (eq. (22); authors' file)";
        t_1: f64 { t_1: "K" } "Initial T_1 memory (eq. (21); authors' file)";
        u_egr: f64 { u_egr: "%" } "Initial EGR actuator states and delay output (authors' file)";
        u_vgt: f64 { u_vgt: "%" } "Initial VGT actuator state and delay output (authors' file)";
    }
}

param_group! {
    "Intercooler control volume of the 12-state extension (section 9.2, eqs (85)-(87))"
    /// Not part of the published set; the defaults are derived from physics in
    /// `docs/extensions.md` (the paper tunes both to data that are not published).
    Intercooler "intercooler" {
        v_ic: f64 { v_ic: "m^3" } "Volume between compressor and intercooler V_ic, > 0 (12-state model, eq. (85))";
        k_ic: f64 { k_ic: "Pa^2 s^2/(K kg^2)" } "Intercooler flow restriction k_ic of W_ic = sqrt(p_c (p_c - p_im) / (T_ic k_ic)), > 0 (12-state model, eq. (86))";
    }
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

param_group! {
    "Input saturation of the authors' implementation (items 1-4 of docs/authors-implementation.md)"
    /// Their engine's speed and fuel range and their actuators' command ranges: under the
    /// authors' semantics the model clamps n_e and u_delta into them before the cylinder and
    /// the EGR and VGT commands before the actuators' delays (each with a guard flag);
    /// `Semantics::Paper` takes the inputs as given. Not in the authors' parameter file
    /// (hard-coded there): the defaults are their values, 500-2000 rpm, 1-250 mg, 0-100 % EGR
    /// and 20-100 % VGT; an engine with another speed, fuel or command range sets its own. A
    /// field the file leaves out takes its default.
    InputSaturation "input_saturation" [serde(default)] {
        n_e: [f64; 2] { n_e_min: "rpm", n_e_max: "rpm" } "Engine speed range n_e_min < n_e_max the model clamps n_e into (item 1)";
        u_delta: [f64; 2] { u_delta_min: "mg/cycle", u_delta_max: "mg/cycle" } "Injected fuel range u_delta_min < u_delta_max the model clamps u_delta into (item 2)";
        u_egr: [f64; 2] { u_egr_min: "%", u_egr_max: "%" } "EGR-valve command range u_egr_min < u_egr_max, inside [0, 100] %, the model clamps u_egr into (item 3)";
        u_vgt: [f64; 2] { u_vgt_min: "%", u_vgt_max: "%" } "VGT command range u_vgt_min < u_vgt_max, inside [0, 100] %, the model clamps u_vgt into (item 4)";
    }
}

impl Default for InputSaturation {
    fn default() -> Self {
        use crate::model::{N_E_RANGE, U_DELTA_RANGE, U_EGR_RANGE, U_VGT_RANGE};
        Self {
            n_e: [N_E_RANGE.0, N_E_RANGE.1],
            u_delta: [U_DELTA_RANGE.0, U_DELTA_RANGE.1],
            u_egr: [U_EGR_RANGE.0, U_EGR_RANGE.1],
            u_vgt: [U_VGT_RANGE.0, U_VGT_RANGE.1],
        }
    }
}

impl InputSaturation {
    /// The EGR command range (lo, hi) [%] (`u_egr`).
    pub fn egr(&self) -> (f64, f64) {
        (self.u_egr[0], self.u_egr[1])
    }

    /// The VGT command range (lo, hi) [%] (`u_vgt`).
    pub fn vgt(&self) -> (f64, f64) {
        (self.u_vgt[0], self.u_vgt[1])
    }
}

param_group! {
    "Turbo-speed integrator limit of the authors' implementation (item 37 of docs/authors-implementation.md)"
    /// Under the authors' semantics omega_t is limited to this range of n_t = omega_t 30/pi
    /// (the integrator stops at it, the equilibrium is flagged); `Semantics::Paper` has no limit.
    /// Not in the authors' parameter file (hard-coded there): the default is their value,
    /// 100-200 000 rpm; a smaller, faster turbocharger sets its own.
    IntegratorLimits "integrator_limits" {
        n_t: [f64; 2] { n_t_min: "rpm", n_t_max: "rpm" } "Turbo speed range n_t_min < n_t_max of the omega_t integrator (item 37)";
    }
}

impl Default for IntegratorLimits {
    fn default() -> Self {
        Self {
            n_t: [100.0, 200_000.0],
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
    /// The authors' input saturation ranges (defaults, their values, where absent).
    #[serde(default)]
    pub input_saturation: InputSaturation,
    /// The authors' turbo-speed integrator limit (default, their value, if absent).
    #[serde(default)]
    pub integrator_limits: IntegratorLimits,
}

/// The authors' published parameter set (from their LGPL-3.0 Simulink package,
/// parameterData.mat; the same values as `data/wahlstrom_eriksson_2011_parameters.json`) as the
/// annotated TOML document of `mvem params show --format toml` (the project file that holds it;
/// a test checks that it is exactly that output).
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
