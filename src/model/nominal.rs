//! The nominal model: the vehicle's true constants, no learned parts, hand-chosen disturbance
//! features (a constant world-frame force and a constant body torque). The classic geometric
//! adaptive baseline, and the model the baselines use.

use super::{HamiltonianModel, ModelTerms, State, FEATURES, GRAVITY_M_S2, MASS_KG};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// Scale of the torque features (N·m per unit of a): a body torque of 1e-3 N·m is a large
/// disturbance for a Crazyflie, so the torque weights stay of order one.
pub const NOMINAL_TORQUE_FEATURE_NM: f32 = 1e-3;

/// The true-constant model of the CF2X (docs/design.md, "The vehicle").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NominalModel {
    /// Mass (kg).
    pub mass_kg: f32,
    /// Body-frame inertia J (kg·m²).
    pub inertia_kg_m2: Matrix3<f32>,
    /// J⁻¹, cached.
    inertia_inv: Matrix3<f32>,
}

impl Default for NominalModel {
    fn default() -> Self {
        Self::new(
            MASS_KG,
            Matrix3::from_diagonal(&Vector3::new(1.4e-5, 1.4e-5, 2.17e-5)),
        )
    }
}

impl NominalModel {
    /// A nominal model with the given mass (kg) and inertia (kg·m²). A singular inertia falls back
    /// to the CF2X's.
    pub fn new(mass_kg: f32, inertia_kg_m2: Matrix3<f32>) -> Self {
        let fallback =
            Matrix3::from_diagonal(&Vector3::new(1.0 / 1.4e-5, 1.0 / 1.4e-5, 1.0 / 2.17e-5));
        Self {
            mass_kg,
            inertia_kg_m2,
            inertia_inv: inertia_kg_m2.try_inverse().unwrap_or(fallback),
        }
    }
}

impl HamiltonianModel for NominalModel {
    fn mass_kg(&self) -> f32 {
        self.mass_kg
    }

    fn terms(&self, state: &State) -> ModelTerms {
        // Features: columns 0–2 a world-fixed force m·e_k seen in the body frame (Rᵀ e_k), so
        // a₀..₂ read as a specific force in m/s²; columns 3–5 a body torque along e_k.
        let mut features = SMatrix::<f32, 6, FEATURES>::zeros();
        features
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(state.rot.transpose() * self.mass_kg));
        features
            .fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() * NOMINAL_TORQUE_FEATURE_NM));
        ModelTerms {
            mass_kg: self.mass_kg,
            gravity_m_s2: GRAVITY_M_S2,
            inertia_inv: self.inertia_inv,
            gain: true_input_gain(),
            features,
        }
    }
}

/// The true input gain: thrust along body z, torques on the rotational rows (docs/math.md, "State,
/// frames and units").
pub fn true_input_gain() -> SMatrix<f32, 6, 4> {
    #[rustfmt::skip]
    let g = SMatrix::<f32, 6, 4>::new(
        0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0,
        1.0, 0.0, 0.0, 0.0,
        0.0, 1.0, 0.0, 0.0,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    g
}
