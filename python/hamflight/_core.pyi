"""Type stubs of hamflight's native module (the exact f32 core, the blob codec, the SITL).

The docstrings are the run-time ones (``help()``), which pyo3 takes from the ``///`` comments of
python/src; tests/test_docstrings.py checks that they are the same words."""

from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
CONTROLLER_NAMES: List[str]
GAIN_KEYWORDS: List[str]
BLOB_HEADER_LEN: int
BLOB_CRC_LEN: int

ArrayLike = Union[npt.NDArray[np.float64], npt.NDArray[np.float32], npt.NDArray[np.integer], Sequence[float], Sequence[Sequence[float]]]
Weights = Union[str, PathLike, bytes, bytearray, "Blob", None]
F32 = npt.NDArray[np.float32]

class BlobError(ValueError):
    """A weight blob was rejected (a ValueError); `kind` names the failed check: Truncated,
    BadMagic, UnsupportedVersion, ShapeMismatch, Checksum, TrailingBytes, Malformed, NonFinite,
    BadMass, BadMotorTau, BadPort. The message names the file and the problem."""

    kind: str

class Blob:
    """A checked weight blob: the learned model's networks and the vehicle's mass.

    `Blob.load(path)`, `Blob.from_bytes(data)` or `Blob.default()`; a rejected blob raises
    `BlobError`. A `Controller` takes one (or its path or bytes) as `weights`. Blobs compare by
    their bytes (`==`, `hash` is the CRC) and pickle as them."""

    @staticmethod
    def load(path: Union[str, PathLike]) -> Blob:
        """Reads and checks a blob file (str or os.PathLike); raises BlobError (or OSError) naming
        the problem. A relative `weights/default.hfw` that does not exist is the package's copy
        (`hamflight.data`)."""
    @staticmethod
    def from_bytes(data: bytes, name: str = "<bytes>") -> Blob:
        """Checks a blob held in memory; `name` is what `name` and the errors call it."""
    @staticmethod
    def default() -> Blob:
        """The blob shipped with this package (the repository's weights/default.hfw)."""
    @staticmethod
    def validate(data: bytes) -> None:
        """Raises BlobError (its `kind` names the failed check) unless `data` is a valid blob."""
    @property
    def mass_kg(self) -> float:
        """The vehicle mass the blob carries (kg)."""
    @property
    def name(self) -> str:
        """The file name it was loaded from (or the name given to from_bytes)."""
    @property
    def crc(self) -> int:
        """The body's CRC-32 as stored in the blob (what the Crazyflie app's console prints)."""
    @property
    def version(self) -> int:
        """The format version in the header."""
    @property
    def params(self) -> int:
        """The number of network parameters."""
    def to_bytes(self) -> bytes:
        """The blob's bytes as loaded (`Blob.from_bytes(b.to_bytes()) == b`)."""
    def encode(self) -> bytes:
        """The weights encoded afresh by the core's encoder (the current format version)."""
    def with_mass(self, mass_kg: float) -> Blob:
        """A copy with another vehicle mass (kg), re-encoded and checked."""
    def __len__(self) -> int: ...
    def __reduce__(self) -> Tuple[Any, Tuple[bytes, str]]:
        """Pickling (and `copy`, multiprocessing, Ray): the bytes as loaded and the name, checked
        again on unpickling."""

class Setpoint:
    """Desired position p* (m), velocity (m/s), acceleration (m/s^2), jerk (m/s^3), all world
    frame, and yaw (rad) and yaw rate (rad/s).

    The derivatives left out are zero. `Controller.step` also takes a position (3,) (held at yaw
    0) or a dict with the bridge's keys (`p`, `v`, `a`, `j`, `yaw`, `yaw_rate`) in its place."""

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
    def p_m(self) -> F32:
        """Desired position (m, world), float32 (3,)."""
    @property
    def v_m_s(self) -> F32:
        """Desired velocity (m/s, world), float32 (3,)."""
    @property
    def a_m_s2(self) -> F32:
        """Desired acceleration (m/s^2, world), float32 (3,)."""
    @property
    def j_m_s3(self) -> F32:
        """Desired jerk (m/s^3, world), float32 (3,)."""
    @property
    def yaw_rad(self) -> float:
        """Desired yaw (rad)."""
    @property
    def yaw_rate_rad_s(self) -> float:
        """Desired yaw rate (rad/s)."""

SetpointLike = Union[Setpoint, ArrayLike, Dict[str, Any]]

class Faults:
    """Faults and conditions of one step; any of the first four forces motors off.

    bad_state, bad_setpoint, bad_dt and numeric are faults: the output is motors off and `fault`
    (also `bool(faults)`) is set. saturated (the mixer's saturated_yaw, saturated_roll_pitch,
    saturated_thrust) and tilt_limited are conditions: the output is still used. `to_dict()` is
    the bridge's `faults` object."""

    @property
    def fault(self) -> bool:
        """The output was forced to motors off (any of bad_state, bad_setpoint, bad_dt, numeric)."""
    @property
    def bad_state(self) -> bool:
        """The state had a NaN or infinite component, or its R is not a rotation."""
    @property
    def bad_setpoint(self) -> bool:
        """The setpoint had a NaN or infinite component."""
    @property
    def bad_dt(self) -> bool:
        """dt was not in (0, 0.1] s."""
    @property
    def numeric(self) -> bool:
        """The model or the law produced a non-finite or singular value."""
    @property
    def saturated(self) -> bool:
        """The mixer saturated (any of the three below; a condition, the output is still used)."""
    @property
    def saturated_yaw(self) -> bool:
        """The yaw torque was scaled down to keep roll/pitch authority."""
    @property
    def saturated_roll_pitch(self) -> bool:
        """The roll/pitch torques were scaled down (not even they fit)."""
    @property
    def saturated_thrust(self) -> bool:
        """The collective thrust was shifted to fit the torques between the limits."""
    @property
    def tilt_limited(self) -> bool:
        """The tilt limit shaped the desired attitude (a condition)."""
    def to_dict(self) -> Dict[str, bool]:
        """The bridge's `faults` object."""
    def __bool__(self) -> bool: ...

class StepResult:
    """One step's output (float32, as the core computes it): what `Controller.step` returns.

    The rotor commands (`rpm`, `rotor_thrust_n`), the wrench to command (`thrust_n`,
    `torque_nm`, `wrench`), the disturbance-weight estimate `a`, the position error `e_p` and
    the `faults`."""

    @property
    def rpm(self) -> F32:
        """Rotor speed commands, rotors 1..4 (rpm), float32 (4,)."""
    @property
    def rotor_thrust_n(self) -> F32:
        """Rotor thrust commands (N), float32 (4,)."""
    @property
    def thrust_n(self) -> float:
        """Collective thrust to command (N): what a mixer should be handed."""
    @property
    def torque_nm(self) -> F32:
        """Body torques to command (N·m), float32 (3,): the law's, with the motor-lag lead the
        attitude gains assume (what `rotor_thrust_n` mixes)."""
    @property
    def wrench(self) -> F32:
        """[thrust (N), τx, τy, τz (N·m)] to command, float32 (4,)."""
    @property
    def a(self) -> F32:
        """The disturbance-weight estimate a, float32 (6,)."""
    @property
    def e_p(self) -> F32:
        """Position error Rᵀ(p − p*) (m, body), float32 (3,)."""
    @property
    def faults(self) -> Faults:
        """The step's faults and conditions."""

class Controller:
    """The exact f32 flight core: model, IDA-PBC law, adaptation, mixer.

    `weights`: None for the nominal CF2X model (with its hand-chosen features), or a blob (path,
    bytes or Blob) for the learned model. `law`: "composite" (the default) or "gradient" (the
    paper's); `adapt=False` turns the adaptation off. Gains as keywords (see GAIN_KEYWORDS):
    k_p_n_per_m, k_v_n_s_per_m, k_r_nm_per_rad, k_w_nm_s_per_rad, max_tilt_rad,
    shaping_omega_rad_s, the adaptation rates c_p, c_v, c_r, c_w (feature units), a_max, and
    motor_tau_s (the lag the composite law assumes); the ones left out are the core's for the
    vehicle the model carries. A gain that is negative, NaN or infinite raises ValueError
    naming it. `Controller.named(NAME)` gives the bridge's controllers."""

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
        """The controller `host-train bridge --controller NAME` runs (CONTROLLER_NAMES; the shipped
        weights unless `weights` is given for the learned ones), with optional gain overrides as
        keywords."""
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
        """One control step; returns a StepResult (rotor commands, wrench, estimate, faults).

        p (3,) m world; R (3, 3) body->world; v_body (3,) m/s and w_body (3,) rad/s in the body
        frame; setpoint a Setpoint, a position (3,) or a dict with the bridge's keys; dt s; acc
        the accelerometer's specific force (3,) m/s^2 body, or None. Arrays are float64,
        float32 or integer (or sequences), cast to f32 as the bridge casts them; another shape
        or dtype raises ValueError naming the argument. A bad state, setpoint or dt is not an
        exception: the motors go off and `faults.fault` is set."""
    def reset(self) -> None:
        """Clears the adaptation estimate and the filters (the model and gains stay)."""
    def set_gains(self, *, law: Optional[str] = None, adapt: Optional[bool] = None, **gains: float) -> None:
        """Changes gains in place (the same keywords as the constructor); the estimate stays."""
    @property
    def a(self) -> F32:
        """The disturbance-weight estimate a, float32 (6,)."""
    @property
    def gains(self) -> Dict[str, Any]:
        """The gains, keyword names as the constructor takes them."""
    @property
    def mass_kg(self) -> float:
        """The vehicle mass the model carries (kg)."""
    @property
    def model(self) -> str:
        """The model: "learned" (from a blob) or "nominal"."""
    @property
    def name(self) -> str:
        """The name: the registry's (`named`), else the model's and the law's (`adaptive-composite`)."""
    def __reduce__(self) -> Tuple[Any, Tuple[Any, ...]]:
        """Pickling (and `copy`, multiprocessing, Ray): the name, the model (its blob bytes,
        re-encoded by the core's encoder; None for the nominal model) and the gains. The
        adaptation estimate and the filters are not carried: the copy starts as after `reset()`."""

class BatchResult:
    """One batched step, one row per vehicle (float32; bool for the flags).

    Row i is what `Controller.step` gives vehicle i: rpm and rotor_thrust_n (N, 4), thrust_n
    (N,), torque_nm (N, 3), a (N, 6), and the flags fault, saturated, tilt_limited (N,)."""

    rpm: F32
    rotor_thrust_n: F32
    thrust_n: F32
    torque_nm: F32
    a: F32
    fault: npt.NDArray[np.bool_]
    saturated: npt.NDArray[np.bool_]
    tilt_limited: npt.NDArray[np.bool_]

class ControllerBatch:
    """N independent controllers stepped by one call on arrays of N states.

    `ControllerBatch(n, weights, law=..., adapt=..., **gains)`: `n` controllers on the same
    model and gains, as the `Controller` constructor takes them; or
    `ControllerBatch(controllers=[...])`: copies of the given controllers, their estimates
    included. Row i of a step equals what a `Controller` would give. `len(batch)` is N."""

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
        """One step of every controller; returns a BatchResult.

        p (N, 3), R (N, 3, 3), v_body (N, 3), w_body (N, 3); setpoint one Setpoint for all,
        positions (N, 3) or a dict of arrays with the bridge's keys (p (N, 3), v, a, j, yaw (N,),
        yaw_rate); dt a float or (N,); acc None or (N, 3)."""
    def reset(self, *indices: int) -> None:
        """Resets every controller, or only those whose indices are given."""
    @property
    def a(self) -> F32:
        """The estimates a, float32 (N, 6)."""

class Scenario:
    """A validated scenario (the TOML files of scenarios/): duration, rates, seed, reference
    trajectory, disturbance, effects, vehicle, sensors, start.

    `Scenario.load(path)`, `Scenario.from_toml(text)` or `Scenario.from_dict(spec)`; `to_dict()`
    gives the keys to edit. Fly it with `sitl.fly`, or step it with `sitl.Plant`. Scenarios
    compare equal when every key, the name and the file are, and pickle."""

    @staticmethod
    def load(path: Union[str, PathLike]) -> Scenario:
        """Reads and validates a scenario file (ValueError naming the problem otherwise). A relative
        `scenarios/NAME.toml` (or `NAME.toml`, `NAME`) that does not exist is the package's copy
        (`hamflight.data`)."""
    @staticmethod
    def from_toml(text: str, name: str = "scenario") -> Scenario:
        """Parses and validates scenario TOML text; `name` names it when the text has no `name`."""
    @staticmethod
    def from_dict(spec: Dict[str, Any], name: Optional[str] = None) -> Scenario:
        """A scenario from a dict with the file's keys (as `to_dict` gives them), validated;
        `name` overrides the dict's. Floats are taken exactly; a bad key or value raises
        ValueError naming it."""
    def to_dict(self) -> Dict[str, Any]:
        """The scenario's keys as a dict (every default filled in); edit and pass to from_dict."""
    def reference(self, t_s: float) -> Dict[str, Any]:
        """The reference at time t: dict of p_m, v_m_s, a_m_s2, j_m_s3 (world) and yaw_rad,
        yaw_rate_rad_s."""
    @property
    def name(self) -> str:
        """The `name` key, else the file's stem (or the name given)."""
    @property
    def duration_s(self) -> float:
        """The flight's length (s)."""
    @property
    def control_hz(self) -> float:
        """The control rate (Hz)."""
    def __reduce__(self) -> Tuple[Any, Tuple[str, Optional[PathLike], Dict[str, Any]]]:
        """Pickling (and `copy`, multiprocessing, Ray): the name, the file it was read from (the
        flight's report names it) and the keys as `to_dict` gives them, validated again on
        unpickling; the copy flies exactly as the original."""
    def __eq__(self, other: object) -> bool: ...
    def __hash__(self) -> int: ...

class Plant:
    """The SITL quadrotor of a scenario (its vehicle, wind, faults and effects), stepped by the
    caller (`hamflight.env.QuadrotorEnv` wraps it).

    `Plant(scenario)` starts at the scenario's initial state at t = 0. Observations are 18
    floats: position (m, world), velocity (m/s, world), R (body -> world, row-major), body rates
    (rad/s)."""

    def __init__(self, scenario: Scenario) -> None: ...
    def reset(self) -> npt.NDArray[np.float64]:
        """Back to the scenario's initial state at t = 0; returns the observation."""
    def observation(self) -> npt.NDArray[np.float64]:
        """The state as one array of 18: position (m, world), velocity (m/s, world), R (body →
        world, row-major), body rates ω (rad/s)."""
    def step_rpm(self, rpm: Sequence[float], dt_s: Optional[float] = None) -> npt.NDArray[np.float64]:
        """Hold the four rotor speeds `rpm` (clamped to the vehicle's range; the motors' lag, if the
        scenario has one, acts on them) for `dt_s` (default: the scenario's control period), the
        physics at the scenario's rate; returns the observation."""
    def step_wrench(
        self, thrust_n: float, torque_nm: Sequence[float], dt_s: Optional[float] = None
    ) -> npt.NDArray[np.float64]:
        """The body wrench (collective thrust N, torques N·m) mixed by the core's mixer for this
        vehicle (roll and pitch first, then yaw, then the thrust, as on the vehicle), held for
        `dt_s`; returns the observation. A non-finite wrench stops the rotors, as the mixer does."""
    def reference(self, t_s: Optional[float] = None) -> Dict[str, Any]:
        """The scenario's reference at `t_s` (default: now), as `Scenario.reference` gives it."""
    @property
    def t_s(self) -> float:
        """Simulated time (s)."""
    @property
    def duration_s(self) -> float:
        """The scenario's flight length (s)."""
    @property
    def control_dt_s(self) -> float:
        """The scenario's control period (s): the default step."""
    @property
    def mass_kg(self) -> float:
        """The vehicle's mass (kg)."""
    @property
    def gravity_m_s2(self) -> float:
        """Gravity (m/s²)."""
    @property
    def inertia_kg_m2(self) -> Tuple[float, float, float]:
        """diag(J) (kg·m², body)."""
    @property
    def max_rpm(self) -> float:
        """The rotors' top speed (rpm)."""
    @property
    def max_thrust_n(self) -> float:
        """The largest collective thrust the four rotors give (N)."""

class FlightResult:
    """A flown SITL flight: per-tick numpy arrays and report.json's scores.

    t_s (n,), p_m and p_ref_m (n, 3), err_m (n,), rpm (n, 4), adaptation (n, 6) or (n, 0); the
    true state rpy_rad, v_world_m_s, w_body_rad_s (n, 3); the state the controller flew on
    est_p_m, est_v_world_m_s, est_rpy_rad, est_w_body_rad_s (n, 3): with a `[sensors]` section
    the estimator's output (and the filtered gyro), else the truth plus the scenario's noise (the
    truth itself without noise). Row i is tick t_s[i]. `report` is the dict `host-train eval`
    writes as report.json, `rmse_m` and `crashed` two of its scores."""

    t_s: npt.NDArray[np.float64]
    """Tick times (s), (n,)."""
    p_m: npt.NDArray[np.float64]
    """Flown (true) position (m, world), (n, 3)."""
    p_ref_m: npt.NDArray[np.float64]
    """Desired position (m, world), (n, 3)."""
    err_m: npt.NDArray[np.float64]
    """|p − p*| (m), (n,)."""
    rpm: npt.NDArray[np.float64]
    """Rotor commands (rpm), (n, 4)."""
    adaptation: npt.NDArray[np.float64]
    """The adaptation estimate a, (n, 6); (n, 0) for a controller that does not adapt."""
    rpy_rad: npt.NDArray[np.float64]
    """True attitude as roll, pitch, yaw (rad, Z-Y-X: R = Rz(yaw) Ry(pitch) Rx(roll)), (n, 3)."""
    v_world_m_s: npt.NDArray[np.float64]
    """True velocity (m/s, world), (n, 3)."""
    w_body_rad_s: npt.NDArray[np.float64]
    """True body rates ω (rad/s, body frame), (n, 3)."""
    est_p_m: npt.NDArray[np.float64]
    """The position the controller was given (m, world), (n, 3): the estimator's with a
    `[sensors]` section, else the true one plus the scenario's noise."""
    est_v_world_m_s: npt.NDArray[np.float64]
    """The velocity the controller was given (m/s, world), (n, 3)."""
    est_rpy_rad: npt.NDArray[np.float64]
    """The attitude the controller was given, roll, pitch, yaw (rad, as rpy_rad), (n, 3)."""
    est_w_body_rad_s: npt.NDArray[np.float64]
    """The body rates the controller was given (rad/s, body frame; the filtered gyro with a
    `[sensors]` section), (n, 3)."""
    report: Dict[str, Any]
    """The scores (the keys of `host-train eval`'s report.json)."""
    @property
    def rmse_m(self) -> Optional[float]:
        """Position RMSE over t ≥ 5 s (m), None if the flight ended before."""
    @property
    def crashed(self) -> bool:
        """The error exceeded 1 m, z went below 0 or the state became non-finite."""

def fly(
    scenario: Union[Scenario, str, PathLike],
    controller: Union[str, Controller] = "adaptive",
    weights: Weights = None,
) -> FlightResult:
    """Flies `scenario` (a Scenario or a path) with `controller`; returns a FlightResult.

    `controller`: a name (the core's, `pid`, `geometric`; `controllers()` lists them; default
    "adaptive") or a hamflight.Controller (a copy flies; its estimate starts from zero).
    `weights` (a blob, its path or bytes) replaces the shipped blob for the learned names. The
    GIL is released during the flight."""
def controllers() -> List[Tuple[str, str]]:
    """The registry's controllers as (name, description) pairs: the core's (`CONTROLLER_NAMES`),
    `pid` and `geometric`."""
def run_tool(command: str, json_config: str) -> str:
    """Runs `host-train collect|import|train` on `json_config`, a JSON object with the flags' names
    (`out`, `epochs`, ...; a key left out takes the flag's default): it becomes the typed job
    (`host_train::data::CollectJob`, `host_train::data::ImportJob`,
    `host_train::train::TrainJob`) and runs through the function the command line calls.
    Returns the command's summary as JSON text. The GIL is released while it runs."""
def _restore_controller(name: str, from_registry: bool, weights: Optional[bytes], gains: Dict[str, Any]) -> Controller:
    """Unpickles a `Controller` (`Controller.__reduce__`)."""
def _restore_blob(data: bytes, name: str) -> Blob:
    """Unpickles a `Blob` (`Blob.__reduce__`)."""
def _restore_scenario(name: str, path: Optional[PathLike], spec: Dict[str, Any]) -> Scenario:
    """Unpickles a `Scenario` (`Scenario.__reduce__`)."""
