#!/usr/bin/env bash
# Build the mvem FMU (FMI 2.0, Model Exchange + Co-Simulation, linux64).
# Usage: scripts/build-fmu.sh [OUT.fmu]   (default: target/fmu/mvem.fmu)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/fmu/mvem.fmu}"
mkdir -p "$(dirname "$out")"
cargo build --release -p mvem-fmu
cargo run --release -q -p mvem-fmu --bin mvem-fmu-build -- --out "$out"
