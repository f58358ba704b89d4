//! The training epochs (paper Problem 1): minibatches of windows through the loss
//! ([`super::loss`]), Adam ([`super::adam`]) on θ (J⁻¹, g), φ (W) and the a_j, the learning-rate
//! schedule, the stages (main, features) and the progress bar.

pub use super::adam::Adam;
use super::data::{self, Windows};
pub use super::init::{init_weights, init_weights_with_prior, with_unactuated_gain_rows_zeroed};
use super::init::{prior_of, with_rigid_body_pinned, FEATURE_INPUT_WEIGHT, RIGID_BODY_TENSORS};
pub use super::loss::{batch_loss, batch_loss_reference, eval_loss};
use super::tensor_model::{to_vec, Consts, TModel};
use super::{GradientPath, TrainConfig};
use burn::tensor::{Device, Tensor, TensorData};
use hamflight::model::{ModelWeights, FEATURES};
use indicatif::{ProgressBar, ProgressStyle};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};
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
    /// Each realization's rotor gain deviations δηⱼ (rotor i realizes 1 + δηⱼᵢ of its
    /// command; [`TrainConfig::flight_rotor_gains`]); empty when not learned.
    pub rotor_gain: Vec<[f32; ROTOR_GAINS]>,
    /// With rotor gains: the main stage's model and a_j, the training model that, with
    /// [`Trained::rotor_gain`], explains each flight (before the feature stage refits W).
    pub main_stage: Option<MainStage>,
    /// The training curve.
    pub curve: Vec<EpochStats>,
    /// Held-out loss of the initial (prior) model.
    pub initial_val_loss: f64,
}

/// The main stage's result when rotor gains are learned ([`Trained::main_stage`]).
pub struct MainStage {
    /// θ and φ after the main stage.
    pub weights: ModelWeights,
    /// Its a_j per realization.
    pub a: Vec<[f32; FEATURES]>,
}

/// Rotor gains per flight: the CF2X's four rotors.
pub const ROTOR_GAINS: usize = 4;

/// The learning rate of main-stage epoch `epoch` (1-based) of `epochs`: a linear warm-up over
/// `warmup` epochs to `lr`, then a cosine decay to lr / 20 at the last epoch.
pub fn lr_at(lr: f64, epoch: usize, epochs: usize, warmup: usize) -> f64 {
    if epoch <= warmup {
        return lr * epoch as f64 / (warmup + 1) as f64;
    }
    let span = epochs.saturating_sub(warmup).max(1) as f64;
    let frac = (epoch - warmup - 1) as f64 / span;
    lr * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * frac).cos()))
}

/// The training state shared by the stages: the tensors, Adam, the minibatch RNG.
struct Trainer<'a> {
    cfg: &'a TrainConfig,
    data: &'a Windows,
    ad: Device,
    c_ad: Consts,
    dt_s: f32,
    params: Vec<Tensor<2>>,
    n_net: usize,
    adam: Adam,
    rng: ChaCha8Rng,
    /// [M,1]: 0 for the disturbance-free realizations (a_j pinned), 1 otherwise.
    a_mask: Option<Tensor<2>>,
    /// Use [`batch_loss_reference`] (benchmarks only).
    reference: bool,
    /// Tensors frozen (no gradient, no step): the J⁻¹ and g heads in the feature stage.
    frozen: Vec<bool>,
    /// Take the loss and gradients from the hand-fused kernel ([`super::fused`]) instead of
    /// burn's autodiff: [`TrainConfig::gradient`] is [`GradientPath::Fused`].
    fused: bool,
    /// Set once the fused kernel has declined a shape and burn stood in (warned once).
    fused_declined: AtomicBool,
}

impl Trainer<'_> {
    /// One pass over `ids` in shuffled minibatches with learning rate `lr` (the a_j with
    /// `lr · a_lr_scale`). Returns the mean training loss per window.
    fn epoch(&mut self, ids: &[usize], lr: f64) -> f64 {
        let cfg = self.cfg;
        let mut lrs = vec![lr; self.params.len()];
        lrs[self.n_net] = lr * cfg.a_lr_scale;
        let mut order = ids.to_vec();
        order.shuffle(&mut self.rng);
        let (mut sum, mut count) = (0.0, 0usize);
        for chunk in order.chunks(cfg.batch.max(1)) {
            let (lv, g) = self.loss_and_grads(chunk);
            if lv.is_finite() {
                self.adam.step(&mut self.params, &g, &lrs);
                if let Some(m) = &self.a_mask {
                    self.params[self.n_net] = self.params[self.n_net].clone() * m.clone();
                }
                if cfg.feature_decay > 0.0 {
                    let p = &mut self.params[FEATURE_INPUT_WEIGHT];
                    *p = p.clone().mul_scalar(1.0 - lr * cfg.feature_decay);
                }
                sum += lv * chunk.len() as f64;
                count += chunk.len();
            }
        }
        sum / count.max(1) as f64
    }

    /// The mean loss over the windows `ids` and its gradient for every tensor, on one shard.
    fn shard_loss_and_grads(&self, ids: &[usize]) -> Shard {
        let b = data::batch(self.data, ids, &self.ad);
        let leaves: Vec<Tensor<2>> = self
            .params
            .iter()
            .zip(&self.frozen)
            .map(|(p, &frozen)| {
                let p = p.clone().autodiff();
                if frozen {
                    p
                } else {
                    p.require_grad()
                }
            })
            .collect();
        let model = TModel::from_tensors(&leaves[..self.n_net]);
        let loss_fn = if self.reference {
            batch_loss_reference
        } else {
            batch_loss
        };
        let loss = loss_fn(
            &model,
            &self.c_ad,
            leaves[self.n_net].clone(),
            &b,
            self.dt_s,
            self.cfg.vel_weight,
        );
        let grads = loss.backward();
        let g: Vec<Option<Tensor<2>>> = leaves.iter().map(|l| l.grad(&grads)).collect();
        (f64::from(to_vec(&loss.inner())[0]), g)
    }

    /// The mean loss over the windows `ids` and its gradient for every tensor: by the
    /// hand-fused kernel ([`super::fused`], the windows split over the cores) unless
    /// [`Trainer::fused`] is off or the benchmark's reference is asked for. By burn, a large
    /// minibatch is split into one shard per core, each with its own autodiff graph (the flex
    /// backend runs an op on one core), and the shards' gradients are averaged, weighted by
    /// their sizes: the whole batch's gradient, to rounding. Faster at every batch size under
    /// `host-train bench-train` on 2 cores (docs/performance.md, "Training speed"). (On a
    /// machine whose other core is busy the shards wait on each other and on the autodiff
    /// registry's lock, and it is slower at small batches.)
    fn loss_and_grads(&self, ids: &[usize]) -> Shard {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        if self.fused && !self.reference {
            if let Some(s) = self.fused_loss_and_grads(ids, cores) {
                return s;
            }
            if !self.fused_declined.swap(true, Ordering::Relaxed) {
                eprintln!(
                    "warning: the fused gradient kernel declines these shapes (hidden {}, \
                     features {}, per-flight width {}); training with burn's autodiff instead",
                    self.cfg.hidden,
                    self.cfg.features,
                    self.params[self.n_net].dims()[1]
                );
            }
        }
        if cores < 2 || ids.len() < SHARD_MIN_BATCH || self.reference {
            return self.shard_loss_and_grads(ids);
        }
        let per = ids.len().div_ceil(cores);
        let parts: Vec<(usize, Shard)> = std::thread::scope(|s| {
            let handles: Vec<_> = ids
                .chunks(per)
                .map(|part| s.spawn(move || (part.len(), self.shard_loss_and_grads(part))))
                .collect();
            handles.into_iter().filter_map(|h| h.join().ok()).collect()
        });
        let n = ids.len() as f64;
        let mut loss = 0.0;
        let mut grads: Vec<Option<Tensor<2>>> = vec![None; self.params.len()];
        for (len, (l, g)) in parts {
            let w = len as f64 / n;
            loss += l * w;
            for (acc, gi) in grads.iter_mut().zip(g) {
                let Some(gi) = gi else { continue };
                let gi = gi.mul_scalar(w);
                *acc = Some(match acc.take() {
                    Some(a) => a + gi,
                    None => gi,
                });
            }
        }
        (loss, grads)
    }
}

impl Trainer<'_> {
    /// [`Trainer::loss_and_grads`] by the hand-fused kernel on `threads` threads (`None` when
    /// it declines the shapes).
    fn fused_loss_and_grads(&self, ids: &[usize], threads: usize) -> Option<Shard> {
        let flat: Vec<Vec<f32>> = self.params.iter().map(to_vec).collect();
        let (loss, g) = super::fused::loss_and_grads(
            self.data,
            ids,
            &flat,
            self.dt_s,
            self.cfg.vel_weight,
            threads,
        )?;
        let grads = g
            .into_iter()
            .zip(&self.params)
            .zip(&self.frozen)
            .map(|((g, p), &frozen)| {
                (!frozen).then(|| Tensor::from_data(TensorData::new(g, p.dims()), &p.device()))
            })
            .collect();
        Some((loss, grads))
    }
}

/// A shard's mean loss and the gradient of every tensor.
type Shard = (f64, Vec<Option<Tensor<2>>>);

/// The smallest minibatch [`Trainer::loss_and_grads`] splits over the cores (64 windows a
/// shard on 2 cores).
const SHARD_MIN_BATCH: usize = 128;

impl<'a> Trainer<'a> {
    fn new(cfg: &'a TrainConfig, data: &'a Windows, device: &Device) -> Self {
        let ad = device.clone().autodiff();
        let n_real = data.realizations.len().max(1);
        // A vehicle described at import (`import --vehicle`) starts from its own inertia.
        let prior = prior_of(data);
        let mut init = init_weights_with_prior(cfg.seed, cfg.init_out_gain, prior);
        if cfg.pin_rigid_body {
            init = with_rigid_body_pinned(&init, &prior);
        }
        let mut params = TModel::from_core(&init, device).tensors();
        let width = FEATURES
            + if cfg.flight_rotor_gains {
                ROTOR_GAINS
            } else {
                0
            };
        params.push(Tensor::zeros([n_real, width], device));
        let n_net = params.len() - 1;
        // Disturbance-free realizations keep a_j = 0: their rows are masked after every step.
        let calm: Vec<bool> = (0..n_real)
            .map(|j| data.realizations.get(j).is_some_and(|r| r.disturbance_free))
            .collect();
        let a_mask = calm.contains(&true).then(|| {
            let m: Vec<f32> = calm.iter().map(|&c| if c { 0.0 } else { 1.0 }).collect();
            Tensor::from_data(TensorData::new(m, [n_real, 1]), device)
        });
        Self {
            cfg,
            data,
            c_ad: Consts::new(&ad, data.mass_kg),
            ad,
            dt_s: 1.0 / data.sample_hz,
            adam: Adam::new(&params),
            params,
            n_net,
            rng: ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_add(1)),
            a_mask,
            reference: false,
            frozen: (0..=n_net)
                .map(|i| cfg.pin_rigid_body && i < RIGID_BODY_TENSORS)
                .collect(),
            fused: cfg.gradient == GradientPath::Fused,
            fused_declined: AtomicBool::new(false),
        }
    }
}

/// Wall time and process CPU time (s, all threads; `None` where /proc is not readable) of
/// each of `epochs` training epochs over `ids` at `cfg`'s batch size and learning rate
/// (forward, backward and Adam; no validation): `host-train bench-train`. The loss and its
/// gradient come from the hand-fused kernel ([`super::fused`]), or from burn's autodiff of
/// [`batch_loss`] (`burn`) or of [`batch_loss_reference`] (`reference`).
pub fn time_epochs(
    cfg: &TrainConfig,
    data: &Windows,
    ids: &[usize],
    epochs: usize,
    reference: bool,
    burn: bool,
) -> Vec<(f64, Option<f64>)> {
    let mut t = Trainer::new(cfg, data, &Device::flex());
    t.reference = reference;
    t.fused = t.fused && !burn && !reference;
    (0..epochs)
        .map(|_| {
            let (t0, c0) = (Instant::now(), process_cpu_s());
            t.epoch(ids, cfg.lr);
            let cpu = process_cpu_s().zip(c0).map(|(c1, c0)| c1 - c0);
            (t0.elapsed().as_secs_f64(), cpu)
        })
        .collect()
}

/// The mean loss over the windows `ids` and every tensor's gradient (flattened) at `cfg`'s
/// initial weights by burn's autodiff, with the minibatch split over the cores as burn trains
/// it (`split`) or whole: for the test that the two agree.
pub fn initial_gradients(
    cfg: &TrainConfig,
    data: &Windows,
    ids: &[usize],
    split: bool,
) -> (f64, Vec<Vec<f32>>) {
    let mut t = Trainer::new(cfg, data, &Device::flex());
    // burn's shards, not the fused kernel: this is what the shards are tested by.
    t.fused = false;
    let (loss, g) = if split {
        t.loss_and_grads(ids)
    } else {
        t.shard_loss_and_grads(ids)
    };
    let g = g
        .iter()
        .map(|g| g.as_ref().map(to_vec).unwrap_or_default())
        .collect();
    (loss, g)
}

/// The parameters [`initial_gradients`] starts from, flattened ([`TModel::tensors`] order, then
/// the per-flight tensor): for tests that move them away from the prior.
pub fn initial_params(cfg: &TrainConfig, data: &Windows) -> Vec<Vec<f32>> {
    Trainer::new(cfg, data, &Device::flex())
        .params
        .iter()
        .map(to_vec)
        .collect()
}

/// The mean loss over the windows `ids` and every tensor's gradient (flattened) at `params`
/// ([`initial_params`]' layout), by the burn path on one graph (`fused` None) or by the
/// hand-fused kernel on the cores with the instruction set `fused`
/// ([`super::fused::loss_and_grads_on`]): for the test that they agree.
///
/// # Panics
/// When `params` do not have the trainer's shapes.
pub fn gradients_at(
    cfg: &TrainConfig,
    data: &Windows,
    ids: &[usize],
    params: &[Vec<f32>],
    fused: Option<super::fused::Isa>,
) -> (f64, Vec<Vec<f32>>) {
    let mut t = Trainer::new(cfg, data, &Device::flex());
    assert_eq!(params.len(), t.params.len(), "parameter count");
    if let Some(isa) = fused {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        return super::fused::loss_and_grads_on(
            data,
            ids,
            params,
            t.dt_s,
            cfg.vel_weight,
            cores,
            isa,
        )
        .expect("the fused kernel takes the core's sizes");
    }
    for (p, v) in t.params.iter_mut().zip(params) {
        let dims = p.dims();
        assert_eq!(dims[0] * dims[1], v.len(), "tensor size");
        *p = Tensor::from_data(TensorData::new(v.clone(), dims), &p.device());
    }
    let (loss, g) = t.shard_loss_and_grads(ids);
    let g = g
        .iter()
        .map(|g| g.as_ref().map(to_vec).unwrap_or_default())
        .collect();
    (loss, g)
}

/// User + system CPU time of this process (s) from `/proc/self/stat` (Linux, 100 ticks/s).
fn process_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesized command name: state is field 3, utime 14, stime 15.
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok());
    Some((ticks(11)? + ticks(12)?) / 100.0)
}

/// Trains on `train` windows, validating on `heldout` after every epoch: `cfg.epochs` epochs
/// ([`lr_at`]: warm-up, cosine decay), stopping early after `cfg.patience` epochs without a
/// better held-out loss; the best epoch's tensors are kept.
pub fn train(
    cfg: &TrainConfig,
    data: &Windows,
    train: &[usize],
    heldout: &[usize],
    quiet: bool,
) -> Trained {
    let device = Device::flex();
    let c_plain = Consts::new(&device, data.mass_kg);
    let dt_s = 1.0 / data.sample_hz;
    let mut t = Trainer::new(cfg, data, &device);
    let n_net = t.n_net;
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
    let initial_val_loss = val(&t.params);
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
    let record = |curve: &mut Vec<EpochStats>, train_loss: f64, val_loss: f64| {
        curve.push(EpochStats {
            epoch: curve.len() + 1,
            train_loss,
            val_loss,
            elapsed_s: start.elapsed().as_secs_f64(),
        });
        bar.set_message(format!("loss {train_loss:.3e} val {val_loss:.3e}"));
        bar.inc(1);
    };
    let mut best = (f64::INFINITY, t.params.clone());
    let mut since_best = 0usize;
    for epoch in 1..=cfg.epochs {
        let lr = lr_at(cfg.lr, epoch, cfg.epochs, cfg.warmup_epochs);
        let train_loss = t.epoch(train, lr);
        let val_loss = val(&t.params);
        record(&mut curve, train_loss, val_loss);
        if val_loss < best.0 {
            best = (val_loss, t.params.clone());
            since_best = 0;
        } else {
            since_best += 1;
            if cfg.patience > 0 && since_best >= cfg.patience {
                break;
            }
        }
    }
    if best.0.is_finite() {
        t.params = best.1;
    }
    let rotor_gain = rotor_gains_of(&t.params[n_net]);
    let main_stage = (!rotor_gain.is_empty()).then(|| MainStage {
        weights: TModel::from_tensors(&t.params[..n_net]).to_core(&c_plain),
        a: a_of(&t.params[n_net]),
    });
    if !rotor_gain.is_empty() && cfg.feature_epochs > 0 {
        bar.inc_length(cfg.feature_epochs as u64);
        feature_stage(&mut t, cfg, &val, &mut curve, &record, train);
    }
    bar.finish();
    let model = TModel::from_tensors(&t.params[..n_net]);
    Trained {
        weights: model.to_core(&c_plain),
        a: a_of(&t.params[n_net]),
        rotor_gain,
        main_stage,
        curve,
        initial_val_loss,
    }
}

/// The a_j in the per-flight tensor [M, p] or [M, p + 4].
fn a_of(per_flight: &Tensor<2>) -> Vec<[f32; FEATURES]> {
    let width = per_flight.dims()[1];
    to_vec(per_flight)
        .chunks_exact(width)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect()
}

/// The rotor gain deviations δηⱼ in the per-flight tensor [M, p + 4] (empty for [M, p]).
fn rotor_gains_of(per_flight: &Tensor<2>) -> Vec<[f32; ROTOR_GAINS]> {
    let width = per_flight.dims()[1];
    if width < FEATURES + ROTOR_GAINS {
        return Vec::new();
    }
    to_vec(per_flight)
        .chunks_exact(width)
        .map(|c| std::array::from_fn(|k| c[FEATURES + k]))
        .collect()
}

/// The feature stage after training with per-flight rotor gains: J⁻¹ and g frozen, the δηⱼ
/// dropped, and W with the a_j trained alone for `cfg.feature_epochs` epochs (a cosine from
/// `cfg.lr`; the best held-out epoch kept). In flight the controller has the shared g and
/// adapts a in W, so W must carry each flight's rotor deficits as the additive W a that the
/// adaptation law can estimate; the rotor gains only kept them out of g.
fn feature_stage(
    t: &mut Trainer<'_>,
    cfg: &TrainConfig,
    val: &dyn Fn(&[Tensor<2>]) -> f64,
    curve: &mut Vec<EpochStats>,
    record: &dyn Fn(&mut Vec<EpochStats>, f64, f64),
    train: &[usize],
) {
    let n_net = t.n_net;
    t.params[n_net] = t.params[n_net].clone().narrow(1, 0, FEATURES);
    t.frozen = (0..=n_net).map(|i| i < FEATURE_INPUT_WEIGHT).collect();
    t.adam = Adam::new(&t.params);
    let mut best = (val(&t.params), t.params.clone());
    for epoch in 1..=cfg.feature_epochs {
        let lr = lr_at(cfg.lr, epoch, cfg.feature_epochs, 0);
        let train_loss = t.epoch(train, lr);
        let val_loss = val(&t.params);
        record(curve, train_loss, val_loss);
        if val_loss < best.0 {
            best = (val_loss, t.params.clone());
        }
    }
    t.params = best.1;
}
