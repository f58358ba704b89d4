//! The port-Hamiltonian dynamics in phase space (q, 𝔭) as batched tensor ops (paper eq. 1–2):
//! the state, the forcing (commands and disturbance), the right-hand side and its RK4 step.

use burn::tensor::{Int, Tensor};
use hamflight::model::learned::{INERTIA_INV_SCALE_PER_KG_M2, TORQUE_SCALE_NM};
use hamflight::model::GRAVITY_M_S2;

use super::{
    hat, invert_sym3, mat_mat, mat_t_vec, mat_vec_n, matvec, Consts, InertiaEval, Nets, TMlp,
};

/// The phase-space state integrated in training: (q, 𝔭) with p, R, 𝔭_v, 𝔭_ω kept apart.
#[derive(Clone, Debug)]
pub struct Phase {
    /// Position `[B,3]`.
    pub p: Tensor<2>,
    /// Rotation `[B,3,3]`.
    pub rot: Tensor<3>,
    /// Linear momentum 𝔭_v `[B,3]`.
    pub pv: Tensor<2>,
    /// Angular momentum 𝔭_ω `[B,3]`.
    pub pw: Tensor<2>,
}

impl Phase {
    pub(super) fn axpy(&self, h: f32, d: &Phase) -> Phase {
        Phase {
            p: self.p.clone() + d.p.clone().mul_scalar(h),
            rot: self.rot.clone() + d.rot.clone().mul_scalar(h),
            pv: self.pv.clone() + d.pv.clone().mul_scalar(h),
            pw: self.pw.clone() + d.pw.clone().mul_scalar(h),
        }
    }
}

/// Per-batch inputs of the ODE that stay constant through a window.
pub struct Forcing {
    /// The realized control over CONTROL_SCALE `[B,4]`: u/CONTROL_SCALE, through the flight's
    /// rotor gains when they are learned.
    pub u_norm: Tensor<2>,
    /// a_j of each window `[B,p]`.
    pub a: Tensor<2>,
    /// Each window's flight's rotor gain deviations δηⱼ `[B,4]` (None: not learned).
    pub rotor_gain: Option<Tensor<2>>,
}

impl Forcing {
    /// From the raw control `[B,4]` and the per-flight parameters `[M,p]` (the a_j) or [M,p+4]
    /// (the a_j, then the rotor gain deviations δηⱼ) with indices `[B]`.
    pub fn new(c: &Consts, u: Tensor<2>, per_flight: Tensor<2>, idx: Tensor<1, Int>) -> Self {
        let sel = per_flight.select(0, idx);
        let [_, width] = sel.dims();
        let p = width.min(hamflight::model::FEATURES);
        let rotor_gain = (width > p).then(|| sel.clone().narrow(1, p, width - p));
        let a = if width > p { sel.narrow(1, 0, p) } else { sel };
        Self {
            u_norm: realized(c, u, rotor_gain.as_ref()),
            a,
            rotor_gain,
        }
    }

    /// The same a_j and rotor gains with another raw control `[B,4]` (the next step of a window).
    pub fn with_control(&self, c: &Consts, u: Tensor<2>) -> Self {
        Self {
            u_norm: realized(c, u, self.rotor_gain.as_ref()),
            a: self.a.clone(),
            rotor_gain: self.rotor_gain.clone(),
        }
    }
}

/// u/CONTROL_SCALE of the wrench that rotors with gain deviations `rotor_gain` (δη, [B,4])
/// realize for the raw command `u`: (I + A diag(δη) A⁻¹) u in the model's units (A the CF2X
/// mixer); u/CONTROL_SCALE itself without them.
pub(super) fn realized(c: &Consts, u: Tensor<2>, rotor_gain: Option<&Tensor<2>>) -> Tensor<2> {
    let u_norm = u * c.control_inv_scale.clone();
    match rotor_gain {
        None => u_norm,
        Some(eta) => {
            let rotors = u_norm.clone().matmul(c.rotor_from_u.clone());
            u_norm + (rotors * eta.clone()).matmul(c.u_from_rotor.clone())
        }
    }
}

impl Phase {
    /// x + h/6 (k₁ + 2 k₂ + 2 k₃ + k₄).
    pub(super) fn rk4_combine(
        &self,
        k1: &Phase,
        k2: &Phase,
        k3: &Phase,
        k4: &Phase,
        dt_s: f32,
    ) -> Phase {
        let x = self;
        let h6 = dt_s / 6.0;
        let (k1, k2, k3, k4) = (k1.clone(), k2.clone(), k3.clone(), k4.clone());
        Phase {
            p: x.p.clone() + (k1.p + (k2.p + k3.p).mul_scalar(2.0) + k4.p).mul_scalar(h6),
            rot: x.rot.clone()
                + (k1.rot + (k2.rot + k3.rot).mul_scalar(2.0) + k4.rot).mul_scalar(h6),
            pv: x.pv.clone() + (k1.pv + (k2.pv + k3.pv).mul_scalar(2.0) + k4.pv).mul_scalar(h6),
            pw: x.pw.clone() + (k1.pw + (k2.pw + k3.pw).mul_scalar(2.0) + k4.pw).mul_scalar(h6),
        }
    }
}

/// ∂(½ 𝔭_ωᵀ J⁻¹(q) 𝔭_ω)/∂rᵢ at fixed 𝔭_ω with the J⁻¹ head `head` ([`TModel::dh_dr`](super::TModel::dh_dr)).
pub fn dh_dr_with(c: &Consts, head: &TMlp, ev: &InertiaEval, pw: Tensor<2>) -> Tensor<3> {
    let b = pw.dims()[0];

    let y = mat_t_vec(ev.l.clone(), pw.clone());
    let outer = pw.reshape([b, 3, 1]) * y.reshape([b, 1, 3]);
    let dh_dl = outer
        .reshape([b, 9])
        .matmul(c.l_map_t.clone())
        .mul_scalar(INERTIA_INV_SCALE_PER_KG_M2);
    head.vjp(&ev.trace, dh_dl).reshape([b, 3, 3])
}

/// g u as a body force and torque from the g head's raw output [B, 24].
pub(super) fn control_wrench_from(
    c: &Consts,
    gain: Tensor<2>,
    u_norm: Tensor<2>,
) -> (Tensor<2>, Tensor<2>) {
    let b = gain.dims()[0];
    let o = gain.reshape([b, 6, 4]);
    let gu = mat_vec_n(o, u_norm) * c.wrench_scale.clone();
    (gu.clone().narrow(1, 0, 3), gu.narrow(1, 3, 3))
}

/// d = W a as a body force and torque from the W head's raw output [B, 6p].
pub(super) fn disturbance_from(
    c: &Consts,
    features: Tensor<2>,
    rot: &Tensor<3>,
    a: Tensor<2>,
) -> (Tensor<2>, Tensor<2>) {
    let [b, p] = a.dims();
    let o = features.reshape([b, 6, p]);
    let oa = mat_vec_n(o, a);
    let n_world = oa.clone().narrow(1, 0, 3);
    let force = mat_t_vec(rot.clone(), n_world).mul_scalar(c.mass_kg);
    let torque = oa.narrow(1, 3, 3).mul_scalar(TORQUE_SCALE_NM);
    (force, torque)
}

/// Paper eq. 1 in (q, 𝔭) at `x` with the heads already evaluated there (`n`; `head`: the J⁻¹
/// head, for the VJP): [`TModel::phase_rhs`](super::TModel::phase_rhs).
pub fn phase_rhs_with(c: &Consts, x: &Phase, f: &Forcing, n: Nets, head: &TMlp) -> Phase {
    let ev = n.inertia;
    let w = matvec(ev.jinv.clone(), x.pw.clone());
    let v = x.pv.clone().div_scalar(c.mass_kg);
    let (fu, tu) = control_wrench_from(c, n.gain, f.u_norm.clone());
    let (fd, td) = disturbance_from(c, n.features, &x.rot, f.a.clone());
    let b = v.dims()[0];
    // Rᵀ (m g e₃) = m g r₃.
    let r3 = x.rot.clone().narrow(1, 2, 1).reshape([b, 3]);
    let pv_dot =
        x.pv.clone().cross(w.clone(), 1) - r3.mul_scalar(c.mass_kg * GRAVITY_M_S2) + fu + fd;
    let dh = dh_dr_with(c, head, &ev, x.pw.clone());
    let shape_torque = x.rot.clone().cross(dh, 2).sum_dim(1).reshape([b, 3]);
    let pw_dot = x.pw.clone().cross(w.clone(), 1) + shape_torque + tu + td;
    Phase {
        p: matvec(x.rot.clone(), v),
        rot: mat_mat(x.rot.clone(), hat(c, w)),
        pv: pv_dot,
        pw: pw_dot,
    }
}

/// One RK4 step of `dt_s` in (q, 𝔭) with the forcing held constant, the heads at `x` given
/// (`n_x`) and evaluated by `nets` at the three other stages (`head`: the J⁻¹ head):
/// `TModel::rk4` with J⁻¹(q), g(q), W(q) at the step's start computed once (they are also
/// the previous step's end, where the velocities were read).
pub fn rk4_with(
    c: &Consts,
    nets: &dyn Fn(&Tensor<3>) -> Nets,
    head: &TMlp,
    x: &Phase,
    n_x: Nets,
    f: &Forcing,
    dt_s: f32,
) -> Phase {
    let stage = |y: &Phase| phase_rhs_with(c, y, f, nets(&y.rot), head);
    let k1 = phase_rhs_with(c, x, f, n_x, head);
    let k2 = stage(&x.axpy(0.5 * dt_s, &k1));
    let k3 = stage(&x.axpy(0.5 * dt_s, &k2));
    let k4 = stage(&x.axpy(dt_s, &k3));
    x.rk4_combine(&k1, &k2, &k3, &k4, dt_s)
}

/// ζ → 𝔭 with J⁻¹(q) known (`TModel::to_phase`).
pub fn to_phase_with(
    c: &Consts,
    ev: &InertiaEval,
    p: Tensor<2>,
    rot: Tensor<3>,
    v: Tensor<2>,
    w: Tensor<2>,
) -> Phase {
    Phase {
        p,
        rot,
        pv: v.mul_scalar(c.mass_kg),
        pw: matvec(invert_sym3(ev.jinv.clone()), w),
    }
}

/// 𝔭 → ζ with J⁻¹(q) known (`TModel::velocities`).
pub fn velocities_with(c: &Consts, ev: &InertiaEval, x: &Phase) -> (Tensor<2>, Tensor<2>) {
    (
        x.pv.clone().div_scalar(c.mass_kg),
        matvec(ev.jinv.clone(), x.pw.clone()),
    )
}
