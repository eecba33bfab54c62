#!/usr/bin/env bash
# A profile-guided (PGO) release build of the `mvem` command: about 10 % faster WHTC integration
# for the 8- and 10-state models, 3 % for 12 states (docs/integrator.md, session 27), with the
# same results to the bit (checked here).
#
# Usage: bash scripts/build-pgo.sh
#   1. finds llvm-profdata of the active Rust toolchain (installs the rustup component
#      `llvm-tools` when it is missing; needs rustup and network access to its server),
#   2. builds an instrumented binary (target/pgo-gen) and runs the training workload
#      (scripts/pgo-workload.sh, which CI runs with its test build): `mvem bench` on the WHTC for
#      8, 10 and 12 states, `mvem simulate --scenario whtc` writing CSV and Parquet,
#      `mvem closed-loop --cycle whtc`,
#   3. merges the profiles and builds the optimized binary: target/pgo/release/mvem,
#   4. checks that it writes the same WHTC CSV (8, 10 and 12 states) and closed-loop trajectory,
#      byte for byte, as the plain `cargo build --release` binary (built if missing).
# Floating-point results do not change (PGO changes inlining, layout and branch order, not the
# arithmetic); step 4 fails the script if they did.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
host=$(rustc -vV | awk '/^host:/ {print $2}')
profdata="$(rustc --print sysroot)/lib/rustlib/$host/bin/llvm-profdata"
if [ ! -x "$profdata" ]; then
    echo "== installing the rustup component llvm-tools (llvm-profdata of this toolchain)"
    # "llvm-tools" since rustup 1.26 knows the rename; older ones only "llvm-tools-preview"
    rustup component add llvm-tools || rustup component add llvm-tools-preview
fi
[ -x "$profdata" ] || { echo "build-pgo.sh: no llvm-profdata at $profdata" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
echo "== instrumented build (target/pgo-gen)"
RUSTFLAGS="-Cprofile-generate=$work/raw" cargo build --release -q -p mvem-cli --target-dir target/pgo-gen
gen=target/pgo-gen/release/mvem
echo "== training run (scripts/pgo-workload.sh)"
bash scripts/pgo-workload.sh "$gen" "$work/train"
compgen -G "$work/raw/*.profraw" >/dev/null ||
    { echo "build-pgo.sh: the training run wrote no profile (.profraw) in $work/raw" >&2; exit 1; }
"$profdata" merge -o "$work/mvem.profdata" "$work/raw"
echo "== optimized build (target/pgo)"
RUSTFLAGS="-Cprofile-use=$work/mvem.profdata" cargo build --release -q -p mvem-cli --target-dir target/pgo
pgo=target/pgo/release/mvem

echo "== same results as the plain release build"
cargo build --release -q -p mvem-cli
plain=target/release/mvem
for m in 8 10 12; do
    "$plain" simulate --scenario whtc --model "$m" --dt 0.1 --out "$work/plain$m.csv" >/dev/null 2>&1
    "$pgo" simulate --scenario whtc --model "$m" --dt 0.1 --out "$work/pgo$m.csv" >/dev/null 2>&1
    cmp -s "$work/plain$m.csv" "$work/pgo$m.csv" ||
        { echo "build-pgo.sh: the WHTC CSV of $m states differs from the plain build's" >&2; exit 1; }
done
"$plain" closed-loop --cycle whtc --out "$work/cl-plain" >/dev/null 2>&1
"$pgo" closed-loop --cycle whtc --out "$work/cl-pgo" >/dev/null 2>&1
cmp -s "$work/cl-plain/trajectory.csv" "$work/cl-pgo/trajectory.csv" ||
    { echo "build-pgo.sh: the closed-loop trajectory differs from the plain build's" >&2; exit 1; }
echo "WHTC CSV (8, 10, 12 states) and closed-loop trajectory identical to the plain build's"
echo "built $pgo (compare: $pgo bench against $plain bench, or MVEM_BIN=$pgo bench/peer.sh PEER_DIR)"
