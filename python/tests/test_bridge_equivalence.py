"""The Python controller gives the bridge's f32 results bit for bit, on a recorded stream of
requests (generated here, deterministic: a wobbling flight around a moving setpoint, with
accelerometer lines, a bad tick and a non-finite state among them)."""

import json

import numpy as np
import pytest

import hamflight
from conftest import ROOT, run_bridge

WEIGHTS = ROOT / "weights" / "default.hfw"


def so3_exp(theta):
    th = np.linalg.norm(theta)
    K = np.array([[0, -theta[2], theta[1]], [theta[2], 0, -theta[0]], [-theta[1], theta[0], 0]])
    if th < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * (K @ K)


def recorded_stream(n=1500, seed=7):
    """Request dicts of the bridge protocol."""
    rng = np.random.default_rng(seed)
    reqs = []
    t = 0.0
    for k in range(n):
        t = round(t + 0.002, 6)
        s = 2 * np.pi * 0.2 * t
        p = np.array([0.5 * np.cos(s), 0.5 * np.sin(s), 0.5 + 0.03 * t]) + rng.normal(0, 0.01, 3)
        R = so3_exp(np.array([0.1 * np.sin(3 * t), 0.08 * np.cos(2 * t), 0.3 * np.sin(0.5 * t)]) + rng.normal(0, 0.01, 3))
        v = rng.normal(0, 0.2, 3)
        w = rng.normal(0, 0.5, 3)
        sp = {
            "p": [0.5 * np.cos(s), 0.5 * np.sin(s), 0.5 + 0.03 * t],
            "v": [-0.5 * 2 * np.pi * 0.2 * np.sin(s), 0.5 * 2 * np.pi * 0.2 * np.cos(s), 0.03],
            "a": [-0.5 * (2 * np.pi * 0.2) ** 2 * np.cos(s), -0.5 * (2 * np.pi * 0.2) ** 2 * np.sin(s), 0.0],
            "yaw": 0.1 * np.sin(t),
            "yaw_rate": 0.1 * np.cos(t),
        }
        req = {"t": t, "p": p.tolist(), "R": R.tolist(), "v": v.tolist(), "w": w.tolist(), "setpoint": sp}
        if k % 3 == 0:
            req["acc"] = (R.T @ np.array([0, 0, 9.8]) + rng.normal(0, 0.3, 3)).tolist()
        if k == 700:
            req["p"][0] = 1e39  # finite in JSON, infinite as f32: bad_state
        if k == 900:
            req["t"] = reqs[-1]["t"]  # a zero-length tick: bad_dt
            t = req["t"]
        reqs.append(req)
    return reqs


def f32(x):
    return np.array(x, dtype=np.float64).astype(np.float32)


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


@pytest.mark.parametrize(
    "name",
    ["adaptive", "adaptive-composite", "learned", "geometric-adaptive", "geometric-adaptive-composite", "ida-pbc"],
)
def test_python_equals_bridge_bit_for_bit(bridge_binary, name):
    reqs = recorded_stream()
    lines = [json.dumps(r) for r in reqs]
    replies = [json.loads(l) for l in run_bridge(bridge_binary, lines, name, WEIGHTS)]
    assert len(replies) == len(reqs)
    ctrl = hamflight.Controller.named(name, weights=WEIGHTS)
    last_t = None
    faults_seen = set()
    for req, rep in zip(reqs, replies):
        assert "error" not in rep, rep
        dt = 0.002 if last_t is None else req["t"] - last_t
        last_t = req["t"]
        out = ctrl.step(
            np.array(req["p"]), np.array(req["R"]), np.array(req["v"]), np.array(req["w"]),
            req["setpoint"], dt, acc=np.array(req["acc"]) if "acc" in req else None,
        )
        np.testing.assert_array_equal(bits(out.rpm), bits(f32(rep["rpm"])))
        np.testing.assert_array_equal(bits(out.rotor_thrust_n), bits(f32(rep["rotor_thrust_n"])))
        np.testing.assert_array_equal(bits([out.thrust_n]), bits(f32([rep["thrust_n"]])))
        np.testing.assert_array_equal(bits(out.torque_nm), bits(f32(rep["torque_nm"])))
        np.testing.assert_array_equal(bits(out.a), bits(f32(rep["a"])))
        assert out.faults.to_dict() == rep["faults"]
        faults_seen |= {k for k, v in rep["faults"].items() if v}
    assert {"fault", "bad_state", "bad_dt"} <= faults_seen


def test_bridge_default_controller_is_named_adaptive(bridge_binary):
    reqs = recorded_stream(50)
    replies = [json.loads(l) for l in run_bridge(bridge_binary, [json.dumps(r) for r in reqs], "adaptive", WEIGHTS)]
    ctrl = hamflight.Controller(hamflight.Blob.load(WEIGHTS))  # the constructor's defaults
    last_t = None
    for req, rep in zip(reqs, replies):
        dt = 0.002 if last_t is None else req["t"] - last_t
        last_t = req["t"]
        out = ctrl.step(req["p"], req["R"], req["v"], req["w"], req["setpoint"], dt, acc=req.get("acc"))
        np.testing.assert_array_equal(bits(out.rpm), bits(f32(rep["rpm"])))
