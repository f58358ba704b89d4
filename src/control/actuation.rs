//! u = g† b on the actuated rows, the motor-lag lead and the mixer: the wrench the rotors
//! deliver.

use super::*;

impl<M: HamiltonianModel> FlightController<M> {
    /// u = g† b on the actuated rows (body z force, torques), the motor-lag lead, the mixer,
    /// and the delivered wrench's motor model ([`Actuation::singular`] if g's actuated block
    /// is singular).
    #[inline(never)]
    pub(super) fn actuate(&mut self, b_act: &Vector4<f32>, dt_s: f32) -> Actuation {
        let g = &self.gains;
        let g_act = self.terms.gain.fixed_rows::<4>(2).into_owned();
        let b_act = *b_act;
        let u = match solve_in_order(&g_act, &b_act) {
            Some(u) => u,
            None => match g_act.try_inverse() {
                Some(inv) => inv * b_act,
                None => {
                    match (g_act.transpose() * g_act + Matrix4::identity() * 1e-9).try_inverse() {
                        Some(inv) => inv * g_act.transpose() * b_act,
                        None => {
                            return Actuation {
                                singular: true,
                                ..Actuation::default()
                            }
                        }
                    }
                }
            },
        };
        // The input's learned effective gain k (PortTerms::input_gain): u = k⁻¹ ∘ g† b.
        let u = if self.port_active {
            let k = self.model.port().input_gain();
            if !k.iter().all(|&x| x >= crate::model::port::MIN_INPUT_GAIN) {
                return Actuation {
                    singular: true,
                    ..Actuation::default()
                };
            }
            u.component_div(&k)
        } else {
            u
        };
        let wrench = Wrench {
            thrust_n: u.x,
            torque_nm: Vector3::new(u.y, u.z, u.w),
        };
        // Motor-lag compensation: lead the command from the delivered wrench's model.
        let lead = g.lag.ratio();
        let commanded = match (lead, self.u_model) {
            // The torques only: the attitude loop is the one the lag limits, and a lead on the
            // collective thrust would spend a heavy vehicle's small thrust margin.
            (Some(ratio), Some(model)) => {
                let c = model + (u - model) * ratio;
                Wrench {
                    thrust_n: u.x,
                    torque_nm: Vector3::new(c.y, c.z, c.w),
                }
            }
            _ => wrench,
        };
        let (rotors, sat) = self.airframe.mix(&commanded);
        let delivered = self.airframe.wrench(&rotors.thrust_n);
        if lead.is_some() {
            let d = Vector4::new(
                delivered.thrust_n,
                delivered.torque_nm.x,
                delivered.torque_nm.y,
                delivered.torque_nm.z,
            );
            let beta = dt_s / (g.lag.motor_tau_s + dt_s);
            let next = match self.u_model {
                Some(m) => m + (d - m) * beta,
                None => d,
            };
            self.u_model = next.iter().all(|x| x.is_finite()).then_some(next);
        }
        Actuation {
            singular: false,
            u,
            wrench,
            commanded,
            rotors,
            sat,
            delivered,
        }
    }
}

/// What [`FlightController::actuate`] gives the rest of the step.
#[derive(Default)]
pub(super) struct Actuation {
    /// g's actuated block was singular: nothing else is set.
    pub(super) singular: bool,
    /// u = g† b = [f (N); τ (N·m)].
    pub(super) u: Vector4<f32>,
    /// u as a wrench, and with the motor-lag lead.
    pub(super) wrench: Wrench,
    pub(super) commanded: Wrench,
    pub(super) rotors: RotorCommand,
    pub(super) sat: Saturation,
    /// The wrench `rotors` deliver.
    pub(super) delivered: Wrench,
}

/// x with G x = b by Gaussian elimination with the pivots in diagonal order (no row
/// exchanges), a third of the work of G⁻¹ and then G⁻¹ b. `None` unless every pivot keeps more
/// than half of its diagonal entry's magnitude (NaN included): g's actuated block is near
/// diagonal (identity for the true g), and where it is not the caller inverts G instead.
#[inline(always)]
pub(super) fn solve_in_order(g: &Matrix4<f32>, b: &Vector4<f32>) -> Option<Vector4<f32>> {
    let keeps = |pivot: f32, diag: f32| pivot.abs() > 0.5 * diag.abs();
    let p1 = g.m11;
    if !keeps(p1, p1) {
        return None;
    }
    let (l2, l3, l4) = (g.m21 / p1, g.m31 / p1, g.m41 / p1);
    let (a22, a23, a24) = (g.m22 - l2 * g.m12, g.m23 - l2 * g.m13, g.m24 - l2 * g.m14);
    let (a32, a33, a34) = (g.m32 - l3 * g.m12, g.m33 - l3 * g.m13, g.m34 - l3 * g.m14);
    let (a42, a43, a44) = (g.m42 - l4 * g.m12, g.m43 - l4 * g.m13, g.m44 - l4 * g.m14);
    let (b2, b3, b4) = (b.y - l2 * b.x, b.z - l3 * b.x, b.w - l4 * b.x);
    if !keeps(a22, g.m22) {
        return None;
    }
    let (l3, l4) = (a32 / a22, a42 / a22);
    let (a33, a34, b3) = (a33 - l3 * a23, a34 - l3 * a24, b3 - l3 * b2);
    let (a43, a44, b4) = (a43 - l4 * a23, a44 - l4 * a24, b4 - l4 * b2);
    if !keeps(a33, g.m33) {
        return None;
    }
    let l4 = a43 / a33;
    let (a44, b4) = (a44 - l4 * a34, b4 - l4 * b3);
    if !keeps(a44, g.m44) {
        return None;
    }
    let x4 = b4 / a44;
    let x3 = (b3 - a34 * x4) / a33;
    let x2 = (b2 - a23 * x3 - a24 * x4) / a22;
    let x1 = (b.x - g.m12 * x2 - g.m13 * x3 - g.m14 * x4) / p1;
    Some(Vector4::new(x1, x2, x3, x4))
}
