//! The adaptation step: the disturbance estimate a's update from the tracking errors and, with
//! the composite law, the model's prediction error (paper eq. `geometric_adaptive_law`).

use super::*;

impl<M: HamiltonianModel> FlightController<M> {
    /// Adaptation (paper eq. geometric_adaptive_law, with the robust clipping of
    /// crate::adapt); the tracking term's drive is bounded while the mixer cannot deliver the
    /// wrench or the tilt limit binds ([`AdaptationRates::saturated`]: at the limit the path
    /// asks for more than the law lets the body tilt, and the tracking error that follows is
    /// no disturbance), so the estimate neither winds up on an
    /// unreachable demand nor stays frozen through a fault that keeps the mixer saturated. The composite law's
    /// prediction term compares with the wrench actually delivered, so it keeps running.
    #[inline(never)]
    pub(super) fn adapt(
        &mut self,
        state: &State,
        meas: &Measurement,
        inertia: &Matrix3<f32>,
        demand: &Demand,
        act: &Actuation,
        dt_s: f32,
    ) {
        let t = &self.terms;
        let errors = &demand.errors;
        #[cfg(not(feature = "composite"))]
        let _ = (state, meas, inertia);
        let g = &self.gains;
        let sat = act.sat;
        // The features' normalization, once for both terms.
        let scale = Adaptation::feature_normalization(&t.features, t.mass_kg);
        #[cfg(feature = "composite")]
        if g.law == AdaptationLaw::Composite {
            let x = PredictionInput {
                features: &t.features,
                gain: &t.gain,
                mass_kg: t.mass_kg,
                gravity_m_s2: t.gravity_m_s2,
                inertia,
                rot: &state.rot,
                v_body_m_s: &state.v_body_m_s,
                w_body_rad_s: &state.w_body_rad_s,
                measurement: meas,
                feature_scale: scale,
                port: self.port_active.then_some(&demand.port_pred),
            };
            self.adaptation
                .predict_step(&g.composite, g.rates.a_max, &x, dt_s);
        }
        if !self.shaper.freezes_adaptation() {
            // Saturated or tilt-limited: the drive bounded, not switched off
            // (AdaptationRates::saturated).
            let rates = if sat.roll_pitch || sat.thrust || demand.tilt_limited {
                g.rates.saturated()
            } else {
                g.rates
            };
            #[cfg(feature = "composite")]
            let torque_share = if g.law == AdaptationLaw::Composite {
                g.composite.torque_rate_scale
            } else {
                1.0
            };
            #[cfg(not(feature = "composite"))]
            let torque_share = 1.0;
            self.adaptation
                .step(&rates, &t.features, errors, (scale, torque_share), dt_s);
        }
        #[cfg(feature = "composite")]
        self.adaptation.record_input(&act.delivered);
        #[cfg(not(feature = "composite"))]
        let _ = act.delivered;
    }
}
