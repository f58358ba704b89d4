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

// The logged records (state, reference, commands) live with the log's reader in the io layer
// (layer 1), so that reading a loop log needs no controller; they are the controller's
// interface types too.
pub use crate::io::{MotorCommands, OnboardSetpoint, OnboardState};

/// An onboard control law stepping at its own rate: what the replay drives.
pub trait OnboardLaw {
    /// Clears the integrators and the rate-derivative memory (as the firmware's init).
    fn reset(&mut self);
    /// One control step of length `dt_s` (integrators and the rate derivative use it).
    fn step(&mut self, state: &OnboardState, sp: &OnboardSetpoint, dt_s: f64) -> MotorCommands;
    /// The law's native rate, Hz (the firmware runs Mellinger at 500 Hz).
    fn rate_hz(&self) -> f64;
}
