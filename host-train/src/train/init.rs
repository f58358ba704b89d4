//! Where training starts and the constraints it keeps: the initial weights around the physical
//! prior, the rigid body pinned to the vehicle description, g's unactuated rows zeroed.

use super::data::Windows;
use hamflight::model::ModelWeights;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Initial weights: hidden layers Xavier-uniform from `seed`, output layers scaled by
/// `out_gain` around the physical prior's biases ([`ModelWeights::prior`]), so J⁻¹, g and W
/// start near the CF2X's J⁻¹, the true g and the nominal features.
pub fn init_weights(seed: u64, out_gain: f32) -> ModelWeights {
    init_weights_with_prior(seed, out_gain, ModelWeights::prior())
}

/// [`init_weights`] around `prior` (for example a described vehicle's,
/// [`ModelWeights::prior_with_inertia`]).
pub fn init_weights_with_prior(seed: u64, out_gain: f32, prior: ModelWeights) -> ModelWeights {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut w = prior;
    macro_rules! xavier {
        ($layer:expr, $gain:expr) => {{
            let fan_in = $layer.weight[0].len() as f32;
            let fan_out = $layer.weight.len() as f32;
            let bound = (6.0 / (fan_in + fan_out)).sqrt() * $gain;
            for v in $layer.weight.iter_mut().flatten() {
                *v = rng.gen_range(-bound..bound);
            }
        }};
    }
    xavier!(w.inertia.l0, 1.0);
    xavier!(w.inertia.l1, 1.0);
    xavier!(w.inertia.l2, out_gain);
    xavier!(w.gain.l0, 1.0);
    xavier!(w.gain.l1, 1.0);
    xavier!(w.gain.l2, out_gain);
    xavier!(w.disturbance.l0, 1.0);
    xavier!(w.disturbance.l1, 1.0);
    xavier!(w.disturbance.l2, out_gain);
    w
}

/// Index in [`TModel::tensors`] of the W head's input-layer weight (J⁻¹ and g heads take 6 each).
pub(crate) const FEATURE_INPUT_WEIGHT: usize = 12;
/// `w` with g's body x and y force rows set to zero (the g head's output weights and biases of
/// those rows), exactly zero at every attitude: no input of a quadrotor makes a body x or y
/// force (`TrainConfig::zero_unactuated_gain_rows`).
pub fn with_unactuated_gain_rows_zeroed(w: &ModelWeights) -> ModelWeights {
    let mut out = *w;
    let l2 = &mut out.gain.l2;
    for (row, bias) in l2.weight.iter_mut().zip(l2.bias.iter_mut()).take(8) {
        row.iter_mut().for_each(|v| *v = 0.0);
        *bias = 0.0;
    }
    out
}

/// The physical prior training starts from: the described vehicle's inertia (`import
/// --vehicle`), else the CF2X's.
pub(crate) fn prior_of(data: &Windows) -> ModelWeights {
    data.vehicle
        .description
        .as_ref()
        .map_or_else(ModelWeights::prior, |v| {
            ModelWeights::prior_with_inertia(&nalgebra::Vector3::from(
                v.inertia_kg_m2.map(|x| x as f32),
            ))
        })
}

/// Number of leading [`TModel::tensors`] that make the J⁻¹ and g heads (six each).
pub(crate) const RIGID_BODY_TENSORS: usize = 12;

/// `w` with J⁻¹ and g set to `prior`'s ([`TrainConfig::pin_rigid_body`]): the described
/// inertia and the true mixer at every attitude. Training then freezes both heads, so the
/// blob carries them unchanged.
pub(crate) fn with_rigid_body_pinned(w: &ModelWeights, prior: &ModelWeights) -> ModelWeights {
    ModelWeights {
        inertia: prior.inertia,
        gain: prior.gain,
        ..*w
    }
}
