#!/usr/bin/env python3
"""How far a change of the simulations' rounding (a numeric change of the integrator, another
compiler or CPU) moves the tuning: compare two reports of the same campaign made by two builds.

Usage: scripts/tuning-builds.py [--limit L] REPORT_A REPORT_B [REPORT_A2 REPORT_B2 ...]

Each REPORT is a `mvem tune --report DIR` directory (its tune_report.json). For every parameter
of the final estimates, and for V_im, V_em, J_t of the first step-3 pass (on step 1's static
maps, which no simulation touches), prints the values, the larger of the two standard errors and
|value_A - value_B| / that standard error. Meaningful with reproducible standard errors, i.e.
reports made with `mvem tune --fixed-jacobian sigma-points` (the default forward differences
move with the rounding themselves, docs/tuning.md, session 22). Exit status 1 when a parameter
reported identifiable in both moves by more than L standard errors (default 0.5).

Measured in session 22 (main and main with the inverse stage solves, lab seeds 1, 3, 4): at
most 0.12 in the first step-3 pass (flagged there), 0.50 after step 5 (seed 1's J_t).
"""
import json
import sys


def load(d):
    return json.load(open(f"{d}/tune_report.json"))


def first_step3(rep):
    st = rep.get("step3") or {}
    unc = st.get("uncertainty") or []
    items = unc.items() if isinstance(unc, dict) else unc
    return {name: e for name, e in items if name in ("v_im", "v_em", "j_t")}


def compare(title, a, b, limit):
    worst, bad = 0.0, []
    print(f"{title}")
    print(f"  {'parameter':32s} {'value A':>12s} {'value B':>12s} {'se':>10s} {'|dA-B|/se':>9s}")
    for name in sorted(set(a) & set(b)):
        ea, eb = a[name], b[name]
        se = max(ea.get("std_error") or 0.0, eb.get("std_error") or 0.0)
        if not (se > 0.0 and se != float("inf")):
            continue
        z = abs(ea["value"] - eb["value"]) / se
        both = ea.get("identifiable") and eb.get("identifiable")
        mark = "" if both else "  (flagged)"
        print(f"  {name:32s} {ea['value']:12.6g} {eb['value']:12.6g} {se:10.3g} {z:9.2f}{mark}")
        if both:
            worst = max(worst, z)
            if z > limit:
                bad.append(name)
    return worst, bad


def main():
    args = sys.argv[1:]
    limit = 0.5
    if args[:1] == ["--limit"]:
        limit = float(args[1])
        args = args[2:]
    if not args or len(args) % 2:
        sys.exit(__doc__)
    fails = []
    for a_dir, b_dir in zip(args[::2], args[1::2]):
        a, b = load(a_dir), load(b_dir)
        for rep in (a, b):
            if rep.get("fixed_jacobian") != "sigma-points":
                print(f"note: {a_dir if rep is a else b_dir} was not made with "
                      "--fixed-jacobian sigma-points; its standard errors move with the rounding")
        w1, b1 = compare(f"{a_dir} vs {b_dir}: first step 3", first_step3(a), first_step3(b), limit)
        w2, b2 = compare(f"{a_dir} vs {b_dir}: final", a["parameters"], b["parameters"], limit)
        print(f"  largest move of a parameter identifiable in both: first step 3 {w1:.2f}, "
              f"final {w2:.2f} standard errors (limit {limit})")
        fails += b1 + b2
    if fails:
        print(f"moved by more than {limit} standard errors: {', '.join(sorted(set(fails)))}")
        sys.exit(1)


if __name__ == "__main__":
    main()
