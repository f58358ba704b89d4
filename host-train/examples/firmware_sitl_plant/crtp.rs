//! The firmware's side of the link: CrazySim's CRTP packets (IMU, pose, setpoints, parameters),
//! what the firmware sends back, its console and process, and its PWM → rotor map.

use std::net::SocketAddr;
use std::process::Child;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use host_train::PlantState;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};

/// The firmware's SITL power distribution: per-rotor force F (N) = A p² + B p, p = PWM / 65535.
const PWM_TO_THRUST_A: f64 = 0.091492681;
const PWM_TO_THRUST_B: f64 = 0.067673604;
/// CrazySim's sensor scales (sensors_sitl.c): g and °/s per LSB.
const G_PER_LSB: f64 = 2.0 * 16.0 / 65536.0;
const DEG_PER_LSB: f64 = 2.0 * 2000.0 / 65536.0;
pub const CRTP_PORT_SIM: u8 = 9;
const CRTP_PORT_LOCALIZATION: u8 = 6;
const CRTP_PORT_COMMANDER_GENERIC: u8 = 7;
const CRTP_PORT_PARAM: u8 = 2;
/// The parameter port's channels: the table of contents, and writes by id.
const PARAM_TOC_CH: u8 = 0;
const PARAM_WRITE_CH: u8 = 2;
/// TOC command: get the item with this id (CMD_GET_ITEM_V2).
const PARAM_CMD_GET_ITEM_V2: u8 = 2;

/// What the firmware sends us, shared between the receiving thread and the loop.
#[derive(Default)]
pub struct FromFirmware {
    pub fw_addr: Option<SocketAddr>,
    pub pwm: [u16; 4],
    pub motor_packets: u64,
    /// Parameter TOC items received: (id, "group.name").
    pub param_toc: Vec<(u16, String)>,
    /// The TOC's end was seen (an answer without an item).
    pub param_toc_end: bool,
    /// Parameter writes the firmware echoed (it echoes a write once done): (id, value bytes).
    pub param_written: Vec<(u16, [u8; 4])>,
}

/// The firmware's console, line by line, into a file and a flag for the stabilizer loop.
pub struct Console {
    pub lines: Mutex<Vec<String>>,
    pub cond: Condvar,
}

impl Console {
    pub fn wait_for(&self, needle: &str, timeout: Duration) -> Option<String> {
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

    pub fn grep(&self, needle: &str) -> Vec<String> {
        let lines = self.lines.lock().unwrap();
        lines
            .iter()
            .filter(|l| l.contains(needle))
            .cloned()
            .collect()
    }
}

/// Kills the firmware when dropped (it is ours: we started it).
pub struct Firmware(pub Child);

impl Drop for Firmware {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn crtp_header(port: u8, channel: u8) -> u8 {
    ((port & 0x0F) << 4) | (3 << 2) | (channel & 0x03)
}

pub fn imu_packet(acc_g: Vector3<f64>, gyro_dps: Vector3<f64>) -> Vec<u8> {
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

pub fn ext_pose_packet(s: &PlantState) -> Vec<u8> {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(s.rot));
    let mut p = vec![crtp_header(CRTP_PORT_LOCALIZATION, 1), 8];
    for v in [s.p_m.x, s.p_m.y, s.p_m.z, q.i, q.j, q.k, q.w] {
        p.extend_from_slice(&(v as f32).to_le_bytes());
    }
    p
}

pub fn position_setpoint_packet(p: &Vector3<f64>, yaw_deg: f64) -> Vec<u8> {
    let mut pk = vec![crtp_header(CRTP_PORT_COMMANDER_GENERIC, 0), 7];
    for v in [p.x, p.y, p.z, yaw_deg] {
        pk.extend_from_slice(&(v as f32).to_le_bytes());
    }
    pk
}

/// A parameter TOC request: the item with id `id` (port 2, channel 0, CMD_GET_ITEM_V2).
pub fn param_toc_request(id: u16) -> Vec<u8> {
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
pub fn param_write_float(id: u16, value: f32) -> Vec<u8> {
    let mut pk = vec![crtp_header(CRTP_PORT_PARAM, PARAM_WRITE_CH)];
    pk.extend_from_slice(&id.to_le_bytes());
    pk.extend_from_slice(&value.to_le_bytes());
    pk
}

/// Parameter answers into `sh`: TOC items (id, type, group\0 name\0; a 1-byte answer past the
/// end) and write echoes (id, value).
pub fn param_answer(d: &[u8], sh: &mut FromFirmware) {
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

pub fn stop_setpoint_packet() -> Vec<u8> {
    vec![crtp_header(CRTP_PORT_COMMANDER_GENERIC, 0), 0]
}

/// Rotor speed (rpm) the plant runs at for a PWM value: the force the firmware meant, F = A p² +
/// B p, through the vehicle's kf.
pub fn pwm_to_rpm(pwm: u16, kf: f64) -> f64 {
    let p = pwm as f64 / 65535.0;
    let f = PWM_TO_THRUST_A * p * p + PWM_TO_THRUST_B * p;
    (f.max(0.0) / kf).sqrt()
}
