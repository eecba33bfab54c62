"""mvem: mean-value diesel engine model with VGT and EGR (Wahlstrom & Eriksson 2011).

Functions (implemented in Rust; the GIL is released while the model runs, so threads run
in parallel):

- simulate(inputs, t_end=None, dt=0.01, rtol=1e-6, atol=None, params=None, model=8,
  cylinder_temp="converged", x0=None) -> dict of numpy arrays (from the steady state at the
  first inputs, or from the state x0)
- simulate_many(list_of_inputs, params=None, threads=None, on_error="raise", ...) -> list of
  dicts: many simulations at once on all cores (input or parameter variations), each equal to
  simulate() of its inputs
- steady(n_e, u_delta, u_egr, u_vgt, params=None, model=8) -> dict
- linearize(n_e, u_delta, u_egr, u_vgt, outputs=None, strict=True, pade_order=0, params=None,
  model=8) -> dict with A, B, C, D, eigenvalues, dc_gain, zeros, ...
- frequency_response(n_e, u_delta, u_egr, u_vgt, f_hz, outputs=None, ...) -> dict with "f_hz"
  and "G" {"u_vgt->W_c": complex array, ...}: the Bode diagram, the actuator delays exact
- Model(model=8, params=None): the right-hand side at any state, for optimal control and custom
  integrators: m.derivatives(x, u) -> dx/dt, m.jacobian(x, u, outputs=None) -> dict with f, A,
  B (and y, C, D), m.signals(x, u) -> dict; u = (n_e, u_delta, u_egr, u_vgt); one point or K
  points at once (states (K, n))
- derivatives(state, inputs, params=None, model=8), jacobian(state, inputs, outputs=None,
  strict=False, params=None, model=8): the same for one call
- step_metrics(t, y, t_step, y0, y_final, du) -> dict
- step_response(n_e, u_delta, u_egr, u_vgt, input="u_vgt", to=65.0, output="W_c", ...) -> dict
- published_params() -> dict
- variables() -> dict name -> {"kind", "unit", "description"} (inputs, states, signals)
- parameters() -> list of {"path", "symbol", "unit", "description", "published"}
- Plant(n_e, u_delta, u_egr, u_vgt, model=8, params=None): the model advanced sample by sample
  with held commands (plant.step(dt, u_egr=..., u_vgt=...) -> dict; plant.t, plant.state,
  plant.reset(...)); exact actuator delays across calls. For controllers written in Python.
- closed_loop(cycle=None, tuning=None, params=None, model=8, duration=None, margins=None) -> dict:
  a drive cycle (the WHTC, t/n_e/M_ref, or a cycle file's path: a demand or a normalized cycle)
  with the baseline EGR/VGT and engine controllers (tuning: a dict of their gains and limits), as
  `mvem closed-loop`: trajectory, stats, violations; margins=S: the loop margins of the loops in
  feedback every S seconds (as `mvem closed-loop --margins S`)
- lab(out, params=None, model=8, **settings) -> dict: a virtual test-cell campaign written to a
  directory, as `mvem lab` (settings: its options in snake case, seed=1, noise="realistic", ...)
- campaign(data) -> dict: what a campaign directory holds and which tuning steps it supports,
  as `mvem campaign --json` (points, sets, sample rates, command steps, steps 1-5)
- tune(data, params=None, model=8, progress=None, **settings) -> dict: the paper's tuning steps
  on a campaign directory, as `mvem tune` (settings: its options in snake case, steps="1-5",
  ...): "params" (the tuned set, usable as params=), "test_cell", "toml" (the file mvem tune
  writes), "report" (tune_report.json), "messages"; Ctrl-C or an exception in progress(dict)
  stops it
- validate(data, params=None, model=8, tau_me=None, sensor_lags=None, roles=None,
  traces=False) -> dict: the relative errors of a parameter set on a campaign, as `mvem
  validate` (datasets, stationary; with traces=True the measured and simulated curves)
- mvem.gym.AirPathEnv: a Gymnasium environment for EGR/VGT control (needs `gymnasium`).

model: 8 (the paper's model), 10 or 12 states (section 9 extensions).
params: None (published set), a dict of overrides ({"turbo": {"j_t": 1e-4}} or
{"turbo.j_t": 1e-4}; one element by its path {"cylinder.c_vol[1]": 0.9} or by the name the
tuning report gives it, {"c_vol1": 0.9}, {"c_egr[2]": 0.01}) or a path to a TOML/JSON
parameter file.
Units: Pa, K, kg/s, rad/s (omega_t), rpm (n_e, n_t), Nm, %, mg/cycle/cylinder.
Errors: ValueError (bad input, options, parameters), RuntimeError (solver / no equilibrium),
both carrying the Rust message.
"""

from ._mvem import (
    Model,
    closed_loop,
    Plant,
    __version__,
    frequency_response,
    linearize,
    loop_margins,
    parameters,
    published_params,
    simulate,
    campaign,
    lab,
    tune,
    validate,
    simulate_many,
    steady,
    step_metrics,
    step_response,
    variables,
)

INPUT_COLUMNS = ("time_s", "n_e_rpm", "u_delta_mg", "u_egr_pct", "u_vgt_pct")

__all__ = [
    "Model",
    "closed_loop",
    "derivatives",
    "jacobian",
    "Plant",
    "simulate",
    "simulate_many",
    "campaign",
    "lab",
    "tune",
    "validate",
    "steady",
    "frequency_response",
    "linearize",
    "loop_margins",
    "step_metrics",
    "step_response",
    "published_params",
    "variables",
    "parameters",
    "INPUT_COLUMNS",
    "__version__",
]


def derivatives(state, inputs, params=None, model=8):
    """dx/dt at a state and held inputs (n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%],
    u_vgt [%]): Model(model, params).derivatives(state, inputs). For many calls, build the
    Model once."""
    return Model(model=model, params=params).derivatives(state, inputs)


def jacobian(state, inputs, outputs=None, strict=False, params=None, model=8):
    """f, A = df/dx, B = df/du (and y, C, D of outputs) at a state and held inputs:
    Model(model, params).jacobian(state, inputs, outputs, strict). For many calls, build the
    Model once."""
    return Model(model=model, params=params).jacobian(
        state, inputs, outputs=outputs, strict=strict
    )
