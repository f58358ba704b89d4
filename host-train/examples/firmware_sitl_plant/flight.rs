//! The flight: the firmware started and answered, the plant stepped every millisecond (of wall
//! clock, or in lock-step with the firmware's tick), the setpoints from the ground to the hold and
//! back, and the flight's numbers.

use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Parser;
use host_train::io::{
    crtp_await_handshake, ext_pose_packet, full_state_setpoint_packet, hl_go_to_packet,
    hl_land_packet, hl_start_trajectory_packet, hl_stop_packet, hl_takeoff_packet, imu_packet,
    param_toc_request, param_write_float, param_write_u8, parse_motor, poly4d_trajectory_eval,
    position_setpoint_packet, pwm_to_rpm, stop_setpoint_packet, CrtpLockstep, Poly4d,
    CRTP_HANDSHAKE, CRTP_PORT_SIM,
};
use host_train::{Plant, PlantState, Scenario, TrajectoryPoint};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};

use crate::crtp::{param_answer, Console, Firmware, FromFirmware};
use crate::record::{plot, write_csv, Sample};
use crate::trajectory::{figure_eight, figure_eight_pieces, Upload, HL_CMD_START_TRAJECTORY};
use crate::{Args, Pilot, SetpointKind};

/// Smooth 0 → 1 over [0, 1] (zero velocity at both ends), with its first and second derivatives.
fn smoothstep(u: f64) -> (f64, f64, f64) {
    if !(0.0..=1.0).contains(&u) {
        return (u.clamp(0.0, 1.0), 0.0, 0.0);
    }
    (u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u), 6.0 - 12.0 * u)
}

/// The end of every pilot's timeline, `te_s` after the descent began from `top`: the descent
/// (`land_s`), one second landed, then the stop for 1 s + `linger_s`; `None` when it is over.
/// The descent comes to rest at the ground itself (a move to a point below it would still be
/// braking, with upward feed-forward, at touch-down and bounce the vehicle back up); once down,
/// the setpoint sinks 5 cm below the ground so that the controller lets go.
fn landing(
    top: Vector3<f64>,
    te_s: f64,
    land_s: f64,
    linger_s: f64,
    yaw: f64,
) -> Option<(&'static str, Option<TrajectoryPoint>)> {
    let touch = Vector3::new(top.x, top.y, 0.0);
    let bottom = Vector3::new(top.x, top.y, -0.05);
    if te_s < land_s {
        Some(("land", Some(smooth_move(top, touch, land_s, te_s, yaw))))
    } else if te_s < land_s + 1.0 {
        Some(("landed", Some(smooth_move(bottom, bottom, 1.0, 0.0, yaw))))
    } else if te_s < land_s + 2.0 + linger_s {
        Some(("stop", None))
    } else {
        None
    }
}

/// A smooth move from `a` to `b` over `dur_s`, at `t_s` into it: position, velocity, acceleration.
fn smooth_move(
    a: Vector3<f64>,
    b: Vector3<f64>,
    dur_s: f64,
    t_s: f64,
    yaw: f64,
) -> TrajectoryPoint {
    let (s, ds, dds) = smoothstep(t_s / dur_s);
    TrajectoryPoint {
        p_m: a + (b - a) * s,
        v_m_s: (b - a) * (ds / dur_s),
        a_m_s2: (b - a) * (dds / (dur_s * dur_s)),
        j_m_s3: Vector3::zeros(),
        yaw_rad: yaw,
        yaw_rate_rad_s: 0.0,
    }
}

/// Every time-based disturbance of the plant moved `offset_s` later: the scenario's clock starts
/// when the hold does, as in `host-train eval`, where the flight starts at p*(0).
fn delay_disturbances(plant: &mut Plant, offset_s: f64) {
    plant.disturbance.wind_onset_s += offset_s;
    plant.disturbance.efficiency_onset_s += offset_s;
    for s in &mut plant.wind_variation.steps {
        s.from_s += offset_s;
        s.until_s = s.until_s.map(|u| u + offset_s);
    }
    for s in &mut plant.wind_variation.sines {
        s.phase_rad -= core::f64::consts::TAU * s.frequency_hz * offset_s;
    }
}

pub fn run() -> Result<()> {
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

    // --pilot trajectory: the figure of eight's pieces, flown relative to p*(0).
    let traj_pieces: Vec<Poly4d> = if args.pilot == Pilot::Trajectory {
        if !(args.traj_time_scale > 0.0 && args.traj_s > 0.0 && args.upload_s > 0.0) {
            bail!("--traj-s, --traj-time-scale and --upload-s must be positive");
        }
        figure_eight_pieces(
            args.traj_size_m,
            args.traj_s,
            args.traj_pieces as usize,
            yaw0,
        )
    } else {
        Vec::new()
    };
    let traj_scale = args.traj_time_scale;
    // The reference of the started trajectory, `tau_s` after its start: the pieces' polynomial
    // at tau / scale, shifted so that it starts at p*(0) (the commander's `relative`: its
    // current setpoint, here the go-to's end, p*(0)).
    let traj_ref = |tau_s: f64| -> TrajectoryPoint {
        let e0 = poly4d_trajectory_eval(&traj_pieces, 0.0).expect("pieces");
        let e = poly4d_trajectory_eval(&traj_pieces, tau_s / traj_scale).expect("pieces");
        TrajectoryPoint {
            p_m: target0.p_m + e.p_m - e0.p_m,
            v_m_s: e.v_m_s / traj_scale,
            a_m_s2: e.a_m_s2 / (traj_scale * traj_scale),
            j_m_s3: Vector3::zeros(),
            yaw_rad: e.yaw_rad,
            yaw_rate_rad_s: e.yaw_rate_rad_s / traj_scale,
        }
    };
    let traj_total_s: f64 =
        traj_pieces.iter().map(|p| p.duration_s as f64).sum::<f64>() * traj_scale;
    // After the trajectory's end: its end point, held this long before the landing.
    const TRAJ_TAIL_S: f64 = 1.0;
    let mut upload = if traj_pieces.is_empty() {
        None
    } else {
        let up = Upload::new(&traj_pieces, 0)?;
        // how closely the f32 pieces follow the analytic figure, and the figure's peak speed
        let (mut fit_max, mut v_max) = (0.0f64, 0.0f64);
        for i in 0..=10_000 {
            let tau = args.traj_s * i as f64 / 10_000.0;
            let e = poly4d_trajectory_eval(&traj_pieces, tau).expect("pieces");
            let f = figure_eight(args.traj_size_m, args.traj_s, tau);
            let fp = Vector3::new(f[0][0], f[1][0], f[2][0]);
            fit_max = fit_max.max((e.p_m - fp).norm());
            v_max = v_max.max(e.v_m_s.norm());
        }
        println!(
            "trajectory: figure of eight {:.2} x {:.2} m in {} s, {} poly4d pieces, {} B in {} \
             memory writes; the pieces within {:.3} mm of the figure; peak speed {:.2} m/s \
             (time scale {traj_scale})",
            2.0 * args.traj_size_m,
            args.traj_size_m,
            args.traj_s,
            traj_pieces.len(),
            up.bytes(),
            up.bytes().div_ceil(host_train::io::CRTP_MEM_CHUNK),
            fit_max * 1e3,
            v_max / traj_scale
        );
        Some(up)
    };
    // The upload's end, the start_trajectory sends (plant time of the last, how many) and its
    // answer.
    let mut upload_done_at: Option<f64> = None;
    let mut upload_began_at: Option<f64> = None;
    let mut traj_start: Option<(f64, u32)> = None;
    let mut traj_start_answered: Option<f64> = None;

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

    // Receiving thread (wall clock only; in lock-step the loop reads the firmware's packets):
    // handshake, motor commands, relay of the rest to cflib.
    if !args.lockstep {
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
                    if d == [CRTP_HANDSHAKE] {
                        let _ = sock.send_to(&[CRTP_HANDSHAKE], addr);
                        sh.fw_addr = Some(addr);
                    }
                    continue;
                }
                if n > 0 && d[0] >> 4 == CRTP_PORT_SIM {
                    if let Some(pwm) = parse_motor(d) {
                        sh.pwm = pwm;
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
        let (shared, lib_addr, stop) = (shared.clone(), lib_addr.clone(), stop.clone());
        // cflib's packets wait here for the loop, which sends them one per millisecond between
        // the sensor stream's packets (see the loop).
        thread::spawn(move || {
            let mut buf = [0u8; 128];
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, addr)) = lib.recv_from(&mut buf) else {
                    continue;
                };
                *lib_addr.lock().unwrap() = Some(addr);
                let mut sh = shared.lock().unwrap();
                sh.from_cflib.push_back(buf[..n].to_vec());
                sh.from_cflib_max = sh.from_cflib_max.max(sh.from_cflib.len());
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
    if args.lockstep {
        cmd.env("CF2_LOCKSTEP", "1");
    } else {
        cmd.env_remove("CF2_LOCKSTEP");
    }
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
    let fw_addr = if args.lockstep {
        let a = crtp_await_handshake(&sock, Duration::from_secs(10))?;
        shared.lock().unwrap().fw_addr = Some(a);
        a
    } else {
        loop {
            if let Some(a) = shared.lock().unwrap().fw_addr {
                break a;
            }
            if Instant::now() > hs_end {
                bail!("no handshake from the firmware within 10 s");
            }
            thread::sleep(Duration::from_millis(5));
        }
    };
    println!(
        "[{:6.2} s] handshake from {fw_addr}",
        t_start.elapsed().as_secs_f64()
    );

    // The firmware's mixer (quadSysId, read by power_distribution_sitl.c's force/torque mode)
    // configured for the vehicle it flies: arm·0.707 = the plant's rotor offset, thrust-to-torque
    // = km / kf.
    // Then the --param ones: (full name, value, written as u8).
    let mut mixer_params: Vec<(String, f32, bool)> = if args.stock_mixer {
        Vec::new()
    } else {
        vec![
            (
                "quadSysId.armLength".into(),
                (plant.params.arm_xy_m / std::f64::consts::FRAC_1_SQRT_2) as f32,
                false,
            ),
            (
                "quadSysId.thrustToTorque".into(),
                (plant.params.km_nm_per_rpm2 / plant.params.kf_n_per_rpm2) as f32,
                false,
            ),
        ]
    };
    mixer_params.extend(args.params.iter().cloned());

    // Lock-step: the loop sends the IMU packet last and waits for the firmware's tick.
    let mut link = if args.lockstep {
        Some(CrtpLockstep::new(
            sock.try_clone()?,
            fw_addr,
            Duration::from_secs_f64(args.tick_timeout_s),
        ))
    } else {
        None
    };
    // Every motor command of a lock-stepped run with its tick, hashed (FNV-1a): two runs that
    // agree here had the same firmware output every millisecond.
    let mut motor_digest: u64 = 0xcbf2_9ce4_8422_2325;
    let pace = !args.lockstep || args.realtime;
    // Motor-command impairments (lock-step only, repeatable): commands waiting for the plant
    // tick they reach it at, the draws, and how many were dropped.
    let mut motor_queue: std::collections::VecDeque<(u64, [u16; 4])> = Default::default();
    let mut impair_rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut motor_dropped = 0u64;
    let mut plant_pwm = [0u16; 4];

    // --- the loop: 1 ms of plant per IMU packet, paced at 1 kHz of wall clock (or lock-step) -
    const DT: f64 = 1e-3;
    let mut samples: Vec<Sample> = Vec::new();
    let mut stab_started_at: Option<f64> = None; // plant time
    let mut late_resets = 0u32;
    let mut max_late_ms = 0.0f64;
    let mut on_ground = true;
    let mut airborne_once = false;
    let mut crash: Option<(f64, String)> = None;
    let mut touchdown_speed: Option<f64> = None;
    // After a lost link: the speed and tilt at which the vehicle reached the ground.
    let mut fall: Option<(f64, f64)> = None;
    // After a lost link, until the motors stop: the largest distance from where the link was lost.
    let mut drift_m = 0.0f64;
    let mut lost_p: Option<Vector3<f64>> = None;
    let mut stop_sent = 0u32;
    let loop_start = Instant::now();
    let mut deadline = loop_start;
    let mut k: u64 = 0;
    let mut motor_at_engage = 0u64;
    // Take-off: the wall clock and the plant time (the motor packet rate in flight).
    let mut engage_wall: Option<(Instant, f64)> = None;
    let mut engage_motor_rate = 0.0;
    // The mixer parameters: their ids from the TOC (scanned from id 0), then written by id.
    let mut mixer_ids: Vec<Option<u16>> = vec![None; mixer_params.len()];
    let mut toc_next: u16 = 0;
    let mut toc_last_req: (u16, u64) = (u16::MAX, 0);
    let mut mixer_done_at: Option<f64> = None;
    let mut engage_at: Option<f64> = None;
    let mut hold_started_at: Option<f64> = None;
    let mut cflib_sent = 0u64;
    // Motor packets in flight (take-off to landing): the plant time of the last new one, the
    // largest gap between two, and how many gaps were 4 ms or more (the 500 Hz controller's
    // output every 2 ms; the SITL power distribution sends at most one per tick and skips the rest).
    let (mut last_motor, mut last_motor_t) = (0u64, f64::NAN);
    let (mut motor_gap_max_s, mut motor_gaps_4ms) = (0.0f64, 0u32);
    // The high-level pilot: the phase it last commanded, and how often.
    let mut hl_phase: (&str, u32) = ("", 0);
    let mut reset_id: Option<u16> = None;
    let mut reset_sent_at: Option<f64> = None;
    let mut reset_echoed_at: Option<f64> = None;
    // After an estimator reset: the largest distance from the setpoint, and when it last was
    // above 1 cm.
    let mut reset_peak_m = 0.0f64;
    let mut reset_last_over_1cm: Option<f64> = None;
    let mut link_lost_at: Option<f64> = None;
    let mut motors_off_at: Option<f64> = None;
    let setpoint_every = ((1000.0 / args.setpoint_hz).round() as u64).max(1);
    let total_guard_s = 60.0
        + args.settle_s
        + args.takeoff_s
        + hold_s
        + args.land_s
        + args.linger_s
        + args.upload_s
        + traj_total_s;
    loop {
        let t = plant.t_s();
        let (mut pwm, motor_packets) = {
            let sh = shared.lock().unwrap();
            (sh.pwm, sh.motor_packets)
        };
        if link.is_some() {
            while motor_queue.front().is_some_and(|x| x.0 <= k) {
                plant_pwm = motor_queue.pop_front().unwrap().1;
            }
            pwm = plant_pwm;
        }
        // The stabilizer loop started: its console line, or in lock-step its first motor packet
        // (the console pipe is read on its own thread: when a line arrives is not repeatable).
        let stab_started = if args.lockstep {
            motor_packets > 0
        } else {
            console
                .wait_for("Starting stabilizer loop", Duration::ZERO)
                .is_some()
        };
        if stab_started_at.is_none() && stab_started {
            stab_started_at = Some(t);
            println!(
                "[{:6.2} s] stabilizer loop started (plant t = {t:.3} s)",
                t_start.elapsed().as_secs_f64()
            );
        }
        if let (Some(t0), None) = (stab_started_at, mixer_done_at) {
            if k.is_multiple_of(2) {
                let sh = shared.lock().unwrap();
                for (id, (name, ..)) in mixer_ids.iter_mut().zip(&mixer_params) {
                    if id.is_none() {
                        *id = sh.param_toc.iter().find(|(_, n)| n == name).map(|x| x.0);
                    }
                }
                if reset_id.is_none() {
                    reset_id = sh
                        .param_toc
                        .iter()
                        .find(|(_, n)| n == "kalman.resetEstimation")
                        .map(|x| x.0);
                }
                let toc_end = sh.param_toc_end;
                let have_next = sh.param_toc.iter().any(|x| x.0 == toc_next);
                let written: Vec<u16> = sh.param_written.iter().map(|w| w.0).collect();
                drop(sh);
                let need_reset = args.estimator_reset_s.is_some() && reset_id.is_none();
                if mixer_ids.iter().all(Option::is_some) && !need_reset {
                    let pending: Vec<(u16, f32, bool)> = mixer_ids
                        .iter()
                        .zip(&mixer_params)
                        .filter_map(|(id, (_, v, u8))| id.map(|id| (id, *v, *u8)))
                        .filter(|(id, ..)| !written.contains(id))
                        .collect();
                    if pending.is_empty() {
                        mixer_done_at = Some(t);
                        println!(
                            "[{:6.2} s] mixer parameters set ({} TOC items read)",
                            t_start.elapsed().as_secs_f64(),
                            toc_next
                        );
                    } else if k.is_multiple_of(20) {
                        for (id, v, u8) in pending {
                            let pk = if u8 {
                                param_write_u8(id, v as u8)
                            } else {
                                param_write_float(id, v)
                            };
                            let _ = sock.send_to(&pk, fw_addr);
                        }
                    }
                } else if toc_end && need_reset {
                    bail!("the firmware has no parameter kalman.resetEstimation");
                } else if toc_end {
                    let missing: Vec<&str> = mixer_ids
                        .iter()
                        .zip(&mixer_params)
                        .filter(|(id, _)| id.is_none())
                        .map(|(_, p)| p.0.as_str())
                        .collect();
                    bail!("the firmware has no parameter {}", missing.join(", "));
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
        let (phase, setpoint): (&'static str, Option<TrajectoryPoint>) = match engage_at {
            None if stab_started_at.is_none() => ("boot", None),
            None => ("settle", None),
            Some(t_engage) if args.pilot == Pilot::Trajectory => {
                // take-off, hover at p*(0) while the trajectory is uploaded, the trajectory,
                // its end point held, the landing there, the stop
                let te = t - t_engage;
                let up_end = args.takeoff_s + args.upload_s;
                let tr_end = up_end + traj_total_s + TRAJ_TAIL_S;
                if te < args.takeoff_s {
                    let sp = smooth_move(ground_xy, target0.p_m, args.takeoff_s, te, yaw0);
                    ("takeoff", Some(sp))
                } else if te < up_end {
                    let sp = smooth_move(target0.p_m, target0.p_m, 1.0, 0.0, yaw0);
                    ("upload", Some(sp))
                } else if te < tr_end {
                    let t0 = traj_start.map_or(t, |s| s.0);
                    ("trajectory", Some(traj_ref(t - t0)))
                } else {
                    let top = traj_ref(traj_total_s).p_m;
                    match landing(top, te - tr_end, args.land_s, args.linger_s, yaw0) {
                        Some(p) => p,
                        None => break,
                    }
                }
            }
            Some(t_engage) => {
                let te = t - t_engage;
                let hold_end = args.takeoff_s + hold_s;
                let hold_ref = |tau: f64| scenario.reference(tau.clamp(0.0, hold_s));
                if te < args.takeoff_s {
                    let sp = smooth_move(ground_xy, target0.p_m, args.takeoff_s, te, yaw0);
                    ("takeoff", Some(sp))
                } else if te < hold_end {
                    ("hold", Some(hold_ref(te - args.takeoff_s)))
                } else {
                    let top = hold_ref(hold_s).p_m;
                    match landing(top, te - hold_end, args.land_s, args.linger_s, yaw0) {
                        Some(p) => p,
                        None => break,
                    }
                }
            }
        };
        if (phase == "hold" || phase == "trajectory") && hold_started_at.is_none() {
            hold_started_at = Some(t);
            delay_disturbances(&mut plant, t);
        }
        // The radio link: lost from `--link-loss-s` into the hold (setpoints and pose alike:
        // with cflib, motion capture reaches the vehicle over the same radio).
        let link_up = match (args.link_loss_s, hold_started_at) {
            (Some(l), Some(h0)) => t < h0 + l,
            _ => true,
        };
        // The estimator reset: `kalman.resetEstimation = 1`, written until the firmware echoes it.
        if let (Some(r), Some(h0), Some(id)) = (args.estimator_reset_s, hold_started_at, reset_id) {
            if t >= h0 + r && reset_echoed_at.is_none() {
                if shared
                    .lock()
                    .unwrap()
                    .param_written
                    .iter()
                    .any(|w| w.0 == id)
                {
                    reset_echoed_at = Some(t);
                } else if k.is_multiple_of(20) {
                    let _ = sock.send_to(&param_write_u8(id, 1), fw_addr);
                    reset_sent_at.get_or_insert(t);
                }
            }
        }
        if !link_up && link_lost_at.is_none() {
            link_lost_at = Some(t);
        }
        if link_lost_at.is_some() && motors_off_at.is_none() && pwm == [0; 4] {
            motors_off_at = Some(t);
        }
        if motor_packets != last_motor {
            if matches!(phase, "takeoff" | "hold" | "land") && last_motor_t.is_finite() {
                let gap = t - last_motor_t;
                motor_gap_max_s = motor_gap_max_s.max(gap);
                if gap >= 0.0035 {
                    motor_gaps_4ms += 1;
                }
            }
            (last_motor, last_motor_t) = (motor_packets, t);
        }
        let phase = if link_lost_at.is_some() {
            "link lost"
        } else {
            phase
        };
        if phase == "takeoff" && engage_wall.is_none() {
            engage_wall = Some((Instant::now(), t));
            motor_at_engage = motor_packets;
        }
        if phase == "landed" {
            if let Some((w, t0)) = engage_wall.take() {
                // per second of wall clock; in lock-step, of plant time
                let dur = if args.lockstep {
                    t - t0
                } else {
                    w.elapsed().as_secs_f64()
                };
                engage_motor_rate = (motor_packets - motor_at_engage) as f64 / dur;
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
                if motors_off_at.is_some() {
                    fall = Some((-vz, tilt));
                } else if (-vz > 1.0 || tilt > 30.0) && crash.is_none() {
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
        if let (Some(_), Some(sp), "hold") = (reset_sent_at, &setpoint, phase) {
            let e = (s.p_m - sp.p_m).norm();
            reset_peak_m = reset_peak_m.max(e);
            if e > 0.01 {
                reset_last_over_1cm = Some(t);
            }
        }
        if link_lost_at.is_some() && motors_off_at.is_none() {
            let p0 = *lost_p.get_or_insert(s.p_m);
            drift_m = drift_m.max((s.p_m - p0).norm());
        }
        if !s.is_finite() {
            crash.get_or_insert((t, "non-finite state".into()));
            break;
        }
        if s.rot[(2, 2)] < 0.0 {
            crash.get_or_insert((t, "upside down".into()));
        }
        if let (Some(sp), None) = (&setpoint, link_lost_at) {
            if (s.p_m - sp.p_m).norm() > 2.0 {
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
        if link.is_none() {
            let _ = sock.send_to(&imu, fw_addr);
        }
        let pose_now = k.is_multiple_of(10) && link_up;
        let setpoint_now = k % setpoint_every == 5 % setpoint_every && link_up;
        // cflib's packets: one per millisecond, and none in a millisecond that already carries a
        // pose or a setpoint. The firmware's socket link queues 5 packets and drops the rest, its
        // reader runs about once per tick, and cflib's UDP driver never resends: one packet lost
        // stalls a parameter download or a memory write for good.
        // The trajectory's upload: one packet per millisecond in the same slots, before cflib's.
        let mut upload_pk = None;
        if let (Some(up), "upload", true) = (&mut upload, phase, link_up) {
            upload_began_at.get_or_insert(t);
            if !pose_now && !setpoint_now {
                let sh = shared.lock().unwrap();
                upload_pk = up
                    .next_packet(k, &sh)
                    .with_context(|| format!("plant t = {t:.3} s"))?;
            }
            if up.done() && upload_done_at.is_none() {
                upload_done_at = Some(t);
                println!(
                    "[{:6.2} s] trajectory uploaded to memory {} ({} B, {} writes, {} packets of \
                     which {} repeats) and defined, plant t = {t:.3} s",
                    t_start.elapsed().as_secs_f64(),
                    up.mem_id.unwrap_or(0),
                    up.bytes(),
                    up.writes(),
                    up.packets,
                    up.repeats
                );
            }
        }
        if let Some(pk) = &upload_pk {
            let _ = sock.send_to(pk, fw_addr);
        } else if !pose_now && !setpoint_now && link_up {
            let next = shared.lock().unwrap().from_cflib.pop_front();
            if let Some(pk) = next {
                let _ = sock.send_to(&pk, fw_addr);
                cflib_sent += 1;
            }
        }
        if pose_now {
            let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(s.rot));
            let _ = sock.send_to(&ext_pose_packet(&s.p_m, &q), fw_addr);
        }
        // The high-level commander flies its own plan: each phase's command three times (a
        // command is not acknowledged, and a repeat 10 ms later changes nothing). The phase
        // that holds the hover point: the high-level pilot's hold, the trajectory pilot's upload.
        let hl_hold_phase = match args.pilot {
            Pilot::HighLevel => Some("hold"),
            Pilot::Trajectory if link_up => Some("upload"),
            _ => None,
        };
        if let (true, Some(hold_phase)) = (setpoint_now, hl_hold_phase) {
            if hl_phase.0 != phase {
                hl_phase = (phase, 0);
            }
            let pk = match phase {
                "takeoff" => Some(hl_takeoff_packet(target0.p_m.z, yaw0, args.takeoff_s)),
                p if p == hold_phase => Some(hl_go_to_packet(&target0.p_m, yaw0, 1.0)),
                "land" => Some(hl_land_packet(0.0, yaw0, args.land_s)),
                "stop" => Some(hl_stop_packet()),
                _ => None,
            };
            if let (Some(pk), true) = (pk, hl_phase.1 < 3) {
                let _ = sock.send_to(&pk, fw_addr);
                hl_phase.1 += 1;
            }
        }
        if args.pilot == Pilot::Trajectory && link_up && phase == "trajectory" {
            if let Some(up) = &upload {
                if !up.done() {
                    bail!(
                        "the trajectory upload did not finish within --upload-s {} s \
                         (plant t = {t:.3} s): {}",
                        args.upload_s,
                        up.status()
                    );
                }
            }
            // start_trajectory once (a repeat would restart it), relative to the hover
            // point; its answer within 100 ms, else sent again (up to three times)
            let answer = shared
                .lock()
                .unwrap()
                .hl_answers
                .iter()
                .find(|a| a.0 == HL_CMD_START_TRAJECTORY)
                .copied();
            match (answer, traj_start) {
                (Some((_, 0)), _) => {
                    traj_start_answered.get_or_insert(t);
                }
                (Some((_, e)), _) => {
                    bail!("start_trajectory refused by the firmware (error {e})")
                }
                (None, Some((t0, n))) if n >= 3 && t - t0 >= 0.1 => {
                    bail!("start_trajectory not answered after 3 sends 100 ms apart")
                }
                (None, Some((t0, n))) if t - t0 >= 0.1 => {
                    traj_start = Some((t, n + 1));
                }
                (None, None) => traj_start = Some((t, 1)),
                (None, Some(_)) => {}
            }
            if traj_start.is_some_and(|s| s.0 == t) {
                let pk = hl_start_trajectory_packet(0, traj_scale as f32, true, false);
                let _ = sock.send_to(&pk, fw_addr);
            }
        }
        if setpoint_now && args.pilot == Pilot::Stream {
            match &setpoint {
                Some(sp) => {
                    let pk = match args.setpoint {
                        SetpointKind::FullState => full_state_setpoint_packet(
                            &sp.p_m,
                            &sp.v_m_s,
                            &sp.a_m_s2,
                            sp.yaw_rad,
                            sp.yaw_rate_rad_s,
                        ),
                        SetpointKind::Position => {
                            position_setpoint_packet(&sp.p_m, sp.yaw_rad.to_degrees())
                        }
                    };
                    let _ = sock.send_to(&pk, fw_addr);
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
                sp: setpoint.as_ref().map(|sp| sp.p_m).unwrap_or(Vector3::new(
                    f64::NAN,
                    f64::NAN,
                    f64::NAN,
                )),
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

        // Lock-step: the IMU packet last (the firmware's next tick), then wait for that tick.
        if let Some(link) = &mut link {
            let tick = link
                .step(&imu)
                .with_context(|| format!("plant t = {:.3} s", plant.t_s()))?;
            let mut sh = shared.lock().unwrap();
            if let Some(p) = tick.motor {
                let drop = args.motor_drop > 0.0 && impair_rng.gen_bool(args.motor_drop.min(1.0));
                let jitter = if args.motor_jitter_ms > 0 {
                    impair_rng.gen_range(0..=args.motor_jitter_ms as u64)
                } else {
                    0
                };
                if drop {
                    motor_dropped += 1;
                } else {
                    // reaches the plant at loop step k + delay (k: already the next step), never
                    // before a command sent earlier
                    let at = (k + args.motor_delay_ms as u64 + jitter)
                        .max(motor_queue.back().map_or(0, |x| x.0));
                    motor_queue.push_back((at, p));
                }
                sh.pwm = p;
                sh.motor_packets += 1;
                for b in (tick.tick as u64)
                    .to_le_bytes()
                    .into_iter()
                    .chain(p.iter().flat_map(|m| m.to_le_bytes()))
                {
                    motor_digest = (motor_digest ^ b as u64).wrapping_mul(0x100_0000_01b3);
                }
            }
            for d in &tick.other {
                param_answer(d, &mut sh);
            }
            drop(sh);
            if let (Some(lib), Some(a)) = (&lib_sock, *lib_addr.lock().unwrap()) {
                for d in &tick.other {
                    let _ = lib.send_to(d, a);
                    relayed.fetch_add(1, Ordering::Relaxed);
                }
            }
        }

        // Pace: the next packet 1 ms after this one's deadline; never burst to catch up.
        if pace {
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
    }
    let wall = loop_start.elapsed().as_secs_f64();
    let (motor_packets, last_pwm, param_written, from_cflib_max) = {
        let sh = shared.lock().unwrap();
        (
            sh.motor_packets,
            sh.pwm,
            sh.param_written.clone(),
            sh.from_cflib_max,
        )
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
    for ((name, v, u8), id) in mixer_params.iter().zip(&mixer_ids) {
        let echo = id
            .and_then(|id| param_written.iter().find(|w| w.0 == id))
            .map(|w| match u8 {
                true => format!("firmware echoed {}", w.1[0]),
                false => format!("firmware echoed {:.6}", f32::from_le_bytes(w.1)),
            })
            .unwrap_or_else(|| "NOT SET".into());
        println!("param: {name} (id {id:?}) = {v:.6}: {echo}");
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
    let traj_stats = stats(&|s| s.phase == "trajectory");
    if let Some(up) = &upload {
        report("hover while uploading", stats(&|s| s.phase == "upload"));
        report("trajectory (vs its polynomial)", traj_stats);
        println!(
            "trajectory upload: memory id {} ({} B), {} B in {} writes, {} packets ({} repeats), \
             done {} after the hover began; start_trajectory sent at plant t = {}, answered {}",
            up.mem_id.map_or("-".into(), |i| i.to_string()),
            up.mem_size,
            up.bytes(),
            up.writes(),
            up.packets,
            up.repeats,
            match (upload_done_at, upload_began_at) {
                (Some(d), Some(b)) => format!("{:.0} ms", (d - b) * 1e3),
                _ => "NEVER".into(),
            },
            traj_start.map_or("-".into(), |s| format!("{:.3} s ({} sends)", s.0, s.1)),
            match (traj_start_answered, traj_start) {
                (Some(a), Some(s)) => format!("{:.0} ms later", (a - s.0) * 1e3),
                _ => "NEVER".into(),
            }
        );
    }
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
    if let Some(tr) = reset_sent_at {
        println!(
            "estimator reset written at plant t = {tr:.3} s ({} s into the hold), echoed {}; then, to the hold's end: peak error {:.2} cm, back within 1 cm {}",
            args.estimator_reset_s.unwrap_or(0.0),
            reset_echoed_at
                .map(|e| format!("{:.0} ms later", (e - tr) * 1e3))
                .unwrap_or_else(|| "NEVER".into()),
            reset_peak_m * 100.0,
            reset_last_over_1cm
                .map(|e| format!("{:.2} s after", e - tr))
                .unwrap_or_else(|| "throughout".into())
        );
    }
    if let Some(tl) = link_lost_at {
        let off = motors_off_at.map(|t| format!("{:.3} s after", t - tl));
        println!(
            "link lost at plant t = {tl:.3} s ({} s into the hold): motors stopped {}; drift until then {:.1} cm; reached the ground at {}",
            args.link_loss_s.unwrap_or(0.0),
            off.unwrap_or_else(|| "NEVER".into()),
            drift_m * 100.0,
            fall.map(|(v, tilt)| format!("{v:.2} m/s, tilt {tilt:.0} deg"))
                .unwrap_or_else(|| "- (still airborne)".into())
        );
    }
    match &crash {
        Some((t, why)) => println!("CRASHED at plant t = {t:.2} s: {why}"),
        None => println!(
            "crashed: no (airborne: {airborne_once}, landed: {})",
            on_ground && airborne_once
        ),
    }
    if let Some(link) = &link {
        println!(
            "timing: lock-step{}: {:.3} s of plant in {wall:.3} s of wall clock ({:.3} plant s per \
             wall s, {:.1} us of wall clock per tick); ticks {} = IMU packets {k}; motor packets \
             {motor_packets} ({engage_motor_rate:.1} per plant s in flight), digest {motor_digest:016x}; \
             CRTP relayed to cflib {}, from cflib {} (at most {} waiting)",
            if args.realtime { " paced in real time" } else { "" },
            plant.t_s(),
            plant.t_s() / wall,
            wall / k as f64 * 1e6,
            link.ticks(),
            relayed.load(Ordering::Relaxed),
            cflib_sent,
            from_cflib_max
        );
    } else {
        println!(
            "timing: {:.3} s of plant in {wall:.3} s of wall clock ({:.4} plant s per wall s); IMU \
             packets {k} ({:.1} /s); motor packets {motor_packets} ({:.1} /s overall, {engage_motor_rate:.1} /s \
             in flight); max lateness {max_late_ms:.2} ms, {late_resets} pacing resets; CRTP relayed \
             to cflib {}, from cflib {} (at most {} waiting)",
            plant.t_s(),
            plant.t_s() / wall,
            k as f64 / wall,
            motor_packets as f64 / wall,
            relayed.load(Ordering::Relaxed),
            cflib_sent,
            from_cflib_max
        );
    }
    println!(
        "motor packets in flight: largest gap {:.1} ms, {motor_gaps_4ms} gaps of 4 ms or more",
        motor_gap_max_s * 1e3
    );
    write_csv(&args.out.join("flight.csv"), &samples)?;
    plot(&args.out.join("flight.svg"), &samples, &scenario.name)?;
    let cm = |x: f64| (x * 1e4).round() / 100.0;
    let settled = stats(&|s| s.phase == "hold" && s.t_s >= hold_t0 + args.window_s);
    let summary = serde_json::json!({
        "scenario": scenario.name,
        "setpoint": format!("{:?}", args.setpoint),
        "setpoint_hz": args.setpoint_hz,
        "window_s": args.window_s,
        "hold_rmse_cm": settled.map(|x| cm(x.0)),
        "hold_max_cm": settled.map(|x| cm(x.1)),
        "takeoff_rmse_cm": stats(&|s| s.phase == "takeoff").map(|x| cm(x.0)),
        "landing_rmse_cm": stats(&|s| s.phase == "land").map(|x| cm(x.0)),
        "pilot": format!("{:?}", args.pilot),
        "trajectory": upload.as_ref().map(|up| serde_json::json!({
            "shape": "figure of eight",
            "size_m": [2.0 * args.traj_size_m, args.traj_size_m],
            "duration_s": traj_total_s,
            "time_scale": traj_scale,
            "pieces": traj_pieces.len(),
            "bytes": up.bytes(),
            "mem_id": up.mem_id,
            "writes": up.writes(),
            "packets": up.packets,
            "repeats": up.repeats,
            "upload_ms": upload_done_at.zip(upload_began_at).map(|(d, b)| (d - b) * 1e3),
            "started_at_s": traj_start.map(|s| s.0),
            "start_answered": traj_start_answered.is_some(),
            "rmse_cm": traj_stats.map(|x| cm(x.0)),
            "max_cm": traj_stats.map(|x| cm(x.1)),
            "rmse_z_cm": traj_stats.map(|x| cm(x.2)),
        })),
        "touchdown_m_s": touchdown_speed,
        "crashed": crash.as_ref().map(|(t, why)| format!("at {t:.2} s: {why}")),
        "airborne": airborne_once,
        "link_loss": link_lost_at.map(|tl| serde_json::json!({
            "at_hold_s": args.link_loss_s,
            "motors_off_after_s": motors_off_at.map(|t| t - tl),
            "drift_cm": cm(drift_m),
            "ground_speed_m_s": fall.map(|f| f.0),
            "ground_tilt_deg": fall.map(|f| f.1),
        })),
        "estimator_reset": reset_sent_at.map(|tr| serde_json::json!({
            "at_hold_s": args.estimator_reset_s,
            "echoed_after_s": reset_echoed_at.map(|e| e - tr),
            "peak_cm": cm(reset_peak_m),
            "back_within_1cm_after_s": reset_last_over_1cm.map(|e| e - tr),
        })),
        "timing": if args.lockstep { "lockstep" } else { "wall-clock" },
        "ticks": link.as_ref().map(|l| l.ticks()),
        "motor_digest": link.as_ref().map(|_| format!("{motor_digest:016x}")),
        "plant_s_per_wall_s": plant.t_s() / wall,
        "max_late_ms": max_late_ms,
        "pacing_resets": late_resets,
        "motor_packets_per_s_in_flight": engage_motor_rate,
        "motor_gap_max_ms": motor_gap_max_s * 1e3,
        "motor_gaps_4ms": motor_gaps_4ms,
        "motor_impairment": (args.motor_delay_ms > 0 || args.motor_jitter_ms > 0 || args.motor_drop > 0.0)
            .then(|| serde_json::json!({
                "delay_ms": args.motor_delay_ms,
                "jitter_ms": args.motor_jitter_ms,
                "drop": args.motor_drop,
                "seed": args.seed,
                "dropped": motor_dropped,
            })),
    });
    host_train::io::write_json_atomic(&args.out.join("summary.json"), &summary)?;
    println!(
        "wrote {}/flight.csv, flight.svg, console.log, summary.json",
        args.out.display()
    );
    if crash.is_some() || !airborne_once {
        std::process::exit(3);
    }
    if link_lost_at.is_some() && motors_off_at.is_none() {
        // the supervisor's watchdog must stop the motors after a lost link
        std::process::exit(4);
    }
    Ok(())
}
