//! `mvem tune`: the paper's five-step parameter estimation (sections 2.3, 8.1) on a campaign.

use crate::common;
use anyhow::Result;
use mvem::io::test_cell::TestCell;
use mvem::params::Params;
use mvem::tuning::complete::StepLevels;
use mvem::tuning::constants::{AmbientSource, InputRangeSource};
use mvem::tuning::pipeline::{Init, TuneReport};
use mvem::tuning::request::{self, CostRows, RequestError, SettingError, TuneSettings};
use mvem::tuning::sensors::SensorLags;
use mvem::tuning::uncertainty::FixedJacobian;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Arguments of `mvem tune`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Examples:
  mvem lab --out campaign && mvem tune --data campaign --out tuned.toml --report tune-report
  mvem tune --data campaign --out steps14.toml --steps 1-4
  mvem tune --data campaign --params steps14.toml --steps 5 --init naive --cost dynamic --out a.toml
  mvem lab --out c12 --model 12 && mvem tune --data c12 --model 12 --out tuned12.toml

Steps: 1 static submodels (stationary data), 2 actuators (set J), 3 V_im, V_em, J_t (sets with
role dynamic, VGT/EGR), 4 tau_Me (fuel set with role dynamic), 5 static parameters by cost (77)
(sets with role static + stationary points). Parameters of steps not run come from --params
(default: the published set, which also supplies the constants that are never tuned:
displacement, cylinders, compression ratio, heating value, wheel radii, maximum EGR and VGT
areas, gas properties; for another engine give its own). Steps 1-4 start from generic
values, never from --params; step 5 (--init step1) starts from step 1's static parameters,
or from those of --params when step 1 is not run (--init naive: eq. (78)). The ambient p_amb, T_amb and T_im are the means of the stationary points where
they contradict --params (--ambient auto|data|params). The model's input ranges
([input_saturation], default the authors' 500-2000 rpm and 1-250 mg) are widened to contain
the campaign's speeds and largest fuel, and the turbo-speed limit of the omega_t integrator
([integrator_limits] n_t, default 200000 rpm) to 1.1 times the highest measured turbo speed
where the campaign exceeds it (--input-ranges campaign|params). Constants that the campaign contradicts (the volumetric
efficiency the measured flows imply, the indicated efficiency step 1 fits to the torque, or a
virtual campaign's true_params.toml) are reported as caveats. The tuned dynamometer time constant tau_Me is not a
model parameter: it is written to the [test_cell] section of the output file, which `mvem
validate` reads (--tau-me overrides). DIR/tune_report.json \"parameters\": per parameter file
path the value, standard error, identifiability and correlations (docs/tuning.md); the paths
are the parameter registry's names, elements counted from 1 as in `mvem params check`, the
FMU and Python's params= (\"cylinder.c_vol[1]\" is c_vol1, the first number of c_vol in the
[cylinder] section; \"compressor.q_c[1][2]\" is a3). \"combinations\": what the
campaign determines where single parameters are flagged (eta_tm at the measured blade speed
ratio, eta_c at a measured compressor operating point). \"caveats\": what the standard
errors do not cover (V_im, V_em, J_t fitted on static maps that are flagged not identifiable
inherit their error as a bias; docs/tuning.md, session 21; constants the campaign contradicts,
session 23). \"ambient\": the means used. A step 5 stopped away from its optimum
by more than the noise is reported with a warning (relative offset R: up to R sqrt(p) standard
errors from the least-squares optimum), and its parameters and those of steps 3-4 repeated on
its static maps with \"converged\": false, not identifiable (session 38), unless the cost
measured along the Gauss-Newton step at 1, 0.1, 0.01, 0.001 of it falls by less than one
residual variance (\"gauss_newton_decrease\"): then it stopped at its optimum within the
noise (session 39).
--model 12: after steps 1-5 (8-state model) the three steps of section 9.2.1: 6 k_ic by linear
least squares of the stationary p_c - p_im (eq. (86)), 7 V_ic, V_im, V_em, J_t on the 12-state
model (with step 3), 8 the static parameters and k_ic by (77) with z_8 = W_ic, beta = 2.58
(with step 5; --beta applies to step 5 only). The output file then carries the tuned
[intercooler] group. Validate with `mvem validate --model 12`.
Nothing is written if a step fails (exit code 1, naming the step).")]
pub struct Args {
    /// Campaign directory (manifest.toml; see docs/tuning-data.md).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Output parameter file (TOML; JSON if it ends in .json).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Report directory: tune_report.json, tune_report.md (created).
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Steps to run, e.g. 1-5, 1-4, 3,4 or 5.
    #[arg(long, default_value = "1-5", value_name = "LIST")]
    pub steps: String,
    /// The engine's constants (displacement, cylinders, compression ratio, heating value,
    /// wheel radii, maximum EGR and VGT areas, gas properties: nothing estimates them) and the
    /// parameters of the steps not run [default: the published set, whose constants are
    /// right only for the published engine].
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Where p_amb, T_amb and T_im (and T_w where the parameter set ties it to T_amb) come
    /// from: the means of the campaign's stationary points (as the published values are the
    /// means of the authors' 82 points), by default (`auto`) each where it differs from the
    /// --params value by more than 3 standard errors of the mean (the campaign was measured
    /// under other conditions); `data`: the means always; `params`: the --params values.
    #[arg(long, value_enum, default_value = "auto")]
    pub ambient: AmbientArg,
    /// The model's input ranges ([input_saturation]: the speed and fuel ranges it clamps n_e
    /// and u_delta into, by default the authors' engine's 500-2000 rpm and 1-250 mg):
    /// `campaign` widens --params' ranges to contain the campaign's engine speeds and largest
    /// fuel (said on stderr, written to --out), and the turbo-speed limit [integrator_limits]
    /// n_t to 1.1 times the highest measured turbo speed where the campaign exceeds it;
    /// `params` keeps them (points outside run clamped, a caveat says so).
    #[arg(long, value_enum, default_value = "campaign")]
    pub input_ranges: InputRangesArg,
    /// Start of step 5: the step-1 values (those of --params when step 1 is not run) or eq.
    /// (78) from the bounds.
    #[arg(long, value_enum, default_value = "step1")]
    pub init: InitArg,
    /// Rows of cost (77): both, only the complete model (dynamic), only the submodels (static).
    #[arg(long, value_enum, default_value = "full")]
    pub cost: CostArg,
    /// beta of eq. (77).
    #[arg(long, default_value_t = 1.0)]
    pub beta: f64,
    /// After step 5, repeat steps 3 and 4 with the final static parameters (not in the paper;
    /// V_im, V_em, J_t then carry no step-1 static errors); with --model 12 also step 7 after
    /// step 8. `--refine-dynamics false`: the paper's order only.
    #[arg(long = "refine-dynamics", default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub refine_dynamics: bool,
    /// With --refine-dynamics: a second round of steps 5 and 3, and the standard errors of
    /// the static parameters and V_im, V_em, J_t from their joint covariance at that fixed
    /// point of the alternation (about +50 % time on `mvem lab` seed 1; default `false`: one
    /// round, the steps' covariances chained, docs/tuning.md).
    #[arg(long = "joint-uncertainty", default_value_t = false, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub joint_uncertainty: bool,
    /// How the Jacobian of steps 3-5's residuals with respect to the parameters each holds
    /// fixed is computed, for the standard errors those parameters add: forward differences
    /// (the default), or central differences along the principal axes of their covariance,
    /// one standard deviation each way (`sigma-points`: far above the simulations' noise, so
    /// these standard errors do not move with the integrator's rounding; more simulations;
    /// docs/tuning.md, session 22).
    #[arg(long = "fixed-jacobian", value_enum, default_value_t = FixedJacobianArg::Forward)]
    pub fixed_jacobian: FixedJacobianArg,
    /// Limit on evaluations of cost (77) in step 5 (finite differences included).
    #[arg(long = "max-evals", default_value_t = 3600, value_name = "N")]
    pub max_evals: usize,
    /// Step 5: most consecutive Broyden (secant) updates of the finite-difference Jacobian of
    /// (77) before it is recomputed (0: recomputed after every accepted step, 35 evaluations).
    #[arg(long = "broyden", default_value_t = 0, value_name = "K")]
    pub broyden: usize,
    /// Step 5: stop when the Bates-Watts relative offset of cost (77) falls below this
    /// (every parameter then within about `TOL sqrt(35)` standard errors of the linearized
    /// optimum; 0: off, docs/tuning.md).
    #[arg(long = "rel-offset", default_value_t = mvem::tuning::complete::STEP5_REL_OFFSET_TOL, value_name = "TOL")]
    pub rel_offset: f64,
    /// Step 5: most restarts (a new central-difference Jacobian and trust region) when ftol/xtol stopped the
    /// search with the relative offset above `--rel-offset` and 1, i.e. far from its optimum; kept
    /// only when they lower the cost (can cost many evaluations; docs/tuning.md, session 14;
    /// 0: none).
    #[arg(long = "restarts", default_value_t = mvem::tuning::complete::STEP5_RESTARTS, value_name = "N")]
    pub restarts: usize,
    /// Step 5 in one pass even when the model at its start oscillates on some data sets where
    /// the engine does not (by default a first pass leaves those sets out, then a second pass
    /// runs on all sets from its result; docs/tuning.md, sessions 12-13).
    #[arg(long = "step5-single-pass")]
    pub step5_single_pass: bool,
    /// Evaluation limit of the first pass of a two-pass step 5.
    #[arg(
        long = "step5-first-pass-max",
        default_value_t = 3600,
        value_name = "N"
    )]
    pub step5_first_pass_max: usize,
    /// Fit the compressor flow map (step 1, and step 5's W_c submodel row) also to the settled
    /// ends of the static-tuning sets' command steps (`false`: the stationary points only, as
    /// the paper's steps 1 and 5; not used for `--model 12`; docs/tuning.md, session 15).
    #[arg(long = "settled-flow-points", default_value_t = true, action = clap::ArgAction::Set, value_name = "BOOL")]
    pub settled_flow_points: bool,
    /// Step 3: length [s] of the fully weighted part of each step response; later samples
    /// weigh `--step3-tail-weight` (not in the paper; default `inf`: eq. (75), every sample
    /// alike; 0.5 s halves the spread of V_em but can change step 5's path, docs/tuning.md).
    #[arg(long = "step3-window", default_value_t = f64::INFINITY, value_name = "SECONDS")]
    pub step3_window: f64,
    /// Step 3: weight of the samples after `--step3-window` (0-1).
    #[arg(long = "step3-tail-weight", default_value_t = mvem::tuning::complete::ResponseWindow::VOLUMES.tail_weight, value_name = "W")]
    pub step3_tail_weight: f64,
    /// Steps 3, 4 (and 7): how the simulated step responses share the measured initial and
    /// final levels of eq. (75): `least-squares` fits the offset and gain of each step over its
    /// whole response, `means` maps them onto the mean 0.2 s before the step and over its last
    /// 20 % (sessions 1-15; noisier, biases the volumes, docs/tuning.md session 16).
    #[arg(long = "step-levels", value_enum, default_value = "least-squares")]
    pub step_levels: LevelsArg,
    /// Sensor time constants of p_im, p_em, W_c, n_t (test-cell quantities, written to the
    /// [test_cell] section of --out): `fit` estimates them in step 3 with V_im, V_em, J_t
    /// (the default when step 3 runs), `none` (the paper, appendix 2), `table6` (the maxima of
    /// the paper's Table 6), or known values `p_im=0.015,p_em=0.02,W_c=0.02,n_t=0.006` [s].
    /// Default without step 3: those of --params' [test_cell] section, else none.
    #[arg(long = "sensor-lags", value_name = "fit|none|table6|LIST")]
    pub sensor_lags: Option<String>,
    /// Model to tune: 8 (steps 1-5) or 12 (then the steps of section 9.2.1).
    #[arg(long, value_enum, default_value = "8")]
    pub model: common::ModelArg,
}

/// `--init`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InitArg {
    /// The step-1 values.
    Step1,
    /// Eq. (78).
    Naive,
}

/// `--step-levels`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LevelsArg {
    /// Offset and gain of each step response by least squares over the whole step.
    LeastSquares,
    /// Means before the step and over its last 20 %.
    Means,
}

/// `--ambient`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum AmbientArg {
    /// The means where the campaign contradicts --params.
    Auto,
    /// The means of the stationary points.
    Data,
    /// The values of --params (default: the published set).
    Params,
}

/// `--input-ranges`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InputRangesArg {
    /// --params' ranges widened to contain the campaign.
    Campaign,
    /// --params' ranges as they are.
    Params,
}

/// `--fixed-jacobian`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FixedJacobianArg {
    /// Forward differences at 1e-4 relative.
    Forward,
    /// Central differences along the principal axes of the fixed parameters' covariance.
    SigmaPoints,
}

/// `--cost`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CostArg {
    /// Both rows of eq. (77).
    Full,
    /// Only the first row (complete model).
    Dynamic,
    /// Only the second row (submodels).
    Static,
}

/// Run `mvem tune`.
/// The command line's options as the core's settings (the same names, snake case).
fn settings(a: &Args) -> TuneSettings {
    TuneSettings {
        steps: a.steps.clone(),
        ambient: match a.ambient {
            AmbientArg::Auto => AmbientSource::Auto,
            AmbientArg::Data => AmbientSource::Data,
            AmbientArg::Params => AmbientSource::Params,
        },
        input_ranges: match a.input_ranges {
            InputRangesArg::Campaign => InputRangeSource::Campaign,
            InputRangesArg::Params => InputRangeSource::Params,
        },
        init: match a.init {
            InitArg::Step1 => Init::Step1,
            InitArg::Naive => Init::Naive,
        },
        cost: match a.cost {
            CostArg::Full => CostRows::Full,
            CostArg::Dynamic => CostRows::Dynamic,
            CostArg::Static => CostRows::Static,
        },
        beta: a.beta,
        refine_dynamics: a.refine_dynamics,
        joint_uncertainty: a.joint_uncertainty,
        fixed_jacobian: match a.fixed_jacobian {
            FixedJacobianArg::Forward => FixedJacobian::Forward,
            FixedJacobianArg::SigmaPoints => FixedJacobian::SigmaPoints,
        },
        max_evals: a.max_evals,
        broyden: a.broyden,
        rel_offset: a.rel_offset,
        restarts: a.restarts,
        step5_single_pass: a.step5_single_pass,
        step5_first_pass_max: a.step5_first_pass_max,
        settled_flow_points: a.settled_flow_points,
        step3_window: Some(a.step3_window),
        step3_tail_weight: a.step3_tail_weight,
        step_levels: match a.step_levels {
            LevelsArg::LeastSquares => StepLevels::LeastSquares,
            LevelsArg::Means => StepLevels::Means,
        },
        sensor_lags: a.sensor_lags.clone(),
    }
}

pub fn run(a: &Args) -> Result<()> {
    let settings = settings(a);
    // the settings first: a bad one is refused before any file is read
    let setting_error =
        |e: SettingError| common::usage(format!("--{}{}", e.field.replace('_', "-"), e.detail));
    settings
        .pipeline_options(a.model.order(), None)
        .map_err(setting_error)?;
    common::check_output_path(&a.out, "--out")?;
    if let Some(r) = &a.report {
        if r.exists() && !r.is_dir() {
            return Err(common::usage(format!(
                "--report {}: exists and is not a directory",
                r.display()
            )));
        }
    }
    let base = match &a.params {
        None => Params::published(),
        Some(p) => mvem::io::params::load_params(p)
            .map_err(|e| common::usage(format!("--params {}: {e}", p.display())))?,
    };
    let base_cell = match &a.params {
        None => None,
        Some(p) => mvem::io::test_cell::load_test_cell(p)
            .map_err(|e| common::usage(format!("--params {}: {e}", p.display())))?,
    };
    let run = common::with_spinner("tuning", || {
        request::tune_campaign(
            &a.data,
            &base,
            base_cell.as_ref(),
            a.params.is_some(),
            a.model.order(),
            &settings,
        )
    })
    .map_err(|e| match e {
        RequestError::Setting(e) => setting_error(e),
        RequestError::Data(e) => common::usage(e.to_string()),
        other => anyhow::Error::from(other),
    })?;
    for m in &run.messages {
        eprintln!("{m}");
    }
    let (rep, c, truth) = (&run.report, &run.campaign, run.truth.as_ref());
    let cell_truth = TestCell {
        tau_me: c.manifest.true_tau_me_s,
        ..TestCell::default()
    };
    let cell_truth = match c.manifest.true_sensor_lags_s {
        Some(l) => cell_truth.with_lags(SensorLags::from_array(l)),
        None => cell_truth,
    };
    let md = markdown(rep, truth, &cell_truth);
    // render everything, then write
    let json = serde_json::to_string_pretty(rep)?;
    let cell = &run.test_cell;
    mvem::io::test_cell::save_params_with_test_cell(&run.params, cell, &a.out)?;
    if let Some(dir) = &a.report {
        std::fs::create_dir_all(dir)
            .map_err(|e| common::usage(format!("--report {}: {e}", dir.display())))?;
        mvem::io::output::write_atomic(&dir.join("tune_report.json"), json.as_bytes())?;
        mvem::io::output::write_atomic(&dir.join("tune_report.md"), md.as_bytes())?;
    }
    print!("{md}");
    eprintln!(
        "wrote {}{}; total {}",
        a.out.display(),
        a.report
            .as_ref()
            .map(|d| format!(
                " and {}",
                Path::new(d).join("tune_report.{json,md}").display()
            ))
            .unwrap_or_default(),
        common::fmt_duration(rep.total_seconds)
    );
    if let Some(t) = cell.tau_me {
        eprintln!(
            "tau_Me = {t:.4} s written to the [test_cell] section of {}; validate with: mvem \
             validate --data {} --params {}",
            a.out.display(),
            a.data.display(),
            a.out.display()
        );
    }
    Ok(())
}

fn pct(x: f64) -> String {
    format!("{:.2}", 100.0 * x)
}

/// The report as Markdown: per step the submodel/output errors (mean and max absolute relative
/// error, per cent), timings, and (virtual campaigns) each tuned parameter against the truth.
pub fn markdown(rep: &TuneReport, truth: Option<&Params>, cell_truth: &TestCell) -> String {
    let mut s = String::from("# Tuning report\n\n");
    let _ = writeln!(
        s,
        "Wall time per step [s]: {}; total {:.1} s\n",
        rep.seconds
            .iter()
            .enumerate()
            .map(|(i, t)| format!("{}: {t:.1}", i + 1))
            .collect::<Vec<_>>()
            .join(", "),
        rep.total_seconds
    );
    if let Some(amb) = &rep.ambient {
        let d = amb.describe();
        let _ = writeln!(s, "{}{}.\n", d[..1].to_uppercase(), &d[1..]);
    }
    if let Some(w) = &rep.input_saturation {
        let _ = writeln!(s, "**Note:** {}.\n", w.describe());
    }
    if let Some(w) = &rep.integrator_limits {
        let _ = writeln!(s, "**Note:** {}.\n", w.describe());
    }
    if !rep.failed_sets.is_empty() {
        let _ = writeln!(
            s,
            "**Warning: the tuned model does not simulate every data set.** A failed simulation \
             enters cost (77) as a constant, so the search cannot see it; the parameters are not \
             usable on these inputs (`mvem validate` reports the same failures).\n\n| data set | \
             failure |\n|---|---|"
        );
        for f in &rep.failed_sets {
            let msg = f.message.replace('|', "\\|").replace('\n', " ");
            let _ = writeln!(s, "| {} | {msg} |", f.set);
        }
        s.push('\n');
    }
    if !rep.oscillations.is_empty() {
        let _ = writeln!(
            s,
            "**Warning: the tuned model oscillates where the engine does not.** In the second \
             half of constant-command intervals (at least 4 s) the simulated output below moves \
             by more than 2 % and twice the measured one, turning back and forth (a limit cycle; \
             `mvem validate` shows the figures). The parameters cannot be trusted there; see \
             docs/tuning.md, session 12.\n\n{}",
            mvem::tuning::validate::oscillation_table(&rep.oscillations)
        );
    }
    let table = |s: &mut String, title: &str, rows: &[mvem::tuning::steps::FitReport]| {
        let _ = writeln!(s, "## {title}\n\n| submodel / output | mean abs. rel. error (%) | max abs. rel. error (%) | n |\n|---|---|---|---|");
        for f in rows {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} |",
                f.submodel,
                pct(f.mean_abs_rel_err),
                pct(f.max_abs_rel_err),
                f.n_points
            );
        }
        s.push('\n');
    };
    if let Some(r) = &rep.step1 {
        table(
            &mut s,
            "Step 1: static submodels (stationary data, eq. (4))",
            &r.fits,
        );
        if rep.step1_settled_flow_points > 0 {
            let _ = writeln!(
                s,
                "W_c (here and in step 5's submodel row): the stationary points and {} settled \
                 ends of the static-tuning sets' command steps (`--settled-flow-points`; \
                 docs/tuning.md, session 15).\n",
                rep.step1_settled_flow_points
            );
        }
    }
    if let Some(r) = &rep.step2 {
        table(&mut s, "Step 2: actuators (set J)", r);
    }
    if let Some(r) = &rep.step3 {
        let _ = writeln!(
            s,
            "Step 3: {} evaluations, converged {}; step levels: {}",
            r.n_eval,
            r.converged,
            match rep.step_levels {
                Some(mvem::tuning::complete::StepLevels::Means) => {
                    "means before the step and over its last 20 % (`--step-levels means`)"
                }
                _ => "offset and gain of each step fitted by least squares",
            }
        );
        if let Some(l) = rep.sensor_lags {
            let fitted = r.params.iter().any(|(n, _)| SensorLags::index(n).is_some());
            let [a, b, c, d] = l.as_array().map(|t| t * 1e3);
            let _ = writeln!(
                s,
                "Sensor time constants ({}; `--sensor-lags`, written to [test_cell]): p_im \
                 {a:.1} ms, p_em {b:.1} ms, W_c {c:.1} ms, n_t {d:.1} ms\n",
                if fitted { "fitted in step 3" } else { "given" }
            );
        }
        table(
            &mut s,
            "Step 3: V_im, V_em, J_t (eq. (5) on the dynamic sets)",
            &r.errors,
        );
    }
    if let Some(r) = &rep.step4 {
        table(
            &mut s,
            "Step 4: tau_Me (eq. (5), M_dynamo on the fuel set)",
            &r.errors,
        );
    }
    if let Some(r) = &rep.step5 {
        let _ = writeln!(
            s,
            "Step 5: cost (77) {:.4e} -> {:.4e}, {} evaluations ({} iterations, {} finite-difference Jacobians), converged {} (stopped by: {}, relative offset {:.2e}, restarts {}), one evaluation {:.3} s; at bounds: {}\n",
            r.cost_start,
            r.cost_end,
            r.n_eval,
            r.n_iter,
            r.n_jacobians,
            r.converged,
            r.stopped_by,
            r.rel_offset,
            r.restarts,
            r.eval_seconds,
            if r.at_bounds.is_empty() { "none".to_string() } else { r.at_bounds.join(", ") }
        );
        search_notes(&mut s, r);
        table(&mut s, "Step 5: submodels (eq. (4))", &r.submodels);
        table(
            &mut s,
            "Step 5: complete model on the static-tuning sets (eq. (5))",
            &r.dynamic,
        );
    }
    if let Some(r) = &rep.step5_refined {
        let _ = writeln!(
            s,
            "Step 5 repeated on the repeated step 3's V_im, V_em, J_t: cost (77) {:.4e} -> {:.4e}, {} evaluations ({} iterations), converged {} (stopped by: {}, relative offset {:.2e})\n",
            r.cost_start, r.cost_end, r.n_eval, r.n_iter, r.converged, r.stopped_by, r.rel_offset
        );
    }
    if let Some(r) = &rep.step3_refined {
        table(&mut s, "Step 3 repeated after step 5", &r.errors);
    }
    if let Some(t) = &rep.twelve {
        let _ = writeln!(
            s,
            "12-state model (section 9.2.1): {:.1} s; step 6 k_ic = {:.6e}\n",
            t.seconds, t.k_ic.params[0].1
        );
        table(
            &mut s,
            "Step 6: k_ic (linear least squares of p_c - p_im, eq. (86))",
            std::slice::from_ref(&t.k_ic),
        );
        let _ = writeln!(s, "| parameter | value |\n|---|---|");
        for (n, v) in &t.k_ic.params {
            let _ = writeln!(s, "| {n} | {v:.6e} |");
        }
        s.push('\n');
        if let Some(r) = &t.dynamic {
            let _ = writeln!(
                s,
                "Step 7: cost {:.4e} -> {:.4e}, {} evaluations, converged {} (stopped by: {}, \
                 relative offset {:.2e})\n",
                r.cost_start, r.cost, r.n_eval, r.converged, r.stopped_by, r.rel_offset
            );
            if let Some(note) = r.stop_note() {
                let _ = writeln!(s, "**Note:** {note}.\n");
            }
            let rel: Vec<String> = r
                .rel_std_err
                .iter()
                .map(|(n, e)| format!("{n} {}", pct(*e)))
                .collect();
            let _ = writeln!(
                s,
                "Step 7: relative standard errors (%) of the search's linearization \
                 (residuals taken as independent): {}; the parameter table has those of the \
                 covariance with the residuals' autocorrelation (docs/tuning.md, session 42)\n",
                rel.join(", ")
            );
            table(
                &mut s,
                "Step 7: V_ic, V_im, V_em, J_t (12-state model, eq. (5) on the dynamic sets)",
                &r.errors,
            );
        }
        if let Some(r) = &t.statics {
            let _ = writeln!(
                s,
                "Step 8: cost (77) with k_ic, z_8 = W_ic, beta = 2.58: {:.4e} -> {:.4e}, {} evaluations, converged {} (stopped by: {}, relative offset {:.2e})\n",
                r.cost_start, r.cost_end, r.n_eval, r.converged, r.stopped_by, r.rel_offset
            );
            search_notes(&mut s, r);
            table(&mut s, "Step 8: submodels (eq. (4))", &r.submodels);
            table(
                &mut s,
                "Step 8: 12-state model on the static-tuning sets (eq. (5))",
                &r.dynamic,
            );
        }
        if let Some(r) = &t.dynamic_refined {
            let _ = writeln!(
                s,
                "Step 7 repeated after step 8: cost {:.4e} -> {:.4e}, {} evaluations, converged \
                 {} (stopped by: {})\n",
                r.cost_start, r.cost, r.n_eval, r.converged, r.stopped_by
            );
            table(&mut s, "Step 7 repeated after step 8", &r.errors);
        }
    }
    parameter_table(&mut s, rep, truth, cell_truth);
    s
}

/// The notes of a search of cost (77), step 5 or step 8 (the same machinery, the pipeline's
/// `run_static_step`): its two passes, the sets left out of its standard errors, how it stopped,
/// and what its standard errors do not cover.
fn search_notes(s: &mut String, r: &mvem::tuning::complete::Step5Report) {
    if let Some(note) = r.passes_note() {
        let _ = writeln!(
            s,
            "**Note:** {note}; `--step5-single-pass` turns this off, \
             `--step5-first-pass-max` limits the first pass.\n"
        );
    }
    if !r.linearized_without.is_empty() {
        let _ = writeln!(
            s,
            "**Standard errors without set(s) {}:** the tuned model oscillates there where \
             the engine does not, so their rows of the Jacobian (noise of a limit cycle's \
             phase) were left out of the covariance; the estimate itself used every set.\n",
            r.linearized_without.join(", ")
        );
    }
    if let Some(note) = r.stop_note() {
        let _ = writeln!(s, "**Note:** {note}.\n");
    }
    if let Some(note) = &r.uncertainty_note {
        let _ = writeln!(s, "**Note:** {note}.\n");
    }
}

/// The uncertainty table: per tuned parameter (file path) value, standard error, whether it is
/// identifiable and why, and (virtual campaigns) the truth and the deviation in standard errors.
fn parameter_table(
    s: &mut String,
    rep: &TuneReport,
    truth: Option<&Params>,
    cell_truth: &TestCell,
) {
    if rep.parameters.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "## Parameters\n\nStandard errors: Gauss-Newton covariance at the optimum of the step \
         that tuned the parameter (residual variance, AR(1) correction); identifiable: rel. std. \
         error <= 25 % and no correlation > 0.99, from a search that reached its optimum (not \
         converged: step 5, 7 or 8 stopped short of it, or steps 3-4 or 7 ran on the maps of a \
         step 5 or 8 that did; docs/tuning.md). Elements are counted from 1, \
         as the parameter registry, the FMU and Python's params= name them (cylinder.c_vol[1] \
         is c_vol1).\n\n| parameter | step | value | \
         std. error | rel. std. error (%) | identifiable | true | deviation (%) | deviation / \
         std. error | why / correlated with |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for (path, e) in &rep.parameters {
        let t = if let Some(name) = path.strip_prefix("test_cell.") {
            cell_truth.get(name)
        } else {
            truth.and_then(|q| q.get(path))
        };
        let (tt, dev, z) = match t {
            Some(t) => (
                format!("{t:.6e}"),
                if t != 0.0 {
                    pct((e.value - t) / t)
                } else {
                    format!("abs {:.2e}", e.value - t)
                },
                format!("{:.2}", (e.value - t) / e.std_error),
            ),
            None => ("-".into(), "-".into(), "-".into()),
        };
        let rel = e.std_error / e.value.abs();
        let corr = e
            .correlated_with
            .iter()
            .take(3)
            .map(|(n, c)| format!("{n} ({c:.3})"))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            s,
            "| {path} | {} | {:.6e} | {:.3e} | {} | {} | {tt} | {dev} | {z} | {}{}{} |",
            e.step,
            e.value,
            e.std_error,
            if rel.is_finite() {
                pct(rel)
            } else {
                "inf".into()
            },
            match (e.identifiable, e.converged) {
                (true, _) => "yes",
                (false, true) => "**no**",
                (false, false) => "**no** (not converged)",
            },
            e.reason,
            if corr.is_empty() { "" } else { "; " },
            corr
        );
    }
    s.push('\n');
    for c in &rep.caveats {
        let _ = writeln!(s, "**Caveat:** {c}.\n");
    }
    if !rep.combinations.is_empty() {
        let _ = writeln!(
            s,
            "Determined as a whole (parameters above not identifiable one by one):\n\n| \
             combination | value | std. error | what |\n|---|---|---|---|"
        );
        for c in &rep.combinations {
            let _ = writeln!(
                s,
                "| {} | {:.6e} | {:.3e} | {} |",
                c.name, c.value, c.std_error, c.description
            );
        }
        s.push('\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mvem::tuning::pipeline::SetFailure;

    #[test]
    fn the_report_names_the_sets_the_tuned_model_cannot_simulate() {
        let rep = TuneReport {
            failed_sets: vec![SetFailure {
                set: "A".into(),
                message: "step size too small at t = 12.5 s | p_im = 1e5".into(),
            }],
            ..TuneReport::default()
        };
        let md = markdown(&rep, None, &TestCell::default());
        assert!(
            md.contains("**Warning: the tuned model does not simulate every data set.**"),
            "{md}"
        );
        // one row, the table's column separator escaped in the message
        assert!(
            md.contains("| A | step size too small at t = 12.5 s \\| p_im = 1e5 |"),
            "{md}"
        );
        // and nothing of it when every set runs
        assert!(
            !markdown(&TuneReport::default(), None, &TestCell::default())
                .contains("does not simulate")
        );
    }
}
