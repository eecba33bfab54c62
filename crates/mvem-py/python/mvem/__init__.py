"""mvem: mean-value diesel engine model with VGT and EGR (Wahlstrom & Eriksson 2011).

Functions (implemented in Rust, the GIL is released while the model runs):

- simulate(inputs, t_end=None, dt=0.01, rtol=1e-6, atol=1e-8, params=None) -> dict of numpy arrays
- steady(n_e, u_delta, u_egr, u_vgt, params=None) -> dict
- published_params() -> dict

Units: Pa, K, kg/s, rad/s (omega_t), rpm (n_e, n_t), Nm, %, mg/cycle/cylinder.
"""

from ._mvem import __version__, published_params, simulate, steady

INPUT_COLUMNS = ("time_s", "n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct")

__all__ = ["simulate", "steady", "published_params", "INPUT_COLUMNS", "__version__"]
