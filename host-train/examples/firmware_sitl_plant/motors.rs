//! The motor packets: in lock-step, their impairments (`--motor-delay-ms`, `--motor-jitter-ms`,
//! `--motor-drop`) and their digest; in any timing, the gaps between them in flight and their
//! rate.

use std::collections::VecDeque;
use std::time::Instant;

use rand::{Rng, SeedableRng};

use crate::Args;

pub struct Motors {
    /// Commands waiting for the plant tick they reach it at (lock-step only, repeatable), the
    /// draws, how many were dropped, and the command the plant runs.
    queue: VecDeque<(u64, [u16; 4])>,
    impair_rng: rand_chacha::ChaCha8Rng,
    pub dropped: u64,
    plant_pwm: [u16; 4],
    /// Every motor command of a lock-stepped run with its tick, hashed (FNV-1a): two runs that
    /// agree here had the same firmware output every millisecond.
    pub digest: u64,
    /// Motor packets in flight (take-off to landing): the count and plant time of the last new
    /// one, the largest gap between two, and how many gaps were 4 ms or more (the 500 Hz
    /// controller's output every 2 ms; the SITL power distribution sends at most one per tick
    /// and skips the rest).
    last_motor: u64,
    last_motor_t: f64,
    pub gap_max_s: f64,
    pub gaps_4ms: u32,
    /// Take-off: the wall clock and the plant time, and the motor packets until then (the
    /// motor packet rate in flight).
    engage_wall: Option<(Instant, f64)>,
    at_engage: u64,
    /// Motor packets per second from the take-off to the landing: of wall clock; in
    /// lock-step, of plant time.
    pub rate_in_flight: f64,
}

impl Motors {
    pub fn new(seed: u64) -> Self {
        Motors {
            queue: Default::default(),
            impair_rng: rand_chacha::ChaCha8Rng::seed_from_u64(seed),
            dropped: 0,
            plant_pwm: [0u16; 4],
            digest: 0xcbf2_9ce4_8422_2325,
            last_motor: 0,
            last_motor_t: f64::NAN,
            gap_max_s: 0.0,
            gaps_4ms: 0,
            engage_wall: None,
            at_engage: 0,
            rate_in_flight: 0.0,
        }
    }

    /// Lock-step: the command that reaches the plant at loop step `k`.
    pub fn reaching_plant(&mut self, k: u64) -> [u16; 4] {
        while self.queue.front().is_some_and(|x| x.0 <= k) {
            self.plant_pwm = self.queue.pop_front().unwrap().1;
        }
        self.plant_pwm
    }

    /// Lock-step: the motor command `p` of firmware tick `tick`, received after loop step `k`
    /// (`k`: already the next step): dropped, or queued with its delay; and hashed.
    pub fn received(&mut self, args: &Args, k: u64, tick: u32, p: [u16; 4]) {
        let drop = args.motor_drop > 0.0 && self.impair_rng.gen_bool(args.motor_drop.min(1.0));
        let jitter = if args.motor_jitter_ms > 0 {
            self.impair_rng.gen_range(0..=args.motor_jitter_ms as u64)
        } else {
            0
        };
        if drop {
            self.dropped += 1;
        } else {
            // reaches the plant at loop step k + delay (k: already the next step), never
            // before a command sent earlier
            let at =
                (k + args.motor_delay_ms as u64 + jitter).max(self.queue.back().map_or(0, |x| x.0));
            self.queue.push_back((at, p));
        }
        for b in (tick as u64)
            .to_le_bytes()
            .into_iter()
            .chain(p.iter().flat_map(|m| m.to_le_bytes()))
        {
            self.digest = (self.digest ^ b as u64).wrapping_mul(0x100_0000_01b3);
        }
    }

    /// The gaps between new motor packets (`motor_packets` so far) at plant time `t`, counted
    /// in the take-off, hold and landing.
    pub fn count_gaps(&mut self, motor_packets: u64, phase: &str, t: f64) {
        if motor_packets != self.last_motor {
            if matches!(phase, "takeoff" | "hold" | "land") && self.last_motor_t.is_finite() {
                let gap = t - self.last_motor_t;
                self.gap_max_s = self.gap_max_s.max(gap);
                if gap >= 0.0035 {
                    self.gaps_4ms += 1;
                }
            }
            (self.last_motor, self.last_motor_t) = (motor_packets, t);
        }
    }

    /// The motor packet rate from the take-off to the landing.
    pub fn count_rate(&mut self, motor_packets: u64, phase: &str, t: f64, lockstep: bool) {
        if phase == "takeoff" && self.engage_wall.is_none() {
            self.engage_wall = Some((Instant::now(), t));
            self.at_engage = motor_packets;
        }
        if phase == "landed" {
            if let Some((w, t0)) = self.engage_wall.take() {
                // per second of wall clock; in lock-step, of plant time
                let dur = if lockstep {
                    t - t0
                } else {
                    w.elapsed().as_secs_f64()
                };
                self.rate_in_flight = (motor_packets - self.at_engage) as f64 / dur;
            }
        }
    }
}
