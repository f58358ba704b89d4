//! The training loss (paper Problem 1): RK4 through each window in (q, 𝔭), each step with its
//! own logged command and d = W a_j inside the ODE, ℓ_p + ℓ_R + ℓ_ζ summed over the window's
//! predicted states.

use super::data::{self, Batch, StateBatch, Windows};
use super::tensor_model::{
    mat_mat_t, rk4_with, to_phase_with, to_vec, velocities_with, Consts, Forcing, FusedHeads,
    TModel,
};
use burn::tensor::Tensor;

/// The largest minibatch [`batch_loss`] runs the heads fused for (measured with
/// `host-train bench-train`: fused is faster at 128 and 256, slower at 7,776).
const FUSE_MAX_BATCH: usize = 1024;

/// The loss of a batch: Σₙ (ℓ_p + ℓ_R + ℓ_ζ) per window, and its mean over the batch.
/// `vel_weight` weighs ‖v − v̄‖² inside ℓ_ζ (`TrainConfig::vel_weight`).
pub fn batch_loss(
    model: &TModel,
    c: &Consts,
    a_all: Tensor<2>,
    b: &Batch,
    dt_s: f32,
    vel_weight: f32,
) -> Tensor<1> {
    // Each state's head outputs computed once: they serve the velocities read there and the
    // next step's first RK4 stage. Small batches run the three heads as one network (fewer
    // ops); large ones apart (the fused layers' zero blocks cost more than the ops saved).
    let fused = (b.len <= FUSE_MAX_BATCH).then(|| FusedHeads::new(model));
    let head = fused.as_ref().map_or(&model.inertia, |f| f.inertia_head());
    let nets_at = |rot: &Tensor<3>| match &fused {
        Some(f) => f.nets(c, rot),
        None => model.nets(c, rot),
    };
    let s0 = &b.states[0];
    let n0 = nets_at(&s0.rot);
    let mut x = to_phase_with(
        c,
        &n0.inertia,
        s0.p.clone(),
        s0.rot.clone(),
        s0.v.clone(),
        s0.w.clone(),
    );
    // a_j is selected once per batch (one node in the graph); only the command changes per step.
    let mut forcing: Option<Forcing> = None;
    let mut nets = Some(n0);
    let preds = b.u.iter().map(|u| {
        let f = match forcing.take() {
            None => Forcing::new(c, u.clone(), a_all.clone(), b.realization.clone()),
            Some(prev) => prev.with_control(c, u.clone()),
        };
        let n_x = nets.take().unwrap_or_else(|| nets_at(&x.rot));
        x = rk4_with(c, &nets_at, head, &x, n_x, &f, dt_s);
        let n = nets_at(&x.rot);
        let (v, w) = velocities_with(c, &n.inertia, &x);
        nets = Some(n);
        forcing = Some(f);
        StateBatch {
            p: x.p.clone(),
            rot: x.rot.clone(),
            v,
            w,
        }
    });
    window_loss(preds, b, vel_weight)
}

/// [`batch_loss`] by the model's plain methods: each head on its own and J⁻¹(q) evaluated
/// again wherever it is needed. The same value (to rounding); kept as the reference the fused
/// path is tested against, and timed by `host-train bench-train --reference`.
pub fn batch_loss_reference(
    model: &TModel,
    c: &Consts,
    a_all: Tensor<2>,
    b: &Batch,
    dt_s: f32,
    vel_weight: f32,
) -> Tensor<1> {
    let s0 = &b.states[0];
    let mut x = model.to_phase(c, s0.p.clone(), s0.rot.clone(), s0.v.clone(), s0.w.clone());
    let mut forcing: Option<Forcing> = None;
    let preds = b.u.iter().map(|u| {
        let f = match forcing.take() {
            None => Forcing::new(c, u.clone(), a_all.clone(), b.realization.clone()),
            Some(prev) => prev.with_control(c, u.clone()),
        };
        x = model.rk4(c, &x, &f, dt_s);
        forcing = Some(f);
        let (v, w) = model.velocities(c, &x);
        StateBatch {
            p: x.p.clone(),
            rot: x.rot.clone(),
            v,
            w,
        }
    });
    window_loss(preds, b, vel_weight)
}

/// Mean held-out loss per window, in chunks, without autodiff.
pub fn eval_loss(
    model: &TModel,
    c: &Consts,
    a_all: &Tensor<2>,
    data: &Windows,
    ids: &[usize],
    dt_s: f32,
    vel_weight: f32,
) -> f64 {
    let device = &a_all.device();
    if ids.is_empty() {
        return f64::NAN;
    }
    let mut sum = 0.0;
    for chunk in ids.chunks(2048) {
        let b = data::batch(data, chunk, device);
        let l = batch_loss(model, c, a_all.clone(), &b, dt_s, vel_weight);
        sum += f64::from(to_vec(&l)[0]) * chunk.len() as f64;
    }
    sum / ids.len() as f64
}

/// The TSE(3) loss of a predicted window (paper Sec. 3): Σₙ ℓ_p + ℓ_R + `vel_weight`·ℓ_v + ℓ_ω
/// per window over the predicted states x₁..x_N against `b`'s, then the mean over the batch.
pub fn window_loss(
    preds: impl IntoIterator<Item = StateBatch>,
    b: &Batch,
    vel_weight: f32,
) -> Tensor<1> {
    let mut total: Option<Tensor<2>> = None;
    for (x, target) in preds.into_iter().zip(b.states.iter().skip(1)) {
        let lp = (x.p - target.p.clone()).square().sum_dim(1);
        let lr = rotation_loss(x.rot, target.rot.clone());
        let lz = (x.v - target.v.clone())
            .square()
            .sum_dim(1)
            .mul_scalar(vel_weight)
            + (x.w - target.w.clone()).square().sum_dim(1);
        let l = lp + lr + lz;
        total = Some(match total {
            Some(t) => t + l,
            None => l,
        });
    }
    total
        .unwrap_or_else(|| Tensor::zeros([1, 1], &b.realization.device()))
        .mean()
}

/// ‖log(R̄ Rᵀ)^∨‖² per window `[B,1]`, from sin²θ = ‖vee(E)‖² by the series
/// θ² = s + s²/3 + 8 s³/45 (s = sin²θ), exact to O(θ⁸) and smooth at θ = 0, where acos is not;
/// prediction errors over a 5-state window are far below the quarter turn where it would matter.
pub fn rotation_loss(r_pred: Tensor<3>, r_true: Tensor<3>) -> Tensor<2> {
    let b = r_pred.dims()[0];
    let e = mat_mat_t(r_pred, r_true);
    let skew = (e.clone() - e.swap_dims(1, 2))
        .mul_scalar(0.5)
        .reshape([b, 9]);
    // ‖vee‖² = ½ Σ skew² (each component appears twice).
    let s = skew.square().sum_dim(1).mul_scalar(0.5);
    s.clone()
        + s.clone().square().div_scalar(3.0)
        + s.clone().square().mul(s).mul_scalar(8.0 / 45.0)
}
