"""VGT step responses at several operating points on a local dask.distributed cluster or ray.

The path for sweeps that outgrow one machine: the same code runs on a remote cluster by giving
dask's Client the scheduler address (or ray.init(address=...)). The cases are split into one
chunk per worker; each task runs its chunk with one mvem.simulate_many call (all the worker's
cores, the GIL released) and computes the step metrics of mvem demo (mvem.step_metrics, the
final value from mvem.steady). Run:

    python examples/python/sweep_ray_or_dask.py [--backend auto|dask|ray] [--model 8|10|12]

auto: dask.distributed's LocalCluster if installed, else ray, else says so and exits with
status 0. Install one with `pip install "dask[distributed]"` or `pip install ray`.
"""

import argparse
import sys

import mvem

CASES = [(n, d) for n in (1200.0, 1500.0, 1800.0) for d in (80.0, 110.0, 150.0)]
WORKERS = 2


def vgt_step(n_e, u_delta):
    """Inputs of a VGT step 75 -> 65 % at 1 s, u_egr 80 % (n_e [rpm], u_delta [mg])."""
    return {"time_s": [0.0, 1.0, 1.0, 8.0], "n_e_rpm": [n_e] * 4, "u_delta_mg": [u_delta] * 4,
            "u_egr_pct": [80.0] * 4, "u_vgt_pct": [75.0, 75.0, 65.0, 65.0]}


def steps(chunk, model=8):
    """W_c responses of a chunk of (n_e, u_delta) cases: one simulate_many call per task."""
    runs = mvem.simulate_many([vgt_step(n, d) for n, d in chunk], dt=0.05, model=model)
    rows = []
    for (n_e, u_delta), r in zip(chunk, runs):
        y_final = mvem.steady(n_e, u_delta, 80.0, 65.0, model=model)["W_c"]
        m = mvem.step_metrics(r["t"], r["W_c"], 1.0, r["W_c"][0], y_final, -10.0)
        rows.append({"n_e_rpm": n_e, "u_delta_mg": u_delta, "W_c_start": m["y0"],
                     "W_c_end": m["y_final"], "dc_gain": m["dc_gain"],
                     "non_minimum_phase": m["non_minimum_phase"],
                     "wrong_way_pct": 100 * m["wrong_way"]["relative"] if m["wrong_way"] else 0.0})
    return rows


def chunks():
    return [CASES[i::WORKERS] for i in range(WORKERS)]


def with_dask(model):
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=WORKERS, threads_per_worker=1, processes=True) as cluster, \
            Client(cluster) as client:
        futures = [client.submit(steps, c, model) for c in chunks()]
        return [r for rows in client.gather(futures) for r in rows]


def with_ray(model):
    import ray

    ray.init(num_cpus=WORKERS, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(steps)
        return [r for rows in ray.get([remote.remote(c, model) for c in chunks()]) for r in rows]
    finally:
        ray.shutdown()


def available(module):
    try:
        __import__(module)
        return True
    except ImportError:
        return False


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", choices=["auto", "dask", "ray"], default="auto")
    ap.add_argument("--model", type=int, choices=[8, 10, 12], default=8)
    a = ap.parse_args()
    backends = {"dask": ("dask.distributed", with_dask), "ray": ("ray", with_ray)}
    order = ["dask", "ray"] if a.backend == "auto" else [a.backend]
    for b in order:
        module, run = backends[b]
        if not available(module):
            if a.backend != "auto":
                print(f"{module} is not installed", file=sys.stderr)
                return 2
            continue
        rows = run(a.model)
        print(f"{len(rows)} VGT steps (75 -> 65 %, {a.model}-state model) on {module}:")
        for r in rows:
            print(f"  n_e {r['n_e_rpm']:6.0f} rpm, u_delta {r['u_delta_mg']:5.0f} mg: "
                  f"W_c {r['W_c_start']:.4f} -> {r['W_c_end']:.4f} kg/s, "
                  f"dW_c/du_vgt {r['dc_gain']:+.2e} kg/s per %, wrong way "
                  f"{r['wrong_way_pct']:.0f} %{' (non-minimum phase)' if r['non_minimum_phase'] else ''}")
        return 0
    print("neither dask.distributed nor ray is installed: pip install 'dask[distributed]' or ray;"
          " skipping")
    return 0


if __name__ == "__main__":
    sys.exit(main())
