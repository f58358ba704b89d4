"""hamflight-cf: weights and logs over the Crazyflie radio, with Bitcraze's cflib.

Subcommands (``hamflight-cf --help``, or ``python -m hamflight.crazyflie``):

- ``upload URI FILE.hfw``: writes a weight blob into the app's MEM_TYPE_APP memory (the shim's
  staging slot), reads it back, commits it and waits until it flies (the app swaps it in only
  while the vehicle is not airborne), then reports the active blob's CRC;
- ``log URI --out flight.csv``: records the variables ``host-train import`` needs, as its CSV;
- ``params URI [name=value ...]``: shows (and sets) the ``hamflight`` parameters.

The memory layout and protocol are the shim's (``firmware/bitcraze-app/hamflight_oot.c``,
"Upload"): an info block at 0x0000, a control word at 0x0040 (BEGIN + length, COMMIT), the
staging slot at 0x1000. cflib splits every read and write into 24-byte packets.

cflib is an optional dependency: ``pip install 'hamflight[crazyflie]'``. Everything but the
connection itself (:func:`main`) takes cflib's objects as arguments, so the tests drive it with
cflib's own :class:`cflib.crazyflie.mem.Memory` over a fake link.
"""

from __future__ import annotations

import argparse
import csv
import math
import struct
import sys
import threading
import time
import zlib
from dataclasses import dataclass
from typing import Callable, Dict, Iterable, List, Optional, Sequence, TextIO, Tuple

#: MEM_TYPE_APP (crazyflie-firmware mem.h; cflib MemoryElement.TYPE_APP).
MEM_TYPE_APP = 0x18
#: The shim's address layout.
INFO_ADDR = 0x0000
INFO_BYTES = 0x40
CONTROL_ADDR = 0x0040
DATA_ADDR = 0x1000
INFO_MAGIC = 0x50554648  # "HFUP"
LAYOUT_VERSION = 1
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
}
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


def upload(
    app: AppMemory,
    blob: bytes,
    say: Callable[[str], None] = print,
    wait_active_s: float = 5.0,
    poll_s: float = 0.1,
) -> Info:
    """BEGIN, the blob at 0x1000 (cflib's 24-byte packets, progress through ``say``), a read-back
    compared byte for byte, COMMIT, then the info block until the blob flies: returns it. A
    blob that waits for the landing returns with state "pending". Raises :class:`UploadError`
    for anything else (nothing is committed unless the read-back matched)."""
    crc = blob_crc(blob)
    info = app.info()
    if info.magic != INFO_MAGIC or info.layout != LAYOUT_VERSION:
        raise UploadError(f"app memory is not hamflight's upload layout {LAYOUT_VERSION} (magic {info.magic:08X})")
    if len(blob) > info.capacity_bytes:
        raise UploadError(f"blob of {len(blob)} B, the staging slot holds {info.capacity_bytes} B")
    if not app.write(CONTROL_ADDR, struct.pack("<BI", CMD_BEGIN, len(blob))):
        raise UploadError("BEGIN refused (the app is swapping a model: try again)")
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
#: cflib's log period is in units of 10 ms: 100 Hz is the fastest any block can run.
MAX_LOG_RATE_HZ = 100.0
G_M_S2 = 9.81


class CsvLogWriter:
    """Joins the three blocks into the importer's CSV rows: a row at each ``hfCmd`` sample whose
    ``hfPosVel`` and ``hfAttGyro`` samples carry a timestamp within ``tolerance_ms`` of it
    (blocks of one period usually share the firmware tick; a row with a stale block is dropped and
    counted in ``dropped``). Time is the firmware's millisecond timestamp, in s."""

    def __init__(self, out: TextIO, tolerance_ms: float = 5.0):
        self.writer = csv.writer(out, lineterminator="\n")
        self.writer.writerow(CSV_COLUMNS)
        self.tolerance_ms = tolerance_ms
        self.latest: Dict[str, Tuple[int, Dict[str, float]]] = {}
        self.rows = 0
        self.dropped = 0

    def add(self, block: str, timestamp_ms: int, data: Dict[str, float]) -> None:
        """One log packet, as cflib's ``LogConfig.data_received_cb`` gives it."""
        self.latest[block] = (timestamp_ms, data)
        if block == "hfCmd":
            self._row(timestamp_ms, data)

    def _row(self, t_ms: int, cmd: Dict[str, float]) -> None:
        pv = self.latest.get("hfPosVel")
        ag = self.latest.get("hfAttGyro")
        if pv is None or ag is None or abs(pv[0] - t_ms) > self.tolerance_ms or abs(ag[0] - t_ms) > self.tolerance_ms:
            self.dropped += 1
            return
        p, a = pv[1], ag[1]
        d2r = math.pi / 180.0
        s = "stateEstimate."
        row = [
            t_ms / 1000.0,
            p[s + "x"], p[s + "y"], p[s + "z"],
            a[s + "qw"], a[s + "qx"], a[s + "qy"], a[s + "qz"],
            p[s + "vx"], p[s + "vy"], p[s + "vz"],
            a["gyro.x"] * d2r, a["gyro.y"] * d2r, cmd["gyro.z"] * d2r,
            cmd["hamflight.thrust"], cmd["hamflight.tx"], cmd["hamflight.ty"], cmd["hamflight.tz"],
            cmd["acc.x"] * G_M_S2, cmd["acc.y"] * G_M_S2, cmd["acc.z"] * G_M_S2,
        ]
        self.writer.writerow([f"{v:.9g}" for v in row])
        self.rows += 1


def log_configs(rate_hz: float):
    """cflib LogConfigs for :data:`LOG_BLOCKS` at ``rate_hz`` (at most 100 Hz)."""
    from cflib.crazyflie.log import LogConfig

    if not 0 < rate_hz <= MAX_LOG_RATE_HZ:
        raise ValueError(f"rate {rate_hz} Hz: cflib's log period is a multiple of 10 ms, 1..100 Hz")
    period_ms = int(round(1000.0 / rate_hz / 10.0)) * 10
    configs = []
    for name, variables in LOG_BLOCKS:
        lc = LogConfig(name=name, period_in_ms=period_ms)
        for var, ty in variables:
            lc.add_variable(var, ty)
        configs.append(lc)
    return configs


# ---- parameters ----

#: The shim's parameters (group hamflight), hamflight_oot.c's PARAM_ADD list.
PARAMS = [
    "kp", "kv", "kR", "kw", "maxTilt", "cp", "cv", "cR", "cw", "aMax", "adapt", "reset",
    "airHeight", "leash", "law", "qF", "qT", "rF", "rT", "revert",
]


def parse_assignments(items: Sequence[str]) -> List[Tuple[str, str]]:
    out = []
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in PARAMS:
            raise ValueError(f"{item!r}: expected name=value with name one of {', '.join(PARAMS)}")
        out.append((name, value))
    return out


# ---- command line ----

EPILOG = """\
The loop: fly; `hamflight-cf log URI --out flight.csv` while flying (or log to the uSD deck);
`host-train import --out data --mass-kg 0.027 flight.csv`; train; `hamflight-cf upload URI
weights.hfw` (it flies from the next time the vehicle is not airborne; RAM only: a reboot flies
the compiled-in blob again, `hamflight-cf params URI revert=1` does so at once on the ground).
Log rate: cflib's log blocks carry at most 26 payload bytes each and run at most every 10 ms,
so the 17 values the importer needs take three blocks at up to 100 Hz (300 packets/s, within
the radio's roughly 1,000 packets/s, shared with setpoints and parameters); the controller itself
runs at 500 Hz. Requires cflib: pip install 'hamflight[crazyflie]'."""


def _connect(uri: str):
    try:
        import cflib.crtp
        from cflib.crazyflie import Crazyflie
        from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
    except ImportError as e:  # pragma: no cover - the message is the point
        raise SystemExit(f"hamflight-cf needs cflib: pip install 'hamflight[crazyflie]' ({e})")
    cflib.crtp.init_drivers()
    return SyncCrazyflie(uri, cf=Crazyflie())


def _cmd_upload(args) -> int:
    blob = open(args.blob, "rb").read()
    print(f"{args.blob}: {len(blob)} B, crc {blob_crc(blob):08X}")
    with _connect(args.uri) as scf:
        app = AppMemory.find(scf.cf.mem)
        upload(app, blob, wait_active_s=args.wait_s)
    return 0


def _cmd_log(args) -> int:
    with _connect(args.uri) as scf, open(args.out, "w", newline="") as f:
        w = CsvLogWriter(f)
        lock = threading.Lock()
        configs = log_configs(args.rate_hz)
        for lc in configs:
            scf.cf.log.add_config(lc)

            def cb(ts, data, conf, w=w):
                with lock:
                    w.add(conf.name, ts, data)

            lc.data_received_cb.add_callback(cb)
        for lc in configs:
            lc.start()
        print(f"logging {len(configs)} blocks at {args.rate_hz:g} Hz to {args.out}; Ctrl-C stops")
        t0 = time.monotonic()
        try:
            while args.seconds is None or time.monotonic() - t0 < args.seconds:
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        for lc in configs:
            lc.stop()
        print(f"{w.rows} rows, {w.dropped} dropped (blocks out of step)")
    return 0


def _cmd_params(args) -> int:
    sets = parse_assignments(args.set)
    with _connect(args.uri) as scf:
        for name, value in sets:
            scf.cf.param.set_value(f"hamflight.{name}", value)
        time.sleep(0.2)
        for name in PARAMS:
            print(f"hamflight.{name} = {scf.cf.param.get_value(f'hamflight.{name}')}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="hamflight-cf",
        description="hamflight on a Crazyflie over the radio (cflib): upload weight blobs, log flights "
        "as host-train import's CSV, show and set the hamflight parameters.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="command", required=True)
    u = sub.add_parser("upload", help="write a weight blob into the app's RAM slot; it flies once not airborne")
    u.add_argument("uri", help="e.g. radio://0/80/2M/E7E7E7E7E7")
    u.add_argument("blob", help="the .hfw weight blob (host-train train writes one)")
    u.add_argument("--wait-s", type=float, default=5.0, help="how long to wait for the swap (default 5 s)")
    u.set_defaults(func=_cmd_upload)
    lg = sub.add_parser("log", help="record a flight as host-train import's CSV")
    lg.add_argument("uri")
    lg.add_argument("--out", required=True, help="CSV file to write")
    lg.add_argument("--rate-hz", type=float, default=100.0, help="1..100 Hz (default 100, cflib's fastest)")
    lg.add_argument("--seconds", type=float, default=None, help="stop after this long (default: Ctrl-C)")
    lg.set_defaults(func=_cmd_log)
    pa = sub.add_parser("params", help="show the hamflight parameters, after setting any name=value given")
    pa.add_argument("uri")
    pa.add_argument("set", nargs="*", help=f"name=value, name one of: {' '.join(PARAMS)}")
    pa.set_defaults(func=_cmd_params)
    return p


def main(argv: Optional[Iterable[str]] = None) -> int:
    args = build_parser().parse_args(None if argv is None else list(argv))
    try:
        return args.func(args)
    except UploadError as e:
        print(f"hamflight-cf: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
