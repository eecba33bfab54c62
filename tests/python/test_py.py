"""The Python package mvem (crates/mvem-py) against the reference data.

Build it first: `maturin develop --release -m crates/mvem-py/Cargo.toml` (scripts/test-python.sh).
"""

import csv
import math
import pathlib
import threading

import numpy as np
import pytest

mvem = pytest.importorskip("mvem")

ROOT = pathlib.Path(__file__).resolve().parents[2]
REF = ROOT / "tests" / "reference"

STEP = {
    "time_s": [0.0, 1.0, 1.0, 8.0],
    "n_e_rpm": [1500.0] * 4,
    "u_delta_mg": [110.0] * 4,
    "u_egr_pct": [80.0] * 4,
    "u_vgt_pct": [75.0, 75.0, 65.0, 65.0],
}


def test_steady_matches_reference_table():
    ref = np.genfromtxt(REF / "steady_states.csv", delimiter=",", names=True, dtype=None,
                        encoding="utf-8")
    cols = ["p_im", "p_em", "X_Oim", "X_Oem", "omega_t", "W_c", "W_egr", "lambda_O", "M_e",
            "T_em", "n_t"]
    worst = 0.0
    for row in ref[::3]:  # every third point: 30 of 90, keeps the test fast
        s = mvem.steady(row["n_e_rpm"], row["u_delta_mg"], row["u_egr_pct"], row["u_vgt_pct"])
        for c in cols:
            scale = max(abs(row[c]), 1e-9)
            worst = max(worst, abs(s[c] - row[c]) / scale)
        assert s["physically_valid"] == (str(row["physically_valid"]) == "True")
    assert worst < 1e-6, worst


def test_steady_is_deterministic():
    a = mvem.steady(1500, 110, 80, 75)
    b = mvem.steady(1500, 110, 80, 75)
    assert a == b
    assert a["n_e_rpm"] == 1500 and a["u_vgt_pct"] == 75


def test_simulate_matches_reference_step():
    ref = np.genfromtxt(REF / "step_vgt_75_to_65.csv", delimiter=",", names=True)
    r = mvem.simulate(STEP, rtol=1e-8)
    assert np.allclose(r["t"], ref["t"], rtol=0, atol=1e-12)
    for c in ["p_im", "p_em", "W_c", "n_t", "x_egr", "lambda_O", "M_e", "T_em", "W_egr"]:
        scale = np.maximum(np.abs(ref[c]), 1e-6 * np.max(np.abs(ref[c])))
        err = np.max(np.abs(r[c] - ref[c]) / scale)
        assert err < 1e-4, (c, err)


def test_numeric_actuators_agree_with_the_closed_form():
    # the actuator states in closed form (default) against all states integrated numerically
    a = mvem.simulate(STEP, rtol=1e-9)
    b = mvem.simulate(STEP, rtol=1e-9, numeric_actuators=True)
    # before the step the actuator state holds its steady value
    t = a["t"]
    lag = a["u_vgt_act"]
    assert np.max(np.abs(lag[t < 1.0] - 75.0)) < 1e-9
    for c, scale in [("p_im", 1e5), ("p_em", 1e5), ("omega_t", 1e4), ("u_vgt_act", 100.0)]:
        assert np.max(np.abs(a[c] - b[c])) / scale < 1e-6, c
    assert not np.array_equal(a["p_em"], b["p_em"])  # really two different integrations


def test_simulate_array_input_equals_dict_input():
    arr = np.column_stack([STEP[k] for k in mvem.INPUT_COLUMNS])
    a = mvem.simulate(arr, t_end=3.0)
    b = mvem.simulate(STEP, t_end=3.0)
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k]), k  # same library call: identical to the last bit
    assert a["t"][-1] == 3.0


def test_params_dict_and_file():
    base = mvem.steady(1500, 110, 80, 75)
    p = mvem.published_params()
    assert p["turbo"]["j_t"] > 0
    # overriding a parameter with its own value changes nothing
    same = mvem.steady(1500, 110, 80, 75, params={"turbo.j_t": p["turbo"]["j_t"]})
    assert same == base
    # the inertia does not move the steady state, the ambient pressure does
    hi = mvem.steady(1500, 110, 80, 75, params={"ambient": {"p_amb": 1.1e5}})
    assert abs(hi["p_im"] / base["p_im"] - 1) > 5e-3
    f = mvem.steady(1500, 110, 80, 75, params=str(ROOT / "crates" / "mvem" / "data" / "published.toml"))
    assert f == base


def test_metadata_names_every_column_and_parameter():
    # every column of a simulation has a unit and description in the core's metadata
    out = mvem.simulate(STEP, model=12)
    meta = mvem.variables()
    for name in out:
        assert meta[name]["unit"] and meta[name]["description"], name
    assert meta["T_em_in"]["unit"] == "K"
    assert meta["omega_t"] == {**meta["omega_t"], "kind": "state", "unit": "rad/s"}
    # the parameter registry agrees with the published set
    p = mvem.published_params()
    params = {q["path"]: q for q in mvem.parameters()}
    assert params["turbo.j_t"]["published"] == p["turbo"]["j_t"]
    assert params["cylinder.c_vol[2]"]["published"] == p["cylinder"]["c_vol"][1]
    assert params["compressor.q_c[1][2]"]["symbol"] == "a3"


def test_fmu_start_value_agrees_with_python_params():
    fmpy = pytest.importorskip("fmpy")
    import os
    fmu = os.environ.get("MVEM_FMU")
    if not fmu:
        pytest.skip("MVEM_FMU not set (scripts/test-python.sh sets it)")
    r = fmpy.simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=0.1, output=["p_im", "W_c"],
                          start_values={"ambient.p_amb": 1.1e5})
    s = mvem.steady(1500, 110, 80, 75, params={"ambient": {"p_amb": 1.1e5}})
    assert r["p_im"][0] == pytest.approx(s["p_im"], rel=1e-12)
    assert r["W_c"][0] == pytest.approx(s["W_c"], rel=1e-12)


@pytest.mark.parametrize("call,exc,msg", [
    (lambda: mvem.steady(float("nan"), 110, 80, 75), ValueError, "n_e = NaN"),
    (lambda: mvem.steady(1500, 110, 80, 75, params={"turbo": {"jt": 1}}), ValueError, "turbo.jt"),
    (lambda: mvem.steady(1500, 110, 80, 75, params={"turbo": {"j_t": -1.0}}), ValueError, "j_t"),
    (lambda: mvem.steady(1500, 110, 80, 75, params="/nonexistent.toml"), ValueError, "nonexistent"),
    (lambda: mvem.simulate({"time_s": [0, 1]}), ValueError, "n_e_rpm"),
    (lambda: mvem.simulate(np.zeros((3, 4))), ValueError, "5 columns"),
    (lambda: mvem.simulate({**STEP, "u_vgt_pct": [75, 75, float("nan"), 65]}), ValueError, "u_vgt"),
    (lambda: mvem.simulate({**STEP, "time_s": [0, 2, 1, 8]}), ValueError, "time"),
    (lambda: mvem.simulate(STEP, rtol=-1), ValueError, "rtol"),
    (lambda: mvem.simulate(STEP, dt=0), ValueError, "dt"),
    (lambda: mvem.simulate(STEP, t_end=float("nan")), ValueError, "t_end"),
    # 1e8 output rows would take hours and tens of GB: refused before anything runs
    (lambda: mvem.simulate(STEP, t_end=1e6), ValueError, "1.000e8 output rows"),
])
def test_bad_input_raises(call, exc, msg):
    with pytest.raises(exc, match=msg):
        call()


def test_solver_failure_is_runtime_error_not_crash():
    # far outside the model's range: either a clean RuntimeError or a finite result, never a crash
    try:
        with pytest.warns(UserWarning, match=r"u_delta_mg is outside its range \[1, 250\] at 2 of 4 input rows \(2 above, up to 1000000\)"):
            r = mvem.simulate({**STEP, "u_delta_mg": [110, 110, 1e6, 1e6]}, t_end=2.0)
    except RuntimeError as e:
        assert str(e)
    else:
        assert all(np.all(np.isfinite(v)) for v in r.values())


def test_releases_the_gil():
    # While simulate runs in a worker thread, the main thread keeps executing Python only if the
    # GIL is released: it spins and counts. With the GIL held during the Rust call the count
    # would stay at the few iterations before and after it (independent of machine speed).
    worker = threading.Thread(
        target=lambda: mvem.simulate(STEP, rtol=1e-10, dt=0.001, t_end=40.0))
    count = 0
    worker.start()
    while worker.is_alive():
        count += 1
    worker.join()
    assert count > 1000, count


def test_results_are_numpy_float_arrays():
    r = mvem.simulate(STEP, t_end=0.05)
    assert isinstance(r["W_c"], np.ndarray) and r["W_c"].dtype == np.float64
    assert not math.isnan(r["W_c"][0])


# ---------------------------------------------------------------------------------------------
# Model order, linearization and step metrics

import json  # noqa: E402
import subprocess  # noqa: E402

from conftest import read_csv  # noqa: E402

POINT = (1500.0, 110.0, 80.0, 75.0)


@pytest.mark.parametrize("model", [10, 12])
def test_simulate_model_order_equals_cli(mvem_cli, tmp_path, model):
    # the Python call and `mvem simulate --model N` run the same library code: equal to 1e-12
    out = tmp_path / "cli.csv"
    subprocess.run([mvem_cli, "simulate", "--scenario", "vgt-step-nmp", "--model", str(model),
                    "--out", str(out)], check=True, capture_output=True)
    cli = read_csv(out)
    r = mvem.simulate(STEP, model=model)
    for c in ["p_im", "p_em", "T_im", "T_em", "W_c", "n_t", "x_egr", "lambda_O", "M_e", "W_egr"]:
        scale = np.maximum(np.abs(cli[c]), 1e-300)
        assert np.max(np.abs(r[c] - cli[c]) / scale) <= 1e-12, c
    if model == 12:
        assert np.max(np.abs(r["T_ic"] / cli["T_ic"] - 1)) <= 1e-12


def test_time_parallel_equals_cli_and_agrees_with_sequential(mvem_cli, tmp_path):
    # two time chunks (docs/integrator.md): the library call of `mvem simulate --time-parallel
    # 2` (equal to 1e-12) and within 1e-7 of the sequential run, on 300 s of the WHTC
    whtc = read_csv(ROOT / "data" / "whtc_inputs_10hz.csv")
    out = tmp_path / "cli.csv"
    subprocess.run([mvem_cli, "simulate", "--scenario", "whtc", "--t-end", "300", "--dt", "0.1",
                    "--time-parallel", "2", "--out", str(out)], check=True, capture_output=True)
    cli = read_csv(out)
    par = mvem.simulate(whtc, t_end=300.0, dt=0.1, time_parallel=2)
    seq = mvem.simulate(whtc, t_end=300.0, dt=0.1)
    assert np.array_equal(par["t"], seq["t"])
    for c in ["p_im", "p_em", "omega_t", "W_c", "M_e"]:
        scale = np.maximum(np.abs(cli[c]), 1e-3)
        assert np.max(np.abs(par[c] - cli[c]) / scale) <= 1e-12, c
        assert np.max(np.abs(par[c] - seq[c]) / scale) <= 1e-7, c
    assert not np.array_equal(par["p_im"], seq["p_im"])  # really the time-parallel run


@pytest.mark.parametrize("model", [8, 12])
def test_steady_model_order_equals_cli(mvem_cli, model):
    p = subprocess.run([mvem_cli, "steady", "--n-e", "1500", "--u-delta", "110", "--u-egr", "80",
                        "--u-vgt", "75", "--model", str(model), "--json"],
                       check=True, capture_output=True, text=True)
    cli = json.loads(p.stdout)
    s = mvem.steady(*POINT, model=model)
    compared = 0
    for k, v in cli.items():
        if isinstance(v, float) and k in s:
            assert s[k] == pytest.approx(v, rel=1e-12, abs=1e-300), k
            compared += 1
    assert compared >= model + 30


@pytest.fixture(scope="module")
def lin():
    return mvem.linearize(*POINT)


def test_linearize_operating_point_equals_steady_and_cli(mvem_cli, lin):
    s = mvem.steady(*POINT)
    assert lin["state_names"] == ["p_im", "p_em", "X_Oim", "X_Oem", "omega_t", "u_egr1", "u_egr2",
                                  "u_vgt_act"]
    assert lin["input_names"] == ["u_delta", "u_egr", "u_vgt", "n_e"]
    for n, v in zip(lin["state_names"], lin["x0"]):
        assert v == s[n], n
    for n, v in zip(lin["output_names"], lin["y0"]):
        assert v == s[n], n
    assert list(lin["u0"]) == [110.0, 80.0, 75.0, 1500.0]
    p = subprocess.run([mvem_cli, "steady", "--n-e", "1500", "--u-delta", "110", "--u-egr", "80",
                        "--u-vgt", "75", "--json"], check=True, capture_output=True, text=True)
    cli = json.loads(p.stdout)
    for n, v in zip(lin["state_names"], lin["x0"]):
        assert v == pytest.approx(cli[n], rel=1e-12), n
    # the CLI's eigenvalues come from the steady-state solver's own forward-difference Jacobian
    # of the non-actuator states: each is a pole of the linear model to that accuracy (1e-7
    # forward steps: ~1e-5 relative); the other poles are the actuators' -1/tau
    ev = lin["eigenvalues"]
    for e in cli["eigenvalues"]:
        z = e["re"] + 1j * e["im"]
        assert np.min(np.abs(ev - z)) < 1e-4 * abs(z), z


def test_linearize_matrices_are_consistent(lin):
    a, b, c, d = lin["A"], lin["B"], lin["C"], lin["D"]
    assert a.shape == (8, 8) and b.shape == (8, 4) and c.shape == (7, 8) and d.shape == (7, 4)
    assert a.dtype == np.float64 and lin["eigenvalues"].dtype == np.complex128
    # eigenvalues: numpy's LAPACK on the same A (independent algorithm)
    ev = np.sort_complex(lin["eigenvalues"])
    ev_np = np.sort_complex(np.linalg.eigvals(a))
    assert np.max(np.abs(ev - ev_np) / np.abs(ev_np)) < 1e-9
    assert np.all(ev.real < 0)
    # DC gain = D - C A^-1 B
    g = d - c @ np.linalg.solve(a, b)
    assert np.max(np.abs(lin["dc_gain"] - g)) <= 1e-9 * np.max(np.abs(g))
    # ... and the slope of the steady states (central difference in u_vgt, +-0.5 %)
    hi, lo = mvem.steady(1500, 110, 80, 75.5), mvem.steady(1500, 110, 80, 74.5)
    k = lin["input_names"].index("u_vgt")
    for o, name in enumerate(lin["output_names"]):
        fd = (hi[name] - lo[name]) / 1.0
        assert lin["dc_gain"][o, k] == pytest.approx(fd, rel=1e-3, abs=1e-9 * abs(lin["y0"][o])), name


def test_linearize_zeros_are_zeros_of_the_channel(lin):
    # u_vgt -> W_c at the demo point: non-minimum phase (the wrong-way W_c response of the demo)
    z = lin["zeros"]["u_vgt->W_c"]
    assert np.any(z.real > 0)
    a = lin["A"]
    k = lin["input_names"].index("u_vgt")
    o = lin["output_names"].index("W_c")
    b, c, d = lin["B"][:, [k]], lin["C"][[o], :], lin["D"][[o]][:, [k]]
    # G(s) = C (sI - A)^-1 B + D vanishes at a transmission zero (relative to |G| nearby)
    for zi in z:
        g = (c @ np.linalg.solve(zi * np.eye(8) - a, b) + d)[0, 0]
        g_near = (c @ np.linalg.solve((zi + 1.0) * np.eye(8) - a, b) + d)[0, 0]
        assert abs(g) < 1e-5 * abs(g_near), zi
    assert set(lin["zeros"]) == {f"{i}->{o}" for i in lin["input_names"]
                                 for o in lin["output_names"]}
    assert lin["mimo_zeros"] is not None


def test_linearize_twelve_states_and_pade():
    r = mvem.linearize(*POINT, model=12, outputs=["W_c", "T_em", "p_c"], pade_order=2)
    assert r["A"].shape == (16, 16)  # 12 states + 2 x 2 Pade states
    assert r["output_names"] == ["W_c", "T_em", "p_c"]
    assert r["mimo_zeros"] is None  # M_e, x_egr, lambda_O not among the outputs
    p = mvem.published_params()
    assert r["delays"] == [p["egr_actuator"]["tau_degr"], p["vgt_actuator"]["tau_dvgt"]]


def test_step_response_equals_cli_demo(mvem_cli, tmp_path):
    subprocess.run([mvem_cli, "demo", "--out", str(tmp_path)], check=True, capture_output=True)
    cli = read_csv(tmp_path / "vgt_step_75_to_65.csv")
    r = mvem.step_response(*POINT, input="u_vgt", to=65.0, output="W_c", t_step=1.0, t_end=8.0)
    assert np.array_equal(r["t"], cli["t"])
    assert np.max(np.abs(r["y"] - cli["W_c"]) / np.abs(cli["W_c"])) <= 1e-12
    # the metrics are those of samples 5 ms apart (whatever dt) with the steady states as end
    # points
    y0 = mvem.steady(*POINT)["W_c"]
    y1 = mvem.steady(1500, 110, 80, 65)["W_c"]
    fine = mvem.step_response(*POINT, input="u_vgt", to=65.0, output="W_c", t_step=1.0,
                              t_end=8.0, dt=0.005)
    m = mvem.step_metrics(fine["t"], fine["y"], 1.0, y0, y1, -10.0)
    for k in ["y0", "y_final", "change", "dc_gain", "overshoot_pct", "rise_time",
              "settling_time"]:
        assert r[k] == pytest.approx(m[k], rel=1e-12, abs=1e-15), k
    assert r["wrong_way"]["value"] == pytest.approx(m["wrong_way"]["value"], rel=1e-12)
    assert r["non_minimum_phase"] and r["gain_sign"] == "negative"
    # the sign of the DC gain agrees with the linear model's
    lin = mvem.linearize(*POINT)
    g = lin["dc_gain"][lin["output_names"].index("W_c"), lin["input_names"].index("u_vgt")]
    assert np.sign(g) == np.sign(r["dc_gain"])


def test_step_metrics_of_a_first_order_response():
    # y = 1 - exp(-(t - 1)) after a unit step at t = 1: rise time ln 9, settling ln 50, no
    # overshoot, no wrong way (linear interpolation between samples: O(dt^2) in z -> 1e-6 s)
    t = np.arange(0, 30, 1e-3)
    y = np.where(t < 1, 0.0, 1 - np.exp(-(t - 1)))
    m = mvem.step_metrics(t, y, 1.0, 0.0, 1.0, 1.0)
    assert m["rise_time"] == pytest.approx(math.log(9), abs=1e-6)
    assert m["settling_time"] == pytest.approx(math.log(50), abs=1e-6)
    assert m["overshoot_pct"] == 0.0 and m["peak"] is None and m["wrong_way"] is None
    assert m["gain_sign"] == "positive" and m["dc_gain"] == 1.0


@pytest.mark.parametrize("call,exc,msg", [
    (lambda: mvem.linearize(float("nan"), 110, 80, 75), ValueError, "n_e = NaN"),
    (lambda: mvem.linearize(*POINT, model=9), ValueError, "model = 9"),
    (lambda: mvem.linearize(*POINT, outputs=["W_x"]), ValueError, "unknown output \"W_x\""),
    (lambda: mvem.linearize(*POINT, outputs=[]), ValueError, "at least one output"),
    (lambda: mvem.linearize(*POINT, pade_order=7), ValueError, "pade_order"),
    (lambda: mvem.linearize(*POINT, params={"turbo": {"jt": 1}}), ValueError, "turbo.jt"),
    (lambda: mvem.simulate(STEP, model=11), ValueError, "model = 11"),
    (lambda: mvem.simulate(STEP, cylinder_temp="twice"), ValueError, "cylinder_temp"),
    (lambda: mvem.steady(*POINT, model=0), ValueError, "model = 0"),
    (lambda: mvem.step_metrics([0, 1], [1, 2, 3], 0, 1, 2, 1), ValueError, "differ in length"),
    (lambda: mvem.step_metrics([[0, 1]], [1, 2], 0, 1, 2, 1), ValueError, "1-D"),
    (lambda: mvem.step_metrics([0, 1], [1, np.nan], 0, 1, 2, 1), ValueError, "non-finite"),
    (lambda: mvem.step_metrics([0, 1], [1, 2], 0, 1, 1, 1), ValueError, "zero final change"),
    (lambda: mvem.step_response(*POINT, input="u_x"), ValueError, "input \"u_x\""),
    (lambda: mvem.step_response(*POINT, output="W_x"), ValueError, "output \"W_x\""),
    (lambda: mvem.step_response(*POINT, t_step=5, t_end=2), ValueError, "t_step"),
    (lambda: mvem.step_response(*POINT, to=float("inf")), ValueError, "to = inf"),
    (lambda: mvem.step_response(*POINT, t_end=1e6), ValueError, "output rows"),
])
def test_bad_input_raises_with_rust_message(call, exc, msg):
    with pytest.raises(exc, match=msg.replace("(", r"\(")):
        call()


def test_wrong_types_raise_type_error_not_crash():
    with pytest.raises(TypeError):
        mvem.linearize("fast", 110, 80, 75)
    with pytest.raises(TypeError):
        mvem.linearize(*POINT, outputs="W_c")  # a str is not a list of names


def test_linearize_runs_in_parallel_threads():
    # the GIL is released: four threads give the same results as one call
    from concurrent.futures import ThreadPoolExecutor
    pts = [(1500, 110, 80, u) for u in (60, 65, 70, 75)]
    with ThreadPoolExecutor(4) as ex:
        par = list(ex.map(lambda p: mvem.linearize(*p)["A"], pts))
    for p, a in zip(pts, par):
        assert np.array_equal(a, mvem.linearize(*p)["A"])


def test_parquet_output_equals_csv_and_reads_with_pyarrow(mvem_cli, tmp_path):
    """`mvem simulate --out X.parquet` holds the same columns and values as the CSV (to 1e-12
    relative; the CSV's shortest round-trip numbers read back exactly), readable by pyarrow;
    `--signals` selects the columns after `t`."""
    pq = pytest.importorskip("pyarrow.parquet")
    args = [mvem_cli, "simulate", "--scenario", "vgt-step-nmp"]
    subprocess.run(args + ["--out", str(tmp_path / "s.csv")], check=True, capture_output=True)
    subprocess.run(args + ["--out", str(tmp_path / "s.parquet")], check=True,
                   capture_output=True)
    with open(tmp_path / "s.csv", newline="") as f:
        names = next(csv.reader(f))
    c = read_csv(tmp_path / "s.csv")
    t = pq.read_table(tmp_path / "s.parquet")
    assert t.column_names == names
    for n in names:
        a, b = c[n], t.column(n).to_numpy()
        assert a.shape == b.shape and np.all(np.abs(a - b) <= 1e-12 * np.maximum(1.0, np.abs(a))), n
    sel = ["W_c", "lambda_O", "p_im"]
    subprocess.run(args + ["--out", str(tmp_path / "sel.parquet"), "--signals", ",".join(sel)],
                   check=True, capture_output=True)
    t2 = pq.read_table(tmp_path / "sel.parquet")
    assert t2.column_names == ["t"] + sel
    assert np.array_equal(t2.column("W_c").to_numpy(), t.column("W_c").to_numpy())


def test_linearize_sampled_with_exact_delays(mvem_cli):
    """linearize(ts=...): the sampled model (the CLI's --ts to the bit), its delay registers, and
    its DC gain C (I - Phi)^-1 Gamma + D equal to the continuous one (the delays and the hold
    do not change a steady gain)."""
    lin = mvem.linearize(1500, 110, 40, 75, ts=0.02)
    dv = lin["discrete"]
    assert dv["ts"] == 0.02
    assert dv["input_names"] == lin["input_names"] and dv["output_names"] == lin["output_names"]
    assert dv["state_names"][8:] == ["u_egr(k-1)", "u_egr(k-2)", "u_egr(k-3)", "u_egr(k-4)",
                                     "u_vgt(k-1)", "u_vgt(k-2)"]
    (egr_l, egr_r), (vgt_l, vgt_r) = dv["delay_samples"]
    assert (egr_l, vgt_l, vgt_r) == (3, 2, 0.0) and egr_r == pytest.approx(0.005, abs=1e-12)
    phi, gamma, c, d = dv["Phi"], dv["Gamma"], dv["C"], dv["D"]
    assert phi.shape == (14, 14) and gamma.shape == (14, 4) and c.shape == (7, 14)
    assert np.all(np.abs(np.linalg.eigvals(phi)) < 1.0)
    dc = c @ np.linalg.solve(np.eye(14) - phi, gamma) + d
    np.testing.assert_allclose(dc, lin["dc_gain"], rtol=1e-6,
                               atol=1e-9 * np.abs(lin["dc_gain"]).max())
    # over the whole range of sample times and for the 12-state model too (measured <= 4e-13
    # of each output's largest gain)
    for model, ts in [(8, 0.001), (8, 100.0), (12, 0.001), (12, 0.05), (12, 100.0)]:
        lm = mvem.linearize(1500, 110, 40, 75, ts=ts, model=model)
        dm = lm["discrete"]
        n = dm["Phi"].shape[0]
        dc = dm["C"] @ np.linalg.solve(np.eye(n) - dm["Phi"], dm["Gamma"]) + dm["D"]
        g = lm["dc_gain"]
        err = np.max(np.abs(dc - g) / np.abs(g).max(axis=1, keepdims=True))
        assert err < 1e-10, (model, ts, err)
    p = subprocess.run([mvem_cli, "linearize", "--n-e", "1500", "--u-delta", "110", "--u-egr", "40",
                        "--u-vgt", "75", "--ts", "0.02", "--json"],
                       check=True, capture_output=True, text=True)
    cli = json.loads(p.stdout)["discrete"]
    np.testing.assert_array_equal(np.array(cli["Phi"]), phi)
    np.testing.assert_array_equal(np.array(cli["Gamma"]), gamma)
    assert "discrete" not in mvem.linearize(1500, 110, 40, 75)
    for bad in (0.0, 1e-4, float("nan")):
        with pytest.raises(ValueError, match="ts"):
            mvem.linearize(1500, 110, 40, 75, ts=bad)
    with pytest.raises(ValueError, match="pade_order"):
        mvem.linearize(1500, 110, 40, 75, ts=0.02, pade_order=2)


def test_loop_margins_equal_the_cli(mvem_cli):
    """loop_margins: the dict of `mvem margins --json` to the bit, a tuning dict reaches it (the
    x_egr -> u_vgt gains doubled halve that loop's gain margin), bad arguments are ValueErrors."""
    m = mvem.loop_margins(1500, 110, 50, 60)
    p = subprocess.run([mvem_cli, "margins", "--n-e", "1500", "--u-delta", "110", "--u-egr", "50",
                        "--u-vgt", "60", "--json"], check=True, capture_output=True, text=True)
    assert m == json.loads(p.stdout)
    assert m["stable"] and [l["name"] for l in m["loops"]] == ["lambda_O->u_egr", "x_egr->u_vgt"]
    gm = m["loops"][1]["alone"]["gain_margin"]
    assert 2.0 < gm < 4.0
    doubled = mvem.loop_margins(1500, 110, 50, 60, tuning={"x_egr_vgt": [300.0, 1600.0]})
    assert doubled["loops"][1]["alone"]["gain_margin"] == pytest.approx(gm / 2, rel=1e-8)
    with pytest.raises(ValueError, match="u_egr"):
        mvem.loop_margins(1500, 110, float("nan"), 60)
    with pytest.raises(ValueError, match="tuning"):
        mvem.loop_margins(1500, 110, 50, 60, tuning={"no_such_field": 1.0})
    with pytest.raises(ValueError, match="tuning"):
        mvem.loop_margins(1500, 110, 50, 60, tuning=[1, 2])


def test_frequency_response_with_exact_delays(mvem_cli):
    """frequency_response: the CLI's --bode to the bit; the fuel path equal to C (jwI - A)^-1 B
    + D of linearize's matrices, u_vgt -> W_c to the undelayed response times e^(-jw tau) (the
    delays exact); f = 0 gives the DC gains; bad frequencies are ValueErrors."""
    f = np.logspace(-2, 2, 25)
    fr = mvem.frequency_response(1500, 110, 80, 75, f, strict=False)
    assert fr["input_names"] == ["u_delta", "u_egr", "u_vgt", "n_e"]
    np.testing.assert_array_equal(fr["f_hz"], f)
    lin = mvem.linearize(1500, 110, 80, 75, strict=False)
    a, b, c, d = lin["A"], lin["B"], lin["C"], lin["D"]
    n = a.shape[0]
    w = 2 * np.pi * f
    und = np.array([c @ np.linalg.solve(1j * wk * np.eye(n) - a, b) + d for wk in w])
    o = lin["output_names"].index("W_c")
    tau_vgt = fr["delays"][1]
    np.testing.assert_allclose(fr["G"]["u_delta->W_c"], und[:, o, 0], rtol=1e-8)
    np.testing.assert_allclose(fr["G"]["u_vgt->W_c"], und[:, o, 2] * np.exp(-1j * w * tau_vgt),
                               rtol=1e-8)
    p = subprocess.run([mvem_cli, "linearize", "--n-e", "1500", "--u-delta", "110", "--u-egr", "80",
                        "--u-vgt", "75", "--bode", "0.01:100:25", "--json"],
                       check=True, capture_output=True, text=True)
    cli = json.loads(p.stdout)["frequency_response"]["channels"]["u_vgt->W_c"]
    g = fr["G"]["u_vgt->W_c"]
    np.testing.assert_allclose(np.abs(g), cli["mag"], rtol=1e-12)
    np.testing.assert_allclose(g.real, cli["re"], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(fr["phase_deg"]["u_vgt->W_c"], cli["phase_deg"], rtol=1e-12)
    # the phase of three points a decade apart is the fine grid's (continuous, not wrapped)
    coarse = mvem.frequency_response(1500, 110, 80, 75, [0.01, 1.0, 100.0], strict=False)
    np.testing.assert_allclose(coarse["phase_deg"]["u_vgt->W_c"],
                               fr["phase_deg"]["u_vgt->W_c"][[0, 12, 24]], atol=1e-9)
    dc = mvem.frequency_response(1500, 110, 80, 75, [0.0], strict=False)["G"]
    np.testing.assert_allclose(dc["u_vgt->W_c"].real, lin["dc_gain"][o, 2], rtol=1e-9)
    for bad, msg in [([1.0, 0.5], "strictly increasing"), ([float("nan")], "f_hz"), ([], "points")]:
        with pytest.raises(ValueError, match=msg):
            mvem.frequency_response(1500, 110, 80, 75, bad)


def test_x0_outside_the_integrator_limits_warns_naming_state_value_and_limit():
    """QA: x0 outside the integrator limits was clipped silently; simulate warns as the CLI's
    `simulate --initial-state` does (one UserWarning per state) and starts from the limit."""
    m = mvem.Model()
    s = mvem.steady(*POINT)
    x0 = {n: s[n] for n in m.state_names}
    x0["p_im"] = 1e8
    with pytest.warns(UserWarning) as rec:
        r = mvem.simulate(STEP, x0=x0)
    msgs = [str(w.message) for w in rec if "x0" in str(w.message)]
    assert len(msgs) == 1
    assert msgs[0].startswith("simulate: x0: p_im: 100000000 is outside the integrator limits [")
    hi = float(msgs[0].split(", ")[1].split("]")[0])
    assert r["p_im"][0] == hi and msgs[0].endswith(f"the simulation starts from {msgs[0].split()[-1]}")
    # inside the limits: no warning
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mvem.simulate(STEP, x0={n: s[n] for n in m.state_names})


@pytest.mark.parametrize("call,msg", [
    (lambda: mvem.simulate(STEP, time_parallel=-1), "time_parallel = -1: expected an integer in [1, 256]"),
    (lambda: mvem.simulate(STEP, time_parallel=2**70), "time_parallel = 1180591620717411303424"),
    (lambda: mvem.linearize(*POINT, pade_order=-1), "pade_order = -1: expected an integer in [0, 3]"),
    (lambda: mvem.simulate_many([STEP], threads=-1), "threads = -1: expected an integer in [1, 1024]"),
    (lambda: mvem.steady(*POINT, model=-2**70), "model = -1180591620717411303424: expected 8, 10 or 12"),
    (lambda: mvem.Plant(*POINT, model=2**64), "model = 18446744073709551616"),
    (lambda: mvem.Model(model=-1), "model = -1"),
])
def test_integer_arguments_out_of_range_raise_value_error(call, msg):
    """QA: negative (or huge) ints gave OverflowError; every integer argument raises ValueError
    naming the argument, the value and the allowed values."""
    with pytest.raises(ValueError) as e:
        call()
    assert str(e.value).startswith(msg), str(e.value)
    assert not isinstance(e.value, OverflowError)


def test_indexed_parameters_are_one_based_everywhere():
    """parameters() names elements 1-based (cylinder.c_vol[1] is c_vol1, as the FMU and
    `mvem params show`); params overrides take those names, refuse index 0 saying which element
    is meant, and validation messages name elements the same way."""
    names = {p["path"]: p for p in mvem.parameters()}
    assert names["cylinder.c_vol[1]"]["symbol"] == "c_vol1"
    c_vol = mvem.published_params()["cylinder"]["c_vol"]
    a = mvem.steady(*POINT, params={"cylinder.c_vol[3]": c_vol[2] * 1.01})
    b = mvem.steady(*POINT, params={"cylinder": {"c_vol": [c_vol[0], c_vol[1], c_vol[2] * 1.01]}})
    assert a["W_c"] == b["W_c"] != mvem.steady(*POINT)["W_c"]
    with pytest.raises(ValueError, match=r"cylinder.c_vol\[0\]`: indices are 1-based.*"
                                         r"cylinder.c_vol\[1\] \(c_vol1\)"):
        mvem.steady(*POINT, params={"cylinder.c_vol[0]": 1.0})
    with pytest.raises(ValueError, match=r"egr_valve.c_egr\[1\] = 1: c_egr1 must be < 0"):
        mvem.steady(*POINT, params={"egr_valve.c_egr[1]": 1.0})


def test_a_non_finite_parameter_value_is_named():
    """NaN or infinity in a params mapping is refused naming the parameter (JSON has no such
    numbers: it was "not a JSON-like mapping: expected value at line 1 column 23")."""
    with pytest.raises(ValueError, match=r"^params: `cylinder.c_vol\[1\]` = NaN is not a finite number"):
        mvem.steady(*POINT, params={"cylinder.c_vol[1]": float("nan")})
    with pytest.raises(ValueError, match=r"^params: `gas.r_a` = inf is not a finite number"):
        mvem.steady(*POINT, params={"gas": {"r_a": float("inf")}})
    with pytest.raises(ValueError, match=r"^params: `compressor.q_c\[2\]\[1\]` = -inf"):
        mvem.steady(*POINT, params={"compressor": {"q_c": [[1.0, 0.0], (float("-inf"), 1.0)]}})


def test_an_absurd_horizon_is_refused_at_once():
    """QA: t_end = 1e300 s with a coarse output grid ran for minutes before failing."""
    import time
    t = time.perf_counter()
    with pytest.raises(ValueError, match=r"^end time 1e300 s is beyond the 1e9 s"):
        mvem.simulate(STEP, t_end=1e300, dt=1e299)
    assert time.perf_counter() - t < 2.0


@pytest.mark.parametrize("call", [
    lambda: mvem.steady(1500, math.inf, 80, 75),
    lambda: mvem.linearize(1500, 110, -math.inf, 75),
    lambda: mvem.Plant(1500, 110, 80, math.inf),
])
def test_a_non_finite_input_is_refused_without_a_clamp_warning_first(call):
    """An infinite input got a UserWarning "outside [1, 250]; the authors' saturation clamps it"
    and then the ValueError "is not finite": it is refused only, as the CLI does."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="not finite|must be finite"):
            call()
