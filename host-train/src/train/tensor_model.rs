//! The learned Hamiltonian model as batched burn tensor operations: the same three networks,
//! normalizations and equations as the core's [`hamflight::model::LearnedModel`] (paper eq. 1
//! and 2), with the networks' input Jacobians (JVP, VJP) written as tensor ops so that
//! first-order autodiff differentiates through ∂H/∂q.
//!
//! Layout: a layer's weight is `[inputs, outputs]` (burn's, the transpose of the core's
//! `weight[o][i]`), its bias `[1, outputs]`. Batched vectors are `[B, 3]`, rotations `[B, 3, 3]`
//! (row-major, so `reshape([B, 9])` gives q's rows r₁, r₂, r₃).

use super::data::{Batch, StateBatch};
use burn::tensor::{Device, Int, Tensor, TensorData};
use hamflight::model::learned::{
    CONTROL_SCALE, INERTIA_INV_EPS, INERTIA_INV_SCALE_PER_KG_M2, TORQUE_SCALE_NM, WRENCH_SCALE,
};
use hamflight::model::GRAVITY_M_S2;
use hamflight::nn::{Dense, Mlp};

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

/// Batch size from which the products of small matrices below are broadcast multiplies and
/// sums instead of batched matmuls: the flex backend runs a batched matmul as one gemm call
/// per matrix, a fixed cost per window, while the broadcast form takes two more ops. Measured
/// with `host-train bench-train`: full batch (shards of 3,888) 0.345 → 0.269 s per epoch,
/// batch 128 (shards of 64) 0.79 → 0.95 s.
const BROADCAST_MIN_BATCH: usize = 1024;

/// M[B,r,k] x[B,k] → [B,r].
pub fn mat_vec_n(m: Tensor<3>, x: Tensor<2>) -> Tensor<2> {
    let [b, r, k] = m.dims();
    if b < BROADCAST_MIN_BATCH {
        return m.matmul(x.reshape([b, k, 1])).reshape([b, r]);
    }
    (m * x.reshape([b, 1, k])).sum_dim(2).reshape([b, r])
}

/// M[B,3,3] v[B,3] → [B,3].
pub fn matvec(m: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    mat_vec_n(m, v)
}

/// A Bᵀ for A[B,3,3], B[B,3,3]: (A Bᵀ)ᵢⱼ = Σₖ Aᵢₖ Bⱼₖ.
pub fn mat_mat_t(a: Tensor<3>, b: Tensor<3>) -> Tensor<3> {
    let n = a.dims()[0];
    if n < BROADCAST_MIN_BATCH {
        return a.matmul(b.swap_dims(1, 2));
    }
    (a.reshape([n, 3, 1, 3]) * b.reshape([n, 1, 3, 3]))
        .sum_dim(3)
        .reshape([n, 3, 3])
}

/// A B for A[B,3,3], B[B,3,3].
pub fn mat_mat(a: Tensor<3>, b: Tensor<3>) -> Tensor<3> {
    let n = a.dims()[0];
    if n < BROADCAST_MIN_BATCH {
        return a.matmul(b);
    }
    (a.reshape([n, 3, 3, 1]) * b.reshape([n, 1, 3, 3]))
        .sum_dim(2)
        .reshape([n, 3, 3])
}

/// Mᵀ v for M[B,3,3], v[B,3].
pub fn mat_t_vec(m: Tensor<3>, v: Tensor<2>) -> Tensor<2> {
    let b = v.dims()[0];
    if b < BROADCAST_MIN_BATCH {
        return v.reshape([b, 1, 3]).matmul(m).reshape([b, 3]);
    }
    (m * v.reshape([b, 3, 1])).sum_dim(1).reshape([b, 3])
}

/// Row-major hat map of ω [B,3] → [B,3,3].
pub fn hat(c: &Consts, w: Tensor<2>) -> Tensor<3> {
    let b = w.dims()[0];
    w.matmul(c.hat_map.clone()).reshape([b, 3, 3])
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
    /// L [B,3,3].
    pub l: Tensor<3>,
    /// J⁻¹ [B,3,3].
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

    /// The J⁻¹ head (for [`TModel::dh_dr_with`]).
    pub fn inertia_head(&self) -> &TMlp {
        &self.inertia
    }
}

/// The phase-space state integrated in training: (q, 𝔭) with p, R, 𝔭_v, 𝔭_ω kept apart.
#[derive(Clone, Debug)]
pub struct Phase {
    /// Position [B,3].
    pub p: Tensor<2>,
    /// Rotation [B,3,3].
    pub rot: Tensor<3>,
    /// Linear momentum 𝔭_v [B,3].
    pub pv: Tensor<2>,
    /// Angular momentum 𝔭_ω [B,3].
    pub pw: Tensor<2>,
}

impl Phase {
    fn axpy(&self, h: f32, d: &Phase) -> Phase {
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
    /// The realized control over CONTROL_SCALE [B,4]: u/CONTROL_SCALE, through the flight's
    /// rotor gains when they are learned.
    pub u_norm: Tensor<2>,
    /// a_j of each window [B,p].
    pub a: Tensor<2>,
    /// Each window's flight's rotor gain deviations δηⱼ [B,4] (None: not learned).
    pub rotor_gain: Option<Tensor<2>>,
}

impl Forcing {
    /// From the raw control [B,4] and the per-flight parameters [M,p] (the a_j) or [M,p+4]
    /// (the a_j, then the rotor gain deviations δηⱼ) with indices [B].
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

    /// The same a_j and rotor gains with another raw control [B,4] (the next step of a window).
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
fn realized(c: &Consts, u: Tensor<2>, rotor_gain: Option<&Tensor<2>>) -> Tensor<2> {
    let u_norm = u * c.control_inv_scale.clone();
    match rotor_gain {
        None => u_norm,
        Some(eta) => {
            let rotors = u_norm.clone().matmul(c.rotor_from_u.clone());
            u_norm + (rotors * eta.clone()).matmul(c.u_from_rotor.clone())
        }
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

    /// d/dt J⁻¹ along Ṙ (a JVP of the head), [B,3,3].
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

    /// ∂(½ 𝔭_ωᵀ J⁻¹(q) 𝔭_ω)/∂rᵢ at fixed 𝔭_ω, rows i, [B,3,3] (a VJP of the head).
    pub fn dh_dr(&self, c: &Consts, ev: &InertiaEval, pw: Tensor<2>) -> Tensor<3> {
        dh_dr_with(c, &self.inertia, ev, pw)
    }

    /// g(q) u as a body force and torque ([B,3] each), from u / CONTROL_SCALE.
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

    /// W(q) [B,6,p] (force rows m Rᵀ n_k, torque rows TORQUE_SCALE_NM t_k).
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

    /// d = W a as a body force and torque ([B,3] each).
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

impl Phase {
    /// x + h/6 (k₁ + 2 k₂ + 2 k₃ + k₄).
    fn rk4_combine(&self, k1: &Phase, k2: &Phase, k3: &Phase, k4: &Phase, dt_s: f32) -> Phase {
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

/// ∂(½ 𝔭_ωᵀ J⁻¹(q) 𝔭_ω)/∂rᵢ at fixed 𝔭_ω with the J⁻¹ head `head` ([`TModel::dh_dr`]).
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
fn control_wrench_from(c: &Consts, gain: Tensor<2>, u_norm: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let b = gain.dims()[0];
    let o = gain.reshape([b, 6, 4]);
    let gu = mat_vec_n(o, u_norm) * c.wrench_scale.clone();
    (gu.clone().narrow(1, 0, 3), gu.narrow(1, 3, 3))
}

/// d = W a as a body force and torque from the W head's raw output [B, 6p].
fn disturbance_from(
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
/// head, for the VJP): [`TModel::phase_rhs`].
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
/// [`TModel::rk4`] with J⁻¹(q), g(q), W(q) at the step's start computed once (they are also
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

/// ζ → 𝔭 with J⁻¹(q) known ([`TModel::to_phase`]).
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

/// 𝔭 → ζ with J⁻¹(q) known ([`TModel::velocities`]).
pub fn velocities_with(c: &Consts, ev: &InertiaEval, x: &Phase) -> (Tensor<2>, Tensor<2>) {
    (
        x.pv.clone().div_scalar(c.mass_kg),
        matvec(ev.jinv.clone(), x.pw.clone()),
    )
}

/// Inverse of a batch of 3×3 matrices [B,3,3] by cofactors (rows a, b, c:
/// A⁻¹ = [b×c | c×a | a×b] / a·(b×c)).
pub fn invert_sym3(m: Tensor<3>) -> Tensor<3> {
    let bsz = m.dims()[0];
    let row = |k: usize| m.clone().narrow(1, k, 1).reshape([bsz, 3]);
    let (a, b, c) = (row(0), row(1), row(2));
    let bc = b.clone().cross(c.clone(), 1);
    let ca = c.cross(a.clone(), 1);
    let ab = a.clone().cross(b, 1);
    let det = (a * bc.clone()).sum_dim(1); // [B,1]
                                           // Columns bc, ca, ab: stack as rows then transpose.
    let rows = Tensor::stack::<3>(vec![bc, ca, ab], 1); // [B,3(row=col index),3]
    rows.swap_dims(1, 2) / det.reshape([bsz, 1, 1])
}

/// The TSE(3) loss of a predicted window (paper Sec. 3): Σₙ ℓ_p + ℓ_R + `vel_weight`·ℓ_v + ℓ_ω
/// per window over the predicted states x₁..x_N against `b`'s, then the mean over the batch.
pub fn window_loss(
    preds: impl IntoIterator<Item = StateBatch>,
    b: &Batch,
    vel_weight: f32,
) -> Tensor<1> {
    let mut total: Option<Tensor<2>> = None;
    for (x, target) in preds.into_iter().zip(b.states.iter().skip(1)) {
        let lp = (x.p - target.p.clone()).square().sum_dim(1);
        let lr = rotation_loss(x.rot, target.rot.clone());
        let lz = (x.v - target.v.clone())
            .square()
            .sum_dim(1)
            .mul_scalar(vel_weight)
            + (x.w - target.w.clone()).square().sum_dim(1);
        let l = lp + lr + lz;
        total = Some(match total {
            Some(t) => t + l,
            None => l,
        });
    }
    total
        .unwrap_or_else(|| Tensor::zeros([1, 1], &b.realization.device()))
        .mean()
}

/// ‖log(R̄ Rᵀ)^∨‖² per window [B,1], from sin²θ = ‖vee(E)‖² by the series
/// θ² = s + s²/3 + 8 s³/45 (s = sin²θ), exact to O(θ⁸) and smooth at θ = 0, where acos is not;
/// prediction errors over a 5-state window are far below the quarter turn where it would matter.
pub fn rotation_loss(r_pred: Tensor<3>, r_true: Tensor<3>) -> Tensor<2> {
    let b = r_pred.dims()[0];
    let e = mat_mat_t(r_pred, r_true);
    let skew = (e.clone() - e.swap_dims(1, 2))
        .mul_scalar(0.5)
        .reshape([b, 9]);
    // ‖vee‖² = ½ Σ skew² (each component appears twice).
    let s = skew.square().sum_dim(1).mul_scalar(0.5);
    s.clone()
        + s.clone().square().div_scalar(3.0)
        + s.clone().square().mul(s).mul_scalar(8.0 / 45.0)
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
