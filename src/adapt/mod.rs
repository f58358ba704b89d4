//! The disturbance adaptation: the paper's gradient law (eq. `geometric_adaptive_law`) and a
//! composite (prediction-error) law beside it, one module, one robust modification for both.
//!
//! **Gradient law (the paper's):** ȧ = Wᵀ(q, 𝔭) [c_p e_p + c_v e_v; c_R e_R + c_ω e_ω],
//! integrated per control tick with a projection that keeps ‖a‖ ≤ a_max.
//!
//! Sign: the disturbance enters 𝔭̇ as +W a*, the controller subtracts W a; with
//! V = ½ k_p‖e_p‖² + ½ m‖e_v‖² + ½ ãᵀΓ⁻¹ã (ã = a* − a) this law cancels the cross term.
//!
//! **Robust modification (against windup):** the paper's law integrates the tracking
//! errors whatever their cause. A 0.5 m step makes e_p ≈ 0.5 m for a second, which the law reads
//! as a disturbance and winds a up; unwinding takes seconds (`step`: 0.51 cm RMSE over t ≥ 5 s,
//! against 0.0015 cm for the geometric controller without adaptation). Guards, for both laws:
//! - the projection ‖a‖ ≤ a_max, and, while the mixer saturates or the tilt limit binds, the
//!   drives clipped to
//!   [`AdaptationRates::saturated_drive_m`] and [`AdaptationRates::saturated_drive_rad`]: an
//!   unreachable demand is weak evidence about the disturbance, but a fault that keeps the mixer
//!   saturated is a disturbance, and a law switched off for the saturation's length can stay
//!   frozen for good (a rotor loss behind a 72 ms motor lag rolled the vehicle over so);
//! - optional (default off): the drives c_p e_p + c_v e_v and c_R e_R + c_ω e_ω clipped in norm
//!   to c_p `drive_max_m` and c_R `drive_max_rad` (direction kept, so the cancellation between
//!   e_p and e_v during a transient survives; clipping e_p and e_v separately made `step` worse,
//!   up to 13 cm), and a soft freeze that scales them by 1 / (1 + (‖e_p‖ / `soft_freeze_m`)²).
//!   They help `step` under the gradient law only partly and cost the smooth paths
//!   (docs/adaptation.md): the tail of every transient still winds the law, because a tracking
//!   error alone cannot tell a transient from a disturbance.
//! - what does tell them apart is the **prediction error** of the composite law below: during a
//!   transient the model predicts the measured force, so ε ≈ 0 and a stays put
//!   (docs/adaptation.md's laws table has `step` under each law). It is the default law
//!   ([`AdaptationLaw::default`]) where it is compiled in.
//! - for the paper's gradient law, the answer is at the source of the transient: the
//!   **setpoint shaping** of [`crate::shaping`] (a reference model, as model-reference adaptive
//!   control has it) turns a setpoint jump into a motion the vehicle can fly, and the tracking
//!   term is frozen while the shaped setpoint is more than 2 cm from the raw one; smooth
//!   trajectories are untouched (paper-spiral bit for bit; `step`: docs/adaptation.md).
//! - and the **normalized gradient** ([`AdaptationRates::normalized`], default on): the law's
//!   loop gain grows as ‖W‖², so features far larger than nominal (a badly scaled trained model,
//!   or the ×5 of the wrong-features test) made it unstable (paper-spiral crashed at 1.3 s).
//!   Dividing ȧ by max(1, ‖W̃‖² / (2p)) keeps the rates' meaning for every trained model.
//!
//! **Composite law (Slotine and Li's composite adaptation; Neural-Fly's Kalman-style gain):**
//! a is also driven by the model's prediction error, the measured generalized force minus what
//! the model predicts, ε = ℳ(𝔭̇_measured) − (model terms + g u + W a), with a time-varying gain P:
//!
//! - linear rows: with an accelerometer (body-frame specific force f_s),
//!   𝔭̇_v = m v × ω − m g Rᵀe₃ + m f_s and the model terms cancel:
//!   ε_v = m f_s − (g u)_v − (W a)_v, no differentiation; without one, 𝔭̇_v = m (v_k − v_{k−1})/dt;
//! - angular rows: 𝔭̇_ω = J (ω_k − ω_{k−1})/dt, ε_ω = 𝔭̇_ω − Jω × ω − (g u)_ω − (W a)_ω (J from
//!   the model's J⁻¹; the ∂H/∂rᵢ term of a q-dependent J is left out: J barely varies);
//! - u is the wrench the mixer delivered on the previous tick (what acted over the interval),
//!   passed through an assumed first-order motor lag (`motor_tau_s`);
//! - the measured force and W are low-passed by the same first-order filter (time constant
//!   `filter_tau_s`), so ε compares like with like and the differences' noise is smoothed;
//! - the rows are scaled to a's units (force rows / m → m/s², torque rows / 1e-3 N·m), and the
//!   estimate is a Kalman filter for a random walk a: P ← P + Q dt, then, R being diagonal, the
//!   six rows hᵢ as six scalar measurements in turn (exactly the batch K = P Hᵀ(H P Hᵀ + R)⁻¹
//!   update, without a 6×6 solve): k = P hᵢᵀ / sᵢ with sᵢ = hᵢ P hᵢᵀ + rᵢ, a ← a + k εᵢ,
//!   P ← P − (P hᵢᵀ)(P hᵢᵀ)ᵀ / sᵢ, an outer product of one vector, so P stays exactly symmetric
//!   in f32; a diagonal that rounding drives to ≤ 0 restarts P at p0 I, and P is bounded
//!   (largest diagonal ≤ p_max, by scaling, which keeps it PD). (A 6×6 Joseph form cost 11,600
//!   instructions a step on the MCU.) The
//!   process noise Q is what lets it follow a changing disturbance: its bandwidth is about
//!   √(q / (r dt)) for one row.
//!
//! The gradient (tracking) term runs beside it with the same rates and the same robust
//! modification: ȧ = Wᵀ sat(c e) plus the Kalman correction. The composite law's Lyapunov
//! argument wants the tracking term scaled by P as well; we keep the paper's constant gain there
//! (so the two laws differ only by the prediction term) and check the loop in SITL.

use crate::mixer::Wrench;
use crate::model::{FEATURES, NOMINAL_TORQUE_FEATURE_NM};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3, Vector4, Vector6};

mod composite;

use composite::PredictionState;
pub use composite::{CompositeGains, PortPrediction, PredictionInput, FAULT_ABORT_GROWTH};

/// The torque unit a reads in (N·m per unit of a): the features' torque columns are scaled so.
pub const TORQUE_UNIT_NM: f32 = 1e-3;

/// Adaptation rates, one per error, applied per row block (force rows, torque rows).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptationRates {
    /// c_p: weight of the body-frame position error e_p (1/(m·s) per feature unit).
    pub c_p: f32,
    /// c_v: weight of the body-frame velocity error e_v.
    pub c_v: f32,
    /// c_R: weight of the rotation error e_R.
    pub c_r: f32,
    /// c_ω: weight of the angular-velocity error e_ω.
    pub c_w: f32,
    /// Projection radius a_max: ‖a‖ never exceeds it.
    pub a_max: f32,
    /// Robust modification: the translational drive c_p e_p + c_v e_v is clipped to the norm
    /// c_p · `drive_max_m` (m: the drive of a pure position error of that size).
    pub drive_max_m: f32,
    /// Robust modification: the rotational drive c_R e_R + c_ω e_ω is clipped to c_R ·
    /// `drive_max_rad`.
    pub drive_max_rad: f32,
    /// Robust modification: both drives are scaled by 1 / (1 + (‖e_p‖ / `soft_freeze_m`)²), so
    /// the law all but stops while the vehicle is far from the reference (a transient, not a
    /// disturbance) and runs at full rate near it.
    pub soft_freeze_m: f32,
    /// While the mixer saturates (roll/pitch or collective), the translational drive is clipped
    /// to c_p · `saturated_drive_m` (m) instead of being switched off: an unreachable demand
    /// must not wind the estimate up, but a fault that keeps the mixer saturated (a rotor loss)
    /// must still be learned, or the estimate stays at its value from before the fault for as
    /// long as the saturation lasts, which can be for good.
    pub saturated_drive_m: f32,
    /// The same bound on the rotational drive while the mixer saturates: c_R ·
    /// `saturated_drive_rad`.
    pub saturated_drive_rad: f32,
    /// Normalized gradient: ȧ is divided by
    /// max(1, ‖W̃‖²_F / (h p)), where W̃ is W in nominal units (force rows divided by m, torque
    /// rows by [`NOMINAL_TORQUE_FEATURE_NM`]), p = FEATURES is ‖W̃‖²_F of the nominal features
    /// and h = [`NORMALIZATION_HEADROOM`]. The rates are tuned in nominal feature units; the
    /// loop gain of the paper's law grows as ‖W‖², so with it the same rates hold for any
    /// trained model whatever the scale of its features. A scalar factor keeps the law's
    /// direction Wᵀ s (the normalized gradient law of adaptive control).
    pub normalized: bool,
}

impl AdaptationRates {
    /// The same rates without the robust modification (the paper's law literally).
    pub fn unclipped(self) -> Self {
        Self {
            drive_max_m: f32::INFINITY,
            drive_max_rad: f32::INFINITY,
            soft_freeze_m: f32::INFINITY,
            saturated_drive_m: f32::INFINITY,
            saturated_drive_rad: f32::INFINITY,
            normalized: false,
            ..self
        }
    }

    /// The rates that run while the mixer saturates: the drives clipped to
    /// [`AdaptationRates::saturated_drive_m`] and [`AdaptationRates::saturated_drive_rad`]
    /// (each the smaller of its bound and the unsaturated one).
    pub fn saturated(self) -> Self {
        Self {
            drive_max_m: self.drive_max_m.min(self.saturated_drive_m),
            drive_max_rad: self.drive_max_rad.min(self.saturated_drive_rad),
            ..self
        }
    }
}

/// Which adaptation law runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AdaptationLaw {
    /// The paper's gradient law on the tracking errors (eq. `geometric_adaptive_law`).
    Gradient,
    /// The gradient law plus the prediction-error (Kalman-gain) term (feature `composite`).
    #[cfg(feature = "composite")]
    Composite,
}

impl Default for AdaptationLaw {
    /// The composite law where it is compiled in (feature `composite`), else the paper's
    /// gradient law.
    fn default() -> Self {
        #[cfg(feature = "composite")]
        {
            Self::Composite
        }
        #[cfg(not(feature = "composite"))]
        {
            Self::Gradient
        }
    }
}

/// What the platform measures besides the state, for the composite law.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Measurement {
    /// Accelerometer: the specific force (non-gravitational force / m) in the body frame (m/s²).
    /// `None`: the composite law differences the velocity instead.
    pub acc_body_m_s2: Option<Vector3<f32>>,
}

/// The body-frame tracking errors the law is driven by (paper Sec. 3).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct TrackingError {
    /// e_p = Rᵀ(p − p*) (m).
    pub e_p: Vector3<f32>,
    /// e_v = v − Rᵀ v* (m/s).
    pub e_v: Vector3<f32>,
    /// e_R = ½(R*ᵀR − RᵀR*)^∨.
    pub e_r: Vector3<f32>,
    /// e_ω = ω − RᵀR* ω* (rad/s).
    pub e_w: Vector3<f32>,
}

/// The online estimate a of the disturbance weights, and the composite law's gain P.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Adaptation {
    /// The estimate a ∈ ℝᵖ.
    pub a: SVector<f32, FEATURES>,
    /// The composite law's gain P (zero until its first update). Only its upper triangle is
    /// kept up to date (the update reads and writes nothing else); [`Adaptation::covariance`]
    /// gives the whole symmetric matrix.
    p: SMatrix<f32, FEATURES, FEATURES>,
    pred: PredictionState,
}

fn clip(v: &Vector3<f32>, max: f32) -> Vector3<f32> {
    // The default (no clipping) skips the norm: the same result, fewer instructions a tick.
    if max == f32::INFINITY {
        return *v;
    }
    let n = crate::fpu::sqrt(v.norm_squared());
    if n > max && n > 0.0 {
        v * (max / n)
    } else {
        *v
    }
}

/// Headroom of the normalization: features up to this many times the nominal ones' squared
/// norm keep the full rate (a trained model's features are near nominal at hover and grow with
/// tilt; the shipped model's reach ~1.1× on paper-spiral).
pub const NORMALIZATION_HEADROOM: f32 = 2.0;

/// min(1, headroom / (`norm2` / `reference2`)): the normalized gradient's factor; 1 for a
/// non-positive or non-finite reference or norm (nothing to normalize against).
fn normalization(norm2: f32, reference2: f32) -> f32 {
    let ratio = norm2 / (reference2 * NORMALIZATION_HEADROOM);
    if ratio > 1.0 && ratio.is_finite() {
        1.0 / ratio
    } else {
        1.0
    }
}

fn finite<const R: usize, const C: usize>(m: &SMatrix<f32, R, C>) -> bool {
    m.iter().all(|x| x.is_finite())
}

impl Adaptation {
    /// Back to a = 0 and an uninitialized P; forgets the previous tick.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Forget the previous tick (after a fault: the next interval is not one tick long).
    pub fn break_sequence(&mut self) {
        self.pred.has_prev = false;
    }

    /// ȧ of the gradient law for the given features and errors, with the robust clipping, the
    /// normalization factor `scale` ([`Adaptation::feature_normalization`], applied when
    /// `rates.normalized`; computed once by the caller, who needs it for the composite law
    /// too) and only `torque_share` of the torque rates c_R, c_ω (the composite law's
    /// [`CompositeGains::torque_rate_scale`]; 1 for the gradient law).
    pub fn rate(
        rates: &AdaptationRates,
        features: &SMatrix<f32, 6, FEATURES>,
        err: &TrackingError,
        scale: f32,
        torque_share: f32,
    ) -> SVector<f32, FEATURES> {
        let lin = err.e_p * rates.c_p + err.e_v * rates.c_v;
        let ang = err.e_r * rates.c_r + err.e_w * rates.c_w;
        // The default (no soft freeze) gives weight 1 exactly; skip its norm and division.
        let weight = if rates.soft_freeze_m == f32::INFINITY {
            1.0
        } else {
            let x = crate::fpu::sqrt(err.e_p.norm_squared()) / rates.soft_freeze_m;
            // x is NaN only for 0/0 or ∞/∞ (soft_freeze_m of 0 or ∞ with such an error): no
            // weight.
            if x.is_finite() {
                1.0 / (1.0 + x * x)
            } else {
                1.0
            }
        };
        let lin = clip(&lin, rates.c_p.abs() * rates.drive_max_m);
        let ang = clip(&ang, rates.c_r.abs() * rates.drive_max_rad);
        let (lin, ang) = if weight == 1.0 {
            (lin, ang)
        } else {
            (lin * weight, ang * weight)
        };
        let k = if rates.normalized { scale } else { 1.0 };
        let (lin, ang) = (lin * k, ang * (k * torque_share));
        let s = [lin.x, lin.y, lin.z, ang.x, ang.y, ang.z];
        SVector::from(crate::fpu::transpose_mul(&features.data.0, &s))
    }

    /// The normalized gradient's factor min(1, h p / ‖W̃‖²_F) ([`AdaptationRates::normalized`]):
    /// ‖W̃‖²_F of W in nominal units (force rows / m, torque rows / τ) is FEATURES for the
    /// nominal features at hover. The composite law scales its process noise Q by it too, so
    /// the observer's bandwidth (∝ ‖W‖ √Q) stays what it was designed for whatever the scale of
    /// a trained model's features.
    pub fn feature_normalization(features: &SMatrix<f32, 6, FEATURES>, mass_kg: f32) -> f32 {
        // One pass over the columns (column-major storage: rows 0–2 of a column are force,
        // 3–5 torque).
        let (force, torque) = crate::fpu::sum_squares_split(&features.data.0);
        const INV_TAU2: f32 = 1.0 / (NOMINAL_TORQUE_FEATURE_NM * NOMINAL_TORQUE_FEATURE_NM);
        normalization(
            force / (mass_kg * mass_kg) + torque * INV_TAU2,
            FEATURES as f32,
        )
    }

    /// One explicit-Euler step of the gradient law a ← Proj(a + dt ȧ), ȧ from
    /// [`Adaptation::rate`]. A non-finite update is dropped.
    pub fn step(
        &mut self,
        rates: &AdaptationRates,
        features: &SMatrix<f32, 6, FEATURES>,
        err: &TrackingError,
        (scale, torque_share): (f32, f32),
        dt_s: f32,
    ) {
        let next = self.a + Self::rate(rates, features, err, scale, torque_share) * dt_s;
        self.set_projected(next, rates.a_max);
    }

    fn set_projected(&mut self, next: SVector<f32, FEATURES>, a_max: f32) {
        if !finite(&next) {
            return;
        }
        let n = crate::fpu::sqrt(next.norm_squared());
        self.a = if n > a_max && n > 0.0 {
            next * (a_max / n)
        } else {
            next
        };
    }

    /// Record the wrench delivered from this tick on (call after the mixer).
    pub fn record_input(&mut self, delivered: &Wrench) {
        let u = Vector4::new(
            delivered.thrust_n,
            delivered.torque_nm.x,
            delivered.torque_nm.y,
            delivered.torque_nm.z,
        );
        self.pred.prev_u = if finite(&u) { u } else { Vector4::zeros() };
    }

    /// The composite law's gain P, symmetric (its lower triangle mirrored from the upper one
    /// the update keeps).
    pub fn covariance(&self) -> SMatrix<f32, FEATURES, FEATURES> {
        #[cfg(feature = "composite")]
        {
            let mut p = self.p;
            composite::mirror_upper(&mut p.data.0);
            p
        }
        // Without the composite law P is never updated (zero).
        #[cfg(not(feature = "composite"))]
        {
            self.p
        }
    }

    /// How many times the composite law's change detector restarted the torque block of P
    /// ([`CompositeGains::fault_innovation`]) since the last reset.
    pub fn fault_resets(&self) -> u32 {
        self.pred.fault_resets
    }

    /// trace P (the composite law's gain; zero before its first update).
    pub fn covariance_trace(&self) -> f32 {
        self.p.trace()
    }

    /// The composite law's prediction error ε = z_f − h_f a of its last update (a's units:
    /// force rows in m/s², torque rows in 1e-3 N·m), before that update moved a; `None` before
    /// the first update and after a reset.
    pub fn prediction_error(&self) -> Option<Vector6<f32>> {
        self.pred.eps.map(Vector6::from)
    }
}
