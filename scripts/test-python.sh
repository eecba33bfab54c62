#!/usr/bin/env bash
# Python-side tests: the FMU with FMPy and the Python package mvem (crates/mvem-py).
# Needs only Rust, python3 with venv (Debian: python3-venv) and pip: creates .venv-ci, installs
# from PyPI maturin, fmpy, pytest, numpy, pyarrow (Parquet output check), scipy (an
# independent integrator driven by mvem.Model),
# builds the CLI, the FMU library and the package (Cargo profile $MVEM_PROFILE, default release;
# scripts/test-all.sh sets ci), and runs pytest on tests/python (the tests build the
# 10/12-state FMUs with `mvem fmu` and compare with the CLI).
set -euo pipefail
cd "$(dirname "$0")/.."
root="$PWD"
profile="${MVEM_PROFILE:-release}"
venv="$root/.venv-ci"
start=$(date +%s)

if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --upgrade pip >/dev/null
"$venv/bin/python" -m pip install -q "maturin>=1.4,<2" fmpy pytest numpy gymnasium pyarrow scipy

echo "== building the CLI, the FMU library and the 8-state FMU (mvem fmu; profile $profile)"
scripts/build-fmu.sh "$root/target/fmu/mvem.fmu"
export MVEM_FMU="$root/target/fmu/mvem.fmu"
export MVEM_CLI="$root/target/$profile/mvem"
export MVEM_FMU_LIB="$root/target/$profile/libmvem_fmu.so"

echo "== building the Python package (maturin develop --profile $profile)"
(
    export VIRTUAL_ENV="$venv"
    export PATH="$venv/bin:$PATH"
    maturin develop --profile "$profile" -q -m crates/mvem-py/Cargo.toml
)

echo "== pytest tests/python"
"$venv/bin/python" -m pytest -q tests/python
echo "test-python.sh: done in $(( $(date +%s) - start )) s"
