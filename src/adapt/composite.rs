//! The composite law's prediction-error term: the measured generalized force against what the
//! model predicts with the delivered wrench, a Kalman update of a and its gain P, and the change
//! detector on the torque rows (docs/adaptation.md).

use super::*;

/// Tuning of the composite law's prediction-error term (units: a's, see [`TORQUE_UNIT_NM`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompositeGains {
    /// Time constant of the low-pass on the measured force and on W, force rows (s).
    pub filter_tau_s: f32,
    /// The same for the torque rows (s). The low-pass is lag in the observer's loop around the
    /// attitude crossover (4° of its phase margin at 10 ms with the Crazyflie's chain), where
    /// the gyro's own filter already smooths the rate differences.
    pub torque_filter_tau_s: f32,
    /// Measurement variance R of the force rows, per sample ((m/s²)²).
    pub r_force: f32,
    /// Measurement variance R of the torque rows, per sample ((1e-3 N·m)²).
    pub r_torque: f32,
    /// Per-axis factor on `r_torque` (body x, y, z), ones by default.
    /// [`crate::control::Gains::for_vehicle`] sets it from the inertia so every axis's row has
    /// the same noise ([`crate::control::VehicleFacts::torque_noise_scale`]).
    pub r_torque_axis: [f32; 3],
    /// Process noise Q of the force columns of a (per second).
    pub q_force: f32,
    /// Process noise Q of the torque columns of a (per second).
    pub q_torque: f32,
    /// Initial P (diagonal).
    pub p0: f32,
    /// Bound on P's largest diagonal entry.
    pub p_max: f32,
    /// Time constant of the low-pass on the compensation's rate fed forward to the desired
    /// attitude (s); 0 turns the feedforward off (see [`crate::control`]).
    pub feedforward_tau_s: f32,
    /// The motors' first-order time constant the prediction assumes (s): the delivered wrench
    /// passes through this lag before it is compared with the measurement. A lag τ the model
    /// does not know feeds the estimate's own rate back through the prediction (ε gains
    /// ≈ τ W ȧ), which destabilizes it once the estimator's bandwidth times the unmodelled lag
    /// nears 1. Assuming a lag the motors do not have costs little; missing one the motors have
    /// can crash the law (RotorPy's 72 ms with 0 assumed). The cost of a longer assumed lag is a
    /// slower answer to a rotor fault (docs/adaptation.md, the rotor-loss set).
    pub motor_tau_s: f32,
    /// How far the measurement lags the wrench that caused it besides the motors (s): the
    /// sensor's low-pass and the samples of delay in front of the law. The predicted thrust
    /// passes a further first-order lag of `accel_lag_s` (the accelerometer's, for the force
    /// rows), the predicted torques one of `gyro_lag_s` (the gyro's, for the torque rows), so
    /// the prediction is delayed as the measurement is. Without it the delay's share of every
    /// torque command (≈ ω τ of it at frequency ω) reads as a disturbance near the attitude
    /// crossover, and the estimate closes a loop there that eats the attitude loop's phase
    /// margin. 0 turns a stage off.
    pub accel_lag_s: f32,
    /// See [`CompositeGains::accel_lag_s`].
    pub gyro_lag_s: f32,
    /// The share of the tracking term's torque rates c_R, c_ω that runs beside the prediction
    /// term. Both close a loop around the attitude crossover and take its phase margin
    /// ([`crate::control::Gains::for_vehicle`] splits the budget between them).
    pub torque_rate_scale: f32,
    /// Change detection on the torque rows (a fault such as a rotor loss): when the mean square
    /// of the torque rows' prediction error, low-passed over `fault_filter_tau_s`, exceeds
    /// `fault_innovation`² (a's units, 1e-3 N·m), the torque block of P restarts at
    /// `fault_p_reset` I (uncorrelated with the force columns), at most once per
    /// `fault_holdoff_s`, and the torque columns run on [`CompositeGains::fault_q_torque`] for
    /// [`CompositeGains::fault_boost_s`]. The observer's small-signal bandwidth, which the
    /// attitude loop's margin is designed for, stays Q's; a step of torque is learned in tens
    /// of milliseconds instead of the random walk's second. `f32::INFINITY` turns it off.
    pub fault_innovation: f32,
    /// See [`CompositeGains::fault_innovation`] (s).
    pub fault_filter_tau_s: f32,
    /// See [`CompositeGains::fault_innovation`].
    pub fault_p_reset: f32,
    /// See [`CompositeGains::fault_innovation`] (s).
    pub fault_holdoff_s: f32,
    /// After a detected change, the torque columns' process noise is `fault_q_torque` (per
    /// second, as [`CompositeGains::q_torque`]) for `fault_boost_s`: the observer runs fast
    /// while the fault's torque settles (the motors' lag, the filters), then slow again.
    pub fault_q_torque: f32,
    /// See [`CompositeGains::fault_q_torque`] (s).
    pub fault_boost_s: f32,
    /// A change counts only if the low-passed mean square is also `fault_ratio` times its own
    /// slow average (time constant `fault_baseline_tau_s`): a model whose prediction error is
    /// large all the time (an unmodelled motor lag, say) is not faulted, or the fast observer
    /// would close its loop around that error. A boost whose mean square grows past
    /// [`FAULT_ABORT_GROWTH`] times the one that started it ends at once.
    pub fault_ratio: f32,
    /// See [`CompositeGains::fault_ratio`] (s).
    pub fault_baseline_tau_s: f32,
    /// Doubt the assumed motor lag on the force rows: a prediction error that the delivered
    /// thrust through any lag from none to `motor_tau_s` would explain is not learned (the
    /// update sees the error of the nearer of the two predictions, or none when the measurement
    /// lies between them). A model whose lag is longer than the motors' otherwise reads every
    /// fast command as a disturbance; a fault, whose force no lag explains, is learned as before.
    pub lag_doubt: bool,
}

/// A boost of the torque observer ([`CompositeGains::fault_q_torque`]) ends when the torque
/// rows' mean-square prediction error grows past this many times the one that started it: the
/// fast observer is making it worse.
pub const FAULT_ABORT_GROWTH: f32 = 4.0;

impl Default for CompositeGains {
    fn default() -> Self {
        Self {
            filter_tau_s: 0.01,
            torque_filter_tau_s: 0.01,
            r_force: 1.0,
            r_torque: 1.0,
            r_torque_axis: [1.0; 3],
            q_force: 1.0,
            q_torque: 1.0,
            p0: 1.0,
            p_max: 100.0,
            feedforward_tau_s: 0.02,
            motor_tau_s: 0.05,
            accel_lag_s: 0.0,
            gyro_lag_s: 0.0,
            torque_rate_scale: 1.0,
            fault_innovation: f32::INFINITY,
            fault_filter_tau_s: 0.02,
            fault_p_reset: 10.0,
            fault_holdoff_s: 0.5,
            fault_q_torque: 50.0,
            fault_boost_s: 0.3,
            fault_ratio: 10.0,
            fault_baseline_tau_s: 2.0,
            lag_doubt: false,
        }
    }
}

/// What the composite law needs of one tick besides the errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PredictionInput<'a> {
    /// The features W(q, 𝔭) at this state.
    pub features: &'a SMatrix<f32, 6, FEATURES>,
    /// The input gain g(q).
    pub gain: &'a SMatrix<f32, 6, 4>,
    /// Mass m (kg).
    pub mass_kg: f32,
    /// Gravity g (m/s²).
    pub gravity_m_s2: f32,
    /// J (kg·m², body).
    pub inertia: &'a Matrix3<f32>,
    /// R (body → world).
    pub rot: &'a Matrix3<f32>,
    /// v (m/s, body).
    pub v_body_m_s: &'a Vector3<f32>,
    /// ω (rad/s, body).
    pub w_body_rad_s: &'a Vector3<f32>,
    /// The platform's extra measurements.
    pub measurement: &'a Measurement,
    /// [`Adaptation::feature_normalization`] of `features`: the process noise Q is scaled by it.
    pub feature_scale: f32,
    /// The model's port terms at this tick, if not the identity: the prediction then takes the
    /// input's gain, the dissipation, the gyrator and the learned potential out of the
    /// measured momentum rate as well.
    pub port: Option<&'a PortPrediction>,
}

/// What the model's port terms ([`crate::model::PortTerms`]) add to the composite prediction's
/// known momentum rate (docs/math.md "Dissipation, potential and actuator lag"): the input's
/// effective gain k (the prediction's g u becomes g (k ∘ u)) and the port wrench at the state.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct PortPrediction {
    /// k = [`crate::model::PortTerms::input_gain`].
    pub input_gain: Vector4<f32>,
    /// The port force at the state (N, body): [`crate::model::PortTerms::force`] at v, ω.
    pub force_n: Vector3<f32>,
    /// The port torque at the state (N·m, body): [`crate::model::PortTerms::torque`] at
    /// Rᵀe₃, v, ω.
    pub torque_nm: Vector3<f32>,
}

/// The composite law's memory between ticks.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(not(feature = "composite"), allow(dead_code))]
pub(super) struct PredictionState {
    /// v and ω of the previous tick.
    pub(super) prev_v: Vector3<f32>,
    pub(super) prev_w: Vector3<f32>,
    /// The wrench delivered over the interval since the previous tick, [f; τ].
    pub(super) prev_u: Vector4<f32>,
    /// The delivered wrench through the assumed motor lag.
    pub(super) u_lag: Vector4<f32>,
    /// `u_lag` through the measurement's lag (`accel_lag_s`, `gyro_lag_s`).
    pub(super) u_sensed: Vector4<f32>,
    /// The filtered difference of the predictions without and with the motor lag, force rows
    /// (a's units, as `z_f`; [`CompositeGains::lag_doubt`]).
    pub(super) gap_f: [f32; 3],
    /// Whether `u_lag` holds a value.
    pub(super) has_lag: bool,
    /// Whether `prev_*` hold a tick (false after a reset or a fault).
    pub(super) has_prev: bool,
    /// The filtered measured disturbance force (a's units) and the filtered scaled features.
    pub(super) z_f: [f32; 6],
    /// Row-major: `h_f[r]` is row r of the scaled features (the Kalman update's measurement
    /// rows).
    pub(super) h_f: [[f32; FEATURES]; 6],
    /// Whether the filters hold a sample.
    pub(super) has_filter: bool,
    /// The prediction error of the last update (a's units), for diagnostics.
    pub(super) eps: Option<[f32; 6]>,
    /// The torque rows' prediction error squared, low-passed (a's units²): the change
    /// detector's statistic ([`CompositeGains::fault_innovation`]).
    pub(super) torque_eps2_f: f32,
    /// Time since the torque block of P last restarted on a detected change, or since the
    /// filter started (s).
    pub(super) since_fault_s: f32,
    /// What is left of the fast process noise after a detected change (s).
    pub(super) boost_left_s: f32,

    /// The slow average of `torque_eps2_f`, and `torque_eps2_f` when the boost began.
    pub(super) torque_eps2_base: f32,
    pub(super) torque_eps2_at_fault: f32,
    /// How many times the change detector restarted the torque block of P.
    pub(super) fault_resets: u32,
}

impl Adaptation {
    /// One step of the composite law's prediction term: filters the measured disturbance force
    /// and the features, then the Kalman update of a and P (module docs). Call once per tick
    /// with the state's terms, before [`Adaptation::record_input`]. Returns the prediction error
    /// (a's units) when an update ran.
    #[cfg(feature = "composite")]
    pub fn predict_step(
        &mut self,
        gains: &CompositeGains,
        a_max: f32,
        x: &PredictionInput<'_>,
        dt_s: f32,
    ) -> Option<Vector6<f32>> {
        let v = *x.v_body_m_s;
        let w = *x.w_body_rad_s;
        let had_prev = self.pred.has_prev;
        let (prev_v, prev_w, u) = (self.pred.prev_v, self.pred.prev_w, self.pred.prev_u);
        self.pred.prev_v = v;
        self.pred.prev_w = w;
        self.pred.has_prev = true;
        if !(had_prev && dt_s > 0.0 && x.mass_kg > 0.0) {
            return None;
        }
        let m = x.mass_kg;
        let (raw, had_lag) = (u, self.pred.has_lag);
        let u = if had_lag {
            let beta = lag_gain(gains.motor_tau_s, dt_s);
            let lagged = self.pred.u_lag + (u - self.pred.u_lag) * beta;
            self.pred.u_lag = lagged;
            // The measurement's own lag: thrust as the accelerometer sees it, torques as the
            // gyro does.
            let (bf, bt) = (
                lag_gain(gains.accel_lag_s, dt_s),
                lag_gain(gains.gyro_lag_s, dt_s),
            );
            let us = &mut self.pred.u_sensed;
            us.x += (lagged.x - us.x) * bf;
            us.y += (lagged.y - us.y) * bt;
            us.z += (lagged.z - us.z) * bt;
            us.w += (lagged.w - us.w) * bt;
            *us
        } else {
            self.pred.u_lag = u;
            self.pred.u_sensed = u;
            u
        };
        self.pred.has_lag = true;
        // Without the motor lag (`lag_doubt`): the delivered wrench against the lagged one.
        let du = (gains.lag_doubt && had_lag).then(|| raw - self.pred.u_lag);
        // With port terms the input acts through its effective gain: g (k ∘ u).
        let effective = |u: Vector4<f32>| match x.port {
            Some(port) => u.component_mul(&port.input_gain),
            None => u,
        };
        let gu = x.gain * effective(u);
        let gu_v = Vector3::new(gu[0], gu[1], gu[2]);
        let gu_w = Vector3::new(gu[3], gu[4], gu[5]);
        // Measured disturbance force: 𝔭̇_measured − model terms − g u (N, N·m).
        let d_v = match x.measurement.acc_body_m_s2 {
            Some(acc) if crate::fpu::all_finite(acc.iter().copied()) => acc * m - gu_v,
            _ => {
                // Rᵀ e₃ is the third row of R.
                let up = Vector3::new(x.rot.m31, x.rot.m32, x.rot.m33);
                (v - prev_v) * (m / dt_s) - v.cross(&w) * m + up * (m * x.gravity_m_s2) - gu_v
            }
        };
        let jw = x.inertia * w;
        let mut d_w = x.inertia * ((w - prev_w) * (1.0 / dt_s)) - jw.cross(&w) - gu_w;
        let mut d_v = d_v;
        if let Some(port) = x.port {
            // The port wrench's share of the known momentum rate.
            d_v -= port.force_n;
            d_w -= port.torque_nm;
        }
        // The same first-order low-pass on both sides, the rows scaled to a's units (force
        // rows / m → m/s², torque rows / 1e-3 N·m) in the same pass: with g = s α and
        // β = 1 − α, h_f ← fma(W, g, h_f β) (h_f + (s W − h_f) α), z_f likewise from d, and the
        // prediction error ε = z_f − h_f a with the estimate before this tick's update (the
        // sequence `fpu::kalman_rows` uses for its innovations, so row 0's is this ε₀). The
        // first sample has α = 1 on zeroed filters, which gives h_f = s W. A non-finite
        // feature shows as a non-finite sᵢ in the Kalman update, a non-finite z as a non-finite
        // a after it: either drops the update and zeroes the filters for a fresh start.
        let (alpha_f, alpha_t) = if self.pred.has_filter {
            (
                lag_gain(gains.filter_tau_s, dt_s),
                lag_gain(gains.torque_filter_tau_s, dt_s),
            )
        } else {
            (1.0, 1.0)
        };
        let (sf, st) = (1.0 / m, 1.0 / TORQUE_UNIT_NM);
        let coef = [sf * alpha_f, 1.0 - alpha_f, st * alpha_t, 1.0 - alpha_t];
        let d = [d_v.x, d_v.y, d_v.z, d_w.x, d_w.y, d_w.z];
        let mut eps = [0.0f32; 6];
        crate::fpu::filter_rows(
            &x.features.data.0,
            &mut self.pred.h_f,
            &mut self.pred.z_f,
            &d,
            &self.a.data.0[0],
            &coef,
            &mut eps,
        );
        self.pred.has_filter = true;
        // The doubted lag, on the force rows (the thrust's lag; the torque rows keep theirs for
        // the attitude loop's margin and the change detector): the error the prediction
        // without the lag leaves is ε − gap; the update sees the one nearer zero, or none if
        // they differ in sign (the measurement lies between the two predictions): the median
        // of 0, ε and ε − gap.
        let mut z = self.pred.z_f;
        if let Some(du) = du {
            let gap = x.gain.fixed_rows::<3>(0) * effective(du);
            let rows = self
                .pred
                .gap_f
                .iter_mut()
                .zip(eps.iter_mut())
                .zip(z.iter_mut())
                .zip(gap.iter());
            for (((gf, e), zr), gr) in rows {
                *gf += (sf * gr - *gf) * alpha_f;
                let alt = *e - *gf;
                let (lo, hi) = if *e < alt { (*e, alt) } else { (alt, *e) };
                let kept = if hi < 0.0 {
                    hi
                } else if lo > 0.0 {
                    lo
                } else {
                    0.0
                };
                *zr -= *e - kept;
                *e = kept;
            }
        }
        let out = self.kalman(gains, a_max, (dt_s, dt_s * x.feature_scale), z, eps);
        if out.is_none() {
            // A non-finite feature reached the filter: start it again at the next sample.
            self.pred.has_filter = false;
            self.pred.h_f = [[0.0; FEATURES]; 6];
            self.pred.z_f = [0.0; 6];
            self.pred.gap_f = [0.0; 3];
        }
        out
    }

    #[cfg(feature = "composite")]
    fn kalman(
        &mut self,
        g: &CompositeGains,
        a_max: f32,
        (dt_s, q_dt_s): (f32, f32),
        zf: [f32; 6],
        eps: [f32; 6],
    ) -> Option<Vector6<f32>> {
        // P lives in `self.p` as a 6×6 matrix, updated in place (no copy of its 36 entries in
        // and out); the updates below read and write its upper triangle only (the lower one is
        // mirrored on demand by `covariance`), so P stays exactly symmetric. Column-major
        // storage: p[c][r] is P(r, c).
        // A P whose diagonal is not positive starts again here. A non-finite entry of the upper
        // triangle (the only part read) needs no pass of its own: it makes some s non-finite
        // below, which drops this tick's update and starts P again.
        let p = &mut self.p.data.0;
        let diag_ok = p
            .iter()
            .enumerate()
            .all(|(i, col)| col.get(i).is_some_and(|d| *d > 0.0));
        if !diag_ok {
            restart_covariance(p, g.p0);
        }
        // Predict: a random walk, P ← P + Q dt (Q diagonal: force columns, then torque).
        // (`q_dt_s` is dt scaled by the features' normalization.)
        // The torque columns run on the change detector's process noise for a while after a
        // detected change.
        let q_torque = if self.pred.boost_left_s > 0.0 {
            self.pred.boost_left_s -= dt_s;
            g.fault_q_torque
        } else {
            g.q_torque
        };
        let (qf, qt) = (g.q_force * q_dt_s, q_torque * q_dt_s);
        for (i, col) in p.iter_mut().enumerate() {
            if let Some(d) = col.get_mut(i) {
                *d += if i < 3 { qf } else { qt };
            }
        }
        let rows = &self.pred.h_f;
        let a0: [f32; FEATURES] = self.a.data.0[0];
        // `eps`: the prediction error with the estimate before this tick's update
        // (`fpu::filter_rows`).
        // Change detection on the torque rows: restart their block of P.
        let [_, _, _, e3, e4, e5] = eps;
        let e2 = e3 * e3 + e4 * e4 + e5 * e5;
        let e2_f = self.pred.torque_eps2_f
            + (e2 - self.pred.torque_eps2_f) * lag_gain(g.fault_filter_tau_s, dt_s);
        // A non-finite error (a bad feature, dropped below) must not stop the detector for good.
        let e2_f = if e2_f.is_finite() { e2_f } else { 0.0 };
        self.pred.torque_eps2_f = e2_f;
        // Finite as `e2_f` is: it starts at zero and only ever moves toward it.
        let base = self.pred.torque_eps2_base;
        let base = base + (e2_f - base) * lag_gain(g.fault_baseline_tau_s, dt_s);
        self.pred.torque_eps2_base = base;
        let since = self.pred.since_fault_s + dt_s;
        self.pred.since_fault_s = since;
        if self.pred.boost_left_s > 0.0
            && e2_f > FAULT_ABORT_GROWTH * self.pred.torque_eps2_at_fault
        {
            self.pred.boost_left_s = 0.0;
        }
        if e2_f > g.fault_innovation * g.fault_innovation
            && e2_f > g.fault_ratio * base
            && since >= g.fault_holdoff_s
        {
            self.pred.since_fault_s = 0.0;
            self.pred.boost_left_s = g.fault_boost_s;
            self.pred.torque_eps2_at_fault = e2_f;
            self.pred.fault_resets = self.pred.fault_resets.saturating_add(1);
            restart_torque_block(p, g.fault_p_reset);
        }
        // Update: R is diagonal, so the six rows are six scalar measurements in turn (exactly
        // the batch update, without a 6×6 solve): s = h P hᵀ + r, k = P hᵀ / s,
        // a ← a + k (z − h a), P ← P − k (P hᵀ)ᵀ, on P's upper triangle (`fpu::kalman_rows`);
        // the lower is mirrored from it below, so P stays exactly symmetric.
        let mut a = a0;
        let (rf, rt, [rx, ry, rz]) = (g.r_force, g.r_torque, g.r_torque_axis);
        let mut s = [rf, rf, rf, rt * rx, rt * ry, rt * rz];
        crate::fpu::kalman_rows(p, &mut a, rows, &zf, &mut s);
        if !crate::fpu::all_finite(s) {
            // A non-finite feature: no update of a this tick, and P starts again (the rows
            // before it already moved P).
            restart_covariance(p, g.p0);
            return None;
        }
        // Positive diagonal (rounding may lose definiteness: start the gain again), bounded
        // largest diagonal (scaling keeps P positive definite).
        let mut dmax = 0.0f32;
        let mut dpos = true;
        for (i, col) in p.iter().enumerate() {
            let d = col.get(i).copied().unwrap_or(0.0);
            dpos &= d > 0.0;
            // P is finite here (every s was): a plain compare, no NaN handling.
            if d > dmax {
                dmax = d;
            }
        }
        if !dpos {
            restart_covariance(p, g.p0);
            dmax = g.p0;
        }
        if dmax > g.p_max && dmax > 0.0 {
            let f = g.p_max / dmax;
            for v in p.iter_mut().flatten() {
                *v *= f;
            }
        }
        // P is finite here: each update subtracts kᵢ (P hᵀ)ⱼ with |kᵢ (P hᵀ)ⱼ| ≤ √(PᵢᵢPⱼⱼ)
        // for a finite s (checked) and a finite, positive definite P (checked on entry). A
        // non-finite a can only come from a non-finite z: P's update does not read z, so it
        // stands.
        if !(crate::fpu::all_finite(a) && dmax.is_finite()) {
            return None;
        }
        self.set_projected(SVector::from(a), a_max);
        self.pred.eps = Some(eps);
        Some(Vector6::from(eps))
    }
}
/// dt / (τ + dt): the step gain of a first-order lag τ (s); 1 (no lag) for τ ≤ 0 or NaN.
#[cfg(feature = "composite")]
#[inline(always)]
fn lag_gain(tau_s: f32, dt_s: f32) -> f32 {
    if tau_s > 0.0 {
        dt_s / (tau_s + dt_s)
    } else {
        1.0
    }
}

/// P(min(r, c), max(r, c)) from the upper triangle of a column-major P (p[c][r], r ≤ c).
#[cfg(feature = "composite")]
#[inline(always)]
fn upper(p: &[[f32; FEATURES]; FEATURES], r: usize, c: usize) -> f32 {
    let (r, c) = if r <= c { (r, c) } else { (c, r) };
    p.get(c).and_then(|col| col.get(r)).copied().unwrap_or(0.0)
}

/// The torque block of a column-major P (columns and rows 3–5) set to `p_reset` I and its
/// cross terms with the force columns to zero, on the upper triangle (the only part the update
/// reads). Block-diagonal with two positive definite blocks, P stays positive definite.
#[cfg(feature = "composite")]
fn restart_torque_block(p: &mut [[f32; FEATURES]; FEATURES], p_reset: f32) {
    for (c, col) in p.iter_mut().enumerate().skip(3) {
        for (r, v) in col.iter_mut().enumerate().take(c + 1) {
            *v = if r == c { p_reset } else { 0.0 };
        }
    }
}

/// P = p0 I: the composite law's gain starts again.
#[cfg(feature = "composite")]
fn restart_covariance(p: &mut [[f32; FEATURES]; FEATURES], p0: f32) {
    for (i, col) in p.iter_mut().enumerate() {
        for (j, v) in col.iter_mut().enumerate() {
            *v = if i == j { p0 } else { 0.0 };
        }
    }
}

/// The lower triangle of a column-major P set from its upper one.
#[cfg(feature = "composite")]
#[inline(always)]
pub(super) fn mirror_upper(p: &mut [[f32; FEATURES]; FEATURES]) {
    for c in 0..FEATURES {
        for r in (c + 1)..FEATURES {
            let v = upper(p, r, c);
            if let Some(d) = p.get_mut(c).and_then(|col| col.get_mut(r)) {
                *d = v;
            }
        }
    }
}
