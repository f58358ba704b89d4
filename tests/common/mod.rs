//! Shared proptest strategies and reference helpers for the integration tests.
//!
//! Rotations are built in f64 (Shoemake's uniform unit quaternion, then the closed-form matrix)
//! and only then rounded to f32, so the f32 inputs are as orthonormal as f32 allows and the f64
//! originals can serve as independent references.
#![allow(dead_code)] // each test binary uses a different subset

use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;
use std::f64::consts::PI;

/// A uniformly distributed rotation (Haar measure on SO(3)), f64.
pub fn rotation3_f64() -> impl Strategy<Value = Matrix3<f64>> {
    (0.0..1.0f64, 0.0..1.0f64, 0.0..1.0f64).prop_map(|(u1, u2, u3)| {
        // Shoemake, "Uniform random rotations", Graphics Gems III.
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        let (t1, t2) = (2.0 * PI * u2, 2.0 * PI * u3);
        let (w, x, y, z) = (b * t2.cos(), a * t1.sin(), a * t1.cos(), b * t2.sin());
        quat_to_matrix(w, x, y, z)
    })
}

/// A uniformly distributed rotation, rounded to f32.
pub fn rotation3() -> impl Strategy<Value = Matrix3<f32>> {
    rotation3_f64().prop_map(|r| r.cast::<f32>())
}

/// A unit vector, uniform on the sphere, f64.
pub fn unit_vec3_f64() -> impl Strategy<Value = Vector3<f64>> {
    (-1.0..=1.0f64, 0.0..(2.0 * PI)).prop_map(|(z, phi)| {
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vector3::new(r * phi.cos(), r * phi.sin(), z)
    })
}

/// A vector with each component in `[-max, max]`.
pub fn vec3(max: f32) -> impl Strategy<Value = Vector3<f32>> {
    (-max..=max, -max..=max, -max..=max).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

/// A rotation vector φ = θ a with uniform axis and angle θ in `angles` (rad), f64.
pub fn rotvec_f64(angles: core::ops::RangeInclusive<f64>) -> impl Strategy<Value = Vector3<f64>> {
    (unit_vec3_f64(), angles).prop_map(|(axis, theta)| axis * theta)
}

/// Unit quaternion (w, x, y, z) → rotation matrix, f64.
pub fn quat_to_matrix(w: f64, x: f64, y: f64, z: f64) -> Matrix3<f64> {
    Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// Reference exponential map in f64 via the axis–angle quaternion (independent of Rodrigues).
pub fn exp_f64(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    if theta == 0.0 {
        return Matrix3::identity();
    }
    let a = phi / theta;
    let (s, c) = ((0.5 * theta).sin(), (0.5 * theta).cos());
    quat_to_matrix(c, s * a.x, s * a.y, s * a.z)
}

/// Frobenius norm of RᵀR − I.
pub fn orthonormality_error(r: &Matrix3<f32>) -> f32 {
    (r.transpose() * r - Matrix3::identity()).norm()
}

/// Deterministic SplitMix64, for bulk random data where proptest shrinking is of no use.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [-1, 1).
    pub fn symmetric(&mut self) -> f32 {
        ((self.next_u64() >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
}

/// The independent blob encoder of `tests/blob.rs` and `tests/blob_format.rs`.
pub mod blob_ref;
