"""collect, train and import from Python: the CLI's commands with its flags as keywords."""

import csv

import numpy as np
import pytest

import hamflight


def test_collect_then_train_then_fly(tmp_path):
    seen = []
    manifest = hamflight.collect(tmp_path / "data", realizations=2, windows=60, calm_realizations=1, seed=3, progress=seen.append)
    assert seen == ["collect: started", "collect: done"]
    assert len(manifest["realizations"]) == 3
    with open(tmp_path / "data" / "realization_00.csv") as f:
        header = next(csv.reader(f))
    assert header[:3] == ["flight", "t_s", "px"]
    report = hamflight.train(tmp_path / "data", tmp_path / "m.hfw", epochs=1, feature_epochs=0, no_flight_check=True, quiet=True)
    assert isinstance(report, dict) and (tmp_path / "m.hfw.json").exists()
    blob = hamflight.Blob.load(tmp_path / "m.hfw")
    assert blob.mass_kg == pytest.approx(0.027, rel=1e-3)
    out = hamflight.Controller(blob).step([0, 0, 1], np.eye(3), [0, 0, 0], [0, 0, 0], [0, 0, 1], 0.002)
    assert np.all(np.isfinite(out.rpm))


def test_bad_flags_raise_value_error_with_the_cli_message(tmp_path):
    with pytest.raises(ValueError, match="--bogus"):
        hamflight.collect(tmp_path, bogus=1)
    with pytest.raises(ValueError, match="realizations"):
        hamflight.collect(tmp_path, realizations=0)
    with pytest.raises(ValueError):
        hamflight.import_logs(tmp_path / "d", [tmp_path / "missing.csv"])
