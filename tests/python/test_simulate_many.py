"""mvem.simulate_many: many simulations at once on all cores, each equal to mvem.simulate."""

import numpy as np
import pytest

mvem = pytest.importorskip("mvem")


def vgt_step(to, n_e=1500.0):
    return {
        "time_s": [0.0, 1.0, 1.0, 3.0],
        "n_e_rpm": [n_e] * 4,
        "u_delta_mg": [110.0] * 4,
        "u_egr_pct": [80.0] * 4,
        "u_vgt_pct": [75.0, 75.0, to, to],
    }


def assert_same(a, b):
    assert set(a) == set(b)
    for k in a:
        # the same computation on another thread: identical numbers
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize("threads", [None, 1, 2])
def test_each_run_equals_simulate_of_its_inputs(threads):
    inputs = [vgt_step(65.0), vgt_step(55.0, n_e=1200.0), np.array(
        [[0.0, 1800.0, 150.0, 40.0, 50.0], [2.0, 1800.0, 150.0, 40.0, 60.0]])]
    runs = mvem.simulate_many(inputs, threads=threads, dt=0.05, model=10)
    assert len(runs) == 3
    for inp, r in zip(inputs, runs):
        assert_same(r, mvem.simulate(inp, dt=0.05, model=10))


def test_parameter_variations_one_params_entry_per_run():
    j_t = mvem.published_params()["turbo"]["j_t"]
    params = [None, {"turbo.j_t": 2.0 * j_t}, {"turbo": {"j_t": 0.5 * j_t}}]
    runs = mvem.simulate_many([vgt_step(65.0)] * 3, params=params)
    for p, r in zip(params, runs):
        assert_same(r, mvem.simulate(vgt_step(65.0), params=p))
    # a heavier turbo responds more slowly: the runs differ
    k = np.searchsorted(runs[0]["t"], 1.2)
    assert runs[1]["W_c"][k] != runs[0]["W_c"][k]
    # one params entry for all runs
    same = mvem.simulate_many([vgt_step(65.0)] * 2, params={"turbo.j_t": 2.0 * j_t})
    assert_same(same[1], runs[1])


def test_a_failing_run_does_not_sink_the_others():
    bad = vgt_step(65.0)
    bad["u_delta_mg"] = [110.0, float("nan"), 110.0, 110.0]
    inputs = [vgt_step(65.0), bad, vgt_step(60.0, n_e=1200.0)]
    runs = mvem.simulate_many(inputs, on_error="return", threads=2)
    assert isinstance(runs[1], ValueError)
    assert str(runs[1]).startswith("run 1: inputs: row 2: u_delta_mg = NaN")
    # the runs before and after the failed one are complete
    assert_same(runs[0], mvem.simulate(inputs[0]))
    assert_same(runs[2], mvem.simulate(inputs[2]))
    # default: raise the first failure after all runs, naming its index
    with pytest.raises(ValueError, match="^run 1: inputs"):
        mvem.simulate_many(inputs)


@pytest.mark.parametrize("kwargs, msg", [
    ({"threads": 0}, "threads = 0"),
    ({"on_error": "ignore"}, "on_error"),
    ({"params": [None]}, "params: a list of 1 entries for 2 inputs"),
    ({"rtol": -1.0}, "rtol"),
])
def test_bad_options_raise_value_error(kwargs, msg):
    with pytest.raises(ValueError, match=msg):
        mvem.simulate_many([vgt_step(65.0)] * 2, **kwargs)


def test_inputs_must_be_a_list():
    with pytest.raises(ValueError, match="list of inputs"):
        mvem.simulate_many(vgt_step(65.0))
    assert mvem.simulate_many([]) == []


def test_start_states_one_for_all_or_one_per_run():
    """x0: one start state for every run (dict, array or list of numbers), or one per run
    (a list with None for the steady start, or a 2-D array); each run equals simulate(x0=...);
    a bad one is that run's error."""
    m = mvem.Model()
    s = mvem.steady(1500.0, 110.0, 80.0, 75.0)
    x_ss = np.array([s[n] for n in m.state_names])
    x1 = x_ss * np.r_[1.1, 1.05, 1.0, 0.9, 0.97, 1.0, 1.0, 1.0]
    inputs = [vgt_step(65.0), vgt_step(55.0)]
    one = mvem.simulate(inputs[1], x0=x1)
    for x0 in [x1, list(x1), dict(zip(m.state_names, x1))]:
        runs = mvem.simulate_many(inputs, x0=x0)
        assert_same(runs[0], mvem.simulate(inputs[0], x0=x1))
        assert_same(runs[1], one)
    for x0 in [[None, x1], np.stack([x_ss, x1])]:
        runs = mvem.simulate_many(inputs, x0=x0)
        assert_same(runs[0], mvem.simulate(inputs[0]))
        assert_same(runs[1], one)
    assert runs[1]["p_im"][0] == x1[0]
    with pytest.raises(ValueError, match="x0: 3 start states for 2 inputs"):
        mvem.simulate_many(inputs, x0=[x1, x1, x1])
    out = mvem.simulate_many(inputs, x0=[x1[:7], None], on_error="return")
    assert isinstance(out[0], ValueError) and "run 0: x0: expected 8 values" in str(out[0])
    assert_same(out[1], mvem.simulate(inputs[1]))


def test_ctrl_c_stops_the_ensemble_and_the_next_call_runs(tmp_path, ctrl_c):
    """KeyboardInterrupt (as Ctrl-C raises it) while an ensemble runs: the runs not started are
    cancelled, the call raises within about one run's time, and a later call is unaffected."""
    import _thread
    import threading
    import time

    from conftest import ROOT, read_csv

    whtc = read_csv(ROOT / "data" / "whtc_inputs_10hz.csv")
    one = mvem.simulate_many([whtc], dt=10.0)[0]
    t0 = time.perf_counter()
    mvem.simulate_many([whtc] * 4, dt=10.0, threads=2)
    per_run = (time.perf_counter() - t0) / 2  # 4 runs on 2 threads
    n = 200  # about 100 x per_run if it were not stopped
    timer = threading.Timer(5 * per_run, _thread.interrupt_main)
    t0 = time.perf_counter()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        mvem.simulate_many([whtc] * n, dt=10.0, threads=2)
    elapsed = time.perf_counter() - t0
    timer.join()
    # stopped at the signal plus the runs in progress (2 threads): far below the 100 run-times
    # the whole ensemble takes; 25 run-times of margin for a loaded machine
    assert elapsed < 30 * per_run, (elapsed, per_run)
    again = mvem.simulate_many([whtc], dt=10.0)[0]
    assert_same(again, one)


@pytest.mark.parametrize("call", ["simulate", "closed_loop", "closed_loop_margins"])
def test_ctrl_c_stops_a_long_single_run(call, ctrl_c):
    """KeyboardInterrupt while one long run integrates (mvem.simulate of the WHTC at rtol 1e-10,
    about 20 times the default run's work; mvem.closed_loop of the whole WHTC): the integrator
    polls the cancellation before every step, so the call raises soon after the signal instead
    of finishing the run; a later call gives the same result as before. The loop margins along
    a closed-loop run (100 samples, most of the call's time) poll it before each sample."""
    import _thread
    import threading
    import time

    from conftest import ROOT, read_csv

    whtc = read_csv(ROOT / "data" / "whtc_inputs_10hz.csv")
    if call == "simulate":
        run = lambda: mvem.simulate(whtc, rtol=1e-10, atol=1e-10, dt=1.0)  # noqa: E731
        last = lambda r: r["p_im"][-1]  # noqa: E731
    elif call == "closed_loop":
        run = lambda: mvem.closed_loop("whtc")  # noqa: E731
        last = lambda r: r["trajectory"]["p_im"][-1]  # noqa: E731
    else:
        run = lambda: mvem.closed_loop("whtc", duration=200.0, margins=2.0)  # noqa: E731
        last = lambda r: r["margins"]["samples"][-1]  # noqa: E731
    t0 = time.perf_counter()
    full = run()
    t_full = time.perf_counter() - t0
    timer = threading.Timer(0.1 * t_full, _thread.interrupt_main)
    t0 = time.perf_counter()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        run()
    elapsed = time.perf_counter() - t0
    timer.join()
    print(f"{call}: full run {t_full:.2f} s, interrupted at 10 % returned after {elapsed:.2f} s")
    # the signal at 10 % of the run; without the integrator's check the call ran to its end
    assert elapsed < 0.6 * t_full, (elapsed, t_full)
    assert last(run()) == last(full)


def test_on_error_return_gives_bad_parameters_and_start_states_their_slot():
    """QA: on_error="return" raised for an invalid parameter value of one run. Each run whose
    parameters, inputs or x0 cannot be used comes back as its ValueError ("run i: ..."), the
    others are run; with "raise" the first such run is raised before any run starts."""
    m = mvem.Model()
    s = mvem.steady(1500.0, 110.0, 80.0, 75.0)
    x_ss = [s[n] for n in m.state_names]
    inputs = [vgt_step(65.0), vgt_step(60.0), {"time_s": [0.0, 1.0]}, vgt_step(55.0),
              vgt_step(50.0)]
    params = [None, {"cylinder.n_cyl": 6.5}, None, {"cylinder.c_vol[0]": 1.0}, None]
    x0 = [None, None, None, None, x_ss[:7]]
    out = mvem.simulate_many(inputs, params=params, x0=x0, on_error="return", threads=2)
    assert len(out) == 5
    assert_same(out[0], mvem.simulate(inputs[0]))
    assert isinstance(out[1], ValueError)
    assert str(out[1]).startswith("run 1: invalid parameters: 1 invalid parameter(s):")
    assert "cylinder.n_cyl = 6.5: a number of cylinders must be a whole number" in str(out[1])
    assert isinstance(out[2], ValueError) and str(out[2]).startswith(
        "run 2: inputs: missing column `n_e_rpm`")
    assert isinstance(out[3], ValueError) and str(out[3]).startswith(
        "run 3: parameter `cylinder.c_vol[0]`: indices are 1-based")
    assert isinstance(out[4], ValueError) and "run 4: x0: expected 8 values" in str(out[4])
    with pytest.raises(ValueError, match=r"^run 1: invalid parameters"):
        mvem.simulate_many(inputs, params=params, x0=x0)
    # a parameter set shared by every run is the call's error, whatever on_error
    with pytest.raises(ValueError, match=r"^invalid parameters"):
        mvem.simulate_many(inputs[:1], params={"cylinder.n_cyl": 6.5}, on_error="return")


def test_start_states_outside_the_limits_warn_per_run():
    m = mvem.Model()
    s = mvem.steady(1500.0, 110.0, 80.0, 75.0)
    x = {n: s[n] for n in m.state_names}
    x["omega_t"] = 1e9
    with pytest.warns(UserWarning, match=r"^simulate_many run 1: x0: omega_t: 1000000000 is "
                                         r"outside the integrator limits \[10.47"):
        out = mvem.simulate_many([vgt_step(65.0)] * 2, x0=[None, x])
    assert out[1]["omega_t"][0] == pytest.approx(20943.951023931953, rel=1e-12)
