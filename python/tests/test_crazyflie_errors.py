"""hamflight-cf's errors: every user error is one line on stderr ("hamflight-cf: error: ..."),
never a traceback (cflib's included), with exit status 2 for usage errors (all found before
connecting), 1 for failures at run time and 130 for Ctrl-C.

Usage errors need neither cflib nor a radio. The failures at run time go through cflib's own
connection code with its hardware faked where it meets the machine: no Crazyradio plugged in
(``cflib.drivers.crazyradio._find_devices`` finds none), a radio with no Crazyflie in range (a
driver that reports cflib's "Too many packets lost"), a UDP port where nothing answers. The
failures after connecting use a :class:`hcf.Link` whose ``cf`` is a fake (no cflib needed).
"""

import os
import socket
import struct
import subprocess
import sys
import threading
import time
import zlib

import pytest

from hamflight import crazyflie as hcf

try:
    import cflib.crtp
    from cflib.crtp.crtpdriver import CRTPDriver
    from cflib.crtp.exceptions import WrongUriType
except ImportError:  # pragma: no cover
    CRTPDriver = object
    cflib = None

URI = "radio://0/80/2M/E7E7E7E7E7"


@pytest.fixture
def need_cflib():
    if cflib is None:
        msg = "cflib not installed: pip install 'hamflight[crazyflie]'"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)


def run(capsys, argv):
    """main(argv) -> (exit status, stdout, the one stderr line), asserting that stderr is one
    "hamflight-cf: error:" line without a traceback (or empty on success)."""
    try:
        code = hcf.main(argv)
    except SystemExit as e:  # argparse
        code = e.code
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    if code == 0:
        assert err == "", err
        return code, out, ""
    assert err.endswith("\n") and len(err.splitlines()) == 1, err
    assert err.startswith("hamflight-cf: error: "), err
    return code, out, err.strip()


def blob_bytes(body=bytes(range(64)), length=None, crc=None, magic=b"HMFW"):
    """A blob with the tool's own checks' shape: 28-byte header (magic, body length at 24), body,
    CRC-32 of the body."""
    header = bytearray(hcf.BLOB_HEADER_LEN)
    header[:4] = magic
    struct.pack_into("<I", header, 24, len(body) if length is None else length)
    return bytes(header) + body + struct.pack("<I", zlib.crc32(body) if crc is None else crc)


@pytest.fixture
def no_connect(monkeypatch):
    """Fails the test if anything tries to connect: usage errors are found before."""

    class Refuse(hcf.Link):
        def __enter__(self):
            raise AssertionError(f"connected to {self.uri} despite a usage error")

    monkeypatch.setattr(hcf, "Link", Refuse)


USAGE_ERRORS = [
    ([], "the following arguments are required"),
    (["frob", URI], "invalid choice: 'frob'"),
    (["upload", URI], "the following arguments are required: blob"),
    (["log", URI], "the following arguments are required: --out"),
    (["params", URI, "--bogus"], "unrecognized arguments: --bogus"),
    # URIs (cflib: radio, usb, udp, tcp, prrt; debug:// is gone)
    (["params", "E7E7E7E7E7"], "bad URI 'E7E7E7E7E7': expected radio://"),
    (["params", "http://host/"], "unknown scheme 'http://'"),
    (["params", "debug://0/0"], "unknown scheme 'debug://'"),
    (["params", "radio://0"], "no channel"),
    (["params", "radio://x-1/80"], "DONGLE is the Crazyradio's index"),
    (["params", "radio://0/126/2M"], "channel '126': expected 0..125"),
    (["params", "radio://0/80/3M"], "data rate '3M'"),
    (["params", "radio://0/80/2M/E7E7XYZ"], "address 'E7E7XYZ'"),
    (["params", "radio://0/80/2M/E7E7E7E7E7/9"], "expected radio://DONGLE/CHANNEL"),
    (["params", "usb://first"], "expected usb://N"),
    (["params", "udp://localhost"], "expected udp://HOST:PORT"),
    (["params", "udp://localhost:99999"], "expected udp://HOST:PORT"),
    (["params", "tcp://:5000"], "expected tcp://HOST:PORT"),
    # name=value
    (["params", URI, "law"], "'law': expected name=value"),
    (["params", URI, "=1"], "'=1': expected name=value"),
    (["params", URI, "nope=1"], "unknown parameter 'nope'"),
    (["params", URI, "stabilizer.kp=1"], "unknown parameter group 'stabilizer'"),
    (["params", URI, "law=1", "kp=fast"], "'kp=fast': kp takes a finite number"),
    (["params", URI, "kp=inf"], "kp takes a finite number"),
    (["params", URI, "kp="], "kp takes a finite number"),
    (["params", URI, "law=300"], "'law=300': law takes an integer 0..255"),
    (["params", URI, "hamflight.revert=0.5"], "revert takes an integer 0..255"),
    # numbers
    (["log", URI, "--out", "f.csv", "--rate-hz", "500"], "argument --rate-hz: log rate 500 Hz is out of range: 1..100 Hz"),
    (["log", URI, "--out", "f.csv", "--rate-hz", "0.5"], "argument --rate-hz"),
    (["log", URI, "--out", "f.csv", "--rate-hz", "nan"], "argument --rate-hz"),
    (["log", URI, "--out", "f.csv", "--rate-hz", "fast"], "argument --rate-hz: 'fast' is not a number"),
    (["log", URI, "--out", "f.csv", "--seconds", "0"], "argument --seconds"),
    (["upload", URI, "good.hfw", "--wait-s", "-1"], "argument --wait-s"),
    (["params", URI, "--timeout-s", "0"], "argument --timeout-s"),
    # files
    (["log", URI, "--out", "no/such/dir/f.csv"], "no directory"),
    (["log", URI, "--out", "."], "--out .: is a directory"),
    (["upload", URI, "missing.hfw"], "missing.hfw: no such file"),
    (["upload", URI, "."], ".: is a directory"),
    (["upload", URI, "empty.hfw"], "not a hamflight weight blob"),
    (["upload", URI, "text.hfw"], "not a hamflight weight blob"),
    (["upload", URI, "short.hfw"], "its header says"),
    (["upload", URI, "corrupt.hfw"], "CRC does not match"),
]


@pytest.mark.parametrize("argv,cause", USAGE_ERRORS, ids=[" ".join(a) or "no-args" for a, _ in USAGE_ERRORS])
def test_usage_errors_are_one_line_exit_2_before_connecting(argv, cause, capsys, tmp_path, monkeypatch, no_connect):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "good.hfw").write_bytes(blob_bytes())
    (tmp_path / "empty.hfw").write_bytes(b"")
    (tmp_path / "text.hfw").write_text("kp = 1.0\n" * 10)
    (tmp_path / "short.hfw").write_bytes(blob_bytes()[:-10])
    bad = bytearray(blob_bytes())
    bad[40] ^= 1
    (tmp_path / "corrupt.hfw").write_bytes(bytes(bad))
    code, out, err = run(capsys, argv)
    assert code == 2, err
    assert cause in err, err
    assert not (tmp_path / "f.csv").exists()


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root reads any file")
def test_an_unreadable_blob_is_a_usage_error(capsys, tmp_path, no_connect):
    path = tmp_path / "locked.hfw"
    path.write_bytes(blob_bytes())
    path.chmod(0)
    code, _, err = run(capsys, ["upload", URI, str(path)])
    assert code == 2 and "cannot read it" in err, err


def test_without_cflib_the_install_line(capsys, monkeypatch):
    for name in ("cflib", "cflib.crtp", "cflib.crazyflie"):
        monkeypatch.setitem(sys.modules, name, None)
    code, _, err = run(capsys, ["params", URI])
    assert code == 1
    assert err == "hamflight-cf: error: cflib is not installed: pip install 'hamflight[crazyflie]'"


def test_no_crazyradio_dongle(capsys, monkeypatch, need_cflib):
    import cflib.drivers.crazyradio as crazyradio

    monkeypatch.setattr(crazyradio, "_find_devices", lambda serial=None: [])
    code, _, err = run(capsys, ["params", URI, "law=1"])
    assert code == 1
    assert err.startswith("hamflight-cf: error: no Crazyradio dongle found"), err


# A real process, so that stderr is all of it: cflib's logging (which, unconfigured, prints its
# error and traceback to stderr) and its threads' exceptions included.
NO_DONGLE = """
import sys
import cflib.drivers.crazyradio as crazyradio
crazyradio._find_devices = lambda serial=None: []
from hamflight import crazyflie
sys.exit(crazyflie.main(sys.argv[1:]))
"""


def test_no_dongle_in_a_process_prints_one_line(tmp_path, need_cflib):
    blob = tmp_path / "w.hfw"
    blob.write_bytes(blob_bytes())
    for argv in (["params", URI], ["upload", URI, str(blob)], ["log", URI, "--out", str(tmp_path / "f.csv")]):
        proc = subprocess.run([sys.executable, "-c", NO_DONGLE] + argv, capture_output=True, text=True, timeout=60)
        assert proc.returncode == 1, proc.stderr
        assert proc.stderr.startswith("hamflight-cf: error: no Crazyradio dongle found"), proc.stderr
        assert len(proc.stderr.splitlines()) == 1, proc.stderr
    assert not (tmp_path / "f.csv").exists()


def test_a_usage_error_in_a_process(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "hamflight.crazyflie", "log", URI, "--out", str(tmp_path / "f.csv"),
                           "--rate-hz", "500"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.startswith("hamflight-cf: error: argument --rate-hz:") and len(proc.stderr.splitlines()) == 1


class NoCrazyflieInRange(CRTPDriver):
    """A Crazyradio with nothing in range: what cflib's radio driver thread reports once its
    retries run out (radiodriver.py, _RadioDriverThread)."""

    def connect(self, uri, link_statistics_cb, link_error_cb):
        if not uri.startswith("radio://"):
            raise WrongUriType("Not a radio URI")
        threading.Timer(0.05, link_error_cb, ["Too many packets lost"]).start()

    def send_packet(self, pk):
        return True

    def receive_packet(self, wait=0):
        time.sleep(0.01)
        return None

    def close(self):
        pass


def test_no_crazyflie_answers_on_the_radio(capsys, monkeypatch, need_cflib):
    monkeypatch.setattr(cflib.crtp, "CLASSES", [NoCrazyflieInRange])
    monkeypatch.setattr(hcf, "_drivers_ready", True)
    code, _, err = run(capsys, ["params", URI])
    assert code == 1
    assert err.startswith(f"hamflight-cf: error: no Crazyflie answered at {URI}"), err


def test_nothing_answers_on_udp_within_the_timeout(capsys, need_cflib):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as quiet:
        quiet.bind(("127.0.0.1", 0))
        uri = "udp://127.0.0.1:%d" % quiet.getsockname()[1]
        code, _, err = run(capsys, ["params", uri, "--timeout-s", "0.5"])
    assert code == 1
    assert err == (f"hamflight-cf: error: no Crazyflie answered at {uri} within 0.5 s: is it switched on, "
                   "and is the URI its own?")


def test_udp_connection_refused(capsys, need_cflib):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        uri = "udp://127.0.0.1:%d" % s.getsockname()[1]
    code, _, err = run(capsys, ["params", uri, "--timeout-s", "5"])
    assert code == 1
    assert f"no Crazyflie answered at {uri}" in err, err


def test_link_failure_messages_are_one_line():
    tb = "\n\nTraceback (most recent call last):\n  File \"x.py\", line 1\nException: boom\n"
    for message, expected in [
        ("Couldn't load link driver: Cannot find a Crazyradio Dongle" + tb, "no Crazyradio dongle found"),
        ("Couldn't load link driver: [Errno 13] Access denied (insufficient permissions)" + tb, "permission denied"),
        ("Error communicating with crazy radio ,it has probably been unplugged!\nException:x" + tb, "unplugged?"),
        ("Couldn't load link driver: Could not open usb://0" + tb, "no Crazyflie answered on USB"),
        ("Couldn't load link driver: Cannot find radio with serial ABC" + tb, "no Crazyradio with the serial"),
        ("Couldn't load link driver: something new" + tb, "could not open the link to X: something new"),
    ]:
        text = hcf.link_failure("X", message)
        assert expected in text and "\n" not in text and "Traceback" not in text, text


# ---- after connecting: a Link whose Crazyflie is a fake ----


class Toc:
    def __init__(self, names):
        self.names = set(names)

    def get_element_by_complete_name(self, name):
        return name if name in self.names else None


class FakeParam:
    def __init__(self, flashed=True):
        self.toc = Toc([f"hamflight.{n}" for n in hcf.PARAMS] if flashed else ["stabilizer.estimator"])
        self.values = {n: "0" for n in hcf.PARAMS}
        self.sets = []

    def set_value(self, name, value):
        self.sets.append((name, value))
        self.values[name.split(".")[1]] = value

    def get_value(self, name):
        return self.values[name.split(".")[1]]


class FakeLog:
    def __init__(self, flashed=True):
        names = [v for _, vs in hcf.LOG_BLOCKS for v, _ in vs]
        self.toc = Toc(names if flashed else [n for n in names if not n.startswith("hamflight.")])
        self.link = None  # LogConfig.start/stop send nothing

    def add_config(self, lc):
        lc.cf = self


class FakeMem:
    def get_mems(self, kind):
        return []

    def refresh(self, done):
        done()


class FakeCf:
    def __init__(self, flashed=True):
        self.param, self.log, self.mem = FakeParam(flashed), FakeLog(flashed), FakeMem()


def fake_link(monkeypatch, flashed=True, on_enter=None):
    """hcf.Link with its connection replaced by a FakeCf; ``on_enter(link)`` runs at connecting."""
    links = []

    class FakeLink(hcf.Link):
        def __enter__(self):
            self.cf = FakeCf(flashed)
            links.append(self)
            if on_enter:
                on_enter(self)
            return self

        def _close(self):
            self.closed = True

    monkeypatch.setattr(hcf, "Link", FakeLink)
    return links


def test_params_sets_then_shows(capsys, monkeypatch):
    links = fake_link(monkeypatch)
    code, out, _ = run(capsys, ["params", URI, "law=2", "hamflight.kp=0.5"])
    assert code == 0
    assert links[0].cf.param.sets == [("hamflight.law", "2"), ("hamflight.kp", "0.5")]
    assert "hamflight.law = 2" in out.splitlines() and len(out.splitlines()) == len(hcf.PARAMS)
    assert links[0].closed


def test_params_without_the_hamflight_app(capsys, monkeypatch):
    fake_link(monkeypatch, flashed=False)
    code, out, err = run(capsys, ["params", URI, "law=1"])
    assert (code, out) == (1, "")
    assert err == "hamflight-cf: error: the Crazyflie has no hamflight parameters: is the hamflight app flashed?"


def test_upload_without_the_app_memory(capsys, monkeypatch, tmp_path):
    fake_link(monkeypatch)
    blob = tmp_path / "w.hfw"
    blob.write_bytes(blob_bytes())
    code, out, err = run(capsys, ["upload", URI, str(blob)])
    assert code == 1 and out.startswith(f"{blob}: ")
    assert err == "hamflight-cf: error: the Crazyflie has no MEM_TYPE_APP memory: is the hamflight app flashed?"


def test_upload_rejected_by_the_app(capsys, monkeypatch, tmp_path):
    fake_link(monkeypatch)
    monkeypatch.setattr(hcf.AppMemory, "find", staticmethod(lambda mem: object()))

    def reject(app, blob, wait_active_s, wait_landing_s):
        raise hcf.UploadError("the app rejected the blob: vehicle mass outside 0.005..5 kg")

    monkeypatch.setattr(hcf, "upload", reject)
    blob = tmp_path / "w.hfw"
    blob.write_bytes(blob_bytes())
    code, _, err = run(capsys, ["upload", URI, str(blob)])
    assert code == 1
    assert err == "hamflight-cf: error: the app rejected the blob: vehicle mass outside 0.005..5 kg"


def test_a_link_lost_during_an_upload(capsys, monkeypatch, tmp_path):
    links = fake_link(monkeypatch)

    def find(mem):
        links[0].lost = "Too many packets lost"
        raise hcf.UploadError("no answer reading 64 B at 0x0000")

    monkeypatch.setattr(hcf.AppMemory, "find", staticmethod(find))
    blob = tmp_path / "w.hfw"
    blob.write_bytes(blob_bytes())
    code, _, err = run(capsys, ["upload", URI, str(blob)])
    assert code == 1
    assert err == f"hamflight-cf: error: the link to {URI} was lost: Too many packets lost"


def test_log_without_the_hamflight_app(capsys, monkeypatch, tmp_path):
    fake_link(monkeypatch, flashed=False)
    out_csv = tmp_path / "f.csv"
    code, _, err = run(capsys, ["log", URI, "--out", str(out_csv)])
    assert code == 1 and "the Crazyflie does not log hamflight.thrust" in err, err
    assert not out_csv.exists()


def test_log_until_seconds(capsys, monkeypatch, tmp_path, need_cflib):
    fake_link(monkeypatch)
    out_csv = tmp_path / "f.csv"
    code, out, _ = run(capsys, ["log", URI, "--out", str(out_csv), "--seconds", "0.3", "--rate-hz", "50"])
    assert code == 0
    assert "at 50 Hz" in out and "0 rows" in out
    assert out_csv.read_text() == ",".join(hcf.CSV_COLUMNS) + "\n"


def test_a_link_lost_while_logging_keeps_the_rows(capsys, monkeypatch, tmp_path, need_cflib):
    def lose_soon(link):
        threading.Timer(0.3, setattr, [link, "lost", "Too many packets lost"]).start()

    fake_link(monkeypatch, on_enter=lose_soon)
    out_csv = tmp_path / "f.csv"
    code, out, err = run(capsys, ["log", URI, "--out", str(out_csv)])
    assert code == 1 and "0 rows" in out
    assert err == (f"hamflight-cf: error: the link to {URI} was lost after 0 rows (kept in {out_csv}): "
                   "Too many packets lost")
    assert out_csv.exists()


def test_ctrl_c_while_connecting(capsys, monkeypatch):
    def interrupt(link):
        raise KeyboardInterrupt

    fake_link(monkeypatch, on_enter=interrupt)
    code, _, err = run(capsys, ["params", URI])
    assert (code, err) == (130, "hamflight-cf: error: interrupted")


def test_an_unexpected_cflib_exception_is_one_line(capsys, monkeypatch):
    links = fake_link(monkeypatch)

    def timed_out(name, value):
        raise Exception("Connection timed out")

    monkeypatch.setattr(FakeParam, "set_value", lambda self, n, v: timed_out(n, v))
    code, _, err = run(capsys, ["params", URI, "law=1"])
    assert code == 1 and "Connection timed out" in err and "--verbose" in err, err
    assert links[0].closed


def test_subcommand_help_names_units_and_ranges(capsys):
    for command, words in [
        ("upload", ["weight blob", "--wait-s", "seconds", "radio://0/80/2M/E7E7E7E7E7", "2480 MHz"]),
        ("log", ["--rate-hz", "log rate in Hz, 1..100", "10 ms", "--seconds", "N m"]),
        ("params", ["name=value", "0..255", "revert", "--timeout-s"]),
    ]:
        with pytest.raises(SystemExit) as e:
            hcf.main([command, "--help"])
        assert e.value.code == 0
        text = " ".join(capsys.readouterr().out.split())
        for word in words:
            assert word in text, (command, word)
