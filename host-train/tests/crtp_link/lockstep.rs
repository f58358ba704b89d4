//! The same in lock-step: one firmware tick per IMU packet, a tick-done packet after it.

use super::*;

/// What the lock-step stub did: IMU packets (ticks), motor packets sent, poses and setpoints seen,
/// parameter writes echoed.
#[derive(Debug, Default, PartialEq)]
struct LockstepStubLog {
    ticks: u32,
    motors_sent: u32,
    poses: u32,
    setpoints: u32,
    params: Vec<(u16, f32)>,
}

/// The patched firmware's side of lock-step (`cf-lockstep.patch`), as `socketlink.c`'s idle hook
/// does it: every datagram is handled before the next is read; an IMU packet advances the tick;
/// then the tick's output (the motor packet: none for the first `boot_ticks` ticks, as before
/// the stabilizer loop starts, and none every `skip_every`-th tick, as the SITL power
/// distribution skips) and last the tick-done packet. `tick_done: false` plays a firmware
/// without the patch (motor packets, never a tick-done).
fn lockstep_stub(
    plant_addr: SocketAddr,
    mass_kg: f64,
    g: f64,
    boot_ticks: u32,
    skip_every: u32,
    tick_done: bool,
) -> LockstepStubLog {
    let sock = stub_handshake(plant_addr);
    let mut buf = [0u8; 64];
    let mut log = LockstepStubLog::default();
    let (mut z, mut vz, mut z_ref) = (f64::NAN, 0.0, (0.0, 0.0));
    while let Ok((n, _)) = sock.recv_from(&mut buf) {
        let d = &buf[..n];
        if d == [0xFF] {
            break; // the test's end
        }
        if parse_imu(d).is_some() {
            log.ticks += 1;
            let t = log.ticks;
            if t > boot_ticks && !t.is_multiple_of(skip_every) {
                let f = mass_kg * (g + 30.0 * (z_ref.0 - z) + 10.0 * (z_ref.1 - vz));
                let pwm = force_to_pwm(f / 4.0);
                sock.send_to(&motor_packet([pwm; 4]), plant_addr).unwrap();
                log.motors_sent += 1;
            }
            if tick_done {
                sock.send_to(&tick_done_packet(t), plant_addr).unwrap();
            }
        } else if let Some((p, _q)) = parse_ext_pose(d) {
            log.poses += 1;
            if z.is_finite() {
                vz = (p.z - z) / 0.01;
            }
            z = p.z;
        } else if let Some(CrtpSetpoint::FullState { p_m, v_m_s, .. }) = parse_setpoint(d) {
            log.setpoints += 1;
            z_ref = (p_m.z, v_m_s.z);
        } else if n == 7 && d[0] == crtp_header(CRTP_PORT_PARAM, 2) {
            let id = u16::from_le_bytes([d[1], d[2]]);
            log.params
                .push((id, f32::from_le_bytes([d[3], d[4], d[5], d[6]])));
            sock.send_to(d, plant_addr).unwrap();
        }
    }
    log
}

/// A lock-stepped flight: the stub's log, every tick's answer (tick, motor packet, other
/// datagrams), the plant's final state, the motor packets the link counted.
type LockstepFlight = (
    LockstepStubLog,
    Vec<(u32, Option<[u16; 4]>, usize)>,
    PlantState,
    u64,
);

/// One lock-stepped flight against the stub, as `firmware_sitl_plant --lockstep` flies: per
/// millisecond the pose and the setpoint due (every 10 ms), then the IMU sample through
/// `CrtpLockstep::step`, then the plant 1 ms with the last motor command. Returns the stub's log,
/// every tick's answer, the plant's final state and the motor packets the link counted.
fn fly_lockstepped(ticks: u32, boot_ticks: u32, skip_every: u32) -> LockstepFlight {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    let addr = sock.local_addr().unwrap();
    let mut plant = Plant::nominal(PlantState::at_rest(Vector3::new(0.0, 0.0, 1.0), 0.0));
    let (m, g, kf) = (
        plant.params.mass_kg,
        plant.params.gravity_m_s2,
        plant.params.kf_n_per_rpm2,
    );
    let stub = thread::spawn(move || lockstep_stub(addr, m, g, boot_ticks, skip_every, true));
    let fw = crtp_await_handshake(&sock, Duration::from_secs(5)).unwrap();
    let mut link = CrtpLockstep::new(sock.try_clone().unwrap(), fw, Duration::from_secs(5));
    let mut answers = Vec::new();
    for k in 0..ticks {
        let t = k as f64 * 1e-3;
        let s = *plant.state();
        if k == 100 {
            // a parameter write: echoed within the tick it was sent in
            link.send(&param_write_float(1, 0.0396)).unwrap();
        }
        if k % 10 == 0 {
            link.send(&ext_pose_packet(
                &s.p_m,
                &UnitQuaternion::from_matrix(&s.rot),
            ))
            .unwrap();
            let z_ref = 1.0 + 0.2 * ((t - 1.0) / 1.0).clamp(0.0, 1.0);
            let vz_ref = if (1.0..2.0).contains(&t) { 0.2 } else { 0.0 };
            link.send(&full_state_setpoint_packet(
                &Vector3::new(0.0, 0.0, z_ref),
                &Vector3::new(0.0, 0.0, vz_ref),
                &Vector3::zeros(),
                0.0,
                0.0,
            ))
            .unwrap();
        }
        let imu = imu_packet(
            plant.accelerometer() / g,
            s.w_body_rad_s.map(f64::to_degrees),
        );
        let tick = link.step(&imu).unwrap();
        answers.push((tick.tick, tick.motor, tick.other.len()));
        // hold the last command when the firmware skipped this tick
        plant.step(link.pwm.map(|p| pwm_to_rpm(p, kf)), 1e-3);
    }
    assert_eq!(link.ticks(), ticks);
    sock.send_to(&[0xFF], fw).unwrap();
    (
        stub.join().unwrap(),
        answers,
        *plant.state(),
        link.motor_packets,
    )
}

#[test]
fn the_plant_flies_a_lockstepped_stub_tick_by_tick_and_repeatably() {
    let (ticks, boot, skip) = (3000u32, 200u32, 7u32);
    let (log, answers, end, motors) = fly_lockstepped(ticks, boot, skip);

    // One plant step per IMU packet, one firmware tick per IMU packet, every tick answered in
    // order, and every motor packet the stub sent arrived in the tick it was sent in.
    assert_eq!(log.ticks, ticks);
    assert_eq!(answers.len() as u32, ticks);
    let expected_motors = (1..=ticks)
        .filter(|t| *t > boot && !t.is_multiple_of(skip))
        .count();
    assert_eq!(log.motors_sent as usize, expected_motors);
    assert_eq!(motors as usize, expected_motors);
    for (k, (tick, motor, _)) in answers.iter().enumerate() {
        let t = k as u32 + 1;
        assert_eq!(*tick, t, "answers out of order");
        assert_eq!(
            motor.is_some(),
            t > boot && !t.is_multiple_of(skip),
            "tick {t}: a motor packet where the stub sent none, or the reverse"
        );
    }
    // The extras reached the firmware before their tick's IMU sample; the write's echo came back
    // in that same tick.
    assert_eq!(log.poses, ticks / 10);
    assert_eq!(log.setpoints, ticks / 10);
    assert_eq!(log.params, vec![(1, 0.0396)]);
    let echo: Vec<usize> = (0..answers.len()).filter(|&k| answers[k].2 > 0).collect();
    assert_eq!(echo, vec![100], "the echo came in another tick");
    // The loop closed through the bytes, skipped ticks and all: 1.0 -> 1.2 m.
    assert!((end.p_m.z - 1.2).abs() < 0.01, "z = {} m", end.p_m.z);

    // Again: the same bytes every tick and the same plant, to the bit (no wall clock anywhere).
    let (log2, answers2, end2, motors2) = fly_lockstepped(ticks, boot, skip);
    assert_eq!(log2, log);
    assert_eq!(answers2, answers);
    assert_eq!(motors2, motors);
    assert_eq!(end2.p_m, end.p_m);
    assert_eq!(end2.v_body_m_s, end.v_body_m_s);
}

#[test]
fn lockstep_reports_a_firmware_that_never_says_its_tick_is_done() {
    // A firmware without the patch (or run without CF2_LOCKSTEP=1): motor packets, no tick-done.
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    let addr = sock.local_addr().unwrap();
    let stub = thread::spawn(move || lockstep_stub(addr, 0.03, 9.81, 0, u32::MAX, false));
    let fw = crtp_await_handshake(&sock, Duration::from_secs(5)).unwrap();
    let mut link = CrtpLockstep::new(sock.try_clone().unwrap(), fw, Duration::from_millis(200));
    let t0 = Instant::now();
    let err = link
        .step(&imu_packet(Vector3::z(), Vector3::zeros()))
        .expect_err("a tick without a tick-done must fail, not hang");
    assert!(t0.elapsed() < Duration::from_secs(2));
    assert_eq!(err.kind(), ErrorKind::TimedOut);
    let msg = err.to_string();
    assert!(
        msg.contains("tick 1") && msg.contains("CF2_LOCKSTEP"),
        "unhelpful: {msg}"
    );
    assert_eq!(link.motor_packets, 1, "the motor packet was still taken");
    // Only an IMU packet is a step.
    assert_eq!(
        link.step(&motor_packet([0; 4])).unwrap_err().kind(),
        ErrorKind::InvalidInput
    );
    sock.send_to(&[0xFF], fw).unwrap();
    stub.join().unwrap();
    assert_eq!(parse_tick_done(&tick_done_packet(3)), Some(3));
}
