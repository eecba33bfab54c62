"""mvem.Model: the right-hand side dx/dt = f(x, u) at any state and its Jacobians (issue 16's
`mvem.jacobian(state, inputs)` for optimal control), checked against independent paths: the
steady-state solver, the linearization, numpy differences of the derivatives, and the Plant's
integrator.

Build the package first: `maturin develop --release -m crates/mvem-py/Cargo.toml`.
"""

import numpy as np
import pytest

mvem = pytest.importorskip("mvem")

POINT = (1500.0, 110.0, 80.0, 75.0)  # n_e [rpm], u_delta [mg], u_egr [%], u_vgt [%]
# linearize's input order (u_delta, u_egr, u_vgt, n_e) as columns of Model's (n_e, u_delta, ...)
LIN_ORDER = [1, 2, 3, 0]


def steady_state(m, point=POINT, model=8):
    s = mvem.steady(*point, model=model)
    return np.array([s[n] for n in m.state_names]), s


def off_equilibrium(x0, names=None):
    """p_im +5 %, X_Oem -10 %, omega_t -3 %: a point of a transient, away from every kink."""
    names = names or mvem.Model(model=len(x0)).state_names
    x = x0.copy()
    for name, factor in [("p_im", 1.05), ("X_Oem", 0.9), ("omega_t", 0.97)]:
        x[names.index(name)] *= factor
    return x


@pytest.mark.parametrize("model", [8, 10, 12])
def test_derivatives_vanish_at_the_steady_state(model):
    m = mvem.Model(model=model)
    x0, _ = steady_state(m, model=model)
    assert len(m.state_names) == model and m.input_names == ["n_e", "u_delta", "u_egr", "u_vgt"]
    dx = m.derivatives(x0, POINT)
    assert dx.shape == (model,) and dx.dtype == np.float64
    # the steady-state solver converges to ~1e-13 of the state scales per second
    assert np.max(np.abs(dx / m.state_scales)) < 1e-9
    # away from it they do not (the test can fail)
    assert np.max(np.abs(m.derivatives(off_equilibrium(x0), POINT) / m.state_scales)) > 0.1


def test_signals_equal_the_steady_state():
    m = mvem.Model()
    x0, s = steady_state(m)
    sig = m.signals(x0, POINT)
    for name in ["W_c", "W_egr", "W_t", "lambda_O", "x_egr", "M_e", "n_t", "T_em", "eta_c"]:
        assert sig[name] == pytest.approx(s[name], rel=1e-12), name
    assert sig["flags"] == s["flags"]


def test_jacobian_at_a_steady_state_equals_linearize():
    """The same library routine at the same point: A, C identical, B and D with the columns in
    Model's input order."""
    m = mvem.Model()
    lin = mvem.linearize(*POINT)
    j = m.jacobian(lin["x0"], POINT, outputs=lin["output_names"])
    assert j["input_names"] == ["n_e", "u_delta", "u_egr", "u_vgt"]
    assert j["output_names"] == lin["output_names"] and j["kinks"] == []
    np.testing.assert_array_equal(j["A"], lin["A"])
    np.testing.assert_array_equal(j["B"][:, LIN_ORDER], lin["B"])
    np.testing.assert_array_equal(j["C"], lin["C"])
    np.testing.assert_array_equal(j["D"][:, LIN_ORDER], lin["D"])
    np.testing.assert_array_equal(j["y"], lin["y0"])
    # without outputs: f, A, B only
    j0 = m.jacobian(lin["x0"], POINT)
    assert "C" not in j0 and j0["output_names"] == []
    np.testing.assert_array_equal(j0["A"], lin["A"])


@pytest.mark.parametrize("model", [8, 12])
def test_jacobian_off_equilibrium_agrees_with_differences_of_the_derivatives(model):
    """numpy central differences of Model.derivatives (step 1e-6 of the scale: error ~1e-10)
    against the library's Richardson-extrapolated differences, scaled by the state and input
    scales, relative to the largest scaled entry."""
    m = mvem.Model(model=model)
    x0, _ = steady_state(m, model=model)
    x = off_equilibrium(x0)
    u = np.array([1400.0, 130.0, 60.0, 55.0])
    j = m.jacobian(x, u)
    np.testing.assert_array_equal(j["f"], m.derivatives(x, u))
    sx = m.state_scales
    su = np.array([1000.0, 100.0, 100.0, 100.0])
    a = np.zeros((model, model))
    for k in range(model):
        h = 1e-6 * sx[k]
        e = np.zeros(model)
        e[k] = h
        a[:, k] = (m.derivatives(x + e, u) - m.derivatives(x - e, u)) / (2 * h)
    b = np.zeros((model, 4))
    for k in range(4):
        h = 1e-6 * su[k]
        e = np.zeros(4)
        e[k] = h
        b[:, k] = (m.derivatives(x, u + e) - m.derivatives(x, u - e)) / (2 * h)
    a_s = j["A"] * sx[None, :] / sx[:, None]
    b_s = j["B"] * su[None, :] / sx[:, None]
    ref = max(np.abs(a_s).max(), np.abs(b_s).max())
    assert np.abs(a_s - a * sx[None, :] / sx[:, None]).max() < 1e-7 * ref
    assert np.abs(b_s - b * su[None, :] / sx[:, None]).max() < 1e-7 * ref
    # u_delta moves p_em and X_Oem (fuel into the cylinders) and nothing of the actuators
    row = m.state_names.index
    assert abs(j["B"][row("p_em"), 1]) > 0 and abs(j["B"][row("X_Oem"), 1]) > 0
    assert j["B"][row("u_vgt_act"), 1] == 0


def test_derivatives_predict_the_plants_first_millisecond():
    """The Plant's integrator (another path through the simulator) from the steady state after
    a step of u_delta (undelayed): (x(dt) - x0) / dt -> f(x0, u_new), first order in dt."""
    m = mvem.Model()
    x0, _ = steady_state(m)
    u_new = [1500.0, 130.0, 80.0, 75.0]
    f = m.derivatives(x0, u_new)
    errors = []
    for dt in [1e-3, 1e-4]:
        plant = mvem.Plant(*POINT)
        plant.step(dt, u_delta=130.0)
        errors.append(np.abs((plant.state - x0) / dt - f).max() / np.abs(f).max())
    assert errors[1] < 5e-3
    assert errors[1] < 0.2 * errors[0]
    # the old inputs' derivatives (zero) are not what the plant follows
    assert np.abs(m.derivatives(x0, POINT)).max() < 1e-3 * np.abs(f).max()


def test_scipy_integrates_the_model_as_mvem_simulate_does():
    """A third-party integrator (scipy's Radau, with Model.derivatives and the Jacobian A)
    reproduces mvem.simulate's response to a step of u_delta (undelayed) from the steady state:
    the use of Model for custom integrators and optimal control."""
    from scipy.integrate import solve_ivp  # installed by scripts/test-python.sh

    m = mvem.Model()
    x0, _ = steady_state(m)
    u = np.array([1500.0, 130.0, 80.0, 75.0])
    sol = solve_ivp(
        lambda t, x: m.derivatives(x, u),
        (0.0, 3.0),
        x0,
        method="Radau",
        rtol=1e-9,
        atol=1e-9 * m.state_scales,
        jac=lambda t, x: m.jacobian(x, u)["A"],
        dense_output=True,
    )
    assert sol.status == 0
    r = mvem.simulate(
        {
            "time_s": [0.0, 1.0, 1.0, 4.0],
            "n_e_rpm": [1500.0] * 4,
            "u_delta_mg": [110.0, 110.0, 130.0, 130.0],
            "u_egr_pct": [80.0] * 4,
            "u_vgt_pct": [75.0] * 4,
        },
        dt=0.01,
        rtol=1e-9,
    )
    after = r["t"] >= 1.0
    x = sol.sol(r["t"][after] - 1.0).T
    for i, name in enumerate(m.state_names):
        dev = np.abs(x[:, i] - r[name][after]).max() / m.state_scales[i]
        assert dev < 1e-7, name  # measured 4.8e-9 at most (X_Oem)
    # the step moved the states by far more than that
    assert abs(r["p_im"][-1] - x0[0]) > 0.1 * m.state_scales[0]


def test_batches_equal_single_points():
    m = mvem.Model()
    x0, _ = steady_state(m)
    xs = np.stack([x0, off_equilibrium(x0), x0 * 1.01])
    us = np.array([POINT, [1400.0, 130.0, 60.0, 55.0], [1600.0, 90.0, 30.0, 80.0]])
    dx = m.derivatives(xs, us)
    j = m.jacobian(xs, us, outputs=["W_c"])
    sig = m.signals(xs, us)
    assert dx.shape == (3, 8) and j["A"].shape == (3, 8, 8) and j["B"].shape == (3, 8, 4)
    assert j["C"].shape == (3, 1, 8) and j["D"].shape == (3, 1, 4) and sig["W_c"].shape == (3,)
    for k in range(3):
        np.testing.assert_array_equal(dx[k], m.derivatives(xs[k], us[k]))
        one = m.jacobian(xs[k], us[k], outputs=["W_c"])
        for key in ["f", "A", "B", "y", "C", "D"]:
            np.testing.assert_array_equal(j[key][k], one[key])
        assert j["kinks"][k] == one["kinks"]
        assert sig["W_c"][k] == m.signals(xs[k], us[k])["W_c"]
    # one input row for all states
    np.testing.assert_array_equal(m.derivatives(xs, POINT)[1], m.derivatives(xs[1], POINT))


def test_module_functions_and_parameters():
    x0, _ = steady_state(mvem.Model())
    np.testing.assert_array_equal(mvem.derivatives(x0, POINT), mvem.Model().derivatives(x0, POINT))
    np.testing.assert_array_equal(mvem.jacobian(x0, POINT)["A"], mvem.Model().jacobian(x0, POINT)["A"])
    # a parameter set reaches the model: a lighter turbo accelerates faster
    j_t = mvem.published_params()["turbo"]["j_t"]
    x = off_equilibrium(x0)
    f = mvem.derivatives(x, POINT)[4]
    f2 = mvem.derivatives(x, POINT, params={"turbo.j_t": j_t / 2})[4]
    assert f2 == pytest.approx(2 * f, rel=1e-9)


def test_a_kink_is_listed_or_refused():
    """omega_t on the c_m kink (max(omega_t, c_m2), the authors' item 33): listed, or an error
    when strict. An input (or the shut EGR valve's actuator states) at its saturation limit is
    differenced on the side with fewer saturations active, not a kink."""
    m = mvem.Model()
    x0, _ = steady_state(m)
    u = [1500.0, 110.0, 0.0, 75.0]
    assert m.jacobian(x0, u, strict=True)["kinks"] == []
    on_kink = np.array(x0, dtype=float)
    on_kink[4] = mvem.published_params()["turbine"]["c_m"][1]
    j = m.jacobian(on_kink, POINT)
    assert any("omega_t" in k for k in j["kinks"])
    with pytest.raises(RuntimeError, match="kink"):
        m.jacobian(on_kink, POINT, strict=True)


def test_out_of_range_inputs_warn_with_the_point():
    m = mvem.Model()
    x0, _ = steady_state(m)
    xs = np.stack([x0, x0])
    with pytest.warns(UserWarning, match=r"n_e_rpm = 2500 at point 1 \(1 of 2 points\)"):
        m.derivatives(xs, [POINT, [2500.0, 110.0, 80.0, 75.0]])


@pytest.mark.parametrize(
    "call, msg",
    [
        (lambda m, x: m.derivatives(x[:7], POINT), r"state: expected shape \(8,\) or \(K, 8\)"),
        (lambda m, x: m.derivatives(np.r_[np.nan, x[1:]], POINT), "state p_im = NaN"),
        (lambda m, x: m.jacobian(x, [1500.0, 110.0, 80.0]), r"inputs: expected .* shape \(4,\)"),
        (lambda m, x: m.jacobian(x, POINT, outputs=["W_x"]), 'unknown output "W_x"'),
        (lambda m, x: m.derivatives(np.stack([x, x]), np.zeros((3, 4))), r"\(2, 4\) for 2 states"),
        (
            lambda m, x: m.signals(np.stack([x, x]), [POINT, [np.inf, 1.0, 1.0, 30.0]]),
            "point 1: n_e = inf",
        ),
        (lambda m, x: m.jacobian(np.zeros((0, 8)), POINT), "state: no points"),
        (lambda m, x: mvem.Model(model=9), "model = 9"),
        (lambda m, x: mvem.Model(params={"turbo.j_t": -1}), "turbo.j_t"),
    ],
)
def test_bad_arguments_raise_value_error_naming_them(call, msg):
    m = mvem.Model()
    x0, _ = steady_state(m)
    with pytest.raises(ValueError, match=msg):
        call(m, x0)


@pytest.mark.parametrize("model", [8, 10, 12])
def test_random_points_give_finite_values_or_a_value_error(model):
    """States from -1x to 3x the steady state and inputs far outside their ranges: the model's
    integrator limits and input saturations keep every value finite (measured on 2000 points per
    model: no error); anything else must be a ValueError naming the point, never a crash."""
    import warnings

    m = mvem.Model(model=model)
    x0, _ = steady_state(m, model=model)
    rng = np.random.default_rng(1)
    xs = x0 * rng.uniform(-1.0, 3.0, size=(200, model))
    us = np.column_stack([rng.uniform(0, 3000, 200), rng.uniform(-10, 400, 200),
                          rng.uniform(-50, 150, 200), rng.uniform(-50, 150, 200)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        try:
            dx = m.derivatives(xs, us)
            j = m.jacobian(xs, us)
        except ValueError as e:
            assert "point" in str(e)
            return
    assert np.all(np.isfinite(dx)) and np.all(np.isfinite(j["A"])) and np.all(np.isfinite(j["B"]))


def test_plant_delayed_commands_give_its_right_hand_side():
    """Plant.delayed_commands: 60 ms after a step of u_egr 80 -> 60 % and u_vgt 75 -> 65 %, the
    VGT actuator already sees 65 % (tau_dvgt = 40 ms), the EGR actuators still 80 % (tau_degr =
    65 ms). Model.derivatives at the plant's state and those commands is what the plant follows
    (its next 1 ms to first order); with the current commands instead, the EGR actuators would
    move."""
    plant = mvem.Plant(*POINT)
    assert plant.delayed_commands == (80.0, 75.0)
    plant.step(0.01)
    for _ in range(6):
        plant.step(0.01, u_egr=60.0, u_vgt=65.0)
    assert plant.delayed_commands == (80.0, 65.0)
    m = mvem.Model()
    u = (1500.0, 110.0, *plant.delayed_commands)
    x = plant.state
    f = m.derivatives(x, u)
    plant.step(1e-3)
    slope = (plant.state - x) / 1e-3
    scale = m.state_scales
    assert np.abs(slope - f).max() / np.abs(f).max() < 0.02
    assert np.abs(f / scale).max() > 1e-3  # the plant is in a transient
    wrong = m.derivatives(x, (1500.0, 110.0, 60.0, 65.0))
    k = m.state_names.index("u_egr1")
    assert f[k] == pytest.approx(0.0, abs=1e-9) and abs(wrong[k]) > 1.0


def test_ekf_example_estimates_p_em_from_p_im_and_n_t():
    """examples/python/ekf_air_path.py: an EKF on Model.jacobian and Plant.delayed_commands
    tracks p_em through EGR and VGT steps with a tenth of the open-loop model's error (measured
    about 1/60 and 1/15 in the two windows)."""
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python" / "ekf_air_path.py"
    spec = importlib.util.spec_from_file_location("ekf_air_path", path)
    ekf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ekf)
    _, h = ekf.run(3.0, seed=2, verbose=False)
    _, h_open = ekf.run(3.0, seed=2, verbose=False, update=False)
    for lo, hi in [(0.5, 1.5), (1.5, 3.0)]:
        rms = [np.sqrt(np.mean(x[(x[:, 0] > lo) & (x[:, 0] <= hi), 1] ** 2)) for x in (h, h_open)]
        assert rms[0] < 0.1 * rms[1], (lo, hi, rms)


def test_lqi_example_with_the_delays_in_the_design_settles_where_without_it_does_not():
    """examples/python/lqi_vs_baseline.py at input weight 10 %: the LQI designed on
    linearize(ts=0.01)'s sampled model, delays exact, settles the x_egr step +0.02 (measured rise
    1.11 s, settling 5.88 s, no overshoot) where the same weights on the undelayed model drive
    the VGT into its limit (595 % overshoot, never settles); at 5 % both are close."""
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python" / "lqi_vs_baseline.py"
    spec = importlib.util.spec_from_file_location("lqi_vs_baseline", path)
    lqi = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(lqi)
    with_d, _ = lqi.run_step("x_egr", 0.02, 10.0, delays=True)
    assert with_d["settling_time"] is not None and with_d["settling_time"] < 7.0, with_d
    assert with_d["overshoot_pct"] < 2.0, with_d
    without, u = lqi.run_step("x_egr", 0.02, 10.0, delays=False)
    assert without["settling_time"] is None and without["overshoot_pct"] > 100.0, without
    assert u[1] == 20.0  # the VGT at its lower limit
    a, _ = lqi.run_step("x_egr", 0.02, 5.0, delays=True)
    b, _ = lqi.run_step("x_egr", 0.02, 5.0, delays=False)
    assert abs(a["settling_time"] - b["settling_time"]) < 0.5, (a, b)


STEP_INPUTS = {
    "time_s": [0.0, 1.0, 1.0, 3.0],
    "n_e_rpm": [1500.0] * 4,
    "u_delta_mg": [110.0] * 4,
    "u_egr_pct": [80.0] * 4,
    "u_vgt_pct": [75.0, 75.0, 65.0, 65.0],
}


def test_simulate_from_a_given_state_equals_the_cli(mvem_cli, tmp_path):
    """simulate(x0=...): from the steady state it is the default run to the bit; from another
    state (a dict or an array) it equals `mvem simulate --initial-state` (the same library
    path, 17-digit CSV) to 1e-12, and the start is that state."""
    import json
    import subprocess

    from conftest import read_csv

    m = mvem.Model()
    x_ss, _ = steady_state(m)
    base = mvem.simulate(STEP_INPUTS)
    same = mvem.simulate(STEP_INPUTS, x0=x_ss)
    for n in m.state_names + ["W_c"]:
        np.testing.assert_array_equal(same[n], base[n])
    x1 = off_equilibrium(x_ss)
    named = dict(zip(m.state_names, x1))
    r = mvem.simulate(STEP_INPUTS, x0=named)
    np.testing.assert_array_equal(r["p_im"], mvem.simulate(STEP_INPUTS, x0=x1)["p_im"])
    assert r["p_im"][0] == x1[0] and abs(r["p_im"][0] - base["p_im"][0]) > 5e3
    path = tmp_path / "x0.json"
    path.write_text(json.dumps(named))
    inp = tmp_path / "in.csv"
    inp.write_text("time_s,n_e_rpm,u_delta_mg,u_egr_pct,u_vgt_pct\n" + "\n".join(
        ",".join(str(STEP_INPUTS[c][k]) for c in mvem.INPUT_COLUMNS) for k in range(4)) + "\n")
    out = tmp_path / "out.csv"
    subprocess.run([mvem_cli, "simulate", "--inputs", str(inp), "--initial-state", str(path),
                    "--dt", "0.01", "--out", str(out)], check=True, capture_output=True)
    cli = read_csv(out)
    for n in m.state_names + ["W_c", "lambda_O"]:
        np.testing.assert_allclose(r[n], cli[n], rtol=1e-12, atol=0, err_msg=n)


@pytest.mark.parametrize("x0, msg", [
    (np.zeros(7), r"x0: expected 8 values"),
    ({"p_im": 1.5e5}, "x0: missing state p_em"),
    ({"foo": 1.0}, 'x0: unknown state "foo"'),
    (np.r_[np.nan, np.ones(7)], "x0: p_im = NaN is not finite"),
])
def test_simulate_refuses_a_bad_start_state(x0, msg):
    with pytest.raises(ValueError, match=msg):
        mvem.simulate(STEP_INPUTS, x0=x0)
