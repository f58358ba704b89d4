//! N-step open-loop prediction errors: one accumulator and one rollout for the training
//! report's held-out errors ([`super::export`]) and `host-train score`
//! ([`crate::pipeline::score`]).

use hamflight::lie;
use hamflight::model::{rk4_step, HamiltonianModel, State, FEATURES};
use nalgebra::{Matrix4, Vector4};
use serde::Serialize;

use super::data::Windows;

/// Errors of one predictor at steps 1..N.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct HorizonErrors {
    /// Mean over windows of ‖p̂ − p‖ (m).
    pub pos_mae_m: Vec<f64>,
    /// RMS of the same (m).
    pub pos_rmse_m: Vec<f64>,
    /// Mean of ‖R̂ v̂ − R v‖ (m/s, world frame).
    pub vel_mae_m_s: Vec<f64>,
    /// RMS of the same.
    pub vel_rmse_m_s: Vec<f64>,
    /// RMS of ‖v̂ − v‖ in the body frame (m/s): the training report's velocity error.
    pub vel_body_rmse_m_s: Vec<f64>,
    /// Mean geodesic angle of R̂ Rᵀ (rad).
    pub att_mae_rad: Vec<f64>,
    /// RMS of the same.
    pub att_rmse_rad: Vec<f64>,
    /// Mean of ‖ω̂ − ω‖ (rad/s, body).
    pub rate_mae_rad_s: Vec<f64>,
    /// RMS of the same.
    pub rate_rmse_rad_s: Vec<f64>,
}

/// Accumulates error norms at each step.
pub struct Acc {
    sum: Vec<[f64; 5]>,
    sq: Vec<[f64; 5]>,
    /// Windows added.
    pub n: usize,
}

impl Acc {
    /// For `n` predicted steps.
    pub fn new(n: usize) -> Self {
        Self {
            sum: vec![[0.0; 5]; n],
            sq: vec![[0.0; 5]; n],
            n: 0,
        }
    }

    /// Predicted steps per window.
    pub fn steps(&self) -> usize {
        self.sum.len()
    }

    /// Adds step `k` (0-based) of one window.
    pub fn add(&mut self, k: usize, pred: &State, truth: &State) {
        let world = |s: &State| s.rot * s.v_body_m_s;
        let e = [
            f64::from((pred.p_m - truth.p_m).norm()),
            f64::from((world(pred) - world(truth)).norm()),
            f64::from((pred.v_body_m_s - truth.v_body_m_s).norm()),
            f64::from(lie::geodesic_distance(&truth.rot, &pred.rot)),
            f64::from((pred.w_body_rad_s - truth.w_body_rad_s).norm()),
        ];
        if let (Some(s), Some(q)) = (self.sum.get_mut(k), self.sq.get_mut(k)) {
            for i in 0..5 {
                s[i] += e[i];
                q[i] += e[i] * e[i];
            }
        }
    }

    /// Mean and RMS over the windows added.
    pub fn finish(&self) -> HorizonErrors {
        let m = self.n.max(1) as f64;
        let mae = |i: usize| self.sum.iter().map(|s| s[i] / m).collect();
        let rmse = |i: usize| self.sq.iter().map(|s| (s[i] / m).sqrt()).collect();
        HorizonErrors {
            pos_mae_m: mae(0),
            pos_rmse_m: rmse(0),
            vel_mae_m_s: mae(1),
            vel_rmse_m_s: rmse(1),
            vel_body_rmse_m_s: rmse(2),
            att_mae_rad: mae(3),
            att_rmse_rad: rmse(3),
            rate_mae_rad_s: mae(4),
            rate_rmse_rad_s: rmse(4),
        }
    }
}

/// Errors of `model` rolled out over windows `ids` of `data`, with each window's a from `a`
/// (by realization; none or a missing entry: a = 0) and its command through `scaling` (by
/// realization; none: as logged).
pub fn rollout_errors<M: HamiltonianModel>(
    model: &M,
    data: &Windows,
    ids: &[usize],
    a: Option<&[[f32; FEATURES]]>,
    scaling: &[Matrix4<f32>],
) -> HorizonErrors {
    let dt = 1.0 / data.sample_hz;
    let n = data.window_len.saturating_sub(1);
    let mut acc = Acc::new(n);
    for w in ids.iter().filter_map(|&i| data.windows.get(i)) {
        let Some(mut s) = w.states.first().copied() else {
            continue;
        };
        let aj = a
            .and_then(|a| a.get(w.realization).copied())
            .unwrap_or([0.0; FEATURES]);
        for k in 0..n {
            let (Some(u), Some(t)) = (w.u.get(k), w.states.get(k + 1)) else {
                break;
            };
            let u = Vector4::from(*u);
            let u = scaling.get(w.realization).map_or(u, |m| m * u);
            s = rk4_step(model, &s, &u, &aj, dt);
            acc.add(k, &s, t);
        }
        acc.n += 1;
    }
    acc.finish()
}

/// Errors of `model` (a = 0, commands as logged) over windows `ids` of `data`.
pub fn model_errors<M: HamiltonianModel>(
    model: &M,
    data: &Windows,
    ids: &[usize],
) -> HorizonErrors {
    rollout_errors(model, data, ids, None, &[])
}

/// The four MAEs of `e` at step `step` (1-based), for a one-line summary.
pub fn mae_line(e: &HorizonErrors, step: usize) -> String {
    let k = step.saturating_sub(1);
    format!(
        "pos {:.4} m, vel {:.3} m/s, att {:.3} rad, rates {:.3} rad/s",
        e.pos_mae_m.get(k).copied().unwrap_or(f64::NAN),
        e.vel_mae_m_s.get(k).copied().unwrap_or(f64::NAN),
        e.att_mae_rad.get(k).copied().unwrap_or(f64::NAN),
        e.rate_mae_rad_s.get(k).copied().unwrap_or(f64::NAN)
    )
}
