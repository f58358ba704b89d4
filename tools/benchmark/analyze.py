#!/usr/bin/env python3
"""Data facts of the nanodrone-sysid-benchmark flights (numbers for README.md).

Reads the CSVs written by nanodrone.py (and, for the raw timestamps, the
benchmark parquets through nanodrone.read_run) and prints:

  * sample rate and jitter of the raw ROS timestamps behind the 0.01 s grid,
  * repeated states, eRPM dropouts (nan) and glitches per run,
  * thrust-less descents (flying rows with sum kF Omega^2 well below m g),
  * p/v and q/omega consistency, including the best time shift,
  * rotor-speed torques vs the torque the body's angular acceleration needs:
    tau_req = J dw/dt + w x J w against tau_mot built from kF/kM Omega^2,
    fitted with a first-order lag tau_f' = (tau_mot - tau_f)/T (grid over T,
    least-squares gain per axis), and a few alternative lever arms / inertias /
    motor numberings to explain the gain.

Only analysis: the CSVs are not modified. Dependencies: numpy, pandas,
pyarrow (as nanodrone.py). Example:

    /work/bench-venv/bin/python tools/benchmark/analyze.py --csv /work/nanodrone-csv \\
        --git-dir /work/.mirror/idsia-robotics+nanodrone-sysid-benchmark/repo --out facts.json
"""

import argparse
import glob
import json
import os
import sys

import numpy as np
import pandas as pd

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import nanodrone as nd  # noqa: E402

DT = 0.01
J = np.array(nd.INERTIA)


def clean_erpm(e):
    """Analysis-only cleaning: glitches and dropouts -> previous valid value."""
    e = e.copy()
    bad = ~np.isfinite(e) | (e >= nd.GLITCH_ERPM)
    e[bad] = np.nan
    return pd.DataFrame(e).ffill().bfill().to_numpy()


def motor_torques(om2, arm=nd.ARM_XY, kf=nd.KF, km=nd.KM, yaw_signs=(-1, 1, -1, 1), perm=(0, 1, 2, 3)):
    """Body torques of squared rotor speeds, hamflight numbering 1 FR, 2 BR, 3 BL, 4 FL."""
    o = om2[:, list(perm)]
    tx = kf * arm * ((o[:, 2] + o[:, 3]) - (o[:, 0] + o[:, 1]))  # left rotors (y>0) roll +x
    ty = kf * arm * ((o[:, 1] + o[:, 2]) - (o[:, 0] + o[:, 3]))  # back rotors (x<0) pitch +y
    tz = km * (o @ np.array(yaw_signs, float))
    return np.stack([tx, ty, tz], 1)


def lag_filter(u, T):
    if T <= 0:
        return u
    a = 1.0 - np.exp(-DT / T)
    y = np.empty_like(u)
    y[0] = u[0]
    for n in range(1, len(u)):
        y[n] = y[n - 1] + a * (u[n - 1] - y[n - 1])  # zero-order hold, input at n-1 acts over [n-1, n]
    return y


def smooth(x, k=5):
    if k <= 1:
        return x
    ker = np.ones(k) / k
    return np.stack([np.convolve(x[:, i], ker, mode="same") for i in range(x.shape[1])], 1)


def load(csvdir, split):
    runs = {}
    for f in sorted(glob.glob(os.path.join(csvdir, split, "*.csv"))):
        runs[os.path.basename(f)[:-4]] = pd.read_csv(f)
    return runs


def torque_data(c):
    """(tau_req, tau-inputs: om2, mask) for one run, mid-point aligned."""
    w = c[["wx_rad_s", "wy_rad_s", "wz_rad_s"]].to_numpy()
    st = c[["px_m", "py_m", "pz_m", "qw", "qx", "qy", "qz", "vx_world_m_s", "vy_world_m_s",
            "vz_world_m_s", "wx_rad_s", "wy_rad_s", "wz_rad_s"]].to_numpy()
    rep = np.r_[False, np.all(st[1:] == st[:-1], 1)]
    e = clean_erpm(c[["erpm1", "erpm2", "erpm3", "erpm4"]].to_numpy(float))
    om2 = (e * nd.ERPM_TO_RAD_S) ** 2
    wdot = np.zeros_like(w)
    wdot[1:-1] = (w[2:] - w[:-2]) / (2 * DT)
    Jw = w * J
    req = wdot * J + np.cross(w, Jw)
    ok = np.zeros(len(w), bool)
    ok[1:-1] = ~rep[1:-1] & ~rep[2:]
    ok &= np.sum(om2, 1) * nd.KF > 0.3 * nd.MASS * nd.G  # flying
    ok[:50] = False  # start transients
    return req, om2, ok


def fit_gain(req, mot, ok):
    """Least-squares gain k (req ~ k mot) per axis, the R^2, and the reverse-regression gain."""
    out = []
    for i in range(3):
        x, y = mot[ok, i], req[ok, i]
        k = float(x @ y / (x @ x))
        r2 = 1.0 - float(np.sum((y - k * x) ** 2) / np.sum((y - y.mean()) ** 2))
        krev = float((y @ y) / (x @ y))  # regress mot on req, inverted (bias the other way)
        corr = float(np.corrcoef(x, y)[0, 1])
        out.append(dict(k=k, r2=r2, k_rev=krev, corr=corr))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--csv", required=True, help="folder written by nanodrone.py")
    ap.add_argument("--git-dir", help="benchmark git dir, for the raw timestamps (optional)")
    ap.add_argument("--checkout", help="or a checkout of it")
    ap.add_argument("--commit", default=nd.DEFAULT_COMMIT)
    ap.add_argument("--out", help="write the numbers as JSON here")
    args = ap.parse_args()
    facts = {}

    train = load(args.csv, "train")
    test = load(args.csv, "test")
    allruns = {**train, **test}

    # ---- timing -----------------------------------------------------------
    if args.git_dir or args.checkout:
        print("== raw ROS timestamps behind the resampled 0.01 s grid (median dt, std dt, share of dt<=1 ms, max gap)")
        tim = {}
        for run in allruns:
            df = nd.read_run(args, run)
            row = {}
            for col, name in [("ros_timestamp_x", "state"), ("ros_timestamp_y", "motors"), ("ros_timestamp", "accel")]:
                d = np.diff(df[col].to_numpy(float))
                row[name] = dict(median=float(np.median(d)), std=float(d.std()), dup=float(np.mean(d <= 1e-3)),
                                 max_gap=float(d.max()))
            tim[run] = row
            print(f"  {run:26s} " + "  ".join(
                f"{k}: {v['median']*1e3:.2f} ms ±{v['std']*1e3:.2f} dup {100*v['dup']:.1f}% max {v['max_gap']*1e3:.0f} ms"
                for k, v in row.items()))
        facts["timing"] = tim

    # ---- per-run quality ---------------------------------------------------
    print("== per run: repeated states, eRPM dropouts/glitches, low-thrust flying rows, p/v and q/w shifts")
    q_rows = {}
    for run, c in allruns.items():
        st = c.iloc[:, 1:14].to_numpy()
        rep = np.r_[False, np.all(st[1:] == st[:-1], 1)]
        # longest run of repeats
        longest, cur = 0, 0
        for r in rep:
            cur = cur + 1 if r else 0
            longest = max(longest, cur)
        e = c[["erpm1", "erpm2", "erpm3", "erpm4"]].to_numpy(float)
        gl = e[np.isfinite(e) & (e >= nd.GLITCH_ERPM)]
        ec = clean_erpm(e)
        tw = nd.KF * np.sum((ec * nd.ERPM_TO_RAD_S) ** 2, 1) / (nd.MASS * nd.G)
        fly = c["pz_m"].to_numpy() > 0.1
        vz = c["vz_world_m_s"].to_numpy()
        low = fly & (tw < 0.5)
        # p/v: best shift s of v (dp/dt at n vs v at n+s)
        p = c[["px_m", "py_m", "pz_m"]].to_numpy()
        v = c[["vx_world_m_s", "vy_world_m_s", "vz_world_m_s"]].to_numpy()
        ok = ~rep[1:-1] & ~rep[2:]
        dp = (p[2:] - p[:-2]) / (2 * DT)
        best = None
        for s in range(-10, 11):
            vv = np.roll(v, -s, 0)[1:-1]
            m = ok.copy()
            m[:15] = m[-15:] = False
            err = float(np.sqrt(np.mean(np.sum((dp - vv)[m] ** 2, 1))))
            if best is None or err < best[1]:
                best = (s, err)
        m = ok.copy(); m[:15] = m[-15:] = False
        err0 = float(np.sqrt(np.mean(np.sum((dp - v[1:-1])[m] ** 2, 1))))
        # smoothed version (5-sample box on both)
        dps, vs = smooth(dp, 5), smooth(v[1:-1], 5)
        errs = float(np.sqrt(np.mean(np.sum((dps - vs)[m] ** 2, 1))))
        q_rows[run] = dict(rows=len(c), repeated=float(rep.mean()), longest_repeat=int(longest),
                           erpm_nan=int(np.sum(~np.isfinite(e))), glitches=int(gl.size),
                           glitch_values=sorted(float(x) for x in gl),
                           tw_min_flying=float(tw[fly].min()) if fly.any() else None,
                           tw_max=float(tw.max()), low_thrust_rows=int(low.sum()),
                           low_thrust_min_vz=float(vz[low].min()) if low.any() else None,
                           v_fd_rms=err0, v_fd_rms_smoothed=errs, v_best_shift=best[0], v_best_rms=best[1])
        r = q_rows[run]
        print(f"  {run:26s} rep {100*r['repeated']:4.1f}% (longest {longest:3d}) nan {r['erpm_nan']:2d} "
              f"glitch {r['glitches']} {['%.3g' % x for x in gl]} T/W flying min {r['tw_min_flying']:.2f} "
              f"max {r['tw_max']:.2f} low(<0.5) {r['low_thrust_rows']} "
              f"|dp/dt-v| {err0:.3f} (5-box {errs:.3f}) best shift {best[0]:+d} -> {best[1]:.3f} m/s")
    facts["runs"] = q_rows
    tr = [q_rows[r] for r in train]
    facts["train_repeated"] = sum(r["repeated"] * r["rows"] for r in tr) / sum(r["rows"] for r in tr)
    facts["test_repeated"] = sum(q_rows[r]["repeated"] * q_rows[r]["rows"] for r in test) / sum(
        q_rows[r]["rows"] for r in test)
    print(f"  repeated states: train {100*facts['train_repeated']:.1f}%, test {100*facts['test_repeated']:.1f}%")

    # ---- torques -------------------------------------------------------------
    reqs, om2s, oks = [], [], []
    for run, c in train.items():
        a, b, m = torque_data(c)
        reqs.append(a); om2s.append(b); oks.append(m)

    def stacked(fn):
        return np.concatenate([fn(o) for o in om2s]), np.concatenate(reqs), np.concatenate(oks)

    print("== rotor torques vs J dw/dt + w x Jw on the training runs (gain k: req ~ k * mot; "
          "1/k is the 'motor torque is N x too large' ratio)")
    variants = {
        "published (a=0.0353, yaw -+-+)": dict(),
        "arm length 0.05 (a=L/sqrt2 vs L)": dict(arm=0.05),
        "yaw signs +-+-": dict(yaw_signs=(1, -1, 1, -1)),
        "numbering 1 FL,2 BL,3 BR,4 FR (mirror)": dict(perm=(3, 2, 1, 0)),
        "numbering rotated (1 BR,2 BL,3 FL,4 FR)": dict(perm=(1, 2, 3, 0)),
    }
    tq = {}
    for name, kw in variants.items():
        mot, req, ok = stacked(lambda o: motor_torques(o, **kw))
        g = fit_gain(req, mot, ok)
        tq[name] = g
        print(f"  {name:40s} " + "  ".join(
            f"{ax}: k={gi['k']:+.3f} (1/k {1/gi['k'] if gi['k'] else float('inf'):+.2f}, rev {gi['k_rev']:+.3f}) "
            f"corr {gi['corr']:+.2f}" for ax, gi in zip("xyz", g)))
    facts["torque_variants"] = tq

    # lag fit per axis (published constants), with 5-sample box smoothing of both sides too
    print("== first-order lag T between rotor torque and J dw/dt (grid 0..150 ms)")
    lag = {}
    for smooth_k in (1, 5):
        res = {}
        for T in np.r_[0.0, np.arange(0.005, 0.1501, 0.005)]:
            mots, reqs2, oks2 = [], [], []
            for o, rq, m in zip(om2s, reqs, oks):
                mt = lag_filter(motor_torques(o), T)
                mots.append(smooth(mt, smooth_k)); reqs2.append(smooth(rq, smooth_k)); oks2.append(m)
            g = fit_gain(np.concatenate(reqs2), np.concatenate(mots), np.concatenate(oks2))
            res[round(float(T), 4)] = g
        best = {}
        for i, ax in enumerate("xyz"):
            Tb = max(res, key=lambda T: res[T][i]["r2"])
            best[ax] = dict(T=Tb, k=res[Tb][i]["k"], r2=res[Tb][i]["r2"], r2_at_0=res[0.0][i]["r2"],
                            k_at_0=res[0.0][i]["k"])
        lag[f"box{smooth_k}"] = dict(best=best, grid={str(T): [gi["r2"] for gi in v] for T, v in res.items()})
        print(f"  smoothing {smooth_k}: " + "  ".join(
            f"{ax}: T={b['T']*1e3:.0f} ms k={b['k']:.3f} R2={b['r2']:.3f} (T=0: k={b['k_at_0']:.3f} R2={b['r2_at_0']:.3f})"
            for ax, b in best.items()))
    facts["lag"] = lag

    # pure delay (samples) with the box-5 smoothing
    print("== pure delay d (samples) instead of a lag, 5-box smoothing")
    dl = {}
    for d in range(0, 11):
        mots, reqs2, oks2 = [], [], []
        for o, rq, m in zip(om2s, reqs, oks):
            mt = np.roll(motor_torques(o), d, 0)
            mots.append(smooth(mt, 5)); reqs2.append(smooth(rq, 5)); oks2.append(m & (np.arange(len(m)) >= d))
        dl[d] = fit_gain(np.concatenate(reqs2), np.concatenate(mots), np.concatenate(oks2))
    for i, ax in enumerate("xyz"):
        db = max(dl, key=lambda d: dl[d][i]["r2"])
        print(f"  {ax}: best delay {db} samples ({db*10} ms) k={dl[db][i]['k']:.3f} R2={dl[db][i]['r2']:.3f}")
    facts["delay"] = {str(d): v for d, v in dl.items()}

    # thrust: body-z specific force vs kF sum Omega^2 / m, gain and lag
    print("== collective thrust: body-z specific force vs kF sum W^2 / m")
    fz, ft, okz = [], [], []
    for run, c in train.items():
        e = clean_erpm(c[["erpm1", "erpm2", "erpm3", "erpm4"]].to_numpy(float))
        ft.append(nd.KF * np.sum((e * nd.ERPM_TO_RAD_S) ** 2, 1) / nd.MASS)
        fz.append(c["az_m_s2"].to_numpy())
        m = np.ones(len(c), bool); m[:50] = False
        okz.append(m & (ft[-1] > 0.3 * nd.G))
    fzc, ftc, okc = np.concatenate(fz), np.concatenate(ft), np.concatenate(okz)
    k = float(ftc[okc] @ fzc[okc] / (ftc[okc] @ ftc[okc]))
    r2 = 1 - float(np.sum((fzc[okc] - k * ftc[okc]) ** 2) / np.sum((fzc[okc] - fzc[okc].mean()) ** 2))
    dbest = []
    for d in range(-5, 6):
        x = np.concatenate([np.roll(a, d) for a in ft])
        kk = float(x[okc] @ fzc[okc] / (x[okc] @ x[okc]))
        dbest.append((1 - float(np.sum((fzc[okc] - kk * x[okc]) ** 2) / np.sum((fzc[okc] - fzc[okc].mean()) ** 2)), d, kk))
    dbest.sort(reverse=True)
    print(f"  gain {k:.4f} R2 {r2:.4f}; best shift {dbest[0][1]:+d} samples R2 {dbest[0][0]:.4f} (gain {dbest[0][2]:.4f})")
    facts["thrust"] = dict(gain=k, r2=r2, best_shift=dbest[0][1], best_shift_r2=dbest[0][0])

    # airspeed-dependent moment: req ~ k mot + D v_body + c (5-box, motors one sample earlier)
    print("== roll/pitch torque with a rotor aerodynamic moment linear in body velocity "
          "(req ~ k mot + D v_body + c; 5-box smoothing, motors 1 sample earlier)")
    aero = {}
    for grp in ("square", "random", "multisine", ""):
        Rs, Ms, Vs, Ks = [], [], [], []
        for run, c in train.items():
            if not run.startswith(grp):
                continue
            a, o, m = torque_data(c)
            q = c[["qw", "qx", "qy", "qz"]].to_numpy()
            Rm = nd.quat_to_rot(q / np.linalg.norm(q, axis=1, keepdims=True))
            vb = np.einsum("nji,nj->ni", Rm, c[["vx_world_m_s", "vy_world_m_s", "vz_world_m_s"]].to_numpy())
            Rs.append(smooth(a, 5)); Ms.append(smooth(np.roll(motor_torques(o), 1, 0), 5))
            Vs.append(smooth(vb, 5)); Ks.append(m)
        R_, M_, V_, K_ = (np.concatenate(x) for x in (Rs, Ms, Vs, Ks))
        one = np.ones(len(R_))
        row = {}
        for i, ax in enumerate("xy"):
            def lsq(X, y):
                b = np.linalg.lstsq(X, y, rcond=None)[0]
                return b, 1 - float(np.sum((y - X @ b) ** 2) / np.sum((y - y.mean()) ** 2))
            b0, r0 = lsq(np.c_[M_[:, i], one][K_], R_[K_, i])
            b1, r1 = lsq(np.c_[M_[:, i], V_, one][K_], R_[K_, i])
            bm, rm = lsq(np.c_[V_, one][K_], M_[K_, i])  # how much of the motor torque is velocity
            row[ax] = dict(k_plain=float(b0[0]), r2_plain=r0, k_aero=float(b1[0]), D_aero=b1[1:4].tolist(),
                           r2_aero=r1, motor_from_v_r2=rm, motor_from_v=bm[:3].tolist())
            print(f"  {grp or 'all train':10s} {ax}: plain k={b0[0]:.3f} (ratio {1/b0[0]:.1f}) R2={r0:.2f} | "
                  f"with v_body k={b1[0]:.3f} (ratio {1/b1[0]:.1f}) R2={r1:.2f} | motor torque vs v_body: "
                  f"R2={rm:.2f}, {np.round(np.array(bm[:3])*1e4, 1)}e-4 N m per m/s")
        aero[grp or "all"] = row
    facts["aero_moment"] = aero

    # motor lag: per-motor normalised command (m*_thrust, unitless) -> measured Omega^2
    if args.git_dir or args.checkout:
        print("== motor lag: per-motor command m{1..4}_thrust (benchmark parquet, unitless) -> measured W^2; "
              "first-order lag T, gain+offset per motor")
        data = []
        for run in train:
            df = nd.read_run(args, run)
            e = clean_erpm(df[["m1_erpm", "m2_erpm", "m3_erpm", "m4_erpm"]].to_numpy(float))
            om = e * nd.ERPM_TO_RAD_S
            mc = pd.DataFrame(df[["m1_thrust", "m2_thrust", "m3_thrust", "m4_thrust"]].to_numpy(float)).ffill().bfill().to_numpy()
            ok = nd.KF * np.sum(om**2, 1) > 0.3 * nd.MASS * nd.G
            ok[:50] = False
            data.append((mc, om, ok))
        grid = {}
        for Tm in np.arange(0.0, 0.0801, 0.0025):
            xs = np.concatenate([lag_filter(mc, Tm) if Tm > 0 else np.roll(mc, 1, 0) for mc, _, _ in data])
            k_ = np.concatenate([ok for _, _, ok in data])
            r2s = {}
            for pw in (1, 2):
                ys = np.concatenate([om**pw for _, om, _ in data])
                r = []
                for j in range(4):
                    X = np.c_[xs[:, j], np.ones(len(xs))][k_]
                    b = np.linalg.lstsq(X, ys[k_, j], rcond=None)[0]
                    y = ys[k_, j]
                    r.append(1 - float(np.sum((y - X @ b) ** 2) / np.sum((y - y.mean()) ** 2)))
                r2s[pw] = float(np.mean(r))
            grid[round(float(Tm), 4)] = r2s
        for pw in (1, 2):
            Tb = max(grid, key=lambda T: grid[T][pw])
            print(f"  target W^{pw}: best T = {Tb*1e3:.1f} ms (mean R2 over motors {grid[Tb][pw]:.3f}; "
                  f"T=10 ms {grid[0.01][pw]:.3f}, T=50 ms {grid[0.05][pw]:.3f})")
            facts[f"motor_lag_omega{pw}"] = dict(T=Tb, r2=grid[Tb][pw])
        facts["motor_lag_grid"] = {str(k): v for k, v in grid.items()}

    if args.out:
        with open(args.out, "w") as f:
            json.dump(facts, f, indent=1)


if __name__ == "__main__":
    main()
