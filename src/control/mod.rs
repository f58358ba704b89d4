//! The energy-based (IDA-PBC) tracking controller with disturbance compensation
//! (paper eq. `ES_DI_COMP_control`), u = u_ES + u_DI + u_DC, and the [`FlightController`] that
//! owns the model, the gains and the adaptation state.
//!
//! Expanded for the quadrotor (docs/math.md, "The IDA-PBC control law"), with body-frame errors
//! e_p = Rᵀ(p − p*), e_v = v − Rᵀv*, e_R = ½(R*ᵀR − RᵀR*)^∨, e_ω = ω − RᵀR*ω*:
//!
//! - b_v = m g Rᵀe₃ − 𝔭_v × ω − k_p e_p + 𝔭̇*_v − k_v e_v − (W a)_v, with 𝔭̇*_v = m(Rᵀa* − ω × Rᵀv*);
//! - b_ω = ω × Jω − k_R e_R + 𝔭̇*_ω − k_ω e_ω − (W a)_ω, with 𝔭̇*_ω = −J(ω × RᵀR*ω*) (ω̇* ≈ 0);
//! - u = g†[b_v; b_ω].
//!
//! The quadrotor cannot make body x/y force, so R* follows b_v (F = R b_v, b₃* = F/‖F‖, see
//! [`crate::reference::desired_attitude`]) with Ḟ ≈ m p⃛* (the feedforward part of Ḟ: a
//! documented approximation). g† is taken on the actuated rows only (body z force and the three
//! torques): for the true g it is exactly the pseudo-inverse, and for a learned g it keeps model
//! error in the unactuated rows from leaking into the torques.

use crate::adapt::{Adaptation, Measurement, TrackingError};
#[cfg(feature = "composite")]
use crate::adapt::{AdaptationLaw, PortPrediction, PredictionInput};
pub use crate::gains::*;
use crate::mixer::{Airframe, RotorCommand, Saturation, Wrench};
use crate::model::{HamiltonianModel, ModelTerms, State, FEATURES};
use crate::reference::{desired_attitude, Setpoint, TiltLimit};
use crate::shaping::SetpointShaper;
use nalgebra::{Matrix3, Matrix4, SVector, Vector3, Vector4};

mod actuation;
mod demand;
mod estimation;
mod lag_watch;

use actuation::Actuation;
use demand::Demand;
pub use lag_watch::{
    LagWatch, CANDIDATE_TAUS_S, DECIDE_TICKS, DELAY_TICKS, GROWTH_FLOOR_NM2, GROWTH_RATIO,
    GROWTH_TAU_S, HIGH_PASS_TAU_S, MIN_EXCITATION_NM2, PITCH_WEIGHT, SCALE_SPAN, SLOTS,
    SWITCH_HOLD_EXCITED_S, SWITCH_HOLD_S, SWITCH_RATIO, SWITCH_REST_S, WINDOW_S,
};

/// Faults and conditions of one step. Any of the first four means the output is
/// [`RotorCommand::OFF`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Faults {
    /// The state had a NaN or infinite component, or its R is not a rotation
    /// (see [`ROTATION_TOLERANCE`]).
    pub bad_state: bool,
    /// The setpoint had a NaN or infinite component.
    pub bad_setpoint: bool,
    /// dt was not in (0, 0.1] s.
    pub bad_dt: bool,
    /// The model or the law produced a non-finite or singular value.
    pub numeric: bool,
    /// The mixer saturated (a condition, not a fault: the output is still used).
    pub saturation: Saturation,
    /// The tilt limit shaped the desired attitude (a condition).
    pub tilt_limited: bool,
}

impl Faults {
    /// True if the output was forced to the safe state.
    pub fn is_fault(&self) -> bool {
        self.bad_state || self.bad_setpoint || self.bad_dt || self.numeric
    }
}

/// Largest accepted ‖RᵀR − I‖_F for the state's attitude (dimensionless); beyond it, or with
/// det R ≤ 0 (a reflection), the state is `bad_state` and the motors go off.
///
/// A rotation rounded to f32 (from a unit quaternion, or an integrated attitude) sits near 1e-6;
/// a quaternion whose norm is off by ε gives ≈ 4√3 ε, so 1e-3 accepts a quaternion normalized to
/// ≈ 1.4e-4, while a matrix scaled by 1.001 or sheared by 1e-3 is already refused. Inside the
/// tolerance the law's errors (e_R, Rᵀ v*) change by the same relative 1e-3: harmless.
pub const ROTATION_TOLERANCE: f32 = 1e-3;

/// True if `r` is a rotation to [`ROTATION_TOLERANCE`]: ‖RᵀR − I‖_F ≤ tolerance and det R > 0.
/// False for non-finite entries.
pub fn is_rotation(r: &Matrix3<f32>) -> bool {
    // RᵀR is symmetric: its entries are the columns' dot products, six of them, so
    // ‖RᵀR − I‖²_F = Σᵢ (cᵢ·cᵢ − 1)² + 2 Σᵢ<ⱼ (cᵢ·cⱼ)², and det R = c₀ · (c₁ × c₂).
    let (c0, c1, c2) = (r.column(0), r.column(1), r.column(2));
    let d00 = c0.dot(&c0) - 1.0;
    let d11 = c1.dot(&c1) - 1.0;
    let d22 = c2.dot(&c2) - 1.0;
    let (d01, d02, d12) = (c0.dot(&c1), c0.dot(&c2), c1.dot(&c2));
    let dev2 = d00 * d00 + d11 * d11 + d22 * d22 + 2.0 * (d01 * d01 + d02 * d02 + d12 * d12);
    let det = c0.dot(&c1.cross(&c2));
    // The comparisons are false for NaN: a non-finite R is refused.
    dev2 <= ROTATION_TOLERANCE * ROTATION_TOLERANCE && det > 0.0
}

/// What one control step produces.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Output {
    /// Rotor commands to apply ([`RotorCommand::OFF`] on a fault).
    pub rotors: RotorCommand,
    /// The wrench u the law asked for (before the mixer's saturation).
    pub wrench: Wrench,
    /// The wrench to hand to an outside mixer (the Crazyflie's power distribution, a simulator
    /// that takes thrust and moments): [`Output::wrench`] with the motor-lag lead
    /// ([`LagCompensation`]) on the torques, the wrench `rotors` mixes. Handing over `wrench`
    /// instead drops the lead the attitude gains were designed with.
    pub command: Wrench,
    /// The wrench the rotors deliver ([`Output::rotors`] through the forward mixer): the
    /// command less what the mixer's saturation gave up; zero on a fault.
    pub delivered: Wrench,
    /// The disturbance-weight estimate a after this step.
    pub a: SVector<f32, FEATURES>,
    /// The tracking errors of this step.
    pub errors: TrackingError,
    /// Faults and conditions.
    pub faults: Faults,
}

/// The flight controller: model, gains, mixer and adaptation state. `step` is allocation-free
/// and panic-free; non-finite input gives motors off and a fault flag.
#[derive(Clone, Debug)]
pub struct FlightController<M> {
    model: M,
    /// Gains and rates (may be changed between steps).
    pub gains: Gains,
    /// Rotor geometry for the mixer.
    pub airframe: Airframe,
    adaptation: Adaptation,
    /// The composite law's compensation feedforward: the last world compensation force R (W a)_v
    /// (N) and its low-passed rate (N/s).
    #[cfg_attr(not(feature = "composite"), allow(dead_code))]
    comp_prev_n: Option<Vector3<f32>>,
    #[cfg_attr(not(feature = "composite"), allow(dead_code))]
    comp_rate_n_s: Vector3<f32>,
    /// `gains.max_tilt_rad` with its cosine and sine, refreshed when the gain changes.
    tilt: TiltLimit,
    /// The reference model that shapes setpoint jumps.
    shaper: SetpointShaper,
    /// The delivered wrench through the motor model ([`LagCompensation`]): û = [f; τ].
    u_model: Option<Vector4<f32>>,
    /// The last given position (m, world) and velocity (m/s, world), and the
    /// velocity-consistency correction c (m/s, world), for [`Gains::velocity_consistency_tau_s`].
    prev_p_m: Option<(Vector3<f32>, Vector3<f32>)>,
    velocity_correction_m_s: Vector3<f32>,
    /// The model's terms at this tick's state, written in place by the step.
    terms: ModelTerms,
    /// True if the model carries port terms ([`crate::model::PortTerms`]) other than the
    /// identity: the law then compensates them (read once, at construction).
    port_active: bool,
    /// The motor-lag watch ([`Gains::lag_watch`]).
    watch: LagWatch,
}

impl<M: HamiltonianModel> FlightController<M> {
    /// A controller on `model` with `gains`, the CF2X airframe and a = 0.
    pub fn new(model: M, gains: Gains) -> Self {
        let port_active = !model.port().is_identity();
        Self {
            port_active,
            model,
            gains,
            airframe: Airframe::default(),
            adaptation: Adaptation::default(),
            comp_prev_n: None,
            comp_rate_n_s: Vector3::zeros(),
            tilt: TiltLimit::new(gains.max_tilt_rad),
            shaper: SetpointShaper::default(),
            u_model: None,
            prev_p_m: None,
            velocity_correction_m_s: Vector3::zeros(),
            terms: ModelTerms::ZERO,
            watch: LagWatch::default(),
        }
    }

    /// [`FlightController::new`] written to `dst` field by field: no whole controller (about
    /// 1.4 KB with the learned model) passes through the stack, for firmware tasks with small
    /// stacks. `tests::write_new_is_new` checks it against [`FlightController::new`].
    ///
    /// # Safety
    /// `dst` is valid for writes and aligned. Whatever it held is overwritten without a drop (a
    /// controller whose model `M` has no drop glue, such as a reference, has none either).
    pub unsafe fn write_new(dst: *mut Self, model: M, gains: Gains) {
        let port_active = !model.port().is_identity();
        // SAFETY: the caller's contract; each field is written through a raw pointer, without
        // forming a reference to the (possibly uninitialised) controller.
        unsafe {
            (&raw mut (*dst).port_active).write(port_active);
            (&raw mut (*dst).model).write(model);
            (&raw mut (*dst).gains).write(gains);
            (&raw mut (*dst).airframe).write(Airframe::default());
            (&raw mut (*dst).adaptation).write(Adaptation::default());
            (&raw mut (*dst).comp_prev_n).write(None);
            (&raw mut (*dst).comp_rate_n_s).write(Vector3::zeros());
            (&raw mut (*dst).tilt).write(TiltLimit::new(gains.max_tilt_rad));
            (&raw mut (*dst).shaper).write(SetpointShaper::default());
            (&raw mut (*dst).u_model).write(None);
            (&raw mut (*dst).prev_p_m).write(None);
            (&raw mut (*dst).velocity_correction_m_s).write(Vector3::zeros());
            (&raw mut (*dst).terms).write(ModelTerms::ZERO);
            (&raw mut (*dst).watch).write(LagWatch::default());
        }
    }

    /// The model the controller uses.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The current disturbance-weight estimate a.
    pub fn estimate(&self) -> SVector<f32, FEATURES> {
        self.adaptation.a
    }

    /// Resets the adaptation (a = 0).
    pub fn reset(&mut self) {
        self.adaptation.reset();
        self.shaper.reset();
        self.comp_prev_n = None;
        self.comp_rate_n_s = Vector3::zeros();
        self.u_model = None;
        self.prev_p_m = None;
        self.unwatch_lag();
    }

    fn safe(&mut self, faults: Faults) -> Output {
        self.comp_prev_n = None;
        self.u_model = None;
        self.prev_p_m = None;
        self.shaper.reset();
        self.watch.restart();
        // The next good tick does not follow this one by one interval, and nothing was delivered.
        self.adaptation.break_sequence();
        self.adaptation.record_input(&Wrench::default());
        Output {
            rotors: RotorCommand::OFF,
            wrench: Wrench::default(),
            command: Wrench::default(),
            delivered: Wrench::default(),
            a: self.adaptation.a,
            errors: TrackingError::default(),
            faults,
        }
    }

    /// One control tick of length `dt_s` (s) without extra measurements:
    /// [`FlightController::step_measured`] with [`Measurement::default`].
    ///
    /// # Examples
    ///
    /// Hold a hover on the shipped weights; a non-finite state turns the motors off:
    ///
    /// ```
    /// use hamflight::model::LearnedModel;
    /// use hamflight::{FlightController, Gains, RotorCommand, Setpoint, State, VehicleFacts};
    /// use nalgebra::Vector3;
    ///
    /// let model = LearnedModel::from_blob(include_bytes!("../../weights/default.hfw"))?;
    /// let gains = Gains::for_vehicle(&VehicleFacts::of(&model));
    /// let mut fc = FlightController::new(model, gains);
    /// let hold = Setpoint::hover(Vector3::new(0.0, 0.0, 1.0), 0.0);
    /// let at_hold = State { p_m: hold.p_m, ..State::default() };
    ///
    /// let out = fc.step(&at_hold, &hold, 0.002);
    /// assert!(!out.faults.is_fault());
    /// let thrust_n: f32 = out.rotors.thrust_n.iter().sum();
    /// assert!((thrust_n - 0.027 * 9.81).abs() < 0.05, "about m g at hover: {thrust_n}");
    ///
    /// let bad = State { p_m: Vector3::new(f32::NAN, 0.0, 1.0), ..at_hold };
    /// let out = fc.step(&bad, &hold, 0.002);
    /// assert!(out.faults.is_fault());
    /// assert_eq!(out.rotors, RotorCommand::OFF);
    /// # Ok::<(), hamflight::blob::BlobError>(())
    /// ```
    pub fn step(&mut self, state: &State, sp: &Setpoint, dt_s: f32) -> Output {
        self.step_measured(state, sp, &Measurement::default(), dt_s)
    }

    /// The adaptation state (a and the composite law's P).
    pub fn adaptation(&self) -> &Adaptation {
        &self.adaptation
    }

    /// One control tick of length `dt_s` (s): the wrench of the IDA-PBC law, mixed to rotors,
    /// then one step of the adaptation law; `meas` feeds the composite law (the accelerometer).
    pub fn step_measured(
        &mut self,
        state: &State,
        sp: &Setpoint,
        meas: &Measurement,
        dt_s: f32,
    ) -> Output {
        let mut out = Output::default();
        self.step_into(state, sp, meas, dt_s, &mut out);
        out
    }

    /// [`FlightController::step_measured`] written into `out`: for a caller that keeps the
    /// output in place (the Crazyflie app, whose stabilizer task has a small stack).
    pub fn step_into(
        &mut self,
        state: &State,
        sp: &Setpoint,
        meas: &Measurement,
        dt_s: f32,
        out: &mut Output,
    ) {
        // Without the composite law nothing reads the measurement.
        #[cfg(not(feature = "composite"))]
        let _ = meas;
        let mut faults = Faults {
            bad_state: !(state.is_finite() && is_rotation(&state.rot)),
            bad_setpoint: !sp.is_finite(),
            bad_dt: !(dt_s > 0.0 && dt_s <= 0.1),
            ..Faults::default()
        };
        if faults.is_fault() {
            *out = self.safe(faults);
            return;
        }
        let shaped = self.shaper.shape(sp, dt_s, self.gains.shaping_omega_rad_s);
        let sp = &shaped;
        if self.tilt.max_rad != self.gains.max_tilt_rad {
            self.tilt = TiltLimit::new(self.gains.max_tilt_rad);
        }
        let v_law = self.consistent_velocity(state, dt_s);
        self.model.write_terms(state, &mut self.terms);
        let Some(inertia) = self.terms.inertia_inv.try_inverse() else {
            faults.numeric = true;
            *out = self.safe(faults);
            return;
        };
        let demand = self.demand(state, sp, &v_law, &inertia, dt_s);
        faults.tilt_limited = demand.tilt_limited;
        let act = self.actuate(&demand.b_act, dt_s);
        faults.saturation = act.sat;
        let errors = &demand.errors;
        if act.singular || !(act.u.iter().all(|x| x.is_finite()) && errors_finite(errors)) {
            faults.numeric = true;
            *out = self.safe(faults);
            return;
        }
        if self.gains.adapt {
            self.adapt(state, meas, &inertia, &demand, &act, dt_s);
        }
        self.watch_lag(state, &inertia, &act, dt_s);
        *out = Output {
            rotors: act.rotors,
            wrench: act.wrench,
            command: act.commanded,
            delivered: act.delivered,
            a: self.adaptation.a,
            errors: *errors,
            faults,
        };
    }
}

impl<M> FlightController<M> {
    /// The body velocity the law uses: the state's, plus Rᵀ c with the velocity-consistency
    /// correction c ([`Gains::velocity_consistency_tau_s`]) updated from this tick's position.
    fn consistent_velocity(&mut self, state: &State, dt_s: f32) -> Vector3<f32> {
        let tau = self.gains.velocity_consistency_tau_s;
        if tau.is_nan() || tau <= 0.0 {
            self.prev_p_m = None;
            return state.v_body_m_s;
        }
        let v_world = state.rot * state.v_body_m_s;
        if let Some((prev_p, prev_v)) = self.prev_p_m {
            // The mean velocity over the tick against the mean of its ends: second order in dt.
            let diff = (state.p_m - prev_p) / dt_s - (v_world + prev_v) * 0.5;
            let alpha = dt_s / (tau + dt_s);
            let next = self.velocity_correction_m_s + (diff - self.velocity_correction_m_s) * alpha;
            if next.iter().all(|x| x.is_finite()) {
                self.velocity_correction_m_s = next;
            }
        } else {
            self.velocity_correction_m_s = Vector3::zeros();
        }
        self.prev_p_m = Some((state.p_m, v_world));
        state.v_body_m_s + state.rot.transpose() * self.velocity_correction_m_s
    }
}

fn errors_finite(e: &TrackingError) -> bool {
    crate::fpu::all_finite(
        [e.e_p, e.e_v, e.e_r, e.e_w]
            .iter()
            .flat_map(|v| v.iter().copied()),
    )
}

#[cfg(test)]
mod tests {
    use super::actuation::solve_in_order;
    use super::*;

    /// [`FlightController::write_new`] builds what [`FlightController::new`] builds, field for
    /// field (their `Debug` texts agree), over stale bytes too, and it flies the same.
    #[test]
    fn write_new_is_new() {
        use crate::model::NominalModel;
        let model = NominalModel::default();
        let gains = Gains::default();
        let mut made = core::mem::MaybeUninit::<FlightController<NominalModel>>::uninit();
        // SAFETY: stale bytes (0xA5) in place of the controller: written over, not read.
        unsafe {
            made.as_mut_ptr()
                .cast::<u8>()
                .write_bytes(0xA5, core::mem::size_of_val(&made))
        };
        // SAFETY: valid for writes and aligned.
        unsafe { FlightController::write_new(made.as_mut_ptr(), model, gains) };
        // SAFETY: every field written above.
        let mut made = unsafe { made.assume_init() };
        let mut new = FlightController::new(model, gains);
        assert_eq!(format!("{made:?}"), format!("{new:?}"));
        let s = State::default();
        let sp = Setpoint::hover(Vector3::new(0.1, -0.2, 0.3), 0.2);
        for _ in 0..10 {
            assert_eq!(
                format!("{:?}", made.step(&s, &sp, 0.002)),
                format!("{:?}", new.step(&s, &sp, 0.002))
            );
        }
    }

    /// The in-order elimination solves a near-diagonal G as the inverse does, and hands a G
    /// whose pivots collapse (a permutation, a singular or non-finite G) back to the inverse.
    #[test]
    fn solve_in_order_matches_the_inverse_or_declines() {
        let g = Matrix4::new(
            1.02, 0.03, -0.01, 0.02, //
            -0.04, 0.97, 0.05, 0.01, //
            0.02, -0.03, 1.1, -0.06, //
            0.01, 0.02, 0.04, 0.9,
        );
        let b = Vector4::new(0.26, 1e-3, -2e-3, 4e-4);
        let x = solve_in_order(&g, &b).expect("near diagonal");
        let want = g.try_inverse().expect("invertible") * b;
        assert!((x - want).norm() <= 1e-6 * want.norm(), "{x} vs {want}");
        let perm = Matrix4::new(
            0.0, 1.0, 0.0, 0.0, //
            1.0, 0.0, 0.0, 0.0, //
            0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0,
        );
        assert_eq!(solve_in_order(&perm, &b), None);
        assert_eq!(solve_in_order(&Matrix4::zeros(), &b), None);
        let mut nan = g;
        nan.m33 = f32::NAN;
        assert_eq!(solve_in_order(&nan, &b), None);
    }
}
