//! The learned model: J⁻¹(q), g(q) and W(q, 𝔭) from the three small MLPs of [`ModelWeights`]
//! (paper Sec. 3, "Hamiltonian-based dynamics learning with disturbances").
//!
//! Every scale and normalization the networks see is a named constant here, so that the host
//! training code (`host-train`'s `train::model`) and the firmware use exactly the same maps:
//!
//! - **J⁻¹ head** (paper's M⁻¹ with the mass known): the 9 inputs are the rows r₁, r₂, r₃ of R
//!   (already of order one); the 6 outputs are the entries `[l₁₁, l₂₁, l₂₂, l₃₁, l₃₂, l₃₃]` of a
//!   lower-triangular L, and J⁻¹ = [`INERTIA_INV_SCALE_PER_KG_M2`] · (L Lᵀ + [`INERTIA_INV_EPS`] I),
//!   symmetric positive definite for every weight.
//! - **g head**: inputs the rows of R; output o (6×4 row-major) gives
//!   g_ik = o_ik · [`WRENCH_SCALE`]ᵢ / [`CONTROL_SCALE`]ₖ, so that every output is dimensionless
//!   and of order one (the true g has o = identity pattern).
//! - **W head**: inputs the rows of R (see [`super::DIST_IN`] for why not 𝔭); output o (6×p) holds, per
//!   feature k, a world-frame specific force n_k = o\[0..3\]\[k\] (m/s² per unit of aₖ) and a body
//!   torque t_k = o\[3..6\]\[k\] (units of [`TORQUE_SCALE_NM`]). The feature column is
//!   W[:, k] = [m Rᵀ n_k; TORQUE_SCALE_NM · t_k]: wind, a world-fixed force, is then linear in a
//!   at every attitude, and so extrapolates to winds larger than in training.

use super::{
    DisturbanceNet, HamiltonianModel, ModelTerms, ModelWeights, PortTerms, State, StateDerivative,
    DEFAULT_MOTOR_TAU_S, FEATURES, GAIN_IN, GAIN_OUT, GRAVITY_M_S2, JINV_OUT, MASS_KG,
};
use crate::blob::{self, BlobError};
use nalgebra::{Matrix3, SMatrix, Vector3, Vector4};

/// Scale s_J of the J⁻¹ head (1/(kg·m²)): J⁻¹ = s_J (L Lᵀ + ε I). The CF2X's J⁻¹ is
/// diag(7.1e4, 7.1e4, 4.6e4), so L's diagonal is of order one.
pub const INERTIA_INV_SCALE_PER_KG_M2: f32 = 1.0e5;
/// ε of the J⁻¹ head (dimensionless): keeps J⁻¹ ≥ s_J ε I, i.e. J ≤ 1/(s_J ε) = 1e-3 kg·m².
pub const INERTIA_INV_EPS: f32 = 1.0e-2;
/// Force scale (N) of the normalized wrench: the stock vehicle's hover thrust m g. A fixed
/// normalization of the networks' inputs and outputs, the same for every vehicle mass.
pub const FORCE_SCALE_N: f32 = MASS_KG * GRAVITY_M_S2;
/// Torque scale (N·m) of the normalized wrench and of the torque rows of W.
pub const TORQUE_SCALE_NM: f32 = 1.0e-3;
/// Scale of each row of g (and of the generalized force): body force x, y, z (N), torque x, y, z (N·m).
pub const WRENCH_SCALE: [f32; 6] = [
    FORCE_SCALE_N,
    FORCE_SCALE_N,
    FORCE_SCALE_N,
    TORQUE_SCALE_NM,
    TORQUE_SCALE_NM,
    TORQUE_SCALE_NM,
];
/// Scale of each control input u = [f (N); τ (N·m)]: a column of g.
pub const CONTROL_SCALE: [f32; 4] = [
    FORCE_SCALE_N,
    TORQUE_SCALE_NM,
    TORQUE_SCALE_NM,
    TORQUE_SCALE_NM,
];

/// The learned Hamiltonian model: the networks θ (J⁻¹, g) and φ (W) of a weight blob, and the
/// vehicle's motor lag the blob carries.
///
/// `repr(C)` with the weights first: [`ModelWeights`]'s memory (the mass, then the parameters in
/// blob order) starts at offset 0, which in-place decoding relies on.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct LearnedModel {
    /// The learned parameters.
    pub weights: ModelWeights,
    /// The motor time constant's f32 bits XOR those of [`DEFAULT_MOTOR_TAU_S`]: zero bits are
    /// the default lag, so [`LearnedModel::new`] of [`ModelWeights::ZERO`] stays all-zero (a
    /// `static` of it in `.bss`, not a 10 KB initializer in flash), and any lag round-trips
    /// exactly ([`LearnedModel::motor_tau_s`], [`LearnedModel::with_motor_tau_s`]).
    motor_tau_bits: u32,
    /// The dissipation, the learned potential and the input's gains and lags (all zero: the
    /// rigid body alone, [`PortTerms::IDENTITY`]).
    port: PortTerms,
}

const _: () = assert!(core::mem::offset_of!(LearnedModel, weights) == 0);

impl LearnedModel {
    /// Wraps trained weights, with the default motor lag ([`DEFAULT_MOTOR_TAU_S`]).
    pub const fn new(weights: ModelWeights) -> Self {
        Self {
            weights,
            motor_tau_bits: 0,
            port: PortTerms::IDENTITY,
        }
    }

    /// The same model on a vehicle whose motors have the first-order time constant
    /// `motor_tau_s` (s): the lag the composite law's prediction assumes. The blob's value is
    /// checked at decode (in [0, [`crate::model::MAX_MOTOR_TAU_S`]] s).
    #[must_use]
    pub const fn with_motor_tau_s(self, motor_tau_s: f32) -> Self {
        Self {
            motor_tau_bits: motor_tau_s.to_bits() ^ DEFAULT_MOTOR_TAU_S.to_bits(),
            ..self
        }
    }

    /// The same model with the port terms `port` (dissipation, potential, input gains and lags;
    /// checked at decode by [`PortTerms::validate`]).
    #[must_use]
    pub const fn with_port(self, port: PortTerms) -> Self {
        Self { port, ..self }
    }

    /// [`LearnedModel::with_port`] in place (no 10 KB copy on the stack: for in-place decoding).
    pub fn set_port(&mut self, port: PortTerms) {
        self.port = port;
    }

    /// [`LearnedModel::with_motor_tau_s`] in place (no 10 KB copy on the stack).
    pub fn set_motor_tau_s(&mut self, motor_tau_s: f32) {
        self.motor_tau_bits = motor_tau_s.to_bits() ^ DEFAULT_MOTOR_TAU_S.to_bits();
    }

    /// Decodes and checks a weight blob ([`blob::decode_model_into`]): the networks, the mass
    /// and the motor lag (the default for blobs before format version 3).
    ///
    /// # Errors
    /// Any [`BlobError`] of [`blob::decode`].
    pub fn from_blob(bytes: &[u8]) -> Result<Self, BlobError> {
        let mut out = Self::new(ModelWeights::ZERO);
        blob::decode_model_into(bytes, &mut out)?;
        Ok(out)
    }

    /// J⁻¹(q) (1/(kg·m²)), body frame.
    #[inline(never)]
    pub fn inertia_inv(&self, rot: &Matrix3<f32>) -> Matrix3<f32> {
        inertia_inv_from_l(&self.weights.inertia.forward(&rot_input(rot)))
    }

    /// g(q) ∈ ℝ⁶ˣ⁴ (rows body force then torque, columns u = [f; τ]).
    pub fn gain(&self, rot: &Matrix3<f32>) -> SMatrix<f32, 6, 4> {
        let mut g = SMatrix::zeros();
        self.write_gain(rot, &mut g);
        g
    }

    /// [`LearnedModel::gain`] written into `g`.
    #[inline(never)]
    fn write_gain(&self, rot: &Matrix3<f32>, g: &mut SMatrix<f32, 6, 4>) {
        write_gain_from_output(&self.weights.gain.forward(&rot_input(rot)), g);
    }

    /// W(q, 𝔭) ∈ ℝ⁶ˣᵖ at `state` (N, N·m per unit of a).
    pub fn features(&self, state: &State) -> SMatrix<f32, 6, FEATURES> {
        let mut w = SMatrix::zeros();
        self.write_features(state, &mut w);
        w
    }

    /// [`LearnedModel::features`] written into `w`.
    #[inline(never)]
    fn write_features(&self, state: &State, w: &mut SMatrix<f32, 6, FEATURES>) {
        // The head's row-major 6×p output goes straight into w's storage, which read
        // column-major is its transpose (p = 6); transposed back in place, then scaled.
        let x = disturbance_input(state);
        let Ok(flat) = <&mut [f32; super::DIST_OUT]>::try_from(w.as_mut_slice()) else {
            return;
        };
        self.weights.disturbance.forward_into(&x, flat);
        w.transpose_mut();
        scale_features(&state.rot, self.weights.mass_kg, w);
    }

    /// The J⁻¹ head with the two input Jacobians the dynamics need (paper eq. 1 and 2):
    /// returns `(J⁻¹, d/dt J⁻¹ along q̇, [∂H/∂r₁, ∂H/∂r₂, ∂H/∂r₃])`, where the last is
    /// ∂(½ 𝔭_ωᵀ J⁻¹(q) 𝔭_ω)/∂rᵢ at fixed momentum `p_w` (a VJP through the net) and the
    /// second is the JVP of J⁻¹ along `rot_dot` (Ṙ, whose rows are ṙᵢ).
    pub fn inertia_inv_jacobians(
        &self,
        rot: &Matrix3<f32>,
        rot_dot: &Matrix3<f32>,
        p_w: &Vector3<f32>,
    ) -> (Matrix3<f32>, Matrix3<f32>, [Vector3<f32>; 3]) {
        let x = rot_input(rot);
        let dx = rot_input(rot_dot);
        let (l, dl) = self.weights.inertia.jvp(&x, &dx);
        let lm = l_matrix(&l);
        let dlm = l_matrix(&dl);
        let s = INERTIA_INV_SCALE_PER_KG_M2;
        let jinv = inertia_inv_from_l(&l);
        let djinv = (dlm * lm.transpose() + lm * dlm.transpose()) * s;
        // H_ω = ½ s |Lᵀ𝔭|² + ½ s ε |𝔭|², so ∂H/∂L_ab = s 𝔭_a (Lᵀ𝔭)_b.
        let y = lm.transpose() * p_w;
        let dh_dl = [
            s * p_w.x * y.x,
            s * p_w.y * y.x,
            s * p_w.y * y.y,
            s * p_w.z * y.x,
            s * p_w.z * y.y,
            s * p_w.z * y.z,
        ];
        let (_, dh_dx) = self.weights.inertia.vjp(&x, &dh_dl);
        let [a0, a1, a2, b0, b1, b2, c0, c1, c2] = dh_dx;
        (
            jinv,
            djinv,
            [
                Vector3::new(a0, a1, a2),
                Vector3::new(b0, b1, b2),
                Vector3::new(c0, c1, c2),
            ],
        )
    }
}

impl HamiltonianModel for LearnedModel {
    fn mass_kg(&self) -> f32 {
        self.weights.mass_kg
    }

    /// The blob's port terms ([`LearnedModel::with_port`]).
    fn port(&self) -> &PortTerms {
        &self.port
    }

    /// The blob's motor lag ([`LearnedModel::with_motor_tau_s`]).
    fn motor_tau_s(&self) -> f32 {
        f32::from_bits(self.motor_tau_bits ^ DEFAULT_MOTOR_TAU_S.to_bits())
    }

    fn terms(&self, state: &State) -> ModelTerms {
        ModelTerms {
            mass_kg: self.weights.mass_kg,
            gravity_m_s2: GRAVITY_M_S2,
            inertia_inv: self.inertia_inv(&state.rot),
            gain: self.gain(&state.rot),
            features: self.features(state),
        }
    }

    /// One head at a time, each out of line and written in place, so that only one head's
    /// activations are on the stack at once.
    fn write_terms(&self, state: &State, out: &mut ModelTerms) {
        out.mass_kg = self.weights.mass_kg;
        out.gravity_m_s2 = GRAVITY_M_S2;
        out.inertia_inv = self.inertia_inv(&state.rot);
        self.write_gain(&state.rot, &mut out.gain);
        self.write_features(state, &mut out.features);
    }

    /// Paper eq. 1 and 2 with the learned J⁻¹(q): ∂H/∂rᵢ and d/dt J⁻¹ come from the network's
    /// input Jacobians ([`LearnedModel::inertia_inv_jacobians`]).
    fn dynamics(&self, state: &State, u: &Vector4<f32>, a: &[f32; FEATURES]) -> StateDerivative {
        let rot_dot = state.rot * crate::lie::hat(&state.w_body_rad_s);
        let x = rot_input(&state.rot);
        let jinv0 = inertia_inv_from_l(&self.weights.inertia.forward(&x));
        // 𝔭_ω = J ω; J⁻¹ ≥ s_J ε I is always invertible for finite weights.
        let j = jinv0.try_inverse().unwrap_or_else(Matrix3::zeros);
        let p_w = j * state.w_body_rad_s;
        let (jinv, djinv_dt, dh_dr) = self.inertia_inv_jacobians(&state.rot, &rot_dot, &p_w);
        let terms = ModelTerms {
            mass_kg: self.weights.mass_kg,
            gravity_m_s2: GRAVITY_M_S2,
            inertia_inv: jinv,
            gain: self.gain(&state.rot),
            features: self.features(state),
        };
        super::dynamics::hamilton_dynamics(state, &terms, &self.port, &p_w, &dh_dr, &djinv_dt, u, a)
    }
}

/// The rows r₁, r₂, r₃ of R, concatenated: the J⁻¹ and g heads' input.
#[inline]
pub fn rot_input(rot: &Matrix3<f32>) -> [f32; 9] {
    [
        rot.m11, rot.m12, rot.m13, rot.m21, rot.m22, rot.m23, rot.m31, rot.m32, rot.m33,
    ]
}

/// The W head's input: the rows of R (the same as the J⁻¹ and g heads').
#[inline]
pub fn disturbance_input(state: &State) -> [f32; super::DIST_IN] {
    rot_input(&state.rot)
}

/// The lower-triangular L from the head's outputs `[l₁₁, l₂₁, l₂₂, l₃₁, l₃₂, l₃₃]`.
#[inline]
pub fn l_matrix(l: &[f32; JINV_OUT]) -> Matrix3<f32> {
    let [l0, l1, l2, l3, l4, l5] = *l;
    Matrix3::new(l0, 0.0, 0.0, l1, l2, 0.0, l3, l4, l5)
}

/// J⁻¹ = s_J (L Lᵀ + ε I) from the head's outputs.
#[inline]
pub fn inertia_inv_from_l(l: &[f32; JINV_OUT]) -> Matrix3<f32> {
    let lm = l_matrix(l);
    (lm * lm.transpose() + Matrix3::identity() * INERTIA_INV_EPS) * INERTIA_INV_SCALE_PER_KG_M2
}

/// WRENCH_SCALEᵢ / CONTROL_SCALEₖ, the factor [`gain_from_output`] applies to o_ik: 1 where
/// the row and the column have the same unit (the multiply is then exact and folds away), the
/// ratio of the force and torque scales elsewhere.
const GAIN_FACTOR: [[f32; 4]; 6] = {
    let mut f = [[0.0; 4]; 6];
    let mut i = 0;
    while i < 6 {
        let mut k = 0;
        while k < 4 {
            f[i][k] = WRENCH_SCALE[i] / CONTROL_SCALE[k];
            k += 1;
        }
        i += 1;
    }
    f
};

/// g from the gain head's output (row-major 6×4): g_ik = o_ik · (WRENCH_SCALEᵢ / CONTROL_SCALEₖ).
pub fn gain_from_output(out: &[f32; GAIN_OUT]) -> SMatrix<f32, 6, 4> {
    let mut g = SMatrix::<f32, 6, 4>::zeros();
    write_gain_from_output(out, &mut g);
    g
}

/// [`gain_from_output`] written into `g`.
fn write_gain_from_output(out: &[f32; GAIN_OUT], g: &mut SMatrix<f32, 6, 4>) {
    let rows = out.chunks_exact(4).zip(GAIN_FACTOR.iter()).enumerate();
    for (i, (row, factors)) in rows {
        for (k, (o, f)) in row.iter().zip(factors.iter()).enumerate() {
            if let Some(e) = g.get_mut((i, k)) {
                *e = o * f;
            }
        }
    }
}

/// W from the feature head's output (row-major 6×p): column k = [m Rᵀ n_k; TORQUE_SCALE_NM t_k],
/// with m the vehicle's mass (kg).
pub fn features_from_output(
    rot: &Matrix3<f32>,
    out: &[f32; super::DIST_OUT],
    mass_kg: f32,
) -> SMatrix<f32, 6, FEATURES> {
    let mut w = SMatrix::from_row_slice(out);
    scale_features(rot, mass_kg, &mut w);
    w
}

/// The head's output (as a 6×p matrix) into W in place: force rows m Rᵀ n_k, torque rows
/// TORQUE_SCALE_NM t_k.
fn scale_features(rot: &Matrix3<f32>, mass_kg: f32, w: &mut SMatrix<f32, 6, FEATURES>) {
    let rt = rot.transpose();
    for mut col in w.column_iter_mut() {
        let force = rt * col.fixed_rows::<3>(0) * mass_kg;
        col.fixed_rows_mut::<3>(0).copy_from(&force);
        let torque = col.fixed_rows::<3>(3) * TORQUE_SCALE_NM;
        col.fixed_rows_mut::<3>(3).copy_from(&torque);
    }
}

/// The output-layer bias that makes W equal the nominal features at initialization: feature k
/// is a world force along e_k (k < 3) or a body torque along e_(k−3), cycling for p > 6.
pub fn nominal_feature_bias() -> [f32; super::DIST_OUT] {
    let mut b = [0.0; super::DIST_OUT];
    for k in 0..FEATURES {
        let row = k % 6;
        if let Some(v) = b.get_mut(row * FEATURES + k) {
            *v = 1.0;
        }
    }
    b
}

/// The gain head's output for the true g (the identity pattern of docs/math.md, "State, frames
/// and units", normalized).
pub fn true_gain_output() -> [f32; GAIN_OUT] {
    let g = super::true_input_gain();
    let mut out = [0.0; GAIN_OUT];
    for (n, o) in out.iter_mut().enumerate() {
        let (i, k) = (n / 4, n % 4);
        let scale = WRENCH_SCALE.get(i).copied().unwrap_or(1.0)
            / CONTROL_SCALE.get(k).copied().unwrap_or(1.0);
        *o = g.get((i, k)).copied().unwrap_or(0.0) / scale;
    }
    out
}

/// The J⁻¹ head's output L (diagonal) whose J⁻¹ equals `inertia_kg_m2`'s inverse for a diagonal
/// inertia; used to initialize training at the physical prior.
pub fn l_for_diagonal_inertia(inertia_kg_m2: &Vector3<f32>) -> [f32; JINV_OUT] {
    let d = |j: f32| {
        let x = 1.0 / (j * INERTIA_INV_SCALE_PER_KG_M2) - INERTIA_INV_EPS;
        libm::sqrtf(x.max(0.0))
    };
    [
        d(inertia_kg_m2.x),
        0.0,
        d(inertia_kg_m2.y),
        0.0,
        0.0,
        d(inertia_kg_m2.z),
    ]
}

/// The normalized feature output o(hover) (6×p, rows world force x, y, z then body torque
/// x, y, z) at R = I, v = ω = 0.
fn hover_feature_output(net: &DisturbanceNet) -> SMatrix<f32, 6, FEATURES> {
    let hover = State::default();
    SMatrix::<f32, 6, FEATURES>::from_row_slice(&net.forward(&disturbance_input(&hover)))
}

/// The basis change T that makes the features equal the nominal ones at hover: o(hover) T = I,
/// i.e. T = o(hover)⁻¹; `None` if o(hover) is singular or ill-conditioned.
///
/// Adapting a' in W' = W T is the paper's adaptation law with the constant gain matrix
/// Γ = T Tᵀ on a (ȧ = Γ Wᵀ s): the same Lyapunov argument holds for any Γ ≻ 0. It matters
/// because the learned columns mix force and torque at very different scales; in the nominal
/// basis each rate (c_p, c_v on force rows, c_R, c_ω on torque rows) acts on its own block.
pub fn hover_feature_basis(net: &DisturbanceNet) -> Option<SMatrix<f32, FEATURES, FEATURES>> {
    let o = hover_feature_output(net);
    let sv = o.singular_values();
    let (lo, hi) = sv
        .iter()
        .fold((f32::MAX, 0.0f32), |(lo, hi), s| (lo.min(*s), hi.max(*s)));
    if !(lo.is_finite() && hi.is_finite()) || lo <= 1e-3 * hi {
        return None;
    }
    o.try_inverse()
}

impl ModelWeights {
    /// The same model with the feature basis changed by `t` (W' = W T), folded into the W head's
    /// output layer so inference costs nothing more. Weights a for `self` become T⁻¹ a.
    pub fn with_feature_basis(&self, t: &SMatrix<f32, FEATURES, FEATURES>) -> Self {
        let mut out = *self;
        let l2 = &self.disturbance.l2;
        let new = &mut out.disturbance.l2;
        // Output row (i, j) of o' = o T is Σ_k T[k, j] · row (i, k).
        for i in 0..6 {
            for j in 0..FEATURES {
                let Some(dst) = new.weight.get_mut(i * FEATURES + j) else {
                    continue;
                };
                let mut b = 0.0;
                dst.iter_mut().for_each(|v| *v = 0.0);
                for k in 0..FEATURES {
                    let c = t[(k, j)];
                    if let (Some(src), Some(bias)) = (
                        l2.weight.get(i * FEATURES + k),
                        l2.bias.get(i * FEATURES + k),
                    ) {
                        dst.iter_mut()
                            .zip(src.iter())
                            .for_each(|(d, s)| *d += c * s);
                        b += c * bias;
                    }
                }
                if let Some(v) = new.bias.get_mut(i * FEATURES + j) {
                    *v = b;
                }
            }
        }
        out
    }

    /// The same model with the learned features kept only in the span of `p` (a projector on
    /// ℝᵖ, in the features' own basis) and the nominal features elsewhere:
    /// W' = W P + W_nominal (I − P) at every state, exactly (folded into the output layer like
    /// [`ModelWeights::with_feature_basis`]). For features whose training flights excited only
    /// some directions of a: W is identified only along the a_j (the loss sees W a_j alone).
    pub fn with_features_in_subspace(&self, p: &SMatrix<f32, FEATURES, FEATURES>) -> Self {
        let mut out = self.with_feature_basis(p);
        let nominal = SMatrix::<f32, 6, FEATURES>::from_row_slice(&nominal_feature_bias());
        let rest = nominal * (SMatrix::<f32, FEATURES, FEATURES>::identity() - p);
        for (k, b) in out.disturbance.l2.bias.iter_mut().enumerate() {
            *b += rest
                .get((k / FEATURES, k % FEATURES))
                .copied()
                .unwrap_or(0.0);
        }
        out
    }

    /// The same model with the features pulled toward the nominal ones by `keep` ∈ [0, 1]:
    /// W' = keep · W + (1 − keep) · W_nominal at every state, exactly, since the nominal
    /// features are the W head's constant output [`nominal_feature_bias`] (folded into the
    /// output layer, so inference costs nothing more). `keep` = 1 is `self`, 0 the nominal
    /// features; values outside [0, 1] are clamped. What the trainer backs off to when the
    /// learned features do not fly (`host-train train`, docs/training.md).
    pub fn with_features_toward_nominal(&self, keep: f32) -> Self {
        let keep = if keep.is_nan() {
            0.0
        } else {
            keep.clamp(0.0, 1.0)
        };
        let mut out = *self;
        let l2 = &mut out.disturbance.l2;
        l2.weight
            .iter_mut()
            .flat_map(|row| row.iter_mut())
            .for_each(|v| *v *= keep);
        for (b, n) in l2.bias.iter_mut().zip(nominal_feature_bias()) {
            *b = keep * *b + (1.0 - keep) * n;
        }
        out
    }
}

const _: () = assert!(GAIN_IN == 9 && JINV_OUT == 6 && GAIN_OUT == 24);
const _: () = assert!(DisturbanceNet::DIMS[2] as usize == 6 * FEATURES);

impl ModelWeights {
    /// The physical prior as weights: every hidden weight zero, output biases set so that J⁻¹ is
    /// the CF2X's, g the true input gain and W the nominal features (a world force along e_k, a
    /// body torque along e_k). Training starts near this point.
    pub fn prior() -> Self {
        Self::prior_with_inertia(&Vector3::new(1.4e-5, 1.4e-5, 2.17e-5))
    }

    /// [`ModelWeights::prior`] with J = diag(`inertia_kg_m2`) instead of the CF2X's: the prior
    /// of a described vehicle.
    pub fn prior_with_inertia(inertia_kg_m2: &Vector3<f32>) -> Self {
        let mut w = Self::default();
        w.inertia.l2.bias = l_for_diagonal_inertia(inertia_kg_m2);
        w.gain.l2.bias = true_gain_output();
        w.disturbance.l2.bias = nominal_feature_bias();
        w
    }
}

#[cfg(test)]
mod tests;
