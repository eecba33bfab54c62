//! Virtual test cell: generates a tuning campaign from a known parameter set, so the tuning
//! steps can be checked against the true values.
//!
//! - **Stationary data** (Table 5): 82 operating points by default, the 13 points of the
//!   European Stationary Cycle (idle, speeds A/B/C = 1200/1500/1800 r/min at 25/50/75/100 %
//!   load) plus points drawn uniformly over 800-2000 r/min, 15-100 % load, EGR 0-80 %,
//!   VGT 20-100 %. Each is the equilibrium of the model of [`LabOptions::model`] (default 8 states)
//!   ([`crate::analysis::steady::steady_state`]); a point that fails or is not physically valid
//!   (guard saturation, lambda_O < 1, unstable) or whose measurement the campaign's loader could
//!   refuse (a value within five noise standard deviations of the edge of its plausible range,
//!   [`super::data::STATIONARY_COLUMNS`]) is redrawn with new actuator positions (and, for
//!   random points, a new speed and load); after 200 draws the error says why the last failed.
//!   Load L % means u_delta = L/100 * [`U_DELTA_MAX`]. These speeds and the fuel are the
//!   published engine's; [`LabOptions::envelope`] maps them onto another engine's ESC speeds
//!   and full-load fuel ([`Envelope`]). The EGR position is kept below the
//!   vertex of the area polynomial (eq. (38), 80 % for the published set), above which f_egr
//!   is constant and carries no information on c_egr.
//! - **Actuator set J** (sections 5.2, 6.2.3): at 100 Hz, first 24 EGR steps (0 -> 90 -> 0 %
//!   in 10 % steps, a 30 % and a 75 % step, four 5 % steps; the paper's text lists the first
//!   of these, our copy is cut before the rest, so the 5 % steps are our choice), then 24 VGT
//!   steps (100 -> 10 -> 100 % in 10 % steps, five 5 % steps and a 20 % step), each held
//!   [`LabOptions::step_hold_s`]. The positions are the exact responses of eqs (39)-(41), (57)
//!   (linear systems with transport delay, summed step responses).
//!
//! Measured outputs get gaussian noise ([`Noise`]); inputs (n_e, u_delta, actuator commands,
//! p_amb, T_amb) are exact. "Realistic" default: 0.5 % relative on pressures, flows, speeds,
//! torque, EGR fraction and actuator positions (sensor accuracy class of production pressure
//! and mass-flow sensors), 1 K on temperatures (thermocouple class 1 is +-1.5 K).
//! Everything is drawn from a ChaCha8 generator seeded with [`LabOptions::seed`]: the same seed
//! gives the same campaign.
//!
//! T_t (after the turbine) is not a model output; it is synthesized from the turbine's
//! enthalpy drop, T_t = T_em (1 - eta_tm (1 - Pi_t^(1 - 1/gamma_e))) (eqs (45)-(48), the
//! mechanical losses lumped into eta_tm). No tuning step uses it.
//!
//! - **Dynamic sets A-I, Q-V** (Table 1, [`TABLE1`]): at the speeds, loads, step counts and
//!   sample rates of the table, each starting from a physically valid equilibrium (else redrawn).
//!   VGT/EGR sets: constant speed and fuel, each step changes the
//!   VGT or the EGR command (alternating at random) to a new level drawn uniformly (EGR 0 % to
//!   the vertex of the area polynomial, VGT 25-100 %, at least 5 % change), held
//!   [`Table1Row::hold_s`] (6 s at 1 Hz, 4 s for the 100 Hz sets B and Q, 6 s for C, 10 s for
//!   H); fuel sets (I, V) at 1500 r/min step u_delta between 30 and 90 % load at fixed EGR and
//!   VGT. The paper does not give the hold times or the step levels: these are our choice.
//!   Each set is simulated with the 8-state model from the steady state of its first commands
//!   on a 100 Hz grid (500 Hz with sensor lags) and sampled at its rate; a set whose
//!   simulation fails, or whose measured values leave the loader's plausible ranges
//!   ([`super::data::DYNAMIC_COLUMNS`]), is redrawn.
//! - **Dynamometer**: the measured torque is M_dynamo of eq. (76), M_e through a first-order
//!   lag with [`LabOptions::tau_me_s`] (default 1 s, the torque-sensor time constant of Table 6).
//! - **Sensor time constants** (optional, [`LabOptions::sensor_lags`]): first-order lags with
//!   the maxima of Table 6 (n_t 6 ms, p_em 20 ms, p_im 15 ms, W_c 20 ms).

use super::data::{
    Campaign, DataError, DataSetInfo, DynamicData, Manifest, Role, StationaryPoint, StepKind,
};
use crate::analysis::steady::{steady_state_with, SteadyOptions};
use crate::components::{actuator, egr, turbine, Semantics};
use crate::model::{AnyModel, Drive, Model, ModelOptions, ModelOrder};
use crate::params::Params;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::Path;

/// Fuel at 100 % load [mg/cycle/cylinder].
pub const U_DELTA_MAX: f64 = 220.0;

/// Gaussian measurement noise (standard deviations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Relative standard deviation of pressures, flows, speeds, torque, x_egr, positions [-].
    pub rel: f64,
    /// Standard deviation of temperatures \[K\].
    pub temp_k: f64,
}

impl Noise {
    /// No noise.
    pub const NONE: Noise = Noise {
        rel: 0.0,
        temp_k: 0.0,
    };
    /// The "realistic" default of the module documentation: 0.5 %, 1 K.
    pub const REALISTIC: Noise = Noise {
        rel: 0.005,
        temp_k: 1.0,
    };
}

/// Options of the virtual test cell.
#[derive(Debug, Clone, PartialEq)]
pub struct LabOptions {
    /// Seed of the random generator.
    pub seed: u64,
    /// Measurement noise.
    pub noise: Noise,
    /// Number of stationary points, the 13 ESC points included (>= 13).
    pub n_stationary: usize,
    /// Hold time of each actuator step in set J \[s\].
    pub step_hold_s: f64,
    /// Generate the dynamic sets of Table 1 (A-I, Q-V).
    pub dynamic: bool,
    /// Only these dynamic sets (names of Table 1; None: all).
    pub sets: Option<Vec<String>>,
    /// At most this many steps per dynamic set (None: the counts of Table 1).
    pub max_steps: Option<usize>,
    /// Dynamometer time constant tau_Me of eq. (76) \[s\] (0: the torque is measured directly).
    pub tau_me_s: f64,
    /// Apply the sensor time constants of Table 6 to n_t, p_em, p_im, W_c.
    pub sensor_lags: bool,
    /// Model of the virtual engine (8, 10 or 12 states). With 12 states the stationary p_c is
    /// the state p_c before the intercooler (eq. (87)), above p_im by the drop of eq. (86).
    pub model: ModelOrder,
    /// The engine's operating envelope: the design's speeds and fuel scaled to it (default:
    /// the published engine's).
    pub envelope: Envelope,
}

/// Operating envelope of the virtual engine: the campaign's design (the ESC points, the random
/// stationary points, the speeds of Table 1) is the published engine's mapped onto it.
///
/// Speeds map affinely so that the ESC speeds A, B, C (n_lo + 25, 50, 75 % of n_hi - n_lo, the
/// European Stationary Cycle's definition; 1200, 1500, 1800 r/min for the published engine, so
/// n_lo = 900, n_hi = 2100 r/min) land on this engine's; idle (600 r/min), the random range
/// (800-2000 r/min) and Table 1's speeds move with them. Load L % means u_delta = L/100 *
/// `full_load_mg`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// n_lo of the ESC \[r/min\].
    pub n_lo_rpm: f64,
    /// n_hi of the ESC \[r/min\].
    pub n_hi_rpm: f64,
    /// Injected fuel at 100 % load [mg/cycle/cylinder].
    pub full_load_mg: f64,
}

impl Default for Envelope {
    fn default() -> Self {
        Self::PUBLISHED
    }
}

impl Envelope {
    /// The published engine's: n_lo 900, n_hi 2100 r/min, [`U_DELTA_MAX`] at full load.
    pub const PUBLISHED: Envelope = Envelope {
        n_lo_rpm: 900.0,
        n_hi_rpm: 2100.0,
        full_load_mg: U_DELTA_MAX,
    };

    /// A speed of the published design [r/min] mapped onto this envelope (the identity for
    /// [`Envelope::PUBLISHED`], bit for bit).
    pub fn speed(&self, n_published_rpm: f64) -> f64 {
        let p = Self::PUBLISHED;
        self.n_lo_rpm
            + (n_published_rpm - p.n_lo_rpm)
                * ((self.n_hi_rpm - self.n_lo_rpm) / (p.n_hi_rpm - p.n_lo_rpm))
    }

    /// u_delta [mg/cycle/cylinder] at `load_pct` % load.
    pub fn fuel(&self, load_pct: f64) -> f64 {
        load_pct / 100.0 * self.full_load_mg
    }

    /// Checks the values: positive speeds, n_lo < n_hi, and the design inside the model's input
    /// saturation `limits` (the parameter set's `input_saturation`, items 1-2 of the authors'
    /// implementation: by default n_e in [500, 2000] r/min, u_delta in [1, 250] mg; beyond it
    /// the model would run the clamped value, not the campaign's).
    pub fn validate(&self, limits: &crate::params::InputSaturation) -> Result<(), String> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(self.n_lo_rpm) && ok(self.n_hi_rpm) && self.n_lo_rpm < self.n_hi_rpm) {
            return Err(format!(
                "speeds n_lo {} and n_hi {} r/min: need 0 < n_lo < n_hi",
                self.n_lo_rpm, self.n_hi_rpm
            ));
        }
        let [lo, hi] = limits.n_e;
        let idle = self.speed(ESC_POINTS[0].0);
        let top = self.speed(RANDOM_SPEEDS.1);
        if idle < lo || top > hi {
            return Err(format!(
                "speeds n_lo {} and n_hi {} r/min put the design at {idle:.0}-{top:.0} r/min, \
                 outside the model's speed range {lo}-{hi} r/min (input_saturation.n_e of the \
                 parameter set: the authors' input saturation, item 1)",
                self.n_lo_rpm, self.n_hi_rpm
            ));
        }
        let [f_lo, f_hi] = limits.u_delta;
        let least = self.fuel(ESC_POINTS[0].1);
        if !(ok(self.full_load_mg) && self.full_load_mg <= f_hi && least >= f_lo) {
            return Err(format!(
                "full-load fuel {} mg/cycle/cylinder: the design's {least} (idle) to {} mg must \
                 lie in the model's fuel range {f_lo}-{f_hi} mg/cycle (input_saturation.u_delta, item 2)",
                self.full_load_mg, self.full_load_mg
            ));
        }
        Ok(())
    }
}

impl LabOptions {
    /// The sensor time constants the virtual test cell applies: Table 6's with
    /// `sensor_lags`, none without.
    pub fn sensor_time_constants(&self) -> super::sensors::SensorLags {
        if self.sensor_lags {
            super::sensors::SensorLags::TABLE6
        } else {
            super::sensors::SensorLags::NONE
        }
    }
}

impl Default for LabOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            noise: Noise::REALISTIC,
            n_stationary: 82,
            step_hold_s: 1.0,
            dynamic: true,
            sets: None,
            max_steps: None,
            tau_me_s: 1.0,
            sensor_lags: false,
            model: ModelOrder::Eight,
            envelope: Envelope::PUBLISHED,
        }
    }
}

/// Errors of the virtual test cell.
#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// The parameter set is invalid.
    #[error("invalid parameters: {0}")]
    Params(String),
    /// No valid equilibrium was found for a point after many draws.
    #[error(
        "no physically valid steady state found for stationary point {index} after {tries} draws \
         (the last: {last})"
    )]
    NoValidPoint {
        /// Point index.
        index: usize,
        /// Draws.
        tries: usize,
        /// Why the last draw was refused (no equilibrium, not physically valid, or a value the
        /// loader could refuse, named with its range).
        last: String,
    },
    /// Writing the campaign failed.
    #[error(transparent)]
    Data(#[from] DataError),
    /// Writing the parameter file failed.
    #[error(transparent)]
    Io(#[from] crate::io::IoError),
}

struct Gauss(ChaCha8Rng);

impl Gauss {
    /// Standard normal by Box-Muller.
    fn next(&mut self) -> f64 {
        let u1: f64 = 1.0 - self.0.gen::<f64>(); // (0, 1]
        let u2: f64 = self.0.gen::<f64>();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
    fn rel(&mut self, v: f64, s: f64) -> f64 {
        if s == 0.0 {
            v
        } else {
            v * (1.0 + s * self.next())
        }
    }
    fn abs(&mut self, v: f64, s: f64) -> f64 {
        if s == 0.0 {
            v
        } else {
            v + s * self.next()
        }
    }
}

/// Speed range of the random stationary points of the published design \[r/min\].
pub const RANDOM_SPEEDS: (f64, f64) = (800.0, 2000.0);

/// The 13 ESC operating points (speed [r/min], load [%]).
pub const ESC_POINTS: [(f64, f64); 13] = [
    (600.0, 10.0),
    (1200.0, 100.0),
    (1500.0, 50.0),
    (1500.0, 75.0),
    (1200.0, 50.0),
    (1200.0, 75.0),
    (1200.0, 25.0),
    (1500.0, 100.0),
    (1500.0, 25.0),
    (1800.0, 100.0),
    (1800.0, 25.0),
    (1800.0, 75.0),
    (1800.0, 50.0),
];

/// Noise-free measurement of the equilibrium at `d` (Table 5 variables), or None if there is
/// no physically valid equilibrium.
pub fn stationary_truth<const N: usize, M: Model<N>>(
    m: &M,
    p: &Params,
    d: &Drive,
) -> Option<StationaryPoint> {
    let ss = steady_state_with(m, d, None, &SteadyOptions::default()).ok()?;
    if !ss.physically_valid() {
        return None;
    }
    let s = ss.signals;
    let pi_t = turbine::pi_t(p.ambient.p_amb, ss.x[1], m.options().semantics);
    let t_t = s.t_em * (1.0 - s.eta_tm * (1.0 - pi_t.powf(1.0 - 1.0 / p.gas.gamma_e)));
    Some(StationaryPoint {
        m_e: s.m_e,
        n_e: d.n_e_rpm,
        n_t: s.n_t,
        p_amb: p.ambient.p_amb,
        p_c: s.p_c_out,
        p_em: ss.x[1],
        p_im: ss.x[0],
        t_amb: p.ambient.t_amb,
        t_c: s.t_c,
        t_em: s.t_em,
        t_im: s.t_im,
        t_t,
        u_egr: d.u_egr_pct,
        u_vgt: d.u_vgt_pct,
        u_delta: d.u_delta_mg,
        w_c: s.w_c,
        x_egr: s.x_egr,
    })
}

fn noisy_point(g: &mut Gauss, p: &StationaryPoint, n: Noise) -> StationaryPoint {
    StationaryPoint {
        m_e: g.rel(p.m_e, n.rel),
        n_t: g.rel(p.n_t, n.rel),
        p_c: g.rel(p.p_c, n.rel),
        p_em: g.rel(p.p_em, n.rel),
        p_im: g.rel(p.p_im, n.rel),
        t_c: g.abs(p.t_c, n.temp_k),
        t_em: g.abs(p.t_em, n.temp_k),
        t_im: g.abs(p.t_im, n.temp_k),
        t_t: g.abs(p.t_t, n.temp_k),
        w_c: g.rel(p.w_c, n.rel),
        x_egr: g.rel(p.x_egr, n.rel).clamp(0.0, 1.0),
        ..*p
    }
}

/// Stationary campaign: `opts.n_stationary` valid equilibria (ESC points first), with noise.
/// Returns (noise-free, measured) points.
pub fn stationary(
    p: &Params,
    opts: &LabOptions,
) -> Result<(Vec<StationaryPoint>, Vec<StationaryPoint>), LabError> {
    let m = AnyModel::new(opts.model, p.clone(), ModelOptions::default())
        .map_err(|e| LabError::Params(e.to_string()))?;
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let vertex = (-p.egr_valve.c_egr[1] / (2.0 * p.egr_valve.c_egr[0])).clamp(0.0, 100.0);
    let egr_max = if vertex > 0.0 { 0.99 * vertex } else { 80.0 };
    let mut truth = Vec::with_capacity(opts.n_stationary);
    const TRIES: usize = 200;
    for index in 0..opts.n_stationary.max(13) {
        let mut found = None;
        let mut last = String::new();
        for _ in 0..TRIES {
            let (n_e, load) = if index < 13 {
                ESC_POINTS[index]
            } else {
                (
                    rng.gen_range(RANDOM_SPEEDS.0..RANDOM_SPEEDS.1),
                    rng.gen_range(15.0..100.0),
                )
            };
            // a third of the points without EGR, as in engine-lab practice
            let u_egr = if rng.gen::<f64>() < 0.3 {
                0.0
            } else {
                rng.gen_range(2.0..egr_max)
            };
            let u_vgt = rng.gen_range(20.0..100.0);
            let e = &opts.envelope;
            let d = Drive::new(e.speed(n_e), e.fuel(load), u_egr, u_vgt);
            // an equilibrium whose measurement the loader could refuse (a value near the edge of
            // its plausible range) is redrawn like an invalid one
            match crate::dispatch!(&m, m => stationary_truth(m, p, &d)) {
                None => {
                    last = format!(
                        "n_e {} r/min, u_delta {} mg/cycle: no physically valid equilibrium",
                        d.n_e_rpm, d.u_delta_mg
                    )
                }
                Some(pt) => match outside_loader_range(&pt, opts.noise) {
                    None => {
                        found = Some(pt);
                        break;
                    }
                    Some((c, v)) => {
                        let k = super::data::STATIONARY_COLUMNS
                            .iter()
                            .find(|k| k.name == c)
                            .expect("a stationary column");
                        last = format!(
                            "n_e {} r/min, u_delta {} mg/cycle: {c} = {} {} at or within five noise \
                             standard deviations of the edge of the loader's plausible range \
                             [{}, {}] {} (docs/tuning-data.md)",
                            d.n_e_rpm,
                            d.u_delta_mg,
                            crate::numerics::Num(v),
                            k.unit,
                            k.min,
                            k.max,
                            k.unit
                        )
                    }
                },
            }
        }
        truth.push(found.ok_or(LabError::NoValidPoint {
            index,
            tries: TRIES,
            last,
        })?);
    }
    let mut g = Gauss(ChaCha8Rng::seed_from_u64(opts.seed ^ 0x5eed_0001));
    let meas = truth
        .iter()
        .map(|t| noisy_point(&mut g, t, opts.noise))
        .collect();
    Ok((truth, meas))
}

/// Command levels of set J: (EGR levels, VGT levels); each change is a step.
pub fn actuator_levels() -> (Vec<f64>, Vec<f64>) {
    let mut egr: Vec<f64> = (0..=9).map(|k| 10.0 * k as f64).collect(); // 0..90
    egr.extend((0..9).rev().map(|k| 10.0 * k as f64)); // 80..0
    egr.extend([30.0, 0.0, 75.0, 80.0, 85.0, 80.0, 75.0]); // 30, 30, 75, four 5 % steps
    let mut vgt: Vec<f64> = (0..=9).rev().map(|k| 10.0 + 10.0 * k as f64).collect(); // 100..10
    vgt.extend((1..=9).map(|k| 10.0 + 10.0 * k as f64)); // 20..100
    vgt.extend([95.0, 90.0, 85.0, 90.0, 95.0, 75.0]); // five 5 % steps, one 20 % step
    (egr, vgt)
}

/// Actuator set J at 100 Hz: commands and measured positions (with noise, relative to 100 %).
pub fn actuator_set(p: &Params, opts: &LabOptions) -> DynamicData {
    let (egr, vgt) = actuator_levels();
    let hold = opts.step_hold_s;
    let fs = 100.0;
    let n_seg = egr.len() + vgt.len() - 1;
    let n = (n_seg as f64 * hold * fs).round() as usize;
    // command sequence: EGR steps with VGT at 100 %, then VGT steps with EGR at 0 %
    let mut egr_steps = Vec::new(); // (time, delta)
    let mut vgt_steps = Vec::new();
    for k in 1..egr.len() {
        egr_steps.push((k as f64 * hold, egr[k] - egr[k - 1]));
    }
    let off = (egr.len() - 1) as f64 * hold;
    for k in 1..vgt.len() {
        vgt_steps.push((off + k as f64 * hold, vgt[k] - vgt[k - 1]));
    }
    let mut g = Gauss(ChaCha8Rng::seed_from_u64(opts.seed ^ 0x5eed_000a));
    let level = |steps: &[(f64, f64)], v0: f64, tt: f64| {
        v0 + steps
            .iter()
            .filter(|(ts, _)| *ts <= tt)
            .map(|(_, d)| d)
            .sum::<f64>()
    };
    let t: Vec<f64> = (0..n).map(|i| i as f64 / fs).collect();
    let ue: Vec<f64> = t.iter().map(|&tt| level(&egr_steps, egr[0], tt)).collect();
    let uv: Vec<f64> = t.iter().map(|&tt| level(&vgt_steps, vgt[0], tt)).collect();
    // the true positions: the actuator models driven by the commands after the model's
    // saturation, the parameter set's command ranges (with the authors' ranges, VGT commands
    // below 20 % do not move the actuator further)
    let (sat_egr, sat_vgt) =
        crate::model::command_saturation(Semantics::Authors, &p.input_saturation);
    let pos_e = actuator::position(&t, &ue, sat_egr, |s| {
        egr::actuator_step_response(&p.egr_actuator, s)
    });
    let pos_v = actuator::position(&t, &uv, sat_vgt, |s| {
        turbine::actuator_step_response(&p.vgt_actuator, s)
    });
    let mut pe = Vec::with_capacity(n);
    let mut pv = Vec::with_capacity(n);
    for (e, v) in pos_e.iter().zip(&pos_v) {
        pe.push(g.abs(*e, opts.noise.rel * 100.0));
        pv.push(g.abs(*v, opts.noise.rel * 100.0));
    }
    DynamicData {
        name: "J".into(),
        t,
        columns: vec![
            ("u_egr_pos".into(), pe),
            ("u_vgt_pos".into(), pv),
            ("u_egr".into(), ue),
            ("u_vgt".into(), uv),
        ],
    }
}

/// Generate a campaign in memory: (campaign, noise-free stationary points).
pub fn campaign(
    p: &Params,
    opts: &LabOptions,
) -> Result<(Campaign, Vec<StationaryPoint>), LabError> {
    opts.envelope
        .validate(&p.input_saturation)
        .map_err(LabError::Params)?;
    let (truth, meas) = stationary(p, opts)?;
    let j = actuator_set(p, opts);
    let (egr, vgt) = actuator_levels();
    let mut infos = Vec::new();
    let mut dynamic = Vec::new();
    if opts.dynamic {
        for (info, d) in dynamic_sets(p, opts)? {
            infos.push(info);
            dynamic.push(d);
        }
    }
    infos.push(DataSetInfo {
        name: "J".into(),
        roles: vec![Role::Actuator],
        kind: StepKind::Actuator,
        file: "J.csv".into(),
        sample_rate_hz: 100.0,
        speed_rpm: None,
        load_pct: None,
        steps: Some(egr.len() + vgt.len() - 2),
    });
    dynamic.push(j);
    let manifest = Manifest {
        stationary: "stationary.csv".into(),
        true_params: Some("true_params.toml".into()),
        true_tau_me_s: (opts.dynamic && opts.tau_me_s > 0.0).then_some(opts.tau_me_s),
        true_sensor_lags_s: opts
            .dynamic
            .then(|| opts.sensor_time_constants().as_array()),
        description: format!(
            "virtual test cell (mvem::tuning::lab), seed {}, noise {} relative / {} K gaussian, \
             dynamometer tau_Me {} s, sensor lags {}",
            opts.seed,
            opts.noise.rel,
            opts.noise.temp_k,
            opts.tau_me_s,
            if opts.sensor_lags { "Table 6" } else { "none" }
        ),
        columns: Default::default(),
        units: Default::default(),
        datasets: infos,
    };
    Ok((
        Campaign {
            manifest,
            stationary: meas,
            dynamic,
        },
        truth,
    ))
}

/// One dynamic data set of the paper's Table 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table1Row {
    /// Name (A-I, Q-V).
    pub name: &'static str,
    /// What is stepped.
    pub kind: StepKind,
    /// Roles (Table 1 caption: B, C, I dynamic tuning; A-I static tuning; A, D-I and Q-V
    /// validation).
    pub roles: &'static [Role],
    /// Engine speed [r/min].
    pub speed_rpm: f64,
    /// Load [%] (VGT/EGR sets).
    pub load_pct: Option<f64>,
    /// Number of steps.
    pub steps: usize,
    /// Sample rate \[Hz\].
    pub sample_rate_hz: f64,
    /// Hold time of each step \[s\] (our choice; the paper does not give it).
    pub hold_s: f64,
}

const ST_VA: &[Role] = &[Role::Static, Role::Validation];
const DY_ST: &[Role] = &[Role::Dynamic, Role::Static];
const VA: &[Role] = &[Role::Validation];

#[allow(clippy::too_many_arguments)]
const fn row(
    name: &'static str,
    kind: StepKind,
    roles: &'static [Role],
    speed_rpm: f64,
    load: f64,
    steps: usize,
    sample_rate_hz: f64,
    hold_s: f64,
) -> Table1Row {
    Table1Row {
        name,
        kind,
        roles,
        speed_rpm,
        load_pct: if load > 0.0 { Some(load) } else { None },
        steps,
        sample_rate_hz,
        hold_s,
    }
}

/// The dynamic sets of Table 1 (J, the actuator set, is [`actuator_set`]).
pub const TABLE1: [Table1Row; 15] = [
    row("A", StepKind::VgtEgr, ST_VA, 1200.0, 25.0, 77, 1.0, 6.0),
    row("B", StepKind::VgtEgr, DY_ST, 1200.0, 40.0, 23, 100.0, 4.0),
    row("Q", StepKind::VgtEgr, VA, 1200.0, 40.0, 12, 100.0, 4.0),
    row("C", StepKind::VgtEgr, DY_ST, 1200.0, 50.0, 2, 100.0, 6.0),
    row("R", StepKind::VgtEgr, VA, 1200.0, 50.0, 77, 1.0, 6.0),
    row("D", StepKind::VgtEgr, ST_VA, 1200.0, 75.0, 77, 1.0, 6.0),
    row("S", StepKind::VgtEgr, VA, 1500.0, 25.0, 77, 1.0, 6.0),
    row("E", StepKind::VgtEgr, ST_VA, 1500.0, 50.0, 77, 1.0, 6.0),
    row("T", StepKind::VgtEgr, VA, 1500.0, 75.0, 77, 1.0, 6.0),
    row("F", StepKind::VgtEgr, ST_VA, 1900.0, 25.0, 77, 1.0, 6.0),
    row("U", StepKind::VgtEgr, VA, 1900.0, 50.0, 77, 1.0, 6.0),
    row("G", StepKind::VgtEgr, ST_VA, 1900.0, 75.0, 55, 1.0, 6.0),
    row("H", StepKind::VgtEgr, ST_VA, 1900.0, 100.0, 1, 100.0, 10.0),
    row(
        "I",
        StepKind::Fuel,
        &[Role::Dynamic, Role::Static, Role::Validation],
        1500.0,
        0.0,
        7,
        10.0,
        5.0,
    ),
    row("V", StepKind::Fuel, VA, 1500.0, 0.0, 28, 1.0, 6.0),
];

fn name_seed(seed: u64, name: &str) -> u64 {
    seed ^ name
        .bytes()
        .fold(0xd1_u64, |h, b| h.wrapping_mul(131) ^ b as u64)
}

/// Initial drive and command steps of a Table 1 set (draw `attempt` of the set's sequence).
fn table1_steps(
    p: &Params,
    e: &Envelope,
    r: &Table1Row,
    n_steps: usize,
    seed: u64,
    attempt: u64,
) -> (Drive, Vec<(f64, usize, f64)>) {
    let mut rng = ChaCha8Rng::seed_from_u64(name_seed(seed, r.name).wrapping_add(attempt));
    let vertex = (-p.egr_valve.c_egr[1] / (2.0 * p.egr_valve.c_egr[0])).clamp(0.0, 100.0);
    let egr_max = if vertex > 0.0 { 0.99 * vertex } else { 80.0 };
    let mut steps = Vec::with_capacity(n_steps);
    match r.kind {
        StepKind::Fuel => {
            let (u_egr, u_vgt) = (rng.gen_range(10.0..40.0), rng.gen_range(40.0..80.0));
            let mut level: f64 = rng.gen_range(30.0..90.0);
            let d0 = Drive::new(e.speed(r.speed_rpm), e.fuel(level), u_egr, u_vgt);
            for k in 1..=n_steps {
                let mut next = level;
                while (next - level).abs() < 5.0 {
                    next = rng.gen_range(30.0..90.0);
                }
                level = next;
                steps.push((k as f64 * r.hold_s, 1, e.fuel(level)));
            }
            (d0, steps)
        }
        _ => {
            let load = r.load_pct.unwrap_or(50.0);
            let mut egr = rng.gen_range(0.0..egr_max);
            let mut vgt = rng.gen_range(25.0..100.0);
            let d0 = Drive::new(e.speed(r.speed_rpm), e.fuel(load), egr, vgt);
            for k in 1..=n_steps {
                let (ch, cur, lo, hi) = if rng.gen::<bool>() {
                    (2, &mut egr, 0.0, egr_max)
                } else {
                    (3, &mut vgt, 25.0, 100.0)
                };
                let mut next = *cur;
                while (next - *cur).abs() < 5.0 {
                    next = rng.gen_range(lo..hi);
                }
                *cur = next;
                steps.push((k as f64 * r.hold_s, ch, next));
            }
            (d0, steps)
        }
    }
}

/// Generate the dynamic sets of Table 1 selected by `opts` (in parallel; deterministic).
pub fn dynamic_sets(
    p: &Params,
    opts: &LabOptions,
) -> Result<Vec<(DataSetInfo, DynamicData)>, LabError> {
    let rows: Vec<&Table1Row> = TABLE1
        .iter()
        .filter(|r| {
            opts.sets
                .as_ref()
                .is_none_or(|v| v.iter().any(|n| n == r.name))
        })
        .collect();
    rows.par_iter()
        .map(crate::numerics::cancel::carry(|r: &&Table1Row| {
            let n_steps = opts.max_steps.map_or(r.steps, |m| m.min(r.steps)).max(1);
            let t_end = (n_steps + 1) as f64 * r.hold_s;
            let mut last = String::new();
            for attempt in 0..10 {
                let (d0, steps) = table1_steps(p, &opts.envelope, r, n_steps, opts.seed, attempt);
                match step_set(p, opts, r.name, d0, &steps, t_end, r.sample_rate_hz) {
                    Ok(d) => {
                        let info = DataSetInfo {
                            name: r.name.into(),
                            roles: r.roles.to_vec(),
                            kind: r.kind,
                            file: format!("{}.csv", r.name),
                            sample_rate_hz: r.sample_rate_hz,
                            speed_rpm: Some(opts.envelope.speed(r.speed_rpm)),
                            load_pct: r.load_pct,
                            steps: Some(n_steps),
                        };
                        return Ok((info, d));
                    }
                    Err(e) => last = e.to_string(),
                }
            }
            Err(LabError::Params(format!(
                "data set {}: no valid step sequence in 10 draws ({last})",
                r.name
            )))
        }))
        .collect()
}

/// First-order lag dy/dt = (u - y)/tau on samples `(t, u)`, exact for u linear between samples,
/// starting at y = `u[0]` (steady state) [same unit as u]. tau <= 0 returns u.
pub fn first_order_lag(t: &[f64], u: &[f64], tau: f64) -> Vec<f64> {
    let mut lag = FirstOrderLag::new(tau);
    t.iter().zip(u).map(|(t, u)| lag.next(*t, *u)).collect()
}

/// [`first_order_lag`] sample by sample, for signals that arrive in pieces (the same numbers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FirstOrderLag {
    /// Time constant \[s\].
    tau: f64,
    /// The previous sample: time \[s\], input, output.
    last: Option<(f64, f64, f64)>,
}

impl FirstOrderLag {
    /// A lag with time constant `tau` \[s\] before its first sample.
    pub fn new(tau: f64) -> Self {
        Self { tau, last: None }
    }

    /// The output at the next sample `(t, u)` (the first sample's output is `u`).
    pub fn next(&mut self, t: f64, u: f64) -> f64 {
        let tau = self.tau;
        let y = match self.last {
            _ if tau <= 0.0 => u,
            None => u,
            Some((t0, u0, prev)) => {
                let h = t - t0;
                let a = (-h / tau).exp();
                let b = if h > 0.0 {
                    1.0 - tau * (1.0 - a) / h
                } else {
                    1.0
                };
                a * prev + (1.0 - a) * u0 + b * (u - u0)
            }
        };
        self.last = Some((t, u, y));
        y
    }
}

/// Generate a campaign and write it to `out_dir` (manifest, CSVs, `true_params.toml`).
pub fn generate(params: &Params, opts: &LabOptions, out_dir: &Path) -> Result<Campaign, LabError> {
    let (c, _) = campaign(params, opts)?;
    super::data::save_campaign(out_dir, &c)?;
    crate::io::params::save_params(params, &out_dir.join("true_params.toml"))?;
    Ok(c)
}

/// A dynamic data set with command steps at constant speed (Table 6 columns), simulated with
/// the model of `opts.model` (default 8 states) from the steady state of the first command and sampled at `sample_rate_hz`.
/// `steps`: (time \[s\], channel 1 = u_delta, 2 = u_egr, 3 = u_vgt, new value). Measured
/// outputs get the noise of `opts` (positions: relative to 100 %), the torque the dynamometer
/// lag (eq. (76)) and, optionally, the sensor lags of Table 6.
#[allow(clippy::too_many_arguments)]
pub fn step_set(
    p: &Params,
    opts: &LabOptions,
    name: &str,
    initial: Drive,
    steps: &[(f64, usize, f64)],
    t_end: f64,
    sample_rate_hz: f64,
) -> Result<DynamicData, LabError> {
    use crate::analysis::steady::simulate_from_steady;
    use crate::sim::{InputSchedule, SimOptions};
    let m = AnyModel::new(opts.model, p.clone(), ModelOptions::default())
        .map_err(|e| LabError::Params(e.to_string()))?;
    let sched =
        InputSchedule::steps(initial, steps).map_err(|e| LabError::Params(e.to_string()))?;
    // simulate on a fine grid (lags), then sample at the data rate
    let fine_hz = if opts.sensor_lags { 500.0 } else { 100.0 };
    let ratio = (fine_hz / sample_rate_hz).round().max(1.0) as usize;
    let so = SimOptions {
        dt_out: 1.0 / (sample_rate_hz * ratio as f64),
        ..SimOptions::default()
    };
    // like a stationary point, a set starts from a physically valid equilibrium (near the smoke
    // limit the turbocharger can have a second, slow equilibrium with lambda_O < 1 and
    // saturated efficiencies, from which a tuned model would start on the other branch)
    let valid = crate::dispatch!(&m, m => crate::analysis::steady::steady_state(m, &initial)
        .map(|ss| ss.physically_valid()))
    .map_err(|e| LabError::Params(format!("set {name}: no initial steady state: {e}")))?;
    if !valid {
        return Err(LabError::Params(format!(
            "set {name}: the initial steady state is not physically valid"
        )));
    }
    let sol = crate::dispatch!(&m, m => simulate_from_steady(m, &sched, 0.0, t_end, &so))
        .map_err(|e| LabError::Params(format!("simulation of set {name} failed: {e}")))?;
    let idx: Vec<usize> = (0..sol.len()).step_by(ratio).collect();
    let mut g = Gauss(ChaCha8Rng::seed_from_u64(name_seed(opts.seed, name)));
    let n = opts.noise;
    let lag = |c: &str, tau: f64| -> Vec<f64> {
        let v = sol.get(c).map(|v| v.to_vec()).unwrap_or_default();
        let v = first_order_lag(sol.t(), &v, tau);
        idx.iter().filter_map(|&i| v.get(i).copied()).collect()
    };
    let sensors = opts.sensor_time_constants();
    let sensor = |c: &str| sensors.of(c);
    let noisy = |g: &mut Gauss, v: Vec<f64>, s: f64, abs: bool| -> Vec<f64> {
        v.into_iter()
            .map(|x| if abs { g.abs(x, s) } else { g.rel(x, s) })
            .collect()
    };
    let ts: Vec<f64> = idx.iter().map(|&i| sol.t()[i]).collect();
    // commands as logged: the value in force at each sample (right-continuous: a sample at a
    // step time shows the new value), from the step list itself
    let mut sorted: Vec<&(f64, usize, f64)> = steps.iter().collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let command = |ch: usize| -> Vec<f64> {
        ts.iter()
            .map(|&t| {
                let mut v = initial.to_array()[ch];
                for (tt, c, val) in &sorted {
                    if *c == ch && *tt <= t + 1e-9 {
                        v = *val;
                    }
                }
                v
            })
            .collect()
    };
    let columns = vec![
        (
            "n_t".to_string(),
            noisy(&mut g, lag("n_t", sensor("n_t")), n.rel, false),
        ),
        (
            "p_em".to_string(),
            noisy(&mut g, lag("p_em", sensor("p_em")), n.rel, false),
        ),
        (
            "p_im".to_string(),
            noisy(&mut g, lag("p_im", sensor("p_im")), n.rel, false),
        ),
        (
            "W_c".to_string(),
            noisy(&mut g, lag("W_c", sensor("W_c")), n.rel, false),
        ),
        (
            "u_egr_pos".to_string(),
            noisy(&mut g, lag("u_egr_actual", 0.0), n.rel * 100.0, true),
        ),
        (
            "u_vgt_pos".to_string(),
            noisy(&mut g, lag("u_vgt_actual", 0.0), n.rel * 100.0, true),
        ),
        (
            "M_e".to_string(),
            noisy(&mut g, lag("M_e", opts.tau_me_s), n.rel, false),
        ),
        ("n_e".to_string(), command(0)),
        ("u_egr".to_string(), command(2)),
        ("u_vgt".to_string(), command(3)),
        ("u_delta".to_string(), command(1)),
    ];
    // what the campaign's own loader would refuse (a transient beyond a plausible range, e.g.
    // p_em beyond the pressure range): the set is redrawn
    for (c, v) in &columns {
        let col = super::data::DYNAMIC_COLUMNS.iter().find(|k| k.name == c);
        if let Some((k, x)) = col.and_then(|k| {
            v.iter()
                .find(|x| !(k.min..=k.max).contains(*x))
                .map(|x| (k, x))
        }) {
            return Err(LabError::Params(format!(
                "set {name}: {} = {x} {} outside the loader's plausible range [{}, {}]",
                k.name, k.unit, k.min, k.max
            )));
        }
    }
    Ok(DynamicData {
        name: name.to_string(),
        t: ts,
        columns,
    })
}

/// Measured quantities of a stationary point that get noise ([`noisy_point`]); the others are
/// the test cell's exact inputs and conditions. x_egr is clamped to [0, 1] after its noise.
const NOISY_COLUMNS: [&str; 10] = [
    "M_e", "n_t", "p_c", "p_em", "p_im", "T_c", "T_em", "T_im", "T_t", "W_c",
];

/// The first column of a noise-free stationary point whose value, five standard deviations of
/// `noise` from it, leaves the loader's plausible range ([`super::data::STATIONARY_COLUMNS`]),
/// with its value: the campaign's own loader could refuse the measured point.
fn outside_loader_range(pt: &StationaryPoint, noise: Noise) -> Option<(&'static str, f64)> {
    super::data::STATIONARY_COLUMNS
        .iter()
        .zip(pt.values())
        .find(|(c, v)| {
            let sd = match (NOISY_COLUMNS.contains(&c.name), c.unit) {
                (false, _) => 0.0,
                (true, "K") => noise.temp_k,
                (true, _) => noise.rel * v.abs(),
            };
            // T_t is optional and NaN-free here; a NaN is outside
            !(v - 5.0 * sd >= c.min && v + 5.0 * sd <= c.max)
        })
        .map(|(c, v)| (c.name, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_published_envelope_is_the_identity_and_another_maps_the_esc_speeds() {
        let e = Envelope::PUBLISHED;
        for n in [
            600.0, 800.0, 1200.0, 1234.5678, 1500.0, 1800.0, 1900.0, 2000.0,
        ] {
            assert_eq!(e.speed(n), n, "bit for bit");
        }
        assert_eq!(e.fuel(50.0), 50.0 / 100.0 * U_DELTA_MAX);
        let limits = crate::params::InputSaturation::default();
        assert!(e.validate(&limits).is_ok());
        // an engine with n_lo 700, n_hi 1900: ESC A/B/C at 1000/1300/1600 r/min
        let o = Envelope {
            n_lo_rpm: 700.0,
            n_hi_rpm: 1900.0,
            full_load_mg: 150.0,
        };
        for (a, b) in [
            (1200.0, 1000.0),
            (1500.0, 1300.0),
            (1800.0, 1600.0),
            (600.0, 400.0),
        ] {
            assert!((o.speed(a) - b).abs() < 1e-9, "{a} -> {}", o.speed(a));
        }
        assert_eq!(o.fuel(100.0), 150.0);
        // idle at 400 r/min is below the model's speed saturation (500 r/min)
        let err = o.validate(&limits).unwrap_err();
        assert!(err.contains("400-1800 r/min"), "{err}");
        let ok = Envelope {
            n_lo_rpm: 800.0,
            ..o
        };
        assert!(ok.validate(&limits).is_ok());
        let rich = Envelope {
            full_load_mg: 260.0,
            ..ok
        };
        assert!(rich
            .validate(&limits)
            .unwrap_err()
            .contains("fuel range 1-250"));
        let bad = Envelope {
            n_lo_rpm: 2000.0,
            n_hi_rpm: 1000.0,
            ..ok
        };
        assert!(bad.validate(&limits).unwrap_err().contains("n_lo < n_hi"));
        // an engine whose parameter set allows 400 r/min
        let low = crate::params::InputSaturation {
            n_e: [350.0, 2000.0],
            ..limits
        };
        assert!(o.validate(&low).is_ok());
    }

    #[test]
    fn a_campaign_follows_its_envelope() {
        let opts = LabOptions {
            noise: Noise::NONE,
            n_stationary: 20,
            dynamic: false,
            envelope: Envelope {
                n_lo_rpm: 800.0,
                n_hi_rpm: 1800.0,
                full_load_mg: 150.0,
            },
            ..LabOptions::default()
        };
        let (truth, _) = stationary(&Params::published(), &opts).unwrap();
        let e = opts.envelope;
        for (s, (n, load)) in truth.iter().zip(ESC_POINTS) {
            assert!((s.n_e - e.speed(n)).abs() < 1e-9);
            assert!((s.u_delta - e.fuel(load)).abs() < 1e-9);
        }
        for s in &truth[13..] {
            assert!((e.speed(RANDOM_SPEEDS.0)..=e.speed(RANDOM_SPEEDS.1)).contains(&s.n_e));
            assert!(s.u_delta <= 150.0);
        }
        let sets = dynamic_sets(
            &Params::published(),
            &LabOptions {
                sets: Some(vec!["I".into()]),
                max_steps: Some(2),
                dynamic: true,
                ..opts.clone()
            },
        )
        .unwrap();
        assert_eq!(sets[0].0.speed_rpm, Some(e.speed(1500.0)));
        let n_e = sets[0].1.get("n_e").expect("n_e column");
        assert!(n_e.iter().all(|&n| (n - e.speed(1500.0)).abs() < 1e-9));
    }
}
