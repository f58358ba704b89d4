//! The learned port-Hamiltonian model of the quadrotor (paper eq. 1 and 2): network shapes and
//! weights. With the mass known (paper Sec. 4), M(q) = diag(m I, J(q)) and V(q) = m g e₃ᵀ p; the
//! networks give J⁻¹(q), the input gain g(q) and the disturbance features W(q, 𝔭).

use crate::nn::Mlp;
use nalgebra::{Matrix3, SMatrix, Vector4};
use serde::{Deserialize, Serialize};

pub mod dynamics;
pub mod learned;
mod nominal;
pub mod port;
mod state;
pub use dynamics::{hamiltonian, rk4_step, StateDerivative};
pub use learned::LearnedModel;
pub use nominal::{true_input_gain, NominalModel, NOMINAL_TORQUE_FEATURE_NM};
pub use port::{ActuatorLag, PortError, PortTerms, PORT_PARAMS};
pub use state::State;

/// The stock CF2X's mass (kg): the default vehicle, and the mass of a version-1 weight blob.
/// A trained model carries its own vehicle's mass ([`ModelWeights::mass_kg`]); the mass is
/// known, not learned (paper Sec. 4).
pub const MASS_KG: f32 = 0.027;
/// The lightest vehicle mass (kg) a weight blob may carry.
pub const MIN_MASS_KG: f32 = 0.005;
/// The heaviest vehicle mass (kg) a weight blob may carry.
pub const MAX_MASS_KG: f32 = 5.0;
/// Gravitational acceleration (m/s²), as in the SITL plant and gym-pybullet-drones.
pub const GRAVITY_M_S2: f32 = 9.8;
/// The motors' first-order time constant (s) assumed for a model that does not carry its own
/// (the nominal model, and weight blobs of the format versions without the lag): such a model is
/// flown with this lag assumed.
pub const DEFAULT_MOTOR_TAU_S: f32 = 0.05;
/// The largest motor time constant a weight blob may carry (s): a first-order lag longer than
/// this is no quadrotor's motor (a Crazyflie's is 20–70 ms).
pub const MAX_MOTOR_TAU_S: f32 = 1.0;

/// What the controller needs of a model at one state, evaluated once per control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelTerms {
    /// Mass m (kg): M = diag(m I, J).
    pub mass_kg: f32,
    /// Gravity (m/s²) in V(q) = m g e₃ᵀ p.
    pub gravity_m_s2: f32,
    /// J⁻¹(q) (1/(kg·m²)), body frame.
    pub inertia_inv: Matrix3<f32>,
    /// The input gain g(q) ∈ ℝ⁶ˣ⁴: rows body force x, y, z then torque x, y, z; columns u = [f; τ].
    pub gain: SMatrix<f32, 6, 4>,
    /// The disturbance features W(q, 𝔭) ∈ ℝ⁶ˣᵖ (N and N·m per unit of a): d = W a.
    pub features: SMatrix<f32, 6, FEATURES>,
}

impl ModelTerms {
    /// All zeros: the terms before a model was evaluated.
    pub const ZERO: Self = Self {
        mass_kg: 0.0,
        gravity_m_s2: 0.0,
        inertia_inv: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        gain: SMatrix::<f32, 6, 4>::from_array_storage(nalgebra::ArrayStorage([[0.0; 6]; 4])),
        features: SMatrix::<f32, 6, FEATURES>::from_array_storage(nalgebra::ArrayStorage(
            [[0.0; 6]; FEATURES],
        )),
    };
}

/// A port-Hamiltonian model of the vehicle (paper eq. 1): learned
/// or nominal ([`NominalModel`]). The controller is written against this trait.
pub trait HamiltonianModel {
    /// M⁻¹, g and W at `state`.
    fn terms(&self, state: &State) -> ModelTerms;

    /// [`HamiltonianModel::terms`] written into `out`: the controller keeps the terms of its
    /// tick in place, so they need no room on the step's stack.
    fn write_terms(&self, state: &State, out: &mut ModelTerms) {
        *out = self.terms(state);
    }

    /// The vehicle's mass m (kg): what the gains scale with ([`crate::Gains::for_mass_kg`]).
    fn mass_kg(&self) -> f32 {
        self.terms(&State::default()).mass_kg
    }

    /// The vehicle's motor time constant (s), from the blob where it carries one, else
    /// [`DEFAULT_MOTOR_TAU_S`]: what the composite law's prediction and the attitude gains
    /// assume ([`crate::control::VehicleFacts`]).
    fn motor_tau_s(&self) -> f32 {
        DEFAULT_MOTOR_TAU_S
    }

    /// The dissipation, the learned potential, the gyrator and the input's gains and lags
    /// ([`PortTerms`]): the identity (the rigid body alone) unless the model carries its own.
    /// Constant: they do not depend on the state.
    fn port(&self) -> &PortTerms {
        &PortTerms::IDENTITY
    }

    /// The state derivative of paper eq. 1 (Hamilton's equations on SE(3)) and eq. 2 (ζ̇) under
    /// the control `u` = [f (N); τ (N·m)] and the disturbance d = W(q, 𝔭) `a`.
    ///
    /// The default assumes J does not depend on q (no ∂H/∂rᵢ, no d/dt J⁻¹), which is exact for
    /// [`NominalModel`]; [`LearnedModel`] adds both through its network's input Jacobians.
    fn dynamics(&self, state: &State, u: &Vector4<f32>, a: &[f32; FEATURES]) -> StateDerivative {
        dynamics::constant_inertia_dynamics(self, state, u, a)
    }
}

/// A borrowed model is a model: the controller can fly a `&'static LearnedModel` whose weights
/// stay in flash (a `static` built at compile time) instead of a 10 KB copy in RAM.
impl<M: HamiltonianModel + ?Sized> HamiltonianModel for &M {
    fn terms(&self, state: &State) -> ModelTerms {
        (**self).terms(state)
    }

    fn write_terms(&self, state: &State, out: &mut ModelTerms) {
        (**self).write_terms(state, out)
    }

    fn mass_kg(&self) -> f32 {
        (**self).mass_kg()
    }

    fn motor_tau_s(&self) -> f32 {
        (**self).motor_tau_s()
    }

    fn port(&self) -> &PortTerms {
        (**self).port()
    }

    fn dynamics(&self, state: &State, u: &Vector4<f32>, a: &[f32; FEATURES]) -> StateDerivative {
        (**self).dynamics(state, u, a)
    }
}

/// Width of every hidden layer. A performance knob: the whole control step must fit the MCU budget.
pub const HIDDEN: usize = 16;
/// Number of disturbance features p (columns of W).
pub const FEATURES: usize = 6;

/// Inputs of the J⁻¹ head: the rows r₁, r₂, r₃ of R.
pub const JINV_IN: usize = 9;
/// Outputs of the J⁻¹ head: the 6 entries of a lower-triangular L (J⁻¹ = L Lᵀ + εI).
pub const JINV_OUT: usize = 6;
/// Inputs of the input-gain network: the rows of R (g does not depend on position).
pub const GAIN_IN: usize = 9;
/// Outputs of the input-gain network: g(q) ∈ ℝ⁶ˣ⁴, row-major.
pub const GAIN_OUT: usize = 24;
/// Inputs of the disturbance-feature network: the rows of R. The paper's W(q, 𝔭) also sees the
/// momentum; the disturbances this model is trained on (wind, weak rotors) do not depend on it,
/// and with velocity inputs the network fitted spurious velocity dependence that cost the adaptive
/// controller 3× in tracking on paper-spiral (docs/math.md, "Difference from the paper").
pub const DIST_IN: usize = 9;
/// Outputs of the disturbance-feature network: W ∈ ℝ⁶ˣᵖ, row-major.
pub const DIST_OUT: usize = 6 * FEATURES;

/// The J⁻¹(q) network.
pub type InertiaNet = Mlp<JINV_IN, HIDDEN, JINV_OUT>;
/// The g(q) network.
pub type GainNet = Mlp<GAIN_IN, HIDDEN, GAIN_OUT>;
/// The W(q, 𝔭) network.
pub type DisturbanceNet = Mlp<DIST_IN, HIDDEN, DIST_OUT>;

/// What the weight blob carries: the vehicle's known mass and all learned parameters θ (J⁻¹, g)
/// and φ (W).
///
/// `repr(C)`, fields in blob order: its memory is the mass then every network parameter in
/// [`ModelWeights::params_mut`] order, f32 each with no padding ([`ModelWeights::BYTES`]), the
/// order of the blob's body after its motor lag and port terms. A firmware may therefore decode
/// a blob in place by moving the parameter bytes (`hf_model_load` of the Bitcraze app).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[repr(C)]
pub struct ModelWeights {
    /// The vehicle's mass m (kg), known and given at training (paper Sec. 4: M = diag(m I, J)).
    /// One firmware image flies any vehicle: the controller's gains and the W force columns scale
    /// with it.
    pub mass_kg: f32,
    /// θ: the inverse-inertia head.
    pub inertia: InertiaNet,
    /// θ: the input gain.
    pub gain: GainNet,
    /// φ: the disturbance features.
    pub disturbance: DisturbanceNet,
}

const _: () = {
    assert!(core::mem::size_of::<ModelWeights>() == ModelWeights::BYTES);
    assert!(core::mem::align_of::<ModelWeights>() == core::mem::align_of::<f32>());
};

impl Default for ModelWeights {
    /// All-zero networks on the stock vehicle's mass ([`MASS_KG`]).
    fn default() -> Self {
        Self {
            mass_kg: MASS_KG,
            ..Self::ZERO
        }
    }
}

impl ModelWeights {
    /// The network shapes in blob-header order: J⁻¹, g, W, each `[inputs, hidden, outputs]`.
    pub const DIMS: [[u16; 3]; 3] = [InertiaNet::DIMS, GainNet::DIMS, DisturbanceNet::DIMS];

    /// Total multiply–adds of one forward pass of the three networks.
    pub const MACS: usize = InertiaNet::MACS + GainNet::MACS + DisturbanceNet::MACS;

    /// Number of parameters (f32) of the three networks.
    pub const PARAMS: usize = InertiaNet::PARAMS + GainNet::PARAMS + DisturbanceNet::PARAMS;

    /// Size in memory: the mass and [`ModelWeights::PARAMS`] f32s, no padding (asserted).
    pub const BYTES: usize = 4 * (1 + Self::PARAMS);

    /// Every bit zero, the mass too: a place to decode a blob into ([`crate::blob::decode_into`]
    /// sets every field), not a model to fly. All-zero keeps a `static` of it in `.bss`; a
    /// non-zero mass would put a 10 KB initializer image in flash.
    pub const ZERO: Self = Self {
        mass_kg: 0.0,
        inertia: Mlp::ZERO,
        gain: Mlp::ZERO,
        disturbance: Mlp::ZERO,
    };

    /// True if every parameter is finite.
    pub fn is_finite(&self) -> bool {
        self.mass_kg.is_finite()
            && self.inertia.is_finite()
            && self.gain.is_finite()
            && self.disturbance.is_finite()
    }

    /// True if the mass is one a blob may carry: in [[`MIN_MASS_KG`], [`MAX_MASS_KG`]].
    pub fn mass_is_valid(&self) -> bool {
        (MIN_MASS_KG..=MAX_MASS_KG).contains(&self.mass_kg)
    }

    /// Every network parameter in blob order (after the mass): J⁻¹, g, W networks, each as
    /// [`Mlp::params_mut`].
    pub fn params_mut(&mut self) -> impl Iterator<Item = &mut f32> {
        self.inertia
            .params_mut()
            .chain(self.gain.params_mut())
            .chain(self.disturbance.params_mut())
    }
}

#[cfg(test)]
mod tests {
    use super::ModelWeights;

    /// The memory of [`ModelWeights`] is the mass then the parameters in `params_mut()` order.
    #[test]
    fn weights_memory_is_the_mass_then_the_params_in_blob_order() {
        let mut w = ModelWeights::ZERO;
        w.mass_kg = -1.0;
        for (i, p) in w.params_mut().enumerate() {
            *p = i as f32;
        }
        assert_eq!(core::mem::size_of_val(&w), ModelWeights::BYTES);
        // SAFETY: `w` is `BYTES` bytes of f32s (asserted above and at compile time), aligned for
        // f32, and only read while the slice lives.
        let mem = unsafe {
            core::slice::from_raw_parts(
                (&w as *const ModelWeights).cast::<f32>(),
                1 + ModelWeights::PARAMS,
            )
        };
        assert_eq!(mem[0], -1.0);
        for (i, v) in mem[1..].iter().enumerate() {
            assert_eq!(*v, i as f32, "parameter {i}");
        }
    }
}
