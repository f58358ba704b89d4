"""The Monte Carlo sweep, smaller: multiprocessing and Ray (sized for 2 cores) give the same
numbers, flight for flight."""

import pytest

from hamflight import montecarlo as mc

N = 40


@pytest.fixture(scope="module")
def draws():
    return mc.draw(N, seed=11)


@pytest.fixture(scope="module")
def serial(draws):
    return mc.run(draws, backend="serial")


def test_draws_are_reproducible(draws):
    assert mc.draw(N, seed=11) == draws and mc.draw(N, seed=12) != draws


def test_multiprocessing_equals_serial(draws, serial):
    assert mc.run(draws, backend="multiprocessing", workers=2, chunk=10) == serial


def test_ray_equals_serial(draws, serial):
    pytest.importorskip("ray")
    assert mc.run(draws, backend="ray", workers=2, chunk=10) == serial


def test_summary_of_the_sweep(serial):
    s = mc.summarize(serial)
    print(mc.summary_text(s))
    assert s["flights"] == N and s["crashed"] == 0
    assert s["success_rate"] >= 0.9
    assert s["rmse_cm"]["p50"] < 1.0
