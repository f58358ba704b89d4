"""A Monte Carlo sweep over randomized disturbances in the SITL, on one machine
(multiprocessing) or on Ray, with the same numbers from both.

Each flight is a 10 s circle (radius 0.5 m, 10 s period, 1 m height) under a wind of random
strength (0 to 1.2 m/s^2 specific force) and heading, a random gust (a sine of 0 to 0.4 m/s^2
at 0.2 to 1 Hz), random rotor efficiencies (each 70 % to 100 %) and state noise with its own
seed. The draws come from one numpy generator seeded with ``seed``, so a sweep is a pure
function of (n, seed, controller): the backend only changes who flies which flight.

A flight succeeds when it does not crash and its RMSE over t >= 5 s is below ``SUCCESS_RMSE_M``.

>>> from hamflight import montecarlo as mc
>>> res = mc.run(mc.draw(1000), backend="multiprocessing", workers=2)
>>> print(mc.summary_text(mc.summarize(res)))
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from . import sitl

#: RMSE over t >= 5 s (m) below which a flight counts as a success.
SUCCESS_RMSE_M = 0.02

BASE = """
name = "montecarlo-circle"
duration_s = 10.0
[trajectory]
kind = "circle"
center_m = [0.0, 0.0, 1.0]
radius_m = 0.5
period_s = 10.0
[effects.noise]
pos_m = 0.0005
vel_m_s = 0.005
"""


def draw(n: int, seed: int = 2024) -> List[Dict[str, Any]]:
    """n disturbance draws (dicts of plain floats, picklable), reproducible from ``seed``."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        mag = rng.uniform(0.0, 1.2)
        heading = rng.uniform(0.0, 2 * np.pi)
        wind = [mag * np.cos(heading), mag * np.sin(heading), rng.uniform(-0.2, 0.2)]
        gust_dir = rng.normal(size=2)
        gust_dir /= np.linalg.norm(gust_dir)
        amp = rng.uniform(0.0, 0.4)
        out.append(
            {
                "index": i,
                "seed": int(rng.integers(0, 2**31)),
                "wind_m_s2": [float(x) for x in wind],
                "gust_m_s2": [float(amp * gust_dir[0]), float(amp * gust_dir[1]), 0.0],
                "gust_hz": float(rng.uniform(0.2, 1.0)),
                "rotor_efficiency": [float(x) for x in rng.uniform(0.7, 1.0, 4)],
            }
        )
    return out


_BASE_SPEC: Optional[Dict[str, Any]] = None


def scenario_for(d: Dict[str, Any]) -> "sitl.Scenario":
    """The SITL scenario of one draw."""
    global _BASE_SPEC
    if _BASE_SPEC is None:
        _BASE_SPEC = sitl.Scenario.from_toml(BASE, name="montecarlo-circle").to_dict()
    spec = dict(_BASE_SPEC)
    spec["seed"] = d["seed"]
    spec["disturbance"] = {
        **spec["disturbance"],
        "wind_m_s2": d["wind_m_s2"],
        "rotor_efficiency": d["rotor_efficiency"],
        "wind_sines": [{"amplitude_m_s2": d["gust_m_s2"], "frequency_hz": d["gust_hz"], "phase_rad": 0.0}],
    }
    return sitl.Scenario.from_dict(spec)


def fly_one(d: Dict[str, Any], controller: str = "adaptive") -> Dict[str, Any]:
    """Flies one draw; returns its index, RMSE over t >= 5 s (m; inf on a crash) and crash flag."""
    log = sitl.fly(scenario_for(d), controller)
    rmse = log.rmse_m
    crashed = bool(log.crashed)
    return {
        "index": d["index"],
        "rmse_m": float("inf") if crashed or rmse is None else float(rmse),
        "crashed": crashed,
    }


def fly_many(ds: Sequence[Dict[str, Any]], controller: str = "adaptive") -> List[Dict[str, Any]]:
    return [fly_one(d, controller) for d in ds]


def _chunks(ds: Sequence[Dict[str, Any]], size: int) -> List[Sequence[Dict[str, Any]]]:
    return [ds[i : i + size] for i in range(0, len(ds), size)]


def run(
    draws: Sequence[Dict[str, Any]],
    *,
    backend: str = "multiprocessing",
    workers: int = 2,
    controller: str = "adaptive",
    chunk: int = 25,
    ray_local_mode: bool = False,
) -> List[Dict[str, Any]]:
    """Flies every draw on ``backend``: "serial", "multiprocessing" (a process pool of
    ``workers``) or "ray" (``ray.init(num_cpus=workers)`` unless Ray is already initialized;
    ``ray_local_mode`` runs the tasks in this process). Results sorted by index."""
    parts = _chunks(list(draws), chunk)
    if backend == "serial":
        results = [r for p in parts for r in fly_many(p, controller)]
    elif backend == "multiprocessing":
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        with ctx.Pool(workers) as pool:
            results = [r for rs in pool.starmap(fly_many, [(p, controller) for p in parts]) for r in rs]
    elif backend == "ray":
        import ray

        started = False
        if not ray.is_initialized():
            kwargs = dict(num_cpus=workers, include_dashboard=False, log_to_driver=False)
            if ray_local_mode:
                kwargs["local_mode"] = True
            ray.init(**kwargs)
            started = True
        try:
            remote = ray.remote(num_cpus=1)(fly_many)
            results = [r for rs in ray.get([remote.remote(p, controller) for p in parts]) for r in rs]
        finally:
            if started:
                ray.shutdown()
    else:
        raise ValueError(f'backend: expected "serial", "multiprocessing" or "ray", got {backend!r}')
    return sorted(results, key=lambda r: r["index"])


def summarize(results: Sequence[Dict[str, Any]], success_rmse_m: float = SUCCESS_RMSE_M) -> Dict[str, Any]:
    """Success rate, crash count and RMSE quantiles (cm) of a sweep."""
    rmse = np.array([r["rmse_m"] for r in results])
    finite = rmse[np.isfinite(rmse)]
    q = {f"p{p}": float(100 * np.quantile(finite, p / 100)) for p in (5, 50, 90, 95, 99)} if len(finite) else {}
    return {
        "flights": len(results),
        "success_rate": float(np.mean(rmse < success_rmse_m)),
        "crashed": int(sum(r["crashed"] for r in results)),
        "rmse_cm": {**q, "max": float(100 * finite.max()) if len(finite) else float("nan")},
    }


def summary_text(s: Dict[str, Any]) -> str:
    q = s["rmse_cm"]
    keys = [k for k in ("p5", "p50", "p90", "p95", "p99", "max") if k in q]
    return (
        f"{s['flights']} flights: success {100 * s['success_rate']:.1f} % (RMSE t >= 5 s < "
        f"{100 * SUCCESS_RMSE_M:.0f} cm), {s['crashed']} crashed; RMSE (cm) "
        + ", ".join(f"{k} {q[k]:.3f}" for k in keys)
    )
