//! The firmware's side of the link: what the firmware sends back, its console and its process.
//! The packets themselves are host-train's (`host_train::io`: `imu_packet`, `parse_motor`, ...).

use std::net::SocketAddr;
use std::process::Child;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use host_train::io::{
    parse_crtp_mem_answer, parse_hl_answer, parse_param_answer, CrtpMemAnswer, ParamAnswer,
};

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
    /// cflib's packets for the firmware, waiting for the loop to send them.
    pub from_cflib: std::collections::VecDeque<Vec<u8>>,
    /// The longest that wait has been (packets).
    pub from_cflib_max: usize,
    /// The memory TOC: the number of memories, once answered.
    pub mem_count: Option<u8>,
    /// Memory infos answered: (id, (type, size) or none past the end).
    pub mem_info: Vec<(u8, Option<(u8, u32)>)>,
    /// Memory writes answered: (memory id, address, status).
    pub mem_written: Vec<(u8, u32, u8)>,
    /// The high-level commander's answers, in order: (command, result).
    pub hl_answers: Vec<(u8, u8)>,
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

/// Parameter answers into `sh`: TOC items and write echoes; and the memory port's and the
/// high-level commander's answers.
pub fn param_answer(d: &[u8], sh: &mut FromFirmware) {
    if let Some(a) = parse_hl_answer(d) {
        sh.hl_answers.push(a);
        return;
    }
    match parse_crtp_mem_answer(d) {
        Some(CrtpMemAnswer::Count(n)) => sh.mem_count = Some(n),
        Some(CrtpMemAnswer::Info { id, kind_size }) => {
            if !sh.mem_info.iter().any(|x| x.0 == id) {
                sh.mem_info.push((id, kind_size));
            }
        }
        Some(CrtpMemAnswer::Written { id, addr, status }) => {
            sh.mem_written.push((id, addr, status))
        }
        Some(CrtpMemAnswer::Read { .. }) | None => {}
    }
    match parse_param_answer(d) {
        Some(ParamAnswer::TocEnd) => sh.param_toc_end = true,
        Some(ParamAnswer::TocItem { id, name, .. })
            if !sh.param_toc.iter().any(|(i, _)| *i == id) =>
        {
            sh.param_toc.push((id, name));
        }
        Some(ParamAnswer::Written { id, value }) => sh.param_written.push((id, value)),
        Some(ParamAnswer::TocItem { .. }) | None => {}
    }
}
