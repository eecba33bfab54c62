#!/usr/bin/env python3
"""Calibration of the reported standard errors by Monte Carlo: several campaigns of the same
engine (e.g. `mvem lab --seed S --out campS` for S = 1..8, each tuned with
`mvem tune --data campS --report repS`) give an empirical spread of every estimate, to put next
to the standard errors the reports state.

Usage: scripts/tuning-spread.py REPORT_DIR:CAMPAIGN_DIR [REPORT_DIR:CAMPAIGN_DIR ...]

The campaigns must share the true parameters (CAMP/true_params.toml; tau_Me from
CAMP/manifest.toml). For every parameter of the reports, one line:
  n        campaigns in which the parameter was reported
  bias     mean of (value - true) / |true|                             [%]
  rms      root mean square of (value - true) / |true|                  [%]
  se med   median reported relative standard error se / |value|        [%]
  se/rms   se med / rms: about 1 when the standard errors are calibrated, >> 1 when they
           overstate the uncertainty, << 1 when they understate it
  z rms    root mean square of (value - true) / se (about 1 when calibrated)
  id       campaigns that report the parameter identifiable
Parameters whose truth is 0 print the absolute error in place of the relative one (marked *).
With fewer than about 8 campaigns the figures are rough (a root mean square of n values has a
relative standard error of about 1 / sqrt(2 n)).
"""
import json
import math
import statistics
import sys
import tomllib

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from importlib import import_module

lookup = import_module("tuning-compare").lookup


def main():
    pairs = [a.split(":", 1) for a in sys.argv[1:]]
    if not pairs or any(len(p) != 2 for p in pairs):
        sys.exit(__doc__)
    rows = {}
    for rep, camp in pairs:
        params = json.load(open(f"{rep}/tune_report.json"))["parameters"]
        truth = tomllib.load(open(f"{camp}/true_params.toml", "rb"))
        manifest = tomllib.load(open(f"{camp}/manifest.toml", "rb"))
        for path, e in params.items():
            t = manifest.get("true_tau_me_s") if path == "test_cell.tau_me" else lookup(truth, path)
            if t is None or not isinstance(t, (int, float)):
                continue
            se = e["std_error"] if e["std_error"] is not None else math.inf
            rows.setdefault(path, []).append((e["value"], float(t), se, e["identifiable"]))
    print(f"{'parameter':32} {'n':>2} {'bias %':>9} {'rms %':>9} {'se med %':>10} "
          f"{'se/rms':>8} {'z rms':>7} {'id':>4}")
    for path in sorted(rows):
        r = rows[path]
        t = r[0][1]
        rel = t != 0.0
        den = abs(t) if rel else 1.0
        err = [(v - t) / den for v, _, _, _ in r]
        bias = statistics.fmean(err)
        rms = math.sqrt(statistics.fmean([x * x for x in err]))
        se_rel = statistics.median([se / (abs(v) if rel and v else 1.0) for v, _, se, _ in r])
        z = [(v - t) / se for v, t, se, _ in r if 0 < se < math.inf]
        z_rms = math.sqrt(statistics.fmean([x * x for x in z])) if z else math.nan
        ratio = se_rel / rms if rms > 0 else math.inf
        ident = sum(1 for *_, i in r if i)
        scale = 100.0 if rel else 1.0
        mark = " " if rel else "*"
        print(f"{path:32} {len(r):2d} {scale * bias:9.3g}{mark}{scale * rms:8.3g}{mark}"
              f"{scale * se_rel:9.3g}{mark} {ratio:8.3g} {z_rms:7.3g} {ident:2d}/{len(r)}")


if __name__ == "__main__":
    main()
