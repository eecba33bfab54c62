//! Dormand-Prince 5(4) coefficients with Hairer's 4th-order dense output
//! (E. Hairer, S. P. Norsett, G. Wanner, Solving Ordinary Differential Equations I, 2nd ed.,
//! Springer 1993, Table 5.2 of section II.5 and the dense output of section II.6; `dopri5.f`),
//! and the method's trial step.

use super::integrator::{Integrator, Interp, Trial};
use super::segment::SegmentInputs;
use super::SimError;
use crate::model::Dynamics;

pub(crate) const C2: f64 = 1.0 / 5.0;
pub(crate) const C3: f64 = 3.0 / 10.0;
pub(crate) const C4: f64 = 4.0 / 5.0;
pub(crate) const C5: f64 = 8.0 / 9.0;

pub(crate) const A21: f64 = 1.0 / 5.0;
pub(crate) const A31: f64 = 3.0 / 40.0;
pub(crate) const A32: f64 = 9.0 / 40.0;
pub(crate) const A41: f64 = 44.0 / 45.0;
pub(crate) const A42: f64 = -56.0 / 15.0;
pub(crate) const A43: f64 = 32.0 / 9.0;
pub(crate) const A51: f64 = 19372.0 / 6561.0;
pub(crate) const A52: f64 = -25360.0 / 2187.0;
pub(crate) const A53: f64 = 64448.0 / 6561.0;
pub(crate) const A54: f64 = -212.0 / 729.0;
pub(crate) const A61: f64 = 9017.0 / 3168.0;
pub(crate) const A62: f64 = -355.0 / 33.0;
pub(crate) const A63: f64 = 46732.0 / 5247.0;
pub(crate) const A64: f64 = 49.0 / 176.0;
pub(crate) const A65: f64 = -5103.0 / 18656.0;
pub(crate) const A71: f64 = 35.0 / 384.0;
pub(crate) const A73: f64 = 500.0 / 1113.0;
pub(crate) const A74: f64 = 125.0 / 192.0;
pub(crate) const A75: f64 = -2187.0 / 6784.0;
pub(crate) const A76: f64 = 11.0 / 84.0;

/// Error coefficients: 5th-order weights minus 4th-order weights.
pub(crate) const E1: f64 = 71.0 / 57600.0;
pub(crate) const E3: f64 = -71.0 / 16695.0;
pub(crate) const E4: f64 = 71.0 / 1920.0;
pub(crate) const E5: f64 = -17253.0 / 339200.0;
pub(crate) const E6: f64 = 22.0 / 525.0;
pub(crate) const E7: f64 = -1.0 / 40.0;

/// Dense output coefficients (dopri5.f, `CONTD5`).
pub(crate) const D1: f64 = -12715105075.0 / 11282082432.0;
pub(crate) const D3: f64 = 87487479700.0 / 32700410799.0;
pub(crate) const D4: f64 = -10690763975.0 / 1880347072.0;
pub(crate) const D5: f64 = 701980252875.0 / 199316789632.0;
pub(crate) const D6: f64 = -1453857185.0 / 822651844.0;
pub(crate) const D7: f64 = 69997945.0 / 29380423.0;

/// Dense output polynomial of one accepted step (`rcont1..5` of dopri5.f).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Dense<const N: usize> {
    pub r: [[f64; N]; 5],
}

impl<const N: usize> Dense<N> {
    /// Build from the step's start y0, end y1, stages k1..k7 and step size h.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        y0: &[f64; N],
        y1: &[f64; N],
        k1: &[f64; N],
        k3: &[f64; N],
        k4: &[f64; N],
        k5: &[f64; N],
        k6: &[f64; N],
        k7: &[f64; N],
        h: f64,
    ) -> Self {
        let mut r = [[0.0; N]; 5];
        for i in 0..N {
            let ydiff = y1[i] - y0[i];
            let bspl = h * k1[i] - ydiff;
            r[0][i] = y0[i];
            r[1][i] = ydiff;
            r[2][i] = bspl;
            r[3][i] = ydiff - h * k7[i] - bspl;
            r[4][i] =
                h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
        }
        Self { r }
    }

    /// y(t0 + theta h), theta in [0, 1].
    pub fn eval(&self, theta: f64) -> [f64; N] {
        let t1 = 1.0 - theta;
        std::array::from_fn(|i| {
            self.r[0][i]
                + theta
                    * (self.r[1][i]
                        + t1 * (self.r[2][i] + theta * (self.r[3][i] + t1 * self.r[4][i])))
        })
    }
}

impl<const N: usize, M: Dynamics<N>> Integrator<'_, N, M> {
    /// One Dormand-Prince 5(4) trial step.
    pub(super) fn step_dopri5(
        &mut self,
        inp: &mut SegmentInputs,
        t: f64,
        h: f64,
        t_new: f64,
        f0: &[f64; N],
    ) -> Result<Trial<N, M::Memory>, SimError> {
        let y = self.y;
        let k1 = *f0;
        let mut yt = [0.0; N];
        for i in 0..N {
            yt[i] = y[i] + h * A21 * k1[i];
        }
        let k2 = self.rhs(inp, t + C2 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        let k3 = self.rhs(inp, t + C3 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        let k4 = self.rhs(inp, t + C4 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        let k5 = self.rhs(inp, t + C5 * h, &yt)?.dx;
        for i in 0..N {
            yt[i] =
                y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        let k6 = self.rhs(inp, t_new, &yt)?.dx;
        let mut y1 = [0.0; N];
        for i in 0..N {
            y1[i] =
                y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        let ev7 = self.rhs(inp, t_new, &y1)?;
        let k7 = ev7.dx;
        let mut e = [0.0; N];
        for i in 0..N {
            e[i] =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
        }
        Ok(Trial {
            y1,
            err: self.error_norm(&y, &y1, &e),
            e,
            dense: Some(Interp::Dopri(Dense::new(
                &y, &y1, &k1, &k3, &k4, &k5, &k6, &k7, h,
            ))),
            f1: Some((k7, ev7.memory_next)),
        })
    }
}
