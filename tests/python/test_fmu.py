"""The mvem FMU (FMI 2.0, Model Exchange + Co-Simulation) checked with FMPy.

The FMU is taken from $MVEM_FMU (scripts/test-python.sh builds it), else built here with
`mvem fmu`; the 10- and 12-state and one-iteration FMUs are built with `mvem fmu` (the CLI and
libmvem_fmu.so from target/release, see conftest.py) and compared with `mvem simulate`.

Reference: tests/reference/step_vgt_75_to_65.csv (independent implementation, rtol 1e-9), the
authors' demo VGT step: n_e 1500 rpm, u_delta 110 mg, u_egr 80 %, u_vgt 75 -> 65 % at t = 1 s.
"""

import os
import pathlib
import subprocess

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
from fmpy import read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Model, FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
REF = ROOT / "tests" / "reference" / "step_vgt_75_to_65.csv"
OUTPUTS = ["p_im", "p_em", "W_c", "n_t", "x_egr", "lambda_O", "M_e", "T_em", "W_egr"]
# stated tolerance: 1e-4 relative (to max(|ref|, 1e-6 * max|ref| of the column))
TOL = 1e-4


def build_fmu(mvem_cli, out, *args):
    lib = ROOT / "target" / "release" / "libmvem_fmu.so"
    if not lib.is_file():
        subprocess.run(["cargo", "build", "--release", "-q", "-p", "mvem-fmu"], cwd=ROOT,
                       check=True)
    env = dict(os.environ, MVEM_FMU_LIB=os.environ.get("MVEM_FMU_LIB", str(lib)))
    subprocess.run([mvem_cli, "fmu", "--out", str(out), *args], check=True,
                   capture_output=True, env=env)
    return str(out)


@pytest.fixture(scope="session")
def fmu(tmp_path_factory, mvem_cli):
    env = os.environ.get("MVEM_FMU")
    if env:
        return env
    return build_fmu(mvem_cli, tmp_path_factory.mktemp("fmu") / "mvem.fmu")


def step_input():
    return np.array(
        [(0.0, 1500, 110, 80, 75), (1.0, 1500, 110, 80, 75),
         (1.0, 1500, 110, 80, 65), (8.0, 1500, 110, 80, 65)],
        dtype=[("time", float), ("n_e", float), ("u_delta", float), ("u_egr", float),
               ("u_vgt", float)])


def reference():
    return np.genfromtxt(REF, delimiter=",", names=True)


def max_rel_err(t, y, t_ref, y_ref):
    # the ME result also has samples at event times; compare on the reference grid
    keep = np.concatenate([[True], np.diff(t) > 0])
    yi = np.interp(t_ref, t[keep], y[keep])
    scale = np.maximum(np.abs(y_ref), 1e-6 * np.max(np.abs(y_ref)))
    return float(np.max(np.abs(yi - y_ref) / scale))


def test_fmpy_validate_reports_no_problems(fmu):
    assert validate_fmu(fmu) == []


def test_model_description_structure(fmu):
    md = read_model_description(fmu)
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.numberOfContinuousStates == 8
    names = {v.name: v for v in md.modelVariables}
    for n in ["n_e", "u_delta", "u_egr", "u_vgt"]:
        assert names[n].causality == "input"
    for n in OUTPUTS:
        assert names[n].causality == "output", n
    assert [d.variable.name for d in md.derivatives] == [
        "der(p_im)", "der(p_em)", "der(X_Oim)", "der(X_Oem)", "der(omega_t)",
        "der(u_egr1)", "der(u_egr2)", "der(u_vgt_act)"]
    # the derivatives carry their state's unit per second (QA: they had none)
    units = {u.name: u for u in md.unitDefinitions}
    for x, dx in [("p_im", "Pa/s"), ("X_Oim", "1/s"), ("omega_t", "rad/s2"),
                  ("u_vgt_act", "%/s")]:
        assert names[f"der({x})"].unit == dx, x
        assert units[dx].baseUnit.s == units[names[x].unit].baseUnit.s - 1, x
    tau = names["vgt_actuator.tau_dvgt"]
    assert tau.causality == "parameter" and tau.variability == "tunable"
    assert "[s]" in tau.description


@pytest.mark.parametrize("fmi_type,kw", [
    ("CoSimulation", {}),
    ("ModelExchange", {"solver": "CVode", "relative_tolerance": 1e-8}),
])
def test_vgt_step_matches_reference(fmu, fmi_type, kw):
    ref = reference()
    r = simulate_fmu(fmu, fmi_type=fmi_type, start_time=0.0, stop_time=8.0,
                     output_interval=0.01, input=step_input(), output=OUTPUTS, **kw)
    assert abs(r["time"][-1] - 8.0) < 1e-9
    errs = {o: max_rel_err(r["time"], r[o], ref["t"], ref[o]) for o in OUTPUTS}
    print(fmi_type, errs)
    assert max(errs.values()) < TOL, errs
    # the step is visible: W_c first dips (non-minimum phase), then settles higher
    w_c = np.interp(ref["t"], r["time"], r["W_c"])
    assert w_c[(ref["t"] >= 1) & (ref["t"] <= 2)].min() < w_c[0] - 0.003
    assert w_c[-1] > w_c[0] + 0.003


def test_parameter_start_value_changes_the_result(fmu):
    # a 10 % larger ambient pressure moves the steady intake pressure (the start value is used)
    base = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=0.1, output=["p_im"])
    hi = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=0.1, output=["p_im"],
                      start_values={"ambient.p_amb": 1.1e5})
    assert abs(hi["p_im"][0] / base["p_im"][0] - 1) > 5e-3


def _slave(fmu, cls=FMU2Slave):
    md = read_model_description(fmu)
    from fmpy import extract
    d = extract(fmu)
    s = cls(guid=md.guid, unzipDirectory=d, modelIdentifier="mvem", instanceName="t")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return s, vr


def test_bad_calls_return_error_with_message(fmu, capsys):
    s, vr = _slave(fmu)
    s.instantiate()
    # wrong order: step before initialization
    with pytest.raises(FMICallException):
        s.doStep(0.0, 0.1)
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    # NaN input is refused and the old value kept
    with pytest.raises(FMICallException):
        s.setReal([vr["u_vgt"]], [float("nan")])
    # unknown value reference
    with pytest.raises(FMICallException):
        s.getReal([99999])
    # no Integer variables
    with pytest.raises(FMICallException):
        s.getInteger([0])
    s.exitInitializationMode()
    assert s.getReal([vr["u_vgt"]]) == [75.0]
    # communication point that is not the FMU's time
    with pytest.raises(FMICallException):
        s.doStep(5.0, 0.1)
    # invalid tunable parameter during the run: refused, old value kept
    j = s.getReal([vr["turbo.j_t"]])[0]
    with pytest.raises(FMICallException):
        s.setReal([vr["turbo.j_t"]], [-1.0])
    assert s.getReal([vr["turbo.j_t"]])[0] == j
    s.doStep(0.0, 0.1)
    s.terminate()
    s.freeInstance()
    out = capsys.readouterr().out
    assert "u_vgt = NaN is not finite" in out
    assert "unknown value reference 99999" in out
    assert "differs from the FMU time" in out


def test_model_exchange_state_access(fmu):
    s, vr = _slave(fmu, FMU2Model)
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    from ctypes import c_double
    xs = (c_double * 8)()
    dx = (c_double * 8)()
    s.getContinuousStates(xs, 8)
    s.getDerivatives(dx, 8)
    ref = reference()
    assert abs(xs[0] / ref["p_im"][0] - 1) < 1e-6
    # steady state: derivatives negligible relative to the state scales
    assert abs(dx[0]) < 1e-3 * 1e5 and abs(dx[4]) < 1e-3 * 1e4
    # NaN states are refused
    xs[1] = float("nan")
    with pytest.raises(FMICallException):
        s.setContinuousStates(xs, 8)
    s.terminate()
    s.freeInstance()


def test_directional_derivatives_are_the_python_models_jacobian(fmu):
    """fmi2GetDirectionalDerivative (Model Exchange) off equilibrium: the columns of A for unit
    state seeds and of B for u_delta and n_e equal mvem.Model's Jacobian (the same library
    differences, one along the seed, the other per column) to 1e-7 of the column's largest
    entry; the current u_egr moves no derivative (the actuators see the delayed history)."""
    mvem = pytest.importorskip("mvem")
    md = read_model_description(fmu)
    assert md.modelExchange.providesDirectionalDerivative
    assert md.coSimulation.providesDirectionalDerivative
    s, vr = _slave(fmu, FMU2Model)
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    s.enterContinuousTimeMode()
    from ctypes import c_double
    xs = (c_double * 8)()
    s.getContinuousStates(xs, 8)
    x = np.array(xs[:])
    x[0] *= 1.05
    x[4] *= 0.97
    s.setContinuousStates((c_double * 8)(*x), 8)
    names = ["p_im", "p_em", "X_Oim", "X_Oem", "omega_t", "u_egr1", "u_egr2", "u_vgt_act"]
    ders = [vr[f"der({n})"] for n in names]
    j = mvem.Model().jacobian(x, [1500.0, 110.0, 80.0, 75.0])
    for k, n in enumerate(names):
        col = np.array(s.getDirectionalDerivative(ders, [vr[n]], [1.0]))
        assert np.abs(col - j["A"][:, k]).max() <= 1e-7 * np.abs(j["A"][:, k]).max(), n
    for k, n in [(0, "n_e"), (1, "u_delta")]:
        col = np.array(s.getDirectionalDerivative(ders, [vr[n]], [1.0]))
        assert np.abs(col - j["B"][:, k]).max() <= 1e-7 * np.abs(j["B"][:, k]).max(), n
    assert s.getDirectionalDerivative(ders, [vr["u_egr"]], [1.0]) == [0.0] * 8
    assert np.abs(j["B"][:, 2]).max() > 0  # Model's u_egr is the command the actuators see
    with pytest.raises(FMICallException):
        s.getDirectionalDerivative(ders, [vr["turbo.j_t"]], [1.0])
    s.terminate()
    s.freeInstance()


def test_initialization_mode_directional_derivatives_are_the_dc_gains(fmu):
    """fmi2GetDirectionalDerivative in Initialization Mode (the states are the steady state at
    the inputs): the outputs' changes per input equal mvem.linearize's DC gain D - C A^-1 B (the
    same model through the Python package) to 1e-6 of each output's largest gain, the state
    derivatives' changes are 0, and a state as a known is refused."""
    mvem = pytest.importorskip("mvem")
    point = (1500.0, 110.0, 60.0, 75.0)  # u_egr away from the EGR valve's vertex (80.06 %)
    outputs = ["p_im", "p_em", "W_c", "x_egr", "lambda_O", "M_e"]
    lin = mvem.linearize(*point, outputs=outputs)
    s, vr = _slave(fmu, FMU2Model)
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal([vr["n_e"], vr["u_delta"], vr["u_egr"], vr["u_vgt"]], list(point))
    names = ["p_im", "p_em", "X_Oim", "X_Oem", "omega_t", "u_egr1", "u_egr2", "u_vgt_act"]
    ders = [vr[f"der({n})"] for n in names]
    unknowns = [vr[o] for o in outputs] + ders
    g = lin["dc_gain"]
    for k, name in enumerate(lin["input_names"]):
        dv = np.array(s.getDirectionalDerivative(unknowns, [vr[name]], [1.0]))
        for o, out in enumerate(outputs):
            size = np.abs(g[o]).max()
            assert abs(dv[o] - g[o, k]) <= 1e-6 * size, (name, out, dv[o], g[o, k])
        assert np.all(dv[len(outputs):] == 0.0), name
    with pytest.raises(FMICallException):
        s.getDirectionalDerivative(unknowns, [vr["p_im"]], [1.0])
    s.exitInitializationMode()
    s.terminate()
    s.freeInstance()


# ---------------------------------------------------------------------------------------------
# 10- and 12-state FMUs, the one-iteration Co-Simulation FMU, and `mvem fmu`

from conftest import read_csv  # noqa: E402

STATES = {
    10: ["p_im", "p_em", "T_im", "T_em", "X_Oim", "X_Oem", "omega_t", "u_egr1", "u_egr2",
         "u_vgt_act"],
    12: ["p_im", "p_em", "p_c", "T_im", "T_em", "T_ic", "X_Oim", "X_Oem", "omega_t", "u_egr1",
         "u_egr2", "u_vgt_act"],
}


@pytest.fixture(scope="session")
def cli_step(mvem_cli, tmp_path_factory):
    """`mvem simulate --scenario vgt-step-nmp --rtol 1e-9 [args]` as {column: array}."""
    cache = {}

    def run(*args):
        if args not in cache:
            out = tmp_path_factory.mktemp("cli") / "step.csv"
            subprocess.run([mvem_cli, "simulate", "--scenario", "vgt-step-nmp", "--rtol", "1e-9",
                            "--out", str(out), *args], check=True, capture_output=True)
            cache[args] = read_csv(out)
        return cache[args]
    return run


@pytest.fixture(scope="session", params=[10, 12])
def variant(request, mvem_cli, tmp_path_factory):
    n = request.param
    return n, build_fmu(mvem_cli, tmp_path_factory.mktemp("fmu") / f"mvem{n}.fmu",
                        "--model", str(n))


def test_variant_fmu_validates_with_its_states(variant):
    n, fmu = variant
    assert validate_fmu(fmu) == []
    md = read_model_description(fmu)
    assert md.modelExchange is not None and md.coSimulation is not None
    assert md.numberOfContinuousStates == n
    assert [d.variable.name for d in md.derivatives] == [f"der({s})" for s in STATES[n]]
    names = {v.name: v for v in md.modelVariables}
    assert len(names) == len(md.modelVariables)  # no duplicate names (T_em is a state only)
    for o in OUTPUTS + STATES[n]:
        assert names[o].causality == "output", o
    assert names["T_em"].description.startswith("Exhaust manifold temperature")
    assert names["T_em"].unit == "K"
    assert [u.variable.name for u in md.outputs][:n] == STATES[n]


@pytest.mark.parametrize("fmi_type,kw", [
    ("CoSimulation", {}),
    ("ModelExchange", {"solver": "CVode", "relative_tolerance": 1e-8}),
])
def test_variant_vgt_step_matches_cli(variant, cli_step, fmi_type, kw):
    n, fmu = variant
    ref = cli_step("--model", str(n))
    outs = OUTPUTS + (["T_im", "p_c", "T_ic"] if n == 12 else ["T_im"])
    r = simulate_fmu(fmu, fmi_type=fmi_type, start_time=0.0, stop_time=8.0,
                     output_interval=0.01, input=step_input(), output=outs, **kw)
    errs = {o: max_rel_err(r["time"], r[o], ref["t"], ref[o]) for o in outs}
    print(n, fmi_type, errs)
    assert max(errs.values()) < TOL, errs


def test_one_iteration_fmu_is_co_simulation_only_and_matches_cli(mvem_cli, cli_step,
                                                                  tmp_path):
    fmu = build_fmu(mvem_cli, tmp_path / "oi.fmu", "--cylinder-temp", "one-iteration")
    assert validate_fmu(fmu) == []
    md = read_model_description(fmu)
    assert md.modelExchange is None and md.coSimulation is not None
    ref = cli_step("--cylinder-temp", "one-iteration")
    r = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=8.0, output_interval=0.01,
                     input=step_input(), output=OUTPUTS)
    errs = {o: max_rel_err(r["time"], r[o], ref["t"], ref[o]) for o in OUTPUTS}
    assert max(errs.values()) < TOL, errs


def test_params_file_sets_start_values(mvem_cli, tmp_path):
    # a complete parameter file: the published one with another ambient pressure
    text = (ROOT / "crates" / "mvem" / "data" / "published.toml").read_text()
    lines = [("p_amb = 1.05e5" if ln.startswith("p_amb =") else ln) for ln in text.splitlines()]
    assert "p_amb = 1.05e5" in lines
    pfile = tmp_path / "p.toml"
    pfile.write_text("\n".join(lines) + "\n")
    fmu = build_fmu(mvem_cli, tmp_path / "p.fmu", "--params", str(pfile), "--model", "10")
    md = read_model_description(fmu)
    names = {v.name: v for v in md.modelVariables}
    assert float(names["ambient.p_amb"].start) == 1.05e5
    r = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=0.1, output=["p_im", "W_c"])
    p = subprocess.run([mvem_cli, "steady", "--n-e", "1500", "--u-delta", "110", "--u-egr", "80",
                        "--u-vgt", "75", "--model", "10", "--params", str(pfile), "--json"],
                       check=True, capture_output=True, text=True)
    import json
    s = json.loads(p.stdout)
    assert r["p_im"][0] == pytest.approx(s["p_im"], rel=1e-12)
    assert r["W_c"][0] == pytest.approx(s["W_c"], rel=1e-12)


def test_tampered_resources_are_refused(mvem_cli, tmp_path):
    # modelDescription.xml and resources/mvem.json must belong together (GUID check)
    import zipfile
    fmu = build_fmu(mvem_cli, tmp_path / "a.fmu", "--model", "10")
    other = build_fmu(mvem_cli, tmp_path / "b.fmu", "--model", "12")
    bad = tmp_path / "bad.fmu"
    with zipfile.ZipFile(fmu) as a, zipfile.ZipFile(other) as b, zipfile.ZipFile(bad, "w") as z:
        for name in a.namelist():
            src = b if name == "resources/mvem.json" else a
            z.writestr(name, src.read(name))
    with pytest.raises(Exception):
        simulate_fmu(str(bad), fmi_type="CoSimulation", stop_time=0.1)


@pytest.mark.parametrize("args,msg", [
    (["--model", "9"], "invalid value '9'"),
    (["--params", "/nonexistent.toml"], "nonexistent.toml"),
    (["--lib", "/nonexistent/libmvem_fmu.so"], "not found"),
    (["--cylinder-temp", "twice"], "invalid value 'twice'"),
])
def test_mvem_fmu_usage_errors_exit_2(mvem_cli, tmp_path, args, msg):
    p = subprocess.run([mvem_cli, "fmu", "--out", str(tmp_path / "x.fmu"), *args],
                       capture_output=True, text=True)
    assert p.returncode == 2, p.stderr
    assert msg in p.stderr
    assert not (tmp_path / "x.fmu").exists()
