//! The port-Hamiltonian terms beyond the rigid body (paper eq. 1 with its dissipation and a
//! learned potential; docs/math.md "Dissipation, potential and actuator lag"):
//!
//! - a potential V_K(q) = ½ bᵀ K b of the attitude, b = Rᵀe₃ the world vertical in the body
//!   frame (K symmetric): its torque is τ_V = b × K b, a pull toward (or away from) a trim
//!   attitude that is linear in the tilt near level;
//! - a dissipation D = diag(D_v, D_ω) ⪰ 0: rotor drag −D_v v and rate damping −D_ω ω;
//! - a gyrator B between the linear and the angular port: ṗ_ω += B v, ṗ_v −= Bᵀ ω (the rotors'
//!   flapping moment; skew, so it moves energy and neither makes nor takes it);
//! - the input's effective gain k = (k_f, k_τ) on u = [f; τ] and its first-order lags (T_f, T_τ)
//!   from the commanded (or measured-rotor) wrench to the one that acts.
//!
//! With no input and no disturbance, Ḣ = −ζᵀ D ζ ≤ 0 for H = ½ 𝔭ᵀM⁻¹𝔭 + m g e₃ᵀp + V_K: energy
//! leaves only through D. Every field zero is the rigid body alone ([`PortTerms::IDENTITY`]):
//! the gains are stored as offsets from 1, so an all-zero model stays all-zero (a `static` in
//! `.bss`).

use nalgebra::{Matrix3, Vector3, Vector4};
use serde::{Deserialize, Serialize};

/// Number of f32 numbers in [`PortTerms`] (its blob encoding, [`PortTerms::to_array`]).
pub const PORT_PARAMS: usize = 27;
/// The smallest effective input gain a model may carry: below it, the law's inversion
/// (u = k⁻¹ ∘ g⁻¹ b) would ask for more than 50× the computed wrench.
pub const MIN_INPUT_GAIN: f32 = 0.02;
/// The largest effective input gain a model may carry.
pub const MAX_INPUT_GAIN: f32 = 50.0;

/// The terms (module docs); all zero is the rigid body alone.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct PortTerms {
    /// k_f − 1: the thrust's effective gain minus one.
    pub thrust_gain_offset: f32,
    /// k_τ − 1 per body axis (roll, pitch, yaw).
    pub torque_gain_offset: [f32; 3],
    /// T_f (s): the first-order lag the thrust acts through.
    pub thrust_lag_s: f32,
    /// T_τ (s): the first-order lag the torques act through.
    pub torque_lag_s: f32,
    /// D_v (N·s/m) per body axis, ≥ 0: the force −D_v ∘ v.
    pub drag_n_s_m: [f32; 3],
    /// D_ω (N·m·s/rad) per body axis, ≥ 0: the torque −D_ω ∘ ω.
    pub rate_damping_nm_s: [f32; 3],
    /// B (N·m per m/s), row-major, rows τx, τy, τz: the torque B v, and the force −Bᵀω.
    pub gyrator_nm_s_m: [[f32; 3]; 3],
    /// K (N·m), symmetric, as [k₁₁, k₂₂, k₃₃, k₁₂, k₁₃, k₂₃]: V_K = ½ bᵀ K b.
    pub tilt_stiffness_nm: [f32; 6],
}

/// Why a set of port terms cannot be flown.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PortError {
    /// A number is NaN or infinite.
    NonFinite,
    /// An effective gain is outside [[`MIN_INPUT_GAIN`], [`MAX_INPUT_GAIN`]].
    BadGain,
    /// A lag is outside [0, [`super::MAX_MOTOR_TAU_S`]] s.
    BadLag,
    /// A dissipation entry is negative (D must be ⪰ 0: energy may only leave).
    NegativeDissipation,
}

impl PortTerms {
    /// The rigid body alone: unit gains, no lag, no dissipation, no learned potential.
    pub const IDENTITY: Self = Self {
        thrust_gain_offset: 0.0,
        torque_gain_offset: [0.0; 3],
        thrust_lag_s: 0.0,
        torque_lag_s: 0.0,
        drag_n_s_m: [0.0; 3],
        rate_damping_nm_s: [0.0; 3],
        gyrator_nm_s_m: [[0.0; 3]; 3],
        tilt_stiffness_nm: [0.0; 6],
    };

    /// True if these are the rigid body's alone (every field zero).
    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// The effective input gain k = (k_f, k_τx, k_τy, k_τz) on u = [f; τ].
    #[inline]
    pub fn input_gain(&self) -> Vector4<f32> {
        Vector4::new(
            1.0 + self.thrust_gain_offset,
            1.0 + self.torque_gain_offset[0],
            1.0 + self.torque_gain_offset[1],
            1.0 + self.torque_gain_offset[2],
        )
    }

    /// K as a matrix.
    #[inline]
    pub fn stiffness(&self) -> Matrix3<f32> {
        let [k11, k22, k33, k12, k13, k23] = self.tilt_stiffness_nm;
        Matrix3::new(k11, k12, k13, k12, k22, k23, k13, k23, k33)
    }

    /// V_K(b) = ½ bᵀ K b (J) at the body-frame world vertical `b` = Rᵀe₃.
    pub fn potential_j(&self, b: &Vector3<f32>) -> f32 {
        0.5 * b.dot(&(self.stiffness() * b))
    }

    /// The port wrench (force N, torque N·m; body frame) at the world vertical `b` = Rᵀe₃ and
    /// the body velocities `v` (m/s) and `w` (rad/s): ([`PortTerms::force`],
    /// [`PortTerms::torque`]).
    #[inline]
    pub fn wrench(
        &self,
        b: &Vector3<f32>,
        v: &Vector3<f32>,
        w: &Vector3<f32>,
    ) -> (Vector3<f32>, Vector3<f32>) {
        (self.force(v, w), self.torque(b, v, w))
    }

    /// The port force (N, body frame) at the body velocities `v` (m/s) and `w` (rad/s):
    /// −D_v v − Bᵀω. Out of line and written per component: the control step calls it and
    /// [`PortTerms::torque`] at different velocities.
    #[inline(never)]
    pub fn force(&self, v: &Vector3<f32>, w: &Vector3<f32>) -> Vector3<f32> {
        let [[b00, b01, b02], [b10, b11, b12], [b20, b21, b22]] = self.gyrator_nm_s_m;
        let [dvx, dvy, dvz] = self.drag_n_s_m;
        Vector3::new(
            -dvx * v.x - (b00 * w.x + b10 * w.y + b20 * w.z),
            -dvy * v.y - (b01 * w.x + b11 * w.y + b21 * w.z),
            -dvz * v.z - (b02 * w.x + b12 * w.y + b22 * w.z),
        )
    }

    /// The port torque (N·m, body frame) at the world vertical `b` = Rᵀe₃ and the body
    /// velocities `v` (m/s) and `w` (rad/s): −D_ω ω + B v + b × K b.
    #[inline(never)]
    pub fn torque(&self, b: &Vector3<f32>, v: &Vector3<f32>, w: &Vector3<f32>) -> Vector3<f32> {
        let [[b00, b01, b02], [b10, b11, b12], [b20, b21, b22]] = self.gyrator_nm_s_m;
        let [dwx, dwy, dwz] = self.rate_damping_nm_s;
        let [k11, k22, k33, k12, k13, k23] = self.tilt_stiffness_nm;
        let kb = Vector3::new(
            k11 * b.x + k12 * b.y + k13 * b.z,
            k12 * b.x + k22 * b.y + k23 * b.z,
            k13 * b.x + k23 * b.y + k33 * b.z,
        );
        Vector3::new(
            -dwx * w.x + (b00 * v.x + b01 * v.y + b02 * v.z),
            -dwy * w.y + (b10 * v.x + b11 * v.y + b12 * v.z),
            -dwz * w.z + (b20 * v.x + b21 * v.y + b22 * v.z),
        ) + b.cross(&kb)
    }

    /// [`PortTerms::force`] at two linear velocities that share ω: (at `v_a`, at `v_b`), each
    /// the same bits as its own call; −Bᵀω and the parameters are read once. Out of line: the
    /// control step calls it for the law (the reference velocity) and the composite
    /// prediction (the state's) at once.
    #[inline(never)]
    pub fn force_pair(
        &self,
        v_a: &Vector3<f32>,
        v_b: &Vector3<f32>,
        w: &Vector3<f32>,
    ) -> (Vector3<f32>, Vector3<f32>) {
        let [[b00, b01, b02], [b10, b11, b12], [b20, b21, b22]] = self.gyrator_nm_s_m;
        let [dvx, dvy, dvz] = self.drag_n_s_m;
        let bw = Vector3::new(
            b00 * w.x + b10 * w.y + b20 * w.z,
            b01 * w.x + b11 * w.y + b21 * w.z,
            b02 * w.x + b12 * w.y + b22 * w.z,
        );
        (
            Vector3::new(
                -dvx * v_a.x - bw.x,
                -dvy * v_a.y - bw.y,
                -dvz * v_a.z - bw.z,
            ),
            Vector3::new(
                -dvx * v_b.x - bw.x,
                -dvy * v_b.y - bw.y,
                -dvz * v_b.z - bw.z,
            ),
        )
    }

    /// [`PortTerms::torque`] at two velocity pairs that share the world vertical `b`:
    /// (at (`v_a`, `w_a`), at (`v_b`, `w_b`)), each the same bits as its own call; b × K b and
    /// the parameters are computed and read once.
    #[inline(never)]
    pub fn torque_pair(
        &self,
        b: &Vector3<f32>,
        (v_a, w_a): (&Vector3<f32>, &Vector3<f32>),
        (v_b, w_b): (&Vector3<f32>, &Vector3<f32>),
    ) -> (Vector3<f32>, Vector3<f32>) {
        let [[b00, b01, b02], [b10, b11, b12], [b20, b21, b22]] = self.gyrator_nm_s_m;
        let [dwx, dwy, dwz] = self.rate_damping_nm_s;
        let [k11, k22, k33, k12, k13, k23] = self.tilt_stiffness_nm;
        let kb = Vector3::new(
            k11 * b.x + k12 * b.y + k13 * b.z,
            k12 * b.x + k22 * b.y + k23 * b.z,
            k13 * b.x + k23 * b.y + k33 * b.z,
        );
        let pot = b.cross(&kb);
        let at = |v: &Vector3<f32>, w: &Vector3<f32>| {
            Vector3::new(
                -dwx * w.x + (b00 * v.x + b01 * v.y + b02 * v.z),
                -dwy * w.y + (b10 * v.x + b11 * v.y + b12 * v.z),
                -dwz * w.z + (b20 * v.x + b21 * v.y + b22 * v.z),
            ) + pot
        };
        (at(v_a, w_a), at(v_b, w_b))
    }

    /// Checks that the terms can be flown: finite, gains in range, lags in range, D ⪰ 0.
    ///
    /// # Errors
    /// The first [`PortError`] in that order.
    pub fn validate(&self) -> Result<(), PortError> {
        let all = self.to_array();
        if !crate::fpu::all_finite(all.iter().copied()) {
            return Err(PortError::NonFinite);
        }
        let (gains, rest) = all.split_at(4);
        let (lags, rest) = rest.split_at(2);
        let dissipation = rest.get(..6).unwrap_or(&[]);
        if !gains
            .iter()
            .all(|k| (MIN_INPUT_GAIN..=MAX_INPUT_GAIN).contains(&(1.0 + k)))
        {
            return Err(PortError::BadGain);
        }
        if !lags
            .iter()
            .all(|t| (0.0..=super::MAX_MOTOR_TAU_S).contains(t))
        {
            return Err(PortError::BadLag);
        }
        if dissipation.iter().any(|&d| d < 0.0) {
            return Err(PortError::NegativeDissipation);
        }
        Ok(())
    }

    /// Every number in blob order: k_f − 1, k_τ − 1, T_f, T_τ, D_v, D_ω, B (row-major), K.
    pub fn to_array(&self) -> [f32; PORT_PARAMS] {
        let [t0, t1, t2] = self.torque_gain_offset;
        let [d0, d1, d2] = self.drag_n_s_m;
        let [w0, w1, w2] = self.rate_damping_nm_s;
        let [[b00, b01, b02], [b10, b11, b12], [b20, b21, b22]] = self.gyrator_nm_s_m;
        let [k0, k1, k2, k3, k4, k5] = self.tilt_stiffness_nm;
        [
            self.thrust_gain_offset,
            t0,
            t1,
            t2,
            self.thrust_lag_s,
            self.torque_lag_s,
            d0,
            d1,
            d2,
            w0,
            w1,
            w2,
            b00,
            b01,
            b02,
            b10,
            b11,
            b12,
            b20,
            b21,
            b22,
            k0,
            k1,
            k2,
            k3,
            k4,
            k5,
        ]
    }

    /// The terms of [`PortTerms::to_array`]'s order (not validated).
    pub fn from_array(a: &[f32; PORT_PARAMS]) -> Self {
        let mut it = a.iter().copied();
        let mut next = || it.next().unwrap_or(0.0);
        let mut t = Self::IDENTITY;
        t.thrust_gain_offset = next();
        t.torque_gain_offset = [next(), next(), next()];
        t.thrust_lag_s = next();
        t.torque_lag_s = next();
        t.drag_n_s_m = [next(), next(), next()];
        t.rate_damping_nm_s = [next(), next(), next()];
        for row in t.gyrator_nm_s_m.iter_mut() {
            *row = [next(), next(), next()];
        }
        t.tilt_stiffness_nm = [next(), next(), next(), next(), next(), next()];
        t
    }
}

/// The input's first-order lags (T_f on the thrust, T_τ on the torques), discretized by
/// backward Euler, x̄ₖ = (T x̄ₖ₋₁ + dt xₖ) / (T + dt): unlike exp(−dt/T) its pole is defined at
/// T = 0 (no lag), so a fit may reach T = 0 and leave it again.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ActuatorLag {
    /// The lagged wrench [f; τ], or `None` before the first input.
    lagged: Option<Vector4<f32>>,
}

impl ActuatorLag {
    /// A lag that starts at its first input (no transient from zero).
    pub const fn new() -> Self {
        Self { lagged: None }
    }

    /// A lag already settled at `u`.
    pub fn settled_at(u: &Vector4<f32>) -> Self {
        Self { lagged: Some(*u) }
    }

    /// Feeds the wrench `u` for one step of `dt_s` and returns the lagged wrench that acts.
    pub fn step(&mut self, port: &PortTerms, u: &Vector4<f32>, dt_s: f32) -> Vector4<f32> {
        let pole = |lag: f32| {
            let lag = if lag > 0.0 { lag } else { 0.0 };
            let den = lag + dt_s;
            if den > 0.0 {
                lag / den
            } else {
                0.0
            }
        };
        let (a_f, a_t) = (pole(port.thrust_lag_s), pole(port.torque_lag_s));
        let prev = self.lagged.unwrap_or(*u);
        let next = Vector4::new(
            a_f * prev.x + (1.0 - a_f) * u.x,
            a_t * prev.y + (1.0 - a_t) * u.y,
            a_t * prev.z + (1.0 - a_t) * u.z,
            a_t * prev.w + (1.0 - a_t) * u.w,
        );
        self.lagged = Some(next);
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> PortTerms {
        PortTerms::from_array(&core::array::from_fn(|i| 0.01 * (i as f32 + 1.0)))
    }

    #[test]
    fn identity_is_all_zero_and_round_trips() {
        assert!(PortTerms::IDENTITY.is_identity());
        assert_eq!(PortTerms::IDENTITY.input_gain(), Vector4::repeat(1.0));
        let s = sample();
        assert!(!s.is_identity());
        assert_eq!(PortTerms::from_array(&s.to_array()), s);
        assert_eq!(s.validate(), Ok(()));
    }

    #[test]
    fn validate_names_each_fault() {
        let mut s = sample();
        s.drag_n_s_m[1] = -1e-6;
        assert_eq!(s.validate(), Err(PortError::NegativeDissipation));
        let mut s = sample();
        s.torque_gain_offset[2] = -0.99;
        assert_eq!(s.validate(), Err(PortError::BadGain));
        let mut s = sample();
        s.torque_lag_s = 2.0;
        assert_eq!(s.validate(), Err(PortError::BadLag));
        let mut s = sample();
        s.tilt_stiffness_nm[3] = f32::NAN;
        assert_eq!(s.validate(), Err(PortError::NonFinite));
    }

    /// The potential's torque is the negative gradient of V_K along a body rotation: for
    /// R → R exp(ε ê), b → b − ε e × b, and dV = −ε τ_V · e.
    #[test]
    fn potential_torque_is_minus_its_gradient() {
        let s = sample();
        let b = Vector3::new(0.3, -0.2, 0.93).normalize();
        let (_, tau) = s.wrench(&b, &Vector3::zeros(), &Vector3::zeros());
        let tau_v = tau;
        let eps = 1e-3;
        for e in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let bp = b - e.cross(&b) * eps;
            let bm = b + e.cross(&b) * eps;
            let dv = (s.potential_j(&bp) - s.potential_j(&bm)) / (2.0 * eps);
            assert!(
                (dv + tau_v.dot(&e)).abs() < 1e-4,
                "axis {e:?}: dV/dε {dv} against −τ·e {}",
                -tau_v.dot(&e)
            );
        }
    }

    /// Energy leaves only through D: the port's power on ζ is −ζᵀDζ (B is skew, K is a
    /// potential and does no work at zero rate).
    #[test]
    fn port_power_is_minus_dissipation() {
        let s = sample();
        let b = Vector3::new(0.1, 0.2, 0.97).normalize();
        let v = Vector3::new(0.5, -1.2, 0.3);
        let w = Vector3::new(-2.0, 0.7, 1.1);
        let (f, t) = s.wrench(&b, &v, &w);
        let (_, t_pot) = s.wrench(&b, &Vector3::zeros(), &Vector3::zeros());
        let power = f.dot(&v) + (t - t_pot).dot(&w);
        let dissipated = Vector3::from(s.drag_n_s_m).dot(&v.component_mul(&v))
            + Vector3::from(s.rate_damping_nm_s).dot(&w.component_mul(&w));
        assert!(
            (power + dissipated).abs() < 1e-5,
            "{power} against {}",
            -dissipated
        );
    }

    /// The pairs give the same bits as one call per velocity.
    #[test]
    fn pairs_match_single_calls() {
        let s = sample();
        let b = Vector3::new(0.1, 0.2, 0.97).normalize();
        let (va, vb) = (Vector3::new(0.5, -1.2, 0.3), Vector3::new(-0.2, 0.4, 0.9));
        let (wa, wb) = (Vector3::new(-2.0, 0.7, 1.1), Vector3::new(0.3, -0.6, 0.2));
        assert_eq!(
            s.force_pair(&va, &vb, &wa),
            (s.force(&va, &wa), s.force(&vb, &wa))
        );
        assert_eq!(
            s.torque_pair(&b, (&va, &wa), (&vb, &wb)),
            (s.torque(&b, &va, &wa), s.torque(&b, &vb, &wb))
        );
    }

    #[test]
    fn lag_settles_and_identity_passes_through() {
        let mut lag = ActuatorLag::new();
        let u = Vector4::new(0.4, 1e-3, -2e-3, 5e-4);
        assert_eq!(lag.step(&PortTerms::IDENTITY, &u, 0.01), u);
        let mut s = PortTerms::IDENTITY;
        s.torque_lag_s = 0.05;
        let mut lag = ActuatorLag::settled_at(&Vector4::zeros());
        let first = lag.step(&s, &u, 0.01);
        assert_eq!(first.x, u.x, "no thrust lag");
        assert!((first.y - u.y / 6.0).abs() < 1e-9, "{}", first.y);
        for _ in 0..200 {
            lag.step(&s, &u, 0.01);
        }
        assert!((lag.step(&s, &u, 0.01) - u).norm() < 1e-7);
    }

    /// The whole model (learned rigid body, gravity, the port terms) with no input and no
    /// disturbance: H never increases, and it does decrease (the dissipation is on).
    #[test]
    fn energy_never_increases_without_input() {
        use crate::model::{dynamics, LearnedModel, ModelWeights, State};
        let mut port = sample();
        port.drag_n_s_m = [0.03, 0.03, 0.04];
        port.rate_damping_nm_s = [1.2e-4, 1.2e-4, 2.4e-4];
        port.tilt_stiffness_nm = [9e-5, 8e-5, 0.0, -3e-5, 1e-6, 7e-6];
        let model = LearnedModel::new(ModelWeights::prior()).with_port(port);
        let mut s = State {
            rot: crate::lie::exp(&Vector3::new(0.3, -0.2, 0.5)),
            v_body_m_s: Vector3::new(0.8, -0.5, 0.3),
            w_body_rad_s: Vector3::new(2.0, -1.5, 0.7),
            ..State::default()
        };
        let h0 = dynamics::hamiltonian(&model, &s);
        let mut h = h0;
        for k in 0..400 {
            s = dynamics::rk4_step(&model, &s, &Vector4::zeros(), &[0.0; 6], 1e-3);
            s.rot = crate::lie::orthonormalize(&s.rot).unwrap_or(s.rot);
            let next = dynamics::hamiltonian(&model, &s);
            assert!(
                next <= h + 1e-7 * h.abs().max(1e-3),
                "step {k}: H {h} -> {next}"
            );
            h = next;
        }
        assert!(
            h < h0 - 1e-4,
            "the dissipation takes energy out: {h0} -> {h}"
        );
    }
}
