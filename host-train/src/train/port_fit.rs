//! Learning a blob's port terms ([`hamflight::model::PortTerms`]: the input's gains and lags,
//! the dissipation, the gyrator and the learned potential) from logged flights, through the
//! core's own rollout: the model that is scored and flown is the one fitted.
//!
//! The fit is Levenberg–Marquardt on multi-step rollouts (`lm::lm_fit`, the
//! benchmark's mean-error-norm metric by IRLS). Its parameters are scaled to accelerations so
//! that one step size suits them all: drag and rate damping in 1/s, the gyrator in rad/s² per
//! m/s, the tilt stiffness in rad/s² per unit of the world vertical's body components; the blob
//! holds them as momentum rates (N·s/m, N·m·s/rad, N·m), converted with the model's mass and
//! its inertia at hover.
//!
//! **What the logs can set** (docs/benchmark.md "What the data identify"): motion shows
//! J⁻¹ g k, never J and g apart. The convention: J stays the vehicle description's (the blob
//! it starts from), g its rigid-body map, and what the flights say about the torques is in the
//! effective gains k (PortTerms::torque_gain_offset).

use hamflight::model::port::MIN_INPUT_GAIN;
use hamflight::model::{HamiltonianModel, LearnedModel, PortTerms, State, MAX_MOTOR_TAU_S};
use serde::Serialize;

use super::data::Windows;
use super::lm::{lm_fit, FitStep, Prior, Problem, Roll};
use super::response::{rollout, Response};

/// Number of fitted numbers (the scaled parameters, module docs).
pub const FIT_PARAMS: usize = 27;
const THRUST_GAIN: usize = 0;
const TORQUE_GAIN: std::ops::Range<usize> = 1..4;
const THRUST_LAG: usize = 4;
const TORQUE_LAG: usize = 5;
const DRAG: std::ops::Range<usize> = 6..9;
const DAMPING: std::ops::Range<usize> = 9..12;
const GYRATOR: std::ops::Range<usize> = 12..21;
const TILT: std::ops::Range<usize> = 21..27;
/// k₃₃ of the tilt stiffness: near level it only adds to k₁₁ and k₂₂ (the torque of ½ bᵀKb is
/// b × K b), so the fit holds it at zero.
const TILT_K33: usize = 23;

/// Which terms a fit may use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct PortStructure {
    /// The learned potential ½ bᵀ K b.
    pub tilt: bool,
    /// The gyrator B (torque from the body velocity).
    pub gyrator: bool,
    /// The rotor drag D_v.
    pub drag: bool,
    /// The rate damping D_ω.
    pub rate_damping: bool,
    /// The torques' effective gains k_τ (else held at the starting blob's, the vehicle
    /// description's 1: on flights flown in closed loop, a moment the onboard controller
    /// cancels is correlated with its torque commands and biases free gains toward zero).
    pub torque_gains: bool,
    /// The torques' first-order lag behind the rotors (else held at zero: the motors' own lag,
    /// the blob's motor time constant, is then the whole actuator chain the law designs for;
    /// a fitted lag adds to it, [`hamflight::gains::VehicleFacts::of`]).
    pub torque_lag: bool,
}

impl Default for PortStructure {
    fn default() -> Self {
        Self {
            tilt: true,
            gyrator: true,
            drag: true,
            rate_damping: true,
            torque_gains: true,
            torque_lag: true,
        }
    }
}

/// The scaled parameters' conversion to and from [`PortTerms`] for a model's mass and inertia.
#[derive(Clone, Copy, Debug)]
pub struct Scaling {
    /// m (kg).
    pub mass_kg: f32,
    /// diag J at hover (kg·m²).
    pub inertia_kg_m2: [f32; 3],
}

impl Scaling {
    /// The mass and hover inertia of `model`.
    pub fn of(model: &LearnedModel) -> Self {
        let terms = model.terms(&State::default());
        let j = terms
            .inertia_inv
            .try_inverse()
            .map(|j| [j.m11, j.m22, j.m33])
            .unwrap_or([1e-5; 3]);
        Self {
            mass_kg: terms.mass_kg,
            inertia_kg_m2: j,
        }
    }

    /// J for K's rows: the mean of J_x and J_y (K is symmetric, one scale for all of it).
    fn tilt_inertia(&self) -> f32 {
        0.5 * (self.inertia_kg_m2[0] + self.inertia_kg_m2[1])
    }

    /// The port terms of scaled parameters `p` (bounds applied: gains ≥ MIN_INPUT_GAIN, lags in
    /// [0, MAX_MOTOR_TAU_S], dissipation ≥ 0).
    pub fn to_port(&self, p: &[f64]) -> PortTerms {
        let at = |i: usize| p.get(i).copied().unwrap_or(0.0) as f32;
        // Just above the bound: (k − 1) + 1 rounds, and the blob must pass its own check.
        let gain = |i: usize| at(i).max(MIN_INPUT_GAIN + 1e-5) - 1.0;
        let lag = |i: usize| at(i).clamp(0.0, MAX_MOTOR_TAU_S);
        let j = self.inertia_kg_m2;
        let mut t = PortTerms::IDENTITY;
        t.thrust_gain_offset = gain(THRUST_GAIN);
        for (o, i) in t.torque_gain_offset.iter_mut().zip(TORQUE_GAIN) {
            *o = gain(i);
        }
        t.thrust_lag_s = lag(THRUST_LAG);
        t.torque_lag_s = lag(TORQUE_LAG);
        for (o, i) in t.drag_n_s_m.iter_mut().zip(DRAG) {
            *o = self.mass_kg * at(i).max(0.0);
        }
        for ((o, i), ji) in t.rate_damping_nm_s.iter_mut().zip(DAMPING).zip(j) {
            *o = ji * at(i).max(0.0);
        }
        for (row, (out, ji)) in t.gyrator_nm_s_m.iter_mut().zip(j).enumerate() {
            for (col, o) in out.iter_mut().enumerate() {
                *o = ji * at(GYRATOR.start + 3 * row + col);
            }
        }
        let jt = self.tilt_inertia();
        for (o, i) in t.tilt_stiffness_nm.iter_mut().zip(TILT) {
            *o = jt * at(i);
        }
        t
    }

    /// The scaled parameters of `t` (the inverse of [`Scaling::to_port`] within its bounds).
    pub fn to_params(&self, t: &PortTerms) -> Vec<f64> {
        let mut p = vec![0.0f64; FIT_PARAMS];
        let j = self.inertia_kg_m2;
        let div = |a: f32, b: f32| if b != 0.0 { f64::from(a / b) } else { 0.0 };
        let k = t.input_gain();
        p[THRUST_GAIN] = f64::from(k.x);
        for (i, kk) in TORQUE_GAIN.zip([k.y, k.z, k.w]) {
            p[i] = f64::from(kk);
        }
        p[THRUST_LAG] = f64::from(t.thrust_lag_s);
        p[TORQUE_LAG] = f64::from(t.torque_lag_s);
        for (i, d) in DRAG.zip(t.drag_n_s_m) {
            p[i] = div(d, self.mass_kg);
        }
        for ((i, d), ji) in DAMPING.zip(t.rate_damping_nm_s).zip(j) {
            p[i] = div(d, ji);
        }
        for (row, (vals, ji)) in t.gyrator_nm_s_m.iter().zip(j).enumerate() {
            for (col, v) in vals.iter().enumerate() {
                p[GYRATOR.start + 3 * row + col] = div(*v, ji);
            }
        }
        for (i, v) in TILT.zip(t.tilt_stiffness_nm) {
            p[i] = div(v, self.tilt_inertia());
        }
        p
    }
}

/// The rollout of a base model with the port terms of scaled parameters.
struct PortRoll<'a> {
    base: &'a LearnedModel,
    scaling: Scaling,
}

impl Roll for PortRoll<'_> {
    fn roll(
        &self,
        p: &[f64],
        s0: &State,
        u: &[[f32; 4]],
        dt_s: f32,
        visit: &mut dyn FnMut(usize, &State),
    ) {
        let model = self.base.with_port(self.scaling.to_port(p));
        rollout(&model, &Response::identity(), s0, u, dt_s, |k, s| {
            visit(k, s)
        });
    }
}

/// What [`fit`] is told.
#[derive(Clone, Debug)]
pub struct PortFitConfig {
    /// Levenberg–Marquardt iterations at most.
    pub iterations: usize,
    /// The error scales (m, m/s, rad, rad/s) of the residuals.
    pub scales: [f64; 4],
    /// Threads for the Jacobian.
    pub threads: usize,
    /// Which terms the fit uses.
    pub structure: PortStructure,
    /// A prior pulling each free torque gain k_τ toward the vehicle description's 1: the cost
    /// (in the fit's units, the mean scaled error norm) of a unit deviation per axis; 0: none.
    /// Flights flown in closed loop bias free gains toward zero (docs/benchmark.md "What the
    /// data identify"), and a blob whose gains are far below the rotors' over-drives them.
    pub torque_gain_prior: f64,
    /// A prior pulling each free rate damping D_ω / J toward zero: the cost of 1/s of damping
    /// per axis; 0: none. On closed-loop flights the damping stands in, in part, for the
    /// onboard attitude loop, and the law cancels it on a vehicle that lacks it.
    pub rate_damping_prior: f64,
}

impl Default for PortFitConfig {
    fn default() -> Self {
        Self {
            iterations: 20,
            scales: [0.1, 0.5, 0.2, 0.6],
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            structure: PortStructure::default(),
            torque_gain_prior: 0.0,
            rate_damping_prior: 0.0,
        }
    }
}

/// Where a fit of `structure` starts: the torques lagged and, when their gains are free, weak
/// (a full-gain start of free gains diverges on real logs); nothing else.
pub fn default_start(structure: &PortStructure) -> PortTerms {
    let mut t = PortTerms::IDENTITY;
    if structure.torque_gains {
        t.torque_gain_offset = [-0.9; 3];
    }
    if structure.torque_lag {
        t.torque_lag_s = 0.05;
    }
    t
}

/// Fits the port terms of `base` to windows `ids` of `data` from `start`. Returns the model with
/// the fitted terms and the iterations.
pub fn fit(
    base: &LearnedModel,
    data: &Windows,
    ids: &[usize],
    start: &PortTerms,
    cfg: &PortFitConfig,
    progress: impl FnMut(&FitStep),
) -> (LearnedModel, Vec<FitStep>) {
    let scaling = Scaling::of(base);
    let s = cfg.structure;
    let fixed: Vec<bool> = (0..FIT_PARAMS)
        .map(|i| {
            i == TILT_K33
                || (!s.tilt && TILT.contains(&i))
                || (!s.gyrator && GYRATOR.contains(&i))
                || (!s.drag && DRAG.contains(&i))
                || (!s.rate_damping && DAMPING.contains(&i))
                || (!s.torque_gains && TORQUE_GAIN.contains(&i))
                || (!s.torque_lag && i == TORQUE_LAG)
        })
        .collect();
    let project = |q: &mut [f64]| {
        for (i, x) in q.iter_mut().enumerate() {
            if i == THRUST_GAIN || TORQUE_GAIN.contains(&i) {
                *x = x.max(f64::from(MIN_INPUT_GAIN));
            } else if i == THRUST_LAG || i == TORQUE_LAG {
                *x = x.clamp(0.0, f64::from(MAX_MOTOR_TAU_S));
            } else if DRAG.contains(&i) || DAMPING.contains(&i) {
                *x = x.max(0.0);
            }
        }
    };
    let mut priors: Vec<Prior> = Vec::new();
    if s.torque_gains && cfg.torque_gain_prior > 0.0 {
        priors.extend(TORQUE_GAIN.map(|index| Prior {
            index,
            target: 1.0,
            weight: cfg.torque_gain_prior,
        }));
    }
    if s.rate_damping && cfg.rate_damping_prior > 0.0 {
        priors.extend(DAMPING.map(|index| Prior {
            index,
            target: 0.0,
            weight: cfg.rate_damping_prior,
        }));
    }
    let roll = PortRoll { base, scaling };
    let problem = Problem {
        roll: &roll,
        data,
        ids,
        scales: cfg.scales,
        threads: cfg.threads,
        priors: &priors,
    };
    let (p, steps) = lm_fit(
        &problem,
        scaling.to_params(start),
        &fixed,
        &project,
        cfg.iterations,
        progress,
    );
    (base.with_port(scaling.to_port(&p)), steps)
}

/// The fitted terms per axis in the units a person reads (the training report).
#[derive(Clone, Debug, Serialize)]
pub struct PortReport {
    /// The thrust's effective gain k_f.
    pub thrust_gain: f32,
    /// The torques' effective gains k_τ (roll, pitch, yaw): the learned part of J⁻¹ g k.
    pub torque_gain: [f32; 3],
    /// T_f (s).
    pub thrust_lag_s: f32,
    /// T_τ (s).
    pub torque_lag_s: f32,
    /// Rotor drag D_v / m (1/s) per body axis.
    pub drag_per_s: [f32; 3],
    /// Rate damping D_ω / J (1/s) per body axis.
    pub rate_damping_per_s: [f32; 3],
    /// The gyrator's angular acceleration per body velocity, J⁻¹B (rad/s² per m/s), rows ω̇.
    pub gyrator_rad_s2_per_m_s: [[f32; 3]; 3],
    /// K / J (rad/s² per unit of b), as [k₁₁, k₂₂, k₃₃, k₁₂, k₁₃, k₂₃].
    pub tilt_rad_s2: [f32; 6],
    /// What these numbers can and cannot say (module docs).
    pub identifiability: &'static str,
}

/// The convention that makes the fit unique, in one sentence for the report.
pub const IDENTIFIABILITY: &str = "motion identifies J^-1 g k only: J is the vehicle \
    description's, g the rigid-body rotor map, and the flights' torque information is in the \
    effective gains k";

/// [`PortReport`] of a model.
pub fn report(model: &LearnedModel) -> PortReport {
    let sc = Scaling::of(model);
    let p = sc.to_params(model.port());
    let f = |i: usize| p.get(i).copied().unwrap_or(0.0) as f32;
    let t = model.port();
    PortReport {
        thrust_gain: f(THRUST_GAIN),
        torque_gain: [f(1), f(2), f(3)],
        thrust_lag_s: t.thrust_lag_s,
        torque_lag_s: t.torque_lag_s,
        drag_per_s: [f(6), f(7), f(8)],
        rate_damping_per_s: [f(9), f(10), f(11)],
        gyrator_rad_s2_per_m_s: [
            [f(12), f(13), f(14)],
            [f(15), f(16), f(17)],
            [f(18), f(19), f(20)],
        ],
        tilt_rad_s2: [f(21), f(22), f(23), f(24), f(25), f(26)],
        identifiability: IDENTIFIABILITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hamflight::model::ModelWeights;
    use nalgebra::Vector3;

    #[test]
    fn scaling_round_trips() {
        let model = LearnedModel::new(ModelWeights::prior_with_inertia(&Vector3::new(
            2.4e-5, 2.4e-5, 3.2e-5,
        )));
        let sc = Scaling::of(&model);
        // Gains within their bounds (≥ 0.02), everything else small and positive.
        let p: Vec<f64> = (0..FIT_PARAMS)
            .map(|i| if i < 4 { 0.5 } else { 0.01 } + 0.01 * i as f64)
            .collect();
        let port = sc.to_port(&p);
        assert_eq!(port.validate(), Ok(()));
        let back = sc.to_params(&port);
        for (a, b) in p.iter().zip(&back) {
            assert!((a - b).abs() < 1e-5 * a.abs().max(1.0), "{a} against {b}");
        }
    }
}
