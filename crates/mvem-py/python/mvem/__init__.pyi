"""Type stubs of mvem (the Python bindings of the Rust crate mvem-py)."""

import os
from typing import Any, Callable, Dict, List, Literal, Mapping, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str
INPUT_COLUMNS: Tuple[str, str, str, str, str]

#: None (published set), overrides {"group": {"field": value}} / {"group.field": value}, one
#: element by its 1-based path as parameters() lists it {"cylinder.c_vol[1]": value} (c_vol1;
#: index 0 is refused), or a path to a TOML/JSON parameter file.
Params = Union[None, Mapping[str, Any], str, "os.PathLike[str]"]
#: Number of states: 8 (the paper's model), 10 or 12 (section 9 extensions).
ModelOrder = Literal[8, 10, 12]
FloatArray = "np.ndarray[Any, np.dtype[np.float64]]"
ComplexArray = "np.ndarray[Any, np.dtype[np.complex128]]"

def simulate(
    inputs: Union[Mapping[str, npt.ArrayLike], npt.ArrayLike],
    t_end: Optional[float] = None,
    dt: float = 0.01,
    rtol: float = 1e-6,
    atol: Optional[float] = None,
    params: Params = None,
    model: ModelOrder = 8,
    cylinder_temp: Literal["converged", "one-iteration"] = "converged",
    numeric_actuators: bool = False,
    time_parallel: int = 1,
    x0: Union[None, Mapping[str, float], npt.ArrayLike] = None,
) -> Dict[str, "np.ndarray[Any, np.dtype[np.float64]]"]:
    """Simulate from the steady state at the first input row (or from x0).

    inputs: columns time_s [s], n_e_rpm [rpm], u_delta_mg [mg/cycle/cylinder], u_egr_pct [%],
    u_vgt_pct [%] (dict of 1-D arrays, or a 2-D array with 5 columns); linear interpolation,
    two rows with the same time make a step. t_end [s], dt [s]: end time and output interval.
    numeric_actuators: integrate the actuator states numerically too (default: closed form).
    time_parallel: time chunks integrated at once (1 to 256), one thread each (default 1:
    sequential). x0: start state (dict of every state name -> value, or an array in state
    order); a value outside the integrator limits is clipped into them with a UserWarning
    naming the state, the value and the limits (as `mvem simulate --initial-state` warns).
    Integer arguments out of range (time_parallel=-1, model=2**70) raise ValueError naming
    the argument and the range. Times beyond 1e9 s are refused (ValueError).
    Returns "t" [s], the states (Pa, K, -, rad/s, %) and every signal as numpy arrays.
    ValueError: bad inputs/options/params; RuntimeError: solver failure. Ctrl-C
    (KeyboardInterrupt) stops the run within one integrator step.
    """

def simulate_many(
    inputs: Sequence[Union[Mapping[str, npt.ArrayLike], npt.ArrayLike]],
    params: Union[Params, Sequence[Params]] = None,
    threads: Optional[int] = None,
    on_error: Literal["raise", "return"] = "raise",
    t_end: Optional[float] = None,
    dt: float = 0.01,
    rtol: float = 1e-6,
    atol: Optional[float] = None,
    model: ModelOrder = 8,
    cylinder_temp: Literal["converged", "one-iteration"] = "converged",
    numeric_actuators: bool = False,
    x0: Any = None,
) -> List[Union[Dict[str, "np.ndarray[Any, np.dtype[np.float64]]"], Exception]]:
    """Many simulations at once on `threads` worker threads (None: one per core), GIL released.
    Ctrl-C (KeyboardInterrupt) stops the ensemble, the runs in progress within one step.

    Run i simulates inputs[i] (as simulate) with params (one for all runs, or a list with one
    entry per run). on_error="raise": raise the first failure ("run i: ...": invalid inputs,
    params or x0 of a run before any run starts, a solver failure after all runs); "return": a
    failed run's slot holds its ValueError/RuntimeError, also for a run with invalid inputs,
    params or x0, and the others run. Shared arguments (options, one params or x0 for all,
    lists of the wrong length) raise either way. threads: 1 to 1024. Results in input order,
    each equal to simulate(inputs[i], ...) with the same arguments. x0: None (steady starts),
    one start state for all runs (dict or 1-D array), or one per run (a list of None / dict /
    array, or a 2-D array with a row per run).
    """

def steady(
    n_e: float,
    u_delta: float,
    u_egr: float,
    u_vgt: float,
    params: Params = None,
    model: ModelOrder = 8,
) -> Dict[str, Union[float, bool, List[str]]]:
    """Steady state at n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%].

    Returns the inputs, states and signals by name (SI units), "physically_valid" and "flags".
    """

class Excursion(TypedDict):
    value: float  # signal value (units of y)
    time: float  # [s]
    relative: float  # size relative to |final change| [-]

class StepMetrics(TypedDict):
    t_step: float  # [s]
    y0: float
    y_final: float
    du: float
    change: float  # y_final - y0
    dc_gain: float  # change / du (units of y per unit of input)
    gain_sign: Literal["positive", "negative"]
    wrong_way: Optional[Excursion]
    non_minimum_phase: bool
    overshoot_pct: float  # [%]
    peak: Optional[Excursion]
    rise_time: Optional[float]  # 10-90 % [s]
    settling_time: Optional[float]  # 2 % band, from the step [s]

def linearize(
    n_e: float,
    u_delta: float,
    u_egr: float,
    u_vgt: float,
    outputs: Optional[Sequence[str]] = None,
    strict: bool = True,
    pade_order: int = 0,
    params: Params = None,
    model: ModelOrder = 8,
    ts: Optional[float] = None,
) -> Dict[str, Any]:
    """Linearize at the steady state of the inputs: dx' = A dx + B du, dy = C dx + D du.

    Keys: "A" (n x n) [1/s], "B" (n x 4), "C" (p x n), "D" (p x 4) float arrays; inputs in
    "input_names" order (u_delta [mg], u_egr [%], u_vgt [%], n_e [rpm]); "state_names",
    "output_names"; "x0", "u0", "y0"; "eigenvalues" (complex array [1/s]); "dc_gain"
    (p x 4, output units per input unit, or None); "zeros" {"u_vgt->W_c": complex array or
    None}; "mimo_zeros" (complex array or None); "kinks" (list of str); "one_sided" (list of str);
    "delays" [s].
    ts [s] (1e-3 to 100, with pade_order 0): also "discrete", the model sampled with a
    zero-order hold, delays exact: {"ts", "Phi", "Gamma", "C", "D", "state_names" (states, then
    the registers "u_egr(k-1)", ...), "input_names", "output_names", "delay_samples" [(whole,
    remainder [s]) of u_egr, u_vgt]}.
    ValueError: bad arguments; RuntimeError: no steady state, or a kink with strict=True.
    """

def frequency_response(
    n_e: float,
    u_delta: float,
    u_egr: float,
    u_vgt: float,
    f_hz: npt.ArrayLike,
    outputs: Optional[Sequence[str]] = None,
    strict: bool = True,
    params: Params = None,
    model: ModelOrder = 8,
) -> Dict[str, Any]:
    """Frequency response at the steady state of the inputs, the actuator delays exact.

    f_hz [Hz]: finite, >= 0, strictly increasing. Keys: "f_hz" (array), "G" {"u_vgt->W_c":
    complex array (output unit per input unit), ...} for every input and output, "phase_deg"
    {channel: array [deg], continuous whatever the spacing of f_hz}, "input_names",
    "output_names", "delays" [s] of (u_egr, u_vgt). At f = 0: the DC gains.
    ValueError: bad arguments; RuntimeError: no steady state, or a kink with strict=True.
    """

def loop_margins(
    n_e: float,
    u_delta: float,
    u_egr: float,
    u_vgt: float,
    tuning: Optional[Dict[str, Any]] = None,
    params: Params = None,
    model: ModelOrder = 8,
) -> Dict[str, Any]:
    """Stability margins of the baseline controller's air-path loops (lambda_O -> u_egr,
    x_egr -> u_vgt; discrete PIs every 10 ms around the sampled model, delays exact) at the
    steady state of the inputs, as `mvem margins --json`. Keys: "operating_point",
    "model_states", "ts", "stable", "max_pole_all", "steady_state_warnings", "loops" [{"name",
    "input", "output", "kp", "ki", "alone", "others_closed"}], each margins dict {"inert",
    "stable", "gain_margin", "gain_margin_db", "gain_margin_hz", "gain_reduction_margin",
    "phase_margin_deg", "gain_crossover_hz", "delay_margin_s", "peak_sensitivity",
    "peak_sensitivity_hz"}.
    ValueError: bad inputs, tuning or parameters; RuntimeError: no steady state, or a kink the
    loops see.
    """

def step_metrics(
    t: npt.ArrayLike,
    y: npt.ArrayLike,
    t_step: float,
    y0: float,
    y_final: float,
    du: float,
) -> StepMetrics:
    """Metrics of the samples y(t) [units of y] for an input step du at t_step [s]."""

def step_response(
    n_e: float,
    u_delta: float,
    u_egr: float,
    u_vgt: float,
    input: Literal["n_e", "u_delta", "u_egr", "u_vgt"] = "u_vgt",
    to: float = 65.0,
    output: str = "W_c",
    t_step: float = 1.0,
    t_end: float = 8.0,
    dt: float = 0.01,
    rtol: float = 1e-6,
    atol: Optional[float] = None,
    params: Params = None,
    model: ModelOrder = 8,
) -> Dict[str, Any]:
    """Simulate a step of `input` to `to` at t_step [s]; StepMetrics of `output` plus "t", "y"
    (sampled every dt; the metrics from samples at most 5 ms apart, at a tolerance scaled to
    the step's size: docs/analysis.md)."""

def published_params() -> Dict[str, Dict[str, Union[float, List[float], List[List[float]]]]]:
    """The published parameter set as a nested dict (SI units)."""

class Variable(TypedDict):
    kind: Literal["time", "input", "state", "signal"]
    unit: str  # e.g. "Pa", "kg/s", "-" (dimensionless)
    description: str  # one line, with the paper's equation number

def variables() -> Dict[str, Variable]:
    """Names, units and descriptions of every input, state and signal (the core's metadata)."""

class Parameter(TypedDict):
    path: str  # "cylinder.c_vol[1]" (1-based, = c_vol1), accepted as is by `params` overrides
    symbol: str  # the paper's symbol, e.g. "c_vol1"
    unit: str
    description: str
    published: float

def parameters() -> List[Parameter]:
    """Every scalar parameter with its unit and description, in parameter-file order."""

def closed_loop(
    cycle: Union[
        None, str, "os.PathLike[str]", Mapping[str, npt.ArrayLike], npt.ArrayLike
    ] = None,
    tuning: Optional[Mapping[str, Any]] = None,
    params: Params = None,
    model: ModelOrder = 8,
    duration: Optional[float] = None,
    margins: Optional[float] = None,
) -> Dict[str, Any]:
    """A drive cycle in closed loop with the baseline EGR/VGT and engine controllers.

    cycle: None / "whtc" (the WHTC on this engine's mapping curve), a demand with columns
    t [s], n_e [rpm], M_ref [Nm] (dict or 2-D array), or a cycle file's path (a demand CSV, or
    a normalized cycle: Time [s], Speed [%], Torque [%], "m" motoring, denormalized as the
    WHTC). tuning: BaselineTuning fields (others default). Keys: "trajectory" (dict of arrays, 10 ms rows), "stats", "violations",
    "passes", "reference_speeds_rpm", "solver", "controller_tuning", "sample_time_s"; the
    trajectory's egr_loop / vgt_loop say which loop gave the command (1 main, 2 limiter, 0 none,
    NaN no loop). margins=S: "margins" with the loop margins of the air-path loops in feedback
    every S seconds (counts, unstable_t, per-loop extremes, "samples": one dict per sample).
    """

def lab(
    out: Union[str, "os.PathLike[str]"],
    params: Params = None,
    model: ModelOrder = 8,
    *,
    seed: int = 1,
    noise: str = "realistic",
    n_stationary: int = 82,
    tau_me: float = 1.0,
    sensor_lags: bool = False,
    sets: Optional[Sequence[str]] = None,
    max_steps: Optional[int] = None,
    dynamic: bool = True,
    speeds: str = "900:2100",
    full_load: float = 220.0,
) -> Dict[str, Any]:
    """A virtual test-cell campaign (stationary points, Table 1 sets, actuator set J, noise)
    of the engine `params`, written to the directory `out` as `mvem lab` writes it. Keys: "dir",
    "stationary", "datasets", "samples".
    """

def tune(
    data: Union[str, "os.PathLike[str]"],
    params: Params = None,
    model: Literal[8, 12] = 8,
    *,
    progress: Optional[Callable[[Dict[str, Any]], Any]] = None,
    steps: str = "1-5",
    ambient: Literal["auto", "data", "params"] = "auto",
    input_ranges: Literal["campaign", "params"] = "campaign",
    init: Literal["step1", "naive"] = "step1",
    cost: Literal["full", "dynamic", "static"] = "full",
    beta: float = 1.0,
    refine_dynamics: bool = True,
    joint_uncertainty: bool = False,
    fixed_jacobian: Literal["forward", "sigma-points"] = "forward",
    max_evals: int = 3600,
    broyden: int = 0,
    rel_offset: float = ...,
    restarts: int = ...,
    step5_single_pass: bool = False,
    step5_first_pass_max: int = 3600,
    settled_flow_points: bool = True,
    step3_window: Optional[float] = None,
    step3_tail_weight: float = ...,
    step_levels: Literal["least-squares", "means"] = "least-squares",
    sensor_lags: Optional[str] = None,
) -> Dict[str, Any]:
    """The paper's tuning steps on a campaign directory (manifest.toml; docs/tuning-data.md),
    as `mvem tune` runs them: the same parameters and report from the same campaign and
    settings. params: the engine's constants and the parameters of the steps not run (a path
    also supplies its [test_cell] section). Keys: "params" (nested dict, usable as params=),
    "test_cell", "toml" (the parameter file), "report" (tune_report.json; its "parameters"
    keyed by the paths of parameters(), elements 1-based: "cylinder.c_fric[1]" is c_fric1, a
    valid params= key as it stands), "messages"
    (warnings and notes; each warning also a UserWarning). ValueError for a bad setting,
    parameter set or campaign file; RuntimeError when a step fails. Ctrl-C stops it within
    one round of simulations (KeyboardInterrupt). progress: called with {"stage",
    "evaluations", "cost", "elapsed_s"} at each step's start (evaluations and cost None) and
    during its searches (at most every 0.2 s); an exception it raises stops the tuning and is
    raised. The result does not depend on it.
    """

def campaign(
    data: Union[str, "os.PathLike[str]"], init: bool = False, force: bool = False
) -> Dict[str, Any]:
    """What a campaign directory holds and which tuning steps 1-5 it supports, before any
    tuning (as `mvem campaign --json`): "stationary_points", ranges, "renamed", "units",
    "datasets" (kind, roles, samples, duration_s, sample rates, command_steps, positions) and
    "steps" (step, title, supported, uses). init=True first drafts data/manifest.toml from the
    directory's CSV files (as `mvem campaign --init`; "notes": what was guessed; an existing
    manifest is kept unless force=True). ValueError when the campaign does not load."""

def validate(
    data: Union[str, "os.PathLike[str]"],
    params: Params = None,
    model: ModelOrder = 8,
    tau_me: Optional[float] = None,
    sensor_lags: Optional[str] = None,
    roles: Optional[str] = None,
    traces: bool = False,
) -> Dict[str, Any]:
    """The relative errors (eqs (4), (5), per cent) of a parameter set on a campaign, as
    `mvem validate`: "datasets" ({set: {output: percent}}), "stationary" ({submodel:
    percent}), "oscillations" (if any), "tau_me", "sensor_lags", "messages"; with traces=True
    "traces": {set: {"t": array, output: {"measured": array, "simulated": array}}}. A path
    params supplies its [test_cell] (tau_Me, sensor time constants); tau_me and sensor_lags
    override them.
    """

class Model:
    """The right-hand side dx/dt = f(x, u) at any state, and its Jacobians (optimal control,
    custom integrators). u = (n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]),
    held: the actuators see u_egr, u_vgt as their delayed commands. One point (state (n,),
    inputs (4,)) or K points (states (K, n), inputs (K, 4) or (4,)); batched results carry a
    leading K axis. The cylinder-out temperature is the converged fixed point.
    """

    def __init__(self, model: ModelOrder = 8, params: Params = None) -> None: ...
    @property
    def state_names(self) -> List[str]: ...
    @property
    def input_names(self) -> List[str]:
        """n_e, u_delta, u_egr, u_vgt: the order of u and of the columns of B and D."""
    @property
    def state_scales(self) -> "np.ndarray[Any, np.dtype[np.float64]]": ...
    def derivatives(
        self, x: npt.ArrayLike, u: npt.ArrayLike
    ) -> "np.ndarray[Any, np.dtype[np.float64]]":
        """dx/dt [state units per s]: shape (n,), or (K, n)."""
    def signals(self, x: npt.ArrayLike, u: npt.ArrayLike) -> Dict[str, Any]:
        """Every signal (floats, or arrays (K,)) and "flags" (active guard saturations)."""
    def jacobian(
        self,
        x: npt.ArrayLike,
        u: npt.ArrayLike,
        outputs: Optional[Sequence[str]] = None,
        strict: bool = False,
    ) -> Dict[str, Any]:
        """Keys "f" (n), "A" (n, n) [1/s], "B" (n, 4) and with outputs "y" (p), "C" (p, n),
        "D" (p, 4) (leading K axis when batched); "state_names", "input_names",
        "output_names", "kinks". Richardson-extrapolated central differences (entries to about
        1e-9 relative), not exact derivatives."""

def derivatives(
    state: npt.ArrayLike, inputs: npt.ArrayLike, params: Params = None, model: ModelOrder = 8
) -> "np.ndarray[Any, np.dtype[np.float64]]":
    """Model(model, params).derivatives(state, inputs)."""

def jacobian(
    state: npt.ArrayLike,
    inputs: npt.ArrayLike,
    outputs: Optional[Sequence[str]] = None,
    strict: bool = False,
    params: Params = None,
    model: ModelOrder = 8,
) -> Dict[str, Any]:
    """Model(model, params).jacobian(state, inputs, outputs, strict)."""

class Plant:
    """The model advanced sample by sample with the commands held (zero-order hold).

    Starts at t = 0 in the steady state of (n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%],
    u_vgt [%]). State, cylinder-temperature memory, exact actuator delays and the integrator's
    warm state carry over between calls; the GIL is released while integrating. A Plant may be
    shared between threads: an internal lock serializes its calls (one step at a time, each
    returning its own outputs); for parallel runs give each thread its own Plant.
    """

    def __init__(
        self,
        n_e: float,
        u_delta: float,
        u_egr: float,
        u_vgt: float,
        model: ModelOrder = 8,
        params: Params = None,
    ) -> None: ...
    def step(
        self,
        dt: float,
        n_e: Optional[float] = None,
        u_delta: Optional[float] = None,
        u_egr: Optional[float] = None,
        u_vgt: Optional[float] = None,
    ) -> Dict[str, float]:
        """Hold the commands (left out: the last ones) for dt [s]; the outputs at the end."""
    def outputs(self) -> Dict[str, float]:
        """States and signals at the current time."""
    def reset(
        self,
        n_e: Optional[float] = None,
        u_delta: Optional[float] = None,
        u_egr: Optional[float] = None,
        u_vgt: Optional[float] = None,
    ) -> None:
        """Start again at t = 0 in the steady state of the commands."""
    @property
    def delayed_commands(self) -> Tuple[float, float]:
        """(u_egr(t - tau_degr), u_vgt(t - tau_dvgt)) [%]: the commands the actuators see now.
        Model.derivatives(plant.state, (n_e, u_delta, *plant.delayed_commands)) is the plant's
        right-hand side."""
    @property
    def t(self) -> float: ...
    @property
    def state(self) -> "np.ndarray[Any, np.dtype[np.float64]]": ...
    @property
    def state_names(self) -> List[str]: ...
    @property
    def commands(self) -> Tuple[float, float, float, float]: ...
