//! The high-level commander's packets (take-off, go-to, land, stop, trajectories), the
//! [`Poly4d`] trajectory pieces the firmware flies, and the memory port that uploads them.

use super::*;

/// The high-level commander's port (commands on channel 0).
pub const PORT_SETPOINT_HL: u8 = 8;
const HL_STOP: u8 = 3;
const HL_GO_TO: u8 = 4;
const HL_TAKEOFF_2: u8 = 7;
const HL_LAND_2: u8 = 8;

fn hl_vertical(command: u8, height_m: f64, yaw_rad: f64, duration_s: f64) -> Vec<u8> {
    // group mask 0 (every vehicle), height, yaw, useCurrentYaw = false, duration
    let mut pk = vec![header(PORT_SETPOINT_HL, 0), command, 0];
    push_f32s(&mut pk, &[height_m, yaw_rad]);
    pk.push(0);
    push_f32s(&mut pk, &[duration_s]);
    pk
}

/// The high-level commander's take-off (cflib's `HighLevelCommander.takeoff`, COMMAND_TAKEOFF_2):
/// from the current x, y to `height_m` (absolute) with yaw `yaw_rad`, in `duration_s`.
pub fn hl_takeoff_packet(height_m: f64, yaw_rad: f64, duration_s: f64) -> Vec<u8> {
    hl_vertical(HL_TAKEOFF_2, height_m, yaw_rad, duration_s)
}

/// The high-level commander's landing (COMMAND_LAND_2): down to `height_m` in `duration_s`.
pub fn hl_land_packet(height_m: f64, yaw_rad: f64, duration_s: f64) -> Vec<u8> {
    hl_vertical(HL_LAND_2, height_m, yaw_rad, duration_s)
}

/// The high-level commander's go-to (COMMAND_GO_TO, absolute): to `p_m` and `yaw_rad` in
/// `duration_s`, on its smooth polynomial, then hover there.
pub fn hl_go_to_packet(p_m: &Vector3<f64>, yaw_rad: f64, duration_s: f64) -> Vec<u8> {
    let mut pk = vec![header(PORT_SETPOINT_HL, 0), HL_GO_TO, 0, 0];
    push_f32s(&mut pk, &[p_m.x, p_m.y, p_m.z, yaw_rad, duration_s]);
    pk
}

/// The high-level commander's stop (COMMAND_STOP): its setpoints end, the motors stop.
pub fn hl_stop_packet() -> Vec<u8> {
    vec![header(PORT_SETPOINT_HL, 0), HL_STOP, 0]
}

const HL_START_TRAJECTORY: u8 = 5;
const HL_DEFINE_TRAJECTORY: u8 = 6;
/// `define_trajectory`'s location: the trajectory memory (TRAJECTORY_LOCATION_MEM).
const TRAJECTORY_LOCATION_MEM: u8 = 1;
/// `define_trajectory`'s type: uncompressed poly4d pieces (CRTP_CHL_TRAJECTORY_TYPE_POLY4D).
const TRAJECTORY_TYPE_POLY4D: u8 = 0;
/// The trajectory ids the firmware keeps (NUM_TRAJECTORY_DEFINITIONS).
pub const HL_TRAJECTORY_IDS: u8 = 10;

/// The high-level commander's `define_trajectory` (COMMAND_DEFINE_TRAJECTORY, 6): trajectory
/// `trajectory_id` (< [`HL_TRAJECTORY_IDS`]) is `n_pieces` uncompressed poly4d pieces at byte
/// `offset` of the trajectory memory. Packed: id, location (1: memory), type (0: poly4d),
/// offset (uint32), n_pieces (uint8). No group mask: every vehicle takes it.
pub fn hl_define_trajectory_packet(trajectory_id: u8, offset: u32, n_pieces: u8) -> Vec<u8> {
    let mut pk = vec![
        header(PORT_SETPOINT_HL, 0),
        HL_DEFINE_TRAJECTORY,
        trajectory_id,
        TRAJECTORY_LOCATION_MEM,
        TRAJECTORY_TYPE_POLY4D,
    ];
    pk.extend_from_slice(&offset.to_le_bytes());
    pk.push(n_pieces);
    pk
}

/// The high-level commander's `start_trajectory` (COMMAND_START_TRAJECTORY, 5), group mask 0
/// (every vehicle): fly trajectory `trajectory_id` from now. `relative`: shifted so that it
/// starts at the commander's current setpoint (position only; yaw stays as uploaded);
/// `reversed`: backwards; `time_scale`: 1 the uploaded speed, 2 twice as long. Packed: group
/// mask, relative, reversed, id (uint8 each), time scale (f32).
pub fn hl_start_trajectory_packet(
    trajectory_id: u8,
    time_scale: f32,
    relative: bool,
    reversed: bool,
) -> Vec<u8> {
    let mut pk = vec![
        header(PORT_SETPOINT_HL, 0),
        HL_START_TRAJECTORY,
        0,
        relative as u8,
        reversed as u8,
        trajectory_id,
    ];
    pk.extend_from_slice(&time_scale.to_le_bytes());
    pk
}

/// The high-level commander's answer to every command (`crtpCommanderHighLevelTask`): the
/// command's packet cut to 4 data bytes, the last one replaced by the result (0: done, else an
/// errno: 16 EBUSY, 8 ENOEXEC). Returns (command, result).
pub fn parse_hl_answer(d: &[u8]) -> Option<(u8, u8)> {
    if d.len() != 5 || port_channel(d) != Some((PORT_SETPOINT_HL, 0)) {
        return None;
    }
    Some((d[1], d[4]))
}

/// One piece of a trajectory as the firmware stores it (`struct poly4d`, `pptraj.h`): four
/// polynomials of degree 7 (x, y, z in m, yaw in rad; coefficients in ascending order, the
/// constant first) in the piece's own time 0..`duration_s`.
#[derive(Clone, Debug, PartialEq)]
pub struct Poly4d {
    /// x, y, z, yaw: 8 coefficients each, ascending.
    pub coef: [[f32; 8]; 4],
    /// The piece's duration (s).
    pub duration_s: f32,
}

/// A poly4d's size in the trajectory memory: 4 × 8 coefficients and the duration, f32 each.
pub const POLY4D_BYTES: usize = 132;
/// The firmware's trajectory memory (TRAJECTORY_MEMORY_SIZE): 31 poly4d pieces.
pub const TRAJECTORY_MEMORY_BYTES: usize = 4096;

/// A trajectory's value at one time: position, velocity, acceleration (world), yaw and yaw rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolyEval {
    /// Position (m).
    pub p_m: Vector3<f64>,
    /// Velocity (m/s).
    pub v_m_s: Vector3<f64>,
    /// Acceleration (m/s²).
    pub a_m_s2: Vector3<f64>,
    /// Yaw (rad).
    pub yaw_rad: f64,
    /// Yaw rate (rad/s).
    pub yaw_rate_rad_s: f64,
}

/// A polynomial (ascending coefficients) and its first two derivatives at `t`, in f64.
fn poly_eval3(c: &[f32; 8], t: f64) -> (f64, f64, f64) {
    let (mut p, mut v, mut a) = (0.0, 0.0, 0.0);
    for (i, ci) in c.iter().enumerate().rev() {
        let ci = *ci as f64;
        let i = i as f64;
        p = p * t + ci;
        if i >= 1.0 {
            v = v * t + i * ci;
        }
        if i >= 2.0 {
            a = a * t + i * (i - 1.0) * ci;
        }
    }
    (p, v, a)
}

impl Poly4d {
    /// The memory image: x's 8 coefficients, y's, z's, yaw's, then the duration, f32
    /// little-endian ([`POLY4D_BYTES`]).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(POLY4D_BYTES);
        for c in self.coef.iter().flatten().chain([&self.duration_s]) {
            b.extend_from_slice(&c.to_le_bytes());
        }
        b
    }

    /// The piece at `t_s` of its own time (not clamped: the caller picks the piece).
    pub fn eval(&self, t_s: f64) -> PolyEval {
        let e: [(f64, f64, f64); 4] = core::array::from_fn(|i| poly_eval3(&self.coef[i], t_s));
        PolyEval {
            p_m: Vector3::new(e[0].0, e[1].0, e[2].0),
            v_m_s: Vector3::new(e[0].1, e[1].1, e[2].1),
            a_m_s2: Vector3::new(e[0].2, e[1].2, e[2].2),
            yaw_rad: e[3].0,
            yaw_rate_rad_s: e[3].1,
        }
    }
}

/// A piecewise trajectory at `t_s` from its start, as the firmware's `piecewise_eval` flies it
/// forward at time scale 1 without a shift: the piece whose span holds `t_s` (a time on a
/// boundary belongs to the earlier piece); before the start the first piece's start; after the
/// end the last piece's end point at rest. `None` for no pieces.
pub fn poly4d_trajectory_eval(pieces: &[Poly4d], t_s: f64) -> Option<PolyEval> {
    let mut t = t_s.max(0.0);
    for piece in pieces {
        let d = piece.duration_s as f64;
        if t <= d {
            return Some(piece.eval(t));
        }
        t -= d;
    }
    let last = pieces.last()?;
    let e = last.eval(last.duration_s as f64);
    Some(PolyEval {
        v_m_s: Vector3::zeros(),
        a_m_s2: Vector3::zeros(),
        yaw_rate_rad_s: 0.0,
        ..e
    })
}

/// The memory port (CRTP port 4): channel 0 the memory TOC (count, info), 1 reads, 2 writes.
pub const PORT_MEM: u8 = 4;
const MEM_SETTINGS_CH: u8 = 0;
const MEM_READ_CH: u8 = 1;
const MEM_WRITE_CH: u8 = 2;
const MEM_CMD_GET_NBR: u8 = 1;
const MEM_CMD_GET_INFO: u8 = 2;
/// The memory type of the high-level commander's trajectory memory (MEM_TYPE_TRAJ).
pub const MEM_TYPE_TRAJ: u8 = 0x12;
/// The data bytes one memory write or read carries (cflib's chunk; the packet has room for 25).
pub const MEM_CHUNK: usize = 24;

/// The memory TOC's count request (port 4, channel 0, MEM_CMD_GET_NBR).
pub fn mem_count_request() -> Vec<u8> {
    vec![header(PORT_MEM, MEM_SETTINGS_CH), MEM_CMD_GET_NBR]
}

/// The memory TOC's info request for memory `id` (MEM_CMD_GET_INFO): its type and size.
pub fn mem_info_request(id: u8) -> Vec<u8> {
    vec![header(PORT_MEM, MEM_SETTINGS_CH), MEM_CMD_GET_INFO, id]
}

/// A memory write (port 4, channel 2): memory `id`, byte address `addr` (uint32), then the data
/// (at most [`MEM_CHUNK`] bytes; longer data panics: split it with [`mem_write_packets`]).
pub fn mem_write_packet(id: u8, addr: u32, data: &[u8]) -> Vec<u8> {
    assert!(
        data.len() <= MEM_CHUNK,
        "a memory write carries at most {MEM_CHUNK} bytes"
    );
    let mut pk = vec![header(PORT_MEM, MEM_WRITE_CH), id];
    pk.extend_from_slice(&addr.to_le_bytes());
    pk.extend_from_slice(data);
    pk
}

/// `data` written to memory `id` from `addr` on: one write per [`MEM_CHUNK`] bytes, with its
/// address, in order.
pub fn mem_write_packets(id: u8, addr: u32, data: &[u8]) -> Vec<(u32, Vec<u8>)> {
    data.chunks(MEM_CHUNK)
        .enumerate()
        .map(|(i, c)| {
            let a = addr + (i * MEM_CHUNK) as u32;
            (a, mem_write_packet(id, a, c))
        })
        .collect()
}

/// A memory read request (port 4, channel 1): memory `id`, address, length (≤ [`MEM_CHUNK`]).
pub fn mem_read_request(id: u8, addr: u32, len: u8) -> Vec<u8> {
    let mut pk = vec![header(PORT_MEM, MEM_READ_CH), id];
    pk.extend_from_slice(&addr.to_le_bytes());
    pk.push(len);
    pk
}

/// What the firmware answers on the memory port (`crtp_mem.c`).
#[derive(Clone, Debug, PartialEq)]
pub enum MemAnswer {
    /// The number of memories (ids 0..n).
    Count(u8),
    /// Memory `id`'s type and size; `None` for an id past the end (the firmware answers with
    /// the id alone).
    Info {
        /// The memory's id.
        id: u8,
        /// Its type and size in bytes.
        kind_size: Option<(u8, u32)>,
    },
    /// A write answered: memory, address, status (0: written; else an errno, 5 EIO: e.g. past
    /// the memory's end).
    Written {
        /// The memory's id.
        id: u8,
        /// The write's address.
        addr: u32,
        /// 0 or an errno.
        status: u8,
    },
    /// A read answered: memory, address, status, and the data (empty unless status 0).
    Read {
        /// The memory's id.
        id: u8,
        /// The read's address.
        addr: u32,
        /// 0 or an errno.
        status: u8,
        /// The bytes read.
        data: Vec<u8>,
    },
}

/// Decodes a memory answer: the count (GET_NBR, n), an info (GET_INFO, id, type, size uint32,
/// 8 bytes of serial number), a write's answer (id, address, status) or a read's (id, address,
/// status, data).
pub fn parse_mem_answer(d: &[u8]) -> Option<MemAnswer> {
    let (port, ch) = port_channel(d)?;
    if port != PORT_MEM {
        return None;
    }
    let addr = |d: &[u8]| u32::from_le_bytes([d[2], d[3], d[4], d[5]]);
    match (ch, d.get(1), d.len()) {
        (MEM_SETTINGS_CH, Some(&MEM_CMD_GET_NBR), 3) => Some(MemAnswer::Count(d[2])),
        (MEM_SETTINGS_CH, Some(&MEM_CMD_GET_INFO), 3) => Some(MemAnswer::Info {
            id: d[2],
            kind_size: None,
        }),
        (MEM_SETTINGS_CH, Some(&MEM_CMD_GET_INFO), 16) => Some(MemAnswer::Info {
            id: d[2],
            kind_size: Some((d[3], u32::from_le_bytes([d[4], d[5], d[6], d[7]]))),
        }),
        (MEM_WRITE_CH, Some(_), 7) => Some(MemAnswer::Written {
            id: d[1],
            addr: addr(d),
            status: d[6],
        }),
        (MEM_READ_CH, Some(_), n) if n >= 7 => Some(MemAnswer::Read {
            id: d[1],
            addr: addr(d),
            status: d[6],
            data: d[7..].to_vec(),
        }),
        _ => None,
    }
}
