//! The paper's section-9 comparison of the model extensions, and the cylinder-out temperature
//! study of section 4.2.3, as plain-data functions for reports and front ends.
//!
//! - [`compare_vgt_steps`]: simulate VGT steps (by default the two of Figs 11-14: n_e =
//!   1500 rpm, u_delta = 110 mg, u_egr = 80 %, u_vgt 75 -> 65 % and 30 -> 25 % at t = 1 s) with
//!   each model order (8, 10, 12 states) and return the time series, the stationary differences
//!   to the first order (steady states before and after the step) and the W_c features the
//!   paper discusses: non-minimum-phase dip, overshoot, and the sign reversal of the DC gain
//!   between the two steps ([`sign_reversal`]).
//! - [`cylinder_temp_study`]: simulate an input schedule (the paper uses the ETC; mvem ships
//!   the WHTC, `data/whtc_inputs_10hz.csv`) with the converged cylinder-out temperature and with
//!   one fixed-point iteration per accepted step (Fig. 2), and return the relative error of T_e.
//!
//! Each model order's response is the core step experiment
//! ([`crate::analysis::experiment::run_step`]); the W_c features are its [`StepMetrics`]
//! (definitions in [`crate::analysis::step`]), with the root-solved steady state at the new input
//! as the final value.

use crate::analysis::experiment::{run_step, StepRunError};
use crate::analysis::steady::{steady_state, SimFromSteadyError, SteadyError};
use crate::analysis::step::StepMetrics;
use crate::model::{
    AnyModel, CylinderTemp, Engine10, Engine12, Engine8, Model, ModelOptions, ModelOrder,
};
use crate::params::{ParamIssues, Params};
use crate::sim::{simulate, InputSchedule, ScheduleError, SimError, SimOptions, Start};
use serde::{Deserialize, Serialize};

pub use super::experiment::VgtStep;

/// Check a step of [`compare_vgt_steps`] (finite values, 0 < t_step < t_end, a change).
fn check_step(step: &VgtStep) -> Result<(), ExtensionError> {
    let fields = [
        ("n_e_rpm", step.n_e_rpm),
        ("u_delta_mg", step.u_delta_mg),
        ("u_egr_pct", step.u_egr_pct),
        ("u_vgt_from", step.u_vgt_from),
        ("u_vgt_to", step.u_vgt_to),
        ("t_step", step.t_step),
        ("t_end", step.t_end),
    ];
    for (field, value) in fields {
        if !value.is_finite() {
            return Err(ExtensionError::BadStep {
                field,
                value,
                constraint: "must be finite",
            });
        }
    }
    if !(step.t_step > 0.0 && step.t_step < step.t_end) {
        return Err(ExtensionError::BadStep {
            field: "t_step",
            value: step.t_step,
            constraint: "must lie in (0, t_end)",
        });
    }
    if step.u_vgt_from == step.u_vgt_to {
        return Err(ExtensionError::BadStep {
            field: "u_vgt_to",
            value: step.u_vgt_to,
            constraint: "must differ from u_vgt_from",
        });
    }
    Ok(())
}

/// Signals compared by [`compare_vgt_steps`] by default (names of [`crate::sim::Solution`]
/// columns; `T_im`, `T_em`, `p_c` are states of the extensions and signals of the 8-state model).
pub const COMPARED_SIGNALS: &[&str] = &[
    "p_im", "p_em", "p_c", "T_im", "T_em", "W_c", "W_ic", "W_egr", "n_t", "x_egr", "lambda_O",
    "M_e", "T_e",
];

/// Options of [`compare_vgt_steps`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompareOptions {
    /// Model orders to simulate; stationary differences are relative to the first.
    pub orders: Vec<ModelOrder>,
    /// Relative tolerance of the simulations (atol = rtol / 100 of each state's scale).
    pub rtol: f64,
    /// Output interval \[s\].
    pub dt_out: f64,
    /// Signals to return and compare (Solution column names).
    pub signals: Vec<String>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        Self {
            orders: vec![ModelOrder::Eight, ModelOrder::Ten, ModelOrder::Twelve],
            rtol: 1e-8,
            dt_out: 0.01,
            signals: COMPARED_SIGNALS.iter().map(|s| s.to_string()).collect(),
        }
    }
}

/// One model order's response to one step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepResponse {
    /// Model order.
    pub order: ModelOrder,
    /// Output times \[s\].
    pub t: Vec<f64>,
    /// (signal name, samples), in [`CompareOptions::signals`] order.
    pub series: Vec<(String, Vec<f64>)>,
    /// (signal name, value) at the steady state before the step.
    pub steady_before: Vec<(String, f64)>,
    /// (signal name, value) at the steady state at the new input.
    pub steady_after: Vec<(String, f64)>,
    /// Step metrics of the compressor flow W_c (from the steady states before and after).
    pub w_c: StepMetrics,
    /// Accepted integration steps.
    pub steps: usize,
}

impl StepResponse {
    /// Samples of a signal by name.
    pub fn series(&self, name: &str) -> Option<&[f64]> {
        self.series
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }
}

/// Stationary difference of one signal between a model order and the reference order.
#[derive(Debug, Clone, PartialEq)]
pub struct StationaryDifference {
    /// Model order.
    pub order: ModelOrder,
    /// Signal name.
    pub signal: String,
    /// (value - reference) / |reference| before the step [-] (absolute if the reference is 0).
    pub before: f64,
    /// The same at the steady state after the step [-].
    pub after: f64,
}

/// All model orders' responses to one step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepComparison {
    /// The step.
    pub step: VgtStep,
    /// One response per model order, in [`CompareOptions::orders`] order.
    pub responses: Vec<StepResponse>,
    /// Stationary differences of every order after the first to the first, per signal.
    pub stationary: Vec<StationaryDifference>,
}

impl StepComparison {
    /// The response of `order`.
    pub fn response(&self, order: ModelOrder) -> Option<&StepResponse> {
        self.responses.iter().find(|r| r.order == order)
    }
}

/// Why a comparison could not be made (naming the model order and case).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExtensionError {
    /// Invalid parameters.
    #[error(transparent)]
    Params(#[from] ParamIssues),
    /// A step definition is invalid.
    #[error("VGT step: {field} = {}: {constraint}", crate::numerics::Num(*value))]
    BadStep {
        /// Field name.
        field: &'static str,
        /// Value.
        value: f64,
        /// Constraint.
        constraint: &'static str,
    },
    /// An option is invalid.
    #[error("option {field} = {}: {constraint}", crate::numerics::Num(*value))]
    BadOption {
        /// Field name.
        field: &'static str,
        /// Value.
        value: f64,
        /// Constraint.
        constraint: &'static str,
    },
    /// The input schedule could not be built.
    #[error(transparent)]
    Schedule(#[from] ScheduleError),
    /// A steady state was not found.
    #[error("{order:?}-state model, {case}: {source}")]
    Steady {
        /// Model order.
        order: ModelOrder,
        /// Which case.
        case: String,
        /// Cause.
        source: SteadyError,
    },
    /// The W_c step metrics are undefined (no change).
    #[error("{order:?}-state model, {case}: W_c: {message}")]
    Metrics {
        /// Model order.
        order: ModelOrder,
        /// Which case.
        case: String,
        /// Cause.
        message: String,
    },
    /// A simulation failed.
    #[error("{order:?}-state model, {case}: {source}")]
    Sim {
        /// Model order.
        order: ModelOrder,
        /// Which case.
        case: String,
        /// Cause.
        source: SimError,
    },
}

/// Build the model variant `order`.
pub fn build_model(
    order: ModelOrder,
    p: &Params,
    opts: ModelOptions,
) -> Result<AnyModel, ParamIssues> {
    Ok(match order {
        ModelOrder::Eight => AnyModel::Eight(Engine8::new(p.clone(), opts)?),
        ModelOrder::Ten => AnyModel::Ten(Engine10::new(p.clone(), opts)?),
        ModelOrder::Twelve => AnyModel::Twelve(Engine12::new(p.clone(), opts)?),
    })
}

fn run_order<const N: usize, M: Model<N>>(
    m: &M,
    order: ModelOrder,
    step: &VgtStep,
    co: &CompareOptions,
) -> Result<StepResponse, ExtensionError> {
    let sim_opts = SimOptions {
        rtol: co.rtol,
        atol: co.rtol * 1e-2,
        dt_out: co.dt_out,
        ..SimOptions::default()
    };
    let case = step.label();
    let run = run_step(m, &step.spec(), &sim_opts).map_err(|e| match e {
        StepRunError::SteadyBefore { source, .. } | StepRunError::SteadyAfter { source, .. } => {
            ExtensionError::Steady {
                order,
                case: case.clone(),
                source,
            }
        }
        StepRunError::Sim(source) => ExtensionError::Sim {
            order,
            case: case.clone(),
            source,
        },
        StepRunError::Schedule(e) => ExtensionError::Schedule(e),
        StepRunError::BadStep {
            field,
            value,
            constraint,
        } => ExtensionError::BadStep {
            field,
            value,
            constraint,
        },
    })?;
    let pick = |after: bool| -> Vec<(String, f64)> {
        co.signals
            .iter()
            .map(|n| {
                let v = if after {
                    run.value_after(n)
                } else {
                    run.value_before(n)
                };
                (n.clone(), v.unwrap_or(f64::NAN))
            })
            .collect()
    };
    let series = co
        .signals
        .iter()
        .map(|n| {
            let v = run
                .sol
                .get(n)
                .map(|c| c.to_vec())
                .unwrap_or_else(|| vec![f64::NAN; run.sol.len()]);
            (n.clone(), v)
        })
        .collect();
    let w_c = run.metrics("W_c").map_err(|e| ExtensionError::Metrics {
        order,
        case: case.clone(),
        message: e.to_string(),
    })?;
    Ok(StepResponse {
        order,
        t: run.sol.t().to_vec(),
        series,
        steady_before: pick(false),
        steady_after: pick(true),
        w_c,
        steps: run.sol.stats.steps,
    })
}

fn rel_diff(v: f64, r: f64) -> f64 {
    if r == 0.0 {
        v - r
    } else {
        (v - r) / r.abs()
    }
}

/// Simulate each step with each model order in `co.orders` (from the steady state, with the
/// parameters `p` and options `opts`) and compare (see the module documentation).
pub fn compare_vgt_steps(
    p: &Params,
    opts: ModelOptions,
    steps: &[VgtStep],
    co: &CompareOptions,
) -> Result<Vec<StepComparison>, ExtensionError> {
    if !(co.rtol.is_finite() && co.rtol >= 1e-12 && co.rtol < 1.0) {
        return Err(ExtensionError::BadOption {
            field: "rtol",
            value: co.rtol,
            constraint: "must lie in [1e-12, 1)",
        });
    }
    if co.orders.is_empty() {
        return Err(ExtensionError::BadOption {
            field: "orders",
            value: 0.0,
            constraint: "at least one model order",
        });
    }
    let models = co
        .orders
        .iter()
        .map(|&o| build_model(o, p, opts))
        .collect::<Result<Vec<_>, _>>()?;
    let mut out = Vec::with_capacity(steps.len());
    for step in steps {
        check_step(step)?;
        let mut responses = Vec::with_capacity(models.len());
        for (any, &order) in models.iter().zip(&co.orders) {
            let r = crate::dispatch!(any, m => run_order(m, order, step, co))?;
            responses.push(r);
        }
        let mut stationary = Vec::new();
        let reference = &responses[0];
        for r in &responses[1..] {
            for (k, name) in co.signals.iter().enumerate() {
                stationary.push(StationaryDifference {
                    order: r.order,
                    signal: name.clone(),
                    before: rel_diff(r.steady_before[k].1, reference.steady_before[k].1),
                    after: rel_diff(r.steady_after[k].1, reference.steady_after[k].1),
                });
            }
        }
        out.push(StepComparison {
            step: *step,
            responses,
            stationary,
        });
    }
    Ok(out)
}

/// Whether the DC gain of W_c from u_vgt changes sign between the cases of `cases` for model
/// `order` (the paper's sign reversal, Figs 9-10, 12, 14): `Some(true)` if both signs occur,
/// `Some(false)` if not, `None` if `order` has fewer than two responses.
pub fn sign_reversal(cases: &[StepComparison], order: ModelOrder) -> Option<bool> {
    let gains: Vec<f64> = cases
        .iter()
        .filter_map(|c| c.response(order))
        .map(|r| r.w_c.dc_gain)
        .collect();
    if gains.len() < 2 {
        return None;
    }
    Some(gains.iter().any(|g| *g > 0.0) && gains.iter().any(|g| *g < 0.0))
}

/// Options of [`cylinder_temp_study`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CylinderTempOptions {
    /// Relative tolerance of both simulations (atol = rtol / 100 of each state's scale). The
    /// one-iteration result depends on the accepted step sequence and hence on it.
    pub rtol: f64,
    /// Output interval \[s\] (errors are evaluated at these samples).
    pub dt_out: f64,
}

impl Default for CylinderTempOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            dt_out: 0.1,
        }
    }
}

/// Result of [`cylinder_temp_study`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CylinderTempStudy {
    /// Relative tolerance used.
    pub rtol: f64,
    /// Absolute tolerance used (times each state's scale).
    pub atol: f64,
    /// Output times \[s\].
    pub t: Vec<f64>,
    /// T_e \[K\] with the converged fixed point.
    pub t_e_converged: Vec<f64>,
    /// T_e \[K\] with one iteration per accepted step.
    pub t_e_one_iteration: Vec<f64>,
    /// Relative error (one iteration - converged) / converged [-] at each sample.
    pub rel_error: Vec<f64>,
    /// Maximum |relative error| [-].
    pub max_abs_rel_error: f64,
    /// Time of the maximum \[s\].
    pub t_max: f64,
    /// Mean |relative error| over the samples [-].
    pub mean_abs_rel_error: f64,
    /// Accepted steps of the converged run.
    pub steps_converged: usize,
    /// Accepted steps of the one-iteration run.
    pub steps_one_iteration: usize,
}

/// Simulate `sched` on `[t0, t_end]` with `m` twice, with [`CylinderTemp::Converged`] and
/// [`CylinderTemp::OneIteration`] (the authors' memory held from the last accepted step),
/// both from the (converged) steady state at the first inputs, and compare T_e (paper
/// section 4.2.3, Fig. 2: max 0.15 % on the ETC).
pub fn cylinder_temp_study<const N: usize, M: Model<N>>(
    m: &M,
    sched: &InputSchedule,
    t0: f64,
    t_end: f64,
    co: &CylinderTempOptions,
) -> Result<CylinderTempStudy, SimFromSteadyError> {
    let mut o = *m.options();
    o.cylinder_temp = CylinderTemp::Converged;
    let conv = m.with_options(o);
    o.cylinder_temp = CylinderTemp::OneIteration;
    let one = m.with_options(o);
    let d0 = sched.at(t0);
    let x0 = steady_state(&conv, &d0)?.x;
    let sim_opts = SimOptions {
        rtol: co.rtol,
        atol: co.rtol * 1e-2,
        dt_out: co.dt_out,
        ..SimOptions::default()
    };
    let a = simulate(&conv, sched, t0, t_end, Start::State(x0), &sim_opts)?;
    let b = simulate(&one, sched, t0, t_end, Start::State(x0), &sim_opts)?;
    let ta = a.get("T_e").unwrap_or(&[]);
    let tb = b.get("T_e").unwrap_or(&[]);
    let n = ta.len().min(tb.len());
    let rel_error: Vec<f64> = (0..n).map(|i| (tb[i] - ta[i]) / ta[i]).collect();
    let (mut max, mut t_max, mut sum) = (0.0f64, f64::NAN, 0.0);
    for (i, e) in rel_error.iter().enumerate() {
        if e.abs() > max {
            max = e.abs();
            t_max = a.t()[i];
        }
        sum += e.abs();
    }
    Ok(CylinderTempStudy {
        rtol: sim_opts.rtol,
        atol: sim_opts.atol,
        t: a.t()[..n].to_vec(),
        t_e_converged: ta[..n].to_vec(),
        t_e_one_iteration: tb[..n].to_vec(),
        rel_error,
        max_abs_rel_error: max,
        t_max,
        mean_abs_rel_error: if n > 0 { sum / n as f64 } else { f64::NAN },
        steps_converged: a.stats.steps,
        steps_one_iteration: b.stats.steps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_steps_and_options_are_reported_by_name() {
        let p = Params::published();
        let mut s = VgtStep::paper_cases()[0];
        s.t_step = 9.0;
        let e = compare_vgt_steps(
            &p,
            ModelOptions::default(),
            &[s],
            &CompareOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("t_step = 9"), "{e}");
        s = VgtStep::paper_cases()[0];
        s.u_delta_mg = f64::NAN;
        let e = compare_vgt_steps(
            &p,
            ModelOptions::default(),
            &[s],
            &CompareOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("u_delta_mg = NaN"), "{e}");
        let co = CompareOptions {
            rtol: 0.0,
            ..CompareOptions::default()
        };
        let e = compare_vgt_steps(&p, ModelOptions::default(), &VgtStep::paper_cases(), &co)
            .unwrap_err();
        assert!(e.to_string().contains("rtol"), "{e}");
    }
}
