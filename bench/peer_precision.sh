#!/usr/bin/env bash
# Work against accuracy, side by side with the C/SUNDIALS-CVODE peer: both programs integrate the
# WHTC over a sweep of tolerances, each point's time is measured alternately with the other
# program's, and each point's accuracy is the max scaled deviation of p_im, p_em (by 1e5 Pa),
# X_Oim, X_Oem (by 0.1) and omega_t (by 1e4 rad/s) over the 0.1 s samples from one tight
# reference (mvem, rtol 1e-10, every state integrated numerically: `whtc_once --check`). The
# ratio of the two programs at their default tolerance (bench/peer.sh) compares two different
# accuracies; this script also gives mvem's time at the peer's accuracy, interpolated in log-log
# between mvem's points.
#
# Usage: bench/peer_precision.sh PEER_DIR [ROUNDS]
#   PEER_DIR  a checkout of the peer (Makefile, whtc_cvode.c, model.c, x0.txt); copied to a
#             temporary directory and built there with `make` (needs libsundials-dev).
#   ROUNDS    alternated rounds of the whole sweep (default 3); the time of a point is the median
#             over the rounds of the min of REPEAT runs.
#   REPEAT    (environment, default 3) runs per point and round.
#   RTOLS     (environment) the tolerances, default "1e-4 3e-5 1e-5 3e-6 1e-6 3e-7 1e-7 3e-8".
#   OUT       (environment) also write the points as CSV to this file.
#
# The peer runs in its `stop` mode (a stop time at every input row) with its own absolute
# tolerance (atol_i = 1e-2 x rtol x scale_i, its default) and, as a second series, with mvem's
# (atol_i = rtol x scale_i, --atol-factor 1). mvem runs at its defaults with --rtol R (atol =
# rtol x scale), one thread. The peer writes 12 significant digits, far below the deviations
# measured here.
set -euo pipefail

peer_src=${1:?usage: bench/peer_precision.sh PEER_DIR [ROUNDS]}
rounds=${2:-3}
repeat=${REPEAT:-3}
rtols=${RTOLS:-"1e-4 3e-5 1e-5 3e-6 1e-6 3e-7 1e-7 3e-8"}
root=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cp -r "$peer_src" "$work/peer"
make -s -C "$work/peer" whtc_cvode >/dev/null
cargo build --release -q -p mvem-cli --manifest-path "$root/Cargo.toml"
cargo build --release -q -p mvem --example whtc_once --manifest-path "$root/Cargo.toml"
mvem=$root/target/release/mvem
once=$root/target/release/examples/whtc_once
inputs="$root/data/whtc_inputs_10hz.csv"
params="$root/data/wahlstrom_eriksson_2011_parameters.json"
peer() { "$work/peer/whtc_cvode" --inputs "$inputs" --params "$params" --x0 "$work/peer/x0.txt" \
    --dt 0.1 --mode stop "$@"; }

# the peer's CSV (t, p_im, p_em, X_Oim, X_Oem, omega_t, ...) against whtc_once's reference file
# (one line per compared state, 18 001 values each)
maxdev() {
    python3 - "$work/ref.csv" "$1" <<'EOF'
import csv, sys
ref = [[float(v) for v in line.split(",")] for line in open(sys.argv[1])]
scale = [1e5, 1e5, 0.1, 0.1, 1e4]
rows = list(csv.reader(open(sys.argv[2])))[1:]
assert len(rows) == len(ref[0]), (len(rows), len(ref[0]))
print("%.3e" % max(abs(float(r[k + 1]) - ref[k][i]) / scale[k]
                   for k in range(5) for i, r in enumerate(rows)))
EOF
}

echo "load before: $(uptime)"
echo "reference (mvem rtol 1e-10, every state integrated numerically) ..."
"$once" --check "$work/ref.csv" >/dev/null
# accuracy: deterministic, measured once per point
for r in $rtols; do
    "$once" --rtol "$r" --atol "$r" --check "$work/ref.csv" | awk '/max dev/ {print $3}' >"$work/dev_m_$r"
    peer --rtol "$r" --out "$work/p.csv" --quiet 2>/dev/null; maxdev "$work/p.csv" >"$work/dev_p_$r"
    peer --rtol "$r" --atol-factor 1 --out "$work/p.csv" --quiet 2>/dev/null; maxdev "$work/p.csv" >"$work/dev_q_$r"
    : >"$work/t_m_$r"; : >"$work/t_p_$r"; : >"$work/t_q_$r"
done
# the peer's deviation at its tightest, with mvem's model: the floor the two ports agree to
peer --rtol 1e-10 --out "$work/p.csv" --quiet 2>/dev/null
echo "peer at rtol 1e-10 against the reference: $(maxdev "$work/p.csv") (the two ports' agreement)"

for round in $(seq 1 "$rounds"); do
    for r in $rtols; do
        "$mvem" bench --rtol "$r" --repeat "$repeat" --no-reference --evals 1 --dt 0.1 --time-parallel 1 |
            awk '/wall time/ {v=$4; u=$5; print (u ~ /^ms/) ? v/1000 : v; exit}' >>"$work/t_m_$r"
        peer --rtol "$r" --repeat "$repeat" 2>&1 | tr ' ' '\n' |
            awk -F= '/^integrate_s_min=/ {print $2}' >>"$work/t_p_$r"
        peer --rtol "$r" --atol-factor 1 --repeat "$repeat" 2>&1 | tr ' ' '\n' |
            awk -F= '/^integrate_s_min=/ {print $2}' >>"$work/t_q_$r"
    done
    echo "round $round done"
done
echo "load after: $(uptime)"

median() { sort -g "$1" | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
: >"$work/points"
for r in $rtols; do
    echo "$r $(median "$work/t_m_$r") $(cat "$work/dev_m_$r") $(median "$work/t_p_$r") $(cat "$work/dev_p_$r") $(median "$work/t_q_$r") $(cat "$work/dev_q_$r")" >>"$work/points"
done
python3 - "$work/points" "${OUT:-}" <<'EOF'
import math, sys
pts = [[float(v) for v in l.split()] for l in open(sys.argv[1])]
print("\nmedian over the rounds of the min of each round's runs [s]; max scaled deviation from the reference")
print("| rtol | mvem time | mvem dev | peer time | peer dev | peer (atol as mvem) time | dev |")
print("|---:|---:|---:|---:|---:|---:|---:|")
for r, tm, dm, tp, dp, tq, dq in pts:
    print(f"| {r:.0e} | {tm:.4f} | {dm:.2e} | {tp:.4f} | {dp:.2e} | {tq:.4f} | {dq:.2e} |")
# mvem's time at a given deviation: log-log interpolation between its points (the points sorted by
# deviation; outside their range: none)
mv = sorted((dm, tm) for _, tm, dm, *_ in pts)
def mvem_time_at(d):
    for (d0, t0), (d1, t1) in zip(mv, mv[1:]):
        if d0 <= d <= d1 and d1 > d0:
            w = (math.log(d) - math.log(d0)) / (math.log(d1) - math.log(d0))
            return math.exp(math.log(t0) + w * (math.log(t1) - math.log(t0)))
    return None
print("\nat equal accuracy: mvem's time interpolated at each peer point's deviation")
print("| peer rtol | peer atol factor | peer dev | peer time | mvem time at that dev | ratio mvem/peer |")
print("|---:|---:|---:|---:|---:|---:|")
for r, tm, dm, tp, dp, tq, dq in pts:
    for f, t, d in ((1e-2, tp, dp), (1.0, tq, dq)):
        m = mvem_time_at(d)
        if m is None:
            print(f"| {r:.0e} | {f:g} | {d:.2e} | {t:.4f} | outside mvem's sweep | |")
        else:
            print(f"| {r:.0e} | {f:g} | {d:.2e} | {t:.4f} | {m:.4f} | {m / t:.3f} |")
if sys.argv[2]:
    with open(sys.argv[2], "w") as f:
        f.write("rtol,mvem_s,mvem_dev,peer_s,peer_dev,peer_atol1_s,peer_atol1_dev\n")
        for p in pts:
            f.write(",".join(f"{v:.6g}" for v in p) + "\n")
EOF
