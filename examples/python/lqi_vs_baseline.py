"""An LQ-integral controller designed from mvem.linearize, on set-point steps of x_egr and
lambda_O at 1500 rpm / 110 mg, next to the baseline PI/selector controller (docs/control.md).

Design: the 8-state linearization at (1500 rpm, 110 mg, u_egr 50 %, u_vgt 60 %) with inputs
u_egr, u_vgt and outputs x_egr, lambda_O, sampled at 10 ms; two output integrators; the discrete
Riccati equation iterated to convergence. Full state feedback from plant.state (the model's
states, i.e. a perfect observer). Two design models: the continuous undelayed one discretized
here by the matrix exponential (the actuator delays, 65 / 40 ms, left out), and
mvem.linearize(..., ts=0.01)'s sampled model with the delays exact, whose extra states are the
past commands (the controller keeps them). Both at input weights 5 % and 10 %: at 10 % the design
without the delays drives the VGT into its limit; the one with them settles.

    python examples/python/lqi_vs_baseline.py
"""

import numpy as np

import mvem

DT = 0.01
OP = dict(n_e=1500.0, u_delta=110.0, u_egr=50.0, u_vgt=60.0)


def expm(m):
    """Matrix exponential by scaling and squaring with a Taylor series (small matrices)."""
    s = max(0, int(np.ceil(np.log2(max(np.linalg.norm(m, 1), 1e-16)))) + 1)
    a = m / 2.0**s
    e, term = np.eye(len(m)), np.eye(len(m))
    for k in range(1, 20):
        term = term @ a / k
        e = e + term
    for _ in range(s):
        e = e @ e
    return e


def riccati_gain(aa, ba, q, r):
    """The discrete LQ gain: the Riccati equation iterated to convergence."""
    p = q.copy()
    for _ in range(20000):
        k = np.linalg.solve(r + ba.T @ p @ ba, ba.T @ p @ aa)
        p_new = q + aa.T @ p @ (aa - ba @ k)
        if np.max(np.abs(p_new - p)) < 1e-9 * np.max(np.abs(p)):
            p = p_new
            break
        p = p_new
    return np.linalg.solve(r + ba.T @ p @ ba, ba.T @ p @ aa)


def weights(c, n, w_u):
    """Outputs scaled by typical changes (x_egr 0.01, lambda_O 0.1), integrators by half of
    them, inputs by w_u [%]."""
    q = np.zeros((n + 2, n + 2))
    q[:n, :n] = c.T @ np.diag([1 / 0.01**2, 1 / 0.1**2]) @ c
    q[n:, n:] = np.diag([1 / (0.01 * 0.5) ** 2, 1 / (0.1 * 0.5) ** 2])
    return q, np.diag([1.0 / w_u**2, 1.0 / w_u**2])


def lqi_gain(lin, w_u):
    """Design on the continuous undelayed model, discretized here by the matrix exponential."""
    a, b, c = lin["A"], lin["B"], lin["C"]
    iu = [lin["input_names"].index("u_egr"), lin["input_names"].index("u_vgt")]
    b = b[:, iu]
    n, m = a.shape[0], 2
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = a, b
    e = expm(big * DT)
    ad, bd = e[:n, :n], e[:n, n:]
    # augmented: z+ = z + DT (y - r)
    aa = np.block([[ad, np.zeros((n, 2))], [DT * c, np.eye(2)]])
    ba = np.vstack([bd, np.zeros((2, m))])
    return riccati_gain(aa, ba, *weights(c, n, w_u))


def lqi_gain_delays(lin, w_u):
    """Design on mvem's sampled model with the actuator delays exact (linearize(ts=DT)): its
    states are the engine's and the registers of the past commands u_egr(k-1), ..., which the
    controller knows (it sent them)."""
    d = lin["discrete"]
    phi, c = d["Phi"], d["C"]
    iu = [d["input_names"].index("u_egr"), d["input_names"].index("u_vgt")]
    gam = d["Gamma"][:, iu]
    n, m = phi.shape[0], 2
    aa = np.block([[phi, np.zeros((n, 2))], [DT * c, np.eye(2)]])
    ba = np.vstack([gam, np.zeros((2, m))])
    return riccati_gain(aa, ba, *weights(c, n, w_u))


def run_step(signal, delta, w_u=5.0, delays=False):
    """The set-point step of `signal` by `delta` at t = 2 s with the LQI of input weight w_u
    [%], designed without (delays=False) or with the delays (the sampled model's registers)."""
    lin = mvem.linearize(**OP, outputs=["x_egr", "lambda_O"], ts=DT if delays else None)
    k = lqi_gain_delays(lin, w_u) if delays else lqi_gain(lin, w_u)
    names = lin["discrete"]["state_names"] if delays else []
    # registers: the past commands (deviations), newest first, per channel
    regs = {ch: [0.0] * sum(1 for s in names if s.startswith(ch + "(")) for ch in ("u_egr", "u_vgt")}
    x0, y0 = lin["x0"], lin["y0"]
    plant = mvem.Plant(**OP)
    z = np.zeros(2)
    u0 = np.array([OP["u_egr"], OP["u_vgt"]])
    ref = np.array(y0, dtype=float)
    t_log, y_log = [], []
    for i in range(1500):
        t = i * DT
        r = ref.copy()
        if t >= 2.0:
            r[0 if signal == "x_egr" else 1] += delta
        out = plant.outputs()
        y = np.array([out["x_egr"], out["lambda_O"]])
        z = z + DT * (y - r)
        u = u0 - k @ np.concatenate([plant.state - x0, regs["u_egr"], regs["u_vgt"], z])
        u = np.clip(u, [0.0, 20.0], [100.0, 100.0])
        for j, ch in enumerate(("u_egr", "u_vgt")):
            if regs[ch]:
                regs[ch] = [u[j] - u0[j]] + regs[ch][:-1]
        out = plant.step(DT, u_egr=u[0], u_vgt=u[1])
        t_log.append(plant.t)
        y_log.append(out[signal])
    i0 = 0 if signal == "x_egr" else 1
    m = mvem.step_metrics(t_log, y_log, t_step=2.0, y0=ref[i0], y_final=ref[i0] + delta,
                          du=delta)
    return m, u


def fmt(v):
    return "-" if v is None else f"{v:.2f}"


if __name__ == "__main__":
    for delays in (False, True):
        for w_u in (5.0, 10.0):
            for signal, delta in [("x_egr", 0.02), ("lambda_O", 0.2)]:
                m, u = run_step(signal, delta, w_u, delays)
                print(f"LQI {'with' if delays else 'without'} delays, weight {w_u:.0f} %, "
                      f"{signal:8} +{delta}: rise {fmt(m['rise_time'])} s, settling "
                      f"{fmt(m['settling_time'])} s, overshoot {m['overshoot_pct']:.1f} %, "
                      f"final u_egr/u_vgt {u[0]:.1f}/{u[1]:.1f} %")
    print("baseline (docs/control.md, same point, from its own steady set-points): "
          "x_egr +0.02 rise 0.75 s settling 2.32 s; lambda_O +0.2 rise 1.98 s settling 9.14 s")
