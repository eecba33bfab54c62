//! The five-step tuning pipeline of the paper (sections 2.3, 8.1) from data only.
//!
//! 1. static submodels from the stationary points ([`super::steps::step1`], generic starts);
//! 2. actuators from the actuator set ([`super::steps::step2`]);
//! 3. V_im, V_em, J_t from the dynamic-tuning VGT/EGR sets ([`super::complete::step3`]);
//! 4. tau_Me from the dynamic-tuning fuel set ([`super::complete::step4`]);
//! 5. the static parameters by cost (77) on the static-tuning sets and the stationary points
//!    ([`super::complete::step5`]), started from the step-1 values (or eq. (78)).
//!
//! With [`PipelineOptions::model`] = 12 the three steps of section 9.2.1 follow
//! ([`super::twelve`]): k_ic by linear least squares (always), V_ic with V_im, V_em, J_t by
//! (74)-(75) on the 12-state model (when step 3 is selected), the static parameters with k_ic
//! by (77), N = 8, z_8 = W_ic, beta = 2.58 (when step 5 is selected).
//!
//! `base` supplies the constants that are not tuned (gas properties, geometry, A_egrmax, ...)
//! and the values of the parameters of the steps that are not run. Steps 1-4 start from generic
//! values, never from `base`; step 5 ([`Init::Step1`], the default) starts from the static
//! parameters as they are when it begins: step 1's, or, when step 1 is not run, `base`'s
//! ([`Init::Naive`]: eq. (78) from the bounds, whatever ran). A failing step stops the pipeline
//! with a [`PipelineError`] naming it.

use super::complete::{
    dynamic_residuals, fit_dynamic, naive_theta, sets_with_role, static_params, static_theta,
    step3, step4, step5, step5_bounds, theta_of, torque_residuals, CompleteReport, Cost77,
    DynamicFit, Step3Start, Step5Options, Step5Report, StepLevels, PUBLISHED_V_D,
};
use super::constants::{
    ambient_from_stationary, implausible_constants, widen_input_saturation,
    widen_integrator_limits, AmbientFromData, AmbientSource, InputRangeSource, InputRangesWidened,
    TurboLimitWidened,
};
use super::data::{Campaign, DynamicData, Role, StepKind};
use super::sensors::{SensorLagMode, SensorLags, MAX_LAG_S};
use super::steps::{
    step1_with, step2, FitReport, Step1Report, Step1Start, Step2Start, StepError, SEM,
};
use super::twelve::{fit_k_ic, intake_volume, BETA_12, V_IC_START};
use super::uncertainty::{
    block_covariance, estimates_from_cov, fd_jacobian_named, function_std_error, joint_covariance,
    sensitivity, sigma_point_jacobian_named, step1_estimates, step2_estimates, toml_path,
    Combination, Conditional, FixedJacobian, Linearization, NamedCov, ParamEstimate,
};
use super::validate::{
    dynamic_errors_with, oscillation_summary, DataSetErrors, OscillationSummary, ValidateError,
};
use crate::components::{compressor, pow_ln, turbine, Semantics};
use crate::model::ModelOrder;
use crate::params::Params;
use nalgebra::DMatrix;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// Initialization of the static parameters of step 5.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all(deserialize = "kebab-case"))]
pub enum Init {
    /// The step-1 values (or the values of `base` when step 1 is not run).
    Step1,
    /// Eq. (78) from the bounds (section 8.2, method (a)).
    Naive,
}

/// Options of the pipeline.
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineOptions {
    /// Which of steps 1-5 to run.
    pub steps: [bool; 5],
    /// Start of step 5.
    pub init: Init,
    /// Step 3 start and bounds, for the published engine: [`tune`] scales them to the base
    /// parameter set's displacement and compressor radius ([`Step3Start::scaled_to`]).
    pub step3: Step3Start,
    /// Step 3 evaluation limit.
    pub step3_max_eval: usize,
    /// Step 5 options (cost rows, beta, gamma_j, evaluation limit).
    pub step5: Step5Options,
    /// After step 5, run steps 3 and 4 again with the final static parameters (not in the
    /// paper; step 3 on step-1 static parameters carries their stationary errors into V_im,
    /// V_em; see docs/tuning.md); with `model` = 12 also step 7 again after step 8, on step 8's
    /// static parameters. Default on; only steps that are selected are repeated.
    pub refine_dynamics: bool,
    /// Model tuned: 8 (steps 1-5) or 12 (steps 1-5, then the three steps of section 9.2.1).
    pub model: ModelOrder,
    /// With `refine_dynamics`: run a second round of steps 5 and 3 (step 5 on the repeated
    /// step 3's V_im, V_em, J_t, then step 3 again) and report the static parameters and V_im,
    /// V_em, J_t with their joint covariance at that fixed point of the alternation
    /// ([`super::uncertainty::joint_covariance`]) instead of chaining the steps' covariances.
    /// Default off: measured in session 9 (docs/tuning.md) with the second round, the
    /// compressor-map flags and step 5's relative-offset stop, it makes V_im, V_em, J_t
    /// identifiable on `mvem lab` seeds 2 and 4 but reports c_vgt1 3.3 standard errors off on
    /// seed 3, gives the volumes of a different engine's campaign rel. std. errors of 170-550 %
    /// and costs about +50 % CPU on seed 1 (37 s -> 59 s).
    pub joint_uncertainty: bool,
    /// Step 5 in two passes when the model at its start oscillates where the engine does not
    /// ([`super::validate::sustained_oscillations`] on the step-5 sets): first without those
    /// sets, then on all sets from that result. A limit cycle makes cost (77) rough (its phase
    /// moves with every parameter), and a local search started in it stays in it. Default on
    /// (session 13): of nine `mvem lab` campaigns only seed 5's steps 1-4 model oscillates (set
    /// A); there it ends at cost 1.466e-3 instead of 1.560e-3 and validates at 1.29x instead of
    /// 2.04x the noise floor, at the price of a first pass that runs to its evaluation limit
    /// (4 345 evaluations in all, about 3-6 minutes instead of 1); the other campaigns are
    /// unchanged (docs/tuning.md, sessions 12 and 13).
    pub stage_oscillating: bool,
    /// The evaluation limit of the first pass of a staged step 5 ([`Self::stage_oscillating`]);
    /// the second pass keeps `step5.max_evaluations`. Default 3600 (as step 5's own limit):
    /// seed 5 capped at 300 or 800 validated at 1.97x / 1.67x the noise floor, against 1.29x
    /// uncapped.
    pub stage_first_pass_max_evaluations: usize,
    /// Step 1 fits the compressor flow (eqs (66)-(72)) also to the settled ends of the
    /// static-tuning sets' command steps ([`super::settled::flow_points`]; the paper tunes the
    /// static models on sets A-I too), not only to the stationary points, and step 5's W_c
    /// submodel row runs over the same points ([`Step5Options::flow_points`]). Default on
    /// (session 15): on `mvem lab` seed 5 the stationary points alone leave the map 8-15 % low
    /// at the Pi_c of about 1.03 where set A settles; the tuned model then has no equilibrium on
    /// 36 of A's 77 holds and oscillates there. With these points it settles on every hold and
    /// follows A's plateaus; validation over nine campaigns 1.22x -> 1.14x the noise floor on
    /// average, seed 5 1.66x -> 1.19x (docs/tuning.md, session 15). Not used for the 12-state
    /// model, whose p_c the dynamic sets do not record.
    pub settled_flow_points: bool,
    /// Sensor lags of p_im, p_em, W_c, n_t ([`super::sensors`]): fitted in step 3 (the
    /// default), known, or none (the paper). Whatever step 3 ends with is held in step 5 and
    /// used by the final checks, and reported in [`TuneReport::sensor_lags`]. Fitting by
    /// default (session 17): on `mvem lab --sensor-lags` campaigns the volumes and J_t tuned
    /// without lags were 23-76 % off and reported identifiable (docs/tuning.md).
    pub sensor_lags: SensorLagMode,
    /// How J_f, the Jacobian of the dynamic steps' residuals with respect to the parameters
    /// they hold fixed, is computed for `Cov + S C_f S^T` ([`FixedJacobian`]; `mvem tune
    /// --fixed-jacobian`). Default forward differences (as since session 10); the sigma points
    /// give fixed-parameter standard errors that do not move with the simulations' rounding
    /// (docs/tuning.md, session 22).
    pub fixed_jacobian: FixedJacobian,
    /// Where p_amb, T_amb, T_im (and a tied T_w) come from: the means of the stationary points
    /// where they contradict the base parameter set (default), always, or never
    /// ([`super::constants::ambient_from_stationary`]).
    pub ambient: AmbientSource,
    /// The model's input ranges (`[input_saturation]`): the base parameter set's, widened to
    /// contain the campaign's speeds and fuel (default), or as they are
    /// ([`super::constants::widen_input_saturation`]).
    pub input_ranges: InputRangeSource,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        Self {
            steps: [true; 5],
            init: Init::Step1,
            step3: Step3Start::default(),
            step3_max_eval: 100,
            step5: Step5Options::default(),
            refine_dynamics: true,
            model: ModelOrder::Eight,
            joint_uncertainty: false,
            stage_oscillating: true,
            stage_first_pass_max_evaluations: 3600,
            settled_flow_points: true,
            sensor_lags: SensorLagMode::Fit,
            fixed_jacobian: FixedJacobian::Forward,
            ambient: AmbientSource::Auto,
            input_ranges: InputRangeSource::Campaign,
        }
    }
}

/// Parse a step selection like "1-5", "1-4", "3,4" or "5".
pub fn parse_steps(s: &str) -> Result<[bool; 5], String> {
    let mut out = [false; 5];
    for part in s.split(',') {
        let part = part.trim();
        let (a, b) = match part.split_once('-') {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (part, part),
        };
        let n = |x: &str| -> Result<usize, String> {
            match x.parse::<usize>() {
                Ok(v) if (1..=5).contains(&v) => Ok(v),
                _ => Err(format!("step {x:?} is not a number 1-5 (in {s:?})")),
            }
        };
        let (a, b) = (n(a)?, n(b)?);
        if a > b {
            return Err(format!("step range {part:?} is decreasing"));
        }
        for k in a..=b {
            out[k - 1] = true;
        }
    }
    Ok(out)
}

/// What the pipeline did.
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct TuneReport {
    /// The ambient conditions chosen before step 1 from the stationary points' means and the
    /// base parameter set (option `ambient`; `None` without stationary points).
    pub ambient: Option<AmbientFromData>,
    /// The base parameter set's input ranges widened to the campaign before step 1 (option
    /// `input_ranges`; `None` when the campaign lies inside them).
    pub input_saturation: Option<InputRangesWidened>,
    /// The base parameter set's turbo-speed integrator limit widened to the campaign's turbo
    /// speeds before step 1 (option `input_ranges`; `None` when the campaign lies below it).
    pub integrator_limits: Option<TurboLimitWidened>,
    /// Step 1 submodel fits.
    pub step1: Option<Step1Report>,
    /// Settled ends of command steps in the compressor-flow fit of step 1 besides the
    /// stationary points (option `settled_flow_points`; 0: stationary points only).
    pub step1_settled_flow_points: usize,
    /// How steps 3, 4 (and 7) matched the simulated step levels to the measured ones
    /// ([`StepLevels`]).
    pub step_levels: Option<StepLevels>,
    /// Step 2 actuator fits.
    pub step2: Option<Vec<FitReport>>,
    /// Step 3.
    pub step3: Option<CompleteReport>,
    /// Step 4.
    pub step4: Option<CompleteReport>,
    /// Tuned dynamometer time constant tau_Me \[s\] (eq. (76); not part of the model parameters).
    pub tau_me_s: Option<f64>,
    /// Sensor lags of p_im, p_em, W_c, n_t \[s\] that steps 3-5 used (fitted or given; test-cell
    /// quantities like tau_Me); None when step 3 did not run and none were given.
    pub sensor_lags: Option<SensorLags>,
    /// Step 5.
    pub step5: Option<Step5Report>,
    /// Step 3 repeated after step 5 (option `refine_dynamics`; with `joint_uncertainty` the
    /// last of its two repetitions).
    pub step3_refined: Option<CompleteReport>,
    /// Step 5 repeated on the V_im, V_em, J_t of the repeated step 3 (options
    /// `refine_dynamics` and `joint_uncertainty`: the second round of the alternation).
    pub step5_refined: Option<Step5Report>,
    /// Step 4 repeated after step 5 (option `refine_dynamics`).
    pub step4_refined: Option<CompleteReport>,
    /// Whether the uncertainty of the static parameters and V_im, V_em, J_t is their joint
    /// covariance at the fixed point of step 5 and the repeated step 3 (option
    /// `joint_uncertainty`; false when not computed or singular: then chained step by step).
    pub joint_uncertainty: bool,
    /// How J_f of the fixed parameters' contribution was computed (option `fixed_jacobian`).
    pub fixed_jacobian: FixedJacobian,
    /// The 12-state steps of section 9.2.1 (option `model` = 12).
    pub twelve: Option<TwelveReport>,
    /// How well each tuned parameter is known, keyed by its name in the parameter registry
    /// ("exhaust_manifold.v_em", elements 1-based: `"cylinder.c_vol[1]"` is c_vol1,
    /// `"compressor.q_c[1][2]"` is a3, as [`crate::params::Params::get`], the FMU and Python's
    /// `params=` name them; tau_Me: "test_cell.tau_me"), from the last step that tuned it
    /// ([`super::uncertainty`]).
    pub parameters: BTreeMap<String, ParamEstimate>,
    /// Functions of parameters that the campaign determines although the parameters are not
    /// identifiable one by one (eta_tm at the measured blade speed ratio,
    /// `turbine_efficiency_on_the_measured_range`; eta_c at a measured compressor operating
    /// point, `compressor_efficiency_on_the_measured_range`).
    pub combinations: Vec<Combination>,
    /// Sustained oscillations of the tuned model under constant commands that the engine does
    /// not show, on the campaign's dynamic sets (not the actuator sets;
    /// [`super::validate::sustained_oscillations`]); empty when it settles like the engine or
    /// when a set cannot be simulated (validate reports that).
    pub oscillations: Vec<OscillationSummary>,
    /// Sets of the campaign (not the actuator sets) that the tuned model cannot simulate, each
    /// with the simulator's message (time and state of the failure): the parameters are not
    /// usable on those inputs, whatever the cost function said (a failed simulation enters
    /// cost (77) as a constant). Empty when every set runs.
    pub failed_sets: Vec<SetFailure>,
    /// What the standard errors of `parameters` do not cover, in words (empty: nothing known);
    /// printed by `mvem tune` and in tune_report.md ([`inherited_static_bias`]).
    pub caveats: Vec<String>,
    /// Wall time of each step \[s\] (0 when not run).
    pub seconds: [f64; 5],
    /// Total wall time \[s\].
    pub total_seconds: f64,
}

/// The three 12-state steps of section 9.2.1.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TwelveReport {
    /// First step: k_ic by linear least squares (errors of p_c - p_im).
    pub k_ic: FitReport,
    /// Second step: V_ic, V_im, V_em, J_t by (74)-(75) on the 12-state model.
    pub dynamic: Option<CompleteReport>,
    /// The second step repeated after the third, on its static parameters (option
    /// `refine_dynamics`, as step 3 after step 5); the reported V_ic, V_im, V_em, J_t are its.
    pub dynamic_refined: Option<CompleteReport>,
    /// Third step: the static parameters and k_ic by (77), N = 8, z_8 = W_ic, beta = 2.58.
    pub statics: Option<Step5Report>,
    /// Wall time \[s\].
    pub seconds: f64,
}

/// A failed pipeline step.
#[derive(Debug, thiserror::Error)]
#[error("tuning step {step} ({}) failed: {source}", step_title(*.step))]
pub struct PipelineError {
    /// Step number 1-5; 6-8 for the three 12-state steps of section 9.2.1.
    pub step: u8,
    /// Cause.
    #[source]
    pub source: StepError,
}

/// What tuning step `step` estimates (for messages).
pub fn step_title(step: u8) -> &'static str {
    match step {
        1 => "static submodels from the stationary points",
        2 => "actuators from the actuator set",
        3 => "V_im, V_em, J_t",
        4 => "tau_Me",
        5 => "static parameters by cost (77)",
        6 => "k_ic",
        7 => "V_ic, V_im, V_em, J_t of the 12-state model",
        8 => "static parameters and k_ic of the 12-state model",
        _ => "result",
    }
}

/// Stop before step `step` if the caller cancelled ([`crate::numerics::cancel`]): a step
/// whose searches were cancelled may have ended with what it had, so the pipeline checks
/// between its steps too.
fn checkpoint(step: u8) -> Result<(), PipelineError> {
    if crate::numerics::cancel::requested() {
        return Err(PipelineError {
            step,
            source: StepError::Cancelled,
        });
    }
    Ok(())
}

/// Begin step `step`: stop if the caller cancelled ([`checkpoint`]), else report the stage
/// ([`crate::numerics::progress`]; `again`: a repeated step).
fn begin(step: u8, again: bool) -> Result<(), PipelineError> {
    checkpoint(step)?;
    crate::numerics::progress::report(|| crate::numerics::progress::Progress::Stage {
        name: format!(
            "step {step} ({}){}",
            step_title(step),
            if again { ", again" } else { "" }
        ),
    });
    Ok(())
}

fn at(step: u8) -> impl Fn(StepError) -> PipelineError {
    move |source| PipelineError { step, source }
}

fn missing(step: u8, what: &str) -> PipelineError {
    PipelineError {
        step,
        source: StepError::Solver {
            submodel: "data",
            message: format!(
                "the campaign has no {what}; select the steps it supports (`mvem tune \
                 --steps`): the steps not run take their parameters from the base set (--params)"
            ),
        },
    }
}

/// Run the selected steps on a campaign; returns the tuned parameters and the report.
pub fn tune(
    c: &Campaign,
    base: &Params,
    opts: &PipelineOptions,
) -> Result<(Params, TuneReport), PipelineError> {
    let t_all = Instant::now();
    // the settled ends of the dynamic sets' holds: further compressor flow points of step 1's
    // flow fit and of step 5's W_c submodel row
    let flow_extra = if opts.settled_flow_points && opts.model != ModelOrder::Twelve {
        super::settled::flow_points(c)
    } else {
        Vec::new()
    };
    let opts = &mut PipelineOptions {
        step5: Step5Options {
            flow_points: flow_extra.clone(),
            ..opts.step5.clone()
        },
        ..opts.clone()
    };
    // the sensor lags: step 3 fits them or holds the given ones, steps 4-5 hold step 3's
    let given = match opts.sensor_lags {
        SensorLagMode::None => Some(SensorLags::NONE),
        SensorLagMode::Known(l) => Some(l),
        SensorLagMode::Fit => None,
    };
    opts.step3.fit_lags = given.is_none();
    if let Some(l) = given {
        opts.step3.lags = l;
    }
    opts.step5.sensor_lags = opts.step3.lags;
    // step 3's start and bounds are given for the published engine: scale them to this one's
    // displacement and compressor radius (the identity for the published engine)
    opts.step3 = opts.step3.scaled_to(base);
    let mut p = base.clone();
    let mut rep = TuneReport {
        fixed_jacobian: opts.fixed_jacobian,
        ..TuneReport::default()
    };
    // the test cell's ambient conditions: measured at every stationary point
    rep.ambient = ambient_from_stationary(&mut p, &c.stationary, opts.ambient);
    // the model's input ranges contain the campaign (another engine's speeds run unclamped)
    rep.input_saturation = widen_input_saturation(&mut p, c, opts.input_ranges);
    // and its turbo-speed limit contains the campaign's turbo speeds (a small turbocharger)
    rep.integrator_limits = widen_integrator_limits(&mut p, c, opts.input_ranges);
    // inputs the model would run clamped (the parameter set's input saturation), turbo speeds
    // it cannot reach (its integrator limit)
    rep.caveats
        .extend(super::constants::inputs_outside_saturation(&p, c));
    rep.caveats
        .extend(super::constants::turbo_speeds_above_limit(&p, c));
    // estimates by tuning name; a later step overwrites an earlier one
    let mut est: Vec<(String, ParamEstimate)> = Vec::new();
    // covariance of every estimate so far (blocks of the steps), carried into the later steps
    let mut cov = NamedCov::default();
    // step 5's linearization, for the joint covariance with the repeated step 3
    let mut cond5: Option<Conditional> = None;
    let infos = &c.manifest.datasets;
    if opts.steps[0] {
        begin(1, false)?;
        let t = Instant::now();
        let (q, r) =
            step1_with(&p, &c.stationary, &flow_extra, &Step1Start::default()).map_err(at(1))?;
        p = q;
        rep.step1_settled_flow_points = flow_extra.len();
        let bounds =
            super::steps::at_bounds(&r, &super::scale::CampaignScale::of(&p, &c.stationary));
        if !bounds.is_empty() {
            let list: Vec<String> = bounds
                .iter()
                .map(|(n, v, b)| format!("{n} = {v:.4e} (bound {b:e})"))
                .collect();
            rep.caveats.push(format!(
                "step 1 ended with {} on or beyond the edge of its search box (step 5's box, \
                 complete::STATIC_PARAMS, scaled to the campaign's measured flows and pressure \
                 ratios by tuning::scale): there the search stopped, the data's optimum may lie \
                 beyond, and step 5 starts from the box's edge",
                list.join(", ")
            ));
        }
        let (e, k) = step1_estimates(&p, &c.stationary, &flow_extra, &r);
        est.extend(e);
        cov.set_block(&k);
        rep.step1 = Some(r);
        rep.seconds[0] = t.elapsed().as_secs_f64();
    }
    if opts.steps[1] {
        begin(2, false)?;
        let t = Instant::now();
        let j = sets_with_role(infos, &c.dynamic, Role::Actuator, false);
        let j = j
            .first()
            .ok_or_else(|| missing(2, "actuator data set (role \"actuator\")"))?;
        let (q, r) = step2(&p, j, &Step2Start::default()).map_err(at(2))?;
        p = q;
        let (e, k) = step2_estimates(&p, j);
        est.extend(e);
        cov.set_block(&k);
        rep.step2 = Some(r);
        rep.seconds[1] = t.elapsed().as_secs_f64();
    }
    if opts.steps[2] || opts.steps[3] {
        rep.step_levels = Some(opts.step3.window.levels);
    }
    if opts.steps[2] {
        begin(3, false)?;
        let t = Instant::now();
        let sets = sets_with_role(infos, &c.dynamic, Role::Dynamic, true);
        if sets.is_empty() {
            return Err(missing(3, "VGT/EGR data set with role \"dynamic\""));
        }
        let r = run_step3(&mut p, &sets, c, opts, &mut cov, &mut est)?.0;
        hold_lags(opts, &r);
        rep.step3 = Some(r);
        rep.seconds[2] = t.elapsed().as_secs_f64();
    }
    if opts.steps[3] {
        begin(4, false)?;
        let t = Instant::now();
        let set = infos
            .iter()
            .zip(&c.dynamic)
            .find(|(i, _)| i.roles.contains(&Role::Dynamic) && i.kind == StepKind::Fuel)
            .map(|(_, d)| d)
            .ok_or_else(|| missing(4, "fuel-step data set with role \"dynamic\""))?;
        // the last pass carries the uncertainty of what it holds fixed: this one when step 4
        // is not repeated after step 5
        let last = !(opts.refine_dynamics && opts.steps[4]);
        let (tau, r) = run_step4(&p, set, c, last, opts, &mut cov, &mut est)?;
        rep.tau_me_s = Some(tau);
        rep.step4 = Some(r);
        rep.seconds[3] = t.elapsed().as_secs_f64();
    }
    if opts.steps[4] {
        begin(5, false)?;
        let t = Instant::now();
        let th0 = match opts.init {
            Init::Step1 => static_theta(&p),
            Init::Naive => naive_theta(),
        };
        let (r, c5) = run_step5(&mut p, c, &th0, opts, &mut cov, &mut est)?;
        cond5 = c5;
        rep.step5 = Some(r);
        rep.seconds[4] = t.elapsed().as_secs_f64();
    }
    if opts.refine_dynamics && opts.steps[4] {
        begin(3, true)?;
        let t = Instant::now();
        let sets = sets_with_role(infos, &c.dynamic, Role::Dynamic, true);
        if opts.steps[2] && !sets.is_empty() {
            let (r, _) = run_step3(&mut p, &sets, c, opts, &mut cov, &mut est)?;
            hold_lags(opts, &r);
            rep.step3_refined = Some(r);
            if opts.joint_uncertainty && cond5.is_some() {
                // a second round, step 5 on the repeated step 3's V_im, V_em, J_t, then step 3
                // again: the first step 5 ran on the first step-3 pass (on the step-1 static
                // parameters), so its result depends on those volumes and is not yet the
                // fixed point the joint covariance describes
                let th0 = static_theta(&p);
                let (r5, c5) = run_step5(&mut p, c, &th0, opts, &mut cov, &mut est)?;
                let stop = r5.early_stop();
                rep.step5_refined = Some(r5);
                let (r, c3) = run_step3(&mut p, &sets, c, opts, &mut cov, &mut est)?;
                hold_lags(opts, &r);
                rep.step3_refined = Some(r);
                if let (Some(c5), Some(c3)) = (&c5, &c3) {
                    rep.joint_uncertainty =
                        joint_step5_step3(c5, c3, &mut cov, &mut est, &p, stop.as_deref());
                }
            }
        }
        if let Some(set) = infos
            .iter()
            .zip(&c.dynamic)
            .find(|(i, _)| i.roles.contains(&Role::Dynamic) && i.kind == StepKind::Fuel)
            .map(|(_, d)| d)
            .filter(|_| opts.steps[3])
        {
            begin(4, true)?;
            let (tau, r) = run_step4(&p, set, c, true, opts, &mut cov, &mut est)?;
            rep.tau_me_s = Some(tau);
            rep.step4_refined = Some(r);
        }
        rep.seconds[2] += t.elapsed().as_secs_f64();
    }
    if opts.model == ModelOrder::Twelve {
        begin(6, false)?;
        let last5 = rep.step5_refined.as_ref().or(rep.step5.as_ref());
        let stop5 = last5.and_then(Step5Report::early_stop);
        rep.twelve = Some(tune_twelve(c, &mut p, opts, stop5, &mut cov, &mut est)?);
    }
    // the last step run (0: none), which the checks of the result are reported under
    let last_step = opts
        .steps
        .iter()
        .rposition(|s| *s)
        .map_or(0, |i| i as u8 + 1);
    // a search cancelled in the last step may have returned what it had
    checkpoint(last_step)?;
    p.validate().map_err(|e| PipelineError {
        step: last_step,
        source: StepError::Solver {
            submodel: "result",
            message: format!("the tuned parameters are invalid: {e}"),
        },
    })?;
    if let Some(t) = &rep.twelve {
        // step 8's estimates are in `est` already (run_static_step)
        for r in [&t.dynamic, &t.dynamic_refined].into_iter().flatten() {
            est.extend(r.uncertainty.iter().cloned());
        }
    }
    if opts.steps[2] || given.is_some() {
        rep.sensor_lags = Some(opts.step5.sensor_lags);
    }
    for (name, e) in est {
        let key = if name == "tau_me" || SensorLags::index(&name).is_some() {
            Some(format!("test_cell.{name}"))
        } else {
            toml_path(&name).map(str::to_string)
        };
        if let Some(k) = key {
            // the reported value is the final one (ties such as Q_c symmetry applied)
            let value = super::complete::param_value(&p, &name).unwrap_or(e.value);
            rep.parameters.insert(k, ParamEstimate { value, ..e });
        }
    }
    flag_extrapolated_efficiency_peak(&p.compressor, &c.stationary, &mut rep.parameters);
    flag_flow_map_coefficients(&mut rep.parameters);
    flag_vgt_area_map(&mut rep.parameters);
    flag_efficiency_ellipse_shape(&mut rep.parameters);
    flag_maps_known_only_as_a_whole(&mut rep.parameters);
    flag_a3_on_the_psd_edge(&p.compressor.q_c, &mut rep.parameters);
    // steps 3-4 repeated on the static maps of a step 5 stopped short of its optimum
    let last5 = rep.step5_refined.as_ref().or(rep.step5.as_ref());
    if let Some(stop) = last5.and_then(Step5Report::early_stop) {
        flag_rests_on_unconverged_step5(
            &mut rep.parameters,
            &stop,
            rep.step3_refined.is_some(),
            rep.step4_refined.is_some(),
        );
    }
    if opts.steps[0] || opts.steps[4] {
        rep.combinations
            .extend(turbine_efficiency_on_the_measured_range(
                &p,
                &c.stationary,
                &cov,
                &mut rep.parameters,
            ));
        rep.combinations
            .extend(compressor_efficiency_on_the_measured_range(
                &p,
                &c.stationary,
                &cov,
                &mut rep.parameters,
            ));
    }
    // V_ic + V_im from the last step-7 pass (the one whose values are reported)
    let v_sum = rep.twelve.as_ref().and_then(|t| {
        t.dynamic_refined
            .as_ref()
            .or(t.dynamic.as_ref())
            .and_then(intake_volume)
    });
    if let Some(mut k) = v_sum {
        let why = format!(
            "V_ic + V_im = {:.4e} +- {:.2e} m^3 is determined (tune_report \"combinations\")",
            k.value, k.std_error
        );
        let keys = ["intercooler.v_ic", "intake_manifold.v_im"];
        // a sum of estimates flagged not converged (step 7 stopped short, or on the maps of a
        // step 8 that did): its standard error does not cover that either
        if keys
            .iter()
            .any(|key| rep.parameters.get(*key).is_some_and(|e| !e.converged))
        {
            k.description.push_str(
                "; V_ic and V_im are flagged not converged (their reasons in the parameter \
                 table), which this standard error does not cover either",
            );
        }
        for key in keys {
            if let Some(e) = rep.parameters.get_mut(key).filter(|e| !e.identifiable) {
                e.reason = format!("{}; {why}", e.reason);
            }
        }
        rep.combinations.push(k);
    }
    // constants the campaign contradicts (displacement, cylinders, heating value)
    rep.caveats
        .extend(implausible_constants(&p, &c.stationary, opts.steps[0]));
    rep.caveats.extend(inherited_static_bias(&rep.parameters));
    rep.caveats
        .extend(lags_at_upper_bound(rep.sensor_lags.as_ref(), opts));
    (rep.oscillations, rep.failed_sets) =
        oscillations_on_campaign(c, &p, opts.model, rep.tau_me_s, &opts.step5.sensor_lags);
    rep.total_seconds = t_all.elapsed().as_secs_f64();
    Ok((p, rep))
}

/// A data set the model cannot simulate, with the reason.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SetFailure {
    /// Data set name.
    pub set: String,
    /// What failed (the simulator's message: time and state of the failure).
    pub message: String,
}

/// A caveat when step 3 fitted a sensor lag onto its upper bound [`MAX_LAG_S`]
/// ([`super::complete::lag_at_upper_bound`]): no test-cell sensor is that slow, so the lag stands
/// in for a model error, and V_im, V_em, J_t fitted with it carry it (seen on a 2-litre
/// engine's campaign, docs/tuning.md session 24). `None` for given lags or none at the bound.
fn lags_at_upper_bound(lags: Option<&SensorLags>, opts: &PipelineOptions) -> Option<String> {
    if !opts.step3.fit_lags {
        return None;
    }
    let at: Vec<String> = super::sensors::LAG_NAMES
        .iter()
        .zip(lags?.as_array())
        .filter(|(_, v)| super::complete::lag_at_upper_bound(*v))
        .map(|(n, v)| format!("{n} {:.1} ms", v * 1e3))
        .collect();
    (!at.is_empty()).then(|| {
        format!(
            "step 3 put the sensor lag(s) {} on the upper bound of {:.0} ms: no test-cell sensor \
             is that slow, so the lag stands in for something the model gets wrong, and V_im, \
             V_em, J_t fitted with it are biased by it; try `--sensor-lags none` or the \
             sensors' known time constants and compare the validation",
            at.join(", "),
            MAX_LAG_S * 1e3
        )
    })
}

/// Step 3's sensor lags (fitted or held, [`CompleteReport::sensor_lags`]) held from now on:
/// the start of a repeated step 3 and step 5's first row.
fn hold_lags(opts: &mut PipelineOptions, r: &CompleteReport) {
    opts.step3.lags = r.sensor_lags;
    opts.step5.sensor_lags = r.sensor_lags;
}

/// Errors of the model `p` on `sets` ([`dynamic_errors_with`], with their oscillation windows),
/// in parallel, in the order of `sets`; the sets that fail to simulate come second, with their
/// messages.
fn errors_on_sets(
    p: &Params,
    sets: &[&DynamicData],
    stat: &[super::data::StationaryPoint],
    order: ModelOrder,
    tau_me: Option<f64>,
    lags: &SensorLags,
) -> (Vec<DataSetErrors>, Vec<SetFailure>) {
    use rayon::prelude::*;
    let all: Vec<_> = sets
        .par_iter()
        .map(|d| {
            (
                d.name.clone(),
                dynamic_errors_with(order, p, d, stat, tau_me, lags),
            )
        })
        .collect();
    let (mut ok, mut failed) = (Vec::new(), Vec::new());
    for (set, r) in all {
        match r {
            Ok(e) => ok.push(e),
            Err(e) => failed.push(SetFailure {
                set,
                message: match e {
                    ValidateError::Model { message, .. } => message,
                    other => other.to_string(),
                },
            }),
        }
    }
    (ok, failed)
}

/// Names of the sets of `sets` on which the model `p` oscillates where the engine does not
/// ([`super::validate::sustained_oscillations`]); sets that fail to simulate are not counted.
fn oscillating_sets(
    p: &Params,
    sets: &[&DynamicData],
    stat: &[super::data::StationaryPoint],
    order: ModelOrder,
) -> Vec<String> {
    oscillating_names(&errors_on_sets(p, sets, stat, order, None, &SensorLags::NONE).0)
}

/// Names of the sets of `errs` with at least one oscillation window.
fn oscillating_names(errs: &[DataSetErrors]) -> Vec<String> {
    errs.iter()
        .filter(|e| !e.oscillations.is_empty())
        .map(|e| e.name.clone())
        .collect()
}

/// [`super::validate::sustained_oscillations`] of `p` on every dynamic set of `c` except the
/// actuator sets (the tuning sets and the validation sets: the model's behaviour on any input of
/// the campaign), and the sets it cannot simulate.
fn oscillations_on_campaign(
    c: &Campaign,
    p: &Params,
    order: ModelOrder,
    tau_me: Option<f64>,
    lags: &SensorLags,
) -> (Vec<OscillationSummary>, Vec<SetFailure>) {
    let sets: Vec<&DynamicData> = c
        .manifest
        .datasets
        .iter()
        .zip(&c.dynamic)
        .filter(|(i, _)| i.kind != StepKind::Actuator)
        .map(|(_, d)| d)
        .collect();
    let (errs, failed) = errors_on_sets(p, &sets, &c.stationary, order, tau_me, lags);
    (oscillation_summary(&errs), failed)
}

/// The point `(x, y)` of `points` where `f(p, x, y)` has the smallest positive, finite
/// linearized standard error over the parameters `names` of `cov`
/// ([`function_std_error`]), with that standard error; `None` when there is none.
fn best_determined_point(
    points: &[(f64, f64)],
    f: impl Fn(&Params, f64, f64) -> f64,
    p: &Params,
    names: &[&str],
    cov: &NamedCov,
) -> Option<(f64, f64, f64)> {
    points
        .iter()
        .map(|&(x, y)| {
            let se = function_std_error(|q: &Params| f(q, x, y), p, names, cov);
            (x, y, se)
        })
        .filter(|c| c.2.is_finite() && c.2 > 0.0)
        .min_by(|a, b| a.2.total_cmp(&b.2))
}

/// eta_tm,max and BSR_opt (eq. (49)): `eta_tm = eta_tm,max - c_m(omega_t) (BSR - BSR_opt)^2`
/// is seen only over the campaign's blade speed ratios (eq. (50) at its stationary points).
/// When BSR_opt lies outside that range the parabola's vertex is extrapolated and its height and
/// position trade against each other (on `mvem lab` campaigns BSR spans 0.51-0.67 for a
/// vertex near 0.98: correlation 0.99-0.9996): both are then reported not identifiable with
/// that reason, whatever their standard errors. What the campaign determines is eta_tm over the
/// measured range: returned as a [`Combination`], eta_tm at the measured stationary point (its
/// BSR and omega_t) where its standard error (from the final covariance `cov`) is smallest.
/// `None` without finite BSR values or a finite standard error.
fn turbine_efficiency_on_the_measured_range(
    p: &Params,
    pts: &[crate::tuning::data::StationaryPoint],
    cov: &NamedCov,
    parameters: &mut BTreeMap<String, ParamEstimate>,
) -> Option<Combination> {
    let seen: Vec<(f64, f64)> = super::steps::bsr_series(p, pts)
        .into_iter()
        .filter(|(b, w)| b.is_finite() && w.is_finite())
        .collect();
    let lo = seen.iter().map(|s| s.0).fold(f64::INFINITY, f64::min);
    let hi = seen.iter().map(|s| s.0).fold(f64::NEG_INFINITY, f64::max);
    let opt = p.turbine.bsr_opt;
    // eq. (49) at a point (the authors' c_m, SEM)
    let eta_at = |q: &Params, b: f64, w: f64| {
        q.turbine.eta_tmmax - turbine::c_m(&q.turbine, w, SEM) * (b - q.turbine.bsr_opt).powi(2)
    };
    let names = ["eta_tmmax", "bsr_opt", "c_m1", "c_m2", "c_m3"];
    // the measured point where the campaign determines eta_tm best (smallest standard error)
    let (b_ref, w_ref, std_error) = best_determined_point(&seen, eta_at, p, &names, cov)?;
    let value = eta_at(p, b_ref, w_ref);
    if !(lo..=hi).contains(&opt) {
        let why = format!(
            "the vertex of eta_tm over BSR (eq. (49)) lies at BSR_opt = {opt:.3}, outside the \
             measured BSR range {lo:.3}-{hi:.3} (eq. (50) at the stationary points): eta_tm,max \
             and BSR_opt trade against each other; the campaign determines eta_tm on that range \
             ({value:.4} +- {std_error:.4} at BSR {b_ref:.3}, tune_report \"combinations\")"
        );
        // the reason takes an earlier flag's first place: it names the cause
        flag_keys_with(
            parameters,
            ["turbine.eta_tmmax", "turbine.bsr_opt"],
            &why,
            ParamEstimate::flag_first,
        );
    }
    Some(Combination {
        name: "turbine.eta_tm_at_bsr".into(),
        description: format!(
            "eta_tm (eq. (49)) at BSR = {b_ref:.4}, omega_t = {w_ref:.1} rad/s: the measured \
             stationary point where it is best determined (measured BSR {lo:.3}-{hi:.3})"
        ),
        at: vec![("bsr".into(), b_ref), ("omega_t".into(), w_ref)],
        value,
        std_error,
    })
}

/// eta_c,max and c_pi (eqs (62)-(64)): the peak value and the pressure exponent of the
/// compressor-efficiency ellipse. Like its position and shape ([`flag_efficiency_ellipse_shape`])
/// they are fitted to eta_c over the noisy regressors W_c and Pi_c (errors in variables), a bias
/// the linearized standard error does not contain: eta_c,max was 3.4 standard errors (rel.
/// 0.24 %) and c_pi 3.1 off on `mvem lab --seed 6` with the ellipse's centre inside the measured
/// region (docs/tuning.md, session 10). Both are reported not identifiable with that reason.
/// What the campaign determines is eta_c over the measured region: returned as a
/// [`Combination`], eta_c (eq. (62)) at the measured stationary point (its W_c and Pi_c) where its
/// standard error (from the final covariance `cov`) is smallest. `None` without a stationary
/// point with Pi_c > 1 or a finite standard error.
fn compressor_efficiency_on_the_measured_range(
    p: &Params,
    pts: &[crate::tuning::data::StationaryPoint],
    cov: &NamedCov,
    parameters: &mut BTreeMap<String, ParamEstimate>,
) -> Option<Combination> {
    let seen: Vec<(f64, f64)> = pts
        .iter()
        .map(|s| (s.w_c, compressor::pi_c(s.p_c, s.p_amb, SEM))) // eq. (59)
        .filter(|(w, pi)| w.is_finite() && pi.is_finite() && *pi > 1.0)
        .collect();
    let eta_at = |q: &Params, w: f64, pi: f64| compressor::efficiency(&q.compressor, w, pi, SEM);
    let names = ["eta_cmax", "w_copt", "pi_copt", "c_pi", "a1", "a2", "a3"];
    // points where the authors' lower limit of eta_c (item 29) holds the model at 0.2 say
    // nothing about the ellipse (zero gradient): left out
    let unclamped: Vec<(f64, f64)> = seen
        .into_iter()
        .filter(|&(w, pi)| compressor::efficiency(&p.compressor, w, pi, Semantics::Paper) > 0.2)
        .collect();
    let (w_ref, pi_ref, std_error) = best_determined_point(&unclamped, eta_at, p, &names, cov)?;
    let value = eta_at(p, w_ref, pi_ref);
    let why = format!(
        "peak value or exponent of the compressor-efficiency ellipse (eqs (62)-(64)), fitted to \
         eta_c of eq. (58) over the noisy regressors W_c and Pi_c (errors in variables): its \
         bias is not in the linearized standard error; the campaign determines eta_c over the \
         measured region ({value:.4} +- {std_error:.4} at W_c {w_ref:.4} kg/s, Pi_c \
         {pi_ref:.4}, tune_report \"combinations\")"
    );
    // the cause first (an earlier flag, e.g. a correlation with W_copt, is its symptom)
    flag_keys_with(
        parameters,
        ["compressor.eta_cmax", "compressor.c_pi"],
        &why,
        ParamEstimate::flag_first,
    );
    Some(Combination {
        name: "compressor.eta_c_at_point".into(),
        description: format!(
            "eta_c (eq. (62)) at W_c = {w_ref:.4} kg/s, Pi_c = {pi_ref:.4}: the measured \
             stationary point where it is best determined"
        ),
        at: vec![("w_c".into(), w_ref), ("pi_c".into(), pi_ref)],
        value,
        std_error,
    })
}

/// The parameters of the compressor-efficiency ellipse (eqs (62)-(65)), by registry path.
const EFFICIENCY_ELLIPSE: [&str; 7] = [
    "compressor.eta_cmax",
    "compressor.w_copt",
    "compressor.pi_copt",
    "compressor.c_pi",
    "compressor.q_c[1][1]",
    "compressor.q_c[1][2]",
    "compressor.q_c[2][2]",
];

/// The parameters of the compressor-flow model (eqs (68)-(70)), by registry path. In the complete
/// model the compressor acts only through W_c and its power P_c = W_c c_pa (T_c - T_amb) with
/// T_c - T_amb = T_amb (Pi_c^(1 - 1/gamma_a) - 1) / eta_c (eqs (58), (61)), so the complete-model
/// row of cost (77) trades an error of the efficiency model
/// against the flow map: with an extrapolated efficiency peak (`mvem lab` seed 4, step 5
/// converged) c_Phi2 and c_Wphi2 ended 7.0 and -4.3 standard errors from the truth at rel. std.
/// errors of 13-14 %.
const FLOW_MAP: [&str; 8] = [
    "compressor.c_psi2",
    "compressor.c_phi2",
    "compressor.c_wpsi[1]",
    "compressor.c_wpsi[2]",
    "compressor.c_wpsi[3]",
    "compressor.c_wphi[1]",
    "compressor.c_wphi[2]",
    "compressor.c_wphi[3]",
];

/// Flag the compressor-flow coefficients ([`FLOW_MAP`]) as not identifiable one by one, always.
/// The flow model is an ellipse in (Psi_c, Phi_c) (eq. (71)) with centre (c_Psi2, c_Phi2) and
/// axes c_Psi1(omega_t), c_Phi1(omega_t) (eqs (69)-(70)), and a campaign sees it only on the arc
/// of its operating points: centre and axes trade against each other along curved directions
/// that the linearized standard errors do not see. Measured: on `mvem lab` seeds 1-4 the
/// covariance already flags all eight; on a campaign of a different engine two converged
/// tunings (whose searches differed only by 1e-10 in the simulated data) put the centre at
/// c_Phi2 = -0.73 for a true 0, once with seven of the eight flagged and c_Psi2 8 standard
/// errors off, once with two flagged and six coefficients 4-1 100 standard errors off. What
/// the data determine is the map's values over the measured region, which the validation
/// errors report.
fn flag_flow_map_coefficients(parameters: &mut BTreeMap<String, ParamEstimate>) {
    flag_keys(
        parameters,
        FLOW_MAP,
        "a coefficient of the compressor-flow ellipse (eqs (69)-(71)), seen only on the arc of \
         the measured operating points: its centre and axes trade against each other, so the \
         data fix the map, not this coefficient",
    );
}

/// The coefficients of the VGT effective-area map, eq. (56).
const VGT_AREA_MAP: [&str; 4] = [
    "turbine.c_vgt1",
    "turbine.c_vgt2",
    "turbine.c_f1",
    "turbine.c_f2",
];

/// Flag the VGT effective-area coefficients ([`VGT_AREA_MAP`]) as not identifiable one by one,
/// always. f_vgt = c_f2 + c_f1 sqrt(1 - ((u_vgt - c_vgt2)/c_vgt1)^2) (eq. (56)) is an ellipse
/// arc, seen only over the campaign's VGT positions, like the compressor-flow ellipse
/// ([`flag_flow_map_coefficients`]): centre, axes and offset trade along curved directions.
/// Measured: with step 3's least-squares levels (session 16) the chained covariance no longer
/// masked this, and `mvem lab` seed 8 (step 5 converged) reported c_f1 1.791 +- 0.005 for a true
/// 1.948 (32 standard errors) and c_f2 81 off; c_vgt1 had been 3.2-3.7 standard errors off on
/// seeds 3 and 4 with the joint covariance (sessions 8 and 16). What the data determine is the
/// map over the measured positions, which the validation errors report.
fn flag_vgt_area_map(parameters: &mut BTreeMap<String, ParamEstimate>) {
    flag_keys(
        parameters,
        VGT_AREA_MAP,
        "a coefficient of the VGT effective-area ellipse arc (eq. (56)), seen only over the \
         measured VGT positions: its centre, axes and offset trade against each other, so the \
         data fix the map, not this coefficient",
    );
}

/// [`ParamEstimate::flag`] every tuned parameter of `keys` (TOML paths) with `why`.
fn flag_keys<'k>(
    parameters: &mut BTreeMap<String, ParamEstimate>,
    keys: impl IntoIterator<Item = &'k str>,
    why: &str,
) {
    flag_keys_with(parameters, keys, why, ParamEstimate::flag);
}

/// [`flag_keys`] by `flag` ([`ParamEstimate::flag`], or [`ParamEstimate::flag_first`] for a
/// cause that explains earlier flags).
fn flag_keys_with<'k>(
    parameters: &mut BTreeMap<String, ParamEstimate>,
    keys: impl IntoIterator<Item = &'k str>,
    why: &str,
    flag: fn(&mut ParamEstimate, &str),
) {
    for key in keys {
        if let Some(e) = parameters.get_mut(key) {
            flag(e, why);
        }
    }
}

/// The position and shape of the compressor-efficiency ellipse (eqs (62)-(65)): the peak
/// (W_copt, pi_copt) and Q_c; not eta_c,max and c_pi.
const EFFICIENCY_ELLIPSE_SHAPE: [&str; 5] = [
    "compressor.w_copt",
    "compressor.pi_copt",
    "compressor.q_c[1][1]",
    "compressor.q_c[1][2]",
    "compressor.q_c[2][2]",
];

/// Flag the position and shape of the compressor-efficiency ellipse
/// ([`EFFICIENCY_ELLIPSE_SHAPE`]) as not identifiable one by one, always. eta_c is measured
/// only through eq. (58), the isentropic over the measured temperature rise, and its regressors
/// W_c and Pi_c are measured with noise too (errors in variables): the least-squares peak is
/// biased by more than its linearized standard error, which describes only the noise of the
/// response. Measured (`mvem lab`, realistic noise): W_copt +13 % from a step 5 started at the
/// truth (rel. std. error 3.4 %); with the joint covariance of steps 5 and 3, seed 2 W_copt
/// +18 % and pi_copt +5.4 % at 4.0 and 3.9 standard errors, seed 3 4.3 and 4.0 (session 8).
/// The peak value eta_c,max is a stationary value of the ellipse (first-order insensitive to
/// a shift of the peak) and c_pi the pressure axis' exponent: they stay as the covariance says.
fn flag_efficiency_ellipse_shape(parameters: &mut BTreeMap<String, ParamEstimate>) {
    flag_keys(
        parameters,
        EFFICIENCY_ELLIPSE_SHAPE,
        "position or shape of the compressor-efficiency ellipse (eqs (62)-(65)), fitted to eta_c \
         of eq. (58) over the noisy regressors W_c and Pi_c (errors in variables): its bias is \
         not in the linearized standard error, so the data fix eta_c over the measured region \
         and its peak value, not this parameter",
    );
}

/// The shape coefficients of one submodel's map (polynomials and offsets, not physical
/// quantities), by registry path: the turbine-efficiency map (eq. (53)-(54) c_m), the turbine flow
/// (c_f1, c_f2), friction (c_fric), volumetric efficiency (c_vol) and the EGR-valve flow
/// (c_egr, and pi_egropt: W_egr is the product of the area map f_egr(u_egr) of eq. (38) and
/// the flow function Psi_egr(Pi_egr) of eq. (34), which pi_egropt shapes, so over the measured
/// (u_egr, Pi_egr) the two trade; `mvem lab` seed 10 reported pi_egropt 0.667 +- 0.0055 for a
/// true 0.650, 3.0 standard errors off, with the area map flagged, in sessions 15 and 16).
/// The compressor-flow map ([`FLOW_MAP`]) is not among them: its coefficients are
/// always flagged ([`flag_flow_map_coefficients`]).
const MAP_COEFFICIENTS: [&[&str]; 5] = [
    &["turbine.c_m[1]", "turbine.c_m[2]", "turbine.c_m[3]"],
    &["turbine.c_f1", "turbine.c_f2"],
    &[
        "cylinder.c_fric[1]",
        "cylinder.c_fric[2]",
        "cylinder.c_fric[3]",
    ],
    &[
        "cylinder.c_vol[1]",
        "cylinder.c_vol[2]",
        "cylinder.c_vol[3]",
    ],
    &[
        "egr_valve.c_egr[1]",
        "egr_valve.c_egr[2]",
        "egr_valve.c_egr[3]",
        "egr_valve.pi_egropt",
    ],
];

/// The reason of a3 (`compressor.q_c[1][2]`, the off-diagonal of Q_c in eq. (62)) when its
/// standard error is infinite because it lies on the edge of Q_c's positive semidefinite cone,
/// |a3| = sqrt(a1 a2) (`q_c`: the final Q_c): the search moved a3 beyond the edge, where the
/// projection of every evaluation (`steps::compressor::project_q_c`) clamps it, so a3 changed
/// nothing and its Jacobian column was zero (step 8 on the small campaign of docs/tuning.md,
/// session 43). The generic "not determined by the data" follows in parentheses.
fn flag_a3_on_the_psd_edge(q_c: &[[f64; 2]; 2], parameters: &mut BTreeMap<String, ParamEstimate>) {
    let (a1, a2, a3) = (q_c[0][0], q_c[1][1], q_c[0][1]);
    let edge = (a1.max(0.0) * a2.max(0.0)).sqrt();
    let Some(e) = parameters.get_mut("compressor.q_c[1][2]") else {
        return;
    };
    if e.std_error.is_infinite() && a3.abs() >= edge * (1.0 - 1e-9) {
        e.flag_first(&format!(
            "a3 = {a3:.4} lies on the edge of Q_c's positive semidefinite cone, |a3| = \
             sqrt(a1 a2) = {edge:.4} (eq. (62)): the search moved it beyond, where the projection \
             of Q_c clamps it, so there it changes nothing and the data do not determine it"
        ));
    }
}

/// Flag every coefficient of a map ([`MAP_COEFFICIENTS`]) when any of that map's tuned
/// coefficients is not identifiable (session 8: at least half; session 9: any, after a
/// different engine's turbine-efficiency map with c_m3 flagged (rel. std. error 112 %) reported
/// c_m2 at 2788 +- 1.7 rad/s for a true 2769, 11 standard errors off: the offset of a power law
/// whose exponent is not determined is not determined either, whatever its curvature says). The campaign then fixes the map as a whole (its
/// values over the measured region), not its coefficients one by one: the map's flat
/// directions are curved, so other coefficient sets lie along them, and the linearized standard
/// error of a coefficient that looks well determined does not bound its distance from the
/// truth. The rule came from the compressor-flow map (now flagged always): on a campaign of a
/// different engine (published parameters with a dozen changes of 5-20 %, step 5 converged)
/// 7 of its 8 coefficients were flagged,
/// and the eighth, c_Psi2, was reported at 0.41 +- 0.05 for a true 0 (8 standard errors off),
/// the step-1 fit having put the ellipse centre at c_Phi2 = -0.72, another parametrization of
/// the same map.
fn flag_maps_known_only_as_a_whole(parameters: &mut BTreeMap<String, ParamEstimate>) {
    for map in MAP_COEFFICIENTS {
        let tuned: Vec<&str> = map
            .iter()
            .copied()
            .filter(|k| parameters.contains_key(*k))
            .collect();
        let flagged: Vec<&str> = tuned
            .iter()
            .copied()
            .filter(|k| !parameters[*k].identifiable)
            .collect();
        if tuned.is_empty() || flagged.is_empty() {
            continue;
        }
        let why = format!(
            "{} of the {} coefficients of its map are not identifiable ({}): the data fix the \
             map as a whole, and the linearized standard error of one coefficient does not \
             bound its error",
            flagged.len(),
            tuned.len(),
            flagged.join(", ")
        );
        flag_keys(parameters, tuned, &why);
    }
}

/// The dynamics parameters of step 3 that step 3's standard errors cannot vouch for.
///
/// Step 3 fits V_im, V_em and J_t with the static maps of steps 1 and 5 held fixed, and adds
/// their uncertainty by propagating the maps' linearized covariance. For a map parameter flagged
/// not identifiable that covariance is a local curvature, not its error (the flags say so), and
/// step 3 inherits the map's error as a bias that no standard error shows: on `mvem lab`
/// campaigns of the published engine, step 3 on the true static maps lands within 2.2 of its
/// own standard errors, on the tuned maps V_im came out 28 % low (seed 4, the compressor
/// efficiency ellipse) and J_t 10 % high (seed 1, the turbine), 4-6.5 standard errors off once
/// those are computed without the noise of forward differences (docs/tuning.md, session 21).
/// Returns a caveat naming the step-3 parameters reported identifiable and how many parameters
/// of which static sections are flagged; `None` when either list is empty.
pub fn inherited_static_bias(parameters: &BTreeMap<String, ParamEstimate>) -> Option<String> {
    let dynamics: Vec<&str> = ["intake_manifold.v_im", "exhaust_manifold.v_em", "turbo.j_t"]
        .into_iter()
        .filter(|k| {
            parameters
                .get(*k)
                .is_some_and(|e| e.identifiable && e.step == 3)
        })
        .collect();
    let mut flagged: BTreeMap<&str, (usize, usize)> = BTreeMap::new();
    for (k, e) in parameters {
        if e.step == 1 || e.step == 5 {
            let section = k.split('.').next().unwrap_or(k);
            let n = flagged.entry(section).or_default();
            n.1 += 1;
            n.0 += usize::from(!e.identifiable);
        }
    }
    flagged.retain(|_, n| n.0 > 0);
    if dynamics.is_empty() || flagged.is_empty() {
        return None;
    }
    let total: usize = flagged.values().map(|n| n.0).sum();
    let sections: Vec<String> = flagged
        .iter()
        .map(|(s, n)| format!("{s} {} of {}", n.0, n.1))
        .collect();
    Some(format!(
        "{} {} reported identifiable with standard errors that include the static maps' \
         covariance, but {total} static parameters are flagged not identifiable ({}): their \
         covariance does not bound their error, and step 3 inherits that error as a bias its \
         standard errors do not show (on virtual campaigns of the published engine V_im came \
         out up to 28 % and J_t up to 13 % off; docs/tuning.md, session 21). Compare them \
         with design data, or \
         run steps 3-4 on static maps you trust (--params FILE --steps 3-4)",
        dynamics.join(", "),
        if dynamics.len() == 1 { "is" } else { "are" },
        sections.join(", ")
    ))
}

/// Flag the efficiency-ellipse parameters as not identifiable when the fitted peak
/// (W_copt, pi_copt) of eqs (62)-(63) lies outside the measured region, the range of W_c and of
/// pi_c = (Pi_c - 1)^c_pi (eq. (64), Pi_c = p_c / p_amb) over the campaign's stationary points.
/// The peak, its value eta_c,max and the ellipse's shape are then an extrapolation of the data:
/// the linearized standard errors describe the curvature of the fit inside the measured region,
/// not how far the extrapolated peak may be from the truth (a `mvem lab` campaign, seed 4, put
/// W_copt at 1.77 kg/s, pi_copt 2.58 for a true 0.275 and 1.05 with measured W_c 0.077-0.638
/// kg/s, as the least-squares optimum of its data). The flow-map parameters ([`FLOW_MAP`])
/// fitted with it are flagged for the same reason.
fn flag_extrapolated_efficiency_peak(
    c: &crate::params::Compressor,
    pts: &[super::data::StationaryPoint],
    parameters: &mut BTreeMap<String, ParamEstimate>,
) {
    let range = |v: &mut dyn Iterator<Item = f64>| {
        v.filter(|x| x.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            })
    };
    let w = range(&mut pts.iter().map(|s| s.w_c));
    let pi = range(
        &mut pts
            .iter()
            .map(|s| compressor::pi_c(s.p_c, s.p_amb, SEM) - 1.0) // eq. (59)
            .filter(|&x| x > 0.0)
            .map(|x| pow_ln(x, c.c_pi)), // eq. (64), as in compressor::efficiency
    );
    if !(w.0 <= w.1 && pi.0 <= pi.1) {
        return; // no usable stationary points: nothing to compare with
    }
    let inside = |x: f64, (lo, hi): (f64, f64)| (lo..=hi).contains(&x);
    if inside(c.w_copt, w) && inside(c.pi_copt, pi) {
        return;
    }
    for key in EFFICIENCY_ELLIPSE.iter().chain(&FLOW_MAP) {
        if let Some(e) = parameters.get_mut(*key) {
            e.flag(&format!(
                "the fitted efficiency peak (W_copt = {:.4} kg/s, pi_copt = {:.4}) lies outside \
                 the measured region (W_c {:.4}-{:.4} kg/s, pi_c {:.4}-{:.4}): {}, which the \
                 linearized standard error does not bound",
                c.w_copt,
                c.pi_copt,
                w.0,
                w.1,
                pi.0,
                pi.1,
                if FLOW_MAP.contains(key) {
                    "the flow map is fitted together with an extrapolated efficiency model"
                } else {
                    "the peak and the ellipse are extrapolated"
                },
            ));
        }
    }
}

/// Step 5 from `th0` on `p` (replaced by the result), its uncertainty with that of the
/// parameters it holds fixed ([`add_fixed`]) added to `cov` and `est` (flagged when the search
/// stopped at its evaluation limit); the step's report and linearization. See
/// [`run_static_step`].
fn run_step5(
    p: &mut Params,
    c: &Campaign,
    th0: &[f64],
    opts: &PipelineOptions,
    cov: &mut NamedCov,
    est: &mut Vec<(String, ParamEstimate)>,
) -> Result<(Step5Report, Option<Conditional>), PipelineError> {
    run_static_step(p, c, th0, opts, &opts.step5, 5, cov, est)
}

/// The search of cost (77) (`complete::step5` with the options `so`) of step `step`: 5 (the
/// 8-state model) or 8 (the 12-state model with k_ic, section 9.2.1), from `th0` on `p`
/// (replaced by the result), with every safeguard of step 5 for both (session 43; before, step 8
/// called `complete::step5` without them):
///
/// * a start whose model (`so.model`, the model the search simulates) oscillates on some of
///   the static-tuning sets where the engine does not: a first pass without those sets, then
///   all sets from its result ([`PipelineOptions::stage_oscillating`]);
/// * the rows of the sets on which the result oscillates left out of the linearization
///   ([`relinearize_rows`], [`Step5Report::linearized_without`]);
/// * its estimates flagged when the search stopped short ([`Step5Report::flag_early_stop`]).
///
/// Step 5 adds the uncertainty of the parameters it holds fixed ([`add_fixed`]) and its
/// covariance to `cov`; step 8's standard errors stay conditional on what it holds fixed
/// (V_ic, V_im, V_em, J_t of step 7 are not in `cov`), which its report says
/// ([`Step5Report::uncertainty_note`]). The estimates are added to `est`.
#[allow(clippy::too_many_arguments)]
fn run_static_step(
    p: &mut Params,
    c: &Campaign,
    th0: &[f64],
    opts: &PipelineOptions,
    so: &Step5Options,
    step: u8,
    cov: &mut NamedCov,
    est: &mut Vec<(String, ParamEstimate)>,
) -> Result<(Step5Report, Option<Conditional>), PipelineError> {
    let sets: Vec<_> = c
        .manifest
        .datasets
        .iter()
        .zip(&c.dynamic)
        .filter(|(i, _)| i.roles.contains(&Role::Static) && i.kind != StepKind::Actuator)
        .map(|(_, d)| d)
        .collect();
    if sets.is_empty() && so.dynamic_row {
        return Err(missing(step, "data set with role \"static\""));
    }
    // the model the search simulates: the oscillation checks must see the same one
    let model = so.model;
    // a start that oscillates on some sets where the engine does not: a first pass without them
    let mut th0 = th0.to_vec();
    let mut first: Option<(Vec<String>, Step5Report, Vec<String>)> = None;
    if opts.stage_oscillating && so.dynamic_row {
        let lags = &so.sensor_lags;
        let (at_start, _) = errors_on_sets(p, &sets, &c.stationary, model, None, lags);
        let osc = oscillating_names(&at_start);
        let calm: Vec<&DynamicData> = sets
            .iter()
            .filter(|d| !osc.contains(&d.name))
            .copied()
            .collect();
        if !osc.is_empty() && !calm.is_empty() {
            let o1 = Step5Options {
                max_evaluations: so
                    .max_evaluations
                    .min(opts.stage_first_pass_max_evaluations),
                ..so.clone()
            };
            let (q1, r1) = step5(p, &c.stationary, &calm, &th0, &o1).map_err(at(step))?;
            // the first pass does not see the sets it leaves out and can move to where they
            // no longer simulate (no stable steady start, a failed solve): then cost (77) is
            // flat there (failure residuals) and the second pass would stay; discard it
            let at_first: Vec<String> =
                errors_on_sets(&q1, &sets, &c.stationary, model, None, lags)
                    .0
                    .into_iter()
                    .map(|e| e.name)
                    .collect();
            let lost: Vec<String> = at_start
                .iter()
                .map(|e| e.name.clone())
                .filter(|n| !at_first.contains(n))
                .collect();
            if lost.is_empty() {
                th0 = theta_of(&step5_bounds(p, &c.stationary, &th0, so), &q1);
            }
            first = Some((osc, r1, lost));
        }
    }
    // the box step 5 searches, for the variance bound of add_fixed
    let boxes: Vec<(f64, f64)> = step5_bounds(p, &c.stationary, &th0, so)
        .iter()
        .map(|b| (b.lo, b.hi))
        .collect();
    let (q, mut r) = step5(p, &c.stationary, &sets, &th0, so).map_err(at(step))?;
    if let Some((osc, r1, lost)) = first {
        r.first_pass_without = osc;
        r.first_pass_discarded_for = lost;
        r.first_pass_evaluations = r1.n_eval;
        r.first_pass_stopped_by = r1.stopped_by.clone();
        r.cost_start = r1.cost_start;
        r.n_eval += r1.n_eval;
        r.n_iter += r1.n_iter;
        r.n_jacobians += r1.n_jacobians;
        r.restarts += r1.restarts;
    }
    *p = q;
    let cost = Cost77::new(p, &c.stationary, &sets, so);
    // rows of the linearization: all, or those of the sets where the tuned model settles
    let osc_end = if so.dynamic_row {
        oscillating_sets(p, &sets, &c.stationary, model)
    } else {
        Vec::new()
    };
    let mut keep: Option<Vec<bool>> = (!osc_end.is_empty()).then(|| cost.rows_without(&osc_end));
    if let Some(k) = &keep {
        let scales: Vec<f64> = step5_bounds(p, &c.stationary, &th0, so)
            .iter()
            .map(|b| b.scale)
            .collect();
        let blocks = kept_blocks(&cost.covariance_blocks(), k);
        if relinearize_rows(&mut r, k, &cost.residuals_at(p), &blocks, &scales, step) {
            r.linearized_without = osc_end;
        } else {
            // the linearization keeps every row, and so must the chained residuals
            keep = None;
        }
    }
    let cond = if step == 5 {
        add_fixed(
            &mut r.uncertainty,
            &r.linearization,
            cov,
            |q: &Params| match &keep {
                Some(k) => select_rows(&cost.residuals_at(q), k),
                None => cost.residuals_at(q),
            },
            p,
            step,
            &boxes,
            opts.fixed_jacobian,
        )
    } else {
        r.uncertainty_note = Some(conditional_note(step));
        None
    };
    r.flag_early_stop();
    est.extend(r.uncertainty.iter().cloned());
    Ok((r, cond))
}

/// The note of a step whose standard errors are conditional on the parameters it holds fixed
/// ([`Step5Report::uncertainty_note`]).
fn conditional_note(step: u8) -> String {
    format!(
        "the standard errors of step {step} are conditional on the parameters it holds fixed \
         (V_ic, V_im, V_em, J_t of step 7, the actuators of step 2, the sensor lags of step 3): \
         their uncertainty is not included, unlike step 5's"
    )
}

/// The entries of `r` where `keep` is true.
fn select_rows(r: &[f64], keep: &[bool]) -> Vec<f64> {
    r.iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(x, _)| *x)
        .collect()
}

/// The residual blocks (lengths, [`Cost77::covariance_blocks`]) whose rows `keep` keeps; a
/// block is kept or dropped whole.
fn kept_blocks(blocks: &[usize], keep: &[bool]) -> Vec<usize> {
    let mut start = 0;
    let mut out = Vec::with_capacity(blocks.len());
    for &len in blocks {
        if keep.get(start).copied().unwrap_or(true) {
            out.push(len);
        }
        start += len;
    }
    out
}

/// Step 5's covariance, standard errors and linearization recomputed from the rows of its
/// Jacobian that `keep` keeps (`residuals`: cost (77) at the estimate, all rows; `blocks`:
/// the kept rows' blocks; `scales`: the parameters' typical magnitudes, for the relative
/// standard errors of [`Step5Report::rel_std_err`], computed as in `step5`). Used when the
/// tuned model oscillates on some sets ([`Step5Report::linearized_without`]). Returns whether
/// it did: fewer rows than parameters (or lengths that do not match) leave `r` as it is.
fn relinearize_rows(
    r: &mut Step5Report,
    keep: &[bool],
    residuals: &[f64],
    blocks: &[usize],
    scales: &[f64],
    step: u8,
) -> bool {
    let Some(lin) = r.linearization.as_mut() else {
        return false;
    };
    let rows: Vec<usize> = (0..keep.len()).filter(|&i| keep[i]).collect();
    if rows.len() <= lin.jacobian.ncols()
        || keep.len() != lin.jacobian.nrows()
        || residuals.len() != keep.len()
    {
        return false;
    }
    let j = lin.jacobian.select_rows(rows.iter());
    let res = select_rows(residuals, keep);
    let cov = block_covariance(&j, &res, blocks);
    let std_err = crate::numerics::lsq::param_stats(&j, &res).std_err;
    let names: Vec<&str> = lin.names.iter().map(String::as_str).collect();
    let theta: Vec<f64> = r.uncertainty.iter().map(|(_, e)| e.value).collect();
    if theta.len() != names.len() {
        return false;
    }
    r.uncertainty = estimates_from_cov(&names, &theta, &cov, step);
    r.rel_std_err = names
        .iter()
        .zip(&theta)
        .zip(scales.iter().zip(&std_err))
        .map(|((n, v), (sc, e))| (n.to_string(), e / v.abs().max(sc * 1e-3)))
        .collect();
    lin.jacobian = j;
    lin.covariance = cov;
    true
}

/// Step 3 on `sets` from `p` (replaced by the result), its uncertainty with that of the
/// parameters it holds fixed ([`add_fixed`]) added to `cov` and `est`; the step's report.
fn run_step3(
    p: &mut Params,
    sets: &[&DynamicData],
    c: &Campaign,
    opts: &PipelineOptions,
    cov: &mut NamedCov,
    est: &mut Vec<(String, ParamEstimate)>,
) -> Result<(CompleteReport, Option<Conditional>), PipelineError> {
    let (q, mut r) =
        step3(p, sets, &c.stationary, &opts.step3, opts.step3_max_eval).map_err(at(3))?;
    *p = q;
    let res = dynamic_residuals(
        ModelOrder::Eight,
        sets,
        &c.stationary,
        opts.step3.amp_floor,
        opts.step3.window,
    );
    let s3 = &opts.step3;
    // the box of each of the step's parameters (V_im, V_em, J_t, then the lags it fitted)
    let boxes: Vec<(f64, f64)> = s3
        .lo
        .iter()
        .zip(&s3.hi)
        .map(|(l, h)| (*l, *h))
        .chain(std::iter::repeat((0.0, MAX_LAG_S)))
        .take(r.params.len())
        .collect();
    // the sensor lags step 3 ended with (their own uncertainty is in the step's covariance)
    let lags = r.sensor_lags;
    let res = move |q: &Params| res(q, &lags);
    // the estimates of the linearization get the chained covariance; those held at a bound
    // (sensor lags at 0, [`fit_dynamic`]) keep theirs
    let in_lin = |n: &String| r.linearization.as_ref().is_none_or(|l| l.names.contains(n));
    let (mut own, held): (Vec<_>, Vec<_>) = r.uncertainty.drain(..).partition(|(n, _)| in_lin(n));
    let boxes: Vec<(f64, f64)> = boxes
        .iter()
        .zip(&r.params)
        .filter(|(_, (n, _))| in_lin(n))
        .map(|(b, _)| *b)
        .collect();
    let cond = add_fixed(
        &mut own,
        &r.linearization,
        cov,
        res,
        p,
        3,
        &boxes,
        opts.fixed_jacobian,
    );
    r.uncertainty = own;
    r.uncertainty.extend(held);
    // stopped at its evaluation limit, or by ftol/xtol farther from its optimum than the noise:
    // flagged as steps 5, 7 and 8 are
    r.flag_early_stop();
    est.extend(r.uncertainty.iter().cloned());
    Ok((r, cond))
}

/// Step 4 on the fuel-step `set` with the engine parameters `p`; its estimate added to `est`,
/// with the uncertainty of the parameters it holds fixed ([`add_fixed`]: the static
/// parameters, actuators, V_im, V_em, J_t shape the torque transients through the lag) when
/// `chain` (the pass whose value is reported), else conditional on them; tau_Me and the
/// step's report. The step levels are step 3's (`opts.step3.window.levels`).
fn run_step4(
    p: &Params,
    set: &DynamicData,
    c: &Campaign,
    chain: bool,
    opts: &PipelineOptions,
    cov: &mut NamedCov,
    est: &mut Vec<(String, ParamEstimate)>,
) -> Result<(f64, CompleteReport), PipelineError> {
    let levels = opts.step3.window.levels;
    let (tau, mut r) = step4(p, set, &c.stationary, levels).map_err(at(4))?;
    if chain {
        let res = torque_residuals(set, &c.stationary, tau, levels);
        add_fixed(
            &mut r.uncertainty,
            &r.linearization,
            cov,
            res,
            p,
            4,
            &[],
            opts.fixed_jacobian,
        );
    }
    r.flag_early_stop();
    est.extend(r.uncertainty.iter().cloned());
    Ok((tau, r))
}

/// Add to a step's covariance the uncertainty of the parameters it held fixed (every earlier
/// estimate in `cov`; [`super::uncertainty`]), with the step's residual function `res` at the
/// whole parameter set `p` (the estimate); replace the step's `estimates` and insert its
/// covariance into `cov`. `boxes`: the bounds (lo, hi) the step's search kept its
/// parameters in (in the order of its linearization; empty: none): an estimate confined to
/// [lo, hi] has a variance of at most (hi - lo)^2 / 4 (Popoviciu's inequality), so a larger
/// linearized variance (the propagation through a nearly singular step) is scaled down to that
/// bound, its correlations kept ([`cap_variances`]). `how`: J_f by forward differences or
/// sigma points ([`FixedJacobian`]).
/// Returns the step's conditional linearization ([`Conditional`]) for
/// [`joint_covariance`].
#[allow(clippy::too_many_arguments)]
fn add_fixed(
    estimates: &mut Vec<(String, ParamEstimate)>,
    lin: &Option<Linearization>,
    cov: &mut NamedCov,
    res: impl Fn(&Params) -> Vec<f64> + Sync,
    p: &Params,
    step: u8,
    boxes: &[(f64, f64)],
    how: FixedJacobian,
) -> Option<Conditional> {
    let lin = lin.as_ref()?;
    let own: Vec<&str> = lin.names.iter().map(String::as_str).collect();
    let fixed = cov.without(&own);
    let n = own.len();
    let (total, s) = if fixed.names.is_empty() {
        (lin.covariance.clone(), DMatrix::zeros(n, 0))
    } else {
        let j_fixed = match how {
            FixedJacobian::Forward => fd_jacobian_named(&res, p, &fixed.names),
            FixedJacobian::SigmaPoints => sigma_point_jacobian_named(&res, p, &fixed),
        };
        let s = sensitivity(&lin.jacobian, &j_fixed);
        (&lin.covariance + &s * &fixed.cov * s.transpose(), s)
    };
    let total = if boxes.len() == n {
        cap_variances(total, boxes)
    } else {
        total
    };
    let theta: Vec<f64> = estimates.iter().map(|(_, e)| e.value).collect();
    if theta.len() == n {
        *estimates = estimates_from_cov(&own, &theta, &total, step);
    }
    cov.set_block(&NamedCov {
        names: lin.names.clone(),
        cov: total,
    });
    Some(Conditional {
        names: lin.names.clone(),
        cov: lin.covariance.clone(),
        fixed: fixed.names,
        s,
    })
}

/// Scale the rows and columns of a covariance so that no variance exceeds `(hi - lo)^2 / 4`
/// of its parameter's box (Popoviciu's bound on the variance of a quantity confined to
/// [lo, hi]); correlations are kept, so the result stays positive semidefinite. Infinite, NaN
/// or non-positive variances (undetermined directions, or a propagation whose huge terms
/// cancelled to a negative diagonal) become the bound with no correlation, and correlations
/// beyond +-1 (the same rounding) are clipped to +-1.
pub(crate) fn cap_variances(mut c: DMatrix<f64>, boxes: &[(f64, f64)]) -> DMatrix<f64> {
    let n = c.nrows();
    // per parameter the factor of its row and column; None: undetermined or lost to rounding
    let f: Vec<Option<f64>> = (0..n)
        .map(|i| {
            let (lo, hi) = boxes[i];
            let cap = 0.25 * (hi - lo) * (hi - lo);
            let v = c[(i, i)];
            if !(cap.is_finite() && cap > 0.0) || (v > 0.0 && v <= cap) {
                Some(1.0)
            } else if v.is_finite() && v > 0.0 {
                Some((cap / v).sqrt())
            } else {
                None
            }
        })
        .collect();
    for i in 0..n {
        for j in 0..n {
            c[(i, j)] = match (f[i], f[j]) {
                (Some(a), Some(b)) => c[(i, j)] * a * b,
                _ if i == j => 0.25 * (boxes[i].1 - boxes[i].0).powi(2),
                _ => 0.0,
            };
        }
    }
    // a propagation whose huge terms cancelled can leave |correlation| > 1: clip to 1
    for i in 0..n {
        for j in 0..n {
            let m = (c[(i, i)] * c[(j, j)]).sqrt();
            if i != j && c[(i, j)].abs() > m {
                c[(i, j)] = m.copysign(c[(i, j)]);
            }
        }
    }
    c
}

/// Replace the estimates of step 5 and of the repeated step 3 by their joint covariance at the
/// fixed point of the alternation ([`joint_covariance`]; `ext` the covariance of every other
/// estimate). Each step's parameters keep their values, their standard errors and flags come
/// from their block of the joint covariance (correlations within the step, as before). Returns
/// false (nothing changed) when the alternation's linearization is singular.
fn joint_step5_step3(
    c5: &Conditional,
    c3: &Conditional,
    cov: &mut NamedCov,
    est: &mut Vec<(String, ParamEstimate)>,
    p: &Params,
    step5_stop: Option<&str>,
) -> bool {
    let mut own: Vec<&str> = c5.names.iter().map(String::as_str).collect();
    own.extend(c3.names.iter().map(String::as_str));
    let ext = cov.without(&own);
    let Some(joint) = joint_covariance(&[c5, c3], &ext) else {
        return false;
    };
    let mut row0 = 0;
    for (c, step) in [(c5, 5u8), (c3, 3u8)] {
        let nb = c.names.len();
        let sub = joint.cov.view((row0, row0), (nb, nb)).into_owned();
        let names: Vec<&str> = c.names.iter().map(String::as_str).collect();
        let theta: Vec<f64> = names
            .iter()
            .map(|n| super::complete::param_value(p, n).unwrap_or(f64::NAN))
            .collect();
        let mut e = estimates_from_cov(&names, &theta, &sub, step);
        if let Some(why) = step5_stop.filter(|_| step == 5) {
            flag_not_converged(&mut e, why);
        }
        est.extend(e);
        row0 += nb;
    }
    cov.set_block(&joint);
    true
}

/// Flag the estimates of a step-5 search that did not reach its optimum (`why`,
/// [`Step5Report::early_stop`]: its evaluation limit, or ftol/xtol far from it): the
/// linearized covariance at its end point does not describe the estimate (seeds 2 and 4 of
/// `mvem lab` put some such parameters 60-360 standard errors from the truth).
fn flag_not_converged(e: &mut [(String, ParamEstimate)], why: &str) {
    for (_, e) in e.iter_mut() {
        e.flag_not_converged(why);
    }
}

/// The reason of an estimate fitted on the static maps of a step-5 (or step-8) search that
/// stopped short of its optimum (`stop`, its `early_stop`).
fn on_maps_of(stop: &str) -> String {
    format!("fitted on the static maps of a {stop}")
}

/// Flag the reported estimates of steps 3 and 4 repeated after a step 5 that did not reach its
/// optimum (`stop`, [`Step5Report::early_stop`] of the last step-5 pass; `step3_rerun`,
/// `step4_rerun`: whether the step ran again on its static maps): they were fitted on those
/// maps, so they carry the maps' distance from their optimum, which their standard errors do not
/// include (QA, session 37: an 8.9-litre campaign of 15 points, step 5 stopped by xtol at
/// relative offset 3.8, reported V_em +67 % off the truth as identifiable, 4.9 standard errors).
/// The step-5 estimates themselves are flagged where step 5 ran ([`run_step5`]).
fn flag_rests_on_unconverged_step5(
    parameters: &mut BTreeMap<String, ParamEstimate>,
    stop: &str,
    step3_rerun: bool,
    step4_rerun: bool,
) {
    let why = on_maps_of(stop);
    for e in parameters.values_mut() {
        if (e.step == 3 && step3_rerun) || (e.step == 4 && step4_rerun) {
            e.flag_not_converged(&why);
        }
    }
}

/// The three steps of section 9.2.1 on `p` (the 8-state result), numbered 6-8 in errors.
/// `maps_stop`: the early stop of the last step-5 pass ([`Step5Report::early_stop`]), whose
/// static maps step 7 runs on. With `refine_dynamics` step 7 runs again after step 8, on its
/// maps. Each search's estimates are flagged as step 5's are when it did not reach its optimum
/// ([`Step5Report::flag_early_stop`]), and step 7's also when its maps come from such a search.
/// Step 8 runs through [`run_static_step`] as step 5 does; its estimates are added to `est`.
fn tune_twelve(
    c: &Campaign,
    p: &mut Params,
    opts: &PipelineOptions,
    maps_stop: Option<String>,
    cov: &mut NamedCov,
    est: &mut Vec<(String, ParamEstimate)>,
) -> Result<TwelveReport, PipelineError> {
    let t = Instant::now();
    let (k, k_rep) = fit_k_ic(&c.stationary).map_err(at(6))?;
    p.intercooler.k_ic = k;
    let mut dynamic = None;
    if opts.steps[2] {
        begin(7, false)?;
        dynamic = Some(run_step7(c, p, opts, maps_stop.as_deref())?);
    }
    let mut statics = None;
    if opts.steps[4] {
        begin(8, false)?;
        let so = Step5Options {
            model: ModelOrder::Twelve,
            beta: BETA_12,
            ..opts.step5.clone()
        };
        let th0 = theta_of(&static_params(ModelOrder::Twelve), p);
        let (r, _) = run_static_step(p, c, &th0, opts, &so, 8, cov, est)?;
        statics = Some(r);
    }
    // step 7 again on step 8's static maps, as step 3 after step 5
    let mut dynamic_refined = None;
    if opts.refine_dynamics && opts.steps[2] && opts.steps[4] {
        begin(7, true)?;
        let stop8 = statics.as_ref().and_then(Step5Report::early_stop);
        dynamic_refined = Some(run_step7(c, p, opts, stop8.as_deref())?);
    }
    Ok(TwelveReport {
        k_ic: k_rep,
        dynamic,
        dynamic_refined,
        statics,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Step 7 (V_ic, V_im, V_em, J_t by (74)-(75) on the 12-state model) from `p` (replaced by
/// the result), V_ic started at [`V_IC_START`] scaled to the engine, the others at their
/// values in `p`; its estimates flagged when the search did not reach its optimum, or when the
/// static maps it ran on come from a search that did not (`maps_stop`).
fn run_step7(
    c: &Campaign,
    p: &mut Params,
    opts: &PipelineOptions,
    maps_stop: Option<&str>,
) -> Result<CompleteReport, PipelineError> {
    let sets = sets_with_role(&c.manifest.datasets, &c.dynamic, Role::Dynamic, true);
    if sets.is_empty() {
        return Err(missing(7, "VGT/EGR data set with role \"dynamic\""));
    }
    let s3 = &opts.step3;
    // V_ic's start and bounds are given for the published engine: scaled by the
    // displacement as step 3's volumes are (Step3Start::scaled_to; the identity there)
    let v_ic = V_IC_START.map(|v| v * (p.cylinder.v_d / PUBLISHED_V_D));
    let th0 = [
        v_ic[0],
        p.intake_manifold.v_im,
        p.exhaust_manifold.v_em,
        p.turbo.j_t,
    ];
    let clip = |v: f64, lo: f64, hi: f64| v.clamp(lo, hi);
    let th0: Vec<f64> = th0
        .iter()
        .zip([v_ic[1], s3.lo[0], s3.lo[1], s3.lo[2]])
        .zip([v_ic[2], s3.hi[0], s3.hi[1], s3.hi[2]])
        .map(|((v, lo), hi)| clip(*v, lo, hi))
        .collect();
    let f = DynamicFit {
        order: ModelOrder::Twelve,
        names: &["v_ic", "v_im", "v_em", "j_t"],
        theta0: &th0,
        lo: &[v_ic[1], s3.lo[0], s3.lo[1], s3.lo[2]],
        hi: &[v_ic[2], s3.hi[0], s3.hi[1], s3.hi[2]],
        scale: &[0.01, 0.02, 0.02, 1e-4],
        amp_floor: s3.amp_floor,
        window: s3.window,
        lags: opts.step5.sensor_lags,
        max_eval: opts.step3_max_eval,
    };
    let (q, mut r) = fit_dynamic(
        "12-state step 2 (V_ic, V_im, V_em, J_t)",
        p,
        &sets,
        &c.stationary,
        &f,
    )
    .map_err(at(7))?;
    *p = q;
    r.flag_early_stop();
    if let Some(stop) = maps_stop {
        flag_not_converged(&mut r.uncertainty, &on_maps_of(stop));
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::element_name;
    use crate::tuning::data::StationaryPoint;

    #[test]
    fn a_caveat_names_step_3_parameters_that_rest_on_flagged_static_maps() {
        let est = |identifiable: bool, step: u8| ParamEstimate {
            value: 1.0,
            std_error: 0.01,
            identifiable,
            correlated_with: vec![],
            reason: String::new(),
            step,
            converged: true,
        };
        let mut p = BTreeMap::new();
        p.insert("intake_manifold.v_im".to_string(), est(true, 3));
        p.insert("exhaust_manifold.v_em".to_string(), est(false, 3));
        p.insert("turbo.j_t".to_string(), est(true, 3));
        p.insert("compressor.w_copt".to_string(), est(false, 5));
        p.insert("compressor.pi_copt".to_string(), est(false, 5));
        p.insert("turbine.k_t".to_string(), est(true, 5));
        p.insert("cylinder.eta_sc".to_string(), est(true, 5));
        p.insert("egr_actuator.tau_egr1".to_string(), est(false, 2)); // not a static map
        let note = inherited_static_bias(&p).expect("a caveat");
        assert!(note.starts_with("intake_manifold.v_im, turbo.j_t are reported identifiable"));
        assert!(
            note.contains(
                "but 2 static parameters are flagged not identifiable (compressor 2 of 2)"
            ),
            "{note}"
        );
        assert!(
            !note.contains("egr_actuator") && !note.contains("turbine"),
            "{note}"
        );
        // every static parameter identifiable, or no step-3 parameter identifiable: nothing to say
        let mut ok = p.clone();
        ok.insert("compressor.w_copt".to_string(), est(true, 5));
        ok.insert("compressor.pi_copt".to_string(), est(true, 1));
        assert_eq!(inherited_static_bias(&ok), None);
        let mut flagged3 = p.clone();
        for k in ["intake_manifold.v_im", "turbo.j_t"] {
            flagged3.insert(k.to_string(), est(false, 3));
        }
        assert_eq!(inherited_static_bias(&flagged3), None);
        // QA (a 100-litre engine's campaign): one parameter read "turbo.j_t are reported"
        let mut one = p.clone();
        one.insert("intake_manifold.v_im".to_string(), est(false, 3));
        let note = inherited_static_bias(&one).expect("a caveat");
        assert!(
            note.starts_with("turbo.j_t is reported identifiable with standard errors"),
            "{note}"
        );
    }

    /// QA (session 37, an 8.9-litre campaign of 15 points): step 5 stopped by xtol at relative
    /// offset 3.8 (35 parameters: up to 22.5 standard errors from its optimum), step 3 ran
    /// again on its static maps, and V_em, 4.9 standard errors off the truth, was reported
    /// identifiable; the early stop was a separate warning. Now every estimate of that step 5
    /// and of the steps repeated on its maps is "not converged", with the stop as the reason.
    #[test]
    fn estimates_of_a_step_5_stopped_short_of_its_optimum_are_not_identifiable() {
        let est = |identifiable: bool, step: u8, reason: &str| ParamEstimate {
            value: 1.0,
            std_error: 0.1,
            identifiable,
            correlated_with: vec![],
            reason: reason.to_string(),
            step,
            converged: true,
        };
        // converged, or stopped within the noise: nothing to flag
        assert_eq!(
            Step5Report::for_tests(35, "relative offset", 0.1).early_stop(),
            None
        );
        assert_eq!(Step5Report::for_tests(35, "xtol", 0.16).early_stop(), None); // R^2 p = 0.9

        // R = 3.8 with a decrease of 5.25 residual variances measured along the Gauss-Newton
        // step (session 39: one below 1 is the optimum within the noise, not flagged)
        let mut r = Step5Report::for_tests(35, "xtol", 3.8);
        r.gauss_newton_decrease = Some(0.4);
        r.gauss_newton_t = Some(0.01);
        assert_eq!(r.early_stop(), None);
        r.gauss_newton_decrease = Some(5.25);
        r.gauss_newton_t = Some(0.1);
        let stop = r.early_stop().expect("stopped short");
        assert_eq!(
            stop,
            "step 5 stopped (xtol) before its optimum (relative offset 3.800: up to 22.5 \
             standard errors from it, not in the standard errors; measured along the \
             Gauss-Newton step: 5.25 residual variances at t = 0.1)"
        );
        let mut limit = Step5Report::for_tests(35, "evaluation limit", f64::NAN);
        limit.converged = false;
        limit.n_eval = 80;
        assert_eq!(
            limit.early_stop().as_deref(),
            Some("step 5 stopped at its evaluation limit before converging, after 80 evaluations")
        );
        // step 5's own estimates (run_step5)
        let mut s5 = vec![
            ("k_t".to_string(), est(true, 5, "rel. std. error 1.00 %")),
            ("w_copt".to_string(), est(false, 5, "rel. std. error 40 %")),
        ];
        flag_not_converged(&mut s5, &stop);
        assert!(s5.iter().all(|(_, e)| !e.identifiable && !e.converged));
        assert_eq!(s5[0].1.reason, format!("{stop} (rel. std. error 1.00 %)"));
        assert_eq!(s5[1].1.reason, format!("rel. std. error 40 %; {stop}"));
        // the steps repeated on its maps
        let mut m = BTreeMap::new();
        m.insert(
            "exhaust_manifold.v_em".to_string(),
            est(true, 3, "rel. std. error 13.60 %"),
        );
        m.insert(
            "test_cell.tau_me".to_string(),
            est(true, 4, "rel. std. error 2.00 %"),
        );
        m.insert(
            "egr_actuator.tau_egr1".to_string(),
            est(true, 2, "rel. std. error 1.00 %"),
        );
        m.insert(
            "cylinder.eta_sc".to_string(),
            est(true, 1, "rel. std. error 1.00 %"),
        );
        let mut only3 = m.clone();
        flag_rests_on_unconverged_step5(&mut only3, &stop, true, false);
        let v_em = &only3["exhaust_manifold.v_em"];
        assert!(!v_em.identifiable && !v_em.converged);
        assert_eq!(
            v_em.reason,
            format!("fitted on the static maps of a {stop} (rel. std. error 13.60 %)")
        );
        // step 4 not repeated, steps 1-2 not on step 5's maps: unchanged
        for k in [
            "test_cell.tau_me",
            "egr_actuator.tau_egr1",
            "cylinder.eta_sc",
        ] {
            assert_eq!(only3[k], m[k], "{k}");
        }
        flag_rests_on_unconverged_step5(&mut m, &stop, true, true);
        assert!(!m["test_cell.tau_me"].identifiable && !m["test_cell.tau_me"].converged);
        assert!(m["cylinder.eta_sc"].identifiable);
    }

    #[test]
    fn variances_beyond_the_box_are_capped_with_their_correlations_by_hand() {
        // var 4 and 1e6, covariance 0.5 * 2 * 1000 (correlation 0.5); boxes [0, 10] (bound
        // 25: kept) and [0, 2] (bound 1: scaled by 1e-3); an undetermined third one and a
        // negative fourth (rounding)
        let c = DMatrix::from_row_slice(
            4,
            4,
            &[
                4.0,
                1000.0,
                0.0,
                0.0,
                1000.0,
                1e6,
                0.0,
                0.0,
                0.0,
                0.0,
                f64::INFINITY,
                0.0,
                0.0,
                0.0,
                0.0,
                -1e-3,
            ],
        );
        let k = cap_variances(c, &[(0.0, 10.0), (0.0, 2.0), (1.0, 3.0), (0.0, 4.0)]);
        assert_eq!(k[(0, 0)], 4.0);
        assert!((k[(1, 1)] - 1.0).abs() < 1e-12);
        // correlation kept: 0.5 * 2 * 1
        assert!((k[(0, 1)] - 1.0).abs() < 1e-12 && (k[(1, 0)] - 1.0).abs() < 1e-12);
        assert_eq!((k[(2, 2)], k[(3, 3)]), (1.0, 4.0));
        assert_eq!((k[(0, 2)], k[(2, 1)], k[(3, 0)]), (0.0, 0.0, 0.0));
        // a correlation beyond 1 (rounding) is clipped
        let c = DMatrix::from_row_slice(2, 2, &[1.0, 3.0, 3.0, 4.0]);
        let k = cap_variances(c, &[(0.0, 10.0), (0.0, 10.0)]);
        assert_eq!((k[(0, 1)], k[(1, 0)], k[(1, 1)]), (2.0, 2.0, 4.0));
    }

    fn estimate() -> ParamEstimate {
        ParamEstimate {
            value: 1.0,
            std_error: 0.01,
            identifiable: true,
            correlated_with: vec![],
            reason: "rel. std. error 1 %".into(),
            step: 5,
            converged: true,
        }
    }

    /// Points over W_c in [w0, w1] kg/s and Pi_c in [1.1, 2.5].
    fn points(w0: f64, w1: f64) -> Vec<StationaryPoint> {
        (0..10)
            .map(|k| {
                let f = k as f64 / 9.0;
                StationaryPoint {
                    w_c: w0 + f * (w1 - w0),
                    p_amb: 1.0e5,
                    p_c: 1.0e5 * (1.1 + 1.4 * f),
                    ..Default::default()
                }
            })
            .collect()
    }

    #[test]
    fn an_efficiency_peak_outside_the_measured_region_is_flagged() {
        let mut c = Params::published().compressor;
        c.c_pi = 1.0;
        c.pi_copt = 1.0; // pi_c = Pi_c - 1 spans 0.1-1.5 in `points`
        let all = || {
            let mut m: BTreeMap<String, ParamEstimate> = EFFICIENCY_ELLIPSE
                .iter()
                .chain(&FLOW_MAP)
                .map(|k| (k.to_string(), estimate()))
                .collect();
            m.insert("compressor.r_c".into(), estimate());
            m
        };
        // peak inside: nothing changes
        c.w_copt = 0.3;
        let mut m = all();
        flag_extrapolated_efficiency_peak(&c, &points(0.1, 0.6), &mut m);
        assert!(m.values().all(|e| e.identifiable));
        // W_copt beyond the largest measured flow: the ellipse's parameters are flagged, with
        // the reason; the flow parameter r_c is not
        c.w_copt = 1.77;
        let mut m = all();
        flag_extrapolated_efficiency_peak(&c, &points(0.1, 0.6), &mut m);
        for k in EFFICIENCY_ELLIPSE.iter().chain(&FLOW_MAP) {
            assert!(!m[*k].identifiable, "{k}");
            assert!(m[*k].reason.contains("outside the measured region"), "{k}");
            assert!(m[*k].reason.contains("rel. std. error 1 %"), "{k}");
        }
        assert!(m["compressor.c_phi2"].reason.contains("flow map"));
        assert!(m["compressor.r_c"].identifiable);
        // pi_copt beyond the measured pressure ratios
        c.w_copt = 0.3;
        c.pi_copt = 2.58;
        let mut m = all();
        flag_extrapolated_efficiency_peak(&c, &points(0.1, 0.6), &mut m);
        assert!(!m["compressor.pi_copt"].identifiable);
        // no stationary points: nothing to compare with, nothing flagged
        let mut m = all();
        flag_extrapolated_efficiency_peak(&c, &[], &mut m);
        assert!(m.values().all(|e| e.identifiable));
    }

    #[test]
    fn eta_c_is_reported_at_its_best_determined_measured_point() {
        let p = Params::published();
        let pts = points(0.1, 0.6);
        // only eta_cmax and W_copt uncertain, uncorrelated: var(eta_c) at (W_c, Pi_c) is
        // var(eta_cmax) + (2 a1 (W_c - W_copt) + 2 a3 x1)^2 var(W_copt) (eq. (62), by hand),
        // smallest at the measured point where that gradient is smallest
        let (s_eta, s_w) = (0.004, 0.02);
        let cov = NamedCov::new(
            &["eta_cmax", "w_copt"],
            DMatrix::from_row_slice(2, 2, &[s_eta * s_eta, 0.0, 0.0, s_w * s_w]),
        );
        let c = &p.compressor;
        let by_hand = |w: f64, pi: f64| {
            let x0 = w - c.w_copt;
            let x1 = (pi - 1.0).powf(c.c_pi) - c.pi_copt;
            let g = 2.0 * (c.q_c[0][0] * x0 + c.q_c[0][1] * x1); // -d eta_c / d W_copt
            (s_eta * s_eta + g * g * s_w * s_w).sqrt()
        };
        let best = pts
            .iter()
            .map(|s| {
                let pi = s.p_c / s.p_amb;
                (s.w_c, pi, by_hand(s.w_c, pi))
            })
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .unwrap();
        let mut m: BTreeMap<String, ParamEstimate> = EFFICIENCY_ELLIPSE
            .iter()
            .map(|k| (k.to_string(), estimate()))
            .collect();
        // c_pi already flagged for a symptom
        m.get_mut("compressor.c_pi")
            .unwrap()
            .flag("correlation 0.999 with w_copt");
        let k = compressor_efficiency_on_the_measured_range(&p, &pts, &cov, &mut m).unwrap();
        assert_eq!(k.name, "compressor.eta_c_at_point");
        assert_eq!(
            k.at,
            vec![("w_c".to_string(), best.0), ("pi_c".to_string(), best.1)]
        );
        assert!(
            (k.std_error / best.2 - 1.0).abs() < 1e-6,
            "{} {}",
            k.std_error,
            best.2
        );
        let eta = compressor::efficiency(c, best.0, best.1, SEM);
        assert_eq!(k.value, eta);
        // eta_cmax and c_pi flagged (errors in variables), the cause first and the earlier
        // reason after it; the shape parameters are left to flag_efficiency_ellipse_shape
        for key in ["compressor.eta_cmax", "compressor.c_pi"] {
            assert!(!m[key].identifiable, "{key}");
            assert!(m[key].reason.starts_with("peak value or exponent"), "{key}");
            assert!(m[key].reason.contains("errors in variables"), "{key}");
        }
        assert!(m["compressor.eta_cmax"]
            .reason
            .ends_with("(rel. std. error 1 %)"));
        assert!(m["compressor.c_pi"]
            .reason
            .ends_with("(correlation 0.999 with w_copt (rel. std. error 1 %))"));
        assert!(m["compressor.w_copt"].identifiable);
        // no usable stationary point: no combination, nothing flagged
        let mut m: BTreeMap<String, ParamEstimate> = EFFICIENCY_ELLIPSE
            .iter()
            .map(|k| (k.to_string(), estimate()))
            .collect();
        assert!(compressor_efficiency_on_the_measured_range(&p, &[], &cov, &mut m).is_none());
        assert!(m.values().all(|e| e.identifiable));
    }

    #[test]
    fn flow_map_coefficients_are_never_reported_one_by_one() {
        let mut m: BTreeMap<String, ParamEstimate> = FLOW_MAP
            .iter()
            .map(|k| {
                let e = ParamEstimate {
                    value: 0.4,
                    std_error: 0.05,
                    identifiable: true,
                    correlated_with: Vec::new(),
                    reason: "rel. std. error 12.5 %".into(),
                    step: 5,
                    converged: true,
                };
                (k.to_string(), e)
            })
            .collect();
        let j_t = ParamEstimate {
            value: 2.2e-4,
            std_error: 1e-5,
            identifiable: true,
            correlated_with: Vec::new(),
            reason: "rel. std. error 4.5 %".into(),
            step: 3,
            converged: true,
        };
        m.insert("turbo.j_t".into(), j_t);
        flag_flow_map_coefficients(&mut m);
        for k in FLOW_MAP {
            assert!(!m[k].identifiable, "{k}");
            assert!(
                m[k].reason.contains("ellipse")
                    && m[k].reason.ends_with("(rel. std. error 12.5 %)")
            );
        }
        assert!(m["turbo.j_t"].identifiable);
        // the VGT area map likewise (lab seed 8: c_f1 1.791 +- 0.005 for a true 1.948)
        for k in VGT_AREA_MAP {
            let e = ParamEstimate {
                value: 1.791,
                std_error: 0.005,
                reason: "rel. std. error 0.27 %".into(),
                ..m["turbo.j_t"].clone()
            };
            m.insert(k.to_string(), e);
        }
        flag_vgt_area_map(&mut m);
        for k in VGT_AREA_MAP {
            assert!(!m[k].identifiable, "{k}");
            assert!(m[k]
                .reason
                .contains("VGT effective-area ellipse arc (eq. (56))"));
            assert!(m[k].reason.ends_with("(rel. std. error 0.27 %)"), "{k}");
        }
        assert!(m["turbo.j_t"].identifiable);
    }

    #[test]
    fn a_fitted_lag_on_its_upper_bound_is_a_caveat() {
        let mut opts = PipelineOptions::default();
        opts.step3.fit_lags = true;
        let lags = |p_im: f64, n_t: f64| SensorLags {
            p_im,
            p_em: 0.0,
            w_c: 0.02,
            n_t,
        };
        assert!(lags_at_upper_bound(Some(&lags(0.01, 0.0)), &opts).is_none());
        assert!(lags_at_upper_bound(None, &opts).is_none());
        let c = lags_at_upper_bound(Some(&lags(0.1989, 0.2)), &opts).expect("caveat");
        assert!(
            c.contains("tau_p_im 198.9 ms, tau_n_t 200.0 ms") && c.contains("200 ms"),
            "{c}"
        );
        // 197 ms is inside the box by more than the 2 ms grid; given lags are not fitted
        assert!(lags_at_upper_bound(Some(&lags(0.197, 0.0)), &opts).is_none());
        opts.step3.fit_lags = false;
        assert!(lags_at_upper_bound(Some(&lags(0.2, 0.2)), &opts).is_none());
    }

    #[test]
    fn a_map_with_a_coefficient_not_identifiable_is_flagged_whole() {
        let est = |identifiable: bool| ParamEstimate {
            value: 1.0,
            std_error: 0.01,
            identifiable,
            correlated_with: Vec::new(),
            reason: "rel. std. error 1 %".into(),
            step: 5,
            converged: true,
        };
        let mut m = BTreeMap::new();
        // 2 of 3 turbine-efficiency coefficients flagged; 1 of 2 turbine-flow ones; 1 of 3
        // c_vol; the only tuned c_egr coefficient; no friction coefficient
        for (k, identifiable) in [
            ("turbine.c_m[1]", false),
            ("turbine.c_m[2]", false),
            ("turbine.c_m[3]", true),
            ("turbine.c_f1", false),
            ("turbine.c_f2", true),
            ("cylinder.c_vol[1]", true),
            ("cylinder.c_vol[2]", true),
            ("cylinder.c_vol[3]", false),
            ("egr_valve.c_egr[1]", false),
            ("egr_valve.pi_egropt", true),
            ("cylinder.c_fric[1]", true),
            ("cylinder.c_fric[2]", true),
            ("cylinder.c_fric[3]", true),
            ("intake_manifold.v_im", false),
            ("turbo.j_t", true),
        ] {
            m.insert(k.to_string(), est(identifiable));
        }
        flag_maps_known_only_as_a_whole(&mut m);
        // a flagged coefficient of a map: the rest is flagged, with the reason
        let r = &m["turbine.c_m[3]"].reason;
        assert!(!m["turbine.c_m[3]"].identifiable);
        assert!(r.starts_with("2 of the 3 coefficients"), "{r}");
        assert!(
            r.contains("turbine.c_m[1], turbine.c_m[2]") && r.ends_with("(rel. std. error 1 %)"),
            "{r}"
        );
        assert!(!m["turbine.c_f2"].identifiable);
        assert!(m["turbine.c_f2"]
            .reason
            .starts_with("1 of the 2 coefficients"));
        // 1 of 3 c_vol flagged: the others are flagged too (any flagged coefficient)
        assert!(!m["cylinder.c_vol[1]"].identifiable && !m["cylinder.c_vol[2]"].identifiable);
        assert!(m["cylinder.c_vol[1]"]
            .reason
            .starts_with("1 of the 3 coefficients"));
        // a map with every coefficient identifiable stays so
        assert!((0..3).all(|i| m[&element_name("cylinder.c_fric", &[i])].identifiable));
        // the EGR-valve flow: a flagged area coefficient flags pi_egropt (their product is
        // what the data fix); other parameters untouched
        assert!(!m.contains_key("egr_valve.c_egr[2]"));
        assert!(!m["egr_valve.pi_egropt"].identifiable);
        assert!(m["egr_valve.pi_egropt"].reason.starts_with(
            "1 of the 2 coefficients of its map are not identifiable (egr_valve.c_egr[1])"
        ));
        assert!(m["turbo.j_t"].identifiable && !m["intake_manifold.v_im"].identifiable);
    }

    #[test]
    fn a3_on_the_edge_of_the_psd_cone_says_so() {
        let est = |std_error: f64| ParamEstimate {
            value: -16.3865,
            std_error,
            identifiable: false,
            correlated_with: Vec::new(),
            reason: "not determined by the data".into(),
            step: 8,
            converged: true,
        };
        // a1 = 5.92563, a2 = 45.31454: sqrt(a1 a2) = 16.3865 (step 8 of session 43)
        let (a1, a2): (f64, f64) = (5.92563, 45.31454);
        let edge = -(a1 * a2).sqrt();
        let q = [[a1, edge], [edge, a2]];
        let mut m = BTreeMap::from([("compressor.q_c[1][2]".to_string(), est(f64::INFINITY))]);
        flag_a3_on_the_psd_edge(&q, &mut m);
        let r = &m["compressor.q_c[1][2]"].reason;
        assert!(
            r.starts_with("a3 = -16.3865 lies on the edge of Q_c's positive semidefinite cone")
                && r.contains("sqrt(a1 a2) = 16.3865")
                && r.ends_with("(not determined by the data)"),
            "{r}"
        );
        // inside the cone, or a finite standard error: left as it is
        for (a3, se) in [(0.9 * edge, f64::INFINITY), (edge, 1.0)] {
            let q = [[a1, a3], [a3, a2]];
            let mut m = BTreeMap::from([("compressor.q_c[1][2]".to_string(), est(se))]);
            flag_a3_on_the_psd_edge(&q, &mut m);
            assert_eq!(
                m["compressor.q_c[1][2]"].reason,
                "not determined by the data"
            );
        }
    }

    /// The keys the flags look up are the report's keys: registry paths, elements 1-based (a
    /// list still in the old 0-based names, "cylinder.c_vol[0]", would flag nothing).
    #[test]
    fn the_flagged_key_lists_are_registry_paths() {
        let lists = [
            &EFFICIENCY_ELLIPSE[..],
            &FLOW_MAP[..],
            &VGT_AREA_MAP[..],
            &EFFICIENCY_ELLIPSE_SHAPE[..],
        ];
        for key in lists.into_iter().chain(MAP_COEFFICIENTS).flatten() {
            let info = crate::params::ParamInfo::find(key);
            assert_eq!(info.map(|i| i.path.as_str()), Some(*key), "{key}");
        }
        assert_eq!(MAP_COEFFICIENTS[2][0], "cylinder.c_fric[1]");
        assert_eq!(EFFICIENCY_ELLIPSE[5], toml_path("a3").unwrap());
    }

    #[test]
    fn sets_the_model_cannot_simulate_are_named_with_the_reason() {
        // a set of constant commands that runs, one with a single sample, one with a NaN engine
        // speed: the last two come back as failures naming the set, the first as errors
        let set = |name: &str, n: usize, n_e: f64| DynamicData {
            name: name.into(),
            t: (0..n).map(|i| 0.1 * i as f64).collect(),
            columns: [
                ("n_e", n_e),
                ("u_delta", 100.0),
                ("u_egr", 30.0),
                ("u_vgt", 60.0),
            ]
            .iter()
            .map(|(c, v)| (c.to_string(), vec![*v; n]))
            .collect(),
        };
        let (good, short, nan) = (
            set("good", 21, 1500.0),
            set("short", 1, 1500.0),
            set("nan", 21, f64::NAN),
        );
        let p = Params::published();
        let (ok, failed) = errors_on_sets(
            &p,
            &[&good, &short, &nan],
            &[],
            ModelOrder::Eight,
            None,
            &SensorLags::NONE,
        );
        assert_eq!(ok.len(), 1);
        assert_eq!(ok[0].name, "good");
        assert!(ok[0].oscillations.is_empty());
        let names: Vec<&str> = failed.iter().map(|f| f.set.as_str()).collect();
        assert_eq!(names, ["short", "nan"]);
        assert!(
            failed[0].message.contains("fewer than 2 samples"),
            "{}",
            failed[0].message
        );
        assert!(!failed[1].message.is_empty());
        // the message is the simulator's, without the set name repeated
        assert!(!failed[0].message.contains("data set short"));
    }

    #[test]
    fn rows_of_an_oscillating_set_leave_the_linearization_by_hand() {
        // one parameter; a calm block of 4 rows (J = 1, residuals +-0.1) and a limit-cycle
        // block of 3 rows (J = 1000: noise that passes for information, residuals +-1)
        let jac = DMatrix::from_column_slice(7, 1, &[1.0, 1.0, 1.0, 1.0, 1e3, 1e3, 1e3]);
        let res = [0.1, -0.1, 0.1, -0.1, 1.0, -1.0, 1.0];
        let blocks = [4, 3];
        let full = block_covariance(&jac, &res, &blocks);
        let mut r = Step5Report {
            params: vec![("p".into(), 2.0)],
            uncertainty: estimates_from_cov(&["p"], &[2.0], &full, 5),
            linearization: Some(Linearization {
                names: vec!["p".into()],
                jacobian: jac,
                covariance: full.clone(),
            }),
            ..Step5Report::for_tests(1, "xtol", 0.1)
        };
        // with every row: about sqrt(7/6 * 3e6) / 3e6 = 6.2e-4
        assert!(
            (full[(0, 0)].sqrt() - 6.24e-4).abs() < 1e-6,
            "{}",
            full[(0, 0)]
        );
        let keep = [true, true, true, true, false, false, false];
        let kept = kept_blocks(&blocks, &keep);
        assert_eq!(kept, vec![4]);
        assert!(relinearize_rows(&mut r, &keep, &res, &kept, &[1.0], 5));
        // calm rows only: m = 4, n = 1, dof factor 4/3, mean square 0.01, lag-1 correlation
        // -0.75 (clamped to 0): variance 0.01 * 4/3 / (J^T J = 4) = 1/300
        let se = r.uncertainty[0].1.std_error;
        assert!((se - (1.0f64 / 300.0).sqrt()).abs() < 1e-12, "{se}");
        let lin = r.linearization.as_ref().expect("linearization");
        assert_eq!(lin.jacobian.nrows(), 4);
        assert!((lin.covariance[(0, 0)] - 1.0 / 300.0).abs() < 1e-15);
        // relative std. error as in step 5: the plain Gauss-Newton one, sigma^2 (J^T J)^-1 with
        // sigma^2 = 0.04 / 3, over the value 2
        let rel = r.rel_std_err[0].1;
        assert!(
            (rel - (0.04f64 / 3.0 / 4.0).sqrt() / 2.0).abs() < 1e-12,
            "{rel}"
        );
        // too few rows left: nothing changes
        let before = r.uncertainty[0].1.std_error;
        assert!(!relinearize_rows(
            &mut r,
            &[true, false, false, false],
            &res[..4],
            &[1],
            &[1.0],
            5,
        ));
        assert_eq!(r.uncertainty[0].1.std_error, before);
    }
}
