"""mvem.Plant (sample-by-sample plant for controllers in Python) and mvem.gym.AirPathEnv."""

import numpy as np
import pytest

mvem = pytest.importorskip("mvem")

STEP = {
    "time_s": [0.0, 1.0, 1.0, 4.0],
    "n_e_rpm": [1500.0] * 4,
    "u_delta_mg": [110.0] * 4,
    "u_egr_pct": [80.0] * 4,
    "u_vgt_pct": [75.0, 75.0, 65.0, 65.0],
}


def test_stepping_equals_simulate_on_the_paper_vgt_step():
    sim = mvem.simulate(STEP, dt=0.01)
    plant = mvem.Plant(n_e=1500.0, u_delta=110.0, u_egr=80.0, u_vgt=75.0)
    w_c = []
    for k in range(400):
        out = plant.step(0.01, u_vgt=65.0 if k >= 100 else 75.0)
        w_c.append(out["W_c"])
    assert plant.t == pytest.approx(4.0, abs=1e-9)
    ref = sim["W_c"][1:401]
    span = sim["W_c"].max() - sim["W_c"].min()
    assert np.max(np.abs(np.array(w_c) - ref)) < 1e-3 * span
    # the state is a numpy array in state_names order
    assert plant.state.shape == (8,)
    assert plant.state_names[0] == "p_im"
    assert plant.state[0] == pytest.approx(sim["p_im"][400], rel=1e-4)


def test_reset_and_errors():
    plant = mvem.Plant(1500.0, 110.0, 80.0, 75.0, model=10)
    plant.step(0.05, u_vgt=60.0)
    plant.reset(u_vgt=60.0)
    assert plant.t == 0.0
    assert plant.state.shape == (10,)
    with pytest.raises(ValueError, match="dt"):
        plant.step(-1.0)
    with pytest.raises(ValueError, match="u_delta"):
        plant.step(0.01, u_delta=float("nan"))
    with pytest.raises(ValueError):
        mvem.Plant(1500.0, 110.0, 80.0, 75.0, model=9)


def test_air_path_env_passes_check_env():
    gym = pytest.importorskip("gymnasium")
    from gymnasium.utils.env_checker import check_env

    from mvem.gym import AirPathEnv

    env = AirPathEnv(duration=2.0)
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(seed=3)
    total, done = 0.0, False
    while not done:
        obs, r, term, trunc, _ = env.step(np.zeros(2, dtype=np.float32))
        total += r
        done = term or trunc
    assert np.isfinite(total)
    assert env.observation_space.contains(obs)
    assert isinstance(gym.__version__, str)
    # an action of the wrong shape or with NaN is a ValueError naming what is expected; one
    # outside [-1, 1] is clipped to it (inf too)
    env.reset(seed=3)
    for bad in ([0.5], [0.0, np.nan], [[0.0, 0.0], [0.0, 0.0]]):
        with pytest.raises(ValueError, match=r"action: expected 2 finite numbers in \[-1, 1\]"):
            env.step(np.array(bad))
    clipped = env.step(np.array([5.0, -5.0]))
    env.reset(seed=3)
    edge = env.step(np.array([1.0, -1.0]))
    assert clipped[1] == edge[1]
    np.testing.assert_array_equal(clipped[0], edge[0])


def test_out_of_range_commands_are_clamped_with_a_warning():
    import warnings

    # in range: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p = mvem.Plant(n_e=1500.0, u_delta=110.0, u_egr=80.0, u_vgt=75.0)
        p.step(0.01, u_vgt=65.0)
        mvem.steady(1500.0, 110.0, 80.0, 75.0)
    # the authors' saturation clamps u_vgt = 10 % to 20 %: a UserWarning names input and range,
    # and the plant runs as with 20 %
    with pytest.warns(UserWarning, match=r"Plant.step: u_vgt_pct = 10 is outside \[20, 100\]"):
        out10 = p.step(0.5, u_vgt=10.0)
    q = mvem.Plant(n_e=1500.0, u_delta=110.0, u_egr=80.0, u_vgt=75.0)
    q.step(0.01, u_vgt=65.0)
    out20 = q.step(0.5, u_vgt=20.0)
    assert out10["W_c"] == pytest.approx(out20["W_c"], rel=1e-12)
    with pytest.warns(UserWarning, match=r"steady: n_e_rpm = 1e300 is outside \[500, 2000\]"):
        mvem.steady(1e300, 110.0, 80.0, 75.0)
    rows = {
        "time_s": [0.0, 1.0, 2.0],
        "n_e_rpm": [1500.0, 1500.0, 1500.0],
        "u_delta_mg": [110.0, 300.0, 110.0],
        "u_egr_pct": [80.0, 80.0, 80.0],
        "u_vgt_pct": [75.0, 75.0, 75.0],
    }
    with pytest.warns(UserWarning, match=r"simulate: u_delta_mg is outside its range \[1, 250\] at 1 of 3 input rows "
                      r"\(1 above, up to 300\), first at t = 0\.73684\d* s \(the whole channel runs from 110 to 300\)"):
        mvem.simulate(rows, dt=0.5)


def test_a_range_warning_comes_before_the_step():
    """Plant.step warns of a changed command outside its range before it steps (one lock per
    step otherwise): a warning made an error leaves the plant, its time and held commands as
    they were; the command held on warns no more."""
    import warnings

    p = mvem.Plant(n_e=1500.0, u_delta=110.0, u_egr=80.0, u_vgt=75.0)
    p.step(0.1)
    x = p.state.copy()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match=r"Plant.step: u_vgt_pct = 10 is outside \[20, 100\]"):
            p.step(0.1, u_vgt=10.0)
    assert p.t == pytest.approx(0.1, abs=1e-12)
    np.testing.assert_array_equal(p.state, x)
    assert list(p.commands) == [1500.0, 110.0, 80.0, 75.0]
    with pytest.warns(UserWarning, match=r"u_vgt_pct = 10 is outside"):
        p.step(0.1, u_vgt=10.0)
    assert p.t == pytest.approx(0.2, abs=1e-12) and p.commands[3] == 10.0
    # held on (unchanged): no warning; in range again: none either
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p.step(0.1)
        p.step(0.1, u_vgt=10.0)
        p.step(0.1, u_vgt=60.0)
    assert p.t == pytest.approx(0.5, abs=1e-12)


def test_a_plant_shared_by_threads_serializes_its_steps():
    """QA: a Plant stepped from several threads raised RuntimeError "Already borrowed" (the
    GIL is released while it integrates). Its calls are serialized: every step of every
    thread runs, each returns the outputs of its own step, and the plant ends where one
    thread doing all the steps ends (the commands alternate identically in both)."""
    import threading

    shared = mvem.Plant(1500.0, 110.0, 80.0, 75.0)
    errors, outs = [], []

    def run():
        try:
            for _ in range(40):
                out = shared.step(0.01, u_vgt=70.0)
                outs.append(out["W_c"])
                _ = shared.state, shared.t, shared.commands, shared.delayed_commands
        except Exception as e:  # noqa: BLE001 - collected and asserted below
            errors.append(e)

    threads = [threading.Thread(target=run) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert len(outs) == 160
    assert shared.t == pytest.approx(1.6, abs=1e-9)
    alone = mvem.Plant(1500.0, 110.0, 80.0, 75.0)
    for _ in range(160):
        alone.step(0.01, u_vgt=70.0)
    np.testing.assert_allclose(shared.state, alone.state, rtol=1e-12)
