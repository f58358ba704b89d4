#!/usr/bin/env python3
"""What the rotation needs: the rigid body plus a fitted body moment, scored on the protocol.

Fits, by least squares on the TRAINING runs, the body moment the rotor torques leave unexplained,

    J ω̇ + ω × J ω − τ_rotors(Ω)  ≈  D_v v_body + D_ω ω + c        (3 × 7 coefficients)

(ω̇ by central differences, v_body = Rᵀ v_world, repeated rows and rows next to them left out),
then rolls the rigid body with that moment added over the protocol's windows of the melon runs
(reference_score.py's windows, RK4 at 100 Hz) and prints MAE at 10 / 50 steps next to the plain
rigid body, the hold baseline and the paper's rows. Nothing is learned here but the 21 numbers:
it says whether a velocity-dependent moment is what the Hamiltonian model lacks.

    python tools/benchmark/drag_moment.py --csv DIR [--out fit.json]

DIR is nanodrone.py's output (train/ and test/ CSVs). Needs numpy and pandas.
"""
import argparse
import glob
import json
import os

import numpy as np
import pandas as pd

import reference_score as rs


def fit(files):
    rows, targets = [], []
    for f in files:
        p, v, q, w, u = rs.load_run(f)
        moving = np.ones(len(p), bool)
        same = np.all(np.diff(p, axis=0) == 0, axis=1) & np.all(np.diff(w, axis=0) == 0, axis=1)
        moving[1:] &= ~same
        moving[:-1] &= ~same
        ok = moving[2:] & moving[1:-1] & moving[:-2]
        wd = (w[2:] - w[:-2]) / (2 * rs.DT)
        wc, qc, vc, uc = w[1:-1], q[1:-1], v[1:-1], u[1:-1]
        vb = rs.qrot(rs.qconj(qc), vc)
        resid = wd * rs.J + np.cross(wc, wc * rs.J) - uc[:, 1:]
        x = np.hstack([vb, wc, np.ones((len(wc), 1))])
        good = ok & np.all(np.isfinite(x), 1) & np.all(np.isfinite(resid), 1)
        rows.append(x[good])
        targets.append(resid[good])
    X, Y = np.vstack(rows), np.vstack(targets)
    coef, *_ = np.linalg.lstsq(X, Y, rcond=None)  # (7, 3)
    r2 = 1 - ((Y - X @ coef) ** 2).sum(0) / ((Y - Y.mean(0)) ** 2).sum(0)
    return coef, r2, len(X)


def torque_gain_fit(files, lag):
    """Least squares of the whole J ω̇ + ω × J ω on [τ_rotors(k − lag), v_body, ω, yaw rotor
    acceleration Σ sᵢ Ω̇ᵢ, 1]: the effective gain of the rotor torques (1 if J, k_F, k_M and the
    arm are right) with the rotors' reaction to their own acceleration, and R² per axis."""
    xs, ys = [], []
    for f in files:
        p, v, q, w, u = rs.load_run(f)
        e = pd.read_csv(f)[["erpm1", "erpm2", "erpm3", "erpm4"]].to_numpy(float)
        e[~np.isfinite(e) | (e >= rs.GLITCH)] = np.nan
        om = pd.DataFrame(e).ffill().bfill().to_numpy() * rs.ERPM_TO_RAD_S
        same = np.all(np.diff(p, axis=0) == 0, axis=1) & np.all(np.diff(w, axis=0) == 0, axis=1)
        mv = np.ones(len(p), bool)
        mv[1:] &= ~same
        mv[:-1] &= ~same
        k = np.arange(2 + lag, len(p) - 2)
        ok = mv[k] & mv[k - 1] & mv[k + 1]
        lhs = (w[k + 1] - w[k - 1]) / (2 * rs.DT) * rs.J + np.cross(w[k], w[k] * rs.J)
        yawd = ((om[k + 1 - lag] - om[k - 1 - lag]) / (2 * rs.DT)) @ rs.YAW
        x = np.hstack([u[k - lag, 1:], rs.qrot(rs.qconj(q[k]), v[k]), w[k], yawd[:, None],
                       np.ones((len(k), 1))])
        g = ok & np.all(np.isfinite(x), 1) & np.all(np.isfinite(lhs), 1)
        xs.append(x[g])
        ys.append(lhs[g])
    X, Y = np.vstack(xs), np.vstack(ys)
    coef, *_ = np.linalg.lstsq(X, Y, rcond=None)
    r2 = 1 - ((Y - X @ coef) ** 2).sum(0) / ((Y - Y.mean(0)) ** 2).sum(0)
    return np.diag(coef[:3]), coef[9, 2], r2


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog=__doc__.split("\n\n", 1)[1])
    ap.add_argument("--csv", required=True, help="nanodrone.py's output folder")
    ap.add_argument("--out", help="write the fit and the scores as JSON")
    args = ap.parse_args()
    train = sorted(glob.glob(os.path.join(args.csv, "train", "*.csv")))
    print("effective rotor-torque gain (1 = the published J, k_F, k_M, arm are consistent):")
    for lag in (0, 1, 2, 3):
        gain, yaw_acc, r2t = torque_gain_fit(train, lag)
        print(f"  rotor torque {lag * 10:2d} ms earlier: gains τx τy τz {np.round(gain, 3).tolist()}, "
              f"yaw rotor-acceleration coefficient {yaw_acc:.2e} N·m per rad/s², R² {np.round(r2t, 3).tolist()}")
    coef, r2, n = fit(train)
    print(f"fit on {n} training rows: R² per axis {np.round(r2, 3).tolist()}")
    print("D_v (N·m per m/s, rows x y z of v_body; columns τx τy τz):\n", np.array2string(coef[:3], precision=6))
    print("D_ω (N·m per rad/s):\n", np.array2string(coef[3:6], precision=6))
    print("c (N·m):", np.array2string(coef[6], precision=6))

    def deriv(s, T, tau, full):
        p, v, q, w = s
        if full:
            vb = rs.qrot(rs.qconj(q), v)
            x = np.concatenate([vb, w, np.ones(w.shape[:-1] + (1,))], -1)
            tau = tau + x @ coef
        return base_deriv(s, T, tau, full)

    base_deriv = rs.deriv
    runs = [rs.load_run(f) for f in sorted(glob.glob(os.path.join(args.csv, "test", "*.csv")))]
    result = {"coef": coef.tolist(), "r2": r2.tolist(), "rows": n, "models": {}}
    for name in ("const_vw", "phys_full", "phys_drag"):
        if name == "phys_drag":
            rs.deriv = deriv
            model = "phys_full"
        else:
            rs.deriv = base_deriv
            model = name
        r = rs.evaluate(model, runs, per_run_rows=False)["protocol"]
        result["models"][name] = r
        print(f"{name:10s} " + "  ".join(f"{k} {r[k][9]:.4f}/{r[k][49]:.4f}" for k in ("pos", "vel", "att", "rates")))
    rs.deriv = base_deriv
    for m, d in rs.PAPER.items():
        print(f"paper {m:6s} " + "  ".join(f"{k} {d[k][0]:.4f}/{d[k][1]:.4f}" for k in ("pos", "vel", "att", "rates")))
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
