//! What the five tuning steps do not estimate: the test cell's ambient conditions and the
//! engine's constants.
//!
//! * **Ambient.** The ambient pressure p_amb and temperature T_amb (eqs (44), (59); the
//!   exhaust-pipe wall temperature T_w of eq. (25), which the paper writes T_amb) and the
//!   intercooler's cooling temperature T_im (eq. (73)) are measured at every stationary point
//!   (paper Table 5). The authors' published values are the means of their 82 stationary
//!   points (p_amb = 101 111.341 463 414 63 Pa is a sum divided by 82, and so are T_amb and
//!   T_im), so a campaign measured on another day or in another test cell carries its own.
//!   [`ambient_from_stationary`] sets them the same way, the means of the campaign's
//!   stationary points, by default where the campaign contradicts the parameter file's values
//!   ([`AmbientSource::Auto`]: a campaign measured under the file's conditions keeps them
//!   exactly). T_w follows T_amb when the parameter set ties them (equal values, as the
//!   published set and the paper's eq. (25) do); a T_w of its own is kept.
//! * **Constants.** Geometry and properties that no step estimates ([`ENGINE_CONSTANTS`]:
//!   displacement, cylinders, compression ratio, heating value, wheel radii, maximum valve
//!   and vane areas, ...). They come from the parameter file; the published engine's are the
//!   default, right only for that engine. [`constant_differences`] compares two sets'
//!   constants (e.g. with a virtual campaign's `true_params.toml`), and
//!   [`implausible_constants`] checks them against what the campaign measured: a wrong
//!   displacement shows in the volumetric efficiency (eq. (11)) the measured flows imply, a
//!   wrong cylinder count or heating value in the gross indicated efficiency (eq. (29)) that
//!   step 1 fits to the measured torque.

use super::data::StationaryPoint;
use crate::components::cylinder;
use crate::io::csv_inputs::Outside;
use crate::numerics::Num;
use crate::params::Params;
use serde::{Deserialize, Serialize};

/// Parameters that no tuning step estimates (names of the parameter registry, paths of the
/// parameter file) besides the ambient conditions: the engine's geometry and properties.
pub const ENGINE_CONSTANTS: [&str; 33] = [
    "cylinder.v_d",
    "cylinder.n_cyl",
    "cylinder.r_c",
    "cylinder.q_hv",
    "cylinder.afs",
    "cylinder.gamma_c",
    "exhaust_pipe.d_pipe",
    "exhaust_pipe.l_pipe",
    "exhaust_pipe.n_pipe",
    "egr_valve.a_egrmax",
    "turbine.a_vgtmax",
    "turbine.r_t",
    "turbine.w_tlin",
    "compressor.r_c",
    "intake_manifold.x_oc",
    "gas.c_pa",
    "gas.c_pe",
    "gas.c_va",
    "gas.c_ve",
    "gas.r_a",
    "gas.r_e",
    "gas.gamma_a",
    "gas.gamma_e",
    "input_saturation.n_e[1]",
    "input_saturation.n_e[2]",
    "input_saturation.u_delta[1]",
    "input_saturation.u_delta[2]",
    "input_saturation.u_egr[1]",
    "input_saturation.u_egr[2]",
    "input_saturation.u_vgt[1]",
    "input_saturation.u_vgt[2]",
    "integrator_limits.n_t[1]",
    "integrator_limits.n_t[2]",
];

/// Where the ambient conditions of the tuned model come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AmbientSource {
    /// Each of p_amb, T_amb, T_im from the stationary points' mean where the campaign
    /// contradicts the parameter file's value (the mean differs from it by more than
    /// [`AMBIENT_Z`] standard errors of the mean and by more than [`AMBIENT_RESOLUTION`]),
    /// else the file's: a campaign measured under the file's conditions keeps their exact
    /// values rather than the noise of their means.
    #[default]
    Auto,
    /// The means of the campaign's stationary points (as the published values are).
    Data,
    /// The parameter file's values, whatever the campaign measured.
    Params,
}

/// Standard errors of the mean beyond which [`AmbientSource::Auto`] takes the campaign's mean.
pub const AMBIENT_Z: f64 = 3.0;

/// Differences that [`AmbientSource::Auto`] never counts as a contradiction, whatever the
/// standard error (noise-free data): p_amb 10 Pa, T_amb and T_im 0.05 K.
pub const AMBIENT_RESOLUTION: [f64; 3] = [10.0, 0.05, 0.05];

/// One ambient quantity: the campaign's mean, its standard error, the file's value and which
/// the tuning uses.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AmbientValue {
    /// Mean over the stationary points (Pa or K).
    pub mean: f64,
    /// Standard error of that mean (sample standard deviation / sqrt(n); 0 for one point).
    pub std_error: f64,
    /// The parameter file's value.
    pub file: f64,
    /// The value the tuning uses (the mean or the file's).
    pub used: f64,
    /// Whether `used` is the mean.
    pub from_data: bool,
}

/// The ambient conditions of the tuning: p_amb, T_amb and T_im from the stationary points or
/// the parameter file ([`ambient_from_stationary`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AmbientFromData {
    /// Stationary points averaged.
    pub points: usize,
    /// How each quantity was chosen.
    pub source: AmbientSource,
    /// Ambient pressure p_amb \[Pa\] (eqs (44), (59)).
    pub p_amb: AmbientValue,
    /// Ambient temperature T_amb \[K\] (eq. (59)).
    pub t_amb: AmbientValue,
    /// Intake manifold temperature T_im \[K\] (eq. (73)).
    pub t_im: AmbientValue,
    /// The exhaust-pipe wall temperature T_w \[K\] used (eq. (25)): T_amb's when the
    /// parameter file tied them, else the file's.
    pub t_w: f64,
    /// Whether T_w follows T_amb (the file had T_w = T_amb).
    pub t_w_tied: bool,
}

impl AmbientFromData {
    /// Whether any quantity differs from the parameter file's.
    pub fn changed(&self) -> bool {
        [self.p_amb, self.t_amb, self.t_im]
            .iter()
            .any(|v| v.used != v.file)
    }

    /// One line for reports: the means, the file's values and which are used.
    pub fn describe(&self) -> String {
        let one = |name: &str, v: &AmbientValue, unit: &str, digits: usize| {
            format!(
                "{name} {:.*} {unit} (mean {:.*} +- {:.*}, file {:.*}: {})",
                digits,
                v.used,
                digits,
                v.mean,
                digits,
                v.std_error,
                digits,
                v.file,
                if v.from_data {
                    "the mean"
                } else {
                    "the file's"
                }
            )
        };
        format!(
            "ambient over the {} stationary points ({}): {}, {}, {}, T_w {:.2} K{}",
            self.points,
            match self.source {
                AmbientSource::Auto => "--ambient auto: the mean where it contradicts the file",
                AmbientSource::Data => "--ambient data",
                AmbientSource::Params => "--ambient params",
            },
            one("p_amb", &self.p_amb, "Pa", 0),
            one("T_amb", &self.t_amb, "K", 2),
            one("T_im", &self.t_im, "K", 2),
            self.t_w,
            if self.t_w_tied {
                " (tied to T_amb)"
            } else {
                " (its own)"
            }
        )
    }
}

/// Sets p_amb, T_amb and T_im of `p` as `source` says (the means of the stationary points, or
/// where they contradict `p`'s values, or not at all), and T_w to T_amb where `p` ties them;
/// returns what was chosen, `None` without stationary points (nothing changed).
pub fn ambient_from_stationary(
    p: &mut Params,
    stationary: &[StationaryPoint],
    source: AmbientSource,
) -> Option<AmbientFromData> {
    if stationary.is_empty() {
        return None;
    }
    let n = stationary.len() as f64;
    let stat = |f: fn(&StationaryPoint) -> f64, file: f64, resolution: f64| {
        let mean = stationary.iter().map(f).sum::<f64>() / n;
        let var = if stationary.len() > 1 {
            stationary
                .iter()
                .map(|s| (f(s) - mean).powi(2))
                .sum::<f64>()
                / (n - 1.0)
        } else {
            0.0
        };
        let std_error = (var / n).sqrt();
        let d = (mean - file).abs();
        let from_data = match source {
            AmbientSource::Data => true,
            AmbientSource::Params => false,
            AmbientSource::Auto => d > resolution && d > AMBIENT_Z * std_error,
        };
        AmbientValue {
            mean,
            std_error,
            file,
            used: if from_data { mean } else { file },
            from_data,
        }
    };
    let r = AMBIENT_RESOLUTION;
    let p_amb = stat(|s| s.p_amb, p.ambient.p_amb, r[0]);
    let t_amb = stat(|s| s.t_amb, p.ambient.t_amb, r[1]);
    let t_im = stat(|s| s.t_im, p.intake_manifold.t_im, r[2]);
    let t_w_tied = p.exhaust_pipe.t_w == p.ambient.t_amb;
    p.ambient.p_amb = p_amb.used;
    p.ambient.t_amb = t_amb.used;
    p.intake_manifold.t_im = t_im.used;
    if t_w_tied {
        p.exhaust_pipe.t_w = p.ambient.t_amb;
    }
    Some(AmbientFromData {
        points: stationary.len(),
        source,
        p_amb,
        t_amb,
        t_im,
        t_w: p.exhaust_pipe.t_w,
        t_w_tied,
    })
}

/// A constant of [`ENGINE_CONSTANTS`] that differs between two parameter sets.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConstantDifference {
    /// Path in the parameter file (`cylinder.v_d`).
    pub name: &'static str,
    /// Value in the set used.
    pub used: f64,
    /// Value in the other set.
    pub other: f64,
}

/// The engine constants whose values differ between `used` and `other` by more than 1e-9
/// relative.
pub fn constant_differences(used: &Params, other: &Params) -> Vec<ConstantDifference> {
    ENGINE_CONSTANTS
        .iter()
        .filter_map(|&name| {
            let (a, b) = (used.get(name)?, other.get(name)?);
            ((a - b).abs() > 1e-9 * a.abs().max(b.abs())).then_some(ConstantDifference {
                name,
                used: a,
                other: b,
            })
        })
        .collect()
}

/// Range of the mean volumetric efficiency (eq. (11)) that [`implausible_constants`] accepts:
/// four-stroke diesel engines lie about 0.8-1.0 (the published engine's stationary points
/// average 0.92).
pub const ETA_VOL_RANGE: (f64, f64) = (0.7, 1.1);

/// Range of the gross indicated efficiency eta_igch (1 - 1/r_c^(gamma_cyl - 1)) of eq. (29)
/// that [`implausible_constants`] accepts: diesel engines lie about 0.40-0.50 (the published
/// engine 0.43).
pub const ETA_IG_RANGE: (f64, f64) = (0.33, 0.55);

/// The mean volumetric efficiency the stationary points imply with the displacement of `p`:
/// W_ei 120 R_a T_im / (p_im n_e V_d), eq. (11), with W_ei = W_c / (1 - x_egr) (eq. (10));
/// `None` without a usable point.
pub fn measured_volumetric_efficiency(p: &Params, stationary: &[StationaryPoint]) -> Option<f64> {
    let v: Vec<f64> = stationary
        .iter()
        .filter(|s| s.x_egr < 0.95 && s.p_im > 0.0 && s.n_e > 0.0)
        .map(|s| {
            // eq. (11) is linear in eta_vol: the measured flow over the flow at eta_vol = 1
            let w_ei = s.w_c / (1.0 - s.x_egr);
            w_ei / cylinder::w_ei(&p.cylinder, 1.0, s.p_im, s.n_e, p.gas.r_a, s.t_im)
        })
        .filter(|e| e.is_finite())
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The gross indicated efficiency eta_igch (1 - 1/r_c^(gamma_cyl - 1)) of eq. (29).
pub fn gross_indicated_efficiency(p: &Params) -> f64 {
    p.cylinder.eta_igch * cylinder::CylinderConsts::new(&p.gas, &p.cylinder).otto_factor
}

/// Caveats where the campaign contradicts the engine constants of `p`: the volumetric
/// efficiency the measured flows imply outside [`ETA_VOL_RANGE`] (displacement), and, when
/// `eta_igch_tuned` (step 1 fitted it to the measured torque), the gross indicated efficiency
/// outside [`ETA_IG_RANGE`] (cylinders, heating value, compression ratio). Empty when nothing
/// is implausible.
pub fn implausible_constants(
    p: &Params,
    stationary: &[StationaryPoint],
    eta_igch_tuned: bool,
) -> Vec<String> {
    let mut out = Vec::new();
    let c = &p.cylinder;
    if let Some(e) = measured_volumetric_efficiency(p, stationary) {
        if !(ETA_VOL_RANGE.0..=ETA_VOL_RANGE.1).contains(&e) {
            out.push(format!(
                "the stationary points imply a mean volumetric efficiency of {e:.2} (eq. (11): \
                 W_ei 120 R_a T_im / (p_im n_e V_d) with W_ei = W_c / (1 - x_egr)), outside the \
                 {:.1}-{:.1} of four-stroke diesel engines: is V_d = {:.2} dm^3 this engine's \
                 displacement (give the engine's constants with --params FILE), and is W_c in \
                 kg/s (a unit guessed by `mvem campaign --init` from the values' range, g/s \
                 for kg/h say, shows here: check the manifest's [units])?",
                ETA_VOL_RANGE.0,
                ETA_VOL_RANGE.1,
                c.v_d * 1e3
            ));
        }
    }
    let e = gross_indicated_efficiency(p);
    if eta_igch_tuned && !(ETA_IG_RANGE.0..=ETA_IG_RANGE.1).contains(&e) {
        let in_range = |v: f64| (ETA_IG_RANGE.0..=ETA_IG_RANGE.1).contains(&v);
        // u_delta logged as the fuel of all cylinders per cycle (a factor n_cyl, which the
        // loader's range cannot tell from a larger cylinder) divides eta_igch by n_cyl
        let fuel = if c.n_cyl > 1.0 && in_range(e * c.n_cyl) {
            format!(
                " Or is u_delta the fuel of all {} cylinders per cycle? It must be per cylinder \
                 (mg/cycle/cylinder): with u_delta / {} the efficiency would be {:.3}, a diesel \
                 engine's.",
                c.n_cyl,
                c.n_cyl,
                e * c.n_cyl
            )
        } else {
            String::new()
        };
        out.push(format!(
            "the measured torque gives a gross indicated efficiency eta_igch (1 - 1/r_c^(gamma_cyl \
             - 1)) of {e:.3} (eq. (29), eta_igch = {:.3}), outside the {:.2}-{:.2} of diesel \
             engines: are n_cyl = {}, q_HV = {:.4e} J/kg and r_c = {} this engine's? Give the \
             engine's constants with --params FILE.{fuel}",
            c.eta_igch, ETA_IG_RANGE.0, ETA_IG_RANGE.1, c.n_cyl, c.q_hv, c.r_c
        ));
    }
    out
}

/// A caveat when the campaign's engine speeds or fuel leave the model's input saturation
/// (`input_saturation` of `p`, the authors' items 1-2): the model runs those points and samples
/// clamped, so the tuning fits a model of another operating point. `None` when all lie inside.
pub fn inputs_outside_saturation(p: &Params, c: &super::data::Campaign) -> Option<String> {
    let s = &p.input_saturation;
    let out =
        |n_e: f64, u: f64| n_e < s.n_e[0] || n_e > s.n_e[1] || u < s.u_delta[0] || u > s.u_delta[1];
    let points = c
        .stationary
        .iter()
        .filter(|x| out(x.n_e, x.u_delta))
        .count();
    let (mut samples, mut total) = (0usize, 0usize);
    for d in &c.dynamic {
        if let (Some(n), Some(u)) = (d.get("n_e"), d.get("u_delta")) {
            total += n.len();
            samples += n.iter().zip(u).filter(|(n, u)| out(**n, **u)).count();
        }
    }
    let (lo, hi, _) = campaign_input_extent(c).unwrap_or((f64::NAN, f64::NAN, f64::NAN));
    (points + samples > 0).then(|| {
        format!(
            "{points} of the {} stationary points and {samples} of the {total} dynamic samples \
             lie outside the model's input saturation (n_e {}-{} rpm, u_delta {}-{} mg: \
             input_saturation of the parameter file, by default the authors' engine's; the \
             campaign's speeds span {lo:.0}-{hi:.0} rpm), so the model ran them clamped: set \
             this engine's ranges in [input_saturation] of --params",
            c.stationary.len(),
            s.n_e[0],
            s.n_e[1],
            s.u_delta[0],
            s.u_delta[1]
        )
    })
}

/// The campaign's EGR and VGT commands outside the command ranges of `s` (the parameter set
/// `set` names, e.g. `the published parameters` or its file; `input_saturation.u_egr`,
/// `u_vgt`, the authors' items 3-4): one warning per data set (the stationary points, each
/// dynamic set) and column, naming both, the range, how many values lie outside and how far
/// (the extreme below and above, in points of %). The model runs such commands clamped (with
/// the authors' [20, 100] % a VGT commanded to 10 % sits at 20 %), so another engine whose
/// actuators are commanded over a wider range must set its range before tuning. Empty when
/// every command lies inside.
///
/// The count is the input files' ([`crate::io::csv_inputs::Outside`]), but not their whole
/// warning ([`crate::io::csv_inputs::range_warnings_of_rows`]): that one reads rows of all four
/// inputs with their times, linear between rows (so it interpolates the first time a channel
/// crosses its limit), while a campaign's stationary points have no time and its dynamic
/// commands are held between samples (zero-order hold), and the two say different things to
/// do (an inputs file runs clamped; a campaign needs the engine's range in the parameter file).
pub fn commands_outside_ranges(
    c: &super::data::Campaign,
    s: &crate::params::InputSaturation,
    set: &str,
) -> Vec<String> {
    // (where, what a value is, the EGR and VGT commands)
    let mut sources: Vec<(String, &str, Vec<f64>, Vec<f64>)> = vec![(
        format!("the stationary points ({})", c.manifest.stationary),
        "points",
        c.stationary.iter().map(|x| x.u_egr).collect(),
        c.stationary.iter().map(|x| x.u_vgt).collect(),
    )];
    for (info, d) in c.manifest.datasets.iter().zip(&c.dynamic) {
        let col = |name: &str| d.get(name).map(<[f64]>::to_vec).unwrap_or_default();
        sources.push((
            format!("set {} ({})", info.name, info.file),
            "samples",
            col("u_egr"),
            col("u_vgt"),
        ));
    }
    let mut out = Vec::new();
    for (data, unit, egr, vgt) in &sources {
        for (col, actuator, [lo, hi], values) in [
            ("u_egr", "EGR-valve", s.u_egr, egr),
            ("u_vgt", "VGT", s.u_vgt, vgt),
        ] {
            let o = Outside::of(values.iter().copied(), lo, hi);
            if o.count() == 0 {
                continue;
            }
            let sides = o.sides(|v, below| {
                let (d, side, limit) = if below {
                    (lo - v, "under", lo)
                } else {
                    (v - hi, "over", hi)
                };
                format!("{} % ({} points of % {side} {limit} %)", Num(v), Num(d))
            });
            out.push(format!(
                "{data}: {col} leaves the {actuator} command range [{lo}, {hi}] % of {set} \
                 (input_saturation.{col}) at {} of {} {unit} ({sides}); the model runs these \
                 commands clamped into the range: if this engine's {actuator} is commanded \
                 over a wider range, set input_saturation.{col} of the parameter file (for \
                 tuning and validation alike)",
                o.count(),
                values.len(),
            ));
        }
    }
    out
}

/// Where the tuned model's input ranges (`[input_saturation]`, the authors' items 1-2) come
/// from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InputRangeSource {
    /// The parameter file's ranges, widened to contain the campaign: the speed range to its
    /// lowest and highest engine speed, the fuel range up to its largest u_delta (the bottom of
    /// the fuel range stays: the authors' minimum fuel keeps lambda_O of eq. (15) finite).
    #[default]
    Campaign,
    /// The parameter file's ranges as they are; points outside run clamped (a caveat says so).
    Params,
}

/// The input ranges a tuning widened ([`widen_input_saturation`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct InputRangesWidened {
    /// The parameter file's speed range \[rpm\].
    pub n_e_file: [f64; 2],
    /// The speed range used and written \[rpm\].
    pub n_e: [f64; 2],
    /// The parameter file's fuel range [mg/cycle/cylinder].
    pub u_delta_file: [f64; 2],
    /// The fuel range used and written [mg/cycle/cylinder].
    pub u_delta: [f64; 2],
}

impl InputRangesWidened {
    /// One line for the report and the command line.
    pub fn describe(&self) -> String {
        format!(
            "input_saturation widened to the campaign: n_e {}-{} rpm (file {}-{}), u_delta {}-{} mg/cycle \
             (file {}-{}); the model would otherwise have run the campaign's points beyond the \
             file's ranges clamped (the authors' items 1-2 are their engine's ranges), and the \
             tuned file carries these",
            self.n_e[0],
            self.n_e[1],
            self.n_e_file[0],
            self.n_e_file[1],
            self.u_delta[0],
            self.u_delta[1],
            self.u_delta_file[0],
            self.u_delta_file[1]
        )
    }
}

/// The lowest and highest engine speed \[rpm\] and the largest fuel [mg/cycle/cylinder] of the
/// campaign (stationary points and dynamic samples; None without any).
fn campaign_input_extent(c: &super::data::Campaign) -> Option<(f64, f64, f64)> {
    let (mut lo, mut hi, mut u_hi) = (f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for x in &c.stationary {
        lo = lo.min(x.n_e);
        hi = hi.max(x.n_e);
        u_hi = u_hi.max(x.u_delta);
    }
    for d in &c.dynamic {
        for &v in d.get("n_e").unwrap_or(&[]) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        for &v in d.get("u_delta").unwrap_or(&[]) {
            u_hi = u_hi.max(v);
        }
    }
    (lo.is_finite() && hi.is_finite()).then_some((lo, hi, u_hi))
}

/// With [`InputRangeSource::Campaign`], widen `p`'s `[input_saturation]` to contain the
/// campaign's engine speeds and largest fuel (see there) and say what changed; `None` when the
/// campaign lies inside (or with [`InputRangeSource::Params`]). A campaign of another engine
/// tuned with a parameter file that does not set the ranges (they default to the authors'
/// 500-2000 rpm, 1-250 mg) would otherwise be fitted by a model that clamps its high-speed
/// points to 2000 rpm.
pub fn widen_input_saturation(
    p: &mut Params,
    c: &super::data::Campaign,
    source: InputRangeSource,
) -> Option<InputRangesWidened> {
    if source == InputRangeSource::Params {
        return None;
    }
    let (lo, hi, u_hi) = campaign_input_extent(c)?;
    let s = &mut p.input_saturation;
    let before = (s.n_e, s.u_delta);
    s.n_e = [s.n_e[0].min(lo), s.n_e[1].max(hi)];
    if u_hi.is_finite() {
        s.u_delta[1] = s.u_delta[1].max(u_hi);
    }
    ((s.n_e, s.u_delta) != before).then_some(InputRangesWidened {
        n_e_file: before.0,
        n_e: s.n_e,
        u_delta_file: before.1,
        u_delta: s.u_delta,
    })
}

/// Headroom of a widened turbo-speed integrator limit over the campaign's highest measured turbo
/// speed ([`widen_integrator_limits`]): the limit stops the omega_t integrator (the authors'
/// item 37), so a limit at the measured maximum would clamp a model that overshoots it by its
/// noise; 10 % is twenty times the lab's 0.5 % speed noise.
pub const N_T_HEADROOM: f64 = 1.1;

/// The campaign's highest measured turbo speed \[rpm\] and where it was measured (the
/// stationary points or a data set's name); None without any.
fn campaign_turbo_max(c: &super::data::Campaign) -> Option<(f64, String)> {
    let mut best: Option<(f64, String)> = None;
    let mut take = |v: f64, at: &str| {
        if v.is_finite() && best.as_ref().is_none_or(|b| v > b.0) {
            best = Some((v, at.to_string()));
        }
    };
    for x in &c.stationary {
        take(x.n_t, "the stationary points");
    }
    for d in &c.dynamic {
        for &v in d.get("n_t").unwrap_or(&[]) {
            take(v, &format!("set {}", d.name));
        }
    }
    best
}

/// The turbo-speed integrator limit a tuning widened ([`widen_integrator_limits`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TurboLimitWidened {
    /// The parameter file's range `[integrator_limits] n_t` \[rpm\].
    pub n_t_file: [f64; 2],
    /// The range used and written \[rpm\].
    pub n_t: [f64; 2],
    /// The campaign's highest measured turbo speed \[rpm\].
    pub measured_max: f64,
    /// Where it was measured (the stationary points or `set NAME`).
    pub at: String,
}

impl TurboLimitWidened {
    /// One line for the report and the command line.
    pub fn describe(&self) -> String {
        format!(
            "integrator_limits.n_t widened to the campaign: {}-{} rpm (file {}-{}): {} measure \
             turbo speeds up to {:.0} rpm, above the file's limit, where the model's omega_t \
             integrator would stop (the authors' item 37, 200 000 rpm for their engine); the \
             new limit is {N_T_HEADROOM} times the highest measured speed, and the tuned file \
             carries it",
            self.n_t[0],
            self.n_t[1],
            self.n_t_file[0],
            self.n_t_file[1],
            self.at,
            self.measured_max
        )
    }
}

/// With [`InputRangeSource::Campaign`], widen `p`'s `[integrator_limits] n_t` to
/// [`N_T_HEADROOM`] times the campaign's highest measured turbo speed (rounded up to 1000 rpm)
/// where that speed lies above the limit, and say so; `None` when the campaign lies below it
/// (or with [`InputRangeSource::Params`]: [`turbo_speeds_above_limit`] then says the model runs
/// them clamped). Small turbochargers run beyond the authors' 200 000 rpm.
pub fn widen_integrator_limits(
    p: &mut Params,
    c: &super::data::Campaign,
    source: InputRangeSource,
) -> Option<TurboLimitWidened> {
    if source == InputRangeSource::Params {
        return None;
    }
    let (max, at) = campaign_turbo_max(c)?;
    let l = &mut p.integrator_limits;
    if max <= l.n_t[1] {
        return None;
    }
    let file = l.n_t;
    l.n_t[1] = (N_T_HEADROOM * max / 1000.0).ceil() * 1000.0;
    Some(TurboLimitWidened {
        n_t_file: file,
        n_t: l.n_t,
        measured_max: max,
        at,
    })
}

/// A warning when the campaign's turbo speeds exceed the model's turbo-speed integrator limit
/// (`[integrator_limits] n_t` of `p`, the authors' item 37): the model's omega_t stops at the
/// limit, so it cannot reach those operating points. `None` when all lie below.
pub fn turbo_speeds_above_limit(p: &Params, c: &super::data::Campaign) -> Option<String> {
    let lim = p.integrator_limits.n_t[1];
    let (max, at) = campaign_turbo_max(c)?;
    if max <= lim {
        return None;
    }
    let points = c.stationary.iter().filter(|x| x.n_t > lim).count();
    let (mut samples, mut total) = (0usize, 0usize);
    for d in &c.dynamic {
        if let Some(n) = d.get("n_t") {
            total += n.len();
            samples += n.iter().filter(|v| **v > lim).count();
        }
    }
    Some(format!(
        "{points} of the {} stationary points and {samples} of the {total} dynamic samples \
         measure turbo speeds above the model's limit n_t = {lim} rpm (integrator_limits of the \
         parameter file; the highest, {max:.0} rpm, in {at}), where the model's omega_t \
         integrator stops (the authors' item 37): set this turbocharger's range in \
         [integrator_limits] of the parameter file",
        c.stationary.len()
    ))
}

/// The published engine's constants in one line (for the note that they are used).
pub fn describe_constants(p: &Params) -> String {
    format!(
        "V_d {:.2} dm^3, {} cylinders, r_c {}, R_c {:.1} mm, R_t {:.1} mm, A_egrmax {:.2} cm^2, \
         A_vgtmax {:.2} cm^2",
        p.cylinder.v_d * 1e3,
        p.cylinder.n_cyl,
        p.cylinder.r_c,
        p.compressor.r_c * 1e3,
        p.turbine.r_t * 1e3,
        p.egr_valve.a_egrmax * 1e4,
        p.turbine.a_vgtmax * 1e4
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tuning::lab::{stationary, LabOptions, Noise};

    fn points(p: &Params, n: usize) -> Vec<StationaryPoint> {
        let opts = LabOptions {
            noise: Noise::NONE,
            n_stationary: n,
            ..LabOptions::default()
        };
        stationary(p, &opts).expect("stationary points").0
    }

    #[test]
    fn every_constant_is_a_parameter_and_none_is_tuned() {
        let p = Params::published();
        for name in ENGINE_CONSTANTS {
            assert!(p.get(name).is_some(), "{name}");
        }
        // the static parameters of cost (77) are not constants
        for sp in crate::tuning::complete::STATIC_PARAMS {
            let info = crate::params::ParamInfo::find(sp.name).expect(sp.name);
            assert!(
                !ENGINE_CONSTANTS.contains(&info.path.as_str()),
                "{}",
                sp.name
            );
        }
    }

    #[test]
    fn ambient_is_the_mean_where_the_campaign_contradicts_the_file() {
        let mut s = points(&Params::published(), 13);
        for (i, x) in s.iter_mut().enumerate() {
            x.p_amb = 95_000.0 + 100.0 * i as f64; // mean 95 600
            x.t_amb = 288.0 + if i % 2 == 0 { 1.0 } else { -1.0 }; // 7 of +1, 6 of -1
        }
        let published = Params::published();
        // T_im: the lab's noise-free values, the file's exactly
        for source in [AmbientSource::Auto, AmbientSource::Data] {
            let mut p = Params::published();
            let a = ambient_from_stationary(&mut p, &s, source).expect("points");
            assert!((p.ambient.p_amb - 95_600.0).abs() < 1e-9);
            assert!((p.ambient.t_amb - (288.0 + 1.0 / 13.0)).abs() < 1e-12);
            assert!(a.p_amb.from_data && a.t_amb.from_data);
            assert_eq!(
                p.exhaust_pipe.t_w, p.ambient.t_amb,
                "published: T_w = T_amb"
            );
            assert_eq!(a.p_amb.file, published.ambient.p_amb);
            // the mean of equal values may differ from them in the last bit: auto keeps the
            // file's, data takes the mean
            assert!((p.intake_manifold.t_im - published.intake_manifold.t_im).abs() < 1e-9);
            assert_eq!(a.t_im.from_data, source == AmbientSource::Data);
            assert!(a.describe().contains("tied to T_amb"));
            assert!(a.changed());
        }
        // auto: a mean within 3 standard errors of the file's value keeps the file's
        let mut q = Params::published();
        q.ambient.p_amb = 95_600.0 + 2.0 * 389.4; // sd of 0..1200 step 100 is 389.4, se 108
        q.ambient.t_amb = 288.0;
        q.exhaust_pipe.t_w = 350.0;
        let a = ambient_from_stationary(&mut q, &s, AmbientSource::Auto).unwrap();
        assert!(a.p_amb.from_data, "7.2 standard errors off");
        assert!(!a.t_amb.from_data, "0.27 standard errors off");
        assert_eq!(q.ambient.t_amb, 288.0);
        assert_eq!(q.exhaust_pipe.t_w, 350.0, "its own T_w stays");
        let mut r = Params::published();
        let a = ambient_from_stationary(&mut r, &s, AmbientSource::Params).unwrap();
        assert!(!a.changed());
        assert_eq!(r, Params::published());
        assert!(ambient_from_stationary(&mut r, &[], AmbientSource::Data).is_none());
    }

    #[test]
    fn the_published_engine_is_plausible_and_a_wrong_displacement_or_cylinder_count_is_not() {
        let p = Params::published();
        let s = points(&p, 30);
        let e = measured_volumetric_efficiency(&p, &s).unwrap();
        assert!((0.85..0.97).contains(&e), "published eta_vol {e}");
        assert!(implausible_constants(&p, &s, true).is_empty());
        // the campaign of an engine with two thirds of the displacement, read with the
        // published V_d: the implied volumetric efficiency drops by a third
        let mut small = p.clone();
        small.cylinder.v_d *= 2.0 / 3.0;
        let s_small = points(&small, 30);
        let e_small = measured_volumetric_efficiency(&p, &s_small).unwrap();
        assert!(e_small < ETA_VOL_RANGE.0, "{e_small}");
        let c = implausible_constants(&p, &s_small, false);
        assert_eq!(c.len(), 1);
        assert!(c[0].contains("V_d = 12.74 dm^3"), "{}", c[0]);
        // torque of 4 cylinders read as 6: step 1 puts eta_igch at 4/6 of the truth
        let mut q = p.clone();
        q.cylinder.eta_igch *= 4.0 / 6.0;
        let c = implausible_constants(&q, &s, true);
        assert_eq!(c.len(), 1);
        assert!(c[0].contains("n_cyl = 6"), "{}", c[0]);
        assert!(!c[0].contains("u_delta"), "{}", c[0]);
        assert!(implausible_constants(&q, &s, false).is_empty());
        // QA (a test cell logging the fuel of all cylinders per cycle, 6 x 121 mg on a
        // 7-litre engine, with the engine's constants given): the caveat asked for n_cyl,
        // q_HV, r_c and --params, which were right; it now names the fuel per cylinder
        let mut f = p.clone();
        f.cylinder.eta_igch /= 6.0;
        let c = implausible_constants(&f, &s, true);
        assert_eq!(c.len(), 1);
        let e = gross_indicated_efficiency(&p);
        assert!(
            c[0].ends_with(&format!(
                "Or is u_delta the fuel of all 6 cylinders per cycle? It must be per cylinder \
                 (mg/cycle/cylinder): with u_delta / 6 the efficiency would be {e:.3}, a diesel \
                 engine's."
            )),
            "{}",
            c[0]
        );
    }

    /// A noise-free campaign of the 13 ESC points and set I (one step).
    fn small_campaign(p: &Params) -> crate::tuning::data::Campaign {
        crate::tuning::lab::campaign(
            p,
            &LabOptions {
                noise: Noise::NONE,
                n_stationary: 13,
                sets: Some(vec!["I".into()]),
                max_steps: Some(1),
                ..LabOptions::default()
            },
        )
        .unwrap()
        .0
    }

    #[test]
    fn inputs_beyond_the_saturation_are_named() {
        let p = Params::published();
        let mut c = small_campaign(&p);
        assert!(inputs_outside_saturation(&p, &c).is_none());
        c.stationary[2].n_e = 2500.0;
        let msg = inputs_outside_saturation(&p, &c).expect("one point outside");
        assert!(
            msg.starts_with("1 of the 13 stationary points and 0 of the"),
            "{msg}"
        );
        assert!(msg.contains("600-2500 rpm"), "{msg}");
        let mut q = p.clone();
        q.input_saturation.n_e = [500.0, 3000.0];
        assert!(inputs_outside_saturation(&q, &c).is_none());
        // the default: the ranges widened to the campaign, so nothing runs clamped
        let mut w = p.clone();
        assert!(widen_input_saturation(&mut w, &c, InputRangeSource::Params).is_none());
        assert_eq!(w, p);
        c.stationary[3].u_delta = 300.0;
        c.stationary[4].n_e = 450.0;
        let r = widen_input_saturation(&mut w, &c, InputRangeSource::Campaign).expect("widened");
        assert_eq!(w.input_saturation.n_e, [450.0, 2500.0]);
        assert_eq!(w.input_saturation.u_delta, [1.0, 300.0]);
        assert_eq!(
            (r.n_e_file, r.u_delta_file),
            ([500.0, 2000.0], [1.0, 250.0])
        );
        assert!(r.describe().contains("n_e 450-2500 rpm (file 500-2000)"));
        assert!(inputs_outside_saturation(&w, &c).is_none());
        assert!(w.validate().is_ok());
        // a campaign inside the file's ranges leaves them
        let mut again = w.clone();
        assert!(widen_input_saturation(&mut again, &c, InputRangeSource::Campaign).is_none());
        assert_eq!(again, w);
    }

    /// QA finding: a small turbocharger's campaign measured turbo speeds above the parameter
    /// file's integrator limit (the authors' 200 000 rpm), and tune and validate ran the model
    /// clamped without a word. The limit is widened like the input ranges (or a warning names
    /// the measured maximum, where and the limit).
    #[test]
    fn turbo_speeds_above_the_integrator_limit_widen_it_or_are_named() {
        let p = Params::published();
        let mut c = small_campaign(&p);
        assert!(turbo_speeds_above_limit(&p, &c).is_none());
        let mut w = p.clone();
        assert!(widen_integrator_limits(&mut w, &c, InputRangeSource::Campaign).is_none());
        c.stationary[4].n_t = 230_000.0;
        let k = c.dynamic[0]
            .columns
            .iter()
            .position(|x| x.0 == "n_t")
            .unwrap();
        c.dynamic[0].columns[k].1[3] = 240_400.0;
        let msg = turbo_speeds_above_limit(&p, &c).expect("above");
        assert!(
            msg.starts_with("1 of the 13 stationary points and 1 of the")
                && msg.contains("limit n_t = 200000 rpm")
                && msg.contains("the highest, 240400 rpm, in set I"),
            "{msg}"
        );
        assert!(widen_integrator_limits(&mut w, &c, InputRangeSource::Params).is_none());
        assert_eq!(w, p);
        let r = widen_integrator_limits(&mut w, &c, InputRangeSource::Campaign).expect("widened");
        assert_eq!(w.integrator_limits.n_t, [100.0, 265_000.0]);
        assert_eq!(r.n_t_file, [100.0, 200_000.0]);
        assert!(
            r.describe().contains("100-265000 rpm (file 100-200000)"),
            "{}",
            r.describe()
        );
        assert!(turbo_speeds_above_limit(&w, &c).is_none());
        assert!(w.validate().is_ok());
    }

    #[test]
    fn constant_differences_name_geometry_not_tuned_parameters() {
        let p = Params::published();
        let mut q = p.clone();
        q.cylinder.n_cyl = 4.0;
        q.turbine.r_t = 0.033;
        q.intake_manifold.v_im = 0.01; // tuned in step 3: not a constant
        q.ambient.p_amb = 95_000.0; // from the data
        let d = constant_differences(&p, &q);
        let names: Vec<&str> = d.iter().map(|x| x.name).collect();
        assert_eq!(names, ["cylinder.n_cyl", "turbine.r_t"]);
        assert_eq!((d[0].used, d[0].other), (6.0, 4.0));
        assert!(constant_differences(&p, &p).is_empty());
    }
}
