//! The vehicle state in the paper's convention.

use nalgebra::{Matrix3, Vector3};

/// The rigid-body state x = (q, ζ): position and attitude, body-frame velocities (paper Sec. 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State {
    /// Position p of the body origin in the world frame (m), world z up.
    pub p_m: Vector3<f32>,
    /// Attitude R, mapping body-frame vectors to the world frame (body x forward, z up).
    pub rot: Matrix3<f32>,
    /// Linear velocity v in the body frame (m/s).
    pub v_body_m_s: Vector3<f32>,
    /// Angular velocity ω in the body frame (rad/s).
    pub w_body_rad_s: Vector3<f32>,
}

impl Default for State {
    fn default() -> Self {
        Self {
            p_m: Vector3::zeros(),
            rot: Matrix3::identity(),
            v_body_m_s: Vector3::zeros(),
            w_body_rad_s: Vector3::zeros(),
        }
    }
}

impl State {
    /// True if every component is finite.
    pub fn is_finite(&self) -> bool {
        crate::fpu::all_finite(
            self.p_m
                .iter()
                .chain(self.rot.iter())
                .chain(self.v_body_m_s.iter())
                .chain(self.w_body_rad_s.iter())
                .copied(),
        )
    }

    /// The generalized coordinates q = [p; r₁; r₂; r₃] with rᵢ the rows of R (paper Sec. 2).
    pub fn q(&self) -> [f32; 12] {
        let r = &self.rot;
        [
            self.p_m.x, self.p_m.y, self.p_m.z, r.m11, r.m12, r.m13, r.m21, r.m22, r.m23, r.m31,
            r.m32, r.m33,
        ]
    }
}
