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
    fn degenerate_inputs_do_not_panic() {
        let nan = Matrix3::from_element(f32::NAN);
        assert!(log(&nan).iter().all(|x| x.is_finite()));
        assert!(orthonormalize(&nan).is_none());
        assert!(orthonormalize(&Matrix3::zeros()).is_none());
        assert_eq!(exp(&Vector3::zeros()), Matrix3::identity());
    }
}
