//! The learned Hamiltonian model as batched burn tensor operations: the same three networks,
//! normalizations and equations as the core's [`hamflight::model::LearnedModel`] (paper eq. 1
//! and 2), with the networks' input Jacobians (JVP, VJP) written as tensor ops so that
//! first-order autodiff differentiates through ∂H/∂q.
//!
//! Layout: a layer's weight is `[inputs, outputs]` (burn's, the transpose of the core's
//! `weight[o][i]`), its bias `[1, outputs]`. Batched vectors are `[B, 3]`, rotations `[B, 3, 3]`
//! (row-major, so `reshape([B, 9])` gives q's rows r₁, r₂, r₃).

use burn::tensor::{Device, Tensor, TensorData};
use hamflight::model::learned::{
    CONTROL_SCALE, INERTIA_INV_EPS, INERTIA_INV_SCALE_PER_KG_M2, TORQUE_SCALE_NM, WRENCH_SCALE,
};
use hamflight::nn::{Dense, Mlp};

mod dynamics;
use dynamics::{control_wrench_from, disturbance_from};
mod linalg;
pub use dynamics::{
    dh_dr_with, phase_rhs_with, rk4_with, to_phase_with, velocities_with, Forcing, Phase,
};
pub use linalg::{hat, invert_sym3, mat_mat, mat_mat_t, mat_t_vec, mat_vec_n, matvec};

/// One two-hidden-layer tanh MLP as tensors.
#[derive(Clone, Debug)]
pub struct TMlp {
    /// Weights `[in, out]` of layers 0, 1, 2.
    pub w: [Tensor<2>; 3],
    /// Biases `[1, out]`.
    pub b: [Tensor<2>; 3],
    /// The weights transposed, once per batch for the VJP ([`TMlp::with_transposes`]).
    pub wt: Option<[Tensor<2>; 3]>,
}

/// The hidden activations of one forward pass (kept for the JVP/VJP).
pub struct Trace {
    h0: Tensor<2>,
    h1: Tensor<2>,
    /// The output.
    pub y: Tensor<2>,
}

fn tanh(x: Tensor<2>) -> Tensor<2> {
    x.tanh()
}

impl TMlp {
    /// Forward pass.
    pub fn forward(&self, x: Tensor<2>) -> Trace {
        let h0 = tanh(x.matmul(self.w[0].clone()) + self.b[0].clone());
        let h1 = tanh(h0.clone().matmul(self.w[1].clone()) + self.b[1].clone());
        let y = h1.clone().matmul(self.w[2].clone()) + self.b[2].clone();
        Trace { h0, h1, y }
    }

    /// Jacobian–vector product J dx at the traced point.
    pub fn jvp(&self, t: &Trace, dx: Tensor<2>) -> Tensor<2> {
        let s0 = t.h0.clone().square().neg().add_scalar(1.0);
        let s1 = t.h1.clone().square().neg().add_scalar(1.0);
        let d0 = s0 * dx.matmul(self.w[0].clone());
        let d1 = s1 * d0.matmul(self.w[1].clone());
        d1.matmul(self.w[2].clone())
    }

    /// Vector–Jacobian product Jᵀ dy at the traced point.
    pub fn vjp(&self, t: &Trace, dy: Tensor<2>) -> Tensor<2> {
        let s0 = t.h0.clone().square().neg().add_scalar(1.0);
        let s1 = t.h1.clone().square().neg().add_scalar(1.0);
        let wt = |k: usize| match &self.wt {
            Some(wt) => wt[k].clone(),
            None => self.w[k].clone().transpose(),
        };
        let g1 = s1 * dy.matmul(wt(2));
        let g0 = s0 * g1.matmul(wt(1));
        g0.matmul(wt(0))
    }

    /// The same network with its transposed weights kept, so that each VJP skips three
    /// transposes (one graph node each per call in training).
    pub fn with_transposes(mut self) -> Self {
        self.wt = Some(self.w.clone().map(|w| w.transpose()));
        self
    }

    /// All six tensors, in `[w0, b0, w1, b1, w2, b2]` order.
    pub fn tensors(&self) -> Vec<Tensor<2>> {
        vec![
            self.w[0].clone(),
            self.b[0].clone(),
            self.w[1].clone(),
            self.b[1].clone(),
            self.w[2].clone(),
            self.b[2].clone(),
        ]
    }

    /// Rebuilds from six tensors in [`TMlp::tensors`] order.
    pub fn from_tensors(t: &[Tensor<2>]) -> Self {
        Self {
            w: [t[0].clone(), t[2].clone(), t[4].clone()],
            b: [t[1].clone(), t[3].clone(), t[5].clone()],
            wt: None,
        }
    }

    /// From the core's fixed-size network.
    pub fn from_core<const I: usize, const H: usize, const O: usize>(
        m: &Mlp<I, H, O>,
        device: &Device,
    ) -> Self {
        fn dense<const I: usize, const O: usize>(
            d: &Dense<I, O>,
            device: &Device,
        ) -> (Tensor<2>, Tensor<2>) {
            let mut w = vec![0f32; I * O];
            for (o, row) in d.weight.iter().enumerate() {
                for (i, v) in row.iter().enumerate() {
                    w[i * O + o] = *v;
                }
            }
            (
                Tensor::from_data(TensorData::new(w, [I, O]), device),
                Tensor::from_data(TensorData::new(d.bias.to_vec(), [1, O]), device),
            )
        }
        let (w0, b0) = dense(&m.l0, device);
        let (w1, b1) = dense(&m.l1, device);
        let (w2, b2) = dense(&m.l2, device);
        Self {
            w: [w0, w1, w2],
            b: [b0, b1, b2],
            wt: None,
        }
    }

    /// To the core's fixed-size network. Shapes must match (they do by construction).
    pub fn to_core<const I: usize, const H: usize, const O: usize>(&self) -> Mlp<I, H, O> {
        fn dense<const I: usize, const O: usize>(w: &Tensor<2>, b: &Tensor<2>) -> Dense<I, O> {
            let wv = to_vec(w);
            let bv = to_vec(b);
            let mut d = Dense::<I, O>::ZERO;
            for (o, row) in d.weight.iter_mut().enumerate() {
                for (i, v) in row.iter_mut().enumerate() {
                    *v = wv[i * O + o];
                }
            }
            d.bias.copy_from_slice(&bv[..O]);
            d
        }
        Mlp {
            l0: dense(&self.w[0], &self.b[0]),
            l1: dense(&self.w[1], &self.b[1]),
            l2: dense(&self.w[2], &self.b[2]),
        }
    }
}

/// A tensor's values as a flat `Vec<f32>`.
pub fn to_vec<const D: usize>(t: &Tensor<D>) -> Vec<f32> {
    t.clone()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap_or_default()
}

/// Constant tensors of the equations.
#[derive(Clone, Debug)]
pub struct Consts {
    /// `[6, 9]`: l → row-major L.
    l_map: Tensor<2>,
    /// `[9, 6]`: row-major ∂H/∂L → ∂H/∂l (the lower triangle).
    l_map_t: Tensor<2>,
    /// `[3, 9]`: ω → row-major ω̂.
    hat_map: Tensor<2>,
    /// `[1, 3, 3]` identity times INERTIA_INV_EPS.
    eps_eye: Tensor<3>,
    /// `[1, 6]` row scale of g.
    wrench_scale: Tensor<2>,
    /// `[1, 4]` 1 / CONTROL_SCALE.
    control_inv_scale: Tensor<2>,
    /// `[4, 4]`: a row u/CONTROL_SCALE → the CF2X's rotor thrusts (row form of A⁻¹ S).
    rotor_from_u: Tensor<2>,
    /// `[4, 4]`: rotor thrusts → u/CONTROL_SCALE (row form of S⁻¹ A).
    u_from_rotor: Tensor<2>,
    /// The vehicle's mass m (kg): known, not learned (paper Sec. 4).
    pub mass_kg: f32,
}

impl Consts {
    /// Builds the constants on `device` for a vehicle of mass `mass_kg` (kg).
    pub fn new(device: &Device, mass_kg: f32) -> Self {
        let mut l = vec![0f32; 54];
        // l index k → L position (row-major).
        for (k, pos) in [0usize, 3, 4, 6, 7, 8].into_iter().enumerate() {
            l[k * 9 + pos] = 1.0;
        }
        let mut lt = vec![0f32; 54];
        for k in 0..6 {
            for pos in 0..9 {
                lt[pos * 6 + k] = l[k * 9 + pos];
            }
        }
        // ω̂ = [[0, -w3, w2], [w3, 0, -w1], [-w2, w1, 0]].
        let mut h = vec![0f32; 27];
        let set = |h: &mut Vec<f32>, comp: usize, pos: usize, v: f32| h[comp * 9 + pos] = v;
        set(&mut h, 2, 1, -1.0);
        set(&mut h, 1, 2, 1.0);
        set(&mut h, 2, 3, 1.0);
        set(&mut h, 0, 5, -1.0);
        set(&mut h, 1, 6, -1.0);
        set(&mut h, 0, 7, 1.0);
        let cinv: Vec<f32> = CONTROL_SCALE.iter().map(|c| 1.0 / c).collect();
        let (rotor_from_u, u_from_rotor) = super::export::normalized_rotor_maps();
        let row_form =
            |m: [[f32; 4]; 4]| Tensor::from_data(TensorData::new(m.concat(), [4, 4]), device);
        Self {
            l_map: Tensor::from_data(TensorData::new(l, [6, 9]), device),
            l_map_t: Tensor::from_data(TensorData::new(lt, [9, 6]), device),
            hat_map: Tensor::from_data(TensorData::new(h, [3, 9]), device),
            eps_eye: Tensor::<2>::eye(3, device)
                .reshape([1, 3, 3])
                .mul_scalar(INERTIA_INV_EPS),
            wrench_scale: Tensor::from_data(TensorData::new(WRENCH_SCALE.to_vec(), [1, 6]), device),
            control_inv_scale: Tensor::from_data(TensorData::new(cinv, [1, 4]), device),
            rotor_from_u: row_form(rotor_from_u),
            u_from_rotor: row_form(u_from_rotor),
            mass_kg,
        }
    }
}

/// The learned networks (θ: J⁻¹, g; φ: W) as tensors.
#[derive(Clone, Debug)]
pub struct TModel {
    /// J⁻¹ head.
    pub inertia: TMlp,
    /// g head.
    pub gain: TMlp,
    /// W head.
    pub disturbance: TMlp,
}

/// The J⁻¹ head evaluated at a batch of rotations.
pub struct InertiaEval {
    /// The net's trace (for JVP/VJP).
    pub trace: Trace,
    /// L `[B,3,3]`.
    pub l: Tensor<3>,
    /// J⁻¹ `[B,3,3]`.
    pub jinv: Tensor<3>,
}

/// J⁻¹ = s_J (L Lᵀ + ε I) from the J⁻¹ head's trace.
fn inertia_from_trace(c: &Consts, trace: Trace) -> InertiaEval {
    let b = trace.y.dims()[0];
    let l = trace.y.clone().matmul(c.l_map.clone()).reshape([b, 3, 3]);
    let jinv = (mat_mat_t(l.clone(), l.clone()) + c.eps_eye.clone())
        .mul_scalar(INERTIA_INV_SCALE_PER_KG_M2);
    InertiaEval { trace, l, jinv }
}

/// The three heads evaluated at one batch of rotations.
pub struct Nets {
    /// J⁻¹ and its head's trace.
    pub inertia: InertiaEval,
    /// The g head's raw output [B, 24].
    pub gain: Tensor<2>,
    /// The W head's raw output [B, 6p].
    pub features: Tensor<2>,
}

/// The three heads as one network for training: layer 0 side by side `[9, 3H]`, layers 1 and
/// 2 block-diagonal, so a batch of rotations takes one pass of three matmuls instead of nine
/// (the flex backend's time goes to the number of small ops, not their size). Built once per
/// batch from the heads' tensors (the blocks keep their gradients).
pub struct FusedHeads {
    net: TMlp,
    /// The J⁻¹ head alone (with its transposes), for the VJP of ∂H/∂q.
    inertia: TMlp,
    hidden: usize,
    out: [usize; 3],
}

impl FusedHeads {
    /// Fuses `m`'s heads.
    pub fn new(m: &TModel) -> Self {
        let heads = [&m.inertia, &m.gain, &m.disturbance];
        let hidden = m.inertia.w[0].dims()[1];
        let out = heads.map(|h| h.w[2].dims()[1]);
        let device = m.inertia.w[0].device();
        let block_diag = |k: usize, widths: [usize; 3]| {
            let rows: Vec<Tensor<2>> = (0..3)
                .map(|i| {
                    let r = heads[i].w[k].dims()[0];
                    let blocks: Vec<Tensor<2>> = (0..3)
                        .map(|j| {
                            if i == j {
                                heads[i].w[k].clone()
                            } else {
                                Tensor::zeros([r, widths[j]], &device)
                            }
                        })
                        .collect();
                    Tensor::cat(blocks, 1)
                })
                .collect();
            Tensor::cat(rows, 0)
        };
        let net = TMlp {
            w: [
                Tensor::cat(heads.iter().map(|h| h.w[0].clone()).collect(), 1),
                block_diag(1, [hidden; 3]),
                block_diag(2, out),
            ],
            b: [0, 1, 2].map(|k| Tensor::cat(heads.iter().map(|h| h.b[k].clone()).collect(), 1)),
            wt: None,
        };
        Self {
            net,
            inertia: m.inertia.clone().with_transposes(),
            hidden,
            out,
        }
    }

    /// The three heads at a batch of rotations (what [`TModel::nets`] gives, in one pass).
    pub fn nets(&self, c: &Consts, rot: &Tensor<3>) -> Nets {
        let b = rot.dims()[0];
        let t = self.net.forward(rot.clone().reshape([b, 9]));
        let [oi, og, od] = self.out;
        let h = self.hidden;
        let trace = Trace {
            h0: t.h0.narrow(1, 0, h),
            h1: t.h1.narrow(1, 0, h),
            y: t.y.clone().narrow(1, 0, oi),
        };
        Nets {
            inertia: inertia_from_trace(c, trace),
            gain: t.y.clone().narrow(1, oi, og),
            features: t.y.narrow(1, oi + og, od),
        }
    }

    /// The J⁻¹ head (for [`dh_dr_with`]).
    pub fn inertia_head(&self) -> &TMlp {
        &self.inertia
    }
}

impl TModel {
    /// From the core's weights.
    pub fn from_core(w: &hamflight::model::ModelWeights, device: &Device) -> Self {
        Self {
            inertia: TMlp::from_core(&w.inertia, device),
            gain: TMlp::from_core(&w.gain, device),
            disturbance: TMlp::from_core(&w.disturbance, device),
        }
    }

    /// To the core's weights.
    pub fn to_core(&self, c: &Consts) -> hamflight::model::ModelWeights {
        hamflight::model::ModelWeights {
            mass_kg: c.mass_kg,
            inertia: self.inertia.to_core(),
            gain: self.gain.to_core(),
            disturbance: self.disturbance.to_core(),
        }
    }

    /// All 18 tensors (inertia, gain, disturbance; each in [`TMlp::tensors`] order).
    pub fn tensors(&self) -> Vec<Tensor<2>> {
        let mut v = self.inertia.tensors();
        v.extend(self.gain.tensors());
        v.extend(self.disturbance.tensors());
        v
    }

    /// Rebuilds from 18 tensors in [`TModel::tensors`] order.
    pub fn from_tensors(t: &[Tensor<2>]) -> Self {
        Self {
            inertia: TMlp::from_tensors(&t[0..6]),
            gain: TMlp::from_tensors(&t[6..12]),
            disturbance: TMlp::from_tensors(&t[12..18]),
        }
    }

    /// J⁻¹(R) = s_J (L Lᵀ + ε I).
    pub fn inertia_inv(&self, c: &Consts, rot: &Tensor<3>) -> InertiaEval {
        let b = rot.dims()[0];
        let trace = self.inertia.forward(rot.clone().reshape([b, 9]));
        inertia_from_trace(c, trace)
    }

    /// The three heads at a batch of rotations, one forward pass each.
    pub fn nets(&self, c: &Consts, rot: &Tensor<3>) -> Nets {
        let b = rot.dims()[0];
        let x = rot.clone().reshape([b, 9]);
        Nets {
            inertia: self.inertia_inv(c, rot),
            gain: self.gain.forward(x.clone()).y,
            features: self.disturbance.forward(x).y,
        }
    }

    /// d/dt J⁻¹ along Ṙ (a JVP of the head), `[B,3,3]`.
    pub fn inertia_inv_dot(&self, c: &Consts, ev: &InertiaEval, rot_dot: Tensor<3>) -> Tensor<3> {
        let b = rot_dot.dims()[0];
        let dl = self
            .inertia
            .jvp(&ev.trace, rot_dot.reshape([b, 9]))
            .matmul(c.l_map.clone())
            .reshape([b, 3, 3]);
        let t = dl.matmul(ev.l.clone().swap_dims(1, 2));
        (t.clone() + t.swap_dims(1, 2)).mul_scalar(INERTIA_INV_SCALE_PER_KG_M2)
    }

    /// ∂(½ 𝔭_ωᵀ J⁻¹(q) 𝔭_ω)/∂rᵢ at fixed 𝔭_ω, rows i, `[B,3,3]` (a VJP of the head).
    pub fn dh_dr(&self, c: &Consts, ev: &InertiaEval, pw: Tensor<2>) -> Tensor<3> {
        dh_dr_with(c, &self.inertia, ev, pw)
    }

    /// g(q) u as a body force and torque (`[B,3]` each), from u / CONTROL_SCALE.
    pub fn control_wrench(
        &self,
        c: &Consts,
        rot: &Tensor<3>,
        u_norm: Tensor<2>,
    ) -> (Tensor<2>, Tensor<2>) {
        let b = rot.dims()[0];
        let o = self.gain.forward(rot.clone().reshape([b, 9])).y;
        control_wrench_from(c, o, u_norm)
    }

    /// The feature head's raw output [B, 6, p].
    pub fn feature_output(&self, rot: &Tensor<3>) -> Tensor<3> {
        let b = rot.dims()[0];
        let y = self.disturbance.forward(rot.clone().reshape([b, 9])).y;
        let p = y.dims()[1] / 6;
        y.reshape([b, 6, p])
    }

    /// W(q) `[B,6,p]` (force rows m Rᵀ n_k, torque rows TORQUE_SCALE_NM t_k).
    pub fn features(&self, c: &Consts, rot: &Tensor<3>) -> Tensor<3> {
        let o = self.feature_output(rot);
        let [b, _, p] = o.dims();
        let force = rot
            .clone()
            .swap_dims(1, 2)
            .matmul(o.clone().narrow(1, 0, 3))
            .mul_scalar(c.mass_kg);
        let torque = o.narrow(1, 3, 3).mul_scalar(TORQUE_SCALE_NM);
        let _ = (b, p);
        Tensor::cat(vec![force, torque], 1)
    }

    /// d = W a as a body force and torque (`[B,3]` each).
    pub fn disturbance(&self, c: &Consts, rot: &Tensor<3>, a: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let b = rot.dims()[0];
        let o = self.disturbance.forward(rot.clone().reshape([b, 9])).y;
        disturbance_from(c, o, rot, a)
    }

    /// Paper eq. 1 in (q, 𝔭): the phase-space derivative, and the velocities (v, ω) at `x`.
    pub fn phase_rhs(&self, c: &Consts, x: &Phase, f: &Forcing) -> Phase {
        phase_rhs_with(c, x, f, self.nets(c, &x.rot), &self.inertia)
    }

    /// The state derivative (ṗ, Ṙ, v̇, ω̇) of paper eq. 1 and 2 at a batch of states — what the
    /// core's `dynamics` returns, for parity checks.
    pub fn state_derivative(
        &self,
        c: &Consts,
        p: Tensor<2>,
        rot: Tensor<3>,
        v: Tensor<2>,
        w: Tensor<2>,
        f: &Forcing,
    ) -> (Tensor<2>, Tensor<3>, Tensor<2>, Tensor<2>) {
        let ev = self.inertia_inv(c, &rot);
        let pw = matvec(invert_sym3(ev.jinv.clone()), w.clone());
        let x = Phase {
            p,
            rot: rot.clone(),
            pv: v.mul_scalar(c.mass_kg),
            pw: pw.clone(),
        };
        let d = self.phase_rhs(c, &x, f);
        let djinv = self.inertia_inv_dot(c, &ev, d.rot.clone());
        let w_dot = matvec(djinv, pw) + matvec(ev.jinv, d.pw);
        (d.p, d.rot, d.pv.div_scalar(c.mass_kg), w_dot)
    }

    /// ζ → 𝔭 at the start of a window: 𝔭_v = m v, 𝔭_ω = J(q) ω.
    pub fn to_phase(
        &self,
        c: &Consts,
        p: Tensor<2>,
        rot: Tensor<3>,
        v: Tensor<2>,
        w: Tensor<2>,
    ) -> Phase {
        to_phase_with(c, &self.inertia_inv(c, &rot), p, rot, v, w)
    }

    /// 𝔭 → ζ: (v, ω) = (𝔭_v / m, J⁻¹(q) 𝔭_ω).
    pub fn velocities(&self, c: &Consts, x: &Phase) -> (Tensor<2>, Tensor<2>) {
        velocities_with(c, &self.inertia_inv(c, &x.rot), x)
    }

    /// One RK4 step of `dt_s` in (q, 𝔭) with the forcing held constant.
    pub fn rk4(&self, c: &Consts, x: &Phase, f: &Forcing, dt_s: f32) -> Phase {
        let k1 = self.phase_rhs(c, x, f);
        let k2 = self.phase_rhs(c, &x.axpy(0.5 * dt_s, &k1), f);
        let k3 = self.phase_rhs(c, &x.axpy(0.5 * dt_s, &k2), f);
        let k4 = self.phase_rhs(c, &x.axpy(dt_s, &k3), f);
        x.rk4_combine(&k1, &k2, &k3, &k4, dt_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flight's rotor gains turn the commanded wrench into what rotors with efficiencies
    /// 1 + δη realize: A diag(1 + δη) A⁻¹ u, in the model's units u / CONTROL_SCALE.
    #[test]
    fn rotor_gains_realize_the_weak_rotors_wrench() {
        let device = Device::flex();
        let c = Consts::new(&device, 0.027);
        let eff = [0.8f32, 0.9, 1.0, 1.05];
        let u = [0.27f32, 1e-4, -2e-4, 5e-5];
        let mut per_flight = vec![0f32; hamflight::model::FEATURES];
        per_flight.extend(eff.iter().map(|e| e - 1.0));
        let width = per_flight.len();
        let f = Forcing::new(
            &c,
            Tensor::from_data(TensorData::new(u.to_vec(), [1, 4]), &device),
            Tensor::from_data(TensorData::new(per_flight, [1, width]), &device),
            Tensor::from_data(TensorData::new(vec![0i64], [1]), &device),
        );
        let got = to_vec(&f.u_norm);
        let want = super::super::export::rotor_scaling(&eff) * nalgebra::Vector4::from(u);
        for k in 0..4 {
            let w = want[k] / CONTROL_SCALE[k];
            assert!(
                (got[k] - w).abs() < 1e-5 * w.abs().max(1.0),
                "{k}: {} vs {w}",
                got[k]
            );
        }
        // Without rotor gains the command passes as it is.
        let plain = Forcing::new(
            &c,
            Tensor::from_data(TensorData::new(u.to_vec(), [1, 4]), &device),
            Tensor::zeros([1, hamflight::model::FEATURES], &device),
            Tensor::from_data(TensorData::new(vec![0i64], [1]), &device),
        );
        for (k, v) in to_vec(&plain.u_norm).iter().enumerate() {
            assert!((v - u[k] / CONTROL_SCALE[k]).abs() < 1e-6);
        }
    }
}
