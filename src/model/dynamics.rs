//! Hamilton's equations on SE(3) (paper eq. 1) and the velocity derivative (paper eq. 2),
//! written out for M = diag(m I, J(q)) and V = m g e₃ᵀ p (docs/math.md,
//! "Hamiltonian dynamics on SE(3)"):
//!
//! - ṗ = R v, Ṙ = R ω̂ (ṙᵢ = rᵢ × ω);
//! - 𝔭̇_v = 𝔭_v × ω − m g Rᵀe₃ + (g (k ∘ u))_v + d_v − D_v v − Bᵀω;
//! - 𝔭̇_ω = 𝔭_ω × ω + 𝔭_v × v + Σᵢ rᵢ × ∂H/∂rᵢ + (g (k ∘ u))_ω + d_ω − D_ω ω + B v + b × K b;
//! - v̇ = 𝔭̇_v / m, ω̇ = (d/dt J⁻¹) 𝔭_ω + J⁻¹ 𝔭̇_ω;
//!
//! with d = W(q, 𝔭) a, b = Rᵀe₃ and the port terms k, D, B, K of [`super::PortTerms`] (the
//! identity for the rigid body alone; the input lags act before `u` reaches these equations,
//! [`super::ActuatorLag`]).

use super::{HamiltonianModel, ModelTerms, PortTerms, State, FEATURES};
use nalgebra::{Matrix3, SVector, Vector3, Vector4};

/// The time derivative of a [`State`] (paper eq. 1 and 2, in the state's own coordinates).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct StateDerivative {
    /// ṗ = R v (m/s, world frame).
    pub p_dot_m_s: Vector3<f32>,
    /// Ṙ = R ω̂ (1/s).
    pub rot_dot: Matrix3<f32>,
    /// v̇, body frame (m/s²).
    pub v_dot_m_s2: Vector3<f32>,
    /// ω̇, body frame (rad/s²).
    pub w_dot_rad_s2: Vector3<f32>,
}

/// Evaluates paper eq. 1 and 2 from a model's terms at `state`.
///
/// `p_w` is the angular momentum 𝔭_ω = J ω (body frame, kg·m²/s), `dh_dr` the gradients
/// ∂H/∂rᵢ of the kinetic energy at fixed momentum (zero for a constant J), `djinv_dt` the
/// derivative of J⁻¹(q) along q̇ (zero for a constant J), `u` the control [f (N); τ (N·m)] and `a`
/// the disturbance weights (d = W a). A non-positive mass gives a zero linear acceleration.
#[allow(clippy::too_many_arguments)]
pub fn hamilton_dynamics(
    state: &State,
    terms: &ModelTerms,
    port: &PortTerms,
    p_w: &Vector3<f32>,
    dh_dr: &[Vector3<f32>; 3],
    djinv_dt: &Matrix3<f32>,
    u: &Vector4<f32>,
    a: &[f32; FEATURES],
) -> StateDerivative {
    let m = terms.mass_kg;
    let v = state.v_body_m_s;
    let w = state.w_body_rad_s;
    let rot = &state.rot;
    let p_v = v * m;
    let ku = u.component_mul(&port.input_gain());
    let wrench = terms.gain * ku + terms.features * SVector::<f32, FEATURES>::from_row_slice(a);
    // Rᵀ e₃ is the third row r₃ of R; ∂V/∂p = m g e₃.
    let r3 = Vector3::new(rot.m31, rot.m32, rot.m33);
    let (f_port, t_port) = port.wrench(&r3, &v, &w);
    let f_ext = Vector3::new(wrench.x, wrench.y, wrench.z) + f_port;
    let t_ext = Vector3::new(wrench.w, wrench.a, wrench.b) + t_port;
    let p_v_dot = p_v.cross(&w) - r3 * (m * terms.gravity_m_s2) + f_ext;
    let rows = [
        Vector3::new(rot.m11, rot.m12, rot.m13),
        Vector3::new(rot.m21, rot.m22, rot.m23),
        r3,
    ];
    let shape_torque = rows
        .iter()
        .zip(dh_dr.iter())
        .fold(Vector3::zeros(), |acc, (r, g)| acc + r.cross(g));
    let p_w_dot = p_w.cross(&w) + p_v.cross(&v) + shape_torque + t_ext;
    let v_dot = if m > 0.0 {
        p_v_dot / m
    } else {
        Vector3::zeros()
    };
    StateDerivative {
        p_dot_m_s: rot * v,
        rot_dot: rot * crate::lie::hat(&w),
        v_dot_m_s2: v_dot,
        w_dot_rad_s2: djinv_dt * p_w + terms.inertia_inv * p_w_dot,
    }
}

/// Paper eq. 1 and 2 for a model whose J does not depend on q (∂H/∂rᵢ = 0, d/dt J⁻¹ = 0): the
/// default [`HamiltonianModel::dynamics`], used by [`super::NominalModel`].
pub fn constant_inertia_dynamics<M: HamiltonianModel + ?Sized>(
    model: &M,
    state: &State,
    u: &Vector4<f32>,
    a: &[f32; FEATURES],
) -> StateDerivative {
    let terms = model.terms(state);
    let j = terms
        .inertia_inv
        .try_inverse()
        .unwrap_or_else(Matrix3::zeros);
    let p_w = j * state.w_body_rad_s;
    let zero = [Vector3::zeros(); 3];
    hamilton_dynamics(
        state,
        &terms,
        model.port(),
        &p_w,
        &zero,
        &Matrix3::zeros(),
        u,
        a,
    )
}

/// `state + dt · deriv`, component-wise (R is not re-projected onto SO(3)).
pub fn euler_update(state: &State, deriv: &StateDerivative, dt_s: f32) -> State {
    State {
        p_m: state.p_m + deriv.p_dot_m_s * dt_s,
        rot: state.rot + deriv.rot_dot * dt_s,
        v_body_m_s: state.v_body_m_s + deriv.v_dot_m_s2 * dt_s,
        w_body_rad_s: state.w_body_rad_s + deriv.w_dot_rad_s2 * dt_s,
    }
}

/// One classic RK4 step of the model's dynamics with `u` and `a` held constant, as in training.
/// R is integrated as a matrix (it leaves SO(3) by O(dt⁵) per step; re-orthonormalize with
/// [`crate::lie::orthonormalize`] over long horizons).
pub fn rk4_step<M: HamiltonianModel + ?Sized>(
    model: &M,
    state: &State,
    u: &Vector4<f32>,
    a: &[f32; FEATURES],
    dt_s: f32,
) -> State {
    let k1 = model.dynamics(state, u, a);
    let k2 = model.dynamics(&euler_update(state, &k1, 0.5 * dt_s), u, a);
    let k3 = model.dynamics(&euler_update(state, &k2, 0.5 * dt_s), u, a);
    let k4 = model.dynamics(&euler_update(state, &k3, dt_s), u, a);
    let sixth = dt_s / 6.0;
    State {
        p_m: state.p_m
            + (k1.p_dot_m_s + (k2.p_dot_m_s + k3.p_dot_m_s) * 2.0 + k4.p_dot_m_s) * sixth,
        rot: state.rot + (k1.rot_dot + (k2.rot_dot + k3.rot_dot) * 2.0 + k4.rot_dot) * sixth,
        v_body_m_s: state.v_body_m_s
            + (k1.v_dot_m_s2 + (k2.v_dot_m_s2 + k3.v_dot_m_s2) * 2.0 + k4.v_dot_m_s2) * sixth,
        w_body_rad_s: state.w_body_rad_s
            + (k1.w_dot_rad_s2 + (k2.w_dot_rad_s2 + k3.w_dot_rad_s2) * 2.0 + k4.w_dot_rad_s2)
                * sixth,
    }
}

/// The Hamiltonian H = ½ m |v|² + ½ ωᵀ J(q) ω + m g e₃ᵀ p + ½ bᵀ K b (J), i.e. paper Sec. 2's
/// ½ 𝔭ᵀ M⁻¹ 𝔭 + V with 𝔭 = M ζ and the learned potential of [`super::PortTerms`].
pub fn hamiltonian<M: HamiltonianModel + ?Sized>(model: &M, state: &State) -> f32 {
    let terms = model.terms(state);
    let j = terms
        .inertia_inv
        .try_inverse()
        .unwrap_or_else(Matrix3::zeros);
    let w = state.w_body_rad_s;
    0.5 * terms.mass_kg * state.v_body_m_s.norm_squared()
        + 0.5 * w.dot(&(j * w))
        + terms.mass_kg * terms.gravity_m_s2 * state.p_m.z
        + model
            .port()
            .potential_j(&Vector3::new(state.rot.m31, state.rot.m32, state.rot.m33))
}
