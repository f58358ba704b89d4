//! The learned port-Hamiltonian model of the quadrotor (paper eq. 1 and 2): network shapes and
//! weights. With the mass known (paper Sec. 4), M(q) = diag(m I, J(q)) and V(q) = m g e₃ᵀ p; the
//! networks give J⁻¹(q), the input gain g(q) and the disturbance features W(q, 𝔭).

use crate::nn::Mlp;
use serde::{Deserialize, Serialize};

mod state;
pub use state::State;

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
/// Inputs of the disturbance-feature network: the rows of R and the scaled body velocities ζ.
pub const DIST_IN: usize = 15;
/// Outputs of the disturbance-feature network: W ∈ ℝ⁶ˣᵖ, row-major.
pub const DIST_OUT: usize = 6 * FEATURES;

/// The J⁻¹(q) network.
pub type InertiaNet = Mlp<JINV_IN, HIDDEN, JINV_OUT>;
/// The g(q) network.
pub type GainNet = Mlp<GAIN_IN, HIDDEN, GAIN_OUT>;
/// The W(q, 𝔭) network.
pub type DisturbanceNet = Mlp<DIST_IN, HIDDEN, DIST_OUT>;

/// All learned parameters θ (J⁻¹, g) and φ (W): what the weight blob carries.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct ModelWeights {
    /// θ: the inverse-inertia head.
    pub inertia: InertiaNet,
    /// θ: the input gain.
    pub gain: GainNet,
    /// φ: the disturbance features.
    pub disturbance: DisturbanceNet,
}

impl ModelWeights {
    /// The network shapes in blob-header order: J⁻¹, g, W, each `[inputs, hidden, outputs]`.
    pub const DIMS: [[u16; 3]; 3] = [InertiaNet::DIMS, GainNet::DIMS, DisturbanceNet::DIMS];

    /// Total multiply–adds of one forward pass of the three networks.
    pub const MACS: usize = InertiaNet::MACS + GainNet::MACS + DisturbanceNet::MACS;

    /// True if every parameter is finite.
    pub fn is_finite(&self) -> bool {
        self.inertia.is_finite() && self.gain.is_finite() && self.disturbance.is_finite()
    }
}
