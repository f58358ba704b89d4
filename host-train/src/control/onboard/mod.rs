//! The onboard controller of the benchmark's Crazyflie 2.1 Brushless, reproduced: our own Rust
//! implementation of Bitcraze's Mellinger controller (firmware tag 2025.09,
//! `src/modules/src/controller/controller_mellinger.c`) and the legacy quadrotor power
//! distribution (`src/modules/src/power_distribution_quadrotor.c`), written from reading the
//! source (no code copied; the published default gains are cited as facts).
//!
//! The nanodrone-sysid-benchmark flights were flown in closed loop by this controller; replaying
//! it along a logged flight (state and reference from the log) reproduces the logged motor
//! commands `m1_thrust..m4_thrust`, which is what [`crate::pipeline`]'s `onboard` subcommand checks.
//!
//! Units: [`OnboardState`] and [`OnboardSetpoint`] are SI, world frame z up, body FLU (as
//! hamflight); [`MotorCommands`] are the firmware's PWM ratios divided by 65535 (0..1), the log's
//! `m*_thrust`. Motor numbering 1 front-right, 2 back-right, 3 back-left, 4 front-left.

pub mod config;
pub mod mellinger;
pub mod power;

pub use config::{MellingerGains, OnboardConfig};
pub use mellinger::{Mellinger, MellingerOutput};
pub use power::{legacy_power_distribution, LegacyControl, PWM_MAX};

use nalgebra::{UnitQuaternion, Vector3};

/// The estimated state the onboard controller sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnboardState {
    /// Position, world, m.
    pub p_m: Vector3<f64>,
    /// Velocity, world, m/s.
    pub v_m_s: Vector3<f64>,
    /// Attitude, body (FLU) to world (z up).
    pub q: UnitQuaternion<f64>,
    /// Body angular rate (the gyro), rad/s.
    pub w_body_rad_s: Vector3<f64>,
}

/// The full-state reference (the high-level commander's setpoint, position mode absolute).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OnboardSetpoint {
    /// Reference position, world, m.
    pub p_m: Vector3<f64>,
    /// Reference velocity, world, m/s.
    pub v_m_s: Vector3<f64>,
    /// Reference acceleration (feedforward), world, m/s².
    pub a_m_s2: Vector3<f64>,
    /// Reference yaw, rad.
    pub yaw_rad: f64,
}

impl OnboardSetpoint {
    /// Hover at `p_m` with yaw `yaw_rad`.
    pub fn hover(p_m: Vector3<f64>, yaw_rad: f64) -> Self {
        Self {
            p_m,
            v_m_s: Vector3::zeros(),
            a_m_s2: Vector3::zeros(),
            yaw_rad,
        }
    }
}

/// Normalized motor commands 0..1 (PWM ratio / 65535), motors 1..4 in the benchmark's order.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct MotorCommands(pub [f64; 4]);

impl MotorCommands {
    /// Collective: the mean of the four commands.
    pub fn collective(&self) -> f64 {
        self.0.iter().sum::<f64>() / 4.0
    }

    /// The legacy distribution's inverse: (collective, roll, pitch, yaw) in command units
    /// (normalized), with roll = the firmware's `control.roll`, pitch = `control.pitch`,
    /// yaw = `control.yaw` (each divided by 65535) when no motor is capped.
    pub fn axes(&self) -> [f64; 4] {
        let [m1, m2, m3, m4] = self.0;
        // m1 = T - r + p + y, m2 = T - r - p - y, m3 = T + r - p + y, m4 = T + r + p - y,
        // with r = roll / 2, p = pitch / 2.
        let t = (m1 + m2 + m3 + m4) / 4.0;
        let r = (-m1 - m2 + m3 + m4) / 4.0;
        let p = (m1 - m2 - m3 + m4) / 4.0;
        let y = (m1 - m2 + m3 - m4) / 4.0;
        [t, 2.0 * r, 2.0 * p, y]
    }
}

/// An onboard control law stepping at its own rate: what the replay drives.
pub trait OnboardLaw {
    /// Clears the integrators and the rate-derivative memory (as the firmware's init).
    fn reset(&mut self);
    /// One control step of length `dt_s` (integrators and the rate derivative use it).
    fn step(&mut self, state: &OnboardState, sp: &OnboardSetpoint, dt_s: f64) -> MotorCommands;
    /// The law's native rate, Hz (the firmware runs Mellinger at 500 Hz).
    fn rate_hz(&self) -> f64;
}
