"""A Gymnasium-style environment on the SITL quadrotor (:class:`hamflight.sitl.Plant`), for
flying a Python policy.

>>> from hamflight.env import QuadrotorEnv
>>> env = QuadrotorEnv("hover")
>>> obs, info = env.reset()
>>> obs, reward, terminated, truncated, info = env.step([env.hover_thrust_n, 0.0, 0.0, 0.0])

The action is the body wrench ``[thrust N, torque x, y, z N·m]``, mixed by the core's mixer for
the scenario's vehicle and held for one control period (the scenario's, 2 ms by default). The
observation is 18 floats: the position error p − p_ref (m, world), the velocity (m/s, world), R
(body → world, row-major) and the body rates ω (rad/s); ``info`` has the reference, the time and
the true position. The reward is minus the position error (m). An episode terminates when the
vehicle is more than 1 m from the reference, below the ground or not finite (the SITL's crash
test), and is truncated at the scenario's duration.

With the ``gymnasium`` package installed the class is a ``gymnasium.Env`` with Box spaces;
without it, the same methods and return values, so nothing here needs it.
"""

from __future__ import annotations

from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np

from ._core import Plant, Scenario

try:  # optional: the same API either way
    import gymnasium as _gym
    from gymnasium import spaces as _spaces

    _Base: Any = _gym.Env
except ImportError:  # pragma: no cover - exercised where gymnasium is absent
    _gym = None
    _spaces = None
    _Base = object

__all__ = ["QuadrotorEnv", "CRASH_ERR_M"]

#: Distance from the reference (m) past which the episode terminates, as the SITL's crash test.
CRASH_ERR_M = 1.0


class QuadrotorEnv(_Base):
    """The scenario's quadrotor under a wrench action (see the module's docs)."""

    metadata = {"render_modes": []}

    def __init__(self, scenario: Union[str, Scenario] = "hover") -> None:
        sc = scenario if isinstance(scenario, Scenario) else Scenario.load(scenario)
        self.plant = Plant(sc)
        self.hover_thrust_n = self.plant.mass_kg * self.plant.gravity_m_s2
        if _spaces is not None:
            torque = 0.01
            self.action_space = _spaces.Box(
                low=np.array([0.0, -torque, -torque, -torque]),
                high=np.array([self.plant.max_thrust_n, torque, torque, torque]),
                dtype=np.float64,
            )
            self.observation_space = _spaces.Box(-np.inf, np.inf, shape=(18,), dtype=np.float64)

    def _observe(self, state: np.ndarray) -> Tuple[np.ndarray, dict]:
        ref = self.plant.reference()
        obs = state.copy()
        obs[0:3] -= ref["p_m"]
        info = {"t_s": self.plant.t_s, "p_m": state[0:3].copy(), "reference": ref}
        return obs, info

    def reset(
        self, *, seed: Optional[int] = None, options: Optional[dict] = None
    ) -> Tuple[np.ndarray, dict]:
        """Back to the scenario's start; returns ``(observation, info)``. The plant is
        deterministic: ``seed`` is accepted for the Gymnasium API and changes nothing."""
        if _gym is not None:
            super().reset(seed=seed)
        return self._observe(self.plant.reset())

    def step(self, action: Sequence[float]) -> Tuple[np.ndarray, float, bool, bool, dict]:
        """Apply ``[thrust N, τx, τy, τz N·m]`` for one control period; returns
        ``(observation, reward, terminated, truncated, info)``."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (4,):
            raise ValueError(f"action must be [thrust_n, tx, ty, tz], got shape {a.shape}")
        state = self.plant.step_wrench(float(a[0]), [float(a[1]), float(a[2]), float(a[3])])
        obs, info = self._observe(state)
        err = float(np.linalg.norm(obs[0:3]))
        finite = bool(np.all(np.isfinite(state)))
        terminated = (not finite) or err > CRASH_ERR_M or state[2] < 0.0
        truncated = (not terminated) and self.plant.t_s >= self.plant.duration_s - 1e-9
        reward = -err if finite else -CRASH_ERR_M
        return obs, reward, terminated, truncated, info
