"""hamflight.sitl: scenario files flown from Python, the log as numpy arrays."""

import json
import subprocess

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
