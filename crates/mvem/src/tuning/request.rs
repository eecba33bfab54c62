//! One tuning run on a campaign directory, as every front end asks for it: the settings (the
//! options of `mvem tune`, by the same names, with the same defaults and checks), the engine's
//! constants checked against a virtual campaign's truth, the pipeline ([`super::pipeline`]),
//! the test-cell quantities it estimates, and the warnings and notes a user must see.
//!
//! The command line (`mvem tune`, `mvem validate`) and Python (`mvem.tune`, `mvem.validate`)
//! both call [`tune_campaign`] and [`validate_campaign`], so the same campaign and settings give
//! the same parameter file, report and error tables from either.

use super::complete::{ResponseWindow, StepLevels, STEP5_REL_OFFSET_TOL, STEP5_RESTARTS};
use super::constants::{constant_differences, describe_constants, AmbientSource, InputRangeSource};
use super::data::Role;
use super::data::{load_campaign, save_campaign, Campaign, DataError};
use super::lab::{campaign, Envelope, LabOptions, Noise, TABLE1};
use super::pipeline::{self, Init, PipelineError, PipelineOptions, TuneReport};
use super::sensors::{SensorLagMode, SensorLags};
use super::uncertainty::FixedJacobian;
use super::validate::{validate_campaign_with, ValidateError, ValidationReport};
use crate::io::test_cell::TestCell;
use crate::model::ModelOrder;
use crate::params::Params;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::Path;

/// Which rows of cost (77) step 5 uses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CostRows {
    /// Both rows of eq. (77).
    #[default]
    Full,
    /// Only the first row (the complete model on the dynamic sets).
    Dynamic,
    /// Only the second row (the submodels on the stationary points).
    Static,
}

/// The settings of one tuning run: the options of `mvem tune` by their names (snake case here,
/// kebab case on the command line), with its defaults. Unknown names are refused
/// (`deny_unknown_fields`), so a misspelt setting is an error, not a silent default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TuneSettings {
    /// Steps to run: `1-5`, `1-4`, `3,4`, `5`, ...
    pub steps: String,
    /// Where p_amb, T_amb, T_im come from (`auto`, `data`, `params`).
    pub ambient: AmbientSource,
    /// The model's input ranges (`campaign`: widened to contain the campaign; `params`).
    pub input_ranges: InputRangeSource,
    /// Start of step 5 (`step1` values or `naive`, eq. (78)).
    pub init: Init,
    /// Rows of cost (77) (`full`, `dynamic`, `static`).
    pub cost: CostRows,
    /// beta of eq. (77) (> 0).
    pub beta: f64,
    /// After step 5, steps 3 and 4 again with the final static parameters.
    pub refine_dynamics: bool,
    /// With `refine_dynamics`: a second round and the joint covariance.
    pub joint_uncertainty: bool,
    /// The Jacobian of the fixed parameters' residuals (`forward`, `sigma-points`).
    pub fixed_jacobian: FixedJacobian,
    /// Step 5's evaluation limit.
    pub max_evals: usize,
    /// Broyden updates between finite-difference Jacobians in step 5.
    pub broyden: usize,
    /// Step 5's relative offset tolerance (>= 0).
    pub rel_offset: f64,
    /// Step 5's restarts.
    pub restarts: usize,
    /// Step 5 in one pass (no first pass without the oscillating sets).
    pub step5_single_pass: bool,
    /// Evaluation limit of step 5's first pass.
    pub step5_first_pass_max: usize,
    /// Step 1 uses the settled ends of the dynamic sets' steps as compressor flow points.
    pub settled_flow_points: bool,
    /// Step 3's response window \[s\] (> 0; `None`: infinite, every sample alike).
    pub step3_window: Option<f64>,
    /// Weight of the samples after the window in step 3, in (0, 1].
    pub step3_tail_weight: f64,
    /// How step 3 finds the step levels (`least-squares`, `means`).
    pub step_levels: StepLevels,
    /// Sensor lags: `fit`, `none`, `table6` or four time constants \[s\] (p_im, p_em, W_c,
    /// n_t); `None`: fitted when step 3 runs, else those of the base parameter file's test cell.
    pub sensor_lags: Option<String>,
}

impl Default for TuneSettings {
    fn default() -> Self {
        Self {
            steps: "1-5".into(),
            ambient: AmbientSource::Auto,
            input_ranges: InputRangeSource::Campaign,
            init: Init::Step1,
            cost: CostRows::Full,
            beta: 1.0,
            refine_dynamics: true,
            joint_uncertainty: false,
            fixed_jacobian: FixedJacobian::Forward,
            max_evals: 3600,
            broyden: 0,
            rel_offset: STEP5_REL_OFFSET_TOL,
            restarts: STEP5_RESTARTS,
            step5_single_pass: false,
            step5_first_pass_max: 3600,
            settled_flow_points: true,
            step3_window: None,
            step3_tail_weight: ResponseWindow::VOLUMES.tail_weight,
            step_levels: StepLevels::LeastSquares,
            sensor_lags: None,
        }
    }
}

/// A setting that cannot be used: `field` (the snake-case name) and what is wrong, starting
/// with its value where it has one (` 0: must be > 0`) or with `: ` (`: unknown step 7`).
#[derive(Debug, Clone, PartialEq)]
pub struct SettingError {
    /// The setting's name (snake case).
    pub field: &'static str,
    /// The value and the constraint, as appended to the name.
    pub detail: String,
}

impl fmt::Display for SettingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", self.field, self.detail)
    }
}

impl std::error::Error for SettingError {}

impl TuneSettings {
    /// The steps selected by [`Self::steps`].
    pub fn step_list(&self) -> Result<[bool; 5], SettingError> {
        pipeline::parse_steps(&self.steps).map_err(|e| SettingError {
            field: "steps",
            detail: format!(": {e}"),
        })
    }

    /// The pipeline's options for `model`, every setting checked (the first bad one named).
    /// `base_cell`: the test-cell section of the base parameter file, whose sensor lags are
    /// used when [`Self::sensor_lags`] is not given and step 3 is not run.
    pub fn pipeline_options(
        &self,
        model: ModelOrder,
        base_cell: Option<&TestCell>,
    ) -> Result<PipelineOptions, SettingError> {
        if model == ModelOrder::Ten {
            return Err(SettingError {
                field: "model",
                detail: " 10: the tuning pipeline tunes the 8- or 12-state model (the 10-state \
                         model has no parameters of its own)"
                    .into(),
            });
        }
        let steps = self.step_list()?;
        if !(self.beta.is_finite() && self.beta > 0.0) {
            return Err(SettingError {
                field: "beta",
                detail: format!(" {}: must be > 0", self.beta),
            });
        }
        if !(self.rel_offset.is_finite() && self.rel_offset >= 0.0) {
            return Err(SettingError {
                field: "rel_offset",
                detail: format!(" {}: must be >= 0", self.rel_offset),
            });
        }
        let window = self.step3_window.unwrap_or(f64::INFINITY);
        if window.is_nan() || window <= 0.0 {
            return Err(SettingError {
                field: "step3_window",
                detail: format!(" {window}: must be > 0 seconds (inf: every sample alike)"),
            });
        }
        let tail = self.step3_tail_weight;
        if !(tail.is_finite() && tail > 0.0 && tail <= 1.0) {
            return Err(SettingError {
                field: "step3_tail_weight",
                detail: format!(" {tail}: must lie in (0, 1]"),
            });
        }
        let mut opts = PipelineOptions {
            model,
            steps,
            init: self.init,
            ..PipelineOptions::default()
        };
        opts.step5.beta = self.beta;
        opts.refine_dynamics = self.refine_dynamics;
        opts.joint_uncertainty = self.joint_uncertainty;
        opts.fixed_jacobian = self.fixed_jacobian;
        opts.ambient = self.ambient;
        opts.input_ranges = self.input_ranges;
        opts.step5.max_evaluations = self.max_evals;
        opts.step5.broyden_updates = self.broyden;
        opts.step5.rel_offset_tol = self.rel_offset;
        opts.step5.restarts = self.restarts;
        opts.stage_oscillating = !self.step5_single_pass;
        opts.stage_first_pass_max_evaluations = self.step5_first_pass_max;
        opts.settled_flow_points = self.settled_flow_points;
        opts.step3.window = ResponseWindow {
            seconds: window,
            tail_weight: tail,
            levels: self.step_levels,
        };
        opts.sensor_lags = match self.sensor_lags.as_deref().map(str::trim) {
            Some("fit") => SensorLagMode::Fit,
            Some(v) => SensorLagMode::Known(SensorLags::parse(v).map_err(|e| SettingError {
                field: "sensor_lags",
                detail: format!(": {e}"),
            })?),
            None if steps[2] => SensorLagMode::Fit,
            None => match base_cell.and_then(TestCell::lags) {
                Some(l) => SensorLagMode::Known(l),
                None => SensorLagMode::None,
            },
        };
        opts.step5.dynamic_row = self.cost != CostRows::Static;
        opts.step5.static_row = self.cost != CostRows::Dynamic;
        Ok(opts)
    }
}

/// Why a tuning or validation run on a campaign did not produce its result.
#[derive(Debug)]
pub enum RequestError {
    /// A setting cannot be used.
    Setting(SettingError),
    /// The campaign directory cannot be read (file, line and field named).
    Data(DataError),
    /// A tuning step failed (named).
    Pipeline(PipelineError),
    /// A validation simulation or submodel failed (the data set named).
    Validate(ValidateError),
    /// Something else failed (said what).
    Failed(String),
}

impl fmt::Display for RequestError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Setting(e) => e.fmt(f),
            Self::Data(e) => e.fmt(f),
            Self::Pipeline(e) => e.fmt(f),
            Self::Validate(e) => e.fmt(f),
            Self::Failed(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for RequestError {}

/// What a tuning run gives: the tuned parameter set, the test-cell quantities it estimated
/// (written next to the parameters), the report (`tune_report.json`), and the warnings and
/// notes for the user (each starting with `warning:` or `note:`).
#[derive(Debug)]
pub struct CampaignTuning {
    /// The campaign as loaded.
    pub campaign: Campaign,
    /// A virtual campaign's true parameters (its manifest's `true_params`), if readable.
    pub truth: Option<Params>,
    /// The tuned parameters.
    pub params: Params,
    /// tau_Me and the sensor lags: estimated, or kept from the base file's test cell when the
    /// step that estimates them did not run.
    pub test_cell: TestCell,
    /// The report (with the constants' caveats).
    pub report: TuneReport,
    /// Warnings and notes, in the order a user should read them.
    pub messages: Vec<String>,
}

/// A step that failed for lack of data ([`pipeline::tune`]'s "the campaign has no ..."): its
/// message also names the steps the campaign supports ([`super::summary`]).
fn with_supported_steps(mut e: PipelineError, campaign: &Campaign) -> PipelineError {
    if let super::steps::StepError::Solver {
        submodel: "data",
        message,
    } = &mut e.source
    {
        let s = super::summary::summarize(campaign);
        let ok: Vec<String> = s
            .steps
            .iter()
            .filter(|x| x.supported)
            .map(|x| x.step.to_string())
            .collect();
        message.push_str(&format!(
            " (this campaign supports steps {}: `mvem campaign --data DIR` lists its sets)",
            if ok.is_empty() {
                "none".to_string()
            } else {
                ok.join(",")
            }
        ));
    }
    e
}

/// Tune on the campaign in `data_dir` from `base` (the engine's constants and the parameters
/// of the steps not run; `base_cell` its test-cell section, if any). `constants_given`: the
/// caller gave the engine's constants (else a note says they are the published engine's).
pub fn tune_campaign(
    data_dir: &Path,
    base: &Params,
    base_cell: Option<&TestCell>,
    constants_given: bool,
    model: ModelOrder,
    settings: &TuneSettings,
) -> Result<CampaignTuning, RequestError> {
    let opts = settings
        .pipeline_options(model, base_cell)
        .map_err(RequestError::Setting)?;
    let campaign = load_campaign(data_dir).map_err(RequestError::Data)?;
    let set = if constants_given {
        "the parameters given"
    } else {
        "the published parameters"
    };
    let mut messages: Vec<String> =
        super::summary::campaign_warnings(&campaign, &base.input_saturation, set)
            .into_iter()
            .map(|w| format!("warning: {w}"))
            .collect();
    if !constants_given {
        messages.push(format!(
            "note: the engine's constants are the published engine's ({}): for another engine \
             give a parameter file with its constants (`mvem params show > FILE`, then edit)",
            describe_constants(base)
        ));
    }
    // a virtual campaign's engine: its constants against those used
    let truth = campaign
        .manifest
        .true_params
        .as_ref()
        .and_then(|f| crate::io::params::load_params(&data_dir.join(f)).ok());
    let mut constant_caveats = Vec::new();
    if let Some(truth) = &truth {
        let d = constant_differences(base, truth);
        if !d.is_empty() {
            let list: Vec<String> = d
                .iter()
                .map(|x| format!("{} {} (the campaign's engine: {})", x.name, x.used, x.other))
                .collect();
            let msg = format!(
                "the constants used differ from those of the engine that generated this campaign \
                 ({} of its manifest): {}; the tuned parameters absorb the difference. Give its \
                 constants with --params",
                campaign.manifest.true_params.as_deref().unwrap_or_default(),
                list.join(", ")
            );
            messages.push(format!("warning: {msg}"));
            constant_caveats.push(msg);
        }
    }
    let (params, mut report) = pipeline::tune(&campaign, base, &opts)
        .map_err(|e| RequestError::Pipeline(with_supported_steps(e, &campaign)))?;
    messages.extend(report_messages(&report));
    report.caveats.extend(constant_caveats);
    // test-cell quantities next to the model parameters; a value of the base file is kept
    // when the step that estimates it is not run
    let cell = TestCell {
        tau_me: report.tau_me_s.or(base_cell.and_then(|c| c.tau_me)),
        ..TestCell::default()
    };
    let test_cell = match report.sensor_lags.filter(SensorLags::any) {
        Some(l) => cell.with_lags(l),
        None => cell,
    };
    Ok(CampaignTuning {
        campaign,
        truth,
        params,
        test_cell,
        report,
        messages,
    })
}

/// The warnings and notes of a report, each starting with `warning:` or `note:` (the ambient
/// conditions used are a note): input ranges widened, searches stopped by their evaluation
/// limit, step 5 stopped away from its optimum, oscillations the engine does not show, the
/// caveats of the standard errors, data sets the tuned model cannot simulate.
pub fn report_messages(rep: &TuneReport) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(amb) = &rep.ambient {
        out.push(format!("note: {}", amb.describe()));
    }
    if let Some(w) = &rep.input_saturation {
        out.push(format!("warning: {}", w.describe()));
    }
    if let Some(w) = &rep.integrator_limits {
        out.push(format!("warning: {}", w.describe()));
    }
    for (step, conv) in [
        (3, rep.step3.as_ref().map(|r| r.converged)),
        (4, rep.step4.as_ref().map(|r| r.converged)),
        (5, rep.step5.as_ref().map(|r| r.converged)),
        (5, rep.step5_refined.as_ref().map(|r| r.converged)),
        (
            7,
            rep.twelve
                .as_ref()
                .and_then(|t| t.dynamic.as_ref().map(|r| r.converged)),
        ),
        (
            7,
            rep.twelve
                .as_ref()
                .and_then(|t| t.dynamic_refined.as_ref().map(|r| r.converged)),
        ),
        (
            8,
            rep.twelve
                .as_ref()
                .and_then(|t| t.statics.as_ref().map(|r| r.converged)),
        ),
    ] {
        if conv == Some(false) {
            out.push(format!(
                "warning: step {step} stopped at its evaluation limit before a convergence test \
                 was met{}",
                if step == 5 || step == 8 {
                    " (raise --max-evals)"
                } else {
                    ""
                }
            ));
        }
    }
    let step8 = rep.twelve.as_ref().and_then(|t| t.statics.as_ref());
    for r in [rep.step5.as_ref(), rep.step5_refined.as_ref(), step8]
        .into_iter()
        .flatten()
    {
        if let Some(note) = r.passes_note() {
            let kind = if r.first_pass_discarded_for.is_empty() {
                "note"
            } else {
                "warning"
            };
            out.push(format!(
                "{kind}: {note}; --step5-single-pass turns this off"
            ));
        }
        out.extend(stop_message(r.stop_note(), r.early_stop().is_some()));
    }
    // step 7 judged as step 5 (ftol/xtol with a large relative offset)
    if let Some(t) = &rep.twelve {
        for r in [&t.dynamic, &t.dynamic_refined].into_iter().flatten() {
            out.extend(stop_message(r.stop_note(), r.early_stop().is_some()));
        }
    }
    for o in &rep.oscillations {
        out.push(format!(
            "warning: {}: check the compressor efficiency at low pressure ratios (docs/tuning.md, \
             session 12) and the figures of mvem validate",
            o.describe()
        ));
    }
    for c in &rep.caveats {
        out.push(format!("note: {c}"));
    }
    for f in &rep.failed_sets {
        out.push(format!(
            "warning: the tuned model does not simulate data set {}: {} (tune_report.md)",
            f.set, f.message
        ));
    }
    out
}

/// A search's stop note (`stop_note` of its report) as a message: a stop at the optimum within
/// the noise (measured along the Gauss-Newton step) is a note, one short of it (`short`) a
/// warning.
fn stop_message(note: Option<String>, short: bool) -> Option<String> {
    let kind = if short { "warning" } else { "note" };
    note.map(|n| format!("{kind}: {n}"))
}

/// What a validation run gives: the campaign, the relative errors, the dynamometer and sensor
/// time constants the simulations used, and notes on where they came from.
#[derive(Debug)]
pub struct CampaignValidation {
    /// The campaign as loaded.
    pub campaign: Campaign,
    /// Relative errors, eqs (4), (5).
    pub report: ValidationReport,
    /// The dynamometer time constant tau_Me \[s\] applied to the simulated torque, if any.
    pub tau_me: Option<f64>,
    /// The sensor time constants applied to the simulated outputs.
    pub sensor_lags: SensorLags,
    /// Notes (`note: ...`) and warnings (`warning: ...`), as `mvem validate` prints them.
    pub messages: Vec<String>,
}

/// The roles of a comma-separated list (`static`, `dynamic`, `actuator`, `validation`).
pub fn parse_roles(s: &str) -> Result<Vec<Role>, SettingError> {
    s.split(',')
        .map(|r| match r.trim() {
            "static" => Ok(Role::Static),
            "dynamic" => Ok(Role::Dynamic),
            "actuator" => Ok(Role::Actuator),
            "validation" => Ok(Role::Validation),
            o => Err(SettingError {
                field: "roles",
                detail: format!(": unknown role {o:?} (static, dynamic, actuator, validation)"),
            }),
        })
        .collect()
}

/// The relative errors of `p` on the campaign in `data_dir` (eqs (4), (5)), as `mvem
/// validate` computes them. `cell`: the parameter file's test-cell section, whose tau_Me and
/// sensor time constants apply unless `tau_me` (> 0 s) or `sensor_lags` (`none`, `table6` or
/// `p_im=0.015,...`) are given; `roles`: the data sets' roles to validate (all if `None`).
pub fn validate_campaign(
    data_dir: &Path,
    p: &Params,
    cell: Option<&TestCell>,
    model: ModelOrder,
    tau_me: Option<f64>,
    sensor_lags: Option<&str>,
    roles: Option<&str>,
) -> Result<CampaignValidation, RequestError> {
    if let Some(t) = tau_me {
        if !(t.is_finite() && t > 0.0) {
            return Err(RequestError::Setting(SettingError {
                field: "tau_me",
                detail: format!(" {t}: must be > 0"),
            }));
        }
    }
    let roles = roles
        .map(parse_roles)
        .transpose()
        .map_err(RequestError::Setting)?;
    let mut messages = Vec::new();
    let cell_tau = cell.and_then(|c| c.tau_me);
    if let (None, Some(t)) = (tau_me, cell_tau) {
        messages.push(format!(
            "note: tau_Me = {t} s from the [test_cell] section of the parameter file (override \
             with --tau-me)"
        ));
    }
    let tau_me = tau_me.or(cell_tau);
    let sensor_lags = match sensor_lags {
        Some(v) => SensorLags::parse(v).map_err(|e| {
            RequestError::Setting(SettingError {
                field: "sensor_lags",
                detail: format!(": {e}"),
            })
        })?,
        None => match cell.and_then(TestCell::lags) {
            Some(l) => {
                messages.push(format!(
                    "note: sensor time constants p_im, p_em, W_c, n_t = {:?} s from the \
                     [test_cell] section of the parameter file (override with --sensor-lags)",
                    l.as_array()
                ));
                l
            }
            None => SensorLags::NONE,
        },
    };
    let campaign = load_campaign(data_dir).map_err(RequestError::Data)?;
    messages.extend(
        super::summary::campaign_warnings(
            &campaign,
            &p.input_saturation,
            "the parameters validated",
        )
        .into_iter()
        .map(|w| format!("warning: {w}")),
    );
    // the sets validated: those with one of the roles asked for
    let chosen = |r: &[Role]| {
        roles
            .as_ref()
            .is_none_or(|want| r.iter().any(|x| want.contains(x)))
    };
    let selected = Campaign {
        dynamic: campaign
            .manifest
            .datasets
            .iter()
            .zip(&campaign.dynamic)
            .filter(|(i, _)| chosen(&i.roles))
            .map(|(_, d)| d.clone())
            .collect(),
        ..campaign.clone()
    };
    if let (Some(want), true) = (&roles, selected.dynamic.is_empty()) {
        let sets: Vec<String> = campaign
            .manifest
            .datasets
            .iter()
            .map(|i| format!("{} ({})", i.name, super::summary::roles_text(&i.roles)))
            .collect();
        messages.push(format!(
            "warning: no data set has the role {}: only the stationary points are validated \
             (the campaign's sets: {})",
            super::summary::roles_text(want),
            if sets.is_empty() {
                "none".to_string()
            } else {
                sets.join(", ")
            }
        ));
    }
    // what the model runs clamped: the validation compares a model of other operating points
    for w in [
        super::constants::inputs_outside_saturation(p, &selected),
        super::constants::turbo_speeds_above_limit(p, &selected),
    ]
    .into_iter()
    .flatten()
    {
        messages.push(format!("warning: {w}"));
    }
    let report =
        validate_campaign_with(model, &campaign, p, tau_me, &sensor_lags, roles.as_deref())
            .map_err(RequestError::Validate)?;
    for o in report.oscillation_rows() {
        messages.push(format!("warning: {}; see the report", o.describe()));
    }
    Ok(CampaignValidation {
        campaign,
        report,
        tau_me,
        sensor_lags,
        messages,
    })
}

/// The settings of a virtual test-cell campaign: the options of `mvem lab` by their names (snake
/// case), with its defaults; unknown names are refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LabSettings {
    /// Seed of the noise and of the stationary points' placement.
    pub seed: u64,
    /// `realistic` (0.5 % relative, 1 K), `none`, or `REL,KELVIN`.
    pub noise: String,
    /// Stationary points (at least 13: the ESC points).
    pub n_stationary: usize,
    /// Dynamometer time constant tau_Me \[s\] of the torque measurement (>= 0).
    pub tau_me: f64,
    /// Apply the Table 6 sensor lags to p_im, p_em, W_c, n_t.
    pub sensor_lags: bool,
    /// Only these dynamic sets of Table 1 (`None`: all).
    pub sets: Option<Vec<String>>,
    /// At most this many command steps per set (>= 1).
    pub max_steps: Option<usize>,
    /// Generate the dynamic sets (else stationary points only).
    pub dynamic: bool,
    /// The engine's speed range `LO:HI` \[rpm\].
    pub speeds: String,
    /// Full-load fuel \[mg/cycle/cylinder\].
    pub full_load: f64,
}

impl Default for LabSettings {
    fn default() -> Self {
        Self {
            seed: 1,
            noise: "realistic".into(),
            n_stationary: 82,
            tau_me: 1.0,
            sensor_lags: false,
            sets: None,
            max_steps: None,
            dynamic: true,
            speeds: "900:2100".into(),
            full_load: 220.0,
        }
    }
}

impl LabSettings {
    /// The virtual test cell's options for `model` on the engine `p`, every setting checked (the
    /// first bad one named).
    pub fn lab_options(&self, p: &Params, model: ModelOrder) -> Result<LabOptions, SettingError> {
        let bad = |field: &'static str, detail: String| SettingError { field, detail };
        let noise = match self.noise.as_str() {
            "realistic" => Noise::REALISTIC,
            "none" => Noise::NONE,
            s => {
                let form = || {
                    bad(
                        "noise",
                        format!(" {s:?}: expected realistic, none or REL,KELVIN (e.g. 0.005,1)"),
                    )
                };
                let (a, b) = s.split_once(',').ok_or_else(form)?;
                let rel: f64 = a.trim().parse().map_err(|_| form())?;
                let temp_k: f64 = b.trim().parse().map_err(|_| form())?;
                if !(rel.is_finite()
                    && (0.0..0.5).contains(&rel)
                    && temp_k.is_finite()
                    && temp_k >= 0.0)
                {
                    return Err(bad(
                        "noise",
                        format!(" {s:?}: REL must be in [0, 0.5), KELVIN >= 0"),
                    ));
                }
                Noise { rel, temp_k }
            }
        };
        if self.n_stationary < 13 {
            return Err(bad(
                "n_stationary",
                format!(" {}: at least 13 (the ESC points)", self.n_stationary),
            ));
        }
        if !(self.tau_me.is_finite() && self.tau_me >= 0.0) {
            return Err(bad("tau_me", format!(" {}: must be >= 0", self.tau_me)));
        }
        if let Some(v) = &self.sets {
            if let Some(n) = v
                .iter()
                .find(|n| !TABLE1.iter().any(|r| r.name == n.as_str()))
            {
                return Err(bad(
                    "sets",
                    format!(": unknown data set {n:?} (Table 1: A-I, Q-V)"),
                ));
            }
        }
        if self.max_steps == Some(0) {
            return Err(bad("max_steps", " 0: at least 1".into()));
        }
        let form = || {
            bad(
                "speeds",
                format!(" {:?}: expected LO:HI in r/min", self.speeds),
            )
        };
        let (lo, hi) = self.speeds.split_once(':').ok_or_else(form)?;
        let envelope = Envelope {
            n_lo_rpm: lo.trim().parse().map_err(|_| form())?,
            n_hi_rpm: hi.trim().parse().map_err(|_| form())?,
            full_load_mg: self.full_load,
        };
        envelope.validate(&p.input_saturation).map_err(|e| {
            bad(
                "speeds",
                format!(" {:?} with full_load {}: {e}", self.speeds, self.full_load),
            )
        })?;
        Ok(LabOptions {
            envelope,
            seed: self.seed,
            noise,
            n_stationary: self.n_stationary,
            dynamic: self.dynamic,
            sets: self.sets.clone(),
            max_steps: self.max_steps,
            tau_me_s: self.tau_me,
            sensor_lags: self.sensor_lags,
            model,
            ..LabOptions::default()
        })
    }
}

/// A virtual campaign of the engine `p` (the `model`-state model) with `settings`, written to
/// `out_dir` as `mvem lab` writes it (manifest, stationary and dynamic CSVs, the true
/// parameters), everything generated before the first file is written. Returns the campaign.
pub fn write_lab_campaign(
    out_dir: &Path,
    p: &Params,
    model: ModelOrder,
    settings: &LabSettings,
) -> Result<Campaign, RequestError> {
    let opts = settings
        .lab_options(p, model)
        .map_err(RequestError::Setting)?;
    if out_dir.exists() && !out_dir.is_dir() {
        return Err(RequestError::Setting(SettingError {
            field: "out",
            detail: format!(" {}: exists and is not a directory", out_dir.display()),
        }));
    }
    let c = campaign(p, &opts)
        .map_err(|e| RequestError::Failed(format!("virtual test cell: {e}")))?
        .0;
    save_campaign(out_dir, &c).map_err(RequestError::Data)?;
    crate::io::params::save_params(p, &out_dir.join("true_params.toml"))
        .map_err(|e| RequestError::Failed(format!("writing the true parameters: {e}")))?;
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_default_to_the_command_lines_defaults_and_refuse_unknown_names() {
        let s: TuneSettings = serde_json::from_str("{}").unwrap();
        assert_eq!(s, TuneSettings::default());
        let opts = s.pipeline_options(ModelOrder::Eight, None).unwrap();
        let want = PipelineOptions {
            sensor_lags: SensorLagMode::Fit,
            ..PipelineOptions::default()
        };
        assert_eq!(opts.steps, want.steps);
        assert_eq!(opts.step5.beta, 1.0);
        assert_eq!(opts.step3.window.seconds, f64::INFINITY);
        let e = serde_json::from_str::<TuneSettings>(r#"{"betta": 2}"#).unwrap_err();
        assert!(e.to_string().contains("unknown field `betta`"), "{e}");
        let e = serde_json::from_str::<TuneSettings>(r#"{"cost": "both"}"#).unwrap_err();
        assert!(e.to_string().contains("`full`, `dynamic`, `static`"), "{e}");
        let s: TuneSettings = serde_json::from_str(
            r#"{"steps": "1,2", "cost": "dynamic", "init": "naive", "fixed_jacobian": "sigma-points",
                "step_levels": "means", "step3_window": 2.5, "sensor_lags": "none"}"#,
        )
        .unwrap();
        let o = s.pipeline_options(ModelOrder::Twelve, None).unwrap();
        assert_eq!(o.steps, [true, true, false, false, false]);
        assert!(o.step5.dynamic_row && !o.step5.static_row);
        assert_eq!(o.init, Init::Naive);
        assert_eq!(o.fixed_jacobian, FixedJacobian::SigmaPoints);
        assert_eq!(o.step3.window.seconds, 2.5);
        assert_eq!(o.sensor_lags, SensorLagMode::Known(SensorLags::NONE));
    }

    #[test]
    fn roles_parse_and_an_unknown_one_is_named() {
        assert_eq!(
            parse_roles("static, validation").unwrap(),
            vec![Role::Static, Role::Validation]
        );
        assert_eq!(
            parse_roles("actuator,x").unwrap_err().to_string(),
            "roles: unknown role \"x\" (static, dynamic, actuator, validation)"
        );
    }

    #[test]
    fn bad_settings_are_named() {
        let bad = |s: TuneSettings, model: ModelOrder| {
            s.pipeline_options(model, None).unwrap_err().to_string()
        };
        let d = TuneSettings::default;
        assert_eq!(
            bad(TuneSettings { beta: 0.0, ..d() }, ModelOrder::Eight),
            "beta 0: must be > 0"
        );
        assert!(bad(d(), ModelOrder::Ten).starts_with("model 10: "));
        assert!(bad(
            TuneSettings {
                steps: "7".into(),
                ..d()
            },
            ModelOrder::Eight
        )
        .starts_with("steps: "));
        assert_eq!(
            bad(
                TuneSettings {
                    rel_offset: f64::NAN,
                    ..d()
                },
                ModelOrder::Eight
            ),
            "rel_offset NaN: must be >= 0"
        );
        assert!(bad(
            TuneSettings {
                step3_window: Some(0.0),
                ..d()
            },
            ModelOrder::Eight
        )
        .starts_with("step3_window 0: must be > 0"));
        assert!(bad(
            TuneSettings {
                step3_tail_weight: 1.5,
                ..d()
            },
            ModelOrder::Eight
        )
        .starts_with("step3_tail_weight 1.5: must lie in (0, 1]"));
        assert!(bad(
            TuneSettings {
                sensor_lags: Some("1,2".into()),
                ..d()
            },
            ModelOrder::Eight
        )
        .starts_with("sensor_lags: "));
    }
}
