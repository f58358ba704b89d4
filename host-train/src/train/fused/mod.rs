//! The training loss and its exact gradient as one hand-fused CPU kernel in plain f32, without
//! burn: [`super::tensor_model`]'s equations (paper eq. 1 and 2 in (q, 𝔭), RK4, the TSE(3) loss of
//! [`super::loss::window_loss`]) for a minibatch of windows, with the reverse pass (adjoints)
//! written out, the second-order term through the J⁻¹ head's VJP (∂H/∂R) included.
//!
//! Eight windows run in lockstep, one per lane of `V` (an `[f32; 8]` whose element-wise ops
//! LLVM vectorizes), and the windows are split over the cores with `std::thread::scope`. The
//! burn path ([`super::loss::batch_loss`] under autodiff) stays the reference it is tested
//! against (`host-train/tests/train_parity.rs`).
//!
//! Layout of the parameters: the 18 MLP tensors in [`super::tensor_model::TModel::tensors`] order
//! (weights `[in, out]`, biases `[1, out]`, flattened row-major), then the per-flight tensor
//! `[M, p]` or `[M, p + 4]` (the a_j, then the rotor gain deviations δηⱼ).

// The kernel indexes small fixed-size arrays the way the equations do (i, j, k), and the
// reverse passes take every array they update.
#![allow(clippy::needless_range_loop, clippy::too_many_arguments)]

use super::data::Windows;
use hamflight::model::learned::{
    rot_input, CONTROL_SCALE, INERTIA_INV_EPS, INERTIA_INV_SCALE_PER_KG_M2, TORQUE_SCALE_NM,
    WRENCH_SCALE,
};
use hamflight::model::{FEATURES, GRAVITY_M_S2, HIDDEN};
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// Windows per lane group.
const LANES: usize = 8;
const H: usize = HIDDEN;
const P: usize = FEATURES;
const OI: usize = 6;
const OG: usize = 24;
const OD: usize = 6 * P;
/// Rotor gains per flight.
const NR: usize = 4;
/// l index k → row-major position in L (the lower triangle).
const L_POS: [usize; 6] = [0, 3, 4, 6, 7, 8];

mod group;
mod lanes;
mod mlp;
mod point;
mod rhs;

use group::*;
use lanes::*;
use mlp::*;
use point::*;
use rhs::*;

/// The mean loss over the windows `ids` of `data` and its gradient for every parameter tensor
/// (`params`: the 18 MLP tensors then the per-flight one, flattened; see the module doc), with
/// the windows split over `threads` threads. `None` when the tensors' sizes are not the core's
/// compile-time ones (hidden 16, p = 6) or the per-flight tensor's width is neither p nor
/// p + 4.
pub fn loss_and_grads(
    data: &Windows,
    ids: &[usize],
    params: &[Vec<f32>],
    dt_s: f32,
    vel_weight: f32,
    threads: usize,
) -> Option<(f64, Vec<Vec<f32>>)> {
    loss_and_grads_on(data, ids, params, dt_s, vel_weight, threads, Isa::Best)
}

/// The instruction set the kernel runs with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// The best the CPU has (AVX-512VL, AVX2 or the baseline; [`loss_and_grads`]).
    Best,
    /// The build's baseline target (on x86_64 SSE2), whatever the CPU has: for the test of the
    /// path other CPUs take.
    Baseline,
}

/// [`loss_and_grads`] with the instruction set `isa`.
pub fn loss_and_grads_on(
    data: &Windows,
    ids: &[usize],
    params: &[Vec<f32>],
    dt_s: f32,
    vel_weight: f32,
    threads: usize,
    isa: Isa,
) -> Option<(f64, Vec<Vec<f32>>)> {
    if params.len() != 19 || ids.is_empty() || data.window_len < 2 {
        return None;
    }
    let nets = Nets {
        i: Head::from_flat(&params[0..6])?,
        g: Head::from_flat(&params[6..12])?,
        d: Head::from_flat(&params[12..18])?,
    };
    let pf = &params[18];
    let n_flights = data.realizations.len().max(1);
    if !pf.len().is_multiple_of(n_flights) {
        return None;
    }
    let width = pf.len() / n_flights;
    if width != P && width != P + NR {
        return None;
    }
    if ids.iter().any(|&i| {
        data.windows
            .get(i)
            .is_none_or(|w| w.realization >= n_flights)
    }) {
        return None;
    }
    let k = K::new(data.mass_kg, dt_s, vel_weight);
    let batch = ids.len();
    let groups: Vec<&[usize]> = ids.chunks(LANES).collect();
    let threads = threads.clamp(1, groups.len());
    let per = groups.len().div_ceil(threads);
    let run = |part: &[&[usize]]| -> Grads {
        let mut g = Grads {
            i: HeadGrad::zero(),
            g: HeadGrad::zero(),
            d: HeadGrad::zero(),
            per_flight: vec![0.0; pf.len()],
            loss: 0.0,
        };
        let mut sc = Scratch {
            pts: Vec::new(),
            recs: Vec::new(),
            adj: Vec::new(),
            states: Vec::new(),
            un: Vec::new(),
            rotors: Vec::new(),
        };
        for ids in part {
            let gr = Group::load(data, ids, batch);
            if isa == Isa::Baseline {
                group(&k, &nets, pf, width, &gr, &mut sc, &mut g);
            } else {
                group_dispatch(&k, &nets, pf, width, &gr, &mut sc, &mut g);
            }
        }
        g
    };
    let parts: Vec<Grads> = if threads == 1 {
        vec![run(&groups)]
    } else {
        // The first part on this thread, the others on threads of their own.
        let mut chunks = groups.chunks(per);
        let first = chunks.next().unwrap_or(&[]);
        std::thread::scope(|s| {
            let hs: Vec<_> = chunks.map(|p| s.spawn(move || run(p))).collect();
            let mut out = vec![run(first)];
            out.extend(hs.into_iter().filter_map(|h| h.join().ok()));
            out
        })
    };
    let mut loss = 0.0;
    let mut out: Vec<Vec<f32>> = Vec::new();
    for g in parts {
        loss += g.loss;
        let mut flat: Vec<Vec<f32>> = Vec::with_capacity(19);
        flat.extend(g.i.flat());
        flat.extend(g.g.flat());
        flat.extend(g.d.flat());
        flat.push(g.per_flight);
        if out.is_empty() {
            out = flat;
        } else {
            for (o, f) in out.iter_mut().zip(flat) {
                for (a, b) in o.iter_mut().zip(f) {
                    *a += b;
                }
            }
        }
    }
    Some((loss, out))
}

/// [`group`] compiled for the best vector extension the CPU has: AVX-512VL (32 vector
/// registers) or AVX2 (a lane group then fills one 256-bit register), or the baseline target
/// (SSE2: two registers), each faster than the one before it under `host-train bench-train`.
/// Explicit FMA (`f32::mul_add`) was slower there, so the lanes multiply and add apart
/// (docs/performance.md, "Training speed", has the figures).
fn group_dispatch(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx2") && has!("avx512f") && has!("avx512vl") {
            // SAFETY: the CPU has every feature `group_avx512` enables (checked just above).
            unsafe { group_avx512(k, n, pf, width, gr, sc, g) };
            return;
        }
        if has!("avx2") {
            // SAFETY: the CPU has every feature `group_avx2` enables (checked just above).
            unsafe { group_avx2(k, n, pf, width, gr, sc, g) };
            return;
        }
    }
    group(k, n, pf, width, gr, sc, g);
}

/// [`group`] with AVX2 and AVX-512VL enabled (the same 8-lane code with 32 vector registers
/// instead of 16: fewer spills).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
fn group_avx512(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
    group(k, n, pf, width, gr, sc, g);
}

/// [`group`] with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn group_avx2(
    k: &K,
    n: &Nets,
    pf: &[f32],
    width: usize,
    gr: &Group,
    sc: &mut Scratch,
    g: &mut Grads,
) {
    group(k, n, pf, width, gr, sc, g);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rational tanh stays within a few ulp of the library's over the range that matters.
    #[test]
    fn fast_tanh_matches_the_library() {
        let mut worst = 0f32;
        for i in -200_000..=200_000 {
            let x = i as f32 * 1e-4;
            let e = (tanh_f32(x) - (x as f64).tanh() as f32).abs();
            worst = worst.max(e / (x as f64).tanh().abs().max(1e-30) as f32);
        }
        assert!(worst < 2e-6, "worst relative error {worst}");
        assert_eq!(tanh_f32(30.0), 1.0);
        assert_eq!(tanh_f32(-30.0), -1.0);
    }
}
