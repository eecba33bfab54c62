#!/usr/bin/env bash
# Side-by-side WHTC timing of mvem and a C/SUNDIALS-CVODE peer (the 8-state model hand-ported to
# C, BDF + Newton + dense solver, stop time at every input row), alternating the two programs.
#
# Usage: bench/peer.sh PEER_DIR [ROUNDS]
#   PEER_DIR  a checkout of the peer (Makefile, whtc_cvode.c, model.c, x0.txt); it is copied to a
#             temporary directory and built there with `make` (needs libsundials-dev; Debian 12:
#             SUNDIALS 6.4.1). Nothing of it enters this repository.
#   ROUNDS    alternated rounds (default 7); each round runs mvem's integration, the peer's
#             integration, and both whole processes with CSV output twice: replacing the
#             previous run's file, and writing a new one.
#   MVEM_BIN  (environment) an already built `mvem` binary to use instead of building one.
#   REPEAT    (environment, default 1) runs per round of each integration: a round then takes
#             the min of REPEAT runs of each program (mvem bench --repeat, the peer's --repeat),
#             which on a noisy VM is steadier than one run; the medians are over the rounds.
#
# Prints the load (uptime) before and after, per-round times, and the medians and ratios
# mvem / peer of the integration alone (mvem: `mvem bench` wall time of one run from the steady
# state, storing t, the state and the inputs at every output time, its signals evaluated after
# the timing; peer: integrate_s_min of one run, storing the state at every output time) and of the whole process writing CSV (wall clock of
# `mvem simulate --scenario whtc --dt 0.1` vs the peer with --out, both at rtol 1e-6).
# An extra line gives mvem's time-parallel integration (`mvem bench --time-parallel 2`: the
# cycle in 2 time chunks on 2 threads, timed in the same process right after the sequential run)
# against the same peer runs. The peer is single-threaded: that ratio compares 2 cores with 1,
# and it means something only when the machine has a second core free (quote the load).
set -euo pipefail

peer_src=${1:?usage: bench/peer.sh PEER_DIR [ROUNDS]}
rounds=${2:-7}
root=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cp -r "$peer_src" "$work/peer"
make -s -C "$work/peer" whtc_cvode >/dev/null
if [ -z "${MVEM_BIN:-}" ]; then
    cargo build --release -q -p mvem-cli --manifest-path "$root/Cargo.toml"
fi
mvem=${MVEM_BIN:-$root/target/release/mvem}
inputs="$root/data/whtc_inputs_10hz.csv"
params="$root/data/wahlstrom_eriksson_2011_parameters.json"

now() { date +%s.%N; }
median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }

echo "load before: $(uptime)"
# the output files the first round's "replacing" runs replace
"$mvem" simulate --scenario whtc --dt 0.1 --out "$work/mvem.csv" >/dev/null 2>&1
"$work/peer/whtc_cvode" --inputs "$inputs" --params "$params" --x0 "$work/peer/x0.txt" \
    --dt 0.1 --mode stop --rtol 1e-6 --out "$work/peer.csv" --quiet 2>/dev/null
: >"$work/mi"; : >"$work/mp"; : >"$work/pi"; : >"$work/mw"; : >"$work/pw"; : >"$work/nmw"; : >"$work/npw"
for r in $(seq 1 "$rounds"); do
    # integration alone: the sequential run (first wall time), then 2 time chunks (second)
    "$mvem" bench --repeat "${REPEAT:-1}" --no-reference --evals 1 --dt 0.1 --time-parallel 2 >"$work/b"
    mi=$(awk '/wall time/ {v=$4; u=$5; print (u ~ /^ms/) ? v/1000 : v; exit}' "$work/b")
    mp=$(awk '/wall time/ {n++} /wall time/ && n == 2 {v=$4; u=$5; print (u ~ /^ms/) ? v/1000 : v}' "$work/b")
    pi=$("$work/peer/whtc_cvode" --inputs "$inputs" --params "$params" --x0 "$work/peer/x0.txt" \
        --dt 0.1 --mode stop --rtol 1e-6 --repeat "${REPEAT:-1}" 2>&1 |
        tr ' ' '\n' | awk -F= '/^integrate_s_min=/ {print $2}')
    # whole process with CSV output, twice: replacing the file the previous run wrote (as a
    # user rerunning into the same path does), then writing a new file (both outputs removed
    # before, outside the timing). mvem replaces its output atomically (a temporary file renamed
    # over the old one), and on ext4 that rename makes the kernel allocate the new file's blocks
    # (auto_da_alloc), which the next replacement frees again (with the `discard` mount option,
    # a synchronous TRIM inside the rename: docs/integrator.md, session 32); the peer truncates
    # its file in place.
    whole() {
        local t
        t=$(now); "$mvem" simulate --scenario whtc --dt 0.1 --out "$work/mvem.csv" >/dev/null 2>&1
        echo "$(now) - $t" | bc -l >>"$work/$1mw"
        t=$(now); "$work/peer/whtc_cvode" --inputs "$inputs" --params "$params" --x0 "$work/peer/x0.txt" \
            --dt 0.1 --mode stop --rtol 1e-6 --out "$work/peer.csv" --quiet 2>/dev/null
        echo "$(now) - $t" | bc -l >>"$work/$1pw"
    }
    whole ""
    rm -f "$work/mvem.csv" "$work/peer.csv"
    whole "n"
    mw=$(tail -1 "$work/mw"); pw=$(tail -1 "$work/pw")
    nmw=$(tail -1 "$work/nmw"); npw=$(tail -1 "$work/npw")
    printf 'round %d: integration mvem %.4f s (2 time chunks %.4f s), peer %.4f s; whole process (replacing / new file) mvem %.4f / %.4f s, peer %.4f / %.4f s\n' \
        "$r" "$mi" "$mp" "$pi" "$mw" "$nmw" "$pw" "$npw"
    echo "$mi" >>"$work/mi"; echo "$mp" >>"$work/mp"; echo "$pi" >>"$work/pi"
done
echo "load after: $(uptime)"
mi=$(median <"$work/mi"); mp=$(median <"$work/mp"); pi=$(median <"$work/pi")
mw=$(median <"$work/mw"); pw=$(median <"$work/pw")
printf 'median integration:   mvem %.4f s, peer %.4f s, ratio mvem/peer %.3f\n' "$mi" "$pi" "$(echo "$mi / $pi" | bc -l)"
printf 'median integration, mvem in 2 time chunks on 2 threads (the peer on 1): mvem %.4f s, peer %.4f s, ratio %.3f\n' \
    "$mp" "$pi" "$(echo "$mp / $pi" | bc -l)"
printf 'median whole process, replacing the previous output: mvem %.4f s, peer %.4f s, ratio mvem/peer %.3f\n' "$mw" "$pw" "$(echo "$mw / $pw" | bc -l)"
nmw=$(median <"$work/nmw"); npw=$(median <"$work/npw")
printf 'median whole process, new output file: mvem %.4f s, peer %.4f s, ratio mvem/peer %.3f\n' "$nmw" "$npw" "$(echo "$nmw / $npw" | bc -l)"
