"""hamflight.Blob: load, validate with typed errors, mass, name, CRC, round trip."""

import copy
import pickle
import zlib

import numpy as np
import pytest

import hamflight
from conftest import ROOT

WEIGHTS = ROOT / "weights" / "default.hfw"


def test_load_and_fields():
    b = hamflight.Blob.load(WEIGHTS)
    data = WEIGHTS.read_bytes()
    assert b.name == "default.hfw"
    assert b.mass_kg == pytest.approx(0.027, rel=1e-6)
    body = data[hamflight.BLOB_HEADER_LEN : -hamflight.BLOB_CRC_LEN]
    assert b.crc == zlib.crc32(body) == int.from_bytes(data[-4:], "little")
    assert b.version == 4 and len(b) == len(data)
    assert b.to_bytes() == data
    assert hamflight.Blob.from_bytes(b.to_bytes()) == b
    assert b.encode() == data  # the core's encoder writes the same bytes
    assert hamflight.Blob.default() == b  # the built-in copy is the repository's file
    hamflight.Blob.validate(data)


def test_pickle_round_trip():
    b = hamflight.Blob.default().with_mass(0.031)
    for back in (pickle.loads(pickle.dumps(b)), copy.deepcopy(b)):
        assert type(back) is hamflight.Blob and back == b
        assert (back.name, back.mass_kg, back.crc, back.to_bytes()) == (b.name, b.mass_kg, b.crc, b.to_bytes())
    # A controller on the unpickled blob flies as one on the original.
    s = ([0, 0, 0.5], np.eye(3), [0, 0, 0], [0, 0, 0], [0.1, 0, 0.5], 0.002)
    a = hamflight.Controller(b).step(*s)
    c = hamflight.Controller(pickle.loads(pickle.dumps(b))).step(*s)
    np.testing.assert_array_equal(a.rpm, c.rpm)


def test_with_mass_round_trips():
    b = hamflight.Blob.default().with_mass(0.034)
    assert b.mass_kg == pytest.approx(0.034)
    again = hamflight.Blob.from_bytes(b.to_bytes())
    assert again.mass_kg == pytest.approx(0.034) and again.crc == b.crc
    assert hamflight.Controller(b).gains["k_p_n_per_m"] == pytest.approx(16 * 0.034, rel=1e-6)


def corrupt(kind):
    data = bytearray(WEIGHTS.read_bytes())
    if kind == "BadMagic":
        data[0] = ord("X")
    elif kind == "UnsupportedVersion":
        data[4] = 9
    elif kind == "ShapeMismatch":
        data[6] = 99
    elif kind == "Truncated":
        data = data[:100]
    elif kind == "TrailingBytes":
        data += b"\0"
    elif kind == "Checksum":
        data[40] ^= 1
    elif kind == "BadMass":
        body = bytearray(data[hamflight.BLOB_HEADER_LEN : -4])
        body[0:4] = np.float32(50.0).tobytes()
        data[hamflight.BLOB_HEADER_LEN : -4] = body
        data[-4:] = zlib.crc32(bytes(body)).to_bytes(4, "little")
    elif kind == "NonFinite":
        body = bytearray(data[hamflight.BLOB_HEADER_LEN : -4])
        body[8:12] = np.float32(np.nan).tobytes()
        data[hamflight.BLOB_HEADER_LEN : -4] = body
        data[-4:] = zlib.crc32(bytes(body)).to_bytes(4, "little")
    return bytes(data)


@pytest.mark.parametrize(
    "kind", ["BadMagic", "UnsupportedVersion", "ShapeMismatch", "Truncated", "TrailingBytes", "Checksum", "BadMass", "NonFinite"]
)
def test_rejected_blobs_raise_blob_error_naming_the_problem(kind, tmp_path):
    data = corrupt(kind)
    for call in (hamflight.Blob.validate, hamflight.Blob.from_bytes, hamflight.Controller):
        with pytest.raises(hamflight.BlobError) as e:
            call(data)
        assert e.value.kind == kind and kind in str(e.value)
        assert isinstance(e.value, ValueError)
    f = tmp_path / "bad.hfw"
    f.write_bytes(data)
    with pytest.raises(hamflight.BlobError, match="bad.hfw"):
        hamflight.Blob.load(f)
    with pytest.raises(hamflight.BlobError, match="bad.hfw"):
        hamflight.Controller(str(f))


def test_missing_file_is_an_os_error():
    with pytest.raises(OSError, match="cannot read weight blob"):
        hamflight.Blob.load("/nonexistent/x.hfw")


def test_controller_from_path_bytes_and_blob_agree():
    args = (np.array([0, 0, 0.5]), np.eye(3), np.zeros(3), np.zeros(3), hamflight.Setpoint([0.1, 0, 0.5]), 0.002)
    outs = [hamflight.Controller(w).step(*args).rpm for w in (WEIGHTS, str(WEIGHTS), WEIGHTS.read_bytes(), hamflight.Blob.load(WEIGHTS))]
    for o in outs[1:]:
        np.testing.assert_array_equal(outs[0], o)
    nominal = hamflight.Controller().step(*args).rpm
    assert not np.array_equal(nominal, outs[0])
    assert hamflight.Controller().model == "nominal" and hamflight.Controller(WEIGHTS).model == "learned"
