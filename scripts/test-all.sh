#!/usr/bin/env bash
# Runs every test of the project: formatting, lints, the library's API docs, the Rust test
# suites, then the Python side (FMU with FMPy, the Python package with pytest; creates
# .venv-ci), then the browser tests of `mvem serve` (Playwright driving Debian's Chromium;
# creates .venv-browser). Used by .ci/run; run it locally the same way.
#
# Everything is built once, with the `ci` profile (Cargo.toml: optimized as release, without
# cross-crate LTO; the reference and robustness tests simulate a lot, so the tests need optimized
# code): clippy, `cargo test` and the CLI/FMU builds of the Python and browser tests share one
# set of artifacts in target/ci (MVEM_PROFILE=release builds target/release instead).
# Long acceptance runs are not part of it: scripts/tuning-acceptance.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
export MVEM_PROFILE="${MVEM_PROFILE:-ci}"
start=$(date +%s)
lap() { echo "test-all.sh: $1 done at $(( $(date +%s) - start )) s"; }
cargo fmt --all --check
# the benchmarks too (criterion is behind mvem's `bench` feature, so `cargo test` does not build it)
cargo clippy --workspace --all-targets --features mvem/bench --profile "$MVEM_PROFILE" -- -D warnings
lap clippy
# the API documentation of every crate: no broken or private intra-doc links (units in brackets
# are escaped, \[s\], so that rustdoc does not read them as links; the CLI binary is not
# documented, its doc comments being the --help texts)
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --profile "$MVEM_PROFILE" -q
lap "cargo doc"
cargo test --workspace --profile "$MVEM_PROFILE" --no-run
lap "cargo test build"
cargo test --workspace --profile "$MVEM_PROFILE"
lap "cargo test"
# the PGO build's training workload with the test build's binary (seconds): a changed command line
# fails here instead of leaving scripts/build-pgo.sh (not run by CI, ~8 min) without a profile
bash scripts/pgo-workload.sh "target/$MVEM_PROFILE/mvem" "target/$MVEM_PROFILE/pgo-workload"
lap "PGO training workload"
bash scripts/test-python.sh
lap "Python tests"
bash scripts/test-browser.sh
lap "browser tests"
