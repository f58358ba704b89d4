"""hamflight: the learned, physics-guided adaptive flight controller for Crazyflie-class
quadrotors, in-process for numpy.

Everything here runs the same compiled f32 Rust code as the firmware and ``host-train bridge``:

- :class:`Controller`: one controller (learned model from a weight blob, or the nominal model),
  ``step(p, R, v_body, w_body, setpoint, dt, acc=None)`` -> :class:`StepResult`;
- :class:`ControllerBatch`: N controllers stepped by one call on (N, ...) arrays;
- :class:`Setpoint`: desired position and derivatives (world frame) and yaw;
- :class:`Blob`: the checked weight-blob codec; a rejected blob raises :class:`BlobError`;
- :mod:`hamflight.sitl`: the SITL plant and scenario files, flights as numpy arrays;
- :mod:`hamflight.data`: the scenario files and the default weights shipped in the package;
- :func:`collect`, :func:`import_logs`, :func:`train`: the data and training commands.

Units are SI and named: positions m (world), R body->world (row-major numpy 3x3), velocities in
the body frame (m/s, rad/s), accelerometer specific force m/s^2 (body, +9.8 along z at hover),
dt s. Inputs may be float64, float32 or integer arrays (or sequences of numbers); they are cast
to f32 as the bridge casts them.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Iterable, Optional, Sequence, Union

from . import _core
from ._core import (  # noqa: F401
    BLOB_CRC_LEN,
    BLOB_HEADER_LEN,
    CONTROLLER_NAMES,
    GAIN_KEYWORDS,
    BatchResult,
    Blob,
    BlobError,
    Controller,
    ControllerBatch,
    Faults,
    Setpoint,
    StepResult,
)
from . import data, sitl  # noqa: F401

__version__: str = _core.__version__

PathLike = Union[str, "os.PathLike[str]"]

__all__ = [
    "Controller",
    "ControllerBatch",
    "Setpoint",
    "StepResult",
    "BatchResult",
    "Faults",
    "Blob",
    "BlobError",
    "CONTROLLER_NAMES",
    "GAIN_KEYWORDS",
    "sitl",
    "data",
    "collect",
    "import_logs",
    "train",
    "__version__",
]


def _jsonable(value: Any) -> Any:
    """The JSON form of what ``json`` does not know: paths as strings, numpy scalars as numbers."""
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if hasattr(value, "item"):
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a valid keyword value")


def _run(command: str, config: dict, progress: Optional[Callable[[str], None]]) -> Any:
    """Runs ``command`` on the typed job ``config`` (the CLI's flag names as keys, underscores
    for dashes; a key left out takes the flag's default). An unknown keyword or a value of the
    wrong type raises ValueError naming it. ``None`` means the default (the key is left out)."""
    text = json.dumps({k: v for k, v in config.items() if v is not None}, default=_jsonable)
    if progress is not None:
        progress(f"{command}: started")
    result = json.loads(_core.run_tool(command, text))
    if progress is not None:
        progress(f"{command}: done")
    return result


def collect(out: PathLike, *, progress: Optional[Callable[[str], None]] = None, **config: Any) -> dict:
    """Collect the paper's training dataset with the SITL (``host-train collect``) into ``out``.

    ``config`` takes the command's flags as keywords (``realizations=2, windows=100,
    seed=1, wind_levels=[0.25, 0.5]``; see ``host-train collect --help``): a typed job, checked
    before anything runs (an unknown keyword raises ValueError listing the valid ones). Returns
    the dataset's manifest as a dict. The dataset is CSV (``pandas.read_csv(f).groupby("flight")``)."""
    return _run("collect", {**config, "out": os.fspath(out)}, progress)


def import_logs(
    out: PathLike,
    logs: Iterable[PathLike],
    *,
    calm: Sequence[PathLike] = (),
    progress: Optional[Callable[[str], None]] = None,
    **config: Any,
) -> list:
    """Import flight logs (Bitcraze uSD-card deck binary logs or the documented CSV) into a
    dataset (``host-train import``): one realization per log, airborne flights only; ``calm``
    marks disturbance-free flights. ``config``: the command's flags as keywords (``mass_kg=0.034,
    motor_tau_s=0.02``). Returns one summary dict per log."""
    job = {
        **config,
        "out": os.fspath(out),
        "logs": [os.fspath(p) for p in logs],
        "calm": [os.fspath(c) for c in calm],
    }
    return _run("import", job, progress)


def train(
    data_dir: PathLike,
    out: PathLike,
    *,
    progress: Optional[Callable[[str], None]] = None,
    **config: Any,
) -> dict:
    """Train the Hamiltonian model on a dataset and write the blob ``out`` and ``out.json``
    (``host-train train``). ``config``: the command's flags as keywords (``epochs=5, lr=3e-3,
    no_flight_check=True, quiet=True``), a typed job (``host_train::train::TrainJob``) checked
    before training starts: an unknown keyword raises ValueError naming it and listing the valid
    ones. ``quiet=True`` prints nothing (no progress bar, no summary). Returns the training
    report as a dict; load the blob with :meth:`Blob.load`."""
    return _run("train", {**config, "data": os.fspath(data_dir), "out": os.fspath(out)}, progress)
