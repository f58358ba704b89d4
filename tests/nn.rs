//! Tests for `hamflight::nn`: a hand-computed forward pass, the JVP against central
//! finite differences and an explicit f64 Jacobian, and the VJP as the JVP's transpose.

mod common;

use common::SplitMix64;
use hamflight::nn::{softplus, tanh, Dense, Mlp};
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

/// A random network with weights uniform in [-scale, scale]: large enough to bend tanh,
/// small enough not to saturate it everywhere.
fn random_mlp<const I: usize, const H: usize, const O: usize>(
    seed: u64,
    scale: f32,
) -> Mlp<I, H, O> {
    fn fill<const I: usize, const O: usize>(rng: &mut SplitMix64, scale: f32) -> Dense<I, O> {
        let mut d = Dense::<I, O>::ZERO;
        for v in d.weight.iter_mut().flatten().chain(d.bias.iter_mut()) {
            *v = scale * rng.symmetric();
        }
        d
    }
    let mut rng = SplitMix64(seed);
    Mlp {
        l0: fill(&mut rng, scale),
        l1: fill(&mut rng, scale),
        l2: fill(&mut rng, scale),
    }
}

fn random_vec<const N: usize>(seed: u64, scale: f32) -> [f32; N] {
    let mut rng = SplitMix64(seed);
    core::array::from_fn(|_| scale * rng.symmetric())
}

/// `W` of a layer as an f64 matrix (O × I).
fn weight_f64<const I: usize, const O: usize>(d: &Dense<I, O>) -> DMatrix<f64> {
    DMatrix::from_fn(O, I, |o, i| d.weight[o][i] as f64)
}

fn bias_f64<const I: usize, const O: usize>(d: &Dense<I, O>) -> DVector<f64> {
    DVector::from_fn(O, |o, _| d.bias[o] as f64)
}

/// Independent f64 reference: the forward pass and the full input Jacobian
/// J = W₂ diag(1 − h₁²) W₁ diag(1 − h₀²) W₀, written with nalgebra matrices.
fn reference<const I: usize, const H: usize, const O: usize>(
    net: &Mlp<I, H, O>,
    x: &[f32; I],
) -> (DVector<f64>, DMatrix<f64>) {
    let (w0, w1, w2) = (
        weight_f64(&net.l0),
        weight_f64(&net.l1),
        weight_f64(&net.l2),
    );
    let x = DVector::from_fn(I, |i, _| x[i] as f64);
    let h0 = (&w0 * x + bias_f64(&net.l0)).map(f64::tanh);
    let h1 = (&w1 * &h0 + bias_f64(&net.l1)).map(f64::tanh);
    let y = &w2 * &h1 + bias_f64(&net.l2);
    let s0 = DMatrix::from_diagonal(&h0.map(|t| 1.0 - t * t));
    let s1 = DMatrix::from_diagonal(&h1.map(|t| 1.0 - t * t));
    (y, w2 * s1 * w1 * s0 * w0)
}

fn to_f64<const N: usize>(v: &[f32; N]) -> DVector<f64> {
    DVector::from_fn(N, |i, _| v[i] as f64)
}

#[test]
fn forward_matches_hand_computation_3_2_2() {
    // Pre-activations are chosen so every tanh is exact in closed form:
    // tanh(½ ln 3) = ½ and tanh(½ ln 2) = ⅓.
    let a = 0.5 * 3.0f32.ln();
    let b = 0.5 * 2.0f32.ln();
    let net: Mlp<3, 2, 2> = Mlp {
        // x = [1, 2, −1]: row 0 gives a + 1 − 1 = a, row 1 gives −0.5 − a + 0.5 = −a.
        l0: Dense {
            weight: [[a, 0.5, 1.0], [0.0, -0.25, a]],
            bias: [0.0, 0.5],
        },
        // h0 = [½, −½]: row 0 gives 0 + b, row 1 gives 1 + (a − 1) = a.
        l1: Dense {
            weight: [[1.0, 1.0], [1.0, -1.0]],
            bias: [b, a - 1.0],
        },
        // h1 = [⅓, ½]: y = [1 + 1 + 0.25, −2 + 2 − 1].
        l2: Dense {
            weight: [[3.0, 2.0], [-6.0, 4.0]],
            bias: [0.25, -1.0],
        },
    };
    let x = [1.0, 2.0, -1.0];
    let y = net.forward(&x);
    assert!((y[0] - 2.25).abs() < 2e-6, "{y:?}");
    assert!((y[1] + 1.0).abs() < 2e-6, "{y:?}");

    // The Jacobian by hand: J = W₂ diag(1 − h₁²) W₁ diag(1 − h₀²) W₀ with
    // 1 − h₀² = [¾, ¾] and 1 − h₁² = [8/9, ¾].
    // W₁ diag(¾, ¾) W₀ = ¾ [[a, ¼, 1 + a], [a, ¾, 1 − a]];
    // diag(8/9, ¾) of that = [[⅔ a, 1/6, ⅔(1 + a)], [9/16 a, 27/64, 9/16 (1 − a)]];
    // W₂ = [[3, 2], [−6, 4]] then gives the rows below.
    let (a, third, nine16) = (a as f64, 2.0 / 3.0, 9.0 / 16.0);
    let m = [
        [third * a, 1.0 / 6.0, third * (1.0 + a)],
        [nine16 * a, 27.0 / 64.0, nine16 * (1.0 - a)],
    ];
    let jac: [[f64; 3]; 2] = [
        core::array::from_fn(|i| 3.0 * m[0][i] + 2.0 * m[1][i]),
        core::array::from_fn(|i| -6.0 * m[0][i] + 4.0 * m[1][i]),
    ];
    for (i, e) in [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        .iter()
        .enumerate()
    {
        let (y_jvp, col) = net.jvp(&x, e);
        assert_eq!(y_jvp, y);
        for o in 0..2 {
            assert!(
                (col[o] as f64 - jac[o][i]).abs() < 1e-5,
                "J[{o}][{i}] = {} vs {}",
                col[o],
                jac[o][i]
            );
        }
    }
    for (o, e) in [[1.0f32, 0.0], [0.0, 1.0]].iter().enumerate() {
        let (y_vjp, row) = net.vjp(&x, e);
        assert_eq!(y_vjp, y);
        for i in 0..3 {
            assert!(
                (row[i] as f64 - jac[o][i]).abs() < 1e-5,
                "Jᵀ[{i}][{o}] = {} vs {}",
                row[i],
                jac[o][i]
            );
        }
    }
}

#[test]
fn zero_network_is_zero_with_zero_jacobian() {
    let net = Mlp::<4, 3, 2>::ZERO;
    let x = [1.0, -2.0, 3.0, 0.5];
    assert_eq!(net.forward(&x), [0.0; 2]);
    assert_eq!(net.jvp(&x, &[1.0; 4]).1, [0.0; 2]);
    assert_eq!(net.vjp(&x, &[1.0; 2]).1, [0.0; 4]);
    assert_eq!(Mlp::<4, 3, 2>::PARAMS, 4 * 3 + 3 + 3 * 3 + 3 + 3 * 2 + 2);
    assert_eq!(Mlp::<4, 3, 2>::DIMS, [4, 3, 2]);
}

#[test]
fn activations_match_f64() {
    for i in -400..=400 {
        let x = i as f32 * 0.1;
        let t = tanh(x) as f64;
        assert!((t - (x as f64).tanh()).abs() < 5e-6, "tanh({x})");
        let sp = softplus(x) as f64;
        let reference = (x as f64).exp().ln_1p();
        assert!(
            (sp - reference).abs() <= 2e-7 * reference.max(1e-30) + 1e-30,
            "softplus({x}) = {sp} vs {reference}"
        );
        assert!(sp > 0.0 || x < -80.0);
    }
    // No overflow at the extremes, and softplus(x) → x for large x.
    assert_eq!(softplus(1e30), 1e30);
    assert_eq!(softplus(f32::MAX), f32::MAX);
    assert!(softplus(-1e30) >= 0.0);
    assert!(
        (tanh(1e30) - 1.0).abs() < 5e-6,
        "tanh saturates to 1 within its bound"
    );
}

proptest! {
    #[test]
    fn forward_and_jacobian_match_f64_reference(seed in any::<u64>(), xs in any::<u64>()) {
        let net = random_mlp::<5, 8, 3>(seed, 0.8);
        let x = random_vec::<5>(xs, 2.0);
        let (y_ref, jac) = reference(&net, &x);
        let y = net.forward(&x);
        prop_assert!((to_f64(&y) - &y_ref).amax() < 1e-5, "{y:?} vs {y_ref}");
        for i in 0..5 {
            let mut e = [0.0f32; 5];
            e[i] = 1.0;
            let (_, col) = net.jvp(&x, &e);
            prop_assert!((to_f64(&col) - jac.column(i)).amax() < 1e-5);
        }
    }

    #[test]
    fn jvp_matches_central_differences(seed in any::<u64>(), xs in any::<u64>(), vs in any::<u64>()) {
        let net = random_mlp::<6, 10, 4>(seed, 0.7);
        let x = random_vec::<6>(xs, 2.0);
        let v = random_vec::<6>(vs, 1.0);
        let (y, jv) = net.jvp(&x, &v);
        prop_assert_eq!(y, net.forward(&x));

        // Step: f32 rounding of y (~1e-7 |y|) costs ~1e-7 |y| / h, truncation costs ~h² |y'''| / 6;
        // h = 2⁻⁷ ≈ 8e-3 balances them near 1e-5. The perturbed inputs are rounded to f32, so the
        // difference quotient uses the step actually taken, accumulated in f64.
        let h = 1.0 / 128.0f32;
        let xp: [f32; 6] = core::array::from_fn(|i| x[i] + h * v[i]);
        let xm: [f32; 6] = core::array::from_fn(|i| x[i] - h * v[i]);
        let step = DVector::from_fn(6, |i, _| (xp[i] as f64 - xm[i] as f64) / 2.0);
        let (yp, ym) = (to_f64(&net.forward(&xp)), to_f64(&net.forward(&xm)));
        // Central difference of the actual step, compared with J applied to the same step.
        let fd = (yp - ym) / 2.0;
        let (_, jac) = reference(&net, &x);
        let j_step = &jac * &step;
        let scale = 1.0 + to_f64(&jv).amax() * h as f64;
        prop_assert!((&fd - &j_step).amax() < 2e-5 * scale, "fd {fd} vs J·step {j_step}");
        // And the f32 JVP itself against the difference quotient per unit step.
        let fd_unit = &fd / h as f64;
        prop_assert!((to_f64(&jv) - &fd_unit).amax() < 3e-3 * (1.0 + to_f64(&jv).amax()), "jvp {jv:?} vs fd {fd_unit}");
    }

    #[test]
    fn jvp_matches_f64_central_differences(seed in any::<u64>(), xs in any::<u64>(), vs in any::<u64>()) {
        // With the forward pass in f64 (the reference), a small step isolates the JVP's own error.
        let net = random_mlp::<6, 10, 4>(seed, 0.7);
        let x = random_vec::<6>(xs, 2.0);
        let v = random_vec::<6>(vs, 1.0);
        let (_, jv) = net.jvp(&x, &v);
        let h = 1e-5;
        let shifted = |sign: f64| {
            let (w0, w1, w2) = (weight_f64(&net.l0), weight_f64(&net.l1), weight_f64(&net.l2));
            let xs = to_f64(&x) + to_f64(&v) * (sign * h);
            let h0 = (w0 * xs + bias_f64(&net.l0)).map(f64::tanh);
            let h1 = (w1 * h0 + bias_f64(&net.l1)).map(f64::tanh);
            w2 * h1 + bias_f64(&net.l2)
        };
        let fd = (shifted(1.0) - shifted(-1.0)) / (2.0 * h);
        prop_assert!((to_f64(&jv) - &fd).amax() < 1e-5 * (1.0 + fd.amax()), "jvp {jv:?} vs fd {fd}");
    }

    #[test]
    fn vjp_is_the_transpose_of_jvp(seed in any::<u64>(), xs in any::<u64>(), us in any::<u64>(), vs in any::<u64>()) {
        let net = random_mlp::<7, 9, 5>(seed, 1.0);
        let x = random_vec::<7>(xs, 3.0);
        let u = random_vec::<5>(us, 1.0);
        let v = random_vec::<7>(vs, 1.0);
        let (y_j, jv) = net.jvp(&x, &v);
        let (y_v, jtu) = net.vjp(&x, &u);
        prop_assert_eq!(y_j, y_v);
        let lhs = to_f64(&u).dot(&to_f64(&jv)); // uᵀ (J v)
        let rhs = to_f64(&jtu).dot(&to_f64(&v)); // (Jᵀ u)ᵀ v
        let (_, jac) = reference(&net, &x);
        let mag = to_f64(&u).abs().dot(&(jac.abs() * to_f64(&v).abs()));
        prop_assert!((lhs - rhs).abs() <= 1e-5 * (mag + 1e-3), "uᵀJv = {lhs}, (Jᵀu)ᵀv = {rhs}");
    }

    #[test]
    fn model_sized_vjp_is_transpose_of_jvp(seed in any::<u64>(), xs in any::<u64>(), us in any::<u64>(), vs in any::<u64>()) {
        // The shape of the real g(q) network: 9 → 16 → 16 → 24.
        let net = random_mlp::<9, 16, 24>(seed, 0.5);
        let x = random_vec::<9>(xs, 1.0);
        let u = random_vec::<24>(us, 1.0);
        let v = random_vec::<9>(vs, 1.0);
        let lhs = to_f64(&u).dot(&to_f64(&net.jvp(&x, &v).1));
        let rhs = to_f64(&net.vjp(&x, &u).1).dot(&to_f64(&v));
        let (_, jac) = reference(&net, &x);
        let mag = to_f64(&u).abs().dot(&(jac.abs() * to_f64(&v).abs()));
        prop_assert!((lhs - rhs).abs() <= 1e-5 * (mag + 1e-3), "uᵀJv = {lhs}, (Jᵀu)ᵀv = {rhs}");
    }

    #[test]
    fn dense_transpose_is_adjoint(seed in any::<u64>(), xs in any::<u64>(), ys in any::<u64>()) {
        let net = random_mlp::<6, 4, 3>(seed, 1.0);
        let layer = net.l0;
        let dx = random_vec::<6>(xs, 1.0);
        let dy = random_vec::<4>(ys, 1.0);
        let lhs = to_f64(&dy).dot(&to_f64(&layer.linear(&dx)));
        let rhs = to_f64(&layer.linear_transpose(&dy)).dot(&to_f64(&dx));
        prop_assert!((lhs - rhs).abs() < 1e-5);
        // forward = linear + bias.
        let f = layer.forward(&dx);
        let l = layer.linear(&dx);
        for o in 0..4 {
            prop_assert!((f[o] - (l[o] + layer.bias[o])).abs() < 1e-6);
        }
    }
}

/// The rational tanh keeps its documented bound (|error| < 5e-6) over the whole useful range,
/// is odd, saturates to ±1 and stays finite for infinite inputs.
#[test]
fn fast_tanh_error_bound() {
    let n = 200_000;
    let mut worst = 0.0f64;
    for i in 0..=n {
        let x = -10.0 + 20.0 * i as f64 / n as f64;
        let x = x as f32;
        let e = (f64::from(hamflight::nn::tanh(x)) - (f64::from(x)).tanh()).abs();
        worst = worst.max(e);
        assert_eq!(hamflight::nn::tanh(-x), -hamflight::nn::tanh(x));
    }
    println!("max |tanh error| = {worst:e}");
    assert!(worst < 5e-6, "max |tanh error| = {worst:e}");
    assert_eq!(hamflight::nn::tanh(f32::INFINITY), hamflight::nn::tanh(8.0));
    assert!((hamflight::nn::tanh(f32::NEG_INFINITY) + 1.0).abs() < 5e-6);
    assert_eq!(hamflight::nn::tanh(0.0), 0.0);
}
