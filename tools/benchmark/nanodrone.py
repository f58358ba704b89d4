#!/usr/bin/env python3
"""Convert the nanodrone-sysid-benchmark flights into hamflight import CSVs.

The benchmark ("Nonlinear System Identification for a Nano-drone Benchmark",
Busetto et al., arXiv 2512.14450, github.com/idsia-robotics/nanodrone-sysid-benchmark)
has no licence, so nothing of it is copied into this repository: this script
reads the parquet files straight out of *your* clone (a bare git dir plus a
commit, or a checked-out folder) and writes CSVs to a folder you choose, which
must be outside the hamflight repository.

Input:  <repo>/control_engineering_practice/data/real/new/parquets/<run>.parquet
        (the unprocessed 100 Hz flights; the `processed/` parquets have a
        constant offset subtracted from some shared columns, do not use them).
Output: <out>/train/<run>.csv, <out>/test/<run>.csv, <out>/vehicle.toml

Split (the benchmark protocol, see tools/benchmark/README.md):
    train: square run1-5, random1 run1-4, random2 run1-4, multisine run1-4
    test:  melon run1, run4, run5   (run2 is corrupt and skipped; run3 was
           never exported to parquet). `--with-corrupt` also writes
           melon run2 to <out>/excluded/ for inspection.

CSV columns (SI, one header line):
    t_s                          time from the run's start (uniform 0.01 s grid)
    px_m,py_m,pz_m               position, world frame (z up)
    qw,qx,qy,qz                  attitude quaternion, body -> world
                                 (benchmark stores (x, y, z, w); re-ordered only)
    vx_world_m_s,..vz_world_m_s  velocity, world frame
    wx_rad_s,wy_rad_s,wz_rad_s   body rates
    erpm1..erpm4                 RAW motor speeds, electrical RPM, hamflight
                                 numbering (1 front-right, 2 back-right,
                                 3 back-left, 4 front-left) = the benchmark's
                                 m1..m4. Not cleaned: glitches (up to 6e6) and
                                 dropped values (written as `nan`) are kept.
                                 Omega[rad/s] = eRPM * 2 pi / 360 (12 poles).
    ax_m_s2,ay_m_s2,az_m_s2      specific force in the BODY frame: the
                                 benchmark's world-frame accelerometer column
                                 (which includes gravity: ~ +9.81 on z at
                                 hover) rotated by R^T.
With --loop-out DIR, also a closed-loop log per run (DIR/train/<run>.csv,
DIR/test/<run>.csv) for replaying the onboard Mellinger controller
(`host-train onboard`): the state columns above (t_s..wz_rad_s, erpm1..4),
then the reference ref_px_m,ref_py_m,ref_pz_m (x_r..z_r),
ref_vx_m_s,ref_vy_m_s,ref_vz_m_s (vx_r..vz_r), ref_yaw_rad (yaw_r), the
onboard controller's output cmd1..cmd4 (m1_thrust..m4_thrust, PWM/65535,
0..1), vbat_v (Vbat) and, as they are, the logged wrench columns
log_thrust, log_torque_roll, log_torque_pitch, log_torque_yaw (thrust,
torque_roll, torque_pitch, torch_yaw). The default output is unchanged.

Rows are written as they are: repeated states (dropped packets filled by
nearest-neighbour resampling) are NOT removed; the importer detects them.

Dependencies: Python >= 3.9, numpy, pandas, pyarrow, and `git` on PATH when
reading from a bare git dir. For example:
    python3 -m venv /work/bench-venv
    /work/bench-venv/bin/pip install numpy pandas pyarrow

Example:
    /work/bench-venv/bin/python tools/benchmark/nanodrone.py \\
        --git-dir /work/.mirror/idsia-robotics+nanodrone-sysid-benchmark/repo \\
        --commit b0cf4b3144e84716546ab8bb028d7eacc42475c2 \\
        --out /work/nanodrone-csv
"""

import argparse
import io
import os
import subprocess
import sys

import numpy as np
import pandas as pd

PARQUET_DIR = "control_engineering_practice/data/real/new/parquets"
DEFAULT_COMMIT = "b0cf4b3144e84716546ab8bb028d7eacc42475c2"

TRAIN_RUNS = (
    [f"square_20251017_run{i}" for i in range(1, 6)]
    + [f"random1_20251017_run{i}" for i in range(1, 5)]
    + [f"random2_20251017_run{i}" for i in range(1, 5)]
    + [f"multisine_20251017_run{i}" for i in range(1, 5)]
)
TEST_RUNS = [f"melon_20251017_run{i}" for i in (1, 4, 5)]
EXCLUDED_RUNS = ["melon_20251017_run2"]  # dp/dt and v disagree by metres per second

# Published vehicle constants (Crazyflie 2.1 Brushless, the paper's table).
MASS = 0.045
G = 9.81
INERTIA = (2.3951e-5, 2.3951e-5, 3.2347e-5)
ARM_XY = 0.0353
KF = 3.7178e-8
KM = 7.728e-11
ERPM_TO_RAD_S = 2.0 * np.pi / 360.0  # 6 pole pairs, /60 s per min
GLITCH_ERPM = 3.0e5  # far above the 1.45e5 eRPM the motors reach in flight

STATE_COLS = ["x", "y", "z", "qx", "qy", "qz", "qw", "vx", "vy", "vz", "wx", "wy", "wz"]


# --------------------------------------------------------------------------
# quaternion helpers, (w, x, y, z) arrays of shape (N, 4)
# --------------------------------------------------------------------------
def quat_to_rot(q):
    """Rotation matrices (N,3,3) of unit quaternions q=(w,x,y,z), body->world."""
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        1,
    )


def quat_mul(a, b):
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def quat_conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


# --------------------------------------------------------------------------
def read_run(args, run):
    rel = f"{PARQUET_DIR}/{run}.parquet"
    if args.checkout:
        return pd.read_parquet(os.path.join(args.checkout, rel))
    blob = subprocess.run(
        ["git", f"--git-dir={args.git_dir}", "show", f"{args.commit}:{rel}"],
        check=True,
        capture_output=True,
    ).stdout
    return pd.read_parquet(io.BytesIO(blob))


def convert(df):
    """Benchmark dataframe -> hamflight CSV dataframe (no cleaning)."""
    q = df[["qw", "qx", "qy", "qz"]].to_numpy(float)
    R = quat_to_rot(q / np.linalg.norm(q, axis=1, keepdims=True))
    a_world = df[["ax", "ay", "az"]].to_numpy(float)
    a_body = np.einsum("nji,nj->ni", R, a_world)  # R^T a
    out = pd.DataFrame(
        {
            "t_s": df["t"].to_numpy(float) - float(df["t"].iloc[0]),
            "px_m": df["x"],
            "py_m": df["y"],
            "pz_m": df["z"],
            "qw": df["qw"],
            "qx": df["qx"],
            "qy": df["qy"],
            "qz": df["qz"],
            "vx_world_m_s": df["vx"],
            "vy_world_m_s": df["vy"],
            "vz_world_m_s": df["vz"],
            "wx_rad_s": df["wx"],
            "wy_rad_s": df["wy"],
            "wz_rad_s": df["wz"],
            "erpm1": df["m1_erpm"],
            "erpm2": df["m2_erpm"],
            "erpm3": df["m3_erpm"],
            "erpm4": df["m4_erpm"],
            "ax_m_s2": a_body[:, 0],
            "ay_m_s2": a_body[:, 1],
            "az_m_s2": a_body[:, 2],
        }
    )
    return out


LOOP_REF = [("ref_px_m", "x_r"), ("ref_py_m", "y_r"), ("ref_pz_m", "z_r"),
            ("ref_vx_m_s", "vx_r"), ("ref_vy_m_s", "vy_r"), ("ref_vz_m_s", "vz_r"),
            ("ref_yaw_rad", "yaw_r")]


def loop_log(c, df):
    """The closed-loop log: the converted state (no accelerometer), the reference, the
    onboard controller's motor commands and the battery voltage."""
    out = c.drop(columns=["ax_m_s2", "ay_m_s2", "az_m_s2"]).copy()
    for name, col in LOOP_REF:
        out[name] = df[col].to_numpy(float)
    for i in range(1, 5):
        out[f"cmd{i}"] = df[f"m{i}_thrust"].to_numpy(float)
    out["vbat_v"] = df["Vbat"].to_numpy(float)
    # the logged wrench columns as they are (for the trust table of `host-train onboard`)
    for name, col in [("log_thrust", "thrust"), ("log_torque_roll", "torque_roll"),
                      ("log_torque_pitch", "torque_pitch"), ("log_torque_yaw", "torch_yaw")]:
        out[name] = df[col].to_numpy(float)
    return out


def sanity(run, df, c):
    """One line of checks per run; returns a dict of the numbers."""
    dt = float(np.median(np.diff(c["t_s"])))
    p = c[["px_m", "py_m", "pz_m"]].to_numpy()
    v = c[["vx_world_m_s", "vy_world_m_s", "vz_world_m_s"]].to_numpy()
    q = c[["qw", "qx", "qy", "qz"]].to_numpy()
    w = c[["wx_rad_s", "wy_rad_s", "wz_rad_s"]].to_numpy()
    e = c[["erpm1", "erpm2", "erpm3", "erpm4"]].to_numpy()
    fb = c[["ax_m_s2", "ay_m_s2", "az_m_s2"]].to_numpy()
    st = df[STATE_COLS].to_numpy()
    rep = np.r_[False, np.all(st[1:] == st[:-1], axis=1)]

    # velocity: central difference of p over the rows that are not repeats
    # of the row before or after (repeats distort a finite difference)
    ok = ~rep[1:-1] & ~rep[2:]
    dp = (p[2:] - p[:-2]) / (2 * dt)
    dv_rms = float(np.sqrt(np.mean(np.sum((dp - v[1:-1])[ok] ** 2, 1))))
    v_rms = float(np.sqrt(np.mean(np.sum(v**2, 1))))

    # rates: body rates from q^-1 dq/dt vs world rates from dq/dt q^-1
    qs = np.where((np.sum(q[2:] * q[:-2], 1) < 0)[:, None], -q[2:], q[2:])
    qd = (qs - q[:-2]) / (2 * dt)
    wb = 2 * quat_mul(quat_conj(q[1:-1]), qd)[:, 1:]
    ww = 2 * quat_mul(qd, quat_conj(q[1:-1]))[:, 1:]
    wm = w[1:-1]
    body_err = float(np.sqrt(np.mean(np.sum((wb - wm)[ok] ** 2, 1))))
    world_err = float(np.sqrt(np.mean(np.sum((ww - wm)[ok] ** 2, 1))))
    w_rms = float(np.sqrt(np.mean(np.sum(wm**2, 1))))

    # specific force: body z vs sum kF Omega^2 / m, over clean flying rows
    om = e * ERPM_TO_RAD_S
    good = np.all(np.isfinite(e) & (e < GLITCH_ERPM) & (e > 1.0e4), 1)
    fz_motor = KF * np.sum(om**2, 1) / MASS
    ratio = float(np.median(fb[good, 2] / fz_motor[good])) if good.any() else float("nan")
    hover = float(np.median(fb[good, 2])) if good.any() else float("nan")
    lateral = float(np.sqrt(np.mean(np.sum(fb[good, :2] ** 2, 1)))) if good.any() else float("nan")
    glitches = e[np.isfinite(e) & (e >= GLITCH_ERPM)]
    r = dict(
        run=run,
        rows=len(c),
        dt=dt,
        repeated=float(rep.mean()),
        v_fd_rms=dv_rms,
        v_rms=v_rms,
        w_body_rms=body_err,
        w_world_rms=world_err,
        w_rms=w_rms,
        fz_median=hover,
        fxy_rms=lateral,
        fz_over_motor=ratio,
        erpm_nan=int(np.sum(~np.isfinite(e))),
        glitches=int(glitches.size),
        glitch_max=float(glitches.max()) if glitches.size else 0.0,
        tw_max=float(np.max(KF * np.sum(om[good] ** 2, 1)) / (MASS * G)) if good.any() else float("nan"),
    )
    print(
        f"{run:28s} {r['rows']:5d} rows dt={dt:.4f}s repeat={100*r['repeated']:4.1f}% "
        f"|dp/dt-v|={dv_rms:.3f} (|v| {v_rms:.2f}) m/s  "
        f"|w_q-w| body={body_err:.3f} world={world_err:.3f} (|w| {w_rms:.2f}) rad/s  "
        f"f_body z={hover:.2f} xy={lateral:.2f} fz/(kF sum W^2/m)={ratio:.3f}  "
        f"eRPM nan={r['erpm_nan']} glitches={r['glitches']} (max {r['glitch_max']:.3g})"
    )
    return r


def main():
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="See the module docstring (or tools/benchmark/README.md) for the columns, "
        "the split and the dependencies.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--git-dir", help="bare git dir of nanodrone-sysid-benchmark (read with git show)")
    src.add_argument("--checkout", help="a checked-out working tree of the benchmark at the right commit")
    ap.add_argument("--commit", default=DEFAULT_COMMIT, help="commit holding the real parquets (default %(default)s)")
    ap.add_argument("--out", required=True, help="output folder (outside the hamflight repository)")
    ap.add_argument("--with-corrupt", action="store_true", help="also write melon run2 to <out>/excluded/")
    ap.add_argument("--motor-tau-s", type=float, default=None,
                    help="motor time constant (command -> measured speed, analyze.py finds 0.0325) to write into "
                         "vehicle.toml; omitted by default, because the CSVs carry measured speeds that must not be lagged again")
    ap.add_argument("--loop-out", default=None,
                    help="also write closed-loop logs (state, reference, cmd1..4 = m*_thrust, vbat_v) "
                         "for `host-train onboard` to this folder (train/ and test/, outside the repository)")
    args = ap.parse_args()

    out = os.path.abspath(args.out)
    here = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    loop_out = os.path.abspath(args.loop_out) if args.loop_out else None
    for d in [out] + ([loop_out] if loop_out else []):
        if d == here or d.startswith(here + os.sep):
            sys.exit(f"refusing to write benchmark data inside the repository ({here}); pick another folder than {d}")

    groups = [("train", TRAIN_RUNS), ("test", TEST_RUNS)]
    if args.with_corrupt:
        groups.append(("excluded", EXCLUDED_RUNS))
    reports = []
    for split, runs in groups:
        os.makedirs(os.path.join(out, split), exist_ok=True)
        print(f"== {split}")
        for run in runs:
            df = read_run(args, run)
            c = convert(df)
            c.to_csv(os.path.join(out, split, run + ".csv"), index=False, float_format="%.9g", na_rep="nan")
            if loop_out:
                os.makedirs(os.path.join(loop_out, split), exist_ok=True)
                loop_log(c, df).to_csv(os.path.join(loop_out, split, run + ".csv"), index=False,
                                       float_format="%.9g", na_rep="nan")
            reports.append((split, sanity(run, df, c)))

    tw = max(r["tw_max"] for s, r in reports if s != "excluded")
    tau_line = (
        f"motor_tau_s = {args.motor_tau_s:.4f}       # command -> MEASURED rotor speed lag (analyze.py); the eRPM columns are measured: do not lag them again\n"
        if args.motor_tau_s is not None
        else ""
    )
    with open(os.path.join(out, "vehicle.toml"), "w") as f:
        f.write(
            'name = "crazyflie-2.1-brushless (nanodrone-sysid-benchmark)"\n'
            f"mass_kg = {MASS}\n"
            f"gravity_m_s2 = {G}\n"
            f"inertia_kg_m2 = [{INERTIA[0]:.5g}, {INERTIA[1]:.5g}, {INERTIA[2]:.5g}]\n"
            f"arm_xy_m = {ARM_XY}            # rotor offset along each body axis, X layout, rotors at (±a, ±a)\n"
            f"kf_n_per_rad_s2 = {KF:.5g}  # thrust per squared rotor speed\n"
            f"km_nm_per_rad_s2 = {KM:.4g} # reaction torque per squared rotor speed\n"
            f"thrust_to_weight = {tw:.2f}      # max over the flights of sum kF Omega^2 / (m g), glitches excluded\n"
            + tau_line
        )
    # totals
    n = sum(r["rows"] for _, r in reports if _ != "excluded")
    rep = sum(r["repeated"] * r["rows"] for s, r in reports if s == "train") / sum(
        r["rows"] for s, r in reports if s == "train"
    )
    print(f"== {n} rows written (train+test); train rows repeating the previous state: {100*rep:.1f}%;"
          f" max thrust/weight {tw:.2f}; vehicle.toml and CSVs in {out}")


if __name__ == "__main__":
    main()
