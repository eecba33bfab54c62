#!/usr/bin/env bash
# Every timing figure of the README's performance table, measured in one run on this machine.
#
# Usage: bench/figures.sh [PEER_DIR] [--tune]
#   PEER_DIR  a checkout of the C/SUNDIALS-CVODE peer: also runs bench/peer.sh side by side
#             (7 alternated rounds). Without it the peer ratios are skipped.
#   --tune    also time the full parameter tuning (`mvem lab --seed 1` campaign, `mvem tune`).
#   MVEM_BIN  (environment) an already built `mvem` binary (default: cargo build --release).
#   The Python figure uses .venv-ci (made by scripts/test-python.sh) when it exists.
#
# Prints the load (uptime) before and after, then one line per figure: min and median wall time
# of alternated repeats (whole processes timed with the shell clock), deterministic counters
# where the program prints them. Machines differ by 2x in speed, so quote figures with the load
# and compare ratios measured in the same run.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
peer=""
tune=0
for a in "$@"; do
    case "$a" in
    --tune) tune=1 ;;
    *) peer="$a" ;;
    esac
done
if [ -z "${MVEM_BIN:-}" ]; then
    cargo build --release -q -p mvem-cli --manifest-path "$root/Cargo.toml"
fi
mvem=${MVEM_BIN:-$root/target/release/mvem}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

now() { date +%s.%N; }
stats() { sort -g | awk '{a[NR]=$1} END {m=(NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2; printf "min %.3f s, median %.3f s (%d runs)", a[1], m, NR}'; }
# time_runs NAME N CMD...: wall clock of N runs of CMD (output discarded)
time_runs() {
    local name=$1 n=$2
    shift 2
    : >"$work/t"
    for _ in $(seq 1 "$n"); do
        local t
        rm -rf "$work/out"
        t=$(now)
        if ! "$@" >/dev/null 2>"$work/err"; then
            printf '%-44s FAILED: %s\n' "$name" "$(tail -1 "$work/err")"
            return
        fi
        echo "$(now) - $t" | bc -l >>"$work/t"
    done
    printf '%-44s %s\n' "$name" "$(stats <"$work/t")"
}

echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "commit:  $(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)"
echo "load before: $(uptime)"
for m in 8 10 12; do
    "$mvem" bench --repeat 9 --model "$m" --evals 200000 >"$work/b$m" 2>&1
    # the sequential (1 thread) block first, then the time-parallel one (2 chunks, 2 threads)
    printf '%-44s %s; %s; %s\n' "WHTC integration, $m states (mvem bench)" \
        "$(awk '/wall time/ {sub(/^ *wall time */, ""); print; exit}' "$work/b$m")" \
        "$(awk '/^ *steps/ {sub(/^ *steps */, ""); print; exit}' "$work/b$m")" \
        "$(awk '/RHS evaluations/ {print $3 " RHS evaluations"; exit}' "$work/b$m")"
    printf '%-44s %s\n' "  + output signals of the samples (after)" \
        "$(awk '/output signals/ {sub(/^ *output signals */, ""); print; exit}' "$work/b$m")"
    printf '%-44s %s; %s\n' "  same, 2 time chunks on 2 threads" \
        "$(awk '/^Time-parallel/ {p=1} p && /wall time/ {sub(/^ *wall time */, ""); print; exit}' "$work/b$m")" \
        "$(awk '/^ *junctions/ {sub(/^ *junctions */, ""); print; exit}' "$work/b$m")"
done
awk '/Model evaluation/ {sub(/^.*calls\): /, ""); print "one model evaluation (8 states)               " $0}' "$work/b8"
awk '/^  (p_im|p_em|X_Oim|X_Oem|omega_t) / {if ($2 + 0 > m) m = $2 + 0; sub(/\)$/, "", $NF); if ($NF + 0 > p) p = $NF + 0} END {printf "%-44s %.2e (scaled, 8 states; 2 time chunks %.2e)\n", "max deviation from rtol 1e-10", m, p}' "$work/b8"
# whole processes, alternated: replacing the previous run's file, then writing a new one (the
# file removed before, outside the timing; a replacement on ext4 can wait for the old file's
# blocks to be freed: bench/peer.sh, docs/integrator.md, session 32)
: >"$work/csv"; : >"$work/pq"; : >"$work/ncsv"; : >"$work/npq"
"$mvem" simulate --scenario whtc --dt 0.1 --out "$work/w.csv" >/dev/null 2>&1
"$mvem" simulate --scenario whtc --dt 0.1 --out "$work/w.parquet" >/dev/null 2>&1
for _ in 1 2 3 4 5; do
    for f in csv pq ncsv npq; do
        ext=$(case $f in *csv) echo csv ;; *) echo parquet ;; esac)
        case $f in n*) rm -f "$work/w.$ext" ;; esac
        t=$(now)
        "$mvem" simulate --scenario whtc --dt 0.1 --out "$work/w.$ext" >/dev/null 2>&1
        echo "$(now) - $t" | bc -l >>"$work/$f"
    done
done
printf '%-44s %s\n' "simulate WHTC whole process, CSV" "$(stats <"$work/csv")"
printf '%-44s %s\n' "simulate WHTC whole process, Parquet" "$(stats <"$work/pq")"
printf '%-44s %s\n' "  the same writing a new CSV file" "$(stats <"$work/ncsv")"
printf '%-44s %s\n' "  the same writing a new Parquet file" "$(stats <"$work/npq")"
time_runs "closed-loop WHTC whole process (10 ms)" 5 "$mvem" closed-loop --cycle whtc --out "$work/out"
"$mvem" bench --ensemble 8 >"$work/ens" 2>&1 || true
printf '%-44s %s\n' "8 WHTC runs, 1 thread vs all cores" "$(grep -E '^ +[0-9]+ thread|speed-up' "$work/ens" | sed 's/^ *//' | tr '\n' ';' | tr -s ' ')"
py=python3
[ -x "$root/.venv-ci/bin/python" ] && py="$root/.venv-ci/bin/python" # made by scripts/test-python.sh
if "$py" -c "import mvem" 2>/dev/null; then
    printf '%-44s %s\n' "Plant.step(0.01) x 10 000 (Python)" \
        "$("$py" "$root/examples/python/bench_plant.py" 2>&1 | tail -1)"
else
    echo "Plant.step: skipped (the mvem Python module is not importable here)"
fi
if [ "$tune" = 1 ]; then
    "$mvem" lab --seed 1 --noise realistic --out "$work/camp" >/dev/null 2>&1
    time_runs "mvem tune, lab seed 1 (steps 1-5)" 1 "$mvem" tune --data "$work/camp" --out "$work/t.toml" --report "$work/out"
fi
echo "load after: $(uptime)"
if [ -n "$peer" ]; then
    MVEM_BIN=$mvem bash "$root/bench/peer.sh" "$peer" 7 | tail -6
fi
