//! The derivatives of the integrated system that the Rosenbrock methods (ROS34PW2, RODAS4,
//! exprb32) need besides f: the Jacobian df/dy and the non-autonomous term df/dt, both by finite
//! differences of the model's right-hand side on the current segment's inputs.

use super::integrator::{Integrator, LagSegment};
use super::segment::SegmentInputs;
use super::SimError;
use crate::model::{Dynamics, ModelInput};

impl<const N: usize, M: Dynamics<N>> Integrator<'_, N, M> {
    /// Finite-difference Jacobian df/dy at (t, y) with f(t, y) = f0 (forward differences,
    /// step sqrt(eps) relative to max(|y_i|, scale_i)); the columns with `skip[c]` stay zero.
    pub(super) fn jacobian(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        f0: &[f64; N],
        skip: &[bool; N],
    ) -> Result<[[f64; N]; N], SimError> {
        let y = self.y;
        let scales = self.model.state_scales();
        // every column at the same t: one input lookup
        let u = inp.at(t);
        let mut j = [[0.0; N]; N];
        for c in (0..N).filter(|&c| !skip[c]) {
            let mut yp = y;
            let mut d = 1.5e-8 * y[c].abs().max(scales[c]);
            if yp[c] + d > self.bounds[c].1 {
                d = -d;
            }
            yp[c] += d;
            let fp = self.rhs_with(t, &yp, &u)?.dx;
            for r in 0..N {
                j[r][c] = (fp[r] - f0[r]) / d;
            }
        }
        self.stats.jacobians += 1;
        Ok(j)
    }

    /// The non-autonomous term f_t = df/dt at (t, y) with z = the non-lag states held fixed:
    /// a forward difference along the direction (du/dt, da/dt) of the inputs (their slopes on
    /// the segment, [`SegmentInputs::rates`]) and of the closed-form lag states a (their exact
    /// rates on the segment), i.e. df/du u' + df/da a'. The inputs are linear on the segment, so
    /// this is the derivative of the reduced system dz/dt = f_z(z, a(t), u(t)) in t; it reads
    /// no input outside the segment (the perturbed inputs are values of the segment's own line,
    /// a relative 1.5e-8 away). Zero (and no evaluation) when nothing moves. `du`: the inputs'
    /// slopes at t, [`SegmentInputs::rates`] (the caller's, which ROS34PW2 also compares).
    pub(super) fn time_derivative(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        f0: &[f64; N],
        lag_seg: &[LagSegment],
        du: &ModelInput,
    ) -> Result<[f64; N], SimError> {
        let u = inp.at(t);
        let uv = u.to_array();
        let dv = du.to_array();
        let y = self.y;
        let scales = self.model.state_scales();
        let mut da = [0.0; N];
        for l in lag_seg {
            da[l.state] = l.rate(t, y[l.state]);
        }
        // the largest relative rate sets the difference step
        let mut rel: f64 = 0.0;
        for (v, d) in uv.iter().zip(&dv) {
            rel = rel.max(d.abs() / v.abs().max(1.0));
        }
        for l in lag_seg {
            rel = rel.max(da[l.state].abs() / y[l.state].abs().max(scales[l.state]));
        }
        if !(rel > 0.0 && rel.is_finite()) {
            return Ok([0.0; N]);
        }
        let d = 1.5e-8 / rel;
        let up = ModelInput::from_array(std::array::from_fn(|k| uv[k] + d * dv[k]));
        let yp: [f64; N] = std::array::from_fn(|i| y[i] + d * da[i]);
        let fp = self.rhs_with(t, &yp, &up)?.dx;
        Ok(std::array::from_fn(|i| (fp[i] - f0[i]) / d))
    }
}
