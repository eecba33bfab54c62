#!/usr/bin/env python3
"""Compare the "parameters" of a tune_report.json (`mvem tune --report DIR`) with the true
parameters of a virtual campaign (`mvem lab --out CAMP`: CAMP/true_params.toml, tau_Me from
CAMP/manifest.toml; the sensor time constants from its true_sensor_lags_s, 0 when absent).

Usage: scripts/tuning-compare.py REPORT_DIR CAMPAIGN_DIR

Prints one line per parameter (value, truth, std. error, (value - truth) / std. error,
identifiable, reason) and a summary: identifiable and within 3 std. errors, flagged, and
identifiable but more than 3 std. errors off or with a relative std. error above 25 % (the
issue-14 acceptance of docs/tuning.md). Exit status 1 when that last group is not empty.
"""
import json
import re
import sys
import tomllib


def lookup(tree, path):
    """The value at a report key ("turbo.j_t", "cylinder.c_vol[1]", "compressor.q_c[1][2]":
    the parameter registry's names, elements counted from 1) in a parsed parameter file."""
    node = tree
    for part in path.split("."):
        m = re.fullmatch(r"(\w+)((?:\[\d+\])*)", part)
        if not m:
            return None
        node = node.get(m.group(1)) if isinstance(node, dict) else None
        for idx in re.findall(r"\[(\d+)\]", m.group(2)):
            if not isinstance(node, list) or not 1 <= int(idx) <= len(node):
                return None
            node = node[int(idx) - 1]
        if node is None:
            return None
    return node


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    rep, camp = sys.argv[1], sys.argv[2]
    params = json.load(open(f"{rep}/tune_report.json"))["parameters"]
    truth = tomllib.load(open(f"{camp}/true_params.toml", "rb"))
    manifest = tomllib.load(open(f"{camp}/manifest.toml", "rb"))
    ok, flagged, bad = [], [], []
    print(f"{'parameter':32} {'value':>13} {'true':>13} {'std.err':>10} {'off/SE':>8}  id  reason")
    for path, e in sorted(params.items()):
        lags = dict(zip(["test_cell.tau_p_im", "test_cell.tau_p_em", "test_cell.tau_w_c",
                         "test_cell.tau_n_t"], manifest.get("true_sensor_lags_s", [0.0] * 4)))
        if path == "test_cell.tau_me":
            t = manifest.get("true_tau_me_s")
        elif path in lags:
            t = lags[path]
        else:
            t = lookup(truth, path)
        v = e["value"]
        se = e["std_error"] if e["std_error"] is not None else float("inf")
        z = (v - t) / se if t is not None and se > 0 else float("nan")
        rel = se / abs(v) if v else float("inf")
        ident = e["identifiable"]
        print(f"{path:32} {v:13.6e} {t if t is not None else float('nan'):13.6e} "
              f"{se:10.3e} {z:8.2f}  {'Y' if ident else '-'}   {e['reason']}")
        if not ident:
            flagged.append(path)
        elif abs(z) <= 3.0 and rel <= 0.25:
            ok.append(path)
        else:
            bad.append(f"{path} ({z:.1f} SE, rel. {100 * rel:.1f} %)")
    print(f"identifiable and within 3 SE: {len(ok)}; flagged: {len(flagged)}; "
          f"identifiable but off: {len(bad)} {', '.join(bad)}")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
