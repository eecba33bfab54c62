//! Stability margins of discrete PI loops around the sampled linear model at an operating
//! point: the baseline controller's air-path loops (lambda_O -> u_egr, x_egr -> u_vgt) as a
//! control engineer checks them before a cycle (`mvem margins`, `docs/control.md`, "Loop
//! margins").
//!
//! The plant is the zero-order-hold model sampled at the controller's period with the actuator
//! delays exact ([`DiscreteModel`], `mvem linearize --ts`), so the loops are analysed as they
//! run: the controller reads the outputs at a sample and holds its commands until the next.
//! An output that reacts to a command within the sample (the actuators bypassed) is read with
//! the command held over the last interval (a register per such command). Each loop is the
//! discrete PI of [`super::pid::Pid`] (backward-Euler integral, no selector,
//! no saturation): with the error e_k = y_k - r_k,
//!
//! ```text
//! I_k = I_{k-1} + ki Ts e_k,   u_k = I_k + kp e_k,   K(z) = kp + ki Ts z / (z - 1)
//! ```
//!
//! With y = G u and u = K y (deviations, r = 0) the return ratio of a loop is L = -G K and the
//! closed loop's characteristic equation 1 + L = 0. Reported per loop, with the other loops
//! open (`alone`) and closed (`others_closed`, the plant the loop sees then:
//! h = g_ii + G_io (I - K_o G_oo)^-1 K_o G_oi):
//!
//! - gain margin: the factor on the loop's kp and ki at which the closed loop (a state-space
//!   matrix of the sampled plant and the PI integrals) gets a pole on the unit circle, found
//!   from its eigenvalues (exact for the linear sampled loop, whatever the Nyquist curve looks
//!   like), and the factor below 1 at which it does, if any (gain-reduction margin);
//! - phase margin at the gain crossover |L| = 1 (the smallest over crossovers), its frequency
//!   and the delay margin phase margin / omega_c;
//! - the peak of the sensitivity |1 / (1 + L)| and its frequency.
//!
//! Frequencies from [`F_MIN_HZ`] to just below the Nyquist frequency 1 / (2 Ts), the phase
//! followed along a grid fine enough for the delays.

use crate::analysis::discrete::DiscreteModel;
use crate::analysis::frequency::{follow_phase, log_grid};
use crate::analysis::zeros::eigenvalues;
use nalgebra::{Complex, DMatrix};

/// Lowest frequency of the loop analysis \[Hz\].
pub const F_MIN_HZ: f64 = 1e-4;
/// Points of the frequency grid (log-spaced).
pub const GRID_POINTS: usize = 4000;
/// Largest gain factor searched for a gain margin.
pub const GAIN_SEARCH_MAX: f64 = 1e4;

/// One discrete PI loop: the command `input` from the error y - r of `output`.
#[derive(Debug, Clone, PartialEq)]
pub struct PiLoop {
    /// A name for reports (`lambda_O->u_egr`).
    pub name: String,
    /// Command: one of the sampled model's input names.
    pub input: String,
    /// Controlled output: one of its output names.
    pub output: String,
    /// Proportional gain [input unit per output unit].
    pub kp: f64,
    /// Integral gain [input unit per output unit and second].
    pub ki: f64,
}

/// The margins of one loop.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopMargins {
    /// The loop's command moves none of the loops' outputs at this point, or no loop command
    /// moves its output (e.g. where no EGR flows): no feedback, nothing to analyse; the loop is
    /// left open in the other loops' figures and the other fields say so (stable, no margins,
    /// |1/(1+L)| = 1). In [`LoopAnalysis::alone`] also where only the loop's own channel is
    /// zero (x_egr at the shut EGR valve whatever the VGT does, while the valve moves it): by
    /// itself it has no feedback (its integral a pole at 1 nothing moves, not an
    /// instability); with the other loops closed it has, through them.
    pub inert: bool,
    /// Whether the closed loop (this loop, with the others open or closed as the field says) is
    /// stable at the nominal gains; the gain margins are `None` when it is not.
    pub stable: bool,
    /// Factor (> 1) on kp and ki at which the closed loop reaches the stability boundary; `None`
    /// when no factor up to [`GAIN_SEARCH_MAX`] does.
    pub gain_margin: Option<f64>,
    /// Factor (< 1) at which it does when the gains are lowered; `None`: stable down to 1e-4.
    pub gain_reduction_margin: Option<f64>,
    /// Frequency of the closed-loop poles on the unit circle at the gain margin \[Hz\].
    pub gain_margin_hz: Option<f64>,
    /// Phase margin \[deg\] (the smallest over the gain crossovers); `None`: |L| never crosses 1.
    pub phase_margin_deg: Option<f64>,
    /// Its gain-crossover frequency \[Hz\].
    pub gain_crossover_hz: Option<f64>,
    /// Extra loop delay the phase margin allows \[s\] (phase margin / omega_c).
    pub delay_margin_s: Option<f64>,
    /// Peak of |1 / (1 + L)| over the grid.
    pub peak_sensitivity: f64,
    /// Its frequency \[Hz\].
    pub peak_sensitivity_hz: f64,
}

/// The loops' margins at one operating point.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopAnalysis {
    /// Sample time \[s\].
    pub ts: f64,
    /// The loops analysed.
    pub loops: Vec<PiLoop>,
    /// Per loop, the other loops open.
    pub alone: Vec<LoopMargins>,
    /// Per loop, the other loops closed (as designed).
    pub others_closed: Vec<LoopMargins>,
    /// Largest |z| of the closed-loop poles with every loop closed (< 1: stable).
    pub max_pole_all: f64,
    /// The frequency grid \[Hz\].
    pub f_hz: Vec<f64>,
    /// Per loop, L(e^{j 2 pi f Ts}) with the other loops open, on the grid.
    pub l_alone: Vec<Vec<Complex<f64>>>,
    /// Per loop, L with the other loops closed.
    pub l_others_closed: Vec<Vec<Complex<f64>>>,
    /// Set by [`margins_at`]: the steady state's flags (those of `mvem steady`) when it is not
    /// physically valid (a guard saturation of the authors' implementation, lambda_O < 1, a
    /// state at an integrator limit, an unstable open-loop equilibrium), else empty. The
    /// margins are those of the linear model at that point all the same.
    pub steady_state_warnings: Vec<String>,
}

/// Why a loop analysis cannot be made.
#[derive(Debug, Clone, PartialEq)]
pub enum MarginsError {
    /// A loop names an input or output the sampled model does not have.
    UnknownChannel(String),
    /// A gain that is not a finite number.
    BadGain(String),
    /// No loop, or two loops on one command.
    BadLoops(String),
    /// The eigenvalues of a closed-loop matrix failed.
    Eigen(String),
}

impl std::fmt::Display for MarginsError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::UnknownChannel(s) | Self::BadGain(s) | Self::BadLoops(s) | Self::Eigen(s) => {
                f.write_str(s)
            }
        }
    }
}

impl std::error::Error for MarginsError {}

/// A sampled linear plant x_{k+1} = Phi x_k + Gamma u_k, y_k = C x_k + D u_k (the part of a
/// [`DiscreteModel`] the loop analysis uses; also for plants built by hand).
#[derive(Debug, Clone, PartialEq)]
pub struct SampledPlant {
    /// Sample time \[s\].
    pub ts: f64,
    /// State transition.
    pub phi: DMatrix<f64>,
    /// Input matrix.
    pub gamma: DMatrix<f64>,
    /// Output matrix.
    pub c: DMatrix<f64>,
    /// Feedthrough.
    pub d: DMatrix<f64>,
    /// Input names (columns of Gamma and D).
    pub input_names: Vec<String>,
    /// Output names (rows of C and D).
    pub output_names: Vec<String>,
    /// A typical magnitude of each state (the closed-loop matrix's eigenvalues are computed in
    /// the states divided by it: the same values, better conditioned); empty: all 1.
    pub state_scales: Vec<f64>,
}

impl SampledPlant {
    fn n_states(&self) -> usize {
        self.phi.nrows()
    }
}

impl From<&DiscreteModel> for SampledPlant {
    fn from(dm: &DiscreteModel) -> Self {
        Self {
            ts: dm.ts,
            phi: dm.phi.clone(),
            gamma: dm.gamma.clone(),
            c: dm.c.clone(),
            d: dm.d.clone(),
            input_names: dm.input_names.clone(),
            output_names: dm.output_names.clone(),
            state_scales: dm.state_scales.clone(),
        }
    }
}

/// Indices (input, output) of the loops in `dm`, checked.
fn channels(dm: &SampledPlant, loops: &[PiLoop]) -> Result<Vec<(usize, usize)>, MarginsError> {
    if loops.is_empty() {
        return Err(MarginsError::BadLoops("no loop given".into()));
    }
    let mut idx = Vec::with_capacity(loops.len());
    for l in loops {
        let i = dm
            .input_names
            .iter()
            .position(|n| *n == l.input)
            .ok_or_else(|| {
                MarginsError::UnknownChannel(format!(
                    "loop {}: input {:?} is not one of {}",
                    l.name,
                    l.input,
                    dm.input_names.join(", ")
                ))
            })?;
        let o = dm
            .output_names
            .iter()
            .position(|n| *n == l.output)
            .ok_or_else(|| {
                MarginsError::UnknownChannel(format!(
                    "loop {}: output {:?} is not one of the linearized outputs {}",
                    l.name,
                    l.output,
                    dm.output_names.join(", ")
                ))
            })?;
        if !(l.kp.is_finite() && l.ki.is_finite()) {
            return Err(MarginsError::BadGain(format!(
                "loop {}: kp {} and ki {} must be finite",
                l.name, l.kp, l.ki
            )));
        }
        if idx.iter().any(|&(j, _)| j == i) {
            return Err(MarginsError::BadLoops(format!(
                "loop {}: {} is the command of another loop",
                l.name, l.input
            )));
        }
        idx.push((i, o));
    }
    Ok(idx)
}

/// The closed-loop matrix of the sampled plant with the loops `active` closed, loop k's gains
/// times `scale[k]` (state: the plant's, then one PI integral per controlled output among the
/// active loops with ki != 0; a proportional-only loop has none, its constant integral being no
/// mode of the loop).
///
/// Loops that integrate the same output (a limiter and a main loop of two commands on one
/// measurement) have integrals I_m = (ki_m / ki_g) I_g + const of the group's first loop g
/// (they integrate the same error), so the group has one integral: the combinations that stay
/// constant (a pole at exactly z = 1 of the full realization, the set-points' conflict that the
/// selectors resolve, not a mode the loops move) are left out.
fn closed_loop_matrix(
    dm: &SampledPlant,
    loops: &[PiLoop],
    idx: &[(usize, usize)],
    active: &[usize],
    scale: &[f64],
) -> DMatrix<f64> {
    let n = dm.n_states();
    // the integral states: the first active loop with ki != 0 of each output
    let mut owners: Vec<usize> = Vec::new();
    for &k in active {
        if loops[k].ki != 0.0 && !owners.iter().any(|&g| idx[g].1 == idx[k].1) {
            owners.push(k);
        }
    }
    let m = owners.len();
    let ts = dm.ts;
    let mut a = DMatrix::zeros(n + m, n + m);
    a.view_mut((0, 0), (n, n)).copy_from(&dm.phi);
    for &k in active {
        let (i, o) = idx[k];
        let (kp, ki) = (loops[k].kp * scale[k], loops[k].ki * scale[k]);
        // the group's integral and this loop's share of it
        let q = (ki != 0.0)
            .then(|| owners.iter().position(|&g| idx[g].1 == o))
            .flatten();
        let share = q.map_or(0.0, |q| ki / (loops[owners[q]].ki * scale[owners[q]]));
        // u_k = share I_{g,k-1} + (kp + ki Ts) C_o x_k,  I_g,k = I_g,k-1 + ki_g Ts C_o x_k
        for r in 0..n {
            let g = dm.gamma[(r, i)];
            if g != 0.0 {
                for c in 0..n {
                    a[(r, c)] += g * (kp + ki * ts) * dm.c[(o, c)];
                }
                if let Some(q) = q {
                    a[(r, n + q)] += g * share;
                }
            }
        }
        if let Some(q) = q.filter(|&q| owners[q] == k) {
            for c in 0..n {
                a[(n + q, c)] = ki * ts * dm.c[(o, c)];
            }
            a[(n + q, n + q)] = 1.0;
        }
    }
    // in the scaled states (D^-1 A D: the same eigenvalues; the integrals in command units)
    let scale = |i: usize| {
        dm.state_scales
            .get(i)
            .copied()
            .filter(|s| s.is_finite() && *s > 0.0)
            .unwrap_or(1.0)
    };
    DMatrix::from_fn(n + m, n + m, |i, j| a[(i, j)] * scale(j) / scale(i))
}

/// Largest |z| (and the frequency of that pole \[Hz\]) of the closed loop.
fn max_pole(a: &DMatrix<f64>, ts: f64) -> Result<(f64, f64), MarginsError> {
    // the delay registers make the matrix defective (a nilpotent chain per delayed command),
    // where the real Schur iteration to machine precision can stall on their exact zeros: then
    // the same eigenvalues after an orthogonal similarity that fills them (a fixed pseudo-random
    // Q from a QR factorization), then looser tolerances (the decision |z| < 1 needs far less
    // than 1e-10)
    let ev = match eigenvalues(a) {
        Ok(ev) => ev,
        Err(first) => {
            let n = a.nrows();
            let mut seed = 0x9e37_79b9_7f4a_7c15u64;
            let r = DMatrix::from_fn(n, n, |_, _| {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            });
            let q = r.qr().q();
            let rotated = q.transpose() * a * &q;
            match eigenvalues(&rotated) {
                Ok(ev) => ev,
                Err(_) => [1e-14, 1e-12, 1e-10]
                    .iter()
                    .find_map(|&tol| {
                        nalgebra::linalg::Schur::try_new(rotated.clone(), tol, 200_000)
                            .map(|s| s.complex_eigenvalues().iter().copied().collect::<Vec<_>>())
                    })
                    .ok_or_else(|| MarginsError::Eigen(format!("closed-loop poles: {first}")))?,
            }
        }
    };
    Ok(ev
        .iter()
        .map(|z| (z.norm(), z.arg().abs() / (2.0 * std::f64::consts::PI * ts)))
        .fold((0.0, 0.0), |b, p| if p.0 > b.0 { p } else { b }))
}

/// The first factor along `factors` at which the closed loop with loop `k` scaled gets a pole
/// on or outside the unit circle, refined by bisection against the last stable factor.
fn boundary(
    stable_at: &dyn Fn(f64) -> Result<(bool, f64), MarginsError>,
    factors: impl Iterator<Item = f64>,
) -> Result<Option<(f64, f64)>, MarginsError> {
    let mut last = 1.0;
    for f in factors {
        if !stable_at(f)?.0 {
            let (mut ok, mut bad) = (last, f);
            for _ in 0..60 {
                let mid = (ok * bad).sqrt();
                if stable_at(mid)?.0 {
                    ok = mid;
                } else {
                    bad = mid;
                }
                if (bad / ok - 1.0).abs() < 1e-10 {
                    break;
                }
            }
            return Ok(Some((bad, stable_at(bad)?.1)));
        }
        last = f;
    }
    Ok(None)
}

/// The discrete PI's K(z) at z.
fn pi_at(l: &PiLoop, ts: f64, z: Complex<f64>) -> Complex<f64> {
    Complex::new(l.kp, 0.0) + z / (z - 1.0) * (l.ki * ts)
}

/// Margins of the loops `loops` around the sampled model `dm` (see the module).
pub fn loop_margins(dm: &DiscreteModel, loops: &[PiLoop]) -> Result<LoopAnalysis, MarginsError> {
    loop_margins_of(&SampledPlant::from(dm), loops)
}

/// The plant as the controller reads it: where a loop's output reacts to a loop's command
/// within the sample (D != 0: the actuators bypassed), the output measured at sample k is that
/// of the command held over the last interval, y_k = C x_k + D u_{k-1} (the controller measures,
/// then commands: `control::run`), so each such command gets a register v_k = u_{k-1}:
/// x+ = Phi x + Gamma u, v+ = u, y = C x + D v. Unchanged when every such D is 0.
fn as_measured(dm: &SampledPlant, idx: &[(usize, usize)]) -> SampledPlant {
    let held: Vec<usize> = idx
        .iter()
        .map(|&(i, _)| i)
        .filter(|&i| idx.iter().any(|&(_, o)| dm.d[(o, i)] != 0.0))
        .collect();
    if held.is_empty() {
        return dm.clone();
    }
    let (n, h) = (dm.n_states(), held.len());
    let mut phi = DMatrix::zeros(n + h, n + h);
    phi.view_mut((0, 0), (n, n)).copy_from(&dm.phi);
    let mut gamma = DMatrix::zeros(n + h, dm.gamma.ncols());
    gamma
        .view_mut((0, 0), (n, dm.gamma.ncols()))
        .copy_from(&dm.gamma);
    let mut c = DMatrix::zeros(dm.c.nrows(), n + h);
    c.view_mut((0, 0), (dm.c.nrows(), n)).copy_from(&dm.c);
    let mut d = dm.d.clone();
    let mut state_scales = dm.state_scales.clone();
    state_scales.resize(n, 1.0);
    for (q, &i) in held.iter().enumerate() {
        gamma[(n + q, i)] = 1.0;
        for o in 0..d.nrows() {
            c[(o, n + q)] = d[(o, i)];
            d[(o, i)] = 0.0;
        }
        state_scales.push(1.0);
    }
    SampledPlant {
        phi,
        gamma,
        c,
        d,
        state_scales,
        ..dm.clone()
    }
}

/// [`loop_margins`] of any sampled plant.
pub fn loop_margins_of(dm: &SampledPlant, loops: &[PiLoop]) -> Result<LoopAnalysis, MarginsError> {
    let idx = channels(dm, loops)?;
    let measured = as_measured(dm, &idx);
    let dm = &measured;
    let ts = dm.ts;
    let n_loops = loops.len();
    let nyquist = 0.5 / ts;
    // log-spaced up to just below the Nyquist frequency (z = -1 is a real point of L, reached
    // as the limit)
    let f_hi = nyquist * (1.0 - 1e-6);
    let f_hz = log_grid(F_MIN_HZ, f_hi, GRID_POINTS)
        .map_err(|e| MarginsError::BadLoops(format!("sample time {ts} s: {e}")))?;
    // G(z) on the grid: C (zI - Phi)^-1 Gamma + D, the loops' outputs x inputs
    let n = dm.n_states();
    let phi = dm.phi.map(|v| Complex::new(v, 0.0));
    let gam = DMatrix::from_fn(n, n_loops, |r, k| {
        Complex::new(dm.gamma[(r, idx[k].0)], 0.0)
    });
    let cc = DMatrix::from_fn(n_loops, n, |k, c| Complex::new(dm.c[(idx[k].1, c)], 0.0));
    let mut g_grid = Vec::with_capacity(f_hz.len());
    for &f in &f_hz {
        let z = Complex::from_polar(1.0, 2.0 * std::f64::consts::PI * f * ts);
        let m = DMatrix::from_diagonal_element(n, n, z) - &phi;
        let x = m.lu().solve(&gam).ok_or_else(|| {
            MarginsError::Eigen(format!(
                "zI - Phi singular at {f} Hz (a pole on the unit circle)"
            ))
        })?;
        g_grid.push((&cc * x, z));
    }
    // a loop whose command moves no loop output here, or whose output no loop command moves
    // (G's column or row exactly 0: the EGR valve without flow, x_egr = 0 whatever the VGT
    // does) has no feedback: left open (its PI integral would be a pole at 1 that no feedback
    // moves)
    let zero = Complex::new(0.0, 0.0);
    let inert: Vec<bool> = (0..n_loops)
        .map(|k| {
            let column = g_grid
                .iter()
                .all(|(g, _)| (0..n_loops).all(|j| g[(j, k)] == zero));
            let row = g_grid
                .iter()
                .all(|(g, _)| (0..n_loops).all(|j| g[(k, j)] == zero));
            column || row
        })
        .collect();
    let all: Vec<usize> = (0..n_loops).filter(|&k| !inert[k]).collect();
    let ones = vec![1.0; n_loops];
    let (max_pole_all, _) = max_pole(&closed_loop_matrix(dm, loops, &idx, &all, &ones), ts)?;
    let mut alone = Vec::with_capacity(n_loops);
    let mut others_closed = Vec::with_capacity(n_loops);
    let mut l_alone = Vec::with_capacity(n_loops);
    let mut l_others = Vec::with_capacity(n_loops);
    for k in 0..n_loops {
        if inert[k] {
            let m = LoopMargins::inert(f_hz[0]);
            alone.push(m.clone());
            others_closed.push(m);
            l_alone.push(vec![Complex::new(0.0, 0.0); f_hz.len()]);
            l_others.push(vec![Complex::new(0.0, 0.0); f_hz.len()]);
            continue;
        }
        let others: Vec<usize> = all.iter().copied().filter(|&j| j != k).collect();
        // L alone: -g_kk K_k; others closed: -K_k (g_kk + G_ko (I - K_o G_oo)^-1 K_o G_ok)
        let mut la = Vec::with_capacity(f_hz.len());
        let mut lo = Vec::with_capacity(f_hz.len());
        for (g, z) in &g_grid {
            let kk = pi_at(&loops[k], ts, *z);
            la.push(-g[(k, k)] * kk);
            let h = if others.is_empty() {
                g[(k, k)]
            } else {
                let no = others.len();
                let ko = DMatrix::from_fn(no, no, |a, b| {
                    if a == b {
                        pi_at(&loops[others[a]], ts, *z)
                    } else {
                        Complex::new(0.0, 0.0)
                    }
                });
                let goo = DMatrix::from_fn(no, no, |a, b| g[(others[a], others[b])]);
                let gko = DMatrix::from_fn(1, no, |_, b| g[(k, others[b])]);
                let gok = DMatrix::from_fn(no, 1, |a, _| g[(others[a], k)]);
                let m = DMatrix::identity(no, no) - &ko * &goo;
                match m.lu().solve(&(&ko * &gok)) {
                    Some(v) => g[(k, k)] + (gko * v)[(0, 0)],
                    None => Complex::new(f64::NAN, f64::NAN),
                }
            };
            lo.push(-h * kk);
        }
        // alone, a loop whose command does not move its own output here (x_egr at the shut
        // EGR valve whatever the VGT does, while the valve still moves x_egr) has no feedback:
        // inert by itself (its PI integral a pole at 1 that nothing moves, not an instability),
        // its feedback only through the other loops
        let alone_inert = g_grid.iter().all(|(g, _)| g[(k, k)] == zero);
        for (set, l, out, no_feedback) in [
            (vec![k], &la, &mut alone, alone_inert),
            (
                all.clone(),
                &lo,
                &mut others_closed,
                alone_inert && others.is_empty(),
            ),
        ] {
            if no_feedback {
                out.push(LoopMargins::inert(f_hz[0]));
                continue;
            }
            let stable_at = |s: f64| -> Result<(bool, f64), MarginsError> {
                let mut sc = ones.clone();
                sc[k] = s;
                let (r, f) = max_pole(&closed_loop_matrix(dm, loops, &idx, &set, &sc), ts)?;
                Ok((r < 1.0, f))
            };
            let stable = stable_at(1.0)?.0;
            let (up, down) = if stable {
                let ups = (1..).map(|j| 1.05f64.powi(j));
                let downs = (1..).map(|j| 1.05f64.powi(-j));
                (
                    boundary(&stable_at, ups.take_while(|&f| f <= GAIN_SEARCH_MAX))?,
                    boundary(
                        &stable_at,
                        downs.take_while(|&f| f >= 1.0 / GAIN_SEARCH_MAX),
                    )?,
                )
            } else {
                (None, None)
            };
            out.push(margins_of(&f_hz, l, stable, up, down));
        }
        l_alone.push(la);
        l_others.push(lo);
    }
    Ok(LoopAnalysis {
        ts,
        loops: loops.to_vec(),
        alone,
        others_closed,
        max_pole_all,
        f_hz,
        l_alone,
        l_others_closed: l_others,
        steady_state_warnings: Vec::new(),
    })
}

impl LoopMargins {
    /// The figures of a loop without feedback ([`Self::inert`]): stable, no margins,
    /// |1/(1+L)| = 1 at the grid's first frequency `f0_hz` \[Hz\].
    fn inert(f0_hz: f64) -> Self {
        Self {
            inert: true,
            stable: true,
            gain_margin: None,
            gain_reduction_margin: None,
            gain_margin_hz: None,
            phase_margin_deg: None,
            gain_crossover_hz: None,
            delay_margin_s: None,
            peak_sensitivity: 1.0,
            peak_sensitivity_hz: f0_hz,
        }
    }
}

/// The frequency-domain figures of one return ratio and the gain margins found.
fn margins_of(
    f_hz: &[f64],
    l: &[Complex<f64>],
    stable: bool,
    up: Option<(f64, f64)>,
    down: Option<(f64, f64)>,
) -> LoopMargins {
    // phase [rad] followed along the grid (as the frequency responses' phases)
    let mut phase = Vec::with_capacity(l.len());
    let mut prev: Option<f64> = None;
    for &v in l {
        let p = follow_phase(prev, v);
        phase.push(p.to_radians());
        prev = Some(p);
    }
    let mut pm: Option<(f64, f64)> = None;
    for k in 1..l.len() {
        let (a, b) = (l[k - 1].norm(), l[k].norm());
        if (a - 1.0) * (b - 1.0) <= 0.0 && a != b && a.is_finite() && b.is_finite() {
            // crossing interpolated in log |L| over log f
            let w = (0.0 - a.ln()) / (b.ln() - a.ln());
            let f = (f_hz[k - 1].ln() + w * (f_hz[k].ln() - f_hz[k - 1].ln())).exp();
            let ph = phase[k - 1] + w * (phase[k] - phase[k - 1]);
            let m = (ph + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI);
            let m = if m > std::f64::consts::PI {
                m - 2.0 * std::f64::consts::PI
            } else {
                m
            };
            if pm.is_none_or(|(p, _)| m < p) {
                pm = Some((m, f));
            }
        }
    }
    let (ms, ms_f) = l
        .iter()
        .zip(f_hz)
        .map(|(v, &f)| ((Complex::new(1.0, 0.0) + v).inv().norm(), f))
        .fold((0.0, 0.0), |b, p| if p.0 > b.0 { p } else { b });
    LoopMargins {
        inert: false,
        stable,
        gain_margin: up.map(|u| u.0),
        gain_reduction_margin: down.map(|d| d.0),
        gain_margin_hz: up.map(|u| u.1),
        phase_margin_deg: pm.map(|p| p.0.to_degrees()),
        gain_crossover_hz: pm.map(|p| p.1),
        delay_margin_s: pm.map(|(p, f)| p / (2.0 * std::f64::consts::PI * f)),
        peak_sensitivity: ms,
        peak_sensitivity_hz: ms_f,
    }
}

/// The baseline controller's two main air-path loops ([`super::baseline`]): lambda_O -> u_egr
/// and x_egr -> u_vgt with their PI gains, each at its gain schedule's factor for the operating
/// point's commands `d` in the engine's command ranges `limits` (the parameter set's
/// `input_saturation`; the limiters, selectors and saturations are not part of the linear
/// analysis).
pub fn baseline_loops(
    t: &super::baseline::BaselineTuning,
    d: &crate::model::Drive,
    limits: &crate::params::InputSaturation,
) -> Vec<PiLoop> {
    use super::InCharge::Main;
    super::along::loops_in_charge(t, Some(Main), Some(Main), d, limits)
}

/// The sampled model of `m` at its steady state for the constant inputs `d`, at the sample
/// time `ts`, with the outputs the loops control (lambda_O, x_egr), and the margins of `loops`
/// around it (with the steady state's flags in `steady_state_warnings` when it is not
/// physically valid). A kink of the model at the point (a saturation or switch whose one-sided
/// derivatives differ) is an error when it lies in the direction of a state or of a loop's
/// command; one in the direction of an input no loop uses (n_e at the end of its range) is not.
pub fn margins_at<const N: usize, M: crate::model::Model<N>>(
    m: &M,
    d: &crate::model::Drive,
    loops: &[PiLoop],
    ts: f64,
) -> Result<(DiscreteModel, LoopAnalysis), String> {
    use crate::analysis::{
        discrete::discretize, linearize::LinearizeOptions, steady::steady_state,
    };
    let ss = steady_state(m, d).map_err(|e| e.to_string())?;
    let mut outputs: Vec<String> = Vec::new();
    for l in loops {
        if !outputs.contains(&l.output) {
            outputs.push(l.output.clone());
        }
    }
    // kinks are checked below: one in a direction no loop uses (n_e at its saturation limit,
    // u_delta) leaves the loops' linear model exact
    let opts = LinearizeOptions {
        outputs,
        strict: false,
        ..LinearizeOptions::default()
    };
    let dm = discretize(m, &ss.x, d, &opts, ts).map_err(|e| e.to_string())?;
    // the actuator states of a command no loop moves (u_egr1, u_egr2 of u_egr; u_vgt_act of
    // u_vgt, eqs. (40), (57)) are driven by that held command alone: no loop excites them, so
    // a kink in their direction (the EGR valve closed, f_egr >= 0) leaves the loops' transfer
    // functions and the closed loop's poles exact (the actuator block is autonomous)
    let unused = |v: &str| {
        let input = match v.split('(').next().unwrap_or(v) {
            "u_egr1" | "u_egr2" => "u_egr",
            "u_vgt_act" => "u_vgt",
            other => other,
        };
        ["n_e", "u_delta", "u_egr", "u_vgt"].contains(&input)
            && !loops.iter().any(|l| l.input == input)
    };
    if let Some(k) = dm.continuous.kinks.iter().find(|k| !unused(&k.variable)) {
        return Err(format!(
            "the operating point sits at a kink of the model that the loops see: {k}; the \
             derivative is one-sided there"
        ));
    }
    let mut a = loop_margins(&dm, loops).map_err(|e| e.to_string())?;
    if !ss.physically_valid() {
        a.steady_state_warnings = ss.flags.clone();
    }
    Ok((dm, a))
}

/// The report of `mvem margins --json` (and of Python's `loop_margins`, the explorer's
/// `POST /api/margins`): [`loop_analysis_json`] plus `"operating_point"` {n_e, u_delta, u_egr,
/// u_vgt} and `"model_states"`.
pub fn margins_report_json(
    d: &crate::model::Drive,
    model_states: usize,
    a: &LoopAnalysis,
) -> serde_json::Value {
    let mut v = loop_analysis_json(a);
    v["operating_point"] = serde_json::json!({
        "n_e": d.n_e_rpm, "u_delta": d.u_delta_mg, "u_egr": d.u_egr_pct, "u_vgt": d.u_vgt_pct,
    });
    v["model_states"] = serde_json::json!(model_states);
    v
}

/// One loop's margins as JSON (`mvem margins --json`): the fields of [`LoopMargins`] by name,
/// plus `gain_margin_db` (20 log10 of the gain margin); `null` where a figure does not exist.
pub fn loop_margins_json(m: &LoopMargins) -> serde_json::Value {
    serde_json::json!({
        "inert": m.inert,
        "stable": m.stable,
        "gain_margin": m.gain_margin,
        "gain_margin_db": m.gain_margin.map(|g| 20.0 * g.log10()),
        "gain_margin_hz": m.gain_margin_hz,
        "gain_reduction_margin": m.gain_reduction_margin,
        "phase_margin_deg": m.phase_margin_deg,
        "gain_crossover_hz": m.gain_crossover_hz,
        "delay_margin_s": m.delay_margin_s,
        "peak_sensitivity": m.peak_sensitivity,
        "peak_sensitivity_hz": m.peak_sensitivity_hz,
    })
}

/// The analysis as JSON: `"ts"`, `"stable"` (every loop closed), `"max_pole_all"`,
/// `"steady_state_warnings"` (the flags of a physically invalid steady state, else empty) and
/// per loop `{"name", "input", "output", "kp", "ki", "alone", "others_closed"}`.
pub fn loop_analysis_json(a: &LoopAnalysis) -> serde_json::Value {
    serde_json::json!({
        "ts": a.ts,
        "stable": a.max_pole_all < 1.0,
        "max_pole_all": a.max_pole_all,
        "steady_state_warnings": a.steady_state_warnings,
        "loops": a.loops.iter().enumerate().map(|(k, l)| serde_json::json!({
            "name": l.name,
            "input": l.input,
            "output": l.output,
            "kp": l.kp,
            "ki": l.ki,
            "alone": loop_margins_json(&a.alone[k]),
            "others_closed": loop_margins_json(&a.others_closed[k]),
        })).collect::<Vec<_>>(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x+ = phi x + gamma u, y = c x + d u, sampled every 10 ms.
    fn scalar(phi: f64, gamma: f64, c: f64, d: f64) -> SampledPlant {
        SampledPlant {
            ts: 0.01,
            phi: DMatrix::from_element(1, 1, phi),
            gamma: DMatrix::from_element(1, 1, gamma),
            c: DMatrix::from_element(1, 1, c),
            d: DMatrix::from_element(1, 1, d),
            input_names: vec!["u".into()],
            output_names: vec!["y".into()],
            state_scales: Vec::new(),
        }
    }

    /// The loop u = kp y (+ ki) on the scalar plant's channel.
    fn p_loop(kp: f64, ki: f64) -> PiLoop {
        PiLoop {
            name: "y->u".into(),
            input: "u".into(),
            output: "y".into(),
            kp,
            ki,
        }
    }

    /// x+ = 0.9 x + 0.1 u, y = x, P control u = kp y with kp = -2: the closed-loop pole
    /// 0.9 + 0.1 kp a (a the gain factor) leaves the unit circle at a = 9.5 (z = -1); never for
    /// a < 1; L = 0.2 / (z - 0.9) crosses |L| = 1 where cos theta = 1.77 / 1.8, phase margin
    /// 180 deg - arg(e^{j theta} - 0.9).
    #[test]
    fn first_order_plant_with_p_control_has_the_analytic_margins() {
        let ts = 0.01;
        let a = loop_margins_of(&scalar(0.9, 0.1, 1.0, 0.0), &[p_loop(-2.0, 0.0)]).unwrap();
        assert!((a.max_pole_all - 0.7).abs() < 1e-12);
        let m = &a.alone[0];
        assert!(m.stable);
        assert!((m.gain_margin.unwrap() / 9.5 - 1.0).abs() < 1e-8, "{m:?}");
        assert!((m.gain_margin_hz.unwrap() - 0.5 / ts).abs() < 1e-6, "{m:?}");
        assert_eq!(m.gain_reduction_margin, None);
        let theta = (1.77f64 / 1.8).acos();
        let pm = 180.0
            - Complex::new(theta.cos() - 0.9, theta.sin())
                .arg()
                .to_degrees();
        assert!(
            (m.phase_margin_deg.unwrap() - pm).abs() < 1e-3,
            "{m:?} against {pm}"
        );
        let fc = theta / (2.0 * std::f64::consts::PI * ts);
        assert!(
            (m.gain_crossover_hz.unwrap() / fc - 1.0).abs() < 1e-4,
            "{m:?}"
        );
        // one loop: the others-closed figures are the same loop
        assert_eq!(a.alone[0], a.others_closed[0]);
        // |1 / (1 + L)| peaks at z = -1 (L = -0.2 / 1.9)
        assert!(
            (m.peak_sensitivity - 1.0 / (1.0 - 0.2 / 1.9)).abs() < 1e-6,
            "{m:?}"
        );
    }

    /// Two PI loops on one output y of x+ = 0.9 x + 0.1 u1 + 0.05 u2 integrate the same error:
    /// with one integral each the closed loop would have a pole at exactly 1 (a constant
    /// combination of the integrals); with the group's one integral the pair is the single loop
    /// u = 0.1 K1 + 0.05 K2 through a unit input, and its poles, gain margins and the factor
    /// on one loop at the boundary are that loop's.
    #[test]
    fn loops_on_one_output_share_one_integral() {
        let plant = SampledPlant {
            gamma: DMatrix::from_row_slice(1, 2, &[0.1, 0.05]),
            d: DMatrix::zeros(1, 2),
            input_names: vec!["u1".into(), "u2".into()],
            ..scalar(0.9, 0.1, 1.0, 0.0)
        };
        let pi = |input: &str, kp: f64, ki: f64| PiLoop {
            name: input.into(),
            input: input.into(),
            output: "y".into(),
            kp,
            ki,
        };
        let (l1, l2) = (pi("u1", -2.0, -30.0), pi("u2", -3.0, -20.0));
        let pair = loop_margins_of(&plant, &[l1.clone(), l2.clone()]).unwrap();
        let single = |f1: f64| {
            let kp = 0.1 * f1 * l1.kp + 0.05 * l2.kp;
            let ki = 0.1 * f1 * l1.ki + 0.05 * l2.ki;
            loop_margins_of(&scalar(0.9, 1.0, 1.0, 0.0), &[p_loop(kp, ki)]).unwrap()
        };
        let s = single(1.0);
        assert!(pair.max_pole_all < 1.0, "{}", pair.max_pole_all);
        assert!((pair.max_pole_all - s.max_pole_all).abs() < 1e-12);
        // loop 1's gain margin with loop 2 closed: the single loop with f1 = gm is at the boundary
        let gm = pair.others_closed[0].gain_margin.unwrap();
        let r = |f: f64| single(f).max_pole_all;
        assert!(
            r(gm * (1.0 - 1e-6)) < 1.0 && r(gm * (1.0 + 1e-6)) >= 1.0,
            "{gm}"
        );
    }

    #[test]
    fn bad_loops_are_named() {
        let plant = scalar(0.5, 1.0, 1.0, 0.3);
        let lp = |input: &str, output: &str, kp: f64| PiLoop {
            name: "l".into(),
            input: input.into(),
            output: output.into(),
            kp,
            ki: 1.0,
        };
        let e = |l: Vec<PiLoop>| loop_margins_of(&plant, &l).unwrap_err().to_string();
        assert!(e(vec![]).contains("no loop"));
        assert!(e(vec![lp("v", "y", 1.0)]).contains("input \"v\""));
        assert!(e(vec![lp("u", "z", 1.0)]).contains("output \"z\""));
        assert!(e(vec![lp("u", "y", f64::NAN)]).contains("finite"));
        assert!(e(vec![lp("u", "y", 1.0), lp("u", "y", 2.0)]).contains("another loop"));
    }

    /// A static plant y_k = 0.3 u_{k-1} (D = 0.3: the controller reads the command held over the
    /// last interval) with u = kp y, kp = -1: the pole kp 0.3 = -0.3; it reaches -1 at the gain
    /// factor 1 / 0.3 (the Nyquist frequency); |L| = 0.3 never crosses 1.
    #[test]
    fn direct_feedthrough_acts_through_the_held_command() {
        let a = loop_margins_of(&scalar(0.0, 0.0, 0.0, 0.3), &[p_loop(-1.0, 0.0)]).unwrap();
        assert!((a.max_pole_all - 0.3).abs() < 1e-12, "{}", a.max_pole_all);
        let m = &a.alone[0];
        assert!((m.gain_margin.unwrap() * 0.3 - 1.0).abs() < 1e-8, "{m:?}");
        assert!((m.gain_margin_hz.unwrap() - 50.0).abs() < 1e-6, "{m:?}");
        assert_eq!(m.phase_margin_deg, None);
        assert!(a.l_alone[0].iter().all(|l| (l.norm() - 0.3).abs() < 1e-12));
    }
}
