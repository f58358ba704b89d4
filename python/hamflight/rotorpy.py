"""hamflight driving RotorPy (https://github.com/spencerfolk/rotorpy) through its rotor-speed
interface (``control_abstraction="cmd_motor_speeds"``).

Conversions from RotorPy's state dict (world frame z up, gravity along -z, as ours):

=================  ==========================================  ==============================
hamflight input    from RotorPy                                note
=================  ==========================================  ==============================
``p`` (m, world)   ``state["x"]``                              same frame
``R`` body->world  ``Rotation.from_quat(state["q"]).as_matrix()``  RotorPy's q is [x, y, z, w]
``v_body`` (m/s)   ``R.T @ state["v"]``                        RotorPy's v is in the world frame
``w_body`` (rad/s) ``state["w"]``                              already body frame
setpoint           flat outputs ``x``, ``x_dot``, ``x_ddot``,  yaw ``yaw``, ``yaw_dot``
                   ``x_dddot``
=================  ==========================================  ==============================

Output: the core's four rotor thrusts T_i (N) become RotorPy rotor speeds
ω = sqrt(T / k_eta) (rad/s), clipped to RotorPy's [rotor_speed_min, rotor_speed_max]. The rotors
are matched by position, not by number: our rotor 1 sits at (+x, -y), 2 at (-x, -y), 3 at
(-x, +y), 4 at (+x, +y); RotorPy's Crazyflie numbers them r1 (+x, +y), r2 (+x, -y),
r3 (-x, -y), r4 (-x, +y), so RotorPy's speeds are ours in the order (4, 1, 2, 3); the spin
directions then agree (RotorPy's ``rotor_directions`` [1, -1, 1, -1] and our yaw signs).
What RotorPy's Crazyflie differs in and the controller does not know: mass 30 g (the model
says 27 g), arm 30.4 mm (28 mm), yaw-moment ratio k_m/k_eta 0.034 m (0.025 m), inertia
(1.43, 1.43, 2.89)e-5 kg m^2, a 72 ms motor lag, rotor drag and induced inflow (``aero``).
"""

from __future__ import annotations

from typing import Any, Dict, Optional

import numpy as np

from ._core import Controller, Setpoint

#: RotorPy rotor j is our rotor ROTOR_ORDER[j] (0-based): matched by position.
ROTOR_ORDER = (3, 0, 1, 2)


def state_to_core(state: Dict[str, Any]):
    """(p, R, v_body, w_body) for Controller.step from a RotorPy state dict."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_quat(state["q"]).as_matrix()
    return (
        np.asarray(state["x"], dtype=np.float64),
        R,
        R.T @ np.asarray(state["v"], dtype=np.float64),
        np.asarray(state["w"], dtype=np.float64),
    )


def flat_to_setpoint(flat: Dict[str, Any]) -> Setpoint:
    """A Setpoint from a RotorPy trajectory's flat outputs."""
    return Setpoint(
        flat["x"],
        flat.get("x_dot"),
        flat.get("x_ddot"),
        flat.get("x_dddot"),
        float(flat.get("yaw", 0.0)),
        float(flat.get("yaw_dot", 0.0)),
    )


class RotorPyController:
    """A hamflight Controller with RotorPy's controller interface: ``update(t, state, flat)``
    returns ``{"cmd_motor_speeds": ...}`` (rad/s, RotorPy's rotor order), so it also plugs
    into ``rotorpy.environments.Environment``.

    The tick length is the difference of successive ``t`` (``dt`` for the first call, and
    whenever time does not advance).
    """

    def __init__(self, controller: Controller, quad_params: Dict[str, Any], dt: float = 0.002):
        self.controller = controller
        self.k_eta = float(quad_params["k_eta"])
        self.speed_min = float(quad_params.get("rotor_speed_min", 0.0))
        self.speed_max = float(quad_params["rotor_speed_max"])
        self.dt = dt
        self._t_last: Optional[float] = None
        self.last = None

    def reset(self) -> None:
        self.controller.reset()
        self._t_last = None

    def update(self, t: float, state: Dict[str, Any], flat: Dict[str, Any]) -> Dict[str, Any]:
        dt = self.dt if self._t_last is None or t <= self._t_last else t - self._t_last
        self._t_last = t
        p, R, v_body, w_body = state_to_core(state)
        out = self.controller.step(p, R, v_body, w_body, flat_to_setpoint(flat), dt)
        self.last = out
        thrust = out.rotor_thrust_n.astype(np.float64)[list(ROTOR_ORDER)]
        speeds = np.sqrt(np.maximum(thrust, 0.0) / self.k_eta)
        speeds = np.clip(speeds, self.speed_min, self.speed_max)
        return {
            "cmd_motor_speeds": speeds,
            "cmd_thrust": float(out.thrust_n),
            "cmd_moment": out.torque_nm.astype(np.float64),
            "cmd_q": np.array([0.0, 0.0, 0.0, 1.0]),
            "cmd_w": np.zeros(3),
            "cmd_v": np.zeros(3),
            "cmd_acc": np.zeros(3),
        }


def fly(
    controller: Controller,
    trajectory: Any,
    t_final: float,
    *,
    quad_params: Optional[Dict[str, Any]] = None,
    wind_profile: Any = None,
    dt: float = 0.002,
    initial_state: Optional[Dict[str, Any]] = None,
    aero: bool = True,
) -> Dict[str, np.ndarray]:
    """Closed loop: ``controller`` flies RotorPy's Multirotor (its Crazyflie parameters unless
    ``quad_params``) along ``trajectory`` (any RotorPy trajectory) for ``t_final`` s, one
    control tick per RotorPy step of ``dt`` s, under ``wind_profile`` (a RotorPy wind, air
    velocity in m/s). The vehicle starts at rest on the trajectory's first point, rotors at
    hover speed. Returns arrays ``t`` (n,), ``x`` (n, 3), ``x_des`` (n, 3), ``err`` (n,),
    ``speeds`` (n, 4) and ``fault`` (n,)."""
    from rotorpy.vehicles.multirotor import Multirotor

    if quad_params is None:
        from rotorpy.vehicles.crazyflie_params import quad_params
    flat0 = trajectory.update(0.0)
    hover = np.sqrt(quad_params["mass"] * 9.81 / (4 * quad_params["k_eta"]))
    state = initial_state or {
        "x": np.asarray(flat0["x"], dtype=np.float64).copy(),
        "v": np.zeros(3),
        "q": np.array([0.0, 0.0, 0.0, 1.0]),
        "w": np.zeros(3),
        "wind": np.zeros(3),
        "rotor_speeds": np.full(4, hover),
    }
    vehicle = Multirotor(quad_params, initial_state=state, control_abstraction="cmd_motor_speeds", aero=aero)
    pilot = RotorPyController(controller, quad_params, dt)
    pilot.reset()
    n = int(round(t_final / dt))
    log = {k: [] for k in ("t", "x", "x_des", "speeds", "fault")}
    for k in range(n + 1):
        t = k * dt
        if wind_profile is not None:
            state["wind"] = wind_profile.update(t, state["x"])
        flat = trajectory.update(t)
        cmd = pilot.update(t, state, flat)
        log["t"].append(t)
        log["x"].append(np.array(state["x"], dtype=np.float64))
        log["x_des"].append(np.asarray(flat["x"], dtype=np.float64))
        log["speeds"].append(cmd["cmd_motor_speeds"])
        log["fault"].append(bool(pilot.last.faults.fault))
        if k < n:
            state = vehicle.step(state, cmd, dt)
    out = {k: np.asarray(v) for k, v in log.items()}
    out["err"] = np.linalg.norm(out["x"] - out["x_des"], axis=1)
    return out
