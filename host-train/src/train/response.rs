//! The measured-input response: what a real log's measured rotor speeds and body velocity do to
//! the motion that a blob's rigid body (paper eq. 1 and 2) does not say, for open-loop prediction.
//!
//! A blob's model maps a wrench u = [f; τ] to the motion. On a log whose wrench comes from
//! measured rotor speeds (the nano-drone benchmark, docs/benchmark.md), three things sit between
//! the computed wrench and the motion that the paper's M, g and W cannot hold:
//! - the speeds' own filtering: the thrust and the torques act through first-order lags
//!   (`thrust_lag_s`, `torque_lag_s`) and with effective gains (`thrust_gain`, `torque_gain` per
//!   axis); on the benchmark's flights the torques show 8–34 % of what the rigid body needs,
//!   about 70 ms late;
//! - a body wrench linear in the body velocity ζ = (v, ω), the rotors' drag and flapping
//!   moment and the rate damping, written as an acceleration A ζ (`accel_per_velocity`);
//! - a constant body acceleration c (`accel_bias`): a centre-of-mass offset, a trim torque;
//! - an angular acceleration linear in the tilt, K (`accel_per_tilt`): the vehicle's own
//!   attitude loop holding it near level. The loop acts through the rotors, so a perfect log of
//!   their speeds would carry it in the torques; the benchmark's logs carry 8–34 % of the
//!   torques, and K takes the rest of the loop's effect as the state feedback it is
//!   (−5.5 and −5.8 rad/s² per rad on roll and pitch there; docs/benchmark.md).
//!
//! So the predicted motion is the blob's dynamics under u' = [k_f f̄; k_τ ∘ τ̄] with
//! τ̄̇ = (τ − τ̄)/T and the same for f̄ with T_f (backward Euler at the log's rate), plus
//! ζ̇ += A ζ + c, ω̇ += K (Rᵀe₃)ₓᵧ. With the identity response ([`Response::identity`]) it is the blob's own
//! prediction. The response is host-side: the flight core's control path does not
//! use it (the controller flies the blob's M, g and W; docs/benchmark.md says why).
//!
//! [`fit`] identifies the response on a dataset by Levenberg–Marquardt on multi-step rollouts
//! ([`super::lm`]).

use hamflight::model::{
    rk4_step, ActuatorLag, HamiltonianModel, ModelTerms, State, StateDerivative, FEATURES,
};
use nalgebra::{Vector3, Vector4};
use serde::{Deserialize, Serialize};

use super::data::Windows;
pub use super::lm::FitStep;
use super::lm::{lm_fit, Problem, Roll};
use super::predict::{Acc, HorizonErrors};

/// The measured-input response (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Response {
    /// k_f: the thrust's effective gain (1: as computed).
    pub thrust_gain: f32,
    /// k_τ: each body torque's effective gain (roll, pitch, yaw; 1: as computed).
    pub torque_gain: [f32; 3],
    /// T (s): the first-order lag the torques act through (0: none).
    pub torque_lag_s: f32,
    /// A: body-frame acceleration per unit of ζ = (v (m/s), ω (rad/s)), row-major 6×6: rows
    /// v̇ (m/s²) then ω̇ (rad/s²).
    pub accel_per_velocity: [[f32; 6]; 6],
    /// c: constant body-frame acceleration, v̇ (m/s²) then ω̇ (rad/s²).
    pub accel_bias: [f32; 6],
    /// T_f (s): the first-order lag the thrust acts through (0: none).
    #[serde(default)]
    pub thrust_lag_s: f32,
    /// K: body angular acceleration (rad/s²) per unit of the world vertical's body x and y
    /// components, (Rᵀe₃)ₓ ≈ −pitch and (Rᵀe₃)ᵧ ≈ roll; row-major 3×2, rows ω̇ₓ, ω̇ᵧ, ω̇_z. The
    /// onboard attitude loop's pull toward level, which the measured rotor speeds carry too
    /// little of (module docs).
    #[serde(default)]
    pub accel_per_tilt: [[f32; 2]; 3],
}

/// Number of parameters: k_f, k_τ (3), T, A (36), c (6), T_f, K (6).
pub const PARAMS: usize = 54;
/// Indices of K in the parameters.
const TILT: std::ops::Range<usize> = 48..54;
/// Index of T in the parameters.
const TORQUE_LAG: usize = 4;
/// Index of T_f in the parameters.
const THRUST_LAG: usize = 47;

/// Parameters [`fit`] leaves where they start: the constant body force (c's v̇ part), which a
/// fit trades against the thrust gain (on the nano-drone flights it took 8 m/s² of the 9.8 and
/// left the thrust gain at 0.24); a quadrotor's constant force is its thrust's.
const FIXED: [usize; 3] = [41, 42, 43];

/// Which entries of A's force rows (v̇ ← ζ) a fit may use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, clap::ValueEnum)]
pub enum ForceTerms {
    /// Every entry: v̇ from v and ω.
    Full,
    /// The diagonal only: a linear rotor drag per body axis (v̇ᵢ ← vᵢ).
    #[default]
    Drag,
    /// None: the force is the thrust's alone.
    None,
}

/// True if parameter `i` stays where it starts: [`FIXED`], A's force-row entries that `force`
/// leaves out, and K ([`TILT`]) unless `tilt`.
fn is_fixed(i: usize, force: ForceTerms, tilt: bool) -> bool {
    if FIXED.contains(&i) {
        return true;
    }
    if !tilt && TILT.contains(&i) {
        return true;
    }
    if !(5..23).contains(&i) {
        return false;
    }
    let (row, col) = ((i - 5) / 6, (i - 5) % 6);
    match force {
        ForceTerms::Full => false,
        ForceTerms::Drag => row != col,
        ForceTerms::None => true,
    }
}

impl Response {
    /// The blob's own prediction: unit gains, no lag, no velocity term.
    pub fn identity() -> Self {
        Self {
            thrust_gain: 1.0,
            torque_gain: [1.0; 3],
            torque_lag_s: 0.0,
            accel_per_velocity: [[0.0; 6]; 6],
            accel_bias: [0.0; 6],
            thrust_lag_s: 0.0,
            accel_per_tilt: [[0.0; 2]; 3],
        }
    }

    /// The parameters as one vector in [`PARAMS`] order.
    pub fn to_params(&self) -> [f64; PARAMS] {
        let mut p = [0.0; PARAMS];
        let flat = [self.thrust_gain]
            .into_iter()
            .chain(self.torque_gain)
            .chain([self.torque_lag_s])
            .chain(self.accel_per_velocity.into_iter().flatten())
            .chain(self.accel_bias)
            .chain([self.thrust_lag_s])
            .chain(self.accel_per_tilt.into_iter().flatten());
        for (o, v) in p.iter_mut().zip(flat) {
            *o = f64::from(v);
        }
        p
    }

    /// The response of a parameter vector ([`Response::to_params`]'s order); the lag is
    /// clamped to ≥ 0.
    pub fn from_params(p: &[f64; PARAMS]) -> Self {
        let mut r = Self::identity();
        let mut it = p.iter().map(|&v| v as f32);
        let mut next = || it.next().unwrap_or(0.0);
        r.thrust_gain = next();
        r.torque_gain = [next(), next(), next()];
        r.torque_lag_s = next().max(0.0);
        for row in r.accel_per_velocity.iter_mut() {
            for v in row.iter_mut() {
                *v = next();
            }
        }
        for v in r.accel_bias.iter_mut() {
            *v = next();
        }
        r.thrust_lag_s = next().max(0.0);
        for row in r.accel_per_tilt.iter_mut() {
            for v in row.iter_mut() {
                *v = next();
            }
        }
        r
    }

    /// True if every number is finite.
    pub fn is_finite(&self) -> bool {
        self.to_params().iter().all(|v| v.is_finite())
    }
}

/// A blob's model with the response's velocity term added to its dynamics (the input part is
/// applied by [`rollout`]).
struct WithVelocityTerm<'a, M> {
    base: &'a M,
    response: &'a Response,
}

impl<M: HamiltonianModel> HamiltonianModel for WithVelocityTerm<'_, M> {
    fn terms(&self, state: &State) -> ModelTerms {
        self.base.terms(state)
    }

    fn mass_kg(&self) -> f32 {
        self.base.mass_kg()
    }

    fn motor_tau_s(&self) -> f32 {
        self.base.motor_tau_s()
    }

    fn port(&self) -> &hamflight::model::PortTerms {
        self.base.port()
    }

    fn dynamics(&self, state: &State, u: &Vector4<f32>, a: &[f32; FEATURES]) -> StateDerivative {
        let mut d = self.base.dynamics(state, u, a);
        let z = [
            state.v_body_m_s.x,
            state.v_body_m_s.y,
            state.v_body_m_s.z,
            state.w_body_rad_s.x,
            state.w_body_rad_s.y,
            state.w_body_rad_s.z,
        ];
        let r = self.response;
        let mut acc = [0.0f32; 6];
        for ((o, row), c) in acc.iter_mut().zip(&r.accel_per_velocity).zip(&r.accel_bias) {
            *o = row.iter().zip(&z).map(|(a, b)| a * b).sum::<f32>() + c;
        }
        d.v_dot_m_s2 += Vector3::new(acc[0], acc[1], acc[2]);
        let down = state.rot.transpose() * Vector3::z();
        for (o, k) in acc[3..].iter_mut().zip(&r.accel_per_tilt) {
            *o += k[0] * down.x + k[1] * down.y;
        }
        d.w_dot_rad_s2 += Vector3::new(acc[3], acc[4], acc[5]);
        d
    }
}

/// Rolls `base` with `response` out from `s0` under the logged wrenches `u` (one per step of
/// `dt_s`, RK4 as training integrates, a = 0), calling `visit(k, state)` after step k. Stops
/// early if the state stops being finite.
pub fn rollout<M: HamiltonianModel>(
    base: &M,
    response: &Response,
    s0: &State,
    u: &[[f32; 4]],
    dt_s: f32,
    mut visit: impl FnMut(usize, &State),
) {
    let model = WithVelocityTerm { base, response };
    // The model's own input lags (its PortTerms; none for a rigid-body blob), then the
    // response's.
    let port = *base.port();
    let mut model_lag = ActuatorLag::new();
    // The lag discretized by backward Euler, τ̄ₖ = (T τ̄ₖ₋₁ + dt τₖ) / (T + dt): unlike
    // exp(−dt/T), its pole moves at T = 0, so a fit that reaches T = 0 can leave it again.
    let pole = |lag: f32| {
        let lag = lag.max(0.0);
        if lag + dt_s > 0.0 {
            lag / (lag + dt_s)
        } else {
            0.0
        }
    };
    let (alpha, alpha_f) = (pole(response.torque_lag_s), pole(response.thrust_lag_s));
    let mut tau = u.first().map_or([0.0; 3], |u0| [u0[1], u0[2], u0[3]]);
    let mut thrust = u.first().map_or(0.0, |u0| u0[0]);
    let mut s = *s0;
    for (k, uk) in u.iter().enumerate() {
        let lagged = model_lag.step(&port, &Vector4::from(*uk), dt_s);
        let uk = &[lagged.x, lagged.y, lagged.z, lagged.w];
        for (t, &x) in tau.iter_mut().zip(&uk[1..]) {
            *t = alpha * *t + (1.0 - alpha) * x;
        }
        thrust = alpha_f * thrust + (1.0 - alpha_f) * uk[0];
        let ue = Vector4::new(
            response.thrust_gain * thrust,
            response.torque_gain[0] * tau[0],
            response.torque_gain[1] * tau[1],
            response.torque_gain[2] * tau[2],
        );
        s = rk4_step(&model, &s, &ue, &[0.0; FEATURES], dt_s);
        if !s.is_finite() {
            return;
        }
        visit(k, &s);
    }
}

/// Errors of `base` with `response` (a = 0) over windows `ids` of `data`: the `score` row.
pub fn response_errors<M: HamiltonianModel>(
    base: &M,
    response: &Response,
    data: &Windows,
    ids: &[usize],
) -> HorizonErrors {
    let dt = 1.0 / data.sample_hz;
    let n = data.window_len.saturating_sub(1);
    let mut acc = Acc::new(n);
    for w in ids.iter().filter_map(|&i| data.windows.get(i)) {
        add_window(&mut acc, base, response, w, dt);
    }
    acc.finish()
}

/// Adds the errors of `base` with `response` (a = 0) on window `w` to `acc` (its first
/// `acc`-many steps), rolled out at `dt_s` from the window's first state. A rollout that
/// diverged counts with its last finite state at every later step, so that a diverging
/// response scores badly instead of dropping its worst windows.
pub fn add_window<M: HamiltonianModel>(
    acc: &mut Acc,
    base: &M,
    response: &Response,
    w: &super::data::Window,
    dt_s: f32,
) {
    let Some(s0) = w.states.first() else { return };
    let n = acc.steps();
    let u = w.u.get(..n).unwrap_or(&w.u);
    let mut last = (0, *s0);
    rollout(base, response, s0, u, dt_s, |k, s| {
        if let Some(t) = w.states.get(k + 1) {
            acc.add(k, s, t);
        }
        last = (k + 1, *s);
    });
    for k in last.0..n {
        if let Some(t) = w.states.get(k + 1) {
            acc.add(k, &last.1, t);
        }
    }
    acc.n += 1;
}

/// What [`fit`] is told.
#[derive(Clone, Debug)]
pub struct FitConfig {
    /// Levenberg–Marquardt iterations at most.
    pub iterations: usize,
    /// The error scales (m, m/s, rad, rad/s) that make position, velocity, attitude and rate
    /// residuals comparable.
    pub scales: [f64; 4],
    /// Threads for the finite-difference Jacobian.
    pub threads: usize,
    /// Which force terms of A the fit uses (default: the drag per axis).
    pub force: ForceTerms,
    /// Fit K, the angular acceleration with tilt (default true; false holds it where it
    /// starts).
    pub tilt: bool,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            iterations: 20,
            scales: [0.1, 0.5, 0.2, 0.6],
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            force: ForceTerms::default(),
            tilt: true,
        }
    }
}

/// The response's own rollout ([`rollout`] of `base` with [`Response::from_params`]).
struct ResponseRoll<'a, M> {
    base: &'a M,
}

impl<M: HamiltonianModel + Sync> Roll for ResponseRoll<'_, M> {
    fn roll(
        &self,
        p: &[f64],
        s0: &State,
        u: &[[f32; 4]],
        dt_s: f32,
        visit: &mut dyn FnMut(usize, &State),
    ) {
        let mut q = [0.0; PARAMS];
        for (o, v) in q.iter_mut().zip(p) {
            *o = *v;
        }
        rollout(
            self.base,
            &Response::from_params(&q),
            s0,
            u,
            dt_s,
            |k, s| visit(k, s),
        );
    }
}

/// Fits the response to windows `ids` of `data` from `start`, by Levenberg–Marquardt with a
/// forward-difference Jacobian on `cfg.threads` threads. `progress` sees every iteration. Returns
/// the best response found and the iterations.
pub fn fit<M: HamiltonianModel + Sync>(
    base: &M,
    data: &Windows,
    ids: &[usize],
    start: &Response,
    cfg: &FitConfig,
    progress: impl FnMut(&FitStep),
) -> (Response, Vec<FitStep>) {
    let fixed: Vec<bool> = (0..PARAMS)
        .map(|i| is_fixed(i, cfg.force, cfg.tilt))
        .collect();
    let project = |q: &mut [f64]| {
        for i in [TORQUE_LAG, THRUST_LAG] {
            if let Some(x) = q.get_mut(i) {
                *x = x.max(0.0);
            }
        }
    };
    let problem = Problem {
        roll: &ResponseRoll { base },
        data,
        ids,
        scales: cfg.scales,
        threads: cfg.threads,
        priors: &[],
    };
    let (p, steps) = lm_fit(
        &problem,
        start.to_params().to_vec(),
        &fixed,
        &project,
        cfg.iterations,
        progress,
    );
    let mut q = [0.0; PARAMS];
    for (o, v) in q.iter_mut().zip(&p) {
        *o = *v;
    }
    (Response::from_params(&q), steps)
}
