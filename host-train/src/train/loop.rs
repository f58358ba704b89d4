//! The training loop (paper Problem 1): RK4 through each window in (q, 𝔭), each step with its
//! own logged command and d = W a_j inside the ODE, loss ℓ_p + ℓ_R + ℓ_ζ summed over the window's
//! predicted states, Adam on θ (J⁻¹, g), φ (W) and the a_j.

use super::data::StateBatch;
use super::data::{self, Batch, Windows};
use super::model::{to_vec, window_loss, Consts, Forcing, TModel};
use super::TrainConfig;
use burn::tensor::{Device, Tensor, TensorData};
use hamflight::model::{ModelWeights, FEATURES};
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::time::Instant;

/// One epoch of the training curve.
#[derive(Clone, Debug, Serialize)]
pub struct EpochStats {
    /// Epoch number (1-based).
    pub epoch: usize,
    /// Mean training loss per window (over the epoch's minibatches).
    pub train_loss: f64,
    /// Mean held-out loss per window.
    pub val_loss: f64,
    /// Wall time since the start of training (s).
    pub elapsed_s: f64,
}

/// What training produced.
pub struct Trained {
    /// θ and φ.
    pub weights: ModelWeights,
    /// a_j per realization.
    pub a: Vec<[f32; FEATURES]>,
    /// The training curve.
    pub curve: Vec<EpochStats>,
    /// Held-out loss of the initial (prior) model.
    pub initial_val_loss: f64,
}

/// Initial weights: hidden layers Xavier-uniform from `seed`, output layers scaled by
/// `out_gain` around the physical prior's biases ([`ModelWeights::prior`]), so J⁻¹, g and W
/// start near the CF2X's J⁻¹, the true g and the nominal features.
pub fn init_weights(seed: u64, out_gain: f32) -> ModelWeights {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut w = ModelWeights::prior();
    macro_rules! xavier {
        ($layer:expr, $gain:expr) => {{
            let fan_in = $layer.weight[0].len() as f32;
            let fan_out = $layer.weight.len() as f32;
            let bound = (6.0 / (fan_in + fan_out)).sqrt() * $gain;
            for v in $layer.weight.iter_mut().flatten() {
                *v = rng.gen_range(-bound..bound);
            }
        }};
    }
    xavier!(w.inertia.l0, 1.0);
    xavier!(w.inertia.l1, 1.0);
    xavier!(w.inertia.l2, out_gain);
    xavier!(w.gain.l0, 1.0);
    xavier!(w.gain.l1, 1.0);
    xavier!(w.gain.l2, out_gain);
    xavier!(w.disturbance.l0, 1.0);
    xavier!(w.disturbance.l1, 1.0);
    xavier!(w.disturbance.l2, out_gain);
    w
}

/// The loss of a batch: Σₙ (ℓ_p + ℓ_R + ℓ_ζ) per window, and its mean over the batch.
/// `vel_weight` weighs ‖v − v̄‖² inside ℓ_ζ ([`TrainConfig::vel_weight`]).
pub fn batch_loss(
    model: &TModel,
    c: &Consts,
    a_all: Tensor<2>,
    b: &Batch,
    dt_s: f32,
    vel_weight: f32,
) -> Tensor<1> {
    let s0 = &b.states[0];
    let mut x = model.to_phase(c, s0.p.clone(), s0.rot.clone(), s0.v.clone(), s0.w.clone());
    // a_j is selected once per batch (one node in the graph); only the command changes per step.
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

/// Adam (β₁ = 0.9, β₂ = 0.999, ε = 1e-8) on a list of tensors, a learning rate per tensor.
pub struct Adam {
    m: Vec<Tensor<2>>,
    v: Vec<Tensor<2>>,
    t: i32,
}

impl Adam {
    /// Zero moments for `params`.
    pub fn new(params: &[Tensor<2>]) -> Self {
        Self {
            m: params.iter().map(|p| p.zeros_like()).collect(),
            v: params.iter().map(|p| p.zeros_like()).collect(),
            t: 0,
        }
    }

    /// One Adam step (β₁ = 0.9, β₂ = 0.999, ε = 1e-8) with a learning rate per tensor.
    pub fn step(&mut self, params: &mut [Tensor<2>], grads: &[Tensor<2>], lrs: &[f64]) {
        self.t += 1;
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        let c1 = 1.0 - b1.powi(self.t);
        let c2 = 1.0 - b2.powi(self.t);
        for i in 0..params.len() {
            let g = grads[i].clone();
            self.m[i] = self.m[i].clone().mul_scalar(b1) + g.clone().mul_scalar(1.0 - b1);
            self.v[i] = self.v[i].clone().mul_scalar(b2) + g.square().mul_scalar(1.0 - b2);
            let mhat = self.m[i].clone().div_scalar(c1);
            let vhat = self.v[i].clone().div_scalar(c2);
            let upd = mhat / vhat.sqrt().add_scalar(eps);
            params[i] = params[i].clone() - upd.mul_scalar(lrs[i]);
        }
    }
}

/// Index in [`TModel::tensors`] of the W head's input-layer weight (J⁻¹ and g heads take 6 each).
const FEATURE_INPUT_WEIGHT: usize = 12;

/// Trains on `train` windows, validating on `heldout` after every epoch.
pub fn train(
    cfg: &TrainConfig,
    data: &Windows,
    train: &[usize],
    heldout: &[usize],
    quiet: bool,
) -> Trained {
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let c_plain = Consts::new(&device, data.mass_kg);
    let c_ad = Consts::new(&ad, data.mass_kg);
    let dt_s = 1.0 / data.sample_hz;
    let n_real = data.realizations.len().max(1);
    let init = init_weights(cfg.seed, cfg.init_out_gain);
    let mut params = TModel::from_core(&init, &device).tensors();
    params.push(Tensor::zeros([n_real, FEATURES], &device));
    let n_net = params.len() - 1;
    // Disturbance-free realizations keep a_j = 0: their rows are masked after every step.
    let pinned: Vec<f32> = (0..n_real)
        .map(|j| {
            let free = data.realizations.get(j).is_some_and(|r| r.disturbance_free);
            if free {
                0.0
            } else {
                1.0
            }
        })
        .collect();
    let any_pinned = pinned.contains(&0.0);
    let a_mask: Tensor<2> = Tensor::from_data(TensorData::new(pinned, [n_real, 1]), &device);
    let mut adam = Adam::new(&params);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(1));
    let val = |params: &[Tensor<2>]| {
        let model = TModel::from_tensors(&params[..n_net]);
        eval_loss(
            &model,
            &c_plain,
            &params[n_net],
            data,
            heldout,
            dt_s,
            cfg.vel_weight,
        )
    };
    let initial_val_loss = val(&params);
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(cfg.epochs as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] epoch {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(format!("val {initial_val_loss:.3e}"));
    let start = Instant::now();
    let mut curve = Vec::with_capacity(cfg.epochs);
    let mut order = train.to_vec();
    for epoch in 1..=cfg.epochs {
        // Cosine decay from lr to lr / 20.
        let frac = (epoch - 1) as f64 / cfg.epochs.max(1) as f64;
        let lr = cfg.lr * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * frac).cos()));
        let mut lrs = vec![lr; params.len()];
        lrs[n_net] = lr * cfg.a_lr_scale;
        order.shuffle(&mut rng);
        let (mut sum, mut count) = (0.0, 0usize);
        for chunk in order.chunks(cfg.batch.max(1)) {
            let b = data::batch(data, chunk, &ad);
            let leaves: Vec<Tensor<2>> = params
                .iter()
                .map(|p| p.clone().autodiff().require_grad())
                .collect();
            let model = TModel::from_tensors(&leaves[..n_net]);
            let loss = batch_loss(
                &model,
                &c_ad,
                leaves[n_net].clone(),
                &b,
                dt_s,
                cfg.vel_weight,
            );
            let grads = loss.backward();
            let g: Vec<Tensor<2>> = leaves
                .iter()
                .zip(params.iter())
                .map(|(l, p)| l.grad(&grads).unwrap_or_else(|| p.zeros_like()))
                .collect();
            let lv = f64::from(to_vec(&loss.inner())[0]);
            if lv.is_finite() {
                adam.step(&mut params, &g, &lrs);
                if any_pinned {
                    params[n_net] = params[n_net].clone() * a_mask.clone();
                }
                if cfg.feature_decay > 0.0 {
                    let p = &mut params[FEATURE_INPUT_WEIGHT];
                    *p = p.clone().mul_scalar(1.0 - lr * cfg.feature_decay);
                }
                sum += lv * chunk.len() as f64;
                count += chunk.len();
            }
        }
        let train_loss = sum / count.max(1) as f64;
        let val_loss = val(&params);
        curve.push(EpochStats {
            epoch,
            train_loss,
            val_loss,
            elapsed_s: start.elapsed().as_secs_f64(),
        });
        bar.set_message(format!("loss {train_loss:.3e} val {val_loss:.3e}"));
        bar.inc(1);
    }
    bar.finish();
    let model = TModel::from_tensors(&params[..n_net]);
    let a_flat = to_vec(&params[n_net]);
    let a = a_flat
        .chunks_exact(FEATURES)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect();
    Trained {
        weights: model.to_core(&c_plain),
        a,
        curve,
        initial_val_loss,
    }
}
