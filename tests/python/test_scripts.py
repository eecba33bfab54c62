"""The analysis scripts of scripts/ on synthetic tune reports (no simulation)."""

import json
import subprocess
import sys

from conftest import ROOT


def write_report(d, values, se, identifiable=True, fixed_jacobian="sigma-points"):
    """A tune_report.json with the final `parameters` and a first step-3 pass (v_im, j_t)."""
    d.mkdir()
    params = {
        name: {"value": v, "std_error": se[name], "identifiable": identifiable, "step": 3}
        for name, v in values.items()
    }
    step3 = [
        ["v_im", {"value": values["intake_manifold.v_im"], "std_error": 0.005,
                  "identifiable": identifiable}],
        ["j_t", {"value": values["turbo.j_t"], "std_error": 1.5e-5,
                 "identifiable": identifiable}],
    ]
    rep = {"parameters": params, "step3": {"uncertainty": step3},
           "fixed_jacobian": fixed_jacobian}
    (d / "tune_report.json").write_text(json.dumps(rep))
    return str(d)


def run_builds(*args):
    return subprocess.run([sys.executable, str(ROOT / "scripts" / "tuning-builds.py"), *args],
                          capture_output=True, text=True)


def test_tuning_builds_measures_moves_in_standard_errors(tmp_path):
    se = {"intake_manifold.v_im": 0.002, "turbo.j_t": 4e-6}
    a = write_report(tmp_path / "a", {"intake_manifold.v_im": 0.0218, "turbo.j_t": 2.19e-4}, se)
    # V_im moves by 0.3 standard errors, J_t by 0.75
    b = write_report(tmp_path / "b", {"intake_manifold.v_im": 0.0212, "turbo.j_t": 2.16e-4}, se)
    out = run_builds(a, b)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "moved by more than 0.5 standard errors: turbo.j_t" in out.stdout
    line = next(x for x in out.stdout.splitlines() if "intake_manifold.v_im" in x)
    assert line.split()[-1] == "0.30", line
    # a looser limit passes; the first step-3 pass moved by 0.12 (v_im) and 0.20 (j_t)
    out = run_builds("--limit", "0.8", a, b)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "first step 3 0.20, final 0.75" in out.stdout, out.stdout


def test_tuning_builds_ignores_flagged_parameters_and_warns_on_forward_differences(tmp_path):
    se = {"intake_manifold.v_im": 0.002, "turbo.j_t": 4e-6}
    a = write_report(tmp_path / "a", {"intake_manifold.v_im": 0.0218, "turbo.j_t": 2.19e-4}, se,
                     identifiable=False, fixed_jacobian="forward")
    b = write_report(tmp_path / "b", {"intake_manifold.v_im": 0.0150, "turbo.j_t": 1.00e-4}, se)
    out = run_builds(a, b)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "(flagged)" in out.stdout
    assert "was not made with --fixed-jacobian sigma-points" in out.stdout


def test_tuning_compare_reads_report_keys_1_based():
    """scripts/tuning-compare.py (and tuning-spread.py, which imports it) looks a report key up in
    the true parameter file as the report names it: elements counted from 1 (the registry's
    names), "cylinder.c_fric[1]" the first number of c_fric; an index 0 names nothing."""
    import importlib
    import tomllib
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        lookup = importlib.import_module("tuning-compare").lookup
    finally:
        sys.path.pop(0)
    truth = tomllib.loads((ROOT / "crates" / "mvem" / "data" / "published.toml").read_text())
    assert lookup(truth, "cylinder.c_fric[1]") == truth["cylinder"]["c_fric"][0]
    assert lookup(truth, "cylinder.c_fric[3]") == truth["cylinder"]["c_fric"][2]
    assert lookup(truth, "compressor.q_c[1][2]") == truth["compressor"]["q_c"][0][1]
    assert lookup(truth, "turbo.j_t") == truth["turbo"]["j_t"]
    assert lookup(truth, "cylinder.c_fric[0]") is None
    assert lookup(truth, "cylinder.c_fric[4]") is None
