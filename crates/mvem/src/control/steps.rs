//! Set-point step tests of the baseline air-path controller at a fixed speed and fuel.

use super::baseline::{Baseline, BaselineTuning};
use super::cycle::{Demand, MappingCurve};
use super::{run, ControlError, Controller, Measurement, Output, Trajectory};
use crate::analysis::step::StepMetrics;
use crate::model::AnyModel;

/// The baseline controller with its set-points overridden, stepped at `t_step`.
struct Stepped {
    inner: Baseline,
    t_step: f64,
    after: (f64, f64),
}

impl Controller for Stepped {
    fn sample_time(&self) -> f64 {
        self.inner.sample_time()
    }
    fn start(&mut self, t0: f64, n_e: f64, m_ref: f64, motoring: bool) -> Output {
        self.inner.start(t0, n_e, m_ref, motoring)
    }
    fn update(&mut self, m: &Measurement) -> Output {
        if m.t >= self.t_step - 1e-9 {
            self.inner.setpoint_override = self.after;
        }
        self.inner.update(m)
    }
    fn notes(&self) -> Vec<String> {
        self.inner.notes()
    }
}

/// Result of one set-point step.
#[derive(Debug, Clone)]
pub struct SetpointStep {
    /// The run (one row per sample).
    pub traj: Trajectory,
    /// Step metrics of the stepped signal (final value: mean of the last second).
    pub metrics: StepMetrics,
    /// Peak-to-peak of the stepped signal over the last 2 s (limit-cycle check).
    pub tail_peak_to_peak: f64,
    /// Final EGR and VGT commands [%].
    pub final_commands: (f64, f64),
}

/// Hold `n_e` \[rpm\] and `u_delta` \[mg\], settle with the set-points `before` (lambda_O,s,
/// x_egr,s) until `t_step`, then step to `after`; run to `t_end`. `signal` is `"lambda_O"` or
/// `"x_egr"` (the stepped one, for the metrics). A NaN set-point is the maps' own at the
/// operating point (with a lambda_O,s from the maps their valve position set-point applies,
/// [`super::baseline::SetpointMaps::u_egr_max`]).
#[allow(clippy::too_many_arguments)]
pub fn setpoint_step(
    model: &AnyModel,
    curve: &MappingCurve,
    tuning: BaselineTuning,
    n_e: f64,
    u_delta: f64,
    before: (f64, f64),
    after: (f64, f64),
    signal: &str,
    t_step: f64,
    t_end: f64,
) -> Result<SetpointStep, ControlError> {
    let mut inner = Baseline::new(model, curve, tuning)?;
    let (l_map, x_map) = inner.maps.setpoints(n_e, u_delta);
    let or_map = |v: f64, map: f64| if v.is_nan() { map } else { v };
    inner.fuel_override = u_delta;
    inner.setpoint_override = before;
    let mut c = Stepped {
        inner,
        t_step,
        after,
    };
    let demand = Demand::new(
        vec![0.0, t_end],
        vec![n_e, n_e],
        vec![0.0, 0.0],
        vec![false, false],
    )?;
    demand.check_speeds(curve.n_e_range())?;
    let (traj, _) = run(
        model.clone(),
        &demand,
        &mut c,
        &crate::sim::stepper::plant_options(),
    )?;
    let t = traj.get("t").expect("column");
    let y = traj.get(signal).ok_or_else(|| {
        ControlError::Setup(format!("unknown signal {signal} (lambda_O or x_egr)"))
    })?;
    let i_step = t.partition_point(|&s| s < t_step);
    let y0 = y[i_step];
    let last = |secs: f64| t.partition_point(|&s| s < t_end - secs);
    let tail1 = &y[last(1.0)..];
    let y_final = tail1.iter().sum::<f64>() / tail1.len() as f64;
    let tail2 = &y[last(2.0)..];
    let pp = tail2.iter().cloned().fold(f64::MIN, f64::max)
        - tail2.iter().cloned().fold(f64::MAX, f64::min);
    let du = if signal == "lambda_O" {
        or_map(after.0, l_map) - or_map(before.0, l_map)
    } else {
        or_map(after.1, x_map) - or_map(before.1, x_map)
    };
    let metrics = StepMetrics::compute(t, y, t_step, y0, y_final, du)
        .map_err(|e| ControlError::Setup(e.to_string()))?;
    let n = traj.len();
    let final_commands = (
        traj.get("u_egr").unwrap()[n - 1],
        traj.get("u_vgt").unwrap()[n - 1],
    );
    Ok(SetpointStep {
        traj,
        metrics,
        tail_peak_to_peak: pp,
        final_commands,
    })
}
