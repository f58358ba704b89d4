//! Rotation helpers in f64: roll-pitch-yaw, hat and vee, the exponential map.

use nalgebra::{Matrix3, Vector3};

/// Roll, pitch, yaw (rad) of a rotation matrix, Z-Y-X convention (as pybullet's Euler angles).
pub fn rpy_of(r: &Matrix3<f64>) -> Vector3<f64> {
    let roll = r[(2, 1)].atan2(r[(2, 2)]);
    let pitch = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    Vector3::new(roll, pitch, yaw)
}

/// Rotation from roll, pitch, yaw (rad), Z-Y-X convention: R = Rz(yaw) Ry(pitch) Rx(roll).
pub fn rot_from_rpy(rpy: Vector3<f64>) -> Matrix3<f64> {
    rot_z(rpy.z) * so3_exp(&Vector3::new(0.0, rpy.y, 0.0)) * so3_exp(&Vector3::new(rpy.x, 0.0, 0.0))
}

/// Rotation about world z by `yaw_rad`.
pub fn rot_z(yaw_rad: f64) -> Matrix3<f64> {
    let (s, c) = yaw_rad.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Skew-symmetric matrix x̂ with x̂ y = x × y.
pub fn hat(x: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -x.z, x.y, x.z, 0.0, -x.x, -x.y, x.x, 0.0)
}

/// Inverse of [`hat`] on the skew part of `m`: vee(m) = ½ (m − mᵀ)^∨.
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    0.5 * Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    )
}

/// Exponential map so(3) → SO(3) (Rodrigues), accurate for small angles.
pub fn so3_exp(theta: &Vector3<f64>) -> Matrix3<f64> {
    let a2 = theta.norm_squared();
    let (sa, ca) = if a2 < 1e-8 {
        (
            1.0 - a2 / 6.0 + a2 * a2 / 120.0,
            0.5 - a2 / 24.0 + a2 * a2 / 720.0,
        )
    } else {
        let a = a2.sqrt();
        (a.sin() / a, (1.0 - a.cos()) / a2)
    };
    let k = hat(theta);
    Matrix3::identity() + k * sa + k * k * ca
}
