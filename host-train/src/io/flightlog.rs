//! The flight log: everything recorded during one closed-loop flight, one entry per control tick.
//! A leaf module, so that flying ([`crate::fly::eval`]) and drawing ([`crate::report::plot`]) both depend on it
//! and not on each other.

use serde::{Deserialize, Serialize};

/// Everything logged during one flight, one entry per control tick.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct FlightLog {
    /// Scenario name.
    pub scenario: String,
    /// Controller name.
    pub controller: String,
    /// Tick times (s).
    pub t_s: Vec<f64>,
    /// Flown (true) position (m, world).
    pub p_m: Vec<[f64; 3]>,
    /// Desired position (m, world).
    pub p_ref_m: Vec<[f64; 3]>,
    /// Position error |p − p*| (m).
    pub err_m: Vec<f64>,
    /// Rotor commands issued at each tick (rpm); the last tick may repeat the previous command.
    pub rpm: Vec<[f64; 4]>,
    /// True roll, pitch, yaw at each tick (rad, Z-Y-X).
    #[serde(default)]
    pub rpy_rad: Vec<[f64; 3]>,
    /// Whether the tick's rotor command sat at a limit (0 or the top speed): the mixer or the
    /// plant saturated.
    #[serde(default)]
    pub saturated: Vec<bool>,
    /// The estimated position the controller was given (m, world); empty without a sensor
    /// chain ([`crate::sim::sensors`]).
    #[serde(default)]
    pub est_p_m: Vec<[f64; 3]>,
    /// Adaptation estimate at each tick (empty vectors if the controller does not adapt).
    pub adaptation: Vec<Vec<f64>>,
    /// Time of the crash (s), if any.
    pub crash_time_s: Option<f64>,
    /// Planned duration (s).
    pub planned_duration_s: f64,
    /// Control rate (Hz).
    pub control_hz: f64,
    /// Effective physics rate (Hz).
    pub physics_hz: f64,
    /// Wall time of the whole flight (s).
    pub wall_s: f64,
    /// Total wall time spent inside `Controller::step` (s).
    pub control_wall_s: f64,
    /// Number of controller steps.
    pub control_steps: u64,
}
