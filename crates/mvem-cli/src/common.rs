//! Shared argument groups (model, solver), built-in scenarios, error classes and small helpers
//! of the subcommands.

use anyhow::{Context, Result};
use clap::ValueEnum;
use mvem::analysis::experiment::VgtStep;
use mvem::components::Semantics;
use mvem::io::csv_inputs;
use mvem::model::{Actuators, AnyModel, CylinderTemp, Drive, ModelOptions, ModelOrder};
use mvem::params::Params;
use mvem::sim::{InputSchedule, SimOptions};
use std::fmt;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// Errors and exit codes

/// Exit code of a successful run.
pub const EXIT_OK: u8 = 0;
/// Exit code of a runtime failure (solver, no equilibrium, `--strict` check failed).
pub const EXIT_RUNTIME: u8 = 1;
/// Exit code of a usage or input-file error (bad option, bad CSV, bad parameters).
pub const EXIT_USAGE: u8 = 2;

/// A usage or input error found by the CLI itself (exit code 2).
#[derive(Debug)]
pub struct UsageError(pub String);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// A usage error as an [`anyhow::Error`].
pub fn usage(msg: impl Into<String>) -> anyhow::Error {
    UsageError(msg.into()).into()
}

/// Exit code for an error: 2 if anything in its chain is a usage or input-file problem,
/// 1 otherwise (a runtime failure).
pub fn exit_code(e: &anyhow::Error) -> u8 {
    use mvem::sim::SimError;
    let input = e.chain().any(|c| {
        c.is::<UsageError>()
            || c.is::<mvem::io::IoError>()
            || c.is::<mvem::params::ParamIssues>()
            || c.is::<mvem::model::ModelError>()
            || c.is::<mvem::model::InputError>()
            || c.is::<mvem::sim::ScheduleError>()
            || matches!(
                c.downcast_ref::<SimError>(),
                Some(
                    SimError::BadOption { .. }
                        | SimError::BadCommand { .. }
                        | SimError::BadInterval { .. }
                        | SimError::BadHorizon { .. }
                )
            )
            || matches!(
                c.downcast_ref::<mvem::analysis::steady::SteadyError>(),
                Some(mvem::analysis::steady::SteadyError::Input(_))
            )
    });
    if input {
        EXIT_USAGE
    } else {
        EXIT_RUNTIME
    }
}

/// The error and its causes joined by ": ", leaving out a cause whose text is already part of
/// the message (library errors often repeat their source).
pub fn error_message(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for c in e.chain() {
        let s = c.to_string();
        if msg.is_empty() {
            msg = s;
        } else if !msg.contains(&s) {
            msg.push_str(": ");
            msg.push_str(&s);
        }
    }
    msg
}

// ---------------------------------------------------------------------------------------------
// Model arguments

/// `--model`: number of states.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// The paper's 8-state model (sections 3-7).
    #[value(name = "8")]
    Eight,
    /// 10 states: adiabatic manifolds (section 9.1).
    #[value(name = "10")]
    Ten,
    /// 12 states: plus the volume before the intercooler (section 9.2).
    #[value(name = "12")]
    Twelve,
}

impl ModelArg {
    /// The model variant.
    pub fn order(self) -> ModelOrder {
        match self {
            ModelArg::Eight => ModelOrder::Eight,
            ModelArg::Ten => ModelOrder::Ten,
            ModelArg::Twelve => ModelOrder::Twelve,
        }
    }
}

/// `--semantics`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SemanticsArg {
    /// The authors' Simulink implementation (saturations, switches, integrator limits).
    Authors,
    /// The paper's plain equations.
    Paper,
}

/// `--cylinder-temp`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CylinderTempArg {
    /// Solve the cylinder-out temperature fixed point to convergence at every evaluation.
    Converged,
    /// One iteration per evaluation, held between steps (the authors' Simulink Memory blocks).
    OneIteration,
}

/// `--actuators`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ActuatorsArg {
    /// Actuator dynamics and transport delays on.
    Dynamic,
    /// Commands pass straight through to the valve positions.
    Bypass,
}

/// Parameter set and model variant (shared by every command that builds a model).
#[derive(Debug, Clone, clap::Args)]
pub struct ModelArgs {
    /// Parameter file: TOML, nested JSON, or the authors' flat JSON
    /// [default: the built-in published set]
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Model variant (number of states).
    #[arg(long, value_enum, default_value = "8")]
    pub model: ModelArg,
    /// Equations: the authors' implementation or the paper's plain equations.
    #[arg(long, value_enum, default_value = "authors")]
    pub semantics: SemanticsArg,
    /// Cylinder-out temperature fixed point (eq. (24)).
    #[arg(long = "cylinder-temp", value_enum, default_value = "converged")]
    pub cylinder_temp: CylinderTempArg,
    /// Actuator dynamics (eqs (39)-(41), (57)) or bypass.
    #[arg(long, value_enum, default_value = "dynamic")]
    pub actuators: ActuatorsArg,
    /// The parameter file as first read: a command that asks for the input ranges and then the
    /// model reads the file once, so both come from the same contents.
    #[arg(skip)]
    pub(crate) loaded: std::sync::OnceLock<Params>,
}

impl Default for ModelArgs {
    /// The flags' defaults: the published set, 8 states, the authors' semantics, converged
    /// T_e, dynamic actuators.
    fn default() -> Self {
        Self {
            params: None,
            model: ModelArg::Eight,
            semantics: SemanticsArg::Authors,
            cylinder_temp: CylinderTempArg::Converged,
            actuators: ActuatorsArg::Dynamic,
            loaded: std::sync::OnceLock::new(),
        }
    }
}

impl ModelArgs {
    /// The parameters: the file given with `--params` (validated; read once per command) or
    /// the published set.
    pub fn load_params(&self) -> Result<Params> {
        let Some(path) = &self.params else {
            return Ok(Params::published());
        };
        if let Some(p) = self.loaded.get() {
            return Ok(p.clone());
        }
        let p = mvem::io::params::load_params(path)
            .with_context(|| format!("cannot use parameter file {}", path.display()))?;
        Ok(self.loaded.get_or_init(|| p).clone())
    }

    /// Model options from the flags.
    pub fn options(&self) -> ModelOptions {
        ModelOptions {
            semantics: match self.semantics {
                SemanticsArg::Authors => Semantics::Authors,
                SemanticsArg::Paper => Semantics::Paper,
            },
            cylinder_temp: match self.cylinder_temp {
                CylinderTempArg::Converged => CylinderTemp::Converged,
                CylinderTempArg::OneIteration => CylinderTemp::OneIteration,
            },
            actuators: match self.actuators {
                ActuatorsArg::Dynamic => Actuators::Dynamic,
                ActuatorsArg::Bypass => Actuators::Bypass,
            },
        }
    }

    /// The model variant.
    pub fn order(&self) -> ModelOrder {
        self.model.order()
    }

    /// The input saturation ranges the model will apply (the parameter set's
    /// `input_saturation`, the command ranges included; `None` with `--semantics paper`,
    /// which applies none), for the warnings of [`check_drive`] and [`warn_ranges`].
    pub fn input_ranges(&self) -> Result<Option<InputRanges>> {
        Ok(match self.semantics {
            SemanticsArg::Paper => None,
            SemanticsArg::Authors => Some(csv_inputs::input_ranges(
                &self.load_params()?.input_saturation,
            )),
        })
    }

    /// Build the model (parameters loaded and validated).
    pub fn build(&self) -> Result<AnyModel> {
        let p = self.load_params()?;
        AnyModel::new(self.order(), p, self.options()).context("cannot build the model")
    }
}

// ---------------------------------------------------------------------------------------------
// Solver arguments

/// Integration tolerances and output interval (shared by `simulate`, `demo`, `bench`).
#[derive(Debug, Clone, clap::Args)]
pub struct SolverArgs {
    /// Relative tolerance of the integrator, in (0, 1) [default: 1e-6]
    #[arg(long, value_name = "R")]
    pub rtol: Option<f64>,
    /// Absolute tolerance, relative to each state's typical magnitude (1e5 Pa, 0.1, 1e4 rad/s,
    /// 100 %) [default: equal to rtol, as the library's `SimOptions::default()` (1e-6, 1e-6)]
    #[arg(long, value_name = "A")]
    pub atol: Option<f64>,
    /// Output interval [s] (the end time is always written) [default: 0.01; step, report: 0.005; bench: 0.1]
    #[arg(long, value_name = "S")]
    pub dt: Option<f64>,
    /// Integrate the actuator states numerically like the other states (default: in closed
    /// form on every segment where the delayed command is linear; see docs/integrator.md)
    #[arg(long)]
    pub numeric_actuators: bool,
    /// Integrate without the non-autonomous term gamma_i h^2 df/dt in the stages of the default
    /// method (the default of earlier versions, for comparison; see docs/integrator.md)
    #[arg(long)]
    pub no_time_derivative: bool,
}

impl SolverArgs {
    /// Options with `default_dt` when `--dt` is not given; checked (the message names the option).
    pub fn options(&self, default_dt: f64) -> Result<SimOptions> {
        let rtol = self.rtol.unwrap_or(1e-6);
        let o = SimOptions {
            rtol,
            atol: self.atol.unwrap_or(rtol),
            dt_out: self.dt.unwrap_or(default_dt),
            exact_actuators: !self.numeric_actuators,
            rosw_time_derivative: !self.no_time_derivative,
            ..SimOptions::default()
        };
        o.validate().map_err(|e| match e {
            mvem::sim::SimError::BadOption {
                field,
                value,
                constraint,
            } => usage(format!(
                "invalid option --{field} {}: {constraint}",
                mvem::numerics::Num(value)
            )),
            other => usage(other.to_string()),
        })?;
        Ok(o)
    }
}

// ---------------------------------------------------------------------------------------------
// Scenarios

/// Built-in input scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Scenario {
    /// n_e 1500 rpm, u_delta 110 mg, u_egr 80 %, u_vgt 75 -> 65 % at t = 1 s, 0..8 s
    /// (non-minimum-phase W_c, negative DC gain).
    VgtStepNmp,
    /// As vgt-step-nmp but u_vgt 30 -> 25 % (overshoot, positive DC gain).
    VgtStepOvershoot,
    /// The WHTC drive cycle, 10 Hz inputs, 0..1800 s (data/whtc_inputs_10hz.csv).
    Whtc,
}

/// The WHTC inputs (built in).
pub const WHTC_CSV: &str = include_str!("../../../data/whtc_inputs_10hz.csv");

/// Name used for the built-in WHTC inputs in messages.
pub const WHTC_NAME: &str = "<built-in data/whtc_inputs_10hz.csv>";

impl Scenario {
    /// The paper's VGT step of this scenario (defined in the core,
    /// [`VgtStep::paper_cases`]); `None` for the WHTC.
    pub fn paper_step(self) -> Option<VgtStep> {
        let [nmp, overshoot] = VgtStep::paper_cases();
        match self {
            Scenario::VgtStepNmp => Some(nmp),
            Scenario::VgtStepOvershoot => Some(overshoot),
            Scenario::Whtc => None,
        }
    }

    /// The input schedule and the end time [s].
    pub fn schedule(self) -> Result<(InputSchedule, f64)> {
        match self.paper_step() {
            Some(step) => Ok((step.spec().schedule()?, step.t_end)),
            None => {
                let s = whtc_schedule()?;
                let t_end = s.t_last();
                Ok((s, t_end))
            }
        }
    }

    /// The name on the command line.
    pub fn name(self) -> String {
        self.to_possible_value()
            .map(|v| v.get_name().to_string())
            .unwrap_or_default()
    }
}

/// The built-in WHTC input schedule.
pub fn whtc_schedule() -> Result<InputSchedule> {
    Ok(csv_inputs::parse_inputs_csv(
        WHTC_CSV,
        Path::new(WHTC_NAME),
    )?)
}

/// A whole input cycle: the CSV `inputs` or, without one, the built-in WHTC; returns the
/// schedule, its name for messages, and its first and last time [s] (which must differ).
pub fn cycle_inputs(
    inputs: Option<&Path>,
    ranges: Option<&InputRanges>,
) -> Result<(InputSchedule, String, f64, f64)> {
    let (sched, source) = match inputs {
        Some(p) => (load_inputs(p, ranges)?, p.display().to_string()),
        None => (whtc_schedule()?, WHTC_NAME.to_string()),
    };
    let (t0, t_end) = (sched.t_first(), sched.t_last());
    if t_end <= t0 {
        return Err(usage(format!(
            "{source}: the inputs span no time (first and last row at {t0} s)"
        )));
    }
    Ok((sched, source, t0, t_end))
}

/// Input saturation ranges per channel (name, lo, hi) ([`ModelArgs::input_ranges`]).
pub type InputRanges = [(&'static str, f64, f64); 4];

/// Load an input CSV and warn once per channel (on stderr) about values outside the model's
/// input saturation ranges (`None`: the model saturates nothing).
pub fn load_inputs(path: &Path, ranges: Option<&InputRanges>) -> Result<InputSchedule> {
    let s = csv_inputs::load_inputs_csv(path)?;
    warn_ranges(&s, &path.display().to_string(), ranges);
    Ok(s)
}

/// Print the range warnings of a schedule, once per channel.
pub fn warn_ranges(s: &InputSchedule, source: &str, ranges: Option<&InputRanges>) {
    for w in ranges
        .map(|r| csv_inputs::range_warnings(s, r))
        .unwrap_or_default()
    {
        eprintln!("warning: {source}: {w}");
    }
}

// ---------------------------------------------------------------------------------------------
// Helpers

/// Check up front that an output file can be created where asked (its directory exists), so
/// that no computation is wasted on an impossible write.
pub fn check_output_path(path: &Path, what: &str) -> Result<()> {
    if path.as_os_str().is_empty() {
        return Err(usage(format!("{what}: empty file name")));
    }
    if path.is_dir() {
        return Err(usage(format!("{what} {}: is a directory", path.display())));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(usage(format!(
            "{what} {}: directory {} does not exist",
            path.display(),
            dir.display()
        )));
    }
    Ok(())
}

/// Refuse an output grid with more than [`mvem::sim::MAX_ROWS`] rows, or a time beyond
/// [`mvem::sim::MAX_TIME`] ([`mvem::sim::check_horizon`]), before simulating.
pub fn check_samples(t0: f64, t_end: f64, dt: f64) -> Result<()> {
    use mvem::sim::MAX_ROWS;
    let n = (t_end - t0) / dt + 1.0;
    if n > MAX_ROWS {
        let num = mvem::numerics::Num;
        return Err(usage(format!(
            "--dt {}: {n:.3e} output samples from {} s to {} s (at most {MAX_ROWS:e}); use a larger --dt",
            num(dt),
            num(t0),
            num(t_end)
        )));
    }
    mvem::sim::check_horizon(t0, t_end, dt).map_err(|e| usage(e.to_string()))
}

/// Unit of a state, signal or input column, for tables and axis labels (the core's metadata,
/// [`mvem::model::meta::unit`]; `""` for an unknown name).
pub fn unit(name: &str) -> &'static str {
    mvem::model::meta::unit(name)
}

/// A value with 8 significant digits, plain for magnitudes in [1e-3, 1e7), scientific otherwise.
pub fn fmt_value(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        format!("{v}")
    } else if (1e-3..1e7).contains(&a) {
        let dec = (7 - a.log10().floor() as i32).clamp(0, 10) as usize;
        format!("{v:.dec$}")
    } else {
        format!("{v:.7e}")
    }
}

/// Seconds as a short human string.
pub fn fmt_duration(s: f64) -> String {
    if s < 1e-6 {
        format!("{:.0} ns", s * 1e9)
    } else if s < 1e-3 {
        format!("{:.2} us", s * 1e6)
    } else if s < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.3} s")
    }
}

/// Whether stderr is an interactive terminal (progress display only then).
pub fn stderr_is_terminal() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal()
}

/// A spinner on stderr showing the elapsed time while `f` runs (only on a terminal; the
/// result never depends on it), its message following the computation's progress reports
/// (`mvem::numerics::progress`): "tuning: step 5 (...): 1234 evaluations, cost 1.4660e-3".
pub fn with_spinner<T>(msg: &str, f: impl FnOnce() -> T) -> T {
    use mvem::numerics::progress::{with_observer, Observer, Progress};
    if !stderr_is_terminal() {
        return f();
    }
    let pb = indicatif::ProgressBar::new_spinner();
    pb.set_draw_target(indicatif::ProgressDrawTarget::stderr());
    if let Ok(style) = indicatif::ProgressStyle::with_template("{spinner} [{elapsed}] {wide_msg}") {
        pb.set_style(style);
    }
    pb.set_message(msg.to_string());
    pb.enable_steady_tick(std::time::Duration::from_millis(100));
    let (bar, msg) = (pb.clone(), msg.to_string());
    let stage = std::sync::Mutex::new(msg.clone());
    let observer: Observer = std::sync::Arc::new(move |p: &Progress| {
        let mut stage = stage
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match p {
            Progress::Stage { name } => {
                *stage = format!("{msg}: {name}");
                bar.set_message(stage.clone());
            }
            Progress::Search { evaluations, cost } => bar.set_message(format!(
                "{stage}: {evaluations} evaluations, cost {cost:.4e}"
            )),
        }
    });
    let out = with_observer(&observer, f);
    pb.finish_and_clear();
    out
}

// ---------------------------------------------------------------------------------------------
// Operating points

/// The operating point of the analysis commands (all four inputs).
#[derive(Debug, Clone, clap::Args)]
pub struct PointArgs {
    /// Engine speed n_e [rpm].
    #[arg(long = "n-e", value_name = "RPM", allow_negative_numbers = true)]
    pub n_e: f64,
    /// Injected fuel u_delta [mg/cycle/cylinder].
    #[arg(long = "u-delta", value_name = "MG", allow_negative_numbers = true)]
    pub u_delta: f64,
    /// EGR valve command u_egr [%] (0 closed, 100 open).
    #[arg(long = "u-egr", value_name = "PCT", allow_negative_numbers = true)]
    pub u_egr: f64,
    /// VGT command u_vgt [%] (0 closed, 100 open).
    #[arg(long = "u-vgt", value_name = "PCT", allow_negative_numbers = true)]
    pub u_vgt: f64,
}

impl PointArgs {
    /// The checked operating point (see [`check_drive`]).
    pub fn drive(&self, ranges: Option<&InputRanges>) -> Result<Drive> {
        let d = Drive::new(self.n_e, self.u_delta, self.u_egr, self.u_vgt);
        check_drive(&d, ranges)?;
        Ok(d)
    }
}

/// An operating point whose inputs may be supplied otherwise (`map`: a grid axis; `step`:
/// `--from` for the stepped input); the command says which are required.
#[derive(Debug, Clone, clap::Args)]
pub struct OptionalPointArgs {
    /// Engine speed n_e [rpm] (unless given otherwise, e.g. as an --axis).
    #[arg(long = "n-e", value_name = "RPM", allow_negative_numbers = true)]
    pub n_e: Option<f64>,
    /// Injected fuel u_delta [mg/cycle/cylinder] (unless given otherwise).
    #[arg(long = "u-delta", value_name = "MG", allow_negative_numbers = true)]
    pub u_delta: Option<f64>,
    /// EGR valve command u_egr [%] (unless given otherwise).
    #[arg(long = "u-egr", value_name = "PCT", allow_negative_numbers = true)]
    pub u_egr: Option<f64>,
    /// VGT command u_vgt [%] (unless given otherwise).
    #[arg(long = "u-vgt", value_name = "PCT", allow_negative_numbers = true)]
    pub u_vgt: Option<f64>,
}

impl OptionalPointArgs {
    /// The given values in [`Drive::to_array`] order.
    pub fn given(&self) -> [Option<f64>; 4] {
        [self.n_e, self.u_delta, self.u_egr, self.u_vgt]
    }
}

/// Option names of the inputs in [`Drive::to_array`] order.
pub const INPUT_OPTIONS: [&str; 4] = ["--n-e", "--u-delta", "--u-egr", "--u-vgt"];

/// Refuse non-finite inputs (usage error naming the option) and warn on stderr about values
/// outside the model's input saturation ranges (which clamp them; `None`: none).
pub fn check_drive(d: &Drive, ranges: Option<&InputRanges>) -> Result<()> {
    check_drive_except(d, ranges, [false; 4])
}

/// [`check_drive`] without the range warning for the inputs marked in `other` (in
/// [`Drive::to_array`] order): those a caller checks on its own, such as `mvem map`'s axes,
/// whose values the point only holds a place for.
pub fn check_drive_except(d: &Drive, ranges: Option<&InputRanges>, other: [bool; 4]) -> Result<()> {
    for (name, v) in INPUT_OPTIONS.iter().zip(d.to_array()) {
        if !v.is_finite() {
            return Err(usage(format!("{name} {v}: must be finite")));
        }
    }
    for (((name, lo, hi), v), other) in ranges.into_iter().flatten().zip(d.to_array()).zip(other) {
        if !other && (v < *lo || v > *hi) {
            eprintln!(
                "warning: {name} = {} is outside [{lo}, {hi}]; the authors' saturation clamps it (--semantics paper uses it as given; the ranges are input_saturation of the parameter file)",
                mvem::numerics::Num(v)
            );
        }
    }
    Ok(())
}

/// A point as `n_e 1500 rpm, u_delta 110 mg/cycle, u_egr 80 %, u_vgt 75 %` (the fuel per cycle
/// and cylinder, in the unit of the explorer and the CSVs).
pub fn fmt_drive(d: &Drive) -> String {
    format!(
        "n_e {} rpm, u_delta {} mg/cycle, u_egr {} %, u_vgt {} %",
        d.n_e_rpm, d.u_delta_mg, d.u_egr_pct, d.u_vgt_pct
    )
}

/// `--threads N` of the commands that take 0 for all cores: a whole number 0..=1024 (more
/// threads than that only cost time: each one is an operating-system thread).
pub fn threads_arg(s: &str) -> std::result::Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number >= 0"))?;
    if n > 1024 {
        return Err(format!("{n} threads: at most 1024 (0: all cores)"));
    }
    Ok(n)
}
