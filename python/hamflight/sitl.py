"""The SITL quadrotor of ``host-train`` (CF2X constants, wind, rotor faults, motor lag, noise)
and its TOML scenario files, from Python.

>>> from hamflight import sitl
>>> log = sitl.fly("scenarios/paper-spiral.toml", "adaptive")
>>> log.rmse_m, log.p_m.shape          # RMSE over t >= 5 s (m), (ticks, 3) positions
>>> log.rpy_rad, log.v_world_m_s, log.est_p_m   # attitude, velocity, the estimate flown on

``fly`` takes a scenario (a :class:`Scenario` or a path) and a controller: a name
(:func:`controllers` lists them; the learned ones fly the shipped blob unless ``weights`` is
given) or a :class:`hamflight.Controller` (a fresh copy of it flies). To vary a scenario, edit
its dict: ``Scenario.from_dict({**s.to_dict(), "seed": 3})``. A :class:`Scenario` pickles (for
multiprocessing and Ray) to an equal one that flies bit for bit as the original.

The repository's scenario files are inside the package (:mod:`hamflight.data`): a relative
``"scenarios/NAME.toml"`` that does not exist from the working directory is read from there, so
the paths above work outside a checkout.

:class:`Plant` is the same quadrotor stepped by the caller (``reset``, ``step_rpm``,
``step_wrench``, ``observation``, ``reference``), for a policy of your own;
:class:`hamflight.env.QuadrotorEnv` wraps it as a Gymnasium-style environment.
"""

from __future__ import annotations

from ._core import FlightResult, Plant, Scenario, controllers, fly

__all__ = ["Scenario", "FlightResult", "Plant", "fly", "controllers"]
