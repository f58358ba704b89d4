"""The Controller's API: inputs, errors, faults, gains, reset, the batch and the blob."""

import copy
import pathlib
import pickle
import re
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import hamflight
from conftest import ROOT

HOVER = dict(p=np.array([0.0, 0.0, 0.5]), R=np.eye(3), v_body=np.zeros(3), w_body=np.zeros(3))


def step(ctrl, **over):
    args = {**HOVER, **over}
    sp = args.pop("setpoint", hamflight.Setpoint([0.1, 0.0, 0.5]))
    dt = args.pop("dt", 0.002)
    return ctrl.step(args["p"], args["R"], args["v_body"], args["w_body"], sp, dt, acc=args.get("acc"))


def test_version_is_the_rust_crates_version():
    text = (ROOT / "host-train" / "Cargo.toml").read_text()
    version = re.search(r'^version = "([^"]+)"', text, re.M).group(1)
    assert hamflight.__version__ == version == "0.1.0"


def test_step_gives_a_typed_result_with_named_fields():
    c = hamflight.Controller.named("adaptive")
    out = step(c)
    assert isinstance(out, hamflight.StepResult)
    assert out.rpm.shape == (4,) and out.rpm.dtype == np.float32
    assert out.rotor_thrust_n.shape == (4,)
    assert out.torque_nm.shape == (3,) and out.wrench.shape == (4,)
    assert out.wrench[0] == np.float32(out.thrust_n)
    assert out.a.shape == (6,)
    assert isinstance(out.faults, hamflight.Faults) and not out.faults
    # Hover thrust near m g for the 27 g vehicle, pulling toward +x.
    assert 0.2 < out.thrust_n < 0.4
    assert np.all(out.rpm > 10000)


@pytest.mark.parametrize(
    "arg, bad, shape",
    [
        ("p", np.zeros(4), "(3,)"),
        ("p", np.zeros((3, 1)), "(3,)"),
        ("R", np.eye(4), "(3, 3)"),
        ("R", np.zeros(9), "(3, 3)"),
        ("v_body", np.zeros(2), "(3,)"),
        ("w_body", np.zeros(3, dtype=np.complex128), "(3,)"),
        ("w_body", np.zeros(3, dtype=bool), "(3,)"),
        ("w_body", "abc", "(3,)"),
        ("acc", np.zeros(5), "(3,)"),
    ],
)
def test_wrong_shapes_and_dtypes_raise_value_error_naming_the_shape(arg, bad, shape):
    c = hamflight.Controller()
    with pytest.raises(ValueError) as e:
        step(c, **{arg: bad})
    msg = str(e.value)
    assert msg.startswith(arg + ":") and f"shape {shape}" in msg, msg


def test_inputs_may_be_float32_or_lists_and_give_the_same_result():
    a = step(hamflight.Controller())
    b = step(hamflight.Controller(), p=[0, 0, 0.5], R=np.eye(3, dtype=np.float32), v_body=(0, 0, 0), w_body=np.zeros(3, dtype=np.float32))
    c = step(hamflight.Controller(), p=np.array([0.0, 0.0, 0.5, 9.0])[:3], R=np.asfortranarray(np.eye(3)))
    np.testing.assert_array_equal(a.rpm, b.rpm)
    np.testing.assert_array_equal(a.rpm, c.rpm)


def test_integer_arrays_are_accepted_as_floats_are():
    acc = np.array([0.0, 0.0, 10.0])
    a = step(hamflight.Controller(), p=np.array([0.0, 0.0, 1.0]), setpoint=np.array([1.0, 0.0, 1.0]), acc=acc)
    b = step(hamflight.Controller(), p=np.array([0, 0, 1]), R=np.eye(3, dtype=np.int32), v_body=np.zeros(3, np.int8),
             w_body=np.zeros(3, np.uint16), setpoint=np.array([1, 0, 1]), acc=acc.astype(np.int64))
    np.testing.assert_array_equal(a.rpm, b.rpm)
    c = step(hamflight.Controller(), p=np.array([0, 0, 1]), setpoint=hamflight.Setpoint(np.array([1, 0, 1]), v_m_s=np.zeros(3, int)), acc=acc)
    d = step(hamflight.Controller(), p=np.array([0, 0, 1]), setpoint={"p": np.array([1, 0, 1]), "yaw": np.int64(0)}, acc=acc)
    np.testing.assert_array_equal(a.rpm, c.rpm)
    np.testing.assert_array_equal(a.rpm, d.rpm)
    n = 3
    floats = [np.tile([0.0, 0.0, 1.0], (n, 1)), np.repeat(np.eye(3)[None], n, axis=0), np.zeros((n, 3)), np.zeros((n, 3))]
    ints = [x.astype(np.int64) for x in floats]
    sp = {"p": np.tile([1, 0, 1], (n, 1)), "yaw": np.zeros(n, np.int32)}
    x = hamflight.ControllerBatch(n).step(*floats, {"p": np.tile([1.0, 0.0, 1.0], (n, 1))}, 0.002)
    y = hamflight.ControllerBatch(n).step(*ints, sp, 0.002, acc=None)
    np.testing.assert_array_equal(x.rpm, y.rpm)
    # The SITL plant's rotor speeds too.
    plant = hamflight.sitl.Plant(hamflight.sitl.Scenario.load("hover"))
    o1 = plant.step_rpm(np.full(4, 15000.0))
    plant.reset()
    np.testing.assert_array_equal(o1, plant.step_rpm(np.full(4, 15000)))


@pytest.mark.parametrize("gain, value", [("k_p_n_per_m", -1.0), ("c_v", float("nan")), ("motor_tau_s", float("inf")), ("a_max", 1e39)])
def test_negative_or_non_finite_gains_are_refused_naming_the_gain(gain, value):
    msg = rf"^{gain}: expected a finite number >= 0, got "
    with pytest.raises(ValueError, match=msg):
        hamflight.Controller(**{gain: value})
    with pytest.raises(ValueError, match=msg):
        hamflight.Controller.named("adaptive", **{gain: value})
    with pytest.raises(ValueError, match=msg):
        hamflight.ControllerBatch(2, **{gain: value})
    c = hamflight.Controller()
    before = c.gains
    with pytest.raises(ValueError, match=msg):
        c.set_gains(k_v_n_s_per_m=0.5, **{gain: value})
    assert c.gains == before  # nothing changed
    assert hamflight.Controller(**{gain: 0.0}).gains[gain] == 0.0  # zero is a gain (off)


def test_setpoint_forms_agree():
    sp = hamflight.Setpoint([0.1, 0, 0.5], v_m_s=[0.1, 0, 0], yaw_rad=0.2)
    a = step(hamflight.Controller(), setpoint=sp)
    b = step(hamflight.Controller(), setpoint={"p": [0.1, 0, 0.5], "v": [0.1, 0, 0], "yaw": 0.2})
    np.testing.assert_array_equal(a.rpm, b.rpm)
    c = step(hamflight.Controller(), setpoint=np.array([0.1, 0, 0.5]))
    d = step(hamflight.Controller(), setpoint=hamflight.Setpoint([0.1, 0, 0.5]))
    np.testing.assert_array_equal(c.rpm, d.rpm)
    with pytest.raises(ValueError, match='unknown key "q"'):
        step(hamflight.Controller(), setpoint={"p": [0, 0, 1], "q": 1})
    with pytest.raises(ValueError, match="'p' is required"):
        step(hamflight.Controller(), setpoint={"v": [0, 0, 1]})


@pytest.mark.parametrize(
    "over, flag",
    [
        ({"p": np.array([np.nan, 0, 0.5])}, "bad_state"),
        ({"w_body": np.array([0, np.inf, 0])}, "bad_state"),
        ({"R": np.diag([1.0, 1.0, -1.0])}, "bad_state"),
        ({"setpoint": hamflight.Setpoint([np.nan, 0, 1])}, "bad_setpoint"),
        ({"dt": 0.0}, "bad_dt"),
        ({"dt": 0.5}, "bad_dt"),
        ({"dt": float("nan")}, "bad_dt"),
    ],
)
def test_non_finite_input_gives_the_safe_fault_motors_off(over, flag):
    c = hamflight.Controller.named("adaptive")
    step(c)
    out = step(c, **over)
    assert out.faults.fault and getattr(out.faults, flag) and bool(out.faults)
    np.testing.assert_array_equal(out.rpm, np.zeros(4, np.float32))
    np.testing.assert_array_equal(out.rotor_thrust_n, np.zeros(4, np.float32))
    assert out.thrust_n == 0.0
    # It recovers on the next good input.
    assert not step(c).faults.fault


def test_gains_and_law_as_keywords():
    c = hamflight.Controller(law="composite", k_p_n_per_m=0.5, max_tilt_rad=0.4, motor_tau_s=0.07)
    g = c.gains
    assert g["law"] == "composite" and g["adapt"] is True
    assert g["k_p_n_per_m"] == pytest.approx(0.5) and g["max_tilt_rad"] == pytest.approx(0.4)
    assert g["motor_tau_s"] == pytest.approx(0.07)
    assert set(hamflight.GAIN_KEYWORDS) <= set(g)
    default = hamflight.Controller().gains
    assert default["k_p_n_per_m"] == pytest.approx(16 * 0.027) and default["law"] == "composite"
    with pytest.raises(TypeError, match='unexpected keyword argument "kp"'):
        hamflight.Controller(kp=1.0)
    with pytest.raises(ValueError, match="law"):
        hamflight.Controller(law="fast")
    with pytest.raises(ValueError, match="unknown controller"):
        hamflight.Controller.named("nope")
    c.set_gains(law="gradient", adapt=False)
    assert c.gains["law"] == "gradient" and c.gains["adapt"] is False
    # Different gains give a different command.
    a = step(hamflight.Controller(k_p_n_per_m=0.1))
    b = step(hamflight.Controller(k_p_n_per_m=0.9))
    assert not np.array_equal(a.rpm, b.rpm)


def test_reset_clears_the_estimate_and_replays_identically():
    c = hamflight.Controller.named("adaptive")
    first = [step(c, p=np.array([0.02 * k, 0, 0.5])).rpm for k in range(50)]
    assert np.any(c.a != 0)
    c.reset()
    assert np.all(c.a == 0)
    again = [step(c, p=np.array([0.02 * k, 0, 0.5])).rpm for k in range(50)]
    np.testing.assert_array_equal(np.array(first), np.array(again))


def _trace(ctrl, n=120):
    """rpm and a over n steps toward a moving position (the estimate adapts)."""
    rows = []
    for k in range(n):
        out = step(ctrl, p=np.array([0.02 * k, 0.0, 0.5]), v_body=np.array([0.05, 0.0, 0.0]))
        rows.append(np.concatenate([out.rpm, out.a]))
    return np.array(rows)


PICKLED = [
    *[(lambda n=n: hamflight.Controller.named(n)) for n in hamflight.CONTROLLER_NAMES],
    lambda: hamflight.Controller(),
    lambda: hamflight.Controller(hamflight.Blob.default().with_mass(0.031), law="gradient", c_p=3.0),
    lambda: hamflight.Controller.named("adaptive", weights=hamflight.Blob.default().with_mass(0.03), k_p_n_per_m=0.6),
]


@pytest.mark.parametrize("make", PICKLED, ids=[*hamflight.CONTROLLER_NAMES, "nominal", "blob-gradient", "named-blob"])
def test_pickle_round_trip_gives_the_same_controller(make):
    c = make()
    c.set_gains(max_tilt_rad=0.6)
    back = pickle.loads(pickle.dumps(c))
    assert type(back) is hamflight.Controller
    assert (back.name, back.model, back.mass_kg, back.gains) == (c.name, c.model, c.mass_kg, c.gains)
    # Bit-identical outputs on the same inputs.
    np.testing.assert_array_equal(_trace(back), _trace(c))
    # copy.deepcopy takes the same path (the estimate restarts, as a fresh controller's).
    fresh = make()
    fresh.set_gains(max_tilt_rad=0.6)
    np.testing.assert_array_equal(_trace(copy.deepcopy(c)), _trace(fresh))


def test_pickle_does_not_carry_the_estimate_the_copy_starts_as_after_reset():
    c = hamflight.Controller.named("adaptive")
    _trace(c)
    assert np.any(c.a != 0)
    back = pickle.loads(pickle.dumps(c))
    assert np.all(back.a == 0)  # the estimate restarts
    c.reset()
    np.testing.assert_array_equal(_trace(back), _trace(c))


def test_controller_crosses_a_process_boundary():
    c = hamflight.Controller.named("adaptive")
    with ProcessPoolExecutor(1) as pool:
        remote = pool.submit(_trace, c).result()
    np.testing.assert_array_equal(remote, _trace(c))


def test_batch_equals_single_controllers():
    rng = np.random.default_rng(1)
    n = 16
    singles = [hamflight.Controller.named("adaptive-composite") for _ in range(n)]
    batch = hamflight.ControllerBatch(controllers=singles)
    assert len(batch) == n
    for k in range(30):
        p = rng.normal(0, 0.05, (n, 3)) + [0, 0, 0.5]
        R = np.repeat(np.eye(3)[None], n, axis=0)
        v = rng.normal(0, 0.1, (n, 3))
        w = rng.normal(0, 0.1, (n, 3))
        sp = {"p": np.tile([0.1, 0, 0.5], (n, 1)), "yaw": np.full(n, 0.1)}
        acc = np.tile([0, 0, 9.8], (n, 1)) if k % 2 else None
        out = batch.step(p, R, v, w, sp, 0.002, acc=acc)
        assert out.rpm.shape == (n, 4) and out.a.shape == (n, 6) and out.fault.shape == (n,)
        for i, c in enumerate(singles):
            o = c.step(p[i], R[i], v[i], w[i], {"p": [0.1, 0, 0.5], "yaw": 0.1}, 0.002, acc=None if acc is None else acc[i])
            np.testing.assert_array_equal(o.rpm, out.rpm[i])
            np.testing.assert_array_equal(o.a, out.a[i])
            assert o.thrust_n == out.thrust_n[i]
    with pytest.raises(ValueError, match=r"R: expected .* shape \(16, 3, 3\)"):
        batch.step(p, np.zeros((n, 3)), v, w, sp, 0.002)
    with pytest.raises(ValueError, match=r"p: expected shape \(16, 3\)"):
        batch.step(p[:3], R[:3], v[:3], w[:3], sp, 0.002)


def test_batch_from_n_and_reset():
    b = hamflight.ControllerBatch(8, hamflight.Blob.default(), law="composite")
    n = 8
    p = np.tile([0.0, 0.0, 0.5], (n, 1))
    R = np.repeat(np.eye(3)[None], n, axis=0)
    for _ in range(20):
        b.step(p, R, np.zeros((n, 3)), np.zeros((n, 3)), hamflight.Setpoint([0.1, 0, 0.5]), np.full(n, 0.002))
    assert np.any(b.a != 0)
    b.reset(3)
    assert np.all(b.a[3] == 0) and np.any(b.a[2] != 0)
    b.reset()
    assert np.all(b.a == 0)
    p[5, 0] = np.nan
    out = b.step(p, R, np.zeros((n, 3)), np.zeros((n, 3)), hamflight.Setpoint([0.1, 0, 0.5]), 0.002)
    assert out.fault.tolist() == [i == 5 for i in range(n)]
    assert np.all(out.rpm[5] == 0)
