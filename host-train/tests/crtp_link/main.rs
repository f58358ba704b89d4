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
    crtp_await_handshake, crtp_header, ext_pose_packet, flatness_body_rates, force_to_pwm,
    full_state_setpoint_packet, full_state_setpoint_packet_with_rates, hl_go_to_packet,
    hl_land_packet, hl_stop_packet, hl_takeoff_packet, imu_packet, motor_packet, param_toc_request,
    param_write_float, parse_ext_pose, parse_imu, parse_motor, parse_param_answer, parse_setpoint,
    parse_tick_done, position_setpoint_packet, pwm_to_force_n, pwm_to_rpm, quat_compress,
    stop_setpoint_packet, tick_done_packet, CrtpLockstep, CrtpSetpoint, ParamAnswer,
    CRTP_HANDSHAKE, CRTP_PORT_PARAM,
};
use host_train::io::{
    crtp_mem_count_request, crtp_mem_info_request, crtp_mem_read_request, crtp_mem_write_packet,
    crtp_mem_write_packets, hl_define_trajectory_packet, hl_start_trajectory_packet,
    parse_crtp_mem_answer, parse_hl_answer, poly4d_trajectory_eval, CrtpMemAnswer, Poly4d,
    POLY4D_BYTES,
};
use host_train::{Plant, PlantState};
use nalgebra::{UnitQuaternion, Vector3};

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

mod lockstep;
mod packets;
mod udp;
