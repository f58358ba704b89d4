//! Reference generation: the setpoint a trajectory gives the controller at one instant.

use nalgebra::Vector3;

/// A flat-output setpoint: desired position and its derivatives up to jerk (world frame), and the
/// desired yaw. What a trajectory generator or a companion computer sends each tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// Desired position p* (m, world).
    pub p_m: Vector3<f32>,
    /// Desired velocity ṗ* (m/s, world).
    pub v_m_s: Vector3<f32>,
    /// Desired acceleration p̈* (m/s², world).
    pub a_m_s2: Vector3<f32>,
    /// Desired jerk p⃛* (m/s³, world).
    pub j_m_s3: Vector3<f32>,
    /// Desired yaw ψ* (rad), about world z.
    pub yaw_rad: f32,
    /// Desired yaw rate ψ̇* (rad/s).
    pub yaw_rate_rad_s: f32,
}

impl Default for Setpoint {
    fn default() -> Self {
        Self::hover(Vector3::zeros(), 0.0)
    }
}

impl Setpoint {
    /// Hold position `p_m` with yaw `yaw_rad`.
    pub fn hover(p_m: Vector3<f32>, yaw_rad: f32) -> Self {
        Self {
            p_m,
            v_m_s: Vector3::zeros(),
            a_m_s2: Vector3::zeros(),
            j_m_s3: Vector3::zeros(),
            yaw_rad,
            yaw_rate_rad_s: 0.0,
        }
    }

    /// True if every component is finite.
    pub fn is_finite(&self) -> bool {
        [self.p_m, self.v_m_s, self.a_m_s2, self.j_m_s3]
            .iter()
            .all(|v| v.iter().all(|x| x.is_finite()))
            && self.yaw_rad.is_finite()
            && self.yaw_rate_rad_s.is_finite()
    }
}
