//! The data-efficiency baseline: a black-box MLP dynamics model trained on the same windows as the
//! structured (Hamiltonian) model, for the data-efficiency comparison.
//!
//! The model is one tanh MLP f(R, v, ω/10, u/CONTROL_SCALE, one-hot j) → ẋ for the 18-d state
//! (p, R row-major, v, ω); its output is de-normalized by the per-component mean and standard
//! deviation of the training windows' finite differences. The one-hot j times the first layer's
//! weights is a learned per-realization embedding (the analogue of a_j). It is integrated with
//! RK4 through each 5-state window with the control held constant — in the ambient ℝ¹⁸, with no
//! re-orthonormalization of R (the absence of structure is the point) — and trained with the
//! structured model's loss (ℓ_p + ℓ_R + vel_weight·ℓ_v + ℓ_ω), Adam schedule, batch and seed.
//! Held-out errors are those of [`super::export::prediction_errors`] at the last step, the
//! predicted R first projected to the nearest rotation; ‖RᵀR − I‖ is reported alongside.

use super::adam::Adam;
use super::data::{self, Batch, StateBatch, Windows};
use super::loss::window_loss;
use super::tensor_model::{to_vec, TMlp};
use super::TrainConfig;
use anyhow::Result;
use burn::tensor::{Device, Tensor, TensorData};
use hamflight::model::learned::CONTROL_SCALE;
use nalgebra::{Matrix3, Vector3};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Hidden width of the black-box MLP: with 27 inputs and 18 outputs, 32 gives 2546 parameters
/// (the structured model's three 9→16→16→{6, 24, 36} heads and 8×6 a_j: 2466).
pub const BB_HIDDEN: usize = 32;
/// Dimension of the state derivative.
const OUT: usize = 18;

/// Step-N RMS held-out errors (the last predicted state of each window).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Errors {
    /// ‖p − p̄‖ (m).
    pub pos_m: f64,
    /// Rotation angle between R̄ and the predicted R (projected to SO(3) for the black box).
    pub rot_rad: f64,
    /// ‖v − v̄‖ (m/s).
    pub vel_m_s: f64,
    /// ‖ω − ω̄‖ (rad/s).
    pub rate_rad_s: f64,
}

/// One row of the comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// Fraction of the training windows used.
    pub data_frac: f64,
    /// Training windows used.
    pub train_windows: usize,
    /// Structured model: held-out errors, final held-out loss, training time (s).
    pub structured: Errors,
    /// The structured model's final held-out loss.
    pub structured_val_loss: f64,
    /// The structured model's training time (s).
    pub structured_time_s: f64,
    /// Black-box model: held-out errors.
    pub blackbox: Errors,
    /// The black box's final held-out loss (same loss as the structured model's).
    pub blackbox_val_loss: f64,
    /// The black box's training time (s).
    pub blackbox_time_s: f64,
    /// RMS over held-out windows of ‖RᵀR − I‖_F of the black box's last predicted R.
    pub blackbox_orth_err: f64,
    /// Largest ‖RᵀR − I‖_F over the held-out windows.
    pub blackbox_orth_err_max: f64,
    /// Black-box parameter count.
    pub blackbox_params: usize,
}

/// Per-component mean and standard deviation of the finite-difference state derivatives of the
/// training windows, in the output order (ṗ, Ṙ row-major, v̇, ω̇).
fn derivative_stats(data: &Windows, ids: &[usize]) -> (Vec<f32>, Vec<f32>) {
    let dt = 1.0 / f64::from(data.sample_hz);
    let mut sum = [0f64; OUT];
    let mut sq = [0f64; OUT];
    let mut n = 0f64;
    for &i in ids {
        let w = &data.windows[i];
        for k in 0..w.states.len() - 1 {
            let (a, b) = (&w.states[k], &w.states[k + 1]);
            let mut d = [0f64; OUT];
            for c in 0..3 {
                d[c] = f64::from(b.p_m[c] - a.p_m[c]) / dt;
                d[12 + c] = f64::from(b.v_body_m_s[c] - a.v_body_m_s[c]) / dt;
                d[15 + c] = f64::from(b.w_body_rad_s[c] - a.w_body_rad_s[c]) / dt;
            }
            for r in 0..3 {
                for c in 0..3 {
                    d[3 + 3 * r + c] = f64::from(b.rot[(r, c)] - a.rot[(r, c)]) / dt;
                }
            }
            for c in 0..OUT {
                sum[c] += d[c];
                sq[c] += d[c] * d[c];
            }
            n += 1.0;
        }
    }
    let n = n.max(1.0);
    let mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
    let std: Vec<f32> = (0..OUT)
        .map(|c| {
            let m = sum[c] / n;
            ((sq[c] / n - m * m).max(0.0).sqrt().max(1e-6)) as f32
        })
        .collect();
    (mean, std)
}

/// The black-box model's state: p [B,3], R row-major [B,9], v [B,3], ω [B,3].
#[derive(Clone)]
struct BState {
    p: Tensor<2>,
    r: Tensor<2>,
    v: Tensor<2>,
    w: Tensor<2>,
}

impl BState {
    fn axpy(&self, h: f32, d: &BState) -> BState {
        BState {
            p: self.p.clone() + d.p.clone().mul_scalar(h),
            r: self.r.clone() + d.r.clone().mul_scalar(h),
            v: self.v.clone() + d.v.clone().mul_scalar(h),
            w: self.w.clone() + d.w.clone().mul_scalar(h),
        }
    }
}

/// The black box with its fixed normalizations.
struct BlackBox {
    net: TMlp,
    out_mean: Tensor<2>,
    out_std: Tensor<2>,
}

/// Inputs that stay constant through each step of a window: [u_k / CONTROL_SCALE, one-hot j]
/// [B, 4 + M], one tensor per step k.
fn window_inputs(data: &Windows, ids: &[usize], device: &Device) -> Vec<Tensor<2>> {
    let m = data.realizations.len();
    (0..data.window_len - 1)
        .map(|k| {
            let mut x = Vec::with_capacity(ids.len() * (4 + m));
            for &i in ids {
                let w = &data.windows[i];
                x.extend(w.u[k].iter().zip(CONTROL_SCALE.iter()).map(|(u, s)| u / s));
                x.extend((0..m).map(|j| if j == w.realization { 1.0 } else { 0.0 }));
            }
            Tensor::from_data(TensorData::new(x, [ids.len(), 4 + m]), device)
        })
        .collect()
}

impl BlackBox {
    fn rhs(&self, x: &BState, fixed: &Tensor<2>) -> BState {
        let input = Tensor::cat(
            vec![
                x.r.clone(),
                x.v.clone(),
                x.w.clone().mul_scalar(0.1),
                fixed.clone(),
            ],
            1,
        );
        let y = self.net.forward(input).y * self.out_std.clone() + self.out_mean.clone();
        BState {
            p: y.clone().narrow(1, 0, 3),
            r: y.clone().narrow(1, 3, 9),
            v: y.clone().narrow(1, 12, 3),
            w: y.narrow(1, 15, 3),
        }
    }

    fn rk4(&self, x: &BState, fixed: &Tensor<2>, dt: f32) -> BState {
        let k1 = self.rhs(x, fixed);
        let k2 = self.rhs(&x.axpy(0.5 * dt, &k1), fixed);
        let k3 = self.rhs(&x.axpy(0.5 * dt, &k2), fixed);
        let k4 = self.rhs(&x.axpy(dt, &k3), fixed);
        let h6 = dt / 6.0;
        let comb = |x: &Tensor<2>, a: Tensor<2>, b: Tensor<2>, c: Tensor<2>, d: Tensor<2>| {
            x.clone() + (a + (b + c).mul_scalar(2.0) + d).mul_scalar(h6)
        };
        BState {
            p: comb(&x.p, k1.p, k2.p, k3.p, k4.p),
            r: comb(&x.r, k1.r, k2.r, k3.r, k4.r),
            v: comb(&x.v, k1.v, k2.v, k3.v, k4.v),
            w: comb(&x.w, k1.w, k2.w, k3.w, k4.w),
        }
    }

    /// The predicted states x₁..x_N of a batch, step k under `fixed[k]`.
    fn rollout(&self, b: &Batch, fixed: &[Tensor<2>], dt: f32) -> Vec<BState> {
        let s0 = &b.states[0];
        let mut x = BState {
            p: s0.p.clone(),
            r: s0.rot.clone().reshape([b.len, 9]),
            v: s0.v.clone(),
            w: s0.w.clone(),
        };
        let mut out = Vec::with_capacity(fixed.len());
        for f in fixed {
            x = self.rk4(&x, f, dt);
            out.push(x.clone());
        }
        out
    }

    /// The structured model's loss ([`super::loss::batch_loss`]): mean over windows of
    /// Σₙ ℓ_p + ℓ_R + vel_weight ℓ_v + ℓ_ω.
    fn loss(&self, b: &Batch, fixed: &[Tensor<2>], dt: f32, vel_weight: f32) -> Tensor<1> {
        let preds = self.rollout(b, fixed, dt).into_iter().map(|x| StateBatch {
            p: x.p,
            rot: x.r.reshape([b.len, 3, 3]),
            v: x.v,
            w: x.w,
        });
        window_loss(preds, b, vel_weight)
    }
}

/// Xavier-uniform layers `[in, out]` (output layer scaled by `out_gain`), zero biases.
fn init(seed: u64, dims: [usize; 4], out_gain: f32, device: &Device) -> Vec<Tensor<2>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut t = Vec::with_capacity(6);
    for l in 0..3 {
        let (i, o) = (dims[l], dims[l + 1]);
        let gain = if l == 2 { out_gain } else { 1.0 };
        let bound = (6.0 / (i + o) as f32).sqrt() * gain;
        let w: Vec<f32> = (0..i * o).map(|_| rng.gen_range(-bound..bound)).collect();
        t.push(Tensor::from_data(TensorData::new(w, [i, o]), device));
        t.push(Tensor::zeros([1, o], device));
    }
    t
}

/// What training the black box produced.
pub struct BlackBoxResult {
    /// Step-N held-out errors.
    pub errors: Errors,
    /// RMS and max over held-out windows of ‖RᵀR − I‖_F at step N.
    pub orth_err: (f64, f64),
    /// Final held-out loss.
    pub val_loss: f64,
    /// Training time (s).
    pub time_s: f64,
    /// Parameter count.
    pub params: usize,
}

/// Trains the black box on `train` (same Adam schedule, batch, epochs, seed and loss weights as
/// `cfg`) and evaluates it on `heldout`.
pub fn train_blackbox(
    cfg: &TrainConfig,
    data: &Windows,
    train: &[usize],
    heldout: &[usize],
) -> BlackBoxResult {
    let device = Device::flex();
    let ad = device.clone().autodiff();
    let dt = 1.0 / data.sample_hz;
    let n_in = 9 + 3 + 3 + 4 + data.realizations.len();
    let (mean, std) = derivative_stats(data, train);
    let consts = |d: &Device| {
        (
            Tensor::<2>::from_data(TensorData::new(mean.clone(), [1, OUT]), d),
            Tensor::<2>::from_data(TensorData::new(std.clone(), [1, OUT]), d),
        )
    };
    let (mean_ad, std_ad) = consts(&ad);
    let mut params = init(
        cfg.seed,
        [n_in, BB_HIDDEN, BB_HIDDEN, OUT],
        cfg.init_out_gain,
        &device,
    );
    let n_params: usize = params
        .iter()
        .map(|p| p.dims().iter().product::<usize>())
        .sum();
    let mut adam = Adam::new(&params);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(1));
    let start = Instant::now();
    let mut order = train.to_vec();
    for epoch in 1..=cfg.epochs {
        let frac = (epoch - 1) as f64 / cfg.epochs.max(1) as f64;
        let lr = cfg.lr * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * frac).cos()));
        order.shuffle(&mut rng);
        for chunk in order.chunks(cfg.batch.max(1)) {
            let b = data::batch(data, chunk, &ad);
            let fixed = window_inputs(data, chunk, &ad);
            let leaves: Vec<Tensor<2>> = params
                .iter()
                .map(|p| p.clone().autodiff().require_grad())
                .collect();
            let model = BlackBox {
                net: TMlp::from_tensors(&leaves),
                out_mean: mean_ad.clone(),
                out_std: std_ad.clone(),
            };
            let loss = model.loss(&b, &fixed, dt, cfg.vel_weight);
            let grads = loss.backward();
            let g: Vec<Option<Tensor<2>>> = leaves
                .iter()
                .zip(params.iter())
                .map(|(l, p)| Some(l.grad(&grads).unwrap_or_else(|| p.zeros_like())))
                .collect();
            if f64::from(to_vec(&loss.inner())[0]).is_finite() {
                adam.step(&mut params, &g, &vec![lr; g.len()]);
            }
        }
    }
    let time_s = start.elapsed().as_secs_f64();
    let (mean_p, std_p) = consts(&device);
    let model = BlackBox {
        net: TMlp::from_tensors(&params),
        out_mean: mean_p,
        out_std: std_p,
    };
    let (errors, orth_err, val_loss) = evaluate(&model, data, heldout, dt, cfg.vel_weight, &device);
    BlackBoxResult {
        errors,
        orth_err,
        val_loss,
        time_s,
        params: n_params,
    }
}

/// The nearest rotation to `m` (polar factor by SVD; det fixed to +1).
fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let d = (u * vt).determinant().signum();
    u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt
}

/// Step-N held-out errors, ‖RᵀR − I‖ (RMS, max) and the mean held-out loss.
fn evaluate(
    model: &BlackBox,
    data: &Windows,
    ids: &[usize],
    dt: f32,
    vel_weight: f32,
    device: &Device,
) -> (Errors, (f64, f64), f64) {
    let mut acc = [0f64; 4];
    let (mut orth_sq, mut orth_max, mut loss_sum) = (0f64, 0f64, 0f64);
    for chunk in ids.chunks(1024) {
        let b = data::batch(data, chunk, device);
        let fixed = window_inputs(data, chunk, device);
        loss_sum +=
            f64::from(to_vec(&model.loss(&b, &fixed, dt, vel_weight))[0]) * chunk.len() as f64;
        let last = model.rollout(&b, &fixed, dt).pop();
        let Some(x) = last else { continue };
        let (p, r, v, w) = (to_vec(&x.p), to_vec(&x.r), to_vec(&x.v), to_vec(&x.w));
        for (n, &i) in chunk.iter().enumerate() {
            let Some(t) = data.windows[i].states.last() else {
                continue;
            };
            let vec3 = |a: &[f32]| Vector3::from_fn(|k, _| f64::from(a[3 * n + k]));
            let rm = Matrix3::from_fn(|a, c| f64::from(r[9 * n + 3 * a + c]));
            let tr = t.rot.map(f64::from);
            acc[0] += (vec3(&p) - t.p_m.map(f64::from)).norm_squared();
            let rel = tr.transpose() * nearest_rotation(&rm);
            let cos = ((rel.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
            // Small angles: from the skew part, where acos loses precision.
            let skew = (rel - rel.transpose()) * 0.5;
            let sin = Vector3::new(skew[(2, 1)], skew[(0, 2)], skew[(1, 0)]).norm();
            acc[1] += sin.atan2(cos).powi(2);
            acc[2] += (vec3(&v) - t.v_body_m_s.map(f64::from)).norm_squared();
            acc[3] += (vec3(&w) - t.w_body_rad_s.map(f64::from)).norm_squared();
            let o = (rm.transpose() * rm - Matrix3::identity()).norm();
            orth_sq += o * o;
            orth_max = orth_max.max(o);
        }
    }
    let m = ids.len().max(1) as f64;
    let errors = Errors {
        pos_m: (acc[0] / m).sqrt(),
        rot_rad: (acc[1] / m).sqrt(),
        vel_m_s: (acc[2] / m).sqrt(),
        rate_rad_s: (acc[3] / m).sqrt(),
    };
    (errors, ((orth_sq / m).sqrt(), orth_max), loss_sum / m)
}

/// The data-efficiency comparison at each of `fractions` of the training windows: the structured
/// model ([`super::fit`]: trained only, nothing flown or written) and the black box, both
/// with `epochs` epochs, batch 128, seed 0 and the default held-out split.
///
/// # Errors
/// A dataset that cannot be read, or a failed structured run.
pub fn compare(data_dir: &Path, fractions: &[f64], epochs: usize) -> Result<Vec<Row>> {
    let cfg = TrainConfig {
        epochs,
        batch: 128,
        seed: 0,
        ..TrainConfig::default()
    };
    let windows = data::load(data_dir, cfg.window)?;
    let (train_ids, heldout) = data::split(&windows, cfg.heldout_frac, cfg.seed);
    let mut rows = Vec::with_capacity(fractions.len());
    for &frac in fractions {
        let ids = data::subset(&windows, &train_ids, frac);
        let bb = train_blackbox(&cfg, &windows, &ids, &heldout);
        eprintln!(
            "frac {frac}: black box ({} params) trained on {} windows in {:.0} s, held-out loss {:.3e}",
            bb.params,
            ids.len(),
            bb.time_s,
            bb.val_loss
        );
        let scfg = TrainConfig {
            data_frac: frac,
            ..cfg.clone()
        };
        // Trained only: the comparison is on held-out prediction, nothing is flown or written.
        let rep = super::fit(&scfg, data_dir, true)?.report;
        let last = |v: &[f64]| v.last().copied().unwrap_or(f64::NAN);
        let h = &rep.heldout_learned;
        eprintln!(
            "frac {frac}: structured trained on {} windows in {:.0} s, held-out loss {:.3e}",
            rep.train_windows, rep.train_time_s, rep.final_val_loss
        );
        rows.push(Row {
            data_frac: frac,
            train_windows: ids.len(),
            structured: Errors {
                pos_m: last(&h.pos_m),
                rot_rad: last(&h.rot_rad),
                vel_m_s: last(&h.vel_m_s),
                rate_rad_s: last(&h.rate_rad_s),
            },
            structured_val_loss: rep.final_val_loss,
            structured_time_s: rep.train_time_s,
            blackbox: bb.errors,
            blackbox_val_loss: bb.val_loss,
            blackbox_time_s: bb.time_s,
            blackbox_orth_err: bb.orth_err.0,
            blackbox_orth_err_max: bb.orth_err.1,
            blackbox_params: bb.params,
        });
    }
    Ok(rows)
}
