"""A Gymnasium environment for EGR/VGT control on the mvem plant (needs `pip install gymnasium`).

AirPathEnv: every episode drives the 8-state model through a random sequence of operating
points (engine speed n_e and fuel u_delta held for 2-4 s each, seeded by ``reset(seed=...)``).
The agent sets the EGR valve and the VGT every ``dt`` seconds (default 0.05 s, 10 s episodes).

Action (``Box(-1, 1, (2,))``): u_egr = 50 (a0 + 1) % in [0, 100], u_vgt = 20 + 40 (a1 + 1) % in
[20, 100].

Observation (``Box``, float32, 9 values, each scaled to about [0, 1]):
``[n_e/2000 rpm, u_delta/250 mg, lambda_O/5, x_egr, p_im/4e5 Pa, p_em/4e5 Pa, omega_t/1.5e4 rad/s,
x_egr_ref, lambda_min/5]``.

Targets: x_egr_ref = 0.3 (1 - u_delta / 250) (more EGR at low load), lambda_min = 1.4.

Reward per step: ``-((x_egr - x_egr_ref) / 0.05)**2 - 10 max(0, lambda_min - lambda_O)**2
- (p_em - p_im) / 1e5`` (EGR tracking, smoke, pumping work). The episode is truncated after
``duration`` seconds; it terminates (reward -100) if the solver fails.
"""

import math

import numpy as np

try:
    import gymnasium as gym
    from gymnasium import spaces
except ImportError as e:  # pragma: no cover - optional dependency
    raise ImportError("mvem.gym needs gymnasium: pip install gymnasium") from e

from . import Plant

OBS_SCALE = np.array([2000.0, 250.0, 5.0, 1.0, 4e5, 4e5, 1.5e4, 1.0, 5.0])


class AirPathEnv(gym.Env):
    """EGR/VGT control on random operating-point sequences (see the module docstring)."""

    metadata = {"render_modes": []}

    def __init__(self, dt=0.05, duration=10.0, lambda_min=1.4, model=8, params=None):
        super().__init__()
        self.dt = float(dt)
        self.duration = float(duration)
        self.lambda_min = float(lambda_min)
        self._model = model
        self._params = params
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(
            low=np.full(9, -1.0, dtype=np.float32),
            high=np.full(9, 10.0, dtype=np.float32),
            dtype=np.float32,
        )
        self._plant = None
        self._schedule = []
        self._u = (50.0, 60.0)

    def _point(self, t):
        for t0, n_e, u_delta in reversed(self._schedule):
            if t >= t0 - 1e-9:
                return n_e, u_delta
        return self._schedule[0][1], self._schedule[0][2]

    def _obs(self, out, u_delta):
        x_ref = 0.3 * (1.0 - u_delta / 250.0)
        v = np.array(
            [out["n_e"], out["u_delta"], min(out["lambda_O"], 40.0), out["x_egr"], out["p_im"],
             out["p_em"], out["omega_t"], x_ref, self.lambda_min]
        )
        return np.clip(v / OBS_SCALE, -1.0, 10.0).astype(np.float32), x_ref

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        rng = self.np_random
        t, self._schedule = 0.0, []
        while t < self.duration:
            self._schedule.append(
                (t, float(rng.uniform(1000.0, 1900.0)), float(rng.uniform(40.0, 180.0))))
            t += float(rng.uniform(2.0, 4.0))
        n_e, u_delta = self._schedule[0][1], self._schedule[0][2]
        self._u = (50.0, 60.0)
        self._plant = Plant(n_e, u_delta, self._u[0], self._u[1], model=self._model,
                            params=self._params)
        obs, _ = self._obs(self._plant.outputs(), u_delta)
        return obs, {"t": 0.0}

    def step(self, action):
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (2,) or not np.isfinite(a).all():
            raise ValueError(f"action: expected 2 finite numbers in [-1, 1] (u_egr, u_vgt), got {action!r}")
        a = np.clip(a, -1.0, 1.0)
        u_egr = 50.0 * (a[0] + 1.0)
        u_vgt = 20.0 + 40.0 * (a[1] + 1.0)
        n_e, u_delta = self._point(self._plant.t)
        try:
            out = self._plant.step(self.dt, n_e=n_e, u_delta=u_delta, u_egr=u_egr, u_vgt=u_vgt)
        except RuntimeError as e:
            obs = np.zeros(9, dtype=np.float32)
            return obs, -100.0, True, False, {"error": str(e)}
        obs, x_ref = self._obs(out, u_delta)
        lam = out["lambda_O"]
        reward = (-((out["x_egr"] - x_ref) / 0.05) ** 2
                  - 10.0 * max(0.0, self.lambda_min - lam) ** 2
                  - (out["p_em"] - out["p_im"]) / 1e5)
        truncated = self._plant.t >= self.duration - 1e-9
        info = {"t": self._plant.t, "x_egr": out["x_egr"], "lambda_O": lam,
                "x_egr_ref": x_ref, "W_c": out["W_c"]}
        return obs, float(reward) if math.isfinite(reward) else -100.0, False, truncated, info
