//! Scores around the disturbance's events (a rotor fault, a wind step): the peak error after
//! each, how long the vehicle takes to recover, and the RMSE over the 5 s after it. They go into
//! `report.json` under `events` (`rotor-loss-mid` and `hover-wind-step`, docs/adaptation.md).

use serde::{Deserialize, Serialize};

use crate::io::flightlog::FlightLog;
use crate::sim::scenario::Scenario;

/// The error (m) below which the vehicle counts as recovered.
pub const RECOVERED_ERR_M: f64 = 0.01;
/// Length of the RMSE window after an event (s).
pub const EVENT_WINDOW_S: f64 = 5.0;

/// The scores of one event.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct EventMetrics {
    /// When the disturbance changed (s).
    pub t_s: f64,
    /// Largest position error from the event to the next one (or the end) (m).
    pub peak_err_m: f64,
    /// Time from the event until the error stays below [`RECOVERED_ERR_M`] up to the next event
    /// (s); null if it never does.
    pub recovery_s: Option<f64>,
    /// Position RMSE over [t, t + 5 s) (m; the flight's end cuts it short); null if not flown.
    pub rmse_after_m: Option<f64>,
}

/// The scores of every event of `scenario` (see `DisturbanceSpec::event_times_s`) in `log`.
pub fn event_metrics(scenario: &Scenario, log: &FlightLog) -> Vec<EventMetrics> {
    let times = scenario.spec.disturbance.event_times_s();
    let end = log.t_s.last().copied().unwrap_or(0.0);
    let mut out = Vec::new();
    for (i, &te) in times.iter().enumerate() {
        if te > end {
            break;
        }
        let next = times.get(i + 1).copied().unwrap_or(f64::INFINITY);
        let in_window: Vec<(f64, f64)> = log
            .t_s
            .iter()
            .zip(&log.err_m)
            .filter(|(t, _)| **t >= te - 1e-9 && **t < next - 1e-9)
            .map(|(t, e)| (*t, if e.is_finite() { *e } else { f64::MAX }))
            .collect();
        let peak = in_window.iter().map(|(_, e)| *e).fold(0.0, f64::max);
        let last_bad = in_window.iter().rposition(|(_, e)| *e >= RECOVERED_ERR_M);
        let recovery_s = match last_bad {
            None => Some(0.0),
            Some(k) => in_window.get(k + 1).map(|(t, _)| t - te),
        };
        let rmse: Vec<f64> = in_window
            .iter()
            .filter(|(t, _)| *t < te + EVENT_WINDOW_S - 1e-9)
            .map(|(_, e)| *e)
            .collect();
        let rmse_after_m = (!rmse.is_empty())
            .then(|| (rmse.iter().map(|e| e * e).sum::<f64>() / rmse.len() as f64).sqrt());
        out.push(EventMetrics {
            t_s: te,
            peak_err_m: peak,
            recovery_s,
            rmse_after_m,
        });
    }
    out
}
