//! A closed loop over real UDP sockets between host-train's plant and a stub firmware.

use super::*;

/// The stub firmware's parameters.
const PARAMS: [&str; 3] = [
    "stabilizer.controller",
    "quadSysId.armLength",
    "quadSysId.thrustToTorque",
];

/// What the stub saw.
#[derive(Default)]
struct StubLog {
    imu: Vec<(Vector3<f64>, Vector3<f64>)>,
    poses: usize,
    setpoints: Vec<CrtpSetpoint>,
    params: Vec<(u16, f32)>,
}

/// The firmware's side: the handshake as `socketlink.c` does it (send the handshake byte until
/// it comes back), then per IMU sample one motor packet. Its controller is a plain altitude loop
/// on the external pose and the full-state setpoint (equal rotor forces, through the power
/// distribution's force → PWM map): not the point, only enough to close the loop.
fn stub_firmware(plant_addr: SocketAddr, mass_kg: f64, g: f64) -> StubLog {
    let sock = stub_handshake(plant_addr);
    let mut buf = [0u8; 64];
    let mut log = StubLog::default();
    let (mut z, mut z_prev, mut vz) = (0.0, f64::NAN, 0.0);
    let mut z_ref = (0.0, 0.0);
    while let Ok((n, _)) = sock.recv_from(&mut buf) {
        let d = &buf[..n];
        if d == [0xFF] {
            break; // the test's end
        }
        if let Some(imu) = parse_imu(d) {
            log.imu.push(imu);
            let f = mass_kg * (g + 30.0 * (z_ref.0 - z) + 10.0 * (z_ref.1 - vz));
            let pwm = force_to_pwm(f / 4.0);
            sock.send_to(&motor_packet([pwm; 4]), plant_addr).unwrap();
        } else if let Some((p, _q)) = parse_ext_pose(d) {
            log.poses += 1;
            if z_prev.is_finite() {
                vz = (p.z - z_prev) / 0.01;
            }
            z_prev = p.z;
            z = p.z;
        } else if let Some(sp) = parse_setpoint(d) {
            if let CrtpSetpoint::FullState { p_m, v_m_s, .. } = &sp {
                z_ref = (p_m.z, v_m_s.z);
            }
            log.setpoints.push(sp);
        } else if n == 7 && d[0] == crtp_header(CRTP_PORT_PARAM, 2) {
            // a write by id: applied, and echoed once done
            let id = u16::from_le_bytes([d[1], d[2]]);
            log.params
                .push((id, f32::from_le_bytes([d[3], d[4], d[5], d[6]])));
            sock.send_to(d, plant_addr).unwrap();
        } else if n == 4 && d[0] == crtp_header(CRTP_PORT_PARAM, 0) && d[1] == 2 {
            // a TOC request: the item, or past the end the command byte alone
            let id = u16::from_le_bytes([d[2], d[3]]) as usize;
            let mut answer = vec![crtp_header(CRTP_PORT_PARAM, 0), 2];
            if let Some(name) = PARAMS.get(id) {
                let (group, name) = name.split_once('.').unwrap();
                answer.extend_from_slice(&(id as u16).to_le_bytes());
                answer.push(6);
                answer.extend_from_slice(group.as_bytes());
                answer.push(0);
                answer.extend_from_slice(name.as_bytes());
                answer.push(0);
            }
            sock.send_to(&answer, plant_addr).unwrap();
        }
    }
    log
}

#[test]
fn the_plant_flies_a_stub_firmware_over_udp() {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let addr = sock.local_addr().unwrap();
    let mut plant = Plant::nominal(PlantState::at_rest(Vector3::new(0.0, 0.0, 1.0), 0.0));
    let (m, g, kf) = (
        plant.params.mass_kg,
        plant.params.gravity_m_s2,
        plant.params.kf_n_per_rpm2,
    );
    let stub = thread::spawn(move || stub_firmware(addr, m, g));

    // Handshake: the first datagram is the handshake byte; echo it.
    let mut buf = [0u8; 64];
    let fw = loop {
        let (n, from) = sock
            .recv_from(&mut buf)
            .expect("no handshake from the stub");
        if buf[..n] == [CRTP_HANDSHAKE] {
            sock.send_to(&[CRTP_HANDSHAKE], from).unwrap();
            break from;
        }
    };
    // Drain the stub's extra handshakes, then read the parameter TOC until its end.
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut toc = Vec::new();
    for id in 0.. {
        sock.send_to(&param_toc_request(id), fw).unwrap();
        let answer = loop {
            let (n, _) = sock.recv_from(&mut buf).expect("no TOC answer");
            if let Some(a) = parse_param_answer(&buf[..n]) {
                break a;
            }
        };
        match answer {
            ParamAnswer::TocItem { id: got, name, .. } => {
                assert_eq!(got, id);
                toc.push(name);
            }
            ParamAnswer::TocEnd => break,
            other => panic!("unexpected {other:?}"),
        }
    }
    assert_eq!(toc, PARAMS);
    let arm_id = toc.iter().position(|n| n == "quadSysId.armLength").unwrap() as u16;
    sock.send_to(&param_write_float(arm_id, 0.0396), fw)
        .unwrap();
    let echoed = loop {
        let (n, _) = sock.recv_from(&mut buf).expect("the write was not echoed");
        if let Some(ParamAnswer::Written { id, value }) = parse_param_answer(&buf[..n]) {
            break (id, f32::from_le_bytes(value));
        }
    };
    assert_eq!(echoed, (arm_id, 0.0396));

    // 3 s in lock-step: per millisecond one IMU sample out and one motor packet back; the pose
    // at 100 Hz, a full-state setpoint at 100 Hz: hold 1.0 m, then from 1 s climb to 1.2 m.
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut sent_imu = Vec::new();
    let mut sent_sp = Vec::new();
    let mut pwm_seen = Vec::new();
    for k in 0..3000u32 {
        let t = k as f64 * 1e-3;
        let s = *plant.state();
        if k % 10 == 0 {
            let q = UnitQuaternion::from_matrix(&s.rot);
            sock.send_to(&ext_pose_packet(&s.p_m, &q), fw).unwrap();
            let u = ((t - 1.0) / 1.0).clamp(0.0, 1.0);
            let z_ref = 1.0 + 0.2 * u;
            let vz_ref = if (0.0..1.0).contains(&(t - 1.0)) {
                0.2
            } else {
                0.0
            };
            let sp = (
                Vector3::new(0.0, 0.0, z_ref),
                Vector3::new(0.0, 0.0, vz_ref),
            );
            sock.send_to(
                &full_state_setpoint_packet(&sp.0, &sp.1, &Vector3::zeros(), 0.0, 0.0),
                fw,
            )
            .unwrap();
            sent_sp.push(sp);
        }
        let acc_g = plant.accelerometer() / g;
        let gyro = s.w_body_rad_s.map(f64::to_degrees);
        sock.send_to(&imu_packet(acc_g, gyro), fw).unwrap();
        sent_imu.push(acc_g);
        let pwm = loop {
            let (n, _) = sock.recv_from(&mut buf).expect("no motor packet");
            if let Some(p) = parse_motor(&buf[..n]) {
                break p;
            }
        };
        pwm_seen.push(pwm);
        plant.step(pwm.map(|p| pwm_to_rpm(p, kf)), 1e-3);
    }
    sock.send_to(&[0xFF], fw).unwrap();
    let log = stub.join().unwrap();

    // Everything sent arrived and decoded to what was sent (to the layouts' resolution).
    assert_eq!(log.imu.len(), 3000);
    assert_eq!(log.poses, 300);
    assert_eq!(log.params, vec![(arm_id, 0.0396)]);
    for (got, sent) in log.imu.iter().zip(&sent_imu) {
        assert!((got.0 - sent).amax() <= 0.5 * 32.0 / 65536.0 + 1e-12);
    }
    assert_eq!(log.setpoints.len(), sent_sp.len());
    for (got, sent) in log.setpoints.iter().zip(&sent_sp) {
        let CrtpSetpoint::FullState {
            p_m, v_m_s, q_xyzw, ..
        } = got
        else {
            panic!("not a full-state setpoint: {got:?}");
        };
        assert!((p_m - sent.0).amax() <= 0.0005 && (v_m_s - sent.1).amax() <= 0.0005);
        assert!((q_xyzw[3] - 1.0).abs() < 1e-9, "yaw 0 is the identity");
    }
    // The loop closed through the bytes: the plant climbed to the setpoint and holds it.
    let z = plant.state().p_m.z;
    assert!((z - 1.2).abs() < 0.01, "z = {z} m, not the 1.2 m setpoint");
    // Hover PWM: each rotor's force is a quarter of the weight.
    let hover = pwm_to_force_n(pwm_seen[999][0]) * 4.0;
    assert!(
        (hover - m * g).abs() < 0.01 * m * g,
        "hover force {hover} N"
    );
}
