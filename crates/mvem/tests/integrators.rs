//! The integrators on ODEs with known solutions, through the simulator's [`Dynamics`] trait
//! (which every engine model implements through `Model`; as diffsol and DifferentialEquations.jl
//! test their solvers on shared problems): a linear stiff system, Prothero-Robinson, a delayed,
//! input-driven linear lag (closed form and W-method), and the convergence order of the four
//! methods (ROS34PW2, RODAS4, exprb32, DOPRI5) with the step size pinned by `h_max`, RODAS4 and
//! exprb32 also on a non-autonomous problem (their f_t term along the input slopes), and
//! ROS34PW2's optional f_t term on a stiff problem whose input slope jumps every 0.1 s.
//!
//! The toy models have no engine parameters and no model options at all (they implement
//! `Dynamics`, not `Model`), so the simulator cannot read any. Their memory is `()`.

use mvem::model::{
    Drive, Dynamics, Evaluation, InputDelays, LagCommand, LinearLag, ModelInput, Signals,
};
use mvem::sim::{simulate, stop_times, InputSchedule, Method, SimOptions, Solution, Start};

/// Right-hand side of a toy ODE: `dx/dt = f(x, inputs, k)` with a problem constant `k`.
type Rhs<const N: usize> = fn(&[f64; N], &ModelInput, f64) -> [f64; N];

/// A toy ODE behind the simulator's [`Dynamics`] trait.
#[derive(Clone)]
struct Toy<const N: usize> {
    f: Rhs<N>,
    k: f64,
    names: [&'static str; N],
    delays: InputDelays,
    lags: Vec<LinearLag>,
}

impl<const N: usize> Toy<N> {
    fn new(f: Rhs<N>, k: f64, names: [&'static str; N]) -> Self {
        Self {
            f,
            k,
            names,
            delays: InputDelays {
                delayed: [0.0, 0.0],
                current: [true; 4],
            },
            lags: Vec::new(),
        }
    }
}

impl<const N: usize> Dynamics<N> for Toy<N> {
    type Memory = ();
    fn state_names(&self) -> [&'static str; N] {
        self.names
    }
    fn state_scales(&self) -> [f64; N] {
        [1.0; N]
    }
    fn state_bounds(&self) -> [(f64, f64); N] {
        [(f64::NEG_INFINITY, f64::INFINITY); N]
    }
    fn eval(&self, x: &[f64; N], u: &ModelInput, _memory: ()) -> Evaluation<N, ()> {
        Evaluation {
            dx: (self.f)(x, u, self.k),
            signals: Signals::default(),
            memory_next: (),
        }
    }
    fn input_delays(&self) -> InputDelays {
        self.delays
    }
    fn linear_lags(&self) -> Vec<LinearLag> {
        self.lags.clone()
    }
    fn memory_start(&self, _x: &[f64; N], _u: &ModelInput) {}
}

/// Channel 0 (n_e) carries the time itself: a ramp with no interior breakpoint.
fn time_ramp(t_end: f64) -> InputSchedule {
    InputSchedule::new(vec![0.0, t_end], vec![[0.0; 4], [t_end, 0.0, 0.0, 0.0]]).unwrap()
}

fn run<const N: usize>(
    m: &Toy<N>,
    sched: &InputSchedule,
    t_end: f64,
    y0: [f64; N],
    opts: &SimOptions,
) -> Solution {
    simulate(m, sched, 0.0, t_end, Start::State(y0), opts).unwrap()
}

fn opts(method: Method, tol: f64) -> SimOptions {
    SimOptions {
        rtol: tol,
        atol: tol,
        method,
        ..SimOptions::default()
    }
}

/// Max over the output samples of |y_i(t) - exact_i(t)|.
fn max_error<const N: usize>(
    sol: &Solution,
    names: [&str; N],
    exact: impl Fn(f64) -> [f64; N],
) -> f64 {
    let t = sol.t();
    let mut e: f64 = 0.0;
    for (i, name) in names.iter().enumerate() {
        let y = sol.get(name).unwrap();
        for (tk, yk) in t.iter().zip(y) {
            e = e.max((yk - exact(*tk)[i]).abs());
        }
    }
    e
}

// ---------------------------------------------------------------------------------------------
// linear stiff system

/// y' = A y, A = [[-2, 1], [998, -999]] (eigenvalues -1 and -1000; eigenvectors (1, 1) and
/// (1, -998)).
fn stiff_linear(x: &[f64; 2], _u: &ModelInput, _k: f64) -> [f64; 2] {
    [-2.0 * x[0] + x[1], 998.0 * x[0] - 999.0 * x[1]]
}

/// From y(0) = (2, -997): y = e^-t (1, 1) + e^-1000t (1, -998).
fn stiff_linear_exact(t: f64) -> [f64; 2] {
    let (a, b) = ((-t).exp(), (-1000.0 * t).exp());
    [a + b, a - 998.0 * b]
}

#[test]
fn linear_stiff_system_both_methods() {
    let m = Toy::new(stiff_linear, 0.0, ["y1", "y2"]);
    let sched = InputSchedule::constant(Drive::new(0.0, 0.0, 0.0, 0.0));
    for method in [
        Method::Rosenbrock34,
        Method::Rodas4,
        Method::Exprb32,
        Method::Dopri5,
    ] {
        let sol = run(&m, &sched, 5.0, [2.0, -997.0], &opts(method, 1e-7));
        let e = max_error(&sol, ["y1", "y2"], stiff_linear_exact);
        eprintln!("{method:?}: max error {e:.2e}, {:?}", sol.stats);
        // global error at the output samples within a few tolerances of the solution's scale
        // (|y2| ~ 1e3 in the transient; 1 afterwards)
        assert!(e < 1e-5, "{method:?}: max error {e:.2e}");
    }
    // At a loose tolerance the L-stable Rosenbrock methods follow the slow mode with large
    // steps; the explicit pair stays stability-limited (|h lambda| <= 3.3 with lambda = -1000
    // over 5 s: >= 1500 steps).
    let steps = [
        Method::Rosenbrock34,
        Method::Rodas4,
        Method::Exprb32,
        Method::Dopri5,
    ]
    .map(|method| {
        run(&m, &sched, 5.0, [2.0, -997.0], &opts(method, 1e-3))
            .stats
            .steps
    });
    eprintln!("steps at tolerance 1e-3: {steps:?}");
    assert!(steps[0] < 100, "ROS34PW2 steps {}", steps[0]);
    assert!(steps[1] < 100, "RODAS4 steps {}", steps[1]);
    // exprb32 integrates a linear autonomous system exactly (D2 = 0 up to rounding and the
    // finite-difference Jacobian): its step grows by the controller's factor 5 per step
    assert!(steps[2] < 20, "exprb32 steps {}", steps[2]);
    assert!(steps[3] > 1500, "DOPRI5 steps {}", steps[3]);
}

// ---------------------------------------------------------------------------------------------
// Prothero-Robinson

/// y' = lambda (y - g(t)) + g'(t), g = sin: y = sin t from y(0) = 0 for every lambda; the time
/// comes in on channel 0.
fn prothero_robinson(x: &[f64; 1], u: &ModelInput, lambda: f64) -> [f64; 1] {
    let t = u.now.n_e_rpm;
    [lambda * (x[0] - t.sin()) + t.cos()]
}

#[test]
fn prothero_robinson_stiff_and_nonstiff() {
    let t_end = 10.0;
    let sched = time_ramp(t_end);
    let exact = |t: f64| [t.sin()];
    // very stiff: the W-method (L-stable, stiffly accurate) is accurate at step sizes set by
    // g alone
    let m = Toy::new(prothero_robinson, -1e6, ["y"]);
    for method in [Method::Rosenbrock34, Method::Rodas4, Method::Exprb32] {
        let mut o = opts(method, 1e-6);
        if method == Method::Rodas4 {
            // RODAS4's continuous extension (order 3 for non-stiff components) does not follow a
            // stiff component between the step ends: with its steps of about 1 s here it is off
            // by 0.17 between them, while the step ends are within 1.4e-7 (docs/integrator.md)
            o.dt_out = t_end;
        }
        let sol = run(&m, &sched, t_end, [0.0], &o);
        let e = max_error(&sol, ["y"], exact);
        eprintln!(
            "{method:?}, lambda -1e6: max error {e:.2e}, {:?}",
            sol.stats
        );
        assert!(e < 1e-5, "{method:?}: max error {e:.2e}");
        // exprb32's error estimate is its embedded exponential Rosenbrock-Euler step's error,
        // which here is h^2 sin(t) / 2 (2 h phi_3(h lambda) D2 with D2 ~ lambda h^2 sin(t) / 2
        // and phi_3(z) ~ -1/(2z)) whatever lambda: its steps are limited to about sqrt(2 tol)
        // while the solution is far more accurate (8e-8 with 4 779 steps)
        let max_steps = if method == Method::Exprb32 { 6000 } else { 500 };
        assert!(sol.stats.steps < max_steps, "{method:?}: {:?}", sol.stats);
        assert!(sol.stats.rejected < 50, "{method:?}: {:?}", sol.stats);
    }
    // mildly stiff, all methods
    let m = Toy::new(prothero_robinson, -100.0, ["y"]);
    for method in [
        Method::Rosenbrock34,
        Method::Rodas4,
        Method::Exprb32,
        Method::Dopri5,
    ] {
        let sol = run(&m, &sched, t_end, [0.0], &opts(method, 1e-8));
        let e = max_error(&sol, ["y"], exact);
        eprintln!(
            "{method:?}, lambda -100: max error {e:.2e}, {:?}",
            sol.stats
        );
        assert!(e < 1e-7, "{method:?}: max error {e:.2e}");
    }
}

// ---------------------------------------------------------------------------------------------
// delayed, input-driven linear lag

const LAG_TAU: f64 = 0.5;
const LAG_DELAY: f64 = 0.3;

/// y' = (u(t - tau_d) - y) / tau with u on channel 2, delayed by tau_d.
fn delayed_lag(x: &[f64; 1], u: &ModelInput, tau: f64) -> [f64; 1] {
    [(u.u_egr_delayed - x[0]) / tau]
}

/// u steps 0 -> 1 at t = 1: y = 0 before 1 + tau_d, then 1 - exp(-(t - 1 - tau_d) / tau).
fn delayed_lag_exact(t: f64) -> [f64; 1] {
    let s = t - 1.0 - LAG_DELAY;
    [if s <= 0.0 {
        0.0
    } else {
        -(-s / LAG_TAU).exp_m1()
    }]
}

/// A closed-form lag at state 0 of 5 (not trailing: the iteration matrix is the masked 5 x 5,
/// not a leading block) beside four decays that do not see it: the lag state must not enter
/// the W-method's error estimate, so the decays take exactly the steps they take when state 0
/// is a constant instead. (Until session 20 the 5-, 7- and 9-state systems took the
/// leading-block path unmasked: 162 steps instead of 89 here, the lag's stage increments in the
/// error estimate; the solution was right, the lag's values being exact.)
#[test]
fn leading_closed_form_lag_leaves_the_other_states_steps_alone() {
    fn with_lag(x: &[f64; 5], u: &ModelInput, tau: f64) -> [f64; 5] {
        [
            (u.u_egr_delayed - x[0]) / tau,
            -x[1],
            -2.0 * x[2],
            -3.0 * x[3],
            -4.0 * x[4],
        ]
    }
    fn constant(x: &[f64; 5], _u: &ModelInput, _k: f64) -> [f64; 5] {
        [0.0, -x[1], -2.0 * x[2], -3.0 * x[3], -4.0 * x[4]]
    }
    let names = ["a", "y1", "y2", "y3", "y4"];
    let mut lagged = Toy::new(with_lag, 0.05, names);
    lagged.delays = InputDelays {
        delayed: [0.0, 0.0],
        current: [false; 4],
    };
    lagged.lags = vec![LinearLag {
        state: 0,
        tau: 0.05,
        command: LagCommand::Egr,
        saturation: (f64::NEG_INFINITY, f64::INFINITY),
    }];
    let plain = Toy::new(constant, 0.0, names);
    // the lag's command is 0, then ramps to 100 over [1, 2] (its state moves, its derivative is
    // large); 0 at the start, so that the initial step size (from f at the start) is the same
    let sched = InputSchedule::new(
        vec![0.0, 1.0, 2.0],
        vec![[0.0; 4], [0.0; 4], [0.0, 0.0, 100.0, 0.0]],
    )
    .unwrap();
    let y0 = [0.0, 1.0, 1.0, 1.0, 1.0];
    let o = opts(Method::Rosenbrock34, 1e-6);
    let a = run(&lagged, &sched, 2.0, y0, &o);
    let b = run(&plain, &sched, 2.0, y0, &o);
    assert!(a.stats.steps > 5, "{:?}", a.stats);
    assert_eq!(
        (a.stats.steps, a.stats.rejected),
        (b.stats.steps, b.stats.rejected),
        "lagged {:?}, plain {:?}",
        a.stats,
        b.stats
    );
    for name in &names[1..] {
        assert_eq!(a.get(name).unwrap(), b.get(name).unwrap(), "{name}");
    }
    // and the lag follows its ramp exactly: 100 (s - tau (1 - exp(-s / tau))) with s = t - 1
    let (t, lag) = (a.t(), a.get("a").unwrap());
    for (tk, v) in t.iter().zip(lag) {
        let s = (tk - 1.0).max(0.0);
        let exact = 100.0 * (s - 0.05 * (1.0 - (-s / 0.05).exp()));
        assert!((v - exact).abs() < 1e-9, "t = {tk}: {v} vs {exact}");
    }
}

#[test]
fn delayed_input_driven_lag() {
    let mut m = Toy::new(delayed_lag, LAG_TAU, ["y"]);
    // only the delayed lookup of channel 2 drives the dynamics
    m.delays = InputDelays {
        delayed: [LAG_DELAY, 0.0],
        current: [false; 4],
    };
    let sched = InputSchedule::steps(Drive::new(0.0, 0.0, 0.0, 0.0), &[(1.0, 2, 1.0)]).unwrap();
    // the step is a stop time at its delayed time only
    let stops = stop_times(&m, &sched, 0.0, 3.0);
    assert_eq!(stops.len(), 1, "{stops:?}");
    assert!((stops[0].0 - 1.3).abs() < 1e-12 && stops[0].1, "{stops:?}");
    let tol = 1e-8;
    for method in [
        Method::Rosenbrock34,
        Method::Rodas4,
        Method::Exprb32,
        Method::Dopri5,
    ] {
        let sol = run(&m, &sched, 3.0, [0.0], &opts(method, tol));
        let e = max_error(&sol, ["y"], delayed_lag_exact);
        eprintln!("{method:?}: max error {e:.2e}, {:?}", sol.stats);
        assert!(e < 10.0 * tol, "{method:?}: max error {e:.2e}");
    }
    // declared as a linear lag: integrated in closed form (exact to rounding)
    m.lags = vec![LinearLag {
        state: 0,
        tau: LAG_TAU,
        command: LagCommand::Egr,
        saturation: (f64::NEG_INFINITY, f64::INFINITY),
    }];
    for method in [Method::Rosenbrock34, Method::Rodas4, Method::Exprb32] {
        let sol = run(&m, &sched, 3.0, [0.0], &opts(method, tol));
        let e = max_error(&sol, ["y"], delayed_lag_exact);
        eprintln!(
            "{method:?}, closed form: max error {e:.2e}, {:?}",
            sol.stats
        );
        assert!(e < 1e-13, "{method:?}, closed form: max error {e:.2e}");
        assert_eq!(sol.stats.breakpoints, 1, "{method:?}: {:?}", sol.stats);
    }
    // the delayed step is no stop time: the closed form follows it inside a step, still exact
    for method in [Method::Rosenbrock34, Method::Rodas4, Method::Exprb32] {
        let across = SimOptions {
            stop_at_lag_breakpoints: false,
            ..opts(method, tol)
        };
        let sol = run(&m, &sched, 3.0, [0.0], &across);
        let e = max_error(&sol, ["y"], delayed_lag_exact);
        eprintln!(
            "{method:?}, closed form across the step: max error {e:.2e}, {:?}",
            sol.stats
        );
        assert!(
            e < 1e-13,
            "{method:?}, closed form across the step: max error {e:.2e}"
        );
        assert_eq!(sol.stats.breakpoints, 0, "{method:?}: {:?}", sol.stats);
    }
    // the plain W-method ignores the switch: it needs the stop
    let across = SimOptions {
        stop_at_lag_breakpoints: false,
        ..opts(Method::Rosenbrock34, tol)
    };
    let sol = run(
        &m,
        &sched,
        3.0,
        [0.0],
        &SimOptions {
            exact_actuators: false,
            ..across
        },
    );
    assert_eq!(sol.stats.breakpoints, 1, "{:?}", sol.stats);
}

// ---------------------------------------------------------------------------------------------
// convergence order and error vs tolerance

/// y' = -y^2 (nonlinear, so the W-method's lagged Jacobian is not exact): y = 1 / (1 + t).
fn riccati(x: &[f64; 1], _u: &ModelInput, _k: f64) -> [f64; 1] {
    [-x[0] * x[0]]
}

/// y1' = y2, y2' = -y1: y = (cos t, -sin t) from (1, 0). Linear, so the error of a Runge-Kutta
/// step is that of its stability function (DOPRI5: e^z - R(z) = z^6 / 3600 + ...).
fn oscillator(x: &[f64; 2], _u: &ModelInput, _k: f64) -> [f64; 2] {
    [x[1], -x[0]]
}

/// Error at t = 4 with the step size pinned at `h` (tolerances so loose that no step is
/// rejected or shortened, apart from the first few and the split of the last), inputs `sched`.
fn pinned_error<const N: usize>(
    m: &Toy<N>,
    sched: &InputSchedule,
    y0: [f64; N],
    exact: [f64; N],
    method: Method,
    h: f64,
) -> f64 {
    let o = SimOptions {
        rtol: 0.5,
        atol: 1e3,
        h_max: h,
        dt_out: 4.0,
        method,
        ..SimOptions::default()
    };
    let sol = run(m, sched, 4.0, y0, &o);
    assert_eq!(sol.stats.rejected, 0);
    (0..N)
        .map(|i| (sol.get(m.names[i]).unwrap().last().unwrap() - exact[i]).abs())
        .fold(0.0, f64::max)
}

/// Observed orders log2(e(h) / e(h/2)) from the errors at the step sizes `hs` (halving).
fn observed_orders(e: &[f64]) -> Vec<f64> {
    e.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
}

#[test]
fn convergence_order() {
    let riccati_toy = Toy::new(riccati, 0.0, ["y"]);
    let osc = Toy::new(oscillator, 0.0, ["y1", "y2"]);
    let constant = InputSchedule::constant(Drive::new(0.0, 0.0, 0.0, 0.0));
    // ROS34PW2 on a nonlinear problem (its lagged Jacobian is not the exact one: the W-method
    // keeps order 3 all the same); RODAS4 with its fresh Jacobian at every step, order 4
    let cases: [(Method, [f64; 3], f64); 4] = [
        (Method::Rosenbrock34, [0.1, 0.05, 0.025], 3.0),
        (Method::Rodas4, [0.2, 0.1, 0.05], 4.0),
        (Method::Exprb32, [0.2, 0.1, 0.05], 3.0),
        (Method::Dopri5, [0.2, 0.1, 0.05], 5.0),
    ];
    for (method, hs, order) in cases {
        let e: Vec<f64> = hs
            .iter()
            .map(|&h| match method {
                Method::Dopri5 => pinned_error(
                    &osc,
                    &constant,
                    [1.0, 0.0],
                    [4f64.cos(), -4f64.sin()],
                    method,
                    h,
                ),
                _ => pinned_error(&riccati_toy, &constant, [1.0], [0.2], method, h),
            })
            .collect();
        let p = observed_orders(&e);
        eprintln!("{method:?}: h {hs:?}, errors {e:?}, observed orders {p:.2?}");
        for q in p {
            assert!(
                (q - order).abs() < 0.35,
                "{method:?}: observed order {q:.2}"
            );
        }
    }
}

/// RODAS4 is a Rosenbrock method, not a W-method: its order needs the exact df/dt of a
/// non-autonomous problem, here the time entering through an input (Prothero-Robinson with
/// lambda = -1 and -20, g = sin, the time on channel 0). Order 4 shows that the f_t term along
/// the input slope is right; without it the order drops (measured with f_t set to zero: order
/// 0.9-1.0 at lambda = -1, errors 3.8e-3 ... 5.3e-4).
#[test]
fn convergence_order_non_autonomous() {
    let sched = time_ramp(4.0);
    for (lambda, hs) in [
        (-1.0, [0.2, 0.1, 0.05, 0.025]),
        (-20.0, [0.04, 0.02, 0.01, 0.005]),
    ] {
        let m = Toy::new(prothero_robinson, lambda, ["y"]);
        let e: Vec<f64> = hs
            .iter()
            .map(|&h| pinned_error(&m, &sched, [0.0], [4f64.sin()], Method::Rodas4, h))
            .collect();
        let p = observed_orders(&e);
        eprintln!("RODAS4, lambda {lambda}: h {hs:?}, errors {e:?}, observed orders {p:.2?}");
        for q in p {
            assert!(
                (q - 4.0).abs() < 0.5,
                "lambda {lambda}: observed order {q:.2}"
            );
        }
    }
}

/// exprb32 (exponential Rosenbrock, order 3) on the non-autonomous Prothero-Robinson problem
/// (the time as an input): its h^2 phi_2(h J) f_t term along the input slope is part of the
/// method; observed orders 2.97-3.02 at lambda = -1, 2.70-2.95 at lambda = -20.
#[test]
fn exprb32_non_autonomous() {
    let sched = time_ramp(4.0);
    for (lambda, hs) in [
        (-1.0, [0.4, 0.2, 0.1, 0.05]),
        (-20.0, [0.04, 0.02, 0.01, 0.005]),
        (-1e4, [0.4, 0.2, 0.1, 0.05]),
    ] {
        let m = Toy::new(prothero_robinson, lambda, ["y"]);
        let e: Vec<f64> = hs
            .iter()
            .map(|&h| pinned_error(&m, &sched, [0.0], [4f64.sin()], Method::Exprb32, h))
            .collect();
        let p = observed_orders(&e);
        eprintln!("exprb32, lambda {lambda}: h {hs:?}, errors {e:?}, observed orders {p:.2?}");
        if lambda == -1e4 {
            // stiff: the error is far below the non-stiff cases' and not in the asymptotic
            // regime (the first steps, before h reaches h_max, dominate)
            assert!(e.iter().all(|&x| x < 1e-6), "lambda {lambda}: errors {e:?}");
        } else {
            for q in p {
                assert!(q > 2.6, "lambda {lambda}: observed order {q:.2}");
            }
        }
    }
}

#[test]
fn error_follows_tolerance() {
    let m = Toy::new(riccati, 0.0, ["y"]);
    let sched = InputSchedule::constant(Drive::new(0.0, 0.0, 0.0, 0.0));
    let exact = |t: f64| [1.0 / (1.0 + t)];
    for method in [
        Method::Rosenbrock34,
        Method::Rodas4,
        Method::Exprb32,
        Method::Dopri5,
    ] {
        let mut prev = f64::INFINITY;
        for tol in [1e-4, 1e-6, 1e-8, 1e-10] {
            let sol = run(&m, &sched, 4.0, [1.0], &opts(method, tol));
            let e = max_error(&sol, ["y"], exact);
            eprintln!(
                "{method:?}, tol {tol:e}: max error {e:.2e}, {} steps",
                sol.stats.steps
            );
            assert!(e < 10.0 * tol, "{method:?}, tol {tol:e}: max error {e:.2e}");
            // tighter tolerance, smaller error (at least a factor 10 per 100x)
            assert!(
                e < prev / 10.0,
                "{method:?}, tol {tol:e}: {e:.2e} vs {prev:.2e}"
            );
            prev = e;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// ROS34PW2's non-autonomous term across input kinks

/// y' = lambda (y - g(t)) + g'(t) with g on channel 0 and its slope g' on channel 1: y = g from
/// y(0) = g(0), whatever lambda. g is piecewise linear (slopes changing every 0.1 s, as the
/// WHTC's 10 Hz rows), so g' jumps at every row.
fn kinked_tracking(x: &[f64; 1], u: &ModelInput, lambda: f64) -> [f64; 1] {
    [lambda * (x[0] - u.now.n_e_rpm) + u.now.u_delta_mg]
}

/// g of [`kinked_tracking`] on 0 .. `t_end`: slopes from a fixed pseudo-random sequence in
/// [-1, 1], g' held (two rows per time: a jump) on each 0.1 s interval.
fn kinked_schedule(t_end: f64) -> InputSchedule {
    let n = (t_end / 0.1).round() as usize;
    let slope = |k: usize| ((k as f64 * 2.399_963).sin() * 43_758.545_3).fract() * 2.0 - 1.0;
    let (mut times, mut rows) = (Vec::new(), Vec::new());
    let mut g = 0.5;
    for k in 0..n {
        let (t0, t1) = (k as f64 * 0.1, (k + 1) as f64 * 0.1);
        let s = slope(k);
        times.push(t0);
        rows.push([g, s, 0.0, 0.0]);
        g += s * 0.1;
        times.push(t1);
        rows.push([g, s, 0.0, 0.0]);
    }
    InputSchedule::new(times, rows).unwrap()
}

/// The non-autonomous term gamma_i h^2 f_t of ROS34PW2 ([`SimOptions::rosw_time_derivative`],
/// the default) on a stiff tracking problem (lambda = -100, the engine's fast modes) whose input
/// slope jumps every 0.1 s, the pattern of the WHTC. Here J (lambda) is exact and f_t
/// (-lambda g', by the difference along the input slopes) exact to the difference's rounding,
/// and a Rosenbrock method with exact J and f_t is exact on a solution linear in t: with the
/// term the method follows the piecewise-linear solution to 2.4e-11 in one step per segment.
/// Without it (the W-method with the time column of its Jacobian zero, order 3 all the same)
/// every kink leaves an error: 1.5e-9, 62 x more, at the same steps (the tolerance lets both
/// through; on the engine the larger error shows as steps, docs/integrator.md). With a wrong
/// coefficient (gamma_2 off by 10 %, measured once) the error was 1.1e-4 in 12 159 steps.
#[test]
fn rosw_time_derivative_follows_input_kinks() {
    let t_end = 5.0;
    let sched = kinked_schedule(t_end);
    let m = Toy::new(kinked_tracking, -100.0, ["y"]);
    let g = |t: f64| [sched.at(t).n_e_rpm];
    let mut results = Vec::new();
    for with_ft in [true, false] {
        let o = SimOptions {
            rosw_time_derivative: with_ft,
            dt_out: 0.05,
            ..opts(Method::Rosenbrock34, 1e-6)
        };
        let sol = run(&m, &sched, t_end, [0.5], &o);
        let e = max_error(&sol, ["y"], g);
        eprintln!(
            "ROS34PW2, f_t {with_ft}: max error {e:.2e}, {:?}",
            sol.stats
        );
        results.push((e, sol.stats));
    }
    let ((e_ft, s_ft), (e_no, s_no)) = (results[0], results[1]);
    assert!(e_ft < 1e-10, "with f_t: max error {e_ft:.2e}");
    // 50 segments: one step each (the first segment's initial step may take one or two more)
    assert!(
        s_ft.steps + s_ft.rejected <= 53,
        "with f_t: one step per 0.1 s segment expected: {s_ft:?}"
    );
    assert!(
        e_no > 20.0 * e_ft,
        "without f_t the kinks must show: {e_no:.2e} against {e_ft:.2e} ({s_no:?})"
    );
}
