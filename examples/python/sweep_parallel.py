"""Steady states over a grid of operating points, in parallel with concurrent.futures.

mvem releases the GIL while the model runs, so a ThreadPoolExecutor uses all cores without
pickling; a ProcessPoolExecutor works as well. Run:

    python examples/python/sweep_parallel.py [--workers N] [--out sweep.csv]
"""

import argparse
import csv
import itertools
import os
import time
from concurrent.futures import ThreadPoolExecutor

import mvem

COLUMNS = ["n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct", "p_im", "p_em", "W_c", "W_egr",
           "lambda_O", "M_e", "n_t", "physically_valid"]


def point(args):
    n_e, u_delta, u_egr, u_vgt = args
    try:
        s = mvem.steady(n_e, u_delta, u_egr, u_vgt)
    except RuntimeError as e:  # no equilibrium at this point
        return {"n_e_rpm": n_e, "u_delta_mg": u_delta, "u_egr_pct": u_egr, "u_vgt_pct": u_vgt,
                "error": str(e)}
    return {k: s[k] for k in COLUMNS}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--out", default=None, help="CSV file to write (default: print a summary)")
    a = ap.parse_args()
    grid = list(itertools.product([1200, 1500, 1800], [50, 110, 180], [0, 40, 80],
                                  [30, 50, 75, 100]))
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=a.workers) as ex:
        rows = list(ex.map(point, grid))
    dt = time.perf_counter() - t0
    ok = [r for r in rows if "error" not in r]
    print(f"{len(grid)} operating points with {a.workers} threads in {dt:.2f} s "
          f"({len(ok)} solved, {sum(r['physically_valid'] for r in ok)} physically valid)")
    if a.out:
        with open(a.out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS + ["error"])
            w.writeheader()
            w.writerows(rows)
        print(f"wrote {a.out}")
    else:
        best = max(ok, key=lambda r: r["M_e"])
        print(f"largest torque {best['M_e']:.1f} Nm at n_e {best['n_e_rpm']} rpm, "
              f"u_delta {best['u_delta_mg']} mg, u_egr {best['u_egr_pct']} %, "
              f"u_vgt {best['u_vgt_pct']} %")


if __name__ == "__main__":
    main()
