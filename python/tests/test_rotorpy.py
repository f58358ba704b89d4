"""Closed loop in RotorPy: the core drives RotorPy's Crazyflie (its own parameters: 30 g,
72 ms motor lag, rotor drag) through the rotor-speed interface, along RotorPy's circular
trajectory in RotorPy's constant wind."""

import numpy as np
import pytest

import hamflight
from hamflight import rotorpy as hrp

rotorpy = pytest.importorskip("rotorpy")
from rotorpy.trajectories.circular_traj import ThreeDCircularTraj  # noqa: E402
from rotorpy.trajectories.hover_traj import HoverTraj  # noqa: E402
from rotorpy.vehicles.crazyflie_params import quad_params  # noqa: E402
from rotorpy.wind.default_winds import ConstantWind  # noqa: E402


def circle():
    # A 0.5 m circle at 1 m height, one turn per 8 s.
    return ThreeDCircularTraj(center=np.array([0.0, 0.0, 1.0]), radius=np.array([0.5, 0.5, 0.0]), freq=np.full(3, 0.125), yaw_bool=False)


def test_state_conversions():
    from scipy.spatial.transform import Rotation

    q = Rotation.from_euler("z", 90, degrees=True).as_quat()  # [x, y, z, w]
    state = {"x": np.array([1.0, 2, 3]), "v": np.array([1.0, 0, 0]), "q": q, "w": np.array([0.0, 0, 0.5])}
    p, R, v_body, w_body = hrp.state_to_core(state)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # body x points to world y
    np.testing.assert_allclose(v_body, [0, -1, 0], atol=1e-12)  # world x is body -y
    np.testing.assert_allclose(w_body, [0, 0, 0.5])
    # Rotors are matched by position: RotorPy's r1 (+x, +y) is our rotor 4.
    pos_ours = [(1, -1), (-1, -1), (-1, 1), (1, 1)]
    for j, i in enumerate(hrp.ROTOR_ORDER):
        rp = quad_params["rotor_pos"][f"r{j + 1}"]
        assert tuple(np.sign(rp[:2]).astype(int)) == pos_ours[i]


@pytest.mark.parametrize("law", ["gradient", "composite"])
def test_rotorpy_circle_in_wind_is_tracked(law):
    ctrl = hamflight.Controller(hamflight.Blob.default(), law=law)
    log = hrp.fly(ctrl, circle(), 9.0, wind_profile=ConstantWind(0.8, 0.5, 0.0))
    assert not log["fault"].any()
    late = log["t"] >= 5.0
    rmse = float(np.sqrt(np.mean(log["err"][late] ** 2)))
    print(f"RotorPy circle in wind, {law} law: RMSE t >= 5 s {100 * rmse:.2f} cm, max {100 * log['err'].max():.2f} cm")
    assert rmse < 0.02
    assert log["err"].max() < 0.10


def test_adaptation_is_what_holds_the_heavier_rotorpy_vehicle():
    """RotorPy's Crazyflie is 3 g heavier than the model says: without adaptation the
    controller sags; with it, it holds the hover."""
    hover = HoverTraj(x0=np.array([0.0, 0.0, 1.0]))
    on = hrp.fly(hamflight.Controller.named("adaptive"), hover, 4.0)
    off = hrp.fly(hamflight.Controller.named("learned"), hover, 4.0)
    print(f"RotorPy hover, last 0.5 s: adaptive {100 * on['err'][-250:].mean():.2f} cm, without adaptation {100 * off['err'][-250:].mean():.2f} cm")
    assert on["err"][-250:].mean() < 0.01
    assert off["err"][-250:].mean() > 2 * on["err"][-250:].mean()
