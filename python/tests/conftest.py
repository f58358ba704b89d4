"""Shared helpers: the repository root and the host-train binary the bridge tests run."""

import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def host_train_binary():
    """host-train built by `cargo build --release -p host-train` (HAMFLIGHT_HOST_TRAIN, else
    $CARGO_TARGET_DIR/release, else target/release, else PATH)."""
    env = os.environ.get("HAMFLIGHT_HOST_TRAIN")
    if env:
        return pathlib.Path(env)
    for target in (os.environ.get("CARGO_TARGET_DIR"), ROOT / "target"):
        if target:
            p = pathlib.Path(target) / "release" / "host-train"
            if p.exists():
                return p
    found = shutil.which("host-train")
    return pathlib.Path(found) if found else None


@pytest.fixture(scope="session")
def root():
    return ROOT


@pytest.fixture(scope="session")
def bridge_binary():
    exe = host_train_binary()
    if exe is None or not exe.exists():
        msg = "host-train not built: cargo build --release -p host-train (or set HAMFLIGHT_HOST_TRAIN)"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    return exe


def run_bridge(exe, lines, controller, weights, dt=0.002):
    text = "".join(line + "\n" for line in lines)
    proc = subprocess.run(
        [str(exe), "bridge", "--controller", controller, "--weights", str(weights), "--dt", str(dt)],
        input=text.encode(),
        capture_output=True,
        cwd=ROOT,
        check=True,
    )
    return proc.stdout.decode().splitlines()
