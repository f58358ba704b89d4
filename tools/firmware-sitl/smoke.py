#!/usr/bin/env python3
"""Smoke test of the SITL firmware built by tools/firmware-sitl/build.sh.

    python3 tools/firmware-sitl/smoke.py [--binary PATH] [--seconds S] [--no-cflib]

Runs the firmware process (CrazySim's SITL build with hamflight as the out-of-tree controller) and
plays, in this script, the part CrazySim's Gazebo plugin plays (crazysim_plugin.cpp of
llanesc/crazyflie-simulation): a UDP server the firmware connects to, which

  * answers the firmware's one-byte handshake 0xF3 with 0xF3;
  * sends it IMU samples as CRTP packets on port 9 (CRTP_PORT_SETPOINT_SIM), channel 0:
    header, type 0 (SENSOR_GYRO_ACC_SIM), acc x y z as int16 in units of 32 g / 65536 and gyro
    x y z as int16 in units of 4000 deg/s / 65536 (a vehicle at rest: acc = (0, 0, 1 g));
  * sends an external pose (CRTP localization port 6, channel 1, EXT_POSE 8: x y z qx qy qz qw
    as float32) at 100 Hz, as the plugin forwards Gazebo's odometry;
  * receives the motor commands (port 9, 4 x uint16 PWM, at most one per firmware tick);
  * relays every other CRTP packet between the firmware and a cflib client on another UDP port
    (cflib's udp:// driver: one CRTP packet per datagram, header first).

Then it connects cflib (`pip install cflib`; 0.1.34 was used) to udp://127.0.0.1:CFLIB_PORT, reads
the parameters hamflight.law and stabilizer.controller, lists the log group hamflight and logs
hamflight.phase / faults / cycles / law and stabilizer.rtStab (the stabilizer loop rate) for a few
seconds. It prints what it measured and exits 0 if the firmware booted, our controller's init and
app task ran, the stabilizer loop ran and (unless --no-cflib) cflib read hamflight.law.

The IMU stream is paced by this script's wall clock (time.sleep), not lock-stepped: the firmware's
stabilizer runs one iteration per sensor packet, so the loop rate measured here is the rate this
script achieves.
"""

import argparse
import os
import re
import shutil
import socket
import struct
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
DEFAULT_BINARY = os.path.join(REPO, "target", "firmware-sitl", "cmake", "cf2_sitl", "cf2")

CRTP_PORT_SIM = 9
SENSOR_GYRO_ACC_SIM = 0
G_PER_LSB = 2 * 16 / 65536.0  # SENSORS_G_PER_LSB_CFG of sensors_sitl.c
DEG_PER_LSB = 2 * 2000 / 65536.0  # SENSORS_DEG_PER_LSB_CFG


def crtp_header(port, channel):
    """cflib's and the plugin's header: port, the link bits 3, channel."""
    return ((port & 0x0F) << 4) | (3 << 2) | (channel & 0x03)


def imu_packet(acc_g, gyro_dps):
    acc = [int(round(a / G_PER_LSB)) for a in acc_g]
    gyro = [int(round(w / DEG_PER_LSB)) for w in gyro_dps]
    return struct.pack("<BB3h3h", crtp_header(CRTP_PORT_SIM, 0), SENSOR_GYRO_ACC_SIM, *acc, *gyro)


def ext_pose_packet(pos, quat_xyzw):
    return struct.pack("<BB7f", crtp_header(6, 1), 8, *pos, *quat_xyzw)


class Sim:
    """The plugin's side of the firmware's socket, plus the relay to cflib."""

    def __init__(self, fw_port, cflib_port, rate_hz):
        self.fw_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.fw_sock.bind(("127.0.0.1", fw_port))
        self.fw_sock.settimeout(0.2)
        self.lib_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.lib_sock.bind(("127.0.0.1", cflib_port))
        self.lib_sock.settimeout(0.2)
        self.rate_hz = rate_hz
        self.fw_addr = None
        self.lib_addr = None
        self.handshake = threading.Event()
        self.stop = threading.Event()
        self.imu_paused = threading.Event()
        self.imu_sent = 0
        self.motor_packets = 0
        self.motor_times = []
        self.last_pwm = None
        self.max_pwm = 0
        self.calibrated_reply = False
        self.to_lib = 0
        self.to_fw = 0
        self.lock = threading.Lock()

    def start(self):
        for target in (self._recv_fw, self._recv_lib, self._send_sensors):
            threading.Thread(target=target, daemon=True).start()

    def _recv_fw(self):
        while not self.stop.is_set():
            try:
                data, addr = self.fw_sock.recvfrom(64)
            except socket.timeout:
                continue
            if not self.handshake.is_set():
                if data == b"\xf3":
                    self.fw_addr = addr
                    self.fw_sock.sendto(b"\xf3", addr)
                    self.handshake.set()
                continue
            if data and (data[0] >> 4) == CRTP_PORT_SIM:
                if len(data) == 9:
                    with self.lock:
                        self.motor_packets += 1
                        self.motor_times.append(time.monotonic())
                        self.last_pwm = struct.unpack("<4H", data[1:9])
                        self.max_pwm = max(self.max_pwm, max(self.last_pwm))
                elif len(data) == 2:
                    self.calibrated_reply = bool(data[1])
                continue
            if self.lib_addr is not None:
                self.lib_sock.sendto(data, self.lib_addr)
                self.to_lib += 1

    def _recv_lib(self):
        while not self.stop.is_set():
            try:
                data, addr = self.lib_sock.recvfrom(64)
            except socket.timeout:
                continue
            self.lib_addr = addr
            if self.fw_addr is not None and data:
                self.fw_sock.sendto(data, self.fw_addr)
                self.to_fw += 1

    def _send_sensors(self):
        self.handshake.wait()
        period = 1.0 / self.rate_hz
        imu = imu_packet((0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
        pose = ext_pose_packet((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        pose_every = max(1, int(round(self.rate_hz / 100.0)))
        deadline = time.monotonic()
        n = 0
        while not self.stop.is_set():
            if self.imu_paused.is_set():
                time.sleep(0.01)
                deadline = time.monotonic()
                continue
            self.fw_sock.sendto(imu, self.fw_addr)
            self.imu_sent += 1
            if n % pose_every == 0:
                self.fw_sock.sendto(pose, self.fw_addr)
            n += 1
            deadline += period
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.05:
                deadline = time.monotonic()  # fell behind: do not burst


class Console:
    """The firmware's stdout (DEBUG_PRINT is printf in the SITL build), line by line."""

    def __init__(self, proc, path):
        self.proc = proc
        self.lines = []
        self.cond = threading.Condition()
        self.out = open(path, "w")
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for raw in self.proc.stdout:
            line = raw.decode(errors="replace").rstrip("\n")
            self.out.write(line + "\n")
            self.out.flush()
            with self.cond:
                self.lines.append(line)
                self.cond.notify_all()

    def wait_for(self, pattern, timeout):
        rx = re.compile(pattern)
        end = time.monotonic() + timeout
        with self.cond:
            while True:
                for line in self.lines:
                    if rx.search(line):
                        return line
                left = end - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    return None
                self.cond.wait(min(left, 0.2))

    def grep(self, pattern):
        rx = re.compile(pattern)
        with self.cond:
            return [line for line in self.lines if rx.search(line)]


def rss_kib(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def thread_count(pid):
    try:
        return len(os.listdir(f"/proc/{pid}/task"))
    except OSError:
        return None


def cflib_check(uri, seconds, results, sim, engage_seconds):
    try:
        import cflib.crtp
        from cflib.crazyflie import Crazyflie
        from cflib.crazyflie.log import LogConfig
    except ImportError as e:
        results["cflib_error"] = f"cflib not importable ({e}): pip install cflib"
        return
    cflib.crtp.init_drivers()
    cf = Crazyflie(rw_cache=None)
    tocs = threading.Event()
    full = threading.Event()
    failed = []
    cf.connected.add_callback(lambda _uri: tocs.set())
    cf.fully_connected.add_callback(lambda _uri: full.set())
    cf.connection_failed.add_callback(lambda _uri, msg: (failed.append(msg), tocs.set(), full.set()))
    # cflib's udp driver never resends (needs_resending is False) and the firmware's socket link
    # drops a packet when its 5-packet queue is full: with the 1 kHz sensor stream on a loaded host a
    # lost parameter request stalls cflib's download for good. The sensor stream pauses while cflib
    # downloads the TOCs and the parameter values (the stabilizer then waits for its next sample).
    sim.imu_paused.set()
    t0 = time.monotonic()
    cf.open_link(uri)
    try:
        tocs.wait(30)
        if tocs.is_set() and not failed:
            results["cflib_tocs_s"] = round(time.monotonic() - t0, 2)
        full.wait(30)
        if failed:
            results["cflib_error"] = failed[0]
            return
        if not full.is_set():
            results["cflib_error"] = "no fully_connected within 30 s (a lost packet: see above)"
        else:
            results["cflib_connect_s"] = round(time.monotonic() - t0, 2)
        toc = cf.param.toc.toc
        results["param_groups"] = len(toc)
        results["hamflight_params"] = sorted(toc.get("hamflight", {}).keys())
        if full.is_set():
            results["hamflight.law"] = cf.param.get_value("hamflight.law", timeout=10)
            results["hamflight.kp"] = cf.param.get_value("hamflight.kp", timeout=10)
            results["stabilizer.controller"] = cf.param.get_value("stabilizer.controller", timeout=10)
        if full.is_set():
            app_memory_info(cf, results)
        log_toc = cf.log.toc.toc
        results["hamflight_logs"] = sorted(log_toc.get("hamflight", {}).keys())
        sim.imu_paused.clear()
        time.sleep(1.0)
        names = ["hamflight.phase", "hamflight.faults", "hamflight.cycles", "hamflight.law",
                 "hamflight.thrust", "stabilizer.rtStab"]
        conf = LogConfig(name="smoke", period_in_ms=100)
        for n in names:
            group, var = n.split(".")
            if var in log_toc.get(group, {}):
                conf.add_variable(n)
        samples = []
        conf.data_received_cb.add_callback(lambda ts, data, _c: samples.append(data))
        cf.log.add_config(conf)
        conf.start()
        time.sleep(seconds)
        results["log_samples_idle"] = len(samples)
        if samples:
            results["log_last_idle"] = samples[-1]
            rates = [s["stabilizer.rtStab"] for s in samples if "stabilizer.rtStab" in s]
            if rates:
                results["rtStab_hz_median_idle"] = sorted(rates)[len(rates) // 2]
        if engage_seconds > 0:
            engage(cf, sim, engage_seconds, samples, results)
        conf.stop()
    finally:
        sim.imu_paused.clear()
        cf.close_link()


def app_memory_info(cf, results):
    """Reads the info block (64 B at 0) of the shim's weights-upload memory (MEM_TYPE_APP 0x18,
    firmware/bitcraze-app/README.md): magic HFUP, layout, source, upload state, active CRC."""
    mems = cf.mem.get_mems(0x18)
    results["app_memories"] = len(mems)
    if not mems:
        return
    done = threading.Event()
    got = {}

    def ok(m, addr, data):
        if m.id == mems[0].id:
            got["data"] = bytes(data)
            done.set()

    def failed(m, addr, data=None):
        if m.id == mems[0].id:
            done.set()

    cf.mem.mem_read_cb.add_callback(ok)
    cf.mem.mem_read_failed_cb.add_callback(failed)
    if cf.mem.read(mems[0], 0, 64) and done.wait(10) and "data" in got:
        d = got["data"]
        magic, layout, source, state, crc = struct.unpack_from("<4sHBBI", d, 0)
        results["app_memory_info"] = {"magic": magic.decode(errors="replace"), "layout": layout,
                                      "source": source, "upload_state": state,
                                      "active_crc": f"{crc:08X}", "size": mems[0].size}
    else:
        results["app_memory_info"] = "no answer to the read"


def engage(cf, sim, seconds, samples, results):
    """Streams a position setpoint 0.3 m above the origin at 50 Hz: the supervisor lets the
    controller fly, our shim leaves phase OFF and runs hf_step. The vehicle does not move (this
    script sends a vehicle at rest: no plant yet), so the phase stays GROUND and the thrust is
    what the law asks for a vehicle that does not climb."""
    n0 = len(samples)
    with sim.lock:
        sim.max_pwm = 0
        m0 = sim.motor_packets
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        cf.commander.send_position_setpoint(0.0, 0.0, 0.3, 0.0)
        time.sleep(0.02)
    cf.commander.send_stop_setpoint()
    cf.commander.send_notify_setpoint_stop()
    dt = time.monotonic() - t0
    with sim.lock:
        results["engaged_motor_packet_rate_hz"] = round((sim.motor_packets - m0) / dt, 1)
        results["engaged_max_pwm"] = sim.max_pwm
    got = samples[n0:]
    results["log_samples_engaged"] = len(got)
    if got:
        phases = sorted({s.get("hamflight.phase") for s in got})
        results["engaged_phases"] = phases
        cyc = [s["hamflight.cycles"] for s in got if s.get("hamflight.phase", 0) != 0]
        thr = [s["hamflight.thrust"] for s in got if s.get("hamflight.phase", 0) != 0]
        rates = [s["stabilizer.rtStab"] for s in got if "stabilizer.rtStab" in s]
        if cyc:
            cyc.sort()
            results["hf_step_cycles_median"] = cyc[len(cyc) // 2]
            results["hf_step_cycles_max"] = cyc[-1]
            results["hf_step_us_median_host"] = round(cyc[len(cyc) // 2] / 168.0, 1)
        if thr:
            results["engaged_thrust_n_last"] = round(thr[-1], 4)
        if rates:
            results["rtStab_hz_median_engaged"] = sorted(rates)[len(rates) // 2]
        results["log_last_engaged"] = got[-1]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--binary", default=DEFAULT_BINARY, help="the SITL firmware (default: %(default)s)")
    ap.add_argument("--fw-port", type=int, default=19950, help="the port the firmware connects to")
    ap.add_argument("--cflib-port", type=int, default=19850, help="the port cflib connects to")
    ap.add_argument("--rate", type=float, default=1000.0, help="IMU packets per second (default 1000)")
    ap.add_argument("--seconds", type=float, default=5.0, help="how long to log over cflib")
    ap.add_argument("--engage-seconds", type=float, default=3.0,
                    help="stream a position setpoint for this long over cflib (0: do not)")
    ap.add_argument("--no-cflib", action="store_true", help="only boot and count motor packets")
    ap.add_argument("--console", default=None, help="file for the firmware's stdout "
                    "(default: console.log beside the binary)")
    args = ap.parse_args()

    if not os.access(args.binary, os.X_OK):
        sys.exit(f"smoke.py: no firmware at {args.binary}: run tools/firmware-sitl/build.sh first")
    console_path = args.console or os.path.join(os.path.dirname(args.binary), "console.log")

    sim = Sim(args.fw_port, args.cflib_port, args.rate)
    sim.start()
    cmd = [args.binary, str(args.fw_port), "127.0.0.1"]
    # printf to a pipe is block-buffered: stdbuf makes the console line-buffered.
    if shutil.which("stdbuf"):
        cmd = ["stdbuf", "-oL", "-eL"] + cmd
    t_start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    con = Console(proc, console_path)
    ok = True
    results = {}
    try:
        checks = [
            ("handshake", None),
            ("scheduler + system task", r"Build .*|About to run tests"),
            ("our controller's init", r"HAMFLIGHT.*model .* crc"),
            ("our app task", r"select with param stabilizer.controller"),
            ("self test", r"Self test passed"),
            ("stabilizer loop", r"Starting stabilizer loop"),
        ]
        for name, pattern in checks:
            if pattern is None:
                got = sim.handshake.wait(10)
                line = "0xF3" if got else None
            else:
                line = con.wait_for(pattern, 30)
            t = time.monotonic() - t_start
            print(f"[{t:6.2f} s] {name}: {line if line else 'NOT SEEN'}")
            if not line:
                ok = False
                break
        if ok:
            # Motor packets over one second of the running loop.
            time.sleep(1.0)
            with sim.lock:
                n0, i0, t0 = sim.motor_packets, sim.imu_sent, time.monotonic()
            time.sleep(2.0)
            with sim.lock:
                n1, i1, t1 = sim.motor_packets, sim.imu_sent, time.monotonic()
            results["imu_rate_hz"] = round((i1 - i0) / (t1 - t0), 1)
            results["motor_packet_rate_hz"] = round((n1 - n0) / (t1 - t0), 1)
            results["last_pwm"] = sim.last_pwm
            results["rss_kib"] = rss_kib(proc.pid)
            results["threads"] = thread_count(proc.pid)
            if results["motor_packet_rate_hz"] <= 0:
                ok = False
            if not args.no_cflib:
                try:
                    cflib_check(f"udp://127.0.0.1:{args.cflib_port}", args.seconds, results, sim,
                                args.engage_seconds)
                except Exception as e:  # report, do not hide the boot results
                    results["cflib_error"] = repr(e)
                if "hamflight.law" not in results:
                    ok = False
            results["rss_kib_end"] = rss_kib(proc.pid)
            results["packets_relayed_fw_to_cflib"] = sim.to_lib
            results["packets_relayed_cflib_to_fw"] = sim.to_fw
        results["imu_packets_sent"] = sim.imu_sent
        results["motor_packets_received"] = sim.motor_packets
        results["hamflight_console"] = con.grep(r"HAMFLIGHT|OutOfTree|CONTROLLER")
    finally:
        sim.stop.set()
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
    for k, v in results.items():
        if isinstance(v, list) and v and isinstance(v[0], str) and k.endswith("console"):
            print(f"{k}:")
            for line in v:
                print(f"    {line}")
        else:
            print(f"{k}: {v}")
    print(f"console: {console_path}")
    print("SMOKE " + ("PASSED" if ok else "FAILED"))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
