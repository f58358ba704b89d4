"""Type stubs of hamflight's native module (the exact f32 core, the blob codec, the SITL)."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
CONTROLLER_NAMES: List[str]
GAIN_KEYWORDS: List[str]
BLOB_HEADER_LEN: int
BLOB_CRC_LEN: int

ArrayLike = Union[npt.NDArray[np.float64], npt.NDArray[np.float32], Sequence[float], Sequence[Sequence[float]]]
Weights = Union[str, PathLike, bytes, bytearray, "Blob", None]
F32 = npt.NDArray[np.float32]

class BlobError(ValueError):
    """A weight blob was rejected; ``kind`` names the failed check: Truncated, BadMagic,
    UnsupportedVersion, ShapeMismatch, Checksum, TrailingBytes, Malformed, NonFinite, BadMass, BadMotorTau, BadPort."""

    kind: str

class Blob:
    """A checked weight blob: the learned model's networks and the vehicle's mass."""

    @staticmethod
    def load(path: Union[str, PathLike]) -> Blob:
        """Reads and checks a blob file; raises BlobError (or OSError) naming the problem. A
        relative ``weights/default.hfw`` that does not exist is the package's copy
        (:mod:`hamflight.data`)."""
    @staticmethod
    def from_bytes(data: bytes, name: str = "<bytes>") -> Blob: ...
    @staticmethod
    def default() -> Blob:
        """The blob shipped with this package (the repository's weights/default.hfw)."""
    @staticmethod
    def validate(data: bytes) -> None:
        """Raises BlobError unless ``data`` is a valid blob."""
    @property
    def mass_kg(self) -> float: ...
    @property
    def name(self) -> str: ...
    @property
    def crc(self) -> int:
        """The body's CRC-32 as stored in the blob."""
    @property
    def version(self) -> int: ...
    @property
    def params(self) -> int: ...
    def to_bytes(self) -> bytes:
        """The bytes as loaded (``Blob.from_bytes(b.to_bytes()) == b``)."""
    def encode(self) -> bytes:
        """The weights encoded afresh by the core's encoder."""
    def with_mass(self, mass_kg: float) -> Blob: ...
    def __len__(self) -> int: ...
    def __reduce__(self) -> Tuple[Any, Tuple[bytes, str]]:
        """Pickling (and ``copy``): the bytes as loaded and the name, checked again on load."""

class Setpoint:
    """Desired position p* (m), velocity (m/s), acceleration (m/s^2), jerk (m/s^3), all world
    frame, and yaw (rad) and yaw rate (rad/s)."""

    def __init__(
        self,
        p_m: ArrayLike,
        v_m_s: Optional[ArrayLike] = None,
        a_m_s2: Optional[ArrayLike] = None,
        j_m_s3: Optional[ArrayLike] = None,
        yaw_rad: float = 0.0,
        yaw_rate_rad_s: float = 0.0,
    ) -> None: ...
    @property
    def p_m(self) -> F32: ...
    @property
    def v_m_s(self) -> F32: ...
    @property
    def a_m_s2(self) -> F32: ...
    @property
    def j_m_s3(self) -> F32: ...
    @property
    def yaw_rad(self) -> float: ...
    @property
    def yaw_rate_rad_s(self) -> float: ...

SetpointLike = Union[Setpoint, ArrayLike, Dict[str, Any]]

class Faults:
    """Faults and conditions of one step; any of the first four forces motors off."""

    @property
    def fault(self) -> bool: ...
    @property
    def bad_state(self) -> bool: ...
    @property
    def bad_setpoint(self) -> bool: ...
    @property
    def bad_dt(self) -> bool: ...
    @property
    def numeric(self) -> bool: ...
    @property
    def saturated(self) -> bool: ...
    @property
    def saturated_yaw(self) -> bool: ...
    @property
    def saturated_roll_pitch(self) -> bool: ...
    @property
    def saturated_thrust(self) -> bool: ...
    @property
    def tilt_limited(self) -> bool: ...
    def to_dict(self) -> Dict[str, bool]:
        """The bridge's ``faults`` object."""
    def __bool__(self) -> bool: ...

class StepResult:
    """One step's output (float32, as the core computes it)."""

    @property
    def rpm(self) -> F32:
        """Rotor speed commands, rotors 1..4 (rpm), (4,)."""
    @property
    def rotor_thrust_n(self) -> F32:
        """Rotor thrusts (N), (4,)."""
    @property
    def thrust_n(self) -> float:
        """Collective thrust to command (N): what a mixer should be handed."""
    @property
    def torque_nm(self) -> F32:
        """Body torques to command (N m), (3,): the law's with the motor-lag lead."""
    @property
    def wrench(self) -> F32:
        """[thrust (N), tau_x, tau_y, tau_z (N m)], (4,)."""
    @property
    def a(self) -> F32:
        """The disturbance-weight estimate, (6,)."""
    @property
    def e_p(self) -> F32:
        """Position error R^T (p - p*) (m, body), (3,)."""
    @property
    def faults(self) -> Faults: ...

class Controller:
    """The exact f32 flight core: model, IDA-PBC law, adaptation, mixer.

    ``weights``: None for the nominal CF2X model (with its hand-chosen features), or a blob
    (path, bytes or Blob) for the learned model. ``law``: "composite" (the default) or
    "gradient" (the paper's). Gains as keywords (see GAIN_KEYWORDS): k_p_n_per_m, k_v_n_s_per_m,
    k_r_nm_per_rad, k_w_nm_s_per_rad, max_tilt_rad, shaping_omega_rad_s, the adaptation rates
    c_p, c_v, c_r, c_w (feature units), a_max, and motor_tau_s (the lag the composite law assumes).
    """

    def __init__(
        self,
        weights: Weights = None,
        *,
        law: str = "composite",
        adapt: bool = True,
        k_p_n_per_m: float = ...,
        k_v_n_s_per_m: float = ...,
        k_r_nm_per_rad: float = ...,
        k_w_nm_s_per_rad: float = ...,
        max_tilt_rad: float = ...,
        shaping_omega_rad_s: float = ...,
        c_p: float = ...,
        c_v: float = ...,
        c_r: float = ...,
        c_w: float = ...,
        a_max: float = ...,
        motor_tau_s: float = ...,
    ) -> None: ...
    @staticmethod
    def named(name: str, weights: Weights = None, **gains: float) -> Controller:
        """The controller ``host-train bridge --controller NAME`` runs (CONTROLLER_NAMES)."""
    def step(
        self,
        p: ArrayLike,
        R: ArrayLike,
        v_body: ArrayLike,
        w_body: ArrayLike,
        setpoint: SetpointLike,
        dt: float,
        acc: Optional[ArrayLike] = None,
    ) -> StepResult:
        """One control step. p (3,) m world; R (3, 3) body->world; v_body (3,) m/s and w_body
        (3,) rad/s in the body frame; setpoint a Setpoint, a position (3,) or a dict with the
        bridge's keys; dt s; acc the accelerometer's specific force (3,) m/s^2 body, or None."""
    def reset(self) -> None: ...
    def set_gains(self, *, law: Optional[str] = None, adapt: Optional[bool] = None, **gains: float) -> None: ...
    @property
    def a(self) -> F32: ...
    @property
    def gains(self) -> Dict[str, Any]: ...
    @property
    def mass_kg(self) -> float: ...
    @property
    def model(self) -> str: ...
    @property
    def name(self) -> str: ...
    def __reduce__(self) -> Tuple[Any, Tuple[Any, ...]]:
        """Pickling (and ``copy``, multiprocessing, Ray): the name, the model (its blob bytes)
        and the gains. The adaptation estimate and the filters are not carried: the copy starts
        as after ``reset()``."""

class BatchResult:
    """One batched step, one row per vehicle (float32; bool for the flags)."""

    rpm: F32
    rotor_thrust_n: F32
    thrust_n: F32
    torque_nm: F32
    a: F32
    fault: npt.NDArray[np.bool_]
    saturated: npt.NDArray[np.bool_]
    tilt_limited: npt.NDArray[np.bool_]

class ControllerBatch:
    """N independent controllers stepped by one call."""

    def __init__(
        self,
        n: Optional[int] = None,
        weights: Weights = None,
        *,
        controllers: Optional[Sequence[Controller]] = None,
        law: str = "composite",
        adapt: bool = True,
        **gains: float,
    ) -> None: ...
    def __len__(self) -> int: ...
    def step(
        self,
        p: ArrayLike,
        R: ArrayLike,
        v_body: ArrayLike,
        w_body: ArrayLike,
        setpoint: Union[Setpoint, ArrayLike, Dict[str, ArrayLike]],
        dt: Union[float, ArrayLike],
        acc: Optional[ArrayLike] = None,
    ) -> BatchResult:
        """p (N, 3), R (N, 3, 3), v_body (N, 3), w_body (N, 3); setpoint one Setpoint, (N, 3)
        positions or a dict of (N, ...) arrays; dt a float or (N,); acc None or (N, 3)."""
    def reset(self, *indices: int) -> None: ...
    @property
    def a(self) -> F32: ...

class Scenario:
    """A validated scenario (the TOML files of scenarios/)."""

    @staticmethod
    def load(path: Union[str, PathLike]) -> Scenario:
        """Reads and validates a scenario file. A relative ``scenarios/NAME.toml`` (or
        ``NAME.toml``, ``NAME``) that does not exist is the package's copy
        (:mod:`hamflight.data`)."""
    @staticmethod
    def from_toml(text: str, name: str = "scenario") -> Scenario: ...
    @staticmethod
    def from_dict(spec: Dict[str, Any], name: Optional[str] = None) -> Scenario: ...
    def to_dict(self) -> Dict[str, Any]: ...
    def reference(self, t_s: float) -> Dict[str, Any]: ...
    @property
    def name(self) -> str: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def control_hz(self) -> float: ...
    def __reduce__(self) -> Tuple[Any, Tuple[str, Optional[PathLike], Dict[str, Any]]]:
        """Pickling (and ``copy``, multiprocessing, Ray): the name, the file it was read from (the
        flight's report names it) and the keys as ``to_dict`` gives them, validated again on
        unpickling; the copy flies exactly as the original."""
    def __eq__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...

class Plant:
    """The SITL quadrotor of a scenario, stepped by the caller (``hamflight.env.QuadrotorEnv``
    wraps it). Observations are 18 floats: position (m, world), velocity (m/s, world), R
    (body -> world, row-major), body rates (rad/s)."""

    def __init__(self, scenario: Scenario) -> None: ...
    def reset(self) -> npt.NDArray[np.float64]: ...
    def observation(self) -> npt.NDArray[np.float64]: ...
    def step_rpm(self, rpm: Sequence[float], dt_s: Optional[float] = None) -> npt.NDArray[np.float64]:
        """Hold four rotor speeds (rpm, clamped) for dt_s (default: the control period)."""
    def step_wrench(
        self, thrust_n: float, torque_nm: Sequence[float], dt_s: Optional[float] = None
    ) -> npt.NDArray[np.float64]:
        """Mix a body wrench with the core's mixer and hold it for dt_s."""
    def reference(self, t_s: Optional[float] = None) -> Dict[str, Any]: ...
    @property
    def t_s(self) -> float: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def control_dt_s(self) -> float: ...
    @property
    def mass_kg(self) -> float: ...
    @property
    def gravity_m_s2(self) -> float: ...
    @property
    def inertia_kg_m2(self) -> Tuple[float, float, float]: ...
    @property
    def max_rpm(self) -> float: ...
    @property
    def max_thrust_n(self) -> float: ...

class FlightResult:
    """A flown SITL flight: per-tick numpy arrays and report.json's scores."""

    t_s: npt.NDArray[np.float64]
    p_m: npt.NDArray[np.float64]
    p_ref_m: npt.NDArray[np.float64]
    err_m: npt.NDArray[np.float64]
    rpm: npt.NDArray[np.float64]
    adaptation: npt.NDArray[np.float64]
    report: Dict[str, Any]
    @property
    def rmse_m(self) -> Optional[float]:
        """Position RMSE over t >= 5 s (m)."""
    @property
    def crashed(self) -> bool: ...

def fly(
    scenario: Union[Scenario, str, PathLike],
    controller: Union[str, Controller] = "adaptive",
    weights: Weights = None,
) -> FlightResult: ...
def controllers() -> List[Tuple[str, str]]: ...
def run_tool(command: str, json_config: str) -> str: ...
def _restore_controller(name: str, from_registry: bool, weights: Optional[bytes], gains: Dict[str, Any]) -> Controller: ...
def _restore_blob(data: bytes, name: str) -> Blob: ...
def _restore_scenario(name: str, path: Optional[PathLike], spec: Dict[str, Any]) -> Scenario: ...
