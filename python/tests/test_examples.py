"""The Python examples run as a user runs them (a fresh interpreter, the installed package), with
short arguments, and print what their docstrings promise."""

import re
import subprocess
import sys
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run_example(name, *args, timeout=300):
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert out.returncode == 0, f"{name} exited {out.returncode}:\n{out.stdout}\n{out.stderr}"
    return out.stdout


def test_rotorpy_circle_tracks_the_circle():
    text = run_example("rotorpy_circle.py", "--seconds", "8")
    m = re.search(r"RMSE over t >= 6 s ([0-9.]+) cm, max ([0-9.]+) cm", text)
    assert m, f"no RMSE line in:\n{text}"
    rmse_cm, max_cm = float(m.group(1)), float(m.group(2))
    # Converged tracking in the wind; the maximum is the take-off transient.
    assert rmse_cm < 1.0, text
    assert max_cm < 20.0, text


def test_sweep_gives_the_same_flights_on_both_backends():
    text = run_example("sweep.py", "--flights", "16", "--workers", "2")
    assert "identical per-flight results on both backends: True" in text, text
    rates = re.findall(r"16 flights: success ([0-9.]+) %", text)
    assert len(rates) == 2, text
    assert all(float(r) >= 90.0 for r in rates), text
