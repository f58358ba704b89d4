//! The disturbance adaptation law (paper eq. `geometric_adaptive_law`):
//! ȧ = Wᵀ(q, 𝔭) [c_p e_p + c_v e_v; c_R e_R + c_ω e_ω],
//! integrated per control tick with a projection that keeps ‖a‖ ≤ a_max.
//!
//! Sign: the disturbance enters 𝔭̇ as +W a*, the controller subtracts W a; with
//! V = ½ k_p‖e_p‖² + ½ m‖e_v‖² + ½ ãᵀΓ⁻¹ã (ã = a* − a) this law cancels the cross term.

use crate::model::FEATURES;
use nalgebra::{SMatrix, SVector, Vector3};

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

/// The online estimate a of the disturbance weights.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Adaptation {
    /// The estimate a ∈ ℝᵖ.
    pub a: SVector<f32, FEATURES>,
}

impl Adaptation {
    /// Back to a = 0.
    pub fn reset(&mut self) {
        self.a = SVector::zeros();
    }

    /// ȧ for the given features and errors.
    pub fn rate(
        rates: &AdaptationRates,
        features: &SMatrix<f32, 6, FEATURES>,
        err: &TrackingError,
    ) -> SVector<f32, FEATURES> {
        let lin = err.e_p * rates.c_p + err.e_v * rates.c_v;
        let ang = err.e_r * rates.c_r + err.e_w * rates.c_w;
        let s = nalgebra::Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z);
        features.transpose() * s
    }

    /// One explicit-Euler step a ← Proj(a + dt ȧ). A non-finite update is dropped.
    pub fn step(
        &mut self,
        rates: &AdaptationRates,
        features: &SMatrix<f32, 6, FEATURES>,
        err: &TrackingError,
        dt_s: f32,
    ) {
        let next = self.a + Self::rate(rates, features, err) * dt_s;
        if !next.iter().all(|v| v.is_finite()) {
            return;
        }
        let n = next.norm();
        self.a = if n > rates.a_max && n > 0.0 {
            next * (rates.a_max / n)
        } else {
            next
        };
    }
}
