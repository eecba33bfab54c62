#!/usr/bin/env bash
# Build the mvem FMU (FMI 2.0, Model Exchange + Co-Simulation, linux64) with `mvem fmu`.
# Usage: scripts/build-fmu.sh [OUT.fmu] [mvem fmu options, e.g. --model 10 --params P.toml]
#        (default OUT: target/fmu/mvem.fmu)
# Cargo profile: $MVEM_PROFILE (default release; scripts/test-all.sh sets ci).
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/fmu/mvem.fmu}"
shift || true
profile="${MVEM_PROFILE:-release}"
mkdir -p "$(dirname "$out")"
cargo build --profile "$profile" -q -p mvem-fmu -p mvem-cli
"target/$profile/mvem" fmu --out "$out" --lib "target/$profile/libmvem_fmu.so" "$@"
