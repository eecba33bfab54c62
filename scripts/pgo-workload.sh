#!/usr/bin/env bash
# The training workload of the profile-guided build (scripts/build-pgo.sh): runs the `mvem`
# binary BIN on what the PGO profile should represent, writing into DIR (created if missing).
#   `mvem bench` on the WHTC for 8, 10 and 12 states, `mvem simulate --scenario whtc` writing
#   CSV and Parquet, `mvem closed-loop --cycle whtc`.
# Any command that fails fails the script (naming it), so that a change of the command line
# cannot silently leave the PGO build without a profile: scripts/test-all.sh runs it with the
# test build's binary (a few seconds) for that reason, since the PGO build itself (two release
# builds, ~8 min) is not part of CI.
#
# Usage: bash scripts/pgo-workload.sh BIN DIR
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: $0 BIN DIR" >&2; exit 2; }
bin=$1
dir=$2
[ -x "$bin" ] || { echo "pgo-workload.sh: $bin is not an executable" >&2; exit 2; }
mkdir -p "$dir"
run() {
    local log="$dir/last.log"
    if ! "$@" >"$log" 2>&1; then
        echo "pgo-workload.sh: failed: $*" >&2
        tail -n 20 "$log" >&2
        exit 1
    fi
}
for m in 8 10 12; do
    run "$bin" bench --model "$m" --repeat 3 --no-reference --time-parallel 1 --evals 100000
done
run "$bin" simulate --scenario whtc --dt 0.1 --out "$dir/train.csv"
run "$bin" simulate --scenario whtc --dt 0.1 --out "$dir/train.parquet"
run "$bin" closed-loop --cycle whtc --out "$dir/train-cl"
# the outputs the profile was meant to exercise exist and are not empty
for f in "$dir/train.csv" "$dir/train.parquet" "$dir/train-cl/trajectory.csv"; do
    [ -s "$f" ] || { echo "pgo-workload.sh: $f missing or empty" >&2; exit 1; }
done
rm -f "$dir/last.log"
