//! Baseline controllers: the EGR/VGT air-path controller, the torque-following engine controller
//! with a smoke limiter, and the open-loop schedule for comparison.
//!
//! ## Air path (after Wahlström, Eriksson, Nielsen, IEEE TCST 18(4), 2010)
//!
//! The authors control the oxygen/fuel ratio lambda_O with the EGR valve and the EGR fraction
//! x_egr with the VGT (so the sign reversal of u_vgt -> lambda_O / W_c that the paper documents
//! in section 8.3.1 is not inside a loop that needs its sign), with PID controllers combined by
//! min/max selectors, lambda_O,s acting as a lower bound (smoke) and the VGT as open as the
//! set-points allow (pumping work). Implemented here, every 10 ms, with `L = u_delta / u_full(n_e)`:
//!
//! - x_egr on the VGT (main loop): PI on `x_egr - x_egr,s` gives `u_vgt,x` (too little EGR
//!   closes the VGT, raising p_em and the EGR flow).
//! - lambda_O on the EGR valve (main loop): PI on `lambda_O - lambda_O,s` gives `u_egr,lambda`
//!   (air to spare opens the valve: the valve goes as far open as lambda_O,s allows, which lets
//!   the x_egr loop open the VGT, the pumping-work direction).
//! - x_egr on the EGR valve (limiter): PI on `x_egr,s + d_x - x_egr` gives `u_egr,x`; min
//!   selector `u_egr = min(u_egr,lambda, u_egr,x)`: the valve closes when there is too much EGR
//!   even with the VGT at its most open position.
//! - lambda_O on the VGT (limiter): PI on `lambda_O - (lambda_O,s - d_lambda)` gives
//!   `u_vgt,lambda`; `u_vgt = min(u_vgt,x, u_vgt,lambda)` limited to [20, u_vgt,max(L)]: the VGT
//!   closes for air only when closing the EGR valve was not enough (high load, where closing the
//!   VGT raises the boost).
//! - Anti-windup: each PI tracks the applied command when it did not give it ([`Pid`]).
//!   Optionally (`vgt_release_below_egr`, off by default) the x_egr loop leaves the VGT's
//!   selector while the EGR valve is commanded shut, where it has no authority over x_egr
//!   (session 41: conditional integration; the lambda_O limiter alone closes the VGT there).
//!   Optionally (`vgt_release_motored_band`, off by default) the same while the engine is
//!   motored with p_em <= p_im, where no EGR can flow (session 42).
//! - Exhaust back-pressure limit (session 41): above `p_em - p_im = dp_vgt_limit` a PI on the
//!   excess opens the VGT through a max selector over both VGT loops
//!   (`u_vgt = max(min(u_vgt,x, u_vgt,lambda), u_vgt,dp)`), the closed end the engine's
//!   pressures set where the VGT's command range reaches beyond the VGT area map's
//!   ([`BaselineTuning::dp_vgt_limit`], [`DpLimitLog`]).
//! - Set-point pairs out of reach (session 39): where no steady state within the actuator
//!   ranges gives a map cell's lambda_O,s and x_egr,s together, the cell's nominal valve
//!   position is a third set-point, `u_egr,lambda <= u_egr,max(n_e, L)`
//!   ([`SetpointMaps::u_egr_max`], [`SetpointMaps::adjusted`]); a command wound to the end of
//!   its range by one loop is recorded ([`WindupEvent`]) and reported as a warning.
//!
//! Measured signals: lambda_O and x_egr (in an engine: estimates from the air mass flow sensor,
//! p_im, n_e and u_delta; here the model's own values, i.e. perfect estimates), u_delta and n_e.
//!
//! ## Engine
//!
//! `u_delta = u_ff(n_e, M_ref) + PI(M_ref,prev - M_e)` with `u_ff` the inverse of the model's
//! steady torque map at the nominal actuator positions, M_e from the dynamometer's torque sensor
//! (the answer to the previous fuel command) and M_ref,prev the previous sample's demand (the
//! one that command was given for: a step of the demand is the feed-forward's alone); a smoke
//! limiter caps it at `u_delta lambda_O / (lambda_lim (1 + margin))` (lambda_O is inversely
//! proportional to the fuel at a given air charge, eq. (15)), so lambda_O stays above
//! lambda_lim (1.2) during turbo lag; motoring points get the minimum fuel.

use super::cycle::{interp, steady_signals, MappingCurve};
use super::pid::Pid;
use super::{ControlError, Controller, InCharge, Measurement, Output};
use crate::model::meta::VarMeta;
use crate::model::{AnyModel, Drive};
use crate::numerics::Num;
use crate::sim::InputSchedule;

/// Tuning of the baseline controllers (see the module documentation and `docs/control.md`).
///
/// Read from a TOML file by `mvem closed-loop --tuning FILE` (every field optional, the
/// defaults below for the rest; unknown keys refused; PI gains as `[kp, ki]`), checked by
/// [`BaselineTuning::validate`]. The sample time is the closed loop's 10 ms and not read.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BaselineTuning {
    /// Sample time \[s\].
    #[serde(skip)]
    pub ts: f64,
    /// Smoke limit lambda_lim [-].
    pub lambda_limit: f64,
    /// Margin of the smoke limiter over lambda_lim [-] (relative).
    pub smoke_margin: f64,
    /// Torque PI (kp [mg/Nm], ki [mg/(Nm s)]).
    #[serde(deserialize_with = "pi_pair")]
    pub torque: (f64, f64),
    /// x_egr PI on the VGT (kp [%], ki [%/s] per unit x_egr).
    #[serde(deserialize_with = "pi_pair")]
    pub x_egr_vgt: (f64, f64),
    /// x_egr PI on the EGR valve (limiter; kp [%], ki [%/s] per unit x_egr).
    #[serde(deserialize_with = "pi_pair")]
    pub x_egr_egr: (f64, f64),
    /// Band d_x of the EGR valve's x_egr limiter above the set-point [-].
    pub d_x: f64,
    /// lambda_O PI on the EGR valve (kp [%], ki [%/s] per unit lambda_O).
    #[serde(deserialize_with = "pi_pair")]
    pub lambda_egr: (f64, f64),
    /// lambda_O PI on the VGT (kp [%], ki [%/s] per unit lambda_O).
    #[serde(deserialize_with = "pi_pair")]
    pub lambda_vgt: (f64, f64),
    /// Offset d_lambda of the VGT's lambda_O loop below the set-point [-].
    pub d_lambda: f64,
    /// Upper limit of the lambda_O errors of both lambda_O loops [-] (lambda_O,s is a lower
    /// bound: air beyond it says nothing about how far to move; see the module documentation).
    pub lambda_error_cap: f64,
    /// Most open VGT position at full load [%] (the mapping curve's), 100 % at no load.
    pub u_vgt_full_load: f64,
    /// Gain factor of both VGT loops (x_egr -> u_vgt, lambda_O -> u_vgt) at the closed end of
    /// the VGT (u_vgt = 20 %) [-]: the gains are scheduled on the previous VGT command, linearly
    /// from this factor at 20 % to 1 at [`Self::vgt_gain_knee`] and above (1: no schedule). The
    /// VGT's gain to x_egr and lambda_O grows as it closes (docs/control.md, "Gain scheduling
    /// of the VGT loops").
    pub vgt_gain_closed: f64,
    /// VGT command from which the VGT loops have their full gains [%] (see
    /// [`Self::vgt_gain_closed`]).
    pub vgt_gain_knee: f64,
    /// Gain factor of both EGR-valve loops (lambda_O -> u_egr, x_egr -> u_egr) at the closed
    /// valve (u_egr = 0 %) [-]: the gains are scheduled on the previous EGR command, linearly
    /// from this factor at 0 % to 1 at [`Self::egr_gain_knee`] and above (1: no schedule, the
    /// default). On the WHTC 0.5 calms both commands but does not make the loops stable at more
    /// samples (docs/control.md, "Gain scheduling of the EGR-valve loops").
    pub egr_gain_closed: f64,
    /// EGR command from which the EGR-valve loops have their full gains [%] (see
    /// [`Self::egr_gain_closed`]).
    pub egr_gain_knee: f64,
    /// EGR command [%] below which the x_egr -> u_vgt loop may not close the VGT while the
    /// lambda_O loop gives the valve's command (0: never, the default). There the valve is
    /// being shut for air (smoke before NOx), x_egr,s is out of reach, and the two main loops
    /// interact so strongly (relative gain of the pairing 0.007-0.25 at the WHTC's fast
    /// instabilities) that they destabilize each other; the VGT is held (or opened by the
    /// x_egr loop, or closed by the lambda_O -> u_vgt limiter) instead (docs/control.md,
    /// "Session 38").
    pub vgt_hold_below_egr: f64,
    /// How far [%] the lambda_O loop may open the EGR valve beyond the valve's position
    /// set-point of a set-point cell whose pair is out of reach ([`SetpointMaps::adjusted`]):
    /// 0 holds the valve at the cell's nominal position (the default since session 39), 100
    /// lets it open without limit (the behaviour before: the valve winds open at a few %/s
    /// while neither valve loop's error changes sign). No effect where the pair is reachable.
    pub egr_open_beyond_setpoint: f64,
    /// Largest exhaust back-pressure p_em - p_im \[kPa\] the VGT loops may close the VGT into:
    /// above it a limiter ([`Self::dp_vgt`]) opens the VGT through a max selector over both VGT
    /// loops (session 41). The closed end of the VGT's command range is the model's (the
    /// parameter set's `input_saturation.u_vgt`); this is the closed end the engine's pressures
    /// set, whatever that range (docs/control.md, "Session 41").
    pub dp_vgt_limit: f64,
    /// PI of the exhaust back-pressure limiter on the VGT (kp [%/kPa], ki [%/(kPa s)] per kPa
    /// of p_em - p_im above [`Self::dp_vgt_limit`]); acts only above the limit.
    #[serde(deserialize_with = "pi_pair")]
    pub dp_vgt: (f64, f64),
    /// EGR command [%] below which the x_egr -> u_vgt loop leaves the VGT's selector (0: never,
    /// the default; 0.5 if on). With the valve shut the VGT has no authority over x_egr, and the
    /// VGT is left to the lambda_O limiter (session 41's conditional integration; on the default
    /// WHTC less pumping work but a larger x_egr error, docs/control.md, "Session 41"). A
    /// threshold at the valve's very end (0.01) lets the valve's first creep off it hand the VGT
    /// back to the x_egr loop next to the shut valve, session 38's unstable pair (WHTC 480 s);
    /// 0.5 covers that creep (docs/control.md, "Session 42").
    pub vgt_release_below_egr: f64,
    /// Hysteresis band \[kPa\] of the x_egr -> u_vgt loop's release while the engine is
    /// motored and its exhaust back-pressure cannot drive EGR (0: off, the default; session
    /// 42). While the fuel is at its minimum (motoring, or a tip-out's fuel cut) and p_em <=
    /// p_im no EGR flows (eqs (32), (35): no flow without a positive pressure difference) and
    /// closing the VGT cannot make the exhaust outpush the boost of the spinning turbo, so the
    /// loop leaves the VGT's min selector as with [`Self::vgt_release_below_egr`] (its PI
    /// tracks the applied command); it comes back, without a bump, once the engine is fired or
    /// p_em - p_im exceeds this band. Fired, the loop keeps the VGT even with p_em <= p_im:
    /// there closing the VGT is what raises p_em above p_im (released, the loop would leave
    /// x_egr at 0 for good at e.g. 1000 rpm / 157 mg; docs/control.md, "Session 42").
    pub vgt_release_motored_band: f64,
}

/// A PI gain pair `[kp, ki]`: exactly two numbers (a TOML array of three is refused, as
/// serde's tuple would silently drop the rest).
fn pi_pair<'de, D: serde::Deserializer<'de>>(d: D) -> Result<(f64, f64), D::Error> {
    use serde::de::Error;
    let v = <Vec<f64> as serde::Deserialize>::deserialize(d)?;
    match v[..] {
        [kp, ki] => Ok((kp, ki)),
        _ => Err(D::Error::invalid_length(
            v.len(),
            &"a PI gain pair [kp, ki] of two numbers",
        )),
    }
}

impl Default for BaselineTuning {
    fn default() -> Self {
        Self {
            ts: 0.01,
            lambda_limit: 1.2,
            smoke_margin: 0.02,
            torque: (0.02, 2.0),
            x_egr_vgt: (150.0, 800.0),
            x_egr_egr: (50.0, 300.0),
            d_x: 0.02,
            lambda_egr: (40.0, 60.0),
            lambda_vgt: (20.0, 60.0),
            d_lambda: 0.05,
            lambda_error_cap: 1.0,
            u_vgt_full_load: 35.0,
            vgt_gain_closed: 0.5,
            vgt_gain_knee: 40.0,
            egr_gain_closed: 1.0,
            egr_gain_knee: 10.0,
            vgt_hold_below_egr: 0.0,
            egr_open_beyond_setpoint: 0.0,
            dp_vgt_limit: DP_VGT_LIMIT_DEFAULT,
            dp_vgt: (0.1, 1.0),
            vgt_release_below_egr: 0.0,
            vgt_release_motored_band: 0.0,
        }
    }
}

impl BaselineTuning {
    /// The default tuning without gain schedules (`vgt_gain_closed = egr_gain_closed = 1`):
    /// the default until session 37 (which made the VGT loops' schedule the default), with which
    /// the figures measured then are reproduced.
    pub fn unscheduled() -> Self {
        Self {
            vgt_gain_closed: 1.0,
            egr_gain_closed: 1.0,
            ..Self::default()
        }
    }

    /// Largest PI gain accepted (kp or ki, in the gain's unit): a million times the defaults'
    /// order keeps every product of a gain and an error finite.
    pub const GAIN_MAX: f64 = 1e6;

    /// Name, unit and description of every field a user sets (all but the sample time `ts`),
    /// in declaration order: the explorer's tuning form and other front ends read them here. A
    /// PI pair's unit is that of kp, then of ki; its value is `[kp, ki]`.
    pub const FIELDS: [VarMeta; 21] = [
        VarMeta {
            name: "lambda_limit",
            unit: "-",
            description:
                "smoke limit lambda_lim: the torque controller's fuel keeps lambda_O above it",
        },
        VarMeta {
            name: "smoke_margin",
            unit: "-",
            description: "margin of the smoke limiter over lambda_lim (relative)",
        },
        VarMeta {
            name: "torque",
            unit: "mg/Nm, mg/(Nm s)",
            description: "torque PI [kp, ki] on the fuel, around the inverse torque map",
        },
        VarMeta {
            name: "x_egr_vgt",
            unit: "%, %/s",
            description: "x_egr PI [kp, ki] on the VGT (per unit x_egr)",
        },
        VarMeta {
            name: "x_egr_egr",
            unit: "%, %/s",
            description: "x_egr PI [kp, ki] on the EGR valve, the limiter above x_egr,s + d_x",
        },
        VarMeta {
            name: "d_x",
            unit: "-",
            description: "band d_x of the EGR valve's x_egr limiter above the set-point",
        },
        VarMeta {
            name: "lambda_egr",
            unit: "%, %/s",
            description: "lambda_O PI [kp, ki] on the EGR valve (per unit lambda_O)",
        },
        VarMeta {
            name: "lambda_vgt",
            unit: "%, %/s",
            description: "lambda_O PI [kp, ki] on the VGT (per unit lambda_O)",
        },
        VarMeta {
            name: "d_lambda",
            unit: "-",
            description: "offset d_lambda of the VGT's lambda_O loop below the set-point",
        },
        VarMeta {
            name: "lambda_error_cap",
            unit: "-",
            description: "upper limit of the lambda_O errors of both lambda_O loops",
        },
        VarMeta {
            name: "u_vgt_full_load",
            unit: "%",
            description: "most open VGT position at full load (the open end of the VGT's \
                          command range input_saturation.u_vgt at no load)",
        },
        VarMeta {
            name: "vgt_gain_closed",
            unit: "-",
            description: "gain factor of both VGT loops at the VGT's closed end (the lower end \
                          of input_saturation.u_vgt, the authors' 20 %; scheduled on the VGT \
                          command, linear up to the knee; 1: no schedule)",
        },
        VarMeta {
            name: "vgt_gain_knee",
            unit: "%",
            description: "VGT command from which the VGT loops have their full gains",
        },
        VarMeta {
            name: "egr_gain_closed",
            unit: "-",
            description: "gain factor of both EGR-valve loops at the valve's closed end (the \
                          lower end of input_saturation.u_egr, the authors' 0 %; scheduled on \
                          the EGR command, linear up to the knee; 1: no schedule)",
        },
        VarMeta {
            name: "egr_gain_knee",
            unit: "%",
            description: "EGR command from which the EGR-valve loops have their full gains",
        },
        VarMeta {
            name: "vgt_hold_below_egr",
            unit: "%",
            description: "EGR command below which the x_egr loop may not close the VGT while \
                          the lambda_O loop gives the valve's command (0: never)",
        },
        VarMeta {
            name: "egr_open_beyond_setpoint",
            unit: "%",
            description: "how far the lambda_O loop may open the EGR valve beyond its position \
                          set-point where the set-point pair is out of reach (0: holds it; 100: \
                          no limit)",
        },
        VarMeta {
            name: "dp_vgt_limit",
            unit: "kPa",
            description: "largest exhaust back-pressure p_em - p_im the VGT loops may close the \
                          VGT into (above it a limiter opens the VGT)",
        },
        VarMeta {
            name: "dp_vgt",
            unit: "%/kPa, %/(kPa s)",
            description: "PI [kp, ki] of the back-pressure limiter on the VGT (per kPa of p_em - \
                          p_im above dp_vgt_limit)",
        },
        VarMeta {
            name: "vgt_release_below_egr",
            unit: "%",
            description: "EGR command below which the x_egr loop leaves the VGT to the lambda_O \
                          limiter (no EGR to act on; 0: never)",
        },
        VarMeta {
            name: "vgt_release_motored_band",
            unit: "kPa",
            description: "while the engine is motored (fuel at its minimum) and p_em <= p_im (no \
                          EGR flow possible) the x_egr loop leaves the VGT to the lambda_O \
                          limiter; it returns once fired or p_em - p_im exceeds this band (0: \
                          never leaves)",
        },
    ];

    /// The interval each field of [`Self::FIELDS`] must lie in, in the same order (a PI pair's
    /// kp and ki each): what [`Self::validate`] checks besides the set-point floor, and what
    /// front ends show next to the field (the explorer's tuning form, from `/api/models`).
    pub const BOUNDS: [(&'static str, Bounds); 21] = [
        (
            "lambda_limit",
            Bounds::closed(
                1.0,
                5.0,
                " (below 1: richer than stoichiometric; above 5: no fuel left)",
            ),
        ),
        (
            "smoke_margin",
            Bounds {
                hi_open: true,
                ..Bounds::closed(0.0, 1.0, "")
            },
        ),
        ("torque", Bounds::closed(0.0, Self::GAIN_MAX, "")),
        ("x_egr_vgt", Bounds::closed(0.0, Self::GAIN_MAX, "")),
        ("x_egr_egr", Bounds::closed(0.0, Self::GAIN_MAX, "")),
        (
            "d_x",
            Bounds::closed(0.0, 1.0, " (a band of the EGR fraction)"),
        ),
        ("lambda_egr", Bounds::closed(0.0, Self::GAIN_MAX, "")),
        ("lambda_vgt", Bounds::closed(0.0, Self::GAIN_MAX, "")),
        ("d_lambda", Bounds::closed(0.0, 10.0, "")),
        (
            "lambda_error_cap",
            Bounds {
                lo_open: true,
                ..Bounds::closed(0.0, 10.0, "")
            },
        ),
        (
            "u_vgt_full_load",
            Bounds::closed(
                0.0,
                100.0,
                " % (a VGT position, inside the VGT's command range input_saturation.u_vgt)",
            ),
        ),
        (
            "vgt_gain_closed",
            Bounds {
                lo_open: true,
                ..Bounds::closed(0.0, 10.0, " (a factor on the VGT loops' gains)")
            },
        ),
        (
            "vgt_gain_knee",
            Bounds {
                lo_open: true,
                ..Bounds::closed(
                    0.0,
                    100.0,
                    " % (a VGT position; no schedule at or below the VGT's closed end)",
                )
            },
        ),
        (
            "egr_gain_closed",
            Bounds {
                lo_open: true,
                ..Bounds::closed(0.0, 10.0, " (a factor on the EGR-valve loops' gains)")
            },
        ),
        (
            "egr_gain_knee",
            Bounds {
                lo_open: true,
                ..Bounds::closed(
                    0.0,
                    100.0,
                    " % (an EGR-valve position; no schedule at or below the closed end)",
                )
            },
        ),
        (
            "vgt_hold_below_egr",
            Bounds::closed(0.0, 100.0, " % (the EGR valve's command range)"),
        ),
        (
            "egr_open_beyond_setpoint",
            Bounds::closed(0.0, 100.0, " % (the EGR valve's command range)"),
        ),
        (
            "dp_vgt_limit",
            Bounds {
                lo_open: true,
                ..Bounds::closed(0.0, 1e4, " kPa (a pressure difference)")
            },
        ),
        ("dp_vgt", Bounds::closed(0.0, Self::GAIN_MAX, "")),
        (
            "vgt_release_below_egr",
            Bounds::closed(0.0, 100.0, " % (the EGR valve's command range)"),
        ),
        (
            "vgt_release_motored_band",
            Bounds::closed(0.0, 1e3, " kPa (a pressure difference)"),
        ),
    ];

    /// The values of the fields of [`Self::FIELDS`], in its order: one, or a PI pair's two.
    fn field_values(&self) -> [(&'static str, [f64; 2], usize); 21] {
        [
            ("lambda_limit", [self.lambda_limit, 0.0], 1),
            ("smoke_margin", [self.smoke_margin, 0.0], 1),
            ("torque", [self.torque.0, self.torque.1], 2),
            ("x_egr_vgt", [self.x_egr_vgt.0, self.x_egr_vgt.1], 2),
            ("x_egr_egr", [self.x_egr_egr.0, self.x_egr_egr.1], 2),
            ("d_x", [self.d_x, 0.0], 1),
            ("lambda_egr", [self.lambda_egr.0, self.lambda_egr.1], 2),
            ("lambda_vgt", [self.lambda_vgt.0, self.lambda_vgt.1], 2),
            ("d_lambda", [self.d_lambda, 0.0], 1),
            ("lambda_error_cap", [self.lambda_error_cap, 0.0], 1),
            ("u_vgt_full_load", [self.u_vgt_full_load, 0.0], 1),
            ("vgt_gain_closed", [self.vgt_gain_closed, 0.0], 1),
            ("vgt_gain_knee", [self.vgt_gain_knee, 0.0], 1),
            ("egr_gain_closed", [self.egr_gain_closed, 0.0], 1),
            ("egr_gain_knee", [self.egr_gain_knee, 0.0], 1),
            ("vgt_hold_below_egr", [self.vgt_hold_below_egr, 0.0], 1),
            (
                "egr_open_beyond_setpoint",
                [self.egr_open_beyond_setpoint, 0.0],
                1,
            ),
            ("dp_vgt_limit", [self.dp_vgt_limit, 0.0], 1),
            ("dp_vgt", [self.dp_vgt.0, self.dp_vgt.1], 2),
            (
                "vgt_release_below_egr",
                [self.vgt_release_below_egr, 0.0],
                1,
            ),
            (
                "vgt_release_motored_band",
                [self.vgt_release_motored_band, 0.0],
                1,
            ),
        ]
    }

    /// The VGT loops' gain factor at the VGT command `u_vgt` [%] of a VGT whose command range
    /// is `range` [%]: [`Self::vgt_gain_closed`] at its closed end `range.0` and below, 1 at
    /// [`Self::vgt_gain_knee`] and above, linear between (exactly 1 everywhere when
    /// `vgt_gain_closed` is 1, or when the knee is not above the closed end).
    pub fn vgt_gain_factor_in(&self, u_vgt: f64, range: (f64, f64)) -> f64 {
        scheduled_factor(u_vgt, range.0, self.vgt_gain_knee, self.vgt_gain_closed)
    }

    /// The most open EGR-valve position [%] the lambda_O loop may command where the valve's
    /// position set-point is `u_egr_set` [%] ([`SetpointMaps::u_egr_max_at`]: 100 where the
    /// set-point pair is reachable), for a valve whose command range is `range` [%]: the
    /// set-point plus [`Self::egr_open_beyond_setpoint`], within the range.
    pub fn egr_limit_in(&self, u_egr_set: f64, range: (f64, f64)) -> f64 {
        (u_egr_set + self.egr_open_beyond_setpoint).clamp(range.0, range.1)
    }

    /// The EGR-valve loops' gain factor at the EGR command `u_egr` [%] of a valve whose command
    /// range is `range` [%]: [`Self::egr_gain_closed`] at its closed end `range.0` (the
    /// authors' 0 %) and below, 1 at [`Self::egr_gain_knee`] and above, linear between (exactly
    /// 1 everywhere when `egr_gain_closed` is 1, or when the knee is not above the closed end).
    pub fn egr_gain_factor_in(&self, u_egr: f64, range: (f64, f64)) -> f64 {
        scheduled_factor(u_egr, range.0, self.egr_gain_knee, self.egr_gain_closed)
    }

    /// Check every field: finite and in its [`Self::BOUNDS`] (PI gains in [0,
    /// [`Self::GAIN_MAX`]], lambda_lim in [1, 5], the smoke margin in [0, 1), d_x in [0, 1],
    /// d_lambda in [0, 10], the lambda_O error cap in (0, 10], the full-load VGT limit in
    /// [0, 100] % (and inside the engine's VGT range: [`Baseline::new`]), the VGT loops' factor
    /// at the closed end in (0, 10], the knee in (0, 100] %; the EGR-valve loops' factor in
    /// (0, 10], their knee in (0, 100] %; the VGT hold's EGR command in [0, 100] %),
    /// the set-point floor lambda_lim (1 + 2 smoke margin) at most
    /// [`LAMBDA_SETPOINT_MAX`], and the sample time in (0, 1] s. The error names the field (an
    /// element of a pair 1-based: `torque[1]` is the torque PI's kp, `torque[2]` its ki), its
    /// value and the constraint.
    pub fn validate(&self) -> Result<(), ControlError> {
        let bad = |field: &str, v: f64, constraint: String| {
            Err(ControlError::Setup(format!(
                "controller tuning {field} = {}: {constraint}",
                Num(v)
            )))
        };
        if !(self.ts > 0.0 && self.ts <= 1.0) {
            return bad("ts", self.ts, "must be in (0, 1] s".into());
        }
        for ((name, vals, n), (bname, b)) in self.field_values().into_iter().zip(Self::BOUNDS) {
            debug_assert_eq!(name, bname);
            for (k, &v) in vals[..n].iter().enumerate() {
                if !b.contains(v) {
                    // a pair [kp, ki] (or [at 20 %, at 100 %]) named 1-based, as every element
                    // name the user sees ([`crate::params::element_name`]): torque[1] is kp
                    let field = if n == 2 {
                        crate::params::element_name(name, &[k])
                    } else {
                        name.to_string()
                    };
                    return bad(&field, v, format!("must be in {}{}", b.interval(), b.note));
                }
            }
        }
        let floor = self.lambda_limit * (1.0 + 2.0 * self.smoke_margin);
        if floor > LAMBDA_SETPOINT_MAX {
            return Err(ControlError::Setup(format!(
                "controller tuning lambda_limit = {} with smoke_margin = {}: the lambda_O \
                 set-point floor lambda_limit (1 + 2 smoke_margin) = {} must be at most \
                 {LAMBDA_SETPOINT_MAX} (the set-point maps' cap)",
                Num(self.lambda_limit),
                Num(self.smoke_margin),
                Num(floor)
            )));
        }
        Ok(())
    }
}

/// A gain factor scheduled on a command `u` [%]: `at_closed` at the closed end `closed` and
/// below, 1 at `knee` and above, linear between.
fn scheduled_factor(u: f64, closed: f64, knee: f64, at_closed: f64) -> f64 {
    if knee <= closed {
        // (every command at or above the closed end is at or above the knee)
        return 1.0;
    }
    let w = ((knee - u) / (knee - closed)).clamp(0.0, 1.0);
    1.0 - (1.0 - at_closed) * w
}

/// The interval a tuning value must lie in: from `lo` to `hi`, each end included unless marked
/// open (NaN and infinities are never in it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Bounds {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    /// Whether `lo` itself is excluded.
    pub lo_open: bool,
    /// Whether `hi` itself is excluded.
    pub hi_open: bool,
    /// What the error message adds after the interval (a unit, a reason), or "".
    #[serde(skip)]
    pub note: &'static str,
}

impl Bounds {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64, note: &'static str) -> Self {
        Self {
            lo,
            hi,
            lo_open: false,
            hi_open: false,
            note,
        }
    }

    /// Whether `v` lies in the interval.
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && (if self.lo_open {
                v > self.lo
            } else {
                v >= self.lo
            })
            && (if self.hi_open {
                v < self.hi
            } else {
                v <= self.hi
            })
    }

    /// The interval in the usual notation: `[0, 1)`, `(0, 10]`, `[0, 1e6]` (ends from 1e4 on in
    /// scientific notation).
    pub fn interval(&self) -> String {
        let end = |v: f64| {
            if v.abs() >= 1e4 {
                format!("{v:e}")
            } else {
                Num(v).to_string()
            }
        };
        format!(
            "{}{}, {}{}",
            if self.lo_open { "(" } else { "[" },
            end(self.lo),
            end(self.hi),
            if self.hi_open { ")" } else { "]" }
        )
    }
}

/// Default of [`BaselineTuning::dp_vgt_limit`] \[kPa\]: above the largest p_em - p_im of the
/// published engine's closed-loop WHTC and tip-ins with the authors' VGT range (measured in
/// docs/control.md, "Session 41"), so it only acts where the VGT closes beyond that.
pub const DP_VGT_LIMIT_DEFAULT: f64 = 350.0;

/// Upper bound of the lambda_O set-point maps [-] (lean enough for every part load).
pub const LAMBDA_SETPOINT_MAX: f64 = 10.0;

/// Nominal actuator map: EGR valve and VGT positions [%] at load fraction `l` in [0, 1] (the
/// open-loop schedule of the shared WHTC inputs: u_egr = 50 (1 - L), u_vgt = 65 - 30 L).
pub fn nominal_actuators(l: f64) -> (f64, f64) {
    let l = l.clamp(0.0, 1.0);
    (50.0 * (1.0 - l), 65.0 - 30.0 * l)
}

/// Steady maps over (n_e, load fraction) at the nominal actuator positions: torque (for the
/// feed-forward inverse) and the set-points lambda_O,s and x_egr,s.
#[derive(Debug, Clone, PartialEq)]
pub struct SetpointMaps {
    /// Speeds \[rpm\].
    pub n_e: Vec<f64>,
    /// Load fractions L = (u_delta - 1) / (u_full - 1) [-].
    pub load: Vec<f64>,
    /// Steady torque \[Nm\], `[speed][load]`.
    pub m_e: Vec<Vec<f64>>,
    /// lambda_O set-point [-], `[speed][load]`.
    pub lambda_o: Vec<Vec<f64>>,
    /// x_egr set-point [-], `[speed][load]`.
    pub x_egr: Vec<Vec<f64>>,
    /// Full-load fuel over `n_e` \[mg\].
    pub u_full: Vec<f64>,
    /// Fuel range of the model's input saturation (the mapping curve's) \[mg\]: motoring fuel
    /// and the largest fuel.
    pub u_delta_range: (f64, f64),
    /// Command range of the VGT \[%\] (the model's saturation of the command, the parameter
    /// set's `input_saturation.u_vgt`, by default the authors' [`crate::model::U_VGT_RANGE`]):
    /// the closed end, where the controller's VGT command stops and the VGT loops' gain
    /// schedule has its closed-end factor, and the open end, the most open position at no
    /// load. The one place the baseline takes it from.
    pub u_vgt_range: (f64, f64),
    /// Command range of the EGR valve \[%\] (the parameter set's `input_saturation.u_egr`, by
    /// default the authors' [`crate::model::U_EGR_RANGE`]): the controller's EGR command stays
    /// in it, the EGR-valve loops' gain schedule has its closed-end factor at its lower end.
    pub u_egr_range: (f64, f64),
    /// Most open EGR valve position the lambda_O loop may command [%], `[speed][load]`: 100
    /// (no limit) where the cell's set-point pair is reachable, the cell's nominal valve
    /// position where it is not (the valve's position as a third set-point there, see
    /// [`SetpointMaps::adjusted`]).
    pub u_egr_max: Vec<Vec<f64>>,
    /// The cells whose set-point pair the actuators cannot reach together, with what was
    /// adjusted (empty when every pair is reachable).
    pub adjusted: Vec<AdjustedCell>,
}

/// A set-point map cell whose pair (lambda_O,s, x_egr,s) no steady state within the actuator
/// ranges reaches together ([`SetpointMaps::compute`]), and the valve position set there.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AdjustedCell {
    /// Speed \[rpm\].
    pub n_e: f64,
    /// Load fraction [-].
    pub load: f64,
    /// Fuel u_delta \[mg\].
    pub u_delta: f64,
    /// The cell's set-points lambda_O,s [-] and x_egr,s [-] (unchanged).
    pub lambda_o_s: f64,
    /// x_egr set-point [-].
    pub x_egr_s: f64,
    /// The lowest lambda_O [-] the valve reaches with x_egr held at x_egr,s (the VGT
    /// within its range), above lambda_O,s; NaN where x_egr,s itself is out of reach.
    pub lambda_o_reached: f64,
    /// The largest x_egr [-] the actuators give (valve open, VGT at its closed end).
    pub x_egr_max: f64,
    /// The valve's position set-point there [%] (the cell's nominal position).
    pub u_egr_max: f64,
    /// The most open position [%] the lambda_O loop may command there, instead of the range's
    /// open end: the set-point plus the tuning's [`BaselineTuning::egr_open_beyond_setpoint`],
    /// within the valve's command range ([`BaselineTuning::egr_limit_in`]; the controller's
    /// tuning: [`Baseline::with_maps`] sets it).
    pub u_egr_limit: f64,
    /// Why the pair is out of reach, in words.
    pub reason: String,
}

impl SetpointMaps {
    /// Solve the steady states on the grid. The lambda_O set-point is a lower bound:
    /// 0.9 of the nominal steady lambda_O, at least lambda_lim (1 + 2 margin).
    pub fn compute(
        model: &AnyModel,
        curve: &MappingCurve,
        tuning: &BaselineTuning,
    ) -> Result<Self, ControlError> {
        // seven speeds over the engine's range (500, 750, ..., 2000 rpm for the authors')
        let (lo, hi) = curve.n_e_range();
        let n_e: Vec<f64> = (0..7).map(|i| lo + (hi - lo) * i as f64 / 6.0).collect();
        let u_min = curve.u_delta_min();
        let load = vec![0.0, 0.1, 0.25, 0.5, 0.75, 1.0];
        let floor = tuning.lambda_limit * (1.0 + 2.0 * tuning.smoke_margin);
        // the engine's command ranges (its parameter set's, whatever the semantics: the
        // controller commands a real actuator's range)
        let limits = &model.params().input_saturation;
        let mut maps = SetpointMaps {
            u_full: n_e.iter().map(|&n| curve.u_full_at(n)).collect(),
            u_delta_range: curve.u_delta_range,
            u_vgt_range: limits.vgt(),
            u_egr_range: limits.egr(),
            n_e,
            load,
            m_e: vec![],
            lambda_o: vec![],
            x_egr: vec![],
            u_egr_max: vec![],
            adjusted: vec![],
        };
        for (i, &n) in maps.n_e.iter().enumerate() {
            let (mut m_row, mut l_row, mut x_row) = (vec![], vec![], vec![]);
            let mut cap_row = vec![];
            let mut guess = None;
            for &l in &maps.load {
                let u = u_min + l * (maps.u_full[i] - u_min);
                let (ue, uv) = nominal_actuators(l);
                let s =
                    steady_signals(model, &Drive::new(n, u, ue, uv), &mut guess).map_err(|e| {
                        ControlError::Setup(format!(
                            "set-point maps at {n} rpm, {u:.1} mg/cycle: {e}"
                        ))
                    })?;
                m_row.push(s.m_e);
                // floor <= LAMBDA_SETPOINT_MAX: checked by BaselineTuning::validate
                let lambda_s = (0.9 * s.lambda_o).clamp(floor, LAMBDA_SETPOINT_MAX);
                l_row.push(lambda_s);
                x_row.push(s.x_egr);
                let vmax = maps.u_vgt_range.1 - (maps.u_vgt_range.1 - tuning.u_vgt_full_load) * l;
                let cell = Cell {
                    n,
                    u,
                    lambda_s,
                    x_s: s.x_egr,
                    d_x: tuning.d_x,
                    vgt: (maps.u_vgt_range.0, vmax),
                    egr: maps.u_egr_range,
                };
                match cell.out_of_reach(model) {
                    Some((lambda_reached, x_max, reason)) => {
                        cap_row.push(ue);
                        maps.adjusted.push(AdjustedCell {
                            n_e: n,
                            load: l,
                            u_delta: u,
                            lambda_o_s: lambda_s,
                            x_egr_s: s.x_egr,
                            lambda_o_reached: lambda_reached,
                            x_egr_max: x_max,
                            u_egr_max: ue,
                            u_egr_limit: tuning.egr_limit_in(ue, maps.u_egr_range),
                            reason,
                        });
                    }
                    None => cap_row.push(100.0),
                }
            }
            maps.u_egr_max.push(cap_row);
            // the torque map must increase with the fuel to be inverted
            for k in 1..m_row.len() {
                if m_row[k] <= m_row[k - 1] {
                    m_row[k] = m_row[k - 1] + 1e-6;
                }
            }
            maps.m_e.push(m_row);
            maps.lambda_o.push(l_row);
            maps.x_egr.push(x_row);
        }
        Ok(maps)
    }

    /// The most open EGR valve position the lambda_O loop may command at (n_e \[rpm\],
    /// u_delta \[mg\]) [%]: [`Self::u_egr_max`] interpolated as the set-points (100 where the
    /// four surrounding cells' pairs are reachable).
    pub fn u_egr_max_at(&self, n: f64, u_delta: f64) -> f64 {
        let l = self.load_of(n, u_delta);
        let c = self.bilinear(&self.u_egr_max, n, l);
        // exactly 100 (no limit) between reachable cells, whatever the rounding of the weights
        if c >= 100.0 - 1e-9 {
            100.0
        } else {
            c
        }
    }

    /// Full-load fuel at `n` \[mg\].
    pub fn u_full_at(&self, n: f64) -> f64 {
        interp(&self.n_e, &self.u_full, n)
    }

    /// Load fraction of `u_delta` at `n`.
    pub fn load_of(&self, n: f64, u_delta: f64) -> f64 {
        let u_min = self.u_delta_range.0;
        ((u_delta - u_min) / (self.u_full_at(n) - u_min)).clamp(0.0, 1.0)
    }

    /// Interval index and weight of `n` on the speed axis (held outside).
    fn speed_weight(&self, n: f64) -> (usize, f64) {
        let ns = &self.n_e;
        let k = ns.len();
        if n <= ns[0] {
            return (0, 0.0);
        }
        if n >= ns[k - 1] {
            return (k - 2, 1.0);
        }
        let i = ns.partition_point(|&v| v <= n).clamp(1, k - 1) - 1;
        (i, (n - ns[i]) / (ns[i + 1] - ns[i]))
    }

    /// `table[speed][load]` at speed `n`, load index `j` (linear in speed).
    fn at_speed(table: &[Vec<f64>], (i, w): (usize, f64), j: usize) -> f64 {
        (1.0 - w) * table[i][j] + w * table[i + 1][j]
    }

    fn bilinear(&self, table: &[Vec<f64>], n: f64, l: f64) -> f64 {
        let sw = self.speed_weight(n);
        let ls = &self.load;
        let j = ls.partition_point(|&v| v <= l).clamp(1, ls.len() - 1) - 1;
        let f = ((l - ls[j]) / (ls[j + 1] - ls[j])).clamp(0.0, 1.0);
        (1.0 - f) * Self::at_speed(table, sw, j) + f * Self::at_speed(table, sw, j + 1)
    }

    /// Set-points (lambda_O,s, x_egr,s) at (n_e \[rpm\], u_delta \[mg\]).
    pub fn setpoints(&self, n: f64, u_delta: f64) -> (f64, f64) {
        let l = self.load_of(n, u_delta);
        (
            self.bilinear(&self.lambda_o, n, l),
            self.bilinear(&self.x_egr, n, l),
        )
    }

    /// Feed-forward fuel for torque `m` at `n`: the inverse of the steady torque map \[mg\]
    /// (linear in the load between grid points; the torque map increases with the load).
    pub fn fuel_for_torque(&self, n: f64, m: f64) -> f64 {
        let sw = self.speed_weight(n);
        let k = self.load.len();
        let m_at = |j: usize| Self::at_speed(&self.m_e, sw, j);
        let l = if m <= m_at(0) {
            self.load[0]
        } else if m >= m_at(k - 1) {
            self.load[k - 1]
        } else {
            let mut j = 0;
            while j + 2 < k && m_at(j + 1) <= m {
                j += 1;
            }
            let (m0, m1) = (m_at(j), m_at(j + 1));
            self.load[j] + (self.load[j + 1] - self.load[j]) * (m - m0) / (m1 - m0)
        };
        let u_min = self.u_delta_range.0;
        u_min + l * (self.u_full_at(n) - u_min)
    }
}

/// A set-point map cell under test: speed \[rpm\], fuel \[mg\], the set-point pair, the
/// VGT's range there (closed end, most open position at the cell's load) \[%\] and the EGR
/// valve's command range \[%\].
struct Cell {
    n: f64,
    u: f64,
    lambda_s: f64,
    x_s: f64,
    /// The band of the valve's x_egr limiter above x_egr,s [-].
    d_x: f64,
    vgt: (f64, f64),
    egr: (f64, f64),
}

/// Bisection steps of the reachability test along the VGT (of its 80 % range: 0.3 %).
const REACH_STEPS: usize = 8;
/// Intervals of the reachability test's scan of the EGR valve (12.5 % apart).
const REACH_SCAN: usize = 8;

impl Cell {
    /// Whether the pair (lambda_O,s, x_egr,s) is out of reach of the steady states within the
    /// actuator ranges: `Some((the lambda_O nearest lambda_O,s reached with x_egr at x_egr,s,
    /// the largest x_egr, why))` when it is, `None` when it is reachable (or a steady state was
    /// not found: the cell is left as it is).
    ///
    /// The path the two main loops move along: the EGR valve's position `u_egr` (its lambda_O
    /// loop) with the VGT holding x_egr at x_egr,s (its x_egr loop). On [`REACH_SCAN`] + 1
    /// valve positions from shut to open the VGT position with x_egr = x_egr,s is found by
    /// bisection within its range (x_egr falls as the VGT opens); the pair is reachable when
    /// lambda_O,s lies within the lambda_O of those points (lambda_O is not monotonic along the
    /// path: its extremes are often inside). The cell's own steady state (at the nominal
    /// positions) is on the path.
    fn out_of_reach(&self, model: &AnyModel) -> Option<(f64, f64, String)> {
        let mut guess = None;
        let mut at = |ue: f64, uv: f64| {
            steady_signals(model, &Drive::new(self.n, self.u, ue, uv), &mut guess).ok()
        };
        let (closed, vmax) = self.vgt;
        let (shut, open) = self.egr;
        let x_max = at(open, closed)?.x_egr;
        if x_max < self.x_s - 1e-4 {
            return Some((
                f64::NAN,
                x_max,
                format!(
                    "x_egr,s {:.4} is above the largest x_egr {:.4} (valve open, VGT closed)",
                    self.x_s, x_max
                ),
            ));
        }
        let (mut lo_l, mut hi_l) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..=REACH_SCAN {
            let ue = shut + (open - shut) * k as f64 / REACH_SCAN as f64;
            // x_egr,s within the VGT's range at this valve position?
            let (x_c, x_o) = (at(ue, closed)?, at(ue, vmax)?);
            let l = if x_o.x_egr > self.x_s {
                // the VGT at its most open position: a rest of the loops while the valve's
                // x_egr limiter (x_egr,s + d_x) lets the valve open
                if x_o.x_egr > self.x_s + self.d_x {
                    continue;
                }
                x_o.lambda_o
            } else if x_c.x_egr < self.x_s {
                continue;
            } else {
                let (mut lo, mut hi) = (closed, vmax);
                for _ in 0..REACH_STEPS {
                    let mid = 0.5 * (lo + hi);
                    if at(ue, mid)?.x_egr > self.x_s {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                at(ue, 0.5 * (lo + hi))?.lambda_o
            };
            lo_l = lo_l.min(l);
            hi_l = hi_l.max(l);
            if lo_l <= self.lambda_s && self.lambda_s <= hi_l {
                return None;
            }
        }
        if !lo_l.is_finite() {
            // x_egr,s is reached at no scanned valve position with the VGT in range: leave it
            return None;
        }
        let (near, side) = if lo_l > self.lambda_s {
            (lo_l, "lowest")
        } else {
            (hi_l, "highest")
        };
        Some((
            near,
            x_max,
            format!(
                "with x_egr at x_egr,s {:.4} the {side} lambda_O is {:.3}, lambda_O,s {:.3}",
                self.x_s, near, self.lambda_s
            ),
        ))
    }
}

/// The baseline engine + air-path controller (see the module documentation).
#[derive(Debug, Clone)]
pub struct Baseline {
    /// Tuning.
    pub tuning: BaselineTuning,
    /// Set-point and feed-forward maps.
    pub maps: SetpointMaps,
    torque: Pid,
    x_vgt: Pid,
    x_egr: Pid,
    lambda_egr: Pid,
    lambda_vgt: Pid,
    /// The exhaust back-pressure limiter on the VGT (active only above its limit).
    dp_vgt: Pid,
    /// Set-point overrides (lambda_O,s, x_egr,s) for set-point step tests (NaN: from the maps).
    /// A lambda_O,s override also lifts the map's valve position set-point
    /// ([`SetpointMaps::u_egr_max`]), which belongs to the map's pair.
    pub setpoint_override: (f64, f64),
    /// Hold the fuel at this value instead of following the torque demand (NaN: follow).
    pub fuel_override: f64,
    /// The previous VGT command [%] (the VGT loops' gain schedule's variable).
    u_vgt_prev: f64,
    /// The previous EGR command [%] (the EGR-valve loops' gain schedule's variable).
    u_egr_prev: f64,
    /// Whether the lambda_O loop gave the previous EGR command (won the valve's selector).
    egr_by_lambda_prev: bool,
    /// The EGR command's current run in one direction under one loop (windup watch).
    egr_ramp: Ramp,
    /// The VGT command's (windup watch).
    vgt_ramp: Ramp,
    /// Where the exhaust back-pressure limit gave the VGT command ([`DpLimitLog`]).
    dp_log: DpLimitLog,
    /// Where the applied VGT command left the authors' VGT range ([`VgtBeyondMap`]).
    vgt_beyond: VgtBeyondMap,
    /// Whether the x_egr -> u_vgt loop is out of the VGT's selector because p_em <= p_im
    /// ([`BaselineTuning::vgt_release_motored_band`]; kept until p_em - p_im exceeds the band).
    no_egr_flow: bool,
    /// The torque demand of the previous sample \[Nm\]: the demand the previous fuel command
    /// was given for, which the torque measured now answers (the torque PI's reference;
    /// docs/control.md, "Session 43"); `None` before the first sample.
    m_ref_prev: Option<f64>,
}

/// What the exhaust back-pressure limiter on the VGT ([`BaselineTuning::dp_vgt_limit`]) did
/// during a run: it acts where the VGT loops close the VGT beyond what the engine's pressures
/// allow (a VGT command range beyond the VGT area map's, session 41), which the user should know.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DpLimitLog {
    /// Samples at which the limiter gave the VGT command.
    pub samples: usize,
    /// Times it took the VGT command over from the VGT loops (runs of such samples).
    pub episodes: usize,
    /// Time of the first sample \[s\] (0 while `samples` is 0).
    pub first_t: f64,
    /// The largest p_em - p_im measured at such a sample \[kPa\].
    pub dp_max: f64,
    /// The most closed VGT command the loops had reached when it took over [%].
    pub u_vgt_min: f64,
    /// Whether it gave the previous sample's command.
    active: bool,
}

/// Where the applied VGT command left the authors' VGT command range
/// [`crate::model::U_VGT_RANGE`] (20-100 %), the range of the data the published VGT map (the
/// effective area of eq. (56)) was fitted on: possible only where the parameter set's
/// `input_saturation.u_vgt` reaches beyond it, and worth a warning there, since beyond it the
/// model extrapolates that map (session 42). A parameter set does not record the range its own
/// VGT map was fitted on; the warning names the authors'.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VgtBeyondMap {
    /// Samples at which the VGT command was outside 20-100 %.
    pub samples: usize,
    /// Time of the first \[s\] (0 while `samples` is 0).
    pub first_t: f64,
    /// The VGT command there [%].
    pub first_u: f64,
    /// The most closed VGT command below 20 % [%] (NaN if none).
    pub u_min: f64,
    /// The most open VGT command above 100 % [%] (NaN if none).
    pub u_max: f64,
}

impl VgtBeyondMap {
    /// Record the VGT command `u` [%] applied at `t` \[s\].
    fn record(&mut self, t: f64, u: f64) {
        let (lo, hi) = crate::model::U_VGT_RANGE;
        if (lo..=hi).contains(&u) {
            return;
        }
        if self.samples == 0 {
            *self = Self {
                first_t: t,
                first_u: u,
                u_min: f64::NAN,
                u_max: f64::NAN,
                ..Self::default()
            };
        }
        self.samples += 1;
        if u < lo {
            self.u_min = self.u_min.min(u);
        } else {
            self.u_max = self.u_max.max(u);
        }
    }
}

/// Shortest run of a command in one direction under one loop that counts as winding up to
/// the end of its range \[s\] ([`WindupEvent`]).
pub const WINDUP_MIN_S: f64 = 2.0;
/// Slowest mean rate of such a run [%/s] (a loop's integral winding at several %/s).
pub const WINDUP_MIN_RATE: f64 = 1.0;

/// An air-path command wound to an end of its range by one loop: a run of at least
/// [`WINDUP_MIN_S`] in one direction at a mean rate of at least [`WINDUP_MIN_RATE`], the
/// same loop in feedback all the way. What a set-point pair out of the actuators' reach
/// does (the loop's error keeps its sign until the command saturates).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WindupEvent {
    /// Time the command reached the end of its range \[s\].
    pub t: f64,
    /// The loop that wound it (`lambda_O->u_egr`, `x_egr->u_vgt`, ...).
    pub loop_name: &'static str,
    /// The end it reached [%].
    pub end: f64,
    /// Mean rate of the run [%/s].
    pub rate: f64,
    /// Duration of the run \[s\].
    pub duration: f64,
    /// The set-points (lambda_O,s, x_egr,s) [-] when it reached the end.
    pub setpoints: (f64, f64),
}

impl std::fmt::Display for WindupEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "t = {} s: {} wound its command to {:.1} % at {:.1} %/s over {:.1} s \
             (lambda_O,s {:.3}, x_egr,s {:.4})",
            Num((self.t * 100.0).round() / 100.0),
            self.loop_name,
            self.end,
            self.rate,
            self.duration,
            self.setpoints.0,
            self.setpoints.1
        )
    }
}

/// A command's run in one direction under one loop (see [`WindupEvent`]).
#[derive(Debug, Clone, Default)]
struct Ramp {
    /// Direction (+1 opening, -1 closing; 0: no run).
    dir: f64,
    /// Start time \[s\] and command \[%\].
    t0: f64,
    u0: f64,
    /// The loop in feedback during the run.
    loop_name: &'static str,
    /// The runs that ended at an end of the range.
    events: Vec<WindupEvent>,
}

impl Ramp {
    /// The command went from `u.0` to `u.1` over the sample before `t` (`dt` \[s\]) with
    /// `in_charge` in feedback (`name`), within `range` [%].
    #[allow(clippy::too_many_arguments)]
    fn track(
        &mut self,
        t: f64,
        dt: f64,
        u: (f64, f64),
        range: (f64, f64),
        in_charge: InCharge,
        name: &'static str,
        setpoints: (f64, f64),
    ) {
        let du = u.1 - u.0;
        let dir = if du > 0.0 {
            1.0
        } else if du < 0.0 {
            -1.0
        } else {
            0.0
        };
        let at_end = (dir > 0.0 && u.1 >= range.1) || (dir < 0.0 && u.1 <= range.0);
        if at_end && dir == self.dir {
            // (at the end no loop is in feedback: the run's loop wound it there)
            let duration = t - self.t0;
            let rate = (u.1 - self.u0).abs() / duration;
            if duration >= WINDUP_MIN_S && rate >= WINDUP_MIN_RATE {
                self.events.push(WindupEvent {
                    t,
                    loop_name: self.loop_name,
                    end: u.1,
                    rate,
                    duration,
                    setpoints,
                });
            }
            self.dir = 0.0;
        } else if in_charge == InCharge::None || dir == 0.0 {
            self.dir = 0.0;
        } else if dir != self.dir || name != self.loop_name {
            *self = Self {
                dir,
                t0: t - dt,
                u0: u.0,
                loop_name: name,
                events: std::mem::take(&mut self.events),
            };
        }
    }
}

impl Baseline {
    /// Build for `model` with its mapping curve (solves the set-point maps).
    pub fn new(
        model: &AnyModel,
        curve: &MappingCurve,
        tuning: BaselineTuning,
    ) -> Result<Self, ControlError> {
        tuning.validate()?;
        let (lo, hi) = model.params().input_saturation.vgt();
        if !(lo..=hi).contains(&tuning.u_vgt_full_load) {
            return Err(ControlError::Setup(format!(
                "controller tuning u_vgt_full_load = {}: must be in [{}, {}] % (the VGT's \
                 command range, input_saturation.u_vgt of the parameter set)",
                Num(tuning.u_vgt_full_load),
                Num(lo),
                Num(hi)
            )));
        }
        let maps = SetpointMaps::compute(model, curve, &tuning)?;
        Ok(Self::with_maps(maps, tuning))
    }

    /// Build with set-point maps already solved (`tuning` as [`BaselineTuning::validate`]
    /// accepts it; a full-load VGT limit outside the maps' VGT range acts as its closed end).
    pub fn with_maps(mut maps: SetpointMaps, tuning: BaselineTuning) -> Self {
        // the limits the adjusted cells report are this tuning's
        let range = maps.u_egr_range;
        for c in &mut maps.adjusted {
            c.u_egr_limit = tuning.egr_limit_in(c.u_egr_max, range);
        }
        let u_vgt_open = maps.u_vgt_range.1;
        let u_egr_open = maps.u_egr_range.1;
        Self {
            torque: Pid::new(tuning.torque.0, tuning.torque.1, 0.0),
            x_vgt: Pid::new(tuning.x_egr_vgt.0, tuning.x_egr_vgt.1, 0.0),
            x_egr: Pid::new(tuning.x_egr_egr.0, tuning.x_egr_egr.1, 0.0),
            lambda_egr: Pid::new(tuning.lambda_egr.0, tuning.lambda_egr.1, 0.0),
            lambda_vgt: Pid::new(tuning.lambda_vgt.0, tuning.lambda_vgt.1, 0.0),
            dp_vgt: Pid::new(tuning.dp_vgt.0, tuning.dp_vgt.1, 0.0),
            tuning,
            maps,
            setpoint_override: (f64::NAN, f64::NAN),
            fuel_override: f64::NAN,
            u_vgt_prev: u_vgt_open,
            u_egr_prev: u_egr_open,
            egr_by_lambda_prev: false,
            egr_ramp: Ramp::default(),
            vgt_ramp: Ramp::default(),
            dp_log: DpLimitLog::default(),
            vgt_beyond: VgtBeyondMap::default(),
            no_egr_flow: false,
            m_ref_prev: None,
        }
    }

    /// Where the applied VGT command left the authors' VGT range so far ([`VgtBeyondMap`]).
    pub fn vgt_beyond_map(&self) -> &VgtBeyondMap {
        &self.vgt_beyond
    }

    /// What the exhaust back-pressure limit on the VGT did so far ([`DpLimitLog`]).
    pub fn dp_limit_log(&self) -> &DpLimitLog {
        &self.dp_log
    }

    /// The air-path commands wound to an end of their ranges so far, in time order
    /// ([`WindupEvent`]).
    pub fn windup_events(&self) -> Vec<WindupEvent> {
        let mut v: Vec<WindupEvent> = self
            .egr_ramp
            .events
            .iter()
            .chain(&self.vgt_ramp.events)
            .cloned()
            .collect();
        v.sort_by(|a, b| a.t.total_cmp(&b.t));
        v
    }

    /// Most open VGT position at load fraction `l` [%]: the open end of the VGT's range at no
    /// load, [`BaselineTuning::u_vgt_full_load`] at full load (never below the closed end).
    fn u_vgt_max(&self, l: f64) -> f64 {
        let (closed, open) = self.maps.u_vgt_range;
        (open - (open - self.tuning.u_vgt_full_load) * l).max(closed)
    }

    fn setpoints(&self, n: f64, u_delta: f64) -> (f64, f64) {
        let (l, x) = self.maps.setpoints(n, u_delta);
        let (lo, xo) = self.setpoint_override;
        (
            if lo.is_nan() { l } else { lo },
            if xo.is_nan() { x } else { xo },
        )
    }
}

impl Controller for Baseline {
    fn sample_time(&self) -> f64 {
        self.tuning.ts
    }

    fn start(&mut self, t0: f64, n_e: f64, m_ref: f64, motoring: bool) -> Output {
        let u = if !self.fuel_override.is_nan() {
            self.fuel_override
        } else if motoring {
            self.maps.u_delta_range.0
        } else {
            self.maps.fuel_for_torque(n_e, m_ref)
        };
        let l = self.maps.load_of(n_e, u);
        let (u_egr, u_vgt) = nominal_actuators(l);
        let (egr_lo, egr_hi) = self.maps.u_egr_range;
        let u_egr = u_egr.min(egr_hi).max(egr_lo);
        let u_vgt = u_vgt.min(self.u_vgt_max(l)).max(self.maps.u_vgt_range.0);
        self.torque.reset(0.0);
        self.m_ref_prev = Some(m_ref);
        self.x_vgt.reset(u_vgt);
        self.x_egr.reset(u_egr);
        self.lambda_egr.reset(u_egr);
        self.lambda_vgt.reset(u_vgt);
        self.dp_vgt.reset(u_vgt);
        self.u_vgt_prev = u_vgt;
        self.u_egr_prev = u_egr;
        self.egr_by_lambda_prev = false;
        self.egr_ramp = Ramp::default();
        self.vgt_ramp = Ramp::default();
        self.dp_log = DpLimitLog::default();
        self.no_egr_flow = false;
        self.vgt_beyond = VgtBeyondMap::default();
        self.vgt_beyond.record(t0, u_vgt);
        let (lambda_o_ref, x_egr_ref) = self.setpoints(n_e, u);
        Output {
            u_delta: u,
            u_egr,
            u_vgt,
            lambda_o_ref,
            x_egr_ref,
            egr_loop: None,
            vgt_loop: None,
        }
    }

    fn notes(&self) -> Vec<String> {
        let mut notes = Vec::new();
        let d = &self.dp_log;
        if d.samples > 0 {
            notes.push(format!(
                "the exhaust back-pressure limit (p_em - p_im at most dp_vgt_limit = {} kPa) \
                 opened the VGT {} time(s), the first at t = {} s, over {} sample(s) in all \
                 (p_em - p_im up to {:.0} kPa; the VGT loops had closed it to {:.1} %): the VGT \
                 command range reaches further closed than this engine's pressures allow",
                Num(self.tuning.dp_vgt_limit),
                d.episodes,
                Num((d.first_t * 100.0).round() / 100.0),
                d.samples,
                d.dp_max,
                d.u_vgt_min
            ));
        }
        let v = &self.vgt_beyond;
        if v.samples > 0 {
            let (lo, hi) = crate::model::U_VGT_RANGE;
            let reach = |x: f64, what: &str| {
                if x.is_nan() {
                    String::new()
                } else {
                    format!(", {what} {x:.1} %")
                }
            };
            notes.push(format!(
                "the VGT command left {lo}-{hi} %, the range of the authors' data the published \
                 VGT map (eq. (56)) was fitted on, at t = {} s ({:.1} %), at {} sample(s) in all{}{}: \
                 the model extrapolates its VGT map there (unless this parameter set's map was \
                 fitted on a wider range)",
                Num((v.first_t * 100.0).round() / 100.0),
                v.first_u,
                v.samples,
                reach(v.u_min, "down to"),
                reach(v.u_max, "up to"),
            ));
        }
        let ev = self.windup_events();
        let Some(first) = ev.first() else {
            return notes;
        };
        let more = if ev.len() > 1 {
            format!(
                "; {} more, the last at {}",
                ev.len() - 1,
                ev.last().expect("not empty")
            )
        } else {
            String::new()
        };
        notes.push(format!(
            "{} time(s) an air-path loop wound its actuator to the end of its range (at least \
             {} %/s for at least {} s under one loop: a set-point pair out of reach, or a long \
             transient): {first}{more}",
            ev.len(),
            WINDUP_MIN_RATE,
            WINDUP_MIN_S
        ));
        notes
    }

    fn update(&mut self, m: &Measurement) -> Output {
        let dt = self.tuning.ts;
        let s = m.signals;
        // engine: feed-forward + PI on the torque error, smoke limiter. The torque measured now
        // is the engine's answer to the previous fuel command (M_e follows u_delta within the
        // sample it is held over), which was given for the previous sample's demand: the PI
        // compares the two (the feed-forward answers the demand's change). Against the new
        // demand a step of the demand would read as a torque error for one sample and the PI
        // would fight its own feed-forward: at a fuel cut the fuel went to its minimum, then up
        // to 28 mg when the tracked integral came back (docs/control.md, "Session 43").
        // (before a start: the present demand)
        let e_m = self.m_ref_prev.replace(m.m_ref).unwrap_or(m.m_ref) - s.m_e;
        let u_ff = self.maps.fuel_for_torque(m.n_e, m.m_ref);
        let u_smoke =
            s.u_delta * s.lambda_o / (self.tuning.lambda_limit * (1.0 + self.tuning.smoke_margin));
        let (u_min, u_max) = self.maps.u_delta_range;
        let u_hi = u_max.min(u_smoke).max(u_min);
        let u_delta = if !self.fuel_override.is_nan() {
            self.fuel_override
        } else if m.motoring {
            u_min
        } else {
            (u_ff + self.torque.output(e_m, dt)).clamp(u_min, u_hi)
        };
        self.torque.commit(e_m, dt, u_delta - u_ff);
        // air path
        let (lambda_s, x_s) = self.setpoints(m.n_e, u_delta);
        let l = self.maps.load_of(m.n_e, u_delta);
        let vmax = self.u_vgt_max(l);
        let e_xv = s.x_egr - x_s;
        let e_xe = x_s + self.tuning.d_x - s.x_egr;
        let cap = self.tuning.lambda_error_cap;
        let e_le = (s.lambda_o - lambda_s).min(cap);
        let e_lv = (s.lambda_o - (lambda_s - self.tuning.d_lambda)).min(cap);
        // the gains scheduled on the previous commands (1 without a schedule)
        let closed = self.maps.u_vgt_range.0;
        let g = self
            .tuning
            .vgt_gain_factor_in(self.u_vgt_prev, self.maps.u_vgt_range);
        self.x_vgt.set_scale(g);
        self.lambda_vgt.set_scale(g);
        let (egr_closed, egr_open) = self.maps.u_egr_range;
        let g = self
            .tuning
            .egr_gain_factor_in(self.u_egr_prev, self.maps.u_egr_range);
        self.lambda_egr.set_scale(g);
        self.x_egr.set_scale(g);
        let (u_egr_l, u_egr_x) = (
            self.lambda_egr.output(e_le, dt),
            self.x_egr.output(e_xe, dt),
        );
        // the valve's position set-point of a cell whose pair is out of reach: the lambda_O
        // loop opens the valve no further (the range's open end, no limit, elsewhere)
        // (it belongs to the map's pair: a lambda_O,s override, a pair the user gives, has none)
        let egr_max = if self.setpoint_override.0.is_nan() {
            // (its clamp at the closed end changes no command: u_egr is clamped there below)
            self.tuning.egr_limit_in(
                self.maps.u_egr_max_at(m.n_e, u_delta),
                self.maps.u_egr_range,
            )
        } else {
            egr_open
        };
        let u_egr_lc = u_egr_l.min(egr_max);
        let u_egr = u_egr_lc.min(u_egr_x).clamp(egr_closed, egr_open);
        let (u_vgt_x, u_vgt_l) = (
            self.x_vgt.output(e_xv, dt),
            self.lambda_vgt.output(e_lv, dt),
        );
        // the VGT hold: with the valve nearly shut by the lambda_O loop the x_egr loop may
        // open the VGT but not close it (its command no lower than the previous VGT command)
        let hold = self.egr_by_lambda_prev && self.u_egr_prev < self.tuning.vgt_hold_below_egr;
        let held = hold && u_vgt_x < self.u_vgt_prev;
        let u_vgt_x = if held { self.u_vgt_prev } else { u_vgt_x };
        // conditional integration (session 41, an option): with the valve commanded (nearly)
        // shut the VGT has no authority over x_egr (no EGR flow whatever p_em), so the x_egr
        // loop leaves the VGT's selector (its command the open end; its PI tracks the applied
        // command) and the lambda_O limiter alone closes the VGT for air
        // The same while the engine is motored and the pressures cannot drive EGR (session 42,
        // an option): with p_em <= p_im no EGR flows whatever the valve or the VGT (eqs (32),
        // (35)), e.g. after a tip-out, while the boost of the spinning turbo outlasts the
        // exhaust's energy; the loop comes back once fired or p_em - p_im exceeds the band.
        // (Fired, closing the VGT raises p_em above p_im: the loop keeps its authority there.)
        let dp_kpa = (m.p_em - m.p_im) / 1e3;
        let band = self.tuning.vgt_release_motored_band;
        let motored = u_delta <= u_min;
        self.no_egr_flow =
            band > 0.0 && motored && (dp_kpa <= 0.0 || (self.no_egr_flow && dp_kpa <= band));
        let no_egr = u_egr < self.tuning.vgt_release_below_egr || self.no_egr_flow;
        let u_vgt_x = if no_egr { vmax } else { u_vgt_x };
        // the exhaust back-pressure limit (session 41): above dp_vgt_limit a PI opens the VGT
        // through a max selector over both VGT loops (below it the limiter takes no part and
        // starts from the applied command when the limit is next exceeded)
        let e_dp = dp_kpa - self.tuning.dp_vgt_limit;
        let dp_active = e_dp > 0.0;
        let u_vgt_sel = u_vgt_x.min(u_vgt_l);
        let u_vgt_dp = self.dp_vgt.output(e_dp, dt);
        let by_dp = dp_active && u_vgt_dp > u_vgt_sel;
        let u_vgt = if by_dp { u_vgt_dp } else { u_vgt_sel }.clamp(closed, vmax);
        // which loop is in feedback (a command at one of its limits, where only one side of
        // the selector's output passes, and the error cap cut it)
        let egr_loop = if u_egr <= egr_closed || u_egr >= egr_open {
            InCharge::None
        } else if u_egr_lc <= u_egr_x {
            // (inside the range this is u_egr_l <= u_egr_x where egr_max is the open end)
            if e_le < cap && u_egr_l <= egr_max {
                InCharge::Main
            } else {
                InCharge::None
            }
        } else {
            InCharge::Limiter
        };
        let vgt_loop = if u_vgt <= closed || u_vgt >= vmax || by_dp {
            // (the back-pressure limiter is not an air-path loop of the linear analysis)
            InCharge::None
        } else if u_vgt_x <= u_vgt_l {
            // held: the previous command, no feedback
            if held {
                InCharge::None
            } else {
                InCharge::Main
            }
        } else if e_lv < cap {
            InCharge::Limiter
        } else {
            InCharge::None
        };
        self.lambda_egr.commit(e_le, dt, u_egr);
        self.x_egr.commit(e_xe, dt, u_egr);
        self.lambda_vgt.commit(e_lv, dt, u_vgt);
        self.x_vgt.commit(e_xv, dt, u_vgt);
        if dp_active {
            self.dp_vgt.commit(e_dp, dt, u_vgt);
        } else {
            self.dp_vgt.reset(u_vgt);
        }
        if by_dp {
            let d = &mut self.dp_log;
            if !d.active {
                if d.episodes == 0 {
                    d.first_t = m.t;
                    d.u_vgt_min = u_vgt_sel.max(closed);
                }
                d.episodes += 1;
                d.u_vgt_min = d.u_vgt_min.min(u_vgt_sel.max(closed));
            }
            d.samples += 1;
            d.dp_max = d.dp_max.max(dp_kpa);
        }
        self.dp_log.active = by_dp;
        self.vgt_beyond.record(m.t, u_vgt);
        let t = m.t;
        let egr_name = if egr_loop == InCharge::Limiter {
            "x_egr->u_egr (limiter)"
        } else {
            "lambda_O->u_egr"
        };
        let sp = (lambda_s, x_s);
        self.egr_ramp.track(
            t,
            dt,
            (self.u_egr_prev, u_egr),
            // the valve's command range (the parameter set's input_saturation.u_egr; session 41:
            // was 0-100 %, so a valve wound to the open end of a narrower range was not reported)
            (egr_closed, egr_open),
            egr_loop,
            egr_name,
            sp,
        );
        let vgt_name = if vgt_loop == InCharge::Limiter {
            "lambda_O->u_vgt (limiter)"
        } else {
            "x_egr->u_vgt"
        };
        self.vgt_ramp.track(
            t,
            dt,
            (self.u_vgt_prev, u_vgt),
            (closed, vmax),
            vgt_loop,
            vgt_name,
            sp,
        );
        self.u_vgt_prev = u_vgt;
        self.u_egr_prev = u_egr;
        self.egr_by_lambda_prev = u_egr_l <= u_egr_x;
        Output {
            u_delta,
            u_egr,
            u_vgt,
            lambda_o_ref: lambda_s,
            x_egr_ref: x_s,
            egr_loop: Some(egr_loop),
            vgt_loop: Some(vgt_loop),
        }
    }
}

/// An open-loop "controller": the commands of an input schedule, sampled and held.
#[derive(Debug, Clone)]
pub struct OpenLoop {
    /// The schedule (its n_e column is ignored: the demand's speed drives the plant).
    pub schedule: InputSchedule,
    /// Sample time \[s\].
    pub ts: f64,
}

impl OpenLoop {
    fn out(&self, t: f64) -> Output {
        let d = self.schedule.at(t);
        Output {
            u_delta: d.u_delta_mg,
            u_egr: d.u_egr_pct,
            u_vgt: d.u_vgt_pct,
            lambda_o_ref: f64::NAN,
            x_egr_ref: f64::NAN,
            egr_loop: None,
            vgt_loop: None,
        }
    }
}

impl Controller for OpenLoop {
    fn sample_time(&self) -> f64 {
        self.ts
    }
    fn start(&mut self, t0: f64, _: f64, _: f64, _: bool) -> Output {
        self.out(t0)
    }
    fn update(&mut self, m: &Measurement) -> Output {
        self.out(m.t)
    }
}

#[cfg(test)]
mod tests {
    use super::BaselineTuning;
    use crate::model::{U_EGR_RANGE as AUTHORS_EGR, U_VGT_RANGE as AUTHORS_VGT};

    /// Values that once passed the check and then broke a run (a gain whose products overflow,
    /// a smoke limit whose set-point floor is above the maps' cap) are refused, naming the field;
    /// the bounds themselves are accepted.
    #[test]
    fn validate_refuses_values_that_break_a_run() {
        let base = BaselineTuning::default();
        for (t, field) in [
            (
                BaselineTuning {
                    lambda_limit: 9.9,
                    ..base
                },
                "lambda_limit = 9.9",
            ),
            (
                BaselineTuning {
                    lambda_limit: 0.99,
                    ..base
                },
                "lambda_limit = 0.99",
            ),
            (
                BaselineTuning {
                    lambda_limit: 5.0,
                    smoke_margin: 0.99,
                    ..base
                },
                "set-point floor",
            ),
            (
                BaselineTuning {
                    torque: (1e308, 2.0),
                    ..base
                },
                "torque[1] = 1e308",
            ),
            (
                BaselineTuning {
                    torque: (0.02, -1.0),
                    ..base
                },
                "torque[2] = -1",
            ),
            (
                BaselineTuning {
                    lambda_vgt: (20.0, f64::NAN),
                    ..base
                },
                "lambda_vgt[2] = NaN",
            ),
            (BaselineTuning { d_x: 2.0, ..base }, "d_x = 2"),
            (
                BaselineTuning {
                    d_lambda: 1e308,
                    ..base
                },
                "d_lambda = 1e308",
            ),
            (
                BaselineTuning {
                    lambda_error_cap: 0.0,
                    ..base
                },
                "lambda_error_cap = 0",
            ),
            (
                BaselineTuning {
                    lambda_error_cap: f64::INFINITY,
                    ..base
                },
                "lambda_error_cap = inf",
            ),
            (
                BaselineTuning {
                    vgt_gain_closed: 0.0,
                    ..base
                },
                "vgt_gain_closed = 0",
            ),
            (
                BaselineTuning {
                    vgt_gain_knee: 0.0,
                    ..base
                },
                "vgt_gain_knee = 0",
            ),
            (
                BaselineTuning {
                    vgt_gain_knee: f64::NAN,
                    ..base
                },
                "vgt_gain_knee = NaN",
            ),
            (
                BaselineTuning {
                    egr_gain_closed: 0.0,
                    ..base
                },
                "egr_gain_closed = 0",
            ),
            (
                BaselineTuning {
                    egr_gain_knee: 0.0,
                    ..base
                },
                "egr_gain_knee = 0",
            ),
            (
                BaselineTuning {
                    egr_gain_knee: 100.5,
                    ..base
                },
                "egr_gain_knee = 100.5",
            ),
        ] {
            let e = t.validate().expect_err(field).to_string();
            assert!(e.contains(field), "{e} (expected {field})");
        }
        for t in [
            base,
            BaselineTuning {
                lambda_limit: 5.0,
                smoke_margin: 0.5,
                ..base
            },
            BaselineTuning {
                torque: (1e6, 1e6),
                d_x: 1.0,
                d_lambda: 10.0,
                ..base
            },
            BaselineTuning {
                lambda_error_cap: 10.0,
                x_egr_vgt: (0.0, 0.0),
                ..base
            },
            BaselineTuning {
                vgt_gain_closed: 10.0,
                vgt_gain_knee: 100.0,
                ..base
            },
            BaselineTuning {
                vgt_gain_closed: 1e-3,
                vgt_gain_knee: 20.001,
                ..base
            },
        ] {
            t.validate().unwrap();
        }
    }

    /// A PI gain is a pair: three numbers (or one) in a tuning file are refused, naming the
    /// length (serde's tuple took the first two and dropped the rest).
    #[test]
    fn a_pi_gain_must_be_a_pair() {
        let t: BaselineTuning = toml::from_str("torque = [0.03, 3.0]").unwrap();
        assert_eq!(t.torque, (0.03, 3.0));
        for text in ["x_egr_vgt = [150, 800, 3]", "lambda_egr = [40]"] {
            let e = toml::from_str::<BaselineTuning>(text)
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("invalid length") && e.contains("[kp, ki]"),
                "{text}: {e}"
            );
        }
        let j: BaselineTuning = serde_json::from_str(r#"{"lambda_vgt": [1, 2]}"#).unwrap();
        assert_eq!(j.lambda_vgt, (1.0, 2.0));
    }

    /// The schedules' factors: the closed-end factor at and below the closed end (VGT 20 %, EGR
    /// valve 0 %), 1 from the knee on, linear between; exactly 1 everywhere with a closed-end
    /// factor of 1 (no schedule). The defaults: the VGT's 0.5 at 20 % with its knee at 40 %, no
    /// EGR-valve schedule (1; knee 10 %).
    #[test]
    fn gain_factors_are_linear_between_the_closed_end_and_the_knee() {
        let t = BaselineTuning {
            vgt_gain_closed: 0.4,
            vgt_gain_knee: 50.0,
            egr_gain_closed: 0.2,
            egr_gain_knee: 20.0,
            ..BaselineTuning::default()
        };
        for (u, g) in [
            (0.0, 0.4),
            (20.0, 0.4),
            (35.0, 0.7),
            (50.0, 1.0),
            (80.0, 1.0),
        ] {
            assert!(
                (t.vgt_gain_factor_in(u, AUTHORS_VGT) - g).abs() < 1e-12,
                "u_vgt {u}"
            );
        }
        for (u, g) in [
            (-1.0, 0.2),
            (0.0, 0.2),
            (5.0, 0.4),
            (15.0, 0.8),
            (20.0, 1.0),
            (90.0, 1.0),
        ] {
            assert!(
                (t.egr_gain_factor_in(u, AUTHORS_EGR) - g).abs() < 1e-12,
                "u_egr {u}"
            );
        }
        let d = BaselineTuning::default();
        for (u, g) in [(20.0, 0.5), (30.0, 0.75), (40.0, 1.0), (100.0, 1.0)] {
            assert!(
                (d.vgt_gain_factor_in(u, AUTHORS_VGT) - g).abs() < 1e-12,
                "u_vgt {u}"
            );
        }
        for u in [0.0, 5.0, 10.0, 100.0] {
            assert_eq!(d.egr_gain_factor_in(u, AUTHORS_EGR), 1.0);
        }
        let none = BaselineTuning {
            vgt_gain_closed: 1.0,
            egr_gain_closed: 1.0,
            ..d
        };
        for u in [0.0, 5.0, 20.0, 20.5, 33.3, 40.0, 100.0] {
            assert_eq!(none.vgt_gain_factor_in(u, AUTHORS_VGT), 1.0);
            assert_eq!(none.egr_gain_factor_in(u, AUTHORS_EGR), 1.0);
        }
    }

    /// Set-point maps over two speeds and two loads (flat set-points lambda_O,s = 2, x_egr,s =
    /// 0.1), of a VGT whose command range is `u_vgt_range`.
    fn flat_maps(u_vgt_range: (f64, f64)) -> super::SetpointMaps {
        super::SetpointMaps {
            n_e: vec![1000.0, 2000.0],
            load: vec![0.0, 1.0],
            m_e: vec![vec![0.0, 1000.0]; 2],
            lambda_o: vec![vec![2.0; 2]; 2],
            x_egr: vec![vec![0.1; 2]; 2],
            u_full: vec![200.0; 2],
            u_delta_range: (1.0, 250.0),
            u_vgt_range,
            u_egr_range: crate::model::U_EGR_RANGE,
            u_egr_max: vec![vec![100.0; 2]; 2],
            adjusted: vec![],
        }
    }

    /// The VGT commands of the baseline at no load (the fuel held at the motoring 1 mg) with an
    /// EGR fraction `x_egr` held against its set-point 0.1 and lambda_O at 10: (u_vgt, the VGT's
    /// loop in charge) after each of `n` samples.
    fn vgt_commands(
        u_vgt_range: (f64, f64),
        x_egr: f64,
        n: usize,
    ) -> Vec<(f64, Option<super::InCharge>)> {
        use super::{Baseline, Controller, Measurement};
        let mut b = Baseline::with_maps(flat_maps(u_vgt_range), BaselineTuning::default());
        b.fuel_override = 1.0;
        b.start(0.0, 1500.0, 0.0, false);
        let sig = crate::model::Signals {
            u_delta: 1.0,
            lambda_o: 10.0,
            x_egr,
            ..Default::default()
        };
        (0..n)
            .map(|k| {
                let o = b.update(&Measurement {
                    t: 0.01 * k as f64,
                    n_e: 1500.0,
                    m_ref: 0.0,
                    motoring: false,
                    signals: &sig,
                    p_im: 1e5,
                    p_em: 1e5,
                    omega_t: 5000.0,
                    x_oim: 0.2,
                });
                (o.u_vgt, o.vgt_loop)
            })
            .collect()
    }

    /// The VGT's closed end (the clamp of the command, the loop in charge there, the gain
    /// schedule's closed-end factor) and its open end (the most open position at no load)
    /// come from the maps' VGT range, not a literal 20 % and 100 %: a VGT of 10-90 % closes to
    /// 10 % and opens to 90 %, the authors' 20-100 % to 20 % and 100 %.
    #[test]
    fn the_baseline_follows_the_vgt_range_of_its_maps() {
        use super::InCharge;
        for (range, closed, open) in [((20.0, 100.0), 20.0, 100.0), ((10.0, 90.0), 10.0, 90.0)] {
            // x_egr far below its set-point: the x_egr -> u_vgt loop closes the VGT to its end
            let run = vgt_commands(range, 0.0, 400);
            let (u, in_charge) = *run.last().unwrap();
            assert_eq!(u, closed, "{range:?}");
            assert_eq!(in_charge, Some(InCharge::None), "{range:?}");
            assert!(run.iter().all(|(u, _)| *u >= closed), "{range:?}");
            // on the way there, in feedback between the ends
            assert!(
                run.iter()
                    .any(|(u, c)| *u > closed && *c == Some(InCharge::Main)),
                "{range:?}"
            );
            // x_egr far above: it opens to the no-load open end
            let (u, in_charge) = *vgt_commands(range, 0.5, 400).last().unwrap();
            assert_eq!(u, open, "{range:?}");
            assert_eq!(in_charge, Some(InCharge::None), "{range:?}");
        }
        // the schedule: the closed-end factor 0.5 at the range's closed end, 1 from the knee
        // (40 %), linear between
        let t = BaselineTuning::default();
        for (u, g) in [(10.0, 0.5), (25.0, 0.75), (40.0, 1.0), (5.0, 0.5)] {
            assert!(
                (t.vgt_gain_factor_in(u, (10.0, 90.0)) - g).abs() < 1e-12,
                "u_vgt {u}"
            );
        }
        // and the EGR valve's: its closed-end factor at the range's closed end
        let e = BaselineTuning {
            egr_gain_closed: 0.2,
            egr_gain_knee: 20.0,
            ..t
        };
        for (u, g) in [(10.0, 0.2), (15.0, 0.6), (20.0, 1.0), (0.0, 0.2)] {
            assert!(
                (e.egr_gain_factor_in(u, (10.0, 90.0)) - g).abs() < 1e-12,
                "u_egr {u}"
            );
        }
        // a knee at or below the closed end: no schedule
        assert_eq!(t.vgt_gain_factor_in(50.0, (50.0, 100.0)), 1.0);
        assert_eq!(t.vgt_gain_factor_in(60.0, (50.0, 100.0)), 1.0);
    }

    /// The bounds name the fields of the metadata in its order, and their notation.
    #[test]
    fn bounds_follow_the_fields() {
        let names: Vec<&str> = BaselineTuning::FIELDS.iter().map(|f| f.name).collect();
        let bounds: Vec<&str> = BaselineTuning::BOUNDS.iter().map(|b| b.0).collect();
        assert_eq!(names, bounds);
        // validate pairs each value with its bound by position
        let values = BaselineTuning::default().field_values();
        let value_names: Vec<&str> = values.iter().map(|v| v.0).collect();
        assert_eq!(value_names, bounds);
        let b = |name: &str| {
            BaselineTuning::BOUNDS
                .iter()
                .find(|b| b.0 == name)
                .unwrap()
                .1
        };
        assert_eq!(b("smoke_margin").interval(), "[0, 1)");
        assert_eq!(b("lambda_error_cap").interval(), "(0, 10]");
        assert_eq!(b("torque").interval(), "[0, 1e6]");
        assert!(!b("smoke_margin").contains(1.0) && b("smoke_margin").contains(0.0));
        assert!(!b("lambda_error_cap").contains(0.0) && b("lambda_error_cap").contains(10.0));
        assert!(!b("d_x").contains(f64::NAN) && !b("d_lambda").contains(f64::INFINITY));
    }

    /// The metadata names every serialized field but the sample time, in declaration order, so
    /// a field added to the struct without its row (or renamed) fails here.
    #[test]
    fn fields_metadata_names_every_serialized_field() {
        let v = serde_json::to_value(BaselineTuning::default()).unwrap();
        let keys: Vec<&str> = v
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .filter(|k| *k != "ts")
            .collect();
        let mut names: Vec<&str> = BaselineTuning::FIELDS.iter().map(|f| f.name).collect();
        let mut sorted_keys = keys.clone();
        sorted_keys.sort_unstable();
        names.sort_unstable();
        assert_eq!(names, sorted_keys);
        assert!(BaselineTuning::FIELDS.iter().all(|f| !f.unit.is_empty()));
    }
}
