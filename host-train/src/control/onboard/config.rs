//! The Mellinger controller's gains and the onboard configuration (JSON).

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Bitcraze's Mellinger gains, in the firmware's own units (position gains in N/m, N/(m/s),
/// N/(m·s); attitude gains in command counts per unit of the rotation error and rad/s).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MellingerGains {
    /// Horizontal position P, N/m.
    pub kp_xy: f64,
    /// Horizontal velocity D, N/(m/s).
    pub kd_xy: f64,
    /// Horizontal position I, N/(m·s).
    pub ki_xy: f64,
    /// Clamp of the horizontal position integral, m·s.
    pub i_range_xy: f64,
    /// Vertical position P, N/m.
    pub kp_z: f64,
    /// Vertical velocity D, N/(m/s).
    pub kd_z: f64,
    /// Vertical position I, N/(m·s).
    pub ki_z: f64,
    /// Clamp of the vertical position integral, m·s.
    pub i_range_z: f64,
    /// Roll/pitch attitude P, counts per unit rotation error.
    pub kr_xy: f64,
    /// Roll/pitch rate D, counts per rad/s.
    pub kw_xy: f64,
    /// Roll/pitch attitude I.
    pub ki_m_xy: f64,
    /// Clamp of the roll/pitch attitude integral.
    pub i_range_m_xy: f64,
    /// Yaw attitude P, counts per unit rotation error.
    pub kr_z: f64,
    /// Yaw rate D, counts per rad/s.
    pub kw_z: f64,
    /// Yaw attitude I.
    pub ki_m_z: f64,
    /// Clamp of the yaw attitude integral.
    pub i_range_m_z: f64,
    /// Roll/pitch angular-acceleration damping (the derivative of the rate error).
    pub kd_omega_rp: f64,
}

impl MellingerGains {
    /// The firmware's defaults, tag 2025.09 (`controller_mellinger.c`, `g_self`).
    pub fn cf21bl_2025_09() -> Self {
        Self {
            kp_xy: 0.4,
            kd_xy: 0.2,
            ki_xy: 0.05,
            i_range_xy: 2.0,
            kp_z: 1.25,
            kd_z: 0.4,
            ki_z: 0.05,
            i_range_z: 0.4,
            kr_xy: 70000.0,
            kw_xy: 20000.0,
            ki_m_xy: 0.0,
            i_range_m_xy: 1.0,
            kr_z: 60000.0,
            kw_z: 12000.0,
            ki_m_z: 500.0,
            i_range_m_z: 1500.0,
            kd_omega_rp: 200.0,
        }
    }
}

impl Default for MellingerGains {
    fn default() -> Self {
        Self::cf21bl_2025_09()
    }
}

/// Everything the onboard replay needs beyond the gains.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct OnboardConfig {
    /// The Mellinger gains.
    pub gains: MellingerGains,
    /// The controller's mass parameter, kg (`CF_MASS` of cf21bl: 0.0393).
    pub mass_kg: f64,
    /// Force (N) to PWM count stretch (`massThrust`: 132000).
    pub mass_thrust: f64,
    /// Gravity the controller assumes, m/s² (`GRAVITY_MAGNITUDE`: 9.81).
    pub gravity_m_s2: f64,
    /// The motors' idle floor as a normalized command (`powerDist.idleThrust` / 65535; the
    /// benchmark flights show 10000 / 65535, the cf21bl default is 7000).
    pub idle_cmd: f64,
    /// Constant offsets added to the controller's roll, pitch, yaw commands (PWM counts) before
    /// the power distribution; zero in the firmware, identified by `onboard --fit`.
    pub roll_trim: f64,
    /// Pitch command offset, counts.
    pub pitch_trim: f64,
    /// Yaw command offset, counts.
    pub yaw_trim: f64,
    /// The rate the controller runs at, Hz (`ATTITUDE_RATE`: 500).
    pub rate_hz: f64,
    /// A pure delay of the commands behind the state, s, applied by the replay (0 in the
    /// firmware; identified by `onboard --fit`).
    pub cmd_delay_s: f64,
    /// Emulate the firmware's integer truncations (int16 roll/pitch/yaw, int32 motor counts).
    pub integer_outputs: bool,
}

impl OnboardConfig {
    /// The firmware defaults for the cf21bl with the benchmark's idle floor (10000 counts).
    pub fn cf21bl_2025_09() -> Self {
        Self {
            gains: MellingerGains::cf21bl_2025_09(),
            mass_kg: 0.0393,
            mass_thrust: 132000.0,
            gravity_m_s2: 9.81,
            idle_cmd: 10000.0 / 65535.0,
            roll_trim: 0.0,
            pitch_trim: 0.0,
            yaw_trim: 0.0,
            rate_hz: 500.0,
            cmd_delay_s: 0.0,
            integer_outputs: true,
        }
    }

    /// Reads a configuration from JSON (missing fields take the defaults).
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading onboard config {}", path.display()))?;
        let cfg: Self = serde_json::from_str(&text)
            .with_context(|| format!("parsing onboard config {}", path.display()))?;
        cfg.validate()
            .with_context(|| format!("onboard config {}", path.display()))?;
        Ok(cfg)
    }

    /// Writes the configuration as JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::io::write_json_atomic(path, self)
    }

    /// Rejects values the controller cannot run with.
    pub fn validate(&self) -> Result<()> {
        anyhow::ensure!(
            self.rate_hz.is_finite() && self.rate_hz > 0.0,
            "rate_hz must be positive, got {}",
            self.rate_hz
        );
        anyhow::ensure!(
            self.mass_kg.is_finite() && self.mass_kg > 0.0,
            "mass_kg must be positive, got {}",
            self.mass_kg
        );
        anyhow::ensure!(
            (0.0..1.0).contains(&self.idle_cmd),
            "idle_cmd must be in [0, 1), got {}",
            self.idle_cmd
        );
        anyhow::ensure!(
            self.cmd_delay_s.is_finite() && self.cmd_delay_s >= 0.0,
            "cmd_delay_s must be >= 0, got {}",
            self.cmd_delay_s
        );
        Ok(())
    }
}

impl Default for OnboardConfig {
    fn default() -> Self {
        Self::cf21bl_2025_09()
    }
}
