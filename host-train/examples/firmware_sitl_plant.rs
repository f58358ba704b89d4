//! The whole Crazyflie firmware in the loop: CrazySim's SITL build of Bitcraze's firmware, with
//! hamflight as its out-of-tree controller (tools/firmware-sitl/build.sh), flies host-train's SITL
//! plant over CrazySim's UDP protocol.
//!
//!     cargo run --release -p host-train --example firmware_sitl_plant -- \
//!         [--firmware target/firmware-sitl/cmake/cf2_sitl/cf2] [--scenario scenarios/hover.toml]
//!
//! This program plays the part of CrazySim's Gazebo plugin (`crazysim_plugin.cpp`), with the
//! plant in place of Gazebo, and the part of the pilot (CRTP setpoints). It starts the firmware
//! (`cf2 PORT 127.0.0.1`), answers its handshake (`0xF3`), and every millisecond of wall clock
//! steps the plant by 1 ms with the last motor command and sends the firmware one IMU sample (port
//! 9, channel 0, type 0: specific force in units of 32 g / 65536, body rates in 4000 °/s / 65536),
//! every 10 ms the true pose as a motion-capture system would (`EXT_POSE`, localization port 6,
//! channel 1), every 20 ms a position setpoint (generic commander, port 7, type 7, as cflib's
//! `send_position_setpoint`). The setpoints: on the ground until the firmware's estimator has
//! settled, a smooth climb to the scenario's reference p*(0), the reference for the hold, a smooth
//! descent to the ground, then the stop setpoint.
//!
//! PWM → rotor: the firmware's SITL power distribution (`power_distribution_sitl.c`, the one our
//! controller's force/torque command goes through) turns the per-rotor force F into the PWM ratio
//! p = pwm / 65535 by inverting F = A p² + B p (A = 0.091492681, B = 0.067673604, its
//! `pwmToThrustA/B`). The plant inverts that same map, so each rotor makes the force the firmware
//! meant, and runs at rpm = √(F / kf) with the scenario vehicle's kf. (CrazySim's own plugin maps
//! PWM to a rotor speed, ω = 0.0408 pwm + 380.8 rad/s, for Gazebo's rotor with its own motor
//! constant 1.7965e-8 N/(rad/s)²; with our plant's kf that map would not give the firmware's
//! forces.)
//!
//! Mixer: the firmware's mixer constants are the CF2's (`quadSysId.armLength` 0.046 m,
//! `thrustToTorque` 0.005964552 m); the CF2X plant's arm is 0.028 m and its km/kf 0.0251 m, so the
//! plant would make 0.86 × the commanded roll/pitch torque and 4.2 × the yaw torque (the yaw loop
//! then limit-cycles at saturation). Before the take-off this program sets both to the scenario
//! vehicle's over CRTP (it reads the parameter TOC, writes by id and waits for the echo);
//! `--stock-mixer` keeps the firmware's.
//!
//! Ground: the plant has no ground, so this program adds one: below z = 0 the vehicle rests at
//! z = 0, level, still (the accelerometer then reads the normal force, 1 g up).
//!
//! Timing: not lock-stepped. The firmware's FreeRTOS ticks on a wall-clock timer, its stabilizer
//! runs once per IMU packet, and this program paces the IMU stream at 1 kHz of wall clock (one
//! plant millisecond per packet, never bursting to catch up). It reports how well it kept pace.
//!
//! Every other CRTP packet is relayed to a cflib client on `--cflib-port` (udp://127.0.0.1:19850),
//! as smoke.py does, so cflib can watch the flight (or 0: no relay).
//!
//! Output: the flight's numbers on stdout, and in `--out` (default target/firmware-sitl/flight):
//! flight.csv (every 10 ms), flight.svg (z and the setpoint, the position error) and console.log
//! (the firmware's stdout).

use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Parser;
use host_train::{Plant, PlantState, Scenario};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use plotters::prelude::*;

/// The firmware's SITL power distribution: per-rotor force F (N) = A p² + B p, p = PWM / 65535.
const PWM_TO_THRUST_A: f64 = 0.091492681;
const PWM_TO_THRUST_B: f64 = 0.067673604;
/// CrazySim's sensor scales (sensors_sitl.c): g and °/s per LSB.
const G_PER_LSB: f64 = 2.0 * 16.0 / 65536.0;
const DEG_PER_LSB: f64 = 2.0 * 2000.0 / 65536.0;
const CRTP_PORT_SIM: u8 = 9;
const CRTP_PORT_LOCALIZATION: u8 = 6;
const CRTP_PORT_COMMANDER_GENERIC: u8 = 7;
const CRTP_PORT_PARAM: u8 = 2;
/// The parameter port's channels: the table of contents, and writes by id.
const PARAM_TOC_CH: u8 = 0;
const PARAM_WRITE_CH: u8 = 2;
/// TOC command: get the item with this id (CMD_GET_ITEM_V2).
const PARAM_CMD_GET_ITEM_V2: u8 = 2;

#[derive(Parser, Debug)]
#[command(
    about = "Fly host-train's plant with the SITL Crazyflie firmware (hamflight as its controller)"
)]
struct Args {
    /// The SITL firmware (tools/firmware-sitl/build.sh).
    #[arg(long, default_value = "target/firmware-sitl/cmake/cf2_sitl/cf2")]
    firmware: PathBuf,
    /// The scenario: its vehicle, effects and disturbance; its reference is the hold.
    #[arg(long, default_value = "scenarios/hover.toml")]
    scenario: PathBuf,
    /// UDP port the firmware connects to.
    #[arg(long, default_value_t = 19950)]
    port: u16,
    /// UDP port a cflib client may connect to (CRTP relay); 0: no relay.
    #[arg(long, default_value_t = 19850)]
    cflib_port: u16,
    /// Seconds on the ground after the stabilizer loop starts (the Kalman estimator settles).
    #[arg(long, default_value_t = 2.0)]
    settle_s: f64,
    /// Seconds of the climb to p*(0).
    #[arg(long, default_value_t = 2.5)]
    takeoff_s: f64,
    /// Seconds of the hold (default: the scenario's duration).
    #[arg(long)]
    hold_s: Option<f64>,
    /// Seconds of the descent.
    #[arg(long, default_value_t = 2.5)]
    land_s: f64,
    /// Seconds into the hold before the "settled" statistics start.
    #[arg(long, default_value_t = 2.0)]
    window_s: f64,
    /// Keep the firmware's own mixer constants (the CF2's quadSysId.armLength 0.046 m and
    /// thrustToTorque 0.005964552 m) instead of setting them to the scenario vehicle's.
    #[arg(long)]
    stock_mixer: bool,
    /// Directory for flight.csv, flight.svg, console.log.
    #[arg(long, default_value = "target/firmware-sitl/flight")]
    out: PathBuf,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("firmware_sitl_plant: {e:#}");
        std::process::exit(1);
    }
}

/// What the firmware sends us, shared between the receiving thread and the loop.
#[derive(Default)]
struct FromFirmware {
    fw_addr: Option<SocketAddr>,
    pwm: [u16; 4],
    motor_packets: u64,
    /// Parameter TOC items received: (id, "group.name").
    param_toc: Vec<(u16, String)>,
    /// The TOC's end was seen (an answer without an item).
    param_toc_end: bool,
    /// Parameter writes the firmware echoed (it echoes a write once done): (id, value bytes).
    param_written: Vec<(u16, [u8; 4])>,
}

/// The firmware's console, line by line, into a file and a flag for the stabilizer loop.
struct Console {
    lines: Mutex<Vec<String>>,
    cond: Condvar,
}

impl Console {
    fn wait_for(&self, needle: &str, timeout: Duration) -> Option<String> {
        let end = Instant::now() + timeout;
        let mut lines = self.lines.lock().unwrap();
        loop {
            if let Some(l) = lines.iter().find(|l| l.contains(needle)) {
                return Some(l.clone());
            }
            let now = Instant::now();
            if now >= end {
                return None;
            }
            lines = self.cond.wait_timeout(lines, end - now).unwrap().0;
        }
    }

    fn grep(&self, needle: &str) -> Vec<String> {
        let lines = self.lines.lock().unwrap();
        lines
            .iter()
            .filter(|l| l.contains(needle))
            .cloned()
            .collect()
    }
}

/// Kills the firmware when dropped (it is ours: we started it).
struct Firmware(Child);

impl Drop for Firmware {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn crtp_header(port: u8, channel: u8) -> u8 {
    ((port & 0x0F) << 4) | (3 << 2) | (channel & 0x03)
}

fn imu_packet(acc_g: Vector3<f64>, gyro_dps: Vector3<f64>) -> Vec<u8> {
    let q = |x: f64, lsb: f64| (x / lsb).round().clamp(-32768.0, 32767.0) as i16;
    let mut p = vec![crtp_header(CRTP_PORT_SIM, 0), 0];
    for a in acc_g.iter() {
        p.extend_from_slice(&q(*a, G_PER_LSB).to_le_bytes());
    }
    for w in gyro_dps.iter() {
        p.extend_from_slice(&q(*w, DEG_PER_LSB).to_le_bytes());
    }
    p
}

fn ext_pose_packet(s: &PlantState) -> Vec<u8> {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(s.rot));
    let mut p = vec![crtp_header(CRTP_PORT_LOCALIZATION, 1), 8];
    for v in [s.p_m.x, s.p_m.y, s.p_m.z, q.i, q.j, q.k, q.w] {
        p.extend_from_slice(&(v as f32).to_le_bytes());
    }
    p
}

fn position_setpoint_packet(p: &Vector3<f64>, yaw_deg: f64) -> Vec<u8> {
    let mut pk = vec![crtp_header(CRTP_PORT_COMMANDER_GENERIC, 0), 7];
    for v in [p.x, p.y, p.z, yaw_deg] {
        pk.extend_from_slice(&(v as f32).to_le_bytes());
    }
    pk
}

/// A parameter TOC request: the item with id `id` (port 2, channel 0, CMD_GET_ITEM_V2).
fn param_toc_request(id: u16) -> Vec<u8> {
    let mut pk = vec![
        crtp_header(CRTP_PORT_PARAM, PARAM_TOC_CH),
        PARAM_CMD_GET_ITEM_V2,
    ];
    pk.extend_from_slice(&id.to_le_bytes());
    pk
}

/// A float parameter write by id (port 2, channel 2). (Set-by-name does not fit
/// quadSysId.thrustToTorque: 31 data bytes, one more than a CRTP packet carries; the firmware
/// then reads the float's last byte from past the packet.)
fn param_write_float(id: u16, value: f32) -> Vec<u8> {
    let mut pk = vec![crtp_header(CRTP_PORT_PARAM, PARAM_WRITE_CH)];
    pk.extend_from_slice(&id.to_le_bytes());
    pk.extend_from_slice(&value.to_le_bytes());
    pk
}

/// Parameter answers into `sh`: TOC items (id, type, group\0 name\0; a 1-byte answer past the
/// end) and write echoes (id, value).
fn param_answer(d: &[u8], sh: &mut FromFirmware) {
    if d.len() < 2 || d[0] >> 4 != CRTP_PORT_PARAM {
        return;
    }
    match d[0] & 3 {
        PARAM_TOC_CH if d[1] == PARAM_CMD_GET_ITEM_V2 => {
            if d.len() == 2 {
                sh.param_toc_end = true;
                return;
            }
            if d.len() < 6 {
                return;
            }
            let id = u16::from_le_bytes([d[2], d[3]]);
            let mut parts = d[5..].split(|&b| b == 0);
            let group = String::from_utf8_lossy(parts.next().unwrap_or(&[]));
            let name = String::from_utf8_lossy(parts.next().unwrap_or(&[]));
            if !sh.param_toc.iter().any(|(i, _)| *i == id) {
                sh.param_toc.push((id, format!("{group}.{name}")));
            }
        }
        PARAM_WRITE_CH if d.len() == 7 => {
            let id = u16::from_le_bytes([d[1], d[2]]);
            sh.param_written.push((id, [d[3], d[4], d[5], d[6]]));
        }
        _ => {}
    }
}

fn stop_setpoint_packet() -> Vec<u8> {
    vec![crtp_header(CRTP_PORT_COMMANDER_GENERIC, 0), 0]
}

/// Rotor speed (rpm) the plant runs at for a PWM value: the force the firmware meant, F = A p² +
/// B p, through the vehicle's kf.
fn pwm_to_rpm(pwm: u16, kf: f64) -> f64 {
    let p = pwm as f64 / 65535.0;
    let f = PWM_TO_THRUST_A * p * p + PWM_TO_THRUST_B * p;
    (f.max(0.0) / kf).sqrt()
}

/// Smooth 0 → 1 over [0, 1] (zero velocity at both ends).
fn smoothstep(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * (3.0 - 2.0 * u)
}

/// One logged sample (every 10 ms of plant time).
struct Sample {
    t_s: f64,
    phase: &'static str,
    p: Vector3<f64>,
    sp: Vector3<f64>,
    rpy_deg: Vector3<f64>,
    pwm: [u16; 4],
    wall_s: f64,
}

fn run() -> Result<()> {
    let args = Args::parse();
    if !args.firmware.is_file() {
        bail!(
            "no firmware at {}: build it with tools/firmware-sitl/build.sh CHECKOUT",
            args.firmware.display()
        );
    }
    let scenario = Scenario::load(&args.scenario)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let hold_s = args.hold_s.unwrap_or(scenario.spec.duration_s);
    let target0 = scenario.reference(0.0);
    let yaw0 = target0.yaw_rad;
    let ground_xy = Vector3::new(target0.p_m.x, target0.p_m.y, 0.0);

    let mut plant: Plant = scenario.plant();
    plant.set_state(PlantState::at_rest(ground_xy, yaw0));
    plant.set_rotor_rpm([0.0; 4]);
    let kf = plant.params.kf_n_per_rpm2;
    let g = plant.params.gravity_m_s2;

    // --- sockets ---------------------------------------------------------------------------
    let sock = UdpSocket::bind(("127.0.0.1", args.port))
        .with_context(|| format!("cannot bind udp 127.0.0.1:{}", args.port))?;
    sock.set_read_timeout(Some(Duration::from_millis(100)))?;
    let lib_sock = if args.cflib_port != 0 {
        let s = UdpSocket::bind(("127.0.0.1", args.cflib_port))
            .with_context(|| format!("cannot bind udp 127.0.0.1:{}", args.cflib_port))?;
        s.set_read_timeout(Some(Duration::from_millis(100)))?;
        Some(s)
    } else {
        None
    };
    let shared = Arc::new(Mutex::new(FromFirmware::default()));
    let lib_addr: Arc<Mutex<Option<SocketAddr>>> = Arc::new(Mutex::new(None));
    let stop = Arc::new(AtomicBool::new(false));
    let relayed = Arc::new(AtomicU64::new(0));

    // Receiving thread: handshake, motor commands, relay of the rest to cflib.
    {
        let sock = sock.try_clone()?;
        let lib = lib_sock.as_ref().map(|s| s.try_clone()).transpose()?;
        let (shared, lib_addr, stop, relayed) = (
            shared.clone(),
            lib_addr.clone(),
            stop.clone(),
            relayed.clone(),
        );
        thread::spawn(move || {
            let mut buf = [0u8; 128];
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, addr)) = sock.recv_from(&mut buf) else {
                    continue;
                };
                let d = &buf[..n];
                let mut sh = shared.lock().unwrap();
                if sh.fw_addr.is_none() {
                    if d == [0xF3] {
                        let _ = sock.send_to(&[0xF3], addr);
                        sh.fw_addr = Some(addr);
                    }
                    continue;
                }
                if n > 0 && d[0] >> 4 == CRTP_PORT_SIM {
                    if n == 9 {
                        for (i, m) in sh.pwm.iter_mut().enumerate() {
                            *m = u16::from_le_bytes([d[1 + 2 * i], d[2 + 2 * i]]);
                        }
                        sh.motor_packets += 1;
                    }
                    continue;
                }
                param_answer(d, &mut sh);
                drop(sh);
                if let (Some(lib), Some(a)) = (&lib, *lib_addr.lock().unwrap()) {
                    let _ = lib.send_to(d, a);
                    relayed.fetch_add(1, Ordering::Relaxed);
                }
            }
        });
    }
    if let Some(lib) = &lib_sock {
        let lib = lib.try_clone()?;
        let fw = sock.try_clone()?;
        let (shared, lib_addr, stop) = (shared.clone(), lib_addr.clone(), stop.clone());
        thread::spawn(move || {
            let mut buf = [0u8; 128];
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, addr)) = lib.recv_from(&mut buf) else {
                    continue;
                };
                *lib_addr.lock().unwrap() = Some(addr);
                if let Some(fa) = shared.lock().unwrap().fw_addr {
                    let _ = fw.send_to(&buf[..n], fa);
                }
            }
        });
    }

    // --- the firmware ----------------------------------------------------------------------
    let console_path = args.out.join("console.log");
    let fw_path = args.firmware.canonicalize()?;
    // printf to a pipe is block-buffered: stdbuf makes the console line-buffered.
    let mut cmd = if Path::new("/usr/bin/stdbuf").exists() {
        let mut c = Command::new("/usr/bin/stdbuf");
        c.args(["-oL", "-eL"]).arg(&fw_path);
        c
    } else {
        Command::new(&fw_path)
    };
    cmd.arg(args.port.to_string())
        .arg("127.0.0.1")
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let t_start = Instant::now();
    let mut child = Firmware(cmd.spawn().context("cannot start the firmware")?);
    let console = Arc::new(Console {
        lines: Mutex::new(Vec::new()),
        cond: Condvar::new(),
    });
    {
        let out = child.0.stdout.take().unwrap();
        let console = console.clone();
        let mut file = std::fs::File::create(&console_path)?;
        thread::spawn(move || {
            for line in BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                let _ = writeln!(file, "{line}");
                console.lines.lock().unwrap().push(line);
                console.cond.notify_all();
            }
        });
    }
    let hs_end = Instant::now() + Duration::from_secs(10);
    let fw_addr = loop {
        if let Some(a) = shared.lock().unwrap().fw_addr {
            break a;
        }
        if Instant::now() > hs_end {
            bail!("no handshake from the firmware within 10 s");
        }
        thread::sleep(Duration::from_millis(5));
    };
    println!(
        "[{:6.2} s] handshake from {fw_addr}",
        t_start.elapsed().as_secs_f64()
    );

    // The firmware's mixer (quadSysId, read by power_distribution_sitl.c's force/torque mode)
    // configured for the vehicle it flies: arm·0.707 = the plant's rotor offset, thrust-to-torque
    // = km / kf.
    let mixer_params: Vec<(&str, f32)> = if args.stock_mixer {
        Vec::new()
    } else {
        vec![
            (
                "armLength",
                (plant.params.arm_xy_m / std::f64::consts::FRAC_1_SQRT_2) as f32,
            ),
            (
                "thrustToTorque",
                (plant.params.km_nm_per_rpm2 / plant.params.kf_n_per_rpm2) as f32,
            ),
        ]
    };

    // --- the loop: 1 ms of plant per IMU packet, paced at 1 kHz of wall clock ----------------
    const DT: f64 = 1e-3;
    let mut samples: Vec<Sample> = Vec::new();
    let mut stab_started_at: Option<f64> = None; // plant time
    let mut late_resets = 0u32;
    let mut max_late_ms = 0.0f64;
    let mut on_ground = true;
    let mut airborne_once = false;
    let mut crash: Option<(f64, String)> = None;
    let mut touchdown_speed: Option<f64> = None;
    let mut stop_sent = 0u32;
    let loop_start = Instant::now();
    let mut deadline = loop_start;
    let mut k: u64 = 0;
    let mut motor_at_engage = 0u64;
    let mut engage_wall: Option<Instant> = None;
    let mut engage_motor_rate = 0.0;
    // The mixer parameters: their ids from the TOC (scanned from id 0), then written by id.
    let mut mixer_ids: Vec<Option<u16>> = vec![None; mixer_params.len()];
    let mut toc_next: u16 = 0;
    let mut toc_last_req: (u16, u64) = (u16::MAX, 0);
    let mut mixer_done_at: Option<f64> = None;
    let mut engage_at: Option<f64> = None;
    let total_guard_s = 60.0 + args.settle_s + args.takeoff_s + hold_s + args.land_s;
    loop {
        let t = plant.t_s();
        let (pwm, motor_packets) = {
            let sh = shared.lock().unwrap();
            (sh.pwm, sh.motor_packets)
        };
        if stab_started_at.is_none()
            && console
                .wait_for("Starting stabilizer loop", Duration::ZERO)
                .is_some()
        {
            stab_started_at = Some(t);
            println!(
                "[{:6.2} s] stabilizer loop started (plant t = {t:.3} s)",
                t_start.elapsed().as_secs_f64()
            );
        }
        if let (Some(t0), None) = (stab_started_at, mixer_done_at) {
            if k.is_multiple_of(2) {
                let sh = shared.lock().unwrap();
                for (id, (name, _)) in mixer_ids.iter_mut().zip(&mixer_params) {
                    let full = format!("quadSysId.{name}");
                    if id.is_none() {
                        *id = sh.param_toc.iter().find(|(_, n)| *n == full).map(|x| x.0);
                    }
                }
                let toc_end = sh.param_toc_end;
                let have_next = sh.param_toc.iter().any(|x| x.0 == toc_next);
                let written: Vec<u16> = sh.param_written.iter().map(|w| w.0).collect();
                drop(sh);
                if mixer_ids.iter().all(Option::is_some) {
                    let pending: Vec<(u16, f32)> = mixer_ids
                        .iter()
                        .zip(&mixer_params)
                        .filter_map(|(id, (_, v))| id.map(|id| (id, *v)))
                        .filter(|(id, _)| !written.contains(id))
                        .collect();
                    if pending.is_empty() {
                        mixer_done_at = Some(t);
                        println!(
                            "[{:6.2} s] mixer parameters set ({} TOC items read)",
                            t_start.elapsed().as_secs_f64(),
                            toc_next
                        );
                    } else if k.is_multiple_of(20) {
                        for (id, v) in pending {
                            let _ = sock.send_to(&param_write_float(id, v), fw_addr);
                        }
                    }
                } else if toc_end {
                    bail!("the firmware has no parameter quadSysId.armLength / thrustToTorque");
                } else {
                    if have_next {
                        toc_next += 1;
                    }
                    if toc_last_req.0 != toc_next || k - toc_last_req.1 >= 20 {
                        let _ = sock.send_to(&param_toc_request(toc_next), fw_addr);
                        toc_last_req = (toc_next, k);
                    }
                }
            }
            if t - t0 > args.settle_s + 30.0 {
                bail!("the mixer parameters were not set within 30 s");
            }
        }
        if let (Some(t0), Some(_), None) = (stab_started_at, mixer_done_at, engage_at) {
            if t - t0 >= args.settle_s {
                engage_at = Some(t);
            }
        }
        // The flight's timeline, from the engage time.
        let (phase, setpoint): (&'static str, Option<Vector3<f64>>) = match engage_at {
            None if stab_started_at.is_none() => ("boot", None),
            None => ("settle", None),
            Some(t_engage) => {
                let te = t - t_engage;
                let hold_end = args.takeoff_s + hold_s;
                let land_end = hold_end + args.land_s;
                let hold_p = |tau: f64| scenario.reference(tau.clamp(0.0, hold_s)).p_m;
                if te < args.takeoff_s {
                    let a = smoothstep(te / args.takeoff_s);
                    ("takeoff", Some(ground_xy + (target0.p_m - ground_xy) * a))
                } else if te < hold_end {
                    ("hold", Some(hold_p(te - args.takeoff_s)))
                } else if te < land_end {
                    let a = smoothstep((te - hold_end) / args.land_s);
                    let top = hold_p(hold_s);
                    let bottom = Vector3::new(top.x, top.y, -0.05);
                    ("land", Some(top + (bottom - top) * a))
                } else if te < land_end + 1.0 {
                    let top = hold_p(hold_s);
                    ("landed", Some(Vector3::new(top.x, top.y, -0.05)))
                } else if te < land_end + 2.0 {
                    ("stop", None)
                } else {
                    break;
                }
            }
        };
        if phase == "takeoff" && engage_wall.is_none() {
            engage_wall = Some(Instant::now());
            motor_at_engage = motor_packets;
        }
        if phase == "landed" {
            if let Some(w) = engage_wall.take() {
                engage_motor_rate =
                    (motor_packets - motor_at_engage) as f64 / w.elapsed().as_secs_f64();
            }
        }

        // Plant step with the last motor command, then the ground.
        let rpm = pwm.map(|m| pwm_to_rpm(m, kf));
        plant.step(rpm, DT);
        let mut s = *plant.state();
        if s.p_m.z <= 0.0 {
            let vz = s.v_world_m_s().z;
            if !on_ground && airborne_once && touchdown_speed.is_none() {
                touchdown_speed = Some(-vz);
                let tilt = s.rot[(2, 2)].clamp(-1.0, 1.0).acos().to_degrees();
                if (-vz > 1.0 || tilt > 30.0) && crash.is_none() {
                    crash = Some((
                        t,
                        format!("hit the ground at {:.2} m/s, tilt {tilt:.0} deg", -vz),
                    ));
                }
            }
            on_ground = true;
            let yaw = s.rpy().z;
            s = PlantState::at_rest(Vector3::new(s.p_m.x, s.p_m.y, 0.0), yaw);
            plant.set_state(s);
        } else if s.p_m.z > 0.02 {
            if on_ground && phase != "boot" && phase != "settle" {
                airborne_once = true;
                touchdown_speed = None;
            }
            on_ground = false;
        }
        if !s.is_finite() {
            crash.get_or_insert((t, "non-finite state".into()));
            break;
        }
        if s.rot[(2, 2)] < 0.0 {
            crash.get_or_insert((t, "upside down".into()));
        }
        if let Some(sp) = setpoint {
            if (s.p_m - sp).norm() > 2.0 {
                crash.get_or_insert((t, "more than 2 m from the setpoint".into()));
            }
        }

        // Sensors.
        let acc = if on_ground {
            Vector3::new(0.0, 0.0, g)
        } else {
            plant.accelerometer()
        };
        let imu = imu_packet(acc / g, s.w_body_rad_s.map(f64::to_degrees));
        let _ = sock.send_to(&imu, fw_addr);
        if k.is_multiple_of(10) {
            let _ = sock.send_to(&ext_pose_packet(&s), fw_addr);
        }
        if k % 20 == 5 {
            match setpoint {
                Some(sp) => {
                    let _ =
                        sock.send_to(&position_setpoint_packet(&sp, yaw0.to_degrees()), fw_addr);
                }
                None if phase == "stop" && stop_sent < 5 => {
                    let _ = sock.send_to(&stop_setpoint_packet(), fw_addr);
                    stop_sent += 1;
                }
                None => {}
            }
        }
        if k.is_multiple_of(10) {
            samples.push(Sample {
                t_s: plant.t_s(),
                phase,
                p: s.p_m,
                sp: setpoint.unwrap_or(Vector3::new(f64::NAN, f64::NAN, f64::NAN)),
                rpy_deg: s.rpy().map(f64::to_degrees),
                pwm,
                wall_s: loop_start.elapsed().as_secs_f64(),
            });
        }
        if child.0.try_wait()?.is_some() {
            bail!("the firmware exited (console: {})", console_path.display());
        }
        if plant.t_s() > total_guard_s {
            bail!(
                "the stabilizer loop never started (console: {})",
                console_path.display()
            );
        }
        k += 1;

        // Pace: the next packet 1 ms after this one's deadline; never burst to catch up.
        deadline += Duration::from_micros(1000);
        let now = Instant::now();
        if deadline > now {
            thread::sleep(deadline - now);
        } else {
            let late = (now - deadline).as_secs_f64() * 1e3;
            max_late_ms = max_late_ms.max(late);
            if late > 20.0 {
                deadline = now;
                late_resets += 1;
            }
        }
    }
    let wall = loop_start.elapsed().as_secs_f64();
    let (motor_packets, last_pwm, param_written) = {
        let sh = shared.lock().unwrap();
        (sh.motor_packets, sh.pwm, sh.param_written.clone())
    };
    stop.store(true, Ordering::Relaxed);
    let hamflight_lines = console.grep("HAMFLIGHT");
    drop(child);

    // --- the numbers -------------------------------------------------------------------------
    let stats = |f: &dyn Fn(&Sample) -> bool| -> Option<(f64, f64, f64, usize)> {
        let errs: Vec<(f64, f64)> = samples
            .iter()
            .filter(|s| f(s) && s.sp.x.is_finite())
            .map(|s| ((s.p - s.sp).norm(), (s.p.z - s.sp.z).abs()))
            .collect();
        if errs.is_empty() {
            return None;
        }
        let n = errs.len() as f64;
        let rmse = (errs.iter().map(|e| e.0 * e.0).sum::<f64>() / n).sqrt();
        let max = errs.iter().map(|e| e.0).fold(0.0, f64::max);
        let rmse_z = (errs.iter().map(|e| e.1 * e.1).sum::<f64>() / n).sqrt();
        Some((rmse, max, rmse_z, errs.len()))
    };
    let hold_t0 = samples
        .iter()
        .find(|s| s.phase == "hold")
        .map(|s| s.t_s)
        .unwrap_or(f64::NAN);
    let report = |name: &str, st: Option<(f64, f64, f64, usize)>| match st {
        Some((rmse, max, rz, n)) => println!(
            "{name:<34} RMSE {:6.2} cm   max {:6.2} cm   RMSE z {:6.2} cm   ({n} samples)",
            rmse * 100.0,
            max * 100.0,
            rz * 100.0
        ),
        None => println!("{name:<34} no samples"),
    };
    println!(
        "scenario {} (hold at p*(0) = [{:.2}, {:.2}, {:.2}] m for {hold_s} s), firmware {}",
        scenario.name,
        target0.p_m.x,
        target0.p_m.y,
        target0.p_m.z,
        args.firmware.display()
    );
    if args.stock_mixer {
        println!(
            "mixer: the firmware's own (quadSysId armLength 0.046 m, thrustToTorque 0.005964552 m)"
        );
    }
    for ((name, v), id) in mixer_params.iter().zip(&mixer_ids) {
        let echo = id
            .and_then(|id| param_written.iter().find(|w| w.0 == id))
            .map(|w| format!("firmware echoed {:.6}", f32::from_le_bytes(w.1)))
            .unwrap_or_else(|| "NOT SET".into());
        println!("mixer: quadSysId.{name} (id {id:?}) = {v:.6}: {echo}");
    }
    for l in &hamflight_lines {
        println!("  console: {l}");
    }
    report(
        "take-off (vs the streamed setpoint)",
        stats(&|s| s.phase == "takeoff"),
    );
    report("hold, whole", stats(&|s| s.phase == "hold"));
    report(
        &format!("hold, from {} s in", args.window_s),
        stats(&|s| s.phase == "hold" && s.t_s >= hold_t0 + args.window_s),
    );
    report("landing", stats(&|s| s.phase == "land"));
    let hold: Vec<&Sample> = samples.iter().filter(|s| s.phase == "hold").collect();
    if let Some(last) = hold.last() {
        let mean_z = hold.iter().map(|s| s.p.z).sum::<f64>() / hold.len() as f64;
        let max_tilt = hold
            .iter()
            .map(|s| s.rpy_deg.x.abs().max(s.rpy_deg.y.abs()))
            .fold(0.0, f64::max);
        println!(
            "hold: mean z {mean_z:.3} m, max |roll|,|pitch| {max_tilt:.1} deg, yaw at the end {:.1} deg, PWM at the end {:?}",
            last.rpy_deg.z, last.pwm
        );
    }
    let final_state = plant.state();
    println!(
        "end: z = {:.3} m, on the ground: {on_ground}, touch-down speed {}, last PWM {last_pwm:?}",
        final_state.p_m.z,
        touchdown_speed
            .map(|v| format!("{v:.2} m/s"))
            .unwrap_or_else(|| "-".into())
    );
    match &crash {
        Some((t, why)) => println!("CRASHED at plant t = {t:.2} s: {why}"),
        None => println!(
            "crashed: no (airborne: {airborne_once}, landed: {})",
            on_ground && airborne_once
        ),
    }
    println!(
        "timing: {:.3} s of plant in {wall:.3} s of wall clock ({:.4} plant s per wall s); IMU \
         packets {k} ({:.1} /s); motor packets {motor_packets} ({:.1} /s overall, {engage_motor_rate:.1} /s \
         in flight); max lateness {max_late_ms:.2} ms, {late_resets} pacing resets; CRTP relayed \
         to cflib {}",
        plant.t_s(),
        plant.t_s() / wall,
        k as f64 / wall,
        motor_packets as f64 / wall,
        relayed.load(Ordering::Relaxed)
    );
    write_csv(&args.out.join("flight.csv"), &samples)?;
    plot(&args.out.join("flight.svg"), &samples, &scenario.name)?;
    println!(
        "wrote {}/flight.csv, flight.svg, console.log",
        args.out.display()
    );
    if crash.is_some() || !airborne_once {
        std::process::exit(3);
    }
    Ok(())
}

fn write_csv(path: &Path, samples: &[Sample]) -> Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        f,
        "t_s,wall_s,phase,x,y,z,sp_x,sp_y,sp_z,err_m,roll_deg,pitch_deg,yaw_deg,m1,m2,m3,m4"
    )?;
    for s in samples {
        writeln!(
            f,
            "{:.3},{:.4},{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.3},{:.3},{:.3},{},{},{},{}",
            s.t_s,
            s.wall_s,
            s.phase,
            s.p.x,
            s.p.y,
            s.p.z,
            s.sp.x,
            s.sp.y,
            s.sp.z,
            (s.p - s.sp).norm(),
            s.rpy_deg.x,
            s.rpy_deg.y,
            s.rpy_deg.z,
            s.pwm[0],
            s.pwm[1],
            s.pwm[2],
            s.pwm[3]
        )?;
    }
    Ok(())
}

fn plot(path: &Path, samples: &[Sample], name: &str) -> Result<()> {
    let pe = |e: &dyn std::fmt::Debug| anyhow::anyhow!("plotting failed: {e:?}");
    let flown: Vec<&Sample> = samples.iter().filter(|s| s.sp.x.is_finite()).collect();
    if flown.is_empty() {
        return Ok(());
    }
    let (t0, t1) = (flown[0].t_s, flown[flown.len() - 1].t_s);
    let zmax = flown.iter().map(|s| s.p.z.max(s.sp.z)).fold(0.1, f64::max) * 1.1;
    let emax = flown
        .iter()
        .map(|s| (s.p - s.sp).norm() * 100.0)
        .fold(1.0, f64::max)
        * 1.1;
    let mut buf = String::new();
    {
        let root = SVGBackend::with_string(&mut buf, (1000, 700)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| pe(&e))?;
        let (top, bottom) = root.split_vertically(350);
        let mut c = ChartBuilder::on(&top)
            .caption(
                format!("{name}: Crazyflie firmware (SITL) + hamflight on the host-train plant"),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(t0..t1, -0.1..zmax)
            .map_err(|e| pe(&e))?;
        c.configure_mesh()
            .x_desc("plant time (s)")
            .y_desc("z (m)")
            .draw()
            .map_err(|e| pe(&e))?;
        c.draw_series(LineSeries::new(
            flown.iter().map(|s| (s.t_s, s.sp.z)),
            &RGBColor(120, 120, 120),
        ))
        .map_err(|e| pe(&e))?
        .label("setpoint z")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(120, 120, 120)));
        c.draw_series(LineSeries::new(
            flown.iter().map(|s| (s.t_s, s.p.z)),
            &RGBColor(31, 119, 180),
        ))
        .map_err(|e| pe(&e))?
        .label("flown z")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(31, 119, 180)));
        c.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| pe(&e))?;
        let mut c = ChartBuilder::on(&bottom)
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(50)
            .build_cartesian_2d(t0..t1, 0.0..emax)
            .map_err(|e| pe(&e))?;
        c.configure_mesh()
            .x_desc("plant time (s)")
            .y_desc("|p - p_sp| (cm)")
            .draw()
            .map_err(|e| pe(&e))?;
        c.draw_series(LineSeries::new(
            flown.iter().map(|s| (s.t_s, (s.p - s.sp).norm() * 100.0)),
            &RGBColor(214, 39, 40),
        ))
        .map_err(|e| pe(&e))?;
        root.present().map_err(|e| pe(&e))?;
    }
    std::fs::write(path, buf)?;
    Ok(())
}
