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
fn sin_cos_wraps_large_angles_by_whole_f32_turns() {
    // Past 6,000 rad the angle is wrapped by whole turns of the f32 2π; the reference is the same
    // wrap done exactly in f64, so the error left is the f32 rounding of the wrap, of the order of
    // one f32 step of x.
    let tau = f64::from(core::f32::consts::TAU);
    let mut rng = SplitMix64(13);
    for _ in 0..100_000 {
        let x = rng.symmetric() * 1.6e7;
        if x.abs() <= 6000.0 {
            continue;
        }
        let (s, c) = sin_cos(x);
        let wrapped = f64::from(x) % tau;
        let step = f64::from(x.abs()) * f64::from(f32::EPSILON);
        let e = (f64::from(s) - wrapped.sin())
            .abs()
            .max((f64::from(c) - wrapped.cos()).abs());
        assert!(
            e <= 2.0 * step + 1e-6,
            "x = {x}: error {e:e}, f32 step {step:e}"
        );
    }
    // No phase is left past 2^24 rad: the angle wraps to zero.
    assert_eq!(sin_cos(3.0e7), (0.0, 1.0));
    assert_eq!(sin_cos(-3.0e38), (0.0, 1.0));
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

/// Every dense-layer path (the host's run-time FMA dispatch where the CPU has it, the generic
/// loop elsewhere, the M4F kernels under PIL), with and without the activation, is the same fma
/// chain: checked bit for bit at the
/// model's two input widths, with subnormal, huge, signed-zero and non-finite values mixed in.
#[test]
fn dense_forward_gives_the_chains_bits_at_both_widths_and_for_special_values() {
    fn check<const I: usize, const O: usize>(rng: &mut SplitMix64) {
        let special = [0.0f32, -0.0, 1e-45, -3e-39, 3.0e38, f32::NAN, f32::INFINITY];
        let pick = |rng: &mut SplitMix64| {
            let r = rng.next_u64();
            if r.is_multiple_of(11) {
                special[(r >> 8) as usize % special.len()]
            } else {
                rng.symmetric() * 4.0
            }
        };
        let mut layer = Dense::<I, O>::ZERO;
        for v in layer.params_mut() {
            *v = pick(rng);
        }
        let x: [f32; I] = core::array::from_fn(|_| pick(rng));
        let y = layer.forward(&x);
        let t = layer.forward_tanh(&x);
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for (((yo, to), row), b) in y.iter().zip(&t).zip(&layer.weight).zip(&layer.bias) {
            let chain = row
                .iter()
                .zip(&x)
                .fold(*b, |a, (w, xi)| fpu::fma(*w, *xi, a));
            assert!(same(*yo, chain), "{I}x{O}: {yo:e} vs the chain's {chain:e}");
            let act = fpu::tanh(chain);
            assert!(same(*to, act), "{I}x{O}: tanh {to:e} vs {act:e}");
        }
    }
    let mut rng = SplitMix64(5);
    for _ in 0..500 {
        check::<9, 16>(&mut rng);
        check::<16, 16>(&mut rng);
        check::<16, 36>(&mut rng);
        check::<3, 5>(&mut rng);
    }
}

/// The composite law's six scalar updates ([`fpu::kalman_rows`]) against the same updates in
/// f64 on a full symmetric P: a, the upper triangle of P and every s agree to f32 rounding, the
/// lower triangle is left alone, and a row with s ≤ 0 changes nothing.
#[test]
fn kalman_rows_match_f64_sequential_updates() {
    let mut rng = SplitMix64(21);
    for _ in 0..300 {
        // P = B Bᵀ + I / 2, symmetric positive definite.
        let b: [[f64; 6]; 6] =
            core::array::from_fn(|_| core::array::from_fn(|_| f64::from(rng.symmetric())));
        let mut pd = [[0.0f64; 6]; 6];
        for (i, row) in pd.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v =
                    (0..6).map(|k| b[i][k] * b[j][k]).sum::<f64>() + if i == j { 0.5 } else { 0.0 };
            }
        }
        let mut p: [[f32; 6]; 6] =
            core::array::from_fn(|c| core::array::from_fn(|r| pd[r][c] as f32));
        let lower_before: Vec<f32> = (0..6)
            .flat_map(|c| ((c + 1)..6).map(move |r| (c, r)))
            .map(|(c, r)| p[c][r])
            .collect();
        let h: [[f32; 6]; 6] = core::array::from_fn(|_| core::array::from_fn(|_| rng.symmetric()));
        let z: [f32; 6] = core::array::from_fn(|_| rng.symmetric() * 3.0);
        let mut a: [f32; 6] = core::array::from_fn(|_| rng.symmetric());
        let mut r = [0.1f32, 0.2, 0.3, 0.05, 0.07, 0.09];
        // f64 reference from the f32 inputs.
        let mut pr: [[f64; 6]; 6] =
            core::array::from_fn(|i| core::array::from_fn(|j| f64::from(p[j.max(i)][j.min(i)])));
        let mut ar: [f64; 6] = a.map(f64::from);
        let mut sr = [0.0f64; 6];
        for i in 0..6 {
            let hi = h[i].map(f64::from);
            let ph: [f64; 6] = core::array::from_fn(|k| (0..6).map(|j| pr[k][j] * hi[j]).sum());
            let s = f64::from(r[i]) + (0..6).map(|j| hi[j] * ph[j]).sum::<f64>();
            sr[i] = s;
            let e = f64::from(z[i]) - (0..6).map(|j| hi[j] * ar[j]).sum::<f64>();
            for j in 0..6 {
                ar[j] += ph[j] * e / s;
                for k in 0..6 {
                    pr[j][k] -= ph[j] * ph[k] / s;
                }
            }
        }
        fpu::kalman_rows(&mut p, &mut a, &h, &z, &mut r);
        let scale = pr.iter().flatten().fold(1.0f64, |m, v| m.max(v.abs()));
        for c in 0..6 {
            for j in 0..=c {
                let err = (f64::from(p[c][j]) - pr[j][c]).abs();
                assert!(err < 1e-4 * scale, "P({j},{c}) {} vs {}", p[c][j], pr[j][c]);
            }
        }
        let lower_after: Vec<f32> = (0..6)
            .flat_map(|c| ((c + 1)..6).map(move |r| (c, r)))
            .map(|(c, r)| p[c][r])
            .collect();
        assert_eq!(
            lower_before, lower_after,
            "the lower triangle is not written"
        );
        let amax = ar.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        for (got, want) in a.iter().zip(ar.iter()) {
            assert!(
                (f64::from(*got) - want).abs() < 1e-4 * amax,
                "a {got} vs {want}"
            );
        }
        for (got, want) in r.iter().zip(sr.iter()) {
            assert!(
                (f64::from(*got) - want).abs() < 1e-4 * want.abs().max(1.0),
                "s {got} vs {want}"
            );
        }
    }
    // A row with s ≤ 0 (a negative r on a zero row) leaves a and P as they were.
    let mut p = [[0.0f32; 6]; 6];
    for (i, col) in p.iter_mut().enumerate() {
        col[i] = 1.0;
    }
    let before = p;
    let mut a = [0.5f32; 6];
    let mut r = [-1.0f32; 6];
    fpu::kalman_rows(&mut p, &mut a, &[[0.0; 6]; 6], &[1.0; 6], &mut r);
    assert_eq!((p, a), (before, [0.5; 6]));
    assert_eq!(r, [-1.0; 6], "s = r for a zero row");
}
