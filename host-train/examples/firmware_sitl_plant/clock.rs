//! The loop's clock, at the end of each millisecond: in lock-step the IMU packet, the wait for
//! the firmware's tick and what came with it; paced at 1 kHz of wall clock otherwise (or with
//! `--realtime`).

use std::sync::atomic::Ordering;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use host_train::io::CrtpLockstep;

use crate::crtp::param_answer;
use crate::launch::Link;
use crate::motors::Motors;
use crate::Args;

pub struct Clock {
    /// Lock-step: the loop sends the IMU packet last and waits for the firmware's tick.
    pub lockstep: Option<CrtpLockstep>,
    pace: bool,
    /// The loop's start, and the next packet's deadline when paced (wall clock).
    pub loop_start: Instant,
    deadline: Instant,
    /// Pacing: the latest a packet went, and how often the deadline was reset after 20 ms late.
    pub max_late_ms: f64,
    pub late_resets: u32,
}

impl Clock {
    pub fn new(args: &Args, link: &Link) -> Result<Self> {
        let lockstep = if args.lockstep {
            Some(CrtpLockstep::new(
                link.sock.try_clone()?,
                link.fw_addr,
                Duration::from_secs_f64(args.tick_timeout_s),
            ))
        } else {
            None
        };
        let loop_start = Instant::now();
        Ok(Clock {
            lockstep,
            pace: !args.lockstep || args.realtime,
            loop_start,
            deadline: loop_start,
            max_late_ms: 0.0,
            late_resets: 0,
        })
    }

    /// Lock-step: the IMU packet last (the firmware's next tick), then wait for that tick: its
    /// motor command to `motors` (loop step `k`: already the next one), the answers into the
    /// shared state, the rest relayed to cflib.
    pub fn exchange(
        &mut self,
        link: &Link,
        args: &Args,
        motors: &mut Motors,
        imu: &[u8],
        k: u64,
        plant_t: f64,
    ) -> Result<()> {
        if let Some(lockstep) = &mut self.lockstep {
            let tick = lockstep
                .step(imu)
                .with_context(|| format!("plant t = {plant_t:.3} s"))?;
            let mut sh = link.shared.lock().unwrap();
            if let Some(p) = tick.motor {
                motors.received(args, k, tick.tick, p);
                sh.pwm = p;
                sh.motor_packets += 1;
            }
            for d in &tick.other {
                param_answer(d, &mut sh);
            }
            drop(sh);
            if let (Some(lib), Some(a)) = (&link.lib_sock, *link.lib_addr.lock().unwrap()) {
                for d in &tick.other {
                    let _ = lib.send_to(d, a);
                    link.relayed.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        Ok(())
    }

    /// Pace: the next packet 1 ms after this one's deadline; never burst to catch up.
    pub fn pace(&mut self) {
        if self.pace {
            self.deadline += Duration::from_micros(1000);
            let now = Instant::now();
            if self.deadline > now {
                thread::sleep(self.deadline - now);
            } else {
                let late = (now - self.deadline).as_secs_f64() * 1e3;
                self.max_late_ms = self.max_late_ms.max(late);
                if late > 20.0 {
                    self.deadline = now;
                    self.late_resets += 1;
                }
            }
        }
    }
}
