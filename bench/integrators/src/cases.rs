//! The two test cases (WHTC drive cycle, demo step), the output grid and the error measure.

use anyhow::{Context, Result};
use mvem::analysis::steady::steady_state;
use mvem::model::{Drive, Engine8, Model};
use mvem::sim::InputSchedule;
use std::path::Path;

/// Output interval of all runs [s].
pub const DT_OUT: f64 = 0.1;

/// States compared against the reference: (index in the 8-state vector, name, scale).
/// Scales: p_im, p_em 1e5 Pa; X_Oim, X_Oem 0.1; omega_t 1e4 rad/s.
pub const COMPARED: [(usize, &str, f64); 5] = [
    (0, "p_im", 1e5),
    (1, "p_em", 1e5),
    (2, "X_Oim", 0.1),
    (3, "X_Oem", 0.1),
    (4, "omega_t", 1e4),
];

/// One simulation problem: model, inputs, interval, initial state.
pub struct Case {
    /// Short name used in tables and the figure.
    pub name: &'static str,
    /// One-line description for the report.
    pub description: String,
    /// The 8-state model (published parameters, default options).
    pub model: Engine8,
    /// Input schedule.
    pub sched: InputSchedule,
    /// Start time [s].
    pub t0: f64,
    /// End time [s].
    pub t_end: f64,
    /// Initial state: the steady state at the inputs at `t0`.
    pub y0: [f64; 8],
}

impl Case {
    fn new(
        name: &'static str,
        description: String,
        sched: InputSchedule,
        t0: f64,
        t_end: f64,
    ) -> Result<Self> {
        let model = Engine8::published();
        let d: Drive = sched.at(t0);
        let ss = steady_state(&model, &d)
            .map_err(|e| anyhow::anyhow!("steady state of case {name} at {d:?}: {e}"))?;
        Ok(Self {
            name,
            description,
            model,
            sched,
            t0,
            t_end,
            y0: ss.x,
        })
    }

    /// The WHTC drive cycle at 10 Hz, 0..1800 s.
    pub fn whtc(repo: &Path) -> Result<Self> {
        let path = repo.join("data/whtc_inputs_10hz.csv");
        let sched = mvem::io::csv_inputs::load_inputs_csv(&path)
            .with_context(|| format!("loading {}", path.display()))?;
        Self::new(
            "WHTC",
            "WHTC drive cycle, data/whtc_inputs_10hz.csv, 0..1800 s".into(),
            sched,
            0.0,
            1800.0,
        )
    }

    /// The demo step: n_e 1500 rpm, u_delta 110 mg, u_egr 80 %, u_vgt 75 % -> 65 % at 1 s, 0..8 s.
    pub fn step() -> Result<Self> {
        let sched = InputSchedule::steps(Drive::new(1500.0, 110.0, 80.0, 75.0), &[(1.0, 3, 65.0)])
            .context("step schedule")?;
        Self::new(
            "step",
            "demo step: n_e 1500 rpm, u_delta 110 mg, u_egr 80 %, u_vgt 75 -> 65 % at 1 s, 0..8 s"
                .into(),
            sched,
            0.0,
            8.0,
        )
    }

    /// Output times: every [`DT_OUT`] from `t0`, plus `t_end` (mvem's grid).
    pub fn out_times(&self) -> Vec<f64> {
        let mut v = Vec::new();
        let mut k = 0u64;
        loop {
            let t = self.t0 + k as f64 * DT_OUT;
            if t >= self.t_end - 1e-9 * self.t_end.abs().max(1.0) {
                break;
            }
            v.push(t);
            k += 1;
        }
        v.push(self.t_end);
        v
    }

    /// Absolute tolerances: `atol_rel` times the state scales of the model.
    pub fn atol(&self, atol_rel: f64) -> [f64; 8] {
        self.model.state_scales().map(|s| s * atol_rel)
    }
}

/// Samples of the compared states at the output times: `samples[k][j]` is state
/// `COMPARED[j]` at output time k.
pub type Samples = Vec<[f64; 5]>;

/// Pick the compared states out of full 8-state samples.
pub fn compared(full: &[[f64; 8]]) -> Samples {
    full.iter()
        .map(|x| std::array::from_fn(|j| x[COMPARED[j].0]))
        .collect()
}

/// Maximum scaled deviation per compared state, and the time [s] of the overall maximum.
pub fn max_dev(a: &Samples, b: &Samples, times: &[f64]) -> ([f64; 5], f64) {
    assert_eq!(a.len(), b.len(), "sample counts differ");
    assert_eq!(a.len(), times.len(), "sample count vs output times");
    let mut m = [0.0f64; 5];
    let (mut worst, mut t_worst) = (0.0f64, times[0]);
    for (k, (ra, rb)) in a.iter().zip(b).enumerate() {
        for j in 0..5 {
            let d = ((ra[j] - rb[j]) / COMPARED[j].2).abs();
            // NaN counts as infinitely wrong
            let d = if d.is_nan() { f64::INFINITY } else { d };
            m[j] = m[j].max(d);
            if d > worst {
                worst = d;
                t_worst = times[k];
            }
        }
    }
    (m, t_worst)
}
