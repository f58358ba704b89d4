"""hamflight.sitl: scenario files flown from Python, the log as numpy arrays."""

import copy
import json
import pickle
import subprocess
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import hamflight
from hamflight import sitl
from conftest import ROOT

SCEN = ROOT / "scenarios"


def test_fly_a_scenario_file_and_get_numpy_arrays():
    log = sitl.fly(SCEN / "paper-spiral.toml", "adaptive")
    n = len(log.t_s)
    assert n == 15001
    assert log.p_m.shape == (n, 3) and log.p_ref_m.shape == (n, 3)
    assert log.err_m.shape == (n,) and log.rpm.shape == (n, 4) and log.adaptation.shape == (n, 6)
    assert not log.crashed
    assert log.rmse_m < 0.002  # 0.022 cm in docs/adaptation.md, with margin
    np.testing.assert_allclose(np.linalg.norm(log.p_m - log.p_ref_m, axis=1), log.err_m)
    assert log.report["scenario"] == "paper-spiral" and log.report["controller"] == "adaptive"
    assert repr(log) == f"FlightResult(ticks=15001, rmse_m={log.rmse_m!r}, crashed=False)"


def test_a_python_controller_flies_like_its_name():
    a = sitl.fly(SCEN / "hover-wind.toml", "adaptive-composite")
    b = sitl.fly(sitl.Scenario.load(SCEN / "hover-wind.toml"), hamflight.Controller(hamflight.Blob.default(), law="composite"))
    np.testing.assert_array_equal(a.p_m, b.p_m)
    np.testing.assert_array_equal(a.rpm, b.rpm)


def test_baselines_fly_and_the_registry_lists_them():
    names = [n for n, _ in sitl.controllers()]
    assert {"pid", "geometric", "adaptive", "adaptive-composite"} <= set(names)
    log = sitl.fly(SCEN / "hover.toml", "geometric")
    assert log.adaptation.shape[1] == 0 and not log.crashed
    # The DSL PID rolls over on paper-spiral: the log stops at the crash, every array aligned.
    crash = sitl.fly(SCEN / "paper-spiral.toml", "pid")
    n = len(crash.t_s)
    assert crash.crashed and crash.rmse_m is None and n < 1000
    assert repr(crash) == f"FlightResult(ticks={n}, rmse_m=None, crashed=True)"
    assert crash.rpy_rad.shape == crash.est_w_body_rad_s.shape == (n, 3)


def test_scenarios_round_trip_through_dicts_and_toml():
    s = sitl.Scenario.load(SCEN / "paper-spiral.toml")
    d = s.to_dict()
    assert d["disturbance"]["wind_m_s2"] == [0.75, 0.75, 0.0]
    d["duration_s"] = 6.0
    d["disturbance"]["wind_m_s2"] = [0.0, 0.0, 0.0]
    s2 = sitl.Scenario.from_dict(d)
    assert s2.duration_s == 6.0 and s2.name == "paper-spiral"
    log = sitl.fly(s2, "adaptive")
    assert len(log.t_s) == 3001
    s3 = sitl.Scenario.from_toml('duration_s = 2.0\n[trajectory]\nkind = "hover"\nposition_m = [0, 0, 1]\n', name="mine")
    assert s3.name == "mine" and sitl.fly(s3, "ida-pbc").report["duration_s"] == pytest.approx(2.0)
    ref = s.reference(1.0)
    assert ref["p_m"].shape == (3,)
    with pytest.raises(ValueError, match="unknown field"):
        sitl.Scenario.from_dict({**d, "bogus": 1})
    with pytest.raises(ValueError, match="scenario"):
        sitl.Scenario.load(SCEN / "nonexistent.toml")


# The report's scores that are not wall-clock measurements.
WALL = {"wall_s", "sim_speed", "control_step_us"}


def same_flight(a, b):
    for k in ("t_s", "p_m", "p_ref_m", "err_m", "rpm", "adaptation"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
    ra, rb = ({k: v for k, v in r.items() if k not in WALL} for r in (a.report, b.report))
    assert ra == rb
    assert set(a.report) - set(ra) == WALL  # the wall-clock keys are the only ones left out


def test_every_shipped_scenario_pickles_to_an_equal_one():
    names = hamflight.data.scenarios()
    assert len(names) > 10
    for name in names:
        s = sitl.Scenario.load(name)
        for back in (pickle.loads(pickle.dumps(s)), copy.deepcopy(s), copy.copy(s)):
            assert type(back) is sitl.Scenario and back is not s
            assert back == s and hash(back) == hash(s), name
            assert (back.name, back.duration_s, back.control_hz, repr(back)) == (s.name, s.duration_s, s.control_hz, repr(s))
            assert back.to_dict() == s.to_dict(), name
    assert sitl.Scenario.load("hover") != sitl.Scenario.load("hover-wind")
    assert sitl.Scenario.load("hover") != "hover"


def test_an_unpickled_scenario_flies_as_the_original():
    s = sitl.Scenario.load(SCEN / "rotor-loss-mid.toml")
    back = pickle.loads(pickle.dumps(s))
    a, b = sitl.fly(s, "adaptive-composite"), sitl.fly(back, "adaptive-composite")
    assert b.report["scenario_file"] == str(SCEN / "rotor-loss-mid.toml")  # the file is carried
    same_flight(a, b)
    # An edited scenario (no file) with floats that have no short decimal form, through a
    # process boundary as multiprocessing and Ray send it.
    d = s.to_dict()
    d["disturbance"]["wind_m_s2"] = [0.1 + 0.2, np.float32(0.3), -1 / 3]
    d["seed"] = np.int64(7)
    edited = sitl.Scenario.from_dict(d, name="edited")
    assert edited.to_dict()["disturbance"]["wind_m_s2"] == [0.1 + 0.2, float(np.float32(0.3)), -1 / 3]  # exact
    with ProcessPoolExecutor(1) as pool:
        remote = pool.submit(pickle.dumps, edited).result()
    back = pickle.loads(remote)
    assert back == edited and back.name == "edited" and back.to_dict()["seed"] == 7
    a, b = sitl.fly(edited, "adaptive"), sitl.fly(back, "adaptive")
    assert a.report["scenario_file"] is None
    same_flight(a, b)
    assert not np.array_equal(a.p_m, sitl.fly(s, "adaptive").p_m)  # the edit mattered


def test_bad_dict_values_are_named():
    d = sitl.Scenario.load("hover").to_dict()
    with pytest.raises(ValueError, match=r"duration_s: not a finite number"):
        sitl.Scenario.from_dict({**d, "duration_s": float("nan")})
    with pytest.raises(ValueError, match=r"disturbance\.wind_m_s2\[1\]: object is not a JSON value"):
        sitl.Scenario.from_dict({**d, "disturbance": {**d["disturbance"], "wind_m_s2": [0.0, object(), 0.0]}})
    with pytest.raises(ValueError, match=r"keys must be strings"):
        sitl.Scenario.from_dict({**d, 1: 2})


def test_sitl_scores_equal_host_train_eval(bridge_binary, tmp_path):
    """The same flight as `host-train eval`: every score of report.json but the wall times."""
    scen = SCEN / "rotor-loss-mid.toml"
    subprocess.run(
        [str(bridge_binary), "eval", "--scenario", str(scen), "--controller", "adaptive-composite",
         "--weights", str(ROOT / "weights" / "default.hfw"), "--out", str(tmp_path)],
        check=True, capture_output=True, cwd=ROOT,
    )
    want = json.loads((tmp_path / "report.json").read_text())
    got = sitl.fly(scen, "adaptive-composite").report
    for k in ("rmse_pos_m", "rmse_pos_window_m", "max_err_m", "final_err_m", "crashed", "events"):
        assert got[k] == want[k], k


# The per-tick states besides the position: the truth's and the ones the controller flew on.
STATES = ("rpy_rad", "v_world_m_s", "w_body_rad_s", "est_p_m", "est_v_world_m_s", "est_rpy_rad", "est_w_body_rad_s")


def integrated(t, v, p0):
    """p0 plus the trapezoidal integral of v over t, at every t."""
    steps = 0.5 * (v[1:] + v[:-1]) * np.diff(t)[:, None]
    return p0 + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])


def test_the_flight_logs_attitude_velocity_rates_and_the_state_flown_on():
    log = sitl.fly(SCEN / "paper-spiral.toml", "adaptive")
    n = len(log.t_s)
    for k in STATES:
        a = getattr(log, k)
        assert a.shape == (n, 3) and a.dtype == np.float64 and np.all(np.isfinite(a)), k
    # The velocity log integrates to the position log (trapezoids at the control rate) on a
    # flight that moves.
    assert np.ptp(log.p_m, axis=0)[:2].min() > 0.5
    drift = np.abs(integrated(log.t_s, log.v_world_m_s, log.p_m[0]) - log.p_m).max()
    assert drift < 2e-6, drift  # measured 0.6 µm
    # ... and not a shifted one: the velocity one tick off misses by far more (measured 0.9 mm).
    shifted = np.abs(integrated(log.t_s[1:], log.v_world_m_s[:-1], log.p_m[1]) - log.p_m[1:]).max()
    assert shifted > 100 * drift, (shifted, drift)
    # No [sensors] section and no noise: the controller flew on the true state, exactly.
    np.testing.assert_array_equal(log.est_p_m, log.p_m)
    np.testing.assert_array_equal(log.est_rpy_rad, log.rpy_rad)
    np.testing.assert_array_equal(log.est_v_world_m_s, log.v_world_m_s)
    np.testing.assert_array_equal(log.est_w_body_rad_s, log.w_body_rad_s)


def test_the_attitude_log_is_level_in_hover_and_leans_into_the_wind():
    calm = sitl.fly(SCEN / "hover.toml", "adaptive")
    after = calm.t_s >= 1.0
    assert np.abs(calm.rpy_rad[after, :2]).max() < 1e-4  # measured 1.7e-5 rad
    assert np.abs(calm.w_body_rad_s[after]).max() < 5e-4  # measured 1.6e-4 rad/s
    # In a steady wind (0.5, -0.25, 0) m/s² the thrust axis, the third column of
    # R = Rz(yaw) Ry(pitch) Rx(roll), leans against it: along (-0.5, 0.25, g).
    windy = sitl.fly(SCEN / "hover-wind.toml", "adaptive")
    roll, pitch, yaw = windy.rpy_rad[windy.t_s >= 5.0].T
    axis = np.stack([np.cos(yaw) * np.sin(pitch) * np.cos(roll) + np.sin(yaw) * np.sin(roll),
                     np.sin(yaw) * np.sin(pitch) * np.cos(roll) - np.cos(yaw) * np.sin(roll),
                     np.cos(pitch) * np.cos(roll)], axis=1).mean(axis=0)
    want = np.array([-0.5, 0.25, 9.81])
    assert np.degrees(np.arccos(axis @ want / np.linalg.norm(axis) / np.linalg.norm(want))) < 0.01  # measured 0.003°
    assert pitch.mean() < -0.04 and roll.mean() < -0.02  # it does lean: measured -0.051, -0.026 rad


def test_with_an_estimator_the_estimate_flown_on_is_near_the_truth_not_it():
    log = sitl.fly(SCEN / "cf-hover-lag50.toml", "adaptive")
    assert not log.crashed
    off = np.abs(log.est_p_m - log.p_m).max(axis=0)
    assert np.all(off > 1e-4) and np.all(off < 0.001), off  # measured 0.44, 0.50, 0.67 mm
    off_v = np.abs(log.est_v_world_m_s - log.v_world_m_s).max()
    assert 1e-3 < off_v < 0.01, off_v  # measured 5.0 mm/s
    off_att = np.abs(log.est_rpy_rad - log.rpy_rad).max()
    assert 1e-4 < off_att < 0.008, off_att  # measured 0.0041 rad
    off_w = np.abs(log.est_w_body_rad_s - log.w_body_rad_s).max()
    assert 1e-3 < off_w < 0.04, off_w  # the filtered gyro, a sample late; measured 0.020 rad/s
