//! How stiff is the model along a trajectory: eigenvalues of the full 8-state Jacobian
//! (finite differences) at the reference solution.

use crate::cases::Case;
use mvem::components::cylinder::SeligerIterate;
use mvem::model::Model;
use mvem::sim::SegmentInputs;
use nalgebra::SMatrix;

/// Fastest eigenvalues along a trajectory.
pub struct Stiffness {
    /// Most negative real part of the Jacobian's eigenvalues at the start [1/s].
    pub start: f64,
    /// Most negative real part over the trajectory samples [1/s].
    pub worst: f64,
    /// Time of `worst` [s].
    pub t_worst: f64,
    /// Median over the samples of the most negative real part [1/s].
    pub median: f64,
    /// Largest real part over the samples [1/s] (positive: locally unstable).
    pub max_re: f64,
    /// Time of `max_re` [s].
    pub t_max_re: f64,
    /// Number of samples examined.
    pub n: usize,
}

const MEMORY: SeligerIterate = SeligerIterate {
    x_r: 0.0,
    t_1: 300.0,
};

/// Eigenvalues (re, im) of df/dx at state `x` and time `t` [1/s].
fn eigenvalues(case: &Case, inp: &mut SegmentInputs, t: f64, x: &[f64; 8]) -> Vec<(f64, f64)> {
    let u = inp.at(t);
    let scales = case.model.state_scales();
    let f0 = case.model.eval(x, &u, MEMORY).dx;
    let mut j = SMatrix::<f64, 8, 8>::zeros();
    for c in 0..8 {
        let h = 1e-7 * x[c].abs().max(scales[c]);
        let mut xp = *x;
        xp[c] += h;
        let fp = case.model.eval(&xp, &u, MEMORY).dx;
        for r in 0..8 {
            j[(r, c)] = (fp[r] - f0[r]) / h;
        }
    }
    j.complex_eigenvalues()
        .iter()
        .map(|z| (z.re, z.im))
        .collect()
}

/// Examine every `every`-th sample of the trajectory `full` at `times`.
pub fn along(case: &Case, full: &[[f64; 8]], times: &[f64], every: usize) -> Stiffness {
    let mut inp = SegmentInputs::new(&case.model, &case.sched, case.t0, case.t_end);
    let min_re = |ev: &[(f64, f64)]| ev.iter().map(|e| e.0).fold(f64::INFINITY, f64::min);
    let start = min_re(&eigenvalues(case, &mut inp, times[0], &full[0]));
    let mut mins = Vec::new();
    let (mut worst, mut t_worst) = (f64::INFINITY, times[0]);
    let (mut max_re, mut t_max_re) = (f64::NEG_INFINITY, times[0]);
    for k in (0..full.len()).step_by(every.max(1)) {
        let ev = eigenvalues(case, &mut inp, times[k], &full[k]);
        let m = min_re(&ev);
        if m < worst {
            worst = m;
            t_worst = times[k];
        }
        let mx = ev.iter().map(|e| e.0).fold(f64::NEG_INFINITY, f64::max);
        if mx > max_re {
            max_re = mx;
            t_max_re = times[k];
        }
        mins.push(m);
    }
    mins.sort_by(f64::total_cmp);
    Stiffness {
        start,
        worst,
        t_worst,
        median: mins[mins.len() / 2],
        max_re,
        t_max_re,
        n: mins.len(),
    }
}
