//! The vehicle description: one small TOML file that `import`, `train`'s prior and flight check
//! and `score` read, so a vehicle other than the CF2X is described once.
//!
//! ```toml
//! name = "crazyflie-2.1-brushless"
//! mass_kg = 0.045
//! gravity_m_s2 = 9.81
//! inertia_kg_m2 = [2.3951e-5, 2.3951e-5, 3.2347e-5]
//! arm_xy_m = 0.0353            # rotor offset along each body axis: rotors at (±a, ±a)
//! kf_n_per_rad_s2 = 3.7178e-8  # thrust per squared rotor speed
//! km_nm_per_rad_s2 = 7.728e-11 # reaction torque per squared rotor speed
//! thrust_to_weight = 2.0       # top rotor speed: all four carry this many weights
//! motor_tau_s = 0.03           # optional first-order motor time constant
//! ```
//!
//! The rotor layout is the X of [`crate::sim::plant`]: rotor 1 front-right, 2 back-right,
//! 3 back-left, 4 front-left (body x forward, y left, z up), reaction-torque signs −, +, −, +.
//! Every key is required except `name`, `gravity_m_s2` (9.8) and `motor_tau_s`; unknown keys
//! are an error. `cf2x` names the built-in CF2X ([`VehicleParams::cf2x`]) wherever a file is
//! asked for.

use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::sim::plant::VehicleParams;

/// rpm per rad/s.
pub const RPM_PER_RAD_S: f64 = 60.0 / (2.0 * std::f64::consts::PI);

fn default_gravity() -> f64 {
    9.8
}

/// A vehicle description file's contents (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleFile {
    /// Free-text name.
    #[serde(default)]
    pub name: Option<String>,
    /// Mass (kg).
    pub mass_kg: f64,
    /// Gravity (m/s²).
    #[serde(default = "default_gravity")]
    pub gravity_m_s2: f64,
    /// diag(J) (kg·m²).
    pub inertia_kg_m2: [f64; 3],
    /// Rotor offset along each body axis (m).
    pub arm_xy_m: f64,
    /// Thrust coefficient k_F (N per (rad/s)²).
    pub kf_n_per_rad_s2: f64,
    /// Reaction-torque coefficient k_M (N·m per (rad/s)²).
    pub km_nm_per_rad_s2: f64,
    /// Top total thrust over weight.
    pub thrust_to_weight: f64,
    /// First-order motor time constant (s), when known.
    #[serde(default)]
    pub motor_tau_s: Option<f64>,
}

impl VehicleFile {
    /// The built-in CF2X.
    pub fn cf2x() -> Self {
        let p = VehicleParams::cf2x();
        let per_rad = RPM_PER_RAD_S * RPM_PER_RAD_S;
        Self {
            name: Some("cf2x".into()),
            mass_kg: p.mass_kg,
            gravity_m_s2: p.gravity_m_s2,
            inertia_kg_m2: p.inertia_kg_m2,
            arm_xy_m: p.arm_xy_m,
            kf_n_per_rad_s2: p.kf_n_per_rpm2 * per_rad,
            km_nm_per_rad_s2: p.km_nm_per_rpm2 * per_rad,
            thrust_to_weight: p.thrust_to_weight,
            motor_tau_s: None,
        }
    }

    /// Parses and checks a description (`what` names it in errors).
    ///
    /// # Errors
    /// TOML errors (with the key), and any non-positive or non-finite constant, by name.
    pub fn from_toml_str(text: &str, what: &str) -> Result<Self> {
        let v: Self = toml::from_str(text).with_context(|| format!("vehicle `{what}`"))?;
        v.check().with_context(|| format!("vehicle `{what}`"))?;
        Ok(v)
    }

    /// Reads `arg`: a file path, or `cf2x` for the built-in CF2X.
    ///
    /// # Errors
    /// An unreadable file, or [`VehicleFile::from_toml_str`]'s errors.
    pub fn load(arg: &Path) -> Result<Self> {
        if arg.as_os_str() == "cf2x" {
            return Ok(Self::cf2x());
        }
        let text = std::fs::read_to_string(arg)
            .with_context(|| format!("cannot read vehicle description `{}`", arg.display()))?;
        Self::from_toml_str(&text, &arg.display().to_string())
    }

    /// Every constant positive and finite (`motor_tau_s` ≥ 0), thrust-to-weight above 1.
    ///
    /// # Errors
    /// The first bad key, by name.
    pub fn check(&self) -> Result<()> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        let named = [
            ("mass_kg", self.mass_kg),
            ("gravity_m_s2", self.gravity_m_s2),
            ("inertia_kg_m2[0]", self.inertia_kg_m2[0]),
            ("inertia_kg_m2[1]", self.inertia_kg_m2[1]),
            ("inertia_kg_m2[2]", self.inertia_kg_m2[2]),
            ("arm_xy_m", self.arm_xy_m),
            ("kf_n_per_rad_s2", self.kf_n_per_rad_s2),
            ("km_nm_per_rad_s2", self.km_nm_per_rad_s2),
        ];
        for (k, x) in named {
            if !pos(x) {
                bail!("`{k}` must be positive and finite, got {x}");
            }
        }
        if !(self.thrust_to_weight.is_finite() && self.thrust_to_weight > 1.0) {
            bail!(
                "`thrust_to_weight` must be above 1 (the vehicle must lift itself), got {}",
                self.thrust_to_weight
            );
        }
        if self
            .motor_tau_s
            .is_some_and(|t| !(t.is_finite() && t >= 0.0))
        {
            bail!("`motor_tau_s` must be ≥ 0 s");
        }
        Ok(())
    }

    /// The plant parameters: this vehicle's constants, the CF2X's for what the file does not
    /// describe (propeller radius, drag and ground-effect coefficients).
    pub fn params(&self) -> VehicleParams {
        let per_rad = RPM_PER_RAD_S * RPM_PER_RAD_S;
        VehicleParams {
            mass_kg: self.mass_kg,
            gravity_m_s2: self.gravity_m_s2,
            inertia_kg_m2: self.inertia_kg_m2,
            arm_xy_m: self.arm_xy_m,
            kf_n_per_rpm2: self.kf_n_per_rad_s2 / per_rad,
            km_nm_per_rpm2: self.km_nm_per_rad_s2 / per_rad,
            thrust_to_weight: self.thrust_to_weight,
            ..VehicleParams::cf2x()
        }
    }

    /// The realized wrench [f; τx; τy; τz] (N, N·m) of measured rotor speeds (rad/s).
    pub fn wrench_of_rotor_speeds(&self, w_rad_s: [f64; 4]) -> [f64; 4] {
        let rpm_sq = w_rad_s.map(|w| (w * RPM_PER_RAD_S).powi(2));
        self.params().wrench_of_rpm_squared(rpm_sq)
    }

    /// The top rotor speed (rad/s).
    pub fn max_rotor_speed_rad_s(&self) -> f64 {
        self.params().max_rpm() / RPM_PER_RAD_S
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cf2x_round_trips_through_the_file_units() {
        let p = VehicleFile::cf2x().params();
        let c = VehicleParams::cf2x();
        assert!((p.kf_n_per_rpm2 / c.kf_n_per_rpm2 - 1.0).abs() < 1e-12);
        assert!((p.km_nm_per_rpm2 / c.km_nm_per_rpm2 - 1.0).abs() < 1e-12);
        assert!((p.max_rpm() / c.max_rpm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bad_files_name_the_key() {
        let good = "mass_kg = 0.045\ninertia_kg_m2 = [2.4e-5, 2.4e-5, 3.2e-5]\narm_xy_m = 0.0353\n\
                    kf_n_per_rad_s2 = 3.7e-8\nkm_nm_per_rad_s2 = 7.7e-11\nthrust_to_weight = 2.0\n";
        let v = VehicleFile::from_toml_str(good, "t").unwrap();
        assert_eq!(v.gravity_m_s2, 9.8);
        let e = VehicleFile::from_toml_str(&good.replace("0.0353", "-1.0"), "t").unwrap_err();
        assert!(format!("{e:#}").contains("arm_xy_m"), "{e:#}");
        let e =
            VehicleFile::from_toml_str(&good.replace("mass_kg = 0.045\n", ""), "t").unwrap_err();
        assert!(format!("{e:#}").contains("mass_kg"), "{e:#}");
        let e = VehicleFile::from_toml_str(&format!("{good}colour = 1\n"), "t").unwrap_err();
        assert!(format!("{e:#}").contains("colour"), "{e:#}");
        // Hover: four rotors at Ω carry m g, and the thrust row of the wrench says so.
        let w = (v.mass_kg * v.gravity_m_s2 / (4.0 * v.kf_n_per_rad_s2)).sqrt();
        let u = v.wrench_of_rotor_speeds([w; 4]);
        assert!((u[0] / (v.mass_kg * v.gravity_m_s2) - 1.0).abs() < 1e-12);
        assert!(u[1].abs() < 1e-15 && u[2].abs() < 1e-15 && u[3].abs() < 1e-15);
    }
}
