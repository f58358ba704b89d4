//! The reference a controller tracks: [`TrajectoryPoint`], and the f64 → f32 conversions of the
//! host's setpoint and plant state into the core's.

use nalgebra::Vector3;

use crate::sim::plant::PlantState;

/// One point of a reference trajectory: the flat outputs and their derivatives (f64).
///
/// The host's f64 twin of the core's [`hamflight::Setpoint`], kept because the precision differs:
/// trajectories, the SITL plant and the f64 baselines work in f64. The conversion to the core's
/// f32 setpoint is the `From` below (and [`hamflight::State`]'s from the plant's [`PlantState`]
/// beside it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrajectoryPoint {
    /// Desired position p* (m, world).
    pub p_m: Vector3<f64>,
    /// Desired velocity ṗ* (m/s, world).
    pub v_m_s: Vector3<f64>,
    /// Desired acceleration p̈* (m/s², world).
    pub a_m_s2: Vector3<f64>,
    /// Desired jerk p⃛* (m/s³, world).
    pub j_m_s3: Vector3<f64>,
    /// Desired yaw ψ* (rad).
    pub yaw_rad: f64,
    /// Desired yaw rate ψ̇* (rad/s).
    pub yaw_rate_rad_s: f64,
}

impl TrajectoryPoint {
    /// Hold `p_m` with yaw `yaw_rad`.
    pub fn hover(p_m: Vector3<f64>, yaw_rad: f64) -> Self {
        Self {
            p_m,
            v_m_s: Vector3::zeros(),
            a_m_s2: Vector3::zeros(),
            j_m_s3: Vector3::zeros(),
            yaw_rad,
            yaw_rate_rad_s: 0.0,
        }
    }
}

/// f64 → f32, field by field: how a host setpoint becomes the core's.
impl From<&TrajectoryPoint> for hamflight::Setpoint {
    fn from(t: &TrajectoryPoint) -> Self {
        hamflight::Setpoint {
            p_m: t.p_m.cast::<f32>(),
            v_m_s: t.v_m_s.cast::<f32>(),
            a_m_s2: t.a_m_s2.cast::<f32>(),
            j_m_s3: t.j_m_s3.cast::<f32>(),
            yaw_rad: t.yaw_rad as f32,
            yaw_rate_rad_s: t.yaw_rate_rad_s as f32,
        }
    }
}

/// f64 → f32, field by field: how the plant's state becomes the core's (the one place).
impl From<&PlantState> for hamflight::State {
    fn from(s: &PlantState) -> Self {
        hamflight::State {
            p_m: s.p_m.cast::<f32>(),
            rot: s.rot.cast::<f32>(),
            v_body_m_s: s.v_body_m_s.cast::<f32>(),
            w_body_rad_s: s.w_body_rad_s.cast::<f32>(),
        }
    }
}
