//! Learning the Hamiltonian dynamics and disturbance model from collected windows (paper
//! Problem 1, Sec. 3): J⁻¹(q) and g(q) (θ), W(q, 𝔭) (φ) and one a_j per disturbance
//! realization, by RK4 through each window and Adam on the TSE(3) loss ℓ_p + ℓ_R + ℓ_ζ.
//!
//! - [`data`]: the dataset's windows as tensors, the held-out split;
//! - [`model`]: the networks and paper eq. 1–2 as batched burn tensor ops (flex + autodiff);
//! - [`r#loop`]: Adam, the epoch loop, the progress bar;
//! - [`export`]: the weight blob (temp file, then rename) and the `FILE.hfw.json` report.

pub mod data;
pub mod export;
#[path = "loop.rs"]
pub mod r#loop;
pub mod model;

use anyhow::{bail, Result};
use hamflight::model::{FEATURES, HIDDEN};
use serde::Serialize;
use std::path::Path;

pub use export::TrainReport;

/// Training settings. Saved in the report next to the weights they produced.
#[derive(Clone, Debug, Serialize)]
pub struct TrainConfig {
    /// Epochs over the training windows (default 60).
    pub epochs: usize,
    /// Adam's initial learning rate (default 3e-3), decayed by a cosine to 1/20 of it.
    pub lr: f64,
    /// The a_j's learning rate relative to `lr` (default 10: they are few, in m/s² units).
    pub a_lr_scale: f64,
    /// Minibatch size in windows (default 256).
    pub batch: usize,
    /// Seed of the initialization, the split and the minibatch order (default 0).
    pub seed: u64,
    /// Fraction of each realization's windows held out (default 0.1).
    pub heldout_frac: f64,
    /// Fraction of the remaining training windows used (default 1; for data-efficiency runs).
    pub data_frac: f64,
    /// Scale of the output layers' initial weights around the physical prior (default 0.05).
    pub init_out_gain: f32,
    /// Hidden width; fixed at compile time by the core ([`HIDDEN`]), checked here.
    pub hidden: usize,
    /// Number of disturbance features p; fixed by the core ([`FEATURES`]), checked here.
    pub features: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            epochs: 60,
            lr: 3e-3,
            a_lr_scale: 10.0,
            batch: 256,
            seed: 0,
            heldout_frac: 0.1,
            data_frac: 1.0,
            init_out_gain: 0.05,
            hidden: HIDDEN,
            features: FEATURES,
        }
    }
}

/// Trains on the dataset in `data_dir` and writes `out` (the blob) and `out.json` (the report).
///
/// # Errors
/// A dataset that cannot be read, a `hidden`/`features` other than the core's compile-time
/// sizes, or a failure writing the outputs.
pub fn run(cfg: &TrainConfig, data_dir: &Path, out: &Path, quiet: bool) -> Result<TrainReport> {
    if cfg.hidden != HIDDEN || cfg.features != FEATURES {
        bail!(
            "--hidden {} / --features {}: the core is compiled for HIDDEN = {HIDDEN}, FEATURES = \
             {FEATURES} (the firmware's fixed-size networks); change them in src/model/mod.rs",
            cfg.hidden,
            cfg.features
        );
    }
    let windows = data::load(data_dir)?;
    let (mut train_ids, heldout) = data::split(&windows, cfg.heldout_frac, cfg.seed);
    if cfg.data_frac < 1.0 {
        let keep = ((train_ids.len() as f64) * cfg.data_frac).ceil().max(1.0) as usize;
        // The split is already shuffled per realization; take an even share of each.
        let mut kept = Vec::with_capacity(keep);
        for j in 0..windows.realizations.len() {
            let ids: Vec<usize> = train_ids
                .iter()
                .copied()
                .filter(|&i| windows.windows[i].realization == j)
                .collect();
            let n = ((ids.len() as f64) * cfg.data_frac).ceil() as usize;
            kept.extend_from_slice(&ids[..n.min(ids.len())]);
        }
        train_ids = kept;
    }
    let trained = r#loop::train(cfg, &windows, &train_ids, &heldout, quiet);
    let report = export::report(cfg, &windows, &train_ids, &heldout, &trained);
    export::write(out, &trained.weights, &report)?;
    Ok(report)
}
