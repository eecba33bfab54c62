#!/usr/bin/env bash
# Runs every test of the project: formatting, lints, the Rust test suites (release mode: the
# reference and robustness tests simulate a lot), then the Python side (FMU with FMPy, the Python
# package with pytest; creates .venv-ci), then the browser tests of `mvem serve` (Playwright driving
# Debian's Chromium; creates .venv-browser). Used by .ci/run; run it locally the same way.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
cargo fmt --all --check
cargo clippy --workspace --all-targets --release -- -D warnings
cargo test --workspace --release
bash scripts/test-python.sh
bash scripts/test-browser.sh
