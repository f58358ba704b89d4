//! `--pilot trajectory`: a figure of eight made of poly4d pieces, uploaded to the high-level
//! commander's trajectory memory over the memory port, defined and started relative to the hover
//! point (cflib's `TrajectoryMemory.write_data` + `define_trajectory` + `start_trajectory`).
//!
//! The packets are host-train's (`host_train::io`: `crtp_mem_write_packets`,
//! `hl_define_trajectory_packet`, ...); this module builds the pieces and runs the upload as a
//! small state machine: the memory count, the info of each memory until the trajectory memory
//! (MEM_TYPE_TRAJ), every write until the firmware answers it with status 0, the definition until
//! the commander answers it with 0. A request without an answer is sent again after
//! [`RETRY_MS`]; after [`MAX_TRIES`] sends, or an answer with an error, the upload fails with the
//! cause named (never a hang).

use anyhow::{bail, Result};
use host_train::io::{
    crtp_mem_count_request, crtp_mem_info_request, crtp_mem_write_packets,
    hl_define_trajectory_packet, Poly4d, CRTP_MEM_TYPE_TRAJ, POLY4D_BYTES, TRAJECTORY_MEMORY_BYTES,
};
use nalgebra::{Matrix4, Vector3, Vector4};

use crate::crtp::FromFirmware;

/// Milliseconds (plant ticks) before an unanswered request is sent again.
pub const RETRY_MS: u64 = 20;
/// Sends of one request before the upload fails.
pub const MAX_TRIES: u32 = 10;
/// Memory writes sent and not yet answered, at most (the firmware's socket queue holds 5).
const IN_FLIGHT: usize = 4;
/// The high-level commander's HL command numbers (for matching its answers).
pub const HL_CMD_START_TRAJECTORY: u8 = 5;
const HL_CMD_DEFINE_TRAJECTORY: u8 = 6;

/// The figure of eight at `t_s` of `dur_s` (the scenarios' `kind = "figure_eight"`): x = a sin θ,
/// y = (a/2) sin 2θ, z = 0, with θ going 0 → 2π along the septic smoothstep (at rest, without
/// acceleration or jerk, at both ends, which are the start point, the origin). Per axis: position
/// and its first three time derivatives.
pub fn figure_eight(a_m: f64, dur_s: f64, t_s: f64) -> [[f64; 4]; 3] {
    let p = host_train::sim::figure_eight(Vector3::zeros(), a_m, dur_s, t_s);
    let axis = |i: usize| [p.p_m[i], p.v_m_s[i], p.a_m_s2[i], p.j_m_s3[i]];
    [axis(0), axis(1), axis(2)]
}

/// The degree-7 polynomial on [0, d] (ascending coefficients) with value and first three
/// derivatives `a` at 0 and `b` at d (Hermite interpolation: eight conditions, eight
/// coefficients), solved in the normalised time t / d.
pub fn hermite7(d: f64, a: [f64; 4], b: [f64; 4]) -> [f64; 8] {
    // in u = t / d the k-th derivative scales by d^k
    let an: [f64; 4] = core::array::from_fn(|k| a[k] * d.powi(k as i32));
    let bn: [f64; 4] = core::array::from_fn(|k| b[k] * d.powi(k as i32));
    // c0..c3 from the start: c_k = a_k / k!
    let fact = [1.0, 1.0, 2.0, 6.0];
    let lo: [f64; 4] = core::array::from_fn(|k| an[k] / fact[k]);
    // the k-th derivative at u = 1 of u^n is n!/(n-k)!
    let falling = |n: i32, k: i32| (0..k).map(|i| (n - i) as f64).product::<f64>();
    let m = Matrix4::from_fn(|k, j| falling(4 + j as i32, k as i32));
    let rhs = Vector4::from_fn(|k, _| {
        bn[k]
            - (0..4)
                .filter(|&n| n >= k)
                .map(|n| lo[n] * falling(n as i32, k as i32))
                .sum::<f64>()
    });
    let hi = m.lu().solve(&rhs).expect("the Hermite system is regular");
    core::array::from_fn(|n| {
        let c = if n < 4 { lo[n] } else { hi[n - 4] };
        c / d.powi(n as i32)
    })
}

/// The figure of eight as `n` poly4d pieces of equal duration, C³ at the joints, yaw constant
/// `yaw_rad` (the commander does not shift yaw: it is flown as uploaded).
pub fn figure_eight_pieces(a_m: f64, dur_s: f64, n: usize, yaw_rad: f64) -> Vec<Poly4d> {
    let d = dur_s / n as f64;
    (0..n)
        .map(|i| {
            let (p0, p1) = (
                figure_eight(a_m, dur_s, i as f64 * d),
                figure_eight(a_m, dur_s, (i + 1) as f64 * d),
            );
            let axis = |j: usize| hermite7(d, p0[j], p1[j]).map(|c| c as f32);
            let mut yaw = [0f32; 8];
            yaw[0] = yaw_rad as f32;
            Poly4d {
                coef: [axis(0), axis(1), axis(2), yaw],
                duration_s: d as f32,
            }
        })
        .collect()
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    Count,
    Info(u8),
    Write,
    Define,
    Done,
}

/// The upload of one trajectory (to address 0 of the trajectory memory, as trajectory id
/// `traj_id`) and its definition, one packet per call of [`Upload::next_packet`].
pub struct Upload {
    bytes: Vec<u8>,
    n_pieces: u8,
    traj_id: u8,
    stage: Stage,
    mem_count: u8,
    pub mem_id: Option<u8>,
    pub mem_size: u32,
    chunks: Vec<(u32, Vec<u8>)>,
    /// Per chunk: sends, the tick of the last send, answered.
    sends: Vec<(u32, Option<u64>, bool)>,
    /// The current request (count, info, define): sends and the tick of the last one.
    req: (u32, Option<u64>),
    /// Packets sent, and of those repeats.
    pub packets: u32,
    pub repeats: u32,
}

impl Upload {
    pub fn new(pieces: &[Poly4d], traj_id: u8) -> Result<Self> {
        let bytes: Vec<u8> = pieces.iter().flat_map(Poly4d::to_bytes).collect();
        if pieces.is_empty() || bytes.len() > TRAJECTORY_MEMORY_BYTES {
            bail!(
                "{} poly4d pieces ({} B) do not fit the trajectory memory ({} B = {} pieces)",
                pieces.len(),
                bytes.len(),
                TRAJECTORY_MEMORY_BYTES,
                TRAJECTORY_MEMORY_BYTES / POLY4D_BYTES
            );
        }
        Ok(Upload {
            bytes,
            n_pieces: pieces.len() as u8,
            traj_id,
            stage: Stage::Count,
            mem_count: 0,
            mem_id: None,
            mem_size: 0,
            chunks: Vec::new(),
            sends: Vec::new(),
            req: (0, None),
            packets: 0,
            repeats: 0,
        })
    }

    pub fn done(&self) -> bool {
        self.stage == Stage::Done
    }

    pub fn bytes(&self) -> usize {
        self.bytes.len()
    }

    pub fn writes(&self) -> usize {
        self.chunks.len()
    }

    /// Where the upload is, for an error message.
    pub fn status(&self) -> String {
        match self.stage {
            Stage::Count => "waiting for the memory count".into(),
            Stage::Info(i) => format!("reading the memory TOC (id {i} of {})", self.mem_count),
            Stage::Write => format!(
                "{} of {} writes answered",
                self.sends.iter().filter(|s| s.2).count(),
                self.chunks.len()
            ),
            Stage::Define => "waiting for define_trajectory's answer".into(),
            Stage::Done => "done".into(),
        }
    }

    /// A request of the current stage: due now (first send, or unanswered for [`RETRY_MS`]),
    /// counted, or an error after [`MAX_TRIES`].
    fn request(&mut self, k: u64, what: &str, pk: Vec<u8>) -> Result<Option<Vec<u8>>> {
        if self.req.1.is_some_and(|last| k < last + RETRY_MS) {
            return Ok(None);
        }
        if self.req.0 >= MAX_TRIES {
            bail!(
                "trajectory upload: no answer to {what} after {MAX_TRIES} tries {RETRY_MS} ms apart"
            );
        }
        if self.req.0 > 0 {
            self.repeats += 1;
        }
        self.req = (self.req.0 + 1, Some(k));
        self.packets += 1;
        Ok(Some(pk))
    }

    fn advance(&mut self, stage: Stage) {
        self.stage = stage;
        self.req = (0, None);
    }

    /// The next packet to send at plant tick `k` (at most one), given what the firmware answered
    /// so far (`sh`); `None` when nothing is due. An error names what went wrong.
    pub fn next_packet(&mut self, k: u64, sh: &FromFirmware) -> Result<Option<Vec<u8>>> {
        loop {
            match self.stage {
                Stage::Count => match sh.mem_count {
                    Some(0) => bail!("trajectory upload: the firmware has no memories"),
                    Some(n) => {
                        self.mem_count = n;
                        self.advance(Stage::Info(0));
                    }
                    None => return self.request(k, "the memory count", crtp_mem_count_request()),
                },
                Stage::Info(i) => match sh.mem_info.iter().find(|x| x.0 == i) {
                    Some(&(_, Some((kind, size)))) if kind == CRTP_MEM_TYPE_TRAJ => {
                        if (size as usize) < self.bytes.len() {
                            bail!(
                                "trajectory upload: the trajectory memory (id {i}) holds {size} B, \
                                 the trajectory needs {}",
                                self.bytes.len()
                            );
                        }
                        self.mem_id = Some(i);
                        self.mem_size = size;
                        self.chunks = crtp_mem_write_packets(i, 0, &self.bytes);
                        self.sends = vec![(0, None, false); self.chunks.len()];
                        self.advance(Stage::Write);
                    }
                    Some(_) if i + 1 >= self.mem_count => bail!(
                        "trajectory upload: no trajectory memory (type 0x{CRTP_MEM_TYPE_TRAJ:02x}) \
                         among the firmware's {} memories",
                        self.mem_count
                    ),
                    Some(_) => self.advance(Stage::Info(i + 1)),
                    None => {
                        return self.request(
                            k,
                            &format!("the memory info of id {i}"),
                            crtp_mem_info_request(i),
                        )
                    }
                },
                Stage::Write => {
                    let id = self.mem_id.unwrap_or(0);
                    for ((addr, _), s) in self.chunks.iter().zip(self.sends.iter_mut()) {
                        if s.2 {
                            continue;
                        }
                        if let Some(&(_, _, status)) =
                            sh.mem_written.iter().find(|w| w.0 == id && w.1 == *addr)
                        {
                            if status != 0 {
                                bail!(
                                    "trajectory upload: the firmware refused the write at byte \
                                     {addr} of memory {id} (status {status})"
                                );
                            }
                            s.2 = true;
                        }
                    }
                    if self.sends.iter().all(|s| s.2) {
                        self.advance(Stage::Define);
                        continue;
                    }
                    let in_flight = self
                        .sends
                        .iter()
                        .filter(|s| !s.2 && s.1.is_some_and(|l| k < l + RETRY_MS))
                        .count();
                    if in_flight >= IN_FLIGHT {
                        return Ok(None);
                    }
                    let due = self
                        .sends
                        .iter()
                        .position(|s| !s.2 && s.1.is_none_or(|l| k >= l + RETRY_MS));
                    let Some(i) = due else { return Ok(None) };
                    let s = &mut self.sends[i];
                    if s.0 >= MAX_TRIES {
                        bail!(
                            "trajectory upload: the write at byte {} of memory {id} was not \
                             answered after {MAX_TRIES} tries {RETRY_MS} ms apart ({})",
                            self.chunks[i].0,
                            self.status()
                        );
                    }
                    if s.0 > 0 {
                        self.repeats += 1;
                    }
                    *s = (s.0 + 1, Some(k), false);
                    self.packets += 1;
                    return Ok(Some(self.chunks[i].1.clone()));
                }
                Stage::Define => {
                    match sh
                        .hl_answers
                        .iter()
                        .find(|a| a.0 == HL_CMD_DEFINE_TRAJECTORY)
                    {
                        Some(&(_, 0)) => self.advance(Stage::Done),
                        Some(&(_, e)) => bail!(
                            "trajectory upload: define_trajectory refused (error {e}) for id {}",
                            self.traj_id
                        ),
                        None => {
                            let pk = hl_define_trajectory_packet(self.traj_id, 0, self.n_pieces);
                            return self.request(k, "define_trajectory", pk);
                        }
                    }
                }
                Stage::Done => return Ok(None),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn pieces_follow_the_figure() {
        let pieces = figure_eight_pieces(0.5, 10.0, 10, 0.0);
        for i in 0..=1000 {
            let t = i as f64 * 0.01;
            let e = host_train::io::poly4d_trajectory_eval(&pieces, t).unwrap();
            let f = figure_eight(0.5, 10.0, t);
            // ten septic pieces: within 0.2 mm of the figure (0.165 mm at worst)
            assert!((e.p_m.x - f[0][0]).abs() < 2e-4 && (e.p_m.y - f[1][0]).abs() < 2e-4);
            assert!((e.v_m_s.x - f[0][1]).abs() < 2e-3, "t {t}");
        }
    }

    /// host-train's scenario kind `figure_eight` (the same path flown without the firmware,
    /// `host-train eval`, `bitcraze-loop`) is this figure.
    #[test]
    fn the_scenario_kind_is_this_figure() {
        let s = host_train::Scenario::from_toml_str(
            "duration_s = 12.0\n[trajectory]\nkind = \"figure_eight\"\nstart_m = [0.0, 0.0, 1.0]\n\
             half_width_m = 0.5\nduration_s = 10.0\nstart_s = 1.0\n",
            "test",
            "fig8",
        )
        .unwrap();
        for i in 0..=1200 {
            let t = i as f64 * 0.01;
            let r = s.reference(t);
            let f = figure_eight(0.5, 10.0, t - 1.0);
            let got = [r.p_m - Vector3::z(), r.v_m_s, r.a_m_s2, r.j_m_s3];
            for (k, g) in got.iter().enumerate() {
                for axis in 0..3 {
                    assert!((g[axis] - f[axis][k]).abs() < 1e-9, "t {t} derivative {k}");
                }
            }
        }
    }

    /// The firmware's side for the upload: answers every request (the trajectory memory is id
    /// 1 of 3), except the first send of the write at `lose_addr`.
    fn answer(pk: &[u8], sh: &mut FromFirmware, lose_addr: Option<u32>, lost: &mut bool) {
        match (pk[0], pk[1]) {
            (0x4C, 1) => sh.mem_count = Some(3),
            (0x4C, 2) => sh.mem_info.push((
                pk[2],
                Some((if pk[2] == 1 { CRTP_MEM_TYPE_TRAJ } else { 0x18 }, 4096)),
            )),
            (0x4E, id) => {
                let addr = u32::from_le_bytes([pk[2], pk[3], pk[4], pk[5]]);
                if lose_addr == Some(addr) && !*lost {
                    *lost = true;
                } else {
                    sh.mem_written.push((id, addr, 0));
                }
            }
            (0x8C, 6) => sh.hl_answers.push((6, 0)),
            _ => panic!("unexpected packet {pk:?}"),
        }
    }

    #[test]
    fn the_upload_repeats_a_lost_write_and_fails_without_answers() {
        let pieces = figure_eight_pieces(0.5, 10.0, 2, 0.0);
        // a lost answer: that write is sent again after RETRY_MS, the upload completes
        let mut up = Upload::new(&pieces, 0).unwrap();
        let (mut sh, mut lost) = (FromFirmware::default(), false);
        for k in 0..1000 {
            if let Some(pk) = up.next_packet(k, &sh).unwrap() {
                answer(&pk, &mut sh, Some(48), &mut lost);
            }
            if up.done() {
                break;
            }
        }
        assert!(up.done() && lost, "{}", up.status());
        assert_eq!(up.mem_id, Some(1));
        assert_eq!((up.writes(), up.repeats), (11, 1));
        // no answers at all: an error naming the memory count, within MAX_TRIES retries
        let mut up = Upload::new(&pieces, 0).unwrap();
        let sh = FromFirmware::default();
        let err = (0..1000)
            .find_map(|k| up.next_packet(k, &sh).err())
            .expect("fails");
        assert!(err.to_string().contains("the memory count"), "{err}");
        // a refused write: an error at once
        let mut up = Upload::new(&pieces, 0).unwrap();
        let mut sh = FromFirmware {
            mem_count: Some(1),
            mem_info: vec![(0, Some((CRTP_MEM_TYPE_TRAJ, 4096)))],
            ..Default::default()
        };
        sh.mem_written.push((0, 0, 5));
        let err = up.next_packet(0, &sh).unwrap_err();
        assert!(err.to_string().contains("refused"), "{err}");
    }
}
