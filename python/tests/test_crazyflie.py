"""hamflight-cf (hamflight.crazyflie) against cflib's own memory classes over a fake link.

What is faked: only the Crazyflie object under cflib's ``Memory`` (``cflib.crazyflie.mem``):
``add_port_callback``, ``disconnected`` and ``send_packet``. ``send_packet`` answers the CRTP
memory packets cflib builds (info, read, write channels) from ``ShimMemory``, a Python model of
the shim's MEM_TYPE_APP handler (hamflight_oot.c, "Upload"; the C handler itself is tested in
host-train/tests/bitcraze_oot.rs), whose commit check is the real core decoder
(``hamflight.Blob.validate``). Replies arrive on a thread, as cflib's incoming-packet thread
delivers them. cflib's chunking, reply matching and callbacks run unmodified.
"""

import os
import pathlib
import queue
import csv
import io
import re
import struct
import subprocess
import threading
import zlib

import pytest

import hamflight
from hamflight import crazyflie as hcf

try:
    from cflib.crazyflie.mem import Memory
    from cflib.crtp.crtpstack import CRTPPacket, CRTPPort
    from cflib.utils.callbacks import Caller
except ImportError:  # pragma: no cover
    Memory = None

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def need_cflib():
    if Memory is None:
        msg = "cflib not installed: pip install 'hamflight[crazyflie]'"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)


CAPACITY = 9820


class ShimMemory:
    """The shim's handler: info block, BEGIN/COMMIT, the slot; records every packet. While an
    uploaded blob flies (state active) the slot is busy: BEGIN is refused (in flight, error 64;
    on the ground, error 65 and the compiled-in blob flies again ``revert_after`` reads of the
    info block later); ``land_after`` refusals in flight, the vehicle lands."""

    def __init__(self, airborne=False, corrupt_at=None, land_after=None, revert_after=1):
        self.staging = bytearray(CAPACITY)
        self.holds_bytes = False
        self.land_after = land_after
        self.revert_after = revert_after
        self.reverting = None
        self.refused = 0
        self.len = 0
        self.state = 0
        self.error = 0
        self.staged_crc = 0
        self.source, self.crc, self.mass = 0, hamflight.Blob.default().crc, hamflight.Blob.default().mass_kg
        self.airborne = airborne
        self.corrupt_at = corrupt_at
        self.writes = []  # (addr, len)
        self.reads = []
        self.commits = 0

    def size(self):
        return hcf.DATA_ADDR + CAPACITY

    def info(self):
        b = bytearray(hcf.INFO_BYTES)
        if self.reverting is not None:
            self.reverting -= 1
            if self.reverting <= 0:
                self.reverting = None
                self.source, self.state = 0, 0
                self.crc, self.mass = hamflight.Blob.default().crc, hamflight.Blob.default().mass_kg
        struct.pack_into("<IHBBIfHB", b, 0, hcf.INFO_MAGIC, 2, self.source, self.state, self.crc, self.mass, 3, self.error)
        struct.pack_into("<III", b, 0x14, CAPACITY, self.len, self.staged_crc)
        name = b"uploaded" if self.source else b"default.hfw"
        b[0x20:0x20 + len(name)] = name
        return bytes(b)

    def read(self, addr, n):
        self.reads.append((addr, n))
        if addr + n <= hcf.INFO_BYTES:
            return self.info()[addr:addr + n]
        if addr >= hcf.DATA_ADDR and addr - hcf.DATA_ADDR + n <= CAPACITY and self.holds_bytes:
            off = addr - hcf.DATA_ADDR
            return bytes(self.staging[off:off + n])
        return None

    def write(self, addr, data):
        self.writes.append((addr, len(data)))
        if addr == hcf.CONTROL_ADDR:
            if data[0] == hcf.CMD_BEGIN and len(data) == 5:
                (n,) = struct.unpack_from("<I", data, 1)
                if not 0 < n <= CAPACITY or self.state == hcf.STATE_SWAPPING:
                    return False
                if self.state == hcf.STATE_ACTIVE:
                    self.refused += 1
                    if self.airborne:
                        self.error = hcf.ERR_BUSY_FLYING
                        if self.land_after is not None and self.refused >= self.land_after:
                            self.airborne = False
                    else:
                        self.error = hcf.ERR_BUSY_REVERTING
                        if self.reverting is None:
                            self.reverting = self.revert_after
                    return False
                self.staging[:] = bytes(CAPACITY)
                self.holds_bytes = True
                self.len, self.state, self.error = n, 1, 0
                return True
            if data == bytes([hcf.CMD_COMMIT]) and self.state == 1:
                self.commits += 1
                blob = bytes(self.staging[: self.len])
                try:
                    hamflight.Blob.validate(blob)
                except hamflight.BlobError as e:
                    codes = {"Truncated": 16, "Checksum": 20, "BadMass": 24}
                    self.state, self.error = hcf.STATE_REJECTED, codes.get(e.kind, 22)
                    return True
                self.staged_crc = struct.unpack_from("<I", blob, len(blob) - 4)[0]
                self.state = hcf.STATE_PENDING
                if not self.airborne:  # the swap at the next tick on the ground, in place
                    self.holds_bytes = False
                    self.source, self.crc, self.state = 1, self.staged_crc, hcf.STATE_ACTIVE
                    self.mass = hamflight.Blob.from_bytes(blob).mass_kg
                return True
            return False
        off = addr - hcf.DATA_ADDR
        if addr >= hcf.DATA_ADDR and self.state == 1 and off + len(data) <= self.len:
            self.staging[off:off + len(data)] = data
            if self.corrupt_at is not None and off <= self.corrupt_at < off + len(data):
                self.staging[self.corrupt_at] ^= 0xFF
            return True
        return False


class FakeLink:
    """What cflib's Memory needs of a Crazyflie, answering from a ShimMemory."""

    def __init__(self, shim):
        self.shim = shim
        self.callbacks = []
        self.disconnected = Caller()
        self.replies = queue.Queue()
        self.max_payload = 0
        threading.Thread(target=self._deliver, daemon=True).start()

    def add_port_callback(self, port, cb):
        assert port == CRTPPort.MEM
        self.callbacks.append(cb)

    def send_packet(self, pk, expected_reply=(), timeout=0.2):
        data = bytes(pk.data)
        self.max_payload = max(self.max_payload, len(data))
        assert len(data) <= 30, "a CRTP payload is at most 30 bytes"
        reply = CRTPPacket()
        reply.set_header(CRTPPort.MEM, pk.channel)
        if pk.channel == 0:  # info
            if data[0] == 1:
                reply.data = bytes([1, 1])
            else:
                reply.data = bytes([2, data[1], hcf.MEM_TYPE_APP]) + struct.pack("<I", self.shim.size()) + bytes(8)
        elif pk.channel == 1:  # read: id, addr, len -> id, addr, status, data
            mem_id, addr, n = struct.unpack("<BIB", data[:6])
            got = self.shim.read(addr, n)
            reply.data = struct.pack("<BIB", mem_id, addr, 0 if got is not None else 5) + (got or b"")
            assert len(bytes(reply.data)) <= 30
        else:  # write: id, addr, data -> id, addr, status
            mem_id, addr = struct.unpack("<BI", data[:5])
            ok = self.shim.write(addr, data[5:])
            reply.data = struct.pack("<BIB", mem_id, addr, 0 if ok else 5)
        self.replies.put(reply)

    def _deliver(self):
        while True:
            pk = self.replies.get()
            for cb in self.callbacks:
                cb(pk)


def connect(shim):
    link = FakeLink(shim)
    mem = Memory(link)
    return link, hcf.AppMemory.find(mem, timeout_s=5.0)


def other_blob(mass_kg=0.031):
    return hamflight.Blob.default().with_mass(mass_kg).encode()


def test_upload_chunks_verifies_and_reports_the_active_crc():
    shim = ShimMemory()
    link, app = connect(shim)
    blob = other_blob()
    said = []
    info = hcf.upload(app, blob, say=said.append)
    crc = struct.unpack_from("<I", blob, len(blob) - 4)[0]
    assert (info.state, info.source, info.crc) == (hcf.STATE_ACTIVE, 1, crc)
    assert abs(info.mass_kg - 0.031) < 1e-6
    assert bytes(shim.staging[: len(blob)]) == blob
    # cflib's chunking: 24-byte data packets at increasing addresses, then the COMMIT.
    data = [(a, n) for a, n in shim.writes if a >= hcf.DATA_ADDR]
    assert [a for a, _ in data] == [hcf.DATA_ADDR + 24 * k for k in range(len(data))]
    assert max(n for _, n in data) == 24 and sum(n for _, n in data) == len(blob)
    assert shim.writes[0] == (hcf.CONTROL_ADDR, 5) and shim.writes[-1] == (hcf.CONTROL_ADDR, 1)
    assert max(n for _, n in shim.reads) == 24
    assert link.max_payload <= 30
    assert any("100 %" in s for s in said) and any("identical" in s for s in said)
    assert f"crc {crc:08X}" in said[-1]


def test_a_read_back_mismatch_is_never_committed():
    shim = ShimMemory(corrupt_at=500)
    _, app = connect(shim)
    with pytest.raises(hcf.UploadError, match="read-back differs at byte 500"):
        hcf.upload(app, other_blob(), say=lambda s: None)
    assert shim.commits == 0


def test_the_apps_rejection_is_reported():
    # A valid CRC around a mass the decoder refuses: the file passes the tool's own checks,
    # the app's commit check rejects it.
    blob = bytearray(other_blob())
    struct.pack_into("<f", blob, 28, 10.0)
    struct.pack_into("<I", blob, len(blob) - 4, zlib.crc32(bytes(blob[28:-4])))
    shim = ShimMemory()
    _, app = connect(shim)
    with pytest.raises(hcf.UploadError, match="vehicle mass outside"):
        hcf.upload(app, bytes(blob), say=lambda s: None)
    assert (shim.state, shim.source) == (hcf.STATE_REJECTED, 0)


def test_a_corrupt_file_is_refused_before_anything_is_sent():
    blob = bytearray(other_blob())
    blob[200] ^= 1
    shim = ShimMemory()
    _, app = connect(shim)
    with pytest.raises(hcf.UploadError, match="CRC does not match"):
        hcf.upload(app, bytes(blob), say=lambda s: None)
    assert shim.writes == []


def test_an_upload_in_flight_is_reported_pending():
    shim = ShimMemory(airborne=True)
    _, app = connect(shim)
    said = []
    info = hcf.upload(app, other_blob(), say=said.append, wait_active_s=0.3, poll_s=0.05)
    assert info.state == hcf.STATE_PENDING and info.source == 0
    assert "once the vehicle is not airborne" in said[-1]


def test_log_blocks_fit_cflib_and_the_radio():
    for name, variables in hcf.LOG_BLOCKS:
        size = sum(hcf.TYPE_BYTES[t] for _, t in variables)
        assert size <= hcf.LOG_MAX_PAYLOAD_BYTES, (name, size)
    configs = hcf.log_configs(100.0)
    assert [c.period_in_ms for c in configs] == [10, 10, 10]
    with pytest.raises(ValueError):
        hcf.log_configs(200.0)


def test_csv_columns_are_the_importers_documented_ones():
    # The importer's module doc (host-train/src/data/import/mod.rs today), wherever it moves.
    found = (re.search(r"^//! (t_s,px_m[^\n]*)$", p.read_text(), re.M) for p in sorted((ROOT / "host-train/src").rglob("*.rs")))
    line = next(m for m in found if m).group(1)
    required = line.split(",")
    assert hcf.CSV_COLUMNS[: len(required)] == required
    assert hcf.CSV_COLUMNS[len(required):] == ["ax_m_s2", "ay_m_s2", "az_m_s2"]


def synthetic_hover(path, seconds=6.0, mass_kg=0.027):
    """Log packets of a hover at 0.5 m (climb, hold, land) through the tool's writer."""
    with open(path, "w", newline="") as f:
        w = hcf.CsvLogWriter(f)
        n = int(seconds * 100)
        for k in range(n):
            t_ms = 1000 + 10 * k
            z = 0.5 if 50 <= k < n - 50 else 0.0
            w.add("hfPosVel", t_ms, {f"stateEstimate.{v}": x for v, x in zip(("x", "y", "z", "vx", "vy", "vz"), (0.0, 0.0, z, 0.0, 0.0, 0.0))})
            w.add("hfAttGyro", t_ms, {"stateEstimate.qx": 0.0, "stateEstimate.qy": 0.0, "stateEstimate.qz": 0.0,
                                      "stateEstimate.qw": 1.0, "gyro.x": 0.5 * (k % 3), "gyro.y": 0.0})
            w.add("hfCmd", t_ms, {"gyro.z": 0.0, "hamflight.thrust": mass_kg * 9.81, "hamflight.tx": 0.0,
                                  "hamflight.ty": 0.0, "hamflight.tz": 0.0, "acc.x": 0.0, "acc.y": 0.0, "acc.z": 1.0})
        # A command whose state blocks are stale is dropped, not joined.
        w.add("hfCmd", 1000 + 10 * n + 500, {"gyro.z": 0.0, "hamflight.thrust": 0.1, "hamflight.tx": 0.0,
                                              "hamflight.ty": 0.0, "hamflight.tz": 0.0, "acc.x": 0.0, "acc.y": 0.0, "acc.z": 1.0})
        w.finish()
    return w


CMD = {"gyro.z": 0.0, "hamflight.thrust": 0.3, "hamflight.tx": 0.0, "hamflight.ty": 0.0, "hamflight.tz": 0.0,
       "acc.x": 0.0, "acc.y": 0.0, "acc.z": 1.0}


def pos_vel(z):
    return {f"stateEstimate.{v}": x for v, x in zip(("x", "y", "z", "vx", "vy", "vz"), (0.0, 0.0, z, 0.0, 0.0, 1.0))}


def att_gyro(sign):
    return {"stateEstimate.qw": sign, "stateEstimate.qx": 0.0, "stateEstimate.qy": 0.0, "stateEstimate.qz": 0.0,
            "gyro.x": 0.0, "gyro.y": 0.0}


def test_log_blocks_out_of_phase_are_interpolated_not_dropped():
    # The blocks' timers run out of phase (the whole firmware in SITL: 6-9 ms): the state is
    # interpolated to each command's timestamp; a gap of a lost packet drops the rows it spans.
    f = io.StringIO()
    w = hcf.CsvLogWriter(f)
    for k in range(100):
        t = 1000 + 10 * k
        if k not in (50, 51, 52):  # three position samples lost: a 40 ms gap
            w.add("hfPosVel", t + 7, pos_vel(0.001 * (t + 7)))
        w.add("hfAttGyro", t + 3, att_gyro(1.0 if k % 2 else -1.0))  # q and -q alternate
        w.add("hfCmd", t, CMD)
    w.finish()
    rows = list(csv.DictReader(io.StringIO(f.getvalue())))
    # dropped: the first command (no position sample before it) and the four in the 40 ms gap
    assert (w.rows, w.dropped) == (95, 5)
    assert len(rows) == 95
    for r in rows:
        t_ms = 1000 * float(r["t_s"])
        assert abs(float(r["pz_m"]) - 0.001 * t_ms) < 1e-9  # linear in time: exact
        assert abs(abs(float(r["qw"])) - 1.0) < 1e-9  # never the zero between q and -q
    assert 1500 not in [round(1000 * float(r["t_s"])) for r in rows]


def test_the_log_csv_imports_with_host_train(tmp_path, bridge_binary):
    csv_path = tmp_path / "flight.csv"
    w = synthetic_hover(csv_path)
    assert (w.rows, w.dropped) == (600, 1)
    lines = csv_path.read_text().splitlines()
    assert lines[0] == ",".join(hcf.CSV_COLUMNS) and len(lines) == 601
    first = dict(zip(hcf.CSV_COLUMNS, lines[1].split(",")))
    assert float(first["t_s"]) == 1.0 and abs(float(first["az_m_s2"]) - 9.81) < 1e-6
    out = tmp_path / "data"
    proc = subprocess.run(
        [str(bridge_binary), "import", "--out", str(out), "--mass-kg", "0.027", str(csv_path)],
        capture_output=True, text=True,
    )
    assert proc.returncode == 0, proc.stderr
    # 5 s airborne at 100 Hz, less the importer's 0.5 s trim at take-off and at landing.
    assert "600 samples, 400 kept in 1 flights" in proc.stdout + proc.stderr, proc.stdout
    assert (out / "manifest.json").exists() and (out / "realization_00.csv").exists()


def test_help_explains_the_loop(capsys):
    with pytest.raises(SystemExit) as e:
        hcf.main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for word in ("upload", "log", "params", "26 payload bytes", "100 Hz", "RAM only"):
        assert word in text, word


def test_params_assignments_are_checked():
    assert hcf.parse_assignments(["law=1", "revert=1"]) == [("law", "1"), ("revert", "1")]
    with pytest.raises(ValueError):
        hcf.parse_assignments(["nope=1"])
    with pytest.raises(ValueError):
        hcf.parse_assignments(["law"])


def test_closing_the_link_sends_no_setpoint():
    # cflib's close_link sends a zero setpoint (motors off until the pilot's next one); hamflight-cf
    # runs beside a pilot and must not command the vehicle.
    sent = []

    class Commander:
        def send_setpoint(self, *args):
            sent.append(args)

    class FakeCf:
        commander = Commander()
        closed = False

        def close_link(self):
            self.commander.send_setpoint(0, 0, 0, 0)
            self.closed = True

    link = hcf.Link("udp://127.0.0.1:1")
    link.cf = FakeCf()
    link._close()
    assert link.cf.closed and sent == []


def test_udp_links_ask_for_cflibs_resending():
    import types

    from cflib.crtp.udpdriver import UdpDriver

    crtp = types.SimpleNamespace(CLASSES=[object, UdpDriver])
    hcf._resend_over_udp(crtp)
    assert crtp.CLASSES[0] is object and crtp.CLASSES[1] is not UdpDriver
    driver = crtp.CLASSES[1]()
    assert issubclass(crtp.CLASSES[1], UdpDriver) and not driver.needs_resending
    driver.connect("udp://127.0.0.1:9", None, None)  # a UDP socket needs no listener to open
    try:
        assert driver.needs_resending
    finally:
        driver.close()


def test_an_upload_while_an_uploaded_blob_flies_waits_for_the_landing():
    # The uploaded blob holds the slot: in flight BEGIN is refused until the vehicle lands; on
    # the ground the app hands back to the compiled-in blob, and the retried BEGIN goes through.
    shim = ShimMemory(airborne=True, land_after=5, revert_after=3)
    _, app = connect(shim)
    first = other_blob(0.029)
    hcf.upload(app, first, say=lambda s: None)
    assert shim.state == hcf.STATE_PENDING  # in flight: waits for the landing
    shim.source, shim.crc, shim.state = 1, shim.staged_crc, hcf.STATE_ACTIVE  # landed, swapped, took off
    shim.holds_bytes = False
    with pytest.raises(hcf.UploadError, match="Crazyflie refused the read"):
        app.read(hcf.DATA_ADDR, 24)  # the slot's bytes are decoded in place: no data reads
    said = []
    blob = other_blob(0.031)
    info = hcf.upload(app, blob, say=said.append, poll_s=0.001)
    crc = struct.unpack_from("<I", blob, len(blob) - 4)[0]
    assert (info.state, info.source, info.crc) == (hcf.STATE_ACTIVE, 1, crc)
    assert shim.refused >= 6  # 5 in flight, then at least one on the ground
    assert any("waits until the vehicle has landed" in s for s in said)
    assert any("compiled-in blob first" in s for s in said)


def test_a_busy_app_times_out_and_another_refusal_is_reported():
    shim = ShimMemory(airborne=True)
    _, app = connect(shim)
    shim.source, shim.state = 1, hcf.STATE_ACTIVE
    with pytest.raises(hcf.UploadError, match="still refused after 0 s.*upload active"):
        hcf.upload(app, other_blob(), say=lambda s: None, wait_landing_s=0.0)
    shim.source, shim.state, shim.error = 0, hcf.STATE_REJECTED, 0
    orig = shim.write
    shim.write = lambda addr, data: False if addr == hcf.CONTROL_ADDR else orig(addr, data)
    with pytest.raises(hcf.UploadError, match="BEGIN refused: active blob"):
        hcf.upload(app, other_blob(), say=lambda s: None)
