//! Property tests for `hamflight::lie`: exp/log round trips on SO(3) including the
//! half turn, orthonormality, the paper's rotation error against an independent f64 formula,
//! geodesic distance, and degenerate inputs.

mod common;

use common::{
    exp_f64, orthonormality_error, rotation3, rotation3_f64, rotvec_f64, unit_vec3_f64, vec3,
};
use hamflight::lie::{exp, geodesic_distance, hat, log, orthonormalize, rotation_error, vee};
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;
use std::f64::consts::PI;

/// Largest entry-wise difference between two f32 matrices.
fn max_abs_diff(a: &Matrix3<f32>, b: &Matrix3<f32>) -> f32 {
    (a - b).amax()
}

/// Distance between two rotation vectors of a half turn, where φ and −φ are the same rotation.
fn half_turn_distance(a: &Vector3<f32>, b: &Vector3<f32>) -> f32 {
    (a - b).norm().min((a + b).norm())
}

proptest! {
    #[test]
    fn hat_vee_round_trip(v in vec3(10.0), w in vec3(10.0)) {
        prop_assert_eq!(vee(&hat(&v)), v);
        prop_assert!((hat(&v) * w - v.cross(&w)).norm() <= 1e-4);
    }

    #[test]
    fn exp_of_log_is_identity_on_so3(r in rotation3()) {
        let back = exp(&log(&r));
        prop_assert!(max_abs_diff(&back, &r) < 2e-6, "R = {r}, exp(log R) = {back}");
    }

    #[test]
    fn exp_of_log_is_identity_near_half_turn(phi in rotvec_f64(PI - 1e-3..=PI)) {
        let r = exp_f64(&phi).cast::<f32>();
        let back = exp(&log(&r));
        prop_assert!(max_abs_diff(&back, &r) < 2e-6, "R = {r}, exp(log R) = {back}");
        // The angle is right, and the axis is ±the true one (both are valid within 1e-3 of π).
        let got = log(&r);
        prop_assert!((got.norm() as f64 - phi.norm()).abs() < 1e-5);
        prop_assert!((got.cast::<f64>().normalize().dot(&phi.normalize())).abs() > 1.0 - 1e-6);
    }

    #[test]
    fn exp_of_log_is_identity_at_exactly_half_turn(a in unit_vec3_f64()) {
        // R = 2 a aᵀ − I: exactly π about a, built without trigonometry.
        let r64 = 2.0 * a * a.transpose() - Matrix3::identity();
        let r = r64.cast::<f32>();
        let phi = log(&r);
        prop_assert!(phi.iter().all(|x| x.is_finite()));
        prop_assert!((phi.norm() - core::f32::consts::PI).abs() < 1e-6, "|φ| = {}", phi.norm());
        let expected = (a * PI).cast::<f32>();
        prop_assert!(half_turn_distance(&phi, &expected) < 1e-5, "φ = {phi}, a π = {expected}");
        prop_assert!(max_abs_diff(&exp(&phi), &r) < 2e-6);
    }

    #[test]
    fn log_of_exp_is_identity_inside_the_ball(phi in rotvec_f64(0.0..=PI - 1e-2)) {
        let phi32 = phi.cast::<f32>();
        let back = log(&exp(&phi32));
        // f32 rounding of R's entries (~6e-8) turns into an angle error of the same order; the
        // axis is read from the symmetric part past a quarter turn.
        prop_assert!((back - phi32).norm() < 1e-5 + 2e-6 * phi32.norm(), "φ = {phi32}, log(exp φ) = {back}");
    }

    #[test]
    fn log_of_exp_is_identity_for_tiny_angles(axis in unit_vec3_f64(), theta in 0.0..2e-3f64) {
        // Covers the Taylor branch (θ < 1e-3) and its boundary; relative accuracy matters here.
        let phi = (axis * theta).cast::<f32>();
        let back = log(&exp(&phi));
        prop_assert!((back - phi).norm() <= 1e-6 * phi.norm() + 1e-12, "φ = {phi}, log(exp φ) = {back}");
    }

    #[test]
    fn exp_matches_independent_reference(phi in rotvec_f64(0.0..=3.0 * PI)) {
        let r = exp(&phi.cast::<f32>());
        prop_assert!(max_abs_diff(&r, &exp_f64(&phi).cast::<f32>()) < 2e-6);
    }

    #[test]
    fn exp_stays_orthonormal(phi in vec3(20.0)) {
        let r = exp(&phi);
        prop_assert!(orthonormality_error(&r) < 1e-5, "‖RᵀR − I‖ = {} for φ = {phi}", orthonormality_error(&r));
        prop_assert!((r.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn orthonormalize_restores_perturbed_rotations(r in rotation3(), noise in proptest::array::uniform9(-1e-2f32..1e-2)) {
        let perturbed = r + Matrix3::from_column_slice(&noise);
        let fixed = orthonormalize(&perturbed).expect("a perturbed rotation is full rank");
        prop_assert!(orthonormality_error(&fixed) < 1e-5, "‖RᵀR − I‖ = {}", orthonormality_error(&fixed));
        prop_assert!((fixed.determinant() - 1.0).abs() < 1e-5);
        // It lands near the rotation it came from (perturbation ≤ 1e-2 per entry).
        prop_assert!(geodesic_distance(&fixed, &r) < 0.05);
        // Already-orthonormal input is (nearly) a fixed point.
        let again = orthonormalize(&fixed).expect("a rotation is full rank");
        prop_assert!(max_abs_diff(&again, &fixed) < 1e-6);
    }

    #[test]
    fn rotation_error_matches_reference_formula(r in rotation3_f64(), r_des in rotation3_f64()) {
        // e_R = ½ (R*ᵀR − RᵀR*)^∨ in f64, skew entries read by hand: ∨ of a skew S is (S₃₂, S₁₃, S₂₁).
        let e = r_des.transpose() * r - r.transpose() * r_des;
        let expected = Vector3::new(0.5 * e[(2, 1)], 0.5 * e[(0, 2)], 0.5 * e[(1, 0)]);
        let got = rotation_error(&r.cast::<f32>(), &r_des.cast::<f32>());
        prop_assert!((got.cast::<f64>() - expected).norm() < 1e-6, "e_R = {got}, reference {expected}");
        // The skew matrix itself is antisymmetric with the same entries on the other side.
        prop_assert!((e[(1, 2)] + e[(2, 1)]).abs() < 1e-12);
    }

    #[test]
    fn rotation_error_is_sin_theta_axis(r_des in rotation3_f64(), delta in rotvec_f64(0.0..=PI)) {
        // With R = R* exp(δ), e_R = sin|δ| · δ/|δ| exactly (in exact arithmetic).
        let r = r_des * exp_f64(&delta);
        let theta = delta.norm();
        let expected = if theta > 0.0 { delta * (theta.sin() / theta) } else { delta };
        let got = rotation_error(&r.cast::<f32>(), &r_des.cast::<f32>());
        prop_assert!((got.cast::<f64>() - expected).norm() < 2e-6, "e_R = {got}, sin θ a = {expected}");
    }

    #[test]
    fn rotation_error_approximates_log_for_small_errors(r_des in rotation3(), delta in vec3(0.05)) {
        let r = r_des * exp(&delta);
        let e_r = rotation_error(&r, &r_des);
        let log_err = log(&(r_des.transpose() * r));
        let theta = delta.norm();
        // |θ − sin θ| ≤ θ³/6, plus f32 rounding.
        prop_assert!((e_r - log_err).norm() <= theta.powi(3) / 6.0 + 2e-6, "e_R = {e_r}, log = {log_err}");
        prop_assert!((log_err - delta).norm() <= 2e-6);
    }

    #[test]
    fn rotation_error_vanishes_on_target_and_is_antisymmetric(r in rotation3(), r_des in rotation3()) {
        prop_assert!(rotation_error(&r, &r).norm() < 1e-6);
        // Swapping R and R* transposes the error rotation: e_R(R, R*) = −e_R(R*, R) in the
        // respective body frames, related by R*ᵀR.
        let e_ab = rotation_error(&r, &r_des);
        let e_ba = rotation_error(&r_des, &r);
        let rel = r.transpose() * r_des;
        prop_assert!((e_ab + rel * e_ba).norm() < 2e-6);
    }

    #[test]
    fn geodesic_distance_is_symmetric_and_the_angle(r_a in rotation3_f64(), delta in rotvec_f64(0.0..=PI - 1e-2)) {
        let r_b = r_a * exp_f64(&delta);
        let (a, b) = (r_a.cast::<f32>(), r_b.cast::<f32>());
        let d_ab = geodesic_distance(&a, &b);
        let d_ba = geodesic_distance(&b, &a);
        prop_assert!((d_ab - d_ba).abs() < 2e-6, "d(a,b) = {d_ab}, d(b,a) = {d_ba}");
        prop_assert!((d_ab as f64 - delta.norm()).abs() < 2e-6, "d = {d_ab}, θ = {}", delta.norm());
        prop_assert!((0.0..=core::f32::consts::PI).contains(&d_ab));
    }

    #[test]
    fn geodesic_distance_to_self_is_zero(r in rotation3()) {
        prop_assert!(geodesic_distance(&r, &r) < 1e-6);
    }

    #[test]
    fn log_of_arbitrary_finite_matrix_is_finite(m in proptest::array::uniform9(-10.0f32..10.0)) {
        // Not a rotation: log must still be total and finite (it never panics by construction).
        let m = Matrix3::from_column_slice(&m);
        let phi = log(&m);
        prop_assert!(phi.iter().all(|x| x.is_finite()), "log({m}) = {phi}");
        prop_assert!(phi.norm() <= core::f32::consts::PI + 1e-5);
    }
}

#[test]
fn exp_of_zero_is_identity_and_log_of_identity_is_zero() {
    assert_eq!(exp(&Vector3::zeros()), Matrix3::identity());
    assert_eq!(log(&Matrix3::identity()), Vector3::zeros());
    assert_eq!(
        geodesic_distance(&Matrix3::identity(), &Matrix3::identity()),
        0.0
    );
    assert_eq!(
        rotation_error(&Matrix3::identity(), &Matrix3::identity()),
        Vector3::zeros()
    );
}

#[test]
fn half_turns_about_coordinate_axes_and_diagonals() {
    let axes: [Vector3<f64>; 7] = [
        Vector3::x(),
        Vector3::y(),
        Vector3::z(),
        -Vector3::x(),
        Vector3::new(1.0, 1.0, 0.0).normalize(),
        Vector3::new(1.0, -1.0, 1.0).normalize(),
        Vector3::new(0.0, -1.0, -1.0).normalize(),
    ];
    for a in axes {
        let r = (2.0 * a * a.transpose() - Matrix3::identity()).cast::<f32>();
        let phi = log(&r);
        let expected = (a * PI).cast::<f32>();
        assert!(
            half_turn_distance(&phi, &expected) < 1e-5,
            "axis {a}: log = {phi}"
        );
        assert!(max_abs_diff(&exp(&phi), &r) < 2e-6);
    }
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let nan_v = Vector3::new(f32::NAN, 0.0, 0.0);
    let inf_v = Vector3::new(f32::INFINITY, 1.0, 0.0);
    let nan_m = Matrix3::from_element(f32::NAN);
    let inf_m = Matrix3::from_element(f32::INFINITY);
    let huge_m = Matrix3::from_element(f32::MAX);
    let zero_m = Matrix3::zeros();
    for v in [nan_v, inf_v, Vector3::zeros(), Vector3::repeat(f32::MAX)] {
        let _ = exp(&v);
        let _ = vee(&hat(&v));
    }
    for m in [nan_m, inf_m, huge_m, -huge_m, zero_m] {
        let _ = log(&m);
        let _ = geodesic_distance(&m, &Matrix3::identity());
        let _ = geodesic_distance(&Matrix3::identity(), &m);
        let _ = rotation_error(&m, &Matrix3::identity());
        let _ = orthonormalize(&m);
    }
    // Documented behaviour: non-finite or rank-deficient input has no orthonormalization,
    // and log of a non-finite matrix is finite (zero) rather than NaN.
    assert!(orthonormalize(&nan_m).is_none());
    assert!(orthonormalize(&inf_m).is_none());
    assert!(orthonormalize(&zero_m).is_none());
    let rank_one = Matrix3::from_columns(&[Vector3::x(), Vector3::x() * 2.0, Vector3::y()]);
    assert!(orthonormalize(&rank_one).is_none());
    assert!(log(&nan_m).iter().all(|x| x.is_finite()));
    assert!(log(&zero_m).iter().all(|x| x.is_finite()));
}
