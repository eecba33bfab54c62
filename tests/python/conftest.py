"""Shared fixtures: the mvem CLI binary (tests compare the Python package and the FMU with it)."""

import csv
import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def mvem_cli():
    """Path of the `mvem` executable: $MVEM_CLI, else target/release/mvem (built if missing)."""
    exe = os.environ.get("MVEM_CLI") or str(ROOT / "target" / "release" / "mvem")
    if not pathlib.Path(exe).is_file():
        subprocess.run(["cargo", "build", "--release", "-q", "-p", "mvem-cli"], cwd=ROOT,
                       check=True)
    return exe


def read_csv(path):
    """A CLI CSV as {column: array}; duplicate names (a signal named like a state, T_em in the
    10-state model) keep the first column, the state."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    names, data = rows[0], np.array(rows[1:], dtype=float)
    out = {}
    for j, n in enumerate(names):
        out.setdefault(n, data[:, j])
    return out


@pytest.fixture
def ctrl_c():
    """SIGINT handled by Python (KeyboardInterrupt) for the test, whatever the runner inherited:
    a runner started in the background of a non-interactive shell ignores SIGINT, and
    _thread.interrupt_main() (the tests' Ctrl-C) then does nothing."""
    import signal

    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)
