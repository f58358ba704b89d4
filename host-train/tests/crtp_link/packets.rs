//! The packets against the firmware's and cflib's published byte layouts.

use super::*;

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
    // With all three body rates (mrad/s, roll pitch yaw): decoded back as sent.
    let fs = full_state_setpoint_packet_with_rates(
        &Vector3::zeros(),
        &Vector3::zeros(),
        &Vector3::zeros(),
        0.0,
        &Vector3::new(1.25, -0.5, 0.5),
    );
    assert_eq!(fs.len(), 30);
    assert_eq!(&fs[24..26], &1250i16.to_le_bytes());
    assert_eq!(&fs[26..28], &(-500i16).to_le_bytes());
    assert_eq!(&fs[28..30], &500i16.to_le_bytes());
    // The flatness rates: level (a = 0), yaw 0, the body axes are the world's; a jerk across the
    // thrust axis turns it at j / g (x: pitch up, y: roll the other way); along it, not at all;
    // at yaw 90° the body x axis is the world's y.
    let w = flatness_body_rates(
        &Vector3::zeros(),
        &Vector3::new(1.962, -0.981, 5.0),
        0.0,
        0.3,
    );
    assert!((w - Vector3::new(0.1, 0.2, 0.3)).norm() < 1e-12, "{w}");
    let w = flatness_body_rates(
        &Vector3::zeros(),
        &Vector3::new(0.0, 1.962, 0.0),
        std::f64::consts::FRAC_PI_2,
        0.0,
    );
    assert!((w - Vector3::new(0.0, 0.2, 0.0)).norm() < 1e-12, "{w}");
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
