"""collect, train and import from Python: the CLI's commands with its flags as keywords."""

import csv

import numpy as np
import pytest

import hamflight


def test_collect_then_train_then_fly(tmp_path, capfd):
    seen = []
    manifest = hamflight.collect(
        tmp_path / "data", realizations=2, windows=60, calm_realizations=1, seed=3, wind_levels=(0.25, 0.5), progress=seen.append
    )
    assert seen == ["collect: started", "collect: done"]
    assert len(manifest["realizations"]) == 3
    with open(tmp_path / "data" / "realization_00.csv") as f:
        header = next(csv.reader(f))
    assert header[:3] == ["flight", "t_s", "px"]
    capfd.readouterr()
    report = hamflight.train(tmp_path / "data", tmp_path / "m.hfw", epochs=1, feature_epochs=0, no_flight_check=True, quiet=True)
    printed = capfd.readouterr()
    assert printed.out == "" and printed.err == "", printed  # quiet: no progress bar, no summary
    assert isinstance(report, dict) and (tmp_path / "m.hfw.json").exists()
    blob = hamflight.Blob.load(tmp_path / "m.hfw")
    assert blob.mass_kg == pytest.approx(0.027, rel=1e-3)
    out = hamflight.Controller(blob).step([0, 0, 1], np.eye(3), [0, 0, 0], [0, 0, 0], [0, 0, 1], 0.002)
    assert np.all(np.isfinite(out.rpm))


def test_bad_values_raise_value_error_with_the_cli_message(tmp_path):
    with pytest.raises(ValueError, match="bogus"):
        hamflight.collect(tmp_path, bogus=1)
    with pytest.raises(ValueError, match="realizations"):
        hamflight.collect(tmp_path, realizations=0)
    with pytest.raises(ValueError):
        hamflight.import_logs(tmp_path / "d", [tmp_path / "missing.csv"])


def test_a_typo_keyword_raises_value_error_naming_it_and_the_valid_ones(tmp_path):
    with pytest.raises(ValueError, match=r"unknown field `epoch`, expected one of .*`epochs`") as e:
        hamflight.train(tmp_path / "data", tmp_path / "m.hfw", epoch=3)
    assert "`no_flight_check`" in str(e.value)
    assert not (tmp_path / "m.hfw").exists()  # nothing ran
    with pytest.raises(ValueError, match=r"`windws`.*`windows`"):
        hamflight.collect(tmp_path / "d", windws=10)
    with pytest.raises(ValueError, match=r"`min_heigth_m`.*`min_height_m`"):
        hamflight.import_logs(tmp_path / "d", [], mass_kg=0.03, min_heigth_m=0.2)
    assert not (tmp_path / "d").exists()


def test_a_mistyped_value_raises_value_error_naming_its_key(tmp_path):
    with pytest.raises(ValueError, match=r"`epochs`.*invalid type"):
        hamflight.train(tmp_path / "data", tmp_path / "m.hfw", epochs="three")
    with pytest.raises(ValueError, match=r"`gradient`"):
        hamflight.train(tmp_path / "data", tmp_path / "m.hfw", gradient="autodiff")
    with pytest.raises(ValueError, match=r"`wind_levels`"):
        hamflight.collect(tmp_path / "d", wind_levels=0.5)
