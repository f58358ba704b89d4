"""The step-by-step SITL plant and its Gymnasium-style environment: a Python PD policy flies it."""

import numpy as np
import pytest

from hamflight import sitl
from hamflight.env import QuadrotorEnv


def pd_policy(env: QuadrotorEnv, obs: np.ndarray, info: dict) -> np.ndarray:
    """A cascaded PD: position error -> desired acceleration -> thrust along the body z axis
    and a desired z axis; the attitude error (SO(3)) and rates -> torques scaled by J."""
    p = env.plant
    e, v = obs[0:3], obs[3:6]
    rot = obs[6:15].reshape(3, 3)
    w = obs[15:18]
    a_des = -16.0 * e - 8.0 * v + info["reference"]["a_m_s2"] + np.array([0.0, 0.0, p.gravity_m_s2])
    thrust = p.mass_kg * float(a_des @ rot[:, 2])
    b3 = a_des / np.linalg.norm(a_des)
    b1c = np.array([1.0, 0.0, 0.0])
    b2 = np.cross(b3, b1c)
    b2 /= np.linalg.norm(b2)
    r_des = np.column_stack([np.cross(b2, b3), b2, b3])
    m = 0.5 * (r_des.T @ rot - rot.T @ r_des)
    e_r = np.array([m[2, 1], m[0, 2], m[1, 0]])
    j = np.array(p.inertia_kg_m2)
    torque = j * (-400.0 * e_r - 40.0 * w)
    return np.array([thrust, *torque])


def test_a_python_pd_policy_flies_the_step_by_step_plant():
    env = QuadrotorEnv("hover")
    obs, info = env.reset()
    assert obs.shape == (18,)
    # Start a few cm off the reference, moving: the policy must bring it back.
    env.plant.step_wrench(env.hover_thrust_n * 1.5, [0.0, 0.0, 0.0], dt_s=0.1)
    obs, info = env._observe(env.plant.observation())
    start_err = float(np.linalg.norm(obs[0:3]))
    assert start_err > 0.01
    total, steps, done = 0.0, 0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(pd_policy(env, obs, info))
        total += reward
        steps += 1
        assert not terminated, f"crashed at t = {info['t_s']:.2f} s"
        done = truncated
    final_err = float(np.linalg.norm(obs[0:3]))
    assert final_err < 0.01, final_err
    # One control period a step, after the 0.1 s offset.
    assert steps == pytest.approx((env.plant.duration_s - 0.1) / env.plant.control_dt_s, abs=2)
    assert info["t_s"] == pytest.approx(env.plant.duration_s, abs=0.05)


def test_no_thrust_falls_and_terminates():
    env = QuadrotorEnv("hover")
    env.reset()
    for _ in range(5000):
        _, reward, terminated, truncated, _ = env.step([0.0, 0.0, 0.0, 0.0])
        if terminated:
            break
    assert terminated and not truncated
    assert reward <= -0.99


def test_reset_is_deterministic_and_steps_repeat_bit_for_bit():
    env = QuadrotorEnv("paper-spiral")
    a = [env.hover_thrust_n, 1e-6, -1e-6, 0.0]
    runs = []
    for _ in range(2):
        env.reset()
        runs.append(np.array([env.step(a)[0] for _ in range(50)]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_plant_rejects_bad_steps():
    p = sitl.Plant(sitl.Scenario.load("hover"))
    with pytest.raises(ValueError, match="dt_s"):
        p.step_rpm([0.0] * 4, dt_s=-1.0)
    with pytest.raises(ValueError, match="finite"):
        p.step_rpm([float("nan")] * 4)
    with pytest.raises(ValueError, match="action"):
        QuadrotorEnv("hover").step([1.0, 2.0])
    # A non-finite wrench stops the rotors (the mixer's safe output), it does not raise.
    obs = p.step_wrench(float("nan"), [0.0, 0.0, 0.0])
    assert np.all(np.isfinite(obs))
