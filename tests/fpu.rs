//! The M4F-oriented numerics: fused dense layers, square root and sin/cos against f64
//! references. On the host these run the portable paths; the processor-in-the-loop test checks
//! that the firmware's assembly gives the same bits.

mod common;

use common::SplitMix64;
use hamflight::fpu;
use hamflight::nn::Dense;
use hamflight::reference::sin_cos;

#[test]
fn sin_cos_matches_f64_within_2e7() {
    let mut worst = 0.0f64;
    let mut check = |x: f32| {
        let (s, c) = sin_cos(x);
        let xd = f64::from(x);
        let e = (f64::from(s) - xd.sin())
            .abs()
            .max((f64::from(c) - xd.cos()).abs());
        assert!(e < 2e-7, "x = {x}: sin {s} cos {c}, error {e:e}");
        worst = worst.max(e);
    };
    // A dense grid over ±4π (every quadrant boundary) and random values out to ±6000 rad.
    for i in -200_000..=200_000 {
        check(i as f32 * (4.0 * core::f32::consts::PI / 200_000.0));
    }
    let mut rng = SplitMix64(7);
    for _ in 0..200_000 {
        check(rng.symmetric() * 6000.0);
    }
    assert!(worst > 0.0, "the check ran");
}

#[test]
fn sin_cos_exact_at_zero_and_nan_for_non_finite() {
    assert_eq!(sin_cos(0.0), (0.0, 1.0));
    for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let (s, c) = sin_cos(x);
        assert!(s.is_nan() && c.is_nan(), "{x}");
    }
    // Huge inputs saturate the quadrant count instead of overflowing; the result stays bounded.
    let (s, c) = sin_cos(3.0e38);
    assert!(s.abs() <= 1.5 && c.abs() <= 1.5);
}

#[test]
fn sqrt_is_correctly_rounded() {
    let mut rng = SplitMix64(11);
    for _ in 0..100_000 {
        let x = f32::from_bits((rng.next_u64() >> 33) as u32); // non-negative, any exponent
        let want = f64::from(x).sqrt() as f32; // exact: f64 has > 2·24 + 2 bits
        let got = fpu::sqrt(x);
        assert!(
            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
            "sqrt({x:e}) = {got:e}, want {want:e}"
        );
    }
    assert!(fpu::sqrt(-1.0).is_nan());
}

#[test]
fn fma_rounds_once() {
    // 1 + 2⁻²⁴ is not representable; (1 + 2⁻¹²)² = 1 + 2⁻¹¹ + 2⁻²⁴ rounds to 1 + 2⁻¹¹ unfused,
    // and fma((1 + 2⁻¹²), (1 + 2⁻¹²), −(1 + 2⁻¹¹)) is exactly 2⁻²⁴.
    let a = 1.0 + f32::EPSILON * 2048.0; // 1 + 2⁻¹²
    let c = -(1.0 + f32::EPSILON * 4096.0); // −(1 + 2⁻¹¹)
    assert_eq!(fpu::fma(a, a, c), 2.0f32.powi(-24));
    assert_eq!(a * a + c, 0.0, "the unfused form loses it");
}

#[test]
fn dense_forward_is_the_fused_chain_and_close_to_f64() {
    let mut rng = SplitMix64(3);
    for _ in 0..200 {
        let mut layer = Dense::<16, 24>::ZERO;
        for w in layer.weight.iter_mut().flatten() {
            *w = rng.symmetric();
        }
        for b in layer.bias.iter_mut() {
            *b = rng.symmetric();
        }
        let x: [f32; 16] = core::array::from_fn(|_| rng.symmetric());
        let y = layer.forward(&x);
        for ((yo, row), b) in y.iter().zip(&layer.weight).zip(&layer.bias) {
            let chain = row
                .iter()
                .zip(&x)
                .fold(*b, |a, (w, xi)| fpu::fma(*w, *xi, a));
            assert_eq!(
                yo.to_bits(),
                chain.to_bits(),
                "forward is the documented chain"
            );
            let exact: f64 = f64::from(*b)
                + row
                    .iter()
                    .zip(&x)
                    .map(|(w, xi)| f64::from(*w) * f64::from(*xi))
                    .sum::<f64>();
            assert!((f64::from(*yo) - exact).abs() < 1e-5, "{yo} vs {exact}");
        }
    }
}

#[test]
fn all_finite_finds_every_nan_and_infinity() {
    let base = [
        0.0f32,
        -0.0,
        1.0,
        -3.0e38,
        1e-45,
        f32::MAX,
        f32::MIN_POSITIVE,
    ];
    assert!(fpu::all_finite(base));
    assert!(fpu::all_finite([]));
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -f32::NAN] {
        for pos in 0..=base.len() {
            let mut v = base.to_vec();
            v.insert(pos, bad);
            assert!(!fpu::all_finite(v.iter().copied()), "{bad} at {pos}");
        }
    }
}
