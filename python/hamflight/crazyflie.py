"""hamflight-cf: weights and logs over the Crazyflie radio, with Bitcraze's cflib.

Subcommands (``hamflight-cf --help``, or ``python -m hamflight.crazyflie``):

- ``upload URI FILE.hfw``: writes a weight blob into the app's MEM_TYPE_APP memory (the shim's
  RAM slot), reads it back, commits it and waits until it flies (the app swaps it in only
  while the vehicle is not airborne), then reports the active blob's CRC. While an uploaded
  blob flies, the slot is busy: the app refuses a new upload in flight, and the tool waits for
  the landing, then uploads (so an upload in flight still flies from the landing on);
- ``log URI --out flight.csv``: records the variables ``host-train import`` needs, as its CSV;
- ``params URI [name=value ...]``: shows (and sets) the ``hamflight`` parameters.

The memory layout and protocol are the shim's (``firmware/bitcraze-app/hamflight_oot.c``,
"Upload"): an info block at 0x0000, a control word at 0x0040 (BEGIN + length, COMMIT), the
slot's bytes at 0x1000 (readable only until the swap decodes them in place). cflib splits every
read and write into 24-byte packets.

cflib is an optional dependency: ``pip install 'hamflight[crazyflie]'``. Everything but the
connection itself (:class:`Link`) takes cflib's objects as arguments, so the tests drive it with
cflib's own :class:`cflib.crazyflie.mem.Memory` over a fake link.

Errors (:func:`main`): one line on stderr, ``hamflight-cf: error: <cause>``, never a traceback
(cflib's own logging and thread exceptions are silenced unless ``--verbose``); exit status 2 for
usage errors, all found before connecting (arguments, URI, ``name=value``, the blob file), 1 for
failures at run time (cflib missing, no dongle, no answer, link lost, upload rejected), 130 for
Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import logging
import math
import os
import re
import struct
import sys
import threading
import time
import zlib
from dataclasses import dataclass
from typing import Callable, Dict, Iterable, List, Optional, Sequence, TextIO, Tuple
from urllib.parse import urlsplit

#: MEM_TYPE_APP (crazyflie-firmware mem.h; cflib MemoryElement.TYPE_APP).
MEM_TYPE_APP = 0x18
#: The shim's address layout.
INFO_ADDR = 0x0000
INFO_BYTES = 0x40
CONTROL_ADDR = 0x0040
DATA_ADDR = 0x1000
INFO_MAGIC = 0x50554648  # "HFUP"
LAYOUT_VERSION = 2
CMD_BEGIN = 1
CMD_COMMIT = 2
#: Upload states (the info block's byte 7, log hamflight.upState).
STATE_NAMES = {0: "idle", 1: "receiving", 2: "pending", 3: "swapping", 4: "active", 5: "rejected"}
STATE_PENDING, STATE_SWAPPING, STATE_ACTIVE, STATE_REJECTED = 2, 3, 4, 5
#: HF_ERR_* of include/hamflight.h.
ERROR_NAMES = {
    16: "truncated (shorter than its header says)",
    17: "not a hamflight blob (bad magic)",
    18: "unsupported format version",
    19: "network shapes differ from the firmware's",
    20: "CRC mismatch (corrupt or torn upload)",
    21: "bytes after the CRC",
    22: "malformed body",
    23: "NaN or infinite parameter",
    24: "vehicle mass outside 0.005..5 kg",
    25: "motor time constant outside 0..1 s",
    26: "self test failed (hover thrust not m g +- 20 %)",
    27: "port terms that cannot fly (an input gain, a lag or a negative dissipation)",
    64: "busy: an uploaded model is flying; land first",
    65: "busy: handing back to the compiled-in model; retry BEGIN",
}
#: The shim's refusals of a BEGIN while an uploaded blob flies from the slot.
ERR_BUSY_FLYING, ERR_BUSY_REVERTING = 64, 65
BLOB_HEADER_LEN = 28
BLOB_CRC_LEN = 4


class UploadError(RuntimeError):
    """The upload did not end with the blob flying (or pending): the message says why."""


@dataclass
class Info:
    """The app memory's info block (hamflight_oot.c, "Upload")."""

    magic: int
    layout: int
    source: int  # 0 compiled-in, 1 uploaded
    state: int
    crc: int
    mass_kg: float
    version: int
    error: int
    capacity_bytes: int
    upload_len_bytes: int
    staged_crc: int
    name: str

    @staticmethod
    def parse(b: bytes) -> "Info":
        if len(b) < INFO_BYTES:
            raise UploadError(f"info block of {len(b)} B, expected {INFO_BYTES}")
        magic, layout, source, state, crc, mass, version, error = struct.unpack_from("<IHBBIfHB", b, 0)
        capacity, length, staged = struct.unpack_from("<III", b, 0x14)
        name = bytes(b[0x20:0x40]).split(b"\0", 1)[0].decode("ascii", "replace")
        return Info(magic, layout, source, state, crc, mass, version, error, capacity, length, staged, name)

    def describe(self) -> str:
        src = "uploaded" if self.source else f"compiled-in {self.name}"
        text = f"active blob: {src}, crc {self.crc:08X}, {self.mass_kg * 1000:.1f} g; upload {STATE_NAMES.get(self.state, self.state)}"
        if self.state == STATE_REJECTED:
            text += f" ({ERROR_NAMES.get(self.error, self.error)})"
        return text


def blob_crc(blob: bytes) -> int:
    """The body CRC a blob stores in its last four bytes, checked against the body (zlib's
    CRC-32 is the blob's IEEE CRC-32) and against the header's length."""
    if len(blob) < BLOB_HEADER_LEN + BLOB_CRC_LEN or blob[:4] != b"HMFW":
        raise UploadError("not a hamflight weight blob (no HMFW header)")
    (body_len,) = struct.unpack_from("<I", blob, 24)
    if BLOB_HEADER_LEN + body_len + BLOB_CRC_LEN != len(blob):
        raise UploadError(f"blob of {len(blob)} B, its header says {BLOB_HEADER_LEN + body_len + BLOB_CRC_LEN} B")
    (stored,) = struct.unpack_from("<I", blob, len(blob) - BLOB_CRC_LEN)
    if zlib.crc32(blob[BLOB_HEADER_LEN:-BLOB_CRC_LEN]) != stored:
        raise UploadError("the blob's CRC does not match its body (corrupt file)")
    return stored


class AppMemory:
    """Blocking reads and writes of the app memory through cflib's :class:`Memory` (``cf.mem``),
    which chunks them into 24-byte packets and matches the replies."""

    def __init__(self, mem, element, timeout_s: float = 10.0):
        self.mem = mem
        self.element = element
        self.timeout_s = timeout_s
        self._done = threading.Event()
        self._ok = False
        self._data = b""
        mem.mem_write_cb.add_callback(self._write_ok)
        mem.mem_write_failed_cb.add_callback(self._write_failed)
        mem.mem_read_cb.add_callback(self._read_ok)
        mem.mem_read_failed_cb.add_callback(self._read_failed)

    @staticmethod
    def find(mem, timeout_s: float = 10.0) -> "AppMemory":
        """The MEM_TYPE_APP memory of ``mem`` (refreshing cflib's list once if needed)."""
        found = mem.get_mems(MEM_TYPE_APP)
        if not found:
            done = threading.Event()
            mem.refresh(done.set)
            if not done.wait(timeout_s):
                raise UploadError("no answer to the memory list request")
            found = mem.get_mems(MEM_TYPE_APP)
        if not found:
            raise UploadError("the Crazyflie has no MEM_TYPE_APP memory: is the hamflight app flashed?")
        return AppMemory(mem, found[0], timeout_s)

    def _matches(self, m) -> bool:
        return m.id == self.element.id

    def _write_ok(self, m, addr):
        if self._matches(m):
            self._ok = True
            self._done.set()

    def _write_failed(self, m, addr):
        if self._matches(m):
            self._ok = False
            self._done.set()

    def _read_ok(self, m, addr, data):
        if self._matches(m):
            self._ok, self._data = True, bytes(data)
            self._done.set()

    def _read_failed(self, m, addr, data=None):
        if self._matches(m):
            self._ok = False
            self._done.set()

    def write(self, addr: int, data: bytes, progress: Optional[Callable[[str, int], None]] = None) -> bool:
        """True if every packet was acknowledged with status OK."""
        self._done.clear()
        self.mem.write(self.element, addr, bytearray(data), progress_cb=progress)
        if not self._done.wait(self.timeout_s):
            raise UploadError(f"no answer writing {len(data)} B at 0x{addr:04X}")
        return self._ok

    def read(self, addr: int, length: int) -> bytes:
        self._done.clear()
        if not self.mem.read(self.element, addr, length):
            raise UploadError("cflib refused the read (another read of this memory is running)")
        if not self._done.wait(self.timeout_s):
            raise UploadError(f"no answer reading {length} B at 0x{addr:04X}")
        if not self._ok:
            raise UploadError(f"the Crazyflie refused the read of {length} B at 0x{addr:04X}")
        return self._data

    def info(self) -> Info:
        return Info.parse(self.read(INFO_ADDR, INFO_BYTES))


def begin(
    app: AppMemory,
    length: int,
    say: Callable[[str], None] = print,
    wait_landing_s: float = 600.0,
    poll_s: float = 0.1,
    report_every_s: float = 10.0,
) -> None:
    """BEGIN an upload of ``length`` bytes, retried while the app is busy: while it swaps a
    model, and while an uploaded blob flies from the slot (in flight: until the vehicle has
    landed, with a message every ``report_every_s``; on the ground: until the app has handed the
    controller back to the compiled-in blob). Raises :class:`UploadError` after
    ``wait_landing_s`` or for another refusal."""
    start = time.monotonic()
    told = -1
    next_report = start + report_every_s
    while not app.write(CONTROL_ADDR, struct.pack("<BI", CMD_BEGIN, length)):
        info = app.info()
        now = time.monotonic()
        busy = info.state == STATE_ACTIVE and info.error in (ERR_BUSY_FLYING, ERR_BUSY_REVERTING)
        if not busy and info.state != STATE_SWAPPING:
            raise UploadError("BEGIN refused: " + info.describe())
        if busy and info.error == ERR_BUSY_FLYING:
            if told != ERR_BUSY_FLYING:
                say("an uploaded blob is flying and holds the slot: the upload waits until the vehicle "
                    "has landed")
                next_report = now + report_every_s
            elif now >= next_report:
                say(f"still waiting for the landing ({now - start:.0f} s)")
                next_report = now + report_every_s
        elif busy and told != ERR_BUSY_REVERTING:
            say("handing the controller back to the compiled-in blob first")
        told = info.error if busy else -1
        if now - start >= wait_landing_s:
            raise UploadError(f"BEGIN still refused after {wait_landing_s:.0f} s: " + info.describe())
        time.sleep(poll_s)


def upload(
    app: AppMemory,
    blob: bytes,
    say: Callable[[str], None] = print,
    wait_active_s: float = 5.0,
    poll_s: float = 0.1,
    wait_landing_s: float = 600.0,
) -> Info:
    """BEGIN (:func:`begin`: waits while an uploaded blob flies), the blob at 0x1000 (cflib's
    24-byte packets, progress through ``say``), a read-back compared byte for byte, COMMIT, then
    the info block until the blob flies: returns it. A blob that waits for the landing returns
    with state "pending". Raises :class:`UploadError` for anything else (nothing is committed
    unless the read-back matched). After the COMMIT only the info block is read: the app decodes
    the slot's bytes in place, and refuses data reads from the swap on."""
    crc = blob_crc(blob)
    info = app.info()
    if info.magic != INFO_MAGIC or info.layout != LAYOUT_VERSION:
        raise UploadError(f"app memory is not hamflight's upload layout {LAYOUT_VERSION} (magic {info.magic:08X}, "
                          f"layout {info.layout}): flash a matching firmware")
    if len(blob) > info.capacity_bytes:
        raise UploadError(f"blob of {len(blob)} B, the slot holds {info.capacity_bytes} B")
    begin(app, len(blob), say, wait_landing_s, poll_s)
    last = [-1]

    def progress(_msg: str, percent: int) -> None:
        if percent // 10 != last[0] // 10:
            say(f"upload {percent:3d} %")
        last[0] = percent

    if not app.write(DATA_ADDR, blob, progress):
        raise UploadError("a data packet was refused")
    back = app.read(DATA_ADDR, len(blob))
    if back != blob:
        bad = next(i for i, (a, b) in enumerate(zip(back, blob)) if a != b) if len(back) == len(blob) else len(back)
        raise UploadError(f"read-back differs at byte {bad}: not committed")
    say(f"read back {len(blob)} B: identical")
    if not app.write(CONTROL_ADDR, bytes([CMD_COMMIT])):
        raise UploadError("COMMIT refused")
    deadline = time.monotonic() + wait_active_s
    while True:
        info = app.info()
        if info.state == STATE_REJECTED:
            raise UploadError(f"the app rejected the blob: {ERROR_NAMES.get(info.error, info.error)}")
        if info.state == STATE_ACTIVE and info.crc == crc:
            say(info.describe())
            return info
        if time.monotonic() >= deadline:
            if info.state == STATE_PENDING and info.staged_crc == crc:
                say(f"checked (crc {crc:08X}); it flies once the vehicle is not airborne (and the "
                    "out-of-tree controller runs): " + info.describe())
                return info
            raise UploadError("no confirmation: " + info.describe())
        time.sleep(poll_s)


# ---- logs ----

#: host-train import's CSV columns (host-train/src/data/import.rs, "(b) CSV"), with the optional
#: accelerometer.
CSV_COLUMNS = [
    "t_s", "px_m", "py_m", "pz_m", "qw", "qx", "qy", "qz",
    "vx_world_m_s", "vy_world_m_s", "vz_world_m_s", "wx_rad_s", "wy_rad_s", "wz_rad_s",
    "f_n", "tau_x_nm", "tau_y_nm", "tau_z_nm", "ax_m_s2", "ay_m_s2", "az_m_s2",
]
#: Three log blocks, each within cflib's LogConfig.MAX_LEN of 26 payload bytes per packet:
#: (name, [(variable, cflib type)]). The accelerometer travels as FP16 (3 significant digits).
LOG_BLOCKS: List[Tuple[str, List[Tuple[str, str]]]] = [
    ("hfPosVel", [(f"stateEstimate.{v}", "float") for v in ("x", "y", "z", "vx", "vy", "vz")]),
    ("hfAttGyro", [(f"stateEstimate.{v}", "float") for v in ("qx", "qy", "qz", "qw")]
     + [("gyro.x", "float"), ("gyro.y", "float")]),
    ("hfCmd", [("gyro.z", "float")] + [(f"hamflight.{v}", "float") for v in ("thrust", "tx", "ty", "tz")]
     + [(f"acc.{v}", "FP16") for v in ("x", "y", "z")]),
]
TYPE_BYTES = {"float": 4, "FP16": 2, "uint8_t": 1, "uint32_t": 4}
LOG_MAX_PAYLOAD_BYTES = 26
#: cflib's log period is in units of 10 ms: 100 Hz is the fastest any block can run (and one
#: byte of them, 2.55 s, the slowest; the tool takes 1 Hz as its floor).
MAX_LOG_RATE_HZ = 100.0
MIN_LOG_RATE_HZ = 1.0
G_M_S2 = 9.81


class CsvLogWriter:
    """Joins the three blocks into the importer's CSV rows: a row at each ``hfCmd`` sample, with
    the ``hfPosVel`` and ``hfAttGyro`` values interpolated to its timestamp from their samples on
    either side (linear; the quaternion normalized, sign-aligned). The blocks run on timers of
    their own, started one after the other, so their samples need not share a tick: the whole
    firmware in SITL put them 6-9 ms apart, and an earlier exact-match join within 5 ms dropped
    every row. A row waits until both blocks have a sample at or after it; one whose neighbours
    are more than ``max_gap_ms`` apart (a lost packet), or with no sample before it, is dropped and
    counted in ``dropped``, as are the rows still waiting at :meth:`finish`. Time is the
    firmware's millisecond timestamp, in s."""

    STATE_BLOCKS = ("hfPosVel", "hfAttGyro")

    def __init__(self, out: TextIO, max_gap_ms: float = 30.0):
        self.writer = csv.writer(out, lineterminator="\n")
        self.writer.writerow(CSV_COLUMNS)
        self.max_gap_ms = max_gap_ms
        self.history: Dict[str, List[Tuple[int, Dict[str, float]]]] = {b: [] for b in self.STATE_BLOCKS}
        self.pending: List[Tuple[int, Dict[str, float]]] = []
        self.rows = 0
        self.dropped = 0

    def add(self, block: str, timestamp_ms: int, data: Dict[str, float]) -> None:
        """One log packet, as cflib's ``LogConfig.data_received_cb`` gives it."""
        if block == "hfCmd":
            self.pending.append((timestamp_ms, data))
        elif block in self.history:
            h = self.history[block]
            h.append((timestamp_ms, data))
            del h[:-8]
        self._flush()

    def finish(self) -> None:
        """The log ended: rows still waiting for a later state sample are dropped."""
        self.dropped += len(self.pending)
        self.pending.clear()

    def _state_at(self, block: str, t_ms: int):
        """(values at t_ms) or "wait" (no sample at or after t_ms yet) or None (cannot be had)."""
        h = self.history[block]
        if not h or h[-1][0] < t_ms:
            return "wait"
        after = next(i for i, (t, _) in enumerate(h) if t >= t_ms)
        ta, a = h[after]
        if ta == t_ms:
            return dict(a)
        if after == 0:
            return None
        tb, b = h[after - 1]
        if ta - tb > self.max_gap_ms:
            return None
        quat = [f"stateEstimate.q{c}" for c in "wxyz"]
        if all(k in a for k in quat) and sum(a[k] * b[k] for k in quat) < 0:
            a = {**a, **{k: -a[k] for k in quat}}  # q and -q are one attitude: take the near one
        u = (t_ms - tb) / (ta - tb)
        return {k: b[k] + u * (a[k] - b[k]) for k in a}

    def _flush(self) -> None:
        while self.pending:
            t_ms, cmd = self.pending[0]
            states = [self._state_at(b, t_ms) for b in self.STATE_BLOCKS]
            if any(st == "wait" for st in states):
                return
            self.pending.pop(0)
            if any(st is None for st in states):
                self.dropped += 1
                continue
            self._row(t_ms, states[0], states[1], cmd)

    def _row(self, t_ms: int, p: Dict[str, float], a: Dict[str, float], cmd: Dict[str, float]) -> None:
        d2r = math.pi / 180.0
        s = "stateEstimate."
        q = [a[s + "qw"], a[s + "qx"], a[s + "qy"], a[s + "qz"]]
        n = math.sqrt(sum(c * c for c in q)) or 1.0
        row = [
            t_ms / 1000.0,
            p[s + "x"], p[s + "y"], p[s + "z"],
            *(c / n for c in q),
            p[s + "vx"], p[s + "vy"], p[s + "vz"],
            a["gyro.x"] * d2r, a["gyro.y"] * d2r, cmd["gyro.z"] * d2r,
            cmd["hamflight.thrust"], cmd["hamflight.tx"], cmd["hamflight.ty"], cmd["hamflight.tz"],
            cmd["acc.x"] * G_M_S2, cmd["acc.y"] * G_M_S2, cmd["acc.z"] * G_M_S2,
        ]
        self.writer.writerow([f"{v:.9g}" for v in row])
        self.rows += 1


def log_configs(rate_hz: float):
    """cflib LogConfigs for :data:`LOG_BLOCKS` at ``rate_hz`` (1..100 Hz)."""
    from cflib.crazyflie.log import LogConfig

    if not MIN_LOG_RATE_HZ <= rate_hz <= MAX_LOG_RATE_HZ:
        raise ValueError(f"rate {rate_hz} Hz: cflib's log period is a multiple of 10 ms, 1..100 Hz")
    period_ms = int(round(1000.0 / rate_hz / 10.0)) * 10
    configs = []
    for name, variables in LOG_BLOCKS:
        lc = LogConfig(name=name, period_in_ms=period_ms)
        for var, ty in variables:
            lc.add_variable(var, ty)
        configs.append(lc)
    return configs


# ---- errors ----


class CliError(Exception):
    """A failure ``hamflight-cf`` reports as one line on stderr, exiting with ``code``: 1, a failure
    at run time (no dongle, no answer, link lost, upload rejected)."""

    code = 1


class UsageError(CliError, ValueError):
    """A bad command line or input file, found before connecting: exit status 2, argparse's."""

    code = 2


# ---- parameters ----

#: The shim's parameters (group hamflight), hamflight_oot.c's PARAM_ADD list.
PARAMS = [
    "kp", "kv", "kR", "kw", "maxTilt", "cp", "cv", "cR", "cw", "aMax", "adapt", "reset",
    "airHeight", "leash", "law", "qF", "qT", "rF", "rT", "revert",
]
PARAM_GROUP = "hamflight"
#: The PARAM_UINT8 ones (0..255); the rest are PARAM_FLOAT.
PARAM_UINT8 = ("adapt", "reset", "law", "revert")


def parse_assignments(items: Sequence[str]) -> List[Tuple[str, str]]:
    """``name=value`` items as (name, value): ``name`` one of :data:`PARAMS` (``hamflight.``
    optional), ``value`` a number cflib can send as its type (an integer 0..255 for the uint8
    ones, a finite number for the floats). Raises :class:`UsageError` (a ValueError) naming the
    item, so that nothing is sent unless every assignment is good."""
    out = []
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise UsageError(f"{item!r}: expected name=value (e.g. law=1)")
        group, dot, short = name.rpartition(".")
        if dot:
            if group != PARAM_GROUP:
                raise UsageError(f"{item!r}: unknown parameter group {group!r}; hamflight-cf sets the "
                                 f"{PARAM_GROUP} group only ({PARAM_GROUP}.NAME=VALUE or NAME=VALUE)")
            name = short
        if name not in PARAMS:
            raise UsageError(f"{item!r}: unknown parameter {name!r}; the {PARAM_GROUP} group has: {' '.join(PARAMS)}")
        if name in PARAM_UINT8:
            try:
                ok = 0 <= int(value) <= 255
            except ValueError:
                ok = False
            if not ok:
                raise UsageError(f"{item!r}: {name} takes an integer 0..255")
        else:
            try:
                ok = math.isfinite(float(value))
            except ValueError:
                ok = False
            if not ok:
                raise UsageError(f"{item!r}: {name} takes a finite number")
        out.append((name, value))
    return out


# ---- links ----

#: The link schemes cflib's drivers open (cflib.crtp.init_drivers: radio, usb, udp, prrt, tcp;
#: serial:// only when asked for, debug:// no longer exists).
URI_FORMS = ("radio://DONGLE/CHANNEL[/RATE[/ADDRESS]] (e.g. radio://0/80/2M/E7E7E7E7E7), usb://N, "
             "udp://HOST:PORT, tcp://HOST:PORT or prrt://IP:PORT")
URI_SCHEMES = ("radio", "usb", "udp", "tcp", "prrt")


def check_uri(uri: str) -> str:
    """``uri`` if it has the shape cflib's driver for its scheme parses, else :class:`UsageError`
    saying which part is wrong. cflib itself reports most of these as a traceback from its
    driver (an unknown data rate it even takes silently as 2M)."""

    def bad(why: str) -> UsageError:
        return UsageError(f"bad URI {uri!r}: {why}")

    scheme, sep, rest = uri.partition("://")
    if not sep:
        raise bad(f"expected {URI_FORMS}")
    if scheme not in URI_SCHEMES:
        raise bad(f"unknown scheme {scheme + '://'!r}; cflib opens {URI_FORMS}")
    if scheme == "radio":
        path, _, query = rest.partition("?")
        parts = path.strip("/").split("/")
        dongle, more = parts[0], parts[1:]
        if not re.fullmatch(r"[0-9A-Za-z]+", dongle):
            raise bad("DONGLE is the Crazyradio's index (0 for the first) or its serial number")
        if not more:
            raise bad("no channel: expected radio://DONGLE/CHANNEL[/RATE[/ADDRESS]], e.g. radio://0/80/2M/E7E7E7E7E7")
        if len(more) > 3:
            raise bad("expected radio://DONGLE/CHANNEL[/RATE[/ADDRESS]], e.g. radio://0/80/2M/E7E7E7E7E7")
        if not re.fullmatch(r"[0-9]{1,3}", more[0]) or int(more[0]) > 125:
            raise bad(f"channel {more[0]!r}: expected 0..125 (2400..2525 MHz)")
        if len(more) > 1 and more[1] not in ("250K", "1M", "2M"):
            raise bad(f"data rate {more[1]!r}: expected 250K, 1M or 2M")
        if len(more) > 2 and not re.fullmatch(r"[0-9A-Fa-f]{1,10}", more[2]):
            raise bad(f"address {more[2]!r}: expected up to 10 hex digits (the factory one is E7E7E7E7E7)")
        for kv in filter(None, query.split("&")):
            key, _, value = kv.partition("=")
            if key == "rate_limit" and not re.fullmatch(r"[0-9]+", value):
                raise bad("rate_limit takes a whole number of packets per second")
    elif scheme == "usb":
        if not re.fullmatch(r"[0-9]+", rest):
            raise bad("expected usb://N, N the index of the Crazyflie on USB (usb://0 for the first)")
    elif scheme == "prrt":
        if not re.fullmatch(r"[0-9]{1,3}(\.[0-9]{1,3}){3}:[0-9]{1,5}(/[0-9]{1,6})?", rest):
            raise bad("expected prrt://IP:PORT[/DELAY_MS]")
    else:
        parts = urlsplit(uri)
        try:
            port = parts.port  # None without one, ValueError outside 0..65535
        except ValueError:
            port = None
        if not parts.hostname or not port or parts.path not in ("", "/"):
            raise bad(f"expected {scheme}://HOST:PORT, PORT 1..65535")
    return uri


def _first_line(text) -> str:
    """The first non-empty line of an exception's text."""
    return next((line.strip() for line in str(text).splitlines() if line.strip()), "")


def cflib_message(text: str) -> str:
    """One line from a cflib error message, which carries a traceback: "Couldn't load link
    driver: <exception>" (a driver that raised), or "<what>\nException:<exception>" (a driver
    thread's link error), each followed by the traceback, which is dropped."""
    head = str(text).split("Traceback (most recent call last)", 1)[0]
    lines = [line.strip() for line in head.splitlines() if line.strip()]
    prefix = "Couldn't load link driver:"
    if lines and lines[0].startswith(prefix):
        lines[0] = lines[0][len(prefix):].strip()
    lines = [line[len("Exception:"):].strip() if line.startswith("Exception:") else line for line in lines]
    if not lines:
        return "link error"
    return lines[0] if len(lines) < 2 else f"{lines[0]} ({'; '.join(lines[1:])})"


def link_failure(uri: str, message: str) -> str:
    """The cause of a failed connection, in one line, from cflib's ``connection_failed`` message."""
    msg = cflib_message(message)
    low = msg.lower()
    if "cannot find a crazyradio dongle" in low:
        return "no Crazyradio dongle found: plug one in (on Linux, Bitcraze's udev rules let a user open it)"
    if "cannot find radio with serial" in low or low.startswith("cannot find crazyradio"):
        return f"no Crazyradio with the serial number in {uri} is plugged in"
    if "access denied" in low or "insufficient permissions" in low or "errno 13" in low:
        return ("the Crazyradio dongle is not accessible (permission denied): install Bitcraze's udev "
                "rules for it, then replug it")
    if "too many packets lost" in low:
        return (f"no Crazyflie answered at {uri}: is it switched on, and are the channel, data rate "
                "and address its own?")
    if "unplugged" in low or "dongle communication error" in low:
        return f"the Crazyradio dongle stopped answering while connecting to {uri} (unplugged?)"
    if low.startswith("could not open usb"):
        return f"no Crazyflie answered on USB at {uri}: is it plugged in and switched on?"
    if "connection refused" in low:
        return f"no Crazyflie answered at {uri} (connection refused: nothing listens there)"
    if "no driver found" in low:
        return f"cflib has no driver for {uri}"
    return f"could not open the link to {uri}: {msg}"


#: How long connecting may take: the answer to the first packet and cflib's download of the
#: log and parameter tables (TOCs), a few seconds over the radio.
CONNECT_TIMEOUT_S = 20.0


def _import_cflib():
    """cflib's link layer, its drivers initialised once; :class:`CliError` if cflib is missing."""
    try:
        import cflib.crtp
        from cflib.crazyflie import Crazyflie
    except ImportError as e:
        if e.name is None or e.name.split(".")[0] == "cflib":
            raise CliError("cflib is not installed: pip install 'hamflight[crazyflie]'") from None
        raise CliError(f"cflib could not be imported ({e}): pip install 'hamflight[crazyflie]'") from None
    global _drivers_ready
    if not _drivers_ready:
        cflib.crtp.init_drivers()
        _resend_over_udp(cflib.crtp)
        _drivers_ready = True
    return Crazyflie


def _resend_over_udp(crtp) -> None:
    """cflib resends a request whose reply has not come (a TOC item, a parameter, a log block, a
    memory read or write) only over a link that says it ``needs_resending``; its UDP driver says no,
    and a simulated Crazyflie (the firmware as a Linux process, tools/firmware-sitl) drops packets
    when its 5-packet socket queue is full: one lost request then stalls the connection for good
    (one connection in two or three, measured). This swaps cflib's UDP driver for one that asks for
    cflib's own resending, as its radio driver does."""
    try:
        from cflib.crtp.udpdriver import UdpDriver
    except ImportError:
        return

    class ResendingUdpDriver(UdpDriver):
        def connect(self, *args, **kwargs):
            result = UdpDriver.connect(self, *args, **kwargs)
            self.needs_resending = True
            return result

    crtp.CLASSES[:] = [ResendingUdpDriver if c is UdpDriver else c for c in crtp.CLASSES]


_drivers_ready = False


class Link:
    """A cflib connection to one Crazyflie (``cf``) as a context manager. Unlike cflib's
    SyncCrazyflie it gives up after ``timeout_s`` (SyncCrazyflie waits forever for a vehicle
    that never answers), raises :class:`CliError` with the cause in one line, and records in
    ``lost`` why the link dropped later; an error raised inside the block once the link is lost
    (a timeout, say) becomes "the link was lost" unless it is a :class:`CliError` already."""

    def __init__(self, uri: str, timeout_s: float = CONNECT_TIMEOUT_S):
        self.uri = uri
        self.timeout_s = timeout_s
        self.cf = None
        self.lost: Optional[str] = None

    def __enter__(self) -> "Link":
        crazyflie = _import_cflib()
        self.cf = cf = crazyflie()
        done = threading.Event()
        failures: List[str] = []

        def failed(_uri, message):
            failures.append(message)
            done.set()

        def lost(_uri, message):
            self.lost = cflib_message(message)

        cf.connected.add_callback(lambda _uri: done.set())
        cf.connection_failed.add_callback(failed)
        cf.connection_lost.add_callback(lost)
        try:
            cf.open_link(self.uri)
            if not done.wait(self.timeout_s):
                raise CliError(f"no Crazyflie answered at {self.uri} within {self.timeout_s:g} s: is it "
                               "switched on, and is the URI its own?")
            if failures:
                raise CliError(link_failure(self.uri, failures[0]))
        except BaseException:
            self._close()
            raise
        return self

    def __exit__(self, exc_type, exc, tb):
        self._close()
        lost_it = exc_type is not None and issubclass(exc_type, Exception) and not issubclass(exc_type, CliError)
        if self.lost is not None and lost_it:
            raise CliError(f"the link to {self.uri} was lost: {self.lost}") from exc
        return False

    def _close(self) -> None:
        # cflib's close_link first sends a zero setpoint (thrust 0: the motors stop until the
        # pilot's next setpoint). hamflight-cf never flies, and may run beside the pilot (logging
        # a flight, an upload that waits for the landing): it must not command the vehicle. Seen
        # through the whole firmware in SITL: each hamflight-cf exit cut the motors for a setpoint
        # period in flight.
        try:
            self.cf.commander.send_setpoint = lambda *args, **kwargs: None
        except AttributeError:
            pass
        try:
            self.cf.close_link()
        except Exception:  # closing a broken link must not hide why it broke
            pass


@contextlib.contextmanager
def _quiet_cflib(verbose: bool):
    """cflib logs its failures with tracebacks through ``logging`` (which, with no handler
    configured, prints warnings and errors to stderr) and its driver threads can die with one: a
    NullHandler on the ``cflib`` logger and a silent ``threading.excepthook`` leave stderr to
    :func:`main`'s one line. ``verbose`` shows them all instead."""
    if verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
        yield
        return
    log = logging.getLogger("cflib")
    if not any(isinstance(h, logging.NullHandler) for h in log.handlers):
        log.addHandler(logging.NullHandler())
    hook = threading.excepthook
    threading.excepthook = lambda _args: None
    try:
        yield
    finally:
        threading.excepthook = hook


# ---- command line ----

EPILOG = """\
The loop: fly; `hamflight-cf log URI --out flight.csv` while flying (or log to the uSD deck);
`host-train import --out data --mass-kg 0.027 flight.csv`; train; `hamflight-cf upload URI
weights.hfw` (it flies from the next time the vehicle is not airborne; RAM only: a reboot flies
the compiled-in blob again, `hamflight-cf params URI revert=1` does so at once on the ground).
Log rate: cflib's log blocks carry at most 26 payload bytes each and run at most every 10 ms,
so the 17 values the importer needs take three blocks at up to 100 Hz (300 packets/s, within
the radio's roughly 1,000 packets/s, shared with setpoints and parameters); the controller itself
runs at 500 Hz. Requires cflib: pip install 'hamflight[crazyflie]'.
URI: radio://DONGLE/CHANNEL/RATE/ADDRESS, e.g. radio://0/80/2M/E7E7E7E7E7 (the first Crazyradio,
channel 80 = 2480 MHz, 2 Mbit/s, the factory address); usb://0; udp://HOST:PORT; tcp://HOST:PORT.
Exit status: 0 done; 1 a failure at run time (cflib missing, no dongle, no answer, link lost,
upload rejected); 2 a usage error, found before connecting (bad arguments, URI or name=value,
a missing or corrupt blob file); 130 interrupted (Ctrl-C). Errors are one line on stderr;
--verbose adds cflib's log messages and tracebacks."""


def _number(what: str, unit: str, lo: float, hi: float = math.inf, lo_open: bool = False, why: str = ""):
    """An argparse type: a finite number in [lo, hi] (or (lo, hi] with ``lo_open``)."""

    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number ({what} in {unit})") from None
        ok = math.isfinite(x) and (lo < x if lo_open else lo <= x) and x <= hi
        if not ok:
            span = f"{lo:g}..{hi:g} {unit}" if hi < math.inf else (f"more than {lo:g} {unit}" if lo_open else f"at least {lo:g} {unit}")
            raise argparse.ArgumentTypeError(f"{what} {text} {unit} is out of range: {span}{why}")
        return x

    return parse


def read_blob(path: str) -> bytes:
    """The blob file, checked (header, length, CRC) before anything is sent; :class:`UsageError`
    naming the file and the cause otherwise."""
    try:
        with open(path, "rb") as f:
            blob = f.read()
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, not a .hfw weight blob") from None
    except OSError as e:
        raise UsageError(f"{path}: cannot read it ({e.strerror or e})") from None
    try:
        blob_crc(blob)
    except UploadError as e:
        raise UsageError(f"{path}: {e}") from None
    return blob


def check_out(path: str) -> str:
    """``path`` if a CSV can be written there (its directory exists and is writable), checked
    before connecting; the file itself is created only once the link is up."""
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise UsageError(f"--out {path}: is a directory")
    if not os.path.isdir(folder):
        raise UsageError(f"--out {path}: no directory {folder}")
    if not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise UsageError(f"--out {path}: not writable")
    return path


def _cmd_upload(args) -> int:
    check_uri(args.uri)
    blob = read_blob(args.blob)
    print(f"{args.blob}: {len(blob)} B, crc {blob_crc(blob):08X}")
    with Link(args.uri, args.timeout_s) as link:
        app = AppMemory.find(link.cf.mem)
        upload(app, blob, wait_active_s=args.wait_s, wait_landing_s=args.wait_landing_s)
    return 0


def _cmd_log(args) -> int:
    check_uri(args.uri)
    check_out(args.out)
    with Link(args.uri, args.timeout_s) as link:
        toc = link.cf.log.toc
        missing = [v for _, vs in LOG_BLOCKS for v, _ in vs if toc.get_element_by_complete_name(v) is None]
        if missing:
            raise CliError(f"the Crazyflie does not log {', '.join(missing)}: is the hamflight app flashed?")
        try:
            f = open(args.out, "w", newline="")
        except OSError as e:
            raise CliError(f"cannot write {args.out}: {e.strerror or e}") from None
        with f:
            w = CsvLogWriter(f)
            lock = threading.Lock()
            configs = log_configs(args.rate_hz)
            for lc in configs:
                link.cf.log.add_config(lc)

                def cb(ts, data, conf, w=w):
                    with lock:
                        w.add(conf.name, ts, data)

                lc.data_received_cb.add_callback(cb)
            for lc in configs:
                lc.start()
            rate = 1000.0 / configs[0].period_in_ms
            print(f"logging {len(configs)} blocks at {rate:g} Hz to {args.out}; Ctrl-C stops")
            t0 = time.monotonic()
            try:
                while args.seconds is None or time.monotonic() - t0 < args.seconds:
                    if link.lost is not None:
                        break
                    time.sleep(0.2)
            except KeyboardInterrupt:
                pass
            if link.lost is None:
                for lc in configs:
                    lc.stop()
            with lock:
                w.finish()
            print(f"{w.rows} rows, {w.dropped} dropped (a state sample lost or missing)")
        if link.lost is not None:
            raise CliError(f"the link to {args.uri} was lost after {w.rows} rows (kept in {args.out}): {link.lost}")
    return 0


def _cmd_params(args) -> int:
    check_uri(args.uri)
    sets = parse_assignments(args.set)
    with Link(args.uri, args.timeout_s) as link:
        param = link.cf.param
        if param.toc.get_element_by_complete_name(f"{PARAM_GROUP}.{PARAMS[0]}") is None:
            raise CliError(f"the Crazyflie has no {PARAM_GROUP} parameters: is the hamflight app flashed?")
        for name, value in sets:
            param.set_value(f"{PARAM_GROUP}.{name}", value)
        time.sleep(0.2)
        for name in PARAMS:
            print(f"{PARAM_GROUP}.{name} = {param.get_value(f'{PARAM_GROUP}.{name}')}")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse, with its errors as one line (no usage block), exit status 2."""

    def error(self, message: str):
        self.exit(2, f"hamflight-cf: error: {message}; see '{self.prog} --help'\n")


URI_HELP = ("the Crazyflie's link: radio://DONGLE/CHANNEL/RATE/ADDRESS, e.g. radio://0/80/2M/E7E7E7E7E7 "
            "(the first Crazyradio, channel 80 = 2480 MHz, 2 Mbit/s, the factory address); usb://0 for "
            "a USB cable; udp://HOST:PORT or tcp://HOST:PORT")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="hamflight-cf",
        description="hamflight on a Crazyflie over the radio (cflib): upload weight blobs, log flights "
        "as host-train import's CSV, show and set the hamflight parameters.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    common = _Parser(add_help=False)
    common.add_argument("--timeout-s", type=_number("timeout", "s", 0.0, lo_open=True), default=CONNECT_TIMEOUT_S,
                        metavar="S", help="seconds to wait for the Crazyflie to answer and send its log and "
                        f"parameter tables when connecting (default {CONNECT_TIMEOUT_S:g})")
    common.add_argument("-v", "--verbose", action="store_true",
                        help="also show cflib's own log messages and tracebacks on stderr (for debugging)")
    sub = p.add_subparsers(dest="command", required=True, metavar="{upload,log,params}")
    u = sub.add_parser(
        "upload", parents=[common], help="write a weight blob into the app's RAM slot; it flies once not airborne",
        description="Check a weight blob (header, length, CRC), write it into the hamflight app's "
        "slot in RAM (waiting for the landing if an uploaded blob flies), read it back byte for byte, commit it and wait until the app flies it (the app swaps "
        "it in only while the vehicle is not airborne; otherwise it is reported pending). RAM only: a reboot "
        "flies the compiled-in blob again.")
    u.add_argument("uri", help=URI_HELP)
    u.add_argument("blob", help="the .hfw weight blob to fly (host-train train writes one)")
    u.add_argument("--wait-s", type=_number("wait", "s", 0.0), default=5.0, metavar="S",
                   help="seconds to wait after the commit for the app to swap the blob in (default 5); a "
                   "vehicle in flight swaps it only after landing, and the blob is then reported pending")
    u.add_argument("--wait-landing-s", type=_number("wait", "s", 0.0), default=600.0, metavar="S",
                   help="while an uploaded blob flies, the app takes a new one only on the ground: seconds to "
                   "wait for the landing before the upload starts (default 600)")
    u.set_defaults(func=_cmd_upload)
    lg = sub.add_parser(
        "log", parents=[common], help="record a flight as host-train import's CSV",
        description="Log the state estimate, gyro, accelerometer and the hamflight controller's thrust "
        "and torques as the CSV host-train import reads (t_s, position m, quaternion, velocity m/s, body "
        "rates rad/s, thrust N, torques N m, specific force m/s^2), until --seconds or Ctrl-C.")
    lg.add_argument("uri", help=URI_HELP)
    lg.add_argument("--out", required=True, metavar="FILE.csv", help="CSV file to write (replaced if it exists)")
    lg.add_argument("--rate-hz", type=_number(
        "log rate", "Hz", MIN_LOG_RATE_HZ, MAX_LOG_RATE_HZ,
        why=" (cflib runs a log block at most every 10 ms)"), default=MAX_LOG_RATE_HZ, metavar="HZ",
        help="log rate in Hz, 1..100 (default 100): cflib runs a log block at most every 10 ms, so 100 Hz "
        "is the fastest (three blocks, 300 packets/s of the radio's roughly 1,000); other rates round to the "
        "nearest whole number of 10 ms (30 Hz logs at 33.3 Hz)")
    lg.add_argument("--seconds", type=_number("duration", "s", 0.0, lo_open=True), default=None, metavar="S",
                    help="stop after this many seconds (default: at Ctrl-C)")
    lg.set_defaults(func=_cmd_log)
    pa = sub.add_parser(
        "params", parents=[common], help="show the hamflight parameters, after setting any name=value given",
        description="Set the hamflight parameters given as name=value (all checked before connecting), "
        "then print every one. revert=1 flies the compiled-in blob again (on the ground); law, adapt, "
        "reset and revert are integers 0..255, the rest numbers.")
    pa.add_argument("uri", help=URI_HELP)
    pa.add_argument("set", nargs="*", metavar="name=value",
                    help=f"a parameter to set, name one of: {' '.join(PARAMS)} (hamflight.name also works)")
    pa.set_defaults(func=_cmd_params)
    return p


def _fail(message: str, code: int) -> int:
    print(f"hamflight-cf: error: {message}", file=sys.stderr)
    return code


def main(argv: Optional[Iterable[str]] = None) -> int:
    """The console script: 0 done, 1 a failure at run time, 2 a usage error (argparse's, and the
    checks made before connecting), 130 interrupted; every error is one line on stderr."""
    try:
        args = build_parser().parse_args(None if argv is None else list(argv))
    except KeyboardInterrupt:
        return _fail("interrupted", 130)
    with _quiet_cflib(args.verbose):
        try:
            return args.func(args)
        except KeyboardInterrupt:
            return _fail("interrupted", 130)
        except CliError as e:
            return _fail(str(e), e.code)
        except UploadError as e:
            return _fail(str(e), 1)
        except Exception as e:
            if args.verbose:
                raise
            return _fail(f"{_first_line(e) or type(e).__name__} ({type(e).__name__}; --verbose shows the traceback)", 1)


if __name__ == "__main__":
    sys.exit(main())
