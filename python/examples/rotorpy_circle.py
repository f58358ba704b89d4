"""Fly RotorPy's Crazyflie with hamflight: a 0.5 m circle in a 0.8 m/s wind.

    python python/examples/rotorpy_circle.py [--law composite] [--seconds 12]
"""

import argparse

import numpy as np
from rotorpy.trajectories.circular_traj import ThreeDCircularTraj
from rotorpy.wind.default_winds import ConstantWind

import hamflight
from hamflight import rotorpy as hrp

ap = argparse.ArgumentParser()
ap.add_argument("--law", default="composite", choices=["gradient", "composite"])
ap.add_argument("--seconds", type=float, default=12.0)
args = ap.parse_args()

ctrl = hamflight.Controller(hamflight.Blob.default(), law=args.law)
traj = ThreeDCircularTraj(center=np.array([0.0, 0.0, 1.0]), radius=np.array([0.5, 0.5, 0.0]), freq=np.full(3, 0.125), yaw_bool=False)
log = hrp.fly(ctrl, traj, args.seconds, wind_profile=ConstantWind(0.8, 0.5, 0.0))
late = log["t"] >= 6.0
print(f"{ctrl}: RMSE over t >= 6 s {100 * np.sqrt(np.mean(log['err'][late] ** 2)):.2f} cm, "
      f"max {100 * log['err'].max():.2f} cm, final a = {np.round(ctrl.a, 3)}")
