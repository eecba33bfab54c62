//! Discrete-time linear models for sampled control (MPC, discrete observers and Kalman
//! filters): the linearization of [`super::linearize`] sampled with a zero-order hold at the
//! sample time `ts`, with the actuator transport delays represented **exactly**.
//!
//! The continuous model of [`super::linearize`] (without Padé states) is that of the undelayed
//! system. Here its input matrix is split into the part of the current commands and the part of
//! the delayed copies u_egr(t - tau_degr), u_vgt(t - tau_dvgt), which drive only the actuator
//! states (eqs (40), (41), (57)). With a zero-order hold a delay tau = l ts + tau'
//! (0 <= tau' < ts) is exact in discrete time (Åström & Wittenmark, *Computer-Controlled
//! Systems*, sec. 2.3): over the sample interval [k ts, (k+1) ts) the delayed command is
//! u(k - l - 1) until k ts + tau' and u(k - l) after, so
//!
//! ```text
//! x(k+1) = Phi x(k) + Gamma_now u(k) + Gamma_0 u_d(k - l) + Gamma_1 u_d(k - l - 1)
//! Phi     = e^(A ts)
//! Gamma_0 = int_0^(ts - tau') e^(A s) ds g
//! Gamma_1 = e^(A (ts - tau')) int_0^tau' e^(A s) ds g
//! ```
//!
//! with g the delayed copy's column. The past commands u_d(k - 1), ..., u_d(k - L) become
//! shift-register states (`u_egr(k-1)`, ...), L = l + 1 when tau' > 0, else l. The integrals are
//! blocks of the exponential of [[A, B], [0, 0]] t (Van Loan), computed in the scaled
//! coordinates (states by their typical magnitudes, inputs by [`INPUT_SCALES`]) where the matrix
//! is well conditioned.

use super::linearize::{
    converged, linearize, pow2_step, sided_derivative, LinearModel, LinearizeError,
    LinearizeOptions, INPUT_SCALES,
};
use crate::model::{Drive, Model, ModelInput, Signals};
use nalgebra::DMatrix;

/// Shortest sample time accepted \[s\]: the delay registers grow as 1/ts (at 1 ms the authors'
/// delays need 65 + 40 of them).
pub const TS_MIN: f64 = 1e-3;
/// Longest sample time accepted \[s\].
pub const TS_MAX: f64 = 100.0;
/// Most delay registers (past commands as states) of a sampled model: a parameter set with long
/// delays and a short sample time is refused instead of building a huge Phi.
pub const MAX_REGISTERS: usize = 1000;

/// A discrete-time linear model `dx(k+1) = Phi dx(k) + Gamma du(k)`,
/// `dy(k) = C dx(k) + D du(k)` in deviations from the operating point, sampled with a
/// zero-order hold at `ts`, the actuator delays exact (see the module documentation). Units as
/// [`LinearModel`]; the register states are past commands in %.
#[derive(Debug, Clone, PartialEq)]
pub struct DiscreteModel {
    /// Sample time \[s\].
    pub ts: f64,
    /// State transition matrix Phi ((n + L) x (n + L)).
    pub phi: DMatrix<f64>,
    /// Input matrix Gamma ((n + L) x 4).
    pub gamma: DMatrix<f64>,
    /// Output matrix (p x (n + L)).
    pub c: DMatrix<f64>,
    /// Feedthrough matrix (p x 4).
    pub d: DMatrix<f64>,
    /// The model's states, then the registers `u_egr(k-1)`, ..., `u_vgt(k-1)`, ...
    pub state_names: Vec<String>,
    /// Typical magnitudes of the states (registers: the input's scale).
    pub state_scales: Vec<f64>,
    /// Input names (u_delta, u_egr, u_vgt, n_e).
    pub input_names: Vec<String>,
    /// Output names.
    pub output_names: Vec<String>,
    /// Delays \[s\] of u_egr and u_vgt.
    pub delays: [f64; 2],
    /// Each delay as (whole samples l, remainder tau' \[s\]): tau = l ts + tau', 0 <= tau' < ts.
    pub delay_samples: [(usize, f64); 2],
    /// The continuous linearization sampled here (undelayed, without Padé states).
    pub continuous: LinearModel,
}

impl DiscreteModel {
    /// Number of states (the model's and the registers).
    pub fn n_states(&self) -> usize {
        self.phi.nrows()
    }

    /// Response of the outputs to the input sequence `u` (deviations, one row of 4 values per
    /// sample, from a zero state): `y(k)` for each `k` of `u`.
    pub fn response(&self, u: &[[f64; 4]]) -> Vec<Vec<f64>> {
        let n = self.n_states();
        let mut x = nalgebra::DVector::zeros(n);
        let mut out = Vec::with_capacity(u.len());
        for uk in u {
            let uv = nalgebra::DVector::from_row_slice(uk);
            let y = &self.c * &x + &self.d * &uv;
            out.push(y.iter().copied().collect());
            x = &self.phi * &x + &self.gamma * &uv;
        }
        out
    }
}

/// Sample the linearization of `m` at state `x` and constant inputs `d` at `ts` \[s\]
/// ([`TS_MIN`] ..= [`TS_MAX`]) with the actuator delays exact. `opts.pade_order` must be 0
/// (the delays are not approximated here). See the module documentation.
pub fn discretize<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    opts: &LinearizeOptions,
    ts: f64,
) -> Result<DiscreteModel, LinearizeError> {
    check_options(opts.pade_order, ts)?;
    let lin = linearize(m, x, d, opts)?;
    discretize_linear(m, x, d, &lin, ts)
}

/// [`discretize`] of a linearization `lin` already made of `m` at `x`, `d` (by
/// [`linearize`] without Padé states): the same result, without
/// linearizing again (a front end that shows both models).
pub fn discretize_linear<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    lin: &LinearModel,
    ts: f64,
) -> Result<DiscreteModel, LinearizeError> {
    check_options(lin.pade_order, ts)?;
    // as linearize: the converged model (the memory is a property of the integration)
    let conv = converged(m);
    split_and_sample(conv.as_ref().unwrap_or(m), x, d, lin.clone(), ts)
}

/// Whether `ts` is a sample time [`discretize`] accepts ([`TS_MIN`] ..= [`TS_MAX`], finite): the
/// one check, which front ends also call to refuse a bad value before any work.
pub fn check_ts(ts: f64) -> Result<(), LinearizeError> {
    if ts.is_finite() && (TS_MIN..=TS_MAX).contains(&ts) {
        Ok(())
    } else {
        Err(LinearizeError::BadOption {
            field: "ts",
            value: ts,
            constraint: "must lie in [1e-3, 100] s",
        })
    }
}

fn check_options(pade_order: usize, ts: f64) -> Result<(), LinearizeError> {
    check_ts(ts)?;
    if pade_order != 0 {
        return Err(LinearizeError::BadOption {
            field: "pade_order",
            value: pade_order as f64,
            constraint: "must be 0 with a sample time (the delays are exact in discrete time)",
        });
    }
    Ok(())
}

/// The input columns of a linearization without Padé states split into the current commands'
/// part and the delayed copies' part (u_egr(t - tau_degr), u_vgt(t - tau_dvgt)): `b = b_now + g`,
/// `d = d_now + gd` in the u_egr and u_vgt columns. Shared by the sampled model (exact delays in
/// discrete time) and the frequency response ([`super::frequency`], exact delays e^(-s tau)).
#[derive(Debug, Clone, PartialEq)]
pub struct DelaySplit {
    /// Derivatives' sensitivity to the delayed copies (n x 2: u_egr, u_vgt).
    pub g: DMatrix<f64>,
    /// Outputs' sensitivity to the delayed copies (p x 2; state outputs 0).
    pub gd: DMatrix<f64>,
    /// The input matrix of the current commands (n x 4).
    pub b_now: DMatrix<f64>,
    /// The feedthrough of the current commands (p x 4).
    pub d_now: DMatrix<f64>,
}

/// [`DelaySplit`] of `lin`, a linearization of `m` at `x`, `d` without Padé states (the delayed
/// copies' columns by [`directional_derivative`](super::linearize::directional_derivative), on
/// the same side as `lin` for a command at a limit of its range ([`LinearModel::one_sided`]);
/// an entry of the current part that cancels to the rounding of the two difference quotients
/// is an exact 0).
pub fn delay_split<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    lin: &LinearModel,
) -> Result<DelaySplit, LinearizeError> {
    let n = N;
    let p = lin.output_names.len();
    // The delayed copies' columns (directions 4 and 5 of ModelInput::to_array): derivatives
    // and the output rows that are signals (state outputs have no feedthrough).
    let u = ModelInput::constant(*d);
    let mem = m.memory_start(x, &u);
    let mut g = DMatrix::zeros(n, 2);
    let mut gd = DMatrix::zeros(p, 2);
    let (egr_lim, vgt_lim) =
        crate::model::command_saturation(m.options().semantics, &m.params().input_saturation);
    let u0 = d.to_array();
    for (q, input) in ["u_egr", "u_vgt"].into_iter().enumerate() {
        // a command at a limit of its range, which `linearize` differenced on one side (its
        // `one_sided`): its delayed copy sits at the same limit and is differenced on the same
        // side; one within the difference stencil of a limit, on the side away from it (a
        // central difference across the limit averaged the slope inside with the zero beyond,
        // so half of the command's effect came out undelayed: at u_vgt 20 % and 20.001 % the
        // Bode magnitudes were 21 % off at 50 Hz, the sampled model moved half the actuator
        // within the sample)
        let (lo, hi) = if q == 0 { egr_lim } else { vgt_lim };
        let (v, e) = (u0[2 + q], pow2_step(1e-4 * INPUT_SCALES[1 + q]));
        let side = lin
            .one_sided
            .iter()
            .find(|o| o.variable == input)
            .map(|o| f64::from(o.side))
            .or(if v >= lo && v - 2.0 * e < lo {
                Some(1.0)
            } else if v <= hi && v + 2.0 * e > hi {
                Some(-1.0)
            } else {
                None
            });
        let mut v_u = [0.0; 6];
        v_u[4 + q] = side.unwrap_or(1.0);
        let (dfx, dsig) = sided_derivative(m, x, &u, mem, &[0.0; N], &v_u, 1e-4, side.is_some())?;
        // (the derivative along -1 is minus the column's)
        let s = side.unwrap_or(1.0);
        for r in 0..n {
            g[(r, q)] = s * dfx[r];
        }
        for (o, name) in lin.output_names.iter().enumerate() {
            if let Some(j) = Signals::NAMES.iter().position(|s| s == name) {
                if !lin.state_names.iter().any(|s| s == name) {
                    gd[(o, q)] = s * dsig[j];
                }
            }
        }
    }
    // current-command part: the undelayed columns minus the delayed copies' (u_egr: 1, u_vgt: 2)
    let mut b_now = lin.b.clone();
    let mut d_now = lin.d.clone();
    // (an entry that cancels to the rounding of the two difference quotients, e.g. the
    // actuator rows, which only the delayed copy drives, is an exact 0)
    let rest = |total: f64, delayed: f64| {
        let r = total - delayed;
        if r.abs() <= 1e-9 * total.abs() {
            0.0
        } else {
            r
        }
    };
    for q in 0..2 {
        for r in 0..n {
            b_now[(r, 1 + q)] = rest(b_now[(r, 1 + q)], g[(r, q)]);
        }
        for o in 0..p {
            d_now[(o, 1 + q)] = rest(d_now[(o, 1 + q)], gd[(o, q)]);
        }
    }
    Ok(DelaySplit {
        g,
        gd,
        b_now,
        d_now,
    })
}

fn split_and_sample<const N: usize, M: Model<N>>(
    m: &M,
    x: &[f64; N],
    d: &Drive,
    lin: LinearModel,
    ts: f64,
) -> Result<DiscreteModel, LinearizeError> {
    let n = N;
    let p = lin.output_names.len();
    let DelaySplit {
        g,
        gd,
        b_now,
        d_now,
    } = delay_split(m, x, d, &lin)?;

    let delays = lin.delays;
    // the register count bounded in floating point first (a delay of 1e300 s must not reach
    // the integer conversion below)
    let bound: f64 = delays.iter().map(|tau| (tau / ts).ceil() + 1.0).sum();
    if bound.is_nan() || bound > (MAX_REGISTERS + 2) as f64 {
        return Err(too_many_registers(ts));
    }
    let split = |tau: f64| -> (usize, f64) {
        // tau = l ts + rem, 0 <= rem < ts; a remainder within rounding of ts or 0 is snapped
        let l = (tau / ts).floor();
        let rem = tau - l * ts;
        let tol = 1e-9 * ts;
        if rem > ts - tol {
            ((l as usize) + 1, 0.0)
        } else if rem < tol {
            (l as usize, 0.0)
        } else {
            (l as usize, rem)
        }
    };
    let delay_samples = [split(delays[0]), split(delays[1])];
    // registers of channel q: u(k-1) .. u(k-L_q)
    let regs: Vec<usize> = delay_samples
        .iter()
        .map(|&(l, rem)| if rem > 0.0 { l + 1 } else { l })
        .collect();
    let nr: usize = regs.iter().sum();
    if nr > MAX_REGISTERS {
        return Err(too_many_registers(ts));
    }
    let nt = n + nr;
    let reg_index = |q: usize, i: usize| n + regs[..q].iter().sum::<usize>() + (i - 1);

    let vl = VanLoan::new(&lin.a, &lin.state_scales);
    let (phi0, gamma_now) = vl.sample(&b_now, &INPUT_SCALES, ts);
    let mut phi = DMatrix::zeros(nt, nt);
    let mut gamma = DMatrix::zeros(nt, 4);
    let mut c = DMatrix::zeros(p, nt);
    let mut dd = d_now.clone();
    phi.view_mut((0, 0), (n, n)).copy_from(&phi0);
    gamma.view_mut((0, 0), (n, 4)).copy_from(&gamma_now);
    c.view_mut((0, 0), (p, n)).copy_from(&lin.c);
    // u_q(k - j) enters: j = 0 -> the input column, j >= 1 -> register j
    let add = |phi: &mut DMatrix<f64>,
               gamma: &mut DMatrix<f64>,
               q: usize,
               j: usize,
               col: &nalgebra::DVector<f64>| {
        for r in 0..n {
            if j == 0 {
                gamma[(r, 1 + q)] += col[r];
            } else {
                phi[(r, reg_index(q, j))] += col[r];
            }
        }
    };
    for q in 0..2 {
        let (l, rem) = delay_samples[q];
        let gq = DMatrix::from_column_slice(n, 1, g.column(q).as_slice());
        // Gamma_0 over [0, ts - tau'] with u(k - l), Gamma_1 over the first tau' with u(k - l - 1)
        let sq = [INPUT_SCALES[1 + q]];
        let (e_rest, g0) = vl.sample(&gq, &sq, ts - rem);
        add(&mut phi, &mut gamma, q, l, &g0.column(0).into_owned());
        if rem > 0.0 {
            let (_, g1_head) = vl.sample(&gq, &sq, rem);
            let g1 = &e_rest * &g1_head;
            add(&mut phi, &mut gamma, q, l + 1, &g1.column(0).into_owned());
        }
        // outputs see the delayed command at k ts: u(k - l - 1) if tau' > 0, else u(k - l)
        let j_out = if rem > 0.0 { l + 1 } else { l };
        for o in 0..p {
            let v = gd[(o, q)];
            if v != 0.0 {
                if j_out == 0 {
                    dd[(o, 1 + q)] += v;
                } else {
                    c[(o, reg_index(q, j_out))] += v;
                }
            }
        }
        // shift register: r_1(k+1) = u(k), r_i(k+1) = r_{i-1}(k)
        for i in 1..=regs[q] {
            if i == 1 {
                gamma[(reg_index(q, 1), 1 + q)] = 1.0;
            } else {
                phi[(reg_index(q, i), reg_index(q, i - 1))] = 1.0;
            }
        }
    }

    let mut state_names = lin.state_names.clone();
    let mut state_scales = lin.state_scales.clone();
    for (q, name) in ["u_egr", "u_vgt"].iter().enumerate() {
        for i in 1..=regs[q] {
            state_names.push(format!("{name}(k-{i})"));
            state_scales.push(INPUT_SCALES[1 + q]);
        }
    }
    if let Some(v) = phi.iter().chain(gamma.iter()).find(|v| !v.is_finite()) {
        return Err(LinearizeError::NonFinite {
            what: "sampled model (Phi, Gamma)".into(),
            value: *v,
        });
    }
    Ok(DiscreteModel {
        ts,
        phi,
        gamma,
        c,
        d: dd,
        state_names,
        state_scales,
        input_names: lin.input_names.clone(),
        output_names: lin.output_names.clone(),
        delays,
        delay_samples,
        continuous: lin,
    })
}

fn too_many_registers(ts: f64) -> LinearizeError {
    LinearizeError::BadOption {
        field: "ts",
        value: ts,
        constraint: "too short for the parameter set's delays: more than 1000 delay registers \
                     (tau / ts summed over u_egr and u_vgt)",
    }
}

/// Zero-order-hold sampling of `dx/dt = A x + B u` by the exponential of the block matrix
/// [[A, B], [0, 0]] t (Van Loan), in the coordinates scaled by the states' typical magnitudes.
struct VanLoan<'a> {
    a: &'a DMatrix<f64>,
    scales: &'a [f64],
}

impl<'a> VanLoan<'a> {
    fn new(a: &'a DMatrix<f64>, scales: &'a [f64]) -> Self {
        Self { a, scales }
    }

    /// (e^(A t), int_0^t e^(A s) ds B) for `b` (n x m, columns in input units, whose typical
    /// magnitudes are `b_scales`).
    fn sample(&self, b: &DMatrix<f64>, b_scales: &[f64], t: f64) -> (DMatrix<f64>, DMatrix<f64>) {
        let n = self.a.nrows();
        let m = b.ncols();
        let s = self.scales;
        // scaled: A_s = S^-1 A S, B_s = S^-1 B U
        let mut big = DMatrix::zeros(n + m, n + m);
        for i in 0..n {
            for j in 0..n {
                big[(i, j)] = self.a[(i, j)] * s[j] / s[i] * t;
            }
            for j in 0..m {
                big[(i, n + j)] = b[(i, j)] * b_scales[j] / s[i] * t;
            }
        }
        let e = big.exp();
        let phi = DMatrix::from_fn(n, n, |i, j| e[(i, j)] * s[i] / s[j]);
        let gam = DMatrix::from_fn(n, m, |i, j| e[(i, n + j)] * s[i] / b_scales[j]);
        (phi, gam)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::steady::steady_state;
    use crate::model::Engine8;

    /// A scalar system x' = -a x + b u(t - tau) sampled by hand: the discrete model's step
    /// response equals the closed form at every sample.
    #[test]
    fn van_loan_matches_the_scalar_closed_form() {
        let a = DMatrix::from_element(1, 1, -3.0);
        let b = DMatrix::from_element(1, 1, 2.0);
        let vl = VanLoan::new(&a, &[1.0]);
        for t in [0.001, 0.01, 0.37, 2.0] {
            let (e, g) = vl.sample(&b, &[1.0], t);
            let e_ref: f64 = (-3.0 * t).exp();
            let g_ref = 2.0 * (1.0 - e_ref) / 3.0;
            assert!((e[(0, 0)] - e_ref).abs() < 1e-14, "{t}");
            assert!(
                (g[(0, 0)] - g_ref).abs() < 1e-14 * g_ref.abs().max(1.0),
                "{t}"
            );
        }
    }

    #[test]
    fn sample_time_and_pade_are_checked() {
        let m = Engine8::published();
        let d = Drive::from_array([1500.0, 110.0, 80.0, 75.0]);
        let ss = steady_state(&m, &d).unwrap();
        for ts in [0.0, -1.0, 1e-4, 1e3, f64::NAN] {
            let e = discretize(&m, &ss.x, &d, &LinearizeOptions::default(), ts).unwrap_err();
            assert!(e.to_string().contains("ts"), "{e}");
        }
        let o = LinearizeOptions {
            pade_order: 2,
            ..LinearizeOptions::default()
        };
        let e = discretize(&m, &ss.x, &d, &o, 0.01).unwrap_err();
        assert!(e.to_string().contains("pade_order"), "{e}");
        // long delays at a short sample time: refused before any large matrix is built
        let mut p = crate::params::Params::published();
        p.egr_actuator.tau_degr = 0.9;
        p.vgt_actuator.tau_dvgt = 0.2;
        let long = Engine8::new(p, crate::model::ModelOptions::default()).unwrap();
        let ss = steady_state(&long, &d).unwrap();
        let e = discretize(&long, &ss.x, &d, &LinearizeOptions::default(), 1e-3).unwrap_err();
        assert!(e.to_string().contains("1000 delay registers"), "{e}");
        // a delay of 1e300 s (the parameters only ask for >= 0): an error, not an overflow
        let mut p = crate::params::Params::published();
        p.vgt_actuator.tau_dvgt = 1e300;
        let huge = Engine8::new(p, crate::model::ModelOptions::default()).unwrap();
        let e = discretize(&huge, &ss.x, &d, &LinearizeOptions::default(), 100.0).unwrap_err();
        assert!(e.to_string().contains("1000 delay registers"), "{e}");
        let ok = discretize(&long, &ss.x, &d, &LinearizeOptions::default(), 0.01).unwrap();
        assert_eq!(ok.n_states(), 8 + 90 + 20);
    }
}
