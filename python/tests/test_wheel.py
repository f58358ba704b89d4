"""The packaged files (hamflight.data) and, when python/ci.sh passes the wheel it installed
(HAMFLIGHT_WHEEL), the wheel itself: its tag, its size, its contents."""

import os
import pathlib
import zipfile

import pytest

import hamflight
from hamflight import data, sitl
from conftest import ROOT

SO_LIMIT_BYTES = 15 * 1024 * 1024


def test_the_packaged_scenarios_and_weights_are_the_repositorys():
    names = data.scenarios()
    assert names == sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml"))
    assert data.scenario("paper-spiral").read_bytes() == (ROOT / "scenarios" / "paper-spiral.toml").read_bytes()
    assert data.scenario("scenarios/hover.toml") == data.scenario("hover.toml") == data.scenario("hover")
    assert data.default_weights().read_bytes() == (ROOT / "weights" / "default.hfw").read_bytes()
    assert data.default_weights().read_bytes() == hamflight.Blob.default().to_bytes()
    with pytest.raises(FileNotFoundError, match="no packaged scenario 'nope'"):
        data.scenario("nope")


def test_repository_paths_work_outside_a_checkout(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no scenarios/ or weights/ here: the packaged copies are read
    s = sitl.Scenario.load("scenarios/hover.toml")
    assert s.name == "hover"
    assert sitl.Scenario.load("hover").to_dict() == s.to_dict()
    log = sitl.fly("scenarios/hover.toml", "geometric")
    assert not log.crashed and log.report["scenario"] == "hover"
    b = hamflight.Blob.load("weights/default.hfw")
    assert b.to_bytes() == hamflight.Blob.default().to_bytes() and b.name == "default.hfw"
    ctrl = hamflight.Controller("weights/default.hfw")
    assert ctrl.step([0, 0, 1], [[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 0], [0, 0, 0], [0, 0, 1], 0.002).rpm.shape == (4,)
    # A file in the working directory comes first; a missing one still names the path asked for.
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "scenarios" / "hover.toml").write_text('duration_s = 2.0\n[trajectory]\nkind = "hover"\nposition_m = [0, 0, 1]\n')
    assert sitl.Scenario.load("scenarios/hover.toml").duration_s == 2.0
    with pytest.raises(ValueError, match="scenarios/nonexistent.toml"):
        sitl.Scenario.load("scenarios/nonexistent.toml")
    with pytest.raises(OSError, match="weights/missing.hfw"):
        hamflight.Blob.load("weights/missing.hfw")


WHEEL = os.environ.get("HAMFLIGHT_WHEEL")


@pytest.mark.skipif(not WHEEL, reason="HAMFLIGHT_WHEEL not set (python/ci.sh sets it to the wheel it installed)")
def test_the_installed_wheel_is_abi3_manylinux_small_and_complete():
    wheel = pathlib.Path(WHEEL)
    name, version, python_tag, abi_tag, platform_tag = wheel.stem.split("-")
    assert (name, version) == ("hamflight", hamflight.__version__)
    assert (python_tag, abi_tag) == ("cp39", "abi3")
    assert platform_tag.startswith("manylinux_") and platform_tag.endswith("_x86_64"), platform_tag
    so = pathlib.Path(hamflight._core.__file__)
    # Installed from the wheel (into a venv's site-packages), not imported from the checkout.
    assert "site-packages" in so.parts and ROOT / "python" not in so.resolve().parents, so
    assert so.name == "_core.abi3.so", so
    assert so.stat().st_size <= SO_LIMIT_BYTES, f"{so}: {so.stat().st_size} bytes"
    with zipfile.ZipFile(wheel) as z:
        files = set(z.namelist())
    expected = {f"hamflight/scenarios/{p.name}" for p in (ROOT / "scenarios").glob("*.toml")}
    expected |= {"hamflight/weights/default.hfw", "hamflight/data.py", "hamflight/py.typed", "hamflight/_core.abi3.so"}
    assert expected <= files, sorted(expected - files)
    assert data.root() == so.parent and not (so.parent / "scenarios").is_symlink()
