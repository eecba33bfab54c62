//! A whole drive-cycle run, in one place for every front end (`mvem closed-loop`, the
//! closed-loop mode of `mvem serve`): the engine's mapping curve, the demand (the WHTC
//! denormalized for this engine, or a given speed/torque demand), the controller, the loop
//! ([`super::run`]) and the regulation's statistics.

use super::baseline::{AdjustedCell, Baseline, BaselineTuning, OpenLoop};
use super::cycle::{
    parse_normalized_table, whtc_demand, Demand, MappingCurve, MappingOptions, NormalizedRow,
    ReferenceSpeeds, WHTC_NORMALIZED,
};
use super::stats::CycleStats;
use super::{ControlError, Controller, Trajectory};
use crate::model::AnyModel;
use crate::numerics::Num;
use crate::sim::{InputSchedule, SimStats};

/// Controller sample time of a cycle run \[s\].
pub const SAMPLE_TIME: f64 = 0.01;
/// lambda_O limit of the cycle statistics [-].
pub const LAMBDA_LIMIT: f64 = 1.2;
/// lambda_O floor of the regulation check ([`CycleStats::violations`]) [-].
pub const LAMBDA_FLOOR: f64 = 1.05;
/// Relative tolerance of a given demand's torque above the full-load curve [-].
pub const FEASIBLE_TOL: f64 = 0.01;

/// The cycle to drive.
#[derive(Debug, Clone)]
pub enum CycleSource {
    /// The WHTC (UN GTR No. 4) denormalized with this engine's mapping curve.
    Whtc,
    /// A speed/torque demand (checked against the full-load curve).
    Demand(Demand),
    /// A normalized cycle ([`super::cycle::parse_normalized_table`]: time \[s\], speed [%],
    /// torque [%] or motoring) denormalized with this engine's mapping curve as the WHTC is.
    Normalized(Vec<NormalizedRow>),
}

impl CycleSource {
    /// First and last time of the cycle \[s\] (the built-in WHTC: 0 and 1800 s).
    pub fn span(&self) -> Result<(f64, f64), ControlError> {
        let ends = |rows: &[NormalizedRow]| match (rows.first(), rows.last()) {
            (Some(a), Some(b)) => Ok((a.0, b.0)),
            _ => Err(ControlError::Demand("the cycle has no rows".into())),
        };
        match self {
            Self::Whtc => ends(&whtc_table()?),
            Self::Demand(d) => Ok(d.span()),
            Self::Normalized(rows) => ends(rows),
        }
    }
}

/// The controller of a cycle run.
#[derive(Debug, Clone)]
pub enum Scheme {
    /// The baseline EGR/VGT and engine controllers with this tuning.
    Baseline(BaselineTuning),
    /// The commands of an open-loop input schedule (the WHTC's `data/whtc_inputs_10hz.csv`),
    /// sampled every [`SAMPLE_TIME`]; the demand follows the schedule's speed (WHTC only).
    OpenLoop(InputSchedule),
}

/// Why a cycle run needs the authors' semantics ([`run_cycle`] refuses the paper's).
pub const PAPER_SEMANTICS_REFUSED: &str = "the closed loop needs the authors' semantics: the \
     paper's plain equations have no equilibrium at idle and low load (the compressor \
     efficiency's (Pi_c - 1)^c_pi of eq. (64) is undefined for Pi_c < 1), where the mapping \
     curve's motoring points and every cycle's idle lie (docs/authors-implementation.md, \
     \"Where the paper's plain equations have no operating point\")";

/// Check a run's duration `s` \[s\] against the controller's sample time `ts`: a finite number
/// of at least one sample time (a run has at least two samples, its start and one more).
pub fn check_duration(s: f64, ts: f64) -> Result<(), String> {
    if !(s.is_finite() && s > 0.0) {
        return Err(format!("{s}: must be a finite number of seconds > 0"));
    }
    if s < ts * (1.0 - 1e-9) {
        return Err(format!(
            "{} s: shorter than two controller samples (a run has at least its start and one \
             more sample, {} s later)",
            Num(s),
            Num(ts)
        ));
    }
    Ok(())
}

/// The end of a run of `demand` over its whole span, or its first `duration` seconds, on the
/// sample grid of `ts` from its start; notes for `warnings` where the duration or the cycle's
/// end is not on the grid (the samples up to it run, the rest does not) or the duration is
/// longer than the cycle.
fn planned_end(
    demand: &Demand,
    duration: Option<f64>,
    ts: f64,
    warnings: &mut Vec<String>,
) -> Result<f64, ControlError> {
    let (t0, t1) = demand.span();
    let grid = |span: f64| (span / ts + 1e-9).floor() * ts;
    let off = |span: f64| span - grid(span) > 1e-9 * span.max(1.0);
    if let Some(s) = duration {
        check_duration(s, ts).map_err(|e| ControlError::Demand(format!("duration {e}")))?;
        if s <= t1 - t0 + 1e-9 * (t1 - t0).max(1.0) {
            if off(s) {
                warnings.push(format!(
                    "duration {} s is not a multiple of the {} s sample time: ran the samples \
                     up to {} s after the start",
                    Num(s),
                    Num(ts),
                    Num(grid(s))
                ));
            }
            return Ok(t0 + grid(s));
        }
        warnings.push(format!(
            "duration {} s is longer than the cycle ({} s from {} s to {} s): ran all of it",
            Num(s),
            Num(t1 - t0),
            Num(t0),
            Num(t1)
        ));
    }
    if t1 - t0 < ts * (1.0 - 1e-9) {
        return Err(ControlError::Demand(format!(
            "the cycle spans {} s, shorter than two controller samples ({} s apart)",
            Num(t1 - t0),
            Num(ts)
        )));
    }
    if off(t1 - t0) {
        warnings.push(format!(
            "the cycle ends at {} s, off the {} s sample grid from its start at {} s: ran the \
             samples up to {} s and left the last {} s of the cycle out",
            Num(t1),
            Num(ts),
            Num(t0),
            Num(t0 + grid(t1 - t0)),
            Num(((t1 - t0 - grid(t1 - t0)) * 1e9).round() / 1e9)
        ));
    }
    Ok(t1)
}

/// A finished cycle run.
#[derive(Debug, Clone)]
pub struct CycleRun {
    /// One row per controller sample.
    pub traj: Trajectory,
    /// Statistics (lambda_O limit [`LAMBDA_LIMIT`]).
    pub stats: CycleStats,
    /// Regulation limit violations (empty: pass).
    pub violations: Vec<String>,
    /// Reference speeds of the mapping curve.
    pub speeds: ReferenceSpeeds,
    /// Solver statistics of the plant.
    pub solver: SimStats,
    /// What the run did that its input did not say (each a sentence): the duration or the
    /// cycle's end rounded to the sample grid, a duration longer than the cycle, normalized
    /// speeds clamped into the engine's range, a demand below the motoring torque, the
    /// controller's notes ([`Controller::notes`]: an actuator wound to its end).
    pub warnings: Vec<String>,
    /// The baseline's set-point map cells whose pair is out of the actuators' reach, with the
    /// valve position set there ([`super::baseline::SetpointMaps::adjusted`]; empty for the
    /// open-loop schedule).
    pub setpoint_adjustments: Vec<AdjustedCell>,
}

/// The normalized WHTC table with the first sample repeated at t = 0 (as
/// `data/whtc_inputs_10hz.csv`): (time \[s\], speed [%], torque [%] or None for motoring).
pub fn whtc_table() -> Result<Vec<NormalizedRow>, ControlError> {
    let mut table = parse_normalized_table(WHTC_NORMALIZED)
        .map_err(|e| ControlError::Setup(format!("built-in WHTC table: {e}")))?;
    let first = table[0];
    table.insert(0, (0.0, first.1, first.2));
    Ok(table)
}

/// The WHTC demand along the speed trace of an open-loop schedule: the normalized torque on this
/// engine's curve at that speed (the motoring torque at the "m" points).
fn open_loop_demand(sched: &InputSchedule, curve: &MappingCurve) -> Result<Demand, ControlError> {
    let (mut t, mut n, mut m, mut mot) = (vec![], vec![], vec![], vec![]);
    for (ti, _, tq) in whtc_table()? {
        let ne = sched.at(ti).n_e_rpm;
        t.push(ti);
        n.push(ne);
        m.push(match tq {
            Some(p) => p / 100.0 * curve.m_max_at(ne),
            None => curve.m_motor_at(ne),
        });
        mot.push(tq.is_none());
    }
    Demand::new(t, n, m, mot)
}

/// Drive `cycle` with `scheme` on `model`, only the first `duration` seconds if given; the
/// statistics and the regulation check of the trajectory.
pub fn run_cycle(
    model: &AnyModel,
    cycle: CycleSource,
    scheme: Scheme,
    duration: Option<f64>,
) -> Result<CycleRun, ControlError> {
    run_cycle_with(model, cycle, scheme, duration, &mut |_| {})
}

/// [`run_cycle`], calling `on_row` with the trajectory so far after each row (see
/// [`super::run_with`]; not called when the set-up fails).
pub fn run_cycle_with(
    model: &AnyModel,
    cycle: CycleSource,
    scheme: Scheme,
    duration: Option<f64>,
    on_row: &mut dyn FnMut(&Trajectory),
) -> Result<CycleRun, ControlError> {
    if let Some(s) = duration {
        check_duration(s, SAMPLE_TIME)
            .map_err(|e| ControlError::Demand(format!("duration {e}")))?;
    }
    if !crate::dispatch!(model, m => crate::model::Model::options(m).semantics.authors()) {
        return Err(ControlError::Setup(PAPER_SEMANTICS_REFUSED.into()));
    }
    let mut warnings = Vec::new();
    let curve = MappingCurve::compute(model, MappingOptions::default()).map_err(|e| {
        ControlError::Setup(format!("cannot compute the engine's mapping curve: {e}"))
    })?;
    // idle: the bottom of the engine's speed range (the authors': 500 rpm)
    let speeds = curve.reference_speeds(curve.n_e_range().0);
    let demand = match (&cycle, &scheme) {
        (CycleSource::Whtc, Scheme::Baseline(_)) => whtc_demand(&whtc_table()?, &curve, &speeds)?,
        (CycleSource::Whtc, Scheme::OpenLoop(sched)) => open_loop_demand(sched, &curve)?,
        (CycleSource::Demand(_) | CycleSource::Normalized(_), Scheme::OpenLoop(_)) => {
            return Err(ControlError::Demand(
                "the open-loop schedule runs the WHTC only".into(),
            ))
        }
        (CycleSource::Normalized(table), Scheme::Baseline(_)) => {
            warnings.extend(clamped_speeds(table, &curve, &speeds));
            whtc_demand(table, &curve, &speeds)?
        }
        (CycleSource::Demand(d), Scheme::Baseline(_)) => {
            d.check_speeds(curve.n_e_range())?;
            d.check_feasible(&curve, FEASIBLE_TOL)?;
            warnings.extend(d.below_motoring(&curve));
            d.clone()
        }
    };
    let t_end = planned_end(&demand, duration, SAMPLE_TIME, &mut warnings)?;
    let demand = if t_end < demand.span().1 {
        demand.until(t_end)?
    } else {
        demand
    };
    let mut setpoint_adjustments = Vec::new();
    let mut ctrl: Box<dyn Controller> = match scheme {
        Scheme::Baseline(tuning) => {
            let b = Baseline::new(model, &curve, tuning).map_err(|e| {
                ControlError::Setup(format!("cannot set up the baseline controller: {e}"))
            })?;
            setpoint_adjustments.clone_from(&b.maps.adjusted);
            Box::new(b)
        }
        Scheme::OpenLoop(schedule) => Box::new(OpenLoop {
            schedule,
            ts: SAMPLE_TIME,
        }),
    };
    let (traj, solver) = super::run_with(
        model.clone(),
        &demand,
        ctrl.as_mut(),
        &crate::sim::stepper::plant_options(),
        on_row,
    )?;
    warnings.extend(ctrl.notes());
    let stats = CycleStats::compute(&traj, curve.m_peak(), LAMBDA_LIMIT);
    let violations = stats.violations(LAMBDA_FLOOR);
    Ok(CycleRun {
        traj,
        stats,
        violations,
        speeds,
        solver,
        warnings,
        setpoint_adjustments,
    })
}

/// The note on a normalized cycle's speeds that denormalize outside the engine's speed range and
/// are clamped into it (the count and the first: its time, its speed in % and in rpm).
fn clamped_speeds(
    table: &[NormalizedRow],
    curve: &MappingCurve,
    speeds: &ReferenceSpeeds,
) -> Option<String> {
    let (lo, hi) = curve.n_e_range();
    let out: Vec<&NormalizedRow> = table
        .iter()
        .filter(|r| !(lo..=hi).contains(&speeds.denormalize(r.1)))
        .collect();
    let first = out.first()?;
    Some(format!(
        "{} row(s) of the normalized cycle denormalize outside the engine's speed range [{}, \
         {}] rpm and are clamped into it, the first at t = {} s: {} % -> {:.0} rpm",
        out.len(),
        Num(lo),
        Num(hi),
        Num(first.0),
        Num(first.1),
        speeds.denormalize(first.1)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::cycle::Demand;

    /// A cycle whose end is off the sample grid runs the samples up to the grid's last point and
    /// says so in a sentence (it read "..., the last 0.007 s of the cycle not": session 43).
    #[test]
    fn a_cycle_end_off_the_grid_is_said_in_a_sentence() {
        let d = Demand::new(
            vec![0.0, 1.007],
            vec![1200.0, 1200.0],
            vec![500.0, 500.0],
            vec![false, false],
        )
        .unwrap();
        let mut w = Vec::new();
        let end = planned_end(&d, None, 0.01, &mut w).unwrap();
        assert_eq!(end, 1.007);
        assert_eq!(
            w,
            vec![
                "the cycle ends at 1.007 s, off the 0.01 s sample grid from its start at 0 s: ran \
                 the samples up to 1 s and left the last 0.007 s of the cycle out"
                    .to_string()
            ]
        );
    }
}
