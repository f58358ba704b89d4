//! The vehicle's physical constants.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::{ROTOR_XY_SIGN, ROTOR_YAW_SIGN};

/// Physical constants of the vehicle (defaults: the CF2X of gym-pybullet-drones).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VehicleParams {
    /// Mass m (kg).
    pub mass_kg: f64,
    /// Gravitational acceleration g (m/s²).
    pub gravity_m_s2: f64,
    /// Principal moments of inertia diag(J) (kg·m²).
    pub inertia_kg_m2: [f64; 3],
    /// Rotor offset along each body axis in the X layout (m): props at (±a, ±a).
    pub arm_xy_m: f64,
    /// Thrust coefficient kf (N/rpm²).
    pub kf_n_per_rpm2: f64,
    /// Reaction-torque coefficient km (N·m/rpm²).
    pub km_nm_per_rpm2: f64,
    /// Maximum total thrust over weight (dimensionless); sets the rotor speed limit.
    pub thrust_to_weight: f64,
    /// Propeller radius (m), for the ground-effect model.
    pub prop_radius_m: f64,
    /// Rotor drag coefficients (x, y, z) of gym-pybullet-drones, N per (m/s · rad/s).
    pub drag_coeff: [f64; 3],
    /// Ground-effect coefficient of gym-pybullet-drones (dimensionless).
    pub ground_effect_coeff: f64,
    /// The vehicle's own rotor efficiencies (worn or chipped props, a weak motor): rotor i makes
    /// this share of its nominal thrust and reaction torque, at all times, on top of any
    /// `Disturbance::rotor_efficiency` (the two multiply). All 1 for the CF2X.
    #[serde(default = "unit_efficiency")]
    pub rotor_efficiency: [f64; 4],
}

fn unit_efficiency() -> [f64; 4] {
    [1.0; 4]
}

impl Default for VehicleParams {
    fn default() -> Self {
        Self::cf2x()
    }
}

impl VehicleParams {
    /// The Crazyflie CF2X constants (docs/design.md, "The vehicle").
    pub fn cf2x() -> Self {
        Self {
            mass_kg: 0.027,
            gravity_m_s2: 9.8,
            inertia_kg_m2: [1.4e-5, 1.4e-5, 2.17e-5],
            arm_xy_m: 0.028,
            kf_n_per_rpm2: 3.16e-10,
            km_nm_per_rpm2: 7.94e-12,
            thrust_to_weight: 2.25,
            prop_radius_m: 2.31348e-2,
            drag_coeff: [9.1785e-7, 9.1785e-7, 10.311e-7],
            ground_effect_coeff: 11.36859,
            rotor_efficiency: [1.0; 4],
        }
    }

    /// Weight m·g (N).
    pub fn weight_n(&self) -> f64 {
        self.mass_kg * self.gravity_m_s2
    }

    /// Inertia matrix J (kg·m²).
    pub fn inertia(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::from(self.inertia_kg_m2))
    }

    /// Maximum rotor speed (rpm), from the thrust-to-weight ratio (≈ 21,700 rpm for the CF2X).
    pub fn max_rpm(&self) -> f64 {
        (self.thrust_to_weight * self.weight_n() / (4.0 * self.kf_n_per_rpm2)).sqrt()
    }

    /// Rotor speed (rpm) at which four nominal rotors carry the weight (≈ 14,470 rpm).
    pub fn hover_rpm(&self) -> f64 {
        (self.weight_n() / (4.0 * self.kf_n_per_rpm2)).sqrt()
    }

    /// Clamp a rotor command to `[0, max_rpm]` (non-finite entries become 0).
    pub fn clamp_rpm(&self, rpm: [f64; 4]) -> [f64; 4] {
        let max = self.max_rpm();
        rpm.map(|r| {
            if r.is_finite() {
                r.clamp(0.0, max)
            } else {
                0.0
            }
        })
    }

    /// Nominal wrench `u = [f; τx; τy; τz]` (N, N·m, N·m, N·m) of a rotor command (rpm),
    /// after clamping, with all efficiencies 1 and no optional effects.
    pub fn nominal_wrench(&self, rpm: [f64; 4]) -> [f64; 4] {
        let rpm = self.clamp_rpm(rpm);
        self.wrench_of_rpm_squared(rpm.map(|r| r * r))
    }

    /// Nominal wrench `u = [f; τx; τy; τz]` of squared rotor speeds (rpm², not clamped): linear
    /// in them, so it also gives the wrench of a time average of ωᵢ².
    pub fn wrench_of_rpm_squared(&self, rpm_sq: [f64; 4]) -> [f64; 4] {
        let a = self.arm_xy_m;
        let mut u = [0.0; 4];
        for (i, &s) in rpm_sq.iter().enumerate() {
            let t = self.kf_n_per_rpm2 * s;
            u[0] += t;
            u[1] += ROTOR_XY_SIGN[i][1] * a * t;
            u[2] -= ROTOR_XY_SIGN[i][0] * a * t;
            u[3] += ROTOR_YAW_SIGN[i] * self.km_nm_per_rpm2 * s;
        }
        u
    }

    /// Unsaturated inverse of [`VehicleParams::nominal_wrench`]: the squared rotor speeds (rpm²)
    /// that produce `u = [f; τx; τy; τz]` exactly (entries may be negative or above the limit).
    pub fn wrench_to_rpm_squared(&self, u: [f64; 4]) -> [f64; 4] {
        let (kf, km, a) = (self.kf_n_per_rpm2, self.km_nm_per_rpm2, self.arm_xy_m);
        let mut s = [0.0; 4];
        for (i, si) in s.iter_mut().enumerate() {
            *si = 0.25
                * (u[0] / kf + ROTOR_XY_SIGN[i][1] * u[1] / (a * kf)
                    - ROTOR_XY_SIGN[i][0] * u[2] / (a * kf)
                    + ROTOR_YAW_SIGN[i] * u[3] / km);
        }
        s
    }

    /// Wrench → rotor speeds (rpm) through the nominal mixer inverse, with saturation that keeps
    /// attitude authority: yaw torque is given up first, then roll/pitch torque is scaled down, and
    /// the collective thrust is shifted last so that every rotor stays in `[0, max_rpm]`.
    /// Exact (equal to the unsaturated inverse) whenever that is feasible.
    pub fn wrench_to_rpm(&self, u: [f64; 4]) -> [f64; 4] {
        let u = u.map(|x| if x.is_finite() { x } else { 0.0 });
        let smax = self.max_rpm().powi(2);
        let base = (u[0] / (4.0 * self.kf_n_per_rpm2)).max(0.0);
        let rp = self.wrench_to_rpm_squared([0.0, u[1], u[2], 0.0]);
        let yw = self.wrench_to_rpm_squared([0.0, 0.0, 0.0, u[3]]);
        let range = |d: &[f64; 4]| {
            let mx = d.iter().cloned().fold(f64::MIN, f64::max);
            let mn = d.iter().cloned().fold(f64::MAX, f64::min);
            mx - mn
        };
        let comb = |k: f64| -> [f64; 4] { core::array::from_fn(|i| rp[i] + k * yw[i]) };
        let d = if range(&rp) > smax {
            let k = smax / range(&rp);
            rp.map(|x| x * k)
        } else if range(&comb(1.0)) > smax {
            // Largest yaw share that fits, by bisection.
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if range(&comb(mid)) > smax {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            comb(lo)
        } else {
            comb(1.0)
        };
        let mx = d.iter().cloned().fold(f64::MIN, f64::max);
        let mn = d.iter().cloned().fold(f64::MAX, f64::min);
        let lo = -mn;
        let hi = smax - mx;
        let b = if lo <= hi {
            base.clamp(lo, hi)
        } else {
            0.5 * (lo + hi)
        };
        d.map(|x| (b + x).clamp(0.0, smax).sqrt())
    }
}
