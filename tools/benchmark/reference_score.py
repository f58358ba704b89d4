#!/usr/bin/env python3
"""Reference implementation of the nanodrone benchmark's multi-step metric.

An independent re-implementation (our code) of the scoring in
nanodrone-sysid-benchmark (utils/metrics_utils.py::compute_errors and the
test/test_*.py window cutting), run on the CSVs written by nanodrone.py, for
a few baselines that need no training. It is the cross-check for
`host-train score`.

Protocol (as the benchmark does it):
  * test runs: every CSV in <csv>/test (melon run1, run4, run5; the benchmark's
    published data/test has three melon runs, the corrupt run2 excluded);
  * windows: in each run of N rows, every start i = 0 .. N-51 (stride 1, N-50
    windows); the model gets the state x[i] and the inputs u[i .. i+49]
    (u[i+k] is held over step k) and predicts x[i+1 .. i+50];
  * error at horizon h (1..50) = mean over windows of
      pos   ||p_pred - p||_2 (m)          vel   ||v_pred - v||_2 (m/s)
      att   geodesic angle 2 atan2(|vec(q^-1 q_pred)|, |w|) (rad)
      rates ||w_pred - w||_2 (rad/s)
  * "protocol" aggregation replicates the benchmark exactly: the windows of
    the three runs are concatenated, and the truth for window j at horizon h
    is taken as the 1-step truth of window j+h-1 (DataFrame.shift), so the
    last h-1 windows of run k are compared with the first states of run k+1,
    and the last h-1 windows of the last run are dropped;
    "clean" aggregation compares each window with its own run's x[i+h]
    (every window, every horizon). Both are written; they differ by <1 %.
  * motor speeds: eRPM * 2 pi / 360 (rad/s); missing values (nan) and
    glitches (>= 3e5 eRPM) are replaced by the previous valid value.

Models:
  zoh         every state held at x[i] (the benchmark's "naive" baseline)
  const_vw    constant world velocity and constant body rates, integrated
              (p += v dt, q follows the constant body rate)
  phys_paper  the benchmark's published physics model: thrust kF sum W^2
              (kF 3.72e-8, clamped to [0, 2 m g]) along body z, gravity,
              RK4 at 100 Hz, and -- as in the benchmark's models.py --
              zero angular acceleration (body rates held)
  phys_full   rigid body with the published constants: thrust and torques
              from kF, kM, arm 0.0353 m (X layout, hamflight numbering,
              yaw signs - + - +), J = diag(2.3951e-5, 2.3951e-5, 3.2347e-5),
              Euler equation, RK4 at 100 Hz

With `--dataset DIR` (a `host-train import` of the test CSVs) it scores the
windows `host-train score` scores instead: continuous stretches of the
imported flights only (repeated states dropped, take-off and landing
trimmed), the wrench columns as the input. That is the like-for-like check
of the Rust numbers (zoh = zero-order, const_vw = hold, phys_full = nominal);
the benchmark protocol is the `--csv` mode.

Dependencies: numpy, pandas. Example:
    /work/bench-venv/bin/python tools/benchmark/reference_score.py \\
        --csv /work/nanodrone-csv --out /work/nanodrone-csv/reference_score.json
"""

import argparse
import glob
import json
import os

import numpy as np
import pandas as pd

DT = 0.01
H = 50
M, G = 0.045, 9.81
J = np.array([2.3951e-5, 2.3951e-5, 3.2347e-5])
ARM = 0.0353
KF, KM = 3.7178e-8, 7.728e-11
KF_PAPER = 3.72e-8
TW_PAPER = 2.0
YAW = np.array([-1.0, 1.0, -1.0, 1.0])
ERPM_TO_RAD_S = 2 * np.pi / 360
GLITCH = 3.0e5

PAPER = {  # arXiv 2512.14450, held-out melon, MAE at 10 / 50 steps
    "physics": {"pos": (0.0126, 0.127), "vel": (0.057, 0.578), "att": (0.0205, 0.254), "rates": (0.36, 0.88)},
    "mlp": {"pos": (0.031, 0.171), "vel": (0.089, 0.572), "att": (0.033, 0.227), "rates": (0.59, 0.90)},
    "hybrid": {"pos": (0.017, 0.112), "vel": (0.061, 0.556), "att": (0.038, 0.231), "rates": (0.49, 0.60)},
    "lstm": {"pos": (0.039, 0.257), "vel": (0.118, 0.741), "att": (0.037, 0.233), "rates": (0.43, 1.24)},
}


# ---------------------------------------------------------------- quaternions (w, x, y, z)
def qmul(a, b):
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], -1)


def qconj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def qrot(q, v):
    """Rotate body vector v to world by q (body->world)."""
    qv = np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], -1)
    return qmul(qmul(q, qv), qconj(q))[..., 1:]


def qdot(q, w):
    return 0.5 * qmul(q, np.concatenate([np.zeros(w.shape[:-1] + (1,)), w], -1))


def qexp(r):
    """Quaternion of the rotation vector r (body frame)."""
    a = np.linalg.norm(r, axis=-1, keepdims=True)
    s = np.where(a > 1e-12, np.sin(a / 2) / np.maximum(a, 1e-12), 0.5)
    return np.concatenate([np.cos(a / 2), s * r], -1)


def qnorm(q):
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def geodesic(qt, qp):
    r = qmul(qconj(qt), qp)
    return 2 * np.arctan2(np.linalg.norm(r[..., 1:], axis=-1), np.abs(r[..., 0]))


# ---------------------------------------------------------------- models
def wrench_of_speeds(om):
    """[T, tau_x, tau_y, tau_z] of rotor speeds (rad/s), published constants, hamflight numbering."""
    o2 = om**2
    T = KF * o2.sum(-1)
    tx = KF * ARM * ((o2[..., 2] + o2[..., 3]) - (o2[..., 0] + o2[..., 1]))
    ty = KF * ARM * ((o2[..., 1] + o2[..., 2]) - (o2[..., 0] + o2[..., 3]))
    tz = KM * (o2 @ YAW)
    return np.stack([T, tx, ty, tz], -1)


def forces(u, full):
    """Thrust and torques of a wrench row u = [T, tau] for the two physics models."""
    if not full:  # the benchmark's model: its own k_F, thrust clamped, no torques
        T = np.clip(u[..., 0] * (KF_PAPER / KF), 0.0, TW_PAPER * M * G)
        return T, np.zeros(u.shape[:-1] + (3,))
    return u[..., 0], u[..., 1:]


def deriv(s, T, tau, full):
    p, v, q, w = s
    fb = np.zeros(v.shape)
    fb[..., 2] = T / M
    a = qrot(q, fb) - np.array([0.0, 0.0, G])
    if full:
        wd = (tau - np.cross(w, w * J)) / J
    else:
        wd = np.zeros_like(w)
    return v, a, qdot(q, w), wd


def rk4(s, T, tau, full):
    def add(s, k, h):
        p, v, q, w = s
        return (p + h * k[0], v + h * k[1], qnorm(q + h * k[2]), w + h * k[3])
    k1 = deriv(s, T, tau, full)
    k2 = deriv(add(s, k1, DT / 2), T, tau, full)
    k3 = deriv(add(s, k2, DT / 2), T, tau, full)
    k4 = deriv(add(s, k3, DT), T, tau, full)
    p, v, q, w = s
    inc = [(a + 2 * b + 2 * c + d) * (DT / 6) for a, b, c, d in zip(k1, k2, k3, k4)]
    return (p + inc[0], v + inc[1], qnorm(q + inc[2]), w + inc[3])


def rollout(model, x0, om):
    """x0: tuple of (W,3),(W,3),(W,4),(W,3); om: (W,H,4) wrench rows [T, tau]. Returns H states."""
    out = []
    s = x0
    for k in range(H):
        if model == "zoh":
            pass
        elif model == "const_vw":
            p, v, q, w = s
            s = (p + DT * v, v, qnorm(qmul(q, qexp(w * DT))), w)  # exact for a constant body rate
        else:
            full = model == "phys_full"
            T, tau = forces(om[:, k], full)
            s = rk4(s, T, tau, full)
        out.append(s)
    return out


# ---------------------------------------------------------------- data
def load_run(path):
    c = pd.read_csv(path)
    p = c[["px_m", "py_m", "pz_m"]].to_numpy(float)
    v = c[["vx_world_m_s", "vy_world_m_s", "vz_world_m_s"]].to_numpy(float)
    q = qnorm(c[["qw", "qx", "qy", "qz"]].to_numpy(float))
    w = c[["wx_rad_s", "wy_rad_s", "wz_rad_s"]].to_numpy(float)
    e = c[["erpm1", "erpm2", "erpm3", "erpm4"]].to_numpy(float)
    e[~np.isfinite(e) | (e >= GLITCH)] = np.nan
    e = pd.DataFrame(e).ffill().bfill().to_numpy()
    return p, v, q, w, wrench_of_speeds(e * ERPM_TO_RAD_S)


def rot_to_quat(R):
    """(w, x, y, z) of rotation matrices (N,3,3), w >= 0."""
    tr = np.trace(R, axis1=1, axis2=2)
    q = np.empty((len(R), 4))
    q[:, 0] = np.sqrt(np.maximum(1.0 + tr, 1e-12)) / 2
    q[:, 1] = (R[:, 2, 1] - R[:, 1, 2]) / (4 * q[:, 0])
    q[:, 2] = (R[:, 0, 2] - R[:, 2, 0]) / (4 * q[:, 0])
    q[:, 3] = (R[:, 1, 0] - R[:, 0, 1]) / (4 * q[:, 0])
    return qnorm(q)  # tilts here stay far below 180 deg, where this branch is exact


def load_dataset(d):
    """Continuous stretches of a hamflight dataset (import output), as `host-train score`
    cuts them: per realization and flight, split where the time step is not 1/sample_hz
    within 10 % (dropped repeated states, gaps)."""
    man = json.load(open(os.path.join(d, "manifest.json")))
    dt = 1.0 / man["sample_hz"]
    segs, names = [], []
    for r in man["realizations"]:
        c = pd.read_csv(os.path.join(d, r["file"]))
        for f, g in c.groupby("flight"):
            t = g["t_s"].to_numpy()
            cut = np.r_[0, np.nonzero(np.abs(np.diff(t) - dt) > 0.1 * dt)[0] + 1, len(t)]
            R = g[["r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32", "r33"]].to_numpy().reshape(-1, 3, 3)
            p = g[["px", "py", "pz"]].to_numpy()
            vb = g[["vx", "vy", "vz"]].to_numpy()
            v = np.einsum("nij,nj->ni", R, vb)
            w = g[["wx", "wy", "wz"]].to_numpy()
            u = g[["f_n", "tau_x_nm", "tau_y_nm", "tau_z_nm"]].to_numpy()
            q = rot_to_quat(R)
            for a, b in zip(cut[:-1], cut[1:]):
                if b - a >= H + 1:
                    segs.append((p[a:b], v[a:b], q[a:b], w[a:b], u[a:b]))
                    names.append(f"{os.path.basename(r['source_file'])}#{f}[{a}:{b}]")
    return segs, names


def score_run(model, run):
    """Per-run predictions: errors[h-1] arrays over windows (clean), and the
    predicted states, for the protocol aggregation."""
    p, v, q, w, u = run
    N = len(p)
    W = N - H
    idx = np.arange(W)
    x0 = (p[idx], v[idx], q[idx], w[idx])
    us = np.stack([u[idx + k] for k in range(H)], 1)
    preds = rollout(model, x0, us)
    return preds


def errors(pred, truth):
    pp, pv, pq, pw = pred
    tp, tv, tq, tw = truth
    return dict(pos=np.linalg.norm(pp - tp, axis=-1), vel=np.linalg.norm(pv - tv, axis=-1),
                att=geodesic(tq, pq), rates=np.linalg.norm(pw - tw, axis=-1))


def evaluate(model, runs, per_run_rows=True):
    clean = {k: np.zeros(H) for k in ("pos", "vel", "att", "rates")}
    counts = 0
    pooled_pred = [[] for _ in range(H)]
    pooled_t1 = []
    for run in runs:
        p, v, q, w, _ = run
        W = len(p) - H
        preds = score_run(model, run)
        for h in range(1, H + 1):
            t = (p[h:h + W], v[h:h + W], q[h:h + W], w[h:h + W])
            e = errors(preds[h - 1], t)
            for k in clean:
                clean[k][h - 1] += e[k].sum()
            pooled_pred[h - 1].append(preds[h - 1])
        counts += W
        pooled_t1.append((p[1:1 + W], v[1:1 + W], q[1:1 + W], w[1:1 + W]))
    clean = {k: (v / counts).tolist() for k, v in clean.items()}
    per_run = []
    for run in (runs if per_run_rows else []):  # the clean errors of each run alone
        p, v, q, w, _ = run
        W = len(p) - H
        preds = score_run(model, run)
        e = [errors(preds[h - 1], (p[h:h + W], v[h:h + W], q[h:h + W], w[h:h + W])) for h in range(1, H + 1)]
        per_run.append({k: [float(x[k].mean()) for x in e] for k in clean})
    # protocol: concatenate windows, shift the 1-step truth
    t1 = tuple(np.concatenate([t[i] for t in pooled_t1]) for i in range(4))
    proto = {k: [] for k in clean}
    for h in range(1, H + 1):
        pr = tuple(np.concatenate([pp[i] for pp in pooled_pred[h - 1]]) for i in range(4))
        n = len(t1[0]) - (h - 1)
        e = errors(tuple(x[:n] for x in pr), tuple(x[h - 1:h - 1 + n] for x in t1))
        for k in proto:
            proto[k].append(float(e[k].mean()))
    return dict(clean=clean, protocol=proto, windows=counts, per_run=per_run)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--csv", help="folder written by nanodrone.py (uses <csv>/test/*.csv): the benchmark protocol")
    src.add_argument("--dataset", help="a hamflight dataset (host-train import of the test CSVs): the windows "
                     "`host-train score` uses (continuous stretches only), for a like-for-like cross-check")
    ap.add_argument("--models", default="zoh,const_vw,phys_paper,phys_full")
    ap.add_argument("--out", help="write all horizons as JSON")
    args = ap.parse_args()

    if args.csv:
        files = sorted(glob.glob(os.path.join(args.csv, "test", "*.csv")))
        runs = [load_run(f) for f in files]
        names = [os.path.basename(f)[:-4] for f in files]
        print("test runs:", ", ".join(names), f"; windows per run: {[len(r[0]) - H for r in runs]}")
    else:
        runs, names = load_dataset(args.dataset)
        print(f"dataset {args.dataset}: {len(runs)} continuous stretches of >= {H + 1} states, "
              f"{sum(len(r[0]) - H for r in runs)} windows (only the 'clean' rows are meaningful here)")
    result = dict(runs=names, horizon=H, dt=DT,
                  windows_per_run=[len(r[0]) - H for r in runs], models={}, paper=PAPER)
    hdr = f"{'model':12s} {'agg':8s}  {'pos m':>15s}  {'vel m/s':>15s}  {'att rad':>15s}  {'rates rad/s':>15s}   (h=10 / h=50)"
    print(hdr)
    for m in args.models.split(","):
        r = evaluate(m, runs, per_run_rows=bool(args.csv))
        result["models"][m] = r
        for agg in ("protocol", "clean"):
            d = r[agg]
            print(f"{m:12s} {agg:8s}  " + "  ".join(f"{d[k][9]:7.4f}/{d[k][49]:7.4f}" for k in ("pos", "vel", "att", "rates")))
    for m, d in PAPER.items():
        print(f"{'paper ' + m:21s}  " + "  ".join(f"{d[k][0]:7.4f}/{d[k][1]:7.4f}" for k in ("pos", "vel", "att", "rates")))
    if "phys_paper" in result["models"] and args.csv:
        d = result["models"]["phys_paper"]["protocol"]
        print("phys_paper vs paper physics (ours/paper - 1): " + "  ".join(
            f"{k} {100*(d[k][9]/PAPER['physics'][k][0]-1):+.0f}%/{100*(d[k][49]/PAPER['physics'][k][1]-1):+.0f}%"
            for k in ("pos", "vel", "att", "rates")))
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
