//! CrazySim's UDP link to the SITL Crazyflie firmware, held in CI without a firmware checkout
//! (`tools/firmware-sitl` flies the real firmware; CI has none): the packets against their
//! published byte layouts, and a closed loop over real UDP sockets between host-train's plant and
//! a stub firmware that speaks the firmware's side (handshake, parameter TOC and writes, IMU in,
//! motor PWM out, external pose and full-state setpoints decoded as the firmware decodes them),
//! and the same in lock-step (`tools/firmware-sitl/patches/cf-lockstep.patch`: one firmware tick
//! per IMU packet, a tick-done packet after it) through host-train's `CrtpLockstep`, the plant
//! side of `firmware_sitl_plant --lockstep`.

use std::io::ErrorKind;
use std::net::{SocketAddr, UdpSocket};
use std::thread;
use std::time::{Duration, Instant};

use host_train::io::{
    crtp_await_handshake, crtp_header, ext_pose_packet, force_to_pwm, full_state_setpoint_packet,
    hl_go_to_packet, hl_land_packet, hl_stop_packet, hl_takeoff_packet, imu_packet, motor_packet,
    param_toc_request, param_write_float, parse_ext_pose, parse_imu, parse_motor,
    parse_param_answer, parse_setpoint, parse_tick_done, position_setpoint_packet, pwm_to_force_n,
    pwm_to_rpm, quat_compress, stop_setpoint_packet, tick_done_packet, CrtpLockstep, CrtpSetpoint,
    ParamAnswer, CRTP_HANDSHAKE, CRTP_PORT_PARAM,
};
use host_train::io::{
    crtp_mem_count_request, crtp_mem_info_request, crtp_mem_read_request, crtp_mem_write_packet,
    crtp_mem_write_packets, hl_define_trajectory_packet, hl_start_trajectory_packet,
    parse_crtp_mem_answer, parse_hl_answer, poly4d_trajectory_eval, CrtpMemAnswer, Poly4d,
    POLY4D_BYTES,
};
use host_train::{Plant, PlantState};
use nalgebra::{UnitQuaternion, Vector3};

#[test]
fn packets_have_the_firmwares_byte_layouts() {
    // IMU: header 0x9C (port 9, link bits, channel 0), type 0, then int16 little-endian:
    // 1 g = 2048 LSB, 1000 deg/s = 16384 LSB.
    assert_eq!(
        imu_packet(
            Vector3::new(0.0, -0.5, 1.0),
            Vector3::new(1000.0, 0.0, -1.0)
        ),
        vec![0x9C, 0, 0, 0, 0x00, 0xFC, 0x00, 0x08, 0x00, 0x40, 0, 0, 0xF0, 0xFF]
    );
    // Saturation at the int16 range, never wrapping.
    let sat = parse_imu(&imu_packet(
        Vector3::new(100.0, -100.0, 0.0),
        Vector3::zeros(),
    ))
    .unwrap();
    assert!(sat.0.x > 15.9 && sat.0.y < -15.9);
    // Motors: 4 × uint16 little-endian after the header.
    assert_eq!(
        motor_packet([1, 0x0203, 0xFFFF, 0]),
        vec![0x9C, 1, 0, 3, 2, 0xFF, 0xFF, 0, 0]
    );
    // External pose: port 6 channel 1 (0x6D), type 8, 7 × f32.
    let pose = ext_pose_packet(&Vector3::new(1.0, 2.0, 3.0), &UnitQuaternion::identity());
    assert_eq!(&pose[..2], &[0x6D, 8]);
    assert_eq!(&pose[2..6], &1.0f32.to_le_bytes());
    assert_eq!(&pose[26..30], &1.0f32.to_le_bytes());
    // Position setpoint: port 7 channel 0 (0x7C), type 7, x y z yaw(deg) as f32.
    let pos = position_setpoint_packet(&Vector3::new(0.5, 0.0, 1.0), 90.0);
    assert_eq!(pos.len(), 18);
    assert_eq!(&pos[..2], &[0x7C, 7]);
    assert_eq!(&pos[14..18], &90.0f32.to_le_bytes());
    // Full state: type 6, 9 × int16 mm, mm/s, mm/s², the compressed quaternion, 3 × int16 mrad/s.
    let fs = full_state_setpoint_packet(
        &Vector3::new(0.5, -0.25, 1.0),
        &Vector3::new(0.0, 0.1, 0.0),
        &Vector3::new(0.0, 0.0, -9.81),
        0.0,
        0.5,
    );
    assert_eq!(fs.len(), 30);
    assert_eq!(&fs[..2], &[0x7C, 6]);
    assert_eq!(&fs[2..8], &[0xF4, 0x01, 0x06, 0xFF, 0xE8, 0x03]); // 500, -250, 1000 mm
    assert_eq!(&fs[18..20], &(-9810i16).to_le_bytes());
    // Identity: w (index 3) largest, the other three zero.
    assert_eq!(&fs[20..24], &(3u32 << 30).to_le_bytes());
    assert_eq!(&fs[28..30], &500i16.to_le_bytes());
    // A yaw of 90 deg: w = z = 0.7071; the first largest (z, index 2) is sent, w as 511.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    assert_eq!(quat_compress([0.0, 0.0, s, s]), (2 << 30) | 511);
    assert_eq!(stop_setpoint_packet(), vec![0x7C, 0]);
    // High-level commander: port 8 channel 0 (0x8C), the command, group mask 0, then packed
    // fields: take-off / land (7 / 8) height, yaw, useCurrentYaw, duration; go-to (4) relative,
    // x y z yaw duration; stop (3).
    let takeoff = hl_takeoff_packet(1.0, 0.5, 2.5);
    assert_eq!(takeoff.len(), 3 + 4 + 4 + 1 + 4);
    assert_eq!(&takeoff[..3], &[0x8C, 7, 0]);
    assert_eq!(&takeoff[3..7], &1.0f32.to_le_bytes());
    assert_eq!(takeoff[11], 0, "the yaw given, not the current one");
    assert_eq!(&takeoff[12..16], &2.5f32.to_le_bytes());
    assert_eq!(hl_land_packet(0.0, 0.0, 2.0)[1], 8);
    let go = hl_go_to_packet(&Vector3::new(0.5, 0.0, 1.0), 0.0, 1.0);
    assert_eq!(go.len(), 4 + 5 * 4);
    assert_eq!(&go[..4], &[0x8C, 4, 0, 0]);
    assert_eq!(&go[4..8], &0.5f32.to_le_bytes());
    assert_eq!(hl_stop_packet(), vec![0x8C, 3, 0]);
    // Parameters: port 2; TOC request on channel 0 (CMD_GET_ITEM_V2, id), write on channel 2.
    assert_eq!(param_toc_request(0x0102), vec![0x2C, 2, 2, 1]);
    let w = param_write_float(197, 0.25);
    assert_eq!(&w[..3], &[0x2E, 197, 0]);
    assert_eq!(&w[3..], &0.25f32.to_le_bytes());
    // A TOC item as the firmware answers it: id, type, "group\0name\0".
    let mut item = vec![crtp_header(CRTP_PORT_PARAM, 0), 2, 5, 0, 0x06];
    item.extend_from_slice(b"quadSysId\0armLength\0");
    assert_eq!(
        parse_param_answer(&item),
        Some(ParamAnswer::TocItem {
            id: 5,
            kind: 6,
            name: "quadSysId.armLength".into()
        })
    );
    assert_eq!(
        parse_param_answer(&[0x2C, 2]),
        Some(ParamAnswer::TocEnd),
        "an answer past the TOC's end is the command byte alone"
    );
}

#[test]
fn trajectory_packets_have_the_firmwares_byte_layouts() {
    // define_trajectory: 0x8C, command 6, id, location 1 (memory), type 0 (poly4d), offset
    // uint32 LE, n_pieces.
    assert_eq!(
        hl_define_trajectory_packet(3, 0x0102_0304, 10),
        vec![0x8C, 6, 3, 1, 0, 0x04, 0x03, 0x02, 0x01, 10]
    );
    // start_trajectory: command 5, group mask 0, relative, reversed, id, time scale f32
    // (1.0 = 0x3F800000, 2.0 = 0x40000000).
    assert_eq!(
        hl_start_trajectory_packet(2, 1.0, true, false),
        vec![0x8C, 5, 0, 1, 0, 2, 0x00, 0x00, 0x80, 0x3F]
    );
    assert_eq!(
        hl_start_trajectory_packet(9, 2.0, false, true),
        vec![0x8C, 5, 0, 0, 1, 9, 0x00, 0x00, 0x00, 0x40]
    );
    // The commander's answer: the command's first 4 data bytes, the 4th replaced by the result.
    assert_eq!(parse_hl_answer(&[0x8C, 5, 0, 1, 0]), Some((5, 0)));
    assert_eq!(parse_hl_answer(&[0x8C, 6, 3, 1, 8]), Some((6, 8)));
    assert_eq!(parse_hl_answer(&[0x8C, 5, 0, 1]), None);
    assert_eq!(parse_hl_answer(&[0x4C, 5, 0, 1, 0]), None);
    // Memory port 4: the TOC on channel 0 (0x4C): count (1), info (2, id).
    assert_eq!(crtp_mem_count_request(), vec![0x4C, 1]);
    assert_eq!(crtp_mem_info_request(3), vec![0x4C, 2, 3]);
    // A write on channel 2 (0x4E): id, address uint32 LE, data; a read on channel 1 (0x4D): id,
    // address, length.
    assert_eq!(
        crtp_mem_write_packet(2, 0x0100, &[0xAA, 0xBB]),
        vec![0x4E, 2, 0x00, 0x01, 0, 0, 0xAA, 0xBB]
    );
    assert_eq!(
        crtp_mem_read_request(1, 24, 24),
        vec![0x4D, 1, 24, 0, 0, 0, 24]
    );
    // 132 bytes (one poly4d) in 24-byte writes: 6 of them, the last 12 bytes.
    let data: Vec<u8> = (0..132u8).collect();
    let writes = crtp_mem_write_packets(1, 0, &data);
    assert_eq!(
        writes.iter().map(|w| w.0).collect::<Vec<_>>(),
        vec![0, 24, 48, 72, 96, 120]
    );
    assert_eq!(writes[1].1[..8], [0x4E, 1, 24, 0, 0, 0, 24, 25]);
    assert_eq!(writes[5].1.len(), 1 + 1 + 4 + 12);
    assert_eq!(*writes[5].1.last().unwrap(), 131);
    // The firmware's answers.
    assert_eq!(
        parse_crtp_mem_answer(&[0x4C, 1, 7]),
        Some(CrtpMemAnswer::Count(7))
    );
    let mut info = vec![0x4C, 2, 5, 0x12, 0x00, 0x10, 0, 0];
    info.extend_from_slice(&[0; 8]);
    assert_eq!(
        parse_crtp_mem_answer(&info),
        Some(CrtpMemAnswer::Info {
            id: 5,
            kind_size: Some((0x12, 4096))
        })
    );
    assert_eq!(
        parse_crtp_mem_answer(&[0x4C, 2, 9]),
        Some(CrtpMemAnswer::Info {
            id: 9,
            kind_size: None
        }),
        "an id past the end: the id alone"
    );
    assert_eq!(
        parse_crtp_mem_answer(&[0x4E, 2, 24, 0, 0, 0, 0]),
        Some(CrtpMemAnswer::Written {
            id: 2,
            addr: 24,
            status: 0
        })
    );
    assert_eq!(
        parse_crtp_mem_answer(&[0x4E, 2, 0, 0x10, 0, 0, 5]),
        Some(CrtpMemAnswer::Written {
            id: 2,
            addr: 4096,
            status: 5
        })
    );
    assert_eq!(
        parse_crtp_mem_answer(&[0x4D, 1, 24, 0, 0, 0, 0, 7, 8]),
        Some(CrtpMemAnswer::Read {
            id: 1,
            addr: 24,
            status: 0,
            data: vec![7, 8]
        })
    );
    assert_eq!(parse_crtp_mem_answer(&[0x2C, 1, 7]), None);
    // A poly4d in memory: x's 8 coefficients, y's, z's, yaw's, the duration; f32 LE.
    let mut coef = [[0f32; 8]; 4];
    coef[0][0] = 1.0;
    coef[1][1] = -2.0;
    coef[2][7] = 0.5;
    coef[3][0] = 0.25;
    let b = Poly4d {
        coef,
        duration_s: 1.5,
    }
    .to_bytes();
    assert_eq!(b.len(), POLY4D_BYTES);
    assert_eq!(b[0..4], [0x00, 0x00, 0x80, 0x3F]); // x c0 = 1.0
    assert_eq!(b[36..40], [0x00, 0x00, 0x00, 0xC0]); // y c1 = -2.0
    assert_eq!(b[92..96], [0x00, 0x00, 0x00, 0x3F]); // z c7 = 0.5
    assert_eq!(b[96..100], [0x00, 0x00, 0x80, 0x3E]); // yaw c0 = 0.25
    assert_eq!(b[128..132], [0x00, 0x00, 0xC0, 0x3F]); // duration 1.5
    assert_eq!(b.iter().filter(|x| **x != 0).count(), 8); // 2 + 1 + 1 + 2 + 2
}

#[test]
fn poly4d_pieces_evaluate_as_the_firmware_flies_them() {
    let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
    // A: x = 1 + 2t + 3t², y = t^7, z = 0, yaw = 0.25 + 0.5t, 1 s; B: x = 10 - t, 2 s.
    let mut a = [[0f32; 8]; 4];
    a[0][..3].copy_from_slice(&[1.0, 2.0, 3.0]);
    a[1][7] = 1.0;
    a[3][..2].copy_from_slice(&[0.25, 0.5]);
    let mut b = [[0f32; 8]; 4];
    b[0][..2].copy_from_slice(&[10.0, -1.0]);
    let pieces = [
        Poly4d {
            coef: a,
            duration_s: 1.0,
        },
        Poly4d {
            coef: b,
            duration_s: 2.0,
        },
    ];
    let e = poly4d_trajectory_eval(&pieces, 0.5).unwrap();
    // x: 1 + 1 + 0.75, 2 + 3, 6; y: 1/128, 7/64, 42/32; yaw 0.5, rate 0.5
    assert!(close(e.p_m.x, 2.75) && close(e.v_m_s.x, 5.0) && close(e.a_m_s2.x, 6.0));
    assert!(close(e.p_m.y, 0.0078125) && close(e.v_m_s.y, 0.109375));
    assert!(close(e.a_m_s2.y, 1.3125) && close(e.p_m.z, 0.0));
    assert!(close(e.yaw_rad, 0.5) && close(e.yaw_rate_rad_s, 0.5));
    // A boundary belongs to the earlier piece: A's end, x = 6, v = 8.
    let e = poly4d_trajectory_eval(&pieces, 1.0).unwrap();
    assert!(close(e.p_m.x, 6.0) && close(e.v_m_s.x, 8.0));
    // 1 s into B: x = 9, v = -1, y back to 0.
    let e = poly4d_trajectory_eval(&pieces, 2.0).unwrap();
    assert!(close(e.p_m.x, 9.0) && close(e.v_m_s.x, -1.0) && close(e.p_m.y, 0.0));
    // After the end: B's end point at rest; before the start: A's start.
    let e = poly4d_trajectory_eval(&pieces, 5.0).unwrap();
    assert!(close(e.p_m.x, 8.0) && close(e.v_m_s.x, 0.0));
    assert!(close(
        poly4d_trajectory_eval(&pieces, -1.0).unwrap().p_m.x,
        1.0
    ));
    assert_eq!(poly4d_trajectory_eval(&[], 0.0), None);
    // The writes put the pieces' bytes where define_trajectory says (offset 0, in order).
    let image: Vec<u8> = pieces.iter().flat_map(Poly4d::to_bytes).collect();
    let mut mem = vec![0u8; 4096];
    for (addr, pk) in crtp_mem_write_packets(4, 0, &image) {
        assert_eq!(&pk[..2], &[0x4E, 4]);
        assert_eq!(u32::from_le_bytes([pk[2], pk[3], pk[4], pk[5]]), addr);
        mem[addr as usize..addr as usize + pk.len() - 6].copy_from_slice(&pk[6..]);
    }
    assert_eq!(&mem[..2 * POLY4D_BYTES], &image[..]);
    assert_eq!(mem[132..136], 10.0f32.to_le_bytes()); // B's x c0
}

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

/// The firmware's socket after the handshake, as `socketlink.c` does it: the handshake byte sent
/// until it comes back.
fn stub_handshake(plant_addr: SocketAddr) -> UdpSocket {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let mut buf = [0u8; 64];
    loop {
        sock.send_to(&[CRTP_HANDSHAKE], plant_addr).unwrap();
        if let Ok((1, _)) = sock.recv_from(&mut buf) {
            if buf[0] == CRTP_HANDSHAKE {
                break;
            }
        }
    }
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    sock
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
