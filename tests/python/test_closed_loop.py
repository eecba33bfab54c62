"""mvem.closed_loop: the closed-loop drive cycle of `mvem closed-loop` from Python (the same
core run), with the baseline controllers' tuning from a dict."""

import json
import subprocess

import numpy as np
import pytest

from conftest import read_csv

mvem = pytest.importorskip("mvem")

TIP_IN = {"t": [0.0, 2.0, 2.2, 8.0], "n_e": [1200.0] * 4, "M_ref": [100.0, 100.0, 1500.0, 1500.0]}


def test_the_whtc_equals_the_cli(mvem_cli, tmp_path):
    """The first 60 s of the closed-loop WHTC: every trajectory column equals the CLI's
    trajectory.csv (shortest round-trip numbers) to the bit, and so do the statistics."""
    r = mvem.closed_loop("whtc", duration=60.0)
    subprocess.run([mvem_cli, "closed-loop", "--cycle", "whtc", "--duration", "60", "--out",
                    str(tmp_path / "cl")], check=True, capture_output=True)
    cli = read_csv(tmp_path / "cl" / "trajectory.csv")
    traj = r["trajectory"]
    assert len(traj["t"]) == 6001 and traj["t"][-1] == pytest.approx(60.0)
    for name, col in traj.items():
        np.testing.assert_array_equal(col, cli[name], err_msg=name)
    stats = json.loads((tmp_path / "cl" / "stats.json").read_text())
    assert r["stats"] == stats["stats"]
    assert r["violations"] == stats["violations"] and r["passes"] == stats["passes"]
    assert r["controller_tuning"] == stats["controller_tuning"]


def test_a_demand_with_a_tuning_dict():
    """A tip-in at 1200 rpm: the smoke limiter holds lambda_O at 1.22 with the default limit
    and at 1.12 with lambda_limit = 1.1 (the cycle's lambda_O >= 1.2 check then fails); a 2-D
    array demand is the same run as the dict."""
    default = mvem.closed_loop(TIP_IN)
    tuned = mvem.closed_loop(TIP_IN, tuning={"lambda_limit": 1.1})
    assert default["stats"]["lambda_o_min"] > 1.2 and default["passes"]
    assert tuned["stats"]["lambda_o_min"] < 1.15 and not tuned["passes"]
    assert tuned["controller_tuning"]["lambda_limit"] == 1.1
    assert tuned["controller_tuning"]["torque"] == [0.02, 2.0]
    rows = np.column_stack([TIP_IN["t"], TIP_IN["n_e"], TIP_IN["M_ref"]])
    again = mvem.closed_loop(rows, tuning={"lambda_limit": 1.1})
    np.testing.assert_array_equal(again["trajectory"]["lambda_O"], tuned["trajectory"]["lambda_O"])


def test_the_gain_schedules_from_a_dict_equal_the_cli(mvem_cli, tmp_path):
    """The VGT loops' gain schedule (vgt_gain_closed, vgt_gain_knee) from a dict is the CLI's
    `--tuning` file to the bit over the WHTC's first 120 s, and it changes the VGT command
    against the default schedule (0.5 at 20 %, knee 40 %: the runs differ once the VGT is below
    the larger knee); the EGR-valve loops' schedule (egr_gain_closed, egr_gain_knee) is echoed."""
    tuning = {"vgt_gain_closed": 0.7, "vgt_gain_knee": 50.0, "egr_gain_knee": 12.0}
    r = mvem.closed_loop("whtc", duration=120.0, tuning=tuning)
    f = tmp_path / "sched.toml"
    f.write_text("vgt_gain_closed = 0.7\nvgt_gain_knee = 50\negr_gain_knee = 12\n")
    subprocess.run([mvem_cli, "closed-loop", "--cycle", "whtc", "--duration", "120", "--tuning",
                    str(f), "--out", str(tmp_path / "cl")], check=True, capture_output=True)
    cli = read_csv(tmp_path / "cl" / "trajectory.csv")
    for name, col in r["trajectory"].items():
        np.testing.assert_array_equal(col, cli[name], err_msg=name)
    assert r["controller_tuning"]["vgt_gain_closed"] == 0.7
    assert r["controller_tuning"]["egr_gain_closed"] == 1.0
    assert r["controller_tuning"]["egr_gain_knee"] == 12.0
    plain = mvem.closed_loop("whtc", duration=120.0)
    assert plain["controller_tuning"]["vgt_gain_closed"] == 0.5
    u0, u1 = plain["trajectory"]["u_vgt"], r["trajectory"]["u_vgt"]
    assert np.max(np.abs(u1 - u0)) > 1.0
    assert np.min(u0[np.abs(u1 - u0) > 1e-9]) < 50.0


def test_a_normalized_cycle_file_equals_the_cli(mvem_cli, tmp_path):
    """A normalized cycle (UN GTR No. 4's form: Time, Speed [%], Torque [%], "m" motoring) given
    as a path (str or pathlib) runs as `mvem closed-loop --cycle FILE`, every column to the bit;
    a bad row is a ValueError naming its line."""
    path = tmp_path / "modes.tsv"
    path.write_text("Time\tSpeed\tTorque\ns\t%\t%\n0\t0\t0\n10\t0\t0\n30\t55\t50\n"
                    "45\t55\t50\n50\t20\tm\n60\t20\tm\n")
    r = mvem.closed_loop(path)
    subprocess.run([mvem_cli, "closed-loop", "--cycle", str(path), "--out", str(tmp_path / "cl")],
                   check=True, capture_output=True)
    cli = read_csv(tmp_path / "cl" / "trajectory.csv")
    for name, col in r["trajectory"].items():
        np.testing.assert_array_equal(col, cli[name], err_msg=name)
    np.testing.assert_array_equal(mvem.closed_loop(str(path))["trajectory"]["M_e"],
                                  r["trajectory"]["M_e"])
    # half the full-load torque at 55 % speed, delivered by the end of the hold
    m_ref, m_e, t = (r["trajectory"][k] for k in ("M_ref", "M_e", "t"))
    k = int(np.searchsorted(t, 45.0))
    assert abs(m_e[k] - m_ref[k]) < 0.01 * m_ref[k]
    bad = tmp_path / "bad.tsv"
    bad.write_text("Time\tSpeed\tTorque\n0\t0\t0\n1\t50\t120\n")
    with pytest.raises(ValueError, match=r"line 3: torque 120 % is outside \[0, 100\] %"):
        mvem.closed_loop(bad)


@pytest.mark.parametrize("kwargs, msg", [
    ({"cycle": "nedc"}, 'cycle: nedc: .*give "whtc", a demand, or the path of a cycle file'),
    ({"cycle": {"t": [0.0, 1.0], "n_e": [1200.0, 1200.0]}}, "missing column `M_ref`"),
    ({"cycle": {"t": [0.0, 1.0], "n_e": [1200.0, 3000.0], "M_ref": [1.0, 1.0]}},
     r"row 2 \(t = 1 s\): speed 3000 rpm is outside"),
    ({"cycle": np.zeros((3, 2))}, "3 columns"),
    ({"tuning": {"lamda_limit": 1.1}}, "unknown field `lamda_limit`"),
    ({"tuning": {"torque": [-1.0, 2.0]}}, r"torque\[1\] = -1"),
    ({"tuning": 1.1}, "expected a dict"),
    ({"tuning": {"vgt_gain_knee": 0.0}}, r"vgt_gain_knee = 0: must be in \(0, 100\]"),
    ({"duration": -1.0}, "duration -1: must be a finite number of seconds > 0"),
    ({"model": 9}, "model = 9"),
])
def test_bad_arguments_are_value_errors_naming_them(kwargs, msg):
    with pytest.raises(ValueError, match=msg):
        mvem.closed_loop(**kwargs)


def test_margins_along_the_run_equal_the_cli(mvem_cli, tmp_path):
    """margins=S: the loop margins of the loops in feedback every S seconds, the same analysis as
    `mvem closed-loop --margins S` (summary equal to stats.json's, each sample's margins to the
    CLI's margins.csv to the bit); the trajectory says which loop gave each command."""
    r = mvem.closed_loop("whtc", duration=60.0, margins=10.0)
    subprocess.run([mvem_cli, "closed-loop", "--duration", "60", "--margins", "10", "--out",
                    str(tmp_path / "cl")], check=True, capture_output=True)
    stats = json.loads((tmp_path / "cl" / "stats.json").read_text())
    m = dict(r["margins"])
    samples = m.pop("samples")
    assert m == stats["margins"]
    assert m["points"] == len(samples) == 6
    import csv

    with open(tmp_path / "cl" / "margins.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    checked = 0
    for row, s in zip(rows, samples):
        assert s["t"] == float(row["t"])
        assert s["status"] == row["status"].split(":")[0]
        if s["status"] != "analysed":
            continue
        for lp in s["loops"]:
            prefix = "egr" if lp["input"] == "u_egr" else "vgt"
            gm = lp["others_closed"]["gain_margin"]
            want = row[f"{prefix}_gain_margin"]
            assert (gm is None and want == "") or gm == float(want), (row["t"], lp["name"])
            checked += 1
    assert checked >= 4
    codes = r["trajectory"]["egr_loop"]
    assert np.isnan(codes[0]) and set(np.unique(codes[1:])) <= {0.0, 1.0, 2.0}
    with pytest.raises(ValueError, match="margins"):
        mvem.closed_loop("whtc", duration=5.0, margins=0.0)
