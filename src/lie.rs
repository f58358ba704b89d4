//! Lie-group math on SO(3): hat/vee, exponential and logarithm maps, geodesic distance,
//! re-orthonormalization and the paper's rotation error.
//!
//! Conventions: `R` maps body-frame vectors to the world frame; `hat(v) w = v × w`; angles in rad.
//! Every function is total (no panic) and well behaved near the identity and near a half turn.

use nalgebra::{Matrix3, Vector3};

/// Below this angle (rad) the trigonometric ratios use their Taylor series.
const SMALL_ANGLE_RAD: f32 = 1e-3;

/// The hat map ℝ³ → so(3): `hat(v) * w == v.cross(&w)`.
#[inline]
pub fn hat(v: &Vector3<f32>) -> Matrix3<f32> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The vee map so(3) → ℝ³, the inverse of [`hat`]. Takes the skew-symmetric part of `m`, so it
/// is also the projection of any 3×3 matrix onto so(3).
#[inline]
pub fn vee(m: &Matrix3<f32>) -> Vector3<f32> {
    Vector3::new(
        0.5 * (m.m32 - m.m23),
        0.5 * (m.m13 - m.m31),
        0.5 * (m.m21 - m.m12),
    )
}

/// The exponential map so(3) → SO(3) (Rodrigues' formula) of the rotation vector `phi` (rad):
/// a rotation by `|phi|` about `phi / |phi|`.
pub fn exp(phi: &Vector3<f32>) -> Matrix3<f32> {
    let theta2 = phi.norm_squared();
    let theta = libm::sqrtf(theta2);
    // a = sin θ / θ, b = (1 − cos θ) / θ²
    let (a, b) = if theta < SMALL_ANGLE_RAD {
        (1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0)
    } else {
        let (s, c) = (libm::sinf(theta), libm::cosf(theta));
        (s / theta, (1.0 - c) / theta2)
    };
    let k = hat(phi);
    Matrix3::identity() + k * a + k * k * b
}

/// The logarithm map SO(3) → so(3), as a rotation vector with angle in [0, π].
///
/// The angle comes from `atan2(|s|, c)` with `s = vee(R)` and `c = (tr R − 1)/2`, which keeps full
/// f32 precision at both ends; past a quarter turn the axis is read from the symmetric part of `R`,
/// which stays well conditioned up to and at θ = π (where the skew part vanishes). At exactly π
/// both ±axis are valid; the sign follows the larger positive axis component.
pub fn log(r: &Matrix3<f32>) -> Vector3<f32> {
    let s = vee(r);
    let c = 0.5 * (r.trace() - 1.0);
    let sin_theta = s.norm();
    let theta = libm::atan2f(sin_theta, c);
    if !theta.is_finite() {
        return Vector3::zeros();
    }
    if c > 0.0 {
        // θ < π/2: θ / sin θ is bounded and smooth.
        let scale = if theta < SMALL_ANGLE_RAD {
            1.0 + theta * theta / 6.0
        } else {
            theta / sin_theta
        };
        return s * scale;
    }
    // θ ≥ π/2: (R + Rᵀ)/2 = c I + (1 − c) a aᵀ.
    let one_minus_c = 1.0 - c; // in [1, 2]
    let d = Vector3::new(
        (r.m11 - c) / one_minus_c,
        (r.m22 - c) / one_minus_c,
        (r.m33 - c) / one_minus_c,
    );
    let sym = |x: f32, y: f32| 0.5 * (x + y) / one_minus_c;
    let axis = if d.x >= d.y && d.x >= d.z {
        let ax = libm::sqrtf(d.x.max(0.0));
        Vector3::new(ax, sym(r.m12, r.m21) / ax, sym(r.m13, r.m31) / ax)
    } else if d.y >= d.z {
        let ay = libm::sqrtf(d.y.max(0.0));
        Vector3::new(sym(r.m12, r.m21) / ay, ay, sym(r.m23, r.m32) / ay)
    } else {
        let az = libm::sqrtf(d.z.max(0.0));
        Vector3::new(sym(r.m13, r.m31) / az, sym(r.m23, r.m32) / az, az)
    };
    let n = axis.norm();
    if !n.is_finite() || n <= 0.0 {
        return Vector3::zeros();
    }
    let mut axis = axis / n;
    if axis.dot(&s) < 0.0 {
        axis = -axis;
    }
    axis * theta
}

/// Geodesic distance on SO(3): the angle (rad, in [0, π]) of the rotation `r_aᵀ r_b`.
pub fn geodesic_distance(r_a: &Matrix3<f32>, r_b: &Matrix3<f32>) -> f32 {
    log(&(r_a.transpose() * r_b)).norm()
}

/// Re-orthonormalizes a nearly-rotation matrix by Gram–Schmidt on its columns, keeping the
/// direction of the first column and the plane of the first two; the third is their cross
/// product, so the result is right-handed. `None` if `r` is non-finite or (nearly) rank-deficient.
pub fn orthonormalize(r: &Matrix3<f32>) -> Option<Matrix3<f32>> {
    let c0 = r.column(0).into_owned();
    let c1 = r.column(1).into_owned();
    let n0 = c0.norm();
    if !n0.is_finite() || n0 <= 1e-6 {
        return None;
    }
    let x = c0 / n0;
    let y = c1 - x * x.dot(&c1);
    let n1 = y.norm();
    if !n1.is_finite() || n1 <= 1e-6 {
        return None;
    }
    let y = y / n1;
    let z = x.cross(&y);
    Some(Matrix3::from_columns(&[x, y, z]))
}

/// The attitude matrix of the quaternion `q = [w, x, y, z]` (Hamilton convention, scalar first,
/// body → world like R), in the homogeneous form
/// R = (w² − |u|²) I + 2 u uᵀ + 2 w \[u\]×, with u = (x, y, z).
///
/// This is the one place where a quaternion becomes the core's R (the firmware's link carries the
/// attitude as one). It does not normalize: for |q| = 1 + ε the result is (1 + ε)² times a
/// rotation, so RᵀR = |q|⁴ I and ‖RᵀR − I‖_F = √3 (|q|⁴ − 1) ≈ 4√3 ε, which the controller's
/// rotation check ([`crate::control::is_rotation`], [`crate::ROTATION_TOLERANCE`] = 1e-3) refuses
/// beyond |ε| ≈ 1.4e-4. A non-finite q gives a non-finite R, refused by the same check. So a
/// malformed quaternion is a `bad_state` (motors off), never a panic and never silently repaired.
pub fn rot_from_quat(q: &[f32; 4]) -> Matrix3<f32> {
    let [w, x, y, z] = *q;
    let (ww, xx, yy, zz) = (w * w, x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    Matrix3::new(
        ww + xx - yy - zz,
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        ww - xx + yy - zz,
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        ww - xx - yy + zz,
    )
}

/// The unit quaternion `[w, x, y, z]` (w ≥ 0) of the rotation `r`, the inverse of
/// [`rot_from_quat`] on rotations: Shepperd's method (the largest of w, x, y, z is taken from the
/// diagonal, the others from sums and differences, so every branch divides by at least ½), then
/// normalized to the f32 unit sphere.
///
/// For senders of a quaternion (the link's host end). `r` should be a rotation (check it with
/// [`crate::control::is_rotation`]): any other finite matrix gives a finite quaternion of another
/// attitude, a non-finite one gives a non-finite quaternion (refused at the receiver).
pub fn quat_from_rot(r: &Matrix3<f32>) -> [f32; 4] {
    let tr = r.m11 + r.m22 + r.m33;
    let q = if tr >= r.m11 && tr >= r.m22 && tr >= r.m33 {
        // 4w² = 1 + tr is the largest.
        let s = 2.0 * libm::sqrtf((1.0 + tr).max(0.0));
        [
            0.25 * s,
            (r.m32 - r.m23) / s,
            (r.m13 - r.m31) / s,
            (r.m21 - r.m12) / s,
        ]
    } else if r.m11 >= r.m22 && r.m11 >= r.m33 {
        let s = 2.0 * libm::sqrtf((1.0 + r.m11 - r.m22 - r.m33).max(0.0));
        [
            (r.m32 - r.m23) / s,
            0.25 * s,
            (r.m12 + r.m21) / s,
            (r.m13 + r.m31) / s,
        ]
    } else if r.m22 >= r.m33 {
        let s = 2.0 * libm::sqrtf((1.0 + r.m22 - r.m11 - r.m33).max(0.0));
        [
            (r.m13 - r.m31) / s,
            (r.m12 + r.m21) / s,
            0.25 * s,
            (r.m23 + r.m32) / s,
        ]
    } else {
        let s = 2.0 * libm::sqrtf((1.0 + r.m33 - r.m11 - r.m22).max(0.0));
        [
            (r.m21 - r.m12) / s,
            (r.m13 + r.m31) / s,
            (r.m23 + r.m32) / s,
            0.25 * s,
        ]
    };
    let n = libm::sqrtf(q.iter().map(|c| c * c).sum::<f32>());
    // q and −q are the same attitude: the wire form has w ≥ 0.
    let k = if q[0] < 0.0 { -1.0 / n } else { 1.0 / n };
    q.map(|c| c * k)
}

/// The paper's rotation error e_R = ½ (R*ᵀ R − Rᵀ R*)^∨ (body frame; `r_des` is R*).
/// Equals `sin θ · axis` of the error rotation R*ᵀ R for small errors.
#[inline]
pub fn rotation_error(r: &Matrix3<f32>, r_des: &Matrix3<f32>) -> Vector3<f32> {
    let e = r_des.transpose() * r;
    // vee already halves and antisymmetrizes: vee(E) = ½ (E − Eᵀ)^∨.
    vee(&e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hat_is_cross_product() {
        let a = Vector3::new(1.0, -2.0, 0.5);
        let b = Vector3::new(0.3, 0.7, -1.1);
        assert!((hat(&a) * b - a.cross(&b)).norm() < 1e-6);
        assert!((vee(&hat(&a)) - a).norm() < 1e-7);
    }

    #[test]
    fn log_of_half_turn_about_each_axis() {
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let r = exp(&(axis * core::f32::consts::PI));
            let phi = log(&r);
            assert!((phi.norm() - core::f32::consts::PI).abs() < 1e-5);
            assert!((phi.normalize().dot(&axis)).abs() > 1.0 - 1e-5);
        }
    }

    #[test]
    fn quaternion_round_trip_and_norm_check() {
        use crate::control::is_rotation;
        // Near the identity, near half turns about each axis (every Shepperd branch), and generic.
        let mut phis = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1e-4, -2e-4, 3e-4),
            Vector3::new(0.3, -1.2, 2.0),
            Vector3::new(-2.5, 0.4, 1.0),
        ]
        .to_vec();
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            phis.push(axis * (core::f32::consts::PI - 1e-3));
            phis.push(axis * core::f32::consts::PI);
        }
        for phi in phis {
            let r = exp(&phi);
            let q = quat_from_rot(&r);
            let n2: f32 = q.iter().map(|c| c * c).sum();
            assert!((n2 - 1.0).abs() < 1e-6, "{q:?}");
            assert!(q[0] >= 0.0);
            let back = rot_from_quat(&q);
            assert!((back - r).norm() < 2e-6, "{phi:?}: {back} vs {r}");
            assert!(is_rotation(&back));
        }
        // Off unit norm by ε: accepted within the documented ≈ 1.4e-4, refused beyond.
        let q = quat_from_rot(&exp(&Vector3::new(0.3, -1.2, 2.0)));
        assert!(is_rotation(&rot_from_quat(&q.map(|c| c * (1.0 + 1e-4)))));
        assert!(!is_rotation(&rot_from_quat(&q.map(|c| c * (1.0 + 2e-4)))));
        assert!(!is_rotation(&rot_from_quat(&q.map(|c| c * 0.5))));
        assert!(!is_rotation(&rot_from_quat(&[0.0; 4])));
        for bad in [f32::NAN, f32::INFINITY] {
            assert!(!is_rotation(&rot_from_quat(&[bad, 0.0, 0.0, 0.0])));
            assert!(!is_rotation(&rot_from_quat(&[1.0, 0.0, bad, 0.0])));
        }
        assert!(quat_from_rot(&Matrix3::from_element(f32::NAN))
            .iter()
            .all(|c| !c.is_finite()));
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let nan = Matrix3::from_element(f32::NAN);
        assert!(log(&nan).iter().all(|x| x.is_finite()));
        assert!(orthonormalize(&nan).is_none());
        assert!(orthonormalize(&Matrix3::zeros()).is_none());
        assert_eq!(exp(&Vector3::zeros()), Matrix3::identity());
    }
}
