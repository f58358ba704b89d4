//! The weight blob: a bad one keeps the motors off, the embedded one loads in place.

use super::{hover_input, motors};
use crate::control_loop::{ControlLoop, NoCost, TickOutcome};
use crate::link;
use hamflight::model::{LearnedModel, ModelWeights};

/// A fresh `static` slot for [`crate::control_loop::load_model`] (leaked: tests only).
fn slot() -> &'static mut LearnedModel {
    Box::leak(Box::new(LearnedModel::new(ModelWeights::ZERO)))
}

#[test]
fn bad_blob_keeps_motors_off() {
    let slot = slot();
    let err = crate::control_loop::load_model(b"not a blob", slot).unwrap_err();
    assert_eq!(err, hamflight::blob::BlobError::BadMagic);
    let mut l = ControlLoop::<crate::control_loop::Model>::new(Err(err));
    let mut m = motors();
    l.on_input(hover_input(1));
    assert_eq!(l.tick(&mut m, &mut NoCost), TickOutcome::Idle);
    assert_eq!([m.m1.0, m.m2.0, m.m3.0, m.m4.0], [0; 4]);
    assert_eq!(l.status(), link::LinkStatus::BadBlob);
}

#[test]
fn embedded_blob_passes_its_checks_and_decodes_in_place() {
    let model = crate::control_loop::load_model(crate::WEIGHT_BLOB, slot());
    assert!(model.is_ok());
    // The model flies the slot, which now holds exactly what decoding by value gives.
    #[cfg(not(hamflight_untrained))]
    assert_eq!(
        model.map(|m| m.weights),
        hamflight::blob::decode(crate::WEIGHT_BLOB)
    );
}
