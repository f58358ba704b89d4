//! Replaying the onboard controller along a logged flight: state and reference from the log,
//! the controller stateful, sub-stepping between rows at its own rate.

use crate::control::onboard::{Mellinger, OnboardConfig, OnboardLaw};
use crate::io::{LoopFlight, MotorCommands, OnboardSetpoint, OnboardState};
use serde::{Deserialize, Serialize};

/// How the reference acceleration (the logs have none) is made.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum AccelSource {
    /// Zero feedforward.
    Zero,
    /// Central difference of the reference velocity over ±`accel_span` rows.
    Diff,
}

/// The replay's options.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct ReplayOptions {
    /// Controller steps per log row (the firmware: 500 Hz / 100 Hz = 5), the state interpolated
    /// between rows.
    pub substeps: usize,
    /// The reference acceleration.
    pub accel: AccelSource,
    /// Half-width of the central difference, rows.
    pub accel_span: usize,
    /// Compare the commands after a centred moving average over this many rows (≤ 1: raw);
    /// both the logged and the replayed ones, over flown rows only.
    #[serde(default)]
    pub smooth_rows: usize,
}

/// The centred moving average of `cmd` over `rows` rows, over flown rows only (≤ 1: a copy).
#[allow(clippy::needless_range_loop)] // rows index the flight and the commands together
pub fn smooth(f: &LoopFlight, cmd: &[MotorCommands], rows: usize) -> Vec<MotorCommands> {
    if rows <= 1 {
        return cmd.to_vec();
    }
    let half = rows / 2;
    let n = cmd.len();
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half).min(n.saturating_sub(1)));
            let mut sum = [0.0; 4];
            let mut cnt = 0.0;
            for j in a..=b {
                if active(f, j) {
                    for (s, c) in sum.iter_mut().zip(cmd[j].0) {
                        *s += c;
                    }
                    cnt += 1.0;
                }
            }
            if cnt > 0.0 {
                MotorCommands(sum.map(|s| s / cnt))
            } else {
                cmd[k]
            }
        })
        .collect()
}

/// A command above the benchmark's idle floor (10000/65535 = 0.15259) by a margin.
pub const ABOVE_IDLE: f64 = 0.155;

/// Whether row `k` was flown by the controller: all four logged commands above zero (they are
/// 0 while disarmed) and not all four at the idle floor (armed on the ground).
pub fn active(f: &LoopFlight, k: usize) -> bool {
    f.cmd
        .get(k)
        .is_some_and(|c| c.0.iter().all(|&m| m > 0.0) && c.0.iter().any(|&m| m > ABOVE_IDLE))
}

/// The reference with the acceleration filled in.
pub fn setpoints(f: &LoopFlight, opt: &ReplayOptions) -> Vec<OnboardSetpoint> {
    let n = f.len();
    let span = opt.accel_span.max(1);
    (0..n)
        .map(|k| {
            let mut sp = f.setpoint[k];
            if opt.accel == AccelSource::Diff && n > 1 {
                let a = k.saturating_sub(span);
                let b = (k + span).min(n - 1);
                let dt = f.t_s[b] - f.t_s[a];
                if dt > 0.0 {
                    sp.a_m_s2 = (f.setpoint[b].v_m_s - f.setpoint[a].v_m_s) / dt;
                }
            }
            sp
        })
        .collect()
}

pub(crate) fn lerp_state(a: &OnboardState, b: &OnboardState, s: f64) -> OnboardState {
    OnboardState {
        p_m: a.p_m.lerp(&b.p_m, s),
        v_m_s: a.v_m_s.lerp(&b.v_m_s, s),
        q: a.q.try_slerp(&b.q, s, 1e-9).unwrap_or(b.q),
        w_body_rad_s: a.w_body_rad_s.lerp(&b.w_body_rad_s, s),
    }
}

fn lerp_sp(a: &OnboardSetpoint, b: &OnboardSetpoint, s: f64) -> OnboardSetpoint {
    OnboardSetpoint {
        p_m: a.p_m.lerp(&b.p_m, s),
        v_m_s: a.v_m_s.lerp(&b.v_m_s, s),
        a_m_s2: a.a_m_s2.lerp(&b.a_m_s2, s),
        yaw_rad: a.yaw_rad + (b.yaw_rad - a.yaw_rad) * s,
    }
}

/// The controller's commands at every row (zero on inactive rows), delayed by the config's
/// `cmd_delay_s` (rounded to rows). The controller is reset whenever the flight becomes active.
pub fn replay(f: &LoopFlight, cfg: &OnboardConfig, opt: &ReplayOptions) -> Vec<MotorCommands> {
    let sps = setpoints(f, opt);
    let mut law = Mellinger::new(*cfg);
    let n = f.len();
    let sub = opt.substeps.max(1);
    let mut out = vec![MotorCommands::default(); n];
    let mut was_active = false;
    for k in 0..n {
        if !active(f, k) {
            was_active = false;
            continue;
        }
        if !was_active {
            law.reset();
        }
        let dt_row = if k > 0 {
            f.t_s[k] - f.t_s[k - 1]
        } else {
            f.t_s.get(1).map_or(0.01, |t1| t1 - f.t_s[0])
        };
        let dt = dt_row / sub as f64;
        let prev = if was_active && k > 0 { k - 1 } else { k };
        let mut c = MotorCommands::default();
        for j in 1..=sub {
            let s = j as f64 / sub as f64;
            let st = lerp_state(&f.state[prev], &f.state[k], s);
            let sp = lerp_sp(&sps[prev], &sps[k], s);
            c = law.step(&st, &sp, dt);
        }
        out[k] = c;
        was_active = true;
    }
    delay_rows(&out, f, cfg.cmd_delay_s)
}

fn delay_rows(cmd: &[MotorCommands], f: &LoopFlight, delay_s: f64) -> Vec<MotorCommands> {
    let dt = if f.len() > 1 {
        (f.t_s[f.len() - 1] - f.t_s[0]) / (f.len() - 1) as f64
    } else {
        0.01
    };
    let d = (delay_s / dt).round().max(0.0) as usize;
    (0..cmd.len()).map(|k| cmd[k.saturating_sub(d)]).collect()
}
