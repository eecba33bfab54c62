"""The mvem FMU (FMI 2.0, Model Exchange + Co-Simulation) checked with FMPy.

The FMU is taken from $MVEM_FMU (scripts/test-python.sh builds it), else built here with
`cargo run --release -p mvem-fmu --bin mvem-fmu-build`.

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


@pytest.fixture(scope="session")
def fmu(tmp_path_factory):
    env = os.environ.get("MVEM_FMU")
    if env:
        return env
    out = tmp_path_factory.mktemp("fmu") / "mvem.fmu"
    subprocess.run(
        ["cargo", "run", "--release", "-q", "-p", "mvem-fmu", "--bin", "mvem-fmu-build",
         "--", "--out", str(out)],
        cwd=ROOT, check=True)
    return str(out)


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
