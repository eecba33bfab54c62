"""A user's PI controller in Python on mvem.Plant: x_egr held by the VGT at 1500 rpm, 110 mg.

The plant is the Rust model advanced 10 ms at a time with the commands held; the actuator
delays stay exact across calls. Run after `maturin develop --release -m crates/mvem-py/Cargo.toml`:

    python examples/python/plant_pi.py
"""

import mvem

DT = 0.01
plant = mvem.Plant(n_e=1500.0, u_delta=110.0, u_egr=60.0, u_vgt=60.0)
x_ref = plant.outputs()["x_egr"]
kp, ki = 150.0, 800.0          # % per unit x_egr, %/s per unit x_egr (as the Rust baseline)
integral = 60.0                # starts at the current VGT position: bumpless
e_prev = 0.0
log = []
for k in range(1500):          # 15 s
    t = k * DT
    if t >= 2.0:
        x_ref_now = x_ref + 0.02   # set-point step at 2 s
    else:
        x_ref_now = x_ref
    y = plant.outputs()["x_egr"]
    e = y - x_ref_now          # too little EGR -> close the VGT
    u = integral + ki * DT * e + kp * e
    u_sat = min(max(u, 20.0), 100.0)
    integral += ki * DT * e + (u_sat - u)   # tracking anti-windup
    out = plant.step(DT, u_vgt=u_sat)
    log.append((plant.t, out["x_egr"], u_sat))

t = [r[0] for r in log]
y = [r[1] for r in log]
m = mvem.step_metrics(t, y, t_step=2.0, y0=x_ref, y_final=x_ref + 0.02, du=0.02)
print(f"x_egr {x_ref:.4f} -> {x_ref + 0.02:.4f}: rise {m['rise_time']:.2f} s, "
      f"settling {m['settling_time']:.2f} s, overshoot {m['overshoot_pct']:.1f} %, "
      f"final u_vgt {log[-1][2]:.1f} %")
