"""VGT step responses at several operating points on a local dask.distributed cluster (or ray).

Uses dask.distributed's LocalCluster if installed, else ray in local mode, else says so and
exits with status 0. Run:

    python examples/python/sweep_ray_or_dask.py
"""

import sys

import mvem


def step_response(n_e, u_delta, u_egr=80.0, u_vgt=(75.0, 65.0), t_step=1.0, t_end=8.0):
    """W_c [kg/s] before and at the end of a VGT step, and its minimum (non-minimum phase)."""
    inputs = {
        "time_s": [0.0, t_step, t_step, t_end],
        "n_e_rpm": [n_e] * 4,
        "u_delta_mg": [u_delta] * 4,
        "u_egr_pct": [u_egr] * 4,
        "u_vgt_pct": [u_vgt[0], u_vgt[0], u_vgt[1], u_vgt[1]],
    }
    r = mvem.simulate(inputs, dt=0.05)
    w = r["W_c"]
    return {"n_e_rpm": n_e, "u_delta_mg": u_delta, "W_c_start": float(w[0]),
            "W_c_min": float(w.min()), "W_c_end": float(w[-1])}


CASES = [(n, d) for n in (1200.0, 1500.0, 1800.0) for d in (80.0, 110.0, 150.0)]


def with_dask():
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster, \
            Client(cluster) as client:
        futures = [client.submit(step_response, n, d) for n, d in CASES]
        return client.gather(futures)


def with_ray():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(step_response)
        return ray.get([remote.remote(n, d) for n, d in CASES])
    finally:
        ray.shutdown()


def main():
    for name, run in (("dask.distributed", with_dask), ("ray", with_ray)):
        try:
            __import__(name.split(".")[0] if name == "ray" else "dask.distributed")
        except ImportError:
            continue
        rows = run()
        print(f"{len(rows)} VGT steps on {name}:")
        for r in rows:
            sign = "+" if r["W_c_end"] > r["W_c_start"] else "-"
            print(f"  n_e {r['n_e_rpm']:6.0f} rpm, u_delta {r['u_delta_mg']:5.0f} mg: "
                  f"W_c {r['W_c_start']:.4f} -> {r['W_c_end']:.4f} kg/s (DC gain sign {sign}), "
                  f"min {r['W_c_min']:.4f}")
        return 0
    print("neither dask.distributed nor ray is installed: pip install 'dask[distributed]' or ray;"
          " skipping")
    return 0


if __name__ == "__main__":
    sys.exit(main())
