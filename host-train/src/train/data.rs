//! Training windows: the collected dataset (format `hamflight-dataset-v1`, see `dataset.rs`)
//! read into fixed 5-state windows with their constant control and realization index, a
//! deterministic held-out split, and the batch tensors the burn model consumes.

use anyhow::{bail, Context, Result};
use burn::tensor::{Device, Int, Tensor, TensorData};
use hamflight::State;
use nalgebra::{Matrix3, Vector3};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;
use std::path::Path;

/// States per window (N + 1 in the paper's notation, N = 4 predicted states).
pub const WINDOW_LEN: usize = 5;

/// One window: states x₀..x₄ under a constant control u, from realization `realization`.
#[derive(Clone, Debug)]
pub struct Window {
    /// The sampled states.
    pub states: [State; WINDOW_LEN],
    /// The control u = [f (N); τ (N·m)] held over the window.
    pub u: [f32; 4],
    /// Index of the disturbance realization j.
    pub realization: usize,
}

/// The manifest's description of one realization (its true disturbance, for the report).
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct RealizationInfo {
    /// The CSV file, relative to the dataset directory.
    pub file: String,
    /// The world-frame wind as a specific force (m/s²).
    pub wind_m_s2: [f32; 3],
    /// Per-rotor thrust efficiency δᵢ.
    pub rotor_efficiency: [f32; 4],
    /// Number of windows.
    pub windows: usize,
}

#[derive(Clone, Debug, Deserialize)]
struct Manifest {
    format: String,
    sample_hz: f32,
    window_len: usize,
    realizations: Vec<RealizationInfo>,
}

/// A loaded dataset.
#[derive(Clone, Debug)]
pub struct Windows {
    /// All windows, realization by realization.
    pub windows: Vec<Window>,
    /// Sampling rate (Hz); the window's time step is 1 / sample_hz.
    pub sample_hz: f32,
    /// The realizations' true disturbances, in index order.
    pub realizations: Vec<RealizationInfo>,
}

/// Reads `DIR/manifest.json` and every `realization_NN.csv` it lists.
///
/// # Errors
/// Missing or malformed files, a format other than `hamflight-dataset-v1`, a window length
/// other than 5, or non-finite values; the error names the file.
pub fn load(dir: &Path) -> Result<Windows> {
    let mpath = dir.join("manifest.json");
    let text =
        std::fs::read_to_string(&mpath).with_context(|| format!("reading {}", mpath.display()))?;
    let manifest: Manifest =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", mpath.display()))?;
    if manifest.format != "hamflight-dataset-v1" {
        bail!(
            "{}: unsupported format {:?}",
            mpath.display(),
            manifest.format
        );
    }
    if manifest.window_len != WINDOW_LEN {
        bail!(
            "{}: window_len {} (expected {WINDOW_LEN})",
            mpath.display(),
            manifest.window_len
        );
    }
    let mut windows = Vec::new();
    for (j, r) in manifest.realizations.iter().enumerate() {
        let path = dir.join(&r.file);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        let before = windows.len();
        parse_csv(&text, j, &mut windows).with_context(|| format!("parsing {}", path.display()))?;
        if windows.len() == before {
            bail!("{}: no windows", path.display());
        }
    }
    Ok(Windows {
        windows,
        sample_hz: manifest.sample_hz,
        realizations: manifest.realizations,
    })
}

fn parse_csv(text: &str, realization: usize, out: &mut Vec<Window>) -> Result<()> {
    let mut lines = text.lines();
    let header = lines.next().context("empty file")?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let col = |name: &str| {
        cols.iter()
            .position(|c| *c == name)
            .with_context(|| format!("missing column {name}"))
    };
    let names = [
        "window", "step", "px", "py", "pz", "r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32",
        "r33", "vx", "vy", "vz", "wx", "wy", "wz", "f_n", "tau_x_nm", "tau_y_nm", "tau_z_nm",
    ];
    let idx: Vec<usize> = names.iter().map(|n| col(n)).collect::<Result<_>>()?;
    let mut cur: Vec<(State, [f32; 4])> = Vec::with_capacity(WINDOW_LEN);
    let mut cur_window: Option<i64> = None;
    for (ln, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let mut v = [0f64; 24];
        for (slot, &i) in v.iter_mut().zip(idx.iter()) {
            let f = fields
                .get(i)
                .with_context(|| format!("line {}: too few fields", ln + 2))?;
            *slot = f
                .trim()
                .parse::<f64>()
                .with_context(|| format!("line {}: bad number {f:?}", ln + 2))?;
            if !slot.is_finite() {
                bail!("line {}: non-finite value", ln + 2);
            }
        }
        let w = v[0] as i64;
        if cur_window != Some(w) {
            if !cur.is_empty() {
                bail!(
                    "line {}: window {:?} has {} states",
                    ln + 2,
                    cur_window,
                    cur.len()
                );
            }
            cur_window = Some(w);
        }
        let f = |k: usize| v[k] as f32;
        let state = State {
            p_m: Vector3::new(f(2), f(3), f(4)),
            rot: Matrix3::new(f(5), f(6), f(7), f(8), f(9), f(10), f(11), f(12), f(13)),
            v_body_m_s: Vector3::new(f(14), f(15), f(16)),
            w_body_rad_s: Vector3::new(f(17), f(18), f(19)),
        };
        cur.push((state, [f(20), f(21), f(22), f(23)]));
        if cur.len() == WINDOW_LEN {
            let states = std::array::from_fn(|n| cur[n].0);
            out.push(Window {
                states,
                u: cur[0].1,
                realization,
            });
            cur.clear();
        }
    }
    if !cur.is_empty() {
        bail!("last window is incomplete");
    }
    Ok(())
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

/// One step of a batch of windows as tensors: p [B,3], R [B,3,3], v [B,3], ω [B,3].
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
    /// x₀..x₄.
    pub states: Vec<StateBatch>,
    /// u [B,4].
    pub u: Tensor<2>,
    /// The realization index of each window [B].
    pub realization: Tensor<1, Int>,
    /// Batch size.
    pub len: usize,
}

/// Builds the tensors of the windows `ids`.
pub fn batch(data: &Windows, ids: &[usize], device: &Device) -> Batch {
    let b = ids.len();
    let mut states = Vec::with_capacity(WINDOW_LEN);
    for n in 0..WINDOW_LEN {
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
    let u: Vec<f32> = ids.iter().flat_map(|&i| data.windows[i].u).collect();
    let j: Vec<i64> = ids
        .iter()
        .map(|&i| data.windows[i].realization as i64)
        .collect();
    Batch {
        states,
        u: Tensor::from_data(TensorData::new(u, [b, 4]), device),
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
