//! The scores of one flight: [`Report`], the content of `report.json`.
//!
//! | key | meaning |
//! | --- | --- |
//! | `scenario` | scenario name |
//! | `scenario_file` | path of the scenario file (or null) |
//! | `controller` | controller name |
//! | `rmse_pos_m` | position RMSE over the whole flight (m) |
//! | `rmse_pos_window_m` | position RMSE over t ≥ `window_start_s` (m; null if the flight ended before) |
//! | `window_start_s` | start of the scoring window (5 s) |
//! | `max_err_m` | largest position error (m) |
//! | `final_err_m` | position error at the last logged tick (m) |
//! | `crashed` | true if the error exceeded 1 m, z went below 0 or the state became non-finite |
//! | `crash_time_s` | time of the crash (s) or null |
//! | `duration_s` | simulated time actually flown (s) |
//! | `planned_duration_s` | the scenario's duration (s) |
//! | `control_hz`, `physics_hz` | controller rate and effective physics rate (Hz) |
//! | `wall_s` | wall-clock time of the flight (s) |
//! | `sim_speed` | simulated seconds per wall second |
//! | `control_step_us` | mean wall time of one controller step on this host (µs) |
//! | `events` | per disturbance event (rotor fault onset, wind step edge): `t_s`, `peak_err_m` (until the next event), `recovery_s` (until the error stays < 1 cm; null if never), `rmse_after_m` (over the 5 s after) |

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::eval::WINDOW_START_S;
use crate::io::flightlog::FlightLog;
use crate::sim::scenario::Scenario;

/// The scores of one flight (the content of `report.json`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    /// Scenario name.
    pub scenario: String,
    /// Scenario file, if any.
    pub scenario_file: Option<String>,
    /// Controller name.
    pub controller: String,
    /// Position RMSE over the whole flight (m).
    pub rmse_pos_m: f64,
    /// Position RMSE over t ≥ `window_start_s` (m).
    pub rmse_pos_window_m: Option<f64>,
    /// Scoring-window start (s).
    pub window_start_s: f64,
    /// Largest position error (m).
    pub max_err_m: f64,
    /// Error at the last tick (m).
    pub final_err_m: f64,
    /// Crashed (error > 1 m, z < 0 or non-finite state).
    pub crashed: bool,
    /// Crash time (s).
    pub crash_time_s: Option<f64>,
    /// Simulated time flown (s).
    pub duration_s: f64,
    /// Planned duration (s).
    pub planned_duration_s: f64,
    /// Control rate (Hz).
    pub control_hz: f64,
    /// Physics rate (Hz).
    pub physics_hz: f64,
    /// Wall time (s).
    pub wall_s: f64,
    /// Simulated seconds per wall second.
    pub sim_speed: f64,
    /// Mean controller step cost on the host (µs).
    pub control_step_us: f64,
    /// Scores around the disturbance's events ([`crate::fly::events`]); empty without events.
    #[serde(default)]
    pub events: Vec<crate::fly::events::EventMetrics>,
    /// Fraction of ticks whose rotor command sat at a limit.
    #[serde(default)]
    pub saturated_fraction: f64,
    /// Standard deviation of the true roll and of the true pitch over t ≥ `window_start_s`, the
    /// larger of the two (deg): the attitude loop's oscillation in hover.
    #[serde(default)]
    pub att_std_deg: Option<f64>,
    /// Mean of the estimate's position error (estimate − truth) over the window (m, world);
    /// null without a sensor chain.
    #[serde(default)]
    pub est_pos_bias_m: Option<[f64; 3]>,
    /// Mean of the flown position error (truth − reference) over the window (m, world).
    #[serde(default)]
    pub pos_err_mean_m: Option<[f64; 3]>,
}

fn rms(xs: impl Iterator<Item = f64>) -> Option<f64> {
    let (mut s, mut n) = (0.0, 0usize);
    for x in xs {
        s += x * x;
        n += 1;
    }
    (n > 0).then(|| (s / n as f64).sqrt())
}

/// The mean over the window of `f(i)` for the ticks where it is defined.
fn window_mean3(log: &FlightLog, f: impl Fn(usize) -> Option<[f64; 3]>) -> Option<[f64; 3]> {
    let (mut s, mut n) = ([0.0; 3], 0usize);
    for (i, t) in log.t_s.iter().enumerate() {
        if *t < WINDOW_START_S - 1e-9 {
            continue;
        }
        if let Some(x) = f(i) {
            for k in 0..3 {
                s[k] += x[k];
            }
            n += 1;
        }
    }
    (n > 0).then(|| s.map(|x| x / n as f64))
}

/// The larger of the roll and pitch standard deviations over the window (deg).
fn window_std_deg(log: &FlightLog) -> Option<f64> {
    let w: Vec<&[f64; 3]> = log
        .t_s
        .iter()
        .zip(&log.rpy_rad)
        .filter(|(t, _)| **t >= WINDOW_START_S - 1e-9)
        .map(|(_, a)| a)
        .collect();
    if w.len() < 2 {
        return None;
    }
    let n = w.len() as f64;
    let std = |k: usize| {
        let m = w.iter().map(|a| a[k]).sum::<f64>() / n;
        (w.iter().map(|a| (a[k] - m).powi(2)).sum::<f64>() / n).sqrt()
    };
    Some(std(0).max(std(1)).to_degrees())
}

impl Report {
    /// Score a flight log.
    pub fn from_log(log: &FlightLog, scenario_file: Option<&Path>) -> Self {
        let duration = log.t_s.last().copied().unwrap_or(0.0);
        let err_at = |e: f64| if e.is_finite() { e } else { f64::MAX };
        Self {
            scenario: log.scenario.clone(),
            scenario_file: scenario_file.map(|p| p.display().to_string()),
            controller: log.controller.clone(),
            rmse_pos_m: rms(log.err_m.iter().map(|&e| err_at(e))).unwrap_or(0.0),
            rmse_pos_window_m: rms(log
                .t_s
                .iter()
                .zip(&log.err_m)
                .filter(|(t, _)| **t >= WINDOW_START_S - 1e-9)
                .map(|(_, &e)| err_at(e))),
            window_start_s: WINDOW_START_S,
            max_err_m: log.err_m.iter().map(|&e| err_at(e)).fold(0.0, f64::max),
            final_err_m: log.err_m.last().copied().map(err_at).unwrap_or(0.0),
            crashed: log.crash_time_s.is_some(),
            crash_time_s: log.crash_time_s,
            duration_s: duration,
            planned_duration_s: log.planned_duration_s,
            control_hz: log.control_hz,
            physics_hz: log.physics_hz,
            wall_s: log.wall_s,
            sim_speed: if log.wall_s > 0.0 {
                duration / log.wall_s
            } else {
                f64::INFINITY
            },
            control_step_us: if log.control_steps > 0 {
                1e6 * log.control_wall_s / log.control_steps as f64
            } else {
                0.0
            },
            events: Vec::new(),
            saturated_fraction: if log.saturated.is_empty() {
                0.0
            } else {
                log.saturated.iter().filter(|s| **s).count() as f64 / log.saturated.len() as f64
            },
            att_std_deg: window_std_deg(log),
            est_pos_bias_m: window_mean3(log, |i| {
                let (e, p) = (log.est_p_m.get(i)?, log.p_m.get(i)?);
                Some([e[0] - p[0], e[1] - p[1], e[2] - p[2]])
            }),
            pos_err_mean_m: window_mean3(log, |i| {
                let (p, r) = (log.p_m.get(i)?, log.p_ref_m.get(i)?);
                Some([p[0] - r[0], p[1] - r[1], p[2] - r[2]])
            }),
        }
    }

    /// [`Report::from_log`] with the event scores of `scenario` filled in.
    pub fn from_flight(log: &FlightLog, scenario: &Scenario, scenario_file: Option<&Path>) -> Self {
        Self {
            events: crate::fly::events::event_metrics(scenario, log),
            ..Self::from_log(log, scenario_file)
        }
    }
}
