"""Benchmark: 10,000 calls of mvem.Plant.step(0.01) at the paper's operating point with a
changing VGT command (target: <= 0.5 s, i.e. <= 50 us per call including Python overhead).

    python examples/python/bench_plant.py
"""

import os
import time

import mvem

plant = mvem.Plant(n_e=1500.0, u_delta=110.0, u_egr=80.0, u_vgt=75.0)
n = 10_000
t0 = time.perf_counter()
c0 = time.process_time()
for k in range(n):
    plant.step(0.01, u_vgt=75.0 - 10.0 * ((k // 100) % 2))   # a 1 s square wave
wall = time.perf_counter() - t0
cpu = time.process_time() - c0
print(f"{n} steps: {wall:.3f} s wall ({1e6 * wall / n:.1f} us per step), {cpu:.3f} s CPU; "
      f"load average {os.getloadavg()[0]:.1f}")
