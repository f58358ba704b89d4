"""Throughput of the Python package (not a test): Controller.step from Python, the batched
ControllerBatch.step per vehicle, and the JSON-lines bridge through a pipe for comparison.

    python python/bench.py [--steps 200000] [--batch 1000] [--no-bridge]

One process, one core (pin it with `taskset -c 0`). Rates are per CPU second of this process
(time.process_time), so other load on the machine does not lower them; the wall-clock rate is
printed beside when it differs by more than 10 %.
"""

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

# Python puts this script's folder first on the path, where the source package (without its
# compiled `_core`) would shadow the installed wheel.
_here = pathlib.Path(__file__).resolve().parent
sys.path = [p for p in sys.path if pathlib.Path(p or ".").resolve() != _here]

import numpy as np  # noqa: E402

import hamflight  # noqa: E402

ap = argparse.ArgumentParser()
ap.add_argument("--steps", type=int, default=200_000)
ap.add_argument("--batch", type=int, default=1000)
ap.add_argument("--batch-steps", type=int, default=200)
ap.add_argument("--no-bridge", action="store_true")
args = ap.parse_args()

ROOT = pathlib.Path(__file__).resolve().parents[1]


WALL = {}


def best_of(f, reps=3):
    """Best CPU time of reps runs (and its wall time in WALL['last'])."""
    best = None
    for _ in range(reps):
        w0 = time.perf_counter()
        cpu = f()
        wall = time.perf_counter() - w0
        if best is None or cpu < best[0]:
            best = (cpu, wall)
    WALL["last"] = best[1]
    return best[0]


def single(name, law_args):
    c = hamflight.Controller.named(name, **law_args)
    p = np.array([0.0, 0.0, 0.5])
    R = np.eye(3)
    v = np.zeros(3)
    w = np.zeros(3)
    sp = hamflight.Setpoint([0.1, 0.0, 0.5])
    n = args.steps

    def run():
        c.reset()
        step = c.step
        t0 = time.process_time()
        for _ in range(n):
            step(p, R, v, w, sp, 0.002)
        return time.process_time() - t0

    dt = best_of(run)
    return n / dt, n / WALL["last"]


def batch(name):
    n = args.batch
    b = hamflight.ControllerBatch(controllers=[hamflight.Controller.named(name)] * n)
    p = np.tile([0.0, 0.0, 0.5], (n, 1))
    R = np.repeat(np.eye(3)[None], n, axis=0)
    z = np.zeros((n, 3))
    sp = hamflight.Setpoint([0.1, 0.0, 0.5])

    def run():
        b.reset()
        t0 = time.process_time()
        for _ in range(args.batch_steps):
            b.step(p, R, z, z, sp, 0.002)
        return time.process_time() - t0

    dt = best_of(run)
    return n * args.batch_steps / dt, n * args.batch_steps / WALL["last"]


def bridge(name, lines=50_000):
    exe = os.environ.get("HAMFLIGHT_HOST_TRAIN") or str(
        pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "release" / "host-train"
    )
    if not pathlib.Path(exe).exists():
        return None
    req = {"t": 0.0, "p": [0, 0, 0.5], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "v": [0, 0, 0], "w": [0, 0, 0],
           "setpoint": {"p": [0.1, 0, 0.5]}}
    text = []
    for k in range(lines):
        req["t"] = round(0.002 * (k + 1), 6)
        text.append(json.dumps(req))
    data = ("\n".join(text) + "\n").encode()
    t0 = time.perf_counter()
    r0 = os.times()
    out = subprocess.run([exe, "bridge", "--controller", name, "--weights", str(ROOT / "weights" / "default.hfw")],
                         input=data, capture_output=True, check=True, cwd=ROOT)
    dt = time.perf_counter() - t0
    r1 = os.times()
    cpu = (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)
    assert out.stdout.count(b"\n") == lines
    return lines / cpu, lines / dt


print(f"hamflight {hamflight.__version__}, numpy {np.__version__}")
for name in ("adaptive", "adaptive-composite", "geometric-adaptive"):
    def fmt(rate, wall):
        extra = f" [wall {wall:,.0f}]" if abs(wall - rate) > 0.1 * rate else ""
        return f"{rate:>10,.0f}{extra}"

    s, sw = single(name, {})
    b, bw = batch(name)
    line = (f"{name:>20}: Controller.step {fmt(s, sw)} steps/s ({1e6 / s:.2f} us); "
            f"ControllerBatch({args.batch}).step {fmt(b, bw)} vehicle-steps/s ({1e6 / b:.2f} us per vehicle)")
    if not args.no_bridge:
        br = bridge(name)
        if br:
            line += f"; bridge through a pipe {fmt(*br)} replies/s (bridge CPU)"
    print(line, flush=True)
