#!/usr/bin/env python3
"""Why the flights' torque gains come out weak: the closed-loop confound, measured.

On the benchmark's training flights (nanodrone.py's TRAIN_RUNS, never the melon test flights),
regresses the change of each body rate over h steps on the integrated squared rotor speeds of
the four rotors (free per-rotor coefficients), the rate itself (damping) and a constant, then
adds regressors for moments the onboard controller cancels: the tilt (the world vertical's body
components) and the body velocity (the rotors' flapping moment). Prints the per-rotor gains as
a fraction of the published rigid body's (kF arm / J, kM / J) and R².

If the gains grow as regressors for the cancelled moments are added, free gains fitted on these
closed-loop flights are biased toward zero: the onboard controller's torques answer moments the
model lacks, so a weak gain predicts the motion better than the true one. The input variant
`commands` uses the logged motor commands (m*_thrust, through the 32.5 ms motor lag, scaled by
the battery voltage) instead of the measured speeds: noise in the measured speeds is not the
cause if the commands give the same weak gains.

    python3 tools/benchmark/torque_gain_study.py --git-dir NANODRONE_GIT [--steps 5]

Dependencies: numpy, pandas, pyarrow (tools/benchmark/run.sh's venv).
"""

import argparse
import os
import sys

import numpy as np
import pandas as pd

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import nanodrone as nd  # noqa: E402

HOVER_OMEGA2 = nd.MASS * nd.G / (4 * nd.KF)


def lag(x, tau_s, dt_s=0.01):
    """First-order lag (forward Euler at the log's rate), started at the first sample."""
    y = np.empty_like(x)
    a = dt_s / (tau_s + dt_s)
    y[0] = x[0]
    for i in range(1, len(x)):
        y[i] = y[i - 1] + a * (x[i] - y[i - 1])
    return y


def load(args, run):
    d = nd.read_run(args, run)
    om = d[[f"m{i}_erpm" for i in range(1, 5)]].to_numpy(float) * nd.ERPM_TO_RAD_S
    om[~(om < nd.GLITCH_ERPM * nd.ERPM_TO_RAD_S)] = np.nan
    om = pd.DataFrame(om).ffill().bfill().to_numpy()
    cmd = d[[f"m{i}_thrust" for i in range(1, 5)]].to_numpy(float)
    vbat = d["Vbat"].to_numpy(float)
    q = d[["qw", "qx", "qy", "qz"]].to_numpy(float)
    R = nd.quat_to_rot(q / np.linalg.norm(q, axis=1, keepdims=True))
    v_body = np.einsum("nji,nj->ni", R, d[["vx", "vy", "vz"]].to_numpy(float))
    w = d[["wx", "wy", "wz"]].to_numpy(float)
    flying = (d["z"].to_numpy(float) > 0.15) & (cmd.sum(1) > 0.2)
    return dict(om2=om**2, cmd=cmd, vbat=vbat, b=R[:, 2, :], v_body=v_body, w=w, flying=flying)


def command_speeds2(runs):
    """Squared speeds from the commands: Omega^2 = c1 * lag(cmd) * Vbat + c0, fitted on the flights."""
    xs, ys = [], []
    for r in runs:
        x = np.stack([lag(r["cmd"][:, i], 0.0325) for i in range(4)], 1) * r["vbat"][:, None]
        r["cmd_x"] = x
        xs.append(x[r["flying"]].ravel())
        ys.append(r["om2"][r["flying"]].ravel())
    x, y = np.concatenate(xs), np.concatenate(ys)
    A = np.stack([x, np.ones_like(x)], 1)
    c, res, _, _ = np.linalg.lstsq(A, y, rcond=None)
    r2 = 1 - res[0] / np.sum((y - y.mean()) ** 2)
    for r in runs:
        r["cmd_om2"] = c[0] * r["cmd_x"] + c[1]
    return r2


def study(runs, h, source, extra):
    nominal = [nd.KF * nd.ARM_XY / nd.INERTIA[0], nd.KF * nd.ARM_XY / nd.INERTIA[1], nd.KM / nd.INERTIA[2]]
    rows = [[], [], []]
    ys = [[], [], []]
    dt = 0.01
    for r in runs:
        u = r["om2"] if source == "speeds" else r["cmd_om2"]
        n = len(u)
        i = np.arange(n - h)
        keep = r["flying"][i] & r["flying"][i + h]
        cs = np.concatenate([np.zeros((1, 4)), np.cumsum(u, 0)], 0)
        U = (cs[i + h] - cs[i]) * dt
        H = h * dt
        dw = r["w"][i + h] - r["w"][i]
        for a in range(3):
            cols = [U, r["w"][i, a : a + 1] * H, np.full((len(i), 1), H)]
            if "tilt" in extra:
                cols.append(r["b"][i] * H)
            if "velocity" in extra:
                cols.append(r["v_body"][i] * H)
            rows[a].append(np.concatenate(cols, 1)[keep])
            ys[a].append(dw[keep, a])
    out = []
    for a in range(3):
        A, y = np.concatenate(rows[a]), np.concatenate(ys[a])
        ok = np.all(np.isfinite(A), 1) & np.isfinite(y)
        c, res, _, _ = np.linalg.lstsq(A[ok], y[ok], rcond=None)
        r2 = 1 - res[0] / np.sum((y[ok] - y[ok].mean()) ** 2)
        gain = float(np.mean(np.abs(c[:4]))) / nominal[a]
        out.append((gain, r2))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--git-dir", help="bare git dir of nanodrone-sysid-benchmark")
    src.add_argument("--checkout", help="a working tree of the benchmark at --commit")
    ap.add_argument("--commit", default=nd.DEFAULT_COMMIT)
    ap.add_argument("--steps", type=int, default=5, help="rate change over this many 10 ms steps (default 5)")
    args = ap.parse_args()
    runs = [load(args, r) for r in nd.TRAIN_RUNS]
    r2 = command_speeds2(runs)
    print(f"{len(runs)} training flights; commands -> squared speeds R² {r2:.2f}; rate change over {args.steps} steps")
    print("| input | regressors | roll gain (R²) | pitch gain (R²) | yaw gain (R²) |")
    print("| --- | --- | --- | --- | --- |")
    for source in ("speeds", "commands"):
        for extra in ((), ("tilt",), ("tilt", "velocity")):
            res = study(runs, args.steps, source, extra)
            label = "rotors, rate, constant" + "".join(f", {e}" for e in extra)
            cells = " | ".join(f"{g:.2f} ({r:.2f})" for g, r in res)
            print(f"| {source} | {label} | {cells} |")


if __name__ == "__main__":
    main()
