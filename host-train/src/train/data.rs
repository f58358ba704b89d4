//! Training windows: a dataset (format `hamflight-dataset-v2`, read by [`crate::io::dataset`]) cut
//! into windows of `len` states every `stride` samples, each with the command of every step and
//! its realization index, a deterministic held-out split, and the batch tensors the burn model
//! consumes.

use crate::io::dataset::{self, WindowSpec};
use anyhow::{bail, Result};
use burn::tensor::{Device, Int, Tensor, TensorData};
use hamflight::State;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// One window: states x₀..x_N, the command u_k applied from x_k to x_{k+1}, and the
/// realization j it comes from.
#[derive(Clone, Debug)]
pub struct Window {
    /// The sampled states (`len` of them).
    pub states: Vec<State>,
    /// The control u_k = [f (N); τ (N·m)] of each step (`len − 1` of them).
    pub u: Vec<[f32; 4]>,
    /// Index of the disturbance realization j.
    pub realization: usize,
}

/// The manifest's description of one realization (its true disturbance, for the report).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RealizationInfo {
    /// The CSV file, relative to the dataset directory.
    pub file: String,
    /// The world-frame wind as a specific force (m/s²), when known.
    pub wind_m_s2: Option<[f32; 3]>,
    /// Per-rotor thrust efficiency δᵢ, when known.
    pub rotor_efficiency: Option<[f32; 4]>,
    /// Marked disturbance-free: its a_j is pinned to 0.
    pub disturbance_free: bool,
    /// Number of windows.
    pub windows: usize,
    /// For imports, the log it came from (the manifest's `source_file`).
    pub source_file: Option<String>,
}

/// A loaded dataset.
#[derive(Clone, Debug)]
pub struct Windows {
    /// All windows, realization by realization.
    pub windows: Vec<Window>,
    /// Sampling rate (Hz); the window's time step is 1 / sample_hz.
    pub sample_hz: f32,
    /// States per window.
    pub window_len: usize,
    /// The vehicle's mass (kg), from the dataset's manifest: the model's known mass.
    pub mass_kg: f32,
    /// The realizations' true disturbances, in index order.
    pub realizations: Vec<RealizationInfo>,
    /// The manifest's `mass_kg` (kg), even when `train --mass-kg` overrides the model's.
    pub manifest_mass_kg: f32,
    /// The manifest's inertia, rotor efficiencies and motor lag, when given.
    pub vehicle: dataset::VehicleDescription,
}

/// Reads the dataset in `dir` and cuts it into `spec` windows ([`dataset::windows`]).
///
/// # Errors
/// The dataset's read errors (naming the file and line), a bad `spec`, or a realization that
/// yields no window.
pub fn load(dir: &Path, spec: WindowSpec) -> Result<Windows> {
    let ds = dataset::load(dir)?;
    let at = dataset::windows(&ds, spec)?;
    let mut windows = Vec::with_capacity(at.len());
    let mut counts = vec![0usize; ds.realizations.len()];
    for w in &at {
        let samples = &ds.realizations[w.realization].flights[w.flight].samples;
        let win = &samples[w.start..w.start + spec.len];
        windows.push(Window {
            states: win.iter().map(|s| State::from(&s.state)).collect(),
            u: win[..spec.len - 1]
                .iter()
                .map(|s| s.wrench.map(|x| x as f32))
                .collect(),
            realization: w.realization,
        });
        counts[w.realization] += 1;
    }
    let mut realizations = Vec::with_capacity(ds.realizations.len());
    for (r, &n) in ds.realizations.iter().zip(&counts) {
        if n == 0 {
            bail!(
                "`{}`: no window of {} states at {} Hz (flights too short or not continuous)",
                dir.join(&r.meta.file).display(),
                spec.len,
                ds.manifest.sample_hz
            );
        }
        realizations.push(RealizationInfo {
            file: r.meta.file.clone(),
            wind_m_s2: r.meta.wind_m_s2.map(|w| w.map(|x| x as f32)),
            rotor_efficiency: r.meta.rotor_efficiency.map(|d| d.map(|x| x as f32)),
            disturbance_free: r.meta.disturbance_free,
            windows: n,
            source_file: r.meta.source_file.clone(),
        });
    }
    Ok(Windows {
        windows,
        sample_hz: ds.manifest.sample_hz as f32,
        window_len: spec.len,
        mass_kg: ds.manifest.mass_kg as f32,
        realizations,
        manifest_mass_kg: ds.manifest.mass_kg as f32,
        vehicle: ds.manifest.vehicle.clone(),
    })
}

/// A deterministic split: `heldout_frac` of each realization's windows, chosen with `seed`,
/// go to the held-out set. Returns `(train, heldout)` window indices.
pub fn split(data: &Windows, heldout_frac: f64, seed: u64) -> (Vec<usize>, Vec<usize>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_da7a);
    let (mut train, mut held) = (Vec::new(), Vec::new());
    for j in 0..data.realizations.len() {
        let mut ids: Vec<usize> = (0..data.windows.len())
            .filter(|&i| data.windows[i].realization == j)
            .collect();
        ids.shuffle(&mut rng);
        let n_held = ((ids.len() as f64) * heldout_frac).round() as usize;
        let n_held = n_held.min(ids.len().saturating_sub(1));
        held.extend_from_slice(&ids[..n_held]);
        train.extend_from_slice(&ids[n_held..]);
    }
    (train, held)
}

/// One step of a batch of windows as tensors: p `[B,3]`, R `[B,3,3]`, v `[B,3]`, ω `[B,3]`.
#[derive(Clone, Debug)]
pub struct StateBatch {
    /// Position (world, m).
    pub p: Tensor<2>,
    /// Rotation body→world.
    pub rot: Tensor<3>,
    /// Body linear velocity (m/s).
    pub v: Tensor<2>,
    /// Body angular velocity (rad/s).
    pub w: Tensor<2>,
}

/// A batch of windows as tensors.
#[derive(Clone, Debug)]
pub struct Batch {
    /// x₀..x_N.
    pub states: Vec<StateBatch>,
    /// u_k `[B,4]` of each step k = 0..N−1.
    pub u: Vec<Tensor<2>>,
    /// The realization index of each window `[B]`.
    pub realization: Tensor<1, Int>,
    /// Batch size.
    pub len: usize,
}

/// Builds the tensors of the windows `ids`.
pub fn batch(data: &Windows, ids: &[usize], device: &Device) -> Batch {
    let b = ids.len();
    let len = data.window_len;
    let mut states = Vec::with_capacity(len);
    for n in 0..len {
        let (mut p, mut r, mut v, mut w) = (
            Vec::with_capacity(3 * b),
            Vec::with_capacity(9 * b),
            Vec::with_capacity(3 * b),
            Vec::with_capacity(3 * b),
        );
        for &i in ids {
            let s = &data.windows[i].states[n];
            p.extend_from_slice(s.p_m.as_slice());
            r.extend_from_slice(&hamflight::model::learned::rot_input(&s.rot));
            v.extend_from_slice(s.v_body_m_s.as_slice());
            w.extend_from_slice(s.w_body_rad_s.as_slice());
        }
        states.push(StateBatch {
            p: Tensor::from_data(TensorData::new(p, [b, 3]), device),
            rot: Tensor::from_data(TensorData::new(r, [b, 3, 3]), device),
            v: Tensor::from_data(TensorData::new(v, [b, 3]), device),
            w: Tensor::from_data(TensorData::new(w, [b, 3]), device),
        });
    }
    let u = (0..len - 1)
        .map(|k| {
            let u: Vec<f32> = ids.iter().flat_map(|&i| data.windows[i].u[k]).collect();
            Tensor::from_data(TensorData::new(u, [b, 4]), device)
        })
        .collect();
    let j: Vec<i64> = ids
        .iter()
        .map(|&i| data.windows[i].realization as i64)
        .collect();
    Batch {
        states,
        u,
        realization: Tensor::from_data(TensorData::new(j, [b]), device),
        len: b,
    }
}

/// The training windows kept at `data_frac` (data-efficiency runs): the first share of each
/// realization's (already shuffled) windows.
pub fn subset(windows: &Windows, train_ids: &[usize], data_frac: f64) -> Vec<usize> {
    if data_frac >= 1.0 {
        return train_ids.to_vec();
    }
    let mut kept = Vec::new();
    for j in 0..windows.realizations.len() {
        let ids: Vec<usize> = train_ids
            .iter()
            .copied()
            .filter(|&i| windows.windows[i].realization == j)
            .collect();
        let n = ((ids.len() as f64) * data_frac).ceil() as usize;
        kept.extend_from_slice(&ids[..n.min(ids.len())]);
    }
    kept
}
