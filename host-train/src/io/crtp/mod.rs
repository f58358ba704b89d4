//! CrazySim's software-in-the-loop link to the Crazyflie firmware, byte for byte: one UDP socket,
//! one CRTP packet per datagram (header byte first), after a one-byte handshake.
//!
//! The layouts are the firmware's (`socketlink.c`, `sensors_sitl.c`, `power_distribution_sitl.c`,
//! `crtp_commander_generic.c`, `param_logic.c`, `quatcompress.h`, `crtp_commander_high_level.c`,
//! `crtp_mem.c`, `pptraj.h`) and cflib's (`send_position_setpoint`, `send_full_state_setpoint`,
//! `send_extpose`, `HighLevelCommander`, `TrajectoryMemory`); this module writes them from those
//! published layouts. The trajectory upload: find the trajectory memory's id in the memory TOC
//! ([`mem_count_request`], [`mem_info_request`]: type [`MEM_TYPE_TRAJ`]), write the [`Poly4d`]
//! pieces' bytes to it ([`mem_write_packets`], each answered with a status), define them
//! ([`hl_define_trajectory_packet`]) and start them ([`hl_start_trajectory_packet`]; the
//! commander answers every command, [`parse_hl_answer`]); [`poly4d_trajectory_eval`] is what the
//! firmware then flies. `tools/firmware-sitl/README.md` describes the protocol; the plant
//! side that speaks it is `host-train/examples/firmware_sitl_plant`, and
//! `host-train/tests/crtp_link.rs` holds it to a stub firmware in CI.
//!
//! Every encoder returns the datagram; every decoder takes one and returns `None` for a datagram
//! that is not what it reads (wrong port, channel or length), never panicking.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use nalgebra::{UnitQuaternion, Vector3};

mod highlevel;
mod lockstep;
pub use highlevel::*;
pub use lockstep::*;

/// The handshake: the firmware sends this one byte until it gets it back.
pub const HANDSHAKE: u8 = 0xF3;
/// The simulator's port: IMU samples to the firmware, motor PWM from it.
pub const PORT_SIM: u8 = 9;
/// The localization port (external pose on channel 1).
pub const PORT_LOCALIZATION: u8 = 6;
/// The generic commander's port (setpoints on channel 0).
pub const PORT_COMMANDER_GENERIC: u8 = 7;
/// The parameter port (TOC on channel 0, writes on channel 2).
pub const PORT_PARAM: u8 = 2;
const PARAM_TOC_CH: u8 = 0;
const PARAM_WRITE_CH: u8 = 2;
/// TOC command: get the item with this id (CMD_GET_ITEM_V2).
const PARAM_CMD_GET_ITEM_V2: u8 = 2;
/// The localization port's packet type for a full external pose (position + quaternion).
const EXT_POSE: u8 = 8;
/// The generic commander's setpoint types.
const SETPOINT_STOP: u8 = 0;
const SETPOINT_FULL_STATE: u8 = 6;
const SETPOINT_POSITION: u8 = 7;
/// The firmware's SITL power distribution: per-rotor force F (N) = A p² + B p, p = PWM / 65535
/// (`quadSysId.pwmToThrustA/B`).
pub const PWM_TO_THRUST_A: f64 = 0.091492681;
/// See [`PWM_TO_THRUST_A`].
pub const PWM_TO_THRUST_B: f64 = 0.067673604;
/// The IMU's scales (`sensors_sitl.c`): ±16 g and ±2000 °/s over the int16 range.
pub const G_PER_LSB: f64 = 2.0 * 16.0 / 65536.0;
/// See [`G_PER_LSB`].
pub const DEG_PER_LSB: f64 = 2.0 * 2000.0 / 65536.0;

/// The CRTP header byte: port in the high nibble, the link bits 3, the channel in the low two.
pub fn header(port: u8, channel: u8) -> u8 {
    ((port & 0x0F) << 4) | (3 << 2) | (channel & 0x03)
}

/// The port and channel of a datagram, if it has a header.
pub fn port_channel(d: &[u8]) -> Option<(u8, u8)> {
    d.first().map(|h| (h >> 4, h & 3))
}

fn push_f32s(p: &mut Vec<u8>, v: &[f64]) {
    for x in v {
        p.extend_from_slice(&(*x as f32).to_le_bytes());
    }
}

/// One IMU sample (port 9, channel 0, type 0): the specific force in g and the body rates in
/// °/s, each quantised to int16 at [`G_PER_LSB`] / [`DEG_PER_LSB`] (saturating).
pub fn imu_packet(acc_g: Vector3<f64>, gyro_dps: Vector3<f64>) -> Vec<u8> {
    let q = |x: f64, lsb: f64| (x / lsb).round().clamp(-32768.0, 32767.0) as i16;
    let mut p = vec![header(PORT_SIM, 0), 0];
    for a in acc_g.iter() {
        p.extend_from_slice(&q(*a, G_PER_LSB).to_le_bytes());
    }
    for w in gyro_dps.iter() {
        p.extend_from_slice(&q(*w, DEG_PER_LSB).to_le_bytes());
    }
    p
}

/// Reads an IMU packet back: (specific force in g, body rates in °/s).
pub fn parse_imu(d: &[u8]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if d.len() != 14 || port_channel(d) != Some((PORT_SIM, 0)) || d.get(1) != Some(&0) {
        return None;
    }
    let v = |i: usize| i16::from_le_bytes([d[2 + 2 * i], d[3 + 2 * i]]) as f64;
    Some((
        Vector3::new(v(0), v(1), v(2)) * G_PER_LSB,
        Vector3::new(v(3), v(4), v(5)) * DEG_PER_LSB,
    ))
}

/// The four motor PWM values the firmware sends (port 9, 4 × uint16), as `power_distribution_sitl.c`
/// writes them.
pub fn motor_packet(pwm: [u16; 4]) -> Vec<u8> {
    let mut p = vec![header(PORT_SIM, 0)];
    for m in pwm {
        p.extend_from_slice(&m.to_le_bytes());
    }
    p
}

/// Reads a motor packet.
pub fn parse_motor(d: &[u8]) -> Option<[u16; 4]> {
    if d.len() != 9 || port_channel(d).map(|x| x.0) != Some(PORT_SIM) {
        return None;
    }
    Some(core::array::from_fn(|i| {
        u16::from_le_bytes([d[1 + 2 * i], d[2 + 2 * i]])
    }))
}

/// An external pose, as a motion-capture system sends it through cflib's `send_extpose`
/// (localization port 6, channel 1, type 8): position (m) and the body→world quaternion
/// x, y, z, w, as f32.
pub fn ext_pose_packet(p_m: &Vector3<f64>, q: &UnitQuaternion<f64>) -> Vec<u8> {
    let mut pk = vec![header(PORT_LOCALIZATION, 1), EXT_POSE];
    push_f32s(&mut pk, &[p_m.x, p_m.y, p_m.z, q.i, q.j, q.k, q.w]);
    pk
}

/// Reads an external pose back: position (m) and the quaternion x, y, z, w.
pub fn parse_ext_pose(d: &[u8]) -> Option<(Vector3<f64>, [f64; 4])> {
    if d.len() != 30 || port_channel(d) != Some((PORT_LOCALIZATION, 1)) || d[1] != EXT_POSE {
        return None;
    }
    let f = |i: usize| {
        let b = &d[2 + 4 * i..6 + 4 * i];
        f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64
    };
    Some((Vector3::new(f(0), f(1), f(2)), [f(3), f(4), f(5), f(6)]))
}

/// A position setpoint (cflib's `send_position_setpoint`: generic commander type 7): position
/// (m, world) and yaw (°); no feed-forward.
pub fn position_setpoint_packet(p_m: &Vector3<f64>, yaw_deg: f64) -> Vec<u8> {
    let mut pk = vec![header(PORT_COMMANDER_GENERIC, 0), SETPOINT_POSITION];
    push_f32s(&mut pk, &[p_m.x, p_m.y, p_m.z, yaw_deg]);
    pk
}

/// A full-state setpoint (cflib's `send_full_state_setpoint`: generic commander type 6): position
/// in mm, velocity in mm/s and acceleration in mm/s² as int16 (saturating), the attitude as
/// [`quat_compress`]ed quaternion (here the yaw ψ alone), and body rates in mrad/s (here the yaw
/// rate alone). The firmware hands position, velocity and acceleration to the controller as
/// modeAbs with feed-forward.
pub fn full_state_setpoint_packet(
    p_m: &Vector3<f64>,
    v_m_s: &Vector3<f64>,
    a_m_s2: &Vector3<f64>,
    yaw_rad: f64,
    yaw_rate_rad_s: f64,
) -> Vec<u8> {
    let rates = Vector3::new(0.0, 0.0, yaw_rate_rad_s);
    full_state_setpoint_packet_with_rates(p_m, v_m_s, a_m_s2, yaw_rad, &rates)
}

/// [`full_state_setpoint_packet`] with all three body rates (rad/s, body: roll, pitch, yaw), as
/// Crazyswarm's `cmdFullState` sends a trajectory's ([`flatness_body_rates`]).
pub fn full_state_setpoint_packet_with_rates(
    p_m: &Vector3<f64>,
    v_m_s: &Vector3<f64>,
    a_m_s2: &Vector3<f64>,
    yaw_rad: f64,
    rates_rad_s: &Vector3<f64>,
) -> Vec<u8> {
    let milli = |x: f64| (x * 1000.0).round().clamp(-32768.0, 32767.0) as i16;
    let mut pk = vec![header(PORT_COMMANDER_GENERIC, 0), SETPOINT_FULL_STATE];
    for v in [p_m, v_m_s, a_m_s2] {
        for x in v.iter() {
            pk.extend_from_slice(&milli(*x).to_le_bytes());
        }
    }
    let (s, c) = (0.5 * yaw_rad).sin_cos();
    pk.extend_from_slice(&quat_compress([0.0, 0.0, s, c]).to_le_bytes());
    for r in rates_rad_s.iter() {
        pk.extend_from_slice(&milli(*r).to_le_bytes());
    }
    pk
}

/// The body rates (rad/s, body) of a trajectory with acceleration `a_m_s2`, jerk `j_m_s3`, yaw
/// and yaw rate, as the firmware's high-level commander (`pptraj.c`'s `poly4d_eval`) and
/// Crazyswarm's `uav_trajectory` compute them: z_b along t = a + g e3 (g = 9.81, pptraj's GRAV),
/// y_b = z_b × (cos ψ, sin ψ, 0) normalised, x_b = y_b × z_b, h = the jerk's part across z_b over
/// |t|; ω = (−h·y_b, h·x_b, z_b,z ψ̇).
pub fn flatness_body_rates(
    a_m_s2: &Vector3<f64>,
    j_m_s3: &Vector3<f64>,
    yaw_rad: f64,
    yaw_rate_rad_s: f64,
) -> Vector3<f64> {
    let thrust = a_m_s2 + Vector3::z() * 9.81;
    let z_b = thrust.normalize();
    let x_c = Vector3::new(yaw_rad.cos(), yaw_rad.sin(), 0.0);
    let y_b = z_b.cross(&x_c).normalize();
    let x_b = y_b.cross(&z_b);
    let h = (j_m_s3 - z_b * j_m_s3.dot(&z_b)) / thrust.norm();
    Vector3::new(-h.dot(&y_b), h.dot(&x_b), z_b.z * yaw_rate_rad_s)
}

/// The stop setpoint (generic commander type 0): the motors stop.
pub fn stop_setpoint_packet() -> Vec<u8> {
    vec![header(PORT_COMMANDER_GENERIC, 0), SETPOINT_STOP]
}

/// A setpoint as the firmware's generic commander decodes it (positions in m, yaw in rad).
#[derive(Clone, Debug, PartialEq)]
pub enum Setpoint {
    /// Type 0.
    Stop,
    /// Type 7: position and yaw, no feed-forward.
    Position {
        /// Position (m, world).
        p_m: Vector3<f64>,
        /// Yaw (rad).
        yaw_rad: f64,
    },
    /// Type 6, at its int16 millimetre resolution.
    FullState {
        /// Position (m, world).
        p_m: Vector3<f64>,
        /// Velocity (m/s, world).
        v_m_s: Vector3<f64>,
        /// Acceleration (m/s², world).
        a_m_s2: Vector3<f64>,
        /// The attitude quaternion, x, y, z, w (9-bit components).
        q_xyzw: [f64; 4],
        /// Body rates (rad/s).
        rates_rad_s: Vector3<f64>,
    },
}

/// Decodes a generic-commander setpoint (types 0, 6 and 7) as the firmware does.
pub fn parse_setpoint(d: &[u8]) -> Option<Setpoint> {
    if port_channel(d) != Some((PORT_COMMANDER_GENERIC, 0)) {
        return None;
    }
    let body = d.get(2..)?;
    let f = |i: usize| {
        f32::from_le_bytes([
            body[4 * i],
            body[4 * i + 1],
            body[4 * i + 2],
            body[4 * i + 3],
        ]) as f64
    };
    let s = |i: usize| i16::from_le_bytes([body[2 * i], body[2 * i + 1]]) as f64 / 1000.0;
    match (*d.get(1)?, body.len()) {
        (SETPOINT_STOP, 0) => Some(Setpoint::Stop),
        (SETPOINT_POSITION, 16) => Some(Setpoint::Position {
            p_m: Vector3::new(f(0), f(1), f(2)),
            yaw_rad: f(3).to_radians(),
        }),
        (SETPOINT_FULL_STATE, 28) => {
            let comp = u32::from_le_bytes([body[18], body[19], body[20], body[21]]);
            let r =
                |i: usize| i16::from_le_bytes([body[22 + 2 * i], body[23 + 2 * i]]) as f64 / 1000.0;
            Some(Setpoint::FullState {
                p_m: Vector3::new(s(0), s(1), s(2)),
                v_m_s: Vector3::new(s(3), s(4), s(5)),
                a_m_s2: Vector3::new(s(6), s(7), s(8)),
                q_xyzw: quat_decompress(comp),
                rates_rad_s: Vector3::new(r(0), r(1), r(2)),
            })
        }
        _ => None,
    }
}

/// The firmware's "smallest three" quaternion compression (`quatcompress.h`): the index of the
/// largest-magnitude component (x, y, z, w order) in the top two bits, then for each other
/// component in order a sign bit and a 9-bit magnitude over 1/√2, with the quaternion negated so
/// that the largest is positive. `q` must be of unit length.
pub fn quat_compress(q: [f64; 4]) -> u32 {
    let mut largest = 0;
    for i in 1..4 {
        if q[i].abs() > q[largest].abs() {
            largest = i;
        }
    }
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (i, x) in q.iter().enumerate() {
        if i != largest {
            let neg = ((*x < 0.0) != negate) as u32;
            let mag = (511.0 * (x.abs() / core::f64::consts::FRAC_1_SQRT_2) + 0.5) as u32;
            comp = (comp << 10) | (neg << 9) | mag.min(511);
        }
    }
    comp
}

/// The inverse of [`quat_compress`] (to its 9-bit resolution): x, y, z, w.
pub fn quat_decompress(comp: u32) -> [f64; 4] {
    let largest = (comp >> 30) as usize;
    let mut q = [0.0; 4];
    let mut rest = comp;
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i != largest {
            let mag = (rest & 511) as f64;
            let neg = (rest >> 9) & 1 == 1;
            rest >>= 10;
            let v = core::f64::consts::FRAC_1_SQRT_2 * mag / 511.0;
            q[i] = if neg { -v } else { v };
            sum += v * v;
        }
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    q
}

/// A 1-byte parameter write by id (a uint8 or int8 parameter, e.g. `kalman.resetEstimation`).
pub fn param_write_u8(id: u16, value: u8) -> Vec<u8> {
    let mut pk = vec![header(PORT_PARAM, PARAM_WRITE_CH)];
    pk.extend_from_slice(&id.to_le_bytes());
    pk.push(value);
    pk
}

/// A parameter TOC request: the item with id `id` (port 2, channel 0, CMD_GET_ITEM_V2).
pub fn param_toc_request(id: u16) -> Vec<u8> {
    let mut pk = vec![header(PORT_PARAM, PARAM_TOC_CH), PARAM_CMD_GET_ITEM_V2];
    pk.extend_from_slice(&id.to_le_bytes());
    pk
}

/// A float parameter write by id (port 2, channel 2). (Set-by-name does not fit
/// `quadSysId.thrustToTorque`: 31 data bytes, one more than a CRTP packet carries; the firmware
/// then reads the float's last byte from past the packet.)
pub fn param_write_float(id: u16, value: f32) -> Vec<u8> {
    let mut pk = vec![header(PORT_PARAM, PARAM_WRITE_CH)];
    pk.extend_from_slice(&id.to_le_bytes());
    pk.extend_from_slice(&value.to_le_bytes());
    pk
}

/// What the firmware answers on the parameter port.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamAnswer {
    /// A TOC item.
    TocItem {
        /// The parameter's id.
        id: u16,
        /// Its type byte.
        kind: u8,
        /// "group.name".
        name: String,
    },
    /// The TOC request was past its end.
    TocEnd,
    /// A write, echoed once done (the firmware echoes the packet it applied). A 1-byte value
    /// echo has the length of the firmware's "no such id" answer (id, errno), so a caller that
    /// writes a u8 checks the id against the TOC first.
    Written {
        /// The parameter's id.
        id: u16,
        /// The value's bytes, little-endian, zero-padded to 4.
        value: [u8; 4],
    },
}

/// Decodes a parameter answer: a TOC item (CMD_GET_ITEM_V2, id, type, `group\0name\0`), the TOC's
/// end (the command byte alone), or a write echo (id, 4 value bytes).
pub fn parse_param_answer(d: &[u8]) -> Option<ParamAnswer> {
    let (port, ch) = port_channel(d)?;
    if port != PORT_PARAM {
        return None;
    }
    match ch {
        PARAM_TOC_CH if d.get(1) == Some(&PARAM_CMD_GET_ITEM_V2) => {
            if d.len() == 2 {
                return Some(ParamAnswer::TocEnd);
            }
            let id = u16::from_le_bytes([*d.get(2)?, *d.get(3)?]);
            let kind = *d.get(4)?;
            let mut parts = d.get(5..)?.split(|&b| b == 0);
            let group = String::from_utf8_lossy(parts.next().unwrap_or(&[])).into_owned();
            let name = String::from_utf8_lossy(parts.next().unwrap_or(&[])).into_owned();
            Some(ParamAnswer::TocItem {
                id,
                kind,
                name: format!("{group}.{name}"),
            })
        }
        PARAM_WRITE_CH if (4..=7).contains(&d.len()) => {
            let mut value = [0; 4];
            value[..d.len() - 3].copy_from_slice(&d[3..]);
            Some(ParamAnswer::Written {
                id: u16::from_le_bytes([d[1], d[2]]),
                value,
            })
        }
        _ => None,
    }
}

/// The rotor force (N) the firmware means by a PWM value: F = A p² + B p, p = PWM / 65535.
pub fn pwm_to_force_n(pwm: u16) -> f64 {
    let p = pwm as f64 / 65535.0;
    PWM_TO_THRUST_A * p * p + PWM_TO_THRUST_B * p
}

/// The PWM value the firmware's power distribution gives a rotor force (N): the positive root of
/// F = A p² + B p, clamped to [0, 65535].
pub fn force_to_pwm(force_n: f64) -> u16 {
    let (a, b) = (PWM_TO_THRUST_A, PWM_TO_THRUST_B);
    let p = (-b + (b * b + 4.0 * a * force_n.max(0.0)).sqrt()) / (2.0 * a);
    (p * 65535.0).round().clamp(0.0, 65535.0) as u16
}

/// The rotor speed (rpm) a plant with thrust coefficient `kf` (N/rpm²) runs at to make the force
/// the firmware meant by `pwm`.
pub fn pwm_to_rpm(pwm: u16, kf_n_per_rpm2: f64) -> f64 {
    (pwm_to_force_n(pwm).max(0.0) / kf_n_per_rpm2).sqrt()
}

/// Lock-step's channel on the simulator's port: the firmware built with
/// `tools/firmware-sitl/patches/cf-lockstep.patch` and run with `CF2_LOCKSTEP=1` advances its
/// FreeRTOS tick once per IMU packet, and when it has nothing left to do it sends this: port 9,
/// channel 1, the tick count (uint32, little-endian).
pub const CH_SIM_TICK_DONE: u8 = 1;

/// The firmware's lock-step answer: tick `tick` is done (see [`CH_SIM_TICK_DONE`]).
pub fn tick_done_packet(tick: u32) -> Vec<u8> {
    let mut p = vec![header(PORT_SIM, CH_SIM_TICK_DONE)];
    p.extend_from_slice(&tick.to_le_bytes());
    p
}

/// Reads a tick-done packet: the tick.
pub fn parse_tick_done(d: &[u8]) -> Option<u32> {
    if d.len() != 5 || port_channel(d) != Some((PORT_SIM, CH_SIM_TICK_DONE)) {
        return None;
    }
    Some(u32::from_le_bytes([d[1], d[2], d[3], d[4]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_survive_compression_to_nine_bits() {
        for k in 0..64 {
            let yaw = -3.1 + 0.1 * k as f64;
            let q = UnitQuaternion::from_euler_angles(0.3 * (k as f64).sin(), -0.2, yaw);
            let x = [q.i, q.j, q.k, q.w];
            let back = quat_decompress(quat_compress(x));
            let dot: f64 = x.iter().zip(&back).map(|(a, b)| a * b).sum();
            // the same rotation up to sign, to the 9-bit resolution (1/√2 / 511 per component)
            assert!(dot.abs() > 1.0 - 2e-5, "k {k}: {x:?} -> {back:?}");
        }
    }

    #[test]
    fn pwm_and_force_invert_each_other() {
        for pwm in [0u16, 1, 1000, 36_533, 65_535] {
            assert_eq!(force_to_pwm(pwm_to_force_n(pwm)), pwm);
        }
        assert_eq!(force_to_pwm(-1.0), 0);
        assert_eq!(force_to_pwm(10.0), 65_535);
    }

    #[test]
    fn decoders_refuse_what_they_do_not_read() {
        assert_eq!(parse_motor(&[header(PORT_SIM, 0), 1, 2]), None);
        assert_eq!(parse_imu(&motor_packet([1, 2, 3, 4])), None);
        assert_eq!(parse_setpoint(&[]), None);
        assert_eq!(
            parse_setpoint(&[header(PORT_COMMANDER_GENERIC, 0), 6, 0]),
            None
        );
        assert_eq!(parse_param_answer(&[header(PORT_PARAM, 0), 2, 1]), None);
        assert_eq!(parse_tick_done(&motor_packet([1, 2, 3, 4])), None);
        assert_eq!(parse_motor(&tick_done_packet(7)), None);
        assert_eq!(parse_tick_done(&tick_done_packet(70_000)), Some(70_000));
    }
}
