//! Named algebraic signals of the model and the guard flags of the authors' implementation.

use super::meta::VarMeta;

macro_rules! signals {
    ($( $field:ident => $name:literal, $unit:literal, $desc:literal; )*) => {
        /// Every algebraic signal of one model evaluation, computed in the same function as the
        /// derivatives so that logged signals cannot disagree with them. Names (see
        /// [`Signals::NAMES`]) are those of the reference data (`W_c`, `lambda_O`, ...).
        #[derive(Debug, Clone, Copy, PartialEq, Default)]
        pub struct Signals {
            $( #[doc = concat!($desc, " \\[", $unit, "\\].")] pub $field: f64, )*
            /// Active guards and regimes ([`Guard`] bits).
            pub guards: u32,
        }

        impl Signals {
            /// Column names, in [`Signals::values`] order.
            pub const NAMES: &'static [&'static str] = &[$($name),*];
            /// Name, unit and description of each signal, in [`Signals::NAMES`] order.
            pub const META: &'static [VarMeta] = &[$(VarMeta {
                name: $name,
                unit: $unit,
                description: $desc,
            }),*];
            /// Number of named signals.
            pub const COUNT: usize = [$($name),*].len();

            /// Values in [`Signals::NAMES`] order.
            pub fn values(&self) -> [f64; Self::COUNT] {
                [$(self.$field),*]
            }

            /// Value by reference name (e.g. `"W_c"`).
            pub fn get(&self, name: &str) -> Option<f64> {
                match name {
                    $($name => Some(self.$field),)*
                    _ => None,
                }
            }
        }
    };
}

signals! {
    n_e => "n_e", "rpm",
        "Engine speed after the input saturation n_e (item 1)";
    u_delta => "u_delta", "mg/cycle",
        "Injected fuel per cycle and cylinder after the input saturation u_delta (item 2)";
    u_egr => "u_egr", "%",
        "EGR command after saturation, undelayed u_egr (item 3)";
    u_vgt => "u_vgt", "%",
        "VGT command after saturation, undelayed u_vgt (item 4)";
    u_egr_actual => "u_egr_actual", "%",
        "Effective EGR valve position used by the flow model (eq. (39) or the switch, item 6)";
    u_vgt_actual => "u_vgt_actual", "%",
        "Effective VGT position used by the flow model (eq. (57) state or the switch, item 6)";
    w_c => "W_c", "kg/s",
        "Compressor mass flow W_c, eq. (72)";
    w_egr => "W_egr", "kg/s",
        "EGR mass flow W_egr, eq. (32)";
    w_t => "W_t", "kg/s",
        "Turbine mass flow W_t, eq. (55)";
    w_ei => "W_ei", "kg/s",
        "Cylinder in-flow W_ei, eq. (11)";
    w_eo => "W_eo", "kg/s",
        "Cylinder out-flow W_eo, eq. (14)";
    w_f => "W_f", "kg/s",
        "Fuel flow W_f, eq. (13)";
    t_e => "T_e", "K",
        "Cylinder-out temperature T_e, eq. (17)";
    t_em => "T_em", "K",
        "Exhaust manifold temperature T_em, eq. (25) (a state in the 10/12-state models)";
    t_c => "T_c", "K",
        "Compressor outlet temperature T_c, eq. (58)";
    x_r => "x_r", "-",
        "Residual gas fraction used in this evaluation x_r, eq. (22)";
    t_1 => "T_1", "K",
        "Temperature at inlet valve closing used in this evaluation T_1, eq. (21)";
    x_egr => "x_egr", "-",
        "EGR fraction x_egr, eq. (7) (authors: <= 0.9)";
    lambda_o => "lambda_O", "-",
        "Oxygen-to-fuel ratio lambda_O, eq. (15)";
    x_oe => "X_Oe", "-",
        "Cylinder-out oxygen mass fraction X_Oe, eq. (16)";
    m_e => "M_e", "Nm",
        "Engine torque M_e, eq. (26)";
    n_t => "n_t", "rpm",
        "Turbo speed n_t";
    eta_c => "eta_c", "-",
        "Compressor efficiency eta_c, eq. (62)";
    eta_tm => "eta_tm", "-",
        "Total turbine efficiency eta_tm, eq. (49)";
    bsr => "BSR", "-",
        "Blade speed ratio BSR, eq. (50)";
    pi_c => "Pi_c", "-",
        "Compressor pressure ratio Pi_c, eq. (59)/(87)";
    pi_t => "Pi_t", "-",
        "Turbine pressure ratio Pi_t, eq. (44)";
    p_c => "P_c", "W",
        "Compressor power P_c, eq. (61)";
    p_t_eta_m => "P_t_eta_m", "W",
        "Turbine power times mechanical efficiency P_t eta_m, eq. (48)";
    eta_vol => "eta_vol", "-",
        "Volumetric efficiency eta_vol, eq. (12)";
    pi_egr => "Pi_egr", "-",
        "EGR pressure ratio Pi_egr, eq. (35)";
    t_im => "T_im", "K",
        "Intake manifold temperature T_im (constant in the 8-state model)";
    p_c_out => "p_c", "Pa",
        "Pressure after the compressor p_c (= p_im in the 8- and 10-state models)";
    w_ic => "W_ic", "kg/s",
        "Intercooler mass flow W_ic (= W_c in the 8- and 10-state models, eq. (82))";
    t_em_in => "T_em_in", "K",
        "Temperature of the flow into the exhaust manifold T_em,in: the value of eq. (25) (= T_em in the 8-state model; the inflow temperature of eq. (81) in the 10/12-state models)";
}

macro_rules! guards {
    ($( $(#[$doc:meta])* $name:ident = $bit:literal, $label:literal, $invalidates:literal ;)*) => {
        /// Saturations and switches of the authors' implementation, and regimes of the paper's
        /// equations, reported as bits in [`Signals::guards`].
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(u32)]
        pub enum Guard {
            $( $(#[$doc])* $name = 1 << $bit, )*
        }

        impl Guard {
            /// All guards.
            pub const ALL: &'static [Guard] = &[$(Guard::$name),*];

            /// The flag label used in reports (`saturation:eta_c>=0.2`, `regime:egr_choked`, ...).
            pub fn label(self) -> &'static str {
                match self { $(Guard::$name => $label,)* }
            }

            /// Whether an active guard means the point is not a physical equilibrium of the
            /// paper's model (a saturation of the implementation is shaping the result).
            pub fn invalidates(self) -> bool {
                match self { $(Guard::$name => $invalidates,)* }
            }
        }
    };
}

guards! {
    /// n_e outside `input_saturation.n_e` (default [500, 2000] rpm) was clamped (item 1).
    InputNe = 0, "input:n_e in input_saturation.n_e", false;
    /// u_delta outside `input_saturation.u_delta` (default [1, 250] mg) was clamped (item 2).
    InputUDelta = 1, "input:u_delta in input_saturation.u_delta", false;
    /// u_egr outside `input_saturation.u_egr` (default [0, 100] %) was clamped (item 3).
    InputUEgr = 2, "input:u_egr in input_saturation.u_egr", false;
    /// u_vgt outside `input_saturation.u_vgt` (default [20, 100] %) was clamped (item 4).
    InputUVgt = 3, "input:u_vgt in input_saturation.u_vgt", false;
    /// A state is at an integrator limit (items 9-12, 37).
    StateLimit = 4, "saturation:integrator_limit", true;
    /// X_Oe = max(0, .) active (item 14).
    XOe = 5, "saturation:X_Oe>=0", true;
    /// lambda_O < 1: torque scaled by min(lambda_O, 1) (item 15).
    LambdaBelowOne = 6, "lambda_O<1", true;
    /// T_e capped at 1500 K (item 18).
    TeMax = 7, "saturation:T_e<=1500", true;
    /// x_r limited to [0, 1] (item 19).
    XrRange = 8, "saturation:x_r in [0,1]", true;
    /// T_1 >= 273 K active (item 20).
    T1Min = 9, "saturation:T_1>=273", true;
    /// f_egr >= 0 active (item 23).
    FEgrMin = 10, "saturation:f_egr>=0", true;
    /// Pi_c >= 1 active (item 24).
    PiCMin = 11, "saturation:Pi_c>=1", true;
    /// c_Psi1 >= 0 active (item 25).
    CPsi1Min = 12, "saturation:c_psi1>=0", true;
    /// c_Phi1 >= 0.1 active (item 25).
    CPhi1Min = 13, "saturation:c_phi1>=0.1", true;
    /// Phi_c >= 0 active (item 27).
    PhiCMin = 14, "saturation:Phi_c>=0", true;
    /// W_c >= 1e-4 kg/s active (item 28).
    WcMin = 15, "saturation:W_c>=1e-4", true;
    /// eta_c >= 0.2 active (item 29).
    EtaCMin = 16, "saturation:eta_c>=0.2", true;
    /// Pi_t <= 0.9999 active (item 31).
    PiTMax = 17, "saturation:Pi_t<=0.9999", true;
    /// BSR limited to [0, 2 BSR_opt] (item 32).
    BsrRange = 18, "saturation:BSR in [0,2*BSR_opt]", true;
    /// eta_tm limited to [0.2, 1] (item 34).
    EtaTmRange = 19, "saturation:eta_tm in [0.2,1]", true;
    /// f_vgt >= 0 active (item 35).
    FVgtMin = 20, "saturation:f_vgt>=0", true;
    /// x_egr <= 0.9 active (item 13, output only).
    XEgrMax = 21, "saturation:x_egr<=0.9", false;
    /// EGR flow choked: p_im/p_em < Pi_egropt (eq. (35)).
    EgrChoked = 22, "regime:egr_choked", false;
    /// No EGR flow: p_im >= p_em (eq. (35)).
    EgrNoFlow = 23, "regime:egr_no_flow(Pi_egr=1)", false;
    /// c_m on the authors' linear branch below w_tlin (item 33).
    CmLinear = 24, "regime:c_m_linear_branch", false;
    /// Compressor ellipse outside its range: max(0, .) in eq. (71) active.
    PhiEllipse = 25, "regime:compressor_ellipse_clamped(eq.71)", false;
    /// The converged cylinder-out temperature fixed point did not reach its tolerance.
    FixedPointNotConverged = 26, "cylinder_temp_fixed_point_not_converged", true;
}

impl Signals {
    /// Whether `g` is active in this evaluation.
    pub fn has(&self, g: Guard) -> bool {
        self.guards & (g as u32) != 0
    }

    /// Labels of all active guards and regimes.
    pub fn guard_labels(&self) -> Vec<&'static str> {
        Guard::ALL
            .iter()
            .filter(|g| self.has(**g))
            .map(|g| g.label())
            .collect()
    }
}
