//! Tests for `hamflight::blob`'s format: the documented layout constants, exact round trips
//! (and the encoder's bytes), the checks of the values (finite, mass and motor-lag ranges, port
//! terms), the migration of format versions 1 to 3, and the errors' texts.
//!
//! The blobs here are written by an independent encoder that follows the documented layout
//! byte by byte (header, parameters as little-endian f32 layer by layer, CRC-32 computed
//! bit-serially; `common/blob_ref.rs`), so a layout change in the codec shows up as a failure
//! rather than a silent agreement with itself.

mod common;

#[cfg(feature = "std")]
use common::blob_ref::random_tau;
use common::blob_ref::{
    assert_bitwise_eq, blob_from_body, blob_from_body_version, body_values, body_values_port,
    body_values_v3, crc32_reference, encode_reference, encode_reference_tau, for_each_param,
    params, random_weights,
};
use hamflight::blob::{check, decode, BlobError, CRC_LEN, FORMAT_VERSION, HEADER_LEN, MAGIC};
use hamflight::model::{
    GainNet, HamiltonianModel, InertiaNet, LearnedModel, ModelWeights, PortError, PortTerms,
    DEFAULT_MOTOR_TAU_S, MASS_KG, MAX_MASS_KG, MAX_MOTOR_TAU_S, MIN_MASS_KG, PORT_PARAMS,
};
use proptest::prelude::*;

#[test]
fn layout_constants_match_the_documentation() {
    assert_eq!(MAGIC, *b"HMFW");
    assert_eq!(FORMAT_VERSION, 4);
    assert_eq!(PORT_PARAMS, 27);
    assert_eq!(HEADER_LEN, 28);
    assert_eq!(CRC_LEN, 4);
    let blob = encode_reference(&ModelWeights::default());
    assert_eq!(
        blob.len(),
        HEADER_LEN + 4 + 4 + 4 * PORT_PARAMS + 4 * params(&ModelWeights::default()).len() + CRC_LEN
    );
    assert_eq!(ModelWeights::default().mass_kg, MASS_KG);
    // The decode target stays all-zero bits, the model around it too (a `static` of it lives in
    // .bss, not in flash), and reads as the default motor lag.
    let zero = LearnedModel::new(ModelWeights::ZERO);
    // SAFETY: LearnedModel is plain f32 and u32 fields (no padding, no pointers); its bytes are
    // read, not written.
    let bytes = unsafe {
        std::slice::from_raw_parts(
            (&zero as *const LearnedModel).cast::<u8>(),
            std::mem::size_of::<LearnedModel>(),
        )
    };
    assert!(bytes.iter().all(|b| *b == 0));
    assert_eq!(zero.motor_tau_s(), DEFAULT_MOTOR_TAU_S);
    // The motor lag is the body's second value.
    let blob = encode_reference_tau(&ModelWeights::default(), 0.02);
    assert_eq!(blob[HEADER_LEN + 4..HEADER_LEN + 8], 0.02f32.to_le_bytes());
    let m = LearnedModel::from_blob(&blob).expect("valid blob");
    assert_eq!(m.motor_tau_s().to_bits(), 0.02f32.to_bits());
    assert_eq!(crc32_reference(b"123456789"), 0xCBF4_3926);
    assert_eq!(
        hamflight::blob::crc32(b"123456789"),
        crc32_reference(b"123456789")
    );
}

#[test]
fn default_weights_round_trip() {
    let w = ModelWeights::default();
    assert_bitwise_eq(&decode(&encode_reference(&w)).expect("valid blob"), &w);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn round_trip_is_bitwise_exact(seed in any::<u64>()) {
        let w = random_weights(seed);
        let decoded = decode(&encode_reference(&w)).expect("valid blob");
        assert_bitwise_eq(&decoded, &w);
    }
}

/// `blob::encode` exists with the `std` feature (the workspace build enables it via host-train).
#[cfg(feature = "std")]
#[test]
fn encoder_writes_the_documented_layout() {
    for seed in 0..4 {
        let w = random_weights(seed);
        let blob = hamflight::blob::encode(&w);
        assert_eq!(blob, encode_reference(&w), "seed {seed}");
        assert_bitwise_eq(&decode(&blob).expect("valid blob"), &w);
        let tau = random_tau(seed);
        let model = LearnedModel::new(w).with_motor_tau_s(tau);
        let blob = hamflight::blob::encode_model(&model);
        assert_eq!(blob, encode_reference_tau(&w, tau), "seed {seed}");
        assert_eq!(LearnedModel::from_blob(&blob), Ok(model), "seed {seed}");
    }
}

#[test]
fn non_finite_parameter_with_valid_checksum_is_rejected() {
    let n = params(&ModelWeights::default()).len();
    for bad in [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        // The first and last parameter, and the first of each later network.
        let starts = [
            0,
            InertiaNet::PARAMS,
            InertiaNet::PARAMS + GainNet::PARAMS,
            n - 1,
        ];
        for target in starts {
            let mut w = random_weights(17);
            let mut k = 0;
            for_each_param(&mut w, |v| {
                if k == target {
                    *v = bad;
                }
                k += 1;
            });
            let blob = encode_reference(&w);
            assert_eq!(
                decode(&blob).err(),
                Some(BlobError::NonFinite),
                "{bad} at parameter {target}"
            );
        }
    }
}

#[test]
fn mass_outside_the_documented_range_is_rejected() {
    for bad in [0.0, -0.027, MIN_MASS_KG * 0.99, MAX_MASS_KG * 1.01, 1e30] {
        let w = ModelWeights {
            mass_kg: bad,
            ..random_weights(23)
        };
        assert_eq!(
            decode(&encode_reference(&w)).err(),
            Some(BlobError::BadMass),
            "{bad} kg"
        );
    }
    for bad in [f32::NAN, f32::INFINITY] {
        let w = ModelWeights {
            mass_kg: bad,
            ..random_weights(23)
        };
        assert_eq!(
            decode(&encode_reference(&w)).err(),
            Some(BlobError::NonFinite)
        );
    }
    for ok in [MIN_MASS_KG, 0.034, MAX_MASS_KG] {
        let w = ModelWeights {
            mass_kg: ok,
            ..random_weights(23)
        };
        assert_eq!(decode(&encode_reference(&w)).map(|d| d.mass_kg), Ok(ok));
    }
}

#[test]
fn motor_lag_outside_the_documented_range_is_rejected() {
    let w = random_weights(31);
    for bad in [-1e-6, -0.02, MAX_MOTOR_TAU_S * 1.01, 1e30] {
        assert_eq!(
            decode(&encode_reference_tau(&w, bad)).err(),
            Some(BlobError::BadMotorTau),
            "{bad} s"
        );
    }
    for bad in [f32::NAN, f32::NEG_INFINITY] {
        assert_eq!(
            decode(&encode_reference_tau(&w, bad)).err(),
            Some(BlobError::NonFinite)
        );
    }
    for ok in [0.0, 0.02, 0.072, MAX_MOTOR_TAU_S] {
        let m = LearnedModel::from_blob(&encode_reference_tau(&w, ok));
        assert_eq!(m.map(|m| m.motor_tau_s()), Ok(ok));
    }
}

/// A version-1 blob (no mass in its body) still loads, as the stock vehicle it was trained for,
/// with the motor lag every model assumed then.
#[test]
fn version_1_blob_is_migrated_to_the_stock_mass() {
    let w = ModelWeights {
        mass_kg: 0.034,
        ..random_weights(29)
    };
    let body: Vec<u8> = params(&w).iter().flat_map(|v| v.to_le_bytes()).collect();
    let v1 = blob_from_body_version(1, &body);
    let got = LearnedModel::from_blob(&v1).expect("version 1 decodes");
    assert_eq!(got.weights.mass_kg, MASS_KG);
    assert_eq!(got.motor_tau_s(), DEFAULT_MOTOR_TAU_S);
    assert_eq!(params(&got.weights), params(&w));
    // A version-1 header over a version-3 body has two values too many.
    let v3_body = &encode_reference_tau(&w, 0.02)[HEADER_LEN..][..body.len() + 8];
    assert_eq!(
        decode(&blob_from_body_version(1, v3_body)).err(),
        Some(BlobError::Malformed)
    );
}

/// A version-2 blob (the mass, no motor lag) loads with its mass and the default lag
/// (`DEFAULT_MOTOR_TAU_S`, what a model that carries no lag is flown with).
#[test]
fn version_2_blob_is_migrated_to_the_default_motor_lag() {
    let w = ModelWeights {
        mass_kg: 0.034,
        ..random_weights(37)
    };
    let body: Vec<u8> = body_values(&w)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let got = LearnedModel::from_blob(&blob_from_body_version(2, &body)).expect("version 2");
    assert_eq!(got.weights.mass_kg, 0.034);
    assert_eq!(got.motor_tau_s(), DEFAULT_MOTOR_TAU_S);
    assert_eq!(params(&got.weights), params(&w));
    // A version-2 header over a version-3 body has one value too many, and a version-3 header
    // over a version-2 body one too few.
    let v3_body = &encode_reference_tau(&w, 0.02)[HEADER_LEN..][..body.len() + 4];
    assert_eq!(
        decode(&blob_from_body_version(2, v3_body)).err(),
        Some(BlobError::Malformed)
    );
    assert_eq!(
        decode(&blob_from_body_version(3, &body)).err(),
        Some(BlobError::Malformed)
    );
}

#[test]
fn every_error_has_display_text() {
    let all = [
        BlobError::Truncated,
        BlobError::BadMagic,
        BlobError::UnsupportedVersion(7),
        BlobError::ShapeMismatch,
        BlobError::Checksum,
        BlobError::TrailingBytes,
        BlobError::Malformed,
        BlobError::NonFinite,
        BlobError::BadMass,
        BlobError::BadMotorTau,
    ];
    let texts: Vec<String> = all.iter().map(|e| e.to_string()).collect();
    for (e, t) in all.iter().zip(&texts) {
        assert!(!t.trim().is_empty(), "{e:?} has no text");
        let as_error: &dyn core::error::Error = e;
        assert_eq!(as_error.to_string(), *t);
    }
    assert!(texts[2].contains('7'), "the version is named: {}", texts[2]);
    let mut unique = texts.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(unique.len(), texts.len(), "each variant has its own text");
}

#[test]
fn blob_error_text_names_the_range() {
    let text = BlobError::BadMass.to_string();
    assert!(
        text.contains(&format!("{MIN_MASS_KG}..={MAX_MASS_KG} kg")),
        "{text}"
    );
    let text = BlobError::BadMotorTau.to_string();
    assert!(text.contains(&format!("0..={MAX_MOTOR_TAU_S} s")), "{text}");
}

/// A version-3 blob (the mass and the motor lag, no port terms) loads as the rigid body alone.
#[test]
fn version_3_blob_is_migrated_to_the_rigid_body() {
    let w = ModelWeights {
        mass_kg: 0.045,
        ..random_weights(41)
    };
    let body: Vec<u8> = body_values_v3(&w, 0.0325)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let got = LearnedModel::from_blob(&blob_from_body_version(3, &body)).expect("version 3");
    assert_eq!(got.weights.mass_kg, 0.045);
    assert_eq!(got.motor_tau_s(), 0.0325);
    assert_eq!(*got.port(), PortTerms::IDENTITY);
    assert_eq!(params(&got.weights), params(&w));
    // A version-4 header over a version-3 body is 27 values short.
    assert_eq!(
        decode(&blob_from_body_version(4, &body)).err(),
        Some(BlobError::Malformed)
    );
}

/// A non-trivial set of port terms that passes its checks.
fn sample_port() -> PortTerms {
    let mut t = PortTerms::from_array(&core::array::from_fn(|i| 1e-4 * (i as f32 + 1.0)));
    t.thrust_gain_offset = 0.004;
    t.torque_gain_offset = [-0.88, -0.94, -0.76];
    t.thrust_lag_s = 0.048;
    t.torque_lag_s = 0.054;
    t
}

/// The port terms round-trip through the documented layout, and terms that cannot fly are
/// refused with their reason even under a valid checksum.
#[test]
fn port_terms_round_trip_and_are_checked() {
    let w = random_weights(43);
    let port = sample_port();
    let body: Vec<u8> = body_values_port(&w, 0.03, &port)
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let got = LearnedModel::from_blob(&blob_from_body(&body)).expect("valid port terms");
    assert_eq!(*got.port(), port);
    assert_eq!(check(&blob_from_body(&body)).map(|i| i.port), Ok(port));
    #[cfg(feature = "std")]
    assert_eq!(hamflight::blob::encode_model(&got), blob_from_body(&body));
    let bad = |f: &dyn Fn(&mut PortTerms)| {
        let mut p = port;
        f(&mut p);
        let body: Vec<u8> = body_values_port(&w, 0.03, &p)
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        decode(&blob_from_body(&body)).err()
    };
    assert_eq!(
        bad(&|p| p.rate_damping_nm_s[2] = -1e-6),
        Some(BlobError::BadPort(PortError::NegativeDissipation))
    );
    assert_eq!(
        bad(&|p| p.torque_gain_offset[0] = -1.0),
        Some(BlobError::BadPort(PortError::BadGain))
    );
    assert_eq!(
        bad(&|p| p.thrust_lag_s = 1.5),
        Some(BlobError::BadPort(PortError::BadLag))
    );
    // A NaN anywhere in the body is a non-finite parameter first.
    assert_eq!(
        bad(&|p| p.gyrator_nm_s_m[1][2] = f32::NAN),
        Some(BlobError::NonFinite)
    );
}
