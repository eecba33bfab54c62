//! A whole drive-cycle run, in one place for every front end (`mvem closed-loop`, the
//! closed-loop mode of `mvem serve`): the engine's mapping curve, the demand (the WHTC
//! denormalized for this engine, or a given speed/torque demand), the controller, the loop
//! ([`super::run`]) and the regulation's statistics.

use super::baseline::{Baseline, BaselineTuning, OpenLoop};
use super::cycle::{
    parse_normalized_table, whtc_demand, Demand, MappingCurve, MappingOptions, NormalizedRow,
    ReferenceSpeeds, WHTC_NORMALIZED,
};
use super::stats::CycleStats;
use super::{ControlError, Controller, Trajectory};
use crate::model::AnyModel;
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

/// The demand up to `t_end` (linear at the cut).
fn truncate(d: &Demand, t_end: f64) -> Result<Demand, ControlError> {
    let mut t: Vec<f64> = d.times().iter().cloned().filter(|&t| t < t_end).collect();
    t.push(t_end);
    let pts: Vec<_> = t.iter().map(|&x| d.at(x)).collect();
    Demand::new(
        t,
        pts.iter().map(|p| p.n_e).collect(),
        pts.iter().map(|p| p.m_ref).collect(),
        pts.iter().map(|p| p.motoring).collect(),
    )
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
        if !(s.is_finite() && s > 0.0) {
            return Err(ControlError::Demand(format!("duration {s} s: must be > 0")));
        }
    }
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
            whtc_demand(table, &curve, &speeds)?
        }
        (CycleSource::Demand(d), Scheme::Baseline(_)) => {
            d.check_speeds(curve.n_e_range())?;
            d.check_feasible(&curve, FEASIBLE_TOL)?;
            d.clone()
        }
    };
    let demand = match duration {
        None => demand,
        Some(s) => {
            let (t0, t1) = demand.span();
            truncate(&demand, (t0 + s).min(t1))?
        }
    };
    let mut ctrl: Box<dyn Controller> = match scheme {
        Scheme::Baseline(tuning) => {
            Box::new(Baseline::new(model, &curve, tuning).map_err(|e| {
                ControlError::Setup(format!("cannot set up the baseline controller: {e}"))
            })?)
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
    let stats = CycleStats::compute(&traj, curve.m_peak(), LAMBDA_LIMIT);
    let violations = stats.violations(LAMBDA_FLOOR);
    Ok(CycleRun {
        traj,
        stats,
        violations,
        speeds,
        solver,
    })
}
