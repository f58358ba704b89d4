//! What acts on the vehicle besides its rotors: state noise, the optional physical effects, a
//! residual response, and the disturbance (wind, rotor efficiency, its variations).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Optional measurement noise: zero-mean Gaussian, standard deviations per quantity. Applied to
/// the state the controller sees, never to the simulated truth.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StateNoise {
    /// Position noise σ (m).
    pub pos_m: f64,
    /// Body linear-velocity noise σ (m/s).
    pub vel_m_s: f64,
    /// Attitude noise σ (rad), applied as a random rotation about each body axis.
    pub att_rad: f64,
    /// Body angular-rate noise σ (rad/s).
    pub rate_rad_s: f64,
    /// Accelerometer noise σ (m/s², per axis), on `Plant::accelerometer`'s reading.
    pub acc_m_s2: f64,
}

impl StateNoise {
    /// True if every σ of the state (not the accelerometer) is zero.
    pub fn is_off(&self) -> bool {
        self.pos_m == 0.0 && self.vel_m_s == 0.0 && self.att_rad == 0.0 && self.rate_rad_s == 0.0
    }
}

/// Optional physical effects; all off by default.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Effects {
    /// Rotor drag of gym-pybullet-drones: body force `−c ⊙ v · Σ ωᵢ` (ωᵢ in rad/s).
    pub rotor_drag: bool,
    /// Ground effect of gym-pybullet-drones: extra thrust `kf ω² C (r_p / 4h)²` per rotor at
    /// height h (clipped below as in gym-pybullet-drones).
    pub ground_effect: bool,
    /// First-order motor time constant (s); 0 turns motor lag off (rotors follow the command).
    pub motor_tau_s: f64,
    /// Added command delay (s) between the controller's output and the plant's input (the
    /// loop's, [`crate::fly::eval`]; rounded to physics steps); 0 = none.
    pub command_delay_s: f64,
    /// Command jitter (s): each tick's command is further delayed by a seeded uniform draw in
    /// [0, this] (never overtaking an earlier command); 0 = none.
    pub command_jitter_s: f64,
    /// Measurement noise on the state given to the controller.
    pub noise: StateNoise,
    /// Extra dynamics measured on a real vehicle's flights ([`Residual`]); none by default.
    pub residual: Option<Residual>,
}

/// What a real vehicle's flights show beyond the rigid body with its rotors (the measured-input
/// response that `host-train fit-response` fits on logged flights; the same fields): the rotor
/// wrench acts through first-order lags and with effective gains, and the body gets an
/// acceleration linear in the body velocity, a constant one and an angular one linear in the
/// tilt. A plant with it is the flight check's stand-in for the real vehicle: the rigid body
/// of the vehicle description plus what its logs measured, which is not the blob's model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Residual {
    /// The thrust's effective gain.
    pub thrust_gain: f64,
    /// Each body torque's effective gain (roll, pitch, yaw).
    pub torque_gain: [f64; 3],
    /// The torques' first-order lag (s).
    pub torque_lag_s: f64,
    /// Body acceleration per unit of ζ = (v (m/s), ω (rad/s)), row-major 6×6 (rows v̇, ω̇).
    pub accel_per_velocity: [[f64; 6]; 6],
    /// Constant body acceleration, v̇ (m/s²) then ω̇ (rad/s²).
    pub accel_bias: [f64; 6],
    /// The thrust's first-order lag (s).
    #[serde(default)]
    pub thrust_lag_s: f64,
    /// Body angular acceleration (rad/s²) per unit of the world vertical's body x and y
    /// components, row-major 3×2 (rows ω̇ₓ, ω̇ᵧ, ω̇_z).
    #[serde(default)]
    pub accel_per_tilt: [[f64; 2]; 3],
}

/// External disturbance: world wind force and per-rotor efficiency.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Disturbance {
    /// Wind as a world-frame specific force w (m/s²): the force on the body is m·w.
    pub wind_m_s2: [f64; 3],
    /// Time (s) from which the wind acts.
    pub wind_onset_s: f64,
    /// Rotor efficiencies δ₁..δ₄: rotor i makes δᵢ of its nominal thrust and reaction torque.
    pub rotor_efficiency: [f64; 4],
    /// Time (s) from which the efficiencies apply (before it, all rotors are nominal).
    pub efficiency_onset_s: f64,
}

impl Default for Disturbance {
    fn default() -> Self {
        Self {
            wind_m_s2: [0.0; 3],
            wind_onset_s: 0.0,
            rotor_efficiency: [1.0; 4],
            efficiency_onset_s: 0.0,
        }
    }
}

impl Disturbance {
    /// Wind specific force active at time `t_s` (m/s², world).
    pub fn wind_at(&self, t_s: f64) -> Vector3<f64> {
        if t_s >= self.wind_onset_s {
            Vector3::from(self.wind_m_s2)
        } else {
            Vector3::zeros()
        }
    }

    /// Rotor efficiencies active at time `t_s`.
    pub fn efficiency_at(&self, t_s: f64) -> [f64; 4] {
        if t_s >= self.efficiency_onset_s {
            self.rotor_efficiency
        } else {
            [1.0; 4]
        }
    }
}

/// One sinusoidal wind component: w(t) += amplitude sin(2π f t + phase).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindSine {
    /// Amplitude per world axis (m/s², specific force).
    pub amplitude_m_s2: [f64; 3],
    /// Frequency f (Hz).
    pub frequency_hz: f64,
    /// Phase (rad).
    #[serde(default)]
    pub phase_rad: f64,
}

/// One wind step: w(t) += wind_m_s2 for from_s ≤ t < until_s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindStep {
    /// Added wind (m/s², world).
    pub wind_m_s2: [f64; 3],
    /// Start (s).
    pub from_s: f64,
    /// End (s); none: to the end of the flight.
    #[serde(default)]
    pub until_s: Option<f64>,
}

/// Time-varying wind on top of [`Disturbance`]'s constant wind: a sum of sinusoids and steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WindVariation {
    /// Sinusoids.
    pub sines: Vec<WindSine>,
    /// Steps.
    pub steps: Vec<WindStep>,
}

impl WindVariation {
    /// The added wind at `t_s` (m/s², world).
    pub fn at(&self, t_s: f64) -> Vector3<f64> {
        let mut w = Vector3::zeros();
        for s in &self.sines {
            let k = (core::f64::consts::TAU * s.frequency_hz * t_s + s.phase_rad).sin();
            w += Vector3::from(s.amplitude_m_s2) * k;
        }
        for s in &self.steps {
            if t_s >= s.from_s && s.until_s.is_none_or(|u| t_s < u) {
                w += Vector3::from(s.wind_m_s2);
            }
        }
        w
    }
}
