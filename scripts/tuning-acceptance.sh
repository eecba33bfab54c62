#!/usr/bin/env bash
# Acceptance run of the tuning pipeline (docs/tuning.md): a virtual campaign with the published
# parameters and realistic noise, tuned (a) eq. (78) + complete-model cost only, (b) steps 1-4,
# (full) steps 1-5; validation tables of each on the validation sets.
# Usage: scripts/tuning-acceptance.sh [OUT_DIR]   (about 10-20 min on 2 cores)
set -euo pipefail
OUT=${1:-target/tuning-acceptance}
cargo build --release -p mvem-cli
MVEM=target/release/mvem
mkdir -p "$OUT"
$MVEM lab --out "$OUT/campaign" --seed 1 --noise realistic
tau() { { grep -o '"tau_me_s": [0-9.e-]*' "$1/tune_report.json" || true; } | awk '{print $2}'; }
# full method, steps 1-5
/usr/bin/time -v $MVEM tune --data "$OUT/campaign" --out "$OUT/full.toml" --report "$OUT/full" \
  2> "$OUT/full.time" > /dev/null
# (b) steps 1-4 only
$MVEM tune --data "$OUT/campaign" --out "$OUT/b.toml" --steps 1-4 --report "$OUT/b" > /dev/null
# (a) eq. (78) + first row of (77) only (dynamic parameters from (b))
$MVEM tune --data "$OUT/campaign" --params "$OUT/b.toml" --steps 5 --init naive --cost dynamic \
  --out "$OUT/a.toml" --report "$OUT/a" > /dev/null
for m in full b a; do
  t=$(tau "$OUT/$m"); [ -n "$t" ] || t=$(tau "$OUT/b")
  $MVEM validate --data "$OUT/campaign" --params "$OUT/$m.toml" --tau-me "$t" \
    --roles validation --report "$OUT/val_$m" > "$OUT/val_$m.md"
  echo "== $m"; cat "$OUT/val_$m.md"
done
grep -E "Elapsed|User time|System time" "$OUT/full.time"
