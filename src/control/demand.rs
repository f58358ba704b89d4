//! The law's body-frame demand b = [b_v; b_ω] (paper eq. `ES_DI_COMP_control`).

use super::*;

impl<M: HamiltonianModel> FlightController<M> {
    /// The law's body-frame demand b = [b_v; b_ω] on the actuated rows and its errors (paper
    /// eq. `ES_DI_COMP_control`, docs/math.md "The IDA-PBC control law"). Out of line, as are
    /// [`Self::actuate`] and [`Self::adapt`]: each phase's temporaries then live in its own
    /// frame, not all at once in the step's, which keeps the step's stack small enough to run
    /// inline in the Crazyflie's stabilizer task.
    #[inline(never)]
    pub(super) fn demand(
        &mut self,
        state: &State,
        sp: &Setpoint,
        v: &Vector3<f32>,
        inertia: &Matrix3<f32>,
        dt_s: f32,
    ) -> Demand {
        let g = &self.gains;
        let t = &self.terms;
        let m = t.mass_kg;
        let r = &state.rot;
        let rt = r.transpose();
        let w = &state.w_body_rad_s;
        let wa = t.features * self.adaptation.a;
        let wa_v = Vector3::new(wa.x, wa.y, wa.z);
        let wa_w = Vector3::new(wa.w, wa.a, wa.b);
        #[cfg(feature = "composite")]
        let mut port_pred = PortPrediction::default();

        // Translational law: b_v (body frame).
        let e_p = rt * (state.p_m - sp.p_m);
        let v_ref = rt * sp.v_m_s;
        let e_v = v - v_ref;
        let mut b_v =
            rt * ((Vector3::z() * t.gravity_m_s2 + sp.a_m_s2) * m) - e_p * g.k_p - e_v * g.k_v
                + w.cross(&e_v) * m
                - wa_v;
        // The port terms at the reference (docs/math.md "Dissipation, potential and actuator
        // lag"): the law cancels the drag, the gyrator and the learned potential at the
        // reference velocity, so what is left acts on the errors alone and is passive.
        if self.port_active {
            // With the composite law, the port force at the state for its prediction too.
            #[cfg(feature = "composite")]
            {
                let port = self.model.port();
                let (f_law, f_pred) = port.force_pair(&v_ref, &state.v_body_m_s, w);
                port_pred.input_gain = port.input_gain();
                port_pred.force_n = f_pred;
                b_v -= f_law;
            }
            #[cfg(not(feature = "composite"))]
            {
                b_v -= self.model.port().force(&v_ref, w);
            }
        }

        // Desired attitude from the force the law wants. Its rate Ḟ ≈ m p⃛*, and with the
        // composite law also minus the rate of the compensation R (W a)_v, so that the attitude
        // loop is told ahead how the thrust axis must turn to follow a changing disturbance.
        // Plus the position feedback's own rate −k_p ė_p = −k_p R e_v. The velocity feedback's
        // rate −k_v ė_v (Lee's geometric controller differentiates it through the model's
        // acceleration) is left out: it led the 2× figure of eight by a further 25 % but cut
        // the median delay margin by a sixth, 24 to 20 ms (docs/envelope.md, "Aggressive paths").
        #[cfg_attr(not(feature = "composite"), allow(unused_mut))]
        let mut f_dot = sp.j_m_s3 * m - r * (e_v * g.k_p);
        #[cfg(feature = "composite")]
        if g.adapt && g.law == AdaptationLaw::Composite && g.composite.feedforward_tau_s > 0.0 {
            let comp = r * wa_v;
            if let Some(prev) = self.comp_prev_n {
                let rate = (comp - prev) / dt_s;
                let alpha = dt_s / (g.composite.feedforward_tau_s + dt_s);
                let next = self.comp_rate_n_s + (rate - self.comp_rate_n_s) * alpha;
                if next.iter().all(|x| x.is_finite()) {
                    self.comp_rate_n_s = next;
                }
            }
            self.comp_prev_n = Some(comp);
            f_dot -= self.comp_rate_n_s;
        }
        #[cfg(not(feature = "composite"))]
        let _ = dt_s;
        let f_w = r * b_v;
        let att = desired_attitude(&f_w, &f_dot, sp.yaw_rad, sp.yaw_rate_rad_s, &self.tilt);
        // Altitude first: the thrust never gives more vertical force than the law
        // wants. Past the tilt limit the aim is the limited force b₃* F_z / b₃*,z, which keeps
        // F_z and gives up the horizontal part beyond the limit; and while the body axis b₃ is
        // tilted less far than the aim (it lags behind b₃* at a step), the projection
        // F·b₃ would give more than F_z upwards, so the thrust is F_z / b₃,z instead: the
        // vertical force stays the law's and the body gives up horizontal force until it has
        // turned. When b₃ is tilted further than the aim the projection is already the smaller.
        let b3 = Vector3::new(r.m13, r.m23, r.m33);
        if f_w.z > 0.0 && b3.z > MIN_UPRIGHT {
            let b3_star_z = att.rot.m33;
            if att.tilt_limited && b3_star_z > MIN_UPRIGHT {
                let b3_star = Vector3::new(att.rot.m13, att.rot.m23, b3_star_z);
                b_v.z = b3.dot(&(b3_star * (f_w.z / b3_star_z)));
            }
            b_v.z = b_v.z.min(f_w.z / b3.z);
        }
        let e_r = crate::lie::rotation_error(r, &att.rot);
        let w_des_body = rt * att.rot * att.w_rad_s;
        let e_w = w - w_des_body;

        // Rotational law: b_ω (body frame).
        let p_w = inertia * w;
        let p_dot_des_w = -(inertia * w.cross(&w_des_body));
        let pd_w = (e_r * g.k_r + e_w * g.k_w).component_mul(&g.attitude_axis_scale);
        let mut b_w = w.cross(&p_w) - pd_w + p_dot_des_w - wa_w;
        if self.port_active {
            let b_up = Vector3::new(r.m31, r.m32, r.m33);
            // With the composite law, the port torque at the state for its prediction too.
            #[cfg(feature = "composite")]
            {
                let (t_law, t_pred) = self.model.port().torque_pair(
                    &b_up,
                    (&v_ref, &w_des_body),
                    (&state.v_body_m_s, w),
                );
                port_pred.torque_nm = t_pred;
                b_w -= t_law;
            }
            #[cfg(not(feature = "composite"))]
            {
                b_w -= self.model.port().torque(&b_up, &v_ref, &w_des_body);
            }
        }
        Demand {
            b_act: Vector4::new(b_v.z, b_w.x, b_w.y, b_w.z),
            errors: TrackingError { e_p, e_v, e_r, e_w },
            tilt_limited: att.tilt_limited,
            #[cfg(feature = "composite")]
            port_pred,
        }
    }
}

/// The least upward component (world z) of the body axis or of b₃* for which the altitude-first
/// thrust divides by it; below it (past ≈ 84°) the projection alone is used.
const MIN_UPRIGHT: f32 = 0.1;

/// What [`FlightController::demand`] gives the rest of the step.
pub(super) struct Demand {
    /// b on the actuated rows: [b_v,z (N); b_ω (N·m)].
    pub(super) b_act: Vector4<f32>,
    pub(super) errors: TrackingError,
    pub(super) tilt_limited: bool,
    /// The port terms at the state for the composite prediction (when the port is active):
    /// computed beside the law's, handed to [`FlightController::adapt`] (not kept in the
    /// controller, whose size the Crazyflie app's C ABI fixes).
    #[cfg(feature = "composite")]
    pub(super) port_pred: PortPrediction,
}
