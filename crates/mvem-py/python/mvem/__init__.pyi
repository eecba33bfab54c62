"""Type stubs of mvem (the Python bindings of the Rust crate mvem-py)."""

import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
INPUT_COLUMNS: Tuple[str, str, str, str, str]

#: None (published set), overrides {"group": {"field": value}} / {"group.field": value},
#: or a path to a TOML/JSON parameter file.
Params = Union[None, Mapping[str, Any], str, "os.PathLike[str]"]

def simulate(
    inputs: Union[Mapping[str, npt.ArrayLike], npt.ArrayLike],
    t_end: Optional[float] = None,
    dt: float = 0.01,
    rtol: float = 1e-6,
    atol: float = 1e-8,
    params: Params = None,
) -> Dict[str, "np.ndarray[Any, np.dtype[np.float64]]"]:
    """Simulate from the steady state at the first input row.

    inputs: columns time_s [s], n_e_rpm [rpm], u_delta_mg [mg/cycle/cylinder], u_egr_pct [%],
    u_vgt_pct [%] (dict of 1-D arrays, or a 2-D array with 5 columns). Returns "t" [s], the 8
    states and every signal as numpy arrays. ValueError: bad inputs/options/params;
    RuntimeError: solver failure.
    """

def steady(
    n_e: float, u_delta: float, u_egr: float, u_vgt: float, params: Params = None
) -> Dict[str, Union[float, bool, List[str]]]:
    """Steady state at n_e [rpm], u_delta [mg/cycle/cylinder], u_egr [%], u_vgt [%]."""

def published_params() -> Dict[str, Dict[str, Union[float, List[float], List[List[float]]]]]:
    """The published parameter set as a nested dict."""
