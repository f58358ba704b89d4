//! The learned model's unit tests: its heads against the nominal physics and the blob.

use super::*;
use crate::model::{hamiltonian, rk4_step, NominalModel};

/// Deterministic pseudo-random weights in [-amp, amp] (a small LCG, no dependencies).
fn random_weights(seed: u32, amp: f32) -> ModelWeights {
    let mut s = seed.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let mut next = move || {
        s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        ((s >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0) * amp
    };
    let mut w = ModelWeights::prior();
    macro_rules! fill {
        ($net:expr) => {
            for v in $net.l0.weight.iter_mut().flatten() {
                *v = next();
            }
            for v in $net.l1.weight.iter_mut().flatten() {
                *v = next();
            }
            for v in $net.l2.weight.iter_mut().flatten() {
                *v = 0.2 * next();
            }
            for v in $net.l0.bias.iter_mut() {
                *v = next();
            }
        };
    }
    fill!(w.inertia);
    fill!(w.gain);
    fill!(w.disturbance);
    w
}

fn tilted_state() -> State {
    State {
        p_m: Vector3::new(0.1, -0.2, 0.5),
        rot: crate::lie::exp(&Vector3::new(0.3, -0.2, 0.5)),
        v_body_m_s: Vector3::new(0.3, 0.1, -0.2),
        w_body_rad_s: Vector3::new(1.0, -2.0, 0.5),
    }
}

#[test]
fn prior_equals_nominal_model() {
    let learned = LearnedModel::new(ModelWeights::prior());
    let nominal = NominalModel::default();
    let s = tilted_state();
    let (a, b) = (learned.terms(&s), nominal.terms(&s));
    assert!((a.inertia_inv - b.inertia_inv).norm() / b.inertia_inv.norm() < 1e-5);
    assert!((a.gain - b.gain).norm() < 1e-5);
    let wl = a.features;
    let wn = b.features;
    assert!((wl - wn).norm() / wn.norm() < 1e-5, "{wl} vs {wn}");
    let u = Vector4::new(0.3, 1e-4, -2e-4, 5e-5);
    let a6 = [0.1, -0.2, 0.3, 0.5, -0.1, 0.2];
    let (da, db) = (learned.dynamics(&s, &u, &a6), nominal.dynamics(&s, &u, &a6));
    assert!((da.w_dot_rad_s2 - db.w_dot_rad_s2).norm() < 1e-3 * db.w_dot_rad_s2.norm());
    assert!((da.v_dot_m_s2 - db.v_dot_m_s2).norm() < 1e-4);
}

#[test]
fn inertia_jacobians_match_finite_differences() {
    let model = LearnedModel::new(random_weights(7, 0.8));
    let s = tilted_state();
    let rot_dot = s.rot * crate::lie::hat(&s.w_body_rad_s);
    let p_w = Vector3::new(2e-5, -3e-5, 1e-5);
    let (_, djinv, dh_dr) = model.inertia_inv_jacobians(&s.rot, &rot_dot, &p_w);
    let h = 1e-3f32;
    // JVP: central difference of J⁻¹ along Ṙ.
    let fd = (model.inertia_inv(&(s.rot + rot_dot * h))
        - model.inertia_inv(&(s.rot - rot_dot * h)))
        / (2.0 * h);
    assert!(
        (fd - djinv).norm() < 2e-2 * djinv.norm().max(1.0),
        "{fd} vs {djinv}"
    );
    // VJP: central differences of H_ω = ½ 𝔭ᵀ J⁻¹(R) 𝔭 entry by entry.
    let energy = |r: &Matrix3<f32>| 0.5 * p_w.dot(&(model.inertia_inv(r) * p_w));
    for i in 0..3 {
        for k in 0..3 {
            let mut e = Matrix3::zeros();
            e[(i, k)] = h;
            let fd = (energy(&(s.rot + e)) - energy(&(s.rot - e))) / (2.0 * h);
            let an = dh_dr[i][k];
            assert!(
                (fd - an).abs() < 2e-2 * an.abs() + 1e-9,
                "({i},{k}) {fd} vs {an}"
            );
        }
    }
}

#[test]
fn unforced_dynamics_conserve_energy_and_stay_on_so3() {
    let model = LearnedModel::new(random_weights(3, 0.8));
    let mut s = tilted_state();
    let u = Vector4::zeros();
    let a = [0.0; FEATURES];
    // With u = 0 and d = 0 the vehicle falls; H = T + V stays constant.
    // The rotational part ½ ωᵀ J(q) ω (≈ 1e-4 J, far below the potential energy) is
    // conserved on its own, which checks the ∂H/∂rᵢ and d/dt J⁻¹ terms.
    let t_rot = |s: &State| {
        let j = model
            .inertia_inv(&s.rot)
            .try_inverse()
            .unwrap_or_else(Matrix3::zeros);
        0.5 * s.w_body_rad_s.dot(&(j * s.w_body_rad_s))
    };
    let h0 = hamiltonian(&model, &s);
    let t0 = t_rot(&s);
    for _ in 0..500 {
        s = rk4_step(&model, &s, &u, &a, 1e-3);
    }
    let h1 = hamiltonian(&model, &s);
    let t1 = t_rot(&s);
    assert!((h1 - h0).abs() < 1e-5 * h0.abs(), "H {h0} -> {h1}");
    assert!((t1 - t0).abs() < 1e-4 * t0, "T_rot {t0} -> {t1}");
    // The attitude did move: J(q) varies along the path.
    assert!((s.rot - tilted_state().rot).norm() > 0.1);
    let ortho = (s.rot.transpose() * s.rot - Matrix3::identity()).norm();
    assert!(ortho < 1e-4, "RᵀR − I = {ortho}");
    assert!((s.rot.determinant() - 1.0).abs() < 1e-4);
}

#[test]
fn feature_basis_folds_into_the_output_layer_and_gives_nominal_features_at_hover() {
    let w = random_weights(7, 0.5);
    let t = hover_feature_basis(&w.disturbance).expect("well-conditioned");
    let changed = LearnedModel::new(w.with_feature_basis(&t));
    let original = LearnedModel::new(w);
    // At hover the new features are the nominal ones.
    let hover = State::default();
    let nominal = NominalModel::default().terms(&hover).features;
    let err = (changed.features(&hover) - nominal).norm() / nominal.norm();
    assert!(err < 1e-4, "W'(hover) vs nominal: {err}");
    // Everywhere W' = W T (the model's span is unchanged).
    let s = tilted_state();
    let expect = original.features(&s) * t;
    let err = (changed.features(&s) - expect).norm() / expect.norm();
    assert!(err < 1e-4, "W' vs W T: {err}");
}

#[test]
fn features_toward_nominal_blend_exactly_at_every_state() {
    let w = random_weights(11, 0.5);
    let nominal_model = NominalModel::default();
    for s in [State::default(), tilted_state()] {
        let learned = LearnedModel::new(w).features(&s);
        let nominal = nominal_model.terms(&s).features;
        for keep in [0.0f32, 0.3, 1.0] {
            let got = LearnedModel::new(w.with_features_toward_nominal(keep)).features(&s);
            let expect = learned * keep + nominal * (1.0 - keep);
            let err = (got - expect).norm() / expect.norm();
            assert!(err < 1e-5, "keep {keep}: W' vs blend {err}");
        }
    }
    // Out of range clamps: below 0 is the nominal features, NaN too.
    let s = tilted_state();
    let nominal = nominal_model.terms(&s).features;
    for keep in [-1.0f32, f32::NAN] {
        let got = LearnedModel::new(w.with_features_toward_nominal(keep)).features(&s);
        assert!((got - nominal).norm() < 1e-6 * nominal.norm().max(1.0));
    }
}
